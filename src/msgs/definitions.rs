//! The ROS 2 Jazzy message definitions (`.msg` text) of every type a bag
//! holds, and the concatenated `ros2msg` schema text of a type with its
//! dependencies, laid out as rosbag2 writes it into MCAP schemas (see
//! [`schema_text`]): the type's own definition, then for each dependency an
//! empty line, a line of 80 `=`, a line `MSG: pkg/Type` naming it as the
//! field that uses it does, and that type's definition.
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
        "geometry_msgs/msg/Wrench",
        "Vector3  force\nVector3  torque\n",
    ),
    (
        "geometry_msgs/msg/WrenchStamped",
        "std_msgs/Header header\nWrench wrench\n",
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

/// The full name (`pkg/msg/Type`) of a type named `pkg/Type` or `pkg/msg/Type`.
pub fn full_name(name: &str) -> Option<String> {
    match name.split('/').collect::<Vec<_>>().as_slice() {
        [p, t] => Some(format!("{p}/msg/{t}")),
        [p, "msg", t] => Some(format!("{p}/msg/{t}")),
        _ => None,
    }
}

/// The types a definition refers to, named as rosbag2 names them: as the
/// field writes them (`std_msgs/Header`, `foo_msgs/msg/Bar`), a relative name
/// (`PointField`) prefixed with the package of `name` (`sensor_msgs/PointField`);
/// each once, in byte order of the names.
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
        let dep = if base.contains('/') {
            base.to_string()
        } else {
            format!("{pkg}/{base}")
        };
        if !out.contains(&dep) {
            out.push(dep);
        }
    }
    out.sort();
    out
}

/// The full `ros2msg` schema text of `name` (`pkg/msg/Type`) as rosbag2's
/// `ros2 bag record` writes it (rosbag2_cpp's LocalMessageDefinitionSource):
/// the type's definition, then for each dependency not written yet, in the
/// order of [`dependencies_of`] and depth first, an empty line, a line of 80
/// `=`, a line `MSG: ` with the dependency's name as its field writes it
/// (`MSG: std_msgs/Header`, `MSG: sensor_msgs/PointField`) and that type's
/// definition. Foxglove's `@foxglove/rosmsg` matches these names exactly
/// against the field types. `None` if the type or one of its dependencies is
/// unknown.
pub fn schema_text(name: &str) -> Option<String> {
    fn append(name: &str, seen: &mut Vec<String>, text: &mut String) -> Option<()> {
        let def = definition(&full_name(name)?)?;
        text.push_str(def);
        for dep in dependencies_of(name, def) {
            if seen.contains(&dep) {
                continue;
            }
            seen.push(dep.clone());
            text.push('\n');
            text.push_str(SEPARATOR);
            text.push_str("\nMSG: ");
            text.push_str(&dep);
            text.push('\n');
            append(&dep, seen, text)?;
        }
        Some(())
    }
    let mut text = String::new();
    append(name, &mut Vec::new(), &mut text)?;
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
    fn point_cloud_schema_is_laid_out_as_rosbag2_writes_it() {
        // rosbag2: dependencies in byte order of their names as the fields
        // write them, each after an empty line, 80 `=` and `MSG: <name>`
        let sep = format!("\n{SEPARATOR}\nMSG: ");
        let expected = [
            definition("sensor_msgs/msg/PointCloud2").unwrap(),
            &sep,
            "sensor_msgs/PointField\n",
            definition("sensor_msgs/msg/PointField").unwrap(),
            &sep,
            "std_msgs/Header\n",
            "builtin_interfaces/Time stamp\nstring frame_id\n",
            &sep,
            "builtin_interfaces/Time\n",
            "int32 sec\nuint32 nanosec\n",
        ]
        .concat();
        assert_eq!(
            schema_text("sensor_msgs/msg/PointCloud2").unwrap(),
            expected
        );
        assert!(expected.contains(
            "bool is_dense\n\n================================================================================\n\
             MSG: sensor_msgs/PointField\nuint8 INT8    = 1\n"
        ));
    }

    #[test]
    fn marker_array_schema_has_each_dependency_once_by_its_field_name() {
        let m = schema_text("visualization_msgs/msg/MarkerArray").unwrap();
        assert!(m.starts_with("Marker[] markers\n\n"));
        let names: Vec<&str> = m.lines().filter_map(|l| l.strip_prefix("MSG: ")).collect();
        // depth first: Pose brings Quaternion, CompressedImage brings Header
        // and Time; Marker's own std_msgs/Header is then written already
        assert_eq!(
            names,
            [
                "visualization_msgs/Marker",
                "builtin_interfaces/Duration",
                "geometry_msgs/Point",
                "geometry_msgs/Pose",
                "geometry_msgs/Quaternion",
                "geometry_msgs/Vector3",
                "sensor_msgs/CompressedImage",
                "std_msgs/Header",
                "builtin_interfaces/Time",
                "std_msgs/ColorRGBA",
                "visualization_msgs/MeshFile",
                "visualization_msgs/UVCoordinate",
            ]
        );
        assert_eq!(m.matches(SEPARATOR).count(), names.len(), "{m}");
        assert!(m.contains("MSG: geometry_msgs/Quaternion\nfloat64 x 0"));
        assert!(!m.contains("/msg/"), "{m}");
    }

    #[test]
    fn dependencies_are_named_as_the_fields_write_them() {
        let d = dependencies_of(
            "diagnostic_msgs/msg/DiagnosticStatus",
            definition("diagnostic_msgs/msg/DiagnosticStatus").unwrap(),
        );
        // constants are not dependencies; a relative name takes the package
        assert_eq!(d, vec!["diagnostic_msgs/KeyValue".to_string()]);
        // a name with `msg/` keeps it; comments are not fields
        let d = dependencies_of(
            "foo_msgs/msg/Bar",
            "# std_msgs/Header h\nfoo_msgs/msg/Baz[<=3] a # Qux q\nQux[] b\nstring<=5 s\n",
        );
        assert_eq!(
            d,
            vec!["foo_msgs/Qux".to_string(), "foo_msgs/msg/Baz".to_string()]
        );
        // the node's own messages, with their comments
        let d = dependencies_of(
            "garment_sim_msgs/msg/Obstacle",
            include_str!("../../msg/garment_sim_msgs/msg/Obstacle.msg"),
        );
        assert_eq!(
            d,
            [
                "geometry_msgs/Pose",
                "geometry_msgs/Twist",
                "shape_msgs/Mesh",
                "shape_msgs/SolidPrimitive",
                "std_msgs/Header",
            ]
        );
        let d = dependencies_of(
            "garment_sim_msgs/msg/Pin",
            include_str!("../../msg/garment_sim_msgs/msg/Pin.msg"),
        );
        assert_eq!(
            d,
            [
                "geometry_msgs/Point",
                "geometry_msgs/Vector3",
                "std_msgs/Header"
            ]
        );
    }

    #[test]
    fn full_names() {
        assert_eq!(full_name("std_msgs/Header").unwrap(), "std_msgs/msg/Header");
        assert_eq!(
            full_name("std_msgs/msg/Header").unwrap(),
            "std_msgs/msg/Header"
        );
        assert_eq!(full_name("Header"), None);
        assert_eq!(full_name("std_srvs/srv/Trigger"), None);
    }
}
