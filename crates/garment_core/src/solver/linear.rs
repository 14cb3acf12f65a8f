//! The two linear solvers behind one interface: Baraff–Witkin's modified
//! (filtered) preconditioned conjugate gradient, and a direct sparse Cholesky
//! (faer) whose symbolic analysis is computed once and reused.
//!
//! Both solve `A Δv = b` subject to the per-vertex constraint filter of
//! Baraff & Witkin (1998, §5.3): `Δv_i = S_i Δv_i + z_i`, where `S_i` is the
//! identity (free), `I − n nᵀ` (contact along n), or 0 (pinned), and `z_i`
//! is the prescribed velocity change in the constrained directions.

use super::cpu::has_fma;
use super::sparse::{BlockMatrix, LowerCsc, Triangles};
use super::team::{Stages, Team};
use crate::error::{Error, Result};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::cell::UnsafeCell;
use std::sync::atomic::{AtomicU64, Ordering};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
/// Which linear solver a step uses.
pub enum LinearSolverKind {
    /// Filtered preconditioned conjugate gradient (block-Jacobi preconditioner).
    Pcg,
    /// The filtered PCG preconditioned by symmetric block Gauss–Seidel
    /// (`Preconditioner::Sgs`).
    Sgs,
    /// Sparse Cholesky (faer), symbolic factorisation reused.
    Cholesky,
    /// The default: the block-Jacobi PCG while it converges within the
    /// iterations that cost as much as the Cholesky (from operation counts),
    /// else the Cholesky factor (single precision, refined by the PCG). By
    /// benchmark (docs/benchmarks.md) the block-Jacobi PCG wins at small
    /// steps (dt = 1e-4 s: 7–25 iterations), the Cholesky at large ones and
    /// on the garment trials; where the multigrid's hierarchy has two levels
    /// whose coarse one is solved exactly (the 1 cm table drape), the
    /// multigrid PCG (`amg`) in place of the Cholesky (see
    /// `Simulation::solve_heavy`), and then in place of the block-Jacobi
    /// PCG too where that would need more iterations than the multigrid's
    /// last solve cost (see `Simulation::solve_auto`). Decided on iteration counts, never on
    /// measured time: runs are reproducible.
    #[default]
    Auto,
    /// The filtered PCG preconditioned by smoothed-aggregation multigrid
    /// (`super::amg`).
    Amg,
}

impl std::str::FromStr for LinearSolverKind {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "pcg" => Ok(Self::Pcg),
            "sgs" => Ok(Self::Sgs),
            "cholesky" => Ok(Self::Cholesky),
            "auto" => Ok(Self::Auto),
            "amg" => Ok(Self::Amg),
            _ => Err(Error::invalid(format!(
                "unknown linear solver {s:?}: expected auto, pcg, sgs, amg or cholesky"
            ))),
        }
    }
}

/// The constraint on one vertex for this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Filter {
    /// Unconstrained.
    Free,
    /// In contact: motion along `normal` is prescribed.
    Normal(Vector3<f64>),
    /// In a crease, in contact with two surfaces: motion is free only along
    /// the unit `axis` (the crease's line, the two normals' cross product);
    /// both normals' directions are prescribed. `S = a aᵀ`.
    Crease(Vector3<f64>),
    /// Fully prescribed (pinned).
    Fixed,
}

impl Filter {
    #[inline]
    /// `S v`.
    pub fn apply(&self, v: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Filter::Free => *v,
            Filter::Normal(n) => v - n * n.dot(v),
            Filter::Crease(a) => a * a.dot(v),
            Filter::Fixed => Vector3::zeros(),
        }
    }
    /// `S m`
    #[inline]
    pub fn left(&self, m: &Matrix3<f64>) -> Matrix3<f64> {
        match self {
            Filter::Free => *m,
            Filter::Normal(n) => m - n * (n.transpose() * m),
            Filter::Crease(a) => a * (a.transpose() * m),
            Filter::Fixed => Matrix3::zeros(),
        }
    }
    /// `m S`
    #[inline]
    pub fn right(&self, m: &Matrix3<f64>) -> Matrix3<f64> {
        match self {
            Filter::Free => *m,
            Filter::Normal(n) => m - (m * n) * n.transpose(),
            Filter::Crease(a) => (m * a) * a.transpose(),
            Filter::Fixed => Matrix3::zeros(),
        }
    }
    #[inline]
    /// `S` as a matrix.
    pub fn matrix(&self) -> Matrix3<f64> {
        match self {
            Filter::Free => Matrix3::identity(),
            Filter::Normal(n) => Matrix3::identity() - n * n.transpose(),
            Filter::Crease(a) => a * a.transpose(),
            Filter::Fixed => Matrix3::zeros(),
        }
    }
}

/// When [`Pcg::solve`] stops without converging.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cap {
    /// After this many iterations.
    Hard(usize),
    /// After this many, or as soon as the convergence so far shows they
    /// will not do — for a caller with a cheaper alternative (`auto`'s tries
    /// of the PCG): from [`EARLY_FROM`] iterations on, every 8, when the mean
    /// rate of the residual's decrease so far would need more iterations
    /// than the cap to reach the tolerance. On the cloth's systems the rate
    /// mostly slows as the iterations go (the easy components go first): the
    /// tries that converge stay below the cap, and one that would not stops
    /// after a few dozen iterations instead of the cap. Where CG speeds up
    /// instead (a clustered spectrum), a try that would have converged may be
    /// given up; since `auto`'s cap is the break-even count, the Cholesky it
    /// then takes costs about as much. Decided on residuals only:
    /// reproducible.
    Reachable(usize),
}

/// The preconditioner of [`Pcg::solve`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Preconditioner {
    /// The inverses of the 3 × 3 diagonal blocks (Baraff & Witkin 1998).
    BlockJacobi,
    /// Symmetric block Gauss–Seidel, one sweep each way per thread's rows,
    /// applied in Eisenstat's form (see [`SgsRows`]): an iteration
    /// reads the matrix about once, as a block-Jacobi one does, and the
    /// table drape at the thesis step needs 2.0–2.6 times fewer of them
    /// (docs/benchmarks.md).
    Sgs,
}

/// Workspace of the filtered PCG.
#[derive(Debug, Clone, Default)]
pub struct Pcg {
    r: Vec<Vector3<f64>>,
    c: Vec<Vector3<f64>>,
    q: Vec<Vector3<f64>>,
    s: Vec<Vector3<f64>>,
    pinv: Vec<Matrix3<f64>>,
    /// [`Preconditioner::Sgs`]: the backward sweep's output, the filtered
    /// diagonal blocks, where each row's blocks of its own thread end, and
    /// the copies of the lower and upper triangles (see [`SgsRows`]).
    t: Vec<Vector3<f64>>,
    dblk: Vec<Matrix3<f64>>,
    split: Vec<[u32; 2]>,
    lval: Vec<Matrix3<f64>>,
    uval: Vec<Matrix3<f64>>,
    /// Iterations of the last [`Pcg::solve`], also when it failed.
    spent: usize,
    /// Gravity's impulse on each vertex over a step, `m g h` (empty: none):
    /// the floor of the convergence test's reference, see [`Pcg::set_scale`].
    scale: Vec<Vector3<f64>>,
}

impl Pcg {
    /// Iterations the last solve ran, whether it converged or not.
    pub fn spent(&self) -> usize {
        self.spent
    }

    /// Sets gravity's impulse on each vertex over the step, `m g h` (`gh` =
    /// g h), in place. The convergence test measures the residual against
    /// the larger of the filtered right-hand side and this impulse (filtered,
    /// in the same norm): on a cloth at rest the right-hand side is tiny, and
    /// a test relative to it alone asks for round-off (hundreds of iterations
    /// to change Δv by nanometres per second). Never set: relative only.
    pub fn set_scale(&mut self, mass: &[f64], gh: Vector3<f64>) {
        self.scale.clear();
        self.scale.extend(mass.iter().map(|&m| gh * m));
    }

    /// Solves with relative tolerance `tol` on the filtered, preconditioned
    /// residual (relative to the right-hand side's, so the start does not
    /// change when it stops), preconditioned by `precond`; `dv` holds the
    /// first guess (its filtered part; zeros for none) and then the
    /// solution. Returns the iteration count; an error when `cap` stops it
    /// (see [`Cap`]) or the matrix is not positive definite.
    ///
    /// The solve runs in stages on the threads of `team` (the
    /// simulation's, started once; see [`super::team::threads_for`]): the
    /// rows are cut into one contiguous range per thread, and a stage's
    /// part on a range (the product or its sweeps, the vector updates, the
    /// range's share of the dot products) runs on whichever thread takes
    /// it ([`Team::run_stages`]); three stages per iteration, partial sums
    /// added in range order, so the result depends on the number of
    /// ranges (the team's size), never on which thread ran what.
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        a: &BlockMatrix,
        b: &[Vector3<f64>],
        filter: &[Filter],
        z: &[Vector3<f64>],
        dv: &mut [Vector3<f64>],
        tol: f64,
        cap: Cap,
        precond: Preconditioner,
        team: &mut Team,
    ) -> Result<usize> {
        let (max_iter, early) = match cap {
            Cap::Hard(n) => (n, false),
            Cap::Reachable(n) => (n, true),
        };
        let n = a.n;
        self.r.resize(n, Vector3::zeros());
        self.c.resize(n, Vector3::zeros());
        self.q.resize(n, Vector3::zeros());
        self.s.resize(n, Vector3::zeros());
        self.pinv.resize(n, Matrix3::zeros());
        // the pattern's triangles (made once per matrix), whose values the
        // sweeps copy at each solve
        let tri = (precond == Preconditioner::Sgs).then(|| a.triangles());
        if let Some(tri) = tri {
            self.t.resize(n, Vector3::zeros());
            self.dblk.resize(n, Matrix3::zeros());
            self.split.resize(n, [0; 2]);
            self.lval.resize(tri.lcol.len(), Matrix3::zeros());
            self.uval.resize(tri.ucol.len(), Matrix3::zeros());
        }
        let nt = team.size().min(n).max(1);
        let sh = Shared {
            r: Ptr(self.r.as_mut_ptr()),
            c: Ptr(self.c.as_mut_ptr()),
            q: Ptr(self.q.as_mut_ptr()),
            s: Ptr(self.s.as_mut_ptr()),
            pinv: Ptr(self.pinv.as_mut_ptr()),
            dv: Ptr(dv.as_mut_ptr()),
            t: Ptr(self.t.as_mut_ptr()),
            dblk: Ptr(self.dblk.as_mut_ptr()),
            split: Ptr(self.split.as_mut_ptr()),
            lval: Ptr(self.lval.as_mut_ptr()),
            uval: Ptr(self.uval.as_mut_ptr()),
            partial: (0..SLOTS * nt).map(|_| AtomicU64::new(0)).collect(),
            nt,
        };
        let args = PcgArgs {
            early,
            a,
            b,
            filter,
            z,
            tol,
            max_iter,
            scale: &self.scale,
            tri,
        };
        let (it, result) = match precond {
            Preconditioner::BlockJacobi => Solve::<JacobiRows>::new(&args, &sh).run(team),
            Preconditioner::Sgs => Solve::<SgsRows>::new(&args, &sh).run(team),
        };
        self.spent = it;
        result
    }

    /// The filtered PCG preconditioned by the Cholesky factor `P = L Lᵀ` held
    /// by `direct` (`S P⁻¹ S`; in `auto`, this step's single-precision
    /// factor of `S A S + (I − S) m`). It starts from the prescribed part `z`
    /// and stops on [`Pcg::solve`]'s test, Baraff–Witkin's: the filtered
    /// residual in the block-Jacobi norm, `rᵀ D⁻¹ r ≤ tol² · (S b)ᵀ D⁻¹ (S b)`
    /// (`D` = the 3 × 3 diagonal blocks of A), the reference floored by
    /// gravity's impulse ([`Pcg::set_scale`]). That test costs a block-diagonal
    /// product, not a triangular solve with the factor, so an iteration
    /// applies the factor only when it goes on: a step that converges in k
    /// iterations applies it k times. One thread.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_factor(
        &mut self,
        a: &BlockMatrix,
        b: &[Vector3<f64>],
        filter: &[Filter],
        z: &[Vector3<f64>],
        dv: &mut [Vector3<f64>],
        tol: f64,
        cap: Cap,
        direct: &mut impl Precond,
    ) -> Result<usize> {
        let (max_iter, early) = match cap {
            Cap::Hard(n) => (n, false),
            Cap::Reachable(n) => (n, true),
        };
        let n = a.n;
        for v in [&mut self.r, &mut self.c, &mut self.q, &mut self.s] {
            v.resize(n, Vector3::zeros());
        }
        self.pinv.resize(n, Matrix3::zeros());
        let fma = has_fma();
        self.spent = 0;
        dv.copy_from_slice(z);
        // δ0 = (S b)ᵀ D⁻¹ (S b), and the first residual in the same norm
        let (mut delta0, mut rj, mut floor) = (0.0, 0.0, 0.0);
        for i in 0..n {
            self.pinv[i] = block_jacobi(&a.val[a.diag[i]]);
            let (d, g) = reference_terms(&filter[i], &b[i], self.scale.get(i), &self.pinv[i]);
            delta0 += d;
            floor += g;
            self.r[i] = filter[i].apply(&(b[i] - row_mul_best(fma, a, i, dv)));
            rj += self.r[i].dot(&(self.pinv[i] * self.r[i]));
        }
        if !(delta0.is_finite() && rj.is_finite()) {
            return Err(Error::breakdown("non-finite right-hand side"));
        }
        // the reference: the right-hand side, or gravity's impulse if larger
        let delta0 = delta0.max(floor);
        let eps2 = tol * tol * delta0;
        if delta0 <= 0.0 && !zero_rhs(b, filter) {
            return Err(Error::breakdown(
                "the right-hand side's norm underflows (the system is scaled \
                 out of range)",
            ));
        }
        if delta0 <= 0.0 || rj <= eps2 {
            return Ok(0);
        }
        let mut dnew = direct.apply_dot(a, filter, &self.r, &mut self.s);
        self.c.copy_from_slice(&self.s);
        if !(dnew.is_finite() && dnew > 0.0) {
            return Err(Error::breakdown("non-finite preconditioned residual"));
        }
        let mut it = 0;
        loop {
            capped(it, rj / delta0, tol, max_iter, early)?;
            let mut cq = 0.0;
            for i in 0..n {
                let v = filter[i].apply(&row_mul_best(fma, a, i, &self.c));
                self.q[i] = v;
                cq += self.c[i].dot(&v);
            }
            if cq <= 0.0 || !cq.is_finite() {
                return Err(Error::breakdown(format!(
                    "the system matrix is not positive definite (cᵀAc = {cq:e})"
                )));
            }
            let alpha = dnew / cq;
            rj = 0.0;
            for i in 0..n {
                dv[i] += self.c[i] * alpha;
                self.r[i] -= self.q[i] * alpha;
                rj += self.r[i].dot(&(self.pinv[i] * self.r[i]));
            }
            it += 1;
            self.spent = it;
            if rj <= eps2 {
                return Ok(it);
            }
            if !rj.is_finite() {
                return Err(Error::breakdown("non-finite residual"));
            }
            let dold = dnew;
            dnew = direct.apply_dot(a, filter, &self.r, &mut self.s);
            if !(dnew.is_finite() && dnew > 0.0) {
                return Err(Error::breakdown("non-finite preconditioned residual"));
            }
            let beta = dnew / dold;
            for i in 0..n {
                self.c[i] = self.s[i] + self.c[i] * beta;
            }
        }
    }
}

/// Whether the filtered right-hand side is zero (every thread of a solve
/// gets the same answer).
fn zero_rhs(b: &[Vector3<f64>], filter: &[Filter]) -> bool {
    b.iter()
        .zip(filter)
        .all(|(b, f)| f.apply(b) == Vector3::zeros())
}

/// A preconditioner of [`Pcg::solve_factor`]: `out ≈ S Â⁻¹ r` for
/// `Â = S A S + (I − S) m` of this step's matrix `a` and filter, and
/// `rᵀ out`, the PCG's next `δ`, summed as `out` is written.
pub trait Precond {
    fn apply_dot(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        r: &[Vector3<f64>],
        out: &mut [Vector3<f64>],
    ) -> f64;
}

impl Precond for Direct {
    /// The factor held ([`Direct::apply`]), its output filtered.
    fn apply_dot(
        &mut self,
        _: &BlockMatrix,
        filter: &[Filter],
        r: &[Vector3<f64>],
        out: &mut [Vector3<f64>],
    ) -> f64 {
        self.apply(r, out);
        let mut d = 0.0;
        for i in 0..r.len() {
            out[i] = filter[i].apply(&out[i]);
            d += r[i].dot(&out[i]);
        }
        d
    }
}

/// The block-Jacobi preconditioner's block for the diagonal block `d`: its
/// inverse, or the inverse of its diagonal if it is singular.
#[inline]
fn block_jacobi(d: &Matrix3<f64>) -> Matrix3<f64> {
    d.try_inverse()
        .unwrap_or_else(|| Matrix3::from_diagonal(&d.diagonal().map(|x| 1.0 / x.max(1e-300))))
}

/// Iterations after which a [`Cap::Reachable`] solve may give up early.
pub const EARLY_FROM: usize = 16;

/// Whether, after `it` iterations that took the squared residual ratio to
/// `ratio2`, reaching `tol` at the mean rate so far would take more than
/// `max_iter` iterations.
fn out_of_reach(it: usize, ratio2: f64, tol: f64, max_iter: usize) -> bool {
    if it < EARLY_FROM || ratio2.is_nan() || ratio2 <= 0.0 {
        return false;
    }
    // ratio2 ≥ 1 (no progress at all) counts as out of reach
    let per_iter = ratio2.ln() / (2.0 * it as f64);
    per_iter >= 0.0 || tol.ln() / per_iter > max_iter as f64
}

/// One row's terms of the convergence test's reference, in the norm of the
/// block-diagonal inverse `dinv`: the filtered right-hand side's
/// `(S b)ᵀ D⁻¹ (S b)`, and gravity's impulse `w` ([`Pcg::set_scale`]; none:
/// 0) the same way, the floor of that reference.
#[inline(always)]
fn reference_terms(
    f: &Filter,
    b: &Vector3<f64>,
    w: Option<&Vector3<f64>>,
    dinv: &Matrix3<f64>,
) -> (f64, f64) {
    let fb = f.apply(b);
    let floor = w.map_or(0.0, |w| {
        let fw = f.apply(w);
        fw.dot(&(dinv * fw))
    });
    (fb.dot(&(dinv * fb)), floor)
}

/// The error that stops a solve after `it` iterations whose squared
/// residual ratio is `ratio2`: at the cap `max_iter`, or, with `early`
/// ([`Cap::Reachable`]), every 8 iterations once the cap is out of reach.
fn capped(it: usize, ratio2: f64, tol: f64, max_iter: usize, early: bool) -> Result<()> {
    if it >= max_iter {
        return Err(Error::NotConverged {
            max_iterations: max_iter,
            residual_ratio: ratio2.sqrt(),
            stopped_at: None,
        });
    }
    if early && it.is_multiple_of(8) && out_of_reach(it, ratio2, tol, max_iter) {
        return Err(Error::NotConverged {
            max_iterations: max_iter,
            residual_ratio: ratio2.sqrt(),
            stopped_at: Some(it),
        });
    }
    Ok(())
}

/// Inputs of a PCG solve shared by its threads.
struct PcgArgs<'a> {
    /// Give up when the cap is out of reach ([`Cap::Reachable`]).
    early: bool,
    a: &'a BlockMatrix,
    b: &'a [Vector3<f64>],
    filter: &'a [Filter],
    z: &'a [Vector3<f64>],
    tol: f64,
    max_iter: usize,
    /// [`Pcg::set_scale`] (empty: none).
    scale: &'a [Vector3<f64>],
    /// The matrix's triangles ([`Preconditioner::Sgs`]; none otherwise).
    tri: Option<&'a Triangles>,
}

/// Partial sums a range of a PCG solve keeps ([`Shared::put`]).
const SLOTS: usize = 4;

#[derive(Clone, Copy)]
struct Ptr<T>(*mut T);
unsafe impl<T> Send for Ptr<T> {}
unsafe impl<T> Sync for Ptr<T> {}

/// The PCG vectors, written by row ranges (a stage's part only its own
/// rows; `c` is read whole by the product, a stage after it is written).
struct Shared {
    r: Ptr<Vector3<f64>>,
    c: Ptr<Vector3<f64>>,
    q: Ptr<Vector3<f64>>,
    s: Ptr<Vector3<f64>>,
    pinv: Ptr<Matrix3<f64>>,
    dv: Ptr<Vector3<f64>>,
    t: Ptr<Vector3<f64>>,
    dblk: Ptr<Matrix3<f64>>,
    split: Ptr<[u32; 2]>,
    lval: Ptr<Matrix3<f64>>,
    uval: Ptr<Matrix3<f64>>,
    /// Per-range partial sums, [`SLOTS`] per range.
    partial: Vec<AtomicU64>,
    /// Row ranges.
    nt: usize,
}

impl Shared {
    fn put(&self, t: usize, slot: usize, v: f64) {
        self.partial[SLOTS * t + slot].store(v.to_bits(), Ordering::Relaxed);
    }
    /// Sum of every range's partial in `slot` (once the stage that wrote
    /// them is over), in range order.
    fn sum(&self, slot: usize) -> f64 {
        (0..self.nt)
            .map(|t| f64::from_bits(self.partial[SLOTS * t + slot].load(Ordering::Relaxed)))
            .sum()
    }
}

/// What the parts of a stage of a PCG solve do ([`Solve`]), each on its
/// range of rows.
#[derive(Clone, Copy)]
enum Work {
    /// The preconditioner's rows, the reference's terms, the first guess.
    Setup,
    /// The first residual, search direction and norms.
    Start,
    /// The test's norm of the true residual (the tracked norm has reached
    /// its target, [`RowPrecond::CONFIRMS`]).
    Confirm,
    /// `c = S (s + β c)` (none: the first direction, made by `Start`), then
    /// the product's first part ([`RowPrecond::product_first`]).
    Direction(Option<f64>),
    /// `q` = the operator times `c`, and `cᵀ q`.
    Product,
    /// `Δv += α c`, `r −= α q`, `s` from `r`, and `rᵀ s` (the new `δ`).
    Update(f64),
}

/// What comes after a stage: another, or the end (iterations run).
enum Flow {
    Go(Work),
    Done(usize),
}

/// The scalars of a solve, kept by the thread that closes each stage.
#[derive(Default)]
struct Lead {
    delta0: f64,
    eps2: f64,
    dnew: f64,
    dold: f64,
    target: f64,
    beta: Option<f64>,
    it: usize,
}

impl Lead {
    /// After every range has done `done`: what comes next.
    fn next<'a, P: RowPrecond<'a>>(
        &mut self,
        sh: &Shared,
        args: &PcgArgs,
        done: Work,
    ) -> Result<Flow> {
        match done {
            Work::Setup => {
                // the reference: the right-hand side, or gravity's impulse
                // if larger
                self.delta0 = sh.sum(0).max(sh.sum(2));
                Ok(Flow::Go(Work::Start))
            }
            Work::Start => self.started::<P>(sh, args),
            Work::Confirm => {
                let rho = sh.sum(3);
                if !rho.is_finite() {
                    return Err(Error::breakdown(format!(
                        "non-finite residual after {} iterations",
                        self.it
                    )));
                }
                match P::confirmed(rho, self.dnew, self.eps2) {
                    None => Ok(Flow::Done(self.it)),
                    Some(target) => {
                        self.target = target;
                        self.go_on::<P>(args)
                    }
                }
            }
            Work::Direction(_) => Ok(Flow::Go(Work::Product)),
            Work::Product => {
                let cq = sh.sum(2);
                if cq <= 0.0 || !cq.is_finite() {
                    return Err(Error::breakdown(format!(
                        "the system matrix is not positive definite (cᵀAc = {cq:e})"
                    )));
                }
                self.dold = self.dnew;
                Ok(Flow::Go(Work::Update(self.dnew / cq)))
            }
            Work::Update(_) => {
                self.dnew = sh.sum(1);
                if !self.dnew.is_finite() {
                    return Err(Error::breakdown(format!(
                        "non-finite residual after {} iterations",
                        self.it + 1
                    )));
                }
                self.beta = Some(self.dnew / self.dold);
                self.it += 1;
                self.head::<P>(args)
            }
        }
    }

    /// After the first residual: the test's terms, then the first iteration.
    fn started<'a, P: RowPrecond<'a>>(&mut self, sh: &Shared, args: &PcgArgs) -> Result<Flow> {
        let (delta0, dnew) = (self.delta0, sh.sum(1));
        let rho = P::CONFIRMS.then(|| sh.sum(3));
        // a non-finite reference or residual would end the loop at once
        // (NaN compares false) and pass the first guess off as the solution
        if !(delta0.is_finite() && dnew.is_finite() && rho.is_none_or(f64::is_finite)) {
            return Err(Error::breakdown(format!(
                "non-finite right-hand side or residual (δ0 = {delta0:e}, \
                 rᵀM⁻¹r = {dnew:e}{})",
                rho.map_or(String::new(), |rho| format!(", rᵀD⁻¹r = {rho:e}"))
            )));
        }
        if delta0 <= 0.0 {
            // nothing to solve only if the right-hand side is zero: a
            // non-zero one whose norm underflows (a system scaled out of
            // range, a cloth stretched by orders of magnitude) is not a
            // converged solve
            return match zero_rhs(args.b, args.filter) {
                true => Ok(Flow::Done(0)),
                false => Err(Error::breakdown(
                    "the right-hand side's norm underflows (the system is scaled \
                     out of range)",
                )),
            };
        }
        self.eps2 = args.tol * args.tol * delta0;
        self.dnew = dnew;
        let Some(target) = P::first_target(self.eps2, dnew, rho) else {
            return Ok(Flow::Done(0));
        };
        self.target = target;
        self.head::<P>(args)
    }

    /// At the top of an iteration: the test, else the caps, else the
    /// iteration.
    fn head<'a, P: RowPrecond<'a>>(&mut self, args: &PcgArgs) -> Result<Flow> {
        if self.dnew <= self.target {
            return Ok(match P::CONFIRMS {
                true => Flow::Go(Work::Confirm),
                false => Flow::Done(self.it),
            });
        }
        self.go_on::<P>(args)
    }

    fn go_on<'a, P: RowPrecond<'a>>(&mut self, args: &PcgArgs) -> Result<Flow> {
        let ratio = P::ratio(self.dnew, self.target, self.delta0, args.tol);
        capped(self.it, ratio, args.tol, args.max_iter, args.early)?;
        // the first direction needs a stage of its own only for a product
        // in two parts
        Ok(Flow::Go(match (self.beta, P::PRODUCT_FIRST) {
            (None, false) => Work::Product,
            (beta, _) => Work::Direction(beta),
        }))
    }
}

/// A filtered PCG solve preconditioned by `P`, in stages ([`Stages`]) whose
/// parts are the row ranges ([`Rows`]): each part keeps its range's
/// preconditioner, and the thread that closes a stage decides the next from
/// the ranges' partial sums ([`Lead`]).
struct Solve<'a, P> {
    args: &'a PcgArgs<'a>,
    sh: &'a Shared,
    fma: bool,
    parts: Vec<UnsafeCell<(Rows<'a>, P)>>,
    /// The open stage's work: written by the thread that closes a stage,
    /// read by the next stage's parts.
    work: UnsafeCell<Work>,
    lead: UnsafeCell<Lead>,
    result: UnsafeCell<Result<usize>>,
}

// SAFETY: a part's cell is used by the one thread that took the part, `work`
// written and `lead` and `result` used only by the thread closing a stage,
// when no part runs (see `Team::run_stages`); the preconditioners move
// between threads (`P: Send`).
unsafe impl<P: Send> Sync for Solve<'_, P> {}

impl<'a, P: RowPrecond<'a> + Send> Solve<'a, P> {
    fn new(args: &'a PcgArgs<'a>, sh: &'a Shared) -> Self {
        let n = args.a.n;
        let parts = (0..sh.nt)
            .map(|t| {
                let (lo, hi) = (t * n / sh.nt, (t + 1) * n / sh.nt);
                let rows = Rows {
                    args,
                    sh,
                    t,
                    lo,
                    len: hi - lo,
                    f: &args.filter[lo..hi],
                    b: &args.b[lo..hi],
                };
                let p = P::new(&rows);
                UnsafeCell::new((rows, p))
            })
            .collect();
        Solve {
            args,
            sh,
            fma: has_fma(),
            parts,
            work: UnsafeCell::new(Work::Setup),
            lead: UnsafeCell::new(Lead::default()),
            result: UnsafeCell::new(Ok(0)),
        }
    }

    /// Runs the solve on `team`: the iterations, and the result.
    fn run(self, team: &mut Team) -> (usize, Result<usize>) {
        team.run_stages(self.sh.nt, &self);
        (self.lead.into_inner().it, self.result.into_inner())
    }
}

impl<'a, P: RowPrecond<'a> + Send> Stages for Solve<'a, P> {
    fn part(&self, p: usize) {
        // SAFETY: this thread took part p of the open stage (see the Sync
        // impl); `work` was written before the stage opened
        let (rows, pc) = unsafe { &mut *self.parts[p].get() };
        let work = unsafe { *self.work.get() };
        #[cfg(target_arch = "x86_64")]
        if self.fma {
            // SAFETY: the CPU has AVX2 and FMA (`has_fma`)
            return unsafe { range_part_fma(rows, pc, work) };
        }
        range_part::<false, P>(rows, pc, work)
    }

    fn next(&self) -> bool {
        // SAFETY: the thread closing a stage, no part running (Sync impl)
        let (lead, work, result) = unsafe {
            (
                &mut *self.lead.get(),
                &mut *self.work.get(),
                &mut *self.result.get(),
            )
        };
        match lead.next::<P>(self.sh, self.args, *work) {
            Ok(Flow::Go(w)) => {
                *work = w;
                true
            }
            Ok(Flow::Done(it)) => {
                *result = Ok(it);
                false
            }
            Err(e) => {
                *result = Err(e);
                false
            }
        }
    }
}

/// [`range_part`] with the block products on AVX2 and FMA (four-wide fused
/// multiply-adds on the 3 × 3 blocks, [`row_mul_fma`]): which one runs
/// depends on the CPU only, so a run on one machine is reproducible bit for
/// bit.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn range_part_fma<'a, P: RowPrecond<'a>>(rows: &Rows<'a>, p: &mut P, work: Work) {
    range_part::<true, P>(rows, p, work)
}

/// One range's part of a stage of the filtered PCG preconditioned by `P`:
/// the vector updates and the products on the range's rows, and its share
/// of the dot products ([`Shared::put`]).
#[inline(always)]
fn range_part<'a, const FMA: bool, P: RowPrecond<'a>>(rows: &Rows<'a>, p: &mut P, work: Work) {
    let (sh, t) = (rows.sh, rows.t);
    // SAFETY: a range's rows of r, q, s, dv and c are written only by its
    // part; the whole of dv is read only by the stages after the setup and
    // the updates, the whole of c only by the product, a stage after the
    // direction
    let (r, q, s, dv, c) = unsafe {
        (
            rows.own(sh.r),
            rows.own(sh.q),
            rows.own(sh.s),
            rows.own(sh.dv),
            rows.own(sh.c),
        )
    };
    match work {
        Work::Setup => {
            let (f, bb, zz) = (rows.f, rows.b, &rows.args.z[rows.lo..rows.lo + rows.len]);
            let (mut delta0, mut floor) = (0.0, 0.0);
            for k in 0..rows.len {
                let dinv = p.setup_row(rows, k);
                // the convergence test's reference: (S b)ᵀ D⁻¹ (S b),
                // floored by gravity's impulse in the same norm
                let (d, g) =
                    reference_terms(&f[k], &bb[k], rows.args.scale.get(rows.lo + k), &dinv);
                delta0 += d;
                floor += g;
                // start from the caller's guess in dv (the last step's Δv:
                // at small steps Δv changes little from step to step), made
                // to obey the filter
                let g = if dv[k].iter().all(|c| c.is_finite()) {
                    f[k].apply(&dv[k])
                } else {
                    Vector3::zeros()
                };
                dv[k] = g + zz[k];
            }
            sh.put(t, 0, delta0);
            sh.put(t, 2, floor);
        }
        Work::Start => {
            // SAFETY: every range's rows of dv are set up (the stage before)
            let x = unsafe { rows.whole(sh.dv) };
            for k in 0..rows.len {
                r[k] = rows.residual::<FMA>(x, k);
            }
            let (dnew, rho) = p.start::<FMA>(rows, r, s, c);
            sh.put(t, 1, dnew);
            if let Some(rho) = rho {
                sh.put(t, 3, rho);
            }
        }
        Work::Confirm => sh.put(t, 3, p.confirm_part::<FMA>(rows)),
        Work::Direction(beta) => {
            if let Some(beta) = beta {
                p.next_direction(rows, s, c, beta);
            }
            p.product_first::<FMA>(rows, c);
        }
        Work::Product => sh.put(t, 2, p.product::<FMA>(rows, c, q)),
        Work::Update(alpha) => {
            let mut dn = 0.0;
            let along = p.along(c);
            for k in 0..rows.len {
                dv[k] += along[k] * alpha;
                r[k] -= q[k] * alpha;
                s[k] = p.precondition(k, &r[k]);
                dn += r[k].dot(&s[k]);
            }
            sh.put(t, 1, dn);
        }
    }
}

/// What one thread of a PCG solve works on: the solve's inputs, the shared
/// vectors, and its rows `lo..lo + len` of the filter and right-hand side.
struct Rows<'a> {
    args: &'a PcgArgs<'a>,
    sh: &'a Shared,
    t: usize,
    lo: usize,
    len: usize,
    f: &'a [Filter],
    b: &'a [Vector3<f64>],
}

impl<'a> Rows<'a> {
    /// This range's rows of the shared vector `p`.
    ///
    /// # Safety
    /// Only this range's part may write them while the slice lives, and no
    /// other part may read them then (see the stages of [`range_part`]).
    #[inline(always)]
    #[allow(clippy::mut_from_ref)]
    unsafe fn own<T>(&self, p: Ptr<T>) -> &'a mut [T] {
        std::slice::from_raw_parts_mut(p.0.add(self.lo), self.len)
    }

    /// The whole of the shared vector `p`, to read.
    ///
    /// # Safety
    /// Every range's rows must be written (in a stage before), and none
    /// written while the slice lives.
    #[inline(always)]
    unsafe fn whole<T>(&self, p: Ptr<T>) -> &'a [T] {
        std::slice::from_raw_parts(p.0, self.args.a.n)
    }

    /// Row k (matrix row `lo + k`) of `S (b − A x)`, `x` whole.
    #[inline(always)]
    fn residual<const FMA: bool>(&self, x: &[Vector3<f64>], k: usize) -> Vector3<f64> {
        let ax = row_mul_k::<FMA>(self.args.a, self.lo + k, x);
        self.f[k].apply(&(self.b[k] - ax))
    }
}

/// A preconditioner of the PCG in stages ([`Solve`]): its part on one
/// range of rows. The PCG iterates on the vectors `r` (residual, filtered),
/// `c` (search direction, read whole by the product), `q` (the operator
/// times `c`), `s` (the preconditioned residual) and the iterate `Δv`; the
/// preconditioner says how `c` and `s` are made from `r`, what the operator
/// is, and when the tracked norm `δ = rᵀ s` meets the convergence test,
/// Baraff–Witkin's on the true residual, `rᵀ D⁻¹ r ≤ tol² δ0`.
trait RowPrecond<'a>: Sized {
    /// `δ` is not the test's norm: [`RowPrecond::start`] returns that norm
    /// too, and a `δ` that reaches its target is confirmed on the true
    /// residual ([`Work::Confirm`]).
    const CONFIRMS: bool;

    /// The product has a first part ([`RowPrecond::product_first`]).
    const PRODUCT_FIRST: bool;

    /// Its state on `rows`.
    fn new(rows: &Rows<'a>) -> Self;

    /// Sets up row k (matrix row `lo + k`); returns `D_i⁻¹`, the inverse of
    /// the diagonal block the convergence test's norm uses.
    fn setup_row(&mut self, rows: &Rows, k: usize) -> Matrix3<f64>;

    /// After every range's setup: from this range's rows of the residual
    /// `r`, sets the first `s` and `c` (`r` may change into the
    /// preconditioner's form); returns `δ = rᵀ s` and, where `δ` is not the
    /// test's norm, `rᵀ D⁻¹ r`.
    fn start<const FMA: bool>(
        &mut self,
        rows: &Rows,
        r: &mut [Vector3<f64>],
        s: &mut [Vector3<f64>],
        c: &mut [Vector3<f64>],
    ) -> (f64, Option<f64>);

    /// The first target of `δ` for the test's `ε² = tol² δ0`; none: converged.
    fn first_target(eps2: f64, dnew: f64, rho: Option<f64>) -> Option<f64>;

    /// `δ` has reached its target ([`RowPrecond::CONFIRMS`]): this range's
    /// share of the test's norm of the true residual.
    fn confirm_part<const FMA: bool>(&mut self, rows: &Rows) -> f64;

    /// With the test's norm of the true residual `rho`: none if the solve
    /// has converged, else the next target of `δ`.
    fn confirmed(rho: f64, dnew: f64, eps2: f64) -> Option<f64>;

    /// The squared residual ratio the caps judge ([`capped`]).
    fn ratio(dnew: f64, target: f64, delta0: f64, tol: f64) -> f64;

    /// The part of the product that needs only this range's rows of `c`
    /// (a stage before the rest).
    fn product_first<const FMA: bool>(&mut self, rows: &Rows, c: &[Vector3<f64>]);

    /// This range's rows of `q` = the operator times `c` (`c` complete in
    /// every range); returns their part of `cᵀ q`.
    fn product<const FMA: bool>(
        &mut self,
        rows: &Rows,
        c: &[Vector3<f64>],
        q: &mut [Vector3<f64>],
    ) -> f64;

    /// The direction the iterate moves along: `c`, or what the product made
    /// of it.
    fn along<'s>(&'s self, c: &'s [Vector3<f64>]) -> &'s [Vector3<f64>];

    /// Row k of `s` for the residual row `r`.
    fn precondition(&self, k: usize, r: &Vector3<f64>) -> Vector3<f64>;

    /// `c = s + β c` on this range's rows.
    fn next_direction(&self, rows: &Rows, s: &[Vector3<f64>], c: &mut [Vector3<f64>], beta: f64);
}

/// The block-Jacobi preconditioner ([`Preconditioner::BlockJacobi`]) on one
/// thread's rows: the inverses of the diagonal blocks; the operator is
/// `S A`.
struct JacobiRows<'a> {
    pinv: &'a mut [Matrix3<f64>],
}

impl<'a> RowPrecond<'a> for JacobiRows<'a> {
    const CONFIRMS: bool = false;
    const PRODUCT_FIRST: bool = false;

    #[inline(always)]
    fn new(rows: &Rows<'a>) -> Self {
        // SAFETY: rows lo..hi of pinv are this thread's
        JacobiRows {
            pinv: unsafe { rows.own(rows.sh.pinv) },
        }
    }

    #[inline(always)]
    fn setup_row(&mut self, rows: &Rows, k: usize) -> Matrix3<f64> {
        let a = rows.args.a;
        self.pinv[k] = block_jacobi(&a.val[a.diag[rows.lo + k]]);
        self.pinv[k]
    }

    #[inline(always)]
    fn start<const FMA: bool>(
        &mut self,
        rows: &Rows,
        r: &mut [Vector3<f64>],
        _s: &mut [Vector3<f64>],
        c: &mut [Vector3<f64>],
    ) -> (f64, Option<f64>) {
        let mut dnew = 0.0;
        for k in 0..r.len() {
            c[k] = rows.f[k].apply(&(self.pinv[k] * r[k]));
            dnew += r[k].dot(&c[k]);
        }
        (dnew, None)
    }

    #[inline(always)]
    fn first_target(eps2: f64, _: f64, _: Option<f64>) -> Option<f64> {
        Some(eps2)
    }

    /// `δ` is the test's norm: never asked.
    #[inline(always)]
    fn confirm_part<const FMA: bool>(&mut self, _: &Rows) -> f64 {
        0.0
    }

    #[inline(always)]
    fn confirmed(_: f64, _: f64, _: f64) -> Option<f64> {
        None
    }

    #[inline(always)]
    fn ratio(dnew: f64, _: f64, delta0: f64, _: f64) -> f64 {
        dnew / delta0
    }

    #[inline(always)]
    fn product_first<const FMA: bool>(&mut self, _: &Rows, _: &[Vector3<f64>]) {}

    /// `q = S A c`.
    #[inline(always)]
    fn product<const FMA: bool>(
        &mut self,
        rows: &Rows,
        _: &[Vector3<f64>],
        q: &mut [Vector3<f64>],
    ) -> f64 {
        // SAFETY: c is complete (the stage before) and written again only
        // in a later stage
        let c = unsafe { rows.whole(rows.sh.c) };
        let mut cq = 0.0;
        for k in 0..q.len() {
            let v = rows.f[k].apply(&row_mul_k::<FMA>(rows.args.a, rows.lo + k, c));
            q[k] = v;
            cq += c[rows.lo + k].dot(&v);
        }
        cq
    }

    #[inline(always)]
    fn along<'s>(&'s self, c: &'s [Vector3<f64>]) -> &'s [Vector3<f64>] {
        c
    }

    #[inline(always)]
    fn precondition(&self, k: usize, r: &Vector3<f64>) -> Vector3<f64> {
        self.pinv[k] * r
    }

    /// `c = S (s + β c)`; every range's `c` is complete when the stage
    /// ends, before the next product reads it whole.
    #[inline(always)]
    fn next_direction(&self, rows: &Rows, s: &[Vector3<f64>], c: &mut [Vector3<f64>], beta: f64) {
        for k in 0..c.len() {
            c[k] = rows.f[k].apply(&(s[k] + c[k] * beta));
        }
    }
}

/// Symmetric block Gauss–Seidel ([`Preconditioner::Sgs`]) on one thread's
/// rows, in Eisenstat's form (Eisenstat, "Efficient implementation of a
/// class of preconditioned conjugate gradient methods", SIAM J. Sci. Stat.
/// Comput. 2(1), 1981).
///
/// The filtered matrix `Â = S A S + (I − S) τ` (`τ_i` a third of the trace
/// of `A_ii`: the constrained directions are decoupled from the others and
/// carry no right-hand side) is split into `D` (its 3 × 3 diagonal blocks),
/// `L` and `U` (its blocks below and above the diagonal between rows of one
/// thread) and `O` (its blocks between rows of two threads). The
/// preconditioner is `M = (D + L) D⁻¹ (D + U)`: each thread's own symmetric
/// Gauss–Seidel sweep. The conjugate gradient runs on
/// `(D + L)⁻¹ Â (D + U)⁻¹`, whose product costs one backward and one forward
/// sweep: with `t = (D + U)⁻¹ p`, `(D + L)⁻¹ Â t = t + (D + L)⁻¹ (p − D t +
/// O t)`. The sweeps read copies of the lower and upper triangles made at
/// the start (reading the halves of the rows in place makes the hardware
/// fetch the whole rows). The iterate is kept unscaled (`Δv += α t`), and
/// the transformed residual `r̃ = (D + L)⁻¹ r` gives the tracked norm,
/// `r̃ᵀ D r̃ = rᵀ M⁻¹ r`; the loop stops on that norm scaled by the ratio of
/// the test's norm to it at the start, then checks the true residual (one
/// product) and goes on, with the target lowered, until it passes.
struct SgsRows<'a> {
    tri: &'a Triangles,
    /// `D_i⁻¹` and `D_i` (the filtered diagonal blocks) of this thread's rows.
    dinv: &'a mut [Matrix3<f64>],
    dblk: &'a mut [Matrix3<f64>],
    /// Per row, where this thread's lower blocks start and its upper ones end.
    split: &'a mut [[u32; 2]],
    /// `t = (D + U)⁻¹ p`, this thread's rows.
    tt: &'a mut [Vector3<f64>],
}

/// The sweeps of `rows` over the copies of the triangles `tri` (complete
/// in every range: read only in the stages after the setup).
#[inline(always)]
fn sweeps<'s>(
    rows: &'s Rows,
    tri: &'s Triangles,
    dinv: &'s [Matrix3<f64>],
    split: &'s [[u32; 2]],
) -> Sweeps<'s> {
    // SAFETY: every range's rows of the copies are written (the setup's
    // stage) and only read from there on
    let (lval, uval) = unsafe {
        (
            std::slice::from_raw_parts(rows.sh.lval.0, tri.lcol.len()),
            std::slice::from_raw_parts(rows.sh.uval.0, tri.ucol.len()),
        )
    };
    Sweeps {
        lcol: &tri.lcol,
        lval,
        ucol: &tri.ucol,
        uval,
        lptr: &tri.lptr,
        uptr: &tri.uptr,
        f: rows.f,
        dinv,
        split,
        lo: rows.lo,
    }
}

impl<'a> RowPrecond<'a> for SgsRows<'a> {
    const CONFIRMS: bool = true;
    const PRODUCT_FIRST: bool = true;

    #[inline(always)]
    fn new(rows: &Rows<'a>) -> Self {
        let sh = rows.sh;
        // SAFETY: rows lo..hi of these are this thread's
        unsafe {
            SgsRows {
                tri: rows
                    .args
                    .tri
                    .expect("the triangles of a Gauss–Seidel solve"),
                dinv: rows.own(sh.pinv),
                dblk: rows.own(sh.dblk),
                split: rows.own(sh.split),
                tt: rows.own(sh.t),
            }
        }
    }

    /// The filtered diagonal block and its inverse; the row's lower and
    /// upper blocks into their copies, and where this thread's end.
    #[inline(always)]
    fn setup_row(&mut self, rows: &Rows, k: usize) -> Matrix3<f64> {
        let (a, tri, f) = (rows.args.a, self.tri, &rows.f[k]);
        let (rp, diag) = (&a.row_ptr, &a.diag);
        let (lo, hi) = (rows.lo, rows.lo + rows.len);
        let i = lo + k;
        let d = &a.val[diag[i]];
        let tau = d.trace() / 3.0;
        let fd = match *f {
            Filter::Free => *d,
            Filter::Fixed => Matrix3::identity() * tau,
            Filter::Normal(nrm) => {
                let m = f.right(&f.left(d));
                (m + m.transpose()) * 0.5 + nrm * nrm.transpose() * tau
            }
            Filter::Crease(_) => {
                let m = f.right(&f.left(d));
                (m + m.transpose()) * 0.5 + (Matrix3::identity() - f.matrix()) * tau
            }
        };
        self.dblk[k] = fd;
        self.dinv[k] = block_jacobi(&fd);
        let (l0, u0) = (tri.lptr[i] as usize, tri.uptr[i] as usize);
        let (nl, nu) = (diag[i] - rp[i], rp[i + 1] - diag[i] - 1);
        // SAFETY: rows lo..hi of the copies are this thread's, and the
        // pattern's lower and upper counts give their lengths
        unsafe {
            std::ptr::copy_nonoverlapping(a.val.as_ptr().add(rp[i]), rows.sh.lval.0.add(l0), nl);
            std::ptr::copy_nonoverlapping(
                a.val.as_ptr().add(diag[i] + 1),
                rows.sh.uval.0.add(u0),
                nu,
            );
        }
        // this thread's blocks of the row: the lower ones from the first
        // column ≥ lo, the upper ones up to the first ≥ hi (the pattern's
        // columns are sorted)
        let lcols = &tri.lcol[l0..l0 + nl];
        let ucols = &tri.ucol[u0..u0 + nu];
        self.split[k] = [
            (l0 + lcols.partition_point(|&c| (c as usize) < lo)) as u32,
            (u0 + ucols.partition_point(|&c| (c as usize) < hi)) as u32,
        ];
        self.dinv[k]
    }

    /// `r̃ = (D + L)⁻¹ r` in `r`, `s = D r̃`, `p = s`; `δ = r̃ᵀ D r̃`.
    #[inline(always)]
    fn start<const FMA: bool>(
        &mut self,
        rows: &Rows,
        r: &mut [Vector3<f64>],
        s: &mut [Vector3<f64>],
        c: &mut [Vector3<f64>],
    ) -> (f64, Option<f64>) {
        let mut rho = 0.0;
        for k in 0..r.len() {
            rho += r[k].dot(&(self.dinv[k] * r[k]));
        }
        let dnew = sweeps(rows, self.tri, self.dinv, self.split).forward_norm::<FMA>(r, self.dblk);
        for k in 0..r.len() {
            s[k] = self.dblk[k] * r[k];
            c[k] = s[k];
        }
        (dnew, Some(rho))
    }

    #[inline(always)]
    fn first_target(eps2: f64, dnew: f64, rho: Option<f64>) -> Option<f64> {
        let rho = rho.expect("the test's norm at the start");
        (rho > eps2).then(|| eps2 * dnew / rho)
    }

    /// The true residual's test, `rᵀ D⁻¹ r ≤ ε²` (one product): this
    /// range's share.
    #[inline(always)]
    fn confirm_part<const FMA: bool>(&mut self, rows: &Rows) -> f64 {
        let mut rho = 0.0;
        // SAFETY: dv is complete (last written in the stage of δ) and
        // written again only in a later stage
        let x = unsafe { rows.whole(rows.sh.dv) };
        for k in 0..rows.len {
            let rk = rows.residual::<FMA>(x, k);
            rho += rk.dot(&(self.dinv[k] * rk));
        }
        rho
    }

    /// Failing the test, what is left to gain, with a margin.
    #[inline(always)]
    fn confirmed(rho: f64, dnew: f64, eps2: f64) -> Option<f64> {
        (rho > eps2).then(|| dnew * (0.5 * eps2 / rho))
    }

    #[inline(always)]
    fn ratio(dnew: f64, target: f64, _: f64, tol: f64) -> f64 {
        dnew / target * tol * tol
    }

    /// `t = (D + U)⁻¹ p` on this range's rows.
    #[inline(always)]
    fn product_first<const FMA: bool>(&mut self, rows: &Rows, p: &[Vector3<f64>]) {
        sweeps(rows, self.tri, self.dinv, self.split).backward::<FMA>(p, self.tt);
    }

    /// `q = (D + L)⁻¹ (p − D t + O t) + t`, `t` swept by every range (the
    /// stage before).
    #[inline(always)]
    fn product<const FMA: bool>(
        &mut self,
        rows: &Rows,
        p: &[Vector3<f64>],
        q: &mut [Vector3<f64>],
    ) -> f64 {
        let (tri, lo) = (self.tri, rows.lo);
        let sw = sweeps(rows, tri, self.dinv, self.split);
        {
            // SAFETY: every range's rows of t are swept (the stage before);
            // the next sweep comes in a later stage
            let tall = unsafe { rows.whole(rows.sh.t) };
            for k in 0..q.len() {
                let i = lo + k;
                let mut u = p[k] - self.dblk[k] * self.tt[k];
                let (l0, u1) = (tri.lptr[i] as usize, tri.uptr[i + 1] as usize);
                let (l1, u0) = (self.split[k][0] as usize, self.split[k][1] as usize);
                if l1 > l0 || u0 < u1 {
                    let o = blocks_mul_slices(FMA, sw.lcol, sw.lval, l0, l1, tall)
                        + blocks_mul_slices(FMA, sw.ucol, sw.uval, u0, u1, tall);
                    u += rows.f[k].apply(&o);
                }
                q[k] = u;
            }
        }
        sw.forward::<FMA>(q);
        let mut pq = 0.0;
        for k in 0..q.len() {
            q[k] += self.tt[k];
            pq += p[k].dot(&q[k]);
        }
        pq
    }

    #[inline(always)]
    fn along<'s>(&'s self, _: &'s [Vector3<f64>]) -> &'s [Vector3<f64>] {
        self.tt
    }

    #[inline(always)]
    fn precondition(&self, k: usize, r: &Vector3<f64>) -> Vector3<f64> {
        self.dblk[k] * r
    }

    /// `p = s + β p`: read by this range only (its sweeps, and `O t` reads
    /// `t`), so in the stage of the sweep.
    #[inline(always)]
    fn next_direction(&self, _: &Rows, s: &[Vector3<f64>], c: &mut [Vector3<f64>], beta: f64) {
        for k in 0..c.len() {
            c[k] = s[k] + c[k] * beta;
        }
    }
}

/// `D_i⁻¹ (v − Σ_k val[k] x[col[k]])` over the blocks `lo..hi` of one row
/// (`dinv` = `D_i⁻¹`), a row of a triangular sweep, with AVX2 and FMA.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn solve_row_fma(
    col: &[u32],
    val: &[Matrix3<f64>],
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
    v: &Vector3<f64>,
    dinv: &Matrix3<f64>,
) -> Vector3<f64> {
    use std::arch::x86_64::*;
    let three = _mm256_setr_epi64x(-1, -1, -1, 0);
    let acc = blocks_acc_fma(col, val, lo, hi, x);
    let w = _mm256_sub_pd(_mm256_maskload_pd(v.as_ptr(), three), acc);
    // D_i⁻¹ w, D_i⁻¹ column-major like the blocks
    let d = dinv.as_ptr();
    let y = _mm256_mul_pd(_mm256_loadu_pd(d), _mm256_permute4x64_pd(w, 0b00_00_00_00));
    let y = _mm256_fmadd_pd(
        _mm256_loadu_pd(d.add(3)),
        _mm256_permute4x64_pd(w, 0b01_01_01_01),
        y,
    );
    let y = _mm256_fmadd_pd(
        _mm256_maskload_pd(d.add(6), three),
        _mm256_permute4x64_pd(w, 0b10_10_10_10),
        y,
    );
    lanes3(y)
}

/// A row of a triangular sweep: `S_i D_i⁻¹ (v − S_i Σ_k val[k] x[col[k]])`
/// over the blocks `lo..hi`, `f` row i's filter (a free row with
/// [`solve_row_fma`] where `FMA`).
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn solve_row_k<const FMA: bool>(
    col: &[u32],
    val: &[Matrix3<f64>],
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
    v: &Vector3<f64>,
    dinv: &Matrix3<f64>,
    f: &Filter,
) -> Vector3<f64> {
    #[cfg(target_arch = "x86_64")]
    if FMA && matches!(f, Filter::Free) {
        // SAFETY: FMA is only set where the CPU has AVX2 and FMA
        return unsafe { solve_row_fma(col, val, lo, hi, x, v, dinv) };
    }
    let sum = blocks_mul_slices(FMA, col, val, lo, hi, x);
    f.apply(&(dinv * (v - f.apply(&sum))))
}

/// One thread's triangular sweeps of [`SgsRows`] over its rows
/// `lo..lo + len`, from the copies of the lower and upper triangles.
struct Sweeps<'a> {
    /// The lower triangle's blocks and columns, row i's at `lptr[i]..lptr[i + 1]`.
    lcol: &'a [u32],
    lval: &'a [Matrix3<f64>],
    /// The upper triangle's, row i's at `uptr[i]..uptr[i + 1]`.
    ucol: &'a [u32],
    uval: &'a [Matrix3<f64>],
    lptr: &'a [u32],
    uptr: &'a [u32],
    /// This thread's rows' filters and `D_i⁻¹`.
    f: &'a [Filter],
    dinv: &'a [Matrix3<f64>],
    /// Per row, where this thread's lower blocks start and its upper ones end.
    split: &'a [[u32; 2]],
    lo: usize,
}

impl Sweeps<'_> {
    /// `(D + L) y = v` in place (`v` holds this thread's rows).
    #[inline(always)]
    fn forward<const FMA: bool>(&self, v: &mut [Vector3<f64>]) {
        let lo = self.lo;
        for k in 0..v.len() {
            let i = lo + k;
            // SAFETY: the blocks split[k][0]..lptr[i + 1] have columns lo..i,
            // rows already swept
            let y = unsafe { std::slice::from_raw_parts(v.as_ptr().sub(lo), i) };
            v[k] = solve_row_k::<FMA>(
                self.lcol,
                self.lval,
                self.split[k][0] as usize,
                self.lptr[i + 1] as usize,
                y,
                &v[k],
                &self.dinv[k],
                &self.f[k],
            );
        }
    }

    /// [`Sweeps::forward`], returning `yᵀ D y`: the preconditioner's norm
    /// of `v`, `vᵀ M⁻¹ v` (`d` this thread's diagonal blocks).
    #[inline(always)]
    fn forward_norm<const FMA: bool>(&self, v: &mut [Vector3<f64>], d: &[Matrix3<f64>]) -> f64 {
        self.forward::<FMA>(v);
        let mut n = 0.0;
        for k in 0..v.len() {
            n += v[k].dot(&(d[k] * v[k]));
        }
        n
    }

    /// `t = (D + U)⁻¹ p`.
    #[inline(always)]
    fn backward<const FMA: bool>(&self, p: &[Vector3<f64>], t: &mut [Vector3<f64>]) {
        let lo = self.lo;
        let hi = lo + t.len();
        for k in (0..t.len()).rev() {
            let i = lo + k;
            // SAFETY: the blocks uptr[i]..split[k][1] have columns i + 1..hi,
            // rows already swept
            let x = unsafe { std::slice::from_raw_parts(t.as_ptr().sub(lo), hi) };
            t[k] = solve_row_k::<FMA>(
                self.ucol,
                self.uval,
                self.uptr[i] as usize,
                self.split[k][1] as usize,
                x,
                &p[k],
                &self.dinv[k],
                &self.f[k],
            );
        }
    }
}

/// Row i of `A x`: with `FMA`, [`row_mul_fma`] (only where the CPU has AVX2
/// and FMA; inlined into callers compiled with them), else the portable
/// product.
#[inline(always)]
fn row_mul_k<const FMA: bool>(a: &BlockMatrix, i: usize, x: &[Vector3<f64>]) -> Vector3<f64> {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: FMA is only set where the CPU has AVX2 and FMA (see
        // `Solve`'s parts and `row_mul_best`)
        return unsafe { row_mul_fma(a, i, x) };
    }
    row_mul(a, i, x)
}

/// Row i of `A x` with AVX2 and FMA: each 3 × 3 block (nalgebra stores it
/// column-major, nine contiguous f64) is read as three overlapping
/// four-wide columns (the fourth lane is the next column's first entry and
/// is dropped), multiplied by the broadcast entries of `x_j`; two
/// accumulators alternate so consecutive blocks do not wait on each other.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn row_mul_fma(a: &BlockMatrix, i: usize, x: &[Vector3<f64>]) -> Vector3<f64> {
    blocks_mul_fma(&a.col, &a.val, a.row_ptr[i], a.row_ptr[i + 1], x)
}

/// [`row_mul_fma`] over the blocks `lo..hi` of one row of a block CSR
/// matrix given by its columns `col` and blocks `val`.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
pub(super) unsafe fn blocks_mul_fma(
    col: &[u32],
    val: &[Matrix3<f64>],
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
) -> Vector3<f64> {
    lanes3(blocks_acc_fma(col, val, lo, hi, x))
}

/// [`blocks_mul_fma`]'s sum as a four-wide register (lane 3 to be dropped).
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn blocks_acc_fma(
    col: &[u32],
    val: &[Matrix3<f64>],
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    assert!(lo <= hi);
    assert!(hi <= val.len() && hi <= col.len());
    let vp = val.as_ptr() as *const f64;
    let xp = x.as_ptr() as *const f64;
    let nx = x.len();
    // the last block of the matrix: its third column is read masked (a
    // four-wide load would run one f64 past the end)
    let last = val.len().saturating_sub(1);
    sum_blocks_acc_fma(lo, hi, |k| {
        let j = *col.get_unchecked(k) as usize;
        assert!(j < nx);
        let m = vp.add(9 * k);
        let xj = xp.add(3 * j);
        let c2 = if k < last {
            _mm256_loadu_pd(m.add(6))
        } else {
            _mm256_maskload_pd(m.add(6), _mm256_setr_epi64x(-1, -1, -1, 0))
        };
        let t = _mm256_mul_pd(_mm256_loadu_pd(m), _mm256_broadcast_sd(&*xj));
        let t = _mm256_fmadd_pd(
            _mm256_loadu_pd(m.add(3)),
            _mm256_broadcast_sd(&*xj.add(1)),
            t,
        );
        _mm256_fmadd_pd(c2, _mm256_broadcast_sd(&*xj.add(2)), t)
    })
}

/// `Σ block(k)` over `lo..hi` as a 3-vector (lane 3 of each four-wide
/// product dropped): the loop of the fused row kernels ([`blocks_mul_fma`]
/// and the multigrid's single-precision one), two accumulators so that
/// consecutive blocks' products overlap.
///
/// # Safety
/// The CPU must have AVX2 and FMA (inlined into callers compiled with them);
/// `block` must be safe to call for every k in `lo..hi`.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
pub(super) unsafe fn sum_blocks_fma(
    lo: usize,
    hi: usize,
    block: impl FnMut(usize) -> std::arch::x86_64::__m256d,
) -> Vector3<f64> {
    lanes3(sum_blocks_acc_fma(lo, hi, block))
}

/// [`sum_blocks_fma`]'s sum as a four-wide register (lane 3 to be dropped).
///
/// # Safety
/// As [`sum_blocks_fma`].
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn sum_blocks_acc_fma(
    lo: usize,
    hi: usize,
    mut block: impl FnMut(usize) -> std::arch::x86_64::__m256d,
) -> std::arch::x86_64::__m256d {
    use std::arch::x86_64::*;
    let mut acc0 = _mm256_setzero_pd();
    let mut acc1 = _mm256_setzero_pd();
    let mut k = lo;
    while k + 1 < hi {
        acc0 = _mm256_add_pd(acc0, block(k));
        acc1 = _mm256_add_pd(acc1, block(k + 1));
        k += 2;
    }
    if k < hi {
        acc0 = _mm256_add_pd(acc0, block(k));
    }
    _mm256_add_pd(acc0, acc1)
}

/// Lanes 0–2 of a four-wide register as a 3-vector.
///
/// # Safety
/// The CPU must have AVX (inlined into callers compiled with it).
#[cfg(target_arch = "x86_64")]
#[inline(always)]
unsafe fn lanes3(v: std::arch::x86_64::__m256d) -> Vector3<f64> {
    let mut out = [0.0; 4];
    std::arch::x86_64::_mm256_storeu_pd(out.as_mut_ptr(), v);
    Vector3::new(out[0], out[1], out[2])
}

/// Row i of `A x`, with [`row_mul_fma`] when `fma` (the CPU has AVX2 and
/// FMA, [`has_fma`](super::cpu::has_fma)): [`row_mul_k`] chosen at run time, for callers not
/// compiled with those features.
#[inline]
fn row_mul_best(fma: bool, a: &BlockMatrix, i: usize, x: &[Vector3<f64>]) -> Vector3<f64> {
    if fma {
        row_mul_k::<true>(a, i, x)
    } else {
        row_mul_k::<false>(a, i, x)
    }
}

/// `Σ_k a.val[k] x[a.col[k]]` over the blocks `lo..hi` of one row, with
/// AVX2 and FMA when `fma` (see [`row_mul_best`]).
#[inline]
pub(super) fn blocks_mul_best(
    fma: bool,
    a: &BlockMatrix,
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
) -> Vector3<f64> {
    blocks_mul_slices(fma, &a.col, &a.val, lo, hi, x)
}

/// [`blocks_mul_best`] for a block CSR matrix given by its columns `col`
/// and blocks `val` (inlined, so that a constant `fma` in a caller compiled
/// with AVX2 and FMA makes it the fused kernel, inlined too).
#[inline(always)]
pub(super) fn blocks_mul_slices(
    fma: bool,
    col: &[u32],
    val: &[Matrix3<f64>],
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
) -> Vector3<f64> {
    #[cfg(target_arch = "x86_64")]
    if fma {
        // SAFETY: `fma` is set only where the CPU has AVX2 and FMA
        return unsafe { blocks_mul_fma(col, val, lo, hi, x) };
    }
    let mut s = Vector3::zeros();
    for k in lo..hi {
        s += val[k] * x[col[k] as usize];
    }
    s
}

#[inline(always)]
fn row_mul(a: &BlockMatrix, i: usize, x: &[Vector3<f64>]) -> Vector3<f64> {
    let mut s = Vector3::zeros();
    for k in a.row_ptr[i]..a.row_ptr[i + 1] {
        s += a.val[k] * x[a.col[k] as usize];
    }
    s
}

/// Precision of a Cholesky factor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Precision {
    F64,
    /// Single precision: half the memory traffic, for a preconditioner.
    F32,
}

/// A block-Jacobi PCG iteration's flops by operation counts: the product
/// with the `blocks` 3 × 3 blocks of A (both triangles) and the vector work
/// on its `dim` unknowns.
pub fn pcg_iteration_flops(blocks: usize, dim: usize) -> f64 {
    2.0 * 9.0 * blocks as f64 + 30.0 * dim as f64
}

/// Direct solver: Cholesky of `S A S + (I − S) m` (SPD), symbolic analysis once.
pub struct Direct {
    /// Vertex ordering of the factor (new → old).
    perm: Vec<usize>,
    csc: LowerCsc,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    /// Single-precision copy of the matrix values and factor (preconditioner).
    values32: Vec<f32>,
    l32: Vec<f32>,
    rhs32: Vec<f32>,
    /// Which factor is held, if any.
    held: Option<Precision>,
    mem: MemBuffer,
    rhs: Vec<f64>,
    tmp: Vec<Vector3<f64>>,
    /// Position of the transposed block (j, i) of each block (i, j).
    transpose: Vec<usize>,
    /// The single-precision solve (None: faer's, for a simplicial factor).
    sn: Option<super::trisolve::Supernodal>,
    /// Applications of the factor so far.
    applied: usize,
}

impl std::fmt::Debug for Direct {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Direct")
            .field("nnz", &self.csc.row_idx.len())
            .finish()
    }
}

impl Direct {
    /// One thread (faer's sequential kernels): rayon's threads would compete
    /// with the simulation's own (the assembly, the PCG), and measured slower
    /// on two cores (docs/benchmarks.md, "Alternatives measured").
    ///
    /// The fill-reducing ordering is faer's AMD on the vertex graph
    /// ([`super::sparse::amd_vertex_order`]), and the matrix is stored in
    /// that order, so that faer does not permute it at every factorisation.
    pub fn new(a: &BlockMatrix) -> Result<Direct> {
        let perm = super::sparse::amd_vertex_order(a);
        let csc = LowerCsc::new_permuted(a, &perm)?;
        // checked once here (panics on a malformed pattern, a bug), trusted
        // at every factorisation
        SymbolicSparseColMatRef::new_checked(csc.dim, csc.dim, &csc.col_ptr, None, &csc.row_idx);
        // the matrix is stored in the factor's ordering; without a
        // permutation faer's analysis reads the upper triangle: the transpose
        // of the lower one
        let (col_ptr, row_idx) = csc.transposed_pattern();
        let sym = SymbolicSparseColMatRef::new_checked(csc.dim, csc.dim, &col_ptr, None, &row_idx);
        let symbolic = factorize_symbolic_cholesky(
            sym,
            Side::Upper,
            SymmetricOrdering::Identity,
            Default::default(),
        )
        .map_err(|e| Error::factorization(format!("sparse Cholesky analysis failed: {e:?}")))?;
        let l_values = vec![0.0; symbolic.len_val()];
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, Par::Seq),
            symbolic.factorize_numeric_llt_scratch::<f32>(Par::Seq, Default::default()),
            symbolic.solve_in_place_scratch::<f32>(1, Par::Seq),
        ]);
        Ok(Direct {
            perm,
            rhs: vec![0.0; csc.dim],
            values32: vec![0.0; csc.row_idx.len() + 1],
            l32: Vec::new(),
            rhs32: vec![0.0; csc.dim],
            held: None,
            csc,
            l_values,
            mem: MemBuffer::new(req),
            tmp: vec![Vector3::zeros(); a.n],
            transpose: (0..a.n)
                .flat_map(|i| (a.row_ptr[i]..a.row_ptr[i + 1]).map(move |k| (i, k)))
                .map(|(i, k)| a.index(a.col[k] as usize, i))
                .collect(),
            sn: super::trisolve::Supernodal::new(&symbolic),
            symbolic,
            applied: 0,
        })
    }

    /// Whether the factor is supernodal: its single-precision solve
    /// ([`super::trisolve`]) sums in double precision, so that it applies
    /// `(L̃ L̃ᵀ)⁻¹` for the rounded factor `L̃`, a symmetric operator to
    /// double-precision rounding.
    pub fn supernodal(&self) -> bool {
        self.sn.is_some()
    }

    /// Non-zeros of the Cholesky factor L.
    pub fn nnz_l(&self) -> usize {
        self.symbolic.len_val()
    }

    /// PCG iterations that cost as much as one factorisation and solve, by
    /// operation counts: the factorisation ≈ nnz(L)²/n flops, a PCG iteration
    /// ≈ 2 nnz(A) + 30 n, with κ = 0.55 for the dense supernodal kernels'
    /// speed relative to the sparse products (measured with the PCG on one
    /// thread: break-even at 77, 168 and 445 iterations on the 2, 1 and
    /// 0.5 cm table drapes; the formula gives 70, 179, 499). The PCG runs on `threads` threads and the factorisation on
    /// one, so the count is multiplied by the PCG's speed-up, 1 + 0.8
    /// (threads − 1) (measured 1.8–1.95 on two threads).
    /// `blocks`: the 3 × 3 blocks of A (both triangles).
    pub fn break_even_iterations(&self, blocks: usize, threads: usize) -> usize {
        let n = self.csc.dim as f64;
        let l = self.nnz_l() as f64;
        let one = 0.55 * l * l / n / pcg_iteration_flops(blocks, self.csc.dim);
        let speedup = 1.0 + 0.8 * (threads.max(1) - 1) as f64;
        (one * speedup).round().max(10.0) as usize
    }

    /// Fills the values of `S A S + (I − S) m` (lower triangle): every
    /// value copied from the matrix, then the blocks that touch a
    /// constrained vertex overwritten with their filtered values (once per
    /// block and its transpose; the factor's ordering decides which of the
    /// two it stores).
    fn fill<T: Copy>(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        mass: &[f64],
        out: &mut [T],
        conv: impl Fn(f64) -> T,
    ) {
        // walk the stored blocks in storage order (the reads stream; the
        // writes land in the factor's much smaller value array)
        let (entries, flat) = (&self.csc.entries, a.flat());
        for &blk in &self.csc.stored {
            let blk = blk as usize;
            for (&k, v) in entries[blk].iter().zip(&flat[9 * blk..9 * blk + 9]) {
                out[k as usize] = conv(*v);
            }
        }
        // blocks of constrained vertices, overwritten (entries outside the
        // lower triangle write the spare value)
        let mut put = |blk: usize, m: &Matrix3<f64>| {
            for (&k, v) in entries[blk].iter().zip(m.as_slice()) {
                out[k as usize] = conv(*v);
            }
        };
        for i in 0..a.n {
            let fi = filter[i];
            if fi == Filter::Free {
                continue;
            }
            for blk in a.row_ptr[i]..a.row_ptr[i + 1] {
                let j = a.col[blk] as usize;
                let fj = filter[j];
                if i == j {
                    let f = fi.left(&fi.right(&a.val[blk]))
                        + (Matrix3::identity() - fi.matrix()) * mass[i];
                    put(blk, &f);
                } else if fj == Filter::Free || i < j {
                    // (j, i) is the transpose; when j is constrained too
                    // this is its only visit
                    let f = fi.left(&fj.right(&a.val[blk]));
                    put(self.transpose[blk], &f.transpose());
                    put(blk, &f);
                }
            }
        }
    }

    /// Factorises `S A S + (I − S) m` in the given precision and keeps the
    /// factor (for [`Direct::apply`]).
    pub fn factorize(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        mass: &[f64],
        precision: Precision,
    ) -> Result<()> {
        self.held = None;
        let (mut v64, mut v32) = (
            std::mem::take(&mut self.csc.values),
            std::mem::take(&mut self.values32),
        );
        match precision {
            Precision::F64 => self.fill(a, filter, mass, &mut v64, |v| v),
            Precision::F32 => self.fill(a, filter, mass, &mut v32, |v| v as f32),
        }
        (self.csc.values, self.values32) = (v64, v32);
        // SAFETY: the pattern `new` checked; it is never changed after
        let sym = unsafe {
            SymbolicSparseColMatRef::new_unchecked(
                self.csc.dim,
                self.csc.dim,
                &self.csc.col_ptr,
                None,
                &self.csc.row_idx,
            )
        };
        let stack = MemStack::new(&mut self.mem);
        let err = |e| {
            Error::factorization(format!(
                "sparse Cholesky failed (matrix not positive definite?): {e:?}"
            ))
        };
        match precision {
            Precision::F64 => {
                let mat = SparseColMatRef::new(sym, &self.csc.values[..self.csc.row_idx.len()]);
                self.symbolic
                    .factorize_numeric_llt::<f64>(
                        &mut self.l_values,
                        mat,
                        Side::Lower,
                        LltRegularization::default(),
                        Par::Seq,
                        stack,
                        Default::default(),
                    )
                    .map_err(err)?;
            }
            Precision::F32 => {
                self.l32.resize(self.symbolic.len_val(), 0.0);
                let mat = SparseColMatRef::new(sym, &self.values32[..self.csc.row_idx.len()]);
                self.symbolic
                    .factorize_numeric_llt::<f32>(
                        &mut self.l32,
                        mat,
                        Side::Lower,
                        LltRegularization::default(),
                        Par::Seq,
                        stack,
                        Default::default(),
                    )
                    .map_err(err)?;
                if let Some(sn) = &mut self.sn {
                    sn.refresh();
                }
            }
        }
        self.held = Some(precision);
        Ok(())
    }

    /// The precision of the factor held, if any.
    pub fn held(&self) -> Option<Precision> {
        self.held
    }

    /// `out = P⁻¹ r` with the factor held (`P = L Lᵀ`).
    pub fn apply(&mut self, r: &[Vector3<f64>], out: &mut [Vector3<f64>]) {
        let dim = self.csc.dim;
        self.applied += 1;
        for (i, &o) in self.perm.iter().enumerate() {
            self.rhs[3 * i..3 * i + 3].copy_from_slice(r[o].as_slice());
        }
        let stack = MemStack::new(&mut self.mem);
        match (self.held.expect("a factor is held"), &mut self.sn) {
            (Precision::F64, _) => {
                let llt = LltRef::new(&self.symbolic, &self.l_values);
                let rhs = MatMut::from_column_major_slice_mut(&mut self.rhs, dim, 1);
                llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, stack);
            }
            (Precision::F32, Some(sn)) => sn.solve(&self.l32, &mut self.rhs),
            // a simplicial factor: faer's solve, in single precision
            (Precision::F32, None) => {
                for (x32, &x) in self.rhs32.iter_mut().zip(&self.rhs) {
                    *x32 = x as f32;
                }
                let llt = LltRef::new(&self.symbolic, &self.l32);
                let rhs = MatMut::from_column_major_slice_mut(&mut self.rhs32, dim, 1);
                llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, stack);
                for (x, &x32) in self.rhs.iter_mut().zip(&self.rhs32) {
                    *x = x32 as f64;
                }
            }
        }
        for (i, &o) in self.perm.iter().enumerate() {
            out[o] = Vector3::new(self.rhs[3 * i], self.rhs[3 * i + 1], self.rhs[3 * i + 2]);
        }
    }

    /// Direct solve: factorises (f64, kept) and solves exactly.
    pub fn solve(
        &mut self,
        a: &BlockMatrix,
        b: &[Vector3<f64>],
        filter: &[Filter],
        z: &[Vector3<f64>],
        mass: &[f64],
        dv: &mut [Vector3<f64>],
    ) -> Result<()> {
        let n = a.n;
        self.factorize(a, filter, mass, Precision::F64)?;
        // rhs = S (b − A z)
        a.mul(z, &mut self.tmp);
        let mut r = std::mem::take(&mut self.tmp);
        for i in 0..n {
            r[i] = filter[i].apply(&(b[i] - r[i]));
        }
        self.apply(&r, dv);
        for i in 0..n {
            dv[i] += z[i];
        }
        self.tmp = r;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_systems::{mixed_constraints, spd_grid_sized};
    use super::*;

    /// A 6 × 5 (or `nx` × `ny`) grid of vertices with random PSD springs to their right,
    /// upper and diagonal neighbours plus a mass on the diagonal: SPD, and
    /// symmetric bit for bit as the assembly makes it.
    fn spd_grid(seed: u64) -> (BlockMatrix, Vec<f64>) {
        spd_grid_sized(6, 5, seed)
    }

    /// `a b` as an unevaluated sum `p + e`, exactly (`mul_add` is correctly
    /// rounded on every CPU, in software where there is no FMA unit).
    fn two_prod(a: f64, b: f64) -> (f64, f64) {
        let p = a * b;
        (p, a.mul_add(b, -p))
    }

    /// `a + b` as `s + e`, exactly (Knuth's two-sum).
    fn two_sum(a: f64, b: f64) -> (f64, f64) {
        let s = a + b;
        let bb = s - a;
        (s, (a - (s - bb)) + (b - bb))
    }

    /// Row i of `A x` in double-double arithmetic (each product split
    /// exactly, the sums compensated): the reference, correct to about
    /// 2⁻¹⁰⁰ relative to the sum of the terms' magnitudes; and that sum.
    fn row_mul_exact(
        a: &BlockMatrix,
        i: usize,
        x: &[Vector3<f64>],
    ) -> (Vector3<f64>, Vector3<f64>) {
        let mut out = Vector3::zeros();
        let mut mag = Vector3::zeros();
        for r in 0..3 {
            let (mut hi, mut lo) = (0.0, 0.0);
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                let xj = x[a.col[k] as usize];
                for c in 0..3 {
                    let (p, pe) = two_prod(a.val[k][(r, c)], xj[c]);
                    let (s, se) = two_sum(hi, p);
                    hi = s;
                    lo += se + pe;
                    mag[r] += (a.val[k][(r, c)] * xj[c]).abs();
                }
            }
            out[r] = hi + lo;
        }
        (out, mag)
    }

    /// Every row of `A x` (the last, with its masked final block, included),
    /// by the portable product on every CPU and by the AVX2/FMA one where the
    /// CPU has them, lies within the floating-point bound of the recursive
    /// sum of its `m` terms, `(m + 1) ε Σ|a x|`, of the exact product.
    #[test]
    fn fma_row_product_matches_the_portable_one() {
        let (a, _) = spd_grid(7);
        let x: Vec<Vector3<f64>> = (0..a.n)
            .map(|i| {
                Vector3::new(
                    i as f64 * 0.1 - 1.0,
                    2.0 - i as f64 * 0.03,
                    0.5 + (i as f64).sin(),
                )
            })
            .collect();
        let fma = has_fma();
        if !fma {
            eprintln!("this CPU has no AVX2/FMA: only the portable row product is checked");
        }
        let mut worst = 0.0f64;
        for i in 0..a.n {
            let (exact, mag) = row_mul_exact(&a, i, &x);
            let m = 3 * (a.row_ptr[i + 1] - a.row_ptr[i]);
            let bound = (m + 1) as f64 * f64::EPSILON * mag;
            let mut paths = vec![
                ("portable", row_mul(&a, i, &x)),
                ("best (no FMA)", row_mul_best(false, &a, i, &x)),
            ];
            if fma {
                paths.push(("FMA", row_mul_best(true, &a, i, &x)));
            }
            for (name, got) in paths {
                for r in 0..3 {
                    let err = (got[r] - exact[r]).abs();
                    assert!(
                        err <= bound[r],
                        "row {i}, component {r}, {name}: {} against the exact {} (error {err:e}, bound {:e})",
                        got[r],
                        exact[r],
                        bound[r]
                    );
                    worst = worst.max(err / mag[r].max(f64::MIN_POSITIVE));
                }
            }
        }
        // the products are not trivially exact: some row rounds
        assert!(worst > 0.0, "every product exact: the test checks nothing");
    }

    #[test]
    fn a_try_gives_up_once_its_cap_is_out_of_reach() {
        // the projection: too early to tell, no progress, fast and slow rates
        assert!(!out_of_reach(EARLY_FROM - 1, 1.0, 1e-6, 100));
        assert!(out_of_reach(EARLY_FROM, 1.0, 1e-6, 100));
        // 16 iterations took the residual ratio to 1e-3: 1e-6 in ~32
        assert!(!out_of_reach(16, 1e-6, 1e-6, 40));
        assert!(out_of_reach(16, 1e-6, 1e-6, 30));
        let (a, _) = spd_grid(5);
        let n = a.n;
        let filter = vec![Filter::Free; n];
        let b: Vec<Vector3<f64>> = (0..n)
            .map(|i| Vector3::new(1.0, (i as f64).sin(), -0.5))
            .collect();
        let z = vec![Vector3::zeros(); n];
        let mut pcg = Pcg::default();
        let solve = |pcg: &mut Pcg, cap: Cap| {
            let mut x = vec![Vector3::zeros(); n];
            let r = pcg.solve(
                &a,
                &b,
                &filter,
                &z,
                &mut x,
                1e-13,
                cap,
                Preconditioner::BlockJacobi,
                &mut Team::new(1),
            );
            (r, pcg.spent(), x)
        };
        let (r, spent, exact) = solve(&mut pcg, Cap::Hard(10_000));
        let needed = r.unwrap();
        assert_eq!(spent, needed);
        assert!(
            needed > 24,
            "the test needs a system that takes a while: {needed}"
        );
        // within a cap it clearly meets, the try converges to the same
        // solution (this system's CG speeds up as it goes: with the cap at
        // `needed` itself the early rate would give up, see the doc)
        let (r, spent, x) = solve(&mut pcg, Cap::Reachable(10_000));
        assert_eq!(r.unwrap(), needed);
        assert_eq!(spent, needed);
        for i in 0..n {
            assert_eq!(x[i], exact[i]);
        }
        // a cap well out of reach: the plain solve runs to it, the try gives up
        // at the first check
        let cap = needed / 2;
        let (r, spent, _) = solve(&mut pcg, Cap::Hard(cap));
        assert!(r.is_err());
        assert_eq!(spent, cap);
        let (r, spent, _) = solve(&mut pcg, Cap::Reachable(cap));
        assert!(r.unwrap_err().to_string().contains("would not converge"));
        assert_eq!(spent, EARLY_FROM);
    }

    /// The PCG on a team of two or three threads (rows split between them,
    /// partial sums added in thread order) gives the one-thread solution to
    /// round-off, in about the same iterations, bit for bit the same on a
    /// repeat; a try whose cap is out of reach gives up at the same
    /// iteration on every thread count.
    #[test]
    fn pcg_on_a_team_matches_one_thread() {
        let (a, _) = spd_grid_sized(60, 55, 5);
        let n = a.n;
        let (filter, b, z) = mixed_constraints(n);
        let solve = |team: &mut Team, cap: Cap| {
            let mut pcg = Pcg::default();
            let mut x = vec![Vector3::zeros(); n];
            let r = pcg.solve(
                &a,
                &b,
                &filter,
                &z,
                &mut x,
                1e-10,
                cap,
                Preconditioner::BlockJacobi,
                team,
            );
            (r, pcg.spent(), x)
        };
        let (r1, _, x1) = solve(&mut Team::new(1), Cap::Hard(10_000));
        let it1 = r1.unwrap();
        assert!(
            it1 > 3 * EARLY_FROM,
            "the test needs a slower system: {it1}"
        );
        let scale = x1.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for size in [2, 3] {
            let mut team = Team::new(size);
            let (r, _, x) = solve(&mut team, Cap::Hard(10_000));
            let it = r.unwrap();
            assert!(it.abs_diff(it1) <= 1, "{size} threads: {it} against {it1}");
            for i in 0..n {
                assert!(
                    (x[i] - x1[i]).amax() <= 1e-8 * scale,
                    "{size} threads, vertex {i}: {:?} against {:?}",
                    x[i],
                    x1[i]
                );
                // the constraint (I − S) x = z holds
                assert!((x[i] - filter[i].apply(&x[i]) - z[i]).amax() <= 1e-15);
            }
            let (r, _, again) = solve(&mut team, Cap::Hard(10_000));
            assert_eq!(r.unwrap(), it);
            assert!(
                x.iter().zip(&again).all(|(p, q)| p == q),
                "not reproducible"
            );
            // a cap far out of reach: given up at the first check, everywhere
            let (r, spent, _) = solve(&mut team, Cap::Reachable(it / 2));
            assert!(r.unwrap_err().to_string().contains("would not converge"));
            assert_eq!(spent, EARLY_FROM);
        }
    }

    /// The PCG preconditioned by symmetric block Gauss–Seidel gives the
    /// direct solve's constrained solution (free, contact and pinned
    /// vertices, prescribed parts z) on one, two and three threads (each
    /// sweeping its own rows), in fewer iterations than the block-Jacobi
    /// PCG, bit for bit the same on a repeat; a try whose cap is out of
    /// reach gives up at the first check.
    #[test]
    fn sgs_pcg_matches_the_direct_solve_on_every_thread_count() {
        let (a, mass) = spd_grid_sized(60, 55, 5);
        let n = a.n;
        let (filter, b, z) = mixed_constraints(n);
        let mut exact = vec![Vector3::zeros(); n];
        Direct::new(&a)
            .unwrap()
            .solve(&a, &b, &filter, &z, &mass, &mut exact)
            .unwrap();
        let scale = exact.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let solve = |team: &mut Team, cap: Cap, p: Preconditioner| {
            let mut pcg = Pcg::default();
            let mut x = vec![Vector3::zeros(); n];
            let r = pcg.solve(&a, &b, &filter, &z, &mut x, 1e-12, cap, p, team);
            (r, pcg.spent(), x)
        };
        let (r, _, _) = solve(
            &mut Team::new(1),
            Cap::Hard(10_000),
            Preconditioner::BlockJacobi,
        );
        let jacobi = r.unwrap();
        for size in [1, 2, 3] {
            let mut team = Team::new(size);
            let (r, _, x) = solve(&mut team, Cap::Hard(10_000), Preconditioner::Sgs);
            let it = r.unwrap();
            assert!(
                it * 3 < jacobi * 2,
                "{size} threads: {it} iterations against block-Jacobi's {jacobi}"
            );
            for i in 0..n {
                assert!(
                    (x[i] - exact[i]).amax() <= 1e-8 * scale,
                    "{size} threads, vertex {i}: {:?} against {:?}",
                    x[i],
                    exact[i]
                );
                // the constraint (I − S) x = z holds
                assert!((x[i] - filter[i].apply(&x[i]) - z[i]).amax() <= 1e-15);
            }
            let (r, _, again) = solve(&mut team, Cap::Hard(10_000), Preconditioner::Sgs);
            assert_eq!(r.unwrap(), it);
            assert!(
                x.iter().zip(&again).all(|(p, q)| p == q),
                "not reproducible"
            );
            // a cap half of what it needs: given up at the first check
            let cap = EARLY_FROM + 1;
            assert!(it >= 2 * cap, "the test needs a slower system: {it}");
            let (r, spent, _) = solve(&mut team, Cap::Reachable(cap), Preconditioner::Sgs);
            assert!(r.unwrap_err().to_string().contains("would not converge"));
            assert_eq!(spent, EARLY_FROM);
        }
    }

    /// The direct solve (f64 and f32-preconditioned) and the filtered PCG
    /// give the same constrained solution: a free, a contact and a pinned
    /// kind of vertex, with prescribed parts z.
    #[test]
    fn direct_and_pcg_agree_under_the_constraint_filter() {
        // 6 × 5: faer's simplicial factor; 40 × 40: a supernodal one, whose
        // single-precision solve is ours
        for (nx, ny, supernodal) in [(6, 5, false), (40, 40, true)] {
            let (a, mass) = spd_grid_sized(nx, ny, 11);
            let direct = Direct::new(&a).unwrap();
            assert_eq!(direct.sn.is_some(), supernodal, "{nx} x {ny}");
            agree_under_the_constraint_filter(a, mass);
        }
    }

    fn agree_under_the_constraint_filter(a: BlockMatrix, mass: Vec<f64>) {
        let n = a.n;
        let (filter, b, z) = mixed_constraints(n);
        let mut direct = Direct::new(&a).unwrap();
        let mut x_direct = vec![Vector3::zeros(); n];
        direct
            .solve(&a, &b, &filter, &z, &mass, &mut x_direct)
            .unwrap();
        let mut pcg = Pcg::default();
        let mut x_pcg = vec![Vector3::zeros(); n];
        pcg.solve(
            &a,
            &b,
            &filter,
            &z,
            &mut x_pcg,
            1e-13,
            Cap::Hard(10_000),
            Preconditioner::BlockJacobi,
            &mut Team::new(1),
        )
        .unwrap();
        direct
            .factorize(&a, &filter, &mass, Precision::F32)
            .unwrap();
        let mut x_f32 = vec![Vector3::zeros(); n];
        let it = pcg
            .solve_factor(
                &a,
                &b,
                &filter,
                &z,
                &mut x_f32,
                1e-13,
                Cap::Hard(50),
                &mut direct,
            )
            .unwrap();
        assert!(it <= 10, "f32 factor as preconditioner: {it} iterations");
        // the factor is applied once per iteration: the stopping test does
        // not need it
        let before = direct.applied;
        let mut x_again = vec![Vector3::zeros(); n];
        let it_again = pcg
            .solve_factor(
                &a,
                &b,
                &filter,
                &z,
                &mut x_again,
                1e-13,
                Cap::Hard(50),
                &mut direct,
            )
            .unwrap();
        assert_eq!((it_again, &x_again), (it, &x_f32));
        assert_eq!(direct.applied - before, it);
        // and it stops on the PCG's test: the block-Jacobi norm of the
        // filtered residual against that of the filtered b
        for tol in [1e-6, 1e-9] {
            let mut x = vec![Vector3::zeros(); n];
            pcg.solve_factor(&a, &b, &filter, &z, &mut x, tol, Cap::Hard(50), &mut direct)
                .unwrap();
            let (mut rj, mut bj) = (0.0, 0.0);
            for i in 0..n {
                let dinv = a.val[a.diag[i]].try_inverse().unwrap();
                let r = filter[i].apply(&(b[i] - row_mul(&a, i, &x)));
                let fb = filter[i].apply(&b[i]);
                rj += r.dot(&(dinv * r));
                bj += fb.dot(&(dinv * fb));
            }
            assert!(
                rj <= tol * tol * bj * (1.0 + 1e-9),
                "tol {tol}: ratio {:e}",
                (rj / bj).sqrt()
            );
        }
        let scale = x_direct.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for i in 0..n {
            for (name, x) in [("pcg", &x_pcg), ("f32-preconditioned", &x_f32)] {
                assert!(
                    (x[i] - x_direct[i]).amax() <= 1e-9 * scale,
                    "{name} vertex {i}: {:?} vs {:?}",
                    x[i],
                    x_direct[i]
                );
            }
            // the constraint holds exactly: S Δv has no part along the
            // constrained directions beyond z
            let free_part = x_direct[i] - z[i];
            assert!((filter[i].apply(&free_part) - free_part).amax() <= 1e-12 * scale);
            // the residual vanishes in the free directions
            let r = b[i] - row_mul(&a, i, &x_direct);
            assert!(filter[i].apply(&r).amax() <= 1e-9 * scale.max(1.0) * 30.0);
        }
    }

    /// The single-precision supernodal solve gives faer's solution (to
    /// single precision), and both solve `L Lᵀ x = r` for the factor of the
    /// matrix: x is the f64 direct solution to f32 accuracy.
    #[test]
    fn supernodal_solve_matches_faers() {
        let (a, mass) = spd_grid_sized(40, 40, 3);
        let n = a.n;
        let filter = vec![Filter::Free; n];
        let mut direct = Direct::new(&a).unwrap();
        let r: Vec<Vector3<f64>> = (0..n)
            .map(|i| Vector3::new((i as f64 * 0.37).sin(), 1.0, (i as f64 * 0.11).cos()))
            .collect();
        let z = vec![Vector3::zeros(); n];
        let mut exact = vec![Vector3::zeros(); n];
        direct
            .solve(&a, &r, &filter, &z, &mass, &mut exact)
            .unwrap();
        direct
            .factorize(&a, &filter, &mass, Precision::F32)
            .unwrap();
        let mut ours = vec![Vector3::zeros(); n];
        direct.apply(&r, &mut ours);
        let sn = direct.sn.take().expect("a supernodal factor");
        let mut faers = vec![Vector3::zeros(); n];
        direct.apply(&r, &mut faers);
        direct.sn = Some(sn);
        let scale = exact.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let eo: f64 = (0..n)
            .map(|i| (ours[i] - exact[i]).norm_squared())
            .sum::<f64>()
            .sqrt();
        let ef: f64 = (0..n)
            .map(|i| (faers[i] - exact[i]).norm_squared())
            .sum::<f64>()
            .sqrt();
        // double-precision sums: no less accurate than faer's single-precision solve
        assert!(eo <= 1.1 * ef, "error {eo:e} against faer's {ef:e}");
        for i in 0..n {
            assert!(
                (ours[i] - faers[i]).amax() <= 1e-5 * scale,
                "vertex {i}: {:?} vs {:?}",
                ours[i],
                faers[i]
            );
            assert!(
                (ours[i] - exact[i]).amax() <= 1e-4 * scale,
                "vertex {i}: {:?} vs {:?}",
                ours[i],
                exact[i]
            );
        }
        // not a trivial system: the solution differs from the right-hand side
        assert!((0..n).any(|i| (exact[i] - r[i]).amax() > 0.1 * scale));
    }

    /// The filter's one-sided products are `S m` and `m S`.
    #[test]
    fn filter_sides_are_the_matrix_products() {
        let m = Matrix3::new(1.0, 2.0, -3.0, 0.5, -1.5, 4.0, 2.5, 0.25, -0.75);
        for f in [
            Filter::Free,
            Filter::Fixed,
            Filter::Normal(Vector3::new(0.2, -0.4, 0.9).normalize()),
        ] {
            assert!((f.left(&m) - f.matrix() * m).amax() < 1e-14, "{f:?}");
            assert!((f.right(&m) - m * f.matrix()).amax() < 1e-14, "{f:?}");
        }
    }
}
