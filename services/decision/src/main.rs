//! Decision stage process: one decision per range report, published for the actuator. The
//! order in which actuator outputs and frames are applied is `hvs_decision::ordering`.

use std::process::ExitCode;

use hvs_decision::nav_map::{fill_map, pose_message};
use hvs_decision::ordering::{SentQueue, apply_sent, decision_message};
use hvs_decision::{Navigator, Policy};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::NavMap;
use hvs_shared::topics::{self, Stage};

/// Period of the `decision/map` snapshots, ns.
const MAP_PERIOD_NS: u64 = 500_000_000;

fn main() -> ExitCode {
    run_stage(Stage::Decision, run)
}

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let ranges = rt.node.subscriber(&topics::RANGES, 2)?;
    // What the actuator really sent: dead reckoning for the turns and the visit memory.
    let sent = rt.node.subscriber(&topics::ACTUATOR_SENT, 16)?;
    let mut decisions = rt.node.publisher(&topics::DECISIONS)?;
    // For observers (the live view, probes): the pose every decision, the map twice a second.
    let mut poses = rt.node.publisher(&topics::DECISION_POSE)?;
    let mut maps = rt.node.publisher(&topics::NAV_MAP)?;
    let mut map = Box::<NavMap>::default();
    let mut map_due_ns = 0u64;
    let cfg = rt.config.decision.clone();
    let mut nav = Navigator::new(&cfg, &rt.config.robot, &rt.config.actuator.pulses)
        .with_camera_forward_m(rt.config.camera.forward_m)
        .with_nav(&rt.config.nav, &rt.config.robot, &rt.config.actuator.pulses)
        .with_matcher_reach(rt.config.stereo.lo.max_disp, 320);
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
    let guard = ranges.attach_to(&waitset)?;
    let sent_guard = sent.attach_to(&waitset)?;
    let mut pending_sent = SentQueue::new(SentQueue::DEFAULT_CAPACITY);
    rt.run_loop(&waitset, |rt, id| {
        if id.has_event_from(&sent_guard) || id.has_event_from(&guard) {
            sent.clear_events();
            while let Some(report) = sent.receive()? {
                if let Some(late) = pending_sent.push(*report.payload()) {
                    apply_sent(&mut nav, &late);
                }
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
            for a in pending_sent.due(r.capture_ns) {
                apply_sent(&mut nav, &a);
            }
            let d = nav.decide(&r.windows, r.window_count as usize, &r.scan, r.capture_ns);
            let decision = decision_message(r.frame_id, r.capture_ns, &d, policy, monotonic_ns());
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
            let now_ns = monotonic_ns();
            if let Err(e) =
                poses.publish_copy(&pose_message(&nav, r.frame_id, r.capture_ns, now_ns))
            {
                rt.report_publish_error(&e);
            }
            if now_ns >= map_due_ns {
                map_due_ns = now_ns + MAP_PERIOD_NS;
                fill_map(&nav, r.capture_ns, &mut map);
                map.seq += 1;
                map.capture_ns = r.capture_ns;
                map.published_ns = monotonic_ns();
                if let Err(e) = maps.publish_copy(&map) {
                    rt.report_publish_error(&e);
                }
            }
        }
        Ok(LoopControl::Continue)
    })
}
