//! `[capture]`: where frames come from (simulator, V4L2 cameras, files, a recording).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::Invalid;

/// Frame sources.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CaptureSource {
    /// The built-in simulator's rendered camera (topic `sim/camera/640x480`).
    Sim,
    /// Two V4L2 devices: the Minoru stereo webcam (`[capture.v4l2]`).
    V4l2,
    /// A folder of left/right PNG pairs (`[capture.files]`).
    Files,
    /// An MCAP recording of `hvs probe record` / `hvs run --record` (`[capture.replay]`).
    Replay,
}

/// Where frames come from (docs/capture.md).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CaptureConfig {
    /// The frame source.
    pub source: CaptureSource,
    /// Capture width in pixels for the `v4l2` and `files` sources: 640 (both paths are fed,
    /// the 320x240 pair is downscaled from the 640x480 one) or 320 (the fast path only).
    pub width: u32,
    /// Capture height in pixels: 480 with width 640, 240 with width 320.
    pub height: u32,
    /// Optional stereo calibration (OpenCV `FileStorage` YAML) to rectify every pair with;
    /// relative paths are resolved against the config file's folder. Not used by `sim`.
    pub calibration: Option<PathBuf>,
    /// The Minoru's two V4L2 devices.
    pub v4l2: V4l2CaptureConfig,
    /// The PNG folder source.
    pub files: FilesCaptureConfig,
    /// The recording source.
    pub replay: ReplayCaptureConfig,
}

impl Default for CaptureConfig {
    fn default() -> Self {
        Self {
            source: CaptureSource::Sim,
            width: 640,
            height: 480,
            calibration: None,
            v4l2: V4l2CaptureConfig::default(),
            files: FilesCaptureConfig::default(),
            replay: ReplayCaptureConfig::default(),
        }
    }
}

/// Pixel formats requested from a V4L2 camera (both are converted to grey).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum V4l2PixelFormat {
    /// Packed YUV 4:2:2 (`YUYV`): the luma bytes are the grey image.
    Yuyv,
    /// Motion JPEG (`MJPG`): each frame is decoded to grey.
    Mjpeg,
}

/// The two V4L2 devices of the stereo webcam. The frame rate requested is `camera.fps`.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct V4l2CaptureConfig {
    /// Device of the left camera, e.g. `/dev/video0` (a stable `/dev/v4l/by-path/...` link
    /// is better: the numbering changes with the USB plug order).
    pub left_device: PathBuf,
    /// Device of the right camera.
    pub right_device: PathBuf,
    /// Pixel format requested from both cameras.
    pub pixel_format: V4l2PixelFormat,
    /// Largest accepted difference between the kernel timestamps of a left and a right
    /// frame, ms; frames with no partner this close are dropped.
    pub max_skew_ms: f64,
    /// Memory-mapped kernel buffers per camera (2..=16).
    pub buffers: u32,
    /// A camera that delivers no frame for this long is treated as disconnected, ms.
    pub stall_timeout_ms: u64,
    /// First delay before reopening a disconnected camera, ms (doubled after each failure).
    pub reconnect_backoff_ms: u64,
    /// Longest delay between reconnection attempts, ms.
    pub reconnect_max_backoff_ms: u64,
    /// Image controls locked to the same values on both cameras (unset: the cameras'
    /// automatic modes stay on).
    pub controls: V4l2Controls,
}

/// Power-line frequency for the cameras' anti-flicker filter.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum PowerLine {
    /// Filter off.
    Off,
    /// 50 Hz mains (Europe, most of Asia and Africa).
    #[serde(rename = "50hz")]
    Hz50,
    /// 60 Hz mains (the Americas, parts of Asia).
    #[serde(rename = "60hz")]
    Hz60,
}

/// V4L2 controls set on both cameras when the capture opens them. The reference blamed
/// flicker and unequal intensities for bad matches: with these set, both sensors expose,
/// amplify and white-balance alike.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct V4l2Controls {
    /// Manual exposure in the driver's unit (UVC: 100 us), automatic exposure off.
    pub exposure_100us: Option<i32>,
    /// Manual gain (driver units), automatic gain off.
    pub gain: Option<i32>,
    /// Manual white balance, kelvin, automatic white balance off.
    pub white_balance_k: Option<i32>,
    /// Anti-flicker filter for the mains frequency of the lights.
    pub power_line: Option<PowerLine>,
}

impl V4l2Controls {
    /// Checks plausible ranges (each camera's own range is checked when it is set).
    pub fn validate(&self) -> Result<(), Invalid> {
        if let Some(e) = self.exposure_100us
            && !(1..=100_000).contains(&e)
        {
            return Err(Invalid::new(
                "v4l2.controls.exposure_100us",
                format!("= {e} must be in 1..=100000 (0.1 ms .. 10 s)"),
            ));
        }
        if let Some(g) = self.gain
            && !(0..=10_000).contains(&g)
        {
            return Err(Invalid::new(
                "v4l2.controls.gain",
                format!("= {g} must be in 0..=10000"),
            ));
        }
        if let Some(k) = self.white_balance_k
            && !(1000..=12_000).contains(&k)
        {
            return Err(Invalid::new(
                "v4l2.controls.white_balance_k",
                format!("= {k} must be in 1000..=12000 kelvin"),
            ));
        }
        Ok(())
    }
}

impl Default for V4l2CaptureConfig {
    fn default() -> Self {
        Self {
            left_device: PathBuf::from("/dev/video0"),
            right_device: PathBuf::from("/dev/video2"),
            pixel_format: V4l2PixelFormat::Yuyv,
            max_skew_ms: 17.0,
            buffers: 4,
            stall_timeout_ms: 2000,
            reconnect_backoff_ms: 250,
            reconnect_max_backoff_ms: 5000,
            controls: V4l2Controls::default(),
        }
    }
}

/// A folder of left/right PNG pairs (`NAME_left.png` + `NAME_right.png`, or `left/NAME.png`
/// + `right/NAME.png`), played in name order.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FilesCaptureConfig {
    /// The folder (relative paths are resolved against the config file's folder).
    pub folder: PathBuf,
    /// Pairs per second, Hz; 0 = as fast as the pipeline takes them (the next pair is sent
    /// when the ranges of the previous one arrive, or after `lockstep_timeout_ms`).
    pub rate_hz: f64,
    /// Start again from the first pair after the last one (otherwise the stage stops).
    pub loop_playback: bool,
    /// With `rate_hz = 0`: longest wait for the pipeline's ranges before the next pair, ms.
    pub lockstep_timeout_ms: u64,
}

impl Default for FilesCaptureConfig {
    fn default() -> Self {
        Self {
            folder: PathBuf::from("frames"),
            rate_hz: 0.0,
            loop_playback: false,
            lockstep_timeout_ms: 1000,
        }
    }
}

/// A recording played back through the pipeline (docs/capture.md, "Replay").
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ReplayCaptureConfig {
    /// The MCAP file (relative paths are resolved against the config file's folder).
    pub file: PathBuf,
    /// Pairs per second, Hz; 0 = as fast as the pipeline takes them (lockstep: the next pair
    /// goes out when the decision on the previous one arrives). Only lockstep reproduces the
    /// recorded decisions exactly.
    pub rate_hz: f64,
    /// In lockstep: longest wait for the pipeline before the next pair, ms. Only a broken
    /// pipeline should reach it (a stage that died with the frame; the supervisor restarts
    /// it): going on early lets the next frame overtake the awaited one, and that decision is
    /// lost. The default is long because on a machine whose cores other programs keep busy
    /// the niced 640x480 worker took over 2 s for one frame, and a replay is not real-time.
    pub lockstep_timeout_ms: u64,
}

impl Default for ReplayCaptureConfig {
    fn default() -> Self {
        Self {
            file: PathBuf::from("run.mcap"),
            rate_hz: 0.0,
            lockstep_timeout_ms: 10_000,
        }
    }
}

impl CaptureConfig {
    /// Checks the section's values; the key of an error is below the section. Files and
    /// folders it names must exist for the source in use (relative to `base`, the config
    /// file's folder); camera devices may appear later and are checked by the capture stage.
    pub fn validate(&self, base: &Path) -> Result<(), Invalid> {
        let c = self;
        if c.source == CaptureSource::Sim {
            return Ok(());
        }
        if !matches!((c.width, c.height), (640, 480) | (320, 240)) {
            return Err(Invalid::new(
                "width",
                format!(
                    "width = {}, height = {}: the capture size must be 640x480 or 320x240",
                    c.width, c.height
                ),
            ));
        }
        if let Some(calibration) = &c.calibration {
            let path = super::resolve_path(base, calibration);
            if !path.is_file() {
                return Err(Invalid::new(
                    "calibration",
                    format!("names a file that does not exist: {}", path.display()),
                ));
            }
        }
        match c.source {
            CaptureSource::Sim => {}
            CaptureSource::V4l2 => {
                let v = &c.v4l2;
                v.controls.validate()?;
                for (key, device) in [
                    ("v4l2.left_device", &v.left_device),
                    ("v4l2.right_device", &v.right_device),
                ] {
                    if device.as_os_str().is_empty() {
                        return Err(Invalid::new(key, "must name a V4L2 device"));
                    }
                }
                if v.left_device == v.right_device {
                    return Err(Invalid::new(
                        "v4l2.right_device",
                        format!(
                            "= {} is also the left device; the two cameras need two devices",
                            v.right_device.display()
                        ),
                    ));
                }
                if !(v.max_skew_ms > 0.0 && v.max_skew_ms <= 1000.0) {
                    return Err(Invalid::new(
                        "v4l2.max_skew_ms",
                        format!("= {} must be in (0, 1000] ms", v.max_skew_ms),
                    ));
                }
                if !(2..=16).contains(&v.buffers) {
                    return Err(Invalid::new(
                        "v4l2.buffers",
                        format!("= {} must be in 2..=16", v.buffers),
                    ));
                }
                if !(100..=60_000).contains(&v.stall_timeout_ms) {
                    return Err(Invalid::new(
                        "v4l2.stall_timeout_ms",
                        format!("= {} must be in 100..=60000 ms", v.stall_timeout_ms),
                    ));
                }
                if v.reconnect_backoff_ms < 10
                    || v.reconnect_max_backoff_ms < v.reconnect_backoff_ms
                    || v.reconnect_max_backoff_ms > 600_000
                {
                    return Err(Invalid::new(
                        "v4l2.reconnect_max_backoff_ms",
                        format!(
                            "reconnect_backoff_ms = {} and reconnect_max_backoff_ms = {} need \
                             10 <= backoff <= max backoff <= 600000 ms",
                            v.reconnect_backoff_ms, v.reconnect_max_backoff_ms
                        ),
                    ));
                }
            }
            CaptureSource::Files => {
                let f = &c.files;
                let folder = super::resolve_path(base, &f.folder);
                if !folder.is_dir() {
                    return Err(Invalid::new(
                        "files.folder",
                        format!("names a folder that does not exist: {}", folder.display()),
                    ));
                }
                if !(0.0..=1000.0).contains(&f.rate_hz) {
                    return Err(Invalid::new(
                        "files.rate_hz",
                        format!(
                            "= {} must be in 0..=1000 Hz (0 = as fast as the pipeline takes them)",
                            f.rate_hz
                        ),
                    ));
                }
                if !(10..=60_000).contains(&f.lockstep_timeout_ms) {
                    return Err(Invalid::new(
                        "files.lockstep_timeout_ms",
                        format!("= {} must be in 10..=60000 ms", f.lockstep_timeout_ms),
                    ));
                }
            }
            CaptureSource::Replay => {
                let r = &c.replay;
                let file = super::resolve_path(base, &r.file);
                if !file.is_file() {
                    return Err(Invalid::new(
                        "replay.file",
                        format!("names a file that does not exist: {}", file.display()),
                    ));
                }
                if !(0.0..=1000.0).contains(&r.rate_hz) {
                    return Err(Invalid::new(
                        "replay.rate_hz",
                        format!(
                            "= {} must be in 0..=1000 Hz (0 = as fast as the pipeline takes them)",
                            r.rate_hz
                        ),
                    ));
                }
                if !(10..=60_000).contains(&r.lockstep_timeout_ms) {
                    return Err(Invalid::new(
                        "replay.lockstep_timeout_ms",
                        format!("= {} must be in 10..=60000 ms", r.lockstep_timeout_ms),
                    ));
                }
            }
        }
        Ok(())
    }
}
