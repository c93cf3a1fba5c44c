//! The order in which the decision stage applies what it receives, kept apart from iceoryx2
//! so that it can be tested.
//!
//! The decision's clock is the frame's capture time, and the actuator outputs it dead-reckons
//! from are those on the wire by then: an output sent after the frame was captured waits for
//! a later frame. The pose then belongs to the view, and the same frames and outputs give the
//! same decisions whatever the processing delays (a replay repeats the recorded decisions).

use std::collections::VecDeque;

use hvs_shared::messages::{ActuatorReport, Decision};

use crate::{NavDecision, Navigator, Policy};

/// Actuator outputs waiting for a frame captured after them, oldest first.
#[derive(Debug)]
pub struct SentQueue {
    pending: VecDeque<ActuatorReport>,
    capacity: usize,
}

impl SentQueue {
    /// Outputs kept by default (15 a second: seconds of them).
    pub const DEFAULT_CAPACITY: usize = 64;

    /// Keeps at most `capacity` outputs (at least 1).
    pub fn new(capacity: usize) -> Self {
        Self {
            pending: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
        }
    }

    /// Queues an output. When full (only without frames for seconds), the oldest output is
    /// returned to be applied now, late rather than lost.
    pub fn push(&mut self, report: ActuatorReport) -> Option<ActuatorReport> {
        let overflow = if self.pending.len() == self.capacity {
            self.pending.pop_front()
        } else {
            None
        };
        self.pending.push_back(report);
        overflow
    }

    /// Takes the outputs sent at or before `capture_ns`, oldest first.
    pub fn due(&mut self, capture_ns: u64) -> impl Iterator<Item = ActuatorReport> + '_ {
        let n = self
            .pending
            .iter()
            .take_while(|a| a.sent_ns <= capture_ns)
            .count();
        self.pending.drain(..n)
    }

    /// Outputs waiting now.
    pub fn len(&self) -> usize {
        self.pending.len()
    }

    /// True when no output waits.
    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }
}

/// Feeds one actuator output to the navigator's dead reckoning.
pub fn apply_sent(nav: &mut Navigator, a: &ActuatorReport) {
    nav.on_sent(a.sent_ns, a.left_pw, a.right_pw, a.ramp);
}

/// The message for a decision made from frame `frame_id` captured at `capture_ns`.
pub fn decision_message(
    frame_id: u64,
    capture_ns: u64,
    d: &NavDecision,
    policy: Policy,
    published_ns: u64,
) -> Decision {
    Decision {
        frame_id,
        capture_ns,
        published_ns,
        command: d.command as u32,
        intersection: d.intersection as u32,
        wall_left: d.memberships.left as f32,
        wall_front: d.memberships.front as f32,
        wall_right: d.memberships.right as f32,
        turn_angle_deg: d.turn_angle_deg as f32,
        ramp: d.ramp,
        policy: policy.nav_policy().code(),
        reserved: [0; 2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sent(seq: u64, sent_ns: u64) -> ActuatorReport {
        ActuatorReport {
            seq,
            sent_ns,
            ..ActuatorReport::default()
        }
    }

    #[test]
    fn policy_codes_and_labels_are_the_contract_and_the_config_names() {
        use hvs_runtime::config::DecisionPolicy as D;
        for d in [
            D::Reference,
            D::Fuzzy,
            D::MeanEstimation,
            D::ThresholdEstimation,
            D::Explore,
        ] {
            let p = Policy::of(d);
            assert_eq!(p.nav_policy().code(), p as u32, "{d:?}");
            let config_name = serde_json::to_value(d).expect("serialises");
            assert_eq!(config_name, p.nav_policy().label(), "{d:?}");
        }
    }

    #[test]
    fn outputs_wait_for_a_frame_captured_after_them() {
        let mut q = SentQueue::new(8);
        assert!(q.push(sent(1, 100)).is_none());
        assert!(q.push(sent(2, 200)).is_none());
        assert!(q.push(sent(3, 300)).is_none());
        let due: Vec<u64> = q.due(200).map(|a| a.seq).collect();
        assert_eq!(due, [1, 2], "sent at or before the capture");
        assert_eq!(q.len(), 1);
        assert_eq!(q.due(299).count(), 0, "sent after the capture: it waits");
        let due: Vec<u64> = q.due(1_000).map(|a| a.seq).collect();
        assert_eq!(due, [3]);
        assert!(q.is_empty());
    }

    #[test]
    fn a_full_queue_hands_back_the_oldest_to_apply_late() {
        let mut q = SentQueue::new(2);
        assert!(q.push(sent(1, 100)).is_none());
        assert!(q.push(sent(2, 200)).is_none());
        assert_eq!(q.push(sent(3, 300)).map(|a| a.seq), Some(1));
        let due: Vec<u64> = q.due(u64::MAX).map(|a| a.seq).collect();
        assert_eq!(due, [2, 3]);
    }

    #[test]
    fn outputs_out_of_order_stop_at_the_first_later_one() {
        // The queue keeps arrival order; an output stamped later blocks those behind it
        // until a frame captured after it (the actuator stamps in order, so this is only
        // the conservative choice for a misbehaving source).
        let mut q = SentQueue::new(4);
        q.push(sent(1, 300));
        q.push(sent(2, 100));
        assert_eq!(q.due(200).count(), 0);
        assert_eq!(q.due(300).count(), 2);
    }
}
