"""The linear system `garment_sim drape --write-system` writes, read and solved by SciPy.

SciPy's Matrix Market reader (``scipy.io.mmread``) reads the matrix and right-hand
side; numpy reads the per-vertex CSV. On the drapes' own systems this checks, with
nothing of garment_sim's but the files:

- the matrix is symmetric and ``A − M`` is positive semi-definite (the module text of
  the solver: ``A = (1 − hα) M + Σ (h² − hβ) K̃`` with α, β ≤ 0 and every K̃ PSD);
- the answer obeys the constraint filter (``dv = S dv + z``);
- the answer passes the stopping test system.json states, recomputed here;
- SciPy's direct solve of the filtered system is within the distance the answer's own
  residual proves: ``‖dv − dv*‖_M ≤ (rᵀ M⁻¹ r)^½`` (``S A S ≥ S M S``).

Run:  pip install pytest numpy scipy  &&  GARMENT_SIM_BIN=target/release/garment_sim \\
      python -m pytest tests/system_file.py -v
"""

import os
import pathlib
import subprocess
import sys

import pytest

np = pytest.importorskip("numpy")
sp = pytest.importorskip("scipy.sparse")
spla = pytest.importorskip("scipy.sparse.linalg")

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tools"))
from system_files import filter_matrix, load, stopping_test, vec  # noqa: E402
BIN = os.environ.get("GARMENT_SIM_BIN", str(REPO / "target/release/garment_sim"))
TMP = pathlib.Path(os.environ.get("GARMENT_SIM_TMP", "/tmp"))


def drape(name, scene, steps, *args):
    out = TMP / name
    run = subprocess.run(
        [BIN, "drape", str(REPO / scene), "--out", str(out),
         "--write-system", ",".join(map(str, steps)), *args],
        check=True, capture_output=True, cwd=REPO, text=True,
    )
    return out, run.stderr


def free_basis(v):
    """Columns spanning the free directions: 3 for a free vertex, the 2 of the
    tangent plane for one in contact, the crease's axis for one in a crease,
    none for a fixed one."""
    rows, cols, vals = [], [], []
    k = 0
    for i, f in enumerate(v["filter"]):
        if f == "free":
            dirs = np.eye(3)
        elif f == "normal":
            n = np.array([v["normal_x"][i], v["normal_y"][i], v["normal_z"][i]])
            t1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
            t1 /= np.linalg.norm(t1)
            dirs = np.stack([t1, np.cross(n, t1)])
        elif f == "crease":
            dirs = np.array([[v["normal_x"][i], v["normal_y"][i], v["normal_z"][i]]])
        else:
            dirs = np.zeros((0, 3))
        for t in dirs:
            rows += [3 * i, 3 * i + 1, 3 * i + 2]
            cols += [k] * 3
            vals += list(t)
            k += 1
    return sp.csr_matrix((vals, (rows, cols)), shape=(3 * len(v), k))


def check(d, filters):
    meta, a, b, v = load(d)
    n = meta["vertices"]
    assert a.shape == (3 * n, 3 * n) and b.shape == (3 * n,)
    assert a.nnz <= 9 * meta["blocks"]
    assert sorted(set(v["filter"])) == sorted(filters), set(v["filter"])
    m = np.repeat(v["mass_kg"], 3)
    amax = abs(a).max()
    assert abs(a - a.T).max() <= 1e-12 * amax
    # A − M is positive semi-definite
    lam = np.linalg.eigvalsh((a - sp.diags(m)).toarray())
    assert lam[0] >= -1e-9 * amax, lam[0]
    z, dv = vec(v, "z"), vec(v, "dv")
    q = free_basis(v)
    s = q @ q.T
    # the constraint filter: dv = S dv + z
    assert abs((dv - s @ dv) - z).max() <= 1e-12 * max(abs(dv).max(), 1e-300)
    # the filter the solver states is the projector on those free directions
    assert abs(s - filter_matrix(v)).max() <= 1e-12
    # the stopping test, recomputed: r^T D^-1 r <= tol^2 max(...)
    r = s @ (b - a @ dv)
    norm2, ref = stopping_test(meta, a, b, v)
    ratio = np.sqrt(norm2(r) / ref)
    assert ratio <= meta["tolerance"] * (1 + 1e-6), (ratio, meta)
    # SciPy's direct solve of the filtered system: S A S y = S (b − A z)
    ar = (q.T @ a @ q).tocsc()
    y = spla.spsolve(ar, q.T @ (b - a @ z))
    exact = q @ y + z
    err = np.sqrt(np.sum(m * (dv - exact) ** 2))
    bound = np.sqrt(np.sum(r * r / m))
    assert err <= bound * (1 + 1e-6) + 1e-15, (err, bound)
    # and the bound is a small part of the step's velocity change
    assert bound <= 1e-3 * np.sqrt(np.sum(m * exact**2)), (bound, meta)
    return meta


def test_the_table_drapes_systems_in_contact():
    out, err = drape("system_table", "config/scenes/table_drape.yaml", [40, 119, 5000],
                     "--spacing", "0.02", "--dt", "0.008333333333333333", "--duration", "1.0")
    solved = {check(out / f"system-{k}", ["free", "normal"])["solved_by"] for k in (40, 119)}
    # the Cholesky while the cloth lands, the multigrid once it rests
    assert solved == {"cholesky", "amg"}, solved
    # only the steps asked for; one the run does not reach is named
    assert sorted(p.name for p in out.glob("system-*")) == ["system-119", "system-40"]
    assert "step 5000 not reached (the run took 120 steps" in err, err


def test_a_pinned_cloths_system():
    out, _ = drape("system_pins", "config/scenes/hanging_corners.yaml", [50],
                   "--duration", "0.2")
    meta = check(out / "system-50", ["free", "fixed"])
    assert meta["step"] == 50 and meta["iterations"] > 0


def test_a_system_that_cannot_be_written_fails_the_command_after_the_drape():
    out = TMP / "system_blocked"
    out.mkdir(parents=True, exist_ok=True)
    (out / "system-3").write_text("a file where the directory should go\n")
    run = subprocess.run(
        [BIN, "drape", str(REPO / "config/scenes/free_fall.yaml"), "--duration", "0.05",
         "--out", str(out), "--write-system", "3"],
        capture_output=True, cwd=REPO, text=True,
    )
    assert run.returncode != 0, run.stdout
    assert "system-3" in run.stderr and "the run goes on" in run.stderr, run.stderr
    # the drape's own outputs are all there
    for f in ("final.ply", "final.png", "energy.csv", "summary.json"):
        assert (out / f).stat().st_size > 0, f
