//! hvs decision: from ranges per window to walls, the intersection type of the reference
//! navigation table, and a motion command, with no IPC.
//!
//! Policies ([`hvs_runtime::config::DecisionPolicy`]):
//! * `reference`: crisp thresholds `a` (sides) and `b` (front), the navigation table's first
//!   option, a new command every frame, no memory (the thesis);
//! * `fuzzy` (default): wall memberships with a fuzzy band around the thresholds and a corridor
//!   rule ([`fuzzy_memberships`]), smoothed over frames with hysteresis; turns executed to the
//!   reference's `acos` angle by dead reckoning and followed by a committed stretch ahead;
//!   at a junction the least visited legal branch ([`VisitGrid`]);
//! * `explore`: frontier exploration in Nav2's layers (occupancy grid with drift correction,
//!   costmap, frontiers, planner, path follower, progress checker and recovery behaviours;
//!   [`explore`]), every number in `[nav]`;
//! * `mean-estimation` and `threshold-estimation`: the two literature methods the reference
//!   cites, on the fused windows ([`mean_estimation`], [`threshold_estimation`]).
//!
//! The thesis's "B intersection" survives only as a row of the navigation table ("straight");
//! every one of the eight wall patterns already has its own row, so our reading is: B is the
//! state in which the way ahead is open but a side is undecided (its smoothed membership is
//! inside the fuzzy band): keep going straight until it resolves.

pub mod calibration;
pub mod explore;
pub mod local_map;
pub mod nav_map;
pub mod odometry;
pub mod ordering;

mod fuzzy;
mod literature;
mod navigator;
mod reference;
mod visits;

pub use fuzzy::*;
pub use literature::*;
pub use navigator::*;
pub use reference::*;
pub use visits::*;

use std::cell::Cell;
use std::collections::{HashMap, HashSet};

use hvs_runtime::config::{
    DecisionConfig, DecisionPolicy, NavConfig, PulseTable, RobotConfig, WallThresholds,
};
use hvs_shared::messages::{
    IntersectionType, MotionCommand, ObstacleScan, RangeSource, RangeWindow,
};

pub use local_map::{CellState, LocalMap, RegionCount, wall_direction};
pub use odometry::{DeadReckonedPose, Odometry};

/// Decision policy codes carried in [`hvs_shared::messages::Decision::policy`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Policy {
    /// The reference system: crisp wall thresholds and the navigation table's first option.
    Reference = 1,
    /// Fuzzy walls, hysteresis, dead-reckoned turns and visit memory.
    Fuzzy = 2,
    /// Kostavelis et al.'s mean estimation.
    MeanEstimation = 3,
    /// Threshold estimation.
    ThresholdEstimation = 4,
    /// Frontier exploration on an occupancy grid (`[nav]`).
    Explore = 5,
}

impl Policy {
    /// The contract's code of this policy ([`hvs_shared::messages::NavPolicy`]).
    pub fn nav_policy(self) -> hvs_shared::messages::NavPolicy {
        use hvs_shared::messages::NavPolicy as N;
        match self {
            Self::Reference => N::Reference,
            Self::Fuzzy => N::Fuzzy,
            Self::MeanEstimation => N::MeanEstimation,
            Self::ThresholdEstimation => N::ThresholdEstimation,
            Self::Explore => N::Explore,
        }
    }

    /// The code of a configured policy.
    pub fn of(policy: DecisionPolicy) -> Self {
        match policy {
            DecisionPolicy::Reference => Self::Reference,
            DecisionPolicy::Fuzzy => Self::Fuzzy,
            DecisionPolicy::MeanEstimation => Self::MeanEstimation,
            DecisionPolicy::ThresholdEstimation => Self::ThresholdEstimation,
            DecisionPolicy::Explore => Self::Explore,
        }
    }
}

#[cfg(test)]
mod tests;
