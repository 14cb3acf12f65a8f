//! The experiments of the thesis run on the simulator: the damping
//! identification from a motion capture (ch. 5), the virtual Kawabata lab
//! (§2.3.1, §4.5), the fitting of laws to KES curves (§3.4.2), the
//! drapemeter (§2.3.2), the cantilever bending test (Peirce; ASTM D1388),
//! and the comparison with a real drape: its 3D shape from photos (§6.3)
//! and the distance between two shapes (eq. 6.2).

pub mod cantilever;
pub mod compare;
pub mod drapemeter;
pub mod fit_kes;
pub mod identify;
pub mod kes_lab;
pub mod posit;
pub mod reconstruct;
