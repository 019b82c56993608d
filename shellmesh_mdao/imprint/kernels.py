"""Compiled kernels of the imprint stage: (point, segment) pairs within a distance, the skin flips' and the
smoothing stars' tests and independent sets, corner cosines, nearest triangle centroids.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from ..core.kernels import on_segment_ab
from ..core.kernels import check_index, cross3, dot3e, edge_id, norm3

__all__ = ["centroid_d2", "segments_within", "skin_flips", "star_independent", "star_moves", "corner_cosines"]


# ============================================================================ nearest centroids
@njit(cache=True, nogil=True)
def _centroid_d2(P, T, x0, x1, x2):
    m = T.shape[0]
    out = np.empty(m)
    for t in range(m):
        i, j, k = T[t, 0], T[t, 1], T[t, 2]
        c0 = (P[i, 0] + P[j, 0] + P[k, 0]) / 3 - x0
        c1 = (P[i, 1] + P[j, 1] + P[k, 1]) / 3 - x1
        c2 = (P[i, 2] + P[j, 2] + P[k, 2]) / 3 - x2
        out[t] = (c0 * c0 + c1 * c1) + c2 * c2
    return out


def centroid_d2(P, T, x):
    """(m,) squared distance from the point ``x`` to each triangle's centroid ``(a + b + c) / 3``,
    numpy's arithmetic (``reduce_short((cen - x) ** 2, "sum")``, the same bits) without gathering
    the corners."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    T = np.ascontiguousarray(np.asarray(T)[:, :3], dtype=np.int64)
    x = np.asarray(x, dtype=np.float64).reshape(3)
    check_index("T", T, len(P))
    return _centroid_d2(P, T, float(x[0]), float(x[1]), float(x[2]))


@njit(cache=True, nogil=True)
def _segments_within(q, a, ab, eps):
    m, s = q.shape[0], a.shape[0]
    cap = max(16, 4 * m)
    qi = np.empty(cap, np.int64)
    si = np.empty(cap, np.int64)
    tt = np.empty(cap, np.float64)
    # each segment's box grown by eps and a slack far above the rounding of its closest points:
    # a point outside it is farther than eps from the segment in the formula's arithmetic too
    box = np.empty((s, 6))
    for j in range(s):
        sl = eps + 1e-9 * (abs(a[j, 0]) + abs(a[j, 1]) + abs(a[j, 2]) + abs(ab[j, 0]) + abs(ab[j, 1])
                           + abs(ab[j, 2]) + eps)
        for d in range(3):
            e = a[j, d] + ab[j, d]
            box[j, d] = min(a[j, d], e) - sl
            box[j, 3 + d] = max(a[j, d], e) + sl
    k = 0
    for i in range(m):
        q0, q1, q2 = q[i, 0], q[i, 1], q[i, 2]
        for j in range(s):
            if (q0 < box[j, 0] or q0 > box[j, 3] or q1 < box[j, 1] or q1 > box[j, 4] or q2 < box[j, 2]
                    or q2 > box[j, 5]):
                continue
            t, _, _, _, d = on_segment_ab(q0, q1, q2, a, ab, j)
            if d <= eps:
                if k == cap:
                    cap *= 2
                    qi2 = np.empty(cap, np.int64)
                    si2 = np.empty(cap, np.int64)
                    tt2 = np.empty(cap, np.float64)
                    qi2[:k], si2[:k], tt2[:k] = qi[:k], si[:k], tt[:k]
                    qi, si, tt = qi2, si2, tt2
                qi[k], si[k], tt[k] = i, j, t
                k += 1
    return qi[:k], si[:k], tt[:k]


def segments_within(q, a, ab, eps):
    """Every (point, segment) pair with ``q[i]`` within ``eps`` of the segment ``a[j] + t ab[j]``,
    ``t`` in [0, 1]: ``(i, j, t)`` in the order of ``i``, then ``j``, with the closest point's
    ``t`` and distance in numpy's arithmetic (einsum's dot products, ``np.clip``, row norms),
    scanning every pair."""
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 3)
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)
    ab = np.ascontiguousarray(ab, dtype=np.float64).reshape(-1, 3)
    if len(a) != len(ab):
        raise ValueError("segments_within needs one a and one ab per segment")
    return _segments_within(q, a, ab, float(eps))


@njit(cache=True, nogil=True, error_model="numpy")
def _corner_cosines(X):
    k = X.shape[0]
    out = np.empty((k, 3))
    for i in range(k):
        _corner_cos3(X[i, 0], X[i, 1], X[i, 2], out, i)
    return out


@njit(cache=True, nogil=True, inline="always")
def _corner_cos_row(P, a, b, c, out, i):
    """corner_cosines of triangle (P[a], P[b], P[c]) into out[i]."""
    _corner_cos3(P[a], P[b], P[c], out, i)


@njit(cache=True, nogil=True, inline="always")
def _corner_cos3(A, B, C, out, i):
    """corner_cosines of the triangle with corners A, B, C (3-vectors) into out[i]."""
    X = (A, B, C)
    for j in range(3):
        # corner 0: (b - a, c - a); corner 1: (a - b, c - b); corner 2: (a - c, b - c)
        p = j
        q = 1 if j == 0 else 0
        r = 1 if j == 2 else 2
        u0, u1, u2 = X[q][0] - X[p][0], X[q][1] - X[p][1], X[q][2] - X[p][2]
        v0, v1, v2 = X[r][0] - X[p][0], X[r][1] - X[p][1], X[r][2] - X[p][2]
        den = norm3(u0, u1, u2) * norm3(v0, v1, v2)
        if den < 1e-300:                          # np.maximum(den, 1e-300): a NaN stays
            den = 1e-300
        out[i, j] = dot3e(u0, u1, u2, v0, v1, v2) / den


@njit(cache=True, nogil=True, error_model="numpy")
def _skin_flips(E, kptr, h0, h1, cnt, locked, T, P, active, cmax):
    ne = E.shape[0]
    pqrs = np.empty((ne, 4), np.int64)
    ff = np.empty((ne, 2), np.int64)
    orient = np.empty(ne, np.bool_)
    cos = np.empty((4, ne, 3))
    k = 0
    for e in range(ne):
        if cnt[e] != 2 or locked[e]:
            continue
        f0, s0 = h0[e] // 3, h0[e] % 3
        f1, s1 = h1[e] // 3, h1[e] % 3
        p, q, r = T[f0, s0], T[f0, (s0 + 1) % 3], T[f0, (s0 + 2) % 3]
        s = T[f1, (s1 + 2) % 3]
        if not (T[f1, s1] == q and T[f1, (s1 + 1) % 3] == p and r != s):
            continue
        if active.shape[0] and not (active[p] and active[q]):
            continue
        Pp, Pq, Pr, Ps = P[p], P[q], P[r], P[s]
        a0, a1, a2 = cross3(Pq[0] - Pp[0], Pq[1] - Pp[1], Pq[2] - Pp[2], Pr[0] - Pp[0], Pr[1] - Pp[1], Pr[2] - Pp[2])
        b0, b1, b2 = cross3(Pp[0] - Pq[0], Pp[1] - Pq[1], Pp[2] - Pq[2], Ps[0] - Pq[0], Ps[1] - Pq[1], Ps[2] - Pq[2])
        la, lb = norm3(a0, a1, a2), norm3(b0, b1, b2)
        den = la * lb
        if den < 1e-300:
            den = 1e-300
        if not dot3e(a0, a1, a2, b0, b1, b2) / den > cmax:
            continue
        if edge_id(E, kptr, r, s) >= 0:
            continue
        # the new pair (r, s, q), (s, r, p) against the pair's mean unit normal
        c0, c1, c2 = cross3(Ps[0] - Pr[0], Ps[1] - Pr[1], Ps[2] - Pr[2], Pq[0] - Pr[0], Pq[1] - Pr[1], Pq[2] - Pr[2])
        d0, d1, d2 = cross3(Pr[0] - Ps[0], Pr[1] - Ps[1], Pr[2] - Ps[2], Pp[0] - Ps[0], Pp[1] - Ps[1], Pp[2] - Ps[2])
        ma = la if la >= 1e-300 or la != la else 1e-300
        mb = lb if lb >= 1e-300 or lb != lb else 1e-300
        g0, g1, g2 = a0 / ma + b0 / mb, a1 / ma + b1 / mb, a2 / ma + b2 / mb
        lg = norm3(g0, g1, g2)
        if lg < 1e-300:
            lg = 1e-300
        u0, u1, u2 = g0 / lg, g1 / lg, g2 / lg
        orient[k] = (dot3e(c0, c1, c2, u0, u1, u2) > cmax * norm3(c0, c1, c2)) and \
            (dot3e(d0, d1, d2, u0, u1, u2) > cmax * norm3(d0, d1, d2))
        pqrs[k, 0], pqrs[k, 1], pqrs[k, 2], pqrs[k, 3] = p, q, r, s
        ff[k, 0], ff[k, 1] = f0, f1
        _corner_cos_row(P, T[f0, 0], T[f0, 1], T[f0, 2], cos[0], k)
        _corner_cos_row(P, T[f1, 0], T[f1, 1], T[f1, 2], cos[1], k)
        _corner_cos_row(P, r, s, q, cos[2], k)
        _corner_cos_row(P, s, r, p, cos[3], k)
        k += 1
    return pqrs[:k], ff[:k], orient[:k], cos[:, :k]


def skin_flips(E, kptr, h0, h1, cnt, locked, T, P, cmax, active=None):
    """The imprint's angle-improving flips allowed on their own, up to the angles, in one pass
    over the edge table of the triangles ``T`` (:func:`edge_table`'s ``E``, ``h0``, ``h1``,
    ``cnt``; ``kptr`` as in :func:`edge_lookup`; ``locked`` the edges never flipped). Edge p-q of
    the triangles (p, q, r) and (q, p, s) (exactly two, consistently oriented, r != s, both
    ends ``active`` when given) may become r-s when r-s is not an edge yet, the pair's normals
    are within ``cmax`` (a cosine) of each other, and ``orient`` says whether both new
    triangles (r, s, q) and (s, r, p) are within it of the pair's mean unit normal. Returns
    ``(pqrs (k, 4), faces (k, 2), orient, cos (4, k, 3))`` in edge order, ``cos`` the
    :func:`corner_cosines` of the triangles T[f0], T[f1] (as stored) and the two new ones, for
    numpy's ``arccos``. The bits of the numpy formulas of ``imprint.improve.flip_round``."""
    E = np.ascontiguousarray(E, dtype=np.int64).reshape(-1, 2)
    kptr, h0, h1, cnt = (np.ascontiguousarray(x, dtype=np.int64) for x in (kptr, h0, h1, cnt))
    T = np.ascontiguousarray(T, dtype=np.int64).reshape(-1, 3)
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    locked = np.ascontiguousarray(locked, dtype=np.bool_)
    active = np.zeros(0, np.bool_) if active is None else np.ascontiguousarray(active, dtype=np.bool_)
    n = len(P)
    if not (len(h0) == len(h1) == len(cnt) == len(locked) == len(E)) or len(kptr) != n + 1 \
            or (len(active) and len(active) != n):
        raise ValueError("skin_flips: arrays of mismatched lengths")
    check_index("E", E, n)
    check_index("T", T, n)
    if kptr[0] != 0 or kptr[-1] != len(E) or (np.diff(kptr) < 0).any():
        raise ValueError("kptr must be row pointers into E")
    two = cnt == 2
    check_index("h0", h0, 3 * len(T))
    check_index("h1", h1[two], 3 * len(T))
    return _skin_flips(E, kptr, h0, h1, cnt, locked, T, P, active, float(cmax))


@njit(cache=True, nogil=True, error_model="numpy")
def _star_moves(rows, tris, T, P, new, nrm):
    k = rows.shape[0]
    cos_new = np.empty((k, 3))
    cos_old = np.empty((k, 3))
    flip = np.empty(k, np.bool_)
    for i in range(k):
        r, t = rows[i], tris[i]
        A = new[r] if T[t, 0] == r else P[T[t, 0]]
        B = new[r] if T[t, 1] == r else P[T[t, 1]]
        C = new[r] if T[t, 2] == r else P[T[t, 2]]
        _corner_cos3(A, B, C, cos_new, i)
        _corner_cos3(P[T[t, 0]], P[T[t, 1]], P[T[t, 2]], cos_old, i)
        n0, n1, n2 = cross3(B[0] - A[0], B[1] - A[1], B[2] - A[2], C[0] - A[0], C[1] - A[1], C[2] - A[2])
        flip[i] = dot3e(n0, n1, n2, nrm[t, 0], nrm[t, 1], nrm[t, 2]) <= 0
    return cos_new, cos_old, flip


@njit(cache=True, nogil=True)
def _star_independent(order, ptr, star, ntri, rounds):
    cur = order.copy()
    ncur = cur.shape[0]
    nxt = np.empty(ncur, np.int64)
    taken = np.zeros(ntri, np.bool_)
    firstpos = np.empty(ntri, np.int64)
    out = np.empty(ncur, np.int64)
    nout = 0
    for _ in range(rounds):
        if ncur == 0:
            break
        for i in range(ncur):
            for k in range(ptr[cur[i]], ptr[cur[i] + 1]):
                firstpos[star[k]] = ncur
        for i in range(ncur):
            for k in range(ptr[cur[i]], ptr[cur[i] + 1]):
                if i < firstpos[star[k]]:
                    firstpos[star[k]] = i
        first = nout
        nn = 0
        for i in range(ncur):
            v = cur[i]
            win = True
            for k in range(ptr[v], ptr[v + 1]):
                if firstpos[star[k]] != i or taken[star[k]]:
                    win = False
                    break
            if win:
                out[nout] = v
                nout += 1
            else:
                nxt[nn] = v
                nn += 1
        for j in range(first, nout):            # this round's winners take their triangles
            for k in range(ptr[out[j]], ptr[out[j] + 1]):
                taken[star[k]] = True
        cur[:nn] = nxt[:nn]
        ncur = nn
    return out[:nout]


def star_independent(order, ptr, star, ntri: int, rounds: int = 8):
    """The imprint smoothing's independent set of moving vertices: in each of ``rounds``
    rounds, a vertex of ``order`` (best first) is taken when it comes first in ``order``
    among the remaining vertices on every triangle of its star (``star[ptr[v]:ptr[v + 1]]``,
    triangle ids below ``ntri``) and none of those triangles was taken in an earlier round;
    the vertices taken take their triangles, the others go on to the next round in their
    order. Returns the vertices taken, round by round, each round in ``order``'s order (the
    numpy rounds of ``imprint.improve._smooth_round``, the same list)."""
    order = np.ascontiguousarray(order, dtype=np.int64).reshape(-1)
    ptr = np.ascontiguousarray(ptr, dtype=np.int64).reshape(-1)
    star = np.ascontiguousarray(star, dtype=np.int64).reshape(-1)
    if not len(ptr) or ptr[0] != 0 or ptr[-1] != len(star) or (np.diff(ptr) < 0).any():
        raise ValueError("star_independent: ptr must be CSR row pointers into star")
    check_index("order", order, len(ptr) - 1)
    check_index("star", star, int(ntri))
    return _star_independent(order, ptr, star, int(ntri), int(rounds))


def star_moves(rows, tris, T, P, new, nrm):
    """The imprint smoothing's test of moving vertex ``rows[i]`` from ``P`` to ``new`` alone, for
    each of its triangles ``tris[i]`` (of ``T`` (m, 3)): the :func:`corner_cosines` of the
    triangle with that vertex moved and before (for numpy's ``arccos``), and whether the moved
    triangle's normal (cross_rows of its sides) turns against ``nrm[tris[i]]`` (einsum's dot at
    most 0). The bits of the numpy formulas of ``imprint.improve._smooth_round``."""
    rows = np.ascontiguousarray(rows, dtype=np.int64).reshape(-1)
    tris = np.ascontiguousarray(tris, dtype=np.int64).reshape(-1)
    T = np.ascontiguousarray(T, dtype=np.int64).reshape(-1, 3)
    P, new, nrm = (np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3) for x in (P, new, nrm))
    if len(rows) != len(tris) or len(new) != len(P) or len(nrm) != len(T):
        raise ValueError("star_moves: rows/tris of one length, new one row per point, nrm one per triangle")
    check_index("rows", rows, len(P))
    check_index("tris", tris, len(T))
    check_index("T", T, len(P))
    return _star_moves(rows, tris, T, P, new, nrm)


def corner_cosines(X):
    """(k, 3) cosines of the corner angles of triangles with corners ``X`` (k, 3, 3): at corner
    j, ``u . v / max(|u| |v|, 1e-300)`` with u, v the sides to the next and the previous corner
    (einsum's dot and ``norm_rows``' norms, the imprint's formula)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    if X.ndim != 3 or X.shape[1:] != (3, 3):
        raise ValueError("corner_cosines takes a (k, 3, 3) array of triangle corners")
    return _corner_cosines(X)
