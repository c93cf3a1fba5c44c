//! The exploring navigator (`decision.policy = "explore"`), in Nav2's layers:
//!
//! ```text
//!  obstacle scan ──► scan_match ──► grid (log-odds, dead-reckoned frame, drift-corrected)
//!                                     │
//!                                     ▼
//!                                  costmap (inflated by the footprint)
//!                                     │
//!                         planner (Dijkstra from the robot)
//!                           │                    │
//!                           ▼                    ▼
//!                  frontier (choose goal,    path to the goal
//!                   blacklist)                   │
//!                                                ▼
//!                   recovery ◄── progress ── controller ──► motion command
//! ```
//!
//! Beside them, `stall` puts back a pose the picture says never moved, and `redraw` re-draws
//! the grid from corrected poses after a heading lost in a blind turn is found.
//!
//! Each layer is its own file and its own piece of `[nav]`; this file only sequences them per
//! frame. The wall memberships and intersection types are still computed by the navigator
//! (perception); a change of intersection type makes the explorer plan again at once.

pub mod controller;
pub mod costmap;
pub mod frontier;
pub mod grid;
pub mod planner;
pub mod recovery;
pub mod redraw;
pub mod scan_match;
pub mod stall;

use hvs_runtime::config::{CostmapConfig, NavConfig, PulseTable, RobotConfig};
use hvs_shared::messages::{IntersectionType, MotionCommand, ObstacleScan, SCAN_BINS};

use crate::local_map::CellState;
use crate::odometry::DeadReckonedPose;
use controller::{ControlInput, Controller, wrap_rad};
use costmap::Costmap;
use frontier::{Blacklist, choose, find_frontiers, frontier_cells};
use grid::OccupancyGrid;
use planner::CostField;
use recovery::{ProgressChecker, Recovery, RecoveryInput};
use redraw::{BlindArc, GridEdit, RedrawLog, RedrawStep};
pub use scan_match::{CorrectionKind, PoseCorrection};
use stall::StallCheck;

/// The goal being driven to and the path there.
#[derive(Debug, Clone)]
struct Plan {
    goal_m: (f64, f64),
    /// The frontier's centre, looked at from within `view_m`.
    look_at_m: (f64, f64),
    path: Vec<(f64, f64)>,
}

/// A chosen frontier, its goal cell's centre and the path there (grid frame, metres).
type Chosen = (frontier::Frontier, (f64, f64), Vec<(f64, f64)>);

/// What one frontier search found.
struct Search {
    /// Frontier clusters found.
    frontiers: usize,
    /// The frontier chosen, if any.
    chosen: Option<Chosen>,
}

/// Counters for the status line and the tests.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ExploreStatus {
    /// Plans made.
    pub plans: u64,
    /// Frontier clusters found by the last plan.
    pub frontiers: usize,
    /// Goals given up on.
    pub blacklisted: usize,
    /// Recoveries run.
    pub recoveries: u64,
    /// Scans that corrected the pose.
    pub scan_fixes: u64,
    /// Scans whose point-to-wall alignment corrected the position.
    pub position_fixes: u64,
    /// Stalls found (the picture unchanged while dead reckoning moved).
    pub stalls: u64,
    /// Headings re-found over the arc turned while the scan could not be aligned
    /// (`[nav.scan_match] reacquire_turn_deg`).
    pub reacquired: u64,
    /// Grids re-drawn after a blind turn's heading was corrected (`[nav.redraw]`).
    pub redraws: u64,
    /// Plans that found a frontier only with `[nav.costmap] fallback_clearance_m`.
    pub tight_plans: u64,
    /// Times the grid around the robot was forgotten (`[nav.recovery] clear_radius_m`).
    pub forgets: u64,
    /// No reachable frontier is left.
    pub done: bool,
}

/// What the explorer sees this frame.
#[derive(Debug, Clone, Copy)]
pub struct ExploreInput<'a> {
    /// The pose (after the scan's correction).
    pub pose: DeadReckonedPose,
    /// The obstacle scan.
    pub scan: &'a ObstacleScan,
    /// The middle window's range, metres.
    pub front_m: Option<f64>,
    /// Turn rate, rad/s.
    pub turn_rate_rad_s: f64,
    /// Odometry distance, metres.
    pub distance_m: f64,
    /// The intersection type perceived this frame.
    pub intersection: IntersectionType,
    /// Now.
    pub now_ns: u64,
}

/// The last range the middle window read, and the pose it was read from: a wall the robot
/// drives up to leaves the matcher's range (the camera is blind closer than `max_disp`'s
/// depth), and the dead-reckoned distance driven since says how near it now is.
#[derive(Debug, Clone, Copy)]
struct FrontMemory {
    range_m: f64,
    pose: DeadReckonedPose,
}

impl FrontMemory {
    /// The front range now: this frame's, or the remembered one less the way driven
    /// toward it while facing the same way, within `stale_turn_rad` (`None`: nothing known).
    fn front_m(
        memory: &mut Option<Self>,
        seen_m: Option<f64>,
        pose: &DeadReckonedPose,
        stale_turn_rad: f64,
    ) -> Option<f64> {
        if let Some(m) = seen_m {
            *memory = Some(Self {
                range_m: m,
                pose: *pose,
            });
            return Some(m);
        }
        let m = (*memory)?;
        if wrap_rad(pose.heading_rad - m.pose.heading_rad).abs() > stale_turn_rad {
            *memory = None;
            return None;
        }
        let (s, c) = m.pose.heading_rad.sin_cos();
        let driven = (pose.x_m - m.pose.x_m) * c + (pose.y_m - m.pose.y_m) * s;
        Some((m.range_m - driven).max(0.0))
    }
}

/// Whether the picture says a wall nearer than the matcher's shortest range (or one without
/// texture) fills it: nothing in view, or more of the middle third's bins scattered
/// ([`hvs_shared::messages::SCAN_SCATTERED`]) than ranged; "nothing": fewer than `min_bins`
/// valid bins.
/// Seconds from `since_ns` to `now_ns` (0 when `now_ns` is earlier), both CLOCK_MONOTONIC ns.
pub(crate) fn elapsed_s(since_ns: u64, now_ns: u64) -> f64 {
    now_ns.saturating_sub(since_ns) as f64 * 1e-9
}

fn blind(scan: &ObstacleScan, min_bins: u32) -> bool {
    let (valid, scattered) = scan.valid_and_scattered(SCAN_BINS / 3..2 * SCAN_BINS / 3);
    scan.valid_bins() < min_bins as usize || scattered > valid
}

/// The exploring navigator's state.
#[derive(Debug, Clone)]
pub struct Explorer {
    cfg: NavConfig,
    grid: OccupancyGrid,
    controller: Controller,
    camera_forward_m: f64,
    blacklist: Blacklist,
    /// Frontiers turned to from within `view_m` that were still frontiers afterwards:
    /// they are driven to next, not looked at again.
    looked: Blacklist,
    plan: Option<Plan>,
    last_plan_ns: Option<u64>,
    replan_now: bool,
    /// The last search found no frontier with the usual clearance: the next one (next
    /// frame, one search a frame) keeps only `[nav.costmap] fallback_clearance_m`.
    search_tight: bool,
    /// Since when searches with the usual clearance have found no frontier (`None`: the
    /// last one found one).
    closed_since_ns: Option<u64>,
    /// Since when no search, with either clearance, has found a frontier (None: the last
    /// one did).
    unreachable_since_ns: Option<u64>,
    progress: ProgressChecker,
    recovery: Option<Recovery>,
    recoveries_for_goal: u32,
    last_intersection: IntersectionType,
    /// When the blacklist was last cleared because exploration looked finished.
    last_retry_ns: Option<u64>,
    /// The first frame has been seen (the start spin begun).
    started: bool,
    /// The middle window's last range.
    front: Option<FrontMemory>,
    /// The picture against dead reckoning.
    stall: StallCheck,
    /// Where the last turn in place stalled.
    last_turn_stall_m: Option<(f64, f64)>,
    /// A stall was found this frame: recover before anything else.
    stalled: bool,
    /// Dead reckoning's heading at the last frame and the turn it made since the scan last
    /// had points enough to align (`None`: this frame's scan had).
    unaligned: Option<BlindArc>,
    /// The grid's edits since a blind turn began, to re-draw if its heading is corrected.
    redraw: Option<RedrawLog>,
    /// A grid's memory to take the next log's copy in (`None` with re-drawing off).
    spare: Option<OccupancyGrid>,
    /// The last command sent.
    last_command: MotionCommand,
    status: ExploreStatus,
}

impl Explorer {
    /// An explorer with nothing seen yet.
    pub fn new(
        cfg: NavConfig,
        robot: &RobotConfig,
        pulses: &PulseTable,
        camera_forward_m: f64,
    ) -> Self {
        let grid = OccupancyGrid::new(cfg.grid);
        // Written through once here, so that the first copy into it touches no fresh page.
        let spare = (cfg.redraw.blind_turn_deg > 0.0).then(|| {
            let mut spare = OccupancyGrid::new(cfg.grid);
            spare.fault_in();
            spare
        });
        Self {
            cfg,
            grid,
            controller: Controller::new(cfg.controller, robot, pulses),
            camera_forward_m,
            blacklist: Blacklist::default(),
            looked: Blacklist::default(),
            plan: None,
            last_plan_ns: None,
            replan_now: true,
            search_tight: false,
            closed_since_ns: None,
            unreachable_since_ns: None,
            progress: ProgressChecker::default(),
            recovery: None,
            recoveries_for_goal: 0,
            last_intersection: IntersectionType::Unknown,
            last_retry_ns: None,
            started: false,
            front: None,
            stall: StallCheck::new(cfg.stall),
            last_turn_stall_m: None,
            stalled: false,
            unaligned: None,
            redraw: None,
            spare,
            last_command: MotionCommand::Stop,
            status: ExploreStatus::default(),
        }
    }

    /// Sets where the camera sits ahead of the turning centre, metres.
    pub fn set_camera_forward_m(&mut self, forward_m: f64) {
        self.camera_forward_m = forward_m;
    }

    /// Leaves out the scan bins whose columns lie within the matcher's largest disparity
    /// of the left image's edge (`max_disp` of an image `width_px` wide).
    pub fn set_matcher_reach(&mut self, max_disp: u32, width_px: u32) {
        let bins = (f64::from(max_disp) * SCAN_BINS as f64 / f64::from(width_px.max(1))).ceil();
        self.grid.set_first_bin(bins as usize);
    }

    /// Leaves out the scan's leftmost `bin` bins (see [`OccupancyGrid::set_first_bin`]).
    pub fn set_first_bin(&mut self, bin: usize) {
        self.grid.set_first_bin(bin);
    }

    /// The occupancy grid.
    pub fn grid(&self) -> &OccupancyGrid {
        &self.grid
    }

    /// Counters.
    pub fn status(&self) -> ExploreStatus {
        ExploreStatus {
            blacklisted: self.blacklist.len(),
            ..self.status
        }
    }

    /// The goal being driven to, grid frame, metres.
    pub fn goal_m(&self) -> Option<(f64, f64)> {
        self.plan.as_ref().map(|p| p.goal_m)
    }

    /// Whether a recovery behaviour is running.
    pub fn recovering(&self) -> bool {
        self.recovery.is_some()
    }

    /// The correction that aligns `scan` seen from `pose` to the grid, already scaled by the
    /// configured gain (apply it to the odometry before [`Explorer::step`]).
    pub fn correction(
        &mut self,
        pose: &DeadReckonedPose,
        scan: &ObstacleScan,
        turn_rate_rad_s: f64,
        now_ns: u64,
    ) -> Option<PoseCorrection> {
        if let Some(back) = self.stall.update(scan, pose) {
            // Pinned: what dead reckoning integrated since the picture last changed never
            // happened.
            self.stalled = true;
            self.status.stalls += 1;
            return Some(PoseCorrection {
                dx_m: back.x_m - pose.x_m,
                dy_m: back.y_m - pose.y_m,
                dheading_rad: back.heading_rad - pose.heading_rad,
                overlap: 0.0,
                kind: CorrectionKind::PutBack,
            });
        }
        // With the heading search or the re-drawing after blind turns on, every scan counts
        // toward the arc; otherwise the points are wanted only past the checks below.
        let reacquiring = self.cfg.scan_match.reacquire_turn_deg > 0.0;
        let early = (reacquiring || self.cfg.redraw.blind_turn_deg > 0.0)
            .then(|| self.grid.scan_hits_robot_frame(scan, self.camera_forward_m));
        if let Some(points) = &early {
            let alignable = points.len() >= self.cfg.scan_match.min_points as usize;
            if reacquiring {
                self.track_unaligned(pose, alignable);
            }
            if let Some(fix) = self.redraw_step(pose, alignable, now_ns) {
                return Some(fix);
            }
        }
        // Early scans would be aligned to themselves; a scan taken while turning fast is
        // placed by a heading that leads the camera's, and is not added to the grid either.
        if self.status.plans < 3 || !self.scan_placeable(turn_rate_rad_s) {
            return None;
        }
        let points =
            early.unwrap_or_else(|| self.grid.scan_hits_robot_frame(scan, self.camera_forward_m));
        if let Some(fix) = self.reacquire(pose, &points) {
            return Some(fix);
        }
        let cfg = &self.cfg.scan_match;
        let g = cfg.gain;
        let searched =
            scan_match::align(&self.grid, pose, &points, cfg).map(|fix| PoseCorrection {
                dx_m: g * fix.dx_m,
                dy_m: g * fix.dy_m,
                dheading_rad: g * fix.dheading_rad,
                overlap: fix.overlap,
                kind: CorrectionKind::Aligned,
            });
        // The position is refined from where the search put the pose.
        let mut fix = searched.unwrap_or_default();
        let searched_pose = DeadReckonedPose {
            x_m: pose.x_m + fix.dx_m,
            y_m: pose.y_m + fix.dy_m,
            heading_rad: pose.heading_rad + fix.dheading_rad,
        };
        let refined = scan_match::refine_position(&self.grid, &searched_pose, &points, cfg);
        if let Some(r) = refined {
            fix.dx_m += r.dx_m;
            fix.dy_m += r.dy_m;
            self.status.position_fixes += 1;
        }
        if searched.is_none() && refined.is_none() {
            return None;
        }
        self.status.scan_fixes += 1;
        self.stall.shift(fix.dx_m, fix.dy_m, fix.dheading_rad);
        if let Some(log) = self.redraw.as_mut() {
            log.corrected(fix.dheading_rad);
        }
        Some(fix)
    }

    /// Opens, steps or closes the log of the grid's edits since a blind turn (`[nav.redraw]`;
    /// `alignable` whether this frame's scan has `min_points` points); once it is re-drawn
    /// the copy becomes the grid and the position correction that goes with it is returned.
    fn redraw_step(
        &mut self,
        pose: &DeadReckonedPose,
        alignable: bool,
        now_ns: u64,
    ) -> Option<PoseCorrection> {
        if self.cfg.redraw.blind_turn_deg <= 0.0 {
            return None;
        }
        let Some(log) = self.redraw.as_mut() else {
            if !alignable {
                let spare = self.spare.take();
                let log = RedrawLog::open(self.cfg.redraw, &self.grid, spare, pose, now_ns);
                self.redraw = Some(log);
            }
            return None;
        };
        match log.step(pose, alignable, now_ns) {
            RedrawStep::Keep => None,
            RedrawStep::Drop => {
                self.spare = self.redraw.take().map(RedrawLog::into_grid);
                None
            }
            RedrawStep::Done {
                dx_m,
                dy_m,
                dheading_rad,
            } => {
                let redrawn = self.redraw.take()?.into_grid();
                self.spare = Some(std::mem::replace(&mut self.grid, redrawn));
                self.status.redraws += 1;
                // What is remembered in the old frame and steers the next frames goes: the
                // plan, the front memory, the last turn's stall; the blacklists, the
                // progress checker and a running recovery keep their old-frame points
                // (a few tenths of a metre off at most after seed 13's turn).
                self.drop_plan();
                self.front = None;
                self.last_turn_stall_m = None;
                self.stall.shift(dx_m, dy_m, dheading_rad);
                Some(PoseCorrection {
                    dx_m,
                    dy_m,
                    dheading_rad,
                    overlap: 0.0,
                    kind: CorrectionKind::PutBack,
                })
            }
        }
    }

    /// Makes an edit on the grid, and logs it while a blind turn's log is open.
    fn edit(&mut self, edit: GridEdit) {
        edit.apply(&mut self.grid);
        if let Some(log) = self.redraw.as_mut() {
            log.log(&edit);
        }
    }

    /// Sums the turn dead reckoning makes from a scan with fewer than `min_points` points
    /// (`alignable` false this frame) until [`Explorer::reacquire`] closes the arc.
    fn track_unaligned(&mut self, pose: &DeadReckonedPose, alignable: bool) {
        match self.unaligned.as_mut() {
            Some(arc) => {
                arc.advance(pose.heading_rad);
            }
            None if !alignable => self.unaligned = Some(BlindArc::new(pose.heading_rad)),
            None => {}
        }
    }

    /// The heading searched over the arc turned since the scan last had points enough to
    /// align, once this frame's `points` are enough for the wide search (fewer keep the
    /// arc open) and the arc is at least `reacquire_turn_deg`.
    fn reacquire(
        &mut self,
        pose: &DeadReckonedPose,
        points: &[(f64, f64)],
    ) -> Option<PoseCorrection> {
        let cfg = &self.cfg.scan_match;
        if points.len() < cfg.reacquire_points() {
            return None;
        }
        let turned = self.unaligned.take()?.turned_rad();
        if turned.abs() < cfg.reacquire_turn_deg.to_radians() {
            return None;
        }
        let mut fix = scan_match::align_over_arc(&self.grid, pose, points, cfg, turned)?;
        // A turn held by a wall, found after it: not a measure of the wheels' errors.
        fix.kind = CorrectionKind::PutBack;
        self.status.reacquired += 1;
        self.status.scan_fixes += 1;
        self.stall.shift(fix.dx_m, fix.dy_m, fix.dheading_rad);
        Some(fix)
    }

    /// Tells the explorer of a correction made to the pose outside it (the heading fix from
    /// the walls' directions): the stall check compares the picture with the motion the
    /// commands made, and a correction is not motion (measured: a robot standing still while
    /// the walls' fix and the pose put back by the stall check took turns moving the heading
    /// 18 degrees found a stall three times a second for 270 s).
    pub fn corrected(&mut self, dx_m: f64, dy_m: f64, dheading_rad: f64) {
        self.stall.shift(dx_m, dy_m, dheading_rad);
        if let Some(log) = self.redraw.as_mut() {
            log.corrected(dheading_rad);
        }
    }

    /// Whether a scan taken at this turn rate can be placed on the grid: while turning fast
    /// the dead-reckoned heading leads or lags the camera's (command latency), and the scan
    /// would smear the walls (it is neither added nor aligned).
    fn scan_placeable(&self, turn_rate_rad_s: f64) -> bool {
        turn_rate_rad_s.abs() <= self.cfg.grid.max_turn_rate_deg_s.to_radians()
    }

    /// One frame: adds the scan to the grid and returns the motion and its PSC ramp.
    pub fn step(&mut self, input: ExploreInput<'_>) -> (MotionCommand, u32) {
        let command = self.motion(input);
        self.last_command = command;
        let ramp = match command {
            MotionCommand::Left | MotionCommand::Right => u32::from(self.cfg.controller.turn_ramp),
            _ => 0,
        };
        (command, ramp)
    }

    fn motion(&mut self, input: ExploreInput<'_>) -> MotionCommand {
        let pose = input.pose;
        let mut front_m = FrontMemory::front_m(
            &mut self.front,
            input.front_m,
            &pose,
            self.cfg.controller.front_memory_turn_rad,
        );
        if front_m.is_none() && blind(input.scan, self.cfg.controller.blind_scan_bins) {
            // Not a way to drive into.
            front_m = Some(0.0);
        }
        let fp = self.controller.footprint();
        let (half_length_m, half_width_m) = (fp.half_length_m(), fp.half_width_m());
        self.edit(GridEdit::Footprint {
            pose,
            half_length_m,
            half_width_m,
        });
        if input.scan.valid_bins() > 0 && self.scan_placeable(input.turn_rate_rad_s) {
            let pts = self
                .grid
                .scan_points(&pose, self.camera_forward_m, input.scan);
            self.edit(GridEdit::Scan(pts));
        }
        if self.redraw.as_ref().is_some_and(RedrawLog::redrawing) {
            // The grid is being re-drawn from corrected poses over a few frames: the one
            // in use until then is the smeared one, so nothing is planned on it.
            return MotionCommand::Stop;
        }
        if input.intersection != self.last_intersection {
            self.last_intersection = input.intersection;
            self.replan_now = true;
        }
        if !self.started {
            self.started = true;
            if self.cfg.recovery.start_spin_deg > 0.0 {
                self.recovery = Some(Recovery::look_around(
                    &self.cfg.recovery,
                    self.cfg.recovery.start_spin_deg,
                ));
            }
        }
        if self.stalled {
            self.stalled = false;
            // The front range was remembered from a pose dead reckoning ran ahead of.
            self.front = None;
            // Driving or backing into something unseen: it is where the bumper is. Turning:
            // turn the other way.
            let (l, w) = (half_length_m, half_width_m);
            let stalled_left = match self.last_command {
                MotionCommand::Forward => {
                    let a = l + self.cfg.recovery.bump_gap_m;
                    self.edit(GridEdit::Bump {
                        pose,
                        ahead_m: (a, a),
                        left_m: (-w, w),
                    });
                    None
                }
                MotionCommand::Reverse => {
                    let a = -l - self.cfg.recovery.bump_gap_m;
                    self.edit(GridEdit::Bump {
                        pose,
                        ahead_m: (a, a),
                        left_m: (-w, w),
                    });
                    None
                }
                // A turn in place is held mostly by the side its front corner swings
                // toward (measured over 20 generated mazes: a left turn touched the front
                // left corner or the left side in most of its collisions): mark that side,
                // so that the next turn there is checked against it.
                // Only with the middle window seeing something: a blind picture (a plain wall
                // filling it) can look unchanged while the robot turns, and a bump beside a
                // robot that was never held stops every later turn there (measured: three of
                // 16 plain-wall maze runs stood at their start for 300 s).
                MotionCommand::Left | MotionCommand::Right => {
                    let left = self.last_command == MotionCommand::Left;
                    if input.front_m.is_some() {
                        let side = if left {
                            w + self.cfg.recovery.turn_bump_gap_m
                        } else {
                            -w - self.cfg.recovery.turn_bump_gap_m
                        };
                        self.edit(GridEdit::Bump {
                            pose,
                            ahead_m: (0.0, l),
                            left_m: (side, side),
                        });
                    }
                    Some(left)
                }
                MotionCommand::Stop => None,
            };
            let mut rin = self.recovery_input(&input);
            if stalled_left.is_some() {
                // Moving ahead off a stalled turn once per place: a robot that stalls again
                // there is rubbing along a wall it cannot see, and driving on slides it
                // along that wall (measured: 30 touches in 60 s).
                let here = (pose.x_m, pose.y_m);
                let again = self.last_turn_stall_m.is_some_and(|p| {
                    (p.0 - here.0).hypot(p.1 - here.1) < self.cfg.recovery.turn_stall_place_m
                });
                rin.ahead_clear &= !again;
                self.last_turn_stall_m = Some(here);
            }
            self.recovery = Some(Recovery::after_stall(
                &self.cfg.recovery,
                &rin,
                stalled_left,
            ));
            self.status.recoveries += 1;
            self.controller.reset();
            self.plan = None;
        }
        if let Some(mut r) = self.recovery.take() {
            let rin = self.recovery_input(&input);
            if let Some(cmd) = r.step(&rin) {
                self.recovery = Some(r);
                return cmd;
            }
            self.recovery = None;
            self.controller.reset();
            self.replan_now = true;
        }
        let due = self
            .last_plan_ns
            .is_none_or(|t| elapsed_s(t, input.now_ns) >= self.cfg.frontier.replan_s);
        let reached = self.plan.as_ref().is_some_and(|p| {
            (p.goal_m.0 - pose.x_m).hypot(p.goal_m.1 - pose.y_m) < self.cfg.frontier.reached_m
        });
        if reached && let Some(p) = &self.plan {
            // Driven to and still a frontier after this frame's scan: nothing more to see
            // from there.
            let g = p.look_at_m;
            self.seen(g);
        }
        if (self.replan_now || due || reached || self.plan.is_none())
            && let Some(cmd) = self.replan(&input, reached)
        {
            return cmd;
        }
        let Some(plan) = &self.plan else {
            return MotionCommand::Stop;
        };
        let look = plan.look_at_m;
        let d = (look.0 - pose.x_m).hypot(look.1 - pose.y_m);
        let fcfg = self.cfg.frontier;
        if d <= fcfg.view_m
            && d >= fcfg.min_view_m
            && !self.looked.contains(look, fcfg.blacklist_radius_m)
            && self.in_sight(&pose, look)
        {
            // Close enough to see it: face it, then take it as seen.
            let towards = [(pose.x_m, pose.y_m), look];
            let control = self.controller.step(
                &self.grid,
                ControlInput {
                    pose,
                    path: &towards,
                    front_m: None,
                    turn_rate_rad_s: input.turn_rate_rad_s,
                },
            );
            if matches!(
                control.command,
                MotionCommand::Forward | MotionCommand::Stop
            ) {
                // Faced: if this frame's scan did not resolve it (it lies beyond the scan's
                // range, or behind something), it is driven to next.
                self.looked.add(look);
                self.drop_plan();
                return MotionCommand::Stop;
            }
            return control.command;
        }
        let control = self.controller.step(
            &self.grid,
            ControlInput {
                pose,
                path: &plan.path,
                front_m,
                turn_rate_rad_s: input.turn_rate_rad_s,
            },
        );
        if control.blocked {
            self.replan_now = true;
        }
        control.command
    }

    /// A frontier was looked at or driven to: it is not chosen again (if this frame's scan
    /// resolved it, it is gone anyway).
    fn seen(&mut self, p: (f64, f64)) {
        self.blacklist.add(p);
        self.drop_plan();
    }

    /// Forgets the goal and any turn toward it, and plans again this frame.
    fn drop_plan(&mut self) {
        self.plan = None;
        self.replan_now = true;
        self.controller.reset();
    }

    /// Whether the line from the camera to `p` crosses no occupied cell.
    fn in_sight(&self, pose: &DeadReckonedPose, p: (f64, f64)) -> bool {
        let cam = grid::to_grid_frame(pose, (self.camera_forward_m, 0.0));
        let d = (p.0 - cam.0).hypot(p.1 - cam.1);
        let step = 0.5 * self.grid.cell_m();
        let n = (d / step).ceil() as usize;
        (0..n.saturating_sub(1)).all(|i| {
            let t = i as f64 * step / d.max(1e-9);
            self.grid
                .state_at(cam.0 + t * (p.0 - cam.0), cam.1 + t * (p.1 - cam.1))
                != CellState::Occupied
        })
    }

    fn recovery_input(&self, input: &ExploreInput<'_>) -> RecoveryInput {
        let fp = self.controller.footprint();
        let left_clear = fp.turn_blocked(&self.grid, &input.pose, true).is_none();
        let right_clear = fp.turn_blocked(&self.grid, &input.pose, false).is_none();
        RecoveryInput {
            now_ns: input.now_ns,
            distance_m: input.distance_m,
            heading_rad: input.pose.heading_rad,
            behind_clear: fp.behind_clear(
                &self.grid,
                &input.pose,
                self.cfg.recovery.backup_check_m,
            ),
            ahead_clear: fp.ahead_clear(
                &self.grid,
                &input.pose,
                self.cfg.recovery.turn_stall_shift_m,
            ),
            left_clear,
            right_clear,
        }
    }

    /// Builds a costmap with `costmap`, finds the frontiers and chooses one (`previous`: the
    /// goal being driven to, ranked cheaper); `None` when the robot lies outside the map's
    /// window.
    fn search(
        &self,
        costmap: CostmapConfig,
        robot_cell: grid::CellIndex,
        pose: &DeadReckonedPose,
        previous: Option<(f64, f64)>,
    ) -> Option<Search> {
        let fp = self.controller.footprint();
        let map = Costmap::build(
            &self.grid,
            costmap,
            fp.half_width_m(),
            fp.turn_radius_m(),
            robot_cell,
        );
        let start = map.index(robot_cell)?;
        let is_frontier = frontier_cells(&map);
        let field = CostField::to_targets(&map, start, &is_frontier);
        let grid = &self.grid;
        let centre = |i: usize| grid.centre(map.cell(i));
        let frontiers = find_frontiers(&map, &field, &is_frontier, &self.cfg.frontier, centre);
        let keep = self.cfg.frontier.keep_goal_m;
        let fcfg = self.cfg.frontier;
        let extra_cost = |f: &frontier::Frontier| {
            let p = f.centroid_m;
            let turn = wrap_rad((p.1 - pose.y_m).atan2(p.0 - pose.x_m) - pose.heading_rad);
            let g = centre(f.goal);
            // The goal being driven to is ranked cheaper (hysteresis).
            let kept = previous.is_some_and(|q| (q.0 - g.0).hypot(q.1 - g.1) < fcfg.same_goal_m);
            // A frontier in the blind zone cannot be seen from here: drive away and back.
            let blind = (p.0 - pose.x_m).hypot(p.1 - pose.y_m) < fcfg.min_view_m;
            fcfg.turn_weight * turn.abs() - if kept { keep } else { 0.0 }
                + if blind { fcfg.blind_cost_m } else { 0.0 }
        };
        let chosen = choose(&frontiers, &fcfg, map.cell_m(), &self.blacklist, extra_cost)
            .cloned()
            .map(|f| {
                let path = field
                    .path_to(f.goal)
                    .unwrap_or_default()
                    .into_iter()
                    .map(centre)
                    .collect();
                let goal_m = centre(f.goal);
                (f, goal_m, path)
            });
        Some(Search {
            frontiers: frontiers.len(),
            chosen,
        })
    }

    /// Builds the costmap, finds frontiers, chooses a goal and its path; checks progress.
    /// Returns a command when a recovery starts.
    fn replan(&mut self, input: &ExploreInput<'_>, reached: bool) -> Option<MotionCommand> {
        let pose = input.pose;
        self.replan_now = false;
        self.last_plan_ns = Some(input.now_ns);
        self.status.plans += 1;
        let Some(robot_cell) = self.grid.cell_of(pose.x_m, pose.y_m) else {
            // Off the grid's edge ([nav.grid] extent_m): nothing can be planned.
            self.plan = None;
            self.status.done = true;
            return None;
        };
        let previous = if reached {
            None
        } else {
            self.plan.as_ref().map(|p| p.goal_m)
        };
        // Nothing reachable with the usual clearance for `fallback_after_s` (a doorway drawn
        // a cell too narrow by noise or drift closes it; a closing that a look around
        // mends is left to it): the next frame searches again keeping only
        // `fallback_clearance_m` (the controller still checks every motion against the
        // occupied cells). One search a frame keeps a frame's decision time bounded.
        let tight = std::mem::take(&mut self.search_tight);
        let fallback = self.cfg.costmap.fallback_clearance_m;
        let costmap = CostmapConfig {
            clearance_m: if tight {
                fallback
            } else {
                self.cfg.costmap.clearance_m
            },
            ..self.cfg.costmap
        };
        let Some(found) = self.search(costmap, robot_cell, &pose, previous) else {
            self.plan = None;
            return None;
        };
        self.status.frontiers = found.frontiers;
        let closed_for_s = self
            .closed_since_ns
            .map_or(0.0, |t| elapsed_s(t, input.now_ns));
        if found.chosen.is_none()
            && !tight
            && fallback < self.cfg.costmap.clearance_m
            && closed_for_s >= self.cfg.costmap.fallback_after_s
        {
            // The plan in hand (if any) is followed for this one frame.
            self.search_tight = true;
            self.replan_now = true;
            return None;
        }
        if tight && found.chosen.is_some() {
            self.status.tight_plans += 1;
        }
        if !tight && found.chosen.is_some() {
            self.closed_since_ns = None;
        } else if found.chosen.is_none() {
            self.closed_since_ns.get_or_insert(input.now_ns);
        }
        let unreachable_for_s = self
            .unreachable_since_ns
            .map_or(0.0, |t| elapsed_s(t, input.now_ns));
        if found.chosen.is_some() {
            self.unreachable_since_ns = None;
        } else {
            self.unreachable_since_ns.get_or_insert(input.now_ns);
        }
        let fcfg = self.cfg.frontier;
        let Some((f, goal_m, path)) = found.chosen else {
            self.plan = None;
            self.status.done = true;
            // Everything left was given up on, or the map shows no way out (a wall seen
            // wrongly can close it): look around and try every goal again, now and then.
            let since = self
                .last_retry_ns
                .map_or(f64::INFINITY, |t| elapsed_s(t, input.now_ns));
            if since >= self.cfg.frontier.retry_s {
                // No frontier found by any search for `retry_s`: forget what closes the way,
                // but not the walls the look around's turns are checked against.
                let radius_m = self.cfg.recovery.clear_radius_m;
                if radius_m > 0.0 && unreachable_for_s >= self.cfg.frontier.retry_s {
                    let keep_occupied_m = self.controller.footprint().turn_reach_m();
                    self.edit(GridEdit::Forget {
                        centre_m: (pose.x_m, pose.y_m),
                        radius_m,
                        keep_occupied_m,
                    });
                    self.status.forgets += 1;
                }
                self.last_retry_ns = Some(input.now_ns);
                self.blacklist.clear();
                self.looked.clear();
                self.replan_now = true;
                if self.cfg.recovery.rotate_deg > 0.0 {
                    let mut r =
                        Recovery::look_around(&self.cfg.recovery, self.cfg.recovery.rotate_deg);
                    let cmd = r.step(&self.recovery_input(input));
                    self.recovery = Some(r);
                    return cmd;
                }
            }
            return None;
        };
        self.status.done = false;
        let new_goal =
            previous.is_none_or(|g| (g.0 - goal_m.0).hypot(g.1 - goal_m.1) > fcfg.same_goal_m);
        if new_goal {
            self.recoveries_for_goal = 0;
        }
        self.plan = Some(Plan {
            goal_m,
            look_at_m: f.centroid_m,
            path,
        });
        if self.progress.stalled(
            &self.cfg.recovery,
            f.distance_m,
            new_goal,
            (pose.x_m, pose.y_m),
            input.now_ns,
        ) {
            self.progress.reset();
            self.recoveries_for_goal += 1;
            if self.recoveries_for_goal > self.cfg.recovery.max_per_goal {
                self.blacklist.add(f.centroid_m);
                self.plan = None;
                self.replan_now = true;
                self.recoveries_for_goal = 0;
            }
            self.status.recoveries += 1;
            let rin = self.recovery_input(input);
            let mut r = Recovery::start(&self.cfg.recovery, &rin);
            let cmd = r.step(&rin);
            self.recovery = Some(r);
            self.controller.reset();
            return cmd;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An explorer standing in a corridor 0.4 m wide (walls drawn on both sides, the near
    /// end closed), seen free for 2 m ahead and unknown beyond: narrower than the robot's
    /// width plus twice the usual clearance, wide enough for the robot's width.
    fn explorer_in_a_narrow_corridor(fallback_clearance_m: f64) -> Explorer {
        let mut cfg = NavConfig::default();
        cfg.costmap.fallback_clearance_m = fallback_clearance_m;
        let mut e = Explorer::new(cfg, &RobotConfig::default(), &PulseTable::default(), 0.2);
        let origin = DeadReckonedPose {
            x_m: 0.0,
            y_m: 0.0,
            heading_rad: 0.0,
        };
        let free_middle = DeadReckonedPose { x_m: 0.5, ..origin };
        e.grid.clear_footprint(&free_middle, 1.0, 0.19);
        e.grid.mark_bump(&origin, (-0.6, 1.5), (0.25, 0.25));
        e.grid.mark_bump(&origin, (-0.6, 1.5), (-0.25, -0.25));
        e.grid.mark_bump(&origin, (-0.55, -0.55), (-0.25, 0.25));
        e
    }

    fn replan_in_corridor(e: &mut Explorer, now_ns: u64) {
        let scan = ObstacleScan::default();
        let input = ExploreInput {
            pose: DeadReckonedPose {
                x_m: 0.0,
                y_m: 0.0,
                heading_rad: 0.0,
            },
            scan: &scan,
            front_m: None,
            turn_rate_rad_s: 0.0,
            distance_m: 0.0,
            intersection: IntersectionType::Unknown,
            now_ns,
        };
        let _ = e.replan(&input, false);
    }

    #[test]
    fn a_passage_the_usual_clearance_closes_is_searched_again_with_the_fallback_clearance() {
        // Without a fallback (not below the usual clearance) the corridor's end is out of
        // reach: exploration is over.
        let mut e = explorer_in_a_narrow_corridor(CostmapConfig::default().clearance_m);
        replan_in_corridor(&mut e, 0);
        assert!(e.status().done);
        assert!(e.goal_m().is_none());
        // With one: the first search finds nothing, as before ...
        let mut e = explorer_in_a_narrow_corridor(0.0);
        let wait_ns = (e.cfg.costmap.fallback_after_s * 1e9) as u64;
        replan_in_corridor(&mut e, 0);
        assert!(e.status().done);
        assert!(!e.search_tight);
        // ... and once nothing was found for `fallback_after_s`, a search finding nothing
        // is not the last word ...
        replan_in_corridor(&mut e, wait_ns);
        assert!(e.goal_m().is_none());
        assert!(e.search_tight && e.replan_now);
        // ... the next frame's search, keeping less clearance, reaches the corridor's end.
        replan_in_corridor(&mut e, wait_ns + 66_000_000);
        let goal = e.goal_m().expect("a goal through the narrow corridor");
        assert!(goal.0 > 1.0 && goal.1.abs() < 0.2, "{goal:?}");
        assert_eq!(e.status().tight_plans, 1);
        assert!(!e.status().done);
        // The search after it tries the usual clearance first again.
        assert!(!e.search_tight);
    }

    #[test]
    fn the_grid_around_a_robot_with_no_reachable_frontier_is_forgotten_after_retry_s() {
        let closed = |clear_radius_m: f64| {
            let mut e = explorer_in_a_narrow_corridor(CostmapConfig::default().clearance_m);
            e.cfg.recovery.clear_radius_m = clear_radius_m;
            e
        };
        let retry_ns = (NavConfig::default().frontier.retry_s * 1e9) as u64;
        // Off: the walls stay whatever the wait.
        let mut e = closed(0.0);
        replan_in_corridor(&mut e, 0);
        replan_in_corridor(&mut e, retry_ns);
        assert_eq!(e.status().forgets, 0);
        assert_eq!(e.grid.state_at(0.3, 0.25), CellState::Occupied);
        // On: the first search that finds nothing forgets nothing (a look around may mend
        // it) ...
        let mut e = closed(1.0);
        replan_in_corridor(&mut e, 0);
        assert!(e.status().done);
        assert_eq!(e.status().forgets, 0);
        assert_eq!(e.grid.state_at(0.3, 0.25), CellState::Occupied);
        // ... nothing reachable for `retry_s` forgets the walls within 1 m, not beyond, and
        // keeps those the turn check looks at (within its reach of the robot).
        let reach_m = e.controller.footprint().turn_reach_m();
        assert!(reach_m > 0.3 && reach_m < 0.5, "{reach_m}");
        replan_in_corridor(&mut e, retry_ns);
        assert_eq!(e.status().forgets, 1);
        assert_eq!(e.grid.state_at(0.15, 0.25), CellState::Occupied);
        assert_eq!(e.grid.state_at(0.8, 0.25), CellState::Unknown);
        assert_eq!(e.grid.state_at(-0.55, 0.0), CellState::Unknown);
        assert_eq!(e.grid.state_at(1.4, 0.25), CellState::Occupied);
        // A frontier found with the fallback clearance (the default) counts as found: the
        // corridor's end is reached that way, and nothing is forgotten.
        let mut e = explorer_in_a_narrow_corridor(0.0);
        e.cfg.recovery.clear_radius_m = 1.0;
        let wait_ns = retry_ns.max((e.cfg.costmap.fallback_after_s * 1e9) as u64);
        replan_in_corridor(&mut e, 0);
        replan_in_corridor(&mut e, wait_ns);
        replan_in_corridor(&mut e, wait_ns + 66_000_000);
        assert!(e.goal_m().is_some());
        assert_eq!(e.status().forgets, 0);
        assert_eq!(e.grid.state_at(0.8, 0.25), CellState::Occupied);
    }

    #[test]
    fn a_picture_of_scattered_bins_in_the_middle_is_blind() {
        use hvs_shared::messages::SCAN_SCATTERED;
        let mut scan = ObstacleScan {
            tan_half_fov: 0.5,
            range_m: [1.5; SCAN_BINS],
            ..ObstacleScan::default()
        };
        assert!(!blind(&scan, 4));
        // The middle third scattered (a wall nearer than the matcher sees), the sides
        // ranged: blind.
        scan.range_m[SCAN_BINS / 3..2 * SCAN_BINS / 3].fill(SCAN_SCATTERED);
        assert!(blind(&scan, 4));
        // Scattered sides only: the middle still vouches for the way ahead.
        scan.range_m = [1.5; SCAN_BINS];
        scan.range_m[..SCAN_BINS / 3].fill(SCAN_SCATTERED);
        assert!(!blind(&scan, 4));
        // Nothing at all: blind.
        assert!(blind(&ObstacleScan::default(), 4));
    }

    #[test]
    fn a_front_wall_in_the_blind_zone_is_remembered_until_the_robot_turns() {
        let mut memory = None;
        let at = |x_m: f64, heading_deg: f64| DeadReckonedPose {
            x_m,
            y_m: 0.0,
            heading_rad: heading_deg.to_radians(),
        };
        assert_eq!(
            FrontMemory::front_m(&mut memory, None, &at(0.0, 0.0), 0.26),
            None
        );
        assert_eq!(
            FrontMemory::front_m(&mut memory, Some(0.8), &at(0.0, 0.0), 0.26),
            Some(0.8)
        );
        // Blind now: 0.5 m driven toward it leaves 0.3 m.
        let left = FrontMemory::front_m(&mut memory, None, &at(0.5, 2.0), 0.26).unwrap_or(9.0);
        assert!((left - 0.3).abs() < 0.01, "{left}");
        // Driven past it: 0, never negative.
        assert_eq!(
            FrontMemory::front_m(&mut memory, None, &at(1.0, 0.0), 0.26),
            Some(0.0)
        );
        // Turned away: nothing known.
        assert_eq!(
            FrontMemory::front_m(&mut memory, None, &at(1.0, 40.0), 0.26),
            None
        );
        assert_eq!(
            FrontMemory::front_m(&mut memory, None, &at(1.0, 0.0), 0.26),
            None
        );
    }
}
