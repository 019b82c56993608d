"""The remesher's repair of pinched stars (:func:`contract_pinched_stars`): a corner or chain node
with three or four neighbours whose star holds a sliver that no edge operation can remove, as at
the end of a sharp trailing edge in a wing tip thinner than the allowed deviation.

There the tip's cap is folded flat at the mesh scale: the remesh keeps one node on each side of
the cap next to the corner, and the face they make with the corner is a needle. Its short edge
(across the cap) cannot collapse, since both its ends are also neighbours of the corner's third
neighbour (the trailing edge's next node) and the corner would be left with two neighbours; the
corner's spokes cannot flip (each flip makes an edge that exists), a neighbour collapsed into
the corner alone flattens a face onto the trailing edge or turns one over, and the relaxation
cannot move the nodes of a face that lies across the thin cap. Collapsing several of the corner's
neighbours into it at once can: the corner keeps its place and its new neighbours are those of
the nodes removed."""
from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from ..core.kernels import greedy_independent
from ..mesh import dot_norm_rows, dot_rows, dot_unit_rows, reduce_short
from .common import CHAIN, COS_FACING, REGULAR, SPLIT_RATIO, csr_entries, rank_candidates, tri_angles, tri_normals
from .kernels import collapse_apply, edge_lengths
from .operations import chain_keeps, split_round

__all__ = ["contract_pinched_stars"]


def contract_pinched_stars(W, ctx, bad_angle=20.0, max_valence=4):
    """Collapse into each corner or chain node ``c`` with 3 to ``max_valence`` neighbours whose
    star has a triangle below ``bad_angle`` degrees the subset of its neighbours that raises the
    smallest angle of the faces around them most (``ctx`` a remesh context: its input surface
    projects).

    Every subset of the neighbours that may move to ``c`` is tried (regular nodes, and chain
    nodes along a feature edge to ``c`` whose chain keeps enough nodes). One is taken only when
    every node it touches keeps one closed fan of at least three faces (the link condition of a
    collapse, for several nodes at once), every feature edge stays an edge, every changed face
    has an input triangle of its patch facing its way (within 80 degrees) within
    ``max_deviation`` of its centroid (where the skins are closer than that, as in a thin tip,
    a face may have its nodes on either skin), the midpoints of the new spokes of ``c`` are
    within ``max_deviation`` of the input, and the smallest angle of the faces touched rises.
    The subsets of disjoint stars go in one batch; then the new spokes longer than the sweeps
    allow (4/3 of the local size) are split at their middle. Returns the number of nodes
    removed."""
    T = W.topo()
    F, P, n = W.F, W.P, W.n
    nptr, nbr = T.vertex_neighbors()
    deg = np.diff(nptr)
    amin = reduce_short(tri_angles(P, F), "min")
    smin = np.full(n, np.inf)
    np.minimum.at(smin, F.reshape(-1), np.repeat(amin, 3))
    cand = np.flatnonzero((W.kind != REGULAR) & (deg >= 3) & (deg <= max_valence) & (smin < bad_angle))
    if not len(cand):
        return 0
    nc, nv = len(cand), max_valence
    fptr, vf = T.vertex_faces(F)
    # ---- the candidates' neighbours in nv slots (-1 padded), and which of them may move there
    ow, pos = csr_entries(nptr, cand)
    slot = pos - nptr[cand][ow]
    link = np.full((nc, nv), -1, np.int64)
    link[ow, slot] = nbr[pos]
    isf, _ = W.feature_lookup(T)
    e = T.lookup(cand[ow], nbr[pos])
    along = (e >= 0) & isf[np.maximum(e, 0)] & chain_keeps(W, ctx)[nbr[pos]]
    mov = (W.kind[nbr[pos]] == REGULAR) | ((W.kind[nbr[pos]] == CHAIN) & along)
    movmask = np.zeros(nc, np.int64)
    np.bitwise_or.at(movmask, ow, np.where(mov, 1 << slot, 0))
    # ---- pairs (candidate, subset as a bit mask over the slots)
    pm = np.tile(np.arange(1, 1 << nv), nc)
    pc = np.repeat(np.arange(nc), (1 << nv) - 1)
    keep = (pm & ~movmask[pc]) == 0
    pc, pm = pc[keep], pm[keep]
    if not len(pc):
        return 0
    npair = len(pc)
    plink, pcen = link[pc], cand[pc]
    # ---- the faces around each candidate and its neighbours (once per candidate), per pair
    fo, fpos = csr_entries(fptr, np.concatenate([cand, nbr[pos]]))
    key = np.unique(np.concatenate([np.arange(nc), ow])[fo] * len(F) + vf[fpos])
    cptr = np.searchsorted(key // len(F), np.arange(nc + 1))
    ro, rpos = csr_entries(cptr, pc)
    rf = key[rpos] % len(F)
    Fr = F[rf]
    Fn, ncl = _remap(Fr, plink[ro], pm[ro], pcen[ro], nv)
    touched, kept = ncl >= 1, ncl == 1
    changed = kept & (Fn != Fr).any(1)
    ok = np.ones(npair, bool)
    # ---- the fans: c's after the collapse, and those of the nodes on a face that drops out
    kr = np.flatnonzero(kept)
    spokes = _fan_closed(ok, ro[kr], Fn[kr], pcen[ro[kr]], W.n)
    apex = Fr[ncl >= 2]
    apex_pair = np.repeat(ro[ncl >= 2], 3)
    apex = apex.reshape(-1)
    out = ~_in_subset(apex, plink[apex_pair], pm[apex_pair], nv) & (apex != pcen[apex_pair])
    xk = np.unique(apex_pair[out] * n + apex[out])
    xp, xv = xk // n, xk % n
    xo, xpos = csr_entries(fptr, xv)
    Xn, xcl = _remap(F[vf[xpos]], plink[xp[xo]], pm[xp[xo]], pcen[xp[xo]], nv)
    live = xcl <= 1
    xok = np.ones(len(xk), bool)
    _fan_closed(xok, xo[live], Xn[live], xv[xo[live]], W.n)
    ok[xp[~xok]] = False
    # ---- every feature edge at a node of the cluster stays an edge: a spoke of c
    if len(W.fe):
        eptr, erow = _vertex_rows(W.fe, n)
        members = np.concatenate([plink, pcen[:, None]], 1)
        eo, epos = csr_entries(eptr, np.maximum(members, 0).reshape(-1))
        ep = eo // (nv + 1)
        mine = (members.reshape(-1)[eo] >= 0) & (_in_subset(members.reshape(-1)[eo], plink[ep], pm[ep], nv)
                                                   | (eo % (nv + 1) == nv))
        ep, er = ep[mine], erow[epos[mine]]
        ends = [np.where(_in_subset(W.fe[er, k], plink[ep], pm[ep], nv), pcen[ep], W.fe[er, k]) for k in (0, 1)]
        live = ends[0] != ends[1]
        other = np.where(ends[0] == pcen[ep], ends[1], ends[0])[live]
        ok[ep[live][~np.isin(ep[live] * n + other, spokes)]] = False
    # ---- the changed faces: area, an input triangle of the face's patch facing its way (within
    #      80 degrees) within max_deviation of its centroid, angles
    cr = np.flatnonzero(changed & ok[ro])
    Fc = Fn[cr]
    An = tri_normals(P, Fc)
    nn = dot_unit_rows(An)
    cen = (P[Fc[:, 0]] + P[Fc[:, 1]] + P[Fc[:, 2]]) / 3
    q, _, found = ctx.surf.project(cen, nn, W.fpatch[rf[cr]] if ctx.use_patch else None, min_dot=COS_FACING,
                                   hint=W.vtri[Fc[:, 0]])
    bad = ~(dot_rows(An, An) > 0) | ~found | ~(dot_norm_rows(q - cen) <= ctx.delta)
    ok[ro[cr[bad]]] = False
    old_min = np.full(npair, np.inf)
    np.minimum.at(old_min, ro[touched], amin[rf[touched]])
    new_min = np.full(npair, np.inf)
    np.minimum.at(new_min, ro[kr], np.where(changed[kr], np.inf, amin[rf[kr]]))
    np.minimum.at(new_min, ro[cr], reduce_short(tri_angles(P, Fc), "min"))
    ok &= new_min > old_min
    # ---- the new spokes of c: midpoints within max_deviation of the input
    sp, sv = spokes // n, spokes % n
    new = ok[sp] & ~(plink[sp] == sv[:, None]).any(1)
    sp, sv = sp[new], sv[new]
    if len(sv):
        ok[sp[ctx.loc.closest(0.5 * (P[pcen[sp]] + P[sv]), hint=W.vtri[sv])[2] > ctx.delta]] = False
    good = np.flatnonzero(ok)
    if not len(good):
        return 0
    # ---- each candidate's best subset (largest new smallest angle, then the smaller mask); the
    #      candidates whose faces share no node, best first
    g = good[np.lexsort((pm[good], -new_min[good], pc[good]))]
    first = np.ones(len(g), bool)
    first[1:] = pc[g][1:] != pc[g][:-1]
    best = g[first]
    bo, bpos = csr_entries(cptr, pc[best])
    res = F[key[bpos] % len(F)].reshape(-1)
    win = greedy_independent(np.repeat(bo, 3), res, rank_candidates(new_min[best], cand[pc[best]]), n)
    best = best[win]
    sel = (plink[best] >= 0) & (((pm[best][:, None] >> np.arange(nv)[None, :]) & 1) == 1)
    a = plink[best][sel]
    b = np.repeat(pcen[best], sel.sum(1))
    W.F, W.fpatch, W.fe, W.fe_chain, keepv = collapse_apply(F, W.fpatch, W.fe, W.fe_chain, a, b, n)
    W.keep_vertices(keepv)
    # the spokes longer than the sweeps allow (the nodes removed were closer): split at their middle
    centres = np.cumsum(keepv)[pcen[best]] - 1
    T = W.topo()
    at = np.flatnonzero(np.isin(T.E, centres).any(1))
    long = at[edge_lengths(W.P, T.E[at]) > SPLIT_RATIO * 0.5 * (W.h[T.E[at, 0]] + W.h[T.E[at, 1]])]
    if len(long):
        split_round(W, ctx, forced=long)
    return len(a)


def _in_subset(v, links, masks, width):
    """Per row: node ``v[i]`` is one of the slots of ``links[i]`` (k, width) set in the bit
    mask ``masks[i]``."""
    bits = ((masks[:, None] >> np.arange(width)[None, :]) & 1) == 1
    return ((v[:, None] == links) & bits & (links >= 0)).any(1)


def _remap(Fr, links, masks, centre, width):
    """Faces ``Fr`` (k, 3) with the nodes of each row's subset (``links``, ``masks``) moved to
    its ``centre``, and how many nodes of the cluster (the subset and the centre) each holds."""
    ins = np.stack([_in_subset(Fr[:, k], links, masks, width) for k in range(3)], 1)
    return np.where(ins, centre[:, None], Fr), (ins | (Fr == centre[:, None])).sum(1)


def _fan_closed(ok, group, faces, centre, n):
    """Clear ``ok[g]`` unless the ``faces`` of group ``g`` (all holding node ``centre``) close one
    fan of at least three faces around it: each neighbour once as the next and once as the
    previous corner, one cycle. Returns the keys ``group * n + neighbour`` of the fans' spokes."""
    k0 = np.argmax(faces == centre[:, None], axis=1)
    r = np.arange(len(faces))
    nxt = group * n + faces[r, (k0 + 1) % 3]
    prv = group * n + faces[r, (k0 + 2) % 3]
    for col in (nxt, prv):
        u, cnt = np.unique(col, return_counts=True)
        ok[u[cnt > 1] // n] = False
    un, up = np.unique(nxt), np.unique(prv)
    ok[np.setxor1d(un, up) // n] = False
    node, inv = np.unique(np.concatenate([prv, nxt]), return_inverse=True)
    m = len(faces)
    g = sparse.coo_matrix((np.ones(m), (inv[:m], inv[m:])), shape=(len(node), len(node)))
    _, lab = connected_components(g, directed=False)
    ngroup = len(ok)
    ncomp = np.bincount(np.unique(lab * ngroup + node // n) % ngroup, minlength=ngroup)
    nface = np.bincount(group, minlength=ngroup)
    ok &= (ncomp == 1) & (nface >= 3)
    return un


def _vertex_rows(E, n):
    """CSR ``(ptr, rows)`` of the rows of the (k, 2) array ``E`` at each of ``n`` nodes."""
    ends = E.reshape(-1)
    order = np.argsort(ends, kind="stable")
    ptr = np.searchsorted(ends[order], np.arange(n + 1))
    return ptr, order // 2
