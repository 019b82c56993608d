"""Exact plane sections of a triangulated surface, clipped to a member's extent.

A plane meets each triangle of the input surface in an exact straight segment. These
functions compute those segments for all triangles at once, clip them to the
half-spaces that bound a member (a rib lies between its front and rear spar planes, a
spar between its root and tip rib planes) and pick the one connected arc that passes
through a seed point found by ray casting from inside the wing, so a fuselage or tail
cut by the same plane is never taken. The result is an ordered polyline whose every
point lies on the input surface and on the plane (to rounding).

Sign convention: a vertex exactly on the plane counts as being on the positive side
(symbolic perturbation), so planes through vertices or along edges need no special case;
the zero-length pieces this creates are removed from the ordered arc.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ImprintError
from .kernels import arc_links, arc_order
from ..mesh import bbox_diagonal, norm_rows

__all__ = ["Plane", "PlaneSection", "plane_section", "section_arc", "SectionArc"]


@dataclass(frozen=True)
class Plane:
    """Plane through ``point`` with unit ``normal``; ``side(x) = (x - point)·normal``."""

    point: np.ndarray
    normal: np.ndarray

    @staticmethod
    def make(point, normal) -> "Plane":
        n = np.asarray(normal, float)
        ln = np.linalg.norm(n)
        if not np.isfinite(ln) or ln == 0:
            raise ImprintError(f"plane normal {normal} is zero or not finite")
        return Plane(np.asarray(point, float), n / ln)

    def side(self, x: np.ndarray) -> np.ndarray:
        return (np.asarray(x, float) - self.point) @ self.normal

    def flipped(self) -> "Plane":
        return Plane(self.point, -self.normal)


@dataclass
class PlaneSection:
    """All segments of ``plane ∩ surface``.

    ``nodes``  (k, 3) crossing points, one per crossed surface edge.
    ``node_edge`` (k, 2) the surface edge (vertex pair) each node lies on.
    ``links`` (s, 2) node pairs: the segment inside each crossed triangle.
    ``link_tri`` (s,) the crossed triangle of each link.
    """

    nodes: np.ndarray
    node_edge: np.ndarray
    links: np.ndarray
    link_tri: np.ndarray


@dataclass
class SectionArc:
    """One ordered arc of a plane section: ``points`` (k, 3), ``tri`` (k-1,) the input triangle
    containing each segment, ``closed`` whether the arc is a closed loop (then the last point
    is not repeated)."""

    points: np.ndarray
    tri: np.ndarray
    closed: bool

    @property
    def length(self) -> float:
        p = np.vstack([self.points, self.points[:1]]) if self.closed else self.points
        return float(norm_rows(np.diff(p, axis=0), axis=1).sum())


def plane_section(points: np.ndarray, tris: np.ndarray, plane: Plane, zero_vertices=None) -> PlaneSection:
    """Segments in which ``plane`` cuts each triangle (vectorised over all triangles).
    ``zero_vertices``: vertex indices taken to lie exactly on the plane."""
    d = plane.side(points)
    if zero_vertices is not None and len(zero_vertices):
        d[np.asarray(zero_vertices, np.int64)] = 0.0
    pos = d >= 0.0
    p0 = pos[tris[:, 0]]
    crossed = np.flatnonzero((p0 != pos[tris[:, 1]]) | (p0 != pos[tris[:, 2]]))   # not all on one side
    if not len(crossed):
        return PlaneSection(np.zeros((0, 3)), np.zeros((0, 2), np.int64), np.zeros((0, 2), np.int64),
                            np.zeros(0, np.int64))
    t = tris[crossed]
    a = t
    b = np.roll(t, -1, axis=1)
    cut = pos[a] != pos[b]                               # exactly two True per row
    rows, cols = np.nonzero(cut)
    ea, eb = a[rows, cols], b[rows, cols]
    lo, hi = np.minimum(ea, eb).astype(np.int64), np.maximum(ea, eb).astype(np.int64)
    npt = np.int64(len(points))
    key, node_of = np.unique(lo * npt + hi, return_inverse=True)      # edges in (lo, hi) order
    node_of = node_of.reshape(-1)
    node_edge = np.stack([key // npt, key % npt], 1)
    # interpolate from the lower-index vertex so both triangles sharing an edge give the same point
    dl, dh = d[node_edge[:, 0]], d[node_edge[:, 1]]
    tpar = dl / (dl - dh)
    nodes = points[node_edge[:, 0]] + tpar[:, None] * (points[node_edge[:, 1]] - points[node_edge[:, 0]])
    links = node_of.reshape(-1, 2)
    return PlaneSection(nodes, node_edge, links, crossed)


def _cut_at_vertices(sec: PlaneSection, stops: np.ndarray, points: np.ndarray) -> PlaneSection:
    """Cut the section graph at mesh vertices lying on the plane: nodes sitting on a stop
    vertex are replaced by a fresh terminal node per link; zero-length links between two
    nodes of the same stop vertex are dropped."""
    is_stop = np.zeros(len(points), bool)
    is_stop[stops] = True
    ne = sec.node_edge
    # a node sits on a stop vertex when its edge has the stop vertex and the crossing is at it
    at = np.full(len(ne), -1, np.int64)
    for col in (0, 1):
        v = ne[:, col]
        on = is_stop[v] & (norm_rows(sec.nodes - points[v], axis=1) <= 1e-12 * (
            1.0 + norm_rows(points[ne[:, 0]] - points[ne[:, 1]], axis=1)))
        at = np.where(on & (at < 0), v, at)
    a, b = sec.links[:, 0], sec.links[:, 1]
    va, vb = at[a], at[b]
    keep = ~((va >= 0) & (va == vb))
    a, b, va, vb, tri = a[keep], b[keep], va[keep], vb[keep], sec.link_tri[keep]
    k = len(sec.nodes)
    na = np.where(va >= 0, k + 2 * np.arange(len(a)), a)
    nb = np.where(vb >= 0, k + 2 * np.arange(len(a)) + 1, b)
    nodes = np.zeros((k + 2 * len(a), 3))
    nodes[:k] = sec.nodes
    nodes[na[va >= 0]] = points[va[va >= 0]]
    nodes[nb[vb >= 0]] = points[vb[vb >= 0]]
    node_edge = np.vstack([ne, np.repeat(np.stack([np.maximum(va, vb), np.maximum(va, vb)], 1), 2, axis=0)])
    return PlaneSection(nodes, node_edge, np.stack([na, nb], 1), tri)


def _clip_links(p0: np.ndarray, p1: np.ndarray, bounds, tol: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Parameter interval [t0, t1] of each segment p0->p1 inside all half-spaces side >= -tol."""
    t0 = np.zeros(len(p0))
    t1 = np.ones(len(p0))
    for bnd in bounds:
        g0, g1 = bnd.side(p0) + tol, bnd.side(p1) + tol
        den = g0 - g1
        with np.errstate(divide="ignore", invalid="ignore"):
            tc = np.where(den != 0, g0 / den, 0.0)
        # entering (g0 < 0 <= g1): t >= tc ; leaving (g0 >= 0 > g1): t <= tc ; both out: empty
        both_out = (g0 < 0) & (g1 < 0)
        entering = (g0 < 0) & (g1 >= 0)
        leaving = (g0 >= 0) & (g1 < 0)
        t0 = np.where(entering, np.maximum(t0, tc), t0)
        t1 = np.where(leaving, np.minimum(t1, tc), t1)
        t1 = np.where(both_out, -1.0, t1)
    return t0, t1


def section_arc(points: np.ndarray, tris: np.ndarray, plane: Plane, bounds=(), seed=None,
                seed_tri: int | None = None, name: str = "member", merge_tol: float | None = None,
                zero_vertices=None, bound_tol: float = 0.0, stop_vertices=None,
                section: PlaneSection | None = None) -> SectionArc:
    """The connected arc of ``plane ∩ surface`` inside every half-space of ``bounds`` that
    passes through ``seed`` (a point on the surface and the plane, e.g. a ray-cast hit).

    ``seed_tri`` is the surface triangle that contains the seed (from the ray cast); the
    arc through the link nearest to the seed is taken. Consecutive arc points closer than
    ``merge_tol`` (default 1e-12 of the arc's bounding-box diagonal) are merged.
    ``zero_vertices`` are taken to lie exactly on the plane; a point within ``bound_tol``
    outside a bound counts as inside, and clipped pieces not longer than ``bound_tol`` are
    dropped (so an arc ends exactly at a vertex placed on the bound). Raises :class:`ImprintError` (naming
    ``name``) when the plane misses the surface inside the bounds. ``section``: the
    :func:`plane_section` of these ``points``, ``tris``, ``plane`` and ``zero_vertices`` when the
    caller has it already (several arcs of one plane); computed here when None.
    """
    sec = plane_section(points, tris, plane, zero_vertices) if section is None else section
    if not len(sec.links):
        raise ImprintError(f"{name}: its plane does not cut the surface; check the member's position "
                           "(it must lie inside the aircraft)")
    if stop_vertices is not None and len(stop_vertices):
        sec = _cut_at_vertices(sec, np.asarray(stop_vertices, np.int64), points)
        bounds = ()
    p0 = sec.nodes[sec.links[:, 0]]
    p1 = sec.nodes[sec.links[:, 1]]
    t0, t1 = _clip_links(p0, p1, bounds, bound_tol)
    if bound_tol > 0 and len(bounds):
        # drop slivers of links that only touch a bound (zero-length links elsewhere stay)
        clipped = (t0 > 0) | (t1 < 1)
        keep = (t1 > t0) & ~(clipped & ((t1 - t0) * norm_rows(p1 - p0, axis=1) <= bound_tol))
    else:
        keep = t1 > t0
    if not keep.any():
        raise ImprintError(f"{name}: its plane cuts the surface only outside the member's bounds; "
                           "check the layout's stations and chord fractions")
    li = np.flatnonzero(keep)
    t0, t1 = t0[li], t1[li]
    q0 = p0[li] + t0[:, None] * (p1[li] - p0[li])
    q1 = p0[li] + t1[:, None] * (p1[li] - p0[li])
    # graph: original nodes keep their id; clipped ends become new terminal nodes
    k = len(sec.nodes)
    u = np.where(t0 > 0, k + 2 * np.arange(len(li)), sec.links[li, 0])
    v = np.where(t1 < 1, k + 2 * np.arange(len(li)) + 1, sec.links[li, 1])
    nn = k + 2 * len(li)
    pos = np.zeros((nn, 3))
    pos[:k] = sec.nodes
    pos[u] = q0
    pos[v] = q1
    # pick the component through the seed
    if seed is not None:
        seed = np.asarray(seed, float)
        cand = np.arange(len(li))
        if seed_tri is not None and seed_tri >= 0:
            hit = np.flatnonzero(sec.link_tri[li] == seed_tri)
            if len(hit):
                cand = hit
        a, b = q0[cand], q1[cand]
        ab = b - a
        L2 = np.einsum("ij,ij->i", ab, ab)
        tt = np.clip(np.einsum("ij,ij->i", seed - a, ab) / np.where(L2 > 0, L2, 1.0), 0, 1)
        dist = norm_rows(a + tt[:, None] * ab - seed, axis=1)
        best = cand[int(np.argmin(dist))]
    else:
        best = 0
    in_comp = arc_links(u, v, nn, best)
    lu, lv, ltri = u[in_comp], v[in_comp], sec.link_tri[li][in_comp]
    deg = np.bincount(np.concatenate([lu, lv]), minlength=nn)
    if (deg > 2).any():
        bad = np.flatnonzero(deg > 2)[:3]
        raise ImprintError(f"{name}: the surface is non-manifold where the member's plane cuts it "
                           f"(near {np.round(pos[bad], 6).tolist()}); repair the surface there")
    ends = np.flatnonzero(deg == 1)
    closed = len(ends) == 0
    start = int(ends.min()) if len(ends) else int(lu.min())
    # the walk from the start, the lowest neighbour first, and the link of each step
    # (kernels.arc_order: scipy's depth-first order of the link graph, compiled)
    order, seg_link = arc_order(lu, lv, nn, start)
    pts = pos[order]
    # triangle of each consecutive segment
    seg_tri = ltri[seg_link]
    # drop zero-length pieces (plane through vertices)
    if merge_tol is None:
        merge_tol = 1e-12 * bbox_diagonal(pts)
    step = norm_rows(np.diff(pts, axis=0), axis=1)
    keep_pt = np.concatenate([[True], step > merge_tol])
    if closed:
        keep_pt[-1] &= np.linalg.norm(pts[-1] - pts[0]) > merge_tol or len(pts) < 3
    idx = np.flatnonzero(keep_pt)
    seg_tri = seg_tri[idx[1:] - 1] if len(idx) > 1 else np.zeros(0, np.int64)
    return SectionArc(pts[idx], seg_tri, closed)
