"""Member layouts: which ribs, spars and explicit members to build, and where.

A layout is a JSON or YAML file (same schema) or a dict; :func:`load_layout` turns it
into a validated :class:`Layout`, and :meth:`Layout.members` resolves it into a list of
:class:`MemberSpec` (planes, bounding segments, bounding members) in a fixed order.
The file reference, with every error message and its fix, is ``docs/layout.md``.

Wing geometry (all points in the surface file's units):

* station ``eta`` in [0, 1] runs from the root chord (``root_le -> root_te``) to the tip
  chord (``tip_le -> tip_te``); ``le(eta) = lerp(root_le, tip_le, eta)``, ``te`` likewise;
* the *reference surface* ``S(eta, c) = lerp(le(eta), te(eta), c)`` (``c`` chord
  fraction) is the wing's chord "plane" (a ruled surface, flat for an untwisted wing);
* span direction ``s = (tip_le + tip_te)/2 - (root_le + root_te)/2`` (mid-chord line);
* a **rib** plane contains ``up`` and has normal ``n_rib = s - (s·up) up`` normalised
  (the span direction projected into the plane normal to ``up``; it points root -> tip).
  Rib ``k`` at ``eta_k`` passes through ``S(eta_k, c_mid)``, ``c_mid`` the middle of its
  chord range ``[c_a, c_b]`` (first and last spar fractions, or 0 and 1 with fewer than
  two spars). Its defining curve is the plane's intersection with the reference surface
  for ``c`` in ``[c_a, c_b]``; its ends lie on the spar lines ``S(., c_a)``, ``S(., c_b)``;
* a **spar** at chord fraction ``c_j`` runs along ``S(eta, c_j)``, a straight line from
  its root chord point ``S(0, c_j)`` to its tip chord point ``S(1, c_j)``; its plane
  contains ``up`` and that line (normal ``(tip - root) x up`` normalised, pointing aft).
  It is bounded by the first and last rib planes (by the planes of stations 0 and 1
  when the wing has no ribs).
"""
from __future__ import annotations

import difflib
import json
import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import LayoutError, SizeError
from ..families import rib_name, spar_name
from ..mesh import norm_rows
from .parsing import MAX_RIBS, Vec, check_chord as _check_chord, check_eta as _check_eta, \
    check_keys as _check_keys, member_name as _name, number_list as _number_list, \
    unit as _unit, vec3 as _vec3
from .stations import END_RIBS, RIB_ORIENTATIONS, StationWing, parse_station_wing, station_wing_dict

__all__ = ["Layout", "WingLayout", "StationWing", "ExplicitMember", "MemberSpec", "load_layout",
           "layout_from_manifest", "explicit_plane", "resample_polyline", "MIN_UP_SPAN_ANGLE_DEG", "RIB_ORIENTATIONS",
           "END_RIBS", "MIN_MEMBER_GAP", "MIN_LOCAL_SIZE", "coincident_parts"]

#: ``up`` must make at least this angle with the span line (else the rib normal is undefined).
MIN_UP_SPAN_ANGLE_DEG = 10.0

#: two neighbouring ribs (spars) closer than this many element sizes coincide at that size and are
#: refused; from there up to one element size apart they are meshed with a local element size about
#: their gap (the project stage's :func:`~shellmesh_mdao.project.close_member_field`). The remesh's
#: smallest edge (``remesh.DEFAULT_MIN_EDGE_FRACTION`` of its edge length, twice the element size)
#: is 0.2 element sizes.
MIN_MEMBER_GAP = 0.2

#: where a spar or web is too thin for a web of quads of the element size, the mesh refines around
#: it (the project stage's :func:`~shellmesh_mdao.project.thin_member_field`), down to this fraction
#: of the element size; a member that would need smaller elements still is refused
MIN_LOCAL_SIZE = 0.1


def coincident_parts(pairs) -> tuple:
    """The parts of the one error naming every pair of members that coincide (or cross) at an
    element size: ``(pairs text, fix)``; ``pairs`` a list of ``(text, gap)`` (``gap`` None for
    members that cross), each text naming the two members and how close they are. The callers
    (:meth:`Layout.validate`, :func:`~shellmesh_mdao.layout.resolve_layout`) raise
    ``members coincide or cross at element size {size} (closer than ...): {text}: {fix}``."""
    txt = "; ".join(t for t, _ in pairs)
    gaps = [g for _, g in pairs if g is not None]
    fix = f"remove one member of each pair or move them apart (members at least {MIN_MEMBER_GAP:g} element sizes " \
          "apart are meshed, with smaller elements between them)"
    if len(gaps) == len(pairs) and min(gaps) > 0:
        fix += f", or use an element size below {min(gaps) / MIN_MEMBER_GAP:.4g}"
    elif len(gaps) < len(pairs):
        fix += "; ribs that cross: fewer ribs, or ribs.orientation nearer the station direction"
    return txt, fix


_TOP_KEYS = ("wings", "members", "up")
_WING_KEYS = ("name", "root_le", "root_te", "tip_le", "tip_te", "up", "ribs", "spars")
_WING_REQUIRED = ("name", "root_le", "root_te", "tip_le", "tip_te")
_RIB_KEYS = ("count", "eta")
_SPAR_KEYS = ("chord_fractions",)
_MEMBER_KEYS = ("name", "upper", "lower", "direction", "lower_direction")
_MEMBER_REQUIRED = ("name", "upper", "lower")


# ----------------------------------------------------------------------------- parsing helpers


# ----------------------------------------------------------------------------- data classes
@dataclass(frozen=True)
class WingLayout:
    """One wing: its wing-box corners, ``up``, rib stations and spar chord fractions.

    ``rib_eta`` strictly increasing in [0, 1]; ``spar_chord`` strictly increasing in
    (0, 1); ``rib_count`` is set when the ribs were given as ``{"count": N}`` (kept for
    :meth:`Layout.to_dict`); ``up`` is None when the layout-level ``up`` applies."""

    name: str
    root_le: Vec
    root_te: Vec
    tip_le: Vec
    tip_te: Vec
    up: Vec | None = None
    rib_eta: tuple = ()
    spar_chord: tuple = ()
    rib_count: int | None = None

    # ------------------------------------------------------------ geometry
    def corners(self) -> np.ndarray:
        """(4, 3) array root_le, root_te, tip_le, tip_te."""
        return np.array([self.root_le, self.root_te, self.tip_le, self.tip_te], dtype=np.float64)

    def le(self, eta) -> np.ndarray:
        eta = np.asarray(eta, dtype=np.float64)[..., None]
        return (1 - eta) * np.asarray(self.root_le) + eta * np.asarray(self.tip_le)

    def te(self, eta) -> np.ndarray:
        eta = np.asarray(eta, dtype=np.float64)[..., None]
        return (1 - eta) * np.asarray(self.root_te) + eta * np.asarray(self.tip_te)

    def chord_point(self, eta, c) -> np.ndarray:
        """Reference-surface point ``S(eta, c)`` (broadcasting over ``eta`` and ``c``)."""
        eta, c = np.broadcast_arrays(np.asarray(eta, dtype=np.float64), np.asarray(c, dtype=np.float64))
        cc = c[..., None]
        return (1 - cc) * self.le(eta) + cc * self.te(eta)

    def span_vector(self) -> np.ndarray:
        """Mid-chord span line ``(tip_le+tip_te)/2 - (root_le+root_te)/2``."""
        return 0.5 * (np.asarray(self.tip_le) + np.asarray(self.tip_te)) \
            - 0.5 * (np.asarray(self.root_le) + np.asarray(self.root_te))

    def rib_normal(self, up) -> np.ndarray:
        """Unit normal of every rib plane of this wing (root -> tip)."""
        u = _unit(up)
        s = self.span_vector()
        return _unit(s - (s @ u) * u)

    def eta_on_plane(self, c, point, normal) -> np.ndarray:
        """Station ``eta`` at which the reference-surface line of chord fraction ``c``
        crosses the plane ``(x - point)·normal = 0`` (vectorised over ``c``)."""
        c = np.asarray(c, dtype=np.float64)
        a = self.chord_point(np.zeros_like(c), c)
        b = self.chord_point(np.ones_like(c), c) - a
        return ((np.asarray(point) - a) @ np.asarray(normal)) / (b @ np.asarray(normal))


@dataclass(frozen=True)
class ExplicitMember:
    """The paper's general member: polylines ``upper`` and ``lower`` (each (k, 3)) projected
    onto the skin; ``upper`` along ``direction``, ``lower`` along ``lower_direction``
    (default ``-direction``), both to the closest skin point when ``direction`` is None."""

    name: str
    upper: tuple
    lower: tuple
    direction: Vec | None = None
    lower_direction: Vec | None = None

    @property
    def upper_direction(self):
        return None if self.direction is None else np.asarray(self.direction, dtype=np.float64)

    @property
    def lower_dir(self):
        if self.lower_direction is not None:
            return np.asarray(self.lower_direction, dtype=np.float64)
        return None if self.direction is None else -np.asarray(self.direction, dtype=np.float64)


@dataclass
class MemberSpec:
    """A resolved member.

    ``name``            '<wing>/rib_<k>', '<wing>/spar_<j>' or the explicit member's name.
    ``kind``            'rib' | 'spar' | 'explicit'.
    ``wing``, ``index`` owning wing name and k / j (None and position for explicit members).
    ``parameter``       rib station eta or spar chord fraction (None for explicit).
    ``plane_point``, ``plane_normal``  the member plane (unit normal); None for explicit.
    ``up``              the wing's unit up (None for explicit).
    ``start``, ``end``  ends of the member's defining curve on the wing reference surface:
                        rib: at its first and last spar (or LE and TE); spar: at its first
                        and last rib planes (or root and tip stations).
    ``root_point``, ``tip_point``  spar only: chord points ``S(0, c)``, ``S(1, c)``.
    ``bounds``          names of what bounds it: rib (spar_0, spar_last) or ('LE', 'TE');
                        spar (rib_0, rib_last) or ('root', 'tip').
    ``bound_planes``    half-spaces ``((point, normal), ...)`` the member lies in
                        (``(x - point)·normal >= 0`` inside): a rib between its two spar
                        planes (none when bounded by LE/TE), a spar between its end rib
                        planes (or the station-0/1 rib planes).
    ``chord_range``     rib: (c_a, c_b); ``eta_range`` spar: (eta_start, eta_end).
    ``upper``, ``lower``, ``direction``, ``lower_direction``: explicit members only.
    ``seeds``           (k, 3) the defining curve's points when the wing gives them (a full-chord
                        rib of a station-given wing); :meth:`seed_points` resamples them.
    """

    name: str
    kind: str
    wing: str | None
    index: int
    parameter: float | None = None
    plane_point: np.ndarray | None = None
    plane_normal: np.ndarray | None = None
    up: np.ndarray | None = None
    start: np.ndarray | None = None
    end: np.ndarray | None = None
    root_point: np.ndarray | None = None
    tip_point: np.ndarray | None = None
    bounds: tuple = ()
    bound_planes: tuple = ()
    chord_range: tuple | None = None
    eta_range: tuple | None = None
    upper: np.ndarray | None = None
    lower: np.ndarray | None = None
    direction: np.ndarray | None = None
    lower_direction: np.ndarray | None = None
    wing_layout: WingLayout | None = field(default=None, repr=False)
    seeds: np.ndarray | None = field(default=None, repr=False)

    @property
    def is_planar(self) -> bool:
        return self.plane_normal is not None

    def seed_points(self, n: int = 5) -> np.ndarray:
        """``n`` points along the member's defining curve on the wing reference surface
        (from ``start`` to ``end``, in the member plane); explicit members: not defined
        (use ``upper``/``lower``)."""
        if self.kind == "explicit":
            raise LayoutError(f"member '{self.name}' is explicit: it has no chord-plane seed points; "
                              "use its upper/lower polylines")
        n = max(int(n), 2)
        if self.seeds is not None:
            return resample_polyline(self.seeds, n)
        w = self.wing_layout
        if self.kind == "rib":
            c = np.linspace(self.chord_range[0], self.chord_range[1], n)
            eta = w.eta_on_plane(c, self.plane_point, self.plane_normal)
            pts = w.chord_point(eta, c)
        else:
            eta = np.linspace(self.eta_range[0], self.eta_range[1], n)
            pts = w.chord_point(eta, np.full(n, self.parameter))
        pts[0], pts[-1] = self.start, self.end
        return pts


def resample_polyline(points, n: int) -> np.ndarray:
    """``n`` points evenly spaced by arc length along the polyline ``points`` (k, 3), its two
    ends exactly."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    s = np.concatenate([[0.0], np.cumsum(norm_rows(np.diff(p, axis=0), axis=1))])
    if s[-1] == 0:
        return np.repeat(p[:1], n, axis=0)
    q = np.linspace(0.0, s[-1], n)
    out = np.stack([np.interp(q, s, p[:, i]) for i in range(3)], 1)
    out[0], out[-1] = p[0], p[-1]
    return out


def explicit_plane(spec, tol: float = 1e-9):
    """The plane of a planar explicit member from its layout: ``(point, unit normal)`` when its
    ``upper`` and ``lower`` polylines and both projection directions lie in one plane (within
    ``tol`` times the polylines' extent), else ``(None, None)`` (a kinked or twisted member, or
    closest-point projection, whose projection directions are not known before projecting)."""
    d_up = getattr(spec, "direction", None)
    if d_up is None:
        return None, None
    up_pts = np.asarray(spec.upper, float).reshape(-1, 3)
    lo_pts = np.asarray(spec.lower, float).reshape(-1, 3)
    d_lo = getattr(spec, "lower_direction", None)
    dirs = np.asarray([d_up] + ([] if d_lo is None else [d_lo]), float)
    dirs = dirs / norm_rows(dirs, axis=1, keepdims=True)
    pts = np.vstack([up_pts, lo_pts])
    ext = float(norm_rows(np.ptp(pts, axis=0)))
    seg = np.diff(up_pts, axis=0)
    k = int(np.argmax(norm_rows(seg, axis=1)))
    n = np.cross(seg[k], dirs[0])
    ln = float(np.linalg.norm(n))
    if ext == 0 or ln <= 1e-12 * float(np.linalg.norm(seg[k])):
        return None, None
    n = n / ln
    if np.abs((pts - up_pts[0]) @ n).max() > tol * ext or np.abs(dirs @ n).max() > tol:
        return None, None
    return up_pts[0].copy(), n


@dataclass(frozen=True)
class Layout:
    """A validated layout: ``wings`` (:class:`WingLayout`, wings given by their corners),
    ``explicit`` members (:class:`ExplicitMember`, the file's ``members`` list), the default
    ``up`` and ``station_wings`` (:class:`StationWing`, wings given by their span axis and
    stations, measured from the skin: :func:`~shellmesh_mdao.layout.wingbox.resolve_layout`).
    :meth:`members` gives the resolved :class:`MemberSpec` list."""

    wings: tuple = ()
    explicit: tuple = ()
    up: Vec | None = None
    station_wings: tuple = ()

    # ------------------------------------------------------------ resolution
    def wing(self, name: str) -> WingLayout:
        for w in self.wings:
            if w.name == name:
                return w
        raise LayoutError(f"no wing named '{name}' in the layout (wings: {[w.name for w in self.wings]})")

    def wing_up(self, w: WingLayout) -> np.ndarray:
        """Unit ``up`` of a wing (its own, else the layout's)."""
        up = w.up if w.up is not None else self.up
        if up is None:
            raise LayoutError(f"wing '{w.name}' has no 'up' direction: add \"up\": [0, 0, 1] (the normal of its "
                              "chord plane) to the wing or at the top level of the layout")
        return _unit(up)

    def members(self) -> list:
        """Resolved :class:`MemberSpec` list, deterministic order: for each wing in file
        order its spars (leading edge first) then its ribs (root first); then the explicit
        members in file order."""
        out = []
        for w in self.wings:
            out.extend(_wing_members(w, self.wing_up(w)))
        for w in self.station_wings:
            if not w.resolved:
                raise LayoutError(f"wing '{w.name}' is given by its stations: its members are known once its planform "
                                  "is measured from the skin; resolve the layout against the surface first "
                                  "(shellmesh_mdao.layout.resolve_layout, which the pipeline's layout stage runs)")
            out.extend(w.specs)
        for i, m in enumerate(self.explicit):
            out.append(MemberSpec(
                name=m.name, kind="explicit", wing=None, index=i,
                upper=np.asarray(m.upper, dtype=np.float64), lower=np.asarray(m.lower, dtype=np.float64),
                direction=m.upper_direction, lower_direction=m.lower_dir))
        return out

    def member_names(self) -> list:
        """Names of the members, in :meth:`members` order; for a station-given wing not yet
        resolved, the names it will have (:meth:`StationWing.predicted_names`)."""
        if all(w.resolved for w in self.station_wings):
            return [m.name for m in self.members()]
        out = []
        for w in self.wings:
            out.extend(m.name for m in _wing_members(w, self.wing_up(w)))
        for w in self.station_wings:
            out.extend(m.name for m in w.specs) if w.resolved else out.extend(w.predicted_names())
        out.extend(m.name for m in self.explicit)
        return out

    @property
    def all_wing_names(self) -> list:
        """Names of every wing, corner-given then station-given."""
        return [w.name for w in self.wings] + [w.name for w in self.station_wings]

    # ------------------------------------------------------------ checks
    def coincident_pairs(self, size: float) -> list:
        """Every pair of neighbouring members that coincide at element ``size`` (closer than
        :data:`MIN_MEMBER_GAP` element sizes) or cross: ``(text, gap)`` (``gap`` None for members
        that cross), corner-given wings from their rib planes and spar chord points at root and
        tip, station-given wings as their resolution found them (``StationWing.close_pairs``)."""
        size = float(size)
        pairs = []
        for w in self.wings:
            up = self.wing_up(w)
            n = w.rib_normal(up)
            if len(w.rib_eta) >= 2:
                specs = [m for m in _wing_members(w, up) if m.kind == "rib"]
                off = np.array([m.plane_point @ n for m in specs])
                gap = np.diff(off)
                for k in np.flatnonzero(gap < MIN_MEMBER_GAP * size):
                    pairs.append((f"ribs '{specs[k].name}' (eta={w.rib_eta[k]:g}) and '{specs[k + 1].name}' "
                                  f"(eta={w.rib_eta[k + 1]:g}) are {gap[k]:.4g} apart", float(gap[k])))
            if len(w.spar_chord) >= 2:
                c = np.asarray(w.spar_chord)
                root = w.chord_point(np.zeros_like(c), c)
                tip = w.chord_point(np.ones_like(c), c)
                gap = np.minimum(np.linalg.norm(np.diff(root, axis=0), axis=1),
                                 np.linalg.norm(np.diff(tip, axis=0), axis=1))
                for j in np.flatnonzero(gap < MIN_MEMBER_GAP * size):
                    pairs.append((f"spars '{spar_name(w.name, j)}' (c={c[j]:g}) and '{spar_name(w.name, j + 1)}' "
                                  f"(c={c[j + 1]:g}) are {gap[j]:.4g} apart", float(gap[j])))
        for w in self.station_wings:
            pairs.extend(w.close_pairs)
        return pairs

    def validate(self, size: float | None = None) -> "Layout":
        """Check geometric consistency; with an element ``size``, also that no two neighbouring
        ribs (planes) or spars (chord points at root and tip) of a wing coincide: closer than
        :data:`MIN_MEMBER_GAP` element sizes (closer than ``size`` but no closer than that, they
        are meshed with smaller elements between them). One error names every such pair.
        Returns self; raises :class:`LayoutError` (or :class:`SizeError` for a bad ``size``)."""
        for w in self.wings:
            _check_wing_geometry(w, self.wing_up(w))
        names = self.member_names()
        seen = set()
        for n in names:
            if n in seen:
                raise LayoutError(f"duplicate member name '{n}': every wing and explicit member needs a "
                                  "unique name; rename one of them")
            seen.add(n)
        if size is None:
            return self
        if isinstance(size, bool) or not isinstance(size, (int, float, np.integer, np.floating)) \
                or not math.isfinite(float(size)) or float(size) <= 0:
            raise SizeError(f"element size must be a positive finite number, got {size!r}")
        size = float(size)
        pairs = self.coincident_pairs(size)
        if pairs:
            txt, fix = coincident_parts(pairs)
            raise LayoutError(f"members coincide or cross at element size {size:g} (closer than {MIN_MEMBER_GAP:g} "
                              f"element sizes, {MIN_MEMBER_GAP * size:.4g}): {txt}: {fix}")
        return self

    # ------------------------------------------------------------ conversion
    def to_dict(self) -> dict:
        """Plain dict (JSON/YAML-ready) that :func:`load_layout` turns back into an equal Layout."""
        d: dict = {}
        if self.up is not None:
            d["up"] = list(self.up)
        wings = []
        for w in self.wings:
            wd = {"name": w.name, "root_le": list(w.root_le), "root_te": list(w.root_te),
                  "tip_le": list(w.tip_le), "tip_te": list(w.tip_te)}
            if w.up is not None:
                wd["up"] = list(w.up)
            if w.rib_count is not None:
                wd["ribs"] = {"count": int(w.rib_count)}
            elif w.rib_eta:
                wd["ribs"] = {"eta": list(w.rib_eta)}
            if w.spar_chord:
                wd["spars"] = {"chord_fractions": list(w.spar_chord)}
            wings.append(wd)
        wings.extend(station_wing_dict(w) for w in self.station_wings)
        d["wings"] = wings
        mem = []
        for m in self.explicit:
            md = {"name": m.name, "upper": [list(p) for p in m.upper], "lower": [list(p) for p in m.lower]}
            if m.direction is not None:
                md["direction"] = list(m.direction)
            if m.lower_direction is not None:
                md["lower_direction"] = list(m.lower_direction)
            mem.append(md)
        if mem:
            d["members"] = mem
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2)

    # ------------------------------------------------------------ design variables
    def parameters(self) -> tuple:
        """``(rib_eta, spar_chord)``: dicts wing name -> float64 array (copies), for every wing,
        corner-given then station-given (a station-given wing's ``spar_chord`` is its root chord
        fractions, which hold along the whole span when it gives no tip fractions)."""
        ws = self.wings + self.station_wings
        return ({w.name: np.array(w.rib_eta, dtype=np.float64) for w in ws},
                {w.name: np.array(w.spar_chord, dtype=np.float64) for w in ws})

    def with_parameters(self, rib_eta: dict | None = None, spar_chord: dict | None = None,
                        spar_chord_tip: dict | None = None, spar_chord_cranks: dict | None = None) -> "Layout":
        """A new validated Layout with the given rib stations / spar chord fractions per wing
        (wings not named keep theirs). Counts are fixed: each array must have as many
        entries as the wing has ribs / spars.

        Corner- and station-given wings alike: ``rib_eta`` the rib stations (span fractions from
        the root to the tip station for a station-given wing), ``spar_chord`` the spar chord
        fractions (a station-given wing's root fractions, of the local chord). Station-given wings
        that give them also take ``spar_chord_tip`` (one fraction per spar) and
        ``spar_chord_cranks`` (one list per crank, ``(n_cranks, n_spars)``). A station-given wing
        with new values is returned unresolved: the pipeline's layout stage lays it out again."""
        given = {"rib_eta": dict(rib_eta or {}), "spar_chord": dict(spar_chord or {}),
                 "spar_chord_tip": dict(spar_chord_tip or {}), "spar_chord_cranks": dict(spar_chord_cranks or {})}
        names = self.all_wing_names
        for key, d in given.items():
            for k in d:
                if k not in names:
                    close = difflib.get_close_matches(str(k), names, n=1, cutoff=0.5)
                    hint = f"did you mean '{close[0]}'?" if close else f"wings are: {', '.join(names)}"
                    raise LayoutError(f"{key} names unknown wing '{k}': {hint}")
        stations = {w.name: w for w in self.station_wings}
        for key, what in (("spar_chord_tip", "tip"), ("spar_chord_cranks", "crank")):
            for k in given[key]:
                if getattr(stations.get(k), key, None) is None:
                    raise LayoutError(f"{key} names wing '{k}', which has no {what} chord fractions in the "
                                      "layout: give spar_chord for it (or add "
                                      "tip_chord_fractions / crank_chord_fractions to its spars in the layout)")
        wings = tuple(_with_wing_parameters(w, given) for w in self.wings)
        station_wings = tuple(_with_wing_parameters(w, given) for w in self.station_wings)
        return replace(self, wings=wings, station_wings=station_wings).validate()


def _with_wing_parameters(w, given):
    """Wing ``w`` (corner- or station-given) with the values of ``given`` (key -> {wing: values})."""
    changes = {}
    if w.name in given["rib_eta"]:
        eta = _number_list(np.asarray(given["rib_eta"][w.name], dtype=np.float64).reshape(-1),
                           f"rib_eta['{w.name}']")
        if len(eta) != len(w.rib_eta):
            raise LayoutError(f"rib_eta['{w.name}'] has {len(eta)} entries but the wing has "
                              f"{len(w.rib_eta)} ribs: the rib count is fixed, give one eta per rib")
        _check_eta(eta, f"rib_eta['{w.name}']")
        changes.update(rib_eta=eta, rib_count=None)
    for key, attr in (("spar_chord", "spar_chord"), ("spar_chord_tip", "spar_chord_tip")):
        if w.name in given[key]:
            c = _number_list(np.asarray(given[key][w.name], dtype=np.float64).reshape(-1), f"{key}['{w.name}']")
            if len(c) != len(w.spar_chord):
                raise LayoutError(f"{key}['{w.name}'] has {len(c)} entries but the wing has "
                                  f"{len(w.spar_chord)} spars: the spar count is fixed, give one fraction "
                                  "per spar")
            _check_chord(c, f"{key}['{w.name}']")
            changes[attr] = c
    if w.name in given["spar_chord_cranks"]:
        v = np.asarray(given["spar_chord_cranks"][w.name], dtype=np.float64)
        n_c, n_s = len(w.spar_chord_cranks), len(w.spar_chord)
        if v.size != n_c * n_s:
            raise LayoutError(f"spar_chord_cranks['{w.name}'] has {v.size} values but the wing has {n_c} crank(s) "
                              f"and {n_s} spar(s): give one list of {n_s} chord fractions per crank")
        v = v.reshape(n_c, n_s)
        lists = tuple(_number_list(v[i], f"spar_chord_cranks['{w.name}'][{i}]") for i in range(n_c))
        for i, c in enumerate(lists):
            _check_chord(c, f"spar_chord_cranks['{w.name}'][{i}]")
        changes["spar_chord_cranks"] = lists
    if not changes:
        return w
    if isinstance(w, StationWing):                  # laid out again against the skin
        changes.update(planform=None, specs=(), notes=())
    return replace(w, **changes)


# ----------------------------------------------------------------------------- resolution
def _wing_members(w: WingLayout, up: np.ndarray) -> list:
    n_rib = w.rib_normal(up)
    c = np.asarray(w.spar_chord, dtype=np.float64)
    if len(c) >= 2:
        ca, cb = float(c[0]), float(c[-1])
        rib_bounds = (spar_name(w.name, 0), spar_name(w.name, len(c) - 1))
    else:
        ca, cb = 0.0, 1.0
        rib_bounds = ("LE", "TE")
    cmid = 0.5 * (ca + cb)
    # spar planes
    spar_planes = []
    for j, cj in enumerate(c):
        r = w.chord_point(0.0, cj)
        t = w.chord_point(1.0, cj)
        nrm = _unit(np.cross(t - r, up))
        # orient aft (towards the trailing edge)
        if nrm @ (w.chord_point(0.5, 1.0) - w.chord_point(0.5, 0.0)) < 0:
            nrm = -nrm
        spar_planes.append((r, t, nrm))
    # rib planes
    eta = np.asarray(w.rib_eta, dtype=np.float64)
    rib_pts = [w.chord_point(e, cmid) for e in eta]
    if len(eta):
        first_plane = (rib_pts[0], n_rib)
        last_plane = (rib_pts[-1], n_rib)
        spar_bounds = (rib_name(w.name, 0), rib_name(w.name, len(eta) - 1))
    else:
        first_plane = (w.chord_point(0.0, cmid), n_rib)
        last_plane = (w.chord_point(1.0, cmid), n_rib)
        spar_bounds = ("root", "tip")
    out = []
    for j, (r, t, nrm) in enumerate(spar_planes):
        e0 = float(w.eta_on_plane(c[j], *first_plane)) if len(eta) else 0.0
        e1 = float(w.eta_on_plane(c[j], *last_plane)) if len(eta) else 1.0
        out.append(MemberSpec(
            name=spar_name(w.name, j), kind="spar", wing=w.name, index=j, parameter=float(c[j]),
            plane_point=r, plane_normal=nrm, up=up.copy(),
            start=w.chord_point(e0, c[j]), end=w.chord_point(e1, c[j]), root_point=r, tip_point=t,
            bounds=spar_bounds,
            bound_planes=((first_plane[0].copy(), n_rib.copy()), (last_plane[0].copy(), -n_rib)),
            eta_range=(e0, e1), wing_layout=w))
    for k, e in enumerate(eta):
        p = rib_pts[k]
        ea, eb = (float(v) for v in w.eta_on_plane(np.array([ca, cb]), p, n_rib))
        if len(c) >= 2:
            (_, _, n0), (_, _, n1) = spar_planes[0], spar_planes[-1]
            bp = ((spar_planes[0][0].copy(), n0.copy()), (spar_planes[-1][0].copy(), -n1))
        else:
            bp = ()
        out.append(MemberSpec(
            name=rib_name(w.name, k), kind="rib", wing=w.name, index=k, parameter=float(e),
            plane_point=p, plane_normal=n_rib.copy(), up=up.copy(),
            start=w.chord_point(ea, ca), end=w.chord_point(eb, cb), bounds=rib_bounds, bound_planes=bp,
            chord_range=(ca, cb), wing_layout=w))
    return out


def _check_wing_geometry(w: WingLayout, up: np.ndarray) -> None:
    where = f"wing '{w.name}'"
    for a, b, what in ((w.root_le, w.root_te, "root chord (root_le -> root_te)"),
                       (w.tip_le, w.tip_te, "tip chord (tip_le -> tip_te)")):
        if np.linalg.norm(np.subtract(b, a)) <= 1e-12 * max(1.0, np.abs(a).max()):
            raise LayoutError(f"{where}: the {what} has zero length ({list(a)}): give distinct leading- and "
                              "trailing-edge points")
    s = w.span_vector()
    chord = max(np.linalg.norm(np.subtract(w.root_te, w.root_le)), np.linalg.norm(np.subtract(w.tip_te, w.tip_le)))
    if np.linalg.norm(s) <= 1e-9 * chord:
        raise LayoutError(f"{where}: the span line from the root to the tip mid-chord has zero length: the root "
                          "and tip chords coincide; give root and tip stations at different span positions")
    cosang = abs(_unit(s) @ up)
    ang = math.degrees(math.acos(min(1.0, cosang)))
    if ang < MIN_UP_SPAN_ANGLE_DEG:
        raise LayoutError(f"{where}: 'up' {np.round(up, 6).tolist()} is nearly parallel to the span direction "
                          f"{np.round(_unit(s), 6).tolist()} ({ang:.1f} deg apart, minimum "
                          f"{MIN_UP_SPAN_ANGLE_DEG:g}): 'up' must be the normal of the wing's chord plane "
                          "(e.g. [0, 0, 1] for a wing spanning y), not the span direction")
    # the reference surface must cross every rib plane (span component of the chord lines > 0)
    n = w.rib_normal(up)
    for c in (0.0, 1.0):
        b = w.chord_point(1.0, c) - w.chord_point(0.0, c)
        if b @ n <= 0.05 * np.linalg.norm(b):
            raise LayoutError(f"{where}: the {'leading' if c == 0 else 'trailing'} edge from root to tip runs "
                              "against the span direction: check that root_le/root_te and tip_le/tip_te are "
                              "not swapped")


def _parse_wing(d, i) -> WingLayout:
    where = f"wings[{i}]"
    if isinstance(d, dict) and isinstance(d.get("name"), str) and d["name"].strip():
        where = f"wings[{i}] ('{d['name']}')"
    _check_keys(d, _WING_KEYS, _WING_REQUIRED, where)
    name = _name(d["name"], f"{where}.name")
    pts = {k: _vec3(d[k], f"{where}.{k}") for k in ("root_le", "root_te", "tip_le", "tip_te")}
    up = None
    if d.get("up") is not None:
        up = _vec3(d["up"], f"{where}.up")
        if np.linalg.norm(up) == 0:
            raise LayoutError(f"{where}.up is the zero vector: give the chord-plane normal, e.g. [0, 0, 1]")
    rib_eta, rib_count = (), None
    if d.get("ribs") is not None:
        r = d["ribs"]
        _check_keys(r, _RIB_KEYS, (), f"{where}.ribs")
        if ("count" in r) == ("eta" in r):
            raise LayoutError(f"{where}.ribs needs exactly one of 'count' (N evenly spaced stations) or 'eta' "
                              "(list of stations in [0, 1])")
        if "count" in r:
            n = r["count"]
            if isinstance(n, bool) or not isinstance(n, (int, np.integer)):
                raise LayoutError(f"{where}.ribs.count must be an integer, got {type(n).__name__} {n!r}")
            if n < 2:
                raise LayoutError(f"{where}.ribs.count = {n} but needs at least 2 (root and tip ribs); "
                                  "omit 'ribs' for a wing without ribs, or use 'eta' for a single station")
            if n > MAX_RIBS:
                raise LayoutError(f"{where}.ribs.count = {n} is more than {MAX_RIBS} ribs: give the number of ribs "
                                  "of the wing (a few to a few tens)")
            rib_count = int(n)
            rib_eta = tuple(float(v) for v in np.linspace(0.0, 1.0, rib_count))
        else:
            rib_eta = _number_list(r["eta"], f"{where}.ribs.eta")
            _check_eta(rib_eta, f"{where}.ribs.eta")
    spar_chord = ()
    if d.get("spars") is not None:
        s = d["spars"]
        _check_keys(s, _SPAR_KEYS, _SPAR_KEYS, f"{where}.spars")
        spar_chord = _number_list(s["chord_fractions"], f"{where}.spars.chord_fractions")
        _check_chord(spar_chord, f"{where}.spars.chord_fractions")
    return WingLayout(name=name, up=up, rib_eta=rib_eta, spar_chord=spar_chord, rib_count=rib_count, **pts)


def _parse_any_wing(d, i):
    """A corner-given (:class:`WingLayout`) or station-given (:class:`StationWing`) wing entry."""
    where = f"wings[{i}]"
    if isinstance(d, dict) and isinstance(d.get("name"), str) and d["name"].strip():
        where = f"wings[{i}] ('{d['name']}')"
    if isinstance(d, dict) and any(k in d for k in ("axis", "root", "tip")):
        corner = [k for k in ("root_le", "root_te", "tip_le", "tip_te") if k in d]
        if corner:
            raise LayoutError(f"{where} has both wing-box corners ({', '.join(corner)}) and stations (axis/root/tip): "
                              "give the corners or the stations, not both")
        return parse_station_wing(d, i, where)
    return _parse_wing(d, i)


def _parse_polyline(x, where) -> tuple:
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if not isinstance(x, (list, tuple)) or len(x) < 2:
        raise LayoutError(f"{where} must be a list of at least 2 points [[x, y, z], ...], got {x!r}")
    pts = tuple(_vec3(p, f"{where}[{i}]") for i, p in enumerate(x))
    a = np.asarray(pts)
    seg = np.linalg.norm(np.diff(a, axis=0), axis=1)
    scale = max(1.0, float(np.abs(a).max()))
    bad = np.flatnonzero(seg <= 1e-12 * scale)
    if len(bad):
        i = int(bad[0])
        raise LayoutError(f"{where}: segment {i} from point {i} to point {i + 1} has zero length "
                          f"({list(pts[i])}): remove the repeated point")
    return pts


def _parse_member(d, i) -> ExplicitMember:
    where = f"members[{i}]"
    if isinstance(d, dict) and isinstance(d.get("name"), str) and d["name"].strip():
        where = f"members[{i}] ('{d['name']}')"
    _check_keys(d, _MEMBER_KEYS, _MEMBER_REQUIRED, where)
    name = _name(d["name"], f"{where}.name")
    upper = _parse_polyline(d["upper"], f"{where}.upper")
    lower = _parse_polyline(d["lower"], f"{where}.lower")
    dirs = {}
    for k in ("direction", "lower_direction"):
        if d.get(k) is not None:
            v = _vec3(d[k], f"{where}.{k}")
            if np.linalg.norm(v) == 0:
                raise LayoutError(f"{where}.{k} is the zero vector: give a projection direction, or omit "
                                  "it to project to the closest skin point")
            dirs[k] = v
    if "lower_direction" in dirs and "direction" not in dirs:
        raise LayoutError(f"{where} has 'lower_direction' without 'direction': give 'direction' (for the "
                          "upper curve) too, or neither for closest-point projection")
    return ExplicitMember(name=name, upper=upper, lower=lower, direction=dirs.get("direction"),
                          lower_direction=dirs.get("lower_direction"))


def _read_file(path: Path) -> dict:
    if path.is_dir():
        raise LayoutError(f"{path} is a folder, not a layout file; give the .json or .yaml file itself")
    if not path.is_file():
        raise LayoutError(f"layout file not found: {path}; check the path")
    try:
        text = path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as e:
        raise LayoutError(f"{path}: not a text file (byte {e.start} is not UTF-8): a layout is a JSON or YAML "
                          "text file; give the right file or re-save it as UTF-8 text") from None
    except OSError as e:
        raise LayoutError(f"cannot read layout file {path}: {e.strerror or e}; check its permissions") from None
    suffix = path.suffix.lower()
    try:
        if suffix == ".json":
            return json.loads(text)
        import yaml
        return yaml.safe_load(text)
    except json.JSONDecodeError as e:
        raise LayoutError(f"{path}: invalid JSON at line {e.lineno}, column {e.colno}: {e.msg}; fix the syntax") \
            from None
    except Exception as e:  # yaml.YAMLError
        mark = getattr(e, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise LayoutError(f"{path}: invalid YAML{at}: {getattr(e, 'problem', None) or e}; fix the syntax") \
            from None


def load_layout(source) -> Layout:
    """Load and validate a layout from a ``.json`` / ``.yaml`` / ``.yml`` path or a dict
    (a :class:`Layout` is returned as is). Raises :class:`LayoutError` naming the
    offending item and the fix."""
    if isinstance(source, Layout):
        return source
    if isinstance(source, (str, Path)):
        d = _read_file(Path(source))
    else:
        d = source
    if d is None:
        raise LayoutError("the layout is empty: give at least one wing or member")
    _check_keys(d, _TOP_KEYS, (), "the layout")
    up = None
    if d.get("up") is not None:
        up = _vec3(d["up"], "up")
        if np.linalg.norm(up) == 0:
            raise LayoutError("up is the zero vector: give the chord-plane normal, e.g. [0, 0, 1]")
    wings_in = d.get("wings") or []
    members_in = d.get("members") or []
    if not isinstance(wings_in, (list, tuple)):
        raise LayoutError(f"'wings' must be a list of wing entries, got {type(wings_in).__name__}")
    if not isinstance(members_in, (list, tuple)):
        raise LayoutError(f"'members' must be a list of member entries, got {type(members_in).__name__}")
    if not wings_in and not members_in:
        raise LayoutError("the layout has no wings and no members: add a 'wings' or 'members' list")
    parsed = [_parse_any_wing(w, i) for i, w in enumerate(wings_in)]
    seen = {}
    for i, w in enumerate(parsed):
        if w.name in seen:
            raise LayoutError(f"duplicate wing name '{w.name}' (wings[{seen[w.name]}] and wings[{i}]): rename one")
        seen[w.name] = i
    wings = tuple(w for w in parsed if isinstance(w, WingLayout))
    stations = tuple(w for w in parsed if isinstance(w, StationWing))
    members = tuple(_parse_member(m, i) for i, m in enumerate(members_in))
    return Layout(wings=wings, explicit=members, up=up, station_wings=stations).validate()


def layout_from_manifest(manifest: dict, geometry_name: str, ribs=10, spars=(0.15, 0.65)) -> Layout:
    """Layout of every wing of one benchmark geometry in ``manifest.json``: ``ribs`` an int
    (count) or a list of stations, ``spars`` a list of chord fractions (empty: none)."""
    geos = manifest.get("geometries", manifest)
    if geometry_name not in geos:
        close = difflib.get_close_matches(geometry_name, list(geos), n=1)
        hint = f"did you mean '{close[0]}'?" if close else f"known: {', '.join(geos)}"
        raise LayoutError(f"no geometry '{geometry_name}' in the manifest: {hint}")
    g = geos[geometry_name]
    wings = []
    for w in g["wings"]:
        wd = {k: w[k] for k in _WING_REQUIRED}
        if "up" in w:
            wd["up"] = w["up"]
        if ribs is not None and not (np.ndim(ribs) and len(ribs) == 0):
            wd["ribs"] = {"count": int(ribs)} if np.ndim(ribs) == 0 else {"eta": [float(e) for e in ribs]}
        if spars is not None and len(spars):
            wd["spars"] = {"chord_fractions": [float(c) for c in spars]}
        wings.append(wd)
    d = {"wings": wings}
    if "up" in g:
        d["up"] = g["up"]
    return load_layout(d)
