//! The ROS 2 side: message types laid out as their ROS 2 definitions
//! ([`msgs`]), the messages built from a simulation ([`publish`]), ROS
//! command-line arguments ([`args`]), the node's parameters ([`params`])
//! and the node itself ([`node`]).
//! The physics modules never depend on this one.

pub mod args;
pub mod control;
pub mod msgs;
pub mod node;
pub mod params;
pub mod publish;
