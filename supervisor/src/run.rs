//! `hvs run`: start every stage of a config as its own process and keep them alive.
//!
//! The loop (every 20 ms): read heartbeats, notice exits and hangs, apply restart policies with
//! backoff, answer control requests (`hvs restart`, `hvs stop`), collect latencies, and once a
//! status period print one line and publish the status table. A stage is only ever started,
//! stopped or restarted on its own: the others keep their processes.

use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use bytemuck::Zeroable;
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::{CaptureSource, HvsConfig, StageSpec};
use hvs_runtime::ipc::{IpcNode, TopicPublisher, TopicSubscriber};
use hvs_runtime::stats::LatencyWindow;
use hvs_shared::messages::{
    ActuatorReport, ControlCommand, Decision, MAX_STAGES, MotionCommand, NOTE_LEN, SendReason,
    SimTruth, StageHealth, StageHeartbeat, StageState, StageStatusEntry, SupervisorStatus,
    decode_name, encode_name,
};
use hvs_shared::topics::{self, Stage};
use nix::sys::signal::Signal;

use crate::policy::{self, ExitVerdict, RestartHistory};
use crate::process::{self, Launch};
use crate::procstat::{self, ProcSample};
use crate::report::{LatencyReport, RunReport, SimReport, StageReport};

mod lock;
mod log_lines;
mod recording;

pub use log_lines::LineSender;

use lock::InstanceLock;
use recording::{Recorder, check_recording};

/// Supervisor loop period.
const TICK: Duration = Duration::from_millis(20);
/// Log filter for stages when RUST_LOG is not set: stage start-up and problems, but not the
/// per-stage status lines (the supervisor prints one line for all of them).
const DEFAULT_STAGE_LOG: &str = "info,hvs_status=off";

/// Options of `hvs run`.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// Config file.
    pub config_path: PathBuf,
    /// Instance override.
    pub instance: Option<String>,
    /// Stop after this long.
    pub duration: Option<Duration>,
    /// Write the JSON report here at the end.
    pub report: Option<PathBuf>,
    /// Replay this recording instead of the config's frame source; stop at its end.
    pub replay: Option<PathBuf>,
    /// Record the run (`hvs probe record`'s default topics) from before the first frame.
    pub record: Option<PathBuf>,
    /// zenoh endpoints the bridge listens on (added to `[bridge] listen`).
    pub bridge_listen: Vec<String>,
    /// zenoh endpoints the bridge connects to (added to `[bridge] connect`).
    pub bridge_connect: Vec<String>,
    /// Latencies of decisions made in the first this-long are left out of the report (the
    /// stages starting up hold most of a short run's tail; benchmarks compare steady states).
    pub latency_warm_up: Duration,
}

/// Counters of a stage, summed over its incarnations.
#[derive(Debug, Default, Clone, Copy)]
struct Counters {
    frames_in: u64,
    frames_out: u64,
    drops: u64,
    errors: u64,
}

impl Counters {
    fn from_heartbeat(hb: &StageHeartbeat) -> Self {
        Self {
            frames_in: hb.frames_in,
            frames_out: hb.frames_out,
            drops: hb.drops,
            errors: hb.errors,
        }
    }

    fn plus(self, o: Self) -> Self {
        Self {
            frames_in: self.frames_in + o.frames_in,
            frames_out: self.frames_out + o.frames_out,
            drops: self.drops + o.drops,
            errors: self.errors + o.errors,
        }
    }
}

/// One supervised stage.
struct Slot {
    spec: StageSpec,
    program: PathBuf,
    heartbeat: TopicSubscriber<StageHeartbeat>,
    child: Option<Child>,
    pid: u32,
    state: StageState,
    spawned_at: Instant,
    last_heartbeat: Option<Instant>,
    /// The main thread's run-queue wait (ns) when the last heartbeat (or the spawn) was seen.
    wait_at_heartbeat_ns: Option<u64>,
    health: Option<StageHealth>,
    /// The newest heartbeat's note.
    note: [u8; NOTE_LEN],
    hung: bool,
    restart_requested: bool,
    stop_deadline: Option<Instant>,
    restarts: u32,
    /// What the restart policy remembers ([`policy::RestartHistory`]).
    history: RestartHistory,
    next_start: Option<Instant>,
    last_exit: i32,
    past: Counters,
    current: Counters,
    rate_base: u64,
    rate_hz: f64,
    latency_p50_ns: u64,
    latency_p99_ns: u64,
    /// CPU seconds of earlier incarnations.
    cpu_s_past: f64,
    /// The current process's last reading.
    proc_now: Option<ProcSample>,
    rss_max_bytes: u64,
}

impl Slot {
    fn totals(&self) -> Counters {
        self.past.plus(self.current)
    }

    fn cpu_s(&self) -> f64 {
        self.cpu_s_past + self.proc_now.map_or(0.0, |s| s.cpu_s)
    }
}

/// Where stage binaries live: the config's `bin_dir`, else next to this executable.
fn bin_dir(config: &HvsConfig) -> anyhow::Result<PathBuf> {
    if let Some(dir) = &config.supervisor.bin_dir {
        return Ok(config.resolve_path(dir));
    }
    let exe = std::env::current_exe().context("cannot locate the hvs executable")?;
    Ok(exe
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from(".")))
}

fn resolve_program(bin_dir: &Path, program: &str) -> PathBuf {
    if program.contains('/') {
        PathBuf::from(program)
    } else {
        bin_dir.join(program)
    }
}

/// Runs the pipeline until SIGINT/SIGTERM, `hvs stop` or the duration ends.
pub fn run(opts: &RunOptions) -> anyhow::Result<RunReport> {
    let mut config = HvsConfig::load(&opts.config_path)?;
    if let Some(instance) = &opts.instance {
        hvs_runtime::config::validate_instance_name(instance)
            .map_err(|m| anyhow::anyhow!("--instance {m}"))?;
        config.instance = instance.clone();
    }
    let replay = opts.replay.as_deref().map(check_recording).transpose()?;
    if let Some(file) = &replay {
        config.use_replay(file)?;
    }
    if !opts.bridge_listen.is_empty() || !opts.bridge_connect.is_empty() {
        config.add_bridge_endpoints(&opts.bridge_listen, &opts.bridge_connect)?;
    }
    crate::preflight(&config)?;
    let config_path = std::fs::canonicalize(&opts.config_path)
        .with_context(|| format!("cannot resolve {}", opts.config_path.display()))?;
    let instance = config.instance.clone();
    let _lock = InstanceLock::acquire(&instance)?;
    let bins = bin_dir(&config)?;

    let specs: Vec<StageSpec> = config.stage_specs();
    let missing: Vec<String> = specs
        .iter()
        .filter(|s| {
            s.enabled
                && config
                    .stages
                    .get(&s.name)
                    .and_then(|o| o.program.as_ref())
                    .is_none()
        })
        .map(|s| resolve_program(&bins, &s.program))
        .filter(|p| !p.is_file())
        .map(|p| p.display().to_string())
        .collect();
    if !missing.is_empty() {
        bail!(
            "stage binaries not found: {}\nbuild every stage first: cargo build --release (or set supervisor.bin_dir)",
            missing.join(", ")
        );
    }

    let node = IpcNode::create(&instance, "supervisor")?;
    let mut status_pub: TopicPublisher<SupervisorStatus> =
        node.publisher(&topics::SUPERVISOR_STATUS)?;
    let control = node.subscriber(&topics::SUPERVISOR_CONTROL, 4)?;
    let decisions = node.subscriber(&topics::DECISIONS, 4)?;
    let sent = node.subscriber(&topics::ACTUATOR_SENT, 4)?;
    let truth = node.subscriber(&topics::SIM_TRUTH, 1)?;
    let (mut log_forwarder, log_lines) =
        log_lines::LogForwarder::new(node.publisher(&topics::LOG)?);

    let mut slots = Vec::new();
    for mut spec in specs {
        if let Some(file) = &replay {
            spec.args.push("--replay".to_string());
            spec.args.push(file.display().to_string());
        }
        // Every stage loads the config itself: each sees the same endpoints (and so the same
        // stage graph) as the supervisor.
        for (flag, list) in [
            ("--bridge-listen", &opts.bridge_listen),
            ("--bridge-connect", &opts.bridge_connect),
        ] {
            for e in list {
                spec.args.push(flag.to_string());
                spec.args.push(e.clone());
            }
        }
        let heartbeat = node.stage_subscriber(&topics::HEARTBEAT, &spec.name, 4)?;
        let program = resolve_program(&bins, &spec.program);
        let state = if spec.enabled {
            StageState::Stopped
        } else {
            StageState::Disabled
        };
        slots.push(Slot {
            history: RestartHistory::new(&spec),
            spec,
            program,
            heartbeat,
            child: None,
            pid: 0,
            state,
            spawned_at: Instant::now(),
            last_heartbeat: None,
            wait_at_heartbeat_ns: Some(0),
            health: None,
            note: [0; NOTE_LEN],
            hung: false,
            restart_requested: false,
            stop_deadline: None,
            restarts: 0,
            next_start: None,
            last_exit: 0,
            past: Counters::default(),
            current: Counters::default(),
            rate_base: 0,
            rate_hz: 0.0,
            latency_p50_ns: 0,
            latency_p99_ns: 0,
            cpu_s_past: 0.0,
            proc_now: None,
            rss_max_bytes: 0,
        });
    }

    let mut sup = Supervisor {
        config,
        config_path,
        instance,
        slots,
        status_seq: 0,
        started: Instant::now(),
        started_ns: monotonic_ns(),
        decision_latency: LatencyWindow::default(),
        period_decision_latency: LatencyWindow::default(),
        command_latency: LatencyWindow::default(),
        decisions_seen: 0,
        commands_sent: 0,
        neutral_sent: 0,
        watchdog_neutral: 0,
        last_command: MotionCommand::Stop,
        last_truth: None,
        replay_end: None,
        log_lines,
        latency_warm_up: opts.latency_warm_up,
    };
    tracing::info!(
        "hvs: instance {}, config {}, stages from {}",
        sup.instance,
        sup.config_path.display(),
        bins.display()
    );
    // The recorder first: the recording then holds the first frame and every actuator
    // output, which a replay needs to repeat the decisions.
    let recorder = opts
        .record
        .as_deref()
        .map(|out| Recorder::start(&sup.instance, out, &sup.config_path))
        .transpose()?;
    for i in 0..sup.slots.len() {
        if sup.slots[i].state == StageState::Stopped {
            sup.start(i);
        }
    }

    let status_period = Duration::from_millis(sup.config.supervisor.status_period_ms);
    let mut next_status = Instant::now() + status_period;
    let deadline = opts.duration.map(|d| Instant::now() + d);
    let mut stop_reason = "signal";
    loop {
        if !node.sleep(TICK) {
            break;
        }
        if deadline.is_some_and(|d| Instant::now() >= d) {
            stop_reason = "duration reached";
            break;
        }
        let mut stop = false;
        control.clear_events();
        while let Some(req) = control.receive()? {
            let r = req.payload();
            match ControlCommand::from_code(r.command) {
                Some(ControlCommand::Restart) => {
                    sup.request_restart(decode_name(&r.stage), r.sender_pid)
                }
                Some(ControlCommand::Stop) => {
                    tracing::info!("hvs: stop requested by pid {}", r.sender_pid);
                    stop = true;
                }
                None => tracing::warn!("hvs: unknown control command {}", r.command),
            }
        }
        if stop {
            stop_reason = "hvs stop";
            break;
        }
        match sup.replay_end {
            Some(ReplayEnd::Finished) => {
                stop_reason = "replay finished";
                break;
            }
            Some(ReplayEnd::Failed(_)) => {
                stop_reason = "replay failed";
                break;
            }
            None => {}
        }
        sup.poll_heartbeats()?;
        sup.poll_children();
        sup.poll_pipeline(&decisions, &sent, &truth)?;
        log_forwarder.drain();
        status_pub.update_connections();
        if Instant::now() >= next_status {
            let secs = status_period.as_secs_f64();
            sup.update_rates(secs);
            sup.print_status();
            sup.publish_status(&mut status_pub, false);
            next_status += status_period;
        }
    }
    tracing::info!("hvs: stopping ({stop_reason})");
    sup.publish_status(&mut status_pub, true);
    // The last CPU and memory readings, while the stages still run.
    sup.sample_processes();
    sup.shutdown();
    // Collect what arrived during shutdown (the actuator's final neutral).
    sup.poll_pipeline(&decisions, &sent, &truth)?;
    sup.poll_heartbeats()?;
    if let Some(recorder) = recorder {
        recorder.stop();
    }
    let report = sup.report();
    println!(
        "hvs: stopped after {:.1} s; capture-to-decision p50 {:.2} ms p99 {:.2} ms; restarts {}",
        report.duration_s,
        report.latency.capture_to_decision.p50_ms,
        report.latency.capture_to_decision.p99_ms,
        report.stages.iter().map(|s| s.restarts).sum::<u32>()
    );
    if let Some(path) = &opts.report {
        let json = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, json + "\n")
            .with_context(|| format!("cannot write report {}", path.display()))?;
        println!("hvs: report written to {}", path.display());
    }
    if let Some(ReplayEnd::Failed(code)) = sup.replay_end {
        bail!(
            "replay of {} failed: the capture stage ended with {} (its error is above)",
            sup.config.capture.replay.file.display(),
            describe_exit(code)
        );
    }
    Ok(report)
}

struct Supervisor {
    config: HvsConfig,
    config_path: PathBuf,
    instance: String,
    slots: Vec<Slot>,
    status_seq: u64,
    started: Instant,
    started_ns: u64,
    decision_latency: LatencyWindow,
    period_decision_latency: LatencyWindow,
    command_latency: LatencyWindow,
    decisions_seen: u64,
    commands_sent: u64,
    neutral_sent: u64,
    watchdog_neutral: u64,
    last_command: MotionCommand,
    last_truth: Option<SimTruth>,
    /// The replaying capture stage ended.
    replay_end: Option<ReplayEnd>,
    /// Where the stages' output readers queue their lines for the `log` topic.
    log_lines: log_lines::LineSender,
    /// See [`RunOptions::latency_warm_up`].
    latency_warm_up: Duration,
}

/// How the capture stage of a replay ended.
#[derive(Debug, Clone, Copy)]
enum ReplayEnd {
    /// At the end of the recording.
    Finished,
    /// With this exit code (its error is in the log).
    Failed(i32),
}

impl Supervisor {
    fn start(&mut self, i: usize) {
        let slot = &mut self.slots[i];
        let launch = Launch {
            stage: &slot.spec.name,
            program: &slot.program,
            config: &self.config_path,
            instance: &self.instance,
            extra_args: &slot.spec.args,
            default_log_filter: DEFAULT_STAGE_LOG,
            nice: slot.spec.nice,
            log_lines: Some(&self.log_lines),
        };
        slot.spawned_at = Instant::now();
        slot.last_heartbeat = None;
        // A new process has waited for no CPU yet.
        slot.wait_at_heartbeat_ns = Some(0);
        slot.note = [0; NOTE_LEN];
        slot.health = None;
        slot.hung = false;
        slot.next_start = None;
        match process::spawn(&launch) {
            Ok(child) => {
                slot.pid = child.id();
                slot.child = Some(child);
                slot.state = StageState::Starting;
                tracing::info!("hvs: started {} (pid {})", slot.spec.name, slot.pid);
            }
            Err(e) => {
                tracing::error!("hvs: {e}");
                slot.pid = 0;
                slot.last_exit = 127;
                self.after_exit(i, true);
            }
        }
    }

    fn request_restart(&mut self, stage: &str, sender: u32) {
        let Some(i) = self.slots.iter().position(|s| s.spec.name == stage) else {
            tracing::warn!("hvs: restart of unknown stage {stage:?} requested by pid {sender}");
            return;
        };
        let grace = Duration::from_millis(self.config.supervisor.stop_timeout_ms);
        let slot = &mut self.slots[i];
        tracing::info!("hvs: restart of {stage} requested by pid {sender}");
        match slot.state {
            StageState::Disabled => tracing::warn!("hvs: {stage} is disabled in the config"),
            StageState::Running | StageState::Starting => {
                slot.restart_requested = true;
                slot.state = StageState::Stopping;
                slot.stop_deadline = Some(Instant::now() + grace);
                process::signal(slot.pid, Signal::SIGTERM);
            }
            StageState::Stopping => {}
            _ => {
                // Stopped, failed or waiting out a backoff: start it now with a fresh budget.
                slot.history.reset(&slot.spec);
                slot.restarts += 1;
                self.start(i);
            }
        }
    }

    fn poll_heartbeats(&mut self) -> anyhow::Result<()> {
        for slot in &mut self.slots {
            slot.heartbeat.clear_events();
            let beat_before = slot.last_heartbeat;
            while let Some(s) = slot.heartbeat.receive()? {
                let hb = s.payload();
                // Heartbeats of an earlier incarnation (history, or in flight) are not ours.
                if hb.pid != slot.pid || slot.pid == 0 {
                    continue;
                }
                slot.last_heartbeat = Some(Instant::now());
                slot.health = StageHealth::from_code(hb.health);
                slot.note = hb.note;
                slot.current = Counters::from_heartbeat(hb);
                slot.latency_p50_ns = hb.latency_p50_ns;
                slot.latency_p99_ns = hb.latency_p99_ns;
                if slot.state == StageState::Starting {
                    slot.state = StageState::Running;
                    tracing::info!(
                        "hvs: {} running (pid {}, first heartbeat after {} ms)",
                        slot.spec.name,
                        slot.pid,
                        slot.spawned_at.elapsed().as_millis()
                    );
                }
            }
            // The run-queue wait at this stage's newest heartbeat: what the hang check takes
            // off the silence that follows (one small /proc read per poll that saw a beat).
            if slot.last_heartbeat != beat_before {
                slot.wait_at_heartbeat_ns = procstat::run_queue_wait_ns(slot.pid);
            }
        }
        Ok(())
    }

    fn poll_children(&mut self) {
        let startup_timeout = Duration::from_millis(self.config.supervisor.startup_timeout_ms);
        for i in 0..self.slots.len() {
            let slot = &mut self.slots[i];
            let exited = match slot.child.as_mut().map(|c| c.try_wait()) {
                Some(Ok(Some(status))) => Some(process::exit_code(&status)),
                Some(Ok(None)) => None,
                Some(Err(e)) => {
                    tracing::warn!("hvs: cannot poll {}: {e}", slot.spec.name);
                    None
                }
                None => None,
            };
            if let Some(code) = exited {
                slot.child = None;
                slot.last_exit = code;
                let failed = code != 0 || slot.hung;
                if slot.restart_requested {
                    tracing::info!("hvs: {} stopped for restart (exit {code})", slot.spec.name);
                } else if slot.hung {
                    tracing::warn!(
                        "hvs: {} (pid {}) killed after hanging",
                        slot.spec.name,
                        slot.pid
                    );
                } else if failed {
                    tracing::warn!(
                        "hvs: {} (pid {}) died with {}",
                        slot.spec.name,
                        slot.pid,
                        describe_exit(code)
                    );
                } else {
                    tracing::info!("hvs: {} (pid {}) exited cleanly", slot.spec.name, slot.pid);
                }
                self.after_exit(i, failed);
                continue;
            }
            // Hang detection: no heartbeat for too long (a stopped or stuck main loop).
            let slot = &mut self.slots[i];
            let silent_since = slot.last_heartbeat.unwrap_or(slot.spawned_at);
            let now = Instant::now();
            // Read only when the silence is past the limit already (one small file).
            let starved = || {
                let now_ns = procstat::run_queue_wait_ns(slot.pid)?;
                Some(Duration::from_nanos(
                    now_ns.saturating_sub(slot.wait_at_heartbeat_ns?),
                ))
            };
            let hung = |starved| {
                policy::is_hung(
                    slot.state,
                    &slot.spec,
                    startup_timeout,
                    silent_since,
                    now,
                    starved,
                )
            };
            if !slot.hung && hung(Duration::ZERO) && hung(starved().unwrap_or_default()) {
                let silent_for = now.saturating_duration_since(silent_since);
                tracing::warn!(
                    "hvs: {} (pid {}) sent no heartbeat for {} ms ({} ms of it waiting for a \
                     CPU): killing it",
                    slot.spec.name,
                    slot.pid,
                    silent_for.as_millis(),
                    starved().unwrap_or_default().as_millis()
                );
                slot.hung = true;
                process::signal(slot.pid, Signal::SIGKILL);
            }
            // A restart request whose stage ignores SIGTERM.
            if slot.state == StageState::Stopping
                && slot.stop_deadline.is_some_and(|d| Instant::now() > d)
            {
                process::signal(slot.pid, Signal::SIGKILL);
                slot.stop_deadline = None;
            }
            if slot.state == StageState::Backoff
                && slot.next_start.is_some_and(|t| Instant::now() >= t)
            {
                slot.restarts += 1;
                tracing::info!(
                    "hvs: restarting {} (restart {})",
                    slot.spec.name,
                    slot.restarts
                );
                self.start(i);
            }
        }
    }

    /// Decides what happens to a stage whose process ended (or could not be spawned).
    fn after_exit(&mut self, i: usize, failed: bool) {
        let slot = &mut self.slots[i];
        slot.past = slot.past.plus(slot.current);
        slot.current = Counters::default();
        let ran_for = slot.spawned_at.elapsed();
        slot.pid = 0;
        slot.cpu_s_past += slot.proc_now.take().map_or(0.0, |s| s.cpu_s);
        if slot.spec.stage == Stage::Capture && self.config.capture.source == CaptureSource::Replay
        {
            // The end of the recording (the pipeline has decided on its last frame), or a
            // recording that cannot be read: played again from its start it would repeat
            // decisions, so the run ends either way, whatever the restart policy says.
            slot.state = if failed {
                StageState::Failed
            } else {
                StageState::Stopped
            };
            self.replay_end = Some(if failed {
                ReplayEnd::Failed(slot.last_exit)
            } else {
                ReplayEnd::Finished
            });
            return;
        }
        if slot.restart_requested {
            slot.restart_requested = false;
            slot.restarts += 1;
            self.start(i);
            return;
        }
        match slot
            .history
            .after_exit(&slot.spec, failed, ran_for, Instant::now())
        {
            ExitVerdict::Leave { failed } => {
                slot.state = if failed {
                    StageState::Failed
                } else {
                    StageState::Stopped
                };
                if failed {
                    tracing::error!(
                        "hvs: {} will not be restarted (policy {:?})",
                        slot.spec.name,
                        slot.spec.restart
                    );
                }
            }
            ExitVerdict::GiveUp { failures } => {
                slot.state = StageState::Failed;
                tracing::error!(
                    "hvs: giving up on {} after {failures} restarts within {} s",
                    slot.spec.name,
                    slot.spec.restart_window_s
                );
            }
            ExitVerdict::RestartAt { at, backoff } => {
                slot.state = StageState::Backoff;
                slot.next_start = Some(at);
                tracing::info!(
                    "hvs: {} restarts in {} ms",
                    slot.spec.name,
                    backoff.as_millis()
                );
            }
        }
    }

    fn poll_pipeline(
        &mut self,
        decisions: &TopicSubscriber<Decision>,
        sent: &TopicSubscriber<ActuatorReport>,
        truth: &TopicSubscriber<SimTruth>,
    ) -> anyhow::Result<()> {
        decisions.clear_events();
        while let Some(d) = decisions.receive()? {
            let d = d.payload();
            let latency = d.published_ns.saturating_sub(d.capture_ns);
            if self.started.elapsed() >= self.latency_warm_up {
                self.decision_latency.record(latency);
            }
            self.period_decision_latency.record(latency);
            self.decisions_seen += 1;
            self.last_command = MotionCommand::from_code(d.command);
        }
        sent.clear_events();
        while let Some(r) = sent.receive()? {
            let r = r.payload();
            self.commands_sent += 1;
            match SendReason::from_code(r.reason) {
                Some(SendReason::Decision) if self.started.elapsed() < self.latency_warm_up => {}
                Some(SendReason::Decision) => self
                    .command_latency
                    .record(r.sent_ns.saturating_sub(r.decision_capture_ns)),
                Some(reason) => {
                    self.neutral_sent += 1;
                    if reason == SendReason::WatchdogNeutral {
                        self.watchdog_neutral += 1;
                    }
                }
                None => {}
            }
        }
        truth.clear_events();
        if let Some(t) = truth.receive_latest()? {
            self.last_truth = Some(*t.payload());
        }
        Ok(())
    }

    /// Reads every stage process's CPU time and memory.
    fn sample_processes(&mut self) {
        for slot in &mut self.slots {
            if slot.pid == 0 {
                continue;
            }
            if let Some(s) = procstat::sample(slot.pid) {
                slot.rss_max_bytes = slot.rss_max_bytes.max(s.rss_bytes);
                slot.proc_now = Some(s);
            }
        }
    }

    fn update_rates(&mut self, secs: f64) {
        self.sample_processes();
        for slot in &mut self.slots {
            let out = slot.totals().frames_out;
            slot.rate_hz = out.saturating_sub(slot.rate_base) as f64 / secs;
            slot.rate_base = out;
        }
    }

    fn print_status(&mut self) {
        let lat = self.period_decision_latency.take_summary();
        let rates: Vec<String> = self
            .slots
            .iter()
            .filter(|s| s.state != StageState::Disabled)
            .map(|s| match s.state {
                StageState::Running => format!("{} {:.1}", s.spec.name, s.rate_hz),
                other => format!("{} {}", s.spec.name, other.label().to_uppercase()),
            })
            .collect();
        let restarts: u32 = self.slots.iter().map(|s| s.restarts).sum();
        let sim = self
            .last_truth
            .map(|t| {
                format!(
                    " | pose ({:.2}, {:.2}) {:.0} deg, collisions {}",
                    t.x_m,
                    t.y_m,
                    t.heading_rad.to_degrees(),
                    t.collisions
                )
            })
            .unwrap_or_default();
        println!(
            "hvs {} t={:.0}s | {} Hz | restarts {} | cmd {} | capture->decision p50 {:.1} p99 {:.1} ms{}",
            self.instance,
            self.started.elapsed().as_secs_f64(),
            rates.join(", "),
            restarts,
            self.last_command.label(),
            lat.p50_ns as f64 / 1e6,
            lat.p99_ns as f64 / 1e6,
            sim
        );
    }

    fn publish_status(&mut self, publisher: &mut TopicPublisher<SupervisorStatus>, stopping: bool) {
        let lat = self.decision_latency.summary();
        let mut entries = [StageStatusEntry::zeroed(); MAX_STAGES];
        for (e, s) in entries.iter_mut().zip(&self.slots) {
            let t = s.totals();
            *e = StageStatusEntry {
                stage: encode_name(&s.spec.name),
                frames_in: t.frames_in,
                frames_out: t.frames_out,
                drops: t.drops,
                latency_p50_ns: s.latency_p50_ns,
                latency_p99_ns: s.latency_p99_ns,
                pid: s.pid,
                state: s.state as u32,
                restarts: s.restarts,
                rate_hz: s.rate_hz as f32,
                heartbeat_age_ms: s.last_heartbeat.map_or(u32::MAX, |t| {
                    t.elapsed().as_millis().min(u32::MAX as u128) as u32
                }),
                last_exit: s.last_exit,
                health: s.health.map_or(0, |h| h as u32),
                reserved: 0,
                note: s.note,
            };
        }
        self.status_seq += 1;
        let status = SupervisorStatus {
            seq: self.status_seq,
            time_ns: monotonic_ns(),
            started_ns: self.started_ns,
            decision_latency_p50_ns: lat.p50_ns,
            decision_latency_p99_ns: lat.p99_ns,
            supervisor_pid: std::process::id(),
            stage_count: self.slots.len().min(MAX_STAGES) as u32,
            stopping: stopping as u32,
            last_command: self.last_command as u32,
            stages: entries,
        };
        if let Err(e) = publisher.publish_copy(&status) {
            tracing::warn!("hvs: cannot publish status: {e}");
        }
    }

    /// Orderly stop: the actuator first (it sends neutral and drains the link), then the rest
    /// in parallel, SIGKILL after the grace time.
    fn shutdown(&mut self) {
        let grace = Duration::from_millis(self.config.supervisor.stop_timeout_ms);
        for slot in &mut self.slots {
            if slot.state == StageState::Backoff {
                slot.state = StageState::Stopped;
            }
        }
        if let Some(act) = self
            .slots
            .iter_mut()
            .find(|s| s.spec.stage == Stage::Actuator)
            && let Some(child) = act.child.as_mut()
        {
            let status = process::terminate(child, grace);
            act.last_exit = status.as_ref().map_or(0, process::exit_code);
            act.child = None;
            act.state = StageState::Stopped;
        }
        for slot in self.slots.iter().rev() {
            if slot.child.is_some() {
                process::signal(slot.pid, Signal::SIGTERM);
            }
        }
        for slot in self.slots.iter_mut().rev() {
            if let Some(child) = slot.child.as_mut() {
                let status = process::terminate(child, grace);
                slot.last_exit = status.as_ref().map_or(0, process::exit_code);
                slot.child = None;
                if slot.state != StageState::Failed && slot.state != StageState::Disabled {
                    slot.state = StageState::Stopped;
                }
            }
        }
    }

    fn report(&mut self) -> RunReport {
        let duration_s = self.started.elapsed().as_secs_f64();
        let stages = self
            .slots
            .iter()
            .map(|s| {
                let t = s.totals();
                StageReport {
                    stage: s.spec.name.clone(),
                    state: s.state.label().to_string(),
                    frames_in: t.frames_in,
                    frames_out: t.frames_out,
                    drops: t.drops,
                    errors: t.errors,
                    restarts: s.restarts,
                    last_exit: s.last_exit,
                    cpu_s: s.cpu_s(),
                    cpu_pct: 100.0 * s.cpu_s() / duration_s.max(1e-3),
                    rss_mib: s.proc_now.map_or(0.0, |p| procstat::mib(p.rss_bytes)),
                    rss_max_mib: procstat::mib(s.rss_max_bytes),
                }
            })
            .collect();
        RunReport {
            instance: self.instance.clone(),
            config: self.config_path.display().to_string(),
            duration_s,
            stages,
            decisions: self.decisions_seen,
            commands_sent: self.commands_sent,
            neutral_sent: self.neutral_sent,
            watchdog_neutral: self.watchdog_neutral,
            latency: LatencyReport {
                capture_to_decision: self.decision_latency.summary().into(),
                capture_to_command: self.command_latency.summary().into(),
            },
            sim: self.last_truth.map(|t| SimReport {
                x_m: t.x_m,
                y_m: t.y_m,
                heading_deg: t.heading_rad.to_degrees(),
                collisions: t.collisions,
                odometer_m: t.odometer_m,
                psc_frames: t.psc_frames,
                psc_malformed: t.psc_malformed,
            }),
        }
    }
}

fn describe_exit(code: i32) -> String {
    if code < 0 {
        let sig = Signal::try_from(-code)
            .map(|s| s.as_str().to_string())
            .unwrap_or_else(|_| format!("signal {}", -code));
        format!("signal {sig}")
    } else {
        format!("exit code {code}")
    }
}
