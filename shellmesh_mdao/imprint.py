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
   plane and the crossed triangles re-triangulated (best diagonal);
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
from .mesh import ShellMesh
from .section import Plane, SectionArc, section_arc

__all__ = ["ChainSpec", "ChainResult", "closest_on_polyline", "insert_point", "cut_chain"]


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


@dataclass
class ChainResult:
    member: str
    side: str
    vertices: np.ndarray          # ordered chain vertex indices in the skin mesh
    arc: SectionArc = field(repr=False, default=None)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)


def closest_on_polyline(q: np.ndarray, poly: np.ndarray, closed: bool = False) -> np.ndarray:
    """Closest points on a polyline (k, 3) to query points (n, 3), vectorised via a KD-tree
    of segment midpoints with a conservative candidate radius."""
    q = np.atleast_2d(np.asarray(q, float))
    p = np.vstack([poly, poly[:1]]) if closed else poly
    a, b = p[:-1], p[1:]
    ab = b - a
    L = np.linalg.norm(ab, axis=1)
    mid = 0.5 * (a + b)
    tree = cKDTree(mid)
    # candidate radius: distance to the nearest midpoint plus half the longest segment
    d0, _ = tree.query(q)
    r = d0 + 0.5 * L.max() + 1e-300
    cand = tree.query_ball_point(q, r)
    cnt = np.fromiter((len(c) for c in cand), np.int64, len(cand))
    qi = np.repeat(np.arange(len(q)), cnt)
    si = np.concatenate([np.asarray(c, np.int64) for c in cand])
    L2 = np.einsum("ij,ij->i", ab[si], ab[si])
    t = np.clip(np.einsum("ij,ij->i", q[qi] - a[si], ab[si]) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    x = a[si] + t[:, None] * ab[si]
    dist = np.linalg.norm(x - q[qi], axis=1)
    order = np.lexsort((dist, qi))
    first = np.ones(len(order), bool)
    first[1:] = qi[order][1:] != qi[order][:-1]
    return x[order[first]]


def _tri_angles_min(P, T):
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]

    def ang(u, v):
        cu = np.einsum("ij,ij->i", u, v) / np.maximum(np.linalg.norm(u, axis=1) * np.linalg.norm(v, axis=1), 1e-300)
        return np.degrees(np.arccos(np.clip(cu, -1, 1)))

    return np.minimum(np.minimum(ang(b - a, c - a), ang(a - b, c - b)), ang(a - c, b - c))


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
    a, b, c = P[T[:, 0]], P[T[:, 1]], P[T[:, 2]]
    cen = (a + b + c) / 3
    # candidate triangles: nearest centroids, then exact point-triangle distance
    k = min(32, len(T))
    _, cand = cKDTree(cen).query(x, k=k)
    cand = np.atleast_1d(cand)
    bary, dist = _point_tri(x, a[cand], b[cand], c[cand])
    j = int(np.argmin(dist))
    f = int(cand[j])
    w = bary[j]
    tri = T[f]
    L = np.mean(np.linalg.norm(P[tri] - P[np.roll(tri, -1)], axis=1))
    dv = np.linalg.norm(P[tri] - x, axis=1)
    order = np.argsort(dv, kind="stable")
    for i in order:
        if dv[i] <= snap * L and movable[tri[i]]:
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
        has_u = (T == u).any(1)
        has_v = (T == v).any(1)
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
            dd = np.linalg.norm(s + t[:, None] * se - p, axis=1)
            better = dd < best
            best = np.where(better, dd, best)
            nb = np.zeros((len(t), 3))
            nb[np.arange(len(t)), i0] = 1 - t
            nb[np.arange(len(t)), i1] = t
            bb = np.where(better[:, None], nb, bb)
        bary[out] = bb
    x = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    return bary, np.linalg.norm(x - p, axis=1)


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
        diag = float(np.linalg.norm(P.max(0) - P.min(0)))
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
    el = np.linalg.norm(P[rt] - P[rb], axis=1).ravel()
    vmin = np.full(len(P), np.inf)
    np.minimum.at(vmin, rt.ravel(), el)
    np.minimum.at(vmin, rb.ravel(), el)
    rv = np.unique(rt)
    h = vmin[rv]
    # signs: zero only for vertices inside the bounds (exactly on the plane, snapped, or
    # crossing vertices given); outside the bounds a vertex on the plane counts as +
    diag = float(np.linalg.norm(P.max(0) - P.min(0)))
    inside = np.ones(len(P), bool)
    for bnd in spec.bounds:
        inside &= bnd.side(P) >= -1e-9 * diag
    sgn = np.where(d >= 0, 1.0, -1.0)
    sgn[(d == 0) & inside] = 0.0
    sgn[on_plane] = 0.0
    close = rv[(np.abs(d[rv]) <= snap * h) & movable[rv] & inside[rv]]
    sgn[close] = 0.0
    # never three zero corners in one triangle: un-snap the farthest snapped corner
    snapped = np.zeros(len(P), bool)
    snapped[close] = True
    for _ in range(10):
        allz = rt[(sgn[rt] == 0).all(1)]
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
    # chain edges along existing edges: two zero vertices in a region face
    zero_pair_faces = (s == 0).sum(1) >= 2
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
    pos_f, neg_f = (fsg > 0).any(1), (fsg < 0).any(1)
    label = np.where(pos_f & ~neg_f, 1, np.where(neg_f & ~pos_f, -1, 0))
    label[~touch[T2].any(1)] = 0
    chain_v = _chain_from_labels(T2, label, name)
    P = P.copy()
    old = chain_v < n0
    mov = chain_v[~old | ~on_plane[np.minimum(chain_v, n0 - 1)]]
    if len(mov):
        P[mov] = closest_on_polyline(P[mov], arc.points, arc.closed)
    return P, T2, C2, chain_v, (uedges, new_id)


def _chain_from_labels(T, label, name):
    """Ordered vertices of the edges separating faces labelled +1 from faces labelled -1."""
    a, b = T, np.roll(T, -1, axis=1)
    e = np.stack([np.minimum(a, b), np.maximum(a, b)], -1).reshape(-1, 2)
    lab = np.repeat(label, 3)
    ok = lab != 0
    e, lab = e[ok], lab[ok]
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    has_pos = np.zeros(len(uniq), bool)
    has_neg = np.zeros(len(uniq), bool)
    has_pos[inv[lab > 0]] = True
    has_neg[inv[lab < 0]] = True
    ce = uniq[has_pos & has_neg]
    if not len(ce):
        raise ImprintError(f"{name}: the imprint produced no chain edges; use a smaller --size")
    verts, deg = np.unique(ce, return_counts=True)
    if (deg > 2).any():
        raise ImprintError(f"{name}: the imprinted curve branches at vertex {int(verts[deg > 2][0])}; "
                           "the member is too close to another member or to a sharp edge for this --size "
                           "(use a smaller --size or move the member)")
    ends = verts[deg == 1]
    if len(ends) not in (0, 2):
        raise ImprintError(f"{name}: the imprinted curve is broken into pieces; use a smaller --size")
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components, depth_first_order

    nmax = int(ce.max()) + 1
    g = sparse.coo_matrix((np.ones(len(ce)), (ce[:, 0], ce[:, 1])), shape=(nmax, nmax)).tocsr()
    g = g + g.T
    ncomp, lab_v = connected_components(g, directed=False)
    if len(np.unique(lab_v[verts])) != 1:
        raise ImprintError(f"{name}: the imprinted curve is broken into pieces; use a smaller --size")
    start = int(ends.min()) if len(ends) else int(verts.min())
    order = depth_first_order(g, start, directed=False, return_predecessors=False)
    return order.astype(np.int64)


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
        dist = np.linalg.norm(x - qq[:, None, :], axis=2)
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
    """Split faces that still contain an edge which received a new node (faces outside the
    cut region sharing a crossed edge), keeping the mesh conforming."""
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
    if not hit.any():
        return T, C
    rows = np.flatnonzero(hit.any(1))
    if (hit[rows].sum(1) > 1).any():
        raise ImprintError("a skin triangle outside the imprint region has two cut edges; "
                           "use a smaller --size")
    col = np.argmax(hit[rows], axis=1)
    f = T[rows]
    idx = (col[:, None] + np.arange(3)[None]) % 3
    f = np.take_along_axis(f, idx, 1)                       # edge f0-f1 is the cut one
    m = node[pos[rows, col]]
    new = np.vstack([np.stack([f[:, 0], m, f[:, 2]], 1), np.stack([m, f[:, 1], f[:, 2]], 1)])
    keep = np.ones(len(T), bool)
    keep[rows] = False
    return np.vstack([T[keep], new]), np.concatenate([C[keep], C[rows], C[rows]])


def imprint_chains(skin: ShellMesh, surface_points: np.ndarray, surface_tris: np.ndarray, chains,
                   snap: float = 0.25, tol: float = 1e-9):
    """Imprint every chain of ``chains`` (list of :class:`ChainSpec`) into the triangle
    ``skin`` (vertices on the input surface given by ``surface_points``/``surface_tris``).

    Returns ``(mesh, results)``: the imprinted skin (feature edges of each chain tagged with
    the member's component id, chain vertices fixed) and one :class:`ChainResult` per chain.
    """
    if skin.n_quads:
        raise ImprintError("imprint works on a triangle skin; got quads (run it before merging)")
    diag = float(np.linalg.norm(surface_points.max(0) - surface_points.min(0)))
    eps = tol * diag
    # 1. exact arcs on the input surface
    arcs = [section_arc(surface_points, surface_tris, c.plane, c.bounds, seed=c.seed, seed_tri=c.seed_tri,
                        name=f"{c.member} ({c.side})") for c in chains]
    # 2. crossing points = ends of open arcs, deduplicated
    ends = [a.points[[0, -1]] for a in arcs if not a.closed]
    arc_end_rows = {}
    row = 0
    for i, a in enumerate(arcs):
        if not a.closed:
            arc_end_rows[i] = (row, row + 1)
            row += 2
    P, T, C = skin.points.copy(), skin.faces[:, :3].copy(), skin.component.copy()
    names = list(skin.component_names)
    fixed = np.zeros(len(P), bool)
    fixed[skin.fixed_vertices] = True
    fe = [skin.feature_edges]
    fid = [skin.feature_edge_ids]
    feat_v = np.zeros(len(P), bool)
    feat_v[skin.feature_edges.ravel()] = True
    cross_ids = np.zeros(0, np.int64)
    if ends:
        X = np.vstack(ends)
        tree = cKDTree(X)
        pairs = tree.query_pairs(eps, output_type="ndarray")
        rep = np.arange(len(X))
        for i, j in sorted(map(tuple, pairs)):        # few points: crossing points of members
            rep[max(i, j)] = min(rep[i], rep[j])
        uniq = np.unique(rep)
        rep_pos = np.searchsorted(uniq, rep)             # row of X -> index into uniq/cross_ids
        cross_ids = np.empty(len(uniq), np.int64)
        for k, u in enumerate(uniq):
            movable = ~(fixed | feat_v)
            movable = np.concatenate([movable, np.zeros(max(0, len(P) - len(movable)), bool)])
            P, T, C, vid = insert_point(P, T, C, X[u], movable)
            cross_ids[k] = vid
            fixed = np.concatenate([fixed, np.zeros(len(P) - len(fixed), bool)])
            feat_v = np.concatenate([feat_v, np.zeros(len(P) - len(feat_v), bool)])
            fixed[vid] = True
    results = []
    for ci, (spec, arc) in enumerate(zip(chains, arcs)):
        member_id = names.index(spec.member) if spec.member in names else (names.append(spec.member) or len(names) - 1)
        on = np.zeros(len(P), bool)
        if len(cross_ids):
            xs = cross_ids[np.abs(spec.plane.side(P[cross_ids])) <= eps]
            on[xs] = True
        movable = ~(fixed | feat_v)
        endv = None
        if ci in arc_end_rows:
            endv = cross_ids[rep_pos[list(arc_end_rows[ci])]]
        P, T, C, chain_v, (split_e, new_n) = cut_chain(P, T, C, spec, arc, movable, on, snap=snap,
                                                       end_vertices=endv)
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
        results.append(ChainResult(spec.member, spec.side, chain_v, arc))
    mesh = ShellMesh(P, T, C, names, np.flatnonzero(fixed), np.vstack(fe), np.concatenate(fid))
    return mesh, results


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
