//! Short drives through the closed loop: the report's coverage fields and the options that
//! change the world.

use std::path::{Path, PathBuf};

use super::*;

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(p)
}

fn config() -> HvsConfig {
    HvsConfig::load(&repo("config/sim.toml")).expect("config/sim.toml")
}

fn opts(map: &str, seconds: f64) -> DriveOptions {
    DriveOptions {
        map: Some(repo("config/maps").join(map)),
        duration_s: seconds,
        ..DriveOptions::default()
    }
}

#[test]
fn the_report_has_coverage_and_its_curve() {
    let r = drive(&config(), &opts("straight.txt", 4.0)).expect("drives");
    assert!(r.reachable_cells > 0);
    assert!(
        r.coverage_pct > 0.0 && r.coverage_pct <= 100.0,
        "{}",
        r.coverage_pct
    );
    assert_eq!(
        r.coverage_curve.len(),
        1,
        "no 30 s point in 4 s: only the end"
    );
    let (t, pct) = r.coverage_curve[0];
    assert!((t - 4.0).abs() < 1e-9 && pct == r.coverage_pct);
    assert!(r.distance_m > 0.3, "{}", r.distance_m);
    assert!((r.cells_per_m - r.distinct_cells as f64 / r.distance_m).abs() < 1e-12);
    assert_eq!(r.wall_contrast, 1.0);
    assert!(!r.motion_noise);
    assert_eq!(r.seed, config().sim.seed);
    let json = serde_json::to_value(&r).expect("json");
    for key in [
        "coverage_pct",
        "explored_s",
        "coverage_curve",
        "cells_per_m",
    ] {
        assert!(json.get(key).is_some(), "{key}");
    }
}

#[test]
fn options_change_the_world_and_bad_ones_are_errors() {
    let c = config();
    let base = drive(&c, &opts("straight.txt", 3.0)).expect("drives");
    let noisy = drive(
        &c,
        &DriveOptions {
            motion_noise: Some(SimMotionNoise::realistic()),
            ..opts("straight.txt", 3.0)
        },
    )
    .expect("drives");
    assert!(noisy.motion_noise);
    assert_ne!(noisy.end, base.end, "the wheels slip");
    let plain = drive(
        &c,
        &DriveOptions {
            wall_contrast: Some(0.0),
            seed: Some(9),
            ..opts("straight.txt", 3.0)
        },
    )
    .expect("drives");
    assert_eq!((plain.wall_contrast, plain.seed), (0.0, 9));
    let maze = drive(
        &c,
        &DriveOptions {
            maze: Some(MazeOptions {
                seed: 4,
                ..MazeOptions::default()
            }),
            duration_s: 2.0,
            ..DriveOptions::default()
        },
    )
    .expect("drives a generated maze");
    assert_eq!(maze.map, "maze-4");
    assert!(maze.reachable_cells > 1000, "{}", maze.reachable_cells);
    let err = |o: DriveOptions| drive(&c, &o).map(|_| ()).unwrap_err().to_string();
    let e = err(DriveOptions {
        wall_contrast: Some(1.5),
        ..opts("straight.txt", 1.0)
    });
    assert!(e.contains("--wall-contrast"), "{e}");
    let e = err(DriveOptions {
        motion_noise: Some(SimMotionNoise {
            turn_slip: 2.0,
            ..SimMotionNoise::realistic()
        }),
        ..opts("straight.txt", 1.0)
    });
    assert!(
        e.contains("--motion-noise") && e.contains("turn_slip"),
        "{e}"
    );
    let e = err(DriveOptions {
        maze: Some(MazeOptions::default()),
        ..opts("straight.txt", 1.0)
    });
    assert!(e.contains("--map"), "{e}");
}
