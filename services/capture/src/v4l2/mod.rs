//! V4L2 capture from the Minoru's two UVC cameras, by hand-written ioctls.
//!
//! - [`sys`]: the kernel structures and ioctl numbers;
//! - [`device`]: the seam, [`V4l2Device`], with the real [`KernelDevice`] behind it;
//! - [`negotiate`]: which mode both cameras can stream together (pure);
//! - [`controls`]: exposure, gain and white balance locked alike on both cameras;
//! - [`camera`]: one camera and the timestamp-paired stereo camera;
//! - [`fake`]: a fake Minoru for tests (format lists, ENOSPC, EAGAIN, unplug, skew).
//!
//! Why no crate: `v4l` 0.14 (the usual choice) depends on `v4l2-sys-mit`, whose build script
//! runs bindgen and needs libclang, which is not installed here (the build fails with "Unable
//! to find libclang"); its other backend needs the C library libv4l. The few calls a capture
//! needs are small and stable kernel ABI, so they are written here with `nix`'s ioctl macros
//! and `libc` (QUERYCAP, S_FMT, S_PARM, REQBUFS, QUERYBUF, mmap, QBUF/DQBUF, STREAMON/OFF),
//! with the structure sizes checked at compile time against the kernel's (64-bit Linux).

use std::path::PathBuf;

use hvs_runtime::config::V4l2PixelFormat;

use crate::convert::ConvertError;
use crate::pairing::PairError;

pub mod camera;
pub mod controls;
pub mod device;
pub mod fake;
pub mod negotiate;
mod sys;

pub use camera::{Camera, CapturedPair, FrameBuffer, Negotiated, StereoCamera, StereoSpec};
pub use device::{DeviceOpener, KernelDevice, KernelOpener, V4l2Device};

/// The FOURCC code of a pixel format.
pub fn fourcc_of(format: V4l2PixelFormat) -> u32 {
    match format {
        V4l2PixelFormat::Yuyv => sys::fourcc(b"YUYV"),
        V4l2PixelFormat::Mjpeg => sys::fourcc(b"MJPG"),
    }
}

/// A FOURCC code as text (`YUYV`), with unprintable bytes as `?`.
pub fn fourcc_name(code: u32) -> String {
    code.to_le_bytes()
        .iter()
        .map(|&b| if b.is_ascii_graphic() { b as char } else { '?' })
        .collect()
}

/// What to ask one camera for.
#[derive(Debug, Clone, PartialEq)]
pub struct CameraMode {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Pixel format.
    pub format: V4l2PixelFormat,
    /// Frame rate, Hz.
    pub fps: f64,
    /// Memory-mapped buffers to request.
    pub buffers: u32,
}

impl std::fmt::Display for CameraMode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}x{} {} at {} fps",
            self.width,
            self.height,
            fourcc_name(fourcc_of(self.format)),
            self.fps
        )
    }
}

/// Why a camera could not be opened and started. Every message names the device.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The device node does not exist (camera unplugged, wrong path).
    #[error("camera {device} does not exist (not plugged in, or wrong device path?)")]
    Missing {
        /// The device path.
        device: PathBuf,
    },
    /// Another process uses the camera, or the USB bus has no bandwidth left for it.
    #[error("camera {device} is busy: {detail}")]
    Busy {
        /// The device path.
        device: PathBuf,
        /// Which step failed and why.
        detail: String,
    },
    /// The user may not open the device.
    #[error("camera {device}: permission denied (is the user in the `video` group?)")]
    Permission {
        /// The device path.
        device: PathBuf,
    },
    /// The file is not a V4L2 device.
    #[error("{device} is not a V4L2 device (VIDIOC_QUERYCAP failed: {errno})")]
    NotV4l2 {
        /// The device path.
        device: PathBuf,
        /// The ioctl's error.
        errno: nix::errno::Errno,
    },
    /// The device cannot stream video captures (a UVC camera's second node is metadata).
    #[error(
        "{device} ({card}) is not a streaming video capture device (capabilities {caps:#010x}); \
         UVC cameras also create a metadata node: use the camera's other /dev/videoN"
    )]
    NotCapture {
        /// The device path.
        device: PathBuf,
        /// The driver's card name.
        card: String,
        /// The device capabilities.
        caps: u32,
    },
    /// The camera does not offer the requested size or pixel format.
    #[error("camera {device} does not offer {requested}; it offered {offered}")]
    ModeNotOffered {
        /// The device path.
        device: PathBuf,
        /// The requested mode.
        requested: String,
        /// What the driver chose instead.
        offered: String,
    },
    /// Any other failing system call.
    #[error("camera {device}: {op} failed: {errno}")]
    Io {
        /// The device path.
        device: PathBuf,
        /// The call (e.g. `VIDIOC_REQBUFS`).
        op: &'static str,
        /// The error.
        errno: nix::errno::Errno,
    },
    /// The two cameras share no mode (size, format, rate) the configuration allows.
    #[error("{0}")]
    NoCommonMode(negotiate::NoCommonMode),
    /// Every candidate mode failed to stream: the USB bus has no bandwidth for both.
    #[error(
        "cameras {left} + {right}: no mode streams on both ({tried}); put the cameras on \
         separate USB controllers, or try pixel_format = \"mjpeg\""
    )]
    NoBandwidth {
        /// Left device.
        left: PathBuf,
        /// Right device.
        right: PathBuf,
        /// Each mode tried and why it failed.
        tried: String,
    },
    /// The pairing settings are invalid.
    #[error("camera pairing: {0}")]
    Pairing(#[from] PairError),
}

impl OpenError {
    /// Whether retrying cannot help (wrong device, wrong mode, no permission): the stage
    /// stops instead of retrying.
    pub fn is_permanent(&self) -> bool {
        matches!(
            self,
            Self::Permission { .. }
                | Self::NotV4l2 { .. }
                | Self::NotCapture { .. }
                | Self::ModeNotOffered { .. }
                | Self::NoCommonMode(_)
                | Self::Pairing(_)
        )
    }
}

/// Why a running capture failed. Every message names the device.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The camera went away (unplugged, USB reset).
    #[error("camera {device} disconnected: {detail}")]
    Disconnected {
        /// The device path.
        device: PathBuf,
        /// What showed it.
        detail: String,
    },
    /// The camera delivered no frame for too long.
    #[error("camera {device} delivered no frame for {waited_ms} ms")]
    Stalled {
        /// The device path.
        device: PathBuf,
        /// How long it has been silent, ms.
        waited_ms: u64,
    },
    /// A system call failed.
    #[error("camera {device}: {op} failed: {errno}")]
    Io {
        /// The device path.
        device: PathBuf,
        /// The call.
        op: &'static str,
        /// The error.
        errno: nix::errno::Errno,
    },
    /// A frame could not be converted to grey (the pair is skipped; not a device failure).
    #[error("camera {device}: frame {sequence}: {source}")]
    Convert {
        /// The device path.
        device: PathBuf,
        /// The driver's frame sequence number.
        sequence: u32,
        /// The conversion error.
        #[source]
        source: ConvertError,
    },
}

impl CaptureError {
    /// Whether the cameras must be reopened (everything except a bad frame).
    pub fn needs_reconnect(&self) -> bool {
        !matches!(self, Self::Convert { .. })
    }
}

#[cfg(test)]
mod tests;
