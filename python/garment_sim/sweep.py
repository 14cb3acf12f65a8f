"""Sweeps: the product of a sweep file's axes, each a trial, run on Dask.

A sweep file (YAML)::

    trial: ../config/trials/skirt_on_anny.yaml   # the base trial file
    axes:                                        # dotted keys of the trial file
      fabric: [../config/fabrics/acrylic.yaml, ../config/fabrics/wool_tropical.yaml]
      body.friction: [0.3, 0.5]
      overrides.spacing: [0.03]                  # run_trial's keyword arguments
    time_limit_s: 600        # wall time of one trial (default 3600)
    memory_limit: 4GiB       # per worker of the local cluster (default: Dask's share)
    retries: 0               # a trial's reruns after an exception (default 0)
    self_intersections: true # the table's self_intersections column (default true)

Paths in the sweep file (``trial``, and the values of the axes ``trial``,
``garment``, ``fabric``, ``body.obj``) are relative to the sweep file; the
axis ``trial`` swaps the base trial file itself. The trials are the product of
the axes, each named by a stable id made from its axis values; its outputs go
to ``OUT/trials/ID/`` and its row of the table to ``OUT/trials/ID/result.json``
(written once, atomically: a trial whose result exists is not run again).
``OUT/results.parquet`` gathers every row (``garment_sim.table``).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import os
import re
import sys
import time
import traceback
from pathlib import Path
from typing import Any, Dict, List, Optional

import yaml

#: Axis keys whose values are file paths, relative to the sweep file.
PATH_KEYS = {"trial", "garment", "fabric", "body.obj"}
RESULT = "result.json"
SWEEP_KEYS = {"trial", "axes", "time_limit_s", "memory_limit", "retries", "self_intersections"}


class SweepError(Exception):
    """A sweep file that cannot be read, with the file and field."""


def load(path: Path) -> Dict[str, Any]:
    """The sweep file at ``path``, checked, its paths made absolute."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as e:
        raise SweepError(f"sweep file {path}: {e}") from e
    if not isinstance(doc, dict):
        raise SweepError(f"sweep file {path}: a mapping with trial and axes")
    unknown = set(doc) - SWEEP_KEYS
    if unknown:
        raise SweepError(f"sweep file {path}: unknown field(s) {sorted(unknown)} "
                         f"(fields: {sorted(SWEEP_KEYS)})")
    axes = doc.get("axes") or {}
    if not isinstance(axes, dict) or not all(isinstance(v, list) and v for v in axes.values()):
        raise SweepError(f"sweep file {path}: axes: a mapping of dotted keys to non-empty lists")
    base = path.parent.absolute()
    if "trial" not in doc and "trial" not in axes:
        raise SweepError(f"sweep file {path}: trial: the base trial file (or an axis trial)")
    for k, vs in axes.items():
        if k.startswith("overrides."):
            from . import TRIAL_OVERRIDES
            if k[len("overrides."):] not in TRIAL_OVERRIDES:
                raise SweepError(f"sweep file {path}: axes.{k}: not one of "
                                 f"overrides.{{{', '.join(TRIAL_OVERRIDES)}}}")
    limit = doc.get("time_limit_s", 3600)
    if not (isinstance(limit, (int, float)) and limit > 0):
        raise SweepError(f"sweep file {path}: time_limit_s: a positive number of seconds")
    return {
        "path": str(path.absolute()),
        "base": str(base),
        "trial": str(base / doc["trial"]) if "trial" in doc else None,
        "axes": axes,
        "time_limit_s": float(limit),
        "memory_limit": doc.get("memory_limit", "auto"),
        "retries": int(doc.get("retries", 0)),
        "self_intersections": bool(doc.get("self_intersections", True)),
    }


def _slug(k: str, v: Any) -> str:
    s = str(v)
    if isinstance(v, str) and ("/" in v or v.endswith(".yaml")):
        p = Path(v)
        s = p.stem if k != "trial" else f"{p.parent.name}_{p.stem}"
    s = s.replace(".trial", "").replace(".garment", "")
    return re.sub(r"[^A-Za-z0-9.+-]+", "_", s)[:32]


def trial_id(values: Dict[str, Any]) -> str:
    """A stable id of a trial from its axis values (as the sweep file gives
    them): readable values, then a hash of them all."""
    h = hashlib.sha1(json.dumps(values, sort_keys=True).encode()).hexdigest()[:10]
    head = "_".join(_slug(k, v) for k, v in values.items())
    return f"{head}-{h}" if head else h


def trials(sweep: Dict[str, Any]) -> List[Dict[str, Any]]:
    """The product of the axes: per trial its id and axis values."""
    keys = list(sweep["axes"])
    out = []
    for combo in itertools.product(*(sweep["axes"][k] for k in keys)):
        values = dict(zip(keys, combo))
        out.append({"id": trial_id(values), "axes": values})
    ids = [t["id"] for t in out]
    if len(set(ids)) != len(ids):
        raise SweepError(f"sweep file {sweep['path']}: axes: repeated values")
    return out


def _set(doc: Dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    d = doc
    for p in parts[:-1]:
        d = d.setdefault(p, {})
        if not isinstance(d, dict):
            raise SweepError(f"axis {key}: {p} is not a mapping in the trial file")
    d[parts[-1]] = value


def _write_once(path: Path, text: str) -> bool:
    """Writes ``path`` atomically unless it exists; False if it did."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    try:
        os.link(tmp, path)
        return True
    except FileExistsError:
        return False
    finally:
        tmp.unlink()


class _TimeLimit(Exception):
    pass


def run_one(sweep: Dict[str, Any], spec: Dict[str, Any], out: str) -> Dict[str, Any]:
    """Runs one trial of the sweep on a Dask worker (or here) and returns its
    row; the row is also written to ``OUT/trials/ID/result.json``, once."""
    import garment_sim

    d = Path(out) / "trials" / spec["id"]
    d.mkdir(parents=True, exist_ok=True)
    done = d / RESULT
    if done.exists():
        return json.loads(done.read_text())
    # one start file per attempt, named by the process that makes it
    (d / f".start-{os.getpid()}-{time.time_ns()}").touch()
    row: Dict[str, Any] = {"id": spec["id"], "dir": str(d.absolute()), **spec["axes"]}
    # paths in the sweep file are relative to it
    values = {k: str(Path(sweep["base"]) / v) if k in PATH_KEYS else v
              for k, v in spec["axes"].items()}
    base = values.get("trial", sweep["trial"])
    t0, c0 = time.monotonic(), time.process_time()
    limit = sweep["time_limit_s"]
    try:
        doc = yaml.safe_load(Path(base).read_text())
        ov = {}
        for k, v in values.items():
            if k == "trial":
                continue
            if k.startswith("overrides."):
                ov[k[len("overrides."):]] = v
            else:
                _set(doc, k, v)

        # one worker process a core: one thread a trial, unless an axis says
        ov.setdefault("threads", 1)

        def progress(phase, done, of):
            if time.monotonic() - t0 > limit:
                raise _TimeLimit(f"time limit: {limit:g} s of wall time")

        r = garment_sim.run_trial(doc, out=d / "outputs", progress=progress,
                                  base_dir=Path(base).parent, **ov)
        row.update(outcome_of(r.fit, None))
        if sweep.get("self_intersections", True):
            from .intersect import self_intersections
            row["self_intersections"] = int(self_intersections(r.positions, r.faces))
        row["fit"] = r.fit
    except garment_sim.TrialError as e:
        r = getattr(e, "result", None)
        row.update(outcome_of(getattr(r, "fit", None), str(e)))
        if r is not None and sweep.get("self_intersections", True):
            from .intersect import self_intersections
            row["self_intersections"] = int(self_intersections(r.positions, r.faces))
    except _TimeLimit as e:
        row.update({"outcome": "failed", "reason": str(e)})
    except Exception as e:  # a bad sweep value, a file that cannot be read
        row.update({"outcome": "failed",
                    "reason": f"{type(e).__name__}: {e}",
                    "traceback": traceback.format_exc(limit=5)})
    row["trial_wall_s"] = time.monotonic() - t0
    # the worker process's CPU time over the trial (its only task then)
    row["trial_cpu_s"] = time.process_time() - c0
    row["attempts"] = len(list(d.glob(".start-*")))
    _write_once(done, json.dumps(row, indent=1, default=str))
    return json.loads(done.read_text())


def outcome_of(fit: Optional[Dict[str, Any]], error: Optional[str]) -> Dict[str, Any]:
    """The outcome and its reason: fit.json's ``outcome`` (settled /
    not_settled / dressed / failed / stopped, its reasons joined by "; "),
    or failed with the error."""
    if error is not None:
        row: Dict[str, Any] = {"outcome": "failed", "reason": error}
        if fit is not None:
            row["fit"] = fit
        return row
    verdict = fit.get("outcome")
    if isinstance(verdict, dict) and verdict.get("status"):
        # the library's own verdict (fit.json's outcome) and its reasons
        reasons = verdict.get("reasons") or []
        return {"outcome": verdict["status"], "reason": "; ".join(reasons)}
    run = fit["run"]
    if run.get("settle_time_s") is not None:
        return {"outcome": "settled",
                "reason": f"settled {run['settle_time_s']:.3f} s after sewing"}
    return {"outcome": "not_settled",
            "reason": f"rms speed {run['final_rms_speed_m_s']:.4g} m/s at "
                      f"t = {run['simulated_s']:.3f} s"}


class _Bar:
    """Trials done, failed, running and the rate, on one line (tqdm's bar
    when tqdm is installed)."""

    def __init__(self, total: int, skipped: int):
        self.total, self.done, self.failed, self.t0 = total, skipped, 0, time.monotonic()
        self.skipped = skipped
        try:
            from tqdm import tqdm
            self.tq = tqdm(total=total, initial=skipped, unit="trial", file=sys.stderr)
        except ImportError:
            self.tq = None

    def update(self, row: Optional[Dict[str, Any]], running: int) -> None:
        if row is not None:
            self.done += 1
            self.failed += row.get("outcome") == "failed"
        ran = self.done - self.skipped
        rate = 60.0 * ran / max(time.monotonic() - self.t0, 1e-9)
        text = f"failed {self.failed}, running {running}, {rate:.1f} trials/min"
        if self.tq is not None:
            if row is not None:
                self.tq.update(1)
            self.tq.set_postfix_str(text)
        else:
            print(f"\r{self.done}/{self.total} done, {text}   ", end="", file=sys.stderr,
                  flush=True)

    def close(self) -> None:
        if self.tq is not None:
            self.tq.close()
        else:
            print(file=sys.stderr)


def run(sweep_file: Path, out: Path, scheduler: Optional[str] = None,
        workers: Optional[int] = None, quiet: bool = False) -> Path:
    """Runs the sweep (the trials not yet done) and writes ``out/results.parquet``;
    returns its path."""
    from dask.distributed import Client, LocalCluster, as_completed

    from .table import write_table

    sweep = load(sweep_file)
    todo = trials(sweep)
    out = Path(out).absolute()
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.json").write_text(json.dumps({**sweep, "trials": todo}, indent=1))
    left = [t for t in todo if not (out / "trials" / t["id"] / RESULT).exists()]
    cluster = None
    if scheduler is None:
        n = workers or os.cpu_count() or 1
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                               memory_limit=sweep["memory_limit"],
                               dashboard_address=None, host="127.0.0.1")
        client = Client(cluster)
    else:
        client = Client(scheduler)
    bar = _Bar(len(todo), len(todo) - len(left)) if not quiet else None
    try:
        futures = [client.submit(run_one, sweep, t, str(out), key=f"trial-{t['id']}",
                                 retries=sweep["retries"], pure=False) for t in left]
        pending = {t["id"] for t in left}
        seen = [0.0, 0]

        def running() -> int:
            # started (a start file) and not finished, looked at at most once a second
            if time.monotonic() - seen[0] >= 1.0:
                d = out / "trials"
                seen[:] = [time.monotonic(),
                           sum(1 for i in pending if (d / i).is_dir()
                               and any((d / i).glob(".start-*")))]
            return seen[1]
        for fut in as_completed(futures):
            pending.discard(fut.key[len("trial-"):])
            try:
                row = fut.result()
            except Exception as e:  # the worker died too often (memory, crash)
                t = next(t for t in left if f"trial-{t['id']}" == fut.key)
                row = {"id": t["id"], **t["axes"], "outcome": "failed",
                       "reason": f"{type(e).__name__}: {e}",
                       "dir": str(out / "trials" / t["id"])}
                d = out / "trials" / t["id"]
                d.mkdir(parents=True, exist_ok=True)
                _write_once(d / RESULT, json.dumps(row, indent=1, default=str))
            if bar is not None:
                bar.update(row, running())
    finally:
        if bar is not None:
            bar.close()
        client.close()
        if cluster is not None:
            cluster.close()
    rows = [json.loads((out / "trials" / t["id"] / RESULT).read_text()) for t in todo]
    return write_table(rows, list(sweep["axes"]), out / "results.parquet")


def main(argv: Optional[List[str]] = None) -> int:
    p = argparse.ArgumentParser(prog="python -m garment_sim sweep",
                                description="Runs the product of a sweep file's axes on Dask.")
    p.add_argument("sweep", type=Path, help="sweep file (YAML)")
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--scheduler", help="a Dask scheduler's address, e.g. tcp://HOST:8786 "
                   "(default: a local cluster of one worker process per core)")
    p.add_argument("--workers", type=int, help="worker processes of the local cluster")
    a = p.parse_args(argv)
    try:
        table = run(a.sweep, a.out, a.scheduler, a.workers)
    except SweepError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    import pyarrow.parquet as pq
    t = pq.read_table(table, columns=["outcome"]).column("outcome").to_pylist()
    print(f"{len(t)} trials: {t.count('settled')} settled, {t.count('not_settled')} not "
          f"settled, {t.count('failed')} failed; wrote {table}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
