//! Helpers for the end-to-end tests: start a real `hvs run` in its own instance, watch it
//! through `hvs status --json` and through the pipeline's own shared-memory topics, and tear it
//! down.
//!
//! The tests need the release binaries: the README's test command builds them first
//! (`cargo build --release && cargo test --release`).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

/// The stages a default run starts: every stage but the bridge, the last of
/// [`hvs_runtime::config::STAGE_NAMES`], which starts only with a zenoh endpoint
/// (tests/tests/distributed.rs runs it).
pub const DEFAULT_STAGES: [&str; 8] = {
    let all = hvs_runtime::config::STAGE_NAMES;
    assert!(all.len() == 9);
    let mut names = [""; 8];
    let mut i = 0;
    while i < 8 {
        names[i] = all[i];
        i += 1;
    }
    names
};

/// One pipeline at a time: each uses most of a 2-core machine.
static PIPELINE_LOCK: Mutex<()> = Mutex::new(());
static INSTANCE_COUNTER: AtomicU32 = AtomicU32::new(0);

/// The repository root.
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from(".."))
}

/// Folder of the built binaries (the test executable lives in `<it>/deps/`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let deps = exe.parent().expect("deps folder");
    deps.parent().expect("profile folder").to_path_buf()
}

/// Path of a built binary; panics with the build command if it is missing.
pub fn bin(name: &str) -> PathBuf {
    let p = bin_dir().join(name);
    assert!(
        p.is_file(),
        "{} not found: build the workspace first (cargo build --release && cargo test --release)",
        p.display()
    );
    p
}

/// A fresh instance name unique to this process and test.
pub fn unique_instance(tag: &str) -> String {
    format!(
        "e2e{}-{}-{tag}",
        std::process::id(),
        INSTANCE_COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// Writes a config to `dir/name` based on config/sim.toml with `extra` appended (TOML tables
/// in `extra` must not repeat tables of the base: use `base_overrides` to replace lines).
pub fn write_config(
    dir: &Path,
    name: &str,
    base_overrides: &[(&str, &str)],
    extra: &str,
) -> PathBuf {
    let base =
        std::fs::read_to_string(repo_root().join("config/sim.toml")).expect("config/sim.toml");
    let mut text = base.replace(
        "map = \"maps/maze.txt\"",
        &format!(
            "map = \"{}\"",
            repo_root().join("config/maps/maze.txt").display()
        ),
    );
    // Live view on free ports (shown in its status note): tests never take 8765/8766.
    text = text
        .replace("bind = \"127.0.0.1:8765\"", "bind = \"127.0.0.1:0\"")
        .replace(
            "http_bind = \"127.0.0.1:8766\"",
            "http_bind = \"127.0.0.1:0\"",
        );
    for (from, to) in base_overrides {
        assert!(text.contains(from), "config/sim.toml has no line {from:?}");
        text = text.replace(from, to);
    }
    text.push('\n');
    text.push_str(extra);
    let path = dir.join(name);
    std::fs::write(&path, text).expect("write config");
    path
}

/// Runs `hvs` with arguments to completion.
pub fn hvs(args: &[&str]) -> Output {
    Command::new(bin("hvs"))
        .args(args)
        .env("RUST_LOG", "warn")
        .output()
        .expect("run hvs")
}

/// Runs `hvs` with arguments to completion and requires success (the panic message names
/// the command and carries its stderr).
pub fn hvs_ok(args: &[&str]) -> Output {
    let out = hvs(args);
    assert!(
        out.status.success(),
        "hvs {} failed:\n{}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A running `hvs run`, stopped when dropped.
pub struct Pipeline {
    /// Instance name.
    pub instance: String,
    /// The config file used.
    pub config: PathBuf,
    // Options only so that `restart_after` can hand them to the next run.
    dir: Option<tempfile::TempDir>,
    child: Option<Child>,
    serial: Option<MutexGuard<'static, ()>>,
    files_before: Vec<String>,
}

impl Pipeline {
    /// Starts `hvs run` with config/sim.toml plus `extra` config text, in a fresh instance.
    pub fn start(tag: &str, base_overrides: &[(&str, &str)], extra: &str) -> Self {
        let serial = PIPELINE_LOCK.lock().unwrap_or_else(|e| e.into_inner());
        let files_before = iceoryx_files();
        let dir = tempfile::tempdir().expect("tempdir");
        let mut p = Self::launch(unique_instance(tag), dir, base_overrides, extra, serial);
        p.files_before = files_before;
        p
    }

    /// Starts a second `hvs run` beside one started with [`Pipeline::start`] (whose lock
    /// covers both): another machine's instance, from the whole config text `config_text`.
    pub fn start_beside(tag: &str, config_text: &str) -> Self {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("hvs.toml"), config_text).expect("write config");
        Self::spawn(unique_instance(tag), dir, None)
    }

    /// iceoryx2 files that existed before this pipeline started (taken under the lock).
    pub fn files_before(&self) -> &[String] {
        &self.files_before
    }

    /// Starts another `hvs run` on the same instance and run folder as `previous` (which must
    /// have stopped or been killed), keeping the one-pipeline-at-a-time lock.
    pub fn restart_after(mut previous: Pipeline) -> Self {
        if let Some(mut c) = previous.child.take() {
            let _ = c.wait();
        }
        let instance = std::mem::take(&mut previous.instance);
        let dir = previous.dir.take().expect("temp folder");
        let serial = previous.serial.take().expect("pipeline lock");
        let text = std::fs::read_to_string(&previous.config).expect("previous config");
        Self::launch_with_text(instance, dir, &text, serial)
    }

    /// Temp folder with config, logs and report.
    pub fn dir(&self) -> &Path {
        self.dir
            .as_ref()
            .map_or(Path::new("/nonexistent"), |d| d.path())
    }

    fn launch(
        instance: String,
        dir: tempfile::TempDir,
        base_overrides: &[(&str, &str)],
        extra: &str,
        serial: MutexGuard<'static, ()>,
    ) -> Self {
        let config = write_config(dir.path(), "hvs.toml", base_overrides, extra);
        let text = std::fs::read_to_string(&config).expect("config");
        Self::launch_with_text(instance, dir, &text, serial)
    }

    fn launch_with_text(
        instance: String,
        dir: tempfile::TempDir,
        config_text: &str,
        serial: MutexGuard<'static, ()>,
    ) -> Self {
        let config = dir.path().join("hvs.toml");
        std::fs::write(&config, config_text).expect("write config");
        Self::spawn(instance, dir, Some(serial))
    }

    fn spawn(
        instance: String,
        dir: tempfile::TempDir,
        serial: Option<MutexGuard<'static, ()>>,
    ) -> Self {
        let config = dir.path().join("hvs.toml");
        let stdout = std::fs::File::create(dir.path().join("stdout.log")).expect("log file");
        let stderr = std::fs::File::create(dir.path().join("stderr.log")).expect("log file");
        let child = Command::new(bin("hvs"))
            .args(["run", "--config"])
            .arg(&config)
            .args(["--instance", &instance, "--report"])
            .arg(dir.path().join("report.json"))
            .env("HVS_RUN_DIR", dir.path().join("run"))
            .stdin(Stdio::null())
            .stdout(stdout)
            .stderr(stderr)
            .spawn()
            .expect("spawn hvs run");
        Self {
            instance,
            dir: Some(dir),
            config,
            child: Some(child),
            serial,
            files_before: Vec::new(),
        }
    }

    /// Pid of the supervisor.
    pub fn supervisor_pid(&self) -> u32 {
        self.child.as_ref().map_or(0, Child::id)
    }

    /// The supervisor's log so far (stdout and stderr), for failure messages.
    pub fn logs(&self) -> String {
        let read = |n: &str| std::fs::read_to_string(self.dir().join(n)).unwrap_or_default();
        let tail = |s: String| {
            let lines: Vec<&str> = s.lines().collect();
            lines[lines.len().saturating_sub(60)..].join("\n")
        };
        format!(
            "--- stdout ---\n{}\n--- stderr ---\n{}",
            tail(read("stdout.log")),
            tail(read("stderr.log"))
        )
    }

    /// `hvs status --json` of this instance (None while no status is available).
    pub fn status(&self) -> Option<Value> {
        let out = hvs(&["status", "--json", "--instance", &self.instance]);
        if !out.status.success() {
            return None;
        }
        serde_json::from_slice(&out.stdout).ok()
    }

    /// Waits until `pred` holds for the status, or panics with the logs after `timeout`.
    pub fn wait_status(
        &self,
        what: &str,
        timeout: Duration,
        pred: impl Fn(&Value) -> bool,
    ) -> Value {
        let deadline = Instant::now() + timeout;
        let mut last = None;
        while Instant::now() < deadline {
            if let Some(s) = self.status() {
                if pred(&s) {
                    return s;
                }
                last = Some(s);
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        panic!(
            "timed out after {timeout:?} waiting for: {what}\nlast status: {}\n{}",
            last.map(|s| s.to_string()).unwrap_or_default(),
            self.logs()
        );
    }

    /// Waits until every enabled stage runs and has produced output.
    pub fn wait_all_running(&self, timeout: Duration) -> Value {
        self.wait_status("every stage running with output", timeout, |s| {
            stages(s).iter().all(|st| {
                let state = st["state"].as_str().unwrap_or("");
                // The view sends only to clients: it is ready once it serves.
                let serving = st["stage"] == "view"
                    && st["note"]
                        .as_str()
                        .is_some_and(|n| hvs_view::note::ws_port(n).is_some());
                state == "disabled"
                    || (state == "running"
                        && (serving || st["frames_out"].as_u64().unwrap_or(0) > 0))
            })
        })
    }

    /// Sends a signal to the supervisor.
    pub fn signal(&self, signal: Signal) {
        kill(Pid::from_raw(self.supervisor_pid() as i32), signal).expect("signal supervisor");
    }

    /// Waits for the supervisor to exit and returns its exit code, or panics after `timeout`.
    pub fn wait_exit(&mut self, timeout: Duration) -> i32 {
        let deadline = Instant::now() + timeout;
        let child = self.child.as_mut().expect("running");
        loop {
            if let Some(status) = child.try_wait().expect("poll hvs run") {
                self.child = None;
                return status.code().unwrap_or(-1);
            }
            if Instant::now() > deadline {
                panic!("hvs run did not exit within {timeout:?}\n{}", self.logs());
            }
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// The report written at the end of the run.
    pub fn report(&self) -> Value {
        let text = std::fs::read_to_string(self.dir().join("report.json"))
            .unwrap_or_else(|e| panic!("no report.json ({e})\n{}", self.logs()));
        serde_json::from_str(&text).expect("report is JSON")
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        if let Some(child) = self.child.as_mut() {
            let _ = kill(Pid::from_raw(child.id() as i32), Signal::SIGTERM);
            let deadline = Instant::now() + Duration::from_secs(10);
            while Instant::now() < deadline {
                if let Ok(Some(_)) = child.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// The `stages` array of a status.
pub fn stages(status: &Value) -> Vec<Value> {
    status["stages"].as_array().cloned().unwrap_or_default()
}

/// One stage's entry of a status.
pub fn stage(status: &Value, name: &str) -> Value {
    stages(status)
        .into_iter()
        .find(|s| s["stage"] == name)
        .unwrap_or_else(|| panic!("no stage {name} in {status}"))
}

/// Pid of a stage in a status.
pub fn pid_of(status: &Value, name: &str) -> u32 {
    stage(status, name)["pid"].as_u64().unwrap_or(0) as u32
}

/// Sends a signal to a process.
pub fn signal_pid(pid: u32, signal: Signal) {
    kill(Pid::from_raw(pid as i32), signal)
        .unwrap_or_else(|e| panic!("signal {signal} to {pid}: {e}"));
}

pub mod psc_peer;

/// A Python 3 (`HVS_PYTHON` if set, else `python3`) that runs `import_check` with
/// `PYTHONPATH` set to the returned folder: PyPI's `packages` are installed there with pip the
/// first time (`target/<folder>`). Panics, naming pip's error, when they cannot be installed.
pub fn python_with(folder: &str, import_check: &str, packages: &[&str]) -> (String, PathBuf) {
    let python = std::env::var("HVS_PYTHON").unwrap_or_else(|_| "python3".to_string());
    let site = repo_root().join("target").join(folder);
    let imports = |python: &str| {
        Command::new(python)
            .args(["-c", import_check])
            .env("PYTHONPATH", &site)
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !imports(&python) {
        let pip = |extra: &[&str]| {
            Command::new(&python)
                .args([
                    "-m",
                    "pip",
                    "install",
                    "--quiet",
                    "--disable-pip-version-check",
                ])
                .args(extra)
                .arg("--target")
                .arg(&site)
                .args(packages)
                .output()
                .unwrap_or_else(|e| panic!("cannot run {python}: {e} (set HVS_PYTHON)"))
        };
        let mut out = pip(&[]);
        // Debian's python3 refuses installs it does not manage (PEP 668) even into a folder
        // of our own; the folder is ours, so tell it so.
        if String::from_utf8_lossy(&out.stderr).contains("externally-managed") {
            out = pip(&["--break-system-packages"]);
        }
        assert!(
            out.status.success(),
            "pip install {} into {} failed: {}",
            packages.join(" "),
            site.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            imports(&python),
            "{} installed but `{import_check}` fails",
            packages.join(" ")
        );
    }
    (python, site)
}

/// A TCP port free on 127.0.0.1 now (the OS picks it; it stays free unless another process
/// takes it in the moment before the caller binds it).
pub fn free_loopback_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free loopback port")
}

pub use hvs_runtime::ipc::iceoryx_files;

/// The ports the view stage serves on (WebSocket, web page), read from its status note once
/// it serves; panics with the logs after `timeout`.
pub fn view_ports(p: &Pipeline, timeout: Duration) -> (u16, u16) {
    use hvs_view::note::{http_port, ws_port};
    let ports = |s: &Value| {
        let note = stage(s, "view")["note"].as_str().unwrap_or("").to_string();
        ws_port(&note).zip(http_port(&note))
    };
    let status = p.wait_status("the view serving", timeout, |s| ports(s).is_some());
    ports(&status).unwrap_or_default()
}
