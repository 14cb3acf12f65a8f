//! `drape --foxglove` seen by an independent client: Foxglove's own
//! WebSocket protocol client (`@foxglove/ws-protocol`, in Node) subscribes on
//! loopback to every channel the drape advertises and decodes each message
//! from the advertised `ros2msg` schema with Foxglove's ROS 2 message parser
//! and CDR reader (`tests/foxglove/live_client.cjs`). The cloud of the last
//! frame must be `final.ply`'s vertices, the mesh its triangles. (Bags read
//! by Foxglove's decoders: tests/foxglove_bags.rs.)
//!
//! Needs the client's packages: `npm ci --prefix tests/foxglove`.

mod support;
use serde_json::Value;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

const DURATION_S: f64 = 0.5;

/// Vertices and triangles of an ASCII PLY written by `drape`.
fn read_ply(path: &Path) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let text = std::fs::read_to_string(path).unwrap();
    let (head, body) = text.split_once("end_header\n").unwrap();
    let count = |what: &str| -> usize {
        head.lines()
            .find_map(|l| l.strip_prefix(&format!("element {what} ")))
            .unwrap()
            .parse()
            .unwrap()
    };
    let (nv, nf) = (count("vertex"), count("face"));
    let lines: Vec<&str> = body.lines().collect();
    let nums = |l: &str| -> Vec<f64> { l.split_whitespace().map(|x| x.parse().unwrap()).collect() };
    let v = lines[..nv]
        .iter()
        .map(|l| {
            let n = nums(l);
            [n[0], n[1], n[2]]
        })
        .collect();
    let f = lines[nv..nv + nf]
        .iter()
        .map(|l| {
            let n = nums(l);
            assert_eq!(n[0], 3.0);
            [n[1] as usize, n[2] as usize, n[3] as usize]
        })
        .collect();
    (v, f)
}

fn triple(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    [0, 1, 2].map(|k| a[k].as_f64().unwrap())
}

fn ns(v: &Value) -> u64 {
    v.as_str().unwrap().parse().unwrap()
}

/// `tests/foxglove`, failing unless its Node packages are installed.
fn live_dir() -> std::path::PathBuf {
    let live_dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/foxglove");
    assert!(
        live_dir.join("node_modules/@foxglove/ws-protocol").is_dir()
            && live_dir
                .join("node_modules/@foxglove/rosmsg2-serialization")
                .is_dir(),
        "the live view tests need their Node packages: npm ci --prefix tests/foxglove"
    );
    live_dir
}

#[test]
fn foxglove_client_decodes_the_drape_live() {
    let live_dir = live_dir();
    let out = support::Scratch::new("live_view");
    // port 0: the system picks a free port on loopback; the drape prints its URL
    let mut drape = support::garment_sim()
        .args([
            "drape",
            "config/scenes/table_drape.yaml",
            "--spacing",
            "0.05",
            "--duration",
            &DURATION_S.to_string(),
            "--foxglove",
            "127.0.0.1:0",
            "--foxglove-wait",
            "20",
            "--out",
        ])
        .arg(&*out)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stderr = drape.stderr.take().unwrap();
    let (url_tx, url_rx) = mpsc::channel();
    let log = std::thread::spawn(move || {
        let mut all = String::new();
        for line in BufReader::new(stderr).lines() {
            let line = line.unwrap();
            if let Some(u) = line.strip_prefix("live view: ws://") {
                let _ = url_tx.send(format!("ws://{u}"));
            }
            all.push_str(&line);
            all.push('\n');
        }
        all
    });
    let url = match url_rx.recv_timeout(Duration::from_secs(15)) {
        Ok(u) => u,
        Err(_) => {
            let _ = drape.kill();
            let _ = drape.wait();
            panic!("the drape printed no URL:\n{}", log.join().unwrap());
        }
    };
    assert!(url.starts_with("ws://127.0.0.1:"), "{url}");

    let client = Command::new("node")
        .arg(live_dir.join("live_client.cjs"))
        .args([&url, &DURATION_S.to_string(), "20"])
        .output()
        .expect("node (20 or later) is needed for the live view test");
    // the drape ends once the client has closed its connection
    let mut status = None;
    for _ in 0..200 {
        if let Some(s) = drape.try_wait().unwrap() {
            status = Some(s);
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    if status.is_none() {
        let _ = drape.kill();
    }
    let drape_out = drape.wait_with_output().unwrap();
    let drape_stdout = String::from_utf8_lossy(&drape_out.stdout).to_string();
    let drape_err = log.join().unwrap();
    let client_err = String::from_utf8_lossy(&client.stderr);
    assert!(
        client.status.success(),
        "client failed: {client_err}\ndrape: {drape_stdout}{drape_err}"
    );
    assert!(
        status.is_some_and(|s| s.success()),
        "drape did not end by itself after the client left ({status:?}):\n{drape_stdout}{drape_err}"
    );
    let seen: Value = serde_json::from_slice(&client.stdout).unwrap_or_else(|e| {
        panic!(
            "client output is not JSON ({e}): {}",
            String::from_utf8_lossy(&client.stdout)
        )
    });

    // what the server advertised
    assert_eq!(seen["server"]["name"], "garment_sim");
    assert!(
        seen["server"]["capabilities"]
            .as_array()
            .unwrap()
            .contains(&"time".into()),
        "{}",
        seen["server"]
    );
    let mut channels: Vec<(String, String, String, String)> = seen["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let s = |k: &str| c[k].as_str().unwrap().to_string();
            (
                s("topic"),
                s("schema_name"),
                s("encoding"),
                s("schema_encoding"),
            )
        })
        .collect();
    channels.sort();
    let want = [
        ("/clock", "rosgraph_msgs/msg/Clock"),
        ("/cloth/mesh", "visualization_msgs/msg/Marker"),
        ("/cloth/points", "sensor_msgs/msg/PointCloud2"),
        ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
        ("/obstacles/markers", "visualization_msgs/msg/MarkerArray"),
    ]
    .map(|(t, s)| (t.to_string(), s.to_string(), "cdr".into(), "ros2msg".into()));
    assert_eq!(channels, want);
    // every message was read to its last byte by the advertised schema
    assert_eq!(seen["trailing_bytes"], 0);

    // the outputs of the same run
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let (verts, faces) = read_ply(&out.join("final.ply"));
    let n = verts.len();
    assert_eq!(n, 121); // 50 cm square at 5 cm: 11 × 11
    assert_eq!(
        n as u64,
        summary["grid"][0].as_u64().unwrap() * summary["grid"][1].as_u64().unwrap()
    );
    let final_ns = (summary["simulated_s"].as_f64().unwrap() * 1e9).round() as u64;
    assert_eq!(final_ns, 500_000_000);

    // clouds: every frame published, from t = 0 to the end, in order, stamped
    // with the simulated time (header stamp = message log time)
    let clouds = seen["clouds"].as_array().unwrap();
    let frames: usize = drape_stdout
        .lines()
        .find_map(|l| l.strip_prefix("live view "))
        .and_then(|l| l.split('(').nth(1)?.split(' ').next()?.parse().ok())
        .unwrap_or_else(|| panic!("no frame count in: {drape_stdout}"));
    assert_eq!(clouds.len(), frames, "clouds received ≠ frames published");
    // 30 Hz over 0.5 s: t = 0, 1/30, …, 15/30 = 0.5
    assert_eq!(frames, 16);
    let stamps: Vec<u64> = clouds.iter().map(|c| ns(&c["stamp_ns"])).collect();
    assert_eq!(stamps[0], 0);
    assert_eq!(*stamps.last().unwrap(), final_ns);
    assert!(stamps.windows(2).all(|w| w[0] < w[1]), "{stamps:?}");
    for c in clouds {
        assert_eq!(c["log_ns"], c["stamp_ns"]);
        assert_eq!(c["frame_id"], "world");
        assert_eq!(
            (c["width"].as_u64(), c["height"].as_u64()),
            (Some(n as u64), Some(1))
        );
        assert_eq!(
            c["fields"],
            serde_json::json!(["x", "y", "z", "strain", "speed"])
        );
    }
    // the server's clock follows the frames
    let times: Vec<u64> = seen["times_ns"]
        .as_array()
        .unwrap()
        .iter()
        .map(ns)
        .collect();
    assert_eq!(times.last(), Some(&final_ns));
    let clock: Vec<u64> = seen["clock_ns"]
        .as_array()
        .unwrap()
        .iter()
        .map(ns)
        .collect();
    assert_eq!(clock, stamps);

    // the last cloud is final.ply: the cloud carries float32, the PLY the
    // float64 it was rounded from (printed to round-trip), so they agree exactly
    let last = seen["last_cloud"].as_array().unwrap();
    assert_eq!(last.len(), n);
    for (i, (p, v)) in last.iter().zip(&verts).enumerate() {
        let p = triple(p);
        assert!(p.iter().all(|x| x.is_finite()), "point {i}: {p:?}");
        for k in 0..3 {
            assert_eq!(
                p[k] as f32, v[k] as f32,
                "point {i}: cloud {p:?}, final.ply {v:?}"
            );
        }
    }
    // the cloth's extent: at t = 0 a flat grid of 5 cm squares (to float32
    // rounding); by the end it can have fallen at most g t²/2 and moved
    // sideways at most by that much
    let first: Vec<[f64; 3]> = seen["first_cloud"]
        .as_array()
        .unwrap()
        .iter()
        .map(triple)
        .collect();
    assert_eq!(first.len(), n);
    let dist = |a: [f64; 3], b: [f64; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt();
    for j in 0..11 {
        for i in 0..11 {
            let p = first[j * 11 + i];
            if i < 10 {
                assert!(
                    (dist(p, first[j * 11 + i + 1]) - 0.05).abs() < 1e-6,
                    "({i}, {j})"
                );
            }
            if j < 10 {
                assert!(
                    (dist(p, first[(j + 1) * 11 + i]) - 0.05).abs() < 1e-6,
                    "({i}, {j})"
                );
            }
        }
    }
    let fall = 0.5 * 9.81 * DURATION_S * DURATION_S;
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in &first {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k] - fall);
            hi[k] = hi[k].max(p[k] + if k == 2 { 0.01 } else { fall });
        }
    }
    for (i, p) in last.iter().map(triple).enumerate() {
        for k in 0..3 {
            assert!(
                lo[k] <= p[k] && p[k] <= hi[k],
                "point {i}: {p:?} outside {lo:?}..{hi:?}"
            );
        }
    }

    // the mesh of the last frame: final.ply's triangles, float64 exactly
    let meshes = seen["meshes"].as_array().unwrap();
    assert_eq!(meshes.len(), frames);
    let m = meshes.last().unwrap();
    assert_eq!(ns(&m["stamp_ns"]), final_ns);
    assert_eq!(m["type"], 11); // TRIANGLE_LIST
    assert_eq!(m["points"].as_u64(), Some(3 * faces.len() as u64));
    assert_eq!(m["colors"], m["points"]);
    let mesh: Vec<[f64; 3]> = seen["last_mesh_points"]
        .as_array()
        .unwrap()
        .iter()
        .map(triple)
        .collect();
    let expect: Vec<[f64; 3]> = faces.iter().flat_map(|f| f.map(|i| verts[i])).collect();
    assert_eq!(mesh.len(), expect.len());
    // serde_json's float parsing can be off by an ulp of the JSON text
    for (k, (a, b)) in mesh.iter().zip(&expect).enumerate() {
        for c in 0..3 {
            assert!(
                (a[c] - b[c]).abs() <= 4.0 * f64::EPSILON * b[c].abs().max(1.0),
                "mesh point {k}: {a:?} vs {b:?}"
            );
        }
    }

    // the board: a DELETEALL, then a 12-triangle box
    let obs = seen["obstacles"].as_array().unwrap();
    assert_eq!(obs.len(), 2, "{obs:?}");
    assert_eq!(
        (&obs[0]["action"], &obs[0]["ns"]),
        (&3.into(), &"obstacles".into())
    );
    assert_eq!(
        (&obs[1]["type"], &obs[1]["text"], &obs[1]["points"]),
        (&11.into(), &"board".into(), &36.into())
    );

    // the diagnostics of the last frame
    let d = &seen["diagnostics"][0];
    assert_eq!(d["name"], "garment_sim: solver");
    assert_eq!(d["values"]["vertices"], "121");
    assert_eq!(d["values"]["sim_time_s"], "0.500000");
    assert_eq!(d["values"]["obstacles"], "1");
    assert_eq!(d["values"]["steps"], summary["steps"].to_string());
}

/// The node's `foxglove` parameter: Foxglove's client, in the node's own
/// loopback-only network namespace, sees the node's topics live with the
/// node's frame, and decodes every message.
#[test]
fn foxglove_client_sees_the_node_live() {
    let dir = live_dir();
    let out = support::Scratch::new("live_node");
    let json = out.join("client.json");
    let log = out.join("node.log");
    let script = "\"$0\" node --ros-args -p spacing:=0.05 -p real_time_factor:=1.0 \
                  -p duration:=2.0 -p frame_id:=map -p foxglove:=8765 \
                  2> \"$3\" & \
                  for i in $(seq 300); do grep -q 'live view on' \"$3\" 2>/dev/null && break; sleep 0.1; done; \
                  node \"$1\" ws://127.0.0.1:8765 1.0 30 > \"$2\"; c=$?; wait; exit $c";
    let client = dir.join("live_client.cjs");
    let o = support::in_loopback_namespace(
        script,
        &[
            support::garment_sim_path().as_ref(),
            client.as_os_str(),
            json.as_os_str(),
            log.as_os_str(),
        ],
    )
    .output()
    .expect("unshare (util-linux), ip (iproute2) and node are needed");
    let node_log = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        o.status.success(),
        "client or node failed: {}\n{node_log}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(
        node_log.contains("Foxglove live view on ws://127.0.0.1:8765"),
        "{node_log}"
    );
    let seen: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let mut topics: Vec<&str> = seen["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["topic"].as_str().unwrap())
        .collect();
    topics.sort();
    assert_eq!(
        topics,
        [
            "/clock",
            "/cloth/mesh",
            "/cloth/points",
            "/diagnostics",
            "/obstacles/markers"
        ]
    );
    assert_eq!(seen["trailing_bytes"], 0);
    let clouds = seen["clouds"].as_array().unwrap();
    assert!(clouds.len() >= 10, "{} clouds", clouds.len());
    let stamps: Vec<u64> = clouds.iter().map(|c| ns(&c["stamp_ns"])).collect();
    assert!(stamps.windows(2).all(|w| w[0] < w[1]), "{stamps:?}");
    for c in clouds {
        assert_eq!(c["frame_id"], "map");
        assert_eq!(c["width"].as_u64(), Some(121));
    }
    let last: Vec<[f64; 3]> = seen["last_cloud"]
        .as_array()
        .unwrap()
        .iter()
        .map(triple)
        .collect();
    assert_eq!(last.len(), 121);
    // the table drape's cloth: 50 cm across, near the board at 0.75 m
    assert!(last.iter().flatten().all(|c| c.is_finite()));
    let zs: Vec<f64> = last.iter().map(|p| p[2]).collect();
    assert!(zs.iter().all(|&z| (0.3..0.9).contains(&z)), "{zs:?}");
    let xs: Vec<f64> = last.iter().map(|p| p[0]).collect();
    let span =
        xs.iter().cloned().fold(f64::MIN, f64::max) - xs.iter().cloned().fold(f64::MAX, f64::min);
    assert!((0.3..0.55).contains(&span), "x span {span}");
    assert!(seen["meshes"].as_array().is_some_and(|m| !m.is_empty()));
    assert!(seen["diagnostics"].is_array());
}
