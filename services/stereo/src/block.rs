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
//! and without webcam defects on the right image; the `datasets` tests of this file), the
//! config defaults (window 9, texture threshold 4, uniqueness 10 %) leave 40-50 % of the scored
//! pixels of the clean scenes invalid; the texture threshold alone adds 23-32 points of bad-2
//! there. Recommended, per cost:
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
use crate::post::{lr_check, parabola_offset, speckle_filter, to_q8};
use crate::{
    ImageView, MatchStats, StereoError, StereoMatcher, bad_parameter, check_fits, check_pair,
    check_range, check_uniqueness,
};

/// Largest searchable disparity: a map in 1/256 px (`u16`) holds `255 * 256` but not
/// `256 * 256`.
pub const MAX_DISPARITY: u32 = 255;

/// The matching cost of a block matcher.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockCost {
    /// Sum of absolute differences of grey values.
    Sad,
    /// Sum of squared differences of grey values.
    Ssd,
    /// Zero-mean normalised cross-correlation (minimises `1 - ZNCC`).
    Ncc,
    /// Sum of the Hamming distances of census strings over a `width x height` census window.
    Census {
        /// Census window width (odd).
        width: u32,
        /// Census window height (odd; at most 33 pixels in the census window).
        height: u32,
    },
}

impl BlockCost {
    /// The algorithm code of this cost.
    pub fn algorithm(&self) -> StereoAlgorithm {
        match self {
            Self::Sad => StereoAlgorithm::BmSad,
            Self::Ssd => StereoAlgorithm::BmSsd,
            Self::Ncc => StereoAlgorithm::BmNcc,
            Self::Census { .. } => StereoAlgorithm::BmCensus,
        }
    }

    /// The cost a config names; an error when `config.algorithm` is not a block matcher.
    pub fn from_config(config: &StereoConfig) -> Result<Self, StereoError> {
        Ok(match config.algorithm {
            StereoAlgorithm::BmSad => Self::Sad,
            StereoAlgorithm::BmSsd => Self::Ssd,
            StereoAlgorithm::BmNcc => Self::Ncc,
            StereoAlgorithm::BmCensus => Self::Census {
                width: config.bm.census_width,
                height: config.bm.census_height,
            },
            other => {
                return bad_parameter(
                    "algorithm",
                    format!("{other:?} is not a block-matching algorithm"),
                );
            }
        })
    }
}

/// How the winning disparity is refined below one pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SubpixelFit {
    /// Whole pixels only.
    Off,
    /// Parabola through the costs at `d - 1`, `d`, `d + 1` ([`crate::post::parabola_offset`]).
    Parabola,
    /// OpenCV StereoBM's "V" (equiangular) fit: two lines of equal and opposite slope.
    Equiangular,
}

impl SubpixelFit {
    /// The fit used with `cost` when a config asks for subpixel: V for the L1-like SAD and
    /// census costs, the parabola for SSD and NCC.
    pub fn default_for(cost: BlockCost) -> Self {
        match cost {
            BlockCost::Sad | BlockCost::Census { .. } => Self::Equiangular,
            BlockCost::Ssd | BlockCost::Ncc => Self::Parabola,
        }
    }

    /// Offset in `[-0.5, 0.5]` of the minimum from the middle sample (0 when the three costs
    /// are not convex).
    pub fn offset(self, c_minus: f32, c0: f32, c_plus: f32) -> f32 {
        match self {
            Self::Off => 0.0,
            Self::Parabola => parabola_offset(c_minus, c0, c_plus),
            Self::Equiangular => {
                let rise = c_minus.max(c_plus) - c0;
                if rise > 0.0 {
                    ((c_minus - c_plus) / (2.0 * rise)).clamp(-0.5, 0.5)
                } else {
                    0.0
                }
            }
        }
    }
}

/// Block-matching parameters.
#[derive(Debug, Clone, PartialEq)]
pub struct BlockParams {
    /// The matching cost.
    pub cost: BlockCost,
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive; at most [`MAX_DISPARITY`]).
    pub max_disp: u32,
    /// Window size (odd, 3..=31).
    pub window: u32,
    /// Apply the reference equalisation ([`equalize_right`]) to the right image first.
    pub equalize: bool,
    /// Keep a match only if its cost is this many percent below every match more than one
    /// disparity away (0 disables; below 100).
    pub uniqueness_pct: u32,
    /// Minimum mean `|L(x+1) - L(x-1)|` over the left window, grey levels; flatter windows are
    /// invalid (0 disables).
    pub texture_threshold: u32,
    /// Left-right consistency check.
    pub lr_check: bool,
    /// Allowed left-right disagreement, whole px.
    pub lr_max_diff_px: u32,
    /// Subpixel refinement.
    pub subpixel: SubpixelFit,
    /// Speckle filter: regions of at most this many pixels are removed (0 disables).
    pub speckle_window_px: u32,
    /// Speckle filter: neighbours within this many px belong to one region.
    pub speckle_range_px: u32,
    /// Horizontal stripes computed in parallel threads (1 = on the caller's thread).
    pub threads: usize,
}

impl Default for BlockParams {
    /// SAD over 9..=55 with the config's defaults.
    fn default() -> Self {
        Self::new(BlockCost::Sad, 9, 55)
    }
}

impl BlockParams {
    /// Parameters for `cost` over `min_disp..=max_disp`: the classic block-matching starting
    /// point (window 9, uniqueness 10 %, texture 4) with the refinements of
    /// [`StereoConfig::default`] (equalisation, LR check within 1 px, subpixel, speckles of up
    /// to 40 px within 1 px). The config's own defaults (window 15, uniqueness 5 %, texture 0)
    /// are the ones measured best on Middlebury (docs/stereo.md); see also [`Self::recommended`].
    pub fn new(cost: BlockCost, min_disp: u32, max_disp: u32) -> Self {
        let config = StereoConfig::default();
        Self {
            cost,
            min_disp,
            max_disp,
            window: 9,
            equalize: config.equalize,
            uniqueness_pct: 10,
            texture_threshold: 4,
            lr_check: config.lr_check,
            lr_max_diff_px: config.lr_max_diff_px,
            subpixel: if config.subpixel {
                SubpixelFit::default_for(cost)
            } else {
                SubpixelFit::Off
            },
            speckle_window_px: config.speckle_window_px,
            speckle_range_px: config.speckle_range_px,
            threads: 1,
        }
    }

    /// [`BlockParams::new`] with the window, texture threshold and uniqueness measured best
    /// for `cost` (see the module documentation): window 15, no texture threshold, uniqueness
    /// 6 % (SAD), 15 % (SSD) or 10 % (NCC, census).
    pub fn recommended(cost: BlockCost, min_disp: u32, max_disp: u32) -> Self {
        Self {
            window: 15,
            texture_threshold: 0,
            uniqueness_pct: match cost {
                BlockCost::Sad => 6,
                BlockCost::Ssd => 15,
                BlockCost::Ncc | BlockCost::Census { .. } => 10,
            },
            ..Self::new(cost, min_disp, max_disp)
        }
    }

    /// The parameters a config section describes (one thread).
    pub fn from_config(config: &StereoConfig) -> Result<Self, StereoError> {
        let cost = BlockCost::from_config(config)?;
        Ok(Self {
            cost,
            min_disp: config.min_disp,
            max_disp: config.max_disp,
            window: config.window,
            equalize: config.equalize,
            uniqueness_pct: config.uniqueness_pct,
            texture_threshold: config.bm.texture_threshold,
            lr_check: config.lr_check,
            lr_max_diff_px: config.lr_max_diff_px,
            subpixel: if config.subpixel {
                SubpixelFit::default_for(cost)
            } else {
                SubpixelFit::Off
            },
            speckle_window_px: config.speckle_window_px,
            speckle_range_px: config.speckle_range_px,
            threads: 1,
        })
    }

    /// Checks the parameters on their own (the image size is checked per call).
    pub fn validate(&self) -> Result<(), StereoError> {
        check_range(self.min_disp, self.max_disp)?;
        if self.max_disp > MAX_DISPARITY {
            return bad_parameter(
                "max_disp",
                format!("= {} is above {MAX_DISPARITY}", self.max_disp),
            );
        }
        if self.window.is_multiple_of(2) || !(3..=31).contains(&self.window) {
            return bad_parameter(
                "window",
                format!("= {} must be odd and in 3..=31", self.window),
            );
        }
        if self.texture_threshold > 255 {
            return bad_parameter(
                "bm.texture_threshold",
                format!("= {} is above 255 grey levels", self.texture_threshold),
            );
        }
        check_uniqueness(self.uniqueness_pct)?;
        if let BlockCost::Census { width, height } = self.cost
            && (width.is_multiple_of(2)
                || height.is_multiple_of(2)
                || width * height > 33
                || width * height < 3)
        {
            return bad_parameter(
                "bm.census_width",
                format!("census window {width}x{height} must be odd by odd with 3..=33 pixels"),
            );
        }
        if !(1..=64).contains(&self.threads) {
            return bad_parameter("threads", format!("= {} must be in 1..=64", self.threads));
        }
        Ok(())
    }
}

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

// ------------------------------------------------------------------------------------------
// Per-frame preparation.

/// Box sums of `vals` over a `(2r+1)^2` window for the pixels whose window lies inside the
/// image (others 0), with running column and row sums.
fn box_sums(vals: &[i32], w: usize, h: usize, r: usize, out: &mut Vec<i32>, col: &mut Vec<i32>) {
    let win = 2 * r + 1;
    out.clear();
    out.resize(w * h, 0);
    col.clear();
    col.resize(w, 0);
    if w < win || h < win {
        return;
    }
    for y in 0..h {
        for (c, &v) in col.iter_mut().zip(&vals[y * w..(y + 1) * w]) {
            *c += v;
        }
        if y >= win {
            for (c, &v) in col.iter_mut().zip(&vals[(y - win) * w..(y - win + 1) * w]) {
                *c -= v;
            }
        }
        if y + 1 >= win {
            let row = &mut out[(y - r) * w..(y - r + 1) * w];
            let mut s: i32 = col[..win].iter().sum();
            row[r] = s;
            for x in r + 1..w - r {
                s += col[x + r] - col[x - r - 1];
                row[x] = s;
            }
        }
    }
}

/// Window sums of `|L(x+1) - L(x-1)|` (edge pixels repeated).
fn texture_into(
    left: &[u8],
    w: usize,
    h: usize,
    r: usize,
    values: &mut Vec<i32>,
    out: &mut Vec<i32>,
    col: &mut Vec<i32>,
) {
    values.clear();
    for row in left.chunks_exact(w) {
        for x in 0..w {
            let a = row[x.saturating_sub(1)] as i32;
            let b = row[(x + 1).min(w - 1)] as i32;
            values.push((a - b).abs());
        }
    }
    box_sums(values, w, h, r, out, col);
}

/// Scratch for the NCC window statistics.
struct NccScratch<'a> {
    values: &'a mut Vec<i32>,
    sum: &'a mut Vec<i32>,
    sq: &'a mut Vec<i32>,
    col: &'a mut Vec<i32>,
}

impl NccScratch<'_> {
    /// Per-pixel window sums `S = sum(I - 128)` and `1 / sqrt(n * sum((I - 128)^2) - S^2)` (0
    /// for a window of under a quarter grey level of standard deviation).
    fn compute(
        &mut self,
        img: &[u8],
        w: usize,
        h: usize,
        r: usize,
        sum_out: &mut Vec<f32>,
        inv_out: &mut Vec<f32>,
    ) {
        let area = ((2 * r + 1) * (2 * r + 1)) as i64;
        self.values.clear();
        self.values.extend(img.iter().map(|&p| p as i32 - 128));
        box_sums(self.values, w, h, r, self.sum, self.col);
        for v in self.values.iter_mut() {
            *v *= *v;
        }
        box_sums(self.values, w, h, r, self.sq, self.col);
        sum_out.clear();
        inv_out.clear();
        let flat = area * area / 4;
        for (&s, &q) in self.sum.iter().zip(self.sq.iter()) {
            let var_n = area * q as i64 - (s as i64) * (s as i64);
            sum_out.push(s as f32);
            inv_out.push(if var_n > flat {
                (1.0 / (var_n as f64).sqrt()) as f32
            } else {
                0.0
            });
        }
    }
}

// ------------------------------------------------------------------------------------------
// The kernel: generic over the per-pixel term and the accumulator type.

/// Lanes of the fixed-size chunks the inner loops work on (16 x u16 = one AVX2 register).
const LANES: usize = 16;

/// A per-pixel matching term between a left and a right feature.
trait Term: Send + Sync + 'static {
    /// Per-pixel feature: a grey value or a census string.
    type F: Feature;
    /// The term in the accumulator type; for NCC a signed product as wrapping `u32`.
    fn term<A: Acc>(l: Self::F, r: Self::F) -> A;
}

struct SadTerm;
struct SsdTerm;
struct NccTerm;
struct CensusTerm;

impl Term for SadTerm {
    type F = u8;
    #[inline(always)]
    fn term<A: Acc>(l: u8, r: u8) -> A {
        // Byte-wide max - min, then widened to the accumulator: 16 lanes a vector for u16.
        A::from_u8(l.abs_diff(r))
    }
}

impl Term for SsdTerm {
    type F = u8;
    #[inline(always)]
    fn term<A: Acc>(l: u8, r: u8) -> A {
        // |d| <= 255, so d^2 <= 65025 fits 16 bits: a 16-bit multiply, then widened.
        let d = l as i16 - r as i16;
        A::from_u32(d.wrapping_mul(d) as u16 as u32)
    }
}

impl Term for NccTerm {
    type F = u8;
    #[inline(always)]
    fn term<A: Acc>(l: u8, r: u8) -> A {
        A::from_u32(((l as i32 - 128) * (r as i32 - 128)) as u32)
    }
}

impl Term for CensusTerm {
    type F = u32;
    #[inline(always)]
    fn term<A: Acc>(l: u32, r: u32) -> A {
        A::from_u8(crate::census::hamming(l, r) as u8)
    }
}

/// An accumulator type of the running sums (wrapping arithmetic; true sums always fit).
trait Acc: Copy + Ord + Default + Send + Sync + std::fmt::Debug + 'static {
    const MAX: Self;
    fn from_u8(v: u8) -> Self;
    fn from_u32(v: u32) -> Self;
    fn or(self, o: Self) -> Self;
    fn to_u32(self) -> u32;
    fn wadd(self, o: Self) -> Self;
    fn wsub(self, o: Self) -> Self;
    fn pick<'a>(a16: &'a mut AccBufs<u16>, a32: &'a mut AccBufs<u32>) -> &'a mut AccBufs<Self>;
}

impl Acc for u16 {
    const MAX: Self = u16::MAX;
    #[inline(always)]
    fn from_u8(v: u8) -> Self {
        v as u16
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self | o
    }
    #[inline(always)]
    fn from_u32(v: u32) -> Self {
        v as u16
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self as u32
    }
    #[inline(always)]
    fn wadd(self, o: Self) -> Self {
        self.wrapping_add(o)
    }
    #[inline(always)]
    fn wsub(self, o: Self) -> Self {
        self.wrapping_sub(o)
    }
    fn pick<'a>(a16: &'a mut AccBufs<u16>, _: &'a mut AccBufs<u32>) -> &'a mut AccBufs<u16> {
        a16
    }
}

impl Acc for u32 {
    const MAX: Self = u32::MAX;
    #[inline(always)]
    fn from_u8(v: u8) -> Self {
        v as u32
    }
    #[inline(always)]
    fn or(self, o: Self) -> Self {
        self | o
    }
    #[inline(always)]
    fn from_u32(v: u32) -> Self {
        v
    }
    #[inline(always)]
    fn to_u32(self) -> u32 {
        self
    }
    #[inline(always)]
    fn wadd(self, o: Self) -> Self {
        self.wrapping_add(o)
    }
    #[inline(always)]
    fn wsub(self, o: Self) -> Self {
        self.wrapping_sub(o)
    }
    fn pick<'a>(_: &'a mut AccBufs<u16>, a32: &'a mut AccBufs<u32>) -> &'a mut AccBufs<u32> {
        a32
    }
}

/// A per-pixel feature type.
trait Feature: Copy + Default + Send + Sync + 'static {
    fn pick<'a>(f8: &'a mut FeatBufs<u8>, f32: &'a mut FeatBufs<u32>) -> &'a mut FeatBufs<Self>;
}

impl Feature for u8 {
    fn pick<'a>(f8: &'a mut FeatBufs<u8>, _: &'a mut FeatBufs<u32>) -> &'a mut FeatBufs<u8> {
        f8
    }
}

impl Feature for u32 {
    fn pick<'a>(_: &'a mut FeatBufs<u8>, f32: &'a mut FeatBufs<u32>) -> &'a mut FeatBufs<u32> {
        f32
    }
}

/// Running-sum buffers of one stripe.
#[derive(Debug, Default)]
struct AccBufs<A> {
    /// Column sums, `w x dp`, disparity innermost.
    col: Vec<A>,
    /// Row (window) sums at the current pixel, `dp`.
    row: Vec<A>,
    /// NCC costs at the current pixel, `dp`.
    cost: Vec<A>,
    /// WTA masks.
    masks: Masks<A>,
}

/// Reversed, padded right rows of one stripe.
#[derive(Debug, Default)]
struct FeatBufs<F> {
    new: Vec<F>,
    old: Vec<F>,
}

/// Scratch of one stripe (one thread).
#[derive(Debug, Default)]
struct Stripe {
    a16: AccBufs<u16>,
    a32: AccBufs<u32>,
    f8: FeatBufs<u8>,
    f32: FeatBufs<u32>,
    right_sum: Vec<f32>,
    right_inv: Vec<f32>,
    /// Lowest packed cost `cost << 8 | k` of each right pixel of the current row, indexed
    /// `w - 1 - xr`: `LANES` partial minima (left pixels `x` with `x % LANES == p` go to part
    /// `p`), each `w + dp` long.
    right_parts: Vec<u32>,
}

#[derive(Debug, Clone, Copy)]
struct Geometry {
    w: usize,
    h: usize,
    r: usize,
    dmin: usize,
    /// Number of disparities.
    nd: usize,
    /// `nd` rounded up to whole chunks.
    dp: usize,
}

#[derive(Debug, Clone, Copy)]
struct Checks<'a> {
    texture: Option<(&'a [i32], i32)>,
    uniqueness_pct: u32,
    lr: bool,
    fit: SubpixelFit,
    avx2: bool,
}

#[derive(Debug, Clone, Copy)]
struct NccStats<'a> {
    area: f32,
    left_sum: &'a [f32],
    left_inv: &'a [f32],
    right_sum: &'a [f32],
    right_inv: &'a [f32],
}

/// Everything a stripe reads.
struct Job<'a, F> {
    geom: Geometry,
    /// Right shift that makes every cost fit 24 bits when packed with its disparity index.
    pack_shift: u32,
    checks: Checks<'a>,
    left: &'a [F],
    right: &'a [F],
    ncc: Option<NccStats<'a>>,
}

/// Full-image outputs: integer disparity (q8), subpixel offset (1/256 px), right map (q8).
struct Outputs<'a> {
    disp: &'a mut [u16],
    offsets: &'a mut [i16],
    right: &'a mut [u16],
}

/// Rows `y0..` of the outputs given to one stripe.
struct Part<'a> {
    y0: usize,
    disp: &'a mut [u16],
    offsets: &'a mut [i16],
    right: &'a mut [u16],
}

/// Splits the output rows `r..h-r` into stripes and runs them (in parallel when there are
/// several).
fn run<T: Term, A: Acc>(job: &Job<'_, T::F>, stripes: &mut [Stripe], outs: Outputs<'_>) {
    let Geometry { w, h, r, .. } = job.geom;
    let rows = h - 2 * r;
    let threads = stripes.len().clamp(1, rows.max(1));
    let per = rows.div_ceil(threads);
    let (mut disp, mut offsets, mut right) = (
        &mut outs.disp[r * w..(h - r) * w],
        &mut outs.offsets[r * w..(h - r) * w],
        &mut outs.right[r * w..(h - r) * w],
    );
    let mut y0 = r;
    std::thread::scope(|scope| {
        for (i, stripe) in stripes.iter_mut().take(threads).enumerate() {
            let n = per.min(disp.len() / w) * w;
            let (d, d_rest) = std::mem::take(&mut disp).split_at_mut(n);
            let (o, o_rest) = std::mem::take(&mut offsets).split_at_mut(n);
            let (rr, r_rest) = std::mem::take(&mut right).split_at_mut(n);
            (disp, offsets, right) = (d_rest, o_rest, r_rest);
            let part = Part {
                y0,
                disp: d,
                offsets: o,
                right: rr,
            };
            y0 += n / w;
            if n == 0 {
                continue;
            }
            if i + 1 == threads {
                run_stripe::<T, A>(job, stripe, part);
            } else {
                scope.spawn(move || run_stripe::<T, A>(job, stripe, part));
            }
        }
    });
}

/// Runs one stripe with the AVX2 build of the kernel when the CPU has it.
fn run_stripe<T: Term, A: Acc>(job: &Job<'_, T::F>, stripe: &mut Stripe, part: Part<'_>) {
    #[cfg(target_arch = "x86_64")]
    if job.checks.avx2 {
        // SAFETY: `checks.avx2` is only set when `crate::cpu::avx2_popcnt` found AVX2 and
        // POPCNT on this CPU.
        unsafe { stripe_avx2::<T, A>(job, stripe, part) };
        return;
    }
    stripe_rows::<T, A>(job, stripe, part);
}

/// [`stripe_rows`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
fn stripe_avx2<T: Term, A: Acc>(job: &Job<'_, T::F>, stripe: &mut Stripe, part: Part<'_>) {
    stripe_rows::<T, A>(job, stripe, part);
}

/// Copies `src` reversed into the front of `dst` (the rest is padding).
#[inline(always)]
fn reverse_into<F: Copy>(src: &[F], dst: &mut [F]) {
    for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
        *d = *s;
    }
}

/// A left row and a reversed right row.
type RowPair<'a, F> = (&'a [F], &'a [F]);

/// Adds the terms of one image row to the column sums (`sub = None`), or adds one row and
/// subtracts another. `rev_*` are reversed right rows: `R(x - dmin - k) = rev[w - 1 - x + dmin + k]`.
#[inline(always)]
fn update_columns<T: Term, A: Acc>(
    col: &mut [A],
    g: &Geometry,
    left_new: &[T::F],
    rev_new: &[T::F],
    sub: Option<RowPair<'_, T::F>>,
) {
    let (w, dp, dmin) = (g.w, g.dp, g.dmin);
    // Columns left of dmin are never inside a window with a valid disparity.
    for (x, c) in col.chunks_exact_mut(dp).enumerate().skip(dmin) {
        let m = w - 1 - x + dmin;
        let rn = &rev_new[m..m + dp];
        let ln = left_new[x];
        match sub {
            None => {
                for (c, &r) in c.iter_mut().zip(rn) {
                    *c = c.wadd(T::term(ln, r));
                }
            }
            Some((left_old, rev_old)) => {
                let ro = &rev_old[m..m + dp];
                let lo = left_old[x];
                for ((c, &r), &q) in c.iter_mut().zip(rn).zip(ro) {
                    *c = c.wadd(T::term(ln, r)).wsub(T::term(lo, q));
                }
            }
        }
    }
}

// The WTA helpers run over the whole padded disparity row (a multiple of `LANES`), so that
// they are straight vector code with no scalar remainder; entries that must not count are
// OR-ed with an all-ones mask, which makes them `MAX`. A mask for "the first n entries" is a
// window into `[0; dp] ++ [MAX; dp]` (see [`Masks`]).

/// Lowest of `cost[k] | mask[k]`.
#[inline(always)]
fn masked_min<A: Acc>(cost: &[A], mask: &[A]) -> A {
    let mut acc = [A::MAX; LANES];
    for (c, m) in cost.chunks_exact(LANES).zip(mask.chunks_exact(LANES)) {
        for i in 0..LANES {
            acc[i] = acc[i].min(c[i].or(m[i]));
        }
    }
    acc.into_iter().fold(A::MAX, A::min)
}

/// Lowest of `cost[k] | m1[k] | m2[k]`.
#[inline(always)]
fn masked_min2<A: Acc>(cost: &[A], m1: &[A], m2: &[A]) -> A {
    let mut acc = [A::MAX; LANES];
    for ((c, a), b) in cost
        .chunks_exact(LANES)
        .zip(m1.chunks_exact(LANES))
        .zip(m2.chunks_exact(LANES))
    {
        for i in 0..LANES {
            acc[i] = acc[i].min(c[i].or(a[i]).or(b[i]));
        }
    }
    acc.into_iter().fold(A::MAX, A::min)
}

/// Index of the first `k` with `cost[k] | mask[k] == value` (0 if none).
#[inline(always)]
fn first_index<A: Acc>(cost: &[A], mask: &[A], value: A) -> usize {
    for (j, (c, m)) in cost
        .chunks_exact(LANES)
        .zip(mask.chunks_exact(LANES))
        .enumerate()
    {
        let mut bits = 0u32;
        for i in 0..LANES {
            bits |= u32::from(c[i].or(m[i]) == value) << i;
        }
        if bits != 0 {
            return j * LANES + bits.trailing_zeros() as usize;
        }
    }
    0
}

/// Keeps, for each right pixel on the diagonal of a left pixel, the lowest packed
/// `cost >> shift << 8 | k` so far: the lowest cost and, at ties, the smallest disparity.
/// Entries where `mask` (a `u32` limit mask) is set do not count. A plain minimum: a
/// select-and-store here would become a masked store, which is slow on some CPUs.
#[inline(always)]
fn right_update<A: Acc>(costs: &[A], index: &[u32], mask: &[u32], shift: u32, best: &mut [u32]) {
    for (((b, &c), &k), &m) in best.iter_mut().zip(costs).zip(index).zip(mask) {
        *b = (*b).min(((c.to_u32() >> shift) << 8) | k | m);
    }
}

/// Sliding-window masks for the WTA over `dp` entries.
#[derive(Debug, Default)]
struct Masks<A> {
    /// `[0; dp] ++ [MAX; dp]`: `limit(n)` is 0 for the first `n` entries, `MAX` after.
    limit: Vec<A>,
    /// The same for packed `u32` costs.
    limit32: Vec<u32>,
    /// `MAX` at `dp + 1 ..= dp + 3`, else 0: `near(kb)` is `MAX` at `kb - 1 ..= kb + 1`.
    near: Vec<A>,
    /// `0, 1, 2, ...`: the disparity index of each entry.
    index: Vec<u32>,
}

impl<A: Acc> Masks<A> {
    fn build(&mut self, dp: usize) {
        self.limit.clear();
        self.limit.resize(dp, A::default());
        self.limit.resize(2 * dp, A::MAX);
        self.limit32.clear();
        self.limit32.resize(dp, 0);
        self.limit32.resize(2 * dp, u32::MAX);
        self.near.clear();
        self.near.resize(2 * dp + 4, A::default());
        self.near[dp + 1..=dp + 3].fill(A::MAX);
        self.index.clear();
        self.index.extend(0..dp as u32);
    }

    #[inline(always)]
    fn limit(&self, n: usize, dp: usize) -> &[A] {
        &self.limit[dp - n..2 * dp - n]
    }

    #[inline(always)]
    fn limit32(&self, n: usize, dp: usize) -> &[u32] {
        &self.limit32[dp - n..2 * dp - n]
    }

    #[inline(always)]
    fn near(&self, kb: usize, dp: usize) -> &[A] {
        &self.near[dp + 2 - kb..2 * dp + 2 - kb]
    }
}

/// NCC costs `(1 - ZNCC) * 32768` (0..=65536) from the window sums of `L'R'` (as wrapping
/// `u32`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn ncc_costs<A: Acc>(
    row: &[A],
    right_sum: &[f32],
    right_inv: &[f32],
    area: f32,
    left_sum: f32,
    left_inv: f32,
    out: &mut [A],
) {
    for (((o, s), &sr), &ir) in out.iter_mut().zip(row).zip(right_sum).zip(right_inv) {
        let cov = area * (s.to_u32() as i32 as f32) - left_sum * sr;
        let z = cov * (left_inv * ir);
        // z is in [-1, 1] up to rounding. Adding 2^23 leaves the value rounded to an integer
        // in the low mantissa bits: a float-to-int conversion that vectorises.
        let c = ((1.0 - z) * 32768.0).clamp(0.0, 65536.0);
        *o = A::from_u32((c + 8_388_608.0).to_bits() - 0x4B00_0000);
    }
}

/// The output rows of one stripe.
#[inline(always)]
fn stripe_rows<T: Term, A: Acc>(job: &Job<'_, T::F>, stripe: &mut Stripe, part: Part<'_>) {
    let g = job.geom;
    let Geometry {
        w, r, dmin, nd, dp, ..
    } = g;
    let stride = w + dp;
    let Stripe {
        a16,
        a32,
        f8,
        f32,
        right_sum: rsum,
        right_inv: rinv,
        right_parts,
    } = stripe;
    let AccBufs {
        col,
        row,
        cost,
        masks,
    } = A::pick(a16, a32);
    masks.build(dp);
    let feats = T::F::pick(f8, f32);
    col.clear();
    col.resize(w * dp, A::default());
    row.resize(dp, A::default());
    cost.resize(dp, A::default());
    if job.checks.lr {
        right_parts.clear();
        right_parts.resize(LANES * stride, u32::MAX);
    }
    feats.new.resize(stride, T::F::default());
    feats.old.resize(stride, T::F::default());
    rsum.resize(stride, 0.0);
    rinv.resize(stride, 0.0);

    let Part {
        y0,
        disp,
        offsets,
        right,
    } = part;
    let rows = disp.len() / w;
    fn row_of<F>(img: &[F], w: usize, y: usize) -> &[F] {
        &img[y * w..(y + 1) * w]
    }
    let img_row = |img, y| row_of(img, w, y);
    for yy in y0 - r..=y0 + r {
        reverse_into(img_row(job.right, yy), &mut feats.new);
        update_columns::<T, A>(col, &g, img_row(job.left, yy), &feats.new, None);
    }
    let xs = r + dmin;
    let xe = w - r;
    let checks = job.checks;
    for i in 0..rows {
        let y = y0 + i;
        if i > 0 {
            reverse_into(img_row(job.right, y + r), &mut feats.new);
            reverse_into(img_row(job.right, y - r - 1), &mut feats.old);
            update_columns::<T, A>(
                col,
                &g,
                img_row(job.left, y + r),
                &feats.new,
                Some((img_row(job.left, y - r - 1), &feats.old)),
            );
        }
        if let Some(ncc) = &job.ncc {
            reverse_into(&ncc.right_sum[y * w..(y + 1) * w], rsum);
            reverse_into(&ncc.right_inv[y * w..(y + 1) * w], rinv);
        }
        let disp_row = &mut disp[i * w..(i + 1) * w];
        let off_row = &mut offsets[i * w..(i + 1) * w];
        row.fill(A::default());
        for c in col[(xs - r) * dp..(xs + r + 1) * dp].chunks_exact(dp) {
            for (s, &v) in row.iter_mut().zip(c) {
                *s = s.wadd(v);
            }
        }
        for x in xs..xe {
            if x > xs {
                let add = &col[(x + r) * dp..(x + r + 1) * dp];
                let sub = &col[(x - r - 1) * dp..(x - r) * dp];
                for ((s, &a), &b) in row.iter_mut().zip(add).zip(sub) {
                    *s = s.wadd(a).wsub(b);
                }
            }
            let at = y * w + x;
            let textured = checks.texture.is_none_or(|(t, min)| t[at] >= min);
            let defined = job.ncc.is_none_or(|s| s.left_inv[at] > 0.0);
            let usable = textured && defined;
            if !(usable || checks.lr) {
                continue;
            }
            let n = (x - xs + 1).min(nd);
            let m = w - 1 - x + dmin;
            let costs: &[A] = match &job.ncc {
                Some(s) => {
                    ncc_costs(
                        row,
                        &rsum[m..m + dp],
                        &rinv[m..m + dp],
                        s.area,
                        s.left_sum[at],
                        s.left_inv[at],
                        cost,
                    );
                    cost
                }
                None => row,
            };
            if checks.lr {
                // Consecutive pixels update different parts: an update overlapping the last
                // one shifted by one element would defeat store-to-load forwarding.
                let part = (x % LANES) * stride + m;
                right_update(
                    costs,
                    &masks.index,
                    masks.limit32(n, dp),
                    job.pack_shift,
                    &mut right_parts[part..part + dp],
                );
                if !usable {
                    continue;
                }
            }
            let limit = masks.limit(n, dp);
            let best = masked_min(costs, limit);
            let kb = first_index(costs, limit, best);
            if checks.uniqueness_pct > 0 {
                let second = masked_min2(costs, limit, masks.near(kb, dp));
                if second != A::MAX
                    && best.to_u32() as u64 * 100
                        >= second.to_u32() as u64 * (100 - checks.uniqueness_pct as u64)
                {
                    continue;
                }
            }
            disp_row[x] = (((dmin + kb) * 256) as u16).max(1);
            if checks.fit != SubpixelFit::Off && kb > 0 && kb + 1 < n {
                let off = checks.fit.offset(
                    costs[kb - 1].to_u32() as f32,
                    best.to_u32() as f32,
                    costs[kb + 1].to_u32() as f32,
                );
                off_row[x] = (off * 256.0).round() as i16;
            }
        }
        if checks.lr {
            // Right-image disparities along the diagonals: the minimum over the parts.
            let (first, rest) = right_parts.split_at_mut(stride);
            for part in rest.chunks_exact_mut(stride) {
                for (b, p) in first.iter_mut().zip(part.iter_mut()) {
                    *b = (*b).min(*p);
                    *p = u32::MAX;
                }
            }
            let right_row = &mut right[i * w..(i + 1) * w];
            for (j, b) in first[..w].iter().enumerate() {
                right_row[w - 1 - j] = if *b == u32::MAX {
                    0
                } else {
                    to_q8((dmin + (b & 0xFF) as usize) as f32)
                };
            }
            first.fill(u32::MAX);
        }
    }
}

#[cfg(test)]
mod tests {
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
}

/// Scoring on the Middlebury scenes of `../shared/datasets` (run on demand:
/// `cargo test --release -p hvs-stereo --lib block::datasets -- --ignored --nocapture`).
#[cfg(test)]
mod datasets {
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
        let (mut n, mut b1, mut b2, mut valid, mut wrong) =
            (0usize, 0usize, 0usize, 0usize, 0usize);
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
}
