//! ROS 2 without ROS: rmw_zenoh's key expressions, liveliness tokens and attachment, and the
//! CDR encoding of the messages the bridge publishes.

pub mod cdr;
pub mod graph;
pub mod messages;
pub mod publish;
