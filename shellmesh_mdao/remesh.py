"""Skin preparation: isotropic remeshing of the input skin to a target edge length.

The later stages subdivide once at the end (triangles merged into quads, every quad
split into four), so the skin triangulation handed to the imprint stage is built at
``target_edge`` (about ``2 H`` for a final quad size ``H``). :func:`remesh_skin` is a
vectorised Botsch--Kobbelt remesher ("A remeshing approach to multiresolution
modeling", SGP 2004) with

* **batched independent sets**: every split / collapse / flip round selects, in one
  pass over numpy arrays, a set of operations whose neighbourhoods do not overlap
  (local priority maxima), applies them all at once and rebuilds the edge table;
* **feature lines**: input edges with a dihedral angle above ``feature_angle``, open
  boundary edges and component borders are chained into polylines; remesh vertices on
  them are parametrised by arc length along their polyline and only move along it;
  chain end points and junctions (*corners*) never move;
* **exact projection**: every other vertex is put on the closest point of the input
  triangles, restricted to the triangles of its own feature-bounded patch whose normal
  faces the same way as the vertex normal (so a vertex of the upper skin of a 5 % thick
  wing never snaps onto the lower skin across a sharp trailing edge);
* **curvature adaptation**: a sizing field on the input vertices shrinks the edge
  length where the chordal deviation at ``target_edge`` would exceed
  ``max_deviation`` (leading edges, fillets), graded so that neighbouring sizes differ
  by at most ``gradation`` times their distance; after remeshing, edges whose midpoint
  is still farther than ``max_deviation`` from the input shrink the field there and the
  remesher runs again (at most ``deviation_passes`` times).

:func:`improve_triangles` exposes the local clean-up (angle-improving flips of nearly
coplanar triangle pairs, tangential relaxation with projection, inversion checks) for
the imprint stage, which calls it with member chains as extra constrained edges.
"""
from __future__ import annotations

import time

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from .errors import MeshValidationError, SizeError
from .kernels import (collapse_apply, collapse_directions, collapse_select, corner_sin_cos, edge_lengths, edge_lookup,
                      edge_neighbours, edge_rows, edge_table, facing_ok, flip_candidates, greedy_independent,
                      greedy_independent_rings, group_order, move_tests, rank_desc, triangle_normals, vertex_faces)
from .mesh import ShellMesh, bbox_diagonal, cross_rows, dot_norm_rows, dot_rows, dot_unit_rows, reduce_short
from .project import SurfaceLocator, closest_point_on_triangles

__all__ = ["remesh_skin", "improve_triangles", "remesh_statistics", "DEFAULT_DEVIATION_FRACTION",
           "DEFAULT_MIN_EDGE_FRACTION"]

#: ``max_deviation`` defaults to this fraction of ``target_edge`` (the final quads, half
#: as long, then deviate about a quarter of it: 0.05 of the final quad size).
DEFAULT_DEVIATION_FRACTION = 0.1
#: the curvature-adapted edge length never goes below this fraction of ``target_edge``.
DEFAULT_MIN_EDGE_FRACTION = 0.1

_HI = 4.0 / 3.0          # split edges longer than _HI * local size
_LO = 4.0 / 5.0          # collapse edges shorter than _LO * local size
_REGULAR, _CHAIN, _CORNER = 0, 1, 2   # the compiled facing tests (kernels.facing_ok & co.) take kind 0 as regular


# ============================================================================ small kernels
# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


def _tri_normals(P, F):
    """Unnormalised normals (twice the area vectors) of triangles ``F``."""
    return triangle_normals(P, F)


def _tri_min_angle(A, B, C):
    """Smallest interior angle (degrees) of triangles with corners A, B, C (k, 3): the angles
    at A and B are ``arctan2(|u x v|, u . v)`` (numpy's arctan2 on the compiled loop's
    arguments), the third is what remains of pi."""
    return _min_angle_of(corner_sin_cos(A, B, C))


def _min_angle_of(sc):
    """Smallest angle (degrees) of triangles from the (4, k) :func:`~.kernels.corner_sin_cos`
    arguments of their first two corners."""
    a0, a1 = _arctan2_rows(sc)
    return np.degrees(np.minimum(np.minimum(a0, a1), np.pi - a0 - a1))


def _arctan2_rows(sc):
    """``arctan2(sc[0], sc[1])`` and ``arctan2(sc[2], sc[3])`` on fresh arrays, as the numpy
    code before the kernels computed them: on rows of one buffer numpy's AVX-512 loop was seen
    to fall back on its scalar arctan2 (other last bits) in some processes and not others."""
    return (np.arctan2(sc[0].copy(), sc[1].copy()), np.arctan2(sc[2].copy(), sc[3].copy()))


def _tri_angles(P, F):
    """(m, 3) interior angles in degrees."""
    a0, a1 = _arctan2_rows(corner_sin_cos(P[F[:, 0]], P[F[:, 1]], P[F[:, 2]]))
    a0, a1 = np.degrees(a0), np.degrees(a1)
    return np.stack([a0, a1, 180.0 - a0 - a1], 1)


def _expand(ptr, rows):
    """For CSR pointers ``ptr`` and row ids ``rows``: (which row of ``rows``, position in the
    CSR value array) for every entry of those rows."""
    cnt = ptr[rows + 1] - ptr[rows]
    owner = np.repeat(np.arange(len(rows)), cnt)
    start = np.repeat(ptr[rows] - np.cumsum(cnt) + cnt, cnt)
    pos = start + np.arange(int(cnt.sum()))
    return owner, pos


def _hash(ids):
    """Deterministic scrambling of integer ids (Knuth multiplicative hash)."""
    return (np.asarray(ids, dtype=np.uint64) * np.uint64(2654435761)) % np.uint64(4294967291)


def _rank(prio, tiebreak):
    """Unique integer rank of each candidate: larger ``prio`` first, ties broken by a hash of
    ``tiebreak`` (scrambled so that equal priorities do not form spatially ordered chains,
    which would make the independent sets small)."""
    # the hash is a bijection of ids below its prime modulus, so it breaks every tie by itself
    # (the ids as a third key never decided anything); the ranks of
    # np.lexsort((_hash(tiebreak), -prio)), by a compiled radix sort
    return rank_desc(prio, _hash(tiebreak))


# ============================================================================ topology
class _Topo:
    """Edge table of a triangle mesh (edges with one or two incident half-edges)."""

    def __init__(self, F, n, allow_nonmanifold=False):
        m = len(F)
        # the keys lo * n + hi sorted stably, their runs the edges (kernels.edge_table)
        self.he_edge, self.h0, self.h1, cnt, self.E, self.keys = edge_table(F, n)
        if len(cnt) and cnt.max() > 2 and not allow_nonmanifold:
            bad = self.keys[cnt > 2][:3]
            raise MeshValidationError(
                f"the skin has {(cnt > 2).sum()} non-manifold edges (more than two triangles on one "
                f"edge, first node pairs {[[int(k // n), int(k % n)] for k in bad]}): remeshing needs a "
                "manifold skin; remove internal faces or duplicate shells from the input surface")
        self.nonmanifold = cnt > 2      # (allow_nonmanifold only) treated like boundaries
        self.valence = cnt
        self.n = n
        self.m = m
        self._vn = None
        self._vf = None
        self._kptr = None

    def kptr(self):
        """Row pointers of each lower end's edges in ``E`` (E's rows are sorted by key
        lo * n + hi, so by lo: each lo's rows are one run)."""
        if self._kptr is None:
            self._kptr = edge_rows(self.E, self.n)
        return self._kptr

    def lookup(self, u, v):
        """Edge id of node pairs (u, v), -1 where absent (a compiled scan of the few edges
        whose lower end is ``min(u, v)``: :func:`~shellmesh_mdao.kernels.edge_lookup`)."""
        return edge_lookup(self.E, self.kptr(), np.asarray(u).reshape(-1), np.asarray(v).reshape(-1))

    def vertex_neighbors(self):
        """CSR (ptr, nbr) of vertex neighbours."""
        if self._vn is None:
            self._vn = edge_neighbours(self.E, self.n)
        return self._vn

    def vertex_faces(self, F):
        """CSR (ptr, faces) of the faces around each vertex."""
        if self._vf is None:
            self._vf = vertex_faces(F, self.n)
        return self._vf


# ============================================================================ input surface
class _Surface:
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
        An = _tri_normals(self.P, self.T)
        self.tri_area2 = _norm(An)
        self.tri_n = _unit(An)
        topo = _Topo(self.T, nv)
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
        self.h_min = self.target

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
        kind[deg > 0] = _CHAIN
        kind[corner] = _CORNER
        self.v_kind = kind
        # arc coordinate and chain of every interior chain vertex
        self.v_S = np.full(nv, np.nan)
        self.v_chain = np.full(nv, -1, np.int64)
        if nchain:
            inner = kind[self.ch_v] == _CHAIN
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
    def set_sizing(self, h_min, gradation):
        """Curvature- and feature-adapted edge length at every input vertex (``self.h``)."""
        P = self.P
        nv = len(P)
        target = self.target
        topo = self.topo
        E = topo.E
        f1 = np.where(topo.h1 >= 0, topo.h1 // 3, -1)
        delta = self.delta
        h = np.full(nv, target)
        # (1) isolated kinks: a chord of length l across a kink of angle theta deviates by
        #     l theta / 4, so l <= 4 delta / theta at both ends of every non-feature edge.
        inner = f1 >= 0
        sel = np.flatnonzero(inner & ~self.is_feature_edge)
        theta = np.radians(self.edge_dihedral[sel])
        with np.errstate(divide="ignore"):
            hk = np.where(theta > 0, 4.0 * delta / theta, np.inf)
        for col in (0, 1):
            np.minimum.at(h, E[sel, col], hk)
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
        h = np.minimum(h, hs)
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
            interior = self.v_kind[cv[mid]] == _CHAIN
            np.minimum.at(h, cv[mid][interior], hc[interior])
            # (4) short chains: no edge longer than the chain itself around it
            lens = self.ch_len
            np.minimum.at(h, cv, np.maximum(lens[self.ch_c], h_min))
        # (5) local feature size: feature lines facing each other at distance d
        lv, ld = self._thin_pairs(self.is_feature_edge, np.zeros(len(E), bool), 0.0,
                                  lfs_radius=0.5 * target)
        if len(lv):
            np.minimum.at(h, lv, 2.0 * ld)
        # (6) dangling line ends (cut wedges, lines fading into a fold): room for
        #     well-shaped triangles around the end
        if len(self.cut_corners):
            h[self.cut_corners] = np.minimum(h[self.cut_corners], 2.0 * self.w_cut)
        h = np.clip(h, h_min, target)
        # (7) gradation: h_i <= h_j + gradation * |x_i - x_j|  (multi-source Dijkstra)
        self.h = _grade(P, E, h, gradation)
        self.h_min = h_min

    def shrink_sizing(self, verts, hnew, gradation):
        h = self.h.copy()
        np.minimum.at(h, verts, np.maximum(hnew, self.h_min))
        self.h = _grade(self.P, self.topo.E, h, gradation)

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
    def _centroid_tree(self):
        if self._ctree is None:
            self._ctree = cKDTree(self.P[self.T].mean(1))
        return self._ctree

    def project(self, q, nrm, patch=None, min_dot=0.0, hint=None):
        """Closest point of each ``q`` among the input triangles of ``patch`` (if given) whose
        normal has a dot product > ``min_dot`` with ``nrm``; ``hint`` (optional): an input
        triangle near each ``q`` to start the search from (the answer does not depend on it).

        Returns ``(points, triangle, ok)``; where no such triangle is found ``ok`` is False
        and the plain closest point is returned."""
        return _project_compatible(self.loc, self._centroid_tree, self.tri_n,
                                   self.tri_patch if patch is not None else None,
                                   q, nrm, patch, min_dot, hint)


def _project_compatible(loc, tree_fn, tri_n, tri_patch, q, nrm, patch, min_dot, hint=None):
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


# ============================================================================ working mesh
class _Work:
    """Mutable triangle mesh being remeshed, with per-vertex kind and chain coordinates.

    kind: 0 regular (projected on its patch), 1 chain (on input feature polyline, arc
    coordinate ``S`` on chain ``vchain``), 2 corner / fixed (never moves, never removed).
    """

    def __init__(self, P, F, fpatch, kind, S, vchain, vin, vtri, fe, fe_chain, h):
        self.P = P
        self.F = F
        self.fpatch = fpatch
        self.kind = kind
        self.S = S
        self.vchain = vchain
        self.vin = vin
        self.vtri = vtri
        self.h = h
        self.set_features(fe, fe_chain)
        self._topo = None

    @property
    def n(self):
        return len(self.P)

    def set_features(self, fe, fe_chain):
        """The feature edges ``fe`` (k, 2) with their chain ids: each row as (lo, hi), rows
        with lo == hi dropped, sorted by (lo, hi, chain), one row per node pair (the lowest
        chain id)."""
        fe = np.sort(np.asarray(fe, dtype=np.int64).reshape(-1, 2), axis=1)
        fe_chain = np.asarray(fe_chain, dtype=np.int64).reshape(-1)
        keep = fe[:, 0] != fe[:, 1]
        fe, fe_chain = fe[keep], fe_chain[keep]
        if len(fe):
            o = np.lexsort((fe_chain, fe[:, 1], fe[:, 0]))
            fe, fe_chain = fe[o], fe_chain[o]
            u = np.ones(len(fe), bool)
            u[1:] = (fe[1:, 0] != fe[:-1, 0]) | (fe[1:, 1] != fe[:-1, 1])
            fe, fe_chain = fe[u], fe_chain[u]
        self.fe = fe
        self.fe_chain = fe_chain

    allow_nonmanifold = False

    def topo(self):
        if self._topo is None:
            self._topo = _Topo(self.F, self.n, allow_nonmanifold=self.allow_nonmanifold)
        return self._topo

    def touched(self):
        self._topo = None

    def feature_lookup(self, T):
        """(is_feature, chain id) of every edge of ``T``."""
        isf = np.zeros(len(T.E), bool)
        ch = np.full(len(T.E), -1, np.int64)
        if len(self.fe):
            e = T.lookup(self.fe[:, 0], self.fe[:, 1])
            ok = e >= 0
            isf[e[ok]] = True
            ch[e[ok]] = self.fe_chain[ok]
        return isf, ch

    def face_normals(self):
        return _unit(_tri_normals(self.P, self.F))

    def vertex_normals(self):
        An = _tri_normals(self.P, self.F)
        acc = np.zeros((self.n, 3))
        for k in range(3):
            for d in range(3):
                acc[:, d] += np.bincount(self.F[:, k], weights=An[:, d], minlength=self.n)
        return _unit(acc)

    def vertex_patch(self):
        vp = np.full(self.n, -1, np.int64)
        vp[self.F.reshape(-1)] = np.repeat(self.fpatch, 3)
        return vp

    def keep_vertices(self, keep):
        """Drop the per-vertex rows not in ``keep`` (bool); faces and features must already be
        on the new numbering (:func:`~shellmesh_mdao.kernels.collapse_apply`)."""
        for name in ("P", "kind", "S", "vchain", "vin", "vtri", "h"):
            setattr(self, name, getattr(self, name)[keep])
        self.touched()


# ============================================================================ context
class _Ctx:
    """Projection / sizing / chain services shared by the operations.

    ``surf`` is a :class:`_Surface` during remeshing; for :func:`improve_triangles` it is
    None and only ``project`` (normal-compatible closest point) is used."""

    def __init__(self, surf=None, locator=None, max_flip_dihedral=20.0, use_patch=True, min_dot=0.0,
                 delta=None):
        self.surf = surf
        self.delta = delta
        self.max_flip_dihedral = max_flip_dihedral
        self.use_patch = use_patch and surf is not None
        self.min_dot = min_dot
        if surf is not None:
            self.tri_n = surf.tri_n
            self.loc = surf.loc
        else:
            self.loc = locator
            self.tri_n = _unit(_tri_normals(locator.points, locator.triangles))
            self._tree = None

    def _centroid_tree(self):
        if self.surf is not None:
            return self.surf._centroid_tree()
        if self._tree is None:
            self._tree = cKDTree(self.loc.points[self.loc.triangles].mean(1))
        return self._tree

    def project(self, q, nrm, patch, hint=None):
        return _project_compatible(self.loc, self._centroid_tree, self.tri_n,
                                   self.surf.tri_patch if self.use_patch else None,
                                   q, nrm, patch if self.use_patch else None, self.min_dot, hint)

    def sizing(self, W, idx=None):
        """Sizing of vertices ``idx`` of W from the input field (target for improve_triangles)."""
        if idx is None:
            idx = np.arange(W.n)
        if self.surf is None:
            return W.h[idx]
        s = self.surf
        h = np.empty(len(idx))
        k = W.kind[idx]
        r = k == _REGULAR
        h[r] = s.h_at(W.vtri[idx[r]], W.P[idx[r]])
        c = k == _CHAIN
        if c.any():
            _, hc, _ = s.chain_point(W.S[idx[c]], W.vchain[idx[c]])
            h[c] = hc
        q = k == _CORNER
        h[q] = s.h[W.vin[idx[q]]]
        return h

    def chain_S_of(self, W, v, c, near):
        """Arc coordinate of vertex v as a point of chain c (corners: the end nearest ``near``)."""
        S = W.S[v].copy()
        cor = W.kind[v] == _CORNER
        if cor.any():
            S[cor] = self.surf.corner_S(W.vin[v[cor]], c[cor], near[cor])
        return S

    def chain_delta(self, c, d):
        """Wrap arc differences on closed chains into (-L/2, L/2]."""
        s = self.surf
        cl = s.ch_closed[c]
        if cl.any():
            L = s.ch_len[c[cl]]
            d = d.copy()
            d[cl] = d[cl] - L * np.round(d[cl] / L)
        return d


# ============================================================================ operations
_COS_FACING = np.cos(np.radians(80.0))
_COS_TURNED = np.cos(np.radians(100.0))


def _facing_ok(W, ctx, Fn, nrm):
    """Faces (k, 3) with unit normals ``nrm``: True unless the face has regular corners and
    its normal is more than 80 degrees from the input normal at every one of them (a face
    standing across the surface, e.g. through a thin wing from the upper to the lower skin)."""
    return facing_ok(Fn, W.kind, W.vtri, ctx.tri_n, nrm, _COS_FACING)


def _micro_round(W, ctx, eps):
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
    return _collapse_edges(W, ctx, T, cand, prio=-L[cand], check_geometry=False)


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


def _split_round(W, ctx, forced=None, min_angle_guard=0.0, deviation=None):
    """Split, in one batch, the longest edges (> 4/3 local size), at most one per face
    (or the edges ``forced``; ``deviation``: the distance of every edge's midpoint to the
    input, when the caller has it)."""
    T = W.topo()
    E = T.E
    P = W.P
    L = edge_lengths(P, E)
    he = 0.5 * (W.h[E[:, 0]] + W.h[E[:, 1]])
    cand = np.flatnonzero(L > _HI * he) if forced is None else np.unique(forced)
    if not len(cand):
        return 0
    rank = _rank(np.round(L[cand] / he[cand], 1), cand)
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
        Sa0 = np.where(W.kind[aa] == _CHAIN, W.S[aa], np.nan)
        Sb0 = np.where(W.kind[bb] == _CHAIN, W.S[bb], np.nan)
        nearA = np.where(np.isnan(Sb0), ctx.surf.ch_off[c], Sb0)
        Sa = ctx.chain_S_of(W, aa, c, nearA)
        Sb = ctx.chain_S_of(W, bb, c, np.where(np.isnan(Sa0), Sa, Sa0))
        d = ctx.chain_delta(c, Sb - Sa)
        pts, _, Sm = ctx.surf.chain_point(Sa + 0.5 * d, c)
        newP[fm] = pts
        newkind[fm] = _CHAIN
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
            old = _tri_min_angle(P[va], P[vb], P[vc])
            new1 = _tri_min_angle(P[va], newP, P[vc])
            new2 = _tri_min_angle(newP, P[vb], P[vc])
            ok &= ~valid | gross | (np.minimum(new1, new2) >= np.minimum(min_angle_guard, 0.5 * old))
            # and none of them may turn over: a normal more than 100 degrees from the input
            # normal at the new point (a split across a nose much tighter than the edge, whose
            # projected midpoint lands beside the two faces instead of between them)
            if rm.any():
                tn = ctx.tri_n[np.maximum(newtri, 0)]
                for t3 in ((P[va], newP, P[vc]), (newP, P[vb], P[vc])):
                    nn = _unit(cross_rows(t3[1] - t3[0], t3[2] - t3[0]))
                    ok &= ~valid | fm | (newtri < 0) | (_dot(nn, tn) > _COS_TURNED)
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


def _collapse_round(W, ctx, max_normal_turn=45.0, quality=False):
    """Collapse, in one batch, short edges (< 4/5 local size) with disjoint neighbourhoods."""
    T = W.topo()
    E = T.E
    P = W.P
    L = edge_lengths(P, E)
    he = 0.5 * (W.h[E[:, 0]] + W.h[E[:, 1]])
    prio = np.where(L < _LO * he, -(L / he), -np.inf)
    # regular vertices of valence 3 (a vertex inside a triangle of its neighbours) are
    # removed along their shortest edge whatever its length: they block collapses around
    nptr, nbr = T.vertex_neighbors()
    deg = np.diff(nptr)
    v3 = np.flatnonzero((deg == 3) & (W.kind == _REGULAR))
    # a feature-line end (degree 1 in the feature graph) left with valence 3 sits in a
    # sliver fan (a sharp trailing edge fading into a tight tip fold): it gives way to
    # its neighbour on the line, which becomes the new end
    fdeg = np.bincount(W.fe.reshape(-1), minlength=W.n) if len(W.fe) else np.zeros(W.n, np.int64)
    dang = np.flatnonzero((deg == 3) & (W.kind == _CORNER) & (fdeg == 1))
    if len(dang):
        ends = W.fe.reshape(-1)
        other = W.fe[:, ::-1].reshape(-1)
        pos = np.searchsorted(np.sort(ends), dang)
        o = np.argsort(ends, kind="stable")
        nb = other[o[pos]]
        ed = T.lookup(dang, nb)
        ok = (ed >= 0) & (W.kind[nb] == _CHAIN)
        prio[ed[ok]] = 1.0
        dang = dang[ok]
        v3 = np.concatenate([v3, dang])
    if len(v3) and (W.kind[v3] == _REGULAR).any():
        v3r = v3[W.kind[v3] == _REGULAR]
        nb = nbr[nptr[v3r][:, None] + np.arange(3)[None, :]]
        d = np.sqrt(((P[nb] - P[v3r][:, None, :]) ** 2).sum(-1))
        e3 = T.lookup(v3r, nb[np.arange(len(v3r)), np.argmin(d, axis=1)])
        prio[e3] = 1.0
    cand = np.flatnonzero(np.isfinite(prio))
    if not len(cand):
        return 0
    return _collapse_edges(W, ctx, T, cand, prio=prio[cand], max_normal_turn=max_normal_turn,
                           quality=quality, remove_first=v3)


def _collapse_edges(W, ctx, T, cand, prio, max_normal_turn=45.0, quality=False, max_len_ratio=_HI,
                    remove_first=None, check_geometry=True):
    """Collapse a maximal independent set of the candidate edges ``cand`` (higher ``prio``
    first). Cheap topological tests run on all candidates; the geometric tests only on
    the candidates that win their neighbourhood in a selection sub-round: the sweeps' tests
    (new edges against the local size, normal turn, facing, smallest angle), or with
    ``check_geometry=False`` the facing tests only, both in the compiled selection
    (:func:`~shellmesh_mdao.kernels.collapse_select`); with ``quality=True`` (the clean-up:
    the smallest angle must rise, new edges within max_deviation) in numpy, called back each
    sub-round."""
    if quality and not check_geometry:
        raise ValueError("_collapse_edges: the clean-up's quality tests include the geometric ones")
    E = T.E
    P = W.P
    n = W.n
    F = W.F
    isf, _ = W.feature_lookup(T)
    nptr, nbr = T.vertex_neighbors()
    fptr, vf = T.vertex_faces(F)
    # chain vertex counts (a closed chain keeps >= 3 vertices, a chain through one corner >= 2)
    chain_ok_v = np.ones(n, bool)
    if ctx.surf is not None and ctx.surf.n_chains:
        s = ctx.surf
        cnt = np.bincount(W.vchain[W.kind == _CHAIN], minlength=s.n_chains)
        need = np.where(s.ch_closed, 3, np.where(s.ch_first_v == s.ch_last_v, 2, 0))
        cv = W.kind == _CHAIN
        chain_ok_v[cv] = cnt[W.vchain[cv]] > need[W.vchain[cv]]
    # ---- cheap tests: opposite valences, link condition, no pinching, vertex kinds (dangling
    #      feature-line ends listed in remove_first may go along their line; an edge at a
    #      vertex to be removed may only remove that vertex), in one compiled pass
    u, v = E[cand, 0], E[cand, 1]
    _, dir_ok = collapse_directions(E, cand, T.h0, T.h1, T.valence, F, nptr, nbr, W.kind, isf, chain_ok_v,
                                     remove_first=remove_first)
    alive = dir_ok[:, 0] | dir_ok[:, 1]
    if not alive.any():
        return 0
    fn_old = _unit(_tri_normals(P, F)) if check_geometry else None     # the facing tests need no normal turn
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
        ow, pos = _expand(nptr, a)
        xx = nbr[pos]
        m = xx != b[ow]
        ow, xx = ow[m], xx[m]
        r = _norm(P[xx] - P[b[ow]]) / (0.5 * (W.h[xx] + W.h[b[ow]]))
        rmax = np.zeros(k)
        np.maximum.at(rmax, ow, r)
        okd &= rmax <= max_len_ratio
        if not okd.all():
            return allowed_only(a, b, okd)
        ow, pos = _expand(fptr, a)
        ff = vf[pos]
        Fa = F[ff]
        Q0 = P[Fa]
        amin_old = np.full(k, np.inf)
        np.minimum.at(amin_old, ow, _tri_min_angle(Q0[:, 0], Q0[:, 1], Q0[:, 2]))
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
        okd &= ~(np.bincount(ow, weights=~_facing_ok(W, ctx, Fb, _unit(nn)), minlength=k) > 0)
        # the smallest new angle strictly above the smallest old one
        amin_new = np.full(k, np.inf)
        np.minimum.at(amin_new, ow, _tri_min_angle(Q[:, 0], Q[:, 1], Q[:, 2]))
        okd &= amin_new > amin_old
        if ctx.delta is not None and okd.any():
            # clean-up collapses must keep the new edges within max_deviation
            ow2, pos2 = _expand(nptr, a)
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
        a, b = collapse_select(nptr, nbr, fptr, vf, F, P, W.h, u, v, _rank(prio, cand), dir_ok, kind=W.kind,
                               vtri=W.vtri, tri_n=ctx.tri_n, cos_facing=_COS_FACING, max_len_ratio=max_len_ratio,
                               fn_old=fn_old, cos_turn=cos_turn,
                               surface=None if check_geometry else ctx.loc.compiled_tree(), max_sub=16)
        if not len(a):
            return 0
    else:
        greedy_independent_rings(nptr, nbr, u, v, _rank(prio, cand), alive=alive, check=check, max_sub=16)
        if not acc_a:
            return 0
        a = np.concatenate(acc_a)
        b = np.concatenate(acc_b)
    # faces, feature edges (as set_features tabulates them) and vertex numbering after the
    # batch, in one compiled pass; then the per-vertex arrays without the removed vertices
    W.F, W.fpatch, W.fe, W.fe_chain, keepv = collapse_apply(F, W.fpatch, W.fe, W.fe_chain, a, b, n)
    W.keep_vertices(keepv)
    return len(a)


def _flip_round(W, ctx, mode):
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
        ang = np.radians(_tri_angles(P, F))
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
                                                       W.kind, W.vtri, ctx.tri_n, _COS_FACING, deg, tgt)
    if not len(cand):
        return 0
    a, b, c, d = abcd.T
    f0, f1 = ff.T
    old = np.minimum(_min_angle_of(sc[0]), _min_angle_of(sc[1]))
    new = np.minimum(_min_angle_of(sc[2]), _min_angle_of(sc[3]))
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
    rank = _rank(prio[sel], cand[sel])
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


def _relax(W, ctx, lam=1.0, move_chains=True, movable=None, min_angle_floor=10.0):
    """Tangential relaxation (area-weighted centroid of the incident triangles) of the
    regular vertices, projected back onto the input; chain vertices move to the midpoint
    of their chain neighbours in arc length. Moves that would turn a face by more than 60
    degrees (or invert it against the input normal) are undone."""
    F = W.F
    P = W.P
    n = W.n
    An = _tri_normals(P, F)
    area = _norm(An)
    C = (P[F[:, 0]] + P[F[:, 1]] + P[F[:, 2]]) / 3          # P[F].mean(1), the same bits
    wsum = np.zeros(n)
    acc = np.zeros((n, 3))
    for k in range(3):
        wsum += np.bincount(F[:, k], weights=area, minlength=n)
        for dd in range(3):
            acc[:, dd] += np.bincount(F[:, k], weights=area * C[:, dd], minlength=n)
    vn = W.vertex_normals()
    reg = W.kind == _REGULAR
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
        ci = np.flatnonzero(W.kind == _CHAIN)
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
    reg = W.kind == _REGULAR
    amin_old = _tri_min_angle(P[F[:, 0]], P[F[:, 1]], P[F[:, 2]])
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
                             _COS_FACING)
        # no face may end up with a smaller angle than min(its old smallest angle, 10 deg)
        bad |= _min_angle_of(sc) < np.minimum(amin_old[fi], min_angle_floor)
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


# ============================================================================ driver
def _work_from_surface(surf):
    nv = len(surf.P)
    ptr, order = group_order(surf.T.reshape(-1), nv)
    vtri = np.where(np.diff(ptr) > 0, order[np.minimum(ptr[:-1], len(order) - 1)] // 3, -1)
    vtri = np.where(surf.v_kind == _REGULAR, vtri, -1)
    vin = np.where(surf.v_kind == _CORNER, np.arange(nv), -1)
    W = _Work(surf.P.copy(), surf.T.copy(), surf.tri_patch.copy(), surf.v_kind.copy(), surf.v_S.copy(),
              surf.v_chain.copy(), vin, vtri, surf.fe_in.copy(), surf.fe_in_chain.copy(), surf.h.copy())
    return W


def _phase(fn, W, ctx, max_rounds, *args, **kw):
    """Repeat a batched operation until it stalls (fewer than 0.2 % of the faces changed
    per round; the next sweep takes up the rest after relaxation)."""
    total = 0
    for _ in range(max_rounds):
        k = fn(W, ctx, *args, **kw)
        total += k
        if k <= 0.002 * len(W.F):
            break
    return total


def _iterate(W, ctx, iterations, timings, log):
    for it in range(iterations):
        t0 = time.perf_counter()
        ns = _phase(_split_round, W, ctx, 60)
        t1 = time.perf_counter()
        nc = _phase(_collapse_round, W, ctx, 200)
        t2 = time.perf_counter()
        nf = _phase(_flip_round, W, ctx, 10, "valence")
        t3 = time.perf_counter()
        _relax(W, ctx)
        W.h = ctx.sizing(W)
        t4 = time.perf_counter()
        for k, dt in zip(("split", "collapse", "flip", "relax"), (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
            timings[k] = timings.get(k, 0.0) + dt
        if log:
            log(f"iteration {it}: {ns} splits, {nc} collapses, {nf} flips -> {len(W.F)} triangles")


def _open_low_valence_corners(W, ctx):
    """A corner (or line end) with only three neighbours but a full fan of angles around it
    (a trailing edge ending in a rounded tip) cannot lose the slivers around it by
    collapses: split the edge facing its widest angle so that it gets a fourth neighbour."""
    T = W.topo()
    F = W.F
    nptr, _ = T.vertex_neighbors()
    deg = np.diff(nptr)
    ang = np.radians(_tri_angles(W.P, F))
    asum = np.zeros(W.n)
    for k in range(3):
        asum += np.bincount(F[:, k], weights=ang[:, k], minlength=W.n)
    low = (deg == 3) & (W.kind != _REGULAR) & (asum > np.radians(200.0))
    if not low.any():
        return 0
    fi, ki = np.nonzero(low[F])
    # per low vertex: its face with the widest angle there
    o = np.lexsort((-ang[fi, ki], F[fi, ki]))
    first = np.ones(len(o), bool)
    first[1:] = F[fi, ki][o][1:] != F[fi, ki][o][:-1]
    fi, ki = fi[o][first], ki[o][first]
    e = T.lookup(F[fi, (ki + 1) % 3], F[fi, (ki + 2) % 3])
    isf, _ = W.feature_lookup(T)
    e = e[(e >= 0) & ~isf[np.maximum(e, 0)]]
    if not len(e):
        return 0
    return _split_round(W, ctx, forced=e)


def _cleanup_round(W, ctx, bad_angle=20.0):
    """Collapse the shortest edge of every triangle whose smallest angle is below
    ``bad_angle`` when that strictly raises the smallest angle around it (looser length
    and normal limits than the sweeps: the aim is the worst triangles only)."""
    T = W.topo()
    F = W.F
    P = W.P
    A = _tri_angles(P, F)
    bad = np.flatnonzero(reduce_short(A, "min") < bad_angle)
    if not len(bad):
        return 0
    # the shortest side is opposite the smallest angle
    k = np.argmin(A[bad], axis=1)
    e = T.lookup(F[bad, (k + 1) % 3], F[bad, (k + 2) % 3])
    e = np.unique(e[e >= 0])
    if not len(e):
        return 0
    L = edge_lengths(P, T.E[e])
    return _collapse_edges(W, ctx, T, e, prio=-L, max_normal_turn=60.0, quality=True, max_len_ratio=2.0)


def _standing_faces(W, ctx):
    """Faces standing across the surface (see :func:`_facing_ok`)."""
    return np.flatnonzero(~_facing_ok(W, ctx, W.F, W.face_normals()))


def _unstand_round(W, ctx):
    """Collapse an edge of every face standing across the surface (shortest first), with
    the topological, inversion and facing tests only."""
    bad = _standing_faces(W, ctx)
    if not len(bad):
        return 0
    T = W.topo()
    F = W.F
    e = np.unique(np.concatenate([T.lookup(F[bad, k], F[bad, (k + 1) % 3]) for k in range(3)]))
    e = e[e >= 0]
    L = edge_lengths(W.P, T.E[e])
    return _collapse_edges(W, ctx, T, e, prio=-L, check_geometry=False)


def _finish(W, ctx, rounds, timings, log):
    t0 = time.perf_counter()
    if _open_low_valence_corners(W, ctx):
        W.h = ctx.sizing(W)
    _phase(_micro_round, W, ctx, 20, 0.25)
    W.h = ctx.sizing(W)
    for _ in range(rounds):
        _phase(_flip_round, W, ctx, 10, "angle")
        _phase(_cleanup_round, W, ctx, 5)
        _relax(W, ctx)
        W.h = ctx.sizing(W)
    _phase(_flip_round, W, ctx, 10, "angle")
    _phase(_cleanup_round, W, ctx, 5)
    _phase(_flip_round, W, ctx, 10, "angle")
    timings["finish"] = timings.get("finish", 0.0) + time.perf_counter() - t0


class _MidpointDistances:
    """Distance of edge midpoints to the input (``loc.closest``), remembered by the midpoint's
    exact coordinates: the remesh's last steps ask for every edge of a mesh of which only a
    few edges are new since the last time, and a midpoint's distance depends on its
    coordinates alone (a hint only shortens the search), so the answers are the same bits
    as asking for every edge again."""

    def __init__(self, loc):
        self.loc = loc
        self.keys = np.zeros(0, np.uint64)
        self.mid = np.zeros((0, 3))
        self.dist = np.zeros(0)

    @staticmethod
    def _keys(X):
        """One uint64 per row of (k, 3) float64 ``X``, equal for rows of equal bits (rows with
        equal keys are compared in full before a distance is reused)."""
        b = np.ascontiguousarray(X).view(np.uint64)
        return (b[:, 0] * np.uint64(0x9E3779B97F4A7C15)) ^ (b[:, 1] * np.uint64(0xC2B2AE3D27D4EB4F)) ^ b[:, 2]

    def __call__(self, P, E, vtri):
        mid = 0.5 * (P[E[:, 0]] + P[E[:, 1]])
        keys = self._keys(mid)
        dist = np.empty(len(E))
        miss = np.ones(len(E), bool)
        if len(self.keys) and len(E):
            o = np.argsort(self.keys, kind="stable")
            pos = np.minimum(np.searchsorted(self.keys[o], keys), len(o) - 1)
            j = o[pos]
            hit = (self.keys[j] == keys) & (self.mid[j] == mid).all(1)
            dist[hit] = self.dist[j[hit]]
            miss = ~hit
        if miss.any():
            _, _, dist[miss] = self.loc.closest(mid[miss], hint=vtri[E[miss, 0]])
        self.keys, self.mid, self.dist = keys, mid, dist
        return dist


def _deviation(W, ctx, mids):
    """Distance from edge midpoints (and face centroids) to the input, with the input
    triangle each face centroid projects to (patch and normal compatible); the midpoints'
    distances from ``mids`` (a :class:`_MidpointDistances`)."""
    T = W.topo()
    E = T.E
    dm = mids(W.P, E, W.vtri)
    C = (W.P[W.F[:, 0]] + W.P[W.F[:, 1]] + W.P[W.F[:, 2]]) / 3
    fn = W.face_normals()
    cp, ctri, ok = ctx.project(C, fn, W.fpatch, hint=W.vtri[W.F[:, 0]])
    dc = _norm(cp - C)
    return dm, dc, ctri, ok


def remesh_skin(mesh: ShellMesh, target_edge: float, *, feature_angle: float = 30.0,
                max_deviation: float | None = None, iterations: int = 8, min_edge: float | None = None,
                gradation: float = 0.5, corner_angle: float = 50.0, wedge_angle: float = 20.0,
                keep_component_borders: bool = True,
                deviation_passes: int = 2, deviation_pass_fraction: float = 0.0, deviation_splits: bool = True,
                finish_rounds: int = 4,
                max_flip_dihedral: float = 120.0,
                locator: SurfaceLocator | None = None,
                report: dict | None = None, log=None) -> ShellMesh:
    """Isotropic, curvature-adapted remesh of a triangulated skin to ``target_edge``.

    The input's resolution does not set the output's: the result has edges around
    ``target_edge`` on flat regions whatever the input tessellation (a 23.5k- and a 1.5M-
    triangle tessellation of the same aircraft give the same sizes), shorter ones only
    where the surface needs them (curvature, narrow regions between feature lines).

    Deviation guarantee: every vertex lies on the input surface (closest point, float64);
    every edge midpoint lies within ``max_deviation`` of the input unless the edge is
    shorter than ``2 * min_edge`` or splitting it would create a triangle with an angle
    below 20 degrees (``report['n_edges_over_deviation']`` counts those, and
    ``report['deviation_edge_midpoints']`` / ``['deviation_face_centroids']`` give the
    largest distances reached).

    Parameters
    ----------
    mesh : ShellMesh
        The input skin (triangles; quads are split). Must be edge-manifold; open
        boundaries are allowed and kept as feature lines.
    target_edge : float
        Edge length wanted on flat regions (about twice the final quad size ``H``).
    feature_angle : float
        Input edges whose two triangles' normals differ by more than this (degrees) are
        sharp feature lines: kept as chains of mesh edges.
    max_deviation : float, optional
        Chordal deviation allowed between the remesh and the input (absolute length);
        default ``DEFAULT_DEVIATION_FRACTION * target_edge``. Edges shrink where the
        curvature needs it, down to ``min_edge``. Feature lines closer to each other than
        ``2 * max_deviation`` (a wedge at a sharp trailing-edge tip, the two creases of a
        coarsely faceted leading edge, a sliver patch) are merged into one.
    iterations : int
        Split/collapse/flip/relax sweeps (Botsch--Kobbelt) per pass.
    min_edge : float, optional
        Smallest curvature-adapted edge length, default
        ``DEFAULT_MIN_EDGE_FRACTION * target_edge``.
    gradation : float
        Largest rate of change of the edge length with distance (0.5: an edge at
        distance d from a small one is at most 0.5 d longer).
    corner_angle : float
        A feature line turning by more than this (degrees) at a vertex gets a corner
        there (a fixed vertex); feature-line ends and junctions are always corners.
    wedge_angle : float
        Two feature lines leaving a corner at less than this angle (degrees) are treated
        as one line where they are closer than ``2 * max_deviation``.
    keep_component_borders : bool
        Also keep borders between input components as feature lines.
    deviation_passes : int
        Extra passes that shrink the sizing where the measured deviation exceeds
        ``max_deviation`` and remesh again (each re-runs ``iterations // 2`` sweeps and the
        finishing rounds over the whole skin).
    deviation_pass_fraction : float
        A pass runs only while more than this fraction of the edges deviate (default 0: any
        edge); fewer are left to the deviation splits, which split them where they are.
    deviation_splits : bool
        Finally split the edges still deviating too much (see the guarantee above).
    finish_rounds : int
        Angle-improving flip, worst-triangle collapse and relaxation rounds at the end.
    max_flip_dihedral : float
        Largest dihedral (degrees) across which an edge may be flipped during remeshing
        (every flip must also keep the new edge within ``max_deviation`` and not turn a
        triangle against the input normal).
    locator : SurfaceLocator, optional
        A locator already built on the triangles of ``mesh`` (saves rebuilding it).
    report : dict, optional
        Filled with figures: counts, edge-length percentiles relative to the target,
        angles, deviation, timings.
    log : callable, optional
        Called with progress lines.

    Returns
    -------
    ShellMesh
        Triangles, every vertex on the input surface; ``feature_edges`` the sharp lines
        (ids -1); ``fixed_vertices`` their corners (line ends and junctions, sharp turns);
        ``component`` taken from the input triangle each face centroid projects to
        (restricted to the centroid's own feature-bounded patch).

    Raises
    ------
    SizeError
        Non-positive/non-finite sizes, a size larger than the model or one that would
        give more than 5e7 triangles.
    MeshValidationError
        Empty, non-finite or non-manifold input.
    """
    t_start = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("remesh_skin needs a ShellMesh: load the surface with the loader first")
    if mesh.n_faces == 0:
        raise MeshValidationError("the skin has no faces: load a non-empty surface")
    try:
        target = float(target_edge)
    except (TypeError, ValueError):
        raise SizeError(f"target edge length {target_edge!r} is not a number: give a positive size") from None
    if not np.isfinite(target) or target <= 0:
        raise SizeError(f"target edge length {target_edge!r} must be positive and finite: give a positive size")
    if not np.isfinite(mesh.points).all():
        raise MeshValidationError("the skin has NaN/inf coordinates: repair the input surface")
    diag = mesh.diagonal
    if target > diag:
        raise SizeError(f"target edge length {target:g} exceeds the model size (bounding-box diagonal "
                        f"{diag:g}): give a size in the units of the surface file, smaller than the model")
    area = float(mesh.face_areas().sum())
    est = area / (0.433 * target ** 2)
    if est > 5e7:
        raise SizeError(f"target edge length {target:g} would give about {est:.3g} triangles on a skin of "
                        f"area {area:.4g}: give a larger size (in the units of the surface file)")
    delta = DEFAULT_DEVIATION_FRACTION * target if max_deviation is None else float(max_deviation)
    if not np.isfinite(delta) or delta <= 0:
        raise SizeError(f"max_deviation {max_deviation!r} must be positive: give a positive length")
    h_min = DEFAULT_MIN_EDGE_FRACTION * target if min_edge is None else float(min_edge)
    if not np.isfinite(h_min) or h_min <= 0 or h_min > target:
        raise SizeError(f"min_edge {min_edge!r} must be positive and at most target_edge")
    timings = {}
    t0 = time.perf_counter()
    surf = _Surface(mesh, target, delta, feature_angle, corner_angle, wedge_angle, keep_component_borders,
                    locator)
    surf.set_sizing(h_min, gradation)
    timings["prepare"] = time.perf_counter() - t0
    ctx = _Ctx(surf, max_flip_dihedral=max_flip_dihedral, delta=delta)
    W = _work_from_surface(surf)
    W.h = ctx.sizing(W)
    t0 = time.perf_counter()
    nm = _phase(_micro_round, W, ctx, 50, 0.25)
    timings["micro"] = time.perf_counter() - t0
    if log:
        log(f"{nm} tiny input edges collapsed")
    _iterate(W, ctx, iterations, timings, log)
    _finish(W, ctx, finish_rounds, timings, log)
    passes = 0
    mids = _MidpointDistances(surf.loc)
    for _ in range(deviation_passes):
        dm, dc, _, _ = _deviation(W, ctx, mids)
        T = W.topo()
        E = T.E
        L = edge_lengths(W.P, E)
        over = (dm > delta) & (L > _HI * h_min)
        if not over.any() or over.sum() <= deviation_pass_fraction * len(over):
            break
        passes += 1
        # shrink the field at the input triangles under the offending edges
        mid = 0.5 * (W.P[E[over, 0]] + W.P[E[over, 1]])
        _, tri, _ = surf.loc.closest(mid)
        lnew = L[over] * np.sqrt(delta / dm[over]) * 0.8
        verts = np.concatenate([surf.T[tri].reshape(-1), surf.T[W.vtri[E[over]].reshape(-1)[
            W.vtri[E[over]].reshape(-1) >= 0]].reshape(-1)])
        hn = np.concatenate([np.repeat(lnew, 3), np.repeat(np.repeat(lnew, 2)[W.vtri[E[over]].reshape(-1) >= 0], 3)])
        surf.shrink_sizing(verts, hn, gradation)
        W.h = ctx.sizing(W)
        if log:
            log(f"deviation pass {passes}: {int(over.sum())} edges deviate more than {delta:g}")
        _iterate(W, ctx, max(2, iterations // 2), timings, log)
        _finish(W, ctx, finish_rounds, timings, log)
    # ---------------------------------------------------------------- deviation splits
    # last resort for the guarantee: split (at the projected midpoint) every edge whose
    # midpoint is still farther than max_deviation from the input, down to 2 * min_edge
    t0 = time.perf_counter()
    n_dev_splits = 0
    for _ in range(12 if deviation_splits else 0):
        T = W.topo()
        E = T.E
        L = edge_lengths(W.P, E)
        dm = mids(W.P, E, W.vtri)
        over = np.flatnonzero((dm > delta) & (L > 2.0 * h_min))
        if not len(over):
            break
        k = _split_round(W, ctx, forced=over, min_angle_guard=20.0, deviation=dm)
        n_dev_splits += k
        W.h = ctx.sizing(W)
        _phase(_flip_round, W, ctx, 5, "angle")
        _phase(_cleanup_round, W, ctx, 3)
        if not k:
            break
    timings["deviation_splits"] = time.perf_counter() - t0
    # safety net: faces standing across the surface (through a thin tip) are collapsed away
    if len(_standing_faces(W, ctx)):
        _phase(_unstand_round, W, ctx, 10)
        _phase(_flip_round, W, ctx, 5, "angle")
        # the collapses above check no angles: clean up the slivers they left (below 10 degrees only:
        # a clean-up at the finishing rounds' 20 degrees reshaped whole tip caps and left skin nodes
        # off the surface on straight_wing stress seed 58)
        _phase(_cleanup_round, W, ctx, 3, 10.0)
        _phase(_flip_round, W, ctx, 5, "angle")
    # ---------------------------------------------------------------- output
    dm, dc, ctri, ok = _deviation(W, ctx, mids)
    comp = surf.tri_comp[ctri]
    fdeg = np.bincount(W.fe.reshape(-1), minlength=W.n) if len(W.fe) else np.zeros(W.n, np.int64)
    corners = np.flatnonzero((W.kind == _CORNER) | ((fdeg > 0) & (fdeg != 2)))
    out = ShellMesh(W.P, W.F, comp, surf.component_names, corners, W.fe, np.full(len(W.fe), -1, np.int32))
    timings["total"] = time.perf_counter() - t_start
    if report is not None:
        report.update(_stats(out, target, delta, dm, dc))
        # edge length against the local size asked for (curvature / feature-size adapted)
        E = out.edges()
        L = out.edge_lengths()
        he = 0.5 * (W.h[E[:, 0]] + W.h[E[:, 1]])
        pct = [1, 5, 25, 50, 75, 95, 99]
        report["edge_to_local_size_percentiles"] = {p: float(np.percentile(L / he, p)) for p in pct}
        flat = he >= 0.95 * target
        report["fraction_edges_unrefined"] = float(flat.mean())
        if flat.any():
            report["edge_length_percentiles_unrefined"] = {p: float(np.percentile(L[flat], p) / target)
                                                          for p in pct}
        report.update(dict(timings=timings, deviation_passes=passes, n_deviation_splits=n_dev_splits,
                           n_standing_faces=int(len(_standing_faces(W, ctx))),
                           n_input_triangles=len(surf.T),
                           n_feature_chains=int(surf.n_chains), n_corners=int((W.kind == _CORNER).sum()),
                           max_deviation=delta, min_edge=h_min, target_edge=target))
    return out


def _stats(out, target, delta, dm, dc):
    L = out.edge_lengths()
    A = _tri_angles(out.points, out.faces[:, :3])
    amin = A.min(1)
    pct = [0, 1, 5, 25, 50, 75, 95, 99, 100]
    return dict(n_triangles=int(out.n_faces), n_vertices=int(out.n_points),
                edge_length_percentiles={p: float(np.percentile(L, p) / target) for p in pct},
                min_angle=float(amin.min()), angle_percentiles={p: float(np.percentile(amin, p)) for p in (1, 5, 50)},
                n_min_angle_below_10=int((amin < 10).sum()), n_min_angle_below_20=int((amin < 20).sum()),
                max_angle=float(A.max()),
                deviation_edge_midpoints=float(dm.max()) if len(dm) else 0.0,
                deviation_face_centroids=float(dc.max()) if len(dc) else 0.0,
                n_edges_over_deviation=int((dm > delta).sum()))


def remesh_statistics(result: ShellMesh, source: ShellMesh, target_edge: float,
                      locator: SurfaceLocator | None = None) -> dict:
    """Figures of a remesh against its input: edge-length percentiles (relative to
    ``target_edge``), angles, and the distance from the result's vertices, edge midpoints
    and face centroids to the input surface (output -> input) and from the input
    vertices to the result (input -> output)."""
    loc = locator if locator is not None else SurfaceLocator.from_mesh(source)
    tris, _ = result.triangles()
    E = result.edges()
    mid = 0.5 * (result.points[E[:, 0]] + result.points[E[:, 1]])
    _, _, dv = loc.closest(result.points)
    _, _, dm = loc.closest(mid)
    _, _, dc = loc.closest(result.face_centroids())
    _, _, di = SurfaceLocator(result.points, tris).closest(source.points)
    s = _stats(result, float(target_edge), np.inf, dm, dc)
    s.update(deviation_vertices=float(dv.max()), deviation_input_to_output=float(di.max()),
             diagonal=float(source.diagonal))
    return s


# ============================================================================ local clean-up
def improve_triangles(mesh: ShellMesh, locator: SurfaceLocator, *, target_edge: float, iterations: int = 3,
                      max_dihedral: float = 3.0, relax: bool = True, min_angle_floor: float = 10.0) -> ShellMesh:
    """Local clean-up of the triangles of a skin after member curves were cut into it.

    Batched, deterministic, vectorised:

    * **edge flips** of interior triangle--triangle edges that are not in
      ``mesh.feature_edges``, whose two triangles belong to the same component, are
      nearly coplanar (normals within ``max_dihedral`` degrees, before and after) and
      whose flip raises the smaller of the two triangles' smallest angles;
    * **tangential relaxation** of the free vertices (not in ``fixed_vertices``, not on a
      feature edge, not on a quad, not on an open or non-manifold edge of the triangle
      set) to the area-weighted centroid of their triangles, projected onto the input
      surface of ``locator`` (closest point among the input triangles facing the same
      way as the vertex normal, so a vertex never jumps to the other skin of a thin
      trailing edge). A move is undone when a triangle around it would turn by more
      than 60 degrees, face against the input surface, or get a smallest angle below
      ``min(its previous smallest angle, min_angle_floor)`` -- triangles never invert.

    Feature-line vertices do not slide along their lines (member chains must keep the
    nodes the member meshes are built on). Quads, the component of every face and the
    face order are left unchanged (a flip rewrites the two triangles in place).

    Parameters
    ----------
    mesh : ShellMesh
        Skin with triangles (quads allowed, left alone), ``feature_edges`` and
        ``fixed_vertices`` marking what must stay.
    locator : SurfaceLocator
        The input (original) skin surface that free vertices are projected onto.
    target_edge : float
        Local edge length scale (used for tolerances).
    iterations : int
        Flip + relaxation rounds.
    max_dihedral : float
        Largest angle (degrees) between the normals of two triangles whose shared edge
        may be flipped.
    relax : bool
        Also run the tangential relaxation.
    """
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("improve_triangles needs a ShellMesh")
    if not np.isfinite(target_edge) or target_edge <= 0:
        raise SizeError(f"target edge length {target_edge!r} must be positive and finite: give a positive size")
    out = mesh.copy()
    tri = np.flatnonzero(mesh.is_tri)
    if not len(tri):
        return out
    n = mesh.n_points
    F = mesh.faces[tri, :3].copy()
    T = _Topo(F, n, allow_nonmanifold=True)
    fixed = np.zeros(n, bool)
    fixed[mesh.fixed_vertices] = True
    fixed[mesh.feature_edges.reshape(-1)] = True
    fixed[mesh.faces[mesh.is_quad].reshape(-1)] = True
    fixed[T.E[(T.valence == 1) | T.nonmanifold].reshape(-1)] = True
    used = np.zeros(n, bool)
    used[F.reshape(-1)] = True
    kind = np.where(fixed | ~used, _CORNER, _REGULAR).astype(np.int8)
    ctx = _Ctx(None, locator=locator, max_flip_dihedral=max_dihedral)
    vtri = np.full(n, -1, np.int64)
    free = np.flatnonzero(kind == _REGULAR)
    if len(free):
        _, t, _ = locator.closest(mesh.points[free])
        vtri[free] = t
    # non-manifold edges must not be flipped: mark them as features of the working mesh
    nm = T.E[T.nonmanifold]
    fe = np.vstack([mesh.feature_edges, nm]) if len(nm) else mesh.feature_edges
    W = _Work(mesh.points.copy(), F, mesh.component[tri].astype(np.int64), kind, np.full(n, np.nan),
              np.full(n, -1, np.int64), np.full(n, -1, np.int64), vtri, fe, np.zeros(len(fe), np.int64),
              np.full(n, float(target_edge)))
    W.allow_nonmanifold = True
    W.touched()
    for _ in range(max(int(iterations), 0)):
        _phase(_flip_round, W, ctx, 10, "angle")
        if relax:
            _relax(W, ctx, move_chains=False, min_angle_floor=min_angle_floor)
    _phase(_flip_round, W, ctx, 10, "angle")
    faces = out.faces.copy()
    faces[tri, :3] = W.F
    return ShellMesh(W.P, faces, out.component, out.component_names, out.fixed_vertices,
                     out.feature_edges, out.feature_edge_ids)
