//! What the node publishes (and the bag recorder stores), built from a
//! [`Simulation`]: the cloth as a point cloud and a triangle-list marker, the
//! obstacles as markers, the diagnostics and the clock. Pure functions of the
//! simulation state, shared by the node and the headless recorder so both
//! write the same messages.

use super::*;
use crate::solver::Simulation;

pub use crate::pictures::render::vertex_strain;

/// Fields of `cloth/points`: x, y, z (m), strain (1), speed (m/s), all float32.
pub const CLOUD_FIELDS: [&str; 5] = ["x", "y", "z", "strain", "speed"];

/// An unorganised (height 1) PointCloud2 of `n` points whose fields
/// `names` are float32, packed in that order, little-endian, in `data`.
fn float_cloud(header: Header, names: &[&str], n: usize, data: Vec<u8>) -> PointCloud2 {
    let step = 4 * names.len();
    debug_assert_eq!(data.len(), n * step);
    PointCloud2 {
        header,
        height: 1,
        width: n as u32,
        fields: names
            .iter()
            .enumerate()
            .map(|(k, name)| PointField {
                name: name.to_string(),
                offset: 4 * k as u32,
                datatype: PointField::FLOAT32,
                count: 1,
            })
            .collect(),
        is_bigendian: false,
        point_step: step as u32,
        row_step: (step * n) as u32,
        data,
        is_dense: true,
    }
}

/// The cloth vertices as an unorganised PointCloud2 (height 1), little-endian.
pub fn cloud(sim: &Simulation, header: Header) -> PointCloud2 {
    cloud_with(sim, header, &[])
}

/// [`cloud`] with more float32 fields after the [`CLOUD_FIELDS`]: (name,
/// one value per vertex).
pub fn cloud_with(sim: &Simulation, header: Header, extra: &[(&str, &[f64])]) -> PointCloud2 {
    let n = sim.cloth.len();
    let strain = vertex_strain(sim);
    let names: Vec<&str> = CLOUD_FIELDS
        .iter()
        .copied()
        .chain(extra.iter().map(|e| e.0))
        .collect();
    let step = 4 * names.len();
    let mut data = Vec::with_capacity(n * step);
    for i in 0..n {
        let p = sim.cloth.positions()[i];
        let vals = [
            p.x as f32,
            p.y as f32,
            p.z as f32,
            strain[i] as f32,
            sim.cloth.velocities()[i].norm() as f32,
        ];
        for v in vals.into_iter().chain(extra.iter().map(|e| e.1[i] as f32)) {
            data.extend_from_slice(&v.to_le_bytes());
        }
    }
    float_cloud(header, &names, n, data)
}

/// The garment's wrench on the body as `body/wrench` carries it: force N and
/// torque N m about the origin of the header's frame (the simulation's world,
/// as a WrenchStamped means it), moved there from the body frame's origin
/// `origin` (world coordinates) where [`crate::trial::body_forces::Wrench`] takes it.
pub fn body_wrench(
    w: &crate::trial::body_forces::Wrench,
    origin: &nalgebra::Vector3<f64>,
    header: Header,
) -> WrenchStamped {
    let v = |a: nalgebra::Vector3<f64>| Vector3 {
        x: a.x,
        y: a.y,
        z: a.z,
    };
    let force = nalgebra::Vector3::from(w.force);
    let torque = nalgebra::Vector3::from(w.torque) + origin.cross(&force);
    WrenchStamped {
        header,
        wrench: Wrench {
            force: v(force),
            torque: v(torque),
        },
    }
}

/// The fields of `body/points`: the body's vertices and the garment's
/// pressure on each (float32).
pub const BODY_CLOUD_FIELDS: [&str; 4] = ["x", "y", "z", "pressure"];

/// The body's vertices with the garment's pressure on each, Pa, as
/// `body/points` carries them.
pub fn body_cloud(p: &crate::trial::body_forces::BodyPressure, header: Header) -> PointCloud2 {
    let n = p.vertices.len();
    let step = 4 * BODY_CLOUD_FIELDS.len();
    let mut data = Vec::with_capacity(n * step);
    for (x, pr) in p.vertices.iter().zip(&p.pressure) {
        for v in [x.x as f32, x.y as f32, x.z as f32, *pr as f32] {
            data.extend_from_slice(&v.to_le_bytes());
        }
    }
    float_cloud(header, &BODY_CLOUD_FIELDS, n, data)
}

/// Reads x, y, z back from a cloud written by [`cloud`] (or any little-endian
/// cloud with float32 x, y, z fields).
pub fn cloud_points(c: &PointCloud2) -> anyhow::Result<Vec<[f32; 3]>> {
    anyhow::ensure!(!c.is_bigendian, "big-endian point clouds are not supported");
    let off = |name: &str| -> anyhow::Result<usize> {
        let f = c
            .fields
            .iter()
            .find(|f| f.name == name)
            .ok_or_else(|| anyhow::anyhow!("point cloud has no field {name:?}"))?;
        anyhow::ensure!(
            f.datatype == PointField::FLOAT32,
            "field {name:?} is not float32"
        );
        Ok(f.offset as usize)
    };
    let (ox, oy, oz) = (off("x")?, off("y")?, off("z")?);
    let n = (c.width * c.height) as usize;
    let step = c.point_step as usize;
    anyhow::ensure!(
        c.data.len() >= n * step && step >= 12,
        "point cloud data has {} bytes, {} points of {} bytes expected",
        c.data.len(),
        n,
        step
    );
    let rd = |k: usize| f32::from_le_bytes(c.data[k..k + 4].try_into().unwrap());
    Ok((0..n)
        .map(|i| [rd(i * step + ox), rd(i * step + oy), rd(i * step + oz)])
        .collect())
}

/// Colour of a strain value: grey-blue at rest, red at `full` strain.
fn strain_colour(e: f64, full: f64) -> ColorRGBA {
    let t = (e.max(0.0) / full).min(1.0) as f32;
    ColorRGBA {
        r: 0.35 + 0.6 * t,
        g: 0.45 * (1.0 - t) + 0.1,
        b: 0.75 * (1.0 - t) + 0.1,
        a: 1.0,
    }
}

/// The cloth surface as a TRIANGLE_LIST marker coloured by strain (red at 2 %).
pub fn cloth_marker(sim: &Simulation, header: Header) -> Marker {
    let strain = vertex_strain(sim);
    let tris = &sim.cloth.triangles;
    let mut points = Vec::with_capacity(3 * tris.len());
    let mut colors = Vec::with_capacity(3 * tris.len());
    for t in tris {
        for &i in t {
            points.push(Point::from(sim.cloth.positions()[i]));
            colors.push(strain_colour(strain[i], 0.02));
        }
    }
    Marker {
        header,
        ns: "cloth".into(),
        id: 0,
        type_: Marker::TRIANGLE_LIST,
        action: Marker::ADD,
        pose: Pose::default(),
        scale: Vector3 {
            x: 1.0,
            y: 1.0,
            z: 1.0,
        },
        color: ColorRGBA {
            r: 0.4,
            g: 0.5,
            b: 0.8,
            a: 1.0,
        },
        points,
        colors,
        ..Default::default()
    }
}

/// The obstacles as TRIANGLE_LIST markers (namespace `obstacles`, one id per
/// obstacle in scene order), preceded by a DELETEALL so removed obstacles vanish.
pub fn obstacle_markers(sim: &Simulation, header: Header) -> MarkerArray {
    let mut markers = vec![Marker {
        header: header.clone(),
        ns: "obstacles".into(),
        action: Marker::DELETEALL,
        ..Default::default()
    }];
    for (k, o) in sim.obstacles().iter().enumerate() {
        let (v, t) = o.local_triangles();
        let points = t
            .iter()
            .flat_map(|tri| {
                tri.iter().map(|&i| {
                    let p = v[i as usize];
                    Point {
                        x: p[0],
                        y: p[1],
                        z: p[2],
                    }
                })
            })
            .collect();
        markers.push(Marker {
            header: header.clone(),
            ns: "obstacles".into(),
            id: k as i32,
            type_: Marker::TRIANGLE_LIST,
            action: Marker::ADD,
            pose: Pose::from_isometry(&o.pose),
            scale: Vector3 {
                x: 1.0,
                y: 1.0,
                z: 1.0,
            },
            color: ColorRGBA {
                r: 0.6,
                g: 0.6,
                b: 0.55,
                a: 0.8,
            },
            text: o.id.clone(),
            points,
            ..Default::default()
        });
    }
    MarkerArray { markers }
}

/// Figures for `diagnostics`.
#[derive(Debug, Clone, Default)]
pub struct DiagnosticFigures {
    pub step_time_ms: f64,
    pub iterations: usize,
    pub real_time_factor: f64,
    pub rejected_messages: u64,
    /// Messages dropped because they came faster than the steps.
    pub dropped_messages: u64,
    /// Steps that failed and were taken again from the last good state.
    pub recovered_steps: u64,
    pub paused: bool,
    pub last_error: String,
    /// `body` messages taken (late ones included), late ones, and refused
    /// ones by kind (docs/bodies.md).
    pub body_messages: u64,
    pub body_late: u64,
    pub body_refused: Vec<(&'static str, u64)>,
}

/// One DiagnosticStatus `garment_sim: solver` with the step figures.
pub fn diagnostics(sim: &Simulation, header: Header, f: &DiagnosticFigures) -> DiagnosticArray {
    let kv = |k: &str, v: String| KeyValue {
        key: k.into(),
        value: v,
    };
    let (level, message) = if !f.last_error.is_empty() {
        (DiagnosticStatus::WARN, f.last_error.clone())
    } else if f.paused {
        (DiagnosticStatus::OK, "paused".to_string())
    } else {
        (DiagnosticStatus::OK, "running".to_string())
    };
    let mut values = vec![
        kv("sim_time_s", format!("{:.6}", sim.time)),
        kv("steps", sim.steps.to_string()),
        kv("dt_s", format!("{}", sim.params().dt)),
        kv("step_time_ms", format!("{:.3}", f.step_time_ms)),
        kv("solver_iterations", f.iterations.to_string()),
        kv("contacts", sim.last.contacts.to_string()),
        kv("contacts_held", sim.last.stuck.to_string()),
        kv("real_time_factor", format!("{:.3}", f.real_time_factor)),
        kv("rejected_messages", f.rejected_messages.to_string()),
        kv("dropped_messages", f.dropped_messages.to_string()),
        kv("recovered_steps", f.recovered_steps.to_string()),
        kv("vertices", sim.cloth.len().to_string()),
        kv("pins", sim.pins().len().to_string()),
        kv("obstacles", sim.obstacles().len().to_string()),
    ];
    if f.body_messages > 0 || !f.body_refused.is_empty() {
        values.push(kv("body_messages", f.body_messages.to_string()));
        values.push(kv("body_late_frames", f.body_late.to_string()));
        for (k, n) in &f.body_refused {
            values.push(kv(&format!("body_refused_{k}"), n.to_string()));
        }
    }
    if sim.params().self_collision {
        // the cloth against itself (docs/self_collision.md): the last step's
        // pairs pushed apart and paths that crossed, and its time
        let st = &sim.last;
        values.extend([
            kv("self_contacts", st.self_contacts.to_string()),
            kv("self_collisions", st.self_collisions.to_string()),
            kv("self_impact_zones", st.self_zones.to_string()),
            kv("self_collision_ms", format!("{:.3}", 1e3 * st.self_s)),
        ]);
    }
    DiagnosticArray {
        header,
        status: vec![DiagnosticStatus {
            level,
            name: "garment_sim: solver".into(),
            message,
            hardware_id: "garment_sim".into(),
            values,
        }],
    }
}

/// Header stamped with the simulated time.
pub fn header(sim: &Simulation, frame_id: &str) -> Header {
    Header {
        stamp: Time::from_secs(sim.time),
        frame_id: frame_id.to_string(),
    }
}

/// When the node publishes (and a bag records) a frame: the first step at or
/// after each multiple of the period 1/rate of simulated time. The node and
/// `drape --bag` share it, so their bags hold the same stamps.
#[derive(Debug, Clone)]
pub struct FrameClock {
    next: f64,
}

impl FrameClock {
    /// The first frame is due at simulated time `t0`.
    pub fn new(t0: f64) -> FrameClock {
        FrameClock { next: t0 }
    }

    /// Whether a frame is due at simulated time `t`; if so, the next one is
    /// scheduled one period (at `rate_hz`, which may change between calls)
    /// later, or one period after `t` if the run fell behind.
    pub fn due(&mut self, t: f64, rate_hz: f64) -> bool {
        if t + 1e-12 < self.next {
            return false;
        }
        self.next += 1.0 / rate_hz;
        if self.next < t {
            self.next = t + 1.0 / rate_hz;
        }
        true
    }
}
