//! `hvs doctor`: what a robot needs before `hvs run`, one line per check with what to do
//! about it. Exit 0 when nothing fails (warnings allowed), 1 otherwise.
//!
//! Checks: the config (schema, ranges, data flow, the simulator's map); the cameras (found,
//! stable `/dev/v4l/by-path` names, formats, both streaming together in the negotiated
//! mode); the serial device (present, writable, the `dialout` group); the servo controller
//! answering `!SCVER?`; free space on /dev/shm against what the services map; iceoryx2
//! leftovers of a dead run and a supervisor already running.

use std::path::{Path, PathBuf};
use std::time::Duration;

use hvs_capture::v4l2::camera::open_capture_node;
use hvs_capture::v4l2::{
    CameraMode, DeviceOpener, KernelOpener, OpenError, StereoCamera, StereoSpec,
};
use hvs_runtime::config::{CaptureSource, HvsConfig};
use hvs_shared::messages::{
    DisparityMap320x240, DisparityMap640x480, StereoFrame320x240, StereoFrame640x480,
};
use hvs_shared::topics::{self, Topic};

/// How a check came out.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Fine.
    Ok,
    /// Works, but worth knowing.
    Warn,
    /// `hvs run` will not work as configured.
    Fail,
}

impl Verdict {
    fn label(self) -> &'static str {
        match self {
            Self::Ok => "ok  ",
            Self::Warn => "warn",
            Self::Fail => "FAIL",
        }
    }
}

/// One line of the report.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Check {
    /// What was checked (`config`, `camera left`, `serial`, ...).
    pub what: String,
    /// The outcome.
    pub verdict: Verdict,
    /// What was found.
    pub detail: String,
    /// What to do about it (failures and warnings).
    pub fix: Option<String>,
}

impl Check {
    fn ok(what: &str, detail: impl Into<String>) -> Self {
        Self {
            what: what.into(),
            verdict: Verdict::Ok,
            detail: detail.into(),
            fix: None,
        }
    }

    fn bad(
        verdict: Verdict,
        what: &str,
        detail: impl Into<String>,
        fix: impl Into<String>,
    ) -> Self {
        Self {
            what: what.into(),
            verdict,
            detail: detail.into(),
            fix: Some(fix.into()),
        }
    }
}

impl std::fmt::Display for Check {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {:<14} {}",
            self.verdict.label(),
            self.what,
            self.detail
        )?;
        if let Some(fix) = &self.fix {
            write!(f, " -> {fix}")?;
        }
        Ok(())
    }
}

/// Runs every check for the config at `path`; prints one line each; true if none failed.
pub fn doctor(path: &Path) -> bool {
    let checks = run_checks(path, &KernelOpener);
    for c in &checks {
        println!("{c}");
    }
    let failed = checks.iter().filter(|c| c.verdict == Verdict::Fail).count();
    let warned = checks.iter().filter(|c| c.verdict == Verdict::Warn).count();
    if failed == 0 {
        println!("hvs doctor: ready to run ({warned} warnings)");
    } else {
        println!("hvs doctor: {failed} checks failed, {warned} warnings");
    }
    failed == 0
}

/// Every check, cameras opened through `opener`.
pub fn run_checks(path: &Path, opener: &dyn DeviceOpener) -> Vec<Check> {
    let mut checks = Vec::new();
    let config = match HvsConfig::load(path)
        .map_err(anyhow::Error::from)
        .and_then(|c| {
            crate::preflight(&c)?;
            Ok(c)
        }) {
        Ok(c) => {
            checks.push(Check::ok(
                "config",
                format!("{} is valid (instance {:?})", path.display(), c.instance),
            ));
            Some(c)
        }
        Err(e) => {
            checks.push(Check::bad(
                Verdict::Fail,
                "config",
                format!("{e:#}"),
                "fix the key it names (`hvs run --help` for the defaults)",
            ));
            None
        }
    };
    if let Some(c) = &config {
        if let Some(pid) = running_supervisor(c) {
            checks.push(Check::bad(
                Verdict::Warn,
                "devices",
                format!(
                    "cameras and serial device not checked: instance {:?} is running \
                     (supervisor pid {pid}) and holds them",
                    c.instance
                ),
                "`hvs status` shows what they do; `hvs stop` first to check them here",
            ));
        } else {
            checks.extend(camera_checks(c, opener));
            checks.extend(serial_checks(c));
        }
    } else {
        checks.push(Check::bad(
            Verdict::Warn,
            "devices",
            "cameras and serial device not checked",
            "the config must load first",
        ));
    }
    checks.push(shm_check());
    checks.extend(leftover_checks(config.as_ref()));
    checks
}

/// The stable names of `device` under /dev/v4l/by-path and by-id.
fn stable_names(device: &Path) -> Vec<PathBuf> {
    let target = std::fs::canonicalize(device).ok();
    let mut names = Vec::new();
    for dir in ["/dev/v4l/by-path", "/dev/v4l/by-id"] {
        let Ok(entries) = std::fs::read_dir(dir) else {
            continue;
        };
        for e in entries.flatten() {
            if target.is_some() && std::fs::canonicalize(e.path()).ok() == target {
                names.push(e.path());
            }
        }
    }
    names.sort();
    names
}

/// The nodes of a kind present (`/dev/video*`), for the "found instead" hints.
fn present(prefixes: &[&str]) -> String {
    let mut found: Vec<String> = Vec::new();
    for p in prefixes {
        let (dir, stem) = p.rsplit_once('/').unwrap_or(("/dev", p));
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries.flatten() {
                let name = e.file_name().to_string_lossy().into_owned();
                if name.starts_with(stem) {
                    found.push(format!("{dir}/{name}"));
                }
            }
        }
    }
    found.sort();
    if found.is_empty() {
        "none".into()
    } else {
        found.join(", ")
    }
}

fn camera_checks(c: &HvsConfig, opener: &dyn DeviceOpener) -> Vec<Check> {
    let source = c.capture.source;
    if source != CaptureSource::V4l2 {
        let how = match source {
            CaptureSource::Sim => "the simulator renders the pair",
            CaptureSource::Files => "pairs come from capture.files.folder",
            _ => "pairs come from a recording",
        };
        return vec![Check::ok(
            "cameras",
            format!("not used (capture.source = {source:?}: {how})").to_lowercase(),
        )];
    }
    let v = &c.capture.v4l2;
    let mut checks = Vec::new();
    let mut all_there = true;
    for (side, key, device) in [
        ("camera left", "capture.v4l2.left_device", &v.left_device),
        ("camera right", "capture.v4l2.right_device", &v.right_device),
    ] {
        let names = stable_names(device);
        let by_path = device.starts_with("/dev/v4l/");
        // The capture's own open and capability check, so doctor and `hvs run` agree.
        let (mut dev, caps) = match open_capture_node(opener, device) {
            Ok(opened) => opened,
            Err(e) => {
                all_there = false;
                let (detail, fix) = match &e {
                    OpenError::Missing { .. } => (
                        format!("{} ({key}) not found", device.display()),
                        format!(
                            "plug the Minoru in; video devices present: {}; stable names: ls \
                             -l /dev/v4l/by-path/",
                            present(&["/dev/video"])
                        ),
                    ),
                    OpenError::Permission { .. } => (
                        e.to_string(),
                        "add the user to the `video` group (sudo usermod -aG video $USER), \
                         then log in again"
                            .to_string(),
                    ),
                    OpenError::NotCapture { .. } => (
                        e.to_string(),
                        "its /dev/v4l/by-path name ends in -index0".to_string(),
                    ),
                    OpenError::NotV4l2 { .. } => (e.to_string(), format!("set {key} to a camera")),
                    _ => (
                        e.to_string(),
                        "close whatever else uses the camera".to_string(),
                    ),
                };
                checks.push(Check::bad(Verdict::Fail, side, detail, fix));
                continue;
            }
        };
        let offer = hvs_capture::v4l2::camera::enumerate(dev.as_mut(), device);
        let detail = format!(
            "{} ({}, {}): {}",
            device.display(),
            caps.card,
            caps.bus_info,
            offer.map_or_else(|e| e.to_string(), |o| o.summary())
        );
        if !by_path && !names.is_empty() {
            checks.push(Check::bad(
                Verdict::Warn,
                side,
                detail,
                format!(
                    "/dev/videoN changes with the plug order: set {key} = {:?}",
                    names[0].display().to_string()
                ),
            ));
        } else {
            checks.push(Check::ok(side, detail));
        }
    }
    if !all_there {
        return checks;
    }
    let spec = StereoSpec {
        left_device: v.left_device.clone(),
        right_device: v.right_device.clone(),
        mode: CameraMode {
            width: c.capture.width,
            height: c.capture.height,
            format: v.pixel_format,
            fps: c.camera.fps,
            buffers: v.buffers,
        },
        max_skew_ns: (v.max_skew_ms * 1e6) as u64,
        stall_timeout: Duration::from_millis(v.stall_timeout_ms),
        controls: v.controls.clone(),
    };
    checks.push(match StereoCamera::open_with(&spec, opener) {
        Ok(cam) => {
            let n = cam.negotiated();
            if n.fell_back() {
                Check::bad(
                    Verdict::Warn,
                    "cameras",
                    format!("stream together at {}", n.summary()),
                    "put the cameras on separate USB controllers for the preferred mode, or \
                     lower camera.fps",
                )
            } else {
                Check::ok("cameras", format!("stream together at {}", n.summary()))
            }
        }
        Err(e) => Check::bad(
            Verdict::Fail,
            "cameras",
            format!("cannot stream both: {e}"),
            "see the reason; `hvs run` retries this by itself",
        ),
    });
    checks
}

fn serial_checks(c: &HvsConfig) -> Vec<Check> {
    if !c.stage_enabled(hvs_shared::topics::Stage::Actuator) {
        return vec![Check::ok("serial", "not used (the actuator stage is off)")];
    }
    let a = &c.actuator;
    if a.device == "sim" {
        return vec![Check::ok(
            "serial",
            "the simulator's pseudo-terminal (created by the sim stage at start)",
        )];
    }
    let device = PathBuf::from(&a.device);
    if !device.exists() {
        return vec![Check::bad(
            Verdict::Fail,
            "serial",
            format!("{} (actuator.device) not found", device.display()),
            format!(
                "plug in the PSC's USB-serial adapter; serial devices present: {}",
                present(&["/dev/ttyUSB", "/dev/ttyACM", "/dev/serial/by-id/"])
            ),
        )];
    }
    let mut checks = Vec::new();
    if let Err(e) = nix::unistd::access(&device, nix::unistd::AccessFlags::W_OK) {
        checks.push(Check::bad(
            Verdict::Fail,
            "serial",
            format!("cannot write {}: {e}", device.display()),
            "add the user to the `dialout` group (sudo usermod -aG dialout $USER), then log in \
             again",
        ));
        return checks;
    }
    checks.push(Check::ok(
        "serial",
        format!("{} present and writable", device.display()),
    ));
    let wait = Duration::from_millis(1600);
    checks.push(
        match hvs_actuator::link::check_controller(&device, a.baud, wait) {
            Ok(firmware) => Check::ok(
                "controller",
                format!("PSC firmware {firmware} answers at {} baud", a.baud),
            ),
            Err(e) => Check::bad(
                Verdict::Fail,
                "controller",
                e.to_string(),
                "switch the servo controller on (motor battery); `hvs run` waits for it and \
                 starts driving when it answers",
            ),
        },
    );
    checks
}

/// Bytes of shared memory one topic's publisher maps: iceoryx2 sizes its data segment for
/// every subscriber's queue and borrowed samples, the history and the publisher's loans
/// (2); checked against a running pipeline's /dev/shm (docs/bad-input.md).
fn topic_bytes<T>(t: &Topic<T>) -> u64 {
    let samples = t.max_subscribers * (t.max_buffer + t.max_borrowed) + t.history + 2;
    (samples * size_of::<T>() * t.max_publishers) as u64
}

/// What a whole pipeline maps in /dev/shm (the image topics; the small ones are noise).
pub fn shm_needed_bytes() -> u64 {
    topic_bytes::<StereoFrame640x480>(&topics::SIM_CAMERA)
        + topic_bytes::<DisparityMap640x480>(&topics::SIM_GT_DISPARITY)
        + topic_bytes::<StereoFrame320x240>(&topics::FRAMES_LO)
        + topic_bytes::<StereoFrame640x480>(&topics::FRAMES_HI)
        + topic_bytes::<DisparityMap320x240>(&topics::DISPARITY_LO)
        + topic_bytes::<DisparityMap640x480>(&topics::DISPARITY_HI)
}

fn shm_check() -> Check {
    let needed = shm_needed_bytes();
    let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
    match nix::sys::statvfs::statvfs("/dev/shm") {
        Ok(s) => {
            let free = s.blocks_available() * s.fragment_size();
            let detail = format!(
                "/dev/shm: {:.0} MiB free, a pipeline maps up to {:.0} MiB",
                mib(free),
                mib(needed)
            );
            if free >= needed {
                Check::ok("shared memory", detail)
            } else {
                Check::bad(
                    Verdict::Fail,
                    "shared memory",
                    detail,
                    "free /dev/shm (stale hvs runs: `hvs run` removes dead nodes' files) or \
                     enlarge it (mount -o remount,size=256M /dev/shm)",
                )
            }
        }
        Err(e) => Check::bad(
            Verdict::Fail,
            "shared memory",
            format!("/dev/shm: {e}"),
            "iceoryx2 needs a tmpfs at /dev/shm",
        ),
    }
}

fn leftover_checks(config: Option<&HvsConfig>) -> Vec<Check> {
    let mut checks = vec![match hvs_runtime::ipc::dead_nodes() {
        Ok(0) => Check::ok("iceoryx2", "no leftovers of a dead run"),
        Ok(n) => Check::bad(
            Verdict::Warn,
            "iceoryx2",
            format!("{n} nodes of a killed run left their shared memory behind"),
            "harmless: `hvs run` removes them when it starts",
        ),
        Err(e) => Check::bad(
            Verdict::Warn,
            "iceoryx2",
            format!("cannot list nodes: {e}"),
            "check /tmp/iceoryx2 permissions",
        ),
    }];
    if let Some(c) = config
        && let Some(pid) = running_supervisor(c)
    {
        checks.push(Check::bad(
            Verdict::Warn,
            "instance",
            format!("{:?} is running (supervisor pid {pid})", c.instance),
            format!(
                "`hvs stop --instance {}` before another `hvs run` of it, or use another \
                 --instance",
                c.instance
            ),
        ));
    }
    checks
}

/// The pid of a live supervisor of the config's instance (from its lock file).
fn running_supervisor(c: &HvsConfig) -> Option<i32> {
    let lock = hvs_runtime::config::run_dir(&c.instance).join("supervisor.lock");
    let pid = std::fs::read_to_string(lock)
        .ok()?
        .trim()
        .parse::<i32>()
        .ok()?;
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), None)
        .is_ok()
        .then_some(pid)
}

#[cfg(test)]
mod tests {
    use hvs_capture::v4l2::fake::{FakeBus, FakeCamera, MINORU_BUS_BYTES_PER_S};

    use super::*;

    #[test]
    fn the_shared_memory_estimate_counts_every_queue() {
        // 640x480 pair: 6 subscribers x (2 queued + 5 borrowed) + history 1 + 2 loans.
        assert_eq!(
            topic_bytes::<StereoFrame640x480>(&topics::FRAMES_HI),
            45 * size_of::<StereoFrame640x480>() as u64
        );
        let mib = shm_needed_bytes() / (1024 * 1024);
        assert!((100..200).contains(&mib), "{mib} MiB");
    }

    fn minoru_config(dir: &Path) -> PathBuf {
        let path = dir.join("robot.toml");
        let text = "[capture]\nsource = \"v4l2\"\n[capture.v4l2]\n\
                    left_device = \"/dev/fake-video0\"\nright_device = \"/dev/fake-video2\"\n\
                    [stages.sim]\nenabled = false\n[stages.actuator]\nenabled = false\n";
        std::fs::write(&path, text).expect("write config");
        path
    }

    fn bus(budget: f64) -> FakeBus {
        let cams = ["/dev/fake-video0", "/dev/fake-video2"]
            .map(|p| (PathBuf::from(p), FakeCamera::minoru()));
        FakeBus::new(budget, cams.into())
    }

    #[test]
    fn the_camera_checks_report_formats_and_the_mode_both_stream_in() {
        let dir = tempfile::tempdir().expect("tempdir");
        let checks = run_checks(&minoru_config(dir.path()), &bus(1e9));
        let line = |what: &str| {
            checks
                .iter()
                .find(|c| c.what == what)
                .unwrap_or_else(|| panic!("no {what} in {checks:#?}"))
                .to_string()
        };
        assert!(
            line("camera left").contains("Minoru camera, usb-fake-1.1): YUYV 640x480@30/15/5"),
            "{}",
            line("camera left")
        );
        assert!(line("cameras").starts_with(
            "ok   cameras        stream together at 640x480 YUYV at 30 fps on both cameras"
        ));
        // The Minoru's own hub: both only at 15 fps, said as a warning with the reason.
        let checks = run_checks(&minoru_config(dir.path()), &bus(MINORU_BUS_BYTES_PER_S));
        let cams = checks
            .iter()
            .find(|c| c.what == "cameras")
            .expect("cameras");
        assert_eq!(cams.verdict, Verdict::Warn, "{cams}");
        assert!(
            cams.detail
                .contains("640x480 YUYV at 15 fps on both cameras, after 1 failed")
        );
        // Nothing fits: a failure.
        let checks = run_checks(&minoru_config(dir.path()), &bus(1e6));
        let cams = checks
            .iter()
            .find(|c| c.what == "cameras")
            .expect("cameras");
        assert_eq!(cams.verdict, Verdict::Fail, "{cams}");
    }

    #[test]
    fn a_failed_check_says_what_to_do_on_its_line() {
        let c = Check::bad(
            Verdict::Fail,
            "serial",
            "/dev/ttyUSB0 not found",
            "plug it in",
        );
        assert_eq!(
            c.to_string(),
            "FAIL serial         /dev/ttyUSB0 not found -> plug it in"
        );
    }
}
