"""Other multigrid solvers on a step's own linear system, under garment_sim's test.

Reads a directory that `garment_sim drape --write-system STEP` wrote and solves its
filtered system with the PCG preconditioned by PyAMG's smoothed aggregation (Bell,
Olson & Schroder, https://github.com/pyamg/pyamg) in several variants, from the
solve's own first guess, stopped by garment_sim's test (system.json,
"stopping_test"), and prints their iteration counts beside garment_sim's.
docs/benchmarks.md ("How far a multigrid goes") gives the figures and the commands.

    pip install pyamg scipy numpy
    python3 tools/multigrid_headroom.py out/system-60 [--tolerance 1e-6]
"""

import argparse
import pathlib

import numpy as np
import pyamg
import scipy.sparse as sp
from system_files import diagonal_inverses, filter_matrix, load, stopping_test, vec


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("system", type=pathlib.Path)
    ap.add_argument("--tolerance", type=float, help="default: system.json's")
    ap.add_argument("--max-iterations", type=int, default=500)
    args = ap.parse_args()
    meta, a, b, v = load(args.system)
    n = meta["vertices"]
    tol = args.tolerance or meta["tolerance"]
    m = np.asarray(v["mass_kg"], dtype=float)
    s = filter_matrix(v)
    z, guess = vec(v, "z"), vec(v, "guess")
    pos = vec(v, "").reshape(n, 3)
    # the filtered matrix of garment_sim's preconditioners: S A S + (I - S) m
    eye = sp.identity(3 * n, format="csr")
    af = (s @ a @ s + (eye - s) @ sp.diags(np.repeat(m, 3)) @ (eye - s)).tocsr()
    af.eliminate_zeros()
    afb = af.tobsr(blocksize=(3, 3))
    norm2, ref = stopping_test(meta, a, b, v)
    x0 = s @ guess + z
    rhs = s @ (b - a @ z)

    def pcg(prec):
        dv = x0 - z
        r = rhs - af @ dv
        r = s @ r
        for it in range(args.max_iterations + 1):
            if norm2(r) <= tol * tol * ref:
                return it
            c = s @ prec(r)
            rc = r @ c
            if it == 0:
                p = c
            else:
                p = c + (rc / rc_old) * p
            q = s @ (af @ p)
            alpha = rc / (p @ q)
            dv = dv + alpha * p
            r = r - alpha * q
            rc_old = rc
        return None

    def shown(it):
        return it if it is not None else f"> {args.max_iterations}"

    # near-null space: translations and rotations about the centroid
    bmodes = np.zeros((3 * n, 6))
    for c in range(3):
        bmodes[c::3, c] = 1.0
    centred = pos - pos.mean(axis=0)
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        bmodes[:, 3 + k] = np.cross(e, centred).reshape(-1)
    sweep = ("block_gauss_seidel", {"sweep": "symmetric", "iterations": 1})
    sweep2 = ("block_gauss_seidel", {"sweep": "symmetric", "iterations": 2})
    variants = [
        ("two levels, aggregates on every link (as garment_sim's)", dict(strength=None, max_levels=2)),
        ("two levels, aggregates on strong links (symmetric, 0.05)",
         dict(strength=("symmetric", {"theta": 0.05}), max_levels=2)),
        ("two levels, evolution strength", dict(strength="evolution", max_levels=2)),
        ("two levels, two sweeps each way", dict(strength=None, max_levels=2,
                                                 presmoother=sweep2, postsmoother=sweep2)),
        ("levels down to 300 unknowns", dict(strength=None, max_coarse=300)),
        ("levels down to 300, evolution strength", dict(strength="evolution", max_coarse=300)),
    ]
    print(f"{args.system}: step {meta['step']}, dt = {meta['dt_s']:.6g} s, {n} vertices, "
          f"filters {dict(zip(*np.unique(v['filter'], return_counts=True)))}")
    print(f"  garment_sim ({meta['solved_by']}): {meta['iterations']} iterations at tolerance "
          f"{meta['tolerance']:g} (the multigrid: {meta['tolerance'] / 100:g} where its first "
          f"coarse level is swept, as on the 0.5 cm drape and the garments)")
    dinv = diagonal_inverses(a)
    jac = pcg(lambda r: np.einsum("nij,nj->ni", dinv, r.reshape(n, 3)).reshape(-1))
    print(f"  block-Jacobi PCG: {shown(jac)} iterations at tolerance {tol:g}")
    for name, kw in variants:
        kw.setdefault("presmoother", sweep)
        kw.setdefault("postsmoother", sweep)
        ml = pyamg.smoothed_aggregation_solver(afb, B=bmodes, coarse_solver="splu", **kw)
        it = pcg(ml.aspreconditioner(cycle="V"))
        sizes = [lvl.A.shape[0] for lvl in ml.levels]
        print(f"  PyAMG, {name}: {shown(it)} "
              f"iterations (unknowns per level {sizes}, operator complexity "
              f"{ml.operator_complexity():.2f})")


if __name__ == "__main__":
    main()
