"""Compiled kernels of the smoothing stage: the orthogonality Jacobian and gradient, the reduced Hessian,
corner scaled Jacobians, trust radii, closest points on support curves and element normals.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..core.threads import Background
from ..core.kernels import check_index, cross3, dot3e

__all__ = ["ortho_jacobian", "ortho_gradient", "ReducedHessian", "face_quality", "min_corner_sj",
           "nearest_other_distance", "pair_difference", "corner_sums", "corner_max_turn", "element_normals"]


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
    """Jacobian of the quad-corner orthogonality residuals (:class:`~shellmesh_mdao.smooth.energy.OrthoTerm`)
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
    bits as the numpy version of :meth:`~shellmesh_mdao.smooth.energy.OrthoTerm.gradient`: each role's
    terms summed over the corners in order (``np.bincount``), then the three roles added."""
    x = np.ascontiguousarray(x, dtype=np.float64).reshape(-1, 3)
    nv = int(nv)
    if len(x) != nv:
        raise ValueError(f"x must hold the nv = {nv} positions")
    a, b, c, n, su, sv, w = _corners(a, b, c, n, su, sv, w, nv)
    return _ortho_gradient(a, b, c, n, su, sv, w, x, nv)


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
            other = Background(_hessian_values, *args, mid, n)
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
    (smooth.elements._corner_normals, smooth.elements._unit), its edges ``E``, the corners' cross products
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
    ``nref`` (m, 3) (a flipped element): :func:`shellmesh_mdao.smooth.elements.oriented_quality`, the same
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
    version (:func:`shellmesh_mdao.smooth.elements._corner_min_sj` on the corners and
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
