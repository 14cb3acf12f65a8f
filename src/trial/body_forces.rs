//! Forces of the garment on the person: the total force and torque (the
//! wrench) the cloth exerts on one obstacle, and the pressure it puts on each
//! vertex of that obstacle's mesh, from the contact forces of the last step
//! ([`Simulation::contact_forces`]). Computed on demand, outside the step.
//!
//! Each cloth vertex in contact is given to the obstacle whose contact layer
//! is nearest to it: the smallest `distance − (thickness + cloth thickness)`,
//! the measure the solver chooses its contact by. The force on the obstacle
//! is the opposite of the contact's force on the cloth (normal reaction and
//! friction), applied at the closest point of the obstacle's surface; the
//! torque is about the origin of the obstacle's frame (its pose).
//!
//! The pressure on the body: each contact's normal force (its force on the
//! cloth along the body's outward normal, never pulling) goes to the three
//! vertices of the body triangle that holds the closest point, by that
//! point's barycentric coordinates; each body vertex's pressure is what it
//! received over its area (one third of the area of the triangles around it).
//! So Σ pressure × area over the body's vertices is the total normal force.
//!
//! With the obstacles' edge contacts (`Params::obstacle_edges`) the cloth's
//! triangles and edges also push on the mesh's vertices: each such vertex is
//! one more contact, at the vertex, its normal the mesh's there.

use crate::collision::{Obstacle, Proximity};
use crate::set::Handle;
use crate::solver::Simulation;
use nalgebra::{Point3, Vector3};
use parry3d_f64::query::PointQueryWithLocation;

/// One cloth vertex's contact with the obstacle.
#[derive(Debug, Clone, Copy)]
pub struct BodyContact {
    /// The cloth vertex.
    pub vertex: usize,
    /// Force on the obstacle, N (world axes).
    pub force: Vector3<f64>,
    /// Closest point of the obstacle's surface (world), where it acts.
    pub point: Vector3<f64>,
    /// The obstacle's outward normal there.
    pub normal: Vector3<f64>,
}

impl BodyContact {
    /// The normal part of the contact, N (≥ 0: the cloth pushes on the
    /// surface, it never pulls).
    pub fn normal_force(&self) -> f64 {
        (-self.force.dot(&self.normal)).max(0.0)
    }
}

/// Total force and torque of the garment on one obstacle.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Wrench {
    /// N, world axes.
    pub force: [f64; 3],
    /// N m, about the origin of the obstacle's frame, world axes.
    pub torque: [f64; 3],
    /// Sum of the contacts' normal forces, N.
    pub normal_force: f64,
    /// Cloth vertices in contact with the obstacle.
    pub contacts: usize,
}

/// The cloth vertices whose contact in the last step was with obstacle
/// `body` (`None` if the simulation has no such obstacle).
pub fn contacts_with(sim: &Simulation, body: Handle<Obstacle>) -> Option<Vec<BodyContact>> {
    let obstacles = sim.obstacles();
    let target = obstacles.position(body)?;
    let all = obstacles.as_slice();
    let cloth_t = sim.params().cloth_thickness;
    let on_cloth = sim.contact_forces();
    let mut out = Vec::new();
    for (i, f) in on_cloth.iter().enumerate() {
        if *f == Vector3::zeros() {
            continue;
        }
        let x = sim.cloth.positions()[i];
        let mut best: Option<(usize, f64, Proximity)> = None;
        for (k, ob) in all.iter().enumerate() {
            let e = ob.thickness + cloth_t;
            // a box farther than the best gap cannot hold a nearer surface
            if let Some((_, g, _)) = &best {
                let (lo, hi) = ob.bounds(e + g.max(0.0));
                if (0..3).any(|a| x[a] < lo[a] || x[a] > hi[a]) {
                    continue;
                }
            }
            let pr = ob.proximity(&x);
            let gap = pr.distance - e;
            if best.as_ref().is_none_or(|(_, g, _)| gap < *g) {
                best = Some((k, gap, pr));
            }
        }
        if let Some((k, _, pr)) = best {
            if k == target {
                out.push(BodyContact {
                    vertex: i,
                    force: -f,
                    point: pr.point,
                    normal: pr.normal,
                });
            }
        }
    }
    // the cloth's triangles and edges on the mesh's vertices
    // (`Params::obstacle_edges`), at the vertex, along its normal
    let edges: Vec<_> = sim
        .edge_contacts()
        .into_iter()
        .filter(|c| c.obstacle == target)
        .collect();
    if !edges.is_empty() {
        if let Some((v, t)) = world_mesh(&all[target]) {
            let normals = vertex_normals(&v, &t);
            out.extend(edges.iter().map(|c| BodyContact {
                vertex: c.cloth_vertex,
                force: c.force,
                point: c.point,
                normal: normals[c.vertex],
            }));
        }
    }
    Some(out)
}

/// Each vertex's unit normal: the area-weighted mean of its triangles'
/// (zero for a vertex in none).
fn vertex_normals(vertices: &[Vector3<f64>], triangles: &[[u32; 3]]) -> Vec<Vector3<f64>> {
    let mut n = vec![Vector3::zeros(); vertices.len()];
    for t in triangles {
        let [a, b, c] = t.map(|k| vertices[k as usize]);
        let f = (b - a).cross(&(c - a));
        for k in t {
            n[*k as usize] += f;
        }
    }
    n.iter()
        .map(|v| v.try_normalize(0.0).unwrap_or_default())
        .collect()
}

/// The wrench of a set of contacts about `origin`.
pub fn wrench_of(contacts: &[BodyContact], origin: &Vector3<f64>) -> Wrench {
    let mut f = Vector3::zeros();
    let mut t = Vector3::zeros();
    let mut n = 0.0;
    for c in contacts {
        f += c.force;
        t += (c.point - origin).cross(&c.force);
        n += c.normal_force();
    }
    Wrench {
        force: f.into(),
        torque: t.into(),
        normal_force: n,
        contacts: contacts.len(),
    }
}

/// The garment's wrench on obstacle `body` in the last step, torque about
/// the obstacle frame's origin (`None` if there is no such obstacle).
pub fn wrench(sim: &Simulation, body: Handle<Obstacle>) -> Option<Wrench> {
    let contacts = contacts_with(sim, body)?;
    let origin = sim.obstacles().get(body)?.pose.translation.vector;
    Some(wrench_of(&contacts, &origin))
}

/// The garment's pressure on each vertex of a triangle-mesh obstacle.
#[derive(Debug, Clone)]
pub struct BodyPressure {
    /// The mesh's vertices where the obstacle is now (world), m.
    pub vertices: Vec<Vector3<f64>>,
    pub triangles: Vec<[u32; 3]>,
    /// Each vertex's area: a third of its triangles' areas, m².
    pub area: Vec<f64>,
    /// Normal force each vertex received, N.
    pub force: Vec<f64>,
    /// `force / area`, Pa (0 for a vertex without area).
    pub pressure: Vec<f64>,
    /// Σ of the contacts' normal forces, N.
    pub normal_force: f64,
    /// The wrench of the same contacts.
    pub wrench: Wrench,
}

impl BodyPressure {
    /// Σ pressure × area over the vertices, N.
    pub fn integral(&self) -> f64 {
        self.pressure
            .iter()
            .zip(&self.area)
            .map(|(p, a)| p * a)
            .sum()
    }
}

/// Barycentric coordinates of `p`'s projection on triangle `a b c`, clamped
/// to the triangle (non-negative, summing to 1), and the distance from `p`
/// to that point.
fn barycentric(
    p: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
    c: &Vector3<f64>,
) -> ([f64; 3], f64) {
    let tri =
        parry3d_f64::shape::Triangle::new(Point3::from(*a), Point3::from(*b), Point3::from(*c));
    let (proj, loc) = tri.project_local_point_and_get_location(&Point3::from(*p), false);
    let w = loc.barycentric_coordinates().unwrap_or([1.0 / 3.0; 3]);
    (w, (proj.point.coords - p).norm())
}

/// Vertices (world) and triangles of a mesh.
pub type WorldMesh = (Vec<Vector3<f64>>, Vec<[u32; 3]>);

/// Obstacle `ob`'s triangle mesh where it is now, world coordinates: a
/// deforming body's present positions, a rigid mesh placed by its pose
/// (`None` for other shapes).
pub fn world_mesh(ob: &Obstacle) -> Option<WorldMesh> {
    let mut v = Vec::new();
    let t = ob.world_mesh_into(&mut v)?.to_vec();
    Some((v, t))
}

/// The triangle of obstacle `ob`'s mesh (`vertices`, `triangles`: where it
/// is now) that holds the surface point `p`, with `p`'s barycentric
/// coordinates in it: the triangle the obstacle's own closest-point query
/// finds (its triangles are the mesh's, in order), checked; else the nearest
/// by a search of them all.
pub fn holding_triangle(
    ob: &Obstacle,
    vertices: &[Vector3<f64>],
    triangles: &[[u32; 3]],
    p: &Vector3<f64>,
) -> (usize, [f64; 3]) {
    let corners = |k: usize| triangles[k].map(|i| vertices[i as usize]);
    let found = match ob.deforming() {
        Some(d) => Some(d.closest(p).triangle),
        None => ob.shape.as_trimesh().and_then(|m| {
            let (_, (k, _)) = m.project_point_and_get_location(&ob.pose, &Point3::from(*p), false);
            let k = k as usize;
            (k < triangles.len()).then_some(k)
        }),
    };
    let (k, (w, _)) = found
        .map(|k| {
            let [a, b, c] = corners(k);
            (k, barycentric(p, &a, &b, &c))
        })
        .filter(|(_, (_, d))| *d < 1e-9)
        .unwrap_or_else(|| {
            (0..triangles.len())
                .map(|k| {
                    let [a, b, c] = corners(k);
                    (k, barycentric(p, &a, &b, &c))
                })
                .min_by(|x, y| x.1 .1.total_cmp(&y.1 .1))
                .expect("a mesh obstacle has triangles")
        });
    (k, w)
}

/// The garment's pressure on the vertices of obstacle `body`'s triangle
/// mesh (`None` if there is no such obstacle or it is not a triangle mesh).
pub fn body_pressure(sim: &Simulation, body: Handle<Obstacle>) -> Option<BodyPressure> {
    let ob = sim.obstacles().get(body)?;
    let (vertices, triangles) = world_mesh(ob)?;
    let mut area = vec![0.0; vertices.len()];
    for t in &triangles {
        let [a, b, c] = t.map(|k| vertices[k as usize]);
        let third = (b - a).cross(&(c - a)).norm() / 6.0;
        for k in t {
            area[*k as usize] += third;
        }
    }
    let contacts = contacts_with(sim, body)?;
    let mut force = vec![0.0; vertices.len()];
    let mut normal_force = 0.0;
    for c in &contacts {
        let normal = c.normal_force();
        if normal <= 0.0 {
            continue;
        }
        normal_force += normal;
        let (k, w) = holding_triangle(ob, &vertices, &triangles, &c.point);
        for (j, i) in triangles[k].iter().enumerate() {
            force[*i as usize] += w[j] * normal;
        }
    }
    let pressure = force
        .iter()
        .zip(&area)
        .map(|(f, a)| if *a > 0.0 { f / a } else { 0.0 })
        .collect();
    let origin = ob.pose.translation.vector;
    Some(BodyPressure {
        vertices,
        triangles,
        area,
        force,
        pressure,
        normal_force,
        wrench: wrench_of(&contacts, &origin),
    })
}
