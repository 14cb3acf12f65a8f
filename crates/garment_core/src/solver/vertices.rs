//! The per-vertex phases of a step around the assembly and the solve: the
//! constraints (pins, contacts and their friction: the filter S, z and the
//! position correction y), and the update after the solve (velocities,
//! positions, Coulomb stick/slip, the push out of obstacles). Each vertex's
//! work reads the shared state and writes only that vertex's entries, so the
//! simulation's team runs them over its chunks of vertices.

use super::linear::Filter;
use super::sparse::BlockMatrix;
use super::{FrictionState, Pin, FRICTION_FLOOR, STICK_SPEED};
use crate::collision::{crease_between, Obstacle, Proximity, CREASE_COS};
use crate::deforming::HIT_TOLERANCE;
use nalgebra::{Matrix3, Vector3};

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
    /// Hold a vertex in a crease by both surfaces ([`super::Params::creases`]).
    pub creases: bool,
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
    /// The second surface's normal of a vertex held in a crease (else zero).
    pub normals2: &'a mut [Vector3<f64>],
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
    let mut near = Near::default();
    for k in 0..o.filter.len() {
        let i = o.first + k;
        o.filter[k] = Filter::Free;
        o.z[k] = Vector3::zeros();
        o.y[k] = Vector3::zeros();
        o.contact_of[k] = None;
        o.normals2[k] = Vector3::zeros();
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
        // a crease: the nearest surface and another one (a second
        // obstacle's, or another fold of the same mesh) both touching
        let held = o.friction[k].impulse > 0.0 || o.friction[k].stick;
        let crease = best
            .as_ref()
            .and_then(|(ob_i, pr, e)| crease_of(s, i, free, held, *ob_i, pr, *e, &mut near));
        let mut touching = false;
        if let Some(c) = crease {
            touching = true;
            hold_in_crease(s, i, k, &c, held, driving, o);
        } else if let Some((n, velocity, mu, gap, e)) = contact {
            let rel = s.v[i] - velocity;
            let vrel = rel.dot(&n);
            let floor = floor_force(s.mass[i], g);
            let surface = Surface {
                n,
                velocity,
                mu,
                gap,
                e,
            };
            // landing, approaching, pressed against it by last step's force
            // (resting contact) or inside the contact distance
            if surface.touches(s, i, held) {
                let landing = surface.landing();
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

/// One surface a vertex touches: its outward normal, the velocity it
/// carries the vertex with, its friction coefficient, the gap to the
/// contact distance (m, negative inside it) and that distance `e`, m.
#[derive(Debug, Clone, Copy)]
struct Surface {
    n: Vector3<f64>,
    velocity: Vector3<f64>,
    mu: f64,
    gap: f64,
    e: f64,
}

impl Surface {
    /// Beyond the margin (10 % of `e`): reached within this step at the
    /// present speed.
    fn landing(&self) -> bool {
        self.gap >= 0.1 * self.e
    }

    /// Whether it holds vertex `i` this step: landing, approached, pressed
    /// by last step's force (`held`: in contact last step, then unless
    /// pulled off by more than the friction floor) or inside the contact
    /// distance — the single contact's test in [`constrain`].
    fn touches(&self, s: &Scene, i: usize, held: bool) -> bool {
        let vrel = (s.v[i] - self.velocity).dot(&self.n);
        self.landing() || vrel < 0.0 || self.pressed(s, i, held) || self.gap < 0.0
    }

    /// Pressed against it by last step's force (resting contact): one in
    /// contact last step (`held`) stays so unless pulled off by more than
    /// the friction floor, a force the solve does not resolve.
    fn pressed(&self, s: &Scene, i: usize, held: bool) -> bool {
        let floor = floor_force(s.mass[i], s.gravity.norm());
        s.force[i].dot(&self.n) < if held { floor } else { 0.0 }
    }
}

/// A vertex in a crease: the two surfaces that hold it (the nearest first),
/// and a third one that blocks the crease's axis, if any.
#[derive(Debug, Clone, Copy)]
struct Crease {
    first: Surface,
    second: Surface,
    third: Option<Surface>,
}

/// Scratch of [`crease_of`], kept across a chunk's vertices.
#[derive(Default)]
struct Near {
    prox: Vec<Proximity>,
    found: Vec<(Proximity, Surface)>,
}

/// The crease vertex `i` is in, if any: besides its nearest surface `pr` (of
/// obstacle `ob_i`, contact distance `e`), the nearest other surface within
/// its contact zone that makes a crease with it ([`crease_between`]: the
/// other obstacles' nearest points, and the nearest obstacle's own other
/// folds, [`Obstacle::crease_surfaces`]), both touching it
/// ([`Surface::touches`]); and a third that makes a crease with both and
/// whose normal is more than 30° off the plane of theirs.
#[allow(clippy::too_many_arguments)]
fn crease_of(
    s: &Scene,
    i: usize,
    free: Vector3<f64>,
    held: bool,
    ob_i: usize,
    pr: &Proximity,
    e: f64,
    near: &mut Near,
) -> Option<Crease> {
    let h = s.h;
    let ob = &s.obstacles[ob_i];
    let surface = |pr: &Proximity, e: f64, mu: f64| Surface {
        n: pr.normal,
        velocity: pr.velocity,
        mu,
        gap: pr.distance - e,
        e,
    };
    let first = surface(pr, e, ob.friction);
    if !s.creases || !first.touches(s, i, held) {
        return None;
    }
    // within the contact zone as the nearest surface is found
    let in_zone = |pr: &Proximity, e: f64| {
        let approach = -(free - pr.velocity).dot(&pr.normal) * h;
        pr.distance - e < approach.max(0.1 * e)
    };
    let eps = 1e-3 * e;
    near.found.clear();
    for (ob_j, other) in s.obstacles.iter().enumerate() {
        if ob_j == ob_i {
            continue;
        }
        let ahead = s.x[i] + (free - other.linear_velocity) * h;
        if !overlaps(&s.bounds[ob_j], &s.x[i], &ahead) {
            continue;
        }
        let ej = other.thickness + s.cloth_thickness;
        let q = other.proximity(&s.x[i]);
        if in_zone(&q, ej) && crease_between(pr, &q, eps) {
            near.found.push((q, surface(&q, ej, other.friction)));
        }
    }
    // the nearest obstacle's other folds within reach: its contact zone at
    // the present speed, at most twice the contact distance
    let reach = e + ((free - pr.velocity).norm() * h).max(0.1 * e).min(e);
    near.prox.clear();
    ob.crease_surfaces(&s.x[i], pr, reach, eps, &mut near.prox);
    for q in &near.prox {
        if in_zone(q, e) {
            near.found.push((*q, surface(q, e, ob.friction)));
        }
    }
    near.found.sort_by(|a, b| a.1.gap.total_cmp(&b.1.gap));
    let (k2, (pr2, second)) = near
        .found
        .iter()
        .enumerate()
        .find(|(_, (_, f))| f.touches(s, i, held))?;
    let axis = first.n.cross(&second.n).try_normalize(1e-9);
    // a corner holds the vertex only while last step's force presses it
    // into all three (within the contact distance alone, a vertex the
    // cloth pulls out of the corner would be held there whatever the pull)
    let pressed = |f: &Surface| f.pressed(s, i, held);
    let third = axis
        .filter(|_| pressed(&first) && pressed(second))
        .and_then(|a| {
            near.found[k2 + 1..]
                .iter()
                .find(|(q, f)| f.n.dot(&a).abs() > 0.5 && crease_between(pr2, q, eps) && pressed(f))
                .map(|(_, f)| *f)
        });
    Some(Crease {
        first,
        second: *second,
        third,
    })
}

/// The position correction that closes the gaps of `surfaces` as far as
/// they can be: least squares, damped (their normals may be nearly
/// opposite or dependent).
fn close_gaps(surfaces: &[&Surface]) -> Vector3<f64> {
    let mut m = Matrix3::identity() * 0.05;
    let mut rhs = Vector3::zeros();
    for sf in surfaces {
        m += sf.n * sf.n.transpose();
        rhs += sf.n * (-sf.gap).max(0.0);
    }
    m.try_inverse().map_or(Vector3::zeros(), |mi| mi * rhs)
}

/// `x` with `x · n1 = t1` and `x · n2 = t2` in the plane of the unit
/// vectors `n1` and `n2` (`c = n1 · n2`, |c| < 1).
fn in_plane(n1: &Vector3<f64>, n2: &Vector3<f64>, c: f64, t1: f64, t2: f64) -> Vector3<f64> {
    let d = 1.0 - c * c;
    n1 * ((t1 - c * t2) / d) + n2 * ((t2 - c * t1) / d)
}

/// The constraint of vertex `i` (row `k`) held in crease `c`: free only
/// along the crease's axis `a = n1 × n2` (`S = a aᵀ`), the velocity along
/// each surface's normal prescribed as a single contact's is (inelastic, a
/// landing vertex ending the step on it; stopped along the normal of a
/// surface that presses it), both gaps closed by the position correction,
/// and Coulomb friction along the axis from the sum of the normal impulses
/// with the smaller coefficient of the two (static: the vertex moves with
/// the surfaces; kinetic: a force against the sliding). Normals less than
/// 30° from opposite ([`CREASE_COS`]: a slot the vertex is squeezed in)
/// constrain one direction, their difference `n̄ = (n1 − n2)/|n1 − n2|`
/// (`Normal(n̄)`, the two constraints nearly one), the vertex free to slide
/// through the slot with the friction of both; a third surface across the
/// axis leaves no free direction: the vertex moves with the surfaces
/// (`Fixed`).
#[allow(clippy::too_many_arguments)]
fn hold_in_crease(
    s: &Scene,
    i: usize,
    k: usize,
    c: &Crease,
    held: bool,
    driving: Vector3<f64>,
    o: &mut ConstraintRows,
) {
    let h = s.h;
    let (s1, s2) = (&c.first, &c.second);
    let (n1, n2) = (s1.n, s2.n);
    let cos = n1.dot(&n2);
    let mu = s1.mu.min(s2.mu);
    let floor = floor_force(s.mass[i], s.gravity.norm());
    let v = s.v[i];
    let gap_fix = |sf: &Surface| (-sf.gap).max(0.0);
    o.contacts += 1;
    o.normals[k] = n1;
    o.normals2[k] = n2;
    let axis = n1.cross(&n2).try_normalize(1e-9);
    let (filter, vo, z) = match (axis, c.third) {
        (Some(a), None) if cos > -CREASE_COS => {
            // the velocity the crease carries the vertex with: each
            // surface's along its normal, the nearest one's along the axis
            let vo = in_plane(&n1, &n2, cos, s1.velocity.dot(&n1), s2.velocity.dot(&n2))
                + a * a.dot(&s1.velocity);
            o.y[k] = in_plane(&n1, &n2, cos, gap_fix(s1), gap_fix(s2));
            // a surface the vertex is pressed against stops it along its
            // normal, also when it was leaving (the other surface's
            // constraint would otherwise keep that velocity, pushing it off
            // at a constant speed against the force that presses it)
            let target = |sf: &Surface| {
                let vrel = (v - sf.velocity).dot(&sf.n);
                if sf.landing() {
                    -sf.gap / h - vrel
                } else if sf.pressed(s, i, held) {
                    -vrel
                } else {
                    (-vrel).max(0.0)
                }
            };
            let z = in_plane(&n1, &n2, cos, target(s1), target(s2));
            (Filter::Crease(a), vo, z)
        }
        (_, None) => {
            // a slot: its walls' mean velocity, the squeeze stopped, the
            // gaps closed as far as they can be
            let nb = (n1 - n2).normalize();
            let vo = (s1.velocity + s2.velocity) * 0.5;
            o.y[k] = close_gaps(&[s1, s2]);
            (Filter::Normal(nb), vo, nb * nb.dot(&(vo - v)))
        }
        (_, Some(t)) => {
            // a corner: moves with the surfaces (their mean velocity), the
            // gaps closed as far as they can be
            let vo = (s1.velocity + s2.velocity + t.velocity) / 3.0;
            o.y[k] = close_gaps(&[s1, s2, &t]);
            o.filter[k] = Filter::Fixed;
            o.z[k] = vo - v;
            o.contact_of[k] = Some((mu, vo));
            return;
        }
    };
    o.contact_of[k] = Some((mu, vo));
    let landing = s1.landing() || s2.landing();
    let holds = in_cone(
        filter.apply(&driving).norm() * h,
        o.friction[k].impulse,
        mu,
        floor * h,
    );
    if o.friction[k].stick && mu > 0.0 && !landing && holds {
        o.filter[k] = Filter::Fixed;
        o.z[k] = vo - v;
        o.stuck += 1;
    } else {
        o.filter[k] = filter;
        o.z[k] = z;
        if mu > 0.0 {
            o.friction_force[k] = kinetic_friction(
                s.mass[i],
                filter.apply(&(v - vo)),
                driving,
                mu * o.friction[k].impulse,
                h,
            );
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
    /// See [`ConstraintRows::normals2`].
    pub normals2: &'a [Vector3<f64>],
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

/// The friction state after the step of vertex `i` held in a crease, from
/// its constraint impulse `r`: the normal impulse is the sum of the two
/// surfaces' (`r` resolved along their normals, the pressing parts; in a
/// slot, `r` along the squeeze); a sliding vertex sticks once slower than
/// [`STICK_SPEED`] in its free directions (or its sliding reversed on a
/// moving surface: `before` and `after`, its velocity relative to the
/// crease's at the step's start and end), a held one while the impulse off
/// the normals stays in the cone.
fn crease_friction(
    s: &Solved,
    i: usize,
    r: Vector3<f64>,
    mu: f64,
    before: Vector3<f64>,
    after: Vector3<f64>,
) -> FrictionState {
    let (n1, n2) = (s.normals[i], s.normals2[i]);
    let c = n1.dot(&n2);
    let (impulse, normal) = if c > -CREASE_COS {
        let d = 1.0 - c * c;
        let (r1, r2) = (r.dot(&n1), r.dot(&n2));
        let (l1, l2) = ((r1 - c * r2) / d, (r2 - c * r1) / d);
        (l1.max(0.0) + l2.max(0.0), n1 * l1 + n2 * l2)
    } else {
        let nb = (n1 - n2).normalize();
        (r.dot(&nb).abs(), nb * r.dot(&nb))
    };
    let stick = match s.filter[i] {
        Filter::Fixed => in_cone(
            (r - normal).norm(),
            impulse,
            mu,
            floor_force(s.mass[i], s.gravity) * s.h,
        ),
        f => {
            let (ra, ba) = (f.apply(&after), f.apply(&before));
            let moving = s.contact_of[i].is_some_and(|(_, vo)| vo != Vector3::zeros());
            ra.norm() < STICK_SPEED || (moving && ra.dot(&ba) < 0.0)
        }
    };
    FrictionState { impulse, stick }
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
            if s.normals2[i] != Vector3::zeros() {
                o.friction[k] = crease_friction(s, i, r, mu, o.v[k] - vo, v - vo);
            } else {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A crease's filter is the projection on its axis: `S = a aᵀ`, its
    /// one-sided products `S m` and `m S`, `S² = S`, and it removes both
    /// normals of the surfaces whose cross product the axis is.
    #[test]
    fn a_crease_filter_projects_on_its_axis() {
        let n1 = Vector3::new(0.0, 0.6, 0.8);
        let n2 = Vector3::new(0.3, -0.5, 0.7).normalize();
        let a = n1.cross(&n2).normalize();
        let f = Filter::Crease(a);
        let s = f.matrix();
        assert!((s - a * a.transpose()).amax() < 1e-15);
        assert!((s * s - s).amax() < 1e-15);
        let m = Matrix3::new(1.0, 2.0, -3.0, 0.5, -1.5, 4.0, 2.5, 0.25, -0.75);
        assert!((f.left(&m) - s * m).amax() < 1e-14);
        assert!((f.right(&m) - m * s).amax() < 1e-14);
        for n in [n1, n2] {
            assert!(f.apply(&n).norm() < 1e-15);
        }
        let v = Vector3::new(0.7, -0.2, 0.4);
        assert!((f.apply(&v) - a * a.dot(&v)).norm() < 1e-15);
    }

    /// The prescribed part in the normals' plane meets both targets and has
    /// nothing along the crease's axis.
    #[test]
    fn the_prescribed_part_meets_both_normals_targets() {
        let n1 = Vector3::new(0.0, 0.6, 0.8);
        let n2 = Vector3::new(0.3, -0.5, 0.7).normalize();
        let c = n1.dot(&n2);
        let x = in_plane(&n1, &n2, c, 0.25, -0.1);
        assert!((x.dot(&n1) - 0.25).abs() < 1e-15);
        assert!((x.dot(&n2) + 0.1).abs() < 1e-15);
        assert!(x.dot(&n1.cross(&n2)).abs() < 1e-15);
    }
}
