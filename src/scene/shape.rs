//! A cloth's shape as a file holds it (PLY as `drape` writes it, with the
//! material coordinates; OBJ): what `compare` measures and a mesh sequence
//! plays.

use crate::pictures::render::Surface;
use anyhow::{bail, Context, Result};
use nalgebra::Vector3;
use std::path::Path;

type V3 = Vector3<f64>;

/// A cloth shape: vertices, optional material coordinates (m, on the flat
/// cloth: u along warp, v along weft) and triangles.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Shape {
    pub vertices: Vec<V3>,
    pub material: Option<Vec<[f64; 2]>>,
    pub triangles: Vec<[usize; 3]>,
}

impl Shape {
    /// Reads a shape from an ASCII PLY file (`x y z` and optionally `u v`
    /// per vertex, as `garment_sim drape` writes them; faces as vertex index
    /// lists, fan-triangulated) or a Wavefront OBJ file (no material
    /// coordinates). Errors name the file and the line.
    pub fn read(path: &Path) -> Result<Shape> {
        let is_obj = path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
        let s = if is_obj {
            let (v, t) = crate::io::load_obj(path)?;
            Shape {
                vertices: v.iter().map(|p| V3::from(*p)).collect(),
                material: None,
                triangles: t
                    .iter()
                    .map(|t| [t[0] as usize, t[1] as usize, t[2] as usize])
                    .collect(),
            }
        } else {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read {}", path.display()))?;
            Shape::parse_ply(&text).with_context(|| format!("PLY file {}", path.display()))?
        };
        if s.vertices.is_empty() {
            bail!("{}: no vertices", path.display());
        }
        Ok(s)
    }

    /// Parses an ASCII PLY text (see [`Shape::read`]).
    pub fn parse_ply(text: &str) -> Result<Shape> {
        let mut lines = text.lines().enumerate();
        match lines.next() {
            Some((_, l)) if l.trim() == "ply" => {}
            _ => bail!("line 1: not a PLY file (no 'ply' magic)"),
        }
        let mut n_vertex = 0usize;
        let mut n_face = 0usize;
        let mut props: Vec<String> = Vec::new();
        let mut element = String::new();
        let mut header_end = false;
        for (ln, l) in lines.by_ref() {
            let w: Vec<&str> = l.split_whitespace().collect();
            match w.as_slice() {
                ["format", f, ..] if *f != "ascii" => {
                    bail!("line {}: only ASCII PLY is read, not {f}", ln + 1)
                }
                ["element", name, n] => {
                    let n: usize = n
                        .parse()
                        .with_context(|| format!("line {}: bad element count", ln + 1))?;
                    element = name.to_string();
                    match *name {
                        "vertex" => n_vertex = n,
                        "face" => n_face = n,
                        _ => bail!("line {}: unexpected element {name}", ln + 1),
                    }
                }
                ["property", "list", ..] => {}
                ["property", _, name] if element == "vertex" => props.push(name.to_string()),
                ["end_header"] => {
                    header_end = true;
                    break;
                }
                _ => {}
            }
        }
        if !header_end {
            bail!("no end_header");
        }
        let col = |n: &str| props.iter().position(|p| p == n);
        let (Some(ix), Some(iy), Some(iz)) = (col("x"), col("y"), col("z")) else {
            bail!("vertices need properties x, y and z");
        };
        let uv = col("u").zip(col("v"));
        let mut vertices = Vec::with_capacity(n_vertex);
        let mut material = uv.map(|_| Vec::with_capacity(n_vertex));
        for _ in 0..n_vertex {
            let (ln, l) = lines.next().context("fewer vertex lines than declared")?;
            let v: Vec<f64> = l
                .split_whitespace()
                .map(str::parse)
                .collect::<std::result::Result<_, _>>()
                .with_context(|| format!("line {}: bad number", ln + 1))?;
            if v.len() != props.len() || v.iter().any(|x| !x.is_finite()) {
                bail!(
                    "line {}: a vertex needs {} finite numbers",
                    ln + 1,
                    props.len()
                );
            }
            vertices.push(V3::new(v[ix], v[iy], v[iz]));
            if let (Some(m), Some((iu, iv))) = (material.as_mut(), uv) {
                m.push([v[iu], v[iv]]);
            }
        }
        let mut triangles = Vec::with_capacity(2 * n_face);
        for _ in 0..n_face {
            let (ln, l) = lines.next().context("fewer face lines than declared")?;
            let v: Vec<usize> = l
                .split_whitespace()
                .map(str::parse)
                .collect::<std::result::Result<_, _>>()
                .with_context(|| format!("line {}: bad face", ln + 1))?;
            if v.is_empty() || v[0] + 1 != v.len() || v[0] < 3 {
                bail!("line {}: a face is a count ≥ 3 then its indices", ln + 1);
            }
            if let Some(bad) = v[1..].iter().find(|&&i| i >= n_vertex) {
                bail!("line {}: face uses vertex {bad} of {n_vertex}", ln + 1);
            }
            for k in 2..v[0] {
                triangles.push([v[1], v[k], v[k + 1]]);
            }
        }
        Ok(Shape {
            vertices,
            material,
            triangles,
        })
    }

    /// Writes the shape as ASCII PLY (x y z, and u v when it has them).
    pub fn write_ply(&self, path: &Path, comment: &str) -> Result<()> {
        crate::io::write_atomic(path, |w| {
            writeln!(w, "ply\nformat ascii 1.0\ncomment {comment}")?;
            writeln!(
                w,
                "element vertex {}\nproperty double x\nproperty double y\nproperty double z",
                self.vertices.len()
            )?;
            if self.material.is_some() {
                writeln!(w, "property double u\nproperty double v")?;
            }
            writeln!(
                w,
                "element face {}\nproperty list uchar int vertex_indices\nend_header",
                self.triangles.len()
            )?;
            for (k, p) in self.vertices.iter().enumerate() {
                match &self.material {
                    Some(m) => writeln!(w, "{} {} {} {} {}", p.x, p.y, p.z, m[k][0], m[k][1])?,
                    None => writeln!(w, "{} {} {}", p.x, p.y, p.z)?,
                }
            }
            for t in &self.triangles {
                writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
            }
            Ok(())
        })
    }

    /// A simulated cloth as it is now, with its material coordinates.
    pub fn from_cloth(c: &crate::cloth::Cloth) -> Shape {
        Shape {
            vertices: c.positions().to_vec(),
            material: Some(c.material.clone()),
            triangles: c.triangles.clone(),
        }
    }

    /// The shape as a [`Surface`] for pictures.
    pub fn surface(&self) -> Surface {
        Surface {
            vertices: self.vertices.iter().map(|p| [p.x, p.y, p.z]).collect(),
            triangles: self.triangles.clone(),
        }
    }

    /// A shape translated by `d`.
    pub fn translated(&self, d: V3) -> Shape {
        let mut s = self.clone();
        for p in &mut s.vertices {
            *p += d;
        }
        s
    }
}
