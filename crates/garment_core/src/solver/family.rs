//! Per-family forces and stiffness matrices at the current state: used by the
//! finite-difference tests and by the damping identification (thesis §5.4.1,
//! where `F_dissip = β K V` needs each family's K on its own).

use super::elements::*;
use super::sparse::BlockMatrix;
use super::Simulation;
use nalgebra::{Matrix3, Vector3};

/// A spring family.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    Tension,
    Shear,
    Bending,
}

impl Simulation {
    /// Elastic + hysteretic forces of one family (no damping).
    pub fn family_forces(&self, fam: Family) -> Vec<Vector3<f64>> {
        let c = &self.cloth;
        let mut out = vec![Vector3::zeros(); c.len()];
        match fam {
            Family::Tension => {
                for (s, st) in c.tension.iter().zip(&c.tension_state) {
                    let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
                    let (t, _, _) = tension_law(
                        s,
                        &self.fabric_of(s.a).dir(s.weft).tensile,
                        &self.fabric_of(s.a).shear,
                        st,
                        l,
                    );
                    out[s.a] += dir * t;
                    out[s.b] -= dir * t;
                }
            }
            Family::Shear => {
                for (s, st) in c.shear.iter().zip(&c.shear_state) {
                    let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
                    let (t, _, _) = shear_law(s, &self.fabric_of(s.a).shear, st, l);
                    out[s.a] += dir * t;
                    out[s.b] -= dir * t;
                }
            }
            Family::Bending => {
                for (hg, st) in c.hinges.iter().zip(&c.hinge_state) {
                    let (_, _, s, _, g) =
                        hinge_eval(hg, &self.fabric_of(hg.v[0]).dir(hg.weft).bending, st, &c.x);
                    for p in 0..4 {
                        out[hg.v[p]] -=
                            Vector3::new(g[3 * p], g[3 * p + 1], g[3 * p + 2]) * (hg.len * s);
                    }
                }
            }
        }
        out
    }

    /// `∂f/∂x` of one family: exact, or the projected `−K̃` the solver uses.
    pub fn family_jacobian(&self, fam: Family, projected: bool) -> BlockMatrix {
        let c = &self.cloth;
        let mut k = self.a.clone();
        k.clear();
        let axial_add = |k: &mut BlockMatrix, a: usize, b: usize, p: Matrix3<f64>| {
            let (aa, ab, ba, bb) = (k.index(a, a), k.index(a, b), k.index(b, a), k.index(b, b));
            k.val[aa] -= p;
            k.val[bb] -= p;
            k.val[ab] += p;
            k.val[ba] += p;
        };
        match fam {
            Family::Tension => {
                for (s, st) in c.tension.iter().zip(&c.tension_state) {
                    let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
                    let (t, dt, _) = tension_law(
                        s,
                        &self.fabric_of(s.a).dir(s.weft).tensile,
                        &self.fabric_of(s.a).shear,
                        st,
                        l,
                    );
                    axial_add(
                        &mut k,
                        s.a,
                        s.b,
                        axial_block(&Axial { t, dt, l, dir }, projected),
                    );
                }
            }
            Family::Shear => {
                for (s, st) in c.shear.iter().zip(&c.shear_state) {
                    let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
                    let (t, dt, _) = shear_law(s, &self.fabric_of(s.a).shear, st, l);
                    axial_add(
                        &mut k,
                        s.a,
                        s.b,
                        axial_block(&Axial { t, dt, l, dir }, projected),
                    );
                }
            }
            Family::Bending => {
                for (hg, st) in c.hinges.iter().zip(&c.hinge_state) {
                    let law = &self.fabric_of(hg.v[0]).dir(hg.weft).bending;
                    let j = if projected {
                        let (_, _, _, ds, g) = hinge_eval(hg, law, st, &c.x);
                        -(g * g.transpose()) * (hg.len * ds.max(0.0) / hg.h)
                    } else {
                        hinge_jacobian_exact(hg, law, st, &c.x)
                    };
                    for p in 0..4 {
                        for q in 0..4 {
                            let idx = k.index(hg.v[p], hg.v[q]);
                            k.val[idx] += j.fixed_view::<3, 3>(3 * p, 3 * q).into_owned();
                        }
                    }
                }
            }
        }
        k
    }

    /// The stiffness the implicit step uses for a family, as `∂f/∂x` (that is
    /// `−K̃s`): projected like [`Self::family_jacobian`] but with the step
    /// tangents of the hysteretic laws (the stiffer of branch and reversal, see
    /// [`crate::fabric::Law::eval_for_step`]). The damping identification
    /// needs it to write the step's own equation on captured shapes.
    pub fn family_step_jacobian(&self, fam: Family) -> BlockMatrix {
        let c = &self.cloth;
        let mut k = self.a.clone();
        k.clear();
        let mut axial_add = |a: usize, b: usize, t: f64, dts: f64, l: f64, dir: Vector3<f64>| {
            let p = axial_block(&Axial { t, dt: dts, l, dir }, true);
            let (aa, ab, ba, bb) = (k.index(a, a), k.index(a, b), k.index(b, a), k.index(b, b));
            k.val[aa] -= p;
            k.val[bb] -= p;
            k.val[ab] += p;
            k.val[ba] += p;
        };
        match fam {
            Family::Tension => {
                for (s, st) in c.tension.iter().zip(&c.tension_state) {
                    let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
                    let (t, _, dts, _) = tension_law_step(
                        s,
                        &self.fabric_of(s.a).dir(s.weft).tensile,
                        &self.fabric_of(s.a).shear,
                        st,
                        l,
                    );
                    axial_add(s.a, s.b, t, dts, l, dir);
                }
            }
            Family::Shear => {
                for (s, st) in c.shear.iter().zip(&c.shear_state) {
                    let (l, dir) = axial(&c.x[s.a], &c.x[s.b]);
                    let (t, _, dts, _) = shear_law_step(s, &self.fabric_of(s.a).shear, st, l);
                    axial_add(s.a, s.b, t, dts, l, dir);
                }
            }
            Family::Bending => {
                for (hg, st) in c.hinges.iter().zip(&c.hinge_state) {
                    let law = &self.fabric_of(hg.v[0]).dir(hg.weft).bending;
                    let (theta, g) = dihedral_and_grad(hinge_positions(hg, &c.x));
                    let (_, _, dss) = law.eval_for_step(st, theta / hg.h);
                    let ks = hg.len * dss.max(0.0) / hg.h;
                    let gs = |p: usize| Vector3::new(g[3 * p], g[3 * p + 1], g[3 * p + 2]);
                    for p in 0..4 {
                        for q in 0..4 {
                            let idx = k.index(hg.v[p], hg.v[q]);
                            k.val[idx] -= gs(p) * gs(q).transpose() * ks;
                        }
                    }
                }
            }
        }
        k
    }

    /// Total force including gravity and damping at velocities `v` (for the
    /// ∂f/∂v check): `f_el + M g + C v`, with the (first) fabric's damping:
    /// the damping identification works on a cloth of one fabric.
    pub fn total_force_at_velocity(&self, v: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        let d = self.fabric.damping;
        let mut out = self.internal_forces();
        for (i, o) in out.iter_mut().enumerate() {
            *o += self.params.gravity * self.cloth.mass[i] + v[i] * (d.alpha * self.cloth.mass[i]);
        }
        for (fam, beta) in [
            (Family::Tension, d.beta_tension),
            (Family::Shear, d.beta_shear),
            (Family::Bending, d.beta_bend),
        ] {
            if beta != 0.0 {
                let k = self.family_jacobian(fam, true);
                let mut kv = vec![Vector3::zeros(); v.len()];
                k.mul(v, &mut kv);
                // K̃ = −(projected ∂f/∂x): damping force β K̃ v
                for (o, x) in out.iter_mut().zip(kv) {
                    *o -= x * beta;
                }
            }
        }
        out
    }

    /// The damping matrix `∂f/∂v = C = αM + Σ β_k K̃_k` as assembled by the
    /// solver for a cloth of one fabric (its first fabric's α and β).
    pub fn damping_matrix(&self) -> BlockMatrix {
        let d = self.fabric.damping;
        let mut c = self.a.clone();
        c.clear();
        for i in 0..self.cloth.len() {
            c.val[c.diag[i]] = Matrix3::identity() * (d.alpha * self.cloth.mass[i]);
        }
        for (fam, beta) in [
            (Family::Tension, d.beta_tension),
            (Family::Shear, d.beta_shear),
            (Family::Bending, d.beta_bend),
        ] {
            let k = self.family_jacobian(fam, true);
            for (cv, kv) in c.val.iter_mut().zip(&k.val) {
                *cv -= kv * beta;
            }
        }
        c
    }

    /// Sets the hysteresis memory of every spring (tests and experiments).
    pub fn laws_mut(
        &mut self,
    ) -> (
        &mut [crate::fabric::LawState],
        &mut [crate::fabric::LawState],
        &mut [crate::fabric::LawState],
    ) {
        let c = &mut self.cloth;
        (&mut c.tension_state, &mut c.shear_state, &mut c.hinge_state)
    }

    /// Commits the hysteresis memory at the current positions.
    pub fn commit(&mut self) {
        self.commit_laws();
    }
}
