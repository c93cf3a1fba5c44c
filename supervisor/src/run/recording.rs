//! `hvs run --replay` and `--record`: the recording checked before any stage starts, and the
//! recorder child started before the stages and stopped after them.

use std::path::{Path, PathBuf};
use std::process::Child;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use hvs_runtime::config::run_dir;

use super::describe_exit;
use crate::process;

/// Checks, before any stage starts, that `path` is there and starts like an MCAP file (the
/// capture stage reads it).
pub(super) fn check_recording(path: &Path) -> anyhow::Result<PathBuf> {
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    if let Err(e) = hvs_capture::replay::check_magic(&abs) {
        bail!(
            "--replay {}: {e}; record one with `hvs run --record` or `hvs probe record`",
            path.display()
        );
    }
    Ok(abs)
}

/// The recorder child of `hvs run --record`: `hvs probe record` started before the stages.
pub(super) struct Recorder {
    child: Child,
    out: PathBuf,
}

impl Recorder {
    /// Starts the recorder and waits until it has subscribed to every topic.
    pub(super) fn start(instance: &str, out: &Path, config: &Path) -> anyhow::Result<Self> {
        let exe = std::env::current_exe().context("cannot locate the hvs executable")?;
        let ready = run_dir(instance).join("recorder.ready");
        let _ = std::fs::remove_file(&ready);
        let mut cmd = std::process::Command::new(exe);
        // The config gives the recording its camera calibration and transforms.
        cmd.args(["probe", "record", "--instance", instance, "--create-topics"])
            .arg("--config")
            .arg(config)
            .arg("--out")
            .arg(out)
            .arg("--ready-file")
            .arg(&ready);
        let mut child = process::spawn_child("record", cmd, 0)?;
        let deadline = Instant::now() + Duration::from_secs(10);
        while !ready.exists() {
            if let Ok(Some(status)) = child.try_wait() {
                bail!(
                    "--record {}: the recorder exited before it started ({})",
                    out.display(),
                    describe_exit(process::exit_code(&status))
                );
            }
            if Instant::now() > deadline {
                process::terminate(&mut child, Duration::from_secs(1));
                bail!(
                    "--record {}: the recorder did not subscribe within 10 s",
                    out.display()
                );
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = std::fs::remove_file(&ready);
        tracing::info!("hvs: recording to {}", out.display());
        Ok(Self {
            child,
            out: out.to_path_buf(),
        })
    }

    /// Stops it (SIGTERM: it closes the file with its summary) after the stages stopped.
    pub(super) fn stop(mut self) {
        match process::terminate(&mut self.child, Duration::from_secs(30)) {
            Some(s) if s.success() => {}
            status => tracing::warn!(
                "hvs: the recorder of {} ended with {}",
                self.out.display(),
                status.map_or("no status".to_string(), |s| describe_exit(
                    process::exit_code(&s)
                ))
            ),
        }
    }
}
