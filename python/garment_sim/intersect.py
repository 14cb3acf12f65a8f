"""Self-intersections of a triangle mesh, by brute force in NumPy.

Independent of the simulator's contact code: every pair of triangles that
share no vertex is tested (boxes first, all pairs, in chunks), then exactly:
a pair intersects when an edge of either triangle crosses the other triangle,
by the signs of orientation determinants (signed volumes). Touching at a
point or along a line (a zero determinant) does not count.
"""

from __future__ import annotations

import numpy as np


def _orient(a, b, c, d):
    """Signed volume (×6) of the tetrahedra (a, b, c, d), row by row."""
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a)


def _segment_crosses(p, q, a, b, c):
    """Whether segment pq crosses the inside of triangle abc, row by row."""
    s1 = np.sign(_orient(a, b, c, p))
    s2 = np.sign(_orient(a, b, c, q))
    t1 = np.sign(_orient(p, q, a, b))
    t2 = np.sign(_orient(p, q, b, c))
    t3 = np.sign(_orient(p, q, c, a))
    return (s1 * s2 < 0) & (t1 != 0) & (t1 == t2) & (t2 == t3)


def intersecting_pairs(positions, faces, chunk: int = 512) -> np.ndarray:
    """The pairs (i, j), i < j, of triangles sharing no vertex that intersect."""
    x = np.asarray(positions, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    tri = x[f]  # (m, 3, 3)
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    m = len(f)
    found = []
    for s in range(0, m, chunk):
        e = min(s + chunk, m)
        # boxes of rows s..e against every later triangle
        ov = np.all((lo[s:e, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[s:e, None, :]),
                    axis=2)
        i, j = np.nonzero(ov)
        i = i + s
        keep = j > i
        i, j = i[keep], j[keep]
        shared = (f[i][:, :, None] == f[j][:, None, :]).any(axis=(1, 2))
        i, j = i[~shared], j[~shared]
        if len(i) == 0:
            continue
        hit = np.zeros(len(i), dtype=bool)
        for (u, v) in ((0, 1), (1, 2), (2, 0)):
            a, b, c = tri[j, 0], tri[j, 1], tri[j, 2]
            hit |= _segment_crosses(tri[i, u], tri[i, v], a, b, c)
            a, b, c = tri[i, 0], tri[i, 1], tri[i, 2]
            hit |= _segment_crosses(tri[j, u], tri[j, v], a, b, c)
        found.append(np.stack([i[hit], j[hit]], axis=1))
    return np.concatenate(found) if found else np.zeros((0, 2), dtype=np.int64)


def self_intersections(positions, faces) -> int:
    """How many pairs of triangles sharing no vertex intersect."""
    return len(intersecting_pairs(positions, faces))
