//! Fusion stage process: pairs each disparity map with its left image (held zero-copy in
//! shared memory until the map arrives), detects edges, keeps disparity at edges, and publishes
//! ranges per window for every fast-path frame, filling windows the fast path cannot see from
//! a fresh long-range result (in a replay: the long-range result the recorded run fused,
//! named in the frame header, so the replay does not depend on timing).

use std::process::ExitCode;
use std::time::Duration;

use hvs_fusion::pairing::{HeldFrames, HiResults, HiWanted, Pairing, SettledMap, WaitingMaps};
use hvs_fusion::{FusionPath, merge_scans, merge_windows};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::ipc::{ReceivedSample, TopicSubscriber, attach_interval};
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{
    DisparityMap320x240, DisparityMap640x480, MAX_RANGE_WINDOWS, ObstacleScan, RangeReport,
    RangeSource, RangeWindow, Sequenced, StereoFrame320x240, StereoFrame640x480,
};
use hvs_shared::topics::{self, Stage};

/// Frames kept waiting for their disparity map (the topic allows 5 borrowed samples).
const HELD_FRAMES: usize = 3;

/// Maps kept waiting for a frame still on its way (each subscriber may borrow 5 samples).
const WAITING_MAPS: usize = 2;

/// Longest wait of a replayed fast-path map for the 640x480 result its frame names, ns. In
/// a lockstep replay the result is on its way: the capture sent the frame after that
/// result was published (stereo-hi preempted between its subscribers), or, for the result
/// of the frame's own step, right after the 640x480 pair (stereo-hi, niced, has taken over
/// 2 s for one frame on a busy machine). Past this it was lost. A replay at a set rate does
/// not wait: there newer frames are queued behind the map.
const NAMED_WAIT_NS: u64 = 5_000_000_000;

/// How often the stage looks at a map waiting for a named result when nothing arrives.
const WAIT_CHECK: Duration = Duration::from_millis(100);

/// Long-range results kept for a replay naming an earlier one than the latest.
const HI_RESULTS_KEPT: usize = 8;

fn main() -> ExitCode {
    run_stage(Stage::Fusion, run)
}

/// What fusion keeps of a long-range result.
struct HiRanges {
    windows: [RangeWindow; MAX_RANGE_WINDOWS],
    scan: ObstacleScan,
}

/// Moves every queued frame into `held` (the newest `HELD_FRAMES` stay).
fn hold_frames<T>(
    sub: &TopicSubscriber<T>,
    held: &mut HeldFrames<ReceivedSample<T>>,
) -> Result<(), StageError>
where
    T: core::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Sequenced + 'static,
{
    sub.clear_events();
    while let Some(s) = sub.receive()? {
        held.push(s);
    }
    Ok(())
}

/// The frame id of a frame or disparity map sample (its sequence number).
fn frame_id<T>(s: &ReceivedSample<T>) -> u64
where
    T: core::fmt::Debug + iceoryx2::prelude::ZeroCopySend + Sequenced + 'static,
{
    s.payload().sequence()
}

/// The long-range side: pairs each 640x480 disparity map with its held frame.
struct HiSide {
    held: HeldFrames<ReceivedSample<StereoFrame640x480>>,
    waiting: WaitingMaps<ReceivedSample<DisparityMap640x480>>,
    path: FusionPath,
    results: HiResults<HiRanges>,
    /// Frame id of the last map received.
    last_map_id: Option<u64>,
    unpaired: u64,
}

impl HiSide {
    /// Forgets the last map id of an old frame numbering (the results went with
    /// [`HiResults::follow_numbering`]): the capture restarted, so frame ids start again and
    /// whether a replayed frame's named result may still come is judged in the new numbering.
    /// A map of the new numbering that came before its frame keeps its id.
    fn restart(&mut self) {
        let newest = self.held.newest_id();
        self.last_map_id = self
            .last_map_id
            .filter(|&id| newest.is_some_and(|n| id <= n));
    }

    /// Computes the ranges of every map whose frame is here (in the order they came; each
    /// map settles before the next is queued, so none is pushed out while its frame waits).
    fn take_maps(
        &mut self,
        frames: &TopicSubscriber<StereoFrame640x480>,
        maps: &TopicSubscriber<DisparityMap640x480>,
    ) -> Result<(), StageError> {
        maps.clear_events();
        loop {
            // Frames first, each time: a frame queued meanwhile settles its waiting map
            // before the next map can push that one out.
            hold_frames(frames, &mut self.held)?;
            if self.results.follow_numbering(self.held.numbering()) {
                self.restart();
            }
            let received = maps.receive()?;
            let more = received.is_some();
            if let Some(map) = received {
                self.last_map_id = Some(map.payload().header.frame_id);
                if self.waiting.push(map, &self.held, monotonic_ns()).is_some() {
                    self.unpaired += 1;
                }
            }
            while let Some(settled) = self.waiting.next_settled(&self.held) {
                self.fuse(&settled);
            }
            if !more {
                return Ok(());
            }
        }
    }

    fn fuse(&mut self, settled: &SettledMap<ReceivedSample<DisparityMap640x480>>) {
        let Some(frame) = self.held.paired(settled) else {
            self.unpaired += 1;
            return;
        };
        let m = settled.map.payload();
        let (windows, _, _) =
            self.path
                .ranges(&frame.payload().left, &m.disparity_q8, Some(&m.confidence));
        let scan = *self.path.scan();
        self.results.push(
            m.header.frame_id,
            m.header.capture_ns,
            HiRanges { windows, scan },
        );
    }

    /// True when the result of `frame_id` can still come: no map of that frame or a newer
    /// one has been received, or a received map still waits for its frame.
    fn may_come(&self, frame_id: u64) -> bool {
        self.last_map_id.is_none_or(|last| last < frame_id) || !self.waiting.is_empty()
    }
}

fn run(rt: &mut StageRuntime) -> Result<(), StageError> {
    let frames_lo = rt.node.subscriber(&topics::FRAMES_LO, 2)?;
    let disp_lo = rt.node.subscriber(&topics::DISPARITY_LO, 2)?;
    let disp_hi = rt.node.subscriber(&topics::DISPARITY_HI, 1)?;
    let frames_hi = rt.node.subscriber(&topics::FRAMES_HI, 2)?;
    let mut hi = HiSide {
        held: HeldFrames::new(HELD_FRAMES, frame_id),
        waiting: WaitingMaps::new(WAITING_MAPS, frame_id),
        path: FusionPath::new(&rt.config, 640, 480, RangeSource::Hi),
        results: HiResults::new(HI_RESULTS_KEPT),
        last_map_id: None,
        unpaired: 0,
    };
    let mut ranges = rt.node.publisher(&topics::RANGES)?;
    let mut held_lo = HeldFrames::new(HELD_FRAMES, frame_id);
    let mut waiting_lo = WaitingMaps::new(WAITING_MAPS, frame_id);
    let mut lo_path = FusionPath::new(&rt.config, 320, 240, RangeSource::Lo);
    let hi_max_age_ns = rt.config.fusion.hi_max_age_ms * 1_000_000;
    let min_valid_px = rt.config.fusion.min_valid_px;
    let mut unpaired = 0u64;
    let mut replay_missed = 0u64;
    rt.set_note(format!("{} windows", rt.config.fusion.windows));

    let waitset = rt.waitset()?;
    // Maps, frames (a map that overtook its frame waits for it) and a periodic check (a
    // replayed map waiting for its named 640x480 result) wake the stage.
    let _maps_lo = disp_lo.attach_to(&waitset)?;
    let _maps_hi = disp_hi.attach_to(&waitset)?;
    let _frames_lo = frames_lo.attach_to(&waitset)?;
    let _frames_hi = frames_hi.attach_to(&waitset)?;
    let _wait_check = attach_interval(&waitset, WAIT_CHECK)?;

    rt.run_loop(&waitset, |rt, _woken_by| {
        // Whatever woke the stage, both sides take what came.
        hi.take_maps(&frames_hi, &disp_hi)?;
        disp_lo.clear_events();
        loop {
            hold_frames(&frames_lo, &mut held_lo)?;
            let received = disp_lo.receive()?;
            let more = received.is_some();
            if let Some(map) = received {
                rt.count_in(1);
                if waiting_lo.push(map, &held_lo, monotonic_ns()).is_some() {
                    unpaired += 1;
                }
            }
            while let Some(pairing) = waiting_lo.front_pairing(&held_lo) {
                if pairing == Pairing::Held && named_result_pending(&waiting_lo, &held_lo, &hi) {
                    break;
                }
                let Some(settled) = waiting_lo.next_settled(&held_lo) else {
                    break;
                };
                let Some(frame) = held_lo.paired(&settled) else {
                    unpaired += 1;
                    continue;
                };
                let m = settled.map.payload();
                let (lo_windows, edge_px, valid_edge_px) =
                    lo_path.ranges(&frame.payload().left, &m.disparity_q8, Some(&m.confidence));
                let wanted = HiWanted::from_header(frame.payload().header.replay_hi_frame_id);
                let hi_ranges = hi
                    .results
                    .choose(wanted, m.header.capture_ns, hi_max_age_ns);
                if let HiWanted::Named(named) = wanted
                    && hi_ranges.is_none()
                {
                    replay_missed += 1;
                    rt.report_error(
                        "replay",
                        &format!(
                            "frame {}: the recorded 640x480 result of frame {named} is not \
                             here ({replay_missed} so far); fused without it",
                            m.header.frame_id
                        ),
                    );
                }
                let mut sample = match ranges.loan() {
                    Ok(s) => s,
                    Err(e) => {
                        rt.report_publish_error(&e);
                        continue;
                    }
                };
                *sample.payload_mut() = RangeReport {
                    frame_id: m.header.frame_id,
                    capture_ns: m.header.capture_ns,
                    published_ns: monotonic_ns(),
                    hi_frame_id: hi_ranges.map_or(0, |h| h.frame_id),
                    hi_age_ns: hi_ranges
                        .map_or(0, |h| m.header.capture_ns.saturating_sub(h.capture_ns)),
                    window_count: rt.config.fusion.windows,
                    edge_px,
                    windows: merge_windows(
                        &lo_windows,
                        hi_ranges.map(|h| &h.result.windows),
                        min_valid_px,
                    ),
                    valid_edge_px,
                    reserved: 0,
                    scan: merge_scans(lo_path.scan(), hi_ranges.map(|h| &h.result.scan)),
                };
                rt.send_or_report(&mut ranges, sample, monotonic_ns() - settled.received_ns);
            }
            if !more {
                break;
            }
        }
        rt.set_drops(disp_lo.dropped() + unpaired + hi.unpaired);
        Ok(LoopControl::Continue)
    })
}

/// True when the oldest waiting fast-path map, whose frame is held, must wait on: it is the
/// newest, and its frame is replayed and names a 640x480 result that is not here yet but
/// may still come (for at most [`NAMED_WAIT_NS`] after the map arrived).
fn named_result_pending(
    waiting_lo: &WaitingMaps<ReceivedSample<DisparityMap320x240>>,
    held_lo: &HeldFrames<ReceivedSample<StereoFrame320x240>>,
    hi: &HiSide,
) -> bool {
    let Some((map, received_ns)) = waiting_lo.front() else {
        return false;
    };
    let id = map.payload().header.frame_id;
    // Newer maps or frames queued behind it (a replay at a set rate): no waiting.
    if waiting_lo.len() > 1 || held_lo.any_newer_than(id) {
        return false;
    }
    let Some(frame) = held_lo.find(id) else {
        return false;
    };
    let HiWanted::Named(named) = HiWanted::from_header(frame.payload().header.replay_hi_frame_id)
    else {
        return false;
    };
    // The 640x480 maps were taken when the stage woke; one that comes later wakes it again.
    hi.results.find(named).is_none()
        && hi.may_come(named)
        && monotonic_ns().saturating_sub(received_ns) < NAMED_WAIT_NS
}
