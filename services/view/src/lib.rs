//! hvs view stage: the running robot for an operator, in Foxglove or Lichtblick over the
//! Foxglove WebSocket protocol (the `foxglove` crate's server) and in a web page served by
//! the same process. Read-only: clients subscribe, nothing they send reaches the pipeline.
//!
//! - [`channels`]: the Foxglove channels, their topics and schemas,
//! - [`encode`]: payloads to Foxglove messages (JPEG, colour maps, point cloud, grid, ...),
//! - [`worker`]: the encoder thread, fed by [`latest`] one-slot channels,
//! - [`health`]: the stage table, the simulator's truth, the legend and log lines,
//! - [`pacing`]: the per-channel rate limits,
//! - [`page`]: the web page and its HTTP server,
//! - [`client`]: a protocol client (tests and benchmarks),
//! - [`note`]: the stage's status note with its ports, written and read back.
//!
//! Nothing is encoded for a channel no client subscribes to.

pub mod channels;
pub mod client;
pub mod encode;
pub mod health;
pub mod latest;
pub mod note;
pub use hvs_runtime::pacing;
pub mod page;
pub mod worker;
