//! The message layer, shared by the node, the bags and the live view: ROS 2
//! message types laid out field for field as their ROS 2 Jazzy definitions so
//! that serde + CDR gives the bytes every ROS 2 implementation reads (checked
//! against the independent `rosbags` CDR codec in `tests/ros_msgs.py`), their
//! `ros2msg` schema texts ([`definitions`]), and the messages built from a
//! simulation ([`publish`]). No DDS here: [`crate::ros`] sends them,
//! [`crate::bag`] records them, [`crate::live`] serves them.
//!
//! Each type knows its ROS name (`pkg/msg/Type`) through [`RosType`].

pub mod definitions;
pub mod publish;

use serde::{Deserialize, Serialize};

/// A ROS 2 message type: its full name as in bags and DDS type names.
pub trait RosType {
    /// `package/msg/Type`.
    const NAME: &'static str;
}

macro_rules! ros_type {
    ($t:ty, $name:expr) => {
        impl RosType for $t {
            const NAME: &'static str = $name;
        }
    };
}

/// Serialises a message as CDR little-endian with the 4-byte encapsulation
/// header (`00 01 00 00`), as DDS and rosbag2 carry it.
pub fn to_cdr<T: Serialize>(msg: &T) -> Vec<u8> {
    let mut out = vec![0u8, 1, 0, 0];
    cdr_encoding::to_writer::<T, byteorder::LittleEndian, _>(&mut out, msg)
        .expect("CDR serialisation into a Vec cannot fail");
    out
}

/// Reads a CDR message with its encapsulation header (either byte order).
pub fn from_cdr<T: serde::de::DeserializeOwned>(bytes: &[u8]) -> anyhow::Result<T> {
    anyhow::ensure!(bytes.len() >= 4, "CDR message shorter than its header");
    let body = &bytes[4..];
    let v = match bytes[1] {
        0 => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body),
        1 => cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(body),
        k => anyhow::bail!("CDR encapsulation kind {k} not supported (plain CDR only)"),
    };
    Ok(v.map_err(|e| anyhow::anyhow!("CDR: {e}"))?.0)
}

// ---------------------------------------------------------------- builtin / std

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}
ros_type!(Time, "builtin_interfaces/msg/Time");

impl Time {
    /// From seconds (rounded to the nanosecond; negative times clamp to 0).
    pub fn from_secs(t: f64) -> Time {
        let ns = (t.max(0.0) * 1e9).round() as u64;
        Time {
            sec: (ns / 1_000_000_000) as i32,
            nanosec: (ns % 1_000_000_000) as u32,
        }
    }
    pub fn nanos(&self) -> i64 {
        self.sec as i64 * 1_000_000_000 + self.nanosec as i64
    }
    pub fn secs(&self) -> f64 {
        self.sec as f64 + self.nanosec as f64 * 1e-9
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Duration {
    pub sec: i32,
    pub nanosec: u32,
}
ros_type!(Duration, "builtin_interfaces/msg/Duration");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}
ros_type!(Header, "std_msgs/msg/Header");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StringMsg {
    pub data: String,
}
ros_type!(StringMsg, "std_msgs/msg/String");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRGBA {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}
ros_type!(ColorRGBA, "std_msgs/msg/ColorRGBA");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}
ros_type!(Clock, "rosgraph_msgs/msg/Clock");

// ---------------------------------------------------------------- geometry

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
ros_type!(Point, "geometry_msgs/msg/Point");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point32 {
    pub x: f32,
    pub y: f32,
    pub z: f32,
}
ros_type!(Point32, "geometry_msgs/msg/Point32");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Vector3 {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}
ros_type!(Vector3, "geometry_msgs/msg/Vector3");

#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Quaternion {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}
ros_type!(Quaternion, "geometry_msgs/msg/Quaternion");

impl Default for Quaternion {
    fn default() -> Self {
        Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 1.0,
        }
    }
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    pub position: Point,
    pub orientation: Quaternion,
}
ros_type!(Pose, "geometry_msgs/msg/Pose");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Twist {
    pub linear: Vector3,
    pub angular: Vector3,
}
ros_type!(Twist, "geometry_msgs/msg/Twist");

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Wrench {
    pub force: Vector3,
    pub torque: Vector3,
}
ros_type!(Wrench, "geometry_msgs/msg/Wrench");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct WrenchStamped {
    pub header: Header,
    pub wrench: Wrench,
}
ros_type!(WrenchStamped, "geometry_msgs/msg/WrenchStamped");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    pub points: Vec<Point32>,
}
ros_type!(Polygon, "geometry_msgs/msg/Polygon");

impl Pose {
    pub fn from_isometry(p: &nalgebra::Isometry3<f64>) -> Pose {
        let t = p.translation.vector;
        let q = p.rotation.coords; // (i, j, k, w)
        Pose {
            position: Point {
                x: t.x,
                y: t.y,
                z: t.z,
            },
            orientation: Quaternion {
                x: q.x,
                y: q.y,
                z: q.z,
                w: q.w,
            },
        }
    }

    /// The rigid transform, or an error naming the bad field (NaN, zero quaternion).
    pub fn to_isometry(&self) -> Result<nalgebra::Isometry3<f64>, String> {
        let p = self.position;
        let o = self.orientation;
        if ![p.x, p.y, p.z].iter().all(|v| v.is_finite()) {
            return Err(format!(
                "position ({}, {}, {}) is not finite",
                p.x, p.y, p.z
            ));
        }
        let n = (o.x * o.x + o.y * o.y + o.z * o.z + o.w * o.w).sqrt();
        if !n.is_finite() || n < 1e-6 {
            return Err(format!(
                "orientation ({}, {}, {}, {}) is not a rotation quaternion",
                o.x, o.y, o.z, o.w
            ));
        }
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
            o.w, o.x, o.y, o.z,
        ));
        Ok(nalgebra::Isometry3::from_parts(
            nalgebra::Translation3::new(p.x, p.y, p.z),
            q,
        ))
    }
}

impl From<nalgebra::Vector3<f64>> for Point {
    fn from(v: nalgebra::Vector3<f64>) -> Point {
        Point {
            x: v.x,
            y: v.y,
            z: v.z,
        }
    }
}

impl From<nalgebra::Vector3<f64>> for Vector3 {
    fn from(v: nalgebra::Vector3<f64>) -> Vector3 {
        Vector3 {
            x: v.x,
            y: v.y,
            z: v.z,
        }
    }
}

impl Point {
    pub fn vector(&self) -> nalgebra::Vector3<f64> {
        nalgebra::Vector3::new(self.x, self.y, self.z)
    }
}

impl Vector3 {
    pub fn vector(&self) -> nalgebra::Vector3<f64> {
        nalgebra::Vector3::new(self.x, self.y, self.z)
    }
}

// ---------------------------------------------------------------- sensor

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}
ros_type!(PointField, "sensor_msgs/msg/PointField");

impl PointField {
    pub const FLOAT32: u8 = 7;
    pub const UINT32: u8 = 6;
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PointCloud2 {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
    pub is_dense: bool,
}
ros_type!(PointCloud2, "sensor_msgs/msg/PointCloud2");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CompressedImage {
    pub header: Header,
    pub format: String,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}
ros_type!(CompressedImage, "sensor_msgs/msg/CompressedImage");

// ---------------------------------------------------------------- visualization

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct UVCoordinate {
    pub u: f32,
    pub v: f32,
}
ros_type!(UVCoordinate, "visualization_msgs/msg/UVCoordinate");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshFile {
    pub filename: String,
    #[serde(with = "serde_bytes")]
    pub data: Vec<u8>,
}
ros_type!(MeshFile, "visualization_msgs/msg/MeshFile");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Marker {
    pub header: Header,
    pub ns: String,
    pub id: i32,
    #[serde(rename = "type")]
    pub type_: i32,
    pub action: i32,
    pub pose: Pose,
    pub scale: Vector3,
    pub color: ColorRGBA,
    pub lifetime: Duration,
    pub frame_locked: bool,
    pub points: Vec<Point>,
    pub colors: Vec<ColorRGBA>,
    pub texture_resource: String,
    pub texture: CompressedImage,
    pub uv_coordinates: Vec<UVCoordinate>,
    pub text: String,
    pub mesh_resource: String,
    pub mesh_file: MeshFile,
    pub mesh_use_embedded_materials: bool,
}
ros_type!(Marker, "visualization_msgs/msg/Marker");

impl Marker {
    pub const CUBE: i32 = 1;
    pub const SPHERE: i32 = 2;
    pub const CYLINDER: i32 = 3;
    pub const LINE_LIST: i32 = 5;
    pub const TRIANGLE_LIST: i32 = 11;
    pub const ADD: i32 = 0;
    pub const DELETE: i32 = 2;
    pub const DELETEALL: i32 = 3;
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MarkerArray {
    pub markers: Vec<Marker>,
}
ros_type!(MarkerArray, "visualization_msgs/msg/MarkerArray");

// ---------------------------------------------------------------- diagnostics

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    pub key: String,
    pub value: String,
}
ros_type!(KeyValue, "diagnostic_msgs/msg/KeyValue");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    pub level: u8,
    pub name: String,
    pub message: String,
    pub hardware_id: String,
    pub values: Vec<KeyValue>,
}
ros_type!(DiagnosticStatus, "diagnostic_msgs/msg/DiagnosticStatus");

impl DiagnosticStatus {
    pub const OK: u8 = 0;
    pub const WARN: u8 = 1;
    pub const ERROR: u8 = 2;
}

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    pub header: Header,
    pub status: Vec<DiagnosticStatus>,
}
ros_type!(DiagnosticArray, "diagnostic_msgs/msg/DiagnosticArray");

// ---------------------------------------------------------------- shapes

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SolidPrimitive {
    #[serde(rename = "type")]
    pub type_: u8,
    /// Bounded sequence (≤ 3) on the wire: same CDR as an unbounded one.
    pub dimensions: Vec<f64>,
    pub polygon: Polygon,
}
ros_type!(SolidPrimitive, "shape_msgs/msg/SolidPrimitive");

impl SolidPrimitive {
    pub const BOX: u8 = 1;
    pub const SPHERE: u8 = 2;
    pub const CYLINDER: u8 = 3;
    pub const CONE: u8 = 4;
    pub const PRISM: u8 = 5;
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshTriangle {
    pub vertex_indices: [u32; 3],
}
ros_type!(MeshTriangle, "shape_msgs/msg/MeshTriangle");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    pub triangles: Vec<MeshTriangle>,
    pub vertices: Vec<Point>,
}
ros_type!(Mesh, "shape_msgs/msg/Mesh");

// ---------------------------------------------------------------- std_srvs

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TriggerRequest {
    /// CDR of an empty struct is one padding byte (rosidl's structure_needs_at_least_one_member).
    pub structure_needs_at_least_one_member: u8,
}
ros_type!(TriggerRequest, "std_srvs/srv/Trigger_Request");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TriggerResponse {
    pub success: bool,
    pub message: String,
}
ros_type!(TriggerResponse, "std_srvs/srv/Trigger_Response");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetBoolRequest {
    pub data: bool,
}
ros_type!(SetBoolRequest, "std_srvs/srv/SetBool_Request");

#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SetBoolResponse {
    pub success: bool,
    pub message: String,
}
ros_type!(SetBoolResponse, "std_srvs/srv/SetBool_Response");

// ---------------------------------------------------------------- garment_sim_msgs (msg/)

/// `garment_sim_msgs/msg/Obstacle` (msg/garment_sim_msgs/msg/Obstacle.msg).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Obstacle {
    pub header: Header,
    pub id: String,
    pub pose: Pose,
    pub primitives: Vec<SolidPrimitive>,
    pub primitive_poses: Vec<Pose>,
    pub meshes: Vec<Mesh>,
    pub mesh_poses: Vec<Pose>,
    pub velocity: Twist,
    pub thickness: f64,
    pub friction: f64,
    pub operation: u8,
}
ros_type!(Obstacle, "garment_sim_msgs/msg/Obstacle");

impl Obstacle {
    pub const ADD: u8 = 0;
    pub const REMOVE: u8 = 1;
    pub const MOVE: u8 = 3;
}

/// `garment_sim_msgs/msg/Body` (msg/garment_sim_msgs/msg/Body.msg): a
/// deforming body's topology (once) and vertex positions (every frame).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Body {
    pub header: Header,
    pub id: String,
    pub triangles: Vec<u32>,
    pub positions: Vec<f32>,
    pub thickness: f64,
    pub friction: f64,
}
ros_type!(Body, "garment_sim_msgs/msg/Body");

// ---------------------------------------------------------------- mesh_msgs
// The mesh messages of naturerobots/mesh_tools (BSD-3-Clause), which RViz's
// mesh plugin displays: laid out field for field as mesh_msgs/msg/*.msg.

/// `mesh_msgs/msg/MeshTriangleIndices`: one triangle's vertex indices.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshTriangleIndices {
    pub vertex_indices: [u32; 3],
}
ros_type!(MeshTriangleIndices, "mesh_msgs/msg/MeshTriangleIndices");

/// `mesh_msgs/msg/MeshGeometry`: vertices (float64), their normals, faces.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshGeometry {
    pub vertices: Vec<Point>,
    pub vertex_normals: Vec<Point>,
    pub faces: Vec<MeshTriangleIndices>,
}
ros_type!(MeshGeometry, "mesh_msgs/msg/MeshGeometry");

/// `mesh_msgs/msg/MeshGeometryStamped`: a whole mesh, named by `uuid`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshGeometryStamped {
    pub header: Header,
    pub uuid: String,
    pub mesh_geometry: MeshGeometry,
}
ros_type!(MeshGeometryStamped, "mesh_msgs/msg/MeshGeometryStamped");

/// `garment_sim_msgs/msg/Pin` (msg/garment_sim_msgs/msg/Pin.msg).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Pin {
    pub header: Header,
    pub operation: u8,
    pub vertices: Vec<u32>,
    pub grid_i: Vec<u32>,
    pub grid_j: Vec<u32>,
    /// Garment trials: the panel whose grid `grid_i`/`grid_j` index.
    pub panel: String,
    pub targets: Vec<Point>,
    pub velocities: Vec<Vector3>,
}
ros_type!(Pin, "garment_sim_msgs/msg/Pin");

impl Pin {
    pub const PIN: u8 = 0;
    pub const MOVE: u8 = 1;
    pub const RELEASE: u8 = 2;
    pub const RELEASE_ALL: u8 = 3;
}

/// `garment_sim_msgs/srv/Step` request.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StepRequest {
    pub steps: u32,
}
ros_type!(StepRequest, "garment_sim_msgs/srv/Step_Request");

/// `garment_sim_msgs/srv/Step` response.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct StepResponse {
    pub success: bool,
    pub message: String,
    pub sim_time: Time,
}
ros_type!(StepResponse, "garment_sim_msgs/srv/Step_Response");

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cdr_layout_by_hand() {
        // Header: sec, nanosec, string (len incl. NUL, bytes, NUL), aligned.
        let h = Header {
            stamp: Time { sec: 2, nanosec: 3 },
            frame_id: "ab".into(),
        };
        let b = to_cdr(&h);
        assert_eq!(
            b,
            vec![0, 1, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0, 3, 0, 0, 0, b'a', b'b', 0]
        );
        // f64 after a u8 aligns to 8 from the start of the body (after the header).
        let p = SolidPrimitive {
            type_: 1,
            dimensions: vec![1.0],
            polygon: Polygon::default(),
        };
        let b = to_cdr(&p);
        // type (1) + pad to 4 + len (4) + f64 at body offset 8 + polygon len.
        assert_eq!(b.len(), 4 + 8 + 8 + 4);
        let back: SolidPrimitive = from_cdr(&b).unwrap();
        assert_eq!(back, p);
    }

    #[test]
    fn time_from_secs() {
        let t = Time::from_secs(1.25);
        assert_eq!((t.sec, t.nanosec), (1, 250_000_000));
        assert_eq!(t.nanos(), 1_250_000_000);
    }

    #[test]
    fn pose_round_trip_and_bad_quaternion() {
        let iso = nalgebra::Isometry3::new(
            nalgebra::Vector3::new(0.1, 0.2, 0.3),
            nalgebra::Vector3::new(0.0, 0.0, 0.5),
        );
        let p = Pose::from_isometry(&iso);
        let back = p.to_isometry().unwrap();
        assert!((back.to_homogeneous() - iso.to_homogeneous()).norm() < 1e-12);
        let bad = Pose {
            orientation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 0.0,
            },
            ..p
        };
        assert!(bad.to_isometry().unwrap_err().contains("quaternion"));
    }
}
