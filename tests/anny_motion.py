"""The shipped motion assets/bodies/anny/arms_raise.glb (tools/motion_from_anny.py):
its bind pose is body.obj, nothing moves at t = 0, and its linear blend skinning
(tools/motion_from_anny.py's reader, glTF 2.0: slerp between keys) gives the vertices
Blender's glTF importer and armature modifier gave at t = 0, 1.5 and 3 s
(tests/data/anny_motion_blender_frames.json, by tools/blender_eval_motion.py);
and the shipped turn assets/bodies/anny/turn.glb is body.obj turned about the
vertical axis by its ramp-and-hold angle. numpy only; run by tests/python_interop.rs."""

import json
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "tools"))
import motion_from_anny as m  # noqa: E402

GLB = os.path.join(ROOT, "assets/bodies/anny/arms_raise.glb")
OBJ = os.path.join(ROOT, "assets/bodies/anny/body.obj")
FRAMES = os.path.join(ROOT, "tests/data/anny_motion_blender_frames.json")


def load():
    with open(GLB, "rb") as f:
        return m.read_glb(f.read())


def body():
    with open(OBJ) as f:
        return np.array([[float(x) for x in line.split()[1:4]] for line in f if line.startswith("v ")])


def test_bind_pose_is_the_body_and_nothing_moves_at_the_start():
    doc, acc = load()
    prim = doc["meshes"][0]["primitives"][0]
    v = acc(prim["attributes"]["POSITION"]).astype(float) @ m.TO_GLTF
    b = body()
    assert v.shape == b.shape == (1229, 3)
    assert np.abs(v - b).max() < 1e-6  # float32 of 6-decimal metres
    w = acc(prim["attributes"]["WEIGHTS_0"]).astype(float)
    assert w.shape == (1229, 4) and (w >= 0).all() and np.abs(w.sum(axis=1) - 1).max() < 2e-7
    assert np.abs(m.skin(doc, acc, 0.0) @ m.TO_GLTF - b).max() < 1e-6
    # glTF holds the pose before the first key: the same at negative times
    assert np.abs(m.skin(doc, acc, -1.0) @ m.TO_GLTF - b).max() < 1e-6


def test_skinning_matches_blender():
    doc, acc = load()
    with open(FRAMES) as f:
        ref = json.load(f)
    assert ref["format"] == "garment_sim/skinned_frames/1"
    assert [fr["time_s"] for fr in ref["frames"]] == [0.0, 1.5, 3.0]
    b = body()
    for fr in ref["frames"]:
        theirs = np.array(fr["vertices"])
        ours = m.skin(doc, acc, fr["time_s"]) @ m.TO_GLTF
        err = np.abs(ours - theirs).max()
        moved = np.linalg.norm(theirs - b, axis=1).max()
        print(f"t = {fr['time_s']} s: largest difference from Blender {err:.2e} m, largest displacement {moved:.3f} m")
        assert err < 1e-4  # the file's 0.1 mm rounding plus float32


def test_the_arms_end_horizontal():
    doc, acc = load()
    b = body()
    end = m.skin(doc, acc, 3.0) @ m.TO_GLTF
    moved = np.linalg.norm(end - b, axis=1)
    # the hands (|x| > 0.4 m at rest) rise to about the shoulders' height (1.34 m)
    hands = np.abs(b[:, 0]) > 0.4
    assert hands.sum() > 10
    assert (end[hands, 2] > 1.25).all() and (end[hands, 2] < 1.45).all(), end[hands, 2]
    # the legs and the head (above the neck, 1.5 m) do not move
    still = (b[:, 2] < 0.7) | (b[:, 2] > 1.5)
    assert moved[still].max() < 1e-6


def test_the_turn_is_a_rigid_turn_at_a_steady_rate():
    """assets/bodies/anny/turn.glb: body.obj turned about the vertical axis
    x = y = 0 by the angle of the ramp-and-hold closed form (keys every
    0.05 s, slerp between them: at the keys and, after the 0.5 s ramp,
    everywhere), so at 1 rad/s after the ramp."""
    with open(os.path.join(ROOT, "assets/bodies/anny/turn.glb"), "rb") as f:
        doc, acc = m.read_glb(f.read())
    assert doc["animations"][0]["name"] == "turn"
    b = body()

    def angle(t):  # the closed form, independent of the tool's constants
        return t * t if t < 0.5 else t - 0.25

    for t in [0.0, 0.25, 0.5, 0.52, 1.0, 2.345, 3.99, 4.0]:
        a = angle(t)
        r = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
        err = np.abs(m.skin(doc, acc, t) @ m.TO_GLTF - b @ r.T).max()
        assert err < 1e-5, (t, err)
