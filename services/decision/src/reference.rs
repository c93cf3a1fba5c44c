//! The reference layer: the three ranges, crisp walls, the nine intersection types and the
//! navigation table, and the reference's turn angle and ramp formulas.

use super::*;

/// The three ranges the reference uses: left, middle and right windows (metres, `None` when
/// the window saw no valid edge pixel), and which path each came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SideRanges {
    /// Leftmost window.
    pub left_m: Option<f64>,
    /// Middle window.
    pub middle_m: Option<f64>,
    /// Rightmost window.
    pub right_m: Option<f64>,
    /// Source of (left, middle, right): the 640x480 path's ranges use its own thresholds.
    pub sources: [RangeSource; 3],
}

impl SideRanges {
    /// Ranges from the fast path only.
    pub fn lo(left_m: Option<f64>, middle_m: Option<f64>, right_m: Option<f64>) -> Self {
        Self {
            left_m,
            middle_m,
            right_m,
            sources: [RangeSource::Lo; 3],
        }
    }

    /// The window indices used: 1, 3 and 5 of five (or 1, 2 and 3 of three).
    pub fn indices(window_count: usize) -> [usize; 3] {
        if window_count >= 5 {
            [0, 2, 4]
        } else {
            [0, 1, 2]
        }
    }

    /// The thresholds for side `i` (0 left, 1 middle, 2 right): those of the path its range
    /// came from.
    pub fn thresholds(&self, i: usize, cfg: &DecisionConfig) -> WallThresholds {
        if self.sources[i] == RangeSource::Hi {
            cfg.hi
        } else {
            cfg.lo
        }
    }

    /// Picks the reference's three windows from a range report.
    pub fn from_windows(windows: &[RangeWindow], window_count: usize) -> Self {
        let pick = |i: usize| {
            windows
                .get(i)
                .filter(|w| w.valid_px > 0 && w.range_m > 0.0)
                .map(|w| (w.range_m as f64, RangeSource::from_code(w.source)))
        };
        let [l, m, r] = Self::indices(window_count).map(pick);
        let src = |p: Option<(f64, RangeSource)>| p.map_or(RangeSource::None, |p| p.1);
        Self {
            left_m: l.map(|p| p.0),
            middle_m: m.map(|p| p.0),
            right_m: r.map(|p| p.0),
            sources: [src(l), src(m), src(r)],
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
    let (turn_angle_deg, ramp) = reference_turn(r, command);
    Choice {
        walls,
        intersection,
        command,
        turn_angle_deg,
        ramp,
    }
}

/// The reference's turn angle and ramp for a command: `acos(r_near / r_far)` with the middle
/// range as `r_near` and the farthest range seen as `r_far` (0 and ramp 0 for other commands).
pub fn reference_turn(r: &SideRanges, command: MotionCommand) -> (f64, u32) {
    match command {
        MotionCommand::Left | MotionCommand::Right => {
            let seen = [r.left_m, r.middle_m, r.right_m];
            let far = seen.iter().flatten().copied().fold(0.0, f64::max);
            let near = r.middle_m.unwrap_or(far);
            let theta = turn_angle_deg(near, far);
            (theta, turn_ramp(theta))
        }
        _ => (0.0, 0),
    }
}
