//! End-to-end test of `hvs run --record` and `hvs run --replay`: a simulator run through the
//! whole pipeline is recorded, played back through a fresh pipeline (no simulator, no
//! actuator), and the replay must repeat every recorded decision for the same frame.

use std::collections::BTreeMap;
use std::path::Path;

use hvs_tests::{hvs_ok, unique_instance, write_config};
use serde_json::Value;

/// The decisions of a recording by frame id (everything but the times), and how many of
/// them turn.
fn decisions(path: &Path) -> (BTreeMap<u64, Value>, usize) {
    let file = std::fs::File::open(path).expect("open the recording");
    let reader = mcap::io::MessageReader::new(std::io::BufReader::new(file));
    let mut out = BTreeMap::new();
    for message in reader {
        let message = message.expect("every message reads back");
        if message.channel.topic != "/decisions" {
            continue;
        }
        let mut v: Value = serde_json::from_slice(&message.data).expect("decision JSON");
        let id = v["frame_id"].as_u64().expect("frame_id");
        if let Some(o) = v.as_object_mut() {
            for time in ["capture_ns", "published_ns", "capture_to_decision_ms"] {
                o.remove(time);
            }
        }
        assert!(out.insert(id, v).is_none(), "frame {id} decided twice");
    }
    let turns = out
        .values()
        .filter(|v| v["command_label"] == "LEFT" || v["command_label"] == "RIGHT")
        .count();
    (out, turns)
}

#[test]
fn a_replayed_recording_repeats_every_decision_for_the_same_frame() {
    let dir = tempfile::tempdir().expect("tempdir");
    // The right-turn junction with the robot 4 cells nearer than in config/maps: within a
    // few seconds it classifies the junction and turns, so the decisions depend on dead
    // reckoning from the actuator output, not only on the images.
    let map = std::fs::read_to_string(hvs_tests::repo_root().join("config/maps/right_turn.txt"))
        .expect("right_turn.txt");
    let nearer = map.replace("#.>.........#", "#.....>.....#");
    assert_ne!(
        map, nearer,
        "right_turn.txt changed: move the start marker differently"
    );
    let map_path = dir.path().join("right_turn_near.txt");
    std::fs::write(&map_path, nearer).expect("write map");
    let config = write_config(
        dir.path(),
        "sim.toml",
        &[(
            &format!(
                "{}",
                hvs_tests::repo_root()
                    .join("config/maps/maze.txt")
                    .display()
            ),
            &format!("{}", map_path.display()),
        )],
        "",
    );
    let config = config.to_str().expect("utf-8 path");
    let recorded = dir.path().join("robot.mcap");
    let replayed = dir.path().join("replay.mcap");
    let run = hvs_ok(&[
        "run",
        "--config",
        config,
        "--instance",
        &unique_instance("rec"),
        "--duration",
        "10",
        "--record",
        recorded.to_str().expect("utf-8 path"),
    ]);
    println!("{}", String::from_utf8_lossy(&run.stdout));
    let replay = hvs_ok(&[
        "run",
        "--config",
        config,
        "--instance",
        &unique_instance("replay"),
        "--replay",
        recorded.to_str().expect("utf-8 path"),
        "--record",
        replayed.to_str().expect("utf-8 path"),
        // A bound, not the expected time: the replay stops by itself at the end.
        "--duration",
        "240",
    ]);
    let replay_out = String::from_utf8_lossy(&replay.stdout);
    println!("{replay_out}");
    // What the stages reported (a failure below is read against these).
    for (name, out) in [("recorded run", &run), ("replay", &replay)] {
        for line in String::from_utf8_lossy(&out.stderr)
            .lines()
            .filter(|l| l.contains("WARN") || l.contains("ERROR"))
        {
            println!("{name} stderr: {line}");
        }
    }
    let replay_s: f64 = replay_out
        .split("stopped after ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .and_then(|t| t.parse().ok())
        .expect("`hvs: stopped after S s` on stdout");
    assert!(
        replay_s < 200.0,
        "the replay did not end by itself:\n{}",
        String::from_utf8_lossy(&replay.stderr)
    );

    let (original, turns) = decisions(&recorded);
    let (again, _) = decisions(&replayed);
    println!(
        "recorded {} decisions ({turns} turning), replayed {}",
        original.len(),
        again.len()
    );
    // 10 s at 15 Hz gives about 150 decisions; a machine whose cores are shared gives fewer
    // (146 with both cores kept busy), so the bound is well below.
    assert!(original.len() >= 60, "only {} decisions", original.len());
    assert!(turns > 0, "the robot never turned: the test proves less");
    // A recorder that falls behind drops samples and says how many (slow readers never hold
    // the pipeline up). From a complete recording every decision repeats exactly. A lossy one
    // (a machine whose cores are shared) repeats exactly up to its first gap: after a lost
    // sample the replay's navigator has seen less than the robot's had, and may differ.
    let lost: Vec<(&str, u64)> = [
        "decisions",
        "frames/320x240",
        "frames/640x480",
        "ranges",
        "actuator/sent",
    ]
    .into_iter()
    .map(|topic| (topic, recorded_counts(&run.stdout, topic).1))
    .filter(|(_, dropped)| *dropped > 0)
    .collect();
    let (_, dropped_by_replay) = recorded_counts(&replay.stdout, "decisions");
    // The first frame id after which the recorded decisions are not contiguous (a frame the
    // pipeline or the recorder lost): everything before it was recorded in full.
    let first_gap = original
        .keys()
        .zip(original.keys().skip(1))
        .find(|(a, b)| **b != **a + 1)
        .map_or(u64::MAX, |(a, _)| *a + 1);
    let compare_below = if lost.is_empty() { u64::MAX } else { first_gap };
    let mut differ = Vec::new();
    let mut compared = 0u64;
    let mut not_replayed = 0u64;
    for (id, d) in original.range(..compare_below) {
        match again.get(id) {
            Some(r) if r == d => compared += 1,
            Some(r) => differ.push(format!("frame {id}: recorded {d}, replayed {r}")),
            None => not_replayed += 1,
        }
    }
    let extra: Vec<&u64> = again
        .range(..compare_below)
        .map(|(id, _)| id)
        .filter(|id| !original.contains_key(id))
        .collect();
    println!(
        "{compared} decisions compared{}; {not_replayed} missing from the replay's recording \
         ({dropped_by_replay} dropped by its recorder)",
        if lost.is_empty() {
            String::from(" (a complete recording: all of them)")
        } else {
            format!(" (a lossy recording, {lost:?} dropped: those before frame {first_gap})")
        }
    );
    assert!(
        not_replayed <= dropped_by_replay,
        "{not_replayed} recorded decisions were not replayed, but the replay's recorder \
         dropped only {dropped_by_replay}"
    );
    assert!(
        extra.is_empty() || !lost.is_empty(),
        "replayed decisions that a complete recording does not have: {extra:?}"
    );
    assert!(compared > 0, "no decision compared");
    if lost.is_empty() {
        assert!(compared >= 60, "only {compared} decisions compared");
    }
    assert!(
        differ.is_empty(),
        "{} of {} decisions differ: {:#?}",
        differ.len(),
        compared as usize + differ.len(),
        &differ[..differ.len().min(10)]
    );
}

/// The `written` and `dropped` counts `hvs run --record` prints for a topic
/// (`record |   decisions   146 written   8 dropped`).
fn recorded_counts(stdout: &[u8], topic: &str) -> (u64, u64) {
    let text = String::from_utf8_lossy(stdout);
    let line = text
        .lines()
        .find(|l| l.split_whitespace().nth(2) == Some(topic) && l.contains(" written "))
        .unwrap_or_else(|| panic!("no record line for {topic} in:\n{text}"));
    let f: Vec<&str> = line.split_whitespace().collect();
    let number = |i: usize| -> u64 { f[i].parse().unwrap_or_else(|_| panic!("{line}")) };
    (number(3), number(5))
}
