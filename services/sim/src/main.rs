//! Simulator stage process: the default world of `hvs run`.
//!
//! Renders the simulated Minoru's 640x480 pair at camera rate directly into a loaned
//! shared-memory sample (`sim/camera/640x480`) with its exact disparity
//! (`sim/gt_disparity/640x480`), serves the emulated Parallax Servo Controller on
//! a pseudo-terminal that the actuator opens like `/dev/ttyUSB0`, drives the robot from the
//! pulses it receives, and publishes the ground truth (`sim/truth`).

use std::process::ExitCode;
use std::time::Duration;

use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::{run_dir, sim_pty_path};
use hvs_runtime::ipc::attach_interval;
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{
    DisparityHeader, FrameHeader, FrameSource, HI_HEIGHT, HI_WIDTH, SimTruth,
};
use hvs_shared::topics::{self, Stage};
use hvs_sim::{GridMap, PscPty, SimClock, SimConfig, SimWorld, lock_psc};

fn main() -> ExitCode {
    run_stage(Stage::Sim, run)
}

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let cfg = rt.config.clone();
    let map_path = cfg.resolve_path(&cfg.sim.map);
    let map = GridMap::load(&map_path)?;
    let start = map.start_pose();
    let mut world = SimWorld::new(map, SimConfig::from_hvs(&cfg, HI_WIDTH, HI_HEIGHT));
    let clock = SimClock::new();
    let run_folder = run_dir(&cfg.instance);
    std::fs::create_dir_all(&run_folder)
        .map_err(|e| format!("cannot create run folder {}: {e}", run_folder.display()))?;
    let pty = PscPty::create(sim_pty_path(&cfg.instance), world.psc(), clock)?;
    tracing::info!(
        "map {} start ({:.2}, {:.2}) {:.0} deg; PSC on {} -> {}",
        map_path.display(),
        start.x_m,
        start.y_m,
        start.heading_rad.to_degrees(),
        pty.link_path().display(),
        pty.slave_path().display()
    );
    let mut camera = rt.node.publisher(&topics::SIM_CAMERA)?;
    let mut gt_disparity = rt.node.publisher(&topics::SIM_GT_DISPARITY)?;
    let mut truth = rt.node.publisher(&topics::SIM_TRUTH)?;
    rt.set_note(format!("{}", pty.slave_path().display()));

    let waitset = rt.waitset()?;
    let frame_period = Duration::from_secs_f64(1.0 / cfg.camera.fps);
    let tick = attach_interval(&waitset, frame_period)?;
    let right_delay_ns = (cfg.sim.defects.right_delay_ms * 1e6) as u64;
    let mut frame_id = 0u64;

    let result = rt.run_loop(&waitset, |rt, id| {
        if !id.has_event_from(&tick) {
            return Ok(LoopControl::Continue);
        }
        let t = clock.now_s();
        let capture_ns = monotonic_ns();
        let mut sample = match camera.loan() {
            Ok(s) => s,
            Err(e) => {
                rt.report_publish_error(&e);
                return Ok(LoopControl::Continue);
            }
        };
        let mut gt = match gt_disparity.loan() {
            Ok(s) => s,
            Err(e) => {
                rt.report_publish_error(&e);
                return Ok(LoopControl::Continue);
            }
        };
        let frame = sample.payload_mut();
        let gt_map = gt.payload_mut();
        let rendered = world.render(
            t,
            &mut frame.left,
            &mut frame.right,
            Some(&mut gt_map.disparity_q8),
        );
        if let Err(e) = rendered {
            rt.report_error("render", &e);
            return Ok(LoopControl::Continue);
        }
        frame_id += 1;
        // The exact map is certain wherever it has a disparity.
        for (c, &d) in gt_map.confidence.iter_mut().zip(gt_map.disparity_q8.iter()) {
            *c = if d == 0 { 0 } else { 255 };
        }
        gt_map.header = DisparityHeader {
            frame_id,
            capture_ns,
            frame_received_ns: capture_ns,
            published_ns: monotonic_ns(),
            compute_ns: 0,
            width: HI_WIDTH as u32,
            height: HI_HEIGHT as u32,
            min_disp: 0,
            max_disp: 0,
            algorithm: 0,
            valid_px: HI_WIDTH as u32 * HI_HEIGHT as u32,
            row_shift_mpx: 0,
            row_align: 0,
        };
        frame.header = FrameHeader {
            frame_id,
            capture_ns,
            left_capture_ns: capture_ns,
            right_capture_ns: capture_ns + right_delay_ns,
            skew_ns: right_delay_ns as i64,
            published_ns: monotonic_ns(),
            width: HI_WIDTH as u32,
            height: HI_HEIGHT as u32,
            source: FrameSource::Simulator as u32,
            reserved: 0,
            replay_hi_frame_id: 0,
        };
        rt.send_or_report(&mut camera, sample, monotonic_ns() - capture_ns);
        if let Err(e) = gt_disparity.send(gt) {
            rt.report_publish_error(&e);
        }

        let gt = world.ground_truth();
        let counters = lock_psc(&world.psc()).counters();
        let report = SimTruth {
            seq: frame_id,
            time_ns: monotonic_ns(),
            sim_time_s: gt.time_s,
            x_m: gt.pose.x_m,
            y_m: gt.pose.y_m,
            heading_rad: gt.pose.heading_rad,
            odometer_m: gt.odometer_m,
            frame_id,
            psc_frames: counters.frames_ok,
            psc_malformed: counters.malformed_frames.min(u32::MAX as u64) as u32,
            collisions: gt.collisions.min(u32::MAX as u64) as u32,
            in_collision: gt.in_collision as u32,
            left_pw: gt.left_pw.map_or(0, |p| p.round() as u16),
            right_pw: gt.right_pw.map_or(0, |p| p.round() as u16),
        };
        if let Err(e) = truth.publish_copy(&report) {
            rt.report_publish_error(&e);
        }
        Ok(LoopControl::Continue)
    });
    // Keep serving the PSC pty a little longer: when the supervisor dies, every stage gets
    // SIGTERM at once, and the actuator's last words (neutral pulses) must still reach the
    // simulated controller rather than a closed pty.
    std::thread::sleep(PTY_LINGER);
    drop(pty);
    result
}

/// How long the PSC pty stays open after the stage stops.
const PTY_LINGER: std::time::Duration = std::time::Duration::from_millis(400);
