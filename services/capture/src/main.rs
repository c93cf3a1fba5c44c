//! Capture stage process: publishes every stereo pair twice, at 640x480 and at 320x240.
//!
//! Source `sim`: the simulator's rendered camera (`sim/camera/640x480`), which stands in for
//! the two Minoru webcams. The 640x480 pair is copied once from the camera buffer into a loaned
//! shared-memory sample (as a V4L2 buffer would be), and the 320x240 pair is downscaled from it
//! directly into its own loaned sample.

use std::process::ExitCode;

use hvs_capture::downscale_2x;
use hvs_shared::clock::monotonic_ns;
use hvs_shared::config::CaptureSource;
use hvs_shared::messages::{FrameHeader, HI_HEIGHT, HI_WIDTH, LO_HEIGHT, LO_WIDTH};
use hvs_shared::stage::{LoopControl, StageError, StageRuntime, run_stage};
use hvs_shared::topics;

fn main() -> ExitCode {
    run_stage("capture", |rt| match rt.config.capture.source {
        CaptureSource::Sim => run_sim_source(rt),
    })
}

fn run_sim_source(rt: &mut StageRuntime) -> Result<(), StageError> {
    let camera = rt.node.subscriber(&topics::SIM_CAMERA, 2)?;
    let mut hi = rt.node.publisher(&topics::FRAMES_HI)?;
    let mut lo = rt.node.publisher(&topics::FRAMES_LO)?;
    rt.set_note("source sim");
    tracing::info!("{}: source sim ({})", rt.stage, camera.service());

    let waitset = rt.waitset()?;
    let camera_guard = waitset
        .attach_notification(camera.listener())
        .map_err(|e| format!("cannot attach listener: {e:?}"))?;

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
            let header = |width: usize, height: usize| FrameHeader {
                width: width as u32,
                height: height as u32,
                published_ns: monotonic_ns(),
                ..src.header
            };
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
            {
                let out = hi_sample.payload_mut();
                out.left.copy_from_slice(&src.left);
                out.right.copy_from_slice(&src.right);
                out.header = header(HI_WIDTH, HI_HEIGHT);
            }
            {
                let out = lo_sample.payload_mut();
                downscale_2x(&src.left, HI_WIDTH, HI_HEIGHT, &mut out.left)?;
                downscale_2x(&src.right, HI_WIDTH, HI_HEIGHT, &mut out.right)?;
                out.header = header(LO_WIDTH, LO_HEIGHT);
            }
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
