//! Scene obstacles as `parry` shapes with a pose, a thickness and a Coulomb
//! friction coefficient, static or moving with a prescribed velocity
//! (thesis §3.3, §6.4.1.2: objects are thickened for robust contact), or
//! triangle meshes whose vertices move ([`crate::deforming`]).

use crate::deforming::{DeformingBody, Motion};
use crate::error::{fail, Result};
use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};
use parry3d_f64::query::{PointQueryWithLocation, Ray};
use parry3d_f64::shape::{
    Ball, Capsule, Cone, Cuboid, Cylinder, SharedShape, TriMesh, TriMeshFlags,
};
use serde::{Deserialize, Serialize};

/// Default obstacle thickness (thesis §6.4.1.2: the table is thickened by 6 mm).
pub const DEFAULT_OBSTACLE_THICKNESS: f64 = 0.006;
/// Default cloth thickness (thesis: 2 mm).
pub const DEFAULT_CLOTH_THICKNESS: f64 = 0.002;
/// Default Coulomb friction coefficient of an obstacle.
pub const DEFAULT_FRICTION: f64 = 0.3;
/// Vertices (m) and triangles of a mesh.
pub type MeshData = (Vec<[f64; 3]>, Vec<[u32; 3]>);

/// Largest triangle mesh accepted for an obstacle.
pub const MAX_MESH_TRIANGLES: usize = 2_000_000;

/// Geometry of an obstacle, in its own frame. Cylinders, cones and capsules
/// have their axis along local z (as shape_msgs/SolidPrimitive).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
    /// Box with full side lengths, m.
    Box {
        /// Side lengths, m.
        size: [f64; 3],
    },
    /// Sphere.
    Sphere {
        /// Radius, m.
        radius: f64,
    },
    /// Capsule: cylinder of `length` between the centres of its end caps.
    Capsule {
        /// Length between the end caps' centres, m.
        length: f64,
        /// Radius, m.
        radius: f64,
    },
    /// Cylinder along its frame's z axis.
    Cylinder {
        /// Height, m.
        height: f64,
        /// Radius, m.
        radius: f64,
    },
    /// Cone along its frame's z axis.
    Cone {
        /// Height, m.
        height: f64,
        /// Radius of the base, m.
        radius: f64,
    },
    /// Triangle mesh (vertices in m, in the obstacle frame): read from an OBJ
    /// file by the scene loader, or given in a message.
    #[serde(skip)]
    Triangles {
        /// Vertices in the obstacle's frame, m.
        vertices: Vec<[f64; 3]>,
        /// Triangles, indices into `vertices`.
        triangles: Vec<[u32; 3]>,
    },
}

#[derive(Clone)]
/// A rigid obstacle the cloth collides with: a shape, its pose and
/// velocity, its thickness and friction.
pub struct Obstacle {
    /// Its name.
    pub id: String,
    /// The shape as specified.
    pub spec: ShapeSpec,
    /// The shape as the contact queries use it.
    pub shape: SharedShape,
    /// Pose of the obstacle frame.
    pub pose: Isometry3<f64>,
    /// Pose of the parry shape (pose × axis fix for z-axis primitives).
    shape_pose_offset: Isometry3<f64>,
    /// Linear velocity of the obstacle frame's origin, m/s.
    pub linear_velocity: Vector3<f64>,
    /// Angular velocity about the obstacle frame's origin, rad/s (world axes).
    pub angular_velocity: Vector3<f64>,
    /// Thickness the cloth keeps from its surface, m.
    pub thickness: f64,
    /// Coulomb friction coefficient against the cloth.
    pub friction: f64,
    /// Mesh data for visualisation (vertices in the obstacle frame).
    pub mesh: Option<MeshData>,
    /// A triangle mesh every edge of which two triangles share: it has an
    /// inside (found with the mesh's pseudo-normals), like the primitives.
    pub closed: bool,
    /// A mesh whose vertices move (see [`Obstacle::with_motion`]): its
    /// queries read it, not `shape` (the mesh at the motion's start).
    deforming: Option<Box<DeformingBody>>,
}

impl std::fmt::Debug for Obstacle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Obstacle")
            .field("id", &self.id)
            .field("spec", &self.spec)
            .field("pose", &self.pose)
            .finish()
    }
}

/// Cosine of the least angle between two contact normals for the two
/// surfaces to hold a vertex together, in a crease (30°): closer normals are
/// one surface, bent, and hold it along the nearer one's normal alone.
pub const CREASE_COS: f64 = 0.866_025_403_784_438_6;

/// Whether the surfaces of contacts `a` and `b` of one point make a crease:
/// their normals differ by more than 30° ([`CREASE_COS`]) and each closest
/// point lies in front of the other's tangent plane by more than `eps`, m (a
/// concave fold: the neighbouring faces of a flat or convex surface, whose
/// closest points lie on or behind the other's plane, do not).
pub fn crease_between(a: &Proximity, b: &Proximity, eps: f64) -> bool {
    a.normal.dot(&b.normal) < CREASE_COS
        && (b.point - a.point).dot(&a.normal) > eps
        && (a.point - b.point).dot(&b.normal) > eps
}

/// Closest-feature answer of a point query.
#[derive(Debug, Clone, Copy)]
pub struct Proximity {
    /// Signed distance to the obstacle's surface (negative inside), m.
    pub distance: f64,
    /// Outward unit normal at the closest point.
    pub normal: Vector3<f64>,
    /// Closest point on the surface.
    pub point: Vector3<f64>,
    /// Velocity of the point at the queried position carried by the
    /// obstacle (its rigid motion there; a deforming mesh: its closest
    /// triangle's surface velocity plus the normal's rate times the height):
    /// a cloth vertex held in contact rides the contact distance above the
    /// skin and moves with it so.
    pub velocity: Vector3<f64>,
}

impl Obstacle {
    /// An obstacle of shape `spec` at `pose`, at rest.
    pub fn new(
        id: &str,
        spec: ShapeSpec,
        pose: Isometry3<f64>,
        thickness: f64,
        friction: f64,
    ) -> Result<Obstacle> {
        use crate::limits::{self, MAX_FRICTION, MAX_OBSTACLE_THICKNESS};
        limits::check_range(
            &format!("obstacle {id:?}: thickness"),
            thickness,
            0.0,
            MAX_OBSTACLE_THICKNESS,
            "m",
            "MAX_OBSTACLE_THICKNESS, the contact layer around the surface",
        )?;
        limits::check_range(
            &format!("obstacle {id:?}: friction"),
            friction,
            0.0,
            MAX_FRICTION,
            "",
            "MAX_FRICTION, a Coulomb coefficient",
        )?;
        let pos = |name: &str, v: f64| -> Result<()> {
            limits::check_size(&format!("obstacle {id:?}: {name}"), v)
        };
        // parry's cylinder, cone and capsule are along y; ROS primitives along z.
        let y_to_z = Isometry3::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::FRAC_PI_2),
        );
        let mut mesh = None;
        let (shape, offset) = match &spec {
            ShapeSpec::Box { size } => {
                for (k, s) in size.iter().enumerate() {
                    pos(&format!("size[{k}]"), *s)?;
                }
                (
                    SharedShape::new(Cuboid::new(Vector3::new(size[0], size[1], size[2]) / 2.0)),
                    Isometry3::identity(),
                )
            }
            ShapeSpec::Sphere { radius } => {
                pos("radius", *radius)?;
                (SharedShape::new(Ball::new(*radius)), Isometry3::identity())
            }
            ShapeSpec::Capsule { length, radius } => {
                pos("length", *length)?;
                pos("radius", *radius)?;
                (
                    SharedShape::new(Capsule::new_z(length / 2.0, *radius)),
                    Isometry3::identity(),
                )
            }
            ShapeSpec::Cylinder { height, radius } => {
                pos("height", *height)?;
                pos("radius", *radius)?;
                (
                    SharedShape::new(Cylinder::new(height / 2.0, *radius)),
                    y_to_z,
                )
            }
            ShapeSpec::Cone { height, radius } => {
                pos("height", *height)?;
                pos("radius", *radius)?;
                (SharedShape::new(Cone::new(height / 2.0, *radius)), y_to_z)
            }
            ShapeSpec::Triangles {
                vertices,
                triangles,
            } => {
                let s = trimesh(id, vertices, triangles)?;
                mesh = Some((vertices.clone(), triangles.clone()));
                (s, Isometry3::identity())
            }
        };
        Ok(Obstacle {
            id: id.to_string(),
            spec,
            shape,
            pose,
            shape_pose_offset: offset,
            linear_velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            thickness,
            friction,
            closed: mesh.as_ref().is_some_and(|(_, t)| is_closed(t)),
            mesh,
            deforming: None,
        })
    }

    /// A triangle mesh of `triangles` whose vertices (in the obstacle's
    /// frame, placed by `pose`) follow `motion`: from `start` s after the
    /// obstacle is made (holding its first pose until then), to its end
    /// (then holding its last), or over and over with `looping`. The
    /// obstacle's linear and angular velocity, if set, move its frame as
    /// they move a rigid obstacle's.
    #[allow(clippy::too_many_arguments)]
    pub fn with_motion(
        id: &str,
        triangles: Vec<[u32; 3]>,
        motion: std::sync::Arc<dyn Motion>,
        looping: bool,
        start: f64,
        pose: Isometry3<f64>,
        thickness: f64,
        friction: f64,
    ) -> Result<Obstacle> {
        let n = motion.vertex_count();
        let mut first = vec![Vector3::zeros(); n];
        motion.positions(0.0, &mut first);
        let vertices: Vec<[f64; 3]> = first.iter().map(|p| [p.x, p.y, p.z]).collect();
        let mut o = Obstacle::new(
            id,
            ShapeSpec::Triangles {
                vertices,
                triangles: triangles.clone(),
            },
            pose,
            thickness,
            friction,
        )?;
        let body = DeformingBody::new(motion, triangles, o.closed, &pose, looping, start)
            .map_err(|e| e.context(format!("obstacle {id:?}")))?;
        o.deforming = Some(Box::new(body));
        Ok(o)
    }

    /// The moving mesh of an obstacle made with [`Obstacle::with_motion`].
    pub fn deforming(&self) -> Option<&DeformingBody> {
        self.deforming.as_deref()
    }

    /// A triangle-mesh obstacle's vertices where they are now (world),
    /// appended to `out`, and its triangles; `None` (nothing appended) for
    /// a primitive.
    pub fn world_mesh_into(&self, out: &mut Vec<Vector3<f64>>) -> Option<&[[u32; 3]]> {
        match (self.deforming(), &self.spec, &self.mesh) {
            (Some(d), _, _) => out.extend_from_slice(d.positions()),
            (None, ShapeSpec::Triangles { .. }, Some((v, _))) => out.extend(
                v.iter()
                    .map(|p| (self.pose * Point3::from(Vector3::from(*p))).coords),
            ),
            _ => return None,
        }
        self.mesh_triangles()
    }

    /// A triangle-mesh obstacle's triangles (`None` for a primitive).
    pub fn mesh_triangles(&self) -> Option<&[[u32; 3]]> {
        match (self.deforming(), &self.spec, &self.mesh) {
            (Some(d), _, _) => Some(d.triangles()),
            (None, ShapeSpec::Triangles { .. }, Some((_, t))) => Some(t),
            _ => None,
        }
    }

    /// The moving mesh, to change its start or looping.
    pub fn deforming_mut(&mut self) -> Option<&mut DeformingBody> {
        self.deforming.as_deref_mut()
    }

    /// Readies a step of length `dt`: a deforming mesh takes its positions at
    /// the step's end and its vertices' velocities over the step (a rigid
    /// obstacle has nothing to do). Refuses a motion that gives a
    /// non-finite position.
    pub fn begin_step(&mut self, dt: f64) -> Result<()> {
        if self.deforming.is_none() {
            return Ok(());
        }
        let next = self.pose_after(dt);
        let id = self.id.clone();
        let b = self.deforming.as_deref_mut().expect("deforming");
        b.prepare(dt, &next)
            .map_err(|e| e.context(format!("obstacle {id:?}")))
    }

    /// The deepest cloth vertex inside this obstacle's shape (not its
    /// thickened layer): `(vertex, depth in m)`, or `None` if every vertex is
    /// outside.
    pub fn deepest_inside(&self, x: &[Vector3<f64>]) -> Option<(usize, f64)> {
        let (lo, hi) = self.bounds(0.0);
        let mut worst: Option<(usize, f64)> = None;
        for (i, p) in x.iter().enumerate() {
            if (0..3).any(|a| p[a] < lo[a] || p[a] > hi[a]) {
                continue;
            }
            let mut d = -self.proximity(p).distance;
            if d == 0.0 {
                // a point at a ball's centre has no closest surface point: the
                // query reads it as on the surface; a point beside it does not
                d = -self.proximity(&(p + Vector3::new(1e-9, 0.0, 0.0))).distance;
            }
            if d > 0.0 && worst.is_none_or(|(_, w)| d > w) {
                worst = Some((i, d));
            }
        }
        worst
    }

    /// Refuses this obstacle where it lies with a cloth vertex deeper than
    /// [`crate::limits::MAX_OVERLAP`] inside it, naming the obstacle, the
    /// vertex and the depth. Open triangle meshes are not checked: they have
    /// no inside.
    pub fn check_overlap(&self, x: &[Vector3<f64>]) -> Result<()> {
        use crate::limits::MAX_OVERLAP;
        if matches!(self.spec, ShapeSpec::Triangles { .. }) && !self.closed {
            return Ok(());
        }
        if let Some((i, d)) = self.deepest_inside(x) {
            if d > MAX_OVERLAP {
                fail!(
                    placement,
                    "obstacle {:?} overlaps the cloth: vertex {i} at ({:.4}, {:.4}, {:.4}) m lies \
                     {d:.4} m inside it, more than {MAX_OVERLAP} m (MAX_OVERLAP; the contacts \
                     would throw the cloth out): place the cloth or the obstacle apart",
                    self.id,
                    x[i].x,
                    x[i].y,
                    x[i].z
                );
            }
        }
        Ok(())
    }

    /// Signed distance, outward normal and closest point of the surface to
    /// `p`, and the velocity the obstacle carries `p` with.
    /// A point that is not finite has no nearest surface: its distance
    /// and the rest are NaN.
    pub fn proximity(&self, p: &Vector3<f64>) -> Proximity {
        if !p.iter().all(|c| c.is_finite()) {
            let nan = Vector3::repeat(f64::NAN);
            return Proximity {
                distance: f64::NAN,
                normal: nan,
                point: nan,
                velocity: nan,
            };
        }
        if let Some(b) = &self.deforming {
            let c = b.closest(p);
            return Proximity {
                distance: c.distance,
                normal: c.normal,
                point: c.point,
                velocity: c.velocity,
            };
        }
        let iso = self.pose * self.shape_pose_offset;
        let pt = Point3::from(*p);
        let proj = match self.shape.as_trimesh() {
            // parry's plain projection of a mesh never says "inside"; the
            // located one does, from the pseudo-normals of an oriented mesh
            Some(m) if self.closed => m.project_point_and_get_location(&iso, &pt, false).0,
            _ => self.shape.project_point(&iso, &pt, false),
        };
        let c = proj.point.coords;
        let d = p - c;
        let dn = d.norm();
        let (distance, normal) = if dn > 1e-12 {
            if proj.is_inside {
                (-dn, -d / dn)
            } else {
                (dn, d / dn)
            }
        } else {
            // on the surface: take the direction from the shape's centre
            let dir = p - iso.translation.vector;
            let n = if dir.norm() > 1e-12 {
                dir.normalize()
            } else {
                Vector3::z()
            };
            (0.0, n)
        };
        let velocity = self.velocity_at(p);
        Proximity {
            distance,
            normal,
            point: c,
            velocity,
        }
    }

    /// A triangle mesh's other surfaces near `p`, besides the nearest one
    /// `first` ([`Obstacle::proximity`]): for each triangle within `reach`
    /// (m) of `p` that `p` is in front of (either side of an open mesh), its
    /// closest point as a [`Proximity`] whose normal points from that point
    /// to `p`, kept where it makes a crease with `first` ([`crease_between`]
    /// within `eps`, m), appended to `out` nearest first. Primitives (convex)
    /// have none.
    pub fn crease_surfaces(
        &self,
        p: &Vector3<f64>,
        first: &Proximity,
        reach: f64,
        eps: f64,
        out: &mut Vec<Proximity>,
    ) {
        let start = out.len();
        let closed = self.closed;
        let mut keep = |point: Vector3<f64>, face: Vector3<f64>, velocity: Vector3<f64>| {
            let d = p - point;
            let dn = d.norm();
            if !(dn > 1e-12 && dn <= reach) || (closed && d.dot(&face) <= 0.0) {
                return;
            }
            let pr = Proximity {
                distance: dn,
                normal: d / dn,
                point,
                velocity,
            };
            if crease_between(first, &pr, eps) {
                out.push(pr);
            }
        };
        if let Some(b) = &self.deforming {
            b.near(p, reach, |_, point, face, velocity| {
                keep(point, face, velocity)
            });
        } else if let Some(m) = self.shape.as_trimesh() {
            let iso = self.pose * self.shape_pose_offset;
            let local = iso.inverse_transform_point(&Point3::from(*p));
            let r = Vector3::repeat(reach);
            let aabb = parry3d_f64::bounding_volume::Aabb::new(local - r, local + r);
            let velocity = self.velocity_at(p);
            for t in m.bvh().intersect_aabb(&aabb) {
                let tri = m.triangle(t);
                let (a, b, c) = (tri.a.coords, tri.b.coords, tri.c.coords);
                let w = crate::self_contact::geometry::point_triangle(&local.coords, &a, &b, &c);
                let q = a * w[0] + b * w[1] + c * w[2];
                let Some(face) = (b - a).cross(&(c - a)).try_normalize(0.0) else {
                    continue;
                };
                keep(
                    (iso * Point3::from(q)).coords,
                    iso.rotation * face,
                    velocity,
                );
            }
        }
        out[start..].sort_by(|a, b| a.distance.total_cmp(&b.distance));
    }

    /// Velocity of the obstacle's material at `p` (world frame), m/s.
    /// (A deforming mesh: the velocity of its surface point closest to `p`.)
    pub fn velocity_at(&self, p: &Vector3<f64>) -> Vector3<f64> {
        if let Some(b) = &self.deforming {
            return b.closest(p).velocity;
        }
        self.linear_velocity
            + self
                .angular_velocity
                .cross(&(p - self.pose.translation.vector))
    }

    /// Where the segment `a → b` (world frame, the obstacle where it is now)
    /// first enters the obstacle's own shape (not thickened): the fraction of
    /// the segment and the outward normal of the face it crosses. `None` when
    /// it does not reach the shape, or starts inside it. (A deforming mesh:
    /// its triangles where they are now, met from either side.)
    pub fn first_crossing(
        &self,
        a: &Vector3<f64>,
        b: &Vector3<f64>,
    ) -> Option<(f64, Vector3<f64>)> {
        if let Some(m) = &self.deforming {
            let hit = m.first_hit_static(a, b)?;
            return Some((hit.s, m.face_normal(hit.triangle) * hit.side));
        }
        let iso = self.pose * self.shape_pose_offset;
        let d = b - a;
        let ray = Ray::new(Point3::from(*a), d);
        let hit = self.shape.cast_ray_and_get_normal(&iso, &ray, 1.0, true)?;
        if hit.time_of_impact <= 0.0 || hit.normal.norm_squared() < 0.5 {
            return None;
        }
        // the face the segment enters faces it (a mesh hit from behind
        // reports the face's own normal)
        let n = if hit.normal.dot(&d) > 0.0 {
            -hit.normal
        } else {
            hit.normal
        };
        Some((hit.time_of_impact, n))
    }

    /// World-space bounding box grown by `margin` (broad phase: a point outside
    /// it is farther than `margin` from the obstacle).
    /// (A deforming mesh: over the current step.)
    pub fn bounds(&self, margin: f64) -> ([f64; 3], [f64; 3]) {
        if let Some(b) = &self.deforming {
            let (a, b) = b.bounds();
            return (
                [a.x - margin, a.y - margin, a.z - margin],
                [b.x + margin, b.y + margin, b.z + margin],
            );
        }
        let aabb = self
            .shape
            .compute_aabb(&(self.pose * self.shape_pose_offset));
        let (a, b) = (aabb.mins, aabb.maxs);
        (
            [a.x - margin, a.y - margin, a.z - margin],
            [b.x + margin, b.y + margin, b.z + margin],
        )
    }

    /// Advances a moving obstacle by its prescribed velocity over `dt`, and
    /// a deforming mesh to its positions at the end of the step.
    pub fn advance(&mut self, dt: f64) {
        let next = self.pose_after(dt);
        if let Some(b) = self.deforming.as_deref_mut() {
            b.advance(dt, &next);
        }
        self.pose = next;
    }

    /// The pose after `dt` at the prescribed velocities.
    fn pose_after(&self, dt: f64) -> Isometry3<f64> {
        if self.linear_velocity == Vector3::zeros() && self.angular_velocity == Vector3::zeros() {
            return self.pose;
        }
        let rot = UnitQuaternion::from_scaled_axis(self.angular_velocity * dt);
        let t = self.pose.translation.vector;
        Isometry3::from_parts(
            Translation3::from(t + self.linear_velocity * dt),
            rot * self.pose.rotation,
        )
    }

    /// Surface triangles in the obstacle's own frame (for markers and exports):
    /// primitives tessellated, meshes as given.
    /// A deforming mesh: where its vertices are now.
    pub fn local_triangles(&self) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        if let Some(b) = &self.deforming {
            return (b.local_positions(&self.pose), b.triangles().to_vec());
        }
        if let Some((v, t)) = &self.mesh {
            return (v.clone(), t.clone());
        }
        let (pts, tris) = if let Some(s) = self.shape.as_cuboid() {
            s.to_trimesh()
        } else if let Some(s) = self.shape.as_ball() {
            s.to_trimesh(16, 32)
        } else if let Some(s) = self.shape.as_capsule() {
            s.to_trimesh(16, 8)
        } else if let Some(s) = self.shape.as_cylinder() {
            s.to_trimesh(32)
        } else if let Some(s) = self.shape.as_cone() {
            s.to_trimesh(32)
        } else {
            (Vec::new(), Vec::new())
        };
        let v = pts
            .iter()
            .map(|p| {
                let q = self.shape_pose_offset * p;
                [q.x, q.y, q.z]
            })
            .collect();
        (v, tris)
    }
}

/// Is every edge of the triangles shared by exactly two of them?
pub fn is_closed(t: &[[u32; 3]]) -> bool {
    let mut edges: std::collections::HashMap<(u32, u32), u32> = Default::default();
    for tri in t {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    !t.is_empty() && edges.values().all(|&c| c == 2)
}

fn trimesh(id: &str, v: &[[f64; 3]], t: &[[u32; 3]]) -> Result<SharedShape> {
    if t.is_empty() {
        fail!(mesh, "obstacle {id:?}: mesh has no triangles");
    }
    if t.len() > MAX_MESH_TRIANGLES {
        fail!(
            too_large,
            "obstacle {id:?}: mesh has {} triangles, more than the limit {MAX_MESH_TRIANGLES}",
            t.len()
        );
    }
    for (k, tri) in t.iter().enumerate() {
        for &i in tri {
            if i as usize >= v.len() {
                fail!(
                    index("vertex", i as usize, v.len()),
                    "obstacle {id:?}: triangle {k} uses vertex {i} but the mesh has {} vertices",
                    v.len()
                );
            }
        }
    }
    for (k, p) in v.iter().enumerate() {
        if p.iter().any(|c| !c.is_finite()) {
            fail!(
                non_finite(format!("obstacle {id:?}: mesh vertex {k}"), k),
                "obstacle {id:?}: mesh vertex {k} is not finite: {p:?}"
            );
        }
        let r = Vector3::from(*p).norm();
        if r > crate::limits::MAX_OBSTACLE_SIZE {
            fail!(
                bound(format!("obstacle {id:?}: mesh vertex {k}"), r),
                "obstacle {id:?}: mesh vertex {k} = {p:?} lies {r:.3e} m from the obstacle's \
                 origin, more than {} m (MAX_OBSTACLE_SIZE; a mesh in mm?)",
                crate::limits::MAX_OBSTACLE_SIZE
            );
        }
    }
    let pts: Vec<Point3<f64>> = v.iter().map(|p| Point3::new(p[0], p[1], p[2])).collect();
    let m = TriMesh::with_flags(
        pts.clone(),
        t.to_vec(),
        TriMeshFlags::ORIENTED | TriMeshFlags::MERGE_DUPLICATE_VERTICES,
    )
    .or_else(|_| TriMesh::new(pts, t.to_vec()))
    .map_err(|e| crate::Error::mesh(format!("obstacle {id:?}: bad triangle mesh: {e:?}")))?;
    Ok(SharedShape::new(m))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segments_entering_a_box_give_the_entry_face() {
        let b = Obstacle::new(
            "b",
            ShapeSpec::Box {
                size: [0.3, 0.2, 0.01],
            },
            Isometry3::translation(0.0, 0.0, 0.5),
            0.006,
            0.3,
        )
        .unwrap();
        // (from, to, fraction at the entry, the entered face's normal)
        for (from, to, t_entry, normal) in [
            // straight through the 1 cm plate from 2 cm above: the top face a
            // quarter of the way along (0.02 − 0.005 of 0.06 m)
            ([0.01, 0.02, 0.52], [0.01, 0.02, 0.46], 0.25, Vector3::z()),
            // slanted through the side face x = 0.15 from outside
            ([0.17, 0.0, 0.5], [0.13, 0.0, 0.501], 0.5, Vector3::x()),
            // from below: the bottom face (0.015 of 0.12 m), facing down
            ([0.0, 0.0, 0.48], [0.0, 0.0, 0.6], 0.125, -Vector3::z()),
        ] {
            let (t, n) = b
                .first_crossing(&Vector3::from(from), &Vector3::from(to))
                .unwrap();
            assert!((t - t_entry).abs() < 1e-12, "t = {t}");
            assert!((n - normal).norm() < 1e-12, "n = {n}");
        }
        // sliding over the top at the contact distance, short of it, and from inside: none
        assert!(b
            .first_crossing(
                &Vector3::new(-0.1, 0.0, 0.513),
                &Vector3::new(0.1, 0.0, 0.513)
            )
            .is_none());
        assert!(b
            .first_crossing(
                &Vector3::new(0.0, 0.0, 0.52),
                &Vector3::new(0.0, 0.0, 0.506)
            )
            .is_none());
        assert!(b
            .first_crossing(&Vector3::new(0.0, 0.0, 0.5), &Vector3::new(0.0, 0.0, 0.6))
            .is_none());
        // a single triangle (an open mesh) crossed from its back: the normal
        // faces the segment's start
        let tri = Obstacle::new(
            "t",
            ShapeSpec::Triangles {
                vertices: vec![[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 1.0, 0.0]],
                triangles: vec![[0, 1, 2]],
            },
            Isometry3::identity(),
            0.0,
            0.0,
        )
        .unwrap();
        for dir in [1.0, -1.0] {
            let (t, n) = tri
                .first_crossing(
                    &Vector3::new(0.0, 0.0, -0.1 * dir),
                    &Vector3::new(0.0, 0.0, 0.3 * dir),
                )
                .unwrap();
            assert!((t - 0.25).abs() < 1e-12, "t = {t}");
            assert!((n + Vector3::z() * dir).norm() < 1e-12, "n = {n}");
        }
    }

    #[test]
    fn box_and_sphere_distances() {
        let b = Obstacle::new(
            "b",
            ShapeSpec::Box {
                size: [0.3, 0.2, 0.005],
            },
            Isometry3::identity(),
            0.006,
            0.3,
        )
        .unwrap();
        let p = b.proximity(&Vector3::new(0.0, 0.0, 0.01));
        assert!((p.distance - 0.0075).abs() < 1e-12);
        assert!((p.normal - Vector3::z()).norm() < 1e-12);
        let q = b.proximity(&Vector3::new(0.0, 0.0, 0.001));
        assert!((q.distance + 0.0015).abs() < 1e-12);
        assert!((q.normal - Vector3::z()).norm() < 1e-12);
        let s = Obstacle::new(
            "s",
            ShapeSpec::Sphere { radius: 0.1 },
            Isometry3::identity(),
            0.0,
            0.0,
        )
        .unwrap();
        assert!((s.proximity(&Vector3::new(0.0, 0.3, 0.0)).distance - 0.2).abs() < 1e-12);
        // cylinder axis along z
        let c = Obstacle::new(
            "c",
            ShapeSpec::Cylinder {
                height: 1.0,
                radius: 0.1,
            },
            Isometry3::identity(),
            0.0,
            0.0,
        )
        .unwrap();
        assert!((c.proximity(&Vector3::new(0.0, 0.0, 0.6)).distance - 0.1).abs() < 1e-9);
        assert!((c.proximity(&Vector3::new(0.3, 0.0, 0.0)).distance - 0.2).abs() < 1e-9);
    }

    #[test]
    fn moving_obstacle_velocity() {
        let mut s = Obstacle::new(
            "s",
            ShapeSpec::Sphere { radius: 0.1 },
            Isometry3::identity(),
            0.0,
            0.0,
        )
        .unwrap();
        s.linear_velocity = Vector3::new(1.0, 0.0, 0.0);
        s.advance(0.5);
        assert!((s.pose.translation.vector.x - 0.5).abs() < 1e-12);
        s.angular_velocity = Vector3::new(0.0, 0.0, 2.0);
        let p = s.proximity(&Vector3::new(0.5, 1.0, 0.0));
        assert!((p.point - Vector3::new(0.5, 0.1, 0.0)).norm() < 1e-12);
        // the sphere carries the point (0.5, 1, 0), 0.9 m above its surface:
        // v = (1,0,0) + (0,0,2)×(0,1,0) = (−1, 0, 0); its skin below moves at
        // (1,0,0) + (0,0,2)×(0,0.1,0) = (0.8, 0, 0)
        assert!((p.velocity - Vector3::new(-1.0, 0.0, 0.0)).norm() < 1e-12);
        assert!((s.velocity_at(&p.point) - Vector3::new(0.8, 0.0, 0.0)).norm() < 1e-12);
    }
}

#[cfg(test)]
mod mesh_inside {
    use super::*;

    /// A closed, outward-oriented triangle mesh has an inside: a point in it
    /// is at a negative distance.
    #[test]
    fn a_closed_mesh_has_an_inside() {
        let v = vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
            [0.0, 1.0, 1.0],
        ];
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
        let o = Obstacle::new(
            "cube",
            ShapeSpec::Triangles {
                vertices: v,
                triangles: t,
            },
            Isometry3::identity(),
            0.0,
            0.0,
        )
        .unwrap();
        let p = o.proximity(&Vector3::new(0.5, 0.5, 0.3));
        assert!((p.distance + 0.3).abs() < 1e-12, "{}", p.distance);
        assert!((p.normal + Vector3::z()).norm() < 1e-12, "{}", p.normal);
        let q = o.proximity(&Vector3::new(0.5, 0.5, 1.2));
        assert!((q.distance - 0.2).abs() < 1e-12, "{}", q.distance);
    }
}
