//! Wheel slip and speed errors of the simulated robot: the state behind `[sim.motion]`
//! ([`SimMotionNoise`]).
//!
//! The robot's dead reckoning integrates the pulses it commanded, so what makes it drift is
//! the simulated robot moving differently from what was commanded. Three effects, each off at
//! 0:
//!
//! * a constant scale error per wheel, `1 + wheel_scale_sigma * N(0, 1)`, drawn once per run
//!   (tyre diameters, motor gains);
//! * a relative, time-correlated variation of each wheel's speed, an Ornstein-Uhlenbeck
//!   process of standard deviation `wheel_noise_sigma` and correlation time
//!   `wheel_noise_tau_s` (floor grip, battery sag), started from its stationary distribution;
//! * skid losses of turning: when the wheels run in opposite directions the body turns
//!   `turn_slip` less than the wheel speeds give (a share of it on arcs, see
//!   [`WheelNoise::turn_kept`]).
//!
//! Everything is drawn from the simulator's seeded generator ([`crate::defects::SimRng`],
//! already a dependency), from a stream of its own, so a run repeats exactly and the motion's
//! draws do not change the images' noise.

pub use hvs_runtime::config::SimMotionNoise;

use rand::Rng;

use crate::defects::{SimRng, sim_rng};

/// Mixed into `[sim] seed` so that the motion's stream differs from the images' stream.
const MOTION_STREAM: u64 = 0x6d6f_7469_6f6e_5eed;

/// The random state of [`SimMotionNoise`] for one run.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelNoise {
    params: SimMotionNoise,
    rng: SimRng,
    /// Constant scale factors (left, right).
    scale: [f64; 2],
    /// Current relative variations (left, right), the Ornstein-Uhlenbeck states.
    ou: [f64; 2],
}

impl WheelNoise {
    /// The state for a run with seed `seed`: draws the scale errors and the variations'
    /// starting values. `None` when `params` is all off (the robot then skips the noise).
    pub fn new(params: SimMotionNoise, seed: u64) -> Option<Self> {
        if !params.is_on() {
            return None;
        }
        let mut rng = sim_rng(seed ^ MOTION_STREAM);
        let (a, b) = gaussian_pair(&mut rng);
        let scale = [a, b].map(|n| (1.0 + params.wheel_scale_sigma * n).clamp(0.5, 1.5));
        let (a, b) = gaussian_pair(&mut rng);
        let ou = [a, b].map(|n| params.wheel_noise_sigma * n);
        Some(WheelNoise {
            params,
            rng,
            scale,
            ou,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &SimMotionNoise {
        &self.params
    }

    /// The constant scale factors of the (left, right) wheels.
    pub fn scales(&self) -> (f64, f64) {
        (self.scale[0], self.scale[1])
    }

    /// Advances the variations by `h_s` seconds and returns the factors (left, right) that
    /// turn the commanded wheel speeds into the motors' targets (never negative).
    pub fn step(&mut self, h_s: f64) -> (f64, f64) {
        let sigma = self.params.wheel_noise_sigma;
        if sigma > 0.0 && h_s > 0.0 {
            // Exact discretisation of dx = -x / tau dt + sigma sqrt(2 / tau) dW.
            let a = (-h_s / self.params.wheel_noise_tau_s).exp();
            let k = sigma * (1.0 - a * a).max(0.0).sqrt();
            let (n0, n1) = gaussian_pair(&mut self.rng);
            self.ou[0] = self.ou[0] * a + k * n0;
            self.ou[1] = self.ou[1] * a + k * n1;
        }
        let f = |i: usize| (self.scale[i] * (1.0 + self.ou[i])).max(0.0);
        (f(0), f(1))
    }

    /// The fraction of the wheels' turn rate the body keeps at wheel speeds `v_left`,
    /// `v_right`: `1 - turn_slip * k`, with `k` = 1 turning in place (`v_left = -v_right`),
    /// falling linearly to 0 as the slower wheel's speed goes to 0, and 0 when both wheels
    /// run the same way.
    pub fn turn_kept(&self, v_left: f64, v_right: f64) -> f64 {
        let outer = v_left.abs().max(v_right.abs());
        if self.params.turn_slip <= 0.0 || outer <= 0.0 || v_left * v_right >= 0.0 {
            return 1.0;
        }
        let k = (v_left.abs().min(v_right.abs()) / outer).clamp(0.0, 1.0);
        1.0 - self.params.turn_slip * k
    }
}

/// Two independent standard normal samples (Box-Muller on two 53-bit uniforms).
fn gaussian_pair(rng: &mut SimRng) -> (f64, f64) {
    const SCALE: f64 = 1.0 / (1u64 << 53) as f64;
    // u1 in (0, 1] so that ln(u1) is finite.
    let u1 = ((rng.next_u64() >> 11) + 1) as f64 * SCALE;
    let u2 = (rng.next_u64() >> 11) as f64 * SCALE;
    let r = (-2.0 * u1.ln()).sqrt();
    let t = 2.0 * std::f64::consts::PI * u2;
    (r * t.cos(), r * t.sin())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn off_is_none_and_realistic_is_on() {
        assert!(WheelNoise::new(SimMotionNoise::off(), 1).is_none());
        assert!(WheelNoise::new(SimMotionNoise::realistic(), 1).is_some());
    }

    #[test]
    fn same_seed_same_draws_other_seed_other_draws() {
        let p = SimMotionNoise::realistic();
        let run = |seed| {
            let mut n = WheelNoise::new(p, seed).expect("on");
            let steps: Vec<(f64, f64)> = (0..100).map(|_| n.step(0.002)).collect();
            (n.scales(), steps)
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7).0, run(8).0);
    }

    #[test]
    fn scale_errors_have_the_configured_spread() {
        let p = SimMotionNoise {
            wheel_scale_sigma: 0.02,
            ..SimMotionNoise::off()
        };
        let mut sum2 = 0.0;
        let n = 2000;
        for seed in 0..n {
            let w = WheelNoise::new(p, seed).expect("on");
            let (l, r) = w.scales();
            sum2 += (l - 1.0).powi(2) + (r - 1.0).powi(2);
        }
        let sd = (sum2 / (2 * n) as f64).sqrt();
        assert!((sd - 0.02).abs() < 0.002, "{sd}");
        // Without the variation the factors are the scales, at every step.
        let mut w = WheelNoise::new(p, 3).expect("on");
        assert_eq!(w.step(0.1), w.scales());
    }

    #[test]
    fn variation_is_correlated_over_tau_with_the_configured_spread() {
        let p = SimMotionNoise {
            wheel_noise_sigma: 0.03,
            wheel_noise_tau_s: 1.0,
            ..SimMotionNoise::off()
        };
        let mut w = WheelNoise::new(p, 11).expect("on");
        let h = 0.01;
        let xs: Vec<f64> = (0..200_000).map(|_| w.step(h).0 - 1.0).collect();
        let n = xs.len() as f64;
        let mean = xs.iter().sum::<f64>() / n;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
        assert!((var.sqrt() - 0.03).abs() < 0.004, "sd {}", var.sqrt());
        // Autocorrelation at lag tau is about exp(-1).
        let lag = 100;
        let cov = xs
            .windows(lag + 1)
            .map(|win| (win[0] - mean) * (win[lag] - mean))
            .sum::<f64>()
            / (n - lag as f64);
        let rho = cov / var;
        assert!((rho - (-1.0f64).exp()).abs() < 0.1, "rho {rho}");
        // Neighbouring steps hardly differ.
        let max_jump = xs
            .windows(2)
            .map(|p| (p[1] - p[0]).abs())
            .fold(0.0, f64::max);
        assert!(max_jump < 0.03, "{max_jump}");
    }

    #[test]
    fn turn_slip_acts_on_turns_in_place_only() {
        let p = SimMotionNoise {
            turn_slip: 0.05,
            ..SimMotionNoise::off()
        };
        let w = WheelNoise::new(p, 1).expect("on");
        assert!((w.turn_kept(-0.3, 0.3) - 0.95).abs() < 1e-12);
        assert!((w.turn_kept(0.3, -0.3) - 0.95).abs() < 1e-12);
        assert!((w.turn_kept(-0.15, 0.3) - 0.975).abs() < 1e-12);
        assert_eq!(w.turn_kept(0.0, 0.3), 1.0);
        assert_eq!(w.turn_kept(0.2, 0.3), 1.0);
        assert_eq!(w.turn_kept(0.0, 0.0), 1.0);
    }
}
