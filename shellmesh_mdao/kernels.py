"""Compiled kernels (numba) for the loops numpy cannot vectorise, and for the small
per-element formulas that the stages evaluate thousands of times.

Everything else in the package is numpy on whole arrays. A few steps are sequential by
nature: a greedy independent set is built sub-round by sub-round, and each sub-round
depends on the one before. Written in numpy, every sub-round filters and gathers the
entries of every candidate still in play. On a 1.5M-triangle input that was most of the
remesh's time. Here the same result comes from one pass over the entries.

The others replace whole-array formulas whose temporaries and per-call overhead cost more
than the arithmetic: counting sorts for the stable argsorts of vertex ids, the smoothing's
orthogonality Jacobian and gradient and its reduced Hessian, the elements' corner scaled Jacobians, the closest
points on curves and triangles (and the bounding-volume hierarchy that finds the closest
points on the input skin, :class:`TriangleBVH`), the per-row vector formulas of the remesh, the imprint and
the smoother ("rows of three"), and the remesh's collapse and flip tests. Where numpy sums
three products (einsum, row norms) the loops sum them in numpy's order. Angles stay with
numpy: the loops hand back the arguments of its ``arctan2`` and ``arccos`` (on a machine
with AVX-512 numpy computes those with its own vector code, whose last bits differ from the
C library's that a compiled loop would call). The exception is :func:`collapse_select`, whose
tests run inside the greedy selection: its angle test uses the C library's atan2.

The functions are compiled on first use and cached on disk next to this file (numba's
``cache=True``; :func:`warm_up` does it ahead). Every result is the same, bit for bit, as
the numpy code it replaces (the tests compare the two; the exceptions are documented at
:func:`closest_on_triangles` and :func:`collapse_select`). The compiled loops do not check bounds, so the Python
wrappers check every index before handing it over.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from .core.threads import Background as _Background

__all__ = ["greedy_independent", "greedy_independent_rings", "common_neighbour_counts", "ortho_jacobian",
           "ortho_gradient", "ReducedHessian", "chain_walk", "arc_links", "arc_order", "centroid_d2", "corner_sums",
           "corner_max_turn", "segments_scan", "segments_within", "pair_difference", "min_corner_sj", "face_quality",
           "closest_on_curves", "closest_on_triangles", "TriangleBVH", "stable_order", "stable_pair_order",
           "group_order", "edge_neighbours", "vertex_faces", "rank_desc", "edge_table", "edge_rows", "edge_lookup",
           "cross_rows", "norm_rows", "dot_rows", "dot_norm_rows", "dot_unit_rows", "triangle_normals",
           "element_normals", "faces_at", "edge_lengths", "corner_sin_cos", "corner_cosines", "facing_ok",
           "collapse_directions", "collapse_apply", "collapse_select", "flip_candidates", "skin_flips", "star_moves",
           "move_tests", "safe_matching_rounds", "warm_up"]


# ============================================================================ independent sets
@njit(cache=True, nogil=True)
def _build(owner, res, alive, rank, ncand, nres):
    """CSR of the entries of the live candidates: per candidate its resources (``cptr``,
    ``cres``), per resource its candidates by falling rank (``rptr``, ``rcand``)."""
    ccnt = np.zeros(ncand + 1, np.int64)
    for e in range(owner.shape[0]):
        if alive[owner[e]]:
            ccnt[owner[e] + 1] += 1
    cptr = np.cumsum(ccnt)
    cres = np.empty(cptr[ncand], np.int64)
    cfill = cptr[:ncand].copy()
    for e in range(owner.shape[0]):
        c = owner[e]
        if alive[c]:
            cres[cfill[c]] = res[e]
            cfill[c] += 1
    rptr, rcand = _by_resource(cptr, cres, rank, ncand, nres)
    return cptr, cres, rptr, rcand


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
    rptr, rcand = _by_resource(cptr, cres, rank, ncand, nres)
    return cptr, cres, rptr, rcand


@njit(cache=True, nogil=True)
def _by_resource(cptr, cres, rank, ncand, nres):
    """Per resource its candidates by falling rank (``rank``: 1..ncand), filled candidate by
    candidate from the highest rank down, so no list needs sorting."""
    rcnt = np.zeros(nres + 1, np.int64)
    for k in range(cres.shape[0]):
        rcnt[cres[k] + 1] += 1
    rptr = np.cumsum(rcnt)
    by_rank = np.empty(ncand, np.int64)
    for c in range(ncand):
        by_rank[ncand - rank[c]] = c
    rcand = np.empty(rptr[nres], np.int64)
    rfill = rptr[:nres].copy()
    for i in range(ncand):
        c = by_rank[i]
        for k in range(cptr[c], cptr[c + 1]):
            r = cres[k]
            rcand[rfill[r]] = c
            rfill[r] += 1
    return rptr, rcand


@njit(cache=True, nogil=True)
def _top(r, rtop, rptr, rcand, resolved):
    """Highest-ranked candidate of resource ``r`` still in play (-1: none)."""
    p = rtop[r]
    end = rptr[r + 1]
    while p < end and resolved[rcand[p]]:
        p += 1
    rtop[r] = p
    return rcand[p] if p < end else -1


@njit(cache=True, nogil=True)
def _wins(c, cptr, cres, rtop, rptr, rcand, resolved):
    """True when ``c`` is the highest-ranked candidate in play on every one of its resources."""
    for k in range(cptr[c], cptr[c + 1]):
        if _top(cres[k], rtop, rptr, rcand, resolved) != c:
            return False
    return True


@njit(cache=True, nogil=True)
def _first_wave(cptr, cres, rtop, rptr, rcand, resolved, ncand):
    out = np.empty(ncand, np.int64)
    k = 0
    for c in range(ncand):
        if not resolved[c] and _wins(c, cptr, cres, rtop, rptr, rcand, resolved):
            out[k] = c
            k += 1
    return out[:k]


@njit(cache=True, nogil=True)
def _next_wave(win, acc, cptr, cres, rtop, rptr, rcand, resolved, seen, wave):
    """Resolve the winners ``win`` (``acc``: taken, else dropped), drop every candidate in
    play on a resource of a taken winner, and return the next sub-round's winners (sorted):
    only a new top of a resource of a resolved candidate can be one."""
    ncand = resolved.shape[0]
    new = np.empty(ncand, np.int64)
    nn = 0
    for i in range(win.shape[0]):
        resolved[win[i]] = True
        new[nn] = win[i]
        nn += 1
    for i in range(win.shape[0]):
        if acc[i]:
            c = win[i]
            for k in range(cptr[c], cptr[c + 1]):
                r = cres[k]
                for p in range(rtop[r], rptr[r + 1]):
                    d = rcand[p]
                    if not resolved[d]:
                        resolved[d] = True
                        new[nn] = d
                        nn += 1
    out = np.empty(ncand, np.int64)
    no = 0
    for i in range(nn):
        d = new[i]
        for k in range(cptr[d], cptr[d + 1]):
            t = _top(cres[k], rtop, rptr, rcand, resolved)
            if t >= 0 and seen[t] != wave:
                seen[t] = wave
                if _wins(t, cptr, cres, rtop, rptr, rcand, resolved):
                    out[no] = t
                    no += 1
    return np.sort(out[:no])


def _dense_rank(rank):
    """``rank`` as int64 1..n in the same order (unique ranks required)."""
    rank = np.ascontiguousarray(rank, dtype=np.int64)
    n = len(rank)
    if n and (rank.min() != 1 or rank.max() != n or not np.bincount(rank, minlength=n + 1)[1:].all()):
        if len(np.unique(rank)) != n:
            raise ValueError("greedy_independent needs a unique rank per candidate")
        dense = np.empty(n, np.int64)
        dense[np.argsort(rank, kind="stable")] = np.arange(1, n + 1)
        rank = dense
    return rank


def _waves(cptr, cres, rptr, rcand, alive, check, max_sub):
    """The sub-rounds: the first wave from a scan of all candidates, each next one from the
    resources the last one resolved; ``check`` sees each wave's winners in increasing order."""
    ncand = len(alive)
    sel = np.zeros(ncand, bool)
    rtop = rptr[:-1].copy()
    resolved = ~alive
    seen = np.full(ncand, -1, np.int64)
    win = _first_wave(cptr, cres, rtop, rptr, rcand, resolved, ncand)
    for wave in range(max_sub):
        if not len(win):
            break
        good = np.ones(len(win), bool) if check is None else np.asarray(check(win), dtype=np.bool_)
        sel[win[good]] = True
        if wave + 1 == max_sub:
            break
        win = _next_wave(win, good, cptr, cres, rtop, rptr, rcand, resolved, seen, wave)
    return sel


@njit(cache=True, nogil=True)
def _in_range(a, n):
    """Whether every entry of the non-empty int64 vector ``a`` is in [0, n): its least and
    largest entry in one pass (a loop without branches, which the compiler vectorises: 5 us
    for 60k entries, against 12 us for numpy's min and max)."""
    mn = a[0]
    mx = a[0]
    for i in range(a.shape[0]):
        x = a[i]
        mn = min(mn, x)
        mx = max(mx, x)
    return mn >= 0 and mx < n


def _check_index(name, a, n):
    if not len(a):
        return
    ok = (_in_range(a.reshape(-1), n) if a.dtype == np.int64 and a.flags.c_contiguous
          else not (a.min() < 0 or a.max() >= n))
    if not ok:
        raise ValueError(f"{name} holds indices outside [0, {n}): {int(a.min())}..{int(a.max())}")


def _check_csr(nptr, nbr):
    n = len(nptr) - 1
    if n < 0 or (n and (nptr[0] != 0 or nptr[-1] != len(nbr) or (np.diff(nptr) < 0).any())):
        raise ValueError("nptr must be CSR row pointers into nbr: start at 0, never decrease, end at len(nbr)")
    _check_index("nbr", nbr, n)


def _select(build, rank, alive, check, max_sub):
    """Dense ranks, live mask, ``build(alive, rank, ncand)`` -> the CSR tables, then the waves."""
    rank = _dense_rank(rank)
    ncand = len(rank)
    if not ncand:
        return np.zeros(0, bool)
    alive = np.ones(ncand, bool) if alive is None else np.ascontiguousarray(alive, dtype=np.bool_)
    cptr, cres, rptr, rcand = build(alive, rank, ncand)
    return _waves(cptr, cres, rptr, rcand, alive, check, max_sub)


def greedy_independent(owner, res, rank, nres, *, alive=None, check=None, max_sub=12):
    """Greedy maximal independent set of candidates over shared resources.

    Candidate ``owner[i]`` uses resource ``res[i]`` (``0 <= res < nres``); ``rank`` is a unique
    integer per candidate (higher first; 1..ncand is fastest); ``alive`` (bool per
    candidate, default all) leaves the others out. Sub-round by sub-round (at most
    ``max_sub``), every candidate in play that outranks every other candidate in play on
    each of its resources wins; ``check(winners) -> bool array`` (default: all True) keeps
    some of them. A kept winner takes its resources and every other candidate on them drops
    out; a winner not kept just drops out. Returns the bool mask of the kept winners.

    The same sets as running the sub-rounds on whole arrays (select the local maxima, drop
    what touches a taken resource, repeat), but each entry is visited a bounded number of
    times instead of once per sub-round."""
    owner = np.ascontiguousarray(owner, dtype=np.int64)
    res = np.ascontiguousarray(res, dtype=np.int64)
    _check_index("owner", owner, len(rank))
    _check_index("res", res, int(nres))
    if len(owner) != len(res):
        raise ValueError(f"owner and res need one entry each per use, got {len(owner)} and {len(res)}")
    return _select(lambda alive, rank, ncand: _build(owner, res, alive, rank, ncand, int(nres)),
                   rank, alive, check, max_sub)


def greedy_independent_rings(nptr, nbr, u, v, rank, *, alive=None, check=None, max_sub=12):
    """:func:`greedy_independent` where candidate ``c`` uses the vertices of the neighbour
    lists of ``u[c]`` and ``v[c]`` (graph CSR ``nptr``, ``nbr``; for an edge ``(u, v)`` the
    closed 1-rings of both ends), without listing those entries in memory first."""
    nptr, nbr, u, v = (np.ascontiguousarray(x, dtype=np.int64) for x in (nptr, nbr, u, v))
    _check_csr(nptr, nbr)
    _check_index("u", u, len(nptr) - 1)
    _check_index("v", v, len(nptr) - 1)
    if not len(u) == len(v) == len(rank):
        raise ValueError(f"u, v and rank need one entry per candidate, got {len(u)}, {len(v)} and {len(rank)}")
    return _select(lambda alive, rank, ncand: _build_rings(nptr, nbr, u, v, alive, rank, ncand, len(nptr) - 1),
                   rank, alive, check, max_sub)


@njit(cache=True, nogil=True)
def _other_gain(t, e, best1, best2, g):
    """The best gain at triangle ``t`` of an edge other than ``e`` (0 for none)."""
    b = best2[t] if best1[t] == e else best1[t]
    return g[b] if b >= 0 else 0.0


@njit(cache=True, nogil=True)
def _safe_rounds(f0, f1, g, rank, n_faces, max_rounds):
    k = g.shape[0]
    taken = np.zeros(k, np.bool_)
    active = np.ones(k, np.bool_)
    matched = np.zeros(n_faces, np.bool_)
    safe = np.zeros(k, np.bool_)
    best1 = np.full(n_faces, -1, np.int64)          # the live edge of least rank at each triangle
    best2 = np.full(n_faces, -1, np.int64)          # and the next
    bs = np.full(n_faces, k, np.int64)              # the least rank of a safe edge there
    for _ in range(max_rounds):
        nact = 0
        for e in range(k):
            if active[e]:
                nact += 1
                for t in (f0[e], f1[e]):
                    if best1[t] < 0 or rank[e] < rank[best1[t]]:
                        best2[t] = best1[t]
                        best1[t] = e
                    elif best2[t] < 0 or rank[e] < rank[best2[t]]:
                        best2[t] = e
        if nact == 0:
            break
        nsafe = 0
        for e in range(k):
            safe[e] = False
            if active[e] and g[e] >= _other_gain(f0[e], e, best1, best2, g) + _other_gain(f1[e], e, best1, best2, g):
                safe[e] = True
                nsafe += 1
                for t in (f0[e], f1[e]):
                    if rank[e] < bs[t]:
                        bs[t] = rank[e]
        if nsafe == 0:
            break
        for e in range(k):
            if safe[e] and bs[f0[e]] == rank[e] and bs[f1[e]] == rank[e]:
                taken[e] = True
                matched[f0[e]] = True
                matched[f1[e]] = True
        for e in range(k):                          # clear the tables, drop the edges now blocked
            if active[e]:
                for t in (f0[e], f1[e]):
                    best1[t] = -1
                    best2[t] = -1
                    bs[t] = k
                if matched[f0[e]] or matched[f1[e]]:
                    active[e] = False
    return taken, active


def safe_matching_rounds(f0, f1, w, n_faces, max_rounds: int = 100):
    """The merge's exact reduction (:func:`shellmesh_mdao.merge._safe_reduction`) in compiled
    rounds: edges ``(f0[i], f1[i])`` between triangles (``f0 != f1``, in [0, n_faces)) with
    weights ``w`` (gain ``-w``), ranked by weight then index. Each round, an edge whose gain is
    at least the best other gain at its first triangle plus that at its second (0 where there
    is none; "best" by rank) is safe; a safe edge that is the best-ranked safe edge at both its
    triangles is taken, and every edge at a taken triangle leaves. Until no edge is left, none
    is safe or ``max_rounds``. Returns ``(taken, remaining)`` masks; the vectorised numpy rounds'
    masks, bit for bit (the sums and comparisons are the same)."""
    f0 = np.ascontiguousarray(f0, dtype=np.int64).reshape(-1)
    f1 = np.ascontiguousarray(f1, dtype=np.int64).reshape(-1)
    w = np.ascontiguousarray(w, dtype=np.float64).reshape(-1)
    k = len(w)
    if not len(f0) == len(f1) == k:
        raise ValueError(f"safe_matching_rounds: f0, f1 and w need one entry per edge, got {len(f0)}, {len(f1)}, {k}")
    _check_index("f0", f0, int(n_faces))
    _check_index("f1", f1, int(n_faces))
    rank = np.empty(k, dtype=np.int64)
    rank[np.lexsort((np.arange(k), w))] = np.arange(k)
    return _safe_rounds(f0, f1, -w, rank, int(n_faces), int(max_rounds))


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
    _check_index("u", u, len(nptr) - 1)
    _check_index("v", v, len(nptr) - 1)
    if len(u) != len(v):
        raise ValueError(f"u and v need the same length, got {len(u)} and {len(v)}")
    return _common(nptr, nbr, u, v, len(nptr) - 1)


# ============================================================================ smoothing
@njit(cache=True, nogil=True)
def _ortho_jacobian(a, b, c, n, su, sv, sw, col_start, ncol, tv):
    m = a.shape[0]
    indptr = np.zeros(3 * m + 1, np.int64)
    for q in range(m):
        cnt = ncol[a[q]] + ncol[b[q]] + ncol[c[q]]
        for d in range(3):
            indptr[3 * q + d + 1] = indptr[3 * q + d] + cnt
    nnz = indptr[3 * m]
    data = np.empty(nnz, np.float64)
    indices = np.empty(nnz, np.int64)
    vs = np.empty(3, np.int64)
    order = np.empty(3, np.int64)
    vec = np.empty(3, np.float64)
    for q in range(m):
        vs[0], vs[1], vs[2] = a[q], b[q], c[q]
        # the three roles in order of their first column (each vertex owns a contiguous
        # range): a stable sort of three keys
        order[0], order[1], order[2] = 0, 1, 2
        for i in range(1, 3):
            j = i
            while j > 0 and col_start[vs[order[j - 1]]] > col_start[vs[order[j]]]:
                order[j - 1], order[j] = order[j], order[j - 1]
                j -= 1
        k = 0
        for o in range(3):
            role = order[o]
            v = vs[role]
            for jc in range(ncol[v]):
                col = col_start[v] + jc
                t0, t1, t2 = tv[col, 0], tv[col, 1], tv[col, 2]
                if role == 0:
                    vec[0], vec[1], vec[2] = su[q] * t0, su[q] * t1, su[q] * t2
                else:
                    n0, n1, n2 = n[q, 0], n[q, 1], n[q, 2]
                    x0 = n1 * t2 - n2 * t1
                    x1 = n2 * t0 - n0 * t2
                    x2 = n0 * t1 - n1 * t0
                    if role == 1:
                        vec[0] = -su[q] * t0 + sv[q] * x0
                        vec[1] = -su[q] * t1 + sv[q] * x1
                        vec[2] = -su[q] * t2 + sv[q] * x2
                    else:
                        vec[0], vec[1], vec[2] = -sv[q] * x0, -sv[q] * x1, -sv[q] * x2
                for d in range(3):
                    p = indptr[3 * q + d] + k
                    data[p] = vec[d] * sw[q]
                    indices[p] = col
                k += 1
    return data, indices, indptr


def ortho_jacobian(a, b, c, n, su, sv, sw, col_start, ncol, tv):
    """Jacobian of the quad-corner orthogonality residuals (:class:`~shellmesh_mdao.smooth._Ortho`)
    in reduced coordinates, as CSR arrays ``(data, indices, indptr)`` of shape ``(3 m, k)``.

    Corner ``q`` has previous, own and next vertex ``a[q]``, ``b[q]``, ``c[q]``, unit quad
    normal ``n[q]``, inverse arm lengths ``su[q]``, ``sv[q]`` and weight root ``sw[q]``; its
    residual is ``M_a a + M_b b + M_c c`` with ``M_a = su I``, ``M_b = -su I + sv [n]x``,
    ``M_c = -sv [n]x``. Vertex ``v`` owns the reduced columns ``col_start[v] ..
    col_start[v] + ncol[v] - 1`` with tangent vectors ``tv`` (k, 3). Rows ``3 q .. 3 q + 2``
    hold ``M_role @ tv[col] * sw[q]`` for every column of the three vertices, columns sorted
    (the canonical CSR that scipy builds from the same entries, value for value)."""
    col_start = np.ascontiguousarray(col_start, dtype=np.int64)
    ncol = np.ascontiguousarray(ncol, dtype=np.int64)
    tv = np.ascontiguousarray(tv, dtype=np.float64).reshape(-1, 3)
    nv = len(col_start)
    a, b, c, n, su, sv, sw = _corners(a, b, c, n, su, sv, sw, nv)
    if len(ncol) != nv or (len(ncol) and (ncol.min() < 0 or ncol.max() > 3)):
        raise ValueError("ncol must give 0 to 3 columns for each vertex of col_start")
    own = ncol > 0
    if own.any() and (col_start[own].min() < 0 or (col_start + ncol)[own].max() > len(tv)):
        raise ValueError(f"the columns of col_start/ncol must lie in 0..{len(tv) - 1} (rows of tv)")
    return _ortho_jacobian(a, b, c, n, su, sv, sw, col_start, ncol, tv)


def _corners(a, b, c, n, su, sv, w, nv):
    """The corner arrays of the orthogonality kernels, contiguous and checked: vertex ids
    ``a``, ``b``, ``c`` in [0, nv), and one normal and three factors per corner."""
    a, b, c = (np.ascontiguousarray(v, dtype=np.int64).reshape(-1) for v in (a, b, c))
    m = len(a)
    f = [np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in (su, sv, w)]
    n = np.ascontiguousarray(n, dtype=np.float64).reshape(-1, 3)
    if len(b) != m or len(c) != m or len(n) != m or any(len(v) != m for v in f):
        raise ValueError("a, b, c, n, su, sv and w must have one entry per corner")
    for name, v in (("a", a), ("b", b), ("c", c)):
        _check_index(name, v, nv)
    return a, b, c, n, f[0], f[1], f[2]


@njit(cache=True, nogil=True)
def _ortho_gradient(a, b, c, n, su, sv, w, x, nv):
    ga = np.zeros((nv, 3))
    gb = np.zeros((nv, 3))
    gc = np.zeros((nv, 3))
    for q in range(a.shape[0]):
        ia, ib, ic = a[q], b[q], c[q]
        n0, n1, n2 = n[q, 0], n[q, 1], n[q, 2]
        u0, u1, u2 = x[ic, 0] - x[ib, 0], x[ic, 1] - x[ib, 1], x[ic, 2] - x[ib, 2]
        k0, k1, k2 = n1 * u2 - n2 * u1, n2 * u0 - n0 * u2, n0 * u1 - n1 * u0
        r0 = su[q] * (x[ia, 0] - x[ib, 0]) - sv[q] * k0
        r1 = su[q] * (x[ia, 1] - x[ib, 1]) - sv[q] * k1
        r2 = su[q] * (x[ia, 2] - x[ib, 2]) - sv[q] * k2
        w0, w1, w2 = w[q] * r0, w[q] * r1, w[q] * r2
        m0, m1, m2 = n1 * w2 - n2 * w1, n2 * w0 - n0 * w2, n0 * w1 - n1 * w0
        ga[ia, 0] += su[q] * w0
        ga[ia, 1] += su[q] * w1
        ga[ia, 2] += su[q] * w2
        gb[ib, 0] += -su[q] * w0 - sv[q] * m0
        gb[ib, 1] += -su[q] * w1 - sv[q] * m1
        gb[ib, 2] += -su[q] * w2 - sv[q] * m2
        gc[ic, 0] += sv[q] * m0
        gc[ic, 1] += sv[q] * m1
        gc[ic, 2] += sv[q] * m2
    for v in range(nv):
        for d in range(3):
            ga[v, d] = (ga[v, d] + gb[v, d]) + gc[v, d]
    return ga


def ortho_gradient(a, b, c, n, su, sv, w, x, nv):
    """Gradient (nv, 3) of ``1/2 sum_q w[q] |r_q|^2`` at positions ``x`` (nv, 3), with the
    corner residuals ``r_q = su (x_a - x_b) - sv n x (x_c - x_b)`` of
    :func:`ortho_jacobian` (``a``, ``b``, ``c``, ``n``, ``su``, ``sv`` as there). The same
    bits as the numpy version of :meth:`~shellmesh_mdao.smooth._Ortho.gradient`: each role's
    terms summed over the corners in order (``np.bincount``), then the three roles added."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    nv = int(nv)
    if len(x) != nv:
        raise ValueError(f"x must hold the nv = {nv} positions")
    a, b, c, n, su, sv, w = _corners(a, b, c, n, su, sv, w, nv)
    return _ortho_gradient(a, b, c, n, su, sv, w, x, nv)


# ============================================================================ polylines
@njit(cache=True, nogil=True)
def _chain_walk(e, n):
    k = e.shape[0]
    deg = np.zeros(n, np.int64)
    for i in range(k):
        deg[e[i, 0]] += 1
        deg[e[i, 1]] += 1
    ptr = np.zeros(n + 1, np.int64)
    for v in range(n):
        ptr[v + 1] = ptr[v] + deg[v]
    inc = np.empty(ptr[n], np.int64)
    fill = ptr[:n].copy()
    for i in range(k):                     # each node's edges by rising edge id
        inc[fill[e[i, 0]]] = i
        fill[e[i, 0]] += 1
        inc[fill[e[i, 1]]] = i
        fill[e[i, 1]] += 1
    seen = np.zeros(k, np.bool_)
    nodes = np.empty(2 * k + k, np.int64)
    optr = np.zeros(k + 1, np.int64)
    closed = np.zeros(k, np.bool_)
    fwd = np.empty(k + 1, np.int64)
    bwd = np.empty(k + 1, np.int64)
    fe = np.empty(k + 1, np.int64)                  # a loop's nodes, before its rotation
    nc = 0
    m = 0
    for i in range(k):
        if seen[i]:
            continue
        # the chain of edge i: walk on through nodes of degree 2 from both of its ends
        seen[i] = True
        a, b = e[i, 0], e[i, 1]
        nf = 0
        fwd[0] = b
        cur, pe = b, i
        cyc = False
        while deg[cur] == 2:
            ne = inc[ptr[cur]] if inc[ptr[cur]] != pe else inc[ptr[cur] + 1]
            if ne == i:
                cyc = True
                break
            seen[ne] = True
            cur = e[ne, 1] if e[ne, 0] == cur else e[ne, 0]
            pe = ne
            nf += 1
            fwd[nf] = cur
        fe_last = pe                       # the edge that ends the forward walk
        nb = 0
        bwd[0] = a
        be_last = i
        if not cyc:
            cur, pe = a, i
            while deg[cur] == 2:
                ne = inc[ptr[cur]] if inc[ptr[cur]] != pe else inc[ptr[cur] + 1]
                seen[ne] = True
                cur = e[ne, 1] if e[ne, 0] == cur else e[ne, 0]
                pe = ne
                nb += 1
                bwd[nb] = cur
            be_last = pe
        # the sequence: bwd reversed, then fwd (a chain of len nb + nf + 2 nodes)
        L = nb + 1 + nf + 1
        s = m
        for t in range(nb + 1):
            nodes[s + t] = bwd[nb - t]
        for t in range(nf + 1):
            nodes[s + nb + 1 + t] = fwd[t]
        if cyc:
            # a loop: from its lowest node, first towards the lower of that node's two neighbours
            L -= 1                         # the walk came back to its start: drop the repeat
            lo = 0
            for t in range(1, L):
                if nodes[s + t] < nodes[s + lo]:
                    lo = t
            nx = nodes[s + (lo + 1) % L]
            pv = nodes[s + (lo - 1 + L) % L]
            for t in range(L):
                fe[t] = nodes[s + t]
            for t in range(L):
                if nx < pv:
                    nodes[s + t] = fe[(lo + t) % L]
                else:
                    nodes[s + t] = fe[(lo - t + L) % L]
            closed[nc] = True
        else:
            # a path between two break nodes: from the lower one; from the end of the lower
            # edge where both ends are one node
            first, last = nodes[s], nodes[s + L - 1]
            rev = last < first or (last == first and fe_last < be_last)
            if rev:
                for t in range(L // 2):
                    x = nodes[s + t]
                    nodes[s + t] = nodes[s + L - 1 - t]
                    nodes[s + L - 1 - t] = x
        m += L
        nc += 1
        optr[nc] = m
    return nodes[:m], optr[:nc + 1], closed[:nc]


def chain_walk(edges, n):
    """The polylines of an edge graph: chains of edges broken at every node whose degree is
    not 2, and loops. ``edges`` (k, 2): distinct sorted rows of node ids in [0, n), no
    self-loops. Returns ``(nodes, ptr, closed)``: chain ``c`` is ``nodes[ptr[c]:ptr[c + 1]]``,
    ``closed[c]`` for a loop (its first node not repeated). Chains come in the order of their
    lowest edge; a path runs from its lower end node (from the end of its lower edge where
    both ends are one node), a loop from its lowest node towards the lower of that node's two
    neighbours (the walks of scipy's ``depth_first_order`` on the graph with the break nodes
    split, which :func:`~shellmesh_mdao.smooth.polylines_from_edges` used)."""
    e = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    n = int(n)
    _check_index("edges", e.ravel(), n)
    if len(e) and ((e[:, 0] >= e[:, 1]).any() or (len(e) > 1 and not (np.diff(e[:, 0] * n + e[:, 1]) > 0).all())):
        raise ValueError("edges must be distinct rows (u, v) with u < v, sorted")
    return _chain_walk(e, n)


@njit(cache=True, nogil=True)
def _incidence(u, v, nn):
    """Per node the links at it, by rising link id (CSR)."""
    ptr = np.zeros(nn + 1, np.int64)
    for e in range(u.shape[0]):
        ptr[u[e] + 1] += 1
        ptr[v[e] + 1] += 1
    for i in range(nn):
        ptr[i + 1] += ptr[i]
    inc = np.empty(ptr[nn], np.int64)
    fill = ptr[:nn].copy()
    for e in range(u.shape[0]):
        inc[fill[u[e]]] = e
        fill[u[e]] += 1
        inc[fill[v[e]]] = e
        fill[v[e]] += 1
    return ptr, inc


@njit(cache=True, nogil=True)
def _link_component(u, v, nn, best):
    ptr, inc = _incidence(u, v, nn)
    seen_node = np.zeros(nn, np.bool_)
    in_comp = np.zeros(u.shape[0], np.bool_)
    stack = np.empty(nn, np.int64)
    stack[0] = u[best]
    seen_node[u[best]] = True
    top = 1
    while top > 0:
        top -= 1
        x = stack[top]
        for p in range(ptr[x], ptr[x + 1]):
            e = inc[p]
            in_comp[e] = True
            y = v[e] if u[e] == x else u[e]
            if not seen_node[y]:
                seen_node[y] = True
                stack[top] = y
                top += 1
    return in_comp


@njit(cache=True, nogil=True)
def _arc_order(lu, lv, nn, start):
    # each node's neighbours by rising id, a repeated link once with the sum of its ids + 1
    # (the symmetric CSR matrix of the links' ids + 1, as scipy builds and sums it)
    L = lu.shape[0]
    lo = np.empty(2 * L, np.int64)
    hi = np.empty(2 * L, np.int64)
    val = np.empty(2 * L, np.int64)
    for e in range(L):
        lo[2 * e], hi[2 * e], val[2 * e] = lu[e], lv[e], e + 1
        lo[2 * e + 1], hi[2 * e + 1], val[2 * e + 1] = lv[e], lu[e], e + 1
    key = lo * nn + hi
    o = np.argsort(key, kind="mergesort")
    ptr = np.zeros(nn + 1, np.int64)
    nbr = np.empty(2 * L, np.int64)
    w = np.empty(2 * L, np.int64)
    m = 0
    for t in range(2 * L):
        i = o[t]
        if m > 0 and t > 0 and key[o[t - 1]] == key[i]:
            w[m - 1] += val[i]
            continue
        nbr[m], w[m] = hi[i], val[i]
        ptr[lo[i] + 1] += 1
        m += 1
    for i in range(nn):
        ptr[i + 1] += ptr[i]
    # depth-first order from start, the lowest unvisited neighbour first (scipy's walk)
    seen = np.zeros(nn, np.bool_)
    order = np.empty(nn, np.int64)
    seg = np.empty(nn, np.int64)
    root = np.empty(nn, np.int64)
    order[0] = start
    seen[start] = True
    root[0] = start
    r = 0
    k = 1
    while r >= 0:
        x = root[r]
        moved = False
        for p in range(ptr[x], ptr[x + 1]):
            y = nbr[p]
            if not seen[y]:
                seen[y] = True
                if order[k - 1] == x:
                    seg[k - 1] = w[p] - 1
                else:                      # after a dead end: the matrix entry of the two nodes
                    seg[k - 1] = -1
                    z = order[k - 1]
                    for q in range(ptr[z], ptr[z + 1]):
                        if nbr[q] == y:
                            seg[k - 1] = w[q] - 1
                order[k] = y
                k += 1
                r += 1
                root[r] = y
                moved = True
                break
        if not moved:
            r -= 1
    return order[:k], seg[:k - 1]


def arc_links(u, v, nn, best):
    """The links ``(u[e], v[e])`` (node ids in [0, nn)) connected to link ``best``: a bool
    mask (a walk over the links at each node)."""
    u, v = (np.ascontiguousarray(x, dtype=np.int64).reshape(-1) for x in (u, v))
    if len(u) != len(v) or not (0 <= int(best) < len(u)):
        raise ValueError("arc_links needs as many u as v and best among them")
    _check_index("u", u, int(nn))
    _check_index("v", v, int(nn))
    return _link_component(u, v, int(nn), int(best))


def arc_order(lu, lv, nn, start):
    """The depth-first order of the graph of the links ``(lu[e], lv[e])`` from node ``start``,
    the lowest unvisited neighbour first (scipy's ``depth_first_order`` on the symmetric link
    matrix), and for each pair of consecutive nodes of that order the link between them: the
    entry of the symmetric matrix of link ids + 1, minus 1 (a link repeated between two nodes
    gives the sum of their ids + 1, minus 1; two nodes without a link -1), as
    ``section.section_arc`` read it from that matrix."""
    lu, lv = (np.ascontiguousarray(x, dtype=np.int64).reshape(-1) for x in (lu, lv))
    if len(lu) != len(lv):
        raise ValueError("arc_order needs as many lu as lv")
    _check_index("lu", lu, int(nn))
    _check_index("lv", lv, int(nn))
    _check_index("start", np.array([int(start)]), int(nn))
    return _arc_order(lu, lv, int(nn), int(start))


# ============================================================================ smoothing Hessian
@njit(cache=True, nogil=True, inline="always")
def _couple(u, v, cnt, adj, fill, fill_pass):
    """Count (first pass) or list (second pass) ``v`` in ``u``'s adjacency row."""
    if fill_pass:
        adj[fill[u]] = v
        fill[u] += 1
    else:
        cnt[u + 1] += 1


@njit(cache=True, nogil=True)
def _couples(pu, pv, quads, ncol, cnt, adj, fill, fill_pass):
    """Every couple of vertices with columns: each with itself, the ends of each pair (both
    ways), the corners of each quad."""
    for v in range(ncol.shape[0]):
        if ncol[v] > 0:
            _couple(v, v, cnt, adj, fill, fill_pass)
    for e in range(pu.shape[0]):
        u, v = pu[e], pv[e]
        if u != v and ncol[u] > 0 and ncol[v] > 0:
            _couple(u, v, cnt, adj, fill, fill_pass)
            _couple(v, u, cnt, adj, fill, fill_pass)
    for q in range(quads.shape[0]):
        for i in range(4):
            u = quads[q, i]
            if ncol[u] > 0:
                for j in range(4):
                    v = quads[q, j]
                    if v != u and ncol[v] > 0:
                        _couple(u, v, cnt, adj, fill, fill_pass)


@njit(cache=True, nogil=True)
def _hessian_pattern(pu, pv, quads, ncol, col_start):
    n = ncol.shape[0]
    cnt = np.zeros(n + 1, np.int64)
    none = np.zeros(0, np.int64)
    _couples(pu, pv, quads, ncol, cnt, none, none, False)
    ptr = np.cumsum(cnt)
    adj = np.empty(ptr[n], np.int64)
    fill = ptr[:n].copy()
    _couples(pu, pv, quads, ncol, cnt, adj, fill, True)
    # each row sorted, repeats dropped
    vptr = np.zeros(n + 1, np.int64)
    vadj = np.empty(ptr[n], np.int64)
    m = 0
    for u in range(n):
        row = np.sort(adj[ptr[u]:ptr[u + 1]])
        for t in range(row.shape[0]):
            if t == 0 or row[t] != row[t - 1]:
                vadj[m] = row[t]
                m += 1
        vptr[u + 1] = m
    vadj = vadj[:m]
    # each neighbour's first column within the row, and the reduced rows
    aoff = np.empty(m, np.int64)
    k = 0
    for u in range(n):
        k += ncol[u]
    indptr = np.zeros(k + 1, np.int64)
    for u in range(n):
        w = 0
        for e in range(vptr[u], vptr[u + 1]):
            aoff[e] = w
            w += ncol[vadj[e]]
        for c in range(ncol[u]):
            r = col_start[u] + c
            indptr[r + 1] = w
    for r in range(k):
        indptr[r + 1] += indptr[r]
    indices = np.empty(indptr[k], np.int64)
    for u in range(n):
        for c in range(ncol[u]):
            p = indptr[col_start[u] + c]
            for e in range(vptr[u], vptr[u + 1]):
                v = vadj[e]
                for cv in range(ncol[v]):
                    indices[p] = col_start[v] + cv
                    p += 1
    return vptr, vadj, aoff, indptr, indices


@njit(cache=True, nogil=True, inline="always")
def _slot(vptr, vadj, u, v):
    """Position of ``v`` in ``u``'s sorted adjacency row (``v`` must be there)."""
    lo, hi = vptr[u], vptr[u + 1]
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if vadj[mid] <= v:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True, nogil=True)
def _hessian_slots(vptr, vadj, pu, pv, quads, ncol):
    """Adjacency positions of each pair (``u`` -> ``v``, ``v`` -> ``u``), of each vertex to
    itself and of each quad's 16 corner couples (-1 where a vertex has no columns)."""
    n = ncol.shape[0]
    dslot = np.full(n, -1, np.int64)
    for u in range(n):
        if ncol[u] > 0:
            dslot[u] = _slot(vptr, vadj, u, u)
    pslot = np.full((pu.shape[0], 2), -1, np.int64)
    for e in range(pu.shape[0]):
        u, v = pu[e], pv[e]
        if u != v and ncol[u] > 0 and ncol[v] > 0:
            pslot[e, 0] = _slot(vptr, vadj, u, v)
            pslot[e, 1] = _slot(vptr, vadj, v, u)
    qslot = np.full((quads.shape[0], 4, 4), -1, np.int64)
    for q in range(quads.shape[0]):
        for i in range(4):
            u = quads[q, i]
            if ncol[u] > 0:
                for j in range(4):
                    v = quads[q, j]
                    if ncol[v] > 0:
                        qslot[q, i, j] = _slot(vptr, vadj, u, v)
    return dslot, pslot, qslot


@njit(cache=True, nogil=True, inline="always")
def _scatter(data, indptr, aoff, col_start, ncol, u, v, e, B, bu, bv, f):
    """data[rows of u, columns of v] += f * B[bu + cu, bv + cv] (``e`` the position of ``v``
    in ``u``'s adjacency row)."""
    for cu in range(ncol[u]):
        base = indptr[col_start[u] + cu] + aoff[e]
        for cv in range(ncol[v]):
            data[base + cv] += f * B[bu + cu, bv + cv]


@njit(cache=True, nogil=True)
def _hessian_values(data, indptr, aoff, dslot, pslot, qslot, col_start, ncol, tv, pu, pv, pw, quads, on, osu, osv,
                    osw, fo, wrow, wm, wsw, fw, rho, v0, v1):
    """Adds the Hessian's values into the rows of the vertices ``v0 <= x < v1`` of ``data``
    (zeros): every entry gets the same terms in the same order whatever the range, so two
    calls on two ranges in two threads give the bits of one call on all vertices."""
    G = np.zeros((6, 6), np.float64)
    # edge pairs: pw (e_u - e_v)(e_u - e_v)^T (x) I in the tangent columns: the Gram matrix of
    # the two vertices' tangent vectors, +pw on the own blocks and -pw on the mixed ones
    for e in range(pu.shape[0]):
        u, v = pu[e], pv[e]
        inu, inv = v0 <= u < v1, v0 <= v < v1
        if not (inu or inv):
            continue
        for r in range(2):
            x = u if r == 0 else v
            for c in range(ncol[x]):
                for r2 in range(2):
                    y = u if r2 == 0 else v
                    for c2 in range(ncol[y]):
                        i, j = col_start[x] + c, col_start[y] + c2
                        G[3 * r + c, 3 * r2 + c2] = tv[i, 0] * tv[j, 0] + tv[i, 1] * tv[j, 1] + tv[i, 2] * tv[j, 2]
        if ncol[u] > 0 and inu:
            _scatter(data, indptr, aoff, col_start, ncol, u, u, dslot[u], G, 0, 0, pw[e])
        if ncol[v] > 0 and inv:
            _scatter(data, indptr, aoff, col_start, ncol, v, v, dslot[v], G, 3, 3, pw[e])
        if pslot[e, 0] >= 0:
            if inu:
                _scatter(data, indptr, aoff, col_start, ncol, u, v, pslot[e, 0], G, 0, 3, -pw[e])
            if inv:
                _scatter(data, indptr, aoff, col_start, ncol, v, u, pslot[e, 1], G, 3, 0, -pw[e])
    # the quads: orthogonality corners (rows sqrt(w) M_role tv of roles a, b, c, as in
    # ortho_jacobian) and planarity rows (sigma_k sw (m_k . tv)), summed per quad into a
    # 12 x 12 block over its four vertices' columns (the rows of the corners in the range
    # only), then added to the matrix
    B = np.zeros((12, 12), np.float64)
    J = np.zeros((12, 3), np.float64)
    Jw = np.zeros(12, np.float64)
    mine = np.zeros(4, np.bool_)
    for q in range(quads.shape[0]):
        anyin = False
        for i in range(4):
            mine[i] = v0 <= quads[q, i] < v1
            anyin = anyin or mine[i]
        if not anyin:
            continue
        B[:, :] = 0.0
        if on.shape[0]:
            for kk in range(4):
                o = 4 * q + kk
                n0, n1, n2 = on[o, 0], on[o, 1], on[o, 2]
                su, sv, sw = osu[o], osv[o], osw[o]
                for r in range(3):
                    lv = (kk + r + 3) % 4              # a, b, c: the previous, own and next corner
                    x = quads[q, lv]
                    for c in range(ncol[x]):
                        t0, t1, t2 = tv[col_start[x] + c, 0], tv[col_start[x] + c, 1], tv[col_start[x] + c, 2]
                        k0, k1, k2 = n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0
                        if r == 0:
                            j0, j1, j2 = su * t0, su * t1, su * t2
                        elif r == 1:
                            j0, j1, j2 = -su * t0 + sv * k0, -su * t1 + sv * k1, -su * t2 + sv * k2
                        else:
                            j0, j1, j2 = -sv * k0, -sv * k1, -sv * k2
                        J[3 * lv + c, 0], J[3 * lv + c, 1], J[3 * lv + c, 2] = j0 * sw, j1 * sw, j2 * sw
                for r in range(3):
                    lv = (kk + r + 3) % 4
                    if not mine[lv]:
                        continue
                    x = quads[q, lv]
                    for r2 in range(3):
                        lv2 = (kk + r2 + 3) % 4
                        y = quads[q, lv2]
                        for c in range(ncol[x]):
                            for c2 in range(ncol[y]):
                                a_, b_ = 3 * lv + c, 3 * lv2 + c2
                                B[a_, b_] += fo * (J[a_, 0] * J[b_, 0] + J[a_, 1] * J[b_, 1] + J[a_, 2] * J[b_, 2])
        w = wrow[q]
        if w >= 0:
            for kk in range(4):
                x = quads[q, kk]
                sg = 1.0 if kk % 2 == 0 else -1.0
                for c in range(ncol[x]):
                    col = col_start[x] + c
                    Jw[3 * kk + c] = sg * wsw[w] * (wm[w, kk, 0] * tv[col, 0] + wm[w, kk, 1] * tv[col, 1]
                                                    + wm[w, kk, 2] * tv[col, 2])
            for kk in range(4):
                if not mine[kk]:
                    continue
                x = quads[q, kk]
                for k2 in range(4):
                    y = quads[q, k2]
                    for c in range(ncol[x]):
                        for c2 in range(ncol[y]):
                            B[3 * kk + c, 3 * k2 + c2] += fw * (Jw[3 * kk + c] * Jw[3 * k2 + c2])
        for i in range(4):
            if not mine[i]:
                continue
            for j in range(4):
                if qslot[q, i, j] >= 0:
                    _scatter(data, indptr, aoff, col_start, ncol, quads[q, i], quads[q, j], qslot[q, i, j], B, 3 * i,
                             3 * j, 1.0)
    # the regulariser on the diagonal
    for u in range(v0, v1):
        if ncol[u] > 0:
            for c in range(ncol[u]):
                data[indptr[col_start[u] + c] + aoff[dslot[u]] + c] += rho[col_start[u] + c]


class ReducedHessian:
    """The smoothing's reduced Hessian ``T^T (K (x) I) T + fo J_o^T J_o + fw J_w^T J_w +
    diag(rho)`` (:func:`~shellmesh_mdao.smooth.smooth`) assembled by compiled loops into a
    CSR pattern made once per mesh and set of moving vertices.

    Vertex ``v`` owns the reduced columns ``col_start[v] .. col_start[v] + ncol[v] - 1``
    (``ncol`` 0 to 3, columns numbered vertex by vertex in vertex order) with tangent
    vectors ``tv`` (k, 3). The pattern couples two vertices with columns that are the ends
    of a pair (``pu``, ``pv``: the energy's pairs, ``K = sum pw (e_u - e_v)(e_u - e_v)^T``)
    or corners of one of ``quads`` (m, 4) (pass none when no quad term is used); each row's
    columns are sorted. :meth:`values` adds the pairs' blocks, then quad by quad its
    orthogonality corners' Gram blocks of ``sqrt(w) M_role tv`` (the rows of
    :func:`ortho_jacobian`, corner ``kk`` of quad ``q`` at ``4 q + kk`` with roles previous,
    own and next corner) and its planarity row ``sigma_k sw (m_k . tv)``, then ``rho`` on the
    diagonal. Every sum of a block and of its mirror runs over the same products in the same
    order, so the matrix is symmetric bit for bit."""

    def __init__(self, pu, pv, quads, ncol, col_start):
        self.pu, self.pv = (np.ascontiguousarray(v, dtype=np.int64).reshape(-1) for v in (pu, pv))
        self.quads = np.ascontiguousarray(quads, dtype=np.int64).reshape(-1, 4)
        self.ncol = np.ascontiguousarray(ncol, dtype=np.int64)
        self.col_start = np.ascontiguousarray(col_start, dtype=np.int64)
        n = len(self.ncol)
        if len(self.pu) != len(self.pv):
            raise ValueError("pu and pv must have one entry per pair")
        for name, v in (("pu", self.pu), ("pv", self.pv), ("quads", self.quads.ravel())):
            _check_index(name, v, n)
        if len(self.col_start) != n or (n and (self.ncol.min() < 0 or self.ncol.max() > 3)):
            raise ValueError("ncol must give 0 to 3 columns for each vertex of col_start")
        self.k = int(self.ncol.sum())
        own = np.flatnonzero(self.ncol > 0)
        if not np.array_equal(self.col_start[own], (np.cumsum(self.ncol[own]) - self.ncol[own])):
            raise ValueError("col_start must number the columns vertex by vertex, in vertex order")
        vptr, vadj, self.aoff, self.indptr, self.indices = _hessian_pattern(self.pu, self.pv, self.quads, self.ncol,
                                                                            self.col_start)
        self.dslot, self.pslot, self.qslot = _hessian_slots(vptr, vadj, self.pu, self.pv, self.quads, self.ncol)

    #: fewest matrix entries :meth:`values` fills in two threads (each takes the rows of half
    #: the entries; the same bits as one)
    MIN_THREADED = 100_000

    def values(self, tv, pw, rho, ortho=None, fo=1.0, warp=None, fw=1.0, threads: int | None = None):
        """The CSR data for the pattern. ``pw`` (one per pair), ``rho`` (k,); ``ortho``:
        ``(n, su, sv, sw)`` of the ``4 m`` corners (``sw`` the weights' roots) or None;
        ``warp``: ``(qi, m (len(qi), 4, 3), sw (len(qi),))`` of the quads ``quads[qi]`` or
        None; ``fo``, ``fw`` the factors of the two quad terms. With ``threads`` above 1
        (default: numba's thread count, the CPUs this process may use) and at least
        :attr:`MIN_THREADED` entries, two threads fill the rows of two vertex ranges (the
        compiled loop releases the GIL); the values are the same bits either way."""
        tv = np.ascontiguousarray(tv, dtype=np.float64).reshape(-1, 3)
        pw = np.ascontiguousarray(pw, dtype=np.float64).reshape(-1)
        rho = np.ascontiguousarray(rho, dtype=np.float64).reshape(-1)
        nq = len(self.quads)
        if len(tv) != self.k or len(rho) != self.k or len(pw) != len(self.pu):
            raise ValueError(f"tv and rho need one row per column (k = {self.k}), pw one per pair")
        if ortho is None:
            on, osu, osv, osw = np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0)
        else:
            on = np.ascontiguousarray(ortho[0], dtype=np.float64).reshape(-1, 3)
            osu, osv, osw = (np.ascontiguousarray(v, dtype=np.float64).reshape(-1) for v in ortho[1:])
            if not (len(on) == len(osu) == len(osv) == len(osw) == 4 * nq):
                raise ValueError("the orthogonality term needs n, su, sv and sw for the 4 corners of every quad")
        wrow = np.full(nq, -1, np.int64)
        if warp is None:
            wm, wsw = np.zeros((0, 4, 3)), np.zeros(0)
        else:
            qi = np.asarray(warp[0], dtype=np.int64).reshape(-1)
            wm = np.ascontiguousarray(warp[1], dtype=np.float64).reshape(-1, 4, 3)
            wsw = np.ascontiguousarray(warp[2], dtype=np.float64).reshape(-1)
            _check_index("warp quads", qi, nq)
            if len(wm) != len(qi) or len(wsw) != len(qi) or len(np.unique(qi)) != len(qi):
                raise ValueError("the planarity term needs distinct quads, each with one m and one sw")
            wrow[qi] = np.arange(len(qi))
        data = np.zeros(self.indptr[-1], np.float64)
        args = (data, self.indptr, self.aoff, self.dslot, self.pslot, self.qslot, self.col_start, self.ncol, tv,
                self.pu, self.pv, pw, self.quads, on, osu, osv, osw, float(fo), wrow, wm, wsw, float(fw), rho)
        n = len(self.ncol)
        if threads is None:
            from numba import config
            threads = int(config.NUMBA_NUM_THREADS)
        if threads > 1 and len(data) >= self.MIN_THREADED:
            # the vertices split where half of the entries are: their rows in one thread each
            row_end = self.indptr[self.col_start + self.ncol]          # each vertex's rows end here
            mid = int(np.searchsorted(row_end, len(data) // 2))
            other = _Background(_hessian_values, *args, mid, n)
            _hessian_values(*args, 0, mid)
            other.result()
        else:
            _hessian_values(*args, 0, n)
        return data

    def matrix(self, data):
        from scipy import sparse
        return sparse.csr_matrix((data, self.indices, self.indptr), shape=(self.k, self.k))


@njit(cache=True, nogil=True, inline="always")
def _nanmin(x, y):
    """np.minimum of two floats (a NaN wins)."""
    if x != x or y != y:
        return np.nan
    return x if x < y else y


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _element_frame(C, k, E, cr, L, nn):
    """The corners ``C[:k]`` of one element: its own unit normal into ``nn``
    (smooth._corner_normals, smooth._unit), its edges ``E``, the corners' cross products
    ``cr`` and the edge lengths ``L`` (norm_rows' order)."""
    if k == 4:
        u0, u1, u2 = C[2, 0] - C[0, 0], C[2, 1] - C[0, 1], C[2, 2] - C[0, 2]
        w0, w1, w2 = C[3, 0] - C[1, 0], C[3, 1] - C[1, 1], C[3, 2] - C[1, 2]
    else:
        u0, u1, u2 = C[1, 0] - C[0, 0], C[1, 1] - C[0, 1], C[1, 2] - C[0, 2]
        w0, w1, w2 = C[2, 0] - C[0, 0], C[2, 1] - C[0, 1], C[2, 2] - C[0, 2]
    v0, v1, v2 = u1 * w2 - u2 * w1, u2 * w0 - u0 * w2, u0 * w1 - u1 * w0
    ln = np.sqrt((v0 * v0 + v2 * v2) + v1 * v1)          # einsum's order
    if ln > 0:
        nn[0], nn[1], nn[2] = v0 / ln, v1 / ln, v2 / ln
    else:
        nn[0], nn[1], nn[2] = 0.0, 0.0, 0.0
    for i in range(k):
        j = i + 1 if i + 1 < k else 0
        for d in range(3):
            E[i, d] = C[j, d] - C[i, d]
    for i in range(k):
        h = i - 1 if i > 0 else k - 1
        cr[i, 0] = E[h, 1] * E[i, 2] - E[h, 2] * E[i, 1]
        cr[i, 1] = E[h, 2] * E[i, 0] - E[h, 0] * E[i, 2]
        cr[i, 2] = E[h, 0] * E[i, 1] - E[h, 1] * E[i, 0]
        L[i] = np.sqrt((E[i, 0] * E[i, 0] + E[i, 1] * E[i, 1]) + E[i, 2] * E[i, 2])   # norm_rows' order


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _element_min_sj(k, cr, L, n0, n1, n2):
    """The smallest corner scaled Jacobian of one element (its :func:`_element_frame`) against
    the normal ``(n0, n1, n2)``, before the triangles' scale."""
    lo = np.inf
    for i in range(k):
        h = i - 1 if i > 0 else k - 1
        den = L[i] * L[h]
        sc = (cr[i, 0] * n0 + cr[i, 2] * n2) + cr[i, 1] * n1
        q = sc / den if den > 0 else 0.0
        lo = q if i == 0 else _nanmin(lo, q)
    return lo


@njit(cache=True, nogil=True, error_model="numpy")
def _min_corner_sj(P, faces, is_tri, nref, use_ref, tri_scale):
    m = faces.shape[0]
    out = np.empty(m)
    C = np.empty((4, 3))
    E = np.empty((4, 3))
    cr = np.empty((4, 3))
    L = np.empty(4)
    nn = np.empty(3)
    for f in range(m):
        k = 3 if is_tri[f] else 4
        for i in range(k):
            if not 0 <= faces[f, i] < P.shape[0]:
                return None
            for d in range(3):
                C[i, d] = P[faces[f, i], d]
        _element_frame(C, k, E, cr, L, nn)
        scale = tri_scale if k == 3 else 1.0
        best = _nanmin(np.inf, _element_min_sj(k, cr, L, nn[0], nn[1], nn[2]) * scale)
        if use_ref:
            best = _nanmin(best, _element_min_sj(k, cr, L, nref[f, 0], nref[f, 1], nref[f, 2]) * scale)
        out[f] = best
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _face_quality(C, is_tri, nref, tri_scale):
    m = C.shape[0]
    out = np.empty(m)
    E = np.empty((4, 3))
    cr = np.empty((4, 3))
    L = np.empty(4)
    nn = np.empty(3)
    for f in range(m):
        k = 3 if is_tri[f] else 4
        _element_frame(C[f], k, E, cr, L, nn)
        scale = tri_scale if k == 3 else 1.0
        sj = _nanmin(np.inf, _element_min_sj(k, cr, L, nn[0], nn[1], nn[2]) * scale)
        d = (nn[0] * nref[f, 0] + nn[2] * nref[f, 2]) + nn[1] * nref[f, 1] + 0.0   # einsum's dot
        out[f] = sj if d > 0 else d - 1.0
    return out


def face_quality(C, is_tri, nref, tri_scale=2.0 / np.sqrt(3.0)):
    """Per element with corners ``C`` ((m, 4, 3); a triangle's fourth corner not read): the
    smallest corner scaled Jacobian against its own unit normal (triangles times
    ``tri_scale``), replaced by ``dot - 1`` (in [-2, -1]) where that normal points against
    ``nref`` (m, 3) (a flipped element): :func:`shellmesh_mdao.smooth._face_quality`, the same
    bits as its numpy version (``_corner_min_sj`` on ``_corner_normals``, einsum's dot)."""
    C = np.ascontiguousarray(C, dtype=np.float64)
    if C.ndim != 3 or C.shape[1:] != (4, 3):
        raise ValueError(f"C must be an (m, 4, 3) array of corners, got shape {C.shape}")
    is_tri = np.ascontiguousarray(is_tri, dtype=np.bool_).reshape(-1)
    nref = np.ascontiguousarray(nref, dtype=np.float64).reshape(-1, 3)
    if len(is_tri) != len(C) or len(nref) != len(C):
        raise ValueError("is_tri and nref must have one entry per element")
    return _face_quality(C, is_tri, nref, float(tri_scale))


def min_corner_sj(P, faces, is_tri, nref=None, tri_scale=2.0 / np.sqrt(3.0)):
    """Per element ``faces`` ((m, 4), a triangle's fourth entry not read; or (m, 3), triangles
    only) of the points ``P``:
    the smallest corner scaled Jacobian, ``(e_prev x e_next) . n / (|e_prev| |e_next|)``, against
    the element's own unit normal and, when ``nref`` (m, 3) is given, against that normal too
    (the smaller); triangles times ``tri_scale`` (1 = equilateral). The same bits as the numpy
    version (:func:`shellmesh_mdao.smooth._corner_min_sj` on the corners and
    ``_corner_normals``), whose sums of three products it repeats in numpy's order."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64)
    if faces.ndim != 2 or faces.shape[1] not in (3, 4):
        raise ValueError(f"faces must be an (m, 3) or (m, 4) array, got shape {faces.shape}")
    if faces.shape[1] == 3:                               # triangles only: the -1 padded layout
        faces = np.column_stack([faces, np.full(len(faces), -1, np.int64)])
    faces = np.ascontiguousarray(faces)
    is_tri = np.ascontiguousarray(is_tri, dtype=np.bool_).reshape(-1)
    if len(is_tri) != len(faces):
        raise ValueError("is_tri must have one entry per face")
    use_ref = nref is not None
    nref = np.ascontiguousarray(nref if use_ref else np.zeros((len(faces), 3)), dtype=np.float64).reshape(-1, 3)
    if len(nref) != len(faces):
        raise ValueError("nref must have one normal per face")
    out = _min_corner_sj(P, faces, is_tri, nref, use_ref, float(tri_scale))
    if out is None:                    # an index out of range, found in the loop: say which
        _check_index("faces", np.concatenate([faces[:, :3].reshape(-1), faces[~is_tri, 3]]), len(P))
        raise ValueError(f"faces holds indices outside [0, {len(P)})")
    return out


# ============================================================================ sorting
@njit(cache=True, nogil=True)
def _counting_order(keys, n, idx):
    """Stable order of ``keys[idx]`` (all in [0, n)) as positions into ``idx``."""
    cnt = np.zeros(n + 1, np.int64)
    for i in range(idx.shape[0]):
        cnt[keys[idx[i]] + 1] += 1
    for k in range(n):
        cnt[k + 1] += cnt[k]
    out = np.empty(idx.shape[0], np.int64)
    for i in range(idx.shape[0]):
        k = keys[idx[i]]
        out[cnt[k]] = idx[i]
        cnt[k] += 1
    return out


@njit(cache=True, nogil=True)
def _pair_order(lo, hi, n):
    o = _counting_order(hi, n, np.arange(hi.shape[0]))
    return _counting_order(lo, n, o)


def stable_order(keys, n):
    """``np.argsort(keys, kind="stable")`` for integer keys in [0, n), by a counting sort
    (O(len + n); a stable order is unique, so the same array)."""
    keys = np.ascontiguousarray(keys, dtype=np.int64).reshape(-1)
    _check_index("keys", keys, int(n))
    return _counting_order(keys, int(n), np.arange(len(keys)))


@njit(cache=True, nogil=True)
def _group_order(keys, n):
    ptr = np.zeros(n + 1, np.int64)
    for i in range(keys.shape[0]):
        ptr[keys[i] + 1] += 1
    for k in range(n):
        ptr[k + 1] += ptr[k]
    return ptr, _counting_order(keys, n, np.arange(keys.shape[0]))


def group_order(keys, n):
    """Row pointers ``ptr`` (n + 1,) and ``order`` grouping ``arange(len(keys))`` by ``keys``
    (integers in [0, n)): ``order`` is ``np.argsort(keys, kind="stable")`` and group ``k`` is
    ``order[ptr[k]:ptr[k + 1]]``, in one counting pass."""
    keys = np.ascontiguousarray(keys, dtype=np.int64).reshape(-1)
    _check_index("keys", keys, int(n))
    return _group_order(keys, int(n))


@njit(cache=True, nogil=True)
def _vertex_faces(F, n):
    ptr = np.zeros(n + 1, np.int64)
    for f in range(F.shape[0]):
        for k in range(F.shape[1]):
            if F[f, k] >= n or F[f, k] < -1:
                return None
            if F[f, k] >= 0:
                ptr[F[f, k] + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    fill = ptr[:n].copy()
    out = np.empty(ptr[n], np.int64)
    for f in range(F.shape[0]):
        for k in range(F.shape[1]):
            v = F[f, k]
            if v >= 0:
                out[fill[v]] = f
                fill[v] += 1
    return ptr, out


def vertex_faces(F, n):
    """CSR ``(ptr, faces)`` of the faces around each vertex of the face array ``F`` ((m, 3) or
    (m, 4), -1 padded) on ``n`` vertices, each vertex's faces in ascending order (a face
    listing a vertex twice, twice): the stable grouping of the face ids by vertex in one
    counting pass."""
    F = np.ascontiguousarray(F, dtype=np.int64)
    if F.ndim != 2:
        raise ValueError(f"vertex_faces: faces must be an (m, k) array, got shape {F.shape}")
    out = _vertex_faces(F, int(n))
    if out is None:                    # an entry out of range, found in the loop: say which
        _check_index("faces", F[F != -1], int(n))
        raise ValueError(f"faces holds indices outside [0, {int(n)})")
    return out


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
    _check_index("E", E, int(n))
    return _edge_neighbours(E, int(n))


def stable_pair_order(lo, hi, n):
    """``np.argsort(lo * n + hi, kind="stable")`` for integer ``lo``, ``hi`` in [0, n): two
    counting sorts (by ``hi``, then stably by ``lo``), the same array without the products."""
    lo = np.ascontiguousarray(lo, dtype=np.int64).reshape(-1)
    hi = np.ascontiguousarray(hi, dtype=np.int64).reshape(-1)
    if len(lo) != len(hi):
        raise ValueError("lo and hi must have the same length")
    _check_index("lo", lo, int(n))
    _check_index("hi", hi, int(n))
    return _pair_order(lo, hi, int(n))


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
def _edge_table(F, n):
    m = F.shape[0]
    lo = np.empty(3 * m, np.int64)
    hi = np.empty(3 * m, np.int64)
    for f in range(m):
        for k in range(3):
            a, b = F[f, k], F[f, (k + 1) % 3]
            lo[3 * f + k] = a if a < b else b
            hi[3 * f + k] = b if a < b else a
    order = _pair_order(lo, hi, n)
    nh = 3 * m
    he_edge = np.empty(nh, np.int64)
    ne = 0
    for j in range(nh):
        if j == 0 or lo[order[j]] != lo[order[j - 1]] or hi[order[j]] != hi[order[j - 1]]:
            ne += 1
        he_edge[order[j]] = ne - 1
    h0 = np.empty(ne, np.int64)
    h1 = np.full(ne, -1, np.int64)
    cnt = np.zeros(ne, np.int64)
    E = np.empty((ne, 2), np.int64)
    keys = np.empty(ne, np.int64)
    for j in range(nh):
        h = order[j]
        e = he_edge[h]
        if cnt[e] == 0:
            h0[e] = h
            E[e, 0], E[e, 1] = lo[h], hi[h]
            keys[e] = lo[h] * n + hi[h]
        elif cnt[e] == 1:
            h1[e] = h
        cnt[e] += 1
    for e in range(ne):
        if cnt[e] != 2:
            h1[e] = -1
    return he_edge, h0, h1, cnt, E, keys


def edge_table(F, n):
    """Edge table of triangles ``F`` (m, 3) on ``n`` vertices, edges in the order of their keys
    ``lo * n + hi``: ``(he_edge (3m,), h0, h1, valence, E (e, 2), keys)``, half-edge ``3 f + k``
    running from ``F[f, k]`` to ``F[f, k + 1]``; ``h0`` the first half-edge of each edge (in
    half-edge order), ``h1`` the second where the edge has exactly two, else -1. The arrays of
    ``remesh._Topo``'s whole-array construction (stable sort of the keys, run starts)."""
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    _check_index("F", F, int(n))
    return _edge_table(F, int(n))


@njit(cache=True, nogil=True, inline="always")
def _edge_id(E, kptr, u, v):
    """Row of the edge (u, v) (either order) in the sorted edge table ``E``, -1 if absent: a
    scan of the rows of the lower end (``kptr``)."""
    lo, hi = (u, v) if u <= v else (v, u)
    for e in range(kptr[lo], kptr[lo + 1]):
        if E[e, 1] == hi:
            return e
    return -1


@njit(cache=True, nogil=True)
def _edge_lookup(E, kptr, u, v):
    out = np.empty(u.shape[0], np.int64)
    for i in range(u.shape[0]):
        out[i] = _edge_id(E, kptr, u[i], v[i])
    return out


@njit(cache=True, nogil=True)
def _edge_rows(E, n):
    ptr = np.zeros(n + 1, np.int64)
    for e in range(E.shape[0]):
        if not 0 <= E[e, 0] < n:
            return None
        ptr[E[e, 0] + 1] += 1
    for k in range(n):
        ptr[k + 1] += ptr[k]
    return ptr


def edge_rows(E, n):
    """Row pointers ``kptr`` (n + 1,) of the edge table ``E`` (e, 2) of :func:`edge_table` (rows
    ``(lo, hi)`` sorted): the rows whose lower end is ``lo`` are ``E[kptr[lo]:kptr[lo + 1]]``
    (the counts of the lower ends, summed, in one compiled pass)."""
    E = np.ascontiguousarray(E, dtype=np.int64).reshape(-1, 2)
    out = _edge_rows(E, int(n))
    if out is None:                    # a lower end out of range, found in the loop: say which
        _check_index("E", E[:, 0], int(n))
        raise ValueError(f"E holds indices outside [0, {int(n)})")
    return out


def edge_lookup(E, kptr, u, v):
    """Edge id of each node pair ``(u[i], v[i])`` (either order), -1 where absent, in the edge
    table ``E`` (e, 2) of :func:`edge_table` (rows ``(lo, hi)`` sorted): ``kptr`` (n + 1,) the
    rows of each ``lo`` (:func:`edge_rows`); a scan of those few rows."""
    E = np.ascontiguousarray(E, dtype=np.int64).reshape(-1, 2)
    kptr = np.ascontiguousarray(kptr, dtype=np.int64)
    u = np.ascontiguousarray(u, dtype=np.int64).reshape(-1)
    v = np.ascontiguousarray(v, dtype=np.int64).reshape(-1)
    if len(u) != len(v):
        raise ValueError("edge_lookup needs as many u as v")
    _check_index("u", u, len(kptr) - 1)
    _check_index("v", v, len(kptr) - 1)
    return _edge_lookup(E, kptr, u, v)


# ============================================================================ triangles
@njit(cache=True, nogil=True, inline="always")
def _dot3(x0, x1, x2, y0, y1, y2):
    return (x0 * y0 + x2 * y2) + x1 * y1             # numpy's einsum("ij,ij->i") over three


@njit(cache=True, nogil=True, inline="always")
def _clip01(t):
    """np.clip(t, 0, 1): (t > 0 ? t : 0) < 1 ? .. : 1; a NaN stays."""
    if t == t:
        t = t if t > 0.0 else 0.0
        t = t if t < 1.0 else 1.0
    return t


@njit(cache=True, nogil=True, inline="always")
def _on_segment(p0, p1, p2, s0, s1, s2, e0, e1, e2):
    """Closest point of the segment s-e to ``p``: ``s + clip(t, 0, 1) (e - s)``, t = 0 on a
    zero-length segment."""
    d0, d1, d2 = e0 - s0, e1 - s1, e2 - s2
    L2 = _dot3(d0, d1, d2, d0, d1, d2)
    t = 0.0
    if L2 > 0:
        t = _dot3(p0 - s0, p1 - s1, p2 - s2, d0, d1, d2) / L2
    t = _clip01(t)
    return s0 + t * d0, s1 + t * d1, s2 + t * d2


@njit(cache=True, nogil=True, inline="always")
def _sq_dist(x0, x1, x2, p0, p1, p2):
    """|x - p|^2 summed as numpy's row norm sums it (``mesh.norm_rows`` is its square root)."""
    e0, e1, e2 = x0 - p0, x1 - p1, x2 - p2
    return (e0 * e0 + e1 * e1) + e2 * e2


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _closest_on_triangle(p0, p1, p2, a0, a1, a2, b0, b1, b2, c0, c1, c2):
    """Closest point of triangle (a, b, c) to p: Ericson's regions (the vertices, the edges
    ab, ac, bc, the interior); a zero-area triangle goes to the nearest of its edges."""
    ab0, ab1, ab2 = b0 - a0, b1 - a1, b2 - a2
    ac0, ac1, ac2 = c0 - a0, c1 - a1, c2 - a2
    ap0, ap1, ap2 = p0 - a0, p1 - a1, p2 - a2
    d1 = _dot3(ab0, ab1, ab2, ap0, ap1, ap2)
    d2 = _dot3(ac0, ac1, ac2, ap0, ap1, ap2)
    bp0, bp1, bp2 = p0 - b0, p1 - b1, p2 - b2
    d3 = _dot3(ab0, ab1, ab2, bp0, bp1, bp2)
    d4 = _dot3(ac0, ac1, ac2, bp0, bp1, bp2)
    cp0, cp1, cp2 = p0 - c0, p1 - c1, p2 - c2
    d5 = _dot3(ab0, ab1, ab2, cp0, cp1, cp2)
    d6 = _dot3(ac0, ac1, ac2, cp0, cp1, cp2)
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
    da = _dot3(qa0 - p0, qa1 - p1, qa2 - p2, qa0 - p0, qa1 - p1, qa2 - p2)
    if da != da:
        return qa0, qa1, qa2
    db = _dot3(qb0 - p0, qb1 - p1, qb2 - p2, qb0 - p0, qb1 - p1, qb2 - p2)
    if db != db:
        return qb0, qb1, qb2
    dc = _dot3(qc0 - p0, qc1 - p1, qc2 - p2, qc0 - p0, qc1 - p1, qc2 - p2)
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
    as the numpy version of :func:`shellmesh_mdao.project.closest_point_on_triangles` (Ericson's
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
    return _sq_dist(0.5 * (B[i, 0] + B[i, 3]), 0.5 * (B[i, 1] + B[i, 4]), 0.5 * (B[i, 2] + B[i, 5]), p0, p1, p2)


@njit(cache=True, nogil=True, error_model="numpy")
def _bvh_closest(Q, lo, hi, V, TB, tri_id, NB, child, start, cnt, slack, out, oid, seed):
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
            best, bid = _sq_dist(x0, x1, x2, p0, p1, p2), tri_id[t]
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
                    d = _sq_dist(y0, y1, y2, p0, p1, p2)
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


@njit(cache=True, nogil=True)
def _grid_nearest_other(P, verts, lo, cell, dims):
    """:func:`nearest_other_distance` on a uniform grid of cubes of edge ``cell`` from ``lo``
    (``dims`` cells per axis): the points sorted by cell (a counting sort, the points copied in
    that order), each query scanning the cells at Chebyshev distance 0, 1, 2, ... from its own
    until its best squared distance is within the searched block's reach (every point outside
    the block is more than that far). The squared distance is ``(dx*dx + dy*dy) + dz*dz`` of the
    coordinate differences, as a KD-tree's Minkowski sum forms it; the least one, then its
    square root."""
    n = P.shape[0]
    nx, ny, nz = dims[0], dims[1], dims[2]
    ncell = nx * ny * nz
    key = np.empty(n, np.int64)
    cnt = np.zeros(ncell + 1, np.int32)            # cell starts (fewer than 2**31 points)
    for p in range(n):
        a = min(max(int(math.floor((P[p, 0] - lo[0]) / cell)), 0), nx - 1)
        b = min(max(int(math.floor((P[p, 1] - lo[1]) / cell)), 0), ny - 1)
        c = min(max(int(math.floor((P[p, 2] - lo[2]) / cell)), 0), nz - 1)
        key[p] = (a * ny + b) * nz + c
        cnt[key[p] + 1] += 1
    for k in range(ncell):
        cnt[k + 1] += cnt[k]
    slot = np.empty(n, np.int64)
    S = np.empty((n, 3))
    for p in range(n):                             # each cell's points in index order
        s = cnt[key[p]]
        slot[p] = s
        S[s, 0], S[s, 1], S[s, 2] = P[p, 0], P[p, 1], P[p, 2]
        cnt[key[p]] += 1
    for k in range(ncell, 0, -1):                  # each start had moved up to the next one's
        cnt[k] = cnt[k - 1]
    cnt[0] = 0
    want = np.full(n, -1, np.int64)                # queries in grid order: neighbouring memory
    for qi in range(verts.shape[0]):
        want[slot[verts[qi]]] = qi
    eps = 1e-9 * cell                              # a coordinate rounded into the next cell
    out = np.empty(verts.shape[0])
    rmax = max(nx, max(ny, nz))
    for sv in range(n):
        qi = want[sv]
        if qi < 0:
            continue
        x0, x1, x2 = S[sv, 0], S[sv, 1], S[sv, 2]
        k0 = key[verts[qi]]
        c0 = k0 % nz
        b0 = (k0 // nz) % ny
        a0 = k0 // (nz * ny)
        best = np.inf
        r = 0
        while True:
            for a in range(max(a0 - r, 0), min(a0 + r, nx - 1) + 1):
                for b in range(max(b0 - r, 0), min(b0 + r, ny - 1) + 1):
                    # inside the shell only its two cells along z
                    step = 1 if r == 0 or abs(a - a0) == r or abs(b - b0) == r else 2 * r
                    c = c0 - r
                    while c <= c0 + r:
                        if 0 <= c < nz:
                            k = (a * ny + b) * nz + c
                            for s in range(cnt[k], cnt[k + 1]):
                                if s == sv:
                                    continue
                                d0 = x0 - S[s, 0]
                                d1 = x1 - S[s, 1]
                                d2 = x2 - S[s, 2]
                                d = (d0 * d0 + d1 * d1) + d2 * d2
                                if d < best:
                                    best = d
                        c += step
            lim = r * cell - eps
            if (lim > 0 and best <= lim * lim) or r >= rmax:
                break
            r += 1
        out[qi] = math.sqrt(best)
    return out


def nearest_other_distance(P, verts, cell: float | None = None):
    """Distance from each point ``P[verts[i]]`` to the nearest OTHER point of ``P`` (n, 3)
    (0 for a coincident one, inf when ``P`` has one point): the values of
    ``cKDTree(P).query(P[verts], k=2)[0][:, 1]``, bit for bit, on a uniform grid
    (:func:`_grid_nearest_other`; 8 ms against scipy's 22 ms on 25k points of a quad mesh).
    ``cell``: the grid's cube edge, e.g. 1.5 times the mesh's median edge (default from the
    bounding box's volume); it sets the speed only, and grows until the grid has at most
    16 cells per point (64 MB of cell starts for a million nodes)."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    verts = np.ascontiguousarray(verts, dtype=np.int64).reshape(-1)
    n = len(P)
    if not len(verts):
        return np.zeros(0)
    _check_index("verts", verts, n)
    if not np.isfinite(P).all():
        raise ValueError("nearest_other_distance: points must be finite")
    lo = P.min(0)
    ext = P.max(0) - lo
    big = max(float(ext.max()), 1e-300)
    if cell is None or not np.isfinite(cell) or cell <= 0:
        cell = float(np.cbrt(np.prod(np.maximum(ext, 1e-3 * big)) / n))
    cell = max(float(cell), 1e-9 * big)
    while True:
        dims = np.floor(ext / cell).astype(np.int64) + 1
        if float(np.prod(dims.astype(np.float64))) <= 16.0 * n + 64:
            break
        cell *= 1.25
    return _grid_nearest_other(P, verts, lo, cell, dims)



class TriangleBVH:
    """Exact closest points on a fixed set of triangles (float64), for many query points.

    Built once (:func:`_bvh_build`, leaves of up to ``leaf`` triangles; 23.5k triangles in
    about 10 ms); each query descends the tree nearer child first and skips every box
    farther than the best distance found so far. The answer is the closest point of
    :func:`closest_on_triangles`'s formula on the triangle whose squared distance (numpy's
    row-norm sum) is least, the lowest triangle index on a tie: it does not depend on the
    tree's layout, the order of the queries or the number of threads answering them.

    ``points`` (n, 3) float64, ``triangles`` (t, 3) int64 with indices in range (checked by
    the caller, :class:`shellmesh_mdao.project.SurfaceLocator`)."""

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
        workers = [_Background(_bvh_closest, q, int(cuts[j]), int(cuts[j + 1]), *args) for j in range(1, nt)]
        _bvh_closest(q, int(cuts[0]), int(cuts[1]), *args)
        for w in workers:
            w.result()
        return out, oid


# ============================================================================ scatter
@njit(cache=True, nogil=True)
def _pair_difference(i, j, w, rv, n):
    acc_i = np.zeros((n, 3))
    acc_j = np.zeros((n, 3))
    for k in range(i.shape[0]):
        for d in range(3):
            x = w[k] * rv[k, d]
            acc_i[i[k], d] += x
            acc_j[j[k], d] += x
    return acc_i - acc_j


def pair_difference(i, j, w, rv, n):
    """(n, 3) ``bincount(i, w * rv[:, d]) - bincount(j, w * rv[:, d])`` for each axis ``d``:
    the pairs' vectors ``w[k] rv[k]`` summed onto their first vertices minus those summed onto
    their second, each sum in pair order from zero (numpy's bincount, the same bits)."""
    i, j = (np.ascontiguousarray(x, dtype=np.int64).reshape(-1) for x in (i, j))
    w = np.ascontiguousarray(w, dtype=np.float64).reshape(-1)
    rv = np.ascontiguousarray(rv, dtype=np.float64).reshape(-1, 3)
    if not (len(i) == len(j) == len(w) == len(rv)):
        raise ValueError("pair_difference needs one i, j, w and rv per pair")
    _check_index("i", i, int(n))
    _check_index("j", j, int(n))
    return _pair_difference(i, j, w, rv, int(n))


# ============================================================================ vertex normals
@njit(cache=True, nogil=True)
def _corner_sums(faces, av, n):
    acc = np.zeros((n, 3))
    for f in range(faces.shape[0]):
        for k in range(faces.shape[1]):
            v = faces[f, k]
            if v >= 0:
                acc[v, 0] += av[f, 0]
                acc[v, 1] += av[f, 1]
                acc[v, 2] += av[f, 2]
    return acc


@njit(cache=True, nogil=True)
def _corner_max_turn(faces, vn, fn, n):
    kap = np.zeros(n)
    for f in range(faces.shape[0]):
        for k in range(faces.shape[1]):
            v = faces[f, k]
            if v >= 0:
                x = 1.0 - _dot3e(vn[v, 0], vn[v, 1], vn[v, 2], fn[f, 0], fn[f, 1], fn[f, 2])
                a = kap[v]
                if a == a and (x != x or x > a):      # np.maximum: a NaN on either side wins
                    kap[v] = x
    return kap


def corner_sums(faces, av, n):
    """(n, 3): each face's vector ``av[f]`` summed onto its corners (``faces`` (m, k), -1 for no
    corner), face by face and corner by corner from zero: ``np.bincount`` over the valid
    corners in row-major order, the same bits."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    av = np.ascontiguousarray(av, dtype=np.float64).reshape(-1, 3)
    if faces.ndim != 2 or len(faces) != len(av):
        raise ValueError("corner_sums needs (m, k) faces and one (3,) vector per face")
    _check_index("faces", faces[faces >= 0], int(n))
    return _corner_sums(faces, av, int(n))


def corner_max_turn(faces, vn, fn, n):
    """(n,): for each vertex the largest ``1 - vn[v] . fn[f]`` over its faces (0 for a vertex
    without faces): ``np.maximum.at`` of einsum's dot products, the same bits."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    vn = np.ascontiguousarray(vn, dtype=np.float64).reshape(-1, 3)
    fn = np.ascontiguousarray(fn, dtype=np.float64).reshape(-1, 3)
    if faces.ndim != 2 or len(faces) != len(fn) or len(vn) != int(n):
        raise ValueError("corner_max_turn needs (m, k) faces, one normal per face and one per vertex")
    _check_index("faces", faces[faces >= 0], int(n))
    return _corner_max_turn(faces, vn, fn, int(n))


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
    _check_index("T", T, len(P))
    return _centroid_d2(P, T, float(x[0]), float(x[1]), float(x[2]))


# ============================================================================ segments
@njit(cache=True, nogil=True, inline="always")
def _on_segment_ab(q0, q1, q2, a, ab, s):
    """Closest point of segment ``s`` (``a[s] + t ab[s]``) to ``q``: ``(t, x0, x1, x2, distance)``
    in the arithmetic of ``imprint._pick_segments`` (einsum's dot products, ``np.clip``, a t
    of 0 on a zero-length segment, row norms)."""
    a0, a1, a2 = a[s, 0], a[s, 1], a[s, 2]
    e0, e1, e2 = ab[s, 0], ab[s, 1], ab[s, 2]
    L2 = _dot3e(e0, e1, e2, e0, e1, e2)
    t = _clip01(_dot3e(q0 - a0, q1 - a1, q2 - a2, e0, e1, e2) / (L2 if L2 > 0 else 1.0))
    x0, x1, x2 = a0 + t * e0, a1 + t * e1, a2 + t * e2
    return t, x0, x1, x2, np.sqrt(_sq_dist(x0, x1, x2, q0, q1, q2))


@njit(cache=True, nogil=True)
def _segments_scan(q, lo, hi, a, ab):
    m = q.shape[0]
    x = np.empty((m, 3))
    dist = np.empty(m)
    seg = np.empty(m, np.int64)
    tt = np.empty(m)
    for i in range(m):
        q0, q1, q2 = q[i, 0], q[i, 1], q[i, 2]
        bs = -1
        bd = np.inf
        bt = 0.0
        b0 = b1 = b2 = 0.0
        for s in range(lo[i], hi[i]):
            t, x0, x1, x2, d = _on_segment_ab(q0, q1, q2, a, ab, s)
            # the nearest, the lowest segment among equals; NaN distances last (np.lexsort)
            if bs < 0 or d < bd or (bd != bd and d == d):
                bs, bd, bt = s, d, t
                b0, b1, b2 = x0, x1, x2
        x[i, 0], x[i, 1], x[i, 2] = b0, b1, b2
        dist[i] = bd
        seg[i] = bs
        tt[i] = bt
    return x, dist, seg, tt


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
            t, _, _, _, d = _on_segment_ab(q0, q1, q2, a, ab, j)
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


def segments_scan(q, lo, hi, a, ab):
    """The closest point to each query ``q[i]`` on the segments ``a[s] + t ab[s]``,
    ``lo[i] <= s < hi[i]`` (a non-empty range), scanning them all: ``(points, distances,
    segments, t)``, the nearest segment and the lowest among equally near ones, with
    numpy's arithmetic of ``imprint._pick_segments`` (einsum's dot products, ``np.clip``,
    row norms), so the same bits as that pick over any candidate set holding the nearest."""
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 3)
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)
    ab = np.ascontiguousarray(ab, dtype=np.float64).reshape(-1, 3)
    lo = np.ascontiguousarray(lo, dtype=np.int64).reshape(-1)
    hi = np.ascontiguousarray(hi, dtype=np.int64).reshape(-1)
    if len(a) != len(ab) or len(lo) != len(q) or len(hi) != len(q):
        raise ValueError("segments_scan needs one a and one ab per segment and one range per query")
    if len(q) and ((lo < 0).any() or (hi > len(a)).any() or (hi <= lo).any()):
        raise ValueError(f"segment ranges must be non-empty and lie in [0, {len(a)}]")
    return _segments_scan(q, lo, hi, a, ab)


# ============================================================================ rows of three
# The per-row vector formulas of the remesh, the imprint and the smoother, called thousands of
# times a run on a few hundred to a few thousand rows, where numpy's per-call overhead and
# temporaries cost more than the arithmetic. Each takes C-contiguous float64 arrays from its
# wrapper (which sends anything else to numpy) and does numpy's arithmetic in numpy's order.
@njit(cache=True, nogil=True, inline="always")
def _dot3e(x0, x1, x2, y0, y1, y2):
    """einsum's sum of three products, sign of zero included: einsum adds the sum to an output
    that starts at +0, so a sum of negative zeros comes out +0 (which arctan2 tells apart)."""
    return _dot3(x0, x1, x2, y0, y1, y2) + 0.0


@njit(cache=True, nogil=True)
def _cross_rows(a, b):
    k = a.shape[0]
    out = np.empty((k, 3))
    for i in range(k):
        out[i, 0] = a[i, 1] * b[i, 2] - a[i, 2] * b[i, 1]
        out[i, 1] = a[i, 2] * b[i, 0] - a[i, 0] * b[i, 2]
        out[i, 2] = a[i, 0] * b[i, 1] - a[i, 1] * b[i, 0]
    return out


@njit(cache=True, nogil=True)
def _norm_rows(a):
    k = a.shape[0]
    out = np.empty(k)
    for i in range(k):
        out[i] = _norm3(a[i, 0], a[i, 1], a[i, 2])
    return out


@njit(cache=True, nogil=True)
def _dot_rows(a, b):
    k = a.shape[0]
    out = np.empty(k)
    for i in range(k):
        out[i] = _dot3e(a[i, 0], a[i, 1], a[i, 2], b[i, 0], b[i, 1], b[i, 2])
    return out


@njit(cache=True, nogil=True)
def _dot_norm_rows(a):
    k = a.shape[0]
    out = np.empty(k)
    for i in range(k):
        out[i] = np.sqrt(_dot3e(a[i, 0], a[i, 1], a[i, 2], a[i, 0], a[i, 1], a[i, 2]))
    return out


@njit(cache=True, nogil=True)
def _edge_lengths(P, E):
    k = E.shape[0]
    out = np.empty(k)
    for i in range(k):
        a, b = E[i, 0], E[i, 1]
        d0, d1, d2 = P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2]
        out[i] = np.sqrt(_dot3e(d0, d1, d2, d0, d1, d2))
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _dot_unit_rows(a):
    k = a.shape[0]
    out = np.zeros((k, 3))
    for i in range(k):
        n = np.sqrt(_dot3e(a[i, 0], a[i, 1], a[i, 2], a[i, 0], a[i, 1], a[i, 2]))
        if n > 0:
            out[i, 0], out[i, 1], out[i, 2] = a[i, 0] / n, a[i, 1] / n, a[i, 2] / n
    return out


@njit(cache=True, nogil=True)
def _element_normals(P, faces, is_tri):
    k = faces.shape[0]
    n = P.shape[0]
    out = np.zeros((k, 3))
    for i in range(k):
        a, b, c = faces[i, 0], faces[i, 1], faces[i, 2]
        if not (0 <= a < n and 0 <= b < n and 0 <= c < n and (is_tri[i] or 0 <= faces[i, 3] < n)):
            return None
        if is_tri[i]:
            x0, x1, x2 = _cross3(P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2],
                                 P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2])
        else:
            d = faces[i, 3]
            x0, x1, x2 = _cross3(P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2],
                                 P[d, 0] - P[b, 0], P[d, 1] - P[b, 1], P[d, 2] - P[b, 2])
        L = np.sqrt(_dot3e(x0, x1, x2, x0, x1, x2))
        if L > 0:
            out[i, 0], out[i, 1], out[i, 2] = x0 / L, x1 / L, x2 / L
    return out


def element_normals(P, faces, is_tri):
    """Unit normals of mixed elements ``faces`` (m, 4), -1 padded, ``is_tri`` (m,): a
    triangle's ``cross(B - A, C - A)``, a quad's ``cross(C - A, D - B)`` (its diagonals), over
    their einsum norm, zero rows where that is not positive: the bits of the smoothing's
    ``cross_rows`` and ``dot_unit_rows`` on the gathered corners, in one compiled pass."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    is_tri = np.ascontiguousarray(is_tri, dtype=np.bool_).reshape(-1)
    if faces.ndim != 2 or faces.shape[1] != 4 or len(is_tri) != len(faces):
        raise ValueError("element_normals takes (m, 4) faces and one is_tri entry per face")
    out = _element_normals(P, faces, is_tri)
    if out is None:                    # an index out of range, found in the loop: say which
        _check_index("faces", np.concatenate([faces[:, :3].reshape(-1), faces[~is_tri, 3]]), len(P))
        raise ValueError(f"faces holds indices outside [0, {len(P)})")
    return out


@njit(cache=True, nogil=True)
def _faces_at(ptr, vf, verts, m):
    mark = np.zeros(m, np.bool_)
    cnt = 0
    for i in range(verts.shape[0]):
        v = verts[i]
        if not 0 <= v < ptr.shape[0] - 1 or not 0 <= ptr[v] <= ptr[v + 1] <= vf.shape[0]:
            return None
        for p in range(ptr[v], ptr[v + 1]):
            if not 0 <= vf[p] < m:
                return None
            if not mark[vf[p]]:
                mark[vf[p]] = True
                cnt += 1
    out = np.empty(cnt, np.int64)
    k = 0
    for f in range(m):
        if mark[f]:
            out[k] = f
            k += 1
    return out


def faces_at(ptr, vf, verts, m):
    """Sorted ids of the faces incident to the vertices ``verts``, with the vertex-face CSR
    ``ptr``/``vf`` (:func:`vertex_faces`) of ``m`` faces."""
    ptr, vf, verts = (np.ascontiguousarray(x, dtype=np.int64).reshape(-1) for x in (ptr, vf, verts))
    out = _faces_at(ptr, vf, verts, int(m))
    if out is None:                    # found in the loop: say which
        _check_index("verts", verts, len(ptr) - 1)
        _check_index("vf", vf, int(m))
        raise ValueError("faces_at: ptr must be row pointers into vf")
    return out


@njit(cache=True, nogil=True)
def _tri_normals(P, F):
    k = F.shape[0]
    out = np.empty((k, 3))
    for i in range(k):
        a, b, c = F[i, 0], F[i, 1], F[i, 2]
        out[i, 0], out[i, 1], out[i, 2] = _cross3(P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2],
                                                  P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2])
    return out


@njit(cache=True, nogil=True, inline="always")
def _sin_cos(u0, u1, u2, v0, v1, v2):
    """(|u x v|, u . v) with numpy's sums (einsum order for both)."""
    c0, c1, c2 = _cross3(u0, u1, u2, v0, v1, v2)
    return np.sqrt(_dot3e(c0, c1, c2, c0, c1, c2)), _dot3e(u0, u1, u2, v0, v1, v2)


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


@njit(cache=True, nogil=True, error_model="numpy")
def _corner_cosines(X):
    k = X.shape[0]
    out = np.empty((k, 3))
    for i in range(k):
        _corner_cos3(X[i, 0], X[i, 1], X[i, 2], out, i)
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
                d = _dot3e(nrm[i, 0], nrm[i, 1], nrm[i, 2], tri_n[t, 0], tri_n[t, 1], tri_n[t, 2])
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
            d = _dot3e(n0, n1, n2, tri_n[t, 0], tri_n[t, 1], tri_n[t, 2])
            if d != d:
                nan = True
            elif d > best:
                best = d
    return (not any_reg) or ((not nan) and best > cos_facing)


@njit(cache=True, nogil=True, inline="always")
def _tri_min_deg(A, B, C):
    """Smallest angle (degrees) of triangle (A, B, C) as ``remesh._min_angle_of`` computes it
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
        r = np.sqrt(_dot3e(d0, d1, d2, d0, d1, d2)) / (0.5 * (h[x] + h[bi]))
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
        cosn = _dot3e(n0, n1, n2, fn_old[f, 0], fn_old[f, 1], fn_old[f, 2])
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
        _bvh_closest(q, 0, 1, bvh_V, bvh_TB, bvh_id, bvh_box, bvh_child, bvh_start, bvh_cnt, bvh_slack, qout, qid,
                     noseed)
        t = qid[0]
        if not _dot3e(n0, n1, n2, tri_n[t, 0], tri_n[t, 1], tri_n[t, 2]) > 0:
            return np.inf
    d0, d1, d2 = P[ai, 0] - P[bi, 0], P[ai, 1] - P[bi, 1], P[ai, 2] - P[bi, 2]
    return np.sqrt(_dot3e(d0, d1, d2, d0, d1, d2))


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
    win = _first_wave(cptr, cres, rtop, rptr, rcand, resolved, ncand)
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
        win = _next_wave(win, good, cptr, cres, rtop, rptr, rcand, resolved, seen, wave)
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
    ``remesh._collapse_edges`` in one compiled pass (the same masks)."""
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
    _check_index("E", E, n)
    _check_index("F", F, n)
    _check_index("cand", cand, len(E))
    _check_index("h0", h0, 3 * len(F))
    if len(h1) and (h1.max(initial=-1) >= 3 * len(F) or h1.min(initial=0) < -1):
        raise ValueError(f"collapse_directions: h1 must be -1 or below {3 * len(F)}")
    rf = np.zeros(n if remove_first is not None else 0, np.bool_)
    if remove_first is not None:
        remove_first = i64(remove_first).reshape(-1)
        _check_index("remove_first", remove_first, n)
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
    # and one row per pair: remesh._Work.set_features' table, renumbered
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
    rows = _counting_order(key, cmax - cmin + 1, rows) if r else rows
    rows = _counting_order(hi, n, rows) if r else rows
    rows = _counting_order(lo, n, rows) if r else rows
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
    feature edges as ``remesh._Work.set_features`` tabulates them (rows (lo, hi) sorted by
    (lo, hi, chain), degenerate rows dropped, one row per pair, the lowest chain), both on
    the vertices renumbered without the removed ones, and ``keep`` (n,) the vertices left.
    The numpy update ``remesh._collapse_edges`` made before it (remap, face filter,
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
        _check_index(name, x, n)
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
    _check_index("vf", vf, len(F))
    _check_index("F", F, n)
    _check_index("u", u, n)
    _check_index("v", v, n)
    if len(vtri) and vtri.max(initial=-1) >= len(tri_n):
        raise ValueError(f"collapse_select: vertex triangles must be below {len(tri_n)}")
    rank = _dense_rank(rank)
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
    n0, n1, n2 = _cross3(b[0] - a[0], b[1] - a[1], b[2] - a[2], c[0] - a[0], c[1] - a[1], c[2] - a[2])
    L = np.sqrt(_dot3e(n0, n1, n2, n0, n1, n2))
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
        if _edge_id(E, kptr, c, d) >= 0:
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
        if not _dot3e(x0, x1, x2, y0, y1, y2) > cosmax:
            continue
        p0, p1, p2 = _unit_normal(Pa, Pd, Pc)
        q0, q1, q2 = _unit_normal(Pd, Pb, Pc)
        if not (_dot3e(p0, p1, p2, x0, x1, x2) > cosmax and _dot3e(p0, p1, p2, y0, y1, y2) > cosmax
                and _dot3e(q0, q1, q2, x0, x1, x2) > cosmax and _dot3e(q0, q1, q2, y0, y1, y2) > cosmax):
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
    bits of the numpy formulas of ``remesh._flip_round``."""
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
    _check_index("E", E, n)
    _check_index("F", F, n)
    if kptr[0] != 0 or kptr[-1] != len(E) or (np.diff(kptr) < 0).any():
        raise ValueError("kptr must be row pointers into E")
    _check_index("h0", h0, 3 * len(F))
    if h1.max(initial=-1) >= 3 * len(F):
        raise ValueError(f"h1 must be below {3 * len(F)}")
    if vtri.max(initial=-1) >= len(tri_n):
        raise ValueError(f"flip_candidates: vertex triangles must be below {len(tri_n)}")
    return _flip_candidates(E, kptr, h0, h1, isf, F, fpatch, P, float(cosmax), kind, vtri, tri_n, float(cos_facing),
                            valence, deg, tgt)


@njit(cache=True, nogil=True, inline="always")
def _cross3(a0, a1, a2, b0, b1, b2):
    """cross_rows' arithmetic on one row."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, nogil=True, inline="always")
def _norm3(x, y, z):
    """norm_rows' sum on one row."""
    return np.sqrt(x * x + y * y + z * z)


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
        den = _norm3(u0, u1, u2) * _norm3(v0, v1, v2)
        if den < 1e-300:                          # np.maximum(den, 1e-300): a NaN stays
            den = 1e-300
        out[i, j] = _dot3e(u0, u1, u2, v0, v1, v2) / den


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
        a0, a1, a2 = _cross3(Pq[0] - Pp[0], Pq[1] - Pp[1], Pq[2] - Pp[2], Pr[0] - Pp[0], Pr[1] - Pp[1], Pr[2] - Pp[2])
        b0, b1, b2 = _cross3(Pp[0] - Pq[0], Pp[1] - Pq[1], Pp[2] - Pq[2], Ps[0] - Pq[0], Ps[1] - Pq[1], Ps[2] - Pq[2])
        la, lb = _norm3(a0, a1, a2), _norm3(b0, b1, b2)
        den = la * lb
        if den < 1e-300:
            den = 1e-300
        if not _dot3e(a0, a1, a2, b0, b1, b2) / den > cmax:
            continue
        if _edge_id(E, kptr, r, s) >= 0:
            continue
        # the new pair (r, s, q), (s, r, p) against the pair's mean unit normal
        c0, c1, c2 = _cross3(Ps[0] - Pr[0], Ps[1] - Pr[1], Ps[2] - Pr[2], Pq[0] - Pr[0], Pq[1] - Pr[1], Pq[2] - Pr[2])
        d0, d1, d2 = _cross3(Pr[0] - Ps[0], Pr[1] - Ps[1], Pr[2] - Ps[2], Pp[0] - Ps[0], Pp[1] - Ps[1], Pp[2] - Ps[2])
        ma = la if la >= 1e-300 or la != la else 1e-300
        mb = lb if lb >= 1e-300 or lb != lb else 1e-300
        g0, g1, g2 = a0 / ma + b0 / mb, a1 / ma + b1 / mb, a2 / ma + b2 / mb
        lg = _norm3(g0, g1, g2)
        if lg < 1e-300:
            lg = 1e-300
        u0, u1, u2 = g0 / lg, g1 / lg, g2 / lg
        orient[k] = (_dot3e(c0, c1, c2, u0, u1, u2) > cmax * _norm3(c0, c1, c2)) and \
            (_dot3e(d0, d1, d2, u0, u1, u2) > cmax * _norm3(d0, d1, d2))
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
    numpy's ``arccos``. The bits of the numpy formulas of ``imprint._flip_round``."""
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
    _check_index("E", E, n)
    _check_index("T", T, n)
    if kptr[0] != 0 or kptr[-1] != len(E) or (np.diff(kptr) < 0).any():
        raise ValueError("kptr must be row pointers into E")
    two = cnt == 2
    _check_index("h0", h0, 3 * len(T))
    _check_index("h1", h1[two], 3 * len(T))
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
        n0, n1, n2 = _cross3(B[0] - A[0], B[1] - A[1], B[2] - A[2], C[0] - A[0], C[1] - A[1], C[2] - A[2])
        flip[i] = _dot3e(n0, n1, n2, nrm[t, 0], nrm[t, 1], nrm[t, 2]) <= 0
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
    numpy rounds of ``imprint._smooth_round``, the same list)."""
    order = np.ascontiguousarray(order, dtype=np.int64).reshape(-1)
    ptr = np.ascontiguousarray(ptr, dtype=np.int64).reshape(-1)
    star = np.ascontiguousarray(star, dtype=np.int64).reshape(-1)
    if not len(ptr) or ptr[0] != 0 or ptr[-1] != len(star) or (np.diff(ptr) < 0).any():
        raise ValueError("star_independent: ptr must be CSR row pointers into star")
    _check_index("order", order, len(ptr) - 1)
    _check_index("star", star, int(ntri))
    return _star_independent(order, ptr, star, int(ntri), int(rounds))


def star_moves(rows, tris, T, P, new, nrm):
    """The imprint smoothing's test of moving vertex ``rows[i]`` from ``P`` to ``new`` alone, for
    each of its triangles ``tris[i]`` (of ``T`` (m, 3)): the :func:`corner_cosines` of the
    triangle with that vertex moved and before (for numpy's ``arccos``), and whether the moved
    triangle's normal (cross_rows of its sides) turns against ``nrm[tris[i]]`` (einsum's dot at
    most 0). The bits of the numpy formulas of ``imprint._smooth_round``."""
    rows = np.ascontiguousarray(rows, dtype=np.int64).reshape(-1)
    tris = np.ascontiguousarray(tris, dtype=np.int64).reshape(-1)
    T = np.ascontiguousarray(T, dtype=np.int64).reshape(-1, 3)
    P, new, nrm = (np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3) for x in (P, new, nrm))
    if len(rows) != len(tris) or len(new) != len(P) or len(nrm) != len(T):
        raise ValueError("star_moves: rows/tris of one length, new one row per point, nrm one per triangle")
    _check_index("rows", rows, len(P))
    _check_index("tris", tris, len(T))
    _check_index("T", T, len(P))
    return _star_moves(rows, tris, T, P, new, nrm)


@njit(cache=True, nogil=True, error_model="numpy")
def _move_tests(cur, Fi, fn_old, area_old, moved, newtri, vtri, reg, tri_n, cosmax, cos_facing):
    k = Fi.shape[0]
    bad = np.empty(k, np.bool_)
    sc = np.empty((4, k))
    for i in range(k):
        q0, q1, q2 = Fi[i, 0], Fi[i, 1], Fi[i, 2]
        A, B, C = cur[q0], cur[q1], cur[q2]
        n0, n1, n2, ar = _unit_normal_area(A, B, C)
        b = _dot3e(n0, n1, n2, fn_old[i, 0], fn_old[i, 1], fn_old[i, 2]) <= cosmax or ar <= 1e-3 * area_old[i]
        dmax = -2.0
        anyreg = False
        for v in (q0, q1, q2):
            t = newtri[v] if moved[v] else vtri[v]
            if reg[v] and t >= 0:
                d = _dot3e(n0, n1, n2, tri_n[t, 0], tri_n[t, 1], tri_n[t, 2])
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
    faces for numpy's ``arctan2``. The bits of the numpy formulas of ``remesh._accept_moves``."""
    Fi = np.ascontiguousarray(Fi, dtype=np.int64).reshape(-1, 3)
    cur, fn_old, tri_n = (np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3) for x in (cur, fn_old, tri_n))
    area_old = np.ascontiguousarray(area_old, dtype=np.float64).reshape(-1)
    moved, reg = (np.ascontiguousarray(x, dtype=np.bool_).reshape(-1) for x in (moved, reg))
    newtri, vtri = (np.ascontiguousarray(x, dtype=np.int64).reshape(-1) for x in (newtri, vtri))
    n = len(cur)
    if len(fn_old) != len(Fi) or len(area_old) != len(Fi) or not (len(moved) == len(reg) == len(newtri)
                                                                    == len(vtri) == n):
        raise ValueError("move_tests: fn_old/area_old one per face; moved, reg, newtri, vtri one per point")
    _check_index("Fi", Fi, n)
    if max(newtri.max(initial=-1), vtri.max(initial=-1)) >= len(tri_n):
        raise ValueError(f"move_tests: input triangles must be below {len(tri_n)}")
    return _move_tests(cur, Fi, fn_old, area_old, moved, newtri, vtri, reg, tri_n, float(cosmax), float(cos_facing))


def _rows3(a):
    """``a`` as a C-contiguous float64 (k, 3) array, or None when it is not one (other dtype or
    shape: the caller falls back on numpy)."""
    if not isinstance(a, np.ndarray) or a.dtype != np.float64 or a.ndim != 2 or a.shape[1] != 3:
        return None
    return np.ascontiguousarray(a)


def cross_rows(a, b):
    """Row-wise cross product of two (k, 3) float64 arrays (``mesh.cross_rows``'s bits); None
    for any other input (the caller uses numpy)."""
    a3, b3 = _rows3(a), _rows3(b)
    if a3 is None or b3 is None or a3.shape != b3.shape:
        return None
    return _cross_rows(a3, b3)


def norm_rows(a):
    """``sqrt((x*x + y*y) + z*z)`` of each row of a (k, 3) float64 array (``mesh.norm_rows``);
    None for any other input."""
    a3 = _rows3(a)
    return None if a3 is None else _norm_rows(a3)


def dot_rows(a, b):
    """``np.einsum("ij,ij->i", a, b)`` of two (k, 3) float64 arrays, the same bits; None for
    any other input."""
    a3, b3 = _rows3(a), _rows3(b)
    if a3 is None or b3 is None or a3.shape != b3.shape:
        return None
    return _dot_rows(a3, b3)


def dot_norm_rows(a):
    """``np.sqrt(np.einsum("ij,ij->i", a, a))`` of a (k, 3) float64 array; None otherwise."""
    a3 = _rows3(a)
    return None if a3 is None else _dot_norm_rows(a3)


def edge_lengths(P, E):
    """``dot_norm_rows(P[E[:, 1]] - P[E[:, 0]])`` (einsum's norm of each edge vector, the same
    bits) without gathering the two ends' rows: ``P`` (n, 3) float64, ``E`` (k, 2) indices."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    E = np.ascontiguousarray(E, dtype=np.int64).reshape(-1, 2)
    _check_index("E", E, len(P))
    return _edge_lengths(P, E)


def dot_unit_rows(a):
    """Rows of a (k, 3) float64 array divided by :func:`dot_norm_rows`, zero rows where that
    norm is not positive (``np.divide(a, n, out=zeros, where=n > 0)``); None otherwise."""
    a3 = _rows3(a)
    return None if a3 is None else _dot_unit_rows(a3)


def triangle_normals(P, F):
    """Unnormalised normals ``cross(P[F1] - P[F0], P[F2] - P[F0])`` of triangles ``F`` (k, >=3),
    the bits of ``mesh.cross_rows`` on the gathered corners."""
    P = np.ascontiguousarray(P, dtype=np.float64).reshape(-1, 3)
    F = np.ascontiguousarray(np.asarray(F)[:, :3], dtype=np.int64)
    _check_index("F", F, len(P))
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


def corner_cosines(X):
    """(k, 3) cosines of the corner angles of triangles with corners ``X`` (k, 3, 3): at corner
    j, ``u . v / max(|u| |v|, 1e-300)`` with u, v the sides to the next and the previous corner
    (einsum's dot and ``norm_rows``' norms, the imprint's formula)."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    if X.ndim != 3 or X.shape[1:] != (3, 3):
        raise ValueError("corner_cosines takes a (k, 3, 3) array of triangle corners")
    return _corner_cosines(X)


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
    _check_index("F", F, len(kind))
    if len(vtri) and vtri.max(initial=-1) >= len(tri_n):
        raise ValueError(f"facing_ok: vertex triangles must be below {len(tri_n)}")
    return _facing_ok(F, kind, vtri, tri_n, nrm, float(cos_facing))


# ============================================================================ curves
@njit(cache=True, nogil=True, error_model="numpy")
def _closest_on_curves(q, cid, start, stop, a, ab, L):
    k = q.shape[0]
    X = np.empty((k, 3))
    D = np.empty(k)
    S = np.empty(k, np.int64)
    for i in range(k):
        q0, q1, q2 = q[i, 0], q[i, 1], q[i, 2]
        best, bs = np.inf, -1
        bx0 = bx1 = bx2 = np.nan
        for s in range(start[cid[i]], stop[cid[i]]):
            f0, f1, f2 = q0 - a[s, 0], q1 - a[s, 1], q2 - a[s, 2]
            if best < np.inf:
                # every point of the segment is within L[s] of a[s]: one farther than best + L[s]
                # (with a slack far above the rounding) cannot be nearer nor tie
                r = best + L[s]
                if f0 * f0 + f1 * f1 + f2 * f2 > r * r * (1.0 + 1e-9) + 1e-300:
                    continue
            t = _dot3(f0, f1, f2, ab[s, 0], ab[s, 1], ab[s, 2])
            t = _clip01(t / (L[s] * L[s]))
            x0, x1, x2 = a[s, 0] + t * ab[s, 0], a[s, 1] + t * ab[s, 1], a[s, 2] + t * ab[s, 2]
            e0, e1, e2 = x0 - q0, x1 - q1, x2 - q2
            d = np.sqrt(_dot3(e0, e1, e2, e0, e1, e2))
            # nearest, then the lowest segment; a NaN distance (a zero-length segment) only
            # when nothing else is there, as lexsort puts NaN last
            if bs < 0 or d < best or (best != best and d == d):
                best, bs = d, s
                bx0, bx1, bx2 = x0, x1, x2
        X[i, 0], X[i, 1], X[i, 2] = bx0, bx1, bx2
        D[i] = best
        S[i] = bs
    return X, D, S


def closest_on_curves(q, cid, start, stop, a, ab, L):
    """Closest point of each query ``q[i]`` (k, 3) on the polyline ``cid[i]``, whose segments
    are ``a[s] + t ab[s]``, ``0 <= t <= 1``, of length ``L[s]``, for ``s`` in
    ``start[cid[i]] .. stop[cid[i]] - 1``. Returns ``(points (k, 3), distances (k,), segments
    (k,))``: over every segment of the polyline, the nearest, then the lowest segment index;
    the same bits as the numpy formulas of :func:`~shellmesh_mdao.smooth._pick_nearest` over
    any set of candidates that holds the nearest segments. ``L`` must be the segments' lengths
    (``norm(ab)``): a segment whose start is farther than the best distance so far plus its
    length is skipped."""
    q = np.ascontiguousarray(q, dtype=np.float64).reshape(-1, 3)
    cid = np.ascontiguousarray(cid, dtype=np.int64).reshape(-1)
    start = np.ascontiguousarray(start, dtype=np.int64)
    stop = np.ascontiguousarray(stop, dtype=np.int64)
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1, 3)
    ab = np.ascontiguousarray(ab, dtype=np.float64).reshape(-1, 3)
    L = np.ascontiguousarray(L, dtype=np.float64).reshape(-1)
    if len(cid) != len(q) or len(stop) != len(start) or len(ab) != len(a) or len(L) != len(a):
        raise ValueError("closest_on_curves: q/cid, start/stop and a/ab/L must have matching lengths")
    _check_index("cid", cid, len(start))
    if len(start) and ((start < 0).any() or (stop > len(a)).any() or (stop <= start).any()):
        raise ValueError(f"every curve needs a non-empty segment range within 0..{len(a)}")
    return _closest_on_curves(q, cid, start, stop, a, ab, L)


def warm_up() -> float:
    """Compile every kernel (or load it from numba's cache) on a tiny input; returns the
    seconds it took (about 45 s on a new install, 0.3 s once cached). Run by ``make install``
    and by the benchmark before its clock starts."""
    import time
    t0 = time.perf_counter()
    greedy_independent(np.array([0, 1, 1]), np.array([0, 0, 1]), np.array([1, 2]), 2,
                       check=lambda w: np.ones(len(w), bool), max_sub=3)
    greedy_independent_rings(np.array([0, 1, 2]), np.array([1, 0]), np.array([0]), np.array([1]), np.array([1]))
    common_neighbour_counts(np.array([0, 1, 2]), np.array([1, 0]), np.array([0]), np.array([1]))
    ortho_jacobian(np.array([0]), np.array([1]), np.array([2]), np.array([[0.0, 0.0, 1.0]]), np.ones(1),
                   np.ones(1), np.ones(1), np.array([0, 2, 4]), np.array([2, 2, 0]), np.eye(3)[[0, 1, 0, 1]])
    ortho_gradient([0], [1], [2], np.array([[0.0, 0.0, 1.0]]), np.ones(1), np.ones(1), np.ones(1), np.eye(3), 3)
    chain_walk(np.array([[0, 1], [0, 2], [1, 2], [2, 3]]), 4)
    arc_links(np.array([0, 1, 3]), np.array([1, 2, 4]), 5, 0)
    arc_order(np.array([0, 1, 2]), np.array([1, 2, 0]), 3, 0)
    segments_scan(np.zeros((1, 3)), [0], [1], np.zeros((1, 3)), np.ones((1, 3)))
    segments_within(np.zeros((1, 3)), np.zeros((1, 3)), np.ones((1, 3)), 1.0)
    corner_sums(np.array([[0, 1, 2, -1]]), np.ones((1, 3)), 3)
    centroid_d2(np.eye(3), np.array([[0, 1, 2]]), np.zeros(3))
    corner_max_turn(np.array([[0, 1, 2, -1]]), np.eye(3), np.ones((1, 3)), 3)
    pair_difference(np.array([0]), np.array([1]), np.ones(1), np.ones((1, 3)), 2)
    rh = ReducedHessian(np.array([0, 1, 2, 3]), np.array([1, 2, 3, 0]), np.array([[0, 1, 2, 3]]),
                        np.array([2, 2, 1, 0]), np.array([0, 2, 4, 5]))
    rh.values(np.eye(3)[[0, 1, 0, 1, 2]], np.ones(4), np.ones(5),
              ortho=(np.tile([0.0, 0.0, 1.0], (4, 1)), np.ones(4), np.ones(4), np.ones(4)),
              warp=(np.array([0]), np.ones((1, 4, 3)), np.ones(1)))
    min_corner_sj(np.eye(3), np.array([[0, 1, 2, -1]]), np.array([True]), np.array([[0.0, 0.0, 1.0]]))
    min_corner_sj(np.eye(3), np.array([[0, 1, 2, -1]]), np.array([True]))
    face_quality(np.zeros((1, 4, 3)), np.array([True]), np.array([[0.0, 0.0, 1.0]]))
    stable_order(np.array([1, 0, 1]), 2)
    stable_pair_order(np.array([1, 0]), np.array([0, 1]), 2)
    rank_desc(np.array([1.0, 0.0]), np.array([3, 2], np.uint64))
    group_order(np.array([1, 0, 1]), 2)
    edge_neighbours(np.array([[0, 1]]), 2)
    vertex_faces(np.array([[0, 1, 2, -1]]), 3)
    vertex_faces(np.array([[0, 1, 2]]), 3)
    closest_on_triangles(np.ones((1, 3)), np.zeros((1, 3)), np.eye(3)[:1], np.eye(3)[1:2])
    TriangleBVH(np.eye(3), np.array([[0, 1, 2]])).closest(np.ones((1, 3)))
    nearest_other_distance(np.eye(3), np.array([0, 2]), 0.5)
    star_independent(np.array([0, 1]), np.array([0, 1, 2]), np.array([0, 0]), 1)
    _in_range(np.zeros(1, np.int64), 1)
    safe_matching_rounds([0], [1], [-1.0], 2)
    closest_on_curves(np.zeros((1, 3)), [0], [0], [1], np.zeros((1, 3)), np.ones((1, 3)), [np.sqrt(3.0)])
    e = np.eye(3)
    cross_rows(e, e)
    norm_rows(e)
    dot_rows(e, e)
    dot_norm_rows(e)
    dot_unit_rows(e)
    edge_lengths(e, np.array([[0, 1]]))
    triangle_normals(e, np.array([[0, 1, 2]]))
    element_normals(np.vstack([e, [1.0, 1.0, 0.0]]), np.array([[0, 1, 2, -1], [0, 1, 3, 2]]), np.array([True, False]))
    faces_at(np.array([0, 1, 2, 2]), np.array([0, 0]), np.array([0, 2]), 1)
    corner_sin_cos(e[:1], e[1:2], e[2:])
    Q = np.zeros((2, 3, 3))
    corner_sin_cos(Q[:, 0], Q[:, 1], Q[:, 2])           # the strided corners of a (k, 3, 3) array
    corner_cosines(e[None])
    facing_ok(np.array([[0, 1, 2]]), np.zeros(3, np.int64), np.zeros(3, np.int64), e, e[:1], 0.5)
    for surf in (None, (TriangleBVH(e, np.array([[0, 1, 2]])), np.zeros(3))):
        collapse_select(np.array([0, 2, 4, 6]), np.array([1, 2, 0, 2, 0, 1]), np.array([0, 1, 2, 3]),
                        np.zeros(3, np.int64), np.array([[0, 1, 2]]), e, np.ones(3), np.array([0]), np.array([1]),
                        np.array([1]), np.array([[True, True]]), max_len_ratio=2.0, fn_old=e[2:], cos_turn=0.5,
                        kind=np.zeros(3, np.int64), vtri=np.zeros(3, np.int64), tri_n=e[:1], cos_facing=0.2,
                        surface=surf)
    Fq = np.array([[0, 1, 2], [1, 0, 3]])
    for dg in (None, np.full(4, 3.0)):
        flip_candidates(np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3]]), np.array([0, 3, 5, 5, 5]),
                        np.array([0, 2, 4, 1, 5]), np.array([3, -1, -1, -1, -1]), np.zeros(5, bool), Fq,
                        np.zeros(2, np.int64), np.vstack([e, [1.0, -1.0, 0.0]]), 0.5, np.zeros(4, np.int64),
                        np.zeros(4, np.int64), e, 0.2, dg, dg)
    _, h0, h1, cnt, E, _ = edge_table(Fq, 4)
    nptr4, nbr4 = edge_neighbours(E, 4)
    collapse_apply(Fq, np.zeros(2, np.int64), np.array([[0, 1], [1, 3]]), np.array([0, -1]), [3], [0], 4)
    for rf in (None, [3]):
        collapse_directions(E, [0, 1], h0, h1, cnt, Fq, nptr4, nbr4, np.zeros(4, np.int64), np.zeros(5, bool),
                            np.ones(4, bool), remove_first=rf)
    skin_flips(E, np.array([0, 3, 5, 5, 5]), h0, h1, cnt, np.zeros(5, bool), Fq, np.vstack([e, [1.0, -1.0, 0.0]]),
               0.5)
    move_tests(e, np.array([[0, 1, 2]]), e[2:], np.ones(1), np.array([True, False, False]), np.zeros(3, np.int64),
               np.zeros(3, np.int64), np.ones(3, bool), e, 0.5, 0.2)
    star_moves(np.array([0]), np.array([0]), Fq, np.vstack([e, [1.0, -1.0, 0.0]]), np.ones((4, 3)), np.ones((2, 3)))
    edge_lookup(np.array([[0, 1], [0, 2], [1, 2]]), np.array([0, 2, 3, 3]), np.array([0, 2]), np.array([1, 1]))
    edge_rows(np.array([[0, 1], [0, 2], [1, 2]]), 3)
    return time.perf_counter() - t0
