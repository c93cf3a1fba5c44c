//! hvs stereo matching: disparity maps from grey stereo pairs, with no IPC.
//!
//! Every algorithm implements [`StereoMatcher`]; [`matcher_for`] builds the one a config
//! names. Output is a disparity map of the left image in 1/256 px (`u16`, 0 = invalid), the
//! KITTI convention also used on the wire ([`hvs_shared::messages::DISPARITY_SCALE`]).
//! Convention: a left pixel `(x, y)` with disparity `d` matches the right pixel `(x - d, y)`.
//!
//! - [`block`]: correlation block matching with SAD, SSD, NCC or census costs;
//! - [`sgm`]: census + semi-global matching;
//! - [`ogale`]: Ogale & Aloimonos shape-and-stereo correspondence;
//! - [`census`], [`post`], [`equalize`]: building blocks shared by them;
//! - [`rowalign`]: online row alignment (the vertical offset between the cameras);
//! - [`eval`]: scoring against ground truth; [`synthetic`]: pairs with known disparity.

pub mod block;
pub mod census;
pub mod cpu;
pub mod equalize;
pub mod eval;
pub mod ogale;
pub mod post;
pub mod rowalign;
pub mod sgm;
pub mod synthetic;

use hvs_runtime::config::StereoConfig;
use hvs_shared::messages::StereoAlgorithm;

pub use block::BlockMatcher;
pub use ogale::OgaleMatcher;
pub use sgm::SgmMatcher;

/// A borrowed grey image, row-major, one byte per pixel, no row padding.
#[derive(Debug, Clone, Copy)]
pub struct ImageView<'a> {
    /// Pixels, `width * height` bytes.
    pub data: &'a [u8],
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
}

impl<'a> ImageView<'a> {
    /// Wraps `data`, checking that it holds `width * height` pixels.
    pub fn new(data: &'a [u8], width: usize, height: usize) -> Result<Self, StereoError> {
        if data.len() != width * height {
            return Err(StereoError::BufferSize {
                what: "image",
                expected: width * height,
                actual: data.len(),
            });
        }
        Ok(Self {
            data,
            width,
            height,
        })
    }

    /// Row `y` as a slice.
    pub fn row(&self, y: usize) -> &'a [u8] {
        &self.data[y * self.width..(y + 1) * self.width]
    }
}

/// Why a disparity map could not be computed.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StereoError {
    /// Left and right images differ in size.
    #[error("left image is {left_w}x{left_h} but right image is {right_w}x{right_h}")]
    SizeMismatch {
        /// Left width.
        left_w: usize,
        /// Left height.
        left_h: usize,
        /// Right width.
        right_w: usize,
        /// Right height.
        right_h: usize,
    },
    /// A buffer does not hold the expected number of elements.
    #[error("{what} buffer holds {actual} elements, expected {expected}")]
    BufferSize {
        /// Which buffer.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        actual: usize,
    },
    /// The disparity range is empty or inverted.
    #[error("max disparity {max} must be above min disparity {min}")]
    BadRange {
        /// Smallest disparity.
        min: u32,
        /// Largest disparity.
        max: u32,
    },
    /// The image is too small for the disparity range and window.
    #[error(
        "image {width}x{height} is too small for disparities up to {max_disp} with a {window}x{window} window (it must be wider than the largest disparity plus the window)"
    )]
    ImageTooSmall {
        /// Width.
        width: usize,
        /// Height.
        height: usize,
        /// Largest disparity.
        max_disp: u32,
        /// Window size.
        window: u32,
    },
    /// The image is wider than the algorithm handles.
    #[error("image width {width} px is above the {max_width} px this algorithm handles")]
    ImageTooWide {
        /// Width.
        width: usize,
        /// The most handled.
        max_width: usize,
    },
    /// A parameter is out of its range.
    #[error("`{key}` {message}")]
    BadParameter {
        /// The key in a `[stereo.*]` config section, e.g. `sgm.p2` or `uniqueness_pct`.
        key: &'static str,
        /// What is wrong with it.
        message: String,
    },
}

/// Statistics of one computed map.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MatchStats {
    /// Pixels with a valid disparity.
    pub valid_px: u32,
    /// What the row alignment did (`None` when it is off).
    pub row_align: Option<rowalign::AlignStatus>,
}

/// A stereo algorithm.
pub trait StereoMatcher: Send {
    /// Which algorithm this is.
    fn algorithm(&self) -> StereoAlgorithm;

    /// Computes the disparity of every left pixel into `out_q8` (`width * height`, 1/256 px,
    /// 0 = invalid).
    fn compute(
        &mut self,
        left: ImageView<'_>,
        right: ImageView<'_>,
        out_q8: &mut [u16],
    ) -> Result<MatchStats, StereoError>;

    /// The confidence of the last map computed, one byte a pixel (0 = no disparity, 255 =
    /// certain), from the matcher's cost curve; `None` for a matcher that has none (the
    /// stage then publishes 255 wherever the map has a disparity).
    fn confidence(&self) -> Option<&[u8]> {
        None
    }
}

/// Fills `out` with the confidence of a map: the matcher's own where it has one, else 255
/// wherever `disparity_q8` has a value and 0 elsewhere.
pub fn confidence_or_validity(matcher: &dyn StereoMatcher, disparity_q8: &[u16], out: &mut [u8]) {
    match matcher.confidence() {
        Some(c) if c.len() == out.len() => out.copy_from_slice(c),
        _ => {
            for (o, &d) in out.iter_mut().zip(disparity_q8) {
                *o = if d == 0 { 0 } else { 255 };
            }
        }
    }
}

/// Checks that a pair and an output buffer agree in size.
pub fn check_pair(
    left: &ImageView<'_>,
    right: &ImageView<'_>,
    out_len: usize,
) -> Result<(), StereoError> {
    if left.width != right.width || left.height != right.height {
        return Err(StereoError::SizeMismatch {
            left_w: left.width,
            left_h: left.height,
            right_w: right.width,
            right_h: right.height,
        });
    }
    let n = left.width * left.height;
    if out_len != n {
        return Err(StereoError::BufferSize {
            what: "disparity output",
            expected: n,
            actual: out_len,
        });
    }
    Ok(())
}

/// Checks that an image is wider than the disparity range plus the matching window and at
/// least a window high.
pub fn check_fits(image: &ImageView<'_>, max_disp: u32, window: u32) -> Result<(), StereoError> {
    let (w, h) = (image.width, image.height);
    if w <= (max_disp + window) as usize || h < window as usize {
        return Err(StereoError::ImageTooSmall {
            width: w,
            height: h,
            max_disp,
            window,
        });
    }
    Ok(())
}

/// Checks a disparity range on its own: it must not be empty (`max_disp > min_disp`).
pub fn check_range(min_disp: u32, max_disp: u32) -> Result<(), StereoError> {
    if max_disp <= min_disp {
        return Err(StereoError::BadRange {
            min: min_disp,
            max: max_disp,
        });
    }
    Ok(())
}

/// A [`StereoError::BadParameter`] for `key`.
pub(crate) fn bad_parameter<T>(
    key: &'static str,
    message: impl Into<String>,
) -> Result<T, StereoError> {
    Err(StereoError::BadParameter {
        key,
        message: message.into(),
    })
}

/// The uniqueness margin's rule, one for every matcher: a winner must beat the runner-up
/// by `pct` %, and 100 % or more would reject every pixel.
pub fn check_uniqueness(pct: u32) -> Result<(), StereoError> {
    if pct >= 100 {
        return bad_parameter("uniqueness_pct", format!("= {pct} must be below 100"));
    }
    Ok(())
}

/// Checks a whole `[stereo.*]` section for images `width_px` wide, by the rules of the code
/// that uses each value: the disparity range, the row alignment, the gap fill and the
/// parameters of every matcher family (not only the chosen one: a typo in an unused
/// subsection is still an error). `hvs check`, `hvs run` and `hvs doctor` run it before
/// anything starts; [`matcher_for`] runs the chosen matcher's part again.
pub fn validate_section(config: &StereoConfig, width_px: usize) -> Result<(), StereoError> {
    check_range(config.min_disp, config.max_disp)?;
    if config.max_disp as usize >= width_px / 2 {
        return bad_parameter(
            "max_disp",
            format!(
                "= {} leaves too little image at width {width_px}",
                config.max_disp
            ),
        );
    }
    if config.fill_invalid_px > 256 {
        return bad_parameter(
            "fill_invalid_px",
            format!("= {} must be in 0..=256 px", config.fill_invalid_px),
        );
    }
    if let Err((key, message)) = config.row_align.validate() {
        return bad_parameter(key, message);
    }
    sgm::SgmParams::from_config(config).validate()?;
    let census = StereoConfig {
        algorithm: StereoAlgorithm::BmCensus,
        ..config.clone()
    };
    block::BlockParams::from_config(&census)?.validate()?;
    ogale::OgaleParams::from_config(config).validate()?;
    Ok(())
}

/// Builds the matcher a stereo config section describes.
pub fn matcher_for(config: &StereoConfig) -> Result<Box<dyn StereoMatcher>, StereoError> {
    check_range(config.min_disp, config.max_disp)?;
    let inner: Box<dyn StereoMatcher> = match config.algorithm {
        StereoAlgorithm::BmSad
        | StereoAlgorithm::BmSsd
        | StereoAlgorithm::BmNcc
        | StereoAlgorithm::BmCensus => Box::new(BlockMatcher::from_config(config)?),
        StereoAlgorithm::Sgm => Box::new(SgmMatcher::from_config(config)?),
        StereoAlgorithm::Ogale => Box::new(OgaleMatcher::from_config(config)?),
    };
    Ok(if config.row_align.enabled {
        Box::new(rowalign::AlignedMatcher::new(inner, config))
    } else {
        inner
    })
}

/// Converts a disparity in 1/256 px to pixels (`None` for the invalid marker 0).
pub fn q8_to_px(q8: u16) -> Option<f32> {
    (q8 != 0).then(|| q8 as f32 / hvs_shared::messages::DISPARITY_SCALE)
}
