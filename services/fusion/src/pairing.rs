//! Which frame a disparity map belongs to, and which long-range result a fast-path frame
//! fuses: the stage's bookkeeping, kept apart from iceoryx2 so that it can be tested.
//!
//! The stage holds the newest frames (zero-copy samples in shared memory) until their maps
//! arrive ([`HeldFrames`]), maps whose frame is still on its way ([`WaitingMaps`]), and the
//! newest long-range results until a fast-path frame uses one ([`HiResults`]).

use std::collections::VecDeque;

use hvs_shared::messages::NO_HI_FRAME;

/// Items waiting for a partner with the same frame id; the newest `capacity` are kept (an
/// older one is dropped when a new one comes).
#[derive(Debug)]
pub struct HeldFrames<T> {
    items: VecDeque<T>,
    capacity: usize,
    frame_id: fn(&T) -> u64,
    pushed: u64,
}

impl<T> HeldFrames<T> {
    /// Holds at most `capacity` items (at least 1); `frame_id` reads an item's id.
    pub fn new(capacity: usize, frame_id: fn(&T) -> u64) -> Self {
        Self {
            items: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
            frame_id,
            pushed: 0,
        }
    }

    /// Holds `item`, dropping the oldest when full.
    pub fn push(&mut self, item: T) {
        if self.items.len() == self.capacity {
            self.items.pop_front();
        }
        self.items.push_back(item);
        self.pushed += 1;
    }

    /// True when a held item is newer than `frame_id`: frames come in id order, so an item
    /// of that id that is not held will not come any more.
    pub fn any_newer_than(&self, frame_id: u64) -> bool {
        self.items.iter().any(|i| (self.frame_id)(i) > frame_id)
    }

    /// Most items held at once.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Items pushed since the start (held or dropped since): an arrival counter.
    pub fn pushed(&self) -> u64 {
        self.pushed
    }

    /// The held item of `frame_id`, if it is still held.
    pub fn find(&self, frame_id: u64) -> Option<&T> {
        self.items.iter().find(|i| (self.frame_id)(i) == frame_id)
    }

    /// Items held now.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// True when nothing is held.
    pub fn is_empty(&self) -> bool {
        self.items.is_empty()
    }
}

/// Where a waiting map's frame is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pairing {
    /// Held: the map can be fused.
    Held,
    /// The map's frame is not held and a newer frame is: it was lost (or the map came too
    /// late for it), and the map is dropped.
    Gone,
}

/// Disparity maps waiting for their frame, oldest first, at most `capacity` (samples stay
/// borrowed in shared memory while they wait).
///
/// A frame normally arrives long before its map: the matcher starts from that frame. But
/// one publish reaches the subscribers one after another, so on a busy machine the matcher
/// can get the frame, match it and publish the map while the publisher is still preempted
/// before it queued the frame for fusion. Such a map waits here until its frame arrives, or
/// a newer one (proof that its frame was lost).
#[derive(Debug)]
pub struct WaitingMaps<M> {
    /// Each map with [`HeldFrames::pushed`] when it arrived.
    maps: VecDeque<(M, u64)>,
    capacity: usize,
    frame_id: fn(&M) -> u64,
}

impl<M> WaitingMaps<M> {
    /// Keeps at most `capacity` maps (at least 1); `frame_id` reads a map's frame id.
    pub fn new(capacity: usize, frame_id: fn(&M) -> u64) -> Self {
        Self {
            maps: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
            frame_id,
        }
    }

    /// Queues a map that arrived when `held` had the frames it has now; returns the oldest
    /// waiting map when full (it is dropped unpaired).
    pub fn push<F>(&mut self, map: M, held: &HeldFrames<F>) -> Option<M> {
        let evicted = if self.maps.len() == self.capacity {
            self.maps.pop_front().map(|(m, _)| m)
        } else {
            None
        };
        self.maps.push_back((map, held.pushed()));
        evicted
    }

    /// Takes the oldest map if its pairing is settled: its frame is held, or it is not held
    /// and a newer frame is (or more frames came since the map than are held: the frame ids
    /// started again, a restarted capture). `None` while the oldest still waits (or none
    /// waits): maps are fused in the order they came.
    pub fn next_settled<F>(&mut self, held: &HeldFrames<F>) -> Option<(M, Pairing)> {
        let (map, arrived_at) = self.maps.front()?;
        let pairing = if held.find((self.frame_id)(map)).is_some() {
            Pairing::Held
        } else if held.any_newer_than((self.frame_id)(map))
            || held.pushed() > *arrived_at + held.capacity() as u64
        {
            Pairing::Gone
        } else {
            return None;
        };
        self.maps.pop_front().map(|(m, _)| (m, pairing))
    }

    /// Maps waiting now.
    pub fn len(&self) -> usize {
        self.maps.len()
    }

    /// True when no map waits.
    pub fn is_empty(&self) -> bool {
        self.maps.is_empty()
    }
}

/// Which long-range result a fast-path frame asks for (its header's `replay_hi_frame_id`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HiWanted {
    /// Live: the newest result, if it is fresh enough.
    Newest,
    /// A replayed frame that the recorded run fused without one.
    None,
    /// A replayed frame that the recorded run fused with the result of this frame id.
    Named(u64),
}

impl HiWanted {
    /// Reads a frame header's `replay_hi_frame_id` (0 live, [`NO_HI_FRAME`], or an id).
    pub fn from_header(replay_hi_frame_id: u64) -> Self {
        match replay_hi_frame_id {
            0 => Self::Newest,
            NO_HI_FRAME => Self::None,
            id => Self::Named(id),
        }
    }
}

/// A long-range result with the frame it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct HiResult<R> {
    /// Frame id of the 640x480 pair.
    pub frame_id: u64,
    /// Its capture time, CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    /// What fusion made of it.
    pub result: R,
}

/// The newest long-range results, oldest first, at most `capacity`.
#[derive(Debug)]
pub struct HiResults<R> {
    results: VecDeque<HiResult<R>>,
    capacity: usize,
}

impl<R> HiResults<R> {
    /// Keeps at most `capacity` results (at least 1).
    pub fn new(capacity: usize) -> Self {
        Self {
            results: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
        }
    }

    /// Adds the newest result, dropping the oldest when full.
    pub fn push(&mut self, frame_id: u64, capture_ns: u64, result: R) {
        if self.results.len() == self.capacity {
            self.results.pop_front();
        }
        self.results.push_back(HiResult {
            frame_id,
            capture_ns,
            result,
        });
    }

    /// The result of `frame_id`, if kept.
    pub fn find(&self, frame_id: u64) -> Option<&HiResult<R>> {
        self.results.iter().rev().find(|h| h.frame_id == frame_id)
    }

    /// The result a fast-path frame captured at `capture_ns` fuses: the newest when it is at
    /// most `max_age_ns` older than the frame, the named one in a replay, or none.
    pub fn choose(
        &self,
        wanted: HiWanted,
        capture_ns: u64,
        max_age_ns: u64,
    ) -> Option<&HiResult<R>> {
        match wanted {
            HiWanted::Newest => self
                .results
                .back()
                .filter(|h| capture_ns.saturating_sub(h.capture_ns) <= max_age_ns),
            HiWanted::None => None,
            HiWanted::Named(id) => self.find(id),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn held_frames_keep_the_newest_and_find_by_id() {
        let mut held = HeldFrames::new(3, |f: &(u64, &str)| f.0);
        assert!(held.is_empty());
        for id in 1..=5 {
            held.push((id, "frame"));
        }
        assert_eq!(held.len(), 3);
        assert!(held.find(2).is_none(), "the oldest were dropped");
        assert_eq!(held.find(3).map(|f| f.0), Some(3));
        assert_eq!(held.find(5).map(|f| f.0), Some(5));
        assert!(held.find(6).is_none());
        // A capacity of 0 still holds one.
        let mut one = HeldFrames::new(0, |f: &u64| *f);
        one.push(7);
        one.push(8);
        assert_eq!(one.len(), 1);
        assert!(one.find(8).is_some());
    }

    #[test]
    fn a_map_that_overtook_its_frame_waits_for_it() {
        let mut held = HeldFrames::new(3, |f: &u64| *f);
        let mut waiting = WaitingMaps::new(2, |m: &(u64, &str)| m.0);
        held.push(1);
        // Map 1 finds its frame at once.
        assert!(waiting.push((1, "map 1"), &held).is_none());
        assert_eq!(
            waiting.next_settled(&held),
            Some(((1, "map 1"), Pairing::Held))
        );
        // Map 2 came before frame 2: it waits, and so does map 3 behind it.
        assert!(waiting.push((2, "map 2"), &held).is_none());
        assert!(waiting.next_settled(&held).is_none());
        assert!(waiting.push((3, "map 3"), &held).is_none());
        assert_eq!(waiting.len(), 2);
        held.push(2);
        assert_eq!(
            waiting.next_settled(&held),
            Some(((2, "map 2"), Pairing::Held))
        );
        assert!(
            waiting.next_settled(&held).is_none(),
            "frame 3 has not come"
        );
        // Frame 3 was lost: frame 4 comes and settles map 3 as gone.
        held.push(4);
        assert_eq!(
            waiting.next_settled(&held),
            Some(((3, "map 3"), Pairing::Gone))
        );
        assert!(waiting.is_empty());
        // A map for a frame older than the held ones (2, 4, 5) is gone at once.
        held.push(5);
        waiting.push((1, "late map 1"), &held);
        assert_eq!(
            waiting.next_settled(&held),
            Some(((1, "late map 1"), Pairing::Gone))
        );
        // Frame ids that start again (a restarted capture): a map of the old numbering
        // waits until more frames came than are held.
        waiting.push((9, "old map 9"), &held);
        for id in 1..=3 {
            held.push(id);
            assert!(waiting.next_settled(&held).is_none());
        }
        held.push(4);
        assert_eq!(
            waiting.next_settled(&held),
            Some(((9, "old map 9"), Pairing::Gone))
        );
        // When full, the oldest is given back to be counted unpaired.
        waiting.push((6, "map 6"), &held);
        waiting.push((7, "map 7"), &held);
        assert_eq!(waiting.push((8, "map 8"), &held), Some((6, "map 6")));
        assert_eq!(held.pushed(), 8);
    }

    #[test]
    fn the_header_says_which_result_is_wanted() {
        assert_eq!(HiWanted::from_header(0), HiWanted::Newest);
        assert_eq!(HiWanted::from_header(NO_HI_FRAME), HiWanted::None);
        assert_eq!(HiWanted::from_header(42), HiWanted::Named(42));
    }

    #[test]
    fn live_frames_take_the_newest_result_only_while_it_is_fresh() {
        let mut hi = HiResults::new(8);
        assert!(
            hi.choose(HiWanted::Newest, 1_000, 500).is_none(),
            "nothing yet"
        );
        hi.push(10, 1_000, "a");
        hi.push(12, 2_000, "b");
        let fresh = hi.choose(HiWanted::Newest, 2_400, 500);
        assert_eq!(fresh.map(|h| h.result), Some("b"));
        assert!(
            hi.choose(HiWanted::Newest, 2_501, 500).is_none(),
            "aged out"
        );
        // A result newer than the frame (it came first) is not too old.
        assert_eq!(
            hi.choose(HiWanted::Newest, 1_500, 0).map(|h| h.frame_id),
            Some(12)
        );
    }

    #[test]
    fn replayed_frames_take_the_named_result_whatever_its_age() {
        let mut hi = HiResults::new(2);
        hi.push(10, 1_000, "a");
        hi.push(12, 2_000, "b");
        let named = hi.choose(HiWanted::Named(10), 9_000_000, 1);
        assert_eq!(named.map(|h| h.result), Some("a"));
        assert!(hi.choose(HiWanted::None, 2_000, u64::MAX).is_none());
        hi.push(14, 3_000, "c");
        assert!(
            hi.choose(HiWanted::Named(10), 3_000, u64::MAX).is_none(),
            "dropped"
        );
        assert_eq!(hi.find(14).map(|h| h.capture_ns), Some(3_000));
    }
}
