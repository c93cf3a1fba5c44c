//! The visit memory: how often the dead-reckoned robot passed each cell of a coarse grid.

use super::*;

/// A coarse grid of how often the (dead-reckoned) robot passed each cell.
///
/// A pass marks the cells of the robot's footprint: the cell it is in and the eight around
/// it. Dead reckoning drifts 0.1-0.3 m over minutes, so a hallway driven twice is seldom
/// driven in the same line of cells; marking only the cell under the robot made a branch's
/// first cell look visited or not by which side of a cell boundary the robot drove.
#[derive(Debug, Clone, Default)]
pub struct VisitGrid {
    cell_m: f64,
    /// Passes through each cell's neighbourhood.
    visits: HashMap<(i64, i64), u32>,
    /// Cells the robot's centre entered.
    entered: HashSet<(i64, i64)>,
    current: Option<(i64, i64)>,
}

/// Cells a branch's score looks at (cells along the branch from the robot's, weight): the
/// first is skipped (the hallway the robot is in, marked by its own pass), the next four
/// weighted 4, 3, 2, 1. (The next three weighted 3, 2, 1 covered 2302 cells in the 16-pose
/// maze runs against 2365 for these four, with 4 collisions against 3.)
const SCORE_CELLS: [(u32, u32); 4] = [(2, 4), (3, 3), (4, 2), (5, 1)];

impl VisitGrid {
    /// An empty grid of `cell_m` cells.
    pub fn new(cell_m: f64) -> Self {
        Self {
            cell_m,
            visits: HashMap::new(),
            entered: HashSet::new(),
            current: None,
        }
    }

    fn cell(&self, x_m: f64, y_m: f64) -> (i64, i64) {
        (
            (x_m / self.cell_m).floor() as i64,
            (y_m / self.cell_m).floor() as i64,
        )
    }

    /// Records the robot at a position. Entering a cell is a pass of each footprint cell that
    /// was not in the footprint before.
    pub fn record(&mut self, x_m: f64, y_m: f64) {
        let c = self.cell(x_m, y_m);
        if self.current == Some(c) {
            return;
        }
        let near = |a: (i64, i64), b: (i64, i64)| (a.0 - b.0).abs() <= 1 && (a.1 - b.1).abs() <= 1;
        for dx in -1..=1 {
            for dy in -1..=1 {
                let f = (c.0 + dx, c.1 + dy);
                if self.current.is_none_or(|p| !near(p, f)) {
                    *self.visits.entry(f).or_insert(0) += 1;
                }
            }
        }
        self.entered.insert(c);
        self.current = Some(c);
    }

    /// Passes through the cell containing a position.
    pub fn visits_at(&self, x_m: f64, y_m: f64) -> u32 {
        self.visits.get(&self.cell(x_m, y_m)).copied().unwrap_or(0)
    }

    /// How visited the way along `heading_rad` from a position looks: the weighted passes
    /// through the cells of [`SCORE_CELLS`] along it (0.7 to 1.75 m at 0.35 m cells).
    pub fn score(&self, x_m: f64, y_m: f64, heading_rad: f64) -> u32 {
        SCORE_CELLS
            .iter()
            .map(|&(k, weight)| {
                let d = k as f64 * self.cell_m;
                self.visits_at(x_m + d * heading_rad.cos(), y_m + d * heading_rad.sin()) * weight
            })
            .sum()
    }

    /// Distinct cells the robot's centre entered.
    pub fn distinct_cells(&self) -> usize {
        self.entered.len()
    }
}
