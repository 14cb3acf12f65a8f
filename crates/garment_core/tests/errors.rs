//! Each kind of the core's [`Error`] is the variant a caller matches, with
//! the figures of the failure in its fields and its message as before.

use garment_core::deforming::Keyframes;
use garment_core::fabric::kes::parse_curve_csv;
use garment_core::{
    BehaviourSpec, Cloth, Damping, DirectionSpec, Error, Fabric, FabricFile, GridSpec,
    LinearSolverKind, Obstacle, Outline, PanelSpec, Params, Pin, PinPath, ShapeSpec, Simulation,
};
use nalgebra::{Isometry3, Vector3};
use std::error::Error as _;

fn fabric() -> Fabric {
    let dir = || DirectionSpec {
        tensile: BehaviourSpec {
            lt: Some(0.65),
            wt: Some(8.68),
            rt: Some(62.0),
            emt: Some(5.34),
            ..Default::default()
        },
        shear: BehaviourSpec {
            g: Some(0.6),
            hg: Some(0.7),
            hg5: Some(1.5),
            ..Default::default()
        },
        bending: BehaviourSpec {
            b: Some(0.04),
            hb: Some(0.03),
            ..Default::default()
        },
    };
    let file = FabricFile {
        name: "test".into(),
        source: String::new(),
        notes: String::new(),
        areal_mass_mg_per_cm2: 21.3,
        thickness_mm: None,
        cloth_friction: None,
        warp: dir(),
        weft: dir(),
        damping: Damping::NONE,
    };
    Fabric::from_file(file, &|name| {
        Err(std::io::Error::other(format!("no curve {name}")))
    })
    .unwrap()
}

/// A 10 × 10 cm square of 6 × 6 vertices lying flat 1 m up.
fn sim(params: Params) -> Simulation {
    let f = fabric();
    let spec = GridSpec {
        size: [0.1, 0.1],
        spacing: [0.02, 0.02],
        pose: Isometry3::translation(0.0, 0.0, 1.0),
    };
    let cloth = Cloth::grid(&spec, f.areal_mass).unwrap();
    Simulation::new(cloth, f, params).unwrap()
}

#[test]
fn a_step_with_an_overflowing_velocity_diverges_at_that_vertex() {
    let mut s = sim(Params::default());
    let mut v = s.cloth.velocities().to_vec();
    v[7] = Vector3::new(1e308, 0.0, 0.0);
    s.cloth.set_velocities(&v).unwrap();
    let e = s.step().unwrap_err();
    match &e {
        Error::Diverged {
            vertex,
            step,
            pinned,
            time,
            ..
        } => {
            assert!(*vertex < 36);
            assert_eq!((*step, *pinned, *time), (0, false, 0.0));
        }
        e => panic!("not Diverged: {e:?}"),
    }
    assert!(
        e.to_string().starts_with("the step diverged at vertex "),
        "{e}"
    );
    assert_eq!(s.steps, 0, "a failed step changes nothing");
}

#[test]
fn a_pcg_capped_at_one_iteration_fails_the_step_with_not_converged_under_it() {
    let mut s = sim(Params {
        linear_solver: LinearSolverKind::Pcg,
        cg_max_iterations: 1,
        ..Params::default()
    });
    let e = s.step().unwrap_err();
    let Error::StepFailed {
        step, diagnosis, ..
    } = &e
    else {
        panic!("not StepFailed: {e:?}")
    };
    assert_eq!(*step, 0);
    // the message is the diagnosis; the solver's error is its source
    assert_eq!(&e.to_string(), diagnosis);
    match e.root() {
        Error::NotConverged {
            max_iterations: 1,
            residual_ratio,
            stopped_at: None,
        } => assert!(*residual_ratio > Params::default().cg_tolerance),
        r => panic!("not NotConverged: {r:?}"),
    }
    let source = e.source().unwrap().to_string();
    assert!(
        source.starts_with("PCG did not converge in 1 iterations (residual ratio "),
        "{source}"
    );
}

#[test]
fn a_parameter_outside_its_bound_names_the_field_and_value() {
    let e = sim(Params::default())
        .set_params(Params {
            dt: 0.5,
            ..Params::default()
        })
        .unwrap_err();
    match &e {
        Error::OutOfBound { field, value, .. } => {
            assert_eq!((field.as_str(), *value), ("dt", 0.5));
        }
        e => panic!("not OutOfBound: {e:?}"),
    }
    assert_eq!(
        e.to_string(),
        "dt = 0.5: must lie in (0, 0.05] s (MAX_DT: the step is linearised once)"
    );
    // the hysteresis is not a bound: another kind
    let e = sim(Params::default())
        .set_params(Params {
            hysteresis: !Params::default().hysteresis,
            ..Params::default()
        })
        .unwrap_err();
    assert!(matches!(e, Error::Invalid { .. }), "{e:?}");
}

#[test]
fn frames_of_the_wrong_length_or_not_finite_are_refused() {
    let e = Keyframes::at_rate(
        10.0,
        vec![vec![Vector3::zeros(); 3], vec![Vector3::zeros(); 2]],
    )
    .unwrap_err();
    match e {
        Error::Length { got, expected, .. } => assert_eq!((got, expected), (2, 3)),
        e => panic!("not Length: {e:?}"),
    }
    let e = Keyframes::at_rate(
        10.0,
        vec![vec![
            Vector3::zeros(),
            Vector3::new(0.0, f64::INFINITY, 0.0),
        ]],
    )
    .unwrap_err();
    assert!(matches!(e, Error::NonFinite { index: 1, .. }), "{e:?}");
    assert_eq!(
        e.to_string(),
        "frame 0: vertex 1 is not finite: [[0.0, inf, 0.0]]"
    );
}

#[test]
fn a_pin_beyond_the_cloth_is_an_index_error() {
    let mut s = sim(Params::default());
    let e = s
        .set_pins(vec![Pin::new(36, PinPath::Fixed(Vector3::zeros()))])
        .unwrap_err();
    match &e {
        Error::Index { index, len, .. } => assert_eq!((*index, *len), (36, 36)),
        e => panic!("not Index: {e:?}"),
    }
    assert_eq!(
        e.to_string(),
        "pin on vertex 36 but the cloth has 36 vertices"
    );
}

#[test]
fn a_flat_outline_is_a_mesh_error() {
    let outline = Outline::Polygon(vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]]);
    let e = Cloth::panel(&PanelSpec::new(
        &outline,
        [0.02, 0.02],
        [0.0, 0.0],
        &Isometry3::identity(),
        0.2,
    ))
    .unwrap_err();
    assert!(matches!(e, Error::Mesh { .. }), "{e:?}");
    assert_eq!(e.to_string(), "outline polygon has zero area");
}

#[test]
fn a_cloth_inside_an_obstacle_is_a_placement_error() {
    let s = sim(Params::default());
    let ball = Obstacle::new(
        "ball",
        ShapeSpec::Sphere { radius: 0.2 },
        Isometry3::translation(0.05, 0.05, 1.0),
        0.0,
        0.0,
    )
    .unwrap();
    let e = ball.check_overlap(s.cloth.positions()).unwrap_err();
    assert!(matches!(e, Error::Placement { .. }), "{e:?}");
    assert!(
        e.to_string()
            .starts_with("obstacle \"ball\" overlaps the cloth"),
        "{e}"
    );
}

#[test]
fn a_grid_over_the_memory_is_too_large() {
    let e = garment_core::limits::check_memory(1000, 1000, Some(1_000_000)).unwrap_err();
    assert!(matches!(e, Error::TooLarge { .. }), "{e:?}");
}

#[test]
fn a_bad_curve_is_a_fabric_error_and_a_bad_number_keeps_its_cause() {
    let e = parse_curve_csv("x,y,branch\n", "c.csv").unwrap_err();
    assert!(matches!(e, Error::Fabric { .. }), "{e:?}");
    let e = parse_curve_csv("strain_pct,force_gf_cm,branch\n1,zz,load\n", "c.csv").unwrap_err();
    let Error::External { context, source } = &e else {
        panic!("not External: {e:?}")
    };
    assert_eq!(context, "c.csv: line 2: bad number \"zz\"");
    assert!(source.downcast_ref::<std::num::ParseFloatError>().is_some());
    // a curve the reader could not read: the field under the reader's error
    let mut file = fabric_file_with_curve();
    file.warp.tensile.curve = Some("warp.csv".into());
    let e = Fabric::from_file(file, &|name| {
        Err(std::io::Error::other(format!("no file {name}")))
    })
    .unwrap_err();
    assert_eq!(e.to_string(), "warp.tensile.curve");
    assert_eq!(e.source().unwrap().to_string(), "no file warp.csv");
}

fn fabric_file_with_curve() -> FabricFile {
    let f = fabric();
    f.file.clone()
}

#[test]
fn an_unknown_solver_name_is_invalid_and_a_deforming_obstacle_names_itself() {
    let e = "lu".parse::<LinearSolverKind>().unwrap_err();
    assert!(matches!(e, Error::Invalid { .. }), "{e:?}");
    // a motion's triangle beyond its vertices: an index error
    let frames = vec![vec![Vector3::zeros(), Vector3::x(), Vector3::y()]];
    let motion = std::sync::Arc::new(Keyframes::at_rate(30.0, frames).unwrap());
    let body = |tris, start| {
        Obstacle::with_motion(
            "body",
            tris,
            motion.clone(),
            false,
            start,
            Isometry3::identity(),
            0.0,
            0.0,
        )
    };
    let e = body(vec![[0, 1, 3]], 0.0).unwrap_err();
    match &e {
        Error::Index { index, len, .. } => assert_eq!((*index, *len), (3, 3)),
        e => panic!("not Index: {e:?}"),
    }
    // a start that is not finite: the motion's bound under the obstacle's name
    let e = body(vec![[0, 1, 2]], f64::NAN).unwrap_err();
    assert_eq!(e.to_string(), "obstacle \"body\"");
    assert!(matches!(e, Error::Context { .. }), "{e:?}");
    match e.root() {
        Error::OutOfBound { field, value, .. } => {
            assert!(field == "motion start" && value.is_nan())
        }
        r => panic!("not OutOfBound: {r:?}"),
    }
    assert_eq!(
        e.source().unwrap().to_string(),
        "motion start NaN s: must be finite"
    );
}

#[test]
fn the_state_is_written_through_checked_methods() {
    let mut s = sim(Params::default());
    let x = s.cloth.positions().to_vec();
    let e = s.cloth.set_positions(&x[..35]).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Length {
                got: 35,
                expected: 36,
                ..
            }
        ),
        "{e:?}"
    );
    let mut bad = x.clone();
    bad[12].y = f64::NAN;
    let e = s.cloth.set_positions(&bad).unwrap_err();
    assert!(matches!(e, Error::NonFinite { index: 12, .. }), "{e:?}");
    let e = s.cloth.set_position(36, Vector3::zeros()).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Index {
                index: 36,
                len: 36,
                ..
            }
        ),
        "{e:?}"
    );
    assert_eq!(
        s.cloth.positions(),
        &x[..],
        "a refused write changes nothing"
    );
    // a write that is taken is what the step starts from: a lifted cloth
    // falls from the new height (one step of 1/120 s under gravity alone)
    let lifted: Vec<Vector3<f64>> = x.iter().map(|p| p + Vector3::new(0.0, 0.0, 1.0)).collect();
    s.cloth.set_positions(&lifted).unwrap();
    s.cloth
        .set_velocities(&vec![Vector3::new(0.0, 0.0, 0.5); 36])
        .unwrap();
    assert!(s.cloth.velocities().iter().all(|v| v.z == 0.5));
    s.cloth.stop();
    assert!(s.cloth.velocities().iter().all(|v| *v == Vector3::zeros()));
    s.step().unwrap();
    let z: f64 = s.cloth.positions().iter().map(|p| p.z).sum::<f64>() / 36.0;
    let dt = s.params().dt;
    // the implicit step of a free, flat cloth: z drops by g dt² exactly
    // (velocity g dt after one step, the position moved by it)
    assert!((z - (2.0 - 9.81 * dt * dt)).abs() < 1e-9, "{z}");
    // a single piece has no seams: gains for none, and none for one
    assert!(s.cloth.seams().is_empty());
    s.cloth.set_seam_gains(&[]).unwrap();
    let e = s.cloth.set_seam_gains(&[(1.0, 0.0)]).unwrap_err();
    assert!(
        matches!(
            e,
            Error::Length {
                got: 1,
                expected: 0,
                ..
            }
        ),
        "{e:?}"
    );
}
