//! `hvs stereo`, `hvs eval` and `hvs bench stereo`: run, score and time the stereo matchers
//! outside the pipeline.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, bail};
use hvs_runtime::config::{HvsConfig, StereoConfig};
use hvs_shared::messages::StereoAlgorithm;
use hvs_stereo::eval::{self, Degradation, Scene, SceneResult, Score};
use hvs_stereo::{ImageView, matcher_for};
use serde::Serialize;

/// Which stereo settings a command starts from.
#[derive(Debug, Clone, clap::Args)]
pub struct StereoBase {
    /// Take the settings of a config file's `[stereo.lo]` (or `--path hi`: `[stereo.hi]`)
    /// section; without it the built-in defaults are used.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Which section of --config.
    #[arg(long, default_value = "lo", value_parser = ["lo", "hi"])]
    pub path: String,
    /// Do not equalise the right image's mean to the left's before matching.
    #[arg(long)]
    pub no_equalize: bool,
    /// Do not measure and remove the vertical offset between the images (row_align).
    #[arg(long)]
    pub no_row_align: bool,
}

impl StereoBase {
    fn load(&self) -> anyhow::Result<StereoConfig> {
        let mut cfg = match &self.config {
            Some(path) => {
                let c = HvsConfig::load(path)?;
                if self.path == "hi" {
                    c.stereo.hi
                } else {
                    c.stereo.lo
                }
            }
            None => StereoConfig::default(),
        };
        if self.no_equalize {
            cfg.equalize = false;
        }
        if self.no_row_align {
            cfg.row_align.enabled = false;
        }
        Ok(cfg)
    }
}

/// Parses an algorithm name, listing the valid ones on error.
pub fn parse_algorithm(name: &str) -> anyhow::Result<StereoAlgorithm> {
    StereoAlgorithm::from_label(name).with_context(|| {
        let names: Vec<&str> = StereoAlgorithm::ALL.iter().map(|a| a.label()).collect();
        format!(
            "unknown stereo algorithm {name:?}; choose one of {}",
            names.join(", ")
        )
    })
}

fn algorithms(name: &str) -> anyhow::Result<Vec<StereoAlgorithm>> {
    if name == "all" {
        Ok(StereoAlgorithm::ALL.to_vec())
    } else {
        name.split(',').map(parse_algorithm).collect()
    }
}

/// `hvs stereo`: one pair in, one 16-bit disparity PNG out.
pub fn stereo(
    algo: Option<&str>,
    left: &Path,
    right: &Path,
    out: &Path,
    min_disp: Option<u32>,
    max_disp: Option<u32>,
    base: &StereoBase,
) -> anyhow::Result<()> {
    let mut cfg = base.load()?;
    if let Some(a) = algo {
        cfg.algorithm = parse_algorithm(a)?;
    }
    if let Some(m) = min_disp {
        cfg.min_disp = m;
    }
    if let Some(m) = max_disp {
        cfg.max_disp = m;
    }
    let (l, lw, lh) = eval::read_grey(left)?;
    let (r, rw, rh) = eval::read_grey(right)?;
    if (lw, lh) != (rw, rh) {
        bail!(
            "left image {} is {lw}x{lh} but right image {} is {rw}x{rh}",
            left.display(),
            right.display()
        );
    }
    let mut matcher = matcher_for(&cfg)?;
    let mut disp = vec![0u16; lw * lh];
    let t = Instant::now();
    let stats = matcher.compute(
        ImageView::new(&l, lw, lh)?,
        ImageView::new(&r, rw, rh)?,
        &mut disp,
    )?;
    let ms = t.elapsed().as_secs_f64() * 1e3;
    eval::write_disparity_png(out, &disp, lw, lh)?;
    println!(
        "wrote {}: {lw}x{lh}, {} disparities {}..{}, {:.1}% valid, {ms:.1} ms",
        out.display(),
        cfg.algorithm.label(),
        cfg.min_disp,
        cfg.max_disp,
        100.0 * stats.valid_px as f64 / (lw * lh).max(1) as f64
    );
    Ok(())
}

/// Options of `hvs eval`.
#[derive(Debug, Clone)]
pub struct EvalOptions {
    /// Algorithm name, comma-separated list, or `all`.
    pub algo: String,
    /// Dataset folder.
    pub dataset: PathBuf,
    /// Also score with webcam defects.
    pub degrade: bool,
    /// JSON output.
    pub json: bool,
    /// Timing repeats per scene.
    pub repeat: usize,
    /// Write the (degraded) grey inputs here for external tools.
    pub export: Option<PathBuf>,
    /// Score external predictions from this folder instead of running a matcher.
    pub predictions: Option<PathBuf>,
    /// Write our disparity maps here.
    pub save: Option<PathBuf>,
    /// Also score with the right image shifted down by each of these rows (negative: up).
    pub vshift: Vec<i32>,
}

/// One row of `hvs eval`.
#[derive(Debug, Serialize)]
struct Row {
    algorithm: String,
    condition: String,
    #[serde(flatten)]
    result: SceneResult,
}

/// Mean over scenes.
#[derive(Debug, Serialize)]
struct MeanRow {
    algorithm: String,
    condition: String,
    bad1_pct: f64,
    bad2_pct: f64,
    density_pct: f64,
    ms_per_frame: f64,
}

/// The conditions scored: clean, degraded (`--degrade`), and each of them with the right
/// image shifted by every `--vshift` (which replaces the degradation's own 1 px shift).
fn conditions(degrade: bool, vshifts: &[i32]) -> Vec<(String, Option<Degradation>, i32)> {
    let mut bases = vec![("clean", None)];
    if degrade {
        bases.push(("degraded", Some(Degradation::default())));
    }
    let mut c = Vec::new();
    for (name, d) in bases {
        c.push((name.to_string(), d, 0));
        for &v in vshifts.iter().filter(|&&v| v != 0) {
            let d = d.map(|d| Degradation {
                vertical_shift_px: 0,
                ..d
            });
            c.push((format!("{name}-v{v:+}"), d, v));
        }
    }
    c
}

/// `hvs eval`.
pub fn eval(opts: &EvalOptions, base: &StereoBase) -> anyhow::Result<()> {
    let base_cfg = base.load()?;
    let scene_dirs = eval::list_scenes(&opts.dataset)?;
    let mut scenes = Vec::new();
    for dir in &scene_dirs {
        scenes.push(eval::load_scene(dir)?);
    }
    let mut rows = Vec::new();
    // Progress on a terminal only; redirected output stays clean.
    let progress = !opts.json && std::io::IsTerminal::is_terminal(&std::io::stderr());
    for (condition, degradation, vshift) in conditions(opts.degrade, &opts.vshift) {
        let condition = condition.as_str();
        let prepared: Vec<Scene> = scenes
            .iter()
            .map(|s| {
                let mut s = s.clone();
                if let Some(d) = &degradation {
                    s.degrade(d);
                }
                if vshift != 0 {
                    s.shift_right(vshift);
                }
                s
            })
            .collect();
        if let Some(dir) = &opts.export {
            export(dir, &prepared, condition)?;
        }
        if let Some(dir) = &opts.predictions {
            for s in &prepared {
                let path = dir.join(format!("{}-{condition}.png", s.name));
                let (est, w, h) = eval::read_disparity_png(&path)?;
                if (w, h) != (s.width, s.height) {
                    bail!(
                        "{} is {w}x{h}, scene {} is {}x{}",
                        path.display(),
                        s.name,
                        s.width,
                        s.height
                    );
                }
                rows.push(Row {
                    algorithm: opts.algo.clone(),
                    condition: condition.to_string(),
                    result: SceneResult {
                        scene: s.name.clone(),
                        region: s.region,
                        score: eval::score(&s.gt_q8, &s.scored, &est),
                        ms_per_frame: f64::NAN,
                        row_shift_px: None,
                        estimate_q8: Vec::new(),
                    },
                });
            }
            continue;
        }
        let algos = if opts.algo == "none" {
            Vec::new()
        } else {
            algorithms(&opts.algo)?
        };
        for algo in algos {
            let cfg = StereoConfig {
                algorithm: algo,
                ..base_cfg.clone()
            };
            for s in &prepared {
                if progress {
                    eprint!("\r{:<10} {:<9} {:<12}", algo.label(), condition, s.name);
                }
                let r = eval::evaluate(&cfg, s, opts.repeat)?;
                if let Some(dir) = &opts.save {
                    std::fs::create_dir_all(dir)
                        .with_context(|| format!("cannot create {}", dir.display()))?;
                    let path = dir.join(format!("{}-{}-{condition}.png", s.name, algo.label()));
                    eval::write_disparity_png(&path, &r.estimate_q8, s.width, s.height)?;
                }
                rows.push(Row {
                    algorithm: algo.label().to_string(),
                    condition: condition.to_string(),
                    result: r,
                });
            }
        }
    }
    if progress {
        eprint!("\r{:<40}\r", "");
    }
    if rows.is_empty() {
        // `--algo none --export DIR`: inputs written, nothing to score.
        return Ok(());
    }
    let means = means(&rows);
    if opts.json {
        #[derive(Serialize)]
        struct Out<'a> {
            rows: &'a [Row],
            means: &'a [MeanRow],
        }
        println!(
            "{}",
            serde_json::to_string_pretty(&Out {
                rows: &rows,
                means: &means
            })?
        );
        return Ok(());
    }
    println!(
        "{:<12} {:<14} {:<11} {:<7} {:>8} {:>8} {:>10} {:>9} {:>8}",
        "algorithm",
        "condition",
        "scene",
        "region",
        "bad-1 %",
        "bad-2 %",
        "density %",
        "ms/frame",
        "rows px"
    );
    for r in &rows {
        let s: &Score = &r.result.score;
        println!(
            "{:<12} {:<14} {:<11} {:<7} {:>8.2} {:>8.2} {:>10.1} {:>9.2} {:>8}",
            r.algorithm,
            r.condition,
            r.result.scene,
            r.result.region,
            s.bad1_pct,
            s.bad2_pct,
            s.density_pct,
            r.result.ms_per_frame,
            r.result
                .row_shift_px
                .map_or("-".to_string(), |v| format!("{v:+.2}"))
        );
    }
    for m in &means {
        println!(
            "{:<12} {:<14} {:<11} {:<7} {:>8.2} {:>8.2} {:>10.1} {:>9.2}",
            m.algorithm,
            m.condition,
            "MEAN",
            "",
            m.bad1_pct,
            m.bad2_pct,
            m.density_pct,
            m.ms_per_frame
        );
    }
    Ok(())
}

fn means(rows: &[Row]) -> Vec<MeanRow> {
    let mut out: Vec<MeanRow> = Vec::new();
    for r in rows {
        if out
            .iter()
            .any(|m| m.algorithm == r.algorithm && m.condition == r.condition)
        {
            continue;
        }
        let group: Vec<&Row> = rows
            .iter()
            .filter(|x| x.algorithm == r.algorithm && x.condition == r.condition)
            .collect();
        let n = group.len() as f64;
        let avg = |f: &dyn Fn(&Row) -> f64| group.iter().map(|x| f(x)).sum::<f64>() / n;
        out.push(MeanRow {
            algorithm: r.algorithm.clone(),
            condition: r.condition.clone(),
            bad1_pct: avg(&|x| x.result.score.bad1_pct),
            bad2_pct: avg(&|x| x.result.score.bad2_pct),
            density_pct: avg(&|x| x.result.score.density_pct),
            ms_per_frame: avg(&|x| x.result.ms_per_frame),
        });
    }
    out
}

/// Writes `<dir>/<scene>-<condition>/{left,right}.png` and a `scenes.tsv` line per scene
/// (name, condition, width, height, min_disp, max_disp) for external matchers.
fn export(dir: &Path, scenes: &[Scene], condition: &str) -> anyhow::Result<()> {
    use std::io::Write;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let list = dir.join("scenes.tsv");
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&list)
        .with_context(|| format!("cannot write {}", list.display()))?;
    for s in scenes {
        let sub = dir.join(format!("{}-{condition}", s.name));
        std::fs::create_dir_all(&sub)
            .with_context(|| format!("cannot create {}", sub.display()))?;
        eval::write_grey_png(&sub.join("left.png"), &s.left, s.width, s.height)?;
        eval::write_grey_png(&sub.join("right.png"), &s.right, s.width, s.height)?;
        writeln!(
            f,
            "{}\t{condition}\t{}\t{}\t{}\t{}",
            s.name, s.width, s.height, s.min_disp, s.max_disp
        )?;
    }
    Ok(())
}

/// The built-in benchmark pair: the simulator's T junction at the start pose, mild webcam
/// noise, at the requested size (no dataset needed).
pub fn bench_pair(width: usize) -> anyhow::Result<(Vec<u8>, Vec<u8>, usize, usize)> {
    let map = hvs_sim::GridMap::parse(
        include_str!("../../config/maps/t_bottom.txt"),
        "t_bottom.txt",
    )?;
    let rig = if width == 320 {
        hvs_sim::StereoRig::qvga()
    } else {
        hvs_sim::StereoRig::vga()
    };
    let renderer = hvs_sim::Renderer::new(&map, rig);
    let n = rig.width * rig.height;
    let (mut l, mut r) = (vec![0u8; n], vec![0u8; n]);
    let pose = map.start_pose();
    renderer.render_pair(&pose, &pose, &mut l, &mut r, None)?;
    let defects = hvs_sim::WebcamDefects {
        noise_sigma: 2.0,
        ..hvs_sim::WebcamDefects::none()
    };
    defects.apply(
        &mut l,
        &mut r,
        rig.width,
        rig.height,
        &mut hvs_sim::sim_rng(3),
    )?;
    Ok((l, r, rig.width, rig.height))
}

/// `hvs bench stereo`.
/// One line of `hvs bench stereo --json`.
#[derive(Debug, Serialize)]
struct BenchRow {
    algorithm: String,
    width: usize,
    height: usize,
    min_disp: u32,
    max_disp: u32,
    median_ms: f64,
    p10_ms: f64,
    p90_ms: f64,
    mdisp_per_s: f64,
}

pub fn bench(
    algo: &str,
    sizes: &str,
    frames: usize,
    export: Option<&Path>,
    json: bool,
    base: &StereoBase,
) -> anyhow::Result<()> {
    let base_cfg = base.load()?;
    let sizes: Vec<usize> = match sizes {
        "320x240" => vec![320],
        "640x480" => vec![640],
        "both" => vec![320, 640],
        other => bail!("--size {other:?}: use 320x240, 640x480 or both"),
    };
    if !json {
        println!(
            "{:<10} {:<8} {:>9} {:>9} {:>9} {:>9} {:>12}",
            "algorithm", "size", "disp", "median ms", "p10 ms", "p90 ms", "Mdisp/s"
        );
    }
    let mut rows = Vec::new();
    for width in sizes {
        let (l, r, w, h) = bench_pair(width)?;
        let (min_disp, max_disp) = if width == 320 { (9, 55) } else { (18, 110) };
        if let Some(dir) = export {
            std::fs::create_dir_all(dir)
                .with_context(|| format!("cannot create {}", dir.display()))?;
            eval::write_grey_png(&dir.join(format!("left-{w}x{h}.png")), &l, w, h)?;
            eval::write_grey_png(&dir.join(format!("right-{w}x{h}.png")), &r, w, h)?;
        }
        for a in algorithms(algo)? {
            let cfg = StereoConfig {
                algorithm: a,
                min_disp,
                max_disp,
                ..base_cfg.clone()
            };
            let mut matcher = matcher_for(&cfg)?;
            let mut out = vec![0u16; w * h];
            let (lv, rv) = (ImageView::new(&l, w, h)?, ImageView::new(&r, w, h)?);
            for _ in 0..3 {
                matcher.compute(lv, rv, &mut out)?;
            }
            let mut times = Vec::with_capacity(frames);
            for _ in 0..frames.max(1) {
                let t = Instant::now();
                matcher.compute(lv, rv, &mut out)?;
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
            times.sort_by(f64::total_cmp);
            let pick = |q: f64| times[((times.len() - 1) as f64 * q).round() as usize];
            let median = pick(0.5);
            let evals = (w * h) as f64 * (max_disp - min_disp + 1) as f64;
            let row = BenchRow {
                algorithm: a.label().to_string(),
                width: w,
                height: h,
                min_disp,
                max_disp,
                median_ms: median,
                p10_ms: pick(0.1),
                p90_ms: pick(0.9),
                mdisp_per_s: evals / (median / 1e3) / 1e6,
            };
            if !json {
                println!(
                    "{:<10} {:<8} {:>9} {:>9.2} {:>9.2} {:>9.2} {:>12.1}",
                    row.algorithm,
                    format!("{w}x{h}"),
                    format!("{min_disp}..{max_disp}"),
                    row.median_ms,
                    row.p10_ms,
                    row.p90_ms,
                    row.mdisp_per_s
                );
            }
            rows.push(row);
        }
        // The row alignment's measurement on its own, and amortised over the frames between
        // two measurements (the matchers' rows above include it).
        let (lv, rv) = (ImageView::new(&l, w, h)?, ImageView::new(&r, w, h)?);
        let ra = &base_cfg.row_align;
        let mut times = Vec::with_capacity(frames.max(1));
        let mut found = None;
        for _ in 0..frames.max(1) {
            let t = Instant::now();
            found = hvs_stereo::rowalign::estimate_shift(
                lv,
                rv,
                min_disp as usize,
                max_disp as usize,
                ra.max_shift_px as usize,
            );
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        times.sort_by(f64::total_cmp);
        let median = times[times.len() / 2];
        if !json {
            println!(
                "{:<10} {:<8} {:>9} {:>9.3} {:>9} {:>9} {:>12}   (every {} frames: {:.3} ms a frame; \
                 estimate {})",
                "row-align",
                format!("{w}x{h}"),
                format!("+-{}", ra.max_shift_px),
                median,
                "",
                "",
                "",
                ra.every_n_frames,
                median / ra.every_n_frames as f64,
                found.map_or("none".to_string(), |e| format!(
                    "{:+.2} px, {} of {} votes",
                    e.shift_px, e.agreeing, e.votes
                ))
            );
        }
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&rows)?);
    }
    Ok(())
}
