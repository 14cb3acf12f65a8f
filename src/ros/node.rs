//! `garment_sim node`: the simulation as a ROS 2 node (ros2-client on RustDDS;
//! no ROS installation needed).
//!
//! One thread runs the loop ([`Node::run`]): apply parameter changes, take
//! messages, serve services, step, publish, pace; a second spins ros2-client
//! (discovery, parameter services); two more write the log (stderr and
//! `/rosout`, [`super::intake`]: the loop never waits on either). The
//! parameters are in [`super::params`]. Names below are relative to
//! the node namespace (`-r __ns:=/x`), `~/` to the node (`/x/garment_sim`):
//!
//! | name | type | |
//! |---|---|---|
//! | `cloth/points` | sensor_msgs/msg/PointCloud2 | out: x, y, z, strain, speed (float32) |
//! | `cloth/mesh` | visualization_msgs/msg/Marker | out: TRIANGLE_LIST coloured by strain |
//! | `obstacles/markers` | visualization_msgs/msg/MarkerArray | out |
//! | `body/wrench` | geometry_msgs/msg/WrenchStamped | out, with a body: the garment's force on it, torque about the frame's origin |
//! | `body/points` | sensor_msgs/msg/PointCloud2 | out, with a mesh body: its vertices, x, y, z, pressure (float32) |
//! | `diagnostics` | diagnostic_msgs/msg/DiagnosticArray | out: step time, iterations, RTF, rejected messages |
//! | `/clock` | rosgraph_msgs/msg/Clock | out: simulated time |
//! | `scene_description` | std_msgs/msg/String | out, latched (transient local): scene and fabric YAML |
//! | `/rosout` | rcl_interfaces/msg/Log | out: what the node does and refuses |
//! | `obstacles` | garment_sim_msgs/msg/Obstacle | in: add, move, remove |
//! | `pins` | garment_sim_msgs/msg/Pin | in: pin, move, release |
//! | `body` | garment_sim_msgs/msg/Body | in: a deforming body's topology, then its frames |
//! | `body_mesh` | mesh_msgs/msg/MeshGeometryStamped | in: a deforming body, the whole mesh every frame |
//! | `~/reset` | std_srvs/srv/Trigger | reloads the scene (parameters `scene`, `self_collision`, `obstacle_edges`) |
//! | `~/set_paused` | std_srvs/srv/SetBool | |
//! | `~/step` | garment_sim_msgs/srv/Step | N steps while paused |

use super::args::{self, RosArgs, Value};
use super::control::{self, ObstacleRegistry};
use super::intake::{Log, Outcome, TopicLog};
use super::params::{self, Settings, PARAMETERS};
use crate::bag::SimRecorder;
use crate::msgs::publish;
use crate::msgs::{self, RosType};
use crate::scene::Scene;
use crate::solver::Simulation;
use anyhow::{anyhow, bail, Context as _, Result};
use ros2_client::{
    MessageTypeName, Name, NodeName, NodeOptions, ParameterValue, QosProfile, ServiceMapping,
    ServiceTypeName,
};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::Arc;
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
    msgs::StringMsg,
    msgs::WrenchStamped
);

fn to_value(p: &ParameterValue) -> Option<Value> {
    Some(match p {
        ParameterValue::Boolean(b) => Value::Bool(*b),
        ParameterValue::Integer(i) => Value::Int(*i),
        ParameterValue::Double(d) => Value::Double(*d),
        ParameterValue::String(s) => Value::Str(s.clone()),
        _ => return None,
    })
}

/// Resolved names of the node's endpoints.
#[derive(Debug, Clone)]
pub struct Names {
    pub namespace: String,
    pub node: String,
    pub points: String,
    pub mesh: String,
    pub obstacle_markers: String,
    pub body_wrench: String,
    pub body_points: String,
    pub diagnostics: String,
    pub clock: String,
    pub scene_description: String,
    pub obstacles: String,
    pub pins: String,
    pub body: String,
    pub body_mesh: String,
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
            body_wrench: r("body/wrench"),
            body_points: r("body/points"),
            diagnostics: r("diagnostics"),
            clock: r("/clock"),
            scene_description: r("scene_description"),
            obstacles: r("obstacles"),
            pins: r("pins"),
            body: r("body"),
            body_mesh: r("body_mesh"),
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

struct Loaded {
    sim: Simulation,
    registry: ObstacleRegistry,
    description: String,
    /// A garment trial's garment and body.
    worn: Option<Worn>,
    /// The bodies streamed on `body`.
    bodies: super::body::BodyStreams,
}

/// The garment of a trial scene (its panels name pins' grid nodes) and the
/// body it is worn on (the cloud's fit fields).
struct Worn {
    garment: crate::garment::Garment,
    body: crate::collision::Obstacle,
}

fn load(s: &Settings) -> Result<Loaded> {
    let path = PathBuf::from(&s.scene);
    if crate::trial::is_trial_file(&path) {
        // a garment trial: sewn onto its body before the first step
        let t = crate::trial::Trial::load(&path)?;
        let ov = s.overrides()?;
        let (sim, g) = t.sewn(&ov)?;
        let registry = ObstacleRegistry::from_sim(&sim);
        let description = t.description(&g, &sim)?;
        return Ok(Loaded {
            sim,
            registry,
            description,
            worn: Some(Worn {
                garment: g,
                body: t.body.clone(),
            }),
            bodies: Default::default(),
        });
    }
    let scene = Scene::load(&path)?;
    let ov = s.overrides()?;
    let sim = scene.build(&ov)?;
    let registry = ObstacleRegistry::from_sim(&sim);
    let description = crate::bag::scene_description(&scene, &ov, &sim)?;
    Ok(Loaded {
        sim,
        registry,
        description,
        worn: None,
        bodies: Default::default(),
    })
}

/// The cloth as `cloud/points`; for a garment trial with the per-vertex
/// fields of `fit.json` after the usual ones (the same names as in
/// `garment.ply`).
fn cloud(l: &Loaded, h: msgs::Header) -> msgs::PointCloud2 {
    match &l.worn {
        Some(w) => {
            // the body where it is now (a streamed body replaces the trial's)
            let body = crate::trial::body_handle(&l.sim)
                .and_then(|b| l.sim.obstacles().get(b))
                .unwrap_or(&w.body);
            let f = crate::trial::vertex_fit(&l.sim, &w.garment, body);
            publish::cloud_with(
                &l.sim,
                h,
                &[
                    ("strain_warp", &f.warp),
                    ("strain_weft", &f.weft),
                    ("strain_bias", &f.bias),
                    ("pressure", &f.pressure),
                    ("distance", &f.distance),
                ],
            )
        }
        None => publish::cloud(&l.sim, h),
    }
}

/// `body/wrench` and, for a triangle-mesh body, `body/points` with the
/// pressure on its vertices; `None` without a body (the obstacle named
/// [`crate::trial::BODY_ID`]).
fn body_forces(
    sim: &Simulation,
    h: msgs::Header,
) -> Option<(msgs::WrenchStamped, Option<msgs::PointCloud2>)> {
    let body = crate::trial::body_handle(sim)?;
    let origin = sim.obstacles().get(body)?.pose.translation.vector;
    match crate::trial::body_forces::body_pressure(sim, body) {
        Some(p) => Some((
            publish::body_wrench(&p.wrench, &origin, h.clone()),
            Some(publish::body_cloud(&p, h)),
        )),
        None => {
            let w = crate::trial::body_forces::wrench(sim, body)?;
            Some((publish::body_wrench(&w, &origin, h), None))
        }
    }
}

/// Takes what a subscription holds now: each message, `None` for each one
/// beyond `cap` (taken and dropped, so a flood cannot stall the steps), and
/// the errors of those that could not be decoded (the reader moves past
/// them: one bad message does not hide the good ones after it).
fn drain<M, E: std::fmt::Display>(
    mut take: impl FnMut() -> std::result::Result<Option<M>, E>,
    cap: usize,
) -> (Vec<Option<M>>, Vec<String>) {
    let mut got = Vec::new();
    let mut errors = Vec::new();
    // a bound on the errors too: a reader that kept failing without
    // advancing must not hold the loop
    while errors.len() <= cap {
        match take() {
            Ok(Some(m)) => got.push((got.len() < cap).then_some(m)),
            Ok(None) => break,
            Err(e) => errors.push(e.to_string()),
        }
    }
    (got, errors)
}

/// `node --help`.
fn help() -> String {
    format!(
        "garment_sim node [--ros-args ...]: the simulation as a ROS 2 node\n\
         \n\
         ROS arguments: -p NAME:=VALUE, --params-file FILE, -r FROM:=TO (also __ns:=/ns, __node:=name)\n\
         Parameters (name, type, default):\n{}\
         Publishes: cloth/points, cloth/mesh, obstacles/markers, diagnostics, scene_description, /clock, /rosout;\n\
         with a body (a trial's, or a scene obstacle with id body): body/wrench, body/points\n\
         Subscribes: obstacles (garment_sim_msgs/Obstacle), pins (garment_sim_msgs/Pin), body (garment_sim_msgs/Body),\n\
         \x20           body_mesh (mesh_msgs/MeshGeometryStamped)\n\
         Services: ~/reset (std_srvs/Trigger), ~/set_paused (std_srvs/SetBool), ~/step (garment_sim_msgs/Step)\n\
         Environment: ROS_DOMAIN_ID. See docs/ros.md and launch-notes.md.",
        params::help_lines()
    )
}

/// Runs the node until SIGINT/SIGTERM or `duration`.
pub fn run(ros_args: &[String]) -> Result<()> {
    let (rest, ra) = args::parse(ros_args)?;
    if rest.iter().any(|a| a == "-h" || a == "--help") {
        println!("{}", help());
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
    let settings = params::settings_from_args(&ra, &fq)?;
    let loaded = load(&settings).context("loading the scene")?;
    Node::start(names, fq, settings, loaded, ra.enclave.as_deref())?.run()
}

/// The node's publishers, subscriptions and services.
struct Endpoints {
    points: Out<msgs::PointCloud2>,
    mesh: Out<msgs::Marker>,
    obstacle_markers: Out<msgs::MarkerArray>,
    body_wrench: Out<msgs::WrenchStamped>,
    body_points: Out<msgs::PointCloud2>,
    diagnostics: Out<msgs::DiagnosticArray>,
    clock: Out<msgs::Clock>,
    scene_description: Out<msgs::StringMsg>,
    obstacles: ros2_client::Subscription<msgs::Obstacle>,
    pins: ros2_client::Subscription<msgs::Pin>,
    body: ros2_client::Subscription<msgs::Body>,
    body_mesh: ros2_client::Subscription<msgs::MeshGeometryStamped>,
    reset: Serve<msgs::TriggerRequest, msgs::TriggerResponse>,
    set_paused: Serve<msgs::SetBoolRequest, msgs::SetBoolResponse>,
    step: Serve<msgs::StepRequest, msgs::StepResponse>,
    /// Samples and service replies not sent: a reliable subscriber's send
    /// window is full (it does not acknowledge what it receives).
    unsent: Arc<AtomicU64>,
}

/// A publisher that never waits (see [`Endpoints::create`]) and counts in
/// `unsent` what it could not send.
struct Out<M: serde::Serialize> {
    publisher: ros2_client::Publisher<M>,
    unsent: Arc<AtomicU64>,
}

impl<M: serde::Serialize> Out<M> {
    fn publish(&self, m: M) {
        if self.publisher.publish(m).is_err() {
            self.unsent.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// A service server whose replies never wait and are counted in `unsent`
/// when they cannot be sent.
struct Serve<Q: ros2_client::Message, R: ros2_client::Message> {
    server: ros2_client::Server<Q, R>,
    unsent: Arc<AtomicU64>,
}

impl<Q: ros2_client::Message + 'static, R: ros2_client::Message + 'static> Serve<Q, R> {
    fn receive_request(&self) -> ros2_client::ReadResult<Option<(ros2_client::RmwRequestId, Q)>> {
        self.server.receive_request()
    }

    fn send_response(&self, id: ros2_client::RmwRequestId, r: R) {
        if self.server.send_response(id, r).is_err() {
            self.unsent.fetch_add(1, Ordering::Relaxed);
        }
    }
}

impl Endpoints {
    fn create(node: &mut ros2_client::Node, names: &Names) -> Result<Endpoints> {
        // A subscriber that stops acknowledging (a stopped process) fills a
        // reliable writer's send window (RustDDS: 8192 samples, 8 s of
        // /clock); a write then fails at once instead of waiting (100 ms a
        // write by default): the loop never waits on a subscriber, and what
        // is not sent is counted and logged (`Endpoints::unsent`).
        let reliable = QosProfile::publisher_default()
            .reliability(ros2_client::qos::Reliability::Reliable {
                when_full: ros2_client::qos::WhenFull::Fail,
            })
            .history(ros2_client::qos::History::KeepLast { depth: 10 });
        let clock_qos = reliable
            .clone()
            .history(ros2_client::qos::History::KeepLast { depth: 1 });
        let sub_qos = reliable
            .clone()
            .history(ros2_client::qos::History::KeepLast { depth: 100 });
        let latched = reliable
            .clone()
            .durability(ros2_client::qos::Durability::TransientLocal)
            .history(ros2_client::qos::History::KeepLast { depth: 1 });
        let unsent = Arc::new(AtomicU64::new(0));
        macro_rules! publisher {
            ($t:ty, $n:expr, $q:expr) => {{
                let topic = node
                    .create_topic(&name($n)?, type_name(<$t>::NAME), &$q)
                    .map_err(|e| anyhow!("topic {}: {e:?}", $n))?;
                Out {
                    publisher: node
                        .create_publisher::<$t>(&topic, None)
                        .map_err(|e| anyhow!("publisher {}: {e:?}", $n))?,
                    unsent: unsent.clone(),
                }
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
                Serve {
                    server: node
                        .create_server::<$req, $resp>(
                            ServiceMapping::Enhanced,
                            &name($n)?,
                            &ServiceTypeName::new($pkg, $ty),
                            reliable.clone(),
                            reliable.clone(),
                        )
                        .map_err(|e| anyhow!("service {}: {e:?}", $n))?,
                    unsent: unsent.clone(),
                }
            }};
        }
        Ok(Endpoints {
            points: publisher!(msgs::PointCloud2, &names.points, reliable),
            mesh: publisher!(msgs::Marker, &names.mesh, reliable),
            obstacle_markers: publisher!(msgs::MarkerArray, &names.obstacle_markers, reliable),
            body_wrench: publisher!(msgs::WrenchStamped, &names.body_wrench, reliable),
            body_points: publisher!(msgs::PointCloud2, &names.body_points, reliable),
            diagnostics: publisher!(msgs::DiagnosticArray, &names.diagnostics, reliable),
            clock: publisher!(msgs::Clock, &names.clock, clock_qos),
            scene_description: publisher!(msgs::StringMsg, &names.scene_description, latched),
            obstacles: subscription!(msgs::Obstacle, &names.obstacles),
            pins: subscription!(msgs::Pin, &names.pins),
            body: subscription!(msgs::Body, &names.body),
            body_mesh: subscription!(msgs::MeshGeometryStamped, &names.body_mesh),
            reset: server!(
                msgs::TriggerRequest,
                msgs::TriggerResponse,
                &names.reset,
                "std_srvs",
                "Trigger"
            ),
            set_paused: server!(
                msgs::SetBoolRequest,
                msgs::SetBoolResponse,
                &names.set_paused,
                "std_srvs",
                "SetBool"
            ),
            step: server!(
                msgs::StepRequest,
                msgs::StepResponse,
                &names.step,
                "garment_sim_msgs",
                "Step"
            ),
            unsent,
        })
    }
}

/// What the node counts and reports in `diagnostics`.
struct Counters {
    /// Messages refused (bad content).
    rejected: u64,
    /// Messages dropped (more than `max_messages_per_step` between two steps).
    dropped: u64,
    /// Dropped since the last log line about it.
    dropped_now: u64,
    last_drop_log: Instant,
    /// Samples and service replies not sent ([`Endpoints::unsent`]) at the
    /// last log line about them.
    unsent_logged: u64,
    last_unsent_log: Instant,
    last_error: String,
    /// Step times summed since the last publication.
    step_ms_sum: f64,
    step_count: u64,
    last_iterations: usize,
    real_time_factor: f64,
    publish_s: f64,
    publishes: u64,
}

/// The simulation as a ROS 2 node: its settings, its simulation and its
/// endpoints, and what the loop carries from one pass to the next.
struct Node {
    ros: ros2_client::Node,
    /// stderr and `/rosout`, written by their own threads.
    log: Log,
    /// Each input topic's lines, bounded in rate.
    topic_logs: Vec<TopicLog>,
    io: Endpoints,
    names: Names,
    fq: String,
    settings: Settings,
    loaded: Loaded,
    recorder: Option<SimRecorder>,
    /// The Foxglove live view (parameter `foxglove`).
    live: Option<crate::live::LiveView>,
    /// Simulated time of the last state recorded in the bag.
    last_recorded: Option<f64>,
    stop: Arc<AtomicBool>,
    counters: Counters,
    /// Recovers failed steps and counts them (`recovered_steps`).
    recovery: control::Recovery,
    frames: publish::FrameClock,
    /// Wall clock and simulated time the pacing counts from.
    pace_origin: (Instant, f64),
    /// Wall clock and simulated time of the last publication.
    last_publish: (Instant, f64),
    /// Steps asked for by `~/step` and not yet run, and the request to answer.
    pending_steps: u64,
    step_reply: Option<ros2_client::RmwRequestId>,
    /// Publish at the next pass whatever the rate (the scene changed).
    publish_now: bool,
    wall_start: Instant,
    steps_start: u64,
}

impl Node {
    /// Starts DDS, declares the parameters (from [`PARAMETERS`]), creates
    /// the endpoints and the bag, and spins ros2-client on its own thread.
    fn start(
        names: Names,
        fq: String,
        settings: Settings,
        loaded: Loaded,
        enclave: Option<&str>,
    ) -> Result<Node> {
        let domain: u16 = match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.is_empty() => v
                .parse()
                .map_err(|_| anyhow!("ROS_DOMAIN_ID = {v:?}: not a number 0–232"))?,
            _ => 0,
        };
        let (context, security_notes) = super::security::context(domain, enclave)?;
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
            s.set(n, &v).map_err(|e| format!("{e:#}"))
        }));
        let mut ros = context
            .new_node(
                NodeName::new(&names.namespace, &names.node)
                    .map_err(|e| anyhow!("node name: {e:?}"))?,
                opts,
            )
            .map_err(|e| anyhow!("cannot create node: {e:?}"))?;
        let io = Endpoints::create(&mut ros, &names)?;
        io.scene_description.publish(msgs::StringMsg {
            data: loaded.description.clone(),
        });
        let topics = crate::bag::TopicNames {
            points: names.points.clone(),
            mesh: names.mesh.clone(),
            obstacles: names.obstacle_markers.clone(),
            diagnostics: names.diagnostics.clone(),
            clock: names.clock.clone(),
            scene_description: names.scene_description.clone(),
        };
        let recorder = if settings.record_bag.is_empty() {
            None
        } else {
            let dir = PathBuf::from(&settings.record_bag);
            let rec = SimRecorder::create(
                &dir,
                &crate::bag::BagOptions::default(),
                &topics,
                &loaded.description,
            )
            .with_context(|| format!("parameter record_bag = {:?}", settings.record_bag))?;
            Some(rec)
        };
        let live = if settings.foxglove.is_empty() {
            None
        } else {
            let addr = crate::live::parse_addr(&settings.foxglove)?;
            let view = crate::live::LiveView::start_with(addr, &settings.frame_id, &topics)
                .with_context(|| format!("parameter foxglove = {:?}", settings.foxglove))?;
            Some(view)
        };
        let spinner = ros
            .spinner()
            .map_err(|e| anyhow!("cannot start the spinner: {e:?}"))?;
        std::thread::Builder::new()
            .name("ros2-spinner".into())
            .spawn(move || {
                let _ = futures::executor::block_on(spinner.spin());
            })?;
        let stop = crate::scene::run::stop_flag()?;
        let log = Log::new(Some(ros.logging_handle()));
        for (warning, line) in security_notes {
            if warning {
                log.warn(&line);
            } else {
                log.info(&line);
            }
        }
        let topic_logs = [&names.obstacles, &names.pins, &names.body, &names.body_mesh]
            .map(|t| TopicLog::new(t))
            .to_vec();
        let t0 = loaded.sim.time;
        let node = Node {
            ros,
            log,
            topic_logs,
            io,
            fq,
            recorder,
            live,
            last_recorded: None,
            stop,
            recovery: control::Recovery::default(),
            counters: Counters {
                rejected: 0,
                dropped: 0,
                dropped_now: 0,
                last_drop_log: Instant::now() - Duration::from_secs(10),
                unsent_logged: 0,
                last_unsent_log: Instant::now() - Duration::from_secs(10),
                last_error: String::new(),
                step_ms_sum: 0.0,
                step_count: 0,
                last_iterations: 0,
                real_time_factor: 0.0,
                publish_s: 0.0,
                publishes: 0,
            },
            frames: publish::FrameClock::new(t0),
            pace_origin: (Instant::now(), t0),
            last_publish: (Instant::now(), t0),
            pending_steps: 0,
            step_reply: None,
            publish_now: true,
            wall_start: Instant::now(),
            steps_start: loaded.sim.steps,
            names,
            settings,
            loaded,
        };
        if let Some(l) = &node.live {
            node.info(&format!(
                "Foxglove live view on {} (Foxglove: Open connection → Foxglove WebSocket)",
                l.url()
            ));
        }
        node.info(&format!(
            "node {}: scene {} ({} vertices, dt = {} s), frame {:?}, publishing {} and {} at {} Hz",
            node.fq,
            node.settings.scene,
            node.loaded.sim.cloth.len(),
            node.loaded.sim.params().dt,
            node.settings.frame_id,
            node.names.points,
            node.names.mesh,
            node.settings.publish_rate
        ));
        Ok(node)
    }

    /// A line on stderr and `/rosout` (queued: never waits).
    fn info(&self, m: &str) {
        self.log.info(m);
    }

    fn warn(&self, m: &str) {
        self.log.warn(m);
    }

    /// The loop: apply parameter changes, take messages, serve services,
    /// step, publish, pace; until a signal or `duration`.
    fn run(mut self) -> Result<()> {
        // the first pass publishes (and records) the initial state before any step
        let mut initial = true;
        loop {
            if self.stop.load(Ordering::Relaxed) {
                self.info(&format!(
                    "stopping (signal) at t = {:.3} s",
                    self.loaded.sim.time
                ));
                break;
            }
            self.apply_parameters();
            self.take_messages();
            self.serve();
            let running = !self.settings.paused || self.pending_steps > 0;
            if running && !initial {
                self.step();
            }
            self.publish(running);
            initial = false;
            let d = self.settings.duration;
            if d > 0.0 && self.loaded.sim.time + 1e-12 >= d {
                self.info(&format!("duration {d} s reached"));
                break;
            }
            self.pace(running);
        }
        self.finish();
        Ok(())
    }

    /// Reads the runtime parameters (those of [`PARAMETERS`] marked so) from
    /// the parameter services' store.
    fn apply_parameters(&mut self) {
        let before = self.settings.clone();
        for p in PARAMETERS.iter().filter(|p| p.runtime) {
            if let Some(v) = self.ros.get_parameter(p.name).as_ref().and_then(to_value) {
                if let Err(e) = p.set(&mut self.settings, &v) {
                    self.warn(&format!("{e:#}"));
                }
            }
        }
        if self.settings.real_time_factor != before.real_time_factor
            || self.settings.paused != before.paused
        {
            self.pace_origin = (Instant::now(), self.loaded.sim.time);
        }
    }

    /// Applies the obstacle, body and pin messages that arrived since the last
    /// pass, at most `max_messages_per_step` per topic (the rest are dropped
    /// and counted); refused and undecodable ones are counted, and logged at
    /// a bounded rate ([`TopicLog`]).
    fn take_messages(&mut self) {
        let cap = self.settings.max_messages_per_step as usize;
        let obstacles = &self.io.obstacles;
        let taken = drain(|| obstacles.take().map(|m| m.map(|(m, _)| m)), cap);
        let topic = self.names.obstacles.clone();
        let applied = self.apply_taken(taken, &topic, |node, m| {
            control::apply_obstacle(
                &mut node.loaded.sim,
                &mut node.loaded.registry,
                m,
                &node.settings.frame_id,
                node.settings.max_mesh_triangles as usize,
            )
        });
        // the obstacles changed: published at once (refused ones change nothing)
        if applied > 0 {
            self.publish_now = true;
        }
        let bodies = &self.io.body;
        let taken = drain(|| bodies.take().map(|m| m.map(|(m, _)| m)), cap);
        let topic = self.names.body.clone();
        self.apply_taken(taken, &topic, |node, m| {
            let l = &mut node.loaded;
            let input = super::body::BodyInput::from_body(m);
            l.bodies
                .apply(&mut l.sim, &mut l.registry, &input, &node.settings.frame_id)
        });
        let meshes = &self.io.body_mesh;
        let taken = drain(|| meshes.take().map(|m| m.map(|(m, _)| m)), cap);
        let topic = self.names.body_mesh.clone();
        self.apply_taken(taken, &topic, |node, m| {
            let (l, s) = (&mut node.loaded, &node.settings);
            let input = l
                .bodies
                .mesh_input(m, s.body_mesh_thickness, s.body_mesh_friction);
            l.bodies
                .apply(&mut l.sim, &mut l.registry, &input, &s.frame_id)
        });
        let pins = &self.io.pins;
        let taken = drain(|| pins.take().map(|m| m.map(|(m, _)| m)), cap);
        let topic = self.names.pins.clone();
        self.apply_taken(taken, &topic, |node, m| {
            control::apply_pin(
                &mut node.loaded.sim,
                node.loaded.worn.as_ref().map(|w| &w.garment),
                m,
                &node.settings.frame_id,
            )
        });
        let now = Instant::now();
        for l in &mut self.topic_logs {
            if let Some((level, line)) = l.summary(now) {
                self.log.line(level, &line);
            }
        }
        let unsent = self.io.unsent.load(Ordering::Relaxed);
        let c = &mut self.counters;
        if unsent > c.unsent_logged && c.last_unsent_log.elapsed() > Duration::from_secs(1) {
            let m = format!(
                "{} messages (samples or service replies) not sent: a subscriber does not \
                 acknowledge what it receives and its reliable window is full; the node does \
                 not wait for it ({unsent} since the start)",
                unsent - c.unsent_logged
            );
            c.unsent_logged = unsent;
            c.last_unsent_log = Instant::now();
            self.warn(&m);
        }
        let c = &mut self.counters;
        if c.dropped_now > 0 && c.last_drop_log.elapsed() > Duration::from_secs(1) {
            c.last_error = format!(
                "dropped {} messages arriving faster than the simulation steps \
                 (max_messages_per_step = {cap} per topic)",
                c.dropped_now
            );
            c.dropped_now = 0;
            c.last_drop_log = Instant::now();
            let m = c.last_error.clone();
            self.warn(&m);
        }
    }

    /// Applies what [`drain`] took from one topic with `apply`: messages
    /// beyond the cap are counted as dropped, undecodable ones (CDR of another
    /// type or cut short) and refused ones are counted as rejected. Returns
    /// how many were applied.
    fn apply_taken<M>(
        &mut self,
        (got, undecodable): (Vec<Option<M>>, Vec<String>),
        topic: &str,
        apply: impl Fn(&mut Self, &M) -> std::result::Result<String, String>,
    ) -> usize {
        for e in undecodable {
            self.report(Outcome::Undecodable(e), topic);
        }
        if got.iter().any(|m| m.is_some()) {
            let l = &self.loaded;
            self.recovery.before_change(&l.sim, &l.registry);
        }
        let mut applied = 0;
        for m in got {
            match m {
                Some(m) => {
                    let outcome = match apply(self, &m) {
                        Ok(what) => {
                            applied += 1;
                            Outcome::Applied(what)
                        }
                        Err(why) => Outcome::Refused(why),
                    };
                    self.report(outcome, topic);
                }
                None => {
                    self.counters.dropped += 1;
                    self.counters.dropped_now += 1;
                }
            }
        }
        applied
    }

    /// Counts a refusal, and logs what a message did through its topic's
    /// [`TopicLog`].
    fn report(&mut self, outcome: Outcome, topic: &str) {
        match &outcome {
            Outcome::Applied(_) => {}
            Outcome::Refused(why) => {
                self.counters.rejected += 1;
                self.counters.last_error = why.clone();
            }
            Outcome::Undecodable(why) => {
                self.counters.rejected += 1;
                self.counters.last_error = format!("undecodable message (CDR) on {topic}: {why}");
            }
        }
        let now = Instant::now();
        let line = match self.topic_logs.iter_mut().find(|l| l.topic() == topic) {
            Some(l) => l.note(now, outcome),
            None => Some((super::intake::Level::Warn, format!("{topic}: {outcome:?}"))),
        };
        if let Some((level, line)) = line {
            self.log.line(level, &line);
        }
    }

    /// Answers `~/reset`, `~/set_paused` and `~/step`, at most
    /// `max_messages_per_step` requests of each a pass (the rest wait for
    /// the next); the `~/reset` requests of a pass share one reload.
    fn serve(&mut self) {
        let cap = self.settings.max_messages_per_step as usize;
        let mut resets = Vec::new();
        while resets.len() < cap {
            match self.io.reset.receive_request() {
                Ok(Some((id, _))) => resets.push(id),
                _ => break,
            }
        }
        if !resets.is_empty() {
            let resp = self.reset();
            for id in resets {
                self.io.reset.send_response(id, resp.clone());
            }
        }
        let mut served = 0;
        while served < cap {
            let Ok(Some((id, req))) = self.io.set_paused.receive_request() else {
                break;
            };
            served += 1;
            let _ = self
                .ros
                .set_parameter("paused", ParameterValue::Boolean(req.data));
            self.settings.paused = req.data;
            self.pace_origin = (Instant::now(), self.loaded.sim.time);
            let what = if req.data { "paused" } else { "running" };
            self.info(what);
            self.io.set_paused.send_response(
                id,
                msgs::SetBoolResponse {
                    success: true,
                    message: what.into(),
                },
            );
        }
        served = 0;
        while served < cap {
            let Ok(Some((id, req))) = self.io.step.receive_request() else {
                break;
            };
            served += 1;
            let now = msgs::Time::from_secs(self.loaded.sim.time);
            if !self.settings.paused {
                self.io.step.send_response(
                    id,
                    msgs::StepResponse {
                        success: false,
                        message: "not paused: call ~/set_paused true first".into(),
                        sim_time: now,
                    },
                );
            } else {
                if let Some(old) = self.step_reply.replace(id) {
                    // a second request before the first is done: answer the first now
                    self.io.step.send_response(
                        old,
                        msgs::StepResponse {
                            success: true,
                            message: "merged with a later request".into(),
                            sim_time: now,
                        },
                    );
                }
                self.pending_steps += req.steps as u64;
            }
        }
    }

    /// Reloads the scene named by the parameter `scene` (a scene that fails
    /// to load leaves the old one running).
    fn reset(&mut self) -> msgs::TriggerResponse {
        // the parameters read on reset besides at start
        for name in ["scene", "self_collision", "obstacle_edges"] {
            let fresh = self
                .ros
                .get_parameter(name)
                .as_ref()
                .and_then(to_value)
                .map(|v| self.settings.set(name, &v));
            if let Some(Err(e)) = fresh {
                self.warn(&format!("{e:#}"));
            }
        }
        match load(&self.settings) {
            Ok(l) => {
                self.loaded = l;
                self.recovery.forget();
                self.io.scene_description.publish(msgs::StringMsg {
                    data: self.loaded.description.clone(),
                });
                self.frames = publish::FrameClock::new(self.loaded.sim.time);
                self.pace_origin = (Instant::now(), self.loaded.sim.time);
                self.pending_steps = 0;
                if let Some(l) = &self.live {
                    l.restart();
                }
                if let Some(rec) = self.recorder.as_mut() {
                    // frames of the new run follow the old ones in the bag
                    let gap = (1e9 / self.settings.publish_rate) as u64;
                    rec.restart(&self.loaded.description, gap);
                    self.last_recorded = None;
                }
                self.info(&format!("reset: scene {}", self.settings.scene));
                self.publish_now = true;
                msgs::TriggerResponse {
                    success: true,
                    message: format!("scene {} reloaded", self.settings.scene),
                }
            }
            Err(e) => {
                self.warn(&format!("reset failed: {e:#}"));
                msgs::TriggerResponse {
                    success: false,
                    message: format!("{e:#}"),
                }
            }
        }
    }

    /// One step; a step that fails is recovered from the last good state
    /// ([`control::Recovery`]: without the messages since, or at rest),
    /// logged and counted in `recovered_steps`; only if that fails too the
    /// simulation pauses with the error in `diagnostics` until `~/reset`.
    /// Publishes `/clock` at up to 1 kHz and answers `~/step` when its steps
    /// are done.
    fn step(&mut self) {
        let l = &mut self.loaded;
        let clock_every = ((1e-3 / l.sim.params().dt).round() as u64).max(1);
        let stepped = self.recovery.step(&mut l.sim, &mut l.registry);
        // between steps the node publishes, reads parameters and messages,
        // or sleeps: the simulation's workers sleep meanwhile instead of
        // spinning (the next step wakes them)
        l.sim.rest_threads();
        let stats = match stepped {
            Ok(control::Stepped::Ok(st)) => Some(st),
            Ok(control::Stepped::Recovered {
                stats,
                error,
                undone,
            }) => {
                self.counters.last_error = format!(
                    "step failed at t = {:.4} s: {error}; recovered: {undone}",
                    self.loaded.sim.time - self.loaded.sim.params().dt
                );
                let m = self.counters.last_error.clone();
                self.warn(&m);
                self.publish_now = true;
                Some(stats)
            }
            Err(e) => {
                self.counters.last_error =
                    format!("step failed at t = {:.4} s: {e}", self.loaded.sim.time);
                let m = format!("{}; pausing (call ~/reset)", self.counters.last_error);
                self.warn(&m);
                self.settings.paused = true;
                let _ = self
                    .ros
                    .set_parameter("paused", ParameterValue::Boolean(true));
                self.pending_steps = 0;
                None
            }
        };
        if let Some(st) = stats {
            self.counters.step_ms_sum += st.total_s * 1e3;
            self.counters.step_count += 1;
            self.counters.last_iterations = st.iterations;
        }
        self.pending_steps = self.pending_steps.saturating_sub(1);
        let sim = &self.loaded.sim;
        if sim.steps.is_multiple_of(clock_every) {
            self.io.clock.publish(msgs::Clock {
                clock: msgs::Time::from_secs(sim.time),
            });
        }
        if self.pending_steps == 0 {
            if let Some(id) = self.step_reply.take() {
                self.io.step.send_response(
                    id,
                    msgs::StepResponse {
                        success: true,
                        message: format!("t = {:.4} s", sim.time),
                        sim_time: msgs::Time::from_secs(sim.time),
                    },
                );
                self.publish_now = true;
            }
        }
    }

    /// Publishes (and records) the state when a frame is due at
    /// `publish_rate` in simulated time, when the scene changed, or, while
    /// paused, at `publish_rate` in wall time.
    fn publish(&mut self, running: bool) {
        let rate = self.settings.publish_rate;
        let paused_due = !running && self.last_publish.0.elapsed().as_secs_f64() >= 1.0 / rate;
        let due = self.frames.due(self.loaded.sim.time, rate);
        if !(due || self.publish_now || paused_due) {
            return;
        }
        let sim = &self.loaded.sim;
        let c = &mut self.counters;
        let now = Instant::now();
        let wall = now.duration_since(self.last_publish.0).as_secs_f64();
        if wall > 0.0 && running {
            c.real_time_factor = (sim.time - self.last_publish.1) / wall;
        }
        self.last_publish = (now, sim.time);
        let t_pub = Instant::now();
        let h = publish::header(sim, &self.settings.frame_id);
        let cloud = cloud(&self.loaded, h.clone());
        let mesh = publish::cloth_marker(sim, h.clone());
        let obstacles = publish::obstacle_markers(sim, h.clone());
        let on_body = body_forces(sim, h.clone());
        let (body_messages, body_late, body_refused) = self.loaded.bodies.counts();
        let fig = publish::DiagnosticFigures {
            step_time_ms: if c.step_count > 0 {
                c.step_ms_sum / c.step_count as f64
            } else {
                0.0
            },
            iterations: c.last_iterations,
            real_time_factor: c.real_time_factor,
            rejected_messages: c.rejected,
            dropped_messages: c.dropped,
            recovered_steps: self.recovery.recovered,
            paused: self.settings.paused,
            last_error: c.last_error.clone(),
            body_messages,
            body_late,
            body_refused,
        };
        let diag = publish::diagnostics(sim, h.clone(), &fig);
        let clock = msgs::Clock { clock: h.stamp };
        // the bag gets what is published, once per simulated state (not
        // the repeats published while paused) unless an obstacle changed
        let new_state = self.last_recorded != Some(sim.time) || self.publish_now;
        let frame = crate::bag::Frame {
            cloud: &cloud,
            mesh: &mesh,
            obstacles: &obstacles,
            diagnostics: &diag,
            clock: &clock,
        };
        if let Some(l) = &self.live {
            l.publish_frame(&frame);
        }
        let failed = self
            .recorder
            .as_mut()
            .filter(|_| new_state)
            .and_then(|rec| match rec.record_frame(&frame) {
                Ok(()) => {
                    self.last_recorded = Some(sim.time);
                    None
                }
                Err(e) => Some(e),
            });
        if let Some(e) = failed {
            let bag = &self.settings.record_bag;
            c.last_error = format!("bag {bag}: {e:#}");
            let m = format!("{}; recording stopped, the bag is closed", c.last_error);
            let closed = self.recorder.take().map(|r| r.finish());
            self.warn(&m);
            if let Some(Err(e)) = closed {
                self.warn(&format!("bag {bag}: {e:#}"));
            }
        }
        let io = &self.io;
        io.points.publish(cloud);
        io.mesh.publish(mesh);
        io.obstacle_markers.publish(obstacles);
        if let Some((wrench, points)) = on_body {
            io.body_wrench.publish(wrench);
            if let Some(p) = points {
                io.body_points.publish(p);
            }
        }
        io.diagnostics.publish(diag);
        io.clock.publish(clock);
        let c = &mut self.counters;
        c.publish_s += t_pub.elapsed().as_secs_f64();
        c.publishes += 1;
        c.step_ms_sum = 0.0;
        c.step_count = 0;
        self.publish_now = false;
    }

    /// Waits for the wall clock at `real_time_factor` (never catching up
    /// more than half a second), or briefly while paused.
    fn pace(&mut self, running: bool) {
        let rtf = self.settings.real_time_factor;
        if !running {
            std::thread::sleep(Duration::from_millis(5));
        } else if rtf > 0.0 {
            let due = (self.loaded.sim.time - self.pace_origin.1) / rtf;
            let ahead = due - self.pace_origin.0.elapsed().as_secs_f64();
            if ahead > 0.0 {
                std::thread::sleep(Duration::from_secs_f64(ahead));
            } else if ahead < -0.5 {
                // too slow to keep up: do not try to catch up later
                self.pace_origin = (Instant::now(), self.loaded.sim.time);
            }
        }
    }

    /// The last `/clock`, the bag closed with the final state, a summary.
    fn finish(mut self) {
        let sim = &self.loaded.sim;
        self.io.clock.publish(msgs::Clock {
            clock: msgs::Time::from_secs(sim.time),
        });
        if let Some(mut rec) = self.recorder.take() {
            let bag = &self.settings.record_bag;
            if self.last_recorded != Some(sim.time) {
                // the state the node stopped in (as `drape --bag` records it)
                let fig = publish::DiagnosticFigures::default();
                if let Err(e) = rec.record(sim, &self.settings.frame_id, &fig) {
                    self.warn(&format!("bag {bag}: {e:#}"));
                }
            }
            match rec.finish() {
                Ok(b) => self.info(&format!(
                    "bag {}: {} messages, {:.3} s, {:.2} MiB{}",
                    b.dir.display(),
                    b.message_count,
                    b.duration_s(),
                    b.bytes as f64 / (1024.0 * 1024.0),
                    if crate::scene::run::interrupted_again() {
                        " (interrupted again while it was being closed: it was finished first)"
                    } else {
                        ""
                    }
                )),
                Err(e) => self.warn(&format!("bag {bag}: {e:#}")),
            }
        }
        let now = Instant::now();
        for l in &mut self.topic_logs {
            if let Some((level, line)) = l.summary_now(now) {
                self.log.line(level, &line);
            }
        }
        let wall = self.wall_start.elapsed().as_secs_f64();
        let steps = sim.steps.saturating_sub(self.steps_start).max(1);
        let c = &self.counters;
        self.log.info(&format!(
            "stopped at t = {:.3} s after {} steps in {:.2} s wall ({:.3} ms per step); \
             {} messages rejected, {} dropped, {} failed steps recovered; {} publications, \
             {:.3} ms each",
            sim.time,
            sim.steps,
            wall,
            1e3 * wall / steps as f64,
            c.rejected,
            c.dropped,
            self.recovery.recovered,
            c.publishes,
            1e3 * c.publish_s / c.publishes.max(1) as f64
        ));
        // what is queued, unless stderr or /rosout stays blocked
        self.log.finish(Duration::from_secs(2));
        std::thread::sleep(Duration::from_millis(200)); // let rosout and the last samples go
    }
}

#[cfg(test)]
mod tests {
    use super::drain;

    /// The shipped skirt trial as the node's scene, at 4 cm.
    fn skirt_trial() -> super::Loaded {
        let scene = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("config/trials/skirt_on_anny.yaml")
            .display()
            .to_string();
        super::load(&super::Settings {
            scene,
            spacing: 0.04,
            ..Default::default()
        })
        .unwrap()
    }

    /// The node's `self_collision` parameter reaches the simulation: unset,
    /// the scene's or trial's own (off in the table drape, on in the
    /// shipped skirt trial); set, it wins over either. `obstacle_edges` too
    /// (off in both files).
    #[test]
    fn the_self_collision_parameter_reaches_the_simulation() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let table = root
            .join("config/scenes/table_drape.yaml")
            .display()
            .to_string();
        let skirt = root
            .join("config/trials/skirt_on_anny.yaml")
            .display()
            .to_string();
        // (scene, the two parameters, what the simulation gets)
        for (scene, sc, oe, want) in [
            (&table, None, None, (false, false)),
            (&table, Some(true), Some(true), (true, true)),
            (&skirt, None, None, (true, false)),
            (&skirt, Some(false), Some(true), (false, true)),
        ] {
            let l = super::load(&super::Settings {
                scene: scene.clone(),
                spacing: 0.05,
                self_collision: sc,
                obstacle_edges: oe,
                ..Default::default()
            })
            .unwrap();
            let p = l.sim.params();
            assert_eq!(
                (p.self_collision, p.obstacle_edges),
                want,
                "{scene} {sc:?} {oe:?}"
            );
        }
    }

    #[test]
    fn a_garment_trial_is_a_scene_the_node_loads_sewn() {
        let l = skirt_trial();
        // sewn: every stitch closed within 2 mm; the body is the obstacle
        let worst = l
            .sim
            .cloth
            .seams()
            .iter()
            .map(|st| st.gap(l.sim.cloth.positions()).norm())
            .fold(0.0, f64::max);
        assert!(!l.sim.cloth.seams().is_empty());
        assert!(worst < 2e-3, "seam gap {worst} m after sewing");
        assert_eq!(l.sim.obstacles().len(), 1);
        assert_eq!(l.sim.obstacles()[0].id, "body");
        assert!(l.sim.params().gravity.norm() > 9.0);
        assert!(l.description.contains("garment_sim/trial_description/1"));
        assert!(l.description.contains("skirt_front"));
        // its cloud carries the fit fields; read back by field name and offset
        let mut l = l;
        for _ in 0..20 {
            l.sim.step().unwrap();
        }
        let c = super::cloud(&l, crate::msgs::Header::default());
        let names: Vec<&str> = c.fields.iter().map(|f| f.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "x",
                "y",
                "z",
                "strain",
                "speed",
                "strain_warp",
                "strain_weft",
                "strain_bias",
                "pressure",
                "distance"
            ]
        );
        let field = |name: &str| -> Vec<f64> {
            let f = c.fields.iter().find(|f| f.name == name).unwrap();
            (0..c.width as usize)
                .map(|i| {
                    let o = i * c.point_step as usize + f.offset as usize;
                    f32::from_le_bytes(c.data[o..o + 4].try_into().unwrap()) as f64
                })
                .collect()
        };
        let (z, d, p) = (field("z"), field("distance"), field("pressure"));
        let w = l.worn.as_ref().unwrap();
        for i in 0..l.sim.cloth.len() {
            let x = l.sim.cloth.positions()[i];
            assert!((z[i] - x.z).abs() < 1e-5);
            // distance: the body's own projection, not the contacts'
            let q = w.body.proximity(&x).distance;
            assert!((d[i] - q).abs() < 1e-6, "{} vs {q}", d[i]);
        }
        // pressure × area sums to the normal force the contacts carry
        let rho = l.sim.fabric.areal_mass;
        let normals = l.sim.contact_normals();
        let normal: f64 = l
            .sim
            .contact_forces()
            .iter()
            .zip(&normals)
            .map(|(f, n)| f.dot(n).max(0.0))
            .sum();
        let integral: f64 = (0..p.len()).map(|i| p[i] * l.sim.cloth.mass[i] / rho).sum();
        assert!(
            normal > 0.0 && (integral / normal - 1.0).abs() < 1e-4,
            "{integral} vs {normal}"
        );
    }

    #[test]
    fn a_garment_pin_names_its_panel_and_grid_node() {
        use crate::msgs::{Header, Pin};
        use crate::ros::control::apply_pin;
        let mut l = skirt_trial();
        let g = l.worn.take().unwrap().garment;
        let p = &g.panels[1];
        // an inner node (two rings of nodes around it kept: none of its
        // neighbours moved onto the outline) and its warp and weft neighbours
        let [nx, ny] = p.grid;
        let (i, j) = (2..ny.saturating_sub(2))
            .flat_map(|j| (2..nx.saturating_sub(2)).map(move |i| (i, j)))
            .find(|&(i, j)| {
                (i - 2..=i + 2).all(|a| (j - 2..=j + 2).all(|b| p.vertex(a, b).is_ok()))
            })
            .unwrap();
        let m = Pin {
            header: Header {
                frame_id: "world".into(),
                ..Default::default()
            },
            operation: Pin::PIN,
            grid_i: vec![i as u32, (i + 1) as u32, i as u32],
            grid_j: vec![j as u32, j as u32, (j + 1) as u32],
            panel: p.name.clone(),
            ..Default::default()
        };
        apply_pin(&mut l.sim, Some(&g), &m, "world").unwrap();
        let v: Vec<usize> = l.sim.pins().iter().map(|q| q.vertex).collect();
        assert_eq!(v.len(), 3);
        assert!(v.iter().all(|&k| k >= p.first && k < p.first + p.count));
        // in the panel's coordinates, (i + 1, j) is one spacing along the
        // grain from (i, j) and (i, j + 1) one spacing across it
        let uv = |k: usize| p.uv[k - p.first];
        let (a, b, c) = (uv(v[0]), uv(v[1]), uv(v[2]));
        let along = [b[0] - a[0], b[1] - a[1]];
        let across = [c[0] - a[0], c[1] - a[1]];
        let h = 0.04;
        assert!(
            (along[0] - h * p.grain[0]).abs() < 1e-9 && (along[1] - h * p.grain[1]).abs() < 1e-9
        );
        assert!(
            (across[0] + h * p.grain[1]).abs() < 1e-9 && (across[1] - h * p.grain[0]).abs() < 1e-9
        );
        // what is refused, and why
        for (panel, gi, want) in [
            ("sleeve", vec![i as u32], "no panel \"sleeve\""),
            ("", vec![i as u32], "need the panel"),
            (p.name.as_str(), vec![nx as u32], "outside panel"),
        ] {
            let bad = Pin {
                panel: panel.into(),
                grid_i: gi,
                grid_j: vec![j as u32],
                ..m.clone()
            };
            let e = apply_pin(&mut l.sim, Some(&g), &bad, "world").unwrap_err();
            assert!(e.contains(want), "{e}");
        }
        let sheet = Pin {
            grid_i: vec![0],
            grid_j: vec![0],
            ..m.clone()
        };
        let e = apply_pin(&mut l.sim, None, &sheet, "world").unwrap_err();
        assert!(e.contains("single sheet"), "{e}");
    }

    #[test]
    fn undecodable_messages_are_reported_and_do_not_hide_the_next() {
        // a subscription holding: good, undecodable, good, good (cap 2)
        let mut queue: Vec<Result<Option<u32>, &str>> = vec![
            Ok(Some(1)),
            Err("deserialization: unexpected end of CDR"),
            Ok(Some(2)),
            Ok(Some(3)),
            Ok(None),
        ];
        queue.reverse();
        let (got, errors) = drain(|| queue.pop().unwrap_or(Ok(None)), 2);
        assert_eq!(got, vec![Some(1), Some(2), None]);
        assert_eq!(
            errors,
            vec!["deserialization: unexpected end of CDR".to_string()]
        );
        // a reader that keeps failing: the loop ends after cap + 1 errors
        let (got, errors) = drain(|| Err::<Option<u32>, _>("bad"), 3);
        assert!(got.is_empty());
        assert_eq!(errors.len(), 4);
    }
}
