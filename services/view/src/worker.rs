//! The encoder thread: JPEG, colour maps, the fused map and the point cloud are made here,
//! off the thread that receives from iceoryx2. It takes its work from one-slot channels that
//! keep only the newest job ([`crate::latest`]), so a slow encoder skips frames rather than
//! delaying the receive loop or piling up old ones.

use std::sync::Arc;
use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender, select};
use hvs_fusion::{DepthModel, FusionPath};
use hvs_probe::render::ColourScale;
use hvs_probe::schemas::Pinhole;
use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::HvsConfig;
use hvs_shared::messages::{LO_HEIGHT, LO_PIXELS, LO_WIDTH, RangeSource};

use crate::channels::ViewChannels;
use crate::encode::{compressed_image, disparity_jpeg, fused_jpeg, jpeg, point_cloud};
use crate::latest::{LatestSender, latest};

/// A left image to send.
#[derive(Debug)]
pub struct ImageJob {
    /// Grey pixels, 320x240 (shared with the frames kept for pairing).
    pub left: Arc<[u8]>,
    /// Capture time, wall-clock ns.
    pub wall_ns: u64,
}

/// A disparity map with its left image, for the disparity, fused and point-cloud channels.
#[derive(Debug)]
pub struct DisparityJob {
    /// Grey pixels of the left image, 320x240.
    pub left: Arc<[u8]>,
    /// Disparity, 1/256 px, 320x240.
    pub disparity_q8: Vec<u16>,
    /// Confidence per pixel.
    pub confidence: Vec<u8>,
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px.
    pub max_disp: u32,
    /// Capture time, wall-clock ns.
    pub wall_ns: u64,
}

/// What one job produced: messages sent and the time it took.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Encoded {
    /// Messages sent to clients.
    pub messages: u64,
    /// Time spent encoding and sending, ns.
    pub busy_ns: u64,
    /// Encoding failures.
    pub errors: u64,
}

/// The handle of the encoder thread.
#[derive(Debug)]
pub struct Encoder {
    /// Left images.
    pub images: LatestSender<ImageJob>,
    /// Disparity maps.
    pub disparities: LatestSender<DisparityJob>,
    /// What the jobs produced (drained by the receive loop into the stage's counters).
    pub done: Receiver<Encoded>,
    stop: Option<Sender<()>>,
    thread: Option<JoinHandle<()>>,
}

/// The settings the encoder needs.
#[derive(Debug, Clone)]
pub struct EncoderSettings {
    /// JPEG quality.
    pub jpeg_quality: u8,
    /// Point cloud pixel step.
    pub point_stride: usize,
    /// Farthest point, m.
    pub max_point_range_m: f64,
    /// The left camera at 320x240.
    pub pinhole: Pinhole,
    /// The config (the fused map uses fusion's own settings).
    pub config: HvsConfig,
}

impl EncoderSettings {
    /// The settings of a config.
    pub fn of(config: &HvsConfig) -> Self {
        Self {
            jpeg_quality: config.view.jpeg_quality,
            point_stride: config.view.point_stride as usize,
            max_point_range_m: config.view.max_point_range_m,
            pinhole: Pinhole::of(&config.camera, LO_WIDTH as u32, LO_HEIGHT as u32),
            config: config.clone(),
        }
    }

    /// The colour scale of a disparity range.
    pub fn scale(&self, min_disp: u32, max_disp: u32) -> ColourScale {
        ColourScale::new(
            min_disp,
            max_disp,
            DepthModel {
                focal_px: self.pinhole.focal_px,
                baseline_m: self.pinhole.baseline_m,
            },
        )
    }
}

impl Encoder {
    /// Starts the thread.
    pub fn start(channels: Arc<ViewChannels>, settings: EncoderSettings) -> std::io::Result<Self> {
        let (images, image_rx) = latest::<ImageJob>();
        let (disparities, disparity_rx) = latest::<DisparityJob>();
        let (done_tx, done) = crossbeam_channel::bounded(64);
        let (stop, stop_rx) = crossbeam_channel::bounded::<()>(0);
        let thread = std::thread::Builder::new()
            .name("view-encoder".into())
            .spawn(move || {
                let mut fused =
                    FusionPath::new(&settings.config, LO_WIDTH, LO_HEIGHT, RangeSource::Lo);
                loop {
                    let out = select! {
                        recv(image_rx) -> job => match job {
                            Ok(job) => encode_image(&channels, &settings, job),
                            Err(_) => return,
                        },
                        recv(disparity_rx) -> job => match job {
                            Ok(job) => encode_disparity(&channels, &settings, &mut fused, job),
                            Err(_) => return,
                        },
                        recv(stop_rx) -> _ => return,
                    };
                    // Dropped when the receive loop is behind: the counts are only statistics.
                    let _ = done_tx.try_send(out);
                }
            })?;
        Ok(Self {
            images,
            disparities,
            done,
            stop: Some(stop),
            thread: Some(thread),
        })
    }

    /// Whether the thread has ended (it only ends on a panic while the stage runs).
    pub fn has_ended(&self) -> bool {
        self.thread.as_ref().is_none_or(JoinHandle::is_finished)
    }
}

impl Drop for Encoder {
    fn drop(&mut self) {
        drop(self.stop.take());
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

fn encode_image(ch: &ViewChannels, s: &EncoderSettings, job: ImageJob) -> Encoded {
    let t0 = monotonic_ns();
    let mut out = Encoded::default();
    if ch.left.has_sinks() {
        match jpeg(
            &job.left,
            LO_WIDTH as u32,
            LO_HEIGHT as u32,
            1,
            s.jpeg_quality,
        ) {
            Ok(bytes) => {
                ch.left
                    .log_with_time(&compressed_image(bytes, job.wall_ns), job.wall_ns);
                out.messages += 1;
            }
            Err(e) => {
                tracing::warn!("left image: {e}");
                out.errors += 1;
            }
        }
    }
    out.busy_ns = monotonic_ns() - t0;
    out
}

fn encode_disparity(
    ch: &ViewChannels,
    s: &EncoderSettings,
    fusion: &mut FusionPath,
    job: DisparityJob,
) -> Encoded {
    let t0 = monotonic_ns();
    let mut out = Encoded::default();
    if job.left.len() != LO_PIXELS || job.disparity_q8.len() != LO_PIXELS {
        out.errors += 1;
        return out;
    }
    let scale = s.scale(job.min_disp, job.max_disp);
    let (w, h) = (LO_WIDTH as u32, LO_HEIGHT as u32);
    let mut send = |result: Result<Vec<u8>, crate::encode::EncodeError>,
                    channel: &foxglove::Channel<foxglove::messages::CompressedImage>,
                    what: &str| match result {
        Ok(bytes) => {
            channel.log_with_time(&compressed_image(bytes, job.wall_ns), job.wall_ns);
            out.messages += 1;
        }
        Err(e) => {
            tracing::warn!("{what}: {e}");
            out.errors += 1;
        }
    };
    if ch.disparity.has_sinks() {
        send(
            disparity_jpeg(&job.disparity_q8, w, h, &scale, s.jpeg_quality),
            &ch.disparity,
            "disparity image",
        );
    }
    if ch.fused.has_sinks() {
        let conf = (job.confidence.len() == LO_PIXELS).then_some(job.confidence.as_slice());
        let _ = fusion.ranges(&job.left, &job.disparity_q8, conf);
        send(
            fused_jpeg(&job.left, fusion.fused(), w, h, &scale, s.jpeg_quality),
            &ch.fused,
            "fused map",
        );
    }
    if ch.points.has_sinks() {
        let pc = point_cloud(
            &job.disparity_q8,
            &job.left,
            &s.pinhole,
            s.point_stride,
            s.max_point_range_m,
            job.wall_ns,
        );
        ch.points.log_with_time(&pc, job.wall_ns);
        out.messages += 1;
    }
    out.busy_ns = monotonic_ns() - t0;
    out
}
