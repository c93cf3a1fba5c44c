//! How much of a map the camera has seen: the share of the map's reachable floor cells whose
//! centre was once within range of the camera, inside its horizontal field of view and in
//! its line of sight (ground truth, from the simulator's map; the robot's own map plays no
//! part).
//!
//! Reachable cells are the floor cells 4-connected to the start cell. Each step looks only at
//! the cells within range of the camera that are not seen yet, and casts one exact grid ray
//! ([`GridMap::cast_ray`]) to each of those inside the field of view: at 2 m on 0.35 m cells
//! that is a few dozen short rays a frame, far less than rendering the frame.

use std::collections::VecDeque;

use hvs_sim::{GridMap, Pose, StereoRig, Vec2};

/// Range within which the camera counts as seeing a cell, metres.
pub const COVERAGE_RANGE_M: f64 = 2.0;

/// The cells seen so far.
#[derive(Debug, Clone)]
pub struct Coverage {
    width: usize,
    height: usize,
    cell_m: f64,
    /// Row-major from the south-west, as the map's cells.
    reachable: Vec<bool>,
    seen: Vec<bool>,
    n_reachable: usize,
    n_seen: usize,
    range_m: f64,
    half_fov_rad: f64,
}

impl Coverage {
    /// Nothing seen yet; the reachable cells are those 4-connected over floor to the cell of
    /// `start` (none when `start` is on a wall).
    pub fn new(map: &GridMap, start: &Pose, range_m: f64, fov_rad: f64) -> Self {
        let (width, height) = (map.width_cells(), map.height_cells());
        let mut reachable = vec![false; width * height];
        let mut n_reachable = 0;
        let (c0, r0) = map.cell_of(start.x_m, start.y_m);
        let mut queue = VecDeque::new();
        if !map.is_wall_cell(c0, r0) {
            reachable[r0 as usize * width + c0 as usize] = true;
            n_reachable = 1;
            queue.push_back((c0, r0));
        }
        while let Some((c, r)) = queue.pop_front() {
            for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let (nc, nr) = (c + dc, r + dr);
                if map.is_wall_cell(nc, nr) {
                    continue;
                }
                let i = nr as usize * width + nc as usize;
                if !reachable[i] {
                    reachable[i] = true;
                    n_reachable += 1;
                    queue.push_back((nc, nr));
                }
            }
        }
        Coverage {
            width,
            height,
            cell_m: map.cell_m(),
            reachable,
            seen: vec![false; width * height],
            n_reachable,
            n_seen: 0,
            range_m,
            half_fov_rad: 0.5 * fov_rad,
        }
    }

    /// For the camera of `rig`: [`COVERAGE_RANGE_M`] and the rig's horizontal field of view.
    pub fn for_rig(map: &GridMap, start: &Pose, rig: &StereoRig) -> Self {
        Self::new(map, start, COVERAGE_RANGE_M, horizontal_fov_rad(rig))
    }

    /// Marks the reachable cells the camera at `camera` (a position and heading) sees.
    pub fn observe(&mut self, map: &GridMap, camera: &Pose) {
        let eye = camera.position();
        if self.n_seen == self.n_reachable || map.is_wall_at(eye.x, eye.y) {
            return;
        }
        let cs = self.cell_m;
        let reach = (self.range_m / cs).ceil() as i64 + 1;
        let (ec, er) = map.cell_of(eye.x, eye.y);
        let forward = camera.forward();
        let cos_half = self.half_fov_rad.cos();
        let r2 = self.range_m * self.range_m;
        let rows = (er - reach).max(0)..=(er + reach).min(self.height as i64 - 1);
        for r in rows {
            let cols = (ec - reach).max(0)..=(ec + reach).min(self.width as i64 - 1);
            for c in cols {
                let i = r as usize * self.width + c as usize;
                if !self.reachable[i] || self.seen[i] {
                    continue;
                }
                let centre = Vec2::new((c as f64 + 0.5) * cs, (r as f64 + 0.5) * cs);
                let d = centre - eye;
                let d2 = d.dot(d);
                if d2 > r2 {
                    continue;
                }
                let dist = d2.sqrt();
                // The eye's own cell counts as seen only when ahead of the eye.
                if dist < 1e-9 || d.dot(forward) < dist * cos_half {
                    continue;
                }
                let clear = map
                    .cast_ray(eye, d)
                    .is_some_and(|hit| hit.distance_m >= dist - 1e-9);
                if clear {
                    self.seen[i] = true;
                    self.n_seen += 1;
                }
            }
        }
    }

    /// Share of the reachable cells seen, percent (0 when none is reachable).
    pub fn pct(&self) -> f64 {
        if self.n_reachable == 0 {
            0.0
        } else {
            100.0 * self.n_seen as f64 / self.n_reachable as f64
        }
    }

    /// Reachable floor cells.
    pub fn reachable_cells(&self) -> usize {
        self.n_reachable
    }

    /// Reachable cells seen.
    pub fn seen_cells(&self) -> usize {
        self.n_seen
    }
}

/// Horizontal field of view of a rig's images, radians (from the outer edges of the first
/// and last columns).
pub fn horizontal_fov_rad(rig: &StereoRig) -> f64 {
    let left = (rig.cx_px + 0.5) / rig.focal_px;
    let right = (rig.width as f64 - 0.5 - rig.cx_px) / rig.focal_px;
    left.atan() + right.atan()
}

/// The camera's pose for a robot pose: the rig centre, `rig.camera_forward_m` ahead.
pub fn camera_pose(robot: &Pose, rig: &StereoRig) -> Pose {
    robot.offset(rig.camera_forward_m, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    const ROOM: &str = "@cell_m 0.5\n#########\n#.......#\n#.>.....#\n#.......#\n#########\n";

    fn room() -> GridMap {
        GridMap::parse(ROOM, "room").unwrap()
    }

    #[test]
    fn fov_of_the_320_rig_is_53_degrees() {
        let fov = horizontal_fov_rad(&StereoRig::qvga()).to_degrees();
        assert!((fov - 53.13).abs() < 0.01, "{fov}");
    }

    #[test]
    fn sees_cells_ahead_within_range_and_field_of_view_only() {
        let map = room();
        // Floor 7 x 3 cells of 0.5 m; the start cell (2.5, ...) is in the middle row.
        let start = map.start_pose();
        let mut cov = Coverage::new(&map, &start, 2.0, 60f64.to_radians());
        assert_eq!(cov.reachable_cells(), 21);
        assert_eq!(cov.pct(), 0.0);
        // Facing east from x = 1.25: the middle row's cells up to 2 m ahead (x centres 1.75,
        // 2.25, 2.75, 3.25) and the neighbouring rows' within 30 degrees.
        cov.observe(&map, &Pose::from_deg(1.25, 1.25, 0.0));
        let seen = cov.seen_cells();
        assert!((4..=9).contains(&seen), "{seen}");
        // Nothing behind: turning back later adds the cells there.
        let before = cov.seen_cells();
        cov.observe(&map, &Pose::from_deg(1.25, 1.25, 0.0));
        assert_eq!(cov.seen_cells(), before, "seen once");
        cov.observe(&map, &Pose::from_deg(3.25, 1.25, 180.0));
        assert!(cov.seen_cells() > before);
        assert!(cov.pct() > 0.0 && cov.pct() < 100.0);
    }

    #[test]
    fn walls_hide_what_lies_behind_them() {
        // Two rooms joined at the south; the wall between them hides the east room.
        let text = "@cell_m 0.5\n#########\n#...#...#\n#.>.#...#\n#.......#\n#########\n";
        let map = GridMap::parse(text, "two").unwrap();
        let mut cov = Coverage::new(&map, &map.start_pose(), 10.0, 170f64.to_radians());
        assert_eq!(cov.reachable_cells(), 19);
        cov.observe(&map, &Pose::from_deg(1.75, 1.75, 0.0));
        // Cells (5..7, rows 1..2) behind the wall stay unseen from the west room's top.
        let east_top_seen = (5..8)
            .flat_map(|c| [(c, 2usize), (c, 3)])
            .filter(|&(c, r)| cov.seen[r * cov.width + c])
            .count();
        assert_eq!(east_top_seen, 0);
        assert_eq!(cov.seen_cells(), 0, "nothing of the west room lies ahead");
        // From the shared south row: the row ahead, then the east room up to the north-east.
        cov.observe(&map, &Pose::from_deg(2.25, 0.75, 0.0));
        // The south row's three cells east of the eye, and three of the east room's that the
        // wall's end does not hide ((3.25, 1.25), (3.75, 1.25), (3.75, 1.75)).
        assert_eq!(cov.seen_cells(), 6);
        cov.observe(&map, &Pose::from_deg(3.75, 0.75, 45.0));
        assert_eq!(
            cov.seen_cells(),
            7,
            "and (3.25, 1.75), now past the wall's end"
        );
    }

    #[test]
    fn unreachable_floor_does_not_count() {
        // A closed cell west of the start room.
        let text = "@cell_m 1\n#######\n#.#.>.#\n#######\n";
        let map = GridMap::parse(text, "t").unwrap();
        let mut cov = Coverage::new(&map, &map.start_pose(), 5.0, 3.0);
        assert_eq!(cov.reachable_cells(), 3);
        cov.observe(&map, &Pose::from_deg(3.2, 1.5, 0.0));
        cov.observe(&map, &Pose::from_deg(5.8, 1.5, 180.0));
        assert_eq!(cov.pct(), 100.0);
    }
}
