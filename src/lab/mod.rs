//! The experiments of the thesis run on the simulator: the damping
//! identification from a motion capture (ch. 5).

pub mod identify;
