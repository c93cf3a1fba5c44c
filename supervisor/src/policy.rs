//! The supervisor's restart and hang policy as pure functions of a stage's history and a
//! clock reading (`now` is always passed in): what `run.rs` does when a stage exits, when it
//! falls silent, and when a backoff ends, decided here and unit-tested without processes.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use hvs_runtime::config::{RestartPolicy, StageSpec};
use hvs_shared::messages::StageState;

/// A stage that ran this long without trouble gets its backoff reset.
pub const HEALTHY_AFTER: Duration = Duration::from_secs(5);

/// What the policy remembers of one stage between exits.
#[derive(Debug, Clone)]
pub struct RestartHistory {
    /// The delay before the next restart (doubles after each, up to `max_backoff_ms`).
    pub backoff: Duration,
    /// When the failures within the restart window happened.
    pub failures: VecDeque<Instant>,
}

/// What to do with a stage whose process ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ExitVerdict {
    /// Start it again at `at` (after `backoff`).
    RestartAt {
        /// When.
        at: Instant,
        /// The delay chosen.
        backoff: Duration,
    },
    /// Restarted too often within the window: leave it failed.
    GiveUp {
        /// Failures counted within the window.
        failures: usize,
    },
    /// The policy does not restart it (`never`, or `on-failure` after a clean exit).
    Leave {
        /// Whether it ended with a failure (the state becomes `failed`, else `stopped`).
        failed: bool,
    },
}

impl RestartHistory {
    /// A stage that has not failed yet.
    pub fn new(spec: &StageSpec) -> Self {
        Self {
            backoff: Duration::from_millis(spec.backoff_ms),
            failures: VecDeque::new(),
        }
    }

    /// A fresh budget (`hvs restart` of a stopped, failed or backing-off stage).
    pub fn reset(&mut self, spec: &StageSpec) {
        *self = Self::new(spec);
    }

    /// Decides on an exit at `now` of a process that ran for `ran_for`; `failed` is a
    /// non-zero exit, a signal or a hang.
    pub fn after_exit(
        &mut self,
        spec: &StageSpec,
        failed: bool,
        ran_for: Duration,
        now: Instant,
    ) -> ExitVerdict {
        let restart = match spec.restart {
            RestartPolicy::Always => true,
            RestartPolicy::OnFailure => failed,
            RestartPolicy::Never => false,
        };
        if !restart {
            return ExitVerdict::Leave { failed };
        }
        if ran_for >= HEALTHY_AFTER {
            self.backoff = Duration::from_millis(spec.backoff_ms);
        }
        let window = Duration::from_secs(spec.restart_window_s);
        while self
            .failures
            .front()
            .is_some_and(|t| now.saturating_duration_since(*t) > window)
        {
            self.failures.pop_front();
        }
        if self.failures.len() as u32 >= spec.max_restarts {
            return ExitVerdict::GiveUp {
                failures: self.failures.len(),
            };
        }
        self.failures.push_back(now);
        let backoff = self.backoff;
        self.backoff = (self.backoff * 2).min(Duration::from_millis(spec.max_backoff_ms));
        ExitVerdict::RestartAt {
            at: now + backoff,
            backoff,
        }
    }
}

/// How long a stage in `state` may stay silent before it counts as hung: the stage's
/// `heartbeat_timeout_ms` once it runs, `startup_timeout` until its first heartbeat, no
/// bound in the other states.
pub fn hang_limit(
    state: StageState,
    spec: &StageSpec,
    startup_timeout: Duration,
) -> Option<Duration> {
    match state {
        StageState::Running => Some(Duration::from_millis(spec.heartbeat_timeout_ms)),
        StageState::Starting => Some(startup_timeout),
        _ => None,
    }
}

/// Whether a stage in `state`, silent since `silent_since` (its last heartbeat, or its
/// spawn), is hung at `now`. `starved` is how long of that silence its main thread was
/// runnable but waiting for a CPU (other programs had the cores): that time does not count.
/// A stuck loop or a blocked call waits for no CPU, so it is found after the limit as
/// before; a stage that merely gets a small share of busy cores is not killed for it (its
/// replacement would get no more). Silence past four times the limit counts whatever the
/// reason, so a kernel that reports no waits cannot keep a stage alive forever.
pub fn is_hung(
    state: StageState,
    spec: &StageSpec,
    startup_timeout: Duration,
    silent_since: Instant,
    now: Instant,
    starved: Duration,
) -> bool {
    hang_limit(state, spec, startup_timeout).is_some_and(|limit| {
        let silent = now.saturating_duration_since(silent_since);
        silent > limit && (silent.saturating_sub(starved) > limit || silent > 4 * limit)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(restart: RestartPolicy) -> StageSpec {
        StageSpec {
            stage: hvs_shared::topics::Stage::Fusion,
            name: "fusion".into(),
            program: "hvs-fusion".into(),
            args: Vec::new(),
            enabled: true,
            restart,
            backoff_ms: 200,
            max_backoff_ms: 1000,
            max_restarts: 3,
            restart_window_s: 60,
            nice: 0,
            heartbeat_timeout_ms: 1000,
        }
    }

    const S: Duration = Duration::from_secs(1);

    #[test]
    fn backoff_doubles_up_to_its_cap_and_resets_after_a_healthy_run() {
        let spec = StageSpec {
            max_restarts: 100,
            ..spec(RestartPolicy::Always)
        };
        let mut h = RestartHistory::new(&spec);
        let t0 = Instant::now();
        let mut delays = Vec::new();
        for k in 0..5 {
            let now = t0 + k * S / 10;
            match h.after_exit(&spec, true, Duration::from_millis(10), now) {
                ExitVerdict::RestartAt { at, backoff } => {
                    assert_eq!(at, now + backoff);
                    delays.push(backoff.as_millis());
                }
                v => panic!("{v:?}"),
            }
        }
        assert_eq!(delays, [200, 400, 800, 1000, 1000]);
        // Ran for longer than HEALTHY_AFTER: back to the first delay.
        let v = h.after_exit(&spec, true, HEALTHY_AFTER, t0 + S);
        assert!(
            matches!(v, ExitVerdict::RestartAt { backoff, .. } if backoff.as_millis() == 200),
            "{v:?}"
        );
    }

    #[test]
    fn too_many_failures_within_the_window_give_up_and_old_ones_are_forgotten() {
        let spec = spec(RestartPolicy::Always);
        let mut h = RestartHistory::new(&spec);
        let t0 = Instant::now();
        for k in 0..3 {
            let v = h.after_exit(&spec, true, Duration::ZERO, t0 + k * S);
            assert!(matches!(v, ExitVerdict::RestartAt { .. }), "{v:?}");
        }
        assert_eq!(
            h.after_exit(&spec, true, Duration::ZERO, t0 + 3 * S),
            ExitVerdict::GiveUp { failures: 3 }
        );
        // 61 s after the first failure it has left the window: one more restart is allowed.
        let mut h2 = RestartHistory::new(&spec);
        for k in 0..3 {
            h2.after_exit(&spec, true, Duration::ZERO, t0 + k * S);
        }
        let v = h2.after_exit(&spec, true, Duration::ZERO, t0 + 61 * S);
        assert!(matches!(v, ExitVerdict::RestartAt { .. }), "{v:?}");
        // A reset (hvs restart) gives a fresh budget.
        h.reset(&spec);
        let v = h.after_exit(&spec, true, Duration::ZERO, t0 + 4 * S);
        assert!(
            matches!(v, ExitVerdict::RestartAt { backoff, .. } if backoff.as_millis() == 200),
            "{v:?}"
        );
    }

    #[test]
    fn the_policies_decide_which_exits_restart() {
        let t0 = Instant::now();
        for (policy, failed, restarts) in [
            (RestartPolicy::Always, false, true),
            (RestartPolicy::Always, true, true),
            (RestartPolicy::OnFailure, false, false),
            (RestartPolicy::OnFailure, true, true),
            (RestartPolicy::Never, false, false),
            (RestartPolicy::Never, true, false),
        ] {
            let spec = spec(policy);
            let v = RestartHistory::new(&spec).after_exit(&spec, failed, Duration::ZERO, t0);
            if restarts {
                assert!(
                    matches!(v, ExitVerdict::RestartAt { .. }),
                    "{policy:?} {failed}: {v:?}"
                );
            } else {
                assert_eq!(v, ExitVerdict::Leave { failed }, "{policy:?}");
            }
        }
    }

    #[test]
    fn hang_bounds_depend_on_the_state() {
        let spec = spec(RestartPolicy::Always);
        let startup = Duration::from_secs(10);
        let t0 = Instant::now();
        // Running: the stage's heartbeat bound.
        assert!(!is_hung(
            StageState::Running,
            &spec,
            startup,
            t0,
            t0 + S,
            Duration::ZERO
        ));
        assert!(is_hung(
            StageState::Running,
            &spec,
            startup,
            t0,
            t0 + S + S / 100,
            Duration::ZERO
        ));
        // Starting: the start-up bound (a stage that hangs before its first heartbeat).
        assert!(!is_hung(
            StageState::Starting,
            &spec,
            startup,
            t0,
            t0 + 9 * S,
            Duration::ZERO
        ));
        assert!(is_hung(
            StageState::Starting,
            &spec,
            startup,
            t0,
            t0 + 11 * S,
            Duration::ZERO
        ));
        // Stopping, backing off, failed: never "hung".
        for state in [
            StageState::Stopping,
            StageState::Backoff,
            StageState::Failed,
            StageState::Stopped,
        ] {
            assert!(
                !is_hung(state, &spec, startup, t0, t0 + 3600 * S, Duration::ZERO),
                "{state:?}"
            );
        }
        // A clock reading before the last heartbeat (a heartbeat stamped after `now` was
        // read) is not a hang.
        assert!(!is_hung(
            StageState::Running,
            &spec,
            startup,
            t0 + S,
            t0,
            Duration::ZERO
        ));
    }

    #[test]
    fn time_spent_waiting_for_a_cpu_does_not_count_as_silence() {
        let spec = spec(RestartPolicy::Always);
        let startup = Duration::from_secs(10);
        let t0 = Instant::now();
        let running = |silent: Duration, starved: Duration| {
            is_hung(
                StageState::Running,
                &spec,
                startup,
                t0,
                t0 + silent,
                starved,
            )
        };
        // 1.5 s silent, 0.9 s of it waiting for a CPU: 0.6 s of its own, not hung.
        assert!(!running(S * 3 / 2, S * 9 / 10));
        // The same silence with little waiting: hung (a stuck loop or a blocked call).
        assert!(running(S * 3 / 2, S / 10));
        // Starved or not, four times the limit is a hang.
        assert!(!running(S * 4, S * 4));
        assert!(running(S * 4 + S / 10, S * 4));
        // The start-up bound is treated alike.
        assert!(!is_hung(
            StageState::Starting,
            &spec,
            startup,
            t0,
            t0 + 12 * S,
            5 * S
        ));
        assert!(is_hung(
            StageState::Starting,
            &spec,
            startup,
            t0,
            t0 + 12 * S,
            S
        ));
    }
}
