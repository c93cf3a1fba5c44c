//! hvs decision: from ranges per window to walls, the intersection type of the reference
//! navigation table, and a motion command, with no IPC.

use hvs_shared::config::WallThresholds;
use hvs_shared::messages::{IntersectionType, MotionCommand, RangeWindow};

/// Decision policy codes carried in [`hvs_shared::messages::Decision::policy`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Policy {
    /// The reference system: crisp wall thresholds and the navigation table's first option.
    Reference = 1,
}

/// The three ranges the reference uses: left, middle and right windows (metres, `None` when
/// the window saw no valid edge pixel).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SideRanges {
    /// Leftmost window.
    pub left_m: Option<f64>,
    /// Middle window.
    pub middle_m: Option<f64>,
    /// Rightmost window.
    pub right_m: Option<f64>,
}

impl SideRanges {
    /// Picks windows 1, 3 and 5 of five (or 1, 2 and 3 of three) from a range report.
    pub fn from_windows(windows: &[RangeWindow], window_count: usize) -> Self {
        let pick = |i: usize| {
            windows
                .get(i)
                .filter(|w| w.valid_px > 0 && w.range_m > 0.0)
                .map(|w| w.range_m as f64)
        };
        let (l, m, r) = if window_count >= 5 {
            (0, 2, 4)
        } else {
            (0, 1, 2)
        };
        Self {
            left_m: pick(l),
            middle_m: pick(m),
            right_m: pick(r),
        }
    }
}

/// Which walls are present.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Walls {
    /// Wall on the left.
    pub left: bool,
    /// Wall in front.
    pub front: bool,
    /// Wall on the right.
    pub right: bool,
}

/// The reference rule: a wall is present left if r1 < a, in front if r3 < b, right if r5 < a.
/// A window without data counts as open (nothing seen close by).
pub fn crisp_walls(r: &SideRanges, t: &WallThresholds) -> Walls {
    let below = |v: Option<f64>, limit: f64| v.is_some_and(|v| v < limit);
    Walls {
        left: below(r.left_m, t.side_m),
        front: below(r.middle_m, t.front_m),
        right: below(r.right_m, t.side_m),
    }
}

/// The intersection type of a wall pattern (the reference table).
pub fn classify(w: Walls) -> IntersectionType {
    match (w.left, w.front, w.right) {
        (true, true, true) => IntersectionType::DeadEnd,
        (true, true, false) => IntersectionType::RightTurn,
        (false, true, true) => IntersectionType::LeftTurn,
        (false, true, false) => IntersectionType::TBottom,
        (true, false, true) => IntersectionType::StraightHallway,
        (false, false, true) => IntersectionType::TWallRight,
        (true, false, false) => IntersectionType::TWallLeft,
        (false, false, false) => IntersectionType::XIntersection,
    }
}

/// The options of the reference navigation table for an intersection, first = taken.
pub fn options(t: IntersectionType) -> &'static [MotionCommand] {
    use MotionCommand::*;
    match t {
        IntersectionType::DeadEnd => &[Reverse],
        IntersectionType::RightTurn => &[Right],
        IntersectionType::LeftTurn => &[Left],
        IntersectionType::TBottom => &[Left, Right, Stop, Reverse],
        IntersectionType::StraightHallway => &[Forward],
        IntersectionType::TWallRight => &[Left, Forward, Stop, Reverse],
        IntersectionType::TWallLeft => &[Right, Forward, Stop, Reverse],
        IntersectionType::BIntersection => &[Forward],
        IntersectionType::XIntersection => &[Right, Forward, Left, Reverse],
        IntersectionType::Unknown => &[Stop],
    }
}

/// Turn angle `acos(r_near / r_far)` in degrees (0 when undefined or r_near >= r_far).
pub fn turn_angle_deg(r_near_m: f64, r_far_m: f64) -> f64 {
    if !(r_near_m > 0.0 && r_far_m > 0.0) || r_near_m >= r_far_m {
        return 0.0;
    }
    (r_near_m / r_far_m).acos().to_degrees()
}

/// PSC ramp for a turn of `theta_deg`: `20 - 15 * theta / 90`, rounded, within 5..=20.
pub fn turn_ramp(theta_deg: f64) -> u32 {
    (20.0 - 15.0 * theta_deg.clamp(0.0, 90.0) / 90.0).round() as u32
}

/// One decision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Choice {
    /// The walls seen.
    pub walls: Walls,
    /// The intersection type.
    pub intersection: IntersectionType,
    /// The command.
    pub command: MotionCommand,
    /// Turn angle for turns, degrees.
    pub turn_angle_deg: f64,
    /// PSC ramp.
    pub ramp: u32,
}

/// The reference decision for one set of ranges.
pub fn reference_decision(r: &SideRanges, t: &WallThresholds) -> Choice {
    let walls = crisp_walls(r, t);
    let intersection = classify(walls);
    let command = options(intersection)[0];
    let (turn_angle_deg, ramp) = match command {
        MotionCommand::Left | MotionCommand::Right => {
            let seen = [r.left_m, r.middle_m, r.right_m];
            let far = seen.iter().flatten().copied().fold(0.0, f64::max);
            let near = r.middle_m.unwrap_or(far);
            let theta = turn_angle_deg(near, far);
            (theta, turn_ramp(theta))
        }
        _ => (0.0, 0),
    };
    Choice {
        walls,
        intersection,
        command,
        turn_angle_deg,
        ramp,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use hvs_shared::config::M_PER_FT;

    fn reference_thresholds() -> WallThresholds {
        WallThresholds {
            side_m: 2.35 * M_PER_FT,
            front_m: 2.4 * M_PER_FT,
        }
    }

    fn feet(l: f64, m: f64, r: f64) -> SideRanges {
        SideRanges {
            left_m: Some(l * M_PER_FT),
            middle_m: Some(m * M_PER_FT),
            right_m: Some(r * M_PER_FT),
        }
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
        let r = SideRanges {
            left_m: None,
            middle_m: None,
            right_m: Some(0.3),
        };
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
}
