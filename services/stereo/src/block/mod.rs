//! Correlation block matching, winner-take-all, with four costs over a `window x window` block:
//! the sum of absolute differences (SAD), of squared differences (SSD), zero-mean normalised
//! cross-correlation (NCC, minimised as `1 - ZNCC`) and census (the sum over the block of the
//! Hamming distances of per-pixel census strings, [`crate::census`]). The reference system
//! compared these four with a 9x9 window.
//!
//! # How a frame is computed
//!
//! The layout follows OpenCV's StereoBM: disparity is the innermost dimension, so every inner
//! loop runs over a contiguous run of disparities and the compiler vectorises it.
//!
//! - For each image column `x` a *column sum* `col[x][k]` (k = d - min_disp) holds the sum over
//!   the window's rows of the per-pixel term (`|L-R|`, `(L-R)^2`, `L'R'` or the Hamming
//!   distance) between `L(x, y)` and `R(x - d, y)`. Going down one row adds the new bottom row
//!   and subtracts the row that left the window (recomputed, not stored).
//! - Along a row a *row sum* `row[k]` slides the same way: add column `x + r`, subtract column
//!   `x - r - 1`. So one window costs O(1) per pixel and disparity, whatever its size.
//! - The right image is read through a reversed copy of each row, so `R(x - d)` for increasing
//!   `d` is a contiguous, increasing run of memory.
//! - Accumulators are `u16` where the largest window sum fits (census always; SAD up to a 15x15
//!   window), else `u32`; 16 disparities a vector with AVX2. An AVX2 build of the same generic
//!   code is picked at run time when the CPU has it (no AVX-512 assumed, stable Rust only);
//!   other CPUs run the baseline (SSE2 on x86-64) build.
//! - NCC keeps running sums of `L'R'` per disparity (`L' = L - 128`, so the sums fit `i32`); the
//!   window sums of `L'`, `L'^2`, `R'`, `R'^2` do not depend on the disparity and are box-filtered
//!   once per frame. `ZNCC = (n*SLR - SL*SR) / sqrt((n*SLL - SL^2)(n*SRR - SR^2))`, and the cost
//!   is `(1 - ZNCC) * 32768` (0..=65536). A left window with (nearly) zero variance has no
//!   defined NCC and comes out invalid.
//!
//! # Refinements (each switchable)
//!
//! - **Left border.** A left pixel `x` searches only the disparities whose right window fits:
//!   `x - d - r >= 0`. Pixels near the left edge therefore get a shorter range instead of being
//!   discarded (OpenCV discards the whole `max_disp` strip); the robot's left range window needs
//!   them. Pixels with no disparity that fits (`x < min_disp + r`) and pixels within `r` of the
//!   top, bottom or right edge are invalid. A point near the left edge whose true disparity is
//!   larger than the ones that fit is not visible in the right image at all; uniqueness and the
//!   left-right check remove most such guesses.
//! - **Texture threshold** (`bm.texture_threshold`, 0 = off): the mean over the left window of
//!   `|L(x+1, y) - L(x-1, y)|` (central difference, not halved; edge pixels repeated) must be at
//!   least the threshold, else the pixel is invalid.
//! - **Uniqueness** (`uniqueness_pct`, 0 = off), exact: with `c1` the best cost and `c2` the
//!   lowest cost among the searched disparities more than one away from the best, the pixel is
//!   kept only if `c1 * 100 < c2 * (100 - pct)`, i.e. the best is `pct` percent below every
//!   match more than one disparity away (the config's wording; OpenCV's `uniquenessRatio` u
//!   instead asks `c2 > c1 * (1 + u/100)`, so OpenCV's 15 is about our 13).
//! - **Left-right check** (`lr_check`, `lr_max_diff_px`): the right image's disparity map is
//!   taken from the same costs along the diagonals (right pixel `xr` takes the `d` with the
//!   lowest cost of left pixel `xr + d`, the smallest `d` at ties), then
//!   [`crate::post::lr_check`] compares the two whole-pixel maps, before the subpixel step. To
//!   keep this a plain vector minimum, each cost is packed with its disparity index as
//!   `cost << 8 | k`; SSD windows of 17x17 and more drop the lowest cost bits for this (only for
//!   the right map). It roughly doubles the per-pixel work.
//! - **Subpixel** ([`SubpixelFit`]): a parabola through the three costs around the best
//!   ([`crate::post::parabola_offset`]), or the "V" (equiangular) fit OpenCV's StereoBM uses:
//!   `offset = (c- - c+) / (2 * (max(c-, c+) - c0))`. From a config, SAD and census get the V
//!   fit, SSD and NCC the parabola: on slanted synthetic planes the V fit had an RMS error of
//!   0.06-0.085 px against 0.09-0.115 px for the parabola with SAD and census; for SSD and NCC the
//!   two were within 0.01 px of each other. No fit is made at the ends of a pixel's range.
//! - **Speckle filter** (`speckle_window_px`, `speckle_range_px`): [`crate::post::speckle_filter`].
//!
//! Ties go to the smallest disparity. Output: 1/256 px, 0 = invalid (see [`crate`]).
//!
//! # Settings
//!
//! Measured on Middlebury tsukuba, venus and motorcycle (bad-2 over the scored pixels, with
//! and without webcam defects on the right image; `examples/block_tables.rs`, run on demand, for this
//! module), the config defaults (window 9, texture threshold 4, uniqueness 10 %) leave
//! 40-50 % of the scored pixels of the clean scenes invalid; the texture threshold alone adds
//! 23-32 points of bad-2 there. Recommended, per cost:
//!
//! | cost | window | texture threshold | uniqueness % |
//! | --- | --- | --- | --- |
//! | SAD | 15 | 0 | 6 |
//! | SSD | 15 | 0 | 15 |
//! | NCC | 15 | 0 | 10 |
//! | census 5x5 | 15 | 0 | 10 |
//!
//! ([`BlockParams::recommended`]; config keys `window`, `bm.texture_threshold`,
//! `uniqueness_pct`.)
//!
//! A larger window lowered the mean bad-2 on these scenes (up to 21, the largest tried); 15 is a
//! compromise with the fattening of foreground objects at 320x240. Any texture threshold only
//! removed correct matches there, and on a noisy flat wall it cannot help below the camera's
//! noise floor (the mean `|L(x+1) - L(x-1)|` of pure noise of sigma `s` is about `1.13 s`):
//! uniqueness and the left-right check are what invalidate flat walls. The uniqueness values
//! keep a synthetic flat wall with noise of sigma 2 or 4 free of wrong matches (lower values
//! let 2-3 % of it through) at the least cost in bad-2.

use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;

use crate::census::census;
use crate::equalize::equalize_right;
use crate::post::{lr_check, speckle_filter};
use crate::{ImageView, MatchStats, StereoError, StereoMatcher, check_fits, check_pair};

mod costs;
mod kernel;
mod params;
mod prepare;
mod stripe;
#[cfg(test)]
mod tests;
mod wta;

use costs::{CensusTerm, NccTerm, SadTerm, SsdTerm};
pub use params::{BlockCost, BlockParams, MAX_DISPARITY, SubpixelFit};
use prepare::{NccScratch, texture_into};
use stripe::{Checks, Geometry, Job, NccStats, Outputs, Stripe, run};

/// Lanes of the fixed-size chunks the inner loops work on (16 x u16 = one AVX2 register).
const LANES: usize = 16;

/// Block matcher with reusable scratch buffers.
#[derive(Debug)]
pub struct BlockMatcher {
    params: BlockParams,
    avx2: bool,
    right_eq: Vec<u8>,
    left_census: Vec<u32>,
    right_census: Vec<u32>,
    values: Vec<i32>,
    texture: Vec<i32>,
    box_col: Vec<i32>,
    ncc_sum: Vec<i32>,
    ncc_sq: Vec<i32>,
    left_sum: Vec<f32>,
    left_inv: Vec<f32>,
    right_sum: Vec<f32>,
    right_inv: Vec<f32>,
    offsets: Vec<i16>,
    right_q8: Vec<u16>,
    labels: Vec<u32>,
    stack: Vec<u32>,
    stripes: Vec<Stripe>,
}

impl BlockMatcher {
    /// Builds the matcher from a config section (`bm-sad`, `bm-ssd`, `bm-ncc`, `bm-census`).
    pub fn from_config(config: &StereoConfig) -> Result<Self, StereoError> {
        Self::new(BlockParams::from_config(config)?)
    }

    /// Creates a matcher; fails on an empty disparity range or a bad parameter.
    pub fn new(params: BlockParams) -> Result<Self, StereoError> {
        params.validate()?;
        #[cfg(target_arch = "x86_64")]
        let avx2 = crate::cpu::avx2_popcnt();
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        Ok(Self {
            stripes: (0..params.threads).map(|_| Stripe::default()).collect(),
            params,
            avx2,
            right_eq: Vec::new(),
            left_census: Vec::new(),
            right_census: Vec::new(),
            values: Vec::new(),
            texture: Vec::new(),
            box_col: Vec::new(),
            ncc_sum: Vec::new(),
            ncc_sq: Vec::new(),
            left_sum: Vec::new(),
            left_inv: Vec::new(),
            right_sum: Vec::new(),
            right_inv: Vec::new(),
            offsets: Vec::new(),
            right_q8: Vec::new(),
            labels: Vec::new(),
            stack: Vec::new(),
        })
    }

    /// The parameters in use.
    pub fn params(&self) -> &BlockParams {
        &self.params
    }

    /// Uses (`true`) or avoids the AVX2 build of the kernels; returns whether it is used (only
    /// where the CPU has AVX2). Both give identical maps; for tests and benchmarks.
    pub fn set_simd(&mut self, on: bool) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            self.avx2 = on && crate::cpu::avx2_popcnt();
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let _ = on;
        }
        self.avx2
    }
}

impl StereoMatcher for BlockMatcher {
    fn algorithm(&self) -> StereoAlgorithm {
        self.params.cost.algorithm()
    }

    fn compute(
        &mut self,
        left: ImageView<'_>,
        right: ImageView<'_>,
        out_q8: &mut [u16],
    ) -> Result<MatchStats, StereoError> {
        check_pair(&left, &right, out_q8.len())?;
        let p = self.params.clone();
        let (w, h) = (left.width, left.height);
        check_fits(&left, p.max_disp, p.window)?;
        let n = w * h;
        let r = (p.window / 2) as usize;
        let area = (p.window * p.window) as i32;

        let right_px: &[u8] = if p.equalize {
            self.right_eq.resize(n, 0);
            equalize_right(left.data, right.data, &mut self.right_eq);
            &self.right_eq
        } else {
            right.data
        };
        // `right_px` may borrow `self.right_eq`, so the steps below take the other fields one
        // by one rather than `&mut self`.
        let texture_on = p.texture_threshold > 0;
        if texture_on {
            texture_into(
                left.data,
                w,
                h,
                r,
                &mut self.values,
                &mut self.texture,
                &mut self.box_col,
            );
        }
        if p.cost == BlockCost::Ncc {
            let mut stats = NccScratch {
                values: &mut self.values,
                sum: &mut self.ncc_sum,
                sq: &mut self.ncc_sq,
                col: &mut self.box_col,
            };
            stats.compute(left.data, w, h, r, &mut self.left_sum, &mut self.left_inv);
            stats.compute(right_px, w, h, r, &mut self.right_sum, &mut self.right_inv);
        }
        if let BlockCost::Census { width, height } = p.cost {
            let (cw, ch) = (width as usize, height as usize);
            self.left_census.resize(n, 0);
            self.right_census.resize(n, 0);
            census(left.data, w, h, cw, ch, &mut self.left_census);
            census(right_px, w, h, cw, ch, &mut self.right_census);
        }

        let nd = (p.max_disp - p.min_disp + 1) as usize;
        let geom = Geometry {
            w,
            h,
            r,
            dmin: p.min_disp as usize,
            nd,
            dp: nd.div_ceil(LANES) * LANES,
        };
        // Largest window cost, for packing costs with an 8-bit disparity index into a u32.
        let max_cost: u64 = match p.cost {
            BlockCost::Sad => area as u64 * 255,
            BlockCost::Ssd => area as u64 * 255 * 255,
            BlockCost::Ncc => 65_536,
            BlockCost::Census { width, height } => area as u64 * (width * height) as u64,
        };
        let pack_shift = (64 - max_cost.leading_zeros()).saturating_sub(24);
        let checks = Checks {
            texture: texture_on.then(|| (&self.texture[..], p.texture_threshold as i32 * area)),
            uniqueness_pct: p.uniqueness_pct,
            lr: p.lr_check,
            fit: p.subpixel,
            avx2: self.avx2,
        };
        self.offsets.clear();
        self.offsets.resize(n, 0);
        self.right_q8.clear();
        self.right_q8.resize(n, 0);
        out_q8.fill(0);
        let outs = Outputs {
            disp: out_q8,
            offsets: &mut self.offsets,
            right: &mut self.right_q8,
        };
        let stripes = &mut self.stripes;
        let grey_job = |ncc| Job {
            geom,
            pack_shift,
            checks,
            left: left.data,
            right: right_px,
            ncc,
        };
        match p.cost {
            BlockCost::Sad if area * 255 < u16::MAX as i32 => {
                run::<SadTerm, u16>(&grey_job(None), stripes, outs)
            }
            BlockCost::Sad => run::<SadTerm, u32>(&grey_job(None), stripes, outs),
            BlockCost::Ssd => run::<SsdTerm, u32>(&grey_job(None), stripes, outs),
            BlockCost::Ncc => {
                let stats = NccStats {
                    area: area as f32,
                    left_sum: &self.left_sum,
                    left_inv: &self.left_inv,
                    right_sum: &self.right_sum,
                    right_inv: &self.right_inv,
                };
                run::<NccTerm, u32>(&grey_job(Some(stats)), stripes, outs)
            }
            BlockCost::Census { .. } => run::<CensusTerm, u16>(
                &Job {
                    geom,
                    pack_shift,
                    checks,
                    left: &self.left_census,
                    right: &self.right_census,
                    ncc: None,
                },
                stripes,
                outs,
            ),
        }

        if p.lr_check {
            lr_check(out_q8, &self.right_q8, w, p.lr_max_diff_px);
        }
        if p.subpixel != SubpixelFit::Off {
            for (d, &off) in out_q8.iter_mut().zip(&self.offsets) {
                if *d != 0 && off != 0 {
                    let whole = (*d as i32 + 128) >> 8;
                    *d = (whole * 256 + off as i32).clamp(1, u16::MAX as i32) as u16;
                }
            }
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
        let valid_px = out_q8.iter().filter(|&&d| d != 0).count() as u32;
        Ok(MatchStats {
            valid_px,
            row_align: None,
        })
    }
}
