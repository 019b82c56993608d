"""Building blocks of generated aircraft: airfoil sections, lofts through them, end caps, bodies.

Every function returns plain arrays: points ``(n, 3)`` and triangles ``(m, 3)`` of vertex indices.
A *section* is a closed loop of ``k`` points: the lower surface from the trailing edge to the
leading edge, then the upper surface back towards the trailing edge (:func:`airfoil_loop`). A
*loft* joins ``s`` sections of the same ``k`` points, each to the next, by two triangles per
quad (:func:`loft`); :func:`flat_cap` and :func:`round_cap` close its ends. Orientation is not
settled here: the caller makes the closed surface's signed volume positive
(:func:`orient_outward`) after checking every edge is used once in each direction.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Airfoil", "airfoil", "section_points", "loft", "flat_cap", "round_cap", "body_of_revolution",
           "orient_outward", "signed_volume", "match_cap"]


@dataclass(frozen=True)
class Airfoil:
    """A unit-chord section sampled at ``n + 1`` chord stations ``x`` (0 leading edge, 1 trailing
    edge, cosine spaced), heights ``upper`` and ``lower`` (in chords) at each, and the closed
    loop through them: ``loop`` ``(k, 2)`` as (x, z); ``lower_idx[i]`` and ``upper_idx[i]`` the
    loop indices of station ``i`` (the same at the leading edge, and at a sharp trailing edge)."""

    x: np.ndarray
    upper: np.ndarray
    lower: np.ndarray
    loop: np.ndarray
    lower_idx: np.ndarray
    upper_idx: np.ndarray

    @property
    def n(self) -> int:
        return len(self.x) - 1

    @property
    def blunt(self) -> bool:
        return bool(self.upper[-1] > self.lower[-1])


def airfoil(n: int, thickness: float, camber: float = 0.0, camber_pos: float = 0.4,
            te_thickness: float = 0.0) -> Airfoil:
    """NACA 4-digit section of unit chord with continuous parameters: largest ``thickness`` and
    ``camber`` (shares of the chord), camber at ``camber_pos``; the thickness is laid off normal to
    the chord line (so upper and lower points share their chord stations) with the closed-trailing-
    edge coefficient (-0.1036), and ``te_thickness`` > 0 opens the trailing edge linearly from the
    leading edge to a blunt base that tall. ``n`` intervals per side, cosine spaced (the leading-edge
    radius, 1.1 thickness^2 chords, is resolved for ``n`` >= 40 down to 4 % thickness)."""
    beta = np.linspace(0.0, np.pi, n + 1)
    x = 0.5 * (1.0 - np.cos(beta))
    x[-1] = 1.0
    yt = 5.0 * thickness * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4)
    yt = np.maximum(yt, 0.0) + 0.5 * te_thickness * x
    yt[0] = 0.0
    if camber > 0:
        p = camber_pos
        yc = np.where(x < p, camber / p**2 * (2 * p * x - x**2),
                      camber / (1 - p) ** 2 * ((1 - 2 * p) + 2 * p * x - x**2))
    else:
        yc = np.zeros_like(x)
    upper, lower = yc + yt, yc - yt
    blunt = te_thickness > 0
    lower_idx = np.arange(n, -1, -1)                     # loop index of station i on the lower side
    n_up = n if blunt else n - 1                        # upper stations 1..n (blunt) or 1..n-1
    upper_idx = np.concatenate([[n], n + np.arange(1, n_up + 1)])
    if not blunt:
        upper_idx = np.concatenate([upper_idx, [0]])    # the sharp trailing edge is the loop's first point
    loop = np.vstack([np.stack([x[::-1], lower[::-1]], 1), np.stack([x[1:n_up + 1], upper[1:n_up + 1]], 1)])
    return Airfoil(x, upper, lower, loop, lower_idx, upper_idx)


def section_points(af: Airfoil, le, u, w, chord: float) -> np.ndarray:
    """The section loop in space: ``le + chord (x u + z w)`` for the loop's (x, z); ``u`` the chord
    direction, ``w`` the thickness direction (unit vectors)."""
    L = af.loop
    return np.asarray(le, float) + chord * (L[:, :1] * np.asarray(u, float) + L[:, 1:] * np.asarray(w, float))


def loft(rings: np.ndarray, offset: int = 0) -> np.ndarray:
    """Triangles joining ``rings`` ``(s, k, 3)`` (closed loops of ``k`` points, stored in that
    order from vertex ``offset`` on), each to the next: two per quad."""
    s, k = rings.shape[:2]
    i, j = np.meshgrid(np.arange(s - 1), np.arange(k), indexing="ij")
    a = (i * k + j).ravel()
    b = (i * k + (j + 1) % k).ravel()
    c, d = b + k, a + k
    return np.vstack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]) + offset


def flat_cap(loop_2d: np.ndarray, offset: int) -> np.ndarray:
    """Triangles of the planar polygon ``loop_2d`` (its own vertices only: a constrained Delaunay
    triangulation), numbered from ``offset``."""
    import triangle as tr

    n = len(loop_2d)
    seg = np.stack([np.arange(n), (np.arange(n) + 1) % n], 1)
    t = tr.triangulate({"vertices": np.asarray(loop_2d, float), "segments": seg}, "pQ")
    if len(t["vertices"]) != n:
        raise RuntimeError("flat cap triangulation added points")   # 'p' without 'q'/'a' never does
    return np.asarray(t["triangles"], np.int64) + offset


def round_cap(af: Airfoil, ring: np.ndarray, ring_offset: int, outward, first_new: int, n_theta: int = 8,
              bulge: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Round end cap on the section ``ring`` ``(k, 3)`` (vertices ``ring_offset`` on): at each chord
    station the lower and upper points are joined by a half ellipse bulging along ``outward`` by
    ``bulge`` times the half thickness there (1: a revolved half circle), ``n_theta`` segments; a
    blunt trailing edge's half disc closes it. Returns the new points (numbered from ``first_new``)
    and the cap's triangles."""
    v = np.asarray(outward, float)
    v = v / np.linalg.norm(v)
    n, m = af.n, n_theta
    L, U = ring[af.lower_idx], ring[af.upper_idx]
    M, H = 0.5 * (U + L), 0.5 * (U - L)
    h = np.linalg.norm(H, axis=1)
    th = np.linspace(0.0, np.pi, m + 1)
    grid = np.empty((n + 1, m + 1), np.int64)
    grid[:, 0] = ring_offset + af.lower_idx
    grid[:, -1] = ring_offset + af.upper_idx
    live = h > 0                                        # collapsed columns: the leading edge, a sharp TE
    grid[~live, 1:-1] = grid[~live, :1]
    cols = np.flatnonzero(live)
    P = (M[cols, None, :] - np.cos(th[None, 1:-1, None]) * H[cols, None, :]
         + bulge * h[cols, None, None] * np.sin(th[None, 1:-1, None]) * v)
    grid[cols, 1:-1] = first_new + np.arange(len(cols) * (m - 1)).reshape(len(cols), m - 1)
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    a, b, c, d = grid[i, j], grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]
    T = np.vstack([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    if live[-1]:                                       # blunt trailing edge: half disc in its base plane
        jj = np.arange(1, m)
        T = np.vstack([T, np.stack([np.full(m - 1, grid[-1, 0]), grid[-1, jj + 1], grid[-1, jj]], 1)])
    T = T[(T[:, 0] != T[:, 1]) & (T[:, 1] != T[:, 2]) & (T[:, 0] != T[:, 2])]
    return P.reshape(-1, 3), T


def body_of_revolution(x, r, zc, n_around: int = 48, width: float = 1.0, height: float = 1.0):
    """Closed body: at each station ``x[i]`` an ellipse of half width ``width r[i]`` and half
    height ``height r[i]`` about ``(x[i], 0, zc[i])``, ``n_around`` points (one of them on top);
    the first and last stations (``r`` = 0) are poles. Returns ``(points, triangles)``."""
    x, r, zc = (np.asarray(a, float) for a in (x, r, zc))
    phi = np.pi / 2 + 2 * np.pi * np.arange(n_around) / n_around
    ring = np.stack([np.broadcast_to(x[1:-1, None], (len(x) - 2, n_around)),
                     width * r[1:-1, None] * np.cos(phi), zc[1:-1, None] + height * r[1:-1, None] * np.sin(phi)], -1)
    s = len(x) - 2
    P = np.vstack([[[x[0], 0.0, zc[0]]], ring.reshape(-1, 3), [[x[-1], 0.0, zc[-1]]]])
    T = loft(ring, offset=1)
    j = np.arange(n_around)
    nose = np.stack([np.zeros(n_around, np.int64), 1 + (j + 1) % n_around, 1 + j], 1)
    last = 1 + s * n_around
    base = 1 + (s - 1) * n_around
    tail = np.stack([np.full(n_around, last), base + j, base + (j + 1) % n_around], 1)
    return P, np.vstack([nose, T, tail])


def signed_volume(points, tris) -> float:
    """Signed volume enclosed by the closed triangulation (positive with outward normals)."""
    v = np.asarray(points, float)[np.asarray(tris)]
    return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)


def match_cap(cap: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """``cap`` turned, if needed, so that it runs each edge it shares with ``tris`` the other way
    (a consistently oriented closed surface uses every edge once in each direction)."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]).astype(np.int64)
    ce = np.concatenate([cap[:, [0, 1]], cap[:, [1, 2]], cap[:, [2, 0]]]).astype(np.int64)
    N = int(max(e.max(), ce.max())) + 1
    key = e[:, 0] * N + e[:, 1]
    same = int(np.isin(ce[:, 0] * N + ce[:, 1], key).sum())
    rev = int(np.isin(ce[:, 1] * N + ce[:, 0], key).sum())
    return cap[:, ::-1] if same > rev else cap


def orient_outward(points, tris) -> np.ndarray:
    """``tris`` reversed if their signed volume is negative."""
    return tris[:, ::-1].copy() if signed_volume(points, tris) < 0 else tris
