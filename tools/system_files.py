"""Reading what `garment_sim drape --write-system STEP` writes (docs/drape.md).

    meta, a, b, v = load(pathlib.Path("out/system-60"))

`meta` is system.json, `a` the matrix (SciPy CSR, 3n x 3n), `b` the right-hand side,
`v` vertices.csv as a numpy record array; `vec(v, "dv")` gives a column triple as one
3n vector (vertex i's coordinate c at 3i + c); `filter_matrix(v)` the constraint filter
S and `stopping_test(meta, a, b, v)` garment_sim's convergence test.
"""

import json

import numpy as np
import scipy.io as sio
import scipy.sparse as sp


def load(d):
    meta = json.loads((d / "system.json").read_text())
    a = sp.csr_matrix(sio.mmread(str(d / "A.mtx")))
    b = np.asarray(sio.mmread(str(d / "b.mtx"))).reshape(-1)
    v = np.genfromtxt(d / "vertices.csv", delimiter=",", names=True, dtype=None, encoding="utf-8")
    return meta, a, b, v


def vec(v, prefix):
    """The columns `prefix_x`, `prefix_y`, `prefix_z` (or `x`, `y`, `z` for "") as one
    3n vector."""
    p = prefix + "_" if prefix else ""
    return np.stack([v[p + "x"], v[p + "y"], v[p + "z"]], axis=1).reshape(-1)


def filter_matrix(v):
    """The constraint filter S (3n x 3n, block diagonal): I for a free vertex,
    I - n n^T for one in contact along n, a a^T for one in a crease of axis a
    (given in the normal columns), 0 for a fixed one."""
    blocks = []
    for i, f in enumerate(v["filter"]):
        if f == "free":
            blocks.append(np.eye(3))
        elif f == "normal":
            nv = np.array([v["normal_x"][i], v["normal_y"][i], v["normal_z"][i]])
            blocks.append(np.eye(3) - np.outer(nv, nv))
        elif f == "crease":
            av = np.array([v["normal_x"][i], v["normal_y"][i], v["normal_z"][i]])
            blocks.append(np.outer(av, av))
        else:
            blocks.append(np.zeros((3, 3)))
    return sp.block_diag(blocks, format="csr")


def diagonal_inverses(a):
    """The inverses of A's 3 x 3 diagonal blocks, (n, 3, 3): the block-Jacobi
    preconditioner and the norm of the stopping test."""
    n = a.shape[0] // 3
    return np.linalg.inv(np.stack([a[3 * i:3 * i + 3, 3 * i:3 * i + 3].toarray() for i in range(n)]))


def stopping_test(meta, a, b, v):
    """garment_sim's test (system.json, "stopping_test"): a filtered residual r
    has converged once norm2(r) <= tolerance^2 ref, norm2(r) = r^T D^-1 r with D
    the 3 x 3 diagonal blocks of A, ref the larger of S b and S w (w_i = m_i g dt)
    in that norm. Returns (norm2, ref)."""
    n = meta["vertices"]
    s = filter_matrix(v)
    dinv = diagonal_inverses(a)

    def norm2(r):
        r3 = r.reshape(n, 3)
        return float(np.einsum("ni,nij,nj->", r3, dinv, r3))

    g = np.array(meta["gravity_m_s2"]) * meta["dt_s"]
    w = s @ np.outer(np.asarray(v["mass_kg"], dtype=float), g).reshape(-1)
    return norm2, max(norm2(s @ b), norm2(w))
