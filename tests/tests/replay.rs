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
        .filter(|v| v["command"] == "LEFT" || v["command"] == "RIGHT")
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
    assert!(original.len() >= 200, "only {} decisions", original.len());
    assert!(turns > 0, "the robot never turned: the test proves less");
    let mut differ = Vec::new();
    for (id, d) in &original {
        match again.get(id) {
            Some(r) if r == d => {}
            Some(r) => differ.push(format!("frame {id}: recorded {d}, replayed {r}")),
            None => differ.push(format!("frame {id}: recorded {d}, not replayed")),
        }
    }
    let extra: Vec<&u64> = again
        .keys()
        .filter(|id| !original.contains_key(id))
        .collect();
    assert!(
        differ.is_empty() && extra.is_empty(),
        "{} of {} decisions differ, {} extra: {:#?} {extra:?}",
        differ.len(),
        original.len(),
        extra.len(),
        &differ[..differ.len().min(10)]
    );
}
