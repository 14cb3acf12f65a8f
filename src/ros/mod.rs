//! The ROS 2 node (ros2-client on RustDDS): ROS command-line arguments
//! ([`args`]), the node's parameters ([`params`]), obstacles and pins from
//! messages ([`control`]), what the node logs about them without ever
//! waiting on its log ([`intake`]), the node itself ([`node`]) and its DDS
//! Security from the environment ([`security`]). The messages it exchanges,
//! and what it publishes, are built by [`crate::msgs`], which the bags
//! share. The physics never depends on this module.

pub mod args;
pub mod body;
pub mod control;
pub mod intake;
pub mod node;
pub mod params;
pub mod security;
