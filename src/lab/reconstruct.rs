//! The 3D shape of a real drape from photos (thesis §6.3): marks on the
//! cloth seen in several calibrated photos, a generic model of the cloth
//! (a simulated drape), and the interleaved calibration–reconstruction loop:
//!
//! 1. a first pose of every camera from the model's marks ([`posit`], then
//!    least squares on the reprojection error, [`refine_pose`]) (§6.3.1);
//! 2. every mark seen in two or more views triangulated ([`triangulate`])
//!    and moved there on the model (§6.3.2);
//! 3. every camera posed again on the moved marks; 2–3 repeated until the
//!    root-mean-square reprojection error stops falling;
//! 4. the whole model deformed through the reconstructed marks by radial
//!    basis functions (§6.3.3, [`Rbf`]).
//!
//! Marks are points of the cloth, addressed by material coordinates (u, v)
//! or by grid (i, j) at a spacing, or known points of the scene (a table's
//! corners) with given coordinates. Known points never move: they fix the
//! gauge (frame and scale) of the reconstruction. Without them the frame is
//! the model's only approximately: the reconstructed shape is then right up
//! to a rigid motion and scale close to the identity.

use super::compare::{MaterialLocator, Shape, MATERIAL_TOLERANCE};
use super::posit::{
    flatness, posit, project, refine_pose, rms, triangulate, Intrinsics, Pose, COLLINEAR,
};
use anyhow::{bail, Context, Result};
use nalgebra::{DMatrix, Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;
use std::path::{Path, PathBuf};

type V3 = Vector3<f64>;

/// A VIEWS.yaml file: the camera's intrinsics, the known points, and per
/// view the pixels of the marks seen in it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewsFile {
    /// Eq. 6.1's intrinsic parameters, the same for every view.
    pub intrinsics: Intrinsics,
    /// Image width and height, pixels (for the pictures when no photo is
    /// given; default [2 cu, 2 cv]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub image_size: Option<[usize; 2]>,
    /// Spacing (m) of the grid that `grid: [i, j]` marks count on: mark
    /// (i, j) is at material point (i s, j s). Default: the model's grid
    /// spacing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid_spacing: Option<f64>,
    /// Points of the scene whose coordinates (m) are known.
    #[serde(default)]
    pub known_points: Vec<KnownPoint>,
    pub views: Vec<ViewSpec>,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KnownPoint {
    pub name: String,
    pub position: [f64; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ViewSpec {
    pub name: String,
    /// The photo (PNG), relative to the VIEWS file.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo: Option<PathBuf>,
    pub marks: Vec<MarkSpec>,
}

/// A mark seen in a view: which one (exactly one of `grid`, `uv`, `point`)
/// and where, pixels (x right, y down).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MarkSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grid: Option<[i64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uv: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub point: Option<String>,
    pub pixel: [f64; 2],
}

impl MarkSpec {
    /// How the mark is named in messages and reports.
    pub fn label(&self) -> String {
        match (&self.grid, &self.uv, &self.point) {
            (Some(g), None, None) => format!("grid [{}, {}]", g[0], g[1]),
            (None, Some(m), None) => format!("uv [{}, {}]", m[0], m[1]),
            (None, None, Some(p)) => format!("point {p}"),
            _ => "(no single id)".into(),
        }
    }
}

impl ViewsFile {
    /// Reads and parses a VIEWS.yaml; errors name the file.
    pub fn load(path: &Path) -> Result<ViewsFile> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read views file {}", path.display()))?;
        crate::io::check_yaml_shape(&text)
            .with_context(|| format!("views file {}", path.display()))?;
        serde_yaml::from_str(&text)
            .with_context(|| format!("views file {}: invalid YAML or field", path.display()))
    }

    /// The file as compact YAML (one line per mark).
    pub fn to_yaml(&self) -> String {
        use std::fmt::Write;
        let k = &self.intrinsics;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "intrinsics: {{ focal: {}, ku: {}, kv: {}, cu: {}, cv: {}, skew: {} }}",
            k.focal, k.ku, k.kv, k.cu, k.cv, k.skew
        );
        if let Some(sz) = self.image_size {
            let _ = writeln!(s, "image_size: [{}, {}]", sz[0], sz[1]);
        }
        if let Some(g) = self.grid_spacing {
            let _ = writeln!(s, "grid_spacing: {g}");
        }
        if !self.known_points.is_empty() {
            let _ = writeln!(s, "known_points:");
            for p in &self.known_points {
                let _ = writeln!(
                    s,
                    "  - {{ name: {}, position: [{}, {}, {}] }}",
                    p.name, p.position[0], p.position[1], p.position[2]
                );
            }
        }
        let _ = writeln!(s, "views:");
        for v in &self.views {
            let _ = writeln!(s, "  - name: {}", v.name);
            if let Some(p) = &v.photo {
                let _ = writeln!(s, "    photo: {}", p.display());
            }
            let _ = writeln!(s, "    marks:");
            for m in &v.marks {
                let id = match (&m.grid, &m.uv, &m.point) {
                    (Some(g), _, _) => format!("grid: [{}, {}]", g[0], g[1]),
                    (_, Some(u), _) => format!("uv: [{}, {}]", u[0], u[1]),
                    (_, _, Some(p)) => format!("point: {p}"),
                    _ => String::new(),
                };
                let _ = writeln!(
                    s,
                    "      - {{ {id}, pixel: [{:.3}, {:.3}] }}",
                    m.pixel[0], m.pixel[1]
                );
            }
        }
        s
    }
}

/// A mark: a point of the cloth or a known point of the scene.
#[derive(Debug, Clone, PartialEq)]
pub enum MarkKind {
    /// Material coordinates on the cloth, m.
    Cloth { uv: [f64; 2] },
    /// A known point, fixed.
    Known { position: V3 },
}

#[derive(Debug, Clone, PartialEq)]
pub struct Mark {
    pub label: String,
    pub kind: MarkKind,
}

/// One view: its name, photo, and the marks seen (index into the marks, pixel).
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    pub name: String,
    pub photo: Option<PathBuf>,
    pub seen: Vec<(usize, [f64; 2])>,
}

/// The checked input of the reconstruction.
#[derive(Debug, Clone)]
pub struct Problem {
    pub intrinsics: Intrinsics,
    pub image_size: [usize; 2],
    pub marks: Vec<Mark>,
    pub views: Vec<View>,
    /// The model's position of every mark.
    pub model_marks: Vec<V3>,
}

/// The grid spacing of a shape with material coordinates: the smallest
/// nonzero |Δu| and |Δv| along its triangles' edges.
pub fn material_spacing(shape: &Shape) -> Option<[f64; 2]> {
    let m = shape.material.as_ref()?;
    let mut s = [f64::INFINITY; 2];
    for t in &shape.triangles {
        for e in 0..3 {
            let (a, b) = (m[t[e]], m[t[(e + 1) % 3]]);
            for d in 0..2 {
                let x = (a[d] - b[d]).abs();
                if x > 1e-9 {
                    s[d] = s[d].min(x);
                }
            }
        }
    }
    (s[0].is_finite() && s[1].is_finite()).then_some(s)
}

impl Problem {
    /// Checks a views file against the model: every view has at least four
    /// marks that are not collinear, every mark names one existing point
    /// (a material point on the model's cloth or a known point) once, every
    /// pixel is finite. Errors name the view and the mark. `base` is the
    /// folder photo paths are relative to.
    pub fn new(file: &ViewsFile, model: &Shape, base: &Path) -> Result<Problem> {
        let k = file.intrinsics;
        k.check()?;
        if file.views.is_empty() {
            bail!("no views");
        }
        let loc = MaterialLocator::new(model)
            .context("the model has no material coordinates (u, v) or no faces")?;
        let spacing = match file.grid_spacing {
            Some(g) if !(g.is_finite() && g > 0.0) => bail!("grid_spacing = {g} must be > 0"),
            Some(g) => [g, g],
            None => material_spacing(model).context("the model's grid spacing is unknown")?,
        };
        let mut known: HashMap<&str, V3> = HashMap::new();
        for p in &file.known_points {
            if !p.position.iter().all(|c| c.is_finite()) {
                bail!(
                    "known point {}: position {:?} is not finite",
                    p.name,
                    p.position
                );
            }
            if known.insert(&p.name, V3::from(p.position)).is_some() {
                bail!("known point {} is given twice", p.name);
            }
        }
        let (mut ulo, mut uhi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for m in model.material.iter().flatten() {
            for d in 0..2 {
                ulo[d] = ulo[d].min(m[d]);
                uhi[d] = uhi[d].max(m[d]);
            }
        }
        let mut marks: Vec<Mark> = Vec::new();
        let mut model_marks: Vec<V3> = Vec::new();
        let mut index: HashMap<String, usize> = HashMap::new();
        let mut views = Vec::new();
        let mut names = std::collections::HashSet::new();
        for v in &file.views {
            if !names.insert(v.name.clone()) {
                bail!("view '{}' is given twice", v.name);
            }
            if v.marks.len() < 4 {
                bail!(
                    "view '{}': {} marks, a camera's pose needs at least 4",
                    v.name,
                    v.marks.len()
                );
            }
            let mut seen = Vec::new();
            for (n, m) in v.marks.iter().enumerate() {
                let what = || format!("view '{}', mark {} ({})", v.name, n + 1, m.label());
                if !m.pixel.iter().all(|c| c.is_finite()) {
                    bail!("{}: pixel {:?} is not finite", what(), m.pixel);
                }
                let (key, kind, pos) = match (&m.grid, &m.uv, &m.point) {
                    (Some(_), None, None) | (None, Some(_), None) => {
                        let uv = match (m.grid, m.uv) {
                            (Some(g), _) => [g[0] as f64 * spacing[0], g[1] as f64 * spacing[1]],
                            (_, Some(u)) => u,
                            _ => unreachable!(),
                        };
                        if !uv.iter().all(|c| c.is_finite()) {
                            bail!("{}: material point {uv:?} is not finite", what());
                        }
                        let Some(p) = loc.at(uv, MATERIAL_TOLERANCE) else {
                            bail!(
                                "{}: no such mark: material point ({}, {}) m lies outside the \
                                 model's cloth (u in [{}, {}], v in [{}, {}] m)",
                                what(),
                                uv[0],
                                uv[1],
                                ulo[0],
                                uhi[0],
                                ulo[1],
                                uhi[1]
                            );
                        };
                        let key = format!(
                            "uv {} {}",
                            (uv[0] * 1e6).round() as i64,
                            (uv[1] * 1e6).round() as i64
                        );
                        (key, MarkKind::Cloth { uv }, p)
                    }
                    (None, None, Some(name)) => {
                        let Some(p) = known.get(name.as_str()) else {
                            let mut have: Vec<&str> = known.keys().copied().collect();
                            have.sort();
                            bail!(
                                "{}: no such mark: no known point named '{name}' (known points: {})",
                                what(),
                                if have.is_empty() { "none".into() } else { have.join(", ") }
                            );
                        };
                        (
                            format!("point {name}"),
                            MarkKind::Known { position: *p },
                            *p,
                        )
                    }
                    _ => bail!("{}: give exactly one of grid, uv or point", what()),
                };
                let id = *index.entry(key).or_insert_with(|| {
                    marks.push(Mark {
                        label: m.label(),
                        kind,
                    });
                    model_marks.push(pos);
                    marks.len() - 1
                });
                if seen.iter().any(|(i, _)| *i == id) {
                    bail!("{}: the mark is given twice in this view", what());
                }
                seen.push((id, m.pixel));
            }
            let pts: Vec<V3> = seen.iter().map(|(i, _)| model_marks[*i]).collect();
            let line = flatness(&pts).0;
            let pix: Vec<V3> = seen.iter().map(|(_, p)| V3::new(p[0], p[1], 0.0)).collect();
            let pline = flatness(&pix).0;
            if line < COLLINEAR || pline < COLLINEAR {
                let labels: Vec<&str> = seen
                    .iter()
                    .take(6)
                    .map(|(i, _)| marks[*i].label.as_str())
                    .collect();
                bail!(
                    "view '{}': its {} marks ({}{}) are collinear {}: the camera's pose is undetermined",
                    v.name,
                    seen.len(),
                    labels.join(", "),
                    if seen.len() > 6 { ", …" } else { "" },
                    if line < COLLINEAR { "on the cloth" } else { "in the image" }
                );
            }
            views.push(View {
                name: v.name.clone(),
                photo: v.photo.as_ref().map(|p| base.join(p)),
                seen,
            });
        }
        let image_size = file.image_size.unwrap_or([
            (2.0 * k.cu).round().max(1.0) as usize,
            (2.0 * k.cv).round().max(1.0) as usize,
        ]);
        Ok(Problem {
            intrinsics: k,
            image_size,
            marks,
            views,
            model_marks,
        })
    }
}

/// Where the radial basis functions of the deformation (§6.3.3) live.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RbfSpace {
    /// The model's 3D space: the displacement at a vertex is interpolated
    /// from the marks near it in space.
    World,
    /// The flat cloth's material coordinates (u, v): from the marks near it
    /// on the cloth, whatever folds bring near it in space.
    Material,
}

/// The kernel φ(r) of the radial basis functions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum RbfKernel {
    /// φ(r) = r: the biharmonic kernel in 3D.
    Linear,
    /// φ(r) = r³: the triharmonic kernel in 3D.
    Cubic,
    /// φ(r) = r² ln r: the thin-plate spline, biharmonic in 2D.
    ThinPlate,
}

impl RbfKernel {
    pub fn phi(self, r: f64) -> f64 {
        match self {
            RbfKernel::Linear => r,
            RbfKernel::Cubic => r * r * r,
            RbfKernel::ThinPlate => {
                if r > 0.0 {
                    r * r * r.ln()
                } else {
                    0.0
                }
            }
        }
    }
}

/// How the model is deformed through the reconstructed marks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Deformation {
    pub space: RbfSpace,
    pub kernel: RbfKernel,
}

/// By default the displacement is a function on the flat cloth interpolated
/// by the thin-plate spline: of all the functions of (u, v) through the marks,
/// the one of least bending energy (Duchon 1977), and marks that a fold
/// brings close in space but that lie far apart on the cloth do not pull on
/// each other.
impl Default for Deformation {
    fn default() -> Self {
        Deformation {
            space: RbfSpace::Material,
            kernel: RbfKernel::ThinPlate,
        }
    }
}

/// The model deformed through marks given as (position on the model,
/// material point, displacement to the reconstructed position).
pub fn deform(model: &Shape, marks: &[(V3, [f64; 2], V3)], how: &Deformation) -> Result<Shape> {
    if marks.len() < 4 {
        bail!(
            "{} cloth marks were triangulated (seen in two or more views): the model's \
             deformation needs at least 4",
            marks.len()
        );
    }
    let at = |x: &V3, uv: [f64; 2]| match how.space {
        RbfSpace::World => *x,
        RbfSpace::Material => V3::new(uv[0], uv[1], 0.0),
    };
    let centres: Vec<V3> = marks.iter().map(|(x, uv, _)| at(x, *uv)).collect();
    let values: Vec<V3> = marks.iter().map(|m| m.2).collect();
    let rbf = Rbf::fit_with(&centres, &values, how.kernel)?;
    let mut s = model.clone();
    if how.space == RbfSpace::Material && model.material.is_none() {
        bail!(
            "the model has no material coordinates (u v per vertex) for a deformation in \
             material space: give a PLY with u v (as drape writes final.ply), or use \
             --rbf-space world"
        );
    }
    for (k, x) in s.vertices.iter_mut().enumerate() {
        let uv = model.material.as_ref().map(|m| m[k]).unwrap_or([0.0; 2]);
        *x += rbf.at(&at(x, uv));
    }
    Ok(s)
}

/// How the loop stops.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LoopSettings {
    /// At most this many calibration–reconstruction rounds.
    pub max_rounds: usize,
    /// A round that lowers the RMS reprojection error by less than this
    /// fraction ends the loop.
    pub min_fall: f64,
    pub deformation: Deformation,
}

impl Default for LoopSettings {
    fn default() -> Self {
        LoopSettings {
            max_rounds: 20_000,
            min_fall: 1e-9,
            deformation: Deformation::default(),
        }
    }
}

/// Reprojection errors of one view.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewFit {
    /// RMS and largest pixel error over the marks seen.
    pub rms: f64,
    pub max: f64,
    /// Per mark seen (same order as [`View::seen`]): reprojected pixel and error.
    pub reprojected: Vec<[f64; 2]>,
    pub errors: Vec<f64>,
}

/// What the reconstruction found.
#[derive(Debug, Clone)]
pub struct Reconstruction {
    pub poses: Vec<Pose>,
    /// Reconstructed position of every mark (known points: their own;
    /// marks seen in one view only: the model's).
    pub marks: Vec<V3>,
    /// Was the mark triangulated (seen in two or more views)?
    pub triangulated: Vec<bool>,
    /// RMS reprojection error (px) after the first poses and after every round.
    pub history: Vec<f64>,
    pub fits: Vec<ViewFit>,
    /// RMS pixel error per mark over the views that see it.
    pub mark_rms: Vec<f64>,
    /// The model deformed through the reconstructed marks.
    pub shape: Shape,
}

fn view_fit(p: &Problem, v: &View, pose: &Pose, marks: &[V3]) -> ViewFit {
    let mut reprojected = Vec::new();
    let mut errors = Vec::new();
    for (i, q) in &v.seen {
        let r = project(&p.intrinsics, pose, &marks[*i]).unwrap_or([f64::NAN; 2]);
        let e = ((r[0] - q[0]).powi(2) + (r[1] - q[1]).powi(2)).sqrt();
        reprojected.push(r);
        errors.push(if e.is_finite() { e } else { f64::INFINITY });
    }
    ViewFit {
        rms: rms(&errors),
        max: errors.iter().cloned().fold(0.0, f64::max),
        reprojected,
        errors,
    }
}

/// RMS pixel error over all observations of marks that take part (known or
/// triangulated).
fn total_rms(p: &Problem, poses: &[Pose], marks: &[V3], used: &[bool]) -> f64 {
    let mut e = Vec::new();
    for (v, pose) in p.views.iter().zip(poses) {
        for (i, q) in &v.seen {
            if used[*i] {
                let r = project(&p.intrinsics, pose, &marks[*i]).unwrap_or([f64::INFINITY; 2]);
                e.push(((r[0] - q[0]).powi(2) + (r[1] - q[1]).powi(2)).sqrt());
            }
        }
    }
    rms(&e)
}

/// Poses a view on the marks that take part (all of its marks when fewer
/// than four do), from `start` or, without one, from POSIT.
fn pose_view(
    p: &Problem,
    v: &View,
    marks: &[V3],
    used: &[bool],
    start: Option<Pose>,
) -> Result<Pose> {
    let mut obj = Vec::new();
    let mut pix = Vec::new();
    for (i, q) in &v.seen {
        if used[*i] {
            obj.push(marks[*i]);
            pix.push(*q);
        }
    }
    if obj.len() < 4 {
        obj = v.seen.iter().map(|(i, _)| marks[*i]).collect();
        pix = v.seen.iter().map(|(_, q)| *q).collect();
    }
    let start = match start {
        Some(s) => s,
        None => {
            let norm: Vec<[f64; 2]> = pix.iter().map(|q| p.intrinsics.normalise(*q)).collect();
            posit(&obj, &norm).with_context(|| format!("view '{}': first pose", v.name))?
        }
    };
    Ok(refine_pose(&p.intrinsics, start, &obj, &pix))
}

/// Runs the calibration–reconstruction loop of §6.3.1–6.3.2 and deforms
/// `model` through the reconstructed marks (§6.3.3). `progress` hears the
/// round and its RMS error (px).
pub fn reconstruct(
    p: &Problem,
    model: &Shape,
    settings: &LoopSettings,
    progress: &mut dyn FnMut(usize, f64),
) -> Result<Reconstruction> {
    let n = p.marks.len();
    let known: Vec<bool> = p
        .marks
        .iter()
        .map(|m| matches!(m.kind, MarkKind::Known { .. }))
        .collect();
    let mut views_of: Vec<Vec<(usize, [f64; 2])>> = vec![Vec::new(); n];
    for (vi, v) in p.views.iter().enumerate() {
        for (i, q) in &v.seen {
            views_of[*i].push((vi, *q));
        }
    }
    // 1. first poses on the model's marks
    let mut marks = p.model_marks.clone();
    let all = vec![true; n];
    let mut poses = p
        .views
        .iter()
        .map(|v| pose_view(p, v, &marks, &all, None))
        .collect::<Result<Vec<_>>>()?;
    let seen_twice: Vec<bool> = (0..n).map(|i| known[i] || views_of[i].len() >= 2).collect();
    let mut history = vec![total_rms(p, &poses, &marks, &seen_twice)];
    progress(0, history[0]);
    let mut triangulated = vec![false; n];
    // 2–3. triangulate, pose again, until the error stops falling
    for round in 1..=settings.max_rounds {
        let mut new_marks = marks.clone();
        let mut new_tri = triangulated.clone();
        for i in 0..n {
            if known[i] || views_of[i].len() < 2 {
                continue;
            }
            let ps: Vec<Pose> = views_of[i].iter().map(|(v, _)| poses[*v]).collect();
            let qs: Vec<[f64; 2]> = views_of[i].iter().map(|(_, q)| *q).collect();
            if let Some(x) = triangulate(&p.intrinsics, &ps, &qs) {
                new_marks[i] = x;
                new_tri[i] = true;
            }
        }
        let new_used: Vec<bool> = (0..n).map(|i| known[i] || new_tri[i]).collect();
        let new_poses = p
            .views
            .iter()
            .zip(&poses)
            .map(|(v, s)| pose_view(p, v, &new_marks, &new_used, Some(*s)))
            .collect::<Result<Vec<_>>>()?;
        let e = total_rms(p, &new_poses, &new_marks, &new_used);
        let prev = *history.last().unwrap_or(&f64::INFINITY);
        // the first round changes which marks count; after it, keep a round only if it helps
        if round > 1 && (e.is_nan() || e >= prev) {
            break;
        }
        marks = new_marks;
        poses = new_poses;
        triangulated = new_tri;
        history.push(e);
        progress(round, e);
        if round > 1 && (prev - e <= settings.min_fall * prev || e < 1e-9) {
            break;
        }
    }
    let fits: Vec<ViewFit> = p
        .views
        .iter()
        .zip(&poses)
        .map(|(v, pose)| view_fit(p, v, pose, &marks))
        .collect();
    let mut per_mark: Vec<Vec<f64>> = vec![Vec::new(); n];
    for (v, f) in p.views.iter().zip(&fits) {
        for ((i, _), e) in v.seen.iter().zip(&f.errors) {
            per_mark[*i].push(*e);
        }
    }
    let mark_rms = per_mark.iter().map(|e| rms(e)).collect();
    // 4. the model through the reconstructed marks
    let tri: Vec<usize> = (0..n).filter(|&i| triangulated[i]).collect();
    let marks_on_model: Vec<(V3, [f64; 2], V3)> = tri
        .iter()
        .filter_map(|&i| match p.marks[i].kind {
            MarkKind::Cloth { uv } => Some((p.model_marks[i], uv, marks[i] - p.model_marks[i])),
            MarkKind::Known { .. } => None,
        })
        .collect();
    let shape = deform(model, &marks_on_model, &settings.deformation)?;
    Ok(Reconstruction {
        poses,
        marks,
        triangulated,
        history,
        fits,
        mark_rms,
        shape,
    })
}

/// Radial basis function interpolation of a 3D displacement field
/// (§6.3.3): d(x) = Σ w_k φ(|x − c_k|) + A x + b with a kernel φ
/// ([`RbfKernel`]: r, the 3D biharmonic, as in Carr et al. 2001,
/// "Reconstruction and representation of 3D objects with radial basis
/// functions", SIGGRAPH; r³; or the thin-plate r² ln r) and the linear
/// polynomial that makes it reproduce affine fields exactly; the weights
/// solve the dense system [Φ P; Pᵀ 0] [w; c] = [d; 0] (by SVD: centres on a
/// plane leave the polynomial's normal part free, and get its least-norm
/// value).
#[derive(Debug, Clone)]
pub struct Rbf {
    kernel: RbfKernel,
    centres: Vec<V3>,
    weights: Vec<V3>,
    linear: Matrix3<f64>,
    constant: V3,
}

impl Rbf {
    /// Interpolates `values` at `centres` with φ(r) = r.
    pub fn fit(centres: &[V3], values: &[V3]) -> Result<Rbf> {
        Rbf::fit_with(centres, values, RbfKernel::Linear)
    }

    /// As [`Rbf::fit`] with another kernel.
    pub fn fit_with(centres: &[V3], values: &[V3], kernel: RbfKernel) -> Result<Rbf> {
        let n = centres.len();
        let m = n + 4;
        let mut a = DMatrix::<f64>::zeros(m, m);
        // scale the polynomial columns like the kernel for conditioning
        let scale = centres
            .iter()
            .map(|c| (c - centres[0]).norm())
            .fold(0.0, f64::max)
            .max(1e-9);
        for i in 0..n {
            for j in 0..n {
                a[(i, j)] = kernel.phi((centres[i] - centres[j]).norm());
            }
            let row = [scale, centres[i].x, centres[i].y, centres[i].z];
            for (k, r) in row.iter().enumerate() {
                a[(i, n + k)] = *r;
                a[(n + k, i)] = *r;
            }
        }
        let mut b = DMatrix::<f64>::zeros(m, 3);
        for i in 0..n {
            for d in 0..3 {
                b[(i, d)] = values[i][d];
            }
        }
        let svd = a.svd(true, true);
        let x = svd
            .solve(&b, 1e-12 * scale)
            .map_err(|e| anyhow::anyhow!("RBF system: {e}"))?;
        if x.iter().any(|v| !v.is_finite()) {
            bail!("RBF system: no finite solution");
        }
        let weights = (0..n)
            .map(|i| V3::new(x[(i, 0)], x[(i, 1)], x[(i, 2)]))
            .collect();
        let constant = V3::new(x[(n, 0)], x[(n, 1)], x[(n, 2)]) * scale;
        let linear = Matrix3::from_fn(|r, c| x[(n + 1 + c, r)]);
        Ok(Rbf {
            kernel,
            centres: centres.to_vec(),
            weights,
            linear,
            constant,
        })
    }

    /// The interpolated displacement at `x`.
    pub fn at(&self, x: &V3) -> V3 {
        let mut d = self.linear * x + self.constant;
        for (c, w) in self.centres.iter().zip(&self.weights) {
            d += w * self.kernel.phi((x - c).norm());
        }
        d
    }
}

// ---------------------------------------------------------------------------
// Synthetic views: a drape seen by cameras of known pose, for the tests and
// the shipped example.

/// A small deterministic random generator (SplitMix64), so that synthetic
/// views are the same on every machine.
pub struct SplitMix(u64);

impl SplitMix {
    pub fn new(seed: u64) -> SplitMix {
        SplitMix(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
    }
}

/// `n` cameras on a ring around `target`, at distance `distance`, looking at
/// it from elevations alternating between `elevations[0]` and
/// `elevations[1]` (rad), starting at azimuth `azimuth0` (rad).
pub fn ring_cameras(
    target: V3,
    distance: f64,
    elevations: [f64; 2],
    azimuth0: f64,
    n: usize,
) -> Vec<Pose> {
    (0..n)
        .map(|k| {
            let az = azimuth0 + 2.0 * std::f64::consts::PI * k as f64 / n as f64;
            let el = elevations[k % 2];
            let eye =
                target + V3::new(el.cos() * az.cos(), el.cos() * az.sin(), el.sin()) * distance;
            Pose::looking_at(eye, target, V3::z())
        })
        .collect()
}

/// The rig of the shipped example and the tests: a 2400 × 1600 pixel camera
/// (18 mm lens, 6 µm pixels slightly taller than wide, a little skew) at ten
/// places 1 m from the table drape's middle, on a ring at 25° and 50°
/// above the horizontal in turn.
pub fn example_rig() -> (Intrinsics, [usize; 2], Vec<Pose>) {
    let k = Intrinsics {
        focal: 0.018,
        ku: 1.0 / 6.0e-6,
        kv: 1.0 / 5.95e-6,
        cu: 1203.5,
        cv: 796.0,
        skew: 40.0,
    };
    let target = V3::new(0.0, -0.05, 0.68);
    let cams = ring_cameras(
        target,
        1.0,
        [25f64.to_radians(), 50f64.to_radians()],
        0.3,
        10,
    );
    (k, [2400, 1600], cams)
}

/// The corners of an obstacle (its triangulation's vertices: a box's eight
/// corners) as known points named `{id}_{k}`, k from 1.
pub fn obstacle_corners(o: &crate::collision::Obstacle) -> Vec<KnownPoint> {
    crate::pictures::render::Surface::from_obstacle(o)
        .vertices
        .iter()
        .enumerate()
        .map(|(k, p)| KnownPoint {
            name: format!("{}_{}", o.id, k + 1),
            position: *p,
        })
        .collect()
}

/// What [`synthetic_views`] makes.
pub struct SyntheticSettings {
    pub intrinsics: Intrinsics,
    pub image_size: [usize; 2],
    /// Marks at material points (i s, j s), s = `mark_spacing`.
    pub mark_spacing: f64,
    /// Standard deviation of the Gaussian noise added to every pixel coordinate.
    pub noise_px: f64,
    /// Fraction of the marks hidden in each view (chosen at random).
    pub hidden: f64,
    pub seed: u64,
}

/// The views of `truth` (a shape with material coordinates) and of the
/// `known` points by cameras at `poses`: grid marks every `mark_spacing`
/// over the cloth, projected with the intrinsics, with noise and hidden
/// marks as asked; marks outside the image are left out.
pub fn synthetic_views(
    truth: &Shape,
    known: &[KnownPoint],
    poses: &[Pose],
    s: &SyntheticSettings,
) -> Result<ViewsFile> {
    let loc = MaterialLocator::new(truth).context("the true shape has no material coordinates")?;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for m in truth.material.iter().flatten() {
        for d in 0..2 {
            lo[d] = lo[d].min(m[d]);
            hi[d] = hi[d].max(m[d]);
        }
    }
    let h = s.mark_spacing;
    let mut points: Vec<(MarkSpec, V3)> = Vec::new();
    let (i0, i1) = ((lo[0] / h).ceil() as i64, (hi[0] / h + 1e-9).floor() as i64);
    let (j0, j1) = ((lo[1] / h).ceil() as i64, (hi[1] / h + 1e-9).floor() as i64);
    for j in j0..=j1 {
        for i in i0..=i1 {
            if let Some(x) = loc.at([i as f64 * h, j as f64 * h], MATERIAL_TOLERANCE) {
                let spec = MarkSpec {
                    grid: Some([i, j]),
                    uv: None,
                    point: None,
                    pixel: [0.0; 2],
                };
                points.push((spec, x));
            }
        }
    }
    for k in known {
        let spec = MarkSpec {
            grid: None,
            uv: None,
            point: Some(k.name.clone()),
            pixel: [0.0; 2],
        };
        points.push((spec, V3::from(k.position)));
    }
    let mut rng = SplitMix::new(s.seed);
    let mut views = Vec::new();
    for (vi, pose) in poses.iter().enumerate() {
        let mut order: Vec<usize> = (0..points.len()).collect();
        // Fisher–Yates, then hide the first fraction
        for k in (1..order.len()).rev() {
            let r = (rng.uniform() * (k + 1) as f64) as usize;
            order.swap(k, r.min(k));
        }
        let n_hide = (s.hidden * points.len() as f64).round() as usize;
        let mut hide = vec![false; points.len()];
        for &k in &order[..n_hide.min(points.len())] {
            hide[k] = true;
        }
        let mut marks = Vec::new();
        for (k, (spec, x)) in points.iter().enumerate() {
            let (nx, ny) = (rng.normal(), rng.normal());
            if hide[k] {
                continue;
            }
            let Some(q) = project(&s.intrinsics, pose, x) else {
                continue;
            };
            let q = [q[0] + s.noise_px * nx, q[1] + s.noise_px * ny];
            if q[0] < 0.0
                || q[1] < 0.0
                || q[0] > s.image_size[0] as f64
                || q[1] > s.image_size[1] as f64
            {
                continue;
            }
            let mut m = spec.clone();
            m.pixel = q;
            marks.push(m);
        }
        views.push(ViewSpec {
            name: format!("view{:02}", vi + 1),
            photo: None,
            marks,
        });
    }
    Ok(ViewsFile {
        intrinsics: s.intrinsics,
        image_size: Some(s.image_size),
        grid_spacing: Some(h),
        known_points: known.to_vec(),
        views,
    })
}

// ---------------------------------------------------------------------------
// Pictures

/// Reads a PNG photo (any colour type and bit depth) as an RGB image.
pub fn read_png(path: &Path) -> Result<crate::pictures::plot::Image> {
    let f = std::fs::File::open(path)
        .with_context(|| format!("cannot open photo {}", path.display()))?;
    let mut dec = png::Decoder::new(std::io::BufReader::new(f));
    dec.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = dec
        .read_info()
        .with_context(|| format!("photo {}: not a PNG file", path.display()))?;
    let mut buf = vec![0; reader.output_buffer_size().context("photo too large")?];
    let info = reader
        .next_frame(&mut buf)
        .with_context(|| format!("photo {}: bad PNG data", path.display()))?;
    let (w, h) = (info.width as usize, info.height as usize);
    let ch = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => {
            bail!("photo {}: indexed colours after expansion", path.display())
        }
    };
    let mut img = crate::pictures::plot::Image::new(w, h, crate::pictures::plot::WHITE);
    for y in 0..h {
        for x in 0..w {
            let o = y * info.line_size + x * ch;
            img.pixels[y * w + x] = if ch < 3 {
                [buf[o]; 3]
            } else {
                [buf[o], buf[o + 1], buf[o + 2]]
            };
        }
    }
    Ok(img)
}

/// The largest side of a view's picture, pixels (larger photos are shrunk).
pub const MAX_PICTURE_SIDE: usize = 1600;

/// A view's picture: the photo (or a blank of the image's size), the
/// reconstructed model's wireframe (green), every mark where it was seen
/// (white disc, black ring) and where the reconstruction puts it (blue
/// cross; red when the error exceeds 2 px), labelled with the view's RMS
/// error.
pub fn view_picture(
    p: &Problem,
    r: &Reconstruction,
    view: usize,
) -> Result<crate::pictures::plot::Image> {
    use crate::pictures::plot::{Image, BLACK, WHITE};
    let v = &p.views[view];
    let pose = &r.poses[view];
    let photo = match &v.photo {
        Some(path) => Some(read_png(path).with_context(|| format!("view '{}'", v.name))?),
        None => None,
    };
    let (w, h) = match &photo {
        Some(ph) => (ph.width, ph.height),
        None => (p.image_size[0], p.image_size[1]),
    };
    let s = (MAX_PICTURE_SIDE as f64 / w.max(h) as f64).min(1.0);
    let (pw, ph) = (
        ((w as f64) * s).round().max(1.0) as usize,
        ((h as f64) * s).round().max(1.0) as usize,
    );
    let mut img = Image::new(pw, ph, [246, 246, 242]);
    if let Some(photo) = &photo {
        for y in 0..ph {
            for x in 0..pw {
                let sx = (((x as f64 + 0.5) / s) as usize).min(photo.width - 1);
                let sy = (((y as f64 + 0.5) / s) as usize).min(photo.height - 1);
                img.pixels[y * pw + x] = photo.get(sx, sy);
            }
        }
    }
    let to_px = |q: [f64; 2]| (q[0] * s, q[1] * s);
    // wireframe: each edge once
    let mut edges = std::collections::HashSet::new();
    for t in &r.shape.triangles {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            edges.insert((a.min(b), a.max(b)));
        }
    }
    let proj: Vec<Option<[f64; 2]>> = r
        .shape
        .vertices
        .iter()
        .map(|x| project(&p.intrinsics, pose, x))
        .collect();
    for (a, b) in edges {
        if let (Some(qa), Some(qb)) = (proj[a], proj[b]) {
            img.line(to_px(qa), to_px(qb), [0, 150, 60], 1);
        }
    }
    let fit = &r.fits[view];
    for (_, q) in &v.seen {
        let (x, y) = to_px(*q);
        img.disc(x, y, 5.0, WHITE);
        img.circle(x, y, 5.0, BLACK, 1);
    }
    for (k, (_, q)) in v.seen.iter().enumerate() {
        let rp = fit.reprojected[k];
        if !rp.iter().all(|c| c.is_finite()) {
            continue;
        }
        let c = if fit.errors[k] > 2.0 {
            [213, 30, 0]
        } else {
            [0, 80, 200]
        };
        let (x, y) = to_px(rp);
        img.line((x - 4.0, y), (x + 4.0, y), c, 1);
        img.line((x, y - 4.0), (x, y + 4.0), c, 1);
        if fit.errors[k] > 2.0 {
            img.line(to_px(*q), (x, y), c, 1);
        }
    }
    let label = format!(
        "{}: {} marks, reprojection error rms {:.2} px, largest {:.2} px",
        v.name,
        v.seen.len(),
        fit.rms,
        fit.max
    );
    img.fill_rect(0, 0, pw as i64, 24, WHITE);
    img.text(8, 8, &label, 1, BLACK);
    Ok(img)
}
