//! What the `body` messages (`garment_sim_msgs/msg/Body`) do: a deforming
//! body's topology, sent once, then its vertex positions frame by frame.
//! Every message is checked in full before it is taken: a bad one is refused
//! with an error naming the body, the field and the index, counted by kind,
//! and the body is left as it was.
//!
//! Policy (docs/bodies.md):
//! - a message with `triangles` starts (or replaces) the body `id`: its
//!   topology and its first frame;
//! - a message without `triangles` is a frame of a body already started, with
//!   as many vertices;
//! - a frame stamped at or before the body's last accepted frame is out of
//!   order, and refused;
//! - a frame stamped at or before the simulation's time is late: it is taken
//!   as the body's position one step ahead (the body reaches it at the end of
//!   the next step) and counted;
//! - a non-finite value, a vertex index out of range or a vertex count that
//!   differs from the topology's is refused.

use crate::msgs;
use std::collections::HashMap;

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

#[derive(Debug, Clone)]
struct Stream {
    vertices: usize,
    last: f64,
}

/// The bodies streamed so far: each one's vertex count and last frame time.
#[derive(Debug, Default, Clone)]
pub struct BodyStreams {
    streams: HashMap<String, Stream>,
    refused: HashMap<Refusal, u64>,
    late: u64,
    accepted: u64,
}

impl BodyStreams {
    /// Checks a message against the bodies so far; `now` is the simulation's
    /// time and `dt` its step, `frame_id` its frame.
    pub fn accept(
        &mut self,
        m: &msgs::Body,
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
        m: &msgs::Body,
        frame_id: &str,
        now: f64,
        dt: f64,
    ) -> Result<BodyUpdate, (Refusal, String)> {
        let id = &m.id;
        let fail = |k: Refusal, what: String| Err((k, format!("body {id:?}: {what}")));
        if !m.header.frame_id.is_empty() && m.header.frame_id != frame_id {
            return fail(
                Refusal::Frame,
                format!(
                    "header.frame_id {:?} is not the simulation frame {frame_id:?} (the node \
                     does not use TF: send positions in {frame_id:?})",
                    m.header.frame_id
                ),
            );
        }
        if m.positions.len() % 3 != 0 {
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
                format!(
                    "positions[{k}] (vertex {}, {}) is {}",
                    k / 3,
                    ["x", "y", "z"][k % 3],
                    m.positions[k]
                ),
            );
        }
        let positions: Vec<[f64; 3]> = m
            .positions
            .chunks_exact(3)
            .map(|p| [p[0] as f64, p[1] as f64, p[2] as f64])
            .collect();
        let time = m.header.stamp.secs();
        if m.triangles.is_empty() {
            let Some(s) = self.streams.get_mut(id) else {
                return fail(
                    Refusal::NoTopology,
                    "positions without a topology: send the triangles first (a message with \
                     triangles starts a body)"
                        .into(),
                );
            };
            if n != s.vertices {
                return fail(
                    Refusal::VertexCount,
                    format!(
                        "{n} vertices, the body's topology has {} (send new triangles to \
                         change it)",
                        s.vertices
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
        }
        if n < 3 || n > MAX_BODY_VERTICES {
            return fail(
                Refusal::VertexCount,
                format!("{n} vertices: a body has 3 to {MAX_BODY_VERTICES} (MAX_BODY_VERTICES)"),
            );
        }
        if m.triangles.len() % 3 != 0 {
            return fail(
                Refusal::Triangles,
                format!(
                    "triangles has {} indices, not 3 per triangle",
                    m.triangles.len()
                ),
            );
        }
        if let Some(k) = m.triangles.iter().position(|&v| v as usize >= n) {
            return fail(
                Refusal::Triangles,
                format!(
                    "triangles[{k}] (triangle {}) is vertex {}, out of range (0 to {})",
                    k / 3,
                    m.triangles[k],
                    n - 1
                ),
            );
        }
        if let Some(t) = m
            .triangles
            .chunks_exact(3)
            .position(|t| t[0] == t[1] || t[1] == t[2] || t[0] == t[2])
        {
            return fail(Refusal::Triangles, format!("triangle {t} repeats a vertex"));
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
            },
        );
        Ok(BodyUpdate::Start {
            id: id.clone(),
            triangles: m
                .triangles
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

    fn msg(id: &str, t: f64, tris: Vec<u32>, pos: Vec<f32>) -> msgs::Body {
        msgs::Body {
            header: msgs::Header {
                stamp: msgs::Time::from_secs(t),
                frame_id: "world".into(),
            },
            id: id.into(),
            triangles: tris,
            positions: pos,
            thickness: f64::NAN,
            friction: f64::NAN,
        }
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
        let (taken, late, refused) = b.counts();
        assert_eq!((taken, late), (4, 1));
        assert_eq!(
            refused,
            vec![
                ("frame", 1),
                ("no_topology", 1),
                ("non_finite", 1),
                ("out_of_order", 1),
                ("triangles", 3),
                ("vertex_count", 2)
            ]
        );
    }
}
