//! Frontiers: free cells next to unknown ones, grouped into 8-connected clusters, each ranked
//! by explore_lite's cost (path distance against size, here also the turn to face it), with a
//! blacklist of goals that turned out unreachable.

use std::collections::VecDeque;

use hvs_runtime::config::FrontierConfig;

use super::costmap::Costmap;
use super::planner::CostField;
use crate::local_map::CellState;

/// One frontier cluster.
#[derive(Debug, Clone, PartialEq)]
pub struct Frontier {
    /// Cells in the cluster.
    pub size_cells: usize,
    /// The reachable cell of the cluster with the lowest path cost (window index).
    pub goal: usize,
    /// Path cost to `goal`, metres.
    pub distance_m: f64,
    /// The cluster's centroid, grid frame, metres.
    pub centroid_m: (f64, f64),
}

/// Whether a window cell is a frontier cell: free, with an unknown 4-neighbour.
fn is_frontier(map: &Costmap, i: usize) -> bool {
    if map.state(i) != CellState::Free {
        return false;
    }
    let (_, cols, rows) = map.window();
    let (c, r) = (i % cols, i / cols);
    let mut around = [None; 4];
    if c > 0 {
        around[0] = Some(i - 1);
    }
    if c + 1 < cols {
        around[1] = Some(i + 1);
    }
    if r > 0 {
        around[2] = Some(i - cols);
    }
    if r + 1 < rows {
        around[3] = Some(i + cols);
    }
    around
        .into_iter()
        .flatten()
        .any(|j| map.state(j) == CellState::Unknown)
}

/// Which window cells are frontier cells (free, with an unknown 4-neighbour), by window
/// index: what [`CostField::to_targets`] must reach and [`find_frontiers`] clusters.
pub fn frontier_cells(map: &Costmap) -> Vec<bool> {
    (0..map.len()).map(|i| is_frontier(map, i)).collect()
}

/// Every frontier cluster with a reachable cell; `is_frontier` is [`frontier_cells`] of
/// `map`, `field` holds the final path costs of those cells at least, and `centre` maps a
/// window index to metres.
pub fn find_frontiers(
    map: &Costmap,
    field: &CostField,
    is_frontier: &[bool],
    cfg: &FrontierConfig,
    centre: impl Fn(usize) -> (f64, f64),
) -> Vec<Frontier> {
    let n = map.len();
    // A mask of another window's size marks nothing beyond its end.
    let is_frontier = |i: usize| is_frontier.get(i).copied().unwrap_or(false);
    let mut seen = vec![false; n];
    let mut out = Vec::new();
    let min_cells = (cfg.min_size_m / map.cell_m()).ceil() as usize;
    let mut queue = VecDeque::new();
    for start in 0..n {
        if seen[start] || !is_frontier(start) {
            continue;
        }
        seen[start] = true;
        queue.push_back(start);
        let (mut size, mut sx, mut sy) = (0usize, 0.0, 0.0);
        let mut best: Option<(usize, f64)> = None;
        while let Some(i) = queue.pop_front() {
            size += 1;
            let (x, y) = centre(i);
            sx += x;
            sy += y;
            let d = field.cost_m(i);
            if d.is_finite() && best.is_none_or(|(_, b)| d < b) {
                best = Some((i, d));
            }
            for (j, _) in map.neighbours(i) {
                if !seen[j] && is_frontier(j) {
                    seen[j] = true;
                    queue.push_back(j);
                }
            }
        }
        tracing::trace!(
            size,
            reachable = best.is_some(),
            x_m = sx / size as f64,
            y_m = sy / size as f64,
            "frontier cluster"
        );
        if size < min_cells.max(1) {
            continue;
        }
        if let Some((goal, distance_m)) = best {
            out.push(Frontier {
                size_cells: size,
                goal,
                distance_m,
                centroid_m: (sx / size as f64, sy / size as f64),
            });
        }
    }
    out
}

/// Goals given up on.
#[derive(Debug, Clone, Default)]
pub struct Blacklist {
    points_m: Vec<(f64, f64)>,
}

impl Blacklist {
    /// Adds a goal.
    pub fn add(&mut self, p: (f64, f64)) {
        self.points_m.push(p);
    }

    /// Whether a point lies within `radius_m` of a blacklisted goal.
    pub fn contains(&self, p: (f64, f64), radius_m: f64) -> bool {
        self.points_m
            .iter()
            .any(|q| (q.0 - p.0).hypot(q.1 - p.1) <= radius_m)
    }

    /// Blacklisted goals.
    pub fn len(&self) -> usize {
        self.points_m.len()
    }

    /// Whether nothing is blacklisted.
    pub fn is_empty(&self) -> bool {
        self.points_m.is_empty()
    }

    /// Forgets every goal (the map has changed enough to try them again).
    pub fn clear(&mut self) {
        self.points_m.clear();
    }
}

/// The frontier to explore next: the lowest `distance_weight * distance - size_weight * size
/// + extra_cost(frontier)`, skipping frontiers centred near a blacklisted point (the caller adds the turn to face it and
///   the hysteresis for the goal being driven to).
pub fn choose<'a>(
    frontiers: &'a [Frontier],
    cfg: &FrontierConfig,
    cell_m: f64,
    blacklist: &Blacklist,
    extra_cost: impl Fn(&Frontier) -> f64,
) -> Option<&'a Frontier> {
    frontiers
        .iter()
        .filter(|f| !blacklist.contains(f.centroid_m, cfg.blacklist_radius_m))
        .map(|f| {
            let cost = cfg.distance_weight * f.distance_m
                - cfg.size_weight * f.size_cells as f64 * cell_m
                + extra_cost(f);
            (f, cost)
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(f, _)| f)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_blacklist_matches_within_its_radius() {
        let mut b = Blacklist::default();
        assert!(!b.contains((0.0, 0.0), 1.0));
        b.add((1.0, 1.0));
        assert!(b.contains((1.2, 1.0), 0.3));
        assert!(!b.contains((1.5, 1.0), 0.3));
        b.clear();
        assert!(b.is_empty());
    }
}
