//! Tests of the maze generator: every seed's map checked on the grid it loads as.

use std::collections::{HashSet, VecDeque};

use super::*;
use crate::map::{GridMap, Vec2};

fn load(m: &Maze) -> GridMap {
    GridMap::parse(&m.text, "maze").unwrap_or_else(|e| panic!("seed {}: {e}", m.options.seed))
}

fn maze(seed: u64) -> (Maze, GridMap) {
    let m = generate_maze(&MazeOptions {
        seed,
        ..MazeOptions::default()
    })
    .unwrap();
    let g = load(&m);
    (m, g)
}

/// Whether text cell (col, row from the top) is a wall of `g` (outside the grid: wall).
fn wall(g: &GridMap, col: i64, row: i64) -> bool {
    g.is_wall_cell(col, g.height_cells() as i64 - 1 - row)
}

fn floor_cells(g: &GridMap) -> usize {
    let (w, h) = (g.width_cells() as i64, g.height_cells() as i64);
    (0..h)
        .flat_map(|r| (0..w).map(move |c| (c, r)))
        .filter(|&(c, r)| !g.is_wall_cell(c, r))
        .count()
}

/// Floor cells 4-connected to the start's.
fn reachable(g: &GridMap) -> usize {
    let s = g.start_pose();
    let start = g.cell_of(s.x_m, s.y_m);
    let mut seen = HashSet::from([start]);
    let mut queue = VecDeque::from([start]);
    while let Some((c, r)) = queue.pop_front() {
        for (dc, dr) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
            let n = (c + dc, r + dr);
            if !g.is_wall_cell(n.0, n.1) && seen.insert(n) {
                queue.push_back(n);
            }
        }
    }
    seen.len()
}

/// Sizes of the 8-connected wall components that do not touch the grid's edge (holes in the
/// floor: pillars and what loops enclose).
fn islands(g: &GridMap) -> Vec<usize> {
    let (w, h) = (g.width_cells() as i64, g.height_cells() as i64);
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for r in 0..h {
        for c in 0..w {
            if !g.is_wall_cell(c, r) || !seen.insert((c, r)) {
                continue;
            }
            let (mut size, mut edge) = (0, false);
            let mut queue = VecDeque::from([(c, r)]);
            while let Some((c, r)) = queue.pop_front() {
                size += 1;
                edge |= c == 0 || r == 0 || c == w - 1 || r == h - 1;
                for dr in -1..=1 {
                    for dc in -1..=1 {
                        let n = (c + dc, r + dr);
                        if n.0 >= 0
                            && n.1 >= 0
                            && n.0 < w
                            && n.1 < h
                            && g.is_wall_cell(n.0, n.1)
                            && seen.insert(n)
                        {
                            queue.push_back(n);
                        }
                    }
                }
            }
            if !edge {
                out.push(size);
            }
        }
    }
    out
}

#[test]
fn every_seed_loads_connected_with_rooms_corridors_pillars_loops_and_dead_ends() {
    let mut texts = HashSet::new();
    for seed in 0..50 {
        let (m, g) = maze(seed);
        // Roughly config/maps/maze.txt: 11.55 m square.
        assert!((g.width_m() - 11.55).abs() < 1e-9 && (g.height_m() - 11.55).abs() < 1e-9);
        assert_eq!(g.cell_m(), CELL_M);
        // Walls all round.
        let (w, h) = (g.width_cells() as i64, g.height_cells() as i64);
        for k in 0..w.max(h) {
            for (c, r) in [(k, 0), (k, h - 1), (0, k), (w - 1, k)] {
                if c < w && r < h {
                    assert!(g.is_wall_cell(c, r), "seed {seed}: border ({c},{r})");
                }
            }
        }
        assert_eq!(
            reachable(&g),
            floor_cells(&g),
            "seed {seed}: all floor reachable"
        );
        assert!(m.slots.contains(&SlotKind::Room), "seed {seed}");
        assert!(m.slots.contains(&SlotKind::Corridor), "seed {seed}");
        let holes = islands(&g);
        let pillars = holes.iter().filter(|&&s| s <= 9).count();
        let loops = holes.iter().filter(|&&s| s > 9).count();
        assert!(pillars >= 1, "seed {seed}: pillars {holes:?}");
        assert_eq!(pillars, m.pillars.len(), "seed {seed}");
        assert!(loops >= 1, "seed {seed}: no loop {holes:?}");
        assert!(m.loops >= 1, "seed {seed}");
        assert!(!m.dead_ends.is_empty(), "seed {seed}: no dead end");
        for d in &m.dead_ends {
            check_dead_end(&g, d, seed);
        }
        assert!(texts.insert(m.text.clone()), "seed {seed} repeats a layout");
    }
}

fn check_dead_end(g: &GridMap, d: &DeadEnd, seed: u64) {
    let r = d.cells;
    let (c0, r0) = (r.col as i64, r.row as i64);
    let (c1, r1) = (c0 + r.cols as i64, r0 + r.rows as i64);
    for row in r0..r1 {
        for col in c0..c1 {
            assert!(!wall(g, col, row), "seed {seed}: dead end {d:?} floor");
        }
    }
    let width = if matches!(d.open, Side::North | Side::South) {
        r.cols
    } else {
        r.rows
    };
    assert!(DOOR_CELLS.contains(&width), "seed {seed}: {d:?}");
    // Every side but the open one is wall all along.
    let sides = [
        (
            Side::North,
            (c0..c1).map(|c| (c, r0 - 1)).collect::<Vec<_>>(),
        ),
        (Side::South, (c0..c1).map(|c| (c, r1)).collect()),
        (Side::West, (r0..r1).map(|rr| (c0 - 1, rr)).collect()),
        (Side::East, (r0..r1).map(|rr| (c1, rr)).collect()),
    ];
    for (side, cells) in sides {
        let walled = cells.iter().all(|&(c, rr)| wall(g, c, rr));
        if side == d.open {
            assert!(
                cells.iter().all(|&(c, rr)| !wall(g, c, rr)),
                "seed {seed}: {d:?}"
            );
        } else {
            assert!(walled, "seed {seed}: {d:?} open on {side:?}");
        }
    }
}

#[test]
fn doorways_are_0_7_to_1_05_m_and_are_openings_in_walls() {
    for seed in 0..50 {
        let (m, g) = maze(seed);
        assert!(
            m.doorways.len() >= m.slots.len() - 1 - m.merged,
            "seed {seed}"
        );
        for d in &m.doorways {
            let wm = d.width_m();
            assert!(
                (0.7 - 1e-9..=1.05 + 1e-9).contains(&wm),
                "seed {seed}: {wm}"
            );
            let r = d.cells;
            let (c0, r0) = (r.col as i64, r.row as i64);
            let (c1, r1) = (c0 + r.cols as i64, r0 + r.rows as i64);
            for row in r0..r1 {
                for col in c0..c1 {
                    assert!(!wall(&g, col, row), "seed {seed}: doorway {d:?}");
                }
            }
            // The jambs: wall just beyond both ends of the opening, through the wall.
            let jambs: Vec<(i64, i64)> = if d.across_x {
                (r0..r1).flat_map(|rr| [(c0 - 1, rr), (c1, rr)]).collect()
            } else {
                (c0..c1).flat_map(|c| [(c, r0 - 1), (c, r1)]).collect()
            };
            assert!(
                jambs.iter().all(|&(c, rr)| wall(&g, c, rr)),
                "seed {seed}: doorway {d:?} is not {wm} m wide"
            );
        }
    }
}

#[test]
fn the_start_is_on_floor_with_room_to_turn() {
    for seed in 0..50 {
        let (_, g) = maze(seed);
        let s = g.start_pose();
        assert!(
            !g.rect_hits_wall(&s, 0.438, 0.311),
            "seed {seed}: footprint"
        );
        // Turning circle (0.27 m) with a margin: no wall cell within 0.45 m of the centre.
        let p = s.position();
        let (col, row) = g.cell_of(p.x, p.y);
        for dr in -4..=4 {
            for dc in -4..=4 {
                let (c, r) = (col + dc, row + dr);
                if !g.is_wall_cell(c, r) {
                    continue;
                }
                let cs = g.cell_m();
                let nx = p.x.clamp(c as f64 * cs, (c + 1) as f64 * cs);
                let ny = p.y.clamp(r as f64 * cs, (r + 1) as f64 * cs);
                let d = (Vec2::new(nx, ny) - p).length();
                assert!(
                    d >= START_CLEARANCE_M - 1e-9,
                    "seed {seed}: wall {d} m away"
                );
            }
        }
        // Facing a doorway: the way ahead is open for more than a metre.
        let hit = g.cast_ray(p, s.forward()).unwrap();
        assert!(
            hit.distance_m > 1.0,
            "seed {seed}: {} m ahead",
            hit.distance_m
        );
    }
}

#[test]
fn deterministic_per_seed_and_sizes_follow_the_rooms() {
    let a = generate_maze(&MazeOptions::default()).unwrap();
    let b = generate_maze(&MazeOptions::default()).unwrap();
    assert_eq!(a, b);
    for (rx, ry) in [(2, 2), (3, 2), (2, 5), (6, 3), (8, 8)] {
        for seed in 0..5 {
            let m = generate_maze(&MazeOptions {
                seed,
                rooms_x: rx,
                rooms_y: ry,
            })
            .unwrap();
            let g = load(&m);
            assert_eq!(g.width_cells(), 2 + 16 * rx);
            assert_eq!(g.height_cells(), 2 + 16 * ry);
            assert_eq!(reachable(&g), floor_cells(&g), "{rx}x{ry} seed {seed}");
            assert!(!m.pillars.is_empty());
        }
    }
}

#[test]
fn rooms_option_parses_and_bad_ones_are_errors() {
    assert_eq!(MazeOptions::parse_rooms("4x4"), Ok((4, 4)));
    assert_eq!(MazeOptions::parse_rooms("3X7"), Ok((3, 7)));
    for bad in ["4", "4x", "x4", "1x4", "4x17", "ax4", "-1x3", ""] {
        let e = MazeOptions::parse_rooms(bad).unwrap_err();
        assert!(e.to_string().contains(&format!("{bad:?}")), "{e}");
    }
    assert!(
        generate_maze(&MazeOptions {
            rooms_x: 1,
            ..MazeOptions::default()
        })
        .is_err()
    );
}

#[test]
fn a_small_example() {
    let m = generate_maze(&MazeOptions {
        seed: 3,
        rooms_x: 2,
        rooms_y: 2,
    })
    .unwrap();
    let g = load(&m);
    assert_eq!((g.width_cells(), g.height_cells()), (34, 34));
    assert!(
        m.text
            .lines()
            .next()
            .is_some_and(|l| l.starts_with("; generated"))
    );
}
