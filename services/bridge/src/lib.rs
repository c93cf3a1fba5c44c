//! The bridge stage: allow-listed hvs topics between this machine's iceoryx2 shared memory
//! and zenoh (another hvs machine, an operator station), and ROS 2 publications in
//! rmw_zenoh's wire format. docs/distributed.md walks through both setups.
//!
//! - [`session`]: the zenoh session from `[bridge]` (explicit endpoints, no multicast),
//! - [`wire`]: how an hvs sample travels (contract bytes, LZ4, a 32-byte attachment),
//! - [`check`]: what an incoming value must satisfy before it enters shared memory,
//! - [`queue`]: the newest-kept hand-over from zenoh's threads to the stage's thread,
//! - [`ports`]: one outgoing or incoming topic, with its counters,
//! - [`ros`]: rmw_zenoh keys, liveliness tokens, attachment, and CDR messages.

pub mod check;
pub mod ports;
pub mod queue;
pub mod ros;
pub mod session;
pub mod wire;
