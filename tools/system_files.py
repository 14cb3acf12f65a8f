"""Reading what `garment_sim drape --write-system STEP` writes (docs/drape.md).

    meta, a, b, v = load(pathlib.Path("out/system-60"))

`meta` is system.json, `a` the matrix (SciPy CSR, 3n x 3n), `b` the right-hand side,
`v` vertices.csv as a numpy record array; `vec(v, "dv")` gives a column triple as one
3n vector (vertex i's coordinate c at 3i + c).
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
