//! Plausibility bounds on what a scene file, the command line or a message
//! may ask of a simulation, in one place: the scene loader, the command line
//! and the node's `pins` and `obstacles` messages all check against these.
//! Each bound says its unit and why it is where it is; docs/limits.md lists
//! them for users. A value outside a bound is refused with the field named,
//! except a far pin target, which the pin reaches at [`PIN_TRAVEL_SPEED`]
//! (see [`crate::solver::PinPath::travel`]). The module depends on no other
//! part of the crate: the obstacles ([`crate::collision::Obstacle::check_overlap`])
//! and the solver use it.

use crate::error::{fail, Result};
use nalgebra::Vector3;

/// Fastest a pin may be asked to move, m/s. A hand or a robot gripper
/// handling cloth moves at a few m/s; 10 m/s leaves room for a flick while
/// refusing values that are a unit slip (mm/s sent as m/s) or noise.
pub const MAX_PIN_SPEED: f64 = 10.0;

/// Speed at which a pin travels in a straight line to a new target that is
/// farther from its vertex than one step at this speed, m/s. A target set
/// by a message is where the pin should go, not a jump: moving the vertex
/// there in one step stretches its springs by metres and the step's matrix
/// loses its positive definiteness. 2 m/s is a brisk hand movement.
pub const PIN_TRAVEL_SPEED: f64 = 2.0;

/// How far beyond the box around the cloth a pin target or an obstacle's
/// origin may lie, m. The cloth can only reach as far as its own size from
/// where it is; a target metres beyond that is a unit slip (mm sent as m)
/// or a wrong frame, and would drag the cloth at [`PIN_TRAVEL_SPEED`] for
/// seconds towards nothing.
pub const MAX_REACH: f64 = 2.0;

/// Largest obstacle dimension (box side, radius, height, length), m: a
/// room-sized floor or wall. Larger values (1e300) overflow the contact
/// geometry.
pub const MAX_OBSTACLE_SIZE: f64 = 100.0;

/// Largest obstacle thickness (the contact layer around its surface), m.
/// The thesis thickens its table by 6 mm; 10 cm is far beyond any use.
pub const MAX_OBSTACLE_THICKNESS: f64 = 0.1;

/// Cloth thickness range, m: from 10 µm (a film) to 2 cm (a quilt).
pub const CLOTH_THICKNESS: (f64, f64) = (1e-5, 0.02);

/// Smallest cloth spacing (grid cell side) and cloth size, m. Two reasons.
/// The spring laws are the fabric's KES curves, measured on 5 × 20 cm
/// strips: they describe the cloth as a sheet, not its yarns, which lie
/// 0.25 to 1 mm apart in woven fabrics. And the step: a vertex's mass
/// shrinks with the cell's area while the laws' forces per unit width (the
/// hysteresis's among them) do not. Measured on `hanging_corners.yaml`
/// scaled to 10 × 10 cells (dt 2 ms, 0.05 s; docs/limits.md), the most
/// stretched spring is at 0.35 % at 5 mm, 0.30 % at 2 mm, 0.90 % at 1 mm,
/// 3.9 % at 0.5 mm, 31 % at 0.1 mm, 338 % at 10 µm, and at 1 µm the step's
/// matrix is not positive definite: finer than 1 mm the step is wrong
/// before it fails.
pub const MIN_CLOTH_SPACING: f64 = 1e-3;

/// A cloth's size and spacing along warp and weft (`size_field`,
/// `spacing_field`: the names the file or command line gives them), each
/// finite and at least [`MIN_CLOTH_SPACING`], and the grid's cells (the
/// size divided into a whole number of cells, as the grid is built) too.
pub fn check_cloth_grid(
    size_field: &str,
    size: [f64; 2],
    spacing_field: &str,
    spacing: [f64; 2],
) -> Result<()> {
    let why = "MIN_CLOTH_SPACING: the laws describe the fabric as a sheet, not its \
               yarns, and on finer cells, whose masses vanish, the step overstretches \
               the cloth, then fails";
    for (k, dir) in ["warp", "weft"].iter().enumerate() {
        for (field, v) in [(size_field, size[k]), (spacing_field, spacing[k])] {
            if !(v.is_finite() && v >= MIN_CLOTH_SPACING) {
                fail!(
                    bound(field, v),
                    "{field} ({dir}) = {} m: must be a finite number ≥ {MIN_CLOTH_SPACING} m \
                     ({why})",
                    num(v)
                );
            }
        }
        let cell = size[k] / (size[k] / spacing[k]).round().max(1.0);
        if cell < MIN_CLOTH_SPACING {
            fail!(
                bound(size_field, cell),
                "{size_field} ({dir}) = {} m at {spacing_field} = {} m gives cells of {} m, \
                 below {MIN_CLOTH_SPACING} m ({why})",
                num(size[k]),
                num(spacing[k]),
                num(cell)
            );
        }
    }
    Ok(())
}

/// Farthest a motion-capture marker may lie from the capture's origin, m.
/// A capture volume is a room, a few metres across; 100 m leaves room for
/// any laboratory's origin. Beyond it a position is a unit slip
/// (millimetres written as metres) or a corrupt sample: one marker at
/// 1e30 m makes the speeds 1e32 m/s and the fit meaningless. A distance,
/// not a bound per axis, so that it holds in the frame the vertical is
/// turned to as well as in the file's.
pub const MAX_CAPTURE_DISTANCE: f64 = 100.0;

/// A number as a person writes it: 1e30 and 1e-9 with an exponent, not as
/// 31 digits or 9 zeros.
fn num(v: f64) -> String {
    if v != 0.0 && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// A marker position within [`MAX_CAPTURE_DISTANCE`] of the origin.
pub fn check_capture_position(what: &str, p: &Vector3<f64>) -> Result<()> {
    let d = p.norm();
    if d.is_nan() || d > MAX_CAPTURE_DISTANCE {
        fail!(
            bound(what, d),
            "{what} = ({}, {}, {}) m lies {d:.3e} m from the capture's origin, beyond \
             {MAX_CAPTURE_DISTANCE} m (MAX_CAPTURE_DISTANCE: a capture volume is a room; \
             millimetres written as metres, or a corrupt sample?)",
            num(p.x),
            num(p.y),
            num(p.z)
        );
    }
    Ok(())
}

/// Largest Coulomb friction coefficient: rubber on rubber is about 1–2.
pub const MAX_FRICTION: f64 = 10.0;

/// Largest obstacle speed (linear, and angular times its size), m/s, for
/// the same reason as [`MAX_PIN_SPEED`].
pub const MAX_OBSTACLE_SPEED: f64 = 10.0;

/// Largest angular speed of an obstacle, rad/s (a turntable turns at a few
/// rad/s; 100 rad/s is about 1000 rpm).
pub const MAX_ANGULAR_SPEED: f64 = 100.0;

/// Deepest a cloth vertex may lie inside an obstacle's shape when the
/// obstacle is placed (scene build, `obstacles` ADD or MOVE), m. The contact
/// handling puts such a vertex back on the surface within one step: 1 cm
/// in 1 ms is 10 m/s, [`MAX_PIN_SPEED`]; deeper overlaps throw the cloth
/// (a sphere put around it sends it metres away).
pub const MAX_OVERLAP: f64 = 0.01;

/// Largest gravity, m/s²: 10 g, beyond any place cloth hangs (a
/// centrifuge aside); 1e300 overflows the forces at the first step.
pub const MAX_GRAVITY: f64 = 100.0;

/// Longest time step, s. The step is linearised once: the thesis runs 1 to
/// 10 ms, the lab's quasi-static tests 10 ms, a motion capture's frame
/// (20 Hz and faster) is the longest step `identify` takes, and the contact
/// tests hold a thin board at 50 ms. Longer steps give numbers that look
/// like results (a KES resilience of 1e12 %, a drapemeter specimen hanging
/// far below its table).
pub const MAX_DT: f64 = 0.05;

/// A time step in (0, [`MAX_DT`]] s.
pub fn check_dt(what: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0 && v <= MAX_DT) {
        fail!(
            bound(what, v),
            "{what} = {v}: must lie in (0, {MAX_DT}] s (MAX_DT: the step is linearised once)"
        );
    }
    Ok(())
}

/// A duration: finite and ≥ 0 s.
pub fn check_duration(what: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v >= 0.0) {
        fail!(
            bound(what, v),
            "{what} = {v}: must be a finite number ≥ 0 s"
        );
    }
    Ok(())
}

/// KES-FB1 extension at the maximum load EMT, %: woven fabrics extend 1 to
/// 30 %, knits up to about 100 % under 500 gf/cm; more is a unit slip.
pub const KES_EMT: (f64, f64) = (0.0, 100.0);

/// KES-FB1 shear rigidity G, gf/(cm·deg): fabrics lie between 0.2 and 10.
pub const KES_G: (f64, f64) = (0.0, 50.0);

/// KES-FB2 bending rigidity B, gf·cm²/cm: fabrics lie between 0.005 and 2
/// (a heavy denim); 50 is a board.
pub const KES_B: (f64, f64) = (0.0, 50.0);

/// A KES summary value in `(lo, hi]`.
pub fn check_kes(what: &str, v: f64, (lo, hi): (f64, f64), unit: &str) -> Result<()> {
    if !(v.is_finite() && v > lo && v <= hi) {
        fail!(
            bound(what, v),
            "{what} = {v}: must lie in ({lo}, {hi}] {unit} (the range of measured fabrics)"
        );
    }
    Ok(())
}

/// Memory a simulation of `n` vertices needs at its peak, estimated, bytes:
/// 64 MiB for the process (code, threads, the ROS and Foxglove runtimes)
/// plus 16 KiB per vertex at 40,000 vertices (the peak resident size
/// measured with the Cholesky solver, whose factor dominates), growing with
/// log n as the factor's fill-in does on a grid (nested dissection). The
/// estimate lies above the measured peaks from 10,000 to 1,000,000 vertices
/// (10,201 vertices: 189 MB measured, 234 MB estimated).
pub fn memory_estimate(n: usize) -> u64 {
    const PROCESS: f64 = 64.0 * 1024.0 * 1024.0;
    let n = n.max(1) as f64;
    let growth = (n.log2() / 40_000f64.log2()).max(1.0);
    (PROCESS + n * 16384.0 * growth) as u64
}

/// Refuses a grid of `nx × ny` vertices whose [`memory_estimate`] exceeds
/// the memory `available` (bytes; none: not known, not checked), with the
/// estimate in the message.
pub fn check_memory(nx: usize, ny: usize, available: Option<u64>) -> Result<()> {
    let n = nx.saturating_mul(ny);
    let need = memory_estimate(n);
    if let Some(avail) = available {
        if need > avail {
            fail!(
                too_large,
                "a cloth of {nx} × {ny} = {n} vertices needs about {:.2} GB, more than the \
                 {:.2} GB of memory available; use a coarser spacing",
                need as f64 / 1e9,
                avail as f64 / 1e9
            );
        }
    }
    Ok(())
}

/// Relative tolerance of the conjugate gradients: in (0, 1) exclusive; 0
/// cannot be reached in floating point and 1 or more accepts the first
/// guess (the cloth frozen in place).
pub fn check_cg_tolerance(what: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0 && v < 1.0) {
        fail!(
            bound(what, v),
            "{what} = {v}: must lie in (0, 1) (a relative residual)"
        );
    }
    Ok(())
}

/// A finite number > 0.
pub fn check_positive(what: &str, v: f64, unit: &str) -> Result<()> {
    if !(v.is_finite() && v > 0.0) {
        fail!(
            bound(what, v),
            "{what} = {v}: must be a finite number > 0 {unit}"
        );
    }
    Ok(())
}

/// A finite number in `[lo, hi]`, with the reason given.
pub fn check_range(what: &str, v: f64, lo: f64, hi: f64, unit: &str, why: &str) -> Result<()> {
    if !(v.is_finite() && v >= lo && v <= hi) {
        fail!(
            bound(what, v),
            "{what} = {v}: must lie in [{lo}, {hi}] {unit} ({why})"
        );
    }
    Ok(())
}

/// An obstacle dimension: > 0 and at most [`MAX_OBSTACLE_SIZE`].
pub fn check_size(what: &str, v: f64) -> Result<()> {
    if !(v.is_finite() && v > 0.0 && v <= MAX_OBSTACLE_SIZE) {
        fail!(
            bound(what, v),
            "{what} = {v}: must be > 0 and at most {MAX_OBSTACLE_SIZE} m \
             (MAX_OBSTACLE_SIZE, a room-sized floor)"
        );
    }
    Ok(())
}

/// A speed vector no faster than `max` (m/s or rad/s).
pub fn check_speed(what: &str, v: &Vector3<f64>, max: f64, unit: &str) -> Result<()> {
    let s = v.norm();
    if !(v.iter().all(|c| c.is_finite()) && s <= max) {
        fail!(
            bound(what, s),
            "{what} = ({}, {}, {}): speed {s:.3e} {unit} is not finite or above the limit \
             of {max} {unit}",
            v.x,
            v.y,
            v.z
        );
    }
    Ok(())
}

/// The box around a set of points, grown by `margin` on every side.
pub fn reach_box(x: &[Vector3<f64>], margin: f64) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in x {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    for a in 0..3 {
        lo[a] -= margin;
        hi[a] += margin;
    }
    (lo, hi)
}

/// A point within [`MAX_REACH`] of the box around the cloth `x`.
pub fn check_reach(what: &str, p: &Vector3<f64>, x: &[Vector3<f64>]) -> Result<()> {
    if !p.iter().all(|c| c.is_finite()) {
        let a = p.iter().position(|c| !c.is_finite()).unwrap_or(0);
        fail!(
            non_finite(what, a),
            "{what} = ({}, {}, {}) is not finite",
            p.x,
            p.y,
            p.z
        );
    }
    let (lo, hi) = reach_box(x, MAX_REACH);
    if (0..3).any(|a| p[a] < lo[a] || p[a] > hi[a]) {
        // how far outside the cloth's own box, m (the bound is MAX_REACH)
        let out = (0..3).fold(0.0f64, |m, a| m.max(lo[a] - p[a]).max(p[a] - hi[a])) + MAX_REACH;
        fail!(
            bound(what, out),
            "{what} = ({}, {}, {}) m is more than {MAX_REACH} m (MAX_REACH) outside the box \
             around the cloth, x ∈ [{:.3}, {:.3}], y ∈ [{:.3}, {:.3}], z ∈ [{:.3}, {:.3}] m \
             (a position in mm, or in another frame?)",
            p.x,
            p.y,
            p.z,
            lo[0] + MAX_REACH,
            hi[0] - MAX_REACH,
            lo[1] + MAX_REACH,
            hi[1] - MAX_REACH,
            lo[2] + MAX_REACH,
            hi[2] - MAX_REACH
        );
    }
    Ok(())
}
