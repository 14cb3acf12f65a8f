"""The garment_sim node against an independent DDS implementation: Eclipse
Cyclone DDS (the `cyclonedds` Python binding, the DDS of ROS 2's
rmw_cyclonedds), speaking the ROS 2 topic and service conventions by hand
(`rt/` topics, `rq/`/`rr/` service topics, `pkg::msg::dds_::Type_` type names),
with the types written here from their .msg definitions (ROS 2 Jazzy,
garment_sim_msgs in msg/, mesh_msgs of naturerobots/mesh_tools).

Run by tests/ros_node.rs inside a network namespace it makes (loopback only).
The node binary is in GARMENT_SIM_BIN."""

import math
import os
import pathlib
import subprocess
import time
from dataclasses import dataclass, field

import pytest

cyclonedds = pytest.importorskip("cyclonedds")
import cyclonedds.idl.types as t  # noqa: E402
from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.pub import DataWriter  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402

BIN = os.environ.get("GARMENT_SIM_BIN")
RELIABLE = Qos(Policy.Reliability.Reliable(max_blocking_time=1_000_000_000), Policy.History.KeepLast(50))
# /rosout is transient-local (depth 1 in ros2-client; 1000 in rcl): a late reader gets the last line.
LATCHED = Qos(Policy.Reliability.Reliable(max_blocking_time=1_000_000_000), Policy.History.KeepLast(50),
              Policy.Durability.TransientLocal)


def ros(pkg, kind, name):
    return f"{pkg}::{kind}::dds_::{name}_"


# ---- ROS 2 Jazzy types, written from their .msg definitions ----
@dataclass
class Time(IdlStruct, typename=ros("builtin_interfaces", "msg", "Time")):
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Duration(IdlStruct, typename=ros("builtin_interfaces", "msg", "Duration")):
    sec: t.int32 = 0
    nanosec: t.uint32 = 0


@dataclass
class Header(IdlStruct, typename=ros("std_msgs", "msg", "Header")):
    stamp: Time = field(default_factory=Time)
    frame_id: str = ""


@dataclass
class StringMsg(IdlStruct, typename=ros("std_msgs", "msg", "String")):
    data: str = ""


@dataclass
class Clock(IdlStruct, typename=ros("rosgraph_msgs", "msg", "Clock")):
    clock: Time = field(default_factory=Time)


@dataclass
class PointField(IdlStruct, typename=ros("sensor_msgs", "msg", "PointField")):
    name: str
    offset: t.uint32
    datatype: t.uint8
    count: t.uint32


@dataclass
class PointCloud2(IdlStruct, typename=ros("sensor_msgs", "msg", "PointCloud2")):
    header: Header
    height: t.uint32
    width: t.uint32
    fields: t.sequence[PointField]
    is_bigendian: bool
    point_step: t.uint32
    row_step: t.uint32
    data: t.sequence[t.uint8]
    is_dense: bool


@dataclass
class Point(IdlStruct, typename=ros("geometry_msgs", "msg", "Point")):
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Point32(IdlStruct, typename=ros("geometry_msgs", "msg", "Point32")):
    x: t.float32 = 0.0
    y: t.float32 = 0.0
    z: t.float32 = 0.0


@dataclass
class Vector3(IdlStruct, typename=ros("geometry_msgs", "msg", "Vector3")):
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0


@dataclass
class Quaternion(IdlStruct, typename=ros("geometry_msgs", "msg", "Quaternion")):
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    w: float = 1.0


@dataclass
class Pose(IdlStruct, typename=ros("geometry_msgs", "msg", "Pose")):
    position: Point = field(default_factory=Point)
    orientation: Quaternion = field(default_factory=Quaternion)


@dataclass
class Twist(IdlStruct, typename=ros("geometry_msgs", "msg", "Twist")):
    linear: Vector3 = field(default_factory=Vector3)
    angular: Vector3 = field(default_factory=Vector3)


@dataclass
class Polygon(IdlStruct, typename=ros("geometry_msgs", "msg", "Polygon")):
    points: t.sequence[Point32] = field(default_factory=list)


@dataclass
class ColorRGBA(IdlStruct, typename=ros("std_msgs", "msg", "ColorRGBA")):
    r: t.float32
    g: t.float32
    b: t.float32
    a: t.float32


@dataclass
class CompressedImage(IdlStruct, typename=ros("sensor_msgs", "msg", "CompressedImage")):
    header: Header
    format: str
    data: t.sequence[t.uint8]


@dataclass
class UVCoordinate(IdlStruct, typename=ros("visualization_msgs", "msg", "UVCoordinate")):
    u: t.float32
    v: t.float32


@dataclass
class MeshFile(IdlStruct, typename=ros("visualization_msgs", "msg", "MeshFile")):
    filename: str
    data: t.sequence[t.uint8]


@dataclass
class Marker(IdlStruct, typename=ros("visualization_msgs", "msg", "Marker")):
    header: Header
    ns: str
    id: t.int32
    type: t.int32
    action: t.int32
    pose: Pose
    scale: Vector3
    color: ColorRGBA
    lifetime: Duration
    frame_locked: bool
    points: t.sequence[Point]
    colors: t.sequence[ColorRGBA]
    texture_resource: str
    texture: CompressedImage
    uv_coordinates: t.sequence[UVCoordinate]
    text: str
    mesh_resource: str
    mesh_file: MeshFile
    mesh_use_embedded_materials: bool


@dataclass
class MarkerArray(IdlStruct, typename=ros("visualization_msgs", "msg", "MarkerArray")):
    markers: t.sequence[Marker]


@dataclass
class KeyValue(IdlStruct, typename=ros("diagnostic_msgs", "msg", "KeyValue")):
    key: str
    value: str


@dataclass
class DiagnosticStatus(IdlStruct, typename=ros("diagnostic_msgs", "msg", "DiagnosticStatus")):
    level: t.uint8
    name: str
    message: str
    hardware_id: str
    values: t.sequence[KeyValue]


@dataclass
class DiagnosticArray(IdlStruct, typename=ros("diagnostic_msgs", "msg", "DiagnosticArray")):
    header: Header
    status: t.sequence[DiagnosticStatus]


@dataclass
class Log(IdlStruct, typename=ros("rcl_interfaces", "msg", "Log")):
    stamp: Time
    level: t.uint8
    name: str
    msg: str
    file: str
    function: str
    line: t.uint32


@dataclass
class SolidPrimitive(IdlStruct, typename=ros("shape_msgs", "msg", "SolidPrimitive")):
    type: t.uint8 = 0
    dimensions: t.sequence[float, 3] = field(default_factory=list)
    polygon: Polygon = field(default_factory=Polygon)


@dataclass
class MeshTriangle(IdlStruct, typename=ros("shape_msgs", "msg", "MeshTriangle")):
    vertex_indices: t.array[t.uint32, 3]


@dataclass
class Mesh(IdlStruct, typename=ros("shape_msgs", "msg", "Mesh")):
    triangles: t.sequence[MeshTriangle] = field(default_factory=list)
    vertices: t.sequence[Point] = field(default_factory=list)


# ---- garment_sim_msgs (msg/) ----
@dataclass
class Obstacle(IdlStruct, typename=ros("garment_sim_msgs", "msg", "Obstacle")):
    header: Header = field(default_factory=Header)
    id: str = ""
    pose: Pose = field(default_factory=Pose)
    primitives: t.sequence[SolidPrimitive] = field(default_factory=list)
    primitive_poses: t.sequence[Pose] = field(default_factory=list)
    meshes: t.sequence[Mesh] = field(default_factory=list)
    mesh_poses: t.sequence[Pose] = field(default_factory=list)
    velocity: Twist = field(default_factory=Twist)
    thickness: float = math.nan
    friction: float = math.nan
    operation: t.uint8 = 0


@dataclass
class Pin(IdlStruct, typename=ros("garment_sim_msgs", "msg", "Pin")):
    header: Header = field(default_factory=Header)
    operation: t.uint8 = 0
    vertices: t.sequence[t.uint32] = field(default_factory=list)
    grid_i: t.sequence[t.uint32] = field(default_factory=list)
    grid_j: t.sequence[t.uint32] = field(default_factory=list)
    panel: str = ""
    targets: t.sequence[Point] = field(default_factory=list)
    velocities: t.sequence[Vector3] = field(default_factory=list)


@dataclass
class Body(IdlStruct, typename=ros("garment_sim_msgs", "msg", "Body")):
    header: Header = field(default_factory=Header)
    id: str = ""
    triangles: t.sequence[t.uint32] = field(default_factory=list)
    positions: t.sequence[t.float32] = field(default_factory=list)
    thickness: float = math.nan
    friction: float = math.nan


# ---- mesh_msgs (naturerobots/mesh_tools, the meshes of RViz's mesh plugin) ----
@dataclass
class MeshTriangleIndices(IdlStruct, typename=ros("mesh_msgs", "msg", "MeshTriangleIndices")):
    vertex_indices: t.array[t.uint32, 3]


@dataclass
class MeshGeometry(IdlStruct, typename=ros("mesh_msgs", "msg", "MeshGeometry")):
    vertices: t.sequence[Point] = field(default_factory=list)
    vertex_normals: t.sequence[Point] = field(default_factory=list)
    faces: t.sequence[MeshTriangleIndices] = field(default_factory=list)


@dataclass
class MeshGeometryStamped(IdlStruct, typename=ros("mesh_msgs", "msg", "MeshGeometryStamped")):
    header: Header = field(default_factory=Header)
    uuid: str = ""
    mesh_geometry: MeshGeometry = field(default_factory=MeshGeometry)


# ---- services (request/reply types of the ROS 2 DDS mapping) ----
@dataclass
class SetBool_Request(IdlStruct, typename=ros("std_srvs", "srv", "SetBool_Request")):
    data: bool


@dataclass
class SetBool_Response(IdlStruct, typename=ros("std_srvs", "srv", "SetBool_Response")):
    success: bool
    message: str


@dataclass
class Trigger_Request(IdlStruct, typename=ros("std_srvs", "srv", "Trigger_Request")):
    structure_needs_at_least_one_member: t.uint8 = 0


@dataclass
class Trigger_Response(IdlStruct, typename=ros("std_srvs", "srv", "Trigger_Response")):
    success: bool
    message: str


@dataclass
class Step_Request(IdlStruct, typename=ros("garment_sim_msgs", "srv", "Step_Request")):
    steps: t.uint32


@dataclass
class Step_Response(IdlStruct, typename=ros("garment_sim_msgs", "srv", "Step_Response")):
    success: bool
    message: str
    sim_time: Time


@dataclass
class ParameterValue(IdlStruct, typename=ros("rcl_interfaces", "msg", "ParameterValue")):
    type: t.uint8 = 0
    bool_value: bool = False
    integer_value: t.int64 = 0
    double_value: float = 0.0
    string_value: str = ""
    byte_array_value: t.sequence[t.uint8] = field(default_factory=list)
    bool_array_value: t.sequence[bool] = field(default_factory=list)
    integer_array_value: t.sequence[t.int64] = field(default_factory=list)
    double_array_value: t.sequence[float] = field(default_factory=list)
    string_array_value: t.sequence[str] = field(default_factory=list)


@dataclass
class Parameter(IdlStruct, typename=ros("rcl_interfaces", "msg", "Parameter")):
    name: str
    value: ParameterValue


@dataclass
class SetParametersResult(IdlStruct, typename=ros("rcl_interfaces", "msg", "SetParametersResult")):
    successful: bool
    reason: str


@dataclass
class SetParameters_Request(IdlStruct, typename=ros("rcl_interfaces", "srv", "SetParameters_Request")):
    parameters: t.sequence[Parameter]


@dataclass
class SetParameters_Response(IdlStruct, typename=ros("rcl_interfaces", "srv", "SetParameters_Response")):
    results: t.sequence[SetParametersResult]


@dataclass
class ListParametersResult(IdlStruct, typename=ros("rcl_interfaces", "msg", "ListParametersResult")):
    names: t.sequence[str]
    prefixes: t.sequence[str]


@dataclass
class ListParameters_Request(IdlStruct, typename=ros("rcl_interfaces", "srv", "ListParameters_Request")):
    prefixes: t.sequence[str]
    depth: t.uint64


@dataclass
class ListParameters_Response(IdlStruct, typename=ros("rcl_interfaces", "srv", "ListParameters_Response")):
    result: ListParametersResult


@dataclass
class GetParameters_Request(IdlStruct, typename=ros("rcl_interfaces", "srv", "GetParameters_Request")):
    names: t.sequence[str]


@dataclass
class GetParameters_Response(IdlStruct, typename=ros("rcl_interfaces", "srv", "GetParameters_Response")):
    values: t.sequence[ParameterValue]


# ---- helpers ----
class Node:
    """A garment_sim node process and a Cyclone DDS participant beside it."""

    def __init__(self, *ros_args, ns=""):
        assert BIN, "run through `cargo test --release --test ros_node`"
        self.ns = ns
        self.proc = subprocess.Popen(
            [BIN, "node", "--ros-args", *ros_args],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        )
        self.dp = DomainParticipant(0)
        self.readers = {}

    def reader(self, topic, typ, qos=RELIABLE):
        if topic not in self.readers:
            self.readers[topic] = DataReader(self.dp, Topic(self.dp, "rt" + topic, typ), qos=qos)
        return self.readers[topic]

    def writer(self, topic, typ):
        return DataWriter(self.dp, Topic(self.dp, "rt" + topic, typ), qos=RELIABLE)

    def wait(self, topic, typ, pred=lambda m: True, timeout=30.0):
        latched = topic == "/rosout" or topic.endswith("scene_description")
        r = self.reader(topic, typ, LATCHED if latched else RELIABLE)
        end = time.time() + timeout
        while time.time() < end:
            assert self.proc.poll() is None, "node exited:\n" + self.proc.stdout.read()
            for m in r.take(N=100):
                if pred(m):
                    return m
            time.sleep(0.02)
        raise AssertionError(f"nothing on {topic} within {timeout} s")

    def latest(self, topic, typ, timeout=30.0):
        """The newest sample after what is already queued (waits for a fresh one)."""
        r = self.reader(topic, typ)
        r.take(N=1000)
        m = self.wait(topic, typ, timeout=timeout)
        rest = r.take(N=1000)
        return rest[-1] if rest else m

    def call(self, service, req_t, resp_t, request, timeout=30.0):
        """One request on rq/<service>Request, sent once both service topics have
        matched the node's endpoints; the reply comes on rr/<service>Reply."""
        w = DataWriter(self.dp, Topic(self.dp, f"rq{service}Request", req_t), qos=RELIABLE)
        r = DataReader(self.dp, Topic(self.dp, f"rr{service}Reply", resp_t), qos=RELIABLE)
        end = time.time() + timeout
        while not (w.get_matched_subscriptions() and r.get_matched_publications()):
            assert time.time() < end, f"service {service} not discovered within {timeout} s"
            assert self.proc.poll() is None, "node exited:\n" + self.proc.stdout.read()
            time.sleep(0.05)
        time.sleep(0.2)
        w.write(request)
        while time.time() < end:
            assert self.proc.poll() is None, "node exited:\n" + self.proc.stdout.read()
            got = r.take(N=10)
            if got:
                return got[0]
            time.sleep(0.02)
        raise AssertionError(f"no reply from {service} within {timeout} s")

    def measured_rtf(self, seconds):
        """Simulated seconds per wall second over `seconds`, from the cloud
        stamps (after half a second for a new pace to settle)."""
        time.sleep(0.5)
        a = self.latest("/cloth/points", PointCloud2)
        wa = time.time()
        time.sleep(seconds)
        b = self.latest("/cloth/points", PointCloud2)
        return (stamp(b.header) - stamp(a.header)) / (time.time() - wa)

    def diag(self, d):
        return {kv.key: kv.value for kv in d.status[0].values}

    def stop(self):
        self.proc.terminate()
        try:
            out, _ = self.proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, _ = self.proc.communicate()
        return self.proc.returncode, out


def xyz(cloud):
    import numpy as np

    a = np.frombuffer(bytes(cloud.data), dtype=np.float32).reshape(cloud.width, cloud.point_step // 4)
    names = [f.name for f in cloud.fields]
    return a[:, [names.index("x"), names.index("y"), names.index("z")]]


def secs(t):
    return t.sec + 1e-9 * t.nanosec


def stamp(h):
    return secs(h.stamp)


# ---- tests ----
def test_publishes_under_namespace_and_remap(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text("/**:\n  ros__parameters:\n    frame_id: map\n    spacing: 0.05\n")
    n = Node("--params-file", str(params), "-p", "real_time_factor:=0.0", "-p", "publish_rate:=50.0",
             "-r", "__ns:=/lab", "-r", "cloth/mesh:=/viz/cloth")
    try:
        c = n.wait("/lab/cloth/points", PointCloud2, lambda m: stamp(m.header) > 0.2)
        assert c.header.frame_id == "map"
        assert [f.name for f in c.fields][:3] == ["x", "y", "z"]
        assert c.width == 121 and c.height == 1  # 0.5 m cloth at 5 cm
        p = xyz(c)
        assert p[:, 2].max() < 0.8 and p[:, 2].min() > 0.0
        m = n.wait("/viz/cloth", Marker)
        assert m.type == 11 and len(m.points) == 3 * 2 * 100
        o = n.wait("/lab/obstacles/markers", MarkerArray, lambda a: len(a.markers) >= 2)
        assert o.markers[0].action == 3 and o.markers[1].text == "board"
        d = n.wait("/lab/diagnostics", DiagnosticArray)
        kv = n.diag(d)
        assert float(kv["step_time_ms"]) > 0 and kv["rejected_messages"] == "0"
        assert kv["recovered_steps"] == "0", kv
        ck = n.wait("/clock", Clock, lambda k: secs(k.clock) > stamp(c.header))
        log = n.wait("/rosout", Log, lambda l: "scene" in l.msg)
        desc = n.wait("/lab/scene_description", StringMsg)  # latched: arrives though published at start
        assert "scene_yaml:" in desc.data and "fabric_yaml:" in desc.data and "areal_mass" in desc.data
        assert log.name.endswith("garment_sim")
        # stamps advance at the publish rate in simulated time
        s = [stamp(n.wait("/lab/cloth/points", PointCloud2).header) for _ in range(5)]
        assert all(b > a for a, b in zip(s, s[1:]))
    finally:
        code, out = n.stop()
    assert code == 0, out


def read_ply(path):
    import numpy as np

    lines = open(path).read().splitlines()
    n = int(next(l for l in lines if l.startswith("element vertex")).split()[2])
    start = lines.index("end_header") + 1
    return np.array([[float(v) for v in l.split()[:3]] for l in lines[start:start + n]])


def test_coordinates_match_the_headless_simulation(tmp_path):
    """Paused at start, the cloud is the scene's initial cloth; after ~/step 50 it
    is where `garment_sim drape` puts it after 50 steps (same solver)."""
    import numpy as np

    for d, dur in [("h0", "0"), ("h50", "0.05")]:
        out = subprocess.run([BIN, "drape", "config/scenes/table_drape.yaml", "--spacing", "0.05",
                              "--solver", "cholesky", "--duration", dur, "--out", str(tmp_path / d)],
                             capture_output=True, text=True)
        assert out.returncode == 0, out.stderr
    n = Node("-p", "spacing:=0.05", "-p", "solver:=cholesky", "-p", "paused:=true")
    try:
        c = n.wait("/cloth/points", PointCloud2)
        assert stamp(c.header) == 0.0 and c.width == 121
        err0 = np.abs(xyz(c) - read_ply(tmp_path / "h0" / "final.ply")).max()
        r = n.call("/garment_sim/step", Step_Request, Step_Response, Step_Request(steps=50))
        assert r.success and abs(secs(r.sim_time) - 0.05) < 1e-9, r
        c = n.wait("/cloth/points", PointCloud2, lambda c: abs(stamp(c.header) - 0.05) < 1e-9)
        ref = read_ply(tmp_path / "h50" / "final.ply")
        err50 = np.abs(xyz(c) - ref).max()
        moved = np.abs(ref - read_ply(tmp_path / "h0" / "final.ply")).max()
        print(f"cloud vs headless: {err0:.1e} m at t = 0, {err50:.1e} m after 50 steps (cloth moved {moved:.3f} m)")
        assert err0 < 1e-6 and err50 < 1e-6 and moved > 1e-3
    finally:
        code, out = n.stop()
    assert code == 0, out


def test_the_cloth_responds_to_an_obstacle():
    """A sphere rising under the lying cloth lifts it; no vertex is ever inside it.
    (Contacts are vertex against obstacle: the grid must be finer than the
    obstacle, here 2 cm cells under a 5 cm sphere.)"""
    import numpy as np

    n = Node("-p", "spacing:=0.02", "-p", "publish_rate:=30.0")
    try:
        c = n.wait("/cloth/points", PointCloud2, lambda c: stamp(c.header) > 1.0, timeout=60)
        p = xyz(c)
        k = int(np.argmin(np.linalg.norm(p[:, :2] - p[:, :2].mean(axis=0), axis=1)))
        r = 0.05
        centre = p[k] - np.array([0.0, 0.0, r + 0.01])
        obs = n.writer("/obstacles", Obstacle)
        time.sleep(1.0)
        obs.write(Obstacle(header=Header(frame_id="world"), id="finger",
                           pose=Pose(position=Point(x=float(centre[0]), y=float(centre[1]), z=float(centre[2]))),
                           primitives=[SolidPrimitive(type=2, dimensions=[r])], primitive_poses=[Pose()],
                           velocity=Twist(linear=Vector3(z=0.1)), thickness=0.003))
        clouds, spheres = {}, {}
        lifted = -1.0
        # 1.5 s of simulated time with the sphere (30 Hz: about 45 frames); the
        # wall clock only bounds it, so a loaded machine that paces slower
        # than real time still sees the whole rise
        end = time.time() + 60.0
        both = []
        while time.time() < end and not (both and both[-1] - both[0] >= 1.5):
            for cc in n.reader("/cloth/points", PointCloud2).take(N=100):
                clouds[stamp(cc.header)] = xyz(cc)
            for a in n.reader("/obstacles/markers", MarkerArray).take(N=100):
                for m in a.markers:
                    if m.text == "finger":
                        spheres[stamp(m.header)] = np.array([m.pose.position.x, m.pose.position.y, m.pose.position.z])
            both = sorted(set(clouds) & set(spheres))
            time.sleep(0.02)
        assert len(both) > 30, len(both)
        closest = min(np.linalg.norm(clouds[t] - spheres[t], axis=1).min() for t in both)
        rise = spheres[both[-1]][2] - spheres[both[0]][2]
        top = spheres[both[-1]][2] + r
        lifted = clouds[both[-1]][:, 2].max() - clouds[both[0]][:, 2].max()
        print(f"sphere rose {rise:.3f} m, the cloth's highest point {lifted:.3f} m (ends {1e3 * (clouds[both[-1]][:, 2].max() - top):.1f} mm "
              f"above the sphere's top); closest vertex {closest * 1e3:.2f} mm from the centre "
              f"(radius {r * 1e3:.0f} mm, contact distance {(r + 0.005) * 1e3:.0f} mm)")
        assert closest >= r, closest  # never inside the sphere
        assert rise > 0.1 and lifted > 0.8 * rise  # the cloth is carried up
        assert clouds[both[-1]][:, 2].max() >= top  # draped over it
    finally:
        code, out = n.stop()
    assert code == 0, out


def test_obstacles_pins_bad_input_and_services():
    n = Node("-p", "spacing:=0.05", "-p", "real_time_factor:=0.0", "-p", "publish_rate:=50.0",
             "-p", "max_mesh_triangles:=10", "-p", "max_messages_per_step:=5")
    try:
        n.wait("/cloth/points", PointCloud2)
        obs = n.writer("/obstacles", Obstacle)
        pins = n.writer("/pins", Pin)
        time.sleep(1.0)
        # add a sphere obstacle
        sphere = Obstacle(header=Header(frame_id="world"), id="ball",
                          pose=Pose(position=Point(x=0.3, y=0.0, z=1.2)),
                          primitives=[SolidPrimitive(type=2, dimensions=[0.05])], primitive_poses=[Pose()])
        obs.write(sphere)
        a = n.wait("/obstacles/markers", MarkerArray, lambda a: any(m.text == "ball" for m in a.markers))
        ball = [m for m in a.markers if m.text == "ball"][0]
        assert abs(ball.pose.position.z - 1.2) < 1e-12
        # bad input, each refused, logged and counted while the node runs on:
        bad = [
            ("pins", Pin(header=Header(frame_id="world"), operation=0, vertices=[99999]), "out of range"),
            ("pins", Pin(header=Header(frame_id="world"), operation=0, vertices=[0],
                         targets=[Point(x=math.nan, y=0.0, z=1.0)]), "not finite"),
            ("obstacles", Obstacle(header=Header(frame_id="base_link"), id="x",
                                   primitives=[SolidPrimitive(type=1, dimensions=[0.1, 0.1, 0.1])],
                                   primitive_poses=[Pose()]), "base_link"),
            ("obstacles", Obstacle(header=Header(frame_id="world"), id="inf",
                                   pose=Pose(position=Point(x=math.inf)),
                                   primitives=[SolidPrimitive(type=2, dimensions=[0.1])],
                                   primitive_poses=[Pose()]), "not finite"),
            ("obstacles", Obstacle(header=Header(frame_id="world"), id="holey",
                                   meshes=[Mesh(triangles=[MeshTriangle([0, 1, 5])],
                                                vertices=[Point(), Point(x=1.0), Point(y=1.0)])],
                                   mesh_poses=[Pose()]), "vertex 5"),
            ("obstacles", Obstacle(header=Header(frame_id="world"), id="ghost", operation=3), "no such obstacle"),
            ("obstacles", Obstacle(header=Header(frame_id="world"), id="ghost", operation=1), "no such obstacle"),
            ("obstacles", Obstacle(header=Header(frame_id="world"), id="huge",
                                   meshes=[Mesh(triangles=[MeshTriangle([0, 1, 2])] * 12,
                                                vertices=[Point(), Point(x=1.0), Point(y=1.0)])],
                                   mesh_poses=[Pose()]), "max_mesh_triangles"),
        ]
        for k, (topic, msg, why) in enumerate(bad):
            (pins if topic == "pins" else obs).write(msg)
            d = n.wait("/diagnostics", DiagnosticArray, lambda d: n.diag(d)["rejected_messages"] == str(k + 1))
            assert why in d.status[0].message, (why, d.status[0].message)
            assert d.status[0].level == 1
            n.wait("/rosout", Log, lambda l: why in l.msg)
        t_bad = stamp(n.latest("/cloth/points", PointCloud2).header)
        # a flood of valid pins, faster than the steps: the excess is dropped and counted
        for _ in range(400):
            pins.write(Pin(header=Header(frame_id="world"), operation=0, vertices=[60]))
        d = n.wait("/diagnostics", DiagnosticArray, lambda d: int(n.diag(d)["dropped_messages"]) > 0)
        print(f"flood of 400 pins: {n.diag(d)['dropped_messages']} dropped")
        assert n.diag(d)["rejected_messages"] == str(len(bad))
        # still running
        assert stamp(n.latest("/cloth/points", PointCloud2).header) > t_bad
        pins.write(Pin(header=Header(frame_id="world"), operation=3))  # RELEASE_ALL
        # a valid pin: vertex 0 held at a point above the table
        pins.write(Pin(header=Header(frame_id="world"), operation=0, grid_i=[0], grid_j=[0],
                       targets=[Point(x=-0.5, y=-0.5, z=1.5)]))
        c = n.wait("/cloth/points", PointCloud2, lambda c: abs(float(xyz(c)[0, 2]) - 1.5) < 1e-5)
        assert abs(float(xyz(c)[0, 0]) + 0.5) < 1e-5
        # pause, step 10, reset
        r = n.call("/garment_sim/set_paused", SetBool_Request, SetBool_Response, SetBool_Request(data=True))
        assert r.success
        time.sleep(0.5)
        t0 = stamp(n.latest("/cloth/points", PointCloud2).header)
        time.sleep(0.5)
        assert stamp(n.latest("/cloth/points", PointCloud2).header) == t0  # paused: still published, same time
        r = n.call("/garment_sim/step", Step_Request, Step_Response, Step_Request(steps=10))
        assert r.success, r.message
        t1 = secs(r.sim_time)
        assert abs((t1 - t0) - 10 * 0.001) < 1e-6, (t0, t1)
        r = n.call("/garment_sim/reset", Trigger_Request, Trigger_Response, Trigger_Request())
        assert r.success, r.message
        c = n.wait("/cloth/points", PointCloud2, lambda c: stamp(c.header) == 0.0)
        assert c.width == 121
    finally:
        code, out = n.stop()
    assert code == 0, out
    assert f"{len(bad)} messages rejected" in out, out


def test_parameter_services():
    # renamed node (-r __node:=...): its services follow its name
    n = Node("-p", "spacing:=0.05", "-p", "real_time_factor:=0.0", "-r", "__node:=cloth_sim")
    try:
        n.wait("/cloth/points", PointCloud2)
        g = n.call("/cloth_sim/get_parameters", GetParameters_Request, GetParameters_Response,
                   GetParameters_Request(names=["publish_rate", "frame_id", "spacing"]))
        assert [v.type for v in g.values] == [3, 4, 3]
        assert g.values[0].double_value == 30.0 and g.values[1].string_value == "world"
        assert g.values[2].double_value == 0.05
        r = n.call("/cloth_sim/set_parameters", SetParameters_Request, SetParameters_Response,
                   SetParameters_Request(parameters=[
                       Parameter("frame_id", ParameterValue(type=4, string_value="odom")),
                       Parameter("publish_rate", ParameterValue(type=3, double_value=-1.0)),
                   ]))
        assert r.results[0].successful
        assert not r.results[1].successful and "publish_rate" in r.results[1].reason
        c = n.wait("/cloth/points", PointCloud2, lambda c: c.header.frame_id == "odom")
        assert c.width == 121
        # pacing: real_time_factor 0.5 at run time → simulated time runs at half the wall clock
        r = n.call("/cloth_sim/set_parameters", SetParameters_Request, SetParameters_Response,
                   SetParameters_Request(parameters=[
                       Parameter("real_time_factor", ParameterValue(type=3, double_value=0.5))]))
        assert r.results[0].successful
        ratio = n.measured_rtf(3.0)
        print(f"real-time factor 0.5 asked, {ratio:.3f} measured")
        assert 0.4 < ratio < 0.56, ratio
    finally:
        code, out = n.stop()
    assert code == 0, out


def parameter_table():
    """The node's parameters as docs/ros.md lists them (a unit test checks
    that table against the node's own): {name: (type, runtime)}."""
    here = os.path.dirname(os.path.abspath(__file__))
    text = open(os.path.join(here, "..", "docs", "ros.md")).read()
    rows = text.split("<!-- parameters:begin -->")[1].split("<!-- parameters:end -->")[0]
    table = {}
    for line in rows.strip().splitlines()[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        table[cells[0].strip("`")] = (cells[1], cells[3] == "yes")
    return table


def test_every_runtime_parameter_is_listed_and_takes_effect():
    table = parameter_table()
    kinds = {"bool": 1, "integer": 2, "double": 3, "string": 4}
    n = Node("-p", "spacing:=0.05", "-p", "real_time_factor:=0.0", "-p", "publish_rate:=50.0")
    srv = "/garment_sim/"

    def set_param(name, value):
        kind = table[name][0]
        v = ParameterValue(type=kinds[kind])
        setattr(v, {"bool": "bool_value", "integer": "integer_value", "double": "double_value",
                    "string": "string_value"}[kind], value)
        r = n.call(srv + "set_parameters", SetParameters_Request, SetParameters_Response,
                   SetParameters_Request(parameters=[Parameter(name, v)]))
        assert r.results[0].successful, (name, value, r.results[0].reason)

    try:
        n.wait("/cloth/points", PointCloud2)
        listed = n.call(srv + "list_parameters", ListParameters_Request, ListParameters_Response,
                        ListParameters_Request(prefixes=[], depth=0)).result.names
        print("listed:", sorted(listed))
        assert set(table) <= set(listed), set(table) - set(listed)
        g = n.call(srv + "get_parameters", GetParameters_Request, GetParameters_Response,
                   GetParameters_Request(names=list(table)))
        assert [v.type for v in g.values] == [kinds[k] for k, _ in table.values()]
        runtime = {name for name, (_, rt) in table.items() if rt}
        checked = set()
        # frame_id: what is published carries the new frame
        set_param("frame_id", "odom")
        n.wait("/cloth/points", PointCloud2, lambda c: c.header.frame_id == "odom")
        set_param("frame_id", "world")
        n.wait("/cloth/points", PointCloud2, lambda c: c.header.frame_id == "world")
        checked.add("frame_id")
        # real_time_factor: simulated time follows the wall clock at 1.0
        set_param("real_time_factor", 1.0)
        ratio = n.measured_rtf(2.0)
        print(f"real-time factor 1 asked, {ratio:.3f} measured")
        assert 0.8 < ratio < 1.1, ratio
        checked.add("real_time_factor")
        # publish_rate: at 10 Hz (was 50) frames 0.1 s of simulated time apart
        set_param("publish_rate", 10.0)
        time.sleep(0.5)
        r = n.reader("/cloth/points", PointCloud2)
        r.take(N=1000)
        stamps = []
        end = time.time() + 1.5
        while time.time() < end:
            stamps += [stamp(c.header) for c in r.take(N=100)]
            time.sleep(0.02)
        gaps = [b - a for a, b in zip(stamps, stamps[1:])]
        print("frame gaps at 10 Hz:", [round(g, 4) for g in gaps])
        assert len(gaps) >= 5 and all(abs(g - 0.1) < 2e-3 for g in gaps), gaps
        checked.add("publish_rate")
        # paused: simulated time stops, then goes on
        set_param("paused", True)
        time.sleep(0.5)
        t0 = stamp(n.latest("/cloth/points", PointCloud2).header)
        time.sleep(0.5)
        assert stamp(n.latest("/cloth/points", PointCloud2).header) == t0
        set_param("paused", False)
        n.wait("/cloth/points", PointCloud2, lambda c: stamp(c.header) > t0)
        checked.add("paused")
        # max_mesh_triangles: a 3-triangle mesh refused at 2, accepted at 3
        obs = n.writer("/obstacles", Obstacle)
        pins = n.writer("/pins", Pin)
        time.sleep(1.0)
        tri = Mesh(triangles=[MeshTriangle([0, 1, 2])] * 3,
                   vertices=[Point(x=2.0), Point(x=3.0), Point(x=2.0, y=1.0)])
        set_param("max_mesh_triangles", 2)
        obs.write(Obstacle(header=Header(frame_id="world"), id="tri", meshes=[tri], mesh_poses=[Pose()]))
        d = n.wait("/diagnostics", DiagnosticArray, lambda d: n.diag(d)["rejected_messages"] == "1")
        assert "max_mesh_triangles = 2" in d.status[0].message, d.status[0].message
        set_param("max_mesh_triangles", 3)
        obs.write(Obstacle(header=Header(frame_id="world"), id="tri", meshes=[tri], mesh_poses=[Pose()]))
        n.wait("/obstacles/markers", MarkerArray, lambda a: any(m.text == "tri" for m in a.markers))
        checked.add("max_mesh_triangles")
        # max_messages_per_step: 40 pins at once (fewer than the default 100) are cut to 1 per step
        set_param("max_messages_per_step", 1)
        for _ in range(40):
            pins.write(Pin(header=Header(frame_id="world"), operation=0, vertices=[60]))
        d = n.wait("/diagnostics", DiagnosticArray, lambda d: int(n.diag(d)["dropped_messages"]) > 0)
        print(f"40 pins at max_messages_per_step 1: {n.diag(d)['dropped_messages']} dropped")
        checked.add("max_messages_per_step")
        assert checked == runtime, (checked, runtime)
    finally:
        code, out = n.stop()
    assert code == 0, out


def box_frames(n):
    """A 19.9 cm square box, 1 cm below to a top rising 2 cm a frame (0.62 m/s at 32
    frames a second): vertices and outward triangles of each frame. Every
    coordinate is a multiple of 2^-10 m, so float32 carries it exactly."""
    h = 102 / 1024
    tris = [(0, 2, 1), (0, 3, 2), (4, 5, 6), (4, 6, 7), (0, 1, 5), (0, 5, 4),
            (1, 2, 6), (1, 6, 5), (2, 3, 7), (2, 7, 6), (3, 0, 4), (3, 4, 7)]
    frames = []
    for k in range(n):
        top = (240 + 20 * k) / 1024
        frames.append([(x, y, z) for z in (-10 / 1024, top) for (x, y) in ((-h, -h), (h, -h), (h, h), (-h, h))])
    return frames, tris


def box_from_files(tmp_path):
    """The box of `box_frames(10)` lifting a 30 cm cloth, run headless with the frames
    read from OBJ files by a scene's `motion` (thickness 4 mm, friction 0.4): the
    frames, the triangles, the final cloth, and the path of the same scene without the box."""
    frames, tris = box_frames(10)
    (tmp_path / "frames").mkdir()
    for k, f in enumerate(frames):
        lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in f] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in tris]
        (tmp_path / "frames" / f"box_{k}.obj").write_text("\n".join(lines) + "\n")
    fabric = pathlib.Path("config/fabrics/acrylic.yaml").resolve()
    common = (f"cloth:\n  fabric: {fabric}\n  size: [0.3, 0.3]\n  spacing: 0.03\n"
              "  pose: { position: [-0.15, -0.15, 0.3] }\ndt: 0.00390625\nduration: 0.375\noutput_rate: 32\n")
    (tmp_path / "files.yaml").write_text(
        "name: box_from_files\n" + common + "obstacles:\n  - id: box\n"
        "    motion: { frames: \"frames/box_*.obj\", fps: 32 }\n    thickness: 0.004\n    friction: 0.4\n")
    (tmp_path / "stream.yaml").write_text("name: box_streamed\n" + common)
    out = subprocess.run([BIN, "drape", str(tmp_path / "files.yaml"), "--threads", "1",
                          "--out", str(tmp_path / "ref")], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    return frames, tris, read_ply(tmp_path / "ref" / "final.ply"), tmp_path / "stream.yaml"


def test_a_body_streamed_frame_by_frame_moves_the_cloth_as_its_frames_from_files(tmp_path):
    """A box streamed on `body` (topology once, then frames stamped k/32 s, the node
    stepped in lockstep) lifts the cloth as the same frames read from OBJ files by a
    scene's `motion` do headless; bad frames are refused, counted, and the node runs on."""
    import numpy as np

    frames, tris, ref, scene = box_from_files(tmp_path)
    n = Node("-p", f"scene:={scene}", "-p", "paused:=true", "-p", "threads:=1",
             "-p", "publish_rate:=32.0")
    try:
        c = n.wait("/cloth/points", PointCloud2)
        start = xyz(c)
        body = n.writer("/body", Body)
        flat = lambda f: [float(v) for p in f for v in p]
        hdr = lambda k: Header(stamp=Time(sec=0, nanosec=k * 31250000), frame_id="world")
        body.write(Body(header=hdr(0), id="box", triangles=[i for t in tris for i in t],
                        positions=flat(frames[0]), thickness=0.004, friction=0.4))
        n.wait("/rosout", Log, lambda l: 'added body "box"' in l.msg)
        for k in range(1, len(frames)):
            body.write(Body(header=hdr(k), id="box", positions=flat(frames[k])))
        d = n.wait("/diagnostics", DiagnosticArray, lambda d: n.diag(d).get("body_messages") == "10")
        r = n.call("/garment_sim/step", Step_Request, Step_Response, Step_Request(steps=96))
        assert r.success and abs(secs(r.sim_time) - 0.375) < 1e-9, r
        c = n.wait("/cloth/points", PointCloud2, lambda c: abs(stamp(c.header) - 0.375) < 1e-9)
        err = float(np.abs(xyz(c) - ref).max())
        lifted = float(ref[:, 2].max() - start[:, 2].max())
        print(f"streamed vs files: {err:.2e} m after 96 steps; the box lifted the cloth {lifted * 1e3:.1f} mm")
        assert lifted > 0.05, lifted  # the box did move the cloth
        assert err < 1e-5, err
        # bad frames: refused, counted, the node runs on
        body.write(Body(header=hdr(20), id="box", positions=[0.0] * 21))  # 7 vertices, not 8
        nan = flat(frames[9])
        nan[4] = math.nan
        body.write(Body(header=hdr(21), id="box", positions=nan))
        body.write(Body(header=hdr(5), id="box", positions=flat(frames[9])))  # before the last frame
        body.write(Body(header=hdr(22), id="ghost", positions=flat(frames[9])))  # no topology
        body.write(Body(header=hdr(23), id="box", triangles=[0, 1, 8], positions=flat(frames[9])))
        want = {"body_refused_vertex_count": "1", "body_refused_non_finite": "1",
                "body_refused_out_of_order": "1", "body_refused_no_topology": "1",
                "body_refused_triangles": "1"}
        d = n.wait("/diagnostics", DiagnosticArray,
                   lambda d: all(n.diag(d).get(k) == v for k, v in want.items()))
        assert n.diag(d)["body_messages"] == "10" and int(n.diag(d)["rejected_messages"]) == 5
        r = n.call("/garment_sim/step", Step_Request, Step_Response, Step_Request(steps=2))
        assert r.success, r
    finally:
        code, out = n.stop()
    assert code == 0, out
    assert "positions[4] (vertex 1, y) is NaN" in out, out


def test_a_mesh_geometry_stream_moves_the_cloth_as_the_same_frames_from_files(tmp_path):
    """The same box sent on `body_mesh` as mesh_msgs/MeshGeometryStamped, the whole mesh
    (float64 vertices, normals, faces) in every message: the first is the topology, the
    next ones, with the same faces, its frames. With the box's thickness and friction as
    the node's parameters, the cloth ends where the frames from files put it; bad
    meshes are refused, counted by kind, and the node runs on."""
    import numpy as np

    frames, tris, ref, scene = box_from_files(tmp_path)
    n = Node("-p", f"scene:={scene}", "-p", "paused:=true", "-p", "threads:=1",
             "-p", "publish_rate:=32.0", "-p", "body_mesh_thickness:=0.004",
             "-p", "body_mesh_friction:=0.4")
    try:
        c = n.wait("/cloth/points", PointCloud2)
        start = xyz(c)
        body = n.writer("/body_mesh", MeshGeometryStamped)
        faces = [MeshTriangleIndices(list(f)) for f in tris]
        hdr = lambda k: Header(stamp=Time(sec=0, nanosec=k * 31250000), frame_id="world")

        def mesh(k, f, faces=faces, uuid="box"):
            centre = np.mean(f, axis=0)
            normals = [(np.array(p) - centre) / np.linalg.norm(np.array(p) - centre) for p in f]
            return MeshGeometryStamped(header=hdr(k), uuid=uuid, mesh_geometry=MeshGeometry(
                vertices=[Point(x=x, y=y, z=z) for x, y, z in f],
                vertex_normals=[Point(x=float(a), y=float(b), z=float(c)) for a, b, c in normals],
                faces=faces))

        body.write(mesh(0, frames[0]))
        n.wait("/rosout", Log, lambda l: 'added body "box": 8 vertices, 12 triangles' in l.msg)
        for k in range(1, len(frames)):
            body.write(mesh(k, frames[k]))
        n.wait("/diagnostics", DiagnosticArray, lambda d: n.diag(d).get("body_messages") == "10")
        r = n.call("/garment_sim/step", Step_Request, Step_Response, Step_Request(steps=96))
        assert r.success and abs(secs(r.sim_time) - 0.375) < 1e-9, r
        c = n.wait("/cloth/points", PointCloud2, lambda c: abs(stamp(c.header) - 0.375) < 1e-9)
        err = float(np.abs(xyz(c) - ref).max())
        lifted = float(ref[:, 2].max() - start[:, 2].max())
        print(f"MeshGeometryStamped vs files: {err:.2e} m after 96 steps; the box lifted the cloth "
              f"{lifted * 1e3:.1f} mm")
        assert lifted > 0.05, lifted
        assert err < 1e-5, err
        # bad meshes: refused, counted by kind, the node runs on
        body.write(mesh(20, frames[9] + [(0.0, 0.0, 1.0)]))  # the box's faces, 9 vertices
        nan = [list(p) for p in frames[9]]
        nan[1][1] = math.nan
        body.write(mesh(21, nan))
        body.write(mesh(5, frames[9]))  # before the last frame
        body.write(mesh(22, frames[9], faces=faces[:-1] + [MeshTriangleIndices([0, 1, 8])]))
        body.write(MeshGeometryStamped(header=hdr(23), uuid="box"))  # empty
        want = {"body_refused_vertex_count": "1", "body_refused_non_finite": "1",
                "body_refused_out_of_order": "1", "body_refused_triangles": "1",
                "body_refused_empty": "1"}
        d = n.wait("/diagnostics", DiagnosticArray,
                   lambda d: all(n.diag(d).get(k) == v for k, v in want.items()))
        assert n.diag(d)["body_messages"] == "10" and int(n.diag(d)["rejected_messages"]) == 5
        # the box as it was: a frame with its faces is still taken
        body.write(mesh(24, frames[9]))
        n.wait("/diagnostics", DiagnosticArray, lambda d: n.diag(d).get("body_messages") == "11")
        r = n.call("/garment_sim/step", Step_Request, Step_Response, Step_Request(steps=2))
        assert r.success, r
    finally:
        code, out = n.stop()
    assert code == 0, out
    for why in ["mesh_geometry.vertices[1].y is NaN", "9 vertices, the body's topology has 8",
                "mesh_geometry.faces[11].vertex_indices[2] is vertex 8", "a topology with no vertices"]:
        assert why in out, (why, out)
