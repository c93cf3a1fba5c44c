//! V4L2 capture from the Minoru's two UVC cameras, by hand-written ioctls.
//!
//! Why no crate: `v4l` 0.14 (the usual choice) depends on `v4l2-sys-mit`, whose build script
//! runs bindgen and needs libclang, which is not installed here (the build fails with "Unable
//! to find libclang"); its other backend needs the C library libv4l. The few calls a capture
//! needs are small and stable kernel ABI, so they are written here with `nix`'s ioctl macros
//! and `libc` (QUERYCAP, S_FMT, S_PARM, REQBUFS, QUERYBUF, mmap, QBUF/DQBUF, STREAMON/OFF),
//! with the structure sizes checked at compile time against the kernel's (64-bit Linux).

use std::fs::{File, OpenOptions};
use std::os::fd::AsRawFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use hvs_shared::clock::monotonic_ns;
use hvs_shared::config::V4l2PixelFormat;

use crate::convert::{ConvertError, MjpegToGrey, yuyv_to_grey};
use crate::pairing::{Pair, PairError, Pairer, Side, Stamped};

/// Kernel structures and ioctl numbers (linux/videodev2.h).
#[allow(missing_docs)]
mod sys {
    pub const BUF_TYPE_VIDEO_CAPTURE: u32 = 1;
    pub const MEMORY_MMAP: u32 = 1;
    pub const FIELD_NONE: u32 = 1;
    pub const CAP_VIDEO_CAPTURE: u32 = 0x0000_0001;
    pub const CAP_STREAMING: u32 = 0x0400_0000;
    pub const CAP_DEVICE_CAPS: u32 = 0x8000_0000;
    pub const CAP_TIMEPERFRAME: u32 = 0x1000;
    pub const BUF_FLAG_TIMESTAMP_MASK: u32 = 0xe000;
    pub const BUF_FLAG_TIMESTAMP_MONOTONIC: u32 = 0x2000;

    pub const fn fourcc(code: &[u8; 4]) -> u32 {
        (code[0] as u32) | (code[1] as u32) << 8 | (code[2] as u32) << 16 | (code[3] as u32) << 24
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct Capability {
        pub driver: [u8; 16],
        pub card: [u8; 32],
        pub bus_info: [u8; 32],
        pub version: u32,
        pub capabilities: u32,
        pub device_caps: u32,
        pub reserved: [u32; 3],
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct PixFormat {
        pub width: u32,
        pub height: u32,
        pub pixelformat: u32,
        pub field: u32,
        pub bytesperline: u32,
        pub sizeimage: u32,
        pub colorspace: u32,
        pub priv_: u32,
        pub flags: u32,
        pub ycbcr_enc: u32,
        pub quantization: u32,
        pub xfer_func: u32,
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub union FormatUnion {
        pub pix: PixFormat,
        pub raw: [u8; 200],
        // The kernel union holds pointers (struct v4l2_window): 8-byte aligned.
        pub align: [u64; 25],
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct Format {
        pub type_: u32,
        pub fmt: FormatUnion,
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct Fract {
        pub numerator: u32,
        pub denominator: u32,
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct CaptureParm {
        pub capability: u32,
        pub capturemode: u32,
        pub timeperframe: Fract,
        pub extendedmode: u32,
        pub readbuffers: u32,
        pub reserved: [u32; 4],
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub union ParmUnion {
        pub capture: CaptureParm,
        pub raw: [u8; 200],
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct StreamParm {
        pub type_: u32,
        pub parm: ParmUnion,
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct RequestBuffers {
        pub count: u32,
        pub type_: u32,
        pub memory: u32,
        pub capabilities: u32,
        pub flags: u8,
        pub reserved: [u8; 3],
    }

    #[repr(C)]
    #[derive(Clone, Copy, Default)]
    pub struct Timecode {
        pub type_: u32,
        pub flags: u32,
        pub frames: u8,
        pub seconds: u8,
        pub minutes: u8,
        pub hours: u8,
        pub userbits: [u8; 4],
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct Buffer {
        pub index: u32,
        pub type_: u32,
        pub bytesused: u32,
        pub flags: u32,
        pub field: u32,
        pub timestamp: libc::timeval,
        pub timecode: Timecode,
        pub sequence: u32,
        pub memory: u32,
        /// `m.offset` for MMAP buffers (the union also holds a pointer: 8 bytes).
        pub m: u64,
        pub length: u32,
        pub reserved2: u32,
        pub request_fd: i32,
    }

    impl Buffer {
        pub fn mmap_capture(index: u32) -> Self {
            Self {
                index,
                type_: BUF_TYPE_VIDEO_CAPTURE,
                bytesused: 0,
                flags: 0,
                field: 0,
                timestamp: libc::timeval {
                    tv_sec: 0,
                    tv_usec: 0,
                },
                timecode: Timecode::default(),
                sequence: 0,
                memory: MEMORY_MMAP,
                m: 0,
                length: 0,
                reserved2: 0,
                request_fd: 0,
            }
        }
    }

    #[cfg(target_pointer_width = "64")]
    const _: () = {
        assert!(size_of::<Capability>() == 104);
        assert!(size_of::<PixFormat>() == 48);
        assert!(size_of::<Format>() == 208);
        assert!(size_of::<StreamParm>() == 204);
        assert!(size_of::<RequestBuffers>() == 20);
        assert!(size_of::<Buffer>() == 88);
    };

    nix::ioctl_read!(querycap, b'V', 0, Capability);
    nix::ioctl_readwrite!(s_fmt, b'V', 5, Format);
    nix::ioctl_readwrite!(reqbufs, b'V', 8, RequestBuffers);
    nix::ioctl_readwrite!(querybuf, b'V', 9, Buffer);
    nix::ioctl_readwrite!(qbuf, b'V', 15, Buffer);
    nix::ioctl_readwrite!(dqbuf, b'V', 17, Buffer);
    nix::ioctl_write_ptr!(streamon, b'V', 18, libc::c_int);
    nix::ioctl_write_ptr!(streamoff, b'V', 19, libc::c_int);
    nix::ioctl_readwrite!(s_parm, b'V', 22, StreamParm);
}

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

struct Mapping {
    ptr: *mut u8,
    len: usize,
}

impl Drop for Mapping {
    fn drop(&mut self) {
        // SAFETY: `ptr`/`len` come from a successful mmap and are unmapped exactly once.
        unsafe {
            libc::munmap(self.ptr.cast(), self.len);
        }
    }
}

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

/// One open, streaming V4L2 camera.
pub struct Camera {
    device: PathBuf,
    file: File,
    buffers: Vec<Mapping>,
    width: usize,
    height: usize,
    stride_bytes: usize,
    format: V4l2PixelFormat,
    fps: Option<f64>,
}

fn io_error(device: &Path, op: &'static str, errno: nix::errno::Errno) -> OpenError {
    match errno {
        nix::errno::Errno::EBUSY => OpenError::Busy {
            device: device.to_path_buf(),
            detail: format!("{op}: device in use by another process"),
        },
        nix::errno::Errno::ENOSPC => OpenError::Busy {
            device: device.to_path_buf(),
            detail: format!(
                "{op}: not enough USB bandwidth (both cameras on one bus: try mjpeg, a lower \
                 rate or 320x240)"
            ),
        },
        nix::errno::Errno::ENODEV | nix::errno::Errno::ENXIO => OpenError::Missing {
            device: device.to_path_buf(),
        },
        errno => OpenError::Io {
            device: device.to_path_buf(),
            op,
            errno,
        },
    }
}

fn c_text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

impl Camera {
    /// Opens `device`, sets `mode`, maps the buffers and starts streaming.
    pub fn open(device: &Path, mode: &CameraMode) -> Result<Self, OpenError> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
            .open(device)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::NotFound => OpenError::Missing {
                    device: device.to_path_buf(),
                },
                std::io::ErrorKind::PermissionDenied => OpenError::Permission {
                    device: device.to_path_buf(),
                },
                _ => io_error(
                    device,
                    "open",
                    nix::errno::Errno::from_raw(e.raw_os_error().unwrap_or(libc::EIO)),
                ),
            })?;
        let fd = file.as_raw_fd();

        // SAFETY: `Capability` is plain old data matching struct v4l2_capability.
        let mut cap: sys::Capability = unsafe { std::mem::zeroed() };
        // SAFETY: valid fd and a pointer to a correctly sized structure.
        unsafe { sys::querycap(fd, &mut cap) }.map_err(|errno| OpenError::NotV4l2 {
            device: device.to_path_buf(),
            errno,
        })?;
        let caps = if cap.capabilities & sys::CAP_DEVICE_CAPS != 0 {
            cap.device_caps
        } else {
            cap.capabilities
        };
        let needed = sys::CAP_VIDEO_CAPTURE | sys::CAP_STREAMING;
        if caps & needed != needed {
            return Err(OpenError::NotCapture {
                device: device.to_path_buf(),
                card: c_text(&cap.card),
                caps,
            });
        }

        let fourcc = fourcc_of(mode.format);
        let mut fmt = sys::Format {
            type_: sys::BUF_TYPE_VIDEO_CAPTURE,
            fmt: sys::FormatUnion { raw: [0; 200] },
        };
        fmt.fmt.pix = sys::PixFormat {
            width: mode.width,
            height: mode.height,
            pixelformat: fourcc,
            field: sys::FIELD_NONE,
            ..Default::default()
        };
        // SAFETY: valid fd and structure.
        unsafe { sys::s_fmt(fd, &mut fmt) }.map_err(|e| io_error(device, "VIDIOC_S_FMT", e))?;
        // SAFETY: the driver filled the `pix` member for a video capture type.
        let pix = unsafe { fmt.fmt.pix };
        if pix.width != mode.width || pix.height != mode.height || pix.pixelformat != fourcc {
            return Err(OpenError::ModeNotOffered {
                device: device.to_path_buf(),
                requested: format!("{}x{} {}", mode.width, mode.height, fourcc_name(fourcc)),
                offered: format!(
                    "{}x{} {}",
                    pix.width,
                    pix.height,
                    fourcc_name(pix.pixelformat)
                ),
            });
        }
        let stride_bytes = if mode.format == V4l2PixelFormat::Yuyv {
            (pix.bytesperline as usize).max(2 * mode.width as usize)
        } else {
            0
        };

        let fps = set_rate(fd, device, mode.fps)?;

        let mut req = sys::RequestBuffers {
            count: mode.buffers,
            type_: sys::BUF_TYPE_VIDEO_CAPTURE,
            memory: sys::MEMORY_MMAP,
            ..Default::default()
        };
        // SAFETY: valid fd and structure.
        unsafe { sys::reqbufs(fd, &mut req) }.map_err(|e| io_error(device, "VIDIOC_REQBUFS", e))?;
        if req.count < 2 {
            return Err(OpenError::Busy {
                device: device.to_path_buf(),
                detail: format!(
                    "the driver granted {} buffers, at least 2 needed",
                    req.count
                ),
            });
        }
        let mut buffers = Vec::with_capacity(req.count as usize);
        for index in 0..req.count {
            let mut buf = sys::Buffer::mmap_capture(index);
            // SAFETY: valid fd and structure.
            unsafe { sys::querybuf(fd, &mut buf) }
                .map_err(|e| io_error(device, "VIDIOC_QUERYBUF", e))?;
            // SAFETY: maps the driver's buffer at the offset it reported; checked below.
            let ptr = unsafe {
                libc::mmap(
                    std::ptr::null_mut(),
                    buf.length as usize,
                    libc::PROT_READ | libc::PROT_WRITE,
                    libc::MAP_SHARED,
                    fd,
                    buf.m as libc::off_t,
                )
            };
            if ptr == libc::MAP_FAILED {
                return Err(io_error(device, "mmap", nix::errno::Errno::last()));
            }
            buffers.push(Mapping {
                ptr: ptr.cast(),
                len: buf.length as usize,
            });
        }
        let camera = Self {
            device: device.to_path_buf(),
            file,
            buffers,
            width: mode.width as usize,
            height: mode.height as usize,
            stride_bytes,
            format: mode.format,
            fps,
        };
        for index in 0..camera.buffers.len() as u32 {
            camera
                .queue(index)
                .map_err(|e| io_error(device, "VIDIOC_QBUF", e))?;
        }
        let kind = sys::BUF_TYPE_VIDEO_CAPTURE as libc::c_int;
        // SAFETY: valid fd and a pointer to the buffer type.
        unsafe { sys::streamon(fd, &kind) }.map_err(|e| io_error(device, "VIDIOC_STREAMON", e))?;
        Ok(camera)
    }

    /// The device path.
    pub fn device(&self) -> &Path {
        &self.device
    }

    /// The frame rate the driver accepted, Hz (`None` if it cannot set one).
    pub fn fps(&self) -> Option<f64> {
        self.fps
    }

    fn queue(&self, index: u32) -> Result<(), nix::errno::Errno> {
        let mut buf = sys::Buffer::mmap_capture(index);
        // SAFETY: valid fd and structure; `index` is below the granted count.
        unsafe { sys::qbuf(self.file.as_raw_fd(), &mut buf) }.map(|_| ())
    }

    /// Gives a buffer back to the driver.
    pub fn requeue(&self, index: u32) -> Result<(), CaptureError> {
        self.queue(index)
            .map_err(|errno| self.capture_error("VIDIOC_QBUF", errno))
    }

    fn capture_error(&self, op: &'static str, errno: nix::errno::Errno) -> CaptureError {
        if matches!(errno, nix::errno::Errno::ENODEV | nix::errno::Errno::ENXIO) {
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
    pub fn dequeue(&self) -> Result<Option<Stamped<FrameBuffer>>, CaptureError> {
        let mut buf = sys::Buffer::mmap_capture(0);
        // SAFETY: valid fd and structure.
        match unsafe { sys::dqbuf(self.file.as_raw_fd(), &mut buf) } {
            Ok(_) => {}
            Err(nix::errno::Errno::EAGAIN | nix::errno::Errno::EINTR) => return Ok(None),
            Err(errno) => return Err(self.capture_error("VIDIOC_DQBUF", errno)),
        }
        let stamp_ns =
            if buf.flags & sys::BUF_FLAG_TIMESTAMP_MASK == sys::BUF_FLAG_TIMESTAMP_MONOTONIC {
                (buf.timestamp.tv_sec as u64)
                    .saturating_mul(1_000_000_000)
                    .saturating_add(buf.timestamp.tv_usec as u64 * 1000)
            } else {
                monotonic_ns()
            };
        Ok(Some(Stamped {
            stamp_ns,
            token: FrameBuffer {
                index: buf.index,
                bytes_used: buf.bytesused,
                sequence: buf.sequence,
            },
        }))
    }

    /// The bytes of a dequeued buffer.
    pub fn data(&self, frame: &FrameBuffer) -> &[u8] {
        match self.buffers.get(frame.index as usize) {
            Some(m) => {
                let len = (frame.bytes_used as usize).min(m.len);
                // SAFETY: the mapping is live for `self`'s lifetime and `len <= m.len`; the
                // driver does not write a buffer while it is dequeued.
                unsafe { std::slice::from_raw_parts(m.ptr, len) }
            }
            None => &[],
        }
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
        let kind = sys::BUF_TYPE_VIDEO_CAPTURE as libc::c_int;
        // SAFETY: valid fd; failure (device gone) is harmless here.
        let _ = unsafe { sys::streamoff(self.file.as_raw_fd(), &kind) };
        // The mappings are unmapped when `buffers` drops, then the file closes.
    }
}

/// Sets the frame interval; returns the rate the driver accepted (`None` if it has no
/// frame-rate control).
fn set_rate(fd: libc::c_int, device: &Path, fps: f64) -> Result<Option<f64>, OpenError> {
    let mut parm = sys::StreamParm {
        type_: sys::BUF_TYPE_VIDEO_CAPTURE,
        parm: sys::ParmUnion { raw: [0; 200] },
    };
    parm.parm.capture = sys::CaptureParm {
        timeperframe: sys::Fract {
            numerator: 1000,
            denominator: (fps * 1000.0).round().max(1.0) as u32,
        },
        ..Default::default()
    };
    // SAFETY: valid fd and structure.
    match unsafe { sys::s_parm(fd, &mut parm) } {
        Ok(_) => {}
        Err(nix::errno::Errno::ENOTTY | nix::errno::Errno::EINVAL) => return Ok(None),
        Err(e) => return Err(io_error(device, "VIDIOC_S_PARM", e)),
    }
    // SAFETY: the driver filled the capture member.
    let cp = unsafe { parm.parm.capture };
    if cp.capability & sys::CAP_TIMEPERFRAME == 0 || cp.timeperframe.numerator == 0 {
        return Ok(None);
    }
    Ok(Some(
        cp.timeperframe.denominator as f64 / cp.timeperframe.numerator as f64,
    ))
}

/// Settings of a [`StereoCamera`].
#[derive(Debug, Clone, PartialEq)]
pub struct StereoSpec {
    /// Left device.
    pub left_device: PathBuf,
    /// Right device.
    pub right_device: PathBuf,
    /// Mode of both cameras.
    pub mode: CameraMode,
    /// Largest left/right timestamp difference of a pair, ns.
    pub max_skew_ns: u64,
    /// A camera silent this long is reported as stalled.
    pub stall_timeout: Duration,
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

/// The two cameras of the Minoru, paired by timestamp.
pub struct StereoCamera {
    cameras: [Camera; 2],
    pairer: Pairer<FrameBuffer>,
    mjpeg: MjpegToGrey,
    last_frame: [Instant; 2],
    stall_timeout: Duration,
}

/// Frames each side may hold while waiting for a partner.
const MAX_PENDING: usize = 2;

impl StereoCamera {
    /// Opens and starts both cameras (left first).
    pub fn open(spec: &StereoSpec) -> Result<Self, OpenError> {
        let pairer = Pairer::new(spec.max_skew_ns, MAX_PENDING)?;
        let left = Camera::open(&spec.left_device, &spec.mode)?;
        let right = Camera::open(&spec.right_device, &spec.mode)?;
        let now = Instant::now();
        Ok(Self {
            cameras: [left, right],
            pairer,
            mjpeg: MjpegToGrey::new(),
            last_frame: [now, now],
            stall_timeout: spec.stall_timeout,
        })
    }

    /// The left and the right camera.
    pub fn cameras(&self) -> (&Camera, &Camera) {
        (&self.cameras[0], &self.cameras[1])
    }

    /// Pairing counters.
    pub fn stats(&self) -> crate::pairing::PairStats {
        self.pairer.stats()
    }

    fn requeue_all(&self, released: Vec<(Side, Stamped<FrameBuffer>)>) -> Result<(), CaptureError> {
        for (side, frame) in released {
            self.camera(side).requeue(frame.token.index)?;
        }
        Ok(())
    }

    fn camera(&self, side: Side) -> &Camera {
        match side {
            Side::Left => &self.cameras[0],
            Side::Right => &self.cameras[1],
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
                    self.requeue_all(step.released)?;
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
            let mut fds = [
                libc::pollfd {
                    fd: self.cameras[0].file.as_raw_fd(),
                    events: libc::POLLIN,
                    revents: 0,
                },
                libc::pollfd {
                    fd: self.cameras[1].file.as_raw_fd(),
                    events: libc::POLLIN,
                    revents: 0,
                },
            ];
            let wait_ms = (deadline - now).as_millis().clamp(1, 1000) as libc::c_int;
            // SAFETY: two valid pollfd entries.
            let n = unsafe { libc::poll(fds.as_mut_ptr(), 2, wait_ms) };
            if n < 0 {
                let errno = nix::errno::Errno::last();
                if errno == nix::errno::Errno::EINTR {
                    return Ok(None);
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
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn mode() -> CameraMode {
        CameraMode {
            width: 640,
            height: 480,
            format: V4l2PixelFormat::Yuyv,
            fps: 30.0,
            buffers: 4,
        }
    }

    #[test]
    fn missing_device_is_named() {
        let err = Camera::open(Path::new("/dev/video-hvs-missing"), &mode())
            .err()
            .expect("no such device");
        assert!(matches!(err, OpenError::Missing { .. }), "{err:?}");
        assert!(!err.is_permanent());
        assert_eq!(
            err.to_string(),
            "camera /dev/video-hvs-missing does not exist (not plugged in, or wrong device path?)"
        );
    }

    #[test]
    fn stereo_open_names_the_missing_side() {
        let spec = StereoSpec {
            left_device: PathBuf::from("/dev/video-hvs-missing-left"),
            right_device: PathBuf::from("/dev/video-hvs-missing-right"),
            mode: mode(),
            max_skew_ns: 10_000_000,
            stall_timeout: Duration::from_secs(2),
        };
        let err = StereoCamera::open(&spec).err().expect("no such devices");
        assert!(
            err.to_string().contains("/dev/video-hvs-missing-left"),
            "{err}"
        );
    }

    #[test]
    fn a_file_that_is_not_a_camera_fails_querycap() {
        // /dev/null opens fine; VIDIOC_QUERYCAP then fails (ENOTTY): the real ioctl path runs.
        let err = Camera::open(Path::new("/dev/null"), &mode())
            .err()
            .expect("not a camera");
        assert!(matches!(err, OpenError::NotV4l2 { .. }), "{err:?}");
        assert!(err.is_permanent());
        let msg = err.to_string();
        assert!(msg.starts_with("/dev/null is not a V4L2 device"), "{msg}");
    }

    #[test]
    fn fourcc_codes_match_the_kernel() {
        assert_eq!(fourcc_of(V4l2PixelFormat::Yuyv), 0x5659_5559);
        assert_eq!(fourcc_of(V4l2PixelFormat::Mjpeg), 0x4750_4a4d);
        assert_eq!(fourcc_name(0x4750_4a4d), "MJPG");
        assert_eq!(mode().to_string(), "640x480 YUYV at 30 fps");
    }

    #[test]
    fn ioctl_numbers_match_the_kernel() {
        // Values from linux/videodev2.h on x86_64 / aarch64.
        #[cfg(target_pointer_width = "64")]
        {
            assert_eq!(
                nix::request_code_read!(b'V', 0, size_of::<sys::Capability>()),
                0x8068_5600
            );
            assert_eq!(
                nix::request_code_readwrite!(b'V', 5, size_of::<sys::Format>()),
                0xc0d0_5605
            );
            assert_eq!(
                nix::request_code_readwrite!(b'V', 17, size_of::<sys::Buffer>()),
                0xc058_5611
            );
            assert_eq!(
                nix::request_code_readwrite!(b'V', 22, size_of::<sys::StreamParm>()),
                0xc0cc_5616
            );
        }
    }
}
