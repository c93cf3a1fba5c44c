//! The seam between the capture and the kernel: every V4L2 call the capture makes goes
//! through [`V4l2Device`]. [`KernelDevice`] is the real thing (ioctls on an open
//! `/dev/videoN`, buffers memory-mapped from the driver) and the default path;
//! [`super::fake`] reproduces a Minoru's behaviour for tests without hardware.

use std::fs::{File, OpenOptions};
use std::os::fd::{AsRawFd, RawFd};
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;

use nix::errno::Errno;

use super::sys;

/// What `VIDIOC_QUERYCAP` says about a device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceCaps {
    /// Driver name (`uvcvideo`).
    pub driver: String,
    /// Card name (the camera's product string).
    pub card: String,
    /// Bus position (`usb-0000:00:14.0-1.2`): two cameras on one hub share a prefix.
    pub bus_info: String,
    /// The device node's capabilities.
    pub caps: u32,
}

impl DeviceCaps {
    /// True for a streaming video capture node (not a UVC metadata node).
    pub fn is_streaming_capture(&self) -> bool {
        let needed = sys::CAP_VIDEO_CAPTURE | sys::CAP_STREAMING;
        self.caps & needed == needed
    }
}

/// A frame size a device offers for a pixel format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameSizes {
    /// One size.
    Discrete {
        /// Width, px.
        width: u32,
        /// Height, px.
        height: u32,
    },
    /// Any size in a range with steps.
    Stepwise {
        /// Smallest and largest width and the width step, px.
        width: (u32, u32, u32),
        /// Smallest and largest height and the height step, px.
        height: (u32, u32, u32),
    },
}

impl FrameSizes {
    /// Whether `width x height` is one of these sizes.
    pub fn contains(&self, width: u32, height: u32) -> bool {
        let fits = |v: u32, (lo, hi, step): (u32, u32, u32)| {
            v >= lo && v <= hi && (v - lo).is_multiple_of(step.max(1))
        };
        match *self {
            Self::Discrete {
                width: w,
                height: h,
            } => w == width && h == height,
            Self::Stepwise {
                width: w,
                height: h,
            } => fits(width, w) && fits(height, h),
        }
    }
}

/// Frame rates a device offers for one format and size.
#[derive(Debug, Clone, PartialEq)]
pub enum FrameRates {
    /// A list of rates, Hz.
    Discrete(Vec<f64>),
    /// Any rate between these, Hz (slowest, fastest).
    Range(f64, f64),
}

/// A dequeued buffer as the driver returned it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Dequeued {
    /// Buffer index.
    pub index: u32,
    /// Bytes the driver filled.
    pub bytes_used: u32,
    /// The driver's frame counter.
    pub sequence: u32,
    /// The kernel's CLOCK_MONOTONIC timestamp, ns (`None` if the driver has none).
    pub stamp_ns: Option<u64>,
}

/// What a control offers (`VIDIOC_QUERYCTRL`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ControlInfo {
    /// Driver's name for it.
    pub name: String,
    /// Smallest value.
    pub minimum: i32,
    /// Largest value.
    pub maximum: i32,
    /// Step.
    pub step: i32,
    /// Default.
    pub default_value: i32,
    /// Disabled, read-only or inactive (cannot be set now).
    pub unusable: bool,
}

/// One opened V4L2 device. Methods return the ioctl's `errno` on failure; the callers turn
/// it into an error that names the device and the step.
pub trait V4l2Device: Send {
    /// `VIDIOC_QUERYCAP`.
    fn query_caps(&mut self) -> Result<DeviceCaps, Errno>;
    /// `VIDIOC_ENUM_FMT`: the FOURCC codes offered.
    fn formats(&mut self) -> Result<Vec<u32>, Errno>;
    /// `VIDIOC_ENUM_FRAMESIZES` for a format.
    fn frame_sizes(&mut self, fourcc: u32) -> Result<Vec<FrameSizes>, Errno>;
    /// `VIDIOC_ENUM_FRAMEINTERVALS` for a format and size (`EINVAL`/`ENOTTY`: not said).
    fn frame_rates(&mut self, fourcc: u32, width: u32, height: u32) -> Result<FrameRates, Errno>;
    /// `VIDIOC_S_FMT`: returns what the driver set (width, height, fourcc, bytes per line).
    fn set_format(
        &mut self,
        fourcc: u32,
        width: u32,
        height: u32,
    ) -> Result<(u32, u32, u32, u32), Errno>;
    /// `VIDIOC_S_PARM`: the rate the driver accepted (`None`: no frame-rate control).
    fn set_frame_rate(&mut self, fps: f64) -> Result<Option<f64>, Errno>;
    /// `VIDIOC_REQBUFS` + `VIDIOC_QUERYBUF` + mmap: returns the buffers granted.
    fn map_buffers(&mut self, count: u32) -> Result<u32, Errno>;
    /// `VIDIOC_QBUF`.
    fn queue(&mut self, index: u32) -> Result<(), Errno>;
    /// `VIDIOC_DQBUF` without waiting: `Ok(None)` when no buffer is ready (`EAGAIN`).
    fn dequeue(&mut self) -> Result<Option<Dequeued>, Errno>;
    /// The first `len` bytes of a mapped buffer (empty for an unknown index).
    fn buffer(&self, index: u32, len: usize) -> &[u8];
    /// `VIDIOC_STREAMON`.
    fn stream_on(&mut self) -> Result<(), Errno>;
    /// `VIDIOC_STREAMOFF`.
    fn stream_off(&mut self) -> Result<(), Errno>;
    /// `VIDIOC_QUERYCTRL` (`Ok(None)`: the device has no such control).
    fn query_control(&mut self, id: u32) -> Result<Option<ControlInfo>, Errno>;
    /// `VIDIOC_G_CTRL`.
    fn control(&mut self, id: u32) -> Result<i32, Errno>;
    /// `VIDIOC_S_CTRL`.
    fn set_control(&mut self, id: u32, value: i32) -> Result<(), Errno>;
    /// A descriptor to `poll(2)` for a filled buffer; `None` makes the capture wait in short
    /// sleeps instead (a fake).
    fn poll_fd(&self) -> Option<RawFd>;
}

/// Opens devices by path: [`KernelOpener`] opens real ones.
pub trait DeviceOpener {
    /// Opens `path` for capture (non-blocking). `Err` carries the `open(2)` errno.
    fn open(&self, path: &Path) -> Result<Box<dyn V4l2Device>, Errno>;
}

/// Opens real V4L2 devices.
#[derive(Debug, Clone, Copy, Default)]
pub struct KernelOpener;

impl DeviceOpener for KernelOpener {
    fn open(&self, path: &Path) -> Result<Box<dyn V4l2Device>, Errno> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
            .open(path)
            .map_err(|e| Errno::from_raw(e.raw_os_error().unwrap_or(libc::EIO)))?;
        Ok(Box::new(KernelDevice {
            file,
            buffers: Vec::new(),
        }))
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

/// A real device: an open `/dev/videoN` and its memory-mapped buffers.
pub struct KernelDevice {
    file: File,
    buffers: Vec<Mapping>,
}

// SAFETY: the mappings are owned by this value alone and only read through `&self`; moving
// the value to another thread moves the only handle to them.
unsafe impl Send for KernelDevice {}

fn c_text(bytes: &[u8]) -> String {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

fn fract_to_fps(numerator: u32, denominator: u32) -> f64 {
    if numerator == 0 {
        0.0
    } else {
        denominator as f64 / numerator as f64
    }
}

impl V4l2Device for KernelDevice {
    fn query_caps(&mut self) -> Result<DeviceCaps, Errno> {
        // SAFETY: `Capability` is plain old data matching struct v4l2_capability.
        let mut cap: sys::Capability = unsafe { std::mem::zeroed() };
        // SAFETY: valid fd and a pointer to a correctly sized structure.
        unsafe { sys::querycap(self.file.as_raw_fd(), &mut cap) }?;
        let caps = if cap.capabilities & sys::CAP_DEVICE_CAPS != 0 {
            cap.device_caps
        } else {
            cap.capabilities
        };
        Ok(DeviceCaps {
            driver: c_text(&cap.driver),
            card: c_text(&cap.card),
            bus_info: c_text(&cap.bus_info),
            caps,
        })
    }

    fn formats(&mut self) -> Result<Vec<u32>, Errno> {
        let mut out = Vec::new();
        for index in 0..64 {
            let mut d = sys::FmtDesc {
                index,
                type_: sys::BUF_TYPE_VIDEO_CAPTURE,
                ..Default::default()
            };
            // SAFETY: valid fd and structure.
            match unsafe { sys::enum_fmt(self.file.as_raw_fd(), &mut d) } {
                Ok(_) => out.push(d.pixelformat),
                Err(Errno::EINVAL) => break,
                Err(e) => return Err(e),
            }
        }
        Ok(out)
    }

    fn frame_sizes(&mut self, fourcc: u32) -> Result<Vec<FrameSizes>, Errno> {
        let mut out = Vec::new();
        for index in 0..256 {
            let mut e = sys::FrmSizeEnum {
                index,
                pixel_format: fourcc,
                ..Default::default()
            };
            // SAFETY: valid fd and structure.
            match unsafe { sys::enum_framesizes(self.file.as_raw_fd(), &mut e) } {
                Ok(_) => {}
                Err(Errno::EINVAL) => break,
                Err(err) => return Err(err),
            }
            let s = e.size;
            if e.type_ == sys::FRMSIZE_TYPE_DISCRETE {
                out.push(FrameSizes::Discrete {
                    width: s[0],
                    height: s[1],
                });
            } else {
                // Continuous and stepwise are reported once, at index 0.
                out.push(FrameSizes::Stepwise {
                    width: (s[0], s[1], s[2]),
                    height: (s[3], s[4], s[5]),
                });
                break;
            }
        }
        Ok(out)
    }

    fn frame_rates(&mut self, fourcc: u32, width: u32, height: u32) -> Result<FrameRates, Errno> {
        let mut rates = Vec::new();
        for index in 0..256 {
            let mut e = sys::FrmIvalEnum {
                index,
                pixel_format: fourcc,
                width,
                height,
                ..Default::default()
            };
            // SAFETY: valid fd and structure.
            match unsafe { sys::enum_frameintervals(self.file.as_raw_fd(), &mut e) } {
                Ok(_) => {}
                Err(Errno::EINVAL) if index > 0 => break,
                Err(err) => return Err(err),
            }
            let i = e.interval;
            if e.type_ == sys::FRMIVAL_TYPE_DISCRETE {
                rates.push(fract_to_fps(i[0], i[1]));
            } else {
                // min and max interval: the fastest rate is the shortest interval.
                return Ok(FrameRates::Range(
                    fract_to_fps(i[2], i[3]),
                    fract_to_fps(i[0], i[1]),
                ));
            }
        }
        Ok(FrameRates::Discrete(rates))
    }

    fn set_format(
        &mut self,
        fourcc: u32,
        width: u32,
        height: u32,
    ) -> Result<(u32, u32, u32, u32), Errno> {
        let mut fmt = sys::Format {
            type_: sys::BUF_TYPE_VIDEO_CAPTURE,
            fmt: sys::FormatUnion { raw: [0; 200] },
        };
        fmt.fmt.pix = sys::PixFormat {
            width,
            height,
            pixelformat: fourcc,
            field: sys::FIELD_NONE,
            ..Default::default()
        };
        // SAFETY: valid fd and structure.
        unsafe { sys::s_fmt(self.file.as_raw_fd(), &mut fmt) }?;
        // SAFETY: the driver filled the `pix` member for a video capture type.
        let pix = unsafe { fmt.fmt.pix };
        Ok((pix.width, pix.height, pix.pixelformat, pix.bytesperline))
    }

    fn set_frame_rate(&mut self, fps: f64) -> Result<Option<f64>, Errno> {
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
        match unsafe { sys::s_parm(self.file.as_raw_fd(), &mut parm) } {
            Ok(_) => {}
            Err(Errno::ENOTTY | Errno::EINVAL) => return Ok(None),
            Err(e) => return Err(e),
        }
        // SAFETY: the driver filled the capture member.
        let cp = unsafe { parm.parm.capture };
        if cp.capability & sys::CAP_TIMEPERFRAME == 0 || cp.timeperframe.numerator == 0 {
            return Ok(None);
        }
        Ok(Some(fract_to_fps(
            cp.timeperframe.numerator,
            cp.timeperframe.denominator,
        )))
    }

    fn map_buffers(&mut self, count: u32) -> Result<u32, Errno> {
        let fd = self.file.as_raw_fd();
        let mut req = sys::RequestBuffers {
            count,
            type_: sys::BUF_TYPE_VIDEO_CAPTURE,
            memory: sys::MEMORY_MMAP,
            ..Default::default()
        };
        // SAFETY: valid fd and structure.
        unsafe { sys::reqbufs(fd, &mut req) }?;
        self.buffers.clear();
        for index in 0..req.count {
            let mut buf = sys::Buffer::mmap_capture(index);
            // SAFETY: valid fd and structure.
            unsafe { sys::querybuf(fd, &mut buf) }?;
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
                return Err(Errno::last());
            }
            self.buffers.push(Mapping {
                ptr: ptr.cast(),
                len: buf.length as usize,
            });
        }
        Ok(req.count)
    }

    fn queue(&mut self, index: u32) -> Result<(), Errno> {
        let mut buf = sys::Buffer::mmap_capture(index);
        // SAFETY: valid fd and structure; the driver checks `index`.
        unsafe { sys::qbuf(self.file.as_raw_fd(), &mut buf) }.map(|_| ())
    }

    fn dequeue(&mut self) -> Result<Option<Dequeued>, Errno> {
        let mut buf = sys::Buffer::mmap_capture(0);
        // SAFETY: valid fd and structure.
        match unsafe { sys::dqbuf(self.file.as_raw_fd(), &mut buf) } {
            Ok(_) => {}
            Err(Errno::EAGAIN | Errno::EINTR) => return Ok(None),
            Err(errno) => return Err(errno),
        }
        let monotonic =
            buf.flags & sys::BUF_FLAG_TIMESTAMP_MASK == sys::BUF_FLAG_TIMESTAMP_MONOTONIC;
        Ok(Some(Dequeued {
            index: buf.index,
            bytes_used: buf.bytesused,
            sequence: buf.sequence,
            stamp_ns: monotonic.then(|| {
                (buf.timestamp.tv_sec as u64)
                    .saturating_mul(1_000_000_000)
                    .saturating_add(buf.timestamp.tv_usec as u64 * 1000)
            }),
        }))
    }

    fn buffer(&self, index: u32, len: usize) -> &[u8] {
        match self.buffers.get(index as usize) {
            Some(m) => {
                // SAFETY: the mapping is live for `self`'s lifetime and `len <= m.len`; the
                // driver does not write a buffer while it is dequeued.
                unsafe { std::slice::from_raw_parts(m.ptr, len.min(m.len)) }
            }
            None => &[],
        }
    }

    fn stream_on(&mut self) -> Result<(), Errno> {
        let kind = sys::BUF_TYPE_VIDEO_CAPTURE as libc::c_int;
        // SAFETY: valid fd and a pointer to the buffer type.
        unsafe { sys::streamon(self.file.as_raw_fd(), &kind) }.map(|_| ())
    }

    fn stream_off(&mut self) -> Result<(), Errno> {
        let kind = sys::BUF_TYPE_VIDEO_CAPTURE as libc::c_int;
        // SAFETY: valid fd and a pointer to the buffer type.
        unsafe { sys::streamoff(self.file.as_raw_fd(), &kind) }.map(|_| ())
    }

    fn query_control(&mut self, id: u32) -> Result<Option<ControlInfo>, Errno> {
        let mut q = sys::QueryCtrl {
            id,
            ..Default::default()
        };
        // SAFETY: valid fd and structure.
        match unsafe { sys::queryctrl(self.file.as_raw_fd(), &mut q) } {
            Ok(_) => {}
            Err(Errno::EINVAL) => return Ok(None),
            Err(e) => return Err(e),
        }
        Ok(Some(ControlInfo {
            name: c_text(&q.name),
            minimum: q.minimum,
            maximum: q.maximum,
            step: q.step,
            default_value: q.default_value,
            unusable: q.flags
                & (sys::CTRL_FLAG_DISABLED | sys::CTRL_FLAG_READ_ONLY | sys::CTRL_FLAG_INACTIVE)
                != 0,
        }))
    }

    fn control(&mut self, id: u32) -> Result<i32, Errno> {
        let mut c = sys::Control { id, value: 0 };
        // SAFETY: valid fd and structure.
        unsafe { sys::g_ctrl(self.file.as_raw_fd(), &mut c) }?;
        Ok(c.value)
    }

    fn set_control(&mut self, id: u32, value: i32) -> Result<(), Errno> {
        let mut c = sys::Control { id, value };
        // SAFETY: valid fd and structure.
        unsafe { sys::s_ctrl(self.file.as_raw_fd(), &mut c) }.map(|_| ())
    }

    fn poll_fd(&self) -> Option<RawFd> {
        Some(self.file.as_raw_fd())
    }
}

impl Drop for KernelDevice {
    fn drop(&mut self) {
        // Failure (device gone) is harmless here; the mappings go before the file closes.
        let _ = self.stream_off();
        self.buffers.clear();
    }
}
