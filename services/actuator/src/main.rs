//! Actuator stage process: newest decision -> PSC bytes on the serial port, neutral when
//! decisions stop, on shutdown and on errors; reconnects with backoff when the device is
//! missing, silent or vanishes; publishes everything it wrote on `actuator/sent`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use hvs_actuator::{Commander, DecisionInput, Outgoing, PscLink};
use hvs_shared::clock::monotonic_ns;
use hvs_shared::config::sim_pty_path;
use hvs_shared::ipc::TopicPublisher;
use hvs_shared::messages::{ActuatorReport, MotionCommand, SendReason, StageHealth};
use hvs_shared::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::topics;

/// How often the actuator wakes to check the watchdog and the wire.
const TICK: Duration = Duration::from_millis(5);
/// Reconnect backoff bounds.
const BACKOFF_MIN: Duration = Duration::from_millis(200);
const BACKOFF_MAX: Duration = Duration::from_secs(2);

fn main() -> ExitCode {
    run_stage("actuator", run)
}

/// The serial link with its reconnect schedule.
struct Connection {
    device: PathBuf,
    exclusive: bool,
    link: Option<PscLink>,
    next_attempt: Instant,
    backoff: Duration,
    failures: u32,
}

impl Connection {
    fn ensure(&mut self, rt: &mut StageRuntime, commander: &mut Commander) {
        if self.link.is_some() || Instant::now() < self.next_attempt {
            return;
        }
        let a = &rt.config.actuator;
        match PscLink::open(&self.device, a.baud, a.link_check, self.exclusive) {
            Ok(link) => {
                tracing::info!(
                    "{}: link up on {} at {} baud (PSC firmware {:?})",
                    rt.stage,
                    self.device.display(),
                    a.baud,
                    link.firmware()
                );
                rt.set_note(format!("{} {}", self.device.display(), link.firmware()));
                rt.set_health(StageHealth::Running);
                self.link = Some(link);
                self.backoff = BACKOFF_MIN;
                self.failures = 0;
                commander.link_reset();
            }
            Err(e) => {
                // Warn on the first failure and then every 10th, not at every retry.
                if self.failures.is_multiple_of(10) {
                    tracing::warn!("{}: {e}; retrying every {:?}", rt.stage, self.backoff);
                }
                self.failures += 1;
                rt.set_note(format!("waiting for {}", self.device.display()));
                rt.set_health(StageHealth::Degraded);
                self.next_attempt = Instant::now() + self.backoff;
                self.backoff = (self.backoff * 2).min(BACKOFF_MAX);
            }
        }
    }

    /// Writes `out`; on failure drops the link so it is reopened.
    fn send(
        &mut self,
        rt: &mut StageRuntime,
        commander: &mut Commander,
        reports: &mut TopicPublisher<ActuatorReport>,
        out: &Outgoing,
    ) {
        let Some(link) = self.link.as_mut() else {
            return;
        };
        if let Err(e) = link.write(&out.bytes) {
            rt.report_error("serial link lost", &e);
            self.link = None;
            self.next_attempt = Instant::now() + BACKOFF_MIN;
            return;
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
            byte_count: out.bytes.len() as u32,
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
            tracing::debug!("{}: watchdog: no fresh decision, neutral sent", rt.stage);
        }
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
        "{}: PSC on {} at {} baud, channels L{} R{}, watchdog {} ms",
        rt.stage,
        device.display(),
        cfg.baud,
        cfg.left_channel,
        cfg.right_channel,
        cfg.watchdog_ms
    );
    let mut commander = Commander::new(&cfg);
    let mut conn = Connection {
        device,
        // A real controller is ours alone; the simulator's pty stays shareable so that a
        // restarted actuator is never locked out by its killed predecessor's TIOCEXCL.
        exclusive: !is_sim,
        link: None,
        next_attempt: Instant::now(),
        backoff: BACKOFF_MIN,
        failures: 0,
    };
    conn.ensure(rt, &mut commander);

    let waitset = rt.waitset()?;
    let decisions_guard = waitset
        .attach_notification(decisions.listener())
        .map_err(|e| format!("cannot attach listener: {e:?}"))?;
    let _tick = waitset
        .attach_interval(TICK)
        .map_err(|e| format!("cannot attach interval: {e:?}"))?;

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
        conn.ensure(rt, &mut commander);
        if let Some(out) = commander.poll(monotonic_ns()) {
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
    conn.send(rt, &mut commander, &mut reports, &neutral);
    if let Some(link) = conn.link.as_mut() {
        link.drain();
        tracing::info!("{}: neutral sent ({:?})", rt.stage, reason);
    } else {
        tracing::warn!("{}: link down, could not send neutral on exit", rt.stage);
    }
    result
}
