//! [`SgmParams`]: the parameters of one matcher and their rules.

use super::*;

/// Semi-global matching parameters (the stereo config plus what it has no field for).
#[derive(Debug, Clone, PartialEq)]
pub struct SgmParams {
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive, at most 255).
    pub max_disp: u32,
    /// Penalty for a 1 px disparity change between neighbours (census cost units).
    pub p1: u32,
    /// Penalty for larger changes (`p1 <= p2 <= MAX_P2`).
    pub p2: u32,
    /// Aggregation paths: 4, 5 or 8.
    pub paths: u32,
    /// Side of the block the census costs are averaged over (1, 3, 5 or 7).
    pub block: u32,
    /// Apply the reference equalisation to the right image first.
    pub equalize: bool,
    /// Smooth both images with a 3x3 box before the census transform (robustness to noise
    /// and to a vertical misalignment of about a pixel; see the module notes).
    pub prefilter: bool,
    /// A match is rejected unless its S is this many percent below every S more than one
    /// disparity away (0 disables; below 100).
    pub uniqueness_pct: u32,
    /// Left-right consistency check.
    pub lr_check: bool,
    /// Allowed left-right disagreement, px.
    pub lr_max_diff_px: u32,
    /// Subpixel fit on S (equiangular; see the module notes).
    pub subpixel: bool,
    /// Speckle filter: regions of at most this many pixels are removed (0 disables).
    pub speckle_window_px: u32,
    /// Neighbours within this many px belong to the same speckle region.
    pub speckle_range_px: u32,
    /// Fill invalid runs up to this long from the background side (0 = off).
    pub fill_invalid_px: u32,
    /// Minimum mean |horizontal gradient| of the left image over the texture window, grey
    /// levels per pixel; flatter pixels come out invalid (0 disables).
    pub texture_threshold: f32,
    /// Radius of the (square) texture window.
    pub texture_radius: u32,
}

impl SgmParams {
    /// The parameters a stereo config section describes (texture settings get their defaults).
    pub fn from_config(config: &StereoConfig) -> Self {
        Self {
            min_disp: config.min_disp,
            max_disp: config.max_disp,
            p1: config.sgm.p1,
            p2: config.sgm.p2,
            paths: config.sgm.paths,
            block: config.sgm.block,
            equalize: config.equalize,
            prefilter: true,
            uniqueness_pct: config.uniqueness_pct,
            lr_check: config.lr_check,
            lr_max_diff_px: config.lr_max_diff_px,
            subpixel: config.subpixel,
            speckle_window_px: config.speckle_window_px,
            speckle_range_px: config.speckle_range_px,
            fill_invalid_px: config.fill_invalid_px,
            texture_threshold: config.sgm.texture_threshold,
            texture_radius: config.sgm.texture_radius,
        }
    }

    /// Checks the parameters on their own (image size is checked per call).
    pub fn validate(&self) -> Result<(), StereoError> {
        check_range(self.min_disp, self.max_disp)?;
        if self.max_disp > 255 {
            return bad_parameter(
                "max_disp",
                format!("= {} must be at most 255 for sgm", self.max_disp),
            );
        }
        if !matches!(self.paths, 4 | 5 | 8) {
            return bad_parameter("sgm.paths", format!("= {} must be 4, 5 or 8", self.paths));
        }
        if !BLOCK_SIZES.contains(&self.block) {
            return bad_parameter(
                "sgm.block",
                format!("= {} must be 1, 3, 5 or 7", self.block),
            );
        }
        if self.p2 > MAX_P2 || self.p1 > self.p2 {
            return bad_parameter(
                "sgm.p2",
                format!(
                    "penalties p1 = {}, p2 = {} need p1 <= p2 <= {MAX_P2} (path costs fit a byte)",
                    self.p1, self.p2
                ),
            );
        }
        check_uniqueness(self.uniqueness_pct)?;
        if !(0.0..=64.0).contains(&self.texture_threshold) {
            return bad_parameter(
                "sgm.texture_threshold",
                format!("= {} must be in 0..=64 grey levels", self.texture_threshold),
            );
        }
        if self.texture_radius > 15 {
            return bad_parameter(
                "sgm.texture_radius",
                format!("= {} must be at most 15", self.texture_radius),
            );
        }
        Ok(())
    }
}
