//! Smoothed-aggregation algebraic multigrid (Vaněk, Mandel & Brezina 1996)
//! as the preconditioner of the filtered PCG, built on the filtered system as
//! Tamstorf, Jones & McCormick ("Smoothed aggregation multigrid for cloth
//! simulation", ACM TOG 34(6), 2015) do: the hierarchy is that of
//! `Â = S A S + (I − S) m`, whose restriction to the free directions is the
//! system the PCG solves, and every coarse basis function lies in the range
//! of the filter S, so the cycle's output obeys the constraints.
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
//!   operator, as CG needs), and a double-precision sparse Cholesky on the
//!   coarsest level.
//!
//! Everything runs on one thread in a fixed order: reproducible bit for bit.

use super::cpu::has_fma;
use super::linear::{blocks_mul_best, Direct, Filter, Precision};
use super::sparse::BlockMatrix;
use anyhow::Result;
use nalgebra::{Matrix3, Vector3};

/// The arm (m) of the inertia added to every rotation node: keeps an
/// aggregate on one line (no rotation about it) positive definite.
const ARM: f64 = 1e-3;
/// Coarsening stops at this many vertices (solved directly).
const COARSEST: usize = 300;
/// Most levels, the finest included.
const MAX_LEVELS: usize = 10;
/// Power iterations for ρ(D⁻¹ Â) at the first setup, and at each later one
/// (warm-started).
const POWER_FIRST: usize = 12;
const POWER_AGAIN: usize = 3;

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
    /// Smoothed prolongator (fine × coarse).
    p: Csr,
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
    /// Power-iteration vector of ρ(D⁻¹ Â) (kept from step to step).
    eig: Vec<Vector3<f64>>,
}

#[derive(Debug, Clone, Default)]
struct Work {
    x: Vec<Vector3<f64>>,
    b: Vec<Vector3<f64>>,
    t: Vec<Vector3<f64>>,
    dinv: Vec<Matrix3<f64>>,
}

/// The hierarchy and its work space.
pub struct Amg {
    /// Coarse matrices: `coarse[l]` is level l + 1's.
    coarse: Vec<BlockMatrix>,
    /// Transpose positions of each coarse matrix's blocks.
    coarse_t: Vec<Vec<u32>>,
    transfers: Vec<Transfer>,
    work: Vec<Work>,
    bottom: Direct,
    bottom_filter: Vec<Filter>,
    bottom_mass: Vec<f64>,
    set: bool,
    /// Blocks of the finest matrix.
    blocks0: usize,
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
        }
        let last = coarse.last().unwrap_or(a);
        let bottom = Direct::new(last)?;
        let coarse_t = coarse
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
                dinv: vec![Matrix3::zeros(); m],
            })
            .collect();
        Ok(Amg {
            bottom_filter: vec![Filter::Free; level_n],
            bottom_mass: vec![0.0; level_n],
            coarse,
            coarse_t,
            transfers,
            work,
            bottom,
            set: false,
            blocks0: a.col.len(),
        })
    }

    /// The cost of a setup and of a cycle, in products with the finest
    /// matrix (one PCG iteration's main cost), by operation counts: a 3 × 3
    /// block product of the setup (P, `Â P`, the Galerkin sums) counts as
    /// three block-vector products; a cycle makes two passes over every
    /// level's matrix and prolongator plus the PCG's own product.
    pub fn cost(&self) -> (f64, f64) {
        let blocks0: f64 = self.blocks0 as f64;
        let mut setup = (POWER_AGAIN + 1) as f64 * blocks0;
        let mut cycle = blocks0;
        for (l, t) in self.transfers.iter().enumerate() {
            let fine = if l == 0 {
                blocks0
            } else {
                self.coarse[l - 1].col.len() as f64
            };
            setup += 3.0 * (t.ap_pos.len() + t.g_pos.len()) as f64 + 2.0 * fine;
            cycle += 2.0 * (fine + t.p.col.len() as f64);
        }
        (setup / blocks0.max(1.0), cycle / blocks0.max(1.0))
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
        let t = Transfer {
            agg,
            nagg,
            rot,
            arm: vec![Vector3::zeros(); if rot { n } else { 0 }],
            p,
            p_pos,
            ap,
            ap_pos,
            g_pos,
            eig: Vec::new(),
        };
        (t, c)
    }

    /// Fills the hierarchy for this step's matrix `a`, filter and masses,
    /// and factorises the coarsest level.
    pub fn setup(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        mass: &[f64],
        x: &[Vector3<f64>],
    ) -> Result<()> {
        let levels = self.transfers.len();
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
        }
        // diagonal blocks of the coarsest level, for its smoothing-free solve
        let last = self.coarse.last().unwrap_or(a);
        if levels == 0 {
            // a single level: the factor of Â itself
            self.bottom.factorize(last, filter, mass, Precision::F64)?;
        } else {
            self.bottom
                .factorize(last, &self.bottom_filter, &self.bottom_mass, Precision::F64)?;
        }
        self.set = true;
        Ok(())
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
        // S D̂⁻¹ S, D̂ = S A_ii S + (I − S) m
        for i in 0..n {
            let d = a.val[a.diag[i]];
            w.dinv[i] = match fl(i) {
                Filter::Free => block_inverse(&d),
                Filter::Fixed => Matrix3::zeros(),
                f => {
                    let dh = f.left(&f.right(&d)) + (Matrix3::identity() - f.matrix()) * mass[i];
                    f.left(&f.right(&block_inverse(&dh)))
                }
            };
        }
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
        let rot_t = |i: usize, arm: &[Vector3<f64>]| fl(i).left(&(-arm[i].cross_matrix()));
        // P = (I − ω D⁻¹ Â) T, T_j = S_j
        for v in t.p.val.iter_mut() {
            *v = Matrix3::zeros();
        }
        for i in 0..n {
            let di = w.dinv[i] * (-omega);
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                let j = a.col[k] as usize;
                let dij = di * a.val[k];
                let m = fl(j).right(&dij);
                t.p.val[t.p_pos[k] as usize] += m;
                if t.rot {
                    t.p.val[t.p_pos[k] as usize + 1] += dij * rot_t(j, &t.arm);
                }
            }
            let d = t.p_pos[a.diag[i]] as usize;
            t.p.val[d] += fl(i).matrix();
            if t.rot {
                t.p.val[d + 1] += rot_t(i, &t.arm);
            }
        }
        // Â P = S A P
        for v in t.ap.val.iter_mut() {
            *v = Matrix3::zeros();
        }
        let mut q = 0;
        for i in 0..n {
            for k in a.row_ptr[i]..a.row_ptr[i + 1] {
                let j = a.col[k] as usize;
                let aik = a.val[k];
                for e in t.p.ptr[j]..t.p.ptr[j + 1] {
                    t.ap.val[t.ap_pos[q] as usize] += aik * t.p.val[e];
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
        // Pᵀ (Â P)
        for v in c.val.iter_mut() {
            *v = Matrix3::zeros();
        }
        let mut q = 0;
        for i in 0..n {
            for e in t.p.ptr[i]..t.p.ptr[i + 1] {
                let pt = t.p.val[e].transpose();
                for g in t.ap.ptr[i]..t.ap.ptr[i + 1] {
                    c.val[t.g_pos[q] as usize] += pt * t.ap.val[g];
                    q += 1;
                }
            }
        }
        // symmetric bit for bit
        for k in 0..c.val.len() {
            let kt = c_t[k] as usize;
            if kt > k {
                let m = (c.val[k] + c.val[kt].transpose()) * 0.5;
                c.val[k] = m;
                c.val[kt] = m.transpose();
            } else if kt == k {
                c.val[k] = (c.val[k] + c.val[k].transpose()) * 0.5;
            }
        }
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
    }

    /// `out = M⁻¹ r`, one V-cycle; `a` and `filter` as given to the last
    /// [`Amg::setup`].
    pub fn apply(
        &mut self,
        a: &BlockMatrix,
        filter: &[Filter],
        r: &[Vector3<f64>],
        out: &mut [Vector3<f64>],
    ) {
        let levels = self.transfers.len();
        let fma = has_fma();
        self.work[0].b.copy_from_slice(r);
        for i in 0..a.n {
            self.work[0].b[i] = filter[i].apply(&r[i]);
        }
        if levels == 0 {
            self.bottom.apply(&self.work[0].b, out);
            for i in 0..a.n {
                out[i] = filter[i].apply(&out[i]);
            }
            return;
        }
        // down: pre-smooth, restrict
        for l in 0..levels {
            let m: &BlockMatrix = if l == 0 { a } else { &self.coarse[l - 1] };
            let (w, rest) = self.work[l..].split_first_mut().expect("levels");
            let t = &self.transfers[l];
            // from zero: the blocks right of the diagonal multiply zeros
            for i in 0..m.n {
                let ri = w.b[i] - blocks_mul_best(fma, m, m.row_ptr[i], m.diag[i], &w.x);
                w.x[i] = w.dinv[i] * ri;
            }
            // the residual: the sweep zeroed each row's (filtered) residual
            // as it went, so what is left is the part right of the diagonal
            let wc = &mut rest[0];
            wc.b.iter_mut().for_each(|v| *v = Vector3::zeros());
            for i in 0..m.n {
                let mut ri = -blocks_mul_best(fma, m, m.diag[i] + 1, m.row_ptr[i + 1], &w.x);
                if l == 0 {
                    ri = filter[i].apply(&ri);
                }
                for e in t.p.ptr[i]..t.p.ptr[i + 1] {
                    wc.b[t.p.col[e] as usize] += t.p.val[e].tr_mul(&ri);
                }
            }
        }
        // bottom
        {
            let w = &mut self.work[levels];
            self.bottom.apply(&w.b, &mut w.x);
        }
        // up: prolongate, post-smooth backwards
        for l in (0..levels).rev() {
            let m: &BlockMatrix = if l == 0 { a } else { &self.coarse[l - 1] };
            let (w, rest) = self.work[l..].split_first_mut().expect("levels");
            let xc = &rest[0].x;
            let t = &self.transfers[l];
            for i in 0..m.n {
                let mut s = Vector3::zeros();
                for e in t.p.ptr[i]..t.p.ptr[i + 1] {
                    s += t.p.val[e] * xc[t.p.col[e] as usize];
                }
                w.x[i] += s;
            }
            for i in (0..m.n).rev() {
                let ri = w.b[i] - blocks_mul_best(fma, m, m.row_ptr[i], m.row_ptr[i + 1], &w.x);
                w.x[i] += w.dinv[i] * ri;
            }
        }
        for i in 0..a.n {
            out[i] = filter[i].apply(&self.work[0].x[i]);
        }
    }
}
