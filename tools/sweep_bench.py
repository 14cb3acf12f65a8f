"""Benchmark of sweeps on Dask (docs/python.md#cost): trials per minute with 1
and 2 local workers, and the cost of a task beyond its trial.

    python3 tools/sweep_bench.py [--trials 16] [--instant 200] [--out /tmp/sweep_bench]

Needs the package (pip install ./python) and dask[distributed], pyarrow.
Trials: the shipped skirt at 4 cm, 0.2 s of drape after its 1 s of sewing, one
thread, distinct by the body's friction. The overhead: a sweep of trials that
fail at once (their garment's file is missing), whose wall time is all the
sweep's own (submit, schedule, marker files, the table), and bare Dask no-op
tasks through the same client.
"""

import argparse
import shutil
import time
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]


def sweep_file(d: Path, n: int, garment=None) -> Path:
    axes = {"body.friction": [round(0.3 + 0.001 * i, 3) for i in range(n)],
            "overrides.spacing": [0.04], "overrides.max_time": [0.2], "overrides.threads": [1]}
    if garment:
        axes["garment"] = [garment]
    doc = {"trial": str(REPO / "config/trials/skirt_on_anny.yaml"), "axes": axes,
           "self_intersections": True}
    p = d / f"sweep_{n}_{'x' if garment else 'skirt'}.yaml"
    p.write_text(yaml.safe_dump(doc))
    return p


def timed(f):
    t = time.monotonic()
    f()
    return time.monotonic() - t


def main():
    from garment_sim import sweep

    a = argparse.ArgumentParser()
    a.add_argument("--trials", type=int, default=16)
    a.add_argument("--instant", type=int, default=200)
    a.add_argument("--out", type=Path, default=Path("/tmp/sweep_bench"))
    args = a.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    args.out.mkdir(parents=True)
    s = sweep_file(args.out, args.trials)
    for w in (1, 2):
        out = args.out / f"w{w}"
        wall = timed(lambda: sweep.run(s, out, workers=w, quiet=True))
        import pandas as pd
        t = pd.read_parquet(out / "results.parquet")
        busy = t["trial_wall_s"].sum()
        cpu = t["trial_cpu_s"].sum()
        print(f"{w} worker(s): {args.trials} trials in {wall:.1f} s wall "
              f"({60 * args.trials / wall:.1f} trials/min, cluster start included); "
              f"a trial {busy / len(t):.2f} s wall, {cpu / len(t):.2f} s CPU in its task; outcomes "
              f"{t['outcome'].value_counts().to_dict()}")
    x = sweep_file(args.out, args.instant, garment=str(args.out / "missing.garment.yaml"))
    for w in (1, 2):
        out = args.out / f"x{w}"
        t0 = time.monotonic()
        sweep.run(x, out, workers=w, quiet=True)
        wall = time.monotonic() - t0
        print(f"{w} worker(s): {args.instant} instant (failing) trials in {wall:.1f} s wall: "
              f"{1e3 * wall / args.instant:.1f} ms a trial, cluster start included")
    import os
    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores at the end")
    from dask.distributed import Client, LocalCluster, as_completed
    for w in (1, 2):
        t0 = time.monotonic()
        with LocalCluster(n_workers=w, threads_per_worker=1, processes=True,
                          dashboard_address=None, host="127.0.0.1") as c, Client(c) as cl:
            cl.submit(int, 0).result()
            print(f"{w} worker(s): the local cluster up and a first task back in "
                  f"{time.monotonic() - t0:.1f} s")
            n = 1000
            t0 = time.monotonic()
            fs = [cl.submit(int, i, key=f"noop-{i}") for i in range(n)]
            for _ in as_completed(fs):
                pass
            dt = time.monotonic() - t0
            print(f"{w} worker(s): {n} no-op Dask tasks: {1e3 * dt / n:.2f} ms a task")


if __name__ == "__main__":
    main()
