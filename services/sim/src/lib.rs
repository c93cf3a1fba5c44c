//! hvs simulator library: text maps, a raycast stereo renderer with ground-truth disparity,
//! webcam defects, a Parallax Servo Controller (PSC) emulator behind a pseudo-terminal, and a
//! skid-steer robot that drives through the map from the emulated PSC's pulse widths.
//!
//! The crate is pure logic plus OS pty handling; inter-process wiring lives in the binary.
//! Typical use: build a [`SimWorld`] from a [`GridMap`], serve its PSC on a [`PscPty`], and on
//! each camera tick call [`SimWorld::render`] with the [`SimClock`] time.

#![warn(missing_docs)]

pub mod defects;
pub mod map;
pub mod maze;
pub mod noise;
pub mod pngio;
pub mod psc;
pub mod pty;
pub mod render;
pub mod robot;
pub mod texture;
pub mod world;

pub use defects::{DefectsError, SimRng, WebcamDefects, sim_rng};
pub use map::{Face, GridMap, MapError, Pose, PoseParseError, RayHit, Vec2};
pub use maze::{MazeError, MazeOptions, generate_maze};
pub use noise::{SimMotionNoise, WheelNoise};
pub use pngio::{PngError, RenderSize, RenderToDirError, RenderedFiles, render_to_dir};
pub use psc::{
    PscCommand, PscCounters, PscEmulator, PscEvent, PscParser, SerialMismatch, SerialSettings,
};
pub use pty::{PscPty, PtyError, PtyStats, SimClock};
pub use render::{Eye, RenderError, Renderer, StereoRig, render_pair};
pub use robot::{Robot, RobotParams};
pub use world::{GroundTruth, SharedPsc, SimConfig, SimRenderError, SimWorld, lock_psc};
