//! `garment_sim node`: the simulation as a ROS 2 node (ros2-client on RustDDS;
//! no ROS installation needed).
//!
//! One thread runs the loop read messages → step → publish; a second spins
//! ros2-client (discovery, parameter services). Names below are relative to
//! the node namespace (`-r __ns:=/x`), `~/` to the node (`/x/garment_sim`):
//!
//! | name | type | |
//! |---|---|---|
//! | `cloth/points` | sensor_msgs/msg/PointCloud2 | out: x, y, z, strain, speed (float32) |
//! | `cloth/mesh` | visualization_msgs/msg/Marker | out: TRIANGLE_LIST coloured by strain |
//! | `obstacles/markers` | visualization_msgs/msg/MarkerArray | out |
//! | `diagnostics` | diagnostic_msgs/msg/DiagnosticArray | out: step time, iterations, RTF, rejected messages |
//! | `/clock` | rosgraph_msgs/msg/Clock | out: simulated time |
//! | `scene_description` | std_msgs/msg/String | out, latched (transient local): scene and fabric YAML |
//! | `/rosout` | rcl_interfaces/msg/Log | out: what the node does and refuses |
//! | `obstacles` | garment_sim_msgs/msg/Obstacle | in: add, move, remove |
//! | `pins` | garment_sim_msgs/msg/Pin | in: pin, move, release |
//! | `~/reset` | std_srvs/srv/Trigger | reloads the scene (parameter `scene`) |
//! | `~/set_paused` | std_srvs/srv/SetBool | |
//! | `~/step` | garment_sim_msgs/srv/Step | N steps while paused |

use super::args::{self, RosArgs, Value};
use super::control::{self, ObstacleRegistry};
use super::msgs::{self, RosType};
use super::publish;
use crate::scene::{Overrides, Scene};
use crate::solver::{LinearSolverKind, Simulation};
use anyhow::{anyhow, bail, Context as _, Result};
use ros2_client::{
    rosout, Context, ContextOptions, MessageTypeName, Name, NodeName, NodeOptions, ParameterValue,
    QosProfile, ServiceMapping, ServiceTypeName,
};
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

macro_rules! message {
    ($($t:ty),*) => { $(impl ros2_client::Message for $t {})* };
}
message!(
    msgs::PointCloud2,
    msgs::Marker,
    msgs::MarkerArray,
    msgs::DiagnosticArray,
    msgs::Clock,
    msgs::Obstacle,
    msgs::Pin,
    msgs::TriggerRequest,
    msgs::TriggerResponse,
    msgs::SetBoolRequest,
    msgs::SetBoolResponse,
    msgs::StepRequest,
    msgs::StepResponse,
    msgs::StringMsg
);

/// The node's parameters (ROS 2 parameters; `-p`, `--params-file`, and at
/// run time the parameter services for those marked so).
#[derive(Debug, Clone, PartialEq)]
pub struct Settings {
    /// Scene file (read at start and on `~/reset`).
    pub scene: String,
    /// frame_id of everything published and expected in messages.
    pub frame_id: String,
    /// Hz of simulated time (runtime).
    pub publish_rate: f64,
    /// 1: paced with the wall clock; 0: as fast as possible (runtime).
    pub real_time_factor: f64,
    /// Runtime.
    pub paused: bool,
    /// Simulated seconds after which the node exits (0: never).
    pub duration: f64,
    /// Overrides of the scene (0 / "": the scene's own).
    pub dt: f64,
    pub spacing: f64,
    pub solver: String,
    /// Threads of the assembly, the PCG and the contacts (0: one per core
    /// from 500 vertices).
    pub threads: i64,
    /// Bag directory to record into ("": no recording).
    pub record_bag: String,
    /// Messages applied per topic between two steps; more are dropped
    /// (counted, logged): a sender faster than the simulation cannot queue
    /// work without bound (runtime).
    pub max_messages_per_step: i64,
    /// Largest obstacle mesh accepted, triangles (runtime).
    pub max_mesh_triangles: i64,
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
            threads: 0,
            record_bag: String::new(),
            max_messages_per_step: 100,
            max_mesh_triangles: 200_000,
        }
    }
}

/// The shipped example: `config/scenes/table_drape.yaml` from the working
/// directory, else from the source tree the binary was built from.
fn default_scene() -> String {
    let rel = "config/scenes/table_drape.yaml";
    if Path::new(rel).exists() {
        rel.into()
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join(rel)
            .display()
            .to_string()
    }
}

fn num(name: &str, v: &Value) -> Result<f64> {
    match v {
        Value::Int(i) => Ok(*i as f64),
        Value::Double(d) => Ok(*d),
        other => bail!("parameter {name}: {other:?} is not a number"),
    }
}

impl Settings {
    /// Sets one parameter (unknown names and wrong types are errors).
    pub fn set(&mut self, name: &str, v: &Value) -> Result<()> {
        let text = |v: &Value| -> Result<String> {
            match v {
                Value::Str(s) => Ok(s.clone()),
                other => bail!("parameter {name}: {other:?} is not a string"),
            }
        };
        match name {
            "scene" => self.scene = text(v)?,
            "frame_id" => {
                let f = text(v)?;
                if f.is_empty() {
                    bail!("parameter frame_id: must not be empty");
                }
                self.frame_id = f
            }
            "publish_rate" => {
                let r = num(name, v)?;
                if !(r.is_finite() && r > 0.0) {
                    bail!("parameter publish_rate = {r}: must be > 0 Hz");
                }
                self.publish_rate = r
            }
            "real_time_factor" => {
                let r = num(name, v)?;
                if !(r.is_finite() && r >= 0.0) {
                    bail!("parameter real_time_factor = {r}: must be ≥ 0 (0: as fast as possible)");
                }
                self.real_time_factor = r
            }
            "paused" => match v {
                Value::Bool(b) => self.paused = *b,
                other => bail!("parameter paused: {other:?} is not a bool"),
            },
            "duration" => {
                let d = num(name, v)?;
                if !(d.is_finite() && d >= 0.0) {
                    bail!("parameter duration = {d}: must be ≥ 0 s (0: run until stopped)");
                }
                self.duration = d
            }
            "dt" => {
                let d = num(name, v)?;
                if !(d.is_finite() && d >= 0.0) {
                    bail!("parameter dt = {d}: must be > 0 s (0: the scene's)");
                }
                self.dt = d
            }
            "spacing" => {
                let d = num(name, v)?;
                if !(d.is_finite() && d >= 0.0) {
                    bail!("parameter spacing = {d}: must be > 0 m (0: the scene's)");
                }
                self.spacing = d
            }
            "solver" => {
                let s = text(v)?;
                if !["", "auto", "pcg", "cholesky"].contains(&s.as_str()) {
                    bail!("parameter solver = {s:?}: one of auto, pcg, cholesky");
                }
                self.solver = s
            }
            "threads" => {
                let k = match v {
                    Value::Int(i) => *i,
                    other => bail!("parameter threads: {other:?} is not an integer"),
                };
                if !(0..=crate::solver::MAX_THREADS as i64).contains(&k) {
                    bail!(
                        "parameter threads = {k}: 0 (one per core) to {}",
                        crate::solver::MAX_THREADS
                    );
                }
                self.threads = k
            }
            "record_bag" => self.record_bag = text(v)?,
            "max_messages_per_step" | "max_mesh_triangles" => {
                let k = match v {
                    Value::Int(i) => *i,
                    other => bail!("parameter {name}: {other:?} is not an integer"),
                };
                if k < 1 {
                    bail!("parameter {name} = {k}: must be ≥ 1");
                }
                if name == "max_messages_per_step" {
                    self.max_messages_per_step = k
                } else {
                    self.max_mesh_triangles = k.min(crate::collision::MAX_MESH_TRIANGLES as i64)
                }
            }
            "use_sim_time" => {}
            other => bail!(
                "unknown parameter {other:?} (known: scene, frame_id, publish_rate, \
                 real_time_factor, paused, duration, dt, spacing, solver, threads, record_bag, \
                 max_messages_per_step, max_mesh_triangles)"
            ),
        }
        Ok(())
    }

    fn declared(&self) -> Vec<(&'static str, ParameterValue)> {
        vec![
            ("scene", ParameterValue::String(self.scene.clone())),
            ("frame_id", ParameterValue::String(self.frame_id.clone())),
            ("publish_rate", ParameterValue::Double(self.publish_rate)),
            (
                "real_time_factor",
                ParameterValue::Double(self.real_time_factor),
            ),
            ("paused", ParameterValue::Boolean(self.paused)),
            ("duration", ParameterValue::Double(self.duration)),
            ("dt", ParameterValue::Double(self.dt)),
            ("spacing", ParameterValue::Double(self.spacing)),
            ("solver", ParameterValue::String(self.solver.clone())),
            ("threads", ParameterValue::Integer(self.threads)),
            (
                "record_bag",
                ParameterValue::String(self.record_bag.clone()),
            ),
        ]
    }

    fn overrides(&self) -> Result<Overrides> {
        Ok(Overrides {
            spacing: (self.spacing > 0.0).then_some(self.spacing),
            dt: (self.dt > 0.0).then_some(self.dt),
            solver: match self.solver.as_str() {
                "" => None,
                "auto" => Some(LinearSolverKind::Auto),
                "pcg" => Some(LinearSolverKind::Pcg),
                "cholesky" => Some(LinearSolverKind::Cholesky),
                s => bail!("solver {s:?}"),
            },
            threads: (self.threads > 0).then_some(self.threads as usize),
            ..Default::default()
        })
    }
}

fn to_value(p: &ParameterValue) -> Option<Value> {
    Some(match p {
        ParameterValue::Boolean(b) => Value::Bool(*b),
        ParameterValue::Integer(i) => Value::Int(*i),
        ParameterValue::Double(d) => Value::Double(*d),
        ParameterValue::String(s) => Value::Str(s.clone()),
        _ => return None,
    })
}

/// Parameters that can change while the node runs (the others are read at
/// start and on `~/reset`).
pub const RUNTIME_PARAMETERS: [&str; 4] =
    ["publish_rate", "real_time_factor", "paused", "frame_id"];

/// Resolved names of the node's endpoints.
#[derive(Debug, Clone)]
pub struct Names {
    pub namespace: String,
    pub node: String,
    pub points: String,
    pub mesh: String,
    pub obstacle_markers: String,
    pub diagnostics: String,
    pub clock: String,
    pub scene_description: String,
    pub obstacles: String,
    pub pins: String,
    pub reset: String,
    pub set_paused: String,
    pub step: String,
}

impl Names {
    pub fn resolve(ra: &RosArgs) -> Result<Names> {
        let namespace = args::check_namespace(ra.namespace.as_deref().unwrap_or("/"))?;
        let node = ra.node_name.clone().unwrap_or_else(|| "garment_sim".into());
        NodeName::new(&namespace, &node).map_err(|e| anyhow!("node name {node:?}: {e:?}"))?;
        let r = |n: &str| args::remap(n, &namespace, &node, &ra.remaps);
        Ok(Names {
            points: r("cloth/points"),
            mesh: r("cloth/mesh"),
            obstacle_markers: r("obstacles/markers"),
            diagnostics: r("diagnostics"),
            clock: r("/clock"),
            scene_description: r("scene_description"),
            obstacles: r("obstacles"),
            pins: r("pins"),
            reset: r("~/reset"),
            set_paused: r("~/set_paused"),
            step: r("~/step"),
            namespace,
            node,
        })
    }
}

fn name(full: &str) -> Result<Name> {
    Name::parse(full).map_err(|e| anyhow!("topic or service name {full:?}: {e:?}"))
}

fn type_name(ros: &str) -> MessageTypeName {
    let pkg = ros.split('/').next().unwrap_or_default();
    let ty = ros.rsplit('/').next().unwrap_or_default();
    MessageTypeName::new(pkg, ty)
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

struct Loaded {
    sim: Simulation,
    registry: ObstacleRegistry,
    description: String,
}

fn load(s: &Settings) -> Result<Loaded> {
    let path = PathBuf::from(&s.scene);
    let scene = Scene::load(&path)?;
    let ov = s.overrides()?;
    let sim = scene.build(&ov)?;
    let registry = ObstacleRegistry::from_sim(&sim);
    let description = crate::bag::scene_description(&scene, &ov, &sim)?;
    Ok(Loaded {
        sim,
        registry,
        description,
    })
}

const HELP: &str = "garment_sim node [--ros-args ...]: the simulation as a ROS 2 node\n\
\n\
ROS arguments: -p NAME:=VALUE, --params-file FILE, -r FROM:=TO (also __ns:=/ns, __node:=name)\n\
Parameters: scene (path), frame_id (world), publish_rate (30.0 Hz), real_time_factor (1.0; 0 = as\n\
  fast as possible), paused (false), duration (0 = run until stopped, s), dt, spacing, solver\n\
  (overrides of the scene), threads (0 = one per core), record_bag (directory; empty = none)\n\
Publishes: cloth/points, cloth/mesh, obstacles/markers, diagnostics, scene_description, /clock, /rosout\n\
Subscribes: obstacles (garment_sim_msgs/Obstacle), pins (garment_sim_msgs/Pin)\n\
Services: ~/reset (std_srvs/Trigger), ~/set_paused (std_srvs/SetBool), ~/step (garment_sim_msgs/Step)\n\
Environment: ROS_DOMAIN_ID. See README.md and launch-notes.md.";

/// Runs the node until SIGINT/SIGTERM or `duration`.
pub fn run(ros_args: &[String]) -> Result<()> {
    let (rest, ra) = args::parse(ros_args)?;
    if rest.iter().any(|a| a == "-h" || a == "--help") {
        println!("{HELP}");
        return Ok(());
    }
    if !rest.is_empty() {
        bail!(
            "node: unexpected arguments {rest:?} (node options go after --ros-args, \
             e.g. --ros-args -p publish_rate:=10.0)"
        );
    }
    let names = Names::resolve(&ra)?;
    let fq = args::expand("~", &names.namespace, &names.node);
    let mut settings = settings_from_args(&ra, &fq)?;
    let mut loaded = load(&settings).context("loading the scene")?;

    let domain: u16 = match std::env::var("ROS_DOMAIN_ID") {
        Ok(v) if !v.is_empty() => v
            .parse()
            .map_err(|_| anyhow!("ROS_DOMAIN_ID = {v:?}: not a number 0–232"))?,
        _ => 0,
    };
    let context = Context::with_options(ContextOptions::new().domain_id(domain))
        .map_err(|e| anyhow!("cannot start DDS: {e:?}"))?;
    let mut opts = NodeOptions::new()
        .enable_rosout(true)
        .start_parameter_services(true);
    for (n, v) in settings.declared() {
        opts = opts.declare_parameter(n, v);
    }
    let check = settings.clone();
    opts = opts.parameter_validator(Box::new(move |n, v| {
        let v = to_value(v).ok_or_else(|| format!("parameter {n}: unsupported type"))?;
        let mut s = check.clone();
        s.set(n, &v).map_err(|e| e.to_string())
    }));
    let mut node = context
        .new_node(
            NodeName::new(&names.namespace, &names.node)
                .map_err(|e| anyhow!("node name: {e:?}"))?,
            opts,
        )
        .map_err(|e| anyhow!("cannot create node: {e:?}"))?;

    let reliable =
        QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth: 10 });
    let clock_qos =
        QosProfile::publisher_default().history(ros2_client::qos::History::KeepLast { depth: 1 });
    let sub_qos = reliable
        .clone()
        .history(ros2_client::qos::History::KeepLast { depth: 100 });
    macro_rules! publisher {
        ($t:ty, $n:expr, $q:expr) => {{
            let topic = node
                .create_topic(&name($n)?, type_name(<$t>::NAME), &$q)
                .map_err(|e| anyhow!("topic {}: {e:?}", $n))?;
            node.create_publisher::<$t>(&topic, None)
                .map_err(|e| anyhow!("publisher {}: {e:?}", $n))?
        }};
    }
    macro_rules! subscription {
        ($t:ty, $n:expr) => {{
            let topic = node
                .create_topic(&name($n)?, type_name(<$t>::NAME), &sub_qos)
                .map_err(|e| anyhow!("topic {}: {e:?}", $n))?;
            node.create_subscription::<$t>(&topic, None)
                .map_err(|e| anyhow!("subscription {}: {e:?}", $n))?
        }};
    }
    macro_rules! server {
        ($req:ty, $resp:ty, $n:expr, $pkg:expr, $ty:expr) => {{
            node.create_server::<$req, $resp>(
                ServiceMapping::Enhanced,
                &name($n)?,
                &ServiceTypeName::new($pkg, $ty),
                reliable.clone(),
                reliable.clone(),
            )
            .map_err(|e| anyhow!("service {}: {e:?}", $n))?
        }};
    }
    let pub_points = publisher!(msgs::PointCloud2, &names.points, reliable);
    let pub_mesh = publisher!(msgs::Marker, &names.mesh, reliable);
    let pub_obstacles = publisher!(msgs::MarkerArray, &names.obstacle_markers, reliable);
    let pub_diag = publisher!(msgs::DiagnosticArray, &names.diagnostics, reliable);
    let pub_clock = publisher!(msgs::Clock, &names.clock, clock_qos);
    let latched = QosProfile::publisher_default()
        .durability(ros2_client::qos::Durability::TransientLocal)
        .history(ros2_client::qos::History::KeepLast { depth: 1 });
    let pub_scene = publisher!(msgs::StringMsg, &names.scene_description, latched);
    let _ = pub_scene.publish(msgs::StringMsg {
        data: loaded.description.clone(),
    });
    let mut recorder = if settings.record_bag.is_empty() {
        None
    } else {
        let topics = crate::bag::TopicNames {
            points: names.points.clone(),
            mesh: names.mesh.clone(),
            obstacles: names.obstacle_markers.clone(),
            diagnostics: names.diagnostics.clone(),
            clock: names.clock.clone(),
            scene_description: names.scene_description.clone(),
        };
        let dir = PathBuf::from(&settings.record_bag);
        let rec = crate::bag::SimRecorder::create(
            &dir,
            &crate::bag::BagOptions::default(),
            &topics,
            &loaded.description,
        )
        .with_context(|| format!("parameter record_bag = {:?}", settings.record_bag))?;
        Some(rec)
    };
    let mut last_recorded: Option<f64> = None;
    let sub_obstacles = subscription!(msgs::Obstacle, &names.obstacles);
    let sub_pins = subscription!(msgs::Pin, &names.pins);
    let srv_reset = server!(
        msgs::TriggerRequest,
        msgs::TriggerResponse,
        &names.reset,
        "std_srvs",
        "Trigger"
    );
    let srv_paused = server!(
        msgs::SetBoolRequest,
        msgs::SetBoolResponse,
        &names.set_paused,
        "std_srvs",
        "SetBool"
    );
    let srv_step = server!(
        msgs::StepRequest,
        msgs::StepResponse,
        &names.step,
        "garment_sim_msgs",
        "Step"
    );
    let spinner = node
        .spinner()
        .map_err(|e| anyhow!("cannot start the spinner: {e:?}"))?;
    std::thread::Builder::new()
        .name("ros2-spinner".into())
        .spawn(move || {
            let _ = futures::executor::block_on(spinner.spin());
        })?;

    let stop = crate::run::stop_flag()?;
    let log = node.logging_handle();
    macro_rules! info {
        ($($a:tt)+) => {{
            let m = format!($($a)+);
            eprintln!("[garment_sim] {m}");
            rosout!(log, ros2_client::log::LogLevel::Info, "{}", m);
        }};
    }
    macro_rules! warn {
        ($($a:tt)+) => {{
            let m = format!($($a)+);
            eprintln!("[garment_sim] warning: {m}");
            rosout!(log, ros2_client::log::LogLevel::Warn, "{}", m);
        }};
    }
    info!(
        "node {fq}: scene {} ({} vertices, dt = {} s), frame {:?}, publishing {} and {} at {} Hz",
        settings.scene,
        loaded.sim.cloth.len(),
        loaded.sim.params.dt,
        settings.frame_id,
        names.points,
        names.mesh,
        settings.publish_rate
    );

    let mut rejected: u64 = 0;
    let mut dropped: u64 = 0;
    let mut dropped_now: u64 = 0;
    let mut last_drop_log = Instant::now() - Duration::from_secs(10);
    let wall_start = Instant::now();
    let mut publish_s = 0.0;
    let mut publishes = 0u64;
    let steps_start = loaded.sim.steps;
    let mut last_error = String::new();
    let mut pending_steps: u64 = 0;
    let mut frames = publish::FrameClock::new(loaded.sim.time);
    let mut clock_every: u64;
    let mut pace_origin = (Instant::now(), loaded.sim.time);
    let mut last_rtf = (Instant::now(), loaded.sim.time);
    let mut step_ms_sum = 0.0;
    let mut step_count = 0u64;
    let mut last_iters = 0usize;
    let mut last_rt = 0.0;
    let mut publish_now = true;
    let mut step_reply = None;
    // the first pass publishes (and records) the initial state before any step
    let mut initial = true;
    loop {
        if stop.load(Ordering::Relaxed) {
            info!("stopping (signal) at t = {:.3} s", loaded.sim.time);
            break;
        }
        // runtime parameters
        let before = settings.clone();
        for n in RUNTIME_PARAMETERS {
            if let Some(v) = node.get_parameter(n).as_ref().and_then(to_value) {
                if let Err(e) = settings.set(n, &v) {
                    warn!("{e}");
                }
            }
        }
        if settings.real_time_factor != before.real_time_factor || settings.paused != before.paused
        {
            pace_origin = (Instant::now(), loaded.sim.time);
        }
        // messages
        let cap = settings.max_messages_per_step as usize;
        let mut taken = 0usize;
        while let Ok(Some((m, _))) = sub_obstacles.take() {
            taken += 1;
            if taken > cap {
                dropped += 1;
                dropped_now += 1;
                continue;
            }
            match control::apply_obstacle(
                &mut loaded.sim,
                &mut loaded.registry,
                &m,
                &settings.frame_id,
                settings.max_mesh_triangles as usize,
            ) {
                Ok(what) => info!("{what}"),
                Err(e) => {
                    rejected += 1;
                    warn!("rejected message on {}: {e}", names.obstacles);
                    last_error = e;
                }
            }
            publish_now = true;
        }
        let mut taken = 0usize;
        while let Ok(Some((m, _))) = sub_pins.take() {
            taken += 1;
            if taken > cap {
                dropped += 1;
                dropped_now += 1;
                continue;
            }
            match control::apply_pin(&mut loaded.sim, &m, &settings.frame_id) {
                Ok(what) => info!("{what}"),
                Err(e) => {
                    rejected += 1;
                    warn!("rejected message on {}: {e}", names.pins);
                    last_error = e;
                }
            }
        }
        if dropped_now > 0 && last_drop_log.elapsed() > Duration::from_secs(1) {
            last_error = format!(
                "dropped {dropped_now} messages arriving faster than the simulation steps \
                 (max_messages_per_step = {cap} per topic)"
            );
            warn!("{last_error}");
            dropped_now = 0;
            last_drop_log = Instant::now();
        }
        // services
        while let Ok(Some((id, _))) = srv_reset.receive_request() {
            let fresh = node
                .get_parameter("scene")
                .as_ref()
                .and_then(to_value)
                .map(|v| settings.set("scene", &v));
            if let Some(Err(e)) = fresh {
                warn!("{e}");
            }
            let resp = match load(&settings) {
                Ok(l) => {
                    loaded = l;
                    let _ = pub_scene.publish(msgs::StringMsg {
                        data: loaded.description.clone(),
                    });
                    frames = publish::FrameClock::new(loaded.sim.time);
                    pace_origin = (Instant::now(), loaded.sim.time);
                    pending_steps = 0;
                    if let Some(rec) = recorder.as_mut() {
                        // frames of the new run follow the old ones in the bag
                        let gap = (1e9 / settings.publish_rate) as u64;
                        rec.restart(&loaded.description, gap);
                        last_recorded = None;
                    }
                    info!("reset: scene {}", settings.scene);
                    publish_now = true;
                    msgs::TriggerResponse {
                        success: true,
                        message: format!("scene {} reloaded", settings.scene),
                    }
                }
                Err(e) => {
                    warn!("reset failed: {e:#}");
                    msgs::TriggerResponse {
                        success: false,
                        message: format!("{e:#}"),
                    }
                }
            };
            let _ = srv_reset.send_response(id, resp);
        }
        while let Ok(Some((id, req))) = srv_paused.receive_request() {
            let _ = node.set_parameter("paused", ParameterValue::Boolean(req.data));
            settings.paused = req.data;
            pace_origin = (Instant::now(), loaded.sim.time);
            info!("{}", if req.data { "paused" } else { "running" });
            let _ = srv_paused.send_response(
                id,
                msgs::SetBoolResponse {
                    success: true,
                    message: if req.data { "paused" } else { "running" }.into(),
                },
            );
        }
        while let Ok(Some((id, req))) = srv_step.receive_request() {
            if !settings.paused {
                let _ = srv_step.send_response(
                    id,
                    msgs::StepResponse {
                        success: false,
                        message: "not paused: call ~/set_paused true first".into(),
                        sim_time: msgs::Time::from_secs(loaded.sim.time),
                    },
                );
            } else {
                if let Some(old) = step_reply.replace(id) {
                    // a second request before the first is done: answer the first now
                    let _ = srv_step.send_response(
                        old,
                        msgs::StepResponse {
                            success: true,
                            message: "merged with a later request".into(),
                            sim_time: msgs::Time::from_secs(loaded.sim.time),
                        },
                    );
                }
                pending_steps += req.steps as u64;
            }
        }

        let running = !settings.paused || pending_steps > 0;
        if running && !initial {
            let dt = loaded.sim.params.dt;
            clock_every = ((1e-3 / dt).round() as u64).max(1);
            let stepped = loaded.sim.step();
            // between steps the node publishes, reads parameters and
            // messages, or sleeps: the simulation's workers sleep meanwhile
            // instead of spinning (the next step wakes them)
            loaded.sim.rest_threads();
            match stepped {
                Ok(st) => {
                    step_ms_sum += st.total_s * 1e3;
                    step_count += 1;
                    last_iters = st.iterations;
                }
                Err(e) => {
                    last_error = format!("step failed at t = {:.4} s: {e:#}", loaded.sim.time);
                    warn!("{last_error}; pausing (call ~/reset)");
                    settings.paused = true;
                    let _ = node.set_parameter("paused", ParameterValue::Boolean(true));
                    pending_steps = 0;
                }
            }
            pending_steps = pending_steps.saturating_sub(1);
            if loaded.sim.steps % clock_every == 0 {
                let _ = pub_clock.publish(msgs::Clock {
                    clock: msgs::Time::from_secs(loaded.sim.time),
                });
            }
            if pending_steps == 0 {
                if let Some(id) = step_reply.take() {
                    let _ = srv_step.send_response(
                        id,
                        msgs::StepResponse {
                            success: true,
                            message: format!("t = {:.4} s", loaded.sim.time),
                            sim_time: msgs::Time::from_secs(loaded.sim.time),
                        },
                    );
                    publish_now = true;
                }
            }
        }
        // while paused the state is still published, at publish_rate in wall time
        let paused_due =
            !running && last_rtf.0.elapsed().as_secs_f64() >= 1.0 / settings.publish_rate;
        let due = frames.due(loaded.sim.time, settings.publish_rate);
        if due || publish_now || paused_due {
            let now = Instant::now();
            let wall = now.duration_since(last_rtf.0).as_secs_f64();
            if wall > 0.0 && running {
                last_rt = (loaded.sim.time - last_rtf.1) / wall;
            }
            last_rtf = (now, loaded.sim.time);
            let t_pub = Instant::now();
            let h = publish::header(&loaded.sim, &settings.frame_id);
            let cloud = publish::cloud(&loaded.sim, h.clone());
            let mesh = publish::cloth_marker(&loaded.sim, h.clone());
            let obstacles = publish::obstacle_markers(&loaded.sim, h.clone());
            let fig = publish::DiagnosticFigures {
                step_time_ms: if step_count > 0 {
                    step_ms_sum / step_count as f64
                } else {
                    0.0
                },
                iterations: last_iters,
                real_time_factor: last_rt,
                rejected_messages: rejected,
                dropped_messages: dropped,
                paused: settings.paused,
                last_error: last_error.clone(),
            };
            let diag = publish::diagnostics(&loaded.sim, h.clone(), &fig);
            let clock = msgs::Clock { clock: h.stamp };
            // the bag gets what is published, once per simulated state (not
            // the repeats published while paused) unless an obstacle changed
            let new_state = last_recorded != Some(loaded.sim.time) || publish_now;
            let failed = recorder.as_mut().filter(|_| new_state).and_then(|rec| {
                let frame = crate::bag::Frame {
                    cloud: &cloud,
                    mesh: &mesh,
                    obstacles: &obstacles,
                    diagnostics: &diag,
                    clock: &clock,
                };
                match rec.record_frame(&frame) {
                    Ok(()) => {
                        last_recorded = Some(loaded.sim.time);
                        None
                    }
                    Err(e) => Some(e),
                }
            });
            if let Some(e) = failed {
                last_error = format!("bag {}: {e:#}", settings.record_bag);
                warn!("{last_error}; recording stopped, the bag is closed");
                if let Some(Err(e)) = recorder.take().map(|r| r.finish()) {
                    warn!("bag {}: {e:#}", settings.record_bag);
                }
            }
            let _ = pub_points.publish(cloud);
            let _ = pub_mesh.publish(mesh);
            let _ = pub_obstacles.publish(obstacles);
            let _ = pub_diag.publish(diag);
            let _ = pub_clock.publish(clock);
            publish_s += t_pub.elapsed().as_secs_f64();
            publishes += 1;
            step_ms_sum = 0.0;
            step_count = 0;
            publish_now = false;
        }
        initial = false;
        if settings.duration > 0.0 && loaded.sim.time + 1e-12 >= settings.duration {
            info!("duration {} s reached", settings.duration);
            break;
        }
        // pacing
        if !running {
            std::thread::sleep(Duration::from_millis(5));
        } else if settings.real_time_factor > 0.0 {
            let due = (loaded.sim.time - pace_origin.1) / settings.real_time_factor;
            let ahead = due - pace_origin.0.elapsed().as_secs_f64();
            if ahead > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(ahead));
            } else if ahead < -0.5 {
                // too slow to keep up: do not try to catch up later
                pace_origin = (Instant::now(), loaded.sim.time);
            }
        }
    }
    let _ = pub_clock.publish(msgs::Clock {
        clock: msgs::Time::from_secs(loaded.sim.time),
    });
    if let Some(mut rec) = recorder.take() {
        if last_recorded != Some(loaded.sim.time) {
            // the state the node stopped in (as `drape --bag` records it)
            let fig = publish::DiagnosticFigures::default();
            if let Err(e) = rec.record(&loaded.sim, &settings.frame_id, &fig) {
                warn!("bag {}: {e:#}", settings.record_bag);
            }
        }
        match rec.finish() {
            Ok(b) => info!(
                "bag {}: {} messages, {:.3} s, {:.2} MiB",
                b.dir.display(),
                b.message_count,
                b.duration_s(),
                b.bytes as f64 / (1024.0 * 1024.0)
            ),
            Err(e) => warn!("bag {}: {e:#}", settings.record_bag),
        }
    }
    std::thread::sleep(Duration::from_millis(200)); // let rosout and the last samples go
    let wall = wall_start.elapsed().as_secs_f64();
    let steps = loaded.sim.steps.saturating_sub(steps_start).max(1);
    eprintln!(
        "[garment_sim] stopped at t = {:.3} s after {} steps in {:.2} s wall ({:.3} ms per step); \
         {} messages rejected, {} dropped; {} publications, {:.3} ms each",
        loaded.sim.time,
        loaded.sim.steps,
        wall,
        1e3 * wall / steps as f64,
        rejected,
        dropped,
        publishes,
        1e3 * publish_s / publishes.max(1) as f64
    );
    Ok(())
}
