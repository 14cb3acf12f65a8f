//! The two linear solvers behind one interface: Baraff–Witkin's modified
//! (filtered) preconditioned conjugate gradient, and a direct sparse Cholesky
//! (faer) whose symbolic analysis is computed once and reused.
//!
//! Both solve `A Δv = b` subject to the per-vertex constraint filter of
//! Baraff & Witkin (1998, §5.3): `Δv_i = S_i Δv_i + z_i`, where `S_i` is the
//! identity (free), `I − n nᵀ` (contact along n), or 0 (pinned), and `z_i`
//! is the prescribed velocity change in the constrained directions.

use super::sparse::{BlockMatrix, LowerCsc};
use anyhow::{anyhow, Result};
use faer::dyn_stack::{MemBuffer, MemStack, StackReq};
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{factorize_symbolic_cholesky, SymbolicCholesky};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum LinearSolverKind {
    /// Filtered preconditioned conjugate gradient (block-Jacobi preconditioner).
    Pcg,
    /// Sparse Cholesky (faer), symbolic factorisation reused.
    Cholesky,
    /// The default: the PCG while it converges within the iterations that
    /// cost as much as the Cholesky (from operation counts), else the
    /// Cholesky. By benchmark (README) the PCG wins at small steps (dt = 1e-4
    /// s: 7–25 iterations) and the Cholesky at large ones (dt = 1e-3 s on 1 cm
    /// and finer grids, where the PCG needs hundreds), so neither is the
    /// faster everywhere. Decided on iteration counts, never on measured time:
    /// runs are reproducible.
    #[default]
    Auto,
}

impl std::str::FromStr for LinearSolverKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "pcg" => Ok(Self::Pcg),
            "cholesky" => Ok(Self::Cholesky),
            "auto" => Ok(Self::Auto),
            _ => Err(format!(
                "unknown linear solver {s:?}: expected auto, pcg or cholesky"
            )),
        }
    }
}

/// The constraint on one vertex for this step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Filter {
    Free,
    /// In contact: motion along `normal` is prescribed.
    Normal(Vector3<f64>),
    /// Fully prescribed (pinned).
    Fixed,
}

impl Filter {
    #[inline]
    pub fn apply(&self, v: &Vector3<f64>) -> Vector3<f64> {
        match self {
            Filter::Free => *v,
            Filter::Normal(n) => v - n * n.dot(v),
            Filter::Fixed => Vector3::zeros(),
        }
    }
    #[inline]
    pub fn matrix(&self) -> Matrix3<f64> {
        match self {
            Filter::Free => Matrix3::identity(),
            Filter::Normal(n) => Matrix3::identity() - n * n.transpose(),
            Filter::Fixed => Matrix3::zeros(),
        }
    }
}

/// Workspace of the filtered PCG.
#[derive(Debug, Clone, Default)]
pub struct Pcg {
    r: Vec<Vector3<f64>>,
    c: Vec<Vector3<f64>>,
    q: Vec<Vector3<f64>>,
    s: Vec<Vector3<f64>>,
    pinv: Vec<Matrix3<f64>>,
}

impl Pcg {
    /// Solves with relative tolerance `tol` on the filtered, preconditioned
    /// residual (relative to the right-hand side's, so the start does not
    /// change when it stops); `dv` holds the first guess (its filtered part;
    /// zeros for none) and then the solution. Returns the iteration count.
    #[allow(clippy::too_many_arguments)]
    pub fn solve(
        &mut self,
        a: &BlockMatrix,
        b: &[Vector3<f64>],
        filter: &[Filter],
        z: &[Vector3<f64>],
        dv: &mut [Vector3<f64>],
        tol: f64,
        max_iter: usize,
    ) -> Result<usize> {
        let n = a.n;
        self.r.resize(n, Vector3::zeros());
        self.c.resize(n, Vector3::zeros());
        self.q.resize(n, Vector3::zeros());
        self.s.resize(n, Vector3::zeros());
        self.pinv.resize(n, Matrix3::zeros());
        for i in 0..n {
            let d = a.val[a.diag[i]];
            self.pinv[i] = d.try_inverse().unwrap_or_else(|| {
                Matrix3::from_diagonal(&d.diagonal().map(|x| 1.0 / x.max(1e-300)))
            });
        }
        // start from the caller's guess in dv (the last step's Δv: at small
        // steps Δv changes little from step to step), made to obey the filter
        for i in 0..n {
            let g = if dv[i].iter().all(|c| c.is_finite()) {
                filter[i].apply(&dv[i])
            } else {
                Vector3::zeros()
            };
            dv[i] = g + z[i];
        }
        // δ0 = filter(b)ᵀ P⁻¹ filter(b)
        let mut delta0 = 0.0;
        for i in 0..n {
            let fb = filter[i].apply(&b[i]);
            delta0 += fb.dot(&(self.pinv[i] * fb));
        }
        a.mul(dv, &mut self.q);
        let mut dnew = 0.0;
        for i in 0..n {
            self.r[i] = filter[i].apply(&(b[i] - self.q[i]));
            self.c[i] = filter[i].apply(&(self.pinv[i] * self.r[i]));
            dnew += self.r[i].dot(&self.c[i]);
        }
        if delta0 <= 0.0 {
            return Ok(0);
        }
        let eps2 = tol * tol * delta0;
        let mut it = 0;
        while dnew > eps2 {
            if it >= max_iter {
                return Err(anyhow!(
                    "PCG did not converge in {max_iter} iterations (residual ratio {:.2e})",
                    (dnew / delta0).sqrt()
                ));
            }
            a.mul(&self.c, &mut self.q);
            let mut cq = 0.0;
            for i in 0..n {
                self.q[i] = filter[i].apply(&self.q[i]);
                cq += self.c[i].dot(&self.q[i]);
            }
            if cq <= 0.0 || !cq.is_finite() {
                return Err(anyhow!(
                    "PCG breakdown: the system matrix is not positive definite (cᵀAc = {cq:e})"
                ));
            }
            let alpha = dnew / cq;
            let dold = dnew;
            dnew = 0.0;
            for i in 0..n {
                dv[i] += self.c[i] * alpha;
                self.r[i] -= self.q[i] * alpha;
                self.s[i] = self.pinv[i] * self.r[i];
                dnew += self.r[i].dot(&self.s[i]);
            }
            let beta = dnew / dold;
            for i in 0..n {
                self.c[i] = filter[i].apply(&(self.s[i] + self.c[i] * beta));
            }
            it += 1;
        }
        Ok(it)
    }
}

/// Direct solver: Cholesky of `S A S + (I − S) m` (SPD), symbolic analysis once.
pub struct Direct {
    csc: LowerCsc,
    symbolic: SymbolicCholesky<usize>,
    l_values: Vec<f64>,
    mem: MemBuffer,
    rhs: Vec<f64>,
    tmp: Vec<Vector3<f64>>,
    /// Row of each block of the pattern.
    block_row: Vec<usize>,
    /// Threads of the numeric factorisation and solve.
    par: Par,
}

impl std::fmt::Debug for Direct {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Direct")
            .field("nnz", &self.csc.row_idx.len())
            .finish()
    }
}

impl Direct {
    /// `threads` > 1 factorises on that many threads (faer's rayon
    /// parallelism over the elimination tree and inside the supernodes).
    pub fn new(a: &BlockMatrix, threads: usize) -> Result<Direct> {
        let par = if threads > 1 {
            Par::rayon(threads)
        } else {
            Par::Seq
        };
        let csc = LowerCsc::new(a);
        let sym = SymbolicSparseColMatRef::new_checked(
            csc.dim,
            csc.dim,
            &csc.col_ptr,
            None,
            &csc.row_idx,
        );
        let symbolic =
            factorize_symbolic_cholesky(sym, Side::Lower, Default::default(), Default::default())
                .map_err(|e| anyhow!("sparse Cholesky analysis failed: {e:?}"))?;
        let l_values = vec![0.0; symbolic.len_val()];
        let req = StackReq::any_of(&[
            symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default()),
            symbolic.solve_in_place_scratch::<f64>(1, par),
        ]);
        Ok(Direct {
            rhs: vec![0.0; csc.dim],
            csc,
            symbolic,
            l_values,
            mem: MemBuffer::new(req),
            tmp: vec![Vector3::zeros(); a.n],
            block_row: (0..a.n)
                .flat_map(|i| std::iter::repeat_n(i, a.row_ptr[i + 1] - a.row_ptr[i]))
                .collect(),
            par,
        })
    }

    /// Non-zeros of the Cholesky factor L.
    pub fn nnz_l(&self) -> usize {
        self.symbolic.len_val()
    }

    /// PCG iterations that cost as much as one factorisation and solve, by
    /// operation counts: the factorisation ≈ nnz(L)²/n flops, a PCG iteration
    /// ≈ 2 nnz(A) + 30 n, with κ = 0.46 for the dense supernodal kernels'
    /// speed relative to the sparse products (fitted to this machine's
    /// benchmark: break-even at 63, 150 and 385 iterations on the 2, 1 and
    /// 0.5 cm table drapes; the formula gives 58, 150, 417).
    pub fn break_even_iterations(&self, a: &BlockMatrix) -> usize {
        let n = self.csc.dim as f64;
        let l = self.nnz_l() as f64;
        let per_iter = 2.0 * 9.0 * a.col.len() as f64 + 30.0 * n;
        (0.46 * l * l / n / per_iter).round().max(10.0) as usize
    }

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
        // values of S A S + (I − S) m, lower triangle
        for (k, &(blk, p, q)) in self.csc.src.iter().enumerate() {
            let i = self.block_row[blk];
            let j = a.col[blk];
            let m = &a.val[blk];
            let v = match (filter[i], filter[j]) {
                (Filter::Free, Filter::Free) => m[(p as usize, q as usize)],
                (fi, fj) => {
                    let mut s = fi.matrix() * m * fj.matrix();
                    if i == j {
                        s += (Matrix3::identity() - fi.matrix()) * mass[i];
                    }
                    s[(p as usize, q as usize)]
                }
            };
            self.csc.values[k] = v;
        }
        // rhs = S (b − A z)
        a.mul(z, &mut self.tmp);
        for i in 0..n {
            let r = filter[i].apply(&(b[i] - self.tmp[i]));
            self.rhs[3 * i] = r.x;
            self.rhs[3 * i + 1] = r.y;
            self.rhs[3 * i + 2] = r.z;
        }
        let sym = SymbolicSparseColMatRef::new_checked(
            self.csc.dim,
            self.csc.dim,
            &self.csc.col_ptr,
            None,
            &self.csc.row_idx,
        );
        let mat = SparseColMatRef::new(sym, &self.csc.values);
        let stack = MemStack::new(&mut self.mem);
        let llt = self
            .symbolic
            .factorize_numeric_llt::<f64>(
                &mut self.l_values,
                mat,
                Side::Lower,
                LltRegularization::default(),
                self.par,
                stack,
                Default::default(),
            )
            .map_err(|e| {
                anyhow!("sparse Cholesky failed (matrix not positive definite?): {e:?}")
            })?;
        let rhs = MatMut::from_column_major_slice_mut(&mut self.rhs, self.csc.dim, 1);
        llt.solve_in_place_with_conj(Conj::No, rhs, self.par, MemStack::new(&mut self.mem));
        for i in 0..n {
            dv[i] = Vector3::new(self.rhs[3 * i], self.rhs[3 * i + 1], self.rhs[3 * i + 2]) + z[i];
        }
        Ok(())
    }
}
