"""Cutting the skin along the member planes: the crossing points inserted first, then each chain's
cut (snap, split, re-triangulate) with its vertices moved onto the exact curve; the chains become
feature edges and fixed vertices (:func:`imprint_chains`)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..core.polyline import arc_param, closest_on_polyline, sub_polyline
from ..errors import ImprintError
from ..core.kernels import chain_walk
from .kernels import centroid_d2
from ..mesh import ShellMesh, bbox_diagonal, cross_rows, norm_rows, reduce_short, unique_edges
from ..options import ImprintOptions
from .common import tri_angles_min
from .checks import check_crossing_collisions, check_loop_corners, fmt_point
from .crossings import arc_crossings, arc_feature_crossings
from ..core.section import SectionArc, plane_section, section_arc
from .specs import ChainSpec

__all__ = ["SNAP_FALLBACK", "ChainResult", "imprint_chains", "insert_point", "cut_chain", "chain_report",
           "split_hanging", "split_at_surface_midpoints", "split_feature_edges"]


#: snap distance a cut is redone at when a larger one misses a crossing (:func:`imprint_chains`)
SNAP_FALLBACK = 0.25


@dataclass
class ChainResult:
    """One imprinted chain: ``member`` and ``side`` as in its :class:`ChainSpec`, its ordered skin
    ``vertices`` (the later imprint steps update them in place), its exact ``arc`` and the
    ``snap`` distance its cut used."""

    member: str
    side: str
    vertices: np.ndarray          # ordered chain vertex indices in the skin mesh
    arc: SectionArc = field(repr=False, default=None)
    snap: float = SNAP_FALLBACK   # snap distance its cut used (the fallback when the asked one failed)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)


def _snap_keeps_star(P, T, v, x, min_angle: float = 1.0):
    """Whether moving vertex ``v`` to ``x`` leaves every triangle around it unfolded (normal
    within 90 degrees of its old one) and with all angles above ``min_angle`` degrees (or
    above its own smallest angle before the move). A crossing point lying on an edge
    opposite ``v`` (a point on a sharp trailing edge next to a skin vertex) would otherwise
    turn that triangle into a zero-area sliver."""
    star = T[reduce_short(T == v, "any")]
    if not len(star):
        return True
    Q = P.copy()
    Q[v] = x

    def normals(X):
        return cross_rows(X[star[:, 1]] - X[star[:, 0]], X[star[:, 2]] - X[star[:, 0]])

    unfolded = np.einsum("ij,ij->i", normals(P), normals(Q)) > 0
    a0, a1 = tri_angles_min(P, star), tri_angles_min(Q, star)
    return bool((unfolded & (a1 >= np.minimum(min_angle, a0))).all())


def insert_point(P: np.ndarray, T: np.ndarray, comp: np.ndarray, x: np.ndarray, movable: np.ndarray,
                 snap: float = 0.3):
    """Insert the surface point ``x`` as a vertex of the triangle mesh (P, T).

    The triangle nearest to ``x`` is found; if a movable vertex of it lies within ``snap``
    times the triangle's mean edge length, that vertex is moved to ``x``; else if ``x`` is
    close to an edge (smallest barycentric coordinate below ``snap/3``) that edge is split
    (both incident triangles), else the triangle is split in three. Returns
    ``(P, T, comp, vertex_index)``.
    """
    x = np.asarray(x, float)
    insert_point.last_split = None
    # candidate triangles: the 32 nearest centroids (nearest first; one point, so a plain
    # compiled scan beats building a tree: kernels.centroid_d2), then exact point-triangle
    # distance
    k = min(32, len(T))
    d2 = centroid_d2(P, T, x)
    cand = np.argpartition(d2, k - 1)[:k] if k < len(T) else np.arange(len(T))
    cand = cand[np.argsort(d2[cand], kind="stable")]
    bary, dist = _point_tri(x, P[T[cand, 0]], P[T[cand, 1]], P[T[cand, 2]])
    j = int(np.argmin(dist))
    f = int(cand[j])
    w = bary[j]
    tri = T[f]
    L = np.mean(norm_rows(P[tri] - P[np.roll(tri, -1)], axis=1))
    dv = norm_rows(P[tri] - x, axis=1)
    order = np.argsort(dv, kind="stable")
    for i in order:
        if dv[i] <= snap * L and movable[tri[i]] and _snap_keeps_star(P, T, int(tri[i]), x):
            P = P.copy()
            P[tri[i]] = x
            return P, T, comp, int(tri[i])
        if dv[i] <= 1e-12 * L:          # already a vertex (fixed): reuse it
            return P, T, comp, int(tri[i])
    n = len(P)
    P = np.vstack([P, x[None]])
    if w.min() < snap / 3:
        # split the edge opposite the smallest barycentric coordinate
        i = int(np.argmin(w))
        u, v = tri[(i + 1) % 3], tri[(i + 2) % 3]
        has_u = reduce_short(T == u, "any")
        has_v = reduce_short(T == v, "any")
        faces = np.flatnonzero(has_u & has_v)
        newT, newC = [], []
        keep = np.ones(len(T), bool)
        for g in faces:
            t = T[g]
            r = int(np.flatnonzero((t != u) & (t != v))[0])
            # rotate so that t = (opp, p, q) with edge p-q = {u, v}
            t = np.roll(t, -r)
            newT += [[t[0], t[1], n], [t[0], n, t[2]]]
            newC += [comp[g], comp[g]]
            keep[g] = False
        T = np.vstack([T[keep], np.asarray(newT, T.dtype)])
        comp = np.concatenate([comp[keep], np.asarray(newC, comp.dtype)])
        insert_point.last_split = (min(u, v), max(u, v))
        return P, T, comp, n
    t = tri
    newT = np.array([[t[0], t[1], n], [t[1], t[2], n], [t[2], t[0], n]], T.dtype)
    keep = np.ones(len(T), bool)
    keep[f] = False
    T = np.vstack([T[keep], newT])
    comp = np.concatenate([comp[keep], np.repeat(comp[f], 3)])
    return P, T, comp, n


def _point_tri(p, a, b, c):
    """Barycentric coordinates of the closest point on each triangle to p, and the distance."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    den = va + vb + vc
    with np.errstate(divide="ignore", invalid="ignore"):
        v = vb / den
        w = vc / den
    bary = np.stack([1 - v - w, v, w], 1)
    # clamp outside cases by projecting onto the triangle's edges
    out = (bary < 0).any(1) | ~np.isfinite(bary).all(1)
    if out.any():
        best = np.full(out.sum(), np.inf)
        bb = np.zeros((out.sum(), 3))
        A, B, C = a[out], b[out], c[out]
        for (i0, i1, s, e) in [(0, 1, A, B), (1, 2, B, C), (2, 0, C, A)]:
            se = e - s
            L2 = np.einsum("ij,ij->i", se, se)
            t = np.clip(np.einsum("ij,ij->i", p - s, se) / np.where(L2 > 0, L2, 1), 0, 1)
            dd = norm_rows(s + t[:, None] * se - p, axis=1)
            better = dd < best
            best = np.where(better, dd, best)
            nb = np.zeros((len(t), 3))
            nb[np.arange(len(t)), i0] = 1 - t
            nb[np.arange(len(t)), i1] = t
            bb = np.where(better[:, None], nb, bb)
        bary[out] = bb
    x = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    return bary, norm_rows(x - p, axis=1)


def cut_chain(P: np.ndarray, T: np.ndarray, comp: np.ndarray, spec: ChainSpec, arc: SectionArc,
              movable: np.ndarray, on_plane: np.ndarray, snap: float = ImprintOptions.snap,
              name: str | None = None, end_vertices=None):
    """Cut the skin triangulation (P, T) along ``spec.plane`` inside ``spec.bounds``, on the
    piece through ``spec.seed``; move the chain vertices onto the exact input ``arc``.

    ``movable`` (n,) marks vertices that may be snapped (those within ``snap`` times their
    shortest incident edge of the plane; default the solver option ``snap``); ``on_plane``
    (n,) marks vertices that must be treated as lying exactly on this plane (crossing
    vertices inserted beforehand); ``end_vertices`` the two of them where an open chain ends. Returns
    ``(P, T, comp, chain_vertices_in_order, (split_edges, new_nodes))``:
    the last pair lists the old edges that received a new node, so the caller can split
    feature edges lying on them.
    """
    name = name or f"{spec.member} ({spec.side})"
    n0 = len(P)
    d = spec.plane.side(P)
    d = np.where(on_plane, 0.0, d)
    # the working skin's own section through the seed gives the faces to cut
    try:
        diag = bbox_diagonal(P)
        stops = None if arc.closed or end_vertices is None else np.asarray(end_vertices, np.int64)
        work = section_arc(P, T, spec.plane, spec.bounds, seed=spec.seed, name=name,
                           zero_vertices=np.flatnonzero(on_plane), bound_tol=1e-9 * diag,
                           stop_vertices=stops)
    except ImprintError as e:
        raise ImprintError(f"{name}: the member plane misses the working skin inside its bounds ({e}); "
                           "use a smaller --size or check the member position") from None
    region = np.unique(work.tri)
    if not len(region):
        raise ImprintError(f"{name}: empty imprint region; use a smaller --size")
    # local edge length per vertex of the region: its shortest incident region edge
    rt = T[region]
    rb = np.roll(rt, -1, axis=1)
    el = norm_rows(P[rt] - P[rb], axis=2).ravel()
    vmin = np.full(len(P), np.inf)
    np.minimum.at(vmin, rt.ravel(), el)
    np.minimum.at(vmin, rb.ravel(), el)
    rv = np.unique(rt)
    h = vmin[rv]
    # signs: zero only for vertices inside the bounds (exactly on the plane, snapped, or
    # crossing vertices given); outside the bounds a vertex on the plane counts as + (diag:
    # of the same points, measured above)
    inside = np.ones(len(P), bool)
    for bnd in spec.bounds:
        inside &= bnd.side(P) >= -1e-9 * diag
    sgn = np.where(d >= 0, 1.0, -1.0)
    sgn[(d == 0) & inside] = 0.0
    sgn[on_plane] = 0.0
    close = rv[(np.abs(d[rv]) <= snap * h) & movable[rv] & inside[rv]]
    sgn[close] = 0.0
    # never three zero corners in one triangle: un-snap the farthest snapped corner. Every
    # triangle around a snapped vertex counts, also one outside the region (beside the cut,
    # its third corner already on the plane): an all-zero face breaks the chain there
    snapped = np.zeros(len(P), bool)
    snapped[close] = True
    near = T[reduce_short(snapped[T], "any")]
    for _ in range(10):
        allz = near[(sgn[near] == 0).all(1)]
        if not len(allz):
            break
        cand = np.where(snapped[allz], np.abs(d[allz]), -1.0)
        worst = allz[np.arange(len(allz)), np.argmax(cand, axis=1)]
        worst = worst[snapped[worst]]
        if not len(worst):
            break
        sgn[worst] = np.where(d[worst] >= 0, 1.0, -1.0)
        snapped[worst] = False
    # faces to split: region faces with a + and a - vertex, or a 0 vertex and a +/- pair
    s = sgn[rt]
    has_pos = (s > 0).any(1)
    has_neg = (s < 0).any(1)
    split = has_pos & has_neg
    # crossing points on edges with strictly opposite signs (unique edges)
    fs = rt[split]
    ss = s[split]
    a_, b_ = fs, np.roll(fs, -1, axis=1)
    sa, sb = ss, np.roll(ss, -1, axis=1)
    cross = (sa * sb) < 0
    rows, cols = np.nonzero(cross)
    ea, eb = a_[rows, cols], b_[rows, cols]
    keys = np.stack([np.minimum(ea, eb), np.maximum(ea, eb)], 1)
    uedges, inv = np.unique(keys, axis=0, return_inverse=True) if len(keys) else (np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    inv = inv.reshape(-1)
    dl, dh = d[uedges[:, 0]], d[uedges[:, 1]]
    tpar = dl / (dl - dh)
    xnew = P[uedges[:, 0]] + tpar[:, None] * (P[uedges[:, 1]] - P[uedges[:, 0]])
    new_id = n0 + np.arange(len(uedges))
    P = np.vstack([P, xnew])
    # per split face: vertex or new node at each corner/edge position, then re-triangulate
    edge_node = np.full(fs.shape, -1, np.int64)
    edge_node[rows, cols] = new_id[inv]
    newT, newC = _retriangulate(P, fs, ss, edge_node, comp[region][split])
    keep = np.ones(len(T), bool)
    keep[region[split]] = False
    # faces outside the region that share a split edge must be split too (conformity):
    # an edge crossing found in a region face whose neighbour is outside the region
    T2 = np.vstack([T[keep], newT])
    C2 = np.concatenate([comp[keep], newC])
    T2, C2 = split_hanging(P, T2, C2, uedges, new_id)
    # label faces touching the region by their side (mixed or all-zero faces: 0); chain edges
    # are the zero-zero edges separating a + face from a - face
    sgn_all = np.concatenate([sgn, np.zeros(len(new_id))])
    touch = np.zeros(len(P), bool)
    touch[rv] = True
    touch[n0:] = True
    fsg = sgn_all[T2]
    pos_f, neg_f = reduce_short(fsg > 0, "any"), reduce_short(fsg < 0, "any")
    label = np.where(pos_f & ~neg_f, 1, np.where(neg_f & ~pos_f, -1, 0))
    label[~reduce_short(touch[T2], "any")] = 0
    chain_v = _chain_from_labels(T2, label, name, P)
    P = P.copy()
    old = chain_v < n0
    mov = chain_v[~old | ~on_plane[np.minimum(chain_v, n0 - 1)]]
    if len(mov):
        before = P[mov]
        P[mov] = closest_on_polyline(before, arc.points, arc.closed)
        _unfold_on_arc(P, chain_v, mov, before, arc)
    return P, T2, C2, chain_v, (uedges, new_id)


def _unfold_on_arc(P, chain_v, mov, before, arc, passes: int = 3) -> int:
    """Keep the chain's order along its arc. Where the skin is thinner than its faces (a
    trailing edge at a wing tip, at a coarse size) the closest arc point of a chain vertex can
    lie on the far side of the section: the chain then runs back along the arc and forth again
    (a spike, a corner of almost 0 degrees in the member's outline). Such a vertex (``mov``,
    positions ``before`` its projection) whose neighbours along the chain are in order goes to
    its closest point on the piece of the arc between them instead. Updates ``P`` in place;
    returns the number of vertices moved."""
    chain_v = np.asarray(chain_v, np.int64)
    k = len(chain_v)
    if k < 3:
        return 0
    orig = dict(zip(np.asarray(mov, np.int64).tolist(), np.asarray(before)))
    closed = bool(arc.closed) and k >= 4
    moved = 0
    for _ in range(passes):
        s, poly, cum = arc_param(P[chain_v], arc.points, arc.closed)
        Ltot = float(cum[-1])
        d = np.diff(np.concatenate([s, s[:1]]) if closed else s)
        if arc.closed:
            d = d - Ltot * np.round(d / Ltot)
        sgn = 1.0 if d.sum() >= 0 else -1.0
        back = d * sgn <= 0                                  # step i -> i + 1 runs back along the arc
        idx = np.arange(k) if closed else np.arange(1, k - 1)
        prev_back = back[(idx - 1) % len(back)]
        next_back = back[idx % len(back)] if closed else back[idx]
        span = (s[(idx + 1) % k] - s[(idx - 1) % k]) * sgn
        if arc.closed:
            span = span - Ltot * np.floor(span / Ltot)
        fold = (prev_back | next_back) & (span > 0) & np.isin(chain_v[idx], mov)
        if not fold.any():
            break
        # one vertex of each run of folded neighbours per pass (its neighbours must be in order)
        cand = idx[fold]
        cand = cand[~np.isin(cand - 1, cand)] if not closed else cand[:1]
        for i in cand.tolist():
            a, b = s[(i - 1) % k], s[(i + 1) % k]
            lo, hi = (a, b) if sgn > 0 else (b, a)
            if arc.closed and hi < lo:                       # the piece wraps past the arc's start
                piece = np.vstack([sub_polyline(poly, cum, lo, Ltot), sub_polyline(poly, cum, 0.0, hi)[1:]])
            elif hi > lo:
                piece = sub_polyline(poly, cum, lo, hi)
            else:
                continue
            v = int(chain_v[i])
            P[v] = closest_on_polyline(orig[v][None], piece, False)[0]
            moved += 1
    return moved


def _chain_from_labels(T, label, name, P=None):
    """Ordered vertices of the edges separating faces labelled +1 from faces labelled -1: a
    path from its lower end vertex, or a loop from its lowest vertex towards the lower of that
    vertex's two neighbours (:func:`~shellmesh_mdao.core.kernels.chain_walk`). A chain that branches
    or falls into pieces is an :class:`ImprintError` whose ``point`` (with ``P`` given) is where."""
    ok = label != 0
    Tl = T[ok].astype(np.int64)
    a, b = Tl, np.roll(Tl, -1, axis=1)
    lo, hi = np.minimum(a, b).ravel(), np.maximum(a, b).ravel()
    lab = np.repeat(label[ok], 3)
    n = np.int64(int(T.max()) + 1) if len(T) else np.int64(1)
    key, inv = np.unique(lo * n + hi, return_inverse=True)     # the edges in (lo, hi) order
    inv = inv.reshape(-1)
    has_pos = np.zeros(len(key), bool)
    has_neg = np.zeros(len(key), bool)
    has_pos[inv[lab > 0]] = True
    has_neg[inv[lab < 0]] = True
    ck = key[has_pos & has_neg]
    ce = np.stack([ck // n, ck % n], 1)
    if not len(ce):
        raise ImprintError(f"{name}: the imprint produced no chain edges; use a smaller --size")
    verts, deg = np.unique(ce, return_counts=True)
    where = None
    try:
        if (deg > 2).any():
            where = int(verts[deg > 2][0])
            raise ImprintError(f"{name}: the imprinted curve branches at vertex {where}; "
                               "the member is too close to another member or to a sharp edge for this --size "
                               "(use a smaller --size or move the member)")
        if (deg == 1).sum() not in (0, 2):
            where = int(verts[deg == 1][0])
            raise ImprintError(f"{name}: the imprinted curve is broken into pieces; use a smaller --size")
        nodes, ptr, _ = chain_walk(ce, int(n))
        if len(ptr) != 2:
            where = int(nodes[ptr[1] - 1])
            raise ImprintError(f"{name}: the imprinted curve is broken into pieces; use a smaller --size")
    except ImprintError as e:
        e.point = None if P is None or where is None else np.asarray(P[where], float)
        raise
    return nodes


def _retriangulate(P, fs, ss, edge_node, comp):
    """Split each face (3 corners with signs in {-1,0,1}) along the zero level set."""
    out_t, out_c = [], []
    # case A: one zero corner, the other two opposite signs -> 2 triangles
    nz = (ss == 0).sum(1)
    A = np.flatnonzero(nz == 1)
    if len(A):
        r = np.argmax(ss[A] == 0, axis=1)                  # zero corner
        idx = (r[:, None] + np.arange(3)[None]) % 3
        f = np.take_along_axis(fs[A], idx, 1)
        en = np.take_along_axis(edge_node[A], idx, 1)       # en[:,1] = node on edge (c1,c2)
        m = en[:, 1]
        out_t += [np.stack([f[:, 0], f[:, 1], m], 1), np.stack([f[:, 0], m, f[:, 2]], 1)]
        out_c += [comp[A], comp[A]]
    # case B: no zero corner -> one lone corner; triangle + quad (best diagonal)
    B = np.flatnonzero(nz == 0)
    if len(B):
        s = ss[B]
        lone = np.where((s[:, 0] == s[:, 1]), 2, np.where(s[:, 1] == s[:, 2], 0, 1))
        idx = (lone[:, None] + np.arange(3)[None]) % 3
        f = np.take_along_axis(fs[B], idx, 1)               # f0 lone, f1, f2 same side
        en = np.take_along_axis(edge_node[B], idx, 1)       # en[:,0] on (f0,f1), en[:,2] on (f2,f0)
        m01, m20 = en[:, 0], en[:, 2]
        out_t.append(np.stack([f[:, 0], m01, m20], 1))
        out_c.append(comp[B])
        # quad m01, f1, f2, m20: diagonal m01-f2 or f1-m20, choose the larger min angle
        t1a = np.stack([m01, f[:, 1], f[:, 2]], 1)
        t1b = np.stack([m01, f[:, 2], m20], 1)
        t2a = np.stack([m01, f[:, 1], m20], 1)
        t2b = np.stack([f[:, 1], f[:, 2], m20], 1)
        q1 = np.minimum(tri_angles_min(P, t1a), tri_angles_min(P, t1b))
        q2 = np.minimum(tri_angles_min(P, t2a), tri_angles_min(P, t2b))
        use1 = q1 >= q2
        out_t += [np.where(use1[:, None], t1a, t2a), np.where(use1[:, None], t1b, t2b)]
        out_c += [comp[B], comp[B]]
    if not out_t:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int32)
    return np.vstack(out_t).astype(np.int64), np.concatenate(out_c).astype(np.int32)


def split_hanging(P, T, C, uedges, new_id):
    """Split every triangle that has an edge which received a new node (``uedges[i]`` got
    node ``new_id[i]``): one split edge -> 2 triangles, two -> 3 (best diagonal), three -> 4.
    Keeps the mesh conforming."""
    if not len(uedges):
        return T, C
    n = int(max(T.max(), new_id.max())) + 1
    key = uedges[:, 0] * n + uedges[:, 1]
    order = np.argsort(key)
    key, node = key[order], new_id[order]
    a, b = T, np.roll(T, -1, axis=1)
    k = np.minimum(a, b) * n + np.maximum(a, b)
    pos = np.clip(np.searchsorted(key, k), 0, len(key) - 1)
    hit = key[pos] == k
    nhit = reduce_short(hit, "sum")
    if not nhit.any():
        return T, C
    mid = np.where(hit, node[pos], -1)                    # node on side i (corner i -> i+1)
    out_t, out_c = [T[nhit == 0]], [C[nhit == 0]]
    # one split side: rotate so the split side is 0 (corners 0-1)
    r = np.flatnonzero(nhit == 1)
    if len(r):
        col = np.argmax(hit[r], axis=1)
        idx = (col[:, None] + np.arange(3)[None]) % 3
        f = np.take_along_axis(T[r], idx, 1)
        m = mid[r, col]
        out_t += [np.stack([f[:, 0], m, f[:, 2]], 1), np.stack([m, f[:, 1], f[:, 2]], 1)]
        out_c += [C[r], C[r]]
    # two split sides: rotate so the unsplit side is 2 (corners 2-0); sides 0 and 1 split
    r = np.flatnonzero(nhit == 2)
    if len(r):
        col = (np.argmin(hit[r], axis=1) + 1) % 3           # first split side after the unsplit one
        idx = (col[:, None] + np.arange(3)[None]) % 3
        f = np.take_along_axis(T[r], idx, 1)
        m0 = mid[r, col]
        m1 = mid[r, (col + 1) % 3]
        out_t.append(np.stack([m0, f[:, 1], m1], 1))
        out_c.append(C[r])
        # quad f0, m0, m1, f2
        t1a, t1b = np.stack([f[:, 0], m0, m1], 1), np.stack([f[:, 0], m1, f[:, 2]], 1)
        t2a, t2b = np.stack([f[:, 0], m0, f[:, 2]], 1), np.stack([m0, m1, f[:, 2]], 1)
        q1 = np.minimum(tri_angles_min(P, t1a), tri_angles_min(P, t1b))
        q2 = np.minimum(tri_angles_min(P, t2a), tri_angles_min(P, t2b))
        u = (q1 >= q2)[:, None]
        out_t += [np.where(u, t1a, t2a), np.where(u, t1b, t2b)]
        out_c += [C[r], C[r]]
    r = np.flatnonzero(nhit == 3)
    if len(r):
        f = T[r]
        m0, m1, m2 = mid[r, 0], mid[r, 1], mid[r, 2]
        out_t += [np.stack([f[:, 0], m0, m2], 1), np.stack([m0, f[:, 1], m1], 1),
                  np.stack([m2, m1, f[:, 2]], 1), np.stack([m0, m1, m2], 1)]
        out_c += [C[r]] * 4
    return np.vstack(out_t), np.concatenate(out_c)


def imprint_chains(skin: ShellMesh, surface_points: np.ndarray, surface_tris: np.ndarray, chains,
                   snap: float = ImprintOptions.snap, tol: float = 1e-9, locator=None,
                   snap_fallback: float = SNAP_FALLBACK):
    """Imprint every chain of ``chains`` (list of :class:`ChainSpec`) into the triangle
    ``skin`` (vertices on the input surface given by ``surface_points``/``surface_tris``).

    ``snap``: snap distance of the cut (:func:`cut_chain`; default the solver option ``snap``,
    :class:`~shellmesh_mdao.options.ImprintOptions`). A cut at a snap distance above
    ``snap_fallback`` that does not keep the chain's crossing points (an open chain not
    ending at its two crossing vertices, a crossing vertex on its arc left out of it, or a
    branching chain) is redone at ``snap_fallback``: a larger snap can reach skin vertices
    beside a crossing point, across a thin section; one still not keeping them is redone
    without snapping, and that cut is taken when it keeps them. ``ChainResult.snap`` tells which
    was used.

    Returns ``(mesh, results)``: the imprinted skin (feature edges of each chain tagged with
    the member's component id, chain vertices fixed) and one :class:`ChainResult` per chain.
    ``locator``: a :class:`~shellmesh_mdao.core.locator.SurfaceLocator` of the input surface (built
    when not given) used to put new skin vertices onto it.
    """
    if locator is None:
        from ..core.locator import SurfaceLocator
        locator = SurfaceLocator(surface_points, surface_tris)
    if skin.n_quads:
        raise ImprintError("imprint works on a triangle skin; got quads (run it before merging)")
    diag = bbox_diagonal(surface_points)
    eps = tol * diag
    # 1. exact arcs on the input surface
    #    (the plane section of the whole input once per plane: a member's chains share it)
    sections: dict = {}

    def section_of(plane):
        key = (np.asarray(plane.point, float).tobytes(), np.asarray(plane.normal, float).tobytes())
        if key not in sections:
            sections[key] = plane_section(surface_points, surface_tris, plane)
        return sections[key]

    arcs = [section_arc(surface_points, surface_tris, c.plane, c.bounds, seed=c.seed, seed_tri=c.seed_tri,
                        name=f"{c.member} ({c.side})", section=section_of(c.plane)) for c in chains]
    # layouts the cut cannot represent, refused here from the exact curves (at any size)
    check_loop_corners(chains, arcs, eps)
    # 2. crossing points: ends of open arcs, and points where one arc crosses another
    #    member's plane ON that member's arc (a middle spar crossing a rib); deduplicated.
    #    ``owners``: the members each point belongs to (for the refusal naming them)
    cand = [a.points[[0, -1]] for a in arcs if not a.closed]
    owners = [(c.member,) for c, a in zip(chains, arcs) if not a.closed for _ in range(2)]
    pairs: list = []
    cross = arc_crossings(chains, arcs, eps, pairs=pairs)
    cand += cross
    owners += [(chains[i].member, chains[j].member) for x, (i, j) in zip(cross, pairs) for _ in range(len(x))]
    feat = arc_feature_crossings(arcs, surface_points, surface_tris, skin, eps)
    cand += feat
    owners += [("a sharp edge of the surface",) for x in feat for _ in range(len(x))]
    P, T, C = skin.points.copy(), skin.faces[:, :3].copy(), skin.component.copy()
    names = list(skin.component_names)
    fixed = np.zeros(len(P), bool)
    fixed[skin.fixed_vertices] = True
    fe = [skin.feature_edges]
    fid = [skin.feature_edge_ids]
    feat_v = np.zeros(len(P), bool)
    feat_v[skin.feature_edges.ravel()] = True
    cross_ids = np.zeros(0, np.int64)
    Xu = np.zeros((0, 3))
    if cand:
        X = np.vstack(cand)
        pairs = cKDTree(X).query_pairs(eps, output_type="ndarray")
        rep = np.arange(len(X))
        if len(pairs):
            from scipy import sparse
            from scipy.sparse.csgraph import connected_components
            g = sparse.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(X), len(X)))
            _, lab = connected_components(g, directed=False)
            first = np.full(lab.max() + 1, len(X))
            np.minimum.at(first, lab, np.arange(len(X)))
            rep = first[lab]
        uniq = np.unique(rep)
        Xu = X[uniq]
        own = [tuple(sorted({n for k in np.flatnonzero(rep == r).tolist() for n in owners[k]})) for r in uniq]
        cross_ids = np.empty(len(uniq), np.int64)
        for k in range(len(uniq)):             # a few points per member
            movable = ~(fixed | feat_v)
            P, T, C, vid = insert_point(P, T, C, Xu[k], movable)
            cross_ids[k] = vid
            if insert_point.last_split is not None:
                f2, i2 = split_feature_edges(np.vstack(fe), np.concatenate(fid),
                                             np.array([insert_point.last_split]), np.array([vid]))
                fe, fid = [f2], [i2]
            grow = len(P) - len(fixed)
            fixed = np.concatenate([fixed, np.zeros(grow, bool)])
            feat_v = np.concatenate([feat_v, np.zeros(grow, bool)])
            fixed[vid] = True
        if len(np.unique(cross_ids)) != len(cross_ids):
            check_crossing_collisions(Xu, own, cross_ids, float(np.median(norm_rows(
                skin.points[skin.faces[:, 0]] - skin.points[skin.faces[:, 1]], axis=1))))
        # an edge joining two crossing vertices (e.g. the upper and lower crossing of a thin
        # section on a coarse skin) would make the plane run along it: split it
        P, T, C, (split_e, new_n) = _split_edges_between(P, T, C, cross_ids, locator)
        f2, i2 = split_feature_edges(np.vstack(fe), np.concatenate(fid), split_e, new_n)
        fe, fid = [f2], [i2]
        grow = len(P) - len(fixed)
        fixed = np.concatenate([fixed, np.zeros(grow, bool)])
        feat_v = np.concatenate([feat_v, np.zeros(grow, bool)])
    results, failed = [], []
    for ci, (spec, arc) in enumerate(zip(chains, arcs)):
        member_id = names.index(spec.member) if spec.member in names else (names.append(spec.member) or len(names) - 1)
        on = np.zeros(len(P), bool)
        must = np.zeros(0, np.int64)
        if len(cross_ids):
            xs = cross_ids[np.abs(spec.plane.side(P[cross_ids])) <= eps]
            on[xs] = True
            # crossing vertices lying on this chain's own arc: the chain must pass through them
            if len(xs):
                dx = norm_rows(closest_on_polyline(P[xs], arc.points, arc.closed) - P[xs], axis=1)
                must = xs[dx <= 1e3 * eps]
        movable = ~(fixed | feat_v)
        endv = None
        if not arc.closed:
            d_end, i_end = cKDTree(Xu).query(arc.points[[0, -1]])
            endv = cross_ids[i_end]
        used = snap
        try:
            try:
                cut = cut_chain(P, T, C, spec, arc, movable, on, snap=snap, end_vertices=endv)
                clean = _keeps_crossings(cut[3], must, endv)
            except ImprintError:
                if snap <= snap_fallback:
                    raise
                clean = False
            if not clean and snap > snap_fallback:
                cut = cut_chain(P, T, C, spec, arc, movable, on, snap=snap_fallback, end_vertices=endv)
                used = snap_fallback
                clean = _keeps_crossings(cut[3], must, endv)
            if not clean and used > 0:
                # last resort, no snapping: a vertex snapped beside a chain end can leave both faces of
                # the chain's last edge on one side of the plane (the chain then stops short of its end)
                try:
                    bare = cut_chain(P, T, C, spec, arc, movable, on, snap=0.0, end_vertices=endv)
                    if _keeps_crossings(bare[3], must, endv):
                        cut, used = bare, 0.0
                except ImprintError:
                    pass
            if endv is not None and not _keeps_crossings(cut[3], np.zeros(0, np.int64), endv):
                _raise_off_ends(spec, cut[0], cut[3], endv)
        except ImprintError as e:
            # the skin is as before this chain (a cut returns new arrays): go on with the others,
            # so that one refusal names every chain that cannot be imprinted
            failed.append((ci, e))
            continue
        P, T, C, chain_v, (split_e, new_n) = cut
        grow = len(P) - len(fixed)
        fixed = np.concatenate([fixed, np.zeros(grow, bool)])
        feat_v = np.concatenate([feat_v, np.zeros(grow, bool)])
        # feature edges that were split get the new node
        fe, fid = split_feature_edges(np.vstack(fe), np.concatenate(fid), split_e, new_n)
        fe, fid = [fe], [fid]
        ce = np.stack([chain_v[:-1], chain_v[1:]], 1)
        if arc.closed:
            ce = np.vstack([ce, [[chain_v[-1], chain_v[0]]]])
        fe.append(np.sort(ce, axis=1))
        fid.append(np.full(len(ce), member_id, np.int32))
        fixed[chain_v] = True
        feat_v[chain_v] = True
        results.append(ChainResult(spec.member, spec.side, chain_v, arc, used))
    if failed:
        _raise_failed(failed, chains, arcs, P, T)
    mesh = ShellMesh(P, T, C, names, np.flatnonzero(fixed), np.vstack(fe), np.concatenate(fid))
    return mesh, results


def _raise_failed(failed, chains, arcs, P, T) -> None:
    """One :class:`ImprintError` for every chain the cut could not imprint (``failed``: pairs of
    chain index and its error): each with the place it broke and the other members whose exact
    curves pass within two skin edges of it (the members it is too close to), or else the
    input's sharp edge. A single failure keeps its own message, with those names added."""
    el = norm_rows(P[T[:, 0]] - P[T[:, 1]], axis=1)
    h = float(np.median(el)) if len(el) else 0.0
    parts = []
    for ci, e in failed:                                  # the few failed chains
        x = getattr(e, "point", None)
        msg = str(e)
        if x is not None:
            near = sorted({c.member for c, a in zip(chains, arcs) if c.member != chains[ci].member and
                           norm_rows(closest_on_polyline(x[None], a.points, a.closed) - x[None], axis=1)[0]
                           <= 2.0 * h})
            who = ("; within two skin edges of " + ", ".join(f"'{n}'" for n in near)) if near else \
                "; no other member within two skin edges (a sharp or thin edge of the skin there)"
            msg = f"{msg} [near {fmt_point(x)}{who}]"
        parts.append(msg)
    if len(parts) == 1:
        raise ImprintError(parts[0])
    raise ImprintError(f"{len(parts)} member curves could not be imprinted at this --size: " + " | ".join(parts))


def _raise_off_ends(spec, P, chain_v, end_vertices) -> None:
    """An open chain that does not run between its two end vertices: the working skin's section
    through the member's seed left the member's own skin side (a skin face there spans from one
    side of the wing to the other, where the wing is thinner than the skin's edges) and came
    back along the other side. The chain would fold the skin; refuse it, naming the member, its
    ends and where the section left them."""
    ends = [int(v) for v in end_vertices]
    off = [int(v) for v in (chain_v[0], chain_v[-1]) if int(v) not in ends]
    far = off[0] if off else int(chain_v[len(chain_v) // 2])
    raise ImprintError(f"{spec.member} ({spec.side}): its curve on the skin does not run between its ends "
                       f"{fmt_point(P[ends[0]])} and {fmt_point(P[ends[1]])}: it leaves that skin side near "
                       f"{fmt_point(P[far])} (a skin face there spans both sides of the wing: the member lies within "
                       "about an element of the end of the skin or of a thin edge); move the member away from that "
                       "end or edge in the layout (by a few element sizes), or use a smaller --size")


def _keeps_crossings(chain_v, must, end_vertices) -> bool:
    """True when the chain ``chain_v`` passes through every vertex of ``must`` and, when
    open (``end_vertices`` given), ends at those two vertices."""
    if len(must) and not np.isin(must, chain_v).all():
        return False
    if end_vertices is not None and chain_v[0] != chain_v[-1]:
        return {int(chain_v[0]), int(chain_v[-1])} == {int(v) for v in end_vertices}
    return True


def _split_edges_between(P, T, C, verts, locator):
    """Split every edge whose two ends are both in ``verts`` at its midpoint, projected onto
    the input surface (both incident triangles are split in two). Also returns the split
    edges and their new nodes (for the feature edges lying on them)."""
    is_v = np.zeros(len(P), bool)
    is_v[verts] = True
    a, b = T, np.roll(T, -1, axis=1)
    hit = is_v[a] & is_v[b]
    if not hit.any():
        return P, T, C, (np.zeros((0, 2), np.int64), np.zeros(0, np.int64))
    e = unique_edges(a[hit], b[hit])
    P, T, C, new_id = split_at_surface_midpoints(P, T, C, e, locator)
    return P, T, C, (e, new_id)


def split_at_surface_midpoints(P, T, C, e, locator):
    """Split the edges ``e`` (k, 2; sorted, unique) at their midpoints moved to the closest
    point of the input surface; every triangle on them is split (:func:`split_hanging`).
    Returns ``(P, T, C, new_ids)``."""
    mid = locator.closest(0.5 * (P[e[:, 0]] + P[e[:, 1]]))[0]
    new_id = len(P) + np.arange(len(e))
    P = np.vstack([P, mid])
    T, C = split_hanging(P, T, C, e, new_id)
    return P, T, C, new_id


def split_feature_edges(fe, fid, split_edges, new_nodes):
    """The feature edges ``fe`` (ids ``fid``) with each one that is among ``split_edges`` (sorted
    pairs) replaced by its two halves through its new node ``new_nodes[i]``: ``(fe, fid)``."""
    if not len(split_edges) or not len(fe):
        return fe, fid
    fe = np.sort(fe, axis=1)
    n = int(max(fe.max(), split_edges.max())) + 1
    key = split_edges[:, 0] * n + split_edges[:, 1]
    o = np.argsort(key)
    key, node = key[o], new_nodes[o]
    k = fe[:, 0] * n + fe[:, 1]
    pos = np.clip(np.searchsorted(key, k), 0, len(key) - 1)
    hit = key[pos] == k
    if not hit.any():
        return fe, fid
    m = node[pos[hit]]
    a, b = fe[hit, 0], fe[hit, 1]
    new = np.vstack([np.stack([a, m], 1), np.stack([m, b], 1)])
    return (np.vstack([fe[~hit], np.sort(new, axis=1)]),
            np.concatenate([fid[~hit], fid[hit], fid[hit]]))


def chain_report(mesh: ShellMesh, chains) -> dict:
    """The imprint's entry of the pipeline report: ``{member: {"chains": [{"side", "n_vertices",
    "snap", "length"}, ...]}}``, one record per chain of ``chains`` (:class:`ChainResult`), its
    length measured along its vertices in ``mesh``."""
    members: dict = {}
    for c in chains:
        e = members.setdefault(c.member, {"chains": []})
        e["chains"].append({"side": c.side, "n_vertices": int(c.n_vertices), "snap": float(c.snap),
                            "length": float(norm_rows(np.diff(mesh.points[c.vertices], axis=0), axis=1).sum())})
    return members
