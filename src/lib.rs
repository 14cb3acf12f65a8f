#![allow(clippy::needless_range_loop)] // numeric kernels index several parallel arrays
//! `garment_sim`: measured-parameter woven-fabric cloth simulation (Charfi 2006)
//! advanced by the Baraff–Witkin implicit solver at a fixed time step.
//!
//! Layers (data flows one way): the physics lives in the `garment_core`
//! crate, re-exported here as [`fabric`] (KES data → laws), [`cloth`] (the
//! warp/weft grid), [`collision`] (obstacles) and [`solver`] (forces,
//! Jacobians, implicit step); it reads no files. Above it: [`io`] reads
//! fabric files, KES curves and OBJ meshes; [`scene`] builds a simulation
//! from YAML, runs it headless and writes its outputs (with body motions
//! and a step's linear system); [`trial`] runs a garment trial (patterns,
//! sewing, drape, dressing, the fit and the forces on the body) through one
//! run interface ([`trial::run_trial`]); [`lab`] runs the thesis'
//! experiments and [`capture`] reads and writes motion captures;
//! [`pictures`] draws drapes, fields and curves (PNG) and trials as glTF;
//! [`msgs`] are the ROS 2 messages that [`bag`] records as rosbag2 bags,
//! [`ros`] (the ROS 2 node) publishes and [`live`] serves to Foxglove over
//! its WebSocket protocol. The command line (`src/cli/`) parses, calls
//! these and prints.

pub use garment_core::{
    cloth, collision, deforming, fabric, garment, limits, self_contact, set, solver,
};

pub mod bag;
pub mod capture;
pub mod io;
pub mod lab;
pub mod live;
pub mod msgs;
pub mod pictures;
pub mod ros;
pub mod run;
pub mod scene;
pub mod trial;
