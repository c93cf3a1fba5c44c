//! `[nav]`: the exploring navigator (`decision.policy = "explore"`): every number it tunes, in
//! one section with units, one sub-table per layer (Nav2's split: the map, the costmap, the
//! frontiers, the planner, the controller, the recovery behaviours). The footprint is not
//! here: it comes from `[robot]`, which the simulator's robot also uses. The heading fix from
//! the walls' directions that the fuzzy policy uses also corrects the explorer's pose; its
//! gain stays `decision.heading_fix_gain` (with `decision.snap_turn_deg = 90`), one number
//! for both.

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Checks that each `(key, value, lo, hi)` lies in `lo..=hi`, naming the first that does not.
pub(super) fn check_ranges(prefix: &str, checks: &[(&str, f64, f64, f64)]) -> Result<(), Invalid> {
    for &(key, value, lo, hi) in checks {
        if !(lo..=hi).contains(&value) {
            return Err(Invalid::new(
                format!("{prefix}.{key}"),
                format!("= {value} must be in {lo}..={hi}"),
            ));
        }
    }
    Ok(())
}

/// The log-odds occupancy grid built from the obstacle scans (`[nav.grid]`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct GridConfig {
    /// Cell edge, metres.
    pub cell_m: f64,
    /// Edge of the square area the grid can hold, centred on the start, metres.
    pub extent_m: f64,
    /// Log-odds added to the cell a scan point falls in.
    pub hit_log_odds: f64,
    /// Log-odds added to a cell a scan ray passes through (negative).
    pub miss_log_odds: f64,
    /// Lower clamp of a cell's log-odds.
    pub min_log_odds: f64,
    /// Upper clamp of a cell's log-odds.
    pub max_log_odds: f64,
    /// A cell is occupied above this log-odds, free below its negative.
    pub decided_log_odds: f64,
    /// Scan points farther than this are not marked (their ray marks free up to it), metres.
    pub scan_range_m: f64,
    /// Scans taken while turning faster than this are not added, degrees per second.
    pub max_turn_rate_deg_s: f64,
    /// A ray stops marking free this share of its length before its point (a ray that
    /// meets a wall at a slant runs beside it for its last stretch and would clear it).
    pub free_margin_share: f64,
    /// A ray stops marking free this far before it passes within this distance of a
    /// nearer point of the same scan, metres (0: off): a ray that looks just past a
    /// wall's end would clear the cells of its corner.
    pub ray_clearance_m: f64,
    /// A scan bin is kept only when a neighbouring bin agrees with it: their depths differ
    /// by at most this share of the depth ...
    pub support_share: f64,
    /// ... plus this, metres.
    pub support_m: f64,
    /// ... and lies in a run of at least this many consecutive bins that all agree with
    /// its depth (2: one neighbour agrees). A longer run drops the bins at a surface's
    /// ends, where block matching on a plain wall most often ranges past the wall.
    pub support_run_bins: u32,
    /// A ray crossing an occupied cell lowers it by this share of `miss_log_odds` only (a
    /// wall fades slowly: a few stray rays do not open it).
    pub occupied_miss_share: f64,
}

impl Default for GridConfig {
    fn default() -> Self {
        Self {
            cell_m: 0.1,
            extent_m: 60.0,
            hit_log_odds: 0.35,
            miss_log_odds: -0.4,
            min_log_odds: -2.0,
            max_log_odds: 3.5,
            decided_log_odds: 0.8,
            scan_range_m: 2.0,
            max_turn_rate_deg_s: 20.0,
            free_margin_share: 0.1,
            ray_clearance_m: 0.0,
            support_share: 0.1,
            support_m: 0.05,
            support_run_bins: 2,
            occupied_miss_share: 0.25,
        }
    }
}

impl GridConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_ranges(
            "grid",
            &[
                ("cell_m", self.cell_m, 0.02, 0.5),
                ("extent_m", self.extent_m, 5.0, 500.0),
                ("hit_log_odds", self.hit_log_odds, 0.01, 10.0),
                ("miss_log_odds", self.miss_log_odds, -10.0, -0.01),
                ("min_log_odds", self.min_log_odds, -50.0, -0.01),
                ("max_log_odds", self.max_log_odds, 0.01, 50.0),
                ("decided_log_odds", self.decided_log_odds, 0.01, 10.0),
                ("scan_range_m", self.scan_range_m, 0.5, 20.0),
                ("max_turn_rate_deg_s", self.max_turn_rate_deg_s, 0.0, 1000.0),
                ("free_margin_share", self.free_margin_share, 0.0, 0.9),
                ("ray_clearance_m", self.ray_clearance_m, 0.0, 1.0),
                ("support_share", self.support_share, 0.0, 1.0),
                ("support_m", self.support_m, 0.0, 1.0),
                (
                    "support_run_bins",
                    f64::from(self.support_run_bins),
                    2.0,
                    8.0,
                ),
                ("occupied_miss_share", self.occupied_miss_share, 0.0, 1.0),
            ],
        )?;
        if self.extent_m / self.cell_m > 4096.0 {
            return Err(Invalid::new(
                "grid.extent_m",
                format!(
                    "= {} is more than 4096 cells of {} m",
                    self.extent_m, self.cell_m
                ),
            ));
        }
        if self.decided_log_odds >= self.max_log_odds || -self.decided_log_odds <= self.min_log_odds
        {
            return Err(Invalid::new(
                "grid.decided_log_odds",
                "must lie between min_log_odds and max_log_odds in magnitude",
            ));
        }
        Ok(())
    }
}

/// Drift correction: each scan aligned to the grid before it is added (`[nav.scan_match]`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ScanMatchConfig {
    /// Align scans at all.
    pub enabled: bool,
    /// Search half-width in x and y around the dead-reckoned pose, metres. 0 (the default)
    /// searches the heading only: the scan's nearest-percentile ranges draw a wall nearer
    /// when seen from farther, and a position search turned that into a pull backwards
    /// (docs/navigation.md, the explorer's status).
    pub search_m: f64,
    /// Search step in x and y, metres.
    pub step_m: f64,
    /// Search half-width in heading, degrees.
    pub search_deg: f64,
    /// Search step in heading, degrees.
    pub step_deg: f64,
    /// Scan points within the grid's range needed to try an alignment.
    pub min_points: u32,
    /// Share of the points that must land on occupied cells at the best pose.
    pub min_overlap: f64,
    /// Share of the found correction applied per scan (0..1).
    pub gain: f64,
    /// Correct the position too, by point-to-wall alignment (each scan point against the
    /// wall the grid's occupied cells draw near it; only along the directions the walls in
    /// view constrain: in a hallway, across it and not along it). Off by default: over the
    /// 20 generated mazes it collided more and covered less (docs/navigation.md).
    pub position: bool,
    /// Scan points farther than this from the nearest mapped wall are new surfaces, not
    /// evidence of drift, metres.
    pub position_reach_m: f64,
    /// Points whose walls must face a direction before the position is corrected along it
    /// (the alignment's information in that direction, in points).
    pub position_min_points: u32,
    /// Share of the position correction applied per scan (0..1).
    pub position_gain: f64,
    /// Largest position correction per scan, metres.
    pub position_max_step_m: f64,
    /// Share by which the best pose's score must beat the dead-reckoned pose's.
    pub min_gain_share: f64,
    /// Occupied cells within this distance of a point's nearest one draw the wall it lies
    /// on (position alignment), metres.
    pub wall_patch_m: f64,
    /// Residuals beyond this weigh less (Huber; position alignment), metres.
    pub huber_m: f64,
    /// A patch is a wall, with a direction, when its spread across is under this share of
    /// its spread along (the eigenvalues of its cells' covariance).
    pub max_flatness: f64,
    /// After the scan had too few points to align (`min_points`: a wall inside the
    /// matcher's blind range) while dead reckoning turned at least this far, degrees, the
    /// first scan that can be aligned again searches the heading over the whole arc turned
    /// (and `search_deg` beyond each end) and the best fit is taken in full: a turn held by
    /// an unseen wall while the camera was blind turns dead reckoning alone (measured: 48
    /// to 140 degrees). 0 turns it off.
    pub reacquire_turn_deg: f64,
    /// Scan points a re-found heading needs (the search is wide, and over 20 generated
    /// mazes the scans with fewer points found most of the wrong headings); scans with
    /// fewer keep the arc open for the next one.
    pub reacquire_min_points: u32,
    /// Share of the points that must land on occupied cells at a re-found heading.
    pub reacquire_min_overlap: f64,
}

impl Default for ScanMatchConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            search_m: 0.0,
            step_m: 0.05,
            search_deg: 3.0,
            step_deg: 1.0,
            min_points: 16,
            min_overlap: 0.5,
            gain: 0.5,
            position: false,
            position_reach_m: 0.2,
            position_min_points: 8,
            position_gain: 0.3,
            position_max_step_m: 0.02,
            min_gain_share: 0.15,
            wall_patch_m: 0.25,
            huber_m: 0.1,
            max_flatness: 0.3,
            reacquire_turn_deg: 0.0,
            reacquire_min_points: 24,
            reacquire_min_overlap: 0.75,
        }
    }
}

/// Most poses the scan matcher may try per scan (it runs every frame).
const MAX_MATCH_POSES: f64 = 20_000.0;

impl ScanMatchConfig {
    /// Scan points a re-found heading needs: `reacquire_min_points`, and never fewer than
    /// any alignment needs (`min_points`).
    pub fn reacquire_points(&self) -> usize {
        self.min_points.max(self.reacquire_min_points) as usize
    }

    fn validate(&self) -> Result<(), Invalid> {
        self.check_ranges()?;
        let xy = 2.0 * (self.search_m / self.step_m).floor() + 1.0;
        let th = 2.0 * (self.search_deg / self.step_deg).floor() + 1.0;
        if xy * xy * th > MAX_MATCH_POSES {
            return Err(Invalid::new(
                "scan_match.search_m",
                format!(
                    "with step_m {}, search_deg {} and step_deg {} tries {} poses a scan, \
                     more than {MAX_MATCH_POSES}",
                    self.step_m,
                    self.search_deg,
                    self.step_deg,
                    xy * xy * th
                ),
            ));
        }
        Ok(())
    }

    fn check_ranges(&self) -> Result<(), Invalid> {
        check_ranges(
            "scan_match",
            &[
                ("search_m", self.search_m, 0.0, 1.0),
                ("step_m", self.step_m, 0.005, 0.5),
                ("search_deg", self.search_deg, 0.0, 30.0),
                ("reacquire_turn_deg", self.reacquire_turn_deg, 0.0, 360.0),
                (
                    "reacquire_min_points",
                    f64::from(self.reacquire_min_points),
                    1.0,
                    64.0,
                ),
                (
                    "reacquire_min_overlap",
                    self.reacquire_min_overlap,
                    0.0,
                    1.0,
                ),
                ("step_deg", self.step_deg, 0.1, 10.0),
                ("min_points", f64::from(self.min_points), 1.0, 64.0),
                ("min_overlap", self.min_overlap, 0.0, 1.0),
                ("gain", self.gain, 0.0, 1.0),
                ("position_reach_m", self.position_reach_m, 0.02, 1.0),
                (
                    "position_min_points",
                    f64::from(self.position_min_points),
                    1.0,
                    64.0,
                ),
                ("position_gain", self.position_gain, 0.0, 1.0),
                ("position_max_step_m", self.position_max_step_m, 0.0, 0.5),
                ("min_gain_share", self.min_gain_share, 0.0, 10.0),
                ("wall_patch_m", self.wall_patch_m, 0.01, 2.0),
                ("huber_m", self.huber_m, 0.001, 1.0),
                ("max_flatness", self.max_flatness, 0.0, 1.0),
            ],
        )
    }
}

/// The costmap the planner and the controller read (`[nav.costmap]`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CostmapConfig {
    /// Clearance kept beyond the footprint's half-width: occupied cells are lethal within
    /// `robot.width_m / 2 + clearance_m`, metres.
    pub clearance_m: f64,
    /// Beyond the lethal band the cost falls to 0 over this distance, metres.
    pub decay_m: f64,
    /// Cost of a cell right at the lethal band, in metres of path (the planner adds it per
    /// cell, so it trades this much detour for keeping off walls).
    pub wall_cost_m: f64,
    /// Extra cost of crossing an unknown cell, in metres of path per cell.
    pub unknown_cost_m: f64,
    /// Extra cost of a seen cell nearer to an unknown one than the footprint's half-width
    /// plus `clearance_m`, in metres of path per cell, falling to 0 at the half-diagonal
    /// plus `clearance_m`: the camera looks ahead only, so a wall end beside the way (in its
    /// blind zone) is often unknown, never occupied; paths keep to the middle of what was
    /// seen.
    pub unknown_clearance_cost_m: f64,
    /// Extra cost of a cell where the robot could stand but not turn in place (an occupied
    /// cell within the footprint's half-diagonal plus `clearance_m`: Nav2's "possibly
    /// inscribed" band), in metres of path per cell: paths keep where turns fit.
    pub turn_clearance_cost_m: f64,
    /// Extra cost of a cell crossed while leaving a lethal start (the robot stands where
    /// the costmap says it cannot), in metres of path per cell.
    pub escape_cost_m: f64,
    /// When no frontier is reachable with `clearance_m`, the search is made once more with
    /// this clearance, metres (not below `clearance_m`: no second search). A doorway
    /// 0.7 m wide leaves 0.29 m between the lethal bands at 0.05 m clearance, three cells of
    /// 0.1 m; a wall drawn a cell thick too far on each side (noise, drift) closes it.
    pub fallback_clearance_m: f64,
    /// ... once searches with `clearance_m` have found no frontier for this long, seconds
    /// (measured: without the wait a closing that a look around mends sent robots into
    /// narrow places, 53 collisions on generated mazes 1-20 against 30).
    pub fallback_after_s: f64,
}

impl Default for CostmapConfig {
    fn default() -> Self {
        Self {
            clearance_m: 0.05,
            decay_m: 0.35,
            wall_cost_m: 0.6,
            unknown_cost_m: 0.05,
            unknown_clearance_cost_m: 1.0,
            turn_clearance_cost_m: 1.0,
            escape_cost_m: 1.0,
            fallback_clearance_m: 0.0,
            fallback_after_s: 20.0,
        }
    }
}

impl CostmapConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_ranges(
            "costmap",
            &[
                ("clearance_m", self.clearance_m, 0.0, 1.0),
                ("decay_m", self.decay_m, 0.0, 3.0),
                ("wall_cost_m", self.wall_cost_m, 0.0, 100.0),
                ("unknown_cost_m", self.unknown_cost_m, 0.0, 100.0),
                (
                    "unknown_clearance_cost_m",
                    self.unknown_clearance_cost_m,
                    0.0,
                    100.0,
                ),
                (
                    "turn_clearance_cost_m",
                    self.turn_clearance_cost_m,
                    0.0,
                    100.0,
                ),
                ("escape_cost_m", self.escape_cost_m, 0.0, 100.0),
                ("fallback_clearance_m", self.fallback_clearance_m, 0.0, 1.0),
                ("fallback_after_s", self.fallback_after_s, 0.0, 3600.0),
            ],
        )
    }
}

/// Frontier choice (`[nav.frontier]`, explore_lite's cost: distance against size).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FrontierConfig {
    /// Frontiers shorter than this are ignored, metres.
    pub min_size_m: f64,
    /// Weight of the path length to a frontier, per metre.
    pub distance_weight: f64,
    /// Weight of a frontier's size, per metre (subtracted).
    pub size_weight: f64,
    /// Weight of turning to face a frontier, per radian.
    pub turn_weight: f64,
    /// Goals within this distance of a blacklisted one are not chosen, metres.
    pub blacklist_radius_m: f64,
    /// Seconds between frontier searches while a goal is being driven to.
    pub replan_s: f64,
    /// A goal closer than this to the robot's centre counts as reached, metres.
    pub reached_m: f64,
    /// The frontier of the goal being driven to is ranked this much cheaper, metres (keeps
    /// two similar frontiers from taking turns).
    pub keep_goal_m: f64,
    /// A frontier whose centre is within this distance, in line of sight, is looked at
    /// (turning to face it) instead of driven to, metres.
    pub view_m: f64,
    /// ... but not nearer than this: the camera is blind close up (the matcher's largest
    /// disparity), metres from the turning centre.
    pub min_view_m: f64,
    /// Extra cost of a frontier whose centre lies in the camera's blind zone, metres.
    pub blind_cost_m: f64,
    /// Seconds between retries once no frontier is left (after a look around).
    pub retry_s: f64,
    /// A goal within this of the previous one is the same goal (ranked `keep_goal_m`
    /// cheaper, its recovery count kept), metres.
    pub same_goal_m: f64,
}

impl Default for FrontierConfig {
    fn default() -> Self {
        Self {
            min_size_m: 0.3,
            distance_weight: 1.0,
            size_weight: 0.3,
            turn_weight: 0.3,
            blacklist_radius_m: 0.4,
            replan_s: 1.0,
            reached_m: 0.3,
            keep_goal_m: 1.0,
            view_m: 1.5,
            min_view_m: 0.7,
            blind_cost_m: 2.0,
            retry_s: 20.0,
            same_goal_m: 0.6,
        }
    }
}

impl FrontierConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_ranges(
            "frontier",
            &[
                ("min_size_m", self.min_size_m, 0.0, 10.0),
                ("distance_weight", self.distance_weight, 0.0, 100.0),
                ("size_weight", self.size_weight, 0.0, 100.0),
                ("turn_weight", self.turn_weight, 0.0, 100.0),
                ("blacklist_radius_m", self.blacklist_radius_m, 0.0, 10.0),
                ("replan_s", self.replan_s, 0.05, 60.0),
                ("reached_m", self.reached_m, 0.05, 5.0),
                ("keep_goal_m", self.keep_goal_m, 0.0, 100.0),
                ("view_m", self.view_m, 0.0, 20.0),
                ("min_view_m", self.min_view_m, 0.0, 20.0),
                ("blind_cost_m", self.blind_cost_m, 0.0, 100.0),
                ("retry_s", self.retry_s, 0.5, 600.0),
                ("same_goal_m", self.same_goal_m, 0.0, 10.0),
            ],
        )
    }
}

/// The path follower for the skid-steer base (`[nav.controller]`): turns in place toward the
/// path, drives ahead along it, through the pulse table's five motions.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ControllerConfig {
    /// The point followed lies this far along the path, metres.
    pub lookahead_m: f64,
    /// A heading error beyond this starts a turn in place, degrees.
    pub turn_above_deg: f64,
    /// A turn in place ends once the heading error is below this, degrees.
    pub aligned_deg: f64,
    /// Turns stop this long before the target by their current rate (command latency), s.
    pub turn_lead_s: f64,
    /// The footprint swept this far ahead must be clear to drive ahead, metres.
    pub check_ahead_m: f64,
    /// A front range (middle window, or its last reading less the way driven since while
    /// it is blind) nearer than this stops driving ahead, metres; the matcher reads nothing
    /// nearer than `max_disp`'s depth (0.35 m at 320x240), so this must lie above it.
    pub stop_range_m: f64,
    /// PSC ramp code (0..63; 0 = at once, 1 = 0.75 s .. 63 = 60 s for the full pulse range)
    /// for turns: a turn that starts gently stops where it was meant to, and a scan taken
    /// early in it is placed well.
    pub turn_ramp: u8,
    /// Margin beyond the circle the footprint's corners sweep that must hold no occupied
    /// cell before turning in place, metres (it absorbs the map's drift and wall depth).
    pub turn_margin_m: f64,
    /// Side margin of the rectangle swept ahead or behind beyond the footprint, metres.
    pub sweep_margin_m: f64,
    /// Largest share of the swept rectangle ahead that may be unknown for "mostly seen
    /// free" (0..1).
    pub max_unknown_ahead_share: f64,
    /// Shifts (ahead or back) in a row to clear the turning disc before turning anyway: a
    /// disc blocked both ways would otherwise rock the robot back and forth.
    pub max_shifts: u32,
    /// A shift needs this much of the way ahead or behind clear, metres.
    pub shift_check_m: f64,
    /// Turning more than this since the middle window last saw the front makes that range
    /// stale, radians (0.26: 15 degrees).
    pub front_memory_turn_rad: f64,
    /// A scan with fewer valid bins than this, and no front range, counts as a wall ahead
    /// (and the frontiers in the blind zone cost `frontier.blind_cost_m` more).
    pub blind_scan_bins: u32,
    /// A turn in place with the front nearer than this (the middle window's range, or its
    /// memory; a blind scan reads 0) backs up first, in shifts, while the way behind is
    /// clear: a turn made blind can be held by a wall the camera never saw, and dead
    /// reckoning then turns alone (docs/navigation.md, second round of 2026-12-07), metres.
    /// 0 turns it off.
    pub turn_front_min_m: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            lookahead_m: 0.45,
            turn_above_deg: 20.0,
            aligned_deg: 6.0,
            turn_lead_s: 0.1,
            check_ahead_m: 0.12,
            stop_range_m: 0.5,
            turn_ramp: 8,
            turn_margin_m: 0.05,
            sweep_margin_m: 0.03,
            max_unknown_ahead_share: 0.25,
            max_shifts: 6,
            shift_check_m: 0.1,
            front_memory_turn_rad: 0.26,
            blind_scan_bins: 4,
            turn_front_min_m: 0.0,
        }
    }
}

impl ControllerConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_ranges(
            "controller",
            &[
                ("lookahead_m", self.lookahead_m, 0.05, 5.0),
                ("turn_above_deg", self.turn_above_deg, 1.0, 180.0),
                ("aligned_deg", self.aligned_deg, 0.5, 90.0),
                ("turn_lead_s", self.turn_lead_s, 0.0, 1.0),
                ("check_ahead_m", self.check_ahead_m, 0.0, 2.0),
                ("stop_range_m", self.stop_range_m, 0.0, 5.0),
                ("turn_ramp", f64::from(self.turn_ramp), 0.0, 63.0),
                ("turn_margin_m", self.turn_margin_m, 0.0, 0.5),
                ("sweep_margin_m", self.sweep_margin_m, 0.0, 0.5),
                (
                    "max_unknown_ahead_share",
                    self.max_unknown_ahead_share,
                    0.0,
                    1.0,
                ),
                ("max_shifts", f64::from(self.max_shifts), 0.0, 100.0),
                ("shift_check_m", self.shift_check_m, 0.0, 1.0),
                (
                    "front_memory_turn_rad",
                    self.front_memory_turn_rad,
                    0.0,
                    3.2,
                ),
                (
                    "blind_scan_bins",
                    f64::from(self.blind_scan_bins),
                    0.0,
                    64.0,
                ),
                ("turn_front_min_m", self.turn_front_min_m, 0.0, 2.0),
            ],
        )?;
        if self.aligned_deg >= self.turn_above_deg {
            return Err(Invalid::new(
                "controller.aligned_deg",
                format!(
                    "= {} must be below turn_above_deg ({})",
                    self.aligned_deg, self.turn_above_deg
                ),
            ));
        }
        Ok(())
    }
}

/// The progress checker and the recovery behaviours (`[nav.recovery]`).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RecoveryConfig {
    /// The path cost to the goal must fall by this much, or the robot move this far, ...
    pub progress_m: f64,
    /// ... within this many seconds, or the recovery behaviours start.
    pub progress_timeout_s: f64,
    /// Back-up distance, metres.
    pub backup_m: f64,
    /// Backing up needs this much of the way behind held free, checked every frame of it,
    /// metres.
    pub backup_check_m: f64,
    /// Rotation in place after backing up, degrees.
    pub rotate_deg: f64,
    /// Standing still after rotating, seconds.
    pub wait_s: f64,
    /// Recoveries for one goal before it is blacklisted.
    pub max_per_goal: u32,
    /// Turn in place this far before exploring, to see around the start, degrees (0: no).
    pub start_spin_deg: f64,
    /// Rotations are cut into steps of at most this much, with a pause after each, so that
    /// the scans taken while standing enter the map (those taken turning fast do not),
    /// radians (0.8: 46 degrees).
    pub rotate_step_rad: f64,
    /// The pause after each rotation step, seconds.
    pub rotate_pause_s: f64,
    /// After a turn in place stalled with the way ahead seen clear, the robot first drives
    /// this far ahead, metres: a robot turning in place is held by something its rear or
    /// side sweeps, which the forward camera never saw (measured: a robot 0.22 m from the
    /// wall behind it in a 0.88 m corridor, whose corners sweep 0.27 m, turned against that
    /// wall, waited and turned again for 270 s), and moving ahead takes it off.
    pub turn_stall_shift_m: f64,
    /// Stalled turns this near each other are at the same place (the second one does not
    /// shift ahead again), metres.
    pub turn_stall_place_m: f64,
    /// A behaviour that has not ended by odometry after this long ends anyway (odometry
    /// that does not advance, with no actuator reports, must not hold the robot in it), s.
    pub behaviour_limit_s: f64,
    /// After a stalled drive, a bump is marked this far beyond the footprint's front or
    /// back, metres (the footprint clearing leaves occupied cells alone, so it stays).
    pub bump_gap_m: f64,
    /// After a stalled turn, a bump is marked this far beside the footprint's side, metres
    /// (inside the circle the corners sweep: the half-diagonal is 0.11 m beyond the side).
    pub turn_bump_gap_m: f64,
    /// With no frontier found by any search (either clearance) for `[nav.frontier] retry_s`,
    /// the grid within this distance of the robot is forgotten (made unknown, bumps too;
    /// the walls within the turn check's reach are kept) before the look around, as Nav2's
    /// clear-costmap recovery does: a wall drawn wrongly (drift, a stray match, a bump) that
    /// closes the way is seen again or not at all, metres (0: off).
    pub clear_radius_m: f64,
}

impl Default for RecoveryConfig {
    fn default() -> Self {
        Self {
            progress_m: 0.15,
            progress_timeout_s: 6.0,
            backup_m: 0.15,
            backup_check_m: 0.05,
            rotate_deg: 90.0,
            wait_s: 0.5,
            max_per_goal: 1,
            start_spin_deg: 0.0,
            rotate_step_rad: 0.8,
            rotate_pause_s: 0.35,
            turn_stall_shift_m: 0.12,
            turn_stall_place_m: 0.5,
            behaviour_limit_s: 5.0,
            bump_gap_m: 0.12,
            turn_bump_gap_m: 0.06,
            clear_radius_m: 1.0,
        }
    }
}

impl RecoveryConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_ranges(
            "recovery",
            &[
                ("progress_m", self.progress_m, 0.01, 5.0),
                ("progress_timeout_s", self.progress_timeout_s, 0.5, 600.0),
                ("backup_m", self.backup_m, 0.0, 2.0),
                ("backup_check_m", self.backup_check_m, 0.0, 2.0),
                ("rotate_deg", self.rotate_deg, 0.0, 360.0),
                ("wait_s", self.wait_s, 0.0, 60.0),
                ("max_per_goal", f64::from(self.max_per_goal), 0.0, 100.0),
                ("start_spin_deg", self.start_spin_deg, 0.0, 720.0),
                ("rotate_step_rad", self.rotate_step_rad, 0.05, 6.3),
                ("rotate_pause_s", self.rotate_pause_s, 0.0, 10.0),
                ("turn_stall_shift_m", self.turn_stall_shift_m, 0.0, 1.0),
                ("turn_stall_place_m", self.turn_stall_place_m, 0.0, 10.0),
                ("behaviour_limit_s", self.behaviour_limit_s, 0.5, 600.0),
                ("bump_gap_m", self.bump_gap_m, 0.0, 1.0),
                ("turn_bump_gap_m", self.turn_bump_gap_m, 0.0, 1.0),
                ("clear_radius_m", self.clear_radius_m, 0.0, 5.0),
            ],
        )
    }
}

/// The stall check (`[nav.stall]`): a robot held by a wall while its wheels turn keeps the
/// same picture while dead reckoning integrates the commands on.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct StallConfig {
    /// Bins valid in both scans needed to compare them.
    pub min_common_bins: u32,
    /// The scan is unchanged when the median relative range change is below this share.
    pub same_share: f64,
    /// Dead-reckoned travel since the scan last changed that must change it, metres ...
    pub moved_m: f64,
    /// ... or turn, radians (0.35: 20 degrees, about 24 of the 64 bins over a 53 degree
    /// view).
    pub turned_rad: f64,
    /// A turn is a stall when dead reckoning turned this far while the scan stayed too
    /// empty to compare, radians (1.57: 90 degrees). A turn held by a wall the camera
    /// faces from nearer than the matcher's shortest range sees nothing the whole time
    /// (measured on generated maze 4: dead reckoning turned on 170 degrees); a free turn
    /// brings something into view well before (textured walls: 40 degrees at most).
    pub blind_turned_rad: f64,
    /// Bins valid in both scans needed to compare their middle thirds (for a drive).
    pub min_common_middle_bins: u32,
    /// Middle bins farther than this are not compared for a drive, metres (`moved_m` is
    /// then at least a tenth of their range).
    pub middle_range_m: f64,
}

impl Default for StallConfig {
    fn default() -> Self {
        Self {
            min_common_bins: 16,
            same_share: 0.03,
            moved_m: 0.2,
            turned_rad: 0.35,
            blind_turned_rad: 1.57,
            min_common_middle_bins: 6,
            middle_range_m: 2.0,
        }
    }
}

impl StallConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_ranges(
            "stall",
            &[
                (
                    "min_common_bins",
                    f64::from(self.min_common_bins),
                    1.0,
                    64.0,
                ),
                ("same_share", self.same_share, 0.0, 1.0),
                ("moved_m", self.moved_m, 0.01, 5.0),
                ("turned_rad", self.turned_rad, 0.01, 6.3),
                ("blind_turned_rad", self.blind_turned_rad, 0.01, 6.3),
                (
                    "min_common_middle_bins",
                    f64::from(self.min_common_middle_bins),
                    1.0,
                    64.0,
                ),
                ("middle_range_m", self.middle_range_m, 0.1, 20.0),
            ],
        )
    }
}

/// Re-drawing the grid after a heading found wrong (`[nav.redraw]`). A turn held by an unseen
/// wall while the camera was blind turns dead reckoning alone (measured: 48 to 140 degrees);
/// the grid is drawn in the turned frame until the walls' heading fix pulls the heading back,
/// and then in two frames at once. From such a turn on the grid's edits are logged beside a
/// copy of the grid; a large correction that follows re-draws them from the corrected poses
/// (rotated by it about where the turn began) and moves the position with them.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RedrawConfig {
    /// A dead-reckoned turn at least this large while the scan had too few points to align
    /// (`scan_match.min_points`) keeps the log, degrees; 0 turns re-drawing off.
    pub blind_turn_deg: f64,
    /// Heading corrections within `jump_window_s` summing to at least this, the other way
    /// from the turn, re-draw the log, if the scans since the blind turn fit the grid
    /// before it best turned by at least as much, degrees.
    pub min_correction_deg: f64,
    /// The window a jump of the heading is summed over, seconds (the walls' heading fix
    /// pulls 34 degrees in five frames).
    pub jump_window_s: f64,
    /// ... once they have settled: a frame's correction under this, degrees (the walls'
    /// fix pulls over several frames).
    pub settled_deg: f64,
    /// The turn that brings the scans since the blind turn onto the grid drawn before it is
    /// searched this far either side of the jump, degrees ...
    pub search_deg: f64,
    /// ... in steps of this, degrees.
    pub search_step_deg: f64,
    /// Scans' points on decided cells of the grid before the turn the best turn needs.
    pub match_min_points: u32,
    /// Share of those points by which the best turn's agreement (points on occupied cells
    /// less points on free ones) must beat no turn's.
    pub match_min_gain_share: f64,
    /// Most logged scans scored per turn tried (spread over the log).
    pub match_max_scans: u32,
    /// Turns scored per frame (no turn first, then the search's): the search spreads over
    /// several frames, the robot driving on, so no frame pays for all of it (measured on
    /// generated maze 13: 16 turns over 60 of 1808 logged edits' scans in 0.29-0.34 ms; a
    /// larger `match_max_scans` costs more).
    pub turns_per_frame: u32,
    /// The log is dropped this long after the turn began without a re-draw, seconds.
    pub window_s: f64,
    /// Logged edits re-drawn per frame (at least 8: a frame logs up to three, and the
    /// re-drawing must catch up): the copy is re-drawn beside the live grid over
    /// several frames, the robot standing, and replaces it when done, so no frame pays for
    /// the whole log (measured: 8-20 us an edit, 1808 edits for 65 s).
    pub edits_per_frame: u32,
}

impl Default for RedrawConfig {
    fn default() -> Self {
        Self {
            blind_turn_deg: 0.0,
            min_correction_deg: 15.0,
            jump_window_s: 1.5,
            search_deg: 14.0,
            search_step_deg: 2.0,
            match_min_points: 60,
            match_min_gain_share: 0.1,
            match_max_scans: 60,
            turns_per_frame: 4,
            settled_deg: 1.0,
            window_s: 120.0,
            edits_per_frame: 64,
        }
    }
}

impl RedrawConfig {
    fn validate(&self) -> Result<(), Invalid> {
        check_ranges(
            "redraw",
            &[
                ("blind_turn_deg", self.blind_turn_deg, 0.0, 360.0),
                ("min_correction_deg", self.min_correction_deg, 1.0, 90.0),
                ("jump_window_s", self.jump_window_s, 0.05, 60.0),
                ("search_deg", self.search_deg, 0.0, 45.0),
                ("search_step_deg", self.search_step_deg, 0.1, 45.0),
                (
                    "match_min_points",
                    f64::from(self.match_min_points),
                    1.0,
                    100_000.0,
                ),
                ("match_min_gain_share", self.match_min_gain_share, 0.0, 1.0),
                (
                    "match_max_scans",
                    f64::from(self.match_max_scans),
                    1.0,
                    10_000.0,
                ),
                (
                    "turns_per_frame",
                    f64::from(self.turns_per_frame),
                    1.0,
                    1000.0,
                ),
                ("settled_deg", self.settled_deg, 0.01, 45.0),
                ("window_s", self.window_s, 1.0, 3600.0),
                (
                    "edits_per_frame",
                    f64::from(self.edits_per_frame),
                    8.0,
                    100_000.0,
                ),
            ],
        )
    }
}

/// The exploring navigator's settings, one sub-table per layer.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct NavConfig {
    /// The occupancy grid.
    pub grid: GridConfig,
    /// Scan-to-grid alignment (drift correction).
    pub scan_match: ScanMatchConfig,
    /// The costmap.
    pub costmap: CostmapConfig,
    /// Frontier choice.
    pub frontier: FrontierConfig,
    /// The path follower.
    pub controller: ControllerConfig,
    /// Progress checking and recovery.
    pub recovery: RecoveryConfig,
    /// The stall check.
    pub stall: StallConfig,
    /// Re-drawing the grid after a heading found wrong.
    pub redraw: RedrawConfig,
    /// Dead reckoning's heading calibrated from the heading fixes.
    pub calibration: super::CalibrationConfig,
}

impl NavConfig {
    /// Checks every sub-table, then what spans them; the key of an error is below the
    /// section (`grid.cell_m`).
    pub fn validate(&self) -> Result<(), Invalid> {
        self.grid.validate()?;
        self.scan_match.validate()?;
        self.costmap.validate()?;
        self.frontier.validate()?;
        self.controller.validate()?;
        self.recovery.validate()?;
        self.stall.validate()?;
        self.redraw.validate()?;
        self.calibration.validate()?;
        let f = &self.frontier;
        if f.min_view_m > f.view_m {
            return Err(Invalid::new(
                "frontier.min_view_m",
                format!("= {} must not exceed view_m ({})", f.min_view_m, f.view_m),
            ));
        }
        if f.view_m > self.grid.scan_range_m {
            return Err(Invalid::new(
                "frontier.view_m",
                format!(
                    "= {} must not exceed grid.scan_range_m ({}): a frontier looked at from \
                     farther is not seen",
                    f.view_m, self.grid.scan_range_m
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_a_bad_value_is_named_with_its_table() {
        assert_eq!(NavConfig::default().validate(), Ok(()));
        let mut c = NavConfig::default();
        c.grid.cell_m = 0.0;
        assert_eq!(c.validate().map_err(|e| e.key), Err("grid.cell_m".into()));
        let mut c = NavConfig::default();
        c.controller.aligned_deg = 30.0;
        assert_eq!(
            c.validate().map_err(|e| e.key),
            Err("controller.aligned_deg".into())
        );
        let mut c = NavConfig::default();
        c.grid.extent_m = 500.0;
        c.grid.cell_m = 0.02;
        assert_eq!(c.validate().map_err(|e| e.key), Err("grid.extent_m".into()));
        let mut c = NavConfig::default();
        c.scan_match.search_m = 1.0;
        c.scan_match.step_m = 0.005;
        assert_eq!(
            c.validate().map_err(|e| e.key),
            Err("scan_match.search_m".into())
        );
        let mut c = NavConfig::default();
        c.stall.same_share = 1.5;
        assert_eq!(
            c.validate().map_err(|e| e.key),
            Err("stall.same_share".into())
        );
        let mut c = NavConfig::default();
        c.redraw.edits_per_frame = 0;
        assert_eq!(
            c.validate().map_err(|e| e.key),
            Err("redraw.edits_per_frame".into())
        );
        let mut c = NavConfig::default();
        c.redraw.turns_per_frame = 0;
        assert_eq!(
            c.validate().map_err(|e| e.key),
            Err("redraw.turns_per_frame".into())
        );
        let mut c = NavConfig::default();
        c.recovery.rotate_step_rad = 0.0;
        assert_eq!(
            c.validate().map_err(|e| e.key),
            Err("recovery.rotate_step_rad".into())
        );
        let mut c = NavConfig::default();
        c.frontier.view_m = 2.5;
        assert_eq!(
            c.validate().map_err(|e| e.key),
            Err("frontier.view_m".into())
        );
    }

    #[test]
    fn every_number_of_a_layer_is_read_from_its_table() {
        let c: NavConfig = toml::from_str(
            "[stall]\nmoved_m = 0.3\n[recovery]\nturn_stall_shift_m = 0.2\n\
             [controller]\nmax_shifts = 2\n[grid]\nsupport_m = 0.1\n\
             [redraw]\nblind_turn_deg = 30.0",
        )
        .expect("parses");
        assert_eq!(c.stall.moved_m, 0.3);
        assert_eq!(c.stall.turned_rad, StallConfig::default().turned_rad);
        assert_eq!(c.recovery.turn_stall_shift_m, 0.2);
        assert_eq!(c.controller.max_shifts, 2);
        assert_eq!(c.grid.support_m, 0.1);
        assert_eq!(c.redraw.blind_turn_deg, 30.0);
        assert_eq!(c.validate(), Ok(()));
        assert!(toml::from_str::<NavConfig>("[stall]\nmoved = 0.3").is_err());
    }
}
