//! Fault injection on real processes: every stage killed (SIGKILL), hung for 2 s (SIGSTOP,
//! then SIGCONT), and unable to start (a program path that does not exist); a camera source
//! that ends; two instances side by side. Each case checks what the robot must not do (drive
//! on stale commands) and that the rest of the pipeline does not notice, and prints what it
//! measured: the table in docs/performance.md ("Faults") comes from here.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use hvs_runtime::ipc::{IpcNode, TopicSubscriber};
use hvs_shared::messages::{ActuatorReport, Decision, MotionCommand, SendReason};
use hvs_shared::topics;
use hvs_tests::{
    Pipeline, bin, hvs, hvs_ok, iceoryx_files, pid_of, signal_pid, stage, unique_instance,
    write_config,
};
use nix::sys::signal::Signal;

const START: Duration = Duration::from_secs(60);
const STAGES: [&str; 8] = hvs_tests::DEFAULT_STAGES;
/// How long after a fault the decisions must flow again (the bound the tests hold; the
/// measured times are printed).
const RESUME_BOUND: Duration = Duration::from_secs(6);

/// What the pipeline's outputs did around a fault.
#[derive(Debug, Default)]
struct Observed {
    /// Longest time without a decision, from the fault on.
    decision_gap: Duration,
    /// From the fault to the first decision after the longest gap.
    resumed_after: Option<Duration>,
    /// First watchdog or start-up neutral after the fault.
    neutral_after: Option<Duration>,
    /// Non-neutral commands sent while no decision was younger than 400 ms.
    stale_commands: u32,
    /// Actuator outputs seen.
    sent: u32,
    /// Longest time without any actuator output (the wheels keep their last pulses).
    actuator_silence: Duration,
}

/// Watches decisions and actuator output for `window` from `t0`; `resume` is called once,
/// `resume.0` after `t0` (the end of a hang).
fn observe(
    decisions: &TopicSubscriber<Decision>,
    sent: &TopicSubscriber<ActuatorReport>,
    t0: Instant,
    window: Duration,
    mut resume: Option<(Duration, Box<dyn FnOnce()>)>,
) -> Observed {
    let mut o = Observed::default();
    let mut last_decision = t0;
    let mut last_sent = t0;
    while t0.elapsed() < window {
        if resume.as_ref().is_some_and(|(at, _)| t0.elapsed() >= *at)
            && let Some((_, f)) = resume.take()
        {
            f();
        }
        let now = Instant::now();
        while decisions.receive().expect("receive decisions").is_some() {
            let gap = now - last_decision;
            if gap > o.decision_gap {
                o.decision_gap = gap;
                o.resumed_after = Some(now - t0);
            }
            last_decision = now;
        }
        while let Some(r) = sent.receive().expect("receive actuator reports") {
            o.sent += 1;
            o.actuator_silence = o.actuator_silence.max(now - last_sent);
            last_sent = now;
            let r = r.payload();
            let reason = SendReason::from_code(r.reason);
            if reason.is_some_and(SendReason::is_neutral) {
                if o.neutral_after.is_none() && reason != Some(SendReason::ShutdownNeutral) {
                    o.neutral_after = Some(now - t0);
                }
            } else if now - last_decision > Duration::from_millis(400)
                && MotionCommand::from_code(r.command) != MotionCommand::Stop
            {
                o.stale_commands += 1;
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let tail = t0.elapsed() - (last_decision - t0);
    if tail > o.decision_gap {
        o.decision_gap = tail;
        o.resumed_after = None;
    }
    o
}

fn ms(d: Option<Duration>) -> String {
    d.map_or("-".to_string(), |d| format!("{}", d.as_millis()))
}

#[test]
fn every_stage_is_killed_and_hung_in_turn_and_the_robot_never_drives_on_stale_commands() {
    let p = Pipeline::start("faults", &[], "");
    let mut status = p.wait_all_running(START);
    let node = IpcNode::create(&p.instance, "e2e-faults").expect("node");
    let decisions = node.subscriber(&topics::DECISIONS, 4).expect("decisions");
    let sent = node.subscriber(&topics::ACTUATOR_SENT, 4).expect("sent");
    let mut rows = Vec::new();
    let mut failures = Vec::new();
    for victim in STAGES {
        for fault in ["SIGKILL", "SIGSTOP 2 s"] {
            let before = status.clone();
            let pid = pid_of(&before, victim);
            std::thread::sleep(Duration::from_millis(300));
            while decisions.receive().expect("drain").is_some() {}
            while sent.receive().expect("drain").is_some() {}
            let t0 = Instant::now();
            let resume: Option<(Duration, Box<dyn FnOnce()>)> = if fault == "SIGKILL" {
                signal_pid(pid, Signal::SIGKILL);
                None
            } else {
                signal_pid(pid, Signal::SIGSTOP);
                // The supervisor may have killed it for hanging by then.
                Some((
                    Duration::from_secs(2),
                    Box::new(move || {
                        let _ = nix::sys::signal::kill(
                            nix::unistd::Pid::from_raw(pid as i32),
                            Signal::SIGCONT,
                        );
                    }),
                ))
            };
            let o = observe(&decisions, &sent, t0, Duration::from_secs(7), resume);
            status = p.wait_status(
                &format!("{victim} running again after {fault}"),
                Duration::from_secs(30),
                |s| STAGES.iter().all(|n| stage(s, n)["state"] == "running"),
            );
            let new_pid = pid_of(&status, victim);
            let disturbed: Vec<&str> = STAGES
                .iter()
                .copied()
                .filter(|n| *n != victim && pid_of(&status, n) != pid_of(&before, n))
                .collect();
            let gap = o.decision_gap > Duration::from_millis(200);
            rows.push(format!(
                "| {victim} | {fault} | {} | {} | {} | {} | {} | {} |",
                o.decision_gap.as_millis(),
                if gap {
                    ms(o.resumed_after)
                } else {
                    "-".to_string()
                },
                ms(o.neutral_after),
                o.actuator_silence.as_millis(),
                if new_pid != pid {
                    "restarted"
                } else {
                    "resumed"
                },
                if disturbed.is_empty() {
                    "none".to_string()
                } else {
                    disturbed.join(", ")
                }
            ));
            let case = format!("{victim} {fault}");
            if !disturbed.is_empty() {
                failures.push(format!("{case}: {disturbed:?} changed pid"));
            }
            if o.stale_commands > 0 {
                failures.push(format!(
                    "{case}: {} motion commands sent with no decision for 400 ms",
                    o.stale_commands
                ));
            }
            if o.decision_gap > RESUME_BOUND
                || (o.resumed_after.is_none() && o.decision_gap > Duration::from_secs(1))
            {
                failures.push(format!("{case}: decisions did not resume: {o:?}"));
            }
            // A gap longer than the watchdog (300 ms) must bring neutral pulses, unless the
            // actuator itself is the victim: then the restarted actuator's start-up neutral.
            if o.decision_gap > Duration::from_millis(500) && o.neutral_after.is_none() {
                failures.push(format!("{case}: no neutral during a decision gap: {o:?}"));
            }
            if victim == "sim" && pid_of(&status, "actuator") != pid_of(&before, "actuator") {
                failures.push("the actuator did not survive its serial device vanishing".into());
            }
        }
    }
    println!(
        "| stage | fault | longest decision gap ms | decisions back after ms | neutral after ms | longest actuator silence ms | victim | other stages restarted |"
    );
    println!("|---|---|---:|---:|---:|---:|---|---|");
    for r in &rows {
        println!("{r}");
    }
    assert!(failures.is_empty(), "{failures:#?}\n{}", p.logs());

    // After all that: a clean stop leaves no shared memory behind, and a fresh run works.
    // The observer's own ports and node first: they are not the pipeline's.
    drop((decisions, sent, node));
    let files_before = p.files_before().to_vec();
    p.signal(Signal::SIGINT);
    let mut p = p;
    assert_eq!(p.wait_exit(Duration::from_secs(30)), 0, "{}", p.logs());
    let leaked: Vec<String> = iceoryx_files()
        .into_iter()
        .filter(|f| !files_before.contains(f))
        .collect();
    assert!(leaked.is_empty(), "left behind: {leaked:#?}");
    let p = Pipeline::restart_after(p);
    let fresh = p.wait_all_running(START);
    for name in STAGES {
        assert_eq!(stage(&fresh, name)["restarts"], 0, "{name}\n{}", p.logs());
    }
}

#[test]
fn a_stage_that_cannot_start_is_given_up_by_policy_and_the_others_keep_running() {
    let base = std::fs::read_to_string(hvs_tests::repo_root().join("config/sim.toml"))
        .expect("config/sim.toml");
    for victim in STAGES {
        let header = format!("[stages.{victim}]\n");
        let table = format!(
            "{header}program = \"/nonexistent/hvs-{victim}\"\nbackoff_ms = 50\nmax_restarts = 3\nrestart_window_s = 60\n"
        );
        // config/sim.toml has some of these tables already: extend those in place.
        let p = if base.contains(&header) {
            Pipeline::start("nostart", &[(&header, &table)], "")
        } else {
            Pipeline::start("nostart", &[], &table)
        };
        let status = p.wait_status(
            &format!("{victim} given up"),
            Duration::from_secs(30),
            |s| stage(s, victim)["state"] == "failed",
        );
        // The others run, and keep their processes for a while.
        std::thread::sleep(Duration::from_secs(2));
        let later = p.status().expect("status");
        for name in STAGES.iter().filter(|n| **n != victim) {
            assert_eq!(
                stage(&later, name)["state"],
                "running",
                "{victim} missing: {name}\n{}",
                p.logs()
            );
            assert_eq!(
                pid_of(&later, name),
                pid_of(&status, name),
                "{name} restarted"
            );
        }
        let log = p.logs();
        assert!(
            log.contains(&format!("/nonexistent/hvs-{victim}")),
            "the error names the program\n{log}"
        );
        // Without a decision path nothing may move: only neutral goes out. (Without the
        // simulator there is no serial line to send on either; the 640x480 worker and the
        // view are not on the decision path.)
        if !matches!(victim, "stereo-hi" | "actuator" | "sim" | "view") {
            let node = IpcNode::create(&p.instance, "e2e-nostart").expect("node");
            let sent = node.subscriber(&topics::ACTUATOR_SENT, 4).expect("sent");
            let t0 = Instant::now();
            let mut seen = 0;
            while t0.elapsed() < Duration::from_secs(1) {
                while let Some(r) = sent.receive().expect("receive") {
                    seen += 1;
                    assert_eq!(
                        MotionCommand::from_code(r.payload().command),
                        MotionCommand::Stop,
                        "{victim} missing but the actuator drives"
                    );
                }
                std::thread::sleep(Duration::from_millis(10));
            }
            assert!(seen > 0, "{victim} missing: the actuator sends nothing");
        }
        println!(
            "{victim}: given up after 3 restarts; the {} others kept their pids",
            STAGES.len() - 1
        );
    }
}

#[test]
fn a_folder_source_that_ends_leaves_the_robot_stopped_and_the_stage_idle() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frames = dir.path().join("frames");
    std::fs::create_dir_all(&frames).expect("mkdir");
    let map = hvs_tests::repo_root().join("config/maps/straight.txt");
    let out = dir.path().join("render");
    hvs_ok(&[
        "sim",
        "render",
        "--map",
        map.to_str().expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
    ]);
    for i in 0..3 {
        for side in ["left", "right"] {
            std::fs::copy(
                out.join(format!("{side}.png")),
                frames.join(format!("{i:02}_{side}.png")),
            )
            .expect("copy");
        }
    }
    // The simulator still runs: its pty is the actuator's serial line.
    let extra = format!(
        "[capture.files]\nfolder = \"{}\"\nrate_hz = 10.0\n",
        frames.display()
    );
    let p = Pipeline::start(
        "files",
        &[
            ("source = \"sim\"", "source = \"files\""),
            ("[stages.sim]\n", "[stages.sim]\nenabled = true\n"),
        ],
        &extra,
    );
    let status = p.wait_status("the 3 pairs played", Duration::from_secs(60), |s| {
        stage(s, "decision")["frames_out"].as_u64() >= Some(3)
    });
    let node = IpcNode::create(&p.instance, "e2e-files").expect("node");
    let sent = node.subscriber(&topics::ACTUATOR_SENT, 4).expect("sent");
    std::thread::sleep(Duration::from_secs(1));
    while sent.receive().expect("drain").is_some() {}
    let t0 = Instant::now();
    let mut last = None;
    while t0.elapsed() < Duration::from_secs(1) {
        while let Some(r) = sent.receive().expect("receive") {
            last = Some(*r.payload());
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let last = last.expect("the actuator keeps sending");
    assert_eq!(
        MotionCommand::from_code(last.command),
        MotionCommand::Stop,
        "frames ended but the robot drives: {last:?}"
    );
    let later = p.status().expect("status");
    assert_eq!(
        pid_of(&later, "capture"),
        pid_of(&status, "capture"),
        "the ended source is idle, not restarted (a restart would replay the folder)"
    );
    assert_eq!(stage(&later, "decision")["frames_out"].as_u64(), Some(3));
}

#[test]
fn two_instances_run_side_by_side_and_stopping_one_leaves_the_other() {
    let p = Pipeline::start("side-a", &[], "");
    p.wait_all_running(START);
    // The second instance outside the test helper's one-pipeline lock, in its own folders.
    let dir = tempfile::tempdir().expect("tempdir");
    let config = write_config(dir.path(), "b.toml", &[], "");
    let other = unique_instance("side-b");
    let mut b = Command::new(bin("hvs"))
        .args(["run", "--config"])
        .arg(&config)
        .args(["--instance", &other, "--duration", "60"])
        .env("HVS_RUN_DIR", dir.path().join("run"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("second hvs run");
    let running = |instance: &str| -> Option<u64> {
        let out = hvs(&["status", "--json", "--instance", instance]);
        let s: serde_json::Value = serde_json::from_slice(&out.stdout).ok()?;
        stage(&s, "decision")["frames_out"].as_u64()
    };
    let deadline = Instant::now() + START;
    while running(&other).unwrap_or(0) < 30 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
    }
    let a0 = running(&p.instance).expect("a runs");
    let b0 = running(&other).expect("b runs");
    std::thread::sleep(Duration::from_secs(2));
    let (a1, b1) = (
        running(&p.instance).unwrap_or(0),
        running(&other).unwrap_or(0),
    );
    assert!(
        a1 > a0 + 20 && b1 > b0 + 20,
        "both decide: a {a0}->{a1}, b {b0}->{b1}"
    );
    hvs_ok(&["stop", "--instance", &other]);
    let _ = b.wait();
    std::thread::sleep(Duration::from_secs(1));
    let a2 = running(&p.instance).expect("a still runs");
    std::thread::sleep(Duration::from_secs(1));
    let a3 = running(&p.instance).expect("a still runs");
    assert!(a3 > a2 + 10, "a kept deciding after b stopped: {a2}->{a3}");
}
