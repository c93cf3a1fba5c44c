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

#[derive(Debug, Clone, Copy, PartialEq)]
struct Entry {
    cost: f64,
    cell: usize,
}

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on cost.
        other.cost.total_cmp(&self.cost)
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl CostField {
    /// Runs Dijkstra from window cell `start`.
    pub fn from_start(map: &Costmap, start: usize) -> Self {
        let n = map.len();
        let mut cost = vec![f64::INFINITY; n];
        let mut parent = vec![u32::MAX; n];
        let mut heap = BinaryHeap::new();
        cost[start] = 0.0;
        heap.push(Entry {
            cost: 0.0,
            cell: start,
        });
        let cell_m = map.cell_m();
        let escape_cost_m = map.escape_cost_m();
        while let Some(Entry { cost: c, cell }) = heap.pop() {
            if c > cost[cell] {
                continue;
            }
            let escaping = map.is_lethal(cell);
            for (next, len) in map.neighbours(cell) {
                let step = if map.is_lethal(next) {
                    // Escaping means moving away from the obstacle: a lethal start may not
                    // follow the lethal band along a wall.
                    if !escaping
                        || map.obstacle_distance_m(next) < 0.5 * cell_m
                        || map.obstacle_distance_m(next) <= map.obstacle_distance_m(cell)
                    {
                        continue;
                    }
                    len * (cell_m + escape_cost_m)
                } else {
                    len * cell_m + map.cost_m(next)
                };
                let nc = c + step;
                if nc < cost[next] {
                    cost[next] = nc;
                    parent[next] = cell as u32;
                    heap.push(Entry {
                        cost: nc,
                        cell: next,
                    });
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

    #[test]
    fn a_path_goes_around_a_wall_and_not_through_it() {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        // A wall segment 1.5 m ahead, seen from the start; free space around it from
        // scans taken beside it.
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
}
