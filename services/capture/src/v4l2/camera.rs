//! One camera (format, rate, buffers, streaming) and the Minoru's two cameras paired by
//! kernel timestamp, opened with the mode negotiation of [`super::negotiate`].

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::{V4l2Controls, V4l2PixelFormat};
use nix::errno::Errno;

use super::controls::{ControlReport, apply_controls};
use super::device::{DeviceCaps, DeviceOpener, FrameRates, V4l2Device};
use super::negotiate::{CameraOffer, FormatOffer, candidate_modes};
use super::{CameraMode, CaptureError, OpenError, fourcc_name, fourcc_of};
use crate::convert::{MjpegToGrey, yuyv_to_grey};
use crate::pairing::{Pair, Pairer, Side, Stamped};

/// One dequeued kernel buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameBuffer {
    /// Buffer index.
    pub index: u32,
    /// Bytes the driver filled.
    pub bytes_used: u32,
    /// The driver's frame counter.
    pub sequence: u32,
}

/// Maps an errno of step `op` on `device` to an [`OpenError`] that says what to do.
pub(crate) fn io_error(device: &Path, op: &'static str, errno: Errno) -> OpenError {
    match errno {
        Errno::ENOENT => OpenError::Missing {
            device: device.to_path_buf(),
        },
        Errno::EACCES | Errno::EPERM => OpenError::Permission {
            device: device.to_path_buf(),
        },
        Errno::EBUSY => OpenError::Busy {
            device: device.to_path_buf(),
            detail: format!("{op}: device in use by another process"),
        },
        Errno::ENOSPC => OpenError::Busy {
            device: device.to_path_buf(),
            detail: format!(
                "{op}: not enough USB bandwidth (both cameras on one bus: try mjpeg, a lower \
                 rate or 320x240)"
            ),
        },
        Errno::ENODEV | Errno::ENXIO => OpenError::Missing {
            device: device.to_path_buf(),
        },
        errno => OpenError::Io {
            device: device.to_path_buf(),
            op,
            errno,
        },
    }
}

/// Opens `path` and checks that it is a streaming capture node (what the capture and `hvs
/// doctor` both do first).
pub fn open_capture_node(
    opener: &dyn DeviceOpener,
    path: &Path,
) -> Result<(Box<dyn V4l2Device>, DeviceCaps), OpenError> {
    let mut dev = opener.open(path).map_err(|e| io_error(path, "open", e))?;
    let caps = dev.query_caps().map_err(|errno| OpenError::NotV4l2 {
        device: path.to_path_buf(),
        errno,
    })?;
    if !caps.is_streaming_capture() {
        return Err(OpenError::NotCapture {
            device: path.to_path_buf(),
            card: caps.card.clone(),
            caps: caps.caps,
        });
    }
    Ok((dev, caps))
}

/// Everything a device offers (`VIDIOC_ENUM_FMT`, `_FRAMESIZES`, `_FRAMEINTERVALS`).
pub fn enumerate(dev: &mut dyn V4l2Device, path: &Path) -> Result<CameraOffer, OpenError> {
    let formats = dev
        .formats()
        .map_err(|e| io_error(path, "VIDIOC_ENUM_FMT", e))?;
    let mut offer = CameraOffer::default();
    for fourcc in formats {
        let sizes = match dev.frame_sizes(fourcc) {
            Ok(s) => s,
            Err(Errno::EINVAL | Errno::ENOTTY) => Vec::new(),
            Err(e) => return Err(io_error(path, "VIDIOC_ENUM_FRAMESIZES", e)),
        };
        let mut with_rates = Vec::new();
        for size in sizes {
            let (w, h) = match size {
                super::device::FrameSizes::Discrete { width, height } => (width, height),
                super::device::FrameSizes::Stepwise { width, height } => (width.1, height.1),
            };
            let rates: Option<FrameRates> = match dev.frame_rates(fourcc, w, h) {
                Ok(r) => Some(r),
                Err(Errno::EINVAL | Errno::ENOTTY) => None,
                Err(e) => return Err(io_error(path, "VIDIOC_ENUM_FRAMEINTERVALS", e)),
            };
            // A stepwise size's rates are those of its largest size: good enough to order.
            with_rates.push((size, rates));
        }
        offer.formats.push(FormatOffer {
            fourcc,
            sizes: with_rates,
        });
    }
    Ok(offer)
}

/// One open, streaming V4L2 camera.
pub struct Camera {
    device: PathBuf,
    dev: Box<dyn V4l2Device>,
    buffer_count: u32,
    width: usize,
    height: usize,
    stride_bytes: usize,
    format: V4l2PixelFormat,
    fps: Option<f64>,
    streaming: bool,
}

impl Camera {
    /// Opens the real device `device`, sets `mode`, maps the buffers and starts streaming.
    pub fn open(device: &Path, mode: &CameraMode) -> Result<Self, OpenError> {
        let mut cam = Self::configure(&super::KernelOpener, device, mode)?;
        cam.start()?;
        Ok(cam)
    }

    /// Opens `device` through `opener` and sets `mode` (format, rate, buffers queued); not
    /// streaming yet.
    pub fn configure(
        opener: &dyn DeviceOpener,
        device: &Path,
        mode: &CameraMode,
    ) -> Result<Self, OpenError> {
        let (dev, _caps) = open_capture_node(opener, device)?;
        Self::configure_open(dev, device, mode)
    }

    fn configure_open(
        mut dev: Box<dyn V4l2Device>,
        device: &Path,
        mode: &CameraMode,
    ) -> Result<Self, OpenError> {
        let fourcc = fourcc_of(mode.format);
        let (w, h, got, bytes_per_line) = dev
            .set_format(fourcc, mode.width, mode.height)
            .map_err(|e| io_error(device, "VIDIOC_S_FMT", e))?;
        if w != mode.width || h != mode.height || got != fourcc {
            return Err(OpenError::ModeNotOffered {
                device: device.to_path_buf(),
                requested: format!("{}x{} {}", mode.width, mode.height, fourcc_name(fourcc)),
                offered: format!("{w}x{h} {}", fourcc_name(got)),
            });
        }
        let stride_bytes = if mode.format == V4l2PixelFormat::Yuyv {
            (bytes_per_line as usize).max(2 * mode.width as usize)
        } else {
            0
        };
        // The rate is set on each device: the Minoru's cameras do not share it.
        let fps = dev
            .set_frame_rate(mode.fps)
            .map_err(|e| io_error(device, "VIDIOC_S_PARM", e))?;
        let granted = dev
            .map_buffers(mode.buffers)
            .map_err(|e| io_error(device, "VIDIOC_REQBUFS", e))?;
        if granted < 2 {
            return Err(OpenError::Busy {
                device: device.to_path_buf(),
                detail: format!("the driver granted {granted} buffers, at least 2 needed"),
            });
        }
        for index in 0..granted {
            dev.queue(index)
                .map_err(|e| io_error(device, "VIDIOC_QBUF", e))?;
        }
        Ok(Self {
            device: device.to_path_buf(),
            dev,
            buffer_count: granted,
            width: mode.width as usize,
            height: mode.height as usize,
            stride_bytes,
            format: mode.format,
            fps,
            streaming: false,
        })
    }

    /// `VIDIOC_STREAMON`; `ENOSPC` (no USB bandwidth) comes back as `OpenError::Busy`.
    pub fn start(&mut self) -> Result<(), OpenError> {
        self.dev
            .stream_on()
            .map_err(|e| io_error(&self.device, "VIDIOC_STREAMON", e))?;
        self.streaming = true;
        Ok(())
    }

    /// The device path.
    pub fn device(&self) -> &Path {
        &self.device
    }

    /// The frame rate the driver accepted, Hz (`None` if it cannot set one).
    pub fn fps(&self) -> Option<f64> {
        self.fps
    }

    /// Buffers the driver granted.
    pub fn buffer_count(&self) -> u32 {
        self.buffer_count
    }

    /// Sets the configured image controls (see [`apply_controls`]).
    pub fn apply_controls(&mut self, controls: &V4l2Controls) -> ControlReport {
        apply_controls(self.dev.as_mut(), controls)
    }

    /// Gives a buffer back to the driver.
    pub fn requeue(&mut self, index: u32) -> Result<(), CaptureError> {
        self.dev
            .queue(index)
            .map_err(|errno| self.capture_error("VIDIOC_QBUF", errno))
    }

    fn capture_error(&self, op: &'static str, errno: Errno) -> CaptureError {
        if matches!(errno, Errno::ENODEV | Errno::ENXIO) {
            CaptureError::Disconnected {
                device: self.device.clone(),
                detail: format!("{op}: {errno}"),
            }
        } else {
            CaptureError::Io {
                device: self.device.clone(),
                op,
                errno,
            }
        }
    }

    /// Takes a filled buffer if one is ready (never blocks): the buffer and its kernel
    /// timestamp (CLOCK_MONOTONIC ns; the dequeue time if the driver has no monotonic stamp).
    pub fn dequeue(&mut self) -> Result<Option<Stamped<FrameBuffer>>, CaptureError> {
        let Some(d) = self
            .dev
            .dequeue()
            .map_err(|e| self.capture_error("VIDIOC_DQBUF", e))?
        else {
            return Ok(None);
        };
        Ok(Some(Stamped {
            stamp_ns: d.stamp_ns.unwrap_or_else(monotonic_ns),
            token: FrameBuffer {
                index: d.index,
                bytes_used: d.bytes_used,
                sequence: d.sequence,
            },
        }))
    }

    /// The bytes of a dequeued buffer.
    pub fn data(&self, frame: &FrameBuffer) -> &[u8] {
        self.dev.buffer(frame.index, frame.bytes_used as usize)
    }

    /// Converts a dequeued buffer to grey into `dst` (`width x height`).
    pub fn to_grey(
        &self,
        frame: &FrameBuffer,
        mjpeg: &mut MjpegToGrey,
        dst: &mut [u8],
    ) -> Result<(), CaptureError> {
        let data = self.data(frame);
        let result = match self.format {
            V4l2PixelFormat::Yuyv => {
                yuyv_to_grey(data, self.width, self.height, self.stride_bytes, dst)
            }
            V4l2PixelFormat::Mjpeg => mjpeg.convert(data, self.width, self.height, dst),
        };
        result.map_err(|source| CaptureError::Convert {
            device: self.device.clone(),
            sequence: frame.sequence,
            source,
        })
    }
}

impl Drop for Camera {
    fn drop(&mut self) {
        if self.streaming {
            // Failure (device gone) is harmless here.
            let _ = self.dev.stream_off();
        }
    }
}

/// Settings of a [`StereoCamera`].
#[derive(Debug, Clone, PartialEq)]
pub struct StereoSpec {
    /// Left device.
    pub left_device: PathBuf,
    /// Right device.
    pub right_device: PathBuf,
    /// Preferred mode of both cameras (the negotiation may fall back from it).
    pub mode: CameraMode,
    /// Largest left/right timestamp difference of a pair, ns.
    pub max_skew_ns: u64,
    /// A camera silent this long is reported as stalled.
    pub stall_timeout: Duration,
    /// Image controls set on both cameras.
    pub controls: V4l2Controls,
}

/// A matched pair of dequeued buffers; give it back with [`StereoCamera::read_pair`] or
/// [`StereoCamera::release_pair`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CapturedPair {
    /// The two buffers with their kernel timestamps.
    pub pair: Pair<FrameBuffer>,
    /// When the pair was completed, CLOCK_MONOTONIC ns.
    pub completed_ns: u64,
}

/// What the negotiation chose and why.
#[derive(Debug, Clone, PartialEq)]
pub struct Negotiated {
    /// The mode both cameras stream in.
    pub mode: CameraMode,
    /// Modes tried before it, each with the reason it failed.
    pub skipped: Vec<(CameraMode, String)>,
    /// What the left and the right camera offer (summaries).
    pub offers: (String, String),
    /// The controls set on each camera.
    pub controls: (ControlReport, ControlReport),
}

impl Negotiated {
    /// Whether the cameras fell back from the preferred mode.
    pub fn fell_back(&self) -> bool {
        !self.skipped.is_empty()
    }

    /// The one log line: what was chosen and why.
    pub fn summary(&self) -> String {
        if self.skipped.is_empty() {
            return format!("{} on both cameras", self.mode);
        }
        let why: Vec<String> = self
            .skipped
            .iter()
            .map(|(m, e)| format!("{m}: {e}"))
            .collect();
        format!(
            "{} on both cameras, after {} failed ({})",
            self.mode,
            self.skipped.len(),
            why.join("; ")
        )
    }
}

/// The two cameras of the Minoru, paired by timestamp.
pub struct StereoCamera {
    cameras: [Camera; 2],
    pairer: Pairer<FrameBuffer>,
    mjpeg: MjpegToGrey,
    last_frame: [Instant; 2],
    stall_timeout: Duration,
    negotiated: Negotiated,
}

/// Frames each side may hold while waiting for a partner.
const MAX_PENDING: usize = 2;

impl StereoCamera {
    /// Opens and starts both real cameras with the negotiation.
    pub fn open(spec: &StereoSpec) -> Result<Self, OpenError> {
        Self::open_with(spec, &super::KernelOpener)
    }

    /// Opens both cameras through `opener`: enumerates what each offers, tries the
    /// candidate modes best first (a `STREAMON` that fails with `ENOSPC` moves on to the
    /// next), sets the controls on both, and starts pairing.
    pub fn open_with(spec: &StereoSpec, opener: &dyn DeviceOpener) -> Result<Self, OpenError> {
        let pairer = Pairer::new(spec.max_skew_ns, MAX_PENDING)?;
        let (mut left, _) = open_capture_node(opener, &spec.left_device)?;
        let (mut right, _) = open_capture_node(opener, &spec.right_device)?;
        let left_offer = enumerate(left.as_mut(), &spec.left_device)?;
        let right_offer = enumerate(right.as_mut(), &spec.right_device)?;
        let m = &spec.mode;
        let candidates = candidate_modes(
            &left_offer,
            &right_offer,
            m.format,
            m.width,
            m.height,
            m.fps,
            m.buffers,
        )
        .map_err(OpenError::NoCommonMode)?;
        drop((left, right));
        let mut skipped = Vec::new();
        for mode in candidates {
            match Self::try_mode(opener, spec, &mode) {
                Ok(mut cameras) => {
                    let controls = (
                        cameras[0].apply_controls(&spec.controls),
                        cameras[1].apply_controls(&spec.controls),
                    );
                    let now = Instant::now();
                    return Ok(Self {
                        cameras,
                        pairer,
                        mjpeg: MjpegToGrey::new(),
                        last_frame: [now, now],
                        stall_timeout: spec.stall_timeout,
                        negotiated: Negotiated {
                            mode,
                            skipped,
                            offers: (left_offer.summary(), right_offer.summary()),
                            controls,
                        },
                    });
                }
                Err(TryFailure::Bandwidth(why)) => skipped.push((mode, why)),
                Err(TryFailure::Other(e)) => return Err(e),
            }
        }
        Err(OpenError::NoBandwidth {
            left: spec.left_device.clone(),
            right: spec.right_device.clone(),
            tried: skipped
                .iter()
                .map(|(m, e)| format!("{m}: {e}"))
                .collect::<Vec<_>>()
                .join("; "),
        })
    }

    /// Configures and starts both cameras in `mode`; a lack of bandwidth is told apart.
    fn try_mode(
        opener: &dyn DeviceOpener,
        spec: &StereoSpec,
        mode: &CameraMode,
    ) -> Result<[Camera; 2], TryFailure> {
        let bandwidth = |device: &Path, e: Errno| {
            if e == Errno::ENOSPC {
                TryFailure::Bandwidth(format!(
                    "VIDIOC_STREAMON on {} failed with ENOSPC (no USB bandwidth left)",
                    device.display()
                ))
            } else {
                TryFailure::Other(io_error(device, "VIDIOC_STREAMON", e))
            }
        };
        let mut left =
            Camera::configure(opener, &spec.left_device, mode).map_err(TryFailure::Other)?;
        let mut right =
            Camera::configure(opener, &spec.right_device, mode).map_err(TryFailure::Other)?;
        left.dev
            .stream_on()
            .map_err(|e| bandwidth(&spec.left_device, e))?;
        left.streaming = true;
        right
            .dev
            .stream_on()
            .map_err(|e| bandwidth(&spec.right_device, e))?;
        right.streaming = true;
        Ok([left, right])
    }

    /// What the negotiation chose.
    pub fn negotiated(&self) -> &Negotiated {
        &self.negotiated
    }

    /// The left and the right camera.
    pub fn cameras(&self) -> (&Camera, &Camera) {
        (&self.cameras[0], &self.cameras[1])
    }

    /// Pairing counters.
    pub fn stats(&self) -> crate::pairing::PairStats {
        self.pairer.stats()
    }

    fn camera_mut(&mut self, side: Side) -> &mut Camera {
        match side {
            Side::Left => &mut self.cameras[0],
            Side::Right => &mut self.cameras[1],
        }
    }

    /// Waits up to `timeout` for the next pair. `Ok(None)` on timeout or signal.
    pub fn next_pair(&mut self, timeout: Duration) -> Result<Option<CapturedPair>, CaptureError> {
        let deadline = Instant::now() + timeout;
        loop {
            for (i, side) in [Side::Left, Side::Right].into_iter().enumerate() {
                while let Some(frame) = self.cameras[i].dequeue()? {
                    self.last_frame[i] = Instant::now();
                    let step = self.pairer.push(side, frame);
                    for (side, frame) in step.released {
                        self.camera_mut(side).requeue(frame.token.index)?;
                    }
                    if let Some(pair) = step.pair {
                        return Ok(Some(CapturedPair {
                            pair,
                            completed_ns: monotonic_ns(),
                        }));
                    }
                }
                let silent = self.last_frame[i].elapsed();
                if silent > self.stall_timeout {
                    return Err(CaptureError::Stalled {
                        device: self.cameras[i].device.clone(),
                        waited_ms: silent.as_millis() as u64,
                    });
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            self.wait_readable((deadline - now).min(Duration::from_secs(1)))?;
        }
    }

    /// Blocks until a camera has a buffer ready or `wait` passes (short sleeps for devices
    /// without a descriptor).
    fn wait_readable(&self, wait: Duration) -> Result<(), CaptureError> {
        let (Some(l), Some(r)) = (self.cameras[0].dev.poll_fd(), self.cameras[1].dev.poll_fd())
        else {
            std::thread::sleep(wait.min(Duration::from_millis(1)));
            return Ok(());
        };
        let mut fds = [
            libc::pollfd {
                fd: l,
                events: libc::POLLIN,
                revents: 0,
            },
            libc::pollfd {
                fd: r,
                events: libc::POLLIN,
                revents: 0,
            },
        ];
        let wait_ms = wait.as_millis().clamp(1, 1000) as libc::c_int;
        // SAFETY: two valid pollfd entries.
        let n = unsafe { libc::poll(fds.as_mut_ptr(), 2, wait_ms) };
        if n < 0 {
            let errno = Errno::last();
            if errno == Errno::EINTR {
                return Ok(());
            }
            return Err(self.cameras[0].capture_error("poll", errno));
        }
        for (i, fd) in fds.iter().enumerate() {
            if fd.revents & (libc::POLLHUP | libc::POLLNVAL) != 0 {
                return Err(CaptureError::Disconnected {
                    device: self.cameras[i].device.clone(),
                    detail: format!("poll revents {:#x}", fd.revents),
                });
            }
        }
        Ok(())
    }

    /// Converts a pair to grey into `left` and `right` (`width x height` each) and gives its
    /// buffers back to the drivers (also when the conversion fails).
    pub fn read_pair(
        &mut self,
        pair: &CapturedPair,
        left: &mut [u8],
        right: &mut [u8],
    ) -> Result<(), CaptureError> {
        let l = self.cameras[0].to_grey(&pair.pair.left.token, &mut self.mjpeg, left);
        let r = self.cameras[1].to_grey(&pair.pair.right.token, &mut self.mjpeg, right);
        self.release_pair(pair)?;
        l.and(r)
    }

    /// Gives a pair's buffers back to the drivers unread.
    pub fn release_pair(&mut self, pair: &CapturedPair) -> Result<(), CaptureError> {
        self.cameras[0].requeue(pair.pair.left.token.index)?;
        self.cameras[1].requeue(pair.pair.right.token.index)
    }
}

/// Why one candidate mode did not stream.
enum TryFailure {
    /// No USB bandwidth for both: try the next mode.
    Bandwidth(String),
    /// Anything else: stop.
    Other(OpenError),
}
