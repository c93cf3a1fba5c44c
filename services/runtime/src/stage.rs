//! What every stage process does the same way: command line, logging, config, node, heartbeat,
//! the once-a-second status line and the event loop.
//!
//! A stage's `main.rs` is then only its own wiring:
//! ```ignore
//! fn main() -> std::process::ExitCode {
//!     hvs_runtime::stage::run_stage(Stage::Fusion, |rt| { /* open topics, loop */ Ok(()) })
//! }
//! ```
//!
//! Everything a stage logs is inside one `tracing` span, `stage`, with the fields `name`,
//! `instance` and `pid`: the messages themselves do not repeat the stage's name.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::Parser;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use tracing_subscriber::EnvFilter;

use crate::clock::monotonic_ns;
use crate::config::{ConfigError, HvsConfig, validate_instance_name};
use crate::ipc::{
    IpcNode, IpcService, NodeOpenError, PublishError, TopicOpenError, TopicPublisher, WaitSetError,
};
use crate::stats::{LatencySummary, LatencyWindow};
use hvs_shared::messages::{NAME_LEN, NOTE_LEN, StageHealth, StageHeartbeat, encode_name};
use hvs_shared::topics::{self, Stage};

/// How often a stage beats. The supervisor's hang timeout is a multiple of this.
pub const HEARTBEAT_PERIOD: Duration = Duration::from_millis(100);

/// Log target of the once-a-second status lines (filter with `RUST_LOG=hvs_status=off`).
pub const STATUS_TARGET: &str = "hvs_status";

/// Command line every stage binary accepts (the supervisor passes all three).
#[derive(Debug, Clone, Parser)]
#[command(
    version,
    about = "An hvs pipeline stage (normally started by `hvs run`)."
)]
pub struct StageArgs {
    /// The pipeline configuration file (TOML).
    #[arg(long, value_name = "FILE")]
    pub config: PathBuf,
    /// Instance name; overrides the config's `instance`.
    #[arg(long, value_name = "NAME")]
    pub instance: Option<String>,
    /// Stage name (for example `stereo-lo`); defaults to the binary's role.
    #[arg(long, value_name = "NAME", value_parser = parse_stage)]
    pub stage: Option<Stage>,
    /// Replay this MCAP recording instead of the config's frame source (`hvs run --replay`).
    #[arg(long, value_name = "FILE")]
    pub replay: Option<PathBuf>,
    /// Adds a zenoh listen endpoint to `[bridge] listen` (`hvs run --bridge-listen`).
    #[arg(long, value_name = "ENDPOINT")]
    pub bridge_listen: Vec<String>,
    /// Adds a zenoh connect endpoint to `[bridge] connect` (`hvs run --bridge-connect`).
    #[arg(long, value_name = "ENDPOINT")]
    pub bridge_connect: Vec<String>,
}

fn parse_stage(name: &str) -> Result<Stage, String> {
    Stage::from_name(name).ok_or_else(|| {
        let names: Vec<&str> = Stage::ALL.iter().map(|s| s.name()).collect();
        format!("unknown stage {name:?}; stages: {}", names.join(", "))
    })
}

/// Why a stage could not start.
#[derive(Debug, thiserror::Error)]
pub enum StageStartError {
    /// The config file is missing or invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// `--instance` is not a valid instance name.
    #[error("--instance {0}")]
    Instance(String),
    /// The iceoryx2 node could not be created.
    #[error(transparent)]
    Node(#[from] NodeOpenError),
    /// The heartbeat topic could not be opened.
    #[error(transparent)]
    Heartbeat(#[from] TopicOpenError),
}

/// Errors a stage body may return.
pub type StageError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Sets up `tracing` for a process: RUST_LOG filters (default `info`), output to stderr.
pub fn init_tracing() {
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    // Ignore the error of a second initialisation (tests call this repeatedly).
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(ansi)
        .with_target(false)
        .try_init();
    let iceoryx_debug = std::env::var("RUST_LOG").is_ok_and(|v| v.contains("iceoryx2"));
    set_log_level(if iceoryx_debug {
        LogLevel::Debug
    } else {
        LogLevel::Warn
    });
}

/// The parent process id when the stage started (0 until [`run_stage`] records it).
static START_PPID: std::sync::atomic::AtomicI32 = std::sync::atomic::AtomicI32::new(0);

/// When the supervisor is gone (killed: the kernel's parent-death signal is what asked this
/// stage to stop), standard error is a pipe nobody reads. A write there fails with EPIPE, and
/// a library that logs with `eprintln!` (iceoryx2's console logger does, warning about the
/// dead supervisor's ports while the stage publishes its last samples) would panic and kill
/// the stage before its orderly stop: the actuator would never send its final neutral. So
/// standard error goes to /dev/null for the rest of the stage's life.
fn silence_stderr_if_orphaned() {
    let started = START_PPID.load(std::sync::atomic::Ordering::Relaxed);
    if started == 0 || nix::unistd::getppid().as_raw() == started {
        return;
    }
    if let Ok(null) = std::fs::OpenOptions::new().write(true).open("/dev/null") {
        use std::os::fd::AsRawFd;
        // SAFETY: dup2 onto fd 2 with a valid open descriptor; no Rust object owns fd 2.
        unsafe {
            libc::dup2(null.as_raw_fd(), 2);
        }
    }
}

/// Parses the stage command line, starts the runtime and runs `body`; maps the outcome to an
/// exit code (0 clean stop, 1 runtime error, 2 bad configuration or arguments).
pub fn run_stage<F>(role: Stage, body: F) -> ExitCode
where
    F: FnOnce(&mut StageRuntime) -> Result<(), StageError>,
{
    init_tracing();
    START_PPID.store(
        nix::unistd::getppid().as_raw(),
        std::sync::atomic::Ordering::Relaxed,
    );
    let args = StageArgs::parse();
    let stage = args.stage.unwrap_or(role);
    let span = tracing::info_span!(
        "stage",
        name = stage.name(),
        instance = tracing::field::Empty,
        pid = std::process::id()
    );
    let _in_span = span.enter();
    let mut runtime = match StageRuntime::start(&args, stage) {
        Ok(rt) => rt,
        Err(e) => {
            tracing::error!("cannot start: {}", crate::error_chain(&e));
            return match e {
                StageStartError::Config(_) | StageStartError::Instance(_) => ExitCode::from(2),
                _ => ExitCode::from(1),
            };
        }
    };
    span.record("instance", runtime.config.instance.as_str());
    match body(&mut runtime) {
        Ok(()) => {
            runtime.set_health(StageHealth::Stopping);
            runtime.beat();
            tracing::info!("stopped");
            ExitCode::SUCCESS
        }
        Err(e) => {
            tracing::error!("{}", crate::error_chain(e.as_ref()));
            ExitCode::from(1)
        }
    }
}

/// What the event loop should do after handling an event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LoopControl {
    /// Keep going.
    Continue,
    /// Leave the loop (clean stop).
    Stop,
}

/// The per-process state shared by every stage: config, node, heartbeat and counters.
pub struct StageRuntime {
    /// The stage this process runs.
    pub stage: Stage,
    /// The validated configuration.
    pub config: HvsConfig,
    /// The iceoryx2 node.
    pub node: IpcNode,
    heartbeat: TopicPublisher<StageHeartbeat>,
    started_ns: u64,
    health: StageHealth,
    note: String,
    frames_in: u64,
    frames_out: u64,
    drops: u64,
    errors: u64,
    latency: LatencyWindow,
    last_latency: LatencySummary,
    last_beat: Instant,
    last_status: Instant,
    status_base: (u64, u64, u64),
}

impl StageRuntime {
    /// Loads the config, creates the node (cleaning up after crashed processes) and opens the
    /// heartbeat topic.
    pub fn start(args: &StageArgs, stage: Stage) -> Result<Self, StageStartError> {
        let mut config = HvsConfig::load(&args.config)?;
        if let Some(instance) = &args.instance {
            validate_instance_name(instance).map_err(StageStartError::Instance)?;
            config.instance = instance.clone();
        }
        if let Some(file) = &args.replay {
            config.use_replay(file)?;
        }
        if !args.bridge_listen.is_empty() || !args.bridge_connect.is_empty() {
            config.add_bridge_endpoints(&args.bridge_listen, &args.bridge_connect)?;
        }
        let node = IpcNode::create(&config.instance, stage.name())?;
        let heartbeat = node.stage_publisher(&topics::HEARTBEAT, stage.name())?;
        tracing::info!(
            "starting (instance {}, config {})",
            config.instance,
            args.config.display()
        );
        let now = Instant::now();
        let mut rt = Self {
            stage,
            config,
            node,
            heartbeat,
            started_ns: monotonic_ns(),
            health: StageHealth::Starting,
            note: String::new(),
            frames_in: 0,
            frames_out: 0,
            drops: 0,
            errors: 0,
            latency: LatencyWindow::default(),
            last_latency: LatencySummary::default(),
            last_beat: now,
            last_status: now,
            status_base: (0, 0, 0),
        };
        rt.beat();
        Ok(rt)
    }

    /// Sets the health reported in heartbeats.
    pub fn set_health(&mut self, health: StageHealth) {
        self.health = health;
    }

    /// Sets the free-text note reported in heartbeats (truncated to 128 bytes).
    pub fn set_note(&mut self, note: impl Into<String>) {
        self.note = note.into();
    }

    /// Counts samples taken in.
    pub fn count_in(&mut self, n: u64) {
        self.frames_in += n;
    }

    /// Counts one published sample and its processing latency.
    pub fn count_out(&mut self, latency_ns: u64) {
        self.frames_out += 1;
        self.latency.record(latency_ns);
    }

    /// Sets the total of input samples lost so far.
    pub fn set_drops(&mut self, total: u64) {
        self.drops = total;
    }

    /// Counts an error (it is also logged by the caller).
    pub fn count_error(&mut self) {
        self.errors += 1;
    }

    /// Publishes a heartbeat now and, once a second, logs the status line.
    pub fn beat(&mut self) {
        self.last_beat = Instant::now();
        if self.last_status.elapsed() >= Duration::from_secs(1) {
            self.status_line();
        }
        let mut hb = StageHeartbeat {
            seq: self.heartbeat.sent() + 1,
            time_ns: monotonic_ns(),
            started_ns: self.started_ns,
            frames_in: self.frames_in,
            frames_out: self.frames_out,
            drops: self.drops,
            errors: self.errors,
            latency_p50_ns: self.last_latency.p50_ns,
            latency_p99_ns: self.last_latency.p99_ns,
            latency_max_ns: self.last_latency.max_ns,
            pid: std::process::id(),
            health: self.health as u32,
            stage: [0; NAME_LEN],
            note: [0; NOTE_LEN],
        };
        hb.stage = encode_name(self.stage.name());
        hb.note = encode_name(&self.note);
        if let Err(e) = self.heartbeat.publish_copy(&hb) {
            tracing::warn!("heartbeat: {e}");
        }
    }

    fn status_line(&mut self) {
        let secs = self.last_status.elapsed().as_secs_f64().max(1e-3);
        self.last_latency = self.latency.take_summary();
        let (base_in, base_out, base_drops) = self.status_base;
        let round2 = |x: f64| (x * 100.0).round() / 100.0;
        tracing::info!(
            target: STATUS_TARGET,
            health = self.health.label(),
            in_hz = round2((self.frames_in - base_in) as f64 / secs),
            out_hz = round2((self.frames_out - base_out) as f64 / secs),
            drops = self.drops - base_drops,
            errors = self.errors,
            latency_p50_ms = round2(self.last_latency.p50_ns as f64 / 1e6),
            latency_p99_ms = round2(self.last_latency.p99_ns as f64 / 1e6),
            note = %self.note,
            "status"
        );
        self.status_base = (self.frames_in, self.frames_out, self.drops);
        self.last_status = Instant::now();
    }

    /// Publishes a heartbeat if one is due.
    pub fn beat_if_due(&mut self) {
        if self.last_beat.elapsed() >= HEARTBEAT_PERIOD {
            self.beat();
        }
    }

    /// A WaitSet that wakes on termination signals as well as on attached listeners.
    pub fn waitset(&self) -> Result<WaitSet<IpcService>, WaitSetError> {
        WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<IpcService>()
            .map_err(|e| WaitSetError::Create(e.into()))
    }

    /// Runs the event loop: waits on `waitset` (whose listeners the caller attached), calls
    /// `on_event` for each attachment that fired, beats every [`HEARTBEAT_PERIOD`], and returns
    /// on SIGINT/SIGTERM, on [`LoopControl::Stop`] or on the first error.
    pub fn run_loop<F>(
        &mut self,
        waitset: &WaitSet<IpcService>,
        mut on_event: F,
    ) -> Result<(), StageError>
    where
        F: FnMut(&mut Self, WaitSetAttachmentId<IpcService>) -> Result<LoopControl, StageError>,
    {
        self.set_health(StageHealth::Running);
        self.beat();
        loop {
            let timeout = HEARTBEAT_PERIOD.saturating_sub(self.last_beat.elapsed());
            let mut failure = None;
            let mut stop = false;
            let result = waitset.wait_and_process_once_with_timeout(
                |id| match on_event(self, id) {
                    Ok(LoopControl::Continue) => CallbackProgression::Continue,
                    Ok(LoopControl::Stop) => {
                        stop = true;
                        CallbackProgression::Stop
                    }
                    Err(e) => {
                        failure = Some(e);
                        CallbackProgression::Stop
                    }
                },
                timeout.max(Duration::from_millis(1)),
            );
            if let Some(e) = failure {
                return Err(e);
            }
            self.beat_if_due();
            if stop {
                return Ok(());
            }
            match result {
                Ok(WaitSetRunResult::TerminationRequest) => {
                    silence_stderr_if_orphaned();
                    tracing::info!("termination requested");
                    return Ok(());
                }
                Ok(_) => {}
                Err(e) => return Err(WaitSetError::Wait(e.into()).into()),
            }
        }
    }

    /// Logs and counts a non-fatal error.
    pub fn report_error(&mut self, context: &str, e: &dyn std::fmt::Display) {
        self.count_error();
        tracing::warn!("{context}: {e}");
    }

    /// Publishes `sample`, counting failures as errors rather than stopping the stage.
    pub fn send_or_report<T>(
        &mut self,
        publisher: &mut TopicPublisher<T>,
        sample: crate::ipc::LoanedSample<T>,
        latency_ns: u64,
    ) where
        T: core::fmt::Debug + ZeroCopySend + bytemuck::Pod + 'static,
    {
        match publisher.send(sample) {
            Ok(_) => self.count_out(latency_ns),
            Err(e) => self.report_error("publish", &e as &dyn std::fmt::Display),
        }
    }

    /// Logs a publish error that happened before a sample existed (a failed loan).
    pub fn report_publish_error(&mut self, e: &PublishError) {
        self.report_error("publish", e);
    }
}
