//! The types the simulation and its element sets share: the state's
//! [`Energies`] and the [`Fabrics`] a per-vertex lookup sees.

use crate::fabric::Fabric;
use serde::Serialize;

/// Energies of the current state, J.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Energies {
    /// Kinetic.
    pub kinetic: f64,
    /// Gravity's potential, `−Σ m g·x` (zero at the origin).
    pub gravity: f64,
    /// Tension springs' elastic energy.
    pub tension: f64,
    /// Shear elements' elastic energy.
    pub shear: f64,
    /// Hinges' and guards' elastic energy.
    pub bending: f64,
    /// Seam stitches (garments).
    pub seam: f64,
    /// Work done so far by the Rayleigh damping forces (≥ 0 dissipated).
    pub dissipated_damping: f64,
}

impl Energies {
    /// Kinetic + potential (gravity and elastic).
    pub fn total(&self) -> f64 {
        self.kinetic + self.gravity + self.tension + self.shear + self.bending + self.seam
    }
}

/// A cloth's fabrics as a per-vertex lookup sees them: the first, the
/// others, and each vertex's index into them (empty: all the first). Every
/// spring and hinge lies within one panel and takes its vertices' fabric.
#[derive(Clone, Copy)]
pub(crate) struct Fabrics<'a> {
    pub first: &'a Fabric,
    pub others: &'a [Fabric],
    pub of: &'a [u16],
}

impl<'a> Fabrics<'a> {
    /// The fabric of vertex `v`.
    #[inline(always)]
    pub fn at(&self, v: usize) -> &'a Fabric {
        match self.of.get(v) {
            Some(&k) if k > 0 => &self.others[usize::from(k) - 1],
            _ => self.first,
        }
    }
}
