//! The stereo command line: `hvs stereo` on real files, its errors, and `hvs eval` on the
//! Middlebury scenes in ../shared/datasets with accuracy floors.

use std::path::{Path, PathBuf};

use hvs_tests::{hvs, hvs_ok, repo_root};
use serde_json::Value;

fn dataset() -> Option<PathBuf> {
    let d = repo_root().join("../shared/datasets");
    if d.join("tsukuba/scene.toml").is_file() {
        Some(d)
    } else {
        eprintln!(
            "SKIPPED: no datasets at {} (they sit beside the repository)",
            d.display()
        );
        None
    }
}

fn write_png(path: &Path, w: u32, h: u32, f: impl Fn(u32, u32) -> u8) {
    let img = image::GrayImage::from_fn(w, h, |x, y| image::Luma([f(x, y)]));
    img.save(path).expect("write png");
}

/// A textured pair with a constant disparity of 12 px.
fn shifted_pair(dir: &Path, w: u32, h: u32) -> (PathBuf, PathBuf) {
    let tex = |x: u32, y: u32| -> u8 {
        let v = x.wrapping_mul(2654435761) ^ y.wrapping_mul(2246822519);
        let v = (v ^ (v >> 13)).wrapping_mul(3266489917);
        ((v >> 24) as u8 / 2) + ((x / 3 + y / 3) % 2 * 60) as u8 + 30
    };
    let (l, r) = (dir.join("left.png"), dir.join("right.png"));
    write_png(&l, w, h, tex);
    write_png(&r, w, h, |x, y| tex(x + 12, y));
    (l, r)
}

#[test]
fn hvs_stereo_writes_a_kitti_disparity_png() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = shifted_pair(dir.path(), 160, 120);
    let out = dir.path().join("d.png");
    for algo in ["sgm", "bm-sad", "bm-census", "ogale"] {
        hvs_ok(&[
            "stereo",
            "--algo",
            algo,
            "--left",
            l.to_str().unwrap(),
            "--right",
            r.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--min-disp",
            "4",
            "--max-disp",
            "30",
        ]);
        let d = image::open(&out).expect("output png").into_luma16();
        assert_eq!(d.dimensions(), (160, 120));
        let vals: Vec<f32> = d
            .pixels()
            .filter(|p| p.0[0] != 0)
            .map(|p| p.0[0] as f32 / 256.0)
            .collect();
        assert!(
            vals.len() > 160 * 120 / 3,
            "{algo}: only {} valid",
            vals.len()
        );
        let good = vals.iter().filter(|v| (**v - 12.0).abs() <= 1.0).count();
        assert!(
            good * 100 >= vals.len() * 90,
            "{algo}: {good} of {} near 12 px",
            vals.len()
        );
    }
}

#[test]
fn hvs_stereo_bad_inputs_fail_with_clear_messages() {
    let dir = tempfile::tempdir().unwrap();
    let (l, r) = shifted_pair(dir.path(), 160, 120);
    let small = dir.path().join("small.png");
    write_png(&small, 150, 120, |x, _| x as u8);
    let narrow_l = dir.path().join("narrow_l.png");
    let narrow_r = dir.path().join("narrow_r.png");
    write_png(&narrow_l, 40, 30, |x, y| (x * 7 + y * 3) as u8);
    write_png(&narrow_r, 40, 30, |x, y| (x * 7 + y * 3) as u8);
    let corrupt = dir.path().join("corrupt.png");
    std::fs::write(&corrupt, b"\x89PNG not really").unwrap();
    let out = dir.path().join("d.png");
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let cases: Vec<(Vec<String>, Vec<&str>)> = vec![
        (
            vec![s(&l), s(&small)],
            vec!["160x120", "150x120", "small.png"],
        ),
        (
            vec![s(&l), s(&dir.path().join("missing.png"))],
            vec!["missing.png"],
        ),
        (vec![s(&corrupt), s(&r)], vec!["corrupt.png"]),
        (vec![s(&narrow_l), s(&narrow_r)], vec!["40x30", "too small"]),
    ];
    for (files, expected) in cases {
        let res = hvs(&[
            "stereo",
            "--left",
            &files[0],
            "--right",
            &files[1],
            "--out",
            out.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&res.stderr);
        assert!(!res.status.success(), "accepted {files:?}");
        for e in expected {
            assert!(err.contains(e), "{files:?}: {err:?} lacks {e:?}");
        }
    }
    let res = hvs(&[
        "stereo",
        "--left",
        &s(&l),
        "--right",
        &s(&r),
        "--out",
        out.to_str().unwrap(),
        "--min-disp",
        "20",
        "--max-disp",
        "20",
    ]);
    let err = String::from_utf8_lossy(&res.stderr);
    assert!(
        !res.status.success() && err.contains("max disparity 20 must be above min disparity 20"),
        "{err}"
    );
    let res = hvs(&[
        "stereo",
        "--algo",
        "bm-xyz",
        "--left",
        &s(&l),
        "--right",
        &s(&r),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&res.stderr).contains("unknown stereo algorithm \"bm-xyz\""));
}

fn eval_means(algos: &str, dataset: &Path) -> Value {
    let res = hvs_ok(&[
        "eval",
        "--algo",
        algos,
        "--dataset",
        dataset.to_str().unwrap(),
        "--degrade",
        "--json",
        "--repeat",
        "1",
    ]);
    serde_json::from_slice(&res.stdout).expect("eval JSON")
}

fn mean<'a>(v: &'a Value, algo: &str, condition: &str) -> &'a Value {
    v["means"]
        .as_array()
        .unwrap()
        .iter()
        .find(|m| m["algorithm"] == algo && m["condition"] == condition)
        .unwrap_or_else(|| panic!("no mean for {algo} {condition} in {v}"))
}

/// Accuracy floors on the real Middlebury pairs, clean and with webcam defects. The default
/// (`sgm`) must stay at or below what OpenCV StereoSGBM measured on the same images
/// (10.53 % clean, 16.69 % degraded: `bench/compare_opencv.py`, docs/stereo.md); the other
/// floors are about 3 points above what each algorithm measured, so a regression fails here.
#[test]
fn eval_on_the_middlebury_scenes_meets_the_accuracy_floors() {
    let Some(dataset) = dataset() else { return };
    // (algorithm, max mean bad-2 % clean, max mean bad-2 % degraded); measured 2026-12-01
    // with the row alignment (the degradation's 1 px vertical shift is now undone):
    // sgm 6.28 / 7.92 (with its gap fill; 8.09 / 10.29 without), bm-census 12.98 / 27.61, bm-sad 15.98 / 37.63, bm-ncc 14.22 / 22.81,
    // bm-ssd 15.86 / 33.16, ogale 29.20 / 40.65 (without it: sgm 14.89 degraded, bm-census
    // 53.41, bm-sad 52.78, bm-ncc 40.82, bm-ssd 49.17, ogale 42.97).
    let floors = [
        ("sgm", 10.53, 13.3),
        ("bm-census", 16.0, 30.6),
        ("bm-sad", 19.0, 40.6),
        ("bm-ssd", 19.0, 36.2),
        ("bm-ncc", 17.0, 25.8),
        ("ogale", 32.0, 43.7),
    ];
    let algos: Vec<&str> = floors.iter().map(|f| f.0).collect();
    let v = eval_means(&algos.join(","), &dataset);
    for (algo, clean_max, degraded_max) in floors {
        let c = mean(&v, algo, "clean")["bad2_pct"].as_f64().unwrap();
        let d = mean(&v, algo, "degraded")["bad2_pct"].as_f64().unwrap();
        assert!(
            c <= clean_max,
            "{algo}: clean bad-2 {c:.2}% above its floor {clean_max}%"
        );
        assert!(
            d <= degraded_max,
            "{algo}: degraded bad-2 {d:.2}% above its floor {degraded_max}%"
        );
    }
    // Every scene is scored in its non-occluded region where one exists.
    let rows = v["rows"].as_array().unwrap();
    assert!(
        rows.iter()
            .any(|r| r["scene"] == "tsukuba" && r["region"] == "nonocc")
    );
    assert!(
        rows.iter()
            .any(|r| r["scene"] == "motorcycle" && r["region"] == "all")
    );
}

/// The row alignment undoes a vertical offset: with the right image shifted by up to 4 rows
/// either way (clean, and with webcam defects), every scene's bad-2 stays within 1 point of
/// its unshifted figure, and the estimated offset is the applied one.
#[test]
fn a_vertical_shift_of_up_to_4_rows_costs_at_most_1_point_on_every_scene() {
    let Some(dataset) = dataset() else { return };
    let res = hvs_ok(&[
        "eval",
        "--algo",
        "sgm",
        "--dataset",
        dataset.to_str().unwrap(),
        "--degrade",
        "--vshift=-4,-3,-2,-1,1,2,3,4",
        "--json",
        "--repeat",
        "1",
    ]);
    let v: Value = serde_json::from_slice(&res.stdout).expect("eval JSON");
    let rows = v["rows"].as_array().expect("rows");
    let bad2 = |scene: &Value, condition: &str| -> f64 {
        rows.iter()
            .find(|r| &r["scene"] == scene && r["condition"] == condition)
            .and_then(|r| r["bad2_pct"].as_f64())
            .unwrap_or_else(|| panic!("no {condition} row for {scene}"))
    };
    let mut checked = 0;
    for r in rows {
        let condition = r["condition"].as_str().expect("condition");
        let Some((base, shift)) = condition.split_once("-v") else {
            continue;
        };
        let shift: f64 = shift.parse().expect("shift");
        let shifted = r["bad2_pct"].as_f64().expect("bad2");
        let unshifted = bad2(&r["scene"], base);
        assert!(
            shifted <= unshifted + 1.0,
            "{} {condition}: bad-2 {shifted:.2} against {unshifted:.2} unshifted",
            r["scene"]
        );
        let estimated = r["row_shift_px"].as_f64().expect("an offset estimate");
        assert!(
            (estimated - shift).abs() <= 0.3,
            "{} {condition}: estimated {estimated:+.2} rows",
            r["scene"]
        );
        checked += 1;
    }
    let scenes = rows.iter().filter(|r| r["condition"] == "clean").count();
    assert!(scenes >= 3, "{scenes} scenes");
    assert_eq!(
        checked,
        scenes * 2 * 8,
        "every scene, clean and degraded, 8 shifts"
    );
}
