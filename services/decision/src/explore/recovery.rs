//! Progress checking and recovery behaviours, as small state machines (Nav2's progress
//! checker and behaviour server): when the robot has not got `progress_m` nearer its goal
//! within `progress_timeout_s`, it backs up, rotates and waits, then plans again; a goal that
//! needed more than `max_per_goal` recoveries is given up.

use hvs_runtime::config::RecoveryConfig;
use hvs_shared::messages::MotionCommand;

/// Watches the robot's progress: the path cost to its goal falling, or the robot moving.
#[derive(Debug, Clone, Copy, Default)]
pub struct ProgressChecker {
    /// Path cost to the goal and position when progress was last made, and when.
    anchor: Option<(f64, (f64, f64), u64)>,
}

impl ProgressChecker {
    /// Starts watching afresh (after a recovery).
    pub fn reset(&mut self) {
        self.anchor = None;
    }

    /// Feeds the path cost to the goal and the robot's position at `now_ns`; true when
    /// neither the cost fell by `progress_m` (a new goal only restarts the cost, not the
    /// clock: a robot that keeps changing its goal without moving is stalled too) nor the
    /// robot moved `progress_m` within `progress_timeout_s`.
    pub fn stalled(
        &mut self,
        cfg: &RecoveryConfig,
        goal_cost_m: f64,
        new_goal: bool,
        position_m: (f64, f64),
        now_ns: u64,
    ) -> bool {
        match self.anchor {
            None => {
                self.anchor = Some((goal_cost_m, position_m, now_ns));
                false
            }
            Some((best, at, since)) => {
                let moved = (position_m.0 - at.0).hypot(position_m.1 - at.1);
                if (!new_goal && goal_cost_m <= best - cfg.progress_m) || moved >= cfg.progress_m {
                    self.anchor = Some((goal_cost_m, position_m, now_ns));
                    return false;
                }
                if new_goal {
                    self.anchor = Some((goal_cost_m, at, since));
                }
                super::elapsed_s(since, now_ns) > cfg.progress_timeout_s
            }
        }
    }
}

/// One recovery behaviour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Behaviour {
    /// Back up `distance_m` (from the odometry distance when it starts).
    BackUp {
        /// How far, metres.
        distance_m: f64,
        /// Odometry distance at which it ends, once started.
        until_m: Option<f64>,
    },
    /// Drive ahead `distance_m` (from the odometry distance when it starts).
    Forward {
        /// How far, metres.
        distance_m: f64,
        /// Odometry distance at which it ends, once started.
        until_m: Option<f64>,
    },
    /// Rotate in place by `target_rad`.
    Rotate {
        /// Turn to make, radians.
        target_rad: f64,
        /// Counter-clockwise.
        left: bool,
        /// Heading when it started.
        start_rad: Option<f64>,
    },
    /// Stand still for `wait_s`.
    Wait {
        /// How long, seconds.
        wait_s: f64,
        /// End time, once started.
        until_ns: Option<u64>,
    },
}

/// What a recovery step sees.
#[derive(Debug, Clone, Copy)]
pub struct RecoveryInput {
    /// Now.
    pub now_ns: u64,
    /// Odometry distance, metres.
    pub distance_m: f64,
    /// Heading, radians.
    pub heading_rad: f64,
    /// Backing up is clear.
    pub behind_clear: bool,
    /// Driving ahead `turn_stall_shift_m` is clear (no wall, mostly seen free).
    pub ahead_clear: bool,
    /// The disc the footprint sweeps turning left holds no seen obstacle.
    pub left_clear: bool,
    /// The same turning right.
    pub right_clear: bool,
}

/// A running sequence of behaviours.
#[derive(Debug, Clone, PartialEq)]
pub struct Recovery {
    steps: Vec<Behaviour>,
    /// When the current step must end.
    deadline_ns: Option<u64>,
    /// How long a step may run before it ends anyway (`behaviour_limit_s`), nanoseconds.
    limit_ns: u64,
}

/// Rotation steps of `total_rad`, each at most `rotate_step_rad` and followed by a pause.
fn rotation(cfg: &RecoveryConfig, total_rad: f64, left: bool) -> Vec<Behaviour> {
    let n = (total_rad / cfg.rotate_step_rad).ceil().max(1.0) as usize;
    let mut out = Vec::with_capacity(2 * n);
    for _ in 0..n {
        out.push(Behaviour::Rotate {
            target_rad: total_rad / n as f64,
            left,
            start_rad: None,
        });
        out.push(Behaviour::Wait {
            wait_s: cfg.rotate_pause_s,
            until_ns: None,
        });
    }
    out
}

impl Recovery {
    /// Starts a recovery: back up (when clear behind), rotate toward the freer side, wait.
    pub fn start(cfg: &RecoveryConfig, input: &RecoveryInput) -> Self {
        let mut steps = Vec::new();
        if input.behind_clear && cfg.backup_m > 0.0 {
            steps.push(Behaviour::BackUp {
                distance_m: cfg.backup_m,
                until_m: None,
            });
        }
        if cfg.rotate_deg > 0.0 {
            let left = input.left_clear || !input.right_clear;
            steps.extend(rotation(cfg, cfg.rotate_deg.to_radians(), left));
        }
        steps.push(Behaviour::Wait {
            wait_s: cfg.wait_s,
            until_ns: None,
        });
        steps.reverse();
        Self::of(cfg, steps)
    }

    /// A sequence of `steps`, the first last.
    fn of(cfg: &RecoveryConfig, steps: Vec<Behaviour>) -> Self {
        Self {
            steps,
            deadline_ns: None,
            limit_ns: (cfg.behaviour_limit_s * 1e9) as u64,
        }
    }

    /// After a stall (the robot pinned while it moved): a stalled turn with the way ahead
    /// clear drives ahead `turn_stall_shift_m` and pauses; otherwise back up when clear
    /// behind, then rotate away from the turn that stalled (`stalled_left`; `None`: it was
    /// not turning, rotate toward the freer side), then wait.
    pub fn after_stall(
        cfg: &RecoveryConfig,
        input: &RecoveryInput,
        stalled_left: Option<bool>,
    ) -> Self {
        if stalled_left.is_some() && input.ahead_clear {
            // A turn held by something unseen beside or behind: move off it, then let the
            // controller turn again from there.
            return Self::of(
                cfg,
                vec![
                    Behaviour::Wait {
                        wait_s: cfg.rotate_pause_s,
                        until_ns: None,
                    },
                    Behaviour::Forward {
                        distance_m: cfg.turn_stall_shift_m,
                        until_m: None,
                    },
                ],
            );
        }
        let mut r = Self::start(cfg, input);
        if let Some(was_left) = stalled_left {
            for b in &mut r.steps {
                if let Behaviour::Rotate { left, .. } = b {
                    *left = !was_left;
                }
            }
        }
        r
    }

    /// A look around: rotate in place by `degrees` counter-clockwise, pausing on the way.
    pub fn look_around(cfg: &RecoveryConfig, degrees: f64) -> Self {
        let mut steps = rotation(cfg, degrees.to_radians(), true);
        steps.reverse();
        Self::of(cfg, steps)
    }

    /// The behaviour running now.
    pub fn behaviour(&self) -> Option<Behaviour> {
        self.steps.last().copied()
    }

    /// The command for this frame, or `None` once the sequence is over.
    pub fn step(&mut self, input: &RecoveryInput) -> Option<MotionCommand> {
        while let Some(b) = self.steps.last_mut() {
            let deadline = *self
                .deadline_ns
                .get_or_insert(input.now_ns.saturating_add(self.limit_ns));
            let command = match b {
                Behaviour::BackUp {
                    distance_m,
                    until_m,
                } => {
                    let until = *until_m.get_or_insert(input.distance_m + *distance_m);
                    (input.distance_m < until && input.behind_clear)
                        .then_some(MotionCommand::Reverse)
                }
                Behaviour::Forward {
                    distance_m,
                    until_m,
                } => {
                    let until = *until_m.get_or_insert(input.distance_m + *distance_m);
                    (input.distance_m < until && input.ahead_clear)
                        .then_some(MotionCommand::Forward)
                }
                Behaviour::Rotate {
                    target_rad,
                    left,
                    start_rad,
                } => {
                    let start = *start_rad.get_or_insert(input.heading_rad);
                    // A rotation stops where an obstacle enters its disc.
                    let clear = if *left {
                        input.left_clear
                    } else {
                        input.right_clear
                    };
                    (clear && (input.heading_rad - start).abs() < *target_rad).then_some(if *left {
                        MotionCommand::Left
                    } else {
                        MotionCommand::Right
                    })
                }
                Behaviour::Wait { wait_s, until_ns } => {
                    let until = *until_ns
                        .get_or_insert(input.now_ns.saturating_add((*wait_s * 1e9) as u64));
                    (input.now_ns < until).then_some(MotionCommand::Stop)
                }
            };
            if command.is_some() && input.now_ns < deadline {
                return command;
            }
            self.steps.pop();
            self.deadline_ns = None;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn progress_stalls_only_after_the_timeout_without_getting_nearer() {
        let cfg = RecoveryConfig::default();
        let mut p = ProgressChecker::default();
        let s = 1_000_000_000u64;
        let here = (0.0, 0.0);
        assert!(!p.stalled(&cfg, 5.0, true, here, 0));
        assert!(!p.stalled(&cfg, 4.95, false, here, 3 * s));
        assert!(p.stalled(&cfg, 4.95, false, here, 7 * s));
        p.reset();
        assert!(!p.stalled(&cfg, 4.0, true, here, 8 * s));
        assert!(!p.stalled(&cfg, 3.0, false, here, 13 * s));
        assert!(!p.stalled(&cfg, 3.0, false, here, 18 * s));
        assert!(p.stalled(&cfg, 3.0, false, here, 20 * s));
        // Changing goals without moving does not count as progress.
        p.reset();
        assert!(!p.stalled(&cfg, 3.0, true, here, 30 * s));
        assert!(!p.stalled(&cfg, 1.0, true, here, 33 * s));
        assert!(p.stalled(&cfg, 0.5, true, here, 37 * s));
        // Moving does.
        p.reset();
        assert!(!p.stalled(&cfg, 3.0, true, here, 40 * s));
        assert!(!p.stalled(&cfg, 3.0, false, (0.5, 0.0), 45 * s));
        assert!(!p.stalled(&cfg, 3.0, false, (0.5, 0.0), 50 * s));
    }

    #[test]
    fn a_recovery_backs_up_rotates_in_steps_waits_and_ends() {
        let cfg = RecoveryConfig::default();
        let mut input = RecoveryInput {
            now_ns: 0,
            distance_m: 10.0,
            heading_rad: 0.0,
            behind_clear: true,
            ahead_clear: true,
            left_clear: true,
            right_clear: true,
        };
        let mut r = Recovery::start(&cfg, &input);
        assert_eq!(r.step(&input), Some(MotionCommand::Reverse));
        input.distance_m += cfg.backup_m;
        let mut lefts = 0;
        let mut pauses = 0;
        for _ in 0..1000 {
            match r.step(&input) {
                Some(MotionCommand::Left) => {
                    lefts += 1;
                    input.heading_rad += 0.1;
                }
                Some(MotionCommand::Stop) => {
                    pauses += 1;
                    input.now_ns += 100_000_000;
                }
                None => break,
                other => panic!("unexpected {other:?}"),
            }
        }
        assert_eq!(r.step(&input), None);
        assert!((lefts as f64 * 0.1 - cfg.rotate_deg.to_radians()).abs() < 0.25);
        assert!(pauses >= 4, "{pauses}");
        // Nothing clear behind: straight to rotating.
        input.behind_clear = false;
        let r = Recovery::start(&cfg, &input);
        assert!(matches!(r.behaviour(), Some(Behaviour::Rotate { .. })));
        let mut look = Recovery::look_around(&RecoveryConfig::default(), 360.0);
        assert_eq!(look.step(&input), Some(MotionCommand::Left));
        // Heading that never changes: each rotation step ends at its time limit.
        let mut steps = 0;
        while look.step(&input).is_some() {
            input.now_ns += 100_000_000;
            steps += 1;
            assert!(steps < 1000, "the look-around never ended");
        }
    }

    #[test]
    fn a_stalled_turn_moves_ahead_when_it_can_and_turns_the_other_way_when_not() {
        let cfg = RecoveryConfig::default();
        let mut input = RecoveryInput {
            now_ns: 0,
            distance_m: 3.0,
            heading_rad: 0.0,
            behind_clear: false,
            ahead_clear: true,
            left_clear: true,
            right_clear: true,
        };
        let mut r = Recovery::after_stall(&cfg, &input, Some(true));
        let mut forwards = 0;
        for _ in 0..100 {
            match r.step(&input) {
                Some(MotionCommand::Forward) => {
                    forwards += 1;
                    input.distance_m += 0.02;
                }
                Some(MotionCommand::Stop) => input.now_ns += 100_000_000,
                None => break,
                other => panic!("unexpected {other:?}"),
            }
        }
        assert_eq!(forwards, (cfg.turn_stall_shift_m / 0.02).ceil() as usize);
        // The way ahead not clear: rotate away from the stalled turn.
        input.ahead_clear = false;
        let mut r = Recovery::after_stall(&cfg, &input, Some(true));
        assert_eq!(r.step(&input), Some(MotionCommand::Right));
        // A stalled drive is not moved ahead.
        input.ahead_clear = true;
        let r = Recovery::after_stall(&cfg, &input, None);
        assert!(matches!(r.behaviour(), Some(Behaviour::Rotate { .. })));
    }
}
