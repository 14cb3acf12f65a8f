#![allow(clippy::needless_range_loop)] // numeric kernels index several parallel arrays
#![warn(missing_docs)]
//! The physics of `garment_sim`: measured-parameter woven fabric (Charfi 2006)
//! advanced by the Baraff–Witkin implicit solver at a fixed time step.
//!
//! Layers, bottom up: [`fabric`] (KES data → constitutive laws with
//! hysteresis), [`cloth`] (the warp/weft grid, its springs and hinges;
//! [`garment`] sews panels into one cloth), [`collision`] (obstacles;
//! [`deforming`] the meshes among them that move), [`self_contact`] (the
//! cloth against itself) and [`solver`] (forces, Jacobians, the implicit
//! step); [`limits`] holds the plausibility bounds every input is checked
//! against. This crate reads no files and knows nothing of ROS, bags or the
//! command line: the `garment_sim` crate above it loads scenes and fabrics,
//! and runs the node, the bags and the lab.
//!
//! What a user of the library needs is re-exported here: a [`Simulation`]
//! of a [`Cloth`] (a [`GridSpec`] rectangle, a [`PanelSpec`] outline, or a
//! [`Garment`] of [`PanelCut`]s sewn by [`SeamSpec`]s) of a [`Fabric`]
//! with its [`Params`], [`Obstacle`]s and [`Pin`]s added through it and
//! named by [`Handle`]s, and each step's [`StepStats`]. What fails returns an
//! [`Error`], whose variants are the kinds of failure. `examples/hang.rs`
//! hangs a square by two corners.

pub mod bvh;
pub mod cloth;
pub mod collision;
pub mod conform;
pub mod deforming;
mod error;
pub mod fabric;
pub mod garment;
pub mod limits;
pub mod plane;
pub mod self_contact;
pub mod set;
pub mod solver;

pub use cloth::{Border, Cloth, GridSpec, HingeLayout, Outline, PanelSpec};
pub use collision::{Obstacle, ShapeSpec};
pub use deforming::{DeformingBody, Keyframes, Motion};
pub use error::{Error, Result};
pub use fabric::{BehaviourSpec, Damping, DirectionSpec, Fabric, FabricFile, Law, LawState};
pub use garment::{Garment, PanelCut, SeamSpec};
pub use set::{Handle, Set};
pub use solver::{
    Energies, LinearSolverKind, Params, Pin, PinPath, Simulation, SolvedBy, StepStats,
};
