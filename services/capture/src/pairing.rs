//! Pairing the frames of two unsynchronised cameras by their kernel timestamps.
//!
//! The rule (docs/capture.md): when a frame arrives from one camera, it is paired with the
//! pending frame of the other camera whose timestamp is closest, if the two are at most
//! `max_skew_ns` apart. Frames that can no longer be paired are released at once (so a V4L2
//! buffer goes back to the driver):
//! - on a pair, every older pending frame of the arriving side, and every pending frame of
//!   the other side older than its partner;
//! - without a pair, pending frames of the other side more than `max_skew_ns` older than the
//!   new frame (later frames of this side are newer still), and the new frame itself if it is
//!   more than `max_skew_ns` older than the other side's newest frame (it arrived too late);
//! - a side holds at most `max_pending` frames; the oldest goes first.

/// Which camera a frame came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// The left camera.
    Left,
    /// The right camera.
    Right,
}

impl Side {
    fn index(self) -> usize {
        match self {
            Side::Left => 0,
            Side::Right => 1,
        }
    }
}

/// A frame with its kernel timestamp; `token` identifies the buffer (e.g. a V4L2 index).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamped<T> {
    /// Capture time, CLOCK_MONOTONIC ns.
    pub stamp_ns: u64,
    /// What the caller needs to find (and release) the frame.
    pub token: T,
}

/// A matched left/right pair.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Pair<T> {
    /// The left frame.
    pub left: Stamped<T>,
    /// The right frame.
    pub right: Stamped<T>,
}

impl<T> Pair<T> {
    /// Right minus left capture time, ns (the value published as `FrameHeader::skew_ns`).
    pub fn skew_ns(&self) -> i64 {
        self.right.stamp_ns as i64 - self.left.stamp_ns as i64
    }
}

/// The result of offering one frame to the [`Pairer`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PairStep<T> {
    /// A pair completed by this frame, if any.
    pub pair: Option<Pair<T>>,
    /// Frames that will never be paired (to be released), with their side.
    pub released: Vec<(Side, Stamped<T>)>,
}

/// Why a pairer could not be created.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PairError {
    /// The skew bound is zero.
    #[error("max_skew_ns = {0} must be positive")]
    Skew(u64),
    /// No frame may wait.
    #[error("max_pending = {0} must be at least 1")]
    Pending(usize),
}

/// Counters of a [`Pairer`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PairStats {
    /// Pairs made.
    pub pairs: u64,
    /// Left frames released unpaired.
    pub dropped_left: u64,
    /// Right frames released unpaired.
    pub dropped_right: u64,
}

/// Pairs left and right frames by timestamp (see the module documentation for the rule).
#[derive(Debug)]
pub struct Pairer<T> {
    max_skew_ns: u64,
    max_pending: usize,
    pending: [Vec<Stamped<T>>; 2],
    stats: PairStats,
}

impl<T: Copy> Pairer<T> {
    /// A pairer accepting at most `max_skew_ns` between partners and holding at most
    /// `max_pending` unpaired frames per side.
    pub fn new(max_skew_ns: u64, max_pending: usize) -> Result<Self, PairError> {
        if max_skew_ns == 0 {
            return Err(PairError::Skew(max_skew_ns));
        }
        if max_pending == 0 {
            return Err(PairError::Pending(max_pending));
        }
        Ok(Self {
            max_skew_ns,
            max_pending,
            pending: [Vec::new(), Vec::new()],
            stats: PairStats::default(),
        })
    }

    /// The counters so far.
    pub fn stats(&self) -> PairStats {
        self.stats
    }

    /// Frames waiting for a partner, left and right.
    pub fn pending(&self) -> (usize, usize) {
        (self.pending[0].len(), self.pending[1].len())
    }

    /// Releases every pending frame (e.g. before the cameras are closed).
    pub fn drain(&mut self) -> Vec<(Side, Stamped<T>)> {
        let mut out: Vec<_> = self.pending[0].drain(..).map(|f| (Side::Left, f)).collect();
        out.extend(self.pending[1].drain(..).map(|f| (Side::Right, f)));
        out
    }

    fn release(&mut self, side: Side, frame: Stamped<T>, out: &mut Vec<(Side, Stamped<T>)>) {
        match side {
            Side::Left => self.stats.dropped_left += 1,
            Side::Right => self.stats.dropped_right += 1,
        }
        out.push((side, frame));
    }

    /// Offers a new frame from `side`.
    pub fn push(&mut self, side: Side, frame: Stamped<T>) -> PairStep<T> {
        let this = side.index();
        let other = 1 - this;
        let other_side = if this == 0 { Side::Right } else { Side::Left };
        let mut released = Vec::new();
        let best = self.pending[other]
            .iter()
            .enumerate()
            .min_by_key(|(_, g)| g.stamp_ns.abs_diff(frame.stamp_ns))
            .map(|(i, g)| (i, g.stamp_ns.abs_diff(frame.stamp_ns)));
        if let Some((i, diff)) = best
            && diff <= self.max_skew_ns
        {
            let partner = self.pending[other].remove(i);
            // Everything older than the partner on the other side, and everything pending on
            // this side (all older than the new frame), can no longer be paired.
            let (keep, drop): (Vec<_>, Vec<_>) = self.pending[other]
                .drain(..)
                .partition(|g| g.stamp_ns > partner.stamp_ns);
            self.pending[other] = keep;
            for g in drop {
                self.release(other_side, g, &mut released);
            }
            let mine: Vec<_> = self.pending[this].drain(..).collect();
            for f in mine {
                self.release(side, f, &mut released);
            }
            self.stats.pairs += 1;
            let pair = if side == Side::Left {
                Pair {
                    left: frame,
                    right: partner,
                }
            } else {
                Pair {
                    left: partner,
                    right: frame,
                }
            };
            return PairStep {
                pair: Some(pair),
                released,
            };
        }
        // No partner now: drop what can never pair.
        let limit = frame.stamp_ns.saturating_sub(self.max_skew_ns);
        let (keep, drop): (Vec<_>, Vec<_>) = self.pending[other]
            .drain(..)
            .partition(|g| g.stamp_ns >= limit);
        self.pending[other] = keep;
        for g in drop {
            self.release(other_side, g, &mut released);
        }
        let other_newest = self.pending[other].iter().map(|g| g.stamp_ns).max();
        if let Some(newest) = other_newest
            && frame.stamp_ns.saturating_add(self.max_skew_ns) < newest
        {
            self.release(side, frame, &mut released);
        } else {
            self.pending[this].push(frame);
            while self.pending[this].len() > self.max_pending {
                let oldest = self.pending[this].remove(0);
                self.release(side, oldest, &mut released);
            }
        }
        PairStep {
            pair: None,
            released,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    fn f(stamp_ms: u64, token: u32) -> Stamped<u32> {
        Stamped {
            stamp_ns: stamp_ms * MS,
            token,
        }
    }

    /// Runs a recorded arrival order through a pairer; returns the pairs as (left, right)
    /// tokens and the released tokens.
    fn run(events: &[(Side, u64, u32)], skew_ms: u64) -> (Vec<(u32, u32, i64)>, Vec<u32>) {
        let mut p = Pairer::new(skew_ms * MS, 2).unwrap();
        let mut pairs = Vec::new();
        let mut released = Vec::new();
        for &(side, t, token) in events {
            let step = p.push(side, f(t, token));
            if let Some(pair) = step.pair {
                pairs.push((
                    pair.left.token,
                    pair.right.token,
                    pair.skew_ns() / MS as i64,
                ));
            }
            released.extend(step.released.into_iter().map(|(_, s)| s.token));
        }
        (pairs, released)
    }

    use Side::{Left as L, Right as R};

    #[test]
    fn interleaved_cameras_pair_in_order_with_their_skew() {
        // Two 30 fps cameras, the right one 7 ms behind.
        let events: Vec<_> = (0..5u32)
            .flat_map(|i| {
                let t = i as u64 * 33;
                [(L, t, 100 + i), (R, t + 7, 200 + i)]
            })
            .collect();
        let (pairs, released) = run(&events, 10);
        assert_eq!(pairs.len(), 5);
        assert!(released.is_empty(), "{released:?}");
        for (i, (l, r, skew)) in pairs.into_iter().enumerate() {
            assert_eq!((l, r, skew), (100 + i as u32, 200 + i as u32, 7));
        }
    }

    #[test]
    fn frames_beyond_the_skew_bound_are_dropped() {
        // Right runs 16 ms behind; with a 10 ms bound nothing pairs and everything is released.
        let events = [(L, 0, 1), (R, 16, 2), (L, 33, 3), (R, 49, 4), (L, 66, 5)];
        let (pairs, released) = run(&events, 10);
        assert!(pairs.is_empty());
        assert_eq!(released, vec![1, 2, 3, 4]);
        // The same with a 20 ms bound pairs (1,2) and (3,4); the skew is right minus left.
        let (pairs, _) = run(&events, 20);
        assert_eq!(pairs, vec![(1, 2, 16), (3, 4, 16)]);
    }

    #[test]
    fn the_closest_partner_wins_even_when_dequeued_late() {
        // Left 0 and 33 are already pending when right 10 is dequeued: it pairs with left 0.
        let events = [(L, 0, 1), (L, 33, 3), (R, 10, 2), (R, 40, 4)];
        let (pairs, released) = run(&events, 15);
        assert_eq!(pairs, vec![(1, 2, 10), (3, 4, 7)]);
        assert!(released.is_empty(), "{released:?}");
    }

    #[test]
    fn a_camera_that_stops_does_not_pin_buffers() {
        // The right camera delivers once; left frames keep coming and are released, never
        // more than max_pending = 2 held.
        let mut p = Pairer::new(10 * MS, 2).unwrap();
        p.push(R, f(0, 0));
        let mut released = 0;
        for i in 1..20u32 {
            let step = p.push(L, f(i as u64 * 33, i));
            assert!(step.pair.is_none());
            released += step.released.len();
            assert!(p.pending().0 <= 2);
        }
        assert_eq!(p.pending(), (2, 0));
        assert_eq!(released, 18); // 17 left frames + the stale right one
        assert_eq!(p.stats().dropped_left, 17);
        assert_eq!(p.stats().dropped_right, 1);
        assert_eq!(p.drain().len(), 2);
    }

    #[test]
    fn a_late_frame_is_released_at_once() {
        // Right 50 is pending; a left frame stamped 10 (delivered late) cannot pair.
        let mut p = Pairer::new(10 * MS, 2).unwrap();
        p.push(R, f(50, 7));
        let step = p.push(L, f(10, 8));
        assert!(step.pair.is_none());
        assert_eq!(step.released, vec![(L, f(10, 8))]);
        assert_eq!(p.pending(), (0, 1));
    }

    #[test]
    fn bad_settings_are_rejected() {
        assert!(
            Pairer::<u32>::new(0, 2)
                .unwrap_err()
                .to_string()
                .contains("max_skew_ns")
        );
        assert!(
            Pairer::<u32>::new(5, 0)
                .unwrap_err()
                .to_string()
                .contains("max_pending")
        );
    }
}
