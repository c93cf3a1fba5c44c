//! Starting and stopping stage processes.
//!
//! Each stage runs in its own process group (a Ctrl-C in the terminal reaches only the
//! supervisor, which then stops the stages in order: actuator first) and with a parent-death
//! signal (if the supervisor is killed, every stage gets SIGTERM, so the actuator sends
//! neutral instead of leaving the wheels driving). Their stdout and stderr are forwarded line by
//! line with the stage name in front.

use std::io::{BufRead, BufReader, Read, Write};
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};

pub use crate::run::LineSender;
use nix::unistd::Pid;

/// Why a stage could not be spawned.
#[derive(Debug, thiserror::Error)]
#[error("cannot start stage {stage} ({program}): {source}")]
pub struct SpawnError {
    /// The stage.
    pub stage: String,
    /// The program.
    pub program: PathBuf,
    /// The OS error.
    #[source]
    pub source: std::io::Error,
}

/// Everything needed to start one stage process.
#[derive(Debug, Clone)]
pub struct Launch<'a> {
    /// Stage name (used as `--stage` and as the log prefix).
    pub stage: &'a str,
    /// Executable.
    pub program: &'a Path,
    /// Config file passed as `--config`.
    pub config: &'a Path,
    /// Instance passed as `--instance`.
    pub instance: &'a str,
    /// Extra arguments.
    pub extra_args: &'a [String],
    /// RUST_LOG for the child, if the supervisor's own environment has none.
    pub default_log_filter: &'a str,
    /// CPU niceness of the child.
    pub nice: i32,
    /// Where its standard error lines go besides the terminal (the `log` topic).
    pub log_lines: Option<&'a LineSender>,
}

/// Spawns a stage and starts forwarding its output.
pub fn spawn(launch: &Launch<'_>) -> Result<Child, SpawnError> {
    let mut cmd = Command::new(launch.program);
    cmd.arg("--config")
        .arg(launch.config)
        .arg("--instance")
        .arg(launch.instance)
        .arg("--stage")
        .arg(launch.stage)
        .args(launch.extra_args);
    if std::env::var_os("RUST_LOG").is_none() {
        cmd.env("RUST_LOG", launch.default_log_filter);
    }
    spawn_logged(launch.stage, cmd, launch.nice, launch.log_lines)
}

/// Spawns `cmd` as a child of the pipeline (own process group, SIGTERM when the supervisor
/// dies, output forwarded with `name` in front).
pub fn spawn_child(name: &str, cmd: Command, nice: i32) -> Result<Child, SpawnError> {
    spawn_logged(name, cmd, nice, None)
}

/// [`spawn_child`], with its standard error lines also sent to `log_lines`.
fn spawn_logged(
    name: &str,
    mut cmd: Command,
    nice: i32,
    log_lines: Option<&LineSender>,
) -> Result<Child, SpawnError> {
    cmd.stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .process_group(0);
    let parent = std::process::id() as libc::pid_t;
    // SAFETY: the closure runs in the child between fork and exec and only calls
    // async-signal-safe functions (prctl, setpriority, getppid, raise).
    unsafe {
        cmd.pre_exec(move || {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            // Lowering priority always works; raising it needs privileges and is best effort.
            if nice != 0 {
                libc::setpriority(libc::PRIO_PROCESS, 0, nice);
            }
            // The supervisor may have died before prctl took effect.
            if libc::getppid() != parent {
                libc::raise(libc::SIGTERM);
            }
            Ok(())
        });
    }
    let mut child = cmd.spawn().map_err(|source| SpawnError {
        stage: name.to_string(),
        program: PathBuf::from(cmd.get_program()),
        source,
    })?;
    if let Some(out) = child.stdout.take() {
        forward(name.to_string(), out, false, None);
    }
    if let Some(err) = child.stderr.take() {
        forward(name.to_string(), err, true, log_lines.cloned());
    }
    Ok(child)
}

/// Copies a child's stream to ours, one prefixed line at a time, until it closes.
fn forward<R: Read + Send + 'static>(
    stage: String,
    stream: R,
    to_stderr: bool,
    log_lines: Option<LineSender>,
) {
    let name = stage.clone();
    let spawned = std::thread::Builder::new()
        .name(format!("log-{stage}"))
        .spawn(move || {
            let mut reader = BufReader::new(stream);
            let mut line = Vec::new();
            loop {
                line.clear();
                match reader.read_until(b'\n', &mut line) {
                    Ok(0) | Err(_) => break,
                    Ok(_) => {
                        let text = String::from_utf8_lossy(&line);
                        let text = text.trim_end();
                        if let Some(l) = &log_lines {
                            l.send(&stage, text);
                        }
                        // A closed terminal must not kill the forwarder: ignore write errors.
                        if to_stderr {
                            let _ = writeln!(std::io::stderr().lock(), "{stage:>10} | {text}");
                        } else {
                            let _ = writeln!(std::io::stdout().lock(), "{stage:>10} | {text}");
                        }
                    }
                }
            }
        });
    if let Err(e) = spawned {
        tracing::warn!("cannot start the log forwarder of {name}: {e}");
    }
}

/// Sends `signal` to a process, ignoring "no such process".
pub fn signal(pid: u32, signal: Signal) {
    if pid == 0 {
        return;
    }
    if let Err(e) = kill(Pid::from_raw(pid as i32), signal)
        && e != nix::errno::Errno::ESRCH
    {
        tracing::warn!("cannot send {signal} to pid {pid}: {e}");
    }
}

/// SIGTERM, then SIGKILL after `grace`; reaps the child. Returns its exit status.
pub fn terminate(child: &mut Child, grace: Duration) -> Option<ExitStatus> {
    if let Ok(Some(status)) = child.try_wait() {
        return Some(status);
    }
    signal(child.id(), Signal::SIGTERM);
    let deadline = Instant::now() + grace;
    while Instant::now() < deadline {
        match child.try_wait() {
            Ok(Some(status)) => return Some(status),
            Ok(None) => std::thread::sleep(Duration::from_millis(10)),
            Err(_) => break,
        }
    }
    signal(child.id(), Signal::SIGKILL);
    child.wait().ok()
}

/// Exit status as a number: the exit code, or minus the signal that killed it.
pub fn exit_code(status: &ExitStatus) -> i32 {
    use std::os::unix::process::ExitStatusExt;
    status
        .code()
        .unwrap_or_else(|| -status.signal().unwrap_or(0))
}
