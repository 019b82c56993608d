"""The remesher's working state: :class:`WorkMesh` (the mutable triangle mesh being remeshed,
with its per-vertex kinds and chain coordinates) and :class:`Context` (projection, sizing and
chain services the operations share)."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..mesh import dot_norm_rows, dot_rows, dot_unit_rows
from .common import CHAIN, CORNER, REGULAR, EdgeTable, tri_normals
from .surface import project_compatible

__all__ = ["WorkMesh", "Context"]

# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


# ============================================================================ working mesh
class WorkMesh:
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
            self._topo = EdgeTable(self.F, self.n, allow_nonmanifold=self.allow_nonmanifold)
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
        return _unit(tri_normals(self.P, self.F))

    def vertex_normals(self):
        An = tri_normals(self.P, self.F)
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
        on the new numbering (:func:`~shellmesh_mdao.remesh.kernels.collapse_apply`)."""
        for name in ("P", "kind", "S", "vchain", "vin", "vtri", "h"):
            setattr(self, name, getattr(self, name)[keep])
        self.touched()


# ============================================================================ context
class Context:
    """Projection / sizing / chain services shared by the operations.

    ``surf`` is a :class:`~.surface.InputSurface` during remeshing; for :func:`~.improve.improve_triangles` it is
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
            self.tri_n = _unit(tri_normals(locator.points, locator.triangles))
            self._tree = None

    def _centroid_tree(self):
        if self.surf is not None:
            return self.surf.centroid_tree()
        if self._tree is None:
            self._tree = cKDTree(self.loc.points[self.loc.triangles].mean(1))
        return self._tree

    def project(self, q, nrm, patch, hint=None):
        return project_compatible(self.loc, self._centroid_tree, self.tri_n,
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
        r = k == REGULAR
        h[r] = s.h_at(W.vtri[idx[r]], W.P[idx[r]])
        c = k == CHAIN
        if c.any():
            _, hc, _ = s.chain_point(W.S[idx[c]], W.vchain[idx[c]])
            h[c] = hc
        q = k == CORNER
        h[q] = s.h[W.vin[idx[q]]]
        if s.field is not None or s.turn_field is not None:     # the local sizes asked for, where
            h = np.minimum(h, s.field_at(W.P[idx]))                 # the vertex is
        return h

    def chain_S_of(self, W, v, c, near):
        """Arc coordinate of vertex v as a point of chain c (corners: the end nearest ``near``)."""
        S = W.S[v].copy()
        cor = W.kind[v] == CORNER
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
