//! The global planner: Dijkstra from the robot over the costmap. One run gives the path cost
//! to every cell, which the frontier search uses to rank goals and to drop unreachable ones,
//! and the path to the chosen goal by following the parents back.
//!
//! A robot whose centre stands in a lethal cell (drift, or a wall seen late) may leave it
//! through lethal cells, each farther from the obstacle than the last; it may not enter one
//! from a free cell.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use super::costmap::Costmap;

/// Path costs from one start cell.
#[derive(Debug, Clone)]
pub struct CostField {
    cost: Vec<f64>,
    parent: Vec<u32>,
    start: usize,
}

/// A queue entry. Path costs are never negative (every step adds a positive length), and
/// the bit patterns of non-negative `f64`s order as the numbers do, so the heap compares
/// them as integers: the same order as `f64::total_cmp`, for fewer instructions in the
/// search's hottest loop (the heap's sift-down).
#[derive(Debug, Clone, Copy)]
struct Entry {
    /// `cost.to_bits()` of the path cost, metres.
    cost_bits: u64,
    cell: usize,
}

impl Entry {
    fn new(cost_m: f64, cell: usize) -> Self {
        debug_assert!(cost_m >= 0.0, "path costs are never negative");
        Self {
            cost_bits: cost_m.to_bits(),
            cell,
        }
    }

    fn cost_m(&self) -> f64 {
        f64::from_bits(self.cost_bits)
    }
}

impl PartialEq for Entry {
    fn eq(&self, other: &Self) -> bool {
        self.cost_bits == other.cost_bits
    }
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on cost.
        other.cost_bits.cmp(&self.cost_bits)
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl CostField {
    /// Runs Dijkstra from window cell `start` over the whole window.
    pub fn from_start(map: &Costmap, start: usize) -> Self {
        Self::search(map, start, None)
    }

    /// Runs Dijkstra from window cell `start` until every cell marked in `targets` (by
    /// window index) is settled or found unreachable: their costs and paths are those of
    /// [`CostField::from_start`] (a settled cell's cost and parent never change, and the
    /// cells on its path were settled before it); any other cell not settled by then reads
    /// as unreachable. The explorer needs the frontier cells only, and they lie on the
    /// near side of the unknown cells that fill the rest of the window.
    ///
    /// From a start outside the lethal band no lethal cell is ever entered, so a lethal
    /// target is unreachable from the outset: it is not waited for (it would keep the
    /// search going to the window's end for nothing).
    pub fn to_targets(map: &Costmap, start: usize, targets: &[bool]) -> Self {
        Self::search(map, start, Some(targets))
    }

    /// Dijkstra, stopping early once every target is settled when there are targets.
    fn search(map: &Costmap, start: usize, targets: Option<&[bool]>) -> Self {
        let n = map.len();
        // Targets that can still be settled (a lethal one only from a lethal start: the
        // module's rule), and which cells are settled (only when stopping early).
        let lethal_start = map.is_lethal(start);
        let mut left = targets.map_or(0, |t| {
            t.iter()
                .take(n)
                .enumerate()
                .filter(|&(i, &x)| x && (lethal_start || !map.is_lethal(i)))
                .count()
        });
        let mut settled = vec![false; if targets.is_some() { n } else { 0 }];
        let mut cost = vec![f64::INFINITY; n];
        let mut parent = vec![u32::MAX; n];
        let mut heap = BinaryHeap::new();
        cost[start] = 0.0;
        if targets.is_some() && left == 0 {
            // Nothing to reach: the start is all there is.
            settled[start] = true;
        } else {
            heap.push(Entry::new(0.0, start));
        }
        let cell_m = map.cell_m();
        let escape_cost_m = map.escape_cost_m();
        while let Some(entry) = heap.pop() {
            let (c, cell) = (entry.cost_m(), entry.cell);
            if c > cost[cell] {
                continue;
            }
            if let Some(t) = targets {
                settled[cell] = true;
                if t.get(cell).copied().unwrap_or(false) {
                    left -= 1;
                    if left == 0 {
                        break;
                    }
                }
            }
            let escaping = map.is_lethal(cell);
            map.for_each_neighbour(cell, |next, len| {
                // A lethal cell's standing cost is infinite, and only a lethal cell's is.
                let stand_m = map.cost_m(next);
                let step = if stand_m.is_infinite() {
                    // Escaping means moving away from the obstacle: a lethal start may not
                    // follow the lethal band along a wall.
                    if !escaping
                        || map.obstacle_distance_m(next) < 0.5 * cell_m
                        || map.obstacle_distance_m(next) <= map.obstacle_distance_m(cell)
                    {
                        return;
                    }
                    len * (cell_m + escape_cost_m)
                } else {
                    len * cell_m + stand_m
                };
                let nc = c + step;
                if nc < cost[next] {
                    cost[next] = nc;
                    parent[next] = cell as u32;
                    heap.push(Entry::new(nc, next));
                }
            });
        }
        if targets.is_some() {
            for ((c, p), &done) in cost.iter_mut().zip(&mut parent).zip(&settled) {
                if !done {
                    *c = f64::INFINITY;
                    *p = u32::MAX;
                }
            }
        }
        Self {
            cost,
            parent,
            start,
        }
    }

    /// The path cost to a window cell (infinite: unreachable).
    pub fn cost_m(&self, cell: usize) -> f64 {
        self.cost[cell]
    }

    /// The cells from the start to `goal` (both included), or `None` when unreachable.
    pub fn path_to(&self, goal: usize) -> Option<Vec<usize>> {
        if !self.cost.get(goal)?.is_finite() {
            return None;
        }
        let mut path = vec![goal];
        let mut at = goal;
        while at != self.start {
            let p = self.parent[at];
            if p == u32::MAX || path.len() > self.cost.len() {
                return None;
            }
            at = p as usize;
            path.push(at);
        }
        path.reverse();
        Some(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::explore::grid::OccupancyGrid;
    use crate::odometry::DeadReckonedPose;
    use hvs_runtime::config::{CostmapConfig, GridConfig};
    use hvs_shared::messages::{ObstacleScan, SCAN_BINS};

    /// A grid with a wall segment 1.5 m ahead, seen from the start, and free space around
    /// it from scans taken beside it.
    fn wall_ahead() -> OccupancyGrid {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let mut scan = ObstacleScan {
            tan_half_fov: 0.3,
            ..ObstacleScan::default()
        };
        scan.range_m = [1.5; SCAN_BINS];
        let far = ObstacleScan {
            range_m: [6.0; SCAN_BINS],
            ..scan
        };
        for _ in 0..3 {
            let pts = grid.scan_points(&DeadReckonedPose::default(), 0.0, &scan);
            grid.insert(&pts);
            for y in [-1.2, 1.2] {
                let pose = DeadReckonedPose {
                    x_m: 0.0,
                    y_m: y,
                    heading_rad: 0.0,
                };
                let pts = grid.scan_points(&pose, 0.0, &far);
                grid.insert(&pts);
            }
        }
        grid
    }

    #[test]
    fn a_path_goes_around_a_wall_and_not_through_it() {
        let grid = wall_ahead();
        let robot = grid.cell_of(0.5, 0.0).expect("inside");
        let map = Costmap::build(&grid, CostmapConfig::default(), 0.155, 0.27, robot);
        let idx = |x: f64, y: f64| {
            grid.cell_of(x, y)
                .and_then(|c| map.index(c))
                .expect("inside")
        };
        let field = CostField::from_start(&map, idx(0.5, 0.0));
        let goal = idx(2.3, 0.0);
        let path = field.path_to(goal).expect("reachable around the wall");
        assert!(path.iter().all(|&c| !map.is_lethal(c)));
        let detour = path
            .iter()
            .map(|&c| grid.centre(map.cell(c)).1.abs())
            .fold(0.0, f64::max);
        assert!(detour > 0.5, "the path must go round the wall: {detour}");
        assert!(field.cost_m(goal) > 1.8);
    }

    #[test]
    fn a_search_to_targets_gives_them_the_whole_searchs_costs_and_paths() {
        let grid = wall_ahead();
        let robot = grid.cell_of(0.5, 0.0).expect("inside");
        let map = Costmap::build(&grid, CostmapConfig::default(), 0.155, 0.27, robot);
        let start = map.index(robot).expect("inside");
        let whole = CostField::from_start(&map, start);
        let frontiers = crate::explore::frontier::frontier_cells(&map);
        assert!(frontiers.iter().filter(|&&f| f).count() > 10);
        let behind_wall = grid
            .cell_of(2.3, 0.0)
            .and_then(|c| map.index(c))
            .expect("inside");
        let mut one = vec![false; map.len()];
        one[behind_wall] = true;
        // Some frontier cells lie in the lethal band, where a search from outside it never
        // goes: they read unreachable in both searches, and do not keep the search going.
        assert!(!map.is_lethal(start));
        let lethal_frontiers: Vec<usize> = (0..map.len())
            .filter(|&i| frontiers[i] && map.is_lethal(i))
            .collect();
        assert!(!lethal_frontiers.is_empty());
        for &i in &lethal_frontiers {
            assert!(!whole.cost_m(i).is_finite(), "lethal frontier cell {i}");
        }
        for targets in [frontiers, one] {
            let part = CostField::to_targets(&map, start, &targets);
            let mut cut = 0;
            for (i, &target) in targets.iter().enumerate() {
                if target {
                    assert_eq!(
                        part.cost_m(i).to_bits(),
                        whole.cost_m(i).to_bits(),
                        "cell {i}"
                    );
                    assert_eq!(part.path_to(i), whole.path_to(i), "cell {i}");
                } else if part.cost_m(i).is_finite() {
                    // A cell settled on the way: final too.
                    assert_eq!(
                        part.cost_m(i).to_bits(),
                        whole.cost_m(i).to_bits(),
                        "cell {i}"
                    );
                } else if whole.cost_m(i).is_finite() {
                    cut += 1;
                }
            }
            assert!(cut > 0, "the search must stop before the farthest cells");
        }
        // No target: only the start.
        let none = CostField::to_targets(&map, start, &vec![false; map.len()]);
        assert_eq!(none.cost_m(start), 0.0);
        assert_eq!(
            (0..map.len())
                .filter(|&i| none.cost_m(i).is_finite())
                .count(),
            1
        );
    }
}
