//! The distance between two shapes of a cloth, thesis eq. 6.2 (§6.4.2.2):
//! the mean (and here also the largest) distance from each vertex of the
//! shape with fewer vertices to its homologue on the other.
//!
//! Homologues are found, in this order:
//! - **grid**: both shapes carry material coordinates (u, v) and have the
//!   same vertices in the same order (same grid): vertex i ↔ vertex i;
//! - **material**: both carry (u, v) on different grids: the point of the
//!   other shape at the same material point (linear interpolation in the
//!   triangle of its (u, v) mesh holding it);
//! - **nearest**: otherwise (or when asked): the nearest point of the other
//!   shape's surface (of its vertices when it has no faces).

use crate::pictures::render::{full_scale, FieldPicture};
use anyhow::{bail, Result};
use nalgebra::{Point3, Vector3};
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::TriMesh;
use serde::Serialize;

pub use crate::scene::shape::Shape;

type V3 = Vector3<f64>;

/// Where material points are on a shape: its triangles in (u, v), bucketed
/// on a uniform grid for the search.
pub struct MaterialLocator<'a> {
    shape: &'a Shape,
    lo: [f64; 2],
    cell: f64,
    n: [usize; 2],
    buckets: Vec<Vec<usize>>,
}

impl<'a> MaterialLocator<'a> {
    /// `None` when the shape has no material coordinates or no triangles.
    pub fn new(shape: &'a Shape) -> Option<MaterialLocator<'a>> {
        let m = shape.material.as_ref()?;
        if shape.triangles.is_empty() {
            return None;
        }
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in m {
            for d in 0..2 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
        let area = ((hi[0] - lo[0]) * (hi[1] - lo[1])).max(1e-12);
        let cell = (area / shape.triangles.len() as f64).sqrt().max(1e-9) * 2.0;
        let n = [
            ((hi[0] - lo[0]) / cell).ceil().max(1.0) as usize,
            ((hi[1] - lo[1]) / cell).ceil().max(1.0) as usize,
        ];
        let mut buckets = vec![Vec::new(); n[0] * n[1]];
        let bin = |x: f64, d: usize| (((x - lo[d]) / cell).floor().max(0.0) as usize).min(n[d] - 1);
        for (k, t) in shape.triangles.iter().enumerate() {
            let (mut a, mut b) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for &i in t {
                for d in 0..2 {
                    a[d] = a[d].min(m[i][d]);
                    b[d] = b[d].max(m[i][d]);
                }
            }
            for i in bin(a[0], 0)..=bin(b[0], 0) {
                for j in bin(a[1], 1)..=bin(b[1], 1) {
                    buckets[j * n[0] + i].push(k);
                }
            }
        }
        Some(MaterialLocator {
            shape,
            lo,
            cell,
            n,
            buckets,
        })
    }

    /// The triangle holding material point (u, v) (within `tol`, m) and the
    /// barycentric weights of its corners; the best one (least outside)
    /// when several hold it.
    pub fn locate(&self, uv: [f64; 2], tol: f64) -> Option<(usize, [f64; 3])> {
        let m = self.shape.material.as_ref()?;
        let bin = |x: f64, d: usize| -> Option<usize> {
            let f = ((x - self.lo[d]) / self.cell).floor();
            let k = f as i64;
            if k < -1 || k > self.n[d] as i64 {
                return None;
            }
            Some((k.max(0) as usize).min(self.n[d] - 1))
        };
        let (i, j) = (bin(uv[0], 0)?, bin(uv[1], 1)?);
        let mut best: Option<(f64, usize, [f64; 3])> = None;
        for &k in &self.buckets[j * self.n[0] + i] {
            let t = self.shape.triangles[k];
            let (a, b, c) = (m[t[0]], m[t[1]], m[t[2]]);
            let det = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
            if det.abs() < 1e-300 {
                continue;
            }
            let l1 = ((uv[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (uv[1] - a[1])) / det;
            let l2 = ((b[0] - a[0]) * (uv[1] - a[1]) - (uv[0] - a[0]) * (b[1] - a[1])) / det;
            let w = [1.0 - l1 - l2, l1, l2];
            // how far outside, in metres of material (0 inside)
            let edge = [(b, c), (c, a), (a, b)];
            let mut out: f64 = 0.0;
            for q in 0..3 {
                if w[q] < 0.0 {
                    let (p0, p1) = edge[q];
                    let len = ((p1[0] - p0[0]).powi(2) + (p1[1] - p0[1]).powi(2)).sqrt();
                    out = out.max(-w[q] * det.abs() / len.max(1e-300));
                }
            }
            if out <= tol && best.as_ref().is_none_or(|b| out < b.0) {
                best = Some((out, k, w));
            }
        }
        best.map(|b| (b.1, b.2))
    }

    /// The shape's point at material point (u, v).
    pub fn at(&self, uv: [f64; 2], tol: f64) -> Option<V3> {
        let (k, w) = self.locate(uv, tol)?;
        let t = self.shape.triangles[k];
        Some(
            self.shape.vertices[t[0]] * w[0]
                + self.shape.vertices[t[1]] * w[1]
                + self.shape.vertices[t[2]] * w[2],
        )
    }
}

/// How homologous points were paired.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Correspondence {
    /// Same grid: vertex i with vertex i.
    Grid,
    /// Same material point (u, v).
    Material,
    /// Nearest point of the other surface.
    Nearest,
}

impl std::fmt::Display for Correspondence {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Correspondence::Grid => "grid (vertex i with vertex i: same grid)",
            Correspondence::Material => "material coordinates (same point (u, v) of the cloth)",
            Correspondence::Nearest => "nearest points (nearest point of the other surface)",
        })
    }
}

/// The result of eq. 6.2.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    /// Mean distance (eq. 6.2), m.
    pub mean: f64,
    /// Largest distance, m.
    pub max: f64,
    /// Root mean square distance, m.
    pub rms: f64,
    pub correspondence: Correspondence,
    /// Which shape's vertices the distances are measured from ("A" or "B":
    /// the one with fewer vertices, A when equal).
    pub from: &'static str,
    pub points: usize,
    /// Per vertex of that shape, m.
    #[serde(skip)]
    pub distances: Vec<f64>,
}

/// Material points of one shape farther than this (m) outside the other's
/// material domain have no homologue there.
pub const MATERIAL_TOLERANCE: f64 = 1e-6;

/// Thesis eq. 6.2 between shapes `a` and `b` (see the module's doc for the
/// pairing); `nearest` forces nearest points.
pub fn compare(a: &Shape, b: &Shape, nearest: bool) -> Result<Comparison> {
    let (from, s, l) = if b.vertices.len() < a.vertices.len() {
        ("B", b, a)
    } else {
        ("A", a, b)
    };
    let same_grid = !nearest
        && match (&s.material, &l.material) {
            (Some(ms), Some(ml)) => {
                ms.len() == ml.len()
                    && ms
                        .iter()
                        .zip(ml)
                        .all(|(p, q)| (p[0] - q[0]).abs() <= 1e-9 && (p[1] - q[1]).abs() <= 1e-9)
            }
            _ => false,
        };
    let (correspondence, distances) = if same_grid {
        let d = s
            .vertices
            .iter()
            .zip(&l.vertices)
            .map(|(p, q)| (p - q).norm())
            .collect();
        (Correspondence::Grid, d)
    } else if let (false, Some(ms), Some(loc)) = (nearest, &s.material, MaterialLocator::new(l)) {
        let mut d = Vec::with_capacity(ms.len());
        for (k, (m, p)) in ms.iter().zip(&s.vertices).enumerate() {
            let Some(q) = loc.at(*m, MATERIAL_TOLERANCE) else {
                let other = if from == "A" { "B" } else { "A" };
                bail!(
                    "vertex {k} of {from} at material point ({:.6}, {:.6}) m lies outside {other}'s \
                     cloth: the shapes are not the same cloth (compare with nearest points instead)",
                    m[0],
                    m[1]
                );
            };
            d.push((q - p).norm());
        }
        (Correspondence::Material, d)
    } else {
        let d = if l.triangles.is_empty() {
            s.vertices
                .iter()
                .map(|p| {
                    l.vertices
                        .iter()
                        .map(|q| (p - q).norm())
                        .fold(f64::INFINITY, f64::min)
                })
                .collect()
        } else {
            let pts: Vec<Point3<f64>> = l.vertices.iter().map(|p| Point3::from(*p)).collect();
            let tris: Vec<[u32; 3]> = l
                .triangles
                .iter()
                .map(|t| [t[0] as u32, t[1] as u32, t[2] as u32])
                .collect();
            let mesh = TriMesh::new(pts, tris).map_err(|e| {
                anyhow::anyhow!(
                    "shape {}: bad triangle mesh: {e:?}",
                    if from == "A" { "B" } else { "A" }
                )
            })?;
            s.vertices
                .iter()
                .map(|p| {
                    let q = mesh.project_local_point(&Point3::from(*p), false).point;
                    (q.coords - p).norm()
                })
                .collect()
        };
        (Correspondence::Nearest, d)
    };
    let n = distances.len().max(1) as f64;
    let mean = distances.iter().sum::<f64>() / n;
    let max = distances.iter().cloned().fold(0.0, f64::max);
    let rms = (distances.iter().map(|d| d * d).sum::<f64>() / n).sqrt();
    Ok(Comparison {
        mean,
        max,
        rms,
        correspondence,
        from,
        points: distances.len(),
        distances,
    })
}

/// The distance map: the shape the distances are measured from, coloured
/// by distance (front, back and side views).
pub fn distance_picture(shape: &Shape, c: &Comparison, title: &str) -> FieldPicture {
    FieldPicture {
        title: title.to_string(),
        info: vec![
            format!("mean {:.2} mm", c.mean * 1e3),
            format!("largest {:.2} mm", c.max * 1e3),
            format!("{} points of {}", c.points, c.from),
            match c.correspondence {
                Correspondence::Grid => "same grid".into(),
                Correspondence::Material => "homologues by (u, v)".into(),
                Correspondence::Nearest => "nearest points".into(),
            },
        ],
        cloth: shape.surface(),
        field: c.distances.clone(),
        full: full_scale(&c.distances, 1e-4),
        label: ("distance".into(), "mm".into()),
        label_scale: 1e3,
        obstacles: Vec::new(),
        size: (1200, 520),
    }
}
