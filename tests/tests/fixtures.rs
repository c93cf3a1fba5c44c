//! Deliberately broken stages (tests/fixtures/, shell scripts standing in for a stage
//! binary): one that hangs before its first heartbeat, one that ignores SIGTERM. The
//! supervisor's handling of each is asserted, with the real stages running beside them.

use std::time::{Duration, Instant};

use hvs_tests::{Pipeline, hvs, hvs_ok, pid_of, repo_root, stage};

const START: Duration = Duration::from_secs(60);

fn fixture(name: &str) -> String {
    repo_root()
        .join("tests/fixtures")
        .join(name)
        .display()
        .to_string()
}

/// Every stage but the one the fixtures stand in for (stereo-hi).
fn others() -> impl Iterator<Item = &'static str> {
    hvs_tests::DEFAULT_STAGES
        .into_iter()
        .filter(|n| *n != "stereo-hi")
}

fn alive(pid: u32) -> bool {
    // Is there such a process, other than a zombie waiting to be reaped?
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .map(|s| {
            !s.rsplit(')')
                .next()
                .unwrap_or("")
                .trim_start()
                .starts_with('Z')
        })
        .unwrap_or(false)
}

#[test]
fn a_stage_that_hangs_before_its_first_heartbeat_is_killed_restarted_then_given_up() {
    let table = format!(
        "[stages.stereo-hi]\nprogram = \"{}\"\nbackoff_ms = 50\nmax_restarts = 2\nrestart_window_s = 60\n",
        fixture("hang-before-heartbeat")
    );
    // A start-up bound of 3 s: the real stages beat well within it even on a loaded machine.
    let p = Pipeline::start(
        "fixture-hang",
        &[("startup_timeout_ms = 10000", "startup_timeout_ms = 3000")],
        &table,
    );
    let first = p.wait_status("stereo-hi starting", START, |s| pid_of(s, "stereo-hi") != 0);
    let first_pid = pid_of(&first, "stereo-hi");
    let t0 = Instant::now();
    let failed = p.wait_status("stereo-hi given up", START, |s| {
        stage(s, "stereo-hi")["state"] == "failed"
    });
    let took = t0.elapsed();
    // Three incarnations, each killed after the 3 s start-up bound: at least 6 s after the
    // first was seen (the supervisor does not give up early).
    assert!(
        took >= Duration::from_secs(5),
        "given up after {took:?}\n{}",
        p.logs()
    );
    assert_eq!(stage(&failed, "stereo-hi")["restarts"], 2, "{failed}");
    assert!(
        !alive(first_pid),
        "the hung process {first_pid} is still there"
    );
    let log = p.logs();
    assert!(log.contains("stereo-hi (pid"), "{log}");
    assert!(log.contains("sent no heartbeat for"), "{log}");
    assert!(
        log.contains("giving up on stereo-hi after 2 restarts"),
        "{log}"
    );
    // The fast path never needed it: every other stage runs and decides.
    for name in others() {
        assert_eq!(stage(&failed, name)["state"], "running", "{name}\n{log}");
        assert_eq!(stage(&failed, name)["restarts"], 0, "{name}\n{log}");
    }
    let decisions_then = stage(&failed, "decision")["frames_out"]
        .as_u64()
        .unwrap_or(0);
    p.wait_status("decisions keep coming", START, |s| {
        stage(s, "decision")["frames_out"].as_u64().unwrap_or(0) > decisions_then + 10
    });
    println!(
        "hang before the first heartbeat: killed after 3 s, restarted twice, given up after {took:?}"
    );
}

#[test]
fn a_stage_that_ignores_sigterm_is_killed_after_the_grace_on_restart_and_on_stop() {
    let table = format!(
        "[stages.stereo-hi]\nprogram = \"{}\"\n",
        fixture("ignore-sigterm")
    );
    // It never beats: a long start-up bound keeps the hang detection out of this test.
    let mut p = Pipeline::start(
        "fixture-term",
        &[
            ("startup_timeout_ms = 10000", "startup_timeout_ms = 600000"),
            ("stop_timeout_ms = 2000", "stop_timeout_ms = 700"),
        ],
        &table,
    );
    let before = p.wait_status("stereo-hi spawned and the fast path running", START, |s| {
        pid_of(s, "stereo-hi") != 0 && stage(s, "decision")["state"] == "running"
    });
    let old = pid_of(&before, "stereo-hi");
    // hvs restart: SIGTERM is ignored, SIGKILL after the 700 ms grace, then a new process.
    let t0 = Instant::now();
    // (`hvs restart` waits for the new process to beat, which this one never does: it runs
    // beside the test, and its own verdict is not what is tested here.)
    let instance = p.instance.clone();
    let restart = std::thread::spawn(move || {
        hvs(&[
            "restart",
            "stereo-hi",
            "--instance",
            &instance,
            "--timeout",
            "3",
        ])
    });
    let after = p.wait_status("stereo-hi replaced", START, |s| {
        let pid = pid_of(s, "stereo-hi");
        pid != 0 && pid != old
    });
    let replaced_after = t0.elapsed();
    let _ = restart.join();
    assert!(!alive(old), "the old process {old} survived the restart");
    assert!(
        replaced_after >= Duration::from_millis(700),
        "replaced after {replaced_after:?}: before the grace ran out, so SIGTERM was not ignored?"
    );
    for name in others() {
        assert_eq!(
            pid_of(&after, name),
            pid_of(&before, name),
            "{name} restarted"
        );
    }
    // hvs stop: the whole run ends although this stage ignores SIGTERM.
    let new = pid_of(&after, "stereo-hi");
    let t0 = Instant::now();
    hvs_ok(&["stop", "--instance", &p.instance]);
    let code = p.wait_exit(Duration::from_secs(30));
    let stopped_after = t0.elapsed();
    assert_eq!(code, 0, "{}", p.logs());
    assert!(!alive(new), "the stage {new} outlived the supervisor");
    println!(
        "ignores SIGTERM: replaced {replaced_after:?} after hvs restart (grace 700 ms), run stopped {stopped_after:?} after hvs stop"
    );
}
