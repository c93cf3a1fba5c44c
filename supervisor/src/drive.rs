//! `hvs sim drive`: runs the closed-loop simulator (`hvs_drive`) and prints its report;
//! `hvs sim maze`: writes a generated maze map (`hvs_sim::maze`).

use std::path::Path;

use anyhow::{Context, Result};
use hvs_drive::{DriveOptions, drive};
use hvs_runtime::config::HvsConfig;

/// `hvs sim drive`: runs and prints the report.
pub fn run(config_path: &Path, opts: &DriveOptions, json: bool) -> Result<()> {
    let config = HvsConfig::load(config_path)
        .with_context(|| format!("config {}", config_path.display()))?;
    let r = drive(&config, opts)?;
    if json {
        println!("{}", serde_json::to_string_pretty(&r)?);
        return Ok(());
    }
    println!(
        "map {}: {:.0} s simulated in {:.1} s, {} decisions, visit memory {}, local map {}",
        r.map,
        r.duration_s,
        r.wall_s,
        r.decisions,
        if r.visit_memory { "on" } else { "off" },
        if r.local_map { "on" } else { "off" }
    );
    println!(
        "collisions {}  distinct cells {}  distance {:.1} m  end {:.2} m ahead, {:.2} m left",
        r.collisions, r.distinct_cells, r.distance_m, r.end_ahead_m, r.end_left_m
    );
    let explored = r
        .explored_s
        .map_or("never".to_string(), |t| format!("at {t:.0} s"));
    println!(
        "coverage {:.1} % of {} reachable cells (95 % {explored})  {:.2} cells/m  wall contrast {}  motion noise {}  seed {}",
        r.coverage_pct,
        r.reachable_cells,
        r.cells_per_m,
        r.wall_contrast,
        if r.motion_noise { "on" } else { "off" },
        r.seed
    );
    println!(
        "decision time (wall clock, this machine): median {:.0} us, p99 {:.0} us, largest {:.0} us",
        r.decision_latency.p50_ns as f64 * 1e-3,
        r.decision_latency.p99_ns as f64 * 1e-3,
        r.decision_latency.max_ns as f64 * 1e-3
    );
    println!("intersections: {:?}", r.intersections);
    println!("commands sent: {:?}", r.commands);
    Ok(())
}

/// `hvs sim maze`: generates the maze and writes it to `out` (standard output without).
pub fn maze(seed: u64, out: Option<&Path>, rooms: &str) -> Result<()> {
    let (rooms_x, rooms_y) = hvs_sim::MazeOptions::parse_rooms(rooms).context("--rooms")?;
    let m = hvs_sim::generate_maze(&hvs_sim::MazeOptions {
        seed,
        rooms_x,
        rooms_y,
    })?;
    match out {
        Some(path) => {
            std::fs::write(path, &m.text).with_context(|| format!("--out {}", path.display()))?;
            let summary = m.text.lines().next().unwrap_or_default();
            println!("{}: {}", path.display(), summary.trim_start_matches("; "));
        }
        None => print!("{}", m.text),
    }
    Ok(())
}
