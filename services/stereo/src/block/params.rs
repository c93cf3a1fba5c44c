//! The parameters of the block matcher: the matching cost, the subpixel fit and
//! [`BlockParams`] with its defaults, its reading of a config section and its validation.

use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;

use crate::post::parabola_offset;
use crate::{StereoError, bad_parameter, check_range, check_uniqueness};

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
    /// Apply the reference equalisation
    /// ([`equalize_right`](crate::equalize::equalize_right)) to the right image first.
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
