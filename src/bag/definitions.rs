//! The ROS 2 Jazzy message definitions (`.msg` text) of every type a bag
//! holds, and the concatenated `ros2msg` schema text of a type with its
//! dependencies, as rosbag2 writes it into MCAP schemas: the type's own
//! definition, then for each dependency (depth first, in order of first use)
//! a line of 80 `=`, a line `MSG: pkg/Type` and that type's definition. The
//! dependency is named as the fields name it (`std_msgs/Header`, without
//! `msg/`), as rosbag2's definition source does; Foxglove's `ros2msg` parser
//! (`@foxglove/rosmsg`) resolves a field's type by that exact name.
//!
//! The texts are those of ros2/common_interfaces, rcl_interfaces and
//! ros2/geometry2 on Jazzy with comments left out (constants kept); they are
//! checked field for field against the independent `rosbags` type store in
//! `tests/bag_interop.py`.

/// `(full name, definition)` of every known type.
pub const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/msg/Time", "int32 sec\nuint32 nanosec\n"),
    (
        "builtin_interfaces/msg/Duration",
        "int32 sec\nuint32 nanosec\n",
    ),
    (
        "std_msgs/msg/Header",
        "builtin_interfaces/Time stamp\nstring frame_id\n",
    ),
    ("std_msgs/msg/String", "string data\n"),
    (
        "std_msgs/msg/ColorRGBA",
        "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    ),
    ("rosgraph_msgs/msg/Clock", "builtin_interfaces/Time clock\n"),
    (
        "geometry_msgs/msg/Point",
        "float64 x\nfloat64 y\nfloat64 z\n",
    ),
    (
        "geometry_msgs/msg/Vector3",
        "float64 x\nfloat64 y\nfloat64 z\n",
    ),
    (
        "geometry_msgs/msg/Quaternion",
        "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    ),
    (
        "geometry_msgs/msg/Pose",
        "Point position\nQuaternion orientation\n",
    ),
    (
        "sensor_msgs/msg/PointField",
        "uint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\nuint8 UINT16  = 4\n\
uint8 INT32   = 5\nuint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n\n\
string name\nuint32 offset\nuint8  datatype\nuint32 count\n",
    ),
    (
        "sensor_msgs/msg/PointCloud2",
        "std_msgs/Header header\n\nuint32 height\nuint32 width\n\nPointField[] fields\n\n\
bool    is_bigendian\nuint32  point_step\nuint32  row_step\nuint8[] data\n\nbool is_dense\n",
    ),
    (
        "sensor_msgs/msg/CompressedImage",
        "std_msgs/Header header\nstring format\nuint8[] data\n",
    ),
    (
        "visualization_msgs/msg/UVCoordinate",
        "float32 u\nfloat32 v\n",
    ),
    (
        "visualization_msgs/msg/MeshFile",
        "string filename\nuint8[] data\n",
    ),
    (
        "visualization_msgs/msg/Marker",
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n\
int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n\
int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\nint32 ARROW_STRIP=12\n\n\
int32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n\n\
std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n\
geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n\
builtin_interfaces/Duration lifetime\nbool frame_locked\n\
geometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\n\
string texture_resource\nsensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\n\
string text\nstring mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials\n",
    ),
    ("visualization_msgs/msg/MarkerArray", "Marker[] markers\n"),
    ("diagnostic_msgs/msg/KeyValue", "string key\nstring value\n"),
    (
        "diagnostic_msgs/msg/DiagnosticStatus",
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n\n\
byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values\n",
    ),
    (
        "diagnostic_msgs/msg/DiagnosticArray",
        "std_msgs/Header header\nDiagnosticStatus[] status\n",
    ),
];

/// The line between a definition and each dependency's.
pub const SEPARATOR: &str =
    "================================================================================";

/// The definition text of one type (`pkg/msg/Type`), without dependencies.
pub fn definition(name: &str) -> Option<&'static str> {
    DEFINITIONS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, d)| *d)
}

const PRIMITIVES: &[&str] = &[
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
    "uint32", "int64", "uint64", "string", "wstring",
];

/// The types a definition refers to, as full names, in order of first use.
/// Relative names (`PointField`) are in the package of `name`.
pub fn dependencies_of(name: &str, text: &str) -> Vec<String> {
    let pkg = name.split('/').next().unwrap_or_default();
    let mut out: Vec<String> = Vec::new();
    for line in text.lines() {
        let line = line.split('#').next().unwrap_or_default().trim();
        let Some(ty) = line.split_whitespace().next() else {
            continue;
        };
        // strip array suffixes ([], [3], [<=3]) and bounded strings (string<=5)
        let base = ty.split(['[', '<']).next().unwrap_or(ty);
        if PRIMITIVES.contains(&base) {
            continue;
        }
        let full = match base.split('/').collect::<Vec<_>>().as_slice() {
            [p, t] => format!("{p}/msg/{t}"),
            [p, m, t] => format!("{p}/{m}/{t}"),
            [t] => format!("{pkg}/msg/{t}"),
            _ => continue,
        };
        if !out.contains(&full) {
            out.push(full);
        }
    }
    out
}

/// The full `ros2msg` schema text of `name`: its definition and, depth first,
/// every dependency's, each after a line of 80 `=` and `MSG: pkg/Type`.
/// `None` if the type or one of its dependencies is unknown.
pub fn schema_text(name: &str) -> Option<String> {
    let mut order: Vec<String> = Vec::new();
    fn visit(n: &str, order: &mut Vec<String>) -> Option<()> {
        let text = definition(n)?;
        for d in dependencies_of(n, text) {
            if !order.contains(&d) {
                order.push(d.clone());
                visit(&d, order)?;
            }
        }
        Some(())
    }
    let mut text = definition(name)?.to_string();
    visit(name, &mut order)?;
    for d in order.iter().filter(|d| d.as_str() != name) {
        text.push_str(SEPARATOR);
        text.push_str("\nMSG: ");
        text.push_str(&d.replacen("/msg/", "/", 1));
        text.push('\n');
        text.push_str(definition(d)?);
    }
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_dependency_is_known() {
        for (name, _) in DEFINITIONS {
            assert!(schema_text(name).is_some(), "{name}");
        }
    }

    #[test]
    fn point_cloud_schema_has_its_dependencies_once() {
        let s = schema_text("sensor_msgs/msg/PointCloud2").unwrap();
        assert!(s.starts_with("std_msgs/Header header\n"));
        for dep in [
            "std_msgs/Header",
            "builtin_interfaces/Time",
            "sensor_msgs/PointField",
        ] {
            assert_eq!(s.matches(&format!("MSG: {dep}\n")).count(), 1, "{dep}\n{s}");
        }
        assert_eq!(s.matches(SEPARATOR).count(), 3);
        // Marker, Header, Time, Pose, Point, Quaternion, Vector3, ColorRGBA,
        // Duration, CompressedImage, UVCoordinate, MeshFile
        let m = schema_text("visualization_msgs/msg/MarkerArray").unwrap();
        assert_eq!(m.matches(SEPARATOR).count(), 12, "{m}");
        assert!(m.contains("MSG: geometry_msgs/Quaternion\nfloat64 x 0"));
        assert!(!m.contains("/msg/"), "{m}");
    }

    #[test]
    fn constants_are_not_dependencies() {
        let d = dependencies_of(
            "diagnostic_msgs/msg/DiagnosticStatus",
            definition("diagnostic_msgs/msg/DiagnosticStatus").unwrap(),
        );
        assert_eq!(d, vec!["diagnostic_msgs/msg/KeyValue".to_string()]);
    }
}
