//! The actuator's serial link at power-on, end to end: the whole pipeline runs against the
//! simulator, but the actuator's device is a scripted servo controller on a real
//! pseudo-terminal ([`PscPeer`]) that answers late, never, with an echo or with garbage, or
//! vanishes and comes back. In every case the actuator is never given up (no restart, state
//! running), nothing but version queries goes out before a valid reply, neutral goes out
//! first, and driving starts within 1 s of the first valid reply. The measured times are
//! printed (docs/bad-input.md, "Servo controller at power-on").

use std::time::{Duration, Instant};

use hvs_tests::psc_peer::{PeerBehaviour, PeerLog, PositionCommand, PscPeer};
use hvs_tests::{Pipeline, stage};

/// Start-up bound for the whole pipeline on a busy machine (the waits end as soon as their
/// condition holds).
const START: Duration = Duration::from_secs(60);
/// The bound: first valid reply to first drive command.
const DRIVE_BOUND: Duration = Duration::from_secs(1);
/// Neutral pulses of config/sim.toml (the built-in table): left wheels on channel 1, right
/// on channel 5.
const NEUTRAL: [(u8, u16); 2] = [(1, 760), (5, 758)];

fn is_neutral(c: &PositionCommand) -> bool {
    NEUTRAL.contains(&(c.channel, c.pulse))
}

/// A pipeline whose actuator opens `peer`'s device.
fn pipeline(tag: &str, peer: &PscPeer) -> Pipeline {
    let device = format!("device = \"{}\"", peer.link().display());
    Pipeline::start(tag, &[("device = \"sim\"", device.as_str())], "")
}

/// Waits until `pred` holds for the peer's log; panics after `timeout` with `what`.
fn wait_log(
    peer: &PscPeer,
    p: &Pipeline,
    what: &str,
    timeout: Duration,
    pred: impl Fn(&PeerLog) -> bool,
) -> PeerLog {
    let deadline = Instant::now() + timeout;
    loop {
        let log = peer.log();
        if pred(&log) {
            return log;
        }
        assert!(
            Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}; peer log: {} queries, {} replies, {} commands\n{}",
            log.queries.len(),
            log.replies.len(),
            log.commands.len(),
            p.logs()
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// The actuator's status entry once its note contains `text`.
fn wait_note(p: &Pipeline, text: &str) -> serde_json::Value {
    let s = p.wait_status(&format!("actuator note {text:?}"), START, |s| {
        stage(s, "actuator")["note"]
            .as_str()
            .is_some_and(|n| n.contains(text))
    });
    stage(&s, "actuator")
}

/// The actuator has never been restarted and is running.
fn assert_never_given_up(p: &Pipeline) {
    let s = p.status().expect("status");
    let a = stage(&s, "actuator");
    assert_eq!(a["restarts"], 0, "actuator restarted: {a}\n{}", p.logs());
    assert_eq!(a["state"], "running", "{a}\n{}", p.logs());
}

/// From the first valid reply at or after `since`: checks that the first command after it
/// is neutral, that nothing but neutral went out before, and returns the time from that
/// reply to the first drive command.
fn reply_to_drive(peer: &PscPeer, p: &Pipeline, since: Instant) -> Duration {
    let log = wait_log(peer, p, "a reply and then a drive command", START, |l| {
        l.replies
            .iter()
            .find(|&&r| r >= since)
            .is_some_and(|&r| l.commands.iter().any(|c| c.at >= r && !is_neutral(c)))
    });
    let reply = *log.replies.iter().find(|&&r| r >= since).expect("a reply");
    let before: Vec<_> = log
        .commands
        .iter()
        .filter(|c| c.at >= since && c.at < reply)
        .collect();
    assert!(
        before.is_empty(),
        "position commands went out before the controller answered: {before:?}"
    );
    let after: Vec<_> = log.commands.iter().filter(|c| c.at >= reply).collect();
    assert!(
        after.len() >= 2 && is_neutral(after[0]) && is_neutral(after[1]),
        "the first two commands after the reply (one per wheel) are not neutral: {after:?}"
    );
    let drive = after
        .iter()
        .find(|c| !is_neutral(c))
        .expect("a drive command");
    let neutral_after = after[0].at - reply;
    let drive_after = drive.at - reply;
    println!(
        "first valid reply -> first neutral {:.1} ms, -> first drive command {:.1} ms",
        neutral_after.as_secs_f64() * 1e3,
        drive_after.as_secs_f64() * 1e3
    );
    drive_after
}

#[test]
fn a_controller_silent_for_5_s_is_waited_for_and_driven_once_it_answers() {
    let dir = tempfile::tempdir().expect("tempdir");
    let peer = PscPeer::start(&dir.path().join("ttyPSC"), PeerBehaviour::Silent);
    let p = pipeline("silent5", &peer);
    let log = wait_log(&peer, &p, "a version query", START, |l| {
        !l.queries.is_empty()
    });
    let first_query = log.queries[0];
    let a = wait_note(&p, "no servo controller answers on");
    println!("note while silent: {}", a["note"]);
    assert_eq!(a["health"], "degraded", "{a}");
    // Switched on 5 s after the first query.
    let on_at = first_query + Duration::from_secs(5);
    std::thread::sleep(on_at.saturating_duration_since(Instant::now()));
    let log = peer.log();
    assert!(
        log.commands.is_empty(),
        "commands sent to a silent controller: {:?}",
        log.commands
    );
    println!(
        "while silent for {:.1} s: {} version queries, 0 position commands",
        first_query.elapsed().as_secs_f64(),
        log.queries.len()
    );
    assert_never_given_up(&p);
    let since = Instant::now();
    peer.set_behaviour(PeerBehaviour::Answer(Duration::ZERO));
    let drive = reply_to_drive(&peer, &p, since);
    assert!(
        drive <= DRIVE_BOUND,
        "driving started {drive:?} after the reply"
    );
    let a = wait_note(&p, "PSC 1.4");
    assert_eq!(a["health"], "running", "{a}");
    assert_never_given_up(&p);
}

#[test]
fn a_controller_that_answers_after_450_ms_is_driven() {
    let dir = tempfile::tempdir().expect("tempdir");
    let since = Instant::now();
    let peer = PscPeer::start(
        &dir.path().join("ttyPSC"),
        PeerBehaviour::Answer(Duration::from_millis(450)),
    );
    let p = pipeline("late450", &peer);
    let drive = reply_to_drive(&peer, &p, since);
    assert!(
        drive <= DRIVE_BOUND,
        "driving started {drive:?} after the reply"
    );
    let log = peer.log();
    let first_reply = log.replies[0];
    let answered = log
        .queries
        .iter()
        .rev()
        .find(|&&q| q <= first_reply)
        .map(|&q| first_reply - q);
    println!(
        "query -> reply {answered:?}, queries before it: {}",
        log.queries.len()
    );
    assert_never_given_up(&p);
}

/// A line that never brings the link up: nothing but version queries, ever.
fn never_driven(tag: &str, behaviour: PeerBehaviour, note: &str) {
    let dir = tempfile::tempdir().expect("tempdir");
    let peer = PscPeer::start(&dir.path().join("ttyPSC"), behaviour);
    let p = pipeline(tag, &peer);
    let a = wait_note(&p, note);
    println!("{behaviour:?}: note {}", a["note"]);
    // Watch for 3 more query windows after the verdict.
    let seen = peer.log().queries.len();
    let log = wait_log(&peer, &p, "three more version queries", START, |l| {
        l.queries.len() >= seen + 3
    });
    assert!(
        log.commands.is_empty(),
        "{behaviour:?}: position commands went out: {:?}",
        &log.commands[..log.commands.len().min(4)]
    );
    assert!(log.replies.is_empty());
    assert_never_given_up(&p);
    println!(
        "{behaviour:?}: {} queries, 0 position commands, actuator running, 0 restarts",
        log.queries.len()
    );
}

#[test]
fn an_echoing_line_is_named_and_never_driven_into() {
    never_driven("echo", PeerBehaviour::Echo, "only an echo on");
}

#[test]
fn a_line_that_answers_garbage_is_named_and_never_driven_into() {
    never_driven("garbage", PeerBehaviour::Garbage, "answers garbage");
}

#[test]
fn a_controller_that_vanishes_mid_run_is_picked_up_again() {
    let dir = tempfile::tempdir().expect("tempdir");
    let since = Instant::now();
    let mut peer = PscPeer::start(
        &dir.path().join("ttyPSC"),
        PeerBehaviour::Answer(Duration::ZERO),
    );
    let p = pipeline("vanish", &peer);
    reply_to_drive(&peer, &p, since);
    let gone_at = Instant::now();
    peer.vanish();
    let a = wait_note(&p, "(waiting");
    println!(
        "{:.0} ms after the node was removed: note {}",
        gone_at.elapsed().as_secs_f64() * 1e3,
        a["note"]
    );
    assert_never_given_up(&p);
    // Plugged back in 2 s later.
    std::thread::sleep(
        (gone_at + Duration::from_secs(2)).saturating_duration_since(Instant::now()),
    );
    let back_at = Instant::now();
    peer.appear();
    let drive = reply_to_drive(&peer, &p, back_at);
    let log = peer.log();
    let reply = *log.replies.iter().find(|&&r| r >= back_at).expect("reply");
    println!(
        "plugged back in -> first valid reply {:.0} ms",
        (reply - back_at).as_secs_f64() * 1e3
    );
    assert!(
        drive <= DRIVE_BOUND,
        "driving resumed {drive:?} after the reply"
    );
    assert_never_given_up(&p);
}
