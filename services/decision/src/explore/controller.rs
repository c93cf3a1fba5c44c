//! The local controller for the skid-steer base: it follows the planner's path through the
//! pulse table's motions (ahead, turn left or right in place, back up, stop). The point
//! followed lies `lookahead_m` along the path; a heading error beyond `turn_above_deg` turns
//! the robot in place until it is within `aligned_deg` (stopping early by the turn rate times
//! the command latency), otherwise it drives ahead. Every motion is checked against the
//! occupancy grid with the robot's footprint first: ahead, the swept rectangle; turning, the
//! circle its corners sweep, checked again every frame of the turn (the camera sees new
//! ground as the robot turns). A robot boxed in (no room to turn, shifting did not make
//! room) with the path behind it backs out along the way it came while that is held free.

use std::f64::consts::FRAC_PI_2;

use hvs_runtime::config::{ControllerConfig, PulsePair, PulseTable, RobotConfig};
use hvs_shared::messages::MotionCommand;

use super::grid::{OccupancyGrid, for_each_rect_sample, to_grid_frame};
use crate::local_map::CellState;
use crate::odometry::DeadReckonedPose;

/// Wraps an angle to (-pi, pi].
pub fn wrap_rad(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let w = (a + PI).rem_euclid(TAU) - PI;
    if w <= -PI { w + TAU } else { w }
}

/// Footprint checks against the grid's occupied cells.
#[derive(Debug, Clone, Copy)]
pub struct FootprintCheck {
    half_width_m: f64,
    half_length_m: f64,
    turn_radius_m: f64,
    /// Margin beyond `turn_radius_m` checked turning, metres.
    turn_margin_m: f64,
    /// Side margin of the swept rectangles beyond the footprint, metres.
    sweep_margin_m: f64,
    /// Largest share of a swept rectangle that may be unknown for "seen clear".
    max_unknown_share: f64,
    /// Where the robot turns about for each turn command, metres to the left of its centre:
    /// a skid-steer's turn pulses rarely cancel (the reference's left turn backs at 0.28 m/s
    /// while it turns), so "in place" is a small circle.
    pivot_left_m: (f64, f64),
}

/// The cells a motion would sweep, by state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweptArea {
    /// Samples on occupied cells.
    pub occupied: usize,
    /// Share of the samples on unknown cells (0..1).
    pub unknown_share: f64,
}

impl SweptArea {
    fn of((occupied, unknown, all): (usize, usize, usize)) -> Self {
        Self {
            occupied,
            unknown_share: unknown as f64 / all.max(1) as f64,
        }
    }
}

/// Body speed and turn rate for a pulse pair, from the wheel model the dead reckoning uses.
fn body_motion(robot: &RobotConfig, pulses: &PulseTable, pair: PulsePair) -> (f64, f64) {
    let wheel = |pw: u16, neutral: u16, forward: u16| {
        let span = f64::from(forward) - f64::from(neutral);
        if span.abs() < 1e-9 {
            0.0
        } else {
            (f64::from(pw) - f64::from(neutral)) / span * robot.forward_speed_mps
        }
    };
    let vl = wheel(pair.left, pulses.neutral.left, pulses.forward.left);
    let vr = wheel(pair.right, pulses.neutral.right, pulses.forward.right);
    (0.5 * (vl + vr), (vr - vl) / robot.track_m)
}

impl FootprintCheck {
    /// The checks for a robot body and its pulse table, with the controller's margins
    /// (`turn_margin_m` beyond the circle the corners sweep turning).
    pub fn of(robot: &RobotConfig, pulses: &PulseTable, cfg: &ControllerConfig) -> Self {
        let pivot = |pair| {
            let (v, w) = body_motion(robot, pulses, pair);
            if w.abs() < 1e-6 { 0.0 } else { v / w }
        };
        Self {
            half_width_m: 0.5 * robot.width_m,
            half_length_m: 0.5 * robot.length_m,
            turn_radius_m: robot.half_diagonal_m(),
            turn_margin_m: cfg.turn_margin_m,
            sweep_margin_m: cfg.sweep_margin_m,
            max_unknown_share: cfg.max_unknown_ahead_share,
            pivot_left_m: (pivot(pulses.left), pivot(pulses.right)),
        }
    }

    /// No occupied cell in `swept` and mostly cells seen free.
    pub fn seen_clear(&self, swept: &SweptArea) -> bool {
        swept.occupied == 0 && swept.unknown_share <= self.max_unknown_share
    }

    /// Half the footprint's length, metres.
    pub fn half_length_m(&self) -> f64 {
        self.half_length_m
    }

    /// Half the footprint's width, metres.
    pub fn half_width_m(&self) -> f64 {
        self.half_width_m
    }

    /// Radius of the circle the footprint's corners sweep turning in place about its centre,
    /// metres.
    pub fn turn_radius_m(&self) -> f64 {
        self.turn_radius_m
    }

    /// How far from the robot's centre the turn check looks for walls, either way, metres:
    /// the corners' circle moved by the turn's pivot, plus `turn_margin_m`.
    pub fn turn_reach_m(&self) -> f64 {
        self.reach_m(self.pivot_left_m.0)
            .max(self.reach_m(self.pivot_left_m.1))
    }

    /// The turn check's radius about the robot's centre for a turn whose centre lies
    /// `pivot_m` to the left, metres.
    fn reach_m(&self, pivot_m: f64) -> f64 {
        self.turn_radius_m + pivot_m.abs() + self.turn_margin_m
    }

    /// Counts the samples of the robot-frame rectangle `ahead` x `left` (metres) by state:
    /// (occupied, unknown, all).
    fn rect_count(
        &self,
        grid: &OccupancyGrid,
        pose: &DeadReckonedPose,
        ahead: (f64, f64),
        left: (f64, f64),
    ) -> (usize, usize, usize) {
        let (mut occupied, mut unknown, mut all) = (0, 0, 0);
        for_each_rect_sample(pose, ahead, left, 0.5 * grid.cell_m(), |x, y| {
            match grid.state_at(x, y) {
                CellState::Occupied => occupied += 1,
                CellState::Unknown => unknown += 1,
                CellState::Free => {}
            }
            all += 1;
        });
        (occupied, unknown, all)
    }

    /// What driving `ahead_m` forward would sweep: the camera is blind closer than the
    /// matcher's shortest range and sees only its field of view, so right after a turn the
    /// cells beside the way ahead are often unknown rather than seen free.
    pub fn ahead_swept(
        &self,
        grid: &OccupancyGrid,
        pose: &DeadReckonedPose,
        ahead_m: f64,
    ) -> SweptArea {
        self.swept(
            grid,
            pose,
            (self.half_length_m, self.half_length_m + ahead_m),
        )
    }

    /// The footprint's width (plus `sweep_margin_m` a side) swept over `ahead` (robot
    /// frame, metres).
    fn swept(&self, grid: &OccupancyGrid, pose: &DeadReckonedPose, ahead: (f64, f64)) -> SweptArea {
        let w = self.half_width_m + self.sweep_margin_m;
        SweptArea::of(self.rect_count(grid, pose, ahead, (-w, w)))
    }

    /// Whether driving `ahead_m` forward sweeps no occupied cell and mostly cells seen free.
    pub fn ahead_clear(&self, grid: &OccupancyGrid, pose: &DeadReckonedPose, ahead_m: f64) -> bool {
        self.seen_clear(&self.ahead_swept(grid, pose, ahead_m))
    }

    /// Whether backing up `back_m` sweeps no occupied cell and mostly cells seen free (the
    /// camera never sees behind: what is known there is the way the robot came, which the
    /// grid clears under its footprint, and walls seen before the robot turned).
    pub fn behind_clear(&self, grid: &OccupancyGrid, pose: &DeadReckonedPose, back_m: f64) -> bool {
        self.seen_clear(&self.swept(
            grid,
            pose,
            (-self.half_length_m - back_m, -self.half_length_m),
        ))
    }

    /// Whether the disc the footprint sweeps turning (`left` or right) holds an occupied
    /// cell, and if so whether the nearest one is ahead of the turning centre.
    pub fn turn_blocked(
        &self,
        grid: &OccupancyGrid,
        pose: &DeadReckonedPose,
        left: bool,
    ) -> Option<bool> {
        let pivot = if left {
            self.pivot_left_m.0
        } else {
            self.pivot_left_m.1
        };
        let r = self.reach_m(pivot);
        let step = 0.5 * grid.cell_m();
        let n = (r / step).ceil() as i64;
        let mut nearest: Option<(f64, f64)> = None;
        for i in -n..=n {
            for j in -n..=n {
                let p = (i as f64 * step, pivot + j as f64 * step);
                let d = (i as f64 * step).hypot(j as f64 * step);
                if d > r {
                    continue;
                }
                let (x, y) = to_grid_frame(pose, p);
                if grid.state_at(x, y) == CellState::Occupied
                    && nearest.is_none_or(|(nd, _)| d < nd)
                {
                    nearest = Some((d, p.0));
                }
            }
        }
        nearest.map(|(_, ahead)| ahead > 0.0)
    }
}

/// What the controller is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    /// Driving along the path (or standing, when told to).
    Follow,
    /// Turning in place toward the path (`left`: counter-clockwise); `disc_clear`: the
    /// turning disc held no occupied cell when the turn began.
    Turn { left: bool, disc_clear: bool },
}

/// What the controller decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Control {
    /// The motion to send.
    pub command: MotionCommand,
    /// The way along the path was blocked (the caller should plan again).
    pub blocked: bool,
    /// Heading error to the followed point, radians.
    pub heading_error_rad: f64,
}

/// The path follower.
#[derive(Debug, Clone)]
pub struct Controller {
    cfg: ControllerConfig,
    footprint: FootprintCheck,
    mode: Mode,
    /// Shifts (ahead or back) made in a row to clear the turning disc.
    shifts: u32,
}

/// What the controller sees this frame.
#[derive(Debug, Clone, Copy)]
pub struct ControlInput<'a> {
    /// The pose on the map.
    pub pose: DeadReckonedPose,
    /// The path, grid frame, metres (from the robot to the goal).
    pub path: &'a [(f64, f64)],
    /// The middle window's range, metres (None: nothing seen).
    pub front_m: Option<f64>,
    /// The current turn rate, rad/s.
    pub turn_rate_rad_s: f64,
}

impl Controller {
    /// A controller for a robot body and its pulse table.
    pub fn new(cfg: ControllerConfig, robot: &RobotConfig, pulses: &PulseTable) -> Self {
        Self {
            cfg,
            footprint: FootprintCheck::of(robot, pulses, &cfg),
            mode: Mode::Follow,
            shifts: 0,
        }
    }

    /// The footprint checks.
    pub fn footprint(&self) -> &FootprintCheck {
        &self.footprint
    }

    /// Forgets a turn in progress.
    pub fn reset(&mut self) {
        self.mode = Mode::Follow;
    }

    /// The point `lookahead_m` along the path from its point nearest the robot.
    fn lookahead(&self, pose: &DeadReckonedPose, path: &[(f64, f64)]) -> Option<(f64, f64)> {
        let nearest = path
            .iter()
            .enumerate()
            .min_by(|a, b| {
                let da = (a.1.0 - pose.x_m).hypot(a.1.1 - pose.y_m);
                let db = (b.1.0 - pose.x_m).hypot(b.1.1 - pose.y_m);
                da.total_cmp(&db)
            })
            .map(|(i, _)| i)?;
        let mut left = self.cfg.lookahead_m;
        let mut prev = (pose.x_m, pose.y_m);
        for &p in &path[nearest..] {
            let d = (p.0 - prev.0).hypot(p.1 - prev.1);
            if d >= left {
                let t = left / d;
                return Some((prev.0 + t * (p.0 - prev.0), prev.1 + t * (p.1 - prev.1)));
            }
            left -= d;
            prev = p;
        }
        path.last().copied()
    }

    /// One control step on the grid.
    pub fn step(&mut self, grid: &OccupancyGrid, input: ControlInput<'_>) -> Control {
        let pose = input.pose;
        let Some(target) = self.lookahead(&pose, input.path) else {
            self.mode = Mode::Follow;
            return Control {
                command: MotionCommand::Stop,
                blocked: false,
                heading_error_rad: 0.0,
            };
        };
        let bearing = (target.1 - pose.y_m).atan2(target.0 - pose.x_m);
        let error = wrap_rad(bearing - pose.heading_rad);
        let out = |command, blocked| Control {
            command,
            blocked,
            heading_error_rad: error,
        };
        if let Mode::Turn { left, disc_clear } = self.mode {
            // The camera sees new ground as the robot turns: a wall that shows up in the
            // disc it sweeps stops a turn begun on a clear disc (the path is then followed
            // afresh: shift off it, or turn anyway once boxed in).
            if disc_clear && self.footprint.turn_blocked(grid, &pose, left).is_some() {
                self.mode = Mode::Follow;
                return out(MotionCommand::Stop, false);
            }
            let lead = input.turn_rate_rad_s.abs() * self.cfg.turn_lead_s;
            let still_to_go = if left { error } else { -error };
            if still_to_go - lead > self.cfg.aligned_deg.to_radians() {
                return out(turn_command(left), false);
            }
            self.mode = Mode::Follow;
            if error.abs() > self.cfg.aligned_deg.to_radians() + lead {
                // Overshot: stand for a frame and look again.
                return out(MotionCommand::Stop, false);
            }
        }
        if error.abs() > self.cfg.turn_above_deg.to_radians() {
            let left = error > 0.0;
            let blocked = self.footprint.turn_blocked(grid, &pose, left);
            // Too near the front to see it (`turn_front_min_m`): back off first, as from a
            // wall ahead in the disc, until the camera sees what the turn will sweep past.
            let front_near = self.cfg.turn_front_min_m > 0.0
                && input.front_m.is_some_and(|m| m < self.cfg.turn_front_min_m);
            if (blocked.is_some() || front_near) && self.shifts < self.cfg.max_shifts {
                // Something in the turning disc (or a front too near): move away from it
                // first.
                if (front_near || blocked == Some(true))
                    && self
                        .footprint
                        .behind_clear(grid, &pose, self.cfg.shift_check_m)
                {
                    self.shifts += 1;
                    return out(MotionCommand::Reverse, false);
                }
                if blocked == Some(false)
                    && self.may_drive_ahead(grid, &pose, self.cfg.shift_check_m, input.front_m)
                {
                    self.shifts += 1;
                    return out(MotionCommand::Forward, false);
                }
                // Boxed in: back out (below), or turn anyway, the shortest way.
            }
            if blocked.is_some()
                && error.abs() > FRAC_PI_2
                && self
                    .footprint
                    .behind_clear(grid, &pose, self.cfg.lookahead_m)
            {
                // Boxed in with the path behind (a hallway narrower than the turning disc,
                // a dead end): back out along the way the robot came, which the grid holds
                // free, until there is room to turn.
                return out(MotionCommand::Reverse, false);
            }
            self.shifts = 0;
            self.mode = Mode::Turn {
                left,
                disc_clear: blocked.is_none(),
            };
            return out(turn_command(left), false);
        }
        if self.may_drive_ahead(grid, &pose, self.cfg.check_ahead_m, input.front_m) {
            out(MotionCommand::Forward, false)
        } else {
            out(MotionCommand::Stop, true)
        }
    }

    /// Driving `ahead_m` forward sweeps no occupied cell, and either mostly cells seen free
    /// or the middle window sees nothing within `stop_range_m` plus that distance (then any
    /// share may be unknown: after a turn the sides of the way lie in the camera's blind
    /// zone, and only the middle of the way is vouched for by the window).
    fn may_drive_ahead(
        &self,
        grid: &OccupancyGrid,
        pose: &DeadReckonedPose,
        ahead_m: f64,
        front_m: Option<f64>,
    ) -> bool {
        let swept = self.footprint.ahead_swept(grid, pose, ahead_m);
        if swept.occupied > 0 || !self.front_open(front_m) {
            return false;
        }
        self.footprint.seen_clear(&swept)
            || front_m.is_some_and(|m| m >= self.cfg.stop_range_m + ahead_m)
    }

    fn front_open(&self, front_m: Option<f64>) -> bool {
        front_m.is_none_or(|m| m >= self.cfg.stop_range_m)
    }
}

fn turn_command(left: bool) -> MotionCommand {
    if left {
        MotionCommand::Left
    } else {
        MotionCommand::Right
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::explore::grid::ScanPoints;
    use hvs_runtime::config::GridConfig;
    use hvs_shared::messages::ObstacleScan;

    /// A grid seen free for 3 m all round the origin.
    fn open_grid() -> OccupancyGrid {
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let mut scan = hvs_shared::messages::ObstacleScan {
            tan_half_fov: 0.5,
            ..Default::default()
        };
        scan.range_m = [5.0; hvs_shared::messages::SCAN_BINS];
        for k in 0..16 {
            let pose = DeadReckonedPose {
                heading_rad: f64::from(k) * std::f64::consts::TAU / 16.0,
                ..DeadReckonedPose::default()
            };
            for _ in 0..3 {
                let pts = grid.scan_points(&pose, 0.0, &scan);
                grid.insert(&pts);
            }
        }
        grid
    }

    /// The controller for the default robot and pulse table.
    fn default_controller() -> Controller {
        Controller::new(
            ControllerConfig::default(),
            &RobotConfig::default(),
            &PulseTable::default(),
        )
    }

    fn input(pose: DeadReckonedPose, path: &[(f64, f64)]) -> ControlInput<'_> {
        ControlInput {
            pose,
            path,
            front_m: None,
            turn_rate_rad_s: 0.0,
        }
    }

    #[test]
    fn drives_ahead_along_a_straight_path_and_turns_toward_a_side_one() {
        let grid = open_grid();
        let mut c = default_controller();
        // Nothing seen ahead: no driving into it.
        let unseen = OccupancyGrid::new(GridConfig::default());
        let ahead = [(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)];
        assert!(
            c.step(&unseen, input(DeadReckonedPose::default(), &ahead))
                .blocked
        );
        let got = c.step(&grid, input(DeadReckonedPose::default(), &ahead));
        assert_eq!(got.command, MotionCommand::Forward);
        let left = [(0.0, 0.0), (0.0, 1.0)];
        let got = c.step(&grid, input(DeadReckonedPose::default(), &left));
        assert_eq!(got.command, MotionCommand::Left);
        // Still turning at 45 degrees, aligned at 88.
        let half = DeadReckonedPose {
            heading_rad: 45f64.to_radians(),
            ..DeadReckonedPose::default()
        };
        assert_eq!(
            c.step(&grid, input(half, &left)).command,
            MotionCommand::Left
        );
        let done = DeadReckonedPose {
            heading_rad: 88f64.to_radians(),
            ..DeadReckonedPose::default()
        };
        assert_eq!(
            c.step(&grid, input(done, &left)).command,
            MotionCommand::Forward
        );
        let right = [(0.0, 0.0), (0.0, -1.0)];
        let mut c = default_controller();
        assert_eq!(
            c.step(&grid, input(DeadReckonedPose::default(), &right))
                .command,
            MotionCommand::Right
        );
    }

    #[test]
    fn a_turn_with_the_front_too_near_to_see_backs_up_first_when_asked() {
        let grid = open_grid();
        let left = [(0.0, 0.0), (0.0, 1.0)];
        let mut blind = input(DeadReckonedPose::default(), &left);
        blind.front_m = Some(0.0);
        // Off (the default): the turn begins at once.
        let mut c = default_controller();
        assert_eq!(c.step(&grid, blind).command, MotionCommand::Left);
        let cfg = ControllerConfig {
            turn_front_min_m: 0.5,
            ..ControllerConfig::default()
        };
        let mut c = Controller::new(cfg, &RobotConfig::default(), &PulseTable::default());
        // On: back up while the front stays near, at most max_shifts frames, then turn.
        for _ in 0..cfg.max_shifts {
            assert_eq!(c.step(&grid, blind).command, MotionCommand::Reverse);
        }
        assert_eq!(c.step(&grid, blind).command, MotionCommand::Left);
        // A front seen far enough: no backing up.
        let mut c = Controller::new(cfg, &RobotConfig::default(), &PulseTable::default());
        let mut seen = blind;
        seen.front_m = Some(0.8);
        assert_eq!(c.step(&grid, seen).command, MotionCommand::Left);
        // Nothing known behind: no backing up either.
        let unseen = OccupancyGrid::new(GridConfig::default());
        let mut c = Controller::new(cfg, &RobotConfig::default(), &PulseTable::default());
        assert_ne!(c.step(&unseen, blind).command, MotionCommand::Reverse);
    }

    #[test]
    fn unknown_sides_ahead_need_a_far_front_range_and_walls_always_block() {
        // Only a narrow strip ahead seen free: the sides of the swept footprint are unknown
        // (the camera's blind zone right after a turn).
        let mut grid = OccupancyGrid::new(GridConfig::default());
        let narrow = ObstacleScan {
            tan_half_fov: 0.05,
            range_m: [3.0; hvs_shared::messages::SCAN_BINS],
            ..Default::default()
        };
        for _ in 0..3 {
            let pts = grid.scan_points(&DeadReckonedPose::default(), 0.0, &narrow);
            grid.insert(&pts);
        }
        let mut c = default_controller();
        let ahead = [(0.0, 0.0), (2.0, 0.0)];
        let mut i = input(DeadReckonedPose::default(), &ahead);
        // Nothing seen by the middle window: not enough.
        assert_eq!(c.step(&grid, i).command, MotionCommand::Stop);
        // The middle window sees 2 m: drive.
        i.front_m = Some(2.0);
        assert_eq!(c.step(&grid, i).command, MotionCommand::Forward);
        // A wall in the swept footprint blocks whatever the window says.
        for _ in 0..6 {
            grid.insert(&ScanPoints {
                camera: (0.0, 0.0),
                hits: vec![(0.3, 0.1)],
                rays: vec![],
            });
        }
        assert_eq!(c.step(&grid, i).command, MotionCommand::Stop);
    }

    #[test]
    fn a_wall_seen_in_the_turning_disc_mid_turn_stops_the_turn() {
        let mut grid = open_grid();
        let mut c = default_controller();
        let left = [(0.0, 0.0), (0.0, 1.0)];
        let start = DeadReckonedPose::default();
        assert_eq!(
            c.step(&grid, input(start, &left)).command,
            MotionCommand::Left
        );
        let half = DeadReckonedPose {
            heading_rad: 40f64.to_radians(),
            ..start
        };
        assert_eq!(
            c.step(&grid, input(half, &left)).command,
            MotionCommand::Left
        );
        // The turn brings a wall into view 0.28 m ahead-left of the centre: inside the disc
        // the corners sweep.
        grid.mark_bump(&half, (0.25, 0.25), (0.12, 0.12));
        assert_eq!(
            c.step(&grid, input(half, &left)).command,
            MotionCommand::Stop
        );
        // A turn begun boxed in (no shift left) is not stopped by what it already knew.
        let mut boxed = default_controller();
        boxed.shifts = boxed.cfg.max_shifts;
        assert_eq!(
            boxed.step(&grid, input(half, &left)).command,
            MotionCommand::Left
        );
        assert_eq!(
            boxed.step(&grid, input(half, &left)).command,
            MotionCommand::Left
        );
    }

    #[test]
    fn boxed_in_with_the_path_behind_it_backs_out_instead_of_turning() {
        let mut grid = open_grid();
        let pose = DeadReckonedPose::default();
        // A hallway narrower than the turning disc: walls 0.35 m either side, from 0.5 m
        // behind to 0.5 m ahead; the path goes back the way the robot came.
        grid.mark_bump(&pose, (-0.5, 0.5), (0.35, 0.35));
        grid.mark_bump(&pose, (-0.5, 0.5), (-0.35, -0.35));
        let back = [(0.0, 0.0), (-1.0, 0.0), (-2.0, 0.0)];
        let mut c = default_controller();
        c.shifts = c.cfg.max_shifts;
        assert_eq!(
            c.step(&grid, input(pose, &back)).command,
            MotionCommand::Reverse
        );
        // A wall behind too: it turns anyway, as before.
        grid.mark_bump(&pose, (-0.3, -0.3), (-0.2, 0.2));
        assert!(matches!(
            c.step(&grid, input(pose, &back)).command,
            MotionCommand::Left | MotionCommand::Right
        ));
        // The path to the side (not behind): no backing out.
        let mut grid = open_grid();
        grid.mark_bump(&pose, (-0.5, 0.5), (0.35, 0.35));
        grid.mark_bump(&pose, (-0.5, 0.5), (-0.35, -0.35));
        let mut c = default_controller();
        c.shifts = c.cfg.max_shifts;
        let side = [(0.0, 0.0), (0.3, 1.0)];
        assert_eq!(
            c.step(&grid, input(pose, &side)).command,
            MotionCommand::Left
        );
    }

    #[test]
    fn a_near_front_range_blocks_driving_ahead() {
        let grid = open_grid();
        let mut c = default_controller();
        let ahead = [(0.0, 0.0), (2.0, 0.0)];
        let mut i = input(DeadReckonedPose::default(), &ahead);
        i.front_m = Some(0.2);
        let got = c.step(&grid, i);
        assert_eq!(got.command, MotionCommand::Stop);
        assert!(got.blocked);
    }

    #[test]
    fn wrap_keeps_angles_in_the_half_open_interval() {
        use std::f64::consts::PI;
        assert!((wrap_rad(3.0 * PI) - PI).abs() < 1e-9);
        assert!((wrap_rad(-PI) - PI).abs() < 1e-9);
        assert!((wrap_rad(0.5) - 0.5).abs() < 1e-12);
    }
}
