//! The estimator recovers known offsets on synthetic and real pairs; the tracker smooths,
//! rejects outliers and follows a knock; the correction undoes a shift.

use super::*;
use crate::synthetic::{plane, texture_at};

/// Shifts `img` down by `shift_px` rows (sub-pixel: the texture resampled), like a right
/// camera mounted lower.
fn shifted(img: &[u8], w: usize, shift_px: f32) -> Vec<u8> {
    let h = img.len() / w;
    let view = ImageView::new(img, w, h).expect("view");
    let mut out = vec![0u8; img.len()];
    apply_shift(view, -shift_px, &mut out);
    out
}

/// A slanted textured wall with 20..40 px of disparity, 320x240, the right image `shift_px`
/// rows lower (resampled from the texture function, so sub-pixel shifts are exact).
fn wall(shift_px: f32, seed: u64) -> (Vec<u8>, Vec<u8>) {
    let (w, h) = (320usize, 240usize);
    let pair = plane(w, h, 0.06, 0.0, 20.0, seed);
    let mut right = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            // Right pixel (x, y) shows the surface point seen on the left at (xl, y - shift).
            let yl = y as f32 - shift_px;
            // x - (0.06 xl + 20) = xr  =>  xl = (xr + 20) / 0.94
            let xl = (x as f32 + 20.0) / 0.94;
            right[y * w + x] = texture_at(xl, yl, seed).clamp(0.0, 255.0) as u8;
        }
    }
    (pair.left, right)
}

fn estimate(left: &[u8], right: &[u8], w: usize, min_d: usize, max_d: usize) -> ShiftEstimate {
    let h = left.len() / w;
    let l = ImageView::new(left, w, h).expect("left");
    let r = ImageView::new(right, w, h).expect("right");
    estimate_shift(l, r, min_d, max_d, 6).expect("an estimate")
}

#[test]
fn known_offsets_are_recovered_on_a_synthetic_wall() {
    for shift in [-4.0f32, -2.5, -1.0, 0.0, 0.5, 1.0, 2.0, 3.25, 4.0] {
        let (l, r) = wall(shift, 3);
        let e = estimate(&l, &r, 320, 2, 55);
        assert!(
            (e.shift_px - shift).abs() <= 0.2,
            "shift {shift}: estimated {e:?}"
        );
        assert!(e.agreeing >= 20, "{e:?}");
    }
}

#[test]
fn a_flat_view_gives_no_estimate() {
    let flat = vec![128u8; 320 * 240];
    let v = ImageView::new(&flat, 320, 240).expect("view");
    assert_eq!(estimate_shift(v, v, 2, 55, 6), None);
}

#[test]
fn gain_and_offset_between_the_cameras_do_not_move_the_estimate() {
    let (l, mut r) = wall(2.0, 5);
    for p in r.iter_mut() {
        *p = (*p as f32 * 0.8 + 10.0).round() as u8;
    }
    let e = estimate(&l, &r, 320, 2, 55);
    assert!((e.shift_px - 2.0).abs() <= 0.2, "{e:?}");
}

/// The Middlebury scenes beside the repository, grey.
fn scenes() -> Vec<crate::eval::Scene> {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/datasets");
    let Ok(dirs) = crate::eval::list_scenes(&root) else {
        eprintln!("SKIPPED: no datasets at {}", root.display());
        return Vec::new();
    };
    dirs.iter()
        .map(|d| crate::eval::load_scene(d).expect("scene loads"))
        .collect()
}

#[test]
fn known_offsets_are_recovered_on_real_pairs() {
    for scene in scenes() {
        for shift in [-4i32, -2, -1, 1, 2, 4] {
            let right = shifted(&scene.right, scene.width, shift as f32);
            let e = estimate(
                &scene.left,
                &right,
                scene.width,
                scene.min_disp as usize,
                scene.max_disp as usize,
            );
            assert!(
                (e.shift_px - shift as f32).abs() <= 0.3,
                "{} shift {shift}: {e:?}",
                scene.name
            );
        }
    }
}

#[test]
fn the_tracker_smooths_rejects_an_outlier_and_follows_a_knock() {
    let est = |s: f32| ShiftEstimate {
        shift_px: s,
        votes: 30,
        agreeing: 25,
    };
    let mut a = RowAligner::new(6, 1);
    a.track(est(2.0));
    a.track(est(2.4));
    let c = a.current.expect("tracked");
    assert!((c - 2.12).abs() < 1e-4, "{c}");
    // One wild measurement is ignored.
    a.track(est(-3.0));
    assert!((a.current.expect("tracked") - c).abs() < 1e-6);
    a.track(est(2.1));
    // A knock: three agreeing measurements far away move it at once.
    for _ in 0..3 {
        a.track(est(-1.0));
    }
    assert_eq!(a.current, Some(-1.0));
}

#[test]
fn the_correction_undoes_a_whole_and_a_half_row_shift() {
    let (w, h) = (64usize, 32usize);
    let img: Vec<u8> = (0..w * h).map(|i| ((i / w) * 8) as u8).collect();
    let view = ImageView::new(&img, w, h).expect("view");
    let mut down = vec![0u8; w * h];
    apply_shift(view, -2.0, &mut down);
    assert_eq!(down[5 * w], img[3 * w], "row 5 holds row 3");
    let mut back = vec![0u8; w * h];
    apply_shift(ImageView::new(&down, w, h).expect("view"), 2.0, &mut back);
    assert_eq!(&back[2 * w..(h - 2) * w], &img[2 * w..(h - 2) * w]);
    let mut half = vec![0u8; w * h];
    apply_shift(view, 0.5, &mut half);
    assert_eq!(
        half[4 * w],
        (img[4 * w] as u32 + img[5 * w] as u32).div_ceil(2) as u8
    );
}

#[test]
fn the_aligner_leaves_an_aligned_pair_untouched() {
    let (l, r) = wall(0.0, 9);
    let lv = ImageView::new(&l, 320, 240).expect("view");
    let rv = ImageView::new(&r, 320, 240).expect("view");
    let mut a = RowAligner::new(6, 4);
    let (out, status) = a.align(lv, rv, 2, 55);
    assert!(status.measured);
    assert_eq!(status.applied_px, 0.0);
    assert!(std::ptr::eq(out.data.as_ptr(), r.as_ptr()), "no copy made");
    let (l, r) = wall(3.0, 9);
    let lv = ImageView::new(&l, 320, 240).expect("view");
    let rv = ImageView::new(&r, 320, 240).expect("view");
    let mut a = RowAligner::new(6, 4);
    let (_, status) = a.align(lv, rv, 2, 55);
    assert!((status.applied_px - 3.0).abs() < 0.2, "{status:?}");
    // Frames between measurements reuse the tracked offset.
    let (_, status) = a.align(lv, rv, 2, 55);
    assert!(!status.measured && status.applied_px != 0.0);
}
