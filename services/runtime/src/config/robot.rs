//! `[robot]`: the one description of the robot's body. The simulator builds its simulated
//! robot from it, and the decision stage its footprint and its dead reckoning; the camera's
//! mount on it is `[camera]` (`height_m`, `forward_m`).

use serde::{Deserialize, Serialize};

use super::Invalid;

/// The robot's body: footprint and drive (the reference robot's figures by default).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    /// Footprint width (across), metres.
    pub width_m: f64,
    /// Footprint length (along the heading, centred on the turning centre), metres.
    pub length_m: f64,
    /// Effective skid-steer track width (what turns the robot, wider than the wheels'
    /// spacing because the wheels skid), metres.
    pub track_m: f64,
    /// Wheel speed at the forward pulses, m/s (reference: 0.274).
    pub forward_speed_mps: f64,
    /// Time constant of the motors' first-order lag, seconds.
    pub motor_tau_s: f64,
}

impl Default for RobotConfig {
    fn default() -> Self {
        Self {
            width_m: 0.311,
            length_m: 0.438,
            track_m: 0.55,
            forward_speed_mps: 0.274,
            motor_tau_s: 0.1,
        }
    }
}

impl RobotConfig {
    /// Half the footprint's diagonal: the radius its corners sweep turning in place, metres.
    pub fn half_diagonal_m(&self) -> f64 {
        0.5 * self.width_m.hypot(self.length_m)
    }

    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        for (key, value, lo, hi) in [
            ("width_m", self.width_m, 0.05, 2.0),
            ("length_m", self.length_m, 0.05, 3.0),
            ("track_m", self.track_m, 0.01, 10.0),
            ("forward_speed_mps", self.forward_speed_mps, 0.001, 10.0),
            ("motor_tau_s", self.motor_tau_s, 0.0, 10.0),
        ] {
            if !(lo..=hi).contains(&value) {
                return Err(Invalid::new(
                    key,
                    format!("= {value} must be in {lo}..={hi}"),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_reference_robot_is_valid_and_bad_values_are_named() {
        let r = RobotConfig::default();
        assert_eq!(r.validate(), Ok(()));
        assert!((r.half_diagonal_m() - 0.2686).abs() < 1e-3);
        let bad = RobotConfig { length_m: 0.0, ..r };
        assert_eq!(
            bad.validate().map_err(|e| e.key),
            Err("length_m".to_string())
        );
    }
}
