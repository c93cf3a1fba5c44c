//! `hvs sim drive`: runs the closed-loop simulator (`hvs_drive`) and prints its report.

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
    println!("intersections: {:?}", r.intersections);
    println!("commands sent: {:?}", r.commands);
    Ok(())
}
