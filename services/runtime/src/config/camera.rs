//! `[camera]`: the stereo camera's geometry and rate.

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Camera geometry and rate.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Frame rate, Hz.
    pub fps: f64,
    /// Focal length at 320x240 in pixels (doubled at 640x480).
    pub focal_px_320: f64,
    /// Stereo baseline in metres. (`focal_px_320 = 380`, `baseline_m = 0.0604` is the
    /// reference's profile: its printed ranges are `380 * 0.1982 ft / d`.)
    pub baseline_m: f64,
    /// Height of the optical centres above the floor, metres (level camera assumed): fusion
    /// uses it to drop floor and ceiling points.
    pub height_m: f64,
    /// Distance of the optical centres ahead of the robot's turning centre, metres (the
    /// decision stage's local map places what the camera sees with it).
    pub forward_m: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            fps: 30.0,
            focal_px_320: 320.0,
            baseline_m: 0.060,
            height_m: 0.25,
            forward_m: 0.20,
        }
    }
}

impl CameraConfig {
    /// Focal length in pixels at an image `width` (scaled from the 320x240 value).
    pub fn focal_px(&self, width: usize) -> f64 {
        self.focal_px_320 * width as f64 / 320.0
    }
}

impl CameraConfig {
    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        let c = self;
        if !(c.fps > 0.0 && c.fps <= 120.0) {
            return Err(Invalid::new(
                "fps",
                format!("= {} must be in (0, 120]", c.fps),
            ));
        }
        if !(c.focal_px_320 > 10.0 && c.focal_px_320 < 10_000.0) {
            return Err(Invalid::new(
                "focal_px_320",
                format!("= {} must be in (10, 10000)", c.focal_px_320),
            ));
        }
        if !(c.baseline_m > 0.001 && c.baseline_m < 2.0) {
            return Err(Invalid::new(
                "baseline_m",
                format!("= {} must be in (0.001, 2) metres", c.baseline_m),
            ));
        }
        if !(0.0..10.0).contains(&c.height_m) {
            return Err(Invalid::new(
                "height_m",
                format!("= {} must be in [0, 10) metres", c.height_m),
            ));
        }
        if !(-2.0..=2.0).contains(&c.forward_m) {
            return Err(Invalid::new(
                "forward_m",
                format!("= {} must be in [-2, 2] metres", c.forward_m),
            ));
        }
        Ok(())
    }
}
