//! The decision library's tests: the reference table, the fuzzy memberships, the navigator's
//! maneuvers and the literature policies.

use super::*;
use crate::navigator::{WEDGE_CHANGE, WEDGE_CHANGE_M, WEDGE_TURN_DEG, view_changed};
use hvs_runtime::config::M_PER_FT;

fn reference_thresholds() -> WallThresholds {
    WallThresholds {
        side_m: 2.35 * M_PER_FT,
        front_m: 2.4 * M_PER_FT,
    }
}

fn feet(l: f64, m: f64, r: f64) -> SideRanges {
    SideRanges::lo(Some(l * M_PER_FT), Some(m * M_PER_FT), Some(r * M_PER_FT))
}

#[test]
fn every_wall_pattern_maps_to_its_table_row() {
    let t = reference_thresholds();
    let cases = [
        (
            (1.0, 1.0, 1.0),
            IntersectionType::DeadEnd,
            MotionCommand::Reverse,
        ),
        (
            (1.0, 1.0, 9.0),
            IntersectionType::RightTurn,
            MotionCommand::Right,
        ),
        (
            (9.0, 1.0, 1.0),
            IntersectionType::LeftTurn,
            MotionCommand::Left,
        ),
        (
            (9.0, 1.0, 9.0),
            IntersectionType::TBottom,
            MotionCommand::Left,
        ),
        (
            (1.0, 9.0, 1.0),
            IntersectionType::StraightHallway,
            MotionCommand::Forward,
        ),
        (
            (9.0, 9.0, 1.0),
            IntersectionType::TWallRight,
            MotionCommand::Left,
        ),
        (
            (1.0, 9.0, 9.0),
            IntersectionType::TWallLeft,
            MotionCommand::Right,
        ),
        (
            (9.0, 9.0, 9.0),
            IntersectionType::XIntersection,
            MotionCommand::Right,
        ),
    ];
    for ((l, m, r), ty, cmd) in cases {
        let c = reference_decision(&feet(l, m, r), &t);
        assert_eq!(
            (c.intersection, c.command),
            (ty, cmd),
            "ranges {l},{m},{r} ft"
        );
    }
}

#[test]
fn crisp_reference_table_examples_that_crisp_thresholds_reproduce() {
    // The thesis's printed examples; its hallway example (2.675, 3.054, 2.910) is not
    // consistent with crisp thresholds and is left to the fuzzy policy.
    let t = reference_thresholds();
    let cases = [
        ((1.490, 1.928, 2.586), IntersectionType::RightTurn),
        ((2.569, 2.258, 1.760), IntersectionType::LeftTurn),
        ((2.828, 2.206, 2.458), IntersectionType::TBottom),
        ((3.154, 2.974, 1.890), IntersectionType::TWallRight),
        ((2.320, 2.813, 2.855), IntersectionType::TWallLeft),
        ((2.720, 2.632, 2.447), IntersectionType::XIntersection),
        ((1.765, 1.843, 1.961), IntersectionType::DeadEnd),
    ];
    for ((l, m, r), ty) in cases {
        assert_eq!(
            reference_decision(&feet(l, m, r), &t).intersection,
            ty,
            "{l},{m},{r}"
        );
    }
}

#[test]
fn empty_windows_count_as_open() {
    let r = SideRanges::lo(None, None, Some(0.3));
    assert_eq!(
        reference_decision(&r, &reference_thresholds()).intersection,
        IntersectionType::TWallRight
    );
}

#[test]
fn turn_angle_and_ramp_follow_the_reference_formulas() {
    assert!((turn_angle_deg(1.0, 2.0) - 60.0).abs() < 1e-9);
    assert_eq!(turn_angle_deg(2.0, 1.0), 0.0);
    assert_eq!(turn_ramp(0.0), 20);
    assert_eq!(turn_ramp(90.0), 5);
    assert_eq!(turn_ramp(60.0), 10);
    let c = reference_decision(&feet(9.0, 1.0, 1.0), &reference_thresholds());
    assert!((c.turn_angle_deg - (1.0f64 / 9.0).acos().to_degrees()).abs() < 1e-9);
    assert_eq!(c.ramp, turn_ramp(c.turn_angle_deg));
}

#[test]
fn windows_1_3_5_are_used_with_five_windows() {
    let w = |r: f32| RangeWindow {
        range_m: r,
        valid_px: 5,
        ..Default::default()
    };
    let windows = [w(1.0), w(2.0), w(3.0), w(4.0), w(5.0)];
    let s = SideRanges::from_windows(&windows, 5);
    assert_eq!(
        (s.left_m, s.middle_m, s.right_m),
        (Some(1.0), Some(3.0), Some(5.0))
    );
    let s = SideRanges::from_windows(&windows, 3);
    assert_eq!(
        (s.left_m, s.middle_m, s.right_m),
        (Some(1.0), Some(2.0), Some(3.0))
    );
}

/// The thesis's printed examples (feet) and the type each figure shows.
const EXAMPLES: [((f64, f64, f64), IntersectionType, MotionCommand); 8] = [
    (
        (2.675, 3.054, 2.910),
        IntersectionType::StraightHallway,
        MotionCommand::Forward,
    ),
    (
        (1.490, 1.928, 2.586),
        IntersectionType::RightTurn,
        MotionCommand::Right,
    ),
    (
        (2.569, 2.258, 1.760),
        IntersectionType::LeftTurn,
        MotionCommand::Left,
    ),
    (
        (2.828, 2.206, 2.458),
        IntersectionType::TBottom,
        MotionCommand::Left,
    ),
    (
        (3.154, 2.974, 1.890),
        IntersectionType::TWallRight,
        MotionCommand::Left,
    ),
    (
        (2.320, 2.813, 2.855),
        IntersectionType::TWallLeft,
        MotionCommand::Right,
    ),
    (
        (2.720, 2.632, 2.447),
        IntersectionType::XIntersection,
        MotionCommand::Right,
    ),
    (
        (1.765, 1.843, 1.961),
        IntersectionType::DeadEnd,
        MotionCommand::Reverse,
    ),
];

fn fuzzy_type(l: f64, m: f64, r: f64) -> IntersectionType {
    let cfg = DecisionConfig::default();
    let mem = fuzzy_memberships(&feet(l, m, r), &cfg);
    classify(Walls {
        left: mem.left >= 0.5,
        front: mem.front >= 0.5,
        right: mem.right >= 0.5,
    })
}

#[test]
fn fuzzy_walls_classify_every_printed_example_and_the_table_gives_its_command() {
    for ((l, m, r), ty, cmd) in EXAMPLES {
        assert_eq!(fuzzy_type(l, m, r), ty, "{l},{m},{r} ft");
        assert_eq!(options(ty)[0], cmd, "{ty:?}");
    }
    // Crisp thresholds get the hallway wrong: it is why the fuzzy corridor rule exists.
    let (l, m, r) = EXAMPLES[0].0;
    assert_eq!(
        reference_decision(&feet(l, m, r), &reference_thresholds()).intersection,
        IntersectionType::XIntersection
    );
}

#[test]
fn fuzzy_decisions_are_stable_across_small_range_changes() {
    // Every example keeps its type when each range moves by up to 0.02 ft (6 mm).
    for ((l, m, r), ty, _) in EXAMPLES {
        for dl in [-0.02, 0.0, 0.02] {
            for dm in [-0.02, 0.0, 0.02] {
                for dr in [-0.02, 0.0, 0.02] {
                    assert_eq!(
                        fuzzy_type(l + dl, m + dm, r + dr),
                        ty,
                        "{l}+{dl},{m}+{dm},{r}+{dr}"
                    );
                }
            }
        }
    }
}

#[test]
fn memberships_are_half_at_the_threshold_and_graded_around_it() {
    assert!((near_membership(Some(1.0), 1.0, 0.1) - 0.5).abs() < 1e-9);
    assert_eq!(near_membership(Some(0.85), 1.0, 0.1), 1.0);
    assert_eq!(near_membership(Some(1.15), 1.0, 0.1), 0.0);
    assert!((near_membership(Some(1.05), 1.0, 0.1) - 0.25).abs() < 1e-9);
    assert_eq!(near_membership(None, 1.0, 0.1), 0.0);
}

/// Left, middle and right windows at the reference's printed ranges (feet), 200 pixels
/// each.
fn windows_ft(l: f64, m: f64, r: f64) -> [RangeWindow; 3] {
    [l, m, r].map(|ft| window(ft * M_PER_FT, 200))
}

fn window(range_m: f64, valid_px: u32) -> RangeWindow {
    RangeWindow {
        range_m: range_m as f32,
        near_m: range_m as f32,
        mean_m: range_m as f32,
        valid_px,
        confidence: 0.8,
        source: RangeSource::Lo as u32,
    }
}

/// A navigator with the default config but no local map (the wedge tests feed no scans).
fn navigator_without_map() -> Navigator {
    let cfg = DecisionConfig {
        local_map: false,
        ..DecisionConfig::default()
    };
    Navigator::new(&cfg, &RobotConfig::default(), &PulseTable::default())
}

fn navigator(policy: DecisionPolicy) -> Navigator {
    let cfg = DecisionConfig {
        policy,
        ..DecisionConfig::default()
    };
    Navigator::new(&cfg, &RobotConfig::default(), &PulseTable::default())
}

#[test]
fn hysteresis_keeps_one_noisy_frame_from_flipping_the_command() {
    let mut nav = navigator(DecisionPolicy::Fuzzy);
    let hallway = windows_ft(2.675, 3.054, 2.910);
    // One frame that alone reads as a T-bottom (front near).
    let glitch = windows_ft(2.828, 2.206, 2.458);
    let mut t = 0u64;
    let mut step = |w: &[RangeWindow; 3], nav: &mut Navigator| {
        t += 33_000_000;
        nav.decide(w, 3, &ObstacleScan::default(), t)
    };
    // From standstill, Forward comes after `hold_frames` frames.
    let first: Vec<MotionCommand> = (0..3).map(|_| step(&hallway, &mut nav).command).collect();
    assert_eq!(
        first,
        [
            MotionCommand::Stop,
            MotionCommand::Stop,
            MotionCommand::Forward
        ]
    );
    for _ in 0..10 {
        assert_eq!(step(&hallway, &mut nav).command, MotionCommand::Forward);
    }
    let d = step(&glitch, &mut nav);
    assert_eq!(d.command, MotionCommand::Forward, "{d:?}");
    assert_eq!(d.intersection, IntersectionType::StraightHallway);
    assert_eq!(step(&hallway, &mut nav).command, MotionCommand::Forward);
    // A real change (the front wall stays) does come through.
    let mut turned = false;
    for _ in 0..6 {
        turned |= step(&glitch, &mut nav).command == MotionCommand::Left;
    }
    assert!(turned);
}

#[test]
fn the_reference_policy_reacts_to_every_frame() {
    let mut nav = navigator(DecisionPolicy::Reference);
    let glitch = windows_ft(2.828, 2.206, 2.458);
    let d = nav.decide(&glitch, 3, &ObstacleScan::default(), 1);
    assert_eq!(
        (d.intersection, d.command),
        (IntersectionType::TBottom, MotionCommand::Left)
    );
}

/// Tells the navigator a command's pulses went out at `t_ns` (an actuator that sends
/// every command at once).
fn send_at_once(nav: &mut Navigator, p: &PulseTable, t_ns: u64, command: MotionCommand, ramp: u8) {
    let pulses = match command {
        MotionCommand::Left => p.left,
        MotionCommand::Right => p.right,
        MotionCommand::Forward => p.forward,
        MotionCommand::Reverse => p.reverse,
        MotionCommand::Stop => p.neutral,
    };
    nav.on_sent(t_ns, pulses.left, pulses.right, ramp);
}

#[test]
fn a_turn_is_executed_to_its_angle_by_dead_reckoning_then_committed() {
    let p = PulseTable::default();
    // A left turn (walls front and right), then, once the robot turns, a hallway.
    let left_turn = windows_ft(2.569, 2.258, 1.760);
    let hallway = windows_ft(2.675, 3.054, 2.910);
    // A turning camera's view changes (an unchanged one while turning means wedged).
    let hallway_turned = windows_ft(2.9, 3.4, 3.2);
    // Snapped to the hallway axes (the default), and by the reference's acos angle.
    let reference_deg = turn_angle_deg(2.258, 2.569).max(30.0);
    for (snap, expected) in [(90.0, 90.0), (0.0, reference_deg)] {
        let cfg = DecisionConfig {
            snap_turn_deg: snap,
            ..DecisionConfig::default()
        };
        let mut nav = Navigator::new(&cfg, &RobotConfig::default(), &p);
        let mut t = 0u64;
        let mut commands = Vec::new();
        let mut ramps = Vec::new();
        for i in 0..200 {
            t += 33_000_000;
            let d = nav.decide(
                match i {
                    0 => &left_turn,
                    i if i % 2 == 0 => &hallway_turned,
                    _ => &hallway,
                },
                3,
                &ObstacleScan::default(),
                t,
            );
            ramps.push(d.ramp);
            send_at_once(&mut nav, &p, t, d.command, d.ramp as u8);
            commands.push(d.command);
            if d.command == MotionCommand::Forward {
                break;
            }
        }
        assert_eq!(commands[0], MotionCommand::Left);
        assert_eq!(
            commands.last(),
            Some(&MotionCommand::Forward),
            "{commands:?}"
        );
        assert!(commands.len() > 2, "{commands:?}");
        // Dead reckoning ends the turn: no ramp.
        assert!(ramps.iter().all(|&r| r == 0), "{ramps:?}");
        // Within the turn-rate lead (here the wheels obey at once, so the lead that covers
        // the real link's latency stops the turn up to ~17 degrees early).
        let turned = nav.pose().heading_rad.to_degrees();
        assert!(
            (turned - expected).abs() < 20.0,
            "snap {snap}: turned {turned} expected {expected}"
        );
    }
}

#[test]
fn a_robot_closing_slowly_on_far_walls_is_not_taken_for_a_wedged_one() {
    // Down an open hallway at 0.27 m/s, 15 frames a second, walls about 3 m ahead come
    // 0.6 % nearer a frame: within a frame-to-frame 2 % test for far longer than the
    // 15 frames that mean "wedged", but 10 % nearer within a second.
    let p = PulseTable::default();
    let mut nav = navigator_without_map();
    let mut t = 0u64;
    let mut commands = Vec::new();
    for k in 0..45 {
        t += 66_666_667;
        let scale = 1.0 - 0.006 * k as f64;
        let view = windows_ft(10.0 * scale, 10.5 * scale, 10.2 * scale);
        let d = nav.decide(&view, 3, &ObstacleScan::default(), t);
        send_at_once(&mut nav, &p, t, d.command, 0);
        commands.push(d.command);
    }
    assert!(
        commands[3..].iter().all(|&c| c == MotionCommand::Forward),
        "{commands:?}"
    );
    // The same view, unchanged while the wheels drive: wedged within about a second.
    let view = windows_ft(7.0, 7.35, 7.1);
    let wedged = (0..30).any(|_| {
        t += 66_666_667;
        let d = nav.decide(&view, 3, &ObstacleScan::default(), t);
        send_at_once(&mut nav, &p, t, MotionCommand::Forward, 0);
        d.command == MotionCommand::Reverse
    });
    assert!(wedged);
}

#[test]
fn a_robot_turning_blind_for_a_whole_turn_is_taken_for_a_wedged_one() {
    // Pinned by a corner closer than the matcher's shortest range: no window ever has
    // data, the wheels are told to turn, and only dead reckoning turns. Without this
    // rule the robot turned on the spot for good (the blind view is never "still").
    let p = PulseTable::default();
    let mut nav = navigator_without_map();
    let blind = [window(0.0, 0), window(0.0, 0), window(0.0, 0)];
    let mut t = 0u64;
    let mut turned_rad = 0.0;
    let mut last = nav.pose().heading_rad;
    let mut backed_up = false;
    for _ in 0..1500 {
        t += 66_666_667;
        let d = nav.decide(&blind, 3, &ObstacleScan::default(), t);
        send_at_once(&mut nav, &p, t, d.command, 0);
        turned_rad += (d.pose.heading_rad - last).abs();
        last = d.pose.heading_rad;
        if d.command == MotionCommand::Reverse {
            backed_up = true;
            break;
        }
    }
    assert!(
        backed_up,
        "turned {turned_rad} rad blind without backing up"
    );
    // Not before a whole turn: a robot turning freely sees something within one.
    assert!(turned_rad >= std::f64::consts::TAU - 0.2, "{turned_rad}");
}

#[test]
fn a_robot_pinned_while_turning_takes_back_the_turn_it_never_made() {
    // A left turn starts; the robot is pinned, so its view never changes while the
    // wheels turn it in dead reckoning. Once that is taken for wedged, the dead-reckoned
    // heading goes back to where the view last changed (without that, 30 degrees or
    // more of a turn never made stayed in the heading).
    let p = PulseTable::default();
    let mut nav = navigator_without_map();
    let left_turn = windows_ft(2.569, 2.258, 1.760);
    let mut t = 0u64;
    let mut turned_deg: f64 = 0.0;
    let mut backed_up = false;
    for _ in 0..100 {
        t += 66_666_667;
        let d = nav.decide(&left_turn, 3, &ObstacleScan::default(), t);
        send_at_once(&mut nav, &p, t, d.command, 0);
        turned_deg = turned_deg.max(d.pose.heading_rad.to_degrees().abs());
        if d.command == MotionCommand::Reverse {
            backed_up = true;
            break;
        }
    }
    assert!(backed_up, "never taken for wedged");
    assert!(turned_deg >= WEDGE_TURN_DEG - 1.0, "{turned_deg}");
    let heading_deg = nav.pose().heading_rad.to_degrees();
    // (The anchor is taken a frame into the turn.)
    assert!(heading_deg.abs() < 5.0, "heading {heading_deg} degrees");
}

#[test]
fn a_robot_off_the_hallways_middle_bends_away_from_a_wall_that_starts_beside_it() {
    // The robot drives down +x 0.25 m from a wall on its left that starts at x = 0.6 m
    // (it turned into the hallway off its middle: the hallway behind it is open on the
    // left), 0.8 m from the hallway's other wall. Once the local map holds the left wall
    // beside it, it bends right, towards the middle, and neither stops nor turns a
    // junction's quarter turn into the wall.
    let p = PulseTable::default();
    let cfg = DecisionConfig {
        local_map: true,
        ..DecisionConfig::default()
    };
    let mut nav = Navigator::new(&cfg, &RobotConfig::default(), &p);
    let start_x_m = -2.5;
    let mut t = 0u64;
    let mut commands = Vec::new();
    let mut nearest_m = f64::INFINITY;
    for _ in 0..400 {
        let pose = nav.pose();
        let at = DeadReckonedPose {
            x_m: pose.x_m + start_x_m,
            ..pose
        };
        if at.x_m >= 1.2 {
            break;
        }
        t += 66_666_667;
        let scan =
            local_map::test_scans::scan_of_hallway(at, 0.2, &[(0.25, 0.6), (-0.8, -5.0)], 6.0);
        // Each window's median range (a third of the scan's bins each, left first).
        let windows = [0, 1, 2].map(|k| {
            let third = hvs_shared::messages::SCAN_BINS / 3;
            let mut bins = scan.range_m[k * third..(k + 1) * third].to_vec();
            bins.sort_by(f32::total_cmp);
            window(f64::from(bins[bins.len() / 2]), 150)
        });
        let d = nav.decide(&windows, 3, &scan, t);
        send_at_once(&mut nav, &p, t, d.command, 0);
        commands.push((d.command, d.turn_angle_deg.round()));
        // (It stands for its first frames: a command must be proposed `hold_frames` times.)
        assert!(
            d.turn_angle_deg <= 20.0
                && !matches!(d.command, MotionCommand::Stop | MotionCommand::Reverse)
                || at.x_m < -2.3,
            "{:?} at {at:?}: {commands:?}",
            d.intersection,
        );
        if at.x_m > 0.6 {
            nearest_m = nearest_m.min(0.25 - at.y_m);
        }
    }
    let end = nav.pose();
    assert!(end.x_m + start_x_m >= 1.2, "{end:?}: {commands:?}");
    // The robot never came nearer the wall than it started (its side is 0.155 m from its
    // centre), and it ends further from it.
    assert!(nearest_m >= 0.24, "{nearest_m}: {commands:?}");
    assert!(end.y_m < -0.05, "{end:?}: {commands:?}");
}

#[test]
fn a_turn_that_ends_blind_ahead_is_not_driven_on() {
    // A left turn ends facing a wall closer than the matcher's shortest range: the
    // front window is blind, the side windows see the wall's ends at 0.4 m. That is a
    // blocked front: the robot stands, then tries the other side (half a turn back),
    // and never drives forward into the wall.
    let p = PulseTable::default();
    let mut nav = navigator_without_map();
    let left_turn = windows_ft(2.569, 2.258, 1.760);
    // The side windows' ranges change as the camera turns (an unchanged view while
    // turning means wedged).
    let blind_ahead = [0.4, 0.45].map(|r| [window(r, 60), window(0.0, 0), window(r, 60)]);
    let mut t = 0u64;
    let mut commands = Vec::new();
    for i in 0..120 {
        t += 66_666_667;
        let view = if i == 0 {
            &left_turn
        } else {
            &blind_ahead[i % 2]
        };
        let d = nav.decide(view, 3, &ObstacleScan::default(), t);
        send_at_once(&mut nav, &p, t, d.command, 0);
        commands.push(d.command);
        if d.command == MotionCommand::Right {
            break;
        }
    }
    assert_eq!(commands[0], MotionCommand::Left);
    assert_eq!(commands.last(), Some(&MotionCommand::Right), "{commands:?}");
    assert!(
        !commands.contains(&MotionCommand::Forward),
        "drove on blind: {commands:?}"
    );
}

#[test]
fn a_pinned_robot_is_noticed_through_a_window_whose_range_jumps() {
    // Pinned at a corner (measured in the maze): the right window's range jumps between
    // 0.38 and 0.67 m from frame to frame (few valid pixels), its nearest points stay at
    // 0.37 m, and the other windows hold still. The wheels drive; the robot must be
    // taken for wedged (with the ranges compared it never was: every jump counted as a
    // changed view).
    let p = PulseTable::default();
    let mut nav = navigator_without_map();
    let jumpy = |range_m: f32| RangeWindow {
        range_m,
        near_m: 0.37,
        mean_m: range_m,
        valid_px: 80,
        confidence: 0.3,
        source: RangeSource::Lo as u32,
    };
    let mut t = 0u64;
    let wedged = (0..60).any(|i| {
        t += 66_666_667;
        let view = [
            window(2.95, 380),
            window(2.78, 410),
            jumpy([0.44, 0.67, 0.38, 0.5][i % 4]),
        ];
        let d = nav.decide(&view, 3, &ObstacleScan::default(), t);
        send_at_once(&mut nav, &p, t, MotionCommand::Forward, 0);
        d.command == MotionCommand::Reverse
    });
    assert!(wedged, "never taken for wedged");
}

#[test]
fn a_view_changes_by_five_percent_or_three_centimetres_or_a_window_coming_or_going() {
    let changed =
        |a: &[Option<f64>], b: &[Option<f64>]| view_changed(a, b, WEDGE_CHANGE, WEDGE_CHANGE_M);
    let v = [Some(3.88), Some(2.84), Some(1.85)];
    // The noise of a robot pinned at a corner (measured): not a change.
    assert!(!changed(&v, &[Some(3.89), Some(2.96), Some(1.84)]));
    assert!(changed(&v, &[Some(3.88), Some(2.60), Some(1.85)]));
    assert!(!changed(&[Some(0.5)], &[Some(0.52)]));
    assert!(changed(&[Some(0.5)], &[Some(0.54)]));
    // A wall 0.45 m ahead after a free 30 degree turn in place: a change.
    assert!(changed(
        &[Some(0.45)],
        &[Some(0.45 / 30f64.to_radians().cos())]
    ));
    assert!(changed(&[Some(0.5)], &[None]));
    assert!(!changed(&[None, None], &[None, None]));
}

/// Records a straight drive from `from` to `to` every 0.05 m.
fn drive_line(grid: &mut VisitGrid, from: (f64, f64), to: (f64, f64)) {
    let steps = ((to.0 - from.0).hypot(to.1 - from.1) / 0.05).ceil() as usize;
    for k in 0..=steps {
        let f = k as f64 / steps.max(1) as f64;
        grid.record(from.0 + f * (to.0 - from.0), from.1 + f * (to.1 - from.1));
    }
}

#[test]
fn visit_memory_prefers_the_branch_not_taken() {
    use std::f64::consts::FRAC_PI_2;
    let mut grid = VisitGrid::new(0.35);
    // Driven: up from 3 m to the right (negative y) of the origin.
    drive_line(&mut grid, (0.1, -3.0), (0.1, 0.1));
    let right = grid.score(0.1, 0.1, -FRAC_PI_2);
    let left = grid.score(0.1, 0.1, FRAC_PI_2);
    assert!(right > 0 && left == 0, "left {left} right {right}");
    // Driven back and up again: each pass counts.
    drive_line(&mut grid, (0.1, 0.1), (0.1, -3.0));
    drive_line(&mut grid, (0.1, -3.0), (0.1, 0.1));
    assert_eq!(grid.visits_at(0.1, -1.0), 3);
    assert_eq!(
        grid.visits_at(0.45, -1.0),
        3,
        "the footprint beside the track"
    );
    assert_eq!(grid.visits_at(0.8, -1.0), 0);
    assert_eq!(grid.score(0.1, 0.1, -FRAC_PI_2), 3 * right);
}

#[test]
fn a_hallway_driven_a_cell_to_one_side_still_counts_as_driven() {
    let mut grid = VisitGrid::new(0.35);
    // Driven east along y = 0.3 m; dead reckoning has the robot back at y = 0.4 m (the
    // next row of cells), facing west along the same hallway.
    drive_line(&mut grid, (-2.0, 0.3), (0.0, 0.3));
    let back = grid.score(0.0, 0.4, std::f64::consts::PI);
    assert!(back > 0, "the way back scores {back}");
    // A hallway two rows over was not driven.
    assert_eq!(grid.score(0.0, 1.1, std::f64::consts::PI), 0);
}

#[test]
fn literature_methods_pick_the_freest_window() {
    let near = window(0.5, 400);
    let far = window(2.0, 100);
    let farther = window(3.0, 100);
    assert_eq!(
        mean_estimation([Some(&farther), Some(&near), Some(&far)]),
        MotionCommand::Left
    );
    assert_eq!(
        mean_estimation([Some(&near), Some(&far), Some(&near)]),
        MotionCommand::Forward
    );
    assert_eq!(
        mean_estimation([Some(&near), Some(&near), Some(&far)]),
        MotionCommand::Right
    );
    assert_eq!(
        threshold_estimation([Some(&near), Some(&far), Some(&near)], 0.73),
        MotionCommand::Forward
    );
    assert_eq!(
        threshold_estimation([Some(&near), Some(&near), Some(&far)], 0.73),
        MotionCommand::Right
    );
}
