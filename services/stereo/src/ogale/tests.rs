//! Tests of the Ogale & Aloimonos matcher on synthetic pairs: both variants, every match
//! function, slants, occlusions, equalisation and parameter checks.

use super::*;
use crate::synthetic::{SyntheticPair, flatten_region, plane, score, texture_at};

fn params(min_disp: u32, max_disp: u32) -> OgaleParams {
    OgaleParams {
        min_disp,
        max_disp,
        ..OgaleParams::default()
    }
}

fn run(p: &OgaleParams, pair: &SyntheticPair) -> Vec<u16> {
    let mut m = OgaleMatcher::new(p.clone()).expect("valid params");
    let (w, h) = (pair.width, pair.height);
    let mut out = vec![0u16; w * h];
    let l = ImageView::new(&pair.left, w, h).expect("left");
    let r = ImageView::new(&pair.right, w, h).expect("right");
    m.compute(l, r, &mut out).expect("compute");
    out
}

/// Shares of the pixels selected by `pick` (with known disparity) that are within `tol` px,
/// invalid, and wrong (valid but off by more than `tol`).
fn shares(
    pair: &SyntheticPair,
    out: &[u16],
    tol: f32,
    pick: impl Fn(usize, usize) -> bool,
) -> (f32, f32, f32) {
    let (mut n, mut good, mut invalid, mut wrong) = (0, 0, 0, 0);
    for y in 0..pair.height {
        for x in 0..pair.width {
            let i = y * pair.width + x;
            let truth = pair.disparity_px[i];
            if !truth.is_finite() || !pick(x, y) {
                continue;
            }
            n += 1;
            match crate::q8_to_px(out[i]) {
                None => invalid += 1,
                Some(d) if (d - truth).abs() <= tol => good += 1,
                Some(_) => wrong += 1,
            }
        }
    }
    let n = n.max(1) as f32;
    (good as f32 / n, invalid as f32 / n, wrong as f32 / n)
}

/// A textured background at `d_bg` with a nearer textured box (columns `x0..x1`, all rows)
/// at `d_fg`. Background pixels hidden in the right image by the box are NaN.
fn two_planes(w: usize, h: usize, d_bg: f32, d_fg: f32, x0: usize, x1: usize) -> SyntheticPair {
    let mut p = plane(w, h, 0.0, 0.0, d_bg, 11);
    let in_box = |u: f32| u >= x0 as f32 && u < x1 as f32;
    for y in 0..h {
        for x in 0..w {
            let (i, xf, yf) = (y * w + x, x as f32, y as f32);
            if in_box(xf) {
                p.left[i] = texture_at(xf, yf, 99) as u8;
                p.disparity_px[i] = if xf - d_fg >= 0.0 { d_fg } else { f32::NAN };
            } else {
                p.left[i] = texture_at(xf, yf, 11) as u8;
                let hidden = in_box(xf - d_bg + d_fg);
                p.disparity_px[i] = if xf - d_bg < 0.0 || hidden {
                    f32::NAN
                } else {
                    d_bg
                };
            }
            // The right image shows the box where it covers the background.
            p.right[i] = if in_box(xf + d_fg) {
                texture_at(xf + d_fg, yf, 99) as u8
            } else {
                texture_at(xf + d_bg, yf, 11) as u8
            };
        }
    }
    p
}

/// Two horizontally striped surfaces stacked vertically: bands of 2 rows of one grey level
/// (neighbouring bands differ by at least 25) with sparse 1-px vertical ticks. Rows
/// `0..h/2` lie at `d_top`, the others at `d_bottom`.
fn striped(w: usize, h: usize, d_top: f32, d_bottom: f32) -> SyntheticPair {
    let tex = |u: usize, y: usize| -> u8 {
        let band = y / 2;
        let grey = 60 + ((band * 6) % 7) as u32 * 25;
        let hash = (u as u32).wrapping_mul(2_654_435_761) ^ (band as u32).wrapping_mul(40_503);
        if (hash >> 7).is_multiple_of(9) {
            if grey > 128 {
                (grey - 70) as u8
            } else {
                (grey + 70) as u8
            }
        } else {
            grey as u8
        }
    };
    let mut left = vec![0u8; w * h];
    let mut right = vec![0u8; w * h];
    let mut disparity_px = vec![f32::NAN; w * h];
    for y in 0..h {
        let d = if y < h / 2 { d_top } else { d_bottom };
        for x in 0..w {
            left[y * w + x] = tex(x, y);
            right[y * w + x] = tex(x + d as usize, y);
            if x as f32 >= d {
                disparity_px[y * w + x] = d;
            }
        }
    }
    SyntheticPair {
        width: w,
        height: h,
        left,
        right,
        disparity_px,
    }
}

#[test]
fn fronto_parallel_plane_is_recovered() {
    let pair = plane(160, 100, 0.0, 0.0, 20.0, 1);
    for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
        let p = params(5, 40).with_variant(variant);
        let out = run(&p, &pair);
        let (good, dense) = score(&pair, &out, 1.0, 40);
        println!("fronto {variant:?}: good {good} dense {dense}");
        assert!(good > 0.97, "{variant:?}: good {good} dense {dense}");
    }
}

#[test]
fn two_planes_are_recovered_and_the_occluded_strip_is_invalid() {
    let (d_bg, d_fg, x0, x1) = (10.0, 30.0, 90, 170);
    let pair = two_planes(240, 120, d_bg, d_fg, x0, x1);
    for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
        let out = run(&params(5, 40).with_variant(variant), &pair);
        let fg = shares(&pair, &out, 1.0, |x, _| (x0..x1).contains(&x));
        let bg = shares(&pair, &out, 1.0, |x, _| {
            x >= 30 && !(x0 - 20..x1).contains(&x)
        });
        // The background strip left of the box is hidden from the right camera.
        let strip = x0 - (d_fg - d_bg) as usize..x0;
        let mut occluded = (0usize, 0usize);
        for y in 0..pair.height {
            for x in strip.clone() {
                occluded.0 += 1;
                occluded.1 += usize::from(out[y * pair.width + x] == 0);
            }
        }
        let occ_invalid = occluded.1 as f32 / occluded.0 as f32;
        println!("two planes {variant:?}: fg {fg:?} bg {bg:?} occluded invalid {occ_invalid}");
        assert!(
            fg.0 > 0.97 && bg.0 > 0.97,
            "{variant:?}: fg {fg:?} bg {bg:?}"
        );
        assert!(
            occ_invalid > 0.9,
            "{variant:?}: only {occ_invalid} of the occluded strip invalid"
        );
    }
}

#[test]
fn stretch_factors_help_on_a_sideways_slanted_plane() {
    // d(x) = 50 - 0.2 x: a hallway wall seen at an angle (right image stretched by 1.2).
    let pair = plane(200, 80, -0.2, 0.0, 50.0, 2);
    let base = params(5, 55);
    let flat = run(&base, &pair);
    let stretched = run(
        &OgaleParams {
            stretch: vec![0.8, 0.9, 1.0, 1.1, 1.25],
            ..base.clone()
        },
        &pair,
    );
    let (flat_good, flat_dense) = score(&pair, &flat, 0.5, 0);
    let (st_good, st_dense) = score(&pair, &stretched, 0.5, 0);
    let (flat_good2, _) = score(&pair, &flat, 2.0, 0);
    let (st_good2, _) = score(&pair, &stretched, 2.0, 0);
    println!(
        "slant: within 0.5 px {flat_good} -> {st_good}, within 2 px {flat_good2} -> {st_good2}, dense {flat_dense} -> {st_dense}"
    );
    assert!(
        st_good > flat_good + 0.15,
        "within 0.5 px: {flat_good} -> {st_good}"
    );
    assert!(
        st_good2 >= flat_good2,
        "within 2 px: {flat_good2} -> {st_good2}"
    );
}

#[test]
fn textureless_block_is_invalid_rather_than_wrong() {
    let mut pair = plane(200, 80, 0.0, 0.0, 20.0, 3);
    flatten_region(&mut pair, 80, 140, 128);
    for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
        let out = run(&params(5, 40).with_variant(variant), &pair);
        let block = shares(&pair, &out, 1.0, |x, _| (80..140).contains(&x));
        println!("flat block {variant:?}: (good, invalid, wrong) {block:?}");
        assert!(
            block.2 < 0.02,
            "{variant:?}: {} of the flat block wrong",
            block.2
        );
    }
    // With nothing to match anywhere, nothing is claimed.
    let flat = SyntheticPair {
        left: vec![90; 120 * 40],
        right: vec![90; 120 * 40],
        ..plane(120, 40, 0.0, 0.0, 10.0, 4)
    };
    for variant in [OgaleVariant::Components, OgaleVariant::Diffusion] {
        let out = run(&params(5, 30).with_variant(variant), &flat);
        let valid = out.iter().filter(|&&d| d != 0).count();
        assert_eq!(
            valid, 0,
            "{variant:?}: {valid} pixels of a blank pair valid"
        );
    }
}

#[test]
fn cutting_vertical_links_at_horizontal_edges_matters() {
    let pair = striped(200, 80, 12.0, 30.0);
    let base = params(5, 40);
    let with_cut = run(&base, &pair);
    let without = run(
        &OgaleParams {
            cut_horizontal_edges: false,
            ..base.clone()
        },
        &pair,
    );
    let (cut_good, cut_dense) = score(&pair, &with_cut, 1.0, 40);
    let (nocut_good, nocut_dense) = score(&pair, &without, 1.0, 40);
    let cut_wrong = cut_dense - cut_good;
    let nocut_wrong = nocut_dense - nocut_good;
    println!(
        "stripes: good {nocut_good} -> {cut_good}, wrong {nocut_wrong} -> {cut_wrong} (without -> with cuts)"
    );
    assert!(cut_good > 0.95, "with cuts only {cut_good} correct");
    assert!(
        cut_good > nocut_good + 0.4,
        "cuts: {nocut_good} -> {cut_good}"
    );
}

#[test]
fn bad_inputs_are_rejected() {
    let ok = params(5, 20);
    let bad = |p: OgaleParams| OgaleMatcher::new(p).expect_err("must be rejected");
    assert!(matches!(
        bad(params(20, 20)),
        StereoError::BadRange { min: 20, max: 20 }
    ));
    assert!(matches!(
        bad(params(0, 300)),
        StereoError::BadParameter { .. }
    ));
    for stretch in [vec![], vec![0.2], vec![f32::NAN], vec![1.0, 3.0]] {
        let p = OgaleParams {
            stretch,
            ..ok.clone()
        };
        assert!(matches!(bad(p), StereoError::BadParameter { .. }));
    }
    let p = OgaleParams {
        match_threshold: 256,
        ..ok.clone()
    };
    assert!(matches!(bad(p), StereoError::BadParameter { .. }));
    let p = OgaleParams {
        vertical_search_px: 3,
        ..ok.clone()
    };
    assert!(matches!(bad(p), StereoError::BadParameter { .. }));
    let config = StereoConfig {
        min_disp: 30,
        max_disp: 10,
        ..StereoConfig::default()
    };
    assert!(matches!(
        OgaleMatcher::from_config(&config),
        Err(StereoError::BadRange { .. })
    ));

    let mut m = OgaleMatcher::new(ok).expect("valid");
    let a = vec![0u8; 64 * 8];
    let b = vec![0u8; 48 * 8];
    let mut out = vec![0u16; 64 * 8];
    fn view(data: &[u8], width: usize, height: usize) -> ImageView<'_> {
        ImageView {
            data,
            width,
            height,
        }
    }
    let err = m
        .compute(view(&a, 64, 8), view(&b, 48, 8), &mut out)
        .expect_err("sizes differ");
    assert!(matches!(err, StereoError::SizeMismatch { .. }));
    let err = m
        .compute(view(&a, 64, 8), view(&a, 64, 8), &mut out[1..])
        .expect_err("output");
    assert!(matches!(err, StereoError::BufferSize { .. }));
    // Views built by hand with too few pixels are caught, not indexed out of bounds.
    let err = m
        .compute(view(&a[1..], 64, 8), view(&a[1..], 64, 8), &mut out)
        .expect_err("data");
    assert!(matches!(err, StereoError::BufferSize { .. }));
    let narrow = vec![0u8; 21 * 8];
    let mut out = vec![0u16; 21 * 8];
    let err = m
        .compute(view(&narrow, 21, 8), view(&narrow, 21, 8), &mut out)
        .expect_err("narrow");
    assert!(matches!(
        err,
        StereoError::ImageTooSmall { max_disp: 20, .. }
    ));
}

#[test]
fn scratch_buffers_are_reused_across_sizes() {
    let small = plane(120, 50, 0.0, 0.0, 15.0, 5);
    let large = plane(180, 70, 0.0, 0.0, 25.0, 6);
    let p = OgaleParams {
        stretch: vec![0.9, 1.0, 1.1],
        ..params(5, 35)
    };
    let mut m = OgaleMatcher::new(p.clone()).expect("valid");
    for pair in [&small, &large, &small] {
        let (w, h) = (pair.width, pair.height);
        let mut out = vec![0u16; w * h];
        let l = ImageView::new(&pair.left, w, h).expect("left");
        let r = ImageView::new(&pair.right, w, h).expect("right");
        let stats = m.compute(l, r, &mut out).expect("compute");
        assert_eq!(
            out,
            run(&p, pair),
            "a reused matcher must give a fresh one's map"
        );
        assert_eq!(
            stats.valid_px as usize,
            out.iter().filter(|&&d| d != 0).count()
        );
    }
    assert_eq!(m.algorithm(), StereoAlgorithm::Ogale);
    let config = StereoConfig {
        algorithm: StereoAlgorithm::Ogale,
        ..StereoConfig::default()
    };
    assert_eq!(
        crate::matcher_for(&config).expect("ogale").algorithm(),
        StereoAlgorithm::Ogale
    );
}

#[test]
fn mean_std_equalisation_undoes_gain_and_offset() {
    let left: Vec<u8> = (0..2000).map(|i| (30 + (i * 7) % 180) as u8).collect();
    let right: Vec<u8> = left
        .iter()
        .map(|&p| (p as f32 * 0.8 + 10.0).round() as u8)
        .collect();
    let mut out = vec![0u8; left.len()];
    equalize_mean_std(&left, &right, &mut out);
    let worst = left
        .iter()
        .zip(&out)
        .map(|(&a, &b)| (a as i32 - b as i32).abs())
        .max();
    assert!(worst.is_some_and(|w| w <= 1), "worst difference {worst:?}");
}

#[test]
fn webcam_defects_are_survived_with_the_robust_options() {
    let mut pair = plane(200, 80, 0.0, 0.0, 20.0, 7);
    crate::synthetic::degrade(&mut pair.right, pair.width, 0.8, 10.0, 4.0, 1, 9);
    let p = OgaleParams {
        equalization: Equalization::MeanStd,
        ..params(5, 40)
    };
    let (good, dense) = score(&pair, &run(&p, &pair), 1.0, 40);
    println!("degraded: good {good} dense {dense}");
    assert!(good > 0.8, "good {good} dense {dense}");
}
