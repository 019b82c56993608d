"""Compiled (numba) kernels of the geometry checks: a sweep over the triangles' boxes that tests every
two triangles whose boxes overlap and which share no vertex for a crossing. Compiled on first use and
cached next to this file (numba ``cache=True``)."""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["sweep_crossings"]


@njit(cache=True, nogil=True, inline="always")
def _orient(a, b, c, d):
    """Six times the signed volume of the tetrahedron (a, b, c, d)."""
    b0, b1, b2 = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    c0, c1, c2 = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    d0, d1, d2 = d[0] - a[0], d[1] - a[1], d[2] - a[2]
    return (b1 * c2 - b2 * c1) * d0 + (b2 * c0 - b0 * c2) * d1 + (b0 * c1 - b1 * c0) * d2


@njit(cache=True, nogil=True)
def _edge_crosses(p, q, a, b, c, tol):
    """Does the segment p-q pass through the triangle (a, b, c) (strictly, beyond ``tol``)?"""
    s1 = _orient(a, b, c, p)
    s2 = _orient(a, b, c, q)
    if not ((s1 > tol and s2 < -tol) or (s1 < -tol and s2 > tol)):
        return False
    o1 = _orient(p, q, a, b)
    o2 = _orient(p, q, b, c)
    o3 = _orient(p, q, c, a)
    return (o1 > tol and o2 > tol and o3 > tol) or (o1 < -tol and o2 < -tol and o3 < -tol)


@njit(cache=True, nogil=True)
def _cross(V, T, i, j, tol):
    for e in range(3):
        if _edge_crosses(V[T[i, e]], V[T[i, (e + 1) % 3]], V[T[j, 0]], V[T[j, 1]], V[T[j, 2]], tol):
            return True
        if _edge_crosses(V[T[j, e]], V[T[j, (e + 1) % 3]], V[T[i, 0]], V[T[i, 1]], V[T[i, 2]], tol):
            return True
    return False


@njit(cache=True, nogil=True)
def sweep_crossings(V, T, lo, hi, order, axis, rel_tol):
    """Pairs (i, j) of triangles ``T`` (vertices ``V``) sharing no vertex whose edges pass through
    each other: a sweep along ``axis`` over the boxes ``lo``/``hi`` in ``order`` (ascending
    ``lo[:, axis]``). The tolerance of a pair is ``rel_tol`` times its larger box edge, cubed.
    Returns ``(pairs, n_tested)``."""
    m = order.shape[0]
    out = []
    tested = 0
    for a in range(m):
        i = order[a]
        for b in range(a + 1, m):
            j = order[b]
            if lo[j, axis] > hi[i, axis]:
                break
            if (lo[j, 0] > hi[i, 0] or lo[i, 0] > hi[j, 0] or lo[j, 1] > hi[i, 1] or lo[i, 1] > hi[j, 1]
                    or lo[j, 2] > hi[i, 2] or lo[i, 2] > hi[j, 2]):
                continue
            shared = False
            for u in range(3):
                for v in range(3):
                    if T[i, u] == T[j, v]:
                        shared = True
            if shared:
                continue
            tested += 1
            size = 0.0
            for k in range(3):
                size = max(size, hi[i, k] - lo[i, k], hi[j, k] - lo[j, k])
            if _cross(V, T, i, j, rel_tol * size * size * size):
                out.append((min(i, j), max(i, j)))
    res = np.empty((len(out), 2), np.int64)
    for k in range(len(out)):
        res[k, 0] = out[k][0]
        res[k, 1] = out[k][1]
    return res, tested
