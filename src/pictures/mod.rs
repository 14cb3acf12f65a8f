//! Pictures: drapes and fields on the cloth as PNG ([`render`]), curves as
//! PNG ([`plot`]).

pub mod glb;
pub mod plot;
pub mod render;
