#!/usr/bin/env python3
"""The table drape side by side with Blender's cloth, in one sitting.

Runs Blender (tools/blender_drape.py, the comparable scene) and garment_sim's
`drape` on the same grid, step and simulated time, interleaved: Blender, ours,
Blender, ours, ..., Blender. Each of our runs is set against the mean of the
Blender runs just before and after it, so a host whose speed drifts during the
sitting (shared machines do) biases no ratio. Times are the simulation loops'
own: Blender's bake (`wall_s` of its JSON), ours the step loop (`wall_s` of
`summary.json`). With `--threads 1` both run on core 0 (`taskset -c 0`).

  python3 tools/vs_blender.py --spacing 0.01 --dt 0.0033333333333333335 --threads 1 --solver amg
  python3 tools/vs_blender.py --spacing 0.01 --dt 1e-4 --threads 2 --friction 80 --rounds 1

Prints each run, then one line per ratio and their range (ours / Blender:
below 1, ours is faster). Needs `blender` (Debian: `apt-get install blender
python3-numpy`) and a release build (`cargo build --release`).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
ap.add_argument("--spacing", type=float, default=0.01, help="grid spacing, m (0.5 m cloth)")
ap.add_argument("--dt", type=float, default=1.0 / 300.0,
                help="time step, s; Blender's is 1/(60 quality), the nearest quality is taken")
ap.add_argument("--duration", type=float, default=2.0, help="simulated time, s")
ap.add_argument("--threads", type=int, default=1, help="threads of both (1: both on core 0)")
ap.add_argument("--solver", default="auto", help="our linear solver (auto, pcg, sgs, amg, cholesky)")
ap.add_argument("--cg-tolerance", type=float, default=None, help="our PCG's relative tolerance")
ap.add_argument("--friction", type=float, default=None,
                help="Blender's collision friction (default its 5; the thesis step needs 80 "
                     "to hold the cloth on the board, docs/benchmarks.md)")
ap.add_argument("--rounds", type=int, default=2, help="our runs (Blender runs one more)")
ap.add_argument("--binary", default=os.path.join(ROOT, "target", "release", "garment_sim"))
ap.add_argument("--blender", default="blender")
ap.add_argument("--out", default="/tmp/vs_blender", help="where both write their results")
args = ap.parse_args()

if not args.spacing > 0 or not args.dt > 0 or not args.duration > 0 or args.rounds < 1:
    sys.exit("vs_blender: --spacing, --dt and --duration must be > 0, --rounds ≥ 1")
n = round(0.5 / args.spacing) + 1
if abs((n - 1) * args.spacing - 0.5) > 1e-9:
    sys.exit(f"vs_blender: --spacing {args.spacing} m does not divide the 0.5 m cloth")
quality = max(1, round(1.0 / (60.0 * args.dt)))
blender_dt = 1.0 / (60.0 * quality)
if abs(blender_dt - args.dt) > 0.01 * args.dt:
    sys.exit(f"vs_blender: Blender steps 1/(60 q) s; the nearest to {args.dt} s is {blender_dt} s")
if not os.path.exists(args.binary):
    sys.exit(f"vs_blender: {args.binary} not found: run `cargo build --release` first")
os.makedirs(args.out, exist_ok=True)
pin = ["taskset", "-c", "0"] if args.threads == 1 else []


# Blender takes its Python's prefix from the first python3 on PATH: keep a
# version manager's interpreter (pyenv's, which lacks the system's numpy) out
# of its way
ENV = dict(os.environ, PATH=os.pathsep.join(
    d for d in os.environ.get("PATH", "").split(os.pathsep) if ".pyenv" not in d))


def run(cmd):
    p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=ENV)
    if p.returncode != 0:
        sys.exit(f"vs_blender: {' '.join(cmd)} failed ({p.returncode}):\n{p.stdout[-2000:]}"
                 f"\n{p.stderr[-2000:]}")


def blender(k):
    out = os.path.join(args.out, f"blender_{k}")
    cmd = pin + [args.blender, "-b", "-t", str(args.threads), "--factory-startup",
                 "--python-exit-code", "1", "--python", os.path.join(ROOT, "tools", "blender_drape.py"),
                 "--", "--n", str(n), "--quality", str(quality), "--sim-time", str(args.duration),
                 "--out", out]
    if args.friction is not None:
        cmd += ["--friction", str(args.friction)]
    run(cmd)
    with open(out + ".json") as f:
        r = json.load(f)
    if not r["finite"]:
        sys.exit("vs_blender: Blender's drape is not finite")
    print(f"blender {k}: {r['wall_s']:8.2f} s (bake; {r['frac_above_table_top']:.0%} of the "
          f"vertices above the board's top)", flush=True)
    return r["wall_s"]


def ours(k):
    out = os.path.join(args.out, f"garment_sim_{k}")
    cmd = pin + [args.binary, "drape", "config/scenes/table_drape.yaml", "--spacing",
                 repr(args.spacing), "--dt", repr(args.dt), "--duration", repr(args.duration),
                 "--threads", str(args.threads), "--solver", args.solver, "--out", out]
    if args.cg_tolerance is not None:
        cmd += ["--cg-tolerance", repr(args.cg_tolerance)]
    run(cmd)
    with open(os.path.join(out, "summary.json")) as f:
        s = json.load(f)
    print(f"ours    {k}: {s['wall_s']:8.2f} s (step loop; {s['mean_solver_iterations']:.1f} "
          f"iterations a step, settled at {s['settle_time_s']} s)", flush=True)
    return s["wall_s"]


print(f"table drape, {n} x {n} vertices ({args.spacing} m), dt = {args.dt:.6g} s (Blender: "
      f"quality {quality}, {blender_dt:.6g} s), {args.duration} s, {args.threads} thread(s), "
      f"ours --solver {args.solver}"
      + (f" --cg-tolerance {args.cg_tolerance}" if args.cg_tolerance is not None else ""),
      flush=True)
b = [blender(0)]
g = []
for k in range(args.rounds):
    g.append(ours(k))
    b.append(blender(k + 1))
ratios = [g[k] / statistics.mean(b[k:k + 2]) for k in range(args.rounds)]
for k, r in enumerate(ratios):
    how = f"{1 / r:.2f}x faster" if r < 1 else f"{r:.2f}x slower"
    print(f"ratio {k}: ours / Blender = {r:.2f} ({how})")
print(f"ours / Blender: {min(ratios):.2f}-{max(ratios):.2f}")
with open(os.path.join(args.out, "vs_blender.json"), "w") as f:
    json.dump(dict(settings=vars(args), n=n, blender_quality=quality, blender_s=b,
                   ours_s=g, ratios=ratios), f, indent=1)
