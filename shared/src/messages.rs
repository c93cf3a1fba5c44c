//! Message payloads exchanged between the hvs processes.
//!
//! Every payload is a fixed-size `#[repr(C)]` struct with no padding (checked at compile time by
//! `bytemuck::Pod`), written in place into an iceoryx2 shared-memory sample and never serialised.
//! Each carries an explicit iceoryx2 type name (`hvs::...`) so that a C, C++ or Python iceoryx2
//! client can open the service by name and read the bytes; `docs/ipc.md` documents the layout
//! field by field, and the tests in this module pin the sizes and offsets it states.
//!
//! Conventions: times are `CLOCK_MONOTONIC` nanoseconds (`*_ns`), distances metres (`*_m`),
//! disparities in 1/256 px (`*_q8`, 0 = invalid, the KITTI convention), enums are `u32` codes
//! (see the `*::from_code` helpers), text is NUL-padded UTF-8 in fixed byte arrays.

use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

pub use crate::codes::{
    ControlCommand, FrameSource, IntersectionType, LogLevel, MotionCommand, NavPolicy, RangeSource,
    RowAlignState, SendReason, StageHealth, StageState, StereoAlgorithm,
};

/// Width of the fast-path (low-resolution) images in pixels.
pub const LO_WIDTH: usize = 320;
/// Height of the fast-path (low-resolution) images in pixels.
pub const LO_HEIGHT: usize = 240;
/// Pixel count of one fast-path image.
pub const LO_PIXELS: usize = LO_WIDTH * LO_HEIGHT;
/// Width of the long-range (high-resolution) images in pixels.
pub const HI_WIDTH: usize = 640;
/// Height of the long-range (high-resolution) images in pixels.
pub const HI_HEIGHT: usize = 480;
/// Pixel count of one long-range image.
pub const HI_PIXELS: usize = HI_WIDTH * HI_HEIGHT;
/// Fixed-point scale of disparities in [`DisparityMap320x240`] and [`DisparityMap640x480`]:
/// stored value = disparity in px x 256; 0 = invalid.
pub const DISPARITY_SCALE: f32 = 256.0;
/// Number of range windows a [`RangeReport`] can hold.
pub const MAX_RANGE_WINDOWS: usize = 5;
/// Number of column bins of an [`ObstacleScan`] (5 px each at 320x240, 10 at 640x480).
pub const SCAN_BINS: usize = 64;
/// Length of the fixed name fields (stage names).
pub const NAME_LEN: usize = 32;
/// Maximum number of stages a [`SupervisorStatus`] lists.
pub const MAX_STAGES: usize = 12;
/// Length of a stage's free-text status note (heartbeat and status entry), bytes.
pub const NOTE_LEN: usize = 128;

/// Encodes `name` into a NUL-padded fixed array, truncating at a UTF-8 boundary if too long.
pub fn encode_name<const N: usize>(name: &str) -> [u8; N] {
    let mut out = [0u8; N];
    let mut len = name.len().min(N);
    while !name.is_char_boundary(len) {
        len -= 1;
    }
    out[..len].copy_from_slice(&name.as_bytes()[..len]);
    out
}

/// Decodes a NUL-padded fixed array written by [`encode_name`]; invalid UTF-8 yields `"?"`.
pub fn decode_name(bytes: &[u8]) -> &str {
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    core::str::from_utf8(&bytes[..end]).unwrap_or("?")
}

/// Payloads that carry a monotonically increasing sequence number (frame id or heartbeat
/// counter); subscribers use it to count samples lost to overflow.
pub trait Sequenced {
    /// The sequence number of this sample.
    fn sequence(&self) -> u64;
}

/// Header of a stereo frame pair (72 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::FrameHeader")]
pub struct FrameHeader {
    /// Capture counter; the 320x240 and 640x480 pairs of one capture share the id.
    pub frame_id: u64,
    /// Capture time of the pair (the left exposure), CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    /// Capture time of the left image, CLOCK_MONOTONIC ns.
    pub left_capture_ns: u64,
    /// Capture time of the right image, CLOCK_MONOTONIC ns.
    pub right_capture_ns: u64,
    /// Right minus left capture time in ns (the two webcams are not synchronised).
    pub skew_ns: i64,
    /// Time the capture stage published the pair, CLOCK_MONOTONIC ns.
    pub published_ns: u64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// [`FrameSource`] code.
    pub source: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Replay only: the 640x480 frame whose ranges the recorded run fused with this frame
    /// ([`NO_HI_FRAME`]: none), so the fusion repeats the recorded choice instead of a
    /// timing-dependent one. 0 (live): the fusion takes the freshest long-range result.
    pub replay_hi_frame_id: u64,
}

/// [`FrameHeader::replay_hi_frame_id`] of a replayed frame the recorded run fused with no
/// long-range result.
pub const NO_HI_FRAME: u64 = u64::MAX;

macro_rules! stereo_frame {
    ($name:ident, $type_name:literal, $w:expr, $h:expr, $doc:literal) => {
        #[doc = $doc]
        ///
        /// Layout: a [`FrameHeader`] then the left and the right grey images, row-major,
        /// one byte per pixel, no row padding.
        #[repr(C)]
        #[derive(Debug, Clone, Copy, Pod, Zeroable, ZeroCopySend)]
        #[type_name($type_name)]
        pub struct $name {
            /// Frame metadata.
            pub header: FrameHeader,
            /// Left image, grey u8, row-major.
            pub left: [u8; $w * $h],
            /// Right image, grey u8, row-major.
            pub right: [u8; $w * $h],
        }

        impl $name {
            /// Image width in pixels.
            pub const WIDTH: usize = $w;
            /// Image height in pixels.
            pub const HEIGHT: usize = $h;
        }

        impl Sequenced for $name {
            fn sequence(&self) -> u64 {
                self.header.frame_id
            }
        }

        impl StereoPayload for $name {
            fn parts(&self) -> (&FrameHeader, &[u8], &[u8]) {
                (&self.header, &self.left, &self.right)
            }

            fn parts_mut(&mut self) -> (&mut FrameHeader, &mut [u8], &mut [u8]) {
                (&mut self.header, &mut self.left, &mut self.right)
            }
        }
    };
}

/// A stereo pair payload of either size.
pub trait StereoPayload: Pod {
    /// The header and the left and right images.
    fn parts(&self) -> (&FrameHeader, &[u8], &[u8]);
    /// The same, writable (filling a loaned sample).
    fn parts_mut(&mut self) -> (&mut FrameHeader, &mut [u8], &mut [u8]);
}

stereo_frame!(
    StereoFrame320x240,
    "hvs::StereoFrame320x240",
    LO_WIDTH,
    LO_HEIGHT,
    "A 320x240 grey stereo pair: the fast path (153 672 bytes)."
);
stereo_frame!(
    StereoFrame640x480,
    "hvs::StereoFrame640x480",
    HI_WIDTH,
    HI_HEIGHT,
    "A 640x480 grey stereo pair: the long-range path (614 472 bytes)."
);

/// Header of a disparity map (64 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::DisparityHeader")]
pub struct DisparityHeader {
    /// Id of the frame pair this map was computed from.
    pub frame_id: u64,
    /// Capture time of that pair, CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    /// Time the stereo stage took the pair, CLOCK_MONOTONIC ns.
    pub frame_received_ns: u64,
    /// Time the map was published, CLOCK_MONOTONIC ns.
    pub published_ns: u64,
    /// Matching time for this map in ns.
    pub compute_ns: u64,
    /// Map width in pixels.
    pub width: u32,
    /// Map height in pixels.
    pub height: u32,
    /// Smallest disparity searched, px.
    pub min_disp: u32,
    /// Largest disparity searched, px.
    pub max_disp: u32,
    /// [`StereoAlgorithm`] code.
    pub algorithm: u32,
    /// Number of pixels with a valid disparity.
    pub valid_px: u32,
    /// The tracked vertical offset between the cameras, 1/1000 px (the right image's content
    /// lies this far below the left's; 0 without an estimate).
    pub row_shift_mpx: i32,
    /// [`RowAlignState`] code.
    pub row_align: u32,
}

macro_rules! disparity_map {
    ($name:ident, $type_name:literal, $w:expr, $h:expr, $doc:literal) => {
        #[doc = $doc]
        ///
        /// Layout: a [`DisparityHeader`], then `disparity_q8`, row-major u16 (little endian on
        /// every supported target), disparity x 256 of each left-image pixel, 0 = invalid,
        /// then `confidence`, row-major u8, one per pixel.
        #[repr(C)]
        #[derive(Debug, Clone, Copy, Pod, Zeroable, ZeroCopySend)]
        #[type_name($type_name)]
        pub struct $name {
            /// Map metadata.
            pub header: DisparityHeader,
            /// Disparity of each left pixel in 1/256 px, 0 = invalid.
            pub disparity_q8: [u16; $w * $h],
            /// Confidence of each disparity, 0 (none) ..= 255 (certain), from the matcher's
            /// cost curve and left-right check (255 for every valid pixel of a matcher
            /// without one, and of the simulator's exact map).
            pub confidence: [u8; $w * $h],
        }

        impl $name {
            /// Map width in pixels.
            pub const WIDTH: usize = $w;
            /// Map height in pixels.
            pub const HEIGHT: usize = $h;
        }

        impl Sequenced for $name {
            fn sequence(&self) -> u64 {
                self.header.frame_id
            }
        }
    };
}

disparity_map!(
    DisparityMap320x240,
    "hvs::DisparityMap320x240",
    LO_WIDTH,
    LO_HEIGHT,
    "Disparity of the fast path's left image (153 664 bytes)."
);
disparity_map!(
    DisparityMap640x480,
    "hvs::DisparityMap640x480",
    HI_WIDTH,
    HI_HEIGHT,
    "Disparity of the long-range path's left image (614 464 bytes)."
);

/// The range seen in one vertical window of the image (24 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::RangeWindow")]
pub struct RangeWindow {
    /// Range estimate in metres (the configured statistic); 0 when no pixel is valid.
    pub range_m: f32,
    /// A low percentile of the window's ranges (nearest obstacle), metres.
    pub near_m: f32,
    /// Mean range (the reference statistic), metres.
    pub mean_m: f32,
    /// Edge pixels with a valid disparity in the window.
    pub valid_px: u32,
    /// Confidence in [0, 1] from the valid pixel count and the spread of ranges.
    pub confidence: f32,
    /// [`RangeSource`] code.
    pub source: u32,
}

/// The nearest obstacle in each of [`SCAN_BINS`] equal column bins of the image, left to right:
/// a laser-scan-like view of the disparity map (floor and ceiling left out) for obstacle
/// avoidance and the decision stage's local map (264 bytes).
///
/// Bin `i` looks along the direction whose tangent (left of the optical axis positive) is
/// `tan_half_fov * (1 - 2 * (i + 0.5) / SCAN_BINS)`; its `range_m` is the distance along the
/// optical axis (depth), so the point lies `range_m * tangent` to the left of the axis.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::ObstacleScan")]
pub struct ObstacleScan {
    /// `(width / 2) / focal_px` of the image the scan came from.
    pub tan_half_fov: f32,
    /// Bins filled from the 640x480 path (the fast path had no data there).
    pub hi_bins: u32,
    /// Depth of the bin's nearest obstacle (a low percentile of its points), metres; 0 = no
    /// data; [`SCAN_SCATTERED`] (negative) = the bin's points agree on no depth, as a
    /// surface nearer than the matcher's shortest range gives.
    pub range_m: [f32; SCAN_BINS],
}

/// `ObstacleScan::range_m` of a bin whose points scatter in depth (no surface the matcher
/// can range; most often one nearer than its shortest range). Negative, so every `r > 0`
/// check reads it as no data.
pub const SCAN_SCATTERED: f32 = -1.0;

impl Default for ObstacleScan {
    fn default() -> Self {
        Self::zeroed()
    }
}

impl ObstacleScan {
    /// Tangent of bin `i`'s viewing direction (left of the optical axis positive).
    pub fn bin_tangent(&self, i: usize) -> f64 {
        self.tan_half_fov as f64 * (1.0 - 2.0 * (i as f64 + 0.5) / SCAN_BINS as f64)
    }

    /// Bins with data.
    pub fn valid_bins(&self) -> usize {
        self.range_m.iter().filter(|&&r| r > 0.0).count()
    }

    /// Of the bins `bins`, those with data and those marked [`SCAN_SCATTERED`].
    pub fn valid_and_scattered(&self, bins: std::ops::Range<usize>) -> (usize, usize) {
        let slice = self.range_m.get(bins).unwrap_or(&[]);
        (
            slice.iter().filter(|&&r| r > 0.0).count(),
            slice.iter().filter(|&&r| r < 0.0).count(),
        )
    }
}

/// Ranges per vertical window for one fast-path frame, and the obstacle scan (440 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::RangeReport")]
pub struct RangeReport {
    /// Fast-path frame id.
    pub frame_id: u64,
    /// Capture time of that frame, CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    /// Time the report was published, CLOCK_MONOTONIC ns.
    pub published_ns: u64,
    /// Frame id of the 640x480 result fused in, 0 if none was fresh enough.
    pub hi_frame_id: u64,
    /// Age of that 640x480 result relative to this frame's capture, ns (0 if none).
    pub hi_age_ns: u64,
    /// Number of windows used (3 or 5).
    pub window_count: u32,
    /// Edge pixels in the fused map.
    pub edge_px: u32,
    /// Per-window ranges, left to right; entries past `window_count` are zero.
    pub windows: [RangeWindow; MAX_RANGE_WINDOWS],
    /// Edge pixels with a valid disparity in the whole fused map.
    pub valid_edge_px: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Nearest obstacle per column bin (fast path, gaps filled from a fresh 640x480 result).
    pub scan: ObstacleScan,
}

impl Sequenced for RangeReport {
    fn sequence(&self) -> u64 {
        self.frame_id
    }
}

/// One navigation decision per fast-path frame (64 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::Decision")]
pub struct Decision {
    /// Frame id the decision was made from.
    pub frame_id: u64,
    /// Capture time of that frame, CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    /// Time the decision was published, CLOCK_MONOTONIC ns.
    pub published_ns: u64,
    /// [`MotionCommand`] code.
    pub command: u32,
    /// [`IntersectionType`] code.
    pub intersection: u32,
    /// Membership in [0, 1] of "wall on the left".
    pub wall_left: f32,
    /// Membership in [0, 1] of "wall in front".
    pub wall_front: f32,
    /// Membership in [0, 1] of "wall on the right".
    pub wall_right: f32,
    /// Turn angle for turn commands, degrees (0 otherwise).
    pub turn_angle_deg: f32,
    /// PSC ramp value to use with the command (0..63).
    pub ramp: u32,
    /// [`NavPolicy`] code.
    pub policy: u32,
    /// Reserved, zero.
    pub reserved: [u32; 2],
}

impl Sequenced for Decision {
    fn sequence(&self) -> u64 {
        self.frame_id
    }
}

/// What the actuator wrote to the servo controller (72 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::ActuatorReport")]
pub struct ActuatorReport {
    /// Counter of reports from this actuator process.
    pub seq: u64,
    /// Time the last byte was handed to the serial port, CLOCK_MONOTONIC ns.
    pub sent_ns: u64,
    /// Frame id of the decision acted on (0 for neutral without a decision).
    pub decision_frame_id: u64,
    /// Capture time of that decision's frame, CLOCK_MONOTONIC ns (0 if none).
    pub decision_capture_ns: u64,
    /// Publication time of that decision, CLOCK_MONOTONIC ns (0 if none).
    pub decision_published_ns: u64,
    /// [`SendReason`] code.
    pub reason: u32,
    /// [`MotionCommand`] code of the motion sent.
    pub command: u32,
    /// Pulse width sent to the left wheels, 2 us units.
    pub left_pw: u16,
    /// Pulse width sent to the right wheels, 2 us units.
    pub right_pw: u16,
    /// Number of valid bytes in `bytes`.
    pub byte_count: u16,
    /// The PSC ramp of both wheel commands (0 = instant, larger = slower change), so that a
    /// reader need not decode the PSC bytes.
    pub ramp: u8,
    /// Zero.
    pub reserved: u8,
    /// The bytes written, both wheel commands (2 x 8 bytes).
    pub bytes: [u8; 16],
}

impl Sequenced for ActuatorReport {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

/// Per-stage heartbeat and counters, published about 10 times a second from the stage's main
/// loop, so a stage whose loop hangs stops beating (184 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::StageHeartbeat")]
pub struct StageHeartbeat {
    /// Heartbeat counter of this process.
    pub seq: u64,
    /// Time of this heartbeat, CLOCK_MONOTONIC ns.
    pub time_ns: u64,
    /// Process start time, CLOCK_MONOTONIC ns.
    pub started_ns: u64,
    /// Samples taken in since start.
    pub frames_in: u64,
    /// Samples published since start.
    pub frames_out: u64,
    /// Input samples lost to overflow since start (sequence gaps).
    pub drops: u64,
    /// Errors since start.
    pub errors: u64,
    /// Median processing latency over the last second, ns.
    pub latency_p50_ns: u64,
    /// 99th percentile processing latency over the last second, ns.
    pub latency_p99_ns: u64,
    /// Largest processing latency over the last second, ns.
    pub latency_max_ns: u64,
    /// Process id.
    pub pid: u32,
    /// [`StageHealth`] code.
    pub health: u32,
    /// Stage name, NUL-padded.
    pub stage: [u8; NAME_LEN],
    /// Free-text status note, NUL-padded (for example the device in use, or what the stage
    /// waits for: "no servo controller answers on /dev/ttyUSB0 (waiting 12 s)").
    pub note: [u8; NOTE_LEN],
}

impl Sequenced for StageHeartbeat {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

/// Ground truth published by the simulator for tests and reports (88 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::SimTruth")]
pub struct SimTruth {
    /// Counter of truth samples.
    pub seq: u64,
    /// Publication time, CLOCK_MONOTONIC ns.
    pub time_ns: u64,
    /// Simulated time since the simulator started, s.
    pub sim_time_s: f64,
    /// Robot x, metres (east).
    pub x_m: f64,
    /// Robot y, metres (north).
    pub y_m: f64,
    /// Robot heading, radians CCW from east.
    pub heading_rad: f64,
    /// Distance driven since start, metres.
    pub odometer_m: f64,
    /// Last frame id rendered.
    pub frame_id: u64,
    /// Servo-controller frames received.
    pub psc_frames: u64,
    /// Malformed servo-controller frames received.
    pub psc_malformed: u32,
    /// Collision events (rising edges) since start.
    pub collisions: u32,
    /// 1 while the robot touches a wall.
    pub in_collision: u32,
    /// Current left-wheel pulse width, 2 us units (0 = never commanded).
    pub left_pw: u16,
    /// Current right-wheel pulse width, 2 us units (0 = never commanded).
    pub right_pw: u16,
}

impl Sequenced for SimTruth {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

/// One stage as the supervisor sees it (96 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::StageStatusEntry")]
pub struct StageStatusEntry {
    /// Stage name, NUL-padded.
    pub stage: [u8; NAME_LEN],
    /// Samples taken in, summed over restarts.
    pub frames_in: u64,
    /// Samples published, summed over restarts.
    pub frames_out: u64,
    /// Input samples lost to overflow, summed over restarts.
    pub drops: u64,
    /// Median processing latency over the last second, ns.
    pub latency_p50_ns: u64,
    /// 99th percentile processing latency over the last second, ns.
    pub latency_p99_ns: u64,
    /// Current process id (0 if not running).
    pub pid: u32,
    /// [`StageState`] code.
    pub state: u32,
    /// Restarts since the supervisor started.
    pub restarts: u32,
    /// Output rate over the last status period, Hz.
    pub rate_hz: f32,
    /// Time since the last heartbeat, ms.
    pub heartbeat_age_ms: u32,
    /// Exit status of the last incarnation (-signal if killed, 0 if none yet).
    pub last_exit: i32,
    /// [`StageHealth`] code of the newest heartbeat (0 before the first).
    pub health: u32,
    /// Zero.
    pub reserved: u32,
    /// The newest heartbeat's note, NUL-padded.
    pub note: [u8; NOTE_LEN],
}

/// The supervisor's view of the whole pipeline, published once a second with history 1 so
/// `hvs status` and probes get it at once (2 840 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::SupervisorStatus")]
pub struct SupervisorStatus {
    /// Status counter.
    pub seq: u64,
    /// Publication time, CLOCK_MONOTONIC ns.
    pub time_ns: u64,
    /// Supervisor start time, CLOCK_MONOTONIC ns.
    pub started_ns: u64,
    /// Median capture-to-decision latency over the last period, ns.
    pub decision_latency_p50_ns: u64,
    /// 99th percentile capture-to-decision latency over the last period, ns.
    pub decision_latency_p99_ns: u64,
    /// Supervisor process id.
    pub supervisor_pid: u32,
    /// Number of valid entries in `stages`.
    pub stage_count: u32,
    /// 1 while shutting down.
    pub stopping: u32,
    /// Last [`MotionCommand`] code decided.
    pub last_command: u32,
    /// Stage entries.
    pub stages: [StageStatusEntry; MAX_STAGES],
}

impl Sequenced for SupervisorStatus {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

/// A control request (48 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::ControlRequest")]
pub struct ControlRequest {
    /// Request counter of the sender.
    pub seq: u64,
    /// Sender process id.
    pub sender_pid: u32,
    /// [`ControlCommand`] code.
    pub command: u32,
    /// Target stage for `Restart`, NUL-padded.
    pub stage: [u8; NAME_LEN],
}

impl Sequenced for ControlRequest {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

/// Bytes of text a [`LogLine`] carries (longer lines are cut at a UTF-8 boundary).
pub const LOG_TEXT_LEN: usize = 200;

/// One line a stage wrote to its standard error (its `tracing` output), as the supervisor
/// forwarded it (256 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::LogLine")]
pub struct LogLine {
    /// Counter of lines from this supervisor.
    pub seq: u64,
    /// Time the supervisor read the line, CLOCK_MONOTONIC ns.
    pub time_ns: u64,
    /// [`LogLevel`] code (0 when the line names none).
    pub level: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// The stage that wrote it, NUL-padded.
    pub stage: [u8; NAME_LEN],
    /// The line, NUL-padded UTF-8.
    pub text: [u8; LOG_TEXT_LEN],
}

impl Sequenced for LogLine {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

/// Cells per side of a [`NavMap`] (a square window centred near the robot).
pub const NAV_MAP_SIDE: usize = 128;
/// [`NavMap`] cell value of a cell never seen.
pub const NAV_MAP_UNKNOWN: u8 = 255;

/// The navigator's dead-reckoned pose, one per decision (56 bytes). The frame is the one
/// dead reckoning starts in: x ahead and y left of the start pose, heading counter-clockwise.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::RobotPose")]
pub struct RobotPose {
    /// Frame id of the decision this pose was used for.
    pub frame_id: u64,
    /// Capture time of that frame, CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    /// Time published, CLOCK_MONOTONIC ns.
    pub published_ns: u64,
    /// Position ahead of the start pose, metres.
    pub x_m: f64,
    /// Position left of the start pose, metres.
    pub y_m: f64,
    /// Heading from the start heading, counter-clockwise, radians.
    pub heading_rad: f64,
    /// Distance driven, metres.
    pub distance_m: f64,
}

impl Sequenced for RobotPose {
    fn sequence(&self) -> u64 {
        self.frame_id
    }
}

/// The navigator's map around the robot, a few times a second (16 432 bytes): row-major
/// cells from the corner `(origin_x_m, origin_y_m)` of the pose frame, x along a row; each
/// cell 0 (free) to 100 (occupied), or [`NAV_MAP_UNKNOWN`].
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::NavMap")]
pub struct NavMap {
    /// Counter of maps from this decision process.
    pub seq: u64,
    /// Capture time of the frame the map was last updated from, CLOCK_MONOTONIC ns.
    pub capture_ns: u64,
    /// Time published, CLOCK_MONOTONIC ns.
    pub published_ns: u64,
    /// x of the first cell's outer corner, metres.
    pub origin_x_m: f64,
    /// y of the first cell's outer corner, metres.
    pub origin_y_m: f64,
    /// Cell edge, metres.
    pub cell_m: f32,
    /// Cells per side ([`NAV_MAP_SIDE`]).
    pub side: u32,
    /// Occupancy per cell, row-major (row = y).
    pub cells: [u8; NAV_MAP_SIDE * NAV_MAP_SIDE],
}

impl Default for NavMap {
    fn default() -> Self {
        Self {
            seq: 0,
            capture_ns: 0,
            published_ns: 0,
            origin_x_m: 0.0,
            origin_y_m: 0.0,
            cell_m: 0.0,
            side: NAV_MAP_SIDE as u32,
            cells: [NAV_MAP_UNKNOWN; NAV_MAP_SIDE * NAV_MAP_SIDE],
        }
    }
}

impl Sequenced for NavMap {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

/// Topics one [`BridgeStats`] describes at most.
pub const MAX_BRIDGE_TOPICS: usize = 16;

/// One topic's traffic through the bridge since it started (96 bytes).
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::BridgeTopicStats")]
pub struct BridgeTopicStats {
    /// The topic (`frames/640x480`, or a ROS 2 topic name), NUL-padded.
    pub topic: [u8; NAME_LEN],
    /// 0: local to network; 1: network to local.
    pub direction: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Messages sent (out) or published into shared memory (in).
    pub messages: u64,
    /// Bytes of the contract type (before compression).
    pub raw_bytes: u64,
    /// Bytes on the wire (payload after compression).
    pub wire_bytes: u64,
    /// Messages dropped because the hand-over queue was full (in), or skipped by the rate
    /// limit (out).
    pub dropped: u64,
    /// Messages refused as malformed (in).
    pub rejected: u64,
    /// Sender-to-publication time, median of the last second, ns (in; 0 otherwise).
    pub hop_p50_ns: u64,
    /// The same, 99th percentile, ns.
    pub hop_p99_ns: u64,
}

/// The bridge's traffic, once a second (1 560 bytes).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable, ZeroCopySend)]
#[type_name("hvs::BridgeStats")]
pub struct BridgeStats {
    /// Counter of reports from this bridge process.
    pub seq: u64,
    /// Time of the report, CLOCK_MONOTONIC ns.
    pub time_ns: u64,
    /// zenoh peers (or routers, in client mode) connected now.
    pub peers: u32,
    /// Entries used in `topics`.
    pub topic_count: u32,
    /// Per topic.
    pub topics: [BridgeTopicStats; MAX_BRIDGE_TOPICS],
}

impl Default for BridgeStats {
    fn default() -> Self {
        Self::zeroed()
    }
}

impl Sequenced for BridgeStats {
    fn sequence(&self) -> u64 {
        self.seq
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{offset_of, size_of};

    #[test]
    fn sizes_match_docs_ipc_md() {
        assert_eq!(size_of::<FrameHeader>(), 72);
        assert_eq!(size_of::<BridgeTopicStats>(), 96);
        assert_eq!(size_of::<BridgeStats>(), 24 + 16 * 96);
        assert_eq!(size_of::<StereoFrame320x240>(), 72 + 2 * 76_800);
        assert_eq!(size_of::<StereoFrame640x480>(), 72 + 2 * 307_200);
        assert_eq!(size_of::<DisparityHeader>(), 72);
        assert_eq!(size_of::<DisparityMap320x240>(), 72 + 3 * 76_800);
        assert_eq!(size_of::<DisparityMap640x480>(), 72 + 3 * 307_200);
        assert_eq!(size_of::<RangeWindow>(), 24);
        assert_eq!(size_of::<RangeReport>(), 440);
        assert_eq!(size_of::<ObstacleScan>(), 264);
        assert_eq!(size_of::<Decision>(), 64);
        assert_eq!(size_of::<ActuatorReport>(), 72);
        assert_eq!(size_of::<StageHeartbeat>(), 248);
        assert_eq!(size_of::<SimTruth>(), 88);
        assert_eq!(size_of::<StageStatusEntry>(), 232);
        assert_eq!(size_of::<SupervisorStatus>(), 56 + 12 * 232);
        assert_eq!(size_of::<ControlRequest>(), 48);
        assert_eq!(size_of::<RobotPose>(), 56);
        assert_eq!(size_of::<LogLine>(), 256);
        assert_eq!(size_of::<NavMap>(), 48 + 128 * 128);
    }

    #[test]
    fn offsets_match_docs_ipc_md() {
        assert_eq!(offset_of!(FrameHeader, skew_ns), 32);
        assert_eq!(offset_of!(FrameHeader, width), 48);
        assert_eq!(offset_of!(FrameHeader, source), 56);
        assert_eq!(offset_of!(StereoFrame320x240, right), 72 + 76_800);
        assert_eq!(offset_of!(DisparityHeader, algorithm), 56);
        assert_eq!(offset_of!(RangeReport, windows), 48);
        assert_eq!(offset_of!(RangeReport, scan), 176);
        assert_eq!(offset_of!(ObstacleScan, range_m), 8);
        assert_eq!(offset_of!(Decision, command), 24);
        assert_eq!(offset_of!(ActuatorReport, reason), 40);
        assert_eq!(offset_of!(ActuatorReport, bytes), 56);
        assert_eq!(offset_of!(StageHeartbeat, pid), 80);
        assert_eq!(offset_of!(StageHeartbeat, stage), 88);
        assert_eq!(offset_of!(SimTruth, psc_malformed), 72);
        assert_eq!(offset_of!(SupervisorStatus, stages), 56);
        assert_eq!(offset_of!(RobotPose, x_m), 24);
        assert_eq!(offset_of!(NavMap, cells), 48);
    }

    #[test]
    fn names_round_trip_and_truncate_on_char_boundary() {
        let n: [u8; 8] = encode_name("stereo-lo");
        assert_eq!(decode_name(&n), "stereo-l");
        let n: [u8; 4] = encode_name("aé"); // 'é' is two bytes: "aé" fits exactly in 3
        assert_eq!(decode_name(&n), "aé");
        let n: [u8; 2] = encode_name("aé");
        assert_eq!(decode_name(&n), "a");
    }
}
