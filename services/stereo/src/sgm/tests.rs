//! Tests of the sgm matcher (the tuning sweeps and the timing loop are the `sgm_sweeps`
//! example).

use super::*;
use crate::synthetic::{SyntheticPair, degrade, flatten_region, plane, score};

use hvs_runtime::config::SgmConfig;

fn config(min_disp: u32, max_disp: u32) -> StereoConfig {
    StereoConfig {
        algorithm: StereoAlgorithm::Sgm,
        min_disp,
        max_disp,
        ..StereoConfig::default()
    }
}

fn run(m: &mut SgmMatcher, pair: &SyntheticPair) -> Vec<u16> {
    let (w, h) = (pair.width, pair.height);
    let mut out = vec![0u16; w * h];
    let l = ImageView::new(&pair.left, w, h).expect("left");
    let r = ImageView::new(&pair.right, w, h).expect("right");
    m.compute(l, r, &mut out).expect("compute");
    out
}

#[test]
fn confidence_is_zero_exactly_where_there_is_no_disparity() {
    let (w, h) = (160, 120);
    let mut pair = webcam(plane(w, h, 0.0, 0.0, 20.0, 4), 4);
    // An untextured band: no disparity, no confidence.
    crate::synthetic::flatten_region(&mut pair, 90, 130, 128);
    let mut m = SgmMatcher::from_config(&config(4, 40)).expect("cfg");
    let out = run(&mut m, &pair);
    let conf = m.confidence().expect("sgm has a confidence").to_vec();
    assert_eq!(conf.len(), w * h);
    for (i, (&d, &c)) in out.iter().zip(&conf).enumerate() {
        assert_eq!(d == 0, c == 0, "pixel {i}: disparity {d} confidence {c}");
    }
    let valid: Vec<u64> = out
        .iter()
        .zip(&conf)
        .filter(|(d, _)| **d != 0)
        .map(|(_, &c)| c as u64)
        .collect();
    let mean_valid = valid.iter().sum::<u64>() as f64 / valid.len().max(1) as f64;
    assert!(valid.len() > 10_000 && mean_valid > 64.0, "{mean_valid:.1}");
}

/// On the real scenes beside the repository, matches within 1 px of the ground truth
/// carry a higher mean confidence than the ones off by more than 2 px.
#[test]
fn confidence_ranks_right_matches_above_wrong_ones_on_real_pairs() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/datasets");
    let Ok(dirs) = crate::eval::list_scenes(&root) else {
        eprintln!("SKIPPED: no datasets at {}", root.display());
        return;
    };
    for dir in dirs {
        let scene = crate::eval::load_scene(&dir).expect("scene");
        let mut m = SgmMatcher::from_config(&scene.config(&StereoConfig::default())).expect("cfg");
        let (w, h) = (scene.width, scene.height);
        let mut out = vec![0u16; w * h];
        let l = ImageView::new(&scene.left, w, h).expect("left");
        let r = ImageView::new(&scene.right, w, h).expect("right");
        m.compute(l, r, &mut out).expect("compute");
        let conf = m.confidence().expect("confidence");
        let (mut right, mut wrong) = ((0u64, 0u64), (0u64, 0u64));
        for i in 0..w * h {
            let (d, g) = (out[i], scene.gt_q8[i]);
            if d == 0 || g == 0 || !scene.scored[i] {
                continue;
            }
            let err = (d as f32 - g as f32).abs() / 256.0;
            let acc = if err <= 1.0 {
                &mut right
            } else if err > 2.0 {
                &mut wrong
            } else {
                continue;
            };
            acc.0 += conf[i] as u64;
            acc.1 += 1;
        }
        let mean = |(sum, n): (u64, u64)| sum as f64 / n.max(1) as f64;
        println!(
            "{}: right {} px mean confidence {:.1}; wrong {} px mean {:.1}",
            scene.name,
            right.1,
            mean(right),
            wrong.1,
            mean(wrong)
        );
        assert!(
            wrong.1 >= 100,
            "{}: too few wrong matches to compare",
            scene.name
        );
        assert!(
            mean(right) > mean(wrong) + 10.0,
            "{}: right {:.1} against wrong {:.1}",
            scene.name,
            mean(right),
            mean(wrong)
        );
    }
}

fn webcam(mut pair: SyntheticPair, seed: u64) -> SyntheticPair {
    degrade(&mut pair.right, pair.width, 0.8, 10.0, 4.0, 0, seed);
    pair
}

fn xorshift(state: &mut u64) -> u64 {
    *state ^= *state << 13;
    *state ^= *state >> 7;
    *state ^= *state << 17;
    *state
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

#[test]
fn block_average_stays_within_the_cost_range() {
    for block in BLOCK_SIZES {
        let n = block * block;
        if block == 1 {
            continue; // doubled, no division
        }
        let recip = (2 * 65536u32).div_ceil(n).min(u16::MAX as u32);
        let top = (CMAX * n * recip) >> 16;
        assert_eq!(top, COST_MAX, "block {block}");
        // The mean is kept to within half a Hamming bit.
        for sum in 0..=CMAX * n {
            let scaled = if block == 1 {
                2 * sum
            } else {
                (sum * recip) >> 16
            };
            let exact = 2.0 * sum as f64 / n as f64;
            assert!(
                (scaled as f64 - exact).abs() < 1.0,
                "block {block} sum {sum}"
            );
        }
    }
}

#[test]
fn simd_and_scalar_give_identical_maps() {
    if !simd_available() {
        eprintln!("no AVX2: only the scalar kernels exist here");
        return;
    }
    let mut seed = 0x5EED_1234_u64;
    let cases: &[(usize, usize, u32, u32)] = &[
        (64, 20, 0, 15),
        (90, 17, 3, 40),
        (120, 24, 9, 55),
        (160, 30, 0, 31),
        (161, 21, 5, 37),
        (200, 12, 18, 110),
        (300, 9, 1, 130),
        (100, 8, 20, 21),
        (24, 6, 0, 12),
        (40, 5, 3, 34),
    ];
    for &(w, h, dmin, dmax) in cases {
        // Random noise, a smooth slanted plane and a degraded copy.
        let noise: Vec<u8> = (0..2 * w * h)
            .map(|_| (xorshift(&mut seed) % 256) as u8)
            .collect();
        let mut pairs = vec![SyntheticPair {
            width: w,
            height: h,
            left: noise[..w * h].to_vec(),
            right: noise[w * h..].to_vec(),
            disparity_px: vec![f32::NAN; w * h],
        }];
        let mid = (dmin + dmax) as f32 / 2.0;
        pairs.push(plane(w, h, -0.05, 0.1, mid, seed));
        pairs.push(webcam(plane(w, h, 0.0, 0.0, mid, seed), seed));
        for pair in &pairs {
            for (combo, (paths, uniq)) in [4, 5, 8]
                .into_iter()
                .flat_map(|p| [(p, 0), (p, 15)])
                .enumerate()
            {
                {
                    let mut cfg = config(dmin, dmax);
                    cfg.sgm.paths = paths;
                    cfg.sgm.block = BLOCK_SIZES[(combo + w) % BLOCK_SIZES.len()];
                    cfg.uniqueness_pct = uniq;
                    cfg.sgm.p1 = 3 + paths;
                    cfg.sgm.p2 = 20 + 3 * uniq;
                    let mut fast = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(true);
                    let mut slow = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(false);
                    assert!(fast.uses_simd() && !slow.uses_simd());
                    let a = run(&mut fast, pair);
                    let b = run(&mut slow, pair);
                    let diff = a.iter().zip(&b).filter(|(x, y)| x != y).count();
                    assert_eq!(
                        diff, 0,
                        "{w}x{h} d {dmin}..={dmax} paths {paths} uniq {uniq} block {}",
                        cfg.sgm.block
                    );
                    // The confidence planes are the same bytes too.
                    assert_eq!(
                        fast.confidence(),
                        slow.confidence(),
                        "confidence {w}x{h} d {dmin}..={dmax} paths {paths}"
                    );
                    // Buffers are reused: a second call gives the same map.
                    assert_eq!(run(&mut fast, pair), a);
                }
            }
        }
    }
}

/// Plain winner-take-all on the census cost, searching the disparities that fit.
fn census_wta(pair: &SyntheticPair, dmin: usize, dmax: usize) -> Vec<u16> {
    let (w, h) = (pair.width, pair.height);
    let (mut cl, mut cr) = (vec![0; w * h], vec![0; w * h]);
    census(&pair.left, w, h, 5, 5, &mut cl);
    census(&pair.right, w, h, 5, 5, &mut cr);
    let mut out = vec![0u16; w * h];
    for y in 0..h {
        for x in dmin..w {
            let i = y * w + x;
            let mut best = (u32::MAX, 0);
            for d in dmin..=dmax.min(x) {
                let c = crate::census::hamming(cl[i], cr[i - d]);
                if c < best.0 {
                    best = (c, d);
                }
            }
            out[i] = crate::post::to_q8(best.1 as f32);
        }
    }
    out
}

#[test]
fn zero_penalties_give_plain_census_wta() {
    for (w, h, dmin, dmax, seed) in [
        (80, 20, 4, 30, 1u64),
        (128, 16, 0, 40, 2),
        (70, 11, 9, 55, 3),
    ] {
        let pair = webcam(
            plane(w, h, -0.1, 0.05, (dmin + dmax) as f32 / 2.0, seed),
            seed,
        );
        let expected = census_wta(&pair, dmin as usize, dmax as usize);
        for paths in [4, 5, 8] {
            for simd in [false, true] {
                let mut cfg = config(dmin, dmax);
                cfg.sgm = hvs_runtime::config::SgmConfig {
                    p1: 0,
                    p2: 0,
                    paths,
                    block: 1,
                    ..Default::default()
                };
                cfg.uniqueness_pct = 0;
                cfg.lr_check = false;
                cfg.subpixel = false;
                cfg.speckle_window_px = 0;
                let params = SgmParams {
                    prefilter: false,
                    texture_threshold: 0.0,
                    ..SgmParams::from_config(&cfg)
                };
                let mut m = SgmMatcher::new(params).expect("params").with_simd(simd);
                let out = run(&mut m, &pair);
                let diff = out.iter().zip(&expected).filter(|(a, b)| a != b).count();
                assert_eq!(diff, 0, "paths {paths} simd {simd}");
            }
        }
    }
}

/// Shares (within 1 px, given a disparity) of the pixels of a synthetic pair that are
/// visible in the right image with a disparity inside the searched range 9..=55.
fn accuracy(pair: &SyntheticPair, paths: u32, penalties: (u32, u32)) -> (f32, f32) {
    let mut cfg = config(9, 55);
    cfg.sgm = hvs_runtime::config::SgmConfig {
        p1: penalties.0,
        p2: penalties.1,
        paths,
        ..Default::default()
    };
    let mut m = SgmMatcher::from_config(&cfg).expect("cfg");
    let out = run(&mut m, pair);
    let mut in_range = pair.clone();
    for d in in_range.disparity_px.iter_mut() {
        if !(9.0..=55.0).contains(d) {
            *d = f32::NAN;
        }
    }
    score(&in_range, &out, 1.0, 0)
}

#[test]
fn planes_are_recovered_with_and_without_webcam_defects() {
    let (w, h) = (320, 240);
    let scenes = [
        ("fronto-parallel", plane(w, h, 0.0, 0.0, 30.0, 11)),
        ("hallway wall a=-0.2", plane(w, h, -0.2, 0.0, 54.0, 12)),
        ("floor tilt b=0.12", plane(w, h, 0.0, 0.12, 12.0, 13)),
    ];
    for (name, pair) in scenes {
        for (label, p) in [
            ("clean", pair.clone()),
            ("webcam", webcam(pair.clone(), 99)),
        ] {
            // The config default penalties and the recommended ones.
            for (paths, pen) in [(5, (4, 32)), (4, (4, 32)), (8, (4, 32)), (5, (16, 48))] {
                let (good, dense) = accuracy(&p, paths, pen);
                eprintln!("{name} {label} paths {paths} {pen:?}: good {good:.3} dense {dense:.3}");
                assert!(
                    good >= 0.95,
                    "{name} {label} paths {paths} {pen:?}: good {good}"
                );
                assert!(
                    dense >= 0.95,
                    "{name} {label} paths {paths} {pen:?}: dense {dense}"
                );
            }
        }
    }
}

#[test]
fn flat_block_between_two_planes_is_invalid() {
    let (w, h) = (240, 80);
    let split = 120;
    let (x0, x1) = (96, 150);
    // (webcam defects on the right, noise sigma on the left, texture threshold): a clean
    // flat block and a nearly flat one with the default threshold, and a noisy one with
    // the threshold docs/stereo.md gives for noisy cameras.
    let default_threshold = SgmConfig::default().texture_threshold;
    for (degraded, left_sigma, threshold) in [
        (false, 0.0, default_threshold),
        (true, 0.5, default_threshold),
        (true, 2.0, 1.0),
    ] {
        let mut pair = two_planes(w, h, split, 20.0, 34.0, 21);
        flatten_region(&mut pair, x0, x1, 128);
        if degraded {
            pair = webcam(pair, 5);
            degrade(&mut pair.left, w, 1.0, 0.0, left_sigma, 0, 6);
        }
        // The config default penalties and others.
        for (paths, p1, p2) in [
            (5, 16, 64),
            (4, 16, 64),
            (8, 16, 64),
            (5, 4, 32),
            (5, 8, 79),
        ] {
            let mut cfg = config(9, 55);
            cfg.sgm = SgmConfig {
                p1,
                p2,
                paths,
                texture_threshold: threshold,
                ..Default::default()
            };
            let mut m = SgmMatcher::from_config(&cfg).expect("cfg");
            let out = run(&mut m, &pair);
            // Margin: census radius + prefilter radius + texture radius + 1.
            let margin = 2 + 1 + cfg.sgm.texture_radius as usize + 1;
            let inside = (0..h)
                .flat_map(|y| (x0 + margin..x1 - margin).map(move |x| y * w + x))
                .collect::<Vec<_>>();
            let valid = inside.iter().filter(|&&i| out[i] != 0).count();
            eprintln!(
                "degraded {degraded} sigma {left_sigma} paths {paths} P {p1}/{p2}: {valid} of {} valid in the flat block",
                inside.len()
            );
            assert!(
                valid * 100 <= inside.len(),
                "{valid} of {} valid",
                inside.len()
            );
            // The textured parts around it are still matched.
            let outside: Vec<usize> = (0..h)
                .flat_map(|y| {
                    (60..x0 - margin)
                        .chain(x1 + margin..w)
                        .map(move |x| y * w + x)
                })
                .filter(|&i| pair.disparity_px[i].is_finite())
                .collect();
            let good = outside
                .iter()
                .filter(|&&i| {
                    out[i] != 0 && (out[i] as f32 / 256.0 - pair.disparity_px[i]).abs() <= 1.0
                })
                .count();
            assert!(
                good * 100 >= outside.len() * 85,
                "{good} of {} good outside",
                outside.len()
            );
        }
    }
}

/// Addresses of the main scratch buffers (to see that they are not reallocated).
fn buffer_addresses(m: &SgmMatcher) -> Vec<usize> {
    let s = &m.scratch;
    vec![
        s.census_l.as_ptr() as usize,
        s.census_r.as_ptr() as usize,
        s.left_f.as_ptr() as usize,
        s.mirrored.as_ptr() as usize,
        s.texture_ok.as_ptr() as usize,
        s.planes.buf.as_ptr() as usize,
        s.cost.buf.as_ptr() as usize,
        s.lbuf.buf.as_ptr() as usize,
        s.srow.buf.as_ptr() as usize,
        s.vbuf[1].buf.as_ptr() as usize,
        s.winners.best.as_ptr() as usize,
        s.volume.as_ptr() as usize,
        s.uniq_t.as_ptr() as usize,
    ]
}

#[test]
fn buffers_are_reused_and_sizes_may_change() {
    let big = webcam(plane(160, 60, -0.05, 0.05, 30.0, 61), 62);
    let small = webcam(plane(100, 30, 0.0, 0.0, 20.0, 63), 64);
    for paths in [5, 8] {
        for simd in [true, false] {
            let mut cfg = config(9, 55);
            cfg.sgm.paths = paths;
            let mut m = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(simd);
            let first = run(&mut m, &big);
            let addresses = buffer_addresses(&m);
            assert_eq!(run(&mut m, &big), first);
            assert_eq!(buffer_addresses(&m), addresses, "paths {paths} simd {simd}");
            // Another size, then back: same results as a fresh matcher.
            let mut fresh = SgmMatcher::from_config(&cfg).expect("cfg").with_simd(simd);
            assert_eq!(run(&mut m, &small), run(&mut fresh, &small));
            assert_eq!(run(&mut m, &big), first);
        }
    }
}

#[test]
fn fast_encodings_match_post_to_q8() {
    for d in 0..=255u16 {
        assert_eq!(q8_int(d), crate::post::to_q8(d as f32), "{d}");
    }
    for i in 0..=255 * 64 {
        let v = i as f32 / 64.0 + 0.003;
        assert_eq!(q8_fast(v), crate::post::to_q8(v), "{v}");
    }
    assert_eq!(equiangular_offset(4.0, 2.0, 4.0), 0.0);
    assert_eq!(equiangular_offset(6.0, 2.0, 4.0), 0.25);
    assert_eq!(equiangular_offset(4.0, 2.0, 6.0), -0.25);
    assert_eq!(equiangular_offset(2.0, 2.0, 2.0), 0.0);
}

#[test]
fn bad_inputs_give_the_right_errors() {
    let cfg = config(9, 55);
    let mut m = SgmMatcher::from_config(&cfg).expect("cfg");
    let img = vec![0u8; 100 * 10];
    let small = vec![0u8; 60 * 10];
    let mut out = vec![0u16; 100 * 10];
    let l = ImageView::new(&img, 100, 10).expect("view");
    let r_small = ImageView::new(&small, 60, 10).expect("view");
    assert!(matches!(
        m.compute(l, r_small, &mut out),
        Err(StereoError::SizeMismatch { .. })
    ));
    assert!(matches!(
        m.compute(l, l, &mut out[..10]),
        Err(StereoError::BufferSize { .. })
    ));
    // Not wider than max_disp + census window.
    let narrow = vec![0u8; 60 * 10];
    let n = ImageView::new(&narrow, 60, 10).expect("view");
    let mut out_n = vec![0u16; 60 * 10];
    assert_eq!(
        m.compute(n, n, &mut out_n),
        Err(StereoError::ImageTooSmall {
            width: 60,
            height: 10,
            max_disp: 55,
            window: 5
        })
    );
    let flat = vec![0u8; 100 * 3];
    let f = ImageView::new(&flat, 100, 3).expect("view");
    let mut out_f = vec![0u16; 300];
    assert!(matches!(
        m.compute(f, f, &mut out_f),
        Err(StereoError::ImageTooSmall { .. })
    ));
    // Ranges and parameters.
    assert_eq!(
        SgmMatcher::from_config(&config(20, 20)).err(),
        Some(StereoError::BadRange { min: 20, max: 20 })
    );
    assert!(matches!(
        SgmMatcher::from_config(&config(30, 10)),
        Err(StereoError::BadRange { .. })
    ));
    assert!(matches!(
        SgmMatcher::from_config(&config(0, 300)),
        Err(StereoError::BadParameter { .. })
    ));
    for (p1, p2, paths) in [(4, 32, 6), (4, 80, 5), (40, 32, 5)] {
        let mut c = config(0, 16);
        c.sgm = hvs_runtime::config::SgmConfig {
            p1,
            p2,
            paths,
            ..Default::default()
        };
        assert!(
            matches!(
                SgmMatcher::from_config(&c),
                Err(StereoError::BadParameter { .. })
            ),
            "{p1} {p2} {paths}"
        );
    }
    let mut c = config(0, 16);
    c.uniqueness_pct = 100;
    assert!(matches!(
        SgmMatcher::from_config(&c),
        Err(StereoError::BadParameter { .. })
    ));
    assert!(
        SgmMatcher::from_config(&config(0, 16))
            .expect("cfg")
            .with_texture(3.0, 40)
            .is_err()
    );
    // The smallest accepted width works.
    let ok = vec![7u8; 61 * 6];
    let o = ImageView::new(&ok, 61, 6).expect("view");
    let mut out_o = vec![0u16; 61 * 6];
    assert!(m.compute(o, o, &mut out_o).is_ok());
    assert_eq!(m.algorithm(), StereoAlgorithm::Sgm);
}

#[test]
fn left_edge_columns_search_the_disparities_that_fit() {
    let pair = plane(200, 40, 0.0, 0.0, 20.0, 31);
    let mut m = SgmMatcher::from_config(&config(4, 60)).expect("cfg");
    let out = run(&mut m, &pair);
    // Columns 20..60 cannot see d = 60 on the right image but still get d = 20.
    let (mut good, mut total) = (0, 0);
    for y in 3..37 {
        for x in 22..60 {
            total += 1;
            let d = out[y * 200 + x];
            if d != 0 && (d as f32 / 256.0 - 20.0).abs() <= 1.0 {
                good += 1;
            }
        }
    }
    assert!(good * 100 >= total * 90, "{good} of {total}");
    // Columns left of min_disp are invalid.
    assert!((0..40).all(|y| out[y * 200..y * 200 + 4].iter().all(|&d| d == 0)));
}

/// A Middlebury scene: grey pair, ground truth (px, 0 = unknown) and the scoring mask.
struct Scene {
    name: String,
    width: usize,
    height: usize,
    left: Vec<u8>,
    right: Vec<u8>,
    gt: Vec<f32>,
    mask: Vec<bool>,
    min_disp: u32,
    max_disp: u32,
}

fn grey(path: &std::path::Path) -> Option<(Vec<u8>, usize, usize)> {
    let img = image::open(path).ok()?.into_rgb8();
    let (w, h) = (img.width() as usize, img.height() as usize);
    let data = img
        .pixels()
        .map(|p| (0.299 * p[0] as f32 + 0.587 * p[1] as f32 + 0.114 * p[2] as f32).round() as u8)
        .collect();
    Some((data, w, h))
}

fn load_scene(name: &str) -> Option<Scene> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/datasets")
        .join(name);
    let dir = if dir.exists() {
        dir
    } else {
        std::path::Path::new("/work/shared/datasets").join(name)
    };
    let toml_text = std::fs::read_to_string(dir.join("scene.toml")).ok()?;
    let t: toml::Table = toml_text.parse().ok()?;
    let min_disp = t.get("min_disp")?.as_integer()? as u32;
    let max_disp = t.get("max_disp")?.as_integer()? as u32;
    let mask_name = t
        .get("nonocc_mask")
        .and_then(|v| v.as_str())
        .filter(|s| !s.is_empty())
        .unwrap_or("all.png");
    let (left, width, height) = grey(&dir.join("left.png"))?;
    let (right, _, _) = grey(&dir.join("right.png"))?;
    let gt: Vec<f32> = image::open(dir.join("gt_disp.png"))
        .ok()?
        .into_luma16()
        .pixels()
        .map(|p| p[0] as f32 / 256.0)
        .collect();
    let mask: Vec<bool> = image::open(dir.join(mask_name))
        .ok()?
        .into_luma8()
        .pixels()
        .map(|p| p[0] == 255)
        .collect();
    (gt.len() == width * height && mask.len() == width * height).then(|| Scene {
        name: name.to_string(),
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

/// bad-2 (invalid or off by more than 2 px, over the scored pixels), the density, and the
/// error among the valid pixels.
fn bad2(scene: &Scene, est: &[u16]) -> (f32, f32, f32) {
    let (mut n, mut bad, mut valid, mut valid_bad) = (0usize, 0usize, 0usize, 0usize);
    for ((&gt, &scored), &q) in scene.gt.iter().zip(&scene.mask).zip(est) {
        if !scored || gt == 0.0 {
            continue;
        }
        n += 1;
        match crate::q8_to_px(q) {
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

fn run_scene(scene: &Scene, right: &[u8], cfg: &StereoConfig) -> Vec<u16> {
    let params = SgmParams {
        prefilter: std::env::var("SGM_PRE").map_or(true, |v| v != "0"),
        ..SgmParams::from_config(cfg)
    };
    let mut m = SgmMatcher::new(params)
        .expect("cfg")
        .with_simd(std::env::var("SGM_SIMD").is_err());
    let mut out = vec![0u16; scene.width * scene.height];
    let l = ImageView::new(&scene.left, scene.width, scene.height).expect("left");
    let r = ImageView::new(right, scene.width, scene.height).expect("right");
    m.compute(l, r, &mut out).expect("compute");
    out
}

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

#[test]
fn middlebury_sanity() {
    let scenes: Vec<Scene> = ["tsukuba", "venus", "motorcycle"]
        .iter()
        .filter_map(|n| load_scene(n))
        .collect();
    if scenes.is_empty() {
        eprintln!("no Middlebury scenes found: skipped");
        return;
    }
    for scene in &scenes {
        let mut cfg = config(scene.min_disp, scene.max_disp);
        // The penalties recommended for the config default (see the module notes).
        cfg.sgm.p1 = 16;
        cfg.sgm.p2 = 48;
        // The matches themselves: filled pixels (confidence 1) would count as claims.
        cfg.fill_invalid_px = 0;
        for (label, right) in [
            ("clean", scene.right.clone()),
            ("degraded", degraded_right(scene)),
        ] {
            let out = run_scene(scene, &right, &cfg);
            let (b, dense, err) = bad2(scene, &out);
            eprintln!(
                "{} {label}: bad-2 {:.1} % (density {:.1} %, error among valid {:.1} %)",
                scene.name,
                100.0 * b,
                100.0 * dense,
                100.0 * err
            );
            // Loose bounds: a regression guard, not a benchmark.
            assert!(err < 0.15, "{} {label}: {err}", scene.name);
            assert!(b < 0.40, "{} {label}: {b}", scene.name);
        }
    }
}
