//! Dead reckoning's heading calibrated online (`[nav.calibration]`).
//!
//! A skid-steer base turning in place skids: the body turns a few per cent less than its
//! wheel speeds say. Two wheels of slightly different size or motor gain turn it while it
//! drives straight. Both errors are systematic, so the heading fixes (the walls' directions,
//! the scan aligned to the grid) that keep pulling the heading back say how large they are:
//! the fixes are set against the turning in place and the driving integrated since a sample
//! began, and a least-squares fit with forgetting gives the share of a turn in place
//! the body loses and the heading it gains per metre driven. Written by hand: it is a
//! two-parameter recursive least squares over a few sums.

use hvs_runtime::config::CalibrationConfig;

/// The learnt corrections and the motion since the sample began.
#[derive(Debug, Clone, Default)]
pub struct HeadingCalibration {
    cfg: CalibrationConfig,
    /// Turning in place integrated from the wheel speeds since the sample began, radians.
    turned_rad: f64,
    /// Any other turning integrated from the wheel speeds (arcs), radians.
    other_rad: f64,
    /// Driving (signed: backwards negative) since the sample began, metres.
    driven_m: f64,
    /// Heading change the calibrated integration applied since the sample began, radians.
    applied_rad: f64,
    /// Fixes applied since the sample began, radians.
    fixed_rad: f64,
    /// Fixes applied this frame, radians.
    frame_fixed_rad: f64,
    /// A fix (of any size) was made this frame: the heading was measured.
    frame_measured: bool,
    /// Weighted sums of the turning and driving the samples in the fit span.
    abs_turned_rad: f64,
    abs_driven_m: f64,
    /// Weighted normal equations of `y = loss * turned - drift * driven`.
    stt: f64,
    std: f64,
    sdd: f64,
    sty: f64,
    sdy: f64,
    /// Share of a turn in place the body loses.
    loss_share: f64,
    /// Heading the body gains per metre driven, rad/m.
    drift_rad_per_m: f64,
}

impl HeadingCalibration {
    /// A calibration with the settings of `cfg` (nothing learnt yet).
    pub fn new(cfg: CalibrationConfig) -> Self {
        Self {
            cfg,
            ..Self::default()
        }
    }

    /// The heading change of one integration step whose wheel speeds turn the robot
    /// `raw_rad` while it moves `ds_m` (signed); `in_place`: the wheels run opposite ways.
    pub fn heading_step(&mut self, raw_rad: f64, ds_m: f64, in_place: bool) -> f64 {
        let applied = if in_place {
            self.turned_rad += raw_rad;
            raw_rad * (1.0 - self.loss_share)
        } else {
            self.other_rad += raw_rad;
            self.driven_m += ds_m;
            raw_rad + self.drift_rad_per_m * ds_m
        };
        self.applied_rad += applied;
        applied
    }

    /// A heading fix of `delta_rad` was applied: what the body really turned is the
    /// applied change plus the fixes.
    pub fn observe_fix(&mut self, delta_rad: f64) {
        self.fixed_rad += delta_rad;
        self.frame_fixed_rad += delta_rad;
        self.frame_measured = true;
    }

    /// The frame ends; `settled`: the heading could be fixed this frame (the walls in view,
    /// not turning fast). A fix takes back only a share of the error it finds and the rest
    /// comes in the next frames, so a sample closes only at a settled frame that measured the
    /// heading (a fix was made) and whose fixes were below `quiet_rad` (the error made over
    /// the sample then taken back), once the motion since it began reaches
    /// `sample_turned_rad` or `sample_driven_m`. A sample whose error exceeds what the limits
    /// allow (`max_turn_loss_share`, `max_drift_rad_per_m`, plus `quiet_rad`) is dropped: a
    /// turn held by a wall and found only later is not a wheel's error.
    pub fn end_frame(&mut self, settled: bool) {
        let quiet = self.frame_measured && self.frame_fixed_rad.abs() < self.cfg.quiet_rad;
        self.frame_fixed_rad = 0.0;
        self.frame_measured = false;
        if !settled
            || !quiet
            || (self.turned_rad.abs() < self.cfg.sample_turned_rad
                && self.driven_m.abs() < self.cfg.sample_driven_m)
        {
            return;
        }
        let true_rad = self.applied_rad + self.fixed_rad;
        let y = self.turned_rad + self.other_rad - true_rad;
        let (t, d) = (self.turned_rad, -self.driven_m);
        let limit = self.cfg.max_turn_loss_share * t.abs()
            + self.cfg.max_drift_rad_per_m * d.abs()
            + self.cfg.quiet_rad;
        if y.abs() > limit {
            self.discard_interval();
            return;
        }
        let l = self.cfg.forget_factor;
        self.stt = l * self.stt + t * t;
        self.std = l * self.std + t * d;
        self.sdd = l * self.sdd + d * d;
        self.sty = l * self.sty + t * y;
        self.sdy = l * self.sdy + d * y;
        self.abs_turned_rad = l * self.abs_turned_rad + t.abs();
        self.abs_driven_m = l * self.abs_driven_m + d.abs();
        self.discard_interval();
        self.solve();
    }

    /// The motion since the sample began did not happen (the pose was put back): it is left
    /// out.
    pub fn discard_interval(&mut self) {
        self.turned_rad = 0.0;
        self.other_rad = 0.0;
        self.driven_m = 0.0;
        self.applied_rad = 0.0;
        self.fixed_rad = 0.0;
        self.frame_fixed_rad = 0.0;
        self.frame_measured = false;
    }

    /// The share of a turn in place the body is found to lose.
    pub fn loss_share(&self) -> f64 {
        self.loss_share
    }

    /// The heading the body is found to gain per metre driven, rad/m.
    pub fn drift_rad_per_m(&self) -> f64 {
        self.drift_rad_per_m
    }

    fn solve(&mut self) {
        let turned = self.abs_turned_rad >= self.cfg.min_turned_rad && self.stt > 0.0;
        let driven = self.abs_driven_m >= self.cfg.min_driven_m && self.sdd > 0.0;
        let det = self.stt * self.sdd - self.std * self.std;
        let (loss, drift) = if turned && driven && det > 1e-9 * self.stt * self.sdd {
            (
                (self.sty * self.sdd - self.sdy * self.std) / det,
                (self.stt * self.sdy - self.std * self.sty) / det,
            )
        } else if turned {
            // The other term at its current value.
            (
                (self.sty - self.drift_rad_per_m * self.std) / self.stt,
                self.drift_rad_per_m,
            )
        } else if driven {
            (
                self.loss_share,
                (self.sdy - self.loss_share * self.std) / self.sdd,
            )
        } else {
            return;
        };
        let (l, k) = (self.cfg.max_turn_loss_share, self.cfg.max_drift_rad_per_m);
        self.loss_share = loss.clamp(-l, l);
        self.drift_rad_per_m = drift.clamp(-k, k);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn on() -> CalibrationConfig {
        CalibrationConfig {
            enabled: true,
            ..CalibrationConfig::default()
        }
    }

    /// Turns of `turn_rad` and drives of `drive_m` in steps, the body losing `loss` of each
    /// turn and gaining `drift` rad/m; a fix after each of `n` legs takes back `gain` of the
    /// heading error then (the rest stays for later fixes).
    fn learn(cal: &mut HeadingCalibration, loss: f64, drift: f64, gain: f64, n: usize) -> f64 {
        let (mut believed, mut truth) = (0.0, 0.0);
        for k in 0..n {
            let turn = if k % 3 == 0 { -1.2 } else { 0.9 };
            for _ in 0..10 {
                believed += cal.heading_step(0.1 * turn, 0.0, true);
                truth += 0.1 * turn * (1.0 - loss);
            }
            let ds = if k % 4 == 0 { -0.05 } else { 0.1 };
            for _ in 0..10 {
                believed += cal.heading_step(0.0, ds, false);
                truth += drift * ds;
            }
            // Fixes each frame until the error left is below 0.1 degree.
            loop {
                let fix = gain * (truth - believed);
                believed += fix;
                cal.observe_fix(fix);
                let quiet = fix.abs() < 1e-3;
                cal.end_frame(true);
                if quiet {
                    break;
                }
            }
        }
        truth - believed
    }

    #[test]
    fn a_turn_loss_and_a_drift_are_learnt_from_partial_fixes() {
        let mut cal = HeadingCalibration::new(on());
        learn(&mut cal, 0.05, 0.06, 0.5, 300);
        assert!(
            (cal.loss_share() - 0.05).abs() < 0.01,
            "{}",
            cal.loss_share()
        );
        assert!(
            (cal.drift_rad_per_m() - 0.06).abs() < 0.01,
            "{}",
            cal.drift_rad_per_m()
        );
        // Learnt, the integration leaves little for the fixes to take back.
        let left = learn(&mut cal, 0.05, 0.06, 0.5, 30);
        assert!(left.abs() < 0.01, "{left}");
    }

    #[test]
    fn nothing_is_applied_before_enough_motion_and_the_limits_hold() {
        let mut cal = HeadingCalibration::new(CalibrationConfig {
            min_turned_rad: 1e6,
            min_driven_m: 1e6,
            ..on()
        });
        learn(&mut cal, 0.1, 0.1, 0.5, 100);
        assert_eq!((cal.loss_share(), cal.drift_rad_per_m()), (0.0, 0.0));
        let mut cal = HeadingCalibration::new(CalibrationConfig {
            max_turn_loss_share: 0.02,
            max_drift_rad_per_m: 0.03,
            ..on()
        });
        // Errors beyond the limits are not taken for the wheels': the fit stays within them.
        learn(&mut cal, 0.1, 0.1, 0.5, 100);
        assert!(cal.loss_share().abs() <= 0.02, "{}", cal.loss_share());
        assert!(
            cal.drift_rad_per_m().abs() <= 0.03,
            "{}",
            cal.drift_rad_per_m()
        );
        // A put-back drops the motion since the sample began: turns that never happened,
        // taken back by the pose put back (not a fix), teach nothing, and the loss learnt
        // stays.
        let mut cal = HeadingCalibration::new(on());
        learn(&mut cal, 0.1, 0.0, 0.5, 100);
        let learnt = cal.loss_share();
        assert!((learnt - 0.1).abs() < 0.01, "{learnt}");
        for _ in 0..50 {
            // Put back: the pose takes the turn back, the calibration drops it.
            cal.heading_step(1.0, 0.0, true);
            cal.discard_interval();
            cal.observe_fix(0.0);
            cal.end_frame(true);
        }
        assert_eq!(cal.loss_share(), learnt);
        // A sample whose error is beyond the limits (a held turn found late) is dropped.
        cal.heading_step(1.0, 0.0, true);
        cal.observe_fix(-0.9);
        cal.end_frame(true);
        cal.observe_fix(0.0);
        cal.end_frame(true);
        assert_eq!(cal.loss_share(), learnt);
    }
}
