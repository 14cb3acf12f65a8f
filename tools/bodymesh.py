"""Small triangle-mesh helpers shared by the body and garment tools (numpy only).

World frame of garment_sim bodies: metres, Z up, the body faces -Y, its left
hand is toward +X, feet on z = 0.
"""

import collections

import numpy as np


def load_obj_text(text):
    """Vertices (n, 3) and faces (list of index lists, 0-based) of an OBJ text."""
    verts, faces = [], []
    for line in text.splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            verts.append([float(p) for p in parts[1:4]])
        elif parts[0] == "f":
            faces.append([int(p.split("/")[0]) - 1 for p in parts[1:]])
    return np.array(verts, dtype=float), faces


def load_obj(path):
    with open(path, "r", encoding="utf-8") as f:
        return load_obj_text(f.read())


def triangulate(verts, faces):
    """Triangles of polygon faces: quads split along their shorter diagonal,
    other polygons fan-triangulated from their first corner."""
    tris = []
    for f in faces:
        if len(f) == 3:
            tris.append(list(f))
        elif len(f) == 4:
            a, b, c, d = f
            if np.linalg.norm(verts[a] - verts[c]) <= np.linalg.norm(verts[b] - verts[d]):
                tris += [[a, b, c], [a, c, d]]
            else:
                tris += [[a, b, d], [b, c, d]]
        else:
            tris += [[f[0], f[i], f[i + 1]] for i in range(1, len(f) - 1)]
    return np.array(tris, dtype=np.int64)


def load_triangles(path):
    verts, faces = load_obj(path)
    return verts, triangulate(verts, faces)


def write_obj(path, verts, tris, header_lines=()):
    with open(path, "w", encoding="utf-8") as f:
        for line in header_lines:
            f.write(f"# {line}\n")
        for v in verts:
            f.write(f"v {v[0]:.6f} {v[1]:.6f} {v[2]:.6f}\n")
        for t in tris:
            f.write(f"f {t[0] + 1} {t[1] + 1} {t[2] + 1}\n")


def mesh_report(verts, tris):
    """Closedness, degeneracy and orientation figures of a triangle mesh."""
    edge_count = collections.Counter()
    directed = collections.Counter()
    for t in tris:
        for i in range(3):
            a, b = int(t[i]), int(t[(i + 1) % 3])
            edge_count[(min(a, b), max(a, b))] += 1
            directed[(a, b)] += 1
    uses = collections.Counter(edge_count.values())
    # consistent orientation: every undirected edge used once in each direction
    inconsistent = sum(1 for (a, b), n in directed.items() if n != 1 or directed.get((b, a), 0) != 1)
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)
    # connected components over shared vertices
    parent = list(range(len(verts)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for t in tris:
        r0 = find(int(t[0]))
        for k in (1, 2):
            r = find(int(t[k]))
            if r != r0:
                parent[r] = r0
    comps = len({find(int(i)) for i in np.unique(tris)})
    used = np.zeros(len(verts), bool)
    used[tris.ravel()] = True
    return {
        "vertices": int(len(verts)),
        "triangles": int(len(tris)),
        "edges": int(len(edge_count)),
        "edges_by_face_count": {int(k): int(v) for k, v in sorted(uses.items())},
        "closed": set(uses) == {2},
        "inconsistently_oriented_directed_edges": int(inconsistent),
        "degenerate_triangles_area_below_1e-10": int((area < 1e-10).sum()),
        "min_triangle_area_m2": float(area.min()),
        "unused_vertices": int((~used).sum()),
        "connected_components": int(comps),
        "signed_volume_m3": volume,
        "euler_characteristic": int(len(verts) - len(edge_count) + len(tris)),
    }


# ---------------------------------------------------------------- slicing

def slice_loops(verts, tris, z):
    """Closed polylines (list of (k, 2) xy arrays) where the plane at height z
    cuts a closed triangle mesh. Vertices lying exactly on the plane are
    treated as slightly above it."""
    above = verts[:, 2] >= z
    ta = above[tris]
    n_above = ta.sum(axis=1)
    crossing = tris[(n_above == 1) | (n_above == 2)]
    # each crossing triangle gives one segment between two cut edges
    seg_of_edge = collections.defaultdict(list)
    points = {}
    segments = []
    for t in crossing:
        cut = []
        for i in range(3):
            a, b = int(t[i]), int(t[(i + 1) % 3])
            if above[a] != above[b]:
                key = (min(a, b), max(a, b))
                if key not in points:
                    pa, pb = verts[key[0]], verts[key[1]]
                    s = (z - pa[2]) / (pb[2] - pa[2])
                    points[key] = (pa + s * (pb - pa))[:2]
                cut.append(key)
        si = len(segments)
        segments.append(cut)
        for key in cut:
            seg_of_edge[key].append(si)
    used = [False] * len(segments)
    loops = []
    for s0 in range(len(segments)):
        if used[s0]:
            continue
        used[s0] = True
        start, cur = segments[s0]
        chain = [start, cur]
        while cur != start:
            nxt = [s for s in seg_of_edge[cur] if not used[s]]
            if not nxt:
                break
            used[nxt[0]] = True
            a, b = segments[nxt[0]]
            cur = b if a == cur else a
            chain.append(cur)
        if chain[-1] == chain[0]:
            chain.pop()
        loops.append(np.array([points[k] for k in chain]))
    return loops


def polygon_area(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def polygon_centroid(p):
    x, y = p[:, 0], p[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cr = x * yn - xn * y
    a = cr.sum() / 2.0
    return np.array([((x + xn) * cr).sum(), ((y + yn) * cr).sum()]) / (6.0 * a)


def polyline_length(p, closed=True):
    d = np.diff(np.vstack([p, p[:1]]) if closed else p, axis=0)
    return float(np.linalg.norm(d, axis=1).sum())


def convex_hull(points):
    """Counter-clockwise convex hull (Andrew's monotone chain) of 2D points."""
    pts = sorted(set(map(tuple, np.asarray(points, float))))
    if len(pts) < 3:
        return np.array(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


def point_in_polygon(pt, poly):
    x, y = pt
    xs, ys = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(xs, -1), np.roll(ys, -1)
    cond = (ys > y) != (yn > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = xs + (y - ys) * (xn - xs) / (yn - ys)
    return bool(np.count_nonzero(cond & (x < xi)) % 2)


# ---------------------------------------------------------------- body sections

def torso_loop(verts, tris, z):
    """The section loop at height z that crosses the sagittal plane x = 0
    (largest such loop), or None."""
    best = None
    for loop in slice_loops(verts, tris, z):
        if loop[:, 0].min() < 0.0 < loop[:, 0].max():
            if best is None or abs(polygon_area(loop)) > abs(polygon_area(best)):
                best = loop
    return best


def crotch_height(verts, tris, step=0.002):
    """Lowest height at which one section loop spans the sagittal plane
    (below it the two legs are separate)."""
    z = 0.2 * verts[:, 2].max()
    while torso_loop(verts, tris, z) is None:
        z += step
    lo, hi = z - step, z
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        if torso_loop(verts, tris, mid) is None:
            lo = mid
        else:
            hi = mid
    return hi


# ---------------------------------------------------------------- 3D queries

def winding_numbers(verts, tris, points):
    """Generalised winding number of each point w.r.t. a closed, outward
    oriented triangle mesh (van Oosterom–Strackee solid angles): ~1 inside,
    ~0 outside."""
    points = np.atleast_2d(points)
    out = np.empty(len(points))
    a0, b0, c0 = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    for i, p in enumerate(points):
        a, b, c = a0 - p, b0 - p, c0 - p
        la, lb, lc = (np.linalg.norm(x, axis=1) for x in (a, b, c))
        det = np.einsum("ij,ij->i", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("ij,ij->i", a, b) * lc
               + np.einsum("ij,ij->i", b, c) * la + np.einsum("ij,ij->i", c, a) * lb)
        out[i] = np.arctan2(det, den).sum() * 2.0 / (4.0 * np.pi)
    return out


def closest_points_on_triangles(p, a, b, c):
    """Closest point to p on each triangle (a, b, c arrays (m, 3)); Ericson,
    Real-Time Collision Detection 5.1.5, vectorised over triangles."""
    ab, ac, ap = b - a, c - a, p - a
    d1 = np.einsum("ij,ij->i", ab, ap)
    d2 = np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3 = np.einsum("ij,ij->i", ab, bp)
    d4 = np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5 = np.einsum("ij,ij->i", ab, cp)
    d6 = np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = 1.0 / (va + vb + vc)
        v = vb * denom
        w = vc * denom
        res = a + ab * v[:, None] + ac * w[:, None]
        # Ericson tests the regions in the order A, B, AB, C, AC, BC, interior;
        # here they are applied from the last to the first so that the earlier
        # tests win where their conditions overlap.
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        m = (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0)
        res[m] = (b + (c - b) * t_bc[:, None])[m]
        t_ac = d2 / (d2 - d6)
        m = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        res[m] = (a + ac * t_ac[:, None])[m]
    m = (d6 >= 0) & (d5 <= d6)
    res[m] = c[m]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        m = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        res[m] = (a + ab * t_ab[:, None])[m]
    m = (d3 >= 0) & (d4 <= d3)
    res[m] = b[m]
    m = (d1 <= 0) & (d2 <= 0)
    res[m] = a[m]
    return res


def distances_to_mesh(verts, tris, points):
    """Unsigned distance of each point to the triangle mesh surface."""
    a, b, c = verts[tris[:, 0]], verts[tris[:, 1]], verts[tris[:, 2]]
    out = np.empty(len(points))
    for i, p in enumerate(np.atleast_2d(points)):
        q = closest_points_on_triangles(p, a, b, c)
        out[i] = np.sqrt(((q - p) ** 2).sum(axis=1).min())
    return out
