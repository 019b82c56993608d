"""Wing sections: the skin cut by a span-station plane, and the shape of one wing section.

:func:`section_loops` cuts the skin with a plane (exact plane sections,
:func:`~shellmesh_mdao.core.section.plane_section`) and returns its closed loops; the open
arcs of an unsewn surface (CAD patches that do not share their edges) are joined end to end,
nearest ends first, when the gap is small against the arcs (at most :data:`JOIN_GAP` of the
larger arc's extent).

:func:`measure_section` measures one wing section loop in the wing's frame (span axis ``a``,
up ``u`` normal to it, ``e = a x u`` the third direction, all in the station plane but ``a``):

* **trailing edge**: the loop's extreme point along the chordwise direction on the
  trailing-edge side. From it the loop is walked both ways while it runs across the chord
  (its direction within 45 degrees of ``u``): a sharp trailing edge stops at once (one point);
  a blunt one ends at its two **corners** (the upper and lower end of its base), a rounded one
  where its tangent turns past 45 degrees. The trailing-edge point is the middle of the two
  corners;
* **leading edge**: the loop point farthest from the trailing-edge point;
* **chord** ``|te - le|``; **twist**: the angle of the chord line about the span axis;
* **heights**: on a grid of chord fractions ``c`` (:data:`CHORD_GRID`), the upper and lower
  skin heights along ``u`` above the chord line point ``le + c (te - le)`` (where the line
  through that point along ``u`` leaves the loop upward and downward); the **thickness** is
  the largest difference. The section's mean point at ``c`` is the chord point moved to the
  middle of the two heights: the point a member seed at that chord fraction starts from.

Which end is the trailing edge: the side given by the caller (``aft``, +1 or -1 along ``e``),
which :func:`edge_bluntness` helps decide: the sharper end of a section (thinner at 5 % of the
chord from the end) is its trailing edge.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from ..core.kernels import arc_order
from ..core.section import Plane, plane_section
from ..errors import LayoutError

__all__ = ["JOIN_GAP", "CHORD_GRID", "SectionShape", "section_loops", "loop_frame", "edge_bluntness",
           "measure_section", "line_heights"]

#: open arcs of a section are joined when the gap between their ends is at most this share of
#: the larger arc's extent (unsewn CAD patches leave gaps of a fraction of a percent)
JOIN_GAP = 0.05
#: chord fractions at which a section's upper and lower heights are measured (cosine spaced:
#: dense at the leading and trailing edge, where the skin curves most)
CHORD_GRID = 0.5 * (1.0 - np.cos(np.pi * np.arange(41) / 40.0))
#: a trailing edge is blunt when its base is taller than this share of the chord
BLUNT_SHARE = 1e-3


def _dedupe(p: np.ndarray, closed: bool, tol: float) -> np.ndarray:
    if len(p) < 2:
        return p
    keep = np.concatenate([[True], np.linalg.norm(np.diff(p, axis=0), axis=1) > tol])
    p = p[keep]
    if closed and len(p) > 2 and np.linalg.norm(p[-1] - p[0]) <= tol:
        p = p[:-1]
    return p


def _join_arcs(arcs: list, loops: list) -> None:
    """Join open arcs end to end, the smallest gap first (an arc's own two ends too), while
    the gap is at most :data:`JOIN_GAP` of the larger arc's extent; closed results go to
    ``loops``, arcs that cannot be closed are dropped."""
    arcs = [a for a in arcs if len(a) >= 2]
    while arcs:
        best = None
        ext = [float(np.linalg.norm(np.ptp(a, axis=0))) for a in arcs]
        for i, a in enumerate(arcs):                       # loop over arc pairs (a handful of arcs)
            g = float(np.linalg.norm(a[-1] - a[0]))
            if len(a) >= 3 and g <= JOIN_GAP * ext[i] and (best is None or g < best[0]):
                best = (g, i, i, False)
            for j, b in enumerate(arcs):
                if j == i:
                    continue
                for rev in (False, True):
                    bs = b[-1] if rev else b[0]
                    g = float(np.linalg.norm(a[-1] - bs))
                    if g <= JOIN_GAP * max(ext[i], ext[j]) and (best is None or g < best[0]):
                        best = (g, i, j, rev)
        if best is None:
            return
        _, i, j, rev = best
        if i == j:
            loops.append(arcs.pop(i))
            continue
        b = arcs[j][::-1] if rev else arcs[j]
        arcs[i] = np.vstack([arcs[i], b])
        arcs.pop(j)


def section_loops(points: np.ndarray, tris: np.ndarray, point, normal) -> list:
    """The closed loops in which the plane through ``point`` with normal ``normal`` cuts the
    surface ``(points, tris)``: a list of (k, 3) arrays (the last point not repeated), open
    arcs joined where the surface is not sewn (:data:`JOIN_GAP`)."""
    P = np.asarray(points, float)
    sec = plane_section(P, np.asarray(tris, np.int64), Plane.make(point, normal))
    if not len(sec.links):
        return []
    n = len(sec.nodes)
    tol = 1e-12 * float(np.linalg.norm(np.ptp(sec.nodes, axis=0)) + 1.0)
    g = sparse.coo_matrix((np.ones(len(sec.links)), (sec.links[:, 0], sec.links[:, 1])), shape=(n, n))
    nc, lab = connected_components(g, directed=False)
    deg = np.bincount(sec.links.ravel(), minlength=n)
    comp_links = lab[sec.links[:, 0]]
    order_l = np.argsort(comp_links, kind="stable")
    starts = np.searchsorted(comp_links[order_l], np.arange(nc + 1))
    loops, arcs = [], []
    for c in range(nc):                                  # loop over the section's pieces
        li = order_l[starts[c]:starts[c + 1]]
        if not len(li):
            continue
        lu, lv = sec.links[li, 0], sec.links[li, 1]
        nodes = np.unique(np.concatenate([lu, lv]))
        ends = nodes[deg[nodes] == 1]
        if (deg[nodes] > 2).any():
            continue                                     # a non-manifold piece: not a wing section
        start = int(ends.min()) if len(ends) else int(lu.min())
        order, _ = arc_order(lu, lv, n, start)
        p = sec.nodes[order]
        if len(ends):
            arcs.append(_dedupe(p, False, tol))
        else:
            p = _dedupe(p, True, tol)
            if len(p) >= 3:
                loops.append(p)
    _join_arcs(arcs, loops)
    return loops


def loop_frame(axis, up):
    """Unit span axis ``a``, up ``u`` (made normal to ``a``) and ``e = a x u``."""
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    u = np.asarray(up, float)
    u = u - (u @ a) * a
    u = u / np.linalg.norm(u)
    return a, u, np.cross(a, u)


def line_heights(loop2: np.ndarray, x: np.ndarray):
    """Upper and lower ``v`` where the vertical lines ``X = x`` (in the loop's 2D frame
    ``(X, V)``) cross the closed polygon ``loop2`` (k, 2): arrays ``(hi, lo)``, NaN where a line
    misses it."""
    p = loop2
    q = np.roll(loop2, -1, axis=0)
    x = np.asarray(x, float).reshape(-1, 1)
    gp, gq = p[None, :, 0] - x, q[None, :, 0] - x
    cross = (gp >= 0) != (gq >= 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(cross, gp / (gp - gq), np.nan)
    v = p[None, :, 1] + t * (q[None, :, 1] - p[None, :, 1])
    v = np.where(cross, v, np.nan)
    with np.errstate(all="ignore"):
        hi = np.where(cross.any(1), np.nanmax(np.where(cross, v, -np.inf), axis=1), np.nan)
        lo = np.where(cross.any(1), np.nanmin(np.where(cross, v, np.inf), axis=1), np.nan)
    return hi, lo


def edge_bluntness(loop: np.ndarray, e: np.ndarray, u: np.ndarray) -> tuple:
    """Thickness of a section loop (along ``u``) at 5 % of its extent along ``e`` from each end:
    ``(at the -e end, at the +e end)``; the thinner end is the sharper edge."""
    X, V = loop @ e, loop @ u
    lo, hi = X.min(), X.max()
    h, l_ = line_heights(np.stack([X, V], 1), np.array([lo + 0.05 * (hi - lo), hi - 0.05 * (hi - lo)]))
    return float(h[0] - l_[0]), float(h[1] - l_[1])


@dataclass
class SectionShape:
    """One measured wing section (see the module docstring).

    ``station``   its span coordinate (``x·a``); ``le``, ``te`` (3,) the chord line's ends;
    ``te_upper``, ``te_lower`` (3,) the trailing-edge corners (both ``te`` when it is sharp);
    ``blunt`` whether it has a base; ``chord``, ``thickness``; ``twist_deg`` the chord's angle
    about the span axis (positive: trailing edge down along ``-u``); ``upper``, ``lower``
    (len(CHORD_GRID),) the skin heights along ``u`` above the chord line at :data:`CHORD_GRID`;
    ``loop`` the section loop; ``center`` (3,) the middle of its extent."""

    station: float
    le: np.ndarray
    te: np.ndarray
    te_upper: np.ndarray
    te_lower: np.ndarray
    blunt: bool
    chord: float
    thickness: float
    twist_deg: float
    upper: np.ndarray
    lower: np.ndarray
    loop: np.ndarray
    center: np.ndarray

    def chord_point(self, c) -> np.ndarray:
        c = np.asarray(c, float)[..., None]
        return self.le + c * (self.te - self.le)


def measure_section(loop: np.ndarray, axis, up, aft: float, name: str = "wing") -> SectionShape:
    """Measure the section ``loop`` (k, 3) of a wing whose span axis is ``axis`` and up ``up``
    (made normal to the axis); ``aft`` (+1 or -1): the trailing edge lies towards ``aft * e``,
    ``e = axis x up``. See the module docstring."""
    a, u, e = loop_frame(axis, up)
    loop = np.asarray(loop, float)
    k = len(loop)
    X, V = loop @ e * aft, loop @ u                     # X grows towards the trailing edge
    i0 = int(np.argmax(X))
    step = np.roll(loop, -1, axis=0) - loop              # segment i: loop[i] -> loop[i+1]
    ln = np.linalg.norm(step, axis=1)
    across = np.abs(step @ u) >= np.cos(np.radians(45.0)) * np.maximum(ln, 1e-300)
    j = i0                                               # walk forward while the segments run across
    for _ in range(k):
        if not across[j % k]:
            break
        j += 1
    i = i0                                               # and backward
    for _ in range(k):
        if not across[(i - 1) % k]:
            break
        i -= 1
    ca, cb = loop[i % k], loop[j % k]
    te_up, te_lo = (ca, cb) if ca @ u >= cb @ u else (cb, ca)
    te = 0.5 * (te_up + te_lo)
    d2 = np.linalg.norm(loop - te, axis=1)
    le = loop[int(np.argmax(d2))].copy()
    chord_v = te - le
    chord = float(np.linalg.norm(chord_v))
    if chord <= 0:
        raise LayoutError(f"wing '{name}': a section at station {float(loop[0] @ a):.6g} has no chord")
    blunt = float((te_up - te_lo) @ u) > BLUNT_SHARE * chord
    if not blunt:
        te_up = te_lo = te = loop[i0].copy()
        chord_v = te - le
        chord = float(np.linalg.norm(chord_v))
    # heights along u above the chord line at the grid's chord fractions
    xc = (le + CHORD_GRID[:, None] * chord_v) @ e * aft
    hi, lo = line_heights(np.stack([X, V], 1), xc)
    base = (le + CHORD_GRID[:, None] * chord_v) @ u
    upper, lower = hi - base, lo - base
    upper[0] = lower[0] = 0.0
    upper[-1], lower[-1] = float((te_up - te) @ u), float((te_lo - te) @ u)
    bad = ~np.isfinite(upper) | ~np.isfinite(lower)
    if bad.any():                                         # a line grazing the loop's end: interpolate
        good = np.flatnonzero(~bad)
        upper[bad] = np.interp(CHORD_GRID[bad], CHORD_GRID[good], upper[good])
        lower[bad] = np.interp(CHORD_GRID[bad], CHORD_GRID[good], lower[good])
    twist = float(np.degrees(np.arctan2(-(chord_v @ u), (chord_v @ e) * aft)))
    lo3, hi3 = loop.min(0), loop.max(0)
    return SectionShape(float(loop[0] @ a), le, te, te_up.copy(), te_lo.copy(), bool(blunt), chord,
                        float(np.max(upper - lower)), twist, upper, lower, loop, 0.5 * (lo3 + hi3))
