"""A trial's glTF scene (GLB_FILE, written by tests/glb.rs) as trimesh loads
it and as its accessors read with NumPy from the GLB's own bytes, against
what the test wrote it from (GLB_EXPECTED, JSON: the garment's first and
last frames, times, triangles and stretch, the body's mesh).

Run by tests/glb.rs: GLB_FILE=... GLB_EXPECTED=... python3 -m pytest tests/glb_trimesh.py
"""

import json
import os
import struct

import numpy as np
import trimesh

GLB = os.environ["GLB_FILE"]
with open(os.environ["GLB_EXPECTED"]) as f:
    EXP = json.load(f)

# the strain pictures' colour map: five stops of viridis (sRGB), 0 to full scale
VIRIDIS = np.array(
    [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]], float
)


def read_glb(path):
    """The JSON and the binary chunk of a GLB file (glTF 2.0 §4.4)."""
    data = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    jlen, jtype = struct.unpack_from("<I4s", data, 12)
    assert jtype == b"JSON"
    gltf = json.loads(data[20 : 20 + jlen])
    blen, btype = struct.unpack_from("<I4s", data, 20 + jlen)
    assert btype == b"BIN\0"
    return gltf, data[28 + jlen : 28 + jlen + blen]


GLTF, BIN = read_glb(GLB)
COMPONENTS = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}
DTYPES = {5126: "<f4", 5125: "<u4"}


def accessor(i):
    """Accessor i as an array (count × components), tightly packed views."""
    a = GLTF["accessors"][i]
    v = GLTF["bufferViews"][a["bufferView"]]
    assert "byteStride" not in v and "sparse" not in a
    n = COMPONENTS[a["type"]]
    start = v.get("byteOffset", 0) + a.get("byteOffset", 0)
    arr = np.frombuffer(BIN, DTYPES[a["componentType"]], a["count"] * n, start)
    return arr.reshape(a["count"], n)


def mesh(name):
    (m,) = [m for m in GLTF["meshes"] if m["name"] == name]
    (p,) = m["primitives"]
    return p


def test_trimesh_loads_the_garment_and_the_body():
    scene = trimesh.load(GLB, process=False)
    assert isinstance(scene, trimesh.Scene)
    g, b = scene.geometry["garment"], scene.geometry["body"]
    assert len(g.vertices) == EXP["garment_vertices"]
    assert np.array_equal(g.faces, EXP["garment_triangles"])
    assert np.array_equal(g.vertices, np.float32(EXP["first"]))
    assert len(b.vertices) == len(EXP["body_vertices"])
    assert np.array_equal(b.faces, EXP["body_triangles"])
    assert np.array_equal(b.vertices, np.float32(EXP["body_vertices"]))
    # the scene is Y-up: the data's z (up) is the world's y, its y the world's −z
    world, _ = scene.graph.get("garment")
    np.testing.assert_allclose(world[:3, :3], [[1, 0, 0], [0, 0, 1], [0, -1, 0]], atol=1e-7)
    # the same 3D coordinates are seen by default loading (no vertex merged)
    assert len(trimesh.load(GLB).geometry["garment"].vertices) == EXP["garment_vertices"]


def test_positions_and_morph_targets_are_the_frames():
    p = mesh("garment")
    base = accessor(p["attributes"]["POSITION"])
    first, last = np.float32(EXP["first"]), np.float32(EXP["last"])
    assert np.array_equal(base, first)
    targets = p["targets"]
    assert len(targets) == len(EXP["times"]) - 1
    moved = base + accessor(targets[-1]["POSITION"])
    np.testing.assert_allclose(moved, last, rtol=0, atol=4e-7)
    assert np.abs(last - first).max() > 0.05, "the cloth moves over the run"
    assert np.array_equal(accessor(mesh("body")["attributes"]["POSITION"]), np.float32(EXP["body_vertices"]))
    tri = accessor(p["indices"]).reshape(-1, 3)
    assert np.array_equal(tri, EXP["garment_triangles"])


def test_the_animation_weighs_frame_k_at_its_time():
    (anim,) = GLTF["animations"]
    (ch,) = anim["channels"]
    garment = [i for i, n in enumerate(GLTF["nodes"]) if n.get("name") == "garment"]
    assert ch["target"] == {"node": garment[0], "path": "weights"}
    s = anim["samplers"][ch["sampler"]]
    assert s.get("interpolation", "LINEAR") == "LINEAR"
    t = accessor(s["input"])[:, 0]
    assert np.array_equal(t, np.float32(EXP["times"]))
    n = len(t)
    w = accessor(s["output"]).reshape(n, n - 1)
    # key 0: no target (the base, frame 0); key k: target k − 1 (frame k) alone
    expected = np.vstack([np.zeros(n - 1), np.eye(n - 1)])
    assert np.array_equal(w, expected)


def test_colours_are_the_stretch_on_the_strain_map():
    lin = accessor(mesh("garment")["attributes"]["COLOR_0"])
    srgb = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * lin ** (1 / 2.4) - 0.055) * 255
    t = np.clip(np.array(EXP["stretch"]) / EXP["stretch_full"], 0, 1)
    stops = np.linspace(0, 1, len(VIRIDIS))
    want = np.stack([np.interp(t, stops, VIRIDIS[:, c]) for c in range(3)], axis=1)
    np.testing.assert_allclose(srgb, want, atol=0.6)
    assert t.max() > 0.5, "the colours span the scale"
