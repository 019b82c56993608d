"""The remesh stage's view of the input skin (:class:`InputSurface`): its triangles, the
feature-bounded patches, the feature chains parametrised by arc length, the curvature- and
feature-adapted sizing field, and the normal-compatible projection onto it
(:func:`project_compatible`)."""
from __future__ import annotations

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from ..errors import MeshValidationError
from .kernels import edge_lengths, group_order
from ..mesh import ShellMesh, bbox_diagonal, dot_norm_rows, dot_rows, dot_unit_rows
from ..core.locator import SurfaceLocator, closest_point_on_triangles
from ..core.sizefield import SizeField
from .common import CHAIN, CORNER, EdgeTable, tri_normals

__all__ = ["InputSurface", "project_compatible", "MAX_TURN", "TURN_MIN_EDGE_FRACTION", "UNRESOLVED_TURN", "WEDGE_DIHEDRAL",
           "SIZING_REASONS"]

#: why the sizing asks for less than the target at an input vertex (:attr:`InputSurface.reason`,
#: the remesh report's ``sizing``): the chordal-deviation bound over a kink or the curvature, and
#: the deviation passes' shrinking; the turning bound across a nose tighter than the edge; a thin
#: feature (feature lines facing each other, a dangling line end); a feature line's own turning
#: or shortness; the local sizes asked for (members closer than the element size); the
#: gradation from a smaller size nearby
SIZING_REASONS = ("curvature", "nose_turning", "thin_feature", "feature_lines", "close_members", "grading")

#: the sizing's turning bound: where the chordal-deviation bound would let an edge turn more than
#: 90 degrees (a fold of radius below 0.32 target edges: a leading-edge nose), no edge spans more
#: than this many degrees of the surface's turning (edge length <= MAX_TURN / curvature), so no
#: face cuts across the fold
MAX_TURN = 45.0

#: the turning bound stops at this fraction of ``min_edge`` (the other sizing terms stop at
#: ``min_edge``): the bundled wing's 16 mm nose radius at its tip is resolved up to a target edge
#: of about 0.5 (size 0.25)
TURN_MIN_EDGE_FRACTION = 0.25

#: the turning bound asks nothing where an edge at its floor (:data:`TURN_MIN_EDGE_FRACTION` of
#: ``min_edge``) would still turn across more than this many degrees of the fold: such edges stand
#: across the fold and face away from the input (a 10 mm nose at element size 0.66, random family
#: seed 9); 60 lies between the bound's own 45 and the 90 at which an edge cuts across anyway
UNRESOLVED_TURN = 60.0

#: within a target edge of a wedge, a crease whose faces meet at a dihedral above this (degrees;
#: closing to less than 45 degrees, like a sharp trailing edge), the turning bound asks for no less
#: than ``min_edge``: a fold running into a wedge narrows to no radius there (a round tip's outline
#: at the trailing edge), and the smaller floor it would ask for beside the crease's chain
#: (:data:`TURN_MIN_EDGE_FRACTION`, for noses) leaves degenerate slivers
WEDGE_DIHEDRAL = 135.0

# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


# ============================================================================ input surface
class InputSurface:
    """The input skin: triangles, patches, feature chains, sizing field and projection."""

    def __init__(self, mesh: ShellMesh, target, delta, feature_angle, corner_angle, wedge_angle,
                 keep_component_borders, locator=None):
        tris, parent = mesh.triangles()
        P = mesh.points
        used = np.zeros(len(P), bool)
        used[tris.reshape(-1)] = True
        if not used.all():                              # drop unreferenced nodes
            o2n = np.cumsum(used) - 1
            P = P[used]
            tris = o2n[tris]
        self.P = np.ascontiguousarray(P, dtype=np.float64)
        self.T = np.ascontiguousarray(tris, dtype=np.int64)
        self.tri_comp = mesh.component[parent].astype(np.int32)
        self.component_names = list(mesh.component_names)
        self.loc = locator if locator is not None else SurfaceLocator(self.P, self.T)
        if locator is not None and (locator.triangles.shape != self.T.shape):
            self.loc = SurfaceLocator(self.P, self.T)
        nv = len(self.P)
        self.diag = bbox_diagonal(self.P)
        self.target = float(target)
        An = tri_normals(self.P, self.T)
        self.tri_area2 = _norm(An)
        self.tri_n = _unit(An)
        topo = EdgeTable(self.T, nv)
        self.topo = topo
        E = topo.E
        f0 = topo.h0 // 3
        f1 = np.where(topo.h1 >= 0, topo.h1 // 3, -1)
        inner = f1 >= 0
        g1 = np.maximum(f1, 0)
        cosd = np.where(inner, _dot(self.tri_n[f0], self.tri_n[g1]), 1.0)
        degen = (self.tri_area2[f0] <= 1e-24 * self.diag ** 2) | (self.tri_area2[g1] <= 1e-24 * self.diag ** 2)
        dihedral = np.degrees(np.arccos(np.clip(cosd, -1, 1)))
        sharp = inner & ~degen & (dihedral > feature_angle)
        border = ~inner
        if keep_component_borders:
            border |= inner & (self.tri_comp[f0] != self.tri_comp[g1])
        self.edge_dihedral = np.where(inner & ~degen, dihedral, 0.0)
        self.f0, self.f1 = f0, f1
        self.delta = float(delta)
        self.feature_angle = float(feature_angle)
        self.w_cut = 2.0 * self.delta
        isfeat = sharp | border
        # ------------------------------------------------------------ thin patches
        # a feature-bounded patch narrower than w_cut (2 * area / perimeter) is merged
        # into its neighbours: cutting across it deviates less than max_deviation, and
        # keeping its outline would force slivers (wing-tip strips of the bwb).
        self.n_thin_patches = 0
        for _ in range(4):
            patch = self._patches(isfeat)
            thin = self._thin_patches(patch, isfeat)
            drop = isfeat & ~border & (thin[patch[f0]] | thin[patch[g1]])
            if not drop.any():
                break
            self.n_thin_patches += int(thin.sum())
            isfeat &= ~drop
        self.tri_patch = patch
        self._build_chains(E[isfeat], corner_angle)
        # ------------------------------------------------------------ thin pairs
        # two feature lines closer than w_cut over a stretch where they are far apart
        # along the feature graph (a wedge at a sharp trailing-edge tip, the two creases
        # of a coarsely faceted leading edge): the weaker line is dropped along that
        # stretch; its new ends become corners with a small local size.
        self.n_thin_pairs = 0
        for _ in range(3):
            drop = self._thin_pairs(isfeat, border, wedge_angle)
            drop &= ~border
            if not drop.any():
                break
            isfeat &= ~drop
            self.tri_patch = self._patches(isfeat)
            self._build_chains(E[isfeat], corner_angle)
        deg1 = np.bincount(E[isfeat].reshape(-1), minlength=nv)
        # dangling line ends: lines cut above, and lines fading into a smooth tight fold
        # (a sharp trailing edge running into a rounded tip cap)
        self.cut_corners = np.flatnonzero(deg1 == 1)
        self.is_feature_edge = isfeat

        self._ctree = None
        self.h = np.full(nv, self.target)
        self.reason = np.full(nv, -1, np.int8)
        self.h_min = self.target
        self.field = None
        self.turn_field = None

    # ------------------------------------------------------------------ patches
    def _patches(self, isfeat):
        """Connected components of triangles across non-feature edges."""
        f0, f1 = self.f0, self.f1
        keep = (f1 >= 0) & ~isfeat
        nt = len(self.T)
        g = sparse.coo_matrix((np.ones(int(keep.sum())), (f0[keep], f1[keep])), shape=(nt, nt))
        return connected_components(g, directed=False)[1].astype(np.int64)

    def _thin_patches(self, patch, isfeat):
        """Patches whose mean width 2 * area / perimeter is below w_cut."""
        npatch = int(patch.max()) + 1
        area = np.bincount(patch, weights=0.5 * self.tri_area2, minlength=npatch)
        E = self.topo.E
        L = edge_lengths(self.P, E)
        per = np.bincount(patch[self.f0[isfeat]], weights=L[isfeat], minlength=npatch)
        in1 = isfeat & (self.f1 >= 0)
        per += np.bincount(patch[self.f1[in1]], weights=L[in1], minlength=npatch)
        return (per > 0) & (2.0 * area < self.w_cut * per)

    def _thin_pairs(self, isfeat, border, wedge_angle, lfs_radius=None):
        """Mask of input edges to un-feature: stretches of feature lines lying within
        w_cut of another line (or of a far part of the same line) although the two are
        more than 1 / sin(wedge_angle / 2) times farther apart along the feature graph;
        of each such pair the weaker line (smaller mean dihedral; open boundaries and
        component borders count as strongest) loses the stretch. Also drops dangling
        lines shorter than w_cut."""
        E = self.topo.E
        drop = np.zeros(len(E), bool)
        if not self.n_chains:
            return drop if lfs_radius is None else (np.zeros(0, np.int64), np.zeros(0))
        nch = self.n_chains
        cc, cv, cS = self.ch_c, self.ch_v, self.ch_S
        seg = np.flatnonzero(cc[1:] == cc[:-1])            # chain segments i -> i+1
        va, vb = cv[seg], cv[seg + 1]
        eid = self.topo.lookup(va, vb)
        L = _norm(self.P[vb] - self.P[va])
        dih = np.where(border[eid], 180.0, self.edge_dihedral[eid])
        strength = np.bincount(cc[seg], weights=dih * L, minlength=nch) / np.maximum(
            np.bincount(cc[seg], weights=L, minlength=nch), 1e-300)
        # dangling short lines
        fdeg = np.bincount(E[isfeat].reshape(-1), minlength=len(self.P))
        dangling = (fdeg[self.ch_first_v] == 1) | (fdeg[self.ch_last_v] == 1)
        short = dangling & (self.ch_len < self.w_cut) & (strength < 180.0)
        if lfs_radius is None:
            drop[eid[short[cc[seg]]]] = True
        # samples every w_cut / 2 along the lines
        k = np.maximum(np.ceil(L / (0.5 * self.w_cut)).astype(np.int64), 1)
        if k.sum() > 5_000_000:
            return drop if lfs_radius is None else (np.zeros(0, np.int64), np.zeros(0))
        owner = np.repeat(np.arange(len(seg)), k)
        t = (np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k) + 0.5) / k[owner]
        X = self.P[va[owner]] + t[:, None] * (self.P[vb[owner]] - self.P[va[owner]])
        Ssm = cS[seg[owner]] + t * (cS[seg[owner] + 1] - cS[seg[owner]])
        Csm = cc[seg[owner]]
        radius = self.w_cut if lfs_radius is None else lfs_radius
        pairs = cKDTree(X).query_pairs(radius, output_type="ndarray")
        if not len(pairs):
            return drop if lfs_radius is None else (np.zeros(0, np.int64), np.zeros(0))
        i, j = pairs[:, 0], pairs[:, 1]
        d = _norm(X[i] - X[j])
        ci, cj = Csm[i], Csm[j]
        si = Ssm[i] - self.ch_off[ci]
        sj = Ssm[j] - self.ch_off[cj]
        li, lj = self.ch_len[ci], self.ch_len[cj]
        g = np.full(len(i), np.inf)
        same = ci == cj
        ds = np.abs(si - sj)
        g[same] = np.where(self.ch_closed[ci[same]], np.minimum(ds[same], li[same] - ds[same]), ds[same])
        fi, la_i = self.ch_first_v[ci], self.ch_last_v[ci]
        fj, la_j = self.ch_first_v[cj], self.ch_last_v[cj]
        for ei, ai in ((fi, si), (la_i, li - si)):
            for ej, aj in ((fj, sj), (la_j, lj - sj)):
                m = ~same & (ei == ej)
                g[m] = np.minimum(g[m], (ai + aj)[m])
        if lfs_radius is not None:
            # local feature size: lines facing each other (closer than half their distance
            # along the feature graph) at distance d want edges no longer than 2 d there
            near = g > 2.0 * d
            return np.concatenate([va[owner[i[near]]], vb[owner[i[near]]], va[owner[j[near]]],
                                   vb[owner[j[near]]]]), np.tile(d[near], 4)
        thin = (g * np.sin(np.radians(wedge_angle) / 2.0) > d) & (d < self.w_cut)
        if not thin.any():
            return drop
        i, j, ci, cj, same = i[thin], j[thin], ci[thin], cj[thin], same[thin]
        # weaker line loses the stretch (ties: the higher chain id); a folded line both sides
        wi = (strength[ci] < strength[cj]) | ((strength[ci] == strength[cj]) & (ci > cj)) | same
        wj = ~wi | same
        lose = np.concatenate([owner[i[wi]], owner[j[wj]]])
        keep_border = border[eid[lose]]
        drop[eid[lose[~keep_border]]] = True
        self.n_thin_pairs += int(len(np.unique(np.stack([np.minimum(ci, cj), np.maximum(ci, cj)], 1), axis=0)))
        return drop

    def _prefix(self, vv, reach, cap=4000):
        """Leading vertices of polyline vv up to arc length ``reach`` (at most ``cap``)."""
        X = self.P[vv[:cap]]
        cum = np.concatenate([[0.0], np.cumsum(_norm(X[1:] - X[:-1]))])
        k = int(np.searchsorted(cum, reach, side="right")) + 1
        return vv[:max(2, min(k, len(X)))]

    def _point_at(self, vv, s):
        """Point at arc length s along the polyline through vertices vv."""
        X = self.P[vv]
        seg = _norm(X[1:] - X[:-1])
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        i = int(np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1))
        t = 0.0 if seg[i] <= 0 else min(max((s - cum[i]) / seg[i], 0.0), 1.0)
        return X[i] + t * (X[i + 1] - X[i])

    # ------------------------------------------------------------------ chains
    def _build_chains(self, FE, corner_angle):
        """Cut the feature graph at corners into chains; arc-length parametrise them."""
        nv = len(self.P)
        k = len(FE)
        deg = np.bincount(FE.reshape(-1), minlength=nv) if k else np.zeros(nv, np.int64)
        corner = (deg > 0) & (deg != 2)
        if k:
            # turning angle at degree-2 vertices
            ends = FE.reshape(-1)
            other = FE[:, ::-1].reshape(-1)
            ptr, order = group_order(ends, nv)
            v2 = np.flatnonzero(deg == 2)
            n1 = other[order[ptr[v2]]]
            n2 = other[order[ptr[v2] + 1]]
            d1 = _unit(self.P[n1] - self.P[v2])
            d2 = _unit(self.P[n2] - self.P[v2])
            turn = 180.0 - np.degrees(np.arccos(np.clip(_dot(d1, d2), -1, 1)))
            corner[v2[turn > corner_angle]] = True
        # label chains: feature edges connected through non-corner vertices
        if k:
            ends = FE.reshape(-1)
            eid = np.repeat(np.arange(k), 2)
            nc = ~corner[ends]
            ptr, order = group_order(ends[nc], nv)
            # each non-corner vertex has exactly two feature edges: connect them
            vs = np.flatnonzero(np.diff(ptr) == 2)
            ea = eid[nc][order[ptr[vs]]]
            eb = eid[nc][order[ptr[vs] + 1]]
            g = sparse.coo_matrix((np.ones(len(vs)), (ea, eb)), shape=(k, k))
            nchain, lab = connected_components(g, directed=False)
            # renumber chains by their smallest edge id (deterministic)
            first = np.full(nchain, k, np.int64)
            np.minimum.at(first, lab, np.arange(k))
            ren = np.empty(nchain, np.int64)
            ren[np.argsort(first, kind="stable")] = np.arange(nchain)
            lab = ren[lab]
            # loops: chains touching no corner; cut them at their smallest vertex
            touches = np.zeros(nchain, bool)
            np.logical_or.at(touches, lab, corner[FE[:, 0]] | corner[FE[:, 1]])
            cut = np.zeros(nv, bool)
            loops = np.flatnonzero(~touches)
            if len(loops):
                vmin = np.full(nchain, nv, np.int64)
                np.minimum.at(vmin, lab, FE.min(1))
                cut[vmin[loops]] = True
            closed = ~touches
            # path graph: interior vertices are nodes, every end (corner or cut) is a slot
            is_end = corner | cut
            node = np.where(is_end[FE], nv + 2 * np.arange(k)[:, None] + np.arange(2)[None, :], FE)
            seglen = edge_lengths(self.P, FE)
            nn = nv + 2 * k + 1
            src = nn - 1
            # start slot of each chain: the end slot with the smallest (edge id, side)
            slot_e, slot_s = np.nonzero(is_end[FE])
            sl_chain = lab[slot_e]
            o = np.lexsort((slot_s, slot_e, sl_chain))
            firstc = np.ones(len(o), bool)
            firstc[1:] = sl_chain[o][1:] != sl_chain[o][:-1]
            start_nodes = node[slot_e[o][firstc], slot_s[o][firstc]]
            rows = np.concatenate([node[:, 0], node[:, 1], np.full(nchain, src)])
            cols = np.concatenate([node[:, 1], node[:, 0], start_nodes])
            w = np.concatenate([seglen, seglen, np.zeros(nchain)])
            # zero-length segments would vanish from the sparse graph: give them a floor
            w = np.where((w <= 0) & (np.arange(len(w)) < 2 * k), 1e-300, w)
            w[2 * k:] = 1e-300
            G = sparse.csr_matrix((w, (rows, cols)), shape=(nn, nn))
            dist = dijkstra(G, directed=True, indices=src)
            # each edge: local arc position of both ends
            s0 = dist[node[:, 0]]
            s1 = dist[node[:, 1]]
            if not (np.isfinite(s0).all() and np.isfinite(s1).all()):
                raise MeshValidationError("feature line extraction failed (disconnected chain); "
                                          "report this input surface")
            # order the chain nodes: each edge contributes its farther end; the start slot opens
            hi_s = np.maximum(s0, s1)
            lo_v = np.where(s0 <= s1, FE[:, 0], FE[:, 1])
            hi_v = np.where(s0 <= s1, FE[:, 1], FE[:, 0])
            clen = np.zeros(nchain)
            np.maximum.at(clen, lab, hi_s)
            # node list of a chain: the start vertex, then the far end of every edge by arc position
            low_node = np.where(s0 <= s1, node[:, 0], node[:, 1])
            is_start = np.isin(low_node, start_nodes)
            st_edge = np.zeros(nchain, np.int64)
            st_edge[lab[is_start]] = np.flatnonzero(is_start)
            cv = np.concatenate([lo_v[st_edge], hi_v])
            cs = np.concatenate([np.zeros(nchain), hi_s])
            cc = np.concatenate([np.arange(nchain), lab])
            o = np.lexsort((cs, cc))
            cv, cs, cc = cv[o], cs[o], cc[o]
            # global arc coordinate: chains laid end to end with a gap of 1 length unit
            off = np.zeros(nchain)
            if nchain > 1:
                off[1:] = np.cumsum(clen[:-1] + 1.0 + clen.max())
            self.ch_S = cs + off[cc]
            self.ch_v = cv
            self.ch_c = cc
            ptr = np.zeros(nchain + 1, np.int64)
            np.cumsum(np.bincount(cc, minlength=nchain), out=ptr[1:])
            self.ch_ptr = ptr
            self.ch_off = off
            self.ch_len = clen
            self.ch_closed = closed
            self.ch_first_v = cv[ptr[:-1]]
            self.ch_last_v = cv[ptr[1:] - 1]
            self.fe_in = FE
            self.fe_in_chain = lab
        else:
            nchain = 0
            self.ch_S = np.zeros(0)
            self.ch_v = np.zeros(0, np.int64)
            self.ch_c = np.zeros(0, np.int64)
            self.ch_ptr = np.zeros(1, np.int64)
            self.ch_off = np.zeros(0)
            self.ch_len = np.zeros(0)
            self.ch_closed = np.zeros(0, bool)
            self.ch_first_v = np.zeros(0, np.int64)
            self.ch_last_v = np.zeros(0, np.int64)
            self.fe_in = np.zeros((0, 2), np.int64)
            self.fe_in_chain = np.zeros(0, np.int64)
            cut = np.zeros(nv, bool)
        self.n_chains = nchain
        kind = np.zeros(nv, np.int8)
        kind[deg > 0] = CHAIN
        kind[corner] = CORNER
        self.v_kind = kind
        # arc coordinate and chain of every interior chain vertex
        self.v_S = np.full(nv, np.nan)
        self.v_chain = np.full(nv, -1, np.int64)
        if nchain:
            inner = kind[self.ch_v] == CHAIN
            # a cut vertex of a loop appears twice (start and end): keep the start (S = 0)
            iv = self.ch_v[inner]
            order = np.lexsort((self.ch_S[inner], iv))
            firstv = np.ones(len(order), bool)
            firstv[1:] = iv[order][1:] != iv[order][:-1]
            sel = np.flatnonzero(inner)[order[firstv]]
            self.v_S[self.ch_v[sel]] = self.ch_S[sel]
            self.v_chain[self.ch_v[sel]] = self.ch_c[sel]

    # ------------------------------------------------------------------ chain geometry
    def chain_wrap(self, S, c):
        """Wrap arc coordinates of closed chains into [start, start + length)."""
        S = np.asarray(S, dtype=np.float64).copy()
        cl = self.ch_closed[c]
        if cl.any():
            s0 = self.ch_off[c[cl]]
            L = self.ch_len[c[cl]]
            S[cl] = s0 + np.mod(S[cl] - s0, L)
        return S

    def chain_point(self, S, c):
        """Points (and h) at arc coordinates S on chains c."""
        S = self.chain_wrap(S, c)
        lo = self.ch_ptr[c]
        hi = self.ch_ptr[c + 1] - 1
        i = np.searchsorted(self.ch_S, S, side="right") - 1
        i = np.clip(i, lo, hi - 1)
        s0 = self.ch_S[i]
        s1 = self.ch_S[i + 1]
        ds = s1 - s0
        t = np.divide(S - s0, ds, out=np.zeros_like(S), where=ds > 0)
        t = np.clip(t, 0.0, 1.0)
        va = self.ch_v[i]
        vb = self.ch_v[i + 1]
        pts = self.P[va] + t[:, None] * (self.P[vb] - self.P[va])
        h = self.h[va] + t * (self.h[vb] - self.h[va])
        return pts, h, S

    def corner_S(self, vin, c, near):
        """Arc coordinate of corner (input vertex ``vin``) as an end of chain ``c``, the end
        nearest to ``near`` when both ends are that corner."""
        s_first = self.ch_off[c]
        s_last = self.ch_off[c] + self.ch_len[c]
        mf = self.ch_first_v[c] == vin
        ml = self.ch_last_v[c] == vin
        pick_last = ml & (~mf | (np.abs(near - s_last) < np.abs(near - s_first)))
        return np.where(pick_last, s_last, s_first)

    # ------------------------------------------------------------------ sizing field
    def set_sizing(self, h_min, gradation, field=None):
        """Curvature- and feature-adapted edge length at every input vertex (``self.h``); with a
        ``field`` (:class:`~shellmesh_mdao.core.sizefield.SizeField`) no longer than it there, and
        :meth:`field_at` gives it wherever a vertex of the remesh is."""
        P = self.P
        nv = len(P)
        target = self.target
        topo = self.topo
        E = topo.E
        f1 = np.where(topo.h1 >= 0, topo.h1 // 3, -1)
        delta = self.delta
        h = np.full(nv, target)
        why = np.full(nv, -1, np.int8)

        def note(hnew, code):
            # the reason of each vertex whose size the term lowers
            lower = hnew < h
            why[lower] = code
            return np.where(lower, hnew, h)

        # (1) isolated kinks: a chord of length l across a kink of angle theta deviates by
        #     l theta / 4, so l <= 4 delta / theta at both ends of every non-feature edge.
        inner = f1 >= 0
        sel = np.flatnonzero(inner & ~self.is_feature_edge)
        theta = np.radians(self.edge_dihedral[sel])
        with np.errstate(divide="ignore"):
            hk = np.where(theta > 0, 4.0 * delta / theta, np.inf)
        hkv = np.full(nv, np.inf)
        for col in (0, 1):
            np.minimum.at(hkv, E[sel, col], hk)
        h = note(hkv, 0)
        # (2) smooth curvature, measured at the scale rho = h_min so that the estimate does
        #     not depend on how finely the input is tessellated: total turning
        #     sum(theta_e * len_e) / total area over the 3x3x3 voxels of size rho around each
        #     vertex; a chord of length l over curvature k deviates by l^2 k / 8.
        rho = h_min
        L = edge_lengths(P, E[sel])
        mass = np.zeros(nv)
        for col in (0, 1):
            mass += np.bincount(E[sel, col], weights=0.5 * theta * L, minlength=nv)
        varea = np.zeros(nv)
        for col in range(3):
            varea += np.bincount(self.T[:, col], weights=self.tri_area2 / 6.0, minlength=nv)
        kappa = _voxel_ratio(P, mass, varea, rho)
        with np.errstate(divide="ignore"):
            hs = np.where(kappa > 0, np.sqrt(8.0 * delta / kappa), np.inf)
        h = note(hs, 0)
        # (2b) turning: the chord bound holds the deviation, but across a fold of radius
        #      r < 2 delta (a leading-edge nose) every chord deviates by less than delta, and
        #      where it lets an edge turn by more than 90 degrees (r < 8 delta / (pi / 2)^2, 0.32
        #      target edges) edges cut across the fold. There no edge spans more than MAX_TURN
        #      of the turning: l <= MAX_TURN r, down to h_turn_min (below h_min; _turning_size).
        #      Only folds that run along a line ask, and only the smooth surface's turning counts
        #      (edges up to the feature angle); within a target edge of a sharper edge that the
        #      thin-feature rules dropped (a tip wedge, the creases of a faceted fin) the remesh
        #      cuts across on purpose and this bound asks nothing; within a target edge of a
        #      wedge (a crease sharper than WEDGE_DIHEDRAL: a sharp trailing edge) it asks for no
        #      less than h_min, the other terms' floor: a fold running into a wedge narrows to no
        #      radius (a round tip's outline reaching the trailing edge) and would ask for h_turn_min
        #      beside the crease's chain, where the remesh leaves degenerate slivers (a fold ending
        #      at a blunter crease, a nose at a tip cap, keeps its radius and asks up to it).
        #      Also evaluated where each remesh vertex is, as a size field (:meth:`field_at`):
        #      graded from where it asks, however coarse the input triangles.
        h_turn_min = TURN_MIN_EDGE_FRACTION * h_min
        smooth_e = theta <= np.radians(self.feature_angle)
        h_turn = _turning_size(P, E[sel[smooth_e]], theta[smooth_e], h_turn_min, target, delta,
                               max(MAX_TURN, 1.5 * self.feature_angle))
        # a fold so tight that an edge at the floor would turn across more than UNRESOLVED_TURN
        # of it cannot be resolved at this size: it asks nothing, and the remesh cuts across it as
        # across a sharp edge (edges at the floor there stood across the fold and faced away)
        h_turn[h_turn * (UNRESOLVED_TURN / MAX_TURN) < h_turn_min] = np.inf
        dropped = sel[~smooth_e]
        if len(dropped):
            near = cKDTree(P[np.unique(E[dropped])]).query(P, distance_upper_bound=target)[0]
            h_turn[np.isfinite(near)] = np.inf
        wedge = np.flatnonzero(inner & (self.edge_dihedral > WEDGE_DIHEDRAL))
        if len(wedge):
            near = np.isfinite(cKDTree(P[np.unique(E[wedge])]).query(P, distance_upper_bound=target)[0])
            h_turn[near] = np.maximum(h_turn[near], h_min)
        h_turn = np.maximum(h_turn, h_turn_min)
        ask = np.flatnonzero(h_turn < target)
        self.turn_field = (SizeField(P[ask], h_turn[ask], max(gradation, 1e-6))
                           if len(ask) else None)
        # (3) chains: turning of the polyline at its interior vertices
        if self.n_chains:
            cv, cS = self.ch_v, self.ch_S
            same_prev = np.zeros(len(cv), bool)
            same_prev[1:] = self.ch_c[1:] == self.ch_c[:-1]
            same_next = np.zeros(len(cv), bool)
            same_next[:-1] = same_prev[1:]
            mid = np.flatnonzero(same_prev & same_next)
            a = P[cv[mid - 1]]
            b = P[cv[mid]]
            c = P[cv[mid + 1]]
            d1 = _unit(b - a)
            d2 = _unit(c - b)
            phi = np.arccos(np.clip(_dot(d1, d2), -1, 1))
            wseg = np.maximum(0.5 * (cS[mid + 1] - cS[mid - 1]), h_min)
            hc = _edge_size(phi, wseg, delta)
            interior = self.v_kind[cv[mid]] == CHAIN
            hcv = np.full(nv, np.inf)
            np.minimum.at(hcv, cv[mid][interior], hc[interior])
            # (4) short chains: no edge longer than the chain itself around it
            lens = self.ch_len
            np.minimum.at(hcv, cv, np.maximum(lens[self.ch_c], h_min))
            h = note(hcv, 3)
        # (5) local feature size: feature lines facing each other at distance d
        lv, ld = self._thin_pairs(self.is_feature_edge, np.zeros(len(E), bool), 0.0,
                                  lfs_radius=0.5 * target)
        hf = np.full(nv, np.inf)
        if len(lv):
            np.minimum.at(hf, lv, 2.0 * ld)
        # (6) dangling line ends (cut wedges, lines fading into a fold): room for
        #     well-shaped triangles around the end
        if len(self.cut_corners):
            hf[self.cut_corners] = np.minimum(hf[self.cut_corners], 2.0 * self.w_cut)
        h = note(hf, 2)
        # (7) the local sizes asked for (members closer than the element size)
        self.field = field
        if field is not None:
            h = note(field.at(P, target), 4)
        h = np.clip(h, h_min, target)
        h = note(h_turn, 1)
        # (8) gradation: h_i <= h_j + gradation * |x_i - x_j|  (multi-source Dijkstra)
        self.h = _grade(P, E, h, gradation)
        why[self.h < h] = 5
        self.reason = why
        self.h_min = h_min

    def field_at(self, x):
        """The size fields at points ``x`` (m, 3): the one given to :meth:`set_sizing` (members
        closer than the element size; not below ``h_min``) and the turning bound's (not below
        ``TURN_MIN_EDGE_FRACTION * h_min``), at most the target."""
        out = np.full(len(x), self.target)
        if self.field is not None:
            out = np.maximum(self.field.at(x, self.target), self.h_min)
        if self.turn_field is not None:
            out = np.minimum(out, self.turn_field.at(x, self.target))
        return out

    def shrink_sizing(self, verts, hnew, gradation):
        """Lower the sizing at input vertices ``verts`` to ``hnew`` (not below ``h_min``; the
        deviation passes: counted as curvature) and grade again."""
        h = self.h.copy()
        np.minimum.at(h, verts, np.maximum(hnew, self.h_min))
        self.reason[h < self.h] = 0
        hg = _grade(self.P, self.topo.E, h, gradation)
        self.reason[hg < h] = 5
        self.h = hg

    def sizing_summary(self) -> dict:
        """The sizing over the input skin in units of the target: ``min``, ``max`` and the
        area-weighted ``median`` of the local size asked for (the size fields included), and
        ``refined``: the share of the skin's area where it is below 0.95 of the target, in all
        and per reason (:data:`SIZING_REASONS`, each vertex counted for the term that set its size)."""
        va = np.zeros(len(self.P))
        for col in range(3):
            va += np.bincount(self.T[:, col], weights=self.tri_area2, minlength=len(self.P))
        va /= max(float(va.sum()), 1e-300)
        h = np.minimum(self.h, self.field_at(self.P)) / self.target
        order = np.argsort(h, kind="stable")
        med = float(h[order][min(np.searchsorted(np.cumsum(va[order]), 0.5), len(h) - 1)])
        low = h < 0.95
        # below 0.95 only by the size fields evaluated anew (graded in space, not along the skin)
        why = np.where(self.h / self.target < 0.95, self.reason, 5)
        refined = {r: float(va[low & (why == k)].sum()) for k, r in enumerate(SIZING_REASONS)}
        return {"min": float(h.min()), "max": float(h.max()), "median": med,
                "refined": float(va[low].sum()), "refined_by": refined}

    def h_at(self, tri, q):
        """Sizing at points q lying on input triangles tri (barycentric interpolation)."""
        t = self.T[tri]
        a, b, c = self.P[t[:, 0]], self.P[t[:, 1]], self.P[t[:, 2]]
        v0, v1, v2 = b - a, c - a, q - a
        d00, d01, d11 = _dot(v0, v0), _dot(v0, v1), _dot(v1, v1)
        d20, d21 = _dot(v2, v0), _dot(v2, v1)
        den = d00 * d11 - d01 * d01
        ok = den > 1e-300
        v = np.divide(d11 * d20 - d01 * d21, den, out=np.full(len(q), 1 / 3), where=ok)
        w = np.divide(d00 * d21 - d01 * d20, den, out=np.full(len(q), 1 / 3), where=ok)
        v = np.clip(v, 0, 1)
        w = np.clip(w, 0, 1)
        s = v + w
        over = s > 1
        v = np.divide(v, s, out=v.copy(), where=over)
        w = np.divide(w, s, out=w.copy(), where=over)
        hh = self.h[t]
        return (1 - v - w) * hh[:, 0] + v * hh[:, 1] + w * hh[:, 2]

    # ------------------------------------------------------------------ projection
    def centroid_tree(self):
        if self._ctree is None:
            self._ctree = cKDTree(self.P[self.T].mean(1))
        return self._ctree

    def project(self, q, nrm, patch=None, min_dot=0.0, hint=None):
        """Closest point of each ``q`` among the input triangles of ``patch`` (if given) whose
        normal has a dot product > ``min_dot`` with ``nrm``; ``hint`` (optional): an input
        triangle near each ``q`` to start the search from (the answer does not depend on it).

        Returns ``(points, triangle, ok)``; where no such triangle is found ``ok`` is False
        and the plain closest point is returned."""
        return project_compatible(self.loc, self.centroid_tree, self.tri_n,
                                   self.tri_patch if patch is not None else None,
                                   q, nrm, patch, min_dot, hint)


def project_compatible(loc, tree_fn, tri_n, tri_patch, q, nrm, patch, min_dot, hint=None):
    cl, ti, _ = loc.closest(q, hint=hint)
    ti = np.asarray(ti, dtype=np.int64)
    ok = _dot(tri_n[ti], nrm) > min_dot
    if tri_patch is not None:
        ok &= tri_patch[ti] == patch
    bad = np.flatnonzero(~ok)
    if len(bad):
        tree = tree_fn()
        T = loc.triangles
        P = loc.points
        for K in (16, 128):
            if not len(bad):
                break
            K = min(K, len(T))
            _, cand = tree.query(q[bad], k=K)
            cand = cand.reshape(len(bad), K)
            owner = np.repeat(np.arange(len(bad)), K)
            cf = cand.reshape(-1)
            good = _dot(tri_n[cf], nrm[bad][owner]) > min_dot
            if tri_patch is not None:
                good &= tri_patch[cf] == patch[bad][owner]
            owner, cf = owner[good], cf[good]
            if not len(cf):
                continue
            t = T[cf]
            x = closest_point_on_triangles(q[bad][owner], P[t[:, 0]], P[t[:, 1]], P[t[:, 2]])
            d = _norm(x - q[bad][owner])
            o = np.lexsort((cf, d, owner))
            firsto = np.ones(len(o), bool)
            firsto[1:] = owner[o][1:] != owner[o][:-1]
            pick = o[firsto]
            rows = bad[owner[pick]]
            cl[rows] = x[pick]
            ti[rows] = cf[pick]
            ok[rows] = True
            bad = np.flatnonzero(~ok)
    return cl, ti, ok


def _point_polyline_distance(X, Y):
    """Distance of each point X[i] to the polyline through Y (dense; small inputs)."""
    if len(Y) < 2:
        return _norm(X - Y[:1])
    a, b = Y[:-1], Y[1:]
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.einsum("kij,ij->ki", X[:, None, :] - a[None], ab) / np.where(L2 > 0, L2, 1.0)
    t = np.clip(t, 0.0, 1.0)
    foot = a[None] + t[:, :, None] * ab[None]
    return np.sqrt(((X[:, None, :] - foot) ** 2).sum(-1)).min(1)


def _voxel_ratio(P, num, den, rho):
    """For every point: sum(num) / max(sum(den), pi rho^2) over the points in the 3x3x3
    block of voxels of size rho around its voxel (vectorised over voxels)."""
    key = np.floor((P - P.min(0)) / rho).astype(np.int64)
    dims = key.max(0) + 3
    lin = (key[:, 0] + 1) * dims[1] * dims[2] + (key[:, 1] + 1) * dims[2] + (key[:, 2] + 1)
    uk, inv = np.unique(lin, return_inverse=True)
    inv = inv.reshape(-1)
    sn = np.bincount(inv, weights=num, minlength=len(uk))
    sd = np.bincount(inv, weights=den, minlength=len(uk))
    tn = np.zeros(len(uk))
    td = np.zeros(len(uk))
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            for dz in (-1, 0, 1):
                q = uk + dx * dims[1] * dims[2] + dy * dims[2] + dz
                pos = np.minimum(np.searchsorted(uk, q), len(uk) - 1)
                hit = uk[pos] == q
                tn[hit] += sn[pos[hit]]
                td[hit] += sd[pos[hit]]
    return tn[inv] / np.maximum(td[inv], np.pi * rho * rho)


def _turning_size(P, E, theta, h_floor, target, delta, trigger):
    """Longest edge at every input point P spanning at most :data:`MAX_TURN` degrees of the
    surface's turning, where the chord bound would let an edge turn more than 90 degrees; inf
    where nothing asks.

    The turning ``theta`` (radians) of the input edges ``E`` times their length, spread along
    them (samples a quarter of the radius apart, summed per cube of that size: where the input
    is tessellated does not matter), is summed over a ball of radius ``R`` around the point;
    over the ball's diameter it is the turning ``t`` across the ball: a fold's turning where the
    point lies on the fold, whichever way it runs (about 0.7 of it, the ball's mean chord, where
    the fold is as wide as the ball); a lone kink's own angle; ``pi k R / 2`` over a curvature
    ``k``. At the radii ``R = h_floor / 2, h_floor, ...`` up to ``target``, where that ball and the
    twice and four times larger ones turn by more than ``trigger`` degrees (above the feature
    angle: never a lone kink), the turning in the ball four times larger runs along a line (a
    fold running on, like a leading edge: not the point of a dome, a spinner or a tail cone,
    nor a tip, whose turning also fades over the larger balls) and the curvature ``t / 2R`` is
    one the chord bound would let an edge turn more than 90 degrees over, the edge asked for is
    ``2 R MAX_TURN / t``: about ``r MAX_TURN`` across a fold of radius ``r`` at the smallest such
    ball (``t`` is about 0.7 of the fold's turning there, the ball's mean chord over its
    diameter: edges of about 1.1 r), the larger ones ask for no less. From the largest ball
    down, each radius looks only at the points the two above it found turning (a fold turns
    the larger balls no less), at one point per cube of a quarter of the radius (its point of
    most turning, the first of equals)."""
    out = np.full(len(P), np.inf)
    if not len(E):
        return out
    ea, ed = P[E[:, 0]], P[E[:, 1]] - P[E[:, 0]]
    L = _norm(ed)
    emid = ea + 0.5 * ed
    lo = P.min(0)
    vmass = np.bincount(E.reshape(-1), weights=np.repeat(theta * L, 2), minlength=len(P))
    trig = np.radians(trigger)
    kmin = (0.5 * np.pi) ** 2 / (8.0 * delta)           # the chord bound's edge turns 90 degrees
    radii = [0.5 * h_floor]
    while radii[-1] < 4.0 * target:
        radii.append(2.0 * radii[-1])
    above = [np.ones(len(P), bool), np.ones(len(P), bool)]    # turning at the two radii above
    lines = [np.zeros(len(P), bool), np.zeros(len(P), bool)]  # along a line there
    for R in radii[::-1]:
        cand = np.flatnonzero(above[0] & above[1])
        hit = np.zeros(len(P), bool)
        lined = np.zeros(len(P), bool)
        if len(cand):
            key = _cube_ids(P[cand], lo, 0.25 * R)
            o = np.lexsort((cand, -vmass[cand], key))
            firsto = np.ones(len(o), bool)
            firsto[1:] = key[o][1:] != key[o][:-1]
            inv = np.empty(len(cand), np.int64)
            inv[o] = np.cumsum(firsto) - 1
            Q = P[cand[o[firsto]]]
            de = cKDTree(Q).query(emid, distance_upper_bound=R + 0.5 * L.max())[0]
            e = np.flatnonzero(de <= R + 0.5 * L)
            turn = np.zeros(len(Q))
            if len(e):
                X, w = _edge_samples(ea[e], ed[e], theta[e] * L[e], 0.25 * R)
                sid = _cube_ids(X, lo, 0.25 * R)
                ws = np.bincount(sid, weights=w)
                Xs = np.stack([np.bincount(sid, weights=w * X[:, c]) for c in range(3)], 1)
                used = ws > 0
                ws, Xs = ws[used], Xs[used] / ws[used, None]
                pairs = cKDTree(Q).sparse_distance_matrix(cKDTree(Xs), R, output_type="ndarray")
                turn = np.bincount(pairs["i"], weights=ws[pairs["j"]], minlength=len(Q)) / (2.0 * R)
                line = _elongated(Q, Xs, ws, pairs["i"], pairs["j"])
            else:
                line = np.zeros(len(Q), bool)
            turn, line = turn[inv], line[inv]
            on = turn > trig
            hit[cand[on]] = True
            lined[cand[line]] = True
            ask = on & lines[0][cand] & (turn > 2.0 * R * kmin) & (R <= target)
            out[cand[ask]] = np.minimum(out[cand[ask]], 2.0 * R * np.radians(MAX_TURN) / turn[ask])
        above = [above[1], hit]
        lines = [lines[1], lined]
    return out


def _elongated(Q, X, w, i, j):
    """Per ball (centre ``Q[i]``): whether the weights ``w[j]`` at ``X[j]`` in it run along a line,
    their spread along their principal axis at least twice that across it (a fold running
    through the ball, not the point of a dome or a cone)."""
    n = len(Q)
    m = np.maximum(np.bincount(i, weights=w[j], minlength=n), 1e-300)
    x = X[j] - Q[i]
    mu = np.stack([np.bincount(i, weights=w[j] * x[:, c], minlength=n) for c in range(3)], 1) / m[:, None]
    S = np.empty((n, 3, 3))
    for a in range(3):
        for b in range(a, 3):
            S[:, a, b] = S[:, b, a] = (np.bincount(i, weights=w[j] * x[:, a] * x[:, b], minlength=n) / m
                                       - mu[:, a] * mu[:, b])
    lam = np.linalg.eigvalsh(S)
    return lam[:, 2] >= 4.0 * np.maximum(lam[:, 1], 0.0)


def _cube_ids(X, lo, a):
    """Per point of ``X``: the number of the cube of edge ``a`` (a lattice from ``lo``) it lies
    in, numbered 0, 1, ... in lexicographic order of the cubes."""
    k = np.floor((X - lo) / a).astype(np.int64)
    o = np.lexsort((k[:, 2], k[:, 1], k[:, 0]))
    new = np.ones(len(o), bool)
    new[1:] = (k[o][1:] != k[o][:-1]).any(1)
    ids = np.empty(len(o), np.int64)
    ids[o] = np.cumsum(new) - 1
    return ids


def _edge_samples(a, d, w, step):
    """Points every about ``step`` along the segments ``a + t d`` and their shares of ``w``."""
    L = _norm(d)
    k = np.maximum(np.ceil(L / step).astype(np.int64), 1)
    owner = np.repeat(np.arange(len(a)), k)
    t = (np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k) + 0.5) / k[owner]
    return a[owner] + t[:, None] * d[owner], (w / k)[owner]


def _edge_size(theta, w, delta):
    """Longest chord keeping the deviation below delta across a bend of angle theta
    spread over width w (both the smooth bound sqrt(8 delta w / theta) and the kink
    bound 4 delta / theta)."""
    with np.errstate(divide="ignore"):
        smooth = np.sqrt(8.0 * delta * w / theta)
        kink = 4.0 * delta / theta
    return np.where(theta > 0, np.minimum(smooth, np.maximum(kink, 0.0)), np.inf)


def _grade(P, E, h, gradation):
    """Smallest field h' <= h with h'_i <= h'_j + gradation |x_i - x_j| along edges."""
    n = len(P)
    if not len(E) or gradation <= 0:
        return h
    L = edge_lengths(P, E) * gradation
    L = np.maximum(L, 1e-300)
    src = n
    rows = np.concatenate([E[:, 0], E[:, 1], np.full(n, src)])
    cols = np.concatenate([E[:, 1], E[:, 0], np.arange(n)])
    base = h.min()
    w = np.concatenate([L, L, h - base + 1e-300])
    G = sparse.csr_matrix((w, (rows, cols)), shape=(n + 1, n + 1))
    d = dijkstra(G, directed=True, indices=src)[:n]
    return np.minimum(h, d + base)
