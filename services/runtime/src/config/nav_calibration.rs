//! `[nav.calibration]`: dead reckoning's two systematic heading errors learnt online from the
//! heading fixes (a skid-steer base turns in place less than its wheels say, and two wheels
//! of slightly different size turn it while it drives straight).

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Online calibration of dead reckoning's heading (`[nav.calibration]`): the heading fixes
/// (the walls' directions, the scan aligned to the grid) over a sample are set against the
/// turning in place and the driving dead reckoning integrated over it, and a least-squares fit
/// with forgetting gives the share of each turn in place that the body loses and the heading
/// the body gains per metre driven; both are then applied to the integration.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationConfig {
    /// Learn and apply the two corrections.
    pub enabled: bool,
    /// A sample of the fit spans the fixes until the motion since it began reaches this
    /// much turning in place, radians ...
    pub sample_turned_rad: f64,
    /// ... or this much driving, metres.
    pub sample_driven_m: f64,
    /// ... closing at a frame whose fixes sum to less than this, radians (0.003: 0.17
    /// degree), the error made over it taken back by then.
    pub quiet_rad: f64,
    /// Each sample's weight in the fit falls by this factor per later sample (0.98: about
    /// the last fifty count).
    pub forget_factor: f64,
    /// The turn correction is applied once the samples in the fit span this much turning in
    /// place (weighted as in the fit), radians.
    pub min_turned_rad: f64,
    /// The drift correction is applied once they span this much driving, metres.
    pub min_driven_m: f64,
    /// The share of a turn in place the body may be found to lose, either way (0..1).
    pub max_turn_loss_share: f64,
    /// The heading drift per metre driven it may be found to have, either way, rad/m.
    pub max_drift_rad_per_m: f64,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        Self {
            enabled: false,
            sample_turned_rad: 0.5,
            sample_driven_m: 0.5,
            quiet_rad: 0.003,
            forget_factor: 0.98,
            min_turned_rad: 6.0,
            min_driven_m: 3.0,
            max_turn_loss_share: 0.2,
            max_drift_rad_per_m: 0.15,
        }
    }
}

impl CalibrationConfig {
    /// Checks every value against its range, naming the first key out of it.
    pub(crate) fn validate(&self) -> Result<(), Invalid> {
        super::nav::check_ranges(
            "calibration",
            &[
                ("sample_turned_rad", self.sample_turned_rad, 0.0, 100.0),
                ("sample_driven_m", self.sample_driven_m, 0.0, 100.0),
                ("quiet_rad", self.quiet_rad, 0.0, 1.0),
                ("forget_factor", self.forget_factor, 0.5, 1.0),
                ("min_turned_rad", self.min_turned_rad, 0.0, 1000.0),
                ("min_driven_m", self.min_driven_m, 0.0, 1000.0),
                ("max_turn_loss_share", self.max_turn_loss_share, 0.0, 0.9),
                ("max_drift_rad_per_m", self.max_drift_rad_per_m, 0.0, 2.0),
            ],
        )
    }
}
