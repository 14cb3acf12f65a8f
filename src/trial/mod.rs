//! Virtual garment trials (`garment_sim trial TRIAL.yaml`): a garment
//! ([`crate::trial::pattern`]) is placed around a body mesh, sewn, draped until it
//! settles, and its fit reported. See `docs/garments.md`.
//!
//! Phases:
//! 1. **Sewing.** Gravity off; the seams pull the panels' edges together
//!    with their stiffness times `sewing.stiffness_factor`, against a drag
//!    (mass-proportional damping `sewing.drag`, 1/s, in place of the
//!    fabric's air friction) that keeps the panels from overshooting; the
//!    body's contacts stop them on the skin. It lasts `sewing.duration`.
//! 2. **Drape.** Gravity on, the seams at their own stiffness, the fabric's
//!    own damping; the run ends when the rms speed stays below
//!    `settle.speed` for `settle.hold` seconds, or at `settle.max_time`.
//! 3. **Motion** (a body with a `motion`, docs/bodies.md). The body, held
//!    in its first pose until now, plays its motion (from `motion.start` s
//!    on); the run ends with it.

pub mod body_forces;
pub mod dressing;
pub mod outcome;
pub mod pattern;
pub mod run;
mod summary;

pub use run::{run, run_built, run_trial, sew_and_drape, TrialOutcome};

use crate::collision::{Obstacle, ShapeSpec};
use crate::fabric::Fabric;
use crate::garment::Garment;
pub use crate::scene::Overrides;
use crate::scene::PoseSpec;
use crate::set::Handle;
use crate::solver::{Params, Simulation};
use crate::trial::pattern::GarmentDef;
use anyhow::{bail, Context, Result};
use body_forces::{BodyPressure, Wrench};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

fn d_spacing() -> f64 {
    0.01
}
fn d_dt() -> f64 {
    1.0 / 200.0
}
fn d_skin() -> f64 {
    0.003
}
fn d_friction() -> f64 {
    0.5
}
fn d_scale() -> f64 {
    1.0
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodyFile {
    /// Closed, outward-oriented triangle mesh (OBJ), relative to the trial
    /// file (or give `motion`).
    #[serde(default)]
    pub obj: Option<PathBuf>,
    /// A body that moves (docs/bodies.md): its meshes, closed and
    /// outward-oriented, in place of `obj`. The garment is sewn and draped
    /// on its first pose; then the body plays its motion (from `start` s
    /// after the drape ends), and the run ends with the motion.
    #[serde(default)]
    pub motion: Option<crate::scene::MotionFile>,
    /// Metres per OBJ unit.
    #[serde(default = "d_scale")]
    pub scale: f64,
    #[serde(default)]
    pub pose: PoseSpec,
    /// Distance from the skin at which the cloth rests, m (Marvelous: 3 mm).
    #[serde(default = "d_skin")]
    pub skin_offset: f64,
    /// Cloth–skin Coulomb friction.
    #[serde(default = "d_friction")]
    pub friction: f64,
    /// Heights (world z, m) of the girths the fit report measures ease at,
    /// e.g. `{chest: 1.21, waist: 1.03, hip: 0.86}`.
    #[serde(default)]
    pub girths: BTreeMap<String, f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SewingFile {
    #[serde(default = "SewingFile::d_duration")]
    pub duration: f64,
    #[serde(default)]
    pub gravity: bool,
    #[serde(default = "SewingFile::d_drag")]
    pub drag: f64,
    #[serde(default = "SewingFile::d_factor")]
    pub stiffness_factor: f64,
    /// A bound on the stitches' pull while sewing, in weights of the
    /// garment: before each step their stiffness is scaled down together so
    /// that `Σ k |g|` is at most `max_force` times the garment's weight
    /// (absent: no bound). Bounded, no vertex keeps a speed above
    /// `max_force · g · dt` either (see `limit_sewing_speed`).
    #[serde(default)]
    pub max_force: Option<f64>,
    /// The sewing ends once every stitch's gap is at most this, m (absent:
    /// it lasts `duration`).
    #[serde(default)]
    pub closed: Option<f64>,
    /// Coulomb coefficient between the cloth and the body while sewing
    /// (absent: the body's own `friction`).
    #[serde(default)]
    pub friction: Option<f64>,
}

impl SewingFile {
    fn d_duration() -> f64 {
        1.0
    }
    fn d_drag() -> f64 {
        20.0
    }
    /// Sewing pulls at 2 % of the seams' stiffness (2e4 N/m per m by
    /// default): edges 20 cm apart close in about half a second against the
    /// default drag, without a jump through the body.
    fn d_factor() -> f64 {
        0.02
    }
}

impl Default for SewingFile {
    fn default() -> Self {
        SewingFile {
            duration: Self::d_duration(),
            gravity: false,
            drag: Self::d_drag(),
            stiffness_factor: Self::d_factor(),
            max_force: None,
            closed: None,
            friction: None,
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SettleFile {
    /// rms speed below which the garment counts as at rest, m/s.
    #[serde(default = "SettleFile::d_speed")]
    pub speed: f64,
    /// It must stay below for this long, s.
    #[serde(default = "SettleFile::d_hold")]
    pub hold: f64,
    /// The drape phase ends here even if not settled, s.
    #[serde(default = "SettleFile::d_max")]
    pub max_time: f64,
}

impl SettleFile {
    fn d_speed() -> f64 {
        0.005
    }
    fn d_hold() -> f64 {
        0.2
    }
    fn d_max() -> f64 {
        6.0
    }
}

impl Default for SettleFile {
    fn default() -> Self {
        SettleFile {
            speed: Self::d_speed(),
            hold: Self::d_hold(),
            max_time: Self::d_max(),
        }
    }
}

/// A trial file. Its run's settings (`spacing`, default 1 cm; `dt`,
/// default 5 ms; `linear_solver` (or `solver`), `cg_tolerance`, `threads`,
/// `hysteresis`, `self_collision`, `obstacle_edges`, `cell_shear`) are an
/// [`Overrides`] flattened into it, the command line's over them. Read with
/// [`TrialFile::parse`], which refuses an unknown key.
#[derive(Debug, Clone, Deserialize)]
pub struct TrialFile {
    /// Garment file, relative to the trial file.
    pub garment: PathBuf,
    pub body: BodyFile,
    /// Overrides the garment's fabric.
    #[serde(default)]
    pub fabric: Option<PathBuf>,
    #[serde(default)]
    pub sewing: SewingFile,
    #[serde(default)]
    pub settle: SettleFile,
    /// A gripper pulls a sleeve over an arm after sewing, in place of the
    /// drape (docs/bodies.md, [`crate::trial::dressing`]).
    #[serde(default)]
    pub dressing: Option<crate::trial::dressing::DressingFile>,
    /// The run's settings: `self_collision` keeps the garment from passing
    /// through itself (docs/self_collision.md; off when absent, on in the
    /// shipped skirt trial); `obstacle_edges`: the body's vertices and edges
    /// meet the garment's triangles and edges too, in every phase (a body
    /// part thinner than the cloth's spacing, fingers, cannot pass between
    /// the cloth's vertices); `cell_shear`: each cell's shear from both its
    /// diagonals, with the egg-crate guards (docs/lab.md; off: each diagonal
    /// alone, thesis eq. 4.34); `cg_tolerance` in (0, 1) (default 1e-6). At
    /// the file's top level, read by [`TrialFile::parse`].
    #[serde(skip)]
    pub run: Overrides,
}

impl TrialFile {
    /// The file's own keys (besides its settings').
    const KEYS: [&'static str; 6] = ["garment", "body", "fabric", "sewing", "settle", "dressing"];

    /// Reads a trial file's text (`what` names it in the errors).
    pub fn parse(text: &str, what: &str) -> Result<TrialFile> {
        let (file, run) = crate::scene::read_file(
            text,
            what,
            &TrialFile::KEYS,
            &[
                (
                    "duration",
                    "not for a trial (a trial drapes until it settles or for \
                     `settle.max_time` after sewing)",
                ),
                (
                    "hinges",
                    "not for a trial (its panels' hinges are the garment file's `hinges`)",
                ),
                ("max_time", "a trial's longest drape is `settle.max_time`"),
            ],
        )?;
        Ok(TrialFile { run, ..file })
    }

    /// The settings with the command line's `ov` over them.
    pub fn settings(&self, ov: &Overrides) -> Overrides {
        ov.or(&self.run)
    }
}

/// A trial as read, with its files resolved.
#[derive(Debug, Clone)]
pub struct Trial {
    pub file: TrialFile,
    pub path: PathBuf,
    pub garment: GarmentDef,
    /// The garment's fabrics (the trial's `fabric`, if given, alone).
    pub fabrics: Vec<Fabric>,
    /// Each panel's fabric, an index into `fabrics`.
    pub fabric_of: Vec<u16>,
    pub body: Obstacle,
}

/// What the body mesh check found and repaired.
#[derive(Debug, Clone, Default, Serialize)]
pub struct BodyCheck {
    pub vertices: usize,
    pub triangles: usize,
    /// Zero-area triangles dropped (the documented repair).
    pub degenerate_dropped: usize,
}

/// Loads a body mesh and checks it can have an inside: every edge shared by
/// exactly two triangles (no hole, no fin), positive enclosed volume (faces
/// outward). Zero-area triangles are dropped (named in the check).
pub fn load_body(path: &Path, scale: f64) -> Result<(crate::collision::MeshData, BodyCheck)> {
    let (mut v, t) = crate::io::load_obj(path)?;
    if !(scale.is_finite() && scale > 0.0) {
        bail!("body scale {scale}: must be > 0");
    }
    v.iter_mut()
        .for_each(|p| p.iter_mut().for_each(|c| *c *= scale));
    let mut check = BodyCheck {
        vertices: v.len(),
        ..Default::default()
    };
    let (kept, dropped) =
        check_body(&v, &t).with_context(|| format!("body mesh {}", path.display()))?;
    check.degenerate_dropped = dropped;
    check.triangles = kept.len();
    Ok(((v, kept), check))
}

/// Checks a body mesh can have an inside (see [`load_body`]): its
/// triangles without the zero-area ones, and how many those were.
pub fn check_body(v: &[[f64; 3]], t: &[[u32; 3]]) -> Result<(Vec<[u32; 3]>, usize)> {
    let area = |tri: &[u32; 3]| {
        let p = |k: usize| Vector3::from(v[tri[k] as usize]);
        (p(1) - p(0)).cross(&(p(2) - p(0))).norm() / 2.0
    };
    let (lo, hi) = bbox(v);
    let size = (Vector3::from(hi) - Vector3::from(lo)).norm();
    let kept: Vec<[u32; 3]> = t
        .iter()
        .copied()
        .filter(|tri| {
            tri[0] != tri[1]
                && tri[1] != tri[2]
                && tri[0] != tri[2]
                && area(tri) > 1e-14 * size * size
        })
        .collect();
    let mut edges: HashMap<(u32, u32), usize> = HashMap::new();
    for tri in &kept {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let open: Vec<(&(u32, u32), &usize)> = edges.iter().filter(|(_, &c)| c != 2).collect();
    if !open.is_empty() {
        let (&(a, _), &c) = *open.iter().min().expect("non-empty");
        let p = v[a as usize];
        bail!(
            "{} edges are not shared by exactly two triangles (e.g. at vertex {} \
             ({:.3}, {:.3}, {:.3}) m, an edge of {c} triangle(s)): the body must be closed to have \
             an inside; close its holes (e.g. Blender: Select ▸ All by Trait ▸ Non Manifold, then \
             Face ▸ Fill)",
            open.len(),
            a + 1,
            p[0],
            p[1],
            p[2]
        );
    }
    let vol: f64 = kept
        .iter()
        .map(|tri| {
            let p = |k: usize| Vector3::from(v[tri[k] as usize]);
            p(0).dot(&p(1).cross(&p(2))) / 6.0
        })
        .sum();
    if vol.is_nan() || vol <= 0.0 {
        bail!(
            "encloses a volume of {vol:.4} m³: its faces must face outward \
             (counter-clockwise seen from outside)"
        );
    }
    let dropped = t.len() - kept.len();
    Ok((kept, dropped))
}

fn bbox(v: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in v {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

impl Trial {
    pub fn load(path: &Path) -> Result<Trial> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read trial file {}", path.display()))?;
        let file = TrialFile::parse(&text, &format!("trial file {}", path.display()))?;
        Trial::from_file(file, path)
    }

    pub fn from_file(file: TrialFile, path: &Path) -> Result<Trial> {
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        let garment = GarmentDef::load(&dir.join(&file.garment))?;
        let (paths, fabric_of) = match &file.fabric {
            Some(f) => (vec![dir.join(f)], vec![0; garment.cuts.len()]),
            None => (garment.fabrics.clone(), garment.fabric_of.clone()),
        };
        let fabrics = paths
            .iter()
            .map(|p| crate::io::load_fabric(p))
            .collect::<Result<Vec<_>>>()?;
        let b = &file.body;
        let what = |f: &str| format!("trial file {}: body.{f}", path.display());
        crate::limits::check_range(
            &what("skin_offset"),
            b.skin_offset,
            0.0,
            0.05,
            "m",
            "a skin offset of at most 5 cm",
        )?;
        crate::limits::check_range(
            &what("friction"),
            b.friction,
            0.0,
            crate::limits::MAX_FRICTION,
            "",
            "a Coulomb coefficient",
        )?;
        let pose = b.pose.isometry(&what("pose"))?;
        let body = match (&b.obj, &b.motion) {
            (Some(obj), None) => {
                let ((v, t), _) = load_body(&dir.join(obj), b.scale)?;
                Obstacle::new(
                    BODY_ID,
                    ShapeSpec::Triangles {
                        vertices: v,
                        triangles: t,
                    },
                    pose,
                    b.skin_offset,
                    b.friction,
                )?
            }
            (None, Some(m)) => {
                let l = m.load(&dir).with_context(|| what("motion"))?;
                let mut first = vec![Vector3::zeros(); l.motion.vertex_count()];
                l.motion.positions(0.0, &mut first);
                let v: Vec<[f64; 3]> = first.iter().map(|p| [p.x, p.y, p.z]).collect();
                check_body(&v, &l.triangles).with_context(|| what("motion (its first pose)"))?;
                let mut o = Obstacle::with_motion(
                    BODY_ID,
                    l.triangles,
                    l.motion,
                    m.looping,
                    m.start,
                    pose,
                    b.skin_offset,
                    b.friction,
                )?;
                // still while the garment is sewn and draped on it
                if let Some(d) = o.deforming_mut() {
                    d.held = true;
                }
                o
            }
            _ => bail!("{}: give obj or motion", what("obj")),
        };
        Ok(Trial {
            file,
            path: path.to_path_buf(),
            garment,
            fabrics,
            fabric_of,
            body,
        })
    }

    /// Cuts and sews the garment and places it with the body.
    pub fn build(&self, ov: &Overrides) -> Result<(Simulation, Garment)> {
        ov.check_for_trial()?;
        let run = self.file.settings(ov);
        let spacing = run.spacing.unwrap_or(d_spacing());
        crate::limits::check_range(
            "spacing",
            spacing,
            0.002,
            0.1,
            "m",
            "a garment grid of 2 mm to 10 cm",
        )?;
        let params = run.apply(Params {
            dt: d_dt(),
            cloth_thickness: crate::collision::DEFAULT_CLOTH_THICKNESS,
            friction_bound_now: true,
            ..Params::default()
        });
        crate::limits::check_dt("dt", params.dt)?;
        // checked before the garment is cut, as dt is (the simulation checks both again)
        crate::limits::check_cg_tolerance("cg_tolerance", params.cg_tolerance)?;
        let masses: Vec<f64> = self.fabrics.iter().map(|f| f.areal_mass).collect();
        let g = Garment::build_with_fabrics(
            &self.garment.cuts,
            &self.fabric_of,
            &self.garment.seams,
            spacing,
            &masses,
        )
        .with_context(|| format!("garment {}", self.garment.source.display()))?;
        // a panel placed partly inside the body (a pattern drafted for
        // another body) is brought out whole before it is sewn
        let mut g = g;
        g.bring_out(&self.body)
            .with_context(|| format!("garment {}", self.garment.source.display()))?;
        let mut sim = Simulation::with_fabrics(g.cloth.clone(), self.fabrics.clone(), params)?;
        sim.add_obstacle(self.body.clone());
        Ok((sim, g))
    }
}

/// The garment's weight in the sewing's bound is its mass times standard
/// gravity, m/s² (whatever the scene's gravity).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// The id of a trial's body among the simulation's obstacles.
pub const BODY_ID: &str = "body";

/// The body of a simulation: its obstacle named [`BODY_ID`] (a trial's
/// body, or a scene's obstacle of that id), the first if several.
pub fn body_handle(sim: &Simulation) -> Option<Handle<Obstacle>> {
    sim.obstacles().find(|o| o.id == BODY_ID)
}

/// Does this YAML file describe a trial (it names a garment) rather than a
/// scene?
pub fn is_trial_file(path: &Path) -> bool {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| serde_yaml::from_str::<serde_yaml::Value>(&t).ok())
        .is_some_and(|v| v.get("garment").is_some())
}

/// What a bag or the node's `scene_description` says of a trial: its file
/// and the garment and fabric files it names, as written.
#[derive(Debug, Clone, Serialize)]
pub struct TrialDescription {
    pub format: String,
    pub trial_file: String,
    pub trial_yaml: String,
    pub garment_file: String,
    pub garment_yaml: String,
    pub panels: Vec<String>,
    pub vertices: usize,
    pub dt_s: f64,
}

impl Trial {
    /// The trial's description (YAML).
    pub fn description(&self, g: &Garment, sim: &Simulation) -> Result<String> {
        let read = |p: &Path| {
            std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))
        };
        let d = TrialDescription {
            format: "garment_sim/trial_description/1".into(),
            trial_file: self.path.display().to_string(),
            trial_yaml: read(&self.path)?,
            garment_file: self.garment.source.display().to_string(),
            garment_yaml: read(&self.garment.source)?,
            panels: g.panels.iter().map(|p| p.name.clone()).collect(),
            vertices: sim.cloth.len(),
            dt_s: sim.params().dt,
        };
        Ok(serde_yaml::to_string(&d)?)
    }

    /// One line on what is about to run: the garment, its grid and fabric,
    /// the body, the step.
    pub fn headline(&self, sim: &Simulation, g: &Garment) -> String {
        format!(
            "garment {}: {} panels, {} seams ({} stitches), {} vertices, {:.0} g of {}; body {} \
             triangles; dt = {} s",
            self.garment.name,
            g.panels.len(),
            g.seams.len(),
            g.cloth.seams().len(),
            g.cloth.len(),
            1e3 * g.cloth.total_mass(),
            sim.fabric.name,
            self.body.mesh.as_ref().map_or(0, |m| m.1.len()),
            sim.params().dt
        )
    }

    /// Builds the trial and runs its sewing phase: the garment on the body,
    /// sewn, gravity on, ready to drape (the node's scene).
    pub fn sewn(&self, ov: &Overrides) -> Result<(Simulation, Garment)> {
        let (mut sim, g) = self.build(ov)?;
        run(
            &mut sim,
            &self.file.sewing,
            &self.file.settle,
            Some(0.0),
            &mut crate::run::run_on,
        )?;
        Ok((sim, g))
    }
}

/// The cost of a phase of a run, per step.
#[derive(Debug, Clone, Serialize)]
pub struct PhaseCost {
    pub steps: u64,
    pub wall_s: f64,
    /// Wall time per step, the wrench included, ms.
    pub ms_per_step: f64,
    /// Of which: assembly, linear solve, and contacts with the obstacles
    /// (for a moving body: its tree's refit, the contacts' detection and
    /// the swept check after the step; self-collision not included), ms.
    pub time_split_ms_per_step: crate::run::TimeSplit,
    pub mean_solver_iterations: f64,
    /// The garment's wrench on the body after each step, ms.
    pub body_wrench_ms_per_step: f64,
}

/// How the run went.
#[derive(Debug, Clone, Serialize)]
pub struct RunStats {
    pub sewing_s: f64,
    /// Simulated time from the end of sewing until settled; `null` if it did
    /// not settle within `settle.max_time`.
    pub settle_time_s: Option<f64>,
    pub simulated_s: f64,
    /// Simulated time of the body's motion after the drape (a body with a
    /// `motion`), s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion_s: Option<f64>,
    /// Simulated time of the dressing after sewing (a trial with
    /// `dressing`), s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dressing_s: Option<f64>,
    pub steps: u64,
    pub wall_s: f64,
    pub ms_per_step: f64,
    pub time_split_ms_per_step: crate::run::TimeSplit,
    pub final_rms_speed_m_s: f64,
    pub mean_solver_iterations: f64,
    /// Time spent on the wrench on the body after each step (outside the
    /// step, included in `ms_per_step`), ms per step.
    pub body_wrench_ms_per_step: f64,
    /// The same figures for the body's motion alone (a body with a
    /// `motion`): the cost of following a moving body.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motion: Option<PhaseCost>,
    /// Every 0.05 s: time (s), rms speed (m/s), vertices in contact, solver
    /// iterations of that step (written as `trial.csv`).
    #[serde(skip)]
    pub trace: Vec<[f64; 4]>,
    /// The garment's wrench on the body after every step, with the time
    /// (written as `body_wrench.csv`; empty when run without a body).
    #[serde(skip)]
    pub wrench: Vec<(f64, Wrench)>,
    /// Why the trial ended early: the step that failed, with its error (a
    /// failed step changes nothing: the figures are of the steps before it).
    /// Absent when it ran its course or was stopped.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
    /// The observer stopped the run before its end.
    #[serde(skip)]
    pub stopped: bool,
}

impl RunStats {
    /// The statistics of a trial that ran its course (or was stopped), or
    /// the error of the step that failed.
    pub fn into_result(self) -> Result<RunStats> {
        crate::scene::run::failed(self.failure.clone())?;
        Ok(self)
    }
}

/// Largest, mean strain of one kind on one panel, %.
#[derive(Debug, Clone, Copy, Serialize, Default)]
pub struct StrainStat {
    pub max_percent: f64,
    pub mean_percent: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct PanelFit {
    pub name: String,
    /// The name of the panel's fabric.
    pub fabric: String,
    pub vertices: usize,
    pub area_m2: f64,
    pub warp: StrainStat,
    pub weft: StrainStat,
    pub bias: StrainStat,
}

#[derive(Debug, Clone, Serialize)]
pub struct GirthFit {
    pub height_m: f64,
    /// Convex-hull perimeter of the body's section (the torso's loop around
    /// the vertical axis), and of the garment's section points within 1.5×
    /// its reach + 5 cm, cm: tape measures.
    pub body_cm: Option<f64>,
    pub garment_cm: Option<f64>,
    /// Garment girth − body girth, cm.
    pub ease_cm: Option<f64>,
    /// Mean distance of the garment from the body in a band 2 cm high, cm.
    pub mean_distance_cm: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    pub garment: String,
    pub fabric: String,
    pub vertices: usize,
    pub spacing_m: f64,
    pub dt_s: f64,
    pub mass_kg: f64,
    /// The garment's weight, N.
    pub weight_n: f64,
    pub panels: Vec<PanelFit>,
    /// Cloth area in contact with the body, m².
    pub contact_area_m2: f64,
    pub contact_vertices: usize,
    /// Total force of the garment on the body (vector, and its size), N.
    pub contact_force_n: [f64; 3],
    pub contact_force_magnitude_n: f64,
    /// Normal force over the contact area, Pa.
    pub mean_pressure_pa: f64,
    pub peak_pressure_pa: f64,
    /// Σ pressure × area over the contact vertices (the normal force), N.
    pub pressure_integral_n: f64,
    /// The pressure map integrated as a force on the body, Σ −p A n, N
    /// (the contact force less friction).
    pub pressure_force_n: [f64; 3],
    /// Vertices per 1 cm band of distance from the skin: [0, 1) cm, … , ≥ 10 cm.
    pub distance_histogram_cm: Vec<usize>,
    pub girths: BTreeMap<String, GirthFit>,
    /// Garment vertices inside the body's surface, and the deepest, cm.
    pub body_penetrations: usize,
    pub deepest_penetration_cm: f64,
    pub largest_seam_gap_mm: f64,
    pub largest_seam_gap_at: Option<String>,
    /// The garment's force and torque on the body (`body_wrench.csv` over
    /// time); `null` without a body.
    pub body_wrench: Option<BodyWrenchFit>,
    /// The pressure on the body's vertices at the end (`body_pressure.ply`).
    pub body_pressure: Option<BodyPressureFit>,
    /// A dressing trial's progress and forces (`dressing.csv` over time).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dressing: Option<crate::trial::dressing::DressingReport>,
    /// What a designer should not miss: a panel stretched beyond
    /// [`OVERSTRETCH`], a seam open beyond 2 mm, cloth inside the body, a
    /// garment that did not settle.
    pub warnings: Vec<String>,
    /// How the trial ended (settled, or why not); set by the run
    /// ([`run_trial`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub outcome: Option<outcome::Outcome>,
    pub run: RunStats,
}

/// The garment's wrench on the body: at the end of the run, averaged over
/// its last [`WRENCH_MEAN_S`] seconds, and its largest force over the run.
#[derive(Debug, Clone, Serialize)]
pub struct BodyWrenchFit {
    /// After the last step (force N, torque N m about the body frame's
    /// origin, normal force N, contacts).
    pub last: Wrench,
    /// Mean force and torque of the steps in the last [`WRENCH_MEAN_S`] s.
    pub mean_force_n: [f64; 3],
    pub mean_torque_nm: [f64; 3],
    /// The mean force's downward part over the garment's weight: 1 when the
    /// body alone holds the garment at rest.
    pub mean_down_over_weight: f64,
    /// Largest force over the run, N, and when, s. The sewing's first
    /// steps slam the panels onto the body (docs/garments.md), so this is
    /// usually a sewing step's.
    pub peak_force_n: f64,
    pub peak_force_time_s: f64,
    /// Largest force once the sewing has ended, N, and when, s (`null`
    /// without steps after it): what the garment as sewn does to the body.
    pub peak_force_after_sewing_n: Option<f64>,
    pub peak_force_after_sewing_time_s: Option<f64>,
}

/// Seconds at the end of a run over which [`BodyWrenchFit`] averages.
pub const WRENCH_MEAN_S: f64 = 0.5;

/// The pressure on the body's vertices ([`BodyPressure`]) summed up.
#[derive(Debug, Clone, Serialize)]
pub struct BodyPressureFit {
    /// Body vertices under a pressure.
    pub loaded_vertices: usize,
    /// Their area, m².
    pub loaded_area_m2: f64,
    pub peak_pressure_pa: f64,
    /// Σ pressure × vertex area over the body's vertices, N (equals
    /// `normal_force_n`).
    pub pressure_integral_n: f64,
    /// Σ of the contacts' normal forces, N.
    pub normal_force_n: f64,
}

impl BodyPressureFit {
    pub fn of(p: &BodyPressure) -> BodyPressureFit {
        let loaded: Vec<usize> = (0..p.pressure.len())
            .filter(|&i| p.pressure[i] > 0.0)
            .collect();
        BodyPressureFit {
            loaded_vertices: loaded.len(),
            loaded_area_m2: loaded.iter().map(|&i| p.area[i]).sum(),
            peak_pressure_pa: p.pressure.iter().copied().fold(0.0, f64::max),
            pressure_integral_n: p.integral(),
            normal_force_n: p.normal_force,
        }
    }
}

impl BodyWrenchFit {
    /// From a run's wrench history (`None` if it has none), the garment's
    /// weight, N, and the time the sewing ended, s.
    pub fn of(history: &[(f64, Wrench)], weight: f64, sewn: f64) -> Option<BodyWrenchFit> {
        let &(t_end, last) = history.last()?;
        let tail: Vec<&Wrench> = history
            .iter()
            .filter(|(t, _)| *t >= t_end - WRENCH_MEAN_S - 1e-12)
            .map(|(_, w)| w)
            .collect();
        let n = tail.len() as f64;
        let mean = |f: &dyn Fn(&Wrench) -> [f64; 3]| -> [f64; 3] {
            let mut m = [0.0; 3];
            for w in &tail {
                let v = f(w);
                for k in 0..3 {
                    m[k] += v[k] / n;
                }
            }
            m
        };
        let mf = mean(&|w| w.force);
        let peak = |after: f64| {
            history
                .iter()
                .filter(|(t, _)| *t > after + 1e-12)
                .map(|(t, w)| (*t, Vector3::from(w.force).norm()))
                .fold(None, |a: Option<(f64, f64)>, b| match a {
                    Some(a) if a.1 >= b.1 => Some(a),
                    _ => Some(b),
                })
        };
        let (peak_t, peak_n) = peak(f64::NEG_INFINITY).unwrap_or((0.0, 0.0));
        let after = peak(sewn);
        Some(BodyWrenchFit {
            last,
            mean_force_n: mf,
            mean_torque_nm: mean(&|w| w.torque),
            mean_down_over_weight: if weight > 0.0 { -mf[2] / weight } else { 0.0 },
            peak_force_n: peak_n,
            peak_force_time_s: peak_t,
            peak_force_after_sewing_n: after.map(|a| a.1),
            peak_force_after_sewing_time_s: after.map(|a| a.0),
        })
    }
}

/// Strain beyond which a panel is reported as overstretched (a pattern that
/// does not fit the body, or cloth caught in a crease of it).
pub const OVERSTRETCH: f64 = 0.5;

/// Per-vertex fields of the fit (for the PLY, the pictures, the node).
#[derive(Debug, Clone)]
pub struct VertexFit {
    pub panel: Vec<usize>,
    pub warp: Vec<f64>,
    pub weft: Vec<f64>,
    pub bias: Vec<f64>,
    /// Largest of warp, weft and bias stretch (the strain map).
    pub stretch: Vec<f64>,
    /// Contact pressure, Pa.
    pub pressure: Vec<f64>,
    /// Distance from the body's surface, m.
    pub distance: Vec<f64>,
    /// Force of the garment on the body at each vertex, N.
    pub force: Vec<Vector3<f64>>,
    /// The contact's normal at each vertex (zero where none).
    pub normal: Vec<Vector3<f64>>,
    /// Each vertex's area of cloth (its mass over its fabric's areal mass), m².
    pub area: Vec<f64>,
}

/// The strain of every tension and shear spring: (0 warp, 1 weft, 2 bias),
/// its two vertices and its engineering strain l/l0 − 1.
fn spring_strains(
    c: &crate::cloth::Cloth,
) -> impl Iterator<Item = (usize, usize, usize, f64)> + '_ {
    let x = c.positions();
    c.tension
        .iter()
        .map(move |s| {
            (
                usize::from(s.weft),
                s.a,
                s.b,
                (x[s.b] - x[s.a]).norm() / s.l0 - 1.0,
            )
        })
        .chain(
            c.shear
                .iter()
                .map(move |s| (2, s.a, s.b, (x[s.b] - x[s.a]).norm() / s.l0 - 1.0)),
        )
        .chain(c.shear_cells.iter().flat_map(move |s| {
            let (d1, d2) = s.diagonals(x);
            [
                (2, s.v[0], s.v[1], d1.norm() / s.l1 - 1.0),
                (2, s.v[2], s.v[3], d2.norm() / s.l2 - 1.0),
            ]
        }))
}

/// The per-vertex fit of the garment as it is now (what `garment.ply` and
/// the node's point cloud carry): strains, contact pressure and force,
/// distance from the body.
pub fn vertex_fit(sim: &Simulation, g: &Garment, body: &Obstacle) -> VertexFit {
    let c = &sim.cloth;
    let n = c.len();
    let mut fields = [
        vec![f64::NEG_INFINITY; n],
        vec![f64::NEG_INFINITY; n],
        vec![f64::NEG_INFINITY; n],
    ];
    for (k, a, b, e) in spring_strains(c) {
        fields[k][a] = fields[k][a].max(e);
        fields[k][b] = fields[k][b].max(e);
    }
    for f in &mut fields {
        f.iter_mut()
            .filter(|e| !e.is_finite())
            .for_each(|e| *e = 0.0);
    }
    let [warp, weft, bias] = fields;
    let stretch: Vec<f64> = (0..n).map(|i| warp[i].max(weft[i]).max(bias[i])).collect();
    // the force on the body is the opposite of the contacts' on the cloth;
    // the pressure is its normal part over the vertex's area
    let on_cloth = sim.contact_forces();
    let normals = sim.contact_normals();
    let force: Vec<Vector3<f64>> = on_cloth.iter().map(|f| -f).collect();
    let area: Vec<f64> = (0..n)
        .map(|i| c.mass[i] / sim.fabric_of(i).areal_mass)
        .collect();
    let pressure = (0..n)
        .map(|i| {
            if on_cloth[i] == Vector3::zeros() {
                0.0
            } else {
                on_cloth[i].dot(&normals[i]).max(0.0) / area[i]
            }
        })
        .collect();
    VertexFit {
        panel: (0..n).map(|i| g.panel_of(i)).collect(),
        warp,
        weft,
        bias,
        stretch,
        pressure,
        distance: c
            .positions()
            .iter()
            .map(|p| body.proximity(p).distance)
            .collect(),
        force,
        normal: normals,
        area,
    }
}

/// The trial's body as it is now in `sim` (a body with a motion moves),
/// else as the trial made it.
pub fn body_now<'a>(sim: &'a Simulation, trial: &'a Trial) -> &'a Obstacle {
    sim.obstacles()
        .iter()
        .find(|o| o.id == trial.body.id)
        .unwrap_or(&trial.body)
}

/// Per panel and spring direction (warp, weft, bias): the largest strain,
/// the strains' sum and their count.
type StrainAcc = [(f64, f64, usize); 3];

/// Every panel's spring strains gathered by direction.
fn panel_strains(c: &crate::cloth::Cloth, vf: &VertexFit, np: usize) -> Vec<StrainAcc> {
    let mut acc = vec![[(f64::NEG_INFINITY, 0.0, 0usize); 3]; np];
    for (k, a, _, e) in spring_strains(c) {
        let s = &mut acc[vf.panel[a]][k];
        s.0 = s.0.max(e);
        s.1 += e;
        s.2 += 1;
    }
    acc
}

/// The panels' fit: their fabric, size and strains, %.
fn panel_fits(sim: &Simulation, g: &Garment, acc: &[StrainAcc]) -> Vec<PanelFit> {
    let stat = |s: (f64, f64, usize)| StrainStat {
        max_percent: if s.2 > 0 { 100.0 * s.0 } else { 0.0 },
        mean_percent: if s.2 > 0 {
            100.0 * s.1 / s.2 as f64
        } else {
            0.0
        },
    };
    g.panels
        .iter()
        .enumerate()
        .map(|(k, p)| PanelFit {
            name: p.name.clone(),
            fabric: sim.fabric_of(p.first).name.clone(),
            vertices: p.count,
            area_m2: p.area,
            warp: stat(acc[k][0]),
            weft: stat(acc[k][1]),
            bias: stat(acc[k][2]),
        })
        .collect()
}

/// The contact between garment and body summed over the vertices in
/// contact.
struct ContactSums {
    /// Contact area, m².
    area: f64,
    /// Contact force, N.
    total: Vector3<f64>,
    /// Σ pressure × area, N.
    normal_sum: f64,
    /// Peak pressure, Pa.
    peak: f64,
    /// Vertices in contact.
    count: usize,
    /// −Σ normal × pressure × area, N.
    pressure_force: Vector3<f64>,
}

impl ContactSums {
    /// Sums over the vertices with a contact force.
    fn of(vf: &VertexFit, n: usize) -> ContactSums {
        let (pressure, force) = (&vf.pressure, &vf.force);
        let (mut area, mut total, mut normal_sum, mut peak, mut nc) =
            (0.0, Vector3::zeros(), 0.0, 0.0f64, 0usize);
        let mut pressure_force = Vector3::zeros();
        for i in 0..n {
            if force[i] == Vector3::zeros() {
                continue;
            }
            total += force[i];
            let a = vf.area[i];
            pressure_force -= vf.normal[i] * (pressure[i] * a);
            normal_sum += pressure[i] * a;
            peak = peak.max(pressure[i]);
            area += a;
            nc += 1;
        }
        ContactSums {
            area,
            total,
            normal_sum,
            peak,
            count: nc,
            pressure_force,
        }
    }
}

/// The girths the body file names: the body's and the garment's
/// perimeters (convex hulls) at each height, the ease and the mean
/// distance of the garment's band within 1 cm of the height.
fn girth_fits(
    c: &crate::cloth::Cloth,
    body: &Obstacle,
    trial: &Trial,
    distance: &[f64],
) -> BTreeMap<String, GirthFit> {
    let (x, n) = (c.positions(), c.len());
    let mut girths = BTreeMap::new();
    let (bv, bt) = body.local_triangles();
    let bw: Vec<[f64; 3]> = bv
        .iter()
        .map(|p| {
            let q = body.pose * nalgebra::Point3::from(Vector3::from(*p));
            [q.x, q.y, q.z]
        })
        .collect();
    let bt: Vec<[usize; 3]> = bt.iter().map(|t| t.map(|k| k as usize)).collect();
    let gw: Vec<[f64; 3]> = x.iter().map(|p| [p.x, p.y, p.z]).collect();
    for (name, &z) in &trial.file.body.girths {
        let body_loop = torso_loop(&bw, &bt, z);
        let centre = body_loop.as_ref().map(|l| centroid(l));
        // the garment's panels are separate meshes joined by stitches: its
        // section is open pieces; take its points around the body's section
        let garment_loop = body_loop.as_ref().and_then(|bl| {
            let cen = centre.expect("a loop has a centre");
            let reach = bl
                .iter()
                .map(|p| ((p[0] - cen[0]).powi(2) + (p[1] - cen[1]).powi(2)).sqrt())
                .fold(0.0, f64::max)
                * 1.5
                + 0.05;
            let pts: Vec<[f64; 2]> = section_points(&gw, &c.triangles, z)
                .into_iter()
                .filter(|p| ((p[0] - cen[0]).powi(2) + (p[1] - cen[1]).powi(2)).sqrt() <= reach)
                .collect();
            (pts.len() >= 3).then_some(pts)
        });
        let band: Vec<f64> = (0..n)
            .filter(|&i| (x[i].z - z).abs() <= 0.01)
            .map(|i| distance[i])
            .collect();
        let bcm = body_loop.map(|l| 100.0 * hull_perimeter(&l));
        let gcm = garment_loop.map(|l| 100.0 * hull_perimeter(&l));
        girths.insert(
            name.clone(),
            GirthFit {
                height_m: z,
                body_cm: bcm,
                garment_cm: gcm,
                ease_cm: bcm.zip(gcm).map(|(b, g)| g - b),
                mean_distance_cm: (!band.is_empty())
                    .then(|| 100.0 * band.iter().sum::<f64>() / band.len() as f64),
            },
        );
    }
    girths
}

/// A warning for every panel stretched beyond `OVERSTRETCH` along a
/// direction, near its most stretched vertex.
fn overstretch_warnings(
    g: &Garment,
    acc: &[StrainAcc],
    stretch: &[f64],
    x: &[Vector3<f64>],
) -> Vec<String> {
    let mut warnings = Vec::new();
    for (k, p) in g.panels.iter().enumerate() {
        let worst = [(0, "warp"), (1, "weft"), (2, "bias")]
            .into_iter()
            .map(|(q, name)| (acc[k][q].0, name))
            .fold(
                (f64::NEG_INFINITY, ""),
                |a, b| if b.0 > a.0 { b } else { a },
            );
        if worst.0 > OVERSTRETCH {
            let (i, _) = (p.first..p.first + p.count).map(|i| (i, stretch[i])).fold(
                (p.first, f64::NEG_INFINITY),
                |a, b| if b.1 > a.1 { b } else { a },
            );
            warnings.push(format!(
                "panel {:?} is stretched {:.0} % along {} (near ({:.3}, {:.3}, {:.3}) m): the \
                 pattern does not fit the body there, or the cloth is caught in a crease",
                p.name,
                100.0 * worst.0,
                worst.1,
                x[i].x,
                x[i].y,
                x[i].z
            ));
        }
    }
    warnings
}

/// Measures the fit of the garment as it is now, with the pressure on the
/// body's vertices.
pub fn fit(
    sim: &Simulation,
    g: &Garment,
    trial: &Trial,
    run: RunStats,
) -> (Fit, VertexFit, Option<BodyPressure>) {
    let c = &sim.cloth;
    let x = c.positions();
    let n = c.len();
    let body = body_now(sim, trial);
    let vf = vertex_fit(sim, g, body);
    let acc = panel_strains(c, &vf, g.panels.len());
    let panels = panel_fits(sim, g, &acc);
    let (pressure, distance, stretch) = (&vf.pressure, &vf.distance, &vf.stretch);
    let contact = ContactSums::of(&vf, n);
    let mut hist = vec![0usize; 11];
    for &d in distance {
        hist[((d.max(0.0) * 100.0).floor() as usize).min(10)] += 1;
    }
    let (pen, deepest) = distance
        .iter()
        .filter(|d| **d < 0.0)
        .fold((0, 0.0f64), |(k, m), d| (k + 1, m.max(-d)));
    let (gap, at) = g.largest_gap(x);
    let mass = c.total_mass();
    let weight = mass * sim.params().gravity.norm();
    let girths = girth_fits(c, body, trial, distance);
    let mut warnings = overstretch_warnings(g, &acc, stretch, x);
    for m in &g.moved {
        warnings.push(m.note(g));
    }
    if gap > outcome::SEAM_CLOSED {
        warnings.push(format!(
            "seam {} is open by {:.1} mm",
            at.map(|k| trial.garment.seam_names[k].as_str())
                .unwrap_or("?"),
            1e3 * gap
        ));
    }
    if pen > 0 {
        warnings.push(format!(
            "{pen} vertices are inside the body (deepest {:.1} mm)",
            1e3 * deepest
        ));
    }
    if run.settle_time_s.is_none() && run.dressing_s.is_none() {
        warnings.push(format!(
            "the garment did not settle (rms speed {:.3} m/s at the end): the fit is of a \
             moving garment",
            run.final_rms_speed_m_s
        ));
    }
    let on_body = body_handle(sim).and_then(|b| body_forces::body_pressure(sim, b));
    let ContactSums {
        area,
        total,
        normal_sum,
        peak,
        count: nc,
        pressure_force,
    } = contact;
    let fit = Fit {
        body_wrench: BodyWrenchFit::of(&run.wrench, weight, run.sewing_s),
        body_pressure: on_body.as_ref().map(BodyPressureFit::of),
        dressing: None,
        garment: trial.garment.name.clone(),
        fabric: sim
            .fabrics()
            .map(|f| f.name.as_str())
            .collect::<Vec<_>>()
            .join(" + "),
        vertices: n,
        spacing_m: c.lc,
        dt_s: sim.params().dt,
        mass_kg: mass,
        weight_n: weight,
        panels,
        contact_area_m2: area,
        contact_vertices: nc,
        contact_force_n: total.into(),
        contact_force_magnitude_n: total.norm(),
        mean_pressure_pa: if area > 0.0 { normal_sum / area } else { 0.0 },
        peak_pressure_pa: peak,
        pressure_integral_n: (0..n).map(|i| pressure[i] * vf.area[i]).sum(),
        pressure_force_n: pressure_force.into(),
        distance_histogram_cm: hist,
        girths,
        body_penetrations: pen,
        deepest_penetration_cm: 100.0 * deepest,
        largest_seam_gap_mm: 1e3 * gap,
        largest_seam_gap_at: at.map(|k| trial.garment.seam_names[k].clone()),
        warnings,
        outcome: None,
        run,
    };
    (fit, vf, on_body)
}

/// Writes `body_wrench.csv`: the garment's wrench on the body after every
/// step.
pub fn write_wrench(run: &RunStats, path: &Path) -> Result<()> {
    crate::io::write_atomic(path, |w| {
        writeln!(
            w,
            "time_s,force_x_n,force_y_n,force_z_n,torque_x_nm,torque_y_nm,torque_z_nm,\
             normal_force_n,contacts"
        )?;
        for (t, r) in &run.wrench {
            let (f, m) = (r.force, r.torque);
            writeln!(
                w,
                "{t:.4},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{:.6e},{}",
                f[0], f[1], f[2], m[0], m[1], m[2], r.normal_force, r.contacts
            )?;
        }
        Ok(())
    })
}

/// Writes the body with the garment's pressure on its vertices as a PLY
/// (`body_pressure.ply`): x, y, z (m, world), `pressure` (Pa), `force` (the
/// normal force the vertex received, N), `area` (m², a third of its
/// triangles').
pub fn write_body_ply(p: &BodyPressure, path: &Path) -> Result<()> {
    crate::io::write_atomic(path, |w| {
        writeln!(
            w,
            "ply\nformat ascii 1.0\ncomment garment_sim body under the garment; metres, \
             pressure Pa, force N, area m^2"
        )?;
        writeln!(w, "element vertex {}", p.vertices.len())?;
        for f in ["x", "y", "z", "pressure", "force", "area"] {
            writeln!(w, "property float {f}")?;
        }
        writeln!(w, "element face {}", p.triangles.len())?;
        writeln!(w, "property list uchar int vertex_indices\nend_header")?;
        for (i, v) in p.vertices.iter().enumerate() {
            writeln!(
                w,
                "{:.6} {:.6} {:.6} {:.6e} {:.6e} {:.6e}",
                v.x, v.y, v.z, p.pressure[i], p.force[i], p.area[i]
            )?;
        }
        for t in &p.triangles {
            writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
        }
        Ok(())
    })
}

/// Closed loops where the plane z = `z` cuts a triangle mesh (xy points).
pub fn slice_loops(v: &[[f64; 3]], t: &[[usize; 3]], z: f64) -> Vec<Vec<[f64; 2]>> {
    // crossing points keyed by the mesh edge they lie on
    let key = |a: usize, b: usize| (a.min(b), a.max(b));
    let point = |a: usize, b: usize| -> [f64; 2] {
        let (p, q) = (v[a], v[b]);
        let s = (z - p[2]) / (q[2] - p[2]);
        [p[0] + s * (q[0] - p[0]), p[1] + s * (q[1] - p[1])]
    };
    let above = |k: usize| v[k][2] > z;
    let mut next: HashMap<(usize, usize), Vec<(usize, usize)>> = HashMap::new();
    for tri in t {
        let cut: Vec<(usize, usize)> = (0..3)
            .filter(|&k| above(tri[k]) != above(tri[(k + 1) % 3]))
            .map(|k| key(tri[k], tri[(k + 1) % 3]))
            .collect();
        if cut.len() == 2 {
            next.entry(cut[0]).or_default().push(cut[1]);
            next.entry(cut[1]).or_default().push(cut[0]);
        }
    }
    let mut seen: std::collections::HashSet<(usize, usize)> = Default::default();
    let mut loops = Vec::new();
    let mut keys: Vec<(usize, usize)> = next.keys().copied().collect();
    keys.sort();
    for start in keys {
        if seen.contains(&start) {
            continue;
        }
        let mut lp = vec![];
        let mut cur = start;
        let mut prev: Option<(usize, usize)> = None;
        loop {
            seen.insert(cur);
            lp.push(point(cur.0, cur.1));
            let nb = &next[&cur];
            let nxt = nb
                .iter()
                .copied()
                .find(|e| Some(*e) != prev && !seen.contains(e));
            match nxt {
                Some(e) => {
                    prev = Some(cur);
                    cur = e;
                }
                None => break,
            }
        }
        if lp.len() >= 3 {
            loops.push(lp);
        }
    }
    loops
}

fn centroid(l: &[[f64; 2]]) -> [f64; 2] {
    let n = l.len() as f64;
    [
        l.iter().map(|p| p[0]).sum::<f64>() / n,
        l.iter().map(|p| p[1]).sum::<f64>() / n,
    ]
}

/// The body's torso at height z: the largest loop of the section around
/// the vertical axis x = y = 0 (the shipped bodies are centred on it), or
/// the largest loop.
fn torso_loop(v: &[[f64; 3]], t: &[[usize; 3]], z: f64) -> Option<Vec<[f64; 2]>> {
    let loops = slice_loops(v, t, z);
    let area = |l: &Vec<[f64; 2]>| crate::cloth::polygon_area(l).abs();
    let around: Vec<&Vec<[f64; 2]>> = loops
        .iter()
        .filter(|l| crate::cloth::polygon_contains(l, [0.0, 0.0]))
        .collect();
    let pick = if around.is_empty() {
        loops.iter().max_by(|a, b| area(a).total_cmp(&area(b)))
    } else {
        around
            .into_iter()
            .max_by(|a, b| area(a).total_cmp(&area(b)))
    };
    pick.cloned()
}

/// Where the plane z = `z` cuts the edges of a triangle mesh (xy points).
fn section_points(v: &[[f64; 3]], t: &[[usize; 3]], z: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    for tri in t {
        for k in 0..3 {
            let (a, b) = (v[tri[k]], v[tri[(k + 1) % 3]]);
            if (a[2] > z) != (b[2] > z) {
                let s = (z - a[2]) / (b[2] - a[2]);
                out.push([a[0] + s * (b[0] - a[0]), a[1] + s * (b[1] - a[1])]);
            }
        }
    }
    out
}

/// Perimeter of the convex hull (a tape measure around the section), m.
pub fn hull_perimeter(p: &[[f64; 2]]) -> f64 {
    let hull = crate::cloth::convex_hull(p);
    let n = hull.len();
    (0..n)
        .map(|k| {
            let (a, b) = (hull[k], hull[(k + 1) % n]);
            ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt()
        })
        .sum()
}

/// The run's trace as CSV: time (s), rms speed (m/s), contacts, solver
/// iterations.
pub fn write_trace(run: &RunStats, path: &Path) -> Result<()> {
    crate::io::write_atomic(path, |w| {
        writeln!(w, "time_s,rms_speed_m_s,contacts,solver_iterations")?;
        for r in &run.trace {
            writeln!(w, "{:.4},{:.6e},{},{}", r[0], r[1], r[2], r[3])?;
        }
        Ok(())
    })
}

/// The garment as OBJ: one group per panel, panel coordinates (m) as UVs.
pub fn write_obj(sim: &Simulation, g: &Garment, path: &Path) -> Result<()> {
    crate::io::write_atomic(path, |w| {
        writeln!(
            w,
            "# garment_sim garment: one group per panel; vt = panel coordinates, m"
        )?;
        writeln!(w, "o garment")?;
        for p in sim.cloth.positions() {
            writeln!(w, "v {:.6} {:.6} {:.6}", p.x, p.y, p.z)?;
        }
        for p in &g.panels {
            for uv in &p.uv {
                writeln!(w, "vt {:.6} {:.6}", uv[0], uv[1])?;
            }
        }
        let tris = &sim.cloth.triangles;
        for (k, p) in g.panels.iter().enumerate() {
            writeln!(w, "g {}", p.name)?;
            for t in tris.iter().filter(|t| g.panel_of(t[0]) == k) {
                writeln!(w, "f {0}/{0} {1}/{1} {2}/{2}", t[0] + 1, t[1] + 1, t[2] + 1)?;
            }
        }
        Ok(())
    })
}

/// The garment as PLY with the per-vertex fit fields.
pub fn write_ply(sim: &Simulation, vf: &VertexFit, path: &Path) -> Result<()> {
    let c = &sim.cloth;
    crate::io::write_atomic(path, |w| {
        writeln!(w, "ply\nformat ascii 1.0\ncomment garment_sim garment; metres, strains l/l0 - 1, pressure Pa, distance from the body m, speed m/s")?;
        writeln!(w, "element vertex {}", c.len())?;
        for f in ["x", "y", "z"] {
            writeln!(w, "property float {f}")?;
        }
        writeln!(w, "property int panel")?;
        for f in [
            "strain_warp",
            "strain_weft",
            "strain_bias",
            "pressure",
            "distance",
            "speed",
        ] {
            writeln!(w, "property float {f}")?;
        }
        writeln!(w, "element face {}", c.triangles.len())?;
        writeln!(w, "property list uchar int vertex_indices\nend_header")?;
        for i in 0..c.len() {
            let p = c.positions()[i];
            writeln!(
                w,
                "{:.6} {:.6} {:.6} {} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e} {:.6e}",
                p.x,
                p.y,
                p.z,
                vf.panel[i],
                vf.warp[i],
                vf.weft[i],
                vf.bias[i],
                vf.pressure[i],
                vf.distance[i],
                c.velocities()[i].norm()
            )?;
        }
        for t in &c.triangles {
            writeln!(w, "3 {} {} {}", t[0], t[1], t[2])?;
        }
        Ok(())
    })
}
