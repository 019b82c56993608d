"""Station-given wings resolved against the skin: spars at local chord fractions, ribs in the
orientation asked for, every member inside its wing box (:func:`resolve_layout`).

A station-given wing (:class:`~shellmesh_mdao.layout.schema.StationWing`) is measured from the
skin (:func:`~shellmesh_mdao.layout.planform.measure_planform`); its members are then laid out
in the **planform plane** of coordinates ``t`` (station, along the span axis ``a``) and ``x``
(chordwise, towards the trailing edge, along ``aft * e``). Every member plane contains the
wing's ``up`` (normal to ``a``), so a member is a line of the planform plane; its seed points are
the planform's mean points (:meth:`~shellmesh_mdao.layout.planform.Planform.mean_point`), inside
the wing, from which the projection stage casts rays along ``+-up``.

**Spars.** Spar ``j`` runs at chord fraction ``c_j(eta)`` of the *local* chord:
``x_j(t) = x_le(t) + c_j (x_te(t) - x_le(t))``. It is straightened into a polyline of the
planform plane (Douglas-Peucker, tolerance :data:`SPAR_TOL` element sizes) with a kink at
every crank station: a kinked spar is a chain of planar pieces (``<wing>/spar_<j>`` when
straight, else ``<wing>/spar_<j>/part_<p>`` from the root) meeting at their kink lines. Its
pieces are at least two element sizes long and its kinks at least one size from where a rib
meets it (a crank takes the nearest station allowed), so no three members meet on one line;
where the ribs leave no room the spar stays straight across. Spars end on the root and tip
ribs.

**Ribs.** Rib ``k`` at span fraction ``eta_k`` passes through the middle of its box (the
middle chord fraction of its first and last spar) at station ``t_k``, in the orientation
``ribs.orientation``: ``normal_to_spar`` (normal to spar ``ribs.spar``, the rear spar by
default, where the rib meets it), ``streamwise`` (the station plane, normal to the span axis),
``normal_to_midchord`` (normal to the line from the root to the tip mid-chord point) or a
vector (the rib planes' normal, made normal to ``up``). The root and tip ribs lie along the
root and tip stations (``end_ribs: station``, the default: the side of body or the symmetry
plane, and the tip) or take the ribs' orientation and touch the station at their inboard
(outboard) end (``end_ribs: same``). Every two neighbouring ribs must stay at least half their
stations' spacing and one element size (ribs whose stations are closer than that: their
stations' spacing) apart at both ends, the root and tip ribs included: a rib that would come
closer, or cross its neighbour, is turned towards the station direction step by step (a fan at
the root and tip of a swept wing) until they do; with ``end_ribs: same`` the root and tip ribs
turn too, each still touching its station (on a short, highly swept surface ribs normal to a spar
would cross from one end station to the other). Turned that way, every rib at last lies along its
station, so any sweep and aspect ratio has a valid layout when the stations are far enough apart;
ribs turned by more than :data:`TURN_NOTE` degrees are named in ``StationWing.notes``. A rib runs
from its first to its last spar (T-junctions) and crosses the spars between (X-junctions).

**Fewer than two spars.** The ribs run from the leading to the trailing edge as closed
sections (full-chord ribs) when both edges are round or blunt (a blunt trailing edge's base at
least :data:`MIN_BASE` element sizes tall; a lower base is the wedge of the upper and lower skin at
that size: :func:`_edge_angles`). A quad at a wedge sharper than
:data:`MIN_EDGE_ANGLE` cannot reach the pipeline's scaled-Jacobian guarantee, so when an edge
is that sharp at some station the wing gets two **edge webs**, ``<wing>/le_web`` and
``<wing>/te_web``, where the wing is half its largest thickness (the most aft / most forward
such chord fraction over the span; at least an element size from the edge and the spar, else
midway between them), and the ribs run between them; ``StationWing.notes`` and
the report say so. The webs' place is the tool's choice, so it is one where a web is at least
:data:`EDGE_WEB_HEIGHT` element sizes tall from the root to the tip station (where the remesh keeps
the upper and lower skin apart): where that one is lower, the web moves to the nearest chord
fraction of its side of the box that is tall enough, else to the nearest at least
:data:`MIN_WEB_HEIGHT` sizes tall, else to the nearest at least :data:`MIN_WEB_HEIGHT` of the finest
local size (:data:`MIN_LOCAL_SIZE` element sizes) tall (:func:`_web_fractions`; a web lower than
:data:`MIN_WEB_HEIGHT` element sizes is meshed with smaller elements, as any spar: the project stage's
:func:`~shellmesh_mdao.project.thin_member_field`); where none is, the wing is too thin to carry a box
at that size and the error says so (its largest thickness there and the element size that would do).

**Checks before meshing** (:class:`~shellmesh_mdao.errors.LayoutError` naming the member and
the fix): a wing with members whose root and tip stations are closer than
:data:`~shellmesh_mdao.layout.schema.MIN_MEMBER_GAP` element sizes (too short for a box at that
size: its root and tip ribs would coincide), a spar or web less than :data:`MIN_WEB_HEIGHT` times
:data:`MIN_LOCAL_SIZE` element sizes tall somewhere (a web lower than :data:`MIN_WEB_HEIGHT` element
sizes is meshed with elements of twice its height, and the mesh refines no further than
:data:`MIN_LOCAL_SIZE` element sizes), neighbouring ribs (spars) that cross or coincide (closer than
:data:`~shellmesh_mdao.layout.schema.MIN_MEMBER_GAP` element sizes; one error names every such
pair of every wing; closer than an element size but no closer than that, they are meshed with
smaller elements between them), a member of one wing inside another wing's box (two halves whose
root ribs overlap at the symmetry plane).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import minimum_filter1d

from ..errors import LayoutError
from ..families import part_name, rib_name, spar_name, web_name
from .planform import Planform, measure_planform
from .schema import MIN_LOCAL_SIZE, MIN_MEMBER_GAP, Layout, MemberSpec, coincident_parts
from .stations import StationWing

__all__ = ["resolve_layout", "resolve_station_wing", "PlanformLine", "MIN_WEB_HEIGHT", "EDGE_WEB_HEIGHT", "MIN_EDGE_ANGLE",
           "MIN_BASE", "SPAR_TOL", "PLANFORM_TOL", "TURN_NOTE", "WEB_GAP"]

#: a spar or web must be at least this many local element sizes tall (the project stage's rule,
#: ``project.MIN_MEMBER_HEIGHT``; the layout stage cannot import it); lower than that at the element
#: size, the mesh refines around it, down to :data:`MIN_LOCAL_SIZE` element sizes
MIN_WEB_HEIGHT = 0.3
#: an edge web stands where the wing is at least this many element sizes tall wherever the wing has
#: room for that: the remesh cuts across a skin thinner than twice its chordal deviation (0.4 sizes
#: by default, as at a blunt edge's base: :data:`MIN_BASE`) with faces running from the upper to the
#: lower skin, and a web's curves imprinted into those faces leave slivers or break; where no place is
#: that tall, :data:`MIN_WEB_HEIGHT` is the limit
EDGE_WEB_HEIGHT = 0.4
#: an edge sharper than this cannot be the corner of a full-chord rib: a quad in a corner of
#: angle a has a scaled Jacobian of at most sin(a), and the pipeline guarantees above 0.2, so
#: 11.5 deg; half as much again for the measurement (one element size from the edge)
MIN_EDGE_ANGLE = 1.5 * float(np.degrees(np.arcsin(0.2)))
#: a blunt trailing edge is a face of the skin (full-chord ribs end on it) only where its base is
#: at least this many element sizes tall: the remesh keeps two feature lines apart only when they
#: are more than twice its chordal deviation apart (0.4 sizes by default) and merges them
#: otherwise, and then the rib's outline ends in the wedge of the upper and lower skin
MIN_BASE = 1.0
#: spars are straightened to this many element sizes of their local-fraction curve
SPAR_TOL = 0.25
#: the planform is measured to this many element sizes
PLANFORM_TOL = 0.1
#: rib turning step towards the station direction when two ribs come too close
_TURN = 0.85
#: an edge web moved to where the wing is tall enough keeps at least this many element sizes from the
#: spar and the edges when an element size leaves no room (the 0.2-size coincidence limit of
#: :data:`~shellmesh_mdao.layout.schema.MIN_MEMBER_GAP` and twice the straightening tolerance)
WEB_GAP = 0.7
#: ribs turned by more than this many degrees from the orientation asked for are noted
TURN_NOTE = 0.5


# ----------------------------------------------------------------------------- planform lines
class PlanformLine:
    """A polyline ``x(t)`` of the planform plane (stations ``t`` increasing), extended
    linearly beyond its ends."""

    def __init__(self, t, x):
        self.t = np.asarray(t, float)
        self.x = np.asarray(x, float)

    def __call__(self, t):
        t = np.asarray(t, float)
        x = np.interp(t, self.t, self.x)
        s0 = (self.x[1] - self.x[0]) / (self.t[1] - self.t[0])
        s1 = (self.x[-1] - self.x[-2]) / (self.t[-1] - self.t[-2])
        x = np.where(t < self.t[0], self.x[0] + s0 * (t - self.t[0]), x)
        return np.where(t > self.t[-1], self.x[-1] + s1 * (t - self.t[-1]), x)

    def slope(self, t) -> float:
        """dx/dt at ``t`` (the mean of both sides at a vertex)."""
        i = int(np.clip(np.searchsorted(self.t, t, side="right") - 1, 0, len(self.t) - 2))
        s = (self.x[i + 1] - self.x[i]) / (self.t[i + 1] - self.t[i])
        if i > 0 and abs(t - self.t[i]) <= 1e-12 * (self.t[-1] - self.t[0]):
            s = 0.5 * (s + (self.x[i] - self.x[i - 1]) / (self.t[i] - self.t[i - 1]))
        return float(s)

    def cross(self, tk, xk, T) -> float:
        """Station where the line ``t = tk + (x - xk) T`` of the planform plane crosses this
        polyline (the crossing nearest ``tk``; NaN when parallel everywhere)."""
        t, x = self.t, self.x
        best = np.nan
        n = len(t)
        for i in range(n - 1):                             # loop over segments (tens)
            s = (x[i + 1] - x[i]) / (t[i + 1] - t[i])
            den = 1.0 - s * T
            if abs(den) < 1e-12:
                continue
            tc = (tk + (x[i] - s * t[i] - xk) * T) / den
            lo = -np.inf if i == 0 else t[i]
            hi = np.inf if i == n - 2 else t[i + 1]
            if lo - 1e-12 <= tc <= hi + 1e-12 and (np.isnan(best) or abs(tc - tk) < abs(best - tk)):
                best = tc
        return float(best)


def _simplify(t, x, tol, keep, allowed=None, min_gap: float = 0.0) -> list:
    """Douglas-Peucker vertices (indices) of the planform curve ``(t, x)``: the indices ``keep``
    always; in each interval the ``allowed`` sample farthest from the interval's chord, when
    farther than ``tol`` and at least ``min_gap`` (in ``t``) from both ends, is added."""
    n = len(t)
    allowed = np.ones(n, bool) if allowed is None else np.asarray(allowed, bool)
    keep = sorted(set(int(k) for k in keep) | {0, n - 1})
    out = set(keep)
    stack = [(keep[i], keep[i + 1]) for i in range(len(keep) - 1)]
    while stack:
        i0, i1 = stack.pop()
        if i1 - i0 < 2:
            continue
        idx = np.arange(i0 + 1, i1)
        ok = allowed[idx] & (t[idx] - t[i0] >= min_gap) & (t[i1] - t[idx] >= min_gap)
        d = np.abs(x[idx] - (x[i0] + (x[i1] - x[i0]) * (t[idx] - t[i0]) / (t[i1] - t[i0])))
        d = np.where(ok, d, -1.0)
        k = int(np.argmax(d))
        if d[k] > tol:
            out.add(int(idx[k]))
            stack += [(i0, int(idx[k])), (int(idx[k]), i1)]
    return sorted(out)


# ----------------------------------------------------------------------------- the wing box
class _Box:
    """The planform-plane layout of one station-given wing while it is resolved."""

    def __init__(self, w: StationWing, pf: Planform, size: float):
        self.w, self.pf, self.size = w, pf, size
        st = pf.stations
        self.t0, self.t1 = pf.root, pf.tip
        self.le = PlanformLine(st, pf.x_of(pf.le))
        self.te = PlanformLine(st, pf.x_of(pf.te))
        # dense stations for the spar curves: the measured ones and their midpoints
        self.ts = np.unique(np.concatenate([st, 0.5 * (st[1:] + st[:-1])]))
        self.cranks = [float(c) for c in pf.cranks]

    def eta(self, t):
        return self.pf.eta(t)

    def frac_curve(self, cfun):
        """The planform curve of chord fraction ``cfun(eta)`` at the dense stations."""
        c = cfun(self.eta(self.ts))
        return self.le(self.ts) + c * (self.te(self.ts) - self.le(self.ts))

    def point(self, t, x) -> np.ndarray:
        """3D mean point (inside the wing) of planform point ``(t, x)``."""
        pf = self.pf
        c = pf.chord_fraction_at(t, x)
        return pf.mean_point(t, c)

    def straight(self, xs, junctions=()) -> PlanformLine:
        """A spar curve (values at the dense stations) straightened within SPAR_TOL sizes: its
        pieces at least two element sizes long, its kinks at least one size from the
        ``junctions`` (stations where ribs meet it), or midway between two junctions closer than
        two sizes; a crank station is a kink, or the nearest station allowed."""
        ts, m = self.ts, self.size
        J = np.asarray([j for j in junctions if np.isfinite(j)], float)
        allowed = np.ones(len(ts), bool)
        if len(J):
            allowed = np.abs(ts[:, None] - J[None, :]).min(axis=1) >= m
        allowed &= (ts - ts[0] >= 2 * m) & (ts[-1] - ts >= 2 * m)
        xs = np.asarray(xs, float)
        if len(J) >= 2:
            # ribs closer than two sizes leave no station a size from both: the line may kink midway
            # between two that are at least a size apart (else it runs straight past a planform
            # that bends there, out of the wing)
            Js = np.unique(J)
            mid = 0.5 * (Js[:-1] + Js[1:])
            # no allowed station strictly between two neighbouring junctions (ts ascending)
            cs = np.concatenate([[0], np.cumsum(allowed)])
            free = cs[np.searchsorted(ts, Js[1:], "left")] == cs[np.searchsorted(ts, Js[:-1], "right")]
            mid = mid[free & (np.diff(Js) >= m) & (mid - ts[0] >= 2 * m) & (ts[-1] - mid >= 2 * m)]
            mid = mid[~np.isin(mid, ts)]
            if len(mid):
                x_mid = np.interp(mid, ts, xs)
                ts, xs = np.concatenate([ts, mid]), np.concatenate([xs, x_mid])
                allowed = np.concatenate([allowed, np.ones(len(mid), bool)])
                o = np.argsort(ts, kind="stable")
                ts, xs, allowed = ts[o], xs[o], allowed[o]
        keep, at = [], []
        for c in self.cranks:
            ok = np.flatnonzero(allowed)
            k = int(ok[np.argmin(np.abs(ts[ok] - c))]) if len(ok) else -1
            if k >= 0 and abs(ts[k] - c) <= 2 * m:
                keep.append(k)
            elif len(J):
                # ribs within a size of every station near the crank: the kink goes to the crank, or
                # as near it as half a size from the nearest rib on each side allows (midway between
                # them when they are closer than a size); a kink on a rib would leave the rib and the
                # next piece meeting the spar at one point
                lo, hi = J[J <= c], J[J > c]
                lo = float(lo.max()) if len(lo) else -np.inf
                hi = float(hi.min()) if len(hi) else np.inf
                g = min(0.5 * m, 0.5 * (hi - lo))
                tc = float(np.clip(c, lo + g, hi - g))
                if ts[0] + 2 * m <= tc <= ts[-1] - 2 * m:
                    at.append(tc)
        if at:
            at = np.unique(at)
            xs = np.concatenate([xs, np.interp(at, ts, xs)])
            ts = np.concatenate([ts, at])
            allowed = np.concatenate([allowed, np.zeros(len(at), bool)])
            o = np.argsort(ts, kind="stable")
            ts, xs, allowed = ts[o], xs[o], allowed[o]
            keep = [int(np.flatnonzero(o == i)[0]) for i in keep] + \
                   [int(i) for i in np.flatnonzero(o >= len(o) - len(at))]
        idx = _simplify(ts, xs, SPAR_TOL * m, keep, allowed, 2 * m)
        return PlanformLine(ts[idx], xs[idx])


def _rib_tan(orientation, box: _Box, ref: PlanformLine | None, tk: float) -> float:
    """``tan(phi)`` of a rib at station ``tk``: its planform direction is ``(tan(phi), 1)`` in
    ``(t, x)`` (0: along the station)."""
    pf = box.pf
    if isinstance(orientation, str):
        if orientation == "streamwise":
            return 0.0
        if orientation == "normal_to_spar" and ref is not None:
            return -ref.slope(tk)
        # normal to the mid-chord line (also normal_to_spar without spars)
        xm0 = 0.5 * (box.le(box.t0) + box.te(box.t0))
        xm1 = 0.5 * (box.le(box.t1) + box.te(box.t1))
        return -float((xm1 - xm0) / (box.t1 - box.t0))
    v = np.asarray(orientation, float)
    nt, nx = float(v @ pf.axis), float(v @ pf.e) * pf.aft
    if abs(nt) <= 1e-9 * np.linalg.norm(v):
        raise LayoutError(f"wing '{box.w.name}': ribs.orientation {v.tolist()} lies along the chord: the rib planes "
                          "would run along the span; give the rib planes' normal (roughly the span direction)")
    return -nx / nt


def _rib_ends(box, bounds, tk, xk, T):
    """Stations where the rib line meets its front and rear bound."""
    return np.array([bounds[0].cross(tk, xk, T), bounds[-1].cross(tk, xk, T)])


def _anchor(box: _Box, bounds, c_mid, tk, T, side) -> tuple:
    """Station and chordwise anchor of a rib of ``tan(phi) = T`` through the middle of its box
    that touches the root station (``side`` +1) at its inboard end or the tip station (-1) at its
    outboard end (``end_ribs: same``), from the first guess ``tk``."""
    tol = 1e-12 * (box.t1 - box.t0)
    for _ in range(50):
        xk = float(bounds[0](tk) + c_mid * (bounds[-1](tk) - bounds[0](tk)))
        ends = _rib_ends(box, bounds, tk, xk, T)
        if not np.isfinite(ends).all():
            break
        shift = (box.t0 - ends.min()) if side > 0 else (box.t1 - ends.max())
        tk += shift
        if abs(shift) <= tol:
            break
    return tk, float(bounds[0](tk) + c_mid * (bounds[-1](tk) - bounds[0](tk)))


def _layout_ribs(box: _Box, bounds, c_mid, ref, T0=None):
    """Rib stations, anchors and ``tan(phi)`` after the fan relaxation (module docstring);
    ``T0``: turn no rib further towards its orientation than these ``tan(phi)``. With
    ``end_ribs: same`` the root and tip ribs turn too (each still touching its station)."""
    w = box.w
    eta = np.asarray(w.rib_eta, float)
    tk = box.pf.station(eta)
    xk = np.array([float(bounds[0](t) + c_mid * (bounds[-1](t) - bounds[0](t))) for t in tk])
    n = len(tk)
    T = np.array([_rib_tan(w.rib_orientation, box, ref, t) for t in tk])
    if T0 is not None:
        T = np.where(np.abs(T0) < np.abs(T), T0, T)
    fixed = np.zeros(n, bool)
    same = w.end_ribs != "station"
    sides = {0: 1.0, n - 1: -1.0} if n >= 2 else {}

    def anchor(k):
        tk[k], xk[k] = _anchor(box, bounds, c_mid, tk[k], T[k], sides[k])

    if not same:
        T[0] = T[-1] = 0.0
        fixed[0] = fixed[-1] = True
    elif n == 1:                                          # a lone rib touches the tip station
        tk[0], xk[0] = _anchor(box, bounds, c_mid, tk[0], T[0], -1.0)
        fixed[0] = True
    else:
        for k in sides:
            anchor(k)
    if n < 2:
        return tk, xk, T
    gap = np.diff(box.pf.station(eta))
    # half their stations' spacing and an element size apart; ribs whose stations are closer than
    # that (meshed with smaller elements between them) at least their stations' spacing
    margin = np.maximum(0.5 * gap, np.minimum(gap, box.size))
    for _ in range(400):                                  # turn ribs that come too close
        ends = np.stack([_rib_ends(box, bounds, tk[k], xk[k], T[k]) for k in range(n)])
        ok = np.isfinite(ends).all(1)
        clear = np.min(np.diff(ends, axis=0), axis=1)
        clear = np.where(ok[1:] & ok[:-1], clear, -np.inf)
        bad = np.flatnonzero(clear < margin)
        if not len(bad):
            break
        for k in bad:
            for r in (k, k + 1):
                if not fixed[r]:
                    T[r] *= _TURN
                    if abs(T[r]) < 1e-6:
                        T[r] = 0.0
        for r in sides:
            if not fixed[r] and (r in bad or r - 1 in bad):
                anchor(r)
    else:
        T[~fixed] = 0.0
        for k in sides:
            if not fixed[k]:
                anchor(k)
    return tk, xk, T


def _turn_note(w: StationWing, box: _Box, ref, tk, T) -> str | None:
    """The note of the ribs the relaxation turned from the orientation asked for (by more than
    :data:`TURN_NOTE` degrees), or None."""
    n = len(tk)
    asked = np.array([_rib_tan(w.rib_orientation, box, ref, t) for t in tk])
    turn = np.degrees(np.arctan(np.abs(asked)) - np.arctan(np.abs(T)))
    if w.end_ribs == "station" and n:
        turn[0] = turn[-1] = 0.0
    k = np.flatnonzero(turn > TURN_NOTE)
    if not len(k):
        return None
    o = w.rib_orientation if isinstance(w.rib_orientation, str) else "the orientation given"
    names = [f"'{rib_name(w.name, int(i))}'" for i in k]
    names = ", ".join(names) if len(names) <= 6 else f"{', '.join(names[:3])}, ... {', '.join(names[-2:])} " \
        f"({len(names)} ribs)"
    ends = " (end_ribs: same: the root and tip ribs still touch their stations)" if \
        w.end_ribs != "station" and (turn[0] > TURN_NOTE or turn[-1] > TURN_NOTE) else ""
    return (f"wing '{w.name}': {'rib' if len(k) == 1 else 'ribs'} {names} turned from {o} towards the station "
            f"direction by up to {turn[k].max():.1f} deg to stay at least half their stations' spacing and an "
            f"element size apart{ends}")


def _edge_angles(pf: Planform, size: float) -> tuple:
    """Smallest leading- and trailing-edge wedge angles (degrees) over the measured stations,
    each measured one element size from the edge. A blunt trailing edge whose base is at least
    :data:`MIN_BASE` element sizes tall counts 180; a lower base is below what the skin resolves
    at that size (the remesh merges its two corner lines into one), so there the edge is the
    wedge of the upper and lower skin, measured from the base's corners."""
    le_min, te_min = 180.0, 180.0
    for s in pf.shapes:
        f = min(max(size / s.chord, 1e-4), 0.25)
        hu, hl = pf.heights(s.station, np.array([f, 1.0 - f]))
        d = f * s.chord
        le_ang = np.degrees(np.arctan2(hu[0], d) - np.arctan2(hl[0], d))
        le_min = min(le_min, float(le_ang))
        if not s.blunt or s.upper[-1] - s.lower[-1] < MIN_BASE * size:
            te_ang = np.degrees(np.arctan2(hu[1] - s.upper[-1], d) - np.arctan2(hl[1] - s.lower[-1], d))
            te_min = min(te_min, float(te_ang))
    return le_min, te_min


def _web_fractions(pf: Planform, spars, size: float, name: str, edge: str) -> tuple:
    """Chord fractions of the leading- and trailing-edge webs (``edge``: the sharp edge, for the
    message). Preferred: where the wing is half its largest thickness, the most aft (front web)
    and most forward (rear web) over the span, at least an element size from the edges (at the
    smallest chord) and from the spar; midway between the edge and the spar where there is no
    room for that. A web must be :data:`EDGE_WEB_HEIGHT` element sizes tall over the whole span
    (strictly between the root and tip stations, as :func:`_spar_height` checks it), with
    :data:`SPAR_TOL` sizes to spare for its straightening: where the preferred fraction is lower
    than that, the web moves to the nearest fraction of its side of the box that is tall enough
    (an element size from the spar and the edges, else :data:`WEB_GAP` sizes), else to the
    nearest at least :data:`MIN_WEB_HEIGHT` sizes tall (the same way), else to the nearest at
    least :data:`MIN_WEB_HEIGHT` times :data:`MIN_LOCAL_SIZE` sizes tall (a web lower than
    :data:`MIN_WEB_HEIGHT` sizes is meshed with smaller elements:
    :func:`~shellmesh_mdao.project.thin_member_field`). Where none is,
    the wing cannot carry a box at this size: a LayoutError names the wing, its thickness and the
    element size that would do."""
    c = np.linspace(0.0, 1.0, 401)
    lo, hi = 0.0, 1.0
    for s in pf.shapes:
        th = pf.thickness(s.station, c)
        over = np.flatnonzero(th >= 0.5 * th.max())
        lo, hi = max(lo, float(c[over[0]])), min(hi, float(c[over[-1]]))
    cmin = float(np.min(pf.chord(pf.stations)))
    g = size / cmin
    lo, hi = max(lo, g), min(hi, 1.0 - g)
    if spars and lo > min(spars) - g:             # no room: midway between the edge and the spar
        lo = 0.5 * min(spars)
    if spars and hi < max(spars) + g:
        hi = 0.5 * (1.0 + max(spars))
    if not (0.0 < lo < hi < 1.0):
        raise LayoutError(f"wing '{name}': with fewer than two spars and a sharp edge the ribs end on edge webs, but "
                          f"there is no room for them (chord fractions {lo:.3g} and {hi:.3g}): give two spars or "
                          "use a smaller element size")
    # the web's height over the span at every fraction (the lowest station), less the straightening
    st = pf.stations
    ts = np.unique(np.concatenate([np.linspace(st[0], st[-1], 43)[1:-1], st[1:-1]]))
    th = np.stack([pf.thickness(t, c) for t in ts])
    H, tmin = th.min(axis=0), ts[np.argmin(th, axis=0)]

    def room(a, b, hh, pref):
        """The fraction nearest ``pref`` between ``a`` and ``b`` (0 the leading edge, 1 the
        trailing edge, else a spar or web) where a web is tall enough at element size ``hh``
        (:data:`EDGE_WEB_HEIGHT` sizes, else :data:`MIN_WEB_HEIGHT`, else :data:`MIN_WEB_HEIGHT`
        local sizes of the finest the mesh refines to, :data:`MIN_LOCAL_SIZE`): an element size from both
        ends, else :data:`WEB_GAP` sizes from a member; None."""
        for need in (EDGE_WEB_HEIGHT, MIN_WEB_HEIGHT, MIN_WEB_HEIGHT * MIN_LOCAL_SIZE):
            got = room_of(a, b, hh, pref, need)
            if got is not None:
                return got
        return None

    def room_of(a, b, hh, pref, need):
        """:func:`room` for webs at least ``need`` element sizes tall."""
        d = int(np.ceil(SPAR_TOL * hh / cmin / (c[1] - c[0])))
        tall = minimum_filter1d(H, 2 * d + 1, mode="nearest") >= need * hh
        if pref is not None and a < pref < b and tall[int(np.argmin(np.abs(c - pref)))]:
            return pref
        for gap in (hh / cmin, WEB_GAP * hh / cmin):
            ga = gap if a > 0.0 else hh / cmin
            gb = gap if b < 1.0 else hh / cmin
            ok = np.flatnonzero(tall & (c >= a + ga) & (c <= b - gb))
            if len(ok):
                return float(c[ok[np.argmin(np.abs(c[ok] - (pref if pref is not None else 0.5 * (a + b))))]])
        return None

    def sides(hh, lo_pref, hi_pref):
        """The front and rear webs' fractions at element size ``hh`` (None where there is no
        room), and the failing side's bounds."""
        a, b = 0.0, (min(spars) if spars else 1.0)
        lo_ = room(a, b, hh, lo_pref)
        if lo_ is None:
            return None, None, (a, b, "le")
        a, b = (max(spars) if spars else lo_), 1.0
        hi_ = room(a, b, hh, hi_pref)
        return lo_, hi_, (a, b, "te")

    got_lo, got_hi, (a, b, side) = sides(size, lo, hi)
    if got_lo is not None and got_hi is not None:
        return got_lo, got_hi
    # no room at this size: the wing is too thin there; the largest element size with room for both
    fit = next((hh for hh in size * 0.98 ** np.arange(1, 400) if None not in sides(hh, None, None)[:2]), None)
    inside = (c > a) & (c < b)
    k = int(np.flatnonzero(inside)[np.argmax(H[inside])])
    if side == "le":
        where = "between its leading edge and " + (f"its spar at {b:.3g} of the chord" if spars else
                                                   "its trailing edge")
    else:
        where = f"between its {'spar' if spars else 'leading-edge web'} at {a:.3g} of the chord and its trailing edge"
    lowest = MIN_WEB_HEIGHT * MIN_LOCAL_SIZE              # in element sizes: a web of the finest local size
    need = lowest * size
    if H[k] < need:
        thick = (f"nowhere at least {lowest:g} element sizes ({need:.4g}) thick from its root to its tip "
                 f"station: at most {H[k]:.4g} ({H[k] / size:.3f} element sizes, at {c[k]:.3g} of the chord, near "
                 f"station {abs(tmin[k]):.6g})")
    else:
        thick = (f"at least {lowest:g} element sizes ({need:.4g}) thick from its root to its tip station "
                 f"only closer than {WEB_GAP:g} element sizes to its {'spar' if spars else 'leading-edge web'}")
    fix = f"use an element size of at most {fit:.4g}, " if fit is not None else ""
    raise LayoutError(
        f"wing '{name}': with fewer than two spars and a sharp {edge} edge the ribs end on edge webs, but {where} "
        f"the wing is {thick}: it is too thin to carry a box at element size {size:g}; {fix}move the tip (or root) "
        "station to where the wing is thicker, give it two spars, or leave the wing out of the layout")


def _spar_height(box: _Box, line: PlanformLine, t0, t1, n=41):
    """Smallest wing thickness along a spar line strictly between stations t0 and t1 (at its
    ends a spar meets the end ribs, which may cut a rounded tip cap: the project stage's rule
    too), and where."""
    t = np.linspace(t0, t1, n + 2)[1:-1]
    x = line(t)
    c = box.pf.chord_fraction_at(t, x)
    th = box.pf.thickness(t, c)
    k = int(np.argmin(th))
    return float(th[k]), t[k], float(c[k])


def resolve_station_wing(w: StationWing, points, tris, size: float | None, up=None) -> StationWing:
    """Measure a station-given wing from the skin ``(points, tris)`` and lay out its members
    (module docstring) for element size ``size`` (None: a fiftieth of the span); ``up`` the
    layout's default up. Returns the resolved wing (``planform``, ``specs``, ``notes``)."""
    span = abs(w.tip - w.root)
    h = float(size) if size is not None else span / 50.0
    if span < MIN_MEMBER_GAP * h and (len(w.rib_eta) >= 2 or w.spar_chord):
        raise LayoutError(
            f"wing '{w.name}' is only {span:.4g} long between its root and tip stations ({span / h:.3f} element "
            f"sizes, at least {MIN_MEMBER_GAP:g} needed): its root and tip ribs (the ends of its spars) coincide at "
            f"element size {h:g}, the surface is too short for a wing box at that size; move its root and tip "
            f"stations apart, leave the wing out of the layout, or use an element size below "
            f"{span / MIN_MEMBER_GAP:.4g}")
    pf = measure_planform(points, tris, w.axis, w.root, w.tip, w.cranks, up=w.up if w.up is not None else up,
                          near=w.near, aft=w.aft, tol=PLANFORM_TOL * h, name=w.name)
    box = _Box(w, pf, h)
    notes = []
    spars = list(w.spar_chord)
    # ---------------------------------------------------------------- spar-like members
    lines = []                                   # (name, index, dense curve, PlanformLine)
    for j in range(len(spars)):
        xs = box.frac_curve(lambda e, j=j: w.spar_fractions(e)[..., j])
        lines.append((spar_name(w.name, j), j, xs, box.straight(xs)))
    loop_ribs = False
    if len(spars) < 2:
        le_ang, te_ang = _edge_angles(pf, h)
        if min(le_ang, te_ang) < MIN_EDGE_ANGLE:
            clo, chi = _web_fractions(pf, spars, h, w.name, "leading" if le_ang < te_ang else "trailing")
            webs = []
            for nm, c in ((web_name(w.name, "le"), clo), (web_name(w.name, "te"), chi)):
                xs = box.frac_curve(lambda e, c=c: np.full_like(np.asarray(e, float), c))
                webs.append((nm, len(spars), xs, box.straight(xs), c))
            edge = "leading" if le_ang < te_ang else "trailing"
            notes.append(f"wing '{w.name}': its {edge} edge is sharper than {MIN_EDGE_ANGLE:.1f} deg "
                         f"({min(le_ang, te_ang):.1f} deg): with fewer than two spars the ribs end on two edge webs, "
                         f"'{web_name(w.name, 'le')}' at {clo:.3g} and '{web_name(w.name, 'te')}' at {chi:.3g} of the chord")
            lines = [webs[0][:4]] + lines + [webs[1][:4]]
        else:
            loop_ribs = True
    # ---------------------------------------------------------------- ribs
    if loop_ribs:
        bounds, c_mid = [box.le, box.te], 0.5
    else:
        bounds = [lines[0][3], lines[-1][3]]
        c_mid = 0.5
    ref = None
    if spars:
        rs = w.rib_spar if w.rib_spar is not None else len(spars) - 1
        ref = next(ln for nm, j, xs, ln in lines if nm == spar_name(w.name, rs))
    T0 = None
    for _ in range(3):                  # ribs on the spar lines, kinks away from the ribs, and again
        tk, xk, T = _layout_ribs(box, bounds, c_mid, ref, T0)
        lines = [(nm, j, xs, box.straight(xs, [ln.cross(tk[k], xk[k], T[k]) for k in range(len(tk))]))
                 for nm, j, xs, ln in lines]
        T0 = T
        if not loop_ribs:
            bounds = [lines[0][3], lines[-1][3]]
        if spars:
            ref = next(ln for nm, j, xs, ln in lines if nm == spar_name(w.name, rs))
    tk, xk, T = _layout_ribs(box, bounds, c_mid, ref, T0)
    note = _turn_note(w, box, ref, tk, T)
    if note:
        notes.append(note)
    # ---------------------------------------------------------------- checks
    close = _close_pairs(w, box, bounds, lines, tk, xk, T, h)
    for nm, j, xs, ln in lines:
        th, tmin, cmin = _spar_height(box, ln, box.t0, box.t1)
        if th < MIN_WEB_HEIGHT * MIN_LOCAL_SIZE * h:
            p = box.point(tmin, float(ln(tmin)))
            edge = "trailing" if cmin > 0.5 else "leading"
            webs = (web_name(w.name, "le"), web_name(w.name, "te"))       # the webs' place is the tool's
            what = "" if nm in webs else "the spar away from the {edge} edge, "
            raise LayoutError(
                f"spar '{nm}' (chord fraction {cmin:.3g} at station {abs(tmin):.6g}) is only {th:.4g} tall near "
                f"[{', '.join(f'{v:.6g}' for v in p)}], {th / h:.3f} element sizes: a web of quads needs "
                f"elements of at most {th / MIN_WEB_HEIGHT:.4g} there (its height at least {MIN_WEB_HEIGHT:g} of them), "
                f"below the smallest local size the mesh refines to ({MIN_LOCAL_SIZE:g} element sizes, "
                f"{MIN_LOCAL_SIZE * h:.4g}); move {what.format(edge=edge)}the tip (or root) station to where the wing "
                f"is thicker, or use an element size below {th / MIN_WEB_HEIGHT / MIN_LOCAL_SIZE:.4g}")
    # ---------------------------------------------------------------- members
    specs = _members(w, box, lines, loop_ribs, bounds, tk, xk, T)
    return replace(w, planform=pf, specs=tuple(specs), notes=tuple(notes), close_pairs=tuple(close))


def _close_pairs(w: StationWing, box: _Box, bounds, lines, tk, xk, T, h: float) -> list:
    """Neighbouring ribs that cross or come closer than :data:`MIN_MEMBER_GAP` element sizes at a
    spar (or edge), and neighbouring spar-like lines that cross or come that close:
    ``[(text, gap)]`` (``gap`` None where they cross)."""
    out = []
    n = len(tk)
    if n >= 2:
        ends = np.stack([_rib_ends(box, bounds, tk[k], xk[k], T[k]) for k in range(n)])
        pts_f = np.stack([ends[:, 0], bounds[0](ends[:, 0])], 1)
        pts_r = np.stack([ends[:, 1], bounds[-1](ends[:, 1])], 1)
        dist = np.minimum(np.linalg.norm(np.diff(pts_f, axis=0), axis=1),
                          np.linalg.norm(np.diff(pts_r, axis=0), axis=1))
        dt = np.minimum(np.diff(ends[:, 0]), np.diff(ends[:, 1]))
        for k in np.flatnonzero((dt <= 0) | (dist < MIN_MEMBER_GAP * h)):
            a, b = rib_name(w.name, k), rib_name(w.name, k + 1)
            out.append((f"ribs '{a}' and '{b}' cross each other", None) if dt[k] <= 0 else
                       (f"ribs '{a}' and '{b}' are {dist[k]:.4g} apart at a spar", float(dist[k])))
    ts = box.ts
    for (na, _, _, la), (nb, _, _, lb) in zip(lines[:-1], lines[1:]):
        gap = lb(ts) - la(ts)
        k = int(np.argmin(gap))
        if gap[k] <= 0:
            out.append((f"spars '{na}' and '{nb}' cross each other near station {ts[k]:.6g}", None))
        elif gap[k] < MIN_MEMBER_GAP * h:
            out.append((f"spars '{na}' and '{nb}' are {gap[k]:.4g} apart near station {ts[k]:.6g}", float(gap[k])))
    return out


def _seeds(box: _Box, ta, xa, tb, xb, n=17) -> np.ndarray:
    """Mean points (inside the wing) along the planform segment (ta, xa) -> (tb, xb)."""
    s = np.linspace(0.0, 1.0, n)
    t, x = ta + s * (tb - ta), xa + s * (xb - xa)
    c = box.pf.chord_fraction_at(t, x)
    return box.pf.mean_point(t, c)


def _plane_normal(p0, p1, up, toward) -> np.ndarray:
    """Unit normal of the plane through the segment p0 -> p1 containing ``up``, towards
    ``toward``."""
    d = np.asarray(p1, float) - np.asarray(p0, float)
    n = np.cross(d - (d @ up) * up, up)
    n = n / np.linalg.norm(n)
    return n if n @ toward >= 0 else -n


def _members(w: StationWing, box: _Box, lines, loop_ribs, bounds, tk, xk, T) -> list:
    """The :class:`MemberSpec` s of a laid-out station wing: spar-like pieces (planar, bounded
    by the end ribs and by the bisector planes of their kinks), then the ribs (planar, bounded
    by the planes of the spar pieces they end on; a full-chord rib is unbounded)."""
    pf, u = box.pf, box.pf.up
    aft = pf.aft * pf.e
    n = len(tk)
    # the ribs' planform ends and planes first: the spars end on the end ribs
    rib = []
    for k in range(n):
        ta, tb = _rib_ends(box, bounds, tk[k], xk[k], T[k])
        xa, xb = float(bounds[0](ta)), float(bounds[-1](tb))
        seeds = _seeds(box, ta, xa, tb, xb)
        if loop_ribs:                              # the ends on the skin's edges
            seeds[0], seeds[-1] = pf.le_at(ta), pf.te_at(tb)
        nrm = _plane_normal(seeds[0], seeds[-1], u, pf.axis)
        rib.append((ta, xa, tb, xb, seeds, nrm))
    specs, piece_planes = [], []
    for li, (nm, j, xs, ln) in enumerate(lines):
        idx = j if nm == spar_name(w.name, j) else (-1 if nm == web_name(w.name, "le") else len(w.spar_chord))
        kt, kx = list(ln.t), list(ln.x)
        npc = len(kt) - 1
        planes = []
        for p in range(npc):
            seeds = _seeds(box, kt[p], kx[p], kt[p + 1], kx[p + 1])
            planes.append((seeds, _plane_normal(seeds[0], seeds[-1], u, aft)))
        piece_planes.append((kt, planes))
        for p in range(npc):
            seeds, nrm = planes[p]
            bp, bnames = [], []
            for end in (0, 1):
                q = p + end
                if (end == 0 and p == 0) or (end == 1 and p == npc - 1):
                    if n:                          # the end rib's plane
                        r = rib[0] if end == 0 else rib[-1]
                        rn = r[5] if end == 0 else -r[5]
                        bp.append((r[4][len(r[4]) // 2].copy(), rn.copy()))
                        bnames.append(rib_name(w.name, 0 if end == 0 else n - 1))
                    else:                          # the station plane
                        bp.append((seeds[0 if end == 0 else -1].copy(), pf.axis.copy() if end == 0 else -pf.axis))
                        bnames.append("root" if end == 0 else "tip")
                    continue
                # the kink's bisector plane (through the kink line), facing this piece
                da = np.asarray(planes[q - 1][0][-1] - planes[q - 1][0][0])
                db = np.asarray(planes[q][0][-1] - planes[q][0][0])
                bis = da / np.linalg.norm(da) + db / np.linalg.norm(db)
                bis = bis - (bis @ u) * u
                bis = bis / np.linalg.norm(bis)
                kp = planes[q][0][0] if end == 1 else seeds[0]
                bp.append((kp.copy(), bis.copy() if end == 0 else -bis))
                bnames.append(part_name(nm, q - 1 if end == 0 else q))
            name = nm if npc == 1 else part_name(nm, p)
            c_mid = float(pf.chord_fraction_at(0.5 * (kt[p] + kt[p + 1]), 0.5 * (kx[p] + kx[p + 1])))
            specs.append(MemberSpec(name=name, kind="spar", wing=w.name, index=idx, parameter=c_mid,
                                    plane_point=seeds[len(seeds) // 2].copy(), plane_normal=nrm, up=u.copy(),
                                    start=seeds[0].copy(), end=seeds[-1].copy(), root_point=seeds[0].copy(),
                                    tip_point=seeds[-1].copy(), bounds=tuple(bnames), bound_planes=tuple(bp),
                                    eta_range=(float(pf.eta(kt[p])), float(pf.eta(kt[p + 1]))), seeds=seeds))
    for k in range(n):
        ta, xa, tb, xb, seeds, nrm = rib[k]
        if loop_ribs:
            specs.append(MemberSpec(name=rib_name(w.name, k), kind="rib", wing=w.name, index=k,
                                    parameter=float(w.rib_eta[k]), plane_point=seeds[len(seeds) // 2].copy(),
                                    plane_normal=nrm, up=u.copy(), start=seeds[0].copy(), end=seeds[-1].copy(),
                                    bounds=("LE", "TE"), chord_range=(0.0, 1.0), seeds=seeds))
            continue
        bp, bnames = [], []
        for li, tt, sgn in ((0, ta, 1.0), (len(lines) - 1, tb, -1.0)):
            kt, planes = piece_planes[li]
            p = int(np.clip(np.searchsorted(kt, tt, side="right") - 1, 0, len(planes) - 1))
            sd, sn = planes[p]
            bp.append((sd[len(sd) // 2].copy(), sgn * sn))
            nm = lines[li][0]
            bnames.append(nm if len(planes) == 1 else part_name(nm, p))
        ca = float(pf.chord_fraction_at(ta, xa))
        cb = float(pf.chord_fraction_at(tb, xb))
        specs.append(MemberSpec(name=rib_name(w.name, k), kind="rib", wing=w.name, index=k,
                                parameter=float(w.rib_eta[k]), plane_point=seeds[len(seeds) // 2].copy(),
                                plane_normal=nrm, up=u.copy(), start=seeds[0].copy(), end=seeds[-1].copy(),
                                bounds=tuple(bnames), bound_planes=tuple(bp), chord_range=(ca, cb), seeds=seeds))
    return specs


def _check_overlaps(wings) -> None:
    """A member of one station-given wing inside another's box is a LayoutError naming both."""
    for a in wings:
        pa = np.vstack([m.seeds for m in a.specs])
        for b in wings:
            if b is a:
                continue
            pf = b.planform
            t = pa @ pf.axis
            inside = (t > pf.root) & (t < pf.tip)
            if not inside.any():
                continue
            q = pa[inside]
            tq = t[inside]
            c = pf.chord_fraction_at(tq, pf.x_of(q))
            hu, hl = pf.heights(tq, c)
            base = (pf.chord_point(tq, c) @ pf.up)
            v = q @ pf.up - base
            hit = (c > 0) & (c < 1) & (v < hu) & (v > hl)
            if hit.any():
                p = q[int(np.argmax(hit))]
                raise LayoutError(f"wing '{a.name}' reaches into wing '{b.name}' near "
                                  f"[{', '.join(f'{x:.6g}' for x in p)}]: their station ranges overlap; move the "
                                  f"root station of one of them (two halves meeting at a symmetry plane: root "
                                  "stations on either side of it)")


def resolve_layout(layout, points, tris, size: float | None = None) -> Layout:
    """The layout with its station-given wings measured from the skin ``(points, tris)`` and
    laid out for element size ``size``; a layout without any is returned as it is (the same
    object). Raises :class:`~shellmesh_mdao.errors.LayoutError` naming the wing or member."""
    if not isinstance(layout, Layout) or not layout.station_wings:
        return layout
    if all(w.resolved for w in layout.station_wings):
        return layout
    P = np.asarray(points, float)
    T = np.asarray(tris, np.int64)
    wings = tuple(w if w.resolved else resolve_station_wing(w, P, T, size, layout.up) for w in layout.station_wings)
    out = replace(layout, station_wings=wings)
    # every pair that coincides or crosses, over all wings, in one error
    pairs = [p for w in wings for p in w.close_pairs]
    if pairs:
        pairs = out.coincident_pairs(size) if size is not None else pairs
        h = float(size) if size is not None else None
        txt, fix = coincident_parts(pairs)
        at = f"{h:g}" if h is not None else "a fiftieth of each wing's span"
        lim = f"{MIN_MEMBER_GAP * h:.4g}" if h is not None else "a fifth of that"
        raise LayoutError(f"members coincide or cross at element size {at} (closer than {MIN_MEMBER_GAP:g} element "
                          f"sizes, {lim}): {txt}: {fix}")
    _check_overlaps(wings)
    return out