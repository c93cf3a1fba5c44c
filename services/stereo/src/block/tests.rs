//! Tests of the block matcher on synthetic pairs: every cost, the refinements, SIMD and
//! threads, config handling and errors (the Middlebury tables and sweeps are the
//! `block_tables` example).

use super::*;
use crate::synthetic::{SyntheticPair, degrade, flatten_region, plane};

const COSTS: [BlockCost; 4] = [
    BlockCost::Sad,
    BlockCost::Ssd,
    BlockCost::Ncc,
    BlockCost::Census {
        width: 5,
        height: 5,
    },
];

fn run_pair(params: &BlockParams, pair: &SyntheticPair) -> Vec<u16> {
    let mut m = BlockMatcher::new(params.clone()).expect("valid params");
    let (w, h) = (pair.width, pair.height);
    let mut out = vec![0u16; w * h];
    let stats = m
        .compute(
            ImageView::new(&pair.left, w, h).expect("left"),
            ImageView::new(&pair.right, w, h).expect("right"),
            &mut out,
        )
        .expect("compute");
    assert_eq!(
        stats.valid_px as usize,
        out.iter().filter(|&&d| d != 0).count()
    );
    out
}

/// Share of the scorable pixels (true match visible, full window in both images) within
/// `tol` px, and the share given any disparity.
fn accuracy(pair: &SyntheticPair, est: &[u16], window: u32, tol: f32) -> (f32, f32) {
    let r = (window / 2) as usize;
    let (w, h) = (pair.width, pair.height);
    let (mut known, mut good, mut dense) = (0usize, 0usize, 0usize);
    for y in r..h - r {
        for x in r..w - r {
            let t = pair.disparity_px[y * w + x];
            if !t.is_finite() || (x as f32) - t - (r as f32) < 0.0 {
                continue;
            }
            known += 1;
            if let Some(d) = crate::q8_to_px(est[y * w + x]) {
                dense += 1;
                if (d - t).abs() <= tol {
                    good += 1;
                }
            }
        }
    }
    let k = known.max(1) as f32;
    (good as f32 / k, dense as f32 / k)
}

#[test]
fn fronto_parallel_plane_is_recovered_by_every_cost() {
    let pair = plane(200, 100, 0.0, 0.0, 20.0, 7);
    for cost in COSTS {
        let params = BlockParams::new(cost, 9, 55);
        let out = run_pair(&params, &pair);
        let (acc, dens) = accuracy(&pair, &out, params.window, 1.0);
        assert!(acc >= 0.95, "{cost:?}: {acc} within 1 px (density {dens})");
        // Whole-pixel estimates on a whole-pixel plane: subpixel must not drift.
        let (acc_half, _) = accuracy(&pair, &out, params.window, 0.25);
        assert!(acc_half >= 0.9, "{cost:?}: {acc_half} within 0.25 px");
    }
}

#[test]
fn left_border_pixels_search_the_disparities_that_fit() {
    // d = 20 with a search up to 55: OpenCV would drop x < 55 + 4; here x >= 24 has a
    // full right window and must be matched.
    let pair = plane(200, 60, 0.0, 0.0, 20.0, 11);
    for cost in COSTS {
        let params = BlockParams::new(cost, 9, 55);
        let out = run_pair(&params, &pair);
        let (w, h) = (pair.width, pair.height);
        let mut good = 0;
        let mut total = 0;
        for y in 4..h - 4 {
            for x in 26..59 {
                total += 1;
                if crate::q8_to_px(out[y * w + x]).is_some_and(|d| (d - 20.0).abs() <= 1.0) {
                    good += 1;
                }
            }
            // No disparity fits left of min_disp + r.
            for x in 0..13 {
                assert_eq!(out[y * w + x], 0, "{cost:?}: ({x},{y})");
            }
        }
        assert!(good * 100 >= total * 90, "{cost:?}: {good} of {total}");
    }
}

#[test]
fn sideways_slanted_plane_is_recovered_by_every_cost() {
    // d = 48 - 0.15 x: from 48 px at the left edge to 18 px at the right.
    let pair = plane(200, 100, -0.15, 0.0, 48.0, 3);
    for cost in COSTS {
        let params = BlockParams::new(cost, 9, 55);
        let out = run_pair(&params, &pair);
        let (acc, dens) = accuracy(&pair, &out, params.window, 1.0);
        assert!(acc >= 0.95, "{cost:?}: {acc} within 1 px (density {dens})");
    }
}

#[test]
fn subpixel_fit_beats_whole_pixels_on_a_slant() {
    let pair = plane(200, 80, -0.15, 0.0, 48.0, 5);
    for cost in COSTS {
        let mut params = BlockParams::new(cost, 9, 55);
        let fitted = run_pair(&params, &pair);
        params.subpixel = SubpixelFit::Off;
        let whole = run_pair(&params, &pair);
        let (a_fit, _) = accuracy(&pair, &fitted, params.window, 0.25);
        let (a_whole, _) = accuracy(&pair, &whole, params.window, 0.25);
        assert!(
            a_fit > a_whole,
            "{cost:?}: {a_fit} vs {a_whole} within 0.25 px"
        );
    }
}

#[test]
fn fits_find_the_vertex() {
    // A V with slopes +-1 and its minimum at +0.25.
    let v = |x: f32| (x - 0.25).abs();
    let off = SubpixelFit::Equiangular.offset(v(-1.0), v(0.0), v(1.0));
    assert!((off - 0.25).abs() < 1e-6, "{off}");
    let p = |x: f32| (x + 0.3) * (x + 0.3);
    let off = SubpixelFit::Parabola.offset(p(-1.0), p(0.0), p(1.0));
    assert!((off + 0.3).abs() < 1e-6, "{off}");
    assert_eq!(SubpixelFit::Equiangular.offset(2.0, 2.0, 2.0), 0.0);
    assert_eq!(SubpixelFit::Off.offset(3.0, 0.0, 1.0), 0.0);
}

/// Pixels of the flat block `x0..x1` whose whole window is flat: (invalid, total); panics
/// on a wrong disparity.
fn flat_block_invalid(
    pair: &SyntheticPair,
    out: &[u16],
    r: usize,
    x0: usize,
    x1: usize,
    what: &str,
) -> (usize, usize) {
    let w = pair.width;
    let (mut invalid, mut total) = (0, 0);
    for y in r..pair.height - r {
        for x in x0 + r..x1 - r {
            total += 1;
            match crate::q8_to_px(out[y * w + x]) {
                None => invalid += 1,
                Some(d) => assert!(
                    (d - pair.disparity_px[y * w + x]).abs() <= 1.0,
                    "{what}: flat pixel ({x},{y}) got {d}"
                ),
            }
        }
    }
    (invalid, total)
}

#[test]
fn textureless_block_comes_out_invalid_not_wrong() {
    let mut pair = plane(200, 80, 0.0, 0.0, 20.0, 9);
    flatten_region(&mut pair, 90, 160, 128);
    for cost in COSTS {
        for params in [
            BlockParams::new(cost, 9, 55),
            BlockParams::recommended(cost, 9, 55),
        ] {
            let out = run_pair(&params, &pair);
            // Census strings see 2 px further than the block window.
            let reach = match cost {
                BlockCost::Census { width, .. } => (width / 2) as usize,
                _ => 0,
            };
            let r = (params.window / 2) as usize + reach;
            let what = format!("{cost:?} window {}", params.window);
            let (invalid, total) = flat_block_invalid(&pair, &out, r, 90, 160, &what);
            assert!(invalid * 100 >= total * 99, "{what}: {invalid} of {total}");
            // The textured rest is still matched.
            let (acc, _) = accuracy(&pair, &out, params.window, 1.0);
            assert!(acc >= 0.55, "{what}: {acc}");
        }
    }
}

#[test]
fn noisy_flat_wall_gets_no_wrong_matches_with_the_recommended_settings() {
    // Both cameras add noise, so the "flat" wall has a mean |gradient| of about 1.13 sigma
    // and only uniqueness and the left-right check can reject it.
    for sigma in [2.0, 4.0] {
        let mut pair = plane(240, 100, 0.0, 0.0, 20.0, 9);
        flatten_region(&mut pair, 80, 180, 128);
        degrade(&mut pair.left, pair.width, 1.0, 0.0, sigma, 0, 3);
        degrade(&mut pair.right, pair.width, 1.0, 0.0, sigma, 0, 4);
        for cost in COSTS {
            let params = BlockParams::recommended(cost, 9, 55);
            let out = run_pair(&params, &pair);
            let what = format!("{cost:?} sigma {sigma}");
            let r = (params.window / 2) as usize;
            flat_block_invalid(&pair, &out, r, 80, 180, &what);
            let (acc, _) = accuracy(&pair, &out, params.window, 1.0);
            assert!(acc >= 0.4, "{what}: {acc}");
        }
    }
}

/// A fronto-parallel plane (d = 20) with its texture's contrast scaled by `contrast` about
/// grey 128 (indoor walls are far less textured than the synthetic noise), and the right
/// image then given `gain` and `offset`.
fn low_contrast_pair(contrast: f32, gain: f32, offset: f32) -> SyntheticPair {
    let mut pair = plane(200, 80, 0.0, 0.0, 20.0, 13);
    for v in pair.left.iter_mut().chain(pair.right.iter_mut()) {
        *v = (128.0 + contrast * (*v as f32 - 128.0)).round() as u8;
    }
    degrade(&mut pair.right, pair.width, gain, offset, 0.0, 0, 1);
    pair
}

/// Share within 1 px of `cost` on [`low_contrast_pair`].
fn under_gain(cost: BlockCost, contrast: f32, gain: f32, offset: f32, equalize: bool) -> f32 {
    let pair = low_contrast_pair(contrast, gain, offset);
    let mut params = BlockParams::new(cost, 9, 55);
    params.equalize = equalize;
    let out = run_pair(&params, &pair);
    accuracy(&pair, &out, params.window, 1.0).0
}

#[test]
fn gain_and_offset_break_sad_and_ssd_but_not_ncc_or_census() {
    // At 0.3 contrast, gain 0.8 + offset 10 (a mean shift of about 16 grey levels against
    // a texture of about +-25) without equalisation.
    for cost in COSTS {
        let acc = under_gain(cost, 0.3, 0.8, 10.0, false);
        match cost {
            BlockCost::Sad | BlockCost::Ssd => assert!(acc < 0.2, "{cost:?}: {acc}"),
            _ => assert!(acc >= 0.99, "{cost:?}: {acc}"),
        }
    }
    // With full-contrast texture the same shift is small against the texture and SAD
    // survives it: how badly a radiometric difference hurts depends on the texture.
    assert!(under_gain(BlockCost::Sad, 1.0, 0.8, 10.0, false) >= 0.95);
}

#[test]
fn equalisation_fixes_a_gain_for_sad_and_ssd() {
    for cost in [BlockCost::Sad, BlockCost::Ssd] {
        assert!(under_gain(cost, 0.3, 0.8, 0.0, false) < 0.2, "{cost:?} raw");
        let acc = under_gain(cost, 0.3, 0.8, 0.0, true);
        assert!(acc >= 0.99, "{cost:?} equalised gain: {acc}");
        // An offset is not a gain: the mean ratio maps 0.8 p + 10 to about 0.91 p + 11.4 (grey 128),
        // right at the mean grey and off by 9 % of the distance from it. On low-contrast
        // texture that residue is small and the match survives.
        let acc = under_gain(cost, 0.3, 0.8, 10.0, true);
        assert!(acc >= 0.95, "{cost:?} equalised gain + offset: {acc}");
    }
}

/// Brute-force reference: direct window sums for every pixel and searched disparity,
/// first-minimum WTA and the exact uniqueness test; integer disparities (q8).
fn brute_force(
    cost: BlockCost,
    l: &[u8],
    rt: &[u8],
    w: usize,
    h: usize,
    p: &BlockParams,
) -> Vec<u16> {
    let r = (p.window / 2) as usize;
    let (dmin, dmax) = (p.min_disp as usize, p.max_disp as usize);
    let (mut lc, mut rc) = (vec![0u32; w * h], vec![0u32; w * h]);
    if let BlockCost::Census { width, height } = cost {
        census(l, w, h, width as usize, height as usize, &mut lc);
        census(rt, w, h, width as usize, height as usize, &mut rc);
    }
    let area = (p.window * p.window) as f64;
    let window_cost = |x: usize, y: usize, d: usize| -> u32 {
        let mut acc = 0i64;
        let (mut sl, mut sr, mut sll, mut srr) = (0i64, 0i64, 0i64, 0i64);
        for yy in y - r..=y + r {
            for xx in x - r..=x + r {
                let (a, b) = (l[yy * w + xx] as i64, rt[yy * w + xx - d] as i64);
                match cost {
                    BlockCost::Sad => acc += (a - b).abs(),
                    BlockCost::Ssd => acc += (a - b) * (a - b),
                    BlockCost::Ncc => {
                        let (a, b) = (a - 128, b - 128);
                        acc += a * b;
                        sl += a;
                        sr += b;
                        sll += a * a;
                        srr += b * b;
                    }
                    BlockCost::Census { .. } => {
                        acc += (lc[yy * w + xx] ^ rc[yy * w + xx - d]).count_ones() as i64
                    }
                }
            }
        }
        if cost == BlockCost::Ncc {
            let n = area;
            let vl = n * sll as f64 - (sl * sl) as f64;
            let vr = n * srr as f64 - (sr * sr) as f64;
            let il = if vl > n * n / 4.0 {
                1.0 / vl.sqrt()
            } else {
                0.0
            };
            let ir = if vr > n * n / 4.0 {
                1.0 / vr.sqrt()
            } else {
                0.0
            };
            let z = (n * acc as f64 - (sl * sr) as f64) * il * ir;
            ((1.0 - z) * 32768.0 + 0.5).clamp(0.0, 65536.0) as u32
        } else {
            acc as u32
        }
    };
    let mut out = vec![0u16; w * h];
    for y in r..h - r {
        for x in r + dmin..w - r {
            let top = dmax.min(x - r);
            let costs: Vec<u32> = (dmin..=top).map(|d| window_cost(x, y, d)).collect();
            let best = *costs.iter().min().expect("one disparity");
            let kb = costs.iter().position(|&c| c == best).expect("present");
            let second = costs
                .iter()
                .enumerate()
                .filter(|(k, _)| k.abs_diff(kb) > 1)
                .map(|(_, &c)| c)
                .min();
            let pct = p.uniqueness_pct as u64;
            if let Some(s) = second
                && pct > 0
                && best as u64 * 100 >= s as u64 * (100 - pct)
            {
                continue;
            }
            out[y * w + x] = (((dmin + kb) * 256) as u16).max(1);
        }
    }
    out
}

#[test]
fn uniqueness_is_exact_against_brute_force() {
    // Noisy right image, so that many pixels sit near the uniqueness limit.
    let mut pair = plane(72, 20, -0.1, 0.0, 14.0, 21);
    degrade(&mut pair.right, pair.width, 1.0, 0.0, 12.0, 0, 5);
    let (w, h) = (pair.width, pair.height);
    for cost in COSTS {
        let mut unfiltered = 0;
        for pct in [0, 5, 15, 40] {
            let mut p = BlockParams::new(cost, 0, 20);
            p.window = 5;
            p.uniqueness_pct = pct;
            p.equalize = false;
            p.texture_threshold = 0;
            p.lr_check = false;
            p.subpixel = SubpixelFit::Off;
            p.speckle_window_px = 0;
            let got = run_pair(&p, &pair);
            let want = brute_force(cost, &pair.left, &pair.right, w, h, &p);
            let differ = got.iter().zip(&want).filter(|(a, b)| a != b).count();
            let valid = want.iter().filter(|&&d| d != 0).count();
            assert!(valid > 0, "{cost:?} {pct}: nothing valid");
            if pct == 0 {
                unfiltered = valid;
            } else if pct == 40 {
                assert!(
                    valid < unfiltered,
                    "{cost:?}: a strict ratio must reject some"
                );
            }
            // NCC costs are f32 in the matcher and f64 here: allow a rare near-tie flip.
            let allowed = if cost == BlockCost::Ncc {
                w * h / 200
            } else {
                0
            };
            assert!(
                differ <= allowed,
                "{cost:?} uniqueness {pct}: {differ} pixels differ"
            );
        }
    }
}

/// Two fronto-parallel planes: background at `db`, a foreground slab at `df` over left
/// columns `x0..x1`. Returns the pair and the occluded left columns.
fn depth_step(w: usize, h: usize, db: f32, df: f32, x0: usize, x1: usize) -> SyntheticPair {
    let far = plane(w, h, 0.0, 0.0, db, 31);
    let near = plane(w, h, 0.0, 0.0, df, 32);
    let mut pair = far.clone();
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if (x0..x1).contains(&x) {
                pair.left[i] = near.left[i];
                pair.disparity_px[i] = df;
            }
            // Right pixel x shows the slab where x + df falls on it.
            if (x0..x1).contains(&(x + df as usize)) {
                pair.right[i] = near.right[i];
            } else {
                pair.right[i] = far.right[i];
            }
            // Background points hidden behind the slab in the right image.
            if !(x0..x1).contains(&x) {
                let xr = x as f32 - db;
                if xr >= x0 as f32 - df && xr < x1 as f32 - df {
                    pair.disparity_px[i] = f32::NAN;
                }
            }
        }
    }
    pair
}

#[test]
fn lr_check_removes_the_occluded_strip() {
    let (db, df, x0, x1) = (12.0, 32.0, 110usize, 170usize);
    let pair = depth_step(220, 70, db, df, x0, x1);
    // Occluded: left columns x0 - (df - db) .. x0.
    let strip = x0 - (df - db) as usize..x0;
    for cost in COSTS {
        let mut p = BlockParams::new(cost, 9, 55);
        p.speckle_window_px = 0;
        p.uniqueness_pct = 0;
        let count = |out: &[u16]| {
            let (mut valid, mut total) = (0, 0);
            for y in 4..pair.height - 4 {
                for x in strip.clone() {
                    total += 1;
                    valid += usize::from(out[y * pair.width + x] != 0);
                }
            }
            (valid, total)
        };
        p.lr_check = false;
        let (before, total) = count(&run_pair(&p, &pair));
        p.lr_check = true;
        let out = run_pair(&p, &pair);
        let (after, _) = count(&out);
        assert!(before * 100 >= total * 90, "{cost:?}: {before} of {total}");
        assert!(
            after * 100 <= total * 25,
            "{cost:?}: {after} of {total} left"
        );
        let (acc, _) = accuracy(&pair, &out, p.window, 1.0);
        assert!(acc >= 0.85, "{cost:?}: visible pixels {acc}");
    }
}

#[test]
fn simd_threads_and_scratch_reuse_do_not_change_the_map() {
    let mut pair = plane(160, 50, -0.12, 0.02, 35.0, 17);
    degrade(&mut pair.right, pair.width, 0.9, 5.0, 3.0, 0, 2);
    let (w, h) = (pair.width, pair.height);
    let small = plane(90, 30, 0.0, 0.0, 10.0, 18);
    for cost in COSTS {
        let reference = run_pair(&BlockParams::new(cost, 5, 50), &pair);
        for (simd, threads) in [(false, 1), (true, 3), (false, 2)] {
            let mut p = BlockParams::new(cost, 5, 50);
            p.threads = threads;
            let mut m = BlockMatcher::new(p).expect("params");
            m.set_simd(simd);
            let mut out = vec![0u16; w * h];
            let l = ImageView::new(&pair.left, w, h).expect("left");
            let r = ImageView::new(&pair.right, w, h).expect("right");
            m.compute(l, r, &mut out).expect("compute");
            assert_eq!(out, reference, "{cost:?} simd {simd} threads {threads}");
            // Another size in between, then the first again: same map.
            let mut other = vec![0u16; small.width * small.height];
            let sl = ImageView::new(&small.left, small.width, small.height).expect("l");
            let sr = ImageView::new(&small.right, small.width, small.height).expect("r");
            m.compute(sl, sr, &mut other).expect("small");
            m.compute(l, r, &mut out).expect("again");
            assert_eq!(out, reference, "{cost:?} after reuse");
        }
    }
}

#[test]
fn config_picks_the_cost_and_algorithm() {
    for alg in [
        StereoAlgorithm::BmSad,
        StereoAlgorithm::BmSsd,
        StereoAlgorithm::BmNcc,
        StereoAlgorithm::BmCensus,
    ] {
        let config = StereoConfig {
            algorithm: alg,
            ..StereoConfig::default()
        };
        let m = BlockMatcher::from_config(&config).expect("bm config");
        assert_eq!(m.algorithm(), alg);
        assert_eq!(m.params().min_disp, config.min_disp);
        assert_eq!(crate::matcher_for(&config).expect("boxed").algorithm(), alg);
    }
    let config = StereoConfig {
        algorithm: StereoAlgorithm::BmCensus,
        ..StereoConfig::default()
    };
    let p = BlockParams::from_config(&config).expect("census");
    assert_eq!(
        p.cost,
        BlockCost::Census {
            width: config.bm.census_width,
            height: config.bm.census_height
        }
    );
    let sgm = StereoConfig {
        algorithm: StereoAlgorithm::Sgm,
        ..StereoConfig::default()
    };
    assert!(matches!(
        BlockMatcher::from_config(&sgm),
        Err(StereoError::BadParameter { .. })
    ));
}

#[test]
fn bad_inputs_give_the_right_errors() {
    // Range: max not above min.
    for (min, max) in [(30, 30), (30, 20)] {
        let p = BlockParams::new(BlockCost::Sad, min, max);
        assert_eq!(
            BlockMatcher::new(p).unwrap_err(),
            StereoError::BadRange { min, max }
        );
        let config = StereoConfig {
            algorithm: StereoAlgorithm::BmSad,
            min_disp: min,
            max_disp: max,
            ..StereoConfig::default()
        };
        assert!(matches!(
            BlockMatcher::from_config(&config),
            Err(StereoError::BadRange { .. })
        ));
    }
    // Parameters out of range.
    let with = |f: &dyn Fn(&mut BlockParams)| {
        let mut p = BlockParams::default();
        f(&mut p);
        BlockMatcher::new(p).map(|_| ())
    };
    for bad in [
        with(&|p| p.window = 8),
        with(&|p| p.window = 33),
        with(&|p| p.window = 1),
        with(&|p| p.uniqueness_pct = 100),
        with(&|p| p.texture_threshold = 256),
        with(&|p| p.max_disp = 256),
        with(&|p| p.threads = 0),
        with(&|p| {
            p.cost = BlockCost::Census {
                width: 7,
                height: 7,
            }
        }),
        with(&|p| {
            p.cost = BlockCost::Census {
                width: 4,
                height: 5,
            }
        }),
    ] {
        assert!(
            matches!(bad, Err(StereoError::BadParameter { .. })),
            "{bad:?}"
        );
    }
    // Images of different sizes.
    let mut m = BlockMatcher::new(BlockParams::default()).expect("params");
    let (a, b) = (vec![0u8; 80 * 30], vec![0u8; 81 * 30]);
    let mut out = vec![0u16; 80 * 30];
    let err = m
        .compute(
            ImageView::new(&a, 80, 30).expect("a"),
            ImageView::new(&b, 81, 30).expect("b"),
            &mut out,
        )
        .unwrap_err();
    assert_eq!(
        err,
        StereoError::SizeMismatch {
            left_w: 80,
            left_h: 30,
            right_w: 81,
            right_h: 30
        }
    );
    // Output buffer of the wrong size.
    let mut short = vec![0u16; 10];
    let view = ImageView::new(&a, 80, 30).expect("a");
    assert!(matches!(
        m.compute(view, view, &mut short),
        Err(StereoError::BufferSize { .. })
    ));
    // Not wider than max_disp + window (55 + 9 = 64), or lower than the window.
    for (w, h) in [(64, 30), (40, 30), (100, 8)] {
        let img = vec![0u8; w * h];
        let v = ImageView::new(&img, w, h).expect("img");
        let mut out = vec![0u16; w * h];
        assert_eq!(
            m.compute(v, v, &mut out).unwrap_err(),
            StereoError::ImageTooSmall {
                width: w,
                height: h,
                max_disp: 55,
                window: 9
            }
        );
    }
    let img = vec![0u8; 65 * 9];
    let v = ImageView::new(&img, 65, 9).expect("img");
    let mut out = vec![0u16; 65 * 9];
    assert!(
        m.compute(v, v, &mut out).is_ok(),
        "65x9 is just large enough"
    );
}
