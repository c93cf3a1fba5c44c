//! hvs actuator: turns motion decisions into Parallax Servo Controller commands on a serial
//! port, never driving on a stale decision.
//!
//! - [`psc`]: the byte protocol;
//! - [`commander`]: coalescing, watchdog and pacing, as a pure state machine;
//! - [`link`]: the serial port itself (`serialport`) as a non-blocking state machine
//!   (absent, probing with `!SCVER?`, up, lost).

pub mod commander;
pub mod link;
pub mod psc;

pub use commander::{Commander, DecisionInput, Outgoing};
pub use link::{LinkError, PscLink};
