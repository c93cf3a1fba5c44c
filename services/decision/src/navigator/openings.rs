//! What the navigator asks the local map: free columns and side openings, where an opening
//! ends, the clearance ahead, corner walls, the side branch to take, the axis correction.

use super::*;

impl Navigator {
    /// Whether a column of the region beside the robot, `ahead_m` along its way, is free:
    /// no wall, and at least 70 % of it seen free.
    pub(super) fn column_free(&self, pose: &DeadReckonedPose, left: bool, ahead_m: f64) -> bool {
        let n = self
            .map
            .count_region(pose, (ahead_m, ahead_m), side_band(left), self.now_ns);
        n.occupied == 0 && n.free * 10 >= (n.free + n.occupied + n.unknown) * 7
    }

    /// Whether the local map saw the region beside the robot (from 0.4 m behind to 1 m ahead)
    /// well enough to say where it is open: at most half of it unknown.
    pub(super) fn side_seen(&self, pose: &DeadReckonedPose, left: bool) -> bool {
        let n = self
            .map
            .count_region(pose, (-0.4, 1.0), side_band(left), self.now_ns);
        n.unknown * 2 <= n.free + n.occupied + n.unknown
    }

    /// The middle of the first side opening at least `Footprint::opening_min_m` long beside the robot,
    /// from 0.4 m behind its centre to 1.5 m ahead, as a distance along its way (negative:
    /// behind).
    pub(super) fn opening_offset(&self, pose: &DeadReckonedPose, left: bool) -> Option<f64> {
        const STEP: f64 = 0.05;
        let mut start: Option<f64> = None;
        const LAST: usize = 38; // 0.4 m behind to 1.5 m ahead
        for k in 0..=LAST {
            let o = -0.4 + k as f64 * STEP;
            let free = self.column_free(pose, left, o);
            if free {
                start.get_or_insert(o);
            }
            if let Some(s) = start {
                let end = if free { o } else { o - STEP };
                if (!free || k == LAST) && end - s + STEP >= self.footprint.opening_min_m {
                    return Some(0.5 * (s + self.corner_opening_end(pose, left, end)));
                }
                if !free {
                    start = None;
                }
            }
        }
        None
    }

    /// Where a side opening seen free up to `end_m` ahead really ends: at the wall ahead
    /// when that wall is near (`CORNER_REACH_M`) and the map holds nothing beside the robot
    /// between the two. The part of a corner opening next to the wall ahead stays hidden
    /// from a forward camera until the robot is beside it; taken for the opening's end, it
    /// put the middle 0.2 to 0.45 m short, and the robot turned into the passage beyond
    /// off-centre and hit its corner (5 of 18 collisions in 16 maze runs).
    pub(super) fn corner_opening_end(
        &self,
        pose: &DeadReckonedPose,
        left: bool,
        end_m: f64,
    ) -> f64 {
        match self.front_clearance_m(pose) {
            Some(c) if self.footprint.front_edge_m + c <= CORNER_REACH_M => {
                let wall_m = self.footprint.front_edge_m + c;
                let between = self.map.count_region(
                    pose,
                    (end_m + 0.05, wall_m - 0.1),
                    side_band(left),
                    self.now_ns,
                );
                if between.occupied == 0 {
                    wall_m.max(end_m)
                } else {
                    end_m
                }
            }
            _ => end_m,
        }
    }

    /// How far ahead of the robot's front edge the local map holds an obstacle in the
    /// corridor it sweeps (up to 1.5 m, in 0.05 m steps), if it holds one.
    pub(super) fn front_clearance_m(&self, pose: &DeadReckonedPose) -> Option<f64> {
        if let Some((asked, clearance)) = self.front_clearance.get()
            && asked == *pose
        {
            return clearance;
        }
        let clearance = (0..=30).map(|k| k as f64 * 0.05).find(|&d| {
            self.map
                .count_region(
                    pose,
                    (
                        self.footprint.front_edge_m + d,
                        self.footprint.front_edge_m + d,
                    ),
                    (
                        -self.footprint.sweep_half_width_m,
                        self.footprint.sweep_half_width_m,
                    ),
                    self.now_ns,
                )
                .occupied
                >= 2
        });
        self.front_clearance.set(Some((*pose, clearance)));
        clearance
    }

    /// Whether the local map saw a wall beside the robot (left or right, 0.35..0.8 m from
    /// its centre line) along the last 0.65 m before the wall ahead (`wall_m` from its
    /// centre), the wall a corner opening would leave out: something occupied beside at
    /// least half of the way (the corner of an opening, or a wall across it further out,
    /// is not such a wall).
    pub(super) fn corner_wall_seen(
        &self,
        pose: &DeadReckonedPose,
        left: bool,
        wall_m: f64,
    ) -> bool {
        const STEPS: usize = 14;
        let lateral = if left { (0.35, 0.8) } else { (-0.8, -0.35) };
        let beside = (0..STEPS)
            .map(|k| wall_m - 0.75 + k as f64 * 0.05)
            .filter(|&a| {
                self.map
                    .count_region(pose, (a, a), lateral, self.now_ns)
                    .occupied
                    > 0
            })
            .count();
        beside * 2 >= STEPS
    }

    /// A side opening beside the robot (left or right) whose way is less visited than the
    /// way ahead, if any: the local map must show the region beside the robot free for
    /// `OPENING_HALF_M` either side of its centre, with no wall in it.
    pub(super) fn side_branch(&self, pose: &DeadReckonedPose) -> Option<MotionCommand> {
        let ahead = self.grid.score(pose.x_m, pose.y_m, pose.heading_rad);
        let mut best: Option<(MotionCommand, u32)> = None;
        for (command, left) in [(MotionCommand::Left, true), (MotionCommand::Right, false)] {
            if !self
                .opening_offset(pose, left)
                .is_some_and(|o| o.abs() <= LINE_UP_TOLERANCE_M)
            {
                continue;
            }
            let score = self.grid.score(
                pose.x_m,
                pose.y_m,
                pose.heading_rad + branch_heading(command),
            );
            if score < ahead && best.is_none_or(|(_, s)| score < s) {
                best = Some((command, score));
            }
        }
        best.map(|(c, _)| c)
    }

    /// A short turn onto the wanted heading when the dead-reckoned heading is more than 6
    /// degrees off it: the nearest hallway axis (a multiple of `snap_turn_deg`), bent by 12
    /// degrees away from a side wall that is too close. Without the bend a robot that left a
    /// turn off-centre scrapes along the wall, and its next turn in place sweeps a corner into
    /// it.
    pub(super) fn axis_correction(
        &mut self,
        pose: DeadReckonedPose,
        near: [Option<f64>; 3],
    ) -> Option<(MotionCommand, f64)> {
        let snap = self.cfg.snap_turn_deg.to_radians();
        if snap <= 0.0 {
            return None;
        }
        let axis = (pose.heading_rad / snap).round() * snap;
        // Keep clear of a side wall closer than about 0.3 m (a side window's nearest points lie
        // about twice the wall's lateral distance ahead: its outer edge is 26.5 degrees off
        // the axis at f = 320 px). Balancing the two sides was tried and made the robot dither:
        // the side windows' nearest edge points are too sparse for a fine lateral estimate.
        let max_bend = 12f64.to_radians();
        // The local map gives the side walls' lateral distances: centre between two walls,
        // keep `side_clearance_m` from one (12 degrees of bend per 0.15 m off).
        let per_m = max_bend / 0.15;
        let look = |left| {
            self.map
                .side_distance(&pose, left, (-0.2, 0.3), 0.9, self.now_ns)
        };
        let clearance = self.cfg.side_clearance_m;
        let close = |v: Option<f64>| v.is_some_and(|v| v < CLEARANCE_NEAR_M);
        // How far the robot is off where it should be (positive: too far right), ignoring
        // less than 0.08 m (the map's cells are 0.1 m).
        let off = match (look(true), look(false)) {
            (Some(l), Some(r)) => Some(0.5 * (l - r)),
            (Some(l), None) => Some(-(clearance - l).max(0.0)),
            (None, Some(r)) => Some((clearance - r).max(0.0)),
            (None, None) => None,
        };
        let bend = match off {
            Some(off) if off.abs() < 0.08 => 0.0,
            Some(off) => (off * per_m).clamp(-max_bend, max_bend),
            None => match (close(near[0]), close(near[2])) {
                (false, true) => max_bend,
                (true, false) => -max_bend,
                _ => 0.0,
            },
        };
        let error = pose.heading_rad - (axis + bend);
        if error.abs() < 6f64.to_radians() || self.odometry.distance_m() < self.next_correction_m {
            return None;
        }
        self.next_correction_m = self.odometry.distance_m() + CORRECTION_SPACING_M;
        let command = if error > 0.0 {
            MotionCommand::Right
        } else {
            MotionCommand::Left
        };
        self.begin_turning(&pose, command, error.abs());
        Some((command, error.abs()))
    }
}
