//! The hvs IPC contract: everything the processes of a pipeline agree on, and nothing else
//! (no runtime, no configuration: a reader needs this crate, `bytemuck` and `iceoryx2`).
//!
//! - [`topics`]: every service, who publishes and who subscribes, and the stages. **Read this
//!   first**: it is the whole data flow of the robot in one file.
//! - [`messages`]: the fixed-size `#[repr(C)]` payloads written in place into shared memory
//!   (byte layout in `docs/ipc.md`).
//! - [`codes`]: the codes they carry, each enum declared once with its code and label.
//!
//! The runtime that stages share (configuration, iceoryx2 helpers, the stage skeleton) is the
//! `hvs-runtime` crate.

pub mod codes;
pub mod messages;
pub mod topics;
