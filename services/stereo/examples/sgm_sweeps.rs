//! Tuning sweeps and a timing loop for the SGM matcher (moved out of the unit tests: timing
//! and tuning are not tests). Each subcommand prints one table to stdout:
//!
//! * `timing`: median, min, p10 and p90 wall time and the mean thread CPU time of one
//!   `compute` on the benchmark's slanted plane with webcam defects (`SGM_SIZE=320|640`,
//!   `SGM_ITERS` (30), `SGM_PATHS` (5), `SGM_SIMD=0` for the scalar kernels, `SGM_DUMP=PREFIX`
//!   writes the raw grey pair for timing other matchers on it).
//! * `subpixel`: mean and rms subpixel error on three synthetic planes (clean and with webcam
//!   defects) and on Middlebury venus with P1/P2 = 16/48.
//! * `flat-block`: valid and wrong shares in a flat block between two planes for a grid of
//!   noise sigma x texture threshold and radius (`SGM_P1`, `SGM_P2` override the penalties).
//! * `tune-penalties`: bad-2 / density / wrong-among-valid per Middlebury scene, clean and
//!   degraded, for each P1 in `SGM_P1S` (2,4,6,8,12) x P2 in `SGM_P2S` (16,24,32,48,64,80,96),
//!   with the mean bad-2 (pairs the matcher rejects, P2 above 79, are skipped with a note on
//!   stderr). Also read: `SGM_PATHS` (5), `SGM_TEXTURE` (a texture threshold; off
//!   when unset), `SGM_TEXR` (its radius), `SGM_UNIQ`, `SGM_LR` (0/1), `SGM_SPECKLE`,
//!   `SGM_PRE=0` (no prefilter), `SGM_DEG=gain,offset,sigma,shift` (0.8,10,4,1) and `SGM_SIMD`
//!   (set to anything: the scalar kernels, here and in `subpixel`).
//!
//! The Middlebury scenes (tsukuba, venus, motorcycle) are read from `../shared/datasets`
//! beside the repository (`/work/shared/datasets` when that is absent); missing ones are
//! skipped with a message.
//!
//! Run: `cargo run --release -p hvs-stereo --example sgm_sweeps -- <timing|subpixel|flat-block|tune-penalties>`,
//! e.g. `SGM_P1S=8,12,16 SGM_P2S=48,64,79 cargo run --release -p hvs-stereo --example sgm_sweeps -- tune-penalties`.

use std::error::Error;
use std::path::{Path, PathBuf};

use hvs_runtime::config::{SgmConfig, StereoConfig};
use hvs_shared::messages::StereoAlgorithm;
use hvs_stereo::sgm::SgmParams;
use hvs_stereo::synthetic::{SyntheticPair, degrade, flatten_region, plane};
use hvs_stereo::{ImageView, SgmMatcher, StereoMatcher};

const USAGE: &str = "usage: sgm_sweeps <timing|subpixel|flat-block|tune-penalties>";

type Result<T> = std::result::Result<T, Box<dyn Error>>;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["timing"] => timing(),
        ["subpixel"] => subpixel(),
        ["flat-block"] => flat_block(),
        ["tune-penalties"] => tune_penalties(),
        ["-h" | "--help"] => {
            println!("{USAGE}");
            Ok(())
        }
        _ => {
            eprintln!("{USAGE}");
            std::process::exit(2);
        }
    }
}

/// The sgm section of a default stereo config over `min_disp..=max_disp`.
fn config(min_disp: u32, max_disp: u32) -> StereoConfig {
    StereoConfig {
        algorithm: StereoAlgorithm::Sgm,
        min_disp,
        max_disp,
        ..StereoConfig::default()
    }
}

fn run(m: &mut SgmMatcher, pair: &SyntheticPair) -> Result<Vec<u16>> {
    let (w, h) = (pair.width, pair.height);
    let mut out = vec![0u16; w * h];
    let l = ImageView::new(&pair.left, w, h)?;
    let r = ImageView::new(&pair.right, w, h)?;
    m.compute(l, r, &mut out)?;
    Ok(out)
}

/// Webcam defects on the right image: gain 0.8, offset +10, noise sigma 4.
fn webcam(mut pair: SyntheticPair, seed: u64) -> SyntheticPair {
    degrade(&mut pair.right, pair.width, 0.8, 10.0, 4.0, 0, seed);
    pair
}

/// Two textured planes (left part at `d_far`, right part at `d_near`), as a robot sees a
/// wall with a box in front of it.
fn two_planes(
    w: usize,
    h: usize,
    split: usize,
    d_far: f32,
    d_near: f32,
    seed: u64,
) -> SyntheticPair {
    let far = plane(w, h, 0.0, 0.0, d_far, seed);
    let near = plane(w, h, 0.0, 0.0, d_near, seed ^ 0x77);
    let mut pair = far.clone();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x >= split {
                pair.left[i] = near.left[i];
                pair.disparity_px[i] = near.disparity_px[i];
            }
            // Right pixel x shows the near plane where it is in front: x + d_near >= split.
            if x as f32 + d_near >= split as f32 {
                pair.right[i] = near.right[i];
            }
        }
    }
    // Far pixels hidden behind the near plane in the right view are occluded.
    for y in 0..h {
        for x in 0..split.min(w) {
            if x as f32 - d_far + d_near >= split as f32 {
                pair.disparity_px[y * w + x] = f32::NAN;
            }
        }
    }
    pair
}

fn env_usize(k: &str, d: usize) -> usize {
    std::env::var(k)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(d)
}

fn env_u32(k: &str) -> Option<u32> {
    std::env::var(k).ok().and_then(|s| s.parse().ok())
}

fn env_list(k: &str, default: &[u32]) -> Vec<u32> {
    std::env::var(k)
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .unwrap_or_else(|| default.to_vec())
}

/// CPU time of this thread (utime + stime in clock ticks of 10 ms; 0 where /proc has none):
/// a fair measure when other processes share the cores.
fn cpu_ticks() -> u64 {
    std::fs::read_to_string("/proc/thread-self/stat")
        .ok()
        .and_then(|t| {
            // Fields after the name: state, ppid, ..., utime (11), stime (12).
            let f: Vec<&str> = t.rsplit(')').next()?.split_whitespace().collect();
            Some(f.get(11)?.parse::<u64>().ok()? + f.get(12)?.parse::<u64>().ok()?)
        })
        .unwrap_or(0)
}

fn timing() -> Result<()> {
    // The benchmark's scene: a slanted plane, disparities 12..53 (320x240) or 40..106.
    let (w, h, dmin, dmax, b, c) = if env_usize("SGM_SIZE", 320) == 640 {
        (640, 480, 18, 110, 50.0, 56.0)
    } else {
        (320, 240, 9, 55, 25.0, 28.0)
    };
    let pair = webcam(plane(w, h, -16.0 / w as f32, b / h as f32, c, 7), 8);
    if let Ok(prefix) = std::env::var("SGM_DUMP") {
        // Raw grey images, for timing other matchers on the same pair.
        for (side, data) in [("left", &pair.left), ("right", &pair.right)] {
            let path = format!("{prefix}_{w}x{h}_{side}.raw");
            std::fs::write(&path, data).map_err(|e| format!("writing {path}: {e}"))?;
        }
    }
    let mut cfg = config(dmin, dmax);
    cfg.sgm.paths = env_usize("SGM_PATHS", 5) as u32;
    let mut m = SgmMatcher::from_config(&cfg)?.with_simd(env_usize("SGM_SIMD", 1) == 1);
    let iters = env_usize("SGM_ITERS", 30).max(1);
    let mut out = vec![0u16; w * h];
    let l = ImageView::new(&pair.left, w, h)?;
    let r = ImageView::new(&pair.right, w, h)?;
    m.compute(l, r, &mut out)?; // warm-up
    let mut times = Vec::new();
    let c0 = cpu_ticks();
    for _ in 0..iters {
        let t = std::time::Instant::now();
        m.compute(l, r, &mut out)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(&out);
    }
    let cpu_ms = (cpu_ticks() - c0) as f64 * 10.0 / iters as f64;
    times.sort_by(f64::total_cmp);
    let pct = |q: f64| times[((times.len() - 1) as f64 * q) as usize];
    println!(
        "{w}x{h}: median {:.2} ms, min {:.2} ms (p10 {:.2}, p90 {:.2}), mean thread CPU time {:.2} ms",
        pct(0.5),
        times[0],
        pct(0.1),
        pct(0.9),
        cpu_ms
    );
    Ok(())
}

/// The folder of Middlebury scene `name`: `../shared/datasets/<name>` beside the repository,
/// else `/work/shared/datasets/<name>`.
fn scene_dir(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/datasets")
        .join(name);
    if dir.exists() {
        dir
    } else {
        Path::new("/work/shared/datasets").join(name)
    }
}

/// A Middlebury scene: grey pair, ground truth (px, 0 = unknown) and the scoring mask.
struct Scene {
    width: usize,
    height: usize,
    left: Vec<u8>,
    right: Vec<u8>,
    gt: Vec<f32>,
    mask: Vec<bool>,
    min_disp: u32,
    max_disp: u32,
}

/// An image as grey, `(0.299 R + 0.587 G + 0.114 B).round()` (the unit tests' conversion,
/// which differs from `hvs_stereo::eval::read_grey` in the last bit for a few pixels).
fn grey(path: &Path) -> Result<(Vec<u8>, usize, usize)> {
    let img = image::open(path)
        .map_err(|e| format!("{}: {e}", path.display()))?
        .into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = img
        .pixels()
        .map(|p| (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32).round() as u8)
        .collect();
    Ok((data, w, h))
}

fn load_scene(name: &str) -> Result<Scene> {
    let dir = scene_dir(name);
    let toml_path = dir.join("scene.toml");
    let toml_text =
        std::fs::read_to_string(&toml_path).map_err(|e| format!("{}: {e}", toml_path.display()))?;
    let t: toml::Table = toml_text
        .parse()
        .map_err(|e| format!("{}: {e}", toml_path.display()))?;
    let int = |k: &str| -> Result<u32> {
        let v = t.get(k).and_then(|v| v.as_integer());
        Ok(v.ok_or_else(|| format!("{}: no integer {k}", toml_path.display()))? as u32)
    };
    let (min_disp, max_disp) = (int("min_disp")?, int("max_disp")?);
    let mask_name = t
        .get("nonocc_mask")
        .and_then(|v| v.as_str())
        .filter(|s| !s.is_empty())
        .unwrap_or("all.png");
    let (left, width, height) = grey(&dir.join("left.png"))?;
    let (right, _, _) = grey(&dir.join("right.png"))?;
    let open = |file: &str| {
        let path = dir.join(file);
        image::open(&path).map_err(|e| format!("{}: {e}", path.display()))
    };
    let gt: Vec<f32> = open("gt_disp.png")?
        .into_luma16()
        .pixels()
        .map(|p| p[0] as f32 / 256.0)
        .collect();
    let mask: Vec<bool> = open(mask_name)?
        .into_luma8()
        .pixels()
        .map(|p| p[0] == 255)
        .collect();
    if gt.len() != width * height || mask.len() != width * height {
        return Err(format!(
            "{}: ground truth or mask not {width}x{height}",
            dir.display()
        )
        .into());
    }
    Ok(Scene {
        width,
        height,
        left,
        right,
        gt,
        mask,
        min_disp,
        max_disp,
    })
}

/// The scenes of `names` that load; the others are reported on stderr and left out.
fn load_scenes(names: &[&str]) -> Vec<Scene> {
    names
        .iter()
        .filter_map(|name| {
            load_scene(name)
                .inspect_err(|e| eprintln!("skipping {name}: {e}"))
                .ok()
        })
        .collect()
}

/// bad-2 (invalid or off by more than 2 px, over the scored pixels), the density, and the
/// error among the valid pixels.
fn bad2(scene: &Scene, est: &[u16]) -> (f32, f32, f32) {
    let (mut n, mut bad, mut valid, mut valid_bad) = (0usize, 0usize, 0usize, 0usize);
    for ((&gt, &scored), &q) in scene.gt.iter().zip(&scene.mask).zip(est) {
        if !scored || gt == 0.0 {
            continue;
        }
        n += 1;
        match hvs_stereo::q8_to_px(q) {
            Some(d) => {
                valid += 1;
                if (d - gt).abs() > 2.0 {
                    bad += 1;
                    valid_bad += 1;
                }
            }
            None => bad += 1,
        }
    }
    let n = n.max(1) as f32;
    (
        bad as f32 / n,
        valid as f32 / n,
        valid_bad as f32 / valid.max(1) as f32,
    )
}

/// One scene matched with `cfg` (`SGM_PRE=0`: no prefilter; `SGM_SIMD` set: scalar kernels),
/// with the texture threshold `texture` over radius `SGM_TEXR` where given.
fn run_scene(
    scene: &Scene,
    right: &[u8],
    cfg: &StereoConfig,
    texture: Option<f32>,
) -> Result<Vec<u16>> {
    let params = SgmParams {
        prefilter: std::env::var("SGM_PRE").map_or(true, |v| v != "0"),
        ..SgmParams::from_config(cfg)
    };
    let mut m = SgmMatcher::new(params)?.with_simd(std::env::var("SGM_SIMD").is_err());
    if let Some(t) = texture {
        let r = env_u32("SGM_TEXR").unwrap_or(SgmConfig::default().texture_radius);
        m = m.with_texture(t, r)?;
    }
    let mut out = vec![0u16; scene.width * scene.height];
    let l = ImageView::new(&scene.left, scene.width, scene.height)?;
    let r = ImageView::new(right, scene.width, scene.height)?;
    m.compute(l, r, &mut out)?;
    Ok(out)
}

/// The right image with webcam defects `SGM_DEG=gain,offset,sigma,shift` (0.8,10,4,1).
fn degraded_right(scene: &Scene) -> Vec<u8> {
    let mut r = scene.right.clone();
    let v: Vec<f32> = std::env::var("SGM_DEG")
        .ok()
        .map(|s| s.split(',').filter_map(|v| v.parse().ok()).collect())
        .filter(|v: &Vec<f32>| v.len() == 4)
        .unwrap_or_else(|| vec![0.8, 10.0, 4.0, 1.0]);
    degrade(&mut r, scene.width, v[0], v[1], v[2], v[3] as usize, 4242);
    r
}

fn subpixel() -> Result<()> {
    let (w, h) = (320, 240);
    let scenes = [
        ("wall", plane(w, h, -0.1, 0.0, 40.0, 51)),
        ("floor", plane(w, h, 0.0, 0.1, 12.0, 52)),
        ("front", plane(w, h, 0.0, 0.0, 30.37, 53)),
    ];
    for (name, pair) in scenes {
        for (label, p) in [("clean", pair.clone()), ("webcam", webcam(pair.clone(), 3))] {
            let mut m = SgmMatcher::from_config(&config(9, 55))?;
            let out = run(&mut m, &p)?;
            let (mut n, mut sum, mut sq) = (0usize, 0f64, 0f64);
            for (i, &q) in out.iter().enumerate() {
                let t = p.disparity_px[i];
                if q != 0 && (9.0..=55.0).contains(&t) {
                    let e = (q as f64 / 256.0 - t as f64).abs();
                    if e < 1.0 {
                        n += 1;
                        sum += e;
                        sq += e * e;
                    }
                }
            }
            println!(
                "{name} {label}: mean |err| {:.3} px, rms {:.3} px over {n}",
                sum / n as f64,
                (sq / n as f64).sqrt()
            );
        }
    }
    if let Some(scene) = load_scenes(&["venus"]).pop() {
        let mut cfg = config(scene.min_disp, scene.max_disp);
        cfg.sgm.p1 = 16;
        cfg.sgm.p2 = 48;
        let out = run_scene(&scene, &scene.right, &cfg, None)?;
        let (mut n, mut sum, mut bad05) = (0usize, 0f64, 0usize);
        for ((&q, &gt), &scored) in out.iter().zip(&scene.gt).zip(&scene.mask) {
            if scored && gt > 0.0 && q != 0 {
                let e = (q as f64 / 256.0 - gt as f64).abs();
                if e < 2.0 {
                    n += 1;
                    sum += e;
                    bad05 += usize::from(e > 0.5);
                }
            }
        }
        println!(
            "venus: mean |err| {:.3} px, bad-0.5 among good {:.1} %",
            sum / n as f64,
            100.0 * bad05 as f64 / n as f64
        );
    }
    Ok(())
}

fn flat_block() -> Result<()> {
    // 9..55 with `SGM_P1`/`SGM_P2` from the environment.
    let mut sweep_cfg = config(9, 55);
    sweep_cfg.sgm.p1 = env_u32("SGM_P1").unwrap_or(sweep_cfg.sgm.p1);
    sweep_cfg.sgm.p2 = env_u32("SGM_P2").unwrap_or(sweep_cfg.sgm.p2);
    let (w, h) = (320, 120);
    let (x0, x1) = (100, 200);
    for sigma in [0.0f32, 1.0, 2.0, 3.0] {
        for &(thr, r) in &[
            (0.0f32, 3u32),
            (0.25, 3),
            (0.25, 5),
            (0.3, 5),
            (0.375, 3),
            (0.5, 3),
            (0.625, 3),
            (0.75, 3),
            (1.0, 3),
        ] {
            let mut line = format!("sigma {sigma} thr {thr} r {r}:");
            for d_near in [24.0f32, 34.0] {
                let mut pair = two_planes(w, h, 150, 20.0, d_near, 21);
                flatten_region(&mut pair, x0, x1, 128);
                pair = webcam(pair, 5);
                degrade(&mut pair.left, w, 1.0, 0.0, sigma, 0, 6);
                let mut m = SgmMatcher::from_config(&sweep_cfg)?.with_texture(thr, r)?;
                let out = run(&mut m, &pair)?;
                let margin = 2 + r as usize + 1;
                let inside: Vec<usize> = (0..h)
                    .flat_map(|y| (x0 + margin..x1 - margin).map(move |x| y * w + x))
                    .collect();
                let valid = inside.iter().filter(|&&i| out[i] != 0).count();
                let wrong = inside
                    .iter()
                    .filter(|&&i| {
                        out[i] != 0 && (out[i] as f32 / 256.0 - pair.disparity_px[i]).abs() > 1.0
                    })
                    .count();
                line += &format!(
                    " valid {:.1}% wrong {:.1}%",
                    100.0 * valid as f32 / inside.len() as f32,
                    100.0 * wrong as f32 / inside.len() as f32
                );
            }
            println!("{line}");
        }
    }
    Ok(())
}

fn tune_penalties() -> Result<()> {
    let scenes = load_scenes(&["tsukuba", "venus", "motorcycle"]);
    if scenes.is_empty() {
        return Err("no Middlebury scenes found (see the messages above)".into());
    }
    let rights: Vec<Vec<u8>> = scenes.iter().map(degraded_right).collect();
    let p2s = env_list("SGM_P2S", &[16, 24, 32, 48, 64, 80, 96]);
    let p1s = env_list("SGM_P1S", &[2, 4, 6, 8, 12]);
    let texture: Option<f32> = std::env::var("SGM_TEXTURE")
        .ok()
        .and_then(|s| s.parse().ok());
    let paths = env_u32("SGM_PATHS").unwrap_or(5);
    for &p2 in &p2s {
        for &p1 in &p1s {
            if p1 > p2 {
                continue;
            }
            // P2 is capped (path costs fit a byte): the default grid reaches past it.
            let probe = SgmConfig {
                p1,
                p2,
                paths,
                ..Default::default()
            };
            if let Err(e) = SgmParams::from_config(&StereoConfig {
                sgm: probe,
                ..config(0, 16)
            })
            .validate()
            {
                eprintln!("p1 {p1:3} p2 {p2:3}: skipped ({e})");
                continue;
            }
            let mut line = format!("p1 {p1:3} p2 {p2:3}:");
            let mut total = 0.0;
            for (scene, right) in scenes.iter().zip(&rights) {
                let mut cfg = config(scene.min_disp, scene.max_disp);
                cfg.sgm = SgmConfig {
                    p1,
                    p2,
                    paths,
                    ..Default::default()
                };
                cfg.uniqueness_pct = env_u32("SGM_UNIQ").unwrap_or(cfg.uniqueness_pct);
                cfg.lr_check = env_u32("SGM_LR").map_or(cfg.lr_check, |v| v != 0);
                cfg.speckle_window_px = env_u32("SGM_SPECKLE").unwrap_or(cfg.speckle_window_px);
                for r in [&scene.right, right] {
                    let out = run_scene(scene, r, &cfg, texture)?;
                    let (b, dense, err) = bad2(scene, &out);
                    total += b;
                    line += &format!(
                        " {:5.1}/{:4.1}/{:4.1}",
                        100.0 * b,
                        100.0 * dense,
                        100.0 * err
                    );
                }
            }
            println!(
                "{line}  mean bad-2 {:.2}",
                100.0 * total / (2 * scenes.len()) as f32
            );
        }
    }
    Ok(())
}
