//! A fake Minoru behind the [`V4l2Device`] seam, so the negotiation, the fallbacks, the
//! controls and the pairing are tested without hardware (the capture's tests and
//! `hvs doctor`'s use it; the product opens [`KernelDevice`](super::KernelDevice)s).
//!
//! It reproduces what users report of the real one: two UVC cameras on one USB 2 bus with a
//! bandwidth budget shared by both (a `STREAMON` that exceeds it fails with `ENOSPC`), format
//! lists with sizes and rates, the rate set per device, `EAGAIN` from `DQBUF` when no frame
//! is ready, `ENODEV` once unplugged, and buffers stamped with CLOCK_MONOTONIC times on each
//! camera's own schedule, the right one offset by a skew.

use std::collections::{BTreeMap, VecDeque};
use std::os::fd::RawFd;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, MutexGuard};

use hvs_runtime::clock::monotonic_ns;
use hvs_runtime::config::V4l2PixelFormat;
use nix::errno::Errno;

use super::device::{
    ControlInfo, Dequeued, DeviceCaps, DeviceOpener, FrameRates, FrameSizes, V4l2Device,
};
use super::fourcc_of;
use super::sys;

/// One fake camera's fixed behaviour.
#[derive(Debug, Clone)]
pub struct FakeCamera {
    /// Card name.
    pub card: String,
    /// Formats offered: FOURCC, then sizes with their rates.
    pub formats: Vec<(u32, Vec<(FrameSizes, FrameRates)>)>,
    /// Controls offered, by id.
    pub controls: BTreeMap<u32, ControlInfo>,
    /// Added to every timestamp, ns (the right camera's skew).
    pub stamp_offset_ns: i64,
    /// Every `n`-th `DQBUF` returns `EAGAIN` even with a frame due (0: never).
    pub eagain_every: u32,
    /// Not a capture node (a UVC metadata node).
    pub metadata_only: bool,
}

impl FakeCamera {
    /// A Minoru camera: YUYV at 640x480 and 320x240 at 30, 15 and 5 fps; MJPEG at 640x480
    /// at 30 fps; exposure, gain, white balance and power-line controls.
    pub fn minoru() -> Self {
        let rates = || FrameRates::Discrete(vec![30.0, 15.0, 5.0]);
        let size = |width, height| FrameSizes::Discrete { width, height };
        let control = |name: &str, minimum, maximum, default_value| ControlInfo {
            name: name.into(),
            minimum,
            maximum,
            step: 1,
            default_value,
            unusable: false,
        };
        use super::controls::id;
        let controls = BTreeMap::from([
            (id::EXPOSURE_AUTO, control("Exposure, Auto", 0, 3, 3)),
            (
                id::EXPOSURE_ABSOLUTE,
                control("Exposure (Absolute)", 1, 5000, 166),
            ),
            (id::GAIN, control("Gain", 0, 255, 64)),
            (
                id::AUTO_WHITE_BALANCE,
                control("White Balance, Auto", 0, 1, 1),
            ),
            (
                id::WHITE_BALANCE_TEMPERATURE,
                control("White Balance Temperature", 2800, 6500, 4600),
            ),
            (
                id::POWER_LINE_FREQUENCY,
                control("Power Line Frequency", 0, 2, 1),
            ),
        ]);
        Self {
            card: "Minoru camera".into(),
            formats: vec![
                (
                    fourcc_of(V4l2PixelFormat::Yuyv),
                    vec![(size(640, 480), rates()), (size(320, 240), rates())],
                ),
                (
                    fourcc_of(V4l2PixelFormat::Mjpeg),
                    vec![(size(640, 480), FrameRates::Discrete(vec![30.0]))],
                ),
            ],
            controls,
            stamp_offset_ns: 0,
            eagain_every: 0,
            metadata_only: false,
        }
    }
}

/// What the fake devices were asked to do, per device path.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FakeDeviceLog {
    /// Every rate set with `VIDIOC_S_PARM`.
    pub rates_set: Vec<f64>,
    /// Every `VIDIOC_S_CTRL`: id and value.
    pub controls_set: Vec<(u32, i32)>,
    /// Every `VIDIOC_STREAMON`: the mode (`640x480@15`) and whether it was refused.
    pub stream_ons: Vec<(String, bool)>,
    /// `EAGAIN`s returned.
    pub eagains: u32,
}

#[derive(Debug, Default)]
struct BusState {
    /// Bytes per second the bus carries for isochronous video.
    budget_bytes_per_s: f64,
    /// Load of each streaming device.
    streaming: BTreeMap<PathBuf, f64>,
    unplugged: Vec<PathBuf>,
    /// First STREAMON on the bus: the cameras' schedules start from it.
    epoch_ns: Option<u64>,
    logs: BTreeMap<PathBuf, FakeDeviceLog>,
}

/// One USB 2 bus with fake cameras on it; cloning shares it.
#[derive(Debug, Clone)]
pub struct FakeBus {
    state: Arc<Mutex<BusState>>,
    cameras: Arc<BTreeMap<PathBuf, FakeCamera>>,
}

/// Bytes per second one stream takes: YUYV 2 bytes a pixel; MJPEG about a sixth of that.
fn stream_load(fourcc: u32, width: u32, height: u32, fps: f64) -> f64 {
    let per_px = if fourcc == fourcc_of(V4l2PixelFormat::Mjpeg) {
        0.35
    } else {
        2.0
    };
    width as f64 * height as f64 * per_px * fps
}

/// What a Minoru's hub carries: two 640x480 YUYV streams at 15 fps (18.4 MB/s), not at 30.
pub const MINORU_BUS_BYTES_PER_S: f64 = 24e6;

impl FakeBus {
    /// A bus carrying `budget_bytes_per_s` with `cameras` at their device paths.
    pub fn new(budget_bytes_per_s: f64, cameras: Vec<(PathBuf, FakeCamera)>) -> Self {
        Self {
            state: Arc::new(Mutex::new(BusState {
                budget_bytes_per_s,
                ..Default::default()
            })),
            cameras: Arc::new(cameras.into_iter().collect()),
        }
    }

    fn lock(&self) -> MutexGuard<'_, BusState> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Unplugs a camera: its open device answers `ENODEV`, opening it `ENOENT`.
    pub fn unplug(&self, path: &Path) {
        let mut s = self.lock();
        s.unplugged.push(path.to_path_buf());
        s.streaming.remove(path);
    }

    /// Plugs it back in.
    pub fn replug(&self, path: &Path) {
        self.lock().unplugged.retain(|p| p != path);
    }

    /// What one device was asked to do.
    pub fn log(&self, path: &Path) -> FakeDeviceLog {
        self.lock().logs.get(path).cloned().unwrap_or_default()
    }
}

impl DeviceOpener for FakeBus {
    fn open(&self, path: &Path) -> Result<Box<dyn V4l2Device>, Errno> {
        let camera = self.cameras.get(path).ok_or(Errno::ENOENT)?.clone();
        if self.lock().unplugged.iter().any(|p| p == path) {
            return Err(Errno::ENOENT);
        }
        Ok(Box::new(FakeDevice {
            path: path.to_path_buf(),
            camera,
            bus: self.clone(),
            format: None,
            fps: 30.0,
            buffers: Vec::new(),
            queued: VecDeque::new(),
            next_frame: 0,
            streaming: false,
            dequeues: 0,
            values: BTreeMap::new(),
        }))
    }
}

/// One opened fake camera.
pub struct FakeDevice {
    path: PathBuf,
    camera: FakeCamera,
    bus: FakeBus,
    format: Option<(u32, u32, u32)>,
    fps: f64,
    buffers: Vec<Vec<u8>>,
    queued: VecDeque<u32>,
    /// Index of the next frame on this camera's schedule.
    next_frame: u64,
    streaming: bool,
    dequeues: u32,
    values: BTreeMap<u32, i32>,
}

impl FakeDevice {
    fn gone(&self) -> bool {
        self.bus.lock().unplugged.iter().any(|p| p == &self.path)
    }

    fn log(&self, f: impl FnOnce(&mut FakeDeviceLog)) {
        f(self.bus.lock().logs.entry(self.path.clone()).or_default());
    }

    fn period_ns(&self) -> u64 {
        (1e9 / self.fps.max(1.0)) as u64
    }

    /// Nominal time of frame `n`: the bus epoch plus `n` periods plus the skew.
    fn frame_time_ns(&self, n: u64, epoch_ns: u64) -> u64 {
        (epoch_ns + n * self.period_ns()).saturating_add_signed(self.camera.stamp_offset_ns)
    }
}

impl V4l2Device for FakeDevice {
    fn query_caps(&mut self) -> Result<DeviceCaps, Errno> {
        let caps = if self.camera.metadata_only {
            0x0080_0000 // V4L2_CAP_META_CAPTURE
        } else {
            sys::CAP_VIDEO_CAPTURE | sys::CAP_STREAMING
        };
        Ok(DeviceCaps {
            driver: "uvcvideo".into(),
            card: self.camera.card.clone(),
            bus_info: "usb-fake-1.1".into(),
            caps,
        })
    }

    fn formats(&mut self) -> Result<Vec<u32>, Errno> {
        Ok(self.camera.formats.iter().map(|f| f.0).collect())
    }

    fn frame_sizes(&mut self, fourcc: u32) -> Result<Vec<FrameSizes>, Errno> {
        let f = self.camera.formats.iter().find(|f| f.0 == fourcc);
        Ok(f.map(|f| f.1.iter().map(|s| s.0).collect())
            .unwrap_or_default())
    }

    fn frame_rates(&mut self, fourcc: u32, width: u32, height: u32) -> Result<FrameRates, Errno> {
        let f = self.camera.formats.iter().find(|f| f.0 == fourcc);
        f.and_then(|f| f.1.iter().find(|s| s.0.contains(width, height)))
            .map(|s| s.1.clone())
            .ok_or(Errno::EINVAL)
    }

    fn set_format(
        &mut self,
        fourcc: u32,
        width: u32,
        height: u32,
    ) -> Result<(u32, u32, u32, u32), Errno> {
        // Like a driver: an unknown format or size gets the first one offered instead.
        let (f, sizes) = self
            .camera
            .formats
            .iter()
            .find(|f| f.0 == fourcc)
            .or(self.camera.formats.first())
            .ok_or(Errno::EINVAL)?;
        let size = sizes
            .iter()
            .find(|s| s.0.contains(width, height))
            .or(sizes.first())
            .ok_or(Errno::EINVAL)?;
        let (w, h) = match size.0 {
            FrameSizes::Discrete { width, height } => (width, height),
            FrameSizes::Stepwise { .. } => (width, height),
        };
        self.format = Some((*f, w, h));
        Ok((w, h, *f, 2 * w))
    }

    fn set_frame_rate(&mut self, fps: f64) -> Result<Option<f64>, Errno> {
        self.fps = fps;
        self.log(|l| l.rates_set.push(fps));
        Ok(Some(fps))
    }

    fn map_buffers(&mut self, count: u32) -> Result<u32, Errno> {
        let (_, w, h) = self.format.ok_or(Errno::EINVAL)?;
        self.buffers = vec![vec![0; (2 * w * h) as usize]; count as usize];
        Ok(count)
    }

    fn queue(&mut self, index: u32) -> Result<(), Errno> {
        if self.gone() {
            return Err(Errno::ENODEV);
        }
        if index as usize >= self.buffers.len() || self.queued.contains(&index) {
            return Err(Errno::EINVAL);
        }
        self.queued.push_back(index);
        Ok(())
    }

    fn dequeue(&mut self) -> Result<Option<Dequeued>, Errno> {
        if self.gone() {
            return Err(Errno::ENODEV);
        }
        if !self.streaming {
            return Err(Errno::EINVAL);
        }
        self.dequeues += 1;
        if self.camera.eagain_every > 0 && self.dequeues.is_multiple_of(self.camera.eagain_every) {
            self.log(|l| l.eagains += 1);
            return Ok(None);
        }
        let epoch = self.bus.lock().epoch_ns.unwrap_or(0);
        let due = self.frame_time_ns(self.next_frame, epoch);
        if due > monotonic_ns() {
            return Ok(None);
        }
        let Some(index) = self.queued.pop_front() else {
            // No buffer to fill: the driver drops the frame.
            self.next_frame += 1;
            return Ok(None);
        };
        let n = self.next_frame;
        self.next_frame += 1;
        // A horizontal ramp that moves with the frame number, as YUYV (Y U Y V).
        let (_, w, _) = self.format.unwrap_or((0, 0, 0));
        let buf = &mut self.buffers[index as usize];
        for (i, px) in buf.chunks_exact_mut(2).enumerate() {
            let x = (i as u32) % w.max(1);
            px[0] = (x as u64 + n) as u8;
            px[1] = 128;
        }
        Ok(Some(Dequeued {
            index,
            bytes_used: buf.len() as u32,
            sequence: n as u32,
            stamp_ns: Some(due),
        }))
    }

    fn buffer(&self, index: u32, len: usize) -> &[u8] {
        self.buffers
            .get(index as usize)
            .map_or(&[][..], |b| &b[..len.min(b.len())])
    }

    fn stream_on(&mut self) -> Result<(), Errno> {
        if self.gone() {
            return Err(Errno::ENODEV);
        }
        let (fourcc, w, h) = self.format.ok_or(Errno::EINVAL)?;
        let load = stream_load(fourcc, w, h, self.fps);
        let label = format!("{w}x{h}@{}", self.fps);
        let mut bus = self.bus.lock();
        let used: f64 = bus.streaming.values().sum();
        let refused = used + load > bus.budget_bytes_per_s;
        bus.logs
            .entry(self.path.clone())
            .or_default()
            .stream_ons
            .push((label, refused));
        if refused {
            return Err(Errno::ENOSPC);
        }
        bus.streaming.insert(self.path.clone(), load);
        let now = monotonic_ns();
        let epoch = *bus.epoch_ns.get_or_insert(now);
        drop(bus);
        // The first frame at or after now on this camera's schedule.
        let period = self.period_ns();
        let since = now.saturating_sub(epoch);
        self.next_frame = since.div_ceil(period);
        self.streaming = true;
        Ok(())
    }

    fn stream_off(&mut self) -> Result<(), Errno> {
        self.streaming = false;
        self.bus.lock().streaming.remove(&self.path);
        Ok(())
    }

    fn query_control(&mut self, id: u32) -> Result<Option<ControlInfo>, Errno> {
        Ok(self.camera.controls.get(&id).cloned())
    }

    fn control(&mut self, id: u32) -> Result<i32, Errno> {
        let info = self.camera.controls.get(&id).ok_or(Errno::EINVAL)?;
        Ok(*self.values.get(&id).unwrap_or(&info.default_value))
    }

    fn set_control(&mut self, id: u32, value: i32) -> Result<(), Errno> {
        let info = self.camera.controls.get(&id).ok_or(Errno::EINVAL)?;
        if value < info.minimum || value > info.maximum {
            return Err(Errno::ERANGE);
        }
        self.values.insert(id, value);
        self.log(|l| l.controls_set.push((id, value)));
        Ok(())
    }

    fn poll_fd(&self) -> Option<RawFd> {
        None
    }
}

impl Drop for FakeDevice {
    fn drop(&mut self) {
        let _ = self.stream_off();
    }
}
