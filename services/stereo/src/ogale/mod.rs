//! Ogale & Aloimonos "shape and stereo correspondence", the matcher the reference robot used.
//!
//! Two readings of the method are implemented (`docs/ogale.md` lists every choice made):
//!
//! - [`OgaleVariant::Components`] (the default; the IJCV 2005 / thesis description): for every
//!   hypothesis a binary match map `M(p) = [BT(p) <= match_threshold]`; matching neighbours are
//!   linked horizontally always and vertically only where no horizontal edge of the left image
//!   separates them; the goodness of a pixel is the size of its connected component, found with
//!   a run-length union-find (runs of matches in a row are the nodes, not pixels).
//! - [`OgaleVariant::Diffusion`] (the released OpenVis3D code): a soft match
//!   `exp(-alpha/255 * BT)` diffused along rows and columns; goodness = row support x column
//!   support, a cross-shaped stand-in for the component size.
//!
//! Both share the rest. Horizontal slant is handled with stretch factors: for every factor `m`
//! the right image is resampled at `m * x'` (linear interpolation) and matched with integer
//! shifts `s`, so hypothesis `(m, s)` pairs left `x` with right `m * (x - s)`: the slanted
//! plane `d(x) = (1 - m) * x + m * s`. Every left pixel keeps the hypothesis with the largest
//! goodness under a greedy two-sided uniqueness (it takes a hypothesis only if its goodness
//! beats both its own best and what its right partner has already granted), then an ambiguity
//! test (`uniqueness_pct`), an optional subpixel fit, OpenVis3D's 3x3 median, the left-right
//! check that marks occlusions, and the speckle filter.

use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;

use crate::equalize::equalize_right;
use crate::post::{lr_check, median3x3, speckle_filter};
use crate::{ImageView, MatchStats, StereoError, StereoMatcher, check_fits, check_pair};

mod components;
mod cost;
mod diffusion;
mod params;
mod prepare;
#[cfg(test)]
mod tests;
mod wta;

use components::Components;
use diffusion::Diffusion;
pub use diffusion::{CENSUS_BETA, DIFFUSION_ALPHA, DIFFUSION_MIN_GOODNESS};
pub use params::{
    DEFAULT_EQUALIZATION, DEFAULT_VARIANT, DEFAULT_VERTICAL_SEARCH_PX, Equalization, MAX_STRETCH,
    MAX_VERTICAL_SEARCH_PX, MIN_STRETCH, MatchFunction, OgaleParams, OgaleVariant,
};
use prepare::{Prepared, equalize_mean_std};
use wta::{NO_DISP, Wta};

/// Apply OpenVis3D's 3x3 median to the left and right disparity maps before the left-right
/// check (invalid pixels take part as 0). It removes the isolated pixels that missed their true
/// hypothesis and took whatever component held them.
pub const MEDIAN_BEFORE_LR: bool = true;

/// Widest image accepted (runs store columns as `u16`).
const MAX_WIDTH_PX: usize = u16::MAX as usize;

/// Ogale & Aloimonos matcher with reusable scratch buffers.
#[derive(Debug)]
pub struct OgaleMatcher {
    params: OgaleParams,
    right_eq: Vec<u8>,
    prep: Prepared,
    wta: Wta,
    cc: Components,
    diff: Diffusion,
    right_q8: Vec<u16>,
    median: Vec<u16>,
    labels: Vec<u32>,
    stack: Vec<u32>,
}

impl OgaleMatcher {
    /// Builds the matcher from a config section (see [`OgaleParams::from_config`]).
    pub fn from_config(config: &StereoConfig) -> Result<Self, StereoError> {
        Self::new(OgaleParams::from_config(config))
    }

    /// Creates a matcher; fails on an empty or too large disparity range or a bad parameter.
    pub fn new(params: OgaleParams) -> Result<Self, StereoError> {
        params.validate()?;
        Ok(Self {
            params,
            right_eq: Vec::new(),
            prep: Prepared::default(),
            wta: Wta::default(),
            cc: Components::default(),
            diff: Diffusion::default(),
            right_q8: Vec::new(),
            median: Vec::new(),
            labels: Vec::new(),
            stack: Vec::new(),
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &OgaleParams {
        &self.params
    }

    /// Winner-take-all result to the output map: ambiguity test, subpixel fit, 3x3 median,
    /// left-right check (occlusions), speckle filter.
    fn finish(&mut self, left: &[u8], out_q8: &mut [u16]) -> MatchStats {
        let p = &self.params;
        let (w, h) = (self.prep.w, self.prep.h);
        let keep = |best: f32, second: f32| -> bool {
            best > 0.0
                && (p.uniqueness_pct == 0
                    || second * 100.0 < best * (100 - p.uniqueness_pct) as f32)
        };
        // Left of this column fewer than two rival disparities fit in the image, so the
        // ambiguity test cannot be made: those pixels stay invalid.
        let x_min = if p.uniqueness_pct > 0 {
            p.min_disp as usize + (self.wta.rival_q8 / 256) as usize + 1
        } else {
            0
        };
        for (i, o) in out_q8.iter_mut().enumerate() {
            let b = self.wta.left[i];
            *o = if i % w >= x_min && keep(b.g, b.second) {
                let mut d = b.d as f32;
                if p.subpixel {
                    let hyp = &self.prep.hyps[b.h as usize];
                    d -= 256.0 * self.prep.subpixel_offset(left, hyp, i % w, i / w);
                }
                d.round().clamp(1.0, u16::MAX as f32) as u16
            } else {
                0
            };
        }
        if MEDIAN_BEFORE_LR {
            self.median.resize(out_q8.len(), 0);
            median3x3(out_q8, w, h, &mut self.median);
            out_q8.copy_from_slice(&self.median);
        }
        if p.lr_check {
            self.right_q8.clear();
            self.right_q8.extend(self.wta.right.iter().map(|r| {
                if r.d == NO_DISP {
                    0
                } else {
                    r.d.clamp(1, u16::MAX as i32) as u16
                }
            }));
            if MEDIAN_BEFORE_LR {
                self.median.resize(out_q8.len(), 0);
                median3x3(&self.right_q8, w, h, &mut self.median);
                std::mem::swap(&mut self.right_q8, &mut self.median);
            }
            lr_check(out_q8, &self.right_q8, w, p.lr_max_diff_px);
        }
        if p.speckle_window_px > 0 {
            speckle_filter(
                out_q8,
                w,
                h,
                p.speckle_window_px as usize,
                p.speckle_range_px,
                &mut self.labels,
                &mut self.stack,
            );
        }
        MatchStats {
            valid_px: out_q8.iter().filter(|&&d| d != 0).count() as u32,
            row_align: None,
        }
    }
}

impl StereoMatcher for OgaleMatcher {
    fn algorithm(&self) -> StereoAlgorithm {
        StereoAlgorithm::Ogale
    }

    fn compute(
        &mut self,
        left: ImageView<'_>,
        right: ImageView<'_>,
        out_q8: &mut [u16],
    ) -> Result<MatchStats, StereoError> {
        check_pair(&left, &right, out_q8.len())?;
        // The views' fields are public: make sure the buffers really hold the pixels.
        ImageView::new(left.data, left.width, left.height)?;
        ImageView::new(right.data, right.width, right.height)?;
        let (w, h) = (left.width, left.height);
        let p = &self.params;
        check_fits(&left, p.max_disp, 1)?;
        if w > MAX_WIDTH_PX {
            return Err(StereoError::ImageTooWide {
                width: w,
                max_width: MAX_WIDTH_PX,
            });
        }
        let n = w * h;
        self.right_eq.resize(n, 0);
        match p.equalization {
            Equalization::Off => self.right_eq.copy_from_slice(right.data),
            Equalization::SumRatio => {
                equalize_right(left.data, right.data, &mut self.right_eq);
            }
            Equalization::MeanStd => equalize_mean_std(left.data, right.data, &mut self.right_eq),
        }
        self.prep.prepare(left.data, &self.right_eq, w, h, p);
        let max_stretch = self.prep.right.iter().map(|r| r.m).fold(1.0f32, f32::max);
        self.wta.reset(n, max_stretch);
        match p.variant {
            OgaleVariant::Components => {
                let thr = match p.match_fn {
                    MatchFunction::Census => p.match_threshold as u16,
                    _ => (4 * p.match_threshold) as u16,
                };
                for hi in 0..self.prep.hyps.len() {
                    self.cc
                        .run(&self.prep, hi, thr, p.cut_horizontal_edges, &mut self.wta);
                }
            }
            OgaleVariant::Diffusion => {
                self.diff.prepare_lut(p.match_fn);
                for hi in 0..self.prep.hyps.len() {
                    self.diff.run(&self.prep, hi, &mut self.wta);
                }
            }
        }
        Ok(self.finish(left.data, out_q8))
    }
}
