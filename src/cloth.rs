//! The warp/weft grid (thesis §3.1): point masses, tension springs along warp
//! and weft, shear springs on both diagonals of every cell, bending hinges of
//! four masses (thesis Fig. 3.5), and per-spring hysteresis memory.
//!
//! Material coordinates: `u` along warp (grid index `i`, spacing `l_c`), `v`
//! along weft (grid index `j`, spacing `l_t`). Vertex `(i, j)` has index
//! `j * nx + i` ("grid order": rows of constant weft index). The cloth's local
//! frame maps warp to +x, weft to +y and the face normal to +z; `pose` places it
//! in the world.

use crate::fabric::LawState;
use anyhow::{bail, Result};
use nalgebra::{Isometry3, Point3, Vector3};

/// Largest grid the builder accepts (vertices); larger asks are a clear error.
pub const MAX_VERTICES: usize = 4_000_000;

#[derive(Debug, Clone)]
pub struct GridSpec {
    /// Size along warp and weft, m.
    pub size: [f64; 2],
    /// Requested spacing along warp (l_c) and weft (l_t), m. The grid uses the
    /// nearest spacing that divides the size exactly.
    pub spacing: [f64; 2],
    /// Pose of the cloth's local frame in the world.
    pub pose: Isometry3<f64>,
}

/// A tension (structure) spring between grid neighbours.
#[derive(Debug, Clone, Copy)]
pub struct TensionSpring {
    pub a: usize,
    pub b: usize,
    /// Along weft (true) or warp (false).
    pub weft: bool,
    /// Width of material it stands for, m (l_t or l_t/2 for warp springs).
    pub width: f64,
    /// Rest length (its own direction's spacing), m.
    pub l0: f64,
    /// The other direction's spacing (for the shear correction, eq. 4.59), m.
    pub l_other: f64,
}

/// A shear spring on a cell diagonal (Provot; thesis ch. 4).
#[derive(Debug, Clone, Copy)]
pub struct ShearSpring {
    pub a: usize,
    pub b: usize,
    /// Cell sides l_c, l_t, m.
    pub lc: f64,
    pub lt: f64,
    /// Rest length sqrt(l_c² + l_t²), m.
    pub l0: f64,
}

/// A bending hinge: shared edge `v[0]–v[1]`, wings `v[2]` and `v[3]`.
#[derive(Debug, Clone, Copy)]
pub struct Hinge {
    pub v: [usize; 4],
    /// Bends the weft threads (curvature along weft) when true, warp otherwise.
    pub weft: bool,
    /// Rest length of the shared edge, m (width of material).
    pub len: f64,
    /// Mean rest height of the two triangles over the edge, m (κ = θ / h).
    pub h: f64,
}

#[derive(Debug, Clone)]
pub struct Cloth {
    pub nx: usize,
    pub ny: usize,
    pub lc: f64,
    pub lt: f64,
    /// Material coordinates (u along warp, v along weft), m.
    pub material: Vec<[f64; 2]>,
    pub x: Vec<Vector3<f64>>,
    pub v: Vec<Vector3<f64>>,
    pub mass: Vec<f64>,
    pub tension: Vec<TensionSpring>,
    pub shear: Vec<ShearSpring>,
    pub hinges: Vec<Hinge>,
    pub tension_state: Vec<LawState>,
    pub shear_state: Vec<LawState>,
    pub hinge_state: Vec<LawState>,
    /// Triangles of the surface (for output), counter-clockwise seen from +z.
    pub triangles: Vec<[usize; 3]>,
}

impl Cloth {
    /// Builds a rectangular warp/weft grid of a fabric with the given areal mass.
    pub fn grid(spec: &GridSpec, areal_mass: f64) -> Result<Cloth> {
        for (k, n) in ["size.warp", "size.weft"].iter().enumerate() {
            if !(spec.size[k].is_finite() && spec.size[k] > 0.0) {
                bail!("cloth {n} = {}: must be > 0 m", spec.size[k]);
            }
            if !(spec.spacing[k].is_finite() && spec.spacing[k] > 0.0) {
                bail!("cloth spacing = {}: must be > 0 m", spec.spacing[k]);
            }
        }
        let nx = (spec.size[0] / spec.spacing[0]).round().max(1.0) as usize + 1;
        let ny = (spec.size[1] / spec.spacing[1]).round().max(1.0) as usize + 1;
        if nx.saturating_mul(ny) > MAX_VERTICES {
            bail!(
                "cloth of {nx} × {ny} vertices is larger than the limit of {MAX_VERTICES}; use a coarser spacing"
            );
        }
        let lc = spec.size[0] / (nx - 1) as f64;
        let lt = spec.size[1] / (ny - 1) as f64;
        let id = |i: usize, j: usize| j * nx + i;
        let n = nx * ny;
        let mut material = Vec::with_capacity(n);
        let mut x = Vec::with_capacity(n);
        let mut mass = Vec::with_capacity(n);
        for j in 0..ny {
            for i in 0..nx {
                let (u, v) = (i as f64 * lc, j as f64 * lt);
                material.push([u, v]);
                x.push((spec.pose * Point3::new(u, v, 0.0)).coords);
                let fu = if i == 0 || i == nx - 1 { 0.5 } else { 1.0 };
                let fv = if j == 0 || j == ny - 1 { 0.5 } else { 1.0 };
                mass.push(areal_mass * lc * lt * fu * fv);
            }
        }
        let mut tension = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                if i + 1 < nx {
                    let half = j == 0 || j == ny - 1;
                    tension.push(TensionSpring {
                        a: id(i, j),
                        b: id(i + 1, j),
                        weft: false,
                        width: if half { lt / 2.0 } else { lt },
                        l0: lc,
                        l_other: lt,
                    });
                }
                if j + 1 < ny {
                    let half = i == 0 || i == nx - 1;
                    tension.push(TensionSpring {
                        a: id(i, j),
                        b: id(i, j + 1),
                        weft: true,
                        width: if half { lc / 2.0 } else { lc },
                        l0: lt,
                        l_other: lc,
                    });
                }
            }
        }
        let l0 = (lc * lc + lt * lt).sqrt();
        let mut shear = Vec::new();
        let mut triangles = Vec::new();
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                shear.push(ShearSpring {
                    a,
                    b: c,
                    lc,
                    lt,
                    l0,
                });
                shear.push(ShearSpring {
                    a: b,
                    b: d,
                    lc,
                    lt,
                    l0,
                });
                if (i + j) % 2 == 0 {
                    triangles.push([a, b, c]);
                    triangles.push([a, c, d]);
                } else {
                    triangles.push([a, b, d]);
                    triangles.push([b, c, d]);
                }
            }
        }
        // Hinges. Warp bending (curvature along warp) folds about a weft edge
        // (i,j)–(i,j+1); its wings are the warp neighbours (i−1,j) and
        // (i+1,j+1), placed symmetrically about the edge's midpoint. Weft
        // bending likewise about a warp edge.
        let mut hinges = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                if i >= 1 && i + 1 < nx && j + 1 < ny {
                    hinges.push(Hinge {
                        v: [id(i, j), id(i, j + 1), id(i - 1, j), id(i + 1, j + 1)],
                        weft: false,
                        len: lt,
                        h: lc,
                    });
                }
                if j >= 1 && j + 1 < ny && i + 1 < nx {
                    hinges.push(Hinge {
                        v: [id(i, j), id(i + 1, j), id(i, j - 1), id(i + 1, j + 1)],
                        weft: true,
                        len: lc,
                        h: lt,
                    });
                }
            }
        }
        let cloth = Cloth {
            nx,
            ny,
            lc,
            lt,
            material,
            v: vec![Vector3::zeros(); n],
            x,
            mass,
            tension_state: vec![LawState::at(0.0); tension.len()],
            shear_state: vec![LawState::at(0.0); shear.len()],
            hinge_state: vec![LawState::at(0.0); hinges.len()],
            tension,
            shear,
            hinges,
            triangles,
        };
        Ok(cloth)
    }

    pub fn len(&self) -> usize {
        self.x.len()
    }

    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Index of grid vertex (i, j), or an error naming the bad index.
    pub fn index(&self, i: usize, j: usize) -> Result<usize> {
        if i >= self.nx || j >= self.ny {
            bail!(
                "grid index ({i}, {j}) is outside the cloth's {} × {} grid",
                self.nx,
                self.ny
            );
        }
        Ok(j * self.nx + i)
    }

    pub fn total_mass(&self) -> f64 {
        self.mass.iter().sum()
    }

    /// Bilinear interpolation of the current positions at material point (u, v).
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
}
