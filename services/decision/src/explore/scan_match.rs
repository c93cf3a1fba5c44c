//! Drift correction: before a scan is added, the dead-reckoned pose is searched over a small
//! window (heading, and x and y when `search_m` is above 0: by default it is 0) for the pose
//! at which the scan's points fall best on the grid's occupied cells (a brute-force
//! correlative matcher, as in Olson's real-time correlative scan matching, without the
//! multi-resolution step: the window is small).

use hvs_runtime::config::ScanMatchConfig;

use super::grid::{OccupancyGrid, to_grid_frame};
use crate::local_map::CellState;
use crate::odometry::DeadReckonedPose;

/// Share by which the best pose's score must beat the dead-reckoned pose's.
const MIN_GAIN: f64 = 0.15;

/// A found correction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseCorrection {
    /// Metres east (grid frame).
    pub dx_m: f64,
    /// Metres north.
    pub dy_m: f64,
    /// Radians counter-clockwise.
    pub dheading_rad: f64,
    /// Share of the points on occupied cells at the corrected pose.
    pub overlap: f64,
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
    let (base, _) = score(grid, pose, points);
    let nxy = (cfg.search_m / cfg.step_m).floor() as i64;
    let nth = (cfg.search_deg / cfg.step_deg).floor() as i64;
    let mut best: Option<(f64, usize, f64, f64, f64)> = None;
    for it in -nth..=nth {
        let dth = (it as f64 * cfg.step_deg).to_radians();
        for ix in -nxy..=nxy {
            for iy in -nxy..=nxy {
                let (dx, dy) = (ix as f64 * cfg.step_m, iy as f64 * cfg.step_m);
                let cand = DeadReckonedPose {
                    x_m: pose.x_m + dx,
                    y_m: pose.y_m + dy,
                    heading_rad: pose.heading_rad + dth,
                };
                let (s, on) = score(grid, &cand, points);
                // Ties go to the smaller correction.
                let size = dx.hypot(dy) + 0.1 * dth.abs();
                let better = match best {
                    None => true,
                    Some((bs, _, bx, by, bt)) => {
                        s > bs + 1e-9
                            || ((s - bs).abs() <= 1e-9 && size < bx.hypot(by) + 0.1 * bt.abs())
                    }
                };
                if better {
                    best = Some((s, on, dx, dy, dth));
                }
            }
        }
    }
    let (s, on, dx, dy, dth) = best?;
    let overlap = on as f64 / points.len() as f64;
    // A better fit must be clearly better: among near-equal fits the noise picks one, and
    // following it would walk the pose at random.
    if overlap < cfg.min_overlap || s <= base * (1.0 + MIN_GAIN) + 1e-9 {
        return None;
    }
    Some(PoseCorrection {
        dx_m: dx,
        dy_m: dy,
        dheading_rad: dth,
        overlap,
    })
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

    #[test]
    fn a_shifted_pose_is_pulled_back_onto_the_map() {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let pose = DeadReckonedPose::default();
        for _ in 0..4 {
            let pts = grid.scan_points(&pose, 0.2, &corner_scan());
            grid.insert(&pts);
        }
        let points = grid.scan_hits_robot_frame(&corner_scan(), 0.2);
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
}
