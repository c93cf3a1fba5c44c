//! Block-matcher accuracy on the Middlebury scenes (tsukuba, venus, motorcycle), each clean
//! and with webcam defects on the right image (gain 0.8, offset +10, noise sigma 4, a 1 px
//! vertical shift; `BM_SHIFT=0` leaves the shift out), for the four costs (SAD, SSD, NCC,
//! census 5x5). Moved out of the unit tests: tuning tables are not tests.
//!
//! Subcommands (one table each, on stdout):
//!
//! * `defaults`: `TABLE` lines (bad-1, bad-2, density, wrong-among-valid, %) per scene and
//!   cost with `BlockParams::new`, and the mean per cost.
//! * `plain-wta`: the same with the reference system's plain winner-take-all (no
//!   equalisation, texture, uniqueness, left-right check or speckle filter; subpixel kept).
//! * `recommended`: the same with the window, uniqueness and texture of
//!   `BlockParams::recommended`.
//! * `sweep`: `SWEEP` lines (mean bad-2, density, wrong-among-valid, and bad-2/wrong per
//!   scene) for every cost x window in `BM_WINDOWS` (5,7,9,11,13,15) x texture threshold in
//!   `BM_TEXTURES` (0,2,4,8) x uniqueness in `BM_UNIQ` (0,5,10,15,25).
//!
//! The scenes are read from `BM_DATASETS` (default `/work/shared/datasets`, the
//! `../shared/datasets` beside the repository); missing ones are skipped with a message (none found: an error).
//!
//! Run: `cargo run --release -p hvs-stereo --example block_tables -- <defaults|plain-wta|recommended|sweep>`,
//! e.g. `BM_WINDOWS=9,15 BM_UNIQ=5 cargo run --release -p hvs-stereo --example block_tables -- sweep`.

use std::error::Error;
use std::path::PathBuf;

use hvs_stereo::block::{BlockCost, BlockParams};
use hvs_stereo::synthetic::degrade;
use hvs_stereo::{BlockMatcher, ImageView, StereoMatcher};

const USAGE: &str = "usage: block_tables <defaults|plain-wta|recommended|sweep>";

type Result<T> = std::result::Result<T, Box<dyn Error>>;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["defaults"] => table(&|_, _| {}),
        // The reference system's plain winner-take-all: window 9, no refinement but subpixel.
        ["plain-wta"] => table(&|_, p| {
            p.equalize = false;
            p.texture_threshold = 0;
            p.uniqueness_pct = 0;
            p.lr_check = false;
            p.speckle_window_px = 0;
        }),
        // The recommended per-cost settings (see the block module documentation).
        ["recommended"] => table(&|_, p| {
            let r = BlockParams::recommended(p.cost, p.min_disp, p.max_disp);
            p.window = r.window;
            p.uniqueness_pct = r.uniqueness_pct;
            p.texture_threshold = r.texture_threshold;
        }),
        ["sweep"] => sweep(),
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

/// A scene with its ground truth in px (NaN where not scored).
struct Scene {
    name: String,
    w: usize,
    h: usize,
    left: Vec<u8>,
    right: Vec<u8>,
    gt: Vec<f32>,
    min_disp: u32,
    max_disp: u32,
}

/// Each scene that loads, clean (`false`) and with webcam defects (`true`).
fn scenes() -> Result<Vec<(Scene, bool)>> {
    let root = std::env::var("BM_DATASETS")
        .map(PathBuf::from)
        .unwrap_or_else(|_| PathBuf::from("/work/shared/datasets"));
    let shift = std::env::var("BM_SHIFT")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let mut out = Vec::new();
    for name in ["tsukuba", "venus", "motorcycle"] {
        let dir = root.join(name);
        let s = match hvs_stereo::eval::load_scene(&dir) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("skipping {name} ({}): {e}", dir.display());
                continue;
            }
        };
        let gt = s
            .gt_q8
            .iter()
            .zip(&s.scored)
            .map(|(&g, &scored)| {
                if g == 0 || !scored {
                    f32::NAN
                } else {
                    g as f32 / 256.0
                }
            })
            .collect();
        let scene = Scene {
            name: s.name,
            w: s.width,
            h: s.height,
            left: s.left,
            right: s.right,
            gt,
            min_disp: s.min_disp,
            max_disp: s.max_disp,
        };
        let mut bad = Scene {
            name: scene.name.clone(),
            left: scene.left.clone(),
            right: scene.right.clone(),
            gt: scene.gt.clone(),
            ..scene
        };
        degrade(&mut bad.right, bad.w, 0.8, 10.0, 4.0, shift, 99);
        out.push((scene, false));
        out.push((bad, true));
    }
    if out.is_empty() {
        return Err(format!("no Middlebury scenes under {}", root.display()).into());
    }
    Ok(out)
}

/// bad-1, bad-2 (invalid counts as bad), density, and the share of valid pixels off by
/// more than 2 px, over the scored pixels.
fn score(scene: &Scene, est: &[u16]) -> [f32; 4] {
    let (mut n, mut b1, mut b2, mut valid, mut wrong) = (0usize, 0usize, 0usize, 0usize, 0usize);
    for (&t, &e) in scene.gt.iter().zip(est) {
        if !t.is_finite() {
            continue;
        }
        n += 1;
        match hvs_stereo::q8_to_px(e) {
            None => {
                b1 += 1;
                b2 += 1;
            }
            Some(d) => {
                valid += 1;
                let err = (d - t).abs();
                b1 += usize::from(err > 1.0);
                b2 += usize::from(err > 2.0);
                wrong += usize::from(err > 2.0);
            }
        }
    }
    let n = n.max(1) as f32;
    [
        b1 as f32 / n,
        b2 as f32 / n,
        valid as f32 / n,
        wrong as f32 / valid.max(1) as f32,
    ]
}

fn run(p: &BlockParams, scene: &Scene) -> Result<[f32; 4]> {
    let mut m = BlockMatcher::new(p.clone())?;
    let mut out = vec![0u16; scene.w * scene.h];
    let l = ImageView::new(&scene.left, scene.w, scene.h)?;
    let r = ImageView::new(&scene.right, scene.w, scene.h)?;
    m.compute(l, r, &mut out)?;
    Ok(score(scene, &out))
}

fn costs() -> [(&'static str, BlockCost); 4] {
    [
        ("sad", BlockCost::Sad),
        ("ssd", BlockCost::Ssd),
        ("ncc", BlockCost::Ncc),
        (
            "census",
            BlockCost::Census {
                width: 5,
                height: 5,
            },
        ),
    ]
}

/// One line per scene, defects and cost: bad-1, bad-2, density, wrong-among-valid, with
/// the parameters `tune` makes from the defaults.
fn table(tune: &dyn Fn(&str, &mut BlockParams)) -> Result<()> {
    let scenes = scenes()?;
    for (name, cost) in costs() {
        let mut sums = [0f32; 4];
        for (scene, bad) in &scenes {
            let mut p = BlockParams::new(cost, scene.min_disp, scene.max_disp);
            tune(name, &mut p);
            let s = run(&p, scene)?;
            for (a, b) in sums.iter_mut().zip(s) {
                *a += b;
            }
            println!(
                "TABLE {:<10} {:<7} {:<6} bad1 {:5.1} bad2 {:5.1} dens {:5.1} wrong {:5.1}",
                scene.name,
                if *bad { "defects" } else { "clean" },
                name,
                100.0 * s[0],
                100.0 * s[1],
                100.0 * s[2],
                100.0 * s[3]
            );
        }
        let k = scenes.len().max(1) as f32;
        println!(
            "TABLE {:<10} {:<7} {:<6} bad1 {:5.1} bad2 {:5.1} dens {:5.1} wrong {:5.1}",
            "mean",
            "",
            name,
            100.0 * sums[0] / k,
            100.0 * sums[1] / k,
            100.0 * sums[2] / k,
            100.0 * sums[3] / k
        );
    }
    Ok(())
}

fn sweep() -> Result<()> {
    let scenes = scenes()?;
    let list = |var: &str, default: &str| -> Vec<u32> {
        std::env::var(var)
            .unwrap_or_else(|_| default.to_string())
            .split(',')
            .filter_map(|v| v.trim().parse().ok())
            .collect()
    };
    let (windows, textures, uniqs) = (
        list("BM_WINDOWS", "5,7,9,11,13,15"),
        list("BM_TEXTURES", "0,2,4,8"),
        list("BM_UNIQ", "0,5,10,15,25"),
    );
    for (name, cost) in costs() {
        for &window in &windows {
            for &texture in &textures {
                for &uniq in &uniqs {
                    let mut sums = [0f32; 4];
                    let mut per = String::new();
                    for (scene, bad) in &scenes {
                        let mut p = BlockParams::new(cost, scene.min_disp, scene.max_disp);
                        p.window = window;
                        p.texture_threshold = texture;
                        p.uniqueness_pct = uniq;
                        let s = run(&p, scene)?;
                        for (a, b) in sums.iter_mut().zip(s) {
                            *a += b;
                        }
                        per += &format!(
                            " {}{}={:.1}/{:.1}",
                            scene.name.chars().take(3).collect::<String>(),
                            if *bad { "*" } else { "" },
                            100.0 * s[1],
                            100.0 * s[3]
                        );
                    }
                    let k = scenes.len().max(1) as f32;
                    println!(
                        "SWEEP {name} w{window} t{texture} u{uniq} bad2 {:.2} dens {:.1} wrong {:.2} |{per}",
                        100.0 * sums[1] / k,
                        100.0 * sums[2] / k,
                        100.0 * sums[3] / k
                    );
                }
            }
        }
    }
    Ok(())
}
