//! Scoring on the Middlebury scenes of `../shared/datasets` (run on demand:
//! `cargo test --release -p hvs-stereo --lib block::tests::datasets -- --ignored --nocapture`).

use super::*;
use crate::synthetic::degrade;
use std::path::{Path, PathBuf};

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

fn grey(path: &Path) -> Option<(Vec<u8>, usize, usize)> {
    let img = image::open(path).ok()?.to_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let g = img
        .pixels()
        .map(|p| {
            let [r, g, b] = p.0;
            ((299 * r as u32 + 587 * g as u32 + 114 * b as u32 + 500) / 1000) as u8
        })
        .collect();
    Some((g, w, h))
}

fn load(dir: &Path) -> Option<Scene> {
    let meta: toml::Table = std::fs::read_to_string(dir.join("scene.toml"))
        .ok()?
        .parse()
        .ok()?;
    let int = |k: &str| meta.get(k).and_then(|v| v.as_integer());
    let text = |k: &str| {
        meta.get(k)
            .and_then(|v| v.as_str())
            .unwrap_or("")
            .to_string()
    };
    let (left, w, h) = grey(&dir.join("left.png"))?;
    let (right, _, _) = grey(&dir.join("right.png"))?;
    let gt_raw = image::open(dir.join("gt_disp.png"))
        .ok()?
        .into_luma16()
        .into_raw();
    let mask_name = match text("nonocc_mask") {
        m if m.is_empty() => text("all_mask"),
        m => m,
    };
    let mask = image::open(dir.join(mask_name))
        .ok()?
        .into_luma8()
        .into_raw();
    let gt = gt_raw
        .iter()
        .zip(&mask)
        .map(|(&g, &m)| {
            if g == 0 || m != 255 {
                f32::NAN
            } else {
                g as f32 / 256.0
            }
        })
        .collect();
    Some(Scene {
        name: text("name"),
        w,
        h,
        left,
        right,
        gt,
        min_disp: int("min_disp")? as u32,
        max_disp: int("max_disp")? as u32,
    })
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
        match crate::q8_to_px(e) {
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

fn scenes() -> Vec<(Scene, bool)> {
    let root = std::env::var("BM_DATASETS")
        .map(PathBuf::from)
        .unwrap_or_else(|_| PathBuf::from("/work/shared/datasets"));
    let mut out = Vec::new();
    for name in ["tsukuba", "venus", "motorcycle"] {
        let Some(scene) = load(&root.join(name)) else {
            eprintln!("skipping {name}: not found under {}", root.display());
            continue;
        };
        let mut bad = Scene {
            name: scene.name.clone(),
            right: scene.right.clone(),
            left: scene.left.clone(),
            gt: scene.gt.clone(),
            ..scene
        };
        // Webcam defects: gain 0.8, offset +10, noise sigma 4, 1 px vertical shift
        // (BM_SHIFT=0 leaves the shift out).
        let shift = std::env::var("BM_SHIFT")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(1);
        degrade(&mut bad.right, bad.w, 0.8, 10.0, 4.0, shift, 99);
        out.push((scene, false));
        out.push((bad, true));
    }
    out
}

fn run(p: &BlockParams, scene: &Scene) -> [f32; 4] {
    let mut m = BlockMatcher::new(p.clone()).expect("params");
    let mut out = vec![0u16; scene.w * scene.h];
    let l = ImageView::new(&scene.left, scene.w, scene.h).expect("left");
    let r = ImageView::new(&scene.right, scene.w, scene.h).expect("right");
    m.compute(l, r, &mut out).expect("compute");
    score(scene, &out)
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
fn table(tune: &dyn Fn(&str, &mut BlockParams)) {
    let scenes = scenes();
    for (name, cost) in costs() {
        let mut sums = [0f32; 4];
        for (scene, bad) in &scenes {
            let mut p = BlockParams::new(cost, scene.min_disp, scene.max_disp);
            tune(name, &mut p);
            let s = run(&p, scene);
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
}

#[test]
#[ignore]
fn dataset_table_defaults() {
    table(&|_, _| {});
}

/// The reference system's plain winner-take-all: window 9, no refinement but subpixel.
#[test]
#[ignore]
fn dataset_table_plain_wta() {
    table(&|_, p| {
        p.equalize = false;
        p.texture_threshold = 0;
        p.uniqueness_pct = 0;
        p.lr_check = false;
        p.speckle_window_px = 0;
    });
}

/// The recommended per-cost settings (see the module documentation).
#[test]
#[ignore]
fn dataset_table_recommended() {
    table(&|_, p| {
        let r = BlockParams::recommended(p.cost, p.min_disp, p.max_disp);
        p.window = r.window;
        p.uniqueness_pct = r.uniqueness_pct;
        p.texture_threshold = r.texture_threshold;
    });
}

#[test]
#[ignore]
fn dataset_sweep() {
    let scenes = scenes();
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
                        let s = run(&p, scene);
                        for (a, b) in sums.iter_mut().zip(s) {
                            *a += b;
                        }
                        per += &format!(
                            " {}{}={:.1}/{:.1}",
                            &scene.name[..3],
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
}
