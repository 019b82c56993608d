"""Skin improvement after the cut: angle-improving edge flips, tangential smoothing (free vertices on
the input surface, chain vertices along their exact arcs), then the local repair of the few
triangles still below the angle bound (:func:`improve_skin`)."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core.polyline import SCAN_WORK, pick_segments
from ..core.kernels import edge_lookup, edge_rows, edge_table, segments_scan
from .kernels import skin_flips, star_independent, star_moves
from ..mesh import ShellMesh, cross_rows, norm_rows, vertex_faces
from .common import MAX_STAND, min_angle_from_cos, min_angles_small, ranges, stands_up, tri_angles_min
from .repair import CHAIN, FREE, SkinPatch, skin_roles

__all__ = ["improve_skin", "flip_round"]


def _closest_on_arcs(q: np.ndarray, cid: np.ndarray, arcs, params: bool = False):
    """Closest point of each query ``q[i]`` on the arc ``arcs[cid[i]]``: the same points, bit
    for bit, as :func:`closest_on_polyline` arc by arc, in one query. Up to
    :data:`SCAN_WORK` query-segment pairs, one compiled loop scans every segment of each
    query's arc (:func:`~shellmesh_mdao.core.kernels.segments_scan`). Above, the segment midpoints
    of all arcs go in one KD-tree with the arc's index times a separation far larger than
    the model as a fourth coordinate, so a query meets only its own arc's segments (at their
    plain distance); its candidates lie within the nearest midpoint's distance plus half its
    arc's longest segment, as in :func:`closest_on_segments`, and the nearest candidate wins
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
    x, _, seg, t = pick_segments(q, qi[keep], si[keep], a, ab)
    return x, seg, t


def flip_round(P, T, locked_edges, max_dihedral=35.0, min_gain=1.0, active=None):
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
    old_min = np.minimum(min_angle_from_cos(cos[0]), min_angle_from_cos(cos[1]))
    t0 = np.stack([r, s, q], 1)
    t1 = np.stack([s, r, p], 1)
    new_min = np.minimum(min_angle_from_cos(cos[2]), min_angle_from_cos(cos[3]))
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


def _stands_up(v, ptr, star, T, P, new, locator, max_stand):
    """For each vertex ``v`` moved alone from ``P`` to ``new``: whether a triangle of its star
    (``ptr``, ``star``: :func:`vertex_faces`) would break the standing rule (:func:`stands_up`)."""
    rows = np.repeat(v, np.diff(ptr)[v])
    tris = star[ranges(ptr[v], ptr[v + 1])]
    X0 = P[T[tris]]
    X1 = X0.copy()
    X1[T[tris] == rows[:, None]] = new[rows]
    bad = stands_up(X0, X1, locator, max_stand)
    out = np.zeros(len(P), bool)
    out[rows[bad]] = True
    return out[v]


def _smooth_round(P, T, movable, locator, chain_of=None, arcs=None, step=0.5, chain_nb=None, hint=None,
                  max_stand=MAX_STAND):
    """Move each movable vertex towards the area-weighted centroid of its star (tangential,
    then onto the input surface); chain vertices (``chain_of[v] >= 0``) move the same way,
    projected onto their exact arc. A move is kept only if it raises the smallest angle of
    the vertex's star and flips no triangle, and (``chain_nb``: each vertex's previous and
    next vertex along its chain, -1 for none) keeps the vertex between its chain neighbours
    along the arc: where the skin is thinner than its faces the closest arc point can be on
    the far side of the section, and the chain would run back and forth there (a spike).
    Nor may a move leave a triangle of the star standing up off the input surface
    (:func:`~.common.stands_up` with ``max_stand``, the rule the local repair keeps too): across
    a sharp input edge that is no feature line (the remesh drops the outline of a tip cap thinner
    than its deviation near a sharp trailing edge) a vertex of the cap's outline would otherwise
    be carried onto the skin beside it, its cap triangles then standing across the crease (and
    the quads merged and subdivided from them folded over it).
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
    tris = star[ranges(ptr[cand], ptr[cand + 1])]
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
    ang_new = min_angle_from_cos(cos_new)
    ang_old = min_angle_from_cos(cos_old)
    # each candidate's star is one run of ``rows`` (every candidate has a face)
    starts = np.concatenate([[0], np.cumsum(np.diff(ptr)[cand])[:-1]])
    worst_new = np.full(n, np.inf)
    worst_old = np.full(n, np.inf)
    worst_new[cand] = np.minimum.reduceat(np.where(flip, -1.0, ang_new), starts)
    worst_old[cand] = np.minimum.reduceat(ang_old, starts)
    ok = cand[worst_new[cand] > worst_old[cand] + 1e-9]
    if chain_nb is not None and chain_of is not None and len(ok):
        ok = ok[_in_order_on_arc(ok, new, P, chain_of, chain_nb, arcs)]
    if len(ok):
        ok = ok[~_stands_up(ok, ptr, star, T, P, new, locator, max_stand)]
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
    kind, chain_of = skin_roles(len(P), fe, fid, fixed, chain_vs, arcs)
    movable = (kind == FREE) | (kind == CHAIN)
    active = None
    if rings is not None and chain_vs:
        # only where the cut changed the skin or the skin is poor: the rest is the remesh's, which
        # the imprint did not touch (rounds over the whole skin cost 0.3 s more on cessna210 for
        # the same figures, docs/benchmarks.md)
        from ..core.topology import face_rings

        ptr, vf = vertex_faces(T, len(P))
        active = np.zeros(len(P), bool)
        for seed, r in ((np.unique(np.concatenate(chain_vs)), int(rings)),
                        (np.unique(T[tri_angles_min(P, T) < poor_angle]), 1)):
            active[seed] = True
            if r > 0:
                active[T[face_rings(T, ptr, vf, seed, r)]] = True
        movable &= active
    chain_nb = _chain_neighbours(len(P), chain_vs, arcs)
    hint = np.full(len(P), -1, np.int64)            # each vertex's input triangle, once projected
    with np.errstate(invalid="ignore"):
        for _ in range(rounds):
            T, nf = flip_round(P, T, fe, min_gain=min_gain, active=active)
            P, nm = _smooth_round(P, T, movable, locator, chain_of, arcs, chain_nb=chain_nb, hint=hint)
            if nf == 0 and nm == 0:
                break
    C = mesh.component
    target = min_angle + 0.5
    if len(T) and tri_angles_min(P, T).min() < target:
        names = list(mesh.component_names)
        member = np.array([names.index(c.member) if c.member in names else -2 for c in chains], np.int64)
        W = SkinPatch(P, T, C, fe, fid, kind, chain_of, chain_vs, arcs, member, locator)
        budget = 32 + len(T) // 4000 if max_repairs is None else int(max_repairs)
        for _ in range(passes):               # loops over the few bad triangles only
            n_fixed = 0
            for f in W.bad_faces(target).tolist():
                if budget <= 0:
                    break
                if W.alive[f] and min_angles_small(W.P[W.T[f:f + 1]])[0] < target:
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
