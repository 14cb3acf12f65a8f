//! The node's parameters, in one table ([`PARAMETERS`]): name, ROS type,
//! default, whether it can change while the node runs, and what it does. The
//! declarations, `-p` and params-file parsing, the parameter services'
//! validation, the runtime updates, `node --help` and the table of
//! `docs/ros.md` (checked by a test) all come from it.

use super::args::{self, RosArgs, Value};
use crate::scene::Overrides;
use crate::solver::{LinearSolverKind, MAX_THREADS};
use anyhow::{bail, Context as _, Result};
use ros2_client::ParameterValue;
use std::path::Path;

/// The node's settings: one field per parameter of [`PARAMETERS`].
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    pub scene: String,
    pub frame_id: String,
    pub publish_rate: f64,
    pub real_time_factor: f64,
    pub paused: bool,
    pub duration: f64,
    pub dt: f64,
    pub spacing: f64,
    pub solver: String,
    /// The PCG's relative tolerance (0: the scene's or trial's, else 1e-6).
    pub cg_tolerance: f64,
    pub threads: i64,
    pub record_bag: String,
    pub foxglove: String,
    pub max_messages_per_step: i64,
    pub max_mesh_triangles: i64,
    /// Contact thickness (m) and friction of the bodies streamed on `body_mesh`.
    pub body_mesh_thickness: f64,
    pub body_mesh_friction: f64,
    /// `None`: the scene's or trial's own `self_collision`.
    pub self_collision: Option<bool>,
    /// `None`: the scene's or trial's own `obstacle_edges`.
    pub obstacle_edges: Option<bool>,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            scene: default_scene(),
            frame_id: "world".into(),
            publish_rate: 30.0,
            real_time_factor: 1.0,
            paused: false,
            duration: 0.0,
            dt: 0.0,
            spacing: 0.0,
            solver: String::new(),
            cg_tolerance: 0.0,
            threads: 1,
            record_bag: String::new(),
            foxglove: String::new(),
            max_messages_per_step: 100,
            max_mesh_triangles: 200_000,
            body_mesh_thickness: crate::collision::DEFAULT_OBSTACLE_THICKNESS,
            body_mesh_friction: crate::collision::DEFAULT_FRICTION,
            self_collision: None,
            obstacle_edges: None,
        }
    }
}

/// The shipped example `config/scenes/table_drape.yaml`: from the working
/// directory, else beside the executable or in one of its parent folders
/// (`target/release/garment_sim` in a checkout), else in `share/garment_sim`
/// of one of them (an installed binary); the relative path if none has it
/// (loading it then fails naming that path). Never the folder the binary
/// was built in: a binary copied elsewhere finds the scene shipped with it.
fn default_scene() -> String {
    let exe = std::env::current_exe().ok();
    find_default_scene(Path::new("."), exe.as_deref())
        .map(|p| p.display().to_string())
        .unwrap_or_else(|| DEFAULT_SCENE.into())
}

const DEFAULT_SCENE: &str = "config/scenes/table_drape.yaml";

fn find_default_scene(cwd: &Path, exe: Option<&Path>) -> Option<std::path::PathBuf> {
    let here = cwd.join(DEFAULT_SCENE);
    if here.is_file() {
        return Some(if cwd == Path::new(".") {
            DEFAULT_SCENE.into()
        } else {
            here
        });
    }
    let dir = exe?.parent()?;
    dir.ancestors().take(4).find_map(|a| {
        [
            a.join(DEFAULT_SCENE),
            a.join("share/garment_sim").join(DEFAULT_SCENE),
        ]
        .into_iter()
        .find(|p| p.is_file())
    })
}

/// A parameter's ROS 2 type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Bool,
    Integer,
    Double,
    String,
    /// `true`, `false` or empty (the scene's own setting): a string in ROS,
    /// set from one of those three strings or, on the command line and in
    /// params files, from a bool (`-p NAME:=true`, `NAME: false`).
    Switch,
}

impl Kind {
    pub fn name(self) -> &'static str {
        match self {
            Kind::Bool => "bool",
            Kind::Integer => "integer",
            Kind::Double => "double",
            Kind::String | Kind::Switch => "string",
        }
    }
}

/// One parameter of the node.
pub struct Parameter {
    pub name: &'static str,
    pub kind: Kind,
    /// Can be changed while the node runs (the parameter services); the
    /// others are read at start (`scene` also on `~/reset`).
    pub runtime: bool,
    pub description: &'static str,
    get: fn(&Settings) -> Value,
    /// Stores a value already converted to `kind`, or says which rule it
    /// breaks.
    put: fn(&mut Settings, Value) -> std::result::Result<(), String>,
}

impl Parameter {
    /// The parameter's value in `s`.
    pub fn get(&self, s: &Settings) -> Value {
        (self.get)(s)
    }

    /// Sets it in `s` from a value of any type that converts to its own (an
    /// integer where a double or a string is expected); wrong types and out-of-range
    /// values are errors that name the parameter.
    pub fn set(&self, s: &mut Settings, v: &Value) -> Result<()> {
        let name = self.name;
        let v = match (self.kind, v) {
            (Kind::Bool, Value::Bool(_))
            | (Kind::Integer, Value::Int(_))
            | (Kind::Double, Value::Double(_))
            | (Kind::String, Value::Str(_)) => v.clone(),
            (Kind::Double, Value::Int(i)) => Value::Double(*i as f64),
            // `-p foxglove:=8765` reads as a YAML integer
            (Kind::String, Value::Int(i)) => Value::Str(i.to_string()),
            (Kind::Switch, Value::Bool(b)) => Value::Str(b.to_string()),
            (Kind::Switch, Value::Str(_)) => v.clone(),
            (k, other) => bail!("parameter {name}: {other:?} is not a {}", k.name()),
        };
        let shown = match &v {
            Value::Str(t) => format!("{t:?}"),
            Value::Double(d) => d.to_string(),
            other => shown(other),
        };
        (self.put)(s, v).map_err(|rule| anyhow::anyhow!("parameter {name} = {shown}: {rule}"))
    }

    /// Its declaration for ros2-client.
    pub fn declared(&self, s: &Settings) -> ParameterValue {
        match self.get(s) {
            Value::Bool(b) => ParameterValue::Boolean(b),
            Value::Int(i) => ParameterValue::Integer(i),
            Value::Double(d) => ParameterValue::Double(d),
            Value::Str(t) => ParameterValue::String(t),
        }
    }
}

fn double(v: Value) -> f64 {
    match v {
        Value::Double(d) => d,
        _ => unreachable!("converted by Parameter::set"),
    }
}

fn int(v: Value) -> i64 {
    match v {
        Value::Int(i) => i,
        _ => unreachable!("converted by Parameter::set"),
    }
}

fn text(v: Value) -> String {
    match v {
        Value::Str(s) => s,
        _ => unreachable!("converted by Parameter::set"),
    }
}

fn boolean(v: Value) -> bool {
    match v {
        Value::Bool(b) => b,
        _ => unreachable!("converted by Parameter::set"),
    }
}

/// A finite double ≥ 0 (`positive`: > 0), else `rule`.
fn nonneg(v: Value, positive: bool, rule: &str) -> std::result::Result<f64, String> {
    let d = double(v);
    if !(d.is_finite() && (d > 0.0 || (!positive && d == 0.0))) {
        return Err(rule.into());
    }
    Ok(d)
}

/// Every parameter of the node, in the order `list_parameters` gives them.
pub const PARAMETERS: &[Parameter] = &[
    Parameter {
        name: "scene",
        kind: Kind::String,
        runtime: false,
        description: "scene file, or a garment trial file (sewn before the first step), read \
                      at start and on `~/reset` (a new value takes effect at the next reset); \
                      the default is taken from the working directory, else from the source \
                      tree the binary was built from",
        get: |s| Value::Str(s.scene.clone()),
        put: |s, v| {
            s.scene = text(v);
            Ok(())
        },
    },
    Parameter {
        name: "frame_id",
        kind: Kind::String,
        runtime: true,
        description: "frame of everything published; messages in another frame are refused \
                      (no TF); not empty",
        get: |s| Value::Str(s.frame_id.clone()),
        put: |s, v| {
            let f = text(v);
            if f.is_empty() {
                return Err("must not be empty".into());
            }
            s.frame_id = f;
            Ok(())
        },
    },
    Parameter {
        name: "publish_rate",
        kind: Kind::Double,
        runtime: true,
        description: "Hz of simulated time; > 0",
        get: |s| Value::Double(s.publish_rate),
        put: |s, v| {
            s.publish_rate = nonneg(v, true, "must be > 0 Hz")?;
            Ok(())
        },
    },
    Parameter {
        name: "real_time_factor",
        kind: Kind::Double,
        runtime: true,
        description: "1 paces with the wall clock, 0 runs as fast as it can; ≥ 0",
        get: |s| Value::Double(s.real_time_factor),
        put: |s, v| {
            s.real_time_factor = nonneg(v, false, "must be ≥ 0 (0: as fast as possible)")?;
            Ok(())
        },
    },
    Parameter {
        name: "paused",
        kind: Kind::Bool,
        runtime: true,
        description: "pauses the simulation (also `~/set_paused`)",
        get: |s| Value::Bool(s.paused),
        put: |s, v| {
            s.paused = boolean(v);
            Ok(())
        },
    },
    Parameter {
        name: "duration",
        kind: Kind::Double,
        runtime: false,
        description: "simulated seconds after which the node exits (0: never)",
        get: |s| Value::Double(s.duration),
        put: |s, v| {
            s.duration = nonneg(v, false, "must be ≥ 0 s (0: run until stopped)")?;
            Ok(())
        },
    },
    Parameter {
        name: "dt",
        kind: Kind::Double,
        runtime: false,
        description: "time step override, s (0: the scene's)",
        get: |s| Value::Double(s.dt),
        put: |s, v| {
            s.dt = nonneg(v, false, "must be > 0 s (0: the scene's)")?;
            Ok(())
        },
    },
    Parameter {
        name: "spacing",
        kind: Kind::Double,
        runtime: false,
        description: "grid spacing override, m (0: the scene's)",
        get: |s| Value::Double(s.spacing),
        put: |s, v| {
            s.spacing = nonneg(v, false, "must be > 0 m (0: the scene's)")?;
            Ok(())
        },
    },
    Parameter {
        name: "solver",
        kind: Kind::String,
        runtime: false,
        description: "linear solver override: `auto`, `pcg`, `sgs`, `amg` or `cholesky` (empty: the \
                      scene's or trial's)",
        get: |s| Value::Str(s.solver.clone()),
        put: |s, v| {
            let k = text(v);
            if !k.is_empty() {
                k.parse::<LinearSolverKind>().map_err(|e| e.to_string())?;
            }
            s.solver = k;
            Ok(())
        },
    },
    Parameter {
        name: "cg_tolerance",
        kind: Kind::Double,
        runtime: false,
        description: "the PCG's relative tolerance override, in (0, 1) (0: the scene's or \
                      trial's, else 1e-6; 1e-2 is Blender's own, docs/benchmarks.md)",
        get: |s| Value::Double(s.cg_tolerance),
        put: |s, v| {
            const RULE: &str = "must be in (0, 1) (0: the scene's)";
            let d = nonneg(v, false, RULE)?;
            if d >= 1.0 {
                return Err(RULE.into());
            }
            s.cg_tolerance = d;
            Ok(())
        },
    },
    Parameter {
        name: "threads",
        kind: Kind::Integer,
        runtime: false,
        description: "threads of the assembly, the PCG and the contacts, 0 to 64 (default 1: \
                      the other cores left to the machine's other nodes; a thread whose core \
                      another process takes leaves its share to the node's main thread, so a \
                      busy core slows the node to about one core's speed, not below; 0: one \
                      per core from 500 vertices, for a machine of its own; they sleep between \
                      steps)",
        get: |s| Value::Int(s.threads),
        put: |s, v| {
            let k = int(v);
            if !(0..=MAX_THREADS as i64).contains(&k) {
                return Err(format!("0 (one per core) to {MAX_THREADS}"));
            }
            s.threads = k;
            Ok(())
        },
    },
    Parameter {
        name: "record_bag",
        kind: Kind::String,
        runtime: false,
        description: "bag directory to record everything published into, at `publish_rate` \
                      ([bags.md](bags.md)); must not exist (empty: no recording)",
        get: |s| Value::Str(s.record_bag.clone()),
        put: |s, v| {
            s.record_bag = text(v);
            Ok(())
        },
    },
    Parameter {
        name: "foxglove",
        kind: Kind::String,
        runtime: false,
        description: "serves what the node publishes to Foxglove over its WebSocket protocol \
                      on `ADDR:PORT`, or `PORT` on 127.0.0.1 (empty: no live view; \
                      [drape.md](drape.md#live-view-in-foxglove))",
        get: |s| Value::Str(s.foxglove.clone()),
        put: |s, v| {
            let a = text(v);
            if !a.is_empty() {
                crate::live::parse_addr(&a).map_err(|e| e.to_string())?;
            }
            s.foxglove = a;
            Ok(())
        },
    },
    Parameter {
        name: "max_messages_per_step",
        kind: Kind::Integer,
        runtime: true,
        description: "messages applied per topic between two steps; more are dropped, logged \
                      and counted (`dropped_messages`); ≥ 1",
        get: |s| Value::Int(s.max_messages_per_step),
        put: |s, v| {
            let k = int(v);
            if k < 1 {
                return Err("must be ≥ 1".into());
            }
            s.max_messages_per_step = k;
            Ok(())
        },
    },
    Parameter {
        name: "max_mesh_triangles",
        kind: Kind::Integer,
        runtime: true,
        description: "largest obstacle mesh accepted, triangles; ≥ 1, at most 2 000 000",
        get: |s| Value::Int(s.max_mesh_triangles),
        put: |s, v| {
            let k = int(v);
            if k < 1 {
                return Err("must be ≥ 1".into());
            }
            s.max_mesh_triangles = k.min(crate::collision::MAX_MESH_TRIANGLES as i64);
            Ok(())
        },
    },
    Parameter {
        name: "body_mesh_thickness",
        kind: Kind::Double,
        runtime: false,
        description: "contact thickness of the bodies streamed on `body_mesh` \
                      (mesh_msgs/MeshGeometryStamped carries none), m; > 0",
        get: |s| Value::Double(s.body_mesh_thickness),
        put: |s, v| {
            s.body_mesh_thickness = nonneg(v, true, "must be > 0 m")?;
            Ok(())
        },
    },
    Parameter {
        name: "body_mesh_friction",
        kind: Kind::Double,
        runtime: false,
        description: "Coulomb friction coefficient of the bodies streamed on `body_mesh`; ≥ 0",
        get: |s| Value::Double(s.body_mesh_friction),
        put: |s, v| {
            s.body_mesh_friction = nonneg(v, false, "must be ≥ 0")?;
            Ok(())
        },
    },
    Parameter {
        name: "self_collision",
        kind: Kind::Switch,
        runtime: false,
        description:
            "keeps the cloth from passing through itself ([self_collision.md](self_collision.md)): \
                      `true` or `false`, empty for the scene's or trial's own `self_collision` \
                      (the shipped skirt trial has it on); a string (`-p` and params files \
                      also take a bool); read at start and on `~/reset`",
        get: |s| switch_value(s.self_collision),
        put: |s, v| {
            s.self_collision = switch(v)?;
            Ok(())
        },
    },
    Parameter {
        name: "obstacle_edges",
        kind: Kind::Switch,
        runtime: false,
        description:
            "the triangle-mesh obstacles' vertices and edges (bodies) meet the cloth's triangles \
                      and edges too, so that a part thinner than the cloth's spacing cannot pass \
                      between its vertices ([self_collision.md](self_collision.md)): `true` or \
                      `false`, empty for the scene's or trial's own `obstacle_edges` (off in the \
                      shipped files); a string like `self_collision`; read at start and on `~/reset`",
        get: |s| switch_value(s.obstacle_edges),
        put: |s, v| {
            s.obstacle_edges = switch(v)?;
            Ok(())
        },
    },
];

/// A switch's value as the node declares it: `true`, `false` or empty
/// (the scene's own).
fn switch_value(b: Option<bool>) -> Value {
    Value::Str(b.map_or_else(String::new, |b| b.to_string()))
}

/// A switch from `true`, `false` or empty (a string, or a bool from `-p`
/// and params files).
fn switch(v: Value) -> std::result::Result<Option<bool>, String> {
    match text(v).as_str() {
        "" => Ok(None),
        "true" => Ok(Some(true)),
        "false" => Ok(Some(false)),
        _ => Err("`true`, `false` or empty (the scene's own)".into()),
    }
}

/// The parameter called `name`.
pub fn parameter(name: &str) -> Option<&'static Parameter> {
    PARAMETERS.iter().find(|p| p.name == name)
}

impl Settings {
    /// Sets one parameter (unknown names and wrong types are errors;
    /// `use_sim_time` is accepted and ignored: the node's clock is the
    /// simulation).
    pub fn set(&mut self, name: &str, v: &Value) -> Result<()> {
        match parameter(name) {
            Some(p) => p.set(self, v),
            None if name == "use_sim_time" => Ok(()),
            None => {
                let known: Vec<&str> = PARAMETERS.iter().map(|p| p.name).collect();
                bail!("unknown parameter {name:?} (known: {})", known.join(", "))
            }
        }
    }

    /// The declarations of every parameter, with this value.
    pub fn declared(&self) -> Vec<(&'static str, ParameterValue)> {
        PARAMETERS
            .iter()
            .map(|p| (p.name, p.declared(self)))
            .collect()
    }

    /// The scene overrides these settings ask for.
    pub fn overrides(&self) -> Result<Overrides> {
        Ok(Overrides {
            spacing: (self.spacing > 0.0).then_some(self.spacing),
            dt: (self.dt > 0.0).then_some(self.dt),
            solver: match self.solver.as_str() {
                "" => None,
                k => Some(k.parse::<LinearSolverKind>().map_err(anyhow::Error::msg)?),
            },
            cg_tolerance: (self.cg_tolerance > 0.0).then_some(self.cg_tolerance),
            threads: (self.threads > 0).then_some(self.threads as usize),
            self_collision: self.self_collision,
            obstacle_edges: self.obstacle_edges,
            ..Default::default()
        })
    }
}

/// Reads `--ros-args`, params files and `-p` into settings (defaults, then
/// files in order, then `-p`).
pub fn settings_from_args(ra: &RosArgs, fq_name: &str) -> Result<Settings> {
    let mut s = Settings::default();
    for f in &ra.params_files {
        for (n, v) in args::read_params_file(f, fq_name)? {
            s.set(&n, &v)
                .with_context(|| format!("params file {}", f.display()))?;
        }
    }
    for (n, v) in &ra.params {
        s.set(n, v).context("-p")?;
    }
    Ok(s)
}

/// The value as a params file or `-p` would write it.
fn shown(v: &Value) -> String {
    match v {
        Value::Bool(b) => b.to_string(),
        Value::Int(i) => i.to_string(),
        Value::Double(d) => format!("{d:?}"),
        Value::Str(s) if s.is_empty() => "\"\"".into(),
        Value::Str(s) => s.clone(),
    }
}

/// The parameter table of `docs/ros.md` (Markdown), from [`PARAMETERS`] and
/// the defaults. The default scene is shown by its relative path.
pub fn markdown_table() -> String {
    let d = Settings {
        scene: "config/scenes/table_drape.yaml".into(),
        ..Settings::default()
    };
    let mut t = String::from(
        "| parameter | type | default | runtime | description |\n|---|---|---|---|---|\n",
    );
    for p in PARAMETERS {
        t.push_str(&format!(
            "| `{}` | {} | `{}` | {} | {} |\n",
            p.name,
            p.kind.name(),
            shown(&p.get(&d)),
            if p.runtime { "yes" } else { "no" },
            p.description
        ));
    }
    t
}

/// The parameters as `node --help` lists them.
pub fn help_lines() -> String {
    let d = Settings::default();
    PARAMETERS
        .iter()
        .map(|p| {
            format!(
                "  {:<22} {:<7} {:<8} {}{}\n",
                p.name,
                p.kind.name(),
                shown(&p.get(&d)),
                if p.runtime { "(runtime) " } else { "" },
                p.description
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn docs_table_is_the_parameter_table() {
        let docs =
            std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/ros.md"))
                .expect("docs/ros.md");
        let begin = "<!-- parameters:begin -->\n";
        let a = docs.find(begin).expect("parameters:begin marker") + begin.len();
        let b = docs
            .find("<!-- parameters:end -->")
            .expect("parameters:end marker");
        let want = markdown_table();
        assert_eq!(
            &docs[a..b],
            want,
            "docs/ros.md's parameter table differs from src/ros/params.rs; it should read:\n{want}"
        );
    }

    #[test]
    fn every_parameter_round_trips_and_refuses_other_types() {
        let mut s = Settings::default();
        for p in PARAMETERS {
            let v = p.get(&s);
            p.set(&mut s, &v).unwrap();
            assert_eq!(p.get(&s), v, "{}", p.name);
            let wrong = match p.kind {
                Kind::String | Kind::Integer | Kind::Double => Value::Bool(true),
                Kind::Bool | Kind::Switch => Value::Str("yes".into()),
            };
            let e = format!("{:#}", p.set(&mut s, &wrong).unwrap_err());
            assert!(e.contains(p.name), "{e}");
        }
        assert!(s.set("use_sim_time", &Value::Bool(true)).is_ok());
        let e = format!("{:#}", s.set("bogus", &Value::Int(1)).unwrap_err());
        assert!(e.contains("max_mesh_triangles"), "{e}");
    }

    #[test]
    fn ranges_are_checked() {
        let mut s = Settings::default();
        for (n, v) in [
            ("publish_rate", Value::Double(0.0)),
            ("publish_rate", Value::Double(f64::NAN)),
            ("real_time_factor", Value::Double(-1.0)),
            ("threads", Value::Int(65)),
            ("solver", Value::Str("lu".into())),
            ("frame_id", Value::Str(String::new())),
            ("max_messages_per_step", Value::Int(0)),
        ] {
            assert!(s.set(n, &v).is_err(), "{n} = {v:?}");
        }
        assert_eq!(s, Settings::default());
        s.set("publish_rate", &Value::Int(10)).unwrap();
        assert_eq!(s.publish_rate, 10.0);
        s.set("max_mesh_triangles", &Value::Int(i64::MAX)).unwrap();
        assert_eq!(
            s.max_mesh_triangles,
            crate::collision::MAX_MESH_TRIANGLES as i64
        );
    }

    #[test]
    fn cg_tolerance_is_set_by_p_or_left_to_the_scene() {
        let s = |a: &[&str]| a.iter().map(|t| t.to_string()).collect::<Vec<_>>();
        let of = |a: &[&str]| {
            let (_, ra) = args::parse(&s(a)).unwrap();
            settings_from_args(&ra, "/garment_sim")
                .map(|st| st.overrides().unwrap().cg_tolerance)
                .map_err(|e| format!("{e:#}"))
        };
        assert_eq!(of(&["--ros-args"]), Ok(None), "unset: the scene's");
        assert_eq!(
            of(&["--ros-args", "-p", "cg_tolerance:=0.01"]),
            Ok(Some(0.01))
        );
        assert_eq!(of(&["--ros-args", "-p", "cg_tolerance:=0.0"]), Ok(None));
        // as a ROS user writes it: exponent form, and an integer zero
        assert_eq!(
            of(&["--ros-args", "-p", "cg_tolerance:=1e-2"]),
            Ok(Some(0.01))
        );
        assert_eq!(of(&["--ros-args", "-p", "cg_tolerance:=0"]), Ok(None));
        for bad in [
            "cg_tolerance:=1.0",
            "cg_tolerance:=-0.1",
            "cg_tolerance:=.nan",
        ] {
            let e = of(&["--ros-args", "-p", bad]).unwrap_err();
            assert!(
                e.contains("cg_tolerance") && e.contains("(0, 1)"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn self_collision_is_set_by_p_a_params_file_or_left_to_the_scene() {
        let s = |a: &[&str]| a.iter().map(|t| t.to_string()).collect::<Vec<_>>();
        let of = |ra: &RosArgs| {
            settings_from_args(ra, "/garment_sim")
                .unwrap()
                .overrides()
                .unwrap()
                .self_collision
        };
        // unset: the scene's own; declared as an empty string
        let (_, ra) = args::parse(&s(&["--ros-args"])).unwrap();
        assert_eq!(of(&ra), None);
        let d = parameter("self_collision").unwrap();
        assert_eq!(
            d.declared(&Settings::default()),
            ParameterValue::String(String::new())
        );
        // `-p self_collision:=true` (a YAML bool) and `:=false`
        for (text, want) in [("true", true), ("false", false)] {
            let p = format!("self_collision:={text}");
            let (_, ra) = args::parse(&s(&["--ros-args", "-p", &p])).unwrap();
            assert_eq!(of(&ra), Some(want), "{p}");
            // `obstacle_edges` is the same kind of switch
            let p = format!("obstacle_edges:={text}");
            let (_, ra) = args::parse(&s(&["--ros-args", "-p", &p])).unwrap();
            let ov = settings_from_args(&ra, "/garment_sim")
                .unwrap()
                .overrides()
                .unwrap();
            assert_eq!(ov.obstacle_edges, Some(want), "{p}");
        }
        // a params file says false, `-p` wins over it
        let dir = std::env::temp_dir().join(format!("gs_selfcol_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("p.yaml");
        std::fs::write(
            &f,
            "garment_sim:\n  ros__parameters:\n    self_collision: false\n",
        )
        .unwrap();
        let fs = f.display().to_string();
        let (_, ra) = args::parse(&s(&["--ros-args", "--params-file", &fs])).unwrap();
        assert_eq!(of(&ra), Some(false));
        let (_, ra) = args::parse(&s(&[
            "--ros-args",
            "--params-file",
            &fs,
            "-p",
            "self_collision:=true",
        ]))
        .unwrap();
        assert_eq!(of(&ra), Some(true));
        let _ = std::fs::remove_dir_all(&dir);
        // a bool (`-p`, params files) or one of the three strings (also the
        // parameter services), read back as the string
        let mut st = Settings::default();
        st.set("self_collision", &Value::Bool(true)).unwrap();
        assert_eq!(st.self_collision, Some(true));
        assert_eq!(d.get(&st), Value::Str("true".into()));
        st.set("self_collision", &Value::Str("false".into()))
            .unwrap();
        assert_eq!(st.self_collision, Some(false));
        st.set("self_collision", &Value::Str(String::new()))
            .unwrap();
        assert_eq!(st.self_collision, None);
        for bad in [Value::Str("on".into()), Value::Int(1), Value::Double(1.0)] {
            let e = format!("{:#}", st.set("self_collision", &bad).unwrap_err());
            assert!(e.contains("self_collision"), "{e}");
        }
        assert_eq!(st.self_collision, None);
    }

    #[test]
    fn default_scene_is_found_from_the_working_directory_or_the_executable() {
        let root =
            std::env::temp_dir().join(format!("garment_sim_defscene_{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let checkout = root.join("checkout");
        let scene = checkout.join(DEFAULT_SCENE);
        std::fs::create_dir_all(scene.parent().unwrap()).unwrap();
        std::fs::write(&scene, "x").unwrap();
        let exe = checkout.join("target/release/garment_sim");
        let elsewhere = root.join("elsewhere");
        std::fs::create_dir_all(&elsewhere).unwrap();
        // run from elsewhere: found beside the executable's checkout
        assert_eq!(
            find_default_scene(&elsewhere, Some(&exe)),
            Some(scene.clone())
        );
        // run from the checkout: found in the working directory
        assert_eq!(find_default_scene(&checkout, None), Some(scene.clone()));
        // installed under a prefix: share/garment_sim/config/...
        let prefix = root.join("usr");
        let shared = prefix.join("share/garment_sim").join(DEFAULT_SCENE);
        std::fs::create_dir_all(shared.parent().unwrap()).unwrap();
        std::fs::write(&shared, "x").unwrap();
        let installed = prefix.join("bin/garment_sim");
        assert_eq!(
            find_default_scene(&elsewhere, Some(&installed)),
            Some(shared)
        );
        // a binary copied where no scene is: none (not the build folder)
        let lone = root.join("lone/garment_sim");
        assert_eq!(find_default_scene(&elsewhere, Some(&lone)), None);
        std::fs::remove_dir_all(&root).unwrap();
    }
}
