"""The interface definitions in msg/ are valid ROS 2 and resolve against the standard
Jazzy types, checked with the independent `rosbags` type system; each message
round-trips through rosbags' CDR codec."""

import pathlib

import pytest

typesys = pytest.importorskip("rosbags.typesys")

PKG = pathlib.Path(__file__).resolve().parents[1] / "msg" / "garment_sim_msgs"


def store():
    ts = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    types = {}
    for f in sorted((PKG / "msg").glob("*.msg")):
        types.update(typesys.get_types_from_msg(f.read_text(), f"garment_sim_msgs/msg/{f.stem}"))
    for f in sorted((PKG / "srv").glob("*.srv")):
        req, res = f.read_text().split("\n---\n")
        types.update(typesys.get_types_from_msg(req, f"garment_sim_msgs/msg/{f.stem}_Request"))
        types.update(typesys.get_types_from_msg(res, f"garment_sim_msgs/msg/{f.stem}_Response"))
    ts.register(types)
    return ts


def test_definitions_parse_and_resolve():
    ts = store()
    for name in [
        "garment_sim_msgs/msg/Obstacle",
        "garment_sim_msgs/msg/Pin",
        "garment_sim_msgs/msg/Body",
        "garment_sim_msgs/msg/Step_Request",  # rosbags files services under msg/
        "garment_sim_msgs/msg/Step_Response",
    ]:
        assert name in ts.types, name
    fields = [f[0] for f in ts.get_msgdef("garment_sim_msgs/msg/Obstacle").fields]
    assert fields[:3] == ["header", "id", "pose"]


def test_cdr_round_trip():
    ts = store()
    Obstacle = ts.types["garment_sim_msgs/msg/Obstacle"]
    Header = ts.types["std_msgs/msg/Header"]
    Time = ts.types["builtin_interfaces/msg/Time"]
    Pose = ts.types["geometry_msgs/msg/Pose"]
    Point = ts.types["geometry_msgs/msg/Point"]
    Quat = ts.types["geometry_msgs/msg/Quaternion"]
    Vec3 = ts.types["geometry_msgs/msg/Vector3"]
    Twist = ts.types["geometry_msgs/msg/Twist"]
    Prim = ts.types["shape_msgs/msg/SolidPrimitive"]
    import numpy as np

    pose = Pose(position=Point(x=0.1, y=0.2, z=0.3), orientation=Quat(x=0.0, y=0.0, z=0.0, w=1.0))
    prim = Prim(type=1, dimensions=np.array([0.3, 0.2, 0.005]), polygon=ts.types["geometry_msgs/msg/Polygon"](points=[]))
    msg = Obstacle(
        header=Header(stamp=Time(sec=1, nanosec=5), frame_id="world"),
        id="board",
        pose=pose,
        primitives=[prim],
        primitive_poses=[pose],
        meshes=[],
        mesh_poses=[],
        velocity=Twist(linear=Vec3(x=0.0, y=0.0, z=0.5), angular=Vec3(x=0.0, y=0.0, z=0.0)),
        thickness=0.006,
        friction=0.3,
        operation=0,
    )
    raw = ts.serialize_cdr(msg, "garment_sim_msgs/msg/Obstacle")
    back = ts.deserialize_cdr(raw, "garment_sim_msgs/msg/Obstacle")
    assert back.id == "board" and back.thickness == 0.006 and back.velocity.linear.z == 0.5
    assert list(back.primitives[0].dimensions) == [0.3, 0.2, 0.005]
    Pin = ts.types["garment_sim_msgs/msg/Pin"]
    pin = Pin(
        header=Header(stamp=Time(sec=0, nanosec=0), frame_id="world"),
        operation=0,
        vertices=np.array([0, 10], dtype=np.uint32),
        grid_i=np.array([], dtype=np.uint32),
        grid_j=np.array([], dtype=np.uint32),
        panel="",
        targets=[Point(x=0.0, y=0.0, z=1.0), Point(x=0.5, y=0.0, z=1.0)],
        velocities=[],
    )
    back = ts.deserialize_cdr(ts.serialize_cdr(pin, "garment_sim_msgs/msg/Pin"), "garment_sim_msgs/msg/Pin")
    assert list(back.vertices) == [0, 10] and back.targets[1].x == 0.5
    Body = ts.types["garment_sim_msgs/msg/Body"]
    body = Body(
        header=Header(stamp=Time(sec=2, nanosec=0), frame_id="world"),
        id="avatar",
        triangles=np.array([0, 1, 2], dtype=np.uint32),
        positions=np.array([0.0, 0.0, 1.0, 0.1, 0.0, 1.0, 0.0, 0.1, 1.0], dtype=np.float32),
        thickness=float("nan"),
        friction=0.3,
    )
    back = ts.deserialize_cdr(ts.serialize_cdr(body, "garment_sim_msgs/msg/Body"), "garment_sim_msgs/msg/Body")
    assert list(back.triangles) == [0, 1, 2] and back.positions.dtype == np.float32
    assert back.positions[5] == np.float32(1.0) and back.friction == 0.3
