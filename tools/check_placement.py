#!/usr/bin/env python3
"""Place GarmentCode panels around a body in garment_sim's frame and check them.

    python3 tools/check_placement.py assets/bodies/anny/body.obj SPEC.json [SPEC.json ...]
        [--offset X Y Z] [--gc-body GARMENTCODE_BODY.obj]

GarmentCode frame: cm, Y up, floor at y = 0, its body faces +Z with its left hand
toward +X, centred on the vertical axis x = z = 0. A panel point (u, v) is placed
at P = R_panel (u, v, 0) + translation, R_panel = Rz(c) Ry(b) Rx(a) for
"rotation": [a, b, c] degrees (pygarment's pattern/rotation.py euler_xyz_to_R,
used by its mesher meshgen/boxmeshgen.py).
garment_sim frame: metres, Z up, the body faces -Y with its left hand toward +X.

    world = R (P / 100) + offset,   R (x, y, z) = (x, -z, y)   (+90 degrees about X)

offset: the default, OFFSET below, puts the pelvis axis of GarmentCode's own
body (assets/bodies/mean_all.obj of the GarmentCode repository; the centroid of
its torso section 10 cm above the crotch, the same definition that centres the
anny body) on the anny body's pelvis axis (x = y = 0); floors coincide (z = 0).
--gc-body recomputes it from that OBJ.

For each panel: boundary points (edges sampled about every 5 mm, curves by the
formulas of GarmentCode's JSON: Bezier control points in the edge frame, SVG-like
arcs) and interior points (2 cm grid) are placed; the report gives the
smallest distance to the body surface, how many points are inside the body
(generalised winding number > 0.5) and the deepest one, the side of the body
the panel is on, and whether the panel's outward normal (right-hand rule of its
edge loop) points away from the body.
"""

import argparse
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bodymesh as bm  # noqa: E402

GC_TO_WORLD = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
OFFSET = np.array([0.0, -0.0177, 0.0])  # m, see the module docstring / --gc-body (x: 0.5 mm, dropped)


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def panel_rotation(euler_deg, order="zyx"):
    a, b, c = (math.radians(e) for e in euler_deg)
    if order == "zyx":  # pygarment's reader / mesher: Rz Ry Rx
        return rot_z(c) @ rot_y(b) @ rot_x(a)
    return rot_x(a) @ rot_y(b) @ rot_z(c)  # scipy 'XYZ' (intrinsic), GarmentCode's writer


# ---------------------------------------------------------------- edge geometry

def rel_to_abs(s, e, uv):
    d = e - s
    n = np.array([-d[1], d[0]])
    return s + uv[0] * d + uv[1] * n


def edge_points(s, e, curvature, n):
    """n + 1 points from s to e along the edge."""
    t = np.linspace(0.0, 1.0, n + 1)[:, None]
    if curvature is None:
        return s + t * (e - s)
    kind = curvature["type"] if isinstance(curvature, dict) else "quadratic"
    params = curvature["params"] if isinstance(curvature, dict) else [curvature]
    if kind == "quadratic":
        c = rel_to_abs(s, e, params[0])
        return (1 - t) ** 2 * s + 2 * (1 - t) * t * c + t ** 2 * e
    if kind == "cubic":
        c1, c2 = rel_to_abs(s, e, params[0]), rel_to_abs(s, e, params[1])
        return (1 - t) ** 3 * s + 3 * (1 - t) ** 2 * t * c1 + 3 * (1 - t) * t ** 2 * c2 + t ** 3 * e
    if kind == "circle":
        radius, large_arc, right = params
        d = e - s
        chord = np.linalg.norm(d)
        h = math.sqrt(max(radius ** 2 - chord ** 2 / 4, 0.0))
        left = np.array([-d[1], d[0]]) / chord
        sign = 1.0 if (bool(right) != bool(large_arc)) else -1.0
        centre = s + d / 2 + sign * h * left
        a0 = math.atan2(*(s - centre)[::-1])
        a1 = math.atan2(*(e - centre)[::-1])
        sweep = (a1 - a0) % (2 * math.pi)  # counter-clockwise sweep
        if not right:  # clockwise
            sweep = sweep - 2 * math.pi
        ang = a0 + t[:, 0] * sweep
        return centre + radius * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    raise ValueError(f"unknown curvature type {kind}")


def panel_outline(panel, spacing=0.5):
    verts = np.array(panel["vertices"], float)
    pts = []
    for edge in panel["edges"]:
        s, e = verts[edge["endpoints"][0]], verts[edge["endpoints"][1]]
        coarse = edge_points(s, e, edge.get("curvature"), 64)
        length = np.linalg.norm(np.diff(coarse, axis=0), axis=1).sum()
        n = max(1, int(math.ceil(length / spacing)))
        pts.append(edge_points(s, e, edge.get("curvature"), n)[:-1])
    return np.vstack(pts)


def interior_grid(outline, spacing=2.0):
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    xs = np.arange(lo[0] + spacing / 2, hi[0], spacing)
    ys = np.arange(lo[1] + spacing / 2, hi[1], spacing)
    pts = [(x, y) for x in xs for y in ys if bm.point_in_polygon((x, y), outline)]
    return np.array(pts).reshape(-1, 2)


def place(points2d, panel, offset, order="zyx"):
    rot = panel_rotation(panel["rotation"], order)
    p3 = np.column_stack([points2d, np.zeros(len(points2d))]) @ rot.T + np.array(panel["translation"])
    return (p3 / 100.0) @ GC_TO_WORLD.T + offset


def derive_offset(gc_body_obj):
    verts, faces = bm.load_obj(gc_body_obj)
    tris = bm.triangulate(verts, faces)
    w = verts @ GC_TO_WORLD.T  # GarmentCode body OBJs are in metres
    zc = bm.crotch_height(w, tris)
    c = bm.polygon_centroid(bm.torso_loop(w, tris, zc + 0.10))
    return np.array([-c[0], -c[1], -w[:, 2].min()])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("body")
    ap.add_argument("specs", nargs="+")
    ap.add_argument("--offset", nargs=3, type=float)
    ap.add_argument("--gc-body", help="GarmentCode body OBJ to derive the offset from")
    args = ap.parse_args()

    offset = OFFSET
    if args.gc_body:
        offset = derive_offset(args.gc_body)
    if args.offset:
        offset = np.array(args.offset)
    verts, tris = bm.load_triangles(args.body)

    report = {"transform": {"R_gc_to_world": GC_TO_WORLD.tolist(), "scale": 0.01,
                            "offset_m": [round(float(x), 5) for x in offset]},
              "garments": {}}
    for spec_path in args.specs:
        with open(spec_path) as f:
            spec = json.load(f)
        panels = spec["pattern"]["panels"]
        out = {}
        for name, panel in panels.items():
            outline = panel_outline(panel)
            inner = interior_grid(outline)
            pts2 = np.vstack([outline, inner]) if len(inner) else outline
            world = place(pts2, panel, offset)
            alt = place(pts2, panel, offset, order="xyz")
            dist = bm.distances_to_mesh(verts, tris, world)
            wn = bm.winding_numbers(verts, tris, world)
            inside = wn > 0.5
            area2 = bm.polygon_area(outline)
            rot = panel_rotation(panel["rotation"])
            normal = GC_TO_WORLD @ rot @ np.array([0.0, 0.0, 1.0 if area2 > 0 else -1.0])
            centre = world.mean(axis=0)
            # body axis point at the panel's height: centroid of the torso section there
            zc = float(np.clip(centre[2], 0.05, verts[:, 2].max() - 0.05))
            loops = bm.slice_loops(verts, tris, zc)
            if loops:
                big = max(loops, key=lambda lp: abs(bm.polygon_area(lp)))
                axis = np.append(bm.polygon_centroid(big), zc)
            else:
                axis = np.array([0.0, 0.0, zc])
            out[name] = {
                "points": int(len(world)),
                "min_distance_to_body_m": round(float(dist.min()), 4),
                "mean_distance_to_body_m": round(float(dist.mean()), 4),
                "points_inside_body": int(inside.sum()),
                "deepest_inside_m": round(float(dist[inside].max()), 4) if inside.any() else 0.0,
                "centre_m": [round(float(x), 4) for x in centre],
                "bbox_min_m": [round(float(x), 4) for x in world.min(axis=0)],
                "bbox_max_m": [round(float(x), 4) for x in world.max(axis=0)],
                "loop_ccw_in_panel_frame": bool(area2 > 0),
                "outward_normal_world": [round(float(x), 3) for x in normal],
                "normal_points_away_from_body": bool(np.dot(normal[:2], (centre - axis)[:2]) > 0),
                "max_diff_rz_ry_rx_vs_rx_ry_rz_m": round(float(np.abs(world - alt).max()), 6),
            }
        report["garments"][os.path.basename(spec_path)] = out
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
