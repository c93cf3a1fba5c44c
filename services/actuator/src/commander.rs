//! What to send and when: coalescing, the watchdog and wire pacing, as a pure state machine.
//!
//! The serial link carries about 15 two-wheel updates a second at 2400 baud, while decisions
//! arrive at camera rate, so the commander keeps only the newest decision (never a queue) and
//! sends it whenever the wire is free. When the newest decision is older than the watchdog
//! bound it sends neutral instead: the Sabertooth in microcontroller mode has no signal-loss
//! timeout, so without this the robot would keep driving on a stale command.

use hvs_runtime::config::{ActuatorConfig, PulsePair};
use hvs_shared::messages::{MotionCommand, SendReason};

use crate::psc::{self, COMMAND_LEN, MAX_PULSE, MAX_RAMP, MIN_PULSE};

/// While neutral is held, it is re-sent this often (a stopped robot stays told to stop).
pub const NEUTRAL_REFRESH_NS: u64 = 500_000_000;

/// The parts of a decision the actuator acts on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecisionInput {
    /// Frame the decision was made from.
    pub frame_id: u64,
    /// Capture time of that frame, ns.
    pub capture_ns: u64,
    /// Publication time of the decision, ns (its freshness is judged from this).
    pub published_ns: u64,
    /// The command.
    pub command: MotionCommand,
    /// PSC ramp for the command.
    pub ramp: u8,
}

/// Bytes to write and what they mean.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outgoing {
    /// Why this is sent.
    pub reason: SendReason,
    /// The motion.
    pub command: MotionCommand,
    /// Left-wheel pulse width.
    pub left_pw: u16,
    /// Right-wheel pulse width.
    pub right_pw: u16,
    /// Ramp used for both wheels.
    pub ramp: u8,
    /// Both position commands, left wheels first.
    pub bytes: [u8; 2 * COMMAND_LEN],
    /// The decision acted on (`None` for neutral without one).
    pub decision: Option<DecisionInput>,
}

/// The commander's state.
#[derive(Debug)]
pub struct Commander {
    config: ActuatorConfig,
    watchdog_ns: u64,
    wire_ns: u64,
    latest: Option<DecisionInput>,
    wire_free_at_ns: u64,
    last_sent: Option<Outgoing>,
    last_sent_ns: u64,
    /// Set when a link comes up: the controller's outputs are unknown, so neutral goes out
    /// before any decision is acted on.
    neutral_first: bool,
}

/// Clamps a pulse pair to the PSC range and to the span of the configured motion table.
fn clamp_pulses(table: &hvs_runtime::config::PulseTable, pair: PulsePair) -> PulsePair {
    let all = [
        table.neutral,
        table.forward,
        table.left,
        table.right,
        table.reverse,
    ];
    let lo = |f: fn(&PulsePair) -> u16| all.iter().map(f).min().unwrap_or(MIN_PULSE).max(MIN_PULSE);
    let hi = |f: fn(&PulsePair) -> u16| all.iter().map(f).max().unwrap_or(MAX_PULSE).min(MAX_PULSE);
    PulsePair {
        left: pair.left.clamp(lo(|p| p.left), hi(|p| p.left)),
        right: pair.right.clamp(lo(|p| p.right), hi(|p| p.right)),
    }
}

impl Commander {
    /// Creates a commander for a link configuration.
    pub fn new(config: &ActuatorConfig) -> Self {
        Self {
            config: config.clone(),
            watchdog_ns: config.watchdog_ms * 1_000_000,
            wire_ns: psc::byte_time_ns(config.baud) * 2 * COMMAND_LEN as u64,
            latest: None,
            wire_free_at_ns: 0,
            last_sent: None,
            last_sent_ns: 0,
            neutral_first: true,
        }
    }

    /// Time the wire needs for one two-wheel update, ns.
    pub fn wire_time_ns(&self) -> u64 {
        self.wire_ns
    }

    /// Takes a decision; only the newest is kept.
    pub fn on_decision(&mut self, d: DecisionInput) {
        if self.latest.is_none_or(|l| d.published_ns >= l.published_ns) {
            self.latest = Some(d);
        }
    }

    /// True when the newest decision is missing or older than the watchdog bound at `now_ns`.
    pub fn is_stale(&self, now_ns: u64) -> bool {
        self.latest
            .is_none_or(|d| now_ns.saturating_sub(d.published_ns) > self.watchdog_ns)
    }

    /// Encodes `command` with `reason`.
    pub fn encode(
        &self,
        command: MotionCommand,
        ramp: u8,
        reason: SendReason,
        decision: Option<DecisionInput>,
    ) -> Outgoing {
        let table = &self.config.pulses;
        let pair = match command {
            MotionCommand::Stop => table.neutral,
            MotionCommand::Forward => table.forward,
            MotionCommand::Left => table.left,
            MotionCommand::Right => table.right,
            MotionCommand::Reverse => table.reverse,
        };
        let pair = clamp_pulses(table, pair);
        let ramp = ramp.min(MAX_RAMP);
        let mut bytes = [0u8; 2 * COMMAND_LEN];
        // Channels and pulses were validated with the config and clamped above, so encoding
        // cannot fail; fall back to neutral bytes rather than panic if it ever did.
        let left = psc::position_command(self.config.left_channel, ramp, pair.left);
        let right = psc::position_command(self.config.right_channel, ramp, pair.right);
        if let (Ok(l), Ok(r)) = (left, right) {
            bytes[..COMMAND_LEN].copy_from_slice(&l);
            bytes[COMMAND_LEN..].copy_from_slice(&r);
        }
        Outgoing {
            reason,
            command,
            left_pw: pair.left,
            right_pw: pair.right,
            ramp,
            bytes,
            decision,
        }
    }

    /// Neutral for `reason`.
    pub fn neutral(&self, reason: SendReason) -> Outgoing {
        self.encode(MotionCommand::Stop, 0, reason, None)
    }

    /// What to send at `now_ns`, if anything: `None` while the wire is busy or nothing new is
    /// to be said.
    pub fn poll(&self, now_ns: u64) -> Option<Outgoing> {
        if now_ns < self.wire_free_at_ns {
            return None;
        }
        if self.neutral_first {
            return Some(self.neutral(SendReason::StartupNeutral));
        }
        if self.is_stale(now_ns) {
            let reason = if self.last_sent.is_none() {
                SendReason::StartupNeutral
            } else {
                SendReason::WatchdogNeutral
            };
            let already_neutral = self
                .last_sent
                .is_some_and(|s| s.command == MotionCommand::Stop && s.reason.is_neutral());
            if already_neutral && now_ns.saturating_sub(self.last_sent_ns) < NEUTRAL_REFRESH_NS {
                return None;
            }
            return Some(self.neutral(reason));
        }
        let d = self.latest?;
        let already_sent = self
            .last_sent
            .and_then(|s| s.decision)
            .is_some_and(|s| s.published_ns >= d.published_ns);
        if already_sent {
            return None;
        }
        let ramp = match d.command {
            MotionCommand::Left | MotionCommand::Right => d.ramp,
            _ => 0,
        };
        Some(self.encode(d.command, ramp, SendReason::Decision, Some(d)))
    }

    /// Records that `out` was written at `now_ns`; the wire is busy for its duration.
    pub fn mark_sent(&mut self, now_ns: u64, out: &Outgoing) {
        self.wire_free_at_ns = now_ns + self.wire_ns;
        self.last_sent = Some(*out);
        self.last_sent_ns = now_ns;
        if out.command == MotionCommand::Stop {
            self.neutral_first = false;
        }
    }

    /// Forgets what was sent (after the link came up again: the controller state is unknown);
    /// the next output is neutral.
    pub fn link_reset(&mut self) {
        self.last_sent = None;
        self.wire_free_at_ns = 0;
        self.neutral_first = true;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn decision(frame_id: u64, published_ns: u64, command: MotionCommand) -> DecisionInput {
        DecisionInput {
            frame_id,
            capture_ns: published_ns.saturating_sub(10 * MS),
            published_ns,
            command,
            ramp: 9,
        }
    }

    /// A commander whose link came up at 0 and that has sent its start-up neutral.
    fn commander() -> Commander {
        let mut c = Commander::new(&ActuatorConfig::default());
        let first = c.poll(0).expect("startup neutral");
        c.mark_sent(0, &first);
        c
    }

    #[test]
    fn a_link_that_comes_up_gets_neutral_before_a_fresh_decision() {
        let mut c = commander();
        let t0 = 1_000 * MS;
        c.on_decision(decision(1, t0, MotionCommand::Forward));
        let out = c.poll(t0).expect("forward");
        c.mark_sent(t0, &out);
        // The link went down and came up again: the controller may hold anything.
        c.link_reset();
        c.on_decision(decision(2, t0 + 80 * MS, MotionCommand::Left));
        let first = c.poll(t0 + 90 * MS).expect("neutral first");
        assert_eq!(first.reason, SendReason::StartupNeutral);
        assert_eq!(first.command, MotionCommand::Stop);
        c.mark_sent(t0 + 90 * MS, &first);
        assert!(c.poll(t0 + 100 * MS).is_none(), "wire busy");
        let next = c.poll(t0 + 157 * MS).expect("then the decision");
        assert_eq!(next.command, MotionCommand::Left);
    }

    #[test]
    fn starts_with_neutral_then_follows_fresh_decisions() {
        let mut c = Commander::new(&ActuatorConfig::default());
        c.on_decision(decision(1, 990 * MS, MotionCommand::Forward));
        let first = c.poll(1_000 * MS).expect("startup neutral");
        assert_eq!(first.reason, SendReason::StartupNeutral);
        assert_eq!((first.left_pw, first.right_pw), (760, 758));
        c.mark_sent(1_000 * MS, &first);
        c.on_decision(decision(1, 1_050 * MS, MotionCommand::Forward));
        let out = c.poll(1_100 * MS).expect("forward");
        assert_eq!(out.reason, SendReason::Decision);
        assert_eq!((out.left_pw, out.right_pw), (720, 800));
        assert_eq!(out.ramp, 0, "straight motions are not ramped");
        assert_eq!(
            &out.bytes[..8],
            &[b'!', b'S', b'C', 1, 0, 0xD0, 0x02, b'\r']
        );
        assert_eq!(
            &out.bytes[8..],
            &[b'!', b'S', b'C', 5, 0, 0x20, 0x03, b'\r']
        );
    }

    #[test]
    fn decisions_are_coalesced_while_the_wire_is_busy() {
        let mut c = commander();
        let t0 = 1_000 * MS;
        c.on_decision(decision(1, t0, MotionCommand::Forward));
        let out = c.poll(t0).expect("send");
        c.mark_sent(t0, &out);
        // Four decisions arrive during the 66.7 ms the wire needs.
        for (i, cmd) in [
            MotionCommand::Left,
            MotionCommand::Forward,
            MotionCommand::Right,
            MotionCommand::Left,
        ]
        .into_iter()
        .enumerate()
        {
            c.on_decision(decision(2 + i as u64, t0 + (10 + 10 * i as u64) * MS, cmd));
            assert!(
                c.poll(t0 + (11 + 10 * i as u64) * MS).is_none(),
                "wire busy"
            );
        }
        let next = c.poll(t0 + 67 * MS).expect("newest only");
        assert_eq!(next.decision.map(|d| d.frame_id), Some(5));
        assert_eq!(next.command, MotionCommand::Left);
        assert_eq!(next.ramp, 9);
        c.mark_sent(t0 + 67 * MS, &next);
        assert!(c.poll(t0 + 200 * MS).is_none(), "nothing new to say");
    }

    #[test]
    fn watchdog_sends_neutral_when_decisions_stop() {
        let mut c = commander();
        let t0 = 1_000 * MS;
        c.on_decision(decision(1, t0, MotionCommand::Forward));
        let out = c.poll(t0).unwrap();
        c.mark_sent(t0, &out);
        assert!(!c.is_stale(t0 + 300 * MS));
        assert!(c.poll(t0 + 300 * MS).is_none());
        let stop = c.poll(t0 + 301 * MS).expect("neutral after 300 ms");
        assert_eq!(stop.reason, SendReason::WatchdogNeutral);
        assert_eq!(stop.command, MotionCommand::Stop);
        c.mark_sent(t0 + 301 * MS, &stop);
        assert!(
            c.poll(t0 + 400 * MS).is_none(),
            "neutral is not repeated at once"
        );
        assert!(c.poll(t0 + 802 * MS).is_some(), "but refreshed");
        // A fresh decision resumes motion.
        c.on_decision(decision(2, t0 + 900 * MS, MotionCommand::Forward));
        assert_eq!(c.poll(t0 + 901 * MS).unwrap().reason, SendReason::Decision);
    }

    #[test]
    fn a_stale_decision_arriving_late_does_not_drive() {
        let mut c = commander();
        c.on_decision(decision(1, 1_000 * MS, MotionCommand::Forward));
        let out = c.poll(1_500 * MS).unwrap();
        assert_eq!(out.command, MotionCommand::Stop);
    }

    #[test]
    fn pulses_are_clamped_to_the_motion_table() {
        let mut config = ActuatorConfig::default();
        config.pulses.forward.left = 1250; // a typo in the table cannot exceed its own span...
        let c = Commander::new(&config);
        let out = c.encode(MotionCommand::Forward, 0, SendReason::Decision, None);
        assert!(out.left_pw <= 1250 && out.left_pw >= 250);
        // ...and every motion stays within the PSC range.
        for cmd in [
            MotionCommand::Stop,
            MotionCommand::Forward,
            MotionCommand::Left,
            MotionCommand::Right,
            MotionCommand::Reverse,
        ] {
            let o = c.encode(cmd, 99, SendReason::Decision, None);
            assert!((250..=1250).contains(&o.left_pw) && (250..=1250).contains(&o.right_pw));
            assert!(o.ramp <= 63);
        }
    }
}
