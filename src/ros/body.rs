//! What the `body` messages (`garment_sim_msgs/msg/Body`) and the
//! `body_mesh` messages (`mesh_msgs/msg/MeshGeometryStamped`) do: a
//! deforming body's topology, then its vertex positions frame by frame. Both
//! are read into one form ([`BodyInput`]) and go through the same checks:
//! every message is checked in full before it is taken; a bad one is refused
//! with an error naming the body, the field and the index, counted by kind,
//! and the body is left as it was.
//!
//! Policy (docs/bodies.md):
//! - a `Body` with `triangles` starts (or replaces) the body `id`: its
//!   topology and its first frame; a `Body` without `triangles` is a frame
//!   of a body already started, with as many vertices;
//! - a `MeshGeometryStamped` carries its whole mesh every time: its faces
//!   start (or replace) the body `uuid` when the body has none yet or other
//!   faces (other indices, or another number of them); with the very faces
//!   the body has, it is a frame, with as many vertices; no faces or no
//!   vertices is refused (empty);
//! - a frame stamped at or before the body's last accepted frame is out of
//!   order, and refused;
//! - a frame stamped at or before the simulation's time is late: it is taken
//!   as the body's position one step ahead (the body reaches it at the end of
//!   the next step) and counted;
//! - a non-finite value, a vertex index out of range or a vertex count that
//!   differs from the topology's is refused.

use super::control::ObstacleRegistry;
use crate::collision::{Obstacle, DEFAULT_FRICTION, DEFAULT_OBSTACLE_THICKNESS};
use crate::deforming::Motion;
use crate::msgs;
use crate::solver::Simulation;
use nalgebra::{Isometry3, Vector3};
use std::collections::HashMap;
use std::sync::{Arc, RwLock};

type V = Vector3<f64>;

/// Largest number of vertices of a streamed body.
pub const MAX_BODY_VERTICES: usize = 1_000_000;

/// Why a body message was refused, by kind (for the diagnostics' counters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Refusal {
    /// Positions before any topology for that id.
    NoTopology,
    /// Another vertex count than the topology's, or a length not a multiple
    /// of 3.
    VertexCount,
    /// A NaN or infinite coordinate, thickness or friction.
    NonFinite,
    /// Triangles that are not triples of vertex indices in range.
    Triangles,
    /// Stamped at or before the last accepted frame.
    OutOfOrder,
    /// Another frame than the simulation's.
    Frame,
    /// A topology without vertices or without triangles.
    Empty,
}

impl Refusal {
    pub fn name(self) -> &'static str {
        match self {
            Refusal::NoTopology => "no_topology",
            Refusal::VertexCount => "vertex_count",
            Refusal::NonFinite => "non_finite",
            Refusal::Triangles => "triangles",
            Refusal::OutOfOrder => "out_of_order",
            Refusal::Frame => "frame",
            Refusal::Empty => "empty",
        }
    }
}

/// A body message that passed every check.
#[derive(Debug, Clone, PartialEq)]
pub enum BodyUpdate {
    /// A new topology: the body `id` starts (or restarts) here.
    Start {
        id: String,
        triangles: Vec<[u32; 3]>,
        positions: Vec<[f64; 3]>,
        /// When the positions hold, s (simulation time).
        time: f64,
        /// NaN: the default.
        thickness: f64,
        friction: f64,
    },
    /// A frame of a started body.
    Frame {
        id: String,
        positions: Vec<[f64; 3]>,
        time: f64,
        /// Stamped at or before the simulation's time: retimed one step ahead.
        late: bool,
    },
}

/// The message a body came in: it names the fields in refusals.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// `garment_sim_msgs/msg/Body`.
    Body,
    /// `mesh_msgs/msg/MeshGeometryStamped`.
    Mesh,
}

impl Source {
    /// Where coordinate `k` (vertex `k / 3`, axis `k % 3`) is in the message.
    fn coordinate(self, k: usize) -> String {
        let axis = ["x", "y", "z"][k % 3];
        match self {
            Source::Body => format!("positions[{k}] (vertex {}, {axis})", k / 3),
            Source::Mesh => format!("mesh_geometry.vertices[{}].{axis}", k / 3),
        }
    }

    /// Where vertex index `k` (of triangle `k / 3`) is in the message.
    fn index(self, k: usize) -> String {
        match self {
            Source::Body => format!("triangles[{k}] (triangle {})", k / 3),
            Source::Mesh => format!("mesh_geometry.faces[{}].vertex_indices[{}]", k / 3, k % 3),
        }
    }

    /// Triangle `t` as the message names it.
    fn triangle(self, t: usize) -> String {
        match self {
            Source::Body => format!("triangle {t}"),
            Source::Mesh => format!("mesh_geometry.faces[{t}]"),
        }
    }

    /// How a sender changes a body's topology.
    fn new_topology(self) -> &'static str {
        match self {
            Source::Body => "send new triangles to change it",
            Source::Mesh => "other faces start a new topology",
        }
    }
}

/// A body message as the checks read it, whichever type it came in.
#[derive(Debug, Clone, PartialEq)]
pub struct BodyInput {
    pub source: Source,
    pub id: String,
    pub frame_id: String,
    /// When the positions hold, s (the header's stamp).
    pub time: f64,
    /// A topology, three vertex indices per triangle: the body starts (or
    /// restarts) here. `None`: a frame of the body.
    pub triangles: Option<Vec<u32>>,
    /// x, y, z of every vertex in turn, m.
    pub positions: Vec<f64>,
    /// Contact thickness, m, and friction coefficient; NaN: the defaults.
    pub thickness: f64,
    pub friction: f64,
}

impl BodyInput {
    /// A `Body`: a topology when `triangles` is not empty, else a frame.
    pub fn from_body(m: &msgs::Body) -> BodyInput {
        BodyInput {
            source: Source::Body,
            id: m.id.clone(),
            frame_id: m.header.frame_id.clone(),
            time: m.header.stamp.secs(),
            triangles: (!m.triangles.is_empty()).then(|| m.triangles.clone()),
            positions: m.positions.iter().map(|&v| v as f64).collect(),
            thickness: m.thickness,
            friction: m.friction,
        }
    }
}

#[derive(Debug, Clone)]
struct Stream {
    vertices: usize,
    last: f64,
    /// The topology, three vertex indices per triangle.
    triangles: Vec<u32>,
}

/// A body's motion fed frame by frame: frames at increasing times (the
/// body's clock, 0 when its topology arrived), interpolated linearly; after
/// the last frame the body holds it.
#[derive(Debug)]
pub struct StreamedMotion {
    vertices: usize,
    frames: RwLock<Vec<(f64, Vec<V>)>>,
}

impl StreamedMotion {
    pub fn new(first: Vec<V>) -> StreamedMotion {
        StreamedMotion {
            vertices: first.len(),
            frames: RwLock::new(vec![(0.0, first)]),
        }
    }

    /// Adds the frame at time `t` (a frame at or before the last one
    /// replaces it), and forgets the frames before the one in force at
    /// `now`, which the body has passed.
    pub fn push(&self, t: f64, x: Vec<V>, now: f64) {
        let mut f = self.frames.write().expect("no panic holds the lock");
        match f.last_mut() {
            Some(last) if t <= last.0 => last.1 = x,
            _ => f.push((t, x)),
        }
        let passed = f.partition_point(|(s, _)| *s <= now).saturating_sub(1);
        f.drain(..passed);
    }

    /// Frames held.
    pub fn len(&self) -> usize {
        self.frames.read().expect("no panic holds the lock").len()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl Motion for StreamedMotion {
    fn vertex_count(&self) -> usize {
        self.vertices
    }

    fn duration(&self) -> f64 {
        let f = self.frames.read().expect("no panic holds the lock");
        f.last().map_or(0.0, |l| l.0)
    }

    fn positions(&self, t: f64, out: &mut [V]) {
        let f = self.frames.read().expect("no panic holds the lock");
        let k = f.partition_point(|(s, _)| *s <= t).max(1) - 1;
        if k + 1 >= f.len() || t <= f[k].0 {
            out.copy_from_slice(&f[k].1);
            return;
        }
        let (t0, a) = (&f[k].0, &f[k].1);
        let (t1, b) = (&f[k + 1].0, &f[k + 1].1);
        let w = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
        for ((o, p), q) in out.iter_mut().zip(a).zip(b) {
            *o = p + (q - p) * w;
        }
    }
}

/// The bodies streamed so far: each one's vertex count and last frame time.
#[derive(Debug, Default, Clone)]
pub struct BodyStreams {
    /// Each body's motion and the simulation time its clock started at.
    motions: HashMap<String, (Arc<StreamedMotion>, f64)>,
    streams: HashMap<String, Stream>,
    refused: HashMap<Refusal, u64>,
    late: u64,
    accepted: u64,
}

impl BodyStreams {
    /// A `MeshGeometryStamped` as a body message: a frame of the body `uuid`
    /// when its faces are that body's topology (the same indices in the same
    /// order), else a topology with `thickness` and `friction` (the node's
    /// parameters). Vertex normals are not read.
    pub fn mesh_input(
        &self,
        m: &msgs::MeshGeometryStamped,
        thickness: f64,
        friction: f64,
    ) -> BodyInput {
        let g = &m.mesh_geometry;
        let faces = || g.faces.iter().flat_map(|f| f.vertex_indices);
        let same = self.streams.get(&m.uuid).is_some_and(|s| {
            s.triangles.len() == 3 * g.faces.len() && faces().eq(s.triangles.iter().copied())
        });
        BodyInput {
            source: Source::Mesh,
            id: m.uuid.clone(),
            frame_id: m.header.frame_id.clone(),
            time: m.header.stamp.secs(),
            triangles: (!same).then(|| faces().collect()),
            positions: g.vertices.iter().flat_map(|p| [p.x, p.y, p.z]).collect(),
            thickness,
            friction,
        }
    }

    /// Checks a message against the bodies so far; `now` is the simulation's
    /// time and `dt` its step, `frame_id` its frame.
    pub fn accept(
        &mut self,
        m: &BodyInput,
        frame_id: &str,
        now: f64,
        dt: f64,
    ) -> Result<BodyUpdate, (Refusal, String)> {
        let r = self.check(m, frame_id, now, dt);
        match &r {
            Ok(BodyUpdate::Frame { late: true, .. }) => {
                self.late += 1;
                self.accepted += 1
            }
            Ok(_) => self.accepted += 1,
            Err((kind, _)) => *self.refused.entry(*kind).or_default() += 1,
        }
        r
    }

    fn check(
        &mut self,
        m: &BodyInput,
        frame_id: &str,
        now: f64,
        dt: f64,
    ) -> Result<BodyUpdate, (Refusal, String)> {
        let (id, src) = (&m.id, m.source);
        let fail = |k: Refusal, what: String| Err((k, format!("body {id:?}: {what}")));
        if !m.frame_id.is_empty() && m.frame_id != frame_id {
            return fail(
                Refusal::Frame,
                format!(
                    "header.frame_id {:?} is not the simulation frame {frame_id:?} (the node \
                     does not use TF: send positions in {frame_id:?})",
                    m.frame_id
                ),
            );
        }
        if !m.positions.len().is_multiple_of(3) {
            return fail(
                Refusal::VertexCount,
                format!(
                    "positions has {} values, not 3 per vertex",
                    m.positions.len()
                ),
            );
        }
        let n = m.positions.len() / 3;
        if let Some(k) = m.positions.iter().position(|v| !v.is_finite()) {
            return fail(
                Refusal::NonFinite,
                format!("{} is {}", src.coordinate(k), m.positions[k]),
            );
        }
        let positions: Vec<[f64; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        let time = m.time;
        let Some(triangles) = &m.triangles else {
            let Some(s) = self.streams.get_mut(id) else {
                return fail(
                    Refusal::NoTopology,
                    "positions without a topology: send the triangles first (a message with \
                     triangles starts a body)"
                        .into(),
                );
            };
            if n == 0 {
                return fail(Refusal::Empty, "no vertices".into());
            }
            if n != s.vertices {
                return fail(
                    Refusal::VertexCount,
                    format!(
                        "{n} vertices, the body's topology has {} ({})",
                        s.vertices,
                        src.new_topology()
                    ),
                );
            }
            if time <= s.last {
                return fail(
                    Refusal::OutOfOrder,
                    format!(
                        "stamped {time:.6} s, at or before its last frame ({:.6} s)",
                        s.last
                    ),
                );
            }
            s.last = time;
            let late = time <= now;
            return Ok(BodyUpdate::Frame {
                id: id.clone(),
                positions,
                time: if late { now + dt } else { time },
                late,
            });
        };
        if n == 0 || triangles.is_empty() {
            let what = if n == 0 { "vertices" } else { "triangles" };
            return fail(Refusal::Empty, format!("a topology with no {what}"));
        }
        if !(3..=MAX_BODY_VERTICES).contains(&n) {
            return fail(
                Refusal::VertexCount,
                format!("{n} vertices: a body has 3 to {MAX_BODY_VERTICES} (MAX_BODY_VERTICES)"),
            );
        }
        if !triangles.len().is_multiple_of(3) {
            return fail(
                Refusal::Triangles,
                format!(
                    "triangles has {} indices, not 3 per triangle",
                    triangles.len()
                ),
            );
        }
        if let Some(k) = triangles.iter().position(|&v| v as usize >= n) {
            return fail(
                Refusal::Triangles,
                format!(
                    "{} is vertex {}, out of range (0 to {})",
                    src.index(k),
                    triangles[k],
                    n - 1
                ),
            );
        }
        if let Some(t) = triangles
            .chunks_exact(3)
            .position(|t| t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
        {
            return fail(
                Refusal::Triangles,
                format!("{} repeats a vertex", src.triangle(t)),
            );
        }
        for (what, v) in [("thickness", m.thickness), ("friction", m.friction)] {
            if v.is_infinite() {
                return fail(Refusal::NonFinite, format!("{what} is {v}"));
            }
        }
        self.streams.insert(
            id.clone(),
            Stream {
                vertices: n,
                last: time,
                triangles: triangles.clone(),
            },
        );
        Ok(BodyUpdate::Start {
            id: id.clone(),
            triangles: triangles
                .chunks_exact(3)
                .map(|t| [t[0], t[1], t[2]])
                .collect(),
            positions,
            time: time.max(now),
            thickness: m.thickness,
            friction: m.friction,
        })
    }

    /// Forgets a body (its obstacle was removed).
    pub fn remove(&mut self, id: &str) {
        self.streams.remove(id);
        self.motions.remove(id);
    }

    /// The streamed body `id`'s motion, if it is one.
    pub fn motion(&self, id: &str) -> Option<&Arc<StreamedMotion>> {
        self.motions.get(id).map(|m| &m.0)
    }

    /// Applies a body message (`body` or `body_mesh`) to the simulation: a
    /// topology makes (or replaces) the obstacle `id`, a body moved by its
    /// frames; a frame becomes the body's position at its stamp. Returns what
    /// to log (empty for a frame: they come at the avatar's frame rate).
    pub fn apply(
        &mut self,
        sim: &mut Simulation,
        reg: &mut ObstacleRegistry,
        m: &BodyInput,
        frame_id: &str,
    ) -> Result<String, String> {
        let (now, dt) = (sim.time, sim.params().dt);
        match self.accept(m, frame_id, now, dt).map_err(|e| e.1)? {
            BodyUpdate::Start {
                id,
                triangles,
                positions,
                thickness,
                friction,
                ..
            } => {
                let count = triangles.len();
                let motion = Arc::new(StreamedMotion::new(
                    positions.iter().map(|p| V::from(*p)).collect(),
                ));
                let made = Obstacle::with_motion(
                    &id,
                    triangles,
                    motion.clone(),
                    false,
                    0.0,
                    Isometry3::identity(),
                    if thickness.is_nan() {
                        DEFAULT_OBSTACLE_THICKNESS
                    } else {
                        thickness
                    },
                    if friction.is_nan() {
                        DEFAULT_FRICTION
                    } else {
                        friction
                    },
                )
                .and_then(|o| o.check_overlap(sim.cloth.positions()).map(|_| o));
                let o = match made {
                    Ok(o) => o,
                    Err(e) => {
                        // refused: the stream did not start
                        self.streams.remove(&id);
                        *self.refused.entry(Refusal::Triangles).or_default() += 1;
                        self.accepted -= 1;
                        return Err(format!("body {id:?}: {e:#}"));
                    }
                };
                let replaced = reg.remove_from(sim, &id);
                let h = sim.add_obstacle(o);
                reg.insert_single(&id, h);
                self.motions.insert(id.clone(), (motion, now));
                Ok(format!(
                    "{} body {id:?}: {} vertices, {} triangles",
                    if replaced { "replaced" } else { "added" },
                    positions.len(),
                    count
                ))
            }
            BodyUpdate::Frame {
                id,
                positions,
                time,
                ..
            } => {
                let Some((motion, t0)) = self.motions.get(&id).filter(|_| reg.contains(&id)) else {
                    self.remove(&id);
                    return Err(format!(
                        "body {id:?}: its obstacle was removed (a new topology starts it again)"
                    ));
                };
                motion.push(
                    time - t0,
                    positions.iter().map(|p| V::from(*p)).collect(),
                    now - t0,
                );
                Ok(String::new())
            }
        }
    }

    /// Messages taken (late ones included), late ones, and refusals by kind.
    pub fn counts(&self) -> (u64, u64, Vec<(&'static str, u64)>) {
        let mut r: Vec<_> = self.refused.iter().map(|(k, n)| (k.name(), *n)).collect();
        r.sort();
        (self.accepted, self.late, r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(id: &str, t: f64, tris: Vec<u32>, pos: Vec<f32>) -> BodyInput {
        BodyInput::from_body(&msgs::Body {
            header: msgs::Header {
                stamp: msgs::Time::from_secs(t),
                frame_id: "world".into(),
            },
            id: id.into(),
            triangles: tris,
            positions: pos,
            thickness: f64::NAN,
            friction: f64::NAN,
        })
    }

    fn quad(z: f32) -> Vec<f32> {
        vec![0., 0., z, 1., 0., z, 1., 1., z, 0., 1., z]
    }

    #[test]
    fn a_stream_starts_with_its_topology_and_refuses_what_breaks_it() {
        let mut b = BodyStreams::default();
        let tris = vec![0, 1, 2, 0, 2, 3];
        // positions before the topology
        let e = b.accept(&msg("a", 0.1, vec![], quad(0.0)), "world", 0.0, 0.01);
        assert_eq!(e.unwrap_err().0, Refusal::NoTopology);
        // the topology
        match b.accept(&msg("a", 0.1, tris.clone(), quad(0.0)), "world", 0.0, 0.01) {
            Ok(BodyUpdate::Start {
                triangles,
                positions,
                time,
                ..
            }) => {
                assert_eq!(triangles, vec![[0, 1, 2], [0, 2, 3]]);
                assert_eq!(positions[2], [1.0, 1.0, 0.0]);
                assert!((time - 0.1).abs() < 1e-12);
            }
            r => panic!("{r:?}"),
        }
        // a frame in order
        match b.accept(&msg("a", 0.2, vec![], quad(0.5)), "world", 0.0, 0.01) {
            Ok(BodyUpdate::Frame {
                positions,
                time,
                late,
                ..
            }) => {
                assert_eq!(positions[3], [0.0, 1.0, 0.5]);
                assert!((time - 0.2).abs() < 1e-12 && !late);
            }
            r => panic!("{r:?}"),
        }
        // out of order, another vertex count, non-finite, another frame
        let e = b.accept(&msg("a", 0.15, vec![], quad(0.5)), "world", 0.0, 0.01);
        assert_eq!(e.unwrap_err().0, Refusal::OutOfOrder);
        let e = b.accept(&msg("a", 0.3, vec![], vec![0.0; 9]), "world", 0.0, 0.01);
        let (k, why) = e.unwrap_err();
        assert_eq!(k, Refusal::VertexCount);
        assert!(why.contains("3 vertices") && why.contains("has 4"), "{why}");
        let mut nan = quad(0.5);
        nan[7] = f32::NAN;
        let (k, why) = b
            .accept(&msg("a", 0.3, vec![], nan), "world", 0.0, 0.01)
            .unwrap_err();
        assert_eq!(k, Refusal::NonFinite);
        assert!(why.contains("positions[7] (vertex 2, y)"), "{why}");
        let e = b.accept(&msg("a", 0.3, vec![], quad(0.5)), "map", 0.0, 0.01);
        assert_eq!(e.unwrap_err().0, Refusal::Frame);
        // refusals left the stream as it was: the next good frame is taken
        assert!(b
            .accept(&msg("a", 0.3, vec![], quad(0.6)), "world", 0.0, 0.01)
            .is_ok());
        // a late frame is retimed one step ahead of the simulation
        match b.accept(&msg("a", 0.35, vec![], quad(0.7)), "world", 0.5, 0.01) {
            Ok(BodyUpdate::Frame { time, late, .. }) => {
                assert!(late && (time - 0.51).abs() < 1e-12)
            }
            r => panic!("{r:?}"),
        }
        // bad topologies
        let (k, why) = b
            .accept(&msg("b", 0.0, vec![0, 1, 4], quad(0.0)), "world", 0.0, 0.01)
            .unwrap_err();
        assert_eq!(k, Refusal::Triangles);
        assert!(
            why.contains("triangles[2]") && why.contains("vertex 4"),
            "{why}"
        );
        let e = b.accept(&msg("b", 0.0, vec![0, 1], quad(0.0)), "world", 0.0, 0.01);
        assert_eq!(e.unwrap_err().0, Refusal::Triangles);
        let e = b.accept(&msg("b", 0.0, vec![0, 1, 1], quad(0.0)), "world", 0.0, 0.01);
        assert_eq!(e.unwrap_err().0, Refusal::Triangles);
        let e = b.accept(
            &msg("b", 0.0, vec![0, 1, 2], vec![0.0; 7]),
            "world",
            0.0,
            0.01,
        );
        assert_eq!(e.unwrap_err().0, Refusal::VertexCount);
        let e = b.accept(&msg("b", 0.0, vec![0, 1, 2], vec![]), "world", 0.0, 0.01);
        assert_eq!(e.unwrap_err().0, Refusal::Empty);
        let (taken, late, refused) = b.counts();
        assert_eq!((taken, late), (4, 1));
        assert_eq!(
            refused,
            vec![
                ("empty", 1),
                ("frame", 1),
                ("no_topology", 1),
                ("non_finite", 1),
                ("out_of_order", 1),
                ("triangles", 3),
                ("vertex_count", 2)
            ]
        );
    }

    fn mesh(id: &str, t: f64, faces: &[[u32; 3]], v: &[[f64; 3]]) -> msgs::MeshGeometryStamped {
        msgs::MeshGeometryStamped {
            header: msgs::Header {
                stamp: msgs::Time::from_secs(t),
                frame_id: "world".into(),
            },
            uuid: id.into(),
            mesh_geometry: msgs::MeshGeometry {
                vertices: v.iter().map(|&[x, y, z]| msgs::Point { x, y, z }).collect(),
                vertex_normals: vec![],
                faces: faces
                    .iter()
                    .map(|&vertex_indices| msgs::MeshTriangleIndices { vertex_indices })
                    .collect(),
            },
        }
    }

    fn square(z: f64) -> Vec<[f64; 3]> {
        vec![[0., 0., z], [1., 0., z], [1., 1., z], [0., 1., z]]
    }

    #[test]
    fn a_mesh_stream_starts_with_new_faces_and_refuses_as_a_body_stream() {
        let mut b = BodyStreams::default();
        let faces = [[0, 1, 2], [0, 2, 3]];
        let take = |b: &mut BodyStreams, m: &msgs::MeshGeometryStamped, now: f64| {
            let input = b.mesh_input(m, 0.004, 0.5);
            b.accept(&input, "world", now, 0.01)
        };
        // empty: no vertices, or vertices without faces
        let (k, why) = take(&mut b, &mesh("m", 0.1, &[], &[]), 0.0).unwrap_err();
        assert_eq!(k, Refusal::Empty);
        assert!(why.contains("no vertices"), "{why}");
        let (k, why) = take(&mut b, &mesh("m", 0.1, &[], &square(0.0)), 0.0).unwrap_err();
        assert_eq!(k, Refusal::Empty);
        assert!(why.contains("no triangles"), "{why}");
        // the first mesh with faces is the topology, with the node's thickness and friction
        match take(&mut b, &mesh("m", 0.1, &faces, &square(0.0)), 0.0) {
            Ok(BodyUpdate::Start {
                id,
                triangles,
                positions,
                time,
                thickness,
                friction,
            }) => {
                assert_eq!(id, "m");
                assert_eq!(triangles, faces.to_vec());
                assert_eq!(positions, square(0.0));
                assert!((time - 0.1).abs() < 1e-12);
                assert_eq!((thickness, friction), (0.004, 0.5));
            }
            r => panic!("{r:?}"),
        }
        // the same faces: a frame, float64 positions as they came
        let mut moved = square(0.25);
        moved[1][0] = 1.0 + 1e-12;
        let m = mesh("m", 0.2, &faces, &moved);
        assert_eq!(b.mesh_input(&m, 0.004, 0.5).triangles, None);
        match take(&mut b, &m, 0.0) {
            Ok(BodyUpdate::Frame {
                positions, late, ..
            }) => assert!(positions == moved && !late),
            r => panic!("{r:?}"),
        }
        // out of order, another vertex count with the same faces, non-finite, another frame
        let e = take(&mut b, &mesh("m", 0.15, &faces, &square(0.3)), 0.0);
        assert_eq!(e.unwrap_err().0, Refusal::OutOfOrder);
        let mut five = square(0.3);
        five.push([2.0, 2.0, 0.3]);
        let (k, why) = take(&mut b, &mesh("m", 0.3, &faces, &five), 0.0).unwrap_err();
        assert_eq!(k, Refusal::VertexCount);
        assert!(
            why.contains("5 vertices") && why.contains("has 4") && why.contains("other faces"),
            "{why}"
        );
        let mut inf = square(0.3);
        inf[2][1] = f64::INFINITY;
        let (k, why) = take(&mut b, &mesh("m", 0.3, &faces, &inf), 0.0).unwrap_err();
        assert_eq!(k, Refusal::NonFinite);
        assert!(why.contains("mesh_geometry.vertices[2].y is inf"), "{why}");
        let mut other = mesh("m", 0.3, &faces, &square(0.3));
        other.header.frame_id = "map".into();
        assert_eq!(take(&mut b, &other, 0.0).unwrap_err().0, Refusal::Frame);
        // other faces are a new topology, checked as one: out of range, a repeated vertex
        let (k, why) = take(
            &mut b,
            &mesh("m", 0.3, &[[0, 1, 2], [0, 2, 9]], &square(0.3)),
            0.0,
        )
        .unwrap_err();
        assert_eq!(k, Refusal::Triangles);
        assert!(
            why.contains("mesh_geometry.faces[1].vertex_indices[2] is vertex 9"),
            "{why}"
        );
        let (k, why) = take(&mut b, &mesh("m", 0.3, &[[0, 1, 1]], &square(0.3)), 0.0).unwrap_err();
        assert_eq!(k, Refusal::Triangles);
        assert!(
            why.contains("mesh_geometry.faces[0] repeats a vertex"),
            "{why}"
        );
        let e = take(&mut b, &mesh("m", 0.3, &[], &square(0.3)), 0.0);
        assert_eq!(e.unwrap_err().0, Refusal::Empty);
        // the refusals left the body as it was: the next frame is taken, a late one retimed
        assert!(take(&mut b, &mesh("m", 0.3, &faces, &square(0.3)), 0.0).is_ok());
        match take(&mut b, &mesh("m", 0.35, &faces, &square(0.4)), 0.5) {
            Ok(BodyUpdate::Frame { time, late, .. }) => {
                assert!(late && (time - 0.51).abs() < 1e-12)
            }
            r => panic!("{r:?}"),
        }
        // other faces with five vertices replace the topology; then five is a frame
        let five_faces = [[0, 1, 2], [0, 2, 3], [2, 1, 4]];
        assert!(matches!(
            take(&mut b, &mesh("m", 0.6, &five_faces, &five), 0.5),
            Ok(BodyUpdate::Start { .. })
        ));
        assert!(matches!(
            take(&mut b, &mesh("m", 0.7, &five_faces, &five), 0.5),
            Ok(BodyUpdate::Frame { late: false, .. })
        ));
        // and four vertices with the old faces start it again (a new topology)
        assert!(matches!(
            take(&mut b, &mesh("m", 0.8, &faces, &square(0.5)), 0.5),
            Ok(BodyUpdate::Start { .. })
        ));
        let (taken, late, refused) = b.counts();
        assert_eq!((taken, late), (7, 1));
        assert_eq!(
            refused,
            vec![
                ("empty", 3),
                ("frame", 1),
                ("non_finite", 1),
                ("out_of_order", 1),
                ("triangles", 2),
                ("vertex_count", 1)
            ]
        );
    }
}
