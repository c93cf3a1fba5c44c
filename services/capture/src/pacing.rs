//! When the capture stage sends the next pair, and when it tries the cameras again: the
//! reconnect backoff, the files source's lockstep with the pipeline and the replay's wait
//! for the recorded decision. Pure functions of what arrived and of a monotonic clock
//! (nanoseconds) that the caller passes in, so that the tests need no time to pass.

use std::time::Duration;

/// Reopening a camera pair that failed: the first delay, doubled after each failure up to a
/// largest one, back to the first after a success.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    first: Duration,
    max: Duration,
    next: Duration,
    attempts: u32,
}

impl Backoff {
    /// Starts at `first`, never above `max`.
    pub fn new(first: Duration, max: Duration) -> Self {
        Self {
            first,
            max: max.max(first),
            next: first,
            attempts: 0,
        }
    }

    /// One more failure: the delay to wait before the next attempt.
    pub fn failed(&mut self) -> Duration {
        let delay = self.next;
        self.attempts += 1;
        self.next = (self.next * 2).min(self.max);
        delay
    }

    /// The delay the next failure waits, without counting one (after a lost connection).
    pub fn current(&self) -> Duration {
        self.next
    }

    /// Failures since the last success.
    pub fn attempts(&self) -> u32 {
        self.attempts
    }

    /// A success: the next failure waits the first delay again.
    pub fn succeeded(&mut self) {
        self.next = self.first;
        self.attempts = 0;
    }
}

/// The files source in lockstep with the pipeline: the next pair goes out when the range
/// report of the last one arrives (the end of the pipeline), or after a timeout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lockstep {
    timeout_ns: u64,
    sent_frame_id: u64,
    sent_ns: u64,
    answered: bool,
}

impl Lockstep {
    /// Waits at most `timeout` for an answer.
    pub fn new(timeout: Duration) -> Self {
        Self {
            timeout_ns: timeout.as_nanos().min(u128::from(u64::MAX)) as u64,
            sent_frame_id: 0,
            sent_ns: 0,
            answered: true,
        }
    }

    /// A pair with `frame_id` went out at `now_ns`.
    pub fn sent(&mut self, frame_id: u64, now_ns: u64) {
        self.sent_frame_id = frame_id;
        self.sent_ns = now_ns;
        self.answered = false;
    }

    /// A range report of `frame_id` arrived.
    pub fn answered_by(&mut self, frame_id: u64) {
        if frame_id >= self.sent_frame_id {
            self.answered = true;
        }
    }

    /// Whether the next pair is due at `now_ns`.
    pub fn due(&self, now_ns: u64) -> bool {
        self.answered || now_ns.saturating_sub(self.sent_ns) >= self.timeout_ns
    }
}

/// What a lockstep replay waits for after a frame: the decision of that frame (a fast-path
/// frame the recorded run decided on) and the 640x480 disparity (a frame whose long-range
/// result the recorded run fused).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReplayWait {
    /// The frame sent.
    pub frame_id: u64,
    /// Wait for its decision.
    pub decision: bool,
    /// Wait for its 640x480 disparity map.
    pub hi_disparity: bool,
    /// When it was sent, CLOCK_MONOTONIC ns.
    pub since_ns: u64,
}

/// Where a [`ReplayWait`] stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WaitState {
    /// Everything awaited arrived.
    Done,
    /// Still waiting.
    Waiting,
    /// The timeout passed first, missing the decision (`true`) or else the disparity.
    TimedOut {
        /// The decision is what is missing (else the 640x480 disparity map).
        missing_decision: bool,
    },
}

impl ReplayWait {
    /// Where the wait stands, given the newest decision's and 640x480 map's frame ids.
    pub fn state(
        &self,
        last_decision: u64,
        last_hi_disparity: u64,
        now_ns: u64,
        timeout: Duration,
    ) -> WaitState {
        let decision_missing = self.decision && last_decision < self.frame_id;
        let hi_missing = self.hi_disparity && last_hi_disparity < self.frame_id;
        if !decision_missing && !hi_missing {
            WaitState::Done
        } else if u128::from(now_ns.saturating_sub(self.since_ns)) >= timeout.as_nanos() {
            WaitState::TimedOut {
                missing_decision: decision_missing,
            }
        } else {
            WaitState::Waiting
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn backoff_doubles_to_its_cap_and_starts_over_after_a_success() {
        let mut b = Backoff::new(Duration::from_millis(100), Duration::from_millis(350));
        let delays: Vec<u128> = (0..4).map(|_| b.failed().as_millis()).collect();
        assert_eq!(delays, [100, 200, 350, 350]);
        assert_eq!(b.attempts(), 4);
        b.succeeded();
        assert_eq!((b.attempts(), b.current()), (0, Duration::from_millis(100)));
        // A cap below the first delay is the first delay.
        let mut odd = Backoff::new(Duration::from_millis(500), Duration::from_millis(10));
        assert_eq!(odd.failed(), Duration::from_millis(500));
        assert_eq!(odd.failed(), Duration::from_millis(500));
    }

    #[test]
    fn lockstep_waits_for_the_answer_to_the_last_pair_or_the_timeout() {
        let mut l = Lockstep::new(Duration::from_millis(100));
        assert!(l.due(0), "the first pair goes out at once");
        l.sent(5, 1_000 * MS);
        assert!(!l.due(1_050 * MS));
        l.answered_by(4);
        assert!(!l.due(1_050 * MS), "an older frame's report is no answer");
        l.answered_by(5);
        assert!(l.due(1_050 * MS));
        l.sent(6, 2_000 * MS);
        assert!(!l.due(2_099 * MS));
        assert!(l.due(2_100 * MS), "timed out");
    }

    #[test]
    fn a_replay_wait_ends_when_everything_awaited_arrived_and_names_what_timed_out() {
        let timeout = Duration::from_millis(200);
        let w = ReplayWait {
            frame_id: 10,
            decision: true,
            hi_disparity: true,
            since_ns: 0,
        };
        assert_eq!(w.state(10, 9, 50 * MS, timeout), WaitState::Waiting);
        assert_eq!(w.state(10, 10, 50 * MS, timeout), WaitState::Done);
        assert_eq!(
            w.state(9, 10, 200 * MS, timeout),
            WaitState::TimedOut {
                missing_decision: true
            }
        );
        assert_eq!(
            w.state(12, 3, 300 * MS, timeout),
            WaitState::TimedOut {
                missing_decision: false
            }
        );
        let lo_only = ReplayWait {
            hi_disparity: false,
            ..w
        };
        assert_eq!(lo_only.state(10, 0, 0, timeout), WaitState::Done);
    }
}
