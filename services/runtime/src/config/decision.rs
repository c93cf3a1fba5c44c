//! `[decision]`: the navigator.

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Wall thresholds for one resolution.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WallThresholds {
    /// Side wall present when the side range is below this, metres (reference `a`).
    pub side_m: f64,
    /// Front wall present when the middle range is below this, metres (reference `b`).
    pub front_m: f64,
}

/// Feet to metres.
pub const M_PER_FT: f64 = 0.3048;

/// Decision policies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DecisionPolicy {
    /// The reference: crisp thresholds, the table's first option, no memory.
    Reference,
    /// Fuzzy walls with hysteresis, the navigation table, visit memory (the default).
    Fuzzy,
    /// Kostavelis et al.: the window with the smallest disparity sum is the freest.
    MeanEstimation,
    /// Free ahead unless `threshold_rate_pct` of the middle window is nearer than the front
    /// threshold; otherwise toward the farther side.
    ThresholdEstimation,
    /// Frontier exploration on a log-odds occupancy grid with a planner, a path follower and
    /// recovery behaviours (`[nav]`); the wall memberships and intersection types are still
    /// computed, as perception.
    Explore,
}

/// Walls, intersections and navigation.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DecisionConfig {
    /// The policy.
    pub policy: DecisionPolicy,
    /// Thresholds for the 320x240 ranges (reference: a = 2.35 ft, b = 2.4 ft).
    pub lo: WallThresholds,
    /// Thresholds for the 640x480 ranges (reference: a = 6.5 ft, b = 7 ft).
    pub hi: WallThresholds,
    /// Half-width of the fuzzy band around a threshold, as a fraction of it: membership
    /// falls from 1 to 0 over `threshold * (1 ± band)`.
    pub fuzzy_band: f64,
    /// Corridor rule: with the front open and both sides nearer than it, a side up to this
    /// many times `a` still counts as a wall (side windows see hallway walls obliquely).
    pub corridor_factor: f64,
    /// Weight of the newest frame in the smoothed memberships (1 = no smoothing).
    pub smoothing: f64,
    /// Frames a new command must persist before it replaces the current one (a blocked
    /// front acts at once).
    pub hold_frames: u32,
    /// Prefer the least visited branch at a junction (dead-reckoned visit grid).
    pub visit_memory: bool,
    /// Cell size of the visit grid, metres.
    pub visit_cell_m: f64,
    /// After a turn, drive at least this far before taking another branch, metres.
    pub commit_m: f64,
    /// Smallest turn executed, degrees (the reference's acos angle can be tiny).
    pub min_turn_deg: f64,
    /// Turns end on a multiple of this heading, degrees, and the heading is held on that axis
    /// while driving (indoor hallways meet at right angles); 0 turns by the reference's
    /// `acos` angle instead.
    pub snap_turn_deg: f64,
    /// Threshold estimation: share of the middle window that must be near to block it, %.
    pub threshold_rate_pct: f64,
    /// Build the local occupancy map from the obstacle scans and use it (heading fix from the
    /// walls, centring, side openings, lining up with a branch, clearance before turning).
    /// Off by default until it passes every junction test (docs/navigation.md).
    pub local_map: bool,
    /// Share of the heading error read from the walls' directions that corrects dead
    /// reckoning each frame (walls meeting at right angles, `snap_turn_deg = 90`); 0 disables.
    pub heading_fix_gain: f64,
    /// Cell size of the local occupancy map built from the obstacle scans, metres.
    pub local_map_cell_m: f64,
    /// Seconds after which a local map cell is forgotten (dead reckoning drifts).
    pub local_map_age_s: f64,
    /// Keep this far from side walls seen in the local map, metres (lateral, from the robot's
    /// centre line).
    pub side_clearance_m: f64,
}

impl Default for DecisionConfig {
    fn default() -> Self {
        Self {
            policy: DecisionPolicy::Fuzzy,
            lo: WallThresholds {
                side_m: 2.35 * M_PER_FT,
                front_m: 2.4 * M_PER_FT,
            },
            hi: WallThresholds {
                side_m: 6.5 * M_PER_FT,
                front_m: 7.0 * M_PER_FT,
            },
            fuzzy_band: 0.065,
            corridor_factor: 1.34,
            smoothing: 0.5,
            hold_frames: 3,
            visit_memory: true,
            visit_cell_m: 0.35,
            commit_m: 0.5,
            min_turn_deg: 30.0,
            snap_turn_deg: 90.0,
            threshold_rate_pct: 20.0,
            local_map: false,
            heading_fix_gain: 0.3,
            local_map_cell_m: 0.1,
            local_map_age_s: 20.0,
            side_clearance_m: 0.4,
        }
    }
}

impl DecisionConfig {
    /// Whether the decision stage fills the local occupancy map: `local_map` on, and never
    /// under `policy = "explore"`, which maps into its own grid.
    pub fn fills_local_map(&self) -> bool {
        self.local_map && self.policy != DecisionPolicy::Explore
    }

    /// Checks the section's values; the key of an error is below the section.
    pub fn validate(&self) -> Result<(), Invalid> {
        for (key, t) in [("lo", self.lo), ("hi", self.hi)] {
            if !(t.side_m > 0.0 && t.front_m > 0.0) {
                return Err(Invalid::new(key, "thresholds must be positive metres"));
            }
        }
        for (key, value, lo, hi) in [
            ("fuzzy_band", self.fuzzy_band, 0.0, 0.5),
            ("corridor_factor", self.corridor_factor, 1.0, 4.0),
            ("smoothing", self.smoothing, 0.01, 1.0),
            ("visit_cell_m", self.visit_cell_m, 0.05, 5.0),
            ("heading_fix_gain", self.heading_fix_gain, 0.0, 1.0),
            ("local_map_cell_m", self.local_map_cell_m, 0.02, 1.0),
            ("local_map_age_s", self.local_map_age_s, 0.1, 3600.0),
            ("side_clearance_m", self.side_clearance_m, 0.0, 5.0),
            ("commit_m", self.commit_m, 0.0, 10.0),
            ("min_turn_deg", self.min_turn_deg, 0.0, 90.0),
            ("snap_turn_deg", self.snap_turn_deg, 0.0, 90.0),
            ("threshold_rate_pct", self.threshold_rate_pct, 0.0, 100.0),
        ] {
            if !(lo..=hi).contains(&value) {
                return Err(Invalid::new(
                    key,
                    format!("= {value} must be in {lo}..={hi}"),
                ));
            }
        }
        if self.hold_frames > 100 {
            return Err(Invalid::new(
                "hold_frames",
                format!("= {} must be at most 100", self.hold_frames),
            ));
        }
        Ok(())
    }
}
