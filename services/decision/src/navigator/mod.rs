//! The fuzzy navigator: smoothed wall memberships, turns executed by dead reckoning,
//! junction choices by the visit memory, the local map's openings and the wedge detectors.
//! `fuzzy.rs` holds the per-frame decision of the fuzzy policy, `openings.rs` the questions
//! it asks the local map (is a side open, where does an opening end, how far is the wall).

use super::*;
use crate::explore::CorrectionKind;

mod fuzzy;
mod openings;

/// The lateral band (metres left of the robot's centre line, low to high) where a side
/// opening must be free: `OPENING_LATERAL_M` on the left, mirrored on the right.
fn side_band(left: bool) -> (f64, f64) {
    if left {
        OPENING_LATERAL_M
    } else {
        (-OPENING_LATERAL_M.1, -OPENING_LATERAL_M.0)
    }
}

/// Heading change of a command's branch, radians (left = +90 degrees).
fn branch_heading(command: MotionCommand) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    match command {
        MotionCommand::Left => FRAC_PI_2,
        MotionCommand::Right => -FRAC_PI_2,
        MotionCommand::Reverse => PI,
        MotionCommand::Forward | MotionCommand::Stop => 0.0,
    }
}

/// What the navigator is doing.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Maneuver {
    /// Deciding frame by frame.
    Cruise,
    /// Turning in place until the dead-reckoned heading has changed by `target_rad`.
    Turning {
        command: MotionCommand,
        start_heading: f64,
        target_rad: f64,
        ramp: u32,
    },
    /// Driving ahead after a turn until `until_m` of odometry (no new branch before).
    Commit { until_m: f64 },
    /// Backing up until `until_m` of odometry: the view froze while the wheels turned
    /// (wedged against a wall), a corner is too close to turn, or the opening to turn into
    /// is behind.
    Backup { until_m: f64 },
    /// Creeping ahead until `until_m` of odometry, to the middle of the opening to turn into.
    Creep { until_m: f64 },
    /// Standing still until `until_ns` after a turn that ended facing a wall, so that the
    /// wheels stop, the walls can fix the heading and the windows show the new view before
    /// the next turn is chosen (`command`, `target_rad`: the turn that ended).
    Settle {
        until_ns: u64,
        command: MotionCommand,
        target_rad: f64,
    },
}

/// One decision of the [`Navigator`], with what it was based on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NavDecision {
    /// Smoothed wall memberships.
    pub memberships: Memberships,
    /// The intersection type.
    pub intersection: IntersectionType,
    /// The command.
    pub command: MotionCommand,
    /// Turn angle for turns, degrees.
    pub turn_angle_deg: f64,
    /// PSC ramp for the command.
    pub ramp: u32,
    /// The dead-reckoned pose.
    pub pose: DeadReckonedPose,
}

/// On the approach to a front wall (1.9 b to 3.1 b away), a side window whose nearest points
/// (its `near_m`) are closer than this share of the front's range sees a side wall running
/// on to the front wall; an open side shows nothing nearer than the junction's corner and
/// the far wall (measured in the simulator's junction maps: 0.49..0.80 with a wall,
/// 0.76..0.88 open, from 1.6 to 2.6 m).
pub(crate) const APPROACH_RATIO: f64 = 0.75;
/// Frames of an unchanged view while moving that mean the robot is wedged (about 1 s at
/// 15 Hz).
pub(crate) const STUCK_FRAMES: u32 = 15;
/// Dead-reckoned driving (metres) or turning (degrees) with an unchanged view that means
/// the robot is wedged, and the relative change of a window's range (at least
/// `WEDGE_CHANGE_M`) that counts as a changed view. Driving 0.5 m changes the front range
/// by at least 5 % up to 10 m; turning 30 degrees moves the view by more than half the
/// camera's field. Turning 30 degrees in front of a wall 0.45 m away changes its range by
/// only 0.07 m (1 / cos 30 - 1): with 0.1 m here a robot turning freely next to a wall was
/// taken for a wedged one and backed into a corner (2 of 6 collisions in 16 maze runs);
/// a pinned robot's view changes by the depth noise, under 0.01 m that close.
pub(crate) const WEDGE_DRIVE_M: f64 = 0.5;
pub(crate) const WEDGE_TURN_DEG: f64 = 30.0;
pub(crate) const WEDGE_CHANGE: f64 = 0.05;
pub(crate) const WEDGE_CHANGE_M: f64 = 0.03;

/// The relative change of a window's range (at least `STILL_CHANGE_M`) within which a
/// view counts as still for the `STUCK_FRAMES` test.
pub(crate) const STILL_CHANGE: f64 = 0.02;
pub(crate) const STILL_CHANGE_M: f64 = 0.002;

/// Whether a window's range appeared, vanished or changed by more than `rel` of its range
/// in `before` (at least `min_m`) between two views.
pub(crate) fn view_changed(
    before: &[Option<f64>],
    now: &[Option<f64>],
    rel: f64,
    min_m: f64,
) -> bool {
    before.iter().zip(now).any(|(a, b)| match (a, b) {
        (Some(a), Some(b)) => (a - b).abs() > (rel * a).max(min_m),
        (None, None) => false,
        _ => true,
    })
}

/// How far to back up when wedged, metres.
pub(crate) const BACKUP_M: f64 = 0.25;
/// A side window whose nearest points are nearer than this (a wall about 0.3 m to the side)
/// steers the robot away from that wall.
pub(crate) const CLEARANCE_NEAR_M: f64 = 0.6;
/// Membership above which a wall appears (and below `1 - ON` it disappears).
pub(crate) const WALL_ON: f64 = 0.6;
/// Scan points farther than this do not enter the local map or the heading fix, metres
/// (depth noise grows with the square of the range).
pub(crate) const MAP_RANGE_M: f64 = 3.0;
/// Segments that must agree on the walls' direction for a heading fix.
pub(crate) const HEADING_FIX_VOTES: usize = 12;
/// Largest heading error a fix corrects (a larger one is a wrong reading), radians.
pub(crate) const HEADING_FIX_MAX_RAD: f64 = 0.7;
/// No heading fix while turning faster than this (the scan is a frame old), rad/s.
pub(crate) const HEADING_FIX_MAX_TURN_RAD_S: f64 = 0.3;
/// The robot's footprint as the navigator uses it, derived from the one robot description
/// (`[robot]`, which the simulator's robot also uses). The margins were tuned on the
/// reference robot (0.311 x 0.438 m); another robot keeps them and moves each figure by its
/// difference in size, so the reference robot gets exactly the tuned values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    /// Half-width of the corridor the robot sweeps (its half-width plus a margin), metres.
    pub sweep_half_width_m: f64,
    /// The robot's front edge ahead of its turning centre, metres.
    pub front_edge_m: f64,
    /// Radius swept by the corners when turning in place (half-diagonal plus a margin), metres.
    pub turn_radius_m: f64,
    /// Shortest side opening the robot turns into (its width plus margins), metres.
    pub opening_min_m: f64,
}

impl Footprint {
    /// The reference robot's size, on which the margins were tuned.
    const REFERENCE: RobotConfig = RobotConfig {
        width_m: 0.311,
        length_m: 0.438,
        track_m: 0.55,
        forward_speed_mps: 0.274,
        motor_tau_s: 0.1,
    };

    /// The footprint of a robot.
    pub fn of(robot: &RobotConfig) -> Self {
        let r = Self::REFERENCE;
        Self {
            sweep_half_width_m: 0.2 + 0.5 * (robot.width_m - r.width_m),
            front_edge_m: 0.22 + 0.5 * (robot.length_m - r.length_m),
            turn_radius_m: 0.3 + (robot.half_diagonal_m() - r.half_diagonal_m()),
            opening_min_m: 0.6 + (robot.width_m - r.width_m),
        }
    }
}

/// How far one shift moves the robot along its way to clear its turning circle, metres.
pub(crate) const TURN_SHIFT_M: f64 = 0.1;
/// Shifts tried before a turn starts anyway.
pub(crate) const MAX_TURN_SHIFTS: u32 = 3;
/// The robot turns into an opening when its centre is this close to the opening's middle.
pub(crate) const LINE_UP_TOLERANCE_M: f64 = 0.1;
/// How near the front wall (from the robot's front edge) the robot turns into a side
/// opening the local map has not seen: its centre then 0.67 m from the wall, so that the
/// 0.4 m it sweeps (0.47..0.87 m from the wall) fits both a 1.05 m opening flush with the
/// wall (0..1.05 m) and one that leaves 0.35 m of wall before it (0.35..1.4 m), and its
/// turning circle (0.3 m) is clear of the wall. (0.52 m, the flush opening's middle, put
/// the robot against the far corner of the second kind; 0.6 m grazed a corner from the
/// maze's start pose.)
pub(crate) const CORNER_TURN_CLEARANCE_M: f64 = 0.45;
/// A wall ahead at most this far from the robot's centre ends a side opening that runs
/// on to it unseen (`corner_opening_end`), metres.
pub(crate) const CORNER_REACH_M: f64 = 1.25;
/// Lateral extent of the region that must be free beside the robot for a side opening.
pub(crate) const OPENING_LATERAL_M: (f64, f64) = (0.35, 1.0);

/// Odometry distance (driving or turning) between two heading corrections, metres.
pub(crate) const CORRECTION_SPACING_M: f64 = 0.25;

/// Sent while turning: stop this many seconds of turn early (the command takes about this
/// long to reach the wheels: one decision period plus two PSC commands on a 2400 baud wire).
pub(crate) const TURN_LEAD_S: f64 = 0.1;

/// How long the robot stands still after a turn that ended facing a wall, nanoseconds.
pub(crate) const SETTLE_NS: u64 = 400_000_000;

/// The stateful decision maker of the decision stage.
#[derive(Debug, Clone)]
pub struct Navigator {
    cfg: DecisionConfig,
    smoothed: Option<Memberships>,
    walls: Walls,
    current: MotionCommand,
    pending: Option<(MotionCommand, u32)>,
    maneuver: Maneuver,
    odometry: Odometry,
    grid: VisitGrid,
    /// Side memberships seen on the approach to the front wall.
    approach: Option<Memberships>,
    /// The front was nearer than 2 b on the last frame that saw it.
    front_was_near: bool,
    /// Turns tried at the current junction after the first one met a wall.
    attempts: u32,
    /// The three ranges a still run began with, and how many frames in a row they stayed
    /// within `STILL_CHANGE` of them while the robot was commanded to move.
    last_view: [Option<f64>; 3],
    frozen_frames: u32,
    /// The view when it last changed, with the odometry distance and heading then.
    view_anchor: Option<([Option<f64>; 3], f64, f64)>,
    /// Frames in a row with no range in any window.
    blind_frames: u32,
    /// Dead-reckoned turning (radians) while no window has seen anything, and the heading
    /// of the last frame.
    blind_turn_rad: f64,
    last_heading_rad: f64,
    /// What the obstacle scans showed around the robot.
    map: LocalMap,
    /// The last `front_clearance_m` answer and the pose it was for. The junction
    /// classification, the side-branch look and the line-up each ask for it (through
    /// `opening_offset`), up to five times a frame, and neither the map nor the clock changes
    /// in between; it is forgotten when a frame begins.
    front_clearance: Cell<Option<(DeadReckonedPose, Option<f64>)>>,
    /// The camera's distance ahead of the turning centre, metres.
    camera_forward_m: f64,
    /// Time of the decision being made.
    now_ns: u64,
    /// Odometry distance before which no new heading correction starts (each one must be
    /// followed by some driving, or the quantised turns dither in place).
    next_correction_m: f64,
    /// Shifts along the way made to clear the turning circle for the turn about to start.
    turn_shifts: u32,
    /// The robot's footprint.
    footprint: Footprint,
    /// The exploring navigator (`policy = "explore"`).
    explorer: Option<Box<crate::explore::Explorer>>,
}

impl Navigator {
    /// A navigator for a decision config, the robot's body (`[robot]`: footprint and dead
    /// reckoning) and its pulse table.
    pub fn new(cfg: &DecisionConfig, robot: &RobotConfig, pulses: &PulseTable) -> Self {
        Self {
            cfg: cfg.clone(),
            footprint: Footprint::of(robot),
            smoothed: None,
            walls: Walls {
                left: false,
                front: false,
                right: false,
            },
            current: MotionCommand::Stop,
            pending: None,
            maneuver: Maneuver::Cruise,
            odometry: Odometry::new(*robot, pulses),
            grid: VisitGrid::new(cfg.visit_cell_m),
            approach: None,
            front_was_near: false,
            attempts: 0,
            last_view: [None; 3],
            frozen_frames: 0,
            view_anchor: None,
            blind_frames: 0,
            blind_turn_rad: 0.0,
            last_heading_rad: 0.0,
            map: LocalMap::new(cfg.local_map_cell_m, cfg.local_map_age_s),
            front_clearance: Cell::new(None),
            camera_forward_m: 0.2,
            now_ns: 0,
            next_correction_m: 0.0,
            turn_shifts: 0,
            explorer: (cfg.policy == DecisionPolicy::Explore).then(|| {
                Box::new(crate::explore::Explorer::new(
                    NavConfig::default(),
                    robot,
                    pulses,
                    0.2,
                ))
            }),
        }
    }

    /// Sets the exploring navigator's settings (`[nav]`; used by `policy = "explore"`).
    pub fn with_nav(mut self, nav: &NavConfig, robot: &RobotConfig, pulses: &PulseTable) -> Self {
        if let Some(old) = &self.explorer {
            let first_bin = old.grid().first_bin();
            self.odometry = Odometry::new(*robot, pulses).with_calibration(nav.calibration);
            let mut e = crate::explore::Explorer::new(*nav, robot, pulses, self.camera_forward_m);
            e.set_first_bin(first_bin);
            self.explorer = Some(Box::new(e));
        }
        self
    }

    /// Tells the exploring navigator the 320x240 matcher's largest disparity (the scan's
    /// leftmost columns within it of the image edge are not trusted).
    pub fn with_matcher_reach(mut self, max_disp: u32, width_px: u32) -> Self {
        if let Some(e) = self.explorer.as_mut() {
            e.set_matcher_reach(max_disp, width_px);
        }
        self
    }

    /// The exploring navigator, when the policy is `explore`.
    pub fn explorer(&self) -> Option<&crate::explore::Explorer> {
        self.explorer.as_deref()
    }

    /// Sets where the camera sits: `forward_m` ahead of the turning centre (default 0.2 m).
    pub fn with_camera_forward_m(mut self, forward_m: f64) -> Self {
        self.camera_forward_m = forward_m;
        if let Some(e) = self.explorer.as_mut() {
            e.set_camera_forward_m(forward_m);
        }
        self
    }

    /// The local occupancy map (left empty under `policy = "explore"`, which maps into
    /// its own grid: [`Navigator::explorer`]).
    pub fn local_map(&self) -> &LocalMap {
        &self.map
    }

    /// A one-line account of the navigator's state, for traces: the maneuver, the openings
    /// the local map shows beside the robot (offset along its way, m) and the side walls'
    /// distances.
    pub fn describe(&self) -> String {
        let pose = self.odometry.pose();
        let fmt = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}"));
        if let Some(e) = &self.explorer {
            let s = e.status();
            return format!(
                "explore goal {} plans {} frontiers {} blacklisted {} recoveries {} fixes {} ({} position) stalls {} tight {}{}{}{}{}{}{}",
                e.goal_m()
                    .map_or("-".to_string(), |g| format!("({:.2},{:.2})", g.0, g.1)),
                s.plans,
                s.frontiers,
                s.blacklisted,
                s.recoveries,
                s.scan_fixes,
                s.position_fixes,
                s.stalls,
                s.tight_plans,
                if s.reacquired > 0 {
                    format!(" reacquired {}", s.reacquired)
                } else {
                    String::new()
                },
                if s.redraws > 0 {
                    format!(" redrawn {}", s.redraws)
                } else {
                    String::new()
                },
                if s.forgets > 0 {
                    format!(" forgot {}", s.forgets)
                } else {
                    String::new()
                },
                if e.recovering() { " recovering" } else { "" },
                if s.done { " done" } else { "" },
                self.odometry
                    .calibration()
                    .map_or(String::new(), |c| format!(
                        " calibrated {:.3} {:.3}",
                        c.loss_share(),
                        c.drift_rad_per_m()
                    )),
            );
        }
        format!(
            "{:?} open L {} R {} seen {}{} wall L {} R {}",
            self.maneuver,
            fmt(self.opening_offset(&pose, true)),
            fmt(self.opening_offset(&pose, false)),
            u8::from(self.side_seen(&pose, true)),
            u8::from(self.side_seen(&pose, false)),
            fmt(self
                .map
                .side_distance(&pose, true, (-0.2, 0.3), 0.9, self.now_ns)),
            fmt(self
                .map
                .side_distance(&pose, false, (-0.2, 0.3), 0.9, self.now_ns)),
        )
    }

    /// The actuator put a command on the wire (feeds dead reckoning).
    pub fn on_sent(&mut self, sent_ns: u64, left_pw: u16, right_pw: u16, ramp: u8) {
        self.odometry.on_sent(sent_ns, left_pw, right_pw, ramp);
    }

    /// The visit grid.
    pub fn visits(&self) -> &VisitGrid {
        &self.grid
    }

    /// The dead-reckoned pose now.
    pub fn pose(&self) -> DeadReckonedPose {
        self.odometry.pose()
    }

    /// Distance driven by dead reckoning, metres.
    pub fn distance_m(&self) -> f64 {
        self.odometry.distance_m()
    }

    /// The state of a point of the pose frame in the map the policy navigates by: the
    /// explorer's occupancy grid, or the local map of the other policies.
    pub fn map_state(&self, x_m: f64, y_m: f64, now_ns: u64) -> crate::local_map::CellState {
        match &self.explorer {
            Some(e) => e.grid().state_at(x_m, y_m),
            None => self.map.state(x_m, y_m, now_ns),
        }
    }

    /// Decides from one range report's windows and obstacle scan at `now_ns` (a scan with no
    /// data leaves the local map as it is).
    pub fn decide(
        &mut self,
        windows: &[RangeWindow],
        window_count: usize,
        scan: &ObstacleScan,
        now_ns: u64,
    ) -> NavDecision {
        self.odometry.advance_to(now_ns);
        self.now_ns = now_ns;
        self.front_clearance.set(None);
        // The walls fix the heading only while the front window sees something: facing a
        // wall closer than the matcher's shortest range, the few points left are noise
        // (measured: a 19 degree wrong fix while standing at a dead end's wall).
        let sides = SideRanges::from_windows(windows, window_count);
        // The heading can be fixed this frame: the front seen, not turning fast (the turn
        // rate is the wheels', which no fix below changes).
        let settled = sides.middle_m.is_some()
            && self.odometry.turn_rate_rad_s().abs() < HEADING_FIX_MAX_TURN_RAD_S;
        if (self.cfg.local_map || self.explorer.is_some())
            && self.cfg.heading_fix_gain > 0.0
            && self.cfg.snap_turn_deg == 90.0
            && settled
            && let Some(a) = wall_direction(scan, MAP_RANGE_M, HEADING_FIX_VOTES)
        {
            // The walls run at a (mod 90 degrees) in the robot's frame: the heading is -a
            // (mod 90 degrees) on the building's axes.
            let q = std::f64::consts::FRAC_PI_2;
            let heading = self.odometry.pose().heading_rad;
            let error = (-a - heading + 0.5 * q).rem_euclid(q) - 0.5 * q;
            if error.abs() < HEADING_FIX_MAX_RAD {
                let fix = self.cfg.heading_fix_gain * error;
                self.odometry.fix_heading(fix);
                if let Some(e) = self.explorer.as_mut() {
                    e.corrected(0.0, 0.0, fix);
                }
            }
        }
        if let Some(e) = self.explorer.as_mut()
            && let Some(fix) = e.correction(
                &self.odometry.pose(),
                scan,
                self.odometry.turn_rate_rad_s(),
                now_ns,
            )
        {
            self.odometry.correct_position(fix.dx_m, fix.dy_m);
            match fix.kind {
                CorrectionKind::Aligned => self.odometry.fix_heading(fix.dheading_rad),
                CorrectionKind::PutBack => self.odometry.correct_heading(fix.dheading_rad),
            }
        }
        self.odometry.end_frame(settled);
        let pose = self.odometry.pose();
        // The exploring navigator keeps its own grid: the local map is the other policies'
        // (filling it cost a tenth of a millisecond a frame for nothing).
        if self.cfg.fills_local_map() && scan.valid_bins() > 0 {
            self.map
                .insert_scan(&pose, self.camera_forward_m, scan, MAP_RANGE_M, now_ns);
        }
        self.grid.record(pose.x_m, pose.y_m);
        let idx = SideRanges::indices(window_count);
        let picked = idx.map(|i| windows.get(i));
        let raw = fuzzy_memberships(&sides, &self.cfg);
        let (policy, lo) = (self.cfg.policy, self.cfg.lo);
        match policy {
            DecisionPolicy::Reference => {
                let c = reference_decision(&sides, &lo);
                self.current = c.command;
                NavDecision {
                    memberships: Memberships {
                        left: f64::from(u8::from(c.walls.left)),
                        front: f64::from(u8::from(c.walls.front)),
                        right: f64::from(u8::from(c.walls.right)),
                    },
                    intersection: c.intersection,
                    command: c.command,
                    turn_angle_deg: c.turn_angle_deg,
                    ramp: c.ramp,
                    pose,
                }
            }
            DecisionPolicy::MeanEstimation | DecisionPolicy::ThresholdEstimation => {
                let proposal = if policy == DecisionPolicy::MeanEstimation {
                    mean_estimation(picked)
                } else {
                    threshold_estimation(picked, lo.front_m)
                };
                let walls = crisp_walls(&sides, &lo);
                let command = self.hold(proposal);
                let (turn_angle_deg, ramp) = reference_turn(&sides, command);
                NavDecision {
                    memberships: raw,
                    intersection: classify(walls),
                    command,
                    turn_angle_deg,
                    ramp,
                    pose,
                }
            }
            DecisionPolicy::Explore => {
                let walls = crisp_walls(&sides, &lo);
                let intersection = classify(walls);
                let input = crate::explore::ExploreInput {
                    pose,
                    scan,
                    front_m: sides.middle_m,
                    turn_rate_rad_s: self.odometry.turn_rate_rad_s(),
                    distance_m: self.odometry.distance_m(),
                    intersection,
                    now_ns,
                };
                let (command, ramp) = match self.explorer.as_mut() {
                    Some(e) => e.step(input),
                    None => (MotionCommand::Stop, 0),
                };
                self.current = command;
                NavDecision {
                    memberships: raw,
                    intersection,
                    command,
                    turn_angle_deg: 0.0,
                    ramp,
                    pose,
                }
            }
            DecisionPolicy::Fuzzy => {
                let near = picked.map(|w| {
                    w.filter(|w| w.valid_px > 0 && w.near_m > 0.0)
                        .map(|w| w.near_m as f64)
                });
                self.fuzzy(&sides, near, raw, pose)
            }
        }
    }

    /// The command filter: a new command must be proposed `hold_frames` times in a row.
    /// (A blocked front does not go through it: the fuzzy policy turns at once.)
    pub(super) fn hold(&mut self, proposal: MotionCommand) -> MotionCommand {
        if proposal == self.current || self.cfg.hold_frames <= 1 {
            self.current = proposal;
            self.pending = None;
            return proposal;
        }
        let count = match self.pending {
            Some((c, n)) if c == proposal => n + 1,
            _ => 1,
        };
        if count >= self.cfg.hold_frames {
            self.current = proposal;
            self.pending = None;
        } else {
            self.pending = Some((proposal, count));
        }
        self.current
    }

    /// Starts a turn in place of `target_rad` and returns the command to send now. The circle
    /// the robot's corners sweep must be clear of what the local map holds: with an obstacle
    /// inside it the robot first moves `TURN_SHIFT_M` along its way, away from it (back from
    /// one ahead of its centre, forward from one beside or behind it when the way ahead is
    /// clear), and the turn is decided again after the shift; after `MAX_TURN_SHIFTS` shifts
    /// it turns anyway.
    pub(super) fn start_turn(
        &mut self,
        pose: &DeadReckonedPose,
        command: MotionCommand,
        target_rad: f64,
    ) -> MotionCommand {
        self.pending = None;
        if self.turn_shifts < MAX_TURN_SHIFTS
            && let Some((ahead_m, _)) =
                self.map
                    .nearest_occupied(pose, self.footprint.turn_radius_m, self.now_ns)
        {
            self.turn_shifts += 1;
            let ahead_clear = self
                .map
                .count_region(
                    pose,
                    (
                        self.footprint.front_edge_m,
                        self.footprint.front_edge_m + TURN_SHIFT_M + 0.05,
                    ),
                    (
                        -self.footprint.sweep_half_width_m,
                        self.footprint.sweep_half_width_m,
                    ),
                    self.now_ns,
                )
                .occupied
                == 0;
            let until_m = self.odometry.distance_m() + TURN_SHIFT_M;
            let (maneuver, shift) = if ahead_m <= 0.0 && ahead_clear {
                (Maneuver::Creep { until_m }, MotionCommand::Forward)
            } else {
                (Maneuver::Backup { until_m }, MotionCommand::Reverse)
            };
            self.maneuver = maneuver;
            self.current = shift;
            return shift;
        }
        self.turn_shifts = 0;
        self.begin_turning(pose, command, target_rad);
        command
    }

    /// Drives ahead after a turn for `commit_m` (no new branch before) and returns the command.
    pub(super) fn commit(&mut self) -> MotionCommand {
        self.maneuver = Maneuver::Commit {
            until_m: self.odometry.distance_m() + self.cfg.commit_m,
        };
        self.current = MotionCommand::Forward;
        self.pending = None;
        MotionCommand::Forward
    }

    /// Puts the navigator into a turn (no checks).
    pub(super) fn begin_turning(
        &mut self,
        pose: &DeadReckonedPose,
        command: MotionCommand,
        target_rad: f64,
    ) {
        self.pending = None;
        // The wedge detector measures a turn from its start: heading changed in earlier
        // maneuvers facing the same wall took a robot 13 degrees into a turn for a wedged one.
        self.view_anchor = None;
        self.current = command;
        self.maneuver = Maneuver::Turning {
            command,
            start_heading: pose.heading_rad,
            target_rad,
            ramp: 0,
        };
    }

    /// How far to turn, radians: with `snap_turn_deg` > 0 to the next multiple of it (indoor
    /// hallways meet at right angles, and dead reckoning keeps the heading on the axis);
    /// otherwise the reference angle, at least `min_turn_deg`.
    pub(super) fn turn_target(
        &self,
        pose: DeadReckonedPose,
        command: MotionCommand,
        reference_deg: f64,
    ) -> f64 {
        let snap = self.cfg.snap_turn_deg.to_radians();
        if snap > 0.0 {
            let sign = if command == MotionCommand::Left {
                1.0
            } else {
                -1.0
            };
            let goal = ((pose.heading_rad + sign * snap) / snap).round() * snap;
            (goal - pose.heading_rad).abs().max(0.5 * snap)
        } else {
            reference_deg
                .max(self.cfg.min_turn_deg)
                .min(90.0)
                .to_radians()
        }
    }
}
