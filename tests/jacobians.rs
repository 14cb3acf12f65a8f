#![allow(clippy::needless_range_loop)]
//! Every force Jacobian against central finite differences, on random
//! deformed configurations, for each spring family and both hysteresis branches.

use garment_sim::cloth::{Cloth, GridSpec};
use garment_sim::fabric::Fabric;
use garment_sim::solver::family::Family;
use garment_sim::solver::{Params, Simulation};
use nalgebra::{Isometry3, Vector3};
use rand::{Rng, SeedableRng};

fn fixture() -> Fabric {
    garment_sim::io::load_fabric(std::path::Path::new("tests/data/acrylic_test.yaml")).unwrap()
}

/// A 4 × 5 cloth, deformed randomly; memory committed at a first random shape
/// with random σp inside the loop, then moved to a second shape so that springs
/// sit on both branches (increment > 0 and < 0).
fn deformed(seed: u64, scale: f64) -> Simulation {
    deformed_with(seed, scale, false)
}

/// [`deformed`], with the cells' shear measure and the egg-crate guards
/// (`Params::cell_shear`) when `cell_shear`.
fn deformed_with(seed: u64, scale: f64, cell_shear: bool) -> Simulation {
    let spec = GridSpec {
        size: [0.06, 0.08],
        spacing: [0.02, 0.02],
        pose: Isometry3::identity(),
    };
    let cloth = Cloth::grid(&spec, 0.213).unwrap();
    let params = Params {
        cell_shear,
        ..Params::default()
    };
    let mut sim = Simulation::new(cloth, fixture(), params).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut x = sim.cloth.positions().to_vec();
    for p in x.iter_mut() {
        *p += Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * scale;
    }
    sim.cloth.set_positions(&x).unwrap();
    sim.commit();
    let (t, s, b) = sim.laws_mut();
    for st in t.iter_mut().chain(s.iter_mut()).chain(b.iter_mut()) {
        st.sp = rng.random_range(-0.3..0.3);
        st.dir = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    }
    let mut x = sim.cloth.positions().to_vec();
    for p in x.iter_mut() {
        *p += Vector3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        ) * scale;
    }
    sim.cloth.set_positions(&x).unwrap();
    sim
}

fn check(fam: Family, seed: u64, scale: f64) {
    check_with(fam, seed, scale, false);
}

fn check_with(fam: Family, seed: u64, scale: f64, cell_shear: bool) {
    let mut sim = deformed_with(seed, scale, cell_shear);
    let k = sim.family_jacobian(fam, false);
    let n = sim.cloth.len();
    let mut max_err: f64 = 0.0;
    let mut max_val: f64 = 0.0;
    let h = 1e-7;
    for j in 0..n {
        for q in 0..3 {
            let x0 = sim.cloth.positions()[j][q];
            set_coordinate(&mut sim, j, q, x0 + h);
            let fp = sim.family_forces(fam);
            set_coordinate(&mut sim, j, q, x0 - h);
            let fm = sim.family_forces(fam);
            set_coordinate(&mut sim, j, q, x0);
            for i in 0..n {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                let an = match k.col[k.row_ptr[i]..k.row_ptr[i + 1]].binary_search(&(j as u32)) {
                    Ok(pos) => k.val[k.row_ptr[i] + pos].column(q).into_owned(),
                    Err(_) => Vector3::zeros(),
                };
                max_err = max_err.max((fd - an).amax());
                max_val = max_val.max(an.amax());
            }
        }
    }
    let rel = max_err / max_val;
    println!("{fam:?} seed {seed}: max |J - J_fd| / max |J| = {rel:.2e} (max |J| = {max_val:.3e})");
    assert!(max_val > 0.0);
    assert!(rel < 1e-5, "{fam:?}: relative error {rel:e}");
}

#[test]
fn tension_jacobian_matches_finite_differences() {
    for seed in 0..4 {
        check(Family::Tension, seed, 0.0015);
    }
}

#[test]
fn shear_jacobian_matches_finite_differences() {
    for seed in 0..4 {
        check(Family::Shear, seed, 0.0015);
    }
}

#[test]
fn bending_jacobian_matches_finite_differences() {
    for seed in 0..4 {
        check(Family::Bending, seed, 0.004);
    }
}

/// The same with the cells' shear measure: the shear cells, the tension
/// springs without the correction of eq. 4.59, the hinges with the
/// egg-crate guards.
#[test]
fn cell_shear_jacobians_match_finite_differences() {
    for seed in 0..4 {
        check_with(Family::Tension, seed, 0.0015, true);
        check_with(Family::Shear, seed, 0.0015, true);
        check_with(Family::Bending, seed, 0.004, true);
    }
}

#[test]
fn both_hysteresis_branches_are_exercised() {
    let sim = deformed(1, 0.0015);
    let c = &sim.cloth;
    let (mut up, mut down) = (0, 0);
    for (s, st) in c.tension.iter().zip(&c.tension_state) {
        let e = (c.positions()[s.b] - c.positions()[s.a]).norm() / s.l0 - 1.0;
        if e > st.x {
            up += 1
        } else if e < st.x {
            down += 1
        }
    }
    assert!(up > 5 && down > 5, "up {up} down {down}");
}

/// ∂f/∂v: finite differences of the total force with respect to velocities
/// equal the damping matrix C = αM + Σ β K̃ the solver assembles.
#[test]
fn velocity_jacobian_is_the_damping_matrix() {
    for cell_shear in [false, true] {
        velocity_jacobian_with(cell_shear);
    }
}

fn velocity_jacobian_with(cell_shear: bool) {
    let mut sim = deformed_with(7, 0.0015, cell_shear);
    let mut rng = rand::rngs::StdRng::seed_from_u64(3);
    let n = sim.cloth.len();
    let v: Vec<Vector3<f64>> = (0..n)
        .map(|_| {
            Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        })
        .collect();
    sim.cloth.set_velocities(&v).unwrap();
    let c = sim.damping_matrix();
    let h = 1e-6;
    let mut max_err: f64 = 0.0;
    let mut max_val: f64 = 0.0;
    for j in 0..n {
        for q in 0..3 {
            let mut vp = v.clone();
            vp[j][q] += h;
            let mut vm = v.clone();
            vm[j][q] -= h;
            let fp = sim.total_force_at_velocity(&vp);
            let fm = sim.total_force_at_velocity(&vm);
            for i in 0..n {
                let fd = (fp[i] - fm[i]) / (2.0 * h);
                let an = match c.col[c.row_ptr[i]..c.row_ptr[i + 1]].binary_search(&(j as u32)) {
                    Ok(pos) => c.val[c.row_ptr[i] + pos].column(q).into_owned(),
                    Err(_) => Vector3::zeros(),
                };
                max_err = max_err.max((fd - an).amax());
                max_val = max_val.max(an.amax());
            }
        }
    }
    assert!(max_err / max_val < 1e-6, "{}", max_err / max_val);
}

/// The forces are the negative gradient of the elastic energies reported in
/// energy.csv (hysteresis off), and the dihedral gradient is that of the angle.
#[test]
fn forces_are_energy_gradients() {
    for cell_shear in [false, true] {
        forces_are_energy_gradients_with(cell_shear);
    }
}

fn forces_are_energy_gradients_with(cell_shear: bool) {
    let mut sim = deformed_with(11, 0.002, cell_shear);
    let f = fixture().without_hysteresis();
    sim.fabric = f;
    let n = sim.cloth.len();
    let fam_e = |s: &Simulation, fam: Family| {
        let e = s.energies();
        match fam {
            Family::Tension => e.tension,
            Family::Shear => e.shear,
            Family::Bending => e.bending,
        }
    };
    for fam in [Family::Tension, Family::Shear, Family::Bending] {
        let force = sim.family_forces(fam);
        let h = 1e-7;
        let mut max_err: f64 = 0.0;
        let mut max_val: f64 = 0.0;
        for j in 0..n {
            for q in 0..3 {
                let x0 = sim.cloth.positions()[j][q];
                set_coordinate(&mut sim, j, q, x0 + h);
                let ep = fam_e(&sim, fam);
                set_coordinate(&mut sim, j, q, x0 - h);
                let em = fam_e(&sim, fam);
                set_coordinate(&mut sim, j, q, x0);
                let fd = -(ep - em) / (2.0 * h);
                max_err = max_err.max((fd - force[j][q]).abs());
                max_val = max_val.max(force[j][q].abs());
            }
        }
        println!(
            "{fam:?}: force vs -dE/dx relative error {:.2e}",
            max_err / max_val
        );
        assert!(max_err / max_val < 1e-5, "{fam:?} {}", max_err / max_val);
    }
}

#[test]
fn dihedral_gradient_matches_finite_differences() {
    use garment_sim::solver::elements::{dihedral, dihedral_and_grad};
    let mut rng = rand::rngs::StdRng::seed_from_u64(5);
    for _ in 0..20 {
        let mut p = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(0.0, 0.02, 0.0),
            Vector3::new(-0.02, 0.0, 0.0),
            Vector3::new(0.02, 0.02, 0.0),
        ];
        for x in p.iter_mut() {
            *x += Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * 0.006;
        }
        let (_, g) = dihedral_and_grad(p);
        for k in 0..4 {
            for c in 0..3 {
                let h = 1e-7;
                let mut a = p;
                a[k][c] += h;
                let mut b = p;
                b[k][c] -= h;
                let fd = (dihedral(a) - dihedral(b)) / (2.0 * h);
                assert!(
                    (fd - g[3 * k + c]).abs() < 1e-5 * g.amax(),
                    "k {k} c {c}: fd {fd} g {}",
                    g[3 * k + c]
                );
            }
        }
    }
}

/// The threaded assembly gives the serial one's matrix and right-hand side.
#[test]
fn threaded_assembly_equals_serial() {
    let build = |threads: usize| {
        let spec = GridSpec {
            size: [0.6, 0.6],
            spacing: [0.01, 0.01],
            pose: Isometry3::identity(),
        };
        let mut cloth = Cloth::grid(&spec, 0.213).unwrap();
        let mut rng = rand::rngs::StdRng::seed_from_u64(9);
        let (mut x, mut vel) = (cloth.positions().to_vec(), cloth.velocities().to_vec());
        for (p, v) in x.iter_mut().zip(vel.iter_mut()) {
            *p += Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * 0.001;
            *v = Vector3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
        }
        cloth.set_positions(&x).unwrap();
        cloth.set_velocities(&vel).unwrap();
        let params = Params {
            threads,
            ..Params::default()
        };
        let mut sim = Simulation::new(cloth, fixture(), params).unwrap();
        sim.assembled_system()
    };
    let (a1, b1) = build(1);
    let (a3, b3) = build(3);
    let amax = a1.iter().map(|m| m.amax()).fold(0.0, f64::max);
    let bmax = b1.iter().map(|v| v.amax()).fold(0.0, f64::max);
    let da = a1
        .iter()
        .zip(&a3)
        .map(|(x, y)| (x - y).amax())
        .fold(0.0, f64::max);
    let db = b1
        .iter()
        .zip(&b3)
        .map(|(x, y)| (x - y).amax())
        .fold(0.0, f64::max);
    println!(
        "threaded vs serial: |dA|/|A| = {:.1e}, |db|/|b| = {:.1e}",
        da / amax,
        db / bmax
    );
    assert!(da <= 1e-12 * amax && db <= 1e-12 * bmax);
}

/// Sets coordinate `q` of vertex `j` (a finite-difference probe).
fn set_coordinate(sim: &mut Simulation, j: usize, q: usize, value: f64) {
    let mut p = sim.cloth.positions()[j];
    p[q] = value;
    sim.cloth.set_position(j, p).unwrap();
}
