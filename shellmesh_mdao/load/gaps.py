"""Open gaps closed by strips of triangles: an open blunt trailing edge (CAD that leaves out the
trailing-edge face) is two long, nearly parallel open boundary curves a small distance apart,
joined at their ends (or, in a half model, ending on the symmetry plane). :func:`gap_closures`
finds such gaps and closes each by a strip of triangles zipped between its two sides.

A gap is closed only when it is clearly one: its two sides are at least :data:`GAP_MIN_ASPECT`
times longer than it is wide, its width is at most :data:`GAP_MAX_WIDTH` of the diagonal (and
more than the plane tolerance: narrower is a crack of unmerged vertices), the width changes
slowly along it (at most :data:`GAP_MAX_TAPER` per unit length: the sides within about 3
degrees of parallel; its greatest width at most :data:`GAP_MAX_WIDTH_RATIO` times its smallest,
away from its ends) and the strip does not fold. (An airfoil section, a hole or an open tip
fails these: its width grows from nothing at its ends.) Anything else (a hole, an open tip, a missing
panel) is left open for :func:`~shellmesh_mdao.load.repair.repair_defects` to refuse."""
from __future__ import annotations

import numpy as np

from ..mesh import ShellMesh

__all__ = ["GAP_MAX_WIDTH", "GAP_MIN_ASPECT", "GAP_MAX_TAPER", "GAP_MAX_WIDTH_RATIO", "gap_closures", "gap_text"]

#: Widest gap closed by a strip, as a fraction of the bounding-box diagonal.
GAP_MAX_WIDTH = 0.01
#: A gap's sides must be at least this many times longer than its greatest width.
GAP_MIN_ASPECT = 10.0
#: Largest change of a gap's width per unit length along it (0.05: sides within ~3 degrees of parallel).
GAP_MAX_TAPER = 0.05
#: Largest ratio of a gap's greatest to its smallest width (away from its ends).
GAP_MAX_WIDTH_RATIO = 4.0


def _boundary_next(mesh: ShellMesh):
    """The boundary half-edges (from, to) of a consistently oriented mesh and ``nxt``: the
    vertex after each boundary vertex (``-1`` elsewhere), or ``None`` when a vertex has two
    outgoing boundary half-edges (two sheets touching at a vertex)."""
    t = mesh.topology()
    b = t.valence[t.he_edge] == 1
    frm, to = t.he_from[b], t.he_to[b]
    if len(np.unique(frm)) != len(frm):
        return frm, to, None
    nxt = np.full(mesh.n_points, -1, np.int64)
    nxt[frm] = to
    return frm, to, nxt


def _plane_candidate(P, frm, to, tol):
    """``(axis, value)`` of the coordinate plane holding the longest part of the open boundary
    (edges with both ends within ``tol`` of it), or ``None``."""
    best = None
    length = np.linalg.norm(P[to] - P[frm], axis=1)
    for ax in range(3):
        a, b = P[frm, ax], P[to, ax]
        flat = np.flatnonzero(np.abs(a - b) <= tol)
        if not len(flat):
            continue
        o = flat[np.argsort(a[flat], kind="stable")]
        split = np.flatnonzero(np.diff(a[o]) > tol) + 1
        for grp in np.split(o, split):
            L = float(length[grp].sum())
            if best is None or L > best[0]:
                best = (L, ax, float(np.median(a[grp])))
    return None if best is None else (best[1], best[2])


def _chains(frm, nxt, on):
    """Chains of the open boundary off the plane: paths that leave the plane at a vertex and
    come back to it (``on`` marks the vertices in the plane), then loops that never touch it.
    Returns a list of vertex arrays (a loop repeats its first vertex at the end)."""
    off = ~(on[frm] & on[nxt[frm]])               # half-edges not lying in the plane
    todo = set(frm[off].tolist())
    chains = []
    for s in frm[off & on[frm]].tolist():         # paths from the plane back to it
        c = [s]
        v = int(nxt[s])
        while not on[v]:
            todo.discard(c[-1])
            c.append(v)
            v = int(nxt[v])
            if len(c) > len(frm):
                return None
        todo.discard(c[-1])
        c.append(v)
        chains.append(np.array(c, np.int64))
    while todo:                                    # loops off the plane
        s = min(todo)
        c = [s]
        v = int(nxt[s])
        while v != s:
            if v not in todo:
                return None
            todo.discard(v)
            c.append(v)
            v = int(nxt[v])
        todo.discard(s)
        c.append(s)
        chains.append(np.array(c, np.int64))
    return chains


def _point_polyline_distance(q, poly):
    """Distance of every point of ``q`` (k, 3) to the polyline ``poly`` (m, 3)."""
    return point_segment_distance(q, poly[:-1], poly[1:])


def point_segment_distance(q, a, b):
    """Distance of every point of ``q`` (k, 3) to the nearest of the segments ``a[i]``-``b[i]``."""
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    out = np.empty(len(q))
    step = max(1, 200_000 // max(len(a), 1))          # about 5 MB per block
    for s in range(0, len(q), step):
        d = q[s:s + step, None, :] - a[None]
        t = np.clip(np.divide(np.einsum("kij,ij->ki", d, ab), L2, out=np.zeros((len(d), len(a))),
                              where=L2 > 0), 0.0, 1.0)
        r = d - t[..., None] * ab[None]
        out[s:s + step] = np.sqrt(np.einsum("kij,kij->ki", r, r).min(1))
    return out


def _zip(P, Q, closed, diag, tol):
    """The strip of triangles closing the gap ``Q`` (boundary vertices in boundary order; a
    loop repeats its first vertex), or ``None`` when ``Q`` is not a gap. Returns
    ``(triangles, info)``."""
    n = len(Q) - 1
    if n < 2 or n > 20000:
        return None
    X = P[Q]
    if closed:                   # start at one end of the loop's longest extent
        far = int(np.argmax(np.linalg.norm(X[:-1] - X[0], axis=1)))
        Q = np.concatenate([Q[far:-1], Q[:far + 1]])
        X = P[Q]
        k = int(np.argmax(np.linalg.norm(X[:-1] - X[0], axis=1)))
    else:                        # the far end from the two ends in the plane
        k = int(np.argmax(np.linalg.norm(X - 0.5 * (X[0] + X[-1]), axis=1)))
    if k <= 0 or k >= n:
        return None
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(X, axis=0), axis=1))])
    L1, L2 = s[k], s[n] - s[k]
    if min(L1, L2) <= 0:
        return None
    side1, side2 = X[:k + 1], X[k:]
    probe = side1[np.linspace(0, k, min(k + 1, 17)).astype(np.int64)[1:-1]]
    if len(probe) and _point_polyline_distance(probe, side2).max() > min(GAP_MAX_WIDTH * diag,
                                                                          min(L1, L2) / GAP_MIN_ASPECT):
        return None              # cheap early refusal of wide openings
    # widths: each side's vertices to the other side, away from the turns
    w1 = _point_polyline_distance(side1, side2)
    w2 = _point_polyline_distance(side2, side1)
    turns = [s[k]] + ([0.0, s[n]] if closed else [])
    dt = np.min(np.abs(s[:, None] - np.asarray(turns)[None]), axis=1)
    w = np.concatenate([w1, w2[1:]])
    wmed = float(np.median(w[w > 0])) if (w > 0).any() else 0.0
    body = dt > 3.0 * wmed
    if not closed:
        body[[0, n]] = True
    if body.sum() < 2:
        return None
    wb = w[body]
    wmax, wmin = float(wb.max()), float(wb.min())
    if wmax <= tol or wmax > GAP_MAX_WIDTH * diag or min(L1, L2) < GAP_MIN_ASPECT * wmax \
            or wmax > GAP_MAX_WIDTH_RATIO * wmin:
        return None
    for ws, ss, m in ((w1, s[:k + 1], body[:k + 1]), (w2[::-1], s[n] - s[k:][::-1], body[k:][::-1])):
        ws, ss = ws[m], ss[m]
        if len(ws) > 1 and (np.abs(np.diff(ws)) > GAP_MAX_TAPER * np.diff(ss) + tol).any():
            return None
    # the zipper: advance along the side that has used the smaller fraction of its length
    tris = []
    if closed:
        tris.append((Q[1], Q[0], Q[n - 1]))
        i, j = 1, n - 1
    else:
        i, j = 0, n
    while j - i > 1:
        if i < k and (j <= k or (s[i + 1] / L1) <= (s[n] - s[j - 1]) / L2):
            tris.append((Q[i + 1], Q[i], Q[j]))
            i += 1
        else:
            tris.append((Q[j], Q[j - 1], Q[i]))
            j -= 1
    T = np.array(tris, np.int64)
    nrm = np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]])
    mean = nrm.sum(0)
    ln = np.linalg.norm(nrm, axis=1)
    if not np.linalg.norm(mean) > 0 or (ln <= 0).any():
        return None
    if ((nrm @ (mean / np.linalg.norm(mean))) < 0.5 * ln).any():
        return None              # the strip folds: not two nearly parallel sides
    a = 0.5 * (X[0] + X[n]) if not closed else X[0]
    info = {"n_triangles": len(T), "length": float(0.5 * (L1 + L2)), "width_min": wmin, "width_max": wmax,
            "start": [float(v) for v in a], "end": [float(v) for v in X[k]],
            "area": float(0.5 * ln.sum())}
    return T, info


def gap_closures(mesh: ShellMesh, tol: float):
    """Candidate closures of the open gaps of a consistently oriented ``mesh``: yields
    ``(mesh, gaps)`` with every open-boundary chain off a candidate symmetry plane (the
    coordinate plane holding most of the open boundary, then none) closed by a strip of
    triangles; ``gaps`` describes each strip (``n_triangles``, ``length``, ``width_min``,
    ``width_max``, ``start``, ``end``, ``area``). A candidate is yielded only when every
    chain off the plane is a gap (see the module text); the caller checks that what stays
    open is a valid half model. New faces take the component of the face along the gap's
    first edge."""
    frm, to, nxt = _boundary_next(mesh)
    if nxt is None or not len(frm):
        return
    P = mesh.points
    diag = mesh.diagonal
    cand = _plane_candidate(P, frm, to, tol)
    planes = ([cand] if cand is not None else []) + [None]
    for plane in planes:
        on = np.zeros(mesh.n_points, bool)
        if plane is not None:
            ax, val = plane
            on[frm] = np.abs(P[frm, ax] - val) <= tol
        chains = _chains(frm, nxt, on)
        if not chains:
            continue
        strips, gaps = [], []
        for c in chains:
            z = _zip(P, c, bool(c[0] == c[-1]), diag, tol)
            if z is None:
                break
            strips.append(z[0])
            gaps.append(z[1])
        else:
            T = np.vstack(strips)
            t = mesh.topology()
            eid = t.edge_ids(T[:, :2])               # the first edge of each strip triangle is a gap edge
            comp = np.full(len(T), mesh.component[0] if mesh.n_faces else 0, np.int32)
            hit = eid >= 0
            comp[hit] = mesh.component[t.edge_faces[t.edge_faces_ptr[eid[hit]]]]
            F = np.vstack([mesh.faces, np.hstack([T, np.full((len(T), 1), -1, np.int64)])])
            out = ShellMesh(P, F, np.concatenate([mesh.component, comp]), list(mesh.component_names))
            yield out, gaps


def gap_text(g: dict) -> str:
    """'80.7 long, 0.34 to 0.43 wide, from (x, y, z) to (x, y, z)' for a gap of :func:`gap_closures`."""
    def pt(p):
        return "(" + ", ".join(f"{v:.6g}" for v in p) + ")"
    wide = (f"{g['width_max']:.3g}" if g["width_max"] <= 1.05 * g["width_min"]
            else f"{g['width_min']:.3g} to {g['width_max']:.3g}")
    return f"{g['length']:.4g} long, {wide} wide, from {pt(g['start'])} to {pt(g['end'])}"
