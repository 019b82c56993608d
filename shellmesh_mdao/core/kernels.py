"""Compiled (numba) kernels shared by several stages: greedy independent sets, counting sorts, vertex-face
and edge tables, chain walks, the per-row vector formulas ("rows of three") and small geometric primitives.

A kernel only one stage uses lives beside that stage (``<stage>/kernels.py``). Every kernel gives the same
result, bit for bit, as the numpy code it replaced; the compiled loops do not check bounds, so the Python
wrappers check every index first. Compiled on first use and cached next to this file (numba ``cache=True``).
"""
from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["by_resource", "first_wave", "next_wave", "dense_rank", "in_range", "check_index", "select",
           "greedy_independent", "chain_walk", "counting_order", "stable_order", "vertex_faces", "stable_pair_order",
           "edge_table", "edge_id", "edge_rows", "edge_lookup", "dot3", "clip01", "sq_dist", "dot3e", "faces_at",
           "cross3", "norm3", "cross_rows", "norm_rows", "dot_rows", "dot_norm_rows", "dot_unit_rows", "arc_links",
           "arc_order", "on_segment_ab", "segments_scan", "closest_on_curves"]


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
    rptr, rcand = by_resource(cptr, cres, rank, ncand, nres)
    return cptr, cres, rptr, rcand


@njit(cache=True, nogil=True)
def by_resource(cptr, cres, rank, ncand, nres):
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
def first_wave(cptr, cres, rtop, rptr, rcand, resolved, ncand):
    out = np.empty(ncand, np.int64)
    k = 0
    for c in range(ncand):
        if not resolved[c] and _wins(c, cptr, cres, rtop, rptr, rcand, resolved):
            out[k] = c
            k += 1
    return out[:k]


@njit(cache=True, nogil=True)
def next_wave(win, acc, cptr, cres, rtop, rptr, rcand, resolved, seen, wave):
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


def dense_rank(rank):
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
    win = first_wave(cptr, cres, rtop, rptr, rcand, resolved, ncand)
    for wave in range(max_sub):
        if not len(win):
            break
        good = np.ones(len(win), bool) if check is None else np.asarray(check(win), dtype=np.bool_)
        sel[win[good]] = True
        if wave + 1 == max_sub:
            break
        win = next_wave(win, good, cptr, cres, rtop, rptr, rcand, resolved, seen, wave)
    return sel


@njit(cache=True, nogil=True)
def in_range(a, n):
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


def check_index(name, a, n):
    if not len(a):
        return
    ok = (in_range(a.reshape(-1), n) if a.dtype == np.int64 and a.flags.c_contiguous
          else not (a.min() < 0 or a.max() >= n))
    if not ok:
        raise ValueError(f"{name} holds indices outside [0, {n}): {int(a.min())}..{int(a.max())}")


def select(build, rank, alive, check, max_sub):
    """Dense ranks, live mask, ``build(alive, rank, ncand)`` -> the CSR tables, then the waves."""
    rank = dense_rank(rank)
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
    check_index("owner", owner, len(rank))
    check_index("res", res, int(nres))
    if len(owner) != len(res):
        raise ValueError(f"owner and res need one entry each per use, got {len(owner)} and {len(res)}")
    return select(lambda alive, rank, ncand: _build(owner, res, alive, rank, ncand, int(nres)),
                   rank, alive, check, max_sub)


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
    split, which :func:`~shellmesh_mdao.core.supports.polylines_from_edges` used)."""
    e = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    n = int(n)
    check_index("edges", e.ravel(), n)
    if len(e) and ((e[:, 0] >= e[:, 1]).any() or (len(e) > 1 and not (np.diff(e[:, 0] * n + e[:, 1]) > 0).all())):
        raise ValueError("edges must be distinct rows (u, v) with u < v, sorted")
    return _chain_walk(e, n)


# ============================================================================ sorting
@njit(cache=True, nogil=True)
def counting_order(keys, n, idx):
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
    o = counting_order(hi, n, np.arange(hi.shape[0]))
    return counting_order(lo, n, o)


def stable_order(keys, n):
    """``np.argsort(keys, kind="stable")`` for integer keys in [0, n), by a counting sort
    (O(len + n); a stable order is unique, so the same array)."""
    keys = np.ascontiguousarray(keys, dtype=np.int64).reshape(-1)
    check_index("keys", keys, int(n))
    return counting_order(keys, int(n), np.arange(len(keys)))


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
        check_index("faces", F[F != -1], int(n))
        raise ValueError(f"faces holds indices outside [0, {int(n)})")
    return out


def stable_pair_order(lo, hi, n):
    """``np.argsort(lo * n + hi, kind="stable")`` for integer ``lo``, ``hi`` in [0, n): two
    counting sorts (by ``hi``, then stably by ``lo``), the same array without the products."""
    lo = np.ascontiguousarray(lo, dtype=np.int64).reshape(-1)
    hi = np.ascontiguousarray(hi, dtype=np.int64).reshape(-1)
    if len(lo) != len(hi):
        raise ValueError("lo and hi must have the same length")
    check_index("lo", lo, int(n))
    check_index("hi", hi, int(n))
    return _pair_order(lo, hi, int(n))


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
    ``remesh.common.EdgeTable``'s whole-array construction (stable sort of the keys, run starts)."""
    F = np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3)
    check_index("F", F, int(n))
    return _edge_table(F, int(n))


@njit(cache=True, nogil=True, inline="always")
def edge_id(E, kptr, u, v):
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
        out[i] = edge_id(E, kptr, u[i], v[i])
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
        check_index("E", E[:, 0], int(n))
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
    check_index("u", u, len(kptr) - 1)
    check_index("v", v, len(kptr) - 1)
    return _edge_lookup(E, kptr, u, v)


# ============================================================================ triangles
@njit(cache=True, nogil=True, inline="always")
def dot3(x0, x1, x2, y0, y1, y2):
    return (x0 * y0 + x2 * y2) + x1 * y1             # numpy's einsum("ij,ij->i") over three


@njit(cache=True, nogil=True, inline="always")
def clip01(t):
    """np.clip(t, 0, 1): (t > 0 ? t : 0) < 1 ? .. : 1; a NaN stays."""
    if t == t:
        t = t if t > 0.0 else 0.0
        t = t if t < 1.0 else 1.0
    return t


@njit(cache=True, nogil=True, inline="always")
def sq_dist(x0, x1, x2, p0, p1, p2):
    """|x - p|^2 summed as numpy's row norm sums it (``mesh.norm_rows`` is its square root)."""
    e0, e1, e2 = x0 - p0, x1 - p1, x2 - p2
    return (e0 * e0 + e1 * e1) + e2 * e2


# ============================================================================ rows of three
# The per-row vector formulas of the remesh, the imprint and the smoother, called thousands of
# times a run on a few hundred to a few thousand rows, where numpy's per-call overhead and
# temporaries cost more than the arithmetic. Each takes C-contiguous float64 arrays from its
# wrapper (which sends anything else to numpy) and does numpy's arithmetic in numpy's order.
@njit(cache=True, nogil=True, inline="always")
def dot3e(x0, x1, x2, y0, y1, y2):
    """einsum's sum of three products, sign of zero included: einsum adds the sum to an output
    that starts at +0, so a sum of negative zeros comes out +0 (which arctan2 tells apart)."""
    return dot3(x0, x1, x2, y0, y1, y2) + 0.0


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
        out[i] = norm3(a[i, 0], a[i, 1], a[i, 2])
    return out


@njit(cache=True, nogil=True)
def _dot_rows(a, b):
    k = a.shape[0]
    out = np.empty(k)
    for i in range(k):
        out[i] = dot3e(a[i, 0], a[i, 1], a[i, 2], b[i, 0], b[i, 1], b[i, 2])
    return out


@njit(cache=True, nogil=True)
def _dot_norm_rows(a):
    k = a.shape[0]
    out = np.empty(k)
    for i in range(k):
        out[i] = np.sqrt(dot3e(a[i, 0], a[i, 1], a[i, 2], a[i, 0], a[i, 1], a[i, 2]))
    return out


@njit(cache=True, nogil=True, error_model="numpy")
def _dot_unit_rows(a):
    k = a.shape[0]
    out = np.zeros((k, 3))
    for i in range(k):
        n = np.sqrt(dot3e(a[i, 0], a[i, 1], a[i, 2], a[i, 0], a[i, 1], a[i, 2]))
        if n > 0:
            out[i, 0], out[i, 1], out[i, 2] = a[i, 0] / n, a[i, 1] / n, a[i, 2] / n
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
        check_index("verts", verts, len(ptr) - 1)
        check_index("vf", vf, int(m))
        raise ValueError("faces_at: ptr must be row pointers into vf")
    return out


@njit(cache=True, nogil=True, inline="always")
def cross3(a0, a1, a2, b0, b1, b2):
    """cross_rows' arithmetic on one row."""
    return a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0


@njit(cache=True, nogil=True, inline="always")
def norm3(x, y, z):
    """norm_rows' sum on one row."""
    return np.sqrt(x * x + y * y + z * z)


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


def dot_unit_rows(a):
    """Rows of a (k, 3) float64 array divided by :func:`dot_norm_rows`, zero rows where that
    norm is not positive (``np.divide(a, n, out=zeros, where=n > 0)``); None otherwise."""
    a3 = _rows3(a)
    return None if a3 is None else _dot_unit_rows(a3)


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


# ============================================================================ segments
@njit(cache=True, nogil=True, inline="always")
def on_segment_ab(q0, q1, q2, a, ab, s):
    """Closest point of segment ``s`` (``a[s] + t ab[s]``) to ``q``: ``(t, x0, x1, x2, distance)``
    in the arithmetic of ``core.polyline.pick_segments`` (einsum's dot products, ``np.clip``, a t
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
            t, x0, x1, x2, d = on_segment_ab(q0, q1, q2, a, ab, s)
            # the nearest, the lowest segment among equals; NaN distances last (np.lexsort)
            if bs < 0 or d < bd or (bd != bd and d == d):
                bs, bd, bt = s, d, t
                b0, b1, b2 = x0, x1, x2
        x[i, 0], x[i, 1], x[i, 2] = b0, b1, b2
        dist[i] = bd
        seg[i] = bs
        tt[i] = bt
    return x, dist, seg, tt


def segments_scan(q, lo, hi, a, ab):
    """The closest point to each query ``q[i]`` on the segments ``a[s] + t ab[s]``,
    ``lo[i] <= s < hi[i]`` (a non-empty range), scanning them all: ``(points, distances,
    segments, t)``, the nearest segment and the lowest among equally near ones, with
    numpy's arithmetic of ``core.polyline.pick_segments`` (einsum's dot products, ``np.clip``,
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
    the same bits as the numpy formulas of :func:`~shellmesh_mdao.core.supports._pick_nearest` over
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
