//! Trace-only (`HVS_DRIVE_TRACE`): for a collision, where the wall that touched the robot
//! lies in the explorer's grid. The touching wall's points (found on the true map around the
//! true footprint) are carried into the dead-reckoned frame through the robot's body, so a
//! wall the grid holds where the robot believes it is reads "occupied": the controller drove
//! into a known wall; one the grid holds a little aside reads by the distance to the nearest
//! occupied cell (the map and the pose disagree); one never seen reads "unknown" or "free".

use hvs_decision::explore::grid::{OccupancyGrid, to_grid_frame};
use hvs_decision::local_map::CellState;
use hvs_decision::odometry::DeadReckonedPose;
use hvs_runtime::config::RobotConfig;
use hvs_shared::messages::{ObstacleScan, SCAN_BINS};
use hvs_sim::{Eye, GridMap, Pose, StereoRig, Vec2};

/// What the diagnosis compares: the true map and pose, the explorer's grid and pose.
pub struct Scene<'a> {
    /// The simulated world's map.
    pub map: &'a GridMap,
    /// The robot's true pose.
    pub truth: &'a Pose,
    /// The pose the explorer believes, on its grid.
    pub believed: &'a DeadReckonedPose,
    /// The explorer's occupancy grid.
    pub grid: &'a OccupancyGrid,
    /// The robot's body.
    pub robot: &'a RobotConfig,
}

/// Prints to stderr, at simulated second `t_s`: with `each_second`, a `consistency` line
/// (mean distance from the true walls within 1 m to the grid's occupied cells, faces
/// counted, faces with none near) and a `hazard` line (the true wall surface within
/// `HAZARD_RADIUS_M` counted by the grid's state: occupied, free, unknown, and of the free
/// and unknown those whose cell ever had a scan point); with `collided`,
/// a `collision` line and a picture.
pub fn trace(scene: &Scene<'_>, t_s: f64, each_second: bool, collided: bool) {
    if each_second {
        let (mean_m, n, unseen) = consistency(scene, 1.0);
        eprintln!("consistency {t_s:6.2} {mean_m:.3} {n} {unseen}");
        let [occupied, free, unknown, seen] = wall_surface_states(scene, HAZARD_RADIUS_M);
        eprintln!("hazard {t_s:6.2} {occupied} {free} {unknown} {seen}");
    }
    if collided {
        eprintln!("collision {t_s:6.2} {}", collision_line(scene));
        eprintln!("{}", picture(scene, 1.0));
    }
}

/// Radius around the robot within which the wall surface is looked up for the `hazard`
/// line, metres: the turning disc (0.27 m) with room for the margins.
const HAZARD_RADIUS_M: f64 = 0.4;

/// The true walls' surface (wall points with floor within 5 cm) within `radius_m` of the
/// robot, carried into the believed frame through the robot's body, counted by the grid's
/// state there: [occupied, free, unknown, seen] (the last: of the free and unknown, those
/// whose cell ever had a scan point, [`OccupancyGrid::hits_at`]). A free count is a wall the footprint checks take
/// for floor (a wall never mapped, carved by rays past its edge, or drawn aside by drift).
fn wall_surface_states(scene: &Scene<'_>, radius_m: f64) -> [usize; 4] {
    let (map, truth, believed, grid) = (scene.map, scene.truth, scene.believed, scene.grid);
    let step = 0.05;
    let k = (radius_m / step).ceil() as i32;
    let mut counts = [0; 4];
    for i in -k..=k {
        for j in -k..=k {
            let (a, l) = (f64::from(i) * step, f64::from(j) * step);
            if a.hypot(l) > radius_m {
                continue;
            }
            let at = |da: f64, dl: f64| {
                let p = truth.offset(a + da, l + dl);
                map.is_wall_at(p.x_m, p.y_m)
            };
            if !at(0.0, 0.0) || (at(step, 0.0) && at(-step, 0.0) && at(0.0, step) && at(0.0, -step))
            {
                continue;
            }
            let (x, y) = to_grid_frame(believed, (a, l));
            let state = grid.state_at(x, y);
            counts[match state {
                CellState::Occupied => 0,
                CellState::Free => 1,
                CellState::Unknown => 2,
            }] += 1;
            if state != CellState::Occupied && grid.hits_at(x, y) > 0 {
                counts[3] += 1;
            }
        }
    }
    counts
}

/// Margin around the footprint searched for the touching wall, metres.
const TOUCH_MARGIN_M: f64 = 0.03;
/// Farthest an occupied cell is looked for around a touching point, metres.
const SEARCH_M: f64 = 0.5;

/// One line describing the touching wall's points in the grid.
fn collision_line(scene: &Scene<'_>) -> String {
    let Scene {
        map,
        truth,
        believed,
        grid,
        robot,
    } = *scene;
    let hl = 0.5 * robot.length_m + TOUCH_MARGIN_M;
    let hw = 0.5 * robot.width_m + TOUCH_MARGIN_M;
    let mut parts = Vec::new();
    let n: i32 = 12;
    for i in -n..=n {
        for j in -n..=n {
            // Only the footprint's rim.
            if i.abs() != n && j.abs() != n {
                continue;
            }
            let a = f64::from(i) / f64::from(n) * hl;
            let l = f64::from(j) / f64::from(n) * hw;
            let touched = truth.offset(a, l);
            if !map.is_wall_at(touched.x_m, touched.y_m) {
                continue;
            }
            let (x, y) = to_grid_frame(believed, (a, l));
            let st = match grid.state_at(x, y) {
                CellState::Occupied => "occ",
                CellState::Free => "free",
                CellState::Unknown => "unk",
            };
            let near = nearest_occupied_m(grid, x, y).unwrap_or(f64::INFINITY);
            let hits = grid.hits_at(x, y);
            parts.push(format!("({a:+.2},{l:+.2}) {st} h{hits} near {near:.2}"));
        }
    }
    parts.join("; ")
}

/// Nearest occupied cell of `grid` to a point, up to `SEARCH_M` (`None`: none that near).
fn nearest_occupied_m(grid: &OccupancyGrid, x: f64, y: f64) -> Option<f64> {
    let step = 0.5 * grid.cell_m();
    let k = (SEARCH_M / step).ceil() as i64;
    let mut nearest: Option<f64> = None;
    for di in -k..=k {
        for dj in -k..=k {
            let (dx, dy) = (di as f64 * step, dj as f64 * step);
            let d = dx.hypot(dy);
            if d <= SEARCH_M
                && nearest.is_none_or(|n| d < n)
                && grid.state_at(x + dx, y + dy) == CellState::Occupied
            {
                nearest = Some(d);
            }
        }
    }
    nearest
}

/// How well the grid agrees with the true walls near the robot, as seen from the believed
/// pose: the true wall faces within `radius_m` of the robot are carried into the believed
/// frame through the robot's body, and each one's distance to the nearest occupied cell is
/// averaged (faces with none within `SEARCH_M` are left out: never seen). Returns (mean
/// distance, faces counted, faces with none near).
fn consistency(scene: &Scene<'_>, radius_m: f64) -> (f64, usize, usize) {
    let Scene {
        map,
        truth,
        believed,
        grid,
        ..
    } = *scene;
    let cell = map.cell_m();
    let (c0, r0) = map.cell_of(truth.x_m, truth.y_m);
    let k = (radius_m / cell).ceil() as i64;
    let (ch, sh) = (truth.heading_rad.cos(), truth.heading_rad.sin());
    let (mut sum, mut n, mut unseen) = (0.0, 0, 0);
    for c in c0 - k..=c0 + k {
        for r in r0 - k..=r0 + k {
            if !map.is_wall_cell(c, r) {
                continue;
            }
            for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                if map.is_wall_cell(c + dc, r + dr) {
                    continue;
                }
                // The face between the wall cell and its free neighbour.
                let fx = (c as f64 + 0.5 + 0.5 * dc as f64) * cell;
                let fy = (r as f64 + 0.5 + 0.5 * dr as f64) * cell;
                let (ex, ey) = (fx - truth.x_m, fy - truth.y_m);
                if ex.hypot(ey) > radius_m {
                    continue;
                }
                // Robot frame, then the believed frame.
                let (a, l) = (ex * ch + ey * sh, -ex * sh + ey * ch);
                let (x, y) = to_grid_frame(believed, (a, l));
                match nearest_occupied_m(grid, x, y) {
                    Some(d) => {
                        sum += d;
                        n += 1;
                    }
                    None => unseen += 1,
                }
            }
        }
    }
    (if n > 0 { sum / n as f64 } else { 0.0 }, n, unseen)
}

/// The grid around the believed pose beside the true walls carried into the believed frame,
/// one character per half cell: `X` both, `#` the grid only, `W` a true wall the grid has
/// free (`w`: unknown), `o` the footprint, `?` unknown, ` ` free.
fn picture(scene: &Scene<'_>, half_m: f64) -> String {
    let (map, truth, believed, grid) = (scene.map, scene.truth, scene.believed, scene.grid);
    let (length_m, width_m) = (scene.robot.length_m, scene.robot.width_m);
    let step = 0.5 * grid.cell_m();
    let k = (half_m / step).ceil() as i64;
    let (cb, sb) = (believed.heading_rad.cos(), believed.heading_rad.sin());
    let mut out = String::new();
    for j in (-k..=k).rev() {
        for i in -k..=k {
            let (x, y) = (
                believed.x_m + i as f64 * step,
                believed.y_m + j as f64 * step,
            );
            // Believed frame -> robot frame -> true world.
            let (ex, ey) = (x - believed.x_m, y - believed.y_m);
            let (a, l) = (ex * cb + ey * sb, -ex * sb + ey * cb);
            let there = truth.offset(a, l);
            let wall = map.is_wall_at(there.x_m, there.y_m);
            let body = a.abs() <= 0.5 * length_m && l.abs() <= 0.5 * width_m;
            let c = match (wall, grid.state_at(x, y)) {
                (true, CellState::Occupied) => 'X',
                (false, CellState::Occupied) => '#',
                (true, CellState::Free) => 'W',
                (true, CellState::Unknown) => 'w',
                (false, _) if body => 'o',
                (false, CellState::Unknown) => '?',
                (false, CellState::Free) => ' ',
            };
            out.push(c);
        }
        out.push('\n');
    }
    out
}

/// Depths in metres, millimetre precision, space-separated (the `scan` and `truth` lines).
pub fn depths_text<T: std::fmt::Display>(depths: &[T]) -> String {
    depths
        .iter()
        .map(|r| format!("{r:.3}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The depth (along the optical axis, metres) of the nearest wall along each bin's viewing
/// direction of `scan`, cast from the left eye of the robot at `robot` on the true map (0:
/// nothing hit): what a perfect matcher would give for the bin's middle column (the
/// `truth` trace line beside the `scan` one).
pub fn true_scan_depths(
    map: &GridMap,
    rig: &StereoRig,
    robot: &Pose,
    scan: &ObstacleScan,
) -> [f64; SCAN_BINS] {
    let eye = rig.eye_position(robot, Eye::Left);
    let mut depths = [0.0; SCAN_BINS];
    for (i, depth) in depths.iter_mut().enumerate() {
        let angle = scan.bin_tangent(i).atan();
        let dir = Vec2::from_heading(robot.heading_rad + angle);
        if let Some(hit) = map.cast_ray(eye, dir) {
            *depth = hit.distance_m * angle.cos();
        }
    }
    depths
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_decision::explore::grid::ScanPoints;
    use hvs_runtime::config::GridConfig;

    #[test]
    fn the_wall_surface_near_the_robot_is_counted_by_the_grids_state() {
        // A hallway 0.5 m cells, the robot in its middle facing east: walls 0.25 m to
        // either side of it.
        let map =
            GridMap::parse("@cell_m 0.5\n#####\n#.>.#\n#####\n", "test").expect("a valid map");
        let truth = map.start_pose();
        let believed = DeadReckonedPose::default();
        let robot = RobotConfig::default();
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let scene = |grid: &OccupancyGrid| {
            wall_surface_states(
                &Scene {
                    map: &map,
                    truth: &truth,
                    believed: &believed,
                    grid,
                    robot: &robot,
                },
                HAZARD_RADIUS_M,
            )
        };
        // Nothing mapped: all of the surface is unknown.
        let [occupied, free, unknown, seen] = scene(&grid);
        assert_eq!(seen, 0);
        assert_eq!((occupied, free), (0, 0));
        assert!(unknown > 10, "{unknown}");
        // The wall's cells marked: its surface reads occupied.
        let mut marked = grid.clone();
        marked.mark_bump(&believed, (-0.4, 0.4), (-0.25, 0.25));
        assert_eq!(scene(&marked), [unknown, 0, 0, 0]);
        // Cleared instead (as rays past a wall's edge clear it): free, where the footprint
        // checks take it for floor.
        grid.clear_footprint(&believed, 0.4, 0.35);
        assert_eq!(scene(&grid), [0, unknown, 0, 0]);
        // Seen once (not yet occupied) before the rays cleared it: counted as seen.
        let mut seen_once = OccupancyGrid::new(GridConfig::default());
        let hits = (-8..=8)
            .flat_map(|i| [(f64::from(i) * 0.05, 0.27), (f64::from(i) * 0.05, -0.27)])
            .collect();
        seen_once.insert(&ScanPoints {
            camera: (0.0, 0.0),
            hits,
            rays: vec![],
        });
        seen_once.clear_footprint(&believed, 0.4, 0.35);
        let [occupied, free, unknown_now, seen] = scene(&seen_once);
        assert_eq!((occupied, unknown_now), (0, 0));
        assert_eq!(free, unknown);
        assert!(seen > free / 2, "{seen} of {free}");
    }

    #[test]
    fn the_true_scan_ranges_a_wall_ahead_at_its_depth() {
        // A room of 0.5 m cells: the robot's centre at x 0.75 m, facing east, so the left
        // eye (0.2 m ahead) sees the east wall (x 3.0 m) 2.05 m ahead in the middle bins.
        let map = GridMap::parse("@cell_m 0.5\n#######\n#>....#\n#.....#\n#######\n", "room")
            .expect("a valid map");
        let robot = map.start_pose();
        let rig = StereoRig::qvga();
        let scan = ObstacleScan {
            tan_half_fov: 0.5,
            ..ObstacleScan::default()
        };
        let depths = true_scan_depths(&map, &rig, &robot, &scan);
        for i in [SCAN_BINS / 2 - 1, SCAN_BINS / 2] {
            assert!((depths[i] - 2.05).abs() < 0.01, "bin {i}: {}", depths[i]);
        }
        // Every bin sees a wall, none nearer than the camera's distance to the side walls.
        assert!(depths.iter().all(|&d| d > 0.2 && d < 2.1), "{depths:?}");
        // Bin 0 looks left (26 degrees): the north wall, 0.22 m beside the eye, is met at a
        // depth of 0.45 m; bin 63 looks right at the south wall, 0.78 m away: 1.58 m.
        assert!((depths[0] - 0.45).abs() < 0.02, "{}", depths[0]);
        assert!(
            (depths[SCAN_BINS - 1] - 1.585).abs() < 0.01,
            "{}",
            depths[SCAN_BINS - 1]
        );
    }
}
