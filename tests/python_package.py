"""The Python package (python/, docs/python.md) against the command line, and
its sweeps on a local Dask cluster (run by tests/python_package.rs; the wheel
is built and installed by tests/run.sh).

GARMENT_SIM_BIN is the command line's binary, GARMENT_SIM_TMP a scratch folder.
"""

import gc
import itertools
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import polars as pl
import pytest
import yaml

import garment_sim
from garment_sim.intersect import self_intersections

REPO = Path(__file__).resolve().parents[1]
BIN = os.environ["GARMENT_SIM_BIN"]
TMP = Path(os.environ["GARMENT_SIM_TMP"])
SKIRT = REPO / "config/trials/skirt_on_anny.yaml"
# small trials: the skirt at 3 cm, 0.2 s of drape after its 1 s of sewing
SMALL = {"spacing": 0.03, "max_time": 0.2, "threads": 1}


def cli(trial, out, **ov):
    args = [BIN, "trial", str(trial), "--out", str(out)]
    for k, v in ov.items():
        args += [f"--{k.replace('_', '-')}", str(v).lower() if isinstance(v, bool) else str(v)]
    return subprocess.run(args, capture_output=True, text=True)


def ply_vertices(path):
    lines = Path(path).read_text().splitlines()
    n = next(int(l.split()[2]) for l in lines if l.startswith("element vertex"))
    start = lines.index("end_header") + 1
    return np.array([[float(x) for x in l.split()[:3]] for l in lines[start:start + n]])


def bad_garment(dir):
    """A garment whose pattern has a stitch to a panel it does not have."""
    spec = json.loads((REPO / "assets/garments/skirt_specification.json").read_text())
    spec["pattern"]["stitches"][0][1]["panel"] = "no_such_panel"
    (dir / "bad_specification.json").write_text(json.dumps(spec))
    g = yaml.safe_load((REPO / "assets/garments/skirt.garment.yaml").read_text())
    g["garmentcode"] = "bad_specification.json"
    g["fabric"] = str(REPO / "config/fabrics/wool_tropical.yaml")
    (dir / "bad.garment.yaml").write_text(yaml.safe_dump(g))
    return dir / "bad.garment.yaml"


def trial_with(dir, name, **fields):
    t = yaml.safe_load(SKIRT.read_text())
    t["garment"] = str(REPO / "assets/garments/skirt.garment.yaml")
    t["body"]["obj"] = str(REPO / "assets/bodies/anny/body.obj")
    t.update(fields)
    p = dir / name
    p.write_text(yaml.safe_dump(t))
    return p


def test_trial_equals_the_command_line_bit_for_bit():
    d = TMP / "a"
    r = cli(SKIRT, d / "cli", spacing=0.03, max_time=0.2, threads=1)
    assert r.returncode == 0, r.stderr
    calls = []
    res = garment_sim.run_trial(str(SKIRT), out=d / "py",
                                progress=lambda *a: calls.append(a), **SMALL)
    # the same files, each the same bytes but fit.json (the times it took)
    files = sorted(os.listdir(d / "cli"))
    assert files == sorted(os.listdir(d / "py"))
    assert {"garment.ply", "garment.obj", "fit_strain.png", "trial.csv"} <= set(files)
    for f in set(files) - {"fit.json"}:
        assert (d / "cli" / f).read_bytes() == (d / "py" / f).read_bytes(), f
    # the arrays are the garment of the files (the PLY's 6 decimals)
    assert res.positions.dtype == np.float64 and res.faces.dtype == np.int64
    assert np.abs(res.positions - ply_vertices(d / "cli/garment.ply")).max() <= 5.0000001e-7
    assert res.faces.shape[1] == 3 and res.faces.max() == len(res.positions) - 1
    # the fit report is the command line's but for the times it took
    ref = json.loads((d / "cli/fit.json").read_text())
    assert json.loads((d / "py/fit.json").read_text())["panels"] == ref["panels"]
    for k in ["vertices", "weight_n", "panels", "contact_force_n", "girths",
              "largest_seam_gap_mm", "body_penetrations", "warnings"]:
        assert res.fit[k] == ref[k], k
    assert res.fit["run"]["steps"] == ref["run"]["steps"] == 240
    # progress: the sewing's, then the drape's, each within its phase
    phases = [c[0] for c in calls]
    assert phases[0] == "sewing" and phases[-1] == "drape"
    assert phases == sorted(phases, key=["sewing", "drape"].index)
    assert all(0 <= done <= of + 1e-9 for _, done, of in calls)
    # a dict is the file's content, its paths against base_dir
    doc = yaml.safe_load(SKIRT.read_text())
    res2 = garment_sim.run_trial(doc, base_dir=SKIRT.parent, **SMALL)
    assert np.array_equal(res2.positions, res.positions)


def test_a_result_moves_between_threads():
    # a run on a thread (as on a Dask worker), its result used and dropped on another
    seen = []
    hook, sys.unraisablehook = sys.unraisablehook, seen.append
    try:
        box = []
        t = threading.Thread(target=lambda: box.append(garment_sim.run_trial(
            str(SKIRT), spacing=0.05, max_time=0.0, threads=1)))
        t.start()
        t.join()
        r = box.pop()
        r.write(TMP / "thread")
        assert len(ply_vertices(TMP / "thread/garment.ply")) == len(r.positions)
        del r
        gc.collect()
    finally:
        sys.unraisablehook = hook
    assert not seen, [str(u.exc_value) for u in seen]


def test_the_gil_is_released_while_the_simulation_steps():
    # another Python thread notes the 10 ms slots it runs in; with no progress
    # callback the run never takes the GIL back, so were the GIL held while the
    # simulation steps, that thread could run in none of the slots strictly
    # inside the call
    slots, stop = set(), threading.Event()

    def spin():
        while not stop.is_set():
            slots.add(int(time.monotonic() * 100))

    t = threading.Thread(target=spin)
    t.start()
    try:
        start = time.monotonic()
        res = garment_sim.run_trial(str(SKIRT), **SMALL)
        end = time.monotonic()
    finally:
        stop.set()
        t.join()
    assert res.fit["run"]["steps"] > 0
    inside = range(int(start * 100) + 2, int(end * 100) - 1)
    assert len(inside) >= 20, f"the run took {end - start:.2f} s"
    ran = sum(1 for s in inside if s in slots)
    assert ran >= len(inside) // 4, f"the other thread ran in {ran} of {len(inside)} slots"


def test_errors_are_the_command_line_s():
    d = TMP / "e"
    d.mkdir(parents=True)
    with pytest.raises(TypeError, match="spaceing"):
        garment_sim.run_trial(str(SKIRT), spaceing=0.03)
    bad = trial_with(d, "bad.trial.yaml", garment=str(bad_garment(d)))
    r = cli(bad, d / "cli", spacing=0.03)
    assert r.returncode != 0
    line = r.stderr.strip().splitlines()[-1]
    assert line.startswith("error: ") and "no_such_panel" in line, r.stderr
    with pytest.raises(garment_sim.TrialError) as e:
        garment_sim.run_trial(str(bad), spacing=0.03)
    assert "error: " + str(e.value) == line
    with pytest.raises(garment_sim.TrialError, match="spacing"):
        garment_sim.run_trial(str(SKIRT), spacing=-1.0)


def test_ctrl_c_stops_the_run_cleanly():
    d = TMP / "c"
    sent = []

    def progress(phase, done, of):
        if not sent:
            sent.append(phase)
            signal.raise_signal(signal.SIGINT)

    # Python's own Ctrl-C handler, as in a terminal: a process started in
    # the background of a script inherits SIGINT ignored, and Python then
    # leaves it ignored
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            garment_sim.run_trial(str(SKIRT), out=d, progress=progress, **SMALL)
    finally:
        signal.signal(signal.SIGINT, before)
    assert sent, "the progress callback was never called"
    fit = json.loads((d / "fit.json").read_text())
    # stopped in the sewing, its outputs those of the steps taken
    assert 0 < fit["run"]["steps"] < 200
    assert len(ply_vertices(d / "garment.ply")) == fit["vertices"]


def test_self_intersections_closed_form():
    # a k × k grid on [0, 1]² (two triangles a cell) and one large triangle
    # in the plane x = c, across the grid: the 2 k triangles of the column of
    # cells holding c cross it, no other
    k = 10
    g = np.linspace(0, 1, k + 1)
    xs, ys = np.meshgrid(g, g, indexing="ij")
    v = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    idx = lambda i, j: i * (k + 1) + j  # noqa: E731
    f = []
    for i in range(k):
        for j in range(k):
            f += [[idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)],
                  [idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]]
    assert self_intersections(v, f) == 0
    c = 0.43
    n = len(v)
    v2 = np.vstack([v, [[c, -1, -1], [c, 3, -1], [c, -1, 3]]])
    assert self_intersections(v2, f + [[n, n + 1, n + 2]]) == 2 * k
    # lifted clear of the grid: none
    v3 = v2.copy()
    v3[n:, 2] += 2.0
    assert self_intersections(v3, f + [[n, n + 1, n + 2]]) == 0


def sweep(file, out, workers=2):
    return subprocess.run([sys.executable, "-m", "garment_sim", "sweep", str(file),
                           "--out", str(out), "--workers", str(workers)],
                          capture_output=True, text=True, timeout=600)


def test_sweep_table_failures_and_resume():
    d = TMP / "s"
    d.mkdir(parents=True)
    bad_garment(d)
    (d / "skirt.garment.yaml").write_text(
        (REPO / "assets/garments/skirt.garment.yaml").read_text()
        .replace("skirt_specification.json",
                 str(REPO / "assets/garments/skirt_specification.json"))
        .replace("../../config/fabrics/wool_tropical.yaml",
                 str(REPO / "config/fabrics/wool_tropical.yaml")))
    base = trial_with(d, "base.trial.yaml")
    axes = {
        "garment": ["skirt.garment.yaml", "bad.garment.yaml"],
        "fabric": [str(REPO / "config/fabrics/acrylic.yaml"),
                   str(REPO / "config/fabrics/wool_tropical.yaml")],
        "body.friction": [0.3, 0.5],
        "overrides.spacing": [0.04, 0.05],
        "overrides.max_time": [0.2],
        "overrides.threads": [1],
    }
    (d / "sweep.yaml").write_text(yaml.safe_dump(
        {"trial": base.name, "axes": axes, "time_limit_s": 300}))
    r = sweep(d / "sweep.yaml", d / "out")
    assert r.returncode == 0, r.stdout + r.stderr
    table = d / "out/results.parquet"
    pdf = pd.read_parquet(table)
    plf = pl.read_parquet(table)
    assert len(pdf) == len(plf) == 16
    assert plf["id"].n_unique() == 16
    keys = list(axes)
    got = sorted(tuple(row[k] for k in keys) for _, row in pdf.iterrows())
    assert got == sorted(itertools.product(*axes.values()))
    assert sorted(plf["body.friction"].to_list()) == sorted(pdf["body.friction"].to_list())
    # the bad pattern: a row with the command line's error, the others ran
    bad = trial_with(d, "bad.trial.yaml", garment=str(d / "bad.garment.yaml"))
    line = cli(bad, d / "cli_bad", spacing=0.04).stderr.strip().splitlines()[-1]
    for _, row in pdf.iterrows():
        if row["garment"] == "bad.garment.yaml":
            assert row["outcome"] == "failed"
            assert "error: " + row["reason"] == line
        else:
            assert row["outcome"] in ("settled", "not_settled"), row["reason"]
            fit = json.loads((Path(row["dir"]) / "outputs/fit.json").read_text())
            assert row["outcome"] == fit["outcome"]["status"]
            assert row["reason"] == "; ".join(fit["outcome"]["reasons"])
            assert row["run.steps"] == fit["run"]["steps"] == 240
            assert row["weight_n"] == fit["weight_n"]
            assert row["spacing_m"] == row["overrides.spacing"]
            assert row["self_intersections"] >= 0
            assert row["attempts"] == 1
    # the polars frame holds the same values
    ran = pdf[pdf["outcome"] != "failed"].sort_values("id")
    assert plf.filter(pl.col("outcome") != "failed").sort("id")["weight_n"].to_list() == \
        ran["weight_n"].tolist()
    assert len(ran) == 8
    # a second run redoes nothing
    marks = {p: p.stat().st_mtime_ns for p in (d / "out/trials").glob("*/result.json")}
    starts = sorted(str(p) for p in (d / "out/trials").glob("*/.start-*"))
    assert len(marks) == 16 and len(starts) == 16
    r = sweep(d / "sweep.yaml", d / "out")
    assert r.returncode == 0, r.stdout + r.stderr
    assert {p: p.stat().st_mtime_ns for p in marks} == marks
    assert sorted(str(p) for p in (d / "out/trials").glob("*/.start-*")) == starts
    assert len(pd.read_parquet(table)) == 16


def test_a_killed_worker_s_trial_is_done_once():
    d = TMP / "k"
    d.mkdir(parents=True)
    base = trial_with(d, "base.trial.yaml")
    axes = {"body.friction": [0.3, 0.4, 0.5, 0.6], "overrides.spacing": [0.025],
            "overrides.max_time": [1.5], "overrides.threads": [1]}
    (d / "sweep.yaml").write_text(yaml.safe_dump({"trial": base.name, "axes": axes}))
    p = subprocess.Popen([sys.executable, "-m", "garment_sim", "sweep", str(d / "sweep.yaml"),
                          "--out", str(d / "out"), "--workers", "2"],
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    # the first trial to start: its worker is killed a second into it
    deadline = time.monotonic() + 120
    start = None
    while start is None and time.monotonic() < deadline and p.poll() is None:
        found = list((d / "out/trials").glob("*/.start-*"))
        start = found[0] if found else None
        time.sleep(0.05)
    assert start is not None, p.communicate()[0]
    time.sleep(1.0)
    victim = start.parent
    assert not (victim / "result.json").exists()
    pid = int(start.name.split("-")[1])
    os.kill(pid, signal.SIGKILL)
    out, _ = p.communicate(timeout=600)
    assert p.returncode == 0, out
    pdf = pd.read_parquet(d / "out/results.parquet")
    assert len(pdf) == 4 and pdf["id"].nunique() == 4
    assert set(pdf["outcome"]) <= {"settled", "not_settled"}, pdf["reason"].tolist()
    row = pdf[pdf["id"] == victim.name].iloc[0]
    # run again elsewhere after the kill, and its result written once
    assert row["attempts"] == 2
    assert len(list(victim.glob(".start-*"))) == 2
    assert sorted(pdf["attempts"].tolist()) == [1, 1, 1, 2]
    fit = json.loads((victim / "outputs/fit.json").read_text())
    assert row["run.steps"] == fit["run"]["steps"]
    assert len(list(victim.glob("result.json*"))) == 1
    assert not list(victim.glob(".result.json.*"))


def test_scene_equals_drape():
    d = TMP / "scene"
    scene = REPO / "config/scenes/table_drape.yaml"
    r = subprocess.run([BIN, "drape", str(scene), "--out", str(d / "cli"), "--spacing", "0.04",
                        "--duration", "0.3", "--threads", "1"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    res = garment_sim.run_scene(str(scene), out=d / "py", spacing=0.04, duration=0.3, threads=1)
    assert (d / "cli/final.ply").read_bytes() == (d / "py/final.ply").read_bytes()
    # final.ply holds every digit
    assert np.array_equal(res.positions, ply_vertices(d / "cli/final.ply"))
    assert res.summary["vertices"] == len(res.positions)
    with pytest.raises(TypeError, match="max_time"):
        garment_sim.run_scene(str(scene), max_time=1.0)
