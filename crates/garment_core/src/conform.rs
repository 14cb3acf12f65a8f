//! A garment panel's grid made to conform to its outline
//! ([`crate::cloth::Border::Conforming`]): every corner of the pattern's
//! outline is a vertex, and no element of the grid spans a part of the
//! plane the panel does not cover.
//!
//! The interior stays the thesis' warp/weft grid (MODEL.md §8); only the
//! border changes:
//! - each corner takes the grid node nearest to it (a kept node moved onto
//!   the corner, or a node outside the outline kept and moved there); two
//!   corners nearer each other than [`MERGE`] spacings share one node, a
//!   short edge then having both its ends on it;
//! - a grid link (a spring between two kept nodes) exists only when the
//!   segment between them, in material positions, stays inside the outline:
//!   springs no longer bridge a dart's notch or the gap between a collar's
//!   tips;
//! - a kept node not tied to the panel along both threads is dropped.

use crate::plane::{polygon_contains, seg_dist, REMOVED};

/// Corners nearer each other than this many spacings share a vertex.
pub const MERGE: f64 = 0.25;

/// Keeps a grid node for every corner, moved onto it (material positions in
/// `material`, indexed through `grid_vertex` as in [`crate::cloth::Cloth`]).
/// Returns the grid node of each corner.
#[allow(clippy::too_many_arguments)]
pub(crate) fn place_corners(
    corners: &[[f64; 2]],
    node_uv: &dyn Fn(usize, usize) -> [f64; 2],
    nx: usize,
    ny: usize,
    lc: f64,
    lt: f64,
    grid_vertex: &mut [usize],
    material: &mut Vec<[f64; 2]>,
) -> Vec<usize> {
    let h = lc.min(lt);
    let o = node_uv(0, 0);
    let mut taken: Vec<usize> = Vec::with_capacity(corners.len());
    for (k, &c) in corners.iter().enumerate() {
        // a corner on (or next to) an earlier one shares its node
        if let Some(m) = (0..k).find(|&m| dist(corners[m], c) < MERGE * h) {
            taken.push(taken[m]);
            continue;
        }
        let fi = (c[0] - o[0]) / lc;
        let fj = (c[1] - o[1]) / lt;
        let lo = |f: f64, n: usize| ((f.floor() as i64) - 1).clamp(0, n as i64 - 1) as usize;
        let hi = |f: f64, n: usize| ((f.ceil() as i64) + 1).clamp(0, n as i64 - 1) as usize;
        let mut cand: Vec<(f64, usize)> = Vec::new();
        for j in lo(fj, ny)..=hi(fj, ny) {
            for i in lo(fi, nx)..=hi(fi, nx) {
                cand.push((dist(node_uv(i, j), c), j * nx + i));
            }
        }
        cand.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let node = cand
            .iter()
            .map(|&(_, n)| n)
            .find(|n| !taken.contains(n))
            .unwrap_or(cand[0].1);
        match grid_vertex[node] {
            REMOVED => {
                grid_vertex[node] = material.len();
                material.push(c);
            }
            v => material[v] = c,
        }
        taken.push(node);
    }
    taken
}

/// Which grid links stay inside the outline.
pub(crate) struct Links<'a> {
    poly: &'a [[f64; 2]],
    /// Grid nodes within a cell or two of the outline: only their links can
    /// leave it.
    near: Vec<bool>,
    tol: f64,
}

impl<'a> Links<'a> {
    pub(crate) fn new(
        poly: &'a [[f64; 2]],
        node_uv: &dyn Fn(usize, usize) -> [f64; 2],
        nx: usize,
        ny: usize,
        lc: f64,
        lt: f64,
    ) -> Links<'a> {
        let o = node_uv(0, 0);
        let mut near = vec![false; nx * ny];
        let n = poly.len();
        for k in 0..n {
            let (a, b) = (poly[k], poly[(k + 1) % n]);
            let idx = |u: f64, l: f64, o: f64, m: usize, up: bool| {
                let f = (u - o) / l;
                let g = if up {
                    f.ceil() as i64 + 2
                } else {
                    f.floor() as i64 - 2
                };
                g.clamp(0, m as i64 - 1) as usize
            };
            let (i0, i1) = (
                idx(a[0].min(b[0]), lc, o[0], nx, false),
                idx(a[0].max(b[0]), lc, o[0], nx, true),
            );
            let (j0, j1) = (
                idx(a[1].min(b[1]), lt, o[1], ny, false),
                idx(a[1].max(b[1]), lt, o[1], ny, true),
            );
            for j in j0..=j1 {
                for i in i0..=i1 {
                    near[j * nx + i] = true;
                }
            }
        }
        Links {
            poly,
            near,
            tol: 1e-9 * lc.min(lt),
        }
    }

    /// Does the segment between grid nodes `na` and `nb`, at material
    /// positions `p` and `q`, stay inside the outline (on it counts)?
    pub(crate) fn inside(&self, na: usize, nb: usize, p: [f64; 2], q: [f64; 2]) -> bool {
        if !self.near[na] && !self.near[nb] {
            return true;
        }
        segment_inside(self.poly, p, q, self.tol)
    }
}

/// Drops every kept node that is not tied to the panel both along warp and
/// along weft (a link to a kept neighbour each way), until every node left
/// is: a node held by springs of one direction only would hang on them
/// like a whisker. Renumbers the vertices (`grid_vertex` and `material` as
/// in [`place_corners`]).
pub(crate) fn drop_unlinked(
    links: &Links,
    nx: usize,
    ny: usize,
    grid_vertex: &mut [usize],
    material: &mut Vec<[f64; 2]>,
) {
    let mut dropped = false;
    loop {
        let kept = |i: i64, j: i64, gvx: &[usize]| -> Option<usize> {
            if i < 0 || j < 0 || i >= nx as i64 || j >= ny as i64 {
                return None;
            }
            let k = j as usize * nx + i as usize;
            (gvx[k] != REMOVED).then_some(k)
        };
        let mut drop = Vec::new();
        for j in 0..ny as i64 {
            for i in 0..nx as i64 {
                let Some(a) = kept(i, j, grid_vertex) else {
                    continue;
                };
                let tied = |dirs: [(i64, i64); 2]| {
                    dirs.iter().any(|&(di, dj)| {
                        kept(i + di, j + dj, grid_vertex).is_some_and(|b| {
                            links.inside(a, b, material[grid_vertex[a]], material[grid_vertex[b]])
                        })
                    })
                };
                if !(tied([(1, 0), (-1, 0)]) && tied([(0, 1), (0, -1)])) {
                    drop.push(a);
                }
            }
        }
        if drop.is_empty() {
            break;
        }
        dropped = true;
        for &k in &drop {
            grid_vertex[k] = REMOVED;
        }
    }
    if !dropped {
        return;
    }
    let old = std::mem::take(material);
    for v in grid_vertex.iter_mut().filter(|v| **v != REMOVED) {
        let m = old[*v];
        *v = material.len();
        material.push(m);
    }
}

/// Does the segment `pq` stay inside the closed polygon (touching its
/// border counts as inside)? Its midpoint is inside or on the border and it
/// crosses no side of the polygon.
pub(crate) fn segment_inside(poly: &[[f64; 2]], p: [f64; 2], q: [f64; 2], tol: f64) -> bool {
    let n = poly.len();
    let mid = [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])];
    let on_border = (0..n).any(|k| seg_dist(mid, poly[k], poly[(k + 1) % n]) <= tol);
    if !(on_border || polygon_contains(poly, mid)) {
        return false;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    // a proper crossing: each segment's ends strictly on either side of the
    // other's line (beyond round-off)
    let eps = tol * dist(p, q).max(tol);
    (0..n).all(|k| {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        let (d1, d2) = (cross(a, b, p), cross(a, b, q));
        let (d3, d4) = (cross(p, q, a), cross(p, q, b));
        let e = eps.max(tol * dist(a, b));
        !(((d1 > e && d2 < -e) || (d1 < -e && d2 > e))
            && ((d3 > e && d4 < -e) || (d3 < -e && d4 > e)))
    })
}

/// Twice the signed area of the triangle `abc` (positive counter-clockwise).
pub(crate) fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

pub(crate) fn dist(p: [f64; 2], q: [f64; 2]) -> f64 {
    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_segment_across_a_notch_is_outside_and_one_along_the_border_inside() {
        // a square with a V notch cut from its top down to (0.5, 0.4)
        let poly = [
            [0.0, 0.0],
            [1.0, 0.0],
            [1.0, 1.0],
            [0.55, 1.0],
            [0.5, 0.4],
            [0.45, 1.0],
            [0.0, 1.0],
        ];
        let tol = 1e-12;
        // across the notch, both ends inside the material
        assert!(!segment_inside(&poly, [0.3, 0.9], [0.7, 0.9], tol));
        // below the notch's tip
        assert!(segment_inside(&poly, [0.3, 0.3], [0.7, 0.3], tol));
        // along a side, on the border
        assert!(segment_inside(&poly, [0.0, 0.2], [0.0, 0.8], tol));
        // from the border into the notch's free space
        assert!(!segment_inside(&poly, [0.45, 1.0], [0.55, 1.0], tol));
        // wholly outside
        assert!(!segment_inside(&poly, [1.2, 0.2], [1.4, 0.2], tol));
    }
}
