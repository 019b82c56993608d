"""Smoothing optimisation (Li & Hwang, paper Sec. IV.C.3, eq. 6-8) with explicit vertex supports.

Every vertex of the conforming skin + member mesh has a **support** that says where it
may move (:class:`Supports`):

========  ======================================================================
kind      meaning
========  ======================================================================
FIXED     never moves (crossings where three or more supports meet, chain ends,
          corners, any vertex the caller did not list as sliding)
CURVE     slides along a polyline (imprint chain = exact member-plane / input-skin
          arc, member-member junction line, sharp feature line) and is projected
          back onto it; one degree of freedom (the chord tangent)
PLANE     moves in the plane of its planar member (rib, spar); two degrees of freedom
SURFACE   moves in its tangent plane, then is projected (closest point, restricted to
          input triangles whose normal agrees with the vertex normal) onto the
          ORIGINAL input surface; two degrees of freedom
========  ======================================================================

:func:`derive_supports` builds the supports from a :class:`~shellmesh_mdao.mesh.ShellMesh`,
the skin locator, the member planes and the curves (polylines) of the feature ids.

:func:`smooth` solves, per trust-region step, the paper's eq. 7

    min_D  E(x + D) + 1/2 sum_i rho_i |d_i|^2     s.t.   d_i in the tangent space of vertex i

with a quadratic energy E over the mesh edges (and optionally the quad diagonals). The
default ``energy="length"`` is the quadratic model of the objective the paper states in
words, the sum of edge LENGTHS (pair weights 1/L frozen at the last refresh, so the
gradient is the sum of unit edge vectors); ``energy="squared"`` is eq. 6/7 as printed (sum
of squared lengths), optionally with rest lengths ``target_edge``. Beyond the paper,
``ortho_weight`` adds a quad-corner orthogonality term (zero for right angles at any
aspect ratio). The tangent constraint ``N D = 0`` is eliminated exactly with an
orthonormal tangent basis ``T`` (``D = T u``, null-space method): the same minimiser as the
KKT system eq. 8 (``solver="kkt"`` assembles eq. 8 literally; a test checks they agree),
with a symmetric positive definite matrix ``T^T A T + diag(rho)`` of half the size. That
matrix depends only on the mesh, the weights and the tangent frames, so it is built (and,
with ``solver="lu"``, factorised as L D L^T by ``qdldl``) once and reused for
``refresh`` steps, during which only the right-hand side changes; the default solves it by
Jacobi-preconditioned CG to :data:`CG_RTOL` (the regulariser keeps it well conditioned; at that
tolerance cheaper than the factorisation at every mesh size, see :data:`AUTO_LU_MAX_UNKNOWNS`).

Each step is clipped per vertex to ``trust`` times the distance to the nearest other
vertex (the paper's ``m D <= r``), the moved vertices are projected onto their supports,
and a vectorised line search halves the step of every vertex of an element that would
fold (scaled Jacobian, measured against the element's own normal and against its normal
before the step, at or below ``min_jacobian`` and lower than before) and of every vertex
whose projection jumps (landing farther from the tangent-plane point than the move, or
finding no input triangle facing the vertex's way nearby, e.g. only the opposite skin of
a thin trailing edge).
"""
from __future__ import annotations

import itertools
import math
import time
import weakref
from dataclasses import dataclass, field

import numpy as np
import qdldl
from scipy import sparse
from scipy.sparse import linalg as spla
from scipy.spatial import cKDTree

from .errors import MeshValidationError, ProjectionError
from .core.threads import Background
from .core.topology import face_rings, faces_of
from .kernels import (ReducedHessian, chain_walk, closest_on_curves, corner_max_turn, corner_sums,
                      element_normals, face_quality, faces_at, min_corner_sj, nearest_other_distance,
                      ortho_gradient, ortho_jacobian, pair_difference)
from .mesh import (ShellMesh, cross_rows, dot_norm_rows, dot_rows, dot_unit_rows, edge_topology, norm_rows,
                   unique_edges, vertex_faces)
from .project import SurfaceLocator, closest_point_on_triangles
from .quality import warp

__all__ = ["FIXED", "CURVE", "PLANE", "SURFACE", "KIND_NAMES", "Curve", "CurveSet", "Supports", "derive_supports",
           "polylines_from_edges", "smooth", "SmoothResult", "mesh_figures", "untangle",
           "AUTO_LU_MAX_UNKNOWNS"]

FIXED, CURVE, PLANE, SURFACE = 0, 1, 2, 3
KIND_NAMES = ("fixed", "curve", "plane", "surface")
_NDOF = np.array([0, 1, 2, 2], dtype=np.int64)
#: ``solver="auto"`` factorises with sparse LU up to this many unknowns and uses
#: Jacobi-preconditioned CG above. 0: CG always. At :data:`CG_RTOL` 1e-3 the smoothing before
#: subdivision takes 188 ms with CG against 215 ms with the factorisation on the target case
#: (5.7k nodes), 41 against 42 ms on a 715-node wing; a factorisation's fill-in grows fast on
#: surface meshes (splu: 0.25 s at 20k unknowns, 2.7 s at 51k).
AUTO_LU_MAX_UNKNOWNS = 0

#: relative residual at which the conjugate gradients stop. The solution is a trust-region step,
#: clipped to ``trust`` times the distance to the nearest vertex and then line-searched, so
#: solving it more finely buys nothing: on the target case's final smoothing (47k unknowns) 10-11
#: iterations instead of the 21-22 that 1e-6 took (36 at 1e-10), the step within about 1e-3 of the
#: exact one, and the corpus's quality figures the same to four decimals (docs/optimisation.md).
CG_RTOL = 1e-3
#: curves of at most this many segments are scanned whole by :meth:`CurveSet.closest` (a
#: compiled loop); longer ones go through its KD-tree of segment midpoints (same answers)
SCAN_SEGMENTS = 512
_TRI_SJ = 2.0 / math.sqrt(3.0)


# ============================================================================ small kernels
# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


def _onb(n: np.ndarray):
    """Deterministic orthonormal tangent basis (t1, t2) of unit normals n (Duff et al. 2017)."""
    s = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (s + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t1 = np.stack([1.0 + s * n[:, 0] ** 2 * a, s * b, -s * n[:, 0]], 1)
    t2 = np.stack([b, s + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return t1, t2


def _pair_keys(pairs: np.ndarray, n: int) -> np.ndarray:
    p = np.sort(np.asarray(pairs, np.int64).reshape(-1, 2), axis=1)
    return p[:, 0] * n + p[:, 1]


# ============================================================================ supports
class Curve:
    """A polyline support: ``points`` (k, 3); ``closed`` joins the last point to the first.
    Closest-point queries are vectorised (KD-tree of segment midpoints, built once)."""

    def __init__(self, points, closed: bool = False):
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        if len(p) < 2 or not np.isfinite(p).all():
            raise ProjectionError("a support curve needs at least 2 finite points: pass the polyline "
                                  "(e.g. the imprint arc) as a (k, 3) array")
        if closed is None:
            closed = False
        if len(p) > 2 and np.array_equal(p[0], p[-1]):
            p, closed = p[:-1], True
        self.points = p
        self.closed = bool(closed)
        q = np.vstack([p, p[:1]]) if self.closed else p
        keep = np.ones(len(q) - 1, bool)
        self._a = q[:-1]
        self._ab = q[1:] - q[:-1]
        L = _norm(self._ab)
        keep &= L > 0
        if not keep.any():
            raise ProjectionError("a support curve has zero length: pass distinct polyline points")
        self._a, self._ab, self._L = self._a[keep], self._ab[keep], L[keep]
        self._tree = cKDTree(self._a + 0.5 * self._ab)

    def closest(self, q):
        """Closest points on the curve to ``q`` (k, 3): returns ``(points, distance, tangent)``
        with the unit direction of the segment each point lies on."""
        q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, 3))
        if not len(q):
            return np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
        d0, _ = self._tree.query(q)
        cnt, si = _ball_lists(self._tree.query_ball_point(q, d0 + 0.5 * self._L.max() * (1 + 1e-9) + 1e-300))
        qi = np.repeat(np.arange(len(q)), cnt)
        return _pick_nearest(q, qi, si, self._a, self._ab, self._L)


def _pick_nearest(q, qi, si, a, ab, L):
    """Closest point of each query ``q[qi]`` over its candidate segments ``si`` (the nearest,
    then the lowest segment index): ``(points, distance, unit tangent)`` per distinct ``qi``
    in increasing order."""
    a, ab = a[si], ab[si]
    t = np.clip(_dot(q[qi] - a, ab) / (L[si] ** 2), 0.0, 1.0)
    x = a + t[:, None] * ab
    dist = _norm(x - q[qi])
    order = np.lexsort((si, dist, qi))
    first = np.ones(len(order), bool)
    first[1:] = qi[order][1:] != qi[order][:-1]
    pick = order[first]
    return x[pick], dist[pick], ab[pick] / L[si[pick], None]


def _ball_lists(cand):
    """Flatten the index lists of ``cKDTree.query_ball_point``: ``(counts, indices)``."""
    cnt = np.fromiter(map(len, cand), np.int64, len(cand))
    return cnt, np.fromiter(itertools.chain.from_iterable(cand), np.int64, int(cnt.sum()))


class CurveSet:
    """Closest points on many :class:`Curve` objects in one query: each query point names its
    curve. Gives exactly what ``curves[c].closest`` gives, in one KD-tree query instead of one
    per curve (the supports of a mesh hold hundreds of short chains, and the smoothing
    projects onto them every step).

    The tree holds every segment midpoint with a fourth coordinate ``c * sep``, ``sep`` far
    larger than the curves' extent, so a query ``(x, c * sep)`` meets the segments of its own
    curve at their plain distance; candidates of other curves are dropped, and a query whose
    nearest midpoint is not on its own curve (one farther than ``sep`` from it) is answered by
    its curve alone. Queries on curves of at most :data:`SCAN_SEGMENTS` segments skip the
    tree: a compiled loop (:func:`~shellmesh_mdao.kernels.closest_on_curves`) scans all the
    segments of the query's curve, with the same rule and the same arithmetic."""

    def __init__(self, curves):
        self.curves = list(curves)
        self._nseg = None
        self._tree = None

    def _build(self):
        cs = self.curves
        self._cid = np.repeat(np.arange(len(cs)), [len(c._L) for c in cs])
        self._a = np.concatenate([c._a for c in cs])
        self._ab = np.concatenate([c._ab for c in cs])
        self._L = np.concatenate([c._L for c in cs])
        self._Lmax = np.array([c._L.max() for c in cs])
        self._nseg = np.array([len(c._L) for c in cs], np.int64)
        self._start = np.concatenate([[0], np.cumsum(self._nseg)[:-1]]).astype(np.int64)

    def _build_tree(self):
        mid = self._a + 0.5 * self._ab
        self._sep = 1e3 * (float(np.abs(mid).max()) + float(self._L.max()) + 1.0)
        self._tree = cKDTree(np.column_stack([mid, self._cid * self._sep]))

    def closest(self, q, cid):
        """``(points, distance, unit tangent)`` of each query ``q`` (k, 3) on curve ``cid`` (k,)."""
        q = np.ascontiguousarray(np.asarray(q, dtype=np.float64).reshape(-1, 3))
        cid = np.asarray(cid, np.int64).reshape(-1)
        k = len(q)
        if not k:
            return np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
        if getattr(self, "_nseg", None) is None:
            self._build()
        X, D, T = np.zeros((k, 3)), np.zeros(k), np.zeros((k, 3))
        # curves of up to SCAN_SEGMENTS segments: every segment is scanned by a compiled loop
        # (the nearest, then the lowest segment: what the candidates below give, bit for bit)
        scan = self._nseg[cid] <= SCAN_SEGMENTS
        if scan.any():
            rows = np.flatnonzero(scan)
            X[rows], D[rows], S = closest_on_curves(q[rows], cid[rows], self._start, self._start + self._nseg,
                                                    self._a, self._ab, self._L)
            T[rows] = self._ab[S] / self._L[S, None]
            if scan.all():
                return X, D, T
        if self._tree is None:
            self._build_tree()
        q4 = np.column_stack([q, cid * self._sep])
        d0, i0 = self._tree.query(q4)
        own = (self._cid[i0] == cid) & ~scan
        if own.any():
            rows = np.flatnonzero(own)
            radius = d0[rows] + 0.5 * self._Lmax[cid[rows]] * (1 + 1e-9) + 1e-300
            cnt, si = _ball_lists(self._tree.query_ball_point(q4[rows], radius))
            qi = np.repeat(np.arange(len(rows)), cnt)
            keep = self._cid[si] == cid[rows][qi]
            X[rows], D[rows], T[rows] = _pick_nearest(q[rows], qi[keep], si[keep], self._a, self._ab, self._L)
        rest = ~own & ~scan
        for c in np.unique(cid[rest]).tolist():
            rows = np.flatnonzero(rest & (cid == c))
            X[rows], D[rows], T[rows] = self.curves[c].closest(q[rows])
        return X, D, T


class _Surface:
    """A SurfaceLocator plus triangle normals and a centroid tree for normal-compatible
    closest points."""

    def __init__(self, locator: SurfaceLocator):
        self.loc = locator
        P, T = locator.points, locator.triangles
        self.tri_n = _unit(cross_rows(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]]))
        self._ctree = None

    def ctree(self):
        if self._ctree is None:
            P, T = self.loc.points, self.loc.triangles
            self._ctree = cKDTree((P[T[:, 0]] + P[T[:, 1]] + P[T[:, 2]]) / 3.0)
        return self._ctree

    def project(self, q, nrm=None, min_dot: float = 0.0, hint=None):
        """Closest point on the surface; with normals ``nrm`` restricted to triangles whose
        normal has a dot product > ``min_dot`` with it. Returns ``(points, ok, tri)``; ``ok``
        is False where no compatible triangle was found nearby (the plain closest point is
        returned there); ``tri`` the plain closest point's triangle, a ``hint`` (see
        :meth:`~shellmesh_mdao.project.SurfaceLocator.closest`) for the next query of a point
        that moves on from there."""
        cl, ti, _ = self.loc.closest(q, hint=hint)
        if nrm is None:
            return cl, np.ones(len(cl), bool), ti
        ok = _dot(self.tri_n[ti], nrm) > min_dot
        bad = np.flatnonzero(~ok)
        T, P = self.loc.triangles, self.loc.points
        for K in (16, 128):
            if not len(bad):
                break
            K = min(K, len(T))
            _, cand = self.ctree().query(q[bad], k=K)
            cand = np.asarray(cand).reshape(len(bad), K)
            owner = np.repeat(np.arange(len(bad)), K)
            cf = cand.reshape(-1)
            good = _dot(self.tri_n[cf], nrm[bad][owner]) > min_dot
            owner, cf = owner[good], cf[good]
            if len(cf):
                t = T[cf]
                x = closest_point_on_triangles(q[bad][owner], P[t[:, 0]], P[t[:, 1]], P[t[:, 2]])
                d = _norm(x - q[bad][owner])
                o = np.lexsort((cf, d, owner))
                first = np.ones(len(o), bool)
                first[1:] = owner[o][1:] != owner[o][:-1]
                pick = o[first]
                rows = bad[owner[pick]]
                cl[rows] = x[pick]
                ok[rows] = True
            bad = np.flatnonzero(~ok)
        return cl, ok, ti


@dataclass
class Supports:
    """Where each vertex may move.

    ``kind``        (n,) int8: FIXED, CURVE, PLANE or SURFACE per vertex.
    ``ref``         (n,) int64: index into ``curves`` / ``planes`` / ``surfaces`` for that
                    kind (-1 for FIXED).
    ``surfaces``    list of :class:`~shellmesh_mdao.project.SurfaceLocator` (the ORIGINAL
                    input surfaces; ``surfaces[0]`` is the skin).
    ``planes``      (p, 2, 3): point and unit normal of each member plane.
    ``curves``      list of :class:`Curve`.
    ``comp_kind``, ``comp_ref``: support of the faces of each component (SURFACE or PLANE),
                    used for new nodes inside faces and on non-feature edges.
    ``edge_pairs``, ``edge_curve``: feature edges (sorted node pairs, rows sorted) and the
                    curve each lies on (-1: none known, the edge's nodes stay fixed).
    """

    kind: np.ndarray
    ref: np.ndarray
    surfaces: list = field(default_factory=list)
    planes: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3)))
    curves: list = field(default_factory=list)
    comp_kind: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int8))
    comp_ref: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    edge_pairs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    edge_curve: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __post_init__(self):
        self.kind = np.asarray(self.kind, np.int8).reshape(-1)
        self.ref = np.asarray(self.ref, np.int64).reshape(-1)
        self.planes = np.asarray(self.planes, np.float64).reshape(-1, 2, 3)
        self.comp_kind = np.asarray(self.comp_kind, np.int8).reshape(-1)
        self.comp_ref = np.asarray(self.comp_ref, np.int64).reshape(-1)
        self.edge_pairs = np.asarray(self.edge_pairs, np.int64).reshape(-1, 2)
        self.edge_curve = np.asarray(self.edge_curve, np.int64).reshape(-1)
        self._surf = [s if isinstance(s, _Surface) else _Surface(s) for s in self.surfaces]
        self.surfaces = [s.loc for s in self._surf]
        self._curve_set = None
        if len(self.kind) != len(self.ref):
            raise MeshValidationError("Supports: kind and ref must have one entry per vertex")
        for k, lst in ((CURVE, self.curves), (PLANE, self.planes), (SURFACE, self.surfaces)):
            r = self.ref[self.kind == k]
            if len(r) and (r.min() < 0 or r.max() >= len(lst)):
                raise MeshValidationError(f"Supports: a {KIND_NAMES[k]} vertex refers to a missing "
                                          f"{KIND_NAMES[k]} (ref out of range)")

    @property
    def n(self) -> int:
        return len(self.kind)

    @property
    def curve_set(self) -> CurveSet:
        """All ``curves`` in one :class:`CurveSet` (built on first use, shared by copies)."""
        if self._curve_set is None:
            self._curve_set = CurveSet(self.curves)
        return self._curve_set

    def _copy_with(self, kind, ref) -> "Supports":
        out = Supports(kind, ref, self._surf, self.planes, self.curves, self.comp_kind, self.comp_ref,
                       self.edge_pairs, self.edge_curve)
        out._curve_set = self.curve_set if self.curves else None
        return out

    def counts(self) -> dict:
        """Number of vertices of each kind."""
        c = np.bincount(self.kind, minlength=4)
        return {KIND_NAMES[i]: int(c[i]) for i in range(4)}

    def dof(self) -> np.ndarray:
        """Degrees of freedom of each vertex (0, 1 or 2)."""
        return _NDOF[self.kind]

    def extended(self, kind, ref) -> "Supports":
        """Copy with vertices appended (same surfaces, planes, curves)."""
        return self._copy_with(np.concatenate([self.kind, np.asarray(kind, np.int8)]),
                               np.concatenate([self.ref, np.asarray(ref, np.int64)]))

    def held(self, movable) -> "Supports":
        """Copy in which every vertex not in ``movable`` (ids) is FIXED (same surfaces,
        planes, curves)."""
        keep = np.zeros(self.n, bool)
        keep[np.asarray(movable, np.int64).reshape(-1)] = True
        return self._copy_with(np.where(keep, self.kind, FIXED), np.where(keep, self.ref, -1))

    def curve_of_edges(self, pairs) -> np.ndarray:
        """Curve id of each node pair (-1 where the pair is not a feature edge with a curve)."""
        pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
        out = np.full(len(pairs), -1, np.int64)
        if not len(self.edge_pairs) or not len(pairs):
            return out
        n = int(max(self.edge_pairs.max(), pairs.max())) + 1
        keys = _pair_keys(self.edge_pairs, n)
        o = np.argsort(keys, kind="stable")
        keys = keys[o]
        q = _pair_keys(pairs, n)
        pos = np.clip(np.searchsorted(keys, q), 0, len(keys) - 1)
        hit = keys[pos] == q
        out[hit] = self.edge_curve[o[pos[hit]]]
        return out

    # ------------------------------------------------------------------ projection
    def project_kind(self, x, kind, ref, normals=None, min_dot: float = 0.0, hint=None, return_tri: bool = False):
        """Project points ``x`` (k, 3) onto the supports ``(kind, ref)`` (k,) each.

        FIXED rows are returned unchanged. SURFACE rows use ``normals`` (k, 3) if given to
        reject triangles facing the other way. Returns ``(points, ok)``, and with
        ``return_tri`` also ``tri`` (k,): each SURFACE row's closest input triangle (-1 on the
        other rows), which as ``hint`` (k,) of a later call for the same points, moved a
        little, saves a part of the search without changing the answer."""
        x = np.asarray(x, np.float64).reshape(-1, 3)
        kind = np.asarray(kind).reshape(-1)
        ref = np.asarray(ref, np.int64).reshape(-1)
        out = x.copy()
        ok = np.ones(len(x), bool)
        tri = np.full(len(x), -1, np.int64)
        if hint is not None:
            hint = np.asarray(hint, np.int64).reshape(-1)
            if len(hint) != len(x):
                raise ValueError(f"project_kind: hint needs one entry per point, got {len(hint)} for {len(x)}")
        pl = np.flatnonzero(kind == PLANE)
        if len(pl):
            p0 = self.planes[ref[pl], 0]
            nn = self.planes[ref[pl], 1]
            out[pl] = x[pl] - _dot(x[pl] - p0, nn)[:, None] * nn
        cv = np.flatnonzero(kind == CURVE)
        if len(cv):                                       # every curve in one query
            out[cv] = self.curve_set.closest(x[cv], ref[cv])[0]
        sel = np.flatnonzero(kind == SURFACE)
        for r in np.unique(ref[sel]).tolist():            # one call per surface
            rows = sel[ref[sel] == r]
            nrm = None if normals is None else np.asarray(normals, np.float64)[rows]
            out[rows], ok[rows], tri[rows] = self._surf[r].project(x[rows], nrm, min_dot,
                                                                   None if hint is None else hint[rows])
        return (out, ok, tri) if return_tri else (out, ok)

    def project(self, points, idx=None, normals=None, min_dot: float = 0.0):
        """Project the vertices ``idx`` (default all) at ``points[idx]`` onto their supports.
        ``points`` is the full (n, 3) array; ``normals`` (n, 3) optional. Returns
        ``(projected (len(idx), 3), ok)``."""
        idx = np.arange(self.n) if idx is None else np.asarray(idx, np.int64)
        nrm = None if normals is None else np.asarray(normals)[idx]
        return self.project_kind(np.asarray(points)[idx], self.kind[idx], self.ref[idx], nrm, min_dot)

    def distance(self, points, idx=None) -> np.ndarray:
        """Distance of each vertex ``idx`` (default all) from its support (0 for FIXED vertices);
        ``points`` is the full (n, 3) array."""
        p = np.asarray(points, np.float64)
        x, _ = self.project(p, idx)
        return _norm(x - (p if idx is None else p[np.asarray(idx, np.int64)]))


def polylines_from_edges(points, edges) -> list:
    """Chain edges (k, 2) into polylines, breaking at nodes whose degree is not 2.

    Returns a list of ``(node_indices, closed)``; point coordinates are ``points[node_indices]``.
    Deterministic: chains are ordered by their smallest edge index and walk from the
    lower-index end (closed loops from their lowest node, towards its lower neighbour); one
    compiled walk (:func:`~shellmesh_mdao.kernels.chain_walk`)."""
    e = np.asarray(edges, np.int64).reshape(-1, 2)
    e = unique_edges(e[:, 0], e[:, 1])
    e = e[e[:, 0] != e[:, 1]]
    if not len(e):
        return []
    # the graph on the edges' own nodes, renumbered in order (a member's few edges among a
    # mesh's many nodes): the same chains, walks and order as on the mesh's numbering
    used, inv = np.unique(e, return_inverse=True)
    nodes, ptr, closed = chain_walk(inv.reshape(-1, 2), len(used))
    orig = used[nodes]
    return [(orig[ptr[c]:ptr[c + 1]], bool(closed[c])) for c in range(len(closed))]


def _plane_array(planes_dict, ncomp):
    """dict comp -> Plane / (point, normal) -> (comp ids, (p, 2, 3) array)."""
    ids, arr = [], []
    for cid in sorted(planes_dict):
        pl = planes_dict[cid]
        if hasattr(pl, "point") and hasattr(pl, "normal"):
            p0, nn = pl.point, pl.normal
        else:
            p0, nn = pl
        p0 = np.asarray(p0, np.float64).reshape(3)
        nn = np.asarray(nn, np.float64).reshape(3)
        ln = np.linalg.norm(nn)
        if not (np.isfinite(ln) and ln > 0 and np.isfinite(p0).all()):
            raise MeshValidationError(f"plane of component {cid} has a zero or non-finite normal/point: "
                                      "pass (point, unit normal) of the member plane")
        ids.append(int(cid))
        arr.append([p0, nn / ln])
    return np.asarray(ids, np.int64), np.asarray(arr, np.float64).reshape(-1, 2, 3)


def _distinct_count(v, vals, n):
    """Number of distinct ``vals`` per vertex ``v`` (pairs), and the min and max value."""
    cnt = np.zeros(n, np.int64)
    lo = np.full(n, np.iinfo(np.int64).max)
    hi = np.full(n, np.iinfo(np.int64).min)
    if len(v):
        v = np.asarray(v, np.int64)
        vals = np.asarray(vals, np.int64)
        base = int(vals.min())
        span = int(vals.max()) - base + 1
        u = np.unique(v * span + (vals - base))          # one key per distinct (vertex, value) pair
        cnt = np.bincount(u // span, minlength=n)
        np.minimum.at(lo, v, vals)
        np.maximum.at(hi, v, vals)
    return cnt, lo, hi


def derive_supports(mesh: ShellMesh, skin=None, planes: dict | None = None, curves: dict | None = None, *,
                    sliding=None, tol: float = 1e-6) -> Supports:
    """Supports of every vertex of ``mesh``.

    Parameters
    ----------
    skin : SurfaceLocator (or ShellMesh / (points, triangles)) of the ORIGINAL input skin;
        the faces of every component not in ``planes`` lie on it. May be None when every
        component is a planar member.
    planes : dict component id -> plane (a :class:`~shellmesh_mdao.imprint.section.Plane` or a
        ``(point, normal)`` pair) for the planar members.
    curves : dict feature-edge id -> polyline (k, 3) or list of polylines (a polyline whose
        last point equals its first is closed; a ``(points, closed)`` tuple also works).
        Each feature edge is assigned to the polyline of its id on which both its nodes
        lie (within ``tol`` times the mesh diagonal; when several do, the first listed unless a
        later one is closer by more than that tolerance).
    sliding : which of ``mesh.fixed_vertices`` may slide: None (none), True (all) or an
        index array. Vertices not in ``fixed_vertices`` are never forced fixed.
    tol : relative tolerance (times the diagonal) for matching feature edges to curves.

    Rules: a vertex with no feature edge whose faces all share one support (skin surface
    or one plane) gets that support; a vertex with exactly two feature edges on the same
    curve slides on that curve; everything else is FIXED (curve ends, crossings, corners,
    nodes of feature edges without a curve, nodes of open boundary or non-manifold edges
    that are not feature edges, vertices where faces of several supports meet without
    feature edges, unlisted ``fixed_vertices``).
    """
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("derive_supports needs a ShellMesh; build one with ShellMesh(points, faces)")
    planes = {} if planes is None else dict(planes)
    curves = {} if curves is None else dict(curves)
    n, m = mesh.n_points, mesh.n_faces
    ncomp = max(len(mesh.component_names), int(mesh.component.max()) + 1 if m else 0)
    bad = [c for c in planes if not (0 <= int(c) < ncomp)]
    if bad:
        raise MeshValidationError(f"planes given for unknown component ids {bad}: use ids of "
                                  f"mesh.component_names ({ncomp} components)")
    pids, parr = _plane_array(planes, ncomp)
    comp_kind = np.full(ncomp, SURFACE, np.int8)
    comp_ref = np.zeros(ncomp, np.int64)
    comp_kind[pids] = PLANE
    comp_ref[pids] = np.arange(len(pids))
    surfaces = []
    used_comp = np.unique(mesh.component)
    if (comp_kind[used_comp] == SURFACE).any():
        if skin is None:
            names = [mesh.component_names[c] for c in used_comp if comp_kind[c] == SURFACE]
            raise MeshValidationError(f"components {names} have no plane and no skin surface was given: "
                                      "pass the input skin locator (skin=SurfaceLocator(...)) or their planes")
        if isinstance(skin, ShellMesh):
            skin = SurfaceLocator.from_mesh(skin)
        elif not isinstance(skin, SurfaceLocator):
            skin = SurfaceLocator(*skin)
        surfaces = [skin]
    # ---- curves and feature-edge assignment
    curve_list, curve_fid = [], []
    for fid in sorted(curves):
        polys = curves[fid]
        if isinstance(polys, np.ndarray) and polys.ndim == 2:
            polys = [polys]
        elif isinstance(polys, tuple) and len(polys) == 2 and isinstance(polys[1], (bool, np.bool_)):
            polys = [polys]
        for p in polys:
            if isinstance(p, Curve):
                curve_list.append(p)
            elif isinstance(p, tuple) and len(p) == 2 and isinstance(p[1], (bool, np.bool_)):
                curve_list.append(Curve(p[0], p[1]))
            else:
                curve_list.append(Curve(p))
            curve_fid.append(int(fid))
    curve_fid = np.asarray(curve_fid, np.int64)
    fe, fid = mesh.feature_edges, mesh.feature_edge_ids
    edge_curve = np.full(len(fe), -1, np.int64)
    eps = tol * max(mesh.diagonal, 1e-300)
    best = np.full(len(fe), np.inf)
    P = mesh.points
    # distances of each feature edge's ends from every curve of its feature, in one query
    sels = [np.flatnonzero(fid == curve_fid[ci]) for ci in range(len(curve_list))]
    cset = CurveSet(curve_list)
    nq = np.array([len(x) for x in sels], np.int64)
    qsel = np.concatenate(sels) if sels else np.zeros(0, np.int64)
    qcid = np.repeat(np.arange(len(curve_list)), nq)
    dq = np.maximum(cset.closest(P[fe[qsel, 0]], qcid)[1], cset.closest(P[fe[qsel, 1]], qcid)[1])
    qstart = np.concatenate([[0], np.cumsum(nq)])
    for ci in range(len(curve_list)):
        sel = sels[ci]
        if not len(sel):
            continue
        d = dq[qstart[ci]:qstart[ci + 1]]
        # a later curve takes an edge only if it is closer by more than eps: an edge on two
        # curves (a member chain lies on the member plane's exact section AND on the polyline
        # of its own feature edges) goes to the first one whatever the rounding, so the
        # vertices between two such edges see one curve and slide on it
        take = (d <= eps) & (d < best[sel] - eps)
        best[sel[take]] = d[take]
        edge_curve[sel[take]] = ci
    # ---- vertex classification
    topo = mesh.topology()
    he_v = topo.he_from
    fsup = comp_kind[mesh.component].astype(np.int64) * (len(parr) + 1) + comp_ref[mesh.component]
    nsup, _, _ = _distinct_count(he_v, fsup[topo.he_face], n)
    kind = np.full(n, FIXED, np.int8)
    ref = np.full(n, -1, np.int64)
    vsup_face = np.zeros(n, np.int64)
    vsup_face[he_v] = topo.he_face                     # any incident face (all share the support)
    nfe = np.bincount(fe.ravel(), minlength=n) if len(fe) else np.zeros(n, np.int64)
    one = (nfe == 0) & (nsup == 1)
    comp_v = mesh.component[vsup_face]
    kind[one] = comp_kind[comp_v[one]]
    ref[one] = comp_ref[comp_v[one]]
    if len(fe):
        v2 = np.concatenate([fe[:, 0], fe[:, 1]])
        c2 = np.concatenate([edge_curve, edge_curve])
        ncurv, lo, hi = _distinct_count(v2, c2, n)
        cv = (nfe == 2) & (ncurv == 1) & (lo >= 0)
        kind[cv] = CURVE
        ref[cv] = lo[cv]
    # open-boundary / non-manifold edges that are not feature edges: their nodes stay put
    odd = topo.valence != 2
    if odd.any():
        is_fe = np.zeros(len(topo.edges), bool)
        if len(fe):
            ids = topo.edge_ids(fe)
            is_fe[ids[ids >= 0]] = True
        loose = topo.edges[odd & ~is_fe].ravel()
        kind[loose] = FIXED
        ref[loose] = -1
    fixed = mesh.fixed_vertices
    if sliding is None or sliding is False:
        stay = fixed
    elif sliding is True:
        stay = np.zeros(0, np.int64)
    else:
        stay = np.setdiff1d(fixed, np.asarray(sliding, np.int64))
    kind[stay] = FIXED
    ref[stay] = -1
    unused = np.ones(n, bool)
    unused[mesh.faces[mesh.faces >= 0]] = False
    kind[unused] = FIXED
    ref[unused] = -1
    out = Supports(kind, ref, surfaces, parr, curve_list, comp_kind, comp_ref, fe.copy(), edge_curve)
    out._curve_set = cset
    return out


# ============================================================================ element checks
def _face_normals(P, faces, is_tri):
    """Unit normals of the elements (:func:`_corner_normals` of their corners, in one compiled
    pass: :func:`~shellmesh_mdao.kernels.element_normals`)."""
    return element_normals(P, faces, is_tri)


def _corner_normals(c, is_tri):
    """Unit normals of elements given by their corners ``c`` (m, 4, 3) (a triangle's fourth
    corner is not read)."""
    v = cross_rows(c[:, 2] - c[:, 0], c[:, 3] - c[:, 1])
    if is_tri.any():
        ct = c[is_tri]
        v[is_tri] = cross_rows(ct[:, 1] - ct[:, 0], ct[:, 2] - ct[:, 0])
    return _unit(v)


def _min_corner_sj(P, faces, is_tri, nref=None):
    """Per element: min over corners of the scaled Jacobian against the element's own normal
    and (if given) against ``nref``; triangles scaled by 2/sqrt(3) (1 = equilateral). A
    compiled loop (:func:`~shellmesh_mdao.kernels.min_corner_sj`), the same bits as
    :func:`_corner_min_sj` on the corners and their :func:`_corner_normals`."""
    return min_corner_sj(P, faces, is_tri, nref, _TRI_SJ)


def _corner_min_sj(c, is_tri, nown, nref=None):
    """:func:`_min_corner_sj` of elements given by their corners ``c`` (m, 4, 3) and unit
    normals ``nown``."""
    out = np.full(len(c), np.inf)
    for mask, k, scale in ((~is_tri, 4, 1.0), (is_tri, 3, _TRI_SJ)):
        if not mask.any():
            continue
        C = c[mask][:, :k]
        E = np.roll(C, -1, axis=1) - C                          # e_next at corner i
        Ep = np.roll(E, 1, axis=1)                              # -e_prev
        cr = cross_rows(Ep, E)
        L = norm_rows(E, axis=2)
        den = L * np.roll(L, 1, axis=1)
        for nn in (nown[mask], None if nref is None else nref[mask]):
            if nn is None:
                continue
            s = np.einsum("ikj,ij->ik", cr, nn)
            sj = np.divide(s, den, out=np.zeros_like(s), where=den > 0).min(1) * scale
            out[mask] = np.minimum(out[mask], sj)
    return out


# ============================================================================ smoothing
@dataclass
class SmoothResult:
    """Outcome of :func:`smooth`.

    ``iterations``        trust-region steps taken; ``seconds`` wall time;
    ``factorisations``    sparse LU factorisations done (one per ``refresh`` steps);
    ``max_move``          largest single vertex move of the whole run (length units);
    ``moves``             largest move of each step;
    ``n_step_halvings``   vertex-step halvings done by the fold / jump line search;
    ``n_rejected``        vertex steps finally set to zero by the line search;
    ``n_fold_hits``, ``n_jump_hits``: line-search hits by cause (a vertex of an element that
                          would fold; a projection that jumped or found no compatible triangle);
    ``quality_before``, ``quality_after``: :func:`mesh_figures` of input and output.
    """

    iterations: int
    seconds: float
    max_move: float
    n_step_halvings: int
    n_rejected: int = 0
    factorisations: int = 0
    n_fold_hits: int = 0
    n_jump_hits: int = 0
    moves: list = field(default_factory=list)
    quality_before: dict = field(default_factory=dict)
    quality_after: dict = field(default_factory=dict)


def _pairs(E, faces, is_tri, diagonal_weight: float):
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


def _frames(mesh: ShellMesh, P, supports: Supports, vnormal):
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
        t1, t2 = _onb(_unit(nn))
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


def _vertex_normals_and_curvature(P, faces, is_tri, n):
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


def mesh_figures(mesh: ShellMesh, supports: Supports | None = None, size: float | None = None) -> dict:
    """The figures of the all-quad acceptance list for a mesh: ``quad_fraction``,
    ``min_sj``, ``mean_sj``, ``n_sj_le_0.2``, ``angles_ok`` (fraction of quads with every
    corner angle in [45, 135] degrees), ``warp_p99`` (degrees), ``median_edge`` (and
    ``median_edge_ratio`` = median / ``size`` when given), plus ``mean_sj_skin`` and
    ``mean_sj_members`` when ``supports`` tells which components are planar members."""
    from .quality import element_quality
    if not mesh.n_faces:
        return {}
    q = element_quality(mesh.points, mesh.faces, ("min_angle", "max_angle", "warp", "scaled_jacobian"))
    sj = q["scaled_jacobian"]
    quad = mesh.is_quad
    ok = quad & (q["min_angle"] >= 45.0) & (q["max_angle"] <= 135.0)
    med = float(np.median(mesh.edge_lengths()))
    out = {"n_faces": int(mesh.n_faces), "quad_fraction": float(quad.mean()), "min_sj": float(sj.min()),
           "mean_sj": float(sj.mean()), "n_sj_le_0.2": int((sj <= 0.2).sum()),
           "angles_ok": float(ok.sum() / max(quad.sum(), 1)),
           "warp_p99": float(np.percentile(q["warp"][quad], 99)) if quad.any() else 0.0,
           "median_edge": med}
    if size:
        out["median_edge_ratio"] = med / float(size)
    if supports is not None and len(supports.comp_kind):
        member = supports.comp_kind[mesh.component] == PLANE
        if (~member).any():
            out["mean_sj_skin"] = float(sj[~member].mean())
        if member.any():
            out["mean_sj_members"] = float(sj[member].mean())
    return out


def _solve_kkt(K3, rho_v, mesh_n, g, supports, T, owner):
    """Eq. 8 assembled literally: [[B, A^T], [A, 0]] [D; lam] = [-g; 0] with B = K x I3 +
    diag(rho) and one constraint row per normal direction of each vertex (3 for fixed).
    Used to check the null-space solve; returns D (n, 3)."""
    n = mesh_n
    # A = complement of T's columns in each vertex block
    dof = supports.dof()
    Td = T.toarray() if T.shape[0] <= 3000 else None
    if Td is None:
        raise ValueError("solver='kkt' is a reference implementation for small meshes (n <= 1000)")
    rows_A = []
    for v in range(n):                       # reference path only (small meshes)
        cols = np.flatnonzero(owner == v)
        B = Td[3 * v:3 * v + 3, cols]
        Q, _ = np.linalg.qr(np.hstack([B, np.eye(3)]))
        N = Q[:, dof[v]:3] if dof[v] else np.eye(3)
        for j in range(N.shape[1]):
            r = np.zeros(3 * n)
            r[3 * v:3 * v + 3] = N[:, j]
            rows_A.append(r)
    A = sparse.csr_matrix(np.array(rows_A))
    rho3 = np.repeat(rho_v, 3)
    B = (K3 + sparse.diags(rho3)).tocsc()
    KKT = sparse.bmat([[B, A.T], [A, None]], format="csc")
    rhs = np.concatenate([-g, np.zeros(A.shape[0])])
    sol = spla.spsolve(KKT, rhs)
    return sol[:3 * n].reshape(n, 3)




class _LDL:
    """Sparse LDL^T factorisations (qdldl: AMD ordering, no pivoting) of symmetric positive
    definite matrices that share one sparsity pattern: the ordering and the symbolic
    factorisation are made for the first matrix and kept while the pattern repeats, only
    the numeric factorisation is redone. Same matrix, same bits."""

    def __init__(self):
        self.pattern = None
        self.solver = None

    def factor(self, indptr, indices, data):
        """Factorise the matrix whose UPPER triangle is the CSC ``(data, indices, indptr)``."""
        n = len(indptr) - 1
        U = sparse.csc_matrix((data, indices, indptr), shape=(n, n))
        if (self.pattern is not None and np.array_equal(self.pattern[0], indptr)
                and np.array_equal(self.pattern[1], indices)):
            self.solver.update(U, upper=True)
        else:
            self.solver = qdldl.Solver(U, upper=True)
            self.pattern = (indptr.copy(), indices.copy())
        return self.solver


class _Linear:
    """Solver of the reduced system H u = b (H symmetric positive definite, symmetric bit for
    bit): a sparse LDL^T factorisation (qdldl, AMD ordering; made once, reused for every
    right-hand side; with ``ldl`` an :class:`_LDL` kept across the matrices of one pattern,
    the ordering too) or Jacobi-preconditioned conjugate gradients on the same matrix."""

    def __init__(self, H, method: str, ldl: _LDL | None = None):
        self.method = method
        if method == "lu":
            U = sparse.triu(H, format="csc")
            self.lu = (_LDL() if ldl is None else ldl).factor(U.indptr, U.indices, U.data)
        else:
            self.H = H.tocsr()
            d = self.H.diagonal()
            self.dinv = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)

    def solve(self, b, rtol: float = CG_RTOL, maxiter: int = 5000):
        if self.method == "lu":
            return self.lu.solve(b)
        x = np.zeros_like(b)
        r = b.copy()
        nb = float(np.sqrt(np.einsum("i,i->", b, b)))
        if nb == 0:
            return x
        z = r * self.dinv
        p = z.copy()
        rz = float(np.einsum("i,i->", r, z))
        for _ in range(maxiter):
            Ap = self.H @ p
            a = rz / float(np.einsum("i,i->", p, Ap))
            x += a * p
            r -= a * Ap
            if np.sqrt(np.einsum("i,i->", r, r)) <= rtol * nb:
                break
            z = r * self.dinv
            rz2 = float(np.einsum("i,i->", r, z))
            p *= rz2 / rz
            p += z
            rz = rz2
        return x


class _Ortho:
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
        :func:`~shellmesh_mdao.kernels.ortho_gradient`)."""
        return ortho_gradient(self.a, self.b, self.c, self.n, self.su, self.sv, self.w, x, n)

    def terms(self):
        """The corners as :meth:`~shellmesh_mdao.kernels.ReducedHessian.values` takes them
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
        The Jacobian is built by a compiled loop (:func:`~shellmesh_mdao.kernels.ortho_jacobian`)."""
        m = len(self.b)
        if not m or not (np.asarray(ncol) > 0).any():
            return sparse.csr_matrix((k, k))
        J = sparse.csr_matrix(ortho_jacobian(self.a, self.b, self.c, self.n, self.su, self.sv, np.sqrt(self.w),
                                             col_start, ncol, tv), shape=(3 * m, k))
        return (J.T @ J).tocsr()


def _draped_vertices(faces, nrm, spread):
    """(n,) bool: the vertices of the faces (quads and triangles) whose corners' support
    normals ``nrm`` (n, 3) are more than ``spread`` degrees apart; corners without a support
    normal (zero: fixed, on a curve) do not count."""
    fv = np.where(faces >= 0, faces, faces[:, :1])                 # a triangle repeats a corner
    f = nrm[fv]                                                     # (m, 4, 3)
    on = np.einsum("mij,mij->mi", f, f) > 0.5
    c = np.einsum("mij,mkj->mik", f, f)
    cmin = np.where(on[:, :, None] & on[:, None, :], c, 1.0).min((1, 2))
    out = np.zeros(len(nrm), bool)
    out[fv[cmin < np.cos(np.radians(spread))].ravel()] = True
    return out


class _Warp:
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
            keep = ~_draped_vertices(faces, nrm, warp_spread)[q].any(1)
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
        """The quads as :meth:`~shellmesh_mdao.kernels.ReducedHessian.values` takes them:
        ``(qi, m, sqrt(w) / l)``, ``qi`` their rows in the mesh's quads."""
        return self.qi, self.m, np.sqrt(self.w) * self.s


def smooth(mesh: ShellMesh, supports: Supports, *, iterations: int = 20, energy: str = "length",
           target_edge: float | None = None, diagonal_weight: float = 0.0, ortho_weight: float = 1.0,
           warp_weight: float = 0.0, warp_from: float = 7.0, warp_spread: float = 180.0, vertices=None,
           trust: float = 0.3, reg: float = 0.25, curvature_weight: float = 10.0, refresh: int = 4,
           min_jacobian: float = 0.3, max_halvings: int = 6, min_dot: float = 0.0, tol: float = 1e-4,
           solver: str = "auto", figures: str = "both") -> tuple[ShellMesh, SmoothResult]:
    """Move vertices along their supports to even out the mesh (paper eq. 6-8).

    Parameters
    ----------
    mesh : the conforming mixed mesh (skin and members).
    supports : :class:`Supports` of its vertices (:func:`derive_supports`).
    iterations : maximum number of trust-region steps.
    energy : ``"length"`` (default): the sum of edge LENGTHS, which the paper states as the
        goal, through its local quadratic model: pair weights ``1/L`` with ``L`` the length
        at the last refresh, so the gradient is the sum of unit edge vectors at each vertex
        (equilibrium: balanced edge directions, scale-free, keeps size gradation);
        ``"squared"``: eq. 6/7 as printed, sum of squared lengths (uniform Laplacian).
    target_edge : with ``energy="squared"``: each edge aims at this length and each quad
        diagonal at sqrt(2) times it (rest vectors along the current directions). With
        either energy it is the ``size`` of the reported ``median_edge_ratio``.
    diagonal_weight : weight of the quad-diagonal pairs relative to the edges (0 = edges
        only, as in the paper).
    ortho_weight : weight of the quad-corner orthogonality term (beyond the paper; see
        :class:`_Ortho`): zero for right-angled corners of any aspect ratio.
    warp_weight : weight of the quad planarity term (beyond the paper; see :class:`_Warp`),
        which flattens the quads whose warp is above ``warp_from`` degrees (measured when the
        frames are rebuilt) by sliding their corners along their supports; 0 (default) drops
        it. Not with ``solver="kkt"``.
    warp_from : warp (degrees) above which a quad is in the planarity term.
    warp_spread : a quad that shares a vertex with a face (itself included) whose corners'
        support normals (input facets, member planes) are more than this many degrees apart
        is left out of the planarity term: that face is draped over a crease or round much
        tighter than itself and cannot be flattened by sliding its corners, and pulling at it
        or beside it drags nodes across the crease. Default 180 (none left out).
    vertices : ids of the vertices that may move (default None: all); the others hold
        still, as if FIXED, and only constrain the step (fold guard, energy). Only the faces at
        them take part (the same result as over the whole mesh with the others FIXED, bit for
        bit).
    trust : per-step move limit as a fraction of the distance to the nearest other vertex.
    reg : regulariser ``rho_i = reg * (mean diagonal of vertex i's energy block)
        * (1 + curvature_weight * kappa_i)`` with ``kappa_i = 1 - min_f n_i . n_f`` over the incident faces (0 on a
        flat patch, 1 across a right-angle crease).
    refresh : steps between rebuilding the tangent frames and weights and refactorising;
        in between the factorisation is reused and only the right-hand side is rebuilt.
    min_jacobian : an element whose scaled Jacobian (own normal, and normal before the
        step) would end at or below this value AND below its value before the step makes
        the line search halve the step of its vertices.
    max_halvings : halvings before a vertex's step is dropped for this iteration.
    min_dot : a skin vertex may only be projected onto input triangles whose normal has a
        dot product above this with the vertex normal.
    tol : stop when the largest move of a step is below ``tol`` times the median edge.
    solver : ``"lu"`` (sparse L D L^T of the reduced system by qdldl, reused for ``refresh`` steps),
        ``"cg"`` (Jacobi-preconditioned CG on the same matrix), ``"auto"`` (LU up to
        :data:`AUTO_LU_MAX_UNKNOWNS` unknowns, 0: none; CG above) or ``"kkt"`` (eq. 8 assembled
        literally; small meshes only, for checks).
    figures : which of ``quality_before`` / ``quality_after`` (:func:`mesh_figures`, about
        20-50 ms each on 25k quads) to fill: ``"both"`` (default), ``"before"``, ``"after"`` or
        ``"none"`` (the others stay empty dicts); for callers that chain passes.

    Returns ``(smoothed mesh, SmoothResult)``; topology, components, feature edges and fixed
    vertices are unchanged, only ``points`` move.
    """
    t0 = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("smooth needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not isinstance(supports, Supports) or supports.n != mesh.n_points:
        raise MeshValidationError("smooth needs Supports with one entry per mesh vertex: build them with "
                                  "derive_supports(mesh, ...) for this mesh")
    if figures not in ("both", "before", "after", "none"):
        raise ValueError(f"figures must be 'both', 'before', 'after' or 'none', got {figures!r}")
    if solver not in ("auto", "lu", "cg", "kkt"):
        raise ValueError(f"solver must be 'auto', 'lu', 'cg' or 'kkt', got {solver!r}")
    if not (np.isfinite(warp_weight) and warp_weight >= 0 and np.isfinite(warp_from) and warp_from >= 0
            and 0 < warp_spread <= 180):
        raise ValueError(f"need finite warp_weight >= 0, warp_from >= 0 and 0 < warp_spread <= 180, got "
                         f"{warp_weight}, {warp_from}, {warp_spread}")
    if warp_weight > 0 and solver == "kkt":
        raise ValueError("the planarity term (warp_weight > 0) needs solver 'auto', 'lu' or 'cg', not 'kkt'")
    if energy not in ("length", "squared"):
        raise ValueError(f"energy must be 'length' or 'squared', got {energy!r}")
    if not (trust > 0 and reg >= 0 and refresh >= 1 and iterations >= 0 and diagonal_weight >= 0):
        raise ValueError("need trust > 0, reg >= 0, refresh >= 1, iterations >= 0, diagonal_weight >= 0")
    if target_edge is not None and not (np.isfinite(target_edge) and target_edge > 0):
        from .errors import SizeError
        raise SizeError(f"target_edge must be a positive length, got {target_edge}")
    if vertices is not None:
        vertices = np.asarray(vertices, np.int64).reshape(-1)
        if len(vertices) and (vertices.min() < 0 or vertices.max() >= mesh.n_points):
            raise ValueError(f"vertices must be ids of mesh vertices (0 to {mesh.n_points - 1})")
        supports = supports.held(vertices)
    n = mesh.n_points
    P = mesh.points.copy()
    faces, is_tri = mesh.faces, mesh.is_tri
    before = mesh_figures(mesh, supports, target_edge) if figures in ("both", "before") else {}
    scale = float(np.median(mesh.edge_lengths())) if mesh.n_faces else 1.0
    dof = supports.dof()
    movable = np.flatnonzero(dof > 0)
    vptr, vface = vertex_faces(faces, n)
    E = mesh.edges()
    if vertices is not None:
        # only the faces at a movable vertex take part: the other faces' terms do not reach the
        # movable vertices' equations, and each of those equations sums the same terms in the
        # same order (pairs, quads and faces keep their order). A draped face (warp_spread) needs
        # two corners with a support normal, i.e. movable ones, so it is among these faces too.
        # The same bits as over the whole mesh, for the cost of the region
        act = faces_of(vptr, vface, movable, len(faces))
        faces, is_tri = faces[act], is_tri[act]
        vptr, vface = vertex_faces(faces, n)
        E = edge_topology(faces).edges
    pairs, pw0, pf = _pairs(E, faces, is_tri, diagonal_weight)
    i, j = pairs[:, 0], pairs[:, 1]
    has_quads = not is_tri.all()
    method = solver
    if solver == "auto":
        method = "lu" if int(dof.sum()) <= AUTO_LU_MAX_UNKNOWNS else "cg"
    moves, halvings, rejected, nfact, n_jump, n_fold = [], 0, 0, 0, 0, 0
    # each vertex's closest input triangle at its last projection: where the next query starts
    hint = np.full(n, -1, np.int64)
    lin = T = nrm = ortho = warpt = hess = None
    ldl = _LDL()                     # the refreshed matrices share one pattern: one ordering
    it = 0
    for it in range(1, iterations + 1):
        if not len(movable):
            it = 0
            break
        # trust region: distance to the nearest other vertex, from a grid of cubes of >= 1.5 median
        # edges in a second thread while this one refreshes and solves (it depends on P alone;
        # the grid's cell sets the speed only: a KD-tree query's values)
        near = Background(nearest_other_distance, P, movable, 1.5 * scale)
        if (it - 1) % refresh == 0:
            vn, kap = _vertex_normals_and_curvature(P, faces, is_tri, n)
            T, owner, nrm, tv = _frames(mesh, P, supports, vn)
            pw = pw0.copy()
            if energy == "length":
                Lp = _norm(P[i] - P[j])
                pw = pw0 * np.divide(scale, Lp, out=np.zeros_like(Lp), where=Lp > 0)
            K = sparse.coo_matrix((np.concatenate([pw, pw, -pw, -pw]),
                                   (np.concatenate([i, j, i, j]), np.concatenate([i, j, j, i]))),
                                  shape=(n, n)).tocsr()
            diag_v = np.asarray(K.diagonal(), dtype=np.float64)
            col_start = np.searchsorted(owner, np.arange(n))
            ortho = None
            if ortho_weight > 0 and has_quads:
                ortho = _Ortho(P, faces, ~is_tri, scale)
                diag_v = diag_v + ortho_weight * ortho.block_trace(n)
            warpt = None
            if warp_weight > 0 and has_quads and method != "kkt":
                warpt = _Warp(P, faces, ~is_tri, scale, lambda v: _support_normals(supports, P, v), warp_from,
                              warp_spread)
                if len(warpt):
                    diag_v = diag_v + warp_weight * warpt.block_trace(n)
                else:
                    warpt = None
            rho_v = reg * diag_v * (1.0 + curvature_weight * kap)
            if method == "kkt":            # full 3n matrix for the literal eq. 8
                K3 = sparse.kron(K, sparse.identity(3), format="csr")
                if ortho is not None:
                    K3 = K3 + ortho_weight * ortho.hessian(3 * np.arange(n), np.full(n, 3),
                                                           np.tile(np.eye(3), (n, 1)), 3 * n)
            else:
                if hess is None:           # the pattern: pairs, and whole quads where a quad term is used
                    quad_terms = has_quads and (ortho_weight > 0 or warp_weight > 0)
                    hess = ReducedHessian(i, j, faces[~is_tri] if quad_terms else np.zeros((0, 4), np.int64), dof,
                                          col_start)
                H = hess.matrix(hess.values(tv, pw, rho_v[owner], ortho=None if ortho is None else ortho.terms(),
                                            fo=ortho_weight,
                                            warp=None if warpt is None else warpt.terms(), fw=warp_weight))
                lin = _Linear(H, method, ldl)
            nfact += 1
        # gradient of the energy at D = 0 (homogeneous quadratic: K3 x, plus rest vectors)
        xc = P - P.mean(0)
        if method == "kkt":
            g = K3 @ xc.ravel()
        elif ortho is None:
            g = (K @ xc).ravel()
        else:
            g = (K @ xc).ravel() + ortho_weight * ortho.gradient(xc, n).ravel()
        if warpt is not None:
            g = g + warp_weight * warpt.gradient(xc, n).ravel()
        if target_edge is not None and energy == "squared":
            rv = (target_edge * pf)[:, None] * _unit(P[i] - P[j])
            g = g - pair_difference(i, j, pw, rv, n).ravel()      # the rest vectors' pull, per vertex
        if method == "kkt":
            D = _solve_kkt(K3, rho_v, n, g, supports, T, owner)
        else:
            D = (T @ lin.solve(-(T.T @ g))).reshape(n, 3)
        r = trust * near.result()
        Dm = D[movable]
        L = _norm(Dm)
        Dm *= np.minimum(1.0, np.divide(r, L, out=np.ones_like(L), where=L > 0))[:, None]
        D = np.zeros((n, 3))
        D[movable] = Dm
        # line search with per-vertex step factors
        todo = movable[_norm(D[movable]) > 0]
        fsel = faces_of(vptr, vface, todo, len(faces))
        nref = _face_normals(P, faces[fsel], is_tri[fsel])
        sj_old = np.full(len(faces), np.inf)
        sj_old[fsel] = _min_corner_sj(P, faces[fsel], is_tri[fsel], nref)
        nref_all = np.zeros((len(faces), 3))
        nref_all[fsel] = nref
        alpha = np.zeros(n)
        alpha[todo] = 1.0
        X = P.copy()
        rounds = 0
        while len(todo):
            badv = np.zeros(0, np.int64)
            live = todo[alpha[todo] > 0]
            X[todo] = P[todo]
            if len(live):
                step = alpha[live, None] * D[live]
                x, ok, tri = supports.project_kind(P[live] + step, supports.kind[live], supports.ref[live],
                                                   nrm[live], min_dot, hint=hint[live], return_tri=True)
                hint[live] = tri
                jump = _norm(x - (P[live] + step)) > _norm(step) + 1e-12 * scale
                X[live] = x
                badv = live[~ok | jump]
                n_jump += len(badv)
            fs = faces_of(vptr, vface, todo, len(faces))
            sj_new = _min_corner_sj(X, faces[fs], is_tri[fs], nref_all[fs])
            badf = fs[(~np.isfinite(sj_new) | (sj_new <= min_jacobian)) & (sj_new < sj_old[fs] - 1e-12)]
            fv = faces[badf]
            fv = fv[fv >= 0]
            hit = np.zeros(n, bool)
            hit[fv[alpha[fv] > 0]] = True
            n_fold += int(hit.sum())
            hit[badv] = True
            badv = np.flatnonzero(hit)
            if not len(badv):
                break
            rounds += 1
            if rounds <= max_halvings:
                alpha[badv] *= 0.5
                halvings += len(badv)
            else:
                alpha[badv] = 0.0
                rejected += len(badv)
            todo = badv
        move = float(_norm(X - P).max()) if n else 0.0
        moves.append(move)
        P = X
        if move < tol * scale:
            break
    out = mesh.with_points(P)
    res = SmoothResult(iterations=it, seconds=time.perf_counter() - t0, max_move=max(moves, default=0.0),
                       n_step_halvings=halvings, n_rejected=rejected, factorisations=nfact, moves=moves,
                       n_fold_hits=n_fold, n_jump_hits=n_jump, quality_before=before,
                       quality_after=mesh_figures(out, supports, target_edge) if figures in ("both", "after") else {})
    return out, res


# ============================================================================ untangling
def _face_quality(C, is_tri, nref):
    """Per element with corner positions ``C`` (k, 4, 3): the scaled Jacobian (own normal,
    :func:`_min_corner_sj`), replaced by ``dot - 1`` (in [-2, -1]) where the element's own
    normal points against its reference normal ``nref`` (k, 3) (a flipped element). A compiled
    loop (:func:`~shellmesh_mdao.kernels.face_quality`), the same bits as
    ``np.where(d > 0, sj, d - 1)`` with ``nown = _corner_normals(C, is_tri)``,
    ``sj = _corner_min_sj(C, is_tri, nown)`` and ``d = _dot(nown, nref)``."""
    return face_quality(C, is_tri, nref, _TRI_SJ)


def _support_normals(supports: Supports, P, verts):
    """(len(verts), 3) normal of each vertex's support at its position: the closest input
    triangle's normal for a SURFACE vertex, the plane normal for a PLANE vertex, zero else."""
    out = np.zeros((len(verts), 3))
    kind, ref = supports.kind[verts], supports.ref[verts]
    pl = np.flatnonzero(kind == PLANE)
    out[pl] = supports.planes[ref[pl], 1]
    sf = np.flatnonzero(kind == SURFACE)
    for r in np.unique(ref[sf]).tolist():                  # one call per surface
        rows = sf[ref[sf] == r]
        srf = supports._surf[r]
        out[rows] = srf.tri_n[srf.loc.closest(P[verts[rows]])[1]]
    return out


def _tangent_dirs(supports: Supports, P, verts, nrm, ndir: int):
    """(len(verts), ndir, 3) unit move directions of each vertex along its support: ``ndir``
    directions evenly spread in the tangent plane (normal ``nrm``) of a SURFACE or PLANE
    vertex, the two senses of the curve tangent for a CURVE vertex."""
    kind, ref = supports.kind[verts], supports.ref[verts]
    nn = np.where((_norm(nrm) == 0)[:, None], [0.0, 0.0, 1.0], nrm)
    t1, t2 = _onb(_unit(nn))
    cv = np.flatnonzero(kind == CURVE)
    t2[cv] = 0.0
    if len(cv):
        t1[cv] = supports.curve_set.closest(P[verts[cv]], ref[cv])[2]
    th = 2.0 * np.pi * np.arange(ndir) / ndir
    d = np.cos(th)[None, :, None] * t1[:, None, :] + np.sin(th)[None, :, None] * t2[:, None, :]
    d[cv] = np.where(np.cos(th) >= 0, 1.0, -1.0)[None, :, None] * t1[cv][:, None, :]
    return d


def untangle(mesh: ShellMesh, supports: Supports, *, goal: float = 0.3, iterations: int = 100,
             faces=None, ref_normals=None, ndir: int = 8, nstep: int = 6, patience: int = 10,
             min_dot: float = 0.0) -> tuple[ShellMesh, dict]:
    """Raise the worst elements' scaled Jacobian by moving vertices ALONG THEIR SUPPORTS
    (optimisation-based untangling by pattern search, vectorised over vertices).

    Every element at or below ``goal`` (scaled Jacobian with its own normal; an element whose
    normal points against its reference normal counts as folded) makes its movable vertices
    and their neighbours candidates. Each iteration tries, for every candidate vertex at once,
    ``ndir`` tangent directions times ``nstep`` step lengths (the vertex's mean edge
    length, halved ``nstep - 1`` times) plus moves towards the centroid of its faces, each
    projected onto the vertex's support (skin: closest point on the input surface restricted
    to triangles facing the vertex's way; planes; curves) and dropped if the projection jumps
    farther than the move. A vertex takes the candidate with the smallest penalty
    ``sum over its faces of max(0, goal + 0.1 - q)^2`` among those that keep the minimum over
    its faces at or above ``min(current minimum, goal)``; vertices that share a face never move
    in the same round (the worst-placed one moves), so no element below ``goal`` ever gets
    worse. Stops when no element is at or below ``goal``, no vertex can improve, or
    ``patience`` iterations in a row brought neither fewer elements at or below ``goal`` nor
    a better worst element.

    ``faces``: ids of the elements to repair (default all); the others only constrain the
    moves (none at or below ``goal`` gets worse, none above falls to it).
    ``ref_normals`` (m, 3): the orientation each face must keep (default: its own normal on
    entry; pass e.g. the parent faces' normals where the entry mesh is folded).

    Returns ``(mesh with moved points, info)`` with ``info`` = ``{"iterations", "moves",
    "min_before", "min_after", "n_bad_before", "n_bad_after"}`` (over ``faces``; ``n_bad`` =
    elements at or below ``goal``, flipped ones included).
    """
    if not isinstance(mesh, ShellMesh):
        raise MeshValidationError("untangle needs a ShellMesh; build one with ShellMesh(points, faces)")
    if not isinstance(supports, Supports) or supports.n != mesh.n_points:
        raise MeshValidationError("untangle needs Supports with one entry per mesh vertex: build them with "
                                  "derive_supports(mesh, ...) for this mesh")
    n = mesh.n_points
    P = mesh.points.copy()
    F = mesh.faces
    is_tri = mesh.is_tri
    m = len(F)
    info = {"iterations": 0, "moves": 0, "min_before": None, "min_after": None, "n_bad_before": 0,
            "n_bad_after": 0}
    if not m:
        return mesh, info
    nref = _face_normals(P, F, is_tri) if ref_normals is None else \
        _unit(np.asarray(ref_normals, np.float64).reshape(m, 3))
    Fc = np.where(F >= 0, F, F[:, :1])

    def quality(sel):
        return _face_quality(P[Fc[sel]], is_tri[sel], nref[sel])

    q = quality(np.arange(m))
    region = np.arange(m) if faces is None else np.unique(np.asarray(faces, np.int64).reshape(-1))
    info["min_before"] = float(q[region].min(initial=np.inf))
    info["n_bad_before"] = int((q[region] <= goal).sum())
    movable = supports.dof() > 0
    vptr, vface = vertex_faces(F, n)
    hi = goal + 0.1
    it = 0
    best = (np.inf, -np.inf)
    since = 0
    for it in range(1, iterations + 1):
        bad = region[q[region] <= goal]
        if not len(bad):
            it -= 1
            break
        # stalled: neither fewer elements at or below the goal nor a better worst one lately
        now = (len(bad), float(q[bad].min()))
        if now[0] < best[0] or now[1] > best[1] + 1e-6:
            best, since = (min(best[0], now[0]), max(best[1], now[1])), 0
        else:
            since += 1
            if since >= patience:
                break
        # candidates: movable vertices of the bad faces and of the faces around them
        v0 = np.unique(F[bad][F[bad] >= 0])
        ring = faces_of(vptr, vface, v0, m)
        cand = np.unique(F[ring][F[ring] >= 0])
        cand = cand[movable[cand]]
        if not len(cand):
            break
        # incidences (vertex, face), grouped by vertex
        cnt = vptr[cand + 1] - vptr[cand]
        inc_v = np.repeat(np.arange(len(cand)), cnt)
        inc_f = vface[np.repeat(vptr[cand], cnt) + np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
        start = np.cumsum(cnt) - cnt
        Cf = P[Fc[inc_f]]                                              # (k, 4, 3)
        slot = Fc[inc_f] == cand[inc_v][:, None]
        slot[is_tri[inc_f], 3] = False
        qf = q[inc_f]
        cur_min = np.minimum.reduceat(qf, start)
        cur_pen = np.add.reduceat(np.maximum(0.0, hi - qf) ** 2, start)
        # mean edge length at each vertex (its two sides in each face)
        pos = np.argmax(slot, axis=1)
        k4 = np.where(is_tri[inc_f], 3, 4)
        nx = np.take_along_axis(Cf, ((pos + 1) % k4)[:, None, None].repeat(3, 2), 1)[:, 0]
        pv = np.take_along_axis(Cf, ((pos - 1) % k4)[:, None, None].repeat(3, 2), 1)[:, 0]
        me = P[cand[inc_v]]
        h = np.add.reduceat(_norm(nx - me) + _norm(pv - me), start) / (2 * cnt)
        # centroid of the vertex's faces
        fsum = Cf[:, :3].sum(1) + np.where(is_tri[inc_f][:, None], 0.0, Cf[:, 3])
        fcen = np.add.reduceat(fsum / k4[:, None], start) / cnt[:, None]
        snrm = _support_normals(supports, P, cand)
        dirs = _tangent_dirs(supports, P, cand, snrm, ndir)              # (c, ndir, 3)
        steps = 0.5 ** np.arange(0, nstep)
        moves = (dirs[:, :, None, :] * steps[None, None, :, None]).reshape(len(cand), -1, 3) * h[:, None, None]
        to_c = (fcen - P[cand])[:, None, :] * np.array([1.0, 0.5, 0.25])[None, :, None]
        moves = np.concatenate([moves, to_c], 1)
        K = moves.shape[1]
        Y = P[cand][:, None, :] + moves
        kind = np.repeat(supports.kind[cand], K)
        refs = np.repeat(supports.ref[cand], K)
        vnrm = np.repeat(snrm, K, axis=0)
        Yp, ok = supports.project_kind(Y.reshape(-1, 3), kind, refs, vnrm, min_dot)
        Yp = Yp.reshape(len(cand), K, 3)
        ok = ok.reshape(len(cand), K) & (_norm((Yp - Y).reshape(-1, 3)).reshape(len(cand), K)
                                         <= _norm(moves.reshape(-1, 3)).reshape(len(cand), K) + 1e-12 * h[:, None])
        # every candidate of every vertex at once: (K, incidences) qualities
        Ck = np.broadcast_to(Cf, (K,) + Cf.shape).copy()
        Ck[:, slot] = np.swapaxes(Yp[inc_v], 0, 1)
        qk = _face_quality(Ck.reshape(-1, 4, 3), np.tile(is_tri[inc_f], K),
                           np.tile(nref[inc_f], (K, 1))).reshape(K, -1)
        mn = np.minimum.reduceat(qk, start, axis=1)                       # (K, c)
        pen = np.add.reduceat(np.maximum(0.0, hi - qk) ** 2, start, axis=1)
        # every face of the vertex keeps min(its quality, goal): none at or below the goal gets
        # worse, none above falls to it
        keep = np.logical_and.reduceat(qk >= np.minimum(qf, goal)[None, :] - 1e-12, start, axis=1)
        feas = ok.T & keep & (
            (pen < cur_pen - 1e-12) | ((pen <= cur_pen) & (mn > cur_min + 1e-12)))
        pen = np.where(feas, pen, np.inf)
        low = pen == pen.min(0)
        best_k = np.argmax(np.where(low & feas, mn, -np.inf), axis=0)
        best_k[~feas.any(0)] = -1
        imp = np.flatnonzero(best_k >= 0)
        if not len(imp):
            break
        # independent set: a vertex moves when it has the best priority among the improving
        # vertices of each of its faces (priority: lowest current minimum, then index)
        rank = np.full(len(cand), np.iinfo(np.int64).max)
        order = np.lexsort((cand[imp], cur_min[imp]))
        rank[imp[order]] = np.arange(len(imp))
        uf, finv = np.unique(inc_f, return_inverse=True)
        frank = np.full(len(uf), np.iinfo(np.int64).max)
        np.minimum.at(frank, finv, rank[inc_v])
        lose = np.zeros(len(cand), bool)
        np.logical_or.at(lose, inc_v, frank[finv] < rank[inc_v])
        go = imp[~lose[imp]]
        P[cand[go]] = Yp[go, best_k[go]]
        info["moves"] += len(go)
        fs = faces_of(vptr, vface, cand[go], m)
        q[fs] = quality(fs)
    info["iterations"] = it
    info["min_after"] = float(q[region].min(initial=np.inf))
    info["n_bad_after"] = int((q[region] <= goal).sum())
    out = mesh.with_points(P)
    return out, info


# ============================================================================ pipeline supports
#: per input-skin locator: its plane sections as polylines, keyed by (point, normal) bytes,
#: the most recently used last
_SECTIONS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
#: planes kept per locator (a study keeps its loaded skin across runs while the rib and spar
#: planes move: the oldest sections are dropped)
SECTION_CACHE_SIZE = 256


def section_polylines(skin, point, normal) -> list:
    """The section of the input skin (a :class:`~shellmesh_mdao.project.SurfaceLocator`) with
    the plane through ``point`` with ``normal``, as ``(nodes, closed)`` polylines (read-only
    arrays). Computed once per locator and plane: the split, merge and quad stages ask for the
    same members' sections (the input skin never changes during a run). At most
    :data:`SECTION_CACHE_SIZE` planes are kept per locator (least recently used dropped)."""
    from .imprint.section import Plane, plane_section

    memo = _SECTIONS.setdefault(skin, {})
    key = (np.asarray(point, np.float64).tobytes(), np.asarray(normal, np.float64).tobytes())
    polys = memo.pop(key, None)
    if polys is None:
        sec = plane_section(skin.points, skin.triangles, Plane.make(point, normal))
        polys = []
        for ix, cl in polylines_from_edges(sec.nodes, sec.links):
            nodes = sec.nodes[ix]
            nodes.setflags(write=False)
            polys.append((nodes, cl))
    memo[key] = polys                                   # most recently used last
    while len(memo) > SECTION_CACHE_SIZE:
        memo.pop(next(iter(memo)))
    return list(polys)


def pipeline_supports(mesh: ShellMesh, skin, infos) -> Supports:
    """Supports of the conforming skin + members mesh of the pipeline.

    ``skin``: :class:`~shellmesh_mdao.project.SurfaceLocator` of the ORIGINAL input skin;
    ``infos``: the layout's :class:`~shellmesh_mdao.members.MemberInfo` list. Member faces
    (components named ``<member>`` or ``<member>/seg_<j>``) of a planar member move in its
    plane; every other face lies on the input skin. Feature edges of member ``k`` (its chains,
    its junction and end lines) slide on the exact section of the input skin with the member's
    plane or on the straight junction lines; geometric feature edges (id -1: trailing edges,
    tips, creases) slide on their own polylines. Nodes of non-planar members (kinked explicit
    members, Coons patches) are fixed. Chain and junction vertices may slide
    (``sliding=True``); crossings, corners and curve ends stay fixed (:func:`derive_supports`).
    """
    by_name = {m.name: m for m in (infos or [])}
    planes, owner = {}, {}
    for i, nm in enumerate(mesh.component_names):
        base = nm.split("/seg_")[0]
        inf = by_name.get(base)
        if inf is None:
            continue
        owner[i] = inf
        if inf.plane_normal is not None:
            planes[i] = (inf.plane_point, inf.plane_normal)
    fe, fid = mesh.feature_edges, mesh.feature_edge_ids
    curves = {}
    for i in np.unique(fid).tolist():                      # loop over members (and -1)
        polys = []
        inf = owner.get(int(i))
        if inf is not None and inf.plane_normal is not None:
            polys += section_polylines(skin, inf.plane_point, inf.plane_normal)
        polys += [(mesh.points[ix], cl) for ix, cl in polylines_from_edges(mesh.points, fe[fid == i])]
        curves[int(i)] = polys
    sup = derive_supports(mesh, skin, planes, curves, sliding=True)
    # a non-planar member (a kinked explicit member meshed panel by panel, or a Coons patch)
    # has no single surface to slide on: its nodes stay where the members stage put them, and
    # new nodes in its faces stay at their linear positions
    nonplanar = np.array([i for i, inf in owner.items() if inf.plane_normal is None], np.int64)
    if len(nonplanar):
        sup.comp_kind[nonplanar] = FIXED
        sup.comp_ref[nonplanar] = -1
        on = np.isin(mesh.component, nonplanar)
        v = mesh.faces[on]
        v = v[v >= 0]
        sup.kind[v] = FIXED
        sup.ref[v] = -1
    return sup


def edge_midpoint_projector(mesh: ShellMesh, supports: Supports):
    """``project(points, parent_edges)`` for :func:`~shellmesh_mdao.split.split_polygons`: a new
    node on edge (a, b) goes onto the curve of a feature edge, else onto the support shared by
    the edge's faces (input skin or member plane); an edge between faces of different supports
    (a junction without a curve) keeps the linear midpoint."""
    topo = mesh.topology()
    ck, cr = supports.comp_kind, supports.comp_ref
    fkind = ck[mesh.component].astype(np.int64)
    fref = cr[mesh.component]
    code = fkind * (int(max(cr.max(initial=0), 0)) + 1) + fref
    ne = len(topo.edges)
    hcode = code[topo.he_face]
    lo = np.full(ne, np.iinfo(np.int64).max)
    hi = np.full(ne, np.iinfo(np.int64).min)
    np.minimum.at(lo, topo.he_edge, hcode)
    np.maximum.at(hi, topo.he_edge, hcode)
    eface = topo.edge_faces[topo.edge_faces_ptr[:-1]]
    ekind = np.where(lo == hi, fkind[eface], FIXED).astype(np.int8)
    eref = np.where(lo == hi, fref[eface], -1)

    def project(points, parent_edges):
        pe = np.asarray(parent_edges, np.int64).reshape(-1, 2)
        eid = topo.edge_ids(pe)
        kind = np.where(eid >= 0, ekind[np.maximum(eid, 0)], FIXED).astype(np.int8)
        ref = np.where(eid >= 0, eref[np.maximum(eid, 0)], -1)
        cv = supports.curve_of_edges(pe)
        kind = np.where(cv >= 0, CURVE, kind).astype(np.int8)
        ref = np.where(cv >= 0, cv, ref)
        x, _ = supports.project_kind(points, kind, ref)
        return x

    return project
