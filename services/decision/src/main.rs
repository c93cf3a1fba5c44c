//! Decision stage process: one decision per range report, published for the actuator.

use std::process::ExitCode;

use hvs_decision::{Policy, SideRanges, reference_decision};
use hvs_shared::clock::monotonic_ns;
use hvs_shared::messages::Decision;
use hvs_shared::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::topics;

fn main() -> ExitCode {
    run_stage("decision", run)
}

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let ranges = rt.node.subscriber(&topics::RANGES, 2)?;
    let mut decisions = rt.node.publisher(&topics::DECISIONS)?;
    let thresholds = rt.config.decision.lo;
    tracing::info!(
        "{}: reference policy, side wall < {:.3} m, front wall < {:.3} m",
        rt.stage,
        thresholds.side_m,
        thresholds.front_m
    );
    let waitset = rt.waitset()?;
    let guard = waitset
        .attach_notification(ranges.listener())
        .map_err(|e| format!("cannot attach listener: {e:?}"))?;
    rt.run_loop(&waitset, |rt, id| {
        if !id.has_event_from(&guard) {
            return Ok(LoopControl::Continue);
        }
        ranges.clear_events();
        while let Some(report) = ranges.receive()? {
            let received_ns = monotonic_ns();
            rt.count_in(1);
            rt.set_drops(ranges.dropped());
            let r = report.payload();
            let sides = SideRanges::from_windows(&r.windows, r.window_count as usize);
            let choice = reference_decision(&sides, &thresholds);
            let decision = Decision {
                frame_id: r.frame_id,
                capture_ns: r.capture_ns,
                published_ns: monotonic_ns(),
                command: choice.command as u32,
                intersection: choice.intersection as u32,
                wall_left: choice.walls.left as u32 as f32,
                wall_front: choice.walls.front as u32 as f32,
                wall_right: choice.walls.right as u32 as f32,
                turn_angle_deg: choice.turn_angle_deg as f32,
                ramp: choice.ramp,
                policy: Policy::Reference as u32,
                reserved: [0; 2],
            };
            rt.set_note(format!(
                "{} {}",
                choice.intersection.label(),
                choice.command.label()
            ));
            match decisions.publish_copy(&decision) {
                Ok(_) => rt.count_out(monotonic_ns() - received_ns),
                Err(e) => rt.report_publish_error(&e),
            }
        }
        Ok(LoopControl::Continue)
    })
}
