//! Skid-steer robot driven by the PSC's pulse widths, with first-order motor lag and collisions
//! against the map's walls.
//!
//! Wheel speed from pulse width (the reference's measured table): left wheels (channel 1,
//! neutral 760, forward 720) and right wheels (channel 5, neutral 758, forward 800) both move at
//! 0.274 m/s forward, so `v_left = (760 - pw_left) * 0.274 / 40` and
//! `v_right = (pw_right - 758) * 0.274 / 42` m/s, with a small deadband around neutral and a clamp
//! at the motors' top speed (265 rpm on 0.171 m wheels = 2.37 m/s).
//!
//! Body motion: `v = (v_l + v_r) / 2`, `omega = (v_r - v_l) / track_eff_m`. Skid steering
//! scrubs the wheels sideways, so the effective track is wider than the geometric one
//! (about 0.28 m between wheel centres). We use 0.55 m (about twice the geometric track, a common
//! skid-steer slip factor): the reference's left-turn pulses (right 840, left 920) then turn at
//! about 170 deg/s and its right-turn pulses (right 510, left 600) at about 280 deg/s; with the
//! reference's ramped turn commands that gives turns of up to 90 degrees in one 1.9 s cycle.
//!
//! With [`Robot::with_motion_noise`] the wheels do not quite do what the pulses command
//! (`[sim.motion]`, [`crate::noise`]): each motor's target is the commanded speed times a
//! per-wheel factor (a constant scale error and a slowly varying error), and turns in place
//! lose a fraction of their rate to skidding. Without it (the default) the robot moves exactly
//! as commanded.

use crate::map::{GridMap, Pose};
use crate::noise::WheelNoise;

/// Robot and motor parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RobotParams {
    /// Footprint width (across), metres.
    pub width_m: f64,
    /// Footprint length (along the heading), metres.
    pub length_m: f64,
    /// PSC channel of the left wheels.
    pub left_channel: u8,
    /// PSC channel of the right wheels.
    pub right_channel: u8,
    /// Neutral (stop) pulse of the left wheels, 2 us units.
    pub left_neutral_pw: f64,
    /// Neutral (stop) pulse of the right wheels, 2 us units.
    pub right_neutral_pw: f64,
    /// Forward pulse of the left wheels, 2 us units (below neutral: the left motor is mirrored).
    pub left_forward_pw: f64,
    /// Forward pulse of the right wheels, 2 us units.
    pub right_forward_pw: f64,
    /// Wheel speed at the forward pulses, m/s.
    pub forward_speed_mps: f64,
    /// Pulses within this many units of neutral stop the motor.
    pub deadband_pw: f64,
    /// Top wheel speed, m/s.
    pub max_wheel_speed_mps: f64,
    /// Time constant of the first-order motor lag, seconds.
    pub motor_tau_s: f64,
    /// Effective skid-steer track width, metres.
    pub track_eff_m: f64,
    /// Largest internal integration step, seconds.
    pub max_step_s: f64,
}

impl Default for RobotParams {
    fn default() -> Self {
        RobotParams {
            width_m: 0.311,
            length_m: 0.438,
            left_channel: 1,
            right_channel: 5,
            left_neutral_pw: 760.0,
            right_neutral_pw: 758.0,
            left_forward_pw: 720.0,
            right_forward_pw: 800.0,
            forward_speed_mps: 0.274,
            deadband_pw: 2.0,
            max_wheel_speed_mps: 2.37,
            motor_tau_s: 0.1,
            track_eff_m: 0.55,
            max_step_s: 0.002,
        }
    }
}

impl RobotParams {
    /// Commanded left wheel speed for a pulse (None = no pulse = stopped), m/s.
    pub fn left_speed_mps(&self, pw: Option<f64>) -> f64 {
        self.wheel_speed(pw, self.left_neutral_pw, self.left_forward_pw)
    }

    /// Commanded right wheel speed for a pulse (None = no pulse = stopped), m/s.
    pub fn right_speed_mps(&self, pw: Option<f64>) -> f64 {
        self.wheel_speed(pw, self.right_neutral_pw, self.right_forward_pw)
    }

    fn wheel_speed(&self, pw: Option<f64>, neutral: f64, forward: f64) -> f64 {
        let Some(pw) = pw.filter(|p| p.is_finite()) else {
            return 0.0;
        };
        let delta = pw - neutral;
        if delta.abs() <= self.deadband_pw || forward == neutral {
            return 0.0;
        }
        let v = delta * self.forward_speed_mps / (forward - neutral);
        v.clamp(-self.max_wheel_speed_mps, self.max_wheel_speed_mps)
    }
}

/// The simulated robot.
#[derive(Debug, Clone, PartialEq)]
pub struct Robot {
    params: RobotParams,
    pose: Pose,
    /// Actual wheel speeds after the motor lag, m/s.
    v_left_mps: f64,
    v_right_mps: f64,
    in_collision: bool,
    collisions: u64,
    odometer_m: f64,
    last_contact_odometer_m: Option<f64>,
    /// Wheel slip and speed errors (`None`: the wheels do exactly what is commanded).
    noise: Option<WheelNoise>,
}

impl Robot {
    /// A robot at rest at `pose` whose wheels do exactly what the pulses command.
    pub fn new(params: RobotParams, pose: Pose) -> Self {
        Robot {
            params,
            pose,
            v_left_mps: 0.0,
            v_right_mps: 0.0,
            in_collision: false,
            collisions: 0,
            odometer_m: 0.0,
            last_contact_odometer_m: None,
            noise: None,
        }
    }

    /// This robot with wheel slip and speed errors (`None`: none).
    pub fn with_motion_noise(mut self, noise: Option<WheelNoise>) -> Self {
        self.noise = noise;
        self
    }

    /// The wheel slip and speed errors, if any.
    pub fn motion_noise(&self) -> Option<&WheelNoise> {
        self.noise.as_ref()
    }

    /// Parameters.
    pub fn params(&self) -> &RobotParams {
        &self.params
    }

    /// Current pose.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// Moves the robot (teleport; clears the collision state and wheel speeds).
    pub fn set_pose(&mut self, pose: Pose) {
        self.pose = pose;
        self.v_left_mps = 0.0;
        self.v_right_mps = 0.0;
        self.in_collision = false;
    }

    /// Actual (lagged) wheel speeds (left, right), m/s.
    pub fn wheel_speeds_mps(&self) -> (f64, f64) {
        (self.v_left_mps, self.v_right_mps)
    }

    /// Forward speed of the body, m/s (0 while blocked by a wall).
    pub fn speed_mps(&self) -> f64 {
        if self.in_collision {
            0.0
        } else {
            0.5 * (self.v_left_mps + self.v_right_mps)
        }
    }

    /// Whether the last step was blocked by a wall.
    pub fn in_collision(&self) -> bool {
        self.in_collision
    }

    /// Number of collision events (rising edges of [`Robot::in_collision`]).
    pub fn collisions(&self) -> u64 {
        self.collisions
    }

    /// Distance travelled by the centre, metres.
    pub fn odometer_m(&self) -> f64 {
        self.odometer_m
    }

    /// Whether the footprint at `pose` overlaps a wall.
    pub fn footprint_hits_wall(&self, pose: &Pose, map: &GridMap) -> bool {
        map.rect_hits_wall(pose, self.params.length_m, self.params.width_m)
    }

    /// Advances `dt_s` seconds with constant pulses (`None` = no pulse, motor stopped), using
    /// internal steps of at most `max_step_s`. A move that would make the footprint overlap a
    /// wall is not taken (a pure rotation is still tried, so the robot can turn away from a
    /// wall it touches); instead the robot advances until it touches the wall. Such a step sets
    /// `in_collision`; a contact counts as a new collision event once the robot has travelled
    /// at least 1 cm since its previous contact.
    pub fn step(&mut self, dt_s: f64, left_pw: Option<f64>, right_pw: Option<f64>, map: &GridMap) {
        if !(dt_s.is_finite() && dt_s > 0.0) {
            return;
        }
        let p = self.params;
        let vl_cmd = p.left_speed_mps(left_pw);
        let vr_cmd = p.right_speed_mps(right_pw);
        let n = (dt_s / p.max_step_s).ceil().max(1.0) as usize;
        let h = dt_s / n as f64;
        let alpha = if p.motor_tau_s > 0.0 {
            1.0 - (-h / p.motor_tau_s).exp()
        } else {
            1.0
        };
        for _ in 0..n {
            let (fl, fr) = self.noise.as_mut().map_or((1.0, 1.0), |w| w.step(h));
            self.v_left_mps += (vl_cmd * fl - self.v_left_mps) * alpha;
            self.v_right_mps += (vr_cmd * fr - self.v_right_mps) * alpha;
            let v = 0.5 * (self.v_left_mps + self.v_right_mps);
            let mut omega = (self.v_right_mps - self.v_left_mps) / p.track_eff_m;
            if let Some(w) = &self.noise {
                omega *= w.turn_kept(self.v_left_mps, self.v_right_mps);
            }
            if v == 0.0 && omega == 0.0 {
                self.in_collision = false;
                continue;
            }
            // Exact arc over the step (midpoint heading for the chord).
            let dth = omega * h;
            let chord = if dth.abs() > 1e-9 {
                2.0 * v / omega * (0.5 * dth).sin()
            } else {
                v * h
            };
            let mid = self.pose.heading_rad + 0.5 * dth;
            let next = Pose::new(
                self.pose.x_m + chord * mid.cos(),
                self.pose.y_m + chord * mid.sin(),
                wrap_angle(self.pose.heading_rad + dth),
            );
            if !self.footprint_hits_wall(&next, map) {
                self.pose = next;
                self.odometer_m += chord.abs();
                self.in_collision = false;
                continue;
            }
            // Blocked: move as far along the step as possible (bisection), so the robot ends up
            // touching the wall instead of hovering a step short of it.
            let (mut lo, mut hi) = (0.0f64, 1.0f64);
            for _ in 0..24 {
                let mid_f = 0.5 * (lo + hi);
                if self.footprint_hits_wall(&lerp_pose(&self.pose, &next, mid_f), map) {
                    hi = mid_f;
                } else {
                    lo = mid_f;
                }
            }
            if lo > 0.0 {
                self.pose = lerp_pose(&self.pose, &next, lo);
                self.odometer_m += chord.abs() * lo;
            }
            // A new contact counts once the robot has moved at least 1 cm since the last one
            // (so decelerating against a wall is one event, not many).
            if !self.in_collision
                && (self
                    .last_contact_odometer_m
                    .is_none_or(|o| self.odometer_m - o > 0.01))
            {
                self.collisions += 1;
            }
            self.in_collision = true;
            self.last_contact_odometer_m = Some(self.odometer_m);
            let turn = Pose::new(self.pose.x_m, self.pose.y_m, next.heading_rad);
            if dth != 0.0 && !self.footprint_hits_wall(&turn, map) {
                self.pose = turn;
            }
        }
    }
}

/// Pose a fraction `f` of the way from `a` to `b` (headings interpolated the short way).
fn lerp_pose(a: &Pose, b: &Pose, f: f64) -> Pose {
    Pose::new(
        a.x_m + (b.x_m - a.x_m) * f,
        a.y_m + (b.y_m - a.y_m) * f,
        wrap_angle(a.heading_rad + wrap_angle(b.heading_rad - a.heading_rad) * f),
    )
}

/// Wraps an angle to (-pi, pi].
pub fn wrap_angle(a: f64) -> f64 {
    let two_pi = 2.0 * std::f64::consts::PI;
    let mut r = a.rem_euclid(two_pi);
    if r > std::f64::consts::PI {
        r -= two_pi;
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::noise::SimMotionNoise;

    fn open_map() -> GridMap {
        // 20 m x 20 m empty room (cells of 1 m), start in the middle facing east.
        let mut text = String::from("@cell_m 1\n");
        text.push_str(&"#".repeat(22));
        text.push('\n');
        for r in 0..20 {
            text.push('#');
            for c in 0..20 {
                text.push(if r == 10 && c == 10 { '>' } else { '.' });
            }
            text.push_str("#\n");
        }
        text.push_str(&"#".repeat(22));
        GridMap::parse(&text, "open").unwrap()
    }

    #[test]
    fn wheel_speed_table() {
        let p = RobotParams::default();
        assert!((p.left_speed_mps(Some(720.0)) - 0.274).abs() < 1e-12);
        assert!((p.right_speed_mps(Some(800.0)) - 0.274).abs() < 1e-12);
        assert_eq!(p.left_speed_mps(Some(760.0)), 0.0);
        assert_eq!(p.right_speed_mps(Some(758.0)), 0.0);
        assert_eq!(p.right_speed_mps(Some(759.5)), 0.0, "deadband");
        assert_eq!(p.left_speed_mps(None), 0.0);
        assert!(
            (p.left_speed_mps(Some(800.0)) + 0.274).abs() < 1e-12,
            "reverse"
        );
        assert_eq!(p.right_speed_mps(Some(1250.0)), 2.37, "clamped");
    }

    #[test]
    fn drives_forward_at_measured_speed() {
        let map = open_map();
        let start = map.start_pose();
        let mut r = Robot::new(RobotParams::default(), start);
        r.step(5.0, Some(720.0), Some(800.0), &map);
        let d = r.pose().x_m - start.x_m;
        // 5 s at 0.274 m/s minus the lag (tau * v = 0.0274 m).
        assert!((d - (5.0 * 0.274 - 0.1 * 0.274)).abs() < 2e-3, "{d}");
        assert!((r.pose().y_m - start.y_m).abs() < 1e-9);
        assert!((r.speed_mps() - 0.274).abs() < 1e-3);
        assert_eq!(r.collisions(), 0);
    }

    #[test]
    fn neutral_and_no_pulse_stay_put() {
        let map = open_map();
        let start = map.start_pose();
        let mut r = Robot::new(RobotParams::default(), start);
        r.step(3.0, Some(760.0), Some(758.0), &map);
        r.step(3.0, None, None, &map);
        assert_eq!(r.pose(), start);
    }

    #[test]
    fn left_turn_pulses_turn_ccw() {
        let map = open_map();
        let start = map.start_pose();
        let mut r = Robot::new(RobotParams::default(), start);
        r.step(0.3, Some(920.0), Some(840.0), &map);
        let turned = wrap_angle(r.pose().heading_rad - start.heading_rad);
        assert!(turned > 0.3, "left turn is CCW: {turned}");
        let mut r = Robot::new(RobotParams::default(), start);
        r.step(0.3, Some(600.0), Some(510.0), &map);
        let turned = wrap_angle(r.pose().heading_rad - start.heading_rad);
        assert!(turned < -0.3, "right turn is CW: {turned}");
        // Steady-state left-turn rate with the documented track width.
        let p = RobotParams::default();
        let rate = (p.right_speed_mps(Some(840.0)) - p.left_speed_mps(Some(920.0))) / p.track_eff_m;
        assert!(
            (rate.to_degrees() - 170.0).abs() < 5.0,
            "{}",
            rate.to_degrees()
        );
    }

    fn noisy(noise: SimMotionNoise, seed: u64, start: Pose) -> Robot {
        Robot::new(RobotParams::default(), start).with_motion_noise(WheelNoise::new(noise, seed))
    }

    #[test]
    fn motion_noise_off_moves_exactly_as_commanded() {
        let map = open_map();
        let start = map.start_pose();
        let mut a = Robot::new(RobotParams::default(), start);
        let mut b = noisy(SimMotionNoise::off(), 5, start);
        assert!(b.motion_noise().is_none());
        for (l, r) in [(720.0, 800.0), (810.0, 808.0), (700.0, 790.0)] {
            a.step(1.3, Some(l), Some(r), &map);
            b.step(1.3, Some(l), Some(r), &map);
        }
        assert_eq!(a, b);
    }

    #[test]
    fn turn_slip_loses_the_configured_share_of_a_turn_in_place() {
        let map = open_map();
        let start = map.start_pose();
        let slip = SimMotionNoise {
            turn_slip: 0.05,
            ..SimMotionNoise::off()
        };
        let turn = |mut r: Robot| {
            // The shipped left-turn pulses (each wheel 50 units from neutral), 1 s.
            r.step(1.0, Some(810.0), Some(808.0), &map);
            let p = r.pose();
            (wrap_angle(p.heading_rad - start.heading_rad), p)
        };
        let (exact, p0) = turn(Robot::new(RobotParams::default(), start));
        let (slipped, p1) = turn(noisy(slip, 1, start));
        assert!(exact > 1.0, "{exact}");
        assert!((slipped / exact - 0.95).abs() < 0.01, "{slipped} / {exact}");
        assert!((p0.x_m - p1.x_m).abs() < 1e-3 && (p0.y_m - p1.y_m).abs() < 1e-3);
        // Straight driving is unchanged by turn slip alone.
        let mut a = Robot::new(RobotParams::default(), start);
        let mut b = noisy(slip, 1, start);
        a.step(3.0, Some(720.0), Some(800.0), &map);
        b.step(3.0, Some(720.0), Some(800.0), &map);
        assert_eq!(a.pose(), b.pose());
    }

    #[test]
    fn realistic_noise_makes_the_robot_drift_from_the_commanded_path() {
        let map = open_map();
        let start = map.start_pose();
        let mut exact = Robot::new(RobotParams::default(), start);
        let mut drifts = Vec::new();
        for seed in 0..8 {
            let mut r = noisy(SimMotionNoise::realistic(), seed, start);
            r.step(20.0, Some(720.0), Some(800.0), &map);
            drifts.push((r.pose().y_m - start.y_m).abs());
            // Deterministic per seed.
            let mut again = noisy(SimMotionNoise::realistic(), seed, start);
            again.step(20.0, Some(720.0), Some(800.0), &map);
            assert_eq!(r.pose(), again.pose());
        }
        exact.step(20.0, Some(720.0), Some(800.0), &map);
        assert!((exact.pose().y_m - start.y_m).abs() < 1e-9);
        // 5.5 m at 2 % scale errors: the heading wanders by degrees, the robot by decimetres.
        let mean = drifts.iter().sum::<f64>() / drifts.len() as f64;
        assert!(mean > 0.05 && mean < 3.0, "{drifts:?}");
    }

    #[test]
    fn wall_stops_robot_and_counts_once() {
        let map = open_map();
        let start = map.start_pose(); // x = 10.5, wall face at x = 21
        let mut r = Robot::new(RobotParams::default(), start);
        r.step(60.0, Some(720.0), Some(800.0), &map);
        let front = r.pose().x_m + 0.219;
        assert!(
            front < 21.0 && front > 20.9999,
            "stopped touching the wall: {front}"
        );
        assert!(r.in_collision());
        assert_eq!(r.collisions(), 1, "continuous contact is one event");
        assert_eq!(r.speed_mps(), 0.0);
        // Back off, then hit again: a second event.
        r.step(2.0, Some(800.0), Some(716.0), &map);
        assert!(!r.in_collision());
        assert!(r.pose().x_m + 0.219 < 20.6);
        r.step(10.0, Some(720.0), Some(800.0), &map);
        assert_eq!(r.collisions(), 2);
        assert!(!r.footprint_hits_wall(&r.pose(), &map));
    }
}
