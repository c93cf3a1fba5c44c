//! Closed-loop simulator tests: the robot's own algorithms (census SGM, Canny fusion, the
//! fuzzy navigator, the actuator's commander and PSC bytes into the simulator's PSC emulator)
//! driving in the intersection maps, through the closed-loop simulator (`hvs_drive`: in this
//! process, faster than real time, deterministic). The last test checks the CLI's errors.
//!
//! Each map starts the robot 1.93 m before the junction's near edge, facing it. A drive lasts
//! 20 simulated seconds: long enough to reach the junction, decide and leave it by a branch,
//! short enough not to reach the end of that branch (the branches end in walls, and what
//! happens there is not what these tests are about).

use hvs_drive::{DriveOptions, drive as run_drive};
use hvs_runtime::config::HvsConfig;
use hvs_tests::{hvs, repo_root};
use serde_json::Value;

fn drive(map: &str, seconds: u32) -> Value {
    drive_with(map, seconds, None)
}

/// Drives `map` for `seconds` with the shipped config (the visit memory as configured, or
/// as given), calling the closed-loop simulator directly; the report as JSON, the form
/// `hvs sim drive --json` prints.
fn drive_with(map: &str, seconds: u32, visit_memory: Option<bool>) -> Value {
    let config = HvsConfig::load(&repo_root().join("config/sim.toml")).expect("config/sim.toml");
    let opts = DriveOptions {
        map: Some(repo_root().join("config/maps").join(map)),
        duration_s: f64::from(seconds),
        visit_memory,
        ..DriveOptions::default()
    };
    let report = run_drive(&config, &opts).unwrap_or_else(|e| panic!("drive {map}: {e}"));
    serde_json::to_value(report).expect("report as JSON")
}

/// Which branch the robot left by, from its final position in the start frame. The junction's
/// centre is 1.93 + 0.525 m ahead of the start.
fn exit_branch(r: &Value) -> &'static str {
    let ahead = r["end_ahead_m"].as_f64().expect("end_ahead_m") - 2.455;
    let left = r["end_left_m"].as_f64().expect("end_left_m");
    if left > 0.8 {
        "left"
    } else if left < -0.8 {
        "right"
    } else if ahead > 0.8 {
        "straight"
    } else if ahead < -1.2 {
        "back"
    } else {
        "none"
    }
}

#[test]
fn front_wall_junctions_are_recognised_and_left_by_a_legal_branch_without_collision() {
    // (map, the type its first turn must be decided as, legal branches)
    let cases: [(&str, &str, &[&str]); 2] = [
        ("t_bottom.txt", "T-bottom", &["left", "right"]),
        ("left_turn.txt", "left-turn", &["left"]),
    ];
    for (map, expected, legal) in cases {
        let r = drive(map, 20);
        assert_eq!(r["collisions"], 0, "{map}: {r}");
        assert_eq!(r["first_turn"][0], expected, "{map}: {r}");
        let branch = exit_branch(&r);
        assert!(legal.contains(&branch), "{map}: left by {branch}: {r}");
    }
}

#[test]
fn a_wrong_first_guess_is_corrected_and_the_robot_still_leaves_legally() {
    // From 1 to 3 m away a forward 53 degree camera cannot reliably tell these two from a
    // T (docs/navigation.md); the robot turns, meets a wall, tries the other side, then the
    // way back, and must end up in the legal branch without touching a wall.
    // `right_corner.txt`: the opening flush with the end wall, as at the maze's hallway
    // ends, looks like a dead end from the approach (the robot used to go back). 25 s: at
    // a front wall the robot first creeps on to 0.67 m from it, then looks to both sides
    // before it turns back.
    for (map, legal) in [
        ("right_turn.txt", "right"),
        ("right_corner.txt", "right"),
        ("dead_end.txt", "back"),
    ] {
        let r = drive(map, 25);
        assert_eq!(r["collisions"], 0, "{map}: {r}");
        assert_eq!(exit_branch(&r), legal, "{map}: {r}");
    }
}

#[test]
fn open_front_junctions_are_driven_straight_through_without_collision() {
    // Straight on is a legal option of every open-front row of the navigation table.
    for map in [
        "straight.txt",
        "t_wall_left.txt",
        "t_wall_right.txt",
        "x.txt",
    ] {
        let r = drive(map, 20);
        assert_eq!(r["collisions"], 0, "{map}: {r}");
        assert_eq!(exit_branch(&r), "straight", "{map}: {r}");
        // It recognised the hallway it started in.
        let hallway = r["intersections"]["hallway"].as_u64().unwrap_or(0);
        assert!(hallway >= 10, "{map}: {r}");
    }
}

#[test]
fn the_maze_is_driven_for_five_minutes_with_and_without_the_visit_memory() {
    // Five simulated minutes from the maze's start pose, both runs side by side (about a
    // minute of wall time each in release). The coverage is printed, not asserted: see
    // docs/navigation.md for why the visit memory does not yet cover clearly more
    // (`scripts/maze-coverage.sh` compares the two from 16 start poses). The shipped
    // configuration (memory on) must not touch a wall from here; without the memory the
    // robot also drives clear of the walls from here now, but not from every start pose
    // (collisions counted in docs/navigation.md).
    let runs: Vec<(&str, Value)> = std::thread::scope(|s| {
        let handles: Vec<_> = ["on", "off"]
            .into_iter()
            .map(|m| s.spawn(move || (m, drive_with("maze.txt", 300, Some(m == "on")))))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("drive thread"))
            .collect()
    });
    for (memory, r) in &runs {
        eprintln!(
            "maze, memory {memory}: collisions {} distinct cells {} distance {:.1} m",
            r["collisions"],
            r["distinct_cells"],
            r["distance_m"].as_f64().unwrap_or(0.0)
        );
        if *memory == "on" {
            assert_eq!(r["collisions"], 0, "memory {memory}: {r}");
        }
        // It drove the whole time: at least 40 m (the forward speed is 0.274 m/s).
        let distance = r["distance_m"].as_f64().expect("distance_m");
        assert!(distance > 40.0, "memory {memory}: {r}");
    }
}

/// Drives with `config/sim.toml` switched to the exploring navigator and the obstacle scan's
/// agreement filter it is measured with, the simulated wheels slipping (the realistic
/// preset: dead reckoning drifts).
fn explore_with(opts: DriveOptions) -> Value {
    let mut config =
        HvsConfig::load(&repo_root().join("config/sim.toml")).expect("config/sim.toml");
    config.decision.policy = hvs_runtime::config::DecisionPolicy::Explore;
    config.fusion.scan_filter = hvs_runtime::config::ScanFilter::Agreement;
    let opts = DriveOptions {
        motion_noise: Some(hvs_sim::SimMotionNoise::realistic()),
        ..opts
    };
    let report = run_drive(&config, &opts).unwrap_or_else(|e| panic!("explore drive: {e}"));
    serde_json::to_value(report).expect("report as JSON")
}

#[test]
fn the_explorer_leaves_its_start_and_uncovers_the_maze_with_slipping_wheels() {
    // Three simulated minutes each (about 30 s of wall time in release), side by side: the
    // maze from its start pose, and two generated mazes no number was tuned on. The
    // explorer must not stand and look: it drives away from its start, and the camera sees
    // a good share of the reachable floor (the start view alone is under 10 %). Collisions
    // are counted, not asserted (docs/navigation.md has the tables: it still touches walls
    // in some runs). At 180 s this build has covered 39 % from the maze's start pose,
    // 42 % of generated maze 11 and 48 % of generated maze 14; an explorer that looks back
    // along its first hallway for a minute (an earlier build: 15 % at 120 s) still passes
    // at three minutes.
    let runs: Vec<(&str, Value)> = std::thread::scope(|s| {
        let maze = s.spawn(|| {
            explore_with(DriveOptions {
                map: Some(repo_root().join("config/maps/maze.txt")),
                duration_s: 180.0,
                ..DriveOptions::default()
            })
        });
        let generated = |seed| {
            explore_with(DriveOptions {
                duration_s: 180.0,
                maze: Some(hvs_sim::MazeOptions {
                    seed,
                    ..hvs_sim::MazeOptions::default()
                }),
                ..DriveOptions::default()
            })
        };
        let maze_11 = s.spawn(move || generated(11));
        // Generated maze 14 held the robot in two loops (the stall check taking the walls'
        // heading fix for motion, and a frontier looked at and blacklisted though still
        // unseen): 8 % coverage in 300 s, 2 m driven; 48 % at 180 s since.
        let maze_14 = s.spawn(move || generated(14));
        vec![
            ("maze.txt", maze.join().expect("drive thread")),
            ("generated maze 11", maze_11.join().expect("drive thread")),
            ("generated maze 14", maze_14.join().expect("drive thread")),
        ]
    });
    for (name, r) in &runs {
        let coverage = r["coverage_pct"].as_f64().expect("coverage_pct");
        let distance = r["distance_m"].as_f64().expect("distance_m");
        eprintln!(
            "explore, {name}: collisions {} coverage {coverage:.1} % distance {distance:.1} m",
            r["collisions"]
        );
        assert_eq!(r["motion_noise"], true, "{name}: {r}");
        assert!(distance > 10.0, "{name}: {r}");
        assert!(coverage > 20.0, "{name}: {r}");
    }
}

#[test]
fn bad_drive_arguments_fail_with_a_message() {
    let out = hvs(&[
        "sim",
        "drive",
        "--map",
        "/nonexistent/map.txt",
        "--duration",
        "1",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/map.txt"), "{err}");
    let out = hvs(&["sim", "drive", "--duration", "-5"]);
    assert!(!out.status.success());
}
