//! [`SimWorld`]: map + robot + PSC emulator + stereo rig + webcam defects on one clock.
//!
//! Time is in seconds on the caller's clock (the same clock must stamp the bytes fed to the PSC
//! emulator, e.g. [`crate::pty::SimClock`]). The PSC emulator is shared behind a mutex so that
//! the pty reader thread can feed it while the world integrates the robot from its outputs.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};

use crate::defects::{DefectsError, SimRng, WebcamDefects, sim_rng};
use crate::map::{GridMap, Pose};
use crate::noise::{SimMotionNoise, WheelNoise};
use crate::psc::PscEmulator;
use crate::render::{RenderError, Renderer, StereoRig};
use crate::robot::{Robot, RobotParams, wrap_angle};

/// A PSC emulator shared between the world and the serial (pty) side.
pub type SharedPsc = Arc<Mutex<PscEmulator>>;

/// Locks a shared PSC, ignoring poisoning (the emulator's state stays consistent per call).
pub fn lock_psc(psc: &SharedPsc) -> MutexGuard<'_, PscEmulator> {
    psc.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Configuration of a [`SimWorld`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimConfig {
    /// Camera rig (image size, focal length, baseline, mounting).
    pub rig: StereoRig,
    /// Webcam defects (the right camera's delay included).
    pub defects: WebcamDefects,
    /// Robot and motor parameters (PSC channels included).
    pub robot: RobotParams,
    /// Wheel slip and speed errors of the robot (`[sim.motion]`; off by default).
    pub motion: SimMotionNoise,
    /// Seed of the image noise and of the motion noise (separate streams).
    pub seed: u64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            rig: StereoRig::vga(),
            defects: WebcamDefects::none(),
            robot: RobotParams::default(),
            motion: SimMotionNoise::off(),
            seed: 1,
        }
    }
}

impl SimConfig {
    /// The simulator settings of an hvs config, rendering `width x height` images: camera
    /// focal length, baseline and mount, webcam defects, the robot's body (`[robot]`, the
    /// description the navigator also uses), PSC channels, the motion noise (`[sim.motion]`)
    /// and seed.
    pub fn from_hvs(config: &hvs_runtime::config::HvsConfig, width: usize, height: usize) -> Self {
        let mut rig = StereoRig::new(width, height, config.camera.focal_px(width));
        rig.baseline_m = config.camera.baseline_m;
        rig.camera_forward_m = config.camera.forward_m;
        let d = &config.sim.defects;
        SimConfig {
            rig,
            defects: WebcamDefects {
                gain: d.gain,
                offset: d.offset,
                noise_sigma: d.noise_sigma,
                vertical_shift_px: d.vertical_shift_px,
                right_delay_s: d.right_delay_ms / 1000.0,
            },
            robot: RobotParams {
                width_m: config.robot.width_m,
                length_m: config.robot.length_m,
                track_eff_m: config.robot.track_m,
                forward_speed_mps: config.robot.forward_speed_mps,
                motor_tau_s: config.robot.motor_tau_s,
                left_channel: config.actuator.left_channel,
                right_channel: config.actuator.right_channel,
                ..RobotParams::default()
            },
            motion: config.sim.motion,
            seed: config.sim.seed,
        }
    }
}

/// Errors of [`SimWorld::render`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimRenderError {
    /// Rendering failed.
    #[error(transparent)]
    Render(#[from] RenderError),
    /// Applying defects failed.
    #[error(transparent)]
    Defects(#[from] DefectsError),
}

/// A snapshot of the simulator's ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GroundTruth {
    /// Simulation time of the snapshot, seconds.
    pub time_s: f64,
    /// Robot pose.
    pub pose: Pose,
    /// Body forward speed, m/s.
    pub speed_mps: f64,
    /// Actual wheel speeds (left, right), m/s.
    pub wheel_speeds_mps: (f64, f64),
    /// Whether the robot is pressed against a wall.
    pub in_collision: bool,
    /// Collision events so far.
    pub collisions: u64,
    /// PSC output pulse of the left wheels' channel (None = never commanded), 2 us units.
    pub left_pw: Option<f64>,
    /// PSC output pulse of the right wheels' channel, 2 us units.
    pub right_pw: Option<f64>,
    /// Distance driven, metres.
    pub odometer_m: f64,
}

/// How long the pose history is kept, seconds.
const HISTORY_S: f64 = 2.0;
/// Largest integration step of [`SimWorld::advance_to`], seconds.
const STEP_S: f64 = 0.005;

/// The simulated world.
#[derive(Debug)]
pub struct SimWorld {
    renderer: Renderer,
    robot: Robot,
    psc: SharedPsc,
    defects: WebcamDefects,
    rng: SimRng,
    time_s: f64,
    history: VecDeque<(f64, Pose)>,
}

impl SimWorld {
    /// A world at time 0 with the robot at the map's start pose and a fresh PSC.
    pub fn new(map: GridMap, config: SimConfig) -> Self {
        let start = map.start_pose();
        let mut history = VecDeque::new();
        history.push_back((0.0, start));
        SimWorld {
            renderer: Renderer::new(&map, config.rig),
            robot: Robot::new(config.robot, start)
                .with_motion_noise(WheelNoise::new(config.motion, config.seed)),
            psc: Arc::new(Mutex::new(PscEmulator::new())),
            defects: config.defects,
            rng: sim_rng(config.seed),
            time_s: 0.0,
            history,
        }
    }

    /// The shared PSC emulator (give it to [`crate::pty::PscPty::create`]).
    pub fn psc(&self) -> SharedPsc {
        Arc::clone(&self.psc)
    }

    /// The map.
    pub fn map(&self) -> &GridMap {
        self.renderer.map()
    }

    /// The camera rig.
    pub fn rig(&self) -> &StereoRig {
        self.renderer.rig()
    }

    /// The renderer.
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// The robot.
    pub fn robot(&self) -> &Robot {
        &self.robot
    }

    /// Current webcam defects.
    pub fn defects(&self) -> &WebcamDefects {
        &self.defects
    }

    /// Switches webcam defects.
    pub fn set_defects(&mut self, defects: WebcamDefects) {
        self.defects = defects;
    }

    /// Simulation time reached, seconds.
    pub fn time_s(&self) -> f64 {
        self.time_s
    }

    /// Robot pose now.
    pub fn pose(&self) -> Pose {
        self.robot.pose()
    }

    /// Teleports the robot (clears the pose history).
    pub fn set_pose(&mut self, pose: Pose) {
        self.robot.set_pose(pose);
        self.history.clear();
        self.history.push_back((self.time_s, pose));
    }

    /// Collision events so far.
    pub fn collisions(&self) -> u64 {
        self.robot.collisions()
    }

    /// Whether the robot is pressed against a wall.
    pub fn in_collision(&self) -> bool {
        self.robot.in_collision()
    }

    /// PSC output pulses (left, right wheels) now, 2 us units.
    pub fn pulses(&self) -> (Option<f64>, Option<f64>) {
        let p = self.robot.params();
        let psc = lock_psc(&self.psc);
        (
            psc.pulse_at(p.left_channel, self.time_s),
            psc.pulse_at(p.right_channel, self.time_s),
        )
    }

    /// A snapshot of the ground truth now.
    pub fn ground_truth(&self) -> GroundTruth {
        let (left_pw, right_pw) = self.pulses();
        GroundTruth {
            time_s: self.time_s,
            pose: self.robot.pose(),
            speed_mps: self.robot.speed_mps(),
            wheel_speeds_mps: self.robot.wheel_speeds_mps(),
            in_collision: self.robot.in_collision(),
            collisions: self.robot.collisions(),
            left_pw,
            right_pw,
            odometer_m: self.robot.odometer_m(),
        }
    }

    /// Integrates the robot up to `time_s` (no-op for earlier times) from the PSC outputs,
    /// sampled at the middle of steps of at most 5 ms.
    pub fn advance_to(&mut self, time_s: f64) {
        if !(time_s.is_finite() && time_s > self.time_s) {
            return;
        }
        let n = ((time_s - self.time_s) / STEP_S).ceil().max(1.0) as usize;
        let h = (time_s - self.time_s) / n as f64;
        let params = *self.robot.params();
        let pulses: Vec<(Option<f64>, Option<f64>)> = {
            let psc = lock_psc(&self.psc);
            (0..n)
                .map(|i| {
                    let t = self.time_s + (i as f64 + 0.5) * h;
                    (
                        psc.pulse_at(params.left_channel, t),
                        psc.pulse_at(params.right_channel, t),
                    )
                })
                .collect()
        };
        let map = self.renderer.map();
        for (i, (l, r)) in pulses.into_iter().enumerate() {
            self.robot.step(h, l, r, map);
            let t = self.time_s + (i as f64 + 1.0) * h;
            self.history.push_back((t, self.robot.pose()));
        }
        self.time_s = time_s;
        lock_psc(&self.psc).commit_until(time_s);
        while self.history.len() > 2 && self.history[1].0 < time_s - HISTORY_S {
            self.history.pop_front();
        }
    }

    /// Robot pose at `time_s` from the recent history (linear interpolation; clamped to the
    /// oldest kept pose and to the current one).
    pub fn pose_at(&self, time_s: f64) -> Pose {
        let Some(&(t_last, p_last)) = self.history.back() else {
            return self.robot.pose();
        };
        if time_s >= t_last {
            return p_last;
        }
        let idx = self.history.partition_point(|(t, _)| *t <= time_s);
        if idx == 0 {
            return self.history[0].1;
        }
        let (t0, p0) = self.history[idx - 1];
        let (t1, p1) = self.history[idx];
        let a = if t1 > t0 {
            (time_s - t0) / (t1 - t0)
        } else {
            1.0
        };
        Pose::new(
            p0.x_m + (p1.x_m - p0.x_m) * a,
            p0.y_m + (p1.y_m - p0.y_m) * a,
            wrap_angle(p0.heading_rad + wrap_angle(p1.heading_rad - p0.heading_rad) * a),
        )
    }

    /// Renders the stereo pair seen at `time_s`: the left eye from the pose at `time_s`, the
    /// right eye from the pose at `time_s + right_delay_s` (advancing the world as needed), then
    /// applies the webcam defects. `gt_disparity_q8` receives the left image's ideal disparity.
    pub fn render(
        &mut self,
        time_s: f64,
        left: &mut [u8],
        right: &mut [u8],
        gt_disparity_q8: Option<&mut [u16]>,
    ) -> Result<(), SimRenderError> {
        let t_right = time_s + self.defects.right_delay_s;
        self.advance_to(time_s.max(t_right));
        let pose_left = self.pose_at(time_s);
        let pose_right = self.pose_at(t_right);
        self.renderer
            .render_pair(&pose_left, &pose_right, left, right, gt_disparity_q8)?;
        let rig = self.renderer.rig();
        self.defects
            .apply(left, right, rig.width, rig.height, &mut self.rng)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::psc::encode_position;

    fn hallway() -> GridMap {
        let mut t = String::from("@cell_m 0.5\n");
        t.push_str(&"#".repeat(40));
        t.push('\n');
        for r in 0..3 {
            t.push('#');
            for c in 0..38 {
                t.push(if r == 1 && c == 1 { '>' } else { '.' });
            }
            t.push_str("#\n");
        }
        t.push_str(&"#".repeat(40));
        GridMap::parse(&t, "hall").unwrap()
    }

    fn config() -> SimConfig {
        SimConfig {
            rig: StereoRig::qvga(),
            ..SimConfig::default()
        }
    }

    #[test]
    fn psc_commands_drive_the_robot() {
        let mut w = SimWorld::new(hallway(), config());
        let start = w.pose();
        let psc = w.psc();
        {
            let mut p = lock_psc(&psc);
            p.receive(&encode_position(1, 0, 720), 0.0);
            p.receive(&encode_position(5, 0, 800), 0.0);
        }
        w.advance_to(2.0);
        let d = w.pose().x_m - start.x_m;
        // Motors start 16 byte times (67 ms) later and lag 0.1 s.
        let expect = 0.274 * (2.0 - 16.0 / 240.0 - 0.1);
        assert!((d - expect).abs() < 0.01, "{d} vs {expect}");
        let gt = w.ground_truth();
        assert_eq!((gt.left_pw, gt.right_pw), (Some(720.0), Some(800.0)));
        assert!((gt.speed_mps - 0.274).abs() < 1e-3);
        assert_eq!(w.time_s(), 2.0);
        // Neutral stops it (after the lag).
        lock_psc(&psc).receive(&encode_position(1, 0, 760), 2.0);
        lock_psc(&psc).receive(&encode_position(5, 0, 758), 2.0);
        w.advance_to(3.5);
        let x = w.pose().x_m;
        w.advance_to(5.0);
        assert!((w.pose().x_m - x).abs() < 1e-4);
    }

    #[test]
    fn motion_noise_comes_from_the_config_and_its_seed() {
        let drive = |motion: SimMotionNoise, seed: u64| {
            let mut w = SimWorld::new(
                hallway(),
                SimConfig {
                    motion,
                    seed,
                    ..config()
                },
            );
            let psc = w.psc();
            lock_psc(&psc).receive(&encode_position(1, 0, 720), 0.0);
            lock_psc(&psc).receive(&encode_position(5, 0, 800), 0.0);
            w.advance_to(10.0);
            w.pose()
        };
        let exact = drive(SimMotionNoise::off(), 1);
        assert_eq!(
            exact,
            drive(SimMotionNoise::off(), 2),
            "off: the seed does not matter"
        );
        let a = drive(SimMotionNoise::realistic(), 1);
        assert_eq!(a, drive(SimMotionNoise::realistic(), 1));
        assert_ne!(a, drive(SimMotionNoise::realistic(), 2));
        assert_ne!(a, exact);
        let map = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/maps/maze.txt");
        let text = format!("[sim]\nseed = 4\nmap = \"{map}\"\n[sim.motion]\nturn_slip = 0.05\n");
        let hvs = hvs_runtime::config::HvsConfig::parse(&text, std::path::Path::new("/x/t.toml"))
            .expect("valid");
        let c = SimConfig::from_hvs(&hvs, 320, 240);
        assert_eq!(c.seed, 4);
        assert_eq!(c.motion.turn_slip, 0.05);
    }

    #[test]
    fn delayed_right_eye_sees_a_later_pose() {
        let mut cfg = config();
        cfg.defects.right_delay_s = 0.5;
        let mut w = SimWorld::new(hallway(), cfg);
        let psc = w.psc();
        lock_psc(&psc).receive(&encode_position(1, 0, 720), 0.0);
        lock_psc(&psc).receive(&encode_position(5, 0, 800), 0.0);
        let n = w.rig().pixels();
        let (mut l, mut r) = (vec![0u8; n], vec![0u8; n]);
        w.render(1.0, &mut l, &mut r, None).unwrap();
        assert!(
            (w.time_s() - 1.5).abs() < 1e-12,
            "advanced to the right eye's time"
        );
        let p1 = w.pose_at(1.0);
        let p15 = w.pose_at(1.5);
        assert!((p15.x_m - p1.x_m - 0.5 * 0.274).abs() < 0.01);
        // The right image equals a render from the later pose.
        let (mut l2, mut r2) = (vec![0u8; n], vec![0u8; n]);
        w.renderer()
            .render_pair(&p1, &p15, &mut l2, &mut r2, None)
            .unwrap();
        assert_eq!(l, l2);
        assert_eq!(r, r2);
        let (mut l3, mut r3) = (vec![0u8; n], vec![0u8; n]);
        w.renderer()
            .render_pair(&p1, &p1, &mut l3, &mut r3, None)
            .unwrap();
        assert_ne!(r, r3, "a synchronised right eye would see something else");
    }
}
