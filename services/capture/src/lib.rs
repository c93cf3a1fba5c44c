//! hvs capture: turns camera output into the pipeline's stereo frames, with no IPC.
//!
//! One capture feeds both paths: the 640x480 pair for the long-range worker and a 320x240 pair
//! for the fast path, downscaled once, directly into the loaned shared-memory sample.
//!
//! - [`convert`]: YUYV and MJPEG to grey, the 2x downscale;
//! - [`pairing`]: matching two unsynchronised cameras' frames by kernel timestamp;
//! - [`v4l2`]: the Minoru's two UVC devices (hand-written V4L2 ioctls);
//! - [`files`]: a folder of left/right PNG pairs;
//! - [`calib`]: OpenCV stereo calibration files and the rectification remap;
//! - [`replay`]: an MCAP recording of the pipeline, played back;
//! - [`writer`]: writing pairs into the published frames (headers, remap, downscale);
//! - [`pacing`]: when the next pair goes out and when the cameras are tried again.
//!
//! The sources and their settings are described in `docs/capture.md`.

#![warn(missing_docs)]

pub mod calib;
pub mod convert;
pub mod files;
pub mod pacing;
pub mod pairing;
pub mod replay;
pub mod v4l2;
pub mod writer;

pub use convert::{ConvertError, downscale_2x};
