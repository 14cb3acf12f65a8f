//! The per-vertex phases of a step around the assembly and the solve: the
//! constraints (pins, contacts and their friction: the filter S, z and the
//! position correction y), and the update after the solve (velocities,
//! positions, Coulomb stick/slip, the push out of obstacles). Each vertex's
//! work reads the shared state and writes only that vertex's entries, so the
//! simulation's team runs them over its chunks of vertices.

use super::linear::Filter;
use super::sparse::BlockMatrix;
use super::{FrictionState, Pin, FRICTION_FLOOR, STICK_SPEED};
use crate::collision::{Obstacle, Proximity};
use crate::deforming::HIT_TOLERANCE;
use nalgebra::Vector3;

/// Axis-aligned box (min, max corners).
pub(super) type Bounds = ([f64; 3], [f64; 3]);

pub(super) fn inside(b: &Bounds, p: &Vector3<f64>) -> bool {
    (0..3).all(|k| p[k] >= b.0[k] && p[k] <= b.1[k])
}

/// Whether the box spanned by the segment `a → b` meets `bounds`.
fn overlaps(bounds: &Bounds, a: &Vector3<f64>, b: &Vector3<f64>) -> bool {
    (0..3).all(|k| a[k].min(b[k]) <= bounds.1[k] && a[k].max(b[k]) >= bounds.0[k])
}

/// What the constraint phase reads.
pub(super) struct Scene<'a> {
    pub h: f64,
    /// End of the step, s.
    pub t1: f64,
    pub cloth_thickness: f64,
    pub obstacles: &'a [Obstacle],
    /// Each obstacle's box grown by its contact zone.
    pub bounds: &'a [Bounds],
    pub pins: &'a [Pin],
    pub pinned: &'a [Option<usize>],
    pub x: &'a [Vector3<f64>],
    pub v: &'a [Vector3<f64>],
    pub mass: &'a [f64],
    /// Last step's total force.
    pub force: &'a [Vector3<f64>],
    /// Gravity, m/s².
    pub gravity: Vector3<f64>,
    /// The cloth–cloth pass whose last step's contacts with the obstacles'
    /// vertices and edges hold vertices (`Params::obstacle_edges`; see
    /// [`crate::self_contact::SelfContact::obstacle_contact`]).
    pub edge: Option<&'a crate::self_contact::SelfContact>,
}

/// What the constraint phase writes, for vertices `first..first + len`.
pub(super) struct ConstraintRows<'a> {
    pub first: usize,
    pub filter: &'a mut [Filter],
    pub z: &'a mut [Vector3<f64>],
    pub y: &'a mut [Vector3<f64>],
    pub contact_of: &'a mut [Option<(f64, Vector3<f64>)>],
    pub friction_force: &'a mut [Vector3<f64>],
    pub normals: &'a mut [Vector3<f64>],
    pub friction: &'a mut [FrictionState],
    /// Vertices in contact.
    pub contacts: usize,
    /// Of those, the ones held by static friction.
    pub stuck: usize,
}

/// Pins, then contacts: the constraint filter, z and y of each vertex, its
/// kinetic friction force, and its contact for the update after the solve.
pub(super) fn constrain(s: &Scene, o: &mut ConstraintRows) {
    let h = s.h;
    let g = s.gravity.norm();
    for k in 0..o.filter.len() {
        let i = o.first + k;
        o.filter[k] = Filter::Free;
        o.z[k] = Vector3::zeros();
        o.y[k] = Vector3::zeros();
        o.contact_of[k] = None;
        // last step's force without its friction: what drives the sliding
        let driving = s.force[i] - o.friction_force[k];
        o.friction_force[k] = Vector3::zeros();
        if let Some(p) = s.pinned[i] {
            let (p, v) = s.pins[p].path.at(s.t1);
            o.filter[k] = Filter::Fixed;
            o.z[k] = v - s.v[i];
            o.y[k] = p - s.x[i] - v * h;
            continue;
        }
        // the velocity that carries the vertex this step, as far as the
        // contacts foresee it: the present one (a resting vertex that springs
        // hold above a surface is not pulled onto it), with gravity's pull
        // added before the first step (a cloth released from rest)
        let free = if s.force[i] == Vector3::zeros() {
            s.v[i] + s.gravity * h
        } else {
            s.v[i]
        };
        let mut best: Option<(usize, Proximity, f64)> = None;
        for (ob_i, ob) in s.obstacles.iter().enumerate() {
            // where the vertex would go this step relative to the obstacle
            let ahead = s.x[i] + (free - ob.linear_velocity) * h;
            if !overlaps(&s.bounds[ob_i], &s.x[i], &ahead) {
                continue;
            }
            let e = ob.thickness + s.cloth_thickness;
            let pr = ob.proximity(&s.x[i]);
            // contact zone: within e plus a margin of 10 % of e, or farther
            // when the vertex would cross the surface within this step at
            // its present speed (large steps: it is caught where it lands)
            let approach = -(free - pr.velocity).dot(&pr.normal) * h;
            if pr.distance - e < approach.max(0.1 * e)
                && best
                    .as_ref()
                    .is_none_or(|b| pr.distance - e < b.1.distance - b.2)
            {
                best = Some((ob_i, pr, e));
            }
        }
        // the contact: an obstacle's surface, else last step's contact of
        // the vertex's triangles or edges with an obstacle's vertices or
        // edges (held along the direction that parts them, no position
        // correction: the cloth–cloth pass keeps their gap)
        let contact = match best {
            Some((ob_i, pr, e)) => Some((
                pr.normal,
                pr.velocity,
                s.obstacles[ob_i].friction,
                pr.distance - e,
                e,
            )),
            None => s
                .edge
                .and_then(|sc| sc.obstacle_contact(i))
                .map(|(n, vo, mu)| (n, vo, mu, 0.0, f64::INFINITY)),
        };
        let mut touching = false;
        if let Some((n, velocity, mu, gap, e)) = contact {
            let rel = s.v[i] - velocity;
            let vrel = rel.dot(&n);
            // pressed against it by last step's force (resting contact); one
            // in contact last step stays so unless pulled off by more than
            // the friction floor, a force the solve does not resolve
            let floor = floor_force(s.mass[i], g);
            let held = o.friction[k].impulse > 0.0 || o.friction[k].stick;
            let pressed = s.force[i].dot(&n) < if held { floor } else { 0.0 };
            // beyond the margin: reached within this step at the present speed
            let landing = gap >= 0.1 * e;
            if landing || vrel < 0.0 || pressed || gap < 0.0 {
                touching = true;
                o.y[k] = n * (-gap).max(0.0);
                // a slow vertex sticks if static friction can hold it against the
                // force that drives it along the surface (else it creeps on)
                let along = driving - n * driving.dot(&n);
                let holds = in_cone(along.norm() * h, o.friction[k].impulse, mu, floor * h);
                if o.friction[k].stick && mu > 0.0 && !landing && holds {
                    // static friction: the vertex moves with the obstacle
                    o.filter[k] = Filter::Fixed;
                    o.z[k] = velocity - s.v[i];
                    o.stuck += 1;
                } else {
                    // inelastic normal constraint (a separating velocity is kept;
                    // a vertex landing from beyond the margin ends the step on
                    // the surface, the gap closed, not overshot); kinetic friction
                    // from last step's normal force, never more than what stops
                    // the tangential motion in one step against the force
                    // driving it
                    o.filter[k] = Filter::Normal(n);
                    o.z[k] = if landing {
                        n * (-gap / h - vrel)
                    } else {
                        n * (-vrel).max(0.0)
                    };
                    if mu > 0.0 {
                        o.friction_force[k] = kinetic_friction(
                            s.mass[i],
                            rel - n * vrel,
                            driving,
                            mu * o.friction[k].impulse,
                            h,
                        );
                    }
                }
                o.contact_of[k] = Some((mu, velocity));
                o.normals[k] = n;
                o.contacts += 1;
            }
        }
        if !touching {
            o.friction[k] = FrictionState::default();
        }
    }
}

/// [`FRICTION_FLOOR`] times the weight of a vertex of mass `m` under
/// gravity of norm `g`, N: the force below which a contact's forces are
/// taken as the solve's error.
#[inline]
fn floor_force(m: f64, g: f64) -> f64 {
    FRICTION_FLOOR * m * g
}

/// Coulomb's cone widened by the friction floor: whether static friction
/// holds a tangential impulse `t` against the normal impulse `n` (none if
/// negative) with the coefficient `mu`, within `floor`, the impulse of
/// [`FRICTION_FLOOR`] times the vertex's weight over the step.
#[inline]
fn in_cone(t: f64, n: f64, mu: f64, floor: f64) -> bool {
    t <= mu * n.max(0.0) + floor
}

/// Kinetic friction on a vertex sliding at tangential velocity `vt`
/// (relative to the obstacle) pressed with the normal impulse whose
/// Coulomb limit is `limit` (μ × impulse, N·s): at most `limit / h`, and
/// never more than what stops the tangential motion in one step against the
/// force `driving` it along; zero for a vertex not sliding.
pub(super) fn kinetic_friction(
    mass: f64,
    vt: Vector3<f64>,
    driving: Vector3<f64>,
    limit: f64,
    h: f64,
) -> Vector3<f64> {
    let vtn = vt.norm();
    if vtn.is_nan() || vtn <= 0.0 {
        return Vector3::zeros();
    }
    let t = vt / vtn;
    let stop = mass * vtn / h + driving.dot(&t).max(0.0);
    -t * (limit / h).min(stop)
}

/// What the update after the solve reads.
pub(super) struct Solved<'a> {
    pub h: f64,
    pub cloth_thickness: f64,
    /// Gravity's norm, m/s² (for the friction floor, [`floor_force`]).
    pub gravity: f64,
    pub mass: &'a [f64],
    pub a: &'a BlockMatrix,
    pub b: &'a [Vector3<f64>],
    pub dv: &'a [Vector3<f64>],
    pub y: &'a [Vector3<f64>],
    pub filter: &'a [Filter],
    pub contact_of: &'a [Option<(f64, Vector3<f64>)>],
    pub normals: &'a [Vector3<f64>],
    pub pinned: &'a [Option<usize>],
    /// The obstacles where they are at the end of the step.
    pub obstacles: &'a [Obstacle],
    /// Their boxes grown by the contact distance.
    pub bounds: &'a [Bounds],
}

/// What the update writes, for vertices `first..first + len`.
pub(super) struct StateRows<'a> {
    pub first: usize,
    pub x: &'a mut [Vector3<f64>],
    pub v: &'a mut [Vector3<f64>],
    pub friction: &'a mut [FrictionState],
}

/// Velocities and positions; Coulomb stick/slip from the constraint impulse
/// `r = (A Δv − b)_i` of each vertex in contact; then no vertex may end
/// inside an obstacle's contact distance: it is pushed back to it and its
/// approaching normal velocity removed.
pub(super) fn finish(s: &Solved, o: &mut StateRows) {
    let h = s.h;
    for k in 0..o.x.len() {
        let i = o.first + k;
        let v = o.v[k] + s.dv[i];
        if let Some((mu, vo)) = s.contact_of[i] {
            let mut r = -s.b[i];
            for q in s.a.row_ptr[i]..s.a.row_ptr[i + 1] {
                r += s.a.val[q] * s.dv[s.a.col[q] as usize];
            }
            let nrm = match s.filter[i] {
                Filter::Normal(nrm) => nrm,
                _ => s.normals[i],
            };
            let rn = r.dot(&nrm);
            let st = &mut o.friction[k];
            st.impulse = rn.max(0.0);
            st.stick = if s.filter[i] == Filter::Fixed {
                // static friction holds while the tangential impulse stays in
                // the cone, widened by the friction floor (the impulses of a
                // contact that carries next to nothing are the solve's error)
                in_cone(
                    (r - nrm * rn).norm(),
                    rn,
                    mu,
                    floor_force(s.mass[i], s.gravity) * h,
                )
            } else {
                // slow; or, on a moving surface, its sliding reversed over
                // the step (it passed through rest relative to the surface,
                // whose own velocity changes from step to step by more than
                // the stick speed)
                let rel = v - vo;
                let rt = rel - nrm * rel.dot(&nrm);
                let before = o.v[k] - vo;
                let bt = before - nrm * before.dot(&nrm);
                rt.norm() < STICK_SPEED || (vo != Vector3::zeros() && rt.dot(&bt) < 0.0)
            };
        }
        o.v[k] = v;
        let x0 = o.x[k];
        o.x[k] += v * h + s.y[i];
        if s.pinned[i].is_some() {
            continue;
        }
        for (ob_i, ob) in s.obstacles.iter().enumerate() {
            let e = ob.thickness + s.cloth_thickness;
            if let Some(body) = ob.deforming() {
                // a deforming mesh: the vertex's path over the step against
                // the triangles' (each point moving linearly); met from
                // outside (either side of an open mesh), it is put back on
                // that side of the triangle it met, at the contact distance
                if overlaps(&s.bounds[ob_i], &x0, &o.x[k]) {
                    if let Some(hit) = body.first_hit(&x0, &o.x[k], HIT_TOLERANCE) {
                        if hit.side > 0.0 || !body.closed() {
                            let n = body.face_normal(hit.triangle) * hit.side;
                            let c = body.point_on(hit.triangle, hit.weights);
                            o.x[k] += n * (e - (o.x[k] - c).dot(&n));
                            let vo = body.velocity_on(hit.triangle, hit.weights);
                            let vn = (o.v[k] - vo).dot(&n);
                            if vn < 0.0 {
                                o.v[k] -= n * vn;
                            }
                        }
                    }
                }
            } else {
                // a vertex that moved farther than the contact distance relative
                // to the obstacle may have crossed its surface, even gone
                // through a thin one (it started the step outside the thickened
                // shape): put it back on the side it came from
                let start = x0 + ob.velocity_at(&x0) * h;
                if (o.x[k] - start).norm_squared() >= e * e
                    && overlaps(&s.bounds[ob_i], &start, &o.x[k])
                {
                    if let Some((t, n)) = ob.first_crossing(&start, &o.x[k]) {
                        let entry = start + (o.x[k] - start) * t;
                        o.x[k] += n * (e - (o.x[k] - entry).dot(&n));
                        let vn = (o.v[k] - ob.velocity_at(&entry)).dot(&n);
                        if vn < 0.0 {
                            o.v[k] -= n * vn;
                        }
                    }
                }
            }
            if !inside(&s.bounds[ob_i], &o.x[k]) {
                continue;
            }
            // a few passes for curved or meeting surfaces
            for _ in 0..3 {
                let pr = ob.proximity(&o.x[k]);
                if pr.distance >= e - 1e-9 {
                    break;
                }
                o.x[k] += pr.normal * (e - pr.distance);
                let vn = (o.v[k] - pr.velocity).dot(&pr.normal);
                if vn < 0.0 {
                    o.v[k] -= pr.normal * vn;
                }
            }
        }
    }
}

/// One row struct per thread of the team: `split_rows!(bounds, Rows {
/// field: slice, … }, other: value, …)` cuts each slice at `bounds`
/// ([`chunks`]) and gives thread t's `Rows` its `first` vertex, its chunk of
/// each slice and the other fields' values.
macro_rules! split_rows {
    ($bounds:expr, $($rows:ident)::+ { $($field:ident: $slice:expr),* $(,)? } $(, $other:ident: $value:expr)* $(,)?) => {{
        let bounds: &[usize] = $bounds;
        $(let mut $field = $crate::solver::vertices::chunks($slice, bounds).into_iter();)*
        bounds[..bounds.len() - 1]
            .iter()
            .map(|&first| $($rows)::+ {
                first,
                $($field: $field.next().unwrap_or_default(),)*
                $($other: $value,)*
            })
            .collect::<Vec<_>>()
    }};
}
pub(super) use split_rows;

/// `s` cut at `bounds` (chunk t = `bounds[t]..bounds[t + 1]`, for the
/// team's thread t).
pub(super) fn chunks<'a, T>(mut s: &'a mut [T], bounds: &[usize]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(bounds.len().saturating_sub(1));
    for w in bounds.windows(2) {
        let (head, tail) = std::mem::take(&mut s).split_at_mut(w[1] - w[0]);
        out.push(head);
        s = tail;
    }
    out
}
