//! Scoring disparity maps against ground truth: scenes laid out like `../shared/datasets`
//! (one folder per scene with `left.png`, `right.png`, `gt_disp.png`, masks and `scene.toml`),
//! the bad-N error rates, webcam defects for `--degrade`, and 16-bit disparity PNG I/O.

use std::path::{Path, PathBuf};
use std::time::Instant;

use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::DISPARITY_SCALE;
use serde::Deserialize;

use crate::{ImageView, StereoError, matcher_for};

/// Why a scene or image could not be used.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A file could not be read or decoded.
    #[error("cannot read image {path}: {detail}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        detail: String,
    },
    /// A file could not be written.
    #[error("cannot write {path}: {detail}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        detail: String,
    },
    /// `scene.toml` is missing or malformed.
    #[error("bad scene description {path}: {detail}")]
    Scene {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        detail: String,
    },
    /// Images of a scene disagree in size.
    #[error("{path} is {actual_w}x{actual_h}, expected {expected_w}x{expected_h}")]
    Size {
        /// The file.
        path: PathBuf,
        /// Its width.
        actual_w: u32,
        /// Its height.
        actual_h: u32,
        /// Expected width.
        expected_w: u32,
        /// Expected height.
        expected_h: u32,
    },
    /// The dataset folder has no scenes.
    #[error("no scenes (folders with a scene.toml) in {0}")]
    NoScenes(PathBuf),
    /// Matching failed.
    #[error("{scene}: {source}")]
    Stereo {
        /// Scene name.
        scene: String,
        /// The error.
        source: StereoError,
    },
}

/// The parts of `scene.toml` the scorer needs.
#[derive(Debug, Clone, Deserialize)]
struct SceneToml {
    name: String,
    width: u32,
    height: u32,
    gt_scale: f32,
    gt_invalid: u32,
    min_disp: u32,
    max_disp: u32,
    #[serde(default)]
    nonocc_mask: String,
    #[serde(default)]
    all_mask: String,
}

/// A loaded scene: grey pair, ground truth and the mask of scored pixels.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Scene name.
    pub name: String,
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// Left image, grey.
    pub left: Vec<u8>,
    /// Right image, grey.
    pub right: Vec<u8>,
    /// Ground-truth disparity in 1/256 px, 0 = unknown.
    pub gt_q8: Vec<u16>,
    /// Pixels that are scored.
    pub scored: Vec<bool>,
    /// Which mask `scored` is: `nonocc` where the scene has one, else `all`.
    pub region: &'static str,
    /// Search range to give a matcher.
    pub min_disp: u32,
    /// Search range to give a matcher (inclusive).
    pub max_disp: u32,
}

/// Reads a PNG (or any format `image` knows) as grey: colour is converted with the ITU-R
/// BT.601 weights 0.299 R + 0.587 G + 0.114 B (what OpenCV's grey conversion uses).
pub fn read_grey(path: &Path) -> Result<(Vec<u8>, usize, usize), EvalError> {
    let img = image::open(path).map_err(|e| EvalError::Image {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    let grey = match img {
        image::DynamicImage::ImageLuma8(g) => g.into_raw(),
        other => other
            .to_rgb8()
            .pixels()
            .map(|p| {
                let [r, g, b] = p.0;
                ((299 * r as u32 + 587 * g as u32 + 114 * b as u32 + 500) / 1000) as u8
            })
            .collect(),
    };
    Ok((grey, w, h))
}

fn read_raw16(path: &Path) -> Result<(Vec<u16>, usize, usize), EvalError> {
    let img = image::open(path).map_err(|e| EvalError::Image {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    Ok((img.into_luma16().into_raw(), w, h))
}

/// Reads a disparity PNG in the KITTI convention (16-bit, disparity x 256, 0 = invalid).
pub fn read_disparity_png(path: &Path) -> Result<(Vec<u16>, usize, usize), EvalError> {
    read_raw16(path)
}

/// Writes a disparity map as a 16-bit grey PNG (disparity x 256, 0 = invalid).
pub fn write_disparity_png(
    path: &Path,
    disp_q8: &[u16],
    width: usize,
    height: usize,
) -> Result<(), EvalError> {
    let img = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(
        width as u32,
        height as u32,
        disp_q8.to_vec(),
    )
    .ok_or_else(|| EvalError::Write {
        path: path.to_path_buf(),
        detail: format!("{} values do not fill {width}x{height}", disp_q8.len()),
    })?;
    img.save(path).map_err(|e| EvalError::Write {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })
}

/// Writes an 8-bit grey PNG.
pub fn write_grey_png(
    path: &Path,
    pixels: &[u8],
    width: usize,
    height: usize,
) -> Result<(), EvalError> {
    let img = image::GrayImage::from_raw(width as u32, height as u32, pixels.to_vec()).ok_or_else(
        || EvalError::Write {
            path: path.to_path_buf(),
            detail: format!("{} values do not fill {width}x{height}", pixels.len()),
        },
    )?;
    img.save(path).map_err(|e| EvalError::Write {
        path: path.to_path_buf(),
        detail: e.to_string(),
    })
}

fn check_size(path: &Path, w: usize, h: usize, ew: usize, eh: usize) -> Result<(), EvalError> {
    if (w, h) != (ew, eh) {
        return Err(EvalError::Size {
            path: path.to_path_buf(),
            actual_w: w as u32,
            actual_h: h as u32,
            expected_w: ew as u32,
            expected_h: eh as u32,
        });
    }
    Ok(())
}

/// Loads one scene folder.
pub fn load_scene(dir: &Path) -> Result<Scene, EvalError> {
    let toml_path = dir.join("scene.toml");
    let text = std::fs::read_to_string(&toml_path).map_err(|e| EvalError::Scene {
        path: toml_path.clone(),
        detail: e.to_string(),
    })?;
    let meta: SceneToml = toml::from_str(&text).map_err(|e| EvalError::Scene {
        path: toml_path.clone(),
        detail: e.to_string(),
    })?;
    let (w, h) = (meta.width as usize, meta.height as usize);
    let (left, lw, lh) = read_grey(&dir.join("left.png"))?;
    check_size(&dir.join("left.png"), lw, lh, w, h)?;
    let (right, rw, rh) = read_grey(&dir.join("right.png"))?;
    check_size(&dir.join("right.png"), rw, rh, w, h)?;
    let gt_path = dir.join("gt_disp.png");
    let (gt_raw, gw, gh) = read_raw16(&gt_path)?;
    check_size(&gt_path, gw, gh, w, h)?;
    if meta.gt_scale <= 0.0 {
        return Err(EvalError::Scene {
            path: toml_path,
            detail: format!("gt_scale {} must be positive", meta.gt_scale),
        });
    }
    let gt_q8: Vec<u16> = gt_raw
        .iter()
        .map(|&v| {
            if v as u32 == meta.gt_invalid {
                0
            } else {
                (v as f32 / meta.gt_scale * DISPARITY_SCALE)
                    .round()
                    .clamp(1.0, u16::MAX as f32) as u16
            }
        })
        .collect();
    let (mask_name, region) = if !meta.nonocc_mask.is_empty() {
        (meta.nonocc_mask.as_str(), "nonocc")
    } else {
        (meta.all_mask.as_str(), "all")
    };
    let scored: Vec<bool> = if mask_name.is_empty() {
        gt_q8.iter().map(|&g| g != 0).collect()
    } else {
        let mask_path = dir.join(mask_name);
        let (mask, mw, mh) = read_grey(&mask_path)?;
        check_size(&mask_path, mw, mh, w, h)?;
        mask.iter()
            .zip(&gt_q8)
            .map(|(&m, &g)| m == 255 && g != 0)
            .collect()
    };
    Ok(Scene {
        name: meta.name,
        width: w,
        height: h,
        left,
        right,
        gt_q8,
        scored,
        region,
        min_disp: meta.min_disp,
        max_disp: meta.max_disp,
    })
}

/// The scene folders of a dataset folder, sorted by name.
pub fn list_scenes(dataset: &Path) -> Result<Vec<PathBuf>, EvalError> {
    let entries = std::fs::read_dir(dataset).map_err(|e| EvalError::Scene {
        path: dataset.to_path_buf(),
        detail: e.to_string(),
    })?;
    let mut dirs: Vec<PathBuf> = entries
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.join("scene.toml").is_file())
        .collect();
    dirs.sort();
    if dirs.is_empty() {
        return Err(EvalError::NoScenes(dataset.to_path_buf()));
    }
    Ok(dirs)
}

/// The webcam defects `--degrade` applies to the right image: gain 0.8, offset +10, Gaussian
/// noise sigma 4, 1 px vertical shift (raw webcam pairs are the real case).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Degradation {
    /// Gain.
    pub gain: f32,
    /// Offset, grey levels.
    pub offset: f32,
    /// Noise sigma, grey levels.
    pub noise_sigma: f32,
    /// Downward shift, px.
    pub vertical_shift_px: usize,
    /// Noise seed.
    pub seed: u64,
}

impl Default for Degradation {
    fn default() -> Self {
        Self {
            gain: 0.8,
            offset: 10.0,
            noise_sigma: 4.0,
            vertical_shift_px: 1,
            seed: 7,
        }
    }
}

impl Scene {
    /// Applies webcam defects to the right image.
    pub fn degrade(&mut self, d: &Degradation) {
        crate::synthetic::degrade(
            &mut self.right,
            self.width,
            d.gain,
            d.offset,
            d.noise_sigma,
            d.vertical_shift_px,
            d.seed,
        );
    }

    /// Shifts the right image down by `rows` (negative: up), repeating the edge rows: a right
    /// camera mounted lower than the left (`hvs eval --vshift`).
    pub fn shift_right(&mut self, rows: i32) {
        let mut out = vec![0u8; self.right.len()];
        if let Ok(view) = ImageView::new(&self.right, self.width, self.height) {
            crate::rowalign::apply_shift(view, -(rows as f32), &mut out);
            self.right = out;
        }
    }

    /// A stereo config for this scene: `base` with the scene's search range.
    pub fn config(&self, base: &StereoConfig) -> StereoConfig {
        StereoConfig {
            min_disp: self.min_disp,
            max_disp: self.max_disp,
            ..base.clone()
        }
    }
}

/// Error rates of one disparity map.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Score {
    /// Scored pixels.
    pub scored_px: u64,
    /// % of scored pixels invalid or off by more than 1 px.
    pub bad1_pct: f64,
    /// % of scored pixels invalid or off by more than 2 px.
    pub bad2_pct: f64,
    /// % of scored pixels with a valid estimate.
    pub density_pct: f64,
    /// % of the valid estimates off by more than 2 px (accuracy of what is claimed).
    pub wrong2_of_valid_pct: f64,
}

/// Scores an estimate (1/256 px, 0 = invalid) against ground truth on the scored pixels.
pub fn score(gt_q8: &[u16], scored: &[bool], estimate_q8: &[u16]) -> Score {
    let (mut n, mut bad1, mut bad2, mut valid, mut wrong2) = (0u64, 0u64, 0u64, 0u64, 0u64);
    for ((&g, &s), &e) in gt_q8.iter().zip(scored).zip(estimate_q8) {
        if !s || g == 0 {
            continue;
        }
        n += 1;
        if e == 0 {
            bad1 += 1;
            bad2 += 1;
            continue;
        }
        valid += 1;
        let err = (e as f64 - g as f64).abs() / DISPARITY_SCALE as f64;
        if err > 1.0 {
            bad1 += 1;
        }
        if err > 2.0 {
            bad2 += 1;
            wrong2 += 1;
        }
    }
    let pct = |a: u64, b: u64| {
        if b == 0 {
            0.0
        } else {
            100.0 * a as f64 / b as f64
        }
    };
    Score {
        scored_px: n,
        bad1_pct: pct(bad1, n),
        bad2_pct: pct(bad2, n),
        density_pct: pct(valid, n),
        wrong2_of_valid_pct: pct(wrong2, valid),
    }
}

/// One scene's result.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SceneResult {
    /// Scene name.
    pub scene: String,
    /// Scored region (`nonocc` or `all`).
    pub region: &'static str,
    /// Error rates.
    #[serde(flatten)]
    pub score: Score,
    /// Median matching time, ms.
    pub ms_per_frame: f64,
    /// The row alignment's tracked offset, px (`None`: off, or no estimate).
    pub row_shift_px: Option<f32>,
    /// The estimate (not serialised).
    #[serde(skip)]
    pub estimate_q8: Vec<u16>,
}

/// Runs `base` (with the scene's search range) on a scene `repeats` times and scores it.
pub fn evaluate(
    base: &StereoConfig,
    scene: &Scene,
    repeats: usize,
) -> Result<SceneResult, EvalError> {
    let stereo_err = |source| EvalError::Stereo {
        scene: scene.name.clone(),
        source,
    };
    let config = scene.config(base);
    let mut matcher = matcher_for(&config).map_err(stereo_err)?;
    let left = ImageView::new(&scene.left, scene.width, scene.height).map_err(stereo_err)?;
    let right = ImageView::new(&scene.right, scene.width, scene.height).map_err(stereo_err)?;
    let mut out = vec![0u16; scene.width * scene.height];
    let mut times = Vec::with_capacity(repeats.max(1));
    let mut row_shift_px = None;
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let stats = matcher.compute(left, right, &mut out).map_err(stereo_err)?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
        row_shift_px = stats.row_align.and_then(|r| r.shift_px);
    }
    times.sort_by(f64::total_cmp);
    Ok(SceneResult {
        scene: scene.name.clone(),
        region: scene.region,
        score: score(&scene.gt_q8, &scene.scored, &out),
        ms_per_frame: times[times.len() / 2],
        row_shift_px,
        estimate_q8: out,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn score_counts_invalid_as_bad_and_ignores_unscored() {
        let q = |d: f32| (d * 256.0) as u16;
        let gt = [q(10.0), q(10.0), q(10.0), q(10.0), 0, q(5.0)];
        let scored = [true, true, true, true, true, false];
        let est = [q(10.5), q(11.5), q(12.5), 0, q(3.0), 0];
        let s = score(&gt, &scored, &est);
        assert_eq!(s.scored_px, 4);
        assert!((s.bad1_pct - 75.0).abs() < 1e-9, "{s:?}"); // 11.5, 12.5, invalid
        assert!((s.bad2_pct - 50.0).abs() < 1e-9, "{s:?}"); // 12.5, invalid
        assert!((s.density_pct - 75.0).abs() < 1e-9);
        assert!((s.wrong2_of_valid_pct - 100.0 / 3.0).abs() < 1e-9);
    }

    #[test]
    fn disparity_png_round_trips() {
        let dir = std::env::temp_dir().join(format!("hvs-eval-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("d.png");
        let d: Vec<u16> = (0..12).map(|i| i * 1000).collect();
        write_disparity_png(&path, &d, 4, 3).unwrap();
        assert_eq!(read_disparity_png(&path).unwrap(), (d, 4, 3));
        let err = read_grey(&dir.join("missing.png")).unwrap_err().to_string();
        assert!(err.contains("missing.png"), "{err}");
        std::fs::write(dir.join("corrupt.png"), b"not a png").unwrap();
        let err = read_grey(&dir.join("corrupt.png")).unwrap_err().to_string();
        assert!(err.contains("corrupt.png"), "{err}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
