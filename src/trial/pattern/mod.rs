//! Garment files (`*.garment.yaml`): a garment from a GarmentCode pattern
//! and/or panels written by hand, with what GarmentCode lacks — the fabric,
//! each panel's grain and the seams' stiffness. Lengths in metres, angles in
//! degrees. See `docs/garments.md`.

pub mod garmentcode;

use crate::garment::{PanelCut, SeamSpec};
use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Seam stiffness when the file gives none, N/m per m of seam: two layers of
/// a fabric of tensile stiffness ~5 kN/m (wool tropical near 4 % strain)
/// over a 1 cm seam allowance, 2 × 5000 / 0.01 = 1e6. A seam then opens
/// 0.2 mm under the 200 N/m of a garment worn 2–3 % tight, and 2 µm under
/// the 2 N/m of a skirt's weight.
pub const DEFAULT_SEAM_STIFFNESS: f64 = 1.0e6;
/// Seam damping time when the file gives none, s.
pub const DEFAULT_SEAM_DAMPING: f64 = 0.02;

/// A hand-written panel, or overrides for a GarmentCode panel of that name.
#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PanelFile {
    /// Outline vertices, m (panel coordinates); a new panel's edges join
    /// consecutive vertices.
    #[serde(default)]
    pub vertices: Option<Vec<[f64; 2]>>,
    /// Placement: translation (m) and rotation (roll, pitch, yaw in degrees,
    /// `R = Rz(yaw) Ry(pitch) Rx(roll)`) of the panel plane in the world.
    #[serde(default)]
    pub translation: Option<[f64; 3]>,
    #[serde(default)]
    pub rotation_deg: Option<[f64; 3]>,
    /// Warp direction, degrees from the panel's x axis (90: the panel's
    /// vertical, the usual grainline).
    #[serde(default)]
    pub grain_deg: Option<f64>,
    /// Fabric file of this panel, relative to the garment file (default:
    /// the garment's).
    #[serde(default)]
    pub fabric: Option<PathBuf>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SeamFile {
    /// (panel name, edge index).
    pub a: (String, usize),
    pub b: (String, usize),
    #[serde(default)]
    pub stiffness: Option<f64>,
}

#[derive(Debug, Clone, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct GarmentFile {
    #[serde(default)]
    pub name: Option<String>,
    /// A GarmentCode specification (JSON), relative to this file.
    #[serde(default)]
    pub garmentcode: Option<PathBuf>,
    /// Added to GarmentCode's placements after the frame change, m.
    #[serde(default)]
    pub offset: Option<[f64; 3]>,
    /// Fabric file, relative to this file.
    pub fabric: PathBuf,
    /// Default warp direction of every panel, degrees from its x axis.
    #[serde(default)]
    pub grain_deg: Option<f64>,
    #[serde(default)]
    pub panels: BTreeMap<String, PanelFile>,
    /// Seams besides GarmentCode's stitches.
    #[serde(default)]
    pub seams: Vec<SeamFile>,
    /// N/m per m of seam (default [`DEFAULT_SEAM_STIFFNESS`]).
    #[serde(default)]
    pub seam_stiffness: Option<f64>,
    /// s (default [`DEFAULT_SEAM_DAMPING`]).
    #[serde(default)]
    pub seam_damping: Option<f64>,
    /// The bending hinges of every panel: `skewed` (default) or
    /// `mirror_symmetric` (see [`HingeLayout`]).
    #[serde(default)]
    pub hinges: HingesFile,
    /// How every panel's grid meets its outline: `on_outline` (default:
    /// border nodes moved onto the outline; a panel with an edge too short
    /// to hold one is cut conforming) or `conforming` (every corner a
    /// vertex, nothing across the outline).
    #[serde(default)]
    pub border: BorderFile,
}

/// `border:` of a garment file ([`Border`]).
#[derive(Debug, Clone, Copy, Deserialize, Serialize, Default, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum BorderFile {
    #[default]
    OnOutline,
    Conforming,
}

impl BorderFile {
    pub fn border(self) -> crate::cloth::Border {
        match self {
            BorderFile::Conforming => crate::cloth::Border::Conforming,
            BorderFile::OnOutline => crate::cloth::Border::OnOutline,
        }
    }
}

pub use crate::scene::HingesFile;

/// A garment as read: its panels cut in the world, its seams, its fabric.
#[derive(Debug, Clone)]
pub struct GarmentDef {
    pub name: String,
    pub cuts: Vec<PanelCut>,
    pub seams: Vec<SeamSpec>,
    /// Seam names "panel:edge ↔ panel:edge" for reports.
    pub seam_names: Vec<String>,
    /// The fabric files: the garment's, then the others its panels name.
    pub fabrics: Vec<PathBuf>,
    /// Each cut's fabric, an index into `fabrics`.
    pub fabric_of: Vec<u16>,
    /// Where each cut came from, for error messages.
    pub source: PathBuf,
}

/// Largest plausible garment panel side, m: a full-circle maxi skirt for a
/// tall wearer is about 3.5 m across; a pattern in mm or cm read as metres
/// is far larger.
pub const MAX_PANEL_SIZE: f64 = 8.0;
/// Smallest plausible panel side, m.
pub const MIN_PANEL_SIZE: f64 = 0.01;
/// Stitched edges whose lengths differ by more than this factor are refused
/// (gathers of up to 2:1 are fine).
pub const MAX_SEAM_RATIO: f64 = 2.5;

impl GarmentDef {
    pub fn load(path: &Path) -> Result<GarmentDef> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read garment file {}", path.display()))?;
        crate::io::check_yaml_shape(&text)
            .with_context(|| format!("garment file {}", path.display()))?;
        let file: GarmentFile = serde_yaml::from_str(&text)
            .with_context(|| format!("garment file {}: invalid YAML or field", path.display()))?;
        GarmentDef::from_file(file, path)
            .with_context(|| format!("garment file {}", path.display()))
    }

    /// The panels of the file's GarmentCode pattern (if any), and its
    /// stitches as (panel, edge, panel, edge).
    fn garmentcode_cuts(
        file: &GarmentFile,
        dir: &Path,
    ) -> Result<(Vec<PanelCut>, Vec<PendingSeam>)> {
        let default_grain = file.grain_deg.unwrap_or(90.0);
        let hinges = file.hinges.layout();
        let border = file.border.border();
        let mut cuts: Vec<PanelCut> = Vec::new();
        let mut pending: Vec<PendingSeam> = Vec::new();
        if let Some(gc) = &file.garmentcode {
            let gcp = dir.join(gc);
            let pat = garmentcode::load(&gcp)?;
            let offset = Vector3::from(file.offset.unwrap_or([0.0; 3]));
            for p in &pat.panels {
                let g = file
                    .panels
                    .get(&p.name)
                    .and_then(|o| o.grain_deg)
                    .unwrap_or(default_grain);
                cuts.push(PanelCut {
                    hinges,
                    border,
                    name: p.name.clone(),
                    edges: p.edges.clone(),
                    grain: grain(g),
                    placement: p.placement(offset),
                });
            }
            for s in &pat.stitches {
                pending.push((s.a.0.clone(), s.a.1, s.b.0.clone(), s.b.1));
            }
        }
        Ok((cuts, pending))
    }

    /// Adds the panels the file gives by their vertices (a GarmentCode
    /// panel named here takes only its grain and fabric).
    fn vertex_cuts(file: &GarmentFile, cuts: &mut Vec<PanelCut>) -> Result<()> {
        let default_grain = file.grain_deg.unwrap_or(90.0);
        let hinges = file.hinges.layout();
        let border = file.border.border();
        for (name, pf) in &file.panels {
            if cuts.iter().any(|c| &c.name == name) {
                if pf.vertices.is_some() || pf.translation.is_some() || pf.rotation_deg.is_some() {
                    bail!(
                        "panels.{name}: a GarmentCode panel takes only grain_deg and fabric here"
                    );
                }
                continue;
            }
            let Some(v) = &pf.vertices else {
                bail!(
                    "panels.{name}: no such panel in the GarmentCode pattern, and no vertices \
                     for a new one"
                );
            };
            if v.len() < 3 {
                bail!("panels.{name}.vertices: a panel needs at least 3 vertices");
            }
            let edges = (0..v.len())
                .map(|k| vec![v[k], v[(k + 1) % v.len()]])
                .collect();
            let t = pf.translation.unwrap_or([0.0; 3]);
            let r = pf.rotation_deg.unwrap_or([0.0; 3]);
            if t.iter()
                .chain(r.iter())
                .chain(v.iter().flatten())
                .any(|c| !c.is_finite())
            {
                bail!("panels.{name}: vertices, translation and rotation must be finite");
            }
            cuts.push(PanelCut {
                hinges,
                border,
                name: name.clone(),
                edges,
                grain: grain(pf.grain_deg.unwrap_or(default_grain)),
                placement: Isometry3::from_parts(
                    Translation3::new(t[0], t[1], t[2]),
                    UnitQuaternion::from_euler_angles(
                        r[0].to_radians(),
                        r[1].to_radians(),
                        r[2].to_radians(),
                    ),
                ),
            });
        }
        Ok(())
    }

    /// Each panel's fabric: the garment's unless the panel names its own;
    /// the fabric files and each panel's index into them.
    fn panel_fabrics(
        file: &GarmentFile,
        dir: &Path,
        cuts: &[PanelCut],
    ) -> (Vec<PathBuf>, Vec<u16>) {
        let mut fabrics: Vec<PathBuf> = vec![dir.join(&file.fabric)];
        let mut fabric_of = Vec::with_capacity(cuts.len());
        for c in cuts {
            let k = match file.panels.get(&c.name).and_then(|p| p.fabric.as_ref()) {
                None => 0,
                Some(f) => {
                    let f = dir.join(f);
                    match fabrics.iter().position(|g| *g == f) {
                        Some(k) => k,
                        None => {
                            fabrics.push(f);
                            fabrics.len() - 1
                        }
                    }
                }
            };
            fabric_of.push(k as u16);
        }
        (fabrics, fabric_of)
    }

    /// The seams: the pattern's stitches, then the file's seams, each
    /// checked (its panels and edges exist, its edges' lengths within
    /// `MAX_SEAM_RATIO`), with their names.
    fn seams(
        file: &GarmentFile,
        cuts: &[PanelCut],
        pending: Vec<PendingSeam>,
    ) -> Result<(Vec<SeamSpec>, Vec<String>)> {
        let stiff = file.seam_stiffness.unwrap_or(DEFAULT_SEAM_STIFFNESS);
        let damping = file.seam_damping.unwrap_or(DEFAULT_SEAM_DAMPING);
        let mut seams = Vec::new();
        let mut seam_names = Vec::new();
        let find = |name: &str, edge: usize, k: usize| -> Result<(usize, usize)> {
            let Some(p) = cuts.iter().position(|c| c.name == name) else {
                bail!("seam {k}: panel {name:?} does not exist");
            };
            if edge >= cuts[p].edges.len() {
                bail!(
                    "seam {k}: panel {name:?} has edges 0–{}, not {edge}",
                    cuts[p].edges.len() - 1
                );
            }
            Ok((p, edge))
        };
        let extra = file
            .seams
            .iter()
            .map(|s| (s.a.0.clone(), s.a.1, s.b.0.clone(), s.b.1, s.stiffness));
        for (k, (pa, ea, pb, eb, st)) in pending
            .into_iter()
            .map(|(a, b, c, d)| (a, b, c, d, None))
            .chain(extra)
            .enumerate()
        {
            let a = find(&pa, ea, k)?;
            let b = find(&pb, eb, k)?;
            let (la, lb) = (cuts[a.0].edge_length(a.1), cuts[b.0].edge_length(b.1));
            if la.max(lb) > MAX_SEAM_RATIO * la.min(lb) {
                bail!(
                    "seam {k}: edge {ea} of panel {pa:?} is {:.1} cm long and edge {eb} of panel \
                     {pb:?} {:.1} cm: more than {MAX_SEAM_RATIO}× apart (MAX_SEAM_RATIO); a \
                     wrong edge index?",
                    100.0 * la,
                    100.0 * lb
                );
            }
            let stiffness = st.unwrap_or(stiff);
            seams.push(SeamSpec {
                a,
                b,
                stiffness,
                damping,
            });
            seam_names.push(format!("{pa}:{ea} – {pb}:{eb}"));
        }
        Ok((seams, seam_names))
    }

    pub fn from_file(file: GarmentFile, path: &Path) -> Result<GarmentDef> {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let (mut cuts, pending) = GarmentDef::garmentcode_cuts(&file, &dir)?;
        GarmentDef::vertex_cuts(&file, &mut cuts)?;
        let (fabrics, fabric_of) = GarmentDef::panel_fabrics(&file, &dir, &cuts);
        if cuts.is_empty() {
            bail!("no panels: give a garmentcode pattern or panels with vertices");
        }
        for c in &cuts {
            check_panel_size(c)?;
        }
        let (seams, seam_names) = GarmentDef::seams(&file, &cuts, pending)?;
        Ok(GarmentDef {
            name: file.name.unwrap_or_else(|| {
                path.file_stem()
                    .map(|s| s.to_string_lossy().trim_end_matches(".garment").to_string())
                    .unwrap_or_default()
            }),
            cuts,
            seams,
            seam_names,
            fabrics,
            fabric_of,
            source: path.to_path_buf(),
        })
    }
}

/// A stitch of the GarmentCode pattern: (panel, edge, panel, edge).
type PendingSeam = (String, usize, String, usize);

/// The grain direction in the panel's plane at `deg` degrees from its x
/// axis.
fn grain(deg: f64) -> [f64; 2] {
    [deg.to_radians().cos(), deg.to_radians().sin()]
}

/// Refuses panels whose size says the pattern is in the wrong unit.
fn check_panel_size(c: &PanelCut) -> Result<()> {
    let poly = c.polygon();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in &poly {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let size = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if size > MAX_PANEL_SIZE {
        bail!(
            "panel {:?} is {size:.2} m across, more than {MAX_PANEL_SIZE} m (MAX_PANEL_SIZE): a \
             pattern in the wrong unit (cm or mm read as m, or units_in_meter wrong)?",
            c.name
        );
    }
    if size < MIN_PANEL_SIZE {
        bail!(
            "panel {:?} is {:.2} mm across, less than {} cm (MIN_PANEL_SIZE): a pattern in the \
             wrong unit?",
            c.name,
            1000.0 * size,
            100.0 * MIN_PANEL_SIZE
        );
    }
    Ok(())
}
