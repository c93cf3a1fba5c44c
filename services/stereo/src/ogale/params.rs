//! The parameters: the variant, match function and equalisation choices with their defaults,
//! and [`OgaleParams`] with its reading of a config section and its validation.

use hvs_runtime::config::StereoConfig;

use crate::{StereoError, bad_parameter, check_range, check_uniqueness};

/// Which reading of Ogale & Aloimonos to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OgaleVariant {
    /// Binary matches, connected components (run-length union-find), largest component wins.
    #[default]
    Components,
    /// OpenVis3D: soft matches diffused along rows and columns, goodness = row x column support.
    Diffusion,
}

/// The variant [`OgaleMatcher::from_config`](super::OgaleMatcher::from_config) builds (the
/// config has no field for it).
pub const DEFAULT_VARIANT: OgaleVariant = OgaleVariant::Components;

/// The pixel dissimilarity behind a match. The intensity forms are all symmetric Birchfield-
/// Tomasi: `BT = (d1 + d2) / 2` with `d1 = max(0, Rmin - L, L - Rmax)` and
/// `d2 = max(0, Lmin - R, R - Lmax)`, where `[Imin, Imax]` is the half-interval around a pixel
/// (`Imin = (I + min over a neighbourhood) / 2`); they differ in the neighbourhood.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MatchFunction {
    /// Plain absolute difference `|L - R|` (no neighbourhood), the thesis's wording.
    AbsDiff,
    /// Classic Birchfield-Tomasi: the two horizontal neighbours (1x3).
    #[default]
    Bt1x3,
    /// OpenVis3D's form: the 3x3 neighbourhood (also tolerates some vertical misalignment).
    Bt3x3,
    /// The contrast-invariant substitute of the notes (section 1.5): Hamming distance of 5x5
    /// census strings (24 bits), blind to any gain and offset between the cameras. With it,
    /// `match_threshold` counts differing bits and the diffusion's soft match is
    /// `exp(-CENSUS_BETA * hamming)`.
    Census,
}

impl MatchFunction {
    /// The match function [`OgaleMatcher::from_config`](super::OgaleMatcher::from_config) uses
    /// for a variant: classic BT for the components (it gave steadier maps than the 3x3 form
    /// once the vertical search is on), OpenVis3D's 3x3 form for the diffusion (as released).
    pub fn default_for(variant: OgaleVariant) -> Self {
        match variant {
            OgaleVariant::Components => MatchFunction::Bt1x3,
            OgaleVariant::Diffusion => MatchFunction::Bt3x3,
        }
    }
}

/// How the right image is brought to the left's radiometry before matching.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Equalization {
    /// Images used as they are.
    Off,
    /// The reference step (`equalize::equalize_right`): right scaled by `sum(L) / sum(R)`;
    /// corrects a global gain only.
    #[default]
    SumRatio,
    /// Right mapped to the left's mean and standard deviation: undoes a global gain *and*
    /// offset (the notes' section 1.7 suggestion).
    MeanStd,
}

/// What `StereoConfig::equalize = true` selects in [`OgaleParams::from_config`].
pub const DEFAULT_EQUALIZATION: Equalization = Equalization::SumRatio;

/// Vertical search of the components variant in [`OgaleParams::from_config`]: a pixel's cost is
/// the smallest over right rows `y - v ..= y + v`, for webcams that are not perfectly rectified.
/// (The diffusion variant defaults to 0, as released: with the 3x3 BT the search made it lose
/// slanted surfaces.)
pub const DEFAULT_VERTICAL_SEARCH_PX: u32 = 1;

/// Largest vertical search accepted.
pub const MAX_VERTICAL_SEARCH_PX: u32 = 2;

/// Smallest stretch factor accepted.
pub const MIN_STRETCH: f32 = 0.5;
/// Largest stretch factor accepted.
pub const MAX_STRETCH: f32 = 2.0;

/// Largest disparity the 1/256-px `u16` output can hold.
const MAX_DISP_PX: u32 = 255;

/// Ogale & Aloimonos parameters: the crate-level [`StereoConfig`] flattened, plus the choices
/// the config has no field for.
#[derive(Debug, Clone, PartialEq)]
pub struct OgaleParams {
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive).
    pub max_disp: u32,
    /// Radiometric equalisation of the right image before matching.
    pub equalization: Equalization,
    /// Left-right consistency check; pixels failing it are marked occluded (invalid).
    pub lr_check: bool,
    /// Allowed left-right disagreement, px.
    pub lr_max_diff_px: u32,
    /// Refine the winning disparity with a parabola through 5x3 SAD costs at the winning
    /// hypothesis moved by -1, 0, +1 (resampled) right pixels.
    pub subpixel: bool,
    /// Ambiguity test: a pixel stays valid only if its best goodness beats every rival
    /// hypothesis (more than `max(stretch) + 0.5` px away, i.e. not a neighbouring shift) by
    /// this many percent (0 disables).
    pub uniqueness_pct: u32,
    /// Speckle filter: regions of at most this many pixels are removed (0 disables).
    pub speckle_window_px: u32,
    /// Speckle filter: neighbours within this many px are one region.
    pub speckle_range_px: u32,
    /// Components variant: a pixel matches when its dissimilarity is at most this (grey levels;
    /// differing bits for [`MatchFunction::Census`]).
    pub match_threshold: u32,
    /// Horizontal stretch factors (1.0 = fronto-parallel); tried in order of `|1 - m|`.
    pub stretch: Vec<f32>,
    /// Cut vertical links where a horizontal edge of the left image separates two pixels.
    pub cut_horizontal_edges: bool,
    /// Vertical grey difference that counts as a horizontal edge.
    pub edge_threshold: u32,
    /// Which reading of the method to run.
    pub variant: OgaleVariant,
    /// The pixel dissimilarity.
    pub match_fn: MatchFunction,
    /// Tolerated vertical misalignment, px: a pixel's cost is the smallest over right rows
    /// `y - v ..= y + v` (0 = rectified pair, same row only).
    pub vertical_search_px: u32,
}

impl Default for OgaleParams {
    fn default() -> Self {
        Self::from_config(&StereoConfig::default())
    }
}

impl OgaleParams {
    /// Takes the parameters from a config section, with [`DEFAULT_VARIANT`] and its defaults
    /// (see [`OgaleParams::with_variant`]), and [`DEFAULT_EQUALIZATION`] when `equalize` is set.
    pub fn from_config(config: &StereoConfig) -> Self {
        Self {
            min_disp: config.min_disp,
            max_disp: config.max_disp,
            equalization: if config.equalize {
                DEFAULT_EQUALIZATION
            } else {
                Equalization::Off
            },
            lr_check: config.lr_check,
            lr_max_diff_px: config.lr_max_diff_px,
            subpixel: config.subpixel,
            uniqueness_pct: config.uniqueness_pct,
            speckle_window_px: config.speckle_window_px,
            speckle_range_px: config.speckle_range_px,
            match_threshold: config.ogale.match_threshold,
            stretch: config.ogale.stretch.clone(),
            cut_horizontal_edges: config.ogale.cut_horizontal_edges,
            edge_threshold: config.ogale.edge_threshold,
            variant: DEFAULT_VARIANT,
            match_fn: MatchFunction::Bt1x3,
            vertical_search_px: 0,
        }
        .with_variant(DEFAULT_VARIANT)
    }

    /// The same parameters with another variant and that variant's defaults: match function
    /// [`MatchFunction::default_for`] and vertical search [`DEFAULT_VERTICAL_SEARCH_PX`] for the
    /// components, none for the diffusion.
    pub fn with_variant(self, variant: OgaleVariant) -> Self {
        Self {
            variant,
            match_fn: MatchFunction::default_for(variant),
            vertical_search_px: match variant {
                OgaleVariant::Components => DEFAULT_VERTICAL_SEARCH_PX,
                OgaleVariant::Diffusion => 0,
            },
            ..self
        }
    }

    /// Checks the parameters on their own (image size is checked per call).
    pub fn validate(&self) -> Result<(), StereoError> {
        check_range(self.min_disp, self.max_disp)?;
        if self.max_disp > MAX_DISP_PX {
            return bad_parameter(
                "max_disp",
                format!(
                    "= {} is above {MAX_DISP_PX} px, the most a 1/256-px map holds",
                    self.max_disp
                ),
            );
        }
        if self.match_threshold > 255 {
            return bad_parameter(
                "ogale.match_threshold",
                format!("= {} must be at most 255", self.match_threshold),
            );
        }
        if self.edge_threshold > 255 {
            return bad_parameter(
                "ogale.edge_threshold",
                format!("= {} must be at most 255", self.edge_threshold),
            );
        }
        check_uniqueness(self.uniqueness_pct)?;
        if self.vertical_search_px > MAX_VERTICAL_SEARCH_PX {
            return bad_parameter(
                "ogale.vertical_search_px",
                format!(
                    "= {} px must be at most {MAX_VERTICAL_SEARCH_PX}",
                    self.vertical_search_px
                ),
            );
        }
        if self.stretch.is_empty() {
            return bad_parameter(
                "ogale.stretch",
                "needs at least one factor (1.0 = fronto-parallel)",
            );
        }
        for &m in &self.stretch {
            if !m.is_finite() || !(MIN_STRETCH..=MAX_STRETCH).contains(&m) {
                return bad_parameter(
                    "ogale.stretch",
                    format!("factor {m} must be in {MIN_STRETCH}..={MAX_STRETCH}"),
                );
            }
        }
        Ok(())
    }
}
