//! A short-term occupancy grid around the robot, in the dead-reckoned frame, built from the
//! fusion stage's obstacle scans; and a heading fix from the walls' directions.
//!
//! The camera sees 53 degrees ahead; the grid remembers what it saw so the navigator knows
//! where the walls beside and behind it are (clearance, centring, turning in place) and where a
//! side opening is. Dead reckoning drifts, so cells older than `max_age` read as unknown: the
//! grid is a local map, not a global one (the visit grid is the long-term memory).
//!
//! Written by hand: the occupancy grid crates on crates.io are either ROS-bound or whole SLAM
//! systems; what is needed here is 150 lines of log-odds over a wrapping array.

use hvs_shared::messages::{ObstacleScan, SCAN_BINS};

use crate::odometry::DeadReckonedPose;

/// Log-odds added to a cell that holds a scan point: two make an unseen cell occupied (with
/// one, a stray scan point made a phantom wall that kept the robot from lining up with an
/// opening, and it turned off the opening into a wall stub).
const HIT: f32 = 0.5;
/// Log-odds added to a cell a scan ray passed through.
const MISS: f32 = -0.4;
/// Log-odds limits (a wall can be cleared by about 8 frames of free rays, a free cell made
/// occupied by 6 hits).
const LOG_ODDS_MIN: f32 = -2.0;
const LOG_ODDS_MAX: f32 = 3.5;
/// A cell is occupied above this log-odds and free below its negative.
const DECIDED: f32 = 0.6;
/// Share of a ray's length before its point that is not marked free.
const FREE_MARGIN: f64 = 0.15;
/// A ray stops marking free this many cells (measured across the wall) before the wall its
/// point lies on.
const GRAZE_CLEAR_CELLS: f64 = 1.5;
/// Neighbouring scan points farther apart than this are not taken for one wall.
const SAME_WALL_M: f64 = 0.3;
/// Cells per side of the wrapping array (a power of two).
const SIDE: usize = 256;

/// What the grid knows about a place.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CellState {
    /// Not seen recently, or seen both ways.
    Unknown,
    /// Scan rays passed through it.
    Free,
    /// Scan points fell in it.
    Occupied,
}

#[derive(Debug, Clone, Copy)]
struct Cell {
    key: (i32, i32),
    log_odds: f32,
    stamp_ns: u64,
}

/// The local occupancy grid (wrapping: a cell is reused by the place 256 cells away, and its
/// key says which place it holds).
#[derive(Debug, Clone)]
pub struct LocalMap {
    cell_m: f64,
    max_age_ns: u64,
    cells: Vec<Cell>,
}

/// Counts of cell states over a region.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RegionCount {
    /// Free cells.
    pub free: u32,
    /// Occupied cells.
    pub occupied: u32,
    /// Unknown cells.
    pub unknown: u32,
}

impl LocalMap {
    /// An empty map of `cell_m` cells whose cells expire after `max_age_s`.
    pub fn new(cell_m: f64, max_age_s: f64) -> Self {
        Self {
            cell_m,
            max_age_ns: (max_age_s * 1e9) as u64,
            cells: vec![
                Cell {
                    key: (i32::MIN, i32::MIN),
                    log_odds: 0.0,
                    stamp_ns: 0,
                };
                SIDE * SIDE
            ],
        }
    }

    fn key(&self, x_m: f64, y_m: f64) -> (i32, i32) {
        (
            (x_m / self.cell_m).floor() as i32,
            (y_m / self.cell_m).floor() as i32,
        )
    }

    fn slot(key: (i32, i32)) -> usize {
        (key.0.rem_euclid(SIDE as i32) as usize) * SIDE + key.1.rem_euclid(SIDE as i32) as usize
    }

    /// Whether a cell holds `key` and was updated within the age limit.
    fn is_live(&self, cell: &Cell, key: (i32, i32), now_ns: u64) -> bool {
        cell.key == key && now_ns.saturating_sub(cell.stamp_ns) <= self.max_age_ns
    }

    fn update(&mut self, key: (i32, i32), delta: f32, now_ns: u64) {
        let slot = Self::slot(key);
        let live = self.is_live(&self.cells[slot], key, now_ns);
        let cell = &mut self.cells[slot];
        if !live {
            *cell = Cell {
                key,
                log_odds: 0.0,
                stamp_ns: now_ns,
            };
        }
        cell.log_odds = (cell.log_odds + delta).clamp(LOG_ODDS_MIN, LOG_ODDS_MAX);
        cell.stamp_ns = now_ns;
    }

    /// A cell's log-odds; 0 (undecided) when it is not live.
    fn log_odds(&self, key: (i32, i32), now_ns: u64) -> f32 {
        let cell = &self.cells[Self::slot(key)];
        if self.is_live(cell, key, now_ns) {
            cell.log_odds
        } else {
            0.0
        }
    }

    /// The state of the cell containing a point of the map frame.
    pub fn state(&self, x_m: f64, y_m: f64, now_ns: u64) -> CellState {
        let log_odds = self.log_odds(self.key(x_m, y_m), now_ns);
        if log_odds > DECIDED {
            CellState::Occupied
        } else if log_odds < -DECIDED {
            CellState::Free
        } else {
            CellState::Unknown
        }
    }

    /// The state at a point given in the robot's frame (`ahead_m`, `left_m` from its turning
    /// centre).
    pub fn state_around(
        &self,
        pose: &DeadReckonedPose,
        ahead_m: f64,
        left_m: f64,
        now_ns: u64,
    ) -> CellState {
        let (s, c) = pose.heading_rad.sin_cos();
        self.state(
            pose.x_m + ahead_m * c - left_m * s,
            pose.y_m + ahead_m * s + left_m * c,
            now_ns,
        )
    }

    /// Cell states over a rectangle of the robot's frame, sampled every half cell (a cell can
    /// count more than once).
    pub fn count_region(
        &self,
        pose: &DeadReckonedPose,
        ahead_m: (f64, f64),
        left_m: (f64, f64),
        now_ns: u64,
    ) -> RegionCount {
        let step = 0.5 * self.cell_m;
        let mut n = RegionCount::default();
        let mut a = ahead_m.0;
        while a <= ahead_m.1 + 1e-9 {
            let mut l = left_m.0;
            while l <= left_m.1 + 1e-9 {
                match self.state_around(pose, a, l, now_ns) {
                    CellState::Free => n.free += 1,
                    CellState::Occupied => n.occupied += 1,
                    CellState::Unknown => n.unknown += 1,
                }
                l += step;
            }
            a += step;
        }
        n
    }

    /// The nearest occupied point within `radius_m` of the robot's turning centre, as
    /// `(ahead_m, left_m)` in its frame, sampled every half cell.
    pub fn nearest_occupied(
        &self,
        pose: &DeadReckonedPose,
        radius_m: f64,
        now_ns: u64,
    ) -> Option<(f64, f64)> {
        let step = 0.5 * self.cell_m;
        let n = (radius_m / step).ceil() as i32;
        let mut best: Option<(f64, f64, f64)> = None;
        for i in -n..=n {
            for j in -n..=n {
                let (a, l) = (f64::from(i) * step, f64::from(j) * step);
                let d = a.hypot(l);
                if d <= radius_m
                    && best.is_none_or(|b| d < b.2)
                    && self.state_around(pose, a, l, now_ns) == CellState::Occupied
                {
                    best = Some((a, l, d));
                }
            }
        }
        best.map(|(a, l, _)| (a, l))
    }

    /// The nearest occupied point's lateral distance on one side (`left` or right) within
    /// `ahead_m` of the robot's centre and `max_m` to the side, sampled every half cell.
    pub fn side_distance(
        &self,
        pose: &DeadReckonedPose,
        left: bool,
        ahead_m: (f64, f64),
        max_m: f64,
        now_ns: u64,
    ) -> Option<f64> {
        let step = 0.5 * self.cell_m;
        let sign = if left { 1.0 } else { -1.0 };
        let mut l = 0.0;
        while l <= max_m {
            let mut a = ahead_m.0;
            while a <= ahead_m.1 + 1e-9 {
                if self.state_around(pose, a, sign * l, now_ns) == CellState::Occupied {
                    return Some(l);
                }
                a += step;
            }
            l += step;
        }
        None
    }

    /// The map around a point as text, north (+y) up: `#` occupied, `.` free, ` ` unknown,
    /// `R` the point; `half_m` metres each way. For traces and debugging.
    pub fn ascii(&self, x_m: f64, y_m: f64, half_m: f64, now_ns: u64) -> String {
        let n = (half_m / self.cell_m).round() as i64;
        let (cx, cy) = self.key(x_m, y_m);
        let mut out = String::new();
        for dy in (-n..=n).rev() {
            for dx in -n..=n {
                let (x, y) = (
                    (cx as i64 + dx) as f64 * self.cell_m + 0.5 * self.cell_m,
                    (cy as i64 + dy) as f64 * self.cell_m + 0.5 * self.cell_m,
                );
                out.push(if dx == 0 && dy == 0 {
                    'R'
                } else {
                    match self.state(x, y, now_ns) {
                        CellState::Occupied => '#',
                        CellState::Free => '.',
                        CellState::Unknown => ' ',
                    }
                });
            }
            out.push('\n');
        }
        out
    }

    /// Adds one scan seen from `pose` with the camera `camera_forward_m` ahead of the turning
    /// centre: the cells along each bin's ray become freer up to its point (at most `max_m`
    /// away), the point's cell more occupied.
    pub fn insert_scan(
        &mut self,
        pose: &DeadReckonedPose,
        camera_forward_m: f64,
        scan: &ObstacleScan,
        max_m: f64,
        now_ns: u64,
    ) {
        let (s, c) = pose.heading_rad.sin_cos();
        let cam = (
            pose.x_m + camera_forward_m * c,
            pose.y_m + camera_forward_m * s,
        );
        let step = 0.5 * self.cell_m;
        // Rays in the map frame: (unit direction, length, whether it ends on a point within
        // reach).
        let mut rays = [((0.0, 0.0), 0.0, false); SCAN_BINS];
        let mut points: [Option<(f64, f64)>; SCAN_BINS] = [None; SCAN_BINS];
        let mut hits = Vec::with_capacity(SCAN_BINS);
        for (i, ray) in rays.iter_mut().enumerate() {
            let depth = scan.range_m[i] as f64;
            if depth <= 0.0 || !depth.is_finite() {
                continue;
            }
            let t = scan.bin_tangent(i);
            let norm = (1.0 + t * t).sqrt();
            let (rf, rl) = (1.0 / norm, t / norm);
            let dir = (rf * c - rl * s, rf * s + rl * c);
            let dist = depth * norm;
            let hit = dist <= max_m;
            *ray = (dir, dist.min(max_m), hit);
            if hit {
                let p = (cam.0 + dist * dir.0, cam.1 + dist * dir.1);
                points[i] = Some(p);
                hits.push(self.key(p.0, p.1));
            }
        }
        // Free space along each ray, except in cells this scan hit: rays that graze a wall
        // seen at a slant pass through the cells its other points fell in, and would erase it.
        for (i, &(dir, dist, hit)) in rays.iter().enumerate() {
            if dist <= 0.0 {
                continue;
            }
            // A ray that hits a wall at a slant runs beside it for its last stretch; stop
            // short of the point by a share of the range so that it does not clear the wall.
            let mut free_to = if hit {
                (dist * (1.0 - FREE_MARGIN)).min(dist - self.cell_m)
            } else {
                dist
            };
            if let Some(sin_inc) = incidence_sin(&points, i, dir) {
                free_to = free_to.min(dist - GRAZE_CLEAR_CELLS * self.cell_m / sin_inc.max(0.05));
            }
            let mut last = None;
            let mut r = 0.0;
            while r < free_to {
                let key = self.key(cam.0 + r * dir.0, cam.1 + r * dir.1);
                if Some(key) != last && !hits.contains(&key) {
                    // A wall fades slowly: one stray ray does not open it.
                    let miss = if self.log_odds(key, now_ns) > DECIDED {
                        0.25 * MISS
                    } else {
                        MISS
                    };
                    self.update(key, miss, now_ns);
                    last = Some(key);
                }
                r += step;
            }
        }
        for key in hits {
            self.update(key, HIT, now_ns);
        }
    }
}

/// The sine of the angle at which bin `i`'s ray (unit direction `dir`) meets the wall its
/// point lies on, the wall drawn through the neighbouring bins' points (the nearer one within
/// `SAME_WALL_M`); `None` when the point has no such neighbour.
fn incidence_sin(points: &[Option<(f64, f64)>], i: usize, dir: (f64, f64)) -> Option<f64> {
    let p = points[i]?;
    let neighbour = [i.checked_sub(1), Some(i + 1)]
        .into_iter()
        .flatten()
        .filter_map(|j| points.get(j).copied().flatten())
        .map(|q| (q, (q.0 - p.0).hypot(q.1 - p.1)))
        .filter(|&(_, d)| d > 1e-9 && d <= SAME_WALL_M)
        .min_by(|a, b| a.1.total_cmp(&b.1))?;
    let ((qx, qy), d) = neighbour;
    let seg = ((qx - p.0) / d, (qy - p.1) / d);
    Some((dir.0 * seg.1 - dir.1 * seg.0).abs())
}

/// The walls' direction in a scan: indoor walls meet at right angles, so segments between scan
/// points, folded modulo 90 degrees, pile up at one angle: the robot's heading error relative
/// to the building's axes. Returns that angle (radians, in (-45, 45] degrees: a wall running at
/// `+a` in the robot's frame means the robot is turned `-a` from an axis) when at least
/// `min_votes` segments agree within 4 degrees and they are at least 40 % of all.
pub fn wall_direction(scan: &ObstacleScan, max_m: f64, min_votes: usize) -> Option<f64> {
    let points: Vec<Option<(f64, f64)>> = (0..SCAN_BINS)
        .map(|i| {
            let d = scan.range_m[i] as f64;
            (d > 0.0 && d <= max_m).then(|| (d, d * scan.bin_tangent(i)))
        })
        .collect();
    // Angles of segments between points at least 4 bins apart and 0.15 to 1.2 m long, times
    // 4 (so that directions 90 degrees apart coincide), in 2-degree bins. (With at most 12
    // bins apart, a wall nearer than 0.8 m had no segment 0.15 m long: adjacent bins are
    // 0.0125 m apart there. The few segments left, from the wall to a point seen past its
    // end, voted for 29 degrees, and a robot facing a flat wall turned its dead-reckoned
    // heading 14 degrees off.)
    const BINS: usize = 180;
    let mut hist = [0u32; BINS];
    let mut folded = Vec::new();
    for i in 0..SCAN_BINS {
        let Some(p) = points[i] else { continue };
        for q in points.iter().skip(i + 4).flatten() {
            let (dx, dy) = (q.0 - p.0, q.1 - p.1);
            let len = dx.hypot(dy);
            if !(0.15..=1.2).contains(&len) {
                continue;
            }
            let a4 = (4.0 * dy.atan2(dx)).rem_euclid(std::f64::consts::TAU);
            let bin = ((a4 / std::f64::consts::TAU * BINS as f64) as usize).min(BINS - 1);
            hist[bin] += 1;
            folded.push(a4);
        }
    }
    if folded.len() < min_votes {
        return None;
    }
    // The densest 4 (x4 = 16) degree arc: bins of 2 (x4) degrees, 8 of them, wrapping.
    let (peak, votes) = (0..BINS)
        .map(|b| (b, (0..8).map(|k| hist[(b + k) % BINS]).sum::<u32>()))
        .max_by_key(|&(_, v)| v)?;
    if (votes as usize) < min_votes || (votes as f64) < 0.4 * folded.len() as f64 {
        return None;
    }
    // Circular mean of the votes in that arc.
    let centre = (peak as f64 + 4.0) / BINS as f64 * std::f64::consts::TAU;
    let (mut sx, mut sy) = (0.0, 0.0);
    for a in folded {
        let d = (a - centre + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        if d.abs() <= 16f64.to_radians() {
            sx += a.cos();
            sy += a.sin();
        }
    }
    let a4 = sy.atan2(sx);
    Some(a4 / 4.0)
}

/// Synthetic obstacle scans for the tests of this module and of the navigator.
#[cfg(test)]
pub(crate) mod test_scans {
    use super::*;

    /// The scan the camera (`forward_m` ahead of the turning centre at `pose`) sees of walls
    /// along the x axis, each at `y` from `x` on (`side_walls`: `(y_m, from_x_m)`), and of a
    /// front wall at `x = front_x_m`.
    pub(crate) fn scan_of_hallway(
        pose: DeadReckonedPose,
        forward_m: f64,
        side_walls: &[(f64, f64)],
        front_x_m: f64,
    ) -> ObstacleScan {
        let mut scan = ObstacleScan {
            tan_half_fov: 0.5,
            ..ObstacleScan::default()
        };
        let (s, c) = pose.heading_rad.sin_cos();
        let cam = (pose.x_m + forward_m * c, pose.y_m + forward_m * s);
        for i in 0..SCAN_BINS {
            let bearing = scan.bin_tangent(i).atan();
            let (ds, dc) = (pose.heading_rad + bearing).sin_cos();
            let mut along = f64::INFINITY;
            for &(wall_y_m, from_x_m) in side_walls {
                let d = (wall_y_m - cam.1) / ds;
                if ds.abs() > 1e-6 && d > 0.0 && cam.0 + d * dc >= from_x_m {
                    along = along.min(d);
                }
            }
            if dc > 1e-6 {
                along = along.min((front_x_m - cam.0) / dc);
            }
            if along.is_finite() {
                scan.range_m[i] = (along * bearing.cos()) as f32;
            }
        }
        scan
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scan a camera at the origin sees of a wall `d` m ahead, turned `yaw` (the wall's
    /// direction in the camera frame), plus a side wall `side` m to the left, parallel to it.
    fn scan_of_walls(front_m: f64, yaw_rad: f64, side_left_m: Option<f64>) -> ObstacleScan {
        let mut scan = ObstacleScan {
            tan_half_fov: 0.5,
            ..ObstacleScan::default()
        };
        // Wall lines: points p with n . p = dist, n the unit normal.
        let front_n = (yaw_rad.cos(), yaw_rad.sin());
        let side_n = (-yaw_rad.sin(), yaw_rad.cos());
        for i in 0..SCAN_BINS {
            let t = scan.bin_tangent(i);
            // Ray (1, t) * depth: depth = dist / (n . (1, t)).
            let mut best = f64::INFINITY;
            for (n, dist) in [(front_n, Some(front_m)), (side_n, side_left_m)] {
                let Some(dist) = dist else { continue };
                let dot = n.0 + n.1 * t;
                if dot > 1e-6 {
                    best = best.min(dist / dot);
                }
            }
            if best.is_finite() {
                scan.range_m[i] = best as f32;
            }
        }
        scan
    }

    #[test]
    fn wall_direction_reads_the_yaw_of_a_front_wall_and_a_side_wall() {
        for yaw_deg in [-20.0f64, -7.0, 0.0, 3.0, 12.0, 30.0] {
            let scan = scan_of_walls(1.5, yaw_deg.to_radians(), Some(0.6));
            let got = wall_direction(&scan, 4.0, 8).expect("walls give a direction");
            // The front wall runs at yaw + 90 degrees, the side wall at yaw: both fold to yaw.
            assert!(
                (got.to_degrees() - yaw_deg).abs() < 1.0,
                "yaw {yaw_deg}: {}",
                got.to_degrees()
            );
        }
    }

    #[test]
    fn wall_direction_reads_a_near_front_wall_with_points_seen_past_its_end() {
        for front_m in [0.4, 0.6, 0.8, 1.0] {
            for yaw_deg in [-5.0f64, 0.0, 3.0] {
                let mut scan = scan_of_walls(front_m, yaw_deg.to_radians(), None);
                // The far side of an opening beside the wall, seen past its end.
                scan.range_m[2] = 1.70;
                scan.range_m[3] = 1.65;
                let got = wall_direction(&scan, 3.0, 12).map(f64::to_degrees);
                assert!(
                    got.is_some_and(|a| (a - yaw_deg).abs() < 1.0),
                    "front {front_m} m, yaw {yaw_deg}: {got:?}"
                );
            }
        }
    }

    #[test]
    fn wall_direction_needs_agreeing_segments() {
        // Scattered points: no direction.
        let mut scan = ObstacleScan {
            tan_half_fov: 0.5,
            ..ObstacleScan::default()
        };
        let mut seed = 7u32;
        for r in scan.range_m.iter_mut() {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            *r = 0.5 + 3.0 * (seed >> 8) as f32 / (1u32 << 24) as f32;
        }
        assert_eq!(wall_direction(&scan, 4.0, 8), None);
        assert_eq!(wall_direction(&ObstacleScan::default(), 4.0, 8), None);
    }

    #[test]
    fn a_scan_marks_the_wall_occupied_and_the_space_before_it_free() {
        let mut map = LocalMap::new(0.1, 10.0);
        let pose = DeadReckonedPose::default();
        let scan = scan_of_walls(1.05, 0.0, None);
        map.insert_scan(&pose, 0.2, &scan, 4.0, 1);
        map.insert_scan(&pose, 0.2, &scan, 4.0, 2);
        // Camera at x = 0.2: the wall is at x = 1.25.
        assert_eq!(map.state(1.25, 0.0, 2), CellState::Occupied);
        assert_eq!(map.state(0.7, 0.05, 2), CellState::Free);
        // Behind the wall and outside the field of view: unknown.
        assert_eq!(map.state(1.6, 0.0, 2), CellState::Unknown);
        assert_eq!(map.state(0.5, 1.5, 2), CellState::Unknown);
        // In the robot's frame, turned: the same place.
        let turned = DeadReckonedPose {
            x_m: 0.0,
            y_m: 0.0,
            heading_rad: std::f64::consts::FRAC_PI_2,
        };
        assert_eq!(
            map.state_around(&turned, 0.0, -1.25, 2),
            CellState::Occupied
        );
        // Cells expire.
        assert_eq!(map.state(1.25, 0.0, 2 + 11_000_000_000), CellState::Unknown);
        let right = map.side_distance(&turned, false, (-0.1, 0.1), 2.0, 2);
        assert!(
            right.is_some_and(|d| (1.15..=1.3).contains(&d)),
            "{right:?}"
        );
        // The wall is the nearest occupied point, straight ahead, once the radius reaches it.
        assert_eq!(map.nearest_occupied(&pose, 1.0, 2), None);
        let near = map.nearest_occupied(&pose, 1.4, 2);
        assert!(
            near.is_some_and(|(a, l)| (1.15..=1.3).contains(&a) && l.abs() < 0.1),
            "{near:?}"
        );
    }

    #[test]
    fn one_stray_scan_point_does_not_make_a_wall_two_do() {
        let mut map = LocalMap::new(0.1, 10.0);
        map.update((3, 4), HIT, 1);
        assert_eq!(map.state(0.35, 0.45, 1), CellState::Unknown);
        map.update((3, 4), HIT, 2);
        assert_eq!(map.state(0.35, 0.45, 2), CellState::Occupied);
    }

    #[test]
    fn the_map_wraps_without_confusing_places() {
        let mut map = LocalMap::new(0.1, 10.0);
        map.update((3, 4), HIT, 1);
        map.update((3, 4), HIT, 1);
        assert_eq!(map.state(0.35, 0.45, 1), CellState::Occupied);
        // 256 cells away shares the slot but is another place.
        assert_eq!(map.state(0.35 + 25.6, 0.45, 1), CellState::Unknown);
        map.update((3 + 256, 4), MISS, 2);
        map.update((3 + 256, 4), MISS, 2);
        assert_eq!(map.state(0.35 + 25.6, 0.45, 2), CellState::Free);
        assert_eq!(map.state(0.35, 0.45, 2), CellState::Unknown);
    }

    /// Drives the robot 1.5 m along +x from the origin, heading `yaw_rad`, past a wall along
    /// the x axis at `wall_y_m` (left), 0.02 m a frame, with a front wall at x = 4 m; returns
    /// the map and the final pose and time.
    fn drive_past_a_side_wall(wall_y_m: f64, yaw_rad: f64) -> (LocalMap, DeadReckonedPose, u64) {
        const CAMERA_FORWARD_M: f64 = 0.2;
        let mut map = LocalMap::new(0.1, 20.0);
        let mut pose = DeadReckonedPose {
            x_m: 0.0,
            y_m: 0.0,
            heading_rad: yaw_rad,
        };
        let mut now_ns = 1;
        while pose.x_m < 1.5 {
            // The side wall runs along the whole drive.
            let scan = test_scans::scan_of_hallway(
                pose,
                CAMERA_FORWARD_M,
                &[(wall_y_m, f64::NEG_INFINITY)],
                4.0,
            );
            map.insert_scan(&pose, CAMERA_FORWARD_M, &scan, 3.0, now_ns);
            now_ns += 66_000_000;
            pose.x_m += 0.02 * yaw_rad.cos();
            pose.y_m += 0.02 * yaw_rad.sin();
        }
        (map, pose, now_ns)
    }

    #[test]
    fn a_wall_driven_past_stays_occupied_beside_the_robot_wherever_it_lies_in_its_cells() {
        // Rays to a wall's far points run inside the row of cells the wall lies in for the
        // last part of their way (from 55 % of it for a wall 0.18 m to the side of 0.1 m
        // cells): marking them free up to 85 % erased every wall lying in the upper half of
        // its cells, and the robot took the hallway beyond the wall for an opening.
        let mut lost = Vec::new();
        for wall_cm in 15..36 {
            for yaw_deg in [-3.0f64, -1.5, 0.0, 1.5, 3.0] {
                let wall_y_m = wall_cm as f64 / 100.0 + 0.003;
                let (map, pose, now_ns) = drive_past_a_side_wall(wall_y_m, yaw_deg.to_radians());
                // The wall's cells from 0.4 m behind the robot to 0.2 m ahead.
                let occupied = (0..7)
                    .filter(|&k| {
                        let x_m = pose.x_m - 0.4 + 0.1 * k as f64;
                        map.state(x_m, wall_y_m, now_ns) == CellState::Occupied
                    })
                    .count();
                if occupied < 6 {
                    lost.push((wall_y_m, yaw_deg, occupied));
                }
            }
        }
        assert!(
            lost.is_empty(),
            "walls (y, yaw, cells of 7 occupied) lost: {lost:?}"
        );
    }

    #[test]
    fn the_space_between_the_robot_and_a_side_wall_stays_free() {
        let (map, pose, now_ns) = drive_past_a_side_wall(0.5, 0.0);
        let n = map.count_region(&pose, (-0.4, 0.2), (0.05, 0.3), now_ns);
        assert_eq!(n.occupied, 0, "{n:?}");
        assert!(n.free * 10 >= (n.free + n.unknown) * 9, "{n:?}");
        assert_eq!(
            map.side_distance(&pose, true, (-0.2, 0.3), 0.9, now_ns)
                .map(|d| (d * 10.0).round()),
            Some(5.0)
        );
    }
}
