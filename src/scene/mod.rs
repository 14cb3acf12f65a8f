//! Scenes (`config/scenes/*.yaml`): the cloth (fabric file, size, spacing,
//! pose), obstacles, pins, gravity, time step, duration and output rate.
//! Errors name the file, the field and what is wrong.

pub mod motion;
mod overrides;
pub mod run;
pub mod shape;
pub mod system_file;

pub use overrides::{read_file, Overrides};

use crate::cloth::HingeLayout;
use crate::cloth::{Cloth, GridSpec, PanelSpec};
use crate::collision::{
    Obstacle, ShapeSpec, DEFAULT_CLOTH_THICKNESS, DEFAULT_FRICTION, DEFAULT_OBSTACLE_THICKNESS,
};
use crate::fabric::Fabric;
use crate::limits::{self, MAX_ANGULAR_SPEED, MAX_OBSTACLE_SPEED, MAX_PIN_SPEED};
use crate::solver::{Params, Pin, PinPath, Simulation};
use anyhow::{bail, Context, Result};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Orientation: either roll/pitch/yaw (rad, ROS convention: R = Rz(yaw) Ry(pitch) Rx(roll))
/// or the direction the local +z axis should point to (minimal rotation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct PoseSpec {
    #[serde(default)]
    pub position: [f64; 3],
    #[serde(default)]
    pub rpy: Option<[f64; 3]>,
    #[serde(default)]
    pub normal: Option<[f64; 3]>,
}

impl PoseSpec {
    pub fn isometry(&self, what: &str) -> Result<Isometry3<f64>> {
        let p = self.position;
        if p.iter().any(|c| !c.is_finite()) {
            bail!("{what}.position = {p:?}: must be finite");
        }
        let rot = match (self.rpy, self.normal) {
            (Some(_), Some(_)) => bail!("{what}: give either rpy or normal, not both"),
            (Some(r), None) => {
                if r.iter().any(|c| !c.is_finite()) {
                    bail!("{what}.rpy = {r:?}: must be finite");
                }
                UnitQuaternion::from_euler_angles(r[0], r[1], r[2])
            }
            (None, Some(n)) => {
                let v = Vector3::from(n);
                if !(v.norm() > 1e-12 && v.iter().all(|c| c.is_finite())) {
                    bail!("{what}.normal = {n:?}: must be a non-zero finite vector");
                }
                UnitQuaternion::rotation_between(&Vector3::z(), &v.normalize()).unwrap_or_else(
                    || UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
                )
            }
            (None, None) => UnitQuaternion::identity(),
        };
        Ok(Isometry3::from_parts(
            Translation3::new(p[0], p[1], p[2]),
            rot,
        ))
    }
}

/// Places the cloth flat on a box obstacle's top face.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlaceOn {
    /// Id of a box obstacle.
    pub obstacle: String,
    /// Where the cloth's grid corner (0, 0) lies, in the box's local x, y, m.
    pub corner: [f64; 2],
    /// Height of the cloth above the box's top face, m.
    pub gap: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClothSpec {
    /// Fabric file, relative to the scene file.
    pub fabric: String,
    /// Size along warp and weft, m.
    pub size: [f64; 2],
    /// Spacing l_c (warp) and l_t (weft), m; a single number for both.
    pub spacing: Spacing,
    /// Pose of the grid corner (0, 0); warp along local x, weft along local y.
    #[serde(default)]
    pub pose: PoseSpec,
    /// Alternative to `pose`: lay the cloth flat on a box.
    #[serde(default)]
    pub place_on: Option<PlaceOn>,
    /// Cloth thickness, m (thesis: 2 mm).
    #[serde(default = "default_cloth_thickness")]
    pub thickness: f64,
    /// Use the hysteretic parts of the laws.
    #[serde(default = "yes")]
    pub hysteresis: bool,
    /// The bending hinges: `skewed` (one per grid edge, the default) or
    /// `mirror_symmetric` (pairs that bend alike in every direction;
    /// docs/drape.md).
    #[serde(default, skip_serializing_if = "HingesFile::is_skewed")]
    pub hinges: HingesFile,
}

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum Spacing {
    Same(f64),
    WarpWeft([f64; 2]),
}

impl Spacing {
    pub fn pair(&self) -> [f64; 2] {
        match *self {
            Spacing::Same(s) => [s, s],
            Spacing::WarpWeft(p) => p,
        }
    }
}

fn default_cloth_thickness() -> f64 {
    DEFAULT_CLOTH_THICKNESS
}
fn default_obstacle_thickness() -> f64 {
    DEFAULT_OBSTACLE_THICKNESS
}
fn yes() -> bool {
    true
}
fn default_friction() -> f64 {
    DEFAULT_FRICTION
}

/// An obstacle's geometry as a scene file gives it, in its own frame:
/// the primitives of [`ShapeSpec`], or a triangle mesh from an OBJ file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeFile {
    /// Box with full side lengths, m.
    Box {
        size: [f64; 3],
    },
    Sphere {
        radius: f64,
    },
    /// Capsule: cylinder of `length` between the centres of its end caps.
    Capsule {
        length: f64,
        radius: f64,
    },
    Cylinder {
        height: f64,
        radius: f64,
    },
    Cone {
        height: f64,
        radius: f64,
    },
    /// Triangle mesh from an OBJ file (path relative to the scene file), with
    /// an optional uniform scale.
    Mesh {
        obj: String,
        #[serde(default = "one")]
        scale: f64,
    },
}

fn one() -> f64 {
    1.0
}

impl ShapeFile {
    /// The geometry, with an OBJ mesh read (relative to `base`) and scaled.
    pub fn resolve(&self, id: &str, base: &Path) -> Result<ShapeSpec> {
        Ok(match *self {
            ShapeFile::Box { size } => ShapeSpec::Box { size },
            ShapeFile::Sphere { radius } => ShapeSpec::Sphere { radius },
            ShapeFile::Capsule { length, radius } => ShapeSpec::Capsule { length, radius },
            ShapeFile::Cylinder { height, radius } => ShapeSpec::Cylinder { height, radius },
            ShapeFile::Cone { height, radius } => ShapeSpec::Cone { height, radius },
            ShapeFile::Mesh { ref obj, scale } => {
                if !(scale.is_finite() && scale > 0.0) {
                    bail!("obstacle {id:?}: scale = {scale}: must be > 0 m");
                }
                let (v, t) = crate::io::load_obj(&base.join(obj))
                    .with_context(|| format!("obstacle {id:?}"))?;
                let vertices = v
                    .iter()
                    .map(|p| [p[0] * scale, p[1] * scale, p[2] * scale])
                    .collect();
                ShapeSpec::Triangles {
                    vertices,
                    triangles: t,
                }
            }
        })
    }
}

/// A body motion read from files (docs/bodies.md): a mesh per frame
/// (`frames` and `fps`) or a glTF 2.0 skinned animation (`gltf`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionFile {
    /// The frames' mesh files (OBJ or ASCII PLY, one topology), relative to
    /// the scene file: a pattern with one `*` in the file name
    /// (`walk/frame_*.obj`, in the order of the numbers it stands for), or
    /// a list of files.
    #[serde(default)]
    pub frames: Option<FrameFiles>,
    /// Frames per second of `frames`.
    #[serde(default)]
    pub fps: Option<f64>,
    /// A glTF 2.0 file (`.gltf` or `.glb`), relative to the scene file.
    #[serde(default)]
    pub gltf: Option<String>,
    /// The glTF animation to play: its name or index (default: the first).
    #[serde(default)]
    pub animation: Option<String>,
    /// Metres per file unit.
    #[serde(default = "one")]
    pub scale: f64,
    /// Play the motion over and over (its last frame should be its first).
    #[serde(default, rename = "loop")]
    pub looping: bool,
    /// Scene time at which the motion starts, s; until then the body holds
    /// its first pose, after its end its last.
    #[serde(default)]
    pub start: f64,
}

/// Frame files: a pattern with one `*`, or a list.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum FrameFiles {
    Pattern(String),
    List(Vec<String>),
}

impl MotionFile {
    /// Reads the motion (paths relative to `base`).
    pub fn load(&self, base: &Path) -> Result<crate::scene::motion::LoadedMotion> {
        match (&self.frames, &self.gltf) {
            (Some(f), None) => {
                let Some(fps) = self.fps else {
                    bail!("motion.frames needs motion.fps (frames per second)");
                };
                let files = match f {
                    FrameFiles::Pattern(p) => crate::scene::motion::expand_pattern(&base.join(p))?,
                    FrameFiles::List(l) => l.iter().map(|p| base.join(p)).collect(),
                };
                crate::scene::motion::load_frames(&files, fps, self.scale)
            }
            (None, Some(g)) => {
                if self.fps.is_some() {
                    bail!("motion.fps is for frames; a glTF animation has its own times");
                }
                let (triangles, skinned) = crate::scene::motion::load_gltf(
                    &base.join(g),
                    self.animation.as_deref(),
                    self.scale,
                )?;
                Ok(crate::scene::motion::LoadedMotion {
                    triangles,
                    motion: std::sync::Arc::new(skinned),
                })
            }
            _ => bail!("motion: give either frames (with fps) or gltf"),
        }
    }
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    pub id: String,
    /// The geometry; none for an obstacle with a `motion`, whose meshes it is.
    #[serde(default)]
    pub shape: Option<ShapeFile>,
    /// Moves the vertices of a body mesh (docs/bodies.md).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion: Option<MotionFile>,
    #[serde(default)]
    pub pose: PoseSpec,
    #[serde(default = "default_obstacle_thickness")]
    pub thickness: f64,
    /// Coulomb friction coefficient.
    #[serde(default = "default_friction")]
    pub friction: f64,
    /// m/s
    #[serde(default)]
    pub linear_velocity: [f64; 3],
    /// rad/s about the obstacle's origin.
    #[serde(default)]
    pub angular_velocity: [f64; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Waypoint {
    pub t: f64,
    pub position: [f64; 3],
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PinSpec {
    /// Grid index (i along warp, j along weft).
    #[serde(default)]
    pub grid: Option<[usize; 2]>,
    /// Or a vertex index (grid order).
    #[serde(default)]
    pub vertex: Option<usize>,
    /// Target point (default: where the vertex starts).
    #[serde(default)]
    pub target: Option<[f64; 3]>,
    /// Constant target velocity, m/s.
    #[serde(default)]
    pub velocity: Option<[f64; 3]>,
    /// Piecewise-linear target path.
    #[serde(default)]
    pub path: Option<Vec<Waypoint>>,
    /// Time at which the pin lets go, s.
    #[serde(default)]
    pub release_at: Option<f64>,
}

/// A scene file. Its run's settings (`dt`, `duration`, `solver`,
/// `cg_tolerance`, `threads`, `self_collision`, `obstacle_edges`,
/// `cell_shear`) are an [`Overrides`] flattened into it, the command line's
/// over them; `dt` and `duration` are required. Read with
/// [`SceneFile::parse`], which refuses an unknown key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneFile {
    #[serde(default)]
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub cloth: ClothSpec,
    #[serde(default)]
    pub obstacles: Vec<ObstacleSpec>,
    #[serde(default)]
    pub pins: Vec<PinSpec>,
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    /// Rate of energy rows and recorded frames, Hz.
    #[serde(default = "default_output_rate")]
    pub output_rate: f64,
    /// A run counts as settled once the rms speed stays below this, m/s.
    #[serde(default = "default_settle_speed")]
    pub settle_speed: f64,
    /// The run's settings: the fixed time step `dt` (s) and the simulated
    /// `duration` (s); the linear `solver` and its `cg_tolerance` (in
    /// (0, 1), default 1e-6: docs/benchmarks.md, "The stopping test and the
    /// final shape"); `threads`; `self_collision` (the cloth kept from
    /// passing through itself), `obstacle_edges` (triangle-mesh obstacles'
    /// vertices and edges meet the cloth's triangles and edges too:
    /// docs/self_collision.md) and `cell_shear` (each cell's shear from both
    /// its diagonals, with the egg-crate guards: docs/lab.md; off: each
    /// diagonal alone, thesis eq. 4.34). At the file's top level, read by
    /// [`SceneFile::parse`].
    #[serde(skip)]
    pub run: Overrides,
}

impl SceneFile {
    /// The file's own keys (besides its settings').
    const KEYS: [&'static str; 8] = [
        "name",
        "description",
        "cloth",
        "obstacles",
        "pins",
        "gravity",
        "output_rate",
        "settle_speed",
    ];

    /// Reads a scene file's text (`what` names it in the errors).
    pub fn parse(text: &str, what: &str) -> Result<SceneFile> {
        let (file, run) = overrides::read_file(
            text,
            what,
            &SceneFile::KEYS,
            &[
                ("spacing", "a scene's grid spacing is `cloth.spacing`"),
                ("hinges", "a scene's hinges are `cloth.hinges`"),
                ("hysteresis", "a scene's hysteresis is `cloth.hysteresis`"),
                ("max_time", "not for a scene (a scene runs for `duration`)"),
            ],
        )?;
        for (key, v, what_it_is) in [
            ("dt", run.dt, "the fixed time step, s"),
            ("duration", run.duration, "the simulated time, s"),
        ] {
            if v.is_none() {
                bail!("{what}: {key}: missing ({what_it_is})");
            }
        }
        Ok(SceneFile { run, ..file })
    }

    /// The fixed time step, s (0 when absent: refused by [`Scene::from_file`]).
    pub fn dt(&self) -> f64 {
        self.run.dt.unwrap_or(0.0)
    }

    /// The simulated duration, s (0 when absent: refused by [`Scene::from_file`]).
    pub fn duration(&self) -> f64 {
        self.run.duration.unwrap_or(0.0)
    }
}

fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}
fn default_output_rate() -> f64 {
    30.0
}
fn default_settle_speed() -> f64 {
    0.005
}

/// A loaded scene: the file, where it came from, and the fabric.
#[derive(Debug, Clone)]
pub struct Scene {
    pub file: SceneFile,
    pub path: PathBuf,
    pub fabric: Fabric,
}

impl Scene {
    pub fn load(path: &Path) -> Result<Scene> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read scene file {}", path.display()))?;
        let file = SceneFile::parse(&text, &format!("scene file {}", path.display()))?;
        Scene::from_file(file, path)
    }

    /// The fabric file a scene file names (relative to the scene file's folder).
    pub fn fabric_path_of(file: &SceneFile, path: &Path) -> PathBuf {
        path.parent()
            .map(Path::to_path_buf)
            .unwrap_or_default()
            .join(&file.cloth.fabric)
    }

    /// This scene's fabric file.
    pub fn fabric_path(&self) -> PathBuf {
        Scene::fabric_path_of(&self.file, &self.path)
    }

    pub fn from_file(file: SceneFile, path: &Path) -> Result<Scene> {
        let fpath = Scene::fabric_path_of(&file, path);
        let fabric = crate::io::load_fabric(&fpath)
            .with_context(|| format!("scene file {}: cloth.fabric", path.display()))?;
        let s = Scene {
            file,
            path: path.to_path_buf(),
            fabric,
        };
        s.validate()
            .with_context(|| format!("scene file {}", path.display()))?;
        Ok(s)
    }

    fn validate(&self) -> Result<()> {
        let f = &self.file;
        let pos = |n: &str, v: f64| -> Result<()> {
            if !(v.is_finite() && v > 0.0) {
                bail!("{n} = {v}: must be a finite number > 0");
            }
            Ok(())
        };
        let Some(dt) = f.run.dt else {
            bail!("dt: missing (the fixed time step, s)");
        };
        pos("dt", dt)?;
        limits::check_dt("dt", dt)?;
        if let Some(t) = f.run.cg_tolerance {
            limits::check_cg_tolerance("cg_tolerance", t)?;
        }
        let Some(duration) = f.run.duration else {
            bail!("duration: missing (the simulated time, s)");
        };
        if !(duration.is_finite() && duration >= 0.0) {
            bail!("duration = {duration}: must be ≥ 0 s");
        }
        pos("output_rate", f.output_rate)?;
        pos("settle_speed", f.settle_speed)?;
        limits::check_cloth_grid(
            "cloth.size",
            f.cloth.size,
            "cloth.spacing",
            f.cloth.spacing.pair(),
        )?;
        pos("cloth.thickness", f.cloth.thickness)?;
        let (lo, hi) = limits::CLOTH_THICKNESS;
        limits::check_range(
            "cloth.thickness",
            f.cloth.thickness,
            lo,
            hi,
            "m",
            "CLOTH_THICKNESS: a film to a quilt",
        )?;
        if f.gravity.iter().any(|g| !g.is_finite()) {
            bail!("gravity = {:?}: must be finite", f.gravity);
        }
        let mut ids = std::collections::HashSet::new();
        for (k, o) in f.obstacles.iter().enumerate() {
            if !ids.insert(o.id.as_str()) {
                bail!("obstacles[{k}].id = {:?}: duplicate id", o.id);
            }
            limits::check_speed(
                &format!("obstacles[{k}].linear_velocity"),
                &Vector3::from(o.linear_velocity),
                MAX_OBSTACLE_SPEED,
                "m/s",
            )?;
            limits::check_speed(
                &format!("obstacles[{k}].angular_velocity"),
                &Vector3::from(o.angular_velocity),
                MAX_ANGULAR_SPEED,
                "rad/s",
            )?;
        }
        for (k, p) in f.pins.iter().enumerate() {
            if p.grid.is_some() == p.vertex.is_some() {
                bail!("pins[{k}]: give exactly one of grid or vertex");
            }
            if [p.target.is_some(), p.velocity.is_some(), p.path.is_some()]
                .iter()
                .filter(|b| **b)
                .count()
                > 1
                && !(p.target.is_some() && p.velocity.is_some() && p.path.is_none())
            {
                bail!("pins[{k}]: give target (optionally with velocity) or path, not both");
            }
        }
        Ok(())
    }

    /// The scene file's name, the context of its errors.
    fn ctx(&self) -> String {
        format!("scene file {}", self.path.display())
    }

    /// The obstacles, their shapes or motions read relative to the scene
    /// file's directory.
    fn build_obstacles(&self) -> Result<Vec<Obstacle>> {
        let f = &self.file;
        let base = self
            .path
            .parent()
            .map(Path::to_path_buf)
            .unwrap_or_default();
        let ctx = || self.ctx();
        let mut obstacles = Vec::new();
        for (k, o) in f.obstacles.iter().enumerate() {
            let pose = o
                .pose
                .isometry(&format!("obstacles[{k}].pose"))
                .with_context(ctx)?;
            let mut ob = match (&o.shape, &o.motion) {
                (Some(shape), None) => shape.resolve(&o.id, &base).and_then(|shape| {
                    Ok(Obstacle::new(&o.id, shape, pose, o.thickness, o.friction)?)
                }),
                (None, Some(m)) => m.load(&base).and_then(|l| {
                    Ok(Obstacle::with_motion(
                        &o.id,
                        l.triangles,
                        l.motion,
                        m.looping,
                        m.start,
                        pose,
                        o.thickness,
                        o.friction,
                    )?)
                }),
                _ => Err(anyhow::anyhow!(
                    "give a shape, or a motion (whose meshes are the shape), not both"
                )),
            }
            .with_context(|| format!("obstacles[{k}]"))
            .with_context(ctx)?;
            ob.linear_velocity = Vector3::from(o.linear_velocity);
            ob.angular_velocity = Vector3::from(o.angular_velocity);
            obstacles.push(ob);
        }
        Ok(obstacles)
    }

    /// The cloth's pose: on the box `cloth.place_on` names, else
    /// `cloth.pose`.
    fn cloth_pose(&self, obstacles: &[Obstacle]) -> Result<Isometry3<f64>> {
        let f = &self.file;
        let ctx = || self.ctx();
        Ok(match &f.cloth.place_on {
            Some(p) => {
                let ob = obstacles
                    .iter()
                    .find(|o| o.id == p.obstacle)
                    .with_context(|| {
                        format!(
                            "cloth.place_on.obstacle = {:?}: no obstacle with that id",
                            p.obstacle
                        )
                    })
                    .with_context(ctx)?;
                let ShapeSpec::Box { size } = ob.spec else {
                    bail!(
                        "{}: cloth.place_on.obstacle {:?} must be a box",
                        ctx(),
                        p.obstacle
                    );
                };
                ob.pose * Translation3::new(p.corner[0], p.corner[1], size[2] / 2.0 + p.gap)
            }
            None => f.cloth.pose.isometry("cloth.pose").with_context(ctx)?,
        })
    }

    /// The cloth at `cloth_pose` (its grid's size, spacing and memory
    /// checked), with the run's hinges.
    fn build_cloth(&self, ov: &Overrides, cloth_pose: Isometry3<f64>) -> Result<Cloth> {
        let f = &self.file;
        let ctx = || self.ctx();
        let spacing = ov.spacing.map(|s| [s, s]).unwrap_or(f.cloth.spacing.pair());
        let grid = GridSpec {
            size: f.cloth.size,
            spacing,
            pose: cloth_pose,
        };
        if grid
            .size
            .iter()
            .chain(&grid.spacing)
            .all(|v| v.is_finite() && *v > 0.0)
        {
            let (nx, ny) = grid.dims();
            limits::check_memory(nx, ny, crate::io::available_memory()).with_context(ctx)?;
        }
        // the spacing the command line gives, and the cells of either
        let spacing_field = if ov.spacing.is_some() {
            "--spacing"
        } else {
            "cloth.spacing"
        };
        limits::check_cloth_grid("cloth.size", grid.size, spacing_field, grid.spacing)
            .with_context(ctx)?;
        Cloth::panel(&PanelSpec {
            hinges: self.hinges(ov).layout(),
            ..PanelSpec::rectangle(&grid, self.fabric.areal_mass)
        })
        .with_context(ctx)
    }

    /// The pins, each checked against the cloth (vertex, reach, speed,
    /// waypoint times, release time).
    fn build_pins(&self, cloth: &Cloth) -> Result<Vec<Pin>> {
        let ctx = || self.ctx();
        let mut pins = Vec::new();
        for (k, p) in self.file.pins.iter().enumerate() {
            let vertex = match (p.grid, p.vertex) {
                (Some([i, j]), _) => cloth
                    .index(i, j)
                    .with_context(|| format!("pins[{k}].grid"))
                    .with_context(ctx)?,
                (_, Some(v)) => {
                    if v >= cloth.len() {
                        bail!(
                            "{}: pins[{k}].vertex = {v}: the cloth has {} vertices",
                            ctx(),
                            cloth.len()
                        );
                    }
                    v
                }
                _ => unreachable!("validated"),
            };
            let start = p
                .target
                .map(Vector3::from)
                .unwrap_or(cloth.positions()[vertex]);
            limits::check_reach(&format!("pins[{k}].target"), &start, cloth.positions())
                .with_context(ctx)?;
            if let Some(v) = p.velocity {
                limits::check_speed(
                    &format!("pins[{k}].velocity"),
                    &Vector3::from(v),
                    MAX_PIN_SPEED,
                    "m/s",
                )
                .with_context(ctx)?;
            }
            let path = self.pin_path(k, p, start, cloth)?;
            if let Some(r) = p.release_at {
                if !(r.is_finite() && r >= 0.0) {
                    bail!(
                        "{}: pins[{k}].release_at = {r}: must be a time ≥ 0 s",
                        ctx()
                    );
                }
            }
            pins.push(Pin {
                vertex,
                path,
                release_at: p.release_at,
            });
        }
        Ok(pins)
    }

    /// Pin `k`'s path: its waypoints (checked: finite increasing times,
    /// positions in reach, speeds between them), a constant velocity from
    /// `start`, or fixed at `start`.
    fn pin_path(
        &self,
        k: usize,
        p: &PinSpec,
        start: Vector3<f64>,
        cloth: &Cloth,
    ) -> Result<PinPath> {
        let ctx = || self.ctx();
        Ok(match (&p.path, p.velocity) {
            (Some(w), _) => {
                if w.is_empty() {
                    bail!("{}: pins[{k}].path is empty", ctx());
                }
                for (q, w) in w.iter().enumerate() {
                    if !w.t.is_finite() {
                        bail!("{}: pins[{k}].path[{q}].t = {}: must be finite", ctx(), w.t);
                    }
                    limits::check_reach(
                        &format!("pins[{k}].path[{q}].position"),
                        &Vector3::from(w.position),
                        cloth.positions(),
                    )
                    .with_context(ctx)?;
                }
                for (q, pair) in w.windows(2).enumerate() {
                    if pair[1].t <= pair[0].t {
                        bail!("{}: pins[{k}].path: waypoint times must increase", ctx());
                    }
                    let v = (Vector3::from(pair[1].position) - Vector3::from(pair[0].position))
                        / (pair[1].t - pair[0].t);
                    limits::check_speed(
                        &format!("pins[{k}].path[{q}..{}] speed", q + 1),
                        &v,
                        MAX_PIN_SPEED,
                        "m/s",
                    )
                    .with_context(ctx)?;
                }
                PinPath::Waypoints(w.iter().map(|w| (w.t, Vector3::from(w.position))).collect())
            }
            (None, Some(v)) => PinPath::Velocity {
                start,
                velocity: Vector3::from(v),
                t0: 0.0,
            },
            (None, None) => PinPath::Fixed(start),
        })
    }

    /// Builds the simulation (applying command-line overrides).
    pub fn build(&self, ov: &Overrides) -> Result<Simulation> {
        ov.check()?;
        ov.check_for_scene()?;
        let f = &self.file;
        let ctx = || self.ctx();
        let obstacles = self.build_obstacles()?;
        let cloth_pose = self.cloth_pose(&obstacles)?;
        let cloth = self.build_cloth(ov, cloth_pose)?;
        // the obstacles lie within reach of the cloth (as a message's must),
        // and the cloth starts outside them (meshes may be open, with no
        // inside: not checked)
        for (k, ob) in obstacles.iter().enumerate() {
            limits::check_reach(
                &format!("obstacles[{k}] ({:?}) pose.position", ob.id),
                &ob.pose.translation.vector,
                cloth.positions(),
            )
            .with_context(ctx)?;
            ob.check_overlap(cloth.positions())
                .with_context(|| format!("obstacles[{k}]"))
                .with_context(ctx)?;
        }
        let params = ov.or(&f.run).apply(Params {
            gravity: Vector3::from(f.gravity),
            cloth_thickness: f.cloth.thickness,
            hysteresis: f.cloth.hysteresis,
            ..Params::default()
        });
        let pins = self.build_pins(&cloth)?;
        let mut sim = Simulation::new(cloth, self.fabric.clone(), params).with_context(ctx)?;
        sim.set_obstacles(obstacles.into_iter().collect());
        sim.set_pins(pins)?;
        Ok(sim)
    }

    pub fn duration(&self, ov: &Overrides) -> f64 {
        ov.duration.unwrap_or(self.file.duration())
    }

    /// The hinge layout of a run with `ov`.
    pub fn hinges(&self, ov: &Overrides) -> HingesFile {
        ov.hinges.unwrap_or(self.file.cloth.hinges)
    }
}

/// `hinges:` of a garment or scene file, `--hinges` of `drape`: how each
/// panel's bending hinges are laid out ([`HingeLayout`]).
#[derive(Debug, Clone, Copy, Deserialize, Serialize, Default, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum HingesFile {
    #[default]
    Skewed,
    MirrorSymmetric,
}

impl HingesFile {
    /// As written in a file: `skewed` or `mirror_symmetric`.
    pub fn name(self) -> &'static str {
        match self {
            HingesFile::Skewed => "skewed",
            HingesFile::MirrorSymmetric => "mirror_symmetric",
        }
    }

    pub fn is_skewed(&self) -> bool {
        *self == HingesFile::Skewed
    }

    pub fn layout(self) -> HingeLayout {
        match self {
            HingesFile::Skewed => HingeLayout::Skewed,
            HingesFile::MirrorSymmetric => HingeLayout::MirrorSymmetric,
        }
    }
}

impl std::str::FromStr for HingesFile {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "skewed" => Ok(HingesFile::Skewed),
            "mirror_symmetric" | "mirror-symmetric" => Ok(HingesFile::MirrorSymmetric),
            _ => Err(format!(
                "unknown hinge layout {s:?}: expected skewed or mirror_symmetric"
            )),
        }
    }
}
