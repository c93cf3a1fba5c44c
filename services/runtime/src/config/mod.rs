//! The hvs configuration file (TOML), shared by the supervisor and every stage.
//!
//! One file describes the whole pipeline; every process loads and validates all of it, so a
//! mistake is reported the same way wherever it is found. Unknown keys are errors (a typo must
//! not silently fall back to a default), and every error names the file and the key at fault.
//! Relative paths inside the file are resolved against the file's own directory.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

mod actuator;
mod bridge;
mod camera;
mod capture;
mod decision;
mod fusion;
mod nav;
mod nav_calibration;
mod robot;
mod sim;
mod stages;
mod stereo;
mod supervisor;
mod view;

pub use actuator::*;
pub use bridge::*;
pub use camera::*;
pub use capture::*;
pub use decision::*;
pub use fusion::*;
pub use nav::*;
pub use nav_calibration::*;
pub use robot::*;
pub use sim::*;
pub use stages::*;
pub use stereo::*;
pub use supervisor::*;
pub use view::*;

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not match the schema (unknown key, wrong type).
    #[error("config file {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, with line, column and key.
        message: String,
    },
    /// A value is out of range or inconsistent with another.
    #[error("config file {path}{}: `{key}` {message}", line_suffix(*.line))]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Dotted key at fault, e.g. `stereo.lo.max_disp`.
        key: String,
        /// The line (1-based) that sets the key, when the file sets it (a default has none).
        line: Option<usize>,
        /// What is wrong with it.
        message: String,
    },
}

/// A value a section refuses: its key below the section (`fps`, `v4l2.buffers`) and what is
/// wrong with it. [`HvsConfig::validate`] turns it into a [`ConfigError`] naming the file,
/// the full key and its line.
#[derive(Debug, Clone, PartialEq)]
pub struct Invalid {
    /// Dotted key below the section.
    pub key: String,
    /// What is wrong with the value.
    pub message: String,
}

impl Invalid {
    /// An error for `key` (below the section).
    pub fn new(key: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            key: key.into(),
            message: message.into(),
        }
    }
}

pub use hvs_shared::topics::STAGE_NAMES;

/// The whole configuration.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HvsConfig {
    /// Instance name: every service lives under `hvs/<instance>/`, so two pipelines (or
    /// parallel tests) never see each other. `[A-Za-z0-9_-]`, at most 32 characters.
    #[serde(default = "default_instance")]
    pub instance: String,
    /// Supervisor timing.
    #[serde(default)]
    pub supervisor: SupervisorConfig,
    /// Camera geometry and rate.
    #[serde(default)]
    pub camera: CameraConfig,
    /// Where frames come from.
    #[serde(default)]
    pub capture: CaptureConfig,
    /// Stereo matching for both paths.
    #[serde(default)]
    pub stereo: StereoPaths,
    /// Edges, fused map and ranges.
    #[serde(default)]
    pub fusion: FusionConfig,
    /// Walls, intersections and navigation.
    #[serde(default)]
    pub decision: DecisionConfig,
    /// The exploring navigator (`decision.policy = "explore"`).
    #[serde(default)]
    pub nav: NavConfig,
    /// The servo-controller link.
    #[serde(default)]
    pub actuator: ActuatorConfig,
    /// The simulated world.
    #[serde(default)]
    pub sim: SimConfig,
    /// The robot's body (footprint, drive), shared by the simulator and the navigator.
    #[serde(default)]
    pub robot: RobotConfig,
    /// The live view (Foxglove WebSocket server and web page).
    #[serde(default)]
    pub view: ViewConfig,
    /// The zenoh bridge to other machines and ROS 2.
    #[serde(default)]
    pub bridge: BridgeConfig,
    /// Per-stage process settings, keyed by stage name (see [`STAGE_NAMES`]).
    #[serde(default)]
    pub stages: BTreeMap<String, StageOverride>,
    /// The file this configuration was loaded from (not part of the TOML).
    #[serde(skip)]
    pub source_path: PathBuf,
}

fn default_instance() -> String {
    "default".into()
}

impl HvsConfig {
    /// Reads, parses and validates a config file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates config text; `path` is used for messages and relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let mut config: HvsConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        config.source_path = path.to_path_buf();
        config.validate()?;
        Ok(config)
    }

    /// The error for `key` (dotted, from the top of the file), with the line of the file
    /// that sets it.
    pub fn invalid(&self, key: &str, message: impl Into<String>) -> ConfigError {
        let line = std::fs::read_to_string(&self.source_path)
            .ok()
            .and_then(|text| key_line(&text, key));
        ConfigError::Invalid {
            path: self.source_path.clone(),
            key: key.into(),
            line,
            message: message.into(),
        }
    }
    /// Checks every section (each checks its own values), then what spans sections: the
    /// stage settings and the data flow between the stages.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Err(message) = validate_instance_name(&self.instance) {
            return Err(self.invalid("instance", message));
        }
        let base = self.base_dir();
        let sections = [
            ("supervisor", self.supervisor.validate()),
            ("camera", self.camera.validate()),
            ("capture", self.capture.validate(base)),
            ("fusion", self.fusion.validate()),
            ("decision", self.decision.validate()),
            ("nav", self.nav.validate()),
            ("actuator", self.actuator.validate()),
            ("sim", self.sim.validate()),
            ("robot", self.robot.validate()),
            ("view", self.view.validate()),
            ("bridge", self.bridge.validate()),
        ];
        // The `[stereo.*]` sections are checked by the matchers' own rules
        // (`hvs_stereo::validate_section`, run by `hvs check`, `hvs run` and `hvs doctor`).
        for (section, checked) in sections {
            if let Err(e) = checked {
                return Err(self.invalid(&format!("{section}.{}", e.key), e.message));
            }
        }
        self.validate_stage_names()?;
        self.validate_flow()?;
        Ok(())
    }

    /// The folder relative paths in the file are taken from (the file's own).
    pub fn base_dir(&self) -> &Path {
        self.source_path.parent().unwrap_or(Path::new("."))
    }

    /// Resolves a path from the file against the file's directory.
    pub fn resolve_path(&self, p: &Path) -> PathBuf {
        resolve_path(self.base_dir(), p)
    }

    /// Replaces the frame source with the recording `file` (`hvs run --replay`): the
    /// simulator and the actuator are off unless `[stages.*]` enables them (there is no robot
    /// to drive; the recorded actuator output feeds the decision's dead reckoning).
    /// A relative `file` is taken from the current folder (a command-line path).
    pub fn use_replay(&mut self, file: &Path) -> Result<(), ConfigError> {
        self.capture.source = CaptureSource::Replay;
        self.capture.replay.file = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
        self.validate()
    }
}

impl HvsConfig {
    /// Adds zenoh endpoints from the command line (`hvs run --bridge-listen/--bridge-connect`)
    /// to `[bridge]`, which starts the bridge stage unless `[stages.bridge]` disables it, and
    /// checks the result.
    pub fn add_bridge_endpoints(
        &mut self,
        listen: &[String],
        connect: &[String],
    ) -> Result<(), ConfigError> {
        self.bridge.listen.extend(listen.iter().cloned());
        self.bridge.connect.extend(connect.iter().cloned());
        self.validate()
    }
}

/// Resolves a path from a config file against `base`, the file's folder.
pub fn resolve_path(base: &Path, p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        base.join(p)
    }
}

/// `":N"` for line `N`, nothing without one.
fn line_suffix(line: Option<usize>) -> String {
    line.map(|n| format!(":{n}")).unwrap_or_default()
}

/// The line (1-based) of `text` that sets the dotted `key` (`stereo.lo.sgm.p2`): under its
/// table header (`[stereo.lo.sgm]`) or as a dotted key under a parent table (`sgm.p2 = ...`
/// under `[stereo.lo]`). A plain line scan, not a TOML parser: it is used only to point at
/// a key in an error message, after the file has parsed, and gives `None` when unsure.
pub fn key_line(text: &str, key: &str) -> Option<usize> {
    let mut table = String::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if let Some(header) = line.strip_prefix('[') {
            table = header.trim_end_matches(']').trim().replace(' ', "");
            continue;
        }
        let Some((name, _)) = line.split_once('=') else {
            continue;
        };
        let name = name.trim().replace(' ', "");
        let full = if table.is_empty() {
            name
        } else {
            format!("{table}.{name}")
        };
        if full == key {
            return Some(i + 1);
        }
    }
    None
}

/// Checks an instance name: `[A-Za-z0-9_-]`, 1 to 32 characters.
pub fn validate_instance_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > 32 {
        return Err(format!("= {name:?} must have 1 to 32 characters"));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(format!(
            "= {name:?} contains {c:?}; use letters, digits, '-' and '_'"
        ));
    }
    Ok(())
}

/// Per-instance run folder for files that are not shared memory (the simulator's pty link,
/// the supervisor lock): `$HVS_RUN_DIR/<instance>` or `/tmp/hvs-<uid>/<instance>`.
pub fn run_dir(instance: &str) -> PathBuf {
    let base = std::env::var_os("HVS_RUN_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(format!("/tmp/hvs-{}", nix::unistd::getuid())));
    base.join(instance)
}

/// Path of the simulator's pty link for an instance (what `actuator.device = "sim"` opens).
pub fn sim_pty_path(instance: &str) -> PathBuf {
    run_dir(instance).join("psc-sim")
}

#[cfg(test)]
mod tests;
