//! A 40 × 40 cm square of an acrylic-like fabric, 2 cm grid, lying flat
//! 1 m up, is held by its two corners on one side and let fall for 0.2 s
//! at the thesis step (1 ms): the library's public face in one run.
//!
//! It prints what can be checked by hand: the cloth's mass (its areal mass
//! times its area), how far the held corners moved (not at all), how far
//! its centre of mass fell (less than free fall's ½ g t²: the pins hold it
//! up) and its energy before and after (the implicit step does not create
//! any).
//!
//! `cargo run --release -p garment_core --example hang`

use garment_core::{
    BehaviourSpec, Cloth, Damping, DirectionSpec, Fabric, FabricFile, GridSpec, Params, Pin,
    PinPath, Simulation,
};
use nalgebra::{Isometry3, Vector3};

/// What a run of [`run`] shows.
pub struct Hang {
    /// Vertices of the grid.
    pub vertices: usize,
    /// The cloth's mass and the fabric's areal mass times the square's
    /// area, kg.
    pub mass: f64,
    pub expected_mass: f64,
    /// The farthest a held corner moved from where it was pinned, m.
    pub held_moved: f64,
    /// Simulated time, s, and the centre of mass's fall over it, m.
    pub time: f64,
    pub fall: f64,
    /// Total energy (kinetic, gravity, elastic) at the start and the end, J.
    pub energy_start: f64,
    pub energy_end: f64,
    /// Mean linear-solver iterations per step.
    pub iterations: f64,
}

/// An acrylic-like fabric from its KES summary values (Charfi 2006's study
/// fabric), undamped.
fn fabric() -> garment_core::Result<Fabric> {
    let dir = |lt, wt, rt, emt, g, hg, hg5, b, hb| DirectionSpec {
        tensile: BehaviourSpec {
            lt: Some(lt),
            wt: Some(wt),
            rt: Some(rt),
            emt: Some(emt),
            ..Default::default()
        },
        shear: BehaviourSpec {
            g: Some(g),
            hg: Some(hg),
            hg5: Some(hg5),
            ..Default::default()
        },
        bending: BehaviourSpec {
            b: Some(b),
            hb: Some(hb),
            ..Default::default()
        },
    };
    let file = FabricFile {
        name: "acrylic-like".into(),
        source: "KES summary values".into(),
        notes: String::new(),
        areal_mass_mg_per_cm2: 21.3,
        thickness_mm: None,
        cloth_friction: None,
        warp: dir(0.65, 8.68, 62.0, 5.34, 0.60, 0.70, 1.50, 0.040, 0.030),
        weft: dir(0.62, 9.5, 60.0, 6.1, 0.58, 0.68, 1.45, 0.030, 0.025),
        damping: Damping::NONE,
    };
    Fabric::from_file(file, &|name| {
        Err(format!("no KES curve files in this example ({name})"))
    })
}

/// Builds the square, pins two corners, runs 200 steps of 1 ms.
pub fn run() -> garment_core::Result<Hang> {
    let fabric = fabric()?;
    let side = 0.4;
    let spec = GridSpec {
        size: [side, side],
        spacing: [0.02, 0.02],
        pose: Isometry3::translation(-0.2, -0.2, 1.0),
    };
    let cloth = Cloth::grid(&spec, fabric.areal_mass)?;
    let (nx, _) = spec.dims();
    let params = Params {
        dt: 1e-3,
        ..Params::default()
    };
    let mut sim = Simulation::new(cloth, fabric, params)?;
    // the corners (0, 0) and (nx − 1, 0), held where they are
    let corners = [0, nx - 1];
    let held: Vec<Vector3<f64>> = corners.iter().map(|&v| sim.cloth.positions()[v]).collect();
    sim.set_pins(
        corners
            .iter()
            .zip(&held)
            .map(|(&v, &p)| Pin::new(v, PinPath::Fixed(p)))
            .collect(),
    )?;
    let com = |sim: &Simulation| {
        let m: f64 = sim.cloth.mass.iter().sum();
        sim.cloth
            .positions()
            .iter()
            .zip(&sim.cloth.mass)
            .map(|(x, &mi)| x * mi)
            .sum::<Vector3<f64>>()
            / m
    };
    let (com0, energy_start) = (com(&sim), sim.energies().total());
    let steps = 200;
    let mut iterations = 0;
    for _ in 0..steps {
        iterations += sim.step()?.iterations;
    }
    let held_moved = corners
        .iter()
        .zip(&held)
        .map(|(&v, p)| (sim.cloth.positions()[v] - p).norm())
        .fold(0.0, f64::max);
    Ok(Hang {
        vertices: sim.cloth.len(),
        mass: sim.cloth.mass.iter().sum(),
        expected_mass: sim.fabric.areal_mass * side * side,
        held_moved,
        time: sim.time,
        fall: com0.z - com(&sim).z,
        energy_start,
        energy_end: sim.energies().total(),
        iterations: iterations as f64 / steps as f64,
    })
}

fn main() -> garment_core::Result<()> {
    let h = run()?;
    let g = Params::default().gravity.norm();
    println!(
        "{} vertices, mass {:.6} kg (areal mass × area: {:.6} kg)",
        h.vertices, h.mass, h.expected_mass
    );
    println!("held corners moved at most {:.3e} m", h.held_moved);
    println!(
        "after {:.3} s the centre of mass fell {:.4} m (free fall: {:.4} m)",
        h.time,
        h.fall,
        0.5 * g * h.time * h.time
    );
    println!(
        "energy {:.6} J at the start, {:.6} J at the end; {:.1} solver iterations per step",
        h.energy_start, h.energy_end, h.iterations
    );
    Ok(())
}
