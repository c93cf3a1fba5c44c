//! `hvs bench stages`: time per frame of the fusion stage's work (Canny or Sobel edges, fused
//! map, window ranges) and of the decision stage's navigator, at 320x240 and 640x480, on a
//! rendered simulator pair with its real disparity map.

use anyhow::{Context, Result};
use hvs_decision::Navigator;
use hvs_fusion::{Canny, FusionPath, sobel_edges};
use hvs_runtime::config::HvsConfig;
use hvs_shared::messages::{MAX_RANGE_WINDOWS, RangeSource, RangeWindow};
use hvs_sim::{GridMap, SimConfig, SimWorld, StereoRig};
use hvs_stereo::{ImageView, matcher_for};

/// Median and 90th percentile of `f` over `n` runs, microseconds.
fn time_us(n: usize, mut f: impl FnMut()) -> (f64, f64) {
    f();
    let mut t: Vec<f64> = (0..n)
        .map(|_| {
            let s = std::time::Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e6
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[n / 2], t[(n * 9) / 10])
}

/// Runs the benchmark and prints a table.
pub fn run(config_path: &std::path::Path, frames: usize) -> Result<()> {
    let config = HvsConfig::load(config_path)
        .with_context(|| format!("config {}", config_path.display()))?;
    let map_path = config.resolve_path(&config.sim.map);
    let map = GridMap::load(&map_path).with_context(|| format!("map {}", map_path.display()))?;
    let frames = frames.max(10);
    println!(
        "{:<9} {:<34} {:>10} {:>10}",
        "size", "step", "median us", "p90 us"
    );
    for (w, h, stereo) in [(320, 240, &config.stereo.lo), (640, 480, &config.stereo.hi)] {
        let mut rig = StereoRig::new(w, h, config.camera.focal_px(w));
        rig.baseline_m = config.camera.baseline_m;
        let mut world = SimWorld::new(
            map.clone(),
            SimConfig {
                rig,
                ..SimConfig::default()
            },
        );
        let (mut left, mut right) = (vec![0u8; w * h], vec![0u8; w * h]);
        world.render(0.0, &mut left, &mut right, None)?;
        let mut disparity = vec![0u16; w * h];
        let mut matcher = matcher_for(stereo)?;
        matcher.compute(
            ImageView::new(&left, w, h)?,
            ImageView::new(&right, w, h)?,
            &mut disparity,
        )?;
        let mut confidence = vec![0u8; w * h];
        hvs_stereo::confidence_or_validity(matcher.as_ref(), &disparity, &mut confidence);
        let size = format!("{w}x{h}");
        let row =
            |step: &str, (m, p): (f64, f64)| println!("{size:<9} {step:<34} {m:>10.1} {p:>10.1}");
        let mut canny = Canny::new();
        let mut edges = vec![0u8; w * h];
        let f = &config.fusion;
        row(
            "canny",
            time_us(frames, || {
                canny.detect(&left, w, h, f.canny_low, f.canny_high, &mut edges);
            }),
        );
        row(
            "sobel",
            time_us(frames, || {
                sobel_edges(&left, w, h, f.canny_high, &mut edges);
            }),
        );
        let mut path = FusionPath::new(&config, w, h, RangeSource::Lo);
        let mut windows = [RangeWindow::default(); MAX_RANGE_WINDOWS];
        row(
            "fusion (edges+fuse+windows+scan)",
            time_us(frames, || {
                windows = path.ranges(&left, &disparity, Some(&confidence)).0;
            }),
        );
        let scan = *path.scan();
        // The local map on: the decision's worst case.
        let mut decision_cfg = config.decision.clone();
        decision_cfg.local_map = true;
        let mut nav = Navigator::new(&decision_cfg, &config.robot, &config.actuator.pulses);
        let mut t_ns = 0u64;
        row(
            if decision_cfg.fills_local_map() {
                "decision (navigator+local map)"
            } else {
                "decision (navigator, explore's grid)"
            },
            time_us(frames, || {
                t_ns += 33_000_000;
                std::hint::black_box(nav.decide(&windows, f.windows as usize, &scan, t_ns));
            }),
        );
    }
    Ok(())
}
