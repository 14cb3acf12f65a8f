#!/usr/bin/env python3
"""Reference figures of a GarmentCode pattern, computed by pygarment 2.0.2 itself.

    python3 tests/garmentcode_reference.py SPEC.json            # areas, lengths, 3D vertices
    python3 tests/garmentcode_reference.py SPEC.json --edges    # plus sampled edge polylines

Prints JSON (cm, cm^2) to stdout. Everything geometric comes from pygarment:
  * the file is loaded by pattern.core.BasicPattern (pygarment's JSON reader, with
    its normalisation of the template);
  * each edge is rebuilt as the pygarment.garmentcode.edge object that writes such
    an edge (Edge; CurveEdge(start, end, control_points, relative=True) for
    "quadratic"/"cubic"; CircleEdgeFactory.from_points_radius(start, end, radius,
    large_arc, right) for "circle"), and its assembly() must give back the JSON
    edge (checked: "roundtrip");
  * edge lengths: Edge.length() (chord), CurveEdge.length() (svgpathtools'
    Bezier arc length), CircleEdge.length() (radius x arc angle);
  * sampling: Edge/CurveEdge/CircleEdge.linearize(n_verts_inside) (arc-length
    uniform for Beziers, angle uniform for arcs);
  * panel area: pygarment has no area function; the area is the shoelace area of
    the closed polygon made of every edge's linearize() points (SAMPLES inner
    points per curved edge);
  * 3D vertex positions: BasicPattern._point_in_3D(vertex, rotation, translation)
    (Euler angles through pattern.rotation.euler_xyz_to_R = Rz Ry Rx, as
    pygarment's mesher uses them).

Needs the pygarment 2.0.2 wheel (its modules install as top-level `garmentcode`
and `pattern`, while they import each other as `pygarment.*`; this script maps
the `pygarment` name onto them) with numpy, scipy and svgpathtools.
"""

import argparse
import importlib.metadata
import importlib.util
import json
import sys
import types

import numpy as np

SAMPLES = 400  # inner points per curved edge for the area
EDGE_SAMPLES = 32  # inner points per curved edge printed with --edges


def import_pygarment():
    """Make `pygarment.garmentcode.*` and `pygarment.pattern.*` importable from
    the pygarment wheel's top-level packages `garmentcode` and `pattern`."""
    dist = importlib.metadata.distribution("pygarment")
    files = {str(f) for f in dist.files or []}
    for needed in ("garmentcode/edge.py", "garmentcode/edge_factory.py", "pattern/core.py"):
        if needed not in files:
            raise RuntimeError(f"pygarment {dist.version} has no {needed}")
    if "pygarment" not in sys.modules:
        site = str(dist.locate_file(""))
        pkg = types.ModuleType("pygarment")
        pkg.__path__ = [site]
        sys.modules["pygarment"] = pkg
    spec = importlib.util.find_spec("pygarment.garmentcode.edge")
    if spec is None or not spec.origin.startswith(str(dist.locate_file(""))):
        raise RuntimeError("pygarment.garmentcode.edge does not come from the pygarment wheel")
    return dist.version


def rebuild_edge(edge_mod, factory_mod, start, end, edge_dict):
    curv = edge_dict.get("curvature")
    if curv is None:
        return edge_mod.Edge(start, end), "line"
    if isinstance(curv, list):  # legacy: bare quadratic control point
        return edge_mod.CurveEdge(start, end, control_points=[list(curv)], relative=True), "quadratic"
    kind = curv["type"]
    if kind in ("quadratic", "cubic"):
        cps = [list(p) for p in curv["params"]]
        return edge_mod.CurveEdge(start, end, control_points=cps, relative=True), kind
    if kind == "circle":
        radius, large_arc, right = curv["params"]
        return factory_mod.CircleEdgeFactory.from_points_radius(
            start, end, radius, large_arc=bool(large_arc), right=bool(right)), kind
    raise ValueError(f"unknown curvature type {kind}")


def roundtrip_ok(edge_obj, edge_dict):
    """pygarment's own serialisation of the rebuilt edge equals the JSON edge."""
    _, props = edge_obj.assembly()
    a, b = props.get("curvature"), edge_dict.get("curvature")
    if isinstance(b, list):
        b = {"type": "quadratic", "params": [b]}
    if a is None or b is None:
        return a is None and b is None
    if a["type"] != b["type"]:
        return False
    return bool(np.allclose(np.array(a["params"], float), np.array(b["params"], float), rtol=1e-7, atol=1e-7))


def polyline(edge_obj, kind, n_inside):
    """Points from start to end: pygarment's linearize() of the edge."""
    if kind == "line":
        seq = edge_obj.linearize()
    else:
        seq = edge_obj.linearize(n_verts_inside=n_inside)
    pts = [list(map(float, seq[0].start))] + [list(map(float, e.end)) for e in seq]
    return pts


def shoelace(points):
    p = np.asarray(points, float)
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("spec")
    ap.add_argument("--edges", action="store_true", help="also print each edge's endpoints and sampled polyline")
    ap.add_argument("--samples", type=int, default=EDGE_SAMPLES,
                    help="inner points per curved edge in the --edges polylines")
    args = ap.parse_args()

    version = import_pygarment()
    import pygarment.garmentcode.edge as edge_mod
    import pygarment.garmentcode.edge_factory as factory_mod
    from pygarment.pattern.core import BasicPattern

    pattern = BasicPattern(args.spec)
    panels_out = {}
    lengths = {}
    for name in pattern.panel_order():
        panel = pattern.pattern["panels"][name]
        verts = [list(map(float, v)) for v in panel["vertices"]]
        ring = []
        edges_out = []
        for i, e in enumerate(panel["edges"]):
            start, end = verts[e["endpoints"][0]], verts[e["endpoints"][1]]
            obj, kind = rebuild_edge(edge_mod, factory_mod, list(start), list(end), e)
            length = float(obj.length())
            lengths[(name, i)] = length
            pts = polyline(obj, kind, SAMPLES)
            ring += pts[:-1]
            item = {"id": i, "endpoints": list(e["endpoints"]), "type": kind, "length_cm": length,
                    "roundtrip": roundtrip_ok(obj, e)}
            if "label" in e:
                item["label"] = e["label"]
            if args.edges:
                item["start"] = start
                item["end"] = end
                item["polyline"] = polyline(obj, kind, args.samples)
            edges_out.append(item)
        signed = shoelace(ring)
        v3 = [BasicPattern._point_in_3D(np.array(v), panel["rotation"], panel["translation"]) for v in verts]
        panels_out[name] = {
            "area_cm2": abs(signed),
            "signed_area_cm2": signed,
            "perimeter_cm": sum(x["length_cm"] for x in edges_out),
            "translation_cm": list(map(float, panel["translation"])),
            "rotation_deg": list(map(float, panel["rotation"])),
            "vertices_cm": verts,
            "vertices_3d_cm": [np.asarray(p, float).ravel().tolist() for p in v3],
            "edges": edges_out,
        }

    stitches_out = []
    for k, st in enumerate(pattern.pattern.get("stitches", [])):
        a, b = st[0], st[1]
        la, lb = lengths[(a["panel"], a["edge"])], lengths[(b["panel"], b["edge"])]
        stitches_out.append({
            "index": k,
            "a": {"panel": a["panel"], "edge": a["edge"], "length_cm": la},
            "b": {"panel": b["panel"], "edge": b["edge"], "length_cm": lb},
            "right_wrong": len(st) > 2 and st[2] == "right_wrong",
            "length_difference_cm": la - lb,
        })

    out = {
        "spec": args.spec,
        "pygarment_version": version,
        "units": {"length": "cm", "area": "cm^2"},
        "functions": {
            "load": "pattern.core.BasicPattern(spec)",
            "edge_objects": "garmentcode.edge.Edge / CurveEdge(start, end, control_points, relative=True) / "
                            "garmentcode.edge_factory.CircleEdgeFactory.from_points_radius(start, end, radius, large_arc, right)",
            "edge_length": "Edge.length() chord; CurveEdge.length() svgpathtools Bezier length; "
                           "CircleEdge.length() radius x arc angle",
            "sampling": "Edge/CurveEdge/CircleEdge.linearize(n_verts_inside)",
            "area": f"shoelace area of the polygon of the linearize() points, {SAMPLES} inner points per curved edge "
                    "(pygarment has no area function)",
            "vertices_3d": "pattern.core.BasicPattern._point_in_3D (rotation via pattern.rotation.euler_xyz_to_R = Rz Ry Rx)",
        },
        "area_samples_per_curved_edge": SAMPLES,
        "panels": panels_out,
        "stitches": stitches_out,
    }
    json.dump(out, sys.stdout, indent=1)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
