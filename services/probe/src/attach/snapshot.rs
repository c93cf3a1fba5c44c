//! `hvs probe snapshot TOPIC --out F.png`: one sample of an image topic as a PNG: a stereo
//! pair, a colour-mapped disparity map, or (`--fused`) the fused map over its left image.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hvs_fusion::{DepthModel, FusionPath};
use hvs_runtime::config::HvsConfig;
use hvs_runtime::ipc::{ReceiveError, ReceivedSample, TopicSubscriber};
use hvs_shared::messages::{
    DisparityHeader, DisparityMap320x240, DisparityMap640x480, RangeSource, StereoFrame320x240,
    StereoFrame640x480,
};
use hvs_shared::topics::{self, Topic, TopicByPath};

use super::{AttachError, Payload, Probe, resolve_topic};
use crate::render::{ColourScale, disparity_image, fused_image, stereo_pair_image};

/// Options of `hvs probe snapshot`.
#[derive(Debug, Clone)]
pub struct SnapshotOptions {
    /// PNG file to write.
    pub out: PathBuf,
    /// Render the fused map (disparity at edge pixels) over the left image.
    pub fused: bool,
    /// Give up when no suitable sample arrives within this time.
    pub timeout: Duration,
}

/// What `hvs probe snapshot` wrote.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SnapshotInfo {
    /// Frame id of the sample shown.
    pub frame_id: u64,
    /// PNG width, px.
    pub width_px: u32,
    /// PNG height, px.
    pub height_px: u32,
}

/// Why `hvs probe snapshot` failed.
#[derive(Debug, thiserror::Error)]
pub enum SnapshotError {
    /// Attaching failed.
    #[error(transparent)]
    Attach(#[from] AttachError),
    /// The topic carries no image.
    #[error(
        "topic {topic} carries no image; snapshot takes frames/320x240, frames/640x480, sim/camera/640x480, disparity/320x240, disparity/640x480 or sim/gt_disparity/640x480"
    )]
    NotAnImage {
        /// The topic path.
        topic: String,
    },
    /// `--fused` was given with a topic that is not a disparity map.
    #[error(
        "--fused needs a disparity topic (disparity/320x240, disparity/640x480, sim/gt_disparity/640x480), not {topic}"
    )]
    FusedNeedsDisparity {
        /// The topic path.
        topic: String,
    },
    /// No suitable sample arrived in time.
    #[error("no sample of topic {topic} of instance {instance:?} arrived within {timeout_s:.1} s")]
    Timeout {
        /// The instance.
        instance: String,
        /// The topic path (both topics for `--fused`).
        topic: String,
        /// The time waited, s.
        timeout_s: f64,
    },
    /// Receiving failed.
    #[error("snapshot of topic {topic}")]
    Receive {
        /// The topic path.
        topic: String,
        /// The receive error.
        #[source]
        source: ReceiveError,
    },
    /// The PNG could not be written.
    #[error("cannot write snapshot {}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The image error.
        #[source]
        source: image::ImageError,
    },
}

/// Frame-pair payloads.
trait PairPayload: Payload {
    const SIZE: (u32, u32);
    fn frame_id(&self) -> u64;
    fn left(&self) -> &[u8];
    fn right(&self) -> &[u8];
}

macro_rules! pair_payload {
    ($t:ty) => {
        impl PairPayload for $t {
            const SIZE: (u32, u32) = (<$t>::WIDTH as u32, <$t>::HEIGHT as u32);
            fn frame_id(&self) -> u64 {
                self.header.frame_id
            }
            fn left(&self) -> &[u8] {
                &self.left
            }
            fn right(&self) -> &[u8] {
                &self.right
            }
        }
    };
}
pair_payload!(StereoFrame320x240);
pair_payload!(StereoFrame640x480);

/// Disparity-map payloads.
trait DisparityPayload: Payload {
    const SIZE: (u32, u32);
    fn header(&self) -> &DisparityHeader;
    fn disparity_q8(&self) -> &[u16];
}

macro_rules! disparity_payload {
    ($t:ty) => {
        impl DisparityPayload for $t {
            const SIZE: (u32, u32) = (<$t>::WIDTH as u32, <$t>::HEIGHT as u32);
            fn header(&self) -> &DisparityHeader {
                &self.header
            }
            fn disparity_q8(&self) -> &[u16] {
                &self.disparity_q8
            }
        }
    };
}
disparity_payload!(DisparityMap320x240);
disparity_payload!(DisparityMap640x480);

/// `hvs probe snapshot TOPIC --out F.png`: writes one sample of an image topic as a PNG.
pub fn snapshot(
    probe: &Probe,
    path: &str,
    config: &HvsConfig,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let not_image = || SnapshotError::NotAnImage {
        topic: path.to_string(),
    };
    match resolve_topic(path)? {
        TopicByPath::StereoFrame320x240(t) if !opts.fused => snapshot_pair(probe, t, path, opts),
        TopicByPath::StereoFrame640x480(t) if !opts.fused => snapshot_pair(probe, t, path, opts),
        TopicByPath::StereoFrame320x240(_) | TopicByPath::StereoFrame640x480(_) => {
            Err(SnapshotError::FusedNeedsDisparity {
                topic: path.to_string(),
            })
        }
        TopicByPath::DisparityMap320x240(t) if !opts.fused => {
            snapshot_disparity(probe, t, path, config, opts)
        }
        TopicByPath::DisparityMap640x480(t) if !opts.fused => {
            snapshot_disparity(probe, t, path, config, opts)
        }
        TopicByPath::DisparityMap320x240(t) => {
            snapshot_fused(probe, t, path, &topics::FRAMES_LO, config, opts)
        }
        TopicByPath::DisparityMap640x480(t) => {
            // The simulator's exact disparity belongs to its own camera frames.
            let frames = if path == topics::SIM_GT_DISPARITY.path {
                &topics::SIM_CAMERA
            } else {
                &topics::FRAMES_HI
            };
            snapshot_fused(probe, t, path, frames, config, opts)
        }
        _ if opts.fused => Err(SnapshotError::FusedNeedsDisparity {
            topic: path.to_string(),
        }),
        _ => Err(not_image()),
    }
}

/// Waits for the newest sample of `sub` until `deadline`.
fn newest_sample<T: Payload>(
    probe: &Probe,
    sub: &TopicSubscriber<T>,
    path: &str,
    deadline: Instant,
) -> Result<Option<ReceivedSample<T>>, SnapshotError> {
    loop {
        if let Some(s) = sub
            .receive_latest()
            .map_err(|source| SnapshotError::Receive {
                topic: path.to_string(),
                source,
            })?
        {
            return Ok(Some(s));
        }
        let now = Instant::now();
        if now >= deadline || probe.termination_requested() {
            return Ok(None);
        }
        // A failed wait is retried until the deadline (receive above reports real errors).
        let _ = probe.wait(sub, (deadline - now).min(Duration::from_millis(100)));
    }
}

fn timeout_error(probe: &Probe, topic: &str, opts: &SnapshotOptions) -> SnapshotError {
    SnapshotError::Timeout {
        instance: probe.instance().to_string(),
        topic: topic.to_string(),
        timeout_s: opts.timeout.as_secs_f64(),
    }
}

fn save_png<P, C>(img: &image::ImageBuffer<P, C>, out: &Path) -> Result<(), SnapshotError>
where
    P: image::Pixel + image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: core::ops::Deref<Target = [P::Subpixel]>,
{
    img.save_with_format(out, image::ImageFormat::Png)
        .map_err(|source| SnapshotError::Write {
            path: out.to_path_buf(),
            source,
        })
}

fn snapshot_pair<T: PairPayload>(
    probe: &Probe,
    topic: &'static Topic<T>,
    path: &str,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let sub = probe.subscribe(topic, None, path, 1)?;
    let sample = newest_sample(probe, &sub, path, Instant::now() + opts.timeout)?
        .ok_or_else(|| timeout_error(probe, path, opts))?;
    let p = sample.payload();
    let (w, h) = T::SIZE;
    let img = stereo_pair_image(p.left(), p.right(), w, h);
    let frame_id = p.frame_id();
    drop(sample);
    save_png(&img, &opts.out)?;
    Ok(SnapshotInfo {
        frame_id,
        width_px: img.width(),
        height_px: img.height(),
    })
}

fn colour_scale(h: &DisparityHeader, width: u32, config: &HvsConfig) -> ColourScale {
    ColourScale::new(
        h.min_disp,
        h.max_disp,
        DepthModel {
            focal_px: config.camera.focal_px(width as usize),
            baseline_m: config.camera.baseline_m,
        },
    )
}

fn snapshot_disparity<T: DisparityPayload>(
    probe: &Probe,
    topic: &'static Topic<T>,
    path: &str,
    config: &HvsConfig,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let sub = probe.subscribe(topic, None, path, 1)?;
    let sample = newest_sample(probe, &sub, path, Instant::now() + opts.timeout)?
        .ok_or_else(|| timeout_error(probe, path, opts))?;
    let p = sample.payload();
    let (w, h) = T::SIZE;
    let img = disparity_image(p.disparity_q8(), w, h, &colour_scale(p.header(), w, config));
    let frame_id = p.header().frame_id;
    drop(sample);
    save_png(&img, &opts.out)?;
    Ok(SnapshotInfo {
        frame_id,
        width_px: img.width(),
        height_px: img.height(),
    })
}

/// Left images kept at first while waiting for the disparity map of the same frame.
const KEPT_LEFT_IMAGES: usize = 8;
/// At most this many: a map older than every kept image doubles the count (on a loaded
/// machine the 640x480 maps trail the frames by more than 8 frames).
const MAX_KEPT_LEFT_IMAGES: usize = 256;

fn snapshot_fused<D: DisparityPayload, F: PairPayload>(
    probe: &Probe,
    disparity: &'static Topic<D>,
    path: &str,
    frames: &'static Topic<F>,
    config: &HvsConfig,
    opts: &SnapshotOptions,
) -> Result<SnapshotInfo, SnapshotError> {
    let receive_error = |topic: &str| {
        let topic = topic.to_string();
        move |source| SnapshotError::Receive { topic, source }
    };
    let frame_sub = probe.subscribe(frames, None, frames.path, frames.max_buffer)?;
    let disp_sub = probe.subscribe(disparity, None, path, disparity.max_buffer)?;
    let (w, h) = D::SIZE;
    let deadline = Instant::now() + opts.timeout;
    // Copies of recent left images (the frames themselves are released at once).
    let mut lefts: VecDeque<(u64, Vec<u8>)> = VecDeque::new();
    let mut kept = KEPT_LEFT_IMAGES;
    while Instant::now() < deadline {
        while let Some(f) = frame_sub.receive().map_err(receive_error(frames.path))? {
            while lefts.len() >= kept {
                lefts.pop_front();
            }
            lefts.push_back((f.payload().frame_id(), f.payload().left().to_vec()));
        }
        while let Some(d) = disp_sub.receive().map_err(receive_error(path))? {
            let d = d.payload();
            let id = d.header().frame_id;
            let Some((_, left)) = lefts.iter().find(|(fid, _)| *fid == id) else {
                if lefts.front().is_some_and(|(oldest, _)| id < *oldest) {
                    // The map trails the frames by more than the kept images: keep more.
                    kept = (kept * 2).min(MAX_KEPT_LEFT_IMAGES);
                }
                continue;
            };
            if F::SIZE != D::SIZE {
                continue;
            }
            // Fusion's own path (its edge detector and thresholds from the config), so that
            // the snapshot shows what the fusion stage computes.
            let source = if w >= 640 {
                RangeSource::Hi
            } else {
                RangeSource::Lo
            };
            let mut path = FusionPath::new(config, w as usize, h as usize, source);
            path.ranges(left, d.disparity_q8(), None);
            let fused_q8 = path.fused();
            let img = fused_image(left, fused_q8, w, h, &colour_scale(d.header(), w, config));
            save_png(&img, &opts.out)?;
            return Ok(SnapshotInfo {
                frame_id: id,
                width_px: img.width(),
                height_px: img.height(),
            });
        }
        if !probe.node.sleep(Duration::from_millis(5)) {
            break;
        }
    }
    Err(timeout_error(
        probe,
        &format!("{path} with its frame on {}", frames.path),
        opts,
    ))
}
