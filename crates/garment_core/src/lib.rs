#![allow(clippy::needless_range_loop)] // numeric kernels index several parallel arrays
//! The physics of `garment_sim`: measured-parameter woven fabric (Charfi 2006)
//! advanced by the Baraff–Witkin implicit solver at a fixed time step.
//!
//! Layers, bottom up: [`fabric`] (KES data → constitutive laws with
//! hysteresis), [`cloth`] (the warp/weft grid, its springs and hinges),
//! [`collision`] (obstacles; [`deforming`] the meshes among them that
//! move) and [`solver`] (forces, Jacobians, the implicit step); [`limits`] holds the plausibility bounds every input is checked
//! against. This crate reads no files and knows nothing of ROS, bags or the
//! command line: the `garment_sim` crate above it loads scenes and fabrics,
//! and runs the node, the bags and the lab.

pub mod bvh;
pub mod cloth;
pub mod collision;
pub mod conform;
pub mod deforming;
pub mod fabric;
pub mod garment;
pub mod limits;
pub mod plane;
pub mod self_contact;
pub mod set;
pub mod solver;
