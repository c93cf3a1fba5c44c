//! Drift correction: before a scan is added, the dead-reckoned pose is searched over a small
//! window (heading, and x and y when `search_m` is above 0: by default it is 0) for the pose
//! at which the scan's points fall best on the grid's occupied cells (a brute-force
//! correlative matcher, as in Olson's real-time correlative scan matching, without the
//! multi-resolution step: the window is small); then, with `position` on, the position is
//! refined by point-to-wall alignment ([`refine_position`]). After a turn made while the
//! scan showed too little to align, the heading can be searched over the whole arc turned
//! ([`align_over_arc`], `reacquire_turn_deg`, off by default).

use hvs_runtime::config::ScanMatchConfig;

use super::grid::{OccupancyGrid, to_grid_frame};
use crate::local_map::CellState;
use crate::odometry::DeadReckonedPose;

/// A found correction.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PoseCorrection {
    /// Metres east (grid frame).
    pub dx_m: f64,
    /// Metres north.
    pub dy_m: f64,
    /// Radians counter-clockwise.
    pub dheading_rad: f64,
    /// Share of the points on occupied cells at the corrected pose.
    pub overlap: f64,
    /// What the correction is.
    pub kind: CorrectionKind,
}

/// Where a [`PoseCorrection`] comes from.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum CorrectionKind {
    /// The scan aligned to the grid: a measurement of dead reckoning's error.
    #[default]
    Aligned,
    /// Motion dead reckoning integrated that did not happen, taken back (a stall), the
    /// heading re-found after a blind turn, or the grid re-drawn after one: not a
    /// measurement of the wheels' errors.
    PutBack,
}

fn score(grid: &OccupancyGrid, pose: &DeadReckonedPose, points: &[(f64, f64)]) -> (f64, usize) {
    let mut s = 0.0;
    let mut on = 0;
    for &p in points {
        let (x, y) = to_grid_frame(pose, p);
        if let Some(cell) = grid.cell_of(x, y) {
            let l = f64::from(grid.log_odds(cell));
            if l > 0.0 {
                s += l;
            }
            if grid.state(cell) == CellState::Occupied {
                on += 1;
            }
        }
    }
    (s, on)
}

/// The candidate correction `(dx_m, dy_m, dheading_rad)` at which `points` (robot frame,
/// metres) score best on the grid, ties going to the smaller correction; `None` unless at
/// least `min_overlap` of the points land on occupied cells there and it beats the
/// uncorrected pose by `min_gain_share` (among near-equal fits the noise picks one, and
/// following it would walk the pose at random).
fn best_fit(
    grid: &OccupancyGrid,
    pose: &DeadReckonedPose,
    points: &[(f64, f64)],
    candidates: impl IntoIterator<Item = (f64, f64, f64)>,
    min_overlap: f64,
    min_gain_share: f64,
) -> Option<PoseCorrection> {
    let (base, _) = score(grid, pose, points);
    let mut best: Option<(f64, usize, f64, f64, f64)> = None;
    for (dx, dy, dth) in candidates {
        let cand = DeadReckonedPose {
            x_m: pose.x_m + dx,
            y_m: pose.y_m + dy,
            heading_rad: pose.heading_rad + dth,
        };
        let (s, on) = score(grid, &cand, points);
        let size = dx.hypot(dy) + 0.1 * dth.abs();
        let better = match best {
            None => true,
            Some((bs, _, bx, by, bt)) => {
                s > bs + 1e-9 || ((s - bs).abs() <= 1e-9 && size < bx.hypot(by) + 0.1 * bt.abs())
            }
        };
        if better {
            best = Some((s, on, dx, dy, dth));
        }
    }
    let (s, on, dx, dy, dth) = best?;
    let overlap = on as f64 / points.len() as f64;
    if overlap < min_overlap || s <= base * (1.0 + min_gain_share) + 1e-9 {
        return None;
    }
    Some(PoseCorrection {
        dx_m: dx,
        dy_m: dy,
        dheading_rad: dth,
        overlap,
        kind: CorrectionKind::Aligned,
    })
}

/// Searches for the pose that best explains `points` (robot frame, metres); `None` when there
/// are too few points, too little overlap, or no pose beats the dead-reckoned one.
pub fn align(
    grid: &OccupancyGrid,
    pose: &DeadReckonedPose,
    points: &[(f64, f64)],
    cfg: &ScanMatchConfig,
) -> Option<PoseCorrection> {
    if !cfg.enabled || points.len() < cfg.min_points as usize {
        return None;
    }
    let nxy = (cfg.search_m / cfg.step_m).floor() as i64;
    let nth = (cfg.search_deg / cfg.step_deg).floor() as i64;
    let candidates = (-nth..=nth).flat_map(|it| {
        let dth = (it as f64 * cfg.step_deg).to_radians();
        (-nxy..=nxy).flat_map(move |ix| {
            (-nxy..=nxy).map(move |iy| (ix as f64 * cfg.step_m, iy as f64 * cfg.step_m, dth))
        })
    });
    best_fit(
        grid,
        pose,
        points,
        candidates,
        cfg.min_overlap,
        cfg.min_gain_share,
    )
}

/// The heading re-found after a blind turn: `points` (robot frame, metres) scored at every
/// heading from `pose`'s back to where dead reckoning says the turn began (`turned_rad`
/// before it; the true heading lies in between when the turn was held) and `search_deg`
/// beyond both ends, in `step_deg` steps, position fixed (a robot turning in place). `None`
/// when there are fewer than [`ScanMatchConfig::reacquire_points`] points, under
/// `reacquire_min_overlap` of them on occupied cells at the best heading, or it does not
/// beat the dead-reckoned heading by `min_gain_share`; ties go to the smaller correction.
pub fn align_over_arc(
    grid: &OccupancyGrid,
    pose: &DeadReckonedPose,
    points: &[(f64, f64)],
    cfg: &ScanMatchConfig,
    turned_rad: f64,
) -> Option<PoseCorrection> {
    if !cfg.enabled || points.len() < cfg.reacquire_points() || cfg.step_deg <= 0.0 {
        return None;
    }
    // Offsets from the current heading, in the direction back toward the turn's start; a
    // turn past half a circle leaves every heading possible.
    let back = -turned_rad.signum();
    let span_deg = turned_rad.abs().to_degrees().min(180.0);
    let steps = ((span_deg + cfg.search_deg) / cfg.step_deg).ceil() as i64;
    let beyond = (cfg.search_deg / cfg.step_deg).floor() as i64;
    let candidates =
        (-beyond..=steps).map(|k| (0.0, 0.0, back * (k as f64 * cfg.step_deg).to_radians()));
    best_fit(
        grid,
        pose,
        points,
        candidates,
        cfg.reacquire_min_overlap,
        cfg.min_gain_share,
    )
}

/// The wall near `q`: the centroid of the occupied cells within `wall_patch_m` of the
/// nearest occupied cell (if one lies within `position_reach_m`) and the wall's unit
/// normal; `None` when nothing is near or the cells do not lie along a line (a corner, a
/// pillar: flatter than `max_flatness`).
fn wall_near(
    grid: &OccupancyGrid,
    q: (f64, f64),
    cfg: &ScanMatchConfig,
) -> Option<((f64, f64), (f64, f64))> {
    let reach_m = cfg.position_reach_m;
    let cell_m = grid.cell_m();
    let centre = grid.cell_of(q.0, q.1)?;
    let k = ((reach_m + cfg.wall_patch_m) / cell_m).ceil() as i64;
    let mut occupied: Vec<(f64, f64)> = Vec::new();
    for dr in -k..=k {
        for dc in -k..=k {
            if let Some(cell) = grid.offset(centre, dc, dr)
                && grid.state(cell) == CellState::Occupied
            {
                occupied.push(grid.centre(cell));
            }
        }
    }
    let d2 = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).powi(2) + (a.1 - b.1).powi(2);
    let nearest = occupied
        .iter()
        .copied()
        .min_by(|a, b| d2(*a, q).total_cmp(&d2(*b, q)))?;
    if d2(nearest, q) > reach_m * reach_m {
        return None;
    }
    let patch: Vec<(f64, f64)> = occupied
        .into_iter()
        .filter(|&c| d2(c, nearest) <= cfg.wall_patch_m * cfg.wall_patch_m)
        .collect();
    if patch.len() < 3 {
        return None;
    }
    let n = patch.len() as f64;
    let mean = (
        patch.iter().map(|p| p.0).sum::<f64>() / n,
        patch.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for p in &patch {
        let (x, y) = (p.0 - mean.0, p.1 - mean.1);
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
    }
    let (big, small, along) = sym2_eigen(sxx / n, sxy / n, syy / n);
    if big <= 0.0 || small > cfg.max_flatness * big {
        return None;
    }
    Some((mean, (-along.1, along.0)))
}

/// Eigenvalues (larger, smaller) of the symmetric 2x2 matrix `[[a, b], [b, c]]` and the unit
/// eigenvector of the larger.
fn sym2_eigen(a: f64, b: f64, c: f64) -> (f64, f64, (f64, f64)) {
    let mid = 0.5 * (a + c);
    let rad = (0.25 * (a - c) * (a - c) + b * b).sqrt();
    let (big, small) = (mid + rad, mid - rad);
    let v = if b.abs() > 1e-12 {
        (big - c, b)
    } else if a >= c {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    let len = v.0.hypot(v.1).max(1e-12);
    (big, small, (v.0 / len, v.1 / len))
}

/// A position correction found by [`refine_position`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionFix {
    /// Metres east (grid frame), gain and step limit applied.
    pub dx_m: f64,
    /// Metres north.
    pub dy_m: f64,
}

/// Point-to-wall alignment (one Gauss-Newton step of point-to-line ICP against the walls
/// the grid draws): each scan point within `position_reach_m` of a mapped wall pulls the
/// position along that wall's normal. The step is taken only along the directions the
/// walls in view constrain (eigenvectors of the normals' information matrix holding at
/// least `position_min_points` points): a hallway's walls say nothing about where along it
/// the robot is, and noise there must not walk the pose. Written by hand: the ICP crates
/// on crates.io work on point clouds, not on an occupancy grid, and this is forty lines.
pub fn refine_position(
    grid: &OccupancyGrid,
    pose: &DeadReckonedPose,
    points: &[(f64, f64)],
    cfg: &ScanMatchConfig,
) -> Option<PositionFix> {
    if !cfg.enabled || !cfg.position || points.len() < cfg.min_points as usize {
        return None;
    }
    // Information matrix [[hxx, hxy], [hxy, hyy]] and gradient (bx, by).
    let (mut hxx, mut hxy, mut hyy, mut bx, mut by) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut inliers = 0;
    for &p in points {
        let q = to_grid_frame(pose, p);
        let Some((on, n)) = wall_near(grid, q, cfg) else {
            continue;
        };
        let r = n.0 * (q.0 - on.0) + n.1 * (q.1 - on.1);
        if r.abs() > cfg.position_reach_m {
            continue;
        }
        let w = if r.abs() <= cfg.huber_m {
            1.0
        } else {
            cfg.huber_m / r.abs()
        };
        hxx += w * n.0 * n.0;
        hxy += w * n.0 * n.1;
        hyy += w * n.1 * n.1;
        bx += w * n.0 * r;
        by += w * n.1 * r;
        inliers += 1;
    }
    if inliers < cfg.min_points as usize {
        return None;
    }
    let (big, small, e1) = sym2_eigen(hxx, hxy, hyy);
    let e2 = (-e1.1, e1.0);
    let min_info = f64::from(cfg.position_min_points);
    let (mut dx, mut dy) = (0.0, 0.0);
    let mut constrained = false;
    for (lambda, e) in [(big, e1), (small, e2)] {
        if lambda >= min_info {
            let along = -(e.0 * bx + e.1 * by) / lambda;
            dx += along * e.0;
            dy += along * e.1;
            constrained = true;
        }
    }
    if !constrained {
        return None;
    }
    let (mut dx, mut dy) = (cfg.position_gain * dx, cfg.position_gain * dy);
    let len = dx.hypot(dy);
    if len > cfg.position_max_step_m {
        let k = cfg.position_max_step_m / len;
        dx *= k;
        dy *= k;
    }
    Some(PositionFix { dx_m: dx, dy_m: dy })
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_runtime::config::GridConfig;
    use hvs_shared::messages::{ObstacleScan, SCAN_BINS};

    /// A corner: a wall ahead at 1.45 m over the left half, 1.85 m over the right (points
    /// in the middle of grid cells).
    fn corner_scan() -> ObstacleScan {
        let mut scan = ObstacleScan {
            tan_half_fov: 0.3,
            ..ObstacleScan::default()
        };
        for (i, r) in scan.range_m.iter_mut().enumerate() {
            *r = if i < SCAN_BINS / 2 { 1.45 } else { 1.85 };
        }
        scan
    }

    /// The grid after four looks at [`corner_scan`] from the origin, facing east, and the
    /// scan's points in the robot's frame.
    fn corner_seen_from_origin() -> (OccupancyGrid, Vec<(f64, f64)>) {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        for _ in 0..4 {
            let pts = grid.scan_points(&DeadReckonedPose::default(), 0.2, &corner_scan());
            grid.insert(&pts);
        }
        let points = grid.scan_hits_robot_frame(&corner_scan(), 0.2);
        (grid, points)
    }

    #[test]
    fn a_shifted_pose_is_pulled_back_onto_the_map() {
        let (grid, points) = corner_seen_from_origin();
        let pose = DeadReckonedPose::default();
        assert!(points.len() > 40, "{}", points.len());
        // Dead reckoning says 0.1 m further ahead than the robot is; a search in position
        // (off by default: docs/navigation.md) finds it.
        let drifted = DeadReckonedPose { x_m: 0.1, ..pose };
        let cfg = ScanMatchConfig {
            search_m: 0.1,
            ..ScanMatchConfig::default()
        };
        assert_eq!(
            align(&grid, &drifted, &points, &ScanMatchConfig::default()),
            None
        );
        let fix = align(&grid, &drifted, &points, &cfg).expect("a correction");
        assert!((fix.dx_m + 0.1).abs() < 0.051, "{fix:?}");
        assert!(fix.overlap > 0.5);
        // At the true pose nothing beats it.
        assert_eq!(align(&grid, &pose, &points, &cfg), None);
    }

    #[test]
    fn a_turn_held_while_blind_is_found_over_the_arc_turned() {
        let (grid, points) = corner_seen_from_origin();
        let pose = DeadReckonedPose::default();
        let cfg = ScanMatchConfig::default();
        // Dead reckoning turned 50 degrees left; the robot did not move.
        let turned = 50f64.to_radians();
        let believed = DeadReckonedPose {
            heading_rad: turned,
            ..pose
        };
        // The frame-to-frame search cannot reach it.
        assert_eq!(align(&grid, &believed, &points, &cfg), None);
        let fix = align_over_arc(&grid, &believed, &points, &cfg, turned).expect("a fix");
        assert!(
            (fix.dheading_rad + turned).abs() <= cfg.step_deg.to_radians() + 1e-9,
            "{fix:?}"
        );
        assert_eq!((fix.dx_m, fix.dy_m), (0.0, 0.0));
        // Searched only back along the turn: dead reckoning that turned left from -100 to
        // -50 degrees is not moved on past where it stands.
        let other = DeadReckonedPose {
            heading_rad: -turned,
            ..pose
        };
        assert_eq!(align_over_arc(&grid, &other, &points, &cfg, turned), None);
        // A turn that happened: nothing beats the dead-reckoned heading.
        assert_eq!(align_over_arc(&grid, &pose, &points, &cfg, turned), None);
    }

    /// Repeats the position refinement from `start` (as the explorer does, once a frame) and
    /// returns where it ends.
    fn settle(
        grid: &OccupancyGrid,
        start: DeadReckonedPose,
        points: &[(f64, f64)],
    ) -> DeadReckonedPose {
        let cfg = position_on();
        let mut pose = start;
        for _ in 0..200 {
            if let Some(fix) = refine_position(grid, &pose, points, &cfg) {
                assert!(fix.dx_m.hypot(fix.dy_m) <= cfg.position_max_step_m + 1e-12);
                pose.x_m += fix.dx_m;
                pose.y_m += fix.dy_m;
            }
        }
        pose
    }

    #[test]
    fn a_drifted_position_is_pulled_back_across_walls_but_not_along_a_hallway() {
        // Two walls 1.2 m apart along x (a hallway), seen from the origin.
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let pose = DeadReckonedPose::default();
        let hallway: Vec<(f64, f64)> = (0..30)
            .flat_map(|i| {
                let x = 0.3 + 0.06 * f64::from(i);
                [(x, 0.62), (x, -0.58)]
            })
            .collect();
        let insert = |grid: &mut OccupancyGrid, pts: &[(f64, f64)]| {
            for _ in 0..4 {
                grid.insert(&ScanPointsFor::hits(pts));
            }
        };
        insert(&mut grid, &hallway);
        // 0.12 m off sideways and 0.3 m along: the sideways error is corrected to within
        // half a cell, the error along the hallway is left alone.
        let drifted = DeadReckonedPose {
            x_m: 0.3,
            y_m: 0.12,
            ..pose
        };
        let end = settle(&grid, drifted, &hallway);
        assert!(end.y_m.abs() < 0.05, "{end:?}");
        assert!((end.x_m - 0.3).abs() < 1e-9, "{end:?}");
        // A wall across the end of the hallway constrains the other direction too.
        let mut cross: Vec<(f64, f64)> = hallway.clone();
        cross.extend((0..20).map(|i| (2.2, -0.55 + 0.06 * f64::from(i))));
        let mut grid = OccupancyGrid::new(GridConfig::default());
        insert(&mut grid, &cross);
        let drifted = DeadReckonedPose {
            x_m: -0.1,
            y_m: -0.1,
            ..pose
        };
        let end = settle(&grid, drifted, &cross);
        assert!(end.x_m.abs() < 0.05 && end.y_m.abs() < 0.05, "{end:?}");
        // Points far from every mapped wall are new surfaces: no correction.
        let far: Vec<(f64, f64)> = (0..30).map(|i| (1.0 + 0.05 * f64::from(i), 3.0)).collect();
        assert_eq!(refine_position(&grid, &pose, &far, &position_on()), None);
        // Off (the default): nothing.
        assert_eq!(
            refine_position(&grid, &drifted, &cross, &ScanMatchConfig::default()),
            None
        );
    }

    fn position_on() -> ScanMatchConfig {
        ScanMatchConfig {
            position: true,
            ..ScanMatchConfig::default()
        }
    }

    /// Scan points given directly (grid frame), with no rays.
    struct ScanPointsFor;
    impl ScanPointsFor {
        fn hits(pts: &[(f64, f64)]) -> crate::explore::grid::ScanPoints {
            crate::explore::grid::ScanPoints {
                camera: (0.0, 0.0),
                hits: pts.to_vec(),
                rays: Vec::new(),
            }
        }
    }
}
