"""Chain refinement and coarsening: chain edges split where the exact curve bulges away from them
(:func:`refine_chains`, bounded by :func:`chain_depths`), and chains coarsened toward the skin's
spacing by collapsing interior chain vertices (:func:`coarsen_chains`)."""
from __future__ import annotations

import numpy as np

from ..core.polyline import closest_on_polyline
from ..core.kernels import greedy_independent
from ..mesh import ShellMesh, norm_rows, unique_edges, vertex_faces
from ..options import ImprintOptions
from .common import edge_keys, has_edge, min_angles_small, polyline_param, ranges, unit_normals
from .cut import split_feature_edges, split_hanging
from .improve import flip_round, improve_skin
from .repair import CHAIN, FREE, skin_roles

__all__ = ["chain_depths", "refine_chains", "coarsen_chains"]


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
                  depth_fraction: float = ImprintOptions.chain_depth_deviation) -> ShellMesh:
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
    its exact section). The imprint stage (:func:`~shellmesh_mdao.imprint.imprint_mesh`) runs
    this when the solver option ``chain_deviation`` is above 0 (a fraction of the remesh edge
    length), with ``depth_fraction`` the option ``chain_depth_deviation`` (its default, 0 turns
    the depth bound off; :class:`~shellmesh_mdao.options.ImprintOptions`)."""
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
            sv = polyline_param(P[v], A, cum)
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
        T, C = split_hanging(P, T, C, E, new_id)
        fe, fid = split_feature_edges(fe, fid, E, new_id)
        fixed += new_id.tolist()
        w_chain, w_pos = np.concatenate(w_chain), np.concatenate(w_pos)
        for ci in np.unique(w_chain):           # new vertex after position e of its chain
            m = w_chain == ci
            chains[ci].vertices = np.insert(np.asarray(chains[ci].vertices, np.int64), w_pos[m] + 1, new_id[m])
    return ShellMesh(P, T, C, list(mesh.component_names), np.unique(np.asarray(fixed, np.int64)), fe, fid)


# ----------------------------------------------------------------------------- chain coarsening
# Cutting the skin along a member's plane puts a chain vertex wherever the plane crosses a skin
# edge, so chains come out 2-3 times finer than the skin (and the members meshed on them with
# them). coarsen_chains removes interior chain vertices by collapsing each into a chain
# neighbour (the survivor keeps its exact position), in vectorised rounds over an independent
# set of candidates, each collapse checked locally (link condition, orientation, angles).
_COS_TURN = np.cos(np.radians(45.0))


def _collapse_checks(P, T, C, ptr, star, ekeys, v, u):
    """Validity of collapsing each vertex v into its neighbour u (u keeps its position), and
    the star's smallest angle before and after: ``(ok, old_min, new_min)``. ok requires a
    closed manifold star around v of one component, edge v-u shared by exactly two faces,
    the link condition (v and u have exactly the two common neighbours opposite v-u), and no
    remaining face degenerate or turned more than 45 degrees."""
    n, k = len(P), len(v)
    cnt = ptr[v + 1] - ptr[v]
    rows = np.repeat(np.arange(k), cnt)
    fs = star[ranges(ptr[v], ptr[v + 1])]
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
    link = has_edge(ekeys, u[rows], nxt, n) & (nxt != u[rows])
    ok &= np.bincount(rows, weights=link, minlength=k) == 2
    cmin = np.full(k, np.iinfo(np.int64).max)
    cmax = np.full(k, np.iinfo(np.int64).min)
    np.minimum.at(cmin, rows, C[fs].astype(np.int64))
    np.maximum.at(cmax, rows, C[fs].astype(np.int64))
    ok &= cmin == cmax
    X = P[tri]
    old_min = np.full(k, np.inf)
    np.minimum.at(old_min, rows, min_angles_small(X))
    new = np.where(is_v, u[rows, None], tri)
    Xn = P[new]
    ang = np.where(has_u, np.inf, min_angles_small(Xn))
    turn = (np.einsum("ij,ij->i", unit_normals(Xn), unit_normals(X)) <= _COS_TURN) & ~has_u
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
    fa = star[ranges(ptr[v], ptr[v + 1])]
    fb = star[ranges(ptr[u], ptr[u + 1])]
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
                   max_deviation: float | None = None, keep=None, improve: bool = True,
                   size_field=None) -> ShellMesh:
    """Coarsen the imprinted chains towards the spacing ``target`` (the skin edge length; where a
    ``size_field``, a :class:`~shellmesh_mdao.core.sizefield.SizeField` in the same units, asks for
    less, that local size).

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
                kind, _co = skin_roles(n, fe, fid, fixed, chain_vs, arcs)
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
                        pos = pos[(kind[arr[pos]] == CHAIN) & ~hold[arr[pos]]]
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
                    lim = lmax if size_field is None else max_ratio * size_field.at(0.5 * (P[w] + P[u]), target)
                    sel = (prio <= lim) & (dv <= dmax)
                    v, u, w, prio, cix, pos, dv = v[sel], u[sel], w[sel], prio[sel], cix[sel], pos[sel], dv[sel]
                else:
                    on_chain = np.zeros(n, bool)
                    for arr in chain_vs:
                        on_chain[arr] = True
                    ek = unique_edges(T.ravel(), np.roll(T, -1, 1).ravel())
                    a, b = ek[:, 0], ek[:, 1]
                    v = np.concatenate([a, b])
                    u = np.concatenate([b, a])
                    sel = (kind[v] == FREE) & ~fixed[v] & ~hold[v] & on_chain[u]
                    v, u = v[sel], u[sel]
                    prio = norm_rows(P[v] - P[u], axis=1)
                    sel = prio < near * (float(target) if size_field is None else size_field.at(P[u], target))
                    v, u, prio = v[sel], u[sel], prio[sel]
                    w = cix = pos = dv = np.zeros(len(v), np.int64)
                if not len(v):
                    break
                ptr, star = vertex_faces(T, n)
                ekeys = edge_keys(T, n)
                ok, old_min, new_min = _collapse_checks(P, T, C, ptr, star, ekeys, v, u)
                if phase == 0:
                    ok &= ~has_edge(ekeys, u, w, n)          # chain stays a simple path
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
                T, _nf = flip_round(P, T, fe)
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
    x = orig[ranges(i0, i1 + 1) % m0]
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
