"""Lifting surfaces found in a skin, and a starting layout for them (``shellmesh wings``).

:func:`find_wings` slices the skin along a span axis and follows its thin, elongated
sections from station to station:

1. **Stations.** :data:`FIND_STATIONS` planes normal to the axis, evenly spaced across the
   skin's extent along it (the two extreme planes a hundredth of the extent inside).
2. **Wing-like sections.** At each station the section loops
   (:func:`~shellmesh_mdao.layout.sections.section_loops`) at most
   :data:`~shellmesh_mdao.layout.planform.WING_LIKE` as thick as they are long (a fuselage or a
   fin cut across is not).
3. **Tracks.** A wing-like loop continues the track of the previous station whose last loop's
   centre is within half a chord of its own centre and whose chord differs from its own by at
   most a factor :data:`CHORD_JUMP` (the nearest such track); else it starts a new track (where
   a wing meets a fuselage, whose side profile is long and thin too, the chord jumps). A track spanning at least :data:`MIN_ASPECT` of its mean chord along the axis is
   a **lifting surface** (the planform cut of a horizontal wing by planes along ``z`` spans
   only its thickness, and is not one).
4. **Halves.** When the skin is mirror-symmetric about the middle plane of its extent (every
   vertex has a mirror image within :data:`SYMMETRY_TOL` of the diagonal) and a lifting surface crosses that plane, it is split there into two halves,
   each with its root at the plane.
5. **Stations of the layout.** Each surface's root is the end of its track at the symmetry
   plane, or else the end with the longer chord (wings taper towards the tip); its tip the
   other end. With an
   element size ``size`` both are moved inwards so the layout can be meshed at that size: the
   root one size from the symmetry plane (the two halves' root ribs two sizes apart) or two
   sizes from the track's inboard end (where the wing leaves a body) and from the junction
   line there (the skin's creases, edges whose faces meet at more than :data:`CREASE_DEG` and run
   across the span, in the root section's extent: the run of element-size station bins near the
   track's end holding at least :data:`CREASE_EDGES` of them each), the tip at least two sizes inboard
   of the track's end and where the wing is at least :data:`TIP_THICKNESS` sizes thick (a spar
   web must be 0.3 sizes tall: at 15 % or 65 % of the chord a wing is about two thirds of its
   largest thickness). Without ``size``: a hundredth of the surface's span.

:func:`starting_layout` writes the layout of the surfaces found: each wing given by its axis,
root, tip, ``up`` (the chord-plane normal) and ``near`` (the middle of its root section), 10
ribs normal to the rear spar (with an element size: at most as many as fit :data:`RIB_GAP`
sizes apart) and spars at 15 % and 65 % of the local chord.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import LayoutError
from .planform import WING_LIKE, loop_chord, measure_planform
from .sections import section_loops

__all__ = ["FoundWing", "find_wings", "starting_layout", "FIND_STATIONS", "MIN_ASPECT", "CHORD_JUMP",
           "TIP_THICKNESS", "RIB_GAP", "CREASE_DEG", "CREASE_EDGES", "SYMMETRY_TOL", "axis_vector"]

#: planes across the skin's extent along the axis
FIND_STATIONS = 160
#: a lifting surface spans at least this many mean chords along the axis
MIN_ASPECT = 0.75
#: a track breaks where the chord changes by more than this factor from one station to the next
#: (a wing meeting a fuselage, whose side profile is long and thin too)
CHORD_JUMP = 1.3
#: the tip station is where the wing is at least this many element sizes thick
TIP_THICKNESS = 0.6
#: with an element size, the starting layout's ribs are at least this many sizes apart (a short
#: surface, a tail, gets fewer ribs than asked for)
RIB_GAP = 1.5
#: a skin edge whose faces meet at more than this angle is a crease (a wing-body junction line near
#: a wing's root keeps the root rib two element sizes away from it)
CREASE_DEG = 30.0
#: an element-size bin of stations with at least this many crease edges is part of a junction line
CREASE_EDGES = 3
#: mirror symmetry tolerance (share of the bounding-box diagonal)
SYMMETRY_TOL = 1e-4


@dataclass
class FoundWing:
    """A lifting surface: ``name``, unit ``axis``, ``root``/``tip`` station coordinates (of the
    layout, moved inwards for the size), ``start``/``end`` the track's own extent, ``up``,
    ``near`` (middle of its root section), ``root_chord``, ``tip_chord``, ``max_thickness``,
    ``mirror`` (the name of its mirror half, if any)."""

    name: str
    axis: np.ndarray
    root: float
    tip: float
    start: float
    end: float
    up: np.ndarray
    near: np.ndarray
    root_chord: float
    tip_chord: float
    max_thickness: float
    mirror: str | None = None
    max_ribs: int | None = None

    def to_layout_wing(self, ribs: int = 10, spars=(0.15, 0.65), orientation="normal_to_spar") -> dict:
        if self.max_ribs is not None:
            ribs = min(int(ribs), self.max_ribs)
        def r(v):
            return round(float(v), 9) + 0.0                # no '-0.0' in the file
        d = {"name": self.name, "axis": [r(v) for v in self.axis], "root": r(self.root), "tip": r(self.tip),
             "up": [r(v) for v in self.up], "near": [r(v) for v in self.near],
             "ribs": {"count": int(ribs), "orientation": orientation}}
        if len(spars):
            d["spars"] = {"chord_fractions": [float(c) for c in spars]}
        return d


def axis_vector(axis) -> np.ndarray:
    """A unit axis from 'x', 'y', 'z' (optionally signed) or a vector."""
    if isinstance(axis, str):
        t = axis.strip().lower()
        sign = -1.0 if t.startswith("-") else 1.0
        t = t.lstrip("+-")
        if t not in ("x", "y", "z"):
            raise LayoutError(f"axis {axis!r}: give x, y or z")
        return sign * np.eye(3)["xyz".index(t)]
    a = np.asarray(axis, float)
    n = np.linalg.norm(a)
    if not np.isfinite(n) or n == 0:
        raise LayoutError(f"axis {a.tolist()} is zero or not finite")
    return a / n


def _mirror_plane(P, a, diag):
    """The coordinate along ``a`` of the skin's mirror plane normal to ``a``, or None."""
    from scipy.spatial import cKDTree

    s = P @ a
    c = 0.5 * (s.min() + s.max())
    Q = P - np.outer(2.0 * (s - c), a)
    d, _ = cKDTree(P).query(Q)
    return c if d.max() <= SYMMETRY_TOL * diag else None


def _tracks(P, T, a, stations):
    """Wing-like loops followed from station to station: a list of tracks, each a list of
    (station index, station, loop, chord, width, centre)."""
    tracks = []                                       # open tracks end at the previous station
    done = []
    for i, t in enumerate(stations):                  # loop over stations
        loops = section_loops(P, T, t * a, a)
        items = []
        for lp in loops:
            L, W, _ = loop_chord(lp)
            if L > 0 and W <= WING_LIKE * L:
                items.append((i, t, lp, L, W, 0.5 * (lp.min(0) + lp.max(0))))
        still = []
        used = set()
        for it in items:
            best, bd = None, np.inf
            for k, tr in enumerate(tracks):
                if k in used:
                    continue
                last = tr[-1]
                d = float(np.linalg.norm((it[5] - last[5]) - ((it[5] - last[5]) @ a) * a))
                jump = max(it[3], last[3]) / max(min(it[3], last[3]), 1e-300)
                if d <= 0.5 * max(last[3], it[3]) and jump <= CHORD_JUMP and d < bd:
                    best, bd = k, d
            if best is None:
                still.append([it])
            else:
                used.add(best)
                tracks[best].append(it)
        done += [tr for k, tr in enumerate(tracks) if k not in used]
        tracks = [tr for k, tr in enumerate(tracks) if k in used] + still
    return done + tracks


def _crease_edges(P, T, a):
    """Midpoints of the skin's crease edges (faces meeting at more than :data:`CREASE_DEG`) that
    run across the span (within 60 degrees of the station planes): a wing-body junction, not a
    sharp leading or trailing edge."""
    e = np.vstack([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]])
    f = np.tile(np.arange(len(T)), 3)
    key = np.sort(e, axis=1)
    order = np.lexsort((key[:, 1], key[:, 0]))
    k, f = key[order], f[order]
    same = (k[1:] == k[:-1]).all(1)
    i = np.flatnonzero(same)
    n = np.cross(P[T[:, 1]] - P[T[:, 0]], P[T[:, 2]] - P[T[:, 0]])
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    cosang = np.einsum("ij,ij->i", n[f[i]], n[f[i + 1]])
    crease = i[cosang < np.cos(np.radians(CREASE_DEG))]
    ek = k[crease]
    d = P[ek[:, 1]] - P[ek[:, 0]]
    across = np.abs(d @ a) <= np.cos(np.radians(30.0)) * np.linalg.norm(d, axis=1)
    return 0.5 * (P[ek[across, 0]] + P[ek[across, 1]])


def _root_creases(P, T, a, piece, sgn, creases, h):
    """Where the junction line at the root of a wing ends (towards the tip): the crease edges
    inside the root section's extent, binned by station in steps of ``h`` from two steps
    inboard of the track's root end; the outermost station of the run of bins holding at least
    :data:`CREASE_EDGES` such edges each (a line across the chord, not a stray facet edge) that
    starts within the first five bins; None when there is none."""
    if not len(creases):
        return None
    t0, lp, L = piece[0][1], piece[0][2], piece[0][3]
    t = creases @ a
    lo, hi = lp.min(0) - 0.05 * L, lp.max(0) + 0.05 * L
    q = creases - np.outer(t, a)
    lo, hi = lo - (lo @ a) * a, hi - (hi @ a) * a
    inside = ((q >= np.minimum(lo, hi) - 1e-12) & (q <= np.maximum(lo, hi) + 1e-12)).all(1)
    r = (t[inside] - t0) * sgn + 2.0 * h               # distance from two steps inboard of the end
    r = r[r >= 0]
    if not len(r):
        return None
    cnt = np.bincount((r / h).astype(np.int64))
    full = np.flatnonzero(cnt[:5] >= CREASE_EDGES)        # the run starts within three steps of the end
    if not len(full):
        return None
    k = int(full[0])
    while k < len(cnt) and cnt[k] >= CREASE_EDGES:
        k += 1
    last = r[(r / h).astype(np.int64) < k].max()
    return float(t0 + sgn * (last - 2.0 * h))


def find_wings(points, tris, axis="y", size: float | None = None) -> list:
    """The lifting surfaces of the skin ``(points, tris)`` along ``axis`` ('x', 'y', 'z' or a
    vector), their stations fitted to the element ``size`` (module docstring), largest first.
    Raises :class:`~shellmesh_mdao.errors.LayoutError` when there is none."""
    P = np.asarray(points, float)
    T = np.asarray(tris, np.int64)
    a = axis_vector(axis)
    s = P @ a
    lo, hi = float(s.min()), float(s.max())
    ext = hi - lo
    if ext <= 0:
        raise LayoutError("the skin has no extent along the axis; choose another --axis")
    diag = float(np.linalg.norm(np.ptp(P, axis=0)))
    stations = np.linspace(lo + 0.01 * ext, hi - 0.01 * ext, FIND_STATIONS)
    step = float(stations[1] - stations[0])
    tracks = [tr for tr in _tracks(P, T, a, stations) if len(tr) >= 3]
    surfaces = []
    for tr in tracks:
        span = tr[-1][1] - tr[0][1]
        chord = float(np.mean([it[3] for it in tr]))
        if span >= MIN_ASPECT * chord:
            surfaces.append(tr)
    if not surfaces:
        raise LayoutError(f"no lifting surface along the axis {np.round(a, 6).tolist()}: no thin sections (at most "
                          f"{WING_LIKE:g} as thick as long) follow each other over {MIN_ASPECT:g} chords; try another "
                          "--axis (the span direction: y for most aircraft, z for a fin)")
    mirror = _mirror_plane(P, a, diag)
    creases = _crease_edges(P, T, a)
    parts = []                                        # (track piece, root end first)
    for tr in surfaces:
        t0, t1 = tr[0][1], tr[-1][1]
        if mirror is not None and t0 < mirror < t1:
            left = [it for it in tr if it[1] < mirror]
            right = [it for it in tr if it[1] > mirror]
            parts += [(right, True, mirror), (left[::-1], True, mirror)]
        else:
            parts.append((tr if tr[0][3] >= tr[-1][3] else tr[::-1], False, None))
    out = []
    for piece, at_mirror, plane in parts:
        if len(piece) < 2:
            continue
        ta, tb = piece[0][1], piece[-1][1]
        sgn = 1.0 if tb > ta else -1.0
        span = abs(tb - ta)
        h = float(size) if size is not None else span / 100.0
        start = plane if at_mirror else ta - sgn * 0.5 * step
        end = tb + sgn * 0.5 * step
        root = (plane + sgn * h) if at_mirror else (start + sgn * 2.0 * h)
        if not at_mirror:                             # clear of the junction's creases
            crease = _root_creases(P, T, a, piece, sgn, creases, h)
            if crease is not None and (crease + sgn * 2.0 * h - root) * sgn > 0:
                root = crease + sgn * 2.0 * h
        # the tip: two sizes inboard of the end, where the wing is at least one size thick
        tip = end - sgn * 2.0 * h
        thick = [(it[1], it[4]) for it in piece]
        for t, W in thick[::-1]:
            if (t - tip) * sgn <= 0 and W >= TIP_THICKNESS * h:
                tip = t
                break
        if (tip - root) * sgn <= 2.0 * h:
            continue                                  # too short for the size: no layout
        root_loop = min(piece, key=lambda it: abs(it[1] - root))[2]
        chord_dir = loop_chord(root_loop)[2]
        up = np.cross(a, chord_dir)
        up = up - (up @ a) * a
        up = up / np.linalg.norm(up)
        up = up if up[int(np.argmax(np.abs(up)))] > 0 else -up
        try:
            pf = measure_planform(P, T, a, root, tip, up=up, near=0.5 * (root_loop.min(0) + root_loop.max(0)),
                                  tol=0.1 * h, name="wing")
        except LayoutError:
            continue
        out.append(FoundWing(name="", axis=a.copy(), root=float(root), tip=float(tip),
                             start=float(start), end=float(end), up=pf.up.copy(),
                             near=pf.shapes[0].center.copy(), root_chord=pf.shapes[0].chord,
                             tip_chord=pf.shapes[-1].chord, max_thickness=max(x.thickness for x in pf.shapes),
                             max_ribs=None if size is None else max(2, int(abs(tip - root) / (RIB_GAP * h)) + 1)))
    if not out:
        raise LayoutError("the lifting surfaces found are too short for the element size; give a smaller --size")
    # names: by size (span x mean chord); mirror halves share their number
    out.sort(key=lambda w: -abs(w.tip - w.root) * 0.5 * (w.root_chord + w.tip_chord))
    n = 0
    for w in out:
        if w.name:
            continue
        n += 1
        partner = None
        if mirror is not None:
            img = w.near - 2.0 * ((w.near @ a) - mirror) * a
            cand = [o for o in out if o is not w and not o.name and (o.tip - o.root) * (w.tip - w.root) < 0
                    and np.linalg.norm(o.near - img) <= 0.25 * max(w.root_chord, 1e-300)]
            partner = cand[0] if cand else None
        for x in (w,) if partner is None else (w, partner):
            side = ("right_" if (x.tip - x.root) > 0 else "left_") if mirror is not None else ""
            x.name = f"{side}surface_{n}"
        if partner is not None:
            w.mirror, partner.mirror = partner.name, w.name
    return out


def starting_layout(wings, ribs: int = 10, spars=(0.15, 0.65), orientation: str = "normal_to_spar") -> dict:
    """The layout dict of the surfaces ``wings`` (:class:`FoundWing`): each given by its
    stations, ``ribs`` ribs in ``orientation`` and spars at ``spars``."""
    return {"wings": [w.to_layout_wing(ribs, spars, orientation) for w in wings]}
