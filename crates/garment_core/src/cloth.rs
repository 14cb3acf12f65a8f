//! The warp/weft grid (thesis §3.1): point masses, tension springs along warp
//! and weft, shear springs on both diagonals of every cell, bending hinges of
//! four masses (thesis Fig. 3.5), and per-spring hysteresis memory.
//!
//! Material coordinates: `u` along warp (grid index `i`, spacing `l_c`), `v`
//! along weft (grid index `j`, spacing `l_t`). Vertex `(i, j)` has index
//! `j * nx + i` ("grid order": rows of constant weft index). The cloth's local
//! frame maps warp to +x, weft to +y and the face normal to +z; `pose` places it
//! in the world.

use crate::conform;
use crate::error::{fail, Result};
use crate::fabric::LawState;
pub(crate) use crate::plane::seg_dist;
pub use crate::plane::{polygon_contains, REMOVED};
use nalgebra::{Isometry3, Point3, Vector3};

/// Largest grid the builder accepts (vertices); larger asks are a clear error.
pub const MAX_VERTICES: usize = 4_000_000;

#[derive(Debug, Clone)]
/// A rectangular warp/weft grid: its size, spacing and pose ([`Cloth::grid`]).
pub struct GridSpec {
    /// Size along warp and weft, m.
    pub size: [f64; 2],
    /// Requested spacing along warp (l_c) and weft (l_t), m. The grid uses the
    /// nearest spacing that divides the size exactly.
    pub spacing: [f64; 2],
    /// Pose of the cloth's local frame in the world.
    pub pose: Isometry3<f64>,
}

impl GridSpec {
    /// Vertices along warp and weft (the spacing rounded to fit the size);
    /// the size and spacing are assumed finite and > 0.
    pub fn dims(&self) -> (usize, usize) {
        let n = |k: usize| (self.size[k] / self.spacing[k]).round().max(1.0) as usize + 1;
        (n(0), n(1))
    }
}

/// A tension (structure) spring between grid neighbours.
#[derive(Debug, Clone, Copy)]
pub struct TensionSpring {
    /// First end (vertex index).
    pub a: usize,
    /// Second end (vertex index).
    pub b: usize,
    /// Along weft (true) or warp (false).
    pub weft: bool,
    /// Width of material it stands for, m (l_t or l_t/2 for warp springs).
    pub width: f64,
    /// Rest length (its own direction's spacing), m.
    pub l0: f64,
    /// The other direction's spacing (for the shear correction, eq. 4.59), m.
    pub l_other: f64,
    /// Subtract the spurious shear of eq. 4.59 (the diagonal springs read a
    /// stretch as shear; the cells' measure, [`ShearCell`], does not).
    pub corrected: bool,
}

/// A shear spring on a cell diagonal (Provot; thesis ch. 4).
#[derive(Debug, Clone, Copy)]
pub struct ShearSpring {
    /// First end (vertex index).
    pub a: usize,
    /// Second end (vertex index).
    pub b: usize,
    /// Cell sides l_c, l_t, m.
    pub lc: f64,
    /// Cell side l_t (weft), m.
    pub lt: f64,
    /// Rest length sqrt(l_c² + l_t²), m.
    pub l0: f64,
}

impl ShearSpring {
    /// The shear measure of a diagonal of length `l`, thesis eq. 4.34/4.35:
    /// `sin θ = (l² − l_c² − l_t²) / (2 l_c l_t)`.
    #[inline]
    pub fn strain(&self, l: f64) -> f64 {
        (l * l - self.l0 * self.l0) / (2.0 * self.lc * self.lt)
    }
}

/// The shear element of a grid cell ([`Cloth::use_cell_shear`]): its two
/// diagonals `v[0]–v[1]` and `v[2]–v[3]` share one measure. For a cell of
/// sides `l_c`, `l_t` sheared in its plane by θ the diagonals' squares move by
/// `±2 l_c l_t sin θ`, so
/// `sin θ = [(l₁² − l₁₀²) − (l₂² − l₂₀²)] / (4 l_c l_t)`: the thesis' eq. 4.34
/// from both diagonals at once. Each diagonal alone ([`ShearSpring`], eq. 4.34
/// as the thesis uses it) also reads a stretch of the cell and a fold across
/// the other diagonal as shear, a strain growing as (κh)² that makes coarse
/// grids resist folds; their difference reads neither, so the tension springs
/// need no correction (eq. 4.59). It reads no egg-crate either, which no hinge
/// sees: [`EggCrateGuard`] comes with it.
#[derive(Debug, Clone, Copy)]
pub struct ShearCell {
    /// Diagonal 1 is `v[0]–v[1]`, diagonal 2 `v[2]–v[3]`; `v[0]` is the cell's
    /// corner (i, j), `v[1]` (i + 1, j + 1), `v[2]` (i + 1, j), `v[3]` (i, j + 1).
    pub v: [usize; 4],
    /// Cell sides l_c (warp), l_t (weft), m.
    pub lc: f64,
    /// Cell side l_t (weft), m.
    pub lt: f64,
    /// Rest lengths of the two diagonals, m.
    pub l1: f64,
    /// Rest length of diagonal 2, m.
    pub l2: f64,
}

impl ShearCell {
    /// The two diagonals' vectors `x[v1] − x[v0]`, `x[v3] − x[v2]`.
    #[inline(always)]
    pub fn diagonals(&self, x: &[Vector3<f64>]) -> (Vector3<f64>, Vector3<f64>) {
        (x[self.v[1]] - x[self.v[0]], x[self.v[3]] - x[self.v[2]])
    }

    /// The shear measure `sin θ` of the cell with diagonals `d1`, `d2`.
    #[inline(always)]
    pub fn strain_of(&self, d1: &Vector3<f64>, d2: &Vector3<f64>) -> f64 {
        ((d1.norm_squared() - self.l1 * self.l1) - (d2.norm_squared() - self.l2 * self.l2))
            / (4.0 * self.lc * self.lt)
    }

    /// The shear measure `sin θ` at positions `x`.
    #[inline]
    pub fn strain(&self, x: &[Vector3<f64>]) -> f64 {
        let (d1, d2) = self.diagonals(x);
        self.strain_of(&d1, &d2)
    }
}

/// A guard of the grid's egg-crate mode (every vertex alternately up and
/// down, each thread segment at its length), which no bending hinge sees
/// (each hinge's four vertices stay coplanar) and only the diagonal springs
/// read: six vertices, two neighbouring cells along one thread, `v[0..3]` a
/// row of three along the thread and `v[3..6]` the next row, with weights
/// [`EGG_CRATE_WEIGHTS`]. `D = Σ w_p x_p` is the third difference
/// `l² l' x_uuv` (u along the thread): zero on a plane and on a cylinder
/// along either thread, `O(h³)` on any smooth shape, and `8a` on the
/// egg-crate of amplitude `a`. Energy `k |D|²` with `k = B l' / (8 l³)` (`B`
/// the elastic bending rigidity of the thread the second difference runs
/// along, `l` its spacing, `l'` the other): the egg-crate costs `½ B κ²` per
/// area for each thread, `κ = 4a/l²` the curvature of its zigzag, and a
/// smooth shape `B l² |x_uuv|² / 8` per area, which vanishes with the
/// spacing.
#[derive(Debug, Clone, Copy)]
pub struct EggCrateGuard {
    /// `v[0..3]` a row of three vertices along the thread, `v[3..6]` the next row.
    pub v: [usize; 6],
    /// The second difference runs along weft (true) or warp.
    pub weft: bool,
    /// `l' / (8 l³)`, 1/m².
    pub scale: f64,
}

/// The weights of [`EggCrateGuard`].
pub const EGG_CRATE_WEIGHTS: [f64; 6] = [1.0, -2.0, 1.0, -1.0, 2.0, -1.0];

/// A bending hinge: shared edge `v[0]–v[1]`, wings `v[2]` and `v[3]`.
#[derive(Debug, Clone, Copy)]
pub struct Hinge {
    /// Shared edge `v[0]–v[1]`, wings `v[2]` and `v[3]`.
    pub v: [usize; 4],
    /// Bends the weft threads (curvature along weft) when true, warp otherwise.
    pub weft: bool,
    /// Rest length of the shared edge, m (width of material).
    pub len: f64,
    /// Mean rest height of the two triangles over the edge, m (κ = θ / h).
    pub h: f64,
}

/// A seam stitch (MODEL.md §8): a zero-length linear spring between a point
/// of one panel's edge and the interpolated point of the other panel's edge.
/// The gap is `g = Σ_k c[k]·x[v[k]]` (`c = [1, −(1−t), −t]` for vertex
/// `v[0]` sewn to the point at fraction `t` between `v[1]` and `v[2]`); the
/// energy is `½ k |g|²` and the damping force `−d ġ` on the gap, spread on
/// the three vertices by `c`. Linear in the positions, so its stiffness
/// matrix `k c cᵀ ⊗ I₃` is exact and constant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stitch {
    /// The sewn vertex `v[0]` and the edge `v[1]–v[2]` it is sewn to.
    pub v: [usize; 3],
    /// The gap's coefficients: `g = Σ_k c[k]·x[v[k]]`.
    pub c: [f64; 3],
    /// Stiffness, N/m.
    pub k: f64,
    /// Damping, N·s/m.
    pub d: f64,
}

impl Stitch {
    /// The gap vector `Σ c_k x_{v_k}` at positions `x`, m.
    pub fn gap(&self, x: &[Vector3<f64>]) -> Vector3<f64> {
        x[self.v[0]] * self.c[0] + x[self.v[1]] * self.c[1] + x[self.v[2]] * self.c[2]
    }
}

/// One finite vector per vertex of a cloth of `n`, or the error naming
/// `what` (positions, velocities).
fn check_vertices(what: &str, x: &[Vector3<f64>], n: usize) -> Result<()> {
    if x.len() != n {
        fail!(
            length(what, x.len(), n),
            "{} {what} given for a cloth of {n} vertices",
            x.len()
        );
    }
    if let Some(i) = x.iter().position(|p| !p.iter().all(|c| c.is_finite())) {
        fail!(
            non_finite(what, i),
            "{what}: vertex {i} is not finite: ({}, {}, {})",
            x[i].x,
            x[i].y,
            x[i].z
        );
    }
    Ok(())
}

/// Distance from `p` to the closed polygon and the closest point on it.
fn closest_on_polygon(poly: &[[f64; 2]], p: [f64; 2]) -> (f64, [f64; 2]) {
    let n = poly.len();
    let mut best = (f64::INFINITY, p);
    for k in 0..n {
        let (a, b) = (poly[k], poly[(k + 1) % n]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let l2 = dx * dx + dy * dy;
        let t = if l2 > 0.0 {
            (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let q = [a[0] + t * dx, a[1] + t * dy];
        let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
        if d < best.0 {
            best = (d, q);
        }
    }
    best
}

/// Keeps the outside nodes next to the border and moves them onto it (see
/// [`Cloth::clipped_to_outline`]).
#[allow(clippy::too_many_arguments)]
fn snap_border(
    poly: &[[f64; 2]],
    node_uv: &dyn Fn(usize, usize) -> [f64; 2],
    nx: usize,
    ny: usize,
    lc: f64,
    lt: f64,
    grid_vertex: &mut [usize],
    material: &mut Vec<[f64; 2]>,
) {
    let h = lc.min(lt);
    let mut moved: Vec<(usize, [f64; 2])> = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            if grid_vertex[j * nx + i] != REMOVED {
                continue;
            }
            let (d, q) = closest_on_polygon(poly, node_uv(i, j));
            // (a node half a spacing out, up to round-off, is kept)
            if d > 0.5 * h * (1.0 + 1e-9) {
                continue;
            }
            // one of the node's cells overlaps the outline
            let overlaps = [(-1i64, -1i64), (0, -1), (-1, 0), (0, 0)]
                .iter()
                .any(|&(di, dj)| {
                    let (ci, cj) = (i as i64 + di, j as i64 + dj);
                    if ci < 0 || cj < 0 || ci >= nx as i64 - 1 || cj >= ny as i64 - 1 {
                        return false;
                    }
                    let (a, b) = (
                        node_uv(ci as usize, cj as usize),
                        node_uv(ci as usize + 1, cj as usize + 1),
                    );
                    clipped_area(poly, a[0], b[0], a[1], b[1]) > 1e-6 * lc * lt
                });
            if !overlaps {
                continue;
            }
            // at least 0.3 spacing from every kept neighbour
            let mut clear = true;
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    let (ni, nj) = (i as i64 + di, j as i64 + dj);
                    if (di, dj) == (0, 0) || ni < 0 || nj < 0 || ni >= nx as i64 || nj >= ny as i64
                    {
                        continue;
                    }
                    let node = nj as usize * nx + ni as usize;
                    let other = match grid_vertex[node] {
                        REMOVED => moved.iter().find(|m| m.0 == node).map(|m| m.1),
                        v => Some(material[v]),
                    };
                    if let Some(o) = other {
                        if ((o[0] - q[0]).powi(2) + (o[1] - q[1]).powi(2)).sqrt() < 0.3 * h {
                            clear = false;
                        }
                    }
                }
            }
            if clear {
                moved.push((j * nx + i, q));
            }
        }
    }
    for (node, q) in moved {
        grid_vertex[node] = material.len();
        material.push(q);
    }
}

#[derive(Debug, Clone, Default)]
/// A cloth: its vertices (positions, velocities, masses), its elements
/// (springs, hinges, cells, guards, seam stitches) with their hysteresis
/// memories, and its triangles.
pub struct Cloth {
    /// Grid nodes along warp.
    pub nx: usize,
    /// Grid nodes along weft.
    pub ny: usize,
    /// Grid spacing along warp (l_c), m.
    pub lc: f64,
    /// Grid spacing along weft (l_t), m.
    pub lt: f64,
    /// Material coordinates (u along warp, v along weft), m.
    pub material: Vec<[f64; 2]>,
    /// Positions, m ([`Cloth::positions`], [`Cloth::set_positions`]).
    pub(crate) x: Vec<Vector3<f64>>,
    /// Velocities, m/s ([`Cloth::velocities`], [`Cloth::set_velocities`]).
    pub(crate) v: Vec<Vector3<f64>>,
    /// Masses, kg.
    pub mass: Vec<f64>,
    /// Tension springs along warp and weft.
    pub tension: Vec<TensionSpring>,
    /// Shear springs on the cells' diagonals.
    pub shear: Vec<ShearSpring>,
    /// Bending hinges.
    pub hinges: Vec<Hinge>,
    /// Hysteresis memory of each tension spring.
    pub tension_state: Vec<LawState>,
    /// Hysteresis memory of each shear spring.
    pub shear_state: Vec<LawState>,
    /// The cells' shear elements and their memories, in place of `shear`
    /// after [`Cloth::use_cell_shear`] (empty otherwise).
    pub shear_cells: Vec<ShearCell>,
    /// Hysteresis memory of each shear cell.
    pub shear_cell_state: Vec<LawState>,
    /// Guards of the egg-crate mode, with `shear_cells`.
    pub guards: Vec<EggCrateGuard>,
    /// Hysteresis memory of each hinge.
    pub hinge_state: Vec<LawState>,
    /// Triangles of the surface (for output), counter-clockwise seen from +z.
    pub triangles: Vec<[usize; 3]>,
    /// For a grid clipped to an outline ([`Cloth::clipped`]): the vertex of
    /// grid node `j·nx + i`, or [`REMOVED`]. Empty for a full rectangular grid,
    /// whose vertex of node (i, j) is `j·nx + i`.
    pub grid_vertex: Vec<usize>,
    /// Seam stitches joining panels of a garment (empty for a single piece;
    /// [`Cloth::seams`], [`Cloth::set_seam_gains`]).
    pub(crate) seams: Vec<Stitch>,
    /// The fabric of each vertex, an index into the simulation's fabrics
    /// (a garment whose panels are cut from several); empty: all the first.
    /// Every spring and hinge lies within one panel and takes its fabric.
    pub vertex_fabric: Vec<u16>,
}

/// Edge length and mean wing height over the edge line of hinge `v`, from
/// the material positions `m`.
fn hinge_rest(m: &[[f64; 2]], v: [usize; 4]) -> (f64, f64) {
    let (p, q) = (m[v[0]], m[v[1]]);
    let e = [q[0] - p[0], q[1] - p[1]];
    let el = (e[0] * e[0] + e[1] * e[1]).sqrt();
    let height = |w: [f64; 2]| ((w[0] - p[0]) * e[1] - (w[1] - p[1]) * e[0]).abs() / el;
    (el, 0.5 * (height(m[v[2]]) + height(m[v[3]])))
}

/// A closed outline in material coordinates (u along warp, v along weft), m.
#[derive(Debug, Clone, PartialEq)]
pub enum Outline {
    /// The rectangle `[0, size[0]] × [0, size[1]]`, m.
    Rectangle {
        /// Side lengths along warp and weft, m.
        size: [f64; 2],
    },
    /// A circle.
    Circle {
        /// Centre, m.
        center: [f64; 2],
        /// Radius, m.
        radius: f64,
    },
    /// Simple polygon (either orientation), vertices in order, not repeated.
    Polygon(Vec<[f64; 2]>),
}

/// Segments of the polygon standing for a circle when cells are clipped
/// (area error ≈ 2π³ r² / (3 n²) = 1.6e-5 of the disc at n = 1024).
pub const CIRCLE_SEGMENTS: usize = 1024;

impl Outline {
    /// The outline as a polygon (a circle as [`CIRCLE_SEGMENTS`] segments).
    pub fn polygon(&self) -> Vec<[f64; 2]> {
        match self {
            Outline::Rectangle { size } => vec![
                [0.0, 0.0],
                [size[0], 0.0],
                [size[0], size[1]],
                [0.0, size[1]],
            ],
            Outline::Circle { center, radius } => (0..CIRCLE_SEGMENTS)
                .map(|k| {
                    let a = 2.0 * std::f64::consts::PI * k as f64 / CIRCLE_SEGMENTS as f64;
                    [center[0] + radius * a.cos(), center[1] + radius * a.sin()]
                })
                .collect(),
            Outline::Polygon(p) => p.clone(),
        }
    }

    /// Is the point inside or on the outline (within `tol`)?
    pub fn contains(&self, p: [f64; 2], tol: f64) -> bool {
        match self {
            Outline::Rectangle { size } => {
                (-tol..=size[0] + tol).contains(&p[0]) && (-tol..=size[1] + tol).contains(&p[1])
            }
            Outline::Circle { center, radius } => {
                let (dx, dy) = (p[0] - center[0], p[1] - center[1]);
                (dx * dx + dy * dy).sqrt() <= radius + tol
            }
            Outline::Polygon(poly) => {
                let n = poly.len();
                polygon_contains(poly, p)
                    || (0..n).any(|k| seg_dist(p, poly[k], poly[(k + 1) % n]) <= tol)
            }
        }
    }

    /// Enclosed area, m².
    pub fn area(&self) -> f64 {
        match self {
            Outline::Rectangle { size } => size[0] * size[1],
            Outline::Circle { radius, .. } => std::f64::consts::PI * radius * radius,
            Outline::Polygon(p) => polygon_area(p).abs(),
        }
    }

    fn validate(&self) -> Result<()> {
        match self {
            Outline::Rectangle { size } => {
                if !size.iter().all(|s| s.is_finite() && *s > 0.0) {
                    fail!(
                        mesh,
                        "outline rectangle {size:?} m: sides must be finite and > 0"
                    );
                }
            }
            Outline::Circle { center, radius } => {
                if !(radius.is_finite() && *radius > 0.0 && center.iter().all(|c| c.is_finite())) {
                    fail!(
                        mesh,
                        "outline circle radius {radius} m at {center:?}: must be finite and > 0"
                    );
                }
            }
            Outline::Polygon(p) => {
                if p.len() < 3 || p.iter().flatten().any(|c| !c.is_finite()) {
                    fail!(
                        mesh,
                        "outline polygon needs at least 3 finite vertices, got {}",
                        p.len()
                    );
                }
                if polygon_area(p).abs() < 1e-12 {
                    fail!(mesh, "outline polygon has zero area");
                }
            }
        }
        Ok(())
    }
}

/// The convex hull of points in the plane, counter-clockwise (Andrew's
/// monotone chain); fewer than three distinct points give an empty hull.
pub fn convex_hull(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return Vec::new();
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let it: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in it {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// Signed shoelace area (positive counter-clockwise).
pub fn polygon_area(p: &[[f64; 2]]) -> f64 {
    let n = p.len();
    (0..n)
        .map(|k| {
            let (a, b) = (p[k], p[(k + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Area of a polygon inside the axis-aligned rectangle [u0, u1] × [v0, v1]
/// (Sutherland–Hodgman clipping of the polygon by the rectangle's four half
/// planes; exact for any simple polygon, since the clip region is convex).
pub fn clipped_area(poly: &[[f64; 2]], u0: f64, u1: f64, v0: f64, v1: f64) -> f64 {
    let mut cur: Vec<[f64; 2]> = poly.to_vec();
    // (axis, bound, keep >= bound)
    for (axis, bound, ge) in [(0, u0, true), (0, u1, false), (1, v0, true), (1, v1, false)] {
        if cur.is_empty() {
            return 0.0;
        }
        let inside = |p: &[f64; 2]| {
            if ge {
                p[axis] >= bound
            } else {
                p[axis] <= bound
            }
        };
        let mut next = Vec::with_capacity(cur.len() + 4);
        for k in 0..cur.len() {
            let (a, b) = (cur[k], cur[(k + 1) % cur.len()]);
            let (ia, ib) = (inside(&a), inside(&b));
            if ia {
                next.push(a);
            }
            if ia != ib {
                let t = (bound - a[axis]) / (b[axis] - a[axis]);
                next.push([a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]);
            }
        }
        cur = next;
    }
    if cur.len() < 3 {
        0.0
    } else {
        polygon_area(&cur).abs()
    }
}

/// How the bending hinges of a panel are laid out on its grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum HingeLayout {
    /// One hinge per grid edge whose wings sit on a skewed diagonal, e.g.
    /// `(i−1, j)` and `(i+1, j+1)` about the edge `(i, j)–(i, j+1)` for warp
    /// bending, `(i, j−1)` and `(i+1, j+1)` about `(i, j)–(i+1, j)` for weft
    /// bending.
    #[default]
    Skewed,
    /// Mirror-symmetric pairs of hinges.
    ///
    /// The skewed single hinge is right for a fold along the warp or
    /// the weft (the KES bending test), but it breaks the woven fabric's mirror
    /// symmetry about its threads: a fold whose generators run along one cell
    /// diagonal leaves its four masses coplanar and costs no bending at all, one
    /// along the other diagonal costs twice the continuum energy (an isometric
    /// cylinder of radius 3 cm at 0.25 cm spacing, linear law, energy over
    /// `B κ²/2 × area`: 0.99, 1.69, 1.97, 1.69, 0.99, 0.29, 0, 0.29 for
    /// generators at 0°, 22.5°, … 157.5° from the weft). A drape folds in every
    /// direction, so with the single hinge an isotropic fabric's folds gather
    /// where bending is free, the node pattern follows the grid and the drape
    /// coefficient moves with the spacing (wool tropical: 55.9 % at 1 cm, 49.1 %
    /// at 0.5 cm).
    ///
    /// Here each edge gets both skewed stencils, `(i−1, j), (i+1, j+1)` and
    /// `(i−1, j+1), (i+1, j)` (and likewise for weft bending), each standing for
    /// half the edge's width of material; where the border leaves only one of
    /// the two, that one carries the whole width, as the single hinge did. The
    /// pair costs the same energy as the single hinge for folds along the
    /// threads, and 0.99 of the continuum energy in every direction on the same
    /// cylinder. Rest lengths and heights come from the material positions (as
    /// [`Cloth::clipped_to_outline`] does for the nodes it moved onto the
    /// outline). The memories of the hinges start at zero (the flat specimen).
    MirrorSymmetric,
}

/// How the border of a panel follows its outline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Border {
    /// The grid nodes inside the outline (a staircase along a slanted or
    /// curved side).
    #[default]
    Staircase,
    /// The staircase plus nodes outside moved onto the outline (see
    /// [`Cloth::panel`]).
    OnOutline,
    /// [`Border::OnOutline`] for a garment panel: every corner of
    /// [`PanelSpec::corners`] is a vertex, and no element spans a part of
    /// the plane outside the outline ([`crate::conform`]).
    Conforming,
}

/// A warp/weft panel: its outline in material coordinates, the grid that
/// fills it, where it lies in the world, and its hinge layout.
#[derive(Debug, Clone)]
pub struct PanelSpec {
    /// The outline, material coordinates.
    pub outline: Outline,
    /// Grid spacing along warp (l_c) and weft (l_t), m (a rectangle's: the
    /// nearest that divides its sides).
    pub spacing: [f64; 2],
    /// A grid node's material position (the grid of a rectangle starts at
    /// its corner (0, 0)), m.
    pub origin: [f64; 2],
    /// Pose of the cloth's local frame in the world.
    pub pose: Isometry3<f64>,
    /// kg/m².
    pub areal_mass: f64,
    /// How the grid meets the outline.
    pub border: Border,
    /// How the bending hinges are laid out.
    pub hinges: HingeLayout,
    /// Points of the outline that must be vertices (material coordinates),
    /// with [`Border::Conforming`]: a pattern's corners.
    pub corners: Vec<[f64; 2]>,
}

impl PanelSpec {
    /// A panel of the outline, its border a staircase, skewed hinges.
    pub fn new(
        outline: &Outline,
        spacing: [f64; 2],
        origin: [f64; 2],
        pose: &Isometry3<f64>,
        areal_mass: f64,
    ) -> PanelSpec {
        PanelSpec {
            outline: outline.clone(),
            spacing,
            origin,
            pose: *pose,
            areal_mass,
            border: Border::Staircase,
            hinges: HingeLayout::Skewed,
            corners: Vec::new(),
        }
    }

    /// The rectangle of a [`GridSpec`], skewed hinges.
    pub fn rectangle(spec: &GridSpec, areal_mass: f64) -> PanelSpec {
        PanelSpec {
            outline: Outline::Rectangle { size: spec.size },
            spacing: spec.spacing,
            origin: [0.0, 0.0],
            pose: spec.pose,
            areal_mass,
            border: Border::Staircase,
            hinges: HingeLayout::Skewed,
            corners: Vec::new(),
        }
    }
}

/// The hinges of a grid in the given layout. `gv(i, j)` is the vertex of
/// grid node (i, j) if kept, `m` the material positions; rest lengths and
/// heights come from them when `from_material` (always for the mirror
/// pairs), else from the spacings. The memories start at zero (flat).
#[allow(clippy::too_many_arguments)]
fn layout_hinges(
    layout: HingeLayout,
    nx: usize,
    ny: usize,
    gv: &dyn Fn(i64, i64) -> Option<usize>,
    m: &[[f64; 2]],
    from_material: bool,
    lc: f64,
    lt: f64,
) -> Vec<Hinge> {
    let (nx, ny) = (nx as i64, ny as i64);
    let mut hinges = Vec::new();
    match layout {
        HingeLayout::Skewed => {
            let rest = |v: [usize; 4], len: f64, h: f64| -> (f64, f64) {
                if from_material {
                    hinge_rest(m, v)
                } else {
                    (len, h)
                }
            };
            for j in 0..ny {
                for i in 0..nx {
                    let Some(a) = gv(i, j) else { continue };
                    // warp bending folds about the weft edge (i,j)–(i,j+1);
                    // its wings are the warp neighbours (i−1,j) and
                    // (i+1,j+1), placed symmetrically about the edge's
                    // midpoint; weft bending likewise about a warp edge
                    if let (Some(v1), Some(w0), Some(w1)) =
                        (gv(i, j + 1), gv(i - 1, j), gv(i + 1, j + 1))
                    {
                        let (len, h) = rest([a, v1, w0, w1], lt, lc);
                        hinges.push(Hinge {
                            v: [a, v1, w0, w1],
                            weft: false,
                            len,
                            h,
                        });
                    }
                    if let (Some(v1), Some(w0), Some(w1)) =
                        (gv(i + 1, j), gv(i, j - 1), gv(i + 1, j + 1))
                    {
                        let (len, h) = rest([a, v1, w0, w1], lc, lt);
                        hinges.push(Hinge {
                            v: [a, v1, w0, w1],
                            weft: true,
                            len,
                            h,
                        });
                    }
                }
            }
        }
        HingeLayout::MirrorSymmetric => {
            for j in 0..ny {
                for i in 0..nx {
                    for weft in [false, true] {
                        // shared edge and the two wing pairs
                        let stencils = if weft {
                            [
                                [(i, j), (i + 1, j), (i, j - 1), (i + 1, j + 1)],
                                [(i, j), (i + 1, j), (i + 1, j - 1), (i, j + 1)],
                            ]
                        } else {
                            [
                                [(i, j), (i, j + 1), (i - 1, j), (i + 1, j + 1)],
                                [(i, j), (i, j + 1), (i - 1, j + 1), (i + 1, j)],
                            ]
                        };
                        let kept: Vec<[usize; 4]> = stencils
                            .iter()
                            .filter_map(|st| {
                                let v: Vec<usize> =
                                    st.iter().filter_map(|&(p, q)| gv(p, q)).collect();
                                (v.len() == 4).then(|| [v[0], v[1], v[2], v[3]])
                            })
                            .collect();
                        let share = 1.0 / kept.len().max(1) as f64;
                        for v in kept {
                            let (len, h) = hinge_rest(m, v);
                            hinges.push(Hinge {
                                v,
                                weft,
                                len: len * share,
                                h,
                            });
                        }
                    }
                }
            }
        }
    }
    hinges
}

impl Cloth {
    /// Builds a rectangular warp/weft grid of a fabric with the given areal
    /// mass: [`Cloth::panel`] of the rectangle, skewed hinges.
    pub fn grid(spec: &GridSpec, areal_mass: f64) -> Result<Cloth> {
        Cloth::panel(&PanelSpec::rectangle(spec, areal_mass))
    }

    /// A warp/weft grid clipped to a closed outline (circle, polygon), its
    /// border a staircase of grid nodes, skewed hinges: [`Cloth::panel`].
    pub fn clipped(
        outline: &Outline,
        spacing: [f64; 2],
        origin: [f64; 2],
        pose: &Isometry3<f64>,
        areal_mass: f64,
    ) -> Result<Cloth> {
        Cloth::panel(&PanelSpec::new(outline, spacing, origin, pose, areal_mass))
    }

    /// [`Cloth::clipped`] with its border on the outline ([`Border::OnOutline`]).
    pub fn clipped_to_outline(
        outline: &Outline,
        spacing: [f64; 2],
        origin: [f64; 2],
        pose: &Isometry3<f64>,
        areal_mass: f64,
    ) -> Result<Cloth> {
        Cloth::panel(&PanelSpec {
            border: Border::OnOutline,
            ..PanelSpec::new(outline, spacing, origin, pose, areal_mass)
        })
    }

    /// A warp/weft panel: the grid over its outline, the masses, springs,
    /// hinges (in [`PanelSpec::hinges`]' layout) and triangles of the part
    /// inside it. Every piece is one: a rectangular cloth, a drapemeter
    /// specimen, a garment panel.
    ///
    /// Grid nodes sit at `origin + (i·l_c, j·l_t)` (material coordinates) over
    /// the outline's bounding box; a node is kept when it lies inside the
    /// outline (or on it, within 1e-9 of the spacing). Each cell's area inside
    /// the outline (exact polygon clipping) is lumped in equal shares onto its
    /// kept corners, so the total mass is the areal mass times the clipped
    /// area, less the slivers of cells with no kept corner. Elements exist only
    /// where all their vertices are kept:
    /// - a tension spring when both ends are; it stands for half the clipped
    ///   area of each of its two neighbouring cells, i.e. width
    ///   `(A_below + A_above) / (2 l)` (which gives the full grid's `l_t` and
    ///   `l_t/2` on whole cells);
    /// - a cell's two shear springs when its four corners are (the pair carries
    ///   the shear, eq. 4.54, and is what the tension correction eq. 4.59
    ///   compensates; a lone diagonal would not be a shear spring);
    /// - a hinge when its four masses are.
    ///
    /// A rectangle ([`Outline::Rectangle`]) is the grid fitted to it: its
    /// spacing is the nearest that divides its sides, every cell is whole,
    /// so each node carries `l_c l_t` of material (halved on each side it
    /// lies on) and each tension spring the width `l_t` (`l_t/2` on the
    /// border), every node is kept ([`Cloth::grid_vertex`] empty) and the
    /// border is on the outline already.
    ///
    /// With [`Border::OnOutline`], a node outside the outline is kept too
    /// when it lies within half a spacing of it, belongs to a cell that
    /// overlaps the outline, and its closest point on the outline is at least
    /// 0.3 spacing from every kept neighbour; it is moved to that point.
    /// Elements touching a moved node take their rest lengths (tension and
    /// shear springs) and rest heights and edge lengths (hinges) from the
    /// moved material positions, so the flat piece is at rest. The staircase
    /// of [`Border::Staircase`] covers 91 % of a 30 cm disc's 18–30 cm
    /// annulus at 1 cm; this border covers nearly all of it (tested).
    ///
    /// Triangles (output, shadows) cover whole cells and three-corner cells
    /// with their one triangle. `nx`, `ny` are those of the bounding grid;
    /// [`Cloth::grid_vertex`] maps its nodes to vertices.
    pub fn panel(spec: &PanelSpec) -> Result<Cloth> {
        Cloth::panel_with_corners(spec).map(|(cloth, _)| cloth)
    }

    /// [`Cloth::panel`], and the vertex each of [`PanelSpec::corners`] is
    /// (with [`Border::Conforming`]; `None` for a corner whose node had no
    /// link to the rest of the panel and was dropped).
    pub fn panel_with_corners(spec: &PanelSpec) -> Result<(Cloth, Vec<Option<usize>>)> {
        let PanelSpec {
            outline,
            spacing,
            pose,
            areal_mass,
            ..
        } = spec;
        let (spacing, areal_mass) = (*spacing, *areal_mass);
        // every cell whole (a rectangle)
        let whole = matches!(outline, Outline::Rectangle { .. });
        let conform = spec.border == Border::Conforming && !whole;
        let snap = (spec.border == Border::OnOutline || conform) && !whole;
        let (lc, lt, origin, i0, j0, nx, ny);
        if let Outline::Rectangle { size } = outline {
            for (k, n) in ["size.warp", "size.weft"].iter().enumerate() {
                if !(size[k].is_finite() && size[k] > 0.0) {
                    fail!(bound(*n, size[k]), "cloth {n} = {}: must be > 0 m", size[k]);
                }
                if !(spacing[k].is_finite() && spacing[k] > 0.0) {
                    fail!(
                        bound("spacing", spacing[k]),
                        "cloth spacing = {}: must be > 0 m",
                        spacing[k]
                    );
                }
            }
            (nx, ny) = GridSpec {
                size: *size,
                spacing,
                pose: *pose,
            }
            .dims();
            if nx.saturating_mul(ny) > MAX_VERTICES {
                fail!(too_large,
                    "cloth of {nx} × {ny} vertices is larger than the limit of {MAX_VERTICES}; use a coarser spacing"
                );
            }
            lc = size[0] / (nx - 1) as f64;
            lt = size[1] / (ny - 1) as f64;
            (origin, i0, j0) = ([0.0, 0.0], 0, 0);
        } else {
            outline.validate()?;
            (lc, lt) = (spacing[0], spacing[1]);
            if !(lc.is_finite() && lc > 0.0 && lt.is_finite() && lt > 0.0) {
                fail!(
                    bound("spacing", lc.min(lt)),
                    "cloth spacing {spacing:?}: must be > 0 m"
                );
            }
            origin = spec.origin;
            let poly = outline.polygon();
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for p in &poly {
                for k in 0..2 {
                    lo[k] = lo[k].min(p[k]);
                    hi[k] = hi[k].max(p[k]);
                }
            }
            if let Outline::Circle { center, radius } = outline {
                lo = [center[0] - radius, center[1] - radius];
                hi = [center[0] + radius, center[1] + radius];
            }
            i0 = ((lo[0] - origin[0]) / lc).floor() as i64;
            let i1 = ((hi[0] - origin[0]) / lc).ceil() as i64;
            j0 = ((lo[1] - origin[1]) / lt).floor() as i64;
            let j1 = ((hi[1] - origin[1]) / lt).ceil() as i64;
            nx = (i1 - i0 + 1) as usize;
            ny = (j1 - j0 + 1) as usize;
            if nx.saturating_mul(ny) > MAX_VERTICES {
                fail!(too_large,
                    "clipped cloth needs a {nx} × {ny} grid, larger than the limit of {MAX_VERTICES}; use a coarser spacing"
                );
            }
        }
        if !(areal_mass.is_finite() && areal_mass > 0.0) {
            fail!(
                bound("areal mass", areal_mass),
                "areal mass {areal_mass} kg/m²: must be > 0"
            );
        }
        let poly = outline.polygon();
        let node_uv = |i: usize, j: usize| {
            [
                origin[0] + (i0 + i as i64) as f64 * lc,
                origin[1] + (j0 + j as i64) as f64 * lt,
            ]
        };
        let tol = 1e-9 * lc.min(lt);
        let mut grid_vertex = vec![REMOVED; nx * ny];
        let mut material = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let uv = node_uv(i, j);
                if whole || outline.contains(uv, tol) {
                    grid_vertex[j * nx + i] = material.len();
                    material.push(uv);
                }
            }
        }
        let corner_nodes = if conform {
            conform::place_corners(
                &spec.corners,
                &node_uv,
                nx,
                ny,
                lc,
                lt,
                &mut grid_vertex,
                &mut material,
            )
        } else {
            Vec::new()
        };
        if snap {
            snap_border(
                &poly,
                &node_uv,
                nx,
                ny,
                lc,
                lt,
                &mut grid_vertex,
                &mut material,
            );
        }
        let links = conform.then(|| conform::Links::new(&poly, &node_uv, nx, ny, lc, lt));
        if let Some(links) = &links {
            conform::drop_unlinked(links, nx, ny, &mut grid_vertex, &mut material);
        }
        if material.len() < 4 {
            fail!(mesh,
                "outline of area {:.3e} m² keeps only {} grid nodes at spacing {lc} × {lt} m; use a finer spacing",
                outline.area(),
                material.len()
            );
        }
        let n = material.len();
        let gv = |i: i64, j: i64| -> Option<usize> {
            if i < 0 || j < 0 || i >= nx as i64 || j >= ny as i64 {
                return None;
            }
            let v = grid_vertex[j as usize * nx + i as usize];
            (v != REMOVED).then_some(v)
        };
        // clipped area of cell (i, j) = [node i, i+1] × [node j, j+1]
        let mut cell_area = vec![0.0; if whole { 0 } else { (nx - 1) * (ny - 1) }];
        let full = lc * lt;
        for j in 0..if whole { 0 } else { ny - 1 } {
            for i in 0..nx - 1 {
                let (a, b) = (node_uv(i, j), node_uv(i + 1, j + 1));
                let corners_in = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
                    .iter()
                    .all(|&(p, q)| outline.contains(node_uv(p, q), -tol));
                cell_area[j * (nx - 1) + i] =
                    if corners_in && matches!(outline, Outline::Circle { .. }) {
                        full // a circle is convex: four corners inside → the whole cell
                    } else {
                        clipped_area(&poly, a[0], b[0], a[1], b[1])
                    };
            }
        }
        let area = |i: i64, j: i64| -> f64 {
            if i < 0 || j < 0 || i >= nx as i64 - 1 || j >= ny as i64 - 1 {
                0.0
            } else {
                cell_area[j as usize * (nx - 1) + i as usize]
            }
        };
        let mut mass = vec![0.0; n];
        if whole {
            for j in 0..ny {
                for i in 0..nx {
                    let fu = if i == 0 || i == nx - 1 { 0.5 } else { 1.0 };
                    let fv = if j == 0 || j == ny - 1 { 0.5 } else { 1.0 };
                    mass[j * nx + i] = areal_mass * lc * lt * fu * fv;
                }
            }
        }
        for j in 0..if whole { 0 } else { ny as i64 - 1 } {
            for i in 0..nx as i64 - 1 {
                let a = area(i, j);
                let kept: Vec<usize> = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)]
                    .iter()
                    .filter_map(|&(p, q)| gv(p, q))
                    .collect();
                for &v in &kept {
                    mass[v] += areal_mass * a / kept.len() as f64;
                }
            }
        }
        let mut tension = Vec::new();
        let mut shear = Vec::new();
        let mut triangles = Vec::new();
        let l0 = (lc * lc + lt * lt).sqrt();
        let dist = |a: usize, b: usize| {
            let (p, q) = (material[a], material[b]);
            ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt()
        };
        // rest length: the grid's, or from the material positions when nodes
        // were moved onto the border
        let rest = |a: usize, b: usize, nominal: f64| if snap { dist(a, b) } else { nominal };
        // a link between two kept grid nodes: always, but where a conforming
        // border drops the links that leave the outline
        let node = |i: i64, j: i64| j as usize * nx + i as usize;
        let linked = |(i, j): (i64, i64), (p, q): (i64, i64)| -> bool {
            match (&links, gv(i, j), gv(p, q)) {
                (Some(l), Some(a), Some(b)) => {
                    l.inside(node(i, j), node(p, q), material[a], material[b])
                }
                (None, Some(_), Some(_)) => true,
                _ => false,
            }
        };
        // a triangle of kept, linked corners, counter-clockwise in the
        // material plane where the border conforms
        let triangle = |c: [(i64, i64); 3]| -> Option<[usize; 3]> {
            let v = [
                gv(c[0].0, c[0].1)?,
                gv(c[1].0, c[1].1)?,
                gv(c[2].0, c[2].1)?,
            ];
            if links.is_some() {
                let ok = (0..3).all(|k| linked(c[k], c[(k + 1) % 3]))
                    && conform::orient(material[v[0]], material[v[1]], material[v[2]])
                        > 1e-3 * lc * lt;
                if !ok {
                    return None;
                }
            }
            Some(v)
        };
        // a whole cell of four kept corners: its shear pair exists when it is
        // linked all round (and convex, where the border conforms)
        let whole_cell = |i: i64, j: i64| -> bool {
            let c = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
            if !c.iter().all(|&(p, q)| gv(p, q).is_some()) {
                return false;
            }
            if links.is_none() {
                return true;
            }
            let m = c.map(|(p, q)| material[gv(p, q).unwrap()]);
            // no side under a quarter spacing, no diagonal under half its
            // grid length: a cell squashed by a moved corner carries no shear
            let short = (0..4).any(|k| conform::dist(m[k], m[(k + 1) % 4]) < 0.25 * lc.min(lt))
                || conform::dist(m[0], m[2]).min(conform::dist(m[1], m[3])) < 0.5 * l0;
            !short
                && (0..4).all(|k| linked(c[k], c[(k + 1) % 4]))
                && linked(c[0], c[2])
                && linked(c[1], c[3])
                && (0..4)
                    .all(|k| conform::orient(m[k], m[(k + 1) % 4], m[(k + 2) % 4]) > 1e-3 * lc * lt)
        };
        for j in 0..ny as i64 {
            for i in 0..nx as i64 {
                let Some(a) = gv(i, j) else { continue };
                if let Some(b) = gv(i + 1, j).filter(|_| linked((i, j), (i + 1, j))) {
                    tension.push(TensionSpring {
                        a,
                        b,
                        weft: false,
                        width: if !whole {
                            (area(i, j - 1) + area(i, j)) / (2.0 * lc)
                        } else if j == 0 || j == ny as i64 - 1 {
                            lt / 2.0
                        } else {
                            lt
                        },
                        l0: rest(a, b, lc),
                        l_other: lt,
                        corrected: true,
                    });
                }
                if let Some(b) = gv(i, j + 1).filter(|_| linked((i, j), (i, j + 1))) {
                    tension.push(TensionSpring {
                        a,
                        b,
                        weft: true,
                        width: if !whole {
                            (area(i - 1, j) + area(i, j)) / (2.0 * lt)
                        } else if i == 0 || i == nx as i64 - 1 {
                            lc / 2.0
                        } else {
                            lc
                        },
                        l0: rest(a, b, lt),
                        l_other: lc,
                        corrected: true,
                    });
                }
                let (b, c, d) = (gv(i + 1, j), gv(i + 1, j + 1), gv(i, j + 1));
                match (b, c, d) {
                    (Some(b), Some(c), Some(d)) if links.is_none() || whole_cell(i, j) => {
                        for (p, q) in [(a, c), (b, d)] {
                            shear.push(ShearSpring {
                                a: p,
                                b: q,
                                lc,
                                lt,
                                l0: rest(p, q, l0),
                            });
                        }
                        if (i + j) % 2 == 0 {
                            triangles.push([a, b, c]);
                            triangles.push([a, c, d]);
                        } else {
                            triangles.push([a, b, d]);
                            triangles.push([b, c, d]);
                        }
                    }
                    // where the border conforms: the cell's part inside, the
                    // first pair of its triangles that are
                    _ if links.is_some() => {
                        let (p00, p10, p11, p01) = ((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1));
                        for pair in [
                            [[p00, p10, p11], [p00, p11, p01]],
                            [[p00, p10, p01], [p10, p11, p01]],
                        ] {
                            let t: Vec<[usize; 3]> =
                                pair.iter().filter_map(|&c| triangle(c)).collect();
                            if !t.is_empty() {
                                triangles.extend(t);
                                break;
                            }
                        }
                    }
                    (Some(b), Some(c), None) => triangles.push([a, b, c]),
                    (Some(b), None, Some(d)) => triangles.push([a, b, d]),
                    (None, Some(c), Some(d)) => triangles.push([a, c, d]),
                    _ => {}
                }
            }
        }
        // a three-corner cell missing corner (i, j) itself
        for j in 0..ny as i64 - 1 {
            for i in 0..nx as i64 - 1 {
                if links.is_some() {
                    if gv(i, j).is_none() {
                        if let Some(t) = triangle([(i + 1, j), (i + 1, j + 1), (i, j + 1)]) {
                            triangles.push(t);
                        }
                    }
                    continue;
                }
                if gv(i, j).is_none() {
                    if let (Some(b), Some(c), Some(d)) =
                        (gv(i + 1, j), gv(i + 1, j + 1), gv(i, j + 1))
                    {
                        triangles.push([b, c, d]);
                    }
                }
            }
        }
        let mut hinges = layout_hinges(spec.hinges, nx, ny, &gv, &material, snap, lc, lt);
        if links.is_some() {
            // a hinge folds about a spring, each wing tied to it by another
            let springs: std::collections::HashSet<(usize, usize)> = tension
                .iter()
                .map(|s| (s.a.min(s.b), s.a.max(s.b)))
                .collect();
            let tied = |p: usize, q: usize| springs.contains(&(p.min(q), p.max(q)));
            // and each wing stands at least a quarter spacing off the edge's
            // line (a wing moved onto it would make the hinge's curvature
            // θ / h unbounded)
            let off = |h: &Hinge, w: usize| {
                let (p, q, m) = (material[h.v[0]], material[h.v[1]], material[w]);
                conform::orient(p, q, m).abs() / conform::dist(p, q)
            };
            hinges.retain(|h| {
                let [a, b, w0, w1] = h.v;
                tied(a, b)
                    && (tied(a, w0) || tied(b, w0))
                    && (tied(a, w1) || tied(b, w1))
                    && off(h, w0).min(off(h, w1)) >= 0.25 * lc.min(lt)
            });
        }
        let x = material
            .iter()
            .map(|m| (pose * Point3::new(m[0], m[1], 0.0)).coords)
            .collect();
        let corners = corner_nodes
            .iter()
            .map(|&k| (grid_vertex[k] != REMOVED).then_some(grid_vertex[k]))
            .collect();
        let cloth = Cloth {
            nx,
            ny,
            lc,
            lt,
            material,
            x,
            v: vec![Vector3::zeros(); n],
            mass,
            tension_state: vec![LawState::at(0.0); tension.len()],
            shear_state: vec![LawState::at(0.0); shear.len()],
            hinge_state: vec![LawState::at(0.0); hinges.len()],
            tension,
            shear,
            shear_cells: Vec::new(),
            shear_cell_state: Vec::new(),
            guards: Vec::new(),
            hinges,
            triangles,
            // a rectangle keeps every node: node k is vertex k
            grid_vertex: if whole { Vec::new() } else { grid_vertex },
            seams: Vec::new(),
            vertex_fabric: Vec::new(),
        };
        Ok((cloth, corners))
    }

    /// Replaces the diagonal spring pairs of every cell ([`ShearSpring`],
    /// thesis eq. 4.34 per diagonal) by one [`ShearCell`], adds the
    /// [`EggCrateGuard`]s along both threads wherever two neighbouring cells
    /// lie at their grid places, and turns off the tension springs'
    /// correction (eq. 4.59). A cloth already converted is left as it is.
    /// The memories of the cells start at zero.
    pub fn use_cell_shear(&mut self) -> Result<()> {
        if self.shear.is_empty() {
            return Ok(());
        }
        if !self.shear.len().is_multiple_of(2) {
            fail!(
                mesh,
                "{} shear springs: not pairs of cell diagonals",
                self.shear.len()
            );
        }
        let m = &self.material;
        // a cell's four sides are tension springs
        let sides: std::collections::HashSet<(usize, usize)> = self
            .tension
            .iter()
            .map(|t| (t.a.min(t.b), t.a.max(t.b)))
            .collect();
        let side = |a: usize, b: usize| sides.contains(&(a.min(b), a.max(b)));
        let mut cells = Vec::with_capacity(self.shear.len() / 2);
        for (k, p) in self.shear.chunks_exact(2).enumerate() {
            let (d1, d2) = (p[0], p[1]);
            let v = [d1.a, d1.b, d2.a, d2.b];
            if d1.lc != d2.lc
                || d1.lt != d2.lt
                || !(side(v[0], v[2]) && side(v[2], v[1]) && side(v[1], v[3]) && side(v[3], v[0]))
            {
                fail!(
                    mesh,
                    "shear springs {} and {} are not the diagonals of one cell",
                    2 * k,
                    2 * k + 1
                );
            }
            cells.push(ShearCell {
                v,
                lc: d1.lc,
                lt: d1.lt,
                l1: d1.l0,
                l2: d2.l0,
            });
        }
        // neighbours: the cell whose left edge (v0, v3) or bottom edge (v0, v2) it is
        let left: std::collections::HashMap<(usize, usize), usize> = cells
            .iter()
            .enumerate()
            .map(|(k, c)| ((c.v[0], c.v[3]), k))
            .collect();
        let bottom: std::collections::HashMap<(usize, usize), usize> = cells
            .iter()
            .enumerate()
            .map(|(k, c)| ((c.v[0], c.v[2]), k))
            .collect();
        let mut guards = Vec::new();
        for a in &cells {
            for weft in [false, true] {
                let (v, l, lo) = if weft {
                    let Some(&n) = bottom.get(&(a.v[3], a.v[1])) else {
                        continue;
                    };
                    let c = &cells[n];
                    ([a.v[0], a.v[3], c.v[3], a.v[2], a.v[1], c.v[1]], a.lt, a.lc)
                } else {
                    let Some(&n) = left.get(&(a.v[2], a.v[1])) else {
                        continue;
                    };
                    let b = &cells[n];
                    ([a.v[0], a.v[2], b.v[2], a.v[3], a.v[1], b.v[1]], a.lc, a.lt)
                };
                // only where the nodes are at their grid places (a node moved
                // onto an outline would make D nonzero at rest)
                let d0 = (0..6).fold([0.0, 0.0], |d, p| {
                    let w = EGG_CRATE_WEIGHTS[p];
                    [d[0] + w * m[v[p]][0], d[1] + w * m[v[p]][1]]
                });
                if d0[0].hypot(d0[1]) <= 1e-9 * l {
                    guards.push(EggCrateGuard {
                        v,
                        weft,
                        scale: lo / (8.0 * l * l * l),
                    });
                }
            }
        }
        self.shear_cell_state = vec![LawState::at(0.0); cells.len()];
        self.shear_cells = cells;
        self.guards = guards;
        self.shear.clear();
        self.shear_state.clear();
        for t in &mut self.tension {
            t.corrected = false;
        }
        Ok(())
    }

    /// The pieces as one cloth (a garment's panels): vertices, springs,
    /// hinges, memories, triangles and stitches of piece `k` follow those of
    /// the pieces before it, their vertex indices shifted by the vertices
    /// before it. The result has no grid of its own: `nx` is its vertex count
    /// and `ny` 1, so [`Cloth::index`]`(i, 0)` is vertex `i`; `lc`, `lt` are
    /// the first piece's.
    pub fn merge(parts: Vec<Cloth>) -> Result<Cloth> {
        let Some(first) = parts.first() else {
            fail!(invalid, "a cloth needs at least one piece");
        };
        let (lc, lt) = (first.lc, first.lt);
        let mut c = Cloth {
            ny: 1,
            lc,
            lt,
            ..Cloth::default()
        };
        let several = parts.iter().any(|p| !p.vertex_fabric.is_empty());
        for p in parts {
            let o = c.x.len();
            if several {
                if p.vertex_fabric.is_empty() {
                    c.vertex_fabric.extend(std::iter::repeat_n(0, p.len()));
                } else {
                    c.vertex_fabric.extend(&p.vertex_fabric);
                }
            }
            c.material.extend(p.material);
            c.x.extend(p.x);
            c.v.extend(p.v);
            c.mass.extend(p.mass);
            c.tension.extend(p.tension.into_iter().map(|mut s| {
                s.a += o;
                s.b += o;
                s
            }));
            c.shear.extend(p.shear.into_iter().map(|mut s| {
                s.a += o;
                s.b += o;
                s
            }));
            c.shear_cells.extend(p.shear_cells.into_iter().map(|mut s| {
                s.v.iter_mut().for_each(|v| *v += o);
                s
            }));
            c.shear_cell_state.extend(p.shear_cell_state);
            c.guards.extend(p.guards.into_iter().map(|mut s| {
                s.v.iter_mut().for_each(|v| *v += o);
                s
            }));
            c.hinges.extend(p.hinges.into_iter().map(|mut h| {
                h.v.iter_mut().for_each(|v| *v += o);
                h
            }));
            c.tension_state.extend(p.tension_state);
            c.shear_state.extend(p.shear_state);
            c.hinge_state.extend(p.hinge_state);
            c.triangles
                .extend(p.triangles.into_iter().map(|t| t.map(|v| v + o)));
            c.seams.extend(p.seams.into_iter().map(|mut s| {
                s.v.iter_mut().for_each(|v| *v += o);
                s
            }));
        }
        c.nx = c.x.len();
        if c.nx > MAX_VERTICES {
            fail!(
                too_large,
                "the pieces have {} vertices together, more than the limit of {MAX_VERTICES}",
                c.nx
            );
        }
        Ok(c)
    }

    /// Number of vertices.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// Whether the cloth has no vertices.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// The vertices' positions, m.
    pub fn positions(&self) -> &[Vector3<f64>] {
        &self.x
    }

    /// The vertices' velocities, m/s.
    pub fn velocities(&self) -> &[Vector3<f64>] {
        &self.v
    }

    /// The seam stitches joining the panels of a garment.
    pub fn seams(&self) -> &[Stitch] {
        &self.seams
    }

    /// Puts the vertices at `x`, m: one finite position per vertex, or an
    /// [`Error::Length`](crate::Error::Length) or [`Error::NonFinite`](crate::Error::NonFinite) and nothing changed.
    pub fn set_positions(&mut self, x: &[Vector3<f64>]) -> Result<()> {
        check_vertices("positions", x, self.len())?;
        self.x.copy_from_slice(x);
        Ok(())
    }

    /// Puts vertex `i` at `p`, m: an [`Error::Index`](crate::Error::Index) for a vertex beyond
    /// the cloth, an [`Error::NonFinite`](crate::Error::NonFinite) for a position not finite.
    pub fn set_position(&mut self, i: usize, p: Vector3<f64>) -> Result<()> {
        let n = self.len();
        if i >= n {
            fail!(
                index("vertex", i, n),
                "vertex {i}: the cloth has {n} vertices"
            );
        }
        check_vertices("position", std::slice::from_ref(&p), 1)?;
        self.x[i] = p;
        Ok(())
    }

    /// Gives the vertices the velocities `v`, m/s: one finite velocity per
    /// vertex, or an [`Error::Length`](crate::Error::Length) or [`Error::NonFinite`](crate::Error::NonFinite) and nothing
    /// changed.
    pub fn set_velocities(&mut self, v: &[Vector3<f64>]) -> Result<()> {
        check_vertices("velocities", v, self.len())?;
        self.v.copy_from_slice(v);
        Ok(())
    }

    /// Adds seam stitches: each on vertices of this cloth, with finite
    /// coefficients and a finite stiffness and damping ≥ 0, or an error and
    /// nothing added.
    pub fn add_seams(&mut self, stitches: &[Stitch]) -> Result<()> {
        use crate::solver::sets::Element;
        let (first, n) = (self.seams.len(), self.len());
        for (k, s) in stitches.iter().enumerate() {
            s.check(first + k, n)?;
        }
        self.seams.extend_from_slice(stitches);
        Ok(())
    }

    /// Stops every vertex (velocities zero).
    pub fn stop(&mut self) {
        self.v.iter_mut().for_each(|v| *v = Vector3::zeros());
    }

    /// Sets each seam stitch's stiffness (N/m) and damping (N·s/m), `(k,
    /// d)` in the order of [`Cloth::seams`]: one pair per stitch, each finite
    /// and ≥ 0, or an error and nothing changed.
    pub fn set_seam_gains(&mut self, gains: &[(f64, f64)]) -> Result<()> {
        let n = self.seams.len();
        if gains.len() != n {
            fail!(
                length("seam gains", gains.len(), n),
                "{} seam gains for {n} seam stitches",
                gains.len()
            );
        }
        for (i, &(k, d)) in gains.iter().enumerate() {
            for (name, v) in [("stiffness", k), ("damping", d)] {
                if !(v.is_finite() && v >= 0.0) {
                    fail!(
                        bound(format!("seam stitch {i}: {name}"), v),
                        "seam stitch {i}: {name} = {v}: must be a finite number ≥ 0"
                    );
                }
            }
        }
        for (s, &(k, d)) in self.seams.iter_mut().zip(gains) {
            s.k = k;
            s.d = d;
        }
        Ok(())
    }

    /// Index of grid vertex (i, j), or an error naming the bad index.
    pub fn index(&self, i: usize, j: usize) -> Result<usize> {
        if i >= self.nx || j >= self.ny {
            let (k, n) = if i >= self.nx {
                (i, self.nx)
            } else {
                (j, self.ny)
            };
            fail!(
                index("grid index", k, n),
                "grid index ({i}, {j}) is outside the cloth's {} × {} grid",
                self.nx,
                self.ny
            );
        }
        if self.grid_vertex.is_empty() {
            return Ok(j * self.nx + i);
        }
        match self.grid_vertex[j * self.nx + i] {
            REMOVED => fail!(
                mesh,
                "grid node ({i}, {j}) lies outside the cloth's outline"
            ),
            v => Ok(v),
        }
    }

    /// Total mass, kg.
    pub fn total_mass(&self) -> f64 {
        self.mass.iter().sum()
    }

    /// Bilinear interpolation of the current positions at material point (u, v)
    /// of a rectangular grid ([`Cloth::grid`]; not for a clipped cloth).
    pub fn at_material(&self, u: f64, v: f64) -> Vector3<f64> {
        let fi = (u / self.lc).clamp(0.0, (self.nx - 1) as f64);
        let fj = (v / self.lt).clamp(0.0, (self.ny - 1) as f64);
        let i0 = (fi.floor() as usize).min(self.nx.saturating_sub(2));
        let j0 = (fj.floor() as usize).min(self.ny.saturating_sub(2));
        let (a, b) = (fi - i0 as f64, fj - j0 as f64);
        let p = |i: usize, j: usize| self.x[j * self.nx + i];
        p(i0, j0) * (1.0 - a) * (1.0 - b)
            + p(i0 + 1, j0) * a * (1.0 - b)
            + p(i0, j0 + 1) * (1.0 - a) * b
            + p(i0 + 1, j0 + 1) * a * b
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_counts_and_mass() {
        let spec = GridSpec {
            size: [0.5, 0.5],
            spacing: [0.02, 0.02],
            pose: Isometry3::identity(),
        };
        let c = Cloth::grid(&spec, 0.213).unwrap();
        assert_eq!((c.nx, c.ny), (26, 26));
        assert!((c.total_mass() - 0.213 * 0.25).abs() < 1e-12);
        assert_eq!(c.tension.len(), 2 * 25 * 26);
        assert_eq!(c.shear.len(), 2 * 25 * 25);
        assert_eq!(c.hinges.len(), 2 * 24 * 25);
        // widths of warp springs add up to the cloth's weft size on each column
        let w: f64 = c
            .tension
            .iter()
            .filter(|s| !s.weft && s.a % c.nx == 0)
            .map(|s| s.width)
            .sum();
        assert!((w - 0.5).abs() < 1e-12);
        assert!(c.index(26, 0).is_err());
    }

    fn check_elements(c: &Cloth, outline: &Outline) {
        let n = c.len();
        let inside = |v: usize| outline.contains(c.material[v], 1e-9);
        for s in &c.tension {
            assert!(s.a < n && s.b < n && inside(s.a) && inside(s.b));
            assert!(s.width > 0.0);
        }
        for s in &c.shear {
            assert!(s.a < n && s.b < n && inside(s.a) && inside(s.b));
        }
        for h in &c.hinges {
            assert!(h.v.iter().all(|&v| v < n && inside(v)));
        }
        for t in &c.triangles {
            assert!(t.iter().all(|&v| v < n));
        }
        // the map and the vertices agree
        let kept = c.grid_vertex.iter().filter(|&&v| v != REMOVED).count();
        assert_eq!(kept, n);
    }

    #[test]
    fn clipped_circle_mass_and_elements() {
        let r = 0.15;
        let outline = Outline::Circle {
            center: [0.0, 0.0],
            radius: r,
        };
        for h in [0.02, 0.01, 0.005] {
            let c =
                Cloth::clipped(&outline, [h, h], [0.0, 0.0], &Isometry3::identity(), 0.2).unwrap();
            check_elements(&c, &outline);
            let want = 0.2 * std::f64::consts::PI * r * r;
            let err = (c.total_mass() - want).abs() / want;
            // only slivers of cells with no corner inside are lost: O(h²/r²)
            assert!(
                err < 0.3 * (h / r).powi(2) + 2e-5,
                "h {h}: mass error {err}"
            );
            // the centre is a vertex and an interior cell is whole
            let centre = c.index(c.nx / 2, c.ny / 2).unwrap();
            assert!(c.material[centre][0].abs() < 1e-12 && c.material[centre][1].abs() < 1e-12);
            assert!((c.mass[centre] - 0.2 * h * h).abs() < 1e-15);
            // removed nodes are reported as such
            assert!(c.index(0, 0).is_err());
        }
    }

    #[test]
    fn clipped_rectangle_is_the_full_grid() {
        let outline = Outline::Polygon(vec![[0.0, 0.0], [0.5, 0.0], [0.5, 0.3], [0.0, 0.3]]);
        let c = Cloth::clipped(
            &outline,
            [0.05, 0.05],
            [0.0, 0.0],
            &Isometry3::identity(),
            0.213,
        )
        .unwrap();
        let g = Cloth::grid(
            &GridSpec {
                size: [0.5, 0.3],
                spacing: [0.05, 0.05],
                pose: Isometry3::identity(),
            },
            0.213,
        )
        .unwrap();
        assert_eq!(c.len(), g.len());
        assert_eq!(
            (c.tension.len(), c.shear.len(), c.hinges.len()),
            (g.tension.len(), g.shear.len(), g.hinges.len())
        );
        assert_eq!(c.triangles.len(), g.triangles.len());
        for (a, b) in c.mass.iter().zip(&g.mass) {
            assert!((a - b).abs() < 1e-15);
        }
        let w = |c: &Cloth| c.tension.iter().map(|s| s.width).sum::<f64>();
        assert!((w(&c) - w(&g)).abs() < 1e-12);
    }

    #[test]
    fn clipped_concave_polygon() {
        // an L shape: 30 × 30 cm less its 15 × 15 cm top-right quarter, grid
        // offset so that no node falls on the outline
        let outline = Outline::Polygon(vec![
            [0.0, 0.0],
            [0.3, 0.0],
            [0.3, 0.15],
            [0.15, 0.15],
            [0.15, 0.3],
            [0.0, 0.3],
        ]);
        let c = Cloth::clipped(
            &outline,
            [0.02, 0.02],
            [0.005, 0.005],
            &Isometry3::identity(),
            0.1,
        )
        .unwrap();
        check_elements(&c, &outline);
        let want = 0.1 * outline.area();
        assert!((outline.area() - 0.0675).abs() < 1e-12);
        assert!(
            (c.total_mass() - want).abs() < 1e-12 * want.max(1.0),
            "{} vs {want}",
            c.total_mass()
        );
        // no spring crosses the notch: both ends of every spring are inside
        assert!(c.tension.iter().all(|s| {
            let (a, b) = (c.material[s.a], c.material[s.b]);
            let notch = |p: [f64; 2]| p[0] > 0.15 && p[1] > 0.15;
            !notch(a) && !notch(b)
        }));
        assert!(Cloth::clipped(
            &Outline::Polygon(vec![[0.0, 0.0], [1.0, 0.0]]),
            [0.1, 0.1],
            [0.0, 0.0],
            &Isometry3::identity(),
            0.1
        )
        .is_err());
    }

    #[test]
    fn border_on_the_outline_keeps_mass_and_rest_state() {
        // a triangle, whose slanted side cuts the cells at every angle
        let outline = Outline::Polygon(vec![[0.0, 0.0], [0.3, 0.0], [0.0, 0.2]]);
        let pose = Isometry3::identity();
        let a = Cloth::clipped(&outline, [0.02, 0.02], [0.003, 0.003], &pose, 0.1).unwrap();
        let b =
            Cloth::clipped_to_outline(&outline, [0.02, 0.02], [0.003, 0.003], &pose, 0.1).unwrap();
        check_elements(&b, &outline);
        assert!(b.len() > a.len());
        let want = 0.1 * outline.area();
        assert!((b.total_mass() - want).abs() < 1e-12, "{}", b.total_mass());
        // rest lengths are the material distances; hinges have positive heights
        let d = |p: usize, q: usize| {
            let (u, v) = (b.material[p], b.material[q]);
            ((u[0] - v[0]).powi(2) + (u[1] - v[1]).powi(2)).sqrt()
        };
        for s in &b.tension {
            assert!((s.l0 - d(s.a, s.b)).abs() < 1e-15 && s.l0 > 0.005);
        }
        for s in &b.shear {
            assert!((s.l0 - d(s.a, s.b)).abs() < 1e-15);
        }
        assert!(b.hinges.iter().all(|h| h.h > 0.005 && h.len > 0.005));
        // moved nodes sit on the outline
        let moved = b.material.len() - a.material.len();
        let on = b
            .material
            .iter()
            .filter(|&&m| {
                let p = outline.polygon();
                (0..3).any(|k| seg_dist(m, p[k], p[(k + 1) % 3]) < 1e-12)
            })
            .count();
        assert!(on >= moved, "{on} on the outline, {moved} moved");
    }
}
