//! `[stages.<name>]`: how the supervisor runs each stage, and the pre-start check of the
//! data flow between them.

use serde::{Deserialize, Serialize};

use hvs_shared::topics::{self, STAGE_NAMES, Stage};

use super::{CaptureSource, ConfigError, HvsConfig, StereoConfig};

/// When the supervisor restarts a stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    /// After any exit or hang.
    Always,
    /// After a non-zero exit, a signal or a hang; a clean exit stays stopped.
    OnFailure,
    /// Never.
    Never,
}

/// Per-stage settings in `[stages.<name>]`; every field is optional.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StageOverride {
    /// Start this stage at all.
    pub enabled: Option<bool>,
    /// Restart policy.
    pub restart: Option<RestartPolicy>,
    /// Program to run (a path, or a name looked up in the supervisor's bin dir).
    pub program: Option<String>,
    /// Extra arguments appended to the standard ones.
    pub args: Option<Vec<String>>,
    /// First restart delay, ms (doubles after each failure).
    pub backoff_ms: Option<u64>,
    /// Largest restart delay, ms.
    pub max_backoff_ms: Option<u64>,
    /// Give up after this many restarts within `restart_window_s`.
    pub max_restarts: Option<u32>,
    /// Window for `max_restarts`, seconds.
    pub restart_window_s: Option<u64>,
    /// CPU niceness of the process (-20..=19; higher = lower priority). The 640x480 worker
    /// defaults to 10 so that it only uses what the fast path leaves.
    pub nice: Option<i32>,
    /// A stage silent this long is declared hung and restarted, ms (default
    /// `supervisor.heartbeat_timeout_ms`, and at least [`NICED_HEARTBEAT_TIMEOUT_MS`] for a
    /// stage with a positive `nice`). The actuator's should be short: while it hangs the
    /// servo controller holds the last pulses.
    pub heartbeat_timeout_ms: Option<u64>,
}

/// A stage's resolved process settings.
#[derive(Debug, Clone, PartialEq)]
pub struct StageSpec {
    /// The stage.
    pub stage: Stage,
    /// Its name ([`Stage::name`]).
    pub name: String,
    /// Program name or path.
    pub program: String,
    /// Extra arguments.
    pub args: Vec<String>,
    /// Whether it is started.
    pub enabled: bool,
    /// Restart policy.
    pub restart: RestartPolicy,
    /// First restart delay, ms.
    pub backoff_ms: u64,
    /// Largest restart delay, ms.
    pub max_backoff_ms: u64,
    /// Restart budget within the window.
    pub max_restarts: u32,
    /// Window for the restart budget, seconds.
    pub restart_window_s: u64,
    /// CPU niceness.
    pub nice: i32,
    /// Hang bound, ms.
    pub heartbeat_timeout_ms: u64,
}

/// The default hang bound of a stage with a positive niceness (the 640x480 worker), ms. On
/// a machine whose cores other programs keep busy, a niced stage gets a small share of them
/// (nice 10 weighs about a tenth of nice 0) and one 640x480 frame can take over a second of
/// wall time: with the general 1 s bound it was restarted as hung while it was working. It
/// feeds nothing the robot waits for (fusion ages its results out after `hi_max_age_ms`).
pub const NICED_HEARTBEAT_TIMEOUT_MS: u64 = 5000;

impl HvsConfig {
    pub(super) fn validate_stage_names(&self) -> Result<(), ConfigError> {
        for (name, o) in &self.stages {
            if !STAGE_NAMES.contains(&name.as_str()) {
                return Err(self.invalid(
                    &format!("stages.{name}"),
                    format!("is not a stage; known stages: {}", STAGE_NAMES.join(", ")),
                ));
            }
            if let Some(p) = &o.program
                && p.trim().is_empty()
            {
                return Err(self.invalid(&format!("stages.{name}.program"), "is empty"));
            }
            if let Some(n) = o.nice
                && !(-20..=19).contains(&n)
            {
                return Err(self.invalid(
                    &format!("stages.{name}.nice"),
                    format!("= {n} must be in -20..=19"),
                ));
            }
            if let Some(t) = o.heartbeat_timeout_ms
                && t < 200
            {
                return Err(self.invalid(
                    &format!("stages.{name}.heartbeat_timeout_ms"),
                    format!("= {t} is too short (minimum 200: stages beat every 100 ms)"),
                ));
            }
            if o.max_restarts == Some(0) && o.restart.is_some_and(|r| r != RestartPolicy::Never) {
                return Err(self.invalid(
                    &format!("stages.{name}.max_restarts"),
                    "= 0 contradicts a restart policy; use restart = \"never\"",
                ));
            }
        }
        if self.stage_enabled(Stage::Sim) {
            let map = self.resolve_path(&self.sim.map);
            if !map.is_file() {
                return Err(self.invalid(
                    "sim.map",
                    format!("names a map file that does not exist: {}", map.display()),
                ));
            }
        }
        Ok(())
    }

    /// The pre-start check of the data flow ([`topics::STAGE_INPUTS`]): a frame source
    /// exists, every enabled stage's inputs have an enabled publisher, the actuator's device
    /// can exist. Errors name the keys to change.
    pub(super) fn validate_flow(&self) -> Result<(), ConfigError> {
        let source = self.capture.source;
        for input in topics::STAGE_INPUTS {
            if !self.stage_enabled(input.stage) {
                continue;
            }
            if input.stage == Stage::Capture && source != CaptureSource::Sim {
                continue;
            }
            let capture_size = format!("{}x{}", self.capture.width, self.capture.height);
            let hi_published = matches!(source, CaptureSource::Sim | CaptureSource::Replay)
                || capture_size == "640x480";
            if input.topic == topics::FRAMES_HI.path
                && self.stage_enabled(Stage::Capture)
                && !hi_published
            {
                return Err(self.invalid(
                    "stages.stereo-hi.enabled",
                    format!(
                        "stereo-hi reads {} but capture.width = {}, height = {} publishes only {}; \
                         set [stages.stereo-hi] enabled = false, or capture at 640x480",
                        input.topic,
                        self.capture.width,
                        self.capture.height,
                        topics::FRAMES_LO.path
                    ),
                ));
            }
            if self.stage_enabled(input.publisher) || self.bridge_delivers(input.topic) {
                continue;
            }
            let message = if input.stage == Stage::Capture {
                format!(
                    "capture.source = \"sim\" reads {} from the sim stage, but [stages.sim] \
                     enabled = false: no stage produces a frame (enable the sim stage, or set \
                     capture.source to \"v4l2\", \"files\" or \"replay\")",
                    input.topic
                )
            } else {
                format!(
                    "{} reads {}, which only {} publishes, and [stages.{}] enabled = false \
                     (enable {}, or disable {})",
                    input.stage,
                    input.topic,
                    input.publisher,
                    input.publisher,
                    input.publisher,
                    input.stage
                )
            };
            return Err(self.invalid(&format!("stages.{}.enabled", input.publisher), message));
        }
        self.validate_bridge_flow()?;
        if self.stage_enabled(Stage::Actuator) {
            let device = self.actuator.device.trim();
            if device == "sim" && !self.stage_enabled(Stage::Sim) {
                return Err(self.invalid(
                    "actuator.device",
                    "= \"sim\" opens the simulator's serial port, but [stages.sim] enabled = \
                     false; name the real device (e.g. \"/dev/ttyUSB0\") or enable the sim stage",
                ));
            }
        }
        Ok(())
    }

    /// Whether the enabled bridge takes `topic` from zenoh into this machine's shared memory.
    pub fn bridge_delivers(&self, topic: &str) -> bool {
        self.stage_enabled(Stage::Bridge) && self.bridge.subscribe.iter().any(|t| t.path() == topic)
    }

    /// The bridge's part of the flow check: it runs with an endpoint, and a topic it takes
    /// from the network has no local publisher too.
    fn validate_bridge_flow(&self) -> Result<(), ConfigError> {
        if !self.stage_enabled(Stage::Bridge) {
            return Ok(());
        }
        if !self.bridge.has_endpoints() {
            return Err(self.invalid(
                "bridge.listen",
                "is empty and so is bridge.connect: the bridge stage needs an endpoint \
                 (hvs run --bridge-listen tcp/127.0.0.1:7447 or --bridge-connect ENDPOINT)",
            ));
        }
        for t in &self.bridge.subscribe {
            let local = topics::STAGE_PUBLISHERS
                .iter()
                .find(|(path, _)| *path == t.path())
                .map(|(_, stage)| *stage)
                .filter(|stage| self.stage_enabled(*stage));
            if let Some(stage) = local {
                return Err(self.invalid(
                    "bridge.subscribe",
                    format!(
                        "takes {t} from the network, but the {stage} stage publishes it here \
                         too; disable [stages.{stage}] or drop {t} from bridge.subscribe"
                    ),
                ));
            }
        }
        Ok(())
    }

    /// Whether a stage is enabled (default: all, `sim` only with the sim capture source, and
    /// `actuator` not in a replay).
    pub fn stage_enabled(&self, stage: Stage) -> bool {
        let default = match stage {
            Stage::Sim => self.capture.source == CaptureSource::Sim,
            Stage::Actuator => self.capture.source != CaptureSource::Replay,
            Stage::Bridge => self.bridge.has_endpoints(),
            _ => true,
        };
        self.stages
            .get(stage.name())
            .and_then(|o| o.enabled)
            .unwrap_or(default)
    }

    /// The resolved process settings of every known stage, in start order.
    pub fn stage_specs(&self) -> Vec<StageSpec> {
        Stage::ALL
            .into_iter()
            .map(|stage| {
                let name = stage.name();
                let o = self.stages.get(name).cloned().unwrap_or_default();
                // The 640x480 worker and the live view only use what the fast path leaves.
                let nice = o.nice.unwrap_or(match stage {
                    Stage::StereoHi => 10,
                    Stage::View => 5,
                    _ => 0,
                });
                StageSpec {
                    stage,
                    name: name.to_string(),
                    program: o
                        .program
                        .unwrap_or_else(|| stage.default_program().to_string()),
                    args: o.args.unwrap_or_default(),
                    enabled: self.stage_enabled(stage),
                    restart: o.restart.unwrap_or(RestartPolicy::Always),
                    backoff_ms: o.backoff_ms.unwrap_or(200),
                    max_backoff_ms: o.max_backoff_ms.unwrap_or(5000),
                    max_restarts: o.max_restarts.unwrap_or(10),
                    restart_window_s: o.restart_window_s.unwrap_or(60),
                    nice,
                    heartbeat_timeout_ms: o.heartbeat_timeout_ms.unwrap_or(if nice > 0 {
                        self.supervisor
                            .heartbeat_timeout_ms
                            .max(NICED_HEARTBEAT_TIMEOUT_MS)
                    } else {
                        self.supervisor.heartbeat_timeout_ms
                    }),
                }
            })
            .collect()
    }

    /// The stereo settings for a stage name (`stereo-lo` or `stereo-hi`).
    pub fn stereo_for(&self, stage: Stage) -> Option<&StereoConfig> {
        match stage {
            Stage::StereoLo => Some(&self.stereo.lo),
            Stage::StereoHi => Some(&self.stereo.hi),
            _ => None,
        }
    }
}
