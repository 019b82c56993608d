"""2-D polygons and plane frames: an orthonormal frame of a plane, points in its 2-D coordinates,
which points lie inside a polygon, sample points inside a polygon. Shared by the imprint (coplanar
member overlaps) and the members stage (checks between members, meshing in a member's plane)."""
from __future__ import annotations

import numpy as np

from ..mesh import norm_rows

__all__ = ["frame_from_normal", "to2d", "point_in_polygon", "interior_samples"]


def frame_from_normal(n, p):
    """An orthonormal frame ``(e1, e2, origin)`` of the plane through ``p`` with unit normal ``n``
    (``e1`` normal to ``n`` and to the axis along which ``n`` is smallest)."""
    a = np.eye(3)[int(np.argmin(np.abs(n)))]
    e1 = np.cross(n, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(n, e1), np.asarray(p, float)


def to2d(pts, e1, e2, o):
    """2-D coordinates of the points ``pts`` (k, 3) in the plane frame ``(e1, e2, o)``."""
    X = pts - o
    return np.stack([X @ e1, X @ e2], 1)


def point_in_polygon(q: np.ndarray, poly: np.ndarray, tol: float, chunk: int = 2048) -> np.ndarray:
    """Points of ``q`` strictly inside the closed polygon ``poly`` (farther than ``tol`` from
    its boundary), even-odd rule, vectorised over points x edges in chunks of points."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a
    L2 = np.einsum("ij,ij->i", ab, ab)
    out = np.zeros(len(q), bool)
    for s in range(0, len(q), chunk):
        qq = q[s:s + chunk]
        qx, qy = qq[:, None, 0], qq[:, None, 1]
        cond = (a[None, :, 1] > qy) != (b[None, :, 1] > qy)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = a[None, :, 0] + (qy - a[None, :, 1]) * ab[None, :, 0] / ab[None, :, 1]
        inside = (np.count_nonzero(cond & (qx < xc), axis=1) % 2) == 1
        t = np.clip(np.einsum("qij,ij->qi", qq[:, None] - a[None], ab) / np.where(L2 > 0, L2, 1.0), 0, 1)
        d = norm_rows(a[None] + t[..., None] * ab[None] - qq[:, None], axis=2).min(1)
        out[s:s + chunk] = inside & (d > tol)
    return out


def interior_samples(poly2: np.ndarray) -> np.ndarray:
    """Centroids of a coarse constrained triangulation of a simple polygon (points strictly inside)."""
    import triangle as tr

    n = len(poly2)
    if n < 3:
        return np.zeros((0, 2))
    seg = np.stack([np.arange(n), (np.arange(n) + 1) % n], 1)
    try:
        t = tr.triangulate({"vertices": poly2, "segments": seg.astype(np.int32)}, "pQ")
    except Exception:                                 # pragma: no cover - degenerate outline
        return np.zeros((0, 2))
    T = np.asarray(t.get("triangles", np.zeros((0, 3))), np.int64).reshape(-1, 3)
    V = np.asarray(t["vertices"])
    return V[T].mean(1) if len(T) else np.zeros((0, 2))
