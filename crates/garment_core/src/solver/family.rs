//! Per-family forces and stiffness matrices at the current state: used by the
//! finite-difference tests and by the damping identification (thesis §5.4.1,
//! where `F_dissip = β K V` needs each family's K on its own).

pub use super::sets::Family;
use super::sets::{self, Jacobian};
use super::sparse::BlockMatrix;
use super::Simulation;
use nalgebra::{Matrix3, Vector3};

impl Simulation {
    /// Elastic + hysteretic forces of one family (no damping).
    pub fn family_forces(&self, fam: Family) -> Vec<Vector3<f64>> {
        let mut out = vec![Vector3::zeros(); self.cloth.len()];
        let f = self.fabric_lookup();
        sets::forces(&self.cloth, &f, |g| g == Some(fam), &mut out);
        out
    }

    /// `∂f/∂x` of one family (the elements' pattern of the system matrix).
    fn family_matrix(&self, fam: Family, kind: Jacobian) -> BlockMatrix {
        let mut k = self.ws.a.clone();
        k.clear();
        let f = self.fabric_lookup();
        sets::jacobians(&self.cloth, &f, |g| g == Some(fam), kind, &mut k);
        k
    }

    /// `∂f/∂x` of one family: exact, or the projected `−K̃` the solver uses.
    pub fn family_jacobian(&self, fam: Family, projected: bool) -> BlockMatrix {
        self.family_matrix(
            fam,
            if projected {
                Jacobian::Projected
            } else {
                Jacobian::Exact
            },
        )
    }

    /// The stiffness the implicit step uses for a family, as `∂f/∂x` (that is
    /// `−K̃s`): projected like [`Self::family_jacobian`] but with the step
    /// tangents of the hysteretic laws (the stiffer of branch and reversal, see
    /// [`crate::fabric::Law::eval_for_step`]). The damping identification
    /// needs it to write the step's own equation on captured shapes.
    pub fn family_step_jacobian(&self, fam: Family) -> BlockMatrix {
        self.family_matrix(fam, Jacobian::Step)
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
        let mut c = self.ws.a.clone();
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

    /// Sets the hysteresis memory of every spring (tests and experiments):
    /// tension springs, the shear family's elements (springs or cells), hinges.
    pub fn laws_mut(
        &mut self,
    ) -> (
        &mut [crate::fabric::LawState],
        &mut [crate::fabric::LawState],
        &mut [crate::fabric::LawState],
    ) {
        let c = &mut self.cloth;
        let shear = if c.shear_cells.is_empty() {
            &mut c.shear_state
        } else {
            &mut c.shear_cell_state
        };
        (&mut c.tension_state, shear, &mut c.hinge_state)
    }

    /// Commits the hysteresis memory at the current positions.
    pub fn commit(&mut self) {
        self.commit_laws();
    }
}
