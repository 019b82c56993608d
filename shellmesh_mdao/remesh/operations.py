"""The remesher's batched edge operations: splits (:func:`split_round`), collapses
(:func:`collapse_round`, :func:`micro_round` and the clean-ups, all through
:func:`collapse_edges`), flips (:func:`flip_round`), the facing test (:func:`faces_facing_ok`)
and :func:`phase`, which repeats one of them until it stalls."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..core.kernels import greedy_independent
from .kernels import (collapse_apply, collapse_directions, collapse_select, edge_lengths, facing_ok, flip_candidates,
                      greedy_independent_rings)
from ..mesh import cross_rows, dot_norm_rows, dot_rows, dot_unit_rows
from .common import (CHAIN, COLLAPSE_RATIO, CORNER, COS_FACING, COS_TURNED, REGULAR, SPLIT_RATIO, csr_entries,
                     min_angle_of, rank_candidates, tri_angles, tri_min_angle, tri_normals)

__all__ = ["faces_facing_ok", "micro_round", "split_round", "collapse_round", "chain_keeps", "collapse_edges",
           "flip_round", "phase"]

# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


def faces_facing_ok(W, ctx, Fn, nrm):
    """Faces (k, 3) with unit normals ``nrm``: True unless the face has regular corners and
    its normal is more than 80 degrees from the input normal at every one of them (a face
    standing across the surface, e.g. through a thin wing from the upper to the lower skin)."""
    return facing_ok(Fn, W.kind, W.vtri, ctx.tri_n, nrm, COS_FACING)


def micro_round(W, ctx, eps):
    """Collapse edges shorter than ``eps`` times the local size (tiny input details, slivers
    left next to corners) with the topological tests and an inversion test against the
    input normals only: such a short move cannot fold the surface at the mesh scale."""
    T = W.topo()
    E = T.E
    L = edge_lengths(W.P, E)
    he = 0.5 * (W.h[E[:, 0]] + W.h[E[:, 1]])
    cand = np.flatnonzero(L < eps * he)
    if not len(cand):
        return 0
    return collapse_edges(W, ctx, T, cand, prio=-L[cand], check_geometry=False)


def _across_ridge(ctx, pa, pb, mid, nrm, fn0, patch, pts, tri, ok):
    """Split points of forced splits (deviation splits, corner openings) of edges
    ``pa``-``pb`` whose closest point ``pts`` lands within a quarter of the edge of one of its
    ends, or that found no compatible triangle (``ok`` False); the split would be refused
    there: an edge across a ridge narrower than itself (a dorsal fin, a fairing) has its
    midpoint inside the ridge, closest to a wall at the edge's foot. Such an edge takes the
    nearest surface point, within the edge's length, on the line through its midpoint along
    the faces' mean normal ``nrm``
    (for a folded pair, whose normals cancel, along the first face's in-plane direction
    across the edge), in the same feature patch. Returns the updated ``(pts, tri, ok)``."""
    L = _norm(pb - pa)
    redo = np.flatnonzero((np.minimum(_norm(pts - pa), _norm(pts - pb)) <= 0.25 * L) | ~ok)
    if not len(redo):
        return pts, tri, ok
    across = _unit(cross_rows(fn0[redo], _unit(pb[redo] - pa[redo])))
    d = np.where((_norm(nrm[redo]) < 0.5)[:, None], across, _unit(nrm[redo]))
    k = len(redo)
    hit, htri, hd = ctx.loc.raycast(np.vstack([mid[redo], mid[redo]]), np.vstack([d, -d]))
    hd = hd.reshape(2, k)
    side = np.argmin(hd, axis=0)                      # the nearer of the two directions
    j = side * k + np.arange(k)
    dist = hd[side, np.arange(k)]
    good = np.isfinite(dist) & (dist <= L[redo])
    if ctx.use_patch:
        good &= ctx.surf.tri_patch[np.maximum(htri[j], 0)] == patch[redo]
    g = redo[good]
    pts, tri, ok = pts.copy(), tri.copy(), ok.copy()
    pts[g] = hit[j[good]]
    tri[g] = htri[j[good]]
    ok[g] = True
    return pts, tri, ok


#: a split's new point lands on another vertex when closer to it than this fraction of its scale
#: (the smaller of its edge's length and the local size asked for): points that coincide (1e-15
#: apart where projections meet); a bound of 0.05 also stops splits the mesh needs (random family
#: seed 0 then keeps elements below scaled Jacobian 0.2)
LANDING = 1e-3


def _lands_on_vertex(X, scale, own, P, neighbours=4):
    """The new points ``X`` (k, 3) closer than ``LANDING * scale`` to a vertex of ``P`` other than
    the vertices ``own`` (k, m) of the faces they split (those have their own rules), or to an
    earlier (lower-index) new point, among their ``neighbours`` nearest."""
    d, j = cKDTree(P).query(X, k=min(neighbours, len(P)))
    d, j = d.reshape(len(X), -1), j.reshape(len(X), -1)
    mine = (j[:, :, None] == own[:, None, :]).any(axis=2)
    out = ((d < LANDING * scale[:, None]) & ~mine).any(axis=1)
    if len(X) > 1:
        d, j = cKDTree(X).query(X, k=min(neighbours + 1, len(X)))
        near = d < LANDING * np.minimum(scale[:, None], scale[np.minimum(j, len(X) - 1)])
        out |= ((j < np.arange(len(X))[:, None]) & near).any(axis=1)
    return out


def split_round(W, ctx, forced=None, min_angle_guard=0.0, deviation=None):
    """Split, in one batch, the longest edges (> 4/3 local size), at most one per face
    (or the edges ``forced``; ``deviation``: the distance of every edge's midpoint to the
    input, when the caller has it)."""
    T = W.topo()
    E = T.E
    P = W.P
    L = edge_lengths(P, E)
    he = 0.5 * (W.h[E[:, 0]] + W.h[E[:, 1]])
    cand = np.flatnonzero(L > SPLIT_RATIO * he) if forced is None else np.unique(forced)
    if not len(cand):
        return 0
    rank = rank_candidates(np.round(L[cand] / he[cand], 1), cand)
    f0 = T.h0[cand] // 3
    h1 = T.h1[cand]
    f1 = np.where(h1 >= 0, h1 // 3, -1)
    v1 = f1 >= 0
    owner = np.concatenate([np.arange(len(cand)), np.flatnonzero(v1)])
    res = np.concatenate([f0, f1[v1]])
    win = greedy_independent(owner, res, rank, len(W.F))
    sel = cand[win]
    f0, f1 = f0[win], f1[win]
    isf, ech = W.feature_lookup(T)
    a, b = E[sel, 0], E[sel, 1]
    k = len(sel)
    newP = np.empty((k, 3))
    newkind = np.zeros(k, np.int8)
    newS = np.full(k, np.nan)
    newch = np.full(k, -1, np.int64)
    newtri = np.full(k, -1, np.int64)
    ok = np.ones(k, bool)
    fm = isf[sel]
    if fm.any():
        c = ech[sel[fm]]
        aa, bb = a[fm], b[fm]
        # arc coordinates of both ends on chain c
        Sa0 = np.where(W.kind[aa] == CHAIN, W.S[aa], np.nan)
        Sb0 = np.where(W.kind[bb] == CHAIN, W.S[bb], np.nan)
        nearA = np.where(np.isnan(Sb0), ctx.surf.ch_off[c], Sb0)
        Sa = ctx.chain_S_of(W, aa, c, nearA)
        Sb = ctx.chain_S_of(W, bb, c, np.where(np.isnan(Sa0), Sa, Sa0))
        d = ctx.chain_delta(c, Sb - Sa)
        pts, _, Sm = ctx.surf.chain_point(Sa + 0.5 * d, c)
        newP[fm] = pts
        newkind[fm] = CHAIN
        newS[fm] = Sm
        newch[fm] = c
    rm = ~fm
    if rm.any():
        mid = 0.5 * (P[a[rm]] + P[b[rm]])
        fn = W.face_normals()
        nrm = fn[f0[rm]] + np.where((f1[rm] >= 0)[:, None], fn[np.maximum(f1[rm], 0)], 0.0)
        pts, tri, okr = ctx.project(mid, _unit(nrm), W.fpatch[f0[rm]], hint=W.vtri[a[rm]])
        if forced is not None:
            pts, tri, okr = _across_ridge(ctx, P[a[rm]], P[b[rm]], mid, nrm, fn[f0[rm]],
                                          W.fpatch[f0[rm]], pts, tri, okr)
        newP[rm] = pts
        newtri[rm] = tri
        ok[rm] = okr
    # the new point must split the edge into two real parts (a projection landing on an
    # end point, e.g. across a thin region, would split forever)
    ok &= np.minimum(_norm(newP - P[a]), _norm(newP - P[b])) > 0.25 * L[sel]
    # nor be carried onto the vertex across the edge by its projection (through a tip cap
    # thinner than the edge it lands on the far side's vertex: a zero-length edge, two
    # coincident nodes); a sliver whose far vertex lies near the edge's midpoint is split
    mid_all = 0.5 * (P[a] + P[b])
    for hh in (T.h0[sel], T.h1[sel]):
        hv = np.maximum(hh, 0)
        pc = P[W.F[hv // 3, (hv % 3 + 2) % 3]]
        ok &= (hh < 0) | (_norm(newP - pc) > 0.25 * _norm(mid_all - pc))
    # nor land on another vertex, old or new: a midpoint whose projection jumps (across a nose or a
    # tip corner tighter than the edge) can reach a vertex already there or the landing point of
    # another split (every point of a convex input vertex's normal cone projects onto it), and
    # coincident nodes feed further splits without end (random family seed 4, a fin's 15 mm nose)
    if (~fm).any():
        r = np.flatnonzero(~fm)
        far = [np.where(hh >= 0, W.F[np.maximum(hh, 0) // 3, (np.maximum(hh, 0) % 3 + 2) % 3], a)
               for hh in (T.h0[sel], T.h1[sel])]
        own = np.stack([a, b] + far, axis=1)
        scale = np.minimum(L[sel], 0.5 * (W.h[a] + W.h[b]))
        ok[r] &= ~_lands_on_vertex(newP[r], scale[r], own[r], P)
    if forced is not None and min_angle_guard > 0:
        # forced (deviation) splits: none of the four new triangles may fall below
        # min(min_angle_guard, half the smallest angle of the triangle it replaces), unless
        # the edge is more than twice max_deviation off the input (faces spanning a ridge
        # narrower than themselves, standing across it: their angles mean nothing there)
        F0 = W.F
        dsel = deviation[sel] if deviation is not None else ctx.loc.closest(0.5 * (P[a] + P[b]))[2]
        gross = dsel > 2.0 * ctx.delta
        for hh in (T.h0[sel], T.h1[sel]):
            valid = hh >= 0
            hv = np.maximum(hh, 0)
            f, sd = hv // 3, hv % 3
            va, vb, vc = F0[f, sd], F0[f, (sd + 1) % 3], F0[f, (sd + 2) % 3]
            old = tri_min_angle(P[va], P[vb], P[vc])
            new1 = tri_min_angle(P[va], newP, P[vc])
            new2 = tri_min_angle(newP, P[vb], P[vc])
            ok &= ~valid | gross | (np.minimum(new1, new2) >= np.minimum(min_angle_guard, 0.5 * old))
            # and none of them may turn over: a normal more than 100 degrees from the input
            # normal at the new point (a split across a nose much tighter than the edge, whose
            # projected midpoint lands beside the two faces instead of between them)
            if rm.any():
                tn = ctx.tri_n[np.maximum(newtri, 0)]
                for t3 in ((P[va], newP, P[vc]), (newP, P[vb], P[vc])):
                    nn = _unit(cross_rows(t3[1] - t3[0], t3[2] - t3[0]))
                    ok &= ~valid | fm | (newtri < 0) | (_dot(nn, tn) > COS_TURNED)
    if not ok.all():
        sel, f0, f1, a, b = sel[ok], f0[ok], f1[ok], a[ok], b[ok]
        newP, newkind, newS, newch, newtri = newP[ok], newkind[ok], newS[ok], newch[ok], newtri[ok]
        fm = fm[ok]
        k = len(sel)
        if not k:
            return 0
    n = W.n
    ids = n + np.arange(k)
    hs = np.concatenate([T.h0[sel], T.h1[sel]])
    mids = np.concatenate([ids, ids])
    valid = hs >= 0
    hs, mids = hs[valid], mids[valid]
    f = hs // 3
    s = hs % 3
    F = W.F
    va = F[f, s]
    vb = F[f, (s + 1) % 3]
    vc = F[f, (s + 2) % 3]
    F2 = F.copy()
    F2[f] = np.stack([va, mids, vc], 1)
    W.F = np.vstack([F2, np.stack([mids, vb, vc], 1)])
    W.fpatch = np.concatenate([W.fpatch, W.fpatch[f]])
    W.P = np.vstack([P, newP])
    W.kind = np.concatenate([W.kind, newkind])
    W.S = np.concatenate([W.S, newS])
    W.vchain = np.concatenate([W.vchain, newch])
    W.vin = np.concatenate([W.vin, np.full(k, -1, np.int64)])
    W.vtri = np.concatenate([W.vtri, newtri])
    W.h = np.concatenate([W.h, np.zeros(k)])
    W.h[ids] = ctx.sizing(W, ids)
    if fm.any():
        e_old = np.stack([a[fm], b[fm]], 1)
        old_keys = e_old[:, 0] * (n + k) + e_old[:, 1]
        fk = W.fe[:, 0] * (n + k) + W.fe[:, 1]
        keep = ~np.isin(fk, old_keys)
        ch = newch[fm]
        add = np.vstack([np.stack([a[fm], ids[fm]], 1), np.stack([ids[fm], b[fm]], 1)])
        W.set_features(np.vstack([W.fe[keep], add]), np.concatenate([W.fe_chain[keep], ch, ch]))
    W.touched()
    return k


def collapse_round(W, ctx, max_normal_turn=45.0, quality=False):
    """Collapse, in one batch, short edges (< 4/5 local size) with disjoint neighbourhoods."""
    T = W.topo()
    E = T.E
    P = W.P
    L = edge_lengths(P, E)
    he = 0.5 * (W.h[E[:, 0]] + W.h[E[:, 1]])
    prio = np.where(L < COLLAPSE_RATIO * he, -(L / he), -np.inf)
    # regular vertices of valence 3 (a vertex inside a triangle of its neighbours) are
    # removed along their shortest edge whatever its length: they block collapses around
    nptr, nbr = T.vertex_neighbors()
    deg = np.diff(nptr)
    v3 = np.flatnonzero((deg == 3) & (W.kind == REGULAR))
    # a feature-line end (degree 1 in the feature graph) left with valence 3 sits in a
    # sliver fan (a sharp trailing edge fading into a tight tip fold): it gives way to
    # its neighbour on the line, which becomes the new end
    fdeg = np.bincount(W.fe.reshape(-1), minlength=W.n) if len(W.fe) else np.zeros(W.n, np.int64)
    dang = np.flatnonzero((deg == 3) & (W.kind == CORNER) & (fdeg == 1))
    if len(dang):
        ends = W.fe.reshape(-1)
        other = W.fe[:, ::-1].reshape(-1)
        pos = np.searchsorted(np.sort(ends), dang)
        o = np.argsort(ends, kind="stable")
        nb = other[o[pos]]
        ed = T.lookup(dang, nb)
        ok = (ed >= 0) & (W.kind[nb] == CHAIN)
        prio[ed[ok]] = 1.0
        dang = dang[ok]
        v3 = np.concatenate([v3, dang])
    if len(v3) and (W.kind[v3] == REGULAR).any():
        v3r = v3[W.kind[v3] == REGULAR]
        nb = nbr[nptr[v3r][:, None] + np.arange(3)[None, :]]
        d = np.sqrt(((P[nb] - P[v3r][:, None, :]) ** 2).sum(-1))
        e3 = T.lookup(v3r, nb[np.arange(len(v3r)), np.argmin(d, axis=1)])
        prio[e3] = 1.0
    cand = np.flatnonzero(np.isfinite(prio))
    if not len(cand):
        return 0
    return collapse_edges(W, ctx, T, cand, prio=prio[cand], max_normal_turn=max_normal_turn,
                           quality=quality, remove_first=v3)


def chain_keeps(W, ctx):
    """Per vertex: not on a chain, or its chain keeps enough vertices without it (a closed chain
    three, a chain through one corner two)."""
    ok = np.ones(W.n, bool)
    s = ctx.surf
    if s is not None and s.n_chains:
        cv = W.kind == CHAIN
        cnt = np.bincount(W.vchain[cv], minlength=s.n_chains)
        need = np.where(s.ch_closed, 3, np.where(s.ch_first_v == s.ch_last_v, 2, 0))
        ok[cv] = cnt[W.vchain[cv]] > need[W.vchain[cv]]
    return ok


def collapse_edges(W, ctx, T, cand, prio, max_normal_turn=45.0, quality=False, max_len_ratio=SPLIT_RATIO,
                    remove_first=None, check_geometry=True):
    """Collapse a maximal independent set of the candidate edges ``cand`` (higher ``prio``
    first). Cheap topological tests run on all candidates; the geometric tests only on
    the candidates that win their neighbourhood in a selection sub-round: the sweeps' tests
    (new edges against the local size, normal turn, facing, smallest angle), or with
    ``check_geometry=False`` the facing tests only, both in the compiled selection
    (:func:`~shellmesh_mdao.remesh.kernels.collapse_select`); with ``quality=True`` (the clean-up:
    the smallest angle must rise, new edges within max_deviation) in numpy, called back each
    sub-round."""
    if quality and not check_geometry:
        raise ValueError("collapse_edges: the clean-up's quality tests include the geometric ones")
    E = T.E
    P = W.P
    n = W.n
    F = W.F
    isf, _ = W.feature_lookup(T)
    nptr, nbr = T.vertex_neighbors()
    fptr, vf = T.vertex_faces(F)
    chain_ok_v = chain_keeps(W, ctx)
    # ---- cheap tests: opposite valences, link condition, no pinching, vertex kinds (dangling
    #      feature-line ends listed in remove_first may go along their line; an edge at a
    #      vertex to be removed may only remove that vertex), in one compiled pass
    u, v = E[cand, 0], E[cand, 1]
    _, dir_ok = collapse_directions(E, cand, T.h0, T.h1, T.valence, F, nptr, nbr, W.kind, isf, chain_ok_v,
                                     remove_first=remove_first)
    alive = dir_ok[:, 0] | dir_ok[:, 1]
    if not alive.any():
        return 0
    fn_old = _unit(tri_normals(P, F)) if check_geometry else None     # the facing tests need no normal turn
    cos_turn = np.cos(np.radians(max_normal_turn))

    def allowed_only(a, b, okd):
        """:func:`geometric` run on the pairs ``okd`` allows only, inf for the others (they get
        inf whatever the costly tests find; each pair's answer does not depend on the others)."""
        out = np.full(len(a), np.inf)
        keep = np.flatnonzero(okd)
        if len(keep):
            out[keep] = geometric(a[keep], b[keep], okd[keep])
        return out

    def geometric(a, b, okd):
        """rmax (inf where invalid) of collapsing vertex ``a`` into ``b`` (arrays; ``okd``: the
        collapses the cheap tests allow), each pair on its own."""
        k = len(a)
        okd = okd.copy()
        ow, pos = csr_entries(nptr, a)
        xx = nbr[pos]
        m = xx != b[ow]
        ow, xx = ow[m], xx[m]
        r = _norm(P[xx] - P[b[ow]]) / (0.5 * (W.h[xx] + W.h[b[ow]]))
        rmax = np.zeros(k)
        np.maximum.at(rmax, ow, r)
        okd &= rmax <= max_len_ratio
        if not okd.all():
            return allowed_only(a, b, okd)
        ow, pos = csr_entries(fptr, a)
        ff = vf[pos]
        Fa = F[ff]
        Q0 = P[Fa]
        amin_old = np.full(k, np.inf)
        np.minimum.at(amin_old, ow, tri_min_angle(Q0[:, 0], Q0[:, 1], Q0[:, 2]))
        m = ~(Fa == b[ow][:, None]).any(1)
        ow, ff, Fa, Q = ow[m], ff[m], Fa[m], Q0[m]
        isa = Fa == a[ow][:, None]
        Q = np.where(isa[:, :, None], P[b[ow]][:, None, :], Q)
        nn = cross_rows(Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0])
        area = _norm(nn)
        cosn = _dot(_unit(nn), fn_old[ff])
        cmin = np.full(k, np.inf)
        np.minimum.at(cmin, ow, np.where(area > 1e-30 * W.h[b[ow]] ** 2, cosn, -2.0))
        okd &= cmin > cos_turn
        Fb = np.where(isa, b[ow][:, None], Fa)
        okd &= ~(np.bincount(ow, weights=~faces_facing_ok(W, ctx, Fb, _unit(nn)), minlength=k) > 0)
        # the smallest new angle strictly above the smallest old one
        amin_new = np.full(k, np.inf)
        np.minimum.at(amin_new, ow, tri_min_angle(Q[:, 0], Q[:, 1], Q[:, 2]))
        okd &= amin_new > amin_old
        if ctx.delta is not None and okd.any():
            # clean-up collapses must keep the new edges within max_deviation
            ow2, pos2 = csr_entries(nptr, a)
            xx2 = nbr[pos2]
            m2 = (xx2 != b[ow2]) & okd[ow2]
            ow2, xx2 = ow2[m2], xx2[m2]
            _, _, dd = ctx.loc.closest(0.5 * (P[xx2] + P[b[ow2]]))
            _, _, d0 = ctx.loc.closest(0.5 * (P[xx2] + P[a[ow2]]))
            # within max_deviation, or no worse than the edges they replace
            lim = np.full(k, ctx.delta)
            np.maximum.at(lim, ow2, d0)
            okd &= ~(np.bincount(ow2, weights=dd > lim[ow2], minlength=k) > 0)
        return np.where(okd, rmax, np.inf)

    # ---- greedy independent set over lock regions (closed 1-rings of both ends),
    #      validating the winners of each sub-round geometrically
    acc_a, acc_b = [], []

    def check(win):
        # both directions of every winner in one batch (u -> v first, then v -> u)
        sc = geometric(np.concatenate([u[win], v[win]]), np.concatenate([v[win], u[win]]),
                       np.concatenate([dir_ok[win, 0], dir_ok[win, 1]])).reshape(2, -1).T
        good = np.isfinite(sc).any(1)
        if good.any():
            w, s = win[good], sc[good]
            d = np.argmin(s, axis=1)           # ties: remove u (the smaller index)
            acc_a.append(np.where(d == 0, u[w], v[w]))
            acc_b.append(np.where(d == 0, v[w], u[w]))
        return good

    if not quality:
        # the sweeps' and the micro collapses: the selection and the tests in one compiled pass
        a, b = collapse_select(nptr, nbr, fptr, vf, F, P, W.h, u, v, rank_candidates(prio, cand), dir_ok, kind=W.kind,
                               vtri=W.vtri, tri_n=ctx.tri_n, cos_facing=COS_FACING, max_len_ratio=max_len_ratio,
                               fn_old=fn_old, cos_turn=cos_turn,
                               surface=None if check_geometry else ctx.loc.compiled_tree(), max_sub=16)
        if not len(a):
            return 0
    else:
        greedy_independent_rings(nptr, nbr, u, v, rank_candidates(prio, cand), alive=alive, check=check, max_sub=16)
        if not acc_a:
            return 0
        a = np.concatenate(acc_a)
        b = np.concatenate(acc_b)
    # faces, feature edges (as set_features tabulates them) and vertex numbering after the
    # batch, in one compiled pass; then the per-vertex arrays without the removed vertices
    W.F, W.fpatch, W.fe, W.fe_chain, keepv = collapse_apply(F, W.fpatch, W.fe, W.fe_chain, a, b, n)
    W.keep_vertices(keepv)
    return len(a)


def flip_round(W, ctx, mode):
    """Flip, in one batch, interior non-feature edges of nearly coplanar triangle pairs.

    mode 'valence': flips that bring vertex valences closer to 6 (4 on open boundaries)
    without halving the smallest angle; mode 'angle': flips that raise the smallest angle
    of the pair."""
    T = W.topo()
    E = T.E
    F = W.F
    P = W.P
    isf, _ = W.feature_lookup(T)
    deg = tgt = None
    if mode == "valence":
        nptr, _ = T.vertex_neighbors()
        deg = np.diff(nptr).astype(np.float64)
        # target valence from the angle sum around the vertex (6 on smooth regions and
        # at feature-line ends, fewer at cone-like corners; +1 on open boundaries)
        ang = np.radians(tri_angles(P, F))
        asum = np.zeros(W.n)
        for k in range(3):
            asum += np.bincount(F[:, k], weights=ang[:, k], minlength=W.n)
        tgt = np.clip(np.round(asum / (np.pi / 3.0)), 2.0, 9.0)
        bnd = T.valence == 1
        tgt[E[bnd].reshape(-1)] += 1.0
    # in one compiled pass (kernels.flip_candidates): c-d not an edge yet, one patch, the
    # valence gain (mode 'valence'), the old pair nearly coplanar, the new pair not folded over
    # the old one (both new faces turn by less than the allowed dihedral from both old faces)
    # nor standing across the input; the angles' arguments of all four faces
    cosmax = np.cos(np.radians(ctx.max_flip_dihedral))
    cand, abcd, ff, gain, m0, m1, sc = flip_candidates(E, T.kptr(), T.h0, T.h1, isf, F, W.fpatch, P, cosmax,
                                                       W.kind, W.vtri, ctx.tri_n, COS_FACING, deg, tgt)
    if not len(cand):
        return 0
    a, b, c, d = abcd.T
    f0, f1 = ff.T
    old = np.minimum(min_angle_of(sc[0]), min_angle_of(sc[1]))
    new = np.minimum(min_angle_of(sc[2]), min_angle_of(sc[3]))
    if mode == "valence":
        ok = new >= 0.5 * old
        prio = gain + 1e-3 * (new - old)
    else:
        gain = new - old
        ok = gain > 1e-3
        prio = gain
    if ctx.delta is not None and ok.any():
        # remeshing: the new edge must stay within max_deviation of the input, and the new
        # faces must face the way the input does where their centroids project
        k = np.flatnonzero(ok)
        Pa, Pb, Pc, Pd = P[a[k]], P[b[k]], P[c[k]], P[d[k]]
        mid = 0.5 * (Pc + Pd)
        C0 = (Pa + Pd + Pc) / 3.0
        C1 = (Pd + Pb + Pc) / 3.0
        # the new edge's midpoint and the new faces' centroids in one query (each answer is its
        # own), the search for each starting at c's input triangle
        nk = len(k)
        hc = W.vtri[c[k]]
        _, t3, d3 = ctx.loc.closest(np.vstack([mid, C0, C1]), hint=np.concatenate([hc, hc, hc]))
        dm, t0, t1 = d3[:nk], t3[nk:2 * nk], t3[2 * nk:]
        good = dm <= ctx.delta
        good &= (_dot(m0[k], ctx.tri_n[t0]) > 0) & (_dot(m1[k], ctx.tri_n[t1]) > 0)
        ok[k[~good]] = False
    if not ok.any():
        return 0
    sel = np.flatnonzero(ok)
    rank = rank_candidates(prio[sel], cand[sel])
    if mode == "valence":
        # valence gains assume the neighbours keep their valence: lock all four vertices
        quad = np.stack([a[sel], b[sel], c[sel], d[sel]], 1)
        win = greedy_independent(np.repeat(np.arange(len(sel)), 4), quad.reshape(-1), rank, W.n)
    else:
        win = greedy_independent(np.repeat(np.arange(len(sel)), 2),
                                 np.stack([f0[sel], f1[sel]], 1).reshape(-1), rank, len(F))
    sel, rank = sel[win], rank[win]
    # two flips of the batch must not create the same edge
    lo = np.minimum(c[sel], d[sel])
    hi = np.maximum(c[sel], d[sel])
    o = np.lexsort((-rank, hi, lo))
    firsto = np.ones(len(o), bool)
    firsto[1:] = (lo[o][1:] != lo[o][:-1]) | (hi[o][1:] != hi[o][:-1])
    sel = sel[np.sort(o[firsto])]
    if not len(sel):
        return 0
    F2 = F.copy()
    F2[f0[sel]] = np.stack([a[sel], d[sel], c[sel]], 1)
    F2[f1[sel]] = np.stack([d[sel], b[sel], c[sel]], 1)
    W.F = F2
    W.touched()
    return len(sel)



#: a face is degenerate when its height over its longest edge is below this fraction of that edge
DEGENERATE_HEIGHT = 1e-8


def _degenerate_faces(P, F):
    """Degenerate faces of ``F`` and, for each, the corner (0-2) at the start of its longest edge."""
    A, B, C = P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]
    L = np.stack([_norm(B - A), _norm(C - B), _norm(A - C)], 1)
    k = np.argmax(L, axis=1)
    lmax = L[np.arange(len(F)), k]
    deg = np.flatnonzero(_norm(cross_rows(B - A, C - A)) <= DEGENERATE_HEIGHT * lmax * lmax)
    return deg, k[deg], lmax[deg]


def degenerate_round(W, ctx):
    """Remove, in one batch, degenerate faces (three nodes in a line, as where the projections of
    several nodes meet on a crest of the input, a nose tighter than the edges; their normals are
    not defined, so no round of the sweeps removes them). The longest edge ``ab`` of such a face
    ``abc`` is flipped with the face ``bad`` across it: the two new faces are ``bad`` split at
    ``c``. Where ``d`` is on the line too (a flat pocket of two faces), the flip's new edge ``cd``
    is collapsed after it (the two faces vanish). Feature edges, open edges and flips whose new
    edge exists already are left. Returns the number of flips."""
    T = W.topo()
    F, P = W.F, W.P
    deg, k, lmax = _degenerate_faces(P, F)
    if not len(deg):
        return 0
    h = 3 * deg + k
    e = T.he_edge[h]
    other = np.where(T.h0[e] == h, T.h1[e], T.h0[e])
    isf, _ = W.feature_lookup(T)
    g, s = np.maximum(other, 0) // 3, np.maximum(other, 0) % 3
    a, b, c = F[deg, k], F[deg, (k + 1) % 3], F[deg, (k + 2) % 3]
    d = F[g, (s + 2) % 3]
    ok = (other >= 0) & ~isf[e] & (W.fpatch[g] == W.fpatch[deg]) & (c != d)
    ok &= T.lookup(c, d) < 0
    sel = np.flatnonzero(ok)
    if not len(sel):
        return 0
    rank = rank_candidates(lmax[sel], deg[sel])
    win = greedy_independent(np.repeat(np.arange(len(sel)), 2),
                             np.stack([deg[sel], g[sel]], 1).reshape(-1), rank, len(F))
    sel = sel[win]
    lo, hi = np.minimum(c[sel], d[sel]), np.maximum(c[sel], d[sel])
    o = np.lexsort((hi, lo))
    first = np.ones(len(o), bool)
    first[1:] = (lo[o][1:] != lo[o][:-1]) | (hi[o][1:] != hi[o][:-1])
    sel = sel[np.sort(o[first])]
    F2 = F.copy()
    F2[deg[sel]] = np.stack([a[sel], d[sel], c[sel]], 1)
    F2[g[sel]] = np.stack([d[sel], b[sel], c[sel]], 1)
    W.F = F2
    W.touched()
    # flat pockets: d on the line ab too; the flip's faces are degenerate as well: collapse cd
    pocket = _norm(cross_rows(P[b[sel]] - P[a[sel]], P[d[sel]] - P[a[sel]])) <= DEGENERATE_HEIGHT * lmax[sel] ** 2
    if pocket.any():
        T2 = W.topo()
        cd = T2.lookup(c[sel][pocket], d[sel][pocket])
        cd = np.unique(cd[cd >= 0])
        if len(cd):
            collapse_edges(W, ctx, T2, cd, prio=-edge_lengths(W.P, T2.E[cd]), max_normal_turn=60.0,
                           max_len_ratio=4.0)
    return len(sel)


def phase(fn, W, ctx, max_rounds, *args, **kw):
    """Repeat a batched operation until it stalls (fewer than 0.2 % of the faces changed
    per round; the next sweep takes up the rest after relaxation)."""
    total = 0
    for _ in range(max_rounds):
        k = fn(W, ctx, *args, **kw)
        total += k
        if k <= 0.002 * len(W.F):
            break
    return total
