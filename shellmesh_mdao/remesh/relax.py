"""The remesher's tangential relaxation (:func:`relax_vertices`) and the tests that undo the
moves that would fold, flatten or turn a face."""
from __future__ import annotations

import numpy as np

from .kernels import group_order, move_tests
from ..mesh import dot_norm_rows, dot_rows, dot_unit_rows, reduce_short
from .common import CHAIN, COS_FACING, REGULAR, min_angle_of, tri_min_angle, tri_normals

__all__ = ["relax_vertices"]

# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


def relax_vertices(W, ctx, lam=1.0, move_chains=True, movable=None, min_angle_floor=10.0):
    """Tangential relaxation (area-weighted centroid of the incident triangles) of the
    regular vertices, projected back onto the input; chain vertices move to the midpoint
    of their chain neighbours in arc length. Moves that would turn a face by more than 60
    degrees (or invert it against the input normal) are undone."""
    F = W.F
    P = W.P
    n = W.n
    An = tri_normals(P, F)
    area = _norm(An)
    C = (P[F[:, 0]] + P[F[:, 1]] + P[F[:, 2]]) / 3          # P[F].mean(1), the same bits
    wsum = np.zeros(n)
    acc = np.zeros((n, 3))
    for k in range(3):
        wsum += np.bincount(F[:, k], weights=area, minlength=n)
        for dd in range(3):
            acc[:, dd] += np.bincount(F[:, k], weights=area * C[:, dd], minlength=n)
    vn = W.vertex_normals()
    reg = W.kind == REGULAR
    if movable is not None:
        reg &= movable
    reg &= wsum > 0
    newP = P.copy()
    newtri = W.vtri.copy()
    newS = W.S.copy()
    ri = np.flatnonzero(reg)
    if len(ri):
        cen = acc[ri] / wsum[ri, None]
        dvec = cen - P[ri]
        dvec -= _dot(dvec, vn[ri])[:, None] * vn[ri]
        q = P[ri] + lam * dvec
        pts, tri, ok = ctx.project(q, vn[ri], W.vertex_patch()[ri], hint=W.vtri[ri])
        ri, pts, tri = ri[ok], pts[ok], tri[ok]
        newP[ri] = pts
        newtri[ri] = tri
    ci = np.zeros(0, np.int64)
    if move_chains and ctx.surf is not None and len(W.fe):
        ci = np.flatnonzero(W.kind == CHAIN)
    if len(ci):
        fe = W.fe
        ends = fe.reshape(-1)
        oth = fe[:, ::-1].reshape(-1)
        ech = np.repeat(W.fe_chain, 2)
        ptr, order = group_order(ends, n)
        good = (ptr[ci + 1] - ptr[ci]) == 2
        ci = ci[good]
        u = oth[order[ptr[ci]]]
        w = oth[order[ptr[ci] + 1]]
        c = ech[order[ptr[ci]]]
        Sv = W.S[ci]
        Su = ctx.chain_S_of(W, u, c, Sv)
        Sw = ctx.chain_S_of(W, w, c, Sv)
        du = ctx.chain_delta(c, Su - Sv)
        dw = ctx.chain_delta(c, Sw - Sv)
        # weight by the sizing so edges approach equal length relative to the local size
        hu, hw = W.h[u], W.h[w]
        t = hu / (hu + hw)
        target = du + t * (dw - du)
        pts, _, Snew = ctx.surf.chain_point(Sv + lam * target, c)
        newP[ci] = pts
        newS[ci] = Snew
    moved = np.zeros(n, bool)
    moved[ri] = True
    moved[ci] = True
    _accept_moves(W, ctx, newP, newtri, newS, moved, An, area, min_angle_floor=min_angle_floor)
    return int(moved.sum())


def _accept_moves(W, ctx, newP, newtri, newS, moved, An_old, area_old, max_turn=60.0, min_angle_floor=10.0):
    F = W.F
    P = W.P
    fn_old = np.divide(An_old, area_old[:, None], out=np.zeros_like(An_old), where=area_old[:, None] > 0)
    cosmax = np.cos(np.radians(max_turn))
    cur = np.where(moved[:, None], newP, P)
    reg = W.kind == REGULAR
    amin_old = tri_min_angle(P[F[:, 0]], P[F[:, 1]], P[F[:, 2]])
    for _ in range(100):
        fm = reduce_short(moved[F], "any")
        fi = np.flatnonzero(fm)
        if not len(fi):
            break
        Fi = F[fi]
        # in one compiled pass (kernels.move_tests): no face turning by more than max_turn or
        # losing its area, none facing against the input at its regular vertices or standing
        # across it; the angles' arguments
        bad, sc = move_tests(cur, Fi, fn_old[fi], area_old[fi], moved, newtri, W.vtri, reg, ctx.tri_n, cosmax,
                             COS_FACING)
        # no face may end up with a smaller angle than min(its old smallest angle, 10 deg)
        bad |= min_angle_of(sc) < np.minimum(amin_old[fi], min_angle_floor)
        if not bad.any():
            break
        back = np.unique(Fi[bad].reshape(-1))
        back = back[moved[back]]
        if not len(back):
            break
        moved[back] = False
        cur[back] = P[back]
    W.P = cur
    W.vtri = np.where(moved, newtri, W.vtri)
    W.S = np.where(moved, newS, W.S)
