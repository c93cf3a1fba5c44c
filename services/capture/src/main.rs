//! Capture stage process: publishes every stereo pair twice, at 640x480 and at 320x240.
//!
//! Sources (`capture.source`, docs/capture.md):
//! - `sim`: the simulator's rendered camera (`sim/camera/640x480`), which stands in for the
//!   two Minoru webcams. The 640x480 pair is copied once from the camera buffer into a loaned
//!   shared-memory sample (as a V4L2 buffer would be), and the 320x240 pair is downscaled from
//!   it directly into its own loaned sample.
//! - `v4l2`: the Minoru's two cameras, paired by kernel timestamp, converted to grey straight
//!   into the loaned sample (or through the rectification remap), reopened with backoff when a
//!   camera drops off the USB bus.
//! - `files`: a folder of PNG pairs at `capture.files.rate_hz`, or in lockstep with the
//!   pipeline's range reports.
//! - `replay` (`hvs run --replay run.mcap`): a recording's pairs with their recorded frame ids
//!   and the recorded actuator output (for the decision's dead reckoning), in lockstep with the
//!   pipeline's decisions so that the recorded decisions are repeated, or at a fixed rate.
//!
//! At a 320x240 capture size only `frames/320x240` is published.

use std::process::ExitCode;
use std::time::{Duration, Instant};

use hvs_capture::calib::{StereoCalibration, StereoRectifier};
use hvs_capture::files::FileSource;
use hvs_capture::pacing::{Backoff, Lockstep, ReplayWait, WaitState};
use hvs_capture::replay::{ReplayEvent, ReplayFrame, ReplayIndex, ReplayPair};
use hvs_capture::v4l2::{CameraMode, StereoCamera, StereoSpec};
use hvs_capture::writer::{
    PairTimes, PairWriter, WriteFailure, rebase_to, write_replayed, write_sim_pair,
};
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::CaptureSource;
use hvs_runtime::ipc::{TopicPublisher, attach_interval};
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{
    FrameSource, HI_HEIGHT, HI_WIDTH, StageHealth, StereoFrame320x240, StereoFrame640x480,
};
use hvs_shared::topics::{self, Stage};

fn main() -> ExitCode {
    run_stage(Stage::Capture, |rt| match rt.config.capture.source {
        CaptureSource::Sim => run_sim_source(rt),
        CaptureSource::V4l2 => run_v4l2_source(rt),
        CaptureSource::Files => run_files_source(rt),
        CaptureSource::Replay => run_replay_source(rt),
    })
}

fn run_sim_source(rt: &mut StageRuntime) -> Result<(), StageError> {
    let camera = rt.node.subscriber(&topics::SIM_CAMERA, 2)?;
    let mut hi = rt.node.publisher(&topics::FRAMES_HI)?;
    let mut lo = rt.node.publisher(&topics::FRAMES_LO)?;
    rt.set_note("source sim");
    tracing::info!("source sim ({})", camera.service());

    let waitset = rt.waitset()?;
    let camera_guard = camera.attach_to(&waitset)?;

    rt.run_loop(&waitset, |rt, id| {
        if !id.has_event_from(&camera_guard) {
            return Ok(LoopControl::Continue);
        }
        camera.clear_events();
        while let Some(raw) = camera.receive()? {
            let received_ns = monotonic_ns();
            rt.count_in(1);
            rt.set_drops(camera.dropped());
            let src = raw.payload();
            if src.header.width as usize != HI_WIDTH || src.header.height as usize != HI_HEIGHT {
                rt.report_error(
                    "camera frame rejected",
                    &format!(
                        "size {}x{}, expected {HI_WIDTH}x{HI_HEIGHT}",
                        src.header.width, src.header.height
                    ),
                );
                continue;
            }
            let mut hi_sample = match hi.loan() {
                Ok(s) => s,
                Err(e) => {
                    rt.report_publish_error(&e);
                    continue;
                }
            };
            let mut lo_sample = match lo.loan() {
                Ok(s) => s,
                Err(e) => {
                    rt.report_publish_error(&e);
                    continue;
                }
            };
            write_sim_pair(
                src,
                hi_sample.payload_mut(),
                lo_sample.payload_mut(),
                monotonic_ns,
            )?;
            // The fast path first: it is the one the decisions wait for.
            // One pair in, one pair out (published at both resolutions).
            rt.send_or_report(&mut lo, lo_sample, monotonic_ns() - received_ns);
            if let Err(e) = hi.send(hi_sample) {
                rt.report_publish_error(&e);
            }
        }
        Ok(LoopControl::Continue)
    })
}

/// Publishes pairs from a non-sim source: loans the samples and lets the [`PairWriter`]
/// fill them in place.
struct PairPublisher {
    hi: Option<TopicPublisher<StereoFrame640x480>>,
    lo: TopicPublisher<StereoFrame320x240>,
    writer: PairWriter,
}

impl PairPublisher {
    /// Opens the publishers for pairs of `width x height` (at 320x240 only the fast path's).
    fn open(
        rt: &mut StageRuntime,
        source: FrameSource,
        (width, height): (u32, u32),
    ) -> Result<Self, StageError> {
        let hi = if width as usize == HI_WIDTH {
            Some(rt.node.publisher(&topics::FRAMES_HI)?)
        } else {
            tracing::info!(
                "capture size {width}x{height}: only {} is published",
                topics::FRAMES_LO.path
            );
            None
        };
        let lo = rt.node.publisher(&topics::FRAMES_LO)?;
        let rectifier = match &rt.config.capture.calibration {
            Some(path) => {
                let path = rt.config.resolve_path(path);
                let calib = StereoCalibration::load(&path)?;
                let rect = StereoRectifier::new(&calib, width, height)?;
                tracing::info!(
                    "rectifying with {} ({})",
                    path.display(),
                    if calib.rectification.is_some() {
                        "R1/R2/P1/P2 from the file"
                    } else {
                        "rectification computed"
                    }
                );
                Some(rect)
            }
            None => None,
        };
        Ok(Self {
            hi,
            lo,
            writer: PairWriter::new(source, rectifier, (width, height)),
        })
    }

    /// Publishes one pair; `fill` writes the grey images. `Ok(false)`: no sample could be
    /// loaned (reported; `fill` was not called).
    fn publish<E>(
        &mut self,
        rt: &mut StageRuntime,
        times: PairTimes,
        fill: impl FnOnce(&mut [u8], &mut [u8]) -> Result<(), E>,
    ) -> Result<bool, WriteFailure<E>> {
        let mut lo_sample = match self.lo.loan() {
            Ok(s) => s,
            Err(e) => {
                rt.report_publish_error(&e);
                return Ok(false);
            }
        };
        match &mut self.hi {
            Some(hi) => {
                let mut hi_sample = match hi.loan() {
                    Ok(s) => s,
                    Err(e) => {
                        rt.report_publish_error(&e);
                        return Ok(false);
                    }
                };
                self.writer.write_hi(
                    times,
                    hi_sample.payload_mut(),
                    lo_sample.payload_mut(),
                    monotonic_ns,
                    fill,
                )?;
                // The fast path first: it is the one the decisions wait for.
                rt.send_or_report(&mut self.lo, lo_sample, monotonic_ns() - times.received_ns);
                if let Err(e) = hi.send(hi_sample) {
                    rt.report_publish_error(&e);
                }
            }
            None => {
                self.writer
                    .write_lo(times, lo_sample.payload_mut(), monotonic_ns, fill)?;
                rt.send_or_report(&mut self.lo, lo_sample, monotonic_ns() - times.received_ns);
            }
        }
        Ok(true)
    }
}

/// Sleeps `total` while beating; false once termination was requested.
fn wait_beating(rt: &mut StageRuntime, total: Duration) -> bool {
    let end = Instant::now() + total;
    loop {
        rt.beat_if_due();
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return true;
        }
        if !rt.node.sleep(left.min(Duration::from_millis(100))) {
            return false;
        }
    }
}

fn run_v4l2_source(rt: &mut StageRuntime) -> Result<(), StageError> {
    let c = rt.config.capture.clone();
    let v = &c.v4l2;
    let spec = StereoSpec {
        left_device: v.left_device.clone(),
        right_device: v.right_device.clone(),
        mode: CameraMode {
            width: c.width,
            height: c.height,
            format: v.pixel_format,
            fps: rt.config.camera.fps,
            buffers: v.buffers,
        },
        max_skew_ns: (v.max_skew_ms * 1e6) as u64,
        stall_timeout: Duration::from_millis(v.stall_timeout_ms),
        controls: v.controls.clone(),
    };
    // Opened for the negotiated size (re-opened if a reconnect negotiates another).
    let mut out: Option<((u32, u32), PairPublisher)> = None;
    let mut backoff = Backoff::new(
        Duration::from_millis(v.reconnect_backoff_ms),
        Duration::from_millis(v.reconnect_max_backoff_ms),
    );
    let devices = format!(
        "{} + {}",
        spec.left_device.display(),
        spec.right_device.display()
    );
    loop {
        let mut cam = match StereoCamera::open(&spec) {
            Ok(cam) => cam,
            Err(e) if e.is_permanent() => return Err(e.into()),
            Err(e) => {
                let delay = backoff.failed();
                rt.count_error();
                rt.set_health(StageHealth::Degraded);
                rt.set_note(format!("v4l2 {devices}: reconnecting"));
                tracing::warn!(
                    "{e}; retrying in {:.1} s (attempt {})",
                    delay.as_secs_f64(),
                    backoff.attempts()
                );
                if !wait_beating(rt, delay) {
                    return Ok(());
                }
                continue;
            }
        };
        let negotiated = cam.negotiated().clone();
        let mode = &negotiated.mode;
        // The one line that says what was chosen and why.
        tracing::info!(
            "source v4l2 {devices}: {}; pairs within {} ms{}",
            negotiated.summary(),
            v.max_skew_ms,
            if backoff.attempts() > 0 {
                format!(" (reconnected after {} attempts)", backoff.attempts())
            } else {
                String::new()
            }
        );
        if (mode.width, mode.height) != (c.width, c.height) {
            tracing::warn!(
                "both cameras stream only at {}x{} on this USB bus: both paths are fed from it \
                 and stereo-hi stays idle",
                mode.width,
                mode.height
            );
        }
        let (left, right) = cam.cameras();
        for (camera, report) in [
            (left, &negotiated.controls.0),
            (right, &negotiated.controls.1),
        ] {
            let device = camera.device().display();
            if !report.applied.is_empty() {
                tracing::info!(%device, applied = ?report.applied, "image controls locked");
            }
            for (key, why) in &report.problems {
                tracing::warn!(%device, "capture.v4l2.controls.{key}: {why}");
            }
            match camera.fps() {
                Some(fps) if (fps - mode.fps).abs() > 0.01 * mode.fps => tracing::warn!(
                    %device,
                    "camera runs at {fps:.2} fps, not the negotiated {}",
                    mode.fps
                ),
                Some(_) => {}
                None => tracing::warn!(
                    %device,
                    "camera has no frame-rate control; it runs at its default rate"
                ),
            }
        }
        let size = (mode.width, mode.height);
        if out.as_ref().is_none_or(|(s, _)| *s != size) {
            // The old publishers first: each topic takes one publisher.
            drop(out.take());
            out = Some((size, PairPublisher::open(rt, FrameSource::V4l2, size)?));
        }
        let Some((_, out)) = out.as_mut() else {
            return Err("capture: no publisher for the negotiated size".into());
        };
        backoff.succeeded();
        rt.set_health(StageHealth::Running);
        rt.set_note(format!(
            "v4l2 {devices} {}x{}@{}",
            mode.width, mode.height, mode.fps
        ));
        rt.beat();
        let dropped_before = rt_drops(&cam);
        let mut dropped_total = 0u64;
        loop {
            if rt.node.termination_requested() {
                tracing::info!("termination requested");
                return Ok(());
            }
            rt.beat_if_due();
            let pair = match cam.next_pair(Duration::from_millis(50)) {
                Ok(Some(pair)) => pair,
                Ok(None) => continue,
                Err(e) => {
                    rt.report_error("capture failed, reopening the cameras", &e);
                    break;
                }
            };
            rt.count_in(1);
            dropped_total = rt_drops(&cam) - dropped_before;
            rt.set_drops(dropped_total);
            let times = PairTimes {
                left_ns: pair.pair.left.stamp_ns,
                right_ns: pair.pair.right.stamp_ns,
                received_ns: pair.completed_ns,
            };
            match out.publish(rt, times, |l, r| cam.read_pair(&pair, l, r)) {
                Ok(true) => {}
                Ok(false) => {
                    if let Err(e) = cam.release_pair(&pair) {
                        rt.report_error("capture failed, reopening the cameras", &e);
                        break;
                    }
                }
                Err(WriteFailure::Source(e)) if e.needs_reconnect() => {
                    rt.report_error("capture failed, reopening the cameras", &e);
                    break;
                }
                Err(e) => rt.report_error("pair skipped", &e),
            }
        }
        tracing::debug!("{dropped_total} frames dropped unpaired");
        drop(cam);
        rt.set_health(StageHealth::Degraded);
        rt.set_note(format!("v4l2 {devices}: reconnecting"));
        if !wait_beating(rt, backoff.current()) {
            return Ok(());
        }
    }
}

/// Frames the pairer dropped so far.
fn rt_drops(cam: &StereoCamera) -> u64 {
    let s = cam.stats();
    s.dropped_left + s.dropped_right
}

fn run_files_source(rt: &mut StageRuntime) -> Result<(), StageError> {
    let c = rt.config.capture.clone();
    let folder = rt.config.resolve_path(&c.files.folder);
    let mut source = FileSource::open(&folder, c.width, c.height, c.files.loop_playback)?;
    let size = (rt.config.capture.width, rt.config.capture.height);
    let mut out = PairPublisher::open(rt, FrameSource::Files, size)?;
    let count = source.pairs().len();
    tracing::info!(
        "source files {} ({count} pairs, {}x{}, {}{})",
        folder.display(),
        c.width,
        c.height,
        if c.files.rate_hz > 0.0 {
            format!("{} Hz", c.files.rate_hz)
        } else {
            "as fast as the pipeline takes them".to_string()
        },
        if c.files.loop_playback {
            ", looping"
        } else {
            ""
        }
    );
    rt.set_note(format!("files {count} pairs"));

    // Publishes the next pair; false at the end of a non-looping folder.
    let mut finished = false;
    let mut send_next = |rt: &mut StageRuntime, out: &mut PairPublisher| -> bool {
        if finished {
            return false;
        }
        let Some(pair) = source.next_pair().cloned() else {
            finished = true;
            tracing::info!("played all {count} pairs; idle (capture.files.loop_playback = false)");
            rt.set_note(format!("files: all {count} pairs played"));
            return false;
        };
        let now = monotonic_ns();
        rt.count_in(1);
        let times = PairTimes {
            left_ns: now,
            right_ns: now,
            received_ns: now,
        };
        if let Err(e) = out.publish(rt, times, |l, r| source.load(&pair, l, r)) {
            rt.report_error("pair skipped", &e);
        }
        true
    };

    let waitset = rt.waitset()?;
    if c.files.rate_hz > 0.0 {
        let tick = attach_interval(&waitset, Duration::from_secs_f64(1.0 / c.files.rate_hz))?;
        return rt.run_loop(&waitset, |rt, id| {
            if id.has_event_from(&tick) {
                send_next(rt, &mut out);
            }
            Ok(LoopControl::Continue)
        });
    }
    // Lockstep: the next pair goes out when the ranges of the last one arrive (the end of the
    // pipeline), or after lockstep_timeout_ms.
    let ranges = rt.node.subscriber(&topics::RANGES, 4)?;
    let ranges_guard = ranges.attach_to(&waitset)?;
    let timeout = Duration::from_millis(c.files.lockstep_timeout_ms);
    // Wakes the loop to check the timeout (the guard must live as long as the loop).
    let _tick = attach_interval(&waitset, (timeout / 4).max(Duration::from_millis(5)))?;
    let mut lockstep = Lockstep::new(timeout);
    send_next(rt, &mut out);
    lockstep.sent(out.writer.frame_id(), monotonic_ns());
    rt.run_loop(&waitset, |rt, id| {
        if id.has_event_from(&ranges_guard) {
            ranges.clear_events();
            while let Some(report) = ranges.receive()? {
                lockstep.answered_by(report.payload().frame_id);
            }
        }
        if lockstep.due(monotonic_ns()) {
            send_next(rt, &mut out);
            lockstep.sent(out.writer.frame_id(), monotonic_ns());
        }
        Ok(LoopControl::Continue)
    })
}

/// Replay counters for the closing line.
#[derive(Debug, Default)]
struct ReplayCounts {
    lo: u64,
    hi: u64,
    sent: u64,
    timeouts: u64,
}

fn run_replay_source(rt: &mut StageRuntime) -> Result<(), StageError> {
    let c = rt.config.capture.replay.clone();
    let file = rt.config.resolve_path(&c.file);
    rt.set_note("replay: indexing");
    rt.beat();
    let indexing = Instant::now();
    let index = ReplayIndex::open(&file)?;
    let s = index.summary().clone();
    let lockstep = c.rate_hz <= 0.0;
    tracing::info!(
        "source replay {} (indexed in {:.1} s): {} frames in the file, playing {} \
         (320x240 {}, 640x480 {}) and {} actuator outputs; {}; {}",
        file.display(),
        indexing.elapsed().as_secs_f64(),
        s.frames_in_file,
        s.steps,
        s.lo_pairs,
        s.hi_pairs,
        s.actuator_sent,
        if s.has_decisions {
            format!("the {} recorded decisions' frames", s.decisions)
        } else {
            "no recorded decisions: every pair".to_string()
        },
        if lockstep {
            "lockstep with the decisions".to_string()
        } else {
            format!("{} Hz", c.rate_hz)
        }
    );
    if let Some(cause) = &s.truncated {
        tracing::warn!(
            "{} breaks off ({cause}): playing the messages before the break",
            file.display()
        );
    }
    if s.hi_missing > 0 || s.lo_missing > 0 {
        tracing::warn!(
            "{} decided frames fused a 640x480 frame the file lacks and {} decided frames \
             lack their 320x240 pair (lost while recording): those decisions cannot be repeated",
            s.hi_missing,
            s.lo_missing
        );
    }
    let mut lo = rt.node.publisher(&topics::FRAMES_LO)?;
    let mut hi = rt.node.publisher(&topics::FRAMES_HI)?;
    let mut sent = rt.node.publisher(&topics::ACTUATOR_SENT)?;
    let decisions = rt.node.subscriber(&topics::DECISIONS, 4)?;
    let disparity_hi = rt.node.subscriber(&topics::DISPARITY_HI, 1)?;
    // Recorded times move to now (one offset: every interval stays as recorded).
    let rebase = rebase_to(index.start_ns(), monotonic_ns());
    let mut reader = index.reader()?;

    let waitset = rt.waitset()?;
    let decisions_guard = decisions.attach_to(&waitset)?;
    let hi_guard = disparity_hi.attach_to(&waitset)?;
    let period = if lockstep {
        Duration::from_millis(10)
    } else {
        Duration::from_secs_f64(1.0 / c.rate_hz)
    };
    let tick = attach_interval(&waitset, period)?;
    let timeout = Duration::from_millis(c.lockstep_timeout_ms);
    let (mut last_decision, mut last_hi) = (0u64, 0u64);
    let mut wait: Option<ReplayWait> = None;
    let mut counts = ReplayCounts::default();
    let started = Instant::now();
    rt.set_note(format!("replay {} frames", s.steps));

    rt.run_loop(&waitset, |rt, id| {
        if id.has_event_from(&decisions_guard) {
            decisions.clear_events();
            while let Some(d) = decisions.receive()? {
                last_decision = last_decision.max(d.payload().frame_id);
            }
        }
        if id.has_event_from(&hi_guard) {
            disparity_hi.clear_events();
            while let Some(m) = disparity_hi.receive()? {
                last_hi = last_hi.max(m.payload().header.frame_id);
            }
        }
        if let Some(w) = wait {
            match w.state(last_decision, last_hi, monotonic_ns(), timeout) {
                WaitState::Done => wait = None,
                WaitState::Waiting => return Ok(LoopControl::Continue),
                WaitState::TimedOut { missing_decision } => {
                    counts.timeouts += 1;
                    rt.report_error(
                        "replay",
                        &format!(
                            "no {} for frame {} within {} ms \
                             (capture.replay.lockstep_timeout_ms); going on",
                            if missing_decision {
                                "decision"
                            } else {
                                "640x480 disparity"
                            },
                            w.frame_id,
                            timeout.as_millis()
                        ),
                    );
                    wait = None;
                }
            }
        }
        // Lockstep: go on whenever nothing is awaited; at a rate: one frame per tick.
        if !lockstep && !id.has_event_from(&tick) {
            return Ok(LoopControl::Continue);
        }
        loop {
            let Some(event) = reader.next_event()? else {
                tracing::info!(
                    "replay finished in {:.1} s: {} 320x240 and {} 640x480 pairs, {} \
                     actuator outputs, {} lockstep timeouts",
                    started.elapsed().as_secs_f64(),
                    counts.lo,
                    counts.hi,
                    counts.sent,
                    counts.timeouts
                );
                rt.set_note("replay finished");
                return Ok(LoopControl::Stop);
            };
            match event {
                ReplayEvent::Sent(mut r) => {
                    r.sent_ns = rebase(r.sent_ns);
                    r.decision_capture_ns = rebase(r.decision_capture_ns);
                    r.decision_published_ns = rebase(r.decision_published_ns);
                    match sent.publish_copy(&r) {
                        Ok(_) => counts.sent += 1,
                        Err(e) => rt.report_publish_error(&e),
                    }
                }
                ReplayEvent::Frame(frame) => {
                    let received_ns = monotonic_ns();
                    rt.count_in(1);
                    let ReplayFrame {
                        step,
                        lo: lo_pair,
                        hi: hi_pair,
                    } = *frame;
                    // The long-range pair first: the fast path's fusion may name it.
                    if let Some(pair) = hi_pair {
                        publish_replayed(rt, &mut hi, &pair, rebase, received_ns, false);
                        counts.hi += 1;
                    }
                    if let Some(pair) = lo_pair {
                        publish_replayed(rt, &mut lo, &pair, rebase, received_ns, true);
                        counts.lo += 1;
                    }
                    if lockstep {
                        wait = Some(ReplayWait {
                            frame_id: step.frame_id,
                            decision: step.lo,
                            hi_disparity: step.wait_for_hi,
                            since_ns: monotonic_ns(),
                        });
                    }
                    return Ok(LoopControl::Continue);
                }
            }
        }
    })
}

/// Copies one recorded pair into a loaned sample and sends it (`counted`: the fast-path pair,
/// whose latency the stage reports).
fn publish_replayed<T>(
    rt: &mut StageRuntime,
    publisher: &mut TopicPublisher<T>,
    pair: &ReplayPair,
    rebase: impl Fn(u64) -> u64,
    received_ns: u64,
    counted: bool,
) where
    T: std::fmt::Debug
        + iceoryx2::prelude::ZeroCopySend
        + hvs_shared::messages::StereoPayload
        + 'static,
{
    let mut sample = match publisher.loan() {
        Ok(s) => s,
        Err(e) => {
            rt.report_publish_error(&e);
            return;
        }
    };
    if let Err(e) = write_replayed(pair, sample.payload_mut(), rebase, monotonic_ns) {
        rt.report_error("replay", &e);
        return;
    }
    if counted {
        rt.send_or_report(publisher, sample, monotonic_ns() - received_ns);
    } else if let Err(e) = publisher.send(sample) {
        rt.report_publish_error(&e);
    }
}
