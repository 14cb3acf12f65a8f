//! Smoothed-aggregation algebraic multigrid (Vaněk, Mandel & Brezina 1996)
//! as the preconditioner of the filtered PCG, built on the filtered system as
//! Tamstorf, Jones & McCormick ("Smoothed aggregation multigrid for cloth
//! simulation", ACM TOG 34(6), 2015) do: the hierarchy is that of
//! `Â = S A S + (I − S) m`, whose restriction to the free directions is the
//! system the PCG solves, and every coarse basis function lies in the range
//! of the filter S when it is built; the cycle prolongates with `S P` and
//! restricts with `Pᵀ S`, so its output obeys the constraints.
//!
//! - Aggregates are fixed once: on the finest level from the cloth's springs
//!   and seam stitches (the links that couple neighbours strongly), on the
//!   coarser ones from the links between the aggregates below, greedily
//!   (Vaněk's three passes). The patterns of the prolongators and coarse
//!   matrices follow, with the position of every product term, so a step
//!   only fills values.
//! - The first tentative prolongator carries the rigid motions of each
//!   aggregate (two coarse nodes: its translations, and its rotations about
//!   its centroid at the current positions), filtered (`S_i`, `−S_i [x_i −
//!   c]×`: a pinned vertex contributes nothing, a contact vertex only its
//!   tangent plane); the next ones each coarse node's three components. The
//!   smoothed one is `P = (I − ω D⁻¹ Â) T` with `ω = 4 / (3 ρ(D⁻¹ Â))`, ρ
//!   estimated by power iterations warm-started from the last step's vector.
//! - Coarse matrices are Galerkin products `Pᵀ Â P`, made symmetric bit for
//!   bit; a coarse direction that every vertex of its aggregate has
//!   constrained has no basis function and gets the aggregate's mass on the
//!   diagonal (`Σ m_i (I − S_i)`), so every coarse matrix is positive definite.
//! - The cycle is a V-cycle with one forward block Gauss–Seidel sweep before
//!   the coarse correction and one backward sweep after (a symmetric
//!   operator, as CG needs), and a sparse Cholesky on the coarsest level.
//!   Coarsening stops at [`COARSEST`] vertices, or earlier at the first
//!   coarse level whose factor has at most [`BOTTOM_PRODUCTS`] times the
//!   finest matrix's values: that level is then solved exactly, which at
//!   large steps saves more iterations than its solve costs (the 1 cm table
//!   drape's first coarse level; not the 0.5 cm one's, nor the garments').
//!   A supernodal factor is held in single precision and its solve sums in
//!   double ([`super::trisolve`]): it applies `(L̃ L̃ᵀ)⁻¹` for the rounded
//!   factor, so the cycle stays symmetric. Its sweeps and transfers read single-precision copies
//!   of the matrices and prolongators ([`Blocks32`]; the cycle is bound by
//!   memory traffic) and compute in double precision; the blocks the sweeps
//!   invert are the rounded diagonal ones. The sweeps read only the lower
//!   triangle of each (symmetric) matrix ([`Lower32`]): a block below the
//!   diagonal serves its row by a gather and its column, transposed, by a
//!   scatter, so each sweep streams half the matrix. The PCG around it
//!   (product, residual, stopping test) stays in double precision.
//! - The prolongators, coarse matrices and coarsest factor are kept from
//!   step to step (up to [`KEEP_MAX`] steps) until the PCG's iterations
//!   beyond those of the first solve with them add up to more than a
//!   setup costs, counted in cycles by the operation counts of
//!   [`Amg::cost`] (about ten at 1 and 0.5 cm; [`Amg::record`]); the
//!   finest level's `S D̂⁻¹ S` follows every step's
//!   matrix and filter. A kept hierarchy is an older approximation of the
//!   coarse problem: the cycle stays symmetric positive definite on the
//!   free directions (the smoother is this step's, and `S P` on the way up
//!   is the transpose of `Pᵀ S` on the way down), so only the iteration
//!   count, never the system solved or its stopping test, depends on it.
//!
//! Everything runs on one thread in a fixed order: reproducible bit for bit.

use super::cpu::has_fma;
#[cfg(target_arch = "x86_64")]
use super::linear::sum_blocks_fma;
use super::linear::{blocks_mul_best, Direct, Filter, Precision, Precond};
use super::sparse::BlockMatrix;
use crate::error::Result;
use nalgebra::{Matrix3, Vector3};

/// The arm (m) of the inertia added to every rotation node: keeps an
/// aggregate on one line (no rotation about it) positive definite.
const ARM: f64 = 1e-3;
/// Coarsening stops at this many vertices (solved directly).
const COARSEST: usize = 300;
/// Coarsening also stops at the first coarse level whose Cholesky factor
/// has at most this many times the finest matrix's values: solving it
/// exactly then costs a cycle about as much as a few products with the
/// finest matrix, and at large steps its exact solve saves more iterations
/// than that (the 1 cm table drape at dt = 1/120 s: 24.2 → 13.7 a step).
const BOTTOM_PRODUCTS: f64 = 1.5;
/// Most levels, the finest included.
const MAX_LEVELS: usize = 10;
/// Power iterations for ρ(D⁻¹ Â) at the first setup, and at each later one
/// (warm-started).
const POWER_FIRST: usize = 12;
const POWER_AGAIN: usize = 3;
/// Steps the coarse levels are kept at most.
const KEEP_MAX: u32 = 8;

/// Block CSR with `n` rows of 3 × 3 blocks (rectangular).
#[derive(Debug, Clone, Default)]
struct Csr {
    ptr: Vec<usize>,
    col: Vec<u32>,
    val: Vec<Matrix3<f64>>,
}

impl Csr {
    fn from_rows(rows: &[Vec<u32>]) -> Csr {
        let mut ptr = Vec::with_capacity(rows.len() + 1);
        let mut col = Vec::new();
        ptr.push(0);
        for r in rows {
            col.extend_from_slice(r);
            ptr.push(col.len());
        }
        let val = vec![Matrix3::zeros(); col.len()];
        Csr { ptr, col, val }
    }
    fn pos(&self, i: usize, j: u32) -> u32 {
        let r = &self.col[self.ptr[i]..self.ptr[i + 1]];
        (self.ptr[i] + r.binary_search(&j).expect("in the pattern")) as u32
    }
}

/// The transfer between a level (fine, `n` vertices) and the next (coarse).
#[derive(Debug, Clone)]
struct Transfer {
    /// Aggregate of each fine vertex.
    agg: Vec<u32>,
    /// Aggregates.
    nagg: usize,
    /// Rotations too: aggregate J has the coarse nodes 2J (translations)
    /// and 2J + 1 (rotations about its centroid); else node J, translations.
    rot: bool,
    /// Each vertex's offset from its aggregate's centroid (`rot`).
    arm: Vec<Vector3<f64>>,
    /// Each vertex's block of the rotations in the tentative prolongator,
    /// `−S_i [arm_i]×` (`rot`).
    rot_t: Vec<Matrix3<f64>>,
    /// Smoothed prolongator (fine × coarse).
    p: Csr,
    /// The transpose of each block of P (the restriction's blocks).
    pt: Vec<Matrix3<f64>>,
    /// P in single precision, for the cycle (the restriction scatters its
    /// blocks transposed, [`scatter32_t`]).
    p32: Blocks32,
    /// For each block of the fine matrix (row i, column j): the position of
    /// `agg[j]` in row i of P.
    p_pos: Vec<u32>,
    /// `Â P` (fine × coarse).
    ap: Csr,
    /// For each fine row i, block (i, j), entry of P's row j in turn: the
    /// position of its column in row i of `Â P`.
    ap_pos: Vec<u32>,
    /// For each fine row i, entry of P's row i, entry of `Â P`'s row i in
    /// turn: the position in the coarse matrix.
    g_pos: Vec<u32>,
    /// For each entry of P (row i, coarse column I): the first entry of
    /// `Â P`'s row i whose column is I or right of it. The Galerkin sums
    /// fill the coarse matrix's upper triangle from there and mirror it.
    g_start: Vec<u32>,
    /// Power-iteration vector of ρ(D⁻¹ Â) (kept from step to step).
    eig: Vec<Vector3<f64>>,
}

#[derive(Debug, Clone, Default)]
struct Work {
    x: Vec<Vector3<f64>>,
    b: Vec<Vector3<f64>>,
    t: Vec<Vector3<f64>>,
    /// The sweeps' sums scattered from the other rows (see [`Acc4`]).
    acc: Vec<Acc4>,
    dinv: Vec<Matrix3<f64>>,
}

/// A vector of three, padded to four and aligned, that a fused kernel adds
/// into with one aligned load and store.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(32))]
struct Acc4([f64; 4]);

impl Acc4 {
    #[inline(always)]
    fn vec(&self) -> Vector3<f64> {
        Vector3::new(self.0[0], self.0[1], self.0[2])
    }
}

/// The hierarchy and its work space.
pub struct Amg {
    /// Coarse matrices: `coarse[l]` is level l + 1's.
    coarse: Vec<BlockMatrix>,
    /// Transpose positions of each coarse matrix's blocks.
    coarse_t: Vec<Vec<u32>>,
    /// The lower triangles of the finest matrix and the coarse ones in
    /// single precision, for the cycle's sweeps (see [`Lower32`]).
    fine32: Lower32,
    coarse32: Vec<Lower32>,
    transfers: Vec<Transfer>,
    work: Vec<Work>,
    bottom: Direct,
    bottom_filter: Vec<Filter>,
    bottom_mass: Vec<f64>,
    set: bool,
    /// Steps since the coarse levels were last filled.
    age: u32,
    /// Iterations of the first solve with the coarse levels as last filled.
    fresh: usize,
    /// A solve took more iterations than [`Amg::record`] allows.
    stale: bool,
    /// Iterations beyond `fresh` summed over the solves since.
    extra: usize,
    /// A setup's cost in cycles ([`Amg::cost`]): the extra iterations
    /// beyond which the coarse levels are filled again.
    keep_extra: f64,
    /// Blocks of the finest matrix.
    blocks0: usize,
    /// Coarsening stopped at a level cheap to solve exactly
    /// ([`BOTTOM_PRODUCTS`]).
    exact: bool,
}

impl Amg {
    /// A copy of the hierarchy as it stands (its kept coarse levels decide a
    /// solve's iterates bit for bit), the coarsest factor computed again
    /// from the same values; `None` for a single level, which keeps nothing
    /// from step to step (its factor is that of each step's matrix).
    pub fn try_clone(&self) -> Option<Amg> {
        let last = self.coarse.last()?;
        let mut bottom = Direct::new(last).ok()?;
        if let (true, Some(p)) = (self.set, self.bottom.held()) {
            // the precision the original's factor has: the same bits
            bottom
                .factorize(last, &self.bottom_filter, &self.bottom_mass, p)
                .ok()?;
        }
        Some(Amg {
            coarse: self.coarse.clone(),
            coarse_t: self.coarse_t.clone(),
            fine32: self.fine32.clone(),
            coarse32: self.coarse32.clone(),
            transfers: self.transfers.clone(),
            work: self.work.clone(),
            bottom,
            bottom_filter: self.bottom_filter.clone(),
            bottom_mass: self.bottom_mass.clone(),
            set: self.set,
            age: self.age,
            fresh: self.fresh,
            stale: self.stale,
            extra: self.extra,
            keep_extra: self.keep_extra,
            blocks0: self.blocks0,
            exact: self.exact,
        })
    }
}

impl std::fmt::Debug for Amg {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Amg")
            .field("levels", &self.sizes())
            .finish()
    }
}

/// Greedy aggregation (Vaněk, Mandel & Brezina 1996): a vertex whose
/// neighbours are all free of aggregates founds one with them; the rest join
/// a neighbouring aggregate of that first pass; what remains founds
/// aggregates with its remaining neighbours. Returns each vertex's aggregate
/// and their count.
fn aggregate(adj: &[Vec<u32>]) -> (Vec<u32>, usize) {
    const NONE: u32 = u32::MAX;
    let n = adj.len();
    let mut agg = vec![NONE; n];
    let mut count = 0u32;
    for i in 0..n {
        if agg[i] != NONE || adj[i].iter().any(|&j| agg[j as usize] != NONE) {
            continue;
        }
        agg[i] = count;
        for &j in &adj[i] {
            agg[j as usize] = count;
        }
        count += 1;
    }
    let first = agg.clone();
    for i in 0..n {
        if agg[i] == NONE {
            if let Some(&j) = adj[i].iter().find(|&&j| first[j as usize] != NONE) {
                agg[i] = first[j as usize];
            }
        }
    }
    for i in 0..n {
        if agg[i] != NONE {
            continue;
        }
        agg[i] = count;
        for &j in &adj[i] {
            if agg[j as usize] == NONE {
                agg[j as usize] = count;
            }
        }
        count += 1;
    }
    (agg, count as usize)
}

fn block_inverse(d: &Matrix3<f64>) -> Matrix3<f64> {
    d.try_inverse()
        .unwrap_or_else(|| Matrix3::from_diagonal(&d.diagonal().map(|x| 1.0 / x.max(1e-300))))
}

impl Amg {
    /// Builds the hierarchy's patterns for the matrix pattern `a` (values
    /// unused) and the finest level's links `edges` (vertex pairs).
    pub fn new(a: &BlockMatrix, edges: &[[usize; 2]]) -> Result<Amg> {
        Self::with_bottom(a, edges, BOTTOM_PRODUCTS)
    }

    /// [`Amg::new`] with coarsening stopped at the first coarse level whose
    /// factor has at most `bottom_products` times the values of `a` (0: only
    /// at [`COARSEST`] vertices).
    fn with_bottom(a: &BlockMatrix, edges: &[[usize; 2]], bottom_products: f64) -> Result<Amg> {
        let n = a.n;
        let mut adj: Vec<Vec<u32>> = vec![Vec::new(); n];
        for &[p, q] in edges {
            if p != q {
                adj[p].push(q as u32);
                adj[q].push(p as u32);
            }
        }
        for r in adj.iter_mut() {
            r.sort_unstable();
            r.dedup();
        }
        let mut coarse: Vec<BlockMatrix> = Vec::new();
        let mut transfers = Vec::new();
        let mut level_n = n;
        let mut bottom = None;
        while level_n > COARSEST && transfers.len() + 1 < MAX_LEVELS {
            let fine = coarse.last().unwrap_or(a);
            let (agg, nc) = aggregate(&adj);
            if nc == 0 || nc * 10 > level_n * 8 {
                break;
            }
            let rot = transfers.is_empty();
            let (t, c) = Self::symbolic(fine, agg, nc, rot);
            let nc = c.n;
            // the next aggregation's links: those of the aggregates (the
            // coarse matrix couples aggregates two apart too, which would
            // make the next aggregates far larger)
            let per = nc / t.nagg;
            let mut next: Vec<Vec<u32>> = vec![Vec::new(); nc];
            for (i, r) in adj.iter().enumerate() {
                let ni = t.agg[i] as usize * per;
                for &j in r {
                    let nj = t.agg[j as usize] as usize * per;
                    for q in 0..per {
                        for w in 0..per {
                            if ni + q != nj + w {
                                next[ni + q].push((nj + w) as u32);
                            }
                        }
                    }
                }
            }
            for r in next.iter_mut() {
                r.sort_unstable();
                r.dedup();
            }
            adj = next;
            transfers.push(t);
            coarse.push(c);
            level_n = nc;
            if level_n > COARSEST && bottom_products > 0.0 {
                let d = Direct::new(coarse.last().expect("pushed"))?;
                if d.nnz_l() as f64 <= bottom_products * 9.0 * a.col.len() as f64 {
                    bottom = Some(d);
                    break;
                }
            }
        }
        let last = coarse.last().unwrap_or(a);
        let exact = bottom.is_some();
        let bottom = match bottom {
            Some(d) => d,
            None => Direct::new(last)?,
        };
        let coarse_t: Vec<Vec<u32>> = coarse
            .iter()
            .map(|c| {
                (0..c.n)
                    .flat_map(|i| (c.row_ptr[i]..c.row_ptr[i + 1]).map(move |k| (i, k)))
                    .map(|(i, k)| c.index(c.col[k] as usize, i) as u32)
                    .collect()
            })
            .collect();
        let mut sizes = vec![n];
        sizes.extend(coarse.iter().map(|c| c.n));
        let work = sizes
            .iter()
            .map(|&m| Work {
                x: vec![Vector3::zeros(); m],
                b: vec![Vector3::zeros(); m],
                t: vec![Vector3::zeros(); m],
                acc: vec![Acc4::default(); m],
                dinv: vec![Matrix3::zeros(); m],
            })
            .collect();
        let mut amg = Amg {
            bottom_filter: vec![Filter::Free; level_n],
            bottom_mass: vec![0.0; level_n],
            coarse32: coarse.iter().map(Lower32::new).collect(),
            coarse,
            fine32: Lower32::new(a),
            coarse_t,
            transfers,
            work,
            bottom,
            set: false,
            age: 0,
            fresh: 0,
            stale: false,
            extra: 0,
            keep_extra: 0.0,
            blocks0: a.col.len(),
            exact,
        };
        let (setup, cycle) = amg.cost();
        amg.keep_extra = setup / cycle.max(1.0);
        Ok(amg)
    }

    /// The cost of a setup and of a cycle, in products with the finest
    /// matrix (one PCG iteration's main cost), by operation counts: a 3 × 3
    /// block product of the setup (P, `Â P`, the Galerkin sums) counts as
    /// three block-vector products; a cycle multiplies by every block of
    /// every level's matrix and prolongator twice (the sweeps' gathers and
    /// scatters of the lower triangle count as the whole matrix's blocks)
    /// plus the PCG's own product. The coarsest level's factorisation and
    /// solves are left out of both: counting its solve in the cycle alone
    /// refilled the hierarchy too often (the 1 cm drape's bench at
    /// dt = 1/120 s 10.1–11.6 against 8.4–10.0 ms a step).
    pub fn cost(&self) -> (f64, f64) {
        let blocks0: f64 = self.blocks0 as f64;
        let mut setup = (POWER_AGAIN + 1) as f64 * blocks0;
        for (l, t) in self.transfers.iter().enumerate() {
            let upper: usize = (0..t.agg.len())
                .flat_map(|i| (t.p.ptr[i]..t.p.ptr[i + 1]).map(move |e| (i, e)))
                .map(|(i, e)| t.ap.ptr[i + 1] - t.g_start[e] as usize)
                .sum();
            setup += 3.0 * (t.ap_pos.len() + upper) as f64 + 2.0 * self.level_blocks(l);
        }
        (setup / blocks0.max(1.0), self.cycle_cost())
    }

    /// A cycle's cost, as in [`Amg::cost`], without the setup's (whose count
    /// walks every entry of P): cheap enough for every step.
    pub fn cycle_cost(&self) -> f64 {
        let blocks0 = self.blocks0 as f64;
        let mut cycle = blocks0;
        for (l, t) in self.transfers.iter().enumerate() {
            cycle += 2.0 * (self.level_blocks(l) + t.p.col.len() as f64);
        }
        cycle / blocks0.max(1.0)
    }

    /// A cycle's cost as in [`Amg::cycle_cost`] with the exact solve of the
    /// coarse level counted (its two passes over the factor, a multiply-add
    /// per value: on the 1 cm table drape 2.6 products of the finest
    /// matrix, more than the rest of the cycle's 4.3); the cycle's cost
    /// alone where the coarsest level is not factored in this sense
    /// ([`Amg::exact_bottom`] false).
    pub fn exact_cycle_cost(&self) -> f64 {
        let bottom = match self.exact {
            true => 2.0 * self.bottom.nnz_l() as f64 / (9.0 * self.blocks0.max(1) as f64),
            false => 0.0,
        };
        self.cycle_cost() + bottom
    }

    /// Blocks of level l's matrix (0: the finest).
    fn level_blocks(&self, l: usize) -> f64 {
        if l == 0 {
            self.blocks0 as f64
        } else {
            self.coarse[l - 1].col.len() as f64
        }
    }

    /// Has the next [`Amg::setup`] fill the coarse levels again (a caller
    /// that skipped steps: the kept levels would be of an older matrix).
    pub fn refill(&mut self) {
        self.stale = true;
    }

    /// Whether coarsening stopped at a coarse level cheap to solve exactly
    /// (see [`BOTTOM_PRODUCTS`]): two levels whose coarse one is factored.
    pub fn exact_bottom(&self) -> bool {
        self.exact
    }

    /// Vertices of each level, finest first.
    pub fn sizes(&self) -> Vec<usize> {
        let mut s = vec![self.work[0].x.len()];
        s.extend(self.coarse.iter().map(|c| c.n));
        s
    }

    /// The patterns of P, `Â P` and `Pᵀ Â P` for aggregates `agg`.
    fn symbolic(a: &BlockMatrix, agg: Vec<u32>, nagg: usize, rot: bool) -> (Transfer, BlockMatrix) {
        let n = a.n;
        // the first coarse node of each vertex's aggregate, and the nodes per aggregate
        let per = if rot { 2 } else { 1 };
        let node = |j: usize| agg[j] * per;
        let nc = nagg * per as usize;
        let mut rows: Vec<Vec<u32>> = (0..n)
            .map(|i| {
                let mut r: Vec<u32> = a.col[a.row_ptr[i]..a.row_ptr[i + 1]]
                    .iter()
                    .flat_map(|&j| (0..per).map(move |q| node(j as usize) + q))
                    .collect();
                r.sort_unstable();
                r.dedup();
                r
            })
            .collect();
        let p = Csr::from_rows(&rows);
        let p_pos: Vec<u32> = (0..n)
            .flat_map(|i| (a.row_ptr[i]..a.row_ptr[i + 1]).map(move |k| (i, k)))
            .map(|(i, k)| p.pos(i, node(a.col[k] as usize)))
            .collect();
        for (i, r) in rows.iter_mut().enumerate() {
            r.clear();
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                let j = a.col[k] as usize;
                r.extend_from_slice(&p.col[p.ptr[j]..p.ptr[j + 1]]);
            }
            r.sort_unstable();
            r.dedup();
        }
        let ap = Csr::from_rows(&rows);
        let mut ap_pos = Vec::new();
        for i in 0..n {
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                let j = a.col[k] as usize;
                for e in p.ptr[j]..p.ptr[j + 1] {
                    ap_pos.push(ap.pos(i, p.col[e]));
                }
            }
        }
        // coarse pattern: row I gathers AP's rows i over the rows of P with column I
        let mut crow: Vec<Vec<u32>> = (0..nc).map(|i| vec![i as u32]).collect();
        for i in 0..n {
            for e in p.ptr[i]..p.ptr[i + 1] {
                crow[p.col[e] as usize].extend_from_slice(&ap.col[ap.ptr[i]..ap.ptr[i + 1]]);
            }
        }
        let mut row_ptr = vec![0];
        let mut col = Vec::new();
        let mut diag = Vec::with_capacity(nc);
        for (i, r) in crow.iter_mut().enumerate() {
            r.sort_unstable();
            r.dedup();
            for &j in r.iter() {
                if j as usize == i {
                    diag.push(col.len());
                }
                col.push(j);
            }
            row_ptr.push(col.len());
        }
        let c = BlockMatrix {
            n: nc,
            val: vec![Matrix3::zeros(); col.len()],
            row_ptr,
            col,
            diag,
            triangles: Default::default(),
        };
        let mut g_pos = Vec::new();
        for i in 0..n {
            for e in p.ptr[i]..p.ptr[i + 1] {
                let ci = p.col[e] as usize;
                for q in ap.ptr[i]..ap.ptr[i + 1] {
                    g_pos.push(c.index(ci, ap.col[q] as usize) as u32);
                }
            }
        }
        let g_start = (0..n)
            .flat_map(|i| (p.ptr[i]..p.ptr[i + 1]).map(move |e| (i, e)))
            .map(|(i, e)| {
                let r = &ap.col[ap.ptr[i]..ap.ptr[i + 1]];
                (ap.ptr[i] + r.partition_point(|&c| c < p.col[e])) as u32
            })
            .collect();
        let t = Transfer {
            agg,
            nagg,
            rot,
            arm: vec![Vector3::zeros(); if rot { n } else { 0 }],
            rot_t: vec![Matrix3::zeros(); if rot { n } else { 0 }],
            pt: vec![Matrix3::zeros(); p.col.len()],
            p32: Blocks32::default(),
            p,
            p_pos,
            ap,
            ap_pos,
            g_pos,
            g_start,
            eig: Vec::new(),
        };
        (t, c)
    }

    /// Fills the hierarchy for this step's matrix `a`, filter and masses,
    /// and factorises the coarsest level; or, while the coarse levels are
    /// kept (see the module's notes), only the finest level's `S D̂⁻¹ S`.
    pub fn setup(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        mass: &[f64],
        x: &[Vector3<f64>],
    ) -> Result<()> {
        let levels = self.transfers.len();
        if levels > 0 {
            self.fine32.fill(a);
        }
        if self.set && levels > 0 && !self.stale && self.age + 1 < KEEP_MAX {
            Self::fill_dinv(a, Some(filter), mass, &mut self.work[0]);
            self.age += 1;
            return Ok(());
        }
        self.age = 0;
        self.stale = false;
        for l in 0..levels {
            let (fine_slice, rest) = self.coarse.split_at_mut(l);
            let fine: &BlockMatrix = if l == 0 { a } else { &fine_slice[l - 1] };
            let c = &mut rest[0];
            let f = if l == 0 { Some(filter) } else { None };
            let first = !self.set;
            Self::fill_level(
                fine,
                f,
                mass,
                x,
                &mut self.transfers[l],
                &mut self.work[l],
                c,
                &self.coarse_t[l],
                first,
            );
            // the sweeps' copy (the coarsest level is solved, not swept)
            if l + 1 < levels {
                self.coarse32[l].fill(&self.coarse[l]);
            }
        }
        // diagonal blocks of the coarsest level, for its smoothing-free solve
        let last = self.coarse.last().unwrap_or(a);
        if levels == 0 {
            // a single level: the factor of Â itself
            self.bottom.factorize(last, filter, mass, Precision::F64)?;
        } else {
            // a supernodal factor in single precision (its solve sums in
            // double: the cycle stays symmetric), half the traffic of an
            // exact first coarse level's solve; in double if that fails
            let (f, m) = (&self.bottom_filter, &self.bottom_mass);
            let single = self.bottom.supernodal()
                && self.bottom.factorize(last, f, m, Precision::F32).is_ok();
            if !single {
                self.bottom.factorize(last, f, m, Precision::F64)?;
            }
        }
        self.set = true;
        Ok(())
    }

    /// Takes the iterations of the solve preconditioned since the last
    /// [`Amg::setup`]: the first after the coarse levels were filled sets
    /// the reference; once the later ones have needed more iterations
    /// beyond it in all than a setup costs in cycles ([`Amg::cost`]), the
    /// next setup fills them again (rent or buy: the extra cycles paid for
    /// keeping an aged hierarchy never exceed the price of a new one).
    pub fn record(&mut self, iterations: usize) {
        if self.age == 0 {
            self.fresh = iterations;
            self.extra = 0;
        } else {
            self.extra += iterations.saturating_sub(self.fresh);
            if self.extra as f64 > self.keep_extra {
                self.stale = true;
            }
        }
    }

    /// `S D̂⁻¹ S`, `D̂ = S A_ii S + (I − S) m`, for each vertex of a level.
    fn fill_dinv(a: &BlockMatrix, filter: Option<&[Filter]>, mass: &[f64], w: &mut Work) {
        let fl = |i: usize| filter.map_or(Filter::Free, |f| f[i]);
        for i in 0..a.n {
            // the diagonal block as the cycle's sweeps read it (single
            // precision): the sweeps' residuals then vanish as they should,
            // and the cycle stays symmetric to double-precision rounding
            let d = a.val[a.diag[i]].map(|v| v as f32 as f64);
            w.dinv[i] = match fl(i) {
                Filter::Free => block_inverse(&d),
                Filter::Fixed => Matrix3::zeros(),
                f => {
                    let dh = f.left(&f.right(&d)) + (Matrix3::identity() - f.matrix()) * mass[i];
                    f.left(&f.right(&block_inverse(&dh)))
                }
            };
        }
    }

    /// One level's numeric setup: `D⁻¹` (filtered), ω, P, `Â P`, the coarse
    /// matrix.
    #[allow(clippy::too_many_arguments)]
    fn fill_level(
        a: &BlockMatrix,
        filter: Option<&[Filter]>,
        mass: &[f64],
        x: &[Vector3<f64>],
        t: &mut Transfer,
        w: &mut Work,
        c: &mut BlockMatrix,
        c_t: &[u32],
        first: bool,
    ) {
        let n = a.n;
        let fma = has_fma();
        let fl = |i: usize| filter.map_or(Filter::Free, |f| f[i]);
        Self::fill_dinv(a, filter, mass, w);
        // ρ(D⁻¹ Â) by power iterations on the range of S
        if t.eig.len() != n {
            t.eig = (0..n)
                .map(|i| {
                    let s = 1.0 + 0.25 * ((i * 7919) % 13) as f64;
                    fl(i).apply(&Vector3::new(s, 2.0 - 0.1 * s, 0.5 + 0.05 * s))
                })
                .collect();
        }
        let iters = if first { POWER_FIRST } else { POWER_AGAIN };
        let mut rho = 0.0;
        for _ in 0..iters {
            let mut nx = 0.0;
            let mut ny = 0.0;
            for i in 0..n {
                let y = w.dinv[i] * blocks_mul_best(fma, a, a.row_ptr[i], a.row_ptr[i + 1], &t.eig);
                nx += t.eig[i].norm_squared();
                ny += y.norm_squared();
                w.t[i] = y;
            }
            if !(ny > 0.0 && ny.is_finite()) {
                break;
            }
            rho = (ny / nx.max(1e-300)).sqrt();
            let s = 1.0 / ny.sqrt();
            for i in 0..n {
                t.eig[i] = w.t[i] * s;
            }
        }
        let omega = if rho > 0.0 { 4.0 / (3.0 * rho) } else { 0.0 };
        // rotations: each vertex's arm from its aggregate's centroid, and
        // T_i's second block −S_i [arm_i]×
        if t.rot {
            let mut cen = vec![(Vector3::zeros(), 0.0); t.nagg];
            for i in 0..n {
                let c = &mut cen[t.agg[i] as usize];
                c.0 += x[i];
                c.1 += 1.0;
            }
            for i in 0..n {
                let c = cen[t.agg[i] as usize];
                t.arm[i] = x[i] - c.0 / c.1;
            }
        }
        if t.rot {
            for i in 0..n {
                t.rot_t[i] = fl(i).left(&(-t.arm[i].cross_matrix()));
            }
        }
        // P = (I − ω D⁻¹ Â) T, T_j = S_j
        smooth_prolongator(fma, a, filter, &w.dinv, omega, t);
        for (pt, p) in t.pt.iter_mut().zip(&t.p.val) {
            *pt = p.transpose();
        }
        t.p32.fill(&t.p.val);
        // Â P = S A P
        galerkin(fma, a, filter, t, c);
        // directions constrained over a whole aggregate: the aggregate's
        // mass (and its moment of inertia for the rotations; plus that of a
        // millimetre's arm, for the axis of an aggregate on one line)
        if let Some(f) = filter {
            let per = if t.rot { 2 } else { 1 };
            for i in 0..n {
                let ci = per * t.agg[i] as usize;
                let free = f[i].matrix();
                if f[i] != Filter::Free {
                    let reg = (Matrix3::identity() - free) * mass[i];
                    c.val[c.diag[ci]] += reg;
                }
                if t.rot {
                    let r = -t.arm[i].cross_matrix();
                    let reg = r.transpose() * (Matrix3::identity() - free) * r
                        + Matrix3::identity() * (ARM * ARM);
                    c.val[c.diag[ci + 1]] += reg * mass[i];
                }
            }
        }
        // symmetric bit for bit: the upper triangle mirrored
        for k in 0..c.val.len() {
            let kt = c_t[k] as usize;
            if kt > k {
                c.val[kt] = c.val[k].transpose();
            } else if kt == k {
                c.val[k] = (c.val[k] + c.val[k].transpose()) * 0.5;
            }
        }
    }

    /// `out = M⁻¹ r`, one V-cycle (`a` and `filter` as given to the last
    /// [`Amg::setup`]), and `rᵀ out` summed as the cycle's last loop writes
    /// `out` (the PCG's next `δ`, without another pass over the vectors).
    pub fn apply_dot(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        r: &[Vector3<f64>],
        out: &mut [Vector3<f64>],
    ) -> f64 {
        let levels = self.transfers.len();
        let fma = has_fma();
        for i in 0..a.n {
            self.work[0].b[i] = filter[i].apply(&r[i]);
        }
        if levels == 0 {
            self.bottom.apply(&self.work[0].b, out);
            let mut d = 0.0;
            for i in 0..a.n {
                out[i] = filter[i].apply(&out[i]);
                d += r[i].dot(&out[i]);
            }
            return d;
        }
        // down: pre-smooth, restrict
        for l in 0..levels {
            let m32 = if l == 0 {
                &self.fine32
            } else {
                &self.coarse32[l - 1]
            };
            let (w, rest) = self.work[l..].split_first_mut().expect("levels");
            let f = if l == 0 { Some(filter) } else { None };
            down(fma, m32, f, &self.transfers[l], w, &mut rest[0]);
        }
        // bottom
        {
            let w = &mut self.work[levels];
            self.bottom.apply(&w.b, &mut w.x);
        }
        // up: prolongate, post-smooth backwards
        for l in (0..levels).rev() {
            let m32 = if l == 0 {
                &self.fine32
            } else {
                &self.coarse32[l - 1]
            };
            let (w, rest) = self.work[l..].split_first_mut().expect("levels");
            let f = if l == 0 { Some(filter) } else { None };
            up(fma, m32, f, &self.transfers[l], w, &rest[0].x);
        }
        let mut d = 0.0;
        for i in 0..a.n {
            out[i] = filter[i].apply(&self.work[0].x[i]);
            d += r[i].dot(&out[i]);
        }
        d
    }
}

/// A kernel `$k::<FMA>` behind `fn $name(fma, …)`, which calls its copy
/// compiled with AVX2 and FMA (`$fma`) when `fma` is set (only where the CPU
/// has them) and the portable one otherwise.
macro_rules! fma_dispatch {
    ($(#[$m:meta])* fn $name:ident / $fma:ident => $k:ident($($arg:ident: $ty:ty),* $(,)?)) => {
        $(#[$m])*
        fn $name(fma: bool, $($arg: $ty),*) {
            #[cfg(target_arch = "x86_64")]
            if fma {
                // SAFETY: `fma` is set only where the CPU has AVX2 and FMA
                return unsafe { $fma($($arg),*) };
            }
            $k::<false>($($arg),*);
        }

        #[doc = concat!("[`", stringify!($name), "`] compiled with AVX2 and FMA.")]
        ///
        /// # Safety
        /// The CPU must have AVX2 and FMA.
        #[cfg(target_arch = "x86_64")]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn $fma($($arg: $ty),*) {
            $k::<true>($($arg),*);
        }
    };
}

fma_dispatch! {
    /// The smoothed prolongator `P = (I − ω D⁻¹ Â) T` into `t.p` (`dinv` =
    /// `S D̂⁻¹ S`; T's blocks `S_j` and, with rotations, `t.rot_t`), with AVX2
    /// and FMA when `fma`.
    fn smooth_prolongator / smooth_prolongator_fma => smooth_prolongator_k(a: &BlockMatrix, filter: Option<&[Filter]>, dinv: &[Matrix3<f64>], omega: f64, t: &mut Transfer)
}

#[inline(always)]
fn smooth_prolongator_k<const FMA: bool>(
    a: &BlockMatrix,
    filter: Option<&[Filter]>,
    dinv: &[Matrix3<f64>],
    omega: f64,
    t: &mut Transfer,
) {
    let fl = |i: usize| filter.map_or(Filter::Free, |f| f[i]);
    for v in t.p.val.iter_mut() {
        *v = Matrix3::zeros();
    }
    for i in 0..a.n {
        let di = dinv[i] * (-omega);
        for k in a.row_ptr[i]..a.row_ptr[i + 1] {
            let j = a.col[k] as usize;
            let pos = t.p_pos[k] as usize;
            let mut dij = Matrix3::zeros();
            mat_mul_add::<FMA>(&mut dij, &di, &a.val[k]);
            t.p.val[pos] += fl(j).right(&dij);
            if t.rot {
                mat_mul_add::<FMA>(&mut t.p.val[pos + 1], &dij, &t.rot_t[j]);
            }
        }
        let d = t.p_pos[a.diag[i]] as usize;
        t.p.val[d] += fl(i).matrix();
        if t.rot {
            t.p.val[d + 1] += t.rot_t[i];
        }
    }
}

fma_dispatch! {
    /// `Â P` (`S A P`, S the filter on the finest level) into `t.ap`, then the
    /// upper triangle of the coarse matrix `Pᵀ Â P` into `c` (its lower
    /// triangle zero), with AVX2 and FMA when `fma`.
    fn galerkin / galerkin_fma => galerkin_k(a: &BlockMatrix, filter: Option<&[Filter]>, t: &mut Transfer, c: &mut BlockMatrix)
}

#[inline(always)]
fn galerkin_k<const FMA: bool>(
    a: &BlockMatrix,
    filter: Option<&[Filter]>,
    t: &mut Transfer,
    c: &mut BlockMatrix,
) {
    let n = a.n;
    for v in t.ap.val.iter_mut() {
        *v = Matrix3::zeros();
    }
    let mut q = 0;
    for i in 0..n {
        for k in a.row_ptr[i]..a.row_ptr[i + 1] {
            let j = a.col[k] as usize;
            let aik = &a.val[k];
            for e in t.p.ptr[j]..t.p.ptr[j + 1] {
                mat_mul_add::<FMA>(&mut t.ap.val[t.ap_pos[q] as usize], aik, &t.p.val[e]);
                q += 1;
            }
        }
        if let Some(f) = filter {
            if f[i] != Filter::Free {
                for e in t.ap.ptr[i]..t.ap.ptr[i + 1] {
                    t.ap.val[e] = f[i].left(&t.ap.val[e]);
                }
            }
        }
    }
    for v in c.val.iter_mut() {
        *v = Matrix3::zeros();
    }
    let mut q = 0;
    for i in 0..n {
        let (lo, hi) = (t.ap.ptr[i], t.ap.ptr[i + 1]);
        for e in t.p.ptr[i]..t.p.ptr[i + 1] {
            let pt = &t.pt[e];
            for g in t.g_start[e] as usize..hi {
                let pos = t.g_pos[q + g - lo] as usize;
                mat_mul_add::<FMA>(&mut c.val[pos], pt, &t.ap.val[g]);
            }
            q += hi - lo;
        }
    }
}

/// `c += a b` for 3 × 3 blocks; with `FMA` (only where the CPU has AVX2 and
/// FMA, inlined into callers compiled with them) each column of the sum is
/// one four-wide fused chain over the columns of `a` (nalgebra stores a
/// block column-major, nine contiguous f64).
#[inline(always)]
fn mat_mul_add<const FMA: bool>(c: &mut Matrix3<f64>, a: &Matrix3<f64>, b: &Matrix3<f64>) {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: FMA is only set where the CPU has AVX2 and FMA
        unsafe { mat_mul_add_fma(c, a, b) };
        return;
    }
    *c += a * b;
}

/// [`mat_mul_add`] with AVX2 and FMA.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn mat_mul_add_fma(c: &mut Matrix3<f64>, a: &Matrix3<f64>, b: &Matrix3<f64>) {
    use std::arch::x86_64::*;
    let ap = a.as_ptr();
    let bp = b.as_ptr();
    let cp = c.as_mut_ptr();
    // columns 0 and 1 read four wide (the fourth lane is the next column's
    // first entry, dropped); column 2 from entries 5..9, moved down a lane
    let a0 = _mm256_loadu_pd(ap);
    let a1 = _mm256_loadu_pd(ap.add(3));
    let a2 = _mm256_permute4x64_pd::<0b11_11_10_01>(_mm256_loadu_pd(ap.add(5)));
    let c0 = _mm256_loadu_pd(cp);
    let c1 = _mm256_loadu_pd(cp.add(3));
    let c2 = _mm256_permute4x64_pd::<0b11_11_10_01>(_mm256_loadu_pd(cp.add(5)));
    macro_rules! col {
        ($cj:expr, $j:expr) => {{
            let t = _mm256_fmadd_pd(a0, _mm256_broadcast_sd(&*bp.add(3 * $j)), $cj);
            let t = _mm256_fmadd_pd(a1, _mm256_broadcast_sd(&*bp.add(3 * $j + 1)), t);
            _mm256_fmadd_pd(a2, _mm256_broadcast_sd(&*bp.add(3 * $j + 2)), t)
        }};
    }
    let r0 = col!(c0, 0);
    let r1 = col!(c1, 1);
    let r2 = col!(c2, 2);
    // stored in order, each four-wide store's fourth lane overwritten by
    // the next; the last column three wide
    _mm256_storeu_pd(cp, r0);
    _mm256_storeu_pd(cp.add(3), r1);
    _mm_storeu_pd(cp.add(6), _mm256_castpd256_pd128(r2));
    _mm_store_sd(cp.add(8), _mm256_extractf128_pd::<1>(r2));
}

/// `acc + m v`; with `FMA` (only where the CPU has AVX2 and FMA, inlined
/// into callers compiled with them) one four-wide fused chain.
#[inline(always)]
fn mat_vec_add<const FMA: bool>(
    m: &Matrix3<f64>,
    v: &Vector3<f64>,
    acc: &Vector3<f64>,
) -> Vector3<f64> {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: FMA is only set where the CPU has AVX2 and FMA
        return unsafe { mat_vec_add_fma(m, v, acc) };
    }
    acc + m * v
}

fma_dispatch! {
    /// The cycle's way down on one level (matrix `m`, its lower triangle;
    /// `filter` on the finest): a forward block Gauss–Seidel sweep from zero
    /// into `w.x`, and the restriction of the residual left into the next
    /// level's right-hand side `next.b` (scattered by `Pᵀ` through `next.acc`). Each block below the diagonal is read once: for the sweep
    /// (`A_ij x_j`, j < i) and, transposed, for the residual the sweep leaves in
    /// row j (`−A_ijᵀ x_i = −A_ji x_i` into row j with the new x_i, summed in `w.acc`).
    fn down / down_fma => down_k(m: &Lower32, filter: Option<&[Filter]>, t: &Transfer, w: &mut Work, next: &mut Work)
}

#[inline(always)]
fn down_k<const FMA: bool>(
    m: &Lower32,
    filter: Option<&[Filter]>,
    t: &Transfer,
    w: &mut Work,
    next: &mut Work,
) {
    let n = m.ptr.len() - 1;
    w.acc.iter_mut().for_each(|v| *v = Acc4::default());
    // from zero: the blocks right of the diagonal multiply zeros; the sweep
    // zeroes each row's (filtered) residual as it goes, so what is left of
    // row j is −Σ_{i > j} A_ji x_i, summed as the x_i come
    for i in 0..n {
        let (lo, d) = (m.ptr[i], m.ptr[i + 1] - 1);
        let ri = w.b[i] - row32_k::<FMA>(&m.col, &m.val, lo, d, &w.x);
        let xi = mat_vec_add::<FMA>(&w.dinv[i], &ri, &Vector3::zeros());
        w.x[i] = xi;
        scatter32_t::<FMA>(&m.col, &m.val, lo, d, &-xi, &mut w.acc);
    }
    next.acc.iter_mut().for_each(|v| *v = Acc4::default());
    for i in 0..n {
        let ri = match filter {
            Some(f) => f[i].apply(&w.acc[i].vec()),
            None => w.acc[i].vec(),
        };
        scatter32_t::<FMA>(
            &t.p.col,
            &t.p32,
            t.p.ptr[i],
            t.p.ptr[i + 1],
            &ri,
            &mut next.acc,
        );
    }
    for (b, a) in next.b.iter_mut().zip(&next.acc) {
        *b = a.vec();
    }
}

fma_dispatch! {
    /// The cycle's way up on one level: the prolongation of the next level's
    /// correction `xc` into `w.x`, then a backward block Gauss–Seidel sweep over
    /// the lower triangle `m`: row i gathers its blocks left of the diagonal and
    /// the diagonal with the x not yet updated, and `w.acc[i]`, where the rows
    /// below have scattered `A_ji x_j` (j > i) with their new x_j.
    fn up / up_fma => up_k(m: &Lower32, filter: Option<&[Filter]>, t: &Transfer, w: &mut Work, xc: &[Vector3<f64>])
}

#[inline(always)]
fn up_k<const FMA: bool>(
    m: &Lower32,
    filter: Option<&[Filter]>,
    t: &Transfer,
    w: &mut Work,
    xc: &[Vector3<f64>],
) {
    let n = m.ptr.len() - 1;
    for i in 0..n {
        let e = row32_k::<FMA>(&t.p.col, &t.p32, t.p.ptr[i], t.p.ptr[i + 1], xc);
        w.x[i] += match filter {
            Some(f) => f[i].apply(&e),
            None => e,
        };
    }
    w.acc.iter_mut().for_each(|v| *v = Acc4::default());
    for i in (0..n).rev() {
        let (lo, hi) = (m.ptr[i], m.ptr[i + 1]);
        let ri = w.b[i] - w.acc[i].vec() - row32_k::<FMA>(&m.col, &m.val, lo, hi, &w.x);
        let xi = mat_vec_add::<FMA>(&w.dinv[i], &ri, &w.x[i]);
        w.x[i] = xi;
        scatter32_t::<FMA>(&m.col, &m.val, lo, hi - 1, &xi, &mut w.acc);
    }
}

/// The lower triangle of a symmetric block matrix, the diagonal block last
/// in each row, in single precision ([`Blocks32`]): the cycle's sweeps read
/// each block below the diagonal once for its row and once, transposed, for
/// its column (half the memory traffic of the whole matrix).
#[derive(Debug, Clone, Default)]
struct Lower32 {
    ptr: Vec<usize>,
    col: Vec<u32>,
    val: Blocks32,
}

impl Lower32 {
    /// The pattern of `m`'s lower triangle (fixed for the hierarchy's life,
    /// as `m`'s own), without values.
    fn new(m: &BlockMatrix) -> Lower32 {
        let mut ptr = Vec::with_capacity(m.n + 1);
        let mut col = Vec::new();
        ptr.push(0);
        for i in 0..m.n {
            col.extend_from_slice(&m.col[m.row_ptr[i]..=m.diag[i]]);
            ptr.push(col.len());
        }
        Lower32 {
            ptr,
            col,
            val: Blocks32::default(),
        }
    }

    /// The values of `m`, whose pattern is the one [`Lower32::new`] was given.
    fn fill(&mut self, m: &BlockMatrix) {
        assert_eq!(self.ptr.len(), m.n + 1, "the matrix's pattern changed");
        self.val.0.clear();
        self.val.0.reserve(9 * self.col.len() + 3);
        for i in 0..m.n {
            for v in &m.val[m.row_ptr[i]..=m.diag[i]] {
                self.val.push(v);
            }
        }
        assert_eq!(
            self.val.0.len(),
            9 * self.col.len(),
            "the matrix's pattern changed"
        );
        self.val.0.extend([0.0; 3]);
    }
}

/// 3 × 3 blocks in single precision, for the cycle: the sweeps and
/// transfers read each block as nine f32 (half the memory traffic of the
/// f64 blocks, which the cycle, bound by memory, streams several times an
/// iteration) and compute in f64. Column-major like nalgebra's blocks, nine
/// floats a block, and three spare zeros at the end so that every column
/// can be read four wide. The PCG itself (its product, residual and
/// stopping test) stays in double precision: only the preconditioner is
/// rounded.
#[derive(Debug, Clone, Default)]
struct Blocks32(Vec<f32>);

impl Blocks32 {
    fn fill(&mut self, val: &[Matrix3<f64>]) {
        self.0.clear();
        self.0.reserve(9 * val.len() + 3);
        for m in val {
            self.push(m);
        }
        self.0.extend([0.0; 3]);
    }

    #[inline]
    fn push(&mut self, m: &Matrix3<f64>) {
        self.0.extend(m.as_slice().iter().map(|&v| v as f32));
    }

    /// Block k as f64 (the portable kernels).
    #[inline(always)]
    fn block(&self, k: usize) -> Matrix3<f64> {
        Matrix3::from_fn(|r, c| self.0[9 * k + 3 * c + r] as f64)
    }
}

/// `Σ_k val[k] x[col[k]]` over `lo..hi` with single-precision blocks
/// ([`Blocks32`]); with `FMA` [`blocks32_mul_fma`].
#[inline(always)]
fn row32_k<const FMA: bool>(
    col: &[u32],
    val: &Blocks32,
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
) -> Vector3<f64> {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: FMA is only set where the CPU has AVX2 and FMA
        return unsafe { blocks32_mul_fma(col, &val.0, lo, hi, x) };
    }
    let mut s = Vector3::zeros();
    for k in lo..hi {
        s += val.block(k) * x[col[k] as usize];
    }
    s
}

/// `acc[col[k]] += val_kᵀ v` for the blocks `lo..hi` (one row's blocks,
/// scattered transposed into their columns); with `FMA`
/// [`scatter32_t_fma`].
#[inline(always)]
fn scatter32_t<const FMA: bool>(
    col: &[u32],
    val: &Blocks32,
    lo: usize,
    hi: usize,
    v: &Vector3<f64>,
    acc: &mut [Acc4],
) {
    #[cfg(target_arch = "x86_64")]
    if FMA {
        // SAFETY: FMA is only set where the CPU has AVX2 and FMA
        return unsafe { scatter32_t_fma(col, &val.0, lo, hi, v, acc) };
    }
    for k in lo..hi {
        let a = &mut acc[col[k] as usize].0;
        let y = val.block(k).transpose() * v;
        for r in 0..3 {
            a[r] += y[r];
        }
    }
}

/// [`scatter32_t`] with AVX2 and FMA: `val_kᵀ v = v.x m_0· + v.y m_1· +
/// v.z m_2·`, the rows `m_r·` of the column-major block (floats r, r + 3,
/// r + 6) permuted out of two eight-wide reads, added into the padded
/// accumulator with one fused chain.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn scatter32_t_fma(
    col: &[u32],
    val: &[f32],
    lo: usize,
    hi: usize,
    v: &Vector3<f64>,
    acc: &mut [Acc4],
) {
    use std::arch::x86_64::*;
    assert!(lo <= hi && hi <= col.len());
    assert!(hi == lo || 9 * hi <= val.len());
    // the fourth lane multiplies by zero: the padding stays zero
    let (vx, vy, vz) = (
        _mm256_setr_pd(v.x, v.x, v.x, 0.0),
        _mm256_setr_pd(v.y, v.y, v.y, 0.0),
        _mm256_setr_pd(v.z, v.z, v.z, 0.0),
    );
    let i0 = _mm256_setr_epi32(0, 3, 6, 6, 0, 0, 0, 0);
    let i1 = _mm256_setr_epi32(1, 4, 7, 7, 0, 0, 0, 0);
    let vp = val.as_ptr();
    for k in lo..hi {
        let j = *col.get_unchecked(k) as usize;
        let a = &mut acc[j];
        let m = vp.add(9 * k);
        let lo8 = _mm256_loadu_ps(m);
        let hi8 = _mm256_loadu_ps(m.add(1));
        let r0 = _mm256_cvtps_pd(_mm256_castps256_ps128(_mm256_permutevar8x32_ps(lo8, i0)));
        let r1 = _mm256_cvtps_pd(_mm256_castps256_ps128(_mm256_permutevar8x32_ps(lo8, i1)));
        let r2 = _mm256_cvtps_pd(_mm256_castps256_ps128(_mm256_permutevar8x32_ps(hi8, i1)));
        let t = _mm256_load_pd(a.0.as_ptr());
        let t = _mm256_fmadd_pd(r0, vx, t);
        let t = _mm256_fmadd_pd(r1, vy, t);
        let t = _mm256_fmadd_pd(r2, vz, t);
        _mm256_store_pd(a.0.as_mut_ptr(), t);
    }
}

/// [`row32_k`] with AVX2 and FMA: each column of a block read four wide
/// (its fourth lane, the next column's first float or a spare zero, is
/// dropped) and widened to f64, two accumulators.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn blocks32_mul_fma(
    col: &[u32],
    val: &[f32],
    lo: usize,
    hi: usize,
    x: &[Vector3<f64>],
) -> Vector3<f64> {
    use std::arch::x86_64::*;
    assert!(lo <= hi && hi <= col.len());
    // the last block's third column is read up to float 9 hi + 1
    assert!(hi == lo || 9 * hi + 3 <= val.len());
    let vp = val.as_ptr();
    let xp = x.as_ptr() as *const f64;
    let nx = x.len();
    sum_blocks_fma(lo, hi, |k| {
        let j = *col.get_unchecked(k) as usize;
        assert!(j < nx);
        let m = vp.add(9 * k);
        let xj = xp.add(3 * j);
        let t = _mm256_mul_pd(_mm256_cvtps_pd(_mm_loadu_ps(m)), _mm256_broadcast_sd(&*xj));
        let t = _mm256_fmadd_pd(
            _mm256_cvtps_pd(_mm_loadu_ps(m.add(3))),
            _mm256_broadcast_sd(&*xj.add(1)),
            t,
        );
        _mm256_fmadd_pd(
            _mm256_cvtps_pd(_mm_loadu_ps(m.add(6))),
            _mm256_broadcast_sd(&*xj.add(2)),
            t,
        )
    })
}

/// [`mat_vec_add`] with AVX2 and FMA.
///
/// # Safety
/// The CPU must have AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
#[inline]
unsafe fn mat_vec_add_fma(m: &Matrix3<f64>, v: &Vector3<f64>, acc: &Vector3<f64>) -> Vector3<f64> {
    use std::arch::x86_64::*;
    let mp = m.as_ptr();
    let c0 = _mm256_loadu_pd(mp);
    let c1 = _mm256_loadu_pd(mp.add(3));
    let c2 = _mm256_permute4x64_pd::<0b11_11_10_01>(_mm256_loadu_pd(mp.add(5)));
    let t = _mm256_setr_pd(acc.x, acc.y, acc.z, 0.0);
    let t = _mm256_fmadd_pd(c0, _mm256_set1_pd(v.x), t);
    let t = _mm256_fmadd_pd(c1, _mm256_set1_pd(v.y), t);
    let t = _mm256_fmadd_pd(c2, _mm256_set1_pd(v.z), t);
    let mut out = [0.0; 4];
    _mm256_storeu_pd(out.as_mut_ptr(), t);
    Vector3::new(out[0], out[1], out[2])
}

#[cfg(test)]
impl Amg {
    /// Asserts that the cycle for `a` under `filter` is a symmetric positive
    /// operator on the free directions (as CG needs) whose output has no
    /// part along the constrained ones, on two fixed vectors.
    pub(super) fn check_cycle(&mut self, a: &BlockMatrix, filter: &[Filter]) {
        let n = a.n;
        let u: Vec<Vector3<f64>> = (0..n)
            .map(|i| filter[i].apply(&Vector3::new((i as f64).cos(), 0.3, (i as f64 * 0.2).sin())))
            .collect();
        let v: Vec<Vector3<f64>> = (0..n)
            .map(|i| filter[i].apply(&Vector3::new(0.5, (i as f64 * 1.3).sin(), -1.0)))
            .collect();
        let (mut mu, mut mv) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        self.apply_dot(a, filter, &u, &mut mu);
        self.apply_dot(a, filter, &v, &mut mv);
        let dot = |p: &[Vector3<f64>], q: &[Vector3<f64>]| -> f64 {
            p.iter().zip(q).map(|(p, q)| p.dot(q)).sum()
        };
        let (uv, vu) = (dot(&u, &mv), dot(&v, &mu));
        assert!(
            (uv - vu).abs() <= 1e-10 * uv.abs().max(vu.abs()),
            "{uv} vs {vu}"
        );
        assert!(dot(&u, &mu) > 0.0 && dot(&v, &mv) > 0.0);
        // the fused `rᵀ out` of the PCG
        let mut mu2 = vec![Vector3::zeros(); n];
        let d = self.apply_dot(a, filter, &u, &mut mu2);
        assert_eq!(mu2, mu);
        assert!((d - dot(&u, &mu)).abs() <= 1e-12 * d.abs(), "{d}");
        for i in 0..n {
            assert!((filter[i].apply(&mu[i]) - mu[i]).amax() <= 1e-15 * mu[i].amax().max(1.0));
        }
    }
}

/// The multigrid as the preconditioner of [`Pcg::solve_factor`](super::linear::Pcg::solve_factor).
impl Precond for Amg {
    /// One V-cycle, whose output is filtered already ([`Amg::apply_dot`]).
    fn apply_dot(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        r: &[Vector3<f64>],
        out: &mut [Vector3<f64>],
    ) -> f64 {
        Amg::apply_dot(self, a, filter, r, out)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_systems::{grid_edges, mixed_constraints, spd_grid_sized};
    use super::*;
    use std::collections::BTreeMap;

    /// An `nx` × `ny` grid with random PSD springs to the right, upper and
    /// diagonal neighbours and a mass on the diagonal, its springs, and a
    /// filter with pinned, contact and free vertices.
    fn grid(nx: usize, ny: usize) -> (BlockMatrix, Vec<f64>, Vec<[usize; 2]>, Vec<Filter>) {
        let (a, mass) = spd_grid_sized(nx, ny, 0x9e37_79b9_7f4a_7c15);
        let edges = grid_edges(nx, ny);
        let n = a.n;
        let filter = (0..n)
            .map(|i| match i % 7 {
                0 => Filter::Fixed,
                3 | 5 => Filter::Normal(Vector3::new(0.3, -0.4, 1.0).normalize()),
                _ => Filter::Free,
            })
            .collect();
        (a, mass, edges, filter)
    }

    /// The positions of an `nx`-wide grid of `n` vertices: a plane, 1 cm
    /// apart.
    fn plane(nx: usize, n: usize) -> Vec<Vector3<f64>> {
        (0..n)
            .map(|k| Vector3::new((k % nx) as f64 * 0.01, (k / nx) as f64 * 0.01, 0.0))
            .collect()
    }

    /// [`grid`], its vertices' positions (a plane, 1 cm apart) and a
    /// hierarchy set up for it.
    #[allow(clippy::type_complexity)]
    fn grid_hierarchy(
        nx: usize,
        ny: usize,
    ) -> (BlockMatrix, Vec<f64>, Vec<Filter>, Vec<Vector3<f64>>, Amg) {
        let (a, mass, edges, filter) = grid(nx, ny);
        let x = plane(nx, a.n);
        // every level swept (these grids' first coarse level is cheap to
        // solve exactly, which `Amg::new` would do)
        let mut amg = Amg::with_bottom(&a, &edges, 0.0).unwrap();
        amg.setup(&a, &filter, &mass, &x).unwrap();
        (a, mass, filter, x, amg)
    }

    /// Coarsening stops at the first coarse level whose Cholesky factor has
    /// at most [`BOTTOM_PRODUCTS`] times the finest matrix's values, and
    /// only there; that level is solved with a single-precision factor whose
    /// solve sums in double precision, so the cycle stays symmetric; and the
    /// PCG needs no more iterations than with that level swept and
    /// coarsened further, to the same solution.
    #[test]
    fn coarsening_stops_at_a_level_cheap_to_solve_exactly() {
        use super::super::linear::{Cap, Pcg};
        let (nx, ny) = (60, 55);
        let (a, mass, edges, filter) = grid(nx, ny);
        let n = a.n;
        let x = plane(nx, n);
        let mut exact = Amg::new(&a, &edges).unwrap();
        let mut swept = Amg::with_bottom(&a, &edges, 0.0).unwrap();
        let (se, ss) = (exact.sizes(), swept.sizes());
        assert!(
            se.len() == 2 && ss.len() > 2 && se[1] == ss[1],
            "{se:?} {ss:?}"
        );
        let values = 9.0 * a.col.len() as f64;
        let factor = exact.bottom.nnz_l() as f64;
        assert!(factor <= BOTTOM_PRODUCTS * values, "{factor} > {values}");
        // a tighter bound keeps coarsening: the rule, not the size, stopped it
        let tight = Amg::with_bottom(&a, &edges, 0.5 * factor / values).unwrap();
        assert_eq!(tight.sizes(), ss);
        exact.setup(&a, &filter, &mass, &x).unwrap();
        swept.setup(&a, &filter, &mass, &x).unwrap();
        assert_eq!(exact.bottom.held(), Some(Precision::F32));
        exact.check_cycle(&a, &filter);
        let b: Vec<Vector3<f64>> = (0..n)
            .map(|i| Vector3::new((i as f64 * 0.7).sin(), -1.0, (i as f64 * 0.1).cos()))
            .collect();
        let z = vec![Vector3::zeros(); n];
        let solve = |m: &mut Amg| {
            let mut dv = vec![Vector3::zeros(); n];
            let it = Pcg::default()
                .solve_factor(&a, &b, &filter, &z, &mut dv, 1e-10, Cap::Hard(300), m)
                .unwrap();
            (it, dv)
        };
        let ((ie, xe), (is, xs)) = (solve(&mut exact), solve(&mut swept));
        // (on the table drape at large steps far fewer: docs/benchmarks.md;
        // on this random grid the swept levels are as good)
        assert!(
            ie <= is,
            "exact first coarse level {ie} iterations, swept {is}"
        );
        let scale = xs.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for i in 0..n {
            assert!((xe[i] - xs[i]).amax() <= 1e-7 * scale, "vertex {i}");
        }
    }

    /// Every coarse matrix is the Galerkin product `Pᵀ Â P` of the level
    /// below (`Â = S A S + (I − S) m` on the finest, the coarse matrix
    /// itself further down) plus, on the first coarse level, the masses of
    /// the constrained directions and the rotations' inertia, summed here
    /// term by term over the sparse blocks; and symmetric bit for bit.
    #[test]
    fn coarse_matrices_are_the_galerkin_products() {
        let (nx, ny) = (60, 55);
        let (a, mass, edges, filter) = grid(nx, ny);
        let n = a.n;
        let x = plane(nx, n);
        let mut amg = Amg::with_bottom(&a, &edges, 0.0).unwrap();
        assert!(amg.transfers.len() >= 2, "levels {:?}", amg.sizes());
        amg.setup(&a, &filter, &mass, &x).unwrap();
        for l in 0..amg.transfers.len() {
            let fine = if l == 0 { &a } else { &amg.coarse[l - 1] };
            let t = &amg.transfers[l];
            let c = &amg.coarse[l];
            // Â of the level, blockwise
            let hat = |i: usize, k: usize| -> Matrix3<f64> {
                let j = fine.col[k] as usize;
                if l > 0 {
                    return fine.val[k];
                }
                let (si, sj) = (filter[i].matrix(), filter[j].matrix());
                let mut m = si * fine.val[k] * sj;
                if i == j {
                    m += (Matrix3::identity() - si) * mass[i];
                }
                m
            };
            let mut ap: BTreeMap<(usize, usize), Matrix3<f64>> = BTreeMap::new();
            for i in 0..fine.n {
                for k in fine.row_ptr[i]..fine.row_ptr[i + 1] {
                    let j = fine.col[k] as usize;
                    for e in t.p.ptr[j]..t.p.ptr[j + 1] {
                        *ap.entry((i, t.p.col[e] as usize))
                            .or_insert(Matrix3::zeros()) += hat(i, k) * t.p.val[e];
                    }
                }
            }
            let mut want: BTreeMap<(usize, usize), Matrix3<f64>> = BTreeMap::new();
            for (&(i, cj), m) in &ap {
                for e in t.p.ptr[i]..t.p.ptr[i + 1] {
                    *want
                        .entry((t.p.col[e] as usize, cj))
                        .or_insert(Matrix3::zeros()) += t.p.val[e].transpose() * m;
                }
            }
            if l == 0 {
                for i in 0..n {
                    let ci = 2 * t.agg[i] as usize;
                    let free = filter[i].matrix();
                    *want.get_mut(&(ci, ci)).unwrap() += (Matrix3::identity() - free) * mass[i];
                    let r = -t.arm[i].cross_matrix();
                    *want.get_mut(&(ci + 1, ci + 1)).unwrap() +=
                        (r.transpose() * (Matrix3::identity() - free) * r
                            + Matrix3::identity() * (ARM * ARM))
                            * mass[i];
                }
            }
            let scale = c.val.iter().map(|m| m.amax()).fold(0.0, f64::max);
            assert!(scale > 0.0);
            for ci in 0..c.n {
                for k in c.row_ptr[ci]..c.row_ptr[ci + 1] {
                    let cj = c.col[k] as usize;
                    let w = want.get(&(ci, cj)).copied().unwrap_or(Matrix3::zeros());
                    assert!(
                        (c.val[k] - w).amax() <= 1e-12 * scale,
                        "level {l}, block ({ci}, {cj}): {} vs {w}",
                        c.val[k]
                    );
                    assert_eq!(c.val[k], c.val[c.index(cj, ci)].transpose());
                }
            }
            assert!(want.keys().all(|&(ci, cj)| {
                let r = &c.col[c.row_ptr[ci]..c.row_ptr[ci + 1]];
                r.binary_search(&(cj as u32)).is_ok()
            }));
        }
    }

    /// A hierarchy kept from a step with another matrix and other
    /// constraints still makes a symmetric positive definite cycle whose
    /// output obeys this step's filter, and the PCG it preconditions reaches
    /// this step's exact solution.
    #[test]
    fn a_kept_hierarchy_preconditions_the_next_system() {
        use super::super::linear::{Cap, Pcg};
        let (a, mass, filter, x, mut amg) = grid_hierarchy(40, 36);
        let n = a.n;
        amg.record(10);
        // the next step: stiffer springs, constraints moved by one vertex
        // (new contacts, released ones, a pin freed)
        let mut a2 = a.clone();
        for i in 0..n {
            for k in a2.row_ptr[i]..a2.row_ptr[i + 1] {
                let s = if k == a2.diag[i] { 1.0 } else { 1.3 };
                a2.val[k] *= s;
            }
            let off: Matrix3<f64> = (a2.row_ptr[i]..a2.row_ptr[i + 1])
                .filter(|&k| k != a2.diag[i])
                .map(|k| a2.val[k])
                .sum();
            // keep it diagonally dominant: the diagonal balances the springs
            a2.val[a2.diag[i]] = Matrix3::identity() * mass[i] - off;
        }
        let filter2: Vec<Filter> = (0..n).map(|i| filter[(i + 1) % n]).collect();
        amg.setup(&a2, &filter2, &mass, &x).unwrap();
        assert_eq!(amg.age, 1, "the coarse levels are kept");
        amg.check_cycle(&a2, &filter2);
        let b: Vec<Vector3<f64>> = (0..n)
            .map(|i| Vector3::new((i as f64 * 0.7).sin(), -1.0, (i as f64 * 0.1).cos()))
            .collect();
        let z: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                let w = Vector3::new(0.01, -0.02, 0.03);
                w - filter2[i].apply(&w)
            })
            .collect();
        let mut exact = vec![Vector3::zeros(); n];
        Direct::new(&a2)
            .unwrap()
            .solve(&a2, &b, &filter2, &z, &mass, &mut exact)
            .unwrap();
        let mut got = vec![Vector3::zeros(); n];
        Pcg::default()
            .solve_factor(
                &a2,
                &b,
                &filter2,
                &z,
                &mut got,
                1e-10,
                Cap::Hard(300),
                &mut amg,
            )
            .unwrap();
        let scale = exact.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for i in 0..n {
            assert!((got[i] - exact[i]).amax() <= 1e-7 * scale, "vertex {i}");
        }
    }

    /// The coarse levels are filled again once the iterations beyond the
    /// first solve's, summed over the solves with the kept hierarchy, cost
    /// more than a setup (both counted in products with the finest matrix
    /// by [`Amg::cost`]), and at the latest after [`KEEP_MAX`] steps.
    #[test]
    fn the_hierarchy_is_refilled_when_its_extra_cycles_cost_a_setup() {
        let (nx, ny) = (40, 36);
        let (a, mass, edges, filter) = grid(nx, ny);
        let x = plane(nx, a.n);
        let mut amg = Amg::new(&a, &edges).unwrap();
        let (setup, cycle) = amg.cost();
        assert!(setup > cycle && cycle > 1.0, "setup {setup}, cycle {cycle}");
        let budget = setup / cycle;
        assert_eq!(amg.keep_extra, budget);
        // iterations beyond the first solve's (10): up to the budget in all
        // keeps the levels, one more fills them at the next setup
        let within = budget.floor() as usize;
        let step = |amg: &mut Amg, extra: usize| {
            amg.setup(&a, &filter, &mass, &x).unwrap();
            amg.record(10 + extra);
            (amg.age, amg.stale)
        };
        assert_eq!(step(&mut amg, 0), (0, false), "the first setup fills");
        assert_eq!(step(&mut amg, within), (1, false), "{within} extra: kept");
        assert_eq!(step(&mut amg, 0), (2, false), "no more extra: kept");
        assert_eq!(
            step(&mut amg, 1),
            (3, true),
            "{} extra > {budget}",
            within + 1
        );
        assert_eq!(step(&mut amg, 0), (0, false), "filled again");
        // without extra iterations, KEEP_MAX bounds the age
        let ages: Vec<u32> = (0..2 * KEEP_MAX).map(|_| step(&mut amg, 0).0).collect();
        assert!(ages.iter().all(|&g| g < KEEP_MAX), "{ages:?}");
        assert!(
            ages.contains(&(KEEP_MAX - 1)) && ages[1..].contains(&0),
            "{ages:?}"
        );
    }

    /// The fused 3 × 3 kernels agree with nalgebra's products to rounding.
    #[test]
    fn block_kernels_match_the_plain_products() {
        let a = Matrix3::new(1.0, 2.0, -3.0, 0.5, -1.5, 4.0, 2.5, 0.25, -0.75);
        let b = Matrix3::new(-0.3, 1.7, 2.0, 0.9, 0.1, -4.0, 3.5, -2.25, 0.5);
        let c0 = Matrix3::new(0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9);
        let v = Vector3::new(0.7, -1.1, 2.3);
        for fma in [false, true] {
            if fma && !has_fma() {
                continue;
            }
            let mut c = c0;
            if fma {
                mat_mul_add::<true>(&mut c, &a, &b);
            } else {
                mat_mul_add::<false>(&mut c, &a, &b);
            }
            assert!((c - (c0 + a * b)).amax() <= 1e-14, "{c}");
            let y = if fma {
                mat_vec_add::<true>(&a, &v, &c0.column(1).into())
            } else {
                mat_vec_add::<false>(&a, &v, &c0.column(1).into())
            };
            let want: Vector3<f64> = c0.column(1) + a * v;
            assert!((y - want).amax() <= 1e-14, "{y}");
        }
    }

    /// The cycle's single-precision blocks: every row of a random grid
    /// matrix, the last block included (read four wide into the spare
    /// zeros), and single blocks, with and without the fused kernels,
    /// against the double-precision products: equal to f32 rounding of the
    /// blocks (a relative 6e-8 each), and the two kernels equal to f64
    /// rounding of each other.
    #[test]
    fn single_precision_blocks_match_the_double_ones() {
        let (a, _, _, _) = grid(9, 7);
        let mut a32 = Blocks32::default();
        a32.fill(&a.val);
        assert_eq!(a32.0.len(), 9 * a.val.len() + 3);
        let x: Vec<Vector3<f64>> = (0..a.n)
            .map(|i| {
                Vector3::new(
                    (i as f64).sin(),
                    1.0 - 0.1 * i as f64,
                    (0.3 * i as f64).cos(),
                )
            })
            .collect();
        for i in 0..a.n {
            let (lo, hi) = (a.row_ptr[i], a.row_ptr[i + 1]);
            let want = blocks_mul_best(false, &a, lo, hi, &x);
            // the bound: Σ |a| |x| times f32's relative rounding
            let scale: f64 = (lo..hi)
                .map(|k| a.val[k].abs().max() * x[a.col[k] as usize].amax())
                .sum();
            let plain = row32_k::<false>(&a.col, &a32, lo, hi, &x);
            assert!(
                (plain - want).amax() <= 3.0 * 6e-8 * scale,
                "row {i}: {plain} vs {want}"
            );
            if has_fma() {
                let fused = row32_k::<true>(&a.col, &a32, lo, hi, &x);
                assert!(
                    (fused - plain).amax() <= 1e-13 * scale,
                    "row {i}: {fused} vs {plain}"
                );
            }
        }
        let last = a.val.len() - 1;
        let acc = Vector3::new(0.5, -0.25, 2.0);
        for k in [0, last / 2, last] {
            // transposed, as the restriction and the sweeps' scatter read them
            let want = acc + a.val[k].transpose() * x[k % a.n];
            let scale = a.val[k].abs().max() * x[k % a.n].amax();
            let j = a.col[k] as usize;
            let mut sc = vec![Acc4([acc.x, acc.y, acc.z, 0.0]); a.n];
            scatter32_t::<false>(&a.col, &a32, k, k + 1, &x[k % a.n], &mut sc);
            let plain = sc[j].vec();
            assert!(
                (plain - want).amax() <= 3.0 * 6e-8 * scale + 1e-15,
                "block {k}"
            );
            if has_fma() {
                let mut sc = vec![Acc4([acc.x, acc.y, acc.z, 0.0]); a.n];
                scatter32_t::<true>(&a.col, &a32, k, k + 1, &x[k % a.n], &mut sc);
                let fused = sc[j].vec();
                assert!(
                    (fused - plain).amax() <= 1e-13 * scale.max(1.0),
                    "block {k}"
                );
                assert_eq!(sc[j].0[3], 0.0, "the padding stays zero");
            }
        }
    }

    /// The cycle's sweeps over the lower triangle ([`Lower32`]) are block
    /// Gauss–Seidel over the whole matrix: on the finest level of a grid
    /// with pinned, contact and free vertices, the forward sweep from zero,
    /// the residual it leaves (filtered, restricted by `Pᵀ`), the
    /// prolongation and the backward sweep equal a plain sweep over every
    /// block of each row (the single-precision blocks, widened), with and
    /// without the fused kernels.
    #[test]
    fn the_lower_triangle_sweeps_are_gauss_seidel_on_the_whole_matrix() {
        let (a, _, filter, _, mut amg) = grid_hierarchy(23, 19);
        let n = a.n;
        let nc = amg.coarse[0].n;
        let b: Vec<Vector3<f64>> = (0..n)
            .map(|i| {
                filter[i].apply(&Vector3::new(
                    (i as f64).sin(),
                    0.5,
                    -(i as f64 * 0.7).cos(),
                ))
            })
            .collect();
        let xc: Vec<Vector3<f64>> = (0..nc)
            .map(|i| Vector3::new(0.1 * i as f64, -1.0, (i as f64).cos()))
            .collect();
        let t = &amg.transfers[0];
        let blk = |k: usize| a.val[k].map(|v| v as f32 as f64);
        let pblk = |e: usize| t.p.val[e].map(|v| v as f32 as f64);
        let dinv = amg.work[0].dinv.clone();
        // the plain sweeps
        let mut x = vec![Vector3::zeros(); n];
        for i in 0..n {
            let mut s = b[i];
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                if k != a.diag[i] {
                    s -= blk(k) * x[a.col[k] as usize];
                }
            }
            x[i] = dinv[i] * s;
        }
        let mut bc = vec![Vector3::zeros(); nc];
        for i in 0..n {
            let mut r = b[i];
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                r -= blk(k) * x[a.col[k] as usize];
            }
            let r = filter[i].apply(&r);
            for e in t.p.ptr[i]..t.p.ptr[i + 1] {
                bc[t.p.col[e] as usize] += pblk(e).transpose() * r;
            }
        }
        let mut y = x.clone();
        for i in 0..n {
            let mut e = Vector3::zeros();
            for k in t.p.ptr[i]..t.p.ptr[i + 1] {
                e += pblk(k) * xc[t.p.col[k] as usize];
            }
            y[i] += filter[i].apply(&e);
        }
        for i in (0..n).rev() {
            let mut s = b[i];
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                s -= blk(k) * y[a.col[k] as usize];
            }
            y[i] += dinv[i] * s;
        }
        let amax = |v: &[Vector3<f64>]| v.iter().map(|v| v.amax()).fold(0.0, f64::max);
        let (sx, sbc, sy) = (amax(&x), amax(&bc), amax(&y));
        assert!(sx > 0.0 && sbc > 0.0 && sy > 0.0);
        for fma in [false, true] {
            if fma && !has_fma() {
                continue;
            }
            let t = &amg.transfers[0];
            let (w, next) = amg.work.split_first_mut().expect("levels");
            w.b.copy_from_slice(&b);
            w.x.iter_mut()
                .for_each(|v| *v = Vector3::new(7.0, 7.0, 7.0));
            next[0]
                .b
                .iter_mut()
                .for_each(|v| *v = Vector3::new(3.0, 3.0, 3.0));
            down(fma, &amg.fine32, Some(&filter), t, w, &mut next[0]);
            let got_bc = &next[0].b;
            for i in 0..n {
                assert!((w.x[i] - x[i]).amax() <= 1e-12 * sx, "fma {fma}, x {i}");
            }
            for c in 0..nc {
                assert!(
                    (got_bc[c] - bc[c]).amax() <= 1e-10 * sbc,
                    "fma {fma}, bc {c}"
                );
            }
            up(fma, &amg.fine32, Some(&filter), t, w, &xc);
            for i in 0..n {
                assert!((w.x[i] - y[i]).amax() <= 1e-10 * sy, "fma {fma}, y {i}");
            }
        }
    }

    /// The multigrid-preconditioned PCG gives the direct solver's constrained
    /// solution on a grid with free, contact and pinned vertices, in far
    /// fewer iterations than the block-Jacobi PCG; its cycle is a symmetric
    /// positive definite operator on the free directions (as CG needs) whose
    /// output obeys the filter; a repeat is the same bit for bit.
    #[test]
    fn multigrid_pcg_matches_the_direct_solve_under_the_filter() {
        use super::super::linear::{Cap, Direct, Pcg, Preconditioner};
        use super::super::team::Team;
        let (nx, ny) = (60, 55);
        let (a, mass) = spd_grid_sized(nx, ny, 17);
        let n = a.n;
        let (filter, b, z) = mixed_constraints(n);
        let edges = grid_edges(nx, ny);
        let x: Vec<Vector3<f64>> = (0..n)
            .map(|k| Vector3::new((k % nx) as f64 * 0.01, (k / nx) as f64 * 0.01, 0.0))
            .collect();
        let mut amg = Amg::new(&a, &edges).unwrap();
        let sizes = amg.sizes();
        assert!(sizes.len() >= 2 && sizes[1] < n / 3, "levels {sizes:?}");
        amg.setup(&a, &filter, &mass, &x).unwrap();
        // the cycle: symmetric and positive on the free directions, and its
        // output has no part along the constrained ones
        amg.check_cycle(&a, &filter);
        // the solve
        let mut direct = Direct::new(&a).unwrap();
        let mut exact = vec![Vector3::zeros(); n];
        direct
            .solve(&a, &b, &filter, &z, &mass, &mut exact)
            .unwrap();
        let mut pcg = Pcg::default();
        let mut xm = vec![Vector3::zeros(); n];
        let it = pcg
            .solve_factor(
                &a,
                &b,
                &filter,
                &z,
                &mut xm,
                1e-10,
                Cap::Hard(500),
                &mut amg,
            )
            .unwrap();
        let mut xj = vec![Vector3::zeros(); n];
        let it_jacobi = pcg
            .solve(
                &a,
                &b,
                &filter,
                &z,
                &mut xj,
                1e-10,
                Cap::Hard(10_000),
                Preconditioner::BlockJacobi,
                &mut Team::new(1),
            )
            .unwrap();
        assert!(
            3 * it < it_jacobi,
            "multigrid {it} iterations, block-Jacobi {it_jacobi}"
        );
        let scale = exact.iter().map(|v| v.amax()).fold(0.0, f64::max);
        for i in 0..n {
            assert!(
                (xm[i] - exact[i]).amax() <= 1e-7 * scale,
                "vertex {i}: {:?} vs {:?}",
                xm[i],
                exact[i]
            );
            // the constrained part is z exactly
            assert!((xm[i] - filter[i].apply(&xm[i]) - z[i]).amax() <= 1e-15);
        }
        // reproducible: a second hierarchy, set up and solved alike, gives
        // the same bits
        let mut amg2 = Amg::new(&a, &edges).unwrap();
        amg2.setup(&a, &filter, &mass, &x).unwrap();
        let mut again = vec![Vector3::zeros(); n];
        let it2 = pcg
            .solve_factor(
                &a,
                &b,
                &filter,
                &z,
                &mut again,
                1e-10,
                Cap::Hard(500),
                &mut amg2,
            )
            .unwrap();
        assert_eq!(it2, it);
        assert!(xm.iter().zip(&again).all(|(p, q)| p == q));
    }
}
