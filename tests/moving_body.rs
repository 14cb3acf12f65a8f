//! Moving bodies (docs/bodies.md): a deforming mesh moved rigidly matches
//! the rigid obstacle, no cloth vertex ends a step inside a capsule or a
//! skinned arm hitting it at 2 m/s, linear blend skinning against its
//! closed form, and a cloth tube following a turning body.
#![allow(clippy::needless_range_loop)]

use garment_sim::cloth::{Cloth, GridSpec, Stitch};
use garment_sim::collision::{Obstacle, ShapeSpec};
use garment_sim::deforming::{Keyframes, Motion};
use garment_sim::fabric::Fabric;
use garment_sim::run::{Control, Phase};
use garment_sim::solver::{Params, Simulation};
use nalgebra::{Isometry3, Matrix4, Rotation3, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::Arc;

type V = Vector3<f64>;

fn fixture() -> Fabric {
    garment_sim::io::load_fabric(Path::new("tests/data/acrylic_test.yaml")).unwrap()
}

/// A closed, outward-oriented capsule along y centred at the origin: the
/// cylinder of half-length `half` and radius `r` (`seg` vertices around),
/// two hemispheres of `rings` latitude bands each.
fn capsule_mesh(half: f64, r: f64, seg: usize, rings: usize) -> (Vec<V>, Vec<[u32; 3]>) {
    let mut v = Vec::new();
    // latitude rings from the −y pole to the +y pole
    let mut lat: Vec<(f64, f64)> = Vec::new(); // (y, ring radius)
    for k in 1..=rings {
        let a = -PI / 2.0 + PI / 2.0 * k as f64 / rings as f64;
        lat.push((-half + r * a.sin(), r * a.cos()));
    }
    for k in 0..rings {
        let a = PI / 2.0 * k as f64 / rings as f64;
        lat.push((half + r * a.sin(), r * a.cos()));
    }
    v.push(V::new(0.0, -half - r, 0.0));
    for &(y, rr) in &lat {
        for j in 0..seg {
            let phi = 2.0 * PI * j as f64 / seg as f64;
            v.push(V::new(rr * phi.cos(), y, rr * phi.sin()));
        }
    }
    v.push(V::new(0.0, half + r, 0.0));
    let top = (v.len() - 1) as u32;
    let ring = |k: usize, j: usize| (1 + k * seg + j % seg) as u32;
    let mut t = Vec::new();
    // orientation: (b − a) × (c − a) outward
    for j in 0..seg {
        t.push([0, ring(0, j), ring(0, j + 1)]);
    }
    for k in 0..lat.len() - 1 {
        for j in 0..seg {
            let (a, b, c, d) = (
                ring(k, j),
                ring(k, j + 1),
                ring(k + 1, j),
                ring(k + 1, j + 1),
            );
            t.push([a, c, b]);
            t.push([b, c, d]);
        }
    }
    let last = lat.len() - 1;
    for j in 0..seg {
        t.push([top, ring(last, j + 1), ring(last, j)]);
    }
    (v, t)
}

/// Signed volume of a closed mesh (positive when its faces face outward).
fn volume(v: &[V], t: &[[u32; 3]]) -> f64 {
    t.iter()
        .map(|f| {
            let [a, b, c] = f.map(|i| v[i as usize]);
            a.dot(&b.cross(&c)) / 6.0
        })
        .sum()
}

/// Distance from `p` to segment a–b.
fn to_segment(p: &V, a: &V, b: &V) -> f64 {
    let d = b - a;
    let s = ((p - a).dot(&d) / d.norm_squared()).clamp(0.0, 1.0);
    (p - (a + d * s)).norm()
}

/// Keyframes moving `v` by `pose(t)` at `fps` over `duration`.
fn rigid_frames(
    v: &[V],
    fps: f64,
    duration: f64,
    pose: impl Fn(f64) -> Isometry3<f64>,
) -> Arc<Keyframes> {
    let n = (duration * fps).round() as usize;
    let frames = (0..=n)
        .map(|k| {
            let p = pose(k as f64 / fps);
            v.iter()
                .map(|x| p.transform_vector(x) + p.translation.vector)
                .collect()
        })
        .collect();
    Arc::new(Keyframes::at_rate(fps, frames).unwrap())
}

fn sheet(size: [f64; 2], spacing: f64, pose: Isometry3<f64>, f: &Fabric, dt: f64) -> Simulation {
    let grid = GridSpec {
        size,
        spacing: [spacing, spacing],
        pose,
    };
    let cloth = Cloth::grid(&grid, f.areal_mass).unwrap();
    Simulation::new(
        cloth,
        f.clone(),
        Params {
            dt,
            ..Params::default()
        },
    )
    .unwrap()
}

/// A box (40 × 40 × 10 cm, 12 triangles) under a falling sheet, sliding
/// along x at 0.3 m/s and carrying the sheet by friction, as a rigid
/// obstacle (constant velocity) and as a deforming mesh (its vertices moved
/// by the same translation, 30 frames a second): the contact geometry and the
/// surface velocity are the same but for rounding (the frames interpolated
/// to the step are the translated vertices to ~1e-16 relative; their velocity
/// is the translation's to ~1e-13 m/s), so the cloths' paths differ by that
/// rounding grown over the steps; bound: no vertex 1 µm apart after 150
/// steps, the same contacts at every step. (On a flat top both contact
/// phases look at the same vertices; on a curved surface the rigid
/// obstacle's look-ahead along the relative path skips a few that the
/// deforming mesh's swept box takes, a step earlier than the rigid one.)
#[test]
fn a_rigidly_moved_mesh_moves_the_cloth_as_the_rigid_obstacle() {
    let f = fixture();
    let dt = 1.0 / 240.0;
    let v: Vec<V> = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
        [1.0, 1.0, 1.0],
        [0.0, 1.0, 1.0],
    ]
    .iter()
    .map(|p| V::new((p[0] - 0.5) * 0.4, (p[1] - 0.5) * 0.4, (p[2] - 1.0) * 0.1))
    .collect();
    let t: Vec<[u32; 3]> = vec![
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ];
    assert!(volume(&v, &t) > 0.0);
    let pose = Isometry3::identity();
    let vel = V::new(0.3, 0.0, 0.0);
    let sheet_pose = Isometry3::translation(-0.12, -0.12, 0.006 + 0.002 + 0.004);
    let mut rigid = sheet([0.24, 0.24], 0.015, sheet_pose, &f, dt);
    let mut ob = Obstacle::new(
        "box",
        ShapeSpec::Triangles {
            vertices: v.iter().map(|p| [p.x, p.y, p.z]).collect(),
            triangles: t.clone(),
        },
        pose,
        0.006,
        0.5,
    )
    .unwrap();
    ob.linear_velocity = vel;
    rigid.add_obstacle(ob);
    let mut moved = sheet([0.24, 0.24], 0.015, sheet_pose, &f, dt);
    let motion = rigid_frames(&v, 30.0, 1.0, |s| Isometry3::translation(0.3 * s, 0.0, 0.0));
    moved.add_obstacle(
        Obstacle::with_motion("box", t, motion, false, 0.0, pose, 0.006, 0.5).unwrap(),
    );
    let mut worst: f64 = 0.0;
    let mut contacts = 0;
    for _ in 0..150 {
        let a = rigid.step().unwrap();
        let b = moved.step().unwrap();
        assert_eq!(a.contacts, b.contacts, "t = {}", rigid.time);
        contacts = contacts.max(a.contacts);
        for (p, q) in rigid.cloth.positions().iter().zip(moved.cloth.positions()) {
            worst = worst.max((p - q).norm());
        }
    }
    // the cloth was carried: its centre moved along x with the capsule
    let cx = |s: &Simulation| {
        s.cloth.positions().iter().map(|p| p.x).sum::<f64>() / s.cloth.len() as f64
    };
    println!(
        "rigid vs deforming: max vertex distance {worst:.3e} m over 150 steps, up to {contacts} \
         contacts, cloth centre x {:.4} m vs {:.4} m",
        cx(&rigid),
        cx(&moved)
    );
    assert!(contacts > 200, "the sheet never lay on the box");
    assert!(cx(&rigid) > 0.05, "friction did not carry the sheet");
    assert!(worst < 1e-6, "the cloths are {worst} m apart");
}

/// A capsule (radius 4 cm, as 24 × 2·6 triangles, inscribed) rising at
/// 2 m/s into a falling sheet at dt = 1/120 s (1.7 cm a step, three times
/// the contact distance): no cloth vertex is ever within the capsule's
/// inscribed radius of its segment (checked from the segment, not the mesh).
#[test]
fn a_capsule_at_2_m_s_does_not_go_through_the_sheet() {
    let f = fixture();
    let dt = 1.0 / 120.0;
    let (r, half, seg, rings) = (0.04, 0.12, 24, 6);
    let (v, t) = capsule_mesh(half, r, seg, rings);
    assert!(volume(&v, &t) > 0.0);
    let mut sim = sheet(
        [0.3, 0.3],
        0.01,
        Isometry3::translation(-0.15, -0.15, 0.0),
        &f,
        dt,
    );
    let speed = 2.0;
    let z0 = -0.08;
    let motion = rigid_frames(&v, 60.0, 0.3, |s| {
        Isometry3::translation(0.0, 0.0, z0 + speed * s)
    });
    sim.add_obstacle(
        Obstacle::with_motion(
            "capsule",
            t,
            motion,
            false,
            0.0,
            Isometry3::identity(),
            0.003,
            0.3,
        )
        .unwrap(),
    );
    // the inscribed radius: the faces' planes are no nearer the segment
    // than r cos of half the largest angular diagonal of a band's quad
    let dphi = 2.0 * PI / seg as f64;
    let dth = PI / 2.0 / rings as f64;
    let r_in = r * ((dphi * dphi + dth * dth).sqrt() / 2.0).cos();
    let mut clearance = f64::INFINITY;
    let mut lifted = 0.0;
    for _ in 0..30 {
        sim.step().unwrap();
        let zc = z0 + speed * sim.time.min(0.3);
        let (a, b) = (V::new(0.0, -half, zc), V::new(0.0, half, zc));
        for (i, p) in sim.cloth.positions().iter().enumerate() {
            let d = to_segment(p, &a, &b);
            assert!(
                d >= r_in,
                "step {}: vertex {i} at {p:?} is {:.2} mm inside the capsule",
                sim.steps,
                (r_in - d) * 1e3
            );
            clearance = clearance.min(d - r);
        }
        lifted = sim
            .cloth
            .positions()
            .iter()
            .map(|p| p.z)
            .fold(f64::NEG_INFINITY, f64::max);
    }
    println!(
        "capsule at 2 m/s: smallest clearance {:.2} mm from the true capsule (inscribed radius \
         {:.2} mm less), sheet's top at {lifted:.3} m",
        clearance * 1e3,
        (r - r_in) * 1e3
    );
    // the capsule went 0.6 m up through where the sheet was: it carried it
    assert!(lifted > 0.3, "the sheet was not lifted: top at {lifted} m");
}

/// A capsule standing upright (radius 4 cm) swept horizontally at 2 m/s
/// through a curtain hanging from its two top corners, at dt = 1/120 s, to
/// 32 cm past it: the curtain is pushed into a pocket round the capsule and no
/// vertex is ever within the capsule's inscribed radius of its segment.
#[test]
fn a_capsule_swept_at_2_m_s_through_a_curtain_does_not_go_through() {
    use garment_sim::solver::{Pin, PinPath};
    let f = fixture();
    let dt = 1.0 / 120.0;
    let (r, half, seg, rings) = (0.04, 0.05, 24, 6);
    let (v, t) = capsule_mesh(half, r, seg, rings);
    // the curtain in the plane x = 0: warp along y, weft along z
    let basis = Rotation3::from_basis_unchecked(&[V::y(), V::z(), V::x()]);
    let mut sim = sheet(
        [0.3, 0.3],
        0.01,
        Isometry3::from_parts(
            Translation3::new(0.0, -0.15, 0.0),
            UnitQuaternion::from_rotation_matrix(&basis),
        ),
        &f,
        dt,
    );
    let (nx, ny) = (sim.cloth.nx, sim.cloth.ny);
    let pins = [(0, ny - 1), (nx - 1, ny - 1)]
        .iter()
        .map(|&(i, j)| {
            let k = sim.cloth.index(i, j).unwrap();
            Pin::new(k, PinPath::Fixed(sim.cloth.positions()[k]))
        })
        .collect();
    sim.set_pins(pins).unwrap();
    // the capsule's axis (local y) turned to z, centred at mid-height
    let (speed, x0, z) = (2.0, -0.08, 0.12);
    let up = UnitQuaternion::from_axis_angle(&V::x_axis(), PI / 2.0);
    let motion = rigid_frames(&v, 60.0, 0.2, |s| {
        Isometry3::from_parts(Translation3::new(x0 + speed * s, 0.0, z), up)
    });
    sim.add_obstacle(
        Obstacle::with_motion(
            "capsule",
            t,
            motion,
            false,
            0.0,
            Isometry3::identity(),
            0.003,
            0.3,
        )
        .unwrap(),
    );
    let dphi = 2.0 * PI / seg as f64;
    let dth = PI / 2.0 / rings as f64;
    let r_in = r * ((dphi * dphi + dth * dth).sqrt() / 2.0).cos();
    let mut clearance = f64::INFINITY;
    let mut pushed: f64 = 0.0;
    for _ in 0..24 {
        sim.step().unwrap();
        let xc = x0 + speed * sim.time.min(0.2);
        let (a, b) = (V::new(xc, 0.0, z - half), V::new(xc, 0.0, z + half));
        for (i, p) in sim.cloth.positions().iter().enumerate() {
            let d = to_segment(p, &a, &b);
            assert!(
                d >= r_in,
                "step {}: vertex {i} at {p:?} is {:.2} mm inside the capsule",
                sim.steps,
                (r_in - d) * 1e3
            );
            clearance = clearance.min(d - r);
        }
        pushed = sim
            .cloth
            .positions()
            .iter()
            .map(|p| p.x)
            .fold(f64::NEG_INFINITY, f64::max);
    }
    println!(
        "capsule through a curtain at 2 m/s: smallest clearance {:.2} mm, the curtain pushed to \
         x = {pushed:.3} m",
        clearance * 1e3
    );
    // the capsule ended 0.32 m past the curtain
    assert!(
        pushed > 0.2,
        "the curtain was not pushed: x up to {pushed} m"
    );
}

/// Builds a glTF 2.0 file (JSON with one base64 buffer) in memory.
#[derive(Default)]
struct GltfBuilder {
    bin: Vec<u8>,
    views: Vec<serde_json::Value>,
    accessors: Vec<serde_json::Value>,
}

impl GltfBuilder {
    fn push(
        &mut self,
        bytes: &[u8],
        kind: &str,
        ctype: u32,
        count: usize,
        extra: serde_json::Value,
    ) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.views.push(serde_json::json!({
            "buffer": 0, "byteOffset": offset, "byteLength": bytes.len()
        }));
        let mut a = serde_json::json!({
            "bufferView": self.views.len() - 1,
            "componentType": ctype,
            "count": count,
            "type": kind
        });
        if let (Some(a), Some(e)) = (a.as_object_mut(), extra.as_object()) {
            for (k, v) in e {
                a.insert(k.clone(), v.clone());
            }
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }
    fn f32s(&mut self, data: &[f32], kind: &str, count: usize) -> usize {
        let b: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.push(&b, kind, 5126, count, serde_json::json!({}))
    }
    fn positions(&mut self, p: &[[f32; 3]]) -> usize {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for q in p {
            for k in 0..3 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
        let b: Vec<u8> = p.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        self.push(
            &b,
            "VEC3",
            5126,
            p.len(),
            serde_json::json!({"min": lo, "max": hi}),
        )
    }
    fn times(&mut self, t: &[f32]) -> usize {
        let b: Vec<u8> = t.iter().flat_map(|x| x.to_le_bytes()).collect();
        let lo = t.iter().cloned().fold(f32::INFINITY, f32::min);
        let hi = t.iter().cloned().fold(f32::NEG_INFINITY, f32::max);
        self.push(
            &b,
            "SCALAR",
            5126,
            t.len(),
            serde_json::json!({"min": [lo], "max": [hi]}),
        )
    }
    fn joints(&mut self, j: &[[u16; 4]]) -> usize {
        let b: Vec<u8> = j.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        self.push(&b, "VEC4", 5123, j.len(), serde_json::json!({}))
    }
    fn indices(&mut self, t: &[[u32; 3]]) -> usize {
        let b: Vec<u8> = t.iter().flatten().flat_map(|x| x.to_le_bytes()).collect();
        self.push(&b, "SCALAR", 5125, 3 * t.len(), serde_json::json!({}))
    }
    /// The file: its `nodes`, one `mesh`, one `skin`, one animation of
    /// `samplers` and `channels`, the scene's `roots`.
    #[allow(clippy::too_many_arguments)] // the parts of a glTF document
    fn write(
        &self,
        path: &Path,
        nodes: serde_json::Value,
        mesh: serde_json::Value,
        skin: serde_json::Value,
        samplers: serde_json::Value,
        channels: serde_json::Value,
        roots: &[usize],
    ) {
        use base64::Engine;
        let uri = format!(
            "data:application/octet-stream;base64,{}",
            base64::engine::general_purpose::STANDARD.encode(&self.bin)
        );
        let doc = serde_json::json!({
            "asset": {"version": "2.0"},
            "scene": 0,
            "scenes": [{"nodes": roots}],
            "nodes": nodes,
            "meshes": [mesh],
            "skins": [skin],
            "animations": [{"name": "bend", "samplers": samplers, "channels": channels}],
            "buffers": [{"byteLength": self.bin.len(), "uri": uri}],
            "bufferViews": self.views,
            "accessors": self.accessors,
        });
        std::fs::write(path, serde_json::to_string_pretty(&doc).unwrap()).unwrap();
    }
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("garment_sim_moving_body_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

/// An arm in glTF's axes (Y up): a closed cylinder of radius `r` along +x
/// from 0 to 0.6 m, `seg` around; joint 0 at the shoulder (origin), joint 1
/// at the elbow (x = 0.3), its rotation about z keyed by `keys` (time,
/// angle in rad) with `interp`. Weights: all on joint 0 for x ≤ 0.25, all
/// on joint 1 for x ≥ 0.35, linear between. Returns the file.
fn arm_gltf(name: &str, r: f64, seg: usize, keys: &[(f32, f64)], interp: &str) -> PathBuf {
    let xs: Vec<f64> = (0..=24).map(|k| 0.025 * k as f64).collect();
    let mut pos: Vec<[f32; 3]> = Vec::new();
    let mut joints = Vec::new();
    let mut weights: Vec<f32> = Vec::new();
    let w1 = |x: f64| ((x - 0.25) / 0.1).clamp(0.0, 1.0);
    for &x in &xs {
        for j in 0..seg {
            let phi = 2.0 * PI * j as f64 / seg as f64;
            pos.push([x as f32, (r * phi.cos()) as f32, (r * phi.sin()) as f32]);
            joints.push([0u16, 1, 0, 0]);
            let w = w1(x) as f32;
            weights.extend([1.0 - w, w, 0.0, 0.0]);
        }
    }
    // cap centres
    for x in [0.0, 0.6] {
        pos.push([x as f32, 0.0, 0.0]);
        joints.push([0, 1, 0, 0]);
        let w = w1(x) as f32;
        weights.extend([1.0 - w, w, 0.0, 0.0]);
    }
    let ring = |k: usize, j: usize| (k * seg + j % seg) as u32;
    let (c0, c1) = ((xs.len() * seg) as u32, (xs.len() * seg + 1) as u32);
    let mut tris = Vec::new();
    // the ring at angle phi has outward direction (0, cos, sin): faces
    // (a, b, c) with (b − a) × (c − a) outward
    for k in 0..xs.len() - 1 {
        for j in 0..seg {
            let (a, b, c, d) = (
                ring(k, j),
                ring(k, j + 1),
                ring(k + 1, j),
                ring(k + 1, j + 1),
            );
            tris.push([a, b, c]);
            tris.push([b, d, c]);
        }
    }
    let last = xs.len() - 1;
    for j in 0..seg {
        tris.push([c0, ring(0, j + 1), ring(0, j)]);
        tris.push([c1, ring(last, j), ring(last, j + 1)]);
    }
    let mut g = GltfBuilder::default();
    let p = g.positions(&pos);
    let jo = g.joints(&joints);
    let we = g.f32s(&weights, "VEC4", pos.len());
    let ix = g.indices(&tris);
    // inverse bind matrices (column-major): identity, and translation by −0.3 x
    let mut ibm = vec![0f32; 32];
    for k in 0..4 {
        ibm[k * 5] = 1.0;
        ibm[16 + k * 5] = 1.0;
    }
    ibm[16 + 12] = -0.3;
    let ib = g.f32s(&ibm, "MAT4", 2);
    let times: Vec<f32> = keys.iter().map(|k| k.0).collect();
    let ti = g.times(&times);
    let rots: Vec<f32> = keys
        .iter()
        .flat_map(|&(_, a)| [0.0, 0.0, (a / 2.0).sin() as f32, (a / 2.0).cos() as f32])
        .collect();
    let ro = g.f32s(&rots, "VEC4", keys.len());
    let path = scratch(name);
    g.write(
        &path,
        serde_json::json!([
            {"name": "shoulder", "children": [1]},
            {"name": "elbow", "translation": [0.3, 0.0, 0.0]},
            {"name": "arm", "mesh": 0, "skin": 0}
        ]),
        serde_json::json!({"primitives": [{
            "attributes": {"POSITION": p, "JOINTS_0": jo, "WEIGHTS_0": we},
            "indices": ix
        }]}),
        serde_json::json!({"joints": [0, 1], "inverseBindMatrices": ib}),
        serde_json::json!([{"input": ti, "output": ro, "interpolation": interp}]),
        serde_json::json!([{"sampler": 0, "target": {"node": 1, "path": "rotation"}}]),
        &[0, 2],
    );
    path
}

/// Linear blend skinning against its closed form: a vertex bound to the
/// elbow alone turns with it about the elbow; one bound half to each joint
/// lands half way between the two joints' images; LINEAR keys slerp (the
/// angle half way at half time), STEP keys hold; the output turned Z up.
#[test]
fn linear_blend_skinning_matches_the_closed_form() {
    let angle = PI / 2.0;
    let path = arm_gltf("lbs.gltf", 0.04, 8, &[(0.0, 0.0), (1.0, angle)], "LINEAR");
    let (tris, sk) = garment_sim::scene::motion::load_gltf(&path, Some("bend"), 1.0).unwrap();
    assert_eq!(sk.vertex_count(), 25 * 8 + 2);
    assert!(
        garment_sim::collision::is_closed(&tris),
        "welded arm not closed"
    );
    assert!((sk.duration() - 1.0).abs() < 1e-12);
    let seg = 8;
    let elbow = V::new(0.3, 0.0, 0.0);
    for (t, th) in [(0.0, 0.0), (0.5, angle / 2.0), (1.0, angle), (2.0, angle)] {
        let p = sk.positions_y_up(t);
        let rot = Rotation3::from_axis_angle(&V::z_axis(), th);
        // ring 20 (x = 0.5): all on the elbow joint
        for j in 0..seg {
            let k = 20 * seg + j;
            let phi = 2.0 * PI * j as f64 / seg as f64;
            let rest = V::new(0.5, 0.04 * phi.cos(), 0.04 * phi.sin());
            let want = elbow + rot * (rest - elbow);
            assert!((p[k] - want).norm() < 1e-6, "t {t}: {} vs {want}", p[k]);
        }
        // ring 12 (x = 0.3): weights 0.5 / 0.5, the mean of the two images
        for j in 0..seg {
            let k = 12 * seg + j;
            let phi = 2.0 * PI * j as f64 / seg as f64;
            let rest = V::new(0.3, 0.04 * phi.cos(), 0.04 * phi.sin());
            let want = (rest + (elbow + rot * (rest - elbow))) / 2.0;
            assert!((p[k] - want).norm() < 1e-6, "t {t}: {} vs {want}", p[k]);
        }
        // ring 2 (x = 0.05): the shoulder's, which does not move
        let k = 2 * seg + 3;
        let phi = 2.0 * PI * 3.0 / seg as f64;
        let rest = V::new(0.05, 0.04 * phi.cos(), 0.04 * phi.sin());
        assert!((p[k] - rest).norm() < 1e-6);
    }
    // Z up: (x, y, z) → (x, −z, y)
    let mut out = vec![V::zeros(); sk.vertex_count()];
    sk.positions(0.5, &mut out);
    let y = sk.positions_y_up(0.5);
    for (a, b) in out.iter().zip(&y) {
        assert!((a - V::new(b.x, -b.z, b.y)).norm() < 1e-12);
    }
    // STEP: the first key's pose until the second key
    let step = arm_gltf("step.gltf", 0.04, 8, &[(0.0, 0.0), (1.0, angle)], "STEP");
    let (_, st) = garment_sim::scene::motion::load_gltf(&step, None, 1.0).unwrap();
    let tip = 24 * seg;
    assert!((st.positions_y_up(0.99)[tip] - V::new(0.6, 0.04, 0.0)).norm() < 1e-6);
    let up = elbow + Rotation3::from_axis_angle(&V::z_axis(), angle) * V::new(0.3, 0.04, 0.0);
    assert!((st.positions_y_up(1.0)[tip] - up).norm() < 1e-6);
    // a matrix check: the joint matrix of a rotation of 30° about z
    let q = UnitQuaternion::from_axis_angle(&V::z_axis(), PI / 6.0);
    let m = Matrix4::new_translation(&elbow) * q.to_homogeneous();
    let r = m * nalgebra::Vector4::new(0.5 - 0.3, 0.04, 0.0, 1.0);
    let third = sk.positions_y_up(1.0 / 3.0);
    assert!(
        (third[20 * seg] - r.xyz()).norm() < 1e-6,
        "{} vs {}",
        third[20 * seg],
        r.xyz()
    );
}

/// The skinned arm (radius 4 cm, 24 around) bending its elbow 90° in 0.2 s
/// (the wrist at 2.4 m/s) up into a sheet lying 1 cm above the forearm, at
/// dt = 1/120 s: no cloth vertex ever inside the arm's rigid parts (the
/// upper arm up to 5 cm from the elbow, the forearm from 5 cm past it),
/// checked from the closed form of the bend, not from the mesh.
#[test]
fn a_bending_arm_does_not_go_through_the_sheet() {
    let (r, seg) = (0.04, 24);
    let bend = 0.2;
    let path = arm_gltf(
        "arm.gltf",
        r,
        seg,
        &[(0.0, 0.0), (bend as f32, PI / 2.0)],
        "LINEAR",
    );
    let (tris, sk) = garment_sim::scene::motion::load_gltf(&path, None, 1.0).unwrap();
    let f = fixture();
    let dt = 1.0 / 120.0;
    let mut sim = sheet(
        [0.3, 0.3],
        0.01,
        Isometry3::translation(0.32, -0.15, r + 0.01),
        &f,
        dt,
    );
    sim.add_obstacle(
        Obstacle::with_motion(
            "arm",
            tris,
            Arc::new(sk),
            false,
            0.0,
            Isometry3::identity(),
            0.003,
            0.3,
        )
        .unwrap(),
    );
    let r_in = r * (PI / seg as f64).cos();
    let elbow = V::new(0.3, 0.0, 0.0);
    let mut clearance = f64::INFINITY;
    let mut hit = 0;
    for _ in 0..36 {
        sim.step().unwrap();
        // in sim axes the elbow turns the forearm from +x towards +z
        let th = PI / 2.0 * (sim.time / bend).min(1.0);
        let dir = V::new(th.cos(), 0.0, th.sin());
        for (i, p) in sim.cloth.positions().iter().enumerate() {
            let upper = (p.x >= 0.0 && p.x <= 0.25).then(|| (p.y * p.y + p.z * p.z).sqrt());
            let s = (p - elbow).dot(&dir);
            let fore = (0.05..=0.3)
                .contains(&s)
                .then(|| (p - elbow - dir * s).norm());
            for d in [upper, fore].into_iter().flatten() {
                assert!(
                    d >= r_in,
                    "step {}: vertex {i} at {p:?} is {:.2} mm inside the arm",
                    sim.steps,
                    (r_in - d) * 1e3
                );
                clearance = clearance.min(d - r);
            }
        }
        hit = hit.max(sim.last.contacts);
    }
    let top = sim
        .cloth
        .positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::NEG_INFINITY, f64::max);
    println!(
        "bending arm: smallest clearance {:.2} mm, up to {hit} contacts, sheet's top at {top:.3} m",
        clearance * 1e3
    );
    assert!(hit > 10, "the forearm never met the sheet");
    assert!(top > 0.2, "the sheet was not flung up: top at {top} m");
}

/// A tube of cloth (circumference 0.9 m, closed by a seam) settled on a
/// body shaped as a cone frustum, the body then turning about the vertical,
/// its rate ramped up over half a second (frames 60 a second, the deforming
/// path), the fabric's own air damping (7 /s on the absolute velocity):
/// after the transient, the cloth's mean angular velocity about the axis
/// (the mass-weighted mean of its vertices' unwrapped turn over 2 s, divided
/// by 2 s) is the body's within 0.5 % (the issue asks 5 %), and so is its
/// rate over every quarter second of those 2 s; most contacts stick. Two
/// bodies: elliptic (a skirt on hips, half as deep as wide) at 0.5 rad/s, and
/// round at 1 rad/s, where nothing but friction can carry the tube round:
/// static friction holds the hem and carries it at the rate of the points
/// where the cloth vertices ride, the contact distance above the skin.
#[test]
fn a_tube_on_a_turning_body_follows_it() {
    for (depth, omega) in [(0.5, 0.5), (1.0, 1.0)] {
        tube_on_a_turning_frustum(depth, omega);
    }
}

/// The tube of [`a_tube_on_a_turning_body_follows_it`] on the frustum whose
/// depth is `depth` times its width, turning at `omega` rad/s.
fn tube_on_a_turning_frustum(depth: f64, omega: f64) {
    let f = fixture();
    let dt = 1.0 / 120.0;
    // the body: a closed frustum, half-axes 0.22 × 0.22 depth m at z = 0.1
    // to 0.1 × 0.1 depth m at 0.7
    let seg = 64;
    let rad = |z: f64| 0.22 - 0.12 * (z - 0.1) / 0.6;
    let zs: Vec<f64> = (0..=12).map(|k| 0.1 + 0.05 * k as f64).collect();
    let mut bv = Vec::new();
    for &z in &zs {
        for j in 0..seg {
            let phi = 2.0 * PI * j as f64 / seg as f64;
            bv.push(V::new(rad(z) * phi.cos(), depth * rad(z) * phi.sin(), z));
        }
    }
    bv.push(V::new(0.0, 0.0, 0.1));
    bv.push(V::new(0.0, 0.0, 0.7));
    let ring = |k: usize, j: usize| (k * seg + j % seg) as u32;
    let (c0, c1) = ((zs.len() * seg) as u32, (zs.len() * seg + 1) as u32);
    let mut bt = Vec::new();
    for k in 0..zs.len() - 1 {
        for j in 0..seg {
            let (a, b, c, d) = (
                ring(k, j),
                ring(k, j + 1),
                ring(k + 1, j),
                ring(k + 1, j + 1),
            );
            bt.push([a, b, d]);
            bt.push([a, d, c]);
        }
    }
    for j in 0..seg {
        bt.push([c0, ring(0, j + 1), ring(0, j)]);
        bt.push([c1, ring(zs.len() - 1, j), ring(zs.len() - 1, j + 1)]);
    }
    assert!(volume(&bv, &bt) > 0.0);
    let start = 0.8;
    // the turn's rate ramps up over the first half second (a body starting
    // to turn), then holds at omega
    let ramp = 0.5;
    let turn_angle = move |s: f64| {
        if s < ramp {
            omega * s * s / (2.0 * ramp)
        } else {
            omega * (s - ramp / 2.0)
        }
    };
    let motion = rigid_frames(&bv, 60.0, 4.0, |s| {
        Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&V::z_axis(), turn_angle(s)),
        )
    });
    // the tube: a grid wrapped round the axis, its first and last columns
    // on one line and stitched together
    let spacing = 0.02;
    let nx = 46;
    let w = spacing * (nx - 1) as f64;
    let radius = w / (2.0 * PI);
    let z0 = 0.53;
    let grid = GridSpec {
        size: [w, 0.14],
        spacing: [spacing, spacing],
        pose: Isometry3::identity(),
    };
    let mut cloth = Cloth::grid(&grid, f.areal_mass).unwrap();
    assert_eq!(cloth.nx, nx);
    let x: Vec<V> = (cloth.material.iter())
        .map(|&[u, v]| {
            let a = 2.0 * PI * u / w;
            V::new(radius * a.cos(), radius * a.sin(), z0 + v)
        })
        .collect();
    cloth.set_positions(&x).unwrap();
    let stitches: Vec<Stitch> = (0..cloth.ny)
        .map(|j| {
            let (a, b) = (cloth.index(0, j).unwrap(), cloth.index(nx - 1, j).unwrap());
            Stitch {
                v: [a, b, b],
                c: [1.0, -1.0, 0.0],
                k: 400.0,
                d: 1.0,
            }
        })
        .collect();
    cloth.add_seams(&stitches).unwrap();
    let mut sim = Simulation::new(
        cloth,
        f,
        Params {
            dt,
            ..Params::default()
        },
    )
    .unwrap();
    sim.add_obstacle(
        Obstacle::with_motion(
            "body",
            bt,
            motion,
            false,
            start,
            Isometry3::identity(),
            0.003,
            0.8,
        )
        .unwrap(),
    );
    // each vertex's angle about the axis, unwrapped step by step: the tube's
    // turn over the window is their mass-weighted mean change
    let angle = |p: &V| p.y.atan2(p.x);
    let mut turned = vec![0.0; sim.cloth.len()];
    let mut last: Vec<f64> = sim.cloth.positions().iter().map(angle).collect();
    let window = (start + 1.0, start + 3.0);
    let m: f64 = sim.cloth.mass.iter().sum();
    // the rate over each quarter second of the window, and the contacts
    // static friction held over the window
    let quarter = (0.25 / dt).round() as usize;
    let mut part = vec![0.0; sim.cloth.len()];
    let mut rates = Vec::new();
    let (mut stuck, mut contacts, mut steps) = (0, 0, 0);
    while sim.time < window.1 - 1e-9 {
        let stats = sim.step().unwrap();
        let inside = sim.time > window.0 + 1e-9;
        for (k, p) in sim.cloth.positions().iter().enumerate() {
            let a = angle(p);
            let d = (a - last[k] + PI).rem_euclid(2.0 * PI) - PI;
            if inside {
                turned[k] += d;
                part[k] += d;
            }
            last[k] = a;
        }
        if inside {
            stuck += stats.stuck;
            contacts += stats.contacts;
            steps += 1;
            if steps % quarter == 0 {
                let t: f64 = part.iter().zip(&sim.cloth.mass).map(|(t, w)| t * w).sum();
                rates.push(t / m / (quarter as f64 * dt));
                part.iter_mut().for_each(|t| *t = 0.0);
            }
        }
    }
    let turn: f64 = turned
        .iter()
        .zip(&sim.cloth.mass)
        .map(|(t, w)| t * w)
        .sum::<f64>()
        / m;
    let mean = turn / (window.1 - window.0);
    let rest_z = sim
        .cloth
        .positions()
        .iter()
        .map(|p| p.z)
        .fold(f64::INFINITY, f64::min);
    println!(
        "body {depth} times as deep as wide turning at {omega} rad/s: the tube's mean angular velocity {mean:.4} rad/s over the \
         {:.0} s from {:.1} s ({:+.2} %), per quarter second {:.4?} rad/s; contacts stuck {stuck} \
         of {contacts}; its hem at {rest_z:.3} m",
        window.1 - window.0,
        window.0,
        100.0 * (mean / omega - 1.0),
        rates
    );
    // the tube rests on the body (its hem where the body is wider than it)
    assert!(rest_z > 0.15 && rest_z < z0, "hem at {rest_z} m");
    assert!(
        (mean / omega - 1.0).abs() < 0.005,
        "the tube turns at {mean} rad/s, the body at {omega}"
    );
    assert_eq!(rates.len(), 8);
    for r in &rates {
        assert!(
            (r / omega - 1.0).abs() < 0.005,
            "the tube turns at {r} rad/s over a quarter second: {rates:?}"
        );
    }
    assert!(2 * stuck > contacts, "{stuck} of {contacts} contacts stuck");
}

/// Runs a trial's phases to their end, with no progress.
fn run_quietly(
    sim: &mut Simulation,
    t: &garment_sim::trial::Trial,
) -> garment_sim::trial::RunStats {
    garment_sim::trial::run(
        sim,
        &t.file.sewing,
        &t.file.settle,
        None,
        &mut garment_sim::run::run_on,
    )
    .unwrap()
}

/// Writes a tetrahedron moved by `d` as an OBJ file; `extra` lines appended.
fn tetra_obj(path: &Path, d: V, extra: &str) {
    let v = [
        [0.0, 0.0, 0.0],
        [0.1, 0.0, 0.0],
        [0.0, 0.1, 0.0],
        [0.0, 0.0, 0.1],
    ];
    let mut s = String::new();
    for p in v {
        s += &format!("v {} {} {}\n", p[0] + d.x, p[1] + d.y, p[2] + d.z);
    }
    s += "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
    s += extra;
    std::fs::write(path, s).unwrap();
}

/// A mesh sequence read from a pattern (frames in the order of their
/// numbers, f_2 before f_10), interpolated between frames; frames whose
/// vertex count, faces or coordinates are wrong refused, naming the file.
#[test]
fn mesh_sequences_are_read_in_order_and_bad_frames_refused() {
    let dir = scratch("seq");
    std::fs::create_dir_all(&dir).unwrap();
    for (k, n) in [1, 2, 10].iter().enumerate() {
        tetra_obj(
            &dir.join(format!("f_{n}.obj")),
            V::new(0.0, 0.0, 0.1 * k as f64),
            "",
        );
    }
    let files = garment_sim::scene::motion::expand_pattern(&dir.join("f_*.obj")).unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().to_string())
        .collect();
    assert_eq!(names, ["f_1.obj", "f_2.obj", "f_10.obj"]);
    let m = garment_sim::scene::motion::load_frames(&files, 10.0, 2.0).unwrap();
    assert_eq!(m.triangles.len(), 4);
    assert!((m.motion.duration() - 0.2).abs() < 1e-12);
    let mut out = vec![V::zeros(); 4];
    // 0.15 s: half way from f_2 (up 0.1) to f_10 (up 0.2), scaled by 2
    m.motion.positions(0.15, &mut out);
    assert!(
        (out[3] - V::new(0.0, 0.0, 2.0 * (0.1 + 0.15))).norm() < 1e-12,
        "{}",
        out[3]
    );
    // a frame with an extra vertex, one with other faces, one not finite
    let bad = dir.join("bad");
    std::fs::create_dir_all(&bad).unwrap();
    tetra_obj(&bad.join("a.obj"), V::zeros(), "");
    tetra_obj(&bad.join("b.obj"), V::zeros(), "v 1 1 1\n");
    let err =
        garment_sim::scene::motion::load_frames(&[bad.join("a.obj"), bad.join("b.obj")], 30.0, 1.0)
            .unwrap_err();
    let msg = format!("{err:#}");
    assert!(msg.contains("b.obj") && msg.contains("5 vertices"), "{msg}");
    std::fs::write(
        bad.join("c.obj"),
        std::fs::read_to_string(bad.join("a.obj"))
            .unwrap()
            .replace("f 2 3 4", "f 2 4 3"),
    )
    .unwrap();
    let err =
        garment_sim::scene::motion::load_frames(&[bad.join("a.obj"), bad.join("c.obj")], 30.0, 1.0)
            .unwrap_err();
    let msg = format!("{err:#}");
    assert!(msg.contains("c.obj") && msg.contains("topology"), "{msg}");
    std::fs::write(
        bad.join("d.obj"),
        std::fs::read_to_string(bad.join("a.obj"))
            .unwrap()
            .replace("v 0.1 0 0", "v nan 0 0"),
    )
    .unwrap();
    let err =
        garment_sim::scene::motion::load_frames(&[bad.join("a.obj"), bad.join("d.obj")], 30.0, 1.0)
            .unwrap_err();
    let msg = format!("{err:#}");
    assert!(msg.contains("d.obj") && msg.contains("finite"), "{msg}");
}

/// A scene file whose obstacle has a `motion`: the body's vertices are
/// where the frames put them at each step, and its surface velocity is the
/// frames' rate of change.
#[test]
fn a_scene_obstacle_follows_its_frames() {
    let dir = scratch("scene");
    std::fs::create_dir_all(dir.join("frames")).unwrap();
    // a tetrahedron rising 0.1 m a frame at 10 frames/s (1 m/s), far below
    // the cloth
    for k in 0..4 {
        tetra_obj(
            &dir.join(format!("frames/t_{k:03}.obj")),
            V::new(0.0, 0.0, -1.0 + 0.1 * k as f64),
            "",
        );
    }
    let fabric = std::fs::canonicalize("tests/data/acrylic_test.yaml").unwrap();
    let yaml = format!(
        "cloth: {{fabric: {}, size: [0.1, 0.1], spacing: 0.05}}\n\
         obstacles:\n  - id: body\n    motion: {{frames: frames/t_*.obj, fps: 10, start: 0.05}}\n\
         dt: 0.01\nduration: 0.2\n",
        fabric.display()
    );
    let path = dir.join("scene.yaml");
    std::fs::write(&path, yaml).unwrap();
    let scene = garment_sim::scene::Scene::load(&path).unwrap();
    let mut sim = scene.build(&Default::default()).unwrap();
    for _ in 0..20 {
        sim.step().unwrap();
        let ob = &sim.obstacles()[0];
        let b = ob.deforming().unwrap();
        // held until 0.05 s, then up 1 m/s until the last frame (0.3 s)
        let t = (sim.time - 0.05).clamp(0.0, 0.3);
        let want = -1.0 + t;
        assert!(
            (b.positions()[0].z - want).abs() < 1e-9,
            "t {}: {}",
            sim.time,
            b.positions()[0].z
        );
        let v = b.velocities()[0].z;
        let expect = if sim.time > 0.05 + 1e-9 { 1.0 } else { 0.0 };
        assert!((v - expect).abs() < 1e-6, "t {}: velocity {v}", sim.time);
    }
    // a shape and a motion together are refused
    let both = std::fs::read_to_string(&path).unwrap().replace(
        "    motion:",
        "    shape: {type: sphere, radius: 0.1}\n    motion:",
    );
    std::fs::write(&path, both).unwrap();
    let err = garment_sim::scene::Scene::load(&path)
        .and_then(|s| s.build(&Default::default()))
        .unwrap_err();
    assert!(format!("{err:#}").contains("not both"), "{err:#}");
}

/// A trial whose body has a motion: the shipped skirt (3 cm grid) sewn and
/// draped on the shipped body's first pose, then the body sinking 2 cm in
/// 0.2 s (two frames): the motion phase lasts the motion, and the skirt,
/// hanging on the hips, ends 2 cm lower than on the body standing still
/// (mean height of its vertices, within 3 mm), no vertex inside the body
/// where it is now (nor in the fit report, which measures against it).
#[test]
fn a_trial_body_with_a_motion_carries_the_garment() {
    use garment_sim::trial::{self, Overrides, Trial};
    let dir = scratch("trial");
    std::fs::create_dir_all(dir.join("frames")).unwrap();
    let root = std::fs::canonicalize(".").unwrap();
    let body = std::fs::read_to_string(root.join("assets/bodies/anny/body.obj")).unwrap();
    for (k, dz) in [0.0, -0.02].iter().enumerate() {
        let mut s = String::new();
        for l in body.lines() {
            if let Some(rest) = l.strip_prefix("v ") {
                let c: Vec<f64> = rest
                    .split_whitespace()
                    .map(|x| x.parse().unwrap())
                    .collect();
                s += &format!("v {} {} {}\n", c[0], c[1], c[2] + dz);
            } else if l.starts_with("f ") {
                s += l;
                s += "\n";
            }
        }
        std::fs::write(dir.join(format!("frames/b_{k}.obj")), s).unwrap();
    }
    let head = format!(
        "garment: {}\nspacing: 0.03\ndt: 0.005\nsettle: {{max_time: 1.0}}\nbody:\n  skin_offset: 0.003\n  \
         friction: 0.5\n",
        root.join("assets/garments/skirt.garment.yaml").display()
    );
    let run = |name: &str, body: &str| {
        let p = dir.join(name);
        std::fs::write(&p, format!("{head}{body}")).unwrap();
        let t = Trial::load(&p).unwrap();
        let (mut sim, g) = t.build(&Overrides::default()).unwrap();
        let st = run_quietly(&mut sim, &t);
        let deepest = sim.obstacles()[0].deepest_inside(sim.cloth.positions());
        let z = sim.cloth.positions().iter().map(|p| p.z).sum::<f64>() / sim.cloth.len() as f64;
        // the fit report measures against the body where it is now
        let (fit, _, _) = trial::fit(&sim, &g, &t, st.clone());
        assert_eq!(fit.body_penetrations, 0, "{name}");
        (st, z, deepest)
    };
    let (still, z_still, _) = run("still.yaml", "  obj: frames/b_0.obj\n");
    let (moved, z_moved, deepest) = run(
        "moved.yaml",
        "  motion: {frames: \"frames/b_*.obj\", fps: 5}\n",
    );
    println!(
        "trial with a motion: motion phase {:?} s, skirt {:.2} cm lower than on the still body",
        moved.motion_s,
        (z_still - z_moved) * 100.0
    );
    assert!(still.motion_s.is_none());
    assert!((moved.motion_s.unwrap() - 0.2).abs() < 0.006);
    assert!(
        deepest.is_none(),
        "a skirt vertex inside the body: {deepest:?}"
    );
    assert!(
        ((z_still - z_moved) - 0.02).abs() < 0.003,
        "the skirt sank {} m with the body's 0.02 m",
        z_still - z_moved
    );
}

/// The shipped motion (assets/bodies/anny/arms_raise.glb) read by our glTF
/// reader and skinned by our linear blend skinning, against the same file
/// evaluated by Blender's glTF importer and armature modifier
/// (tests/data/anny_motion_blender_frames.json, written by
/// tools/blender_eval_motion.py, positions rounded to 0.1 mm).
#[test]
fn the_shipped_motion_skins_as_blender_skins_it() {
    let (tris, skinned) = garment_sim::scene::motion::load_gltf(
        Path::new("assets/bodies/anny/arms_raise.glb"),
        None,
        1.0,
    )
    .unwrap();
    let body = std::fs::read_to_string("assets/bodies/anny/body.obj").unwrap();
    let obj_v = body.lines().filter(|l| l.starts_with("v ")).count();
    let obj_f = body.lines().filter(|l| l.starts_with("f ")).count();
    assert_eq!((skinned.vertex_count(), tris.len()), (obj_v, obj_f));
    let json: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string("tests/data/anny_motion_blender_frames.json").unwrap(),
    )
    .unwrap();
    assert!(
        (skinned.duration() - 3.0).abs() < 1e-9,
        "{}",
        skinned.duration()
    );
    let mut out = vec![Vector3::zeros(); skinned.vertex_count()];
    let mut moved = 0.0f64;
    let first = {
        skinned.positions(0.0, &mut out);
        out.clone()
    };
    for f in json["frames"].as_array().unwrap() {
        let t = f["time_s"].as_f64().unwrap();
        skinned.positions(t, &mut out);
        let theirs = f["vertices"].as_array().unwrap();
        assert_eq!(theirs.len(), out.len());
        let mut worst = 0.0f64;
        for (p, q) in out.iter().zip(theirs) {
            let q = Vector3::new(
                q[0].as_f64().unwrap(),
                q[1].as_f64().unwrap(),
                q[2].as_f64().unwrap(),
            );
            worst = worst.max((p - q).norm());
        }
        moved = moved.max(
            out.iter()
                .zip(&first)
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max),
        );
        println!("t = {t} s: largest distance to Blender's vertex {worst:.2e} m");
        // 0.05 mm rounding per coordinate, Blender's float32
        assert!(worst < 1e-4, "t = {t} s: {worst} m");
    }
    assert!(moved > 0.2, "the hands rise: {moved} m");
}

/// The shipped trial config/trials/tshirt_arms_raise.yaml at 2 cm: the
/// T-shirt sewn and draped on the body in its first pose, then the shipped
/// motion raises the arms 42° to shoulder height. The sleeves go up with the
/// arms (against the same trial on the still body) and no cloth vertex ends
/// inside the body.
#[test]
fn the_tshirt_follows_the_arms_of_the_shipped_motion() {
    use garment_sim::trial::{self, Overrides, Trial};
    let run = |t: &Trial| {
        let (mut sim, g) = t
            .build(&Overrides {
                spacing: Some(0.02),
                threads: Some(1),
                ..Default::default()
            })
            .unwrap();
        let st = run_quietly(&mut sim, t);
        let (fit, _, _) = trial::fit(&sim, &g, t, st.clone());
        (sim, fit, st)
    };
    let moving = Trial::load(Path::new("config/trials/tshirt_arms_raise.yaml")).unwrap();
    let mut still = moving.clone();
    still.body = Trial::load(Path::new("config/trials/tshirt_on_anny.yaml"))
        .unwrap()
        .body;
    still.file.body.motion = None;
    let (s0, _, st0) = run(&still);
    let (s1, fit1, st1) = run(&moving);
    assert!(st0.motion_s.is_none());
    assert!(
        (st1.motion_s.unwrap() - 3.0).abs() < 0.01,
        "{:?}",
        st1.motion_s
    );
    // the sleeves: the vertices more than 20 cm out from the body's axis on the still body
    let sleeve: Vec<usize> = (0..s0.cloth.len())
        .filter(|&i| s0.cloth.positions()[i].x.abs() > 0.2)
        .collect();
    let mean_z = |s: &Simulation| {
        sleeve
            .iter()
            .map(|&i| s.cloth.positions()[i].z)
            .sum::<f64>()
            / sleeve.len() as f64
    };
    let rise = mean_z(&s1) - mean_z(&s0);
    // how far the arm under them rose: the body vertex nearest each sleeve
    // vertex on the still body, from the first pose to the last
    let body = s1.obstacles()[0].deforming().unwrap();
    let mut first = vec![Vector3::zeros(); body.positions().len()];
    body.motion().positions(0.0, &mut first);
    let last = body.positions();
    let arm_rise = sleeve
        .iter()
        .map(|&i| {
            let p = s0.cloth.positions()[i];
            let k = (0..first.len())
                .min_by(|&a, &b| (first[a] - p).norm().total_cmp(&(first[b] - p).norm()))
                .unwrap();
            last[k].z - first[k].z
        })
        .sum::<f64>()
        / sleeve.len() as f64;
    let deepest = s1.obstacles()[0].deepest_inside(s1.cloth.positions());
    println!(
        "T-shirt on the arms raise: {} sleeve vertices rose {:.1} cm, the arm under them {:.1} cm; \
         {} inside the body",
        sleeve.len(),
        rise * 100.0,
        arm_rise * 100.0,
        fit1.body_penetrations
    );
    assert!(sleeve.len() > 20, "{}", sleeve.len());
    assert!(arm_rise > 0.03, "the arm rose {arm_rise} m");
    assert!(
        rise > 0.7 * arm_rise,
        "the sleeves rose {rise} m, the arm under them {arm_rise} m"
    );
    assert!(deepest.is_none(), "{deepest:?}");
    assert_eq!(fit1.body_penetrations, 0);
}

/// Each point's angle about the vertical axis x = y = 0, unwrapped from call
/// to call: `turned` sums each point's change while `counting`.
struct Unwrap {
    last: Vec<f64>,
    turned: Vec<f64>,
}

impl Unwrap {
    fn new(x: &[V]) -> Self {
        Unwrap {
            last: x.iter().map(|p| p.y.atan2(p.x)).collect(),
            turned: vec![0.0; x.len()],
        }
    }
    fn update(&mut self, x: &[V], counting: bool) {
        for (k, p) in x.iter().enumerate() {
            let a = p.y.atan2(p.x);
            if counting {
                self.turned[k] += (a - self.last[k] + PI).rem_euclid(2.0 * PI) - PI;
            }
            self.last[k] = a;
        }
    }
    /// The weighted mean turn of the points where `w` > 0.
    fn mean(&self, w: &[f64]) -> f64 {
        let m: f64 = w.iter().sum();
        self.turned.iter().zip(w).map(|(t, w)| t * w).sum::<f64>() / m
    }
}

/// The shipped motion assets/bodies/anny/turn.glb read by our glTF reader:
/// the body turns about the vertical axis x = y = 0 as a rigid body (every
/// vertex keeps its height and its distance from the axis), its vertices'
/// angle about the axis grows at a rate that ramps up over the first 0.5 s
/// and then holds at 1 rad/s (measured from the vertices at 100 steps a
/// second, each 0.01 s interval within 0.1 %), nothing moves at t = 0.
#[test]
fn the_shipped_turn_turns_at_a_steady_rate() {
    let (tris, turn) =
        garment_sim::scene::motion::load_gltf(Path::new("assets/bodies/anny/turn.glb"), None, 1.0)
            .unwrap();
    let body = std::fs::read_to_string("assets/bodies/anny/body.obj").unwrap();
    let obj: Vec<V> = body
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|r| {
            let c: Vec<f64> = r.split_whitespace().map(|x| x.parse().unwrap()).collect();
            V::new(c[0], c[1], c[2])
        })
        .collect();
    assert_eq!((turn.vertex_count(), tris.len()), (obj.len(), 2454));
    assert!((turn.duration() - 4.0).abs() < 1e-6, "{}", turn.duration());
    let mut x = vec![V::zeros(); obj.len()];
    turn.positions(0.0, &mut x);
    let still = x
        .iter()
        .zip(&obj)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(still < 1e-6, "t = 0: a vertex {still} m from body.obj");
    // the vertices more than 10 cm from the axis: a well-defined angle
    let far: Vec<f64> = obj
        .iter()
        .map(|p| if p.xy().norm() > 0.1 { 1.0 } else { 0.0 })
        .collect();
    let mut un = Unwrap::new(&x);
    let h = 0.01;
    let (mut worst_rigid, mut worst_rate, mut ramp_end_rate) = (0.0f64, 0.0f64, 0.0);
    let mut rates = Vec::new();
    for k in 1..=400 {
        let t = k as f64 * h;
        turn.positions(t, &mut x);
        un.turned.iter_mut().for_each(|a| *a = 0.0);
        un.update(&x, true);
        let rate = un.mean(&far) / h;
        // rigid about the axis: heights and distances from the axis kept
        for (p, q) in x.iter().zip(&obj) {
            worst_rigid = worst_rigid
                .max((p.z - q.z).abs())
                .max((p.xy().norm() - q.xy().norm()).abs());
        }
        // the spread of the rate over the vertices: a rotation turns all alike
        for (a, w) in un.turned.iter().zip(&far) {
            if *w > 0.0 {
                worst_rate = worst_rate.max((a / h - rate).abs());
            }
        }
        if t <= 0.5 + 1e-9 {
            ramp_end_rate = rate;
        } else {
            rates.push(rate);
        }
    }
    let (lo, hi) = rates
        .iter()
        .fold((f64::INFINITY, 0.0f64), |(l, u), r| (l.min(*r), u.max(*r)));
    println!(
        "turn.glb: rate over the last 0.01 s of the ramp {ramp_end_rate:.4} rad/s, after it \
         {lo:.6} to {hi:.6} rad/s; vertices' rates within {worst_rate:.1e} rad/s of their mean, \
         heights and distances from the axis kept within {worst_rigid:.1e} m"
    );
    assert!(worst_rigid < 1e-5, "{worst_rigid}");
    assert!(worst_rate < 1e-3, "{worst_rate}");
    assert!(
        (lo - 1.0).abs() < 1e-4 && (hi - 1.0).abs() < 1e-4,
        "{lo} {hi}"
    );
    // the ramp: the last interval before 0.5 s, at 0.495 s, turns at 0.99 rad/s
    // in the closed form; the keys every 0.05 s make it the chord's 0.95
    assert!(
        ramp_end_rate > 0.9 && ramp_end_rate < 1.0,
        "{ramp_end_rate}"
    );
}

/// Skirt's and body's rates (rad/s), the rates of each 0.5 s (start, skirt,
/// body) and the deepest skirt vertex inside the body.
type TurnRun = (f64, f64, Vec<(f64, f64, f64)>, Option<(usize, f64)>);

/// The skirt of the shipped trial config/trials/skirt_turn.yaml at 3 cm
/// (a shorter drape of 1 s) on the turning body: the angular velocity
/// about the vertical axis over `window` of the motion (s) of the skirt
/// (the mass-weighted mean of its vertices' unwrapped turn, over the
/// window) and of the body (the mean over its own vertices more than 5 cm
/// from the axis), the rate of each 0.5 s for the record, and the deepest
/// skirt vertex inside the body at the end. `alpha`: the fabric's
/// mass-proportional damping, 1/s (negative), in place of its own.
fn skirt_on_the_turn(alpha: Option<f64>, window: (f64, f64)) -> TurnRun {
    use garment_sim::trial::{self, Overrides, Trial};
    let mut t = Trial::load(Path::new("config/trials/skirt_turn.yaml")).unwrap();
    t.file.settle.max_time = 1.0;
    if let Some(a) = alpha {
        for f in t.fabrics.iter_mut() {
            f.damping.alpha = a;
        }
    }
    let (mut sim, _g) = t
        .build(&Overrides {
            spacing: Some(0.03),
            threads: Some(1),
            ..Default::default()
        })
        .unwrap();
    let mass = sim.cloth.mass.clone();
    let mut skirt: Option<(Unwrap, Unwrap, Vec<f64>)> = None;
    let mut bins: Vec<(f64, f64, f64)> = Vec::new();
    let mut bin: Option<(Unwrap, Unwrap, f64)> = None;
    let st = trial::run(&mut sim, &t.file.sewing, &t.file.settle, None, &mut |st| {
        let (s, at) = (st.sim, st.done);
        if st.phase != Phase::Motion {
            return Ok(Control::Continue);
        }
        let b = s.obstacles()[0].deforming().unwrap().positions();
        let x = s.cloth.positions();
        let counting = at > window.0 + 1e-9 && at < window.1 + 1e-9;
        match &mut skirt {
            Some((c, u, _)) => {
                c.update(x, counting);
                u.update(b, counting);
            }
            None => {
                let w = b
                    .iter()
                    .map(|p| if p.xy().norm() > 0.05 { 1.0 } else { 0.0 })
                    .collect();
                skirt = Some((Unwrap::new(x), Unwrap::new(b), w));
            }
        }
        let w = &skirt.as_ref().unwrap().2;
        match &mut bin {
            Some((c, u, t0)) => {
                c.update(x, true);
                u.update(b, true);
                if at - *t0 > 0.5 - 1e-9 {
                    bins.push((*t0, c.mean(&mass) / (at - *t0), u.mean(w) / (at - *t0)));
                    bin = Some((Unwrap::new(x), Unwrap::new(b), at));
                }
            }
            None => bin = Some((Unwrap::new(x), Unwrap::new(b), at)),
        }
        Ok(Control::Continue)
    })
    .unwrap();
    assert!(
        (st.motion_s.unwrap() - 4.0).abs() < 0.01,
        "{:?}",
        st.motion_s
    );
    let (c, u, w) = skirt.unwrap();
    let span = window.1 - window.0;
    let deepest = sim.obstacles()[0].deepest_inside(sim.cloth.positions());
    (c.mean(&mass) / span, u.mean(&w) / span, bins, deepest)
}

/// A skirt on a body that turns at a steady rate follows it: the shipped
/// trial config/trials/skirt_turn.yaml at 3 cm, the body turning
/// (assets/bodies/anny/turn.glb: ramped to 1 rad/s over 0.5 s, then held,
/// 4 s). After the transient, over the last 2 s, the skirt's mean angular
/// velocity about the vertical axis is the body's, measured from the body's
/// own vertices, within 1 % (the issue asks 5 %), and so is its rate over
/// each half second that starts in them; no skirt vertex ends inside the body. So
/// with the fabric's own mass-proportional damping (7 /s, a drag on the
/// absolute velocity that the waist's friction must carry round) and with a
/// drag of 0.5 /s.
#[test]
fn a_skirt_on_the_turning_body_follows_it() {
    let window = (2.0, 4.0);
    for alpha in [None, Some(-0.5)] {
        let (skirt, body, bins, deepest) = skirt_on_the_turn(alpha, window);
        let drag = alpha.map_or("the fabric's own 7 /s".to_string(), |a| {
            format!("{} /s", -a)
        });
        for (t0, c, u) in &bins {
            println!("  motion {t0:.2} s + 0.5 s: skirt {c:.4} rad/s, body {u:.4} rad/s");
        }
        println!(
            "skirt on the turning body, drag {drag}: over {:.1}-{:.1} s of the motion the body \
             turns at {body:.4} rad/s, the skirt at {skirt:.4} rad/s ({:+.2} %); deepest vertex \
             inside the body {deepest:?}",
            window.0,
            window.1,
            100.0 * (skirt / body - 1.0)
        );
        assert!((body - 1.0).abs() < 1e-3, "the body turns at {body} rad/s");
        assert!(
            (skirt / body - 1.0).abs() < 0.01,
            "drag {drag}: the skirt turns at {skirt} rad/s, the body at {body}"
        );
        // the half seconds that start in the window
        let late: Vec<_> = bins.iter().filter(|b| b.0 > window.0 - 0.05).collect();
        assert!(late.len() >= 3, "{bins:?}");
        for (t0, c, u) in late {
            assert!(
                (c / u - 1.0).abs() < 0.01,
                "drag {drag}: over {t0} s + 0.5 s the skirt turns at {c} rad/s, the body at {u}"
            );
        }
        assert!(
            deepest.is_none(),
            "a skirt vertex inside the body: {deepest:?}"
        );
    }
}
