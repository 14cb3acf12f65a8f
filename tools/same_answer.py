#!/usr/bin/env python3
"""Whether two garment trials give the same answer (issue 56's checks).

    python3 tools/same_answer.py REF_DIR RUN_DIR [--garment-sim target/release/garment_sim]

REF_DIR and RUN_DIR are `garment_sim trial --out` folders. Prints, and checks:
the settled garments' mean distance (thesis eq. 6.2, `garment_sim compare`)
<= 3 mm; the ease at every girth within 3 mm; the mean force on the body
(last 0.5 s, downward, over the weight) within 1 % of the weight; each
panel's largest strain (warp, weft, bias) within 1 point. Exit status 1 if
any check fails.
"""
import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ref", type=Path)
    ap.add_argument("run", type=Path)
    ap.add_argument("--garment-sim", default="target/release/garment_sim")
    a = ap.parse_args()
    fa = json.loads((a.ref / "fit.json").read_text())
    fb = json.loads((a.run / "fit.json").read_text())
    ok = True

    def check(name, value, bound, unit):
        nonlocal ok
        good = value is not None and abs(value) <= bound
        ok &= good
        shown = "n/a" if value is None else f"{value:.3f}"
        print(f"{name:<34} {shown:>9} {unit:<3} (bound {bound} {unit}) {'ok' if good else 'FAIL'}")

    with tempfile.TemporaryDirectory() as tmp:
        subprocess.run(
            [a.garment_sim, "compare", str(a.ref / "garment.ply"), str(a.run / "garment.ply"),
             "--out", tmp],
            check=True, stdout=subprocess.DEVNULL)
        c = json.loads((Path(tmp) / "compare.json").read_text())
    check("mean distance (eq. 6.2)", c["mean_m"] * 1e3, 3.0, "mm")
    for g, ga in fa["girths"].items():
        gb = fb["girths"].get(g, {})
        if ga.get("ease_cm") is None and gb.get("ease_cm") is None:
            continue
        d = None if ga.get("ease_cm") is None or gb.get("ease_cm") is None \
            else (gb["ease_cm"] - ga["ease_cm"]) * 10
        check(f"ease at {g}", d, 3.0, "mm")
    wa = fa["body_wrench"]["mean_down_over_weight"]
    wb = fb["body_wrench"]["mean_down_over_weight"]
    check("force on body / weight", (wb - wa) * 100, 1.0, "%")
    pa = {p["name"]: p for p in fa["panels"]}
    worst = 0.0
    for p in fb["panels"]:
        for d in ("warp", "weft", "bias"):
            diff = p[d]["max_percent"] - pa[p["name"]][d]["max_percent"]
            worst = diff if abs(diff) > abs(worst) else worst
    check("largest strain (worst panel, dir)", worst, 1.0, "pt")
    ra, rb = fa["run"], fb["run"]
    print(f"steps {ra['steps']} -> {rb['steps']}, settle {ra['settle_time_s']} -> "
          f"{rb['settle_time_s']} s, wall {ra['wall_s']:.1f} -> {rb['wall_s']:.1f} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
