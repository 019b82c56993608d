"""Compiled kernels of the merge stage: the exact reduction's safe matching rounds."""
from __future__ import annotations

import numpy as np
from numba import njit
from ..core.kernels import check_index

__all__ = ["safe_matching_rounds"]


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
    """The merge's exact reduction (:func:`shellmesh_mdao.merge.triangles._safe_reduction`) in compiled
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
