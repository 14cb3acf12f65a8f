#!/usr/bin/env python3
"""Sleeve panels of a GarmentCode top against the arm of the body they are placed on.

    python3 tools/check_sleeves.py assets/bodies/anny/body.obj \
        assets/garments/tshirt_specification.json [--sleeve left]

For the sleeve panels `SIDE_sleeve_f` and `SIDE_sleeve_b` (SIDE = left: the
body's left arm, +X), placed as tools/check_placement.py places them:
  * the sleeve axis: the panel's local -x -> +x direction (GarmentCode draws
    a sleeve panel with its cuff at x = 0 and its cap toward -x for the left
    sleeve, +x for the right one, and rotates it about Z by the body's
    arm_pose_angle);
  * the upper-arm axis of the body: principal direction of the centroids of
    the horizontal arm sections 2 to 12 cm below the armpit (the definition
    tools/measure_body.py uses for arm_pose_angle), and the angle between the
    two axes;
  * the cuff opening: the summed length of the panels' free edges (edges in no
    stitch), i.e. the sleeve's girth at its open end once sewn;
  * the arm's girth along the sleeve: perimeter of the convex hull of the arm
    section perpendicular to the upper-arm axis, every 2 cm from the cuff up
    toward the armpit, and the ratio cuff opening / arm girth;
  * where the arm centre is relative to the sewn sleeve at the cuff (the cuff
    centre: mean of the free edges' points).
"""

import argparse
import json
import math
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bodymesh as bm  # noqa: E402
import check_placement as cp  # noqa: E402
import measure_body as mb  # noqa: E402


def upper_arm_axis(verts, tris, sign):
    """Point and unit direction (pointing away from the torso) of the upper
    arm on the side sign (+1: +X, left arm; -1: -X)."""
    m = verts * np.array([sign, 1.0, 1.0])  # arm_loops looks at the +X arm
    armpit = mb.armpit_height(m, tris, bm.crotch_height(m, tris) + 0.1, 0.9 * m[:, 2].max())  # as measure_body.py
    cents = []
    for z in np.arange(armpit - 0.12, armpit - 0.02 + 1e-9, 0.005):
        torso = bm.torso_loop(m, tris, z)
        arms = [lp for lp in mb.arm_loops(m, tris, z, torso) if bm.polygon_centroid(lp)[0] > torso[:, 0].max()]
        if arms:
            lp = max(arms, key=lambda a: abs(bm.polygon_area(a)))
            c = bm.polygon_centroid(lp)
            cents.append([c[0], c[1], z])
    cents = np.array(cents)
    centre = cents.mean(axis=0)
    _, _, vt = np.linalg.svd(cents - centre)
    d = vt[0] if vt[0][0] > 0 else -vt[0]
    flip = np.array([sign, 1.0, 1.0])
    return centre * flip, d * flip, armpit


def arm_section(verts, tris, point, d):
    """Section loop of the plane through `point` normal to d that is nearest
    to `point`; returns (loop in the plane, its centre in 3D)."""
    e1 = np.cross(d, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(d, e1)
    loops = mb.loops_in_frame(verts, tris, point, e1, e2, d, 0.0)
    lp = min(loops, key=lambda a: np.linalg.norm(bm.polygon_centroid(a)))
    c = bm.polygon_centroid(lp)
    return lp, point + e1 * c[0] + e2 * c[1]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("body")
    ap.add_argument("spec")
    ap.add_argument("--sleeve", choices=["left", "right"], default="left")
    args = ap.parse_args()

    verts, tris = bm.load_triangles(args.body)
    with open(args.spec) as f:
        pattern = json.load(f)["pattern"]
    stitched = {(side["panel"], side["edge"]) for st in pattern["stitches"] for side in st}
    sign = 1.0 if args.sleeve == "left" else -1.0

    a0, d, armpit = upper_arm_axis(verts, tris, sign)
    print(f"armpit at z = {armpit:.3f} m; upper-arm axis {np.round(d, 3).tolist()}: "
          f"{math.degrees(math.atan2(-d[2], abs(d[0]))):.1f} deg below horizontal in the frontal (XZ) plane, "
          f"tilted {math.degrees(math.asin(-d[1])):.1f} deg forward (-Y)")

    free_pts, opening = [], 0.0
    for name in (f"{args.sleeve}_sleeve_f", f"{args.sleeve}_sleeve_b"):
        panel = pattern["panels"][name]
        verts2 = np.array(panel["vertices"], float)
        ends = cp.place(np.array([[-sign, 0.0], [sign, 0.0]]), panel, cp.OFFSET)
        axis = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
        print(f"{name}: rotation {panel['rotation']}, sleeve axis {np.round(axis, 3).tolist()}, "
              f"{math.degrees(math.acos(np.clip(axis @ d, -1.0, 1.0))):.1f} deg from the upper-arm axis")
        for i, edge in enumerate(panel["edges"]):
            if (name, i) in stitched:
                continue
            s, e = verts2[edge["endpoints"][0]], verts2[edge["endpoints"][1]]
            pts = cp.edge_points(s, e, edge.get("curvature"), 200)
            opening += float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
            free_pts.append(cp.place(pts, panel, cp.OFFSET))
    cuff = np.vstack(free_pts).mean(axis=0)
    q = a0 + ((cuff - a0) @ d) * d  # the axis point nearest the cuff centre
    _, arm_centre = arm_section(verts, tris, q, d)
    print(f"cuff opening (free edges, front + back) {opening:.1f} cm; cuff centre {np.round(cuff, 3).tolist()} m, "
          f"arm centre there {np.round(arm_centre, 3).tolist()} m")
    print(f"{'from cuff (cm)':>14} {'arm hull girth (cm)':>20} {'opening / girth':>16}")
    for k in range(0, 12, 2):
        lp, _ = arm_section(verts, tris, q - (k / 100.0) * d, d)
        g = mb.hull_perimeter(lp) * 100.0
        print(f"{k:14d} {g:20.1f} {opening / g:16.2f}")


if __name__ == "__main__":
    main()
