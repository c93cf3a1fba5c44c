//! The costmap: the occupancy grid inflated by the robot's footprint. Occupied cells and cells
//! nearer to one than the footprint's half-width plus a clearance are lethal to the robot's
//! centre; beyond that band the cost falls off over `decay_m`, so paths keep to the middle of
//! a hallway; cells where the robot could stand but not turn in place (nearer than its
//! half-diagonal plus the clearance) cost `turn_clearance_cost_m` extra; unknown cells cost
//! a little extra (they may hold a wall), and so do seen cells near unknown ones
//! (`unknown_clearance_cost_m`: the wall ends the robot touched were mostly never mapped,
//! their side toward the robot lying in the camera's blind zone).
//!
//! Computed over the part of the grid that has been seen (plus a margin), with a two-pass
//! chamfer distance transform (3-4 weights: within 8 % of the Euclidean distance).

use hvs_runtime::config::CostmapConfig;

use super::grid::{CellIndex, OccupancyGrid};
use crate::local_map::CellState;

/// Unknown cells kept around the seen area, cells.
const MARGIN_CELLS: usize = 4;

/// The inflated grid over a window of the occupancy grid.
#[derive(Debug, Clone)]
pub struct Costmap {
    /// Window origin in grid cells (column, row).
    origin: CellIndex,
    /// Window size in cells.
    cols: usize,
    rows: usize,
    /// Distance to the nearest occupied cell, metres (capped).
    dist_m: Vec<f32>,
    /// Distance to the nearest unknown cell, metres (capped).
    unknown_dist_m: Vec<f32>,
    /// Per-cell state.
    state: Vec<CellState>,
    /// Per-cell cost of standing there, metres of path (infinite when lethal): computed
    /// once a build, as the planner asks for each cell up to eight times.
    cell_cost_m: Vec<f64>,
    lethal_m: f64,
    /// Below this distance the robot cannot turn in place, metres.
    turn_m: f64,
    cfg: CostmapConfig,
    cell_m: f64,
}

impl Costmap {
    /// Extra cost of a cell crossed while leaving a lethal start, metres per cell.
    pub fn escape_cost_m(&self) -> f64 {
        self.cfg.escape_cost_m
    }

    /// Inflates `grid` for a robot of half-width `half_width_m` whose corners sweep
    /// `turn_radius_m` turning in place; the window covers what has been seen and the cell
    /// `robot` stands in (which no scan ray of a forward camera crosses).
    pub fn build(
        grid: &OccupancyGrid,
        cfg: CostmapConfig,
        half_width_m: f64,
        turn_radius_m: f64,
        robot: CellIndex,
    ) -> Self {
        let side = grid.side();
        let (rc, rr) = robot;
        let (c0, c1, r0, r1) = grid.bounds().map_or((rc, rc, rr, rr), |(c0, c1, r0, r1)| {
            (c0.min(rc), c1.max(rc), r0.min(rr), r1.max(rr))
        });
        let c0 = c0.saturating_sub(MARGIN_CELLS);
        let r0 = r0.saturating_sub(MARGIN_CELLS);
        let c1 = (c1 + MARGIN_CELLS).min(side - 1);
        let r1 = (r1 + MARGIN_CELLS).min(side - 1);
        let (cols, rows) = (c1 - c0 + 1, r1 - r0 + 1);
        let cell_m = grid.cell_m();
        let mut state = Vec::with_capacity(cols * rows);
        for r in r0..=r1 {
            for c in c0..=c1 {
                state.push(grid.state((c, r)));
            }
        }
        let dist_m = chamfer_m(&state, cols, rows, cell_m, |s| s == CellState::Occupied);
        let unknown_dist_m = chamfer_m(&state, cols, rows, cell_m, |s| s == CellState::Unknown);
        let mut map = Self {
            origin: (c0, r0),
            cols,
            rows,
            dist_m,
            unknown_dist_m,
            state,
            cell_cost_m: Vec::new(),
            lethal_m: half_width_m + cfg.clearance_m,
            turn_m: turn_radius_m + cfg.clearance_m,
            cfg,
            cell_m,
        };
        map.cell_cost_m = (0..map.len()).map(|i| map.compute_cost_m(i)).collect();
        map
    }

    /// Cell edge, metres.
    pub fn cell_m(&self) -> f64 {
        self.cell_m
    }

    /// Window origin (grid column, row) and size (columns, rows).
    pub fn window(&self) -> (CellIndex, usize, usize) {
        (self.origin, self.cols, self.rows)
    }

    /// The window index of a grid cell, if inside the window.
    pub fn index(&self, (c, r): CellIndex) -> Option<usize> {
        let (c0, r0) = self.origin;
        if c < c0 || r < r0 || c - c0 >= self.cols || r - r0 >= self.rows {
            return None;
        }
        Some((r - r0) * self.cols + (c - c0))
    }

    /// The grid cell of a window index.
    pub fn cell(&self, i: usize) -> CellIndex {
        (self.origin.0 + i % self.cols, self.origin.1 + i / self.cols)
    }

    /// Window size in cells.
    pub fn len(&self) -> usize {
        self.cols * self.rows
    }

    /// Whether the window is empty (never: it holds at least the margin).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Distance from a window cell to the nearest occupied cell, metres (capped at 1000
    /// cells).
    pub fn obstacle_distance_m(&self, i: usize) -> f64 {
        f64::from(self.dist_m[i])
    }

    /// The occupancy state of a window cell.
    pub fn state(&self, i: usize) -> CellState {
        self.state[i]
    }

    /// Whether the robot's centre may not stand in a window cell.
    pub fn is_lethal(&self, i: usize) -> bool {
        self.obstacle_distance_m(i) <= self.lethal_m
    }

    /// The cost of standing in a window cell, metres of path (infinite when lethal).
    pub fn cost_m(&self, i: usize) -> f64 {
        self.cell_cost_m[i]
    }

    /// [`Costmap::cost_m`] from the distances.
    fn compute_cost_m(&self, i: usize) -> f64 {
        let d = self.obstacle_distance_m(i);
        if d <= self.lethal_m {
            return f64::INFINITY;
        }
        let wall = if self.cfg.decay_m > 0.0 {
            self.cfg.wall_cost_m * (1.0 - (d - self.lethal_m) / self.cfg.decay_m).max(0.0)
        } else {
            0.0
        };
        let turn = if d <= self.turn_m {
            self.cfg.turn_clearance_cost_m
        } else {
            0.0
        };
        let unknown = if self.state[i] == CellState::Unknown {
            self.cfg.unknown_cost_m
        } else {
            0.0
        };
        let du = f64::from(self.unknown_dist_m[i]);
        let near_unknown = if du >= self.turn_m {
            0.0
        } else {
            let span = (self.turn_m - self.lethal_m).max(1e-9);
            self.cfg.unknown_clearance_cost_m * ((self.turn_m - du) / span).min(1.0)
        };
        wall + turn + unknown + near_unknown
    }

    /// [`Costmap::neighbours`] (the same cells, lengths and order) handed to `f`, with the
    /// interior cells' eight offsets taken without bounds arithmetic: the planner's inner
    /// loop.
    #[inline(always)]
    pub fn for_each_neighbour(&self, i: usize, mut f: impl FnMut(usize, f64)) {
        let w = self.cols;
        let (c, r) = (i % w, i / w);
        if c > 0 && r > 0 && c + 1 < w && r + 1 < self.rows {
            const D: f64 = std::f64::consts::SQRT_2;
            f(i + 1, 1.0);
            f(i - 1, 1.0);
            f(i + w, 1.0);
            f(i - w, 1.0);
            f(i + w + 1, D);
            f(i - w + 1, D);
            f(i + w - 1, D);
            f(i - w - 1, D);
        } else {
            for (j, len) in self.neighbours(i) {
                f(j, len);
            }
        }
    }

    /// The 8 neighbours of a window cell with their step length in cells.
    pub fn neighbours(&self, i: usize) -> impl Iterator<Item = (usize, f64)> + '_ {
        let (c, r) = ((i % self.cols) as i64, (i / self.cols) as i64);
        const STEPS: [(i64, i64, f64); 8] = [
            (1, 0, 1.0),
            (-1, 0, 1.0),
            (0, 1, 1.0),
            (0, -1, 1.0),
            (1, 1, std::f64::consts::SQRT_2),
            (1, -1, std::f64::consts::SQRT_2),
            (-1, 1, std::f64::consts::SQRT_2),
            (-1, -1, std::f64::consts::SQRT_2),
        ];
        STEPS.iter().filter_map(move |&(dc, dr, len)| {
            let (nc, nr) = (c + dc, r + dr);
            (nc >= 0 && nr >= 0 && nc < self.cols as i64 && nr < self.rows as i64)
                .then(|| ((nr as usize) * self.cols + nc as usize, len))
        })
    }
}

/// Distance from every window cell to the nearest cell whose state is `seed`, metres
/// (capped at 1000 cells): a two-pass chamfer transform in thirds of a cell (3 straight, 4
/// diagonal). Each row first takes the finished row beside it (three independent minima
/// per cell, which vectorise), then sweeps along itself: the only chain of dependent
/// steps left is one add and one minimum per cell (the same minima as testing all four
/// neighbours at once, in another order).
fn chamfer_m(
    state: &[CellState],
    cols: usize,
    rows: usize,
    cell_m: f64,
    seed: impl Fn(CellState) -> bool,
) -> Vec<f32> {
    let seeded = state
        .iter()
        .map(|&s| if seed(s) { 0 } else { FAR_THIRDS })
        .collect();
    chamfer_thirds(seeded, cols, rows)
        .iter()
        .map(|&v| (f64::from(v.min(3000)) / 3.0 * cell_m) as f32)
        .collect()
}

/// Far, in thirds of a cell: no seed. Adding a step to it cannot overflow.
const FAR_THIRDS: u32 = u32::MAX / 2;

/// The chamfer transform of [`chamfer_m`] in thirds of a cell, over `d` (0 at the seeds,
/// [`FAR_THIRDS`] elsewhere).
fn chamfer_thirds(mut d: Vec<u32>, cols: usize, rows: usize) -> Vec<u32> {
    const FAR: u32 = FAR_THIRDS;
    for r in 0..rows {
        let (above, rest) = d.split_at_mut(r * cols);
        let row = &mut rest[..cols];
        if r > 0 {
            take_row(row, &above[(r - 1) * cols..]);
        }
        let mut left = FAR;
        for v in row.iter_mut() {
            left = (*v).min(left + 3);
            *v = left;
        }
    }
    for r in (0..rows).rev() {
        let (upto, below) = d.split_at_mut((r + 1) * cols);
        let row = &mut upto[r * cols..];
        if r + 1 < rows {
            take_row(row, below);
        }
        let mut right = FAR;
        for v in row.iter_mut().rev() {
            right = (*v).min(right + 3);
            *v = right;
        }
    }
    d
}

/// Lowers each cell of `row` to its neighbour in `beside` (the row above or below) plus 3,
/// or the diagonal ones plus 4.
fn take_row(row: &mut [u32], beside: &[u32]) {
    let n = row.len();
    for (v, &b) in row.iter_mut().zip(beside) {
        *v = (*v).min(b + 3);
    }
    if n > 1 {
        for (v, &b) in row[1..].iter_mut().zip(&beside[..n - 1]) {
            *v = (*v).min(b + 4);
        }
        for (v, &b) in row[..n - 1].iter_mut().zip(&beside[1..n]) {
            *v = (*v).min(b + 4);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::odometry::DeadReckonedPose;
    use hvs_runtime::config::GridConfig;
    use hvs_shared::messages::ObstacleScan;

    /// A grid after three looks east from the origin by a camera `camera_forward_m` ahead
    /// of it, every bin reading `range_m`.
    fn looked_east(range_m: f32, camera_forward_m: f64) -> OccupancyGrid {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let mut scan = ObstacleScan {
            tan_half_fov: 0.5,
            ..ObstacleScan::default()
        };
        scan.range_m = [range_m; hvs_shared::messages::SCAN_BINS];
        for _ in 0..3 {
            let pts = grid.scan_points(&DeadReckonedPose::default(), camera_forward_m, &scan);
            grid.insert(&pts);
        }
        grid
    }

    /// The chamfer transform testing the four finished neighbours of each cell in turn: what
    /// [`chamfer_thirds`] must match.
    fn chamfer_thirds_plain(mut d: Vec<u32>, cols: usize, rows: usize) -> Vec<u32> {
        for r in 0..rows {
            for c in 0..cols {
                let i = r * cols + c;
                let mut v = d[i];
                if c > 0 {
                    v = v.min(d[i - 1] + 3);
                }
                if r > 0 {
                    v = v.min(d[i - cols] + 3);
                    if c > 0 {
                        v = v.min(d[i - cols - 1] + 4);
                    }
                    if c + 1 < cols {
                        v = v.min(d[i - cols + 1] + 4);
                    }
                }
                d[i] = v;
            }
        }
        for r in (0..rows).rev() {
            for c in (0..cols).rev() {
                let i = r * cols + c;
                let mut v = d[i];
                if c + 1 < cols {
                    v = v.min(d[i + 1] + 3);
                }
                if r + 1 < rows {
                    v = v.min(d[i + cols] + 3);
                    if c + 1 < cols {
                        v = v.min(d[i + cols + 1] + 4);
                    }
                    if c > 0 {
                        v = v.min(d[i + cols - 1] + 4);
                    }
                }
                d[i] = v;
            }
        }
        d
    }

    #[test]
    fn the_row_at_a_time_chamfer_transform_matches_the_cell_at_a_time_one() {
        // Seeds at the window's corners and edges, in clusters and alone; one-row and
        // one-column windows too.
        let mut seed = 0x9e37_79b9_u64;
        for (cols, rows) in [(23, 17), (1, 9), (9, 1), (1, 1), (2, 2)] {
            let state: Vec<CellState> = (0..cols * rows)
                .map(|i| {
                    seed = seed
                        .wrapping_mul(6_364_136_223_846_793_005)
                        .wrapping_add(1_442_695_040_888_963_407);
                    match (seed >> 60, i) {
                        (_, 0) | (0, _) => CellState::Occupied,
                        (1..=5, _) => CellState::Unknown,
                        _ => CellState::Free,
                    }
                })
                .collect();
            for wanted in [CellState::Occupied, CellState::Unknown, CellState::Free] {
                let seeded: Vec<u32> = state
                    .iter()
                    .map(|&s| if s == wanted { 0 } else { FAR_THIRDS })
                    .collect();
                let fast = chamfer_thirds(seeded.clone(), cols, rows);
                let plain = chamfer_thirds_plain(seeded, cols, rows);
                assert_eq!(fast, plain, "{cols}x{rows}, {wanted:?}");
            }
            // With no seed every cell is capped far.
            let none = chamfer_m(&state, cols, rows, 0.1, |_| false);
            assert!(none.iter().all(|&d| (d - 100.0).abs() < 1e-3));
        }
    }

    #[test]
    fn every_cell_has_the_window_cells_around_it_as_neighbours_in_one_order() {
        let grid = looked_east(1.5, 0.2);
        let c0 = grid.cell_of(0.0, 0.0).expect("inside");
        let map = Costmap::build(&grid, CostmapConfig::default(), 0.155, 0.27, c0);
        let (_, cols, rows) = map.window();
        assert!(cols > 2 && rows > 2);
        let order = [
            (1, 0),
            (-1, 0),
            (0, 1),
            (0, -1),
            (1, 1),
            (1, -1),
            (-1, 1),
            (-1, -1),
        ];
        for i in 0..map.len() {
            let (c, r) = ((i % cols) as i64, (i / cols) as i64);
            let expected: Vec<(usize, f64)> = order
                .iter()
                .filter(|&&(dc, dr)| {
                    (0..cols as i64).contains(&(c + dc)) && (0..rows as i64).contains(&(r + dr))
                })
                .map(|&(dc, dr)| {
                    let len = if dc != 0 && dr != 0 { 2f64.sqrt() } else { 1.0 };
                    (((r + dr) * cols as i64 + c + dc) as usize, len)
                })
                .collect();
            let got: Vec<(usize, f64)> = map.neighbours(i).collect();
            assert_eq!(got, expected, "cell {i} ({c}, {r}) of {cols}x{rows}");
            let mut handed = Vec::new();
            map.for_each_neighbour(i, |j, len| handed.push((j, len)));
            assert_eq!(handed, expected, "cell {i} ({c}, {r}) of {cols}x{rows}");
            let interior = c > 0 && r > 0 && c + 1 < cols as i64 && r + 1 < rows as i64;
            assert_eq!(got.len() == 8, interior, "cell {i}");
        }
    }

    #[test]
    fn cells_near_a_wall_are_lethal_and_cost_falls_with_distance() {
        let grid = looked_east(1.5, 0.2);
        let robot = grid.cell_of(0.0, 0.0).expect("inside");
        let map = Costmap::build(&grid, CostmapConfig::default(), 0.155, 0.27, robot);
        let at = |x: f64| {
            grid.cell_of(x, 0.0)
                .and_then(|c| map.index(c))
                .expect("inside the window")
        };
        assert!(map.is_lethal(at(1.75)));
        assert!(map.is_lethal(at(1.55)));
        assert!(!map.is_lethal(at(1.0)));
        assert!(map.cost_m(at(1.4)) > map.cost_m(at(1.0)));
        assert!(map.cost_m(at(1.4)).is_finite());
        // Standing 0.3 m from the wall's cells fits the footprint's half-width but not the
        // circle its corners sweep turning: the turn clearance cost applies there only.
        let turn_cost = CostmapConfig::default().turn_clearance_cost_m;
        assert!(map.cost_m(at(1.45)) >= turn_cost);
        assert!(map.cost_m(at(1.0)) < turn_cost);
    }

    #[test]
    fn seen_cells_beside_unknown_ones_cost_more_than_the_middle_of_what_was_seen() {
        // One look east with nothing within range: a cone seen free, unknown all round it.
        let grid = looked_east(5.0, 0.0);
        let robot = grid.cell_of(0.0, 0.0).expect("inside");
        let cfg = CostmapConfig::default();
        let map = Costmap::build(&grid, cfg, 0.155, 0.27, robot);
        let at = |x: f64, y: f64| {
            grid.cell_of(x, y)
                .and_then(|c| map.index(c))
                .expect("inside the window")
        };
        // The cone is 1.2 m wide 1.2 m out: its middle is far from the unknown.
        assert_eq!(map.state(at(1.2, 0.0)), CellState::Free);
        assert!(map.cost_m(at(1.2, 0.0)) < 1e-9);
        // A cell seen free next to the cone's edge costs the whole clearance cost; one a
        // little farther in, part of it; an unknown cell, that and the unknown cost.
        let edge = at(1.2, 0.6);
        assert_eq!(map.state(edge), CellState::Free);
        assert!((map.cost_m(edge) - cfg.unknown_clearance_cost_m).abs() < 1e-9);
        let part = map.cost_m(at(1.2, 0.4));
        assert!(part > 0.0 && part < map.cost_m(edge));
        let outside = at(1.2, 0.8);
        assert_eq!(map.state(outside), CellState::Unknown);
        assert!(map.cost_m(outside) > map.cost_m(edge));
        // With the cost set to 0 the middle and the edge cost the same.
        let flat = Costmap::build(
            &grid,
            CostmapConfig {
                unknown_clearance_cost_m: 0.0,
                ..cfg
            },
            0.155,
            0.27,
            robot,
        );
        assert!(flat.cost_m(edge) < 1e-9);
    }
}
