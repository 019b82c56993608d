"""Energies of the smoothing QP and their Hessian: the edge pairs, the tangent frames of the
supports, vertex normals and curvature (the regulariser), and the quad terms beyond the paper,
corner orthogonality (:class:`OrthoTerm`) and planarity (:class:`WarpTerm`)."""
from __future__ import annotations

import math

import numpy as np
from scipy import sparse

from ..core.supports import CURVE, PLANE, SURFACE, Supports
from .kernels import corner_max_turn, corner_sums, ortho_gradient, ortho_jacobian
from ..mesh import ShellMesh, cross_rows, dot_norm_rows, dot_rows, dot_unit_rows
from ..quality import warp
from .elements import draped_vertices, tangent_basis

__all__ = ["local_edge_size", "energy_pairs", "tangent_frames", "vertex_normals_and_curvature", "OrthoTerm", "WarpTerm"]

# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


def local_edge_size(mesh: ShellMesh, cap: float) -> np.ndarray:
    """Each vertex's local element size in ``mesh``: the mean length of the edges at it, at most
    ``cap`` (``cap`` at a vertex without edges). The squared energy's rest lengths
    (:func:`~shellmesh_mdao.smooth.smooth`'s ``edge_size``): the smoothing keeps the grading the
    remesh made (a leading-edge nose, a fold, members closer than the element size) instead of
    pulling every edge towards the one flat-region length."""
    n = mesh.n_points
    E = mesh.edges()
    if not len(E):
        return np.full(n, float(cap))
    L = mesh.edge_lengths()
    total = np.bincount(E.ravel(), np.repeat(L, 2), n)
    count = np.bincount(E.ravel(), minlength=n)
    h = np.divide(total, count, out=np.full(n, float(cap)), where=count > 0)
    return np.minimum(h, float(cap))


def energy_pairs(E, faces, is_tri, diagonal_weight: float):
    """Energy pairs: the unique edges ``E`` of ``faces`` (weight 1) and the quad diagonals
    (weight ``diagonal_weight``), with the rest-length factor (1 for edges, sqrt 2 for
    diagonals)."""
    pairs, w, f = [E], [np.ones(len(E))], [np.ones(len(E))]
    if diagonal_weight > 0 and not is_tri.all():
        q = faces[~is_tri]
        D = np.vstack([q[:, [0, 2]], q[:, [1, 3]]])
        pairs.append(D)
        w.append(np.full(len(D), float(diagonal_weight)))
        f.append(np.full(len(D), math.sqrt(2.0)))
    return np.vstack(pairs), np.concatenate(w), np.concatenate(f)


def tangent_frames(mesh: ShellMesh, P, supports: Supports, vnormal):
    """Tangent basis of each vertex's support: returns the sparse (3n, k) basis T, the dof
    owner vertex of each column and the (n, 3) normals used for projection."""
    n = len(P)
    kind, ref = supports.kind, supports.ref
    cols_v, cols_t = [], []
    # planes
    pl = np.flatnonzero(kind == PLANE)
    nrm = vnormal.copy()
    if len(pl):
        nrm[pl] = supports.planes[ref[pl], 1]
    two = np.flatnonzero((kind == PLANE) | (kind == SURFACE))
    if len(two):
        nn = nrm[two]
        bad = _norm(nn) == 0
        nn = np.where(bad[:, None], [0.0, 0.0, 1.0], nn)
        t1, t2 = tangent_basis(_unit(nn))
        cols_v += [two, two]
        cols_t += [t1, t2]
    cv = np.flatnonzero(kind == CURVE)
    if len(cv):
        # chord of the two feature neighbours on the same curve
        fe = supports.edge_pairs
        ec = supports.edge_curve
        a = np.concatenate([fe[:, 0], fe[:, 1]])
        b = np.concatenate([fe[:, 1], fe[:, 0]])
        c = np.concatenate([ec, ec])
        keep = (kind[a] == CURVE) & (c >= 0) & (c == ref[a])
        a, b = a[keep], b[keep]
        o = np.lexsort((b, a))
        a, b = a[o], b[o]
        start = np.searchsorted(a, cv)
        cnt = np.searchsorted(a, cv, side="right") - start
        tang = np.zeros((len(cv), 3))
        two_n = cnt == 2
        s = start[two_n]
        tang[two_n] = P[b[s + 1]] - P[b[s]]
        tang = _unit(tang)
        # fall back on the polyline direction where the chord is missing or degenerate
        miss = _norm(tang) == 0
        if miss.any():
            rows = np.flatnonzero(miss)
            tang[rows] = supports.curve_set.closest(P[cv[rows]], ref[cv[rows]])[2]
        # make the sign deterministic w.r.t. the chord order (b[s] -> b[s+1]) only
        cols_v.append(cv)
        cols_t.append(tang)
    if not cols_v:
        return sparse.csr_matrix((3 * n, 0)), np.zeros(0, np.int64), nrm, np.zeros((0, 3))
    owner = np.concatenate(cols_v)
    tv = np.vstack(cols_t)
    o = np.argsort(owner, kind="stable")                 # columns ordered by vertex
    owner, tv = owner[o], tv[o]
    k = len(owner)
    rows = (3 * owner[:, None] + np.arange(3)).ravel()
    cols = np.repeat(np.arange(k), 3)
    T = sparse.csr_matrix((tv.ravel(), (rows, cols)), shape=(3 * n, k))
    return T, owner, nrm, tv


def vertex_normals_and_curvature(P, faces, is_tri, n):
    """Area-weighted vertex normals and kappa_i = 1 - min over incident faces of n_i . n_f."""
    c = P[np.where(faces >= 0, faces, faces[:, :1])]
    av = 0.5 * cross_rows(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
    if is_tri.any():
        ct = c[is_tri]
        av[is_tri] = 0.5 * cross_rows(ct[:, 1] - ct[:, 0], ct[:, 2] - ct[:, 0])
    # the face vectors summed onto their corners, and each vertex's largest turn to one of its
    # faces: compiled loops with bincount's and maximum.at's bits (kernels.corner_sums,
    # kernels.corner_max_turn)
    vn = _unit(corner_sums(faces, av, n))
    return vn, corner_max_turn(faces, vn, _unit(av), n)


class OrthoTerm:
    """Orthogonality term of the quads (beyond the paper). For every corner b with previous
    corner a and next corner c the residual

        r = (a - b) / |a - b|  -  n x (c - b) / |c - b|

    (n the quad's unit normal; the normal and both lengths frozen when the term is built)
    is about the corner's deviation from a right angle in radians, and zero for rectangles
    of any aspect ratio. Weight ``scale * sqrt(|a-b| |c-b|)`` (same units as the edge-length
    term). Linear in the positions: r = M_a a + M_b b + M_c c with M_a = s_u I,
    M_b = -s_u I + s_v [n]x, M_c = -s_v [n]x."""

    def __init__(self, P, faces, is_quad, scale):
        Q = faces[is_quad]
        C = P[Q]
        nq = _unit(cross_rows(C[:, 2] - C[:, 0], C[:, 3] - C[:, 1])) if len(Q) else np.zeros((0, 3))
        self.b = Q.reshape(-1)
        self.a = np.roll(Q, 1, axis=1).reshape(-1)
        self.c = np.roll(Q, -1, axis=1).reshape(-1)
        self.n = np.repeat(nq, 4, axis=0)
        # each quad edge's length once: corner k's next arm is edge k (P[c] - P[b]), its previous
        # arm edge k - 1 reversed (P[a] - P[b] = -(edge k - 1): the same squares, the same norm)
        L = _norm((C[:, [1, 2, 3, 0]] - C).reshape(-1, 3)).reshape(-1, 4) if len(Q) else np.zeros((0, 4))
        lv = L.reshape(-1)
        lu_ = np.roll(L, 1, axis=1).reshape(-1)
        ok = (lu_ > 0) & (lv > 0)
        self.su = np.divide(1.0, lu_, out=np.zeros_like(lu_), where=ok)
        self.sv = np.divide(1.0, lv, out=np.zeros_like(lv), where=ok)
        self.w = np.where(ok, scale * np.sqrt(lu_ * lv), 0.0)

    def gradient(self, x, n):
        """(n, 3) gradient of 1/2 sum w |r|^2 at positions x (a compiled loop,
        :func:`~shellmesh_mdao.smooth.kernels.ortho_gradient`)."""
        return ortho_gradient(self.a, self.b, self.c, self.n, self.su, self.sv, self.w, x, n)

    def terms(self):
        """The corners as :meth:`~shellmesh_mdao.smooth.kernels.ReducedHessian.values` takes them
        (``4 q + k`` the corner ``k`` of quad ``q``): ``(n, su, sv, sqrt(w))``."""
        return self.n, self.su, self.sv, np.sqrt(self.w)

    def block_trace(self, n):
        """Mean diagonal of each vertex's 3x3 block of the Hessian."""
        w = self.w
        t = np.bincount(self.a, weights=w * 3 * self.su ** 2, minlength=n)
        t += np.bincount(self.b, weights=w * (3 * self.su ** 2 + 2 * self.sv ** 2), minlength=n)
        t += np.bincount(self.c, weights=w * 2 * self.sv ** 2, minlength=n)
        return t / 3.0

    def hessian(self, col_start, ncol, tv, k):
        """Hessian J_T^T W J_T in the reduced coordinates: vertex v owns columns
        ``col_start[v] .. col_start[v] + ncol[v] - 1`` with tangent vectors ``tv`` (k, 3).
        The Jacobian is built by a compiled loop (:func:`~shellmesh_mdao.smooth.kernels.ortho_jacobian`)."""
        m = len(self.b)
        if not m or not (np.asarray(ncol) > 0).any():
            return sparse.csr_matrix((k, k))
        J = sparse.csr_matrix(ortho_jacobian(self.a, self.b, self.c, self.n, self.su, self.sv, np.sqrt(self.w),
                                             col_start, ncol, tv), shape=(3 * m, k))
        return (J.T @ J).tocsr()


class WarpTerm:
    """Planarity term of the quads (beyond the paper). For every quad (a, b, c, d) whose warp
    is above ``warp_from`` degrees the residual

        r = n . (a - b + c - d) / l

    (n the quad's unit normal, l the mean of its two diagonals; both frozen when the term is
    built) is the quad's twist over its size: zero for any planar quad, and about the warp
    angle in radians. Weight ``scale * l`` (the units of the edge-length term).

    A vertex moves along its support and is projected back onto it, so a move ``u`` in its
    tangent plane ends as ``(I - f f^T) u`` with ``f`` the normal of the support under the
    vertex (the input facet, the member plane; zero on a curve). The residual therefore sees
    the move through ``m = n - (n . f) f``, not through the mesh's own vertex normal, which
    is about ``n`` and would hide the leverage: over a kink of the input the facets on the two
    sides tilt against the quad, and sliding the corners along them flattens it."""

    SIGMA = np.array([1.0, -1.0, 1.0, -1.0])

    def __init__(self, P, faces, is_quad, scale, support_normals, warp_from, warp_spread=180.0):
        """``support_normals(verts)``: (k, 3) normal of the support under each vertex; quads
        that share a vertex with a face whose corners' support normals are more than
        ``warp_spread`` degrees apart (the quad itself included) are left out."""
        Q = faces[is_quad]
        C = P[Q]
        self.n = _unit(cross_rows(C[:, 2] - C[:, 0], C[:, 3] - C[:, 1])) if len(Q) else np.zeros((0, 3))
        ld = 0.5 * (_norm(C[:, 2] - C[:, 0]) + _norm(C[:, 3] - C[:, 1])) if len(Q) else np.zeros(0)
        sel = (ld > 0) & (warp(P, Q) > warp_from) if len(Q) else np.zeros(0, bool)
        q, n, ld, qi = Q[sel], self.n[sel], ld[sel], np.flatnonzero(sel)
        if warp_spread < 180.0 and len(q):
            # a face draped over a crease or round much tighter than itself (its corners'
            # supports turned more than warp_spread apart) cannot be flattened by sliding its
            # corners; pulling at it, or at a quad beside it, drags nodes across the crease
            used = np.unique(faces[faces >= 0])
            nrm = np.zeros((len(P), 3))
            nrm[used] = support_normals(used)
            keep = ~draped_vertices(faces, nrm, warp_spread)[q].any(1)
            q, n, ld, qi = q[keep], n[keep], ld[keep], qi[keep]
            fq = nrm[q]                                                 # (m, 4, 3)
        else:
            verts, inv = np.unique(q, return_inverse=True)
            fq = support_normals(verts)[inv.reshape(q.shape)]
        self.q, self.n, self.qi = q, n, qi
        self.s = 1.0 / ld
        self.w = scale * ld
        self.m = self.n[:, None, :] - np.einsum("mj,mkj->mk", self.n, fq)[:, :, None] * fq

    def __len__(self):
        return len(self.q)

    def gradient(self, x, n):
        """(n, 3) gradient of 1/2 sum w r^2 at positions x, through the moves' ``m``."""
        r = self.s * _dot(self.n, (x[self.q] * self.SIGMA[None, :, None]).sum(1))
        c = (self.w * r * self.s)[:, None, None] * self.m
        g = np.zeros((n, 3))
        for k in range(4):
            for d in range(3):
                g[:, d] += np.bincount(self.q[:, k], weights=self.SIGMA[k] * c[:, k, d], minlength=n)
        return g

    def block_trace(self, n):
        """Mean diagonal of each vertex's 3x3 block of the Hessian (upper bound)."""
        t = np.zeros(n)
        for k in range(4):
            t += np.bincount(self.q[:, k], weights=self.w * self.s ** 2 / 3.0, minlength=n)
        return t

    def terms(self):
        """The quads as :meth:`~shellmesh_mdao.smooth.kernels.ReducedHessian.values` takes them:
        ``(qi, m, sqrt(w) / l)``, ``qi`` their rows in the mesh's quads."""
        return self.qi, self.m, np.sqrt(self.w) * self.s
