//! The fuzzy policy's decision for one frame: the maneuver state machine (cruise, approach,
//! turn, commit, back up) on the smoothed memberships, the visit memory and the local map.

use super::*;

impl Navigator {
    pub(super) fn fuzzy(
        &mut self,
        sides: &SideRanges,
        near: [Option<f64>; 3],
        raw: Memberships,
        pose: DeadReckonedPose,
    ) -> NavDecision {
        let a = self.cfg.smoothing;
        let m = match self.smoothed {
            None => raw,
            Some(s) => Memberships {
                left: s.left + a * (raw.left - s.left),
                front: s.front + a * (raw.front - s.front),
                right: s.right + a * (raw.right - s.right),
            },
        };
        self.smoothed = Some(m);
        let flip = |on: bool, v: f64| if on { v > 1.0 - WALL_ON } else { v >= WALL_ON };
        self.walls = Walls {
            left: flip(self.walls.left, m.left),
            front: flip(self.walls.front, m.front),
            right: flip(self.walls.right, m.right),
        };
        let b = sides.thresholds(1, &self.cfg).front_m;
        // The front: a wall, or no data right after a near wall (closer than the matcher's
        // shortest range).
        if let Some(r) = sides.middle_m {
            self.front_was_near = r < 2.0 * b;
        }
        // The local map: something in the robot's path within 0.25 m of its front edge
        // (a corner approached at an angle, a wall the windows average away).
        let now = self.now_ns;
        let path_blocked = self
            .map
            .count_region(
                &pose,
                (
                    self.footprint.front_edge_m,
                    self.footprint.front_edge_m + 0.25,
                ),
                (
                    -self.footprint.sweep_half_width_m,
                    self.footprint.sweep_half_width_m,
                ),
                now,
            )
            .occupied
            >= 2;
        let front_blocked =
            self.walls.front || path_blocked || (sides.middle_m.is_none() && self.front_was_near);
        // What the sides looked like on the approach (front between 1.4 b and 3.5 b): when the
        // front wall is reached, the side windows see nothing but that wall.
        // A side wall there converges on the front wall (its window's range is clearly shorter
        // than the front's); an open side shows the far wall at about the front's range.
        if let Some(front) = sides.middle_m.filter(|&r| r >= 1.9 * b && r <= 3.1 * b) {
            let band = self.cfg.fuzzy_band;
            let view = Memberships {
                left: near_membership(near[0], APPROACH_RATIO * front, band),
                front: 1.0,
                right: near_membership(near[2], APPROACH_RATIO * front, band),
            };
            self.approach = Some(match self.approach {
                None => view,
                Some(p) => Memberships {
                    left: p.left + a * (view.left - p.left),
                    front: 1.0,
                    right: p.right + a * (view.right - p.right),
                },
            });
        }
        let undecided = |v: f64| v > 1.0 - WALL_ON && v < WALL_ON;
        let no_data = sides.left_m.is_none() && sides.middle_m.is_none() && sides.right_m.is_none();
        let mut intersection = if no_data && !front_blocked {
            IntersectionType::Unknown
        } else if front_blocked {
            // What the side windows showed on the approach; a side the local map shows
            // open is open (the windows see a side opening only obliquely, from afar).
            let view = self.approach.unwrap_or(m);
            classify(Walls {
                left: view.left >= 0.5 && self.opening_offset(&pose, true).is_none(),
                front: true,
                right: view.right >= 0.5 && self.opening_offset(&pose, false).is_none(),
            })
        } else {
            classify(self.walls)
        };
        if !front_blocked && !undecided(m.front) && (undecided(m.left) || undecided(m.right)) {
            intersection = IntersectionType::BIntersection;
        }
        let decision = |command: MotionCommand, angle: f64, ramp: u32, intersection| NavDecision {
            memberships: m,
            intersection,
            command,
            turn_angle_deg: angle,
            ramp,
            pose,
        };
        // Wedged: dead reckoning integrates the commands, but if the picture does not change
        // for a second while the wheels are told to move, the robot is stuck against a wall.
        // The view is compared with the one the still run began with, not with the previous
        // frame: at 0.27 m/s a wall 2.7 m ahead comes 0.7 % nearer a frame, and a
        // frame-to-frame test took a robot driving down an open hallway for a wedged one.
        // The windows' nearest points (`near_m`, a low percentile) are compared, not their
        // ranges: a window with few valid pixels had its range jump by 0.3 m from frame to
        // frame while the robot stood pinned at a corner (its nearest points moved by
        // 0.01 m), and the robot "turned" against that corner for 90 s.
        let view = near;
        let same = !view_changed(&self.last_view, &view, STILL_CHANGE, STILL_CHANGE_M);
        if !same {
            self.last_view = view;
        }
        let moving = !matches!(self.current, MotionCommand::Stop);
        // A blind view (no window has data: a wall closer than the matcher's shortest range)
        // stays the same however the robot moves, so it says nothing about being wedged.
        let blind = view.iter().all(Option::is_none);
        self.frozen_frames = if same && moving && !blind {
            self.frozen_frames + 1
        } else {
            0
        };
        // A noisy view can defeat that test: also wedged when dead reckoning has the robot
        // `WEDGE_DRIVE_M` on (the front window seeing something) or `WEDGE_TURN_DEG` round
        // (any window seeing something) since the view last changed by more than
        // `WEDGE_CHANGE` of a range.
        let odo = (self.odometry.distance_m(), pose.heading_rad);
        let anchor = match self.view_anchor {
            Some((v, d, h)) if !view_changed(&v, &view, WEDGE_CHANGE, WEDGE_CHANGE_M) => (v, d, h),
            _ => (view, odo.0, odo.1),
        };
        self.view_anchor = Some(anchor);
        let wedged_noisy = (odo.0 - anchor.1 >= WEDGE_DRIVE_M && view[1].is_some())
            || ((odo.1 - anchor.2).abs() >= WEDGE_TURN_DEG.to_radians() && !blind);
        // Blind for a whole turn round: a robot turning freely sees something within a
        // turn; one pinned by a corner closer than the matcher's shortest range turns only
        // in dead reckoning (such a robot turned on the spot for 200 s).
        self.blind_turn_rad = if blind {
            self.blind_turn_rad + (pose.heading_rad - self.last_heading_rad).abs()
        } else {
            0.0
        };
        self.last_heading_rad = pose.heading_rad;
        let wedged_blind = self.blind_turn_rad >= std::f64::consts::TAU;
        if self.frozen_frames >= STUCK_FRAMES || wedged_noisy || wedged_blind {
            // The view has not changed since the anchor: the wheels turned the robot only in
            // dead reckoning. Taking that turn back keeps the heading on the hallway axes
            // (a robot pinned while turning kept 45 degrees of turn it never made, beyond
            // what the walls' directions can fix, and turned on the spot for 80 s facing
            // corners). A blind view says nothing about the turn: no correction then.
            if !blind {
                self.odometry.correct_heading(anchor.2 - pose.heading_rad);
            }
            self.frozen_frames = 0;
            self.blind_turn_rad = 0.0;
            self.view_anchor = None;
            self.attempts = 0;
            // Wedged: back away; if backing up is what is stuck (a corner behind), pull
            // forward instead.
            self.maneuver = if matches!(self.maneuver, Maneuver::Backup { .. }) {
                Maneuver::Creep {
                    until_m: self.odometry.distance_m() + BACKUP_M,
                }
            } else {
                Maneuver::Backup {
                    until_m: self.odometry.distance_m() + BACKUP_M,
                }
            };
        }
        // A maneuver in progress.
        match self.maneuver {
            Maneuver::Backup { until_m } => {
                if self.odometry.distance_m() < until_m {
                    self.current = MotionCommand::Reverse;
                    return decision(MotionCommand::Reverse, 0.0, 0, intersection);
                }
                self.maneuver = Maneuver::Cruise;
                self.current = MotionCommand::Stop;
            }
            Maneuver::Turning {
                command,
                start_heading,
                target_rad,
                ramp,
            } => {
                let turned = (pose.heading_rad - start_heading).abs();
                let lead = self.odometry.turn_rate_rad_s().abs() * TURN_LEAD_S;
                if turned + lead < target_rad {
                    self.current = command;
                    return decision(command, target_rad.to_degrees(), ramp, intersection);
                }
                self.approach = None;
                self.front_was_near = false;
                // Blind ahead right after a turn: a wall closer than the matcher's shortest
                // range (the side windows may still see its ends). Committing on a blind
                // front window drove a robot into a wall 0.3 m ahead, and the branch it had
                // turned away from was never tried.
                if !front_blocked && sides.middle_m.is_some() {
                    return decision(self.commit(), 0.0, 0, intersection);
                }
                // Facing a wall: stand still before choosing the next turn. Turning on at
                // once kept the dead-reckoned heading from being fixed by the walls (the fix
                // waits for a slow turn rate), and a robot whose heading was 30 degrees off
                // the axes turned on the spot for minutes, every quarter turn ending at a
                // corner.
                self.maneuver = Maneuver::Settle {
                    until_ns: now.saturating_add(SETTLE_NS),
                    command,
                    target_rad,
                };
                self.current = MotionCommand::Stop;
                return decision(MotionCommand::Stop, 0.0, 0, intersection);
            }
            Maneuver::Settle {
                until_ns,
                command,
                target_rad,
            } => {
                if now < until_ns {
                    self.current = MotionCommand::Stop;
                    return decision(MotionCommand::Stop, 0.0, 0, intersection);
                }
                if !front_blocked && sides.middle_m.is_some() {
                    return decision(self.commit(), 0.0, 0, intersection);
                }
                self.maneuver = Maneuver::Cruise;
                // Still blocked: the branch guessed from afar was not there. Try the other
                // side (half a turn back past the start), then, if that is a wall too, the
                // way back (a dead end). After turning round (a dead end) a quarter turn on.
                self.attempts += 1;
                let (next, target) = if self.attempts == 1 && target_rad < 2.5 {
                    let other = if command == MotionCommand::Left {
                        MotionCommand::Right
                    } else {
                        MotionCommand::Left
                    };
                    (other, std::f64::consts::PI)
                } else {
                    (command, self.turn_target(pose, command, 90.0))
                };
                let sent = self.start_turn(&pose, next, target);
                return decision(sent, target.to_degrees(), 0, intersection);
            }
            Maneuver::Creep { until_m } => {
                let clear = self
                    .map
                    .count_region(
                        &pose,
                        (
                            self.footprint.front_edge_m,
                            self.footprint.front_edge_m + 0.1,
                        ),
                        (
                            -self.footprint.sweep_half_width_m,
                            self.footprint.sweep_half_width_m,
                        ),
                        now,
                    )
                    .occupied
                    == 0;
                if self.odometry.distance_m() < until_m && clear {
                    self.current = MotionCommand::Forward;
                    return decision(MotionCommand::Forward, 0.0, 0, intersection);
                }
                self.maneuver = Maneuver::Cruise;
                self.current = MotionCommand::Stop;
            }
            Maneuver::Commit { until_m } => {
                if self.odometry.distance_m() < until_m && !front_blocked {
                    if let Some(turn) = self.axis_correction(pose, [None; 3]) {
                        return decision(turn.0, turn.1.to_degrees(), 0, intersection);
                    }
                    self.current = MotionCommand::Forward;
                    return decision(MotionCommand::Forward, 0.0, 0, intersection);
                }
                self.maneuver = Maneuver::Cruise;
            }
            Maneuver::Cruise => {}
        }
        if !front_blocked {
            // Open ahead: straight on, a legal option of every open-front row of the table
            // (hallway, both T's with a side wall, X, B). A forward camera with a 45-55 degree
            // field of view sees a side opening 1-3 m before reaching it and cannot place it
            // well enough to turn into it; side branches are taken where a front wall forces
            // the choice. Keep the heading on the hallway axis (dead reckoning).
            let proposal = if intersection == IntersectionType::Unknown {
                // Nothing seen: stop, and after a second look elsewhere.
                self.blind_frames += 1;
                if self.blind_frames >= STUCK_FRAMES {
                    self.blind_frames = 0;
                    let target = self.turn_target(pose, MotionCommand::Left, 90.0);
                    let sent = self.start_turn(&pose, MotionCommand::Left, target);
                    return decision(sent, target.to_degrees(), 0, intersection);
                }
                MotionCommand::Stop
            } else {
                self.blind_frames = 0;
                MotionCommand::Forward
            };
            // With the visit memory: a side opening beside the robot whose way is less
            // visited than the way ahead is taken (the local map saw it on the approach).
            if self.cfg.visit_memory
                && self.cfg.snap_turn_deg > 0.0
                && intersection != IntersectionType::Unknown
                && let Some(command) = self.side_branch(&pose)
            {
                let target = self.turn_target(pose, command, 90.0);
                self.attempts = 0;
                let sent = self.start_turn(&pose, command, target);
                return decision(sent, target.to_degrees(), 0, intersection);
            }
            if let Some(turn) = self.axis_correction(pose, near) {
                return decision(turn.0, turn.1.to_degrees(), 0, intersection);
            }
            let command = self.hold(proposal);
            return decision(command, 0.0, 0, intersection);
        }
        // The front is blocked: the table's options for what the approach showed, the visit
        // memory choosing among the branches.
        let table = options(intersection);
        let moving: Vec<MotionCommand> = table
            .iter()
            .copied()
            .filter(|c| matches!(c, MotionCommand::Left | MotionCommand::Right))
            .collect();
        let mut command = match (moving.first(), self.cfg.visit_memory && moving.len() > 1) {
            (None, _) => MotionCommand::Reverse,
            (Some(&first), false) => first,
            (Some(&first), true) => moving
                .iter()
                .copied()
                .min_by_key(|&c| {
                    self.grid
                        .score(pose.x_m, pose.y_m, pose.heading_rad + branch_heading(c))
                })
                .unwrap_or(first),
        };
        // The local map's free way ahead (the dead-end look and the line-up use it).
        let clearance = self.front_clearance_m(&pose);
        // A dead end read from the approach may have an opening beside the front wall: the
        // side window sees the hallway's wall converge on the front wall up to the corner,
        // and the camera never sees beside the robot. Unless the local map saw a wall
        // there, look (a quarter turn that way; the settle after it tries the other side,
        // then the way back). Without the local map there is nothing to tell a side seen
        // to be a wall from one never seen: the robot turns back as the table says.
        let mut probe_attempts = None;
        if command == MotionCommand::Reverse && self.cfg.local_map && self.cfg.snap_turn_deg > 0.0 {
            let wall_m = self.footprint.front_edge_m + clearance.unwrap_or(0.5);
            let unseen: Vec<(MotionCommand, bool)> =
                [(MotionCommand::Left, true), (MotionCommand::Right, false)]
                    .into_iter()
                    .filter(|&(_, left)| !self.corner_wall_seen(&pose, left, wall_m))
                    .collect();
            let pick = if self.cfg.visit_memory {
                unseen.iter().copied().min_by_key(|&(c, _)| {
                    self.grid
                        .score(pose.x_m, pose.y_m, pose.heading_rad + branch_heading(c))
                })
            } else {
                unseen.first().copied()
            };
            if let Some((c, _)) = pick {
                command = c;
                // With one side unseen, a wall there means the way back (on round).
                probe_attempts = Some(if unseen.len() == 2 { 0 } else { 1 });
            }
        }
        // Line up with the middle of the opening before turning into it (the front wall
        // stops the robot about 1 m short of it; a corner opening starts beside the robot).
        let side = match command {
            MotionCommand::Left => Some(true),
            MotionCommand::Right => Some(false),
            _ => None,
        };
        if let Some(left) = side {
            let offset = self.opening_offset(&pose, left);
            // How far to creep on before turning, if at all.
            let reach = match offset {
                // An opening the local map has not seen beside the robot is taken for one
                // at the corner with the front wall (the hallway ends in a crossing one, or
                // turns): its middle is half its width from that wall, so the robot creeps
                // on to `CORNER_TURN_CLEARANCE_M` from it before turning.
                None if self.turn_shifts == 0 => clearance
                    .filter(|&c| c > CORNER_TURN_CLEARANCE_M + LINE_UP_TOLERANCE_M)
                    .map(|c| c - CORNER_TURN_CLEARANCE_M),
                None => None,
                Some(offset) => {
                    let path_clear = self
                        .map
                        .count_region(
                            &pose,
                            (
                                self.footprint.front_edge_m,
                                self.footprint.front_edge_m + offset + 0.12,
                            ),
                            (
                                -self.footprint.sweep_half_width_m,
                                self.footprint.sweep_half_width_m,
                            ),
                            now,
                        )
                        .occupied
                        == 0;
                    // With something in the way (the front wall, when the opening's middle
                    // is placed too near it), as far as the front wall allows a turn:
                    // turning at once put the robot 0.45 m short of a corridor's middle, and
                    // it hit the end of the corridor's wall.
                    if path_clear {
                        Some(offset)
                    } else {
                        clearance.map(|c| (c - CORNER_TURN_CLEARANCE_M).min(offset))
                    }
                }
            };
            if let Some(reach) = reach.filter(|&r| r > LINE_UP_TOLERANCE_M) {
                self.maneuver = Maneuver::Creep {
                    until_m: self.odometry.distance_m() + reach,
                };
                self.current = MotionCommand::Forward;
                return decision(MotionCommand::Forward, 0.0, 0, intersection);
            }
            if let Some(offset) = offset.filter(|&o| o < -LINE_UP_TOLERANCE_M) {
                self.maneuver = Maneuver::Backup {
                    until_m: self.odometry.distance_m() - offset,
                };
                self.current = MotionCommand::Reverse;
                return decision(MotionCommand::Reverse, 0.0, 0, intersection);
            }
        }
        // Turns run with ramp 0 (the reference's ramp is not used): the reference's ramp set
        // the turn's duration (and so its angle) open loop; here dead reckoning ends the turn,
        // and a ramp would only let the robot roll on into the junction while the pulses slew.
        let (angle, _reference_ramp) = reference_turn(sides, command);
        let (turn, turn_rad) = match command {
            // Dead end: turn around in place rather than back up blind.
            MotionCommand::Reverse => (MotionCommand::Right, std::f64::consts::PI),
            c => (c, self.turn_target(pose, c, angle)),
        };
        self.attempts = probe_attempts.unwrap_or(0);
        let sent = self.start_turn(&pose, turn, turn_rad);
        decision(sent, turn_rad.to_degrees(), 0, intersection)
    }
}
