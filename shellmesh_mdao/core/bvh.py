"""Compiled kernels of the closest-point queries on the input skin: exact closest points on triangles and the
bounding-volume hierarchy (:class:`TriangleBVH`) behind :class:`~shellmesh_mdao.core.locator.SurfaceLocator`, which
the projection, the remesh, the imprint and the node supports all query.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .threads import Background
from .kernels import clip01, dot3, sq_dist

__all__ = ["closest_on_triangles", "bvh_closest", "TriangleBVH"]


@njit(cache=True, nogil=True, inline="always")
def _on_segment(p0, p1, p2, s0, s1, s2, e0, e1, e2):
    """Closest point of the segment s-e to ``p``: ``s + clip(t, 0, 1) (e - s)``, t = 0 on a
    zero-length segment."""
    d0, d1, d2 = e0 - s0, e1 - s1, e2 - s2
    L2 = dot3(d0, d1, d2, d0, d1, d2)
    t = 0.0
    if L2 > 0:
        t = dot3(p0 - s0, p1 - s1, p2 - s2, d0, d1, d2) / L2
    t = clip01(t)
    return s0 + t * d0, s1 + t * d1, s2 + t * d2


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _closest_on_triangle(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """Closest point of triangle (a, b, c) to p: Ericson's regions (the vertices, the edges
    ab, ac, bc, the interior); a zero-area triangle goes to the nearest of its edges."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    d1 = dot3(ab0, ab1, ab2, ap0, ap1, ap2)
    d2 = dot3(ac0, ac1, ac2, ap0, ap1, ap2)
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    d3 = dot3(ab0, ab1, ab2, bp0, bp1, bp2)
    d4 = dot3(ac0, ac1, ac2, bp0, bp1, bp2)
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d5 = dot3(ab0, ab1, ab2, cp0, cp1, cp2)
    d6 = dot3(ac0, ac1, ac2, cp0, cp1, cp2)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    if d1 <= 0 and d2 <= 0:                                   # vertex a
        return a0, a1, a2
    if d3 >= 0 and d4 <= d3:                                  # vertex b
        return b0, b1, b2
    if d6 >= 0 and d5 <= d6:                                  # vertex c
        return c0, c1, c2
    # an edge of zero length (a repeated corner: its denominator is |e|^2 = 0) is no region
    # of its own; the numpy version returned 0 / 0 = NaN there, the next region answers here
    if vc <= 0 and d1 >= 0 and d3 <= 0 and d1 - d3 != 0:     # edge ab
        v = d1 / (d1 - d3)
        return a0 + v * ab0, a1 + v * ab1, a2 + v * ab2
    if vb <= 0 and d2 >= 0 and d6 <= 0 and d2 - d6 != 0:     # edge ac
        w = d2 / (d2 - d6)
        return a0 + w * ac0, a1 + w * ac1, a2 + w * ac2
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0 and (d4 - d3) + (d5 - d6) != 0:   # edge bc
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b0 + w * (c0 - b0), b1 + w * (c1 - b1), b2 + w * (c2 - b2)
    den = va + vb + vc
    vv = vb / den
    ww = vc / den
    x0 = (a0 + vv * ab0) + ww * ac0
    x1 = (a1 + vv * ab1) + ww * ac1
    x2 = (a2 + vv * ab2) + ww * ac2
    if np.isfinite(x0) and np.isfinite(x1) and np.isfinite(x2):
        return x0, x1, x2
    # a zero-area triangle: the nearest of its three edges (the first on a tie; a NaN
    # distance wins, as np.argmin picks the first NaN)
    qa0, qa1, qa2 = _on_segment(p0, p1, p2, a0, a1, a2, b0, b1, b2)
    qb0, qb1, qb2 = _on_segment(p0, p1, p2, b0, b1, b2, c0, c1, c2)
    qc0, qc1, qc2 = _on_segment(p0, p1, p2, c0, c1, c2, a0, a1, a2)
    da = dot3(qa0 - p0, qa1 - p1, qa2 - p2, qa0 - p0, qa1 - p1, qa2 - p2)
    if da != da:
        return qa0, qa1, qa2
    db = dot3(qb0 - p0, qb1 - p1, qb2 - p2, qb0 - p0, qb1 - p1, qb2 - p2)
    if db != db:
        return qb0, qb1, qb2
    dc = dot3(qc0 - p0, qc1 - p1, qc2 - p2, qc0 - p0, qc1 - p1, qc2 - p2)
    if dc != dc:
        return qc0, qc1, qc2
    if db < da:
        if dc < db:
            return qc0, qc1, qc2
        return qb0, qb1, qb2
    if dc < da:
        return qc0, qc1, qc2
    return qa0, qa1, qa2


@njit(cache=True, nogil=True, error_model="numpy")
def _closest_on_triangles(P, A, B, C):
    k = P.shape[0]
    out = np.empty((k, 3))
    for i in range(k):
        p, a, b, c = P[i], A[i], B[i], C[i]
        out[i, 0], out[i, 1], out[i, 2] = _closest_on_triangle(p[0], p[1], p[2], a[0], a[1], a[2], b[0], b[1],
                                                               b[2], c[0], c[1], c[2])
    return out


def closest_on_triangles(p, a, b, c):
    """Closest point of triangle ``(a[i], b[i], c[i])`` to ``p[i]`` (all (k, 3)): the same bits
    as the numpy version of :func:`shellmesh_mdao.core.locator.closest_point_on_triangles` (Ericson's
    regions in the same order, numpy's sums of three products, the degenerate fallback onto
    the nearest edge), one pass per point, except where that version returned NaN: an edge of
    zero length is skipped as a region, so a triangle with a repeated corner gets the closest
    point of its other edges."""
    p, a, b, c = (np.ascontiguousarray(x, dtype=np.float64) for x in np.broadcast_arrays(
        *(np.asarray(x, dtype=np.float64) for x in (p, a, b, c))))
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError("closest_on_triangles takes (k, 3) arrays")
    return _closest_on_triangles(p, a, b, c)


# ============================================================================ closest points on a surface
@njit(cache=True, nogil=True)
def _bvh_build(tlo, thi, leaf):
    """Bounding-volume hierarchy over triangles with boxes ``tlo``/``thi`` (t, 3): a node
    holding more than ``leaf`` triangles is split at the median of their box centres along
    the longest extent of those centres (a stable sort: ties keep their order). Returns the
    triangle order ``perm``, the node boxes (m, 6) (lo, hi), the first child of each node
    (-1 for a leaf; the second is the next node) and each node's range of ``perm``."""
    nt = tlo.shape[0]
    perm = np.arange(nt)
    maxn = 2 * nt + 1
    box = np.empty((maxn, 6))
    child = np.full(maxn, -1, np.int64)
    start = np.zeros(maxn, np.int64)
    cnt = np.zeros(maxn, np.int64)
    visit = np.empty(maxn, np.int64)
    stack = np.empty(256, np.int64)
    key = np.empty(nt)
    tmp = np.empty(nt, np.int64)
    cnt[0] = nt
    m, sp, nv = 1, 1, 0
    stack[0] = 0
    while sp:
        sp -= 1
        nd = stack[sp]
        visit[nv] = nd
        nv += 1
        s, c = start[nd], cnt[nd]
        if c <= leaf:
            continue
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for j in range(s, s + c):
            t = perm[j]
            for k in range(3):
                x = 0.5 * (tlo[t, k] + thi[t, k])
                lo[k] = min(lo[k], x)
                hi[k] = max(hi[k], x)
        ax = 0
        for k in (1, 2):
            if hi[k] - lo[k] > hi[ax] - lo[ax]:
                ax = k
        for j in range(c):
            t = perm[s + j]
            key[j] = 0.5 * (tlo[t, ax] + thi[t, ax])
        o = np.argsort(key[:c], kind="mergesort")
        for j in range(c):
            tmp[j] = perm[s + o[j]]
        perm[s:s + c] = tmp[:c]
        half = c // 2
        child[nd] = m
        start[m], cnt[m] = s, half
        start[m + 1], cnt[m + 1] = s + half, c - half
        stack[sp], stack[sp + 1] = m, m + 1
        sp += 2
        m += 2
    for i in range(nv - 1, -1, -1):               # children before their parents
        nd = visit[i]
        c = child[nd]
        for k in range(3):
            if c < 0:
                lo_k, hi_k = np.inf, -np.inf
                for j in range(start[nd], start[nd] + cnt[nd]):
                    lo_k = min(lo_k, tlo[perm[j], k])
                    hi_k = max(hi_k, thi[perm[j], k])
            else:
                lo_k = min(box[c, k], box[c + 1, k])
                hi_k = max(box[c, 3 + k], box[c + 1, 3 + k])
            box[nd, k], box[nd, 3 + k] = lo_k, hi_k
    return perm, box[:m].copy(), child[:m].copy(), start[:m].copy(), cnt[:m].copy()


@njit(cache=True, nogil=True, inline="always")
def _box_sq_dist(p0, p1, p2, B, i):
    e0 = B[i, 0] - p0 if p0 < B[i, 0] else (p0 - B[i, 3] if p0 > B[i, 3] else 0.0)
    e1 = B[i, 1] - p1 if p1 < B[i, 1] else (p1 - B[i, 4] if p1 > B[i, 4] else 0.0)
    e2 = B[i, 2] - p2 if p2 < B[i, 2] else (p2 - B[i, 5] if p2 > B[i, 5] else 0.0)
    return (e0 * e0 + e1 * e1) + e2 * e2


@njit(cache=True, nogil=True, inline="always")
def _box_centre_sq_dist(p0, p1, p2, B, i):
    return sq_dist(0.5 * (B[i, 0] + B[i, 3]), 0.5 * (B[i, 1] + B[i, 4]), 0.5 * (B[i, 2] + B[i, 5]), p0, p1, p2)


@njit(cache=True, nogil=True, error_model="numpy")
def bvh_closest(Q, lo, hi, V, TB, tri_id, NB, child, start, cnt, slack, out, oid, seed):
    """Rows ``lo .. hi - 1`` of ``out`` / ``oid``: the closest point of the triangles to Q[i]
    and its triangle. Depth first, the nearer child first (by box distance, then by the
    distance to the box centre); a box or a triangle's own box farther than the best
    squared distance so far (times ``1 + 1e-12``, plus ``slack``) is skipped, so every
    triangle that can tie with the answer is computed and the rule picks among them: the
    least squared distance, then the lowest triangle id.

    ``seed`` (empty, or one entry per row of Q): the leaf-order position of a triangle to
    compute first (-1: none), e.g. the one a moved point was closest to before. It only sets
    the first bound, which prunes more of the tree; the answer is the rule's all the same
    (the answer's own distance never exceeds a bound, so it and every triangle that can tie
    with it are still computed)."""
    stack = np.empty(256, np.int64)
    sd = np.empty(256)
    none = np.iinfo(np.int64).max
    seeded = seed.shape[0] > 0
    for i in range(lo, hi):
        p0, p1, p2 = Q[i, 0], Q[i, 1], Q[i, 2]
        best, lim, bid = np.inf, np.inf, none
        x0 = x1 = x2 = np.nan
        if seeded and seed[i] >= 0:
            t = seed[i]
            x0, x1, x2 = _closest_on_triangle(p0, p1, p2, V[t, 0], V[t, 1], V[t, 2], V[t, 3], V[t, 4], V[t, 5],
                                              V[t, 6], V[t, 7], V[t, 8])
            best, bid = sq_dist(x0, x1, x2, p0, p1, p2), tri_id[t]
            lim = best * (1.0 + 1e-12) + slack
        stack[0], sd[0], sp = 0, 0.0, 1
        while sp:
            sp -= 1
            if sd[sp] > lim:
                continue
            nd = stack[sp]
            c = child[nd]
            if c < 0:
                for t in range(start[nd], start[nd] + cnt[nd]):
                    if _box_sq_dist(p0, p1, p2, TB, t) > lim:
                        continue
                    y0, y1, y2 = _closest_on_triangle(p0, p1, p2, V[t, 0], V[t, 1], V[t, 2], V[t, 3], V[t, 4],
                                                      V[t, 5], V[t, 6], V[t, 7], V[t, 8])
                    d = sq_dist(y0, y1, y2, p0, p1, p2)
                    if d < best or (d == best and tri_id[t] < bid):
                        best, bid = d, tri_id[t]
                        x0, x1, x2 = y0, y1, y2
                        lim = best * (1.0 + 1e-12) + slack
                continue
            dl = _box_sq_dist(p0, p1, p2, NB, c)
            dr = _box_sq_dist(p0, p1, p2, NB, c + 1)
            left_first = dl < dr
            if dl == dr:
                left_first = _box_centre_sq_dist(p0, p1, p2, NB, c) <= _box_centre_sq_dist(p0, p1, p2, NB, c + 1)
            # push the farther child first: the nearer one is taken next
            if left_first:
                if dr <= lim:
                    stack[sp], sd[sp], sp = c + 1, dr, sp + 1
                if dl <= lim:
                    stack[sp], sd[sp], sp = c, dl, sp + 1
            else:
                if dl <= lim:
                    stack[sp], sd[sp], sp = c, dl, sp + 1
                if dr <= lim:
                    stack[sp], sd[sp], sp = c + 1, dr, sp + 1
        out[i, 0], out[i, 1], out[i, 2] = x0, x1, x2
        oid[i] = bid


class TriangleBVH:
    """Exact closest points on a fixed set of triangles (float64), for many query points.

    Built once (:func:`_bvh_build`, leaves of up to ``leaf`` triangles; 23.5k triangles in
    about 10 ms); each query descends the tree nearer child first and skips every box
    farther than the best distance found so far. The answer is the closest point of
    :func:`closest_on_triangles`'s formula on the triangle whose squared distance (numpy's
    row-norm sum) is least, the lowest triangle index on a tie: it does not depend on the
    tree's layout, the order of the queries or the number of threads answering them.

    ``points`` (n, 3) float64, ``triangles`` (t, 3) int64 with indices in range (checked by
    the caller, :class:`shellmesh_mdao.core.locator.SurfaceLocator`)."""

    LEAF = 8
    #: fewest queries a thread of :meth:`closest` takes: two threads already pay from about
    #: 600 queries on the 23.5k-triangle cessna210 (1,000 queries 0.94 -> 0.63 ms; a thread
    #: costs some 0.05 ms to start)
    MIN_BLOCK = 512

    def __init__(self, points, triangles, leaf: int = LEAF):
        P = np.ascontiguousarray(points, dtype=np.float64)
        T = np.ascontiguousarray(triangles, dtype=np.int64)
        A, B, C = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
        tlo = np.minimum(np.minimum(A, B), C)
        thi = np.maximum(np.maximum(A, B), C)
        perm, self._box, self._child, self._start, self._cnt = _bvh_build(tlo, thi, int(leaf))
        self._tri_id = perm
        self._pos = np.empty(len(perm), np.int64)                 # leaf-order position of each triangle
        self._pos[perm] = np.arange(len(perm))
        self._V = np.ascontiguousarray(np.hstack([A[perm], B[perm], C[perm]]))      # corners in leaf order
        self._TB = np.ascontiguousarray(np.hstack([tlo[perm], thi[perm]]))
        ext = float(np.abs(P).max()) if len(P) else 0.0
        # coordinates round at about 1e-16 of their magnitude: boxes and closest points that
        # far apart still count as touching
        self._slack = (1e-12 * ext) ** 2

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self._box, self._child, self._start, self._cnt, self._tri_id, self._pos,
                                      self._V, self._TB))

    def closest(self, q, threads: int = 1, hint=None):
        """``(points (k, 3), triangle (k,))`` for queries ``q`` (k, 3) float64 (finite: checked
        by the caller); with ``threads`` > 1, contiguous blocks of at least :attr:`MIN_BLOCK`
        queries are answered in up to that many threads (the kernel releases the GIL). ``hint`` (k,): a
        triangle near each query to try first (-1 or out of range: none), e.g. the one a point
        that has since moved a little was closest to; it saves a part of the search and does
        not change the answer."""
        q = np.ascontiguousarray(q, dtype=np.float64)
        k = len(q)
        out = np.empty((k, 3))
        oid = np.empty(k, np.int64)
        seed = np.empty(0, np.int64)
        if hint is not None:
            hint = np.asarray(hint, dtype=np.int64).reshape(-1)
            if len(hint) != k:
                raise ValueError(f"TriangleBVH.closest: hint needs one entry per query, got {len(hint)} for {k}")
            ok = (hint >= 0) & (hint < len(self._pos))
            seed = np.where(ok, self._pos[np.where(ok, hint, 0)], -1)
        args = (self._V, self._TB, self._tri_id, self._box, self._child, self._start, self._cnt, self._slack,
                out, oid, seed)
        nt = max(1, min(int(threads), k // self.MIN_BLOCK))
        cuts = np.linspace(0, k, nt + 1).astype(np.int64)
        workers = [Background(bvh_closest, q, int(cuts[j]), int(cuts[j + 1]), *args) for j in range(1, nt)]
        bvh_closest(q, int(cuts[0]), int(cuts[1]), *args)
        for w in workers:
            w.result()
        return out, oid
