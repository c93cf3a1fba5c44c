//! hvs actuator: turns motion decisions into Parallax Servo Controller commands on a serial
//! port, never driving on a stale decision.
//!
//! - [`psc`]: the byte protocol;
//! - [`commander`]: coalescing, watchdog and pacing, as a pure state machine;
//! - [`link`]: the serial port itself (`serialport`), with the `!SCVER?` link check.

pub mod commander;
pub mod link;
pub mod psc;

pub use commander::{Commander, DecisionInput, Outgoing};
pub use link::{LinkError, PscLink};
