//! The implicit step (thesis §3.5, eq. 3.3; Baraff & Witkin 1998):
//!
//! ```text
//! (M − h ∂f/∂v − h² ∂f/∂x) Δv = h (f0 + h ∂f/∂x v0 + ∂f/∂x y)
//! Δx = h (v0 + Δv) + y
//! ```
//!
//! linearised once per step at a fixed time step `h`. With Rayleigh damping
//! `∂f/∂v = C = αM + Σ_k β_k K̃_k` and `∂f/∂x = −Σ_k K̃_k` (projected
//! stiffnesses of the tension, shear and bending families, see [`elements`]),
//! the system matrix is `A = (1 − hα) M + Σ_k (h² − h β_k) K̃_k`: symmetric
//! positive definite because α, β ≤ 0 and every K̃_k is PSD. Its block pattern
//! is built once from the springs and hinges and reused every step.
//!
//! Pins and contacts act through the constraint filter (S, z) and the position
//! correction y, never through penalty springs.

pub(crate) mod amg;
pub(crate) mod assemble;
mod cpu;
pub mod elements;
mod energy;
pub mod family;
pub(crate) mod linear;
pub(crate) mod sets;
pub mod sparse;
pub(crate) mod team;
#[cfg(test)]
mod test_systems;
pub(crate) mod trisolve;
mod vertices;

use crate::cloth::Cloth;
use crate::collision::Obstacle;
use crate::error::{fail, Error, Result};
use crate::fabric::Fabric;
use crate::set::{Handle, Set};
pub use energy::Energies;
pub(crate) use energy::Fabrics;
pub use linear::{Filter, LinearSolverKind};
use nalgebra::Vector3;
use serde::Serialize;
use sparse::BlockMatrix;
use std::time::Instant;

/// Every knob of the integrator in one place.
#[derive(Debug, Clone, Serialize)]
pub struct Params {
    /// Fixed time step, s.
    pub dt: f64,
    /// Gravity, m/s².
    pub gravity: Vector3<f64>,
    /// The linear solver.
    pub linear_solver: LinearSolverKind,
    /// Relative tolerance of the PCG (on the preconditioned residual).
    pub cg_tolerance: f64,
    /// Cap on the PCG's iterations per solve.
    pub cg_max_iterations: usize,
    /// Cloth thickness (thesis: 2 mm). A vertex rests at `obstacle thickness +
    /// cloth thickness` from an obstacle's surface (the contact distance e).
    pub cloth_thickness: f64,
    /// Include the hysteretic parts of the laws.
    pub hysteresis: bool,
    /// Threads of the assembly, the PCG and the contacts, started once per
    /// simulation (`team::Team`; 0: one per core for large cloths, see
    /// `team::threads_for`; at most [`MAX_THREADS`]).
    pub threads: usize,
    /// Bound a sliding contact's kinetic friction by what stops it against
    /// this step's driving force instead of last step's. Garments need it:
    /// stiff seam stitches pulling vertices over a curved body change the
    /// driving force from step to step, and the lagged bound lets the
    /// friction overshoot and reverse vertices every step, so a sewn skirt
    /// never comes to rest. Off for scenes (a cloth resting on a flat board
    /// at 1/120 s keeps a few vertices switching between stick and slip
    /// with it on).
    pub friction_bound_now: bool,
    /// Keep the cloth from passing through itself ([`crate::self_contact`]):
    /// layers rest at the fabric's thickness T and slide on each other with
    /// its fabric-on-fabric friction. Off: folds may pass through each other.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub self_collision: bool,
    /// The triangle-mesh obstacles' vertices and edges meet the cloth's
    /// triangles and edges too, as kinematic points and edges of infinite
    /// mass in the cloth–cloth pass ([`crate::self_contact::Kinematic`],
    /// kept [`OBSTACLE_EDGE_GAP`] of the contact distance apart): a part of
    /// a body thinner than the cloth's spacing (fingers) then cannot pass
    /// between the cloth's vertices and hook the cloth. Off: only the
    /// cloth's vertices meet the obstacles' surfaces.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub obstacle_edges: bool,
    /// Each grid cell's shear from both its diagonals
    /// ([`crate::cloth::ShearCell`], with the egg-crate guards,
    /// [`Cloth::use_cell_shear`]): a fold or a stretch reads no shear, so
    /// coarse grids do not resist folds (docs/lab.md). Off: each diagonal
    /// reads the shear alone (thesis eq. 4.34, with the tension correction
    /// of eq. 4.59).
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub cell_shear: bool,
    /// A vertex in a crease (two surfaces within its contact distance that
    /// fold towards each other) is held by both in the same step, free only
    /// along the crease ([`Filter::Crease`], `vertices::hold_in_crease`).
    /// Off: by the nearest surface alone, pushed out of the other after the
    /// step.
    #[serde(skip_serializing_if = "Clone::clone")]
    pub creases: bool,
}

/// The gap the cloth keeps from a triangle-mesh obstacle's vertices and
/// edges with [`Params::obstacle_edges`], as a fraction of the contact
/// distance `e` (obstacle thickness + cloth thickness) its vertices keep
/// from the surface: well below `e`, so that a cloth triangle lying on a
/// curved body over one of its vertices (its chord sags towards the surface
/// by l²/8R between corners held at `e`) is not pushed off it, the pass and
/// the surface contacts pulling the cloth two ways (with half of `e` they
/// did between a hand's fingers at 1 cm; docs/self_collision.md).
pub const OBSTACLE_EDGE_GAP: f64 = 0.25;

/// Where a triangle-mesh obstacle's vertex was pushed by the cloth in the
/// last step ([`Params::obstacle_edges`]).
#[derive(Debug, Clone, Copy)]
pub struct EdgeContact {
    /// The obstacle's index among [`Simulation::obstacles`].
    pub obstacle: usize,
    /// The vertex of its mesh.
    pub vertex: usize,
    /// The cloth vertex of the pair that pushed it most.
    pub cloth_vertex: usize,
    /// Force on the obstacle, N (the momentum over the step).
    pub force: Vector3<f64>,
    /// Where the vertex is (world), m.
    pub point: Vector3<f64>,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            dt: 1e-3,
            gravity: Vector3::new(0.0, 0.0, -9.81),
            linear_solver: LinearSolverKind::default(),
            cg_tolerance: 1e-6,
            cg_max_iterations: 2000,
            cloth_thickness: crate::collision::DEFAULT_CLOTH_THICKNESS,
            hysteresis: true,
            threads: 0,
            friction_bound_now: false,
            creases: true,
            self_collision: false,
            obstacle_edges: false,
            cell_shear: false,
        }
    }
}

impl Params {
    /// Refuses values no simulation can run with, naming the parameter.
    pub fn check(&self) -> Result<()> {
        crate::limits::check_dt("dt", self.dt)?;
        crate::limits::check_cg_tolerance("cg_tolerance", self.cg_tolerance)?;
        if self.cg_max_iterations == 0 {
            fail!(
                bound("cg_max_iterations", 0.0),
                "cg_max_iterations = 0: must be ≥ 1"
            );
        }
        let g = self.gravity;
        if !(g.iter().all(|c| c.is_finite()) && g.norm() <= crate::limits::MAX_GRAVITY) {
            fail!(
                bound("gravity", g.norm()),
                "gravity = ({}, {}, {}) m/s²: must be finite and at most {} m/s² (MAX_GRAVITY)",
                g.x,
                g.y,
                g.z,
                crate::limits::MAX_GRAVITY
            );
        }
        crate::limits::check_range(
            "cloth thickness",
            self.cloth_thickness,
            crate::limits::CLOTH_THICKNESS.0,
            crate::limits::CLOTH_THICKNESS.1,
            "m",
            "CLOTH_THICKNESS: a film to a quilt",
        )?;
        if self.threads > MAX_THREADS {
            fail!(
                bound("threads", self.threads as f64),
                "threads = {}: at most {MAX_THREADS} (0: one per core)",
                self.threads
            );
        }
        Ok(())
    }
}

/// How a pinned vertex moves.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub enum PinPath {
    /// Held at a point.
    Fixed(Vector3<f64>),
    /// Moves from `start` (at time `t0`) with constant velocity.
    Velocity {
        /// Position at `t0`, m.
        start: Vector3<f64>,
        /// Velocity, m/s.
        velocity: Vector3<f64>,
        /// Start time, s.
        t0: f64,
    },
    /// Piecewise-linear path through (time, position) waypoints; held at the
    /// first before it and at the last after it.
    Waypoints(Vec<(f64, Vector3<f64>)>),
    /// Travels in a straight line at constant speed from `from` (at time
    /// `t0`) to where `then` is at time `t1`, then follows `then`: how a pin
    /// reaches a far target at a bounded speed ([`PinPath::travel`]).
    Travel {
        /// Where the travel starts, m.
        from: Vector3<f64>,
        /// When it starts, s.
        t0: f64,
        /// When it arrives, s.
        t1: f64,
        /// The path followed on arrival.
        then: Box<PinPath>,
    },
}

impl PinPath {
    /// Target position and velocity at time t.
    pub fn at(&self, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        match self {
            PinPath::Fixed(p) => (*p, Vector3::zeros()),
            PinPath::Velocity {
                start,
                velocity,
                t0,
            } => (start + velocity * (t - t0), *velocity),
            PinPath::Waypoints(w) => {
                if w.is_empty() {
                    return (Vector3::zeros(), Vector3::zeros());
                }
                if t <= w[0].0 {
                    return (w[0].1, Vector3::zeros());
                }
                for k in 1..w.len() {
                    let (t0, p0) = w[k - 1];
                    let (t1, p1) = w[k];
                    if t <= t1 {
                        let v = (p1 - p0) / (t1 - t0).max(1e-300);
                        return (p0 + v * (t - t0), v);
                    }
                }
                (w[w.len() - 1].1, Vector3::zeros())
            }
            PinPath::Travel { from, t0, t1, then } => {
                if t >= *t1 {
                    return then.at(t);
                }
                let (to, _) = then.at(*t1);
                let v = (to - from) / (t1 - t0);
                (from + v * (t - t0).max(0.0), v)
            }
        }
    }

    /// The path a pin follows to `self` from its vertex at `from` at time
    /// `now`: `self` if its position now is within one step `dt` at
    /// [`crate::limits::PIN_TRAVEL_SPEED`], else a straight travel at that
    /// speed to where `self` will be on arrival, then `self` (a moving target
    /// starts its motion on arrival).
    pub fn travel(self, from: Vector3<f64>, now: f64, dt: f64) -> PinPath {
        use crate::limits::PIN_TRAVEL_SPEED;
        let (p, _) = self.at(now);
        let d = (p - from).norm();
        if d <= PIN_TRAVEL_SPEED * dt {
            return self;
        }
        let arrive = now + d / PIN_TRAVEL_SPEED;
        let then = match self {
            PinPath::Velocity {
                start, velocity, ..
            } => PinPath::Velocity {
                start,
                velocity,
                t0: arrive,
            },
            other => other,
        };
        PinPath::Travel {
            from,
            t0: now,
            t1: arrive,
            then: Box::new(then),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize)]
/// A vertex held on a path.
pub struct Pin {
    /// The vertex.
    pub vertex: usize,
    /// Its path.
    pub path: PinPath,
    /// The pin lets go at this time, s (thesis ch. 5: the square is held by
    /// its corners, then released).
    pub release_at: Option<f64>,
}

impl Pin {
    /// A pin on `vertex` following `path`, never released.
    pub fn new(vertex: usize, path: PinPath) -> Pin {
        Pin {
            vertex,
            path,
            release_at: None,
        }
    }
}

/// Which linear solve gave a step's velocity change.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SolvedBy {
    /// The block-Jacobi PCG.
    #[default]
    Pcg,
    /// The PCG preconditioned by symmetric block Gauss–Seidel.
    Sgs,
    /// The multigrid PCG.
    Amg,
    /// The Cholesky factor (single precision refined by the PCG, or exact).
    Cholesky,
}

/// What one step did.
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct StepStats {
    /// Linear-solver iterations, the failed tries of `auto` included.
    pub iterations: usize,
    /// The solve that gave the step's answer.
    pub solved_by: SolvedBy,
    /// Vertices in contact with an obstacle this step.
    pub contacts: usize,
    /// Of those, the ones static friction held (moving with the obstacle).
    pub stuck: usize,
    /// Wall-clock time of the assembly, s.
    pub assemble_s: f64,
    /// Of the linear solve, s.
    pub solve_s: f64,
    /// Of the obstacle contacts, s.
    pub collide_s: f64,
    /// The cloth against itself ([`Params::self_collision`]; all zero when
    /// off): pairs within the thickness pushed apart, pairs whose paths
    /// crossed, rigid impact zones, and the time it took (not in
    /// `collide_s`).
    pub self_contacts: usize,
    /// See `self_contacts`.
    pub self_collisions: usize,
    /// See `self_contacts`.
    pub self_zones: usize,
    /// See `self_contacts`.
    pub self_s: f64,
    /// Wall-clock time of the whole step, s.
    pub total_s: f64,
}

/// A cloth, its fabric and its scene, advanced at a fixed step.
///
/// Three parts, kept apart: the parameters ([`Params`]); the state, which
/// alone decides what the next step does (the cloth with its positions,
/// velocities and hysteresis memory, the fabrics, the obstacles and pins,
/// time, the friction memory, last step's force, friction force and velocity
/// change, and which linear solver `auto` is on); and a `Workspace`, what a step computes and throws away
/// (matrix, right-hand side, filter, solver buffers, threads). Cloning a
/// simulation clones its state and gives the clone a fresh workspace: it
/// steps exactly as the original does.
#[derive(Debug)]
pub struct Simulation {
    /// The cloth and its state.
    pub cloth: Cloth,
    /// The fabric (a garment of several fabrics: its first).
    pub fabric: Fabric,
    /// A garment's further fabrics: `cloth.vertex_fabric` indexes
    /// `fabric`, then these (see [`Simulation::with_fabrics`]).
    pub other_fabrics: Vec<Fabric>,
    /// Read with [`Simulation::obstacles`]; changed through the simulation.
    obstacles: Set<Obstacle>,
    /// Read with [`Simulation::pins`]; changed through the simulation, which
    /// keeps `pinned` in step with it.
    pins: Set<Pin>,
    /// Read with [`Simulation::params`], changed with
    /// [`Simulation::set_params`].
    params: Params,
    /// Simulated time, s.
    pub time: f64,
    /// Steps taken.
    pub steps: u64,
    /// The last step's statistics.
    pub last: StepStats,
    dissipated: f64,
    /// Total force at the start of the last step (internal + external +
    /// damping): the next step's friction bound reads it.
    pub force: Vec<Vector3<f64>>,
    /// Stick/slip state carried from step to step.
    friction: Vec<FrictionState>,
    /// The last step's velocity change: the linear solvers' first guess.
    dv: Vec<Vector3<f64>>,
    /// The solve that gave the last answer.
    solved_by: SolvedBy,
    /// The last step's kinetic friction force: the next step's constraint
    /// phase takes it out of the force that drives the sliding.
    friction_force: Vec<Vector3<f64>>,
    /// Each vertex's pin in `pins`.
    pinned: Vec<Option<usize>>,
    /// Which solver `auto` is on.
    auto: AutoChoice,
    /// Steps whose linear system is kept ([`Simulation::capture_systems`]).
    capture_at: Vec<u64>,
    /// The last step's system, if it was one of `capture_at`.
    captured: Option<Box<LinearSystem>>,
    ws: Workspace,
}

/// One step's linear system as the solvers saw it, kept by
/// [`Simulation::capture_systems`]: `A Δv = b` under the filter (`Δv_i =
/// S_i Δv_i + z_i`), the first guess the solve started from and the answer
/// it gave, with what a solver outside this program needs to rebuild the
/// test and the multigrid's near-null space (positions, masses, gravity).
#[derive(Debug, Clone)]
pub struct LinearSystem {
    /// Steps taken before this one (the step's index from 0).
    pub step: u64,
    /// Simulated time at the step's start, s.
    pub time: f64,
    /// Time step, s.
    pub dt: f64,
    /// Gravity, m/s².
    pub gravity: Vector3<f64>,
    /// The relative tolerance the solve was asked for ([`Params::cg_tolerance`]).
    pub tolerance: f64,
    /// The system matrix `A = (1 − hα) M + Σ_k (h² − h β_k) K̃_k` (see the
    /// module's documentation), kg.
    pub a: BlockMatrix,
    /// The right-hand side `h (f0 + h ∂f/∂x v0 + ∂f/∂x y)` with the kinetic
    /// friction's impulse, N·s.
    pub b: Vec<Vector3<f64>>,
    /// The constraint filter of each vertex.
    pub filter: Vec<Filter>,
    /// The prescribed part of Δv, m/s.
    pub z: Vec<Vector3<f64>>,
    /// The solve's first guess (the last step's Δv), m/s.
    pub guess: Vec<Vector3<f64>>,
    /// The solve's answer, m/s.
    pub dv: Vec<Vector3<f64>>,
    /// Positions at the step's start, m, and masses, kg.
    pub x: Vec<Vector3<f64>>,
    /// See `x`.
    pub mass: Vec<f64>,
    /// The solve that gave the answer.
    pub solved_by: SolvedBy,
    /// Its iterations.
    pub iterations: usize,
}

/// Where `auto` mode stands (see [`LinearSolverKind::Auto`]).
#[derive(Debug, Clone, Copy)]
struct AutoChoice {
    /// On the Cholesky (the PCG needed too many iterations).
    on_direct: bool,
    /// Step of the next try of the PCG while on the Cholesky, and the gap
    /// to the one after if it fails (doubled at each failure).
    next_probe: u64,
    probe_gap: u64,
    /// Step of the next try of the multigrid after one that did not
    /// converge within its cycles, and the gap to the one after.
    next_amg: u64,
    amg_gap: u64,
    /// The step the multigrid last solved (or tried to).
    amg_last: Option<u64>,
    /// What the multigrid's last solve cost, in block-Jacobi PCG
    /// iterations: the block-Jacobi PCG's cap while it is lower than the
    /// Cholesky's break-even ([`Simulation::solve_auto`]).
    amg_price: Option<usize>,
}

/// What a step computes and throws away, sized for one cloth and one set of
/// [`Params`]: the system, its right-hand side and constraints, the linear
/// solvers' buffers and factors, and the threads.
#[derive(Debug)]
struct Workspace {
    a: BlockMatrix,
    slots: assemble::Slots,
    part: assemble::Partition,
    /// Threads of the assembly, the PCG and the contacts, started once (one
    /// per chunk of `part`).
    team: team::Team,
    b: Vec<Vector3<f64>>,
    z: Vec<Vector3<f64>>,
    y: Vec<Vector3<f64>>,
    filter: Vec<Filter>,
    /// Friction coefficient and obstacle velocity of each vertex in contact.
    contact_of: Vec<Option<(f64, Vector3<f64>)>>,
    /// Normal of each vertex's contact this step (also when it sticks).
    normals: Vec<Vector3<f64>>,
    /// The second surface's normal of a vertex held in a crease this step
    /// (zero for one held by one surface or none).
    normals2: Vec<Vector3<f64>>,
    /// Broad-phase boxes of the obstacles for this step.
    bounds: Vec<vertices::Bounds>,
    pcg: linear::Pcg,
    direct: Option<linear::Direct>,
    /// The multigrid hierarchy (built on first use).
    amg: Option<amg::Amg>,
    /// The cloth–cloth pass (built on the first step with
    /// [`Params::self_collision`]).
    self_contact: Option<Box<crate::self_contact::SelfContact>>,
    /// The triangle-mesh obstacles in that pass ([`Params::obstacle_edges`]):
    /// each one's index, first kinematic vertex and vertex count, and
    /// their vertices where they are now.
    kinematic: Vec<(usize, usize, usize)>,
    kinematic_x: Vec<Vector3<f64>>,
    /// The list being made by [`Simulation::kinematic_now`] (kept to reuse).
    kinematic_next: Vec<(usize, usize, usize)>,
    /// Whether the pass tests the cloth's own pairs.
    self_pairs: bool,
}

impl Workspace {
    /// A workspace for `cloth`, whose elements it first puts in the order
    /// its threads take them (grouped by chunk of vertices; a cloth already
    /// in that order stays as it is).
    fn new(cloth: &mut Cloth, params: &Params) -> Result<Workspace> {
        let n = cloth.len();
        let cliques = sets::cliques(cloth);
        let a = BlockMatrix::from_cliques(n, cliques.iter().map(|c| c.as_slice()));
        let threads = match params.threads {
            0 => team::threads_for(n),
            t => t,
        };
        let part = assemble::partition(cloth, threads);
        let slots = assemble::Slots::new(&a, cloth);
        let direct = match params.linear_solver {
            LinearSolverKind::Cholesky => Some(linear::Direct::new(&a)?),
            LinearSolverKind::Pcg
            | LinearSolverKind::Sgs
            | LinearSolverKind::Auto
            | LinearSolverKind::Amg => None,
        };
        let z = vec![Vector3::zeros(); n];
        Ok(Workspace {
            a,
            slots,
            part,
            team: team::Team::new(threads),
            b: z.clone(),
            y: z.clone(),
            normals: z.clone(),
            normals2: z.clone(),
            z,
            filter: vec![Filter::Free; n],
            contact_of: vec![None; n],
            bounds: Vec::new(),
            pcg: linear::Pcg::default(),
            direct,
            amg: None,
            self_contact: None,
            kinematic: Vec::new(),
            kinematic_x: Vec::new(),
            kinematic_next: Vec::new(),
            self_pairs: params.self_collision,
        })
    }
}

impl Clone for Simulation {
    /// The state and parameters, with a fresh `Workspace` (but for the
    /// multigrid's hierarchy, which carries the coarse levels it keeps).
    fn clone(&self) -> Simulation {
        let mut cloth = self.cloth.clone();
        let mut ws = Workspace::new(&mut cloth, &self.params)
            .expect("a workspace like the one this simulation was built with");
        // the multigrid's kept coarse levels decide its next solves' iterates
        ws.amg = self.ws.amg.as_ref().and_then(amg::Amg::try_clone);
        Simulation {
            cloth,
            fabric: self.fabric.clone(),
            other_fabrics: self.other_fabrics.clone(),
            obstacles: self.obstacles.clone(),
            pins: self.pins.clone(),
            params: self.params.clone(),
            time: self.time,
            steps: self.steps,
            last: self.last,
            dissipated: self.dissipated,
            force: self.force.clone(),
            friction: self.friction.clone(),
            dv: self.dv.clone(),
            solved_by: self.solved_by,
            friction_force: self.friction_force.clone(),
            pinned: self.pinned.clone(),
            auto: self.auto,
            capture_at: self.capture_at.clone(),
            captured: self.captured.clone(),
            ws,
        }
    }
}

impl Simulation {
    /// A simulation of `cloth` in `fabric` with `params`, at time 0, without
    /// obstacles or pins; refuses parameters out of range and elements that
    /// do not fit the cloth.
    pub fn new(mut cloth: Cloth, fabric: Fabric, params: Params) -> Result<Simulation> {
        params.check()?;
        let fabric = if params.hysteresis {
            fabric
        } else {
            fabric.without_hysteresis()
        };
        let n = cloth.len();
        if params.cell_shear {
            cloth.use_cell_shear()?;
        }
        sets::check(&cloth)?;
        let ws = Workspace::new(&mut cloth, &params)?;
        Ok(Simulation {
            cloth,
            fabric,
            other_fabrics: Vec::new(),
            obstacles: Set::new(),
            pins: Set::new(),
            params,
            time: 0.0,
            steps: 0,
            last: StepStats::default(),
            dissipated: 0.0,
            force: vec![Vector3::zeros(); n],
            friction: vec![FrictionState::default(); n],
            dv: vec![Vector3::zeros(); n],
            solved_by: SolvedBy::Pcg,
            friction_force: vec![Vector3::zeros(); n],
            pinned: vec![None; n],
            auto: AutoChoice {
                on_direct: false,
                next_probe: 0,
                probe_gap: AUTO_PROBE,
                next_amg: 0,
                amg_gap: AUTO_PROBE,
                amg_last: None,
                amg_price: None,
            },
            capture_at: Vec::new(),
            captured: None,
            ws,
        })
    }

    /// A cloth cut from several fabrics (a garment whose panels differ):
    /// `cloth.vertex_fabric` gives each vertex's fabric as an index into
    /// `fabrics`; every spring and hinge takes the fabric of its vertices
    /// (they lie within one panel), every vertex its own α.
    pub fn with_fabrics(cloth: Cloth, fabrics: Vec<Fabric>, params: Params) -> Result<Simulation> {
        let mut rest = fabrics.into_iter();
        let Some(first) = rest.next() else {
            fail!(invalid, "a simulation needs at least one fabric");
        };
        let rest: Vec<Fabric> = rest.collect();
        let vf = &cloth.vertex_fabric;
        if !vf.is_empty() && vf.len() != cloth.len() {
            fail!(
                length("vertex_fabric", vf.len(), cloth.len()),
                "vertex_fabric has {} entries for {} vertices",
                vf.len(),
                cloth.len()
            );
        }
        if let Some((v, k)) = vf
            .iter()
            .enumerate()
            .find(|(_, &k)| usize::from(k) > rest.len())
        {
            fail!(
                index("fabric", usize::from(*k), rest.len() + 1),
                "vertex {v} names fabric {k}, but there are {} fabrics",
                rest.len() + 1
            );
        }
        let hysteresis = params.hysteresis;
        let mut sim = Simulation::new(cloth, first, params)?;
        sim.other_fabrics = rest
            .into_iter()
            .map(|f| {
                if hysteresis {
                    f
                } else {
                    f.without_hysteresis()
                }
            })
            .collect();
        Ok(sim)
    }

    /// Every fabric: `fabric`, then `other_fabrics`.
    pub fn fabrics(&self) -> impl Iterator<Item = &Fabric> {
        std::iter::once(&self.fabric).chain(&self.other_fabrics)
    }

    /// Every fabric, to change (the trial's sewing phase sets their α).
    pub fn fabrics_mut(&mut self) -> impl Iterator<Item = &mut Fabric> {
        std::iter::once(&mut self.fabric).chain(&mut self.other_fabrics)
    }

    /// The fabric of vertex `v` (and of the springs and hinges at it).
    #[inline]
    pub fn fabric_of(&self, v: usize) -> &Fabric {
        self.fabric_lookup().at(v)
    }

    /// The per-vertex fabric lookup of the cloth.
    fn fabric_lookup(&self) -> Fabrics<'_> {
        Fabrics {
            first: &self.fabric,
            others: &self.other_fabrics,
            of: &self.cloth.vertex_fabric,
        }
    }

    /// Threads of the assembly, the PCG and the contacts.
    pub fn threads(&self) -> usize {
        self.ws.team.size()
    }

    /// Lets the simulation's worker threads sleep now rather than spin for
    /// the next step (they spin up to 1 ms after each phase to stay on their
    /// cores): for a caller about to wait, e.g. a node pacing the steps with
    /// the wall clock.
    pub fn rest_threads(&self) {
        self.ws.team.rest();
    }

    /// Keeps the linear system of each of the steps `at` (step indices from
    /// 0: the step taken when [`Simulation::steps`] equals one of them), for
    /// [`Simulation::captured_system`] after that step. To study a step's
    /// solve outside this program (`garment_sim drape --write-system`).
    pub fn capture_systems(&mut self, at: &[u64]) {
        self.capture_at = at.to_vec();
    }

    /// The last step's linear system, if [`Simulation::capture_systems`]
    /// asked for that step.
    pub fn captured_system(&self) -> Option<&LinearSystem> {
        self.captured.as_deref()
    }

    /// The integrator's parameters.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// Changes the parameters between two steps (checked as at
    /// construction); a change of threads or linear solver builds a new
    /// workspace. `hysteresis` is the fabric's, fixed at construction.
    pub fn set_params(&mut self, params: Params) -> Result<()> {
        params.check()?;
        if params.hysteresis != self.params.hysteresis {
            fail!(
                invalid,
                "hysteresis is set when the simulation is built, not while it runs"
            );
        }
        let rebuild = params.threads != self.params.threads
            || params.linear_solver != self.params.linear_solver;
        if rebuild {
            let amg = self.ws.amg.take();
            self.ws = Workspace::new(&mut self.cloth, &params)?;
            if params.linear_solver == self.params.linear_solver {
                // the multigrid's kept coarse levels decide its next solves'
                // iterates (as a clone keeps them)
                self.ws.amg = amg;
            }
        }
        self.params = params;
        Ok(())
    }

    /// The obstacles, in the order they were added.
    pub fn obstacles(&self) -> &Set<Obstacle> {
        &self.obstacles
    }

    /// Adds an obstacle; its handle.
    pub fn add_obstacle(&mut self, o: Obstacle) -> Handle<Obstacle> {
        self.obstacles.insert(o)
    }

    /// Removes an obstacle (the others keep their handles).
    pub fn remove_obstacle(&mut self, h: Handle<Obstacle>) -> Option<Obstacle> {
        self.obstacles.remove(h)
    }

    /// An obstacle to move or change.
    pub fn obstacle_mut(&mut self, h: Handle<Obstacle>) -> Option<&mut Obstacle> {
        self.obstacles.get_mut(h)
    }

    /// Replaces every obstacle by `obstacles` (a set taken from
    /// [`Simulation::obstacles`] keeps its handles).
    pub fn set_obstacles(&mut self, obstacles: Set<Obstacle>) {
        self.obstacles.replace(obstacles);
    }

    /// The pins, in the order they were set.
    pub fn pins(&self) -> &Set<Pin> {
        &self.pins
    }

    /// Replaces the pins (checks the vertex indices); their handles, in order.
    pub fn set_pins(&mut self, pins: Vec<Pin>) -> Result<Vec<Handle<Pin>>> {
        self.set_pin_set(pins.into_iter().collect())?;
        Ok(self.pins.with_handles().map(|(h, _)| h).collect())
    }

    /// Replaces the pins by `pins` (a set taken from [`Simulation::pins`]
    /// keeps its handles); checks the vertex indices first.
    pub fn set_pin_set(&mut self, pins: Set<Pin>) -> Result<()> {
        for p in &pins {
            if p.vertex >= self.cloth.len() {
                fail!(
                    index("pin vertex", p.vertex, self.cloth.len()),
                    "pin on vertex {} but the cloth has {} vertices",
                    p.vertex,
                    self.cloth.len()
                );
            }
        }
        self.pins.replace(pins);
        self.index_pins();
        Ok(())
    }

    /// Gives a pin a new path.
    pub fn set_pin_path(&mut self, h: Handle<Pin>, path: PinPath) -> Result<()> {
        match self.pins.get_mut(h) {
            Some(p) => {
                p.path = path;
                Ok(())
            }
            None => fail!(invalid, "no pin {h:?}"),
        }
    }

    /// Lets a pin go.
    pub fn remove_pin(&mut self, h: Handle<Pin>) -> Option<Pin> {
        let p = self.pins.remove(h)?;
        self.index_pins();
        Some(p)
    }

    /// `pinned` from `pins`: each vertex's pin (the last one when several
    /// pin a vertex).
    fn index_pins(&mut self) {
        self.pinned.iter_mut().for_each(|p| *p = None);
        for (k, p) in self.pins.iter().enumerate() {
            self.pinned[p.vertex] = Some(k);
        }
    }

    /// The direct solver, built (symbolic analysis) on first use.
    fn direct(&mut self) -> Result<&mut linear::Direct> {
        if self.ws.direct.is_none() {
            self.ws.direct = Some(linear::Direct::new(&self.ws.a)?);
        }
        Ok(self.ws.direct.as_mut().expect("direct solver built"))
    }

    /// Advances one fixed step.
    pub fn step(&mut self) -> Result<StepStats> {
        let t_start = Instant::now();
        // the cloth-cloth pass takes the start positions (and refuses a
        // tangled cloth on the first step, before anything changes)
        let start = self.begin_self_contact()?;
        let h = self.params.dt;
        let t1 = self.time + h;
        let n = self.cloth.len();
        // the linear solvers' convergence test is floored by gravity's
        // impulse over the step (see `Pcg::set_scale`)
        self.ws
            .pcg
            .set_scale(&self.cloth.mass, self.params.gravity * h);
        // pins whose release time has come let go
        let now = self.time;
        let due = |p: &Pin| p.release_at.is_some_and(|r| r <= now);
        if self.pins.iter().any(due) {
            self.pins.retain(|p| !due(p));
            self.index_pins();
        }
        // 1. constraints for this step: pins, then contacts (filter, z, y);
        //    a deforming obstacle first takes its positions at the step's
        //    end and its velocities over the step
        for ob in self.obstacles.iter_mut() {
            ob.begin_step(h)?;
        }
        self.ws.bounds.clear();
        for ob in &self.obstacles {
            let e = ob.thickness + self.params.cloth_thickness;
            self.ws.bounds.push(ob.bounds(e * 1.1));
        }
        let (contacts, stuck) = self.constrain(h, t1);
        let t_collide = t_start.elapsed().as_secs_f64();
        // 2. forces and system
        let t_asm = Instant::now();
        self.assemble();
        for i in 0..n {
            // a sliding contact's kinetic friction is bounded by what stops
            // its tangential motion against the force driving it: last step's
            // force (the constraint phase's bound), or with
            // `Params::friction_bound_now` this step's
            if let (true, f @ (Filter::Normal(_) | Filter::Crease(_)), Some((mu, vo))) = (
                self.params.friction_bound_now,
                self.ws.filter[i],
                self.ws.contact_of[i],
            ) {
                if self.friction_force[i] != Vector3::zeros() {
                    let rel = self.cloth.v[i] - vo;
                    self.friction_force[i] = vertices::kinetic_friction(
                        self.cloth.mass[i],
                        f.apply(&rel),
                        self.force[i],
                        mu * self.friction[i].impulse,
                        h,
                    );
                }
            }
            if self.friction_force[i] != Vector3::zeros() {
                self.force[i] += self.friction_force[i];
                self.ws.b[i] += self.friction_force[i] * h;
            }
        }
        let assemble_s = t_asm.elapsed().as_secs_f64();
        // forces that overflow (a cloth stretched by orders of magnitude, a
        // pin target at 1e300 m) make every solver's answer meaningless: the
        // PCG's convergence test cannot even be evaluated. Refused here, on
        // every solver, before anything is changed.
        if let Some(i) = (0..n).find(|&i| {
            !(self.force[i].iter().all(|c| c.is_finite())
                && self.ws.b[i].iter().all(|c| c.is_finite()))
        }) {
            return Err(self.diverged(i, "force"));
        }
        // 3. solve
        self.captured = None;
        let guess = self
            .capture_at
            .contains(&self.steps)
            .then(|| self.dv.clone());
        let t_solve = Instant::now();
        let solved = match self.params.linear_solver {
            LinearSolverKind::Pcg => self.solve_pcg(
                linear::Cap::Hard(self.params.cg_max_iterations),
                linear::Preconditioner::BlockJacobi,
            ),
            LinearSolverKind::Sgs => self.solve_pcg(
                linear::Cap::Hard(self.params.cg_max_iterations),
                linear::Preconditioner::Sgs,
            ),
            LinearSolverKind::Cholesky => self.solve_direct(),
            LinearSolverKind::Auto => self.solve_auto(),
            LinearSolverKind::Amg => self.solve_amg_or_direct(),
        };
        let iterations = solved.map_err(|e| Error::StepFailed {
            step: self.steps,
            diagnosis: self.diagnose(),
            source: Box::new(e),
        })?;
        let solve_s = t_solve.elapsed().as_secs_f64();
        if let Some(guess) = guess {
            self.captured = Some(Box::new(LinearSystem {
                step: self.steps,
                time: self.time,
                dt: h,
                gravity: self.params.gravity,
                tolerance: self.params.cg_tolerance,
                a: self.ws.a.clone(),
                b: self.ws.b.clone(),
                filter: self.ws.filter.clone(),
                z: self.ws.z.clone(),
                guess,
                dv: self.dv.clone(),
                x: self.cloth.x.clone(),
                mass: self.cloth.mass.clone(),
                solved_by: self.solved_by,
                iterations,
            }));
        }
        // positions, velocities and time are unchanged yet: a failed step
        // leaves them as they were (the hysteresis memory was advanced to
        // these positions by the assembly, as the next step's would be)
        for i in 0..n {
            if !self.dv[i].iter().all(|c| c.is_finite()) {
                return Err(self.diverged(i, "velocity"));
            }
            if !self.ws.y[i].iter().all(|c| c.is_finite()) {
                return Err(self.diverged(i, "position correction"));
            }
        }
        // 4. obstacles move; velocities and positions, Coulomb stick/slip;
        //    no vertex may end inside a thickened obstacle
        let t_post = Instant::now();
        for ob in self.obstacles.iter_mut() {
            ob.advance(h);
        }
        self.finish(h);
        let own = self.resolve_self_contact(h, start);
        // (the hysteresis memory follows the new shape at the start of the next
        // assembly, fused with it; see `assemble`)
        self.time = t1;
        self.steps += 1;
        let collide_s = t_collide + t_post.elapsed().as_secs_f64() - own.time_s;
        self.last = StepStats {
            iterations,
            solved_by: self.solved_by,
            contacts,
            stuck,
            assemble_s,
            solve_s,
            collide_s,
            self_contacts: own.contacts,
            self_collisions: own.collisions,
            self_zones: own.zones,
            self_s: own.time_s,
            total_s: t_start.elapsed().as_secs_f64(),
        };
        Ok(self.last)
    }

    fn solve_pcg(&mut self, cap: linear::Cap, precond: linear::Preconditioner) -> Result<usize> {
        self.solved_by = match precond {
            linear::Preconditioner::BlockJacobi => SolvedBy::Pcg,
            linear::Preconditioner::Sgs => SolvedBy::Sgs,
        };
        let Workspace {
            pcg,
            a,
            b,
            filter,
            z,
            team,
            ..
        } = &mut self.ws;
        let tol = self.params.cg_tolerance;
        pcg.solve(a, b, filter, z, &mut self.dv, tol, cap, precond, team)
    }

    fn solve_direct(&mut self) -> Result<usize> {
        self.solved_by = SolvedBy::Cholesky;
        self.direct()?;
        let d = self.ws.direct.as_mut().expect("direct solver built");
        d.solve(
            &self.ws.a,
            &self.ws.b,
            &self.ws.filter,
            &self.ws.z,
            &self.cloth.mass,
            &mut self.dv,
        )?;
        Ok(1)
    }

    /// The multigrid hierarchy, built (patterns) on first use from the
    /// springs and seam stitches.
    fn amg(&mut self) -> Result<&mut amg::Amg> {
        if self.ws.amg.is_none() {
            let edges = sets::edges(&self.cloth);
            self.ws.amg = Some(amg::Amg::new(&self.ws.a, &edges)?);
        }
        Ok(self.ws.amg.as_mut().expect("multigrid built"))
    }

    /// The filtered PCG preconditioned by the multigrid hierarchy, refilled
    /// for this step.
    /// Where the hierarchy's first coarse level is swept, not solved exactly
    /// ([`amg::Amg::exact_bottom`]; the 0.5 cm table drape, the garments), it
    /// stops at [`AMG_SWEPT_TOLERANCE`] times the tolerance.
    fn solve_amg(&mut self, cap: linear::Cap) -> Result<usize> {
        self.solved_by = SolvedBy::Amg;
        let tol = if self.amg()?.exact_bottom() {
            self.params.cg_tolerance
        } else {
            self.params.cg_tolerance * AMG_SWEPT_TOLERANCE
        };
        let m = self.ws.amg.as_mut().expect("multigrid built");
        m.setup(&self.ws.a, &self.ws.filter, &self.cloth.mass, &self.cloth.x)?;
        let solved = self.ws.pcg.solve_factor(
            &self.ws.a,
            &self.ws.b,
            &self.ws.filter,
            &self.ws.z,
            &mut self.dv,
            tol,
            cap,
            m,
        );
        m.record(self.ws.pcg.spent());
        solved
    }

    /// `amg`: the multigrid PCG, or the exact Cholesky solve if it does not
    /// converge within `cg_max_iterations`.
    fn solve_amg_or_direct(&mut self) -> Result<usize> {
        match self.solve_amg(linear::Cap::Hard(self.params.cg_max_iterations)) {
            Ok(it) => Ok(it),
            Err(_) => {
                let spent = self.ws.pcg.spent();
                Ok(self.solve_direct()? + spent)
            }
        }
    }

    /// Uses the block-Jacobi PCG while it converges within the iterations
    /// that cost as much as the Cholesky ([`linear::Direct::break_even_iterations`],
    /// from operation counts), else the Cholesky (a single-precision factor
    /// refined by the PCG, see [`Simulation::solve_factored`]); on the
    /// Cholesky, the PCG is tried again after [`AUTO_PROBE`] steps, then
    /// after gaps doubled at each failed try up to [`AUTO_PROBE_MAX`]
    /// (capped at the same count, and given up as soon as the convergence
    /// so far shows the cap is out of reach, [`linear::Cap::Reachable`]:
    /// a failed try costs a few dozen iterations). The choice depends on
    /// iteration counts only, never on measured time, so a run gives the
    /// same trajectory every time. In place of the Cholesky it tries the
    /// multigrid PCG ([`Simulation::solve_heavy`]), and once that has solved
    /// a step the block-Jacobi PCG's cap is at most what that solve cost
    /// ([`Simulation::amg_price`]).
    fn solve_auto(&mut self) -> Result<usize> {
        let blocks = self.ws.a.col.len();
        let threads = self.ws.team.size();
        let cap = self.direct()?.break_even_iterations(blocks, threads);
        let cap = cap.min(self.params.cg_max_iterations);
        // where the multigrid solves (its coarse level exactly), the
        // block-Jacobi PCG gets the iterations its last solve cost instead,
        // if fewer
        let pcg_cap = self.auto.amg_price.map_or(cap, |p| p.min(cap));
        let probe = self.steps >= self.auto.next_probe;
        if !self.auto.on_direct || probe {
            match self.solve_pcg(
                linear::Cap::Reachable(pcg_cap),
                linear::Preconditioner::BlockJacobi,
            ) {
                Ok(it) => {
                    self.auto.on_direct = false;
                    self.auto.probe_gap = AUTO_PROBE;
                    return Ok(it);
                }
                Err(_) => {
                    self.auto.on_direct = true;
                    self.auto.next_probe = self.steps + self.auto.probe_gap;
                    self.auto.probe_gap = (2 * self.auto.probe_gap).min(AUTO_PROBE_MAX);
                    let spent = self.ws.pcg.spent();
                    let it = self.solve_heavy(cap)?;
                    return Ok(it + spent);
                }
            }
        }
        self.solve_heavy(cap)
    }

    /// `auto`'s solve where the block-Jacobi PCG needs more than `cap`
    /// iterations: the multigrid PCG within the cycles that cost as much as
    /// `cap` block-Jacobi iterations; else, or if it does not converge
    /// within them, the Cholesky ([`Simulation::solve_factored`]).
    fn solve_heavy(&mut self, cap: usize) -> Result<usize> {
        if self.steps < self.auto.next_amg {
            return self.solve_factored();
        }
        self.amg()?;
        let m = self.ws.amg.as_mut().expect("multigrid built");
        if self.auto.amg_last.map(|s| s + 1) != Some(self.steps) {
            // its kept coarse levels are of a step before the last
            m.refill();
        }
        let cycle = m.cycle_cost();
        let cycles = ((cap as f64 / cycle.max(1.0)).floor() as usize).max(1);
        let solved = self.solve_amg(linear::Cap::Hard(cycles));
        self.auto.amg_last = Some(self.steps);
        match solved {
            Ok(it) => {
                self.auto.amg_gap = AUTO_PROBE;
                self.auto.amg_price = Some(self.amg_price(it));
                Ok(it)
            }
            Err(_) => {
                // as the block-Jacobi PCG's tries: again after a gap doubled
                // at each failure (the drop onto the board, where the
                // multigrid needs hundreds)
                self.auto.next_amg = self.steps + self.auto.amg_gap;
                self.auto.amg_gap = (2 * self.auto.amg_gap).min(AUTO_PROBE_MAX);
                let spent = self.ws.pcg.spent();
                Ok(self.solve_factored()? + spent)
            }
        }
    }

    /// A multigrid solve of `iterations` (and the first cycle before them)
    /// in block-Jacobi PCG iterations, by operation counts
    /// ([`amg::Amg::exact_cycle_cost`], in products with the finest matrix,
    /// against [`linear::pcg_iteration_flops`]). On
    /// the 1 cm table drape at rest at dt = 1/300 s the multigrid takes 4–7
    /// iterations where the block-Jacobi PCG takes 57–106: the price, about
    /// 25–40, then sends those steps to the multigrid (which took 3.5–6.3 ms
    /// a step there against the PCG's 6.3–11.6).
    fn amg_price(&self, iterations: usize) -> usize {
        let m = self.ws.amg.as_ref().expect("multigrid built");
        let blocks = self.ws.a.col.len();
        // a product with the finest matrix: 9 multiply-adds a block
        let product = 18.0 * blocks.max(1) as f64;
        let pcg_iteration = linear::pcg_iteration_flops(blocks, 3 * self.ws.a.n) / product;
        ((iterations + 1) as f64 * m.exact_cycle_cost() / pcg_iteration).ceil() as usize
    }

    /// The Cholesky factor of this step's `S A S + (I − S) m` in single
    /// precision (faster to compute, half the memory traffic) as the
    /// preconditioner of the filtered PCG, which then converges in one or
    /// two iterations to the PCG tolerance; the double-precision factor and
    /// its exact solve if single precision fails (not positive definite in
    /// f32) or the PCG does not converge in [`F32_REFINE_CAP`] iterations.
    fn solve_factored(&mut self) -> Result<usize> {
        self.solved_by = SolvedBy::Cholesky;
        self.direct()?;
        let d = self.ws.direct.as_mut().expect("direct solver built");
        if d.factorize(
            &self.ws.a,
            &self.ws.filter,
            &self.cloth.mass,
            linear::Precision::F32,
        )
        .is_ok()
        {
            let Workspace {
                pcg,
                a,
                b,
                filter,
                z,
                direct,
                ..
            } = &mut self.ws;
            let d = direct.as_mut().expect("direct solver built");
            let (tol, cap) = (self.params.cg_tolerance, linear::Cap::Hard(F32_REFINE_CAP));
            if let Ok(it) = pcg.solve_factor(a, b, filter, z, &mut self.dv, tol, cap, d) {
                return Ok(it);
            }
        }
        self.solve_direct()
    }

    /// Phase 1 of a step on the team: pins and contacts (see
    /// [`vertices::constrain`]); returns the vertices in contact and, of
    /// those, the ones static friction holds.
    fn constrain(&mut self, h: f64, t1: f64) -> (usize, usize) {
        let scene = vertices::Scene {
            h,
            t1,
            cloth_thickness: self.params.cloth_thickness,
            obstacles: self.obstacles.as_slice(),
            bounds: &self.ws.bounds,
            pins: self.pins.as_slice(),
            pinned: &self.pinned,
            x: &self.cloth.x,
            v: &self.cloth.v,
            mass: &self.cloth.mass,
            force: &self.force,
            gravity: self.params.gravity,
            creases: self.params.creases,
            edge: if self.params.obstacle_edges {
                self.ws.self_contact.as_deref()
            } else {
                None
            },
        };
        let mut rows = vertices::split_rows!(
            &self.ws.part.bounds,
            vertices::ConstraintRows {
                filter: &mut self.ws.filter,
                z: &mut self.ws.z,
                y: &mut self.ws.y,
                contact_of: &mut self.ws.contact_of,
                friction_force: &mut self.friction_force,
                normals: &mut self.ws.normals,
                normals2: &mut self.ws.normals2,
                friction: &mut self.friction,
            },
            contacts: 0,
            stuck: 0,
        );
        self.ws
            .team
            .run_each(&mut rows, |_, r| vertices::constrain(&scene, r));
        (
            rows.iter().map(|r| r.contacts).sum(),
            rows.iter().map(|r| r.stuck).sum(),
        )
    }

    /// Phase 4 of a step on the team, after the obstacles moved: velocities,
    /// positions, stick/slip, and the push out of obstacles (see
    /// [`vertices::finish`]).
    fn finish(&mut self, h: f64) {
        let cloth_t = self.params.cloth_thickness;
        self.ws.bounds.clear();
        for ob in &self.obstacles {
            self.ws.bounds.push(ob.bounds(ob.thickness + cloth_t));
        }
        let solved = vertices::Solved {
            h,
            cloth_thickness: cloth_t,
            gravity: self.params.gravity.norm(),
            mass: &self.cloth.mass,
            a: &self.ws.a,
            b: &self.ws.b,
            dv: &self.dv,
            y: &self.ws.y,
            filter: &self.ws.filter,
            contact_of: &self.ws.contact_of,
            normals: &self.ws.normals,
            normals2: &self.ws.normals2,
            pinned: &self.pinned,
            obstacles: self.obstacles.as_slice(),
            bounds: &self.ws.bounds,
        };
        let mut rows = vertices::split_rows!(
            &self.ws.part.bounds,
            vertices::StateRows {
                x: &mut self.cloth.x,
                v: &mut self.cloth.v,
                friction: &mut self.friction,
            },
        );
        self.ws
            .team
            .run_each(&mut rows, |_, r| vertices::finish(&solved, r));
    }

    /// The triangle-mesh obstacles where they are now, into
    /// `ws.kinematic_x`: whether the set changed since the last call (other
    /// obstacles, or other vertex counts).
    fn kinematic_now(&mut self) -> bool {
        let mut x = std::mem::take(&mut self.ws.kinematic_x);
        let mut parts = std::mem::take(&mut self.ws.kinematic_next);
        x.clear();
        parts.clear();
        for (k, ob) in self.obstacles.as_slice().iter().enumerate() {
            let first = x.len();
            if ob.world_mesh_into(&mut x).is_some() {
                parts.push((k, first, x.len() - first));
            }
        }
        self.ws.kinematic_x = x;
        let changed = parts != self.ws.kinematic;
        self.ws.kinematic_next = std::mem::replace(&mut self.ws.kinematic, parts);
        changed
    }

    /// With [`Params::self_collision`] or [`Params::obstacle_edges`]: the
    /// cloth–cloth pass (built on the first step, which refuses a tangled
    /// start, and again when the triangle-mesh obstacles change) takes the
    /// positions at the start of the update. Whether it runs, and the time
    /// this took, s.
    fn begin_self_contact(&mut self) -> Result<Option<f64>> {
        let edges = self.params.obstacle_edges;
        if !self.params.self_collision && !edges {
            return Ok(None);
        }
        let t = Instant::now();
        let changed = if edges {
            self.kinematic_now()
        } else {
            let had = !self.ws.kinematic.is_empty();
            self.ws.kinematic.clear();
            had
        } || self.ws.self_pairs != self.params.self_collision;
        self.ws.self_pairs = self.params.self_collision;
        let first = self.ws.self_contact.is_none();
        if first || changed {
            let c = &self.cloth;
            let n = c.len();
            let mut stitches = Vec::new();
            for st in &c.seams {
                stitches.push([st.v[0], st.v[1]]);
                stitches.push([st.v[0], st.v[2]]);
            }
            let thickness = (0..n)
                .map(|i| self.fabric_of(i).layer_thickness())
                .collect();
            let friction = (0..n).map(|i| self.fabric_of(i).cloth_friction()).collect();
            let mut kin = crate::self_contact::Kinematic::default();
            if edges {
                let obstacles = self.obstacles.as_slice();
                for &(k, first, count) in &self.ws.kinematic {
                    let ob = &obstacles[k];
                    let tris = ob.mesh_triangles().unwrap_or_default();
                    kin.tris
                        .extend(tris.iter().map(|t| t.map(|v| first + v as usize)));
                    let e = ob.thickness + self.params.cloth_thickness;
                    kin.gap
                        .extend(std::iter::repeat_n(OBSTACLE_EDGE_GAP * e, count));
                    kin.friction.extend(std::iter::repeat_n(ob.friction, count));
                }
                kin.x = self.ws.kinematic_x.clone();
            }
            self.ws.self_contact =
                Some(Box::new(crate::self_contact::SelfContact::with_obstacles(
                    &c.x,
                    &c.triangles,
                    &stitches,
                    thickness,
                    friction,
                    kin,
                    self.params.self_collision,
                )?));
        }
        let sc = self.ws.self_contact.as_mut().expect("self-contact built");
        if edges {
            sc.set_obstacles(&self.ws.kinematic_x)?;
        }
        // a pass rebuilt for a new set of obstacles is not checked again: a
        // cloth caught on a new obstacle stays caught
        sc.begin(&self.cloth.x, first)?;
        Ok(Some(t.elapsed().as_secs_f64()))
    }

    /// The cloth–cloth pass after the update (see [`crate::self_contact`]).
    fn resolve_self_contact(
        &mut self,
        h: f64,
        begun: Option<f64>,
    ) -> crate::self_contact::SelfStats {
        let Some(begin_s) = begun else {
            return Default::default();
        };
        let t = Instant::now();
        if self.params.obstacle_edges {
            // the obstacles at the step's end (their set does not change
            // within a step)
            self.kinematic_now();
        }
        let Some(sc) = self.ws.self_contact.as_mut() else {
            return Default::default();
        };
        if self.params.obstacle_edges {
            // same count as at the step's start: cannot fail
            let _ = sc.set_obstacles(&self.ws.kinematic_x);
        }
        let (pinned, contact_of) = (&self.pinned, &self.ws.contact_of);
        let mut st = sc.resolve(
            h,
            &mut self.cloth.x,
            &mut self.cloth.v,
            &self.cloth.mass,
            &|i| pinned[i].is_some(),
            &|i| contact_of[i].is_some(),
        );
        st.time_s = begin_s + t.elapsed().as_secs_f64();
        st
    }

    /// With [`Params::obstacle_edges`]: the triangle-mesh obstacles'
    /// vertices the cloth pushed in the last step, with the force on each.
    pub fn edge_contacts(&self) -> Vec<EdgeContact> {
        let Some(sc) = self.ws.self_contact.as_ref() else {
            return Vec::new();
        };
        let h = self.params.dt;
        let parts = &self.ws.kinematic;
        sc.obstacle_impulses()
            .filter_map(|(b, cloth, p)| {
                let &(k, first, _) = parts
                    .iter()
                    .find(|&&(_, first, count)| b >= first && b < first + count)?;
                Some(EdgeContact {
                    obstacle: k,
                    vertex: b - first,
                    cloth_vertex: cloth,
                    force: p / h,
                    point: self.ws.kinematic_x[b],
                })
            })
            .collect()
    }

    fn commit_laws(&mut self) {
        sets::commit(&mut self.cloth, &self.fabric, &self.other_fabrics);
    }

    /// Builds `A` and `b` of the step, and the total force `self.force`.
    ///
    /// It first advances every spring's hysteresis memory to the current
    /// shape (the end of the previous step), in the same pass, and adds the
    /// energy the damping dissipates over this step (`−h vᵀ C v`).
    fn assemble(&mut self) {
        let power = assemble::assemble(
            self.params.dt,
            self.params.gravity,
            &self.fabric,
            &self.other_fabrics,
            &mut self.cloth,
            &self.ws.y,
            &self.ws.slots,
            &self.ws.part,
            &mut self.ws.a,
            &mut self.force,
            &mut self.ws.b,
            &mut self.ws.team,
        );
        self.dissipated -= self.params.dt * power;
    }

    /// The force each obstacle contact exerted on the cloth in the last
    /// step, N (zero for a vertex not in contact): the constraint's reaction
    /// `(A Δv − b)/h` of the filtered system (Baraff & Witkin 1998 §5: the
    /// residual of a constrained vertex is the impulse its constraint
    /// supplied) plus the kinetic friction force of a sliding contact. The
    /// force on the obstacles is its opposite.
    pub fn contact_forces(&self) -> Vec<Vector3<f64>> {
        let touching = |i: usize| self.ws.contact_of[i].is_some() && self.pinned[i].is_none();
        let mut out = self.reactions(touching);
        if self.steps > 0 {
            for (i, f) in out.iter_mut().enumerate() {
                if touching(i) {
                    *f += self.friction_force[i];
                }
            }
        }
        out
    }

    /// The constraint reaction `(A Δv − b)/h` of the last step at the
    /// vertices `which` selects, N (zero elsewhere and before any step).
    fn reactions(&self, which: impl Fn(usize) -> bool) -> Vec<Vector3<f64>> {
        let n = self.cloth.len();
        let mut out = vec![Vector3::zeros(); n];
        if self.steps == 0 {
            return out;
        }
        let mut adv = vec![Vector3::zeros(); n];
        self.ws.a.mul(&self.dv, &mut adv);
        let h = self.params.dt;
        for (i, o) in out.iter_mut().enumerate() {
            if which(i) {
                *o = (adv[i] - self.ws.b[i]) / h;
            }
        }
        out
    }

    /// The force each pin exerted on its vertex in the last step, N (zero
    /// for a vertex not pinned): the constraint's reaction `(A Δv − b)/h`,
    /// as for a contact in [`Simulation::contact_forces`]. What holds the
    /// cloth (a gripper) feels its opposite.
    pub fn pin_forces(&self) -> Vec<Vector3<f64>> {
        self.reactions(|i| self.pinned[i].is_some())
    }

    /// The outward normal of each vertex's obstacle contact in the last step
    /// (zero for a vertex not in contact).
    pub fn contact_normals(&self) -> Vec<Vector3<f64>> {
        (0..self.cloth.len())
            .map(|i| {
                if self.ws.contact_of[i].is_some() {
                    self.ws.normals[i]
                } else {
                    Vector3::zeros()
                }
            })
            .collect()
    }

    /// The error of a step that diverged at vertex `i` (a non-finite
    /// `what`), with [`Simulation::diagnose`].
    fn diverged(&self, i: usize, what: &'static str) -> Error {
        Error::Diverged {
            vertex: i,
            step: self.steps,
            time: self.time,
            quantity: what,
            pinned: self.pinned[i].is_some(),
            diagnosis: self.diagnose(),
        }
    }

    /// What most likely drove a failed step, from the state at its start:
    /// the most stretched tension spring and the most sheared diagonal
    /// (vertices, strain, the law's tangent there: a tangent ≤ 0 makes the
    /// system matrix indefinite), and the vertex the pins or contacts moved
    /// farthest this step. Computed only when a step fails.
    pub fn diagnose(&self) -> String {
        let c = &self.cloth;
        let mut parts = Vec::new();
        let worst = c
            .tension
            .iter()
            .enumerate()
            .map(|(k, s)| (k, s, (c.x[s.b] - c.x[s.a]).norm() / s.l0 - 1.0))
            .filter(|(_, _, e)| e.is_finite())
            .max_by(|a, b| a.2.abs().total_cmp(&b.2.abs()));
        if let Some((k, s, e)) = worst {
            let (_, tangent) = self.fabric_of(s.a).dir(s.weft).tensile.elastic.eval(e);
            parts.push(format!(
                "most stretched: tension spring {k} ({} vertices {}–{}) at strain {e:.3e}, \
                 tensile law tangent {tangent:.3e} N/m{}",
                if s.weft { "weft" } else { "warp" },
                s.a,
                s.b,
                if tangent <= 0.0 {
                    " (≤ 0: outside the fabric's measured range)"
                } else {
                    ""
                }
            ));
        }
        // the shear family's elements: diagonal springs, or cells (one set is empty)
        let springs = c.shear.iter().enumerate().map(|(k, s)| {
            let e = s.strain((c.x[s.b] - c.x[s.a]).norm());
            (k, [s.a, s.b, 0, 0], false, e)
        });
        let cells = (c.shear_cells.iter().enumerate()).map(|(k, s)| (k, s.v, true, s.strain(&c.x)));
        let worst = springs
            .chain(cells)
            .filter(|w| w.3.is_finite())
            .max_by(|a, b| a.3.abs().total_cmp(&b.3.abs()));
        if let Some((k, v, cell, e)) = worst {
            let (_, tangent) = self.fabric_of(v[0]).shear.elastic.eval(e);
            let which = if cell {
                format!("cell {k} (diagonals {}–{}, {}–{})", v[0], v[1], v[2], v[3])
            } else {
                format!("diagonal {k} (vertices {}–{})", v[0], v[1])
            };
            parts.push(format!(
                "most sheared: {which} at sin θ = {e:.3e}, shear law tangent {tangent:.3e} N/m"
            ));
        }
        let moved = self
            .ws
            .y
            .iter()
            .enumerate()
            .map(|(i, y)| (i, y.norm()))
            .max_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((i, d)) = moved.filter(|(_, d)| *d > 0.0) {
            parts.push(format!(
                "largest move imposed this step: vertex {i} by {d:.3e} m ({})",
                match self.pinned[i] {
                    Some(p) => format!("pin {p}"),
                    None => "a contact".into(),
                }
            ));
        }
        parts.join("; ")
    }

    /// Energies of the current state (elastic parts of the laws).
    pub fn energies(&self) -> Energies {
        let c = &self.cloth;
        let mut e = Energies {
            dissipated_damping: self.dissipated,
            ..Default::default()
        };
        for i in 0..c.len() {
            e.kinetic += 0.5 * c.mass[i] * c.v[i].norm_squared();
            e.gravity -= c.mass[i] * self.params.gravity.dot(&c.x[i]);
        }
        sets::energies(c, &self.fabric_lookup(), &mut e);
        e
    }

    /// Internal (spring) forces only, at the current positions and memory.
    pub fn internal_forces(&self) -> Vec<Vector3<f64>> {
        let mut out = self.family_forces(family::Family::Tension);
        for fam in [family::Family::Shear, family::Family::Bending] {
            for (o, f) in out.iter_mut().zip(self.family_forces(fam)) {
                *o += f;
            }
        }
        out
    }

    /// Root-mean-square speed of the free vertices, m/s.
    pub fn rms_speed(&self) -> f64 {
        let mut s = 0.0;
        let mut n = 0;
        for i in 0..self.cloth.len() {
            if self.pinned[i].is_none() {
                s += self.cloth.v[i].norm_squared();
                n += 1;
            }
        }
        if n == 0 {
            0.0
        } else {
            (s / n as f64).sqrt()
        }
    }

    /// Is vertex i pinned?
    pub fn is_pinned(&self, i: usize) -> bool {
        self.pinned[i].is_some()
    }

    /// The system matrix and right-hand side of the next step, assembled now
    /// without advancing (tests compare serial and threaded assembly).
    pub fn assembled_system(&mut self) -> (Vec<nalgebra::Matrix3<f64>>, Vec<Vector3<f64>>) {
        let (memories, dissipated) = (sets::memories(&self.cloth), self.dissipated);
        self.assemble();
        let out = (self.ws.a.val.clone(), self.ws.b.clone());
        sets::put_memories(&mut self.cloth, memories);
        self.dissipated = dissipated;
        out
    }
}

/// A sliding vertex slower than this (relative to the obstacle) sticks, m/s.
/// On a moving surface so does one whose sliding reversed over the step: it
/// passed through rest relative to the surface, where static friction takes
/// over. (The surface's own velocity changes from step to step: on a body
/// turning at 1 rad/s, by ω² r h = 1.25 mm/s at r = 15 cm and h = 1/120 s,
/// so the relative velocity left after a step is seldom under this speed.)
pub const STICK_SPEED: f64 = 1e-3;

/// Contact forces below this fraction of a vertex's weight are below what
/// the solve resolves: a contact stays pressed, and static friction holds,
/// within it.
pub const FRICTION_FLOOR: f64 = 1e-3;

/// Coulomb friction state of a vertex in contact.
#[derive(Debug, Clone, Copy, Default)]
struct FrictionState {
    /// Stuck last step, or slid slower than [`STICK_SPEED`] (or reversed its
    /// sliding on a moving surface): the next constraint phase holds it if
    /// static friction can.
    stick: bool,
    /// Normal impulse of the last step, N·s.
    impulse: f64,
}

/// Most threads a simulation may be given ([`Params::threads`]).
pub const MAX_THREADS: usize = 64;

/// PCG iterations allowed with the single-precision factor before the
/// double-precision one is used.
pub const F32_REFINE_CAP: usize = 20;

/// Steps between two tries of the PCG while `auto` mode is on the Cholesky,
/// at first: each failed try doubles the gap, up to [`AUTO_PROBE_MAX`].
pub const AUTO_PROBE: u64 = 25;

/// Where the multigrid's first coarse level is swept, its solves (in `auto`
/// and `amg`) stop at this fraction of the tolerance. At the tolerance itself
/// the 0.5 cm table drape at dt = 1/120 s never comes to rest: it slides on
/// at 7–8 mm/s after 3 s, where the block-Jacobi PCG's and the Cholesky's
/// drapes settle at 1.37 s; at a hundredth it settles at 1.33–1.35 s, in as
/// many iterations a step (docs/benchmarks.md, "`auto`"). A lead, not shown:
/// stick or slip is decided on a contact's constraint impulse, which the
/// filtered residual's test does not bound.
pub const AMG_SWEPT_TOLERANCE: f64 = 1e-2;

/// Largest gap between two tries of the PCG (a failed try costs the
/// break-even count of iterations: at most a few per cent of the time).
pub const AUTO_PROBE_MAX: u64 = 200;
