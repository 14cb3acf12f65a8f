"""The garment_sim node against ROS 2's default middleware: rclpy on eProsima
Fast DDS (rmw_fastrtps_cpp), ROS 2 Jazzy as pip-packaged on PyPI, with the
message classes rosidl generated (garment_sim_msgs included, built from
msg/garment_sim_msgs) in the venv that tests/ros2_venv.sh makes.

Run by tests/ros_fastdds.rs with that venv's Python inside a network
namespace it makes (loopback only). The node binary is in GARMENT_SIM_BIN."""

import json
import math
import os
import subprocess
import time

import numpy as np
import pytest
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from garment_sim_msgs.msg import Obstacle, Pin
from garment_sim_msgs.srv import Step
from geometry_msgs.msg import Point, Pose, WrenchStamped
from rcl_interfaces.msg import Log, Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import GetParameters, ListParameters, SetParameters
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import get_rmw_implementation_identifier
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2, PointField
from shape_msgs.msg import Mesh, MeshTriangle, SolidPrimitive
from std_msgs.msg import Header, String
from std_srvs.srv import SetBool, Trigger
from visualization_msgs.msg import Marker, MarkerArray

BIN = os.environ.get("GARMENT_SIM_BIN")
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)



def documented_parameters():
    """The parameter table of docs/ros.md: name -> (type, default as written)."""
    text = open("docs/ros.md").read()
    table = text.split("<!-- parameters:begin -->")[1].split("<!-- parameters:end -->")[0]
    rows = [[c.strip() for c in line.strip().strip("|").split("|")] for line in table.strip().splitlines()[2:]]
    return {r[0].strip("`"): (r[1], r[2].strip("`")) for r in rows}


PARAMETERS = documented_parameters()
TOPICS = {
    "/cloth/points": "sensor_msgs/msg/PointCloud2",
    "/cloth/mesh": "visualization_msgs/msg/Marker",
    "/obstacles/markers": "visualization_msgs/msg/MarkerArray",
    "/body/wrench": "geometry_msgs/msg/WrenchStamped",
    "/body/points": "sensor_msgs/msg/PointCloud2",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
    "/clock": "rosgraph_msgs/msg/Clock",
    "/scene_description": "std_msgs/msg/String",
    "/rosout": "rcl_interfaces/msg/Log",
    "/obstacles": "garment_sim_msgs/msg/Obstacle",
    "/pins": "garment_sim_msgs/msg/Pin",
    "/body": "garment_sim_msgs/msg/Body",
    "/body_mesh": "mesh_msgs/msg/MeshGeometryStamped",
}
SERVICES = {
    "/garment_sim/reset": "std_srvs/srv/Trigger",
    "/garment_sim/set_paused": "std_srvs/srv/SetBool",
    "/garment_sim/step": "garment_sim_msgs/srv/Step",
    "/garment_sim/list_parameters": "rcl_interfaces/srv/ListParameters",
    "/garment_sim/get_parameters": "rcl_interfaces/srv/GetParameters",
    "/garment_sim/set_parameters": "rcl_interfaces/srv/SetParameters",
    "/garment_sim/describe_parameters": "rcl_interfaces/srv/DescribeParameters",
}
DT = 0.001  # config/scenes/table_drape.yaml
TABLE_Z = 0.75  # the board's centre: a 30 x 20 x 0.5 cm box
BOARD_NORMAL = (0.078, -0.025, 0.996)


@pytest.fixture(scope="module")
def ros():
    assert BIN, "run through `cargo test --release --test ros_fastdds`"
    assert get_rmw_implementation_identifier() == "rmw_fastrtps_cpp", get_rmw_implementation_identifier()
    rclpy.init()
    node = rclpy.create_node("fastdds_probe")
    yield node
    node.destroy_node()
    rclpy.shutdown()


class Sim:
    """A garment_sim node process, seen from an rclpy node on Fast DDS."""

    def __init__(self, ros, *ros_args):
        self.ros = ros
        self.proc = subprocess.Popen([BIN, "node", "--ros-args", *ros_args],
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.got = {}
        self.subs = []
        self.clients = {}

    def alive(self):
        assert self.proc.poll() is None, "node exited:\n" + self.proc.stdout.read()

    def spin(self, seconds):
        end = time.time() + seconds
        while time.time() < end:
            self.alive()
            rclpy.spin_once(self.ros, timeout_sec=0.01)

    def until(self, what, cond, timeout=15.0):
        end = time.time() + timeout
        while time.time() < end:
            v = cond()
            if v:
                return v
            self.spin(0.02)
        raise AssertionError(f"{what}: not within {timeout} s")

    def subscribe(self, topic, typ, qos=RELIABLE):
        if topic not in self.got:
            self.got[topic] = []
            self.subs.append(self.ros.create_subscription(typ, topic, self.got[topic].append, qos))
        return self.got[topic]

    def wait(self, topic, typ, pred=lambda m: True, timeout=15.0, since_now=True):
        """The first message on `topic` from now on (or since subscribing) that satisfies `pred`."""
        box = self.subscribe(topic, typ, LATCHED if topic == "/scene_description" else RELIABLE)
        seen = len(box) if since_now else 0

        def fresh():
            nonlocal seen
            for m in box[seen:]:
                seen += 1
                if pred(m):
                    return m

        return self.until(f"a message on {topic}", fresh, timeout)

    def call(self, typ, name, request, timeout=15.0):
        """One request, sent once the service is discovered and the node has
        had time to discover the new client in turn: a reply the node sends
        before it has matched the client's reply reader never arrives (seen
        with list_parameters called at once: no reply)."""
        if name not in self.clients:
            c = self.ros.create_client(typ, name)
            self.clients[name] = c
            self.until(f"service {name}", c.service_is_ready, timeout)
            self.spin(0.5)
        future = self.clients[name].call_async(request)
        self.until(f"reply of {name}", future.done, timeout)
        return future.result()

    def stop(self):
        for s in self.subs:
            self.ros.destroy_subscription(s)
        for c in self.clients.values():
            self.ros.destroy_client(c)
        self.proc.terminate()
        try:
            out, _ = self.proc.communicate(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            out, _ = self.proc.communicate()
        return self.proc.returncode, out


def secs(t: Time):
    return t.sec + 1e-9 * t.nanosec


def decode_cloud(c: PointCloud2):
    """A structured array of the cloud's points, laid out from its PointFields alone."""
    kinds = {PointField.INT8: "i1", PointField.UINT8: "u1", PointField.INT16: "i2", PointField.UINT16: "u2",
             PointField.INT32: "i4", PointField.UINT32: "u4", PointField.FLOAT32: "f4", PointField.FLOAT64: "f8"}
    order = ">" if c.is_bigendian else "<"
    dtype = np.dtype({"names": [f.name for f in c.fields],
                      "formats": [(order + kinds[f.datatype], (f.count,)) if f.count > 1 else order + kinds[f.datatype]
                                  for f in c.fields],
                      "offsets": [f.offset for f in c.fields], "itemsize": c.point_step})
    assert len(c.data) == c.row_step * c.height
    rows = np.frombuffer(bytes(c.data), dtype=np.uint8).reshape(c.height, c.row_step)
    return np.frombuffer(rows[:, : c.width * c.point_step].tobytes(), dtype=dtype)


def xyz(c):
    p = decode_cloud(c)
    return np.stack([p["x"], p["y"], p["z"]], axis=1).astype(float)


def test_graph_topics_and_contents(ros):
    n = Sim(ros, "-p", "spacing:=0.05")
    try:
        t0 = time.time()
        n.until("node garment_sim in the graph", lambda: ("garment_sim", "/") in ros.get_node_names_and_namespaces())
        print(f"Fast DDS discovered the node in {time.time() - t0:.2f} s")

        def complete():
            topics = dict(ros.get_topic_names_and_types())
            services = dict(ros.get_service_names_and_types())
            return all(t in topics for t in TOPICS) and all(s in services for s in SERVICES) and (topics, services)

        topics, services = n.until("every topic and service of the node", complete)
        for name, typ in TOPICS.items():
            assert typ in topics[name], (name, topics[name])
        for name, typ in SERVICES.items():
            assert services[name] == [typ], (name, services[name])
        # who publishes and subscribes what, by node
        pubs = {t: [i.topic_type for i in ros.get_publishers_info_by_topic(t) if i.node_name == "garment_sim"]
                for t in TOPICS}
        subs = {t: [i.topic_type for i in ros.get_subscriptions_info_by_topic(t) if i.node_name == "garment_sim"]
                for t in TOPICS}
        for t in ["/cloth/points", "/cloth/mesh", "/obstacles/markers", "/diagnostics", "/clock",
                  "/scene_description", "/rosout", "/body/wrench", "/body/points"]:
            assert pubs[t] == [TOPICS[t]], (t, pubs[t])
        for t in ["/obstacles", "/pins", "/body", "/body_mesh"]:
            assert subs[t] == [TOPICS[t]], (t, subs[t])

        # the cloud: fields, layout, values
        c = n.wait("/cloth/points", PointCloud2, lambda c: secs(c.header.stamp) > 0.5)
        assert c.header.frame_id == "world"
        assert [(f.name, f.datatype, f.count) for f in c.fields] == [
            (k, PointField.FLOAT32, 1) for k in ["x", "y", "z", "strain", "speed"]]
        assert (c.height, c.width) == (1, 121) and c.row_step == c.width * c.point_step and not c.is_bigendian
        pts = decode_cloud(c)
        for k in ["x", "y", "z", "strain", "speed"]:
            assert np.isfinite(pts[k]).all(), k
        p = xyz(c)
        grid = p.reshape(11, 11, 3)  # vertex j * nx + i
        along_i = np.linalg.norm(np.diff(grid, axis=1), axis=2).sum(axis=1)  # each row's length
        along_j = np.linalg.norm(np.diff(grid, axis=0), axis=2).sum(axis=0)
        print(f"cloth rows {along_i.min():.4f}-{along_i.max():.4f} m, "
              f"columns {along_j.min():.4f}-{along_j.max():.4f} m long; z {p[:, 2].min():.3f}-{p[:, 2].max():.3f} m; |strain| ≤ {np.abs(pts['strain']).max():.2e}; "
              f"speed ≤ {pts['speed'].max():.3f} m/s")
        assert np.allclose(along_i, 0.5, rtol=0.03) and np.allclose(along_j, 0.5, rtol=0.03)
        # lying on the board: the vertices on top of it (not the flaps swinging under the floating
        # board) are a contact distance above its top face
        normal = np.array(BOARD_NORMAL) / np.linalg.norm(BOARD_NORMAL)
        over = (np.abs(p[:, 0]) < 0.12) & (np.abs(p[:, 1]) < 0.08) & (p[:, 2] > TABLE_Z - 0.02)
        above = (p[over] - [0.0, 0.0, TABLE_Z]) @ normal - 0.0025
        print(f"{over.sum()} vertices over the board, {1e3 * above.min():.2f}-{1e3 * above.max():.2f} mm above it")
        assert over.sum() >= 9 and (above > 0.0).all() and (above < 0.012).all(), above
        assert p[:, 2].max() < TABLE_Z + 0.04 and p[:, 2].min() > TABLE_Z - 0.5  # the rest hangs from it
        assert np.abs(pts["strain"]).max() < 0.1 and (pts["speed"] >= 0).all() and pts["speed"].max() < 5.0
        # the mesh: a triangle list over the same vertices, published with the cloud
        m = n.wait("/cloth/mesh", Marker, lambda m: secs(m.header.stamp) > 0.5)
        assert m.type == Marker.TRIANGLE_LIST and len(m.points) == 3 * 2 * 100 and len(m.colors) == len(m.points)
        c = n.wait("/cloth/points", PointCloud2, lambda c: c.header.stamp == m.header.stamp, since_now=False)
        mp = np.array([[q.x, q.y, q.z] for q in m.points])
        gap = np.linalg.norm(mp[:, None, :] - xyz(c)[None, :, :], axis=2).min(axis=1).max()
        assert gap < 1e-6, gap
        # the simulated clock advances
        k = [secs(n.wait("/clock", Clock).clock) for _ in range(5)]
        assert all(b > a for a, b in zip(k, k[1:])), k
        d = n.wait("/diagnostics", DiagnosticArray)
        assert float({kv.key: kv.value for kv in d.status[0].values}["step_time_ms"]) > 0
        desc = n.wait("/scene_description", String)  # latched: arrives though published at start
        assert "scene_yaml:" in desc.data and "fabric_yaml:" in desc.data
        n.wait("/rosout", Log, lambda l: l.name.endswith("garment_sim"))
    finally:
        code, out = n.stop()
    assert code == 0, out


def test_pause_step_reset(ros):
    n = Sim(ros, "-p", "spacing:=0.05")
    try:
        n.wait("/clock", Clock, lambda k: secs(k.clock) > 0.2)
        r = n.call(SetBool, "/garment_sim/set_paused", SetBool.Request(data=True))
        assert r.success, r.message
        n.spin(0.3)  # what was on its way
        clocks = n.subscribe("/clock", Clock)
        clouds = n.subscribe("/cloth/points", PointCloud2)
        k0, c0 = len(clocks), len(clouds)
        n.spin(1.0)
        t0 = secs(clouds[-1].header.stamp)
        # still published, at the same time: the clock stands still
        assert len(clocks) > k0 and all(secs(k.clock) == t0 for k in clocks[k0:]), [secs(k.clock) for k in clocks]
        assert len(clouds) > c0 and all(secs(c.header.stamp) == t0 for c in clouds[c0:])
        r = n.call(Step, "/garment_sim/step", Step.Request(steps=10))
        assert r.success, r.message
        assert abs(secs(r.sim_time) - (t0 + 10 * DT)) < 1e-6, (t0, secs(r.sim_time))
        n.wait("/clock", Clock, lambda k: k.clock == r.sim_time, since_now=False)
        r = n.call(Trigger, "/garment_sim/reset", Trigger.Request())
        assert r.success, r.message
        c = n.wait("/cloth/points", PointCloud2, lambda c: secs(c.header.stamp) < 0.05)
        assert secs(c.header.stamp) == 0.0 and c.width == 121  # still paused: the scene's initial state
        r = n.call(SetBool, "/garment_sim/set_paused", SetBool.Request(data=False))
        assert r.success, r.message
        k = n.wait("/clock", Clock)
        assert 0.0 < secs(k.clock) < 0.5, secs(k.clock)  # running again from the start
    finally:
        code, out = n.stop()
    assert code == 0, out


# docs/ros.md's type names: the ParameterType and how a default is written
TYPES = {"bool": (ParameterType.PARAMETER_BOOL, lambda t: {"true": True, "false": False}[t]),
         "integer": (ParameterType.PARAMETER_INTEGER, int),
         "double": (ParameterType.PARAMETER_DOUBLE, float),
         "string": (ParameterType.PARAMETER_STRING, lambda t: "" if t == '""' else t)}


def value(v: ParameterValue):
    """The value a ParameterValue holds by its type (None: not set or an array)."""
    return {ParameterType.PARAMETER_BOOL: lambda: v.bool_value,
            ParameterType.PARAMETER_INTEGER: lambda: v.integer_value,
            ParameterType.PARAMETER_DOUBLE: lambda: v.double_value,
            ParameterType.PARAMETER_STRING: lambda: v.string_value}.get(v.type, lambda: None)()


def test_parameter_services(ros):
    n = Sim(ros, "-p", "spacing:=0.05", "-p", "frame_id:=lab", "-p", "publish_rate:=20.0",
            "-p", "self_collision:=true")
    try:
        n.wait("/cloth/points", PointCloud2)
        r = n.call(ListParameters, "/garment_sim/list_parameters", ListParameters.Request())
        names = list(r.result.names)
        print(f"list_parameters: {names}")
        assert len(PARAMETERS) >= 10, PARAMETERS  # the table was read
        # every documented parameter, and only those (with ros2-client's use_sim_time)
        assert set(names) - {"use_sim_time"} == set(PARAMETERS), set(names) ^ set(PARAMETERS)
        r = n.call(GetParameters, "/garment_sim/get_parameters", GetParameters.Request(names=list(PARAMETERS)))
        got = dict(zip(PARAMETERS, r.values))
        given = {"spacing": 0.05, "frame_id": "lab", "publish_rate": 20.0, "self_collision": "true"}
        for k, (typ, default) in PARAMETERS.items():
            v = got[k]
            assert v.type == TYPES[typ][0], (k, typ, v)
            want = given[k] if k in given else TYPES[typ][1](default)
            if k == "scene":  # the default is found from the working directory
                assert value(v).endswith(want), (k, value(v))
            else:
                assert value(v) == want, (k, value(v), want)
        print(f"get_parameters: every documented parameter, type and default ({len(PARAMETERS)})")

        def gaps(count):
            box = n.subscribe("/cloth/points", PointCloud2)
            start = len(box)
            n.until(f"{count} clouds", lambda: len(box) >= start + count)
            s = [secs(c.header.stamp) for c in box[start:start + count]]
            return np.diff(s)

        g20 = gaps(6)
        r = n.call(SetParameters, "/garment_sim/set_parameters", SetParameters.Request(parameters=[
            Parameter(name="publish_rate", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=5.0)),
            Parameter(name="real_time_factor", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                                                    double_value=-1.0)),
        ]))
        assert r.results[0].successful, r.results[0].reason
        assert not r.results[1].successful and "real_time_factor" in r.results[1].reason
        n.spin(0.5)
        g5 = gaps(5)
        print(f"cloud every {g20.mean():.4f} s of simulated time at 20 Hz, every {g5.mean():.4f} s after setting 5 Hz")
        assert np.allclose(g20, 1 / 20, atol=DT + 1e-9) and np.allclose(g5, 1 / 5, atol=DT + 1e-9), (g20, g5)
        r = n.call(GetParameters, "/garment_sim/get_parameters",
                   GetParameters.Request(names=["publish_rate", "real_time_factor"]))
        assert [value(v) for v in r.values] == [5.0, 1.0]

        # self-collision: on from -p (the table drape's file leaves it off), its counts in the
        # diagnostics; set off through the parameter service (a string, its declared type), it
        # takes effect at ~/reset
        def keys(d):
            return {kv.key for kv in d.status[0].values}

        d = n.wait("/diagnostics", DiagnosticArray)
        assert "self_contacts" in keys(d), keys(d)
        r = n.call(SetParameters, "/garment_sim/set_parameters", SetParameters.Request(parameters=[
            Parameter(name="self_collision", value=ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                                  string_value="false"))]))
        assert r.results[0].successful, r.results[0].reason
        r = n.call(SetParameters, "/garment_sim/set_parameters", SetParameters.Request(parameters=[
            Parameter(name="self_collision", value=ParameterValue(type=ParameterType.PARAMETER_STRING,
                                                                  string_value="sometimes"))]))
        assert not r.results[0].successful and "self_collision" in r.results[0].reason
        r = n.call(Trigger, "/garment_sim/reset", Trigger.Request())
        assert r.success, r.message
        d = n.wait("/diagnostics", DiagnosticArray, lambda d: "self_contacts" not in keys(d))
        print(f"self_collision: on from -p (diagnostics carry self_contacts), off after set_parameters and ~/reset")
    finally:
        code, out = n.stop()
    assert code == 0, out


def test_obstacles_and_pins(ros):
    n = Sim(ros, "-p", "spacing:=0.05", "-p", "real_time_factor:=0.0", "-p", "publish_rate:=50.0")
    try:
        n.wait("/cloth/points", PointCloud2)
        obstacles = ros.create_publisher(Obstacle, "/obstacles", RELIABLE)
        pins = ros.create_publisher(Pin, "/pins", RELIABLE)
        try:
            n.until("the node's subscriptions matched",
                    lambda: obstacles.get_subscription_count() > 0 and pins.get_subscription_count() > 0)
            world = Header(frame_id="world")
            ball = Obstacle(header=world, id="ball", operation=Obstacle.ADD,
                            pose=Pose(position=Point(x=0.3, y=0.0, z=1.2)),
                            primitives=[SolidPrimitive(type=SolidPrimitive.SPHERE, dimensions=[0.05])],
                            primitive_poses=[Pose()], thickness=math.nan, friction=math.nan)
            obstacles.publish(ball)
            a = n.wait("/obstacles/markers", MarkerArray, lambda a: any(m.text == "ball" for m in a.markers))
            m = [m for m in a.markers if m.text == "ball"][0]
            assert np.allclose([m.pose.position.x, m.pose.position.y, m.pose.position.z], [0.3, 0.0, 1.2], atol=1e-12)
            ball.operation, ball.pose.position.z = Obstacle.MOVE, 1.4
            obstacles.publish(ball)
            n.wait("/obstacles/markers", MarkerArray,
                   lambda a: any(m.text == "ball" and abs(m.pose.position.z - 1.4) < 1e-12 for m in a.markers))
            obstacles.publish(Obstacle(header=world, id="ball", operation=Obstacle.REMOVE))
            n.wait("/obstacles/markers", MarkerArray, lambda a: not any(m.text == "ball" for m in a.markers))
            # corner (i, j) = (10, 0), vertex 10, held above the table; then released
            pins.publish(Pin(header=world, operation=Pin.PIN, grid_i=[10], grid_j=[0],
                             targets=[Point(x=0.3, y=-0.3, z=1.1)]))
            c = n.wait("/cloth/points", PointCloud2, lambda c: np.abs(xyz(c)[10] - [0.3, -0.3, 1.1]).max() < 1e-5)
            # the cloth hangs from that corner: its neighbour (9, 0) is carried up to it
            c = n.wait("/cloth/points", PointCloud2,
                       lambda c: np.abs(xyz(c)[10] - [0.3, -0.3, 1.1]).max() < 1e-5 and xyz(c)[9, 2] > 1.05)
            assert np.linalg.norm(xyz(c)[9] - xyz(c)[10]) < 0.06
            d = n.wait("/diagnostics", DiagnosticArray)
            assert {kv.key: kv.value for kv in d.status[0].values}["rejected_messages"] == "0"
            # a runtime parameter set through the parameter service: a 2-triangle mesh is now too
            # large (sent while the cloth hangs within reach of the plate)
            r = n.call(SetParameters, "/garment_sim/set_parameters", SetParameters.Request(parameters=[
                Parameter(name="max_mesh_triangles",
                          value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=1))]))
            assert r.results[0].successful, r.results[0].reason
            n.spin(0.2)
            square = Mesh(triangles=[MeshTriangle(vertex_indices=[0, 1, 2]), MeshTriangle(vertex_indices=[0, 2, 3])],
                          vertices=[Point(x=0.0, y=0.0, z=1.3), Point(x=0.1, y=0.0, z=1.3), Point(x=0.1, y=0.1, z=1.3),
                                    Point(x=0.0, y=0.1, z=1.3)])
            obstacles.publish(Obstacle(header=world, id="plate", operation=Obstacle.ADD, meshes=[square],
                                       mesh_poses=[Pose()], thickness=math.nan, friction=math.nan))
            d = n.wait("/diagnostics", DiagnosticArray,
                       lambda d: {kv.key: kv.value for kv in d.status[0].values}["rejected_messages"] == "1")
            assert "max_mesh_triangles" in d.status[0].message, d.status[0].message
            pins.publish(Pin(header=world, operation=Pin.RELEASE_ALL))
            n.wait("/cloth/points", PointCloud2, lambda c: xyz(c)[10, 2] < 1.0)  # falls once let go
        finally:
            ros.destroy_publisher(obstacles)
            ros.destroy_publisher(pins)
    finally:
        code, out = n.stop()
    assert code == 0, out


def test_a_garment_trial_scene(ros):
    """The shipped skirt trial as the node's scene: the cloud carries the fit fields, a pin
    names a panel's grid node, a pin naming a panel the garment lacks is refused."""
    trial = os.path.join(ROOT, "config/trials/skirt_on_anny.yaml")
    n = Sim(ros, "-p", f"scene:={trial}", "-p", "spacing:=0.04", "-p", "real_time_factor:=0.0",
            "-p", "publish_rate:=50.0")
    try:
        c = n.wait("/cloth/points", PointCloud2, timeout=60.0)
        p = decode_cloud(c)
        fit = ["strain_warp", "strain_weft", "strain_bias", "pressure", "distance"]
        assert [f.name for f in c.fields] == ["x", "y", "z", "strain", "speed"] + fit
        for f in fit:
            assert np.isfinite(p[f]).all(), f
        assert (p["pressure"] >= 0).all() and p["distance"].min() > -0.001
        c = n.wait("/cloth/points", PointCloud2, lambda c: (decode_cloud(c)["pressure"] > 0).any())
        pins = ros.create_publisher(Pin, "/pins", RELIABLE)
        try:
            n.until("the node's subscription matched", lambda: pins.get_subscription_count() > 0)
            world = Header(frame_id="world")
            # node (7, 5) of the front panel's 4 cm grid lies inside its outline
            # (src/ros/node.rs a_garment_pin_names_its_panel_and_grid_node)
            target = [0.0, -0.4, 0.8]
            pins.publish(Pin(header=world, operation=Pin.PIN, panel="skirt_front", grid_i=[7], grid_j=[5],
                             targets=[Point(x=target[0], y=target[1], z=target[2])]))
            n.wait("/cloth/points", PointCloud2,
                   lambda c: (np.abs(xyz(c) - target).max(axis=1) < 1e-5).sum() == 1, timeout=30.0)
            pins.publish(Pin(header=world, operation=Pin.PIN, panel="sleeve", grid_i=[0], grid_j=[0]))
            d = n.wait("/diagnostics", DiagnosticArray,
                       lambda d: {kv.key: kv.value for kv in d.status[0].values}["rejected_messages"] == "1")
            assert "no panel" in d.status[0].message, d.status[0].message
        finally:
            ros.destroy_publisher(pins)
    finally:
        code, out = n.stop()
    assert code == 0, out


def obj_vertices(path):
    with open(path) as f:
        return np.array([[float(x) for x in line.split()[1:4]] for line in f if line.startswith("v ")])


def test_body_wrench_reports_the_garments_weight(ros, tmp_path):
    """The skirt trial as the scene, the body still: once the skirt has settled, body/wrench
    reports its weight, straight down, in the node's frame; body/points carries the body's
    vertices (those of the shipped body.obj, read here) with the pressure on them."""
    trial = os.path.join(ROOT, "config/trials/skirt_on_anny.yaml")
    # the skirt's weight at the node's spacing: Σ vertex masses × g of the trial command's
    # fit.json (sewn, no drape), not a contact force
    out = tmp_path / "trial"
    subprocess.run([BIN, "trial", trial, "--spacing", "0.04", "--max-time", "0", "--out", str(out)],
                   check=True, capture_output=True)
    weight = json.load(open(out / "fit.json"))["weight_n"]
    assert 1.0 < weight < 2.0, weight
    n = Sim(ros, "-p", f"scene:={trial}", "-p", "spacing:=0.04", "-p", "real_time_factor:=0.0",
            "-p", "publish_rate:=20.0")
    try:
        box = n.subscribe("/body/wrench", WrenchStamped)

        def weight_held():
            """The latest wrenches, if the last ten in a row (0.5 s simulated) are within 2 %
            of the weight, downward."""
            ok = []
            for w in box:
                f = w.wrench.force
                good = abs(-f.z - weight) < 0.02 * weight and math.hypot(f.x, f.y) < 0.02 * weight
                ok = ok + [w] if good else []
            return len(ok) >= 10 and ok

        run = n.until("body/wrench reporting the skirt's weight", weight_held, timeout=120.0)
        last = run[-1]
        assert last.header.frame_id == "world"
        stamps = [secs(w.header.stamp) for w in run]
        assert all(b > a for a, b in zip(stamps, stamps[1:])), stamps
        print(f"body/wrench at t = {stamps[-1]:.2f} s: force ({last.wrench.force.x:.4f}, "
              f"{last.wrench.force.y:.4f}, {last.wrench.force.z:.4f}) N, weight {weight:.4f} N")
        c = n.wait("/body/points", PointCloud2, lambda c: secs(c.header.stamp) >= stamps[-1])
        assert [f.name for f in c.fields] == ["x", "y", "z", "pressure"]
        p = decode_cloud(c)
        body = obj_vertices(os.path.join(ROOT, "assets/bodies/anny/body.obj"))
        assert len(p) == len(body)
        assert np.abs(xyz(c) - body).max() < 1e-6
        assert np.isfinite(p["pressure"]).all() and (p["pressure"] >= 0).all()
        loaded = body[p["pressure"] > 0]
        assert len(loaded) > 0
        # the skirt hangs from the hips
        assert np.median(loaded[:, 2]) > 0.775 and np.median(loaded[:, 2]) < 1.09, np.median(loaded[:, 2])
    finally:
        code, out = n.stop()
    assert code == 0, out
