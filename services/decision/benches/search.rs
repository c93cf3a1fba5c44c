//! Criterion benchmark of the explorer's search, the decision stage's costliest frame: the
//! inflated costmap over the grid's seen window, the Dijkstra cost field from the robot and
//! the frontier clusters, on a grid built from scans in a synthetic 12 m square floor of
//! rooms, doorways and pillars (a window of about 130x130 cells, as late in a maze run).
//!
//! Run: `cargo bench -p hvs-decision --bench search`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use hvs_decision::DeadReckonedPose;
use hvs_decision::explore::costmap::Costmap;
use hvs_decision::explore::frontier::{find_frontiers, frontier_cells};
use hvs_decision::explore::grid::OccupancyGrid;
use hvs_decision::explore::planner::CostField;
use hvs_runtime::config::{CostmapConfig, FrontierConfig, GridConfig, RobotConfig};
use hvs_shared::messages::{ObstacleScan, SCAN_BINS};

/// Floor edge, metres.
const FLOOR_M: f64 = 12.0;
/// Camera ahead of the robot's centre, metres (the default `[camera] forward_m`).
const CAMERA_FORWARD_M: f64 = 0.2;

/// Whether a point of the floor (start frame, metres) is inside a wall or a pillar: an
/// outer wall, inner walls every 3 m with a 0.9 m doorway in each span, a pillar in each
/// room's middle.
fn solid(x: f64, y: f64) -> bool {
    let (lo, hi) = (-1.0, FLOOR_M - 1.0);
    if x <= lo || y <= lo || x >= hi || y >= hi {
        return true;
    }
    let (u, v) = (x - lo, y - lo);
    let on_line = |w: f64| (w % 3.0) < 0.1;
    let in_door = |w: f64| (w % 3.0 - 1.5).abs() < 0.45;
    let pillar = ((u % 3.0) - 1.55).abs() < 0.15 && ((v % 3.0) - 0.8).abs() < 0.15;
    (on_line(u) && !in_door(v)) || (on_line(v) && !in_door(u)) || pillar
}

/// The depth (along the optical axis) of the first solid point on each bin's ray, by
/// marching 1 cm steps up to 6 m; 0 (no data) beyond.
fn scan_from(pose: &DeadReckonedPose) -> ObstacleScan {
    let mut scan = ObstacleScan {
        tan_half_fov: 0.55,
        ..ObstacleScan::default()
    };
    let (s, c) = pose.heading_rad.sin_cos();
    let (cx, cy) = (
        pose.x_m + CAMERA_FORWARD_M * c,
        pose.y_m + CAMERA_FORWARD_M * s,
    );
    for i in 0..SCAN_BINS {
        let t = scan.bin_tangent(i);
        let n = t.hypot(1.0);
        let (ax, ay) = (1.0 / n, t / n);
        let dir = (ax * c - ay * s, ax * s + ay * c);
        scan.range_m[i] = (1..600)
            .map(|k| f64::from(k) * 0.01)
            .find(|d| solid(cx + d * dir.0, cy + d * dir.1))
            .map_or(0.0, |d| (d * ax) as f32);
    }
    scan
}

/// A grid after looking all round from every free point of a 1 m lattice.
fn explored_grid() -> OccupancyGrid {
    let mut grid = OccupancyGrid::new(GridConfig::default());
    for ix in 0..11 {
        for iy in 0..11 {
            let (x, y) = (f64::from(ix) - 0.3, f64::from(iy) - 0.3);
            if solid(x, y) {
                continue;
            }
            for q in 0..8 {
                let pose = DeadReckonedPose {
                    x_m: x,
                    y_m: y,
                    heading_rad: f64::from(q) * std::f64::consts::FRAC_PI_4,
                };
                let points = grid.scan_points(&pose, CAMERA_FORWARD_M, &scan_from(&pose));
                grid.insert(&points);
            }
        }
    }
    grid
}

fn bench(c: &mut Criterion) {
    let grid = explored_grid();
    let Some(robot) = grid.cell_of(4.7, 4.7) else {
        panic!("the robot's cell is off the grid");
    };
    let body = RobotConfig::default();
    let build = || {
        Costmap::build(
            &grid,
            CostmapConfig::default(),
            0.5 * body.width_m,
            body.half_diagonal_m(),
            robot,
        )
    };
    let map = build();
    let Some(start) = map.index(robot) else {
        panic!("the robot's cell is outside the costmap's window");
    };
    let is_frontier = frontier_cells(&map);
    let field = CostField::to_targets(&map, start, &is_frontier);
    let centre = |i: usize| grid.centre(map.cell(i));
    let frontiers = find_frontiers(
        &map,
        &field,
        &is_frontier,
        &FrontierConfig::default(),
        centre,
    );
    let (_, cols, rows) = map.window();
    println!(
        "search: window {cols}x{rows} cells, {} frontiers",
        frontiers.len()
    );

    let mut group = c.benchmark_group("search");
    group
        .sample_size(50)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    group.bench_function("costmap_build", |b| b.iter(|| black_box(build())));
    group.bench_function("cost_field_whole", |b| {
        b.iter(|| black_box(CostField::from_start(black_box(&map), start)))
    });
    group.bench_function("cost_field_to_frontiers", |b| {
        b.iter(|| black_box(CostField::to_targets(black_box(&map), start, &is_frontier)))
    });
    group.bench_function("frontier_cells_and_clusters", |b| {
        b.iter(|| {
            let is_frontier = frontier_cells(&map);
            black_box(find_frontiers(
                &map,
                &field,
                &is_frontier,
                &FrontierConfig::default(),
                centre,
            ))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
