//! The hvs configuration file (TOML), shared by the supervisor and every stage.
//!
//! One file describes the whole pipeline; every process loads and validates all of it, so a
//! mistake is reported the same way wherever it is found. Unknown keys are errors (a typo must
//! not silently fall back to a default), and every error names the file and the key at fault.
//! Relative paths inside the file are resolved against the file's own directory.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use hvs_shared::messages::StereoAlgorithm;
use hvs_shared::topics::{self, Stage};

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not match the schema (unknown key, wrong type).
    #[error("config file {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// The parser's message, with line, column and key.
        message: String,
    },
    /// A value is out of range or inconsistent with another.
    #[error("config file {path}{}: `{key}` {message}", line_suffix(*.line))]
    Invalid {
        /// The file.
        path: PathBuf,
        /// Dotted key at fault, e.g. `stereo.lo.max_disp`.
        key: String,
        /// The line (1-based) that sets the key, when the file sets it (a default has none).
        line: Option<usize>,
        /// What is wrong with it.
        message: String,
    },
}

pub use hvs_shared::topics::STAGE_NAMES;

/// The whole configuration.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HvsConfig {
    /// Instance name: every service lives under `hvs/<instance>/`, so two pipelines (or
    /// parallel tests) never see each other. `[A-Za-z0-9_-]`, at most 32 characters.
    #[serde(default = "default_instance")]
    pub instance: String,
    /// Supervisor timing.
    #[serde(default)]
    pub supervisor: SupervisorConfig,
    /// Camera geometry and rate.
    #[serde(default)]
    pub camera: CameraConfig,
    /// Where frames come from.
    #[serde(default)]
    pub capture: CaptureConfig,
    /// Stereo matching for both paths.
    #[serde(default)]
    pub stereo: StereoPaths,
    /// Edges, fused map and ranges.
    #[serde(default)]
    pub fusion: FusionConfig,
    /// Walls, intersections and navigation.
    #[serde(default)]
    pub decision: DecisionConfig,
    /// The servo-controller link.
    #[serde(default)]
    pub actuator: ActuatorConfig,
    /// The simulated world.
    #[serde(default)]
    pub sim: SimConfig,
    /// Per-stage process settings, keyed by stage name (see [`STAGE_NAMES`]).
    #[serde(default)]
    pub stages: BTreeMap<String, StageOverride>,
    /// The file this configuration was loaded from (not part of the TOML).
    #[serde(skip)]
    pub source_path: PathBuf,
}

fn default_instance() -> String {
    "default".into()
}

/// Supervisor timing.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SupervisorConfig {
    /// A running stage that has not sent a heartbeat for this long is declared hung and killed.
    pub heartbeat_timeout_ms: u64,
    /// A new stage gets this long to send its first heartbeat.
    pub startup_timeout_ms: u64,
    /// Period of the status line and of the status topic.
    pub status_period_ms: u64,
    /// Grace time between SIGTERM and SIGKILL when stopping a stage.
    pub stop_timeout_ms: u64,
    /// Folder holding the stage binaries (default: the folder of the `hvs` executable).
    pub bin_dir: Option<PathBuf>,
}

impl Default for SupervisorConfig {
    fn default() -> Self {
        Self {
            heartbeat_timeout_ms: 1000,
            startup_timeout_ms: 10_000,
            status_period_ms: 1000,
            stop_timeout_ms: 2000,
            bin_dir: None,
        }
    }
}

/// Camera geometry and rate.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct CameraConfig {
    /// Frame rate, Hz.
    pub fps: f64,
    /// Focal length at 320x240 in pixels (doubled at 640x480).
    pub focal_px_320: f64,
    /// Stereo baseline in metres. (`focal_px_320 = 380`, `baseline_m = 0.0604` is the
    /// reference's profile: its printed ranges are `380 * 0.1982 ft / d`.)
    pub baseline_m: f64,
    /// Height of the optical centres above the floor, metres (level camera assumed): fusion
    /// uses it to drop floor and ceiling points.
    pub height_m: f64,
    /// Distance of the optical centres ahead of the robot's turning centre, metres (the
    /// decision stage's local map places what the camera sees with it).
    pub forward_m: f64,
}

impl Default for CameraConfig {
    fn default() -> Self {
        Self {
            fps: 30.0,
            focal_px_320: 320.0,
            baseline_m: 0.060,
            height_m: 0.25,
            forward_m: 0.20,
        }
    }
}

impl CameraConfig {
    /// Focal length in pixels at an image `width` (scaled from the 320x240 value).
    pub fn focal_px(&self, width: usize) -> f64 {
        self.focal_px_320 * width as f64 / 320.0
    }
}

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
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if let Some(e) = self.exposure_100us
            && !(1..=100_000).contains(&e)
        {
            return Err((
                "capture.v4l2.controls.exposure_100us",
                format!("= {e} must be in 1..=100000 (0.1 ms .. 10 s)"),
            ));
        }
        if let Some(g) = self.gain
            && !(0..=10_000).contains(&g)
        {
            return Err((
                "capture.v4l2.controls.gain",
                format!("= {g} must be in 0..=10000"),
            ));
        }
        if let Some(k) = self.white_balance_k
            && !(1000..=12_000).contains(&k)
        {
            return Err((
                "capture.v4l2.controls.white_balance_k",
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

/// Stereo settings of both paths.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct StereoPaths {
    /// The 320x240 fast path.
    pub lo: StereoConfig,
    /// The 640x480 long-range path.
    pub hi: StereoConfig,
}

impl Default for StereoPaths {
    fn default() -> Self {
        Self {
            lo: StereoConfig {
                min_disp: 9,
                max_disp: 55,
                ..StereoConfig::default()
            },
            hi: StereoConfig {
                min_disp: 18,
                max_disp: 110,
                ..StereoConfig::default()
            },
        }
    }
}

/// Stereo settings of one path. Every algorithm reads the common keys; `[...bm]`, `[...sgm]`
/// and `[...ogale]` hold the settings only that family uses.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct StereoConfig {
    /// The matching algorithm.
    pub algorithm: StereoAlgorithm,
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px (inclusive).
    pub max_disp: u32,
    /// Block size for block matching (odd, 3..=31).
    pub window: u32,
    /// Scale the right image so its mean equals the left's before matching (reference step 2).
    pub equalize: bool,
    /// Reject a match unless its cost is this many percent below every match more than one
    /// disparity away (0 disables).
    pub uniqueness_pct: u32,
    /// Left-right consistency check: the right image's disparity must agree within
    /// `lr_max_diff_px`.
    pub lr_check: bool,
    /// Allowed left-right disagreement, px.
    pub lr_max_diff_px: u32,
    /// Subpixel refinement of the winning disparity.
    pub subpixel: bool,
    /// Remove connected regions of at most this many pixels whose disparities differ from
    /// their surroundings (speckles; 0 disables).
    pub speckle_window_px: u32,
    /// Neighbouring disparities within this many px belong to the same region.
    pub speckle_range_px: u32,
    /// Fill runs of at most this many invalid pixels along a row with the farther of the
    /// disparities at their two ends, at confidence 1 (fusion leaves such pixels out; 0
    /// disables; sgm only).
    pub fill_invalid_px: u32,
    /// Block-matching settings.
    pub bm: BlockMatchConfig,
    /// Semi-global matching settings.
    pub sgm: SgmConfig,
    /// Ogale & Aloimonos settings.
    pub ogale: OgaleConfig,
    /// Online row alignment (the vertical offset between the cameras).
    pub row_align: RowAlignConfig,
}

/// Online row alignment before matching (services/stereo/src/rowalign.rs): the vertical
/// offset between the left and the right image is measured from the images, tracked over
/// frames and removed. With a calibration it measures the residual after rectification.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RowAlignConfig {
    /// Measure and correct the offset.
    pub enabled: bool,
    /// Largest offset searched, rows either way.
    pub max_shift_px: u32,
    /// Measure every this many frames (the tracked offset is applied to every frame).
    pub every_n_frames: u32,
    /// Warn when the tracked offset exceeds this, rows (the camera was knocked).
    pub warn_px: f32,
}

impl Default for RowAlignConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            max_shift_px: 6,
            every_n_frames: 4,
            warn_px: 2.0,
        }
    }
}

impl RowAlignConfig {
    /// Checks the ranges; `Err` carries the key (below the stereo section) and the message.
    pub fn validate(&self) -> Result<(), (&'static str, String)> {
        if !(1..=16).contains(&self.max_shift_px) {
            return Err((
                "row_align.max_shift_px",
                format!("= {} must be in 1..=16 rows", self.max_shift_px),
            ));
        }
        if !(1..=1000).contains(&self.every_n_frames) {
            return Err((
                "row_align.every_n_frames",
                format!("= {} must be in 1..=1000", self.every_n_frames),
            ));
        }
        if !(self.warn_px > 0.0 && self.warn_px <= 16.0) {
            return Err((
                "row_align.warn_px",
                format!("= {} must be in (0, 16] rows", self.warn_px),
            ));
        }
        Ok(())
    }
}

impl Default for StereoConfig {
    fn default() -> Self {
        Self {
            algorithm: StereoAlgorithm::Sgm,
            min_disp: 9,
            max_disp: 55,
            window: 15,
            equalize: true,
            uniqueness_pct: 5,
            lr_check: true,
            lr_max_diff_px: 1,
            subpixel: true,
            speckle_window_px: 40,
            speckle_range_px: 1,
            fill_invalid_px: 16,
            bm: BlockMatchConfig::default(),
            sgm: SgmConfig::default(),
            ogale: OgaleConfig::default(),
            row_align: RowAlignConfig::default(),
        }
    }
}

/// Settings of the block-matching family (`bm-sad`, `bm-ssd`, `bm-ncc`, `bm-census`).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct BlockMatchConfig {
    /// Minimum mean |horizontal gradient| of the left window, grey levels per pixel; flatter
    /// windows come out invalid rather than matched by chance (0 disables).
    pub texture_threshold: u32,
    /// Census window for `bm-census` (odd width x odd height, at most 32 comparisons).
    pub census_width: u32,
    /// Census window height.
    pub census_height: u32,
}

impl Default for BlockMatchConfig {
    fn default() -> Self {
        Self {
            texture_threshold: 0,
            census_width: 5,
            census_height: 5,
        }
    }
}

/// Settings of semi-global matching (`sgm`).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SgmConfig {
    /// Penalty for a disparity change of 1 px between neighbours, in matching-cost units
    /// (twice the mean census Hamming distance over the block: 0..=48).
    pub p1: u32,
    /// Penalty for larger disparity changes (at most 79, so that path costs fit a byte).
    pub p2: u32,
    /// Aggregation paths: 4, 5 or 8.
    pub paths: u32,
    /// Side of the square block the census costs are averaged over before the paths
    /// (1, 3, 5 or 7; OpenCV's `blockSize`): larger blocks resist noise and vertical
    /// misalignment, smaller ones keep thin structures.
    pub block: u32,
    /// Minimum mean |horizontal gradient| of the (prefiltered) left image around a pixel,
    /// grey levels per pixel; flatter pixels come out invalid rather than filled in by the
    /// paths (0 disables). Raise it for noisier cameras (see docs/stereo.md).
    pub texture_threshold: f32,
    /// Radius of the square window the texture is measured over, px.
    pub texture_radius: u32,
}

impl Default for SgmConfig {
    fn default() -> Self {
        Self {
            p1: 16,
            p2: 64,
            paths: 5,
            block: 5,
            texture_threshold: 0.25,
            texture_radius: 5,
        }
    }
}

/// Settings of the Ogale & Aloimonos matcher (`ogale`).
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OgaleConfig {
    /// Two pixels match at a shift when their (Birchfield-Tomasi) difference is at most this.
    pub match_threshold: u32,
    /// Horizontal stretch factors tried for slanted surfaces (1.0 = fronto-parallel).
    pub stretch: Vec<f32>,
    /// Cut vertical links where a horizontal edge separates two pixels.
    pub cut_horizontal_edges: bool,
    /// Vertical grey difference that counts as a horizontal edge.
    pub edge_threshold: u32,
}

impl Default for OgaleConfig {
    fn default() -> Self {
        Self {
            match_threshold: 4,
            stretch: vec![1.0],
            cut_horizontal_edges: true,
            edge_threshold: 8,
        }
    }
}

/// Range statistic over a window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RangeStatistic {
    /// Mean of the edge pixels' ranges (the reference).
    Mean,
    /// Median.
    Median,
    /// Mean of the middle 60 % (20 % trimmed off each end).
    TrimmedMean,
    /// The `near_percentile` percentile: the nearest obstacle, robust to a few outliers.
    Percentile,
}

/// Edge detector of the fusion stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum EdgeDetector {
    /// Canny (the reference): smoothing, Sobel, non-maximum suppression, hysteresis.
    Canny,
    /// Sobel magnitude above `canny_high` (the reference compared it and found it worse).
    Sobel,
}

/// Edges, fused map and ranges.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct FusionConfig {
    /// Edge detector.
    pub edges: EdgeDetector,
    /// Canny low threshold on the gradient magnitude (|gx| + |gy| of a 3x3 Sobel).
    pub canny_low: u32,
    /// Canny high threshold.
    pub canny_high: u32,
    /// Number of vertical windows: 3 or 5.
    pub windows: u32,
    /// Statistic reported as `range_m`.
    pub statistic: RangeStatistic,
    /// A 640x480 result older than this (relative to the fast-path frame) is not fused.
    pub hi_max_age_ms: u64,
    /// Percentile reported as `near_m` (and used by the `percentile` statistic), 0..=50.
    pub near_percentile: f64,
    /// Points lower than this above the floor are floor, not obstacles (0 disables).
    pub min_height_m: f64,
    /// Points higher than this above the floor are ignored (ceiling; 0 disables).
    pub max_height_m: f64,
    /// A fast-path window with fewer valid pixels than this takes a fresh 640x480 value
    /// instead (the fast path cannot see beyond its disparity range).
    pub min_valid_px: u32,
    /// Edge pixels whose disparity confidence (0..1, the stereo stage's plane) is below this
    /// are left out of the ranges; the others weigh by their confidence in the mean and in
    /// the window's confidence.
    pub min_confidence: f32,
}

impl Default for FusionConfig {
    fn default() -> Self {
        Self {
            edges: EdgeDetector::Canny,
            canny_low: 60,
            canny_high: 150,
            windows: 3,
            statistic: RangeStatistic::Mean,
            hi_max_age_ms: 300,
            near_percentile: 10.0,
            min_height_m: 0.05,
            max_height_m: 1.5,
            min_valid_px: 30,
            min_confidence: 0.05,
        }
    }
}

/// Wall thresholds for one resolution.
#[derive(Debug, Clone, Copy, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WallThresholds {
    /// Side wall present when the side range is below this, metres (reference `a`).
    pub side_m: f64,
    /// Front wall present when the middle range is below this, metres (reference `b`).
    pub front_m: f64,
}

/// Feet to metres.
pub const M_PER_FT: f64 = 0.3048;

/// Decision policies.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum DecisionPolicy {
    /// The reference: crisp thresholds, the table's first option, no memory.
    Reference,
    /// Fuzzy walls with hysteresis, the navigation table, visit memory (the default).
    Fuzzy,
    /// Kostavelis et al.: the window with the smallest disparity sum is the freest.
    MeanEstimation,
    /// Free ahead unless `threshold_rate_pct` of the middle window is nearer than the front
    /// threshold; otherwise toward the farther side.
    ThresholdEstimation,
}

/// Odometry model of the robot (dead reckoning from the pulses actually sent).
#[derive(Debug, Clone, Copy, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct OdometryConfig {
    /// Wheel speed at the forward pulses, m/s (reference: 0.274).
    pub forward_speed_mps: f64,
    /// Effective skid-steer track width, metres.
    pub track_m: f64,
    /// Motor time constant, seconds.
    pub motor_tau_s: f64,
}

impl Default for OdometryConfig {
    fn default() -> Self {
        Self {
            forward_speed_mps: 0.274,
            track_m: 0.55,
            motor_tau_s: 0.1,
        }
    }
}

/// Walls, intersections and navigation.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct DecisionConfig {
    /// The policy.
    pub policy: DecisionPolicy,
    /// Thresholds for the 320x240 ranges (reference: a = 2.35 ft, b = 2.4 ft).
    pub lo: WallThresholds,
    /// Thresholds for the 640x480 ranges (reference: a = 6.5 ft, b = 7 ft).
    pub hi: WallThresholds,
    /// Half-width of the fuzzy band around a threshold, as a fraction of it: membership
    /// falls from 1 to 0 over `threshold * (1 ± band)`.
    pub fuzzy_band: f64,
    /// Corridor rule: with the front open and both sides nearer than it, a side up to this
    /// many times `a` still counts as a wall (side windows see hallway walls obliquely).
    pub corridor_factor: f64,
    /// Weight of the newest frame in the smoothed memberships (1 = no smoothing).
    pub smoothing: f64,
    /// Frames a new command must persist before it replaces the current one (a blocked
    /// front acts at once).
    pub hold_frames: u32,
    /// Prefer the least visited branch at a junction (dead-reckoned visit grid).
    pub visit_memory: bool,
    /// Cell size of the visit grid, metres.
    pub visit_cell_m: f64,
    /// After a turn, drive at least this far before taking another branch, metres.
    pub commit_m: f64,
    /// Smallest turn executed, degrees (the reference's acos angle can be tiny).
    pub min_turn_deg: f64,
    /// Turns end on a multiple of this heading, degrees, and the heading is held on that axis
    /// while driving (indoor hallways meet at right angles); 0 turns by the reference's
    /// `acos` angle instead.
    pub snap_turn_deg: f64,
    /// Threshold estimation: share of the middle window that must be near to block it, %.
    pub threshold_rate_pct: f64,
    /// Odometry model for dead reckoning.
    pub odometry: OdometryConfig,
    /// Build the local occupancy map from the obstacle scans and use it (heading fix from the
    /// walls, centring, side openings, lining up with a branch, clearance before turning).
    /// Off by default until it passes every junction test (docs/navigation.md).
    pub local_map: bool,
    /// Share of the heading error read from the walls' directions that corrects dead
    /// reckoning each frame (walls meeting at right angles, `snap_turn_deg = 90`); 0 disables.
    pub heading_fix_gain: f64,
    /// Cell size of the local occupancy map built from the obstacle scans, metres.
    pub local_map_cell_m: f64,
    /// Seconds after which a local map cell is forgotten (dead reckoning drifts).
    pub local_map_age_s: f64,
    /// Keep this far from side walls seen in the local map, metres (lateral, from the robot's
    /// centre line).
    pub side_clearance_m: f64,
}

impl Default for DecisionConfig {
    fn default() -> Self {
        Self {
            policy: DecisionPolicy::Fuzzy,
            lo: WallThresholds {
                side_m: 2.35 * M_PER_FT,
                front_m: 2.4 * M_PER_FT,
            },
            hi: WallThresholds {
                side_m: 6.5 * M_PER_FT,
                front_m: 7.0 * M_PER_FT,
            },
            fuzzy_band: 0.065,
            corridor_factor: 1.34,
            smoothing: 0.5,
            hold_frames: 3,
            visit_memory: true,
            visit_cell_m: 0.35,
            commit_m: 0.5,
            min_turn_deg: 30.0,
            snap_turn_deg: 90.0,
            threshold_rate_pct: 20.0,
            odometry: OdometryConfig::default(),
            local_map: false,
            heading_fix_gain: 0.3,
            local_map_cell_m: 0.1,
            local_map_age_s: 20.0,
            side_clearance_m: 0.4,
        }
    }
}

/// Left/right pulse widths of one motion, in PSC units of 2 us.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PulsePair {
    /// Left wheels.
    pub left: u16,
    /// Right wheels.
    pub right: u16,
}

/// The motion table: pulse widths per motion (reference values measured on the robot).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PulseTable {
    /// Wheels stopped.
    pub neutral: PulsePair,
    /// Straight ahead.
    pub forward: PulsePair,
    /// Turn left.
    pub left: PulsePair,
    /// Turn right.
    pub right: PulsePair,
    /// Back up.
    pub reverse: PulsePair,
}

impl Default for PulseTable {
    fn default() -> Self {
        Self {
            neutral: PulsePair {
                left: 760,
                right: 758,
            },
            forward: PulsePair {
                left: 720,
                right: 800,
            },
            left: PulsePair {
                left: 920,
                right: 840,
            },
            right: PulsePair {
                left: 600,
                right: 510,
            },
            reverse: PulsePair {
                left: 800,
                right: 716,
            },
        }
    }
}

/// The servo-controller link.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActuatorConfig {
    /// Serial device, e.g. `/dev/ttyUSB0`; `sim` means the simulator's pty for this instance.
    pub device: String,
    /// Baud rate: the PSC speaks 2400 (or 38400).
    pub baud: u32,
    /// Neutral is sent when the newest decision is older than this.
    pub watchdog_ms: u64,
    /// PSC channel of the left wheels.
    pub left_channel: u8,
    /// PSC channel of the right wheels.
    pub right_channel: u8,
    /// Pulse widths per motion.
    pub pulses: PulseTable,
    /// Ask `!SCVER?` when the link opens and require an answer.
    pub link_check: bool,
}

impl Default for ActuatorConfig {
    fn default() -> Self {
        Self {
            device: "sim".into(),
            baud: 2400,
            watchdog_ms: 300,
            left_channel: 1,
            right_channel: 5,
            pulses: PulseTable::default(),
            link_check: true,
        }
    }
}

/// Webcam defects the simulator can add.
#[derive(Debug, Clone, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields, default)]
pub struct SimDefects {
    /// Gain applied to the right image.
    pub gain: f32,
    /// Offset added to the right image, grey levels.
    pub offset: f32,
    /// Gaussian noise on both images, grey levels (sigma).
    pub noise_sigma: f32,
    /// Vertical misalignment of the right image, px.
    pub vertical_shift_px: i32,
    /// The right image is taken this much later than the left, ms (unsynchronised capture).
    pub right_delay_ms: f64,
}

impl Default for SimDefects {
    fn default() -> Self {
        Self {
            gain: 1.0,
            offset: 0.0,
            noise_sigma: 0.0,
            vertical_shift_px: 0,
            right_delay_ms: 0.0,
        }
    }
}

/// The simulated world.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Map file (relative to the config file).
    pub map: PathBuf,
    /// Random seed for noise.
    pub seed: u64,
    /// Webcam defects.
    pub defects: SimDefects,
}

impl Default for SimConfig {
    fn default() -> Self {
        Self {
            map: PathBuf::from("maps/maze.txt"),
            seed: 1,
            defects: SimDefects::default(),
        }
    }
}

/// When the supervisor restarts a stage.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum RestartPolicy {
    /// After any exit or hang.
    Always,
    /// After a non-zero exit, a signal or a hang; a clean exit stays stopped.
    OnFailure,
    /// Never.
    Never,
}

/// Per-stage settings in `[stages.<name>]`; every field is optional.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct StageOverride {
    /// Start this stage at all.
    pub enabled: Option<bool>,
    /// Restart policy.
    pub restart: Option<RestartPolicy>,
    /// Program to run (a path, or a name looked up in the supervisor's bin dir).
    pub program: Option<String>,
    /// Extra arguments appended to the standard ones.
    pub args: Option<Vec<String>>,
    /// First restart delay, ms (doubles after each failure).
    pub backoff_ms: Option<u64>,
    /// Largest restart delay, ms.
    pub max_backoff_ms: Option<u64>,
    /// Give up after this many restarts within `restart_window_s`.
    pub max_restarts: Option<u32>,
    /// Window for `max_restarts`, seconds.
    pub restart_window_s: Option<u64>,
    /// CPU niceness of the process (-20..=19; higher = lower priority). The 640x480 worker
    /// defaults to 10 so that it only uses what the fast path leaves.
    pub nice: Option<i32>,
    /// A stage silent this long is declared hung and restarted, ms (default
    /// `supervisor.heartbeat_timeout_ms`, and at least [`NICED_HEARTBEAT_TIMEOUT_MS`] for a
    /// stage with a positive `nice`). The actuator's should be short: while it hangs the
    /// servo controller holds the last pulses.
    pub heartbeat_timeout_ms: Option<u64>,
}

/// A stage's resolved process settings.
#[derive(Debug, Clone, PartialEq)]
pub struct StageSpec {
    /// The stage.
    pub stage: Stage,
    /// Its name ([`Stage::name`]).
    pub name: String,
    /// Program name or path.
    pub program: String,
    /// Extra arguments.
    pub args: Vec<String>,
    /// Whether it is started.
    pub enabled: bool,
    /// Restart policy.
    pub restart: RestartPolicy,
    /// First restart delay, ms.
    pub backoff_ms: u64,
    /// Largest restart delay, ms.
    pub max_backoff_ms: u64,
    /// Restart budget within the window.
    pub max_restarts: u32,
    /// Window for the restart budget, seconds.
    pub restart_window_s: u64,
    /// CPU niceness.
    pub nice: i32,
    /// Hang bound, ms.
    pub heartbeat_timeout_ms: u64,
}

/// The default hang bound of a stage with a positive niceness (the 640x480 worker), ms. On
/// a machine whose cores other programs keep busy, a niced stage gets a small share of them
/// (nice 10 weighs about a tenth of nice 0) and one 640x480 frame can take over a second of
/// wall time: with the general 1 s bound it was restarted as hung while it was working. It
/// feeds nothing the robot waits for (fusion ages its results out after `hi_max_age_ms`).
pub const NICED_HEARTBEAT_TIMEOUT_MS: u64 = 5000;

impl HvsConfig {
    /// Reads, parses and validates a config file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and validates config text; `path` is used for messages and relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Self, ConfigError> {
        let mut config: HvsConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_path_buf(),
            message: e.to_string().trim_end().to_string(),
        })?;
        config.source_path = path.to_path_buf();
        config.validate()?;
        Ok(config)
    }

    /// The error for `key` (dotted, from the top of the file), with the line of the file
    /// that sets it.
    pub fn invalid(&self, key: &str, message: impl Into<String>) -> ConfigError {
        let line = std::fs::read_to_string(&self.source_path)
            .ok()
            .and_then(|text| key_line(&text, key));
        ConfigError::Invalid {
            path: self.source_path.clone(),
            key: key.into(),
            line,
            message: message.into(),
        }
    }

    /// Checks ranges and cross-field consistency.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if let Err(message) = validate_instance_name(&self.instance) {
            return Err(self.invalid("instance", message));
        }
        let s = &self.supervisor;
        for (key, value) in [
            ("supervisor.heartbeat_timeout_ms", s.heartbeat_timeout_ms),
            ("supervisor.startup_timeout_ms", s.startup_timeout_ms),
            ("supervisor.status_period_ms", s.status_period_ms),
            ("supervisor.stop_timeout_ms", s.stop_timeout_ms),
        ] {
            if value < 100 {
                return Err(self.invalid(key, format!("= {value} is too short (minimum 100)")));
            }
        }
        let c = &self.camera;
        if !(c.fps > 0.0 && c.fps <= 120.0) {
            return Err(self.invalid("camera.fps", format!("= {} must be in (0, 120]", c.fps)));
        }
        if !(c.focal_px_320 > 10.0 && c.focal_px_320 < 10_000.0) {
            return Err(self.invalid(
                "camera.focal_px_320",
                format!("= {} must be in (10, 10000)", c.focal_px_320),
            ));
        }
        if !(c.baseline_m > 0.001 && c.baseline_m < 2.0) {
            return Err(self.invalid(
                "camera.baseline_m",
                format!("= {} must be in (0.001, 2) metres", c.baseline_m),
            ));
        }
        if !(0.0..10.0).contains(&c.height_m) {
            return Err(self.invalid(
                "camera.height_m",
                format!("= {} must be in [0, 10) metres", c.height_m),
            ));
        }
        if !(-2.0..=2.0).contains(&c.forward_m) {
            return Err(self.invalid(
                "camera.forward_m",
                format!("= {} must be in [-2, 2] metres", c.forward_m),
            ));
        }
        // The `[stereo.*]` sections are checked by the matchers' own rules
        // (`hvs_stereo::validate_section`, run by `hvs check`, `hvs run` and `hvs doctor`).
        let f = &self.fusion;
        if f.windows != 3 && f.windows != 5 {
            return Err(self.invalid("fusion.windows", format!("= {} must be 3 or 5", f.windows)));
        }
        if f.canny_low >= f.canny_high {
            return Err(self.invalid(
                "fusion.canny_low",
                format!(
                    "= {} must be below canny_high = {}",
                    f.canny_low, f.canny_high
                ),
            ));
        }
        if !(0.0..=1.0).contains(&self.fusion.min_confidence) {
            return Err(self.invalid(
                "fusion.min_confidence",
                format!("= {} must be in 0..=1", self.fusion.min_confidence),
            ));
        }
        if !(0.0..=50.0).contains(&f.near_percentile) {
            return Err(self.invalid(
                "fusion.near_percentile",
                format!("= {} must be in 0..=50", f.near_percentile),
            ));
        }
        if f.min_height_m < 0.0
            || f.max_height_m < 0.0
            || (f.max_height_m > 0.0 && f.max_height_m <= f.min_height_m)
        {
            return Err(self.invalid(
                "fusion.max_height_m",
                format!(
                    "min_height_m = {} and max_height_m = {} must be >= 0 with max above min (0 disables)",
                    f.min_height_m, f.max_height_m
                ),
            ));
        }
        for (key, t) in [
            ("decision.lo", self.decision.lo),
            ("decision.hi", self.decision.hi),
        ] {
            if !(t.side_m > 0.0 && t.front_m > 0.0) {
                return Err(self.invalid(key, "thresholds must be positive metres"));
            }
        }
        let d = &self.decision;
        for (key, value, lo, hi) in [
            ("decision.fuzzy_band", d.fuzzy_band, 0.0, 0.5),
            ("decision.corridor_factor", d.corridor_factor, 1.0, 4.0),
            ("decision.smoothing", d.smoothing, 0.01, 1.0),
            ("decision.visit_cell_m", d.visit_cell_m, 0.05, 5.0),
            ("decision.heading_fix_gain", d.heading_fix_gain, 0.0, 1.0),
            ("decision.local_map_cell_m", d.local_map_cell_m, 0.02, 1.0),
            ("decision.local_map_age_s", d.local_map_age_s, 0.1, 3600.0),
            ("decision.side_clearance_m", d.side_clearance_m, 0.0, 5.0),
            ("decision.commit_m", d.commit_m, 0.0, 10.0),
            ("decision.min_turn_deg", d.min_turn_deg, 0.0, 90.0),
            ("decision.snap_turn_deg", d.snap_turn_deg, 0.0, 90.0),
            (
                "decision.threshold_rate_pct",
                d.threshold_rate_pct,
                0.0,
                100.0,
            ),
            (
                "decision.odometry.forward_speed_mps",
                d.odometry.forward_speed_mps,
                0.001,
                10.0,
            ),
            ("decision.odometry.track_m", d.odometry.track_m, 0.01, 10.0),
            (
                "decision.odometry.motor_tau_s",
                d.odometry.motor_tau_s,
                0.0,
                10.0,
            ),
        ] {
            if !(lo..=hi).contains(&value) {
                return Err(self.invalid(key, format!("= {value} must be in {lo}..={hi}")));
            }
        }
        if d.hold_frames > 100 {
            return Err(self.invalid(
                "decision.hold_frames",
                format!("= {} must be at most 100", d.hold_frames),
            ));
        }
        let a = &self.actuator;
        if a.device.is_empty() {
            return Err(self.invalid("actuator.device", "must name a serial device or `sim`"));
        }
        if !matches!(a.baud, 2400 | 38400) {
            return Err(self.invalid(
                "actuator.baud",
                format!("= {} is not a PSC rate (2400 or 38400)", a.baud),
            ));
        }
        if !(50..=5000).contains(&a.watchdog_ms) {
            return Err(self.invalid(
                "actuator.watchdog_ms",
                format!("= {} must be in 50..=5000", a.watchdog_ms),
            ));
        }
        for (key, ch) in [
            ("actuator.left_channel", a.left_channel),
            ("actuator.right_channel", a.right_channel),
        ] {
            if ch > 15 {
                return Err(self.invalid(key, format!("= {ch} is not a PSC channel (0..=15)")));
            }
        }
        if a.left_channel == a.right_channel {
            return Err(self.invalid("actuator.right_channel", "must differ from left_channel"));
        }
        let p = &a.pulses;
        for (name, pair) in [
            ("neutral", p.neutral),
            ("forward", p.forward),
            ("left", p.left),
            ("right", p.right),
            ("reverse", p.reverse),
        ] {
            for (side, pw) in [("left", pair.left), ("right", pair.right)] {
                if !(250..=1250).contains(&pw) {
                    return Err(self.invalid(
                        &format!("actuator.pulses.{name}.{side}"),
                        format!("= {pw} is outside the PSC range 250..=1250"),
                    ));
                }
            }
        }
        let d = &self.sim.defects;
        if !(d.gain > 0.0 && d.gain < 4.0) {
            return Err(self.invalid(
                "sim.defects.gain",
                format!("= {} must be in (0, 4)", d.gain),
            ));
        }
        if !(0.0..=64.0).contains(&d.noise_sigma) {
            return Err(self.invalid(
                "sim.defects.noise_sigma",
                format!("= {} must be in 0..=64", d.noise_sigma),
            ));
        }
        if d.vertical_shift_px.abs() > 8 {
            return Err(self.invalid(
                "sim.defects.vertical_shift_px",
                format!("= {} must be within +-8", d.vertical_shift_px),
            ));
        }
        if !(0.0..=1000.0).contains(&d.right_delay_ms) {
            return Err(self.invalid(
                "sim.defects.right_delay_ms",
                format!("= {} must be in 0..=1000", d.right_delay_ms),
            ));
        }
        self.validate_capture()?;
        self.validate_stage_names()?;
        self.validate_flow()?;
        Ok(())
    }

    fn validate_stage_names(&self) -> Result<(), ConfigError> {
        for (name, o) in &self.stages {
            if !STAGE_NAMES.contains(&name.as_str()) {
                return Err(self.invalid(
                    &format!("stages.{name}"),
                    format!("is not a stage; known stages: {}", STAGE_NAMES.join(", ")),
                ));
            }
            if let Some(p) = &o.program
                && p.trim().is_empty()
            {
                return Err(self.invalid(&format!("stages.{name}.program"), "is empty"));
            }
            if let Some(n) = o.nice
                && !(-20..=19).contains(&n)
            {
                return Err(self.invalid(
                    &format!("stages.{name}.nice"),
                    format!("= {n} must be in -20..=19"),
                ));
            }
            if let Some(t) = o.heartbeat_timeout_ms
                && t < 200
            {
                return Err(self.invalid(
                    &format!("stages.{name}.heartbeat_timeout_ms"),
                    format!("= {t} is too short (minimum 200: stages beat every 100 ms)"),
                ));
            }
            if o.max_restarts == Some(0) && o.restart.is_some_and(|r| r != RestartPolicy::Never) {
                return Err(self.invalid(
                    &format!("stages.{name}.max_restarts"),
                    "= 0 contradicts a restart policy; use restart = \"never\"",
                ));
            }
        }
        if self.stage_enabled("sim") {
            let map = self.resolve_path(&self.sim.map);
            if !map.is_file() {
                return Err(self.invalid(
                    "sim.map",
                    format!("names a map file that does not exist: {}", map.display()),
                ));
            }
        }
        Ok(())
    }

    /// The pre-start check of the data flow ([`topics::STAGE_INPUTS`]): a frame source
    /// exists, every enabled stage's inputs have an enabled publisher, the actuator's device
    /// can exist. Errors name the keys to change.
    fn validate_flow(&self) -> Result<(), ConfigError> {
        let source = self.capture.source;
        for input in topics::STAGE_INPUTS {
            if !self.stage_enabled(input.stage) {
                continue;
            }
            if input.stage == "capture" && source != CaptureSource::Sim {
                continue;
            }
            let capture_size = format!("{}x{}", self.capture.width, self.capture.height);
            let hi_published = matches!(source, CaptureSource::Sim | CaptureSource::Replay)
                || capture_size == "640x480";
            if input.topic == topics::FRAMES_HI.path
                && self.stage_enabled("capture")
                && !hi_published
            {
                return Err(self.invalid(
                    "stages.stereo-hi.enabled",
                    format!(
                        "stereo-hi reads {} but capture.width = {}, height = {} publishes only {}; \
                         set [stages.stereo-hi] enabled = false, or capture at 640x480",
                        input.topic,
                        self.capture.width,
                        self.capture.height,
                        topics::FRAMES_LO.path
                    ),
                ));
            }
            if self.stage_enabled(input.publisher) {
                continue;
            }
            let message = if input.stage == "capture" {
                format!(
                    "capture.source = \"sim\" reads {} from the sim stage, but [stages.sim] \
                     enabled = false: no stage produces a frame (enable the sim stage, or set \
                     capture.source to \"v4l2\", \"files\" or \"replay\")",
                    input.topic
                )
            } else {
                format!(
                    "{} reads {}, which only {} publishes, and [stages.{}] enabled = false \
                     (enable {}, or disable {})",
                    input.stage,
                    input.topic,
                    input.publisher,
                    input.publisher,
                    input.publisher,
                    input.stage
                )
            };
            return Err(self.invalid(&format!("stages.{}.enabled", input.publisher), message));
        }
        if self.stage_enabled("actuator") {
            let device = self.actuator.device.trim();
            if device == "sim" && !self.stage_enabled("sim") {
                return Err(self.invalid(
                    "actuator.device",
                    "= \"sim\" opens the simulator's serial port, but [stages.sim] enabled = \
                     false; name the real device (e.g. \"/dev/ttyUSB0\") or enable the sim stage",
                ));
            }
        }
        Ok(())
    }

    /// Checks the `[capture]` section (files and folders it names must exist for the source
    /// in use; camera devices may appear later and are checked by the capture stage).
    fn validate_capture(&self) -> Result<(), ConfigError> {
        let c = &self.capture;
        if c.source == CaptureSource::Sim {
            return Ok(());
        }
        if !matches!((c.width, c.height), (640, 480) | (320, 240)) {
            return Err(self.invalid(
                "capture.width",
                format!(
                    "width = {}, height = {}: the capture size must be 640x480 or 320x240",
                    c.width, c.height
                ),
            ));
        }
        if let Some(calibration) = &c.calibration {
            let path = self.resolve_path(calibration);
            if !path.is_file() {
                return Err(self.invalid(
                    "capture.calibration",
                    format!("names a file that does not exist: {}", path.display()),
                ));
            }
        }
        match c.source {
            CaptureSource::Sim => {}
            CaptureSource::V4l2 => {
                let v = &c.v4l2;
                if let Err((key, message)) = v.controls.validate() {
                    return Err(self.invalid(key, message));
                }
                for (key, device) in [
                    ("capture.v4l2.left_device", &v.left_device),
                    ("capture.v4l2.right_device", &v.right_device),
                ] {
                    if device.as_os_str().is_empty() {
                        return Err(self.invalid(key, "must name a V4L2 device"));
                    }
                }
                if v.left_device == v.right_device {
                    return Err(self.invalid(
                        "capture.v4l2.right_device",
                        format!(
                            "= {} is also the left device; the two cameras need two devices",
                            v.right_device.display()
                        ),
                    ));
                }
                if !(v.max_skew_ms > 0.0 && v.max_skew_ms <= 1000.0) {
                    return Err(self.invalid(
                        "capture.v4l2.max_skew_ms",
                        format!("= {} must be in (0, 1000] ms", v.max_skew_ms),
                    ));
                }
                if !(2..=16).contains(&v.buffers) {
                    return Err(self.invalid(
                        "capture.v4l2.buffers",
                        format!("= {} must be in 2..=16", v.buffers),
                    ));
                }
                if !(100..=60_000).contains(&v.stall_timeout_ms) {
                    return Err(self.invalid(
                        "capture.v4l2.stall_timeout_ms",
                        format!("= {} must be in 100..=60000 ms", v.stall_timeout_ms),
                    ));
                }
                if v.reconnect_backoff_ms < 10
                    || v.reconnect_max_backoff_ms < v.reconnect_backoff_ms
                    || v.reconnect_max_backoff_ms > 600_000
                {
                    return Err(self.invalid(
                        "capture.v4l2.reconnect_max_backoff_ms",
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
                let folder = self.resolve_path(&f.folder);
                if !folder.is_dir() {
                    return Err(self.invalid(
                        "capture.files.folder",
                        format!("names a folder that does not exist: {}", folder.display()),
                    ));
                }
                if !(0.0..=1000.0).contains(&f.rate_hz) {
                    return Err(self.invalid(
                        "capture.files.rate_hz",
                        format!(
                            "= {} must be in 0..=1000 Hz (0 = as fast as the pipeline takes them)",
                            f.rate_hz
                        ),
                    ));
                }
                if !(10..=60_000).contains(&f.lockstep_timeout_ms) {
                    return Err(self.invalid(
                        "capture.files.lockstep_timeout_ms",
                        format!("= {} must be in 10..=60000 ms", f.lockstep_timeout_ms),
                    ));
                }
            }
            CaptureSource::Replay => {
                let r = &c.replay;
                let file = self.resolve_path(&r.file);
                if !file.is_file() {
                    return Err(self.invalid(
                        "capture.replay.file",
                        format!("names a file that does not exist: {}", file.display()),
                    ));
                }
                if !(0.0..=1000.0).contains(&r.rate_hz) {
                    return Err(self.invalid(
                        "capture.replay.rate_hz",
                        format!(
                            "= {} must be in 0..=1000 Hz (0 = as fast as the pipeline takes them)",
                            r.rate_hz
                        ),
                    ));
                }
                if !(10..=60_000).contains(&r.lockstep_timeout_ms) {
                    return Err(self.invalid(
                        "capture.replay.lockstep_timeout_ms",
                        format!("= {} must be in 10..=60000 ms", r.lockstep_timeout_ms),
                    ));
                }
            }
        }
        Ok(())
    }

    /// Resolves a path from the file against the file's directory.
    pub fn resolve_path(&self, p: &Path) -> PathBuf {
        if p.is_absolute() {
            return p.to_path_buf();
        }
        let base = self.source_path.parent().unwrap_or(Path::new("."));
        base.join(p)
    }

    /// Replaces the frame source with the recording `file` (`hvs run --replay`): the
    /// simulator and the actuator are off unless `[stages.*]` enables them (there is no robot
    /// to drive; the recorded actuator output feeds the decision's dead reckoning).
    /// A relative `file` is taken from the current folder (a command-line path).
    pub fn use_replay(&mut self, file: &Path) -> Result<(), ConfigError> {
        self.capture.source = CaptureSource::Replay;
        self.capture.replay.file = std::path::absolute(file).unwrap_or_else(|_| file.to_path_buf());
        self.validate()
    }

    /// Whether a stage is enabled (default: all, `sim` only with the sim capture source, and
    /// `actuator` not in a replay).
    pub fn stage_enabled(&self, stage: &str) -> bool {
        let default = match Stage::from_name(stage) {
            Some(Stage::Sim) => self.capture.source == CaptureSource::Sim,
            Some(Stage::Actuator) => self.capture.source != CaptureSource::Replay,
            _ => true,
        };
        self.stages
            .get(stage)
            .and_then(|o| o.enabled)
            .unwrap_or(default)
    }

    /// The resolved process settings of every known stage, in start order.
    pub fn stage_specs(&self) -> Vec<StageSpec> {
        Stage::ALL
            .into_iter()
            .map(|stage| {
                let name = stage.name();
                let o = self.stages.get(name).cloned().unwrap_or_default();
                let nice = o
                    .nice
                    .unwrap_or(if stage == Stage::StereoHi { 10 } else { 0 });
                StageSpec {
                    stage,
                    name: name.to_string(),
                    program: o
                        .program
                        .unwrap_or_else(|| stage.default_program().to_string()),
                    args: o.args.unwrap_or_default(),
                    enabled: self.stage_enabled(name),
                    restart: o.restart.unwrap_or(RestartPolicy::Always),
                    backoff_ms: o.backoff_ms.unwrap_or(200),
                    max_backoff_ms: o.max_backoff_ms.unwrap_or(5000),
                    max_restarts: o.max_restarts.unwrap_or(10),
                    restart_window_s: o.restart_window_s.unwrap_or(60),
                    nice,
                    heartbeat_timeout_ms: o.heartbeat_timeout_ms.unwrap_or(if nice > 0 {
                        self.supervisor
                            .heartbeat_timeout_ms
                            .max(NICED_HEARTBEAT_TIMEOUT_MS)
                    } else {
                        self.supervisor.heartbeat_timeout_ms
                    }),
                }
            })
            .collect()
    }

    /// The stereo settings for a stage name (`stereo-lo` or `stereo-hi`).
    pub fn stereo_for(&self, stage: &str) -> Option<&StereoConfig> {
        match Stage::from_name(stage)? {
            Stage::StereoLo => Some(&self.stereo.lo),
            Stage::StereoHi => Some(&self.stereo.hi),
            _ => None,
        }
    }
}

/// `":N"` for line `N`, nothing without one.
fn line_suffix(line: Option<usize>) -> String {
    line.map(|n| format!(":{n}")).unwrap_or_default()
}

/// The line (1-based) of `text` that sets the dotted `key` (`stereo.lo.sgm.p2`): under its
/// table header (`[stereo.lo.sgm]`) or as a dotted key under a parent table (`sgm.p2 = ...`
/// under `[stereo.lo]`). A plain line scan, not a TOML parser: it is used only to point at
/// a key in an error message, after the file has parsed, and gives `None` when unsure.
pub fn key_line(text: &str, key: &str) -> Option<usize> {
    let mut table = String::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if let Some(header) = line.strip_prefix('[') {
            table = header.trim_end_matches(']').trim().replace(' ', "");
            continue;
        }
        let Some((name, _)) = line.split_once('=') else {
            continue;
        };
        let name = name.trim().replace(' ', "");
        let full = if table.is_empty() {
            name
        } else {
            format!("{table}.{name}")
        };
        if full == key {
            return Some(i + 1);
        }
    }
    None
}

/// Checks an instance name: `[A-Za-z0-9_-]`, 1 to 32 characters.
pub fn validate_instance_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > 32 {
        return Err(format!("= {name:?} must have 1 to 32 characters"));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(format!(
            "= {name:?} contains {c:?}; use letters, digits, '-' and '_'"
        ));
    }
    Ok(())
}

/// Per-instance run folder for files that are not shared memory (the simulator's pty link,
/// the supervisor lock): `$HVS_RUN_DIR/<instance>` or `/tmp/hvs-<uid>/<instance>`.
pub fn run_dir(instance: &str) -> PathBuf {
    let base = std::env::var_os("HVS_RUN_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(format!("/tmp/hvs-{}", nix::unistd::getuid())));
    base.join(instance)
}

/// Path of the simulator's pty link for an instance (what `actuator.device = "sim"` opens).
pub fn sim_pty_path(instance: &str) -> PathBuf {
    run_dir(instance).join("psc-sim")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<HvsConfig, ConfigError> {
        // The sim's map from the repository, so that a file in a folder that does not exist
        // is still a whole, runnable config.
        let map = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/maps/maze.txt");
        let text = format!("{text}\n[sim]\nmap = \"{map}\"\n");
        HvsConfig::parse(&text, Path::new("/nonexistent/test.toml"))
    }

    #[test]
    fn empty_file_gives_defaults() {
        let c = parse("").expect("defaults are valid");
        assert_eq!(c.instance, "default");
        assert_eq!(c.stereo.lo.min_disp, 9);
        assert_eq!(c.stereo.hi.max_disp, 110);
        assert!((c.decision.lo.side_m - 0.71628).abs() < 1e-6);
        assert_eq!(c.stage_specs().len(), STAGE_NAMES.len());
    }

    #[test]
    fn unknown_key_is_named_with_its_line() {
        let err = parse("[stereo.lo]\nmin_disp = 9\nmax_dsip = 55\n").unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("max_dsip"), "{msg}");
        assert!(msg.contains("line 3"), "{msg}");
        assert!(msg.contains("/nonexistent/test.toml"), "{msg}");
    }

    #[test]
    fn wrong_type_is_named() {
        let err = parse("[camera]\nfps = \"fast\"\n").unwrap_err().to_string();
        assert!(err.contains("fps"), "{err}");
        assert!(err.contains("line 2"), "{err}");
    }

    #[test]
    fn key_line_finds_keys_under_headers_and_dotted() {
        let text = "instance = \"x\"\n[stereo.lo]\nmin_disp = 2 # near\nsgm.p2 = 64\n\n[ stereo.lo.sgm ]\np1 = 16\n[fusion]\nwindows=3\n";
        assert_eq!(key_line(text, "instance"), Some(1));
        assert_eq!(key_line(text, "stereo.lo.min_disp"), Some(3));
        assert_eq!(key_line(text, "stereo.lo.sgm.p2"), Some(4));
        assert_eq!(key_line(text, "stereo.lo.sgm.p1"), Some(7));
        assert_eq!(key_line(text, "fusion.windows"), Some(9));
        assert_eq!(key_line(text, "stereo.hi.min_disp"), None);
        assert_eq!(key_line(text, "min_disp"), None);
    }

    #[test]
    fn unknown_stage_is_rejected() {
        let err = parse("[stages.stero-lo]\nrestart = \"never\"\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("stages.stero-lo"), "{err}");
        assert!(err.contains("stereo-lo"), "{err}");
    }

    #[test]
    fn missing_map_file_is_named() {
        let err = HvsConfig::parse(
            "[sim]\nmap = \"maps/nope.txt\"\n",
            Path::new("/nonexistent/dir/sim.toml"),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("sim.map"), "{err}");
        assert!(err.contains("/nonexistent/dir/maps/nope.txt"), "{err}");
    }

    #[test]
    fn bad_instance_name_is_rejected() {
        let err = parse("instance = \"a/b\"").unwrap_err().to_string();
        assert!(err.contains("instance"), "{err}");
    }

    #[test]
    fn pulses_outside_psc_range_are_rejected() {
        let err = parse("[actuator.pulses.forward]\nleft = 100\nright = 800\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("actuator.pulses.forward.left"), "{err}");
    }

    #[test]
    fn capture_defaults_to_sim_and_parses_v4l2() {
        let c = parse("").unwrap();
        assert_eq!(c.capture.source, CaptureSource::Sim);
        let c = parse(
            "[capture]\nsource = \"v4l2\"\nwidth = 320\nheight = 240\n\
             [capture.v4l2]\nleft_device = \"/dev/video4\"\nright_device = \"/dev/video6\"\n\
             pixel_format = \"mjpeg\"\nmax_skew_ms = 10\n\
             [actuator]\ndevice = \"/dev/ttyUSB0\"\n[stages.stereo-hi]\nenabled = false\n",
        )
        .unwrap();
        assert_eq!(c.capture.source, CaptureSource::V4l2);
        assert_eq!(c.capture.v4l2.pixel_format, V4l2PixelFormat::Mjpeg);
        assert_eq!(c.capture.v4l2.left_device, PathBuf::from("/dev/video4"));
        assert!((c.capture.v4l2.max_skew_ms - 10.0).abs() < 1e-9);
        assert!(!c.stage_enabled("sim"));
    }

    #[test]
    fn minoru_example_config_is_valid() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/minoru.toml");
        let c = HvsConfig::load(&path).expect("config/minoru.toml must stay valid");
        assert_eq!(c.capture.source, CaptureSource::V4l2);
        assert!(!c.stage_enabled("sim"));
    }

    #[test]
    fn capture_values_are_checked_by_key() {
        for (text, key) in [
            (
                "[capture]\nsource = \"v4l2\"\nwidth = 800\n",
                "capture.width",
            ),
            (
                "[capture]\nsource = \"v4l2\"\n[capture.v4l2]\nmax_skew_ms = 0\n",
                "capture.v4l2.max_skew_ms",
            ),
            (
                "[capture]\nsource = \"v4l2\"\n[capture.v4l2]\nleft_device = \"/dev/a\"\nright_device = \"/dev/a\"\n",
                "capture.v4l2.right_device",
            ),
            (
                "[capture]\nsource = \"v4l2\"\n[capture.v4l2]\nbuffers = 1\n",
                "capture.v4l2.buffers",
            ),
            (
                "[capture]\nsource = \"files\"\n[capture.files]\nfolder = \"/nonexistent/pairs\"\n",
                "capture.files.folder",
            ),
            (
                "[capture]\nsource = \"v4l2\"\ncalibration = \"calib/none.yml\"\n",
                "capture.calibration",
            ),
        ] {
            let err = parse(text).unwrap_err().to_string();
            assert!(err.contains(key), "{key}: {err}");
        }
        let err = parse("[capture]\nsource = \"usb\"\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("usb"), "{err}");
        let err = parse("[capture.v4l2]\nmax_skew = 3\n")
            .unwrap_err()
            .to_string();
        assert!(err.contains("max_skew"), "{err}");
    }

    #[test]
    fn stage_overrides_apply() {
        let c = parse("[stages.fusion]\nrestart = \"on-failure\"\nmax_restarts = 2\n").unwrap();
        let fusion = c
            .stage_specs()
            .into_iter()
            .find(|s| s.name == "fusion")
            .unwrap();
        assert_eq!(fusion.restart, RestartPolicy::OnFailure);
        assert_eq!(fusion.max_restarts, 2);
        assert!(c.stage_enabled("sim"));
    }

    #[test]
    fn a_config_whose_stages_wait_on_nobody_is_refused_naming_the_keys() {
        let err = |text: &str| match parse(text) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(ConfigError::Invalid { key, message, .. }) => (key, message),
            Err(e) => panic!("{e}"),
        };
        let (key, message) = err("[stages.sim]\nenabled = false\n");
        assert_eq!(key, "stages.sim.enabled");
        assert!(message.contains("no stage produces a frame"), "{message}");
        let (key, message) = err("[stages.capture]\nenabled = false\n");
        assert_eq!(key, "stages.capture.enabled");
        assert!(
            message.starts_with("stereo-lo reads frames/320x240"),
            "{message}"
        );
        let (key, _) = err("[stages.fusion]\nenabled = false\n");
        assert_eq!(key, "stages.fusion.enabled");
        let (key, message) = err(
            "[capture]\nsource = \"v4l2\"\n[actuator]\ndevice = \"/dev/ttyUSB0\"\n\
             [capture.v4l2]\nleft_device = \"/dev/video4\"\n[capture.v4l2.controls]\n\
             exposure_100us = 0\n",
        );
        assert_eq!(key, "capture.v4l2.controls.exposure_100us", "{message}");
        let (key, message) = err("[capture]\nsource = \"v4l2\"\n");
        assert_eq!(key, "actuator.device");
        assert!(
            message.contains("[stages.sim] enabled = false"),
            "{message}"
        );
        // Off together: a pipeline without wheels or decisions is fine.
        parse("[stages.decision]\nenabled = false\n[stages.actuator]\nenabled = false\n")
            .expect("no decisions, no actuator");
    }
}
