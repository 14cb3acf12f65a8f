//! Bags through the decoders the Foxglove app uses (tests/foxglove/decode_bag.mjs:
//! `@mcap/core`'s readers with `@mcap/support`'s decompression, each channel's
//! schema parsed by `@foxglove/rosmsg` as ROS 2, every message decoded by
//! `@foxglove/rosmsg2-serialization`), for a `drape --bag` bag and for a bag
//! recorded by the node. Every message of every channel must decode, the
//! counts must be those of metadata.yaml and of the MCAP statistics, and the
//! last decoded point cloud must be the cloth of the run's final state.
//!
//! The npm packages come from tests/foxglove/package-lock.json, installed by
//! `npm ci --prefix tests/foxglove` (in .ci/run); without them, or without
//! `node`, these tests fail and say what to run. The node starts DDS, so it
//! runs in a network namespace made for the test (`unshare -rn`, loopback
//! only): no packet leaves it.

mod support;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The small run both bags hold: the table drape on a 5 cm grid (11 × 11),
/// dt = 4 ms, 0.3 s, frames at 30 Hz.
const SCENE: &str = "config/scenes/table_drape.yaml";
const SPACING: &str = "0.05";
const DT: &str = "0.004";
const DURATION: &str = "0.3";
const RATE: &str = "30";

/// Every topic a bag holds and its type.
const TOPICS: [(&str, &str); 6] = [
    ("/cloth/points", "sensor_msgs/msg/PointCloud2"),
    ("/cloth/mesh", "visualization_msgs/msg/Marker"),
    ("/obstacles/markers", "visualization_msgs/msg/MarkerArray"),
    ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
    ("/clock", "rosgraph_msgs/msg/Clock"),
    ("/scene_description", "std_msgs/msg/String"),
];

fn bin() -> &'static str {
    support::garment_sim_path()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// Fails unless `node` runs and the npm packages are installed.
fn require_decoders() {
    let probe = Command::new("node").arg("--version").output();
    assert!(
        probe.as_ref().is_ok_and(|o| o.status.success()),
        "needs Node.js (node, version 18 or later) for the Foxglove decoders"
    );
    let modules = Path::new("tests/foxglove/node_modules");
    for pkg in [
        "@mcap/core",
        "@mcap/support",
        "@foxglove/rosmsg",
        "@foxglove/rosmsg2-serialization",
    ] {
        assert!(
            modules.join(pkg).join("package.json").is_file(),
            "needs the npm package {pkg} for the Foxglove decoders: npm ci --prefix tests/foxglove"
        );
    }
}

/// Runs tests/foxglove/decode_bag.mjs on a bag; its JSON report.
fn decode(bag: &Path, stream: bool) -> Value {
    require_decoders();
    let mut cmd = Command::new("node");
    cmd.arg("tests/foxglove/decode_bag.mjs");
    if stream {
        cmd.arg("--stream");
    }
    let o = cmd.arg(bag).output().expect("node runs");
    assert!(o.status.success(), "decode_bag.mjs failed:\n{}", text(&o));
    serde_json::from_slice(&o.stdout)
        .unwrap_or_else(|e| panic!("decode_bag.mjs printed no JSON ({e}):\n{}", text(&o)))
}

/// `rosbag2_bagfile_information` of the bag's metadata.yaml.
fn metadata(bag: &Path) -> serde_yaml::Value {
    let t = std::fs::read_to_string(bag.join("metadata.yaml")).unwrap();
    let md: serde_yaml::Value = serde_yaml::from_str(&t).unwrap();
    md["rosbag2_bagfile_information"].clone()
}

/// The vertex positions of a PLY written by `drape` (ASCII, x y z first).
fn ply_positions(path: &Path) -> Vec<[f64; 3]> {
    let t = std::fs::read_to_string(path).unwrap();
    let n: usize = t
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .expect("element vertex line");
    let body = t.split("end_header\n").nth(1).expect("end_header");
    body.lines()
        .take(n)
        .map(|l| {
            let v: Vec<f64> = l
                .split_whitespace()
                .take(3)
                .map(|x| x.parse().unwrap())
                .collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

/// `drape --bag` of the small run into `dir/name`; the bag and the output directory.
fn drape(dir: &Path, name: &str, compression: &str) -> (PathBuf, PathBuf) {
    let bag = dir.join(name);
    let out = dir.join(format!("{name}_out"));
    let o = Command::new(bin())
        .args([
            "drape",
            SCENE,
            "--spacing",
            SPACING,
            "--dt",
            DT,
            "--duration",
            DURATION,
            "--bag-rate",
            RATE,
            "--bag-compression",
            compression,
            "--out",
        ])
        .arg(&out)
        .arg("--bag")
        .arg(&bag)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    (bag, out)
}

/// Every message of every channel decoded, as many as metadata.yaml and the
/// MCAP statistics count, on the six topics with their types.
fn check_counts(bag: &Path, d: &Value) {
    let md = metadata(bag);
    let total = md["message_count"].as_u64().unwrap();
    assert!(total > 0);
    assert_eq!(d["decoded_messages"].as_u64(), Some(total), "{d}");
    assert_eq!(d["statistics_message_count"].as_u64(), Some(total), "{d}");
    assert_eq!(d["profile"], "ros2");
    let per_topic: Vec<(String, u64)> = md["topics_with_message_count"]
        .as_sequence()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["topic_metadata"]["name"].as_str().unwrap().to_string(),
                t["message_count"].as_u64().unwrap(),
            )
        })
        .collect();
    assert_eq!(per_topic.len(), TOPICS.len(), "{per_topic:?}");
    for (topic, n) in &per_topic {
        assert_eq!(d["counts"][topic].as_u64(), Some(*n), "{topic}: {d}");
    }
    let channels = d["channels"].as_array().unwrap();
    assert_eq!(channels.len(), TOPICS.len());
    for (topic, ty) in TOPICS {
        let c = channels
            .iter()
            .find(|c| c["topic"] == topic)
            .unwrap_or_else(|| panic!("no channel {topic}: {d}"));
        assert_eq!(c["schema_name"], ty, "{topic}");
        assert_eq!(
            (&c["schema_encoding"], &c["message_encoding"]),
            (&"ros2msg".into(), &"cdr".into())
        );
        assert!(c["count"].as_u64().unwrap() > 0, "{topic}");
    }
    // CDR leaves nothing unread: each message is exactly its type
    assert_eq!(d["trailing_bytes"].as_u64(), Some(0), "{d}");
}

/// The last decoded cloud, as float32, is `expected` (float64): x, y, z of
/// each vertex in order, each the float32 nearest to the float64 value.
fn check_last_cloud(d: &Value, expected: &[[f64; 3]], last_ns: u64) {
    let c = &d["last_cloud"];
    assert_eq!(c["topic"], "/cloth/points");
    assert_eq!(c["frame_id"], "world");
    let fields: Vec<&str> = c["fields"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_str().unwrap())
        .collect();
    assert_eq!(fields, ["x", "y", "z", "strain", "speed"]);
    let stamp = c["stamp"]["sec"].as_u64().unwrap() * 1_000_000_000
        + c["stamp"]["nanosec"].as_u64().unwrap();
    assert_eq!(
        c["log_time"].as_str().unwrap().parse::<u64>().unwrap(),
        stamp
    );
    assert_eq!(stamp, last_ns);
    let xyz = c["xyz"].as_array().unwrap();
    assert_eq!(xyz.len(), expected.len());
    assert_eq!(
        c["width"].as_u64().unwrap() * c["height"].as_u64().unwrap(),
        expected.len() as u64
    );
    for (k, (p, e)) in xyz.iter().zip(expected).enumerate() {
        for a in 0..3 {
            let got = p[a].as_f64().unwrap();
            let tol = f64::from(f32::EPSILON) * e[a].abs().max(1e-30);
            assert!(
                (got - e[a]).abs() <= tol,
                "vertex {k} axis {a}: decoded {got}, final state {}",
                e[a]
            );
        }
    }
}

/// The simulated end time of a drape, in nanoseconds (summary.json).
fn end_ns(out: &Path) -> u64 {
    let s: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    (s["simulated_s"].as_f64().unwrap() * 1e9).round() as u64
}

#[test]
fn drape_bags_decode_in_foxglove() {
    let dir = support::Scratch::new("foxglove_drape");
    for compression in ["zstd", "lz4"] {
        let (bag, out) = drape(&dir, &format!("bag_{compression}"), compression);
        let expected = ply_positions(&out.join("final.ply"));
        assert_eq!(expected.len(), 121);
        let d = decode(&bag, false);
        check_counts(&bag, &d);
        check_last_cloud(&d, &expected, end_ns(&out));
        // front to back without the index: the same messages
        let s = decode(&bag, true);
        assert_eq!(s["reader"], "McapStreamReader");
        check_counts(&bag, &s);
        assert_eq!(s["channels"], d["channels"]);
        assert_eq!(s["last_cloud"], d["last_cloud"]);
    }
}

#[test]
fn node_bags_decode_in_foxglove() {
    require_decoders();
    let dir = support::Scratch::new("foxglove_node");
    let bag = dir.join("node_bag");
    // the node in a network namespace of its own: loopback only, with
    // multicast for DDS discovery
    let node = format!(
        "exec \"$0\" node --ros-args \
         -p scene:={SCENE} -p spacing:={SPACING} -p dt:={DT} -p duration:={DURATION} \
         -p publish_rate:={RATE} -p real_time_factor:=0.0 -p record_bag:=\"$1\""
    );
    let o = support::in_loopback_namespace(&node, &[bin().as_ref(), bag.as_os_str()])
        .output()
        .expect("unshare (util-linux) and ip (iproute2) are needed");
    assert!(o.status.success(), "node:\n{}", text(&o));
    let d = decode(&bag, false);
    check_counts(&bag, &d);
    // the node steps the scene as a drape does: its last frame is the
    // drape's final state, at the drape's end time
    let (_, out) = drape(&dir, "drape_bag", "zstd");
    let expected = ply_positions(&out.join("final.ply"));
    check_last_cloud(&d, &expected, end_ns(&out));
}
