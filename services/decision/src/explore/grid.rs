//! The world model: a log-odds occupancy grid in the dead-reckoned frame (the start pose is the
//! origin), built from the fusion stage's obstacle scans: each bin's ray makes the cells it
//! passes through freer, its end point's cell more occupied.
//!
//! Unlike [`crate::LocalMap`] (a short-lived wrapping map for the fuzzy policy) nothing here
//! expires: the scan matcher keeps the pose on the map instead. Written by hand for the same
//! reason: the grid crates on crates.io are ROS-bound or whole SLAM systems.

use hvs_runtime::config::GridConfig;
use hvs_shared::messages::{ObstacleScan, SCAN_BINS};

use crate::local_map::CellState;
use crate::odometry::DeadReckonedPose;

/// A cell index: column (x) and row (y).
pub type CellIndex = (usize, usize);

/// One scan's points in the grid frame, with the camera position they were seen from.
#[derive(Debug, Clone)]
pub struct ScanPoints {
    /// Camera position, metres.
    pub camera: (f64, f64),
    /// Points within the grid's range (metres, grid frame).
    pub hits: Vec<(f64, f64)>,
    /// Rays (unit direction, free length in metres) including those beyond the range.
    pub rays: Vec<((f64, f64), f64)>,
}

/// Calls `f` with the grid-frame position of every sample of the robot-frame rectangle
/// `ahead_m` x `left_m` (each a closed range, metres) seen from `pose`, `step_m` apart, row
/// by row from the rear: the one sampling that the footprint checks, the footprint clearing
/// and bumps share.
pub fn for_each_rect_sample(
    pose: &DeadReckonedPose,
    ahead_m: (f64, f64),
    left_m: (f64, f64),
    step_m: f64,
    mut f: impl FnMut(f64, f64),
) {
    let mut a = ahead_m.0;
    while a <= ahead_m.1 + 1e-9 {
        let mut l = left_m.0;
        while l <= left_m.1 + 1e-9 {
            let (x, y) = to_grid_frame(pose, (a, l));
            f(x, y);
            l += step_m;
        }
        a += step_m;
    }
}

/// Transforms a robot-frame point to the grid frame at `pose`.
pub fn to_grid_frame(pose: &DeadReckonedPose, p: (f64, f64)) -> (f64, f64) {
    let (s, c) = pose.heading_rad.sin_cos();
    (pose.x_m + p.0 * c - p.1 * s, pose.y_m + p.0 * s + p.1 * c)
}

/// The occupancy grid: a square of `side x side` cells centred on the start pose.
#[derive(Debug, Clone)]
pub struct OccupancyGrid {
    cfg: GridConfig,
    side: usize,
    log_odds: Vec<f32>,
    /// Scan points ever added per cell (saturating), for traces.
    hits: Vec<u16>,
    /// Cells ever updated (for bounding searches): min and max column and row.
    bounds: Option<(usize, usize, usize, usize)>,
    /// Scan bins below this one are not used (see [`OccupancyGrid::set_first_bin`]).
    first_bin: usize,
}

impl OccupancyGrid {
    /// An empty grid.
    pub fn new(cfg: GridConfig) -> Self {
        let side = ((cfg.extent_m / cfg.cell_m).ceil() as usize).max(8);
        Self {
            cfg,
            side,
            log_odds: vec![0.0; side * side],
            hits: vec![0; side * side],
            bounds: None,
            first_bin: 0,
        }
    }

    /// Writes every cell once (with its present value), so that later writes find their
    /// memory mapped (a fresh grid's is mapped page by page on first write).
    pub fn fault_in(&mut self) {
        // `black_box`: a store of the value just read must not be left out.
        for v in &mut self.log_odds {
            *v = std::hint::black_box(*v);
        }
        for v in &mut self.hits {
            *v = std::hint::black_box(*v);
        }
    }

    /// Makes this grid a copy of `other`, reusing this one's memory and copying only the
    /// cells either grid ever updated (outside them both hold the initial values). A
    /// fresh copy of the whole default grid (600 x 600 cells) measured 1-12 ms a frame,
    /// its pages faulted in one by one.
    pub fn copy_from(&mut self, other: &OccupancyGrid) {
        if self.side != other.side {
            *self = other.clone();
            return;
        }
        let union = match (self.bounds, other.bounds) {
            (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1), a.2.min(b.2), a.3.max(b.3))),
            (a, b) => a.or(b),
        };
        if let Some((c0, c1, r0, r1)) = union {
            for r in r0..=r1 {
                let row = r * self.side;
                let cells = row + c0..=row + c1;
                self.log_odds[cells.clone()].copy_from_slice(&other.log_odds[cells.clone()]);
                self.hits[cells.clone()].copy_from_slice(&other.hits[cells]);
            }
        }
        self.cfg = other.cfg;
        self.bounds = other.bounds;
        self.first_bin = other.first_bin;
    }

    /// Leaves out the scan's leftmost `bin` bins: a left-image pixel closer to the image's
    /// left edge than the matcher's largest disparity can only try the disparities whose
    /// match fits in the right image, so those columns read far walls where there are near
    /// ones, and their rays would clear walls the robot is next to.
    pub fn set_first_bin(&mut self, bin: usize) {
        self.first_bin = bin.min(SCAN_BINS);
    }

    /// Cell edge, metres.
    pub fn cell_m(&self) -> f64 {
        self.cfg.cell_m
    }

    /// Cells per side.
    pub fn side(&self) -> usize {
        self.side
    }

    /// The bounding box of every cell ever updated: `(col0, col1, row0, row1)` inclusive.
    pub fn bounds(&self) -> Option<(usize, usize, usize, usize)> {
        self.bounds
    }

    /// The cell holding a point, if inside the grid.
    pub fn cell_of(&self, x_m: f64, y_m: f64) -> Option<CellIndex> {
        let half = self.side as f64 * 0.5;
        let c = (x_m / self.cfg.cell_m + half).floor();
        let r = (y_m / self.cfg.cell_m + half).floor();
        if c < 0.0 || r < 0.0 || c >= self.side as f64 || r >= self.side as f64 {
            return None;
        }
        Some((c as usize, r as usize))
    }

    /// The centre of a cell, metres.
    pub fn centre(&self, (c, r): CellIndex) -> (f64, f64) {
        let half = self.side as f64 * 0.5;
        (
            (c as f64 + 0.5 - half) * self.cfg.cell_m,
            (r as f64 + 0.5 - half) * self.cfg.cell_m,
        )
    }

    /// A cell's log-odds.
    pub fn log_odds(&self, (c, r): CellIndex) -> f32 {
        self.log_odds[r * self.side + c]
    }

    /// A cell's state.
    pub fn state(&self, cell: CellIndex) -> CellState {
        let l = f64::from(self.log_odds(cell));
        if l > self.cfg.decided_log_odds {
            CellState::Occupied
        } else if l < -self.cfg.decided_log_odds {
            CellState::Free
        } else {
            CellState::Unknown
        }
    }

    /// Scan points ever added to the cell holding a point (outside the grid: 0), whatever
    /// rays made of the cell since: for traces (was a wall the robot touched ever seen?).
    pub fn hits_at(&self, x_m: f64, y_m: f64) -> u16 {
        self.cell_of(x_m, y_m)
            .map_or(0, |(c, r)| self.hits[r * self.side + c])
    }

    /// The state of the cell holding a point (outside the grid: unknown).
    pub fn state_at(&self, x_m: f64, y_m: f64) -> CellState {
        self.cell_of(x_m, y_m)
            .map_or(CellState::Unknown, |cell| self.state(cell))
    }

    fn update(&mut self, (c, r): CellIndex, delta: f64) {
        let i = r * self.side + c;
        let v = (f64::from(self.log_odds[i]) + delta)
            .clamp(self.cfg.min_log_odds, self.cfg.max_log_odds);
        self.log_odds[i] = v as f32;
        self.bounds = Some(match self.bounds {
            None => (c, c, r, r),
            Some((c0, c1, r0, r1)) => (c0.min(c), c1.max(c), r0.min(r), r1.max(r)),
        });
    }

    /// The scan bins the grid trusts, as robot-frame points `(ahead_m, left_m)` with their
    /// distance from the camera: not left of `first_bin`, and not a stray point (one that
    /// lies in no run of `support_run_bins` consecutive bins agreeing with its depth).
    fn trusted_bins(&self, scan: &ObstacleScan, camera_forward_m: f64) -> Vec<((f64, f64), f64)> {
        let r = &scan.range_m;
        let run = self.cfg.support_run_bins.max(2) as usize;
        let supported = |i: usize| {
            let d = f64::from(r[i]);
            let agrees = |j: usize| {
                let n = f64::from(r[j]);
                n > 0.0 && (n - d).abs() <= self.cfg.support_share * d + self.cfg.support_m
            };
            // Every window of `run` bins that holds bin i.
            (i.saturating_sub(run - 1)..=i)
                .filter(|&start| start + run <= SCAN_BINS)
                .any(|start| (start..start + run).all(|j| j == i || agrees(j)))
        };
        let mut out = Vec::with_capacity(SCAN_BINS);
        for (i, &range_m) in r.iter().enumerate().skip(self.first_bin) {
            let depth = f64::from(range_m);
            if depth <= 0.0 || !depth.is_finite() || !supported(i) {
                continue;
            }
            let t = scan.bin_tangent(i);
            out.push((
                (camera_forward_m + depth, depth * t),
                depth * (1.0 + t * t).sqrt(),
            ));
        }
        out
    }

    /// The scan's trusted points within the grid's range, robot frame (for the matcher).
    pub fn scan_hits_robot_frame(
        &self,
        scan: &ObstacleScan,
        camera_forward_m: f64,
    ) -> Vec<(f64, f64)> {
        self.trusted_bins(scan, camera_forward_m)
            .into_iter()
            .filter(|&(_, dist)| dist <= self.cfg.scan_range_m)
            .map(|(p, _)| p)
            .collect()
    }

    /// The first scan bin used.
    pub fn first_bin(&self) -> usize {
        self.first_bin
    }

    /// One scan's points and rays seen from `pose`, in the grid frame.
    pub fn scan_points(
        &self,
        pose: &DeadReckonedPose,
        camera_forward_m: f64,
        scan: &ObstacleScan,
    ) -> ScanPoints {
        let camera = to_grid_frame(pose, (camera_forward_m, 0.0));
        let bins = self.trusted_bins(scan, camera_forward_m);
        let mut hits = Vec::with_capacity(SCAN_BINS);
        let mut rays = Vec::with_capacity(SCAN_BINS);
        for &((ahead, left), dist) in &bins {
            let g = to_grid_frame(pose, (ahead, left));
            let d = (g.0 - camera.0).hypot(g.1 - camera.1).max(1e-9);
            let dir = ((g.0 - camera.0) / d, (g.1 - camera.1) / d);
            let mut free_m = if dist <= self.cfg.scan_range_m {
                hits.push(g);
                (dist * (1.0 - self.cfg.free_margin_share)).min(dist - self.cfg.cell_m)
            } else {
                self.cfg.scan_range_m
            };
            if self.cfg.ray_clearance_m > 0.0 {
                free_m = free_m.min(self.short_of_nearer_hits(
                    ((ahead - camera_forward_m) / dist, left / dist),
                    camera_forward_m,
                    &bins,
                ));
            }
            rays.push((dir, free_m));
        }
        ScanPoints { camera, hits, rays }
    }

    /// How far a ray (unit direction `u`, robot frame, from the camera) may mark free space
    /// before it passes within `ray_clearance_m` of another bin's nearer point: a ray
    /// that looks just past a wall's end would otherwise clear the cells of its corner.
    fn short_of_nearer_hits(
        &self,
        u: (f64, f64),
        camera_forward_m: f64,
        bins: &[((f64, f64), f64)],
    ) -> f64 {
        let clearance = self.cfg.ray_clearance_m;
        bins.iter()
            .filter(|&&(_, dist)| dist <= self.cfg.scan_range_m)
            .filter_map(|&((ahead, left), _)| {
                let (x, y) = (ahead - camera_forward_m, left);
                let along = x * u.0 + y * u.1;
                let across = (x * u.1 - y * u.0).abs();
                (along > 0.0 && across < clearance).then_some((along - clearance).max(0.0))
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// Adds one scan's points and rays.
    pub fn insert(&mut self, points: &ScanPoints) {
        let step = 0.5 * self.cfg.cell_m;
        let mut hit_cells: Vec<CellIndex> = points
            .hits
            .iter()
            .filter_map(|&(x, y)| self.cell_of(x, y))
            .collect();
        // Sorted once: every ray sample asks whether its cell holds a point.
        hit_cells.sort_unstable();
        hit_cells.dedup();
        let mut touched: Vec<CellIndex> = Vec::with_capacity(512);
        for &(dir, free_m) in &points.rays {
            let mut r = 0.0;
            let mut last = None;
            while r < free_m {
                let p = (points.camera.0 + r * dir.0, points.camera.1 + r * dir.1);
                r += step;
                let Some(cell) = self.cell_of(p.0, p.1) else {
                    break;
                };
                if Some(cell) == last || hit_cells.binary_search(&cell).is_ok() {
                    continue;
                }
                last = Some(cell);
                touched.push(cell);
            }
        }
        // Each cell is made freer once per scan, however many rays cross it (near the camera
        // every ray crosses the same few cells).
        touched.sort_unstable();
        touched.dedup();
        let miss = self.cfg.miss_log_odds;
        for cell in touched {
            // A wall fades slowly: a few stray rays do not open it.
            let delta = if f64::from(self.log_odds(cell)) > self.cfg.decided_log_odds {
                self.cfg.occupied_miss_share * miss
            } else {
                miss
            };
            self.update(cell, delta);
        }
        for cell in hit_cells {
            self.update(cell, self.cfg.hit_log_odds);
            let i = cell.1 * self.side + cell.0;
            self.hits[i] = self.hits[i].saturating_add(1);
        }
    }

    /// Marks the cells under the robot's footprint free (Nav2's footprint clearing): the
    /// robot stands there, and the camera, which looks ahead only, never sees them. The way
    /// the robot came stays known free for backing up. Cells already occupied are left as
    /// they are: the footprint's samples reach into cells only partly under the robot, and
    /// with a drifting pose a wall beside it (or a bump) must not be wiped.
    pub fn clear_footprint(
        &mut self,
        pose: &DeadReckonedPose,
        half_length_m: f64,
        half_width_m: f64,
    ) {
        for_each_rect_sample(
            pose,
            (-half_length_m, half_length_m),
            (-half_width_m, half_width_m),
            0.5 * self.cfg.cell_m,
            |x, y| {
                if let Some(cell) = self.cell_of(x, y) {
                    let now = f64::from(self.log_odds(cell));
                    if now <= self.cfg.decided_log_odds {
                        self.update(cell, self.cfg.min_log_odds - now);
                    }
                }
            },
        );
    }

    /// Marks the robot-frame rectangle `ahead_m` x `left_m` (each a closed range, metres; a
    /// segment when one range is a single value) occupied (a bump: the robot was stopped
    /// there by something the camera never saw).
    pub fn mark_bump(&mut self, pose: &DeadReckonedPose, ahead_m: (f64, f64), left_m: (f64, f64)) {
        for_each_rect_sample(pose, ahead_m, left_m, 0.5 * self.cfg.cell_m, |x, y| {
            if let Some(cell) = self.cell_of(x, y) {
                let now = f64::from(self.log_odds(cell));
                self.update(cell, self.cfg.max_log_odds - now);
            }
        });
    }

    /// Forgets the cells whose centre lies within `radius_m` of `(x_m, y_m)`: they become
    /// unknown, walls and bumps too (their scan-point counts stay, for the traces), except
    /// the occupied cells within `keep_occupied_m` (the walls a turn in place there checks).
    pub fn forget_disc(&mut self, (x_m, y_m): (f64, f64), radius_m: f64, keep_occupied_m: f64) {
        // The disc's bounding box in cells, clipped to the grid (the centre itself may lie
        // off it, the disc's edge still on it).
        let (half, last, cell_m) = (
            self.side as f64 * 0.5,
            self.side as f64 - 1.0,
            self.cfg.cell_m,
        );
        let span = |v_m: f64| {
            let lo = ((v_m - radius_m) / cell_m + half).floor().max(0.0);
            let hi = ((v_m + radius_m) / cell_m + half).floor().min(last);
            (lo, hi)
        };
        let ((c_lo, c_hi), (r_lo, r_hi)) = (span(x_m), span(y_m));
        if c_hi < c_lo || r_hi < r_lo {
            // Wholly off the grid (the clipped range must not wrap to cell 0).
            return;
        }
        for r in r_lo as usize..=r_hi as usize {
            for c in c_lo as usize..=c_hi as usize {
                let cell = (c, r);
                let (cx, cy) = self.centre(cell);
                let d = (cx - x_m).hypot(cy - y_m);
                let now = f64::from(self.log_odds(cell));
                let kept = d <= keep_occupied_m && self.state(cell) == CellState::Occupied;
                if d <= radius_m && !kept && now != 0.0 {
                    self.update(cell, -now);
                }
            }
        }
    }

    /// Whether a cell index is inside the grid after an offset.
    pub fn offset(&self, (c, r): CellIndex, dc: i64, dr: i64) -> Option<CellIndex> {
        let (c, r) = (c as i64 + dc, r as i64 + dr);
        if c < 0 || r < 0 || c >= self.side as i64 || r >= self.side as i64 {
            None
        } else {
            Some((c as usize, r as usize))
        }
    }

    /// An ASCII picture of the grid around a point (`#` occupied, `.` free, space unknown,
    /// `R` the point), north up, for traces.
    pub fn ascii(&self, x_m: f64, y_m: f64, half_m: f64) -> String {
        let n = (half_m / self.cfg.cell_m) as i64;
        let Some(centre) = self.cell_of(x_m, y_m) else {
            return String::new();
        };
        let mut out = String::new();
        for dr in (-n..=n).rev() {
            for dc in -n..=n {
                let ch = match self.offset(centre, dc, dr) {
                    None => ' ',
                    Some(_) if dc == 0 && dr == 0 => 'R',
                    Some(cell) => match self.state(cell) {
                        CellState::Occupied => '#',
                        CellState::Free => '.',
                        CellState::Unknown => ' ',
                    },
                };
                out.push(ch);
            }
            out.push('\n');
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wall_scan(depth_m: f32) -> ObstacleScan {
        let mut scan = ObstacleScan {
            tan_half_fov: 0.5,
            ..ObstacleScan::default()
        };
        for r in scan.range_m.iter_mut() {
            *r = depth_m;
        }
        scan
    }

    #[test]
    fn a_disc_whose_centre_lies_off_the_grid_forgets_the_cells_it_covers_on_it() {
        let mut grid = OccupancyGrid::new(GridConfig {
            extent_m: 4.0,
            ..GridConfig::default()
        });
        let cell_m = grid.cell_m();
        let edge_m = 0.5 * grid.side() as f64 * cell_m;
        let whole = |grid: &mut OccupancyGrid| {
            let pose = DeadReckonedPose::default();
            let far = edge_m + 1.0;
            grid.mark_bump(&pose, (-far, far), (-far, far));
        };
        let occupied =
            |grid: &OccupancyGrid, x_m: f64| grid.state_at(x_m, 0.0) == CellState::Occupied;
        whole(&mut grid);
        // Centred 0.2 m east of the grid's east edge, 0.5 m across: the last three
        // columns go, the fourth from the edge stays.
        grid.forget_disc((edge_m + 0.2, 0.0), 0.5, 0.0);
        assert!(!occupied(&grid, edge_m - 0.5 * cell_m));
        assert!(!occupied(&grid, edge_m - 2.5 * cell_m));
        assert!(occupied(&grid, edge_m - 3.5 * cell_m));
        // Wholly off the grid: nothing goes.
        whole(&mut grid);
        grid.forget_disc((-edge_m - 2.0, -edge_m - 2.0), 0.5, 0.0);
        grid.forget_disc((edge_m + 2.0, edge_m + 2.0), 0.5, 0.0);
        assert!(occupied(&grid, -edge_m + 0.5 * cell_m));
        assert!(occupied(&grid, edge_m - 0.5 * cell_m));
    }

    #[test]
    fn a_ray_past_a_walls_end_stops_short_of_its_corner_with_ray_clearance() {
        // The left half of the view a wall end 1 m ahead, the right half a wall 1.9 m
        // ahead: the right half's first rays pass the end's corner within a centimetre.
        let mut scan = wall_scan(1.9);
        for r in scan.range_m.iter_mut().take(SCAN_BINS / 2) {
            *r = 1.0;
        }
        let scanned = |ray_clearance_m: f64| {
            let mut grid = OccupancyGrid::new(GridConfig {
                ray_clearance_m,
                ..GridConfig::default()
            });
            for _ in 0..3 {
                let pts = grid.scan_points(&DeadReckonedPose::default(), 0.0, &scan);
                grid.insert(&pts);
            }
            grid
        };
        // Without: the cell behind the end's face, beside its corner, is cleared.
        let open = scanned(0.0);
        assert_eq!(open.state_at(1.05, -0.03), CellState::Free);
        // With: it stays unknown, and rays far from the end clear as before.
        let kept = scanned(0.1);
        assert_eq!(kept.state_at(1.05, -0.03), CellState::Unknown);
        assert_eq!(kept.state_at(1.05, 0.03), CellState::Occupied);
        assert_eq!(kept.state_at(1.2, -0.4), CellState::Free);
        assert_eq!(kept.state_at(0.5, 0.1), CellState::Free);
    }

    #[test]
    fn a_bin_is_trusted_only_inside_a_run_of_agreeing_bins() {
        // Bins 10-11 (two) and 20-22 (three) range a wall at 1 m; bin 30 ranges 1 m alone.
        let mut scan = wall_scan(0.0);
        for i in [10, 11, 20, 21, 22, 30] {
            scan.range_m[i] = 1.0;
        }
        let trusted = |scan: &ObstacleScan, support_run_bins: u32| {
            let grid = OccupancyGrid::new(GridConfig {
                support_run_bins,
                ..GridConfig::default()
            });
            grid.trusted_bins(scan, 0.0).len()
        };
        // One agreeing neighbour is enough by default: the pair and the three, not bin 30.
        assert_eq!(trusted(&scan, 2), 5);
        // A run of three: only the three.
        assert_eq!(trusted(&scan, 3), 3);
        assert_eq!(trusted(&scan, 4), 0);
        // A neighbour at another depth breaks the run.
        scan.range_m[21] = 1.5;
        assert_eq!(trusted(&scan, 3), 0);
        assert_eq!(trusted(&scan, 2), 2);
    }

    #[test]
    fn a_wall_ahead_is_occupied_and_the_way_to_it_free() {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let pose = DeadReckonedPose::default();
        for _ in 0..3 {
            let pts = grid.scan_points(&pose, 0.2, &wall_scan(1.5));
            grid.insert(&pts);
        }
        assert_eq!(grid.state_at(1.75, 0.0), CellState::Occupied);
        assert_eq!(grid.state_at(1.0, 0.0), CellState::Free);
        assert_eq!(grid.state_at(2.5, 0.0), CellState::Unknown);
        assert_eq!(grid.state_at(1.0, 2.0), CellState::Unknown);
        // Turned left by 90 degrees, the same scan lands north.
        let turned = DeadReckonedPose {
            heading_rad: std::f64::consts::FRAC_PI_2,
            ..pose
        };
        for _ in 0..3 {
            let pts = grid.scan_points(&turned, 0.2, &wall_scan(1.5));
            grid.insert(&pts);
        }
        assert_eq!(grid.state_at(0.0, 1.75), CellState::Occupied);
    }

    #[test]
    fn rays_beyond_the_range_mark_free_but_no_wall() {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        for _ in 0..3 {
            let pts = grid.scan_points(&DeadReckonedPose::default(), 0.2, &wall_scan(5.0));
            grid.insert(&pts);
        }
        assert_eq!(grid.state_at(1.8, 0.0), CellState::Free);
        assert_eq!(grid.state_at(3.0, 0.0), CellState::Unknown);
        assert_eq!(grid.state_at(5.2, 0.0), CellState::Unknown);
    }

    #[test]
    fn the_robots_footprint_is_cleared_of_unknown_cells_and_nothing_beside_it() {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        // A stray wall under the robot (a wrong match), another 0.5 m to its left.
        let pose = DeadReckonedPose::default();
        for _ in 0..6 {
            for p in [(0.05, 0.0), (0.05, 0.5)] {
                let pts = ScanPoints {
                    camera: (-1.0, p.1),
                    hits: vec![p],
                    rays: vec![],
                };
                grid.insert(&pts);
            }
        }
        assert_eq!(grid.state_at(0.05, 0.0), CellState::Occupied);
        assert_eq!(grid.state_at(0.05, 0.5), CellState::Occupied);
        assert_eq!(grid.state_at(-0.2, 0.0), CellState::Unknown);
        grid.clear_footprint(&pose, 0.22, 0.15);
        // Unknown under the robot: free now. A wall under it stays (a drifting pose must not
        // wipe walls beside the robot).
        assert_eq!(grid.state_at(-0.2, 0.0), CellState::Free);
        assert_eq!(grid.state_at(0.05, 0.0), CellState::Occupied);
        assert_eq!(grid.state_at(0.05, 0.5), CellState::Occupied);
        assert_eq!(grid.state_at(0.4, 0.0), CellState::Unknown);
    }

    #[test]
    fn a_copy_into_a_used_grid_equals_the_original_everywhere() {
        let mut a = OccupancyGrid::new(GridConfig::default());
        let mut b = OccupancyGrid::new(GridConfig::default());
        let here = DeadReckonedPose::default();
        let far = DeadReckonedPose {
            x_m: 5.0,
            y_m: -4.0,
            heading_rad: 1.0,
        };
        a.mark_bump(&here, (0.5, 0.8), (-0.3, 0.3));
        // b was used elsewhere: its cells there must not survive the copy.
        b.mark_bump(&far, (0.5, 0.8), (-0.3, 0.3));
        b.copy_from(&a);
        assert_eq!(b.log_odds, a.log_odds);
        assert_eq!(b.hits, a.hits);
        assert_eq!(b.bounds(), a.bounds());
    }

    #[test]
    fn a_cell_cleared_by_rays_keeps_its_count_of_scan_points() {
        // A wall point seen three times, then rays through its cell from the side (a
        // grazing look past it) until the grid holds it free.
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let wall = (0.55, 0.05);
        for _ in 0..3 {
            grid.insert(&ScanPoints {
                camera: (-1.0, 0.05),
                hits: vec![wall],
                rays: vec![],
            });
        }
        assert_eq!(grid.state_at(wall.0, wall.1), CellState::Occupied);
        for _ in 0..40 {
            grid.insert(&ScanPoints {
                camera: (0.55, -1.0),
                hits: vec![],
                rays: vec![((0.0, 1.0), 2.0)],
            });
        }
        assert_eq!(grid.state_at(wall.0, wall.1), CellState::Free);
        assert_eq!(grid.hits_at(wall.0, wall.1), 3);
        assert_eq!(grid.hits_at(wall.0, -0.5), 0);
    }
}
