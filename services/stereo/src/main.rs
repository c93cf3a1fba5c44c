//! Stereo stage process: `stereo-lo` (320x240 fast path) or `stereo-hi` (640x480 long range).
//!
//! Takes the newest frame pair from shared memory (older ones are dropped and counted: the
//! stage always works on the freshest scene), matches it, and writes the disparity map and its
//! confidence plane directly into a loaned output sample: the full map is never copied.

use std::process::ExitCode;

use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::StereoConfig;
use hvs_runtime::ipc::TopicSubscriber;
use hvs_runtime::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::messages::{
    DisparityHeader, DisparityMap320x240, DisparityMap640x480, RowAlignState, StereoPayload,
};
use hvs_shared::topics::{self, Stage, Topic};
use hvs_stereo::{ImageView, matcher_for};

fn main() -> ExitCode {
    run_stage(Stage::StereoLo, |rt| match rt.stage {
        Stage::StereoHi => run_path(
            rt,
            &topics::FRAMES_HI,
            &topics::DISPARITY_HI,
            |m: &mut DisparityMap640x480| {
                (
                    &mut m.header,
                    &mut m.disparity_q8[..],
                    &mut m.confidence[..],
                )
            },
        ),
        _ => run_path(
            rt,
            &topics::FRAMES_LO,
            &topics::DISPARITY_LO,
            |m: &mut DisparityMap320x240| {
                (
                    &mut m.header,
                    &mut m.disparity_q8[..],
                    &mut m.confidence[..],
                )
            },
        ),
    })
}

type MapParts<M> = fn(&mut M) -> (&mut DisparityHeader, &mut [u16], &mut [u8]);

/// The row alignment as the stage reports it: in every map's header, in the note, and as a
/// warning when the offset is beyond `row_align.warn_px` (again every 10 s while it is).
struct RowReport {
    state: RowAlignState,
    shift_px: Option<f32>,
    warned_at: Option<std::time::Instant>,
    note_shift_dpx: Option<i32>,
}

impl RowReport {
    fn new(config: &StereoConfig) -> Self {
        Self {
            state: if config.row_align.enabled {
                RowAlignState::Searching
            } else {
                RowAlignState::Off
            },
            shift_px: None,
            warned_at: None,
            note_shift_dpx: None,
        }
    }

    fn update(&mut self, status: Option<hvs_stereo::rowalign::AlignStatus>) {
        let Some(s) = status else {
            return;
        };
        self.shift_px = s.shift_px;
        self.state = match (s.shift_px, s.applied_px != 0.0) {
            (None, _) => RowAlignState::Searching,
            (Some(_), false) => RowAlignState::Aligned,
            (Some(_), true) => RowAlignState::Corrected,
        };
    }

    fn report(&mut self, rt: &mut StageRuntime, config: &StereoConfig) {
        let Some(shift) = self.shift_px else {
            return;
        };
        // The note shows the offset to 0.1 px; it changes only when that does.
        let dpx = (shift * 10.0).round() as i32;
        if self.note_shift_dpx != Some(dpx) {
            self.note_shift_dpx = Some(dpx);
            rt.set_note(format!(
                "{} {}..{} rows {:+.1} px",
                config.algorithm.label(),
                config.min_disp,
                config.max_disp,
                shift
            ));
        }
        let warn_px = config.row_align.warn_px;
        if shift.abs() > warn_px
            && self
                .warned_at
                .is_none_or(|t| t.elapsed() >= std::time::Duration::from_secs(10))
        {
            self.warned_at = Some(std::time::Instant::now());
            tracing::warn!(
                shift_px = shift,
                "the right image is {shift:+.1} rows off the left (row_align.warn_px = \
                 {warn_px}): the camera was knocked or its calibration no longer fits; \
                 corrected before matching"
            );
        }
    }
}

fn run_path<F, M>(
    rt: &mut StageRuntime,
    frames_topic: &Topic<F>,
    maps_topic: &Topic<M>,
    map_parts: MapParts<M>,
) -> Result<(), StageError>
where
    F: core::fmt::Debug
        + iceoryx2::prelude::ZeroCopySend
        + hvs_shared::messages::Sequenced
        + StereoPayload
        + 'static,
    M: core::fmt::Debug + iceoryx2::prelude::ZeroCopySend + bytemuck::Pod + 'static,
{
    let config = rt
        .config
        .stereo_for(rt.stage)
        .ok_or_else(|| format!("stage {} is not stereo-lo or stereo-hi", rt.stage))?
        .clone();
    let mut matcher = matcher_for(&config)?;
    // Buffer 1: a slow matcher always gets the newest pair; the skipped ones count as drops.
    let frames: TopicSubscriber<F> = rt.node.subscriber(frames_topic, 1)?;
    let mut maps = rt.node.publisher(maps_topic)?;
    rt.set_note(format!(
        "{} {}..{}",
        config.algorithm.label(),
        config.min_disp,
        config.max_disp
    ));
    tracing::info!(
        "{} disparities {}..{} window {} on {}",
        config.algorithm.label(),
        config.min_disp,
        config.max_disp,
        config.window,
        frames.service()
    );

    let mut row = RowReport::new(&config);
    let waitset = rt.waitset()?;
    let frames_guard = frames.attach_to(&waitset)?;

    rt.run_loop(&waitset, |rt, id| {
        if !id.has_event_from(&frames_guard) {
            return Ok(LoopControl::Continue);
        }
        frames.clear_events();
        let Some(frame) = frames.receive_latest()? else {
            return Ok(LoopControl::Continue);
        };
        let received_ns = monotonic_ns();
        rt.count_in(1);
        rt.set_drops(frames.dropped());
        let (header, left, right) = frame.payload().parts();
        let (w, h) = (header.width as usize, header.height as usize);
        let pair = ImageView::new(left, w, h).and_then(|l| Ok((l, ImageView::new(right, w, h)?)));
        let (left, right) = match pair {
            Ok(p) => p,
            Err(e) => {
                rt.report_error(&format!("frame {} rejected", header.frame_id), &e);
                return Ok(LoopControl::Continue);
            }
        };
        let mut sample = match maps.loan() {
            Ok(s) => s,
            Err(e) => {
                rt.report_publish_error(&e);
                return Ok(LoopControl::Continue);
            }
        };
        let (out_header, out, confidence) = map_parts(sample.payload_mut());
        let started = monotonic_ns();
        let stats = match matcher.compute(left, right, out) {
            Ok(s) => s,
            Err(e) => {
                rt.report_error(&format!("frame {}", header.frame_id), &e);
                return Ok(LoopControl::Continue);
            }
        };
        hvs_stereo::confidence_or_validity(matcher.as_ref(), out, confidence);
        let done = monotonic_ns();
        row.update(stats.row_align);
        *out_header = DisparityHeader {
            frame_id: header.frame_id,
            capture_ns: header.capture_ns,
            frame_received_ns: received_ns,
            published_ns: done,
            compute_ns: done - started,
            width: w as u32,
            height: h as u32,
            min_disp: config.min_disp,
            max_disp: config.max_disp,
            algorithm: matcher.algorithm() as u32,
            valid_px: stats.valid_px,
            row_shift_mpx: row.shift_px.map_or(0, |s| (s * 1000.0).round() as i32),
            row_align: row.state as u32,
        };
        row.report(rt, &config);
        drop(frame);
        rt.send_or_report(&mut maps, sample, done - received_ns);
        Ok(LoopControl::Continue)
    })
}
