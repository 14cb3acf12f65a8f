#![allow(clippy::needless_range_loop)] // numeric kernels index several parallel arrays
//! `garment_sim`: measured-parameter woven-fabric cloth simulation (Charfi 2006)
//! advanced by the Baraff–Witkin implicit solver at a fixed time step.
//!
//! Layers (data flows one way): [`fabric`] (KES data → laws) and [`cloth`]
//! (the warp/weft grid) feed [`solver`] (forces, Jacobians, implicit step),
//! which [`collision`] constrains; [`scene`] builds it all from YAML;
//! [`run`] writes shapes, curves and summaries; [`capture`] reads and
//! writes motion captures (C3D, CSV), [`lab`] runs the thesis experiments
//! and [`plot`] draws their curves as PNG; [`render`] draws pictures of a
//! drape.

pub mod bag;
pub mod capture;
pub mod cloth;
pub mod collision;
pub mod fabric;
pub mod lab;
pub mod plot;
pub mod render;
pub mod ros;
pub mod run;
pub mod scene;
pub mod solver;
