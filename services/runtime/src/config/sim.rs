//! `[sim]`: the simulated world and the camera defects it renders.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Webcam defects the simulator can add.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SimDefects {
    /// Gain applied to the right image.
    pub gain: f32,
    /// Offset added to the right image, grey levels.
    pub offset: f32,
    /// Gaussian noise on both images, grey levels (sigma).
    pub noise_sigma: f32,
    /// Vertical misalignment of the right image, px.
    pub vertical_shift_px: i32,
    /// The right image is taken this much later than the left, ms (unsynchronised capture).
    pub right_delay_ms: f64,
}

impl Default for SimDefects {
    fn default() -> Self {
        Self {
            gain: 1.0,
            offset: 0.0,
            noise_sigma: 0.0,
            vertical_shift_px: 0,
            right_delay_ms: 0.0,
        }
    }
}

/// The simulated world.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Map file (relative to the config file).
    pub map: PathBuf,
    /// Random seed for noise.
    pub seed: u64,
    /// Webcam defects.
    pub defects: SimDefects,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            map: PathBuf::from("maps/maze.txt"),
            seed: 1,
            defects: SimDefects::default(),
        }
    }
}

impl SimConfig {
    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        let d = &self.defects;
        if !(d.gain > 0.0 && d.gain < 4.0) {
            return Err(Invalid::new(
                "defects.gain",
                format!("= {} must be in (0, 4)", d.gain),
            ));
        }
        if !(0.0..=64.0).contains(&d.noise_sigma) {
            return Err(Invalid::new(
                "defects.noise_sigma",
                format!("= {} must be in 0..=64", d.noise_sigma),
            ));
        }
        if d.vertical_shift_px.abs() > 8 {
            return Err(Invalid::new(
                "defects.vertical_shift_px",
                format!("= {} must be within +-8", d.vertical_shift_px),
            ));
        }
        if !(0.0..=1000.0).contains(&d.right_delay_ms) {
            return Err(Invalid::new(
                "defects.right_delay_ms",
                format!("= {} must be in 0..=1000", d.right_delay_ms),
            ));
        }
        Ok(())
    }
}
