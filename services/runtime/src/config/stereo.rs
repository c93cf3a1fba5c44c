//! `[stereo.lo]` and `[stereo.hi]`: the two matchers. Their values are checked by the
//! matchers' own rules (`hvs_stereo::validate_section`), the one place those rules live.

use serde::{Deserialize, Serialize};

use hvs_shared::messages::StereoAlgorithm;

/// Stereo settings of both paths.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct StereoPaths {
    /// The 320x240 fast path.
    pub lo: StereoConfig,
    /// The 640x480 long-range path.
    pub hi: StereoConfig,
}

impl Default for StereoPaths {
    fn default() -> Self {
        Self {
            lo: StereoConfig {
                min_disp: 9,
                max_disp: 55,
                ..StereoConfig::default()
            },
            hi: StereoConfig {
                min_disp: 18,
                max_disp: 110,
                ..StereoConfig::default()
            },
        }
    }
}

/// Stereo settings of one path. Every algorithm reads the common keys; `[...bm]`, `[...sgm]`
/// and `[...ogale]` hold the settings only that family uses.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StereoConfig {
    /// The matching algorithm.
    pub algorithm: StereoAlgorithm,
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive).
    pub max_disp: u32,
    /// Block size for block matching (odd, 3..=31).
    pub window: u32,
    /// Scale the right image so its mean equals the left's before matching (reference step 2).
    pub equalize: bool,
    /// Reject a match unless its cost is this many percent below every match more than one
    /// disparity away (0 disables).
    pub uniqueness_pct: u32,
    /// Left-right consistency check: the right image's disparity must agree within
    /// `lr_max_diff_px`.
    pub lr_check: bool,
    /// Allowed left-right disagreement, px.
    pub lr_max_diff_px: u32,
    /// Subpixel refinement of the winning disparity.
    pub subpixel: bool,
    /// Remove connected regions of at most this many pixels whose disparities differ from
    /// their surroundings (speckles; 0 disables).
    pub speckle_window_px: u32,
    /// Neighbouring disparities within this many px belong to the same region.
    pub speckle_range_px: u32,
    /// Fill runs of at most this many invalid pixels along a row with the farther of the
    /// disparities at their two ends, at confidence 1 (fusion leaves such pixels out; 0
    /// disables; sgm only).
    pub fill_invalid_px: u32,
    /// Block-matching settings.
    pub bm: BlockMatchConfig,
    /// Semi-global matching settings.
    pub sgm: SgmConfig,
    /// Ogale & Aloimonos settings.
    pub ogale: OgaleConfig,
    /// Online row alignment (the vertical offset between the cameras).
    pub row_align: RowAlignConfig,
}

/// Online row alignment before matching (services/stereo/src/rowalign.rs): the vertical
/// offset between the left and the right image is measured from the images, tracked over
/// frames and removed. With a calibration it measures the residual after rectification.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RowAlignConfig {
    /// Measure and correct the offset.
    pub enabled: bool,
    /// Largest offset searched, rows either way.
    pub max_shift_px: u32,
    /// Measure every this many frames (the tracked offset is applied to every frame).
    pub every_n_frames: u32,
    /// Warn when the tracked offset exceeds this, rows (the camera was knocked).
    pub warn_px: f32,
}

impl Default for RowAlignConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            max_shift_px: 6,
            every_n_frames: 4,
            warn_px: 2.0,
        }
    }
}

impl RowAlignConfig {
    /// Checks the ranges; `Err` carries the key (below the stereo section) and the message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !(1..=16).contains(&self.max_shift_px) {
            return Err((
                "row_align.max_shift_px",
                format!("= {} must be in 1..=16 rows", self.max_shift_px),
            ));
        }
        if !(1..=1000).contains(&self.every_n_frames) {
            return Err((
                "row_align.every_n_frames",
                format!("= {} must be in 1..=1000", self.every_n_frames),
            ));
        }
        if !(self.warn_px > 0.0 && self.warn_px <= 16.0) {
            return Err((
                "row_align.warn_px",
                format!("= {} must be in (0, 16] rows", self.warn_px),
            ));
        }
        Ok(())
    }
}

impl Default for StereoConfig {
    fn default() -> Self {
        Self {
            algorithm: StereoAlgorithm::Sgm,
            min_disp: 9,
            max_disp: 55,
            window: 15,
            equalize: true,
            uniqueness_pct: 5,
            lr_check: true,
            lr_max_diff_px: 1,
            subpixel: true,
            speckle_window_px: 40,
            speckle_range_px: 1,
            fill_invalid_px: 16,
            bm: BlockMatchConfig::default(),
            sgm: SgmConfig::default(),
            ogale: OgaleConfig::default(),
            row_align: RowAlignConfig::default(),
        }
    }
}

/// Settings of the block-matching family (`bm-sad`, `bm-ssd`, `bm-ncc`, `bm-census`).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct BlockMatchConfig {
    /// Minimum mean |horizontal gradient| of the left window, grey levels per pixel; flatter
    /// windows come out invalid rather than matched by chance (0 disables).
    pub texture_threshold: u32,
    /// Census window for `bm-census` (odd width x odd height, at most 32 comparisons).
    pub census_width: u32,
    /// Census window height.
    pub census_height: u32,
}

impl Default for BlockMatchConfig {
    fn default() -> Self {
        Self {
            texture_threshold: 0,
            census_width: 5,
            census_height: 5,
        }
    }
}

/// Settings of semi-global matching (`sgm`).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SgmConfig {
    /// Penalty for a disparity change of 1 px between neighbours, in matching-cost units
    /// (twice the mean census Hamming distance over the block: 0..=48).
    pub p1: u32,
    /// Penalty for larger disparity changes (at most 79, so that path costs fit a byte).
    pub p2: u32,
    /// Aggregation paths: 4, 5 or 8.
    pub paths: u32,
    /// Side of the square block the census costs are averaged over before the paths
    /// (1, 3, 5 or 7; OpenCV's `blockSize`): larger blocks resist noise and vertical
    /// misalignment, smaller ones keep thin structures.
    pub block: u32,
    /// Minimum mean |horizontal gradient| of the (prefiltered) left image around a pixel,
    /// grey levels per pixel; flatter pixels come out invalid rather than filled in by the
    /// paths (0 disables). Raise it for noisier cameras (see docs/stereo.md).
    pub texture_threshold: f32,
    /// Radius of the square window the texture is measured over, px.
    pub texture_radius: u32,
}

impl Default for SgmConfig {
    fn default() -> Self {
        Self {
            p1: 16,
            p2: 64,
            paths: 5,
            block: 5,
            texture_threshold: 0.25,
            texture_radius: 5,
        }
    }
}

/// Settings of the Ogale & Aloimonos matcher (`ogale`).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OgaleConfig {
    /// Two pixels match at a shift when their (Birchfield-Tomasi) difference is at most this.
    pub match_threshold: u32,
    /// Horizontal stretch factors tried for slanted surfaces (1.0 = fronto-parallel).
    pub stretch: Vec<f32>,
    /// Cut vertical links where a horizontal edge separates two pixels.
    pub cut_horizontal_edges: bool,
    /// Vertical grey difference that counts as a horizontal edge.
    pub edge_threshold: u32,
}

impl Default for OgaleConfig {
    fn default() -> Self {
        Self {
            match_threshold: 4,
            stretch: vec![1.0],
            cut_horizontal_edges: true,
            edge_threshold: 8,
        }
    }
}
