"""Small helpers the imprint's modules share: triangle angles and normals, concatenated index
ranges, edge keys, arc-length parameters of points on a short polyline, and the standing rule of
every step that moves skin vertices (:func:`stands_up`)."""
from __future__ import annotations

import numpy as np

from .kernels import corner_cosines
from ..mesh import norm_rows

__all__ = ["tri_angles_min", "angles3", "min_angle_from_cos", "min_angles_small", "unit_normals", "ranges",
           "edge_keys", "has_edge", "polyline_param", "MAX_STAND", "MIN_RISE", "standing", "stands_up"]

# the standing rule of the moves of skin vertices (:func:`stands_up`): no triangle may come to stand
# more than MAX_STAND degrees off the input surface (closer to across it than along it), having
# risen by more than MIN_RISE degrees (a vertex carried across a crease turns its triangles by
# tens of degrees; a move within a ridge tighter than the element size -- a leading edge, a tail
# cone at a coarse size -- turns the triangles already standing across it by a few)
MAX_STAND = 45.0
MIN_RISE = 20.0


def tri_angles_min(P, T):
    """Smallest interior angle (degrees) of each triangle ``P[T]``."""
    return angles3(P[np.asarray(T)[:, :3]])


def angles3(Pn):
    """Smallest interior angle (degrees) of triangles given by corner coordinates (t, 3, 3)."""
    # the cosines from a compiled loop (einsum's dot over max(|u| |v|, 1e-300)), the angles
    # from numpy's arccos
    return min_angle_from_cos(corner_cosines(Pn))


def min_angle_from_cos(c):
    """Smallest angle (degrees) of triangles from their (t, 3) corner cosines (numpy's arccos)."""
    ang = np.degrees(np.arccos(np.clip(c, -1, 1)))
    return np.minimum(np.minimum(ang[:, 0], ang[:, 1]), ang[:, 2])


def min_angles_small(X):
    """Smallest interior angle (degrees) of triangles given by their corners (t, 3, 3); the
    same as :func:`angles3` with fewer array operations (for the few faces of a repair)."""
    e = X[:, [1, 2, 0]] - X                                   # e[:, i]: corner i -> i + 1
    l2 = np.einsum("tij,tij->ti", e, e)
    ep = e[:, [2, 0, 1]]                                      # edge arriving at corner i
    cos = -np.einsum("tij,tij->ti", e, ep) / np.maximum(np.sqrt(l2 * l2[:, [2, 0, 1]]), 1e-300)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).min(1)


def unit_normals(X):
    """Unit normals of triangles given by their corners (t, 3, 3); zero for degenerate ones."""
    u = X[:, 1] - X[:, 0]
    v = X[:, 2] - X[:, 0]
    n = np.empty_like(u)
    n[:, 0] = u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1]
    n[:, 1] = u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2]
    n[:, 2] = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]
    ln = np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
    return np.where(ln > 0, n / np.where(ln > 0, ln, 1.0), 0.0)


def ranges(starts, stops):
    """Concatenated aranges [starts[i], stops[i]) (vectorised)."""
    lens = stops - starts
    if not len(lens) or lens.sum() == 0:
        return np.zeros(0, np.int64)
    idx = np.arange(lens.sum())
    off = np.repeat(starts - np.concatenate([[0], np.cumsum(lens)[:-1]]), lens)
    return idx + off


def edge_keys(T, n):
    """Sorted unique keys ``min * n + max`` of the edges of triangles T (or of edges T, (k, 2))."""
    a, b = T.ravel(), np.roll(T, -1, axis=1).ravel()
    return np.unique(np.minimum(a, b) * n + np.maximum(a, b))


def has_edge(ekeys, a, b, n):
    """Whether each edge ``a[i]-b[i]`` is among the sorted edge keys ``ekeys`` (:func:`edge_keys`)."""
    k = np.minimum(a, b) * n + np.maximum(a, b)
    i = np.minimum(np.searchsorted(ekeys, k), max(len(ekeys) - 1, 0))
    return (ekeys[i] == k) if len(ekeys) else np.zeros(len(k), bool)


def polyline_param(q, poly, cum):
    """Arc-length parameter of the closest point on the open polyline ``poly`` (cumulative lengths
    ``cum``) to each query point of ``q``."""
    a, b = poly[:-1], poly[1:]
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    # brute force over segments in chunks (chains are short: hundreds of segments)
    out = np.empty(len(q))
    for s in range(0, len(q), 256):
        qq = q[s:s + 256]
        t = np.clip(np.einsum("qij,ij->qi", qq[:, None, :] - a[None], ab) / np.where(L2 > 0, L2, 1), 0, 1)
        x = a[None] + t[..., None] * ab[None]
        dist = norm_rows(x - qq[:, None, :], axis=2)
        j = np.argmin(dist, axis=1)
        out[s:s + 256] = cum[j] + t[np.arange(len(qq)), j] * np.sqrt(L2[j])
    return out


def standing(X, locator):
    """Degrees (0 to 90) by which each triangle given by its corners ``X`` (t, 3, 3) stands off
    the input surface: the largest angle between its plane and the input's tangent plane at the
    input points closest to its centroid and to a point near each corner, inside it (a corner on
    a sharp edge has two tangent planes; the point beside it, one). Unsigned: a sliver along a
    thin sharp edge (a trailing edge) has a point about as close to the surface's far side as
    to its own, and a turned-over triangle is another check's."""
    fn = unit_normals(X)
    W = np.array([[1.0, 1.0, 1.0], [4.0, 1.0, 1.0], [1.0, 4.0, 1.0], [1.0, 1.0, 4.0]]) / np.array([[3.0], [6.0], [6.0], [6.0]])
    Y = np.einsum("sk,tkj->tsj", W, X)                              # (t, 4, 3) sample points
    _, tri, _ = locator.closest(Y.reshape(-1, 3))
    sn = unit_normals(locator.points[locator.triangles[tri]]).reshape(len(X), 4, 3)
    cos = np.abs(np.einsum("tsj,tj->ts", sn, fn)).min(axis=1)
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))


def stands_up(X0, X1, locator, max_stand=MAX_STAND):
    """The standing rule of every step that moves skin vertices (the imprint's smoothing rounds
    and its local repair): True where triangle ``X1`` (t, 3, 3), triangle ``X0`` after a move of
    its corners, stands more than ``max_stand`` degrees off the input surface (:func:`standing`),
    more than :data:`MIN_RISE` degrees further than it did. Across a sharp input edge that is no
    feature line (the remesh drops the outline of a tip cap thinner than its deviation near a
    sharp trailing edge) a vertex of the cap's outline moved onto the skin beside it leaves its
    cap triangles standing across the crease; the quads merged and subdivided from them fold
    over it."""
    after = standing(X1, locator)
    return (after > max_stand) & (after > standing(X0, locator) + MIN_RISE)
