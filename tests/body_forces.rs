//! Forces on the person (issue 22): the garment's wrench on the body and the
//! pressure on the body's vertices, against closed forms — a sheet at rest
//! on a plate presses with its weight, its areal weight as pressure, and its
//! weight's moment about the plate frame; a sheet across two blocks gives
//! each half its weight; the shipped skirt on the still body puts its weight
//! on it — and Σ pressure × area over the body's vertices equals the normal
//! force.
#![allow(clippy::needless_range_loop)]

mod support;
use garment_sim::cloth::{Cloth, GridSpec};
use garment_sim::collision::{Obstacle, ShapeSpec};
use garment_sim::solver::{Params, Simulation};
use garment_sim::trial::body_forces::{self, BodyPressure, Wrench};
use nalgebra::{Isometry3, Translation3, Vector3};
use std::path::Path;

const G: f64 = 9.81;

fn fabric() -> garment_sim::fabric::Fabric {
    garment_sim::io::load_fabric(Path::new("tests/data/acrylic_test.yaml")).unwrap()
}

/// A flat square plate, `n × n` squares of side `size / n`, each split in
/// two triangles, in its own frame at z = 0 centred on the origin.
fn plate(size: f64, n: usize) -> ShapeSpec {
    let mut vertices = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let s = size / n as f64;
            vertices.push([i as f64 * s - size / 2.0, j as f64 * s - size / 2.0, 0.0]);
        }
    }
    let mut triangles = Vec::new();
    let id = |i: usize, j: usize| (j * (n + 1) + i) as u32;
    for j in 0..n {
        for i in 0..n {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    ShapeSpec::Triangles {
        vertices,
        triangles,
    }
}

/// A `w × d` sheet at rest at height `z`, its corner at (x0, y0).
fn sheet(w: f64, d: f64, spacing: f64, x0: f64, y0: f64, z: f64) -> Simulation {
    let f = fabric();
    let spec = GridSpec {
        size: [w, d],
        spacing: [spacing, spacing],
        pose: Isometry3::translation(x0, y0, z),
    };
    let cloth = Cloth::grid(&spec, f.areal_mass).unwrap();
    Simulation::new(
        cloth,
        f,
        Params {
            dt: 2e-3,
            ..Params::default()
        },
    )
    .unwrap()
}

fn v(a: [f64; 3]) -> Vector3<f64> {
    Vector3::from(a)
}

#[test]
fn a_sheet_on_a_plate_presses_with_its_weight_and_areal_weight() {
    // a 20 cm sheet off the centre of a 40 cm plate whose frame is away from
    // the world origin: the torque about that frame is the weight's moment
    let origin = Vector3::new(0.1, -0.05, 0.3);
    let e = 0.006 + 0.002;
    let mut sim = sheet(
        0.2,
        0.2,
        0.01,
        origin.x - 0.05,
        origin.y - 0.13,
        origin.z + e,
    );
    let body = sim.add_obstacle(
        Obstacle::new(
            "body",
            plate(0.4, 10),
            Isometry3::from_parts(Translation3::from(origin), Default::default()),
            0.006,
            0.3,
        )
        .unwrap(),
    );
    for _ in 0..300 {
        sim.step().unwrap();
    }
    let m = sim.cloth.total_mass();
    let w = body_forces::wrench(&sim, body).unwrap();
    let f = v(w.force);
    println!("wrench {w:?}, weight {:.5} N", m * G);
    assert!(
        (f.z + m * G).abs() < 0.01 * m * G,
        "vertical force {} N, weight {} N",
        f.z,
        m * G
    );
    assert!(f.xy().norm() < 1e-3 * m * G, "horizontal force {f}");
    assert_eq!(
        w.contacts,
        sim.cloth.len(),
        "every vertex rests on the plate"
    );
    // the weight's moment about the plate frame: the centre of mass over
    // the plate, the force straight down
    let c = sim
        .cloth
        .positions()
        .iter()
        .zip(&sim.cloth.mass)
        .map(|(x, mi)| x * *mi)
        .sum::<Vector3<f64>>()
        / m;
    let expected = (c - origin).cross(&Vector3::new(0.0, 0.0, -m * G));
    let t = v(w.torque);
    println!("torque {t}, closed form {expected}");
    assert!(
        (t - expected).norm() < 0.01 * expected.norm(),
        "torque {t}, expected {expected}"
    );
    // the pressure: Σ p A is the normal force, and under the sheet, away
    // from its edges, the plate's vertices carry the areal weight ρ g
    let p = body_forces::body_pressure(&sim, body).unwrap();
    check_integral(&p);
    assert!((p.normal_force - m * G).abs() < 0.01 * m * G);
    let rho_g = sim.fabric.areal_mass * G;
    let (x0, y0) = (origin.x - 0.05, origin.y - 0.13);
    let mut inside = 0;
    for (i, q) in p.vertices.iter().enumerate() {
        let (u, s) = (q.x - x0, q.y - y0);
        // vertices whose triangles (4 cm squares) lie wholly under the sheet
        if (0.04..=0.16).contains(&u) && (0.04..=0.16).contains(&s) {
            inside += 1;
            assert!(
                (p.pressure[i] / rho_g - 1.0).abs() < 0.05,
                "plate vertex {i} at ({u:.3}, {s:.3}) in the sheet: {} Pa, ρ g = {rho_g} Pa",
                p.pressure[i]
            );
        }
        if !(-0.04..=0.24).contains(&u) || !(-0.04..=0.24).contains(&s) {
            assert_eq!(p.pressure[i], 0.0, "plate vertex {i} away from the sheet");
        }
    }
    assert_eq!(inside, 9, "plate vertices well inside the sheet");
    assert_eq!(p.wrench, w);
}

/// Σ pressure × area over the body's vertices is the contacts' normal force.
fn check_integral(p: &BodyPressure) {
    let integral = p.integral();
    println!(
        "Σ pressure × area {integral:.9} N, normal force {:.9} N",
        p.normal_force
    );
    assert!(p.normal_force > 0.0);
    assert!(
        (integral - p.normal_force).abs() < 1e-9 * p.normal_force,
        "Σ p A = {integral} N, normal force {} N",
        p.normal_force
    );
    assert!(p.pressure.iter().all(|x| *x >= 0.0 && x.is_finite()));
}

#[test]
fn a_sheet_across_two_blocks_gives_each_half_its_weight() {
    // two blocks 2 cm apart under a 30 cm sheet centred over the gap: each
    // contact goes to the block under it, each block holds half the weight
    let e = 0.006 + 0.002;
    let mut sim = sheet(0.3, 0.1, 0.01, -0.15, -0.05, 0.5 + e);
    let block = |id: &str, x: f64| {
        Obstacle::new(
            id,
            ShapeSpec::Box {
                size: [0.14, 0.2, 0.1],
            },
            Isometry3::translation(x, 0.0, 0.45),
            0.006,
            0.3,
        )
        .unwrap()
    };
    let left = sim.add_obstacle(block("left", -0.08));
    let right = sim.add_obstacle(block("right", 0.08));
    for _ in 0..500 {
        sim.step().unwrap();
    }
    let m = sim.cloth.total_mass();
    let (wl, wr): (Wrench, Wrench) = (
        body_forces::wrench(&sim, left).unwrap(),
        body_forces::wrench(&sim, right).unwrap(),
    );
    println!("left {wl:?}\nright {wr:?}\nweight {} N", m * G);
    let sum = v(wl.force) + v(wr.force);
    assert!(
        (sum - Vector3::new(0.0, 0.0, -m * G)).norm() < 0.01 * m * G,
        "sum {sum}"
    );
    for w in [&wl, &wr] {
        assert!(
            (w.force[2] + m * G / 2.0).abs() < 0.02 * m * G,
            "{w:?}: half the weight is {} N",
            m * G / 2.0
        );
        assert!(w.contacts > 0);
    }
    assert!(
        wl.contacts + wr.contacts <= sim.cloth.len(),
        "no contact counted twice"
    );
    // a box is not a mesh: no per-vertex pressure
    assert!(body_forces::body_pressure(&sim, left).is_none());
}

/// Numbers of one CSV row.
fn row(l: &str) -> Vec<f64> {
    l.split(',').map(|s| s.parse().unwrap()).collect()
}

/// A PLY vertex property: the columns of `body_pressure.ply`.
fn ply_columns(text: &str) -> (Vec<String>, Vec<Vec<f64>>) {
    let names: Vec<String> = text
        .lines()
        .take_while(|l| !l.starts_with("element face"))
        .filter_map(|l| l.strip_prefix("property float "))
        .map(str::to_string)
        .collect();
    let n: usize = text
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .unwrap()
        .parse()
        .unwrap();
    let rows = text
        .lines()
        .skip_while(|l| *l != "end_header")
        .skip(1)
        .take(n)
        .map(|l| l.split_whitespace().map(|s| s.parse().unwrap()).collect())
        .collect();
    (names, rows)
}

#[test]
fn the_skirt_on_the_still_body_puts_its_weight_on_it() {
    // the shipped trial at 2 cm: once settled, the body alone holds the
    // skirt, so the force on it is the skirt's weight, straight down
    let s = support::Scratch::new("body_forces_skirt");
    let out = s.join("out");
    let o = support::garment_sim()
        .args([
            "trial",
            "config/trials/skirt_on_anny.yaml",
            "--spacing",
            "0.02",
            "--out",
        ])
        .arg(&out)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{}{}",
        text,
        String::from_utf8_lossy(&o.stderr)
    );
    println!("{text}");
    let fit: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("fit.json")).unwrap()).unwrap();
    assert!(fit["run"]["settle_time_s"].is_number(), "not settled");
    let weight = fit["weight_n"].as_f64().unwrap();
    // body_wrench.csv: one row per step, the last 0.5 s averaged
    let csv = std::fs::read_to_string(out.join("body_wrench.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time_s,force_x_n,force_y_n,force_z_n,torque_x_nm,torque_y_nm,torque_z_nm,normal_force_n,contacts"
    );
    let rows: Vec<Vec<f64>> = lines.map(row).collect();
    assert_eq!(rows.len() as u64, fit["run"]["steps"].as_u64().unwrap());
    let end = rows.last().unwrap()[0];
    // the window of fit.json's mean (times written to 0.1 ms)
    let tail: Vec<&Vec<f64>> = rows.iter().filter(|r| r[0] >= end - 0.5 - 1e-6).collect();
    let mean = |k: usize| tail.iter().map(|r| r[k]).sum::<f64>() / tail.len() as f64;
    let f = Vector3::new(mean(1), mean(2), mean(3));
    println!("mean force of the last 0.5 s {f} N, weight {weight} N");
    assert!(
        (f.z + weight).abs() < 0.02 * weight,
        "downward force {} N, weight {weight} N",
        -f.z
    );
    assert!(f.xy().norm() < 0.02 * weight, "sideways force {f}");
    // at rest the force no longer changes from step to step: every step of
    // the last 0.2 s within 1 % (the contacts still shift earlier on)
    for r in rows.iter().filter(|r| r[0] >= end - 0.2) {
        assert!(
            (r[3] + weight).abs() < 0.01 * weight,
            "step at {} s: {r:?}",
            r[0]
        );
    }
    let bw = &fit["body_wrench"];
    assert!((bw["mean_down_over_weight"].as_f64().unwrap() - 1.0).abs() < 0.02);
    assert!((bw["mean_force_n"][2].as_f64().unwrap() - f.z).abs() < 1e-6);
    // body_pressure.ply: the body's vertices with their pressure and area;
    // Σ p A over them is the normal force of the last step
    let ply = std::fs::read_to_string(out.join("body_pressure.ply")).unwrap();
    let (names, cols) = ply_columns(&ply);
    assert_eq!(names, ["x", "y", "z", "pressure", "force", "area"]);
    assert_eq!(cols.len(), 1229);
    let integral: f64 = cols.iter().map(|c| c[3] * c[5]).sum();
    let normal = tail.last().unwrap()[7];
    let bp = &fit["body_pressure"];
    println!("Σ p A from the PLY {integral} N, normal force {normal} N, {bp}");
    assert!(
        (integral - normal).abs() < 1e-4 * normal,
        "Σ p A {integral} N, normal force {normal} N"
    );
    assert!(
        (bp["pressure_integral_n"].as_f64().unwrap() - bp["normal_force_n"].as_f64().unwrap())
            .abs()
            < 1e-9 * normal
    );
    // the skirt hangs from the hips: most of the normal force is on the
    // body above the crotch (0.775 m) and below the waist (1.09 m; the hem
    // brushes the legs)
    let hips: f64 = cols
        .iter()
        .filter(|c| c[2] > 0.775 && c[2] < 1.09)
        .map(|c| c[4])
        .sum();
    let all: f64 = cols.iter().map(|c| c[4]).sum();
    println!("normal force on the hips {hips} N of {all} N");
    assert!(hips > 0.9 * all, "{hips} N of {all} N on the hips");
}
