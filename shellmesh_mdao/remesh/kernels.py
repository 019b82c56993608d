"""Compiled kernels of the remesh stage: the collapses' and flips' tests and batch updates, the greedy
independent sets over closed 1-rings, the candidates' ranking and the per-row formulas only the remesh uses.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit
from ..core.kernels import (by_resource, check_index, counting_order, cross3, dense_rank, dot3e, edge_id, first_wave,
                            next_wave, select)
from ..core.bvh import bvh_closest

__all__ = ["greedy_independent_rings", "common_neighbour_counts", "group_order", "edge_neighbours", "rank_desc",
           "collapse_directions", "collapse_apply", "collapse_select", "flip_candidates", "move_tests",
           "edge_lengths", "triangle_normals", "corner_sin_cos", "facing_ok"]


@njit(cache=True, nogil=True)
def _build_rings(nptr, nbr, u, v, alive, rank, ncand, nres):
    """:func:`_build` for candidates whose resources are the neighbour lists of two
    vertices ``u[c]`` and ``v[c]`` (CSR ``nptr``, ``nbr``), without listing the entries first."""
    cptr = np.zeros(ncand + 1, np.int64)
    for c in range(ncand):
        k = 0
        if alive[c]:
            k = nptr[u[c] + 1] - nptr[u[c]] + nptr[v[c] + 1] - nptr[v[c]]
        cptr[c + 1] = cptr[c] + k
    cres = np.empty(cptr[ncand], np.int64)
    for c in range(ncand):
        if alive[c]:
            k = cptr[c]
            for p in range(nptr[u[c]], nptr[u[c] + 1]):
                cres[k] = nbr[p]
                k += 1
            for p in range(nptr[v[c]], nptr[v[c] + 1]):
                cres[k] = nbr[p]
                k += 1
    rptr, rcand = by_resource(cptr, cres, rank, ncand, nres)
    return cptr, cres, rptr, rcand


def _check_csr(nptr, nbr):
    n = len(nptr) - 1
    if n < 0 or (n and (nptr[0] != 0 or nptr[-1] != len(nbr) or (np.diff(nptr) < 0).any())):
        raise ValueError("nptr must be CSR row pointers into nbr: start at 0, never decrease, end at len(nbr)")
    check_index("nbr", nbr, n)


def greedy_independent_rings(nptr, nbr, u, v, rank, *, alive=None, check=None, max_sub=12):
    """:func:`greedy_independent` where candidate ``c`` uses the vertices of the neighbour
    lists of ``u[c]`` and ``v[c]`` (graph CSR ``nptr``, ``nbr``; for an edge ``(u, v)`` the
    closed 1-rings of both ends), without listing those entries in memory first."""
    nptr, nbr, u, v = (np.ascontiguousarray(x, dtype=np.int64) for x in (nptr, nbr, u, v))
    _check_csr(nptr, nbr)
    check_index("u", u, len(nptr) - 1)
    check_index("v", v, len(nptr) - 1)
    if not len(u) == len(v) == len(rank):
        raise ValueError(f"u, v and rank need one entry per candidate, got {len(u)}, {len(v)} and {len(rank)}")
    return select(lambda alive, rank, ncand: _build_rings(nptr, nbr, u, v, alive, rank, ncand, len(nptr) - 1),
                   rank, alive, check, max_sub)


# ============================================================================ topology
@njit(cache=True, nogil=True)
def _common(nptr, nbr, u, v, n):
    stamp = np.full(n, -1, np.int64)
    out = np.zeros(u.shape[0], np.int64)
    for i in range(u.shape[0]):
        a = u[i]
        for p in range(nptr[a], nptr[a + 1]):
            stamp[nbr[p]] = i
        b = v[i]
        c = 0
        for p in range(nptr[b], nptr[b + 1]):
            if stamp[nbr[p]] == i:
                c += 1
        out[i] = c
    return out


def common_neighbour_counts(nptr, nbr, u, v):
    """Number of common neighbours of ``u[i]`` and ``v[i]`` in the graph with CSR
    neighbour lists ``(nptr, nbr)`` (lists without repeats)."""
    nptr, nbr, u, v = (np.ascontiguousarray(x, dtype=np.int64) for x in (nptr, nbr, u, v))
    _check_csr(nptr, nbr)
    check_index("u", u, len(nptr) - 1)
    check_index("v", v, len(nptr) - 1)
    if len(u) != len(v):
        raise ValueError(f"u and v need the same length, got {len(u)} and {len(v)}")
    return _common(nptr, nbr, u, v, len(nptr) - 1)


@njit(cache=True, nogil=True)
def _group_order(keys, n):
    ptr = np.zeros(n + 1, np.int64)
    for i in range(keys.shape[0]):
        ptr[keys[i] + 1] += 1
    for k in range(n):
        ptr[k + 1] += ptr[k]
    return ptr, counting_order(keys, n, np.arange(keys.shape[0]))


def group_order(keys, n):
    """Row pointers ``ptr`` (n + 1,) and ``order`` grouping ``arange(len(keys))`` by ``keys``
    (integers in [0, n)): ``order`` is ``np.argsort(keys, kind="stable")`` and group ``k`` is
    ``order[ptr[k]:ptr[k + 1]]``, in one counting pass."""
    keys = np.ascontiguousarray(keys, dtype=np.int64).reshape(-1)
    check_index("keys", keys, int(n))
    return _group_order(keys, int(n))


@njit(cache=True, nogil=True)
def _edge_neighbours(E, n):
    ne = E.shape[0]
    ptr = np.zeros(n + 1, np.int64)
    for i in range(ne):
        ptr[E[i, 0] + 1] += 1
        ptr[E[i, 1] + 1] += 1
    for k in range(n):
        ptr[k + 1] += ptr[k]
    fill = ptr[:n].copy()
    nbr = np.empty(2 * ne, np.int64)
    for i in range(ne):                     # first each vertex's edges as their first end ...
        a = E[i, 0]
        nbr[fill[a]] = E[i, 1]
        fill[a] += 1
    for i in range(ne):                     # ... then as their second, each in edge order
        b = E[i, 1]
        nbr[fill[b]] = E[i, 0]
        fill[b] += 1
    return ptr, nbr


def edge_neighbours(E, n):
    """CSR ``(ptr, nbr)`` of the vertices next to each vertex along the edges ``E`` (e, 2) on
    ``n`` vertices: for vertex v, the other ends of the edges whose first end is v (in edge
    order), then of those whose second end is v (the grouping of
    ``concatenate([E[:, 1], E[:, 0]])`` by ``concatenate([E[:, 0], E[:, 1]])``, stable)."""
    E = np.ascontiguousarray(E, dtype=np.int64).reshape(-1, 2)
    check_index("E", E, int(n))
    return _edge_neighbours(E, int(n))


@njit(cache=True, nogil=True)
def _radix_pass(key, shift, src, dst, cnt):
    """One stable counting pass of an LSD radix sort: ``src`` (positions) into ``dst`` by the
    11-bit digit of ``key`` at ``shift``; False (``dst`` untouched) when every position has
    the same digit, as the pass would not change the order."""
    cnt[:] = 0
    for i in range(src.shape[0]):
        cnt[((key[src[i]] >> shift) & 2047) + 1] += 1
    if cnt[((key[src[0]] >> shift) & 2047) + 1] == src.shape[0]:
        return False
    for d in range(2048):
        cnt[d + 1] += cnt[d]
    for i in range(src.shape[0]):
        d = (key[src[i]] >> shift) & 2047
        dst[cnt[d]] = src[i]
        cnt[d] += 1
    return True


@njit(cache=True, nogil=True)
def _rank_desc(prio, tie):
    n = prio.shape[0]
    # the float's bits made to order like the number: -prio ascending, i.e. prio descending
    # (-0.0 counted as 0.0, as a comparison does)
    kf = np.empty(n, np.uint64)
    for i in range(n):
        b = np.float64(-prio[i] + 0.0).view(np.uint64)
        kf[i] = ~b if b >> np.uint64(63) else b | (np.uint64(1) << np.uint64(63))
    a = np.arange(n)
    b = np.empty(n, np.int64)
    cnt = np.zeros(2049, np.int64)
    if n:
        top = np.uint64(0)
        for i in range(n):
            top = max(top, tie[i])
        for shift in range(0, 64, 11):                    # tie first: the passes are stable
            if (top >> np.uint64(shift)) and _radix_pass(tie, np.uint64(shift), a, b, cnt):
                a, b = b, a
        for shift in range(0, 64, 11):
            if _radix_pass(kf, np.uint64(shift), a, b, cnt):
                a, b = b, a
    r = np.empty(n, np.int64)
    for j in range(n):
        r[a[j]] = n - j
    return r


def rank_desc(prio, tie):
    """Unique rank of each entry, ``len(prio)`` for the first: larger ``prio`` (float64, no
    NaN) first, equal ones by smaller ``tie`` (uint64, unique among them). The ranks of
    ``np.lexsort((tie, -prio))`` (a radix sort of the two keys' bits: 20k entries in about
    0.3 ms against 2.7 ms); NaNs are refused."""
    prio = np.ascontiguousarray(prio, dtype=np.float64).reshape(-1)
    tie = np.ascontiguousarray(tie, dtype=np.uint64).reshape(-1)
    if len(prio) != len(tie):
        raise ValueError(f"rank_desc: prio and tie need the same length, got {len(prio)} and {len(tie)}")
    if np.isnan(prio).any():
        raise ValueError("rank_desc: NaN priorities have no rank")
    return _rank_desc(prio, tie)


@njit(cache=True, nogil=True)
def _edge_lengths(P, E):
    k = E.shape[0]
    out = np.empty(k)
    for i in range(k):
        a, b = E[i, 0], E[i, 1]
        d0, d1, d2 = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
        out[i] = np.sqrt(dot3e(d0, d1, d2, d0, d1, d2))
    return out


@njit(cache=True, nogil=True)
def _tri_normals(P, F):
    k = F.shape[0]
    out = np.empty((k, 3))
    for i in range(k):
        a, b, c = F[i, 0], F[i, 1], F[i, 2]
        out[i, 0], out[i, 1], out[i, 2] = cross3(P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2],
                                                  P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2])
    return out


@njit(cache=True, nogil=True, inline="always")
def _sin_cos(u0, u1, u2, v0, v1, v2):
    """(|u x v|, u . v) with numpy's sums (einsum order for both)."""
    c0, c1, c2 = cross3(u0, u1, u2, v0, v1, v2)
    return np.sqrt(dot3e(c0, c1, c2, c0, c1, c2)), dot3e(u0, u1, u2, v0, v1, v2)


@njit(cache=True, nogil=True)
def _corner_sin_cos(A, B, C):
    k = A.shape[0]
    out = np.empty((4, k))
    for i in range(k):
        out[0, i], out[1, i] = _sin_cos(B[i, 0] - A[i, 0], B[i, 1] - A[i, 1], B[i, 2] - A[i, 2],
                                        C[i, 0] - A[i, 0], C[i, 1] - A[i, 1], C[i, 2] - A[i, 2])
        out[2, i], out[3, i] = _sin_cos(C[i, 0] - B[i, 0], C[i, 1] - B[i, 1], C[i, 2] - B[i, 2],
                                        A[i, 0] - B[i, 0], A[i, 1] - B[i, 1], A[i, 2] - B[i, 2])
    return out


@njit(cache=True, nogil=True)
def _facing_ok(F, kind, vtri, tri_n, nrm, cos_facing):
    k = F.shape[0]
    out = np.empty(k, np.bool_)
    for i in range(k):
        any_reg = False
        best = -2.0
        nan = False
        for j in range(3):
            v = F[i, j]
            if kind[v] == 0 and vtri[v] >= 0:
                any_reg = True
                t = vtri[v]
                d = dot3e(nrm[i, 0], nrm[i, 1], nrm[i, 2], tri_n[t, 0], tri_n[t, 1], tri_n[t, 2])
                if d != d:
                    nan = True
                elif d > best:
                    best = d
        out[i] = (not any_reg) or ((not nan) and best > cos_facing)
    return out


@njit(cache=True, nogil=True, inline="always")
def _max_nan(cur, v):
    """np.maximum(cur, v): a NaN on either side wins."""
    if cur != cur:
        return cur
    if v != v or v > cur:
        return v
    return cur


@njit(cache=True, nogil=True, inline="always")
def _min_nan(cur, v):
    """np.minimum(cur, v) for comparisons: a NaN on either side wins."""
    if cur != cur:
        return cur
    if v != v or v < cur:
        return v
    return cur


@njit(cache=True, nogil=True, inline="always")
def _facing_one(q0, q1, q2, kind, vtri, tri_n, n0, n1, n2, cos_facing):
    any_reg = False
    best = -2.0
    nan = False
    for v in (q0, q1, q2):
        if kind[v] == 0 and vtri[v] >= 0:
            any_reg = True
            t = vtri[v]
            d = dot3e(n0, n1, n2, tri_n[t, 0], tri_n[t, 1], tri_n[t, 2])
            if d != d:
                nan = True
            elif d > best:
                best = d
    return (not any_reg) or ((not nan) and best > cos_facing)


@njit(cache=True, nogil=True, inline="always")
def _tri_min_deg(A, B, C):
    """Smallest angle (degrees) of triangle (A, B, C) as ``remesh.common.min_angle_of`` computes it
    (the corners at A and B by arctan2, the third what remains of pi; a NaN wins), with the C
    library's atan2 instead of numpy's."""
    s0, c0 = _sin_cos(B[0] - A[0], B[1] - A[1], B[2] - A[2], C[0] - A[0], C[1] - A[1], C[2] - A[2])
    s1, c1 = _sin_cos(C[0] - B[0], C[1] - B[1], C[2] - B[2], A[0] - B[0], A[1] - B[1], A[2] - B[2])
    a0 = math.atan2(s0, c0)
    a1 = math.atan2(s1, c1)
    return _min_nan(_min_nan(a0, a1), np.pi - a0 - a1) * (180.0 / np.pi)


@njit(cache=True, nogil=True, error_model="numpy")
def _collapse_score(ai, bi, nptr, nbr, fptr, vf, F, P, h, max_len_ratio, fn_old, cos_turn, kind, vtri, tri_n,
                    cos_facing):
    """The tests of :func:`collapse_select` for one pair: rmax of collapsing ``ai`` into ``bi``,
    inf where a test fails."""
    r_max = 0.0
    for p in range(nptr[ai], nptr[ai + 1]):
        x = nbr[p]
        if x == bi:
            continue
        d0, d1, d2 = P[x, 0] - P[bi, 0], P[x, 1] - P[bi, 1], P[x, 2] - P[bi, 2]
        r = np.sqrt(dot3e(d0, d1, d2, d0, d1, d2)) / (0.5 * (h[x] + h[bi]))
        if r_max == r_max and (r != r or r > r_max):
            r_max = r
    if not r_max <= max_len_ratio:
        return np.inf
    cmin = np.inf
    amin_old = np.inf
    amin_new = np.inf
    hb2 = 1e-30 * (h[bi] * h[bi])
    for p in range(fptr[ai], fptr[ai + 1]):
        f = vf[p]
        c0, c1, c2 = F[f, 0], F[f, 1], F[f, 2]
        amin_old = _min_nan(amin_old, _tri_min_deg(P[c0], P[c1], P[c2]))
        if c0 == bi or c1 == bi or c2 == bi:
            continue
        q0 = bi if c0 == ai else c0
        q1 = bi if c1 == ai else c1
        q2 = bi if c2 == ai else c2
        A, B, C = P[q0], P[q1], P[q2]
        n0, n1, n2, area = _unit_normal_area(A, B, C)
        cosn = dot3e(n0, n1, n2, fn_old[f, 0], fn_old[f, 1], fn_old[f, 2])
        cmin = _min_nan(cmin, cosn if area > hb2 else -2.0)
        if not _facing_one(q0, q1, q2, kind, vtri, tri_n, n0, n1, n2, cos_facing):
            return np.inf
        amin_new = _min_nan(amin_new, _tri_min_deg(A, B, C))
    if not cmin > cos_turn:
        return np.inf
    if not amin_new >= _min_nan(5.0, 0.5 * amin_old):
        return np.inf
    return r_max


@njit(cache=True, nogil=True, error_model="numpy")
def _facing_score(ai, bi, fptr, vf, F, P, kind, vtri, tri_n, cos_facing, bvh_V, bvh_TB, bvh_id, bvh_box, bvh_child,
                  bvh_start, bvh_cnt, bvh_slack, center, q, qid, qout, noseed):
    """The micro collapses' test of collapsing ``ai`` into ``bi``: no new face standing across
    the input (:func:`_facing_one`) nor facing against the input triangle closest to its
    centroid (the :class:`TriangleBVH` arrays, queries shifted by ``center`` as
    ``SurfaceLocator.closest`` does); the edge's length, inf where a face fails."""
    for p in range(fptr[ai], fptr[ai + 1]):
        f = vf[p]
        c0, c1, c2 = F[f, 0], F[f, 1], F[f, 2]
        if c0 == bi or c1 == bi or c2 == bi:
            continue
        q0 = bi if c0 == ai else c0
        q1 = bi if c1 == ai else c1
        q2 = bi if c2 == ai else c2
        n0, n1, n2 = _unit_normal(P[q0], P[q1], P[q2])
        if not _facing_one(q0, q1, q2, kind, vtri, tri_n, n0, n1, n2, cos_facing):
            return np.inf
        for k in range(3):
            q[0, k] = (P[q0, k] + P[q1, k] + P[q2, k]) / 3 - center[k]
        bvh_closest(q, 0, 1, bvh_V, bvh_TB, bvh_id, bvh_box, bvh_child, bvh_start, bvh_cnt, bvh_slack, qout, qid,
                     noseed)
        t = qid[0]
        if not dot3e(n0, n1, n2, tri_n[t, 0], tri_n[t, 1], tri_n[t, 2]) > 0:
            return np.inf
    d0, d1, d2 = P[ai, 0] - P[bi, 0], P[ai, 1] - P[bi, 1], P[ai, 2] - P[bi, 2]
    return np.sqrt(dot3e(d0, d1, d2, d0, d1, d2))


@njit(cache=True, nogil=True, error_model="numpy")
def _collapse_select(cptr, cres, rptr, rcand, alive, u, v, dir_ok, max_sub, nptr, nbr, fptr, vf, F, P, h,
                     max_len_ratio, fn_old, cos_turn, kind, vtri, tri_n, cos_facing, facing_only, bvh_V, bvh_TB,
                     bvh_id, bvh_box, bvh_child, bvh_start, bvh_cnt, bvh_slack, center):
    """:func:`_waves` with the collapse tests as the check: :func:`_collapse_score` in both
    directions of each winner, the one with the smaller rmax taken (u into v on a tie); or,
    ``facing_only``, :func:`_facing_score` u into v, else v into u."""
    ncand = alive.shape[0]
    rtop = rptr[:-1].copy()
    resolved = ~alive
    seen = np.full(ncand, -1, np.int64)
    out_a = np.empty(ncand, np.int64)
    out_b = np.empty(ncand, np.int64)
    q = np.empty((1, 3))
    qout = np.empty((1, 3))
    qid = np.empty(1, np.int64)
    noseed = np.empty(0, np.int64)
    na = 0
    win = first_wave(cptr, cres, rtop, rptr, rcand, resolved, ncand)
    for wave in range(max_sub):
        if win.shape[0] == 0:
            break
        good = np.zeros(win.shape[0], np.bool_)
        for i in range(win.shape[0]):
            c = win[i]
            s0 = np.inf
            s1 = np.inf
            for dirn in range(2):
                if not dir_ok[c, dirn] or (facing_only and s0 < np.inf):
                    continue
                a, b = (u[c], v[c]) if dirn == 0 else (v[c], u[c])
                if facing_only:
                    sc = _facing_score(a, b, fptr, vf, F, P, kind, vtri, tri_n, cos_facing, bvh_V, bvh_TB, bvh_id,
                                       bvh_box, bvh_child, bvh_start, bvh_cnt, bvh_slack, center, q, qid, qout,
                                       noseed)
                else:
                    sc = _collapse_score(a, b, nptr, nbr, fptr, vf, F, P, h, max_len_ratio, fn_old, cos_turn, kind,
                                         vtri, tri_n, cos_facing)
                if dirn == 0:
                    s0 = sc
                else:
                    s1 = sc
            if s0 < np.inf or s1 < np.inf:
                good[i] = True
                if s1 < s0:
                    out_a[na], out_b[na] = v[c], u[c]
                else:
                    out_a[na], out_b[na] = u[c], v[c]
                na += 1
        if wave + 1 == max_sub:
            break
        win = next_wave(win, good, cptr, cres, rtop, rptr, rcand, resolved, seen, wave)
    return out_a[:na], out_b[:na]


@njit(cache=True, nogil=True)
def _collapse_directions(E, cand, h0, h1, valence, F, nptr, nbr, kind, isf, chain_ok, rf, use_rf):
    n = nptr.shape[0] - 1
    k = cand.shape[0]
    boundary = np.zeros(n, np.bool_)
    for e in range(E.shape[0]):
        if valence[e] == 1:
            boundary[E[e, 0]] = True
            boundary[E[e, 1]] = True
    u = np.empty(k, np.int64)
    v = np.empty(k, np.int64)
    for i in range(k):
        u[i], v[i] = E[cand[i], 0], E[cand[i], 1]
    common = _common(nptr, nbr, u, v, n)
    ok = np.zeros(k, np.bool_)
    dir_ok = np.zeros((k, 2), np.bool_)
    for i in range(k):
        e = cand[i]
        a0 = h0[e]
        o0 = F[a0 // 3, (a0 % 3 + 2) % 3]
        good = nptr[o0 + 1] - nptr[o0] > 3
        a1 = h1[e]
        if a1 >= 0:
            o1 = F[a1 // 3, (a1 % 3 + 2) % 3]
            good = good and nptr[o1 + 1] - nptr[o1] > 3
        good = good and common[i] == valence[e]
        good = good and not (valence[e] == 2 and boundary[u[i]] and boundary[v[i]])
        ok[i] = good
        for d in range(2):
            a = u[i] if d == 0 else v[i]
            b = v[i] if d == 0 else u[i]
            da = good and (kind[a] == 0 or (kind[a] == 1 and isf[e] and chain_ok[a]))
            if use_rf:
                da = da or (good and rf[a] and kind[a] == 2 and isf[e])
                da = da and not (rf[b] and not rf[a])
            dir_ok[i, d] = da
    return ok, dir_ok


def collapse_directions(E, cand, h0, h1, valence, F, nptr, nbr, kind, isf, chain_ok, remove_first=None):
    """The remesh's cheap collapse tests of the candidate edges ``cand`` of the edge table
    ``E`` (``h0``, ``h1``, ``valence`` per edge, as :func:`edge_table` gives them) of the
    triangles ``F``, with vertex neighbours ``nptr``/``nbr``: ``ok`` (k,) where both opposite
    vertices keep more than three neighbours, the ends share exactly the edge's faces' apexes
    as common neighbours (the link condition) and an interior edge does not join two
    boundary vertices; ``dir_ok`` (k, 2) where the collapse may remove u (into v), v (into u):
    ``ok`` and the removed vertex regular (kind 0), or on a chain (kind 1) along a feature
    edge (``isf`` per edge) with ``chain_ok`` (its chain keeps enough vertices). With
    ``remove_first`` (vertex ids): those vertices may also go when they are corners (kind 2)
    along a feature edge, and an edge at one of them may only remove it. The numpy tests of
    ``remesh.operations.collapse_edges`` in one compiled pass (the same masks)."""
    i64 = lambda x: np.ascontiguousarray(x, dtype=np.int64)     # noqa: E731
    E = i64(E).reshape(-1, 2)
    F = i64(F).reshape(-1, 3)
    cand, h0, h1, valence, nptr, nbr, kind = (i64(x).reshape(-1) for x in (cand, h0, h1, valence, nptr, nbr, kind))
    isf = np.ascontiguousarray(isf, dtype=np.bool_).reshape(-1)
    chain_ok = np.ascontiguousarray(chain_ok, dtype=np.bool_).reshape(-1)
    n = len(nptr) - 1
    if not len(h0) == len(h1) == len(valence) == len(isf) == len(E) or len(kind) != n or len(chain_ok) != n:
        raise ValueError("collapse_directions: arrays of mismatched lengths")
    _check_csr(nptr, nbr)
    check_index("E", E, n)
    check_index("F", F, n)
    check_index("cand", cand, len(E))
    check_index("h0", h0, 3 * len(F))
    if len(h1) and (h1.max(initial=-1) >= 3 * len(F) or h1.min(initial=0) < -1):
        raise ValueError(f"collapse_directions: h1 must be -1 or below {3 * len(F)}")
    rf = np.zeros(n if remove_first is not None else 0, np.bool_)
    if remove_first is not None:
        remove_first = i64(remove_first).reshape(-1)
        check_index("remove_first", remove_first, n)
        rf[remove_first] = True
    return _collapse_directions(E, cand, h0, h1, valence, F, nptr, nbr, kind, isf, chain_ok, rf,
                                remove_first is not None and len(remove_first) > 0)


@njit(cache=True, nogil=True)
def _collapse_apply(F, fpatch, fe, fe_chain, a, b, n):
    remap = np.arange(n)
    keepv = np.ones(n, np.bool_)
    for i in range(a.shape[0]):
        if not keepv[a[i]]:
            return None                         # a vertex removed twice
        remap[a[i]] = b[i]
        keepv[a[i]] = False
    for i in range(b.shape[0]):
        if not keepv[b[i]]:
            return None                         # a vertex collapsed into a removed one
    o2n = np.empty(n, np.int64)
    c = 0
    for v in range(n):
        o2n[v] = c
        if keepv[v]:
            c += 1
    m = F.shape[0]
    F2 = np.empty((m, 3), np.int64)
    p2 = np.empty(m, fpatch.dtype)
    k = 0
    for f in range(m):
        x, y, z = remap[F[f, 0]], remap[F[f, 1]], remap[F[f, 2]]
        if x != y and y != z and x != z:
            F2[k, 0], F2[k, 1], F2[k, 2] = o2n[x], o2n[y], o2n[z]
            p2[k] = fpatch[f]
            k += 1
    # the feature edges remapped, each row (lo, hi), degenerate rows dropped, then sorted by
    # (lo, hi, chain) with ties in row order (three stable counting passes, last key first)
    # and one row per pair: remesh.work.WorkMesh.set_features' table, renumbered
    ne = fe.shape[0]
    lo = np.empty(ne, np.int64)
    hi = np.empty(ne, np.int64)
    rows = np.empty(ne, np.int64)
    r = 0
    cmin = 0
    cmax = 0
    for i in range(ne):
        x, y = remap[fe[i, 0]], remap[fe[i, 1]]
        if x == y:
            continue
        lo[i], hi[i] = (x, y) if x < y else (y, x)
        if r == 0 or fe_chain[i] < cmin:
            cmin = fe_chain[i]
        if r == 0 or fe_chain[i] > cmax:
            cmax = fe_chain[i]
        rows[r] = i
        r += 1
    rows = rows[:r]
    key = np.empty(ne, np.int64)
    for i in range(r):
        key[rows[i]] = fe_chain[rows[i]] - cmin
    rows = counting_order(key, cmax - cmin + 1, rows) if r else rows
    rows = counting_order(hi, n, rows) if r else rows
    rows = counting_order(lo, n, rows) if r else rows
    fe2 = np.empty((r, 2), np.int64)
    ch2 = np.empty(r, np.int64)
    q = 0
    for j in range(r):
        i = rows[j]
        if q and lo[i] == lo[rows[j - 1]] and hi[i] == hi[rows[j - 1]]:
            continue
        fe2[q, 0], fe2[q, 1] = o2n[lo[i]], o2n[hi[i]]
        ch2[q] = fe_chain[i]
        q += 1
    return F2[:k], p2[:k], fe2[:q], ch2[:q], keepv


def collapse_apply(F, fpatch, fe, fe_chain, a, b, n):
    """A batch of edge collapses (vertex ``a[i]`` into ``b[i]``, none of the ``b`` removed) on
    the triangles ``F`` (m, 3) with patches ``fpatch`` and the feature edges ``fe`` (k, 2) with
    chain ids ``fe_chain``, on ``n`` vertices. Returns ``(F, fpatch, fe, fe_chain, keep)``: the
    faces left (the two at each collapsed edge drop out, the rest keep their order), the
    feature edges as ``remesh.work.WorkMesh.set_features`` tabulates them (rows (lo, hi) sorted by
    (lo, hi, chain), degenerate rows dropped, one row per pair, the lowest chain), both on
    the vertices renumbered without the removed ones, and ``keep`` (n,) the vertices left.
    The numpy update ``remesh.operations.collapse_edges`` made before it (remap, face filter,
    set_features, renumbering) in one compiled pass (the same arrays)."""
    i64 = lambda x: np.ascontiguousarray(x, dtype=np.int64)     # noqa: E731
    F = i64(F).reshape(-1, 3)
    fe = i64(fe).reshape(-1, 2)
    fpatch = np.ascontiguousarray(fpatch).reshape(-1)
    fe_chain, a, b = (i64(x).reshape(-1) for x in (fe_chain, a, b))
    n = int(n)
    if len(fpatch) != len(F) or len(fe_chain) != len(fe) or len(a) != len(b):
        raise ValueError("collapse_apply: arrays of mismatched lengths")
    for name, x in (("F", F), ("fe", fe), ("a", a), ("b", b)):
        check_index(name, x, n)
    out = _collapse_apply(F, fpatch, fe, fe_chain, a, b, n)
    if out is None:
        raise ValueError("collapse_apply: each vertex is removed at most once and none into a removed one")
    return out


def collapse_select(nptr, nbr, fptr, vf, F, P, h, u, v, rank, dir_ok, *, kind, vtri, tri_n, cos_facing,
                    max_len_ratio=np.inf, fn_old=None, cos_turn=-1.0, surface=None, max_sub=16):
    """The remesh's batch of edge collapses: :func:`greedy_independent_rings` over the
    candidate edges (``u``, ``v``; ``rank`` higher first; closed 1-rings of both ends as the
    lock regions), every winner checked in both allowed directions (``dir_ok`` (k, 2): u into
    v, v into u) by the geometric tests of collapsing a vertex ``a`` into ``b``, in one
    compiled pass (no call back into Python per sub-round):

    - ``rmax``, the largest ratio of a new edge to the mean local size ``h`` of its ends, at
      most ``max_len_ratio``;
    - no face around ``a`` that keeps its area turning its unit normal away from ``fn_old``
      to a cosine of ``cos_turn`` or less;
    - no new face standing across the input (:func:`facing_ok` with ``kind``, ``vtri``,
      ``tri_n``, ``cos_facing``);
    - the smallest angle of the new faces at least min(5, half the smallest angle of the
      faces around ``a`` before), in degrees.

    A winner passing in a direction is collapsed, in the direction of the smaller rmax (u into
    v on a tie).

    With ``surface`` (a :class:`TriangleBVH` of the input and the ``center`` its triangles were
    shifted by: ``(bvh, center)``) only the facing tests run, u into v first, else v into u: no
    new face standing across the input, nor facing against the input triangle closest to its
    centroid (the remesh's micro collapses; ``h``, ``max_len_ratio``, ``fn_old`` and
    ``cos_turn`` are not used).

    Returns ``(a, b)``: the vertices removed and where each goes, in the order
    the sub-rounds took them. ``nptr``/``nbr``: vertex neighbours; ``fptr``/``vf``: faces
    around each vertex; ``F`` (m, 3) faces on the points ``P``. The angles use the C
    library's atan2 (numpy's AVX-512 loop gives other last bits: see the module's note); a
    test that an angle equal to the bound to the last bit decides could go the other way."""
    def i64(x):
        return np.ascontiguousarray(x, dtype=np.int64)

    def f64(x):
        return np.ascontiguousarray(x, dtype=np.float64)
    nptr, nbr, fptr, vf, u, v, kind, vtri = (i64(x) for x in (nptr, nbr, fptr, vf, u, v, kind, vtri))
    F = i64(F).reshape(-1, 3)
    if fn_old is None:
        fn_old = np.zeros((len(F), 3))
    P, fn_old, tri_n = (f64(x).reshape(-1, 3) for x in (P, fn_old, tri_n))
    h = f64(h)
    dir_ok = np.ascontiguousarray(dir_ok, dtype=np.bool_).reshape(-1, 2)
    n = len(P)
    if len(nptr) != n + 1 or len(fptr) != n + 1 or len(h) != n or len(kind) != n or len(vtri) != n \
            or len(fn_old) != len(F):
        raise ValueError("collapse_select: arrays of mismatched lengths")
    if not len(u) == len(v) == len(rank) == len(dir_ok):
        raise ValueError(f"collapse_select: u, v, rank and dir_ok need one entry per candidate, got {len(u)}, "
                         f"{len(v)}, {len(rank)} and {len(dir_ok)}")
    _check_csr(nptr, nbr)
    if fptr[0] != 0 or fptr[-1] != len(vf) or (np.diff(fptr) < 0).any():
        raise ValueError("fptr must be CSR row pointers into vf")
    check_index("vf", vf, len(F))
    check_index("F", F, n)
    check_index("u", u, n)
    check_index("v", v, n)
    if len(vtri) and vtri.max(initial=-1) >= len(tri_n):
        raise ValueError(f"collapse_select: vertex triangles must be below {len(tri_n)}")
    rank = dense_rank(rank)
    ncand = len(rank)
    if not ncand:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    alive = dir_ok[:, 0] | dir_ok[:, 1]
    cptr, cres, rptr, rcand = _build_rings(nptr, nbr, u, v, alive, rank, ncand, n)
    if surface is None:
        # no tree to query (the sweeps' tests): empty arrays of the tree's types
        tree = (np.empty((0, 9)), np.empty((0, 6)), np.empty(0, np.int64), np.empty((0, 6)), np.empty(0, np.int64),
                np.empty(0, np.int64), np.empty(0, np.int64), 0.0)
        center = np.zeros(3)
    else:
        bvh, center = surface
        center = f64(center).reshape(3)
        if len(tri_n) != len(bvh._tri_id):
            raise ValueError("collapse_select: tri_n needs one normal per triangle of the surface")
        tree = (bvh._V, bvh._TB, bvh._tri_id, bvh._box, bvh._child, bvh._start, bvh._cnt, bvh._slack)
    return _collapse_select(cptr, cres, rptr, rcand, alive, u, v, dir_ok, int(max_sub), nptr, nbr, fptr, vf, F, P,
                            h, float(max_len_ratio), fn_old, float(cos_turn), kind, vtri, tri_n, float(cos_facing),
                            surface is not None, *tree, center)


@njit(cache=True, nogil=True, inline="always")
def _unit_normal_area(a, b, c):
    """Unit normal of triangle (a, b, c) (3-vectors): cross(b - a, c - a) over its einsum norm,
    zero when that is not positive; and that norm (twice the area)."""
    n0, n1, n2 = cross3(b[0] - a[0], b[1] - a[1], b[2] - a[2], c[0] - a[0], c[1] - a[1], c[2] - a[2])
    L = np.sqrt(dot3e(n0, n1, n2, n0, n1, n2))
    if L > 0:
        return n0 / L, n1 / L, n2 / L, L
    return 0.0, 0.0, 0.0, L


@njit(cache=True, nogil=True, inline="always")
def _unit_normal(a, b, c):
    """:func:`_unit_normal_area` without the area."""
    n0, n1, n2, _ = _unit_normal_area(a, b, c)
    return n0, n1, n2


@njit(cache=True, nogil=True, inline="always")
def _tri_args(A, B, C, out, j, i):
    """corner_sin_cos arguments of triangle (A, B, C) into out[j, :, i]."""
    out[j, 0, i], out[j, 1, i] = _sin_cos(B[0] - A[0], B[1] - A[1], B[2] - A[2], C[0] - A[0], C[1] - A[1], C[2] - A[2])
    out[j, 2, i], out[j, 3, i] = _sin_cos(C[0] - B[0], C[1] - B[1], C[2] - B[2], A[0] - B[0], A[1] - B[1], A[2] - B[2])


@njit(cache=True, nogil=True, error_model="numpy")
def _flip_candidates(E, kptr, h0, h1, isf, F, fpatch, P, cosmax, kind, vtri, tri_n, cos_facing, valence, deg, tgt):
    ne = E.shape[0]
    out_e = np.empty(ne, np.int64)
    abcd = np.empty((ne, 4), np.int64)
    ff = np.empty((ne, 2), np.int64)
    gains = np.empty(ne)
    m0 = np.empty((ne, 3))
    m1 = np.empty((ne, 3))
    sc = np.empty((4, 4, ne))
    k = 0
    for e in range(ne):
        if h1[e] < 0 or isf[e]:
            continue
        f0, s0 = h0[e] // 3, h0[e] % 3
        f1, s1 = h1[e] // 3, h1[e] % 3
        a = F[f0, s0]
        b = F[f0, (s0 + 1) % 3]
        c = F[f0, (s0 + 2) % 3]
        d = F[f1, (s1 + 2) % 3]
        if c == d or fpatch[f0] != fpatch[f1]:
            continue
        if edge_id(E, kptr, c, d) >= 0:
            continue
        gain = 0.0
        if valence:
            ea, eb, ec, ed = deg[a] - tgt[a], deg[b] - tgt[b], deg[c] - tgt[c], deg[d] - tgt[d]
            before = ea * ea + eb * eb + ec * ec + ed * ed
            xa, xb = deg[a] + -1.0 - tgt[a], deg[b] + -1.0 - tgt[b]
            xc, xd = deg[c] + 1.0 - tgt[c], deg[d] + 1.0 - tgt[d]
            after = xa * xa + xb * xb + xc * xc + xd * xd
            gain = before - after
            if not gain > 0:
                continue
        Pa, Pb, Pc, Pd = P[a], P[b], P[c], P[d]
        x0, x1, x2 = _unit_normal(Pa, Pb, Pc)
        y0, y1, y2 = _unit_normal(Pb, Pa, Pd)
        if not dot3e(x0, x1, x2, y0, y1, y2) > cosmax:
            continue
        p0, p1, p2 = _unit_normal(Pa, Pd, Pc)
        q0, q1, q2 = _unit_normal(Pd, Pb, Pc)
        if not (dot3e(p0, p1, p2, x0, x1, x2) > cosmax and dot3e(p0, p1, p2, y0, y1, y2) > cosmax
                and dot3e(q0, q1, q2, x0, x1, x2) > cosmax and dot3e(q0, q1, q2, y0, y1, y2) > cosmax):
            continue
        if not (_facing_one(a, d, c, kind, vtri, tri_n, p0, p1, p2, cos_facing)
                and _facing_one(d, b, c, kind, vtri, tri_n, q0, q1, q2, cos_facing)):
            continue
        out_e[k] = e
        abcd[k, 0], abcd[k, 1], abcd[k, 2], abcd[k, 3] = a, b, c, d
        ff[k, 0], ff[k, 1] = f0, f1
        gains[k] = gain
        _tri_args(Pa, Pb, Pc, sc, 0, k)
        _tri_args(Pb, Pa, Pd, sc, 1, k)
        _tri_args(Pa, Pd, Pc, sc, 2, k)
        _tri_args(Pd, Pb, Pc, sc, 3, k)
        m0[k, 0], m0[k, 1], m0[k, 2] = p0, p1, p2
        m1[k, 0], m1[k, 1], m1[k, 2] = q0, q1, q2
        k += 1
    return out_e[:k], abcd[:k], ff[:k], gains[:k], m0[:k], m1[:k], sc[:, :, :k]


def flip_candidates(E, kptr, h0, h1, isf, F, fpatch, P, cosmax, kind, vtri, tri_n, cos_facing, deg=None, tgt=None):
    """The remesh's edge flips allowed on their own, up to the angles, in one pass over the
    edge table (``E`` (e, 2) rows ``(lo, hi)`` sorted, ``kptr`` as in :func:`edge_lookup`;
    ``h0``/``h1`` each edge's half-edges ``3 f + slot``, ``h1 < 0`` on a border; ``isf`` the
    feature edges, never flipped). Edge a-b of the triangles (a, b, c) and (b, a, d) may become
    c-d when c != d, c-d is not an edge yet, both faces are on one patch (``fpatch``), with
    ``deg``/``tgt`` (valence mode) the squared distances of the four valences ``deg`` to their
    targets ``tgt`` fall (``gain > 0``), and the old pair's unit normals are within ``cosmax`` (a
    cosine) of each other, both new faces' normals within it of both old ones, and neither new
    face stands across the input (:func:`facing_ok`).

    Returns, for those flips in edge order, ``(edge, abcd (k, 4), faces (k, 2), gain, m0, m1,
    sc)``: ``gain`` the valence gain (0 without ``deg``), ``m0``/``m1`` the unit normals of the
    new faces (a, d, c) and (d, b, c), ``sc`` (4, 4, k) the :func:`corner_sin_cos` arguments of
    the triangles (a, b, c), (b, a, d), (a, d, c) and (d, b, c) for numpy's ``arctan2``. The
    bits of the numpy formulas of ``remesh.operations.flip_round``."""
    E = np.ascontiguousarray(E, dtype=np.int64).reshape(-1, 2)
    kptr, h0, h1, fpatch, kind, vtri = (np.ascontiguousarray(x, dtype=np.int64)
                                        for x in (kptr, h0, h1, fpatch, kind, vtri))
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    tri_n = np.ascontiguousarray(tri_n, dtype=np.float64).reshape(-1, 3)
    isf = np.ascontiguousarray(isf, dtype=np.bool_)
    n = len(P)
    valence = deg is not None
    deg = np.ascontiguousarray(deg if valence else np.zeros(n), dtype=np.float64)
    tgt = np.ascontiguousarray(tgt if valence else np.zeros(n), dtype=np.float64)
    if not (len(h0) == len(h1) == len(isf) == len(E)) or len(kptr) != n + 1 or len(fpatch) != len(F) \
            or len(kind) != n or len(vtri) != n or len(deg) != n or len(tgt) != n:
        raise ValueError("flip_candidates: arrays of mismatched lengths")
    check_index("E", E, n)
    check_index("F", F, n)
    if kptr[0] != 0 or kptr[-1] != len(E) or (np.diff(kptr) < 0).any():
        raise ValueError("kptr must be row pointers into E")
    check_index("h0", h0, 3 * len(F))
    if h1.max(initial=-1) >= 3 * len(F):
        raise ValueError(f"h1 must be below {3 * len(F)}")
    if vtri.max(initial=-1) >= len(tri_n):
        raise ValueError(f"flip_candidates: vertex triangles must be below {len(tri_n)}")
    return _flip_candidates(E, kptr, h0, h1, isf, F, fpatch, P, float(cosmax), kind, vtri, tri_n, float(cos_facing),
                            valence, deg, tgt)


@njit(cache=True, nogil=True, error_model="numpy")
def _move_tests(cur, Fi, fn_old, area_old, moved, newtri, vtri, reg, tri_n, cosmax, cos_facing):
    k = Fi.shape[0]
    bad = np.empty(k, np.bool_)
    sc = np.empty((4, k))
    for i in range(k):
        q0, q1, q2 = Fi[i, 0], Fi[i, 1], Fi[i, 2]
        A, B, C = cur[q0], cur[q1], cur[q2]
        n0, n1, n2, ar = _unit_normal_area(A, B, C)
        b = dot3e(n0, n1, n2, fn_old[i, 0], fn_old[i, 1], fn_old[i, 2]) <= cosmax or ar <= 1e-3 * area_old[i]
        dmax = -2.0
        anyreg = False
        for v in (q0, q1, q2):
            t = newtri[v] if moved[v] else vtri[v]
            if reg[v] and t >= 0:
                d = dot3e(n0, n1, n2, tri_n[t, 0], tri_n[t, 1], tri_n[t, 2])
                b = b or d <= 0
                dmax = _max_nan(dmax, d)
                anyreg = True
        bad[i] = b or (anyreg and dmax <= cos_facing)
        sc[0, i], sc[1, i] = _sin_cos(B[0] - A[0], B[1] - A[1], B[2] - A[2], C[0] - A[0], C[1] - A[1], C[2] - A[2])
        sc[2, i], sc[3, i] = _sin_cos(C[0] - B[0], C[1] - B[1], C[2] - B[2], A[0] - B[0], A[1] - B[1], A[2] - B[2])
    return bad, sc


def move_tests(cur, Fi, fn_old, area_old, moved, newtri, vtri, reg, tri_n, cosmax, cos_facing):
    """The remesh relaxation's tests of the faces ``Fi`` (k, 3) at the positions ``cur``, each
    face on its own: ``bad`` where its unit normal turned from ``fn_old`` (k, 3) to a cosine of
    ``cosmax`` or less, its area (twice, ``area_old`` the old) fell to 1e-3 of the old or less, or
    it faces against the input at a regular corner (``reg``; input triangle ``newtri`` where
    ``moved``, else ``vtri``, -1 none; ``tri_n`` their normals) or stands across it (no regular
    corner's dot above ``cos_facing``); and the :func:`corner_sin_cos` arguments (4, k) of the
    faces for numpy's ``arctan2``. The bits of the numpy formulas of ``remesh.relax._accept_moves``."""
    Fi = np.ascontiguousarray(Fi, dtype=np.int64).reshape(-1, 3)
    cur, fn_old, tri_n = (np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3) for x in (cur, fn_old, tri_n))
    area_old = np.ascontiguousarray(area_old, dtype=np.float64).reshape(-1)
    moved, reg = (np.ascontiguousarray(x, dtype=np.bool_).reshape(-1) for x in (moved, reg))
    newtri, vtri = (np.ascontiguousarray(x, dtype=np.int64).reshape(-1) for x in (newtri, vtri))
    n = len(cur)
    if len(fn_old) != len(Fi) or len(area_old) != len(Fi) or not (len(moved) == len(reg) == len(newtri)
                                                                    == len(vtri) == n):
        raise ValueError("move_tests: fn_old/area_old one per face; moved, reg, newtri, vtri one per point")
    check_index("Fi", Fi, n)
    if max(newtri.max(initial=-1), vtri.max(initial=-1)) >= len(tri_n):
        raise ValueError(f"move_tests: input triangles must be below {len(tri_n)}")
    return _move_tests(cur, Fi, fn_old, area_old, moved, newtri, vtri, reg, tri_n, float(cosmax), float(cos_facing))


def edge_lengths(P, E):
    """``dot_norm_rows(P[E[:, 1]] - P[E[:, 0]])`` (einsum's norm of each edge vector, the same
    bits) without gathering the two ends' rows: ``P`` (n, 3) float64, ``E`` (k, 2) indices."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    E = np.ascontiguousarray(E, dtype=np.int64).reshape(-1, 2)
    check_index("E", E, len(P))
    return _edge_lengths(P, E)


def triangle_normals(P, F):
    """Unnormalised normals ``cross(P[F1] - P[F0], P[F2] - P[F0])`` of triangles ``F`` (k, >=3),
    the bits of ``mesh.cross_rows`` on the gathered corners."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    F = np.ascontiguousarray(np.asarray(F)[:, :3], dtype=np.int64)
    check_index("F", F, len(P))
    return _tri_normals(P, F)


def corner_sin_cos(A, B, C):
    """For triangles with corners ``A``, ``B``, ``C`` (k, 3): a (4, k) array of ``|u x v|`` and
    ``u . v`` at corner A (u = B - A, v = C - A) and at corner B (u = C - B, v = A - B), with
    the bits of ``norm(cross_rows(u, v))`` and ``einsum("ij,ij->i", u, v)`` (the arguments of
    the remesh's ``arctan2`` angles)."""
    A, B, C = (_rows3_any(x) for x in (A, B, C))
    if not (len(A) == len(B) == len(C)):
        raise ValueError("corner_sin_cos takes three (k, 3) arrays of the same length")
    return _corner_sin_cos(A, B, C)


def _rows3_any(x):
    """``x`` as (k, 3) float64 rows without a copy where it already is one, strided or not (the
    corners ``Q[:, j]`` of a (k, 3, 3) array): the compiled loops read any strides."""
    x = np.asarray(x)
    if x.dtype != np.float64 or x.ndim != 2 or x.shape[1] != 3:
        x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    return x


def facing_ok(F, kind, vtri, tri_n, nrm, cos_facing):
    """Per face ``F[i]`` (k, 3) with unit normal ``nrm[i]``: True unless the face has a corner
    v with ``kind[v] == 0`` and ``vtri[v] >= 0`` and, at every such corner, ``nrm[i] .
    tri_n[vtri[v]]`` is not above ``cos_facing`` (a NaN there counts as not above). The bits
    of the remesh's einsum formula."""
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    kind = np.ascontiguousarray(kind, dtype=np.int64)
    vtri = np.ascontiguousarray(vtri, dtype=np.int64)
    tri_n = np.ascontiguousarray(tri_n, dtype=np.float64).reshape(-1, 3)
    nrm = np.ascontiguousarray(nrm, dtype=np.float64).reshape(-1, 3)
    if len(nrm) != len(F) or len(vtri) != len(kind):
        raise ValueError("facing_ok: one normal per face and one kind per vertex triangle")
    check_index("F", F, len(kind))
    if len(vtri) and vtri.max(initial=-1) >= len(tri_n):
        raise ValueError(f"facing_ok: vertex triangles must be below {len(tri_n)}")
    return _facing_ok(F, kind, vtri, tri_n, nrm, float(cos_facing))
