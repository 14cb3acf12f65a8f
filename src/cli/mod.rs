//! The commands: each file parses its arguments, calls the library and
//! prints what it did.

pub mod bag;
pub mod bench;
pub mod drape;
pub mod identify;
pub mod lab;
pub mod recon;
pub mod trial;
