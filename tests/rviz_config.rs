//! config/garment_sim.rviz against the node: parsed as YAML, its fixed frame
//! is the node's default frame_id, every display topic is one the node
//! publishes (names resolved as the node resolves them, types as it
//! publishes them), with a QoS that matches what the node offers, and the
//! point cloud is coloured by a channel the node's clouds carry.

use garment_sim::bag::Qos;
use garment_sim::msgs::publish;
use garment_sim::msgs::{Marker, MarkerArray, PointCloud2, RosType};
use garment_sim::ros::args::RosArgs;
use garment_sim::ros::node::Names;
use garment_sim::ros::params::Settings;
use garment_sim::scene::{Overrides, Scene};
use serde_yaml::Value;
use std::path::Path;

fn config() -> Value {
    let text = std::fs::read_to_string("config/garment_sim.rviz").unwrap();
    serde_yaml::from_str(&text).expect("config/garment_sim.rviz is YAML")
}

/// Every display, those inside groups (`rviz_common/Group`) included.
fn displays(list: &Value) -> Vec<&Value> {
    let mut out = Vec::new();
    for d in list.as_sequence().expect("a list of displays") {
        if let Some(inner) = d.get("Displays") {
            out.extend(displays(inner));
        } else {
            out.push(d);
        }
    }
    out
}

fn s<'a>(v: &'a Value, key: &str) -> &'a str {
    v[key]
        .as_str()
        .unwrap_or_else(|| panic!("{key} is not a string: {v:?}"))
}

/// The message type an RViz display class subscribes to.
fn display_type(class: &str) -> Option<&'static str> {
    Some(match class {
        "rviz_default_plugins/PointCloud2" => PointCloud2::NAME,
        "rviz_default_plugins/Marker" => Marker::NAME,
        "rviz_default_plugins/MarkerArray" => MarkerArray::NAME,
        _ => return None,
    })
}

/// A subscription with these RViz policies receives from a publisher
/// offering `offered` (the ROS 2 request/offer rules for reliability and
/// durability).
fn compatible(topic: &Value, offered: &Qos) -> bool {
    let reliability = match s(topic, "Reliability Policy") {
        "Reliable" => offered.reliability == "reliable",
        "Best Effort" | "System Default" => true,
        other => panic!("unknown Reliability Policy {other}"),
    };
    let durability = match s(topic, "Durability Policy") {
        "Transient Local" => offered.durability == "transient_local",
        "Volatile" | "System Default" => true,
        other => panic!("unknown Durability Policy {other}"),
    };
    reliability && durability
}

#[test]
fn rviz_config_shows_what_the_node_publishes() {
    let c = config();
    let vm = &c["Visualization Manager"];
    let settings = Settings::default();
    assert_eq!(
        s(&vm["Global Options"], "Fixed Frame"),
        settings.frame_id,
        "the fixed frame is the node's default frame_id"
    );

    // the node's published topics (default namespace, no remapping) and
    // their types, the bag recorder's list of what the node offers
    let names = Names::resolve(&RosArgs::default()).unwrap();
    let published = [
        (names.points.as_str(), PointCloud2::NAME),
        (names.mesh.as_str(), Marker::NAME),
        (names.obstacle_markers.as_str(), MarkerArray::NAME),
    ];
    let offered = Qos::default_publisher();

    // the node's messages for the default scene, for their fields and namespaces
    let scene = Scene::load(Path::new(&settings.scene)).unwrap();
    let sim = scene
        .build(&Overrides {
            spacing: Some(0.05),
            ..Default::default()
        })
        .unwrap();
    let h = publish::header(&sim, &settings.frame_id);
    let cloud = publish::cloud(&sim, h.clone());
    let mut namespaces = vec![publish::cloth_marker(&sim, h.clone()).ns];
    namespaces.extend(
        publish::obstacle_markers(&sim, h)
            .markers
            .into_iter()
            .map(|m| m.ns),
    );

    let all = displays(&vm["Displays"]);
    let mut shown = Vec::new();
    for d in &all {
        let class = s(d, "Class");
        let Some(ty) = display_type(class) else {
            assert!(
                d.get("Topic").is_none(),
                "display {class} subscribes to a topic this test does not know"
            );
            continue;
        };
        let topic = &d["Topic"];
        let name = s(topic, "Value");
        let (_, node_ty) = published
            .iter()
            .find(|(n, _)| *n == name)
            .unwrap_or_else(|| panic!("{class} shows {name}, which the node does not publish"));
        assert_eq!(
            *node_ty, ty,
            "{name}: the node publishes {node_ty}, {class} reads {ty}"
        );
        assert!(
            compatible(topic, &offered),
            "{name}: RViz asks for {topic:?}, the node offers {offered:?}"
        );
        assert_eq!(s(topic, "History Policy"), "Keep Last");
        assert!(topic["Depth"].as_u64().is_some_and(|n| n >= 1));
        assert_eq!(d["Enabled"].as_bool(), Some(true), "{name}");
        if let Some(ns) = d["Namespaces"].as_mapping() {
            for k in ns.keys() {
                let k = k.as_str().unwrap();
                assert!(namespaces.iter().any(|n| n == k), "{name}: namespace {k}");
            }
        }
        if class == "rviz_default_plugins/PointCloud2" {
            assert_eq!(s(d, "Color Transformer"), "Intensity");
            let channel = s(d, "Channel Name");
            assert_eq!(channel, "strain");
            assert!(
                cloud.fields.iter().any(|f| f.name == channel),
                "the node's clouds have no field {channel}"
            );
            assert_eq!(s(d, "Position Transformer"), "XYZ");
        }
        shown.push(name);
    }
    shown.sort();
    let mut want: Vec<&str> = published.iter().map(|(n, _)| *n).collect();
    want.sort();
    assert_eq!(shown, want, "one display per visual topic of the node");

    assert!(
        all.iter()
            .any(|d| s(d, "Class") == "rviz_default_plugins/Grid"),
        "a grid"
    );

    // the orbit view looks at the cloth of the default scene from a distance
    // that frames it
    let view = &vm["Views"]["Current"];
    assert_eq!(s(view, "Class"), "rviz_default_plugins/Orbit");
    let f = &view["Focal Point"];
    let focal = [
        f["X"].as_f64().unwrap(),
        f["Y"].as_f64().unwrap(),
        f["Z"].as_f64().unwrap(),
    ];
    let n = sim.cloth.positions().len() as f64;
    let centre = sim.cloth.positions().iter().fold([0.0; 3], |a, p| {
        [a[0] + p.x / n, a[1] + p.y / n, a[2] + p.z / n]
    });
    let (lo, hi) =
        sim.cloth
            .positions()
            .iter()
            .fold(([f64::MAX; 3], [f64::MIN; 3]), |(lo, hi), p| {
                (
                    [lo[0].min(p.x), lo[1].min(p.y), lo[2].min(p.z)],
                    [hi[0].max(p.x), hi[1].max(p.y), hi[2].max(p.z)],
                )
            });
    let size = (0..3).map(|a| (hi[a] - lo[a]).powi(2)).sum::<f64>().sqrt();
    let off = (0..3)
        .map(|a| (focal[a] - centre[a]).powi(2))
        .sum::<f64>()
        .sqrt();
    assert!(
        off < 0.5 * size,
        "focal point {focal:?}, cloth centre {centre:?}"
    );
    let distance = view["Distance"].as_f64().unwrap();
    assert!(
        (1.5 * size..=6.0 * size).contains(&distance),
        "distance {distance} for a cloth of {size} m"
    );
}
