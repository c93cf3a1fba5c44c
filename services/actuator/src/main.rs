//! Actuator stage process: newest decision -> PSC bytes on the serial port, neutral when
//! decisions stop, on shutdown and on errors. The link is a non-blocking state machine
//! ([`PscLink`]): a missing, silent or vanished controller is waited for (and named in the
//! heartbeat note), never a crash; when it answers, neutral goes out first. Publishes
//! everything it wrote on `actuator/sent`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use hvs_actuator::link::{LinkEvent, LinkSettings};
use hvs_actuator::{Commander, DecisionInput, Outgoing, PscLink};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::sim_pty_path;
use hvs_runtime::ipc::{TopicPublisher, attach_interval};
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{ActuatorReport, MotionCommand, SendReason, StageHealth};
use hvs_shared::topics::{self, Stage};

/// How often the actuator wakes to check the watchdog and the wire.
const TICK: Duration = Duration::from_millis(5);

fn main() -> ExitCode {
    run_stage(Stage::Actuator, run)
}

/// The link with what the stage says about it.
struct Connection {
    link: PscLink,
    /// The whole seconds last shown in the note (the note is refreshed once a second).
    note_shown_s: Option<u64>,
    /// When the stage started (the note's once-a-second clock).
    started: Instant,
}

impl Connection {
    /// Advances the link; logs and reports state changes.
    fn poll(&mut self, rt: &mut StageRuntime, commander: &mut Commander) {
        let now = Instant::now();
        match self.link.poll(now) {
            Some(LinkEvent::Up { firmware }) => {
                tracing::info!(
                    device = %self.link.device().display(),
                    firmware = %firmware,
                    "servo controller answers: link up, neutral first"
                );
                commander.link_reset();
                self.note_shown_s = None;
            }
            Some(LinkEvent::Waiting(e)) => {
                tracing::warn!(state = self.link.state().label(), "{e}; waiting for it");
                self.note_shown_s = None;
            }
            Some(LinkEvent::Lost(e)) => {
                rt.count_error();
                tracing::warn!("{e}; reopening");
                self.note_shown_s = None;
            }
            None => {}
        }
        // Health from the link's state, here only: the stage skeleton marks itself running
        // when its loop starts, whatever the link did before.
        rt.set_health(if self.link.is_up() {
            StageHealth::Running
        } else {
            StageHealth::Degraded
        });
        // One note refresh a second: "no servo controller answers on DEV (waiting 12 s)".
        let shown = Some(now.saturating_duration_since(self.started).as_secs());
        if self.note_shown_s != shown {
            self.note_shown_s = shown;
            rt.set_note(self.link.note(now));
        }
    }

    /// Writes `out` while the link is up; a failure takes the link down (reported).
    fn send(
        &mut self,
        rt: &mut StageRuntime,
        commander: &mut Commander,
        reports: &mut TopicPublisher<ActuatorReport>,
        out: &Outgoing,
    ) -> bool {
        if !self.link.is_up() {
            return false;
        }
        if let Err(e) = self.link.send(&out.bytes, Instant::now()) {
            rt.report_error("serial link lost", &e);
            self.note_shown_s = None;
            return false;
        }
        let now = monotonic_ns();
        commander.mark_sent(now, out);
        let report = ActuatorReport {
            seq: reports.sent() + 1,
            sent_ns: now,
            decision_frame_id: out.decision.map_or(0, |d| d.frame_id),
            decision_capture_ns: out.decision.map_or(0, |d| d.capture_ns),
            decision_published_ns: out.decision.map_or(0, |d| d.published_ns),
            reason: out.reason as u32,
            command: out.command as u32,
            left_pw: out.left_pw,
            right_pw: out.right_pw,
            byte_count: out.bytes.len() as u16,
            ramp: out.ramp,
            reserved: 0,
            bytes: out.bytes,
        };
        match reports.publish_copy(&report) {
            Ok(_) => rt.count_out(
                out.decision
                    .map_or(0, |d| now.saturating_sub(d.published_ns)),
            ),
            Err(e) => rt.report_publish_error(&e),
        }
        if out.reason == SendReason::WatchdogNeutral {
            tracing::debug!("watchdog: no fresh decision, neutral sent");
        }
        true
    }
}

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let decisions = rt.node.subscriber(&topics::DECISIONS, 4)?;
    let mut reports = rt.node.publisher(&topics::ACTUATOR_SENT)?;
    let cfg = rt.config.actuator.clone();
    let is_sim = cfg.device == "sim";
    let device = if is_sim {
        sim_pty_path(&rt.config.instance)
    } else {
        PathBuf::from(&cfg.device)
    };
    tracing::info!(
        "PSC on {} at {} baud, channels L{} R{}, watchdog {} ms",
        device.display(),
        cfg.baud,
        cfg.left_channel,
        cfg.right_channel,
        cfg.watchdog_ms
    );
    let mut commander = Commander::new(&cfg);
    let mut conn = Connection {
        link: PscLink::new(
            LinkSettings {
                device,
                baud: cfg.baud,
                check: cfg.link_check,
                // A real controller is ours alone; the simulator's pty stays shareable so
                // that a restarted actuator is never locked out by its killed predecessor's
                // TIOCEXCL.
                exclusive: !is_sim,
            },
            Instant::now(),
        ),
        note_shown_s: None,
        started: Instant::now(),
    };
    conn.poll(rt, &mut commander);

    let waitset = rt.waitset()?;
    let decisions_guard = decisions.attach_to(&waitset)?;
    let _tick = attach_interval(&waitset, TICK)?;

    let result = rt.run_loop(&waitset, |rt, id| {
        if id.has_event_from(&decisions_guard) {
            decisions.clear_events();
            while let Some(s) = decisions.receive()? {
                let d = s.payload();
                rt.count_in(1);
                commander.on_decision(DecisionInput {
                    frame_id: d.frame_id,
                    capture_ns: d.capture_ns,
                    published_ns: d.published_ns,
                    command: MotionCommand::from_code(d.command),
                    ramp: d.ramp.min(63) as u8,
                });
            }
            rt.set_drops(decisions.dropped());
        }
        conn.poll(rt, &mut commander);
        // Nothing but version queries goes out before the controller answers.
        if conn.link.is_up()
            && let Some(out) = commander.poll(monotonic_ns())
        {
            conn.send(rt, &mut commander, &mut reports, &out);
        }
        Ok(LoopControl::Continue)
    });

    // Whatever ended the loop (signal, supervisor gone, internal error): stop the wheels.
    let reason = if result.is_ok() {
        SendReason::ShutdownNeutral
    } else {
        SendReason::ErrorNeutral
    };
    let neutral = commander.neutral(reason);
    if conn.send(rt, &mut commander, &mut reports, &neutral) {
        conn.link.drain();
        tracing::info!(?reason, "neutral sent");
    } else {
        tracing::warn!(
            device = %conn.link.device().display(),
            "link not up, no neutral sent on exit"
        );
    }
    result
}
