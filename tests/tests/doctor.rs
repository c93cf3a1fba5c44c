//! `hvs doctor` as a user runs it: the simulated robot's config passes; the real robot's
//! config on this machine (no Minoru, no serial adapter) names what is missing and exits 1;
//! a servo controller on a pseudo-terminal is found answering, or named silent.

use std::time::Duration;

use hvs_tests::psc_peer::{PeerBehaviour, PscPeer};
use hvs_tests::{hvs, repo_root, write_config};

fn doctor(config: &std::path::Path) -> (i32, String) {
    let out = hvs(&["doctor", "--config", &config.display().to_string()]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    println!("$ hvs doctor --config {}\n{text}", config.display());
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn the_simulated_robot_is_ready() {
    let (code, text) = doctor(&repo_root().join("config/sim.toml"));
    assert_eq!(code, 0, "{text}");
    for line in text.lines().filter(|l| !l.starts_with("hvs doctor:")) {
        // Leftovers of other tests' runs may warn; nothing fails.
        assert!(
            line.starts_with("ok ") || line.starts_with("warn "),
            "{line}"
        );
    }
    assert!(text.contains("shared memory  /dev/shm:"), "{text}");
}

#[test]
fn the_real_robot_without_its_devices_names_each_one_and_fails() {
    let present: Vec<&str> = ["/dev/video0", "/dev/video2", "/dev/ttyUSB0"]
        .into_iter()
        .filter(|d| std::path::Path::new(d).exists())
        .collect();
    if !present.is_empty() {
        eprintln!("SKIPPED: this machine has {present:?}; the test needs them absent");
        return;
    }
    let (code, text) = doctor(&repo_root().join("config/minoru.toml"));
    assert_eq!(code, 1, "{text}");
    for missing in [
        "FAIL camera left    /dev/video0 (capture.v4l2.left_device) not found -> plug the Minoru in",
        "FAIL camera right   /dev/video2 (capture.v4l2.right_device) not found",
        "FAIL serial         /dev/ttyUSB0 (actuator.device) not found -> plug in the PSC's USB-serial adapter",
    ] {
        assert!(text.contains(missing), "no {missing:?} in\n{text}");
    }
    assert!(text.contains("ok   config         "), "{text}");
}

#[test]
fn a_config_that_does_not_load_fails_naming_the_key() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = write_config(
        dir.path(),
        "bad.toml",
        &[("windows = 3", "windows = 4")],
        "",
    );
    let (code, text) = doctor(&path);
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("FAIL config") && text.contains("`fusion.windows` = 4 must be 3 or 5"),
        "{text}"
    );
}

#[test]
fn the_servo_controller_is_found_answering_or_named_silent() {
    let dir = tempfile::tempdir().expect("tempdir");
    let peer = PscPeer::start(
        &dir.path().join("ttyPSC"),
        PeerBehaviour::Answer(Duration::from_millis(100)),
    );
    let device = format!("device = \"{}\"", peer.link().display());
    let path = write_config(dir.path(), "psc.toml", &[("device = \"sim\"", &device)], "");
    let (code, text) = doctor(&path);
    assert_eq!(code, 0, "{text}");
    assert!(text.contains("present and writable"), "{text}");
    assert!(
        text.contains("ok   controller     PSC firmware 1.4 answers at 2400 baud"),
        "{text}"
    );
    peer.set_behaviour(PeerBehaviour::Silent);
    let (code, text) = doctor(&path);
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("FAIL controller     no servo controller answers on"),
        "{text}"
    );
}

/// `hvs check --config F`: exit status and output.
fn check(config: &std::path::Path) -> (i32, String) {
    let out = hvs(&["check", "--config", &config.display().to_string()]);
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("$ hvs check --config {}\n{text}", config.display());
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn hvs_check_passes_the_shipped_configs_and_names_file_key_and_line() {
    for shipped in ["config/sim.toml", "config/minoru.toml"] {
        let (code, text) = check(&repo_root().join(shipped));
        assert_eq!(code, 0, "{text}");
        assert!(text.contains(": ok"), "{text}");
    }
    let dir = tempfile::tempdir().expect("tempdir");
    // The matchers' rule (uniqueness below 100 %), which the config once accepted.
    let path = write_config(
        dir.path(),
        "uniq.toml",
        &[("uniqueness_pct = 5", "uniqueness_pct = 100")],
        "",
    );
    let line = std::fs::read_to_string(&path)
        .expect("read")
        .lines()
        .position(|l| l.starts_with("uniqueness_pct = 100"))
        .expect("the edited line")
        + 1;
    let (code, text) = check(&path);
    assert_eq!(code, 1, "{text}");
    let want = format!(
        "{}:{line}: `stereo.lo.uniqueness_pct` = 100 must be below 100",
        path.display()
    );
    assert!(text.contains(&want), "no {want:?} in\n{text}");
    // A penalty above the byte-sized path costs (sgm's MAX_P2), in a section of its own.
    let path = write_config(dir.path(), "p2.toml", &[], "[stereo.hi.sgm]\np2 = 90\n");
    let (code, text) = check(&path);
    assert_eq!(code, 1, "{text}");
    assert!(
        text.contains("`stereo.hi.sgm.p2`") && text.contains("<= 79"),
        "{text}"
    );
    // The doctor runs the same checks.
    let (code, text) = doctor(&path);
    assert_eq!(code, 1, "{text}");
    assert!(text.contains("`stereo.hi.sgm.p2`"), "{text}");
}
