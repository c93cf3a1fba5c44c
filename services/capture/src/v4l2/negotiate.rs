//! Which mode to ask both cameras for, from what each one offers (a pure function).
//!
//! The Minoru is two UVC cameras behind one USB 2 hub. Each offers uncompressed YUYV at
//! 640x480 and 320x240 at several rates, but the bus carries both 640x480 streams only at a
//! reduced rate (15 fps), and a `VIDIOC_STREAMON` that finds no bandwidth left fails with
//! `ENOSPC`. The candidates are therefore ordered best first: the configured size at the
//! fastest rate both cameras offer up to `camera.fps`, then each slower common rate down to
//! [`MIN_PREFERRED_FPS`] (the decisions run on every fast-path frame: a slow 640x480 stream
//! costs more than the long-range path gives), then 320x240 down to [`MIN_FPS`] (both paths
//! fed from it, stereo-hi idle). The capture tries them in order and keeps the first that
//! streams.

use std::fmt;

use hvs_runtime::config::V4l2PixelFormat;

use super::device::{FrameRates, FrameSizes};
use super::{CameraMode, fourcc_name, fourcc_of};

/// Slowest rate worth driving on, Hz.
pub const MIN_FPS: f64 = 5.0;
/// Slowest rate tried at the configured size before 320x240 is, Hz (or `camera.fps` if lower).
pub const MIN_PREFERRED_FPS: f64 = 10.0;

/// What one camera offers for one pixel format.
#[derive(Debug, Clone, PartialEq)]
pub struct FormatOffer {
    /// FOURCC code.
    pub fourcc: u32,
    /// Sizes, each with its rates.
    pub sizes: Vec<(FrameSizes, SizeRates)>,
}

/// Rates offered at one size (`None`: the driver does not enumerate them).
pub type SizeRates = Option<FrameRates>;

/// Everything one camera offers.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CameraOffer {
    /// Per pixel format.
    pub formats: Vec<FormatOffer>,
}

impl CameraOffer {
    /// The rates offered for `fourcc` at `width x height`: `None` if that size is not
    /// offered, `Some(None)` if it is but its rates are not enumerated.
    fn rates(&self, fourcc: u32, width: u32, height: u32) -> Option<SizeRates> {
        let f = self.formats.iter().find(|f| f.fourcc == fourcc)?;
        f.sizes
            .iter()
            .find(|(s, _)| s.contains(width, height))
            .map(|(_, r)| r.clone())
    }

    /// A one-line summary, e.g. `YUYV 640x480@30/15/5 320x240@30/15; MJPG 640x480@30`.
    pub fn summary(&self) -> String {
        let mut parts = Vec::new();
        for f in &self.formats {
            let sizes: Vec<String> = f
                .sizes
                .iter()
                .map(|(s, r)| {
                    let size = match s {
                        FrameSizes::Discrete { width, height } => format!("{width}x{height}"),
                        FrameSizes::Stepwise { width, height } => {
                            format!("{}..{}x{}..{}", width.0, width.1, height.0, height.1)
                        }
                    };
                    match r {
                        Some(FrameRates::Discrete(v)) => {
                            let v: Vec<String> = v.iter().map(|x| format!("{x:.0}")).collect();
                            format!("{size}@{}", v.join("/"))
                        }
                        Some(FrameRates::Range(lo, hi)) => format!("{size}@{lo:.0}-{hi:.0}"),
                        None => size,
                    }
                })
                .collect();
            parts.push(format!("{} {}", fourcc_name(f.fourcc), sizes.join(" ")));
        }
        if parts.is_empty() {
            "no capture formats".into()
        } else {
            parts.join("; ")
        }
    }
}

/// The rates at or below `wanted` and at least `floor` that `rates` allows, fastest first;
/// `wanted` itself when the driver does not enumerate its rates.
fn allowed_rates(rates: &SizeRates, wanted: f64, floor: f64) -> Vec<f64> {
    let mut out: Vec<f64> = match rates {
        None => vec![wanted],
        Some(FrameRates::Discrete(v)) => v
            .iter()
            .copied()
            .filter(|&r| r <= wanted * 1.001 && r >= floor * 0.999)
            .collect(),
        Some(FrameRates::Range(lo, hi)) => {
            let top = wanted.min(*hi);
            // A continuous range: the wanted rate (or the fastest), then halves of it.
            let mut v = Vec::new();
            let mut r = top;
            while r >= lo.max(floor) * 0.999 {
                v.push(r);
                r /= 2.0;
            }
            v
        }
    };
    out.sort_by(|a, b| b.total_cmp(a));
    out.dedup_by(|a, b| (*a - *b).abs() < 0.01);
    out
}

/// Rates both lists contain (within 1 %), fastest first.
fn common_rates(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter()
        .copied()
        .filter(|x| b.iter().any(|y| (x - y).abs() <= 0.01 * x.max(*y)))
        .collect()
}

/// Why no mode can be tried at all (a permanent configuration problem).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NoCommonMode {
    /// What was asked.
    pub requested: String,
    /// What each camera offers.
    pub left_offers: String,
    /// What each camera offers.
    pub right_offers: String,
}

impl fmt::Display for NoCommonMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "the two cameras offer no common mode for {}; left offers {}; right offers {}",
            self.requested, self.left_offers, self.right_offers
        )
    }
}

/// The modes to try, best first, for `format` at `width x height` and `fps`, given what
/// both cameras offer. A 640x480 request falls back to 320x240.
pub fn candidate_modes(
    left: &CameraOffer,
    right: &CameraOffer,
    format: V4l2PixelFormat,
    width: u32,
    height: u32,
    fps: f64,
    buffers: u32,
) -> Result<Vec<CameraMode>, NoCommonMode> {
    let fourcc = fourcc_of(format);
    let mut sizes = vec![(width, height, MIN_PREFERRED_FPS.min(fps))];
    if (width, height) == (640, 480) {
        sizes.push((320, 240, MIN_FPS.min(fps)));
    } else {
        sizes[0].2 = MIN_FPS.min(fps);
    }
    let mut out = Vec::new();
    for (w, h, floor) in sizes {
        let (Some(l), Some(r)) = (left.rates(fourcc, w, h), right.rates(fourcc, w, h)) else {
            continue;
        };
        let (l, r) = (allowed_rates(&l, fps, floor), allowed_rates(&r, fps, floor));
        for rate in common_rates(&l, &r) {
            out.push(CameraMode {
                width: w,
                height: h,
                format,
                fps: rate,
                buffers,
            });
        }
    }
    if out.is_empty() {
        return Err(NoCommonMode {
            requested: format!(
                "{width}x{height} {} at up to {fps} fps",
                fourcc_name(fourcc)
            ),
            left_offers: left.summary(),
            right_offers: right.summary(),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A Minoru camera: YUYV 640x480 and 320x240 at 30/15/5 fps, MJPEG 640x480 at 30.
    pub(crate) fn minoru_offer() -> CameraOffer {
        let rates = || Some(FrameRates::Discrete(vec![30.0, 15.0, 5.0]));
        CameraOffer {
            formats: vec![
                FormatOffer {
                    fourcc: fourcc_of(V4l2PixelFormat::Yuyv),
                    sizes: vec![
                        (
                            FrameSizes::Discrete {
                                width: 640,
                                height: 480,
                            },
                            rates(),
                        ),
                        (
                            FrameSizes::Discrete {
                                width: 320,
                                height: 240,
                            },
                            rates(),
                        ),
                    ],
                },
                FormatOffer {
                    fourcc: fourcc_of(V4l2PixelFormat::Mjpeg),
                    sizes: vec![(
                        FrameSizes::Discrete {
                            width: 640,
                            height: 480,
                        },
                        Some(FrameRates::Discrete(vec![30.0])),
                    )],
                },
            ],
        }
    }

    fn modes(v: &[CameraMode]) -> Vec<String> {
        v.iter().map(ToString::to_string).collect()
    }

    #[test]
    fn the_configured_size_at_each_common_rate_then_320x240() {
        let m = minoru_offer();
        let c = candidate_modes(&m, &m, V4l2PixelFormat::Yuyv, 640, 480, 30.0, 4).expect("modes");
        assert_eq!(
            modes(&c),
            [
                "640x480 YUYV at 30 fps",
                "640x480 YUYV at 15 fps",
                "320x240 YUYV at 30 fps",
                "320x240 YUYV at 15 fps",
                "320x240 YUYV at 5 fps"
            ]
        );
        // camera.fps = 15: nothing faster is asked for.
        let c = candidate_modes(&m, &m, V4l2PixelFormat::Yuyv, 640, 480, 15.0, 4).expect("modes");
        assert_eq!(c[0].to_string(), "640x480 YUYV at 15 fps");
    }

    #[test]
    fn only_rates_both_cameras_offer_are_tried() {
        let left = minoru_offer();
        let mut right = minoru_offer();
        right.formats[0].sizes[0].1 = Some(FrameRates::Discrete(vec![25.0, 15.0]));
        let c = candidate_modes(&left, &right, V4l2PixelFormat::Yuyv, 640, 480, 30.0, 4)
            .expect("modes");
        assert_eq!(c[0].to_string(), "640x480 YUYV at 15 fps");
    }

    #[test]
    fn a_range_of_rates_and_unenumerated_rates() {
        let mut m = minoru_offer();
        m.formats[0].sizes[0].1 = Some(FrameRates::Range(1.0, 30.0));
        m.formats[0].sizes[1].1 = None;
        let c = candidate_modes(&m, &m, V4l2PixelFormat::Yuyv, 640, 480, 30.0, 4).expect("modes");
        assert_eq!(
            modes(&c),
            [
                "640x480 YUYV at 30 fps",
                "640x480 YUYV at 15 fps",
                "320x240 YUYV at 30 fps"
            ]
        );
    }

    #[test]
    fn no_common_mode_names_what_each_camera_offers() {
        let m = minoru_offer();
        let bare = CameraOffer::default();
        let e = candidate_modes(&m, &bare, V4l2PixelFormat::Yuyv, 640, 480, 30.0, 4)
            .expect_err("right offers nothing");
        assert_eq!(
            e.to_string(),
            "the two cameras offer no common mode for 640x480 YUYV at up to 30 fps; left offers \
             YUYV 640x480@30/15/5 320x240@30/15/5; MJPG 640x480@30; right offers no capture \
             formats"
        );
    }
}
