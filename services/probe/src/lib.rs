//! hvs probe: read-only inspection of a running pipeline from a separate process.
//!
//! A probe attaches to an instance's topics as an ordinary iceoryx2 subscriber with the
//! topics' own settings: every topic reserves subscriber slots for probes and uses safe
//! overflow, so a slow probe only loses samples itself and a killed one never stalls a
//! publisher. The commands (`hvs probe list|hz|echo|snapshot|top`, see `docs/probe.md`) are
//! wired in the `hvs` binary; this crate holds their logic:
//!
//! - [`rate`]: rate and period estimation from arrivals and sequence numbers,
//! - [`format`]: text and JSON of every message type,
//! - [`render`]: stereo pairs, colour-mapped disparity with a legend in metres, fused maps,
//! - [`top`]: the table of `hvs probe top`,
//! - [`schemas`]: the JSON messages and schemas of the live view and the recordings,
//! - [`attach`]: the IPC glue that attaches and runs each command.

pub mod attach;
pub mod format;
pub mod rate;
pub mod record;
pub mod render;
pub mod schemas;
pub mod top;

pub use attach::{
    AttachError, EchoError, EchoOptions, HzError, HzOptions, ListError, Probe, SnapshotError,
    SnapshotInfo, SnapshotOptions, TopError, TopOptions, TopicRow,
};
