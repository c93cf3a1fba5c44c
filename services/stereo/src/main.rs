//! Stereo stage process: `stereo-lo` (320x240 fast path) or `stereo-hi` (640x480 long range).
//!
//! Takes the newest frame pair from shared memory (older ones are dropped and counted: the
//! stage always works on the freshest scene), matches it, and writes the disparity map directly
//! into a loaned output sample: the full map is never copied.

use std::process::ExitCode;

use hvs_shared::clock::monotonic_ns;
use hvs_shared::ipc::TopicSubscriber;
use hvs_shared::messages::{
    DisparityHeader, DisparityMap320x240, DisparityMap640x480, StereoPayload,
};
use hvs_shared::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::topics::{self, Topic};
use hvs_stereo::{ImageView, matcher_for};

fn main() -> ExitCode {
    run_stage("stereo-lo", |rt| match rt.stage.as_str() {
        "stereo-hi" => run_path(
            rt,
            &topics::FRAMES_HI,
            &topics::DISPARITY_HI,
            |m: &mut DisparityMap640x480| (&mut m.header, &mut m.disparity_q8[..]),
        ),
        _ => run_path(
            rt,
            &topics::FRAMES_LO,
            &topics::DISPARITY_LO,
            |m: &mut DisparityMap320x240| (&mut m.header, &mut m.disparity_q8[..]),
        ),
    })
}

type MapParts<M> = fn(&mut M) -> (&mut DisparityHeader, &mut [u16]);

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
        .stereo_for(&rt.stage)
        .ok_or_else(|| format!("stage {:?} is not stereo-lo or stereo-hi", rt.stage))?
        .clone();
    let mut matcher = matcher_for(&config)?;
    // Buffer 1: a slow matcher always gets the newest pair; the skipped ones count as drops.
    let frames: TopicSubscriber<F> = rt.node.subscriber(frames_topic, 1)?;
    let mut maps = rt.node.publisher(maps_topic)?;
    rt.set_note(format!(
        "{} {}..{}",
        config.algorithm.name(),
        config.min_disp,
        config.max_disp
    ));
    tracing::info!(
        "{}: {} disparities {}..{} window {} on {}",
        rt.stage,
        config.algorithm.name(),
        config.min_disp,
        config.max_disp,
        config.window,
        frames.service()
    );

    let waitset = rt.waitset()?;
    let frames_guard = waitset
        .attach_notification(frames.listener())
        .map_err(|e| format!("cannot attach listener: {e:?}"))?;

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
        let (out_header, out) = map_parts(sample.payload_mut());
        let started = monotonic_ns();
        let stats = match matcher.compute(left, right, out) {
            Ok(s) => s,
            Err(e) => {
                rt.report_error(&format!("frame {}", header.frame_id), &e);
                return Ok(LoopControl::Continue);
            }
        };
        let done = monotonic_ns();
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
        };
        drop(frame);
        rt.send_or_report(&mut maps, sample, done - received_ns);
        Ok(LoopControl::Continue)
    })
}
