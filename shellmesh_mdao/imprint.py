"""Imprint: make each member's curve on the skin a chain of skin mesh edges.

Stage order: load -> layout -> project -> **imprint** -> members -> split -> merge -> smooth -> quad -> export.

For every planar member (rib, spar, and each segment of an explicit member) the exact
curve ``plane ∩ input surface`` between the member's bounds is traced on the INPUT
triangulation (:mod:`.section`): a plane meets each input triangle in an exact segment,
so the curve is exact. The working skin (the remeshed triangulation, whose vertices lie
on the input surface) is then cut by the same plane inside the same bounds:

1. the crossing points where two members meet on the skin (a rib's side line meets a
   spar's) are inserted first, as single vertices both chains will share;
2. skin vertices within ``snap`` times the local edge length of the plane are snapped
   onto the curve (no sliver triangles), the remaining crossed edges are split at the
   plane and the crossed triangles re-triangulated (best diagonal); a cut that misses one
   of its crossing vertices (a larger snap can reach a vertex across a thin section beside
   a crossing) is redone at ``SNAP_FALLBACK``;
3. every new or snapped chain vertex is moved to its closest point on the exact input
   curve, so it lies on the input surface AND on the member plane;
4. the chain edges become ``feature_edges`` tagged with the member's component id, their
   vertices ``fixed_vertices``; later stages never split, merge or move them off the chain.

All per-face work is vectorised; Python loops run over members and crossing points only.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .errors import ImprintError
from .kernels import (centroid_d2, chain_walk, corner_cosines, edge_lookup, edge_rows, edge_table, greedy_independent,
                      segments_scan, segments_within, skin_flips, star_independent, star_moves)
from .mesh import ShellMesh, bbox_diagonal, cross_rows, norm_rows, reduce_short, unique_edges, vertex_faces
from .section import Plane, SectionArc, plane_section, section_arc

__all__ = ["ChainSpec", "ChainResult", "closest_on_polyline", "insert_point", "cut_chain",
           "refine_chains", "split_member_bridges"]


@dataclass
class ChainSpec:
    """One curve to imprint: ``plane`` inside the half-spaces ``bounds`` (side >= 0 is
    inside), the connected piece through ``seed`` (a point on the input surface, in the
    plane, e.g. a ray-cast hit; ``seed_tri`` its input triangle). ``member`` names the
    member (its component name) and ``side`` the skin side ('upper', 'lower', 'loop')."""

    member: str
    side: str
    plane: Plane
    bounds: tuple
    seed: np.ndarray
    seed_tri: int = -1
    ends: tuple = ()   # crossing points (3,) that must be vertices of this chain


#: snap distance a cut is redone at when a larger one misses a crossing (:func:`imprint_chains`)
SNAP_FALLBACK = 0.25
#: closest points on polylines: up to this many query-segment pairs every query scans every
#: segment in a compiled loop; above, a KD-tree of segment midpoints picks candidates (the same
#: points either way)
SCAN_WORK = 2_000_000


@dataclass
class ChainResult:
    member: str
    side: str
    vertices: np.ndarray          # ordered chain vertex indices in the skin mesh
    arc: SectionArc = field(repr=False, default=None)
    snap: float = SNAP_FALLBACK   # snap distance its cut used (the fallback when the asked one failed)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)


def closest_on_polyline(q: np.ndarray, poly: np.ndarray, closed: bool = False) -> np.ndarray:
    """Closest points on a polyline (k, 3) to query points (n, 3), vectorised via a KD-tree
    of segment midpoints with a conservative candidate radius (:func:`_closest_on_segments`)."""
    q = np.atleast_2d(np.asarray(q, float))
    p = np.vstack([poly, poly[:1]]) if closed else poly
    return _closest_on_segments(q, p[:-1], p[1:])[0]


def _closest_on_arcs(q: np.ndarray, cid: np.ndarray, arcs, params: bool = False):
    """Closest point of each query ``q[i]`` on the arc ``arcs[cid[i]]``: the same points, bit
    for bit, as :func:`closest_on_polyline` arc by arc, in one query. Up to
    :data:`SCAN_WORK` query-segment pairs, one compiled loop scans every segment of each
    query's arc (:func:`~shellmesh_mdao.kernels.segments_scan`). Above, the segment midpoints
    of all arcs go in one KD-tree with the arc's index times a separation far larger than
    the model as a fourth coordinate, so a query meets only its own arc's segments (at their
    plain distance); its candidates lie within the nearest midpoint's distance plus half its
    arc's longest segment, as in :func:`_closest_on_segments`, and the nearest candidate wins
    (ties: the lowest segment), as in the scan. ``params``: also return each point's arc
    length from its arc's first point."""
    q = np.asarray(q, float).reshape(-1, 3)
    cid = np.asarray(cid, np.int64)
    ids = np.unique(cid)
    pos = np.full(len(arcs), -1, np.int64)
    pos[ids] = np.arange(len(ids))
    ends = [np.vstack([arcs[c].points, arcs[c].points[:1]]) if arcs[c].closed else arcs[c].points for c in ids]
    nseg = np.array([len(p) - 1 for p in ends], np.int64)
    a = np.concatenate([p[:-1] for p in ends])
    b = np.concatenate([p[1:] for p in ends])
    ab = b - a
    L = norm_rows(ab, axis=1)
    seg_arc = np.repeat(np.arange(len(ids)), nseg)
    first = np.concatenate([[0], np.cumsum(nseg)[:-1]])
    qa = pos[cid]
    if int(nseg[qa].sum()) <= SCAN_WORK:
        # each query against every segment of its own arc in one compiled loop (the same pick
        # over a set that holds the KD-tree's candidates)
        x, _, seg, t = segments_scan(q, first[qa], first[qa] + nseg[qa], a, ab)
    else:
        x, seg, t = _closest_on_arcs_tree(q, qa, a, b, ab, L, seg_arc, len(ids))
    if not params:
        return x
    cum = np.concatenate([[0.0], np.cumsum(L)])
    return x, cum[seg] - cum[first[seg_arc[seg]]] + t * L[seg]


def _closest_on_arcs_tree(q, qa, a, b, ab, L, seg_arc, narcs):
    """:func:`_closest_on_arcs`' pick through one KD-tree of the segment midpoints of all arcs
    (for large inputs): ``(points, segments, t)``."""
    Lmax = np.zeros(narcs)
    np.maximum.at(Lmax, seg_arc, L)
    mid = 0.5 * (a + b)
    sep = 1e3 * (float(np.abs(mid).max()) + float(np.abs(q).max()) + float(L.max()) + 1.0)
    tree = cKDTree(np.column_stack([mid, seg_arc * sep]))
    q4 = np.column_stack([q, qa * sep])
    d0, _ = tree.query(q4)
    cand = tree.query_ball_point(q4, d0 + 0.5 * Lmax[qa] + 1e-300)
    cnt = np.fromiter((len(c) for c in cand), np.int64, len(cand))
    qi = np.repeat(np.arange(len(q)), cnt)
    si = np.concatenate([np.asarray(c, np.int64) for c in cand])
    keep = seg_arc[si] == qa[qi]
    x, _, seg, t = _pick_segments(q, qi[keep], si[keep], a, ab)
    return x, seg, t


def _tri_angles_min(P, T):
    """Smallest interior angle (degrees) of each triangle ``P[T]``."""
    return _angles3(P[np.asarray(T)[:, :3]])


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
    a0, a1 = _tri_angles_min(P, star), _tri_angles_min(Q, star)
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
              movable: np.ndarray, on_plane: np.ndarray, snap: float = 0.25, name: str | None = None,
              end_vertices=None):
    """Cut the skin triangulation (P, T) along ``spec.plane`` inside ``spec.bounds``, on the
    piece through ``spec.seed``; move the chain vertices onto the exact input ``arc``.

    ``movable`` (n,) marks vertices that may be snapped; ``on_plane`` (n,) marks vertices
    that must be treated as lying exactly on this plane (crossing vertices inserted
    beforehand); ``end_vertices`` the two of them where an open chain ends. Returns
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
    T2, C2 = _split_hanging(P, T2, C2, uedges, new_id)
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
    chain_v = _chain_from_labels(T2, label, name)
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
        s, poly, cum = _arc_param(P[chain_v], arc.points, arc.closed)
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
                piece = np.vstack([_sub_polyline(poly, cum, lo, Ltot), _sub_polyline(poly, cum, 0.0, hi)[1:]])
            elif hi > lo:
                piece = _sub_polyline(poly, cum, lo, hi)
            else:
                continue
            v = int(chain_v[i])
            P[v] = closest_on_polyline(orig[v][None], piece, False)[0]
            moved += 1
    return moved


def _chain_from_labels(T, label, name):
    """Ordered vertices of the edges separating faces labelled +1 from faces labelled -1: a
    path from its lower end vertex, or a loop from its lowest vertex towards the lower of that
    vertex's two neighbours (:func:`~shellmesh_mdao.kernels.chain_walk`)."""
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
    if (deg > 2).any():
        raise ImprintError(f"{name}: the imprinted curve branches at vertex {int(verts[deg > 2][0])}; "
                           "the member is too close to another member or to a sharp edge for this --size "
                           "(use a smaller --size or move the member)")
    if (deg == 1).sum() not in (0, 2):
        raise ImprintError(f"{name}: the imprinted curve is broken into pieces; use a smaller --size")
    nodes, ptr, _ = chain_walk(ce, int(n))
    if len(ptr) != 2:
        raise ImprintError(f"{name}: the imprinted curve is broken into pieces; use a smaller --size")
    return nodes


def _arc_param(q: np.ndarray, poly: np.ndarray, closed: bool):
    """Arc-length parameter of the closest point on a polyline to each query point, and the
    polyline's cumulative lengths (:func:`_closest_on_segments`)."""
    p = np.vstack([poly, poly[:1]]) if closed else poly
    L = norm_rows(p[1:] - p[:-1], axis=1)
    cum = np.concatenate([[0.0], np.cumsum(L)])
    _, _, seg, t = _closest_on_segments(q, p[:-1], p[1:], full=True)
    return cum[seg] + t * L[seg], p, cum


def _arc_point(p: np.ndarray, cum: np.ndarray, s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, cum[-1])
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 2)
    seg = np.maximum(cum[i + 1] - cum[i], 1e-300)
    t = np.clip((s - cum[i]) / seg, 0.0, 1.0)
    return p[i] + t[:, None] * (p[i + 1] - p[i])


def _sub_polyline(p: np.ndarray, cum: np.ndarray, s0: float, s1: float) -> np.ndarray:
    """The piece of a polyline (points ``p``, cumulative lengths ``cum``) between parameters
    ``s0 < s1``."""
    inner = (cum > s0) & (cum < s1)
    return np.vstack([_arc_point(p, cum, np.array([s0])), p[inner], _arc_point(p, cum, np.array([s1]))])


def _polyline_param(q, poly, cum):
    a, b = poly[:-1], poly[1:]
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    # brute force over segments in chunks (chains are short: hundreds of segments)
    out = np.empty(len(q))
    for s in range(0, len(q), 256):
        qq = q[s:s + 256]
        t = np.clip(np.einsum("qij,ij->qi", qq[:, None, :] - a[None], ab) / np.where(L2 > 0, L2, 1), 0, 1)
        x = a[None] + t[..., None] * ab[None]
        dist = norm_rows(x - qq[:, None, :], axis=2)
        j = np.argmin(dist, axis=1)
        out[s:s + 256] = cum[j] + t[np.arange(len(qq)), j] * np.sqrt(L2[j])
    return out


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
        q1 = np.minimum(_tri_angles_min(P, t1a), _tri_angles_min(P, t1b))
        q2 = np.minimum(_tri_angles_min(P, t2a), _tri_angles_min(P, t2b))
        use1 = q1 >= q2
        out_t += [np.where(use1[:, None], t1a, t2a), np.where(use1[:, None], t1b, t2b)]
        out_c += [comp[B], comp[B]]
    if not out_t:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int32)
    return np.vstack(out_t).astype(np.int64), np.concatenate(out_c).astype(np.int32)


def _split_hanging(P, T, C, uedges, new_id):
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
        q1 = np.minimum(_tri_angles_min(P, t1a), _tri_angles_min(P, t1b))
        q2 = np.minimum(_tri_angles_min(P, t2a), _tri_angles_min(P, t2b))
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
                   snap: float = 0.25, tol: float = 1e-9, locator=None, snap_fallback: float = SNAP_FALLBACK):
    """Imprint every chain of ``chains`` (list of :class:`ChainSpec`) into the triangle
    ``skin`` (vertices on the input surface given by ``surface_points``/``surface_tris``).

    ``snap``: snap distance of the cut (:func:`cut_chain`; the pipeline passes its solver option
    ``snap``, 0.4 by default). A cut at a snap distance above
    ``snap_fallback`` that does not keep the chain's crossing points (an open chain not
    ending at its two crossing vertices, a crossing vertex on its arc left out of it, or a
    branching chain) is redone at ``snap_fallback``: a larger snap can reach skin vertices
    beside a crossing point, across a thin section. ``ChainResult.snap`` tells which was used.

    Returns ``(mesh, results)``: the imprinted skin (feature edges of each chain tagged with
    the member's component id, chain vertices fixed) and one :class:`ChainResult` per chain.
    ``locator``: a :class:`~shellmesh_mdao.project.SurfaceLocator` of the input surface (built
    when not given) used to put new skin vertices onto it.
    """
    if locator is None:
        from .project import SurfaceLocator
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
    # 2. crossing points: ends of open arcs, and points where one arc crosses another
    #    member's plane ON that member's arc (a middle spar crossing a rib); deduplicated
    cand = [a.points[[0, -1]] for a in arcs if not a.closed]
    cand += _arc_crossings(chains, arcs, eps)
    cand += _arc_feature_crossings(arcs, surface_points, surface_tris, skin, eps)
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
        cross_ids = np.empty(len(uniq), np.int64)
        for k in range(len(uniq)):             # a few points per member
            movable = ~(fixed | feat_v)
            P, T, C, vid = insert_point(P, T, C, Xu[k], movable)
            cross_ids[k] = vid
            if insert_point.last_split is not None:
                f2, i2 = _split_feature_edges(np.vstack(fe), np.concatenate(fid),
                                              np.array([insert_point.last_split]), np.array([vid]))
                fe, fid = [f2], [i2]
            grow = len(P) - len(fixed)
            fixed = np.concatenate([fixed, np.zeros(grow, bool)])
            feat_v = np.concatenate([feat_v, np.zeros(grow, bool)])
            fixed[vid] = True
        if len(np.unique(cross_ids)) != len(cross_ids):
            raise ImprintError("two member crossing points fell on the same skin vertex: members are closer "
                               "than the element size; use a smaller --size or move the members apart")
        # an edge joining two crossing vertices (e.g. the upper and lower crossing of a thin
        # section on a coarse skin) would make the plane run along it: split it
        P, T, C, (split_e, new_n) = _split_edges_between(P, T, C, cross_ids, locator)
        f2, i2 = _split_feature_edges(np.vstack(fe), np.concatenate(fid), split_e, new_n)
        fe, fid = [f2], [i2]
        grow = len(P) - len(fixed)
        fixed = np.concatenate([fixed, np.zeros(grow, bool)])
        feat_v = np.concatenate([feat_v, np.zeros(grow, bool)])
    results = []
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
            cut = cut_chain(P, T, C, spec, arc, movable, on, snap=snap, end_vertices=endv)
            clean = _keeps_crossings(cut[3], must, endv)
        except ImprintError:
            if snap <= snap_fallback:
                raise
            clean = False
        if not clean and snap > snap_fallback:
            cut = cut_chain(P, T, C, spec, arc, movable, on, snap=snap_fallback, end_vertices=endv)
            used = snap_fallback
        P, T, C, chain_v, (split_e, new_n) = cut
        grow = len(P) - len(fixed)
        fixed = np.concatenate([fixed, np.zeros(grow, bool)])
        feat_v = np.concatenate([feat_v, np.zeros(grow, bool)])
        # feature edges that were split get the new node
        fe, fid = _split_feature_edges(np.vstack(fe), np.concatenate(fid), split_e, new_n)
        fe, fid = [fe], [fid]
        ce = np.stack([chain_v[:-1], chain_v[1:]], 1)
        if arc.closed:
            ce = np.vstack([ce, [[chain_v[-1], chain_v[0]]]])
        fe.append(np.sort(ce, axis=1))
        fid.append(np.full(len(ce), member_id, np.int32))
        fixed[chain_v] = True
        feat_v[chain_v] = True
        results.append(ChainResult(spec.member, spec.side, chain_v, arc, used))
    mesh = ShellMesh(P, T, C, names, np.flatnonzero(fixed), np.vstack(fe), np.concatenate(fid))
    return mesh, results


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
    P, T, C, new_id = _split_at_surface_midpoints(P, T, C, e, locator)
    return P, T, C, (e, new_id)


def _split_at_surface_midpoints(P, T, C, e, locator):
    """Split the edges ``e`` (k, 2; sorted, unique) at their midpoints moved to the closest
    point of the input surface; every triangle on them is split (:func:`_split_hanging`).
    Returns ``(P, T, C, new_ids)``."""
    mid = locator.closest(0.5 * (P[e[:, 0]] + P[e[:, 1]]))[0]
    new_id = len(P) + np.arange(len(e))
    P = np.vstack([P, mid])
    T, C = _split_hanging(P, T, C, e, new_id)
    return P, T, C, new_id


def chain_depths(chains) -> np.ndarray:
    """The depth of the member section each chain bounds: the median distance from the
    chain's exact arc points to the nearest of the other arcs of its member (a rib's upper
    chain: the rib's local height). inf for a chain without an arc or without another arc on
    its member."""
    depth = np.full(len(chains), np.inf)
    by_member: dict = {}
    for ci, c in enumerate(chains):                    # a few chains per member
        by_member.setdefault(c.member, []).append(ci)
    for ci, c in enumerate(chains):
        if c.arc is None or not len(c.arc.points):
            continue
        others = [chains[cj].arc for cj in by_member[c.member]
                  if cj != ci and chains[cj].arc is not None and len(chains[cj].arc.points) >= 2]
        if others:
            d = np.min([norm_rows(closest_on_polyline(c.arc.points, o.points, o.closed) - c.arc.points, axis=1)
                        for o in others], axis=0)
            depth[ci] = float(np.median(d))
    return depth


def refine_chains(mesh: ShellMesh, chains, max_deviation: float, rounds: int = 4,
                  depth_fraction: float = 0.0) -> ShellMesh:
    """Split chain edges whose exact arc bulges more than ``max_deviation`` from the chord, at
    the arc point farthest from it (on the input surface and the member plane); both skin
    triangles on the edge are split, and a feature edge on it becomes two. Up to ``rounds``
    passes. Open chains only (a closed loop's chain is left as it is). Each chain's
    ``vertices`` is updated in place (new vertices appended to the mesh, inserted in order);
    new vertices are fixed.

    With ``depth_fraction`` above 0 a chain's bound is also at most that fraction of its
    member's depth (:func:`chain_depths`: the median distance from the chain's arc to the
    member's other chain, one figure per chain): a chord bulging ``s`` from its arc over a
    length ``c`` cuts off about ``2/3 s c`` of the section, so with ``s`` at most ``f`` times
    the depth ``d`` the member's two chains of length ``L`` lose at most about ``4/3 f d L``,
    ``4/3 f`` of an area ``d L`` (1 % at ``f`` 0.0075), however thin the section is against
    the element size.

    A chain whose vertices are snapped skin vertices has chords as long as the skin's edges;
    on a curved section they cut off area (bwb's thin outer wing: a rib 1.05 % smaller than
    its exact section). The pipeline runs this when the solver option ``chain_deviation`` is
    above 0 (a fraction of the remesh edge length; default 0.01), with ``depth_fraction``
    the option ``chain_depth_deviation`` (default 0.0075)."""
    P, T, C = mesh.points.copy(), mesh.faces[:, :3].copy(), mesh.component.copy()
    fe = np.sort(np.asarray(mesh.feature_edges, np.int64).reshape(-1, 2), axis=1)
    fid = np.asarray(mesh.feature_edge_ids).copy()
    fixed = list(np.asarray(mesh.fixed_vertices, np.int64))
    bound = np.full(len(chains), float(max_deviation))
    if depth_fraction > 0:
        bound = np.minimum(bound, float(depth_fraction) * chain_depths(chains))
    for _ in range(rounds):
        edges, xs, w_chain, w_pos = [], [], [], []
        for ci, c in enumerate(chains):
            if c.arc is None or c.arc.closed or len(c.vertices) < 2:
                continue
            A = c.arc.points
            cum = np.concatenate([[0.0], np.cumsum(norm_rows(np.diff(A, axis=0), axis=1))])
            v = np.asarray(c.vertices, np.int64)
            sv = _polyline_param(P[v], A, cum)
            rev = sv[-1] < sv[0]
            if rev:
                v, sv = v[::-1], sv[::-1]
            k = np.searchsorted(sv, cum, side="right") - 1
            ok = (k >= 0) & (k < len(v) - 1) & (cum > sv[np.clip(k, 0, len(v) - 1)]) & \
                (cum < sv[np.clip(k + 1, 0, len(v) - 1)])
            j = np.flatnonzero(ok)
            if not len(j):
                continue
            a, b = P[v[k[j]]], P[v[k[j] + 1]]
            ab = b - a
            t = np.clip(np.einsum("ij,ij->i", A[j] - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-300), 0, 1)
            d = norm_rows(a + t[:, None] * ab - A[j], axis=1)
            o = np.lexsort((-d, k[j]))
            first = np.ones(len(o), bool)
            first[1:] = k[j][o][1:] != k[j][o][:-1]
            o = o[first]
            sel = o[d[o] > bound[ci]]
            if not len(sel):
                continue
            e = k[j][sel]                      # chain edge (in the ordered chain) to split
            edges.append(np.stack([v[e], v[e + 1]], 1))
            xs.append(A[j][sel])
            w_chain.append(np.full(len(e), ci))
            w_pos.append(len(v) - 2 - e if rev else e)
        if not edges:
            break
        E = np.sort(np.vstack(edges), axis=1)
        new_id = len(P) + np.arange(len(E))
        P = np.vstack([P, *xs])
        T, C = _split_hanging(P, T, C, E, new_id)
        fe, fid = _split_feature_edges(fe, fid, E, new_id)
        fixed += new_id.tolist()
        w_chain, w_pos = np.concatenate(w_chain), np.concatenate(w_pos)
        for ci in np.unique(w_chain):           # new vertex after position e of its chain
            m = w_chain == ci
            chains[ci].vertices = np.insert(np.asarray(chains[ci].vertices, np.int64), w_pos[m] + 1, new_id[m])
    return ShellMesh(P, T, C, list(mesh.component_names), np.unique(np.asarray(fixed, np.int64)), fe, fid)


def split_member_bridges(mesh: ShellMesh, chains, locator) -> ShellMesh:
    """Split every skin edge that joins two vertices of the same member's chains without being
    one of its chain edges (a *bridge*), at its midpoint projected onto the input surface.

    A member is meshed on its chain vertices; where two of them are also joined by a skin
    edge (a spar a fraction of an element behind a rounded leading edge: its upper and lower
    lines one skin edge apart around the nose; the upper and lower crossing of a rib with it),
    the member mesh may use the same segment, which then carries two skin faces and the
    member's own two (or a rib's too): not a junction, and not a valid shell mesh. After the
    split the two vertices are two edges apart. Feature edges lying on a split edge are split
    with it; chain vertex lists are unchanged (new vertices are appended)."""
    P, T, C = mesh.points, mesh.faces[:, :3], mesh.component
    if not len(chains) or not len(T):
        return mesh
    members = sorted({c.member for c in chains})
    col = {m: i for i, m in enumerate(members)}
    rows = np.concatenate([np.asarray(c.vertices, np.int64) for c in chains])
    cols = np.concatenate([np.full(len(c.vertices), col[c.member], np.int64) for c in chains])
    on = np.zeros((len(P), len(members)), bool)
    on[rows, cols] = True
    e = unique_edges(T.ravel(), np.roll(T, -1, axis=1).ravel())
    cand = e[on[e[:, 0]].any(1) & on[e[:, 1]].any(1)]
    if not len(cand):
        return mesh
    fe = np.sort(np.asarray(mesh.feature_edges, np.int64).reshape(-1, 2), axis=1)
    fid = np.asarray(mesh.feature_edge_ids)
    n = len(P)
    # chain edges (feature edges tagged with a member's component id) stay
    chain_keys = fe[fid >= 0, 0] * n + fe[fid >= 0, 1]
    bridge = (on[cand[:, 0]] & on[cand[:, 1]]).any(1) & ~np.isin(cand[:, 0] * n + cand[:, 1], chain_keys)
    split = cand[bridge]
    if not len(split):
        return mesh
    T, split = _flip_bridges(P, T, C, split, on, fe, locator)
    if not len(split):
        return ShellMesh(P, T, C, list(mesh.component_names), mesh.fixed_vertices, fe, fid)
    P2, T2, C2, new_id = _split_at_surface_midpoints(P, T, C, split, locator)
    fe2, fid2 = _split_feature_edges(fe, fid, split, new_id) if len(fe) else (fe, fid)
    return ShellMesh(P2, T2, C2, list(mesh.component_names), mesh.fixed_vertices, fe2, fid2)


def _flip_bridges(P, T, C, bridges, on, fe, locator, near: float = 0.25, min_angle: float = 5.0):
    """Bridges whose surface midpoint lies within ``near`` x their length of the opposite vertex
    of one of their two triangles (a chord across a rounded nose whose middle is already a
    vertex) are flipped instead of split: splitting there would put a new vertex beside that
    one and leave slivers (cessna210 stress seed 41: 0.14 and 0.67 degrees). A flip is made
    only between two triangles of one component, when the new edge is new, not a bridge
    itself, both new triangles keep their orientation and have angles of ``min_angle`` or more,
    and no other candidate flip shares a triangle with it. Returns ``(T, bridges still to split)``."""
    n = len(P)
    a, b = T, np.roll(T, -1, axis=1)
    key = (a * n + b).ravel()                                   # directed half-edges
    order = np.argsort(key, kind="stable")
    ks = key[order]

    def half(u, v):
        i = np.searchsorted(ks, u * n + v)
        i = np.minimum(i, len(ks) - 1)
        return np.where(ks[i] == u * n + v, order[i], -1)

    u, v = bridges[:, 0], bridges[:, 1]
    h0, h1 = half(u, v), half(v, u)                             # t0 runs u->v, t1 runs v->u
    ok = (h0 >= 0) & (h1 >= 0)
    if len(fe):
        ok &= ~_has_edge(_edge_keys(fe, n), u, v, n)               # a crease: never flipped
    t0, t1 = np.where(ok, h0 // 3, 0), np.where(ok, h1 // 3, 0)
    w0 = T[t0, (h0 % 3 + 2) % 3]
    w1 = T[t1, (h1 % 3 + 2) % 3]
    ok &= (C[t0] == C[t1]) & (t0 != t1) & (w0 != w1)
    mid = locator.closest(0.5 * (P[u] + P[v]))[0]
    L = norm_rows(P[v] - P[u], axis=1)
    dw = np.minimum(norm_rows(mid - P[w0], axis=1), norm_rows(mid - P[w1], axis=1))
    ok &= dw < near * L
    ok &= ~(on[w0] & on[w1]).any(1)                             # the new edge is no bridge
    ok &= ~_has_edge(_edge_keys(T, n), w0, w1, n)
    new0 = np.stack([u, w1, w0], 1)
    new1 = np.stack([v, w0, w1], 1)
    n_old = _unit_normals(P[T[t0]]) + _unit_normals(P[T[t1]])
    ok &= (np.einsum("ij,ij->i", _unit_normals(P[new0]), n_old) > 0) & \
          (np.einsum("ij,ij->i", _unit_normals(P[new1]), n_old) > 0)
    ok &= np.minimum(_tri_angles_min(P, new0), _tri_angles_min(P, new1)) >= min_angle
    # flips share no triangle: a bridge whose triangle another candidate also has is split instead
    idx = np.flatnonzero(ok)
    tris = np.concatenate([t0[idx], t1[idx]])
    alone = np.bincount(tris, minlength=len(T))[tris] == 1
    take = idx[alone[:len(idx)] & alone[len(idx):]]
    if not len(take):
        return T, bridges
    T = T.copy()
    T[t0[take]] = new0[take]
    T[t1[take]] = new1[take]
    rest = np.ones(len(bridges), bool)
    rest[take] = False
    return T, bridges[rest]


def _arc_feature_crossings(arcs, surface_points, surface_tris, skin, eps):
    """Arc points lying on a sharp edge of the input surface (a trailing edge, a tip cap
    edge) where the skin has a feature line: the chain and the feature line must share a
    vertex there. Arc points are exact points of input edges, so the test is exact."""
    if not len(skin.feature_edges) or not (skin.feature_edge_ids < 0).any():
        return []
    a, b = kept_sharp_segments(surface_points, surface_tris, skin.points,
                               skin.feature_edges[skin.feature_edge_ids < 0], eps)
    if not len(a):
        return []
    out = []
    for arc in arcs:
        pts = arc.points if arc.closed else arc.points[1:-1]
        if not len(pts):
            continue
        x = _on_segments(pts, a, b, eps)
        if len(x):
            out.append(x)
    return out


def _segment_hits(q, a, b, eps):
    """Every (point, segment) pair with point ``q[i]`` within ``eps`` of segment ``a[j]-b[j]``:
    ``(i, j, t)`` with ``t`` the parameter of the closest point along the segment, in the order
    of ``i``, then ``j``. Up to :data:`SCAN_WORK` pairs a compiled loop scans them all
    (:func:`~shellmesh_mdao.kernels.segments_within`); above, a KD-tree of the segment
    midpoints lists the candidates (the same pairs: a segment within ``eps`` has its midpoint
    within half its length plus ``eps``)."""
    q = np.atleast_2d(q)
    if len(q) * len(a) <= SCAN_WORK:
        return segments_within(q, a, b - a, eps)
    tree = cKDTree(0.5 * (a + b))
    reach = 0.5 * norm_rows(b - a, axis=1).max() + eps
    cand = tree.query_ball_point(q, reach)
    cnt = np.fromiter((len(c) for c in cand), np.int64, len(cand))
    if not cnt.sum():
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
    qi = np.repeat(np.arange(len(q)), cnt)
    si = np.concatenate([np.asarray(c, np.int64) for c in cand])
    ab = b[si] - a[si]
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", q[qi] - a[si], ab) / np.where(L2 > 0, L2, 1.0), 0, 1)
    d = norm_rows(a[si] + t[:, None] * ab - q[qi], axis=1)
    ok = d <= eps
    return qi[ok], si[ok], t[ok]


def kept_sharp_segments(surface_points: np.ndarray, surface_tris: np.ndarray, skin_points: np.ndarray,
                        crease_edges: np.ndarray, eps: float):
    """The pieces of the input surface's sharp edges that the skin's feature lines follow.

    Remeshing keeps a sharp line of the input as a chain of skin edges (``crease_edges``,
    their vertices exactly on the input's sharp edges) except where it drops it: the weaker of
    two creases closer than twice the chordal tolerance (a coarsely faceted leading edge's
    narrow nose strip, a wedge at a sharp trailing-edge tip) and the outlines of thin patches.
    The input's sharp edges are cut at every skin crease vertex lying on them; a stretch
    between such cuts is kept when a skin crease edge joins two skin vertices bounding that
    same stretch. Returns ``(a, b)``: the kept pieces as segments (k, 3) each. Vectorised;
    exact (no distance tolerance beyond ``eps`` for "vertex on an input edge")."""
    empty = (np.zeros((0, 3)), np.zeros((0, 3)))
    lines = ShellMesh(surface_points, surface_tris).sharp_edges()
    crease_edges = np.asarray(crease_edges, np.int64).reshape(-1, 2)
    if not len(lines) or not len(crease_edges):
        return empty
    a, b = surface_points[lines[:, 0]], surface_points[lines[:, 1]]
    sv = np.unique(crease_edges)
    qi, si, t = _segment_hits(skin_points[sv], a, b, eps)
    if not len(qi):
        return empty
    nv, ns, nq = len(surface_points), len(lines), len(qi)
    # each input sharp edge as its start, the skin vertices on it (by t), its end
    e_all = np.concatenate([np.arange(ns), si, np.arange(ns)])
    t_all = np.concatenate([np.full(ns, -1.0), t, np.full(ns, 2.0)])
    node = np.concatenate([lines[:, 0], nv + np.arange(nq), lines[:, 1]])
    o = np.lexsort((node, t_all, e_all))
    e_s, t_s, n_s = e_all[o], np.clip(t_all[o], 0.0, 1.0), node[o]
    same = np.flatnonzero(e_s[1:] == e_s[:-1])
    sa, sb, se = n_s[same], n_s[same + 1], e_s[same]
    ta, tb = t_s[same], t_s[same + 1]
    m = len(same)
    # stretches: pieces connected through input vertices (skin vertices cut the lines)
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components
    rows, cols = [], []
    for end in (sa, sb):
        real = end < nv
        rows.append(np.flatnonzero(real))
        cols.append(m + end[real])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    g = sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(m + nv, m + nv))
    _, lab = connected_components(g, directed=False)
    lab = lab[:m]
    # (stretch, skin vertex) pairs bounding each stretch
    bl, bv = [], []
    for end in (sa, sb):
        virt = end >= nv
        bl.append(lab[virt])
        bv.append(sv[qi[end[virt] - nv]])
    bl, bv = np.concatenate(bl), np.concatenate(bv)
    nsk = int(max(len(skin_points), crease_edges.max() + 1))
    pair = np.unique(bl.astype(np.int64) * nsk + bv)
    pl, pv = pair // nsk, pair % nsk
    # a stretch is kept when some skin crease edge (u, v) has both ends among its bounds
    ov = np.argsort(pv, kind="stable")
    pl_s, pv_s = pl[ov], pv[ov]
    u, v = crease_edges[:, 0], crease_edges[:, 1]
    lo, hi = np.searchsorted(pv_s, u, "left"), np.searchsorted(pv_s, u, "right")
    idx = _ranges(lo, hi)
    ce = np.repeat(np.arange(len(u)), hi - lo)
    cl = pl_s[idx]
    ok = np.isin(cl * nsk + v[ce], pair)
    kept = np.zeros(int(lab.max()) + 1 if m else 0, bool)
    kept[cl[ok]] = True
    keep = kept[lab] & (tb > ta)
    ab = b - a
    return a[se[keep]] + ta[keep, None] * ab[se[keep]], a[se[keep]] + tb[keep, None] * ab[se[keep]]


def _on_segments(q, a, b, eps):
    """Points of q within eps of any segment a-b."""
    qi, _, _ = _segment_hits(q, a, b, eps)
    return q[np.unique(qi)] if len(qi) else np.zeros((0, 3))


def _arc_crossings(chains, arcs, eps):
    """Points where arc i crosses the plane of chain j and lies on arc j (within eps). A pair
    whose arc i lies, bounding box and all, farther than ``2 eps`` on one side of plane j is
    skipped unread: none of its points is within ``eps`` of the plane nor on its other side
    (the rounding of the plane distances is some 1e-16 of the model, eps 1e-9 of it)."""
    out = []
    if not chains:
        return out
    pc = np.array([np.asarray(c.plane.point, float) for c in chains])
    pn = np.array([np.asarray(c.plane.normal, float) for c in chains])
    for i, (ci, ai) in enumerate(zip(chains, arcs)):
        p = np.vstack([ai.points, ai.points[:1]]) if ai.closed else ai.points
        lo, hi = (p.min(0) - pc) * pn, (p.max(0) - pc) * pn
        apart = (np.minimum(lo, hi).sum(1) > 2 * eps) | (np.maximum(lo, hi).sum(1) < -2 * eps)
        for j in np.flatnonzero(~apart).tolist():
            cj, aj = chains[j], arcs[j]
            if i == j or cj.member == ci.member:
                continue
            s = cj.plane.side(p)
            k = np.flatnonzero((s[:-1] > eps) & (s[1:] < -eps) | (s[:-1] < -eps) & (s[1:] > eps)
                               | (np.abs(s[:-1]) <= eps))
            if not len(k):
                continue
            t = np.where(np.abs(s[k]) <= eps, 0.0, s[k] / (s[k] - s[k + 1]))
            x = p[k] + t[:, None] * (p[k + 1] - p[k])
            on = norm_rows(closest_on_polyline(x, aj.points, aj.closed) - x, axis=1) <= eps
            if on.any():
                out.append(x[on])
    return out


def _split_feature_edges(fe, fid, split_edges, new_nodes):
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


def chain_specs(layout, projected) -> list:
    """The curves to imprint for every member of a resolved layout.

    ``layout``: a :class:`~shellmesh_mdao.layout.Layout`; ``projected``: the result of
    :func:`~shellmesh_mdao.project.project_layout` (seed points hit on the skin by rays cast
    from inside the wing). A rib or spar gives an upper and a lower chain between its
    bounding planes; a full-chord rib (fewer than two spars) one closed loop. Explicit
    members give one chain per side, each the union of the sections of the planes spanned by
    a polyline segment and its projection direction (one :class:`ChainSpec` per segment,
    sides ``upper_<s>``/``lower_<s>``). Raises :class:`~shellmesh_mdao.errors.LayoutError` when
    an explicit member lies in the plane of another member and their areas overlap.
    """
    _check_coplanar_overlaps(layout.members(), projected)
    specs = []
    for m in layout.members():
        pm = projected[m.name]
        if m.kind == "explicit":
            specs += _explicit_chain_specs(m, pm)
            continue
        plane = Plane.make(m.plane_point, m.plane_normal)
        bounds = tuple(Plane.make(p, n) for p, n in m.bound_planes)
        mid = len(pm.seeds) // 2
        if m.kind == "rib" and not bounds:
            specs.append(ChainSpec(m.name, "loop", plane, (), pm.upper[mid], int(pm.upper_tri[mid])))
            continue
        specs.append(ChainSpec(m.name, "upper", plane, bounds, pm.upper[mid], int(pm.upper_tri[mid])))
        specs.append(ChainSpec(m.name, "lower", plane, bounds, pm.lower[mid], int(pm.lower_tri[mid])))
    return specs


def _check_coplanar_overlaps(members, projected, tol: float = 1e-9) -> None:
    """Two members in one plane whose areas overlap (at least one of them explicit) are a
    :class:`~shellmesh_mdao.errors.LayoutError` naming both, raised before the imprint would
    cut the same skin curve twice. A member's area is taken as the polygon of its projected
    upper points followed by its projected lower points (reversed); explicit members count
    when their layout is planar (:func:`~shellmesh_mdao.members.explicit_plane`)."""
    from .errors import LayoutError
    from .members import _frame_from_normal, _interior_samples, _point_in_polygon, _to2d, explicit_plane

    polys = []
    for m in members:                                     # loop over members
        pm = projected[m.name]
        if m.kind == "explicit":
            pp, pn = explicit_plane(m)
        else:
            pp, pn = m.plane_point, m.plane_normal
        if pn is None:
            continue
        up, lo = np.asarray(pm.upper, float), np.asarray(pm.lower, float)
        if np.linalg.norm(up[0] - lo[-1]) + np.linalg.norm(up[-1] - lo[0]) < \
                np.linalg.norm(up[0] - lo[0]) + np.linalg.norm(up[-1] - lo[-1]):
            lo = lo[::-1]
        polys.append((m, np.asarray(pp, float), np.asarray(pn, float), np.vstack([up, lo[::-1]])))
    for i in range(len(polys)):                           # loop over member pairs (a few dozen members)
        mi, pi, ni, qi = polys[i]
        for j in range(i + 1, len(polys)):
            mj, pj, nj, qj = polys[j]
            if mi.kind != "explicit" and mj.kind != "explicit":
                continue
            scale = float(norm_rows(np.ptp(np.vstack([qi, qj]), axis=0)))
            if np.linalg.norm(np.cross(ni, nj)) > tol or abs((pj - pi) @ ni) > tol * scale:
                continue
            e1, e2, o = _frame_from_normal(ni, pi)
            a2, b2 = _to2d(qi, e1, e2, o), _to2d(qj, e1, e2, o)
            eps = 1e-6 * scale
            sa = np.vstack([a2, 0.5 * (a2 + np.roll(a2, -1, 0)), _interior_samples(a2)])
            sb = np.vstack([b2, 0.5 * (b2 + np.roll(b2, -1, 0)), _interior_samples(b2)])
            if _point_in_polygon(sb, a2, eps).any() or _point_in_polygon(sa, b2, eps).any():
                raise LayoutError(f"members '{mi.name}' and '{mj.name}' lie in the same plane and overlap; remove "
                                  "one of them or move it so their areas do not overlap")


def _explicit_chain_specs(m, pm) -> list:
    """Explicit member: for each side, one chain piece per polyline segment: the plane through
    the segment's two projected points containing the projection direction (or, without a
    direction, the mean of the two points' projection offsets ``hit - seed``; a point that
    already lies on the skin uses the normal of the triangle it lies on), bounded by the
    planes through the segment ends normal to the segment."""
    out = []
    for side, seeds, hits, normals, direction in (
            ("upper", pm.seeds, pm.upper, pm.upper_normal, m.direction),
            ("lower", pm.lower_seeds if pm.lower_seeds is not None else pm.seeds, pm.lower, pm.lower_normal,
             m.lower_direction)):
        for s in range(len(hits) - 1):
            a, b = hits[s], hits[s + 1]
            ab = b - a
            if np.linalg.norm(ab) == 0:
                raise ImprintError(f"{m.name}: points {s} and {s + 1} of its {side} curve project onto the same "
                                   "skin point; space the points further apart")
            if direction is not None:
                dvec = np.asarray(direction, float)
            else:
                dvec = _closest_point_direction(m.name, side, s, seeds, hits, normals, float(np.linalg.norm(ab)))
            nrm = np.cross(ab, dvec)
            if np.linalg.norm(nrm) <= 1e-12 * np.linalg.norm(ab) * max(np.linalg.norm(dvec), 1e-300):
                raise ImprintError(f"{m.name}: segment {s} of its {side} curve is parallel to its projection "
                                   "direction; choose a direction across the curve")
            bounds = (Plane.make(a, ab), Plane.make(b, -ab))
            seed = 0.5 * (a + b)
            out.append(ChainSpec(m.name, f"{side}_{s}", Plane.make(a, nrm), bounds, seed, -1))
    return out


def _closest_point_direction(name, side, s, seeds, hits, normals, length) -> np.ndarray:
    """Projection direction of segment ``s`` of a polyline projected to the closest skin points:
    the mean of the unit offsets ``hit - seed`` of its two ends; an end that lies on the skin
    (offset below 1e-9 of the segment length) takes the normal of its skin triangle instead,
    turned to agree with the other end."""
    dirs = []
    for k in (s, s + 1):
        off = np.asarray(hits[k], float) - np.asarray(seeds[k], float)
        ln = float(np.linalg.norm(off))
        dirs.append(off / ln if ln > 1e-9 * length else None)
    for i in (0, 1):
        if dirs[i] is None and normals is not None and np.linalg.norm(normals[s + i]) > 0:
            nv = np.asarray(normals[s + i], float)
            ref = dirs[1 - i]
            dirs[i] = -nv if ref is not None and nv @ ref < 0 else nv
    if dirs[0] is None and dirs[1] is None:
        raise ImprintError(f"{name}: the ends of segment {s} of its {side} polyline lie on the skin and no "
                           "'direction' is given; give a projection direction")
    if dirs[0] is None or dirs[1] is None:
        return dirs[0] if dirs[1] is None else dirs[1]
    if dirs[0] @ dirs[1] < 0:                      # the ends lie on opposite sides of the skin
        dirs[1] = -dirs[1]
    return dirs[0] + dirs[1]


def skin_families(mesh: ShellMesh, layout) -> ShellMesh:
    """Name the skin patches the member chains cut out: ``<wing>/upper_skin/bay_<k>`` and
    ``<wing>/lower_skin/bay_<k>`` (bay k between rib k and rib k+1, between the first and
    last spar; with fewer than two spars over the whole chord), everything else ``skin``.

    A patch is a set of faces connected across edges that are not member chains. It is a bay
    when at least 99% of its face centroids lie inside the bay's box (between the two rib
    planes and, with two or more spars, the first and last spar planes); its faces are then
    split into upper and lower by their side (along ``up``) of the bay's mid-chord point.
    """
    topo = mesh.topology()
    chain_e = mesh.feature_edges[mesh.feature_edge_ids >= 0]
    is_chain = np.zeros(len(topo.edges), bool)
    if len(chain_e):
        ids = topo.edge_ids(chain_e)
        is_chain[ids[ids >= 0]] = True
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    man = np.flatnonzero((topo.valence == 2) & ~is_chain)
    f0 = topo.edge_faces[topo.edge_faces_ptr[man]]
    f1 = topo.edge_faces[topo.edge_faces_ptr[man] + 1]
    g = sparse.coo_matrix((np.ones(len(man)), (f0, f1)), shape=(mesh.n_faces, mesh.n_faces))
    _, patch = connected_components(g, directed=False)
    cen = mesh.face_centroids()
    names = list(mesh.component_names)
    comp = mesh.component.copy()
    members = {m.name: m for m in layout.members()}
    for w in layout.wings:
        up = layout.wing_up(w)
        ribs = [members[f"{w.name}/rib_{k}"] for k in range(len(w.rib_eta))]
        spars = [members[f"{w.name}/spar_{j}"] for j in range(len(w.spar_chord))]
        cmid = 0.5 * (w.spar_chord[0] + w.spar_chord[-1]) if len(spars) >= 2 else 0.5
        for k in range(len(ribs) - 1):
            # the bay's own mid-chord point: follows dihedral and twist along the span
            chord_pt = 0.5 * (w.chord_point(w.rib_eta[k], cmid) + w.chord_point(w.rib_eta[k + 1], cmid))
            inside = (cen - ribs[k].plane_point) @ ribs[k].plane_normal >= 0
            inside &= (cen - ribs[k + 1].plane_point) @ ribs[k + 1].plane_normal <= 0
            if len(spars) >= 2:
                inside &= (cen - spars[0].plane_point) @ spars[0].plane_normal >= 0
                inside &= (cen - spars[-1].plane_point) @ spars[-1].plane_normal <= 0
            frac = np.bincount(patch, weights=inside.astype(float)) / np.bincount(patch)
            box = frac[patch] >= 0.99
            upper = (cen - chord_pt) @ up >= 0
            for side, mask in (("upper", box & upper), ("lower", box & ~upper)):
                if mask.any():
                    comp[mask] = len(names)
                    names.append(f"{w.name}/{side}_skin/bay_{k}")
    return ShellMesh(mesh.points, mesh.faces, comp, names, mesh.fixed_vertices, mesh.feature_edges,
                     mesh.feature_edge_ids)


def _flip_round(P, T, locked_edges, max_dihedral=35.0, min_gain=1.0, active=None):
    """One round of angle-improving edge flips on an independent set of edges.

    An interior edge shared by exactly two triangles, not locked (chain/feature), is flipped
    when the new pair's minimum angle beats the old by ``min_gain`` degrees, the two
    triangles are nearly coplanar (dihedral below ``max_dihedral``), both new triangles keep
    the old orientation and the new edge does not exist yet. Returns ``(T, n_flipped)``."""
    n = len(P)
    # in one compiled pass over the edge table (kernels.skin_flips): two consistently oriented
    # triangles on a free edge, both ends active, nearly coplanar (dihedral below
    # max_dihedral), the new edge not there yet; whether both new triangles keep the pair's
    # orientation and stay within max_dihedral of its mean normal (a thin new triangle spanning
    # a bend, three close vertices of one chain around a rounded leading edge, would lie in the
    # member plane, across the skin); the angles' cosines of the old and new triangles
    _, h0, h1, cnt, E, _ = edge_table(T, n)
    kptr = edge_rows(E, n)
    locked = np.zeros(len(E), bool)
    if len(locked_edges):
        lk = np.asarray(locked_edges).reshape(-1, 2)
        e = edge_lookup(E, kptr, lk[:, 0], lk[:, 1])
        locked[e[e >= 0]] = True
    cmax = np.cos(np.radians(max_dihedral))
    pqrs, ff, orient, cos = skin_flips(E, kptr, h0, h1, cnt, locked, T, P, cmax, active)
    p, q, r, s = pqrs.T
    f0, f1 = ff.T
    new_key = np.minimum(r, s) * n + np.maximum(r, s)
    # (p, q, r) and (q, p, s) are the triangles f0 and f1 themselves, rotated: the same angles
    old_min = np.minimum(_min_angle_from_cos(cos[0]), _min_angle_from_cos(cos[1]))
    t0 = np.stack([r, s, q], 1)
    t1 = np.stack([s, r, p], 1)
    new_min = np.minimum(_min_angle_from_cos(cos[2]), _min_angle_from_cos(cos[3]))
    good = (new_min > old_min + min_gain) & orient
    cand = np.flatnonzero(good)
    if not len(cand):
        return T, 0
    # independent set: best gain first, each triangle used once
    cand = cand[np.argsort(-(new_min - old_min)[cand], kind="stable")]
    used = np.zeros(len(T), bool)
    take = []
    # greedy over candidates sorted by gain; vectorised in passes
    while len(cand):
        fa, fb = f0[cand], f1[cand]
        free = ~used[fa] & ~used[fb]
        cand = cand[free]
        if not len(cand):
            break
        fa, fb = f0[cand], f1[cand]
        # first occurrence of each triangle among the remaining, in gain order
        tri_all = np.concatenate([fa, fb])
        pos = np.concatenate([np.arange(len(cand)), np.arange(len(cand))])
        firstpos = np.full(len(T), len(cand))
        np.minimum.at(firstpos, tri_all, pos)
        win = (firstpos[fa] == np.arange(len(cand))) & (firstpos[fb] == np.arange(len(cand)))
        take.append(cand[win])
        used[fa[win]] = True
        used[fb[win]] = True
        cand = cand[~win]
    take = np.concatenate(take) if take else np.zeros(0, np.int64)
    # new keys must be unique among the flips taken
    nk = new_key[take]
    _, first = np.unique(nk, return_index=True)
    take = take[np.sort(first)]
    T = T.copy()
    T[f0[take]] = t0[take]
    T[f1[take]] = t1[take]
    return T, len(take)


def _smooth_round(P, T, movable, locator, chain_of=None, arcs=None, step=0.5, chain_nb=None, hint=None):
    """Move each movable vertex towards the area-weighted centroid of its star (tangential,
    then onto the input surface); chain vertices (``chain_of[v] >= 0``) move the same way,
    projected onto their exact arc. A move is kept only if it raises the smallest angle of
    the vertex's star and flips no triangle, and (``chain_nb``: each vertex's previous and
    next vertex along its chain, -1 for none) keeps the vertex between its chain neighbours
    along the arc: where the skin is thinner than its faces the closest arc point can be on
    the far side of the section, and the chain would run back and forth there (a spike).
    Moves are applied on an independent set (no two moved vertices share a triangle).
    ``hint`` (n,): an input triangle near each vertex (-1: none) for the projections, updated in
    place with the triangles they found (a hint saves a part of the search; the answers are
    the same)."""
    n = len(P)
    ptr, star = vertex_faces(T, n)
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    cen = (a + b + c) / 3
    nrm = cross_rows(b - a, c - a)
    area = 0.5 * norm_rows(nrm, axis=1)
    cand = np.flatnonzero(movable & (np.diff(ptr) > 0))
    if not len(cand):
        return P, 0
    rows = np.repeat(cand, np.diff(ptr)[cand])
    tris = star[_ranges(ptr[cand], ptr[cand + 1])]
    w = area[tris]
    tgt = np.zeros((n, 3))
    wsum = np.bincount(rows, weights=w, minlength=n)
    for d in range(3):
        tgt[:, d] = np.bincount(rows, weights=w * cen[tris, d], minlength=n)
    tgt[cand] /= np.maximum(wsum[cand], 1e-300)[:, None]
    vn = np.zeros((n, 3))
    for d in range(3):
        vn[:, d] = np.bincount(rows, weights=nrm[tris, d], minlength=n)
    vn /= np.maximum(norm_rows(vn, axis=1, keepdims=True), 1e-300)
    new = P.copy()
    mv = tgt[cand] - P[cand]
    mv -= np.einsum("ij,ij->i", mv, vn[cand])[:, None] * vn[cand]
    new[cand] = P[cand] + step * mv
    surf = cand if chain_of is None else cand[chain_of[cand] < 0]
    if len(surf):
        new[surf], tri, _ = locator.closest(new[surf], hint=None if hint is None else hint[surf])
        if hint is not None:
            hint[surf] = tri
    if chain_of is not None:
        vv = cand[chain_of[cand] >= 0]
        if len(vv):
            new[vv] = _closest_on_arcs(new[vv], chain_of[vv], arcs)
    # evaluate each vertex's star with only that vertex moved (kernels.star_moves: the corner
    # cosines with and without the move, and whether the moved triangle turns over)
    cos_new, cos_old, flip = star_moves(rows, tris, T, P, new, nrm)
    ang_new = _min_angle_from_cos(cos_new)
    ang_old = _min_angle_from_cos(cos_old)
    # each candidate's star is one run of ``rows`` (every candidate has a face)
    starts = np.concatenate([[0], np.cumsum(np.diff(ptr)[cand])[:-1]])
    worst_new = np.full(n, np.inf)
    worst_old = np.full(n, np.inf)
    worst_new[cand] = np.minimum.reduceat(np.where(flip, -1.0, ang_new), starts)
    worst_old[cand] = np.minimum.reduceat(ang_old, starts)
    ok = cand[worst_new[cand] > worst_old[cand] + 1e-9]
    if chain_nb is not None and chain_of is not None and len(ok):
        ok = ok[_in_order_on_arc(ok, new, P, chain_of, chain_nb, arcs)]
    if not len(ok):
        return P, 0
    # independent set: vertices sharing a triangle cannot both move (the larger gain wins, the
    # lower index on a tie)
    gain = worst_new - worst_old
    # (best gain first, in 8 rounds: kernels.star_independent)
    order = ok[np.argsort(-gain[ok], kind="stable")]
    take = star_independent(order, ptr, star, len(T), 8)
    P = P.copy()
    P[take] = new[take]
    return P, len(take)


def _in_order_on_arc(v, new, P, chain_of, chain_nb, arcs) -> np.ndarray:
    """(len(v),) bool: False for a chain vertex of ``v`` whose position ``new`` (on its arc) is not
    between its chain neighbours' (``chain_nb``: previous and next along the chain, -1 for
    none) along the arc; True for every other vertex. The arc positions come from one query
    (each point answered on its own)."""
    keep = np.ones(len(v), bool)
    pv, nx = chain_nb[0][v], chain_nb[1][v]
    has = np.flatnonzero((chain_of[v] >= 0) & (pv >= 0) & (nx >= 0))
    if not len(has):
        return keep
    c = chain_of[v[has]]
    _, sp = _closest_on_arcs(np.vstack([new[v[has]], P[pv[has]], P[nx[has]]]), np.tile(c, 3), arcs, params=True)
    sv, sa, sb = sp.reshape(3, -1)
    d1, d2 = sv - sa, sb - sv
    closed = np.array([a.closed for a in arcs], bool)[c]
    if closed.any():
        Ltot = np.array([a.length if a.closed else 1.0 for a in arcs])[c]
        d1 = np.where(closed, d1 - Ltot * np.round(d1 / Ltot), d1)
        d2 = np.where(closed, d2 - Ltot * np.round(d2 / Ltot), d2)
    keep[has] = d1 * d2 > 0
    return keep


def _chain_neighbours(n, chain_vs, arcs):
    """(previous, next) vertex of every vertex along its chain (-1 for none; closed arcs wrap)."""
    prev = np.full(n, -1, np.int64)
    nxt = np.full(n, -1, np.int64)
    for vs, arc in zip(chain_vs, arcs):
        if len(vs) < 2:
            continue
        prev[vs[1:]] = vs[:-1]
        nxt[vs[:-1]] = vs[1:]
        if arc.closed and len(vs) >= 3:
            prev[vs[0]] = vs[-1]
            nxt[vs[-1]] = vs[0]
    return prev, nxt


def _ranges(starts, stops):
    """Concatenated aranges [starts[i], stops[i]) (vectorised)."""
    lens = stops - starts
    if not len(lens) or lens.sum() == 0:
        return np.zeros(0, np.int64)
    idx = np.arange(lens.sum())
    off = np.repeat(starts - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens)
    return idx + off


def _angles3(Pn):
    """Smallest interior angle (degrees) of triangles given by corner coordinates (t, 3, 3)."""
    # the cosines from a compiled loop (einsum's dot over max(|u| |v|, 1e-300)), the angles
    # from numpy's arccos
    return _min_angle_from_cos(corner_cosines(Pn))


def _min_angle_from_cos(c):
    """Smallest angle (degrees) of triangles from their (t, 3) corner cosines (numpy's arccos)."""
    ang = np.degrees(np.arccos(np.clip(c, -1, 1)))
    return np.minimum(np.minimum(ang[:, 0], ang[:, 1]), ang[:, 2])


def improve_skin(mesh: ShellMesh, locator, chains=(), rounds: int = 12, min_gain: float = 0.5,
                 min_angle: float = 10.0, passes: int = 8, max_repairs: int | None = None,
                 rings: int | None = 3, poor_angle: float = 30.0) -> ShellMesh:
    """Raise the smallest angles of the imprinted triangle skin to at least ``min_angle``
    degrees where possible.

    1. Vectorised rounds: angle-improving flips of edges that are not chains or feature
       lines, tangential smoothing of free vertices (projected back onto the input surface)
       and sliding of chain vertices along their exact arc (crossings and chain ends stay),
       only where the cut changed the skin or the skin is poor: within ``rings`` edge rings of
       a chain vertex and one ring of a triangle with an angle below ``poor_angle`` degrees
       (``rings`` None, or no chains: over the whole skin).
    2. Local repair of the few triangles still below ``min_angle + 0.5`` (chain vertices
       packed closer than the element size, a chain ending or crossing a crease a fraction of
       an element from the crease's next vertex, oblique members crossing): per bad triangle
       the best of edge collapse (a free vertex into a neighbour; a chain or crease vertex
       along its line; a chain collapse never makes a chain edge longer than 1.3 x the chain's
       longest edge when the repair started, nor than 1.5 x the longer of the two edges it
       joins, so repeated repairs cannot open a gap in a chain), edge split (on the input
       surface, on the exact arc, on the input's sharp edge) and vertex relocation (on the
       surface, along the arc -- within the same spacing bound -- along the sharp edge), each
       followed by local flips, is kept
       when it improves the angles around it. Crossings, chain ends, chain/crease crossings
       and corners never move; every feature line is kept. At most ``max_repairs`` triangles
       are attempted, worst first (default ``32 + n_faces // 4000``): the repair is for the
       few spots imprinting leaves on a remeshed skin, not for remeshing a raw triangulation
       (``remesh=False``).

    Every vertex stays on the input surface, chain vertices on their arc (so on their member
    plane), crease vertices on the input's sharp edges; no face is turned over. When vertices
    are removed or inserted the skin is renumbered and each chain's ``vertices`` (a
    :class:`ChainResult` of ``chains``) is updated in place to the returned mesh.
    """
    P = mesh.points.copy()
    T = mesh.faces[:, :3].copy()
    fe, fid = mesh.feature_edges, mesh.feature_edge_ids
    fixed = np.zeros(len(P), bool)
    fixed[mesh.fixed_vertices] = True
    arcs = [c.arc for c in chains]
    chain_vs = [np.asarray(c.vertices, np.int64) for c in chains]
    kind, chain_of = _skin_roles(len(P), fe, fid, fixed, chain_vs, arcs)
    movable = (kind == _FREE) | (kind == _CHAIN)
    active = None
    if rings is not None and chain_vs:
        # only where the cut changed the skin or the skin is poor: the rest is the remesh's, which
        # the imprint did not touch (rounds over the whole skin cost 0.3 s more on cessna210 for
        # the same figures, docs/benchmarks.md)
        from .core.topology import face_rings

        ptr, vf = vertex_faces(T, len(P))
        active = np.zeros(len(P), bool)
        for seed, r in ((np.unique(np.concatenate(chain_vs)), int(rings)),
                        (np.unique(T[_tri_angles_min(P, T) < poor_angle]), 1)):
            active[seed] = True
            if r > 0:
                active[T[face_rings(T, ptr, vf, seed, r)]] = True
        movable &= active
    chain_nb = _chain_neighbours(len(P), chain_vs, arcs)
    hint = np.full(len(P), -1, np.int64)            # each vertex's input triangle, once projected
    with np.errstate(invalid="ignore"):
        for _ in range(rounds):
            T, nf = _flip_round(P, T, fe, min_gain=min_gain, active=active)
            P, nm = _smooth_round(P, T, movable, locator, chain_of, arcs, chain_nb=chain_nb, hint=hint)
            if nf == 0 and nm == 0:
                break
    C = mesh.component
    target = min_angle + 0.5
    if len(T) and _tri_angles_min(P, T).min() < target:
        names = list(mesh.component_names)
        member = np.array([names.index(c.member) if c.member in names else -2 for c in chains], np.int64)
        W = _SkinPatch(P, T, C, fe, fid, kind, chain_of, chain_vs, arcs, member, locator)
        budget = 32 + len(T) // 4000 if max_repairs is None else int(max_repairs)
        for _ in range(passes):               # loops over the few bad triangles only
            n_fixed = 0
            for f in W.bad_faces(target).tolist():
                if budget <= 0:
                    break
                if W.alive[f] and _min_angles_small(W.P[W.T[f:f + 1]])[0] < target:
                    budget -= 1
                    n_fixed += W.repair_face(f, cap=2.0 * target)
            if not n_fixed or budget <= 0:
                break
        P, T, C, fe, fid, chain_vs, remap = W.export()
        old_fixed = remap[np.flatnonzero(fixed)]
        fixed = np.zeros(len(P), bool)
        fixed[old_fixed[old_fixed >= 0]] = True
        for c, v in zip(chains, chain_vs):
            fixed[v] = True
            c.vertices = v
    return ShellMesh(P, T, C, mesh.component_names, np.flatnonzero(fixed), fe, fid)


# ----------------------------------------------------------------------------- chain coarsening
# Cutting the skin along a member's plane puts a chain vertex wherever the plane crosses a skin
# edge, so chains come out 2-3 times finer than the skin (and the members meshed on them with
# them). coarsen_chains removes interior chain vertices by collapsing each into a chain
# neighbour (the survivor keeps its exact position), in vectorised rounds over an independent
# set of candidates, each collapse checked locally (link condition, orientation, angles).
_COS_TURN = np.cos(np.radians(45.0))


def _edge_keys(T, n):
    """Sorted unique keys ``min * n + max`` of the edges of triangles T (or of edges T, (k, 2))."""
    a, b = T.ravel(), np.roll(T, -1, axis=1).ravel()
    return np.unique(np.minimum(a, b) * n + np.maximum(a, b))


def _has_edge(ekeys, a, b, n):
    k = np.minimum(a, b) * n + np.maximum(a, b)
    i = np.minimum(np.searchsorted(ekeys, k), max(len(ekeys) - 1, 0))
    return (ekeys[i] == k) if len(ekeys) else np.zeros(len(k), bool)


def _collapse_checks(P, T, C, ptr, star, ekeys, v, u):
    """Validity of collapsing each vertex v into its neighbour u (u keeps its position), and
    the star's smallest angle before and after: ``(ok, old_min, new_min)``. ok requires a
    closed manifold star around v of one component, edge v-u shared by exactly two faces,
    the link condition (v and u have exactly the two common neighbours opposite v-u), and no
    remaining face degenerate or turned more than 45 degrees."""
    n, k = len(P), len(v)
    cnt = ptr[v + 1] - ptr[v]
    rows = np.repeat(np.arange(k), cnt)
    fs = star[_ranges(ptr[v], ptr[v + 1])]
    tri = T[fs]
    is_v = tri == v[rows, None]
    has_u = (tri == u[rows, None]).any(1)
    ok = (np.bincount(rows, weights=has_u, minlength=k) == 2) & (cnt >= 3)
    iv = np.argmax(is_v, axis=1)
    ar = np.arange(len(rows))
    nxt, prv = tri[ar, (iv + 1) % 3], tri[ar, (iv + 2) % 3]
    kn, kp = np.sort(rows * n + nxt), np.sort(rows * n + prv)
    ok &= np.bincount(kn // n, weights=kn != kp, minlength=k) == 0        # closed fan
    dup = np.zeros(len(kn), bool)
    dup[1:] = kn[1:] == kn[:-1]
    ok &= np.bincount(kn // n, weights=dup, minlength=k) == 0             # each neighbour once
    link = _has_edge(ekeys, u[rows], nxt, n) & (nxt != u[rows])
    ok &= np.bincount(rows, weights=link, minlength=k) == 2
    cmin = np.full(k, np.iinfo(np.int64).max)
    cmax = np.full(k, np.iinfo(np.int64).min)
    np.minimum.at(cmin, rows, C[fs].astype(np.int64))
    np.maximum.at(cmax, rows, C[fs].astype(np.int64))
    ok &= cmin == cmax
    X = P[tri]
    old_min = np.full(k, np.inf)
    np.minimum.at(old_min, rows, _min_angles_small(X))
    new = np.where(is_v, u[rows, None], tri)
    Xn = P[new]
    ang = np.where(has_u, np.inf, _min_angles_small(Xn))
    turn = (np.einsum("ij,ij->i", _unit_normals(Xn), _unit_normals(X)) <= _COS_TURN) & ~has_u
    new_min = np.full(k, np.inf)
    np.minimum.at(new_min, rows, ang)
    ok &= np.bincount(rows, weights=turn, minlength=k) == 0
    return ok, old_min, new_min


def _independent(ptr, star, v, u, m):
    """Indices (sorted, into the priority-ordered candidates v -> u) of a greedy independent
    set: no two chosen candidates touch a common face of the stars of v and u; earlier
    candidates first (:func:`kernels.greedy_independent`, at most 16 sub-rounds)."""
    k = len(v)
    if not k:
        return np.zeros(0, np.int64)
    fa = star[_ranges(ptr[v], ptr[v + 1])]
    fb = star[_ranges(ptr[u], ptr[u + 1])]
    pa = np.repeat(np.arange(k), ptr[v + 1] - ptr[v])
    pb = np.repeat(np.arange(k), ptr[u + 1] - ptr[u])
    sel = greedy_independent(np.concatenate([pa, pb]), np.concatenate([fa, fb]), np.arange(k, 0, -1), m,
                             max_sub=16)
    return np.flatnonzero(sel)


def _apply_collapses(P, T, C, fe, fid, fixed, chain_vs, v, u):
    """Merge each vertex v into u (independent collapses) and renumber everything."""
    n = len(P)
    to = np.arange(n)
    to[v] = u
    T2 = to[T]
    good = (T2[:, 0] != T2[:, 1]) & (T2[:, 1] != T2[:, 2]) & (T2[:, 2] != T2[:, 0])
    T2, C2 = T2[good], C[good]
    fe2 = to[fe]
    g = fe2[:, 0] != fe2[:, 1]
    fe2, fid2 = np.sort(fe2[g], axis=1), fid[g]
    alive = np.ones(n, bool)
    alive[v] = False
    remap = np.cumsum(alive) - 1
    remap[~alive] = -1
    chain_vs = [remap[c[alive[c]]] for c in chain_vs]
    return P[alive], remap[T2], C2, remap[fe2], fid2, fixed[alive], chain_vs


def coarsen_chains(mesh: ShellMesh, locator, chains, target: float, max_ratio: float = 1.3,
                   min_angle: float = 10.0, near: float = 0.35, rounds: int = 40,
                   max_deviation: float | None = None, keep=None, improve: bool = True) -> ShellMesh:
    """Coarsen the imprinted chains towards the spacing ``target`` (the skin edge length).

    Interior chain vertices (not crossings, chain ends, vertices shared with a crease, nor
    ``keep``) are removed by collapsing each into a chain neighbour, shortest resulting chain
    edge first, while the merged edge stays at most ``max_ratio * target`` and within
    ``max_deviation`` (default ``0.003 * target``) of the imprinted chain points it replaces
    (curved stretches keep a finer spacing, so a member's area, bounded by the chain chords,
    stays within a fraction of a percent of the exact section's); then free skin
    vertices closer than ``near * target`` to a chain vertex are collapsed into it where that
    raises their star's smallest angle. Work is done in vectorised rounds over an independent
    set of candidates (no two sharing a face), each collapse accepted only if the link
    condition holds (manifold result), no face degenerates or turns more than 45 degrees, no
    new angle falls below the smaller of the star's current minimum and ``min_angle``, and
    the chain stays a simple path of mesh edges; angle-improving flips run between rounds.
    Surviving chain vertices keep their exact positions (on the input surface and the member
    plane). With ``improve`` :func:`improve_skin` runs again afterwards (flips, smoothing,
    repairs). Each chain's ``vertices`` is updated in place; feature edges and fixed vertices
    follow. Deterministic.
    """
    P = mesh.points.copy()
    T = mesh.faces[:, :3].copy()
    C = mesh.component.copy()
    fe = np.sort(np.asarray(mesh.feature_edges, np.int64).reshape(-1, 2), axis=1)
    fid = np.asarray(mesh.feature_edge_ids).copy()
    fixed = np.zeros(len(P), bool)
    fixed[mesh.fixed_vertices] = True
    hold = np.zeros(len(P), bool)
    if keep is not None:
        hold[np.asarray(keep, np.int64)] = True
    arcs = [c.arc for c in chains]
    chain_vs = [np.asarray(c.vertices, np.int64) for c in chains]
    lmax = max_ratio * float(target)
    dmax = 0.003 * float(target) if max_deviation is None else float(max_deviation)
    orig = [P[c] for c in chain_vs]                  # the imprinted chains, exact points in order
    oidx = [np.arange(len(c)) for c in chain_vs]     # current chain vertices' places in them
    with np.errstate(invalid="ignore", divide="ignore"):
        for phase in (0, 1):
            for _ in range(rounds):
                n = len(P)
                kind, _co = _skin_roles(n, fe, fid, fixed, chain_vs, arcs)
                if phase == 0:
                    vs, us, ws, cis, pss, dvs = [], [], [], [], [], []
                    for ci, (arr, arc) in enumerate(zip(chain_vs, arcs)):   # a few dozen chains
                        m = len(arr)
                        if arc.closed and m >= 5:
                            pos = np.arange(m)
                        elif not arc.closed and m >= 3:
                            pos = np.arange(1, m - 1)
                        else:
                            continue
                        pos = pos[(kind[arr[pos]] == _CHAIN) & ~hold[arr[pos]]]
                        cur, prv, nxt = arr[pos], arr[(pos - 1) % m], arr[(pos + 1) % m]
                        dv = _chord_deviation(orig[ci], oidx[ci], pos, arc.closed)
                        vs += [cur, cur]
                        us += [prv, nxt]
                        ws += [nxt, prv]
                        cis += [np.full(2 * len(pos), ci)]
                        pss += [pos, pos]
                        dvs += [dv, dv]
                    if not vs:
                        break
                    v, u, w = np.concatenate(vs), np.concatenate(us), np.concatenate(ws)
                    cix, pos, dv = np.concatenate(cis), np.concatenate(pss), np.concatenate(dvs)
                    prio = norm_rows(P[w] - P[u], axis=1)
                    sel = (prio <= lmax) & (dv <= dmax)
                    v, u, w, prio, cix, pos, dv = v[sel], u[sel], w[sel], prio[sel], cix[sel], pos[sel], dv[sel]
                else:
                    on_chain = np.zeros(n, bool)
                    for arr in chain_vs:
                        on_chain[arr] = True
                    ek = unique_edges(T.ravel(), np.roll(T, -1, 1).ravel())
                    a, b = ek[:, 0], ek[:, 1]
                    v = np.concatenate([a, b])
                    u = np.concatenate([b, a])
                    sel = (kind[v] == _FREE) & ~fixed[v] & ~hold[v] & on_chain[u]
                    v, u = v[sel], u[sel]
                    prio = norm_rows(P[v] - P[u], axis=1)
                    sel = prio < near * float(target)
                    v, u, prio = v[sel], u[sel], prio[sel]
                    w = cix = pos = dv = np.zeros(len(v), np.int64)
                if not len(v):
                    break
                ptr, star = vertex_faces(T, n)
                ekeys = _edge_keys(T, n)
                ok, old_min, new_min = _collapse_checks(P, T, C, ptr, star, ekeys, v, u)
                if phase == 0:
                    ok &= ~_has_edge(ekeys, u, w, n)          # chain stays a simple path
                    ok &= new_min >= np.minimum(old_min, min_angle)
                else:
                    ok &= new_min > old_min + 1e-9
                v, u, prio, new_min, cix, pos, dv = v[ok], u[ok], prio[ok], new_min[ok], cix[ok], pos[ok], dv[ok]
                if not len(v):
                    break
                # one direction per vertex (the better angle), then shortest edge first
                o = np.lexsort((u, -new_min, v))
                first = np.ones(len(o), bool)
                first[1:] = v[o][1:] != v[o][:-1]
                o = o[first]
                o = o[np.lexsort((v[o], prio[o]))]
                v, u, cix, pos, dv = v[o], u[o], cix[o], pos[o], dv[o]
                win = _independent(ptr, star, v, u, len(T))
                if phase == 0:
                    for ci in np.unique(cix[win]).tolist():
                        oidx[ci] = np.delete(oidx[ci], pos[win[cix[win] == ci]])
                P, T, C, fe, fid, fixed, chain_vs = _apply_collapses(P, T, C, fe, fid, fixed, chain_vs,
                                                                     v[win], u[win])
                hold = np.zeros(len(P), bool) if keep is None else _remap_hold(hold, v[win])
                T, _nf = _flip_round(P, T, fe)
    for c, vv in zip(chains, chain_vs):
        c.vertices = vv
        fixed[vv] = True
    out = ShellMesh(P, T, C, mesh.component_names, np.flatnonzero(fixed), fe, fid.astype(mesh.feature_edge_ids.dtype))
    if improve:
        out = improve_skin(out, locator, chains)
    return out


def _chord_deviation(orig, oidx, pos, closed):
    """Largest distance of the imprinted chain points ``orig`` between the chain neighbours
    of the current vertices at ``pos`` (places ``oidx`` in ``orig``) from the chord joining
    those neighbours: the deviation if the vertices at ``pos`` were removed."""
    m, m0 = len(oidx), len(orig)
    i0, i1 = oidx[(pos - 1) % m], oidx[(pos + 1) % m]
    i1 = np.where(i1 <= i0, i1 + m0, i1) if closed else i1
    k = np.repeat(np.arange(len(pos)), i1 - i0 + 1)
    x = orig[_ranges(i0, i1 + 1) % m0]
    a, b = orig[i0][k], orig[i1 % m0][k]
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", x - a, ab) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    d = norm_rows(a + t[:, None] * ab - x, axis=1)
    out = np.zeros(len(pos))
    np.maximum.at(out, k, d)
    return out


def _remap_hold(hold, dead):
    alive = np.ones(len(hold), bool)
    alive[dead] = False
    return hold[alive]


# ----------------------------------------------------------------------------- local skin repair
# improve_skin's vectorised flips and smoothing leave a few triangles below the angle bound
# where the imprint packed chain vertices closer than the element size, where a chain ends
# or crosses a crease a fraction of an element away from the crease's next vertex, or where
# two oblique members cross. These spots (a handful per model) are repaired one by one on a
# small editable copy of the skin (_SkinPatch): for each bad triangle every candidate
# operation (edge collapse, edge split, vertex relocation, each followed by local
# angle-improving flips) is tried, rolled back, and the best kept if it improves the local
# angle distribution. Vertex roles decide what an operation may do:
_FREE, _CHAIN, _CREASE, _FIXED, _DEAD = 0, 1, 2, 3, 4
#   _FREE    on the input surface only: moves on the surface, may be collapsed into a neighbour
#   _CHAIN   inside one member chain (not a crossing/end): slides along its exact arc, may be
#            collapsed along its chain into a chain neighbour
#   _CREASE  inside a geometric feature line (2 crease edges, not a corner): slides along the
#            input's sharp edges, may be collapsed along the line into a line neighbour
#   _FIXED   crossings, chain ends, chain/crease crossings, corners, caller-fixed vertices
_MISSING = object()
_KEY = 1 << 31


def _skin_roles(n, fe, fid, fixed, chain_vs, arcs):
    """Role (_FREE/_CHAIN/_CREASE/_FIXED) and chain index (or -1) of every skin vertex."""
    kind = np.full(n, _FREE, np.int8)
    chain_of = np.full(n, -1, np.int64)
    cnt = np.zeros(n, np.int64)
    end = np.zeros(n, bool)
    for i, (v, arc) in enumerate(zip(chain_vs, arcs)):      # one pass per chain
        cnt[v] += 1
        chain_of[v] = i
        if not arc.closed:
            end[v[[0, -1]]] = True
    crease_deg = np.bincount(fe[fid < 0].ravel(), minlength=n)
    on_chain = cnt > 0
    kind[fixed & ~on_chain] = _FIXED
    kind[crease_deg > 0] = _FIXED
    kind[(crease_deg == 2) & ~fixed & ~on_chain] = _CREASE
    kind[on_chain] = _CHAIN
    kind[(cnt > 1) | end | (on_chain & (crease_deg > 0))] = _FIXED
    chain_of[kind != _CHAIN] = -1
    return kind, chain_of


def _closest_on_segments(q, a, b, full: bool = False):
    """Closest points on a set of segments a-b (s, 3) to query points q (n, 3), and their
    distances (every segment scanned by a compiled loop up to :data:`SCAN_WORK` pairs, else a
    KD-tree of segment midpoints with a conservative candidate radius: the same points); with
    ``full``, also the segment of each closest point and its parameter along it (ties: the
    lowest segment)."""
    q = np.atleast_2d(q)
    ab = b - a
    if len(q) * len(a) <= SCAN_WORK:
        # every query against every segment in one compiled loop: the same pick (the nearest
        # candidate, the lowest segment among equals) over a set that holds the KD-tree's
        x, dist, si, t = segments_scan(q, np.zeros(len(q), np.int64), np.full(len(q), len(a)), a, ab)
        return (x, dist, si, t) if full else (x, dist)
    L = norm_rows(ab, axis=1)
    tree = cKDTree(0.5 * (a + b))
    d0, _ = tree.query(q)
    cand = tree.query_ball_point(q, d0 + 0.5 * L.max() + 1e-300)
    cnt = np.fromiter((len(c) for c in cand), np.int64, len(cand))
    qi = np.repeat(np.arange(len(q)), cnt)
    si = np.concatenate([np.asarray(c, np.int64) for c in cand])
    x, dist, si, t = _pick_segments(q, qi, si, a, ab)
    return (x, dist, si, t) if full else (x, dist)


def _pick_segments(q, qi, si, a, ab):
    """Per query ``q[qi]`` (every query listed), the nearest of its candidate segments ``si``
    (``a + t ab``; ties: the lowest segment): ``(points, distances, segments, t)`` in query
    order."""
    L2 = np.einsum("ij,ij->i", ab[si], ab[si])
    t = np.clip(np.einsum("ij,ij->i", q[qi] - a[si], ab[si]) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    x = a[si] + t[:, None] * ab[si]
    dist = norm_rows(x - q[qi], axis=1)
    order = np.lexsort((si, dist, qi))
    first = np.ones(len(order), bool)
    first[1:] = qi[order][1:] != qi[order][:-1]
    o = order[first]
    return x[o], dist[o], si[o], t[o]


def _min_angles_small(X):
    """Smallest interior angle (degrees) of triangles given by their corners (t, 3, 3); the
    same as :func:`_angles3` with fewer array operations (for the few faces of a repair)."""
    e = X[:, [1, 2, 0]] - X                                   # e[:, i]: corner i -> i + 1
    l2 = np.einsum("tij,tij->ti", e, e)
    ep = e[:, [2, 0, 1]]                                      # edge arriving at corner i
    cos = -np.einsum("tij,tij->ti", e, ep) / np.maximum(np.sqrt(l2 * l2[:, [2, 0, 1]]), 1e-300)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).min(1)


def _unit_normals(X):
    """Unit normals of triangles given by their corners (t, 3, 3); zero for degenerate ones."""
    u = X[:, 1] - X[:, 0]
    v = X[:, 2] - X[:, 0]
    n = np.empty_like(u)
    n[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    n[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    n[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    ln = np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    return np.where(ln > 0, n / np.where(ln > 0, ln, 1.0), 0.0)


class _SkinPatch:
    """Editable triangle skin for the local repairs of :func:`improve_skin`: per-vertex face
    lists (CSR plus overrides for the touched vertices), feature edges (sorted keys plus
    overrides), vertex roles and chains, all changed through methods that write an undo
    journal, so a candidate operation can be tried and rolled back. Work per operation is
    local (the faces around a few vertices)."""

    COS_TURN = np.cos(np.radians(45.0))        # no face may turn more than this in one operation
    COS_FLIP = np.cos(np.radians(35.0))        # largest dihedral across a flipped edge

    def __init__(self, P, T, C, fe, fid, kind, chain_of, chains, arcs, chain_member, locator):
        n, m = len(P), len(T)
        self.P = np.zeros((n + 64, 3))
        self.P[:n] = P
        self.n = n
        self.T = np.zeros((m + 128, 3), np.int64)
        self.T[:m] = T
        self.m = m
        self.C = np.zeros(m + 128, C.dtype)
        self.C[:m] = C
        self.alive = np.zeros(m + 128, bool)
        self.alive[:m] = True
        self.kind = np.full(n + 64, _DEAD, np.int8)
        self.kind[:n] = kind
        self.chain_of = np.full(n + 64, -1, np.int64)
        self.chain_of[:n] = chain_of
        self.ptr, self.star = vertex_faces(T, n)
        self.over = {}
        keys = fe[:, 0] * _KEY + fe[:, 1]
        o = np.argsort(keys, kind="stable")
        self.fkeys, self.fids = keys[o], np.asarray(fid)[o]
        self.fover = {}
        self.chains = list(chains)
        # a chain vertex collapse may not make a chain edge longer than 1.3 x the chain's
        # longest edge as imprinted (nor than 1.5 x the longer of the two edges it joins)
        self.chain_lmax = [1.3 * float(norm_rows(np.diff(P[c], axis=0), axis=1).max()) if len(c) > 1
                           else np.inf for c in self.chains]
        self.arcs = arcs
        self.chain_member = chain_member
        self.locator = locator
        self.eps = 1e-9 * locator.diagonal
        self._soup = None
        self._crease0 = (np.asarray(P).copy(), fe[np.asarray(fid) < 0])   # the lines remeshing kept
        self.journal = []
        self.region = None
        self.killed_out = []
        self.applied = {"collapse": 0, "split": 0, "move": 0, "flip": 0}

    # ------------------------------------------------------------ journaled storage
    def _grow(self):
        if self.n + 1 >= len(self.P):
            k = len(self.P)
            self.P = np.vstack([self.P, np.zeros((k, 3))])
            self.kind = np.concatenate([self.kind, np.full(k, _DEAD, np.int8)])
            self.chain_of = np.concatenate([self.chain_of, np.full(k, -1, np.int64)])
        if self.m + 4 >= len(self.T):
            k = len(self.T)
            self.T = np.vstack([self.T, np.zeros((k, 3), np.int64)])
            self.C = np.concatenate([self.C, np.zeros(k, self.C.dtype)])
            self.alive = np.concatenate([self.alive, np.zeros(k, bool)])

    def faces(self, v):
        r = self.over.get(v)
        if r is not None:
            return r
        if v < len(self.ptr) - 1:
            return self.star[self.ptr[v]:self.ptr[v + 1]]
        return np.zeros(0, np.int64)

    def _set_over(self, v, arr):
        self.journal.append(("over", v, self.over.get(v, _MISSING)))
        self.over[v] = arr

    def kill(self, f):
        if self.region is not None and f not in self.region:
            self.killed_out.append(float(_min_angles_small(self.P[self.T[f:f + 1]])[0]))
        self.journal.append(("kill", f))
        self.alive[f] = False
        for v in self.T[f].tolist():
            fs = self.faces(v)
            self._set_over(v, fs[fs != f])

    def add(self, tri, comp):
        self._grow()
        f = self.m
        self.T[f] = tri
        self.C[f] = comp
        self.alive[f] = True
        self.m += 1
        self.journal.append(("add",))
        for v in self.T[f].tolist():
            self._set_over(v, np.append(self.faces(v), f))
        return f

    def set_point(self, v, x):
        self.journal.append(("P", v, self.P[v].copy()))
        self.P[v] = x

    def add_point(self, x, kind, chain):
        self._grow()
        v = self.n
        self.P[v] = x
        self.kind[v] = kind
        self.chain_of[v] = chain
        self.n += 1
        self.journal.append(("addP",))
        return v

    def set_kind(self, v, k):
        self.journal.append(("kind", v, self.kind[v]))
        self.kind[v] = k

    def feat(self, a, b):
        """Feature id of edge a-b (member component id, -1 for a crease) or None."""
        a, b = (a, b) if a < b else (b, a)
        key = a * _KEY + b
        r = self.fover.get(key, _MISSING)
        if r is not _MISSING:
            return r
        i = int(np.searchsorted(self.fkeys, key))
        if i < len(self.fkeys) and self.fkeys[i] == key:
            return int(self.fids[i])
        return None

    def set_feat(self, a, b, val):
        a, b = (a, b) if a < b else (b, a)
        key = a * _KEY + b
        self.journal.append(("feat", key, self.fover.get(key, _MISSING)))
        self.fover[key] = val

    def set_chain(self, ci, arr):
        self.journal.append(("chain", ci, self.chains[ci]))
        self.chains[ci] = arr

    def undo(self, mark):
        while len(self.journal) > mark:
            e = self.journal.pop()
            k = e[0]
            if k == "over" or k == "feat":
                d = self.over if k == "over" else self.fover
                if e[2] is _MISSING:
                    del d[e[1]]
                else:
                    d[e[1]] = e[2]
            elif k == "kill":
                self.alive[e[1]] = True
            elif k == "add":
                self.m -= 1
                self.alive[self.m] = False
            elif k == "P":
                self.P[e[1]] = e[2]
            elif k == "addP":
                self.n -= 1
                self.kind[self.n] = _DEAD
                self.chain_of[self.n] = -1
            elif k == "kind":
                self.kind[e[1]] = e[2]
            elif k == "chain":
                self.chains[e[1]] = e[2]

    # ------------------------------------------------------------ queries
    def neighbours(self, v):
        u = np.unique(self.T[self.faces(v)])
        return u[u != v]

    def oriented(self, a, b):
        """The two faces of edge a-b as ``((f0, r), (f1, s))``: f0 runs a->b with opposite
        corner r, f1 runs b->a with opposite corner s; None unless exactly two such faces."""
        fs = self.faces(a)
        fs = fs[(self.T[fs] == b).any(1)]
        if len(fs) != 2:
            return None
        out = {}
        for f in fs.tolist():
            t = self.T[f]
            i = int(np.flatnonzero(t == a)[0])
            if t[(i + 1) % 3] == b:
                out[0] = (f, int(t[(i + 2) % 3]))
            else:
                out[1] = (f, int(t[(i + 1) % 3]))
        return (out[0], out[1]) if len(out) == 2 else None

    def on_crease(self, q):
        """Closest points on the input's sharp edges (the lines remeshing kept) and distances."""
        if self._soup is None:
            pts, crease = self._crease0
            self._soup = kept_sharp_segments(self.locator.points, self.locator.triangles, pts, crease, self.eps)
        a, b = self._soup
        q = np.atleast_2d(q)
        if not len(a):
            return q, np.full(len(q), np.inf)
        return _closest_on_segments(q, a, b)

    def turned(self, new_tris, old_normals):
        """True where a new triangle is degenerate or turned more than 45 degrees from the
        normal of the face it replaces."""
        nn = _unit_normals(self.P[np.asarray(new_tris)])
        return np.einsum("ij,ij->i", nn, old_normals) <= self.COS_TURN

    # ------------------------------------------------------------ operations
    def flip(self, a, b, min_gain):
        """Flip edge a-b (not a chain/crease edge, faces of one component, dihedral below 35
        degrees) when that raises the pair's smallest angle by more than ``min_gain``.
        Returns the new edge's ends (r, s), or False."""
        if self.feat(a, b) is not None:
            return False
        o = self.oriented(a, b)
        if o is None:
            return False
        (f0, r), (f1, s) = o
        if r == s or self.C[f0] != self.C[f1]:
            return False
        tt = np.array([self.T[f0], self.T[f1], [r, s, b], [s, r, a]])
        X = self.P[tt]
        ang = _min_angles_small(X)
        if min(ang[2], ang[3]) <= min(ang[0], ang[1]) + min_gain:
            return False
        nn = _unit_normals(X)
        if nn[0] @ nn[1] < self.COS_FLIP:
            return False
        navg = nn[0] + nn[1]
        navg /= max(np.linalg.norm(navg), 1e-300)
        if nn[2] @ navg <= self.COS_TURN or nn[3] @ navg <= self.COS_TURN:
            return False
        if (self.T[self.faces(r)] == s).any():              # edge r-s exists already
            return False
        c0, c1 = self.C[f0], self.C[f1]
        self.kill(f0)
        self.kill(f1)
        self.add(tt[2], c0)
        self.add(tt[3], c1)
        return r, s

    def local_flips(self, faces, min_gain=0.01, limit=24):
        """Angle-improving flips of the edges of ``faces``, spreading to the edges around each
        flip (a queue; at most ``limit`` flips). Returns the number of flips."""
        queue = []
        for f in faces:
            t = self.T[f].tolist()
            queue += [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])]
        done, i = 0, 0
        seen = set()
        while i < len(queue) and done < limit:
            a, b = queue[i]
            i += 1
            key = (a, b) if a < b else (b, a)
            if key in seen:
                continue
            seen.add(key)
            o = self.flip(a, b, min_gain)
            if o:
                done += 1
                r, s = o
                queue += [(a, r), (r, b), (b, s), (s, a)]
                for e in ((a, r), (r, b), (b, s), (s, a)):
                    seen.discard(e if e[0] < e[1] else (e[1], e[0]))
        return done

    def collapse(self, v, u):
        """Remove vertex v by merging it into its neighbour u (u keeps its position). A free
        vertex may merge into any neighbour; a chain or crease vertex only along its line."""
        k = self.kind[v]
        fid = self.feat(u, v)
        if k == _FREE:
            if fid is not None:
                return False
        elif k == _CHAIN:
            if fid is None or fid < 0:
                return False
        elif k == _CREASE:
            if fid != -1:
                return False
        else:
            return False
        o = self.oriented(u, v)
        if o is None:
            return False
        (fa, r), (fb, s) = o
        nv = self.neighbours(v)
        common = np.intersect1d(nv, self.neighbours(u))        # link condition
        if len(common) != 2 or sorted(common.tolist()) != sorted((r, s)):
            return False
        moved = []
        for w in nv.tolist():
            if w == u:
                continue
            i = self.feat(v, w)
            if i is not None:
                if k == _FREE or w in (r, s):
                    return False
                moved.append((w, i))
        if k != _FREE and len(moved) != 1:
            return False
        if k == _CHAIN:
            w = moved[0][0]
            lw = float(np.linalg.norm(self.P[u] - self.P[w]))
            if lw > self.chain_lmax[int(self.chain_of[v])] or lw > 1.5 * max(
                    float(np.linalg.norm(self.P[u] - self.P[v])), float(np.linalg.norm(self.P[v] - self.P[w]))):
                return False
        fv = self.faces(v)
        keep = fv[(fv != fa) & (fv != fb)]
        new = self.T[keep].copy()
        new[new == v] = u
        if self.turned(new, _unit_normals(self.P[self.T[keep]])).any():
            return False
        comps = self.C[keep].copy()
        for f in fv.tolist():
            self.kill(f)
        for t, c in zip(new, comps):
            self.add(t, c)
        self.set_feat(u, v, None)
        for w, i in moved:
            self.set_feat(v, w, None)
            self.set_feat(u, w, i)
        if k == _CHAIN:
            ci = int(self.chain_of[v])
            arr = self.chains[ci]
            self.set_chain(ci, arr[arr != v])
        self.set_kind(v, _DEAD)
        return True

    def _chain_of_edge(self, a, b, fid):
        """Index of the chain (of member ``fid``) having a and b as consecutive vertices."""
        for c in np.flatnonzero(self.chain_member == fid).tolist():
            arr = self.chains[c]
            ia, ib = np.flatnonzero(arr == a), np.flatnonzero(arr == b)
            if len(ia) and len(ib):
                d = abs(int(ia[0]) - int(ib[0]))
                if d == 1 or (self.arcs[c].closed and d == len(arr) - 1):
                    return c
        return -1

    def split(self, a, b, t):
        """Split edge a-b near parameter t: the new vertex lies on the input surface, on the
        exact arc for a chain edge (inserted into the chain), on the input's sharp edge for
        a crease edge. Both faces of the edge are split in two."""
        o = self.oriented(a, b)
        if o is None:
            return False
        (f0, r), (f1, s) = o
        x0 = self.P[a] + t * (self.P[b] - self.P[a])
        fid = self.feat(a, b)
        ci = -1
        if fid is None:
            x, kind = self.locator.closest(x0)[0][0], _FREE
        elif fid >= 0:
            ci = self._chain_of_edge(a, b, fid)
            if ci < 0:
                return False
            x, kind = closest_on_polyline(x0, self.arcs[ci].points, self.arcs[ci].closed)[0], _CHAIN
        else:
            xs, d = self.on_crease(np.vstack([x0, self.P[a], self.P[b]]))
            if d[1] > self.eps or d[2] > self.eps or d[0] > 0.25 * np.linalg.norm(self.P[b] - self.P[a]):
                return False
            x, kind = xs[0], _CREASE
        nn = _unit_normals(self.P[self.T[[f0, f1]]])
        self._grow()
        n = self.n
        self.P[n] = x                      # scratch slot for the check; add_point writes it again
        new = np.array([[a, n, r], [n, b, r], [b, n, s], [n, a, s]])
        if self.turned(new, nn[[0, 0, 1, 1]]).any():
            return False
        n = self.add_point(x, kind, ci)
        c0, c1 = self.C[f0], self.C[f1]
        self.kill(f0)
        self.kill(f1)
        for tri, c in zip(new, (c0, c0, c1, c1)):
            self.add(tri, c)
        if fid is not None:
            self.set_feat(a, b, None)
            self.set_feat(a, n, fid)
            self.set_feat(n, b, fid)
        if ci >= 0:
            arr = self.chains[ci]
            ia, ib = int(np.flatnonzero(arr == a)[0]), int(np.flatnonzero(arr == b)[0])
            self.set_chain(ci, np.insert(arr, max(ia, ib) if abs(ia - ib) == 1 else len(arr), n))
        return True

    def _candidates(self, v):
        """Candidate positions of vertex v: on the input surface around it (free), along its
        exact arc towards its chain neighbours (chain), along the input's sharp edge towards
        its line neighbours (crease)."""
        k = self.kind[v]
        x = self.P[v]
        nb = self.neighbours(v)
        if k == _FREE:
            L = float(np.mean(norm_rows(self.P[nb] - x, axis=1)))
            tri = self.T[self.faces(v)]
            nrm = np.cross(self.P[tri[:, 1]] - self.P[tri[:, 0]], self.P[tri[:, 2]] - self.P[tri[:, 0]]).sum(0)
            nrm /= max(np.linalg.norm(nrm), 1e-300)
            e1 = np.cross(nrm, [1.0, 0.0, 0.0])
            if np.linalg.norm(e1) < 0.5:
                e1 = np.cross(nrm, [0.0, 1.0, 0.0])
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(nrm, e1)
            th = np.radians(np.arange(0.0, 360.0, 30.0))
            dirs = np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2
            r = L * np.array([0.4, 0.2, 0.1, 0.05, 0.02])
            cen = self.P[nb].mean(0)
            q = np.vstack([x + (r[:, None, None] * dirs[None]).reshape(-1, 3), cen, 0.5 * (x + cen)])
            return self.locator.closest(q)[0]
        if k == _CHAIN:
            ci = int(self.chain_of[v])
            arr = self.chains[ci]
            i = int(np.flatnonzero(arr == v)[0])
            arc = self.arcs[ci]
            if not arc.closed and (i == 0 or i == len(arr) - 1):
                return np.zeros((0, 3))
            nbs = [arr[(i - 1) % len(arr)], arr[(i + 1) % len(arr)]]
            pts = np.vstack([arc.points, arc.points[:1]]) if arc.closed else arc.points
            cum = np.concatenate([[0.0], np.cumsum(norm_rows(np.diff(pts, axis=0), axis=1))])
            s = _polyline_param(np.vstack([x, self.P[nbs]]), pts, cum)
            d = s[1:] - s[0]
            if arc.closed:
                d = np.where(np.abs(d) > 0.5 * cum[-1], d - np.sign(d) * cum[-1], d)
            sp = s[0] + (np.array([0.05, 0.1, 0.2, 0.3, 0.4, 0.5])[None] * d[:, None]).ravel()
            sp = np.mod(sp, cum[-1]) if arc.closed else np.clip(sp, 0.0, cum[-1])
            q = np.stack([np.interp(sp, cum, pts[:, j]) for j in range(3)], 1)
            # the chain's spacing bound of collapse(): no chain edge at v longer than 1.3 x the chain's
            # longest edge as imprinted (or than the longer of the two now, if that is already over)
            lq = norm_rows(q[:, None, :] - self.P[nbs][None], axis=2).max(1)
            lim = max(self.chain_lmax[ci], float(norm_rows(self.P[nbs] - x, axis=1).max()))
            return q[lq <= lim]
        if k == _CREASE:
            ws = [w for w in nb.tolist() if self.feat(v, w) == -1]
            if len(ws) != 2 or self.on_crease(x)[1][0] > self.eps:
                return np.zeros((0, 3))
            a = np.array([0.05, 0.1, 0.2, 0.3, 0.4, 0.5])
            q = np.vstack([x + a[:, None] * (self.P[w] - x) for w in ws])
            xs, d = self.on_crease(q)
            return xs[d <= 0.1 * norm_rows(q - x, axis=1) + self.eps]
        return np.zeros((0, 3))

    def move(self, v, iters=4):
        """Hill-climb vertex v over its candidate positions to raise its star's smallest
        angle (no face turning more than 45 degrees from where it started)."""
        if self.kind[v] not in (_FREE, _CHAIN, _CREASE):
            return False
        tri = self.T[self.faces(v)]
        if not len(tri):
            return False
        n0 = _unit_normals(self.P[tri])
        which = (tri == v)[None, :, :, None]
        moved = False
        for _ in range(iters):
            X = self.P[tri]
            cur = _min_angles_small(X).min()
            q = self._candidates(v)
            if not len(q):
                break
            Xc = np.where(which, q[:, None, None, :], X[None]).reshape(-1, 3, 3)   # (k * f, 3, 3)
            ang = _min_angles_small(Xc).reshape(len(q), len(tri))
            turn = np.einsum("kfi,fi->kf", _unit_normals(Xc).reshape(len(q), len(tri), 3), n0) <= self.COS_TURN
            score = np.where(turn.any(1), -1.0, ang.min(1))
            j = int(np.argmax(score))
            if score[j] <= cur + 1e-6:
                break
            self.set_point(v, q[j])
            moved = True
        return moved

    # ------------------------------------------------------------ driver
    def _ring_faces(self, verts):
        fs = np.unique(np.concatenate([self.faces(v) for v in verts]))
        return np.unique(np.concatenate([self.faces(int(v)) for v in np.unique(self.T[fs])]))

    @staticmethod
    def _better(a, b, cap):
        """Lexicographic comparison of the sorted (capped) smallest angles: is a better than b?"""
        k = max(len(a), len(b))
        a = np.concatenate([np.sort(a), np.full(k - len(a), cap)])
        b = np.concatenate([np.sort(b), np.full(k - len(b), cap)])
        d = np.flatnonzero(np.abs(a - b) > 1e-7)
        return bool(len(d)) and bool(a[d[0]] > b[d[0]])

    def _apply(self, cand):
        op = cand[0]
        if op == "flip":
            return True                     # the local flips that follow every candidate
        if op == "collapse":
            return self.collapse(cand[1], cand[2])
        if op == "split":
            return self.split(cand[1], cand[2], cand[3])
        return self.move(cand[1])

    def _trial(self, cand, f):
        m0 = self.m
        if not self._apply(cand):
            return False
        self.local_flips(list(range(m0, self.m)) + ([f] if self.alive[f] else []))
        return True

    def repair_face(self, f, cap):
        """Try every candidate operation on face f (collapse of each short edge either way,
        split of the longest edge at the foot of the opposite corner and at its midpoint,
        relocation of each corner; each followed by local flips); keep the one that best
        improves the sorted smallest angles of the faces around f. Returns whether one was
        kept."""
        t = self.T[f].tolist()
        R0 = self._ring_faces(t)
        q_old = np.minimum(_min_angles_small(self.P[self.T[R0]]), cap)
        X = self.P[t]
        L = norm_rows(X[[1, 2, 0]] - X, axis=1)          # edge i joins corners i, i+1
        cands = [("flip",)]
        for i in range(3):
            a, b = t[i], t[(i + 1) % 3]
            if L[i] <= 0.6 * L.max():                        # short edge: collapse either way
                cands += [("collapse", a, b), ("collapse", b, a)]
        i = int(np.argmax(L))                                # longest edge: split
        a, b = t[i], t[(i + 1) % 3]
        ab = X[(i + 1) % 3] - X[i]
        foot = float(np.clip((X[(i + 2) % 3] - X[i]) @ ab / max(ab @ ab, 1e-300), 0.15, 0.85))
        cands.append(("split", a, b, foot))
        if abs(foot - 0.5) > 0.1:
            cands.append(("split", a, b, 0.5))
        cands += [("move", v) for v in t if self.kind[v] in (_FREE, _CHAIN, _CREASE)]
        best, best_q = None, None
        region = set(R0.tolist())
        for cand in cands:
            mark = len(self.journal)
            m0 = self.m
            self.region, self.killed_out = region, []
            if self._trial(cand, f):
                new_f = np.concatenate([R0, np.arange(m0, self.m)])
                q_new = np.minimum(_min_angles_small(self.P[self.T[new_f[self.alive[new_f]]]]), cap)
                old = np.concatenate([q_old, np.minimum(self.killed_out, cap)])
                if self._better(q_new, old, cap) and (best is None or self._better(q_new, best_q, cap)):
                    best, best_q = cand, q_new
            self.region = None
            self.undo(mark)
        if best is None:
            return False
        self._trial(best, f)
        self.applied[best[0]] += 1
        return True

    def bad_faces(self, target):
        """Live faces with an angle below ``target``, worst first."""
        f = np.flatnonzero(self.alive[:self.m])
        a = _min_angles_small(self.P[self.T[f]])
        o = np.argsort(a, kind="stable")
        return f[o[a[o] < target]]

    def export(self):
        """Compacted ``(P, T, C, feature_edges, feature_ids, chains, old_to_new)``: dead faces
        dropped, unreferenced vertices removed (old_to_new -1), surviving order kept."""
        alive = np.flatnonzero(self.alive[:self.m])
        T = self.T[alive]
        used = np.zeros(self.n, bool)
        used[T.ravel()] = True
        remap = np.full(self.n, -1, np.int64)
        remap[used] = np.arange(int(used.sum()))
        okeys = np.array(sorted(self.fover), np.int64)
        base = ~np.isin(self.fkeys, okeys)
        ov = [(k, self.fover[k]) for k in okeys.tolist() if self.fover[k] is not None]
        keys = np.concatenate([self.fkeys[base], np.array([k for k, _ in ov], np.int64)])
        ids = np.concatenate([self.fids[base], np.array([i for _, i in ov], np.int64)]).astype(np.int32)
        fe = remap[np.stack([keys // _KEY, keys % _KEY], 1)]
        return (self.P[:self.n][used], remap[T], self.C[alive], fe, ids, [remap[c] for c in self.chains], remap)
