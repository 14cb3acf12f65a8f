#!/usr/bin/env python3
"""Girth of a sewn GarmentCode skirt against the body's girth at each height.

    python3 tools/check_skirt_clearance.py assets/bodies/anny/body.obj \
        assets/garments/skirt_specification.json [--step 0.01] [--window 0.03]

Skirt girth. The waist seam of each panel is its free edges (edges in no
stitch) lying above the panel's centre once placed (tools/check_placement.py's
placement). The skirt's girth at distance d below the waist seam, measured in
the cloth, is the length of the curve {distance to the waist seam = d} in every
panel, summed over the panels; it is computed with the coarea formula (the
distance has unit gradient): the panel area between the level sets d - s/2 and
d + s/2, over s, on a 1 mm grid of panel points. Dart notches are outside the
panel outline, so the girth is the girth as sewn.

Heights. The waist seam is put at the height of its highest placed point
(GarmentCode's _waist_level); cloth that hangs from it reaches at most d
below it at distance d, so at the height z = z_waist - d the skirt's girth is
at least girth(d) (girth grows with d for a flared skirt).

Body girth. At height z: the perimeter of the convex hull of all body section
loops at z except those of the arms and hands (loops whose centroid is more
than 0.3 m from the sagittal plane); below the crotch that is the hull of
both legs together. --window w also reports the largest such hull perimeter
within z +- w, i.e. the body girth the skirt meets if its waist settles up to
w higher or lower.

Output: one row per height step (cm): d, z, skirt girth, body hull perimeter
at z and its window maximum, and the ratios skirt / body.
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

ARM_X = 0.3  # m: loops with |centroid x| above this are arms / hands
GRID = 0.1  # cm
BAND = 1.0  # cm


def inside_polygon(pts, poly):
    """Even-odd test of many points against one polygon (vectorised)."""
    inside = np.zeros(len(pts), bool)
    x, y = pts[:, 0], pts[:, 1]
    for (x0, y0), (x1, y1) in zip(poly, np.roll(poly, -1, axis=0)):
        if y0 == y1:
            continue
        cond = (y0 > y) != (y1 > y)
        xi = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
        inside ^= cond & (x < xi)
    return inside


def segment_distances(pts, a, b):
    """Distance of each point to the nearest of the segments a[i] -> b[i]."""
    best = np.full(len(pts), np.inf)
    for s, e in zip(a, b):
        d = e - s
        t = np.clip(((pts - s) @ d) / max(d @ d, 1e-12), 0.0, 1.0)
        best = np.minimum(best, np.linalg.norm(pts - (s + t[:, None] * d), axis=1))
    return best


def panel_waist_distances(name, panel, stitched, offset):
    """Distances (cm) of a 1 mm grid of panel points to the panel's waist seam,
    the world height (m) of the highest waist point and the seam's length (cm)."""
    verts = np.array(panel["vertices"], float)
    centre_z = cp.place(verts, panel, offset)[:, 2].mean()
    waist_a, waist_b, top = [], [], -np.inf
    for i, edge in enumerate(panel["edges"]):
        if (name, i) in stitched:
            continue
        s, e = verts[edge["endpoints"][0]], verts[edge["endpoints"][1]]
        pts = cp.edge_points(s, e, edge.get("curvature"), 400)
        z = cp.place(pts, panel, offset)[:, 2]
        if z.mean() > centre_z:
            waist_a.append(pts[:-1])
            waist_b.append(pts[1:])
            top = max(top, float(z.max()))
    if not waist_a:
        raise ValueError(f"{name}: no free edge above the panel centre (no waist seam)")
    outline = cp.panel_outline(panel, spacing=0.1)
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    xs = np.arange(lo[0] + GRID / 2, hi[0], GRID)
    ys = np.arange(lo[1] + GRID / 2, hi[1], GRID)
    grid = np.stack(np.meshgrid(xs, ys), axis=-1).reshape(-1, 2)
    grid = grid[inside_polygon(grid, outline)]
    a, b = np.vstack(waist_a), np.vstack(waist_b)
    return segment_distances(grid, a, b), top, float(np.linalg.norm(b - a, axis=1).sum())


def body_hull_perimeter(verts, tris, z):
    loops = [lp for lp in bm.slice_loops(verts, tris, z) if abs(bm.polygon_centroid(lp)[0]) <= ARM_X]
    if not loops:
        return 0.0
    return bm.polyline_length(bm.convex_hull(np.vstack(loops)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("body")
    ap.add_argument("spec")
    ap.add_argument("--step", type=float, default=0.01, help="height step (m)")
    ap.add_argument("--window", type=float, default=0.03, help="waist height uncertainty (m)")
    ap.add_argument("--json", action="store_true", help="print the rows as JSON")
    args = ap.parse_args()

    with open(args.spec) as f:
        pattern = json.load(f)["pattern"]
    stitched = {(side["panel"], side["edge"]) for st in pattern["stitches"] for side in st}
    verts, tris = bm.load_triangles(args.body)

    dists, tops, waist = [], [], 0.0
    for name, panel in pattern["panels"].items():
        d, top, seam = panel_waist_distances(name, panel, stitched, cp.OFFSET)
        dists.append(d)
        tops.append(top)
        waist += seam
    z_waist = max(tops)
    length = max(float(d.max()) for d in dists)  # cm

    cache = {}

    def hull(z):
        key = round(z, 4)
        if key not in cache:
            cache[key] = body_hull_perimeter(verts, tris, z)
        return cache[key]

    rows = []
    n = int(math.floor(length / 100.0 / args.step + 1e-9))
    for k in range(n + 1):
        d = k * args.step * 100.0  # cm
        lo, hi = max(d - BAND / 2, 0.0), d + BAND / 2
        girth = sum(np.count_nonzero((pd >= lo) & (pd < hi)) for pd in dists) * GRID * GRID / (hi - lo)
        z = z_waist - d / 100.0
        nw = int(round(args.window / args.step))
        body = hull(z) * 100.0
        body_w = max(hull(z + j * args.step) for j in range(-nw, nw + 1)) * 100.0
        rows.append({"d_cm": round(d, 1), "z_m": round(z, 3), "skirt_girth_cm": round(girth, 1),
                     "body_hull_cm": round(body, 1), "body_hull_window_max_cm": round(body_w, 1),
                     "ratio": round(girth / body, 3) if body else None,
                     "ratio_window": round(girth / body_w, 3) if body_w else None})
    if args.json:
        print(json.dumps({"z_waist_m": round(z_waist, 4), "waist_seam_cm": round(waist, 2),
                          "length_cm": round(length, 1), "rows": rows}, indent=1))
        return
    print(f"waist seam {waist:.2f} cm long, at z = {z_waist:.4f} m; "
          f"skirt length (waist to hem, in the cloth) {length:.1f} cm")
    print(f"{'d (cm)':>7} {'z (m)':>6} {'skirt':>7} {'body':>7} {'body+-w':>8} {'ratio':>6} {'ratio+-w':>8}")
    for r in rows:
        print(f"{r['d_cm']:7.1f} {r['z_m']:6.3f} {r['skirt_girth_cm']:7.1f} {r['body_hull_cm']:7.1f} "
              f"{r['body_hull_window_max_cm']:8.1f} {r['ratio'] or 0:6.3f} {r['ratio_window'] or 0:8.3f}")


if __name__ == "__main__":
    main()
