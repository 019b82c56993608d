"""A wing's planform measured from the skin: its sections from the root to the tip station.

:func:`measure_planform` slices the skin with planes normal to the wing's span axis and
measures each section (:func:`~shellmesh_mdao.layout.sections.measure_section`): leading and
trailing edge, chord, thickness, twist and the upper and lower skin heights. The result, a
:class:`Planform`, interpolates linearly between its measured stations; they are placed so
that it follows the real wing within a tolerance:

1. **Which loop is the wing.** A station plane may cut several bodies (a fuselage, a tail, the
   other wing). At the root station the wing's loop is the one containing the hint point
   ``near`` (projected on the plane; else the loop nearest to it) or, without a hint, the
   largest *wing-like* loop: the one with the longest chord among the loops at most
   :data:`WING_LIKE` as thick as they are long. From there the wing is followed station by
   station towards the tip (:data:`TRACK_STATIONS` even steps and every crank station): at
   each station the loop whose centre is nearest to the centre extrapolated from the two
   previous stations, within one previous chord of it.
2. **Where it is measured.** At those stations, then, between two neighbouring measured
   stations, at the middle station: when the measured section differs from the linear
   interpolation of its neighbours by more than ``tol`` (leading or trailing edge position,
   trailing-edge corners, upper or lower heights), the middle station is kept and both halves
   are checked again (down to :data:`MIN_STEP` of the span; at most :data:`MAX_STATIONS`
   stations). Crank stations are always measured, so a kink of the edges is followed exactly.
3. **Which side is up, which edge trails.** ``up`` given: made normal to the span axis. Else
   the normal of the mean chord direction of the root and tip sections, signed so that its
   largest component is positive. The trailing edge is on the side of ``aft`` when given; else
   the sharper edge (thinner at 5 % of the chord from the end, summed over the stations) or,
   when both edges are alike (less than 2 % of the chord apart on average), the side the tip
   lies towards from the root (a swept-back wing).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import LayoutError
from .sections import (CHORD_GRID, SectionShape, edge_bluntness, loop_frame, measure_section, section_loops)

__all__ = ["Planform", "measure_planform", "wing_loops", "loop_chord", "WING_LIKE", "TRACK_STATIONS",
           "MIN_STEP", "MAX_STATIONS"]

#: a loop is wing-like when its thickness is at most this share of its length
WING_LIKE = 0.4
#: even steps of the tracking march from the root to the tip station
TRACK_STATIONS = 32
#: the refinement stops at stations this share of the span apart
MIN_STEP = 1.0 / 512
#: at most this many measured stations per wing
MAX_STATIONS = 400


def loop_chord(loop: np.ndarray) -> tuple:
    """``(length, width, direction)`` of a loop: its diameter (the two points farthest apart),
    the loop's extent normal to that direction in its plane, and the unit direction."""
    p = loop if len(loop) <= 1500 else loop[np.linspace(0, len(loop) - 1, 1500).astype(int)]
    d = np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2)
    i, j = np.unravel_index(int(np.argmax(d)), d.shape)
    v = p[j] - p[i]
    L = float(np.linalg.norm(v))
    if L == 0:
        return 0.0, 0.0, np.array([1.0, 0.0, 0.0])
    v = v / L
    r = loop - loop.mean(0)
    r = r - np.outer(r @ v, v)
    w = float(np.linalg.norm(r, axis=1).max()) * 2.0 if len(r) else 0.0
    # the width across: the extent along the direction of the largest residual
    k = int(np.argmax(np.linalg.norm(r, axis=1)))
    n = r[k] / max(np.linalg.norm(r[k]), 1e-300)
    w = float(np.ptp(loop @ n))
    return L, w, v


def _center(loop):
    return 0.5 * (loop.min(0) + loop.max(0))


def _point_in_loop(q2, loop2) -> bool:
    x, y = q2
    p, r = loop2, np.roll(loop2, -1, axis=0)
    c = (p[:, 1] > y) != (r[:, 1] > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xs = p[:, 0] + (y - p[:, 1]) * (r[:, 0] - p[:, 0]) / (r[:, 1] - p[:, 1])
    return bool((c & (xs > x)).sum() % 2)


def wing_loops(loops: list, max_ratio: float = WING_LIKE) -> list:
    """Indices of the wing-like loops (thickness at most ``max_ratio`` of the length),
    longest first."""
    m = [(loop_chord(lp), i) for i, lp in enumerate(loops)]
    ok = [(c[0], i) for c, i in m if c[0] > 0 and c[1] <= max_ratio * c[0]]
    return [i for _, i in sorted(ok, key=lambda t: -t[0])]


@dataclass
class Planform:
    """A wing measured from its skin: ``axis`` (unit, from the root towards the tip), ``up``
    (unit, normal to it), ``e = axis x up``, ``aft`` (+1/-1: the trailing edge lies towards
    ``aft * e``), the measured ``stations`` (span coordinates ``x·axis``, increasing from the
    root to the tip) and their :class:`SectionShape` s; ``cranks`` the crank stations."""

    name: str
    axis: np.ndarray
    up: np.ndarray
    e: np.ndarray
    aft: float
    stations: np.ndarray
    shapes: list
    cranks: tuple = ()
    le: np.ndarray = field(init=False, repr=False)
    te: np.ndarray = field(init=False, repr=False)
    te_upper: np.ndarray = field(init=False, repr=False)
    te_lower: np.ndarray = field(init=False, repr=False)
    upper: np.ndarray = field(init=False, repr=False)
    lower: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        s = self.shapes
        self.le = np.stack([x.le for x in s])
        self.te = np.stack([x.te for x in s])
        self.te_upper = np.stack([x.te_upper for x in s])
        self.te_lower = np.stack([x.te_lower for x in s])
        self.upper = np.stack([x.upper for x in s])
        self.lower = np.stack([x.lower for x in s])

    # ------------------------------------------------------------------ basics
    @property
    def root(self) -> float:
        return float(self.stations[0])

    @property
    def tip(self) -> float:
        return float(self.stations[-1])

    @property
    def span(self) -> float:
        return self.tip - self.root

    def eta(self, t):
        """Span fraction (0 root, 1 tip) of station coordinates ``t``."""
        return (np.asarray(t, float) - self.root) / self.span

    def station(self, eta):
        """Station coordinate of span fractions ``eta``."""
        return self.root + np.asarray(eta, float) * self.span

    def _weights(self, t):
        t = np.clip(np.asarray(t, float), self.root, self.tip)
        i = np.clip(np.searchsorted(self.stations, t, side="right") - 1, 0, len(self.stations) - 2)
        w = (t - self.stations[i]) / (self.stations[i + 1] - self.stations[i])
        return i, w

    def _lerp(self, arr, t):
        i, w = self._weights(t)
        w = np.asarray(w)[..., None]
        return (1 - w) * arr[i] + w * arr[i + 1]

    def le_at(self, t):
        return self._lerp(self.le, t)

    def te_at(self, t):
        return self._lerp(self.te, t)

    def chord_point(self, t, c):
        """Point of the (interpolated) chord line at station ``t`` and chord fraction ``c``
        (broadcast)."""
        t, c = np.broadcast_arrays(np.asarray(t, float), np.asarray(c, float))
        le, te = self.le_at(t), self.te_at(t)
        return le + c[..., None] * (te - le)

    def heights(self, t, c):
        """``(upper, lower)`` skin heights along ``up`` above the chord line at station ``t``
        and chord fraction ``c`` (broadcast)."""
        t, c = np.broadcast_arrays(np.asarray(t, float), np.asarray(c, float))
        up = self._lerp(self.upper, t)
        lo = self._lerp(self.lower, t)
        cc = np.clip(c, 0.0, 1.0)
        hu = np.array([np.interp(ci, CHORD_GRID, ui) for ci, ui in zip(cc.reshape(-1), up.reshape(-1, up.shape[-1]))])
        hl = np.array([np.interp(ci, CHORD_GRID, li) for ci, li in zip(cc.reshape(-1), lo.reshape(-1, lo.shape[-1]))])
        return hu.reshape(cc.shape), hl.reshape(cc.shape)

    def mean_point(self, t, c):
        """The section's mean point at station ``t`` and chord fraction ``c``: the chord point
        moved along ``up`` to the middle of the upper and lower skin (a point inside the wing
        from which rays along ``+-up`` meet its upper and lower skin)."""
        p = self.chord_point(t, c)
        hu, hl = self.heights(t, c)
        return p + (0.5 * (hu + hl))[..., None] * self.up

    def thickness(self, t, c):
        hu, hl = self.heights(t, c)
        return hu - hl

    def chord(self, t):
        return np.linalg.norm(self.te_at(t) - self.le_at(t), axis=-1)

    def x_of(self, p):
        """Chordwise coordinate (towards the trailing edge) of points ``p``."""
        return np.asarray(p, float) @ self.e * self.aft

    def chord_fraction_at(self, t, x):
        """Chord fraction of the chordwise coordinate ``x`` at station ``t``."""
        xl, xt = self.x_of(self.le_at(t)), self.x_of(self.te_at(t))
        return (np.asarray(x, float) - xl) / (xt - xl)

    def summary(self) -> dict:
        """Station range, root and tip chord and thickness, largest thickness, twist range."""
        s = self.shapes
        return {"name": self.name, "axis": self.axis.tolist(), "up": self.up.tolist(),
                "root": self.root, "tip": self.tip, "n_stations": len(s),
                "root_chord": s[0].chord, "tip_chord": s[-1].chord,
                "root_thickness": s[0].thickness, "tip_thickness": s[-1].thickness,
                "max_thickness": max(x.thickness for x in s),
                "twist_deg": [min(x.twist_deg for x in s), max(x.twist_deg for x in s)],
                "blunt_trailing_edge": any(x.blunt for x in s)}


# ----------------------------------------------------------------------------- measurement
def _pick_root(loops, a, u0, e0, near, name, root):
    if not loops:
        raise LayoutError(f"wing '{name}': the root station plane (x·axis = {root:.6g}) does not cut the skin: "
                          "check the span axis and the root station")
    if near is not None:
        q = np.asarray(near, float)
        inside = [i for i, lp in enumerate(loops)
                  if _point_in_loop(np.array([q @ e0, q @ u0]), np.stack([lp @ e0, lp @ u0], 1))]
        if inside:
            return inside[0]
        return int(np.argmin([np.linalg.norm(lp - q, axis=1).min() for lp in loops]))
    cand = wing_loops(loops)
    if not cand:
        raise LayoutError(f"wing '{name}': no wing-like section at the root station (x·axis = {root:.6g}): the "
                          f"{len(loops)} loop(s) the plane cuts are all thicker than {WING_LIKE:g} of their length "
                          "(a fuselage?); move the root station outboard of the body, or give 'near' (a point of "
                          "the wing's root section)")
    return cand[0]


def _track(P, T, a, stations, root_loop, name):
    """Loops of the wing at ``stations`` (from the root, whose loop is given), each the loop
    nearest to the centre extrapolated from the two previous stations."""
    out = [root_loop]
    cen = [_center(root_loop)]
    for k in range(1, len(stations)):                    # march root -> tip
        t = stations[k]
        loops = section_loops(P, T, t * a, a)
        if len(cen) >= 2:
            pred = cen[-1] + (cen[-1] - cen[-2]) * (t - stations[k - 1]) / (stations[k - 1] - stations[k - 2])
        else:
            pred = cen[-1] + (t - stations[k - 1]) * a
        pred = pred + (t - pred @ a) * a
        prev_chord = loop_chord(out[-1])[0]
        best, bd = None, np.inf
        for lp in loops:
            d = float(np.linalg.norm(_center(lp) - pred))
            if d < bd:
                best, bd = lp, d
        if best is None or bd > max(prev_chord, 1e-300):
            raise LayoutError(f"wing '{name}': its section is lost at station x·axis = {t:.6g} (no loop within a chord "
                              f"of where the wing should be): the station range leaves the wing; move the tip "
                              "station inboard (or the root station outboard)")
        out.append(best)
        cen.append(_center(best))
    return out


def _nearest_loop(P, T, a, t, pred, chord, name):
    loops = section_loops(P, T, t * a, a)
    best, bd = None, np.inf
    for lp in loops:
        d = float(np.linalg.norm(_center(lp) - pred))
        if d < bd:
            best, bd = lp, d
    if best is None or bd > chord:
        raise LayoutError(f"wing '{name}': its section is lost at station x·axis = {t:.6g}: the wing has a gap "
                          "there, or the station range leaves it")
    return best


def _sign_largest(v):
    return v if v[int(np.argmax(np.abs(v)))] > 0 else -v


def _shape_error(m: SectionShape, a: SectionShape, b: SectionShape, w: float) -> float:
    def lerp(x, y):
        return (1 - w) * x + w * y
    errs = [np.linalg.norm(m.le - lerp(a.le, b.le)), np.linalg.norm(m.te - lerp(a.te, b.te)),
            np.linalg.norm(m.te_upper - lerp(a.te_upper, b.te_upper)),
            np.linalg.norm(m.te_lower - lerp(a.te_lower, b.te_lower)),
            np.abs(m.upper - lerp(a.upper, b.upper)).max(), np.abs(m.lower - lerp(a.lower, b.lower)).max()]
    return float(max(errs))


def measure_planform(points, tris, axis, root: float, tip: float, cranks=(), up=None, near=None, aft=None,
                     tol: float | None = None, name: str = "wing") -> Planform:
    """Measure a wing from the skin ``(points, tris)``: span ``axis`` (any length; the station
    coordinate of a point ``x`` is ``x·axis/|axis|``), ``root`` and ``tip`` station coordinates
    (the tip may lie on either side of the root), ``cranks`` between them, optional ``up``,
    ``near`` (a point of the wing's root section) and ``aft`` (a direction from the leading to
    the trailing edge); ``tol`` the interpolation tolerance (default 1/500 of the span). See
    the module docstring. Raises :class:`~shellmesh_mdao.errors.LayoutError` naming the wing."""
    P = np.asarray(points, float)
    T = np.asarray(tris, np.int64)
    a = np.asarray(axis, float)
    if not np.isfinite(a).all() or np.linalg.norm(a) == 0:
        raise LayoutError(f"wing '{name}': the span axis {a.tolist()} is zero or not finite")
    a = a / np.linalg.norm(a)
    root, tip = float(root), float(tip)
    if tip == root:
        raise LayoutError(f"wing '{name}': the root and tip stations are both {root:g}: give different stations")
    if tip < root:                                       # the wing runs towards -axis: flip the axis
        a, root, tip, cranks = -a, -root, -tip, tuple(-float(c) for c in cranks)
    cranks = tuple(sorted(float(c) for c in cranks))
    for c in cranks:
        if not root < c < tip:
            raise LayoutError(f"wing '{name}': crank station {abs(c):g} is not between the root and the tip station")
    span = tip - root
    tol = span / 500.0 if tol is None else float(tol)
    # a provisional frame for the root loop pick
    if up is not None:
        u0 = np.asarray(up, float)
        u0 = u0 - (u0 @ a) * a
        if np.linalg.norm(u0) <= 1e-9 * max(np.linalg.norm(up), 1e-300):
            raise LayoutError(f"wing '{name}': 'up' {np.asarray(up, float).tolist()} is parallel to the span axis; "
                              "give the normal of the wing's chord plane")
    else:
        u0 = np.cross(a, np.eye(3)[int(np.argmin(np.abs(a)))])
    _, u0, e0 = loop_frame(a, u0)
    loops = section_loops(P, T, root * a, a)
    root_loop = loops[_pick_root(loops, a, u0, e0, near, name, root)]
    track = np.unique(np.concatenate([np.linspace(root, tip, TRACK_STATIONS + 1), cranks]))
    tracked = _track(P, T, a, track, root_loop, name)
    # up and the trailing-edge side
    d_root, d_tip = loop_chord(tracked[0])[2], loop_chord(tracked[-1])[2]
    d_tip = d_tip if d_tip @ d_root >= 0 else -d_tip
    d = d_root + d_tip
    d = d - (d @ a) * a
    if up is None:
        u = _sign_largest(np.cross(a, d / np.linalg.norm(d)))
    else:
        u = u0
        cosang = abs(u @ d) / np.linalg.norm(d)
        if cosang > np.cos(np.radians(45.0)):
            raise LayoutError(f"wing '{name}': 'up' {np.round(u, 6).tolist()} lies within 45 deg of the wing's chord "
                              f"{np.round(d / np.linalg.norm(d), 6).tolist()}: give the normal of its chord plane")
    a, u, e = loop_frame(a, u)
    if aft is not None:
        av = np.asarray(aft, float)
        if abs(av @ e) <= 1e-9 * np.linalg.norm(av):
            raise LayoutError(f"wing '{name}': 'aft' {av.tolist()} has no component along the chord")
        sgn = 1.0 if av @ e > 0 else -1.0
    else:
        tot, ch = 0.0, 0.0
        for lp in tracked:
            bm, bp = edge_bluntness(lp, e, u)
            L = float(np.ptp(lp @ e))
            tot += (bm - bp) / max(L, 1e-300)
            ch += 1.0
        if abs(tot) / ch >= 0.02:
            sgn = 1.0 if tot > 0 else -1.0               # the -e end is thicker: the leading edge
        else:
            shift = (_center(tracked[-1]) - _center(tracked[0])) @ e
            sgn = 1.0 if shift >= 0 else -1.0
    shapes = {float(t): measure_section(lp, a, u, sgn, name) for t, lp in zip(track, tracked)}
    # refinement
    st = sorted(shapes)
    stack = [(st[i], st[i + 1]) for i in range(len(st) - 1)]
    min_dt = MIN_STEP * span
    while stack and len(shapes) < MAX_STATIONS:
        t0, t1 = stack.pop()
        if t1 - t0 <= 2 * min_dt:
            continue
        tm = 0.5 * (t0 + t1)
        s0, s1 = shapes[t0], shapes[t1]
        pred = 0.5 * (s0.center + s1.center)
        pred = pred + (tm - pred @ a) * a
        lp = _nearest_loop(P, T, a, tm, pred, max(s0.chord, s1.chord), name)
        sm = measure_section(lp, a, u, sgn, name)
        if _shape_error(sm, s0, s1, 0.5) > tol:
            shapes[tm] = sm
            stack += [(t0, tm), (tm, t1)]
    st = np.array(sorted(shapes))
    pf = Planform(name=name, axis=a, up=u, e=e, aft=sgn, stations=st, shapes=[shapes[t] for t in st],
                  cranks=cranks)
    return pf
