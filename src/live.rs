//! A live view of a simulation in Foxglove, without ROS: a Foxglove WebSocket
//! server (the `foxglove` SDK) publishing the node's topics with the node's
//! messages, so the Foxglove app (Open connection → Foxglove WebSocket →
//! `ws://127.0.0.1:8765`) shows the cloth as it moves.
//!
//! Channels: `/cloth/points` (sensor_msgs/msg/PointCloud2), `/cloth/mesh`
//! (visualization_msgs/msg/Marker), `/obstacles/markers`
//! (visualization_msgs/msg/MarkerArray), `/diagnostics`
//! (diagnostic_msgs/msg/DiagnosticArray) and `/clock`
//! (rosgraph_msgs/msg/Clock) by default ([`TopicNames`]), each with schema
//! encoding `ros2msg` (the full definition with its dependencies, as in our
//! bags: [`crate::msgs::definitions`]) and message encoding `cdr` (CDR with
//! its 4-byte encapsulation header, [`crate::msgs::to_cdr`]). The
//! messages are built by [`crate::msgs::publish`], the same functions the node
//! and the bag recorder use. A message is logged with the simulated time as
//! its time (nanoseconds, the header stamp), and the server offers the `time`
//! capability and broadcasts the simulated time with each frame, as a ROS
//! bridge does for a node on simulated time.
//!
//! A message is built and encoded only while a client subscribes to its
//! channel, so a view nobody watches costs a few atomic loads per frame.
//! The server speaks the `foxglove.sdk.v1` subprotocol (the Foxglove app;
//! clients that offer only `foxglove.websocket.v1` are refused at the
//! handshake). It has no authentication: bind it to loopback (the default)
//! unless the network is trusted.

use crate::bag::{Frame, TopicNames};
use crate::msgs::definitions::schema_text;
use crate::msgs::publish::{self, DiagnosticFigures, FrameClock};
use crate::msgs::{to_cdr, Clock, DiagnosticArray, Marker, MarkerArray, PointCloud2, RosType};
use crate::run::{Control, Step};
use crate::solver::Simulation;
use anyhow::{anyhow, bail, Context as _, Result};
use foxglove::websocket::Capability;
use foxglove::{Context, PartialMetadata, RawChannel, Schema, WebSocketServer};
use serde::Serialize;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Foxglove's default address: loopback, port 8765.
pub const DEFAULT_ADDR: SocketAddr = SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), 8765);

/// Parses `ADDR:PORT` (`127.0.0.1:8765`, `[::1]:8765`) or a bare `PORT`
/// (on 127.0.0.1). Port 0 lets the system choose a free port
/// ([`LiveView::addr`] tells which).
pub fn parse_addr(s: &str) -> Result<SocketAddr> {
    if let Ok(port) = s.parse::<u16>() {
        return Ok(SocketAddr::new(IpAddr::V4(Ipv4Addr::LOCALHOST), port));
    }
    s.parse::<SocketAddr>().map_err(|_| {
        anyhow!("{s:?} is not ADDR:PORT (e.g. 127.0.0.1:8765) or a port number (give the scene before --foxglove)")
    })
}

/// A running Foxglove WebSocket server with the simulation's channels.
/// Dropping it (or [`LiveView::close`]) stops the server.
pub struct LiveView {
    // channels first: they are removed from the context when it drops
    points: Arc<RawChannel>,
    mesh: Arc<RawChannel>,
    obstacles: Arc<RawChannel>,
    diagnostics: Arc<RawChannel>,
    clock: Arc<RawChannel>,
    server: Option<foxglove::WebSocketServerHandle>,
    _context: Arc<Context>,
    addr: SocketAddr,
    frame_id: String,
}

fn channel(ctx: &Arc<Context>, topic: &str, type_name: &str) -> Result<Arc<RawChannel>> {
    let schema =
        schema_text(type_name).ok_or_else(|| anyhow!("no message definition for {type_name}"))?;
    ctx.channel_builder(topic)
        .message_encoding("cdr")
        .schema(Schema::new(type_name, "ros2msg", schema.into_bytes()))
        .build_raw()
        .with_context(|| format!("cannot create the channel {topic}"))
}

impl LiveView {
    /// Serves the default topics on `addr`, the messages' `frame_id` being
    /// `frame_id` (the node's `world` by default).
    pub fn start(addr: SocketAddr, frame_id: &str) -> Result<LiveView> {
        LiveView::start_with(addr, frame_id, &TopicNames::default())
    }

    /// As [`LiveView::start`], with the topic names given (the node passes
    /// its resolved names). `topics.scene_description` is not served: the
    /// protocol has no latched messages for clients that come later.
    pub fn start_with(addr: SocketAddr, frame_id: &str, topics: &TopicNames) -> Result<LiveView> {
        // a context of its own: several views (or the SDK's default context
        // used elsewhere) do not share channels
        let ctx = Context::new();
        let points = channel(&ctx, &topics.points, PointCloud2::NAME)?;
        let mesh = channel(&ctx, &topics.mesh, Marker::NAME)?;
        let obstacles = channel(&ctx, &topics.obstacles, MarkerArray::NAME)?;
        let diagnostics = channel(&ctx, &topics.diagnostics, DiagnosticArray::NAME)?;
        let clock = channel(&ctx, &topics.clock, Clock::NAME)?;
        let host = match addr.ip() {
            IpAddr::V4(ip) => ip.to_string(),
            IpAddr::V6(ip) => format!("[{ip}]"),
        };
        let server = WebSocketServer::new()
            .context(&ctx)
            .name("garment_sim")
            .bind(host, addr.port())
            .capabilities([Capability::Time])
            .start_blocking()
            .with_context(|| format!("cannot serve the Foxglove live view on {addr}"))?;
        let bound = SocketAddr::new(addr.ip(), server.port());
        Ok(LiveView {
            points,
            mesh,
            obstacles,
            diagnostics,
            clock,
            server: Some(server),
            _context: ctx,
            addr: bound,
            frame_id: frame_id.to_string(),
        })
    }

    /// The address served (with the port the system chose for port 0).
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The URL to open in Foxglove, e.g. `ws://127.0.0.1:8765`.
    pub fn url(&self) -> String {
        format!("ws://{}", self.addr)
    }

    /// A link that opens the Foxglove web app on this server.
    pub fn app_url(&self) -> String {
        self.server
            .as_ref()
            .map(|s| s.app_url().to_string())
            .unwrap_or_default()
    }

    /// Clients connected now.
    pub fn clients(&self) -> usize {
        self.server.as_ref().map_or(0, |s| s.client_count())
    }

    /// Whether a client subscribes to any of the channels.
    pub fn subscribed(&self) -> bool {
        self.channels().iter().any(|c| c.has_sinks())
    }

    fn channels(&self) -> [&Arc<RawChannel>; 5] {
        [
            &self.points,
            &self.mesh,
            &self.obstacles,
            &self.diagnostics,
            &self.clock,
        ]
    }

    /// Tells the clients the simulated time `t` (s).
    pub fn broadcast_time(&self, t: f64) {
        if let Some(s) = &self.server {
            s.broadcast_time(crate::msgs::Time::from_secs(t).nanos() as u64);
        }
    }

    /// Publishes the current state: the point cloud, the cloth marker, the
    /// obstacle markers, the diagnostics (with `figures`) and the clock, each
    /// stamped with the simulated time, after broadcasting that time. Only
    /// the subscribed channels' messages are built.
    pub fn publish(&self, sim: &Simulation, figures: &DiagnosticFigures) {
        let h = publish::header(sim, &self.frame_id);
        let t = h.stamp.nanos().max(0) as u64;
        self.broadcast_time(sim.time);
        let log = |ch: &RawChannel, bytes: Vec<u8>| {
            ch.log_with_meta(&bytes, PartialMetadata::with_log_time(t));
        };
        if self.points.has_sinks() {
            log(&self.points, to_cdr(&publish::cloud(sim, h.clone())));
        }
        if self.mesh.has_sinks() {
            log(&self.mesh, to_cdr(&publish::cloth_marker(sim, h.clone())));
        }
        if self.obstacles.has_sinks() {
            let m = publish::obstacle_markers(sim, h.clone());
            log(&self.obstacles, to_cdr(&m));
        }
        if self.diagnostics.has_sinks() {
            let d = publish::diagnostics(sim, h.clone(), figures);
            log(&self.diagnostics, to_cdr(&d));
        }
        if self.clock.has_sinks() {
            log(&self.clock, to_cdr(&Clock { clock: h.stamp }));
        }
    }

    /// Publishes messages already built (the node publishes what it sends
    /// over DDS), logged at the cloud's header stamp.
    pub fn publish_frame(&self, f: &Frame) {
        let stamp = f.cloud.header.stamp;
        let t = stamp.nanos().max(0) as u64;
        if let Some(s) = &self.server {
            s.broadcast_time(t);
        }
        fn log<T: Serialize>(ch: &RawChannel, t: u64, msg: &T) {
            if ch.has_sinks() {
                ch.log_with_meta(&to_cdr(msg), PartialMetadata::with_log_time(t));
            }
        }
        log(&self.points, t, f.cloud);
        log(&self.mesh, t, f.mesh);
        log(&self.obstacles, t, f.obstacles);
        log(&self.diagnostics, t, f.diagnostics);
        log(&self.clock, t, f.clock);
    }

    /// The simulation restarted from t = 0 (the node's `~/reset`): clients
    /// are told the session changed, drop the messages they hold and follow
    /// the new run's time.
    pub fn restart(&self) {
        if let Some(s) = &self.server {
            s.clear_session(None);
        }
    }

    /// Waits until a client subscribes to a channel, then `settle` more (so
    /// that a viewer's other subscriptions arrive before the first frame).
    /// Gives up after `timeout` (`None`: no limit) or when `stop` is set.
    /// Returns whether a client subscribed.
    pub fn wait_for_subscriber(
        &self,
        timeout: Option<Duration>,
        settle: Duration,
        stop: &AtomicBool,
    ) -> bool {
        let start = Instant::now();
        while !self.subscribed() {
            if stop.load(Ordering::Relaxed) || timeout.is_some_and(|d| start.elapsed() >= d) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(settle);
        true
    }

    /// Keeps serving (the last messages sent stay on the viewers' screens)
    /// while a client is connected, until `stop` is set.
    pub fn linger(&self, stop: &AtomicBool) {
        while self.clients() > 0 && !stop.load(Ordering::Relaxed) {
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Stops the server: clients are sent a close frame (messages still
    /// queued for them are dropped) and the port is released (waiting at
    /// most 2 s for the connections to end).
    pub fn close(mut self) {
        self.stop_server();
    }

    fn stop_server(&mut self) {
        if let Some(s) = self.server.take() {
            let shutdown = s.stop();
            let (tx, rx) = std::sync::mpsc::channel();
            std::thread::spawn(move || {
                shutdown.wait_blocking();
                let _ = tx.send(());
            });
            let _ = rx.recv_timeout(Duration::from_secs(2));
        }
    }
}

impl Drop for LiveView {
    fn drop(&mut self) {
        self.stop_server();
    }
}

/// How `drape --foxglove` drives a run.
#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// Frames per simulated second (the scene's `output_rate`).
    pub rate_hz: f64,
    /// Simulated seconds per wall-clock second the run is held to (1: real
    /// time; at least 0.001); 0 runs as fast as the solver goes.
    pub pace: f64,
    /// Simulated time of the run's end: the state then is always published.
    pub end_time: f64,
}

/// The observer of a run shown live ([`crate::scene::run::drape`]): publishes
/// a frame at the first step at or after each multiple of 1/rate of simulated
/// time (as the node and the bags), the final state, and the state at which
/// `stop` ends the run; holds the run to its pace.
pub struct LiveRun<'a> {
    live: &'a LiveView,
    opts: LiveOptions,
    stop: &'a AtomicBool,
    clock: Option<FrameClock>,
    /// Wall clock and simulated time at the first call.
    origin: Option<(Instant, f64)>,
    /// Time spent sleeping to keep the pace.
    slept: Duration,
    /// At the last published frame: wall clock, steps, simulated time, slept.
    last: Option<(Instant, u64, f64, Duration)>,
    last_published: Option<u64>,
    /// Frames published.
    pub frames: u64,
}

impl<'a> LiveRun<'a> {
    pub fn new(live: &'a LiveView, opts: LiveOptions, stop: &'a AtomicBool) -> Result<LiveRun<'a>> {
        if !(opts.rate_hz.is_finite() && opts.rate_hz > 0.0) {
            bail!(
                "live view rate {} Hz: must be a finite number > 0",
                opts.rate_hz
            );
        }
        if !(opts.pace == 0.0 || (opts.pace.is_finite() && opts.pace >= 1e-3)) {
            bail!(
                "pace {}: must be 0 (no pacing) or at least 0.001",
                opts.pace
            );
        }
        Ok(LiveRun {
            live,
            opts,
            stop,
            clock: None,
            origin: None,
            slept: Duration::ZERO,
            last: None,
            last_published: None,
            frames: 0,
        })
    }

    /// Called before the first step and after each step.
    pub fn observe(&mut self, step: &Step) -> Result<Control> {
        let s = step.sim;
        let now = Instant::now();
        let (t0_wall, t0) = *self.origin.get_or_insert((now, s.time));
        if self.opts.pace > 0.0 {
            let due = t0_wall + Duration::from_secs_f64((s.time - t0).max(0.0) / self.opts.pace);
            if due > now {
                std::thread::sleep(due - now);
                self.slept += due - now;
            }
        }
        let stopping = self.stop.load(Ordering::Relaxed);
        let rate = self.opts.rate_hz;
        let due = self
            .clock
            .get_or_insert_with(|| FrameClock::new(s.time))
            .due(s.time, rate);
        let end = s.time + 0.5 * s.params().dt >= self.opts.end_time;
        if (due || end || stopping) && self.last_published != Some(s.steps) {
            let now = Instant::now();
            let (w, n, t, sl) = self.last.unwrap_or((t0_wall, s.steps, t0, Duration::ZERO));
            // the solver's own time: the wall time less the pacing sleeps
            let busy = (now.duration_since(w).saturating_sub(self.slept - sl)).as_secs_f64();
            let steps = s.steps - n;
            let fig = DiagnosticFigures {
                step_time_ms: if steps > 0 {
                    1e3 * busy / steps as f64
                } else {
                    0.0
                },
                real_time_factor: if busy > 0.0 { (s.time - t) / busy } else { 0.0 },
                ..Default::default()
            };
            self.live.publish(s, &fig);
            self.last = Some((now, s.steps, s.time, self.slept));
            self.last_published = Some(s.steps);
            self.frames += 1;
        }
        Ok(if stopping {
            Control::Stop
        } else {
            Control::Continue
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn addresses_parse_with_loopback_for_a_bare_port() {
        assert_eq!(
            parse_addr("9000").unwrap(),
            "127.0.0.1:9000".parse().unwrap()
        );
        assert_eq!(parse_addr("127.0.0.1:8765").unwrap(), DEFAULT_ADDR);
        assert_eq!(parse_addr("[::1]:0").unwrap(), "[::1]:0".parse().unwrap());
        assert!(parse_addr("scene.yaml").is_err());
        assert!(parse_addr("127.0.0.1").is_err());
    }
}
