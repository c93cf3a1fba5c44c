//! One supervisor per instance: the lock file in the instance's run folder.

use std::fs::File;
use std::io::Write;
use std::os::fd::AsRawFd;
use std::path::PathBuf;

use anyhow::{Context, bail};
use hvs_runtime::config::run_dir;

/// Holds the per-instance lock file: one supervisor per instance.
pub(super) struct InstanceLock {
    _file: File,
    path: PathBuf,
}

impl InstanceLock {
    pub(super) fn acquire(instance: &str) -> anyhow::Result<Self> {
        let dir = run_dir(instance);
        std::fs::create_dir_all(&dir)
            .with_context(|| format!("cannot create run folder {}", dir.display()))?;
        let path = dir.join("supervisor.lock");
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .truncate(false)
            .read(true)
            .write(true)
            .open(&path)
            .with_context(|| format!("cannot open lock file {}", path.display()))?;
        // SAFETY: plain flock on a file descriptor we own.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            let other = std::fs::read_to_string(&path).unwrap_or_default();
            bail!(
                "instance {instance:?} already has a running supervisor (pid {}); use `hvs stop --instance {instance}` or another --instance",
                other.trim()
            );
        }
        file.set_len(0)?;
        write!(file, "{}", std::process::id())?;
        Ok(Self { _file: file, path })
    }
}

impl Drop for InstanceLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}
