//! Contacts with scene objects: friction against the closed-form block on an
//! incline, no penetration of primitives, meshes and moving obstacles, and
//! clear errors for bad scene files.
#![allow(clippy::needless_range_loop)]

mod support;
use garment_sim::cloth::{Cloth, GridSpec};
use garment_sim::collision::{Obstacle, ShapeSpec};
use garment_sim::fabric::Fabric;
use garment_sim::scene::{Scene, ShapeFile};
use garment_sim::solver::{Params, Simulation};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use std::path::Path;

fn fixture() -> Fabric {
    garment_sim::io::load_fabric(Path::new("tests/data/acrylic_test.yaml")).unwrap()
}

/// A 10 cm square lying on a plane inclined by `angle` about x, undamped.
fn incline(angle: f64, mu: f64) -> Simulation {
    let rot = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), angle);
    let plane = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.0), rot);
    let e = 0.006 + 0.002;
    let spec = GridSpec {
        size: [0.1, 0.1],
        spacing: [0.02, 0.02],
        pose: plane * Translation3::new(-0.05, -0.05, 0.05 + e),
    };
    let f = fixture().undamped().without_hysteresis();
    let cloth = Cloth::grid(&spec, f.areal_mass).unwrap();
    let mut sim = Simulation::new(
        cloth,
        f,
        Params {
            dt: 1e-3,
            ..Params::default()
        },
    )
    .unwrap();
    let ob = Obstacle::new(
        "plane",
        ShapeSpec::Box {
            size: [2.0, 2.0, 0.1],
        },
        plane,
        0.006,
        mu,
    )
    .unwrap();
    sim.add_obstacle(ob);
    sim
}

fn mean_velocity(sim: &Simulation) -> Vector3<f64> {
    sim.cloth.velocities().iter().sum::<Vector3<f64>>() / sim.cloth.len() as f64
}

#[test]
fn friction_on_an_incline_matches_the_sliding_block() {
    let angle = 20f64.to_radians();
    // μ = 0.2 < tan 20° = 0.364: slides with a = g (sin θ − μ cos θ)
    let mut slide = incline(angle, 0.2);
    for _ in 0..500 {
        slide.step().unwrap();
    }
    let a_expected = 9.81 * (angle.sin() - 0.2 * angle.cos());
    let v = mean_velocity(&slide).norm();
    let a = v / slide.time;
    println!("sliding: a = {a:.4} m/s², closed form {a_expected:.4} m/s²");
    assert!(
        (a / a_expected - 1.0).abs() < 0.03,
        "a = {a}, expected {a_expected}"
    );
    // μ = 0.5 > tan 20°: sticks
    let mut stick = incline(angle, 0.5);
    for _ in 0..500 {
        stick.step().unwrap();
    }
    let v = mean_velocity(&stick).norm();
    println!("sticking: mean speed {v:.2e} m/s after 0.5 s");
    assert!(v < 1e-3, "sticking cloth moves at {v} m/s");
}

/// A 10 cm square resting 20 cm off the axis of a turntable (a box turning
/// about the vertical at 1 rad/s, friction 0.5, the fabric's own air drag,
/// dt = 1/120 s): static friction can hold it (the drag and the centripetal
/// acceleration need 1.6 m/s², under μ g = 4.9 m/s²): after the start
/// (a jump to 1 rad/s, which it slips through) it turns with the table, its
/// centroid at 1 rad/s within 0.3 % over the last half second, more than a
/// tenth of its contacts stuck at each step on average. (A contact whose
/// sliding reverses over a step sticks; the velocity left after a step on a
/// moving obstacle is seldom under the re-stick speed, and without that rule
/// the cloth lags by 2.6 %, its contacts all sliding.)
#[test]
fn cloth_on_a_turntable_turns_with_it() {
    let e = 0.006 + 0.002;
    let spec = GridSpec {
        size: [0.1, 0.1],
        spacing: [0.02, 0.02],
        pose: Isometry3::translation(0.15, -0.05, e),
    };
    let f = fixture();
    let cloth = Cloth::grid(&spec, f.areal_mass).unwrap();
    let dt = 1.0 / 120.0;
    let mut sim = Simulation::new(
        cloth,
        f,
        Params {
            dt,
            ..Params::default()
        },
    )
    .unwrap();
    let table = Obstacle::new(
        "turntable",
        ShapeSpec::Box {
            size: [1.0, 1.0, 0.1],
        },
        Isometry3::translation(0.0, 0.0, -0.05),
        0.006,
        0.5,
    )
    .unwrap();
    let table = sim.add_obstacle(table);
    for _ in 0..24 {
        sim.step().unwrap();
    }
    let omega = 1.0;
    sim.obstacle_mut(table).unwrap().angular_velocity = Vector3::new(0.0, 0.0, omega);
    let centroid =
        |s: &Simulation| s.cloth.positions().iter().sum::<Vector3<f64>>() / s.cloth.len() as f64;
    let angle = |s: &Simulation| {
        let c = centroid(s);
        c.y.atan2(c.x)
    };
    for _ in 0..60 {
        sim.step().unwrap();
    }
    let (a0, t0) = (angle(&sim), sim.time);
    let (mut stuck, mut contacts) = (0, 0);
    for _ in 0..60 {
        let st = sim.step().unwrap();
        stuck += st.stuck;
        contacts += st.contacts;
    }
    let rate = (angle(&sim) - a0) / (sim.time - t0);
    let r = centroid(&sim).xy().norm();
    println!(
        "turntable at {omega} rad/s: cloth at r = {r:.4} m turns at {rate:.5} rad/s; {stuck} of \
         {contacts} contacts stuck over the last half second"
    );
    assert!((r - 0.2).abs() < 0.01, "the cloth slid to r = {r} m");
    assert!((rate / omega - 1.0).abs() < 3e-3, "{rate} rad/s");
    assert_eq!(contacts, 60 * sim.cloth.len());
    assert!(
        10 * stuck > contacts,
        "{stuck} of {contacts} contacts stuck"
    );
}

/// Drops a 30 cm cloth on an obstacle and checks every step that no vertex is
/// closer to it than the contact distance (obstacle + cloth thickness).
fn drop_on(
    spec: ShapeFile,
    pose: Isometry3<f64>,
    velocity: Vector3<f64>,
    steps: usize,
) -> (f64, f64, f64) {
    let f = fixture();
    let grid = GridSpec {
        size: [0.3, 0.3],
        spacing: [0.015, 0.015],
        pose: Isometry3::translation(-0.15, -0.15, 0.12),
    };
    let cloth = Cloth::grid(&grid, f.areal_mass).unwrap();
    let mut sim = Simulation::new(
        cloth,
        f,
        Params {
            dt: 1e-3,
            ..Params::default()
        },
    )
    .unwrap();
    let spec = spec.resolve("o", Path::new("tests/data")).unwrap();
    let mut ob = Obstacle::new("o", spec, pose, 0.006, 0.3).unwrap();
    ob.linear_velocity = velocity;
    sim.add_obstacle(ob);
    let e = 0.008;
    let mut worst = f64::INFINITY;
    for _ in 0..steps {
        sim.step().unwrap();
        for p in sim.cloth.positions() {
            worst = worst.min(sim.obstacles()[0].proximity(p).distance);
        }
    }
    let lowest = sim
        .cloth
        .positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::INFINITY, f64::min);
    let highest = sim
        .cloth
        .positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::NEG_INFINITY, f64::max);
    assert!(
        worst >= e - 1e-6,
        "a vertex ended a step {:.3} mm from the surface (contact distance 8 mm)",
        worst * 1e3
    );
    (worst, lowest, highest)
}

#[test]
fn no_vertex_inside_primitives() {
    let z = Isometry3::identity();
    for (name, spec) in [
        ("sphere", ShapeFile::Sphere { radius: 0.06 }),
        (
            "capsule",
            ShapeFile::Capsule {
                length: 0.1,
                radius: 0.04,
            },
        ),
        (
            "cylinder",
            ShapeFile::Cylinder {
                height: 0.1,
                radius: 0.06,
            },
        ),
        (
            "box",
            ShapeFile::Box {
                size: [0.1, 0.1, 0.1],
            },
        ),
    ] {
        let (worst, lowest, _) = drop_on(spec, z, Vector3::zeros(), 600);
        println!(
            "{name}: closest vertex {:.3} mm, lowest vertex z = {lowest:.3} m",
            worst * 1e3
        );
        assert!(
            lowest < 0.0,
            "{name}: the cloth must drape down around the obstacle"
        );
    }
}

#[test]
fn no_vertex_inside_an_obj_mesh() {
    let (worst, lowest, _) = drop_on(
        ShapeFile::Mesh {
            obj: "cube.obj".into(),
            scale: 1.0,
        },
        Isometry3::identity(),
        Vector3::zeros(),
        600,
    );
    println!(
        "mesh cube: closest vertex {:.3} mm, lowest z {lowest:.3}",
        worst * 1e3
    );
    assert!(lowest < 0.0);
}

#[test]
fn a_rising_obstacle_lifts_the_cloth_without_penetration() {
    // a sphere below the cloth moving up at 0.5 m/s pushes it up
    let (worst, _, highest) = drop_on(
        ShapeFile::Sphere { radius: 0.05 },
        Isometry3::translation(0.0, 0.0, 0.0),
        Vector3::new(0.0, 0.0, 0.5),
        400,
    );
    println!(
        "rising sphere: closest vertex {:.3} mm, highest vertex z = {highest:.3} m",
        worst * 1e3
    );
    // after 0.4 s the sphere's top is at 0.25 m: the cloth rides on it
    assert!(
        highest > 0.25,
        "the cloth must be lifted (highest z {highest})"
    );
}

/// A 20 cm square `height` above a 2 mm board (thickness 1 mm: the contact
/// distance with the 2 mm cloth is 3 mm, so the thickened board is 8 mm
/// thick), stepped at `dt`; the board moves up at `rise` m/s. Returns the
/// smallest height above the board's top face of any vertex at the end of
/// any step, and the largest at the end.
fn thin_board(height: f64, dt: f64, rise: f64, steps: usize) -> (f64, f64) {
    let f = fixture();
    let grid = GridSpec {
        size: [0.2, 0.2],
        spacing: [0.02, 0.02],
        pose: Isometry3::translation(-0.1, -0.1, 0.001 + height),
    };
    let cloth = Cloth::grid(&grid, f.areal_mass).unwrap();
    let mut sim = Simulation::new(
        cloth,
        f,
        Params {
            dt,
            cloth_thickness: 0.002,
            ..Params::default()
        },
    )
    .unwrap();
    let mut ob = Obstacle::new(
        "board",
        ShapeSpec::Box {
            size: [0.3, 0.3, 0.002],
        },
        Isometry3::identity(),
        0.001,
        0.3,
    )
    .unwrap();
    ob.linear_velocity = Vector3::new(0.0, 0.0, rise);
    sim.add_obstacle(ob);
    let mut lowest = f64::INFINITY;
    for _ in 0..steps {
        sim.step().unwrap();
        let top = sim.obstacles()[0].pose.translation.z + 0.001;
        for p in sim.cloth.positions() {
            lowest = lowest.min(p.z - top);
        }
    }
    let top = sim.obstacles()[0].pose.translation.z + 0.001;
    let highest = sim
        .cloth
        .positions()
        .iter()
        .map(|p| p.z - top)
        .fold(f64::NEG_INFINITY, f64::max);
    (lowest, highest)
}

#[test]
fn large_steps_do_not_cross_a_thin_board() {
    let e = 0.003;
    // (what, height above the top face, dt, board speed up, steps)
    for (what, height, dt, rise, steps) in [
        // 1.5 m/s at impact: 2.5 cm per step against the 8 mm thickened board
        ("dropped from 15 cm, dt = 1/60 s", 0.15, 1.0 / 60.0, 0.0, 90),
        // released at rest 4 mm above: the first step alone falls 2.5 cm
        ("released at rest, dt = 0.05 s", 0.004, 0.05, 0.0, 30),
        // the board sweeps 3.3 cm per step through the cloth's path
        (
            "board rising at 2 m/s, dt = 1/60 s",
            0.05,
            1.0 / 60.0,
            2.0,
            60,
        ),
    ] {
        let (lowest, highest) = thin_board(height, dt, rise, steps);
        println!(
            "{what}: lowest vertex {:.3} mm above the top face over all steps, highest {:.3} mm at the end",
            lowest * 1e3,
            highest * 1e3
        );
        // every vertex stays on the side it came from, at the contact distance
        assert!(
            lowest >= e - 1e-6,
            "{what}: a vertex went {:.3} mm below the contact distance",
            (e - lowest) * 1e3
        );
        // and the square ends lying on the board (flat within 3 mm)
        assert!(
            highest < e + 0.003,
            "{what}: the cloth does not lie on the board (highest vertex {:.1} mm up)",
            highest * 1e3
        );
    }
}

#[test]
fn contacts_come_to_rest_on_the_table() {
    // the shipped table drape; once the cloth rests, static friction holds
    // every contact (before, half the contacts flipped between stick and slip
    // every step, for ever; later, until the friction floor, contacts
    // carrying 1e-7 to 1e-4 of their weight flipped every other step on the
    // solve's error: `auto` on one thread, the Gauss–Seidel and multigrid
    // PCGs at tolerances from 1e-6 to 1e-8)
    use garment_sim::scene::Overrides;
    let sc = Scene::load(Path::new("config/scenes/table_drape.yaml")).unwrap();
    for (spacing, dt, threads) in [
        (0.02, 1e-3, None),
        (0.01, 1.0 / 120.0, Some(1)),
        (0.01, 1.0 / 120.0, Some(2)),
    ] {
        let mut sim = sc
            .build(&Overrides {
                spacing: Some(spacing),
                dt: Some(dt),
                threads,
                ..Default::default()
            })
            .unwrap();
        let steps = (4.0 / dt).round() as usize;
        let tail = (0.5 / dt).round() as usize;
        let mut seen = std::collections::BTreeSet::new();
        let mut last = (0, 0);
        let (mut iterations, mut changes) = (0, 0);
        for k in 0..steps {
            let s = sim.step().unwrap();
            if k >= steps - tail {
                seen.insert((s.contacts, s.stuck));
                iterations += s.iterations;
                changes += usize::from((s.contacts, s.stuck) != last);
            }
            last = (s.contacts, s.stuck);
        }
        let mean = iterations as f64 / tail as f64;
        let what = format!("{spacing} m at dt = {dt:.5} s, threads {threads:?}");
        println!(
            "{what}: over the last 0.5 s (contacts, stuck) took the values {seen:?} and changed in {changes} of {tail} steps, {mean:.1} solver iterations per step"
        );
        // at rest the solvers' test is floored by gravity's impulse: a few
        // iterations, not the hundreds a test relative to the tiny
        // right-hand side asked for (260–290 per step at 1 cm)
        assert!(mean < 30.0, "{what}: {mean} iterations per step at rest");
        assert!(
            last.0 > 100,
            "the cloth lies on the board ({} contacts)",
            last.0
        );
        // a chattering contact changes every step or two (15–21 of these 60
        // steps, and hundreds before); a cloth that settles may still let
        // one contact slip once, where its slowly changing load reaches the
        // friction cone (a slip and the stick after it: two changes)
        assert!(
            changes <= 2,
            "{what}: the contacts still change at rest ({changes} of {tail} steps): {seen:?}"
        );
        assert_eq!(last.0, last.1, "{what}: every contact held at rest");
    }
}

fn scene_error(yaml: &str) -> String {
    let dir = support::Scratch::new("bad_scene");
    std::fs::copy("tests/data/acrylic_test.yaml", dir.join("fab.yaml")).unwrap();
    let p = dir.join("bad.yaml");
    std::fs::write(&p, yaml).unwrap();
    let r = Scene::load(&p).and_then(|s| s.build(&Default::default()).map(|_| ()));
    format!("{:#}", r.expect_err("must be rejected"))
}

#[test]
fn bad_scene_files_name_the_file_and_the_field() {
    let base = "cloth: { fabric: fab.yaml, size: [0.2, 0.2], spacing: 0.05 }\n";
    let e = scene_error(&format!("{base}dt: -0.001\nduration: 1\n"));
    assert!(e.contains("bad.yaml") && e.contains("dt"), "{e}");
    let e = scene_error(&format!("{base}dt: 0.001\nduration: 1\nwind: 3\n"));
    assert!(e.contains("bad.yaml") && e.contains("wind"), "{e}");
    let e = scene_error(&format!(
        "{base}dt: 0.001\nduration: 1\npins: [{{grid: [9, 0]}}]\n"
    ));
    assert!(e.contains("pins[0].grid") && e.contains("(9, 0)"), "{e}");
    let e = scene_error(&format!(
        "{base}dt: 0.001\nduration: 1\nobstacles: [{{id: b, shape: {{type: sphere, radius: -1}}}}]\n"
    ));
    assert!(e.contains("obstacles[0]") && e.contains("radius"), "{e}");
    let e = scene_error(
        "cloth: { fabric: nope.yaml, size: [0.2, 0.2], spacing: 0.05 }\ndt: 0.001\nduration: 1\n",
    );
    assert!(e.contains("cloth.fabric") && e.contains("nope.yaml"), "{e}");
    let e = scene_error(&format!(
        "{base}dt: 0.001\nduration: 1\nobstacles: [{{id: m, shape: {{type: mesh, obj: missing.obj}}}}]\n"
    ));
    assert!(e.contains("missing.obj"), "{e}");
}

#[test]
fn bad_fabric_files_name_the_field() {
    let dir = support::Scratch::new("bad_fabric");
    let good = std::fs::read_to_string("tests/data/acrylic_test.yaml").unwrap();
    for (from, to, want) in [
        ("EMT: 5.34", "EMT: -5.34", "warp.tensile.EMT"),
        ("alpha: -7.0", "alpha: 7.0", "damping.alpha"),
        ("B: 0.030", "Bee: 0.030", "Bee"),
        ("2HG5: 1.45", "2HG5: .nan", "weft.shear.2HG5"),
    ] {
        assert!(good.contains(from), "{from}");
        let p = dir.join("f.yaml");
        std::fs::write(&p, good.replacen(from, to, 1)).unwrap();
        let e = format!(
            "{:#}",
            garment_sim::io::load_fabric(&p).expect_err("must be rejected")
        );
        assert!(e.contains("f.yaml") && e.contains(want), "{want}: {e}");
    }
}

#[test]
fn obj_with_a_face_on_a_missing_vertex_is_rejected() {
    let dir = support::Scratch::new("bad_obj");
    let p = dir.join("bad.obj");
    std::fs::write(&p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n").unwrap();
    let e = format!("{:#}", garment_sim::io::load_obj(&p).unwrap_err());
    assert!(e.contains("bad.obj:4") && e.contains("vertex 7"), "{e}");
}

/// Every shipped fabric loads with the simulator's own loader and says where
/// its numbers come from.
#[test]
fn shipped_fabrics_load_and_cite_a_source() {
    let files = support::shipped_fabrics();
    for p in &files {
        let f =
            garment_sim::io::load_fabric(p).unwrap_or_else(|e| panic!("{}: {e:#}", p.display()));
        assert!(
            f.file.source.trim().len() > 20,
            "{} has no source",
            p.display()
        );
        assert!(f.areal_mass > 0.0 && f.damping.alpha < 0.0);
    }
    assert!(files.len() >= 5, "{} fabrics", files.len());
}
