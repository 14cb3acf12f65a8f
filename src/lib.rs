#![allow(clippy::needless_range_loop)] // numeric kernels index several parallel arrays
//! `garment_sim`: measured-parameter woven-fabric cloth simulation (Charfi 2006)
//! advanced by the Baraff–Witkin implicit solver at a fixed time step.
//!
//! Layers (data flows one way): the physics lives in the `garment_core`
//! crate, re-exported here as [`fabric`] (KES data → laws), [`cloth`] (the
//! warp/weft grid), [`collision`] (obstacles) and [`solver`] (forces,
//! Jacobians, implicit step); it reads no files. Above it: [`io`] reads
//! fabric files, KES curves and OBJ meshes, [`motion`] body motions (mesh
//! sequences, glTF skinned animations), [`scene`] builds a simulation
//! from YAML; [`run`] writes shapes, curves and summaries, [`system_file`] a
//! step's linear system for solvers outside it; [`capture`] reads
//! and writes motion captures (C3D, CSV), [`lab`] runs the thesis
//! experiments, [`plot`] draws their curves as PNG and [`render`] pictures
//! of a drape; [`msgs`] are the ROS 2 messages (types, schemas, built from a
//! simulation) that [`bag`] records as rosbag2 bags, [`ros`] (the ROS 2
//! node) publishes and [`live`] serves to Foxglove over its WebSocket
//! protocol. [`pattern`] reads garments (GarmentCode patterns and garment
//! files) that [`garment`] cuts and sews, and [`trial`] drapes on a body;
//! [`body_forces`] are the garment's force and pressure on that body.

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
pub mod scene;
pub mod trial;
