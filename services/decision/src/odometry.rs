//! Dead reckoning from the pulses the actuator actually sent.
//!
//! The decision stage hears every PSC command the actuator put on the wire (the actuator
//! report topic: pulse widths, ramp and send time). From those it integrates a skid-steer
//! model: each wheel's pulse slews toward its target at the PSC ramp rate (the PSC data sheet:
//! ramp 1..63 = 0.75 s .. 60 s for the full 250..1250 excursion, 0 = immediate), the motor
//! follows with a first-order lag, wheel speed is proportional to the pulse's distance from
//! neutral (calibrated by the forward pulses and the forward speed), and the pose follows
//! `v = (vl + vr) / 2`, `w = (vr - vl) / track`. Without wheel encoders this is the best the
//! robot knows about where it went; the visit memory and the turn execution use it.

use hvs_runtime::config::{CalibrationConfig, PulseTable, RobotConfig};

use crate::calibration::HeadingCalibration;

/// PSC pulse range, 2 us units.
const PW_SPAN: f64 = 1000.0;
/// Integration step, seconds.
const STEP_S: f64 = 0.005;

/// Seconds the PSC takes for a full 250..1250 excursion at `ramp` (0 = immediate).
pub fn ramp_full_excursion_s(ramp: u8) -> f64 {
    if ramp == 0 {
        0.0
    } else {
        let r = f64::from(ramp.min(63));
        0.75 + (r - 1.0) * (60.0 - 0.75) / 62.0
    }
}

/// A dead-reckoned pose: metres in the frame of the start pose (x ahead, y to the left),
/// heading in radians counter-clockwise.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct DeadReckonedPose {
    /// Metres ahead of the start.
    pub x_m: f64,
    /// Metres to the left of the start.
    pub y_m: f64,
    /// Heading, radians (0 = the start heading, counter-clockwise positive).
    pub heading_rad: f64,
}

/// One wheel: commanded pulse, current (ramped) pulse, motor speed.
#[derive(Debug, Clone, Copy)]
struct Wheel {
    target_pw: f64,
    pw: f64,
    slew_pw_per_s: f64,
    speed_mps: f64,
    neutral_pw: f64,
    mps_per_pw: f64,
}

impl Wheel {
    fn new(neutral: u16, forward: u16, forward_speed_mps: f64) -> Self {
        let delta = f64::from(forward) - f64::from(neutral);
        Self {
            target_pw: f64::from(neutral),
            pw: f64::from(neutral),
            slew_pw_per_s: f64::INFINITY,
            speed_mps: 0.0,
            neutral_pw: f64::from(neutral),
            mps_per_pw: if delta == 0.0 {
                0.0
            } else {
                forward_speed_mps / delta
            },
        }
    }

    fn command(&mut self, pw: u16, ramp: u8) {
        self.target_pw = f64::from(pw);
        let t = ramp_full_excursion_s(ramp);
        self.slew_pw_per_s = if t > 0.0 { PW_SPAN / t } else { f64::INFINITY };
    }

    fn step(&mut self, dt: f64, tau_s: f64) -> f64 {
        let max = self.slew_pw_per_s * dt;
        self.pw += (self.target_pw - self.pw).clamp(-max, max);
        let commanded = (self.pw - self.neutral_pw) * self.mps_per_pw;
        let a = if tau_s > 0.0 {
            1.0 - (-dt / tau_s).exp()
        } else {
            1.0
        };
        self.speed_mps += (commanded - self.speed_mps) * a;
        self.speed_mps
    }
}

/// Dead reckoning state.
#[derive(Debug, Clone)]
pub struct Odometry {
    config: RobotConfig,
    left: Wheel,
    right: Wheel,
    pose: DeadReckonedPose,
    distance_m: f64,
    time_ns: Option<u64>,
    /// The heading's online calibration (`[nav.calibration]`), when on.
    calibration: Option<HeadingCalibration>,
}

impl Odometry {
    /// Starts at the origin, stopped, with the robot's pulse table.
    pub fn new(config: RobotConfig, pulses: &PulseTable) -> Self {
        Self {
            config,
            left: Wheel::new(
                pulses.neutral.left,
                pulses.forward.left,
                config.forward_speed_mps,
            ),
            right: Wheel::new(
                pulses.neutral.right,
                pulses.forward.right,
                config.forward_speed_mps,
            ),
            pose: DeadReckonedPose::default(),
            distance_m: 0.0,
            time_ns: None,
            calibration: None,
        }
    }

    /// Calibrates the heading online from the fixes passed to [`Odometry::fix_heading`]
    /// (`cfg.enabled`; off otherwise).
    pub fn with_calibration(mut self, cfg: CalibrationConfig) -> Self {
        self.calibration = cfg.enabled.then(|| HeadingCalibration::new(cfg));
        self
    }

    /// The frame ends (see [`HeadingCalibration::end_frame`]).
    pub fn end_frame(&mut self, settled: bool) {
        if let Some(c) = self.calibration.as_mut() {
            c.end_frame(settled);
        }
    }

    /// The calibration, when on.
    pub fn calibration(&self) -> Option<&HeadingCalibration> {
        self.calibration.as_ref()
    }

    /// Integrates up to `time_ns` (CLOCK_MONOTONIC; earlier times are ignored).
    pub fn advance_to(&mut self, time_ns: u64) {
        let Some(t0) = self.time_ns else {
            self.time_ns = Some(time_ns);
            return;
        };
        if time_ns <= t0 {
            return;
        }
        let total = (time_ns - t0) as f64 * 1e-9;
        let n = (total / STEP_S).ceil().max(1.0) as usize;
        let dt = total / n as f64;
        for _ in 0..n {
            let vl = self.left.step(dt, self.config.motor_tau_s);
            let vr = self.right.step(dt, self.config.motor_tau_s);
            let v = 0.5 * (vl + vr);
            let w = (vr - vl) / self.config.track_m;
            let dh = match self.calibration.as_mut() {
                Some(c) => c.heading_step(w * dt, v * dt, vl * vr < 0.0),
                None => w * dt,
            };
            let mid = self.pose.heading_rad + 0.5 * dh;
            self.pose.x_m += v * dt * mid.cos();
            self.pose.y_m += v * dt * mid.sin();
            self.pose.heading_rad += dh;
            self.distance_m += v.abs() * dt;
        }
        self.time_ns = Some(time_ns);
    }

    /// A command went on the wire at `sent_ns` (takes effect from then on).
    pub fn on_sent(&mut self, sent_ns: u64, left_pw: u16, right_pw: u16, ramp: u8) {
        self.advance_to(sent_ns);
        self.left.command(left_pw, ramp);
        self.right.command(right_pw, ramp);
    }

    /// The current pose estimate.
    pub fn pose(&self) -> DeadReckonedPose {
        self.pose
    }

    /// Turns the heading estimate by `delta_rad`, a measured fix (the walls' directions, the
    /// scan aligned to the grid): the calibration learns from it.
    pub fn fix_heading(&mut self, delta_rad: f64) {
        self.pose.heading_rad += delta_rad;
        if let Some(c) = self.calibration.as_mut() {
            c.observe_fix(delta_rad);
        }
    }

    /// Turns the heading estimate by `delta_rad`, a pose put back (motion integrated that
    /// did not happen): the calibration leaves the motion since its sample began out.
    pub fn correct_heading(&mut self, delta_rad: f64) {
        self.pose.heading_rad += delta_rad;
        if let Some(c) = self.calibration.as_mut() {
            c.discard_interval();
        }
    }

    /// Moves the pose estimate by `(dx_m, dy_m)` (a fix from aligning a scan to the map).
    pub fn correct_position(&mut self, dx_m: f64, dy_m: f64) {
        self.pose.x_m += dx_m;
        self.pose.y_m += dy_m;
    }

    /// Distance driven (forwards or backwards), metres.
    pub fn distance_m(&self) -> f64 {
        self.distance_m
    }

    /// Current turn rate estimate, rad/s (counter-clockwise positive).
    pub fn turn_rate_rad_s(&self) -> f64 {
        (self.right.speed_mps - self.left.speed_mps) / self.config.track_m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn odo() -> Odometry {
        Odometry::new(RobotConfig::default(), &PulseTable::default())
    }

    #[test]
    fn forward_pulses_drive_straight_at_the_calibrated_speed() {
        let mut o = odo();
        let p = PulseTable::default();
        o.on_sent(0, p.forward.left, p.forward.right, 0);
        o.advance_to(10_000_000_000);
        let pose = o.pose();
        // 10 s at 0.274 m/s, minus the motor lag (tau 0.1 s).
        assert!((pose.x_m - 2.74).abs() < 0.05, "{pose:?}");
        assert!(pose.y_m.abs() < 1e-9 && pose.heading_rad.abs() < 1e-9);
        o.on_sent(10_000_000_000, p.neutral.left, p.neutral.right, 0);
        o.advance_to(12_000_000_000);
        assert!((o.pose().x_m - pose.x_m).abs() < 0.05);
    }

    #[test]
    fn turn_pulses_turn_the_right_way_and_the_ramp_slows_the_start() {
        let p = PulseTable::default();
        let mut fast = odo();
        fast.on_sent(0, p.left.left, p.left.right, 0);
        fast.advance_to(300_000_000);
        assert!(fast.pose().heading_rad > 0.3, "{:?}", fast.pose());
        let mut ramped = odo();
        ramped.on_sent(0, p.left.left, p.left.right, 10);
        ramped.advance_to(300_000_000);
        assert!(ramped.pose().heading_rad > 0.0);
        assert!(ramped.pose().heading_rad < 0.25 * fast.pose().heading_rad);
        let mut right = odo();
        right.on_sent(0, p.right.left, p.right.right, 0);
        right.advance_to(300_000_000);
        assert!(right.pose().heading_rad < -0.3);
    }

    #[test]
    fn ramp_times_follow_the_psc_data_sheet() {
        assert_eq!(ramp_full_excursion_s(0), 0.0);
        assert!((ramp_full_excursion_s(1) - 0.75).abs() < 1e-12);
        assert!((ramp_full_excursion_s(63) - 60.0).abs() < 1e-12);
    }
}
