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

/// `[sim.motion]`: how the simulated robot's motion departs from what its pulses command.
///
/// The robot's dead reckoning integrates the commanded pulses, so these are what make it
/// drift. All default to 0 (off): the simulated robot then moves exactly as commanded. The
/// random parts are drawn from `[sim] seed`, so a run repeats exactly.
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SimMotionNoise {
    /// Standard deviation of each wheel's constant scale error (drawn once per run; 0.02 = a
    /// wheel 2 % faster or slower than commanded, one sigma).
    pub wheel_scale_sigma: f64,
    /// Standard deviation of each wheel's relative, time-correlated speed variation (an
    /// Ornstein-Uhlenbeck process; 0.03 = 3 % of the wheel's speed, one sigma).
    pub wheel_noise_sigma: f64,
    /// Correlation time of that variation, seconds.
    pub wheel_noise_tau_s: f64,
    /// Extra fraction of the turn lost to skidding when turning in place (the wheels running
    /// in opposite directions; 0.05 = 5 % less turn than commanded). Arcs lose a share of it
    /// that falls to 0 as the inner wheel's speed goes from `-outer` to 0.
    pub turn_slip: f64,
}

impl Default for SimMotionNoise {
    /// Off: the robot moves exactly as commanded.
    fn default() -> Self {
        Self::off()
    }
}

impl SimMotionNoise {
    /// No motion noise at all (the default).
    pub const fn off() -> Self {
        Self {
            wheel_scale_sigma: 0.0,
            wheel_noise_sigma: 0.0,
            wheel_noise_tau_s: 1.0,
            turn_slip: 0.0,
        }
    }

    /// A plausible small skid-steer robot on a hard floor: wheel scale errors of 2 %, a 3 %
    /// speed variation correlated over 1 s, and 5 % of every turn in place lost to skidding.
    /// What `hvs sim drive --motion-noise` and the drift tests use.
    pub const fn realistic() -> Self {
        Self {
            wheel_scale_sigma: 0.02,
            wheel_noise_sigma: 0.03,
            wheel_noise_tau_s: 1.0,
            turn_slip: 0.05,
        }
    }

    /// Whether any of it is on.
    pub fn is_on(&self) -> bool {
        self.wheel_scale_sigma > 0.0 || self.wheel_noise_sigma > 0.0 || self.turn_slip > 0.0
    }

    /// Checks the values; the key of an error is below `[sim.motion]`.
    pub fn validate(&self) -> Result<(), Invalid> {
        let checks = [
            ("wheel_scale_sigma", self.wheel_scale_sigma, 0.0, 0.2),
            ("wheel_noise_sigma", self.wheel_noise_sigma, 0.0, 0.5),
            ("turn_slip", self.turn_slip, 0.0, 0.5),
        ];
        for (key, v, lo, hi) in checks {
            if !(lo..=hi).contains(&v) {
                return Err(Invalid::new(key, format!("= {v} must be in {lo}..={hi}")));
            }
        }
        let tau = self.wheel_noise_tau_s;
        if !(tau.is_finite() && tau > 0.0 && tau <= 3600.0) {
            return Err(Invalid::new(
                "wheel_noise_tau_s",
                format!("= {tau} must be in (0, 3600] seconds"),
            ));
        }
        Ok(())
    }
}

/// The simulated world.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Map file (relative to the config file).
    pub map: PathBuf,
    /// Random seed for noise (the images' and the motion's).
    pub seed: u64,
    /// Webcam defects.
    pub defects: SimDefects,
    /// Wheel slip and speed errors of the simulated robot (`[sim.motion]`, off by default).
    pub motion: SimMotionNoise,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            map: PathBuf::from("maps/maze.txt"),
            seed: 1,
            defects: SimDefects::default(),
            motion: SimMotionNoise::default(),
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
        self.motion
            .validate()
            .map_err(|e| Invalid::new(format!("motion.{}", e.key), e.message))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn motion_noise_defaults_off_and_parses() {
        let c: SimConfig = toml::from_str("seed = 3").expect("parses");
        assert_eq!(c.motion, SimMotionNoise::off());
        assert!(!c.motion.is_on());
        assert!(c.validate().is_ok());
        let c: SimConfig = toml::from_str(
            "[motion]\nwheel_scale_sigma = 0.02\nwheel_noise_sigma = 0.03\nturn_slip = 0.05\n",
        )
        .expect("parses");
        assert_eq!(c.motion, SimMotionNoise::realistic());
        assert!(c.motion.is_on());
        assert!(c.validate().is_ok());
        assert!(toml::from_str::<SimConfig>("[motion]\nslip = 0.1\n").is_err());
    }

    #[test]
    fn bad_motion_noise_names_its_key() {
        let bad = |m: SimMotionNoise| {
            let c = SimConfig {
                motion: m,
                ..SimConfig::default()
            };
            c.validate().map(|_| ()).map_err(|e| e.key)
        };
        let r = SimMotionNoise::realistic();
        assert_eq!(
            bad(SimMotionNoise {
                wheel_scale_sigma: -0.1,
                ..r
            }),
            Err("motion.wheel_scale_sigma".to_string())
        );
        assert_eq!(
            bad(SimMotionNoise {
                wheel_noise_sigma: f64::NAN,
                ..r
            }),
            Err("motion.wheel_noise_sigma".to_string())
        );
        assert_eq!(
            bad(SimMotionNoise {
                wheel_noise_tau_s: 0.0,
                ..r
            }),
            Err("motion.wheel_noise_tau_s".to_string())
        );
        assert_eq!(
            bad(SimMotionNoise {
                turn_slip: 0.9,
                ..r
            }),
            Err("motion.turn_slip".to_string())
        );
        assert_eq!(bad(r), Ok(()));
    }
}
