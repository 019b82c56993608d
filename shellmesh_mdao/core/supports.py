"""Node supports: where each node of the conforming skin + member mesh may move, shared by the
split, merge, smooth and quad stages.

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
the skin locator, the member planes and the curves (polylines) of the feature ids;
:func:`pipeline_supports` those of the pipeline's mesh (member planes, the exact sections of
the input skin with them, feature lines), and :func:`edge_midpoint_projector` puts the split
stage's new nodes onto them.
"""
from __future__ import annotations

import itertools
import weakref
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from ..errors import MeshValidationError, ProjectionError
from ..families import member_of
from .kernels import chain_walk, closest_on_curves
from ..mesh import ShellMesh, cross_rows, dot_norm_rows, dot_rows, dot_unit_rows, unique_edges
from .locator import SurfaceLocator, closest_point_on_triangles

__all__ = ["FIXED", "CURVE", "PLANE", "SURFACE", "KIND_NAMES", "SCAN_SEGMENTS", "SECTION_CACHE_SIZE", "Curve",
           "CurveSet", "Supports", "derive_supports", "polylines_from_edges", "support_normals", "supports_hold",
           "section_polylines", "pipeline_supports", "edge_midpoint_projector"]

FIXED, CURVE, PLANE, SURFACE = 0, 1, 2, 3
KIND_NAMES = ("fixed", "curve", "plane", "surface")
_NDOF = np.array([0, 1, 2, 2], dtype=np.int64)
#: curves of at most this many segments are scanned whole by :meth:`CurveSet.closest` (a
#: compiled loop); longer ones go through its KD-tree of segment midpoints (same answers)
SCAN_SEGMENTS = 512

# einsum's dot, its norm and unit rows (mesh.dot_rows & co.: compiled for (k, 3) rows)
_dot, _norm, _unit = dot_rows, dot_norm_rows, dot_unit_rows


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
    tree: a compiled loop (:func:`~shellmesh_mdao.core.kernels.closest_on_curves`) scans all the
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
        :meth:`~shellmesh_mdao.core.locator.SurfaceLocator.closest`) for the next query of a point
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
    ``surfaces``    list of :class:`~shellmesh_mdao.core.locator.SurfaceLocator` (the ORIGINAL
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
    compiled walk (:func:`~shellmesh_mdao.core.kernels.chain_walk`)."""
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
    planes : dict component id -> plane (a :class:`~shellmesh_mdao.core.section.Plane` or a
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


def support_normals(supports: Supports, P, verts):
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


def supports_hold(before: ShellMesh, after: ShellMesh) -> bool:
    """Whether a stage's result keeps what the node supports are derived from: the points,
    feature edges (and their ids), fixed vertices and component names (with the same faces and
    components too, the split stage's; the merge changes faces only within a component)."""
    return (np.array_equal(after.points, before.points)
            and np.array_equal(after.feature_edges, before.feature_edges)
            and np.array_equal(after.feature_edge_ids, before.feature_edge_ids)
            and np.array_equal(after.fixed_vertices, before.fixed_vertices)
            and after.component_names == before.component_names)


# ============================================================================ pipeline supports
#: per input-skin locator: its plane sections as polylines, keyed by (point, normal) bytes,
#: the most recently used last
_SECTIONS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()
#: planes kept per locator (a study keeps its loaded skin across runs while the rib and spar
#: planes move: the oldest sections are dropped)
SECTION_CACHE_SIZE = 256


def section_polylines(skin, point, normal) -> list:
    """The section of the input skin (a :class:`~shellmesh_mdao.core.locator.SurfaceLocator`) with
    the plane through ``point`` with ``normal``, as ``(nodes, closed)`` polylines (read-only
    arrays). Computed once per locator and plane: the split, merge and quad stages ask for the
    same members' sections (the input skin never changes during a run). At most
    :data:`SECTION_CACHE_SIZE` planes are kept per locator (least recently used dropped)."""
    from .section import Plane, plane_section

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

    ``skin``: :class:`~shellmesh_mdao.core.locator.SurfaceLocator` of the ORIGINAL input skin;
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
        base = member_of(nm)
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
