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
from .core.kernels import (in_range, check_index, greedy_independent, chain_walk, stable_order, vertex_faces,
                           stable_pair_order, edge_table, edge_id, edge_rows, edge_lookup, dot3, clip01, sq_dist,
                           dot3e, faces_at, cross3, norm3, cross_rows, norm_rows, dot_rows, dot_norm_rows,
                           dot_unit_rows)  # noqa: F401

__all__ = ["greedy_independent", "greedy_independent_rings", "common_neighbour_counts", "ortho_jacobian",
           "ortho_gradient", "ReducedHessian", "chain_walk", "arc_links", "arc_order", "centroid_d2", "corner_sums",
           "corner_max_turn", "segments_scan", "segments_within", "pair_difference", "min_corner_sj", "face_quality",
           "closest_on_curves", "closest_on_triangles", "TriangleBVH", "stable_order", "stable_pair_order",
           "group_order", "edge_neighbours", "vertex_faces", "rank_desc", "edge_table", "edge_rows", "edge_lookup",
           "cross_rows", "norm_rows", "dot_rows", "dot_norm_rows", "dot_unit_rows", "triangle_normals",
           "element_normals", "faces_at", "edge_lengths", "corner_sin_cos", "corner_cosines", "facing_ok",
           "collapse_directions", "collapse_apply", "collapse_select", "flip_candidates", "skin_flips", "star_moves",
           "move_tests", "safe_matching_rounds", "warm_up"]


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
    check_index("f0", f0, int(n_faces))
    check_index("f1", f1, int(n_faces))
    rank = np.empty(k, dtype=np.int64)
    rank[np.lexsort((np.arange(k), w))] = np.arange(k)
    return _safe_rounds(f0, f1, -w, rank, int(n_faces), int(max_rounds))


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
        check_index(name, v, nv)
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
    check_index("u", u, int(nn))
    check_index("v", v, int(nn))
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
    check_index("lu", lu, int(nn))
    check_index("lv", lv, int(nn))
    check_index("start", np.array([int(start)]), int(nn))
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
            check_index(name, v, n)
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
            check_index("warp quads", qi, nq)
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
        check_index("faces", np.concatenate([faces[:, :3].reshape(-1), faces[~is_tri, 3]]), len(P))
        raise ValueError(f"faces holds indices outside [0, {len(P)})")
    return out


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
    check_index("verts", verts, n)
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
    check_index("i", i, int(n))
    check_index("j", j, int(n))
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
                x = 1.0 - dot3e(vn[v, 0], vn[v, 1], vn[v, 2], fn[f, 0], fn[f, 1], fn[f, 2])
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
    check_index("faces", faces[faces >= 0], int(n))
    return _corner_sums(faces, av, int(n))


def corner_max_turn(faces, vn, fn, n):
    """(n,): for each vertex the largest ``1 - vn[v] . fn[f]`` over its faces (0 for a vertex
    without faces): ``np.maximum.at`` of einsum's dot products, the same bits."""
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    vn = np.ascontiguousarray(vn, dtype=np.float64).reshape(-1, 3)
    fn = np.ascontiguousarray(fn, dtype=np.float64).reshape(-1, 3)
    if faces.ndim != 2 or len(faces) != len(fn) or len(vn) != int(n):
        raise ValueError("corner_max_turn needs (m, k) faces, one normal per face and one per vertex")
    check_index("faces", faces[faces >= 0], int(n))
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
    check_index("T", T, len(P))
    return _centroid_d2(P, T, float(x[0]), float(x[1]), float(x[2]))


# ============================================================================ segments
@njit(cache=True, nogil=True, inline="always")
def _on_segment_ab(q0, q1, q2, a, ab, s):
    """Closest point of segment ``s`` (``a[s] + t ab[s]``) to ``q``: ``(t, x0, x1, x2, distance)``
    in the arithmetic of ``imprint._pick_segments`` (einsum's dot products, ``np.clip``, a t
    of 0 on a zero-length segment, row norms)."""
    a0, a1, a2 = a[s, 0], a[s, 1], a[s, 2]
    e0, e1, e2 = ab[s, 0], ab[s, 1], ab[s, 2]
    L2 = dot3e(e0, e1, e2, e0, e1, e2)
    t = clip01(dot3e(q0 - a0, q1 - a1, q2 - a2, e0, e1, e2) / (L2 if L2 > 0 else 1.0))
    x0, x1, x2 = a0 + t * e0, a1 + t * e1, a2 + t * e2
    return t, x0, x1, x2, np.sqrt(sq_dist(x0, x1, x2, q0, q1, q2))


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
            x0, x1, x2 = cross3(P[b, 0] - P[a, 0], P[b, 1] - P[a, 1], P[b, 2] - P[a, 2],
                                 P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2])
        else:
            d = faces[i, 3]
            x0, x1, x2 = cross3(P[c, 0] - P[a, 0], P[c, 1] - P[a, 1], P[c, 2] - P[a, 2],
                                 P[d, 0] - P[b, 0], P[d, 1] - P[b, 1], P[d, 2] - P[b, 2])
        L = np.sqrt(dot3e(x0, x1, x2, x0, x1, x2))
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
        check_index("faces", np.concatenate([faces[:, :3].reshape(-1), faces[~is_tri, 3]]), len(P))
        raise ValueError(f"faces holds indices outside [0, {len(P)})")
    return out


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
    numpy rounds of ``imprint._smooth_round``, the same list)."""
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
    most 0). The bits of the numpy formulas of ``imprint._smooth_round``."""
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
            t = dot3(f0, f1, f2, ab[s, 0], ab[s, 1], ab[s, 2])
            t = clip01(t / (L[s] * L[s]))
            x0, x1, x2 = a[s, 0] + t * ab[s, 0], a[s, 1] + t * ab[s, 1], a[s, 2] + t * ab[s, 2]
            e0, e1, e2 = x0 - q0, x1 - q1, x2 - q2
            d = np.sqrt(dot3(e0, e1, e2, e0, e1, e2))
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
    check_index("cid", cid, len(start))
    if len(start) and ((start < 0).any() or (stop > len(a)).any() or (stop <= start).any()):
        raise ValueError(f"every curve needs a non-empty segment range within 0..{len(a)}")
    return _closest_on_curves(q, cid, start, stop, a, ab, L)


def warm_up() -> float:
    """Compile every kernel (or load it from numba's cache) on a tiny input; returns the
    seconds it took (about 45 s on a new install, 0.3 s once cached). Run by ``make install``
    and by the benchmark before its clock starts."""
    import time

    from .project.kernels import closest_on_triangles, TriangleBVH
    from .remesh.kernels import (greedy_independent_rings, common_neighbour_counts, group_order, edge_neighbours,
                                 rank_desc, collapse_directions, collapse_apply, collapse_select, flip_candidates,
                                 move_tests, edge_lengths, triangle_normals, corner_sin_cos, facing_ok)
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
    in_range(np.zeros(1, np.int64), 1)
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
