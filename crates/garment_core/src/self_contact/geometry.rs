//! Distances and continuous collision tests between a vertex and a triangle
//! and between two edges (Bridson, Fedkiw & Anderson 2002 §4–5; Provot 1997
//! for the coplanarity cubic).

use nalgebra::Vector3;

type V = Vector3<f64>;

/// Closest point of triangle (a, b, c) to p as barycentric weights
/// (Ericson, Real-Time Collision Detection §5.1.5, by Voronoi regions).
pub fn point_triangle(p: &V, a: &V, b: &V, c: &V) -> [f64; 3] {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return [0.0, 1.0, 0.0];
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return [1.0 - v, v, 0.0];
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return [0.0, 0.0, 1.0];
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return [1.0 - w, 0.0, w];
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return [0.0, 1.0 - w, w];
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    [1.0 - v - w, v, w]
}

/// Tolerance of [`projection_weights`] and [`line_line`] on the boundary
/// (a vertex exactly over another layer's vertex or edge counts as over
/// its triangles).
const ON_BOUNDARY: f64 = 1e-9;

/// Barycentric weights of the projection of p onto the plane of triangle
/// (a, b, c), if it falls inside the triangle (to `ON_BOUNDARY`; the
/// weights then clamped to it).
pub fn projection_weights(p: &V, a: &V, b: &V, c: &V) -> Option<[f64; 3]> {
    let (u, v, w) = (b - a, c - a, p - a);
    let (uu, uv, vv, wu, wv) = (u.dot(&u), u.dot(&v), v.dot(&v), w.dot(&u), w.dot(&v));
    let det = uu * vv - uv * uv;
    if det <= 0.0 {
        return None;
    }
    let s = (wu * vv - wv * uv) / det;
    let t = (wv * uu - wu * uv) / det;
    let r = 1.0 - s - t;
    if r < -ON_BOUNDARY || s < -ON_BOUNDARY || t < -ON_BOUNDARY {
        return None;
    }
    let (r, s, t) = (r.max(0.0), s.max(0.0), t.max(0.0));
    let sum = r + s + t;
    Some([r / sum, s / sum, t / sum])
}

/// Parameters (s, t) of the closest points of the lines through p0–p1 and
/// q0–q1, if both fall on the segments (to `ON_BOUNDARY`; then clamped);
/// `None` for parallel lines.
pub fn line_line(p0: &V, p1: &V, q0: &V, q1: &V) -> Option<(f64, f64)> {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let (a, b, e) = (d1.dot(&d1), d1.dot(&d2), d2.dot(&d2));
    let (c, f) = (d1.dot(&r), d2.dot(&r));
    let denom = a * e - b * b;
    if denom <= 1e-12 * a * e {
        return None;
    }
    let s = (b * f - c * e) / denom;
    let t = (a * f - b * c) / denom;
    let inside = |x: f64| (-ON_BOUNDARY..=1.0 + ON_BOUNDARY).contains(&x);
    (inside(s) && inside(t)).then(|| (s.clamp(0.0, 1.0), t.clamp(0.0, 1.0)))
}

/// Closest points of segments p0–p1 and q0–q1 as fractions (s, t) along
/// them (Ericson §5.1.9, with parallel segments handled).
pub fn segment_segment(p0: &V, p1: &V, q0: &V, q1: &V) -> (f64, f64) {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.norm_squared();
    let e = d2.norm_squared();
    let f = d2.dot(&r);
    const EPS: f64 = 1e-30;
    if a <= EPS && e <= EPS {
        return (0.0, 0.0);
    }
    if a <= EPS {
        return (0.0, (f / e).clamp(0.0, 1.0));
    }
    let c = d1.dot(&r);
    if e <= EPS {
        return ((-c / a).clamp(0.0, 1.0), 0.0);
    }
    let b = d1.dot(&d2);
    let denom = a * e - b * b;
    let mut s = if denom > 1e-12 * a * e {
        ((b * f - c * e) / denom).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let mut t = (b * s + f) / e;
    if t < 0.0 {
        t = 0.0;
        s = (-c / a).clamp(0.0, 1.0);
    } else if t > 1.0 {
        t = 1.0;
        s = ((b - c) / a).clamp(0.0, 1.0);
    }
    (s, t)
}

/// Roots in [0, 1] of `c0 + c1 t + c2 t² + c3 t³`, ascending: the
/// interval is cut at the critical points into monotone pieces, each with
/// a sign change bisected to double precision.
pub fn cubic_roots(c: [f64; 4]) -> ([f64; 3], usize) {
    let f = |t: f64| ((c[3] * t + c[2]) * t + c[1]) * t + c[0];
    let mut cuts = [0.0, 0.0, 0.0, 1.0];
    let mut nc = 1;
    // f' = c1 + 2 c2 t + 3 c3 t²
    let (qa, qb, qc) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let mut crit = [f64::NAN; 2];
    if qa.abs() > 1e-300 {
        let disc = qb * qb - 4.0 * qa * qc;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            let q = -0.5 * (qb + qb.signum() * sq);
            crit = [q / qa, if q != 0.0 { qc / q } else { f64::NAN }];
        }
    } else if qb.abs() > 1e-300 {
        crit[0] = -qc / qb;
    }
    if crit[0] > crit[1] {
        crit.swap(0, 1);
    }
    for t in crit {
        if t > 0.0 && t < 1.0 {
            cuts[nc] = t;
            nc += 1;
        }
    }
    cuts[nc] = 1.0;
    let mut roots = [0.0; 3];
    let mut nr = 0;
    for k in 0..nc {
        let (mut lo, mut hi) = (cuts[k], cuts[k + 1]);
        let (mut flo, fhi) = (f(lo), f(hi));
        if flo == 0.0 {
            if nr == 0 || roots[nr - 1] != lo {
                roots[nr] = lo;
                nr += 1;
            }
            continue;
        }
        if fhi == 0.0 {
            if k + 1 == nc {
                roots[nr] = hi;
                nr += 1;
            }
            continue;
        }
        if (flo < 0.0) == (fhi < 0.0) {
            continue;
        }
        for _ in 0..60 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            let fm = f(mid);
            if (fm < 0.0) == (flo < 0.0) {
                lo = mid;
                flo = fm;
            } else {
                hi = mid;
            }
        }
        if nr < 3 {
            roots[nr] = 0.5 * (lo + hi);
            nr += 1;
        }
    }
    (roots, nr)
}

/// Coefficients of the cubic `(x1(t) − x0(t)) × (x2(t) − x0(t)) · (x3(t) −
/// x0(t))` for points moving linearly from `p` to `q` over t ∈ [0, 1]: zero
/// when the four points are coplanar.
pub fn coplanarity_cubic(p: [&V; 4], q: [&V; 4]) -> [f64; 4] {
    let vol = |t: f64| {
        let at = |k: usize| p[k] + (q[k] - p[k]) * t;
        let o = at(0);
        (at(1) - o).cross(&(at(2) - o)).dot(&(at(3) - o))
    };
    // the cubic through its values at t = 0, 1/3, 2/3, 1 (exact: the
    // volume is a cubic in t), by Newton's forward differences
    let (f0, f1, f2, f3) = (vol(0.0), vol(1.0 / 3.0), vol(2.0 / 3.0), vol(1.0));
    let d1 = f1 - f0;
    let d2 = f2 - 2.0 * f1 + f0;
    let d3 = f3 - 3.0 * f2 + 3.0 * f1 - f0;
    // f(t) = f0 + d1 u + d2 u(u−1)/2 + d3 u(u−1)(u−2)/6 with u = 3t
    let c3 = d3 * 27.0 / 6.0;
    let c2 = d2 * 9.0 / 2.0 - d3 * 9.0 * 3.0 / 6.0;
    let c1 = d1 * 3.0 - d2 * 3.0 / 2.0 + d3 * 3.0 * 2.0 / 6.0;
    [f0, c1, c2, c3]
}

/// Whether segment p–q crosses triangle (a, b, c) (signed volumes; an end
/// on the triangle counts as crossing; a segment in the triangle's plane,
/// to 1e-12 of the sizes, does not).
pub fn segment_crosses_triangle(p: &V, q: &V, a: &V, b: &V, c: &V) -> bool {
    let vol = |u: &V, v: &V, w: &V, z: &V| (v - u).cross(&(w - u)).dot(&(z - u));
    let l = (b - a).norm() + (c - a).norm() + (q - p).norm();
    let eps = 1e-12 * l * l * l;
    let sp = vol(a, b, c, p);
    let sq = vol(a, b, c, q);
    if (sp > eps && sq > eps) || (sp < -eps && sq < -eps) || (sp.abs() <= eps && sq.abs() <= eps) {
        return false;
    }
    let e1 = vol(p, q, a, b);
    let e2 = vol(p, q, b, c);
    let e3 = vol(p, q, c, a);
    (e1 >= 0.0 && e2 >= 0.0 && e3 >= 0.0) || (e1 <= 0.0 && e2 <= 0.0 && e3 <= 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_roots_of_known_cubic() {
        // (t − 0.2)(t − 0.5)(t − 0.9)
        let (r1, r2, r3) = (0.2, 0.5, 0.9);
        let c = [
            -r1 * r2 * r3,
            r1 * r2 + r1 * r3 + r2 * r3,
            -(r1 + r2 + r3),
            1.0,
        ];
        let (roots, n) = cubic_roots(c);
        assert_eq!(n, 3);
        for (a, b) in roots.iter().zip([r1, r2, r3]) {
            assert!((a - b).abs() < 1e-12, "{roots:?}");
        }
    }

    #[test]
    fn coplanarity_cubic_matches_direct_volume() {
        let p = [
            V::new(0.0, 0.0, 0.0),
            V::new(1.0, 0.1, 0.0),
            V::new(0.2, 1.0, 0.1),
            V::new(0.3, 0.3, 1.0),
        ];
        let q = [
            V::new(0.1, 0.0, 0.2),
            V::new(1.0, 0.3, -0.1),
            V::new(0.0, 1.2, 0.1),
            V::new(0.3, 0.4, -1.0),
        ];
        let c = coplanarity_cubic([&p[0], &p[1], &p[2], &p[3]], [&q[0], &q[1], &q[2], &q[3]]);
        for t in [0.0, 0.17, 0.5, 0.83, 1.0] {
            let at = |k: usize| p[k] + (q[k] - p[k]) * t;
            let direct = (at(1) - at(0))
                .cross(&(at(2) - at(0)))
                .dot(&(at(3) - at(0)));
            let poly = ((c[3] * t + c[2]) * t + c[1]) * t + c[0];
            assert!((direct - poly).abs() < 1e-12, "{t}: {direct} vs {poly}");
        }
    }

    #[test]
    fn closest_points() {
        let (a, b, c) = (
            V::new(0.0, 0.0, 0.0),
            V::new(1.0, 0.0, 0.0),
            V::new(0.0, 1.0, 0.0),
        );
        let w = point_triangle(&V::new(0.25, 0.25, 0.3), &a, &b, &c);
        assert!((w[0] - 0.5).abs() < 1e-12 && (w[1] - 0.25).abs() < 1e-12);
        let w = point_triangle(&V::new(2.0, -1.0, 0.3), &a, &b, &c);
        assert_eq!(w, [0.0, 1.0, 0.0]);
        let (s, t) = segment_segment(
            &V::new(0.0, 0.0, 0.0),
            &V::new(1.0, 0.0, 0.0),
            &V::new(0.3, -1.0, 0.5),
            &V::new(0.3, 1.0, 0.5),
        );
        assert!((s - 0.3).abs() < 1e-12 && (t - 0.5).abs() < 1e-12);
    }
}
