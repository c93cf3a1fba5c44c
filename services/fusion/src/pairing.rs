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
///
/// Frame ids rise. An item whose id is not above the newest one's starts a new numbering
/// (a restarted capture): the items of the old one are dropped, so that a map is never
/// paired with an old frame of the same id.
#[derive(Debug)]
pub struct HeldFrames<T> {
    items: VecDeque<T>,
    capacity: usize,
    frame_id: fn(&T) -> u64,
    newest_id: Option<u64>,
    numbering: u64,
}

impl<T> HeldFrames<T> {
    /// Holds at most `capacity` items (at least 1); `frame_id` reads an item's id.
    pub fn new(capacity: usize, frame_id: fn(&T) -> u64) -> Self {
        Self {
            items: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
            frame_id,
            newest_id: None,
            numbering: 0,
        }
    }

    /// Holds `item`, dropping the oldest when full (all of them when its id starts a new
    /// numbering).
    pub fn push(&mut self, item: T) {
        let id = (self.frame_id)(&item);
        if self.newest_id.is_some_and(|newest| id <= newest) {
            self.items.clear();
            self.numbering += 1;
        }
        self.newest_id = Some(id);
        if self.items.len() == self.capacity {
            self.items.pop_front();
        }
        self.items.push_back(item);
    }

    /// The id of the newest item pushed, if any.
    pub fn newest_id(&self) -> Option<u64> {
        self.newest_id
    }

    /// How many times the frame ids started again since the start.
    pub fn numbering(&self) -> u64 {
        self.numbering
    }

    /// True when a held item is newer than `frame_id`: frames come in id order, so an item
    /// of that id that is not held will not come any more.
    pub fn any_newer_than(&self, frame_id: u64) -> bool {
        self.items.iter().any(|i| (self.frame_id)(i) > frame_id)
    }

    /// The frame a settled map pairs with: held, and of the map's frame id.
    pub fn paired<M>(&self, settled: &SettledMap<M>) -> Option<&T> {
        match settled.pairing {
            Pairing::Held => self.find(settled.frame_id),
            Pairing::Gone => None,
        }
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

/// Where a waiting map's frame is, once that is settled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pairing {
    /// Held: the map can be fused.
    Held,
    /// The map's frame is not held and will not come: a newer frame is held (the frame was
    /// lost, or the map came too late for it), or the frame ids started again since the
    /// map came. The map is dropped.
    Gone,
}

/// A disparity map taken from [`WaitingMaps`].
#[derive(Debug)]
pub struct SettledMap<M> {
    /// The map.
    pub map: M,
    /// Its frame id.
    pub frame_id: u64,
    /// Whether its frame is held.
    pub pairing: Pairing,
    /// When the map was received, CLOCK_MONOTONIC ns (its wait counts in the latency).
    pub received_ns: u64,
}

/// Disparity maps waiting for their frame, oldest first, at most `capacity` (samples stay
/// borrowed in shared memory while they wait).
///
/// A frame normally arrives long before its map: the matcher starts from that frame. But
/// one publish reaches the subscribers one after another, so on a busy machine the matcher
/// (awake, and taking the newest frame) can get the frame, match it and publish the map
/// while the publisher is still preempted before it queued the frame for fusion. Such a map
/// waits here until its frame arrives, or a newer one (proof that its frame was lost).
#[derive(Debug)]
pub struct WaitingMaps<M> {
    /// Each map with [`HeldFrames::numbering`] and the time when it arrived.
    maps: VecDeque<(M, u64, u64)>,
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

    /// Queues a map received at `received_ns` while `held` holds the frames it holds now;
    /// returns the oldest waiting map when full (it is dropped unpaired).
    pub fn push<F>(&mut self, map: M, held: &HeldFrames<F>, received_ns: u64) -> Option<M> {
        let evicted = if self.maps.len() == self.capacity {
            self.maps.pop_front().map(|(m, _, _)| m)
        } else {
            None
        };
        self.maps.push_back((map, held.numbering(), received_ns));
        evicted
    }

    /// The oldest map, if any waits, with the time it was received (CLOCK_MONOTONIC ns).
    pub fn front(&self) -> Option<(&M, u64)> {
        self.maps
            .front()
            .map(|(m, _, received_ns)| (m, *received_ns))
    }

    /// Whether the oldest map's pairing is settled: `None` while it still waits for its
    /// frame (or no map waits). Maps are fused in the order they came.
    pub fn front_pairing<F>(&self, held: &HeldFrames<F>) -> Option<Pairing> {
        let (map, numbering, _) = self.maps.front()?;
        let id = (self.frame_id)(map);
        if held.find(id).is_some() {
            Some(Pairing::Held)
        } else if held.numbering() != *numbering || held.any_newer_than(id) {
            Some(Pairing::Gone)
        } else {
            None
        }
    }

    /// Takes the oldest map if its pairing is settled.
    pub fn next_settled<F>(&mut self, held: &HeldFrames<F>) -> Option<SettledMap<M>> {
        let pairing = self.front_pairing(held)?;
        self.maps
            .pop_front()
            .map(|(map, _, received_ns)| SettledMap {
                frame_id: (self.frame_id)(&map),
                map,
                pairing,
                received_ns,
            })
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

/// The newest long-range results, oldest first, at most `capacity`, all of one frame
/// numbering (a restarted capture numbers its frames from 1 again, and a replayed frame that
/// names result N must not get the old numbering's N).
#[derive(Debug)]
pub struct HiResults<R> {
    results: VecDeque<HiResult<R>>,
    capacity: usize,
    numbering: u64,
}

impl<R> HiResults<R> {
    /// Keeps at most `capacity` results (at least 1).
    pub fn new(capacity: usize) -> Self {
        Self {
            results: VecDeque::with_capacity(capacity.max(1)),
            capacity: capacity.max(1),
            numbering: 0,
        }
    }

    /// Follows the 640x480 frames' numbering ([`HeldFrames::numbering`]): when it changed
    /// (the frame ids started again), every result kept is dropped. True when it changed.
    pub fn follow_numbering(&mut self, numbering: u64) -> bool {
        if numbering == self.numbering {
            return false;
        }
        self.numbering = numbering;
        self.results.clear();
        true
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

    /// Settles the oldest waiting map: its id and pairing.
    fn settle(waiting: &mut WaitingMaps<u64>, held: &HeldFrames<u64>) -> Option<(u64, Pairing)> {
        waiting.next_settled(held).map(|s| (s.map, s.pairing))
    }

    fn stage() -> (HeldFrames<u64>, WaitingMaps<u64>) {
        (
            HeldFrames::new(3, |f: &u64| *f),
            WaitingMaps::new(2, |m: &u64| *m),
        )
    }

    #[test]
    fn a_map_that_overtook_its_frame_waits_for_it_in_order() {
        let (mut held, mut waiting) = stage();
        held.push(1);
        assert!(waiting.push(1, &held, 10).is_none());
        let first = waiting.next_settled(&held).expect("frame 1 is held");
        assert_eq!(
            (first.map, first.pairing, first.received_ns),
            (1, Pairing::Held, 10)
        );
        assert_eq!(held.paired(&first), Some(&1));
        // Map 2 came before frame 2: it waits, and map 3 behind it too.
        waiting.push(2, &held, 20);
        assert_eq!(settle(&mut waiting, &held), None);
        waiting.push(3, &held, 30);
        assert_eq!(waiting.len(), 2);
        held.push(2);
        let second = waiting.next_settled(&held).expect("frame 2 came");
        assert_eq!((second.map, second.received_ns), (2, 20), "its wait counts");
        assert_eq!(settle(&mut waiting, &held), None, "frame 3 has not come");
        held.push(3);
        assert_eq!(settle(&mut waiting, &held), Some((3, Pairing::Held)));
        assert!(waiting.is_empty());
    }

    #[test]
    fn a_map_whose_frame_was_lost_is_settled_by_a_newer_frame() {
        let (mut held, mut waiting) = stage();
        held.push(1);
        waiting.push(2, &held, 0);
        assert_eq!(settle(&mut waiting, &held), None);
        held.push(3);
        let lost = waiting.next_settled(&held).expect("frame 3 settles map 2");
        assert_eq!((lost.map, lost.pairing), (2, Pairing::Gone));
        assert_eq!(
            held.paired(&lost),
            None,
            "no frame for a map settled as gone"
        );
        // A map older than the held frames is gone at once.
        for id in 4..=6 {
            held.push(id);
        }
        waiting.push(3, &held, 40);
        assert_eq!(waiting.front(), Some((&3, 40)));
        assert_eq!(settle(&mut waiting, &held), Some((3, Pairing::Gone)));
        // When full, the oldest is given back, to be counted unpaired.
        waiting.push(7, &held, 0);
        waiting.push(8, &held, 0);
        assert_eq!(waiting.push(9, &held, 0), Some(7));
    }

    #[test]
    fn frame_ids_that_start_again_drop_the_old_numbering() {
        let (mut held, mut waiting) = stage();
        for id in 98..=100 {
            held.push(id);
        }
        // A map of the old numbering waits for frame 101, which never comes.
        waiting.push(101, &held, 0);
        assert_eq!(held.numbering(), 0);
        // The capture restarts: frame ids from 1. The old frames go, and the old map with
        // them; the new ones pair.
        held.push(1);
        assert_eq!((held.numbering(), held.len()), (1, 1));
        assert!(held.find(99).is_none());
        assert_eq!(settle(&mut waiting, &held), Some((101, Pairing::Gone)));
        waiting.push(1, &held, 0);
        waiting.push(2, &held, 0);
        assert_eq!(settle(&mut waiting, &held), Some((1, Pairing::Held)));
        assert_eq!(settle(&mut waiting, &held), None, "map 2 overtook frame 2");
        held.push(2);
        assert_eq!(settle(&mut waiting, &held), Some((2, Pairing::Held)));
        // An id seen again also starts a new numbering: no pairing with the old frame.
        held.push(2);
        assert_eq!((held.numbering(), held.len()), (2, 1));
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

    #[test]
    fn a_restarted_numbering_drops_the_old_results() {
        let mut frames = HeldFrames::new(4, |id: &u64| *id);
        let mut hi = HiResults::new(4);
        for id in [10, 11] {
            frames.push(id);
            assert!(!hi.follow_numbering(frames.numbering()));
            hi.push(id, id * 1_000, id);
        }
        // The capture restarts: its frames are numbered from 1 again.
        frames.push(1);
        assert!(hi.follow_numbering(frames.numbering()), "a new numbering");
        assert!(hi.choose(HiWanted::Named(10), 0, u64::MAX).is_none());
        assert!(hi.choose(HiWanted::Newest, 11_000, u64::MAX).is_none());
        hi.push(1, 20_000, 1);
        assert!(
            !hi.follow_numbering(frames.numbering()),
            "the same numbering"
        );
        assert_eq!(
            hi.choose(HiWanted::Named(1), 0, 0).map(|h| h.result),
            Some(1)
        );
        assert_eq!(frames.newest_id(), Some(1));
    }
}
