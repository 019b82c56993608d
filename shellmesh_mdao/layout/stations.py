"""Wings given by their span axis and stations (``docs/layout.md``, 'Station-given wing'): the
:class:`StationWing` of a layout and its parsing; resolved against the skin by
:func:`~shellmesh_mdao.layout.wingbox.resolve_layout`."""
from __future__ import annotations

import difflib
from dataclasses import dataclass, field

import numpy as np

from ..errors import LayoutError
from ..families import rib_name, spar_name
from .parsing import MAX_RIBS, Vec, check_chord, check_eta, check_keys, member_name, number, number_list, vec3

__all__ = ["StationWing", "RIB_ORIENTATIONS", "END_RIBS", "parse_station_wing", "station_wing_dict"]

_STATION_KEYS = ("name", "axis", "root", "tip", "cranks", "up", "near", "aft", "ribs", "spars")
_STATION_REQUIRED = ("name", "axis", "root", "tip")
_STATION_RIB_KEYS = ("count", "eta", "orientation", "spar", "end_ribs")
_STATION_SPAR_KEYS = ("chord_fractions", "tip_chord_fractions", "crank_chord_fractions")
#: rib orientations of a station-given wing (or a vector: the rib planes' normal)
RIB_ORIENTATIONS = ("normal_to_spar", "streamwise", "normal_to_midchord")
#: how the root and tip ribs of a station-given wing lie
END_RIBS = ("station", "same")


@dataclass(frozen=True)
class StationWing:
    """A wing given by its span axis and stations (``docs/layout.md``, 'Station-given wing'):
    the planform (leading and trailing edge, chord, thickness at every station) is measured
    from the skin when the layout is resolved against it
    (:func:`~shellmesh_mdao.layout.wingbox.resolve_layout`, run by the pipeline's layout stage).

    ``axis`` the span axis; ``root``, ``tip`` and ``cranks`` station coordinates ``x·axis/|axis|``;
    ``up``, ``near`` (a point of the root section), ``aft`` (leading -> trailing edge) optional
    hints; ``rib_eta`` span fractions (0 root, 1 tip) of the ribs, ``rib_count`` when given as a
    count; ``rib_orientation`` one of :data:`RIB_ORIENTATIONS` or a vector (the rib planes'
    normal); ``rib_spar`` the spar the ribs are normal to (``normal_to_spar``; None: the last);
    ``end_ribs`` :data:`END_RIBS`; ``spar_chord`` the spars' chord fractions at the root (and
    everywhere when ``spar_chord_tip`` is None), ``spar_chord_tip`` at the tip,
    ``spar_chord_cranks`` at each crank (linear in the span fraction between them).

    A resolved wing (:attr:`resolved`) also holds its measured ``planform``
    (:class:`~shellmesh_mdao.layout.planform.Planform`), its members ``specs``
    (:class:`MemberSpec`, in :meth:`Layout.members` order), ``notes`` (what the resolution
    decided that the user did not ask for, e.g. edge webs) and ``close_pairs`` (the
    neighbouring ribs or spars that coincide or cross at the resolution's element size:
    ``(text, gap)``, :meth:`Layout.coincident_pairs`)."""

    name: str
    axis: Vec
    root: float
    tip: float
    cranks: tuple = ()
    up: Vec | None = None
    near: Vec | None = None
    aft: Vec | None = None
    rib_eta: tuple = ()
    rib_count: int | None = None
    rib_orientation: object = "normal_to_spar"
    rib_spar: int | None = None
    end_ribs: str = "station"
    spar_chord: tuple = ()
    spar_chord_tip: tuple | None = None
    spar_chord_cranks: tuple | None = None
    planform: object = field(default=None, compare=False, repr=False)
    specs: tuple = field(default=(), compare=False, repr=False)
    notes: tuple = field(default=(), compare=False, repr=False)
    close_pairs: tuple = field(default=(), compare=False, repr=False)

    @property
    def resolved(self) -> bool:
        return self.planform is not None

    def spar_fractions(self, eta) -> np.ndarray:
        """Chord fractions (..., n_spars) of the spars at span fractions ``eta`` (piecewise
        linear through the root, crank and tip values)."""
        eta = np.asarray(eta, dtype=np.float64)
        c0 = np.asarray(self.spar_chord, dtype=np.float64)
        if self.spar_chord_tip is None:
            return np.broadcast_to(c0, eta.shape + c0.shape).copy()
        span = self.tip - self.root
        knots = [0.0] + [(c - self.root) / span for c in self.cranks] + [1.0]
        vals = [c0] + ([np.asarray(v, dtype=np.float64) for v in self.spar_chord_cranks]
                       if self.spar_chord_cranks is not None else
                       [None] * len(self.cranks)) + [np.asarray(self.spar_chord_tip, dtype=np.float64)]
        if any(v is None for v in vals):          # no crank values: linear from the root to the tip
            knots, vals = [0.0, 1.0], [vals[0], vals[-1]]
        V = np.stack(vals)
        return np.stack([np.interp(eta, knots, V[:, j]) for j in range(V.shape[1])], -1)

    def predicted_names(self) -> list:
        """Member names the wing will have whatever its measured planform: its spars (their
        pieces and edge webs are named after resolution) then its ribs."""
        return [spar_name(self.name, j) for j in range(len(self.spar_chord))] + \
            [rib_name(self.name, k) for k in range(len(self.rib_eta))]


def _axis(x, where) -> Vec:
    """A span axis: 'x', 'y', 'z' (optionally signed, '-y') or a vector."""
    if isinstance(x, str):
        t = x.strip().lower()
        sign = -1.0 if t.startswith("-") else 1.0
        t = t.lstrip("+-")
        if t not in ("x", "y", "z"):
            raise LayoutError(f"{where} = {x!r}: give 'x', 'y' or 'z' (optionally '-y'), or a vector [x, y, z]")
        v = [0.0, 0.0, 0.0]
        v["xyz".index(t)] = sign
        return tuple(v)
    v = vec3(x, where)
    if np.linalg.norm(v) == 0:
        raise LayoutError(f"{where} is the zero vector: give the span direction, e.g. 'y' or [0, 1, 0]")
    return v


def _fraction_lists(s, where, n):
    """The optional tip and crank chord fractions of a station-given wing's spars."""
    tip = cranks = None
    if s.get("tip_chord_fractions") is not None:
        tip = number_list(s["tip_chord_fractions"], f"{where}.tip_chord_fractions")
        if len(tip) != n:
            raise LayoutError(f"{where}.tip_chord_fractions has {len(tip)} entries but chord_fractions has {n}: "
                              "give one tip fraction per spar")
        check_chord(tip, f"{where}.tip_chord_fractions")
    if s.get("crank_chord_fractions") is not None:
        if tip is None:
            raise LayoutError(f"{where} has crank_chord_fractions without tip_chord_fractions: give the tip "
                              "fractions too (the fractions run root -> cranks -> tip)")
        c = s["crank_chord_fractions"]
        if not isinstance(c, (list, tuple)):
            raise LayoutError(f"{where}.crank_chord_fractions must be a list (one list of fractions per crank)")
        cranks = tuple(number_list(v, f"{where}.crank_chord_fractions[{i}]") for i, v in enumerate(c))
        for i, v in enumerate(cranks):
            if len(v) != n:
                raise LayoutError(f"{where}.crank_chord_fractions[{i}] has {len(v)} entries but chord_fractions "
                                  f"has {n}: give one fraction per spar")
            check_chord(v, f"{where}.crank_chord_fractions[{i}]")
    return tip, cranks


def parse_station_wing(d, i, where) -> StationWing:
    """A wing given by its span axis and stations (``docs/layout.md``, 'Station-given wing')."""
    check_keys(d, _STATION_KEYS, _STATION_REQUIRED, where)
    name = member_name(d["name"], f"{where}.name")
    axis = _axis(d["axis"], f"{where}.axis")
    root = number(d["root"], f"{where}.root")
    tip = number(d["tip"], f"{where}.tip")
    if root == tip:
        raise LayoutError(f"{where}: root and tip are both {root:g}: give the root and tip stations (coordinates "
                          "along the axis) at different places")
    cranks = ()
    if d.get("cranks") is not None:
        cranks = number_list(d["cranks"], f"{where}.cranks")
        sgn = 1.0 if tip > root else -1.0
        for k, c in enumerate(cranks):
            if not (root < c < tip or tip < c < root):
                raise LayoutError(f"{where}.cranks[{k}] = {c:g} is not between the root ({root:g}) and the tip "
                                  f"({tip:g}): a crank station lies inside the wing")
            if k and (c - cranks[k - 1]) * sgn <= 0:
                raise LayoutError(f"{where}.cranks[{k}] = {c:g} is not further from the root than "
                                  f"{cranks[k - 1]:g}: list the cranks from the root to the tip")
    hints = {}
    for k, what in (("up", "the chord-plane normal, e.g. [0, 0, 1]"), ("aft", "a direction from the leading to "
                    "the trailing edge, e.g. [1, 0, 0]")):
        if d.get(k) is not None:
            v = vec3(d[k], f"{where}.{k}")
            if np.linalg.norm(v) == 0:
                raise LayoutError(f"{where}.{k} is the zero vector: give {what}")
            hints[k] = v
    near = vec3(d["near"], f"{where}.near") if d.get("near") is not None else None
    rib_eta, rib_count, orient, rib_spar, end_ribs = (), None, "normal_to_spar", None, "station"
    if d.get("ribs") is not None:
        r = d["ribs"]
        check_keys(r, _STATION_RIB_KEYS, (), f"{where}.ribs")
        if ("count" in r) == ("eta" in r):
            raise LayoutError(f"{where}.ribs needs exactly one of 'count' (N evenly spaced stations) or 'eta' "
                              "(list of span fractions in [0, 1])")
        if "count" in r:
            n = r["count"]
            if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
                raise LayoutError(f"{where}.ribs.count must be an integer, got {type(n).__name__} {n!r}")
            if n < 2 or n > MAX_RIBS:
                raise LayoutError(f"{where}.ribs.count = {n}: give at least 2 (the root and tip ribs) and at most "
                                  f"{MAX_RIBS}")
            rib_count = int(n)
            rib_eta = tuple(float(v) for v in np.linspace(0.0, 1.0, rib_count))
        else:
            rib_eta = number_list(r["eta"], f"{where}.ribs.eta")
            check_eta(rib_eta, f"{where}.ribs.eta")
        if r.get("orientation") is not None:
            o = r["orientation"]
            if isinstance(o, str):
                if o not in RIB_ORIENTATIONS:
                    close = difflib.get_close_matches(o, RIB_ORIENTATIONS, n=1, cutoff=0.5)
                    hint = f"did you mean '{close[0]}'?" if close else f"give one of {', '.join(RIB_ORIENTATIONS)}"
                    raise LayoutError(f"{where}.ribs.orientation = {o!r} is not an orientation: {hint}, or a vector "
                                      "(the normal of the rib planes)")
                orient = o
            else:
                orient = vec3(o, f"{where}.ribs.orientation")
                if np.linalg.norm(orient) == 0:
                    raise LayoutError(f"{where}.ribs.orientation is the zero vector: give the rib planes' normal")
        if r.get("spar") is not None:
            sp = r["spar"]
            if isinstance(sp, bool) or not isinstance(sp, (int, np.integer)):
                raise LayoutError(f"{where}.ribs.spar must be a spar number (0 = the front spar), got {sp!r}")
            rib_spar = int(sp)
        if r.get("end_ribs") is not None:
            if r["end_ribs"] not in END_RIBS:
                raise LayoutError(f"{where}.ribs.end_ribs = {r['end_ribs']!r}: give 'station' (the root and tip ribs "
                                  "lie along their stations) or 'same' (they take the ribs' orientation)")
            end_ribs = r["end_ribs"]
    spar_chord, tip_c, crank_c = (), None, None
    if d.get("spars") is not None:
        s = d["spars"]
        check_keys(s, _STATION_SPAR_KEYS, ("chord_fractions",), f"{where}.spars")
        spar_chord = number_list(s["chord_fractions"], f"{where}.spars.chord_fractions")
        check_chord(spar_chord, f"{where}.spars.chord_fractions")
        tip_c, crank_c = _fraction_lists(s, f"{where}.spars", len(spar_chord))
        if crank_c is not None and len(crank_c) != len(cranks):
            raise LayoutError(f"{where}.spars.crank_chord_fractions has {len(crank_c)} lists but the wing has "
                              f"{len(cranks)} crank(s): give one list per crank")
    if rib_spar is not None and not (0 <= rib_spar < len(spar_chord)):
        raise LayoutError(f"{where}.ribs.spar = {rib_spar}: the wing has {len(spar_chord)} spar(s) (numbered from 0 "
                          "at the leading edge)")
    return StationWing(name=name, axis=axis, root=root, tip=tip, cranks=cranks, up=hints.get("up"), near=near,
                       aft=hints.get("aft"), rib_eta=rib_eta, rib_count=rib_count, rib_orientation=orient,
                       rib_spar=rib_spar, end_ribs=end_ribs, spar_chord=spar_chord, spar_chord_tip=tip_c,
                       spar_chord_cranks=crank_c)


def station_wing_dict(w: StationWing) -> dict:
    """The file form of a station-given wing (what :func:`parse_station_wing` reads back)."""
    wd = {"name": w.name, "axis": list(w.axis), "root": w.root, "tip": w.tip}
    if w.cranks:
        wd["cranks"] = list(w.cranks)
    for k in ("up", "near", "aft"):
        if getattr(w, k) is not None:
            wd[k] = list(getattr(w, k))
    if w.rib_eta:
        r = {"count": int(w.rib_count)} if w.rib_count is not None else {"eta": list(w.rib_eta)}
        r["orientation"] = w.rib_orientation if isinstance(w.rib_orientation, str) else list(w.rib_orientation)
        if w.rib_spar is not None:
            r["spar"] = int(w.rib_spar)
        r["end_ribs"] = w.end_ribs
        wd["ribs"] = r
    if w.spar_chord:
        s = {"chord_fractions": list(w.spar_chord)}
        if w.spar_chord_tip is not None:
            s["tip_chord_fractions"] = list(w.spar_chord_tip)
        if w.spar_chord_cranks is not None:
            s["crank_chord_fractions"] = [list(v) for v in w.spar_chord_cranks]
        wd["spars"] = s
    return wd
