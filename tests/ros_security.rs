//! The node in a secured ROS 2 graph (SROS2: DDS Security), built with the
//! cargo feature `security`. A keystore is made with openssl by
//! tools/sros2_keystore.sh (as `ros2 security` lays it out); the node gets
//! it from the standard environment (`ROS_SECURITY_ENABLE`,
//! `ROS_SECURITY_STRATEGY=Enforce`, `ROS_SECURITY_KEYSTORE`,
//! `ROS_SECURITY_ENCLAVE_OVERRIDE`). Its peers are ros2-client participants
//! on RustDDS (DDS Security's built-in plugins) in this test, and a Cyclone
//! DDS participant without security (tests/ros_security/intruder.py).
//!
//! - a permitted client (enclave `/operator`, may publish on `obstacles`
//!   only) adds and moves an obstacle, sees its markers where it put them
//!   and reads the cloud;
//! - the operator cannot publish on `pins` (its publisher is refused); a
//!   client permitted on `pins` (`/pinner`) pins a vertex where it says;
//! - participants without the keystore's identity (no security: RustDDS and
//!   Cyclone DDS; an identity from another CA: RustDDS) discover no topic
//!   of the node, receive nothing, and their obstacles never appear;
//! - nothing in plain text crosses the wire while only permitted peers run:
//!   no cloud field name, no topic name (a capture of the loopback, which
//!   does see both from the unsecured node below);
//! - with `Enforce` a keystore whose enclave lacks a file stops the node at
//!   start with an error naming the file; `Permissive` starts it unsecured
//!   with a warning.
//!
//! Everything runs in a network namespace made for the test (`unshare -rn`:
//! only a loopback interface): the test runs itself again inside it.
#![cfg(feature = "security")]

mod support;

use garment_sim::msgs::{self, RosType};
use ros2_client::{
    Context, ContextOptions, MessageTypeName, Name, NodeName, NodeOptions, QosProfile,
};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

const INNER: &str = "GARMENT_SIM_SROS_INNER";

/// The governance's protection of RTPS messages, submessages and payloads,
/// unless the environment says otherwise: whole messages and submessages
/// (payloads included) encrypted, payloads not encrypted a second time
/// (RustDDS 0.15.1 peers do not get each other's samples with payload
/// ENCRYPT or SIGN; with sros2's RTPS SIGN, RustDDS's DCPSTopic
/// announcements show topic names in plain text: docs/ros.md).
const PROTECTION: [(&str, &str); 3] = [
    ("RTPS_PROTECTION", "ENCRYPT"),
    ("METADATA_PROTECTION", "ENCRYPT"),
    ("DATA_PROTECTION", "NONE"),
];

fn keystore_tool(args: &[&OsStrLike]) {
    let mut c = Command::new("bash");
    for (k, default) in PROTECTION {
        c.env(k, std::env::var(k).unwrap_or_else(|_| default.into()));
    }
    let st = c
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/sros2_keystore.sh"))
        .args(args)
        .status()
        .expect("bash and openssl are needed");
    assert!(st.success(), "tools/sros2_keystore.sh {args:?}");
}

type OsStrLike = std::ffi::OsStr;

fn os(s: &str) -> &OsStrLike {
    OsStrLike::new(s)
}

/// Plain text that must not cross the wire in the secured graph: a field
/// name of every cloud and the cloud's DDS topic name (in discovery).
const PLAIN: [&[u8]; 2] = [b"strain", b"rt/cloth/points"];

/// Every frame crossing the namespace's loopback interface while it runs
/// (an AF_PACKET socket): which of [`PLAIN`] appeared, and the bytes seen.
struct Capture {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<([bool; 2], usize)>,
}

impl Capture {
    fn start() -> Capture {
        let proto = (libc::ETH_P_ALL as u16).to_be() as i32;
        let fd = unsafe { libc::socket(libc::AF_PACKET, libc::SOCK_RAW, proto) };
        assert!(
            fd >= 0,
            "AF_PACKET socket: {}",
            std::io::Error::last_os_error()
        );
        let tv = libc::timeval {
            tv_sec: 0,
            tv_usec: 100_000,
        };
        unsafe {
            libc::setsockopt(
                fd,
                libc::SOL_SOCKET,
                libc::SO_RCVTIMEO,
                &tv as *const _ as *const libc::c_void,
                std::mem::size_of::<libc::timeval>() as u32,
            );
        }
        let stop = Arc::new(AtomicBool::new(false));
        let s = stop.clone();
        let thread = std::thread::spawn(move || {
            let mut buf = vec![0u8; 1 << 16];
            let (mut found, mut bytes) = ([false; 2], 0);
            while !s.load(Ordering::Relaxed) {
                let n = unsafe { libc::recv(fd, buf.as_mut_ptr().cast(), buf.len(), 0) };
                if n > 0 {
                    let frame = &buf[..n as usize];
                    bytes += frame.len();
                    for (f, p) in found.iter_mut().zip(PLAIN) {
                        if !*f && frame.windows(p.len()).any(|w| w == p) {
                            *f = true;
                            eprintln!(
                                "capture: {:?} in a frame of {} bytes: {}",
                                String::from_utf8_lossy(p),
                                frame.len(),
                                String::from_utf8_lossy(frame).escape_debug()
                            );
                        }
                    }
                }
            }
            unsafe { libc::close(fd) };
            (found, bytes)
        });
        Capture { stop, thread }
    }

    fn finish(self) -> ([bool; 2], usize) {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.join().unwrap()
    }
}

/// A ros2-client participant: secured with `enclave_dir`'s files if given.
struct Peer {
    ctx: Context,
    node: ros2_client::Node,
}

impl Peer {
    fn new(name: &str, enclave_dir: Option<&Path>) -> Result<Peer, String> {
        let mut o = ContextOptions::new().domain_id(0);
        if let Some(d) = enclave_dir {
            o = o.enable_security(d, String::new());
        }
        let ctx = Context::with_options(o).map_err(|e| format!("{e:?}"))?;
        let node = ctx
            .new_node(
                NodeName::new("/", name).unwrap(),
                NodeOptions::new().enable_rosout(false),
            )
            .map_err(|e| format!("{e:?}"))?;
        Ok(Peer { ctx, node })
    }

    fn topic(&mut self, name: &str, ros_type: &str) -> ros2_client::dds::rustdds::Topic {
        let pkg = ros_type.split('/').next().unwrap();
        let ty = ros_type.rsplit('/').next().unwrap();
        let qos = QosProfile::publisher_default()
            .reliability(ros2_client::qos::Reliability::Reliable {
                when_full: ros2_client::qos::WhenFull::Wait(std::time::Duration::from_millis(100)),
            })
            .history(ros2_client::qos::History::KeepLast { depth: 50 });
        self.node
            .create_topic(
                &Name::parse(name).unwrap(),
                MessageTypeName::new(pkg, ty),
                &qos,
            )
            .unwrap()
    }

    fn publisher<M: RosType + serde::Serialize>(
        &mut self,
        name: &str,
    ) -> Result<ros2_client::Publisher<M>, String> {
        let t = self.topic(name, M::NAME);
        self.node
            .create_publisher::<M>(&t, None)
            .map_err(|e| format!("{e:?}"))
    }

    fn subscription<M: RosType + serde::de::DeserializeOwned + 'static>(
        &mut self,
        name: &str,
    ) -> ros2_client::Subscription<M> {
        let t = self.topic(name, M::NAME);
        self.node.create_subscription::<M>(&t, None).unwrap()
    }

    /// The topic names of the writers this participant discovered.
    fn discovered_topics(&self) -> Vec<String> {
        self.ctx
            .domain_participant()
            .discovered_writers()
            .into_iter()
            .map(|w| w.publication_topic_data.topic_name)
            .collect()
    }
}

/// The first sample satisfying `pred` within `secs` of wall time (a bound
/// for a loaded machine, not a measure), from `sub`.
fn wait<M: serde::de::DeserializeOwned + 'static>(
    sub: &ros2_client::Subscription<M>,
    node: &mut Child,
    secs: u64,
    what: &str,
    mut pred: impl FnMut(&M) -> bool,
) -> M {
    let end = Instant::now() + Duration::from_secs(secs);
    while Instant::now() < end {
        assert!(node.try_wait().unwrap().is_none(), "the node exited");
        while let Ok(Some((m, _))) = sub.take() {
            if pred(&m) {
                return m;
            }
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    panic!("{what}: nothing within {secs} s");
}

fn xyz(c: &msgs::PointCloud2, k: usize) -> [f32; 3] {
    let o = k * c.point_step as usize;
    let f = |i: usize| f32::from_le_bytes(c.data[o + 4 * i..o + 4 * i + 4].try_into().unwrap());
    [f(0), f(1), f(2)]
}

fn sphere(id: &str, op: u8, p: [f64; 3]) -> msgs::Obstacle {
    msgs::Obstacle {
        header: msgs::Header {
            frame_id: "world".into(),
            ..Default::default()
        },
        id: id.into(),
        pose: msgs::Pose {
            position: msgs::Point {
                x: p[0],
                y: p[1],
                z: p[2],
            },
            ..Default::default()
        },
        primitives: vec![msgs::SolidPrimitive {
            type_: 2,
            dimensions: vec![0.05],
            ..Default::default()
        }],
        primitive_poses: vec![msgs::Pose::default()],
        operation: op,
        ..Default::default()
    }
}

fn start_node(ks: &Path, strategy: &str, extra: &[(&str, &str)]) -> Command {
    let mut c = Command::new(support::garment_sim_path());
    c.args([
        "node",
        "--ros-args",
        "-p",
        "spacing:=0.05",
        "-p",
        "publish_rate:=30.0",
    ])
    .env("ROS_SECURITY_ENABLE", "true")
    .env("ROS_SECURITY_STRATEGY", strategy)
    .env("ROS_SECURITY_KEYSTORE", ks)
    .env("ROS_SECURITY_ENCLAVE_OVERRIDE", "/garment_sim");
    for (k, v) in extra {
        c.env(k, v);
    }
    c
}

#[test]
fn secured_graph() {
    if std::env::var_os(INNER).is_none() {
        let exe = std::env::current_exe().unwrap();
        let out = support::in_loopback_namespace(
            "exec \"$0\" --exact secured_graph --nocapture --test-threads=1",
            &[exe.as_os_str()],
        )
        .env(INNER, "1")
        .output()
        .expect("unshare and ip are needed");
        support::succeeded(&out, "1 passed");
        return;
    }
    let dir = support::Scratch::new("ros_security");
    let ks: PathBuf = dir.join("keystore");
    let foreign: PathBuf = dir.join("foreign");
    let k = ks.to_str().unwrap();
    keystore_tool(&[os(k), os("/garment_sim")]);
    // what ros2-client's context and node publish besides
    let base = "ros_discovery_info rt/rosout rt/parameter_events";
    keystore_tool(&[os(k), os("/operator"), os(&format!("rt/obstacles {base}"))]);
    keystore_tool(&[os(k), os("/pinner"), os(&format!("rt/pins {base}"))]);
    // another CA: the same enclave name, every right, not the keystore's identity
    keystore_tool(&[foreign.as_os_str(), os("/operator")]);

    // RustDDS's log lines of the test's own participants, as the node's
    garment_sim::ros::security::dds_log();
    // the node writes into a file: nothing it writes can block it
    let node_log = dir.join("node.log");
    let f = std::fs::File::create(&node_log).unwrap();
    let wire = Capture::start();
    let mut node = start_node(&ks, "Enforce", &[])
        .stdout(f.try_clone().unwrap())
        .stderr(f)
        .spawn()
        .unwrap();
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        scenario(&dir, &ks, &foreign, &mut node, wire)
    }));
    unsafe {
        libc::kill(node.id() as i32, libc::SIGTERM);
    }
    let status = node.wait().unwrap();
    let log = std::fs::read_to_string(&node_log).unwrap();
    println!("node:\n{log}");
    let (plain, bytes) = match result {
        Ok(r) => r,
        Err(e) => std::panic::resume_unwind(e),
    };
    assert!(status.success(), "{log}");
    assert!(
        log.contains("DDS Security on: enclave /garment_sim"),
        "{log}"
    );
    // (4) encrypted: until the intruders came (their own announcements name
    // the topics they ask for), neither a cloud's field names nor its topic
    // name crossed the wire
    println!("secured graph: {bytes} bytes on the loopback, plain text seen: {plain:?}");
    assert!(bytes > 100_000, "{bytes} bytes captured");
    assert_eq!(
        plain,
        [false, false],
        "plain text on the wire of the secured graph"
    );

    refusals(&dir, &ks);
}

/// tests/ros_security/intruder.py for `secs` on Cyclone DDS (loopback).
fn intruder(dir: &Path, secs: u32) -> Child {
    Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ros_security/intruder.py"))
        .arg(secs.to_string())
        .env("CYCLONEDDS_URI", support::cyclone_loopback_uri(dir))
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 with cyclonedds is needed")
}

/// (1)–(3) with the permitted peers, the loopback captured (returned: what
/// [`Capture::finish`] says), then the intruders.
fn scenario(
    dir: &Path,
    ks: &Path,
    foreign: &Path,
    node: &mut Child,
    wire: Capture,
) -> ([bool; 2], usize) {
    let enclave = |name: &str| ks.join("enclaves").join(name);
    // (1) the operator adds and moves an obstacle and reads the cloud
    let mut op = Peer::new("operator", Some(&enclave("operator"))).unwrap();
    let cloud = op.subscription::<msgs::PointCloud2>("/cloth/points");
    let markers = op.subscription::<msgs::MarkerArray>("/obstacles/markers");
    let obstacles = op.publisher::<msgs::Obstacle>("/obstacles").unwrap();
    let c = wait(&cloud, node, 60, "cloud to the operator", |c| c.width > 0);
    assert_eq!(c.width, 121, "a 1 m cloth at 5 cm: 11 × 11 vertices");
    let ball = |a: &msgs::MarkerArray, z: f64| {
        a.markers
            .iter()
            .any(|m| m.text == "ball" && (m.pose.position.z - z).abs() < 1e-12)
    };
    let end = Instant::now() + Duration::from_secs(60);
    let mut seen = false;
    while !seen && Instant::now() < end {
        obstacles
            .publish(sphere("ball", msgs::Obstacle::ADD, [0.3, 0.0, 1.2]))
            .unwrap();
        std::thread::sleep(Duration::from_millis(300));
        while let Ok(Some((a, _))) = markers.take() {
            seen |= ball(&a, 1.2);
        }
    }
    assert!(seen, "the operator's obstacle never appeared");
    obstacles
        .publish(sphere("ball", msgs::Obstacle::MOVE, [0.3, 0.0, 1.4]))
        .unwrap();
    wait(&markers, node, 60, "the moved obstacle", |a| ball(a, 1.4));
    println!("operator: obstacle added at z = 1.2 m and moved to 1.4 m; cloud of 121 points read");

    // (3) the operator may not publish on pins: refused by access control
    let e = match op.publisher::<msgs::Pin>("/pins") {
        Ok(_) => panic!("the operator got a publisher on rt/pins"),
        Err(e) => e,
    };
    assert!(e.contains("not allowed by security"), "{e}");
    println!("operator's publisher on pins: {e}");
    // ... while a client granted pins pins vertex 0 where it says
    let mut pinner = Peer::new("pinner", Some(&enclave("pinner"))).unwrap();
    let pins = pinner.publisher::<msgs::Pin>("/pins").unwrap();
    let pin = msgs::Pin {
        header: msgs::Header {
            frame_id: "world".into(),
            ..Default::default()
        },
        operation: msgs::Pin::PIN,
        grid_i: vec![0],
        grid_j: vec![0],
        targets: vec![msgs::Point {
            x: -0.5,
            y: -0.5,
            z: 1.5,
        }],
        ..Default::default()
    };
    let end = Instant::now() + Duration::from_secs(60);
    let mut pinned = false;
    while !pinned && Instant::now() < end {
        pins.publish(pin.clone()).unwrap();
        std::thread::sleep(Duration::from_millis(300));
        while let Ok(Some((c, _))) = cloud.take() {
            let p = xyz(&c, 0);
            pinned |= (p[2] - 1.5).abs() < 1e-5 && (p[0] + 0.5).abs() < 1e-5;
        }
    }
    assert!(pinned, "the pinner's pin never took effect");
    println!("pinner: vertex 0 pinned at (-0.5, -0.5, 1.5)");
    drop(pinner);
    let captured = wire.finish();

    // (2) participants without the keystore's identity
    let mut plain = Peer::new("plain_intruder", None).unwrap();
    let mut alien = Peer::new("operator", Some(&foreign.join("enclaves/operator"))).unwrap();
    let plain_cloud = plain.subscription::<msgs::PointCloud2>("/cloth/points");
    let alien_cloud = alien.subscription::<msgs::PointCloud2>("/cloth/points");
    let plain_obs = plain.publisher::<msgs::Obstacle>("/obstacles").unwrap();
    let alien_obs = alien.publisher::<msgs::Obstacle>("/obstacles").unwrap();
    let cyclone = intruder(dir, 8);
    // for 8 s they write obstacles while the operator watches the markers
    // (the node keeps publishing them: a fresh array every frame)
    let end = Instant::now() + Duration::from_secs(8);
    let (mut arrays, mut clouds_to_intruders) = (0, 0);
    let mut intruder_seen = Vec::new();
    while Instant::now() < end {
        let _ = plain_obs.publish(sphere("plain_intruder", 0, [0.0, 0.0, 1.2]));
        let _ = alien_obs.publish(sphere("alien_intruder", 0, [0.0, 0.0, 1.2]));
        std::thread::sleep(Duration::from_millis(100));
        while let Ok(Some((a, _))) = markers.take() {
            arrays += 1;
            for m in &a.markers {
                if m.text.contains("intruder") {
                    intruder_seen.push(m.text.clone());
                }
            }
        }
        while let Ok(Some(_)) = plain_cloud.take() {
            clouds_to_intruders += 1;
        }
        while let Ok(Some(_)) = alien_cloud.take() {
            clouds_to_intruders += 1;
        }
    }
    let out = cyclone.wait_with_output().unwrap();
    let report = String::from_utf8_lossy(&out.stdout).to_string();
    assert!(
        out.status.success(),
        "{report}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    println!("cyclone intruder: {report}");
    let v: serde_json::Value = serde_json::from_str(report.trim()).unwrap();
    assert!(v["written"].as_u64().unwrap() > 10, "{report}");
    assert_eq!(
        v["matched_readers"], 0,
        "the Cyclone intruder's obstacles matched a reader"
    );
    assert_eq!(
        v["matched_writers"], 0,
        "the Cyclone intruder matched the node's cloud"
    );
    assert_eq!(v["received"], 0, "the Cyclone intruder received clouds");
    let node_topics = [
        "rt/cloth/points",
        "rt/clock",
        "rt/diagnostics",
        "rt/obstacles/markers",
    ];
    for seen in [plain.discovered_topics(), alien.discovered_topics()] {
        assert!(
            !seen.iter().any(|t| node_topics.contains(&t.as_str())),
            "an intruder discovered the node's topics: {seen:?}"
        );
    }
    assert_eq!(clouds_to_intruders, 0, "an intruder received clouds");
    assert!(
        arrays > 30,
        "the operator got {arrays} marker arrays in 8 s"
    );
    assert!(
        intruder_seen.is_empty(),
        "an intruder's obstacle was applied: {intruder_seen:?}"
    );
    // the node still serves the operator
    wait(&markers, node, 60, "markers after the intruders", |a| {
        ball(a, 1.4)
    });
    println!(
        "intruders (RustDDS without security, RustDDS with another CA, Cyclone DDS without \
         security): no topic of the node discovered, no cloud received, no obstacle applied \
         ({arrays} marker arrays watched)"
    );
    captured
}

/// Enforce with a keystore missing a file refuses to start and names the
/// file; Permissive starts without security and warns.
fn refusals(dir: &Path, ks: &Path) {
    let key = ks.join("enclaves/garment_sim/key.pem");
    std::fs::rename(&key, key.with_extension("moved")).unwrap();
    let out = start_node(ks, "Enforce", &[]).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains(&key.display().to_string()) && err.contains("Enforce"),
        "{err}"
    );
    println!("Enforce without key.pem: {}", err.trim());
    let wire = Capture::start();
    let mut n = start_node(ks, "Permissive", &[])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // an unsecured participant gets the cloud of the fallen-back node
    let mut plain = Peer::new("plain", None).unwrap();
    let cloud = plain.subscription::<msgs::PointCloud2>("/cloth/points");
    let c = wait(&cloud, &mut n, 60, "cloud of the Permissive node", |c| {
        c.width > 0
    });
    assert_eq!(c.width, 121);
    // and so does Cyclone DDS: what the intruder reports can show a node
    let out = intruder(dir, 3).wait_with_output().unwrap();
    let report = String::from_utf8_lossy(&out.stdout).to_string();
    let v: serde_json::Value = serde_json::from_str(report.trim()).unwrap();
    assert!(
        v["matched_writers"].as_u64().unwrap() >= 1 && v["received"].as_u64().unwrap() > 0,
        "{report}"
    );
    unsafe {
        libc::kill(n.id() as i32, libc::SIGTERM);
    }
    let out = n.wait_with_output().unwrap();
    // the capture sees plain text when there is some
    let (plain, bytes) = wire.finish();
    println!("unsecured node: {bytes} bytes on the loopback, plain text seen: {plain:?}");
    assert_eq!(
        plain,
        [true, true],
        "the capture missed the unsecured node's traffic"
    );
    let log =
        String::from_utf8_lossy(&out.stdout).to_string() + &String::from_utf8_lossy(&out.stderr);
    assert!(
        log.contains(&key.display().to_string()) && log.contains("WITHOUT DDS Security"),
        "{log}"
    );
    println!("Permissive without key.pem: started unsecured, warned");
}
