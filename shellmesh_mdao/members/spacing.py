"""Chain spacing before the members are meshed: very uneven chain spacing evened out along the exact
curves (:func:`relax_chain_spacing`), and chain edges much longer than the member is tall split,
with fans in the two skin triangles on them (:func:`split_thin_chain_edges`)."""
from __future__ import annotations

import numpy as np

from ..core.polyline import arc_param, arc_point
from ..errors import ImprintError
from ..mesh import ShellMesh, norm_rows, vertex_faces
from .meshing import tri_min_angles

__all__ = ["relax_chain_spacing", "split_thin_chain_edges"]


def relax_chain_spacing(skin: ShellMesh, P: np.ndarray, mems, chains_arcs, ratio: float = 0.67, rounds: int = 20,
                        min_skin_angle: float = 10.0, pinned=None) -> int:
    """Even out uneven chain spacing by sliding chain vertices along their exact arcs.

    ``chains_arcs``: (open chain, its exact curve as an open polyline) pairs. A chain vertex
    (not a crossing, not a chain end, not on a geometric feature line) whose
    two chain edges differ by more than ``1/ratio`` moves half-way towards the arc-length
    midpoint of its neighbours. The point stays on the exact curve (input surface and member
    plane); moves that would fold a skin triangle or drop its smallest angle below
    ``min(current, min_skin_angle)`` are refused; ``pinned`` (vertex ids) never move (the kinks
    of a kinked member). Updates ``P`` in place; returns the number of vertices moved."""
    F = skin.faces[:, :3]
    n = len(P)
    count = np.zeros(n, np.int64)
    for m in mems:
        np.add.at(count, np.unique(m.chain_vertices()), 1)
    geo = np.zeros(n, bool)
    geo[skin.feature_edges[skin.feature_edge_ids < 0].ravel()] = True
    if pinned is not None and len(pinned):
        geo[np.asarray(pinned, np.int64)] = True
    # per chain: parameters along its arc, ordered; collect movable interior vertices
    recs = []
    for ch, poly in chains_arcs:                     # loop over chains
        if poly is None or len(ch) < 3:
            continue
        s, p, cum = arc_param(P[ch], poly, False)
        if s[-1] < s[0]:
            ch = ch[::-1]
            s = s[::-1]
        if (np.diff(s) <= 0).any():
            continue
        recs.append((ch, s, p, cum))
    if not recs:
        return 0
    ptr, vf = vertex_faces(F, n)
    moved_total = np.zeros(n, bool)

    def tri_state(X, fids):
        t = F[fids]
        a, b, c = X[t[:, 0]], X[t[:, 1]], X[t[:, 2]]
        nrm = np.cross(b - a, c - a)
        return nrm, tri_min_angles(X, t)

    for _ in range(rounds):
        prop_v, prop_x = [], []
        for ch, s, p, cum in recs:                   # loop over chains (vectorised inside)
            sp, sc, sn = s[:-2], s[1:-1], s[2:]
            lp, ln = sc - sp, sn - sc
            v = ch[1:-1]
            mov = (count[v] == 1) & ~geo[v] & (np.minimum(lp, ln) < ratio * np.maximum(lp, ln))
            if not mov.any():
                continue
            target = sc + 0.5 * (0.5 * (sp + sn) - sc)
            prop_v.append(v[mov])
            prop_x.append(arc_point(p, cum, target[mov]))
        if not prop_v:
            break
        v = np.concatenate(prop_v)
        x = np.vstack(prop_x)
        ok = np.ones(len(v), bool)
        for _ in range(6):                           # refuse moves that spoil a skin triangle
            vv = v[ok]
            if not len(vv):
                break
            k = ptr[vv + 1] - ptr[vv]
            fids = np.unique(vf[np.repeat(ptr[vv], k) + np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)])
            X = P.copy()
            X[vv] = x[ok]
            n0, a0 = tri_state(P, fids)
            n1, a1 = tri_state(X, fids)
            fold = np.einsum("ij,ij->i", n0, n1) <= 0.5 * norm_rows(n0, axis=1) * norm_rows(n1, axis=1)
            # a move may not make its vertex's star worse than it was (or than min_skin_angle)
            worst = np.full(n, np.inf)
            for c in range(3):
                np.minimum.at(worst, F[fids, c], a0)
            floor = np.where(np.isin(F[fids], vv), np.minimum(worst[F[fids]], min_skin_angle), np.inf).min(1)
            bad = fold | (a1 < floor - 1e-9)
            if not bad.any():
                break
            badv = np.unique(F[fids[bad]])
            ok &= ~np.isin(v, badv)
        if not ok.any():
            break
        P[v[ok]] = x[ok]
        moved_total[v[ok]] = True
        # refresh parameters of the moved chains
        new = []
        for ch, s, p, cum in recs:
            m = np.isin(ch, v[ok])
            if m.any():
                s = s.copy()
                s[m] = arc_param(P[ch[m]], p, False)[0]
            new.append((ch, s, p, cum))
        recs = new
    return int(moved_total.sum())


def _dist_to_polyline(q: np.ndarray, poly: np.ndarray) -> np.ndarray:
    if len(poly) < 2:
        return norm_rows(q - poly[0], axis=1)
    s, p, cum = arc_param(q, poly, False)
    return norm_rows(arc_point(p, cum, s) - q, axis=1)


def _opposite_angle(P, tri, a, b):
    """Angle (degrees) of each triangle ``tri`` (k, 3) at its corner that is neither ``a`` nor ``b``."""
    c = np.where((tri[:, 0] != a) & (tri[:, 0] != b), tri[:, 0],
                 np.where((tri[:, 1] != a) & (tri[:, 1] != b), tri[:, 1], tri[:, 2]))
    u, v = P[a] - P[c], P[b] - P[c]
    cosv = np.einsum("ij,ij->i", u, v) / np.maximum(norm_rows(u, axis=1) * norm_rows(v, axis=1), 1e-300)
    return np.degrees(np.arccos(np.clip(cosv, -1.0, 1.0)))


def _apex(F, f, a_, b_):
    """The corner of each face ``F[f]`` that is neither ``a_`` nor ``b_``."""
    t = F[f]
    return np.where((t[:, 0] != a_) & (t[:, 0] != b_), t[:, 0], np.where((t[:, 1] != a_) & (t[:, 1] != b_), t[:, 1], t[:, 2]))


def _fan_fractions(P, a_, b_, apices, ck):
    """Where along each edge ``a_-b_`` its ``ck - 1`` split points go (fractions, concatenated):
    the mean over the apices of the points that divide each apex's angle into ``ck`` equal
    parts (the ray at angle ``phi`` from ``c-a`` meets ``a-b`` at ``t = |ca| sin(phi) /
    (|ca| sin(phi) + |cb| sin(theta - phi))``); equal pieces when the apices face the middle."""
    nnew = ck - 1
    rep = np.repeat(np.arange(len(ck)), nnew)
    j = (np.arange(len(rep)) - np.repeat(np.cumsum(nnew) - nnew, nnew) + 1) / ck[rep]
    t = np.zeros(len(rep))
    for c in apices:
        ca, cb = P[a_] - P[c], P[b_] - P[c]
        la, lb = norm_rows(ca, axis=1), norm_rows(cb, axis=1)
        th = np.arccos(np.clip(np.einsum("ij,ij->i", ca, cb) / np.maximum(la * lb, 1e-300), -1.0, 1.0))
        phi = j * th[rep]
        num = la[rep] * np.sin(phi)
        t += num / np.maximum(num + lb[rep] * np.sin(th[rep] - phi), 1e-300)
    return t / len(apices)


def _fan_points(P, mems, cm, cw, a_, b_, ck, frac=None):
    """The ``ck - 1`` points splitting each chain edge ``a_-b_`` (side ``cw`` of member ``cm``)
    into ``ck`` pieces along the side's exact arc, concatenated edge by edge: at the arc-length
    fractions ``frac`` (concatenated) or, by default, equal pieces."""
    nnew = ck - 1
    off = np.concatenate([[0], np.cumsum(nnew)[:-1]])
    X = np.zeros((int(nnew.sum()), 3))
    for mi, w in sorted(set(zip(cm.tolist(), cw.tolist()))):   # one arc query per member side
        sel = np.flatnonzero((cm == mi) & (cw == w))
        s, p, cum = arc_param(P[np.concatenate([a_[sel], b_[sel]])], mems[mi].side_arcs[w], False)
        sa, sb = s[:len(sel)], s[len(sel):]
        rep = np.repeat(np.arange(len(sel)), nnew[sel])
        j = np.arange(len(rep)) - np.repeat(np.cumsum(nnew[sel]) - nnew[sel], nnew[sel]) + 1
        pos = np.repeat(off[sel], nnew[sel]) + j - 1
        tpar = sa[rep] + (sb[rep] - sa[rep]) * (j / ck[sel][rep] if frac is None else frac[pos])
        X[pos] = arc_point(p, cum, tpar)
    return X


def _fan_sequences(a_, b_, ck, first):
    """Node sequences ``a, new..., b`` of every split edge (new nodes numbered from ``first``),
    concatenated; with each sequence's start and length."""
    seq_len = ck + 1
    seq_start = np.concatenate([[0], np.cumsum(seq_len)[:-1]])
    rep = np.repeat(np.arange(len(ck)), seq_len)
    j = np.arange(len(rep)) - seq_start[rep]
    seq = np.where(j == 0, a_[rep], np.where(j == ck[rep], b_[rep], first[rep] + j - 1))
    return seq, seq_start, seq_len


def _fan_min_angles(P, F, mems, cm, cw, a_, b_, f0, f1, ck, frac=None, fixed=None, fixed_floor: float = 0.0):
    """Smallest angle of the fan triangles that splitting each chain edge ``a_-b_`` into ``ck``
    pieces (at the arc fractions ``frac``, concatenated; default: dividing the apex angles
    evenly) would make in its two skin faces ``f0``, ``f1``; -1 where a fan triangle's angle at
    an apex that is ``fixed`` (bool per point) is below ``fixed_floor`` degrees (no smoothing
    can open that corner: its quad after the subdivision keeps it)."""
    c0, c1 = _apex(F, f0, a_, b_), _apex(F, f1, a_, b_)
    if frac is None:
        frac = _fan_fractions(P, a_, b_, (c0, c1), ck)
    X = _fan_points(P, mems, cm, cw, a_, b_, ck, frac)
    Q = np.vstack([P, X])
    first = len(P) + np.concatenate([[0], np.cumsum(ck - 1)[:-1]])
    seq, seq_start, seq_len = _fan_sequences(a_, b_, ck, first)
    e_of = np.repeat(np.arange(len(ck)), ck)
    jj = np.arange(len(e_of)) - np.repeat(np.cumsum(ck) - ck, ck)
    s0 = seq[seq_start[e_of] + jj]
    s1 = seq[seq_start[e_of] + jj + 1]
    worst = np.full(len(ck), np.inf)
    for f in (f0, f1):
        t = F[f]
        c = np.where((t[:, 0] != a_) & (t[:, 0] != b_), t[:, 0], np.where((t[:, 1] != a_) & (t[:, 1] != b_), t[:, 1], t[:, 2]))
        tri = np.stack([s0, s1, c[e_of]], 1)
        ang = tri_min_angles(Q, tri)
        if fixed is not None and fixed_floor > 0:
            at = np.flatnonzero(fixed[c[e_of]])
            if len(at):
                ang[at[_opposite_angle(Q, tri[at], s0[at], s1[at]) < fixed_floor]] = -1.0
        np.minimum.at(worst, e_of, ang)
    return worst


def _mirror_fractions(P, ch, other, L, thin, min_len: float, max_pieces: int):
    """Ladder split points of the thin chain edges of one member side: the closest points on
    the side (chain ``ch``, edge lengths ``L``) of the opposite side's vertices (``other``) that
    fall inside an edge flagged ``thin`` and lie across the member from it (no farther than the
    edge is long), at least ``max(min_len, 0.3 x their distance)`` from the edge's ends and from
    each other. Returns ``(count, frac)``: points per edge and an (edges, max_pieces - 1) array
    of arc fractions along the edge (NaN-padded, increasing)."""
    ne = len(L)
    frac = np.full((ne, max(max_pieces - 1, 1)), np.nan)
    cnt = np.zeros(ne, np.int64)
    if not thin.any() or len(other) == 0:
        return cnt, frac
    s, p, cum = arc_param(P[other], P[ch], False)
    d = norm_rows(arc_point(p, cum, s) - P[other], axis=1)
    e = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, ne - 1)
    t = (s - cum[e]) * L[e] / np.maximum((cum[e + 1] - cum[e]) * L[e], 1e-300)   # fraction along the edge
    margin = np.maximum(min_len, 0.3 * d) / np.maximum(L[e], 1e-300)
    ok = thin[e] & (d <= L[e]) & (t > margin) & (t < 1.0 - margin)
    e, t, margin = e[ok], t[ok], margin[ok]
    o = np.lexsort((t, e))
    e, t, margin = e[o], t[o], margin[o]
    close = np.zeros(len(e), bool)                   # too close to the previous point on the same edge
    close[1:] = (e[1:] == e[:-1]) & (t[1:] - t[:-1] < np.maximum(margin[1:], margin[:-1]))
    e, t = e[~close], t[~close]
    cnt = np.bincount(e, minlength=ne).astype(np.int64)
    j = np.arange(len(e)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    fit = j < frac.shape[1]
    frac[e[fit], j[fit]] = t[fit]
    cnt = np.where(cnt <= frac.shape[1], cnt, 0)     # too many: no ladder for that edge
    return cnt, frac


def split_thin_chain_edges(P, F, C, FE, FID, mems, size, ratio: float = 1.5, max_pieces: int = 16,
                           min_piece: float = 0.02, min_height: float = 0.1, rounds: int = 3,
                           min_fan_angle: float = 15.0, min_skin_angle: float = 10.0, fixed=None):
    """Split chain edges that are long compared with the member's local height.

    Where a member is thinner than its chain spacing (the spars of a thin wing), no
    triangle joining its upper and lower chains can have good angles: a chain edge longer
    than ``ratio`` times the distance from its midpoint to the member's opposite chain is
    split into equal pieces along its exact arc (new points on the input surface and the
    member plane), and the two skin triangles on that edge are split into fans. Pieces are
    never shorter than ``min_piece * size`` and at most ``max_pieces``; where the member is
    thinner than ``min_height * size`` (the tip of a wedge, a trailing edge) nothing is
    split. A fan of ``k`` pieces divides the skin angle opposite the edge (in each of its
    two skin triangles) into ``k``: ``k`` is at most that angle over ``min_fan_angle``
    degrees, so no skin triangle is fanned into slivers (near the sharp leading or trailing
    edge of a full-chord rib the height drops to zero and the old rule split the chain edges
    into up to 16 pieces: skin angles of 3 degrees that no later stage could repair). The
    split points divide each skin face's apex angle evenly (the mean of the two faces' points)
    rather than the edge: with an apex off to one side (an obtuse skin corner at a chain
    vertex, common where a full-chord rib meets a spar) equal pieces leave a sliver of that
    angle in the far piece. Then ``k`` drops until no fan triangle has an angle below the
    smaller of ``min_skin_angle`` (the imprint's own floor) and the smallest angle of the face
    it replaces, and no fan triangle whose apex is one of the ``fixed`` skin vertices (bool per
    point; a chain's crossing with a crease, say) has an angle there below ``min_fan_angle``:
    the subdivision's quad at that corner keeps the angle, whose sine bounds its scaled
    Jacobian (a ladder had split a 38-degree corner at a rib's trailing-edge crossing into
    17.2, 10.5 and 10.3 degrees: a final quad of 0.183 on cessna210 stress seed 41).
    Ladder: a thin edge (longer than ``ratio`` times the height) with vertices of the opposite
    side across it is split at their closest points instead (:func:`_mirror_fractions`), also
    where the height is below ``min_height * size``: in the thin trailing-edge wedge of a
    full-chord rib the two sides then have matching vertices, so the corner triangle and the
    triangles along the wedge are not slivers (a long edge opposite short ones left 8-degree rib
    triangles). The ladder is taken when its fans keep the floor above, else its best single
    point, else the even split.
    Returns the updated ``(P, F, C, FE, FID)``; the members' sides get the new vertices
    (call ``sync_sides`` afterwards)."""
    for _ in range(rounds):
        if fixed is not None and len(fixed) < len(P):       # the points of the rounds before are free
            fixed = np.concatenate([fixed, np.zeros(len(P) - len(fixed), bool)])
        # ------------------------------------------------ candidates, per member side
        cm, cw, ci, ck, ck_old, cfr = [], [], [], [], [], []
        for mi, m in enumerate(mems):                 # loop over members
            for w in (0, 1):
                ch, other, arc = m.sides[w], m.sides[1 - w], m.side_arcs[w]
                if arc is None or len(ch) < 2:
                    continue
                a, b = P[ch[:-1]], P[ch[1:]]
                L = norm_rows(b - a, axis=1)
                H = _dist_to_polyline(0.5 * (a + b), P[other])
                thin = (L > ratio * H) & (L >= 2 * min_piece * size)
                want = np.where(H >= min_height * size, np.ceil(L / np.maximum(ratio * H, 1e-300)), 1)
                k = np.minimum(np.minimum(want, max_pieces), np.floor(L / (min_piece * size))).astype(np.int64)
                # ladder: the opposite side's vertices across a thin edge (also near a wedge tip,
                # where the height rule splits nothing)
                nm, mf = _mirror_fractions(P, ch, other, L, thin, min_piece * size, max_pieces)
                k_lad = np.where(nm > 0, nm + 1, k)
                i = np.flatnonzero(k_lad >= 2)
                cm.append(np.full(len(i), mi))
                cw.append(np.full(len(i), w))
                ci.append(i)
                ck.append(k_lad[i])
                ck_old.append(np.maximum(k[i], 1))
                cfr.append(np.where((nm > 0)[i, None], mf[i], np.nan))
        if not cm or not sum(len(x) for x in ci):
            break
        cm, cw, ci, ck, ck_old = (np.concatenate(x).astype(np.int64) for x in (cm, cw, ci, ck, ck_old))
        cfr = np.vstack(cfr)
        lad = ~np.isnan(cfr[:, 0])
        a_ = np.array([mems[m].sides[w][i] for m, w, i in zip(cm, cw, ci)], np.int64)
        b_ = np.array([mems[m].sides[w][i + 1] for m, w, i in zip(cm, cw, ci)], np.int64)
        # ------------------------------------------------ the two skin faces of every candidate edge
        n = len(P)
        ek = np.minimum(a_, b_) * n + np.maximum(a_, b_)
        fk = (np.minimum(F, np.roll(F, -1, axis=1)) * n + np.maximum(F, np.roll(F, -1, axis=1))).ravel()
        o = np.argsort(fk, kind="stable")
        sk = fk[o]
        lo, hi = np.searchsorted(sk, ek, "left"), np.searchsorted(sk, ek, "right")
        if ((hi - lo) != 2).any():
            bad = int(np.flatnonzero((hi - lo) != 2)[0])
            raise ImprintError(f"member '{mems[cm[bad]].name}': chain edge {a_[bad]}-{b_[bad]} is not an edge between "
                               "two skin triangles (another member's chain or a sharp edge of the skin runs along "
                               "it): move the member in the layout, or use a smaller --size")
        f0, f1 = o[lo] // 3, o[lo + 1] // 3
        # no fan triangle below min_skin_angle, nor below the smallest angle of the face it replaces
        floor_ang = np.minimum(min_skin_angle, np.minimum(tri_min_angles(P, F[f0]), tri_min_angles(P, F[f1])))
        # a ladder split is taken as it is when its fans keep the floor below, else the edge
        # falls back to the even split
        wl = cfr.shape[1]
        if lad.any():
            lv = np.flatnonzero(lad)
            fr = cfr[lv][np.arange(wl)[None, :] < (ck[lv] - 1)[:, None]]
            worst = _fan_min_angles(P, F, mems, cm[lv], cw[lv], a_[lv], b_[lv], f0[lv], f1[lv], ck[lv], fr,
                                       fixed=fixed, fixed_floor=min_fan_angle)
            fail = lv[worst < floor_ang[lv] - 1e-9]
            if len(fail):
                # else the single ladder point whose fans are best, if they keep the floor
                nf = ck[fail] - 1
                rep = np.repeat(fail, nf)
                j = np.arange(len(rep)) - np.repeat(np.cumsum(nf) - nf, nf)
                one = np.ones(len(rep), np.int64) * 2
                w1 = _fan_min_angles(P, F, mems, cm[rep], cw[rep], a_[rep], b_[rep], f0[rep], f1[rep], one,
                                     cfr[rep, j], fixed=fixed, fixed_floor=min_fan_angle)
                o = np.lexsort((-w1, rep))
                best = o[np.concatenate([[True], rep[o][1:] != rep[o][:-1]])]
                good = w1[best] >= floor_ang[rep[best]] - 1e-9
                gi = rep[best][good]
                chosen = cfr[gi, j[best][good]]
                cfr[gi] = np.nan
                cfr[gi, 0] = chosen
                ck[gi] = 2
                fail = np.setdiff1d(fail, gi)
            lad[fail] = False
            ck[fail] = ck_old[fail]
        # a fan of k pieces splits the skin angle opposite the edge into k: no fan angle below
        # min_fan_angle (or, when that angle is already smaller, no split at all)
        apex = np.minimum(_opposite_angle(P, F[f0], a_, b_), _opposite_angle(P, F[f1], a_, b_))
        ck = np.where(lad, ck, np.minimum(ck, np.floor(apex / min_fan_angle))).astype(np.int64)
        # ... but equal pieces along the edge divide that angle evenly only when the apex faces
        # the edge's middle: the split points divide the two apex angles evenly instead (mean of
        # the two), and fewer pieces are used until every fan triangle keeps the smaller of
        # min_skin_angle and the smallest angle of the face it replaces.
        for _k in range(max_pieces):
            live = np.flatnonzero((ck >= 2) & ~lad)
            if not len(live):
                break
            worst = _fan_min_angles(P, F, mems, cm[live], cw[live], a_[live], b_[live], f0[live], f1[live], ck[live],
                                   fixed=fixed, fixed_floor=min_fan_angle)
            bad = live[worst < floor_ang[live] - 1e-9]
            if not len(bad):
                break
            ck[bad] -= 1
        keep_c = ck >= 2
        cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr = (x[keep_c] for x in (cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr))
        if not len(cm):
            break
        # face-disjoint subset: a candidate is taken when it is the first to claim both its faces
        idx = np.arange(len(cm))
        owner = np.full(len(F), len(cm))
        np.minimum.at(owner, f0, idx)
        np.minimum.at(owner, f1, idx)
        take = (owner[f0] == idx) & (owner[f1] == idx)
        cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr = (x[take] for x in (cm, cw, ci, ck, a_, b_, f0, f1, lad, cfr))
        # ------------------------------------------------ new points on the exact arcs
        nnew = ck - 1
        first = len(P) + np.concatenate([[0], np.cumsum(nnew)[:-1]])
        frac = _fan_fractions(P, a_, b_, (_apex(F, f0, a_, b_), _apex(F, f1, a_, b_)), ck)
        use = np.arange(wl)[None, :] < nnew[:, None]
        frac = np.where(np.repeat(lad, nnew), cfr[use], frac)
        X = _fan_points(P, mems, cm, cw, a_, b_, ck, frac)
        # ------------------------------------------------ node sequences a, new..., b of every split edge
        seq, seq_start, seq_len = _fan_sequences(a_, b_, ck, first)
        # ------------------------------------------------ fans replacing the two faces
        new_faces, new_C = [], []
        for f in (f0, f1):
            t = F[f]
            fwd = np.zeros(len(f), bool)
            c = np.zeros(len(f), np.int64)
            for q in range(3):
                u, v = t[:, q], t[:, (q + 1) % 3]
                hit_f = (u == a_) & (v == b_)
                hit_r = (u == b_) & (v == a_)
                fwd |= hit_f
                c = np.where(hit_f | hit_r, t[:, (q + 2) % 3], c)
            e_of = np.repeat(np.arange(len(ck)), ck)          # k fan triangles per face
            jj = np.arange(len(e_of)) - np.repeat(np.cumsum(ck) - ck, ck)
            s0 = seq_start[e_of] + np.where(fwd[e_of], jj, ck[e_of] - jj)
            s1 = seq_start[e_of] + np.where(fwd[e_of], jj + 1, ck[e_of] - jj - 1)
            new_faces.append(np.stack([seq[s0], seq[s1], c[e_of]], 1))
            new_C.append(C[f][e_of])
        drop = np.zeros(len(F), bool)
        drop[f0] = drop[f1] = True
        # ------------------------------------------------ feature edges: (a, b) -> its pieces, same owner
        m_fe = len(P) + len(X)
        fe_key = FE[:, 0] * m_fe + FE[:, 1]
        sp_key = np.minimum(a_, b_) * m_fe + np.maximum(a_, b_)
        hit = np.isin(fe_key, sp_key)
        okey = np.argsort(fe_key, kind="stable")
        pos = okey[np.clip(np.searchsorted(fe_key[okey], sp_key), 0, len(okey) - 1)]
        owner_id = np.where(fe_key[pos] == sp_key, FID[pos], -1).astype(np.int32)
        pieces = np.sort(np.stack([seq[:-1], seq[1:]], 1), axis=1)
        valid = np.ones(len(seq) - 1, bool)
        valid[(seq_start + seq_len - 1)[:-1]] = False             # no piece joins two edges' sequences
        P = np.vstack([P, X])
        F = np.vstack([F[~drop]] + new_faces)
        C = np.concatenate([C[~drop]] + new_C)
        FE = np.vstack([FE[~hit], pieces[valid]])
        FID = np.concatenate([FID[~hit], np.repeat(owner_id, ck)])
        # ------------------------------------------------ chains get the new vertices
        for mi, w in sorted(set(zip(cm.tolist(), cw.tolist()))):   # loop over refined member sides
            sel = np.flatnonzero((cm == mi) & (cw == w))
            ch = mems[mi].sides[w]
            cnt = np.ones(len(ch), np.int64)
            cnt[ci[sel]] += nnew[sel]
            out = np.repeat(ch, cnt)
            start = np.concatenate([[0], np.cumsum(cnt)[:-1]])
            k = nnew[sel]
            within = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k)
            out[np.repeat(start[ci[sel]] + 1, k) + within] = np.repeat(first[sel], k) + within
            mems[mi].sides[w] = out
    return P, F, C, FE, FID
