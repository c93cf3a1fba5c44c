//! `[supervisor]`: the supervisor's timing.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Supervisor timing.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupervisorConfig {
    /// A running stage that has not sent a heartbeat for this long is declared hung and killed.
    pub heartbeat_timeout_ms: u64,
    /// A new stage gets this long to send its first heartbeat.
    pub startup_timeout_ms: u64,
    /// Period of the status line and of the status topic.
    pub status_period_ms: u64,
    /// Grace time between SIGTERM and SIGKILL when stopping a stage.
    pub stop_timeout_ms: u64,
    /// Folder holding the stage binaries (default: the folder of the `hvs` executable).
    pub bin_dir: Option<PathBuf>,
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self {
            heartbeat_timeout_ms: 1000,
            startup_timeout_ms: 10_000,
            status_period_ms: 1000,
            stop_timeout_ms: 2000,
            bin_dir: None,
        }
    }
}

impl SupervisorConfig {
    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        let s = self;
        for (key, value) in [
            ("heartbeat_timeout_ms", s.heartbeat_timeout_ms),
            ("startup_timeout_ms", s.startup_timeout_ms),
            ("status_period_ms", s.status_period_ms),
            ("stop_timeout_ms", s.stop_timeout_ms),
        ] {
            if value < 100 {
                return Err(Invalid::new(
                    key,
                    format!("= {value} is too short (minimum 100)"),
                ));
            }
        }
        Ok(())
    }
}
