//! End-to-end tests of the whole pipeline: real processes, real shared memory, real pty.

use std::time::{Duration, Instant};

use hvs_runtime::ipc::IpcNode;
use hvs_shared::messages::{MotionCommand, RowAlignState, SendReason};
use hvs_shared::topics;
use hvs_tests::{Pipeline, hvs, iceoryx_files, pid_of, signal_pid, stage, write_config};
use nix::sys::signal::Signal;

const START: Duration = Duration::from_secs(60);
/// Every stage of the default (simulator) pipeline.
const STAGES: [&str; 8] = hvs_tests::DEFAULT_STAGES;

/// Newest decision frame id seen on the pipeline's own topic within `window`.
fn newest_decision(node: &IpcNode, window: Duration) -> Option<u64> {
    let sub = node
        .subscriber(&topics::DECISIONS, 4)
        .expect("decisions subscriber");
    let deadline = Instant::now() + window;
    let mut newest = None;
    while Instant::now() < deadline {
        while let Some(d) = sub.receive().expect("receive") {
            newest = newest.max(Some(d.payload().frame_id));
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    newest
}

#[test]
fn frames_reach_every_stage_and_stop_is_orderly() {
    let mut p = Pipeline::start("flow", &[], "");
    let status = p.wait_all_running(START);
    for name in STAGES {
        let s = stage(&status, name);
        // The view sends only to clients (none here): it must have taken samples in.
        let key = if name == "view" {
            "frames_in"
        } else {
            "frames_out"
        };
        assert!(
            s[key].as_u64().unwrap_or(0) > 0,
            "{name} produced nothing: {s}"
        );
    }
    // Observe the data flow directly in shared memory, as a probe would.
    let node = IpcNode::create(&p.instance, "e2e-observer").expect("node");
    let truth = node.subscriber(&topics::SIM_TRUTH, 1).expect("truth");
    let sent = node
        .subscriber(&topics::ACTUATOR_SENT, 4)
        .expect("actuator reports");
    let first = newest_decision(&node, Duration::from_secs(1)).expect("decisions flow");
    let later = newest_decision(&node, Duration::from_secs(1)).expect("decisions keep flowing");
    assert!(
        later > first + 10,
        "decisions at camera rate: {first} -> {later}"
    );
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut decision_commands = 0;
    let mut psc_frames = 0;
    while Instant::now() < deadline && (decision_commands < 5 || psc_frames < 10) {
        while let Some(r) = sent.receive().expect("receive") {
            let r = r.payload();
            assert_eq!(r.byte_count, 16);
            assert_eq!(r.ramp, r.bytes[4], "the ramp field is the PSC command's");
            assert_eq!(&r.bytes[..3], b"!SC");
            assert_eq!(&r.bytes[8..11], b"!SC");
            if SendReason::from_code(r.reason) == Some(SendReason::Decision) {
                decision_commands += 1;
            }
        }
        if let Some(t) = truth.receive_latest().expect("receive") {
            psc_frames = t.payload().psc_frames;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(
        decision_commands >= 5,
        "the actuator acts on decisions\n{}",
        p.logs()
    );
    assert!(
        psc_frames >= 10,
        "the simulated PSC receives the bytes over the pty ({psc_frames})"
    );
    drop((truth, sent, node));

    assert!(
        hvs(&["stop", "--instance", &p.instance]).status.success(),
        "{}",
        p.logs()
    );
    assert_eq!(p.wait_exit(Duration::from_secs(30)), 0, "{}", p.logs());
    let report = p.report();
    for name in STAGES {
        let s = report["stages"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| s["stage"] == name)
            .cloned();
        let s = s.unwrap_or_else(|| panic!("{name} missing from the report"));
        let key = if name == "view" {
            "frames_in"
        } else {
            "frames_out"
        };
        assert!(s[key].as_u64().unwrap_or(0) > 0, "{name}: {s}");
        assert_eq!(s["restarts"], 0, "{name}: {s}");
    }
    assert!(
        report["latency"]["capture_to_decision"]["count"]
            .as_u64()
            .unwrap_or(0)
            > 30
    );
    // The last thing the actuator wrote is neutral (orderly stop: actuator first).
    assert!(
        report["neutral_sent"].as_u64().unwrap_or(0) >= 1,
        "{report}"
    );
    // Nothing of this run remains (files of earlier killed runs may have been cleaned up).
    let leaked: Vec<String> = iceoryx_files()
        .into_iter()
        .filter(|f| !p.files_before().contains(f))
        .collect();
    assert!(
        leaked.is_empty(),
        "iceoryx2 files left behind: {leaked:?}\n{}",
        p.logs()
    );
}

#[test]
fn sigkill_of_stereo_is_restarted_and_nothing_else_moves() {
    let p = Pipeline::start("kill", &[], "");
    let before = p.wait_all_running(START);
    let victim = pid_of(&before, "stereo-lo");
    let node = IpcNode::create(&p.instance, "e2e-observer").expect("node");
    let last_before = newest_decision(&node, Duration::from_millis(500)).expect("decisions");
    signal_pid(victim, Signal::SIGKILL);
    let after = p.wait_status("stereo-lo restarted", Duration::from_secs(30), |s| {
        let st = stage(s, "stereo-lo");
        st["state"] == "running"
            && st["pid"].as_u64() != Some(victim as u64)
            && st["restarts"].as_u64() >= Some(1)
    });
    for name in STAGES.iter().filter(|n| **n != "stereo-lo") {
        assert_eq!(
            pid_of(&after, name),
            pid_of(&before, name),
            "{name} was disturbed\n{}",
            p.logs()
        );
    }
    let resumed = newest_decision(&node, Duration::from_secs(3)).expect("decisions resume");
    assert!(
        resumed > last_before + 10,
        "decisions resumed: {last_before} -> {resumed}"
    );
}

#[test]
fn hvs_restart_replaces_fusion_in_place() {
    let p = Pipeline::start("restart", &[], "");
    let before = p.wait_all_running(START);
    let out = hvs(&["restart", "fusion", "--instance", &p.instance]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "hvs restart failed: {}{}\n{}",
        text,
        String::from_utf8_lossy(&out.stderr),
        p.logs()
    );
    let old = pid_of(&before, "fusion");
    assert!(
        text.contains(&format!("restarted fusion: pid {old} -> ")),
        "{text}"
    );
    let after = p.status().expect("status");
    assert_ne!(pid_of(&after, "fusion"), old);
    for name in STAGES.iter().filter(|n| **n != "fusion") {
        assert_eq!(
            pid_of(&after, name),
            pid_of(&before, name),
            "{name} was disturbed"
        );
    }
    let node = IpcNode::create(&p.instance, "e2e-observer").expect("node");
    let a = newest_decision(&node, Duration::from_millis(500)).expect("decisions after restart");
    let b = newest_decision(&node, Duration::from_millis(1000)).expect("decisions keep coming");
    assert!(b > a + 10, "{a} -> {b}");
    let out = hvs(&["restart", "fusoin", "--instance", &p.instance]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown stage \"fusoin\""));
}

#[test]
fn a_decision_gap_makes_the_actuator_send_neutral() {
    // Freeze the decision stage (SIGSTOP): the actuator must stop the wheels on its own, well
    // before the supervisor notices the hang and restarts it.
    let p = Pipeline::start("gap", &[], "");
    let before = p.wait_all_running(START);
    let node = IpcNode::create(&p.instance, "e2e-observer").expect("node");
    let sent = node
        .subscriber(&topics::ACTUATOR_SENT, 4)
        .expect("actuator reports");
    let truth = node.subscriber(&topics::SIM_TRUTH, 1).expect("truth");
    let decision_pid = pid_of(&before, "decision");
    std::thread::sleep(Duration::from_millis(300));
    while sent.receive().expect("drain").is_some() {}
    signal_pid(decision_pid, Signal::SIGSTOP);
    let stopped_at = Instant::now();
    let mut neutral_after = None;
    while stopped_at.elapsed() < Duration::from_secs(3) && neutral_after.is_none() {
        while let Some(r) = sent.receive().expect("receive") {
            let r = r.payload();
            if SendReason::from_code(r.reason) == Some(SendReason::WatchdogNeutral) {
                assert_eq!(MotionCommand::from_code(r.command), MotionCommand::Stop);
                assert_eq!((r.left_pw, r.right_pw), (760, 758), "neutral pulses");
                neutral_after = Some(stopped_at.elapsed());
            }
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    let neutral_after =
        neutral_after.unwrap_or_else(|| panic!("no watchdog neutral\n{}", p.logs()));
    // Watchdog 300 ms after the last decision, plus one wire time (67 ms) and scheduling.
    assert!(
        neutral_after < Duration::from_millis(600),
        "neutral after {neutral_after:?}"
    );
    // The simulated controller really received neutral pulses over the pty.
    let deadline = Instant::now() + Duration::from_secs(1);
    let mut pulses = (0, 0);
    while Instant::now() < deadline && pulses != (760, 758) {
        if let Some(t) = truth.receive_latest().expect("receive") {
            pulses = (t.payload().left_pw, t.payload().right_pw);
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    assert_eq!(pulses, (760, 758), "the simulated PSC holds neutral");
    signal_pid(decision_pid, Signal::SIGCONT);
    // The supervisor either saw the hang and restarted it, or it resumed; decisions flow again.
    p.wait_status("decision running again", Duration::from_secs(30), |s| {
        stage(s, "decision")["state"] == "running"
    });
    let resumed = newest_decision(&node, Duration::from_secs(2));
    assert!(resumed.is_some(), "decisions resume\n{}", p.logs());
}

#[test]
fn bad_configs_fail_with_a_message_naming_the_fault() {
    let dir = tempfile::tempdir().expect("tempdir");
    // (what, line replacements in config/sim.toml, appended text, expected message parts)
    type Case<'a> = (&'a str, &'a [(&'a str, &'a str)], &'a str, &'a [&'a str]);
    let cases: [Case; 4] = [
        (
            "unknown key",
            &[("min_disp = 2 ", "windw = 3\nmin_disp = 2 ")],
            "",
            &["windw", "line"],
        ),
        (
            "wrong type",
            &[("fps = 30.0", "fps = \"thirty\"")],
            "",
            &["fps", "line"],
        ),
        ("missing map", &[], "", &["sim.map", "nope.txt"]),
        (
            "unknown stage",
            &[],
            "[stages.stereo]\nrestart = \"never\"\n",
            &["stages.stereo", "stereo-lo"],
        ),
    ];
    for (what, overrides, extra, expected) in cases {
        let path = write_config(dir.path(), "bad.toml", overrides, extra);
        if what == "missing map" {
            let text = std::fs::read_to_string(&path).unwrap();
            let text = text.replace("config/maps/maze.txt", "config/maps/nope.txt");
            std::fs::write(&path, text).unwrap();
        }
        let out = hvs(&["run", "--config", path.to_str().unwrap(), "--duration", "1"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success(),
            "{what}: hvs run accepted a bad config"
        );
        assert!(
            err.contains(path.to_str().unwrap()),
            "{what}: message does not name the file: {err}"
        );
        for e in expected {
            assert!(
                err.contains(e),
                "{what}: message does not mention {e:?}: {err}"
            );
        }
    }
    let out = hvs(&["run", "--config", "/nonexistent/hvs.toml"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/hvs.toml"));
}

#[test]
fn sigint_stops_in_order_and_sigkill_everything_then_a_new_run_starts_clean() {
    let mut p = Pipeline::start("crash", &[], "");
    p.wait_all_running(START);
    // Ctrl-C: orderly stop, neutral last, exit 0, report written.
    p.signal(Signal::SIGINT);
    assert_eq!(p.wait_exit(Duration::from_secs(30)), 0, "{}", p.logs());
    let report = p.report();
    assert!(
        report["neutral_sent"].as_u64().unwrap_or(0) >= 1,
        "{report}"
    );

    // Power-cut style: every process of the instance SIGKILLed at once leaves iceoryx2
    // resources behind; the next run on the same instance must clean them up and start.
    let p = Pipeline::restart_after(p);
    let status = p.wait_all_running(START);
    let mut pids: Vec<u32> = STAGES.iter().map(|s| pid_of(&status, s)).collect();
    pids.push(p.supervisor_pid());
    for pid in &pids {
        signal_pid(*pid, Signal::SIGKILL);
    }
    std::thread::sleep(Duration::from_millis(300));
    let p = Pipeline::restart_after(p);
    let status = p.wait_all_running(START);
    for name in STAGES {
        assert_eq!(
            stage(&status, name)["restarts"],
            0,
            "{name} needed restarts\n{}",
            p.logs()
        );
    }
}

#[test]
fn sigkill_of_the_supervisor_stops_the_wheels() {
    let p = Pipeline::start("orphan", &[], "");
    let status = p.wait_all_running(START);
    let node = IpcNode::create(&p.instance, "e2e-observer").expect("node");
    let sent = node
        .subscriber(&topics::ACTUATOR_SENT, 4)
        .expect("actuator reports");
    std::thread::sleep(Duration::from_millis(200));
    while sent.receive().expect("drain").is_some() {}
    p.signal(Signal::SIGKILL);
    // Every stage gets SIGTERM from the kernel (parent-death signal); the actuator's last
    // words are neutral.
    let deadline = Instant::now() + Duration::from_secs(5);
    let mut last = None;
    while Instant::now() < deadline {
        while let Some(r) = sent.receive().expect("receive") {
            last = Some(*r.payload());
        }
        let alive = STAGES
            .iter()
            .map(|s| pid_of(&status, s))
            .filter(|pid| {
                nix::sys::signal::kill(nix::unistd::Pid::from_raw(*pid as i32), None).is_ok()
            })
            .count();
        if alive == 0 {
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    while let Some(r) = sent.receive().expect("receive") {
        last = Some(*r.payload());
    }
    let last = last.unwrap_or_else(|| {
        panic!(
            "the actuator reported nothing after the drain\n{}",
            p.logs()
        )
    });
    assert_eq!(
        SendReason::from_code(last.reason),
        Some(SendReason::ShutdownNeutral),
        "{last:?}"
    );
    assert_eq!((last.left_pw, last.right_pw), (760, 758));
    for name in STAGES {
        let pid = pid_of(&status, name);
        assert!(
            nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), None).is_err(),
            "{name} (pid {pid}) outlived its supervisor"
        );
    }
}

/// A right camera mounted 4 rows (at 640x480) lower: both stereo stages measure the offset
/// from the images, correct it before matching and say so in every disparity header and in
/// their notes.
#[test]
fn a_vertically_misaligned_camera_is_measured_and_corrected() {
    let p = Pipeline::start(
        "vshift",
        &[("vertical_shift_px = 0 ", "vertical_shift_px = 4 ")],
        "",
    );
    p.wait_all_running(Duration::from_secs(60));
    let node = IpcNode::create(&p.instance, "e2e-vshift").expect("node");
    let lo = node.subscriber(&topics::DISPARITY_LO, 2).expect("lo");
    let hi = node.subscriber(&topics::DISPARITY_HI, 2).expect("hi");
    // (320x240: the same offset is 2 rows.)
    let mut seen = [None, None];
    let deadline = Instant::now() + Duration::from_secs(60);
    while seen.iter().any(Option::is_none) {
        assert!(
            Instant::now() < deadline,
            "no corrected maps: {seen:?}\n{}",
            p.logs()
        );
        if let Some(s) = lo.receive().expect("receive lo") {
            let h = s.payload().header;
            if h.row_align == RowAlignState::Corrected as u32 {
                seen[0] = Some(h.row_shift_mpx);
            }
        }
        if let Some(s) = hi.receive().expect("receive hi") {
            let h = s.payload().header;
            if h.row_align == RowAlignState::Corrected as u32 {
                seen[1] = Some(h.row_shift_mpx);
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let (Some(lo_mpx), Some(hi_mpx)) = (seen[0], seen[1]) else {
        panic!("no corrected maps: {seen:?}");
    };
    println!("tracked offset: 320x240 {lo_mpx} mpx, 640x480 {hi_mpx} mpx");
    assert!((lo_mpx - 2000).abs() <= 300, "320x240: {lo_mpx} mpx");
    assert!((hi_mpx - 4000).abs() <= 300, "640x480: {hi_mpx} mpx");
    let s = p.wait_status("the offset in the notes", Duration::from_secs(10), |s| {
        stage(s, "stereo-hi")["note"]
            .as_str()
            .is_some_and(|n| n.contains("rows +4.0 px") || n.contains("rows +3.9 px"))
    });
    println!("stereo-hi note: {}", stage(&s, "stereo-hi")["note"]);
}
