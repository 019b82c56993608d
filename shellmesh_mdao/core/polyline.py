"""Polylines: closest points on segments and polylines, arc-length parameters, and points and
pieces at given arc lengths. Shared by the imprint (chain vertices on their exact arcs) and the
members stage (chain spacing along the same arcs)."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from .kernels import segments_scan
from ..mesh import norm_rows

__all__ = ["SCAN_WORK", "closest_on_segments", "pick_segments", "closest_on_polyline", "arc_param", "arc_point",
           "sub_polyline"]


#: closest points on polylines: up to this many query-segment pairs every query scans every
#: segment in a compiled loop; above, a KD-tree of segment midpoints picks candidates (the same
#: points either way)
SCAN_WORK = 2_000_000


def closest_on_segments(q, a, b, full: bool = False):
    """Closest points on a set of segments a-b (s, 3) to query points q (n, 3), and their
    distances (every segment scanned by a compiled loop up to :data:`SCAN_WORK` pairs, else a
    KD-tree of segment midpoints with a conservative candidate radius: the same points); with
    ``full``, also the segment of each closest point and its parameter along it (ties: the
    lowest segment)."""
    q = np.atleast_2d(q)
    ab = b - a
    if len(q) * len(a) <= SCAN_WORK:
        # every query against every segment in one compiled loop: the same pick (the nearest
        # candidate, the lowest segment among equals) over a set that holds the KD-tree's
        x, dist, si, t = segments_scan(q, np.zeros(len(q), np.int64), np.full(len(q), len(a)), a, ab)
        return (x, dist, si, t) if full else (x, dist)
    L = norm_rows(ab, axis=1)
    tree = cKDTree(0.5 * (a + b))
    d0, _ = tree.query(q)
    cand = tree.query_ball_point(q, d0 + 0.5 * L.max() + 1e-300)
    cnt = np.fromiter((len(c) for c in cand), np.int64, len(cand))
    qi = np.repeat(np.arange(len(q)), cnt)
    si = np.concatenate([np.asarray(c, np.int64) for c in cand])
    x, dist, si, t = pick_segments(q, qi, si, a, ab)
    return (x, dist, si, t) if full else (x, dist)


def pick_segments(q, qi, si, a, ab):
    """Per query ``q[qi]`` (every query listed), the nearest of its candidate segments ``si``
    (``a + t ab``; ties: the lowest segment): ``(points, distances, segments, t)`` in query
    order."""
    L2 = np.einsum("ij,ij->i", ab[si], ab[si])
    t = np.clip(np.einsum("ij,ij->i", q[qi] - a[si], ab[si]) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
    x = a[si] + t[:, None] * ab[si]
    dist = norm_rows(x - q[qi], axis=1)
    order = np.lexsort((si, dist, qi))
    first = np.ones(len(order), bool)
    first[1:] = qi[order][1:] != qi[order][:-1]
    o = order[first]
    return x[o], dist[o], si[o], t[o]


def closest_on_polyline(q: np.ndarray, poly: np.ndarray, closed: bool = False) -> np.ndarray:
    """Closest points on a polyline (k, 3) to query points (n, 3), vectorised via a KD-tree
    of segment midpoints with a conservative candidate radius (:func:`closest_on_segments`)."""
    q = np.atleast_2d(np.asarray(q, float))
    p = np.vstack([poly, poly[:1]]) if closed else poly
    return closest_on_segments(q, p[:-1], p[1:])[0]


def arc_param(q: np.ndarray, poly: np.ndarray, closed: bool):
    """Arc-length parameter of the closest point on a polyline to each query point, and the
    polyline's cumulative lengths (:func:`closest_on_segments`)."""
    p = np.vstack([poly, poly[:1]]) if closed else poly
    L = norm_rows(p[1:] - p[:-1], axis=1)
    cum = np.concatenate([[0.0], np.cumsum(L)])
    _, _, seg, t = closest_on_segments(q, p[:-1], p[1:], full=True)
    return cum[seg] + t * L[seg], p, cum


def arc_point(p: np.ndarray, cum: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points at the arc-length parameters ``s`` (clipped to the polyline) of the polyline with
    points ``p`` and cumulative lengths ``cum`` (as :func:`arc_param` returns them)."""
    s = np.clip(s, 0.0, cum[-1])
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(cum) - 2)
    seg = np.maximum(cum[i + 1] - cum[i], 1e-300)
    t = np.clip((s - cum[i]) / seg, 0.0, 1.0)
    return p[i] + t[:, None] * (p[i + 1] - p[i])


def sub_polyline(p: np.ndarray, cum: np.ndarray, s0: float, s1: float) -> np.ndarray:
    """The piece of a polyline (points ``p``, cumulative lengths ``cum``) between parameters
    ``s0 < s1``."""
    inner = (cum > s0) & (cum < s1)
    return np.vstack([arc_point(p, cum, np.array([s0])), p[inner], arc_point(p, cum, np.array([s1]))])
