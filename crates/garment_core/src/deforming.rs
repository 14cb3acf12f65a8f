//! Deforming obstacles: a triangle mesh of one topology whose vertices move
//! over time (a body from an animation or an avatar pipeline).
//!
//! A [`Motion`] gives the vertex positions (in the obstacle's frame) at any
//! time; [`Keyframes`] is the one built from frames at times t_k, its
//! vertices interpolated linearly between them. Each fixed step of length h
//! the obstacle takes the positions at the start and at the end of the step
//! (x(t) and x(t + h)); a vertex's velocity over the step is
//! (x(t + h) − x(t)) / h, and the velocity of the surface at a point is the
//! barycentric mix of its triangle's. A point at height d above a triangle
//! (along its unit normal n) moves with it at that velocity plus d times the
//! rate of n over the step: exact when the triangle moves rigidly, as a point
//! of a rigid obstacle at the cloth vertex moves with the rigid motion. A
//! contact reads the velocity of the point where the cloth vertex is (it
//! rides the contact distance above the skin; on a body turning at ω the
//! skin's own velocity would hold it back by ω d).
//!
//! Queries run on a bounding-volume hierarchy of the triangles built once
//! (median splits) and refitted every step to boxes that hold each triangle
//! over the whole step (its start and end positions), so one tree serves the
//! closest-point queries at either end and the swept tests between.
//!
//! A closed mesh has an inside: the sign of a point's distance comes from the
//! angle-weighted pseudo-normal of the closest feature (face, edge or vertex;
//! Bærentzen & Aanæs 2005), as for a rigid mesh. Continuous detection: a
//! cloth vertex moving linearly over the step meets a triangle whose vertices
//! move linearly at a root of the coplanarity cubic (Provot 1997) at which the
//! vertex lies in the triangle ([`DeformingBody::first_hit`]).

use crate::bvh::{Aabb, Bvh};
use crate::error::{fail, Result};
use crate::self_contact::geometry::{coplanarity_cubic, cubic_roots, point_triangle};
use nalgebra::{Isometry3, Vector3};
use std::collections::HashMap;
use std::sync::Arc;

type V = Vector3<f64>;

/// Vertex positions of a body over time, in the obstacle's frame (m).
pub trait Motion: Send + Sync + std::fmt::Debug {
    /// Vertices of the mesh it moves.
    fn vertex_count(&self) -> usize;
    /// Length, s: positions are asked for at times in `[0, duration]`.
    fn duration(&self) -> f64;
    /// The positions at time `t` into `out` (`vertex_count` of them).
    fn positions(&self, t: f64, out: &mut [V]);
}

/// Frames at times `t_k` (increasing, the first at 0), the vertices moving
/// linearly from one frame to the next.
#[derive(Debug, Clone)]
pub struct Keyframes {
    times: Vec<f64>,
    frames: Vec<Vec<V>>,
}

impl Keyframes {
    /// Frames at the given times. Refuses no frame, frames of different
    /// vertex counts, non-finite positions and times that do not increase
    /// from 0, naming the frame.
    pub fn new(times: Vec<f64>, frames: Vec<Vec<V>>) -> Result<Keyframes> {
        if frames.is_empty() {
            fail!(invalid, "a motion needs at least one frame");
        }
        if times.len() != frames.len() {
            fail!(
                length("frame times", times.len(), frames.len()),
                "{} frame times for {} frames",
                times.len(),
                frames.len()
            );
        }
        if times[0] != 0.0 {
            fail!(
                bound("the first frame's time", times[0]),
                "the first frame's time is {} s: it must be 0",
                times[0]
            );
        }
        for k in 1..times.len() {
            if !(times[k].is_finite() && times[k] > times[k - 1]) {
                fail!(
                    bound(format!("frame {k}: time"), times[k]),
                    "frame {k}: time {} s does not follow frame {}'s {} s",
                    times[k],
                    k - 1,
                    times[k - 1]
                );
            }
        }
        let n = frames[0].len();
        for (k, f) in frames.iter().enumerate() {
            if f.len() != n {
                fail!(
                    length(format!("frame {k}"), f.len(), n),
                    "frame {k} has {} vertices, frame 0 has {n}: every frame must have the same",
                    f.len()
                );
            }
            if let Some(i) = f.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
                fail!(
                    non_finite(format!("frame {k}"), i),
                    "frame {k}: vertex {i} is not finite: {:?}",
                    f[i]
                );
            }
        }
        Ok(Keyframes { times, frames })
    }

    /// Frames `1 / fps` apart.
    pub fn at_rate(fps: f64, frames: Vec<Vec<V>>) -> Result<Keyframes> {
        if !(fps.is_finite() && fps > 0.0) {
            fail!(
                bound("frame rate", fps),
                "frame rate {fps}: must be > 0 frames/s"
            );
        }
        let times = (0..frames.len()).map(|k| k as f64 / fps).collect();
        Keyframes::new(times, frames)
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.frames.len()
    }
}

impl Motion for Keyframes {
    fn vertex_count(&self) -> usize {
        self.frames[0].len()
    }

    fn duration(&self) -> f64 {
        *self.times.last().expect("at least one frame")
    }

    fn positions(&self, t: f64, out: &mut [V]) {
        // the frame at or before t, and how far t is towards the next
        let k = self.times.partition_point(|&s| s <= t).max(1) - 1;
        if k + 1 >= self.times.len() {
            out.copy_from_slice(&self.frames[k]);
            return;
        }
        let w = ((t - self.times[k]) / (self.times[k + 1] - self.times[k])).clamp(0.0, 1.0);
        let (a, b) = (&self.frames[k], &self.frames[k + 1]);
        for i in 0..out.len() {
            out[i] = a[i] + (b[i] - a[i]) * w;
        }
    }
}

/// New boxes for the tree over `tris`: each triangle's at both `x` and `y`
/// (its start and end of the step).
fn refit(bvh: &mut Bvh, tris: &[[u32; 3]], x: &[V], y: &[V]) {
    bvh.refit(|t| {
        let mut b = Aabb::empty();
        for &i in &tris[t] {
            b.add(&x[i as usize]);
            b.add(&y[i as usize]);
        }
        b
    });
}

/// How near a triangle a point at a root of the coplanarity cubic must be
/// to count as meeting it, m (a point crossing a shared edge meets one of
/// its triangles to rounding).
pub const HIT_TOLERANCE: f64 = 1e-9;

/// A vertex meeting a moving triangle within the step.
#[derive(Debug, Clone, Copy)]
pub struct Hit {
    /// Fraction of the step at which it meets the triangle.
    pub s: f64,
    /// The triangle it meets.
    pub triangle: usize,
    /// Barycentric weights of the meeting point in the triangle.
    pub weights: [f64; 3],
    /// +1 if the vertex came from the side the triangle's normal points to
    /// (the outside of a closed, outward-oriented mesh), −1 otherwise.
    pub side: f64,
}

/// Closest point of the body's surface to a point.
#[derive(Debug, Clone, Copy)]
pub struct Closest {
    /// The triangle the closest point lies on.
    pub triangle: usize,
    /// Its barycentric weights in that triangle.
    pub weights: [f64; 3],
    /// The closest point, m.
    pub point: V,
    /// Signed distance (negative inside a closed mesh), m.
    pub distance: f64,
    /// Outward unit normal.
    pub normal: V,
    /// Velocity over the current step of the point at the queried
    /// position carried by the closest triangle (its surface velocity at the
    /// foot plus its normal's rate times the height above it), m/s.
    pub velocity: V,
}

/// A triangle mesh whose vertices follow a [`Motion`] (positions in the
/// world frame: the obstacle's pose times the motion's).
#[derive(Debug, Clone)]
pub struct DeformingBody {
    motion: Arc<dyn Motion>,
    /// Repeat the motion (its last frame should then be its first).
    pub looping: bool,
    /// Time on the body's clock at which the motion's time 0 plays: before
    /// it the body holds its first pose, s.
    pub start: f64,
    /// Holds the first pose whatever the clock (a trial's body while the
    /// garment is sewn and draped on it) until [`DeformingBody::release`].
    pub held: bool,
    /// Time since the body was made, advanced with the simulation, s.
    clock: f64,
    tris: Vec<[u32; 3]>,
    /// Each triangle's edges (v0v1, v1v2, v2v0) as indices into the edges.
    tri_edges: Vec<[u32; 3]>,
    closed: bool,
    /// Positions now (world), at the start of the step just done (after
    /// [`DeformingBody::advance`]), and at the end of the step being
    /// prepared (after [`DeformingBody::prepare`]).
    x: Vec<V>,
    prev: Vec<V>,
    next: Vec<V>,
    /// Per-vertex velocity over the current step, m/s.
    vel: Vec<V>,
    /// Rate of each face's unit normal over the current step, 1/s.
    face_rate: Vec<V>,
    /// The step `next` was prepared for, s.
    prepared: Option<f64>,
    /// Unit face normals and the vertices' and edges' pseudo-normals of `x`
    /// (closed meshes).
    face_n: Vec<V>,
    vertex_n: Vec<V>,
    edge_n: Vec<V>,
    local: Vec<V>,
    bvh: Bvh,
}

impl DeformingBody {
    /// A body of triangles `tris` moved by `motion`, placed by `pose`.
    /// `closed`: every edge is shared by two triangles (the mesh has an
    /// inside, faces counter-clockwise seen from outside).
    pub fn new(
        motion: Arc<dyn Motion>,
        tris: Vec<[u32; 3]>,
        closed: bool,
        pose: &Isometry3<f64>,
        looping: bool,
        start: f64,
    ) -> Result<DeformingBody> {
        let n = motion.vertex_count();
        if let Some((k, t)) = tris
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i as usize >= n))
        {
            fail!(
                index(
                    "vertex",
                    t.iter().map(|&i| i as usize).max().unwrap_or(0),
                    n
                ),
                "triangle {k} {t:?} uses a vertex beyond the motion's {n}"
            );
        }
        let d = motion.duration();
        if !(d.is_finite() && d >= 0.0) {
            fail!(
                bound("motion duration", d),
                "motion duration {d} s: must be finite and ≥ 0"
            );
        }
        if looping && d <= 0.0 {
            fail!(
                bound("motion duration", d),
                "a looping motion needs a duration > 0 s"
            );
        }
        if !start.is_finite() {
            fail!(
                bound("motion start", start),
                "motion start {start} s: must be finite"
            );
        }
        let mut edge_of: HashMap<(u32, u32), u32> = HashMap::new();
        let tri_edges = tris
            .iter()
            .map(|t| {
                let mut e = [0u32; 3];
                for k in 0..3 {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    let next = edge_of.len() as u32;
                    e[k] = *edge_of.entry((a.min(b), a.max(b))).or_insert(next);
                }
                e
            })
            .collect();
        let z = vec![V::zeros(); n];
        let mut b = DeformingBody {
            motion,
            looping,
            start,
            held: false,
            clock: 0.0,
            tris,
            tri_edges,
            closed,
            x: z.clone(),
            prev: z.clone(),
            next: z.clone(),
            vel: z.clone(),
            face_rate: Vec::new(),
            prepared: None,
            face_n: Vec::new(),
            vertex_n: Vec::new(),
            edge_n: vec![V::zeros(); edge_of.len()],
            local: z,
            bvh: Bvh::default(),
        };
        b.pose_at(0.0, pose, true)?;
        b.x = b.next.clone();
        b.prev = b.x.clone();
        b.bvh = Bvh::build_with(b.tris.len(), |t| {
            let [i, j, k] = b.tris[t].map(|v| b.x[v as usize]);
            (i + j + k) / 3.0
        });
        refit(&mut b.bvh, &b.tris, &b.x, &b.x);
        b.normals();
        b.face_rate = vec![V::zeros(); b.tris.len()];
        Ok(b)
    }

    /// The motion's time for the body's clock `c`.
    fn motion_time(&self, c: f64) -> f64 {
        if self.held {
            return 0.0;
        }
        let d = self.motion.duration();
        let t = (c - self.start).max(0.0);
        if self.looping {
            t.rem_euclid(d)
        } else {
            t.min(d)
        }
    }

    /// The world positions at clock `c` under `pose` into `next`.
    fn pose_at(&mut self, c: f64, pose: &Isometry3<f64>, check: bool) -> Result<()> {
        let t = self.motion_time(c);
        self.motion.positions(t, &mut self.local);
        if check {
            if let Some(i) = self
                .local
                .iter()
                .position(|p| !p.iter().all(|c| c.is_finite()))
            {
                fail!(
                    non_finite("the motion's vertices", i),
                    "the motion gives vertex {i} a non-finite position {:?} at t = {t} s",
                    self.local[i]
                );
            }
        }
        for (o, p) in self.next.iter_mut().zip(&self.local) {
            *o = pose.rotation * p + pose.translation.vector;
        }
        Ok(())
    }

    /// Readies a step of length `h` ending with the obstacle at
    /// `pose_next`: the positions at its end, the vertices' velocities over
    /// it, the tree's boxes over it.
    pub fn prepare(&mut self, h: f64, pose_next: &Isometry3<f64>) -> Result<()> {
        self.pose_at(self.clock + h, pose_next, true)?;
        for i in 0..self.x.len() {
            self.vel[i] = (self.next[i] - self.x[i]) / h;
        }
        for (f, t) in self.tris.iter().enumerate() {
            let [a, b, c] = t.map(|i| self.next[i as usize]);
            let n1 = (b - a)
                .cross(&(c - a))
                .try_normalize(0.0)
                .unwrap_or_default();
            self.face_rate[f] = (n1 - self.face_n[f]) / h;
        }
        refit(&mut self.bvh, &self.tris, &self.x, &self.next);
        self.prepared = Some(h);
        Ok(())
    }

    /// Moves the body to the end of the step of length `h` (prepared with
    /// [`DeformingBody::prepare`], or now if it was not or for another
    /// length). The velocities stay those of the step just done until the
    /// next is prepared.
    pub fn advance(&mut self, h: f64, pose_next: &Isometry3<f64>) {
        if self.prepared != Some(h) {
            // positions were checked finite when the body was made; a
            // motion that gives a non-finite one later is refused by
            // `prepare`, which the simulation calls first
            let _ = self.prepare(h, pose_next);
        }
        std::mem::swap(&mut self.prev, &mut self.x);
        std::mem::swap(&mut self.x, &mut self.next);
        self.clock += h;
        self.prepared = None;
        self.normals();
    }

    /// Unit face normals, and for a closed mesh the angle-weighted vertex
    /// pseudo-normals and the edge pseudo-normals (sum of the two faces').
    fn normals(&mut self) {
        let x = &self.x;
        self.face_n.clear();
        self.face_n.extend(self.tris.iter().map(|t| {
            let [a, b, c] = t.map(|i| x[i as usize]);
            (b - a)
                .cross(&(c - a))
                .try_normalize(0.0)
                .unwrap_or_default()
        }));
        if !self.closed {
            return;
        }
        self.vertex_n.clear();
        self.vertex_n.resize(x.len(), V::zeros());
        self.edge_n.iter_mut().for_each(|n| *n = V::zeros());
        for (f, t) in self.tris.iter().enumerate() {
            let n = self.face_n[f];
            for k in 0..3 {
                let p = x[t[k] as usize];
                let u = x[t[(k + 1) % 3] as usize] - p;
                let w = x[t[(k + 2) % 3] as usize] - p;
                let angle = u.angle(&w);
                if angle.is_finite() {
                    self.vertex_n[t[k] as usize] += n * angle;
                }
                self.edge_n[self.tri_edges[f][k] as usize] += n;
            }
        }
    }

    /// Lets a held body move: its motion starts `start` s from now.
    pub fn release(&mut self) {
        if self.held {
            self.held = false;
            self.start += self.clock;
        }
    }

    /// Time from now to the end of the motion's play (of its first period,
    /// looping), s; 0 if it has ended.
    pub fn remaining(&self) -> f64 {
        (self.start + self.motion.duration() - self.clock).max(0.0)
    }

    /// Time since the body was made, s.
    pub fn clock(&self) -> f64 {
        self.clock
    }

    /// How the body moves.
    pub fn motion(&self) -> &Arc<dyn Motion> {
        &self.motion
    }

    /// Triangles, indices into the vertices.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.tris
    }

    /// Vertex positions now (world frame).
    pub fn positions(&self) -> &[V] {
        &self.x
    }

    /// Vertex velocities over the current step (world frame), m/s.
    pub fn velocities(&self) -> &[V] {
        &self.vel
    }

    /// Whether the mesh is closed (every edge shared by two triangles).
    pub fn closed(&self) -> bool {
        self.closed
    }

    /// Box holding the body over the current step.
    pub fn bounds(&self) -> (V, V) {
        let b = self.bvh.root();
        (b.lo, b.hi)
    }

    fn corners(&self, t: usize, x: &[V]) -> [V; 3] {
        self.tris[t].map(|i| x[i as usize])
    }

    /// Surface velocity at weights `w` of triangle `t`.
    pub fn velocity_on(&self, t: usize, w: [f64; 3]) -> V {
        let [a, b, c] = self.tris[t].map(|i| self.vel[i as usize]);
        a * w[0] + b * w[1] + c * w[2]
    }

    /// Point at weights `w` of triangle `t` now.
    pub fn point_on(&self, t: usize, w: [f64; 3]) -> V {
        let [a, b, c] = self.corners(t, &self.x);
        a * w[0] + b * w[1] + c * w[2]
    }

    /// Unit normal of triangle `t` now.
    pub fn face_normal(&self, t: usize) -> V {
        self.face_n[t]
    }

    /// For each triangle within `reach` of `p` (its box grown by `reach`
    /// meets `p`), `f` with its closest point to `p`: the triangle, the
    /// point, its face normal, and the velocity that surface carries `p`
    /// with (as in [`Closest::velocity`]).
    pub fn near(&self, p: &V, reach: f64, mut f: impl FnMut(usize, V, V, V)) {
        let r = V::repeat(reach);
        let q = Aabb {
            lo: p - r,
            hi: p + r,
        };
        self.bvh.overlapping(&q, |t| {
            let [a, b, c] = self.corners(t, &self.x);
            let w = point_triangle(p, &a, &b, &c);
            let point = a * w[0] + b * w[1] + c * w[2];
            let n = self.face_n[t];
            let velocity = self.velocity_on(t, w) + self.face_rate[t] * (p - point).dot(&n);
            f(t, point, n, velocity);
        });
    }

    /// Closest point of the surface now to `p`.
    pub fn closest(&self, p: &V) -> Closest {
        let (t, _) = self
            .bvh
            .nearest(p, |t| {
                let [a, b, c] = self.corners(t, &self.x);
                let w = point_triangle(p, &a, &b, &c);
                (p - (a * w[0] + b * w[1] + c * w[2])).norm_squared()
            })
            .expect("a body has triangles");
        let [a, b, c] = self.corners(t, &self.x);
        let w = point_triangle(p, &a, &b, &c);
        let point = a * w[0] + b * w[1] + c * w[2];
        // the feature the point lies on: its pseudo-normal decides the side
        let pseudo = if !self.closed {
            self.face_n[t]
        } else {
            let zero = w.map(|x| x == 0.0);
            match zero.iter().filter(|z| **z).count() {
                0 => self.face_n[t],
                1 => {
                    // the edge opposite the vertex of zero weight
                    let k = zero.iter().position(|z| *z).expect("one zero");
                    self.edge_n[self.tri_edges[t][(k + 1) % 3] as usize]
                }
                _ => {
                    let k = zero.iter().position(|z| !*z).unwrap_or(0);
                    self.vertex_n[self.tris[t][k] as usize]
                }
            }
        };
        let d = p - point;
        let dn = d.norm();
        let (distance, normal) = if dn > 1e-12 {
            if self.closed && d.dot(&pseudo) < 0.0 {
                (-dn, -d / dn)
            } else {
                (dn, d / dn)
            }
        } else {
            (0.0, pseudo.try_normalize(0.0).unwrap_or(self.face_n[t]))
        };
        Closest {
            triangle: t,
            weights: w,
            point,
            distance,
            normal,
            velocity: self.velocity_on(t, w) + self.face_rate[t] * d.dot(&self.face_n[t]),
        }
    }

    /// The first time within the step just done (positions at its start →
    /// now) at which a point moving linearly from `a` to `b` meets a
    /// triangle (within `tol`, m), if any: which triangle, where, and from
    /// which side. A point that starts in a triangle's plane is not counted
    /// as meeting it there.
    pub fn first_hit(&self, a: &V, b: &V, tol: f64) -> Option<Hit> {
        self.hit_between(a, b, tol, &self.prev, &self.x)
    }

    /// [`DeformingBody::first_hit`] with the triangles held where they are
    /// now.
    pub fn first_hit_static(&self, a: &V, b: &V) -> Option<Hit> {
        self.hit_between(a, b, HIT_TOLERANCE, &self.x, &self.x)
    }

    fn hit_between(&self, a: &V, b: &V, tol: f64, from: &[V], to: &[V]) -> Option<Hit> {
        let mut q = Aabb::empty();
        q.add(a);
        q.add(b);
        q.lo.add_scalar_mut(-tol);
        q.hi.add_scalar_mut(tol);
        let mut best: Option<Hit> = None;
        self.bvh.overlapping(&q, |t| {
            let [p0, p1, p2] = self.corners(t, from);
            let [q0, q1, q2] = self.corners(t, to);
            // f(s) = ((p1 − p0) × (p2 − p0)) · (x − p0) at time s: zero when
            // the point is in the triangle's plane
            let c = coplanarity_cubic([&p0, &p1, &p2, a], [&q0, &q1, &q2, b]);
            if c[0] == 0.0 {
                return;
            }
            let side = c[0].signum();
            let (roots, nr) = cubic_roots(c);
            for &s in &roots[..nr] {
                if s <= 0.0 || best.is_some_and(|h| s >= h.s) {
                    continue;
                }
                let at = |u: &V, v: &V| u + (v - u) * s;
                let (ta, tb, tc, x) = (at(&p0, &q0), at(&p1, &q1), at(&p2, &q2), at(a, b));
                let w = point_triangle(&x, &ta, &tb, &tc);
                let on = ta * w[0] + tb * w[1] + tc * w[2];
                if (x - on).norm() <= tol {
                    best = Some(Hit {
                        s,
                        triangle: t,
                        weights: w,
                        side,
                    });
                    break;
                }
            }
        });
        best
    }

    /// The motion's vertices now in the obstacle's frame (`pose` the
    /// obstacle's pose now).
    pub fn local_positions(&self, pose: &Isometry3<f64>) -> Vec<[f64; 3]> {
        let inv = pose.inverse();
        self.x
            .iter()
            .map(|p| {
                let q = inv.rotation * p + inv.translation.vector;
                [q.x, q.y, q.z]
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube() -> (Vec<V>, Vec<[u32; 3]>) {
        let v = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ]
        .map(V::from)
        .to_vec();
        let t = vec![
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
        (v, t)
    }

    #[test]
    fn keyframes_interpolate_linearly() {
        let f0 = vec![V::new(0.0, 0.0, 0.0)];
        let f1 = vec![V::new(1.0, 2.0, 0.0)];
        let f2 = vec![V::new(1.0, 2.0, 3.0)];
        let k = Keyframes::at_rate(10.0, vec![f0, f1, f2]).unwrap();
        let mut out = vec![V::zeros()];
        k.positions(0.025, &mut out);
        assert!((out[0] - V::new(0.25, 0.5, 0.0)).norm() < 1e-15);
        k.positions(0.15, &mut out);
        assert!((out[0] - V::new(1.0, 2.0, 1.5)).norm() < 1e-15);
        k.positions(5.0, &mut out);
        assert_eq!(out[0], V::new(1.0, 2.0, 3.0));
        assert!(Keyframes::at_rate(10.0, vec![vec![V::zeros()], vec![]]).is_err());
        assert!(Keyframes::at_rate(10.0, vec![vec![V::new(f64::NAN, 0.0, 0.0)]]).is_err());
    }

    /// The cube turning about the vertical through its centre at 2 rad/s,
    /// one frame per step: a point at height d above a side face (its foot
    /// inside the face) has the velocity of the material point of the
    /// turning cube that is there, the chord of the rotation over the step
    /// ((R p − p) / h), not the skin's at its foot (which differs by
    /// ω d); before and after the step is taken.
    #[test]
    fn turning_cube_carries_a_point_above_its_face() {
        let (v, t) = cube();
        let (omega, h) = (2.0, 0.01);
        let centre = V::new(0.5, 0.5, 0.0);
        let turn = |k: usize| {
            let r = nalgebra::Rotation3::from_axis_angle(&V::z_axis(), omega * h * k as f64);
            move |p: &V| centre + r * (p - centre)
        };
        let frames = (0..4).map(|k| v.iter().map(turn(k)).collect()).collect();
        let m = Arc::new(Keyframes::at_rate(1.0 / h, frames).unwrap());
        let mut b = DeformingBody::new(m, t, true, &Isometry3::identity(), false, 0.0).unwrap();
        b.prepare(h, &Isometry3::identity()).unwrap();
        // 3 cm out from the face x = 1, off its centre
        let p = V::new(1.03, 0.3, 0.6);
        let c = b.closest(&p);
        assert!((c.distance - 0.03).abs() < 1e-12, "{}", c.distance);
        let chord = (turn(1)(&p) - p) / h;
        assert!(
            (c.velocity - chord).norm() < 1e-12,
            "{} {}",
            c.velocity,
            chord
        );
        // the skin's velocity at the foot alone is slower by ω d
        let foot = b.velocity_on(c.triangle, c.weights);
        assert!(
            ((chord - foot).norm() - omega * 0.03).abs() < 1e-3,
            "{}",
            (chord - foot).norm()
        );
        // after the step: the velocities of the step just done, at the
        // point's place in the turned cube
        b.advance(h, &Isometry3::identity());
        let q = turn(1)(&p);
        let c = b.closest(&q);
        assert!(
            (c.velocity - chord).norm() < 1e-12,
            "{} {}",
            c.velocity,
            chord
        );
    }

    /// The cube moving down at 1 m/s: the velocity over a step, the signed
    /// distance of points outside, inside and past an edge, and a point
    /// that the sinking bottom face sweeps over.
    #[test]
    fn moving_cube_velocity_distance_and_hit() {
        let (v, t) = cube();
        let down: Vec<V> = v.iter().map(|p| p - V::new(0.0, 0.0, 1.0)).collect();
        let m = Arc::new(Keyframes::new(vec![0.0, 1.0], vec![v, down]).unwrap());
        let mut b = DeformingBody::new(m, t, true, &Isometry3::identity(), false, 0.0).unwrap();
        let h = 0.1;
        b.prepare(h, &Isometry3::identity()).unwrap();
        let c = b.closest(&V::new(0.5, 0.5, 1.5));
        assert!((c.distance - 0.5).abs() < 1e-12);
        assert!((c.velocity - V::new(0.0, 0.0, -1.0)).norm() < 1e-12);
        let inside = b.closest(&V::new(0.5, 0.4, 0.3));
        assert!((inside.distance + 0.3).abs() < 1e-12, "{}", inside.distance);
        assert!((inside.normal + V::z()).norm() < 1e-12);
        // beyond the edge x = 1, z = 1: closest on the edge, outside
        let e = b.closest(&V::new(1.3, 0.5, 1.4));
        assert!((e.distance - 0.5).abs() < 1e-12);
        b.advance(h, &Isometry3::identity());
        // the bottom face sank from z = 0 to −0.1: a point resting at
        // z = −0.05 below it was met half way, from outside
        let p = V::new(0.3, 0.6, -0.05);
        let hit = b.first_hit(&p, &p, 1e-9).unwrap();
        assert!((hit.s - 0.5).abs() < 1e-9, "{}", hit.s);
        assert_eq!(hit.side, 1.0);
        assert!((b.point_on(hit.triangle, hit.weights) - V::new(0.3, 0.6, -0.1)).norm() < 1e-9);
        // the same point moving down with the face is never met
        assert!(b
            .first_hit(&p, &(p - V::new(0.0, 0.0, 0.1)), 1e-9)
            .is_none());
        // a point beside the cube is never met
        assert!(b
            .first_hit(&V::new(2.0, 0.5, 0.0), &V::new(2.0, 0.5, 0.1), 1e-9)
            .is_none());
    }
}
