//! The Rust ROS 2 message types serialise byte for byte as the independent
//! `rosbags` CDR codec does (tests/ros_msgs.py): samples built from a real
//! simulation (cloud, cloth and obstacle markers, diagnostics), the
//! garment_sim_msgs types from msg/ and mesh_msgs/MeshGeometryStamped.

mod support;

use garment_sim::msgs::publish;
use garment_sim::msgs::*;
use garment_sim::scene::{Overrides, Scene};
use serde::Serialize;
use std::path::Path;

fn write<T: Serialize + RosType>(dir: &Path, stem: &str, msg: &T) {
    std::fs::write(dir.join(format!("{stem}.cdr")), to_cdr(msg)).unwrap();
    std::fs::write(
        dir.join(format!("{stem}.json")),
        serde_json::to_string(msg).unwrap(),
    )
    .unwrap();
    std::fs::write(dir.join(format!("{stem}.type")), T::NAME).unwrap();
}

fn round_trip<T>(msg: &T)
where
    T: Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug,
{
    let back: T = from_cdr(&to_cdr(msg)).unwrap();
    assert_eq!(&back, msg);
}

#[test]
fn messages_match_rosbags_byte_for_byte() {
    let scene = Scene::load(Path::new("config/scenes/table_drape.yaml")).unwrap();
    let mut sim = scene
        .build(&Overrides {
            spacing: Some(0.05),
            ..Default::default()
        })
        .unwrap();
    for _ in 0..20 {
        sim.step().unwrap();
    }
    let h = publish::header(&sim, "world");
    let dir = support::Scratch::new("msgs");

    let cloud = publish::cloud(&sim, h.clone());
    assert_eq!(cloud.width as usize, sim.cloth.len());
    let pts = publish::cloud_points(&cloud).unwrap();
    for (p, x) in pts.iter().zip(sim.cloth.positions()) {
        assert_eq!(p[2], x.z as f32);
    }
    round_trip(&cloud);
    write(&dir, "cloud", &cloud);
    let mesh = publish::cloth_marker(&sim, h.clone());
    assert_eq!(mesh.points.len(), 3 * sim.cloth.triangles.len());
    round_trip(&mesh);
    write(&dir, "cloth_marker", &mesh);
    let obs = publish::obstacle_markers(&sim, h.clone());
    assert_eq!(obs.markers.len(), 1 + sim.obstacles().len());
    assert!(obs.markers[1].points.len() >= 36, "a box is 12 triangles");
    round_trip(&obs);
    write(&dir, "obstacle_markers", &obs);
    let diag = publish::diagnostics(
        &sim,
        h.clone(),
        &publish::DiagnosticFigures {
            step_time_ms: 1.5,
            iterations: 7,
            real_time_factor: 0.9,
            rejected_messages: 2,
            dropped_messages: 5,
            recovered_steps: 1,
            paused: false,
            last_error: "pin: vertex 99999 out of range".into(),
            body_messages: 12,
            body_late: 1,
            body_refused: vec![("out_of_order", 2)],
        },
    );
    let keys: Vec<&str> = diag.status[0]
        .values
        .iter()
        .map(|kv| kv.key.as_str())
        .collect();
    for k in [
        "solver_iterations",
        "contacts",
        "contacts_held",
        "real_time_factor",
        "recovered_steps",
        "body_messages",
        "body_late_frames",
        "body_refused_out_of_order",
    ] {
        assert!(keys.contains(&k), "diagnostics lack {k}: {keys:?}");
    }
    round_trip(&diag);
    write(&dir, "diagnostics", &diag);
    write(&dir, "clock", &Clock { clock: h.stamp });
    let wrench = publish::body_wrench(
        &garment_sim::trial::body_forces::Wrench {
            force: [0.01, -0.02, -1.325],
            torque: [0.0005, 0.0019, -0.0002],
            normal_force: 4.3,
            contacts: 229,
        },
        &nalgebra::Vector3::new(0.0, 0.0, 1.0),
        h.clone(),
    );
    assert_eq!(wrench.wrench.force.z, -1.325);
    // the torque about the world's origin: the body frame's, plus o × F
    assert!((wrench.wrench.torque.x - (0.0005 + 0.02)).abs() < 1e-12);
    assert!((wrench.wrench.torque.y - (0.0019 + 0.01)).abs() < 1e-12);
    round_trip(&wrench);
    write(&dir, "wrench_stamped", &wrench);
    write(
        &dir,
        "string",
        &StringMsg {
            data: "scene: ünïcode ✓".into(),
        },
    );
    write(&dir, "header_empty_frame", &Header::default());
    let pose = Pose {
        position: Point {
            x: 0.1,
            y: -0.2,
            z: 0.7,
        },
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.38268343236508984,
            w: 0.9238795325112867,
        },
    };
    let obstacle = Obstacle {
        header: h.clone(),
        id: "gripper".into(),
        pose,
        primitives: vec![
            SolidPrimitive {
                type_: SolidPrimitive::BOX,
                dimensions: vec![0.3, 0.2, 0.01],
                polygon: Polygon::default(),
            },
            SolidPrimitive {
                type_: SolidPrimitive::PRISM,
                dimensions: vec![0.05],
                polygon: Polygon {
                    points: vec![
                        Point32 {
                            x: 0.0,
                            y: 0.0,
                            z: 0.0,
                        },
                        Point32 {
                            x: 0.1,
                            y: 0.0,
                            z: 0.0,
                        },
                        Point32 {
                            x: 0.0,
                            y: 0.1,
                            z: 0.0,
                        },
                    ],
                },
            },
        ],
        primitive_poses: vec![pose, Pose::default()],
        meshes: vec![Mesh {
            triangles: vec![MeshTriangle {
                vertex_indices: [0, 1, 2],
            }],
            vertices: vec![
                Point::default(),
                Point {
                    x: 1.0,
                    y: 0.0,
                    z: 0.0,
                },
                Point {
                    x: 0.0,
                    y: 1.0,
                    z: 0.0,
                },
            ],
        }],
        mesh_poses: vec![Pose::default()],
        velocity: Twist {
            linear: Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.5,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: 0.1,
            },
        },
        thickness: 0.006,
        friction: 0.3,
        operation: Obstacle::MOVE,
    };
    round_trip(&obstacle);
    write(&dir, "obstacle", &obstacle);
    let pin = Pin {
        header: h.clone(),
        operation: Pin::PIN,
        vertices: vec![],
        grid_i: vec![0, 10],
        grid_j: vec![0, 0],
        panel: String::new(),
        targets: vec![
            Point {
                x: 0.0,
                y: 0.0,
                z: 1.0,
            },
            Point {
                x: 0.5,
                y: 0.0,
                z: 1.0,
            },
        ],
        velocities: vec![Vector3::default(); 2],
    };
    round_trip(&pin);
    write(&dir, "pin", &pin);
    // a body's topology frame (two triangles) and a positions-only frame
    let body = Body {
        header: h.clone(),
        id: "avatar".into(),
        triangles: vec![0, 1, 2, 0, 2, 3],
        positions: vec![0.0, 0.0, 1.0, 0.1, 0.0, 1.0, 0.1, 0.1, 1.0, 0.0, 0.1, 1.25],
        thickness: 0.004,
        friction: f64::NAN,
    };
    let back: Body = from_cdr(&to_cdr(&body)).unwrap();
    assert_eq!(
        (&back.triangles, &back.positions),
        (&body.triangles, &body.positions)
    );
    assert!(back.friction.is_nan());
    let body = Body {
        friction: 0.5,
        ..body
    };
    write(&dir, "body_topology", &body);
    let frame = Body {
        triangles: vec![],
        positions: vec![0.5; 12],
        ..body
    };
    round_trip(&frame);
    write(&dir, "body_frame", &frame);
    // a body as mesh_msgs sends it: float64 vertices, their normals, faces
    let mesh = MeshGeometryStamped {
        header: h.clone(),
        uuid: "avatar".into(),
        mesh_geometry: MeshGeometry {
            vertices: (0..4)
                .map(|k| Point {
                    x: 0.1 * k as f64,
                    y: 0.25,
                    z: 1.0 + 1e-9 * k as f64,
                })
                .collect(),
            vertex_normals: vec![
                Point {
                    x: 0.0,
                    y: 0.0,
                    z: 1.0
                };
                4
            ],
            faces: vec![
                MeshTriangleIndices {
                    vertex_indices: [0, 1, 2],
                },
                MeshTriangleIndices {
                    vertex_indices: [0, 2, 3],
                },
            ],
        },
    };
    round_trip(&mesh);
    write(&dir, "mesh_geometry_stamped", &mesh);
    write(&dir, "step_request", &StepRequest { steps: 12 });
    write(
        &dir,
        "step_response",
        &StepResponse {
            success: true,
            message: "ok".into(),
            sim_time: Time::from_secs(1.5),
        },
    );
    write(&dir, "trigger_request", &TriggerRequest::default());
    write(
        &dir,
        "trigger_response",
        &TriggerResponse {
            success: true,
            message: "reset".into(),
        },
    );
    write(&dir, "setbool_request", &SetBoolRequest { data: true });
    write(
        &dir,
        "setbool_response",
        &SetBoolResponse {
            success: false,
            message: "x".into(),
        },
    );

    support::pytest(
        "tests/ros_msgs.py",
        "rosbags, numpy, pytest",
        false,
        &[("GARMENT_SIM_MSG_SAMPLES", dir.as_os_str())],
        "2 passed",
    );
}
