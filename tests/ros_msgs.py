"""Byte-for-byte check of the Rust ROS 2 message types against the independent
`rosbags` type system and CDR codec (ROS 2 Jazzy definitions, plus the
garment_sim_msgs package in msg/ and mesh_msgs/MeshGeometryStamped).

Run by tests/ros_msgs.rs, which writes for every sample message NAME.cdr (what
Rust serialised, with the 4-byte encapsulation header), NAME.json (the same
message as serde JSON) and NAME.type (the ROS type name) into a directory given
in the environment variable GARMENT_SIM_MSG_SAMPLES."""

import json
import os
import pathlib

import numpy as np
import pytest

typesys = pytest.importorskip("rosbags.typesys")
from rosbags.typesys.msg import get_types_from_msg  # noqa: E402

PKG = pathlib.Path(__file__).resolve().parents[1] / "msg" / "garment_sim_msgs"
DTYPES = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8, "uint8": np.uint8, "int8": np.int8,
    "uint16": np.uint16, "int16": np.int16, "uint32": np.uint32, "int32": np.int32,
    "uint64": np.uint64, "int64": np.int64, "float32": np.float32, "float64": np.float64,
}


def store():
    ts = typesys.get_typestore(typesys.Stores.ROS2_JAZZY)
    types = {}
    for f in sorted((PKG / "msg").glob("*.msg")):
        types.update(get_types_from_msg(f.read_text(), f"garment_sim_msgs/msg/{f.stem}"))
    for f in sorted((PKG / "srv").glob("*.srv")):
        req, res = f.read_text().split("\n---\n")
        types.update(get_types_from_msg(req, f"garment_sim_msgs/msg/{f.stem}_Request"))
        types.update(get_types_from_msg(res, f"garment_sim_msgs/msg/{f.stem}_Response"))
    # std_srvs is not in rosbags' store: its two services, as in ros2/common_interfaces.
    types.update(get_types_from_msg("", "std_srvs/msg/Trigger_Request"))
    types.update(get_types_from_msg("bool success\nstring message", "std_srvs/msg/Trigger_Response"))
    types.update(get_types_from_msg("bool data", "std_srvs/msg/SetBool_Request"))
    types.update(get_types_from_msg("bool success\nstring message", "std_srvs/msg/SetBool_Response"))
    # mesh_msgs (naturerobots/mesh_tools) is not in rosbags' store either: the three types
    # of MeshGeometryStamped, as in its mesh_msgs/msg/.
    types.update(get_types_from_msg("uint32[3] vertex_indices", "mesh_msgs/msg/MeshTriangleIndices"))
    types.update(get_types_from_msg(
        "geometry_msgs/Point[] vertices\ngeometry_msgs/Point[] vertex_normals\n"
        "mesh_msgs/MeshTriangleIndices[] faces", "mesh_msgs/msg/MeshGeometry"))
    types.update(get_types_from_msg(
        "std_msgs/Header header\nstring uuid\nmesh_msgs/MeshGeometry mesh_geometry",
        "mesh_msgs/msg/MeshGeometryStamped"))
    ts.register(types)
    return ts


def conv(ts, nt, det, v):
    kind = int(nt)
    if kind == 1:  # BASE
        t = det[0]
        if t == "string":
            assert isinstance(v, str)
            return v
        if t == "bool":
            return bool(v)
        if t.startswith("float"):
            return float(v)
        return int(v)
    if kind == 2:  # NAME
        return build(ts, det, v)
    (nt2, det2), _n = det
    if int(nt2) == 1 and det2[0] != "string":
        return np.array(v, dtype=DTYPES[det2[0]])
    return [conv(ts, nt2, det2, x) for x in v]


def build(ts, name, val):
    name = name.replace("/srv/", "/msg/")  # rosbags files service halves under msg/
    fields = ts.get_msgdef(name).fields
    assert sorted(f[0] for f in fields) == sorted(val.keys()), (name, [f[0] for f in fields], list(val))
    return ts.types[name](**{f: conv(ts, nt, det, val[f]) for f, (nt, det) in fields})


def samples():
    d = os.environ.get("GARMENT_SIM_MSG_SAMPLES")
    if not d:
        pytest.skip("run through `cargo test --release --test ros_msgs`")
    d = pathlib.Path(d)
    return [(p.stem, (d / f"{p.stem}.type").read_text().strip(), p.read_bytes(),
             json.loads((d / f"{p.stem}.json").read_text())) for p in sorted(d.glob("*.cdr"))]


def test_rust_bytes_equal_rosbags_bytes():
    ts = store()
    s = samples()
    assert len(s) >= 15
    for stem, typename, raw, val in s:
        msg = build(ts, typename, val)
        typename = typename.replace("/srv/", "/msg/")
        ours = bytes(ts.serialize_cdr(msg, typename))
        assert ours == raw, f"{stem} ({typename}): rosbags {ours[:64].hex()} vs rust {raw[:64].hex()}"
        back = ts.deserialize_cdr(raw, typename)
        assert bytes(ts.serialize_cdr(back, typename)) == raw
    print(f"{len(s)} messages byte-identical")


def test_point_cloud_decodes():
    ts = store()
    for stem, typename, raw, val in samples():
        if typename != "sensor_msgs/msg/PointCloud2":
            continue
        c = ts.deserialize_cdr(raw, typename)
        names = [f.name for f in c.fields]
        assert names[:3] == ["x", "y", "z"]
        pts = np.frombuffer(bytes(c.data), dtype=np.float32).reshape(c.width, c.point_step // 4)
        assert pts.shape[0] == c.width > 0
        assert np.isfinite(pts).all()
        assert c.header.frame_id == val["header"]["frame_id"]
        return
    raise AssertionError("no PointCloud2 sample")
