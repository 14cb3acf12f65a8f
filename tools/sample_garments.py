#!/usr/bin/env python3
"""A seeded population of GarmentCode designs, drawn by GarmentCode's own
sampler and fitted by GarmentCode to several bodies, with garment_sim garment
and trial files.

    python3 tools/sample_garments.py --garmentcode GARMENTCODE_CHECKOUT --out DIR
        [--seed 2026] [--quota upper_garment=12 dress=12 skirt=10 pants=8 jumpsuit=8]
        [--bodies anny anny_small anny_large] [--subset assets/population]

GARMENTCODE_CHECKOUT: GarmentCode at commit d449629979028123a5c4dc9e732a2ec19b7fce31
(pygarment 2.0.2; Python needs numpy, scipy, svgpathtools, svgwrite, pyyaml,
psutil, matplotlib, cairosvg), as for tools/make_garments.py.

Drawing (GarmentCode's pattern_sampler.py, the sampler of its dataset): design
number k (k = 0, 1, ...) is `pygarment.DesignSampler(
assets/design_params/default.yaml).randomize()` right after `random.seed(SEED +
k)`, so each design is reproduced by its own seed alone. It is kept only if it
passes GarmentCode's own filters on every body: pattern_sampler's
`assert_param_combinations`, `MetaGarment(name, body, design)` built without
error, `assert_total_length()`, and not `is_self_intersecting()`. Its type is
GarmentCode's (assets/garment_programs/stats_utils.py `garment_type`: main type
upper_garment / dress / skirt / pants / jumpsuit, and the styles). Stratified:
a valid design is taken while its main type has fewer designs than its quota,
or when it brings a feature value no design taken so far has (FEATURES: each
upper, bottom and waistband class of the meta garment, each collar component
(turtle, lapel, hood), each cuff, sleeves and none, an asymmetric top, each
skirt length class); drawing stops when every quota is full and every feature
value is present.

For each design NAME and body B (assets/bodies/B/):
  DIR/designs/NAME_design.yaml   the design: the `v` values that differ from
                                 GarmentCode's default design (the layout of
                                 assets/garments/*_design.yaml), with its seed
                                 and type in the header;
  DIR/B/NAME_specification.json  MetaGarment(NAME, BodyParameters(
                                 assets/bodies/B/garmentcode_body.yaml),
                                 design).assembly(), pygarment's serialize,
                                 panels sorted by name and stitches by their
                                 JSON text (as make_garments.py);
  DIR/B/NAME.garment.yaml        garment_sim garment (fabric by main type,
                                 FABRICS; warp along each panel's vertical);
  DIR/B/NAME.trial.yaml          garment_sim trial on assets/bodies/B/body.obj
                                 with the body's girth heights
                                 (tools/measure_body.py landmarks_m);
  DIR/population.yaml            seed, quotas, bodies, and per design its seed,
                                 draw, type, styles, meta garment and counts.
Paths inside the garment and trial files are relative to the file.

--subset SUBDIR also writes the CI subset (SUBSET_BODIES, and per rule of
SUBSET_RULES the first design of the population, by draw, that matches it and
is not taken yet) in the same layout under SUBDIR, with SUBDIR/subset.yaml.
The output is the same byte for byte from run to run for the same arguments.
"""

import argparse
import copy
import json
import os
import random
import re
import subprocess
import sys

import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
GARMENTCODE_COMMIT = "d449629979028123a5c4dc9e732a2ec19b7fce31"
DEFAULT_BODIES = ["anny", "anny_small", "anny_large"]
DEFAULT_QUOTA = {"upper_garment": 12, "dress": 12, "skirt": 10, "pants": 8, "jumpsuit": 8}
# fabric (config/fabrics/F.yaml) by GarmentCode main type
FABRICS = {
    "upper_garment": "cotton_broadcloth",
    "dress": "polyester_faille",
    "skirt": "wool_tropical",
    "pants": "polyester_tropical",
    "jumpsuit": "cotton_broadcloth",
}
MAX_DRAWS = 20000
SUBSET_BODIES = ["anny", "anny_large"]
# (label, test on a population entry): the CI subset takes, per rule, the first
# design (by draw) that matches and is not taken yet
SUBSET_RULES = [
    ("skirt, no waistband", lambda e: e["type"] == "skirt" and not e["meta"]["wb"]),
    ("skirt with waistband", lambda e: e["type"] == "skirt" and e["meta"]["wb"]),
    ("pants", lambda e: e["type"] == "pants"),
    ("top with sleeves", lambda e: e["type"] == "upper_garment" and "with_sleeves" in e["styles"]),
    ("sleeveless top", lambda e: e["type"] == "upper_garment" and "sleeveless" in e["styles"]),
    ("dress", lambda e: e["type"] == "dress"),
    ("jumpsuit", lambda e: e["type"] == "jumpsuit"),
    ("hood", lambda e: e["features"]["collar"] == "Hood2Panels"),
    ("collar (turtle or lapel)", lambda e: e["features"]["collar"] in ("Turtle", "SimpleLapel")),
]


def design_features(design):
    """Feature values of a sampled design (see FEATURES in the doc)."""
    meta = design["meta"]
    upper = meta["upper"]["v"]
    f = {
        "upper": upper,
        "bottom": meta["bottom"]["v"],
        "wb": meta["wb"]["v"],
        "collar": None,
        "sleeves": None,
        "cuff": None,
        "asymmetric": None,
    }
    if upper:
        sleeveless = design["sleeve"]["sleeveless"]["v"]
        if design["left"]["enable_asym"]["v"]:
            # GarmentCode's asymmetric bodice drops the collar component
            # (bodice.py sets its style to None)
            f["asymmetric"] = True
            sleeveless = sleeveless and design["left"]["sleeve"]["sleeveless"]["v"]
        else:
            f["collar"] = design["collar"]["component"]["style"]["v"]
        f["sleeves"] = not sleeveless
        if not sleeveless:
            f["cuff"] = design["sleeve"]["cuff"]["type"]["v"]
    return f


def feature_values(features, styles):
    """The (feature, value) pairs a design brings to the coverage."""
    out = {(k, v) for k, v in features.items() if v not in (None, False)}
    if features["upper"]:
        out.add(("sleeves", features["sleeves"]))
    out |= {("length", s) for s in styles if s in ("mini", "knee_len", "midi", "maxi")}
    return out


def all_feature_values(default_design):
    """Every (feature, value) pair the sampler can make (from the default design's ranges)."""
    d = default_design
    vals = set()
    for key in ("upper", "bottom", "wb"):
        vals |= {(key, v) for v in d["meta"][key]["range"] if v is not None}
    vals |= {("collar", v) for v in d["collar"]["component"]["style"]["range"] if v is not None}
    vals |= {("cuff", v) for v in d["sleeve"]["cuff"]["type"]["range"] if v is not None}
    vals |= {("sleeves", True), ("sleeves", False), ("asymmetric", True)}
    vals |= {("length", s) for s in ("mini", "knee_len", "midi", "maxi")}
    return vals


def design_diff(default, design):
    """The `v` values of `design` that differ from `default` (nested layout)."""
    out = {}
    for k, v in design.items():
        if isinstance(v, dict) and "v" in v:
            if v["v"] != default[k]["v"]:
                out[k] = {"v": v["v"]}
        elif isinstance(v, dict):
            sub = design_diff(default[k], v)
            if sub:
                out[k] = sub
    return out


def girth_heights(body_obj):
    """Chest, waist and hip girth heights (m) from tools/measure_body.py."""
    text = subprocess.run([sys.executable, os.path.join(HERE, "measure_body.py"), body_obj],
                          check=True, capture_output=True, text=True).stdout
    lm = yaml.safe_load(text)["landmarks_m"]
    return {"chest": lm["chest_girth_z"], "waist": lm["waist_girth_z"], "hips": lm["hip_girth_z"]}


def fmt_float(x):
    return f"{x:.6g}"


class Population:
    def __init__(self, gc_root, bodies, seed, quota):
        self.gc_root = gc_root
        self.bodies = bodies
        self.seed = seed
        self.quota = quota
        # GarmentCode's programs import `assets.garment_programs...` and
        # `pygarment` relative to the repository root.
        sys.path.insert(0, gc_root)
        os.chdir(gc_root)
        import pygarment as pyg
        import pattern_sampler
        import assets.garment_programs.stats_utils as stats_utils
        from assets.bodies.body_params import BodyParameters
        from assets.garment_programs.meta_garment import MetaGarment
        from pygarment.pattern.core import BasicPattern

        self.pattern_sampler = pattern_sampler
        self.stats_utils = stats_utils
        self.MetaGarment = MetaGarment
        self.BasicPattern = BasicPattern
        design_file = os.path.join(gc_root, "assets/design_params/default.yaml")
        with open(design_file) as f:
            self.default_design = yaml.safe_load(f)["design"]
        self.sampler = pyg.DesignSampler(design_file)
        self.body_params = {
            b: BodyParameters(os.path.join(ROOT, "assets/bodies", b, "garmentcode_body.yaml")) for b in bodies}

    def garment_type(self, design):
        props = {"generator": {"stats": {"garment_types": {}, "garment_types_summary": {"main": {}, "style": {}}}}}
        self.stats_utils.garment_type("d", design, props)
        t = props["generator"]["stats"]["garment_types"]["d"]
        return t["main"], t["styles"]

    def fit(self, name, design):
        """GarmentCode's checks and patterns of `design` on every body, or the
        reason it is rejected."""
        try:
            self.pattern_sampler.assert_param_combinations(design)
        except BaseException as e:  # GarmentCode's errors derive from BaseException
            return None, f"{type(e).__name__}: {e}"
        specs = {}
        for b in self.bodies:
            try:
                garment = self.MetaGarment(name, self.body_params[b], copy.deepcopy(design))
                garment.assert_total_length()
                if garment.is_self_intersecting():
                    return None, f"{b}: self-intersecting panels"
                pattern = garment.assembly()
            except BaseException as e:
                if isinstance(e, KeyboardInterrupt):
                    raise
                return None, f"{b}: {type(e).__name__}: {e}"
            spec = pattern.spec["pattern"]
            # GarmentCode collects subcomponents through a Python set of
            # objects, so the order of the panels and stitches changes from run
            # to run (their content does not); both are sorted. No value changes.
            spec["panels"] = {k: spec["panels"][k] for k in sorted(spec["panels"])}
            spec["stitches"] = sorted(spec["stitches"], key=lambda st: json.dumps(st, sort_keys=True))
            specs[b] = pattern
        return specs, None

    def draw(self, log=sys.stderr):
        counts = {t: 0 for t in self.quota}
        wanted = all_feature_values(self.default_design)
        covered = set()
        entries = []
        rejected = {}
        for k in range(MAX_DRAWS):
            if all(counts[t] >= q for t, q in self.quota.items()) and wanted <= covered:
                break
            seed_k = self.seed + k
            random.seed(seed_k)
            design = self.sampler.randomize()
            features = design_features(design)
            if not features["upper"] and not features["bottom"]:
                rejected["empty or waistband alone"] = rejected.get("empty or waistband alone", 0) + 1
                continue
            main, styles = self.garment_type(design)
            brings = feature_values(features, styles) & (wanted - covered)
            if counts.get(main, 0) >= self.quota.get(main, 0) and not brings:
                continue
            name = f"{main}_{seed_k}"
            specs, why = self.fit(name, design)
            if specs is None:
                key = re.sub(r"(?<![A-Za-z])-?[0-9][0-9.]*", "#", why.split("::")[-1])[:80]
                rejected[key] = rejected.get(key, 0) + 1
                continue
            counts[main] = counts.get(main, 0) + 1
            covered |= feature_values(features, styles)
            entries.append({"name": name, "seed": seed_k, "draw": k, "type": main, "styles": styles,
                            "meta": {"upper": features["upper"], "bottom": features["bottom"],
                                     "wb": features["wb"]},
                            "features": features, "design": design, "specs": specs})
            print(f"draw {k}: {name} {styles} {features['upper']}/{features['bottom']}/{features['wb']}"
                  f" collar {features['collar']}", file=log)
        else:
            raise SystemExit(f"no population after {MAX_DRAWS} draws: counts {counts}, "
                             f"missing features {sorted(map(str, wanted - covered))}")
        missing = wanted - covered
        return entries, counts, k, rejected, missing

    def write(self, out_dir, entries, bodies, header):
        out_dir = os.path.abspath(out_dir)
        os.makedirs(os.path.join(out_dir, "designs"), exist_ok=True)
        girths = {b: girth_heights(os.path.join(ROOT, "assets/bodies", b, "body.obj")) for b in bodies}
        index = []
        for e in entries:
            with open(os.path.join(out_dir, "designs", e["name"] + "_design.yaml"), "w") as f:
                f.write(f"# GarmentCode design {e['name']}: random.seed({e['seed']}); "
                        "pygarment.DesignSampler(assets/design_params/default.yaml).randomize()\n")
                f.write(f"# type {e['type']} ({', '.join(e['styles'])}); the `v` values that differ from "
                        "GarmentCode's default design\n")
                yaml.safe_dump({"design": design_diff(self.default_design, e["design"])}, f,
                               default_flow_style=False, sort_keys=True)
            item = {k: e[k] for k in ("name", "seed", "draw", "type", "styles", "meta")}
            item["collar"] = e["features"]["collar"]
            item["panels"], item["stitches"] = {}, {}
            for b in bodies:
                bdir = os.path.join(out_dir, b)
                os.makedirs(bdir, exist_ok=True)
                pattern = e["specs"][b]
                self.BasicPattern.serialize(pattern, bdir, to_subfolder=False)
                spec = pattern.spec["pattern"]
                item["panels"][b] = len(spec["panels"])
                item["stitches"][b] = len(spec["stitches"])
                self.write_garment(bdir, e)
                self.write_trial(bdir, e, b, girths[b])
            index.append(item)
        with open(os.path.join(out_dir, header["file"]), "w") as f:
            f.write(header["comment"])
            doc = {k: v for k, v in header.items() if k not in ("file", "comment")}
            doc["bodies"] = bodies
            doc["girths_m"] = girths
            doc["designs"] = index
            rules = doc.pop("rules", None)
            if rules:
                f.write("rules:\n" + "".join(f"  {k}: {v}\n" for k, v in rules.items()))
            yaml.safe_dump(doc, f, default_flow_style=None, sort_keys=False, width=120)

    def write_garment(self, bdir, e):
        fabric = os.path.relpath(os.path.join(ROOT, "config/fabrics", FABRICS[e["type"]] + ".yaml"), bdir)
        with open(os.path.join(bdir, e["name"] + ".garment.yaml"), "w") as f:
            f.write(f"# GarmentCode design {e['name']} ({e['type']}: {', '.join(e['styles'])}), "
                    "written by tools/sample_garments.py\n")
            f.write(f"name: {e['name']}\n")
            f.write(f"garmentcode: {e['name']}_specification.json\n")
            f.write("# GarmentCode's body axis onto anny's (tools/check_placement.py), m\n")
            f.write("offset: [0, -0.0177, 0]\n")
            f.write(f"fabric: {fabric}\n")
            f.write("# warp along each panel's vertical, the usual grainline\n")
            f.write("grain_deg: 90\n")

    def write_trial(self, bdir, e, body, girths):
        obj = os.path.relpath(os.path.join(ROOT, "assets/bodies", body, "body.obj"), bdir)
        trial = os.path.join(bdir, e["name"] + ".trial.yaml")
        with open(trial, "w") as f:
            f.write(f"# A virtual garment trial: GarmentCode design {e['name']} ({e['type']}) sewn onto\n")
            f.write(f"# the {body} body and draped (tools/sample_garments.py).\n")
            f.write(f"# garment_sim trial {os.path.relpath(trial, ROOT) if trial.startswith(ROOT) else trial}"
                    f" --out out/{e['name']}_{body}\n")
            f.write(f"garment: {e['name']}.garment.yaml\n")
            f.write("body:\n")
            f.write(f"  obj: {obj}\n")
            f.write("  skin_offset: 0.003\n")
            f.write("  friction: 0.5\n")
            f.write("  # girth heights measured on the body (tools/measure_body.py landmarks_m), m\n")
            f.write("  girths: {" + ", ".join(f"{k}: {fmt_float(v)}" for k, v in girths.items()) + "}\n")
            f.write("spacing: 0.01\n")
            f.write("dt: 0.005\n")
            f.write("# layers never pass through each other (docs/self_collision.md)\n")
            f.write("self_collision: true\n")
            f.write("settle: {max_time: 10}\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--garmentcode", required=True, help="GarmentCode checkout (repository root)")
    ap.add_argument("--out", required=True, help="folder for the whole population")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--quota", nargs="+", metavar="TYPE=N",
                    help="designs per GarmentCode main type (default: "
                         + " ".join(f"{k}={v}" for k, v in DEFAULT_QUOTA.items()) + ")")
    ap.add_argument("--bodies", nargs="+", default=DEFAULT_BODIES, help="folders under assets/bodies/")
    ap.add_argument("--subset", help="also write the CI subset into this folder (e.g. assets/population)")
    args = ap.parse_args()

    quota = dict(DEFAULT_QUOTA)
    if args.quota:
        quota = {}
        for item in args.quota:
            t, _, n = item.partition("=")
            if t not in DEFAULT_QUOTA:
                raise SystemExit(f"--quota {item}: type {t!r} is not one of {sorted(DEFAULT_QUOTA)}")
            quota[t] = int(n)
    for b in args.bodies:
        if not os.path.exists(os.path.join(ROOT, "assets/bodies", b, "garmentcode_body.yaml")):
            raise SystemExit(f"--bodies {b}: assets/bodies/{b}/garmentcode_body.yaml does not exist")
    out_dir = os.path.abspath(args.out)
    subset_dir = os.path.abspath(args.subset) if args.subset else None
    if subset_dir:
        missing = [b for b in SUBSET_BODIES if b not in args.bodies]
        if missing:
            raise SystemExit(f"--subset needs the bodies {SUBSET_BODIES} in --bodies (missing {missing})")

    pop = Population(os.path.abspath(args.garmentcode), args.bodies, args.seed, quota)
    entries, counts, draws, rejected, missing = pop.draw()
    common = {
        "garmentcode_commit": GARMENTCODE_COMMIT,
        "sampler": "random.seed(seed); pygarment.DesignSampler(assets/design_params/default.yaml).randomize()",
        "base_seed": args.seed,
    }
    pop.write(out_dir, entries, args.bodies, dict(
        file="population.yaml",
        comment=f"# GarmentCode design population written by: python3 tools/sample_garments.py "
                f"--seed {args.seed} --bodies {' '.join(args.bodies)}\n",
        **common, quota=quota, draws=draws, counts=counts,
        rejected_draws={k: rejected[k] for k in sorted(rejected)},
        features_never_drawn=sorted(f"{k}={v}" for k, v in missing)))
    print(f"{len(entries)} designs from {draws} draws: {counts}; -> {out_dir}")
    if missing:
        print(f"features never drawn: {sorted(missing)}")

    if subset_dir:
        chosen, labels = [], []
        for label, rule in SUBSET_RULES:
            for e in entries:
                if rule(e) and e not in chosen:
                    chosen.append(e)
                    labels.append(label)
                    break
            else:
                print(f"subset: no design for {label!r}")
        chosen_sorted = sorted(zip(chosen, labels), key=lambda p: p[0]["draw"])
        pop.write(subset_dir, [c for c, _ in chosen_sorted], SUBSET_BODIES, dict(
            file="subset.yaml",
            comment="# CI subset of the population of tools/sample_garments.py "
                    f"--seed {args.seed} --bodies {' '.join(args.bodies)} (README.md)\n",
            **common, rules={c["name"]: lab for c, lab in chosen_sorted}))
        print(f"subset: {len(chosen)} designs on {SUBSET_BODIES} -> {subset_dir}")


if __name__ == "__main__":
    main()
