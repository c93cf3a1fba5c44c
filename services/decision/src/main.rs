//! Decision stage process: one decision per range report, published for the actuator.
//!
//! The decision's clock is the frame's capture time, and the actuator output it dead-reckons
//! from is what was on the wire by then (later outputs wait for a later frame): the pose then
//! belongs to the view, and the same frames and outputs give the same decisions whatever the
//! processing delays (a replay repeats the recorded decisions).

use std::collections::VecDeque;
use std::process::ExitCode;

use hvs_decision::{Navigator, Policy};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{ActuatorReport, Decision};
use hvs_shared::topics::{self, Stage};

fn main() -> ExitCode {
    run_stage(Stage::Decision, run)
}

/// Actuator outputs kept until a frame captured after them (15 a second: seconds of them).
const SENT_KEPT: usize = 64;

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let ranges = rt.node.subscriber(&topics::RANGES, 2)?;
    // What the actuator really sent: dead reckoning for the turns and the visit memory.
    let sent = rt.node.subscriber(&topics::ACTUATOR_SENT, 16)?;
    let mut decisions = rt.node.publisher(&topics::DECISIONS)?;
    let cfg = rt.config.decision.clone();
    let mut nav = Navigator::new(&cfg, &rt.config.actuator.pulses)
        .with_camera_forward_m(rt.config.camera.forward_m);
    let policy = Policy::of(cfg.policy);
    tracing::info!(
        "{:?} policy, side wall < {:.3} m, front wall < {:.3} m (640x480: {:.3} / {:.3} m), visit memory {}",
        cfg.policy,
        cfg.lo.side_m,
        cfg.lo.front_m,
        cfg.hi.side_m,
        cfg.hi.front_m,
        if cfg.visit_memory { "on" } else { "off" }
    );
    let waitset = rt.waitset()?;
    let guard = waitset
        .attach_notification(ranges.listener())
        .map_err(|e| format!("cannot attach listener: {e:?}"))?;
    let sent_guard = waitset
        .attach_notification(sent.listener())
        .map_err(|e| format!("cannot attach listener: {e:?}"))?;
    let mut pending_sent: VecDeque<ActuatorReport> = VecDeque::new();
    rt.run_loop(&waitset, |rt, id| {
        if id.has_event_from(&sent_guard) || id.has_event_from(&guard) {
            sent.clear_events();
            while let Some(report) = sent.receive()? {
                if pending_sent.len() == SENT_KEPT {
                    // Only without frames for seconds: the oldest output is applied late
                    // rather than lost.
                    if let Some(a) = pending_sent.pop_front() {
                        nav.on_sent(a.sent_ns, a.left_pw, a.right_pw, a.ramp);
                    }
                }
                pending_sent.push_back(*report.payload());
            }
        }
        if !id.has_event_from(&guard) {
            return Ok(LoopControl::Continue);
        }
        ranges.clear_events();
        while let Some(report) = ranges.receive()? {
            let received_ns = monotonic_ns();
            rt.count_in(1);
            rt.set_drops(ranges.dropped());
            let r = report.payload();
            while let Some(a) = pending_sent.front().filter(|a| a.sent_ns <= r.capture_ns) {
                // Byte 4 of a PSC position command is its ramp.
                nav.on_sent(a.sent_ns, a.left_pw, a.right_pw, a.ramp);
                pending_sent.pop_front();
            }
            let d = nav.decide(&r.windows, r.window_count as usize, &r.scan, r.capture_ns);
            let decision = Decision {
                frame_id: r.frame_id,
                capture_ns: r.capture_ns,
                published_ns: monotonic_ns(),
                command: d.command as u32,
                intersection: d.intersection as u32,
                wall_left: d.memberships.left as f32,
                wall_front: d.memberships.front as f32,
                wall_right: d.memberships.right as f32,
                turn_angle_deg: d.turn_angle_deg as f32,
                ramp: d.ramp,
                policy: policy as u32,
                reserved: [0; 2],
            };
            rt.set_note(format!(
                "{} {} cells {}",
                d.intersection.label(),
                d.command.label(),
                nav.visits().distinct_cells()
            ));
            match decisions.publish_copy(&decision) {
                Ok(_) => rt.count_out(monotonic_ns() - received_ns),
                Err(e) => rt.report_publish_error(&e),
            }
        }
        Ok(LoopControl::Continue)
    })
}
