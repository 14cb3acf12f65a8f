//! Forces and Jacobians of the three spring families (thesis §3.4, ch. 4, §5.4.1).
//!
//! Sign conventions: `f` is the force on the vertices; `K = ∂f/∂x` is the
//! exact Jacobian; the *stiffness* `K̃ = −∂f/∂x`. The solver uses a projected
//! stiffness that is positive semi-definite (so the system matrix of the
//! implicit step is SPD):
//! - axial springs (tension, shear): `K̃ = T'(l) d̂d̂ᵀ + T/l (I − d̂d̂ᵀ)` with the
//!   tangent `T'` clamped at ≥ 0 (a hysteresis branch or the shear correction can
//!   make it negative) and the geometric term `T/l` dropped when the spring is in
//!   compression (`T < 0`). The thesis uses the tensile law in compression; its
//!   compressed springs then have a negative geometric stiffness, which makes
//!   the matrix indefinite and the PCG break down. Dropping it (Choi & Ko 2002)
//!   only removes the buckling instability from the *linearisation*; the force
//!   itself is unchanged, so equilibria are the same.
//! - shear cells: `K̃ = max(F', 0)/(4 l_c l_t) G Gᵀ` plus the Laplacian of the
//!   diagonal in tension (see `CellShear`); egg-crate guards: their exact,
//!   constant `2k w wᵀ ⊗ I`.
//! - bending hinges: `K̃ = (L/h) σ'(κ) ∇θ∇θᵀ` (Gauss–Newton; σ' clamped at ≥ 0):
//!   the term `L σ ∇²θ` is indefinite and small for cloth (bending forces are
//!   orders of magnitude below tension), and dropping it keeps K̃ PSD.
//!
//! The exact Jacobians are also implemented (tests compare them with finite
//! differences, and the damping identification uses them).

use crate::cloth::{Hinge, ShearCell, ShearSpring, TensionSpring};
use crate::fabric::{Law, LawState};
use nalgebra::{Matrix3, SMatrix, Vector3};

/// Scalar response of an axial spring: tension `t` (N, > 0 pulls the ends
/// together) and its derivative `dt` with respect to the current length `l`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Axial {
    pub t: f64,
    pub dt: f64,
    pub l: f64,
    pub dir: Vector3<f64>,
}

/// Tension spring law with the shear correction of thesis eq. 4.55–4.59:
/// `T(l) = w [σ_t(ε) − σ_s,e(u⁺) · l / l_o]`, `ε = l/l0 − 1`,
/// `u⁺ = (l² − l0²) / (2 l0 l_o)` (the sine of the spurious shear angle the two
/// diagonals of a cell see when the cell is stretched along this spring).
/// The correction uses the shear law's elastic part; it is signed (the thesis
/// writes `|F⁺|` for the stretched case) so that compression is corrected too.
///
/// Returns (T, dT/dl, dT/dl for the step matrix (see
/// [`Law::eval_for_step`]), ε).
#[inline]
pub(crate) fn tension_law_step(
    s: &TensionSpring,
    law: &Law,
    shear: &Law,
    st: &LawState,
    l: f64,
) -> (f64, f64, f64, f64) {
    let eps = l / s.l0 - 1.0;
    let (sig, dsig, dsig_step) = law.eval_for_step(st, eps);
    if !s.corrected {
        // no eq. 4.59 correction (the cells' shear measure reads no
        // spurious shear)
        return (
            s.width * sig,
            s.width * dsig / s.l0,
            s.width * dsig_step / s.l0,
            eps,
        );
    }
    let u = (l * l - s.l0 * s.l0) / (2.0 * s.l0 * s.l_other);
    let (ss, dss) = shear.elastic.eval(u);
    let t = s.width * (sig - ss * l / s.l_other);
    let corr = dss * (l / (s.l0 * s.l_other)) * (l / s.l_other) + ss / s.l_other;
    let dt = s.width * (dsig / s.l0 - corr);
    let dt_step = s.width * (dsig_step / s.l0 - corr);
    (t, dt, dt_step, eps)
}

/// Shear spring law, thesis eq. 4.54: `T = ½ FK(θ) l` with
/// `sin θ = (l² − l_c² − l_t²) / (2 l_c l_t)` (eq. 4.34/4.35) taken as the
/// law's argument (sin θ ≈ θ over the KES range, Fig. 4.15). `T > 0` when the
/// diagonal is longer than at rest: each diagonal measures the shear angle in
/// its own sense, so both diagonals use the same expression.
///
/// Returns (T, dT/dl, step dT/dl, sin θ).
#[inline]
pub(crate) fn shear_law_step(
    s: &ShearSpring,
    law: &Law,
    st: &LawState,
    l: f64,
) -> (f64, f64, f64, f64) {
    let u = s.strain(l);
    let (sig, dsig, dsig_step) = law.eval_for_step(st, u);
    let k = l * l / (s.lc * s.lt);
    (
        0.5 * sig * l,
        0.5 * (dsig * k + sig),
        0.5 * (dsig_step * k + sig),
        u,
    )
}

/// A shear cell's response ([`ShearCell`]): energy `E = l_c l_t Φ(u)` with
/// `u = sin θ` its measure, so the force on its clique `(v0, v1, v2, v3)` is
/// `f_p = −½ F(u) G_p` with `G = (−d₁, d₁, d₂, −d₂)` (`d₁ = x₁ − x₀`,
/// `d₂ = x₃ − x₂`): each diagonal carries the tension `½ F l` of thesis
/// eq. 4.54, the first with `F(u)`, the second with `F(−u) = −F(u)`. The
/// stiffness is `K = F'/(4 l_c l_t) G Gᵀ + ½ F (L₁ − L₂)`, `L_k` the
/// Laplacian of diagonal k (`I` on its two diagonal blocks, `−I` between
/// them); the projected one keeps `max(F', 0)` and the positive half of the
/// second term (the diagonal in tension: `½ |F|` on `L₁` when `F > 0`, on `L₂`
/// when `F < 0`), as the axial springs drop the geometric term in compression.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CellShear {
    /// `G` of the clique.
    pub g: [Vector3<f64>; 4],
    /// `F(u)` (N/m), its branch and step tangents.
    pub s: f64,
    pub ds: f64,
    pub dss: f64,
    /// `1 / (4 l_c l_t)`.
    pub k4: f64,
}

/// Evaluates a shear cell at `x` with memory `st` (not committed).
#[inline(always)]
pub(crate) fn cell_shear(c: &ShearCell, law: &Law, st: &LawState, x: &[Vector3<f64>]) -> CellShear {
    let (d1, d2) = c.diagonals(x);
    cell_shear_of(c, law, st, d1, d2, c.strain_of(&d1, &d2))
}

/// [`cell_shear`] of the diagonals `d1`, `d2` and their measure `u`.
#[inline(always)]
pub(crate) fn cell_shear_of(
    c: &ShearCell,
    law: &Law,
    st: &LawState,
    d1: Vector3<f64>,
    d2: Vector3<f64>,
    u: f64,
) -> CellShear {
    let (s, ds, dss) = law.eval_for_step(st, u);
    CellShear {
        g: [-d1, d1, d2, -d2],
        s,
        ds,
        dss,
        k4: 1.0 / (4.0 * c.lc * c.lt),
    }
}

impl CellShear {
    /// Block `(p, q)` of the stiffness `K̃` (`−∂f/∂x`): the Gauss–Newton
    /// coefficient `gn` on `G Gᵀ` and the Laplacian coefficients `l1`, `l2`.
    #[inline(always)]
    pub fn block(&self, p: usize, q: usize, gn: f64, l1: f64, l2: f64) -> Matrix3<f64> {
        let mut m = self.g[p] * self.g[q].transpose() * gn;
        // diagonal k joins clique entries 2k and 2k + 1
        let lap = if p / 2 != q / 2 {
            0.0
        } else {
            let c = if p / 2 == 0 { l1 } else { l2 };
            if p == q {
                c
            } else {
                -c
            }
        };
        if lap != 0.0 {
            m += Matrix3::identity() * lap;
        }
        m
    }

    /// The coefficients (`gn`, `l1`, `l2`) of `K̃` for the tangent `dt`
    /// (`projected`: with the projections above; otherwise the exact
    /// stiffness).
    #[inline(always)]
    pub fn coefficients(&self, dt: f64, projected: bool) -> (f64, f64, f64) {
        if projected {
            (
                dt.max(0.0) * self.k4,
                0.5 * self.s.max(0.0),
                0.5 * (-self.s).max(0.0),
            )
        } else {
            (dt * self.k4, 0.5 * self.s, -0.5 * self.s)
        }
    }
}

/// Elastic energy of a shear cell (J): `l_c l_t Φ(u)`.
pub(crate) fn shear_cell_energy(c: &ShearCell, law: &Law, x: &[Vector3<f64>]) -> f64 {
    c.lc * c.lt * law.elastic.energy(c.strain(x))
}

#[inline]
pub(crate) fn axial(xa: &Vector3<f64>, xb: &Vector3<f64>) -> (f64, Vector3<f64>) {
    let d = xb - xa;
    let l = d.norm();
    if l > 1e-300 {
        (l, d / l)
    } else {
        (0.0, Vector3::x())
    }
}

/// `P = T' d̂d̂ᵀ + T/l (I − d̂d̂ᵀ)`; exact: `∂f_b/∂x_b = −P`, `∂f_b/∂x_a = P`.
#[inline]
pub(crate) fn axial_block(a: &Axial, projected: bool) -> Matrix3<f64> {
    let ddt = a.dir * a.dir.transpose();
    let (dt, g) = if projected {
        (
            a.dt.max(0.0),
            if a.t > 0.0 {
                a.t / a.l.max(1e-300)
            } else {
                0.0
            },
        )
    } else {
        (a.dt, a.t / a.l.max(1e-300))
    };
    ddt * (dt - g) + Matrix3::identity() * g
}

/// Elastic energy of a tension spring (J), elastic parts only.
pub(crate) fn tension_energy(s: &TensionSpring, law: &Law, shear: &Law, l: f64) -> f64 {
    let eps = l / s.l0 - 1.0;
    let u = (l * l - s.l0 * s.l0) / (2.0 * s.l0 * s.l_other);
    let corr = if s.corrected {
        shear.elastic.energy(u)
    } else {
        0.0
    };
    s.width * s.l0 * (law.elastic.energy(eps) - corr)
}

/// Elastic energy of a shear spring (J): `½ l_c l_t Φ(u)`.
pub(crate) fn shear_energy(s: &ShearSpring, law: &Law, l: f64) -> f64 {
    0.5 * s.lc * s.lt * law.elastic.energy(s.strain(l))
}

/// Elastic energy of a hinge (J): `L h Φ(κ)`.
pub(crate) fn hinge_energy(h: &Hinge, law: &Law, theta: f64) -> f64 {
    h.len * h.h * law.elastic.energy(theta / h.h)
}

// ---------------------------------------------------------------- hinges

/// Minimal scalar arithmetic so the dihedral gradient can run on f64 and on
/// dual numbers (forward-mode differentiation gives its exact Hessian).
pub(crate) trait Num:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
{
    fn c(v: f64) -> Self;
    fn sqrt(self) -> Self;
}

impl Num for f64 {
    #[inline]
    fn c(v: f64) -> Self {
        v
    }
    #[inline]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
}

/// Dual number with 12 tangent directions.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Dual {
    pub v: f64,
    pub d: [f64; 12],
}

impl std::ops::Add for Dual {
    type Output = Dual;
    #[inline]
    fn add(self, o: Dual) -> Dual {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a += b;
        }
        Dual { v: self.v + o.v, d }
    }
}
impl std::ops::Sub for Dual {
    type Output = Dual;
    #[inline]
    fn sub(self, o: Dual) -> Dual {
        let mut d = self.d;
        for (a, b) in d.iter_mut().zip(o.d) {
            *a -= b;
        }
        Dual { v: self.v - o.v, d }
    }
}
impl std::ops::Mul for Dual {
    type Output = Dual;
    #[inline]
    fn mul(self, o: Dual) -> Dual {
        let mut d = [0.0; 12];
        for k in 0..12 {
            d[k] = self.d[k] * o.v + self.v * o.d[k];
        }
        Dual { v: self.v * o.v, d }
    }
}
impl std::ops::Div for Dual {
    type Output = Dual;
    #[inline]
    fn div(self, o: Dual) -> Dual {
        let inv = 1.0 / o.v;
        let q = self.v * inv;
        let mut d = [0.0; 12];
        for k in 0..12 {
            d[k] = (self.d[k] - q * o.d[k]) * inv;
        }
        Dual { v: q, d }
    }
}
impl std::ops::Neg for Dual {
    type Output = Dual;
    #[inline]
    fn neg(self) -> Dual {
        let mut d = self.d;
        for a in d.iter_mut() {
            *a = -*a;
        }
        Dual { v: -self.v, d }
    }
}
impl Num for Dual {
    fn c(v: f64) -> Self {
        Dual { v, d: [0.0; 12] }
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        let k = 0.5 / s;
        let mut d = self.d;
        for a in d.iter_mut() {
            *a *= k;
        }
        Dual { v: s, d }
    }
}

type V3<T> = [T; 3];
#[inline]
fn sub<T: Num>(a: V3<T>, b: V3<T>) -> V3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline]
fn cross<T: Num>(a: V3<T>, b: V3<T>) -> V3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline]
fn dot<T: Num>(a: V3<T>, b: V3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline]
fn scale<T: Num>(a: V3<T>, s: T) -> V3<T> {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// Gradient of the signed dihedral angle θ of hinge (x0, x1 | x2, x3) with
/// respect to the four positions. θ = 0 when flat, facets (x0,x1,x2), (x0,x1,x3).
/// `∂θ/∂x2 = −|e| n_A/|n_A|²`, `∂θ/∂x3 = −|e| n_B/|n_B|²`, and the edge
/// vertices share `−(g2 + g3)` according to where each wing's foot falls on the
/// edge (translation and rotation invariance).
#[inline]
pub(crate) fn dihedral_grad<T: Num>(x: [V3<T>; 4]) -> [V3<T>; 4] {
    let e = sub(x[1], x[0]);
    let r2 = sub(x[2], x[0]);
    let r3 = sub(x[3], x[0]);
    let na = cross(e, r2);
    let nb = cross(r3, e);
    let ee = dot(e, e);
    let le = ee.sqrt();
    let g2 = scale(na, -le / dot(na, na));
    let g3 = scale(nb, -le / dot(nb, nb));
    let t2 = dot(r2, e) / ee;
    let t3 = dot(r3, e) / ee;
    let one = T::c(1.0);
    let g1 = [
        -(t2 * g2[0] + t3 * g3[0]),
        -(t2 * g2[1] + t3 * g3[1]),
        -(t2 * g2[2] + t3 * g3[2]),
    ];
    let g0 = [
        -((one - t2) * g2[0] + (one - t3) * g3[0]),
        -((one - t2) * g2[1] + (one - t3) * g3[1]),
        -((one - t2) * g2[2] + (one - t3) * g3[2]),
    ];
    [g0, g1, g2, g3]
}

/// Signed dihedral angle θ (rad) of the hinge.
#[inline]
pub fn dihedral(x: [Vector3<f64>; 4]) -> f64 {
    let e = x[1] - x[0];
    let na = e.cross(&(x[2] - x[0]));
    let nb = (x[3] - x[0]).cross(&e);
    let le = e.norm().max(1e-300);
    (na.cross(&nb).dot(&e) / le).atan2(na.dot(&nb))
}

#[inline]
pub(crate) fn hinge_positions(h: &Hinge, x: &[Vector3<f64>]) -> [Vector3<f64>; 4] {
    [x[h.v[0]], x[h.v[1]], x[h.v[2]], x[h.v[3]]]
}

/// θ and ∇θ as 12-vector.
#[inline]
pub fn dihedral_and_grad(p: [Vector3<f64>; 4]) -> (f64, SMatrix<f64, 12, 1>) {
    let a = |v: &Vector3<f64>| [v.x, v.y, v.z];
    let g = dihedral_grad([a(&p[0]), a(&p[1]), a(&p[2]), a(&p[3])]);
    let mut out = SMatrix::<f64, 12, 1>::zeros();
    for k in 0..4 {
        for c in 0..3 {
            out[3 * k + c] = g[k][c];
        }
    }
    (dihedral(p), out)
}

/// Exact Hessian of θ (12 × 12), by forward differentiation of the gradient.
pub(crate) fn dihedral_hessian(p: [Vector3<f64>; 4]) -> SMatrix<f64, 12, 12> {
    let mut x = [[Dual::c(0.0); 3]; 4];
    for k in 0..4 {
        for c in 0..3 {
            let mut d = [0.0; 12];
            d[3 * k + c] = 1.0;
            x[k][c] = Dual { v: p[k][c], d };
        }
    }
    let g = dihedral_grad(x);
    let mut h = SMatrix::<f64, 12, 12>::zeros();
    for k in 0..4 {
        for c in 0..3 {
            for m in 0..12 {
                h[(3 * k + c, m)] = g[k][c].d[m];
            }
        }
    }
    h
}

/// Bending hinge response: curvature κ = θ/h, moment σ(κ) per width; force
/// `f = −L σ ∇θ` (from the energy `L h Φ(κ)`), with `L` the hinge edge's rest
/// length. Returns (θ, κ, σ, σ', ∇θ).
#[inline]
pub(crate) fn hinge_eval(
    h: &Hinge,
    law: &Law,
    st: &LawState,
    x: &[Vector3<f64>],
) -> (f64, f64, f64, f64, SMatrix<f64, 12, 1>) {
    let p = hinge_positions(h, x);
    let (theta, g) = dihedral_and_grad(p);
    let kappa = theta / h.h;
    let (s, ds) = law.eval(st, kappa);
    (theta, kappa, s, ds, g)
}

/// Exact Jacobian ∂f/∂x of a hinge (12 × 12).
pub(crate) fn hinge_jacobian_exact(
    h: &Hinge,
    law: &Law,
    st: &LawState,
    x: &[Vector3<f64>],
) -> SMatrix<f64, 12, 12> {
    let (_, _, s, ds, g) = hinge_eval(h, law, st, x);
    let hess = dihedral_hessian(hinge_positions(h, x));
    -(g * g.transpose() * (h.len * ds / h.h) + hess * (h.len * s))
}
