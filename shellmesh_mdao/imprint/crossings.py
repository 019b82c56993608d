"""Where chains must share vertices: the points where one member's exact curve crosses another
member's (:func:`arc_crossings`), and where it crosses a sharp edge of the input that the skin keeps
as a feature line (:func:`arc_feature_crossings`, :func:`kept_sharp_segments`)."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core.polyline import SCAN_WORK, closest_on_polyline
from .kernels import segments_within
from ..mesh import ShellMesh, norm_rows
from .common import ranges

__all__ = ["arc_crossings", "arc_feature_crossings", "kept_sharp_segments"]


def arc_feature_crossings(arcs, surface_points, surface_tris, skin, eps):
    """Arc points lying on a sharp edge of the input surface (a trailing edge, a tip cap
    edge) where the skin has a feature line: the chain and the feature line must share a
    vertex there. Arc points are exact points of input edges, so the test is exact."""
    if not len(skin.feature_edges) or not (skin.feature_edge_ids < 0).any():
        return []
    a, b = kept_sharp_segments(surface_points, surface_tris, skin.points,
                               skin.feature_edges[skin.feature_edge_ids < 0], eps)
    if not len(a):
        return []
    out = []
    for arc in arcs:
        pts = arc.points if arc.closed else arc.points[1:-1]
        if not len(pts):
            continue
        x = _on_segments(pts, a, b, eps)
        if len(x):
            out.append(x)
    return out


def _segment_hits(q, a, b, eps):
    """Every (point, segment) pair with point ``q[i]`` within ``eps`` of segment ``a[j]-b[j]``:
    ``(i, j, t)`` with ``t`` the parameter of the closest point along the segment, in the order
    of ``i``, then ``j``. Up to :data:`SCAN_WORK` pairs a compiled loop scans them all
    (:func:`~shellmesh_mdao.imprint.kernels.segments_within`); above, a KD-tree of the segment
    midpoints lists the candidates (the same pairs: a segment within ``eps`` has its midpoint
    within half its length plus ``eps``)."""
    q = np.atleast_2d(q)
    if len(q) * len(a) <= SCAN_WORK:
        return segments_within(q, a, b - a, eps)
    tree = cKDTree(0.5 * (a + b))
    reach = 0.5 * norm_rows(b - a, axis=1).max() + eps
    cand = tree.query_ball_point(q, reach)
    cnt = np.fromiter((len(c) for c in cand), np.int64, len(cand))
    if not cnt.sum():
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    qi = np.repeat(np.arange(len(q)), cnt)
    si = np.concatenate([np.asarray(c, np.int64) for c in cand])
    ab = b[si] - a[si]
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", q[qi] - a[si], ab) / np.where(L2 > 0, L2, 1.0), 0, 1)
    d = norm_rows(a[si] + t[:, None] * ab - q[qi], axis=1)
    ok = d <= eps
    return qi[ok], si[ok], t[ok]


def kept_sharp_segments(surface_points: np.ndarray, surface_tris: np.ndarray, skin_points: np.ndarray,
                        crease_edges: np.ndarray, eps: float):
    """The pieces of the input surface's sharp edges that the skin's feature lines follow.

    Remeshing keeps a sharp line of the input as a chain of skin edges (``crease_edges``,
    their vertices exactly on the input's sharp edges) except where it drops it: the weaker of
    two creases closer than twice the chordal tolerance (a coarsely faceted leading edge's
    narrow nose strip, a wedge at a sharp trailing-edge tip) and the outlines of thin patches.
    The input's sharp edges are cut at every skin crease vertex lying on them; a stretch
    between such cuts is kept when a skin crease edge joins two skin vertices bounding that
    same stretch. Returns ``(a, b)``: the kept pieces as segments (k, 3) each. Vectorised;
    exact (no distance tolerance beyond ``eps`` for "vertex on an input edge")."""
    empty = (np.zeros((0, 3)), np.zeros((0, 3)))
    lines = ShellMesh(surface_points, surface_tris).sharp_edges()
    crease_edges = np.asarray(crease_edges, np.int64).reshape(-1, 2)
    if not len(lines) or not len(crease_edges):
        return empty
    a, b = surface_points[lines[:, 0]], surface_points[lines[:, 1]]
    sv = np.unique(crease_edges)
    qi, si, t = _segment_hits(skin_points[sv], a, b, eps)
    if not len(qi):
        return empty
    nv, ns, nq = len(surface_points), len(lines), len(qi)
    # each input sharp edge as its start, the skin vertices on it (by t), its end
    e_all = np.concatenate([np.arange(ns), si, np.arange(ns)])
    t_all = np.concatenate([np.full(ns, -1.0), t, np.full(ns, 2.0)])
    node = np.concatenate([lines[:, 0], nv + np.arange(nq), lines[:, 1]])
    o = np.lexsort((node, t_all, e_all))
    e_s, t_s, n_s = e_all[o], np.clip(t_all[o], 0.0, 1.0), node[o]
    same = np.flatnonzero(e_s[1:] == e_s[:-1])
    sa, sb, se = n_s[same], n_s[same + 1], e_s[same]
    ta, tb = t_s[same], t_s[same + 1]
    m = len(same)
    # stretches: pieces connected through input vertices (skin vertices cut the lines)
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components
    rows, cols = [], []
    for end in (sa, sb):
        real = end < nv
        rows.append(np.flatnonzero(real))
        cols.append(m + end[real])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    g = sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(m + nv, m + nv))
    _, lab = connected_components(g, directed=False)
    lab = lab[:m]
    # (stretch, skin vertex) pairs bounding each stretch
    bl, bv = [], []
    for end in (sa, sb):
        virt = end >= nv
        bl.append(lab[virt])
        bv.append(sv[qi[end[virt] - nv]])
    bl, bv = np.concatenate(bl), np.concatenate(bv)
    nsk = int(max(len(skin_points), crease_edges.max() + 1))
    pair = np.unique(bl.astype(np.int64) * nsk + bv)
    pl, pv = pair // nsk, pair % nsk
    # a stretch is kept when some skin crease edge (u, v) has both ends among its bounds
    ov = np.argsort(pv, kind="stable")
    pl_s, pv_s = pl[ov], pv[ov]
    u, v = crease_edges[:, 0], crease_edges[:, 1]
    lo, hi = np.searchsorted(pv_s, u, "left"), np.searchsorted(pv_s, u, "right")
    idx = ranges(lo, hi)
    ce = np.repeat(np.arange(len(u)), hi - lo)
    cl = pl_s[idx]
    ok = np.isin(cl * nsk + v[ce], pair)
    kept = np.zeros(int(lab.max()) + 1 if m else 0, bool)
    kept[cl[ok]] = True
    keep = kept[lab] & (tb > ta)
    ab = b - a
    return a[se[keep]] + ta[keep, None] * ab[se[keep]], a[se[keep]] + tb[keep, None] * ab[se[keep]]


def _on_segments(q, a, b, eps):
    """Points of q within eps of any segment a-b."""
    qi, _, _ = _segment_hits(q, a, b, eps)
    return q[np.unique(qi)] if len(qi) else np.zeros((0, 3))


def arc_crossings(chains, arcs, eps, pairs: list | None = None):
    """Points where arc i crosses the plane of chain j and lies on arc j (within eps), one array
    per such pair (i, j); ``pairs``, when given, receives the pairs in the same order. A pair
    whose arc i lies, bounding box and all, farther than ``2 eps`` on one side of plane j is
    skipped unread: none of its points is within ``eps`` of the plane nor on its other side
    (the rounding of the plane distances is some 1e-16 of the model, eps 1e-9 of it)."""
    out = []
    if not chains:
        return out
    pc = np.array([np.asarray(c.plane.point, float) for c in chains])
    pn = np.array([np.asarray(c.plane.normal, float) for c in chains])
    for i, (ci, ai) in enumerate(zip(chains, arcs)):
        p = np.vstack([ai.points, ai.points[:1]]) if ai.closed else ai.points
        lo, hi = (p.min(0) - pc) * pn, (p.max(0) - pc) * pn
        apart = (np.minimum(lo, hi).sum(1) > 2 * eps) | (np.maximum(lo, hi).sum(1) < -2 * eps)
        for j in np.flatnonzero(~apart).tolist():
            cj, aj = chains[j], arcs[j]
            if i == j or cj.member == ci.member:
                continue
            s = cj.plane.side(p)
            k = np.flatnonzero((s[:-1] > eps) & (s[1:] < -eps) | (s[:-1] < -eps) & (s[1:] > eps)
                               | (np.abs(s[:-1]) <= eps))
            if not len(k):
                continue
            t = np.where(np.abs(s[k]) <= eps, 0.0, s[k] / (s[k] - s[k + 1]))
            x = p[k] + t[:, None] * (p[k + 1] - p[k])
            on = norm_rows(closest_on_polyline(x, aj.points, aj.closed) - x, axis=1) <= eps
            if on.any():
                out.append(x[on])
                if pairs is not None:
                    pairs.append((i, j))
    return out
