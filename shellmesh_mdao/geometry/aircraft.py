"""A parametric family of aircraft: closed skins and layouts given by stations, drawn at random.

:class:`AircraftParams` holds the shape: a wing (NACA 4-digit sections of any thickness and camber,
taper, leading-edge sweep, dihedral, linear twist, sharp or blunt trailing edge, an optional
crank, flat or round tips, an optional winglet blended into the tip or joined to it as a separate
lifting surface), a fuselage (a body of revolution or of elliptic sections) that the wing runs
through, a horizontal tail and a fin. :data:`RANGES` gives every number's range and
:func:`draw_aircraft` draws each uniformly in it. Axes: x aft, y to the right (starboard), z up;
lengths in metres, angles in degrees, thicknesses as shares of the local chord.

:func:`aircraft_surface` builds each part as a closed, outward triangulation (a wing and a
horizontal tail run from tip to tip through the fuselage, the fin's root section lies inside it)
and unites them with manifold3d's boolean union into **one** closed, consistently oriented
surface without self-intersections; its vertices and triangles are put in a canonical order, so
the same parameters give the same mesh bit for bit.

:func:`aircraft_layout` writes a layout of station-given wings (docs/layout.md), as
``shellmesh wings`` does, from the known shape: each wing half (and, with
:attr:`StructureParams.tails`, each horizontal-tail half and the fin) by its span axis, root and tip
stations (the root two element sizes outboard of where it leaves the fuselage, or one size from the
symmetry plane of a wing without one; the tip two sizes inboard of where the tip cap or the
winglet begins, and where the wing is at least 0.6 sizes thick; a surface whose stations would be at
most two sizes apart, too short for a box at that size, gets none), its crank, ``up`` and ``near``;
:class:`StructureParams` sets the ribs, spars and rib orientation. :func:`random_aircraft` draws
both from a seed.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..core.topology import canonical_triangles
from ..families import SKIN
from ..mesh import ShellMesh
from .lofts import (airfoil, body_of_revolution, flat_cap, loft, match_cap, orient_outward, round_cap,
                    section_points)

__all__ = ["AircraftParams", "StructureParams", "RANGES", "CHOICES", "ORIENTATIONS", "draw_aircraft",
           "draw_structure", "aircraft_parts", "aircraft_surface", "aircraft_layout", "random_aircraft",
           "wing_planform", "wing_section"]

#: range of every number of :class:`AircraftParams` that is drawn (uniformly)
RANGES = {
    "root_chord": (1.5, 6.0), "aspect_ratio": (3.0, 10.0), "taper": (0.2, 1.0), "sweep_deg": (0.0, 60.0),
    "outer_sweep_deg": (0.0, 60.0), "dihedral_deg": (-5.0, 10.0), "twist_deg": (-6.0, 4.0),
    "thickness": (0.04, 0.18), "tip_thickness": (0.04, 0.18), "camber": (0.0, 0.04), "camber_pos": (0.2, 0.6),
    "te_thickness": (0.002, 0.02), "tip_bulge": (0.5, 1.0), "crank_eta": (0.25, 0.55), "crank_chord": (0.0, 1.0),
    "winglet_height": (0.08, 0.2), "winglet_cant_deg": (60.0, 90.0), "winglet_sweep_deg": (0.0, 60.0),
    "winglet_taper": (0.3, 0.8), "winglet_chord": (0.5, 1.0), "winglet_thickness": (0.06, 0.12),
    "winglet_radius": (0.2, 0.5),
    "fuselage_radius": (0.06, 0.2), "fuselage_height_ratio": (0.8, 1.25), "nose_length": (1.5, 3.5),
    "wing_x": (0.2, 1.5), "wing_z": (-1.0, 1.0), "tail_length": (2.5, 5.0), "tail_radius": (0.2, 0.5),
    "htail_span": (0.2, 0.4), "htail_chord": (0.25, 0.6), "htail_taper": (0.2, 1.0),
    "htail_sweep_deg": (0.0, 60.0), "htail_dihedral_deg": (-5.0, 10.0), "htail_thickness": (0.04, 0.18),
    "fin_height": (0.12, 0.3), "fin_chord": (0.4, 0.9), "fin_taper": (0.2, 1.0), "fin_sweep_deg": (0.0, 60.0),
    "fin_thickness": (0.04, 0.18),
}
#: the discrete choices and their probabilities
CHOICES = {"tip": (("flat", "round"), (0.5, 0.5)), "blunt_te": ((False, True), (0.5, 0.5)),
           "cranked": ((False, True), (0.5, 0.5)), "winglet": (("none", "blended", "separate"), (0.5, 0.25, 0.25)),
           "fuselage": ((False, True), (0.15, 0.85)), "htail": ((False, True), (0.2, 0.8)),
           "fin": ((False, True), (0.2, 0.8))}
#: rib orientations drawn for a layout
ORIENTATIONS = ("normal_to_spar", "streamwise", "normal_to_midchord")


@dataclass(frozen=True)
class AircraftParams:
    """The shape of a generated aircraft (ranges: :data:`RANGES`; defaults: a small airliner).

    Wing (through the fuselage, from tip to tip; chords along x, sections in planes y = const):

    * ``root_chord`` m, the chord at the centre line; ``aspect_ratio`` span^2 / planform area
      (the whole trapezoid(s), centre part included); ``taper`` tip chord / root chord;
    * ``sweep_deg`` leading-edge sweep (inboard of the crank), ``outer_sweep_deg`` outboard of it;
      ``dihedral_deg``; ``twist_deg`` the tip's incidence (nose up positive), linear from 0 at
      the centre line, about the quarter chord;
    * ``thickness`` / ``tip_thickness`` shares of the chord at the centre line / tip (linear
      between), ``camber`` (share of the chord) at ``camber_pos`` (share of the chord);
    * ``blunt_te`` and ``te_thickness`` (share of the chord): a blunt trailing edge that tall;
    * ``tip`` ``"flat"`` (a planar cap) or ``"round"`` (each chord station's half thickness
      revolved, bulging ``tip_bulge`` times it: 1 a half circle) -- for every free end (the wing,
      tail and fin tips, the winglets);
    * ``cranked``: the trailing edge kinks at ``crank_eta`` of the exposed semi-span (from the
      fuselage side) where the chord is ``taper + crank_chord (1 - taper)`` root chords; the
      leading edge sweeps ``outer_sweep_deg`` outboard of it;
    * ``winglet`` ``"none"``, ``"blended"`` (the wing's sections turn up through a bend of
      radius ``winglet_radius`` x its height, the chord continuous) or ``"separate"`` (a closed
      lifting surface through the tip, from below the wing, root chord ``winglet_chord`` tip
      chords, united with the wing); ``winglet_height`` semi-spans above the tip,
      ``winglet_cant_deg`` from the horizontal, ``winglet_sweep_deg``, ``winglet_taper`` its
      tip chord / root chord, ``winglet_thickness`` its tip thickness (share of its chord).

    Fuselage (``fuselage``; without it a flying wing, no tails):

    * ``fuselage_radius`` semi-spans (raised if needed so the wing's centre section lies within
      80 % of the body's half height; the span follows the aspect ratio, the body radius and the
      crank station from one another), ``fuselage_height_ratio`` height / width (1: a body of
      revolution); ``nose_length`` radii (an elliptic nose), ``wing_x`` root chords of cylinder
      ahead of the wing, ``wing_z`` the wing's height in the body (-1 low ... 1 high: the share of
      the room the centre section leaves), ``tail_length`` radii of tail cone, ``tail_radius``
      the cone's end radius in radii (raised if a tail's root section needs more room; an elliptic
      end cap closes it).

    Tails (trailing edges at 95 % of the tail cone; the cylinder runs on behind the wing until the
    horizontal tail's leading edge is a tenth of the root chord behind the wing's trailing edge):

    * ``htail``: ``htail_span`` exposed semi-span in wing semi-spans, ``htail_chord`` root chord
      in wing root chords, ``htail_taper``, ``htail_sweep_deg``, ``htail_dihedral_deg``,
      ``htail_thickness`` (NACA 00xx);
    * ``fin``: ``fin_height`` above the body in wing semi-spans, ``fin_chord`` root chord in wing
      root chords, ``fin_taper``, ``fin_sweep_deg``, ``fin_thickness``.

    Resolution (not drawn): ``n_chord`` intervals per section side (cosine spaced: the leading-edge
    radius of a 4 % section is resolved), ``n_around`` points around the fuselage, ``n_theta``
    segments across a round tip, ``span_step`` the largest spanwise section spacing in mean chords.
    """

    root_chord: float = 3.0
    aspect_ratio: float = 8.0
    taper: float = 0.35
    sweep_deg: float = 27.0
    outer_sweep_deg: float = 27.0
    dihedral_deg: float = 5.0
    twist_deg: float = -3.0
    thickness: float = 0.14
    tip_thickness: float = 0.10
    camber: float = 0.02
    camber_pos: float = 0.4
    blunt_te: bool = False
    te_thickness: float = 0.005
    tip: str = "round"
    tip_bulge: float = 1.0
    cranked: bool = True
    crank_eta: float = 0.35
    crank_chord: float = 0.5
    winglet: str = "blended"
    winglet_height: float = 0.1
    winglet_cant_deg: float = 80.0
    winglet_sweep_deg: float = 35.0
    winglet_taper: float = 0.5
    winglet_chord: float = 0.8
    winglet_thickness: float = 0.08
    winglet_radius: float = 0.3
    fuselage: bool = True
    fuselage_radius: float = 0.1
    fuselage_height_ratio: float = 1.0
    nose_length: float = 2.0
    wing_x: float = 1.0
    wing_z: float = -0.5
    tail_length: float = 3.5
    tail_radius: float = 0.3
    htail: bool = True
    htail_span: float = 0.3
    htail_chord: float = 0.4
    htail_taper: float = 0.4
    htail_sweep_deg: float = 30.0
    htail_dihedral_deg: float = 5.0
    htail_thickness: float = 0.1
    fin: bool = True
    fin_height: float = 0.2
    fin_chord: float = 0.7
    fin_taper: float = 0.4
    fin_sweep_deg: float = 35.0
    fin_thickness: float = 0.1
    n_chord: int = 64
    n_around: int = 48
    n_theta: int = 8
    span_step: float = 0.3

    def check(self) -> None:
        """Raise ``ValueError`` naming the first parameter outside its range or choices."""
        for name, (lo, hi) in RANGES.items():
            v = getattr(self, name)
            if not (np.isfinite(v) and lo <= v <= hi):
                raise ValueError(f"AircraftParams.{name} = {v!r} is outside its range [{lo:g}, {hi:g}]")
        for name, (opts, _) in CHOICES.items():
            if getattr(self, name) not in opts:
                raise ValueError(f"AircraftParams.{name} = {getattr(self, name)!r}: choose one of {list(opts)}")
        if self.n_chord < 16 or self.n_around < 12 or self.n_theta < 2 or not self.span_step > 0:
            raise ValueError("AircraftParams resolution: need n_chord >= 16, n_around >= 12, n_theta >= 2, "
                             "span_step > 0")

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class StructureParams:
    """The members of a generated layout: ``ribs`` per wing (3-15; a surface too short for them
    at the element size gets as many as fit 1.5 sizes apart), spar ``spars`` chord fractions (1-3),
    rib ``orientation`` (:data:`ORIENTATIONS`), and ``tails``: the horizontal tail and the fin get
    ribs and spars too (else only the wing)."""

    ribs: int = 10
    spars: tuple = (0.15, 0.65)
    orientation: str = "normal_to_spar"
    tails: bool = False

    def to_dict(self) -> dict:
        return asdict(self)


def draw_aircraft(rng) -> AircraftParams:
    """Every number of :data:`RANGES` uniformly in its range and every choice of :data:`CHOICES`
    with its probabilities, from ``rng`` (a seed or a ``numpy.random.Generator``), in a fixed order."""
    rng = np.random.default_rng(rng)
    vals = {name: float(rng.uniform(lo, hi)) for name, (lo, hi) in RANGES.items()}
    for name, (opts, p) in CHOICES.items():
        vals[name] = opts[int(rng.choice(len(opts), p=p))]
    if not vals["cranked"]:
        vals["outer_sweep_deg"] = vals["sweep_deg"]
    return AircraftParams(**vals)


def draw_structure(rng) -> StructureParams:
    """Ribs (3-15), 1-3 spars (one at 25-45 % of the chord; two at 10-25 % and 55-75 %; three at
    10-20 %, 35-50 % and 60-75 %), a rib orientation and whether the tails get members."""
    rng = np.random.default_rng(rng)
    ribs = int(rng.integers(3, 16))
    n = int(rng.integers(1, 4))
    bands = {1: [(0.25, 0.45)], 2: [(0.10, 0.25), (0.55, 0.75)], 3: [(0.10, 0.20), (0.35, 0.50), (0.60, 0.75)]}[n]
    spars = tuple(round(float(rng.uniform(lo, hi)), 4) for lo, hi in bands)
    orientation = ORIENTATIONS[int(rng.integers(len(ORIENTATIONS)))]
    return StructureParams(ribs=ribs, spars=spars, orientation=orientation, tails=bool(rng.random() < 0.5))


# ------------------------------------------------------------------ the shape, derived
@dataclass(frozen=True)
class _Surface:
    """A lifting surface's planform along its own span coordinate ``s`` (0 root ... ``span``)."""

    origin: np.ndarray        # leading edge at s = 0
    axis: np.ndarray          # span direction (normal to the section planes)
    u: np.ndarray             # chord direction before twist
    w: np.ndarray             # thickness direction before twist
    span: float
    s_knots: np.ndarray       # chord, leading-edge offset (along u) and rise (along w) knots
    chords: np.ndarray
    le_off: np.ndarray
    rise: np.ndarray
    twist: tuple              # (at s = 0, at s = span), degrees
    thick: tuple
    camber: float
    camber_pos: float
    te: float

    def at(self, s):
        s = np.asarray(s, float)
        c = np.interp(s, self.s_knots, self.chords)
        le = (self.origin + s[..., None] * self.axis + np.interp(s, self.s_knots, self.le_off)[..., None] * self.u
              + np.interp(s, self.s_knots, self.rise)[..., None] * self.w)
        f = s / self.span
        tw = self.twist[0] + f * (self.twist[1] - self.twist[0])
        t = self.thick[0] + f * (self.thick[1] - self.thick[0])
        return le, c, tw, t


def _twisted(u, w, le, c, tw_deg):
    """Chord and thickness directions turned nose up by ``tw_deg`` about the quarter chord, and the
    leading edge moved with them."""
    a = np.radians(tw_deg)
    u2 = np.cos(a) * u - np.sin(a) * w
    w2 = np.sin(a) * u + np.cos(a) * w
    return le + 0.25 * c * (u - u2), u2, w2


@dataclass(frozen=True)
class _Shape:
    p: AircraftParams
    b: float                  # wing semi-span
    mean_chord: float
    wing: _Surface
    y_body: float             # the fuselage's half width at the wing (0 without)
    y_crank: float | None
    fus: dict | None          # x, r, width, height stations of the body
    htail: _Surface | None
    fin: _Surface | None
    fin_base: float           # height of the body's top along the fin's root (0 without)
    htail_base: float         # half width of the body along the tail's root


def _body_profile(R, Ln, x_cyl_end, Lt, r_end):
    """Stations of the fuselage: elliptic nose, cylinder, smooth tail cone, elliptic end cap."""
    bn = np.linspace(0.0, np.pi / 2, 13)
    xn, rn = Ln * (1 - np.cos(bn)), R * np.sin(bn)
    m = max(2, int(np.ceil((x_cyl_end - Ln) / (0.5 * R))))
    xc = np.linspace(Ln, x_cyl_end, m + 1)[1:]
    xi = np.linspace(0.0, 1.0, 17)[1:]
    xt = x_cyl_end + Lt * xi
    rt = r_end + (R - r_end) * 0.5 * (1 + np.cos(np.pi * xi))
    be = np.linspace(0.0, np.pi / 2, 7)[1:]
    xe, re = xt[-1] + r_end * np.sin(be), r_end * np.cos(be)
    x = np.concatenate([xn, xc, xt, xe])
    r = np.concatenate([rn, np.full(m, R), rt, re])
    r[-1] = 0.0
    return x, r


def _shape(p: AircraftParams) -> _Shape:
    p.check()
    cr, lam = p.root_chord, p.taper
    ct = lam * cr
    ck = (lam + p.crank_chord * (1 - lam)) * cr if p.cranked else None
    # semi-span from the aspect ratio: b = AR * mean chord / 2 (the mean chord depends on eta only)
    H_need = (0.5 * p.thickness + p.camber) * cr / 0.8     # the wing's centre section within 80 % of the body

    def body(b):
        return max(p.fuselage_radius * b, H_need / p.fuselage_height_ratio) if p.fuselage else 0.0

    # the body and the crank station depend on the span, the span on the mean chord (aspect
    # ratio), the mean chord on the crank station: a fixed point (a contraction: converges fast)
    b = p.aspect_ratio * cr * (1 + lam) / 4
    for _ in range(30):
        if not p.cranked:
            break
        R = body(b)
        eta = (R + p.crank_eta * (b - R)) / b
        b = p.aspect_ratio * 0.5 * (eta * (cr + ck) + (1 - eta) * (ck + ct)) / 2
    R = body(b)
    y_body = R
    y_crank = R + p.crank_eta * (b - R) if p.cranked else None
    tl_in, tl_out = np.tan(np.radians(p.sweep_deg)), np.tan(np.radians(p.outer_sweep_deg))
    if p.cranked:
        s_knots = np.array([0.0, y_crank, b])
        chords = np.array([cr, ck, ct])
        le_off = np.array([0.0, y_crank * tl_in, y_crank * tl_in + (b - y_crank) * tl_out])
    else:
        s_knots, chords, le_off = np.array([0.0, b]), np.array([cr, ct]), np.array([0.0, b * tl_in])
    rise = s_knots * np.tan(np.radians(p.dihedral_deg))
    fus = None
    htail = fin = None
    fin_base = htail_base = 0.0
    x_w, z_w = 0.0, 0.0
    if p.fuselage:
        H = p.fuselage_height_ratio * R
        room_hi = 0.8 * H - (0.5 * p.thickness + p.camber) * cr
        room_lo = 0.8 * H - 0.5 * p.thickness * cr
        z_w = p.wing_z * (room_hi if p.wing_z > 0 else room_lo)
        Ln = p.nose_length * R
        x_w = Ln + p.wing_x * cr
        Lt = p.tail_length * R
        c_ht = p.htail_chord * cr
        c_f = p.fin_chord * cr
        # the tails' trailing edges at 95 % of the cone: the cylinder runs on past the wing to
        # leave room for their root chords
        need = max(c_ht if p.htail else 0.0, c_f if p.fin else 0.0) + 0.1 * cr
        aft = max(0.3 * cr, need - 0.95 * Lt)
        if p.htail:     # and the tail's leading edge a tenth of the root chord behind the wing's trailing edge
            yy = np.linspace(0.0, R + p.htail_span * b, 65)
            te_wing = x_w + np.interp(yy, s_knots, le_off) + np.interp(yy, s_knots, chords)
            le_tail = x_w + cr + aft + 0.95 * Lt - c_ht + yy * np.tan(np.radians(p.htail_sweep_deg))
            aft += max(0.0, float((te_wing + 0.1 * cr - le_tail).max()))
        x_cyl = x_w + cr + aft
        r_end = p.tail_radius * R
        for on, c, t in ((p.htail, c_ht, p.htail_thickness), (p.fin, c_f, p.fin_thickness)):
            if on:      # a root section within 80 % of the cone's end radius
                r_end = max(r_end, 0.5 * t * c / (0.8 * min(1.0, p.fuselage_height_ratio)))
        r_end = min(r_end, 0.9 * R)
        x, r = _body_profile(R, Ln, x_cyl, Lt, r_end)
        fus = {"x": x, "r": r, "width": 1.0, "height": p.fuselage_height_ratio, "R": R, "x_te": x_cyl + 0.95 * Lt}

        def r_at(xq):
            return np.interp(xq, x, r)

        x_te = fus["x_te"]
        ex, ez, ey = np.eye(3)[0], np.eye(3)[2], np.eye(3)[1]
        if p.htail:
            x0 = x_te - c_ht
            htail_base = float(r_at(np.linspace(x0, x_te, 33)).max())
            b_ht = htail_base + p.htail_span * b
            tl = np.tan(np.radians(p.htail_sweep_deg))
            htail = _Surface(np.array([x0, 0.0, 0.0]), ey, ex, ez, b_ht, np.array([0.0, b_ht]),
                             np.array([c_ht, p.htail_taper * c_ht]), np.array([0.0, b_ht * tl]),
                             np.array([0.0, b_ht * np.tan(np.radians(p.htail_dihedral_deg))]), (0.0, 0.0),
                             (p.htail_thickness, p.htail_thickness), 0.0, 0.4, p.te_thickness if p.blunt_te else 0.0)
        if p.fin:
            x0 = x_te - c_f
            tl = np.tan(np.radians(p.fin_sweep_deg))
            top = H
            fin_base = float(top)
            h_f = top + p.fin_height * b
            # sections in planes z = const, thickness along -y (the chord plane x-z)
            fin = _Surface(np.array([x0, 0.0, 0.0]), ez, ex, -ey, h_f, np.array([0.0, h_f]),
                           np.array([c_f, p.fin_taper * c_f]), np.array([0.0, h_f * tl]), np.array([0.0, 0.0]),
                           (0.0, 0.0), (p.fin_thickness, p.fin_thickness), 0.0, 0.4,
                           p.te_thickness if p.blunt_te else 0.0)
    wing = _Surface(np.array([x_w, 0.0, z_w]), np.eye(3)[1], np.eye(3)[0], np.eye(3)[2], b, s_knots, chords,
                    le_off, rise, (0.0, p.twist_deg), (p.thickness, p.tip_thickness), p.camber, p.camber_pos,
                    p.te_thickness if p.blunt_te else 0.0)
    area2 = np.trapezoid(chords, s_knots) if hasattr(np, "trapezoid") else np.trapz(chords, s_knots)
    return _Shape(p, b, float(area2 / b), wing, y_body, y_crank, fus, htail, fin, fin_base, htail_base)


def wing_planform(params: AircraftParams) -> dict:
    """The wing's derived sizes: ``semi_span``, ``mean_chord`` (planform area / span),
    ``root_chord``, ``tip_chord``, ``body_half_width`` (0 without a fuselage), ``crank`` (its
    station, or None)."""
    sh = _shape(params)
    return {"semi_span": sh.b, "mean_chord": sh.mean_chord, "root_chord": float(sh.wing.chords[0]),
            "tip_chord": float(sh.wing.chords[-1]), "body_half_width": sh.y_body, "crank": sh.y_crank}


def wing_section(params: AircraftParams, y: float) -> dict:
    """The wing's section at station ``y`` (either side, inside the wing's span): ``chord`` (m),
    ``thickness`` (the NACA thickness, share of the chord), ``depth`` (m: the largest distance
    between the upper and lower surface across the chord, a blunt trailing edge's opening
    included), ``twist_deg``, ``leading_edge`` (the point, before the twist turns the section
    about its quarter chord)."""
    sh = _shape(params)
    w = sh.wing
    le, c, tw, t = w.at(abs(float(y)))
    le = le.copy()
    le[1] = float(y)
    af = airfoil(max(params.n_chord, 256), t, w.camber, w.camber_pos, w.te)
    return {"chord": float(c), "thickness": float(t), "depth": float((af.upper - af.lower).max() * c),
            "twist_deg": float(tw), "leading_edge": le}


# ------------------------------------------------------------------ parts
def _stations(span: float, knots, step: float) -> np.ndarray:
    """Section stations from 0 to ``span``: every knot, at most ``step`` apart."""
    k = np.unique(np.clip(np.asarray(knots, float), 0.0, span))
    out = [k[:1]]
    for a, b in zip(k[:-1], k[1:]):
        n = max(1, int(np.ceil((b - a) / step)))
        out.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(out)


def _rings(surf: _Surface, s, p: AircraftParams, af_n: int):
    le, c, tw, t = surf.at(s)
    rings = []
    for i in range(len(s)):
        af = airfoil(af_n, t[i], surf.camber, surf.camber_pos, surf.te)
        le2, u2, w2 = _twisted(surf.u, surf.w, le[i], c[i], tw[i])
        rings.append(section_points(af, le2, u2, w2, c[i]))
    return np.array(rings), af


def _plane_coords(ring):
    """2-D coordinates of a planar ring in its own plane (orthonormal axes, so a triangulation of
    them is valid in space)."""
    c = ring - ring.mean(0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    return c @ vt[:2].T


def _close(rings, af, ends, p: AircraftParams):
    """A closed, outward triangulation of the loft through ``rings``; ``ends`` lists for its first
    (0) and last (-1) section the outward direction and the cap ("flat" or "round")."""
    P = rings.reshape(-1, 3)
    T = loft(rings)
    k = rings.shape[1]
    caps, extra = [], []
    n_pts = len(P)
    for which, out, tip in ends:
        off = 0 if which == 0 else (len(rings) - 1) * k
        ring = rings[which]
        if tip == "flat":
            cap = flat_cap(_plane_coords(ring), off)
        else:
            newP, cap = round_cap(af, ring, off, out, n_pts, p.n_theta, p.tip_bulge)
            extra.append(newP)
            n_pts += len(newP)
        caps.append(match_cap(cap, T))
    P = np.vstack([P] + extra)
    T = np.vstack([T] + caps)
    return P, orient_outward(P, T)


def _mirror_rings(rings):
    """Rings of the left half (y mirrored), from the tip to the centre line."""
    m = rings[::-1].copy()
    m[..., 1] *= -1.0
    return m


def _winglet_rings(sh: _Shape, p: AircraftParams, n: int, tip_ring: np.ndarray):
    """Sections of a blended winglet past the wing tip (right side): a bend from the dihedral to
    the cant angle, then a straight part; the chord tapers, the thickness and camber change
    linearly over its length."""
    w = sh.wing
    le0, c0, tw0, t0 = w.at(w.span)
    gam, cant = np.radians(p.dihedral_deg), np.radians(p.winglet_cant_deg)
    h = p.winglet_height * sh.b
    # the bend's centre lies on the upper side: every point of the (twisted) tip section, the
    # trailing edge of a twisted one too, stays on this side of it
    n0 = np.array([0.0, -np.sin(gam), np.cos(gam)])
    rho = max(p.winglet_radius * h, 1.5 * float(((tip_ring - le0) @ n0).max()))
    na, ns = 8, 8
    alpha = np.linspace(gam, cant, na + 1)[1:]
    q = le0 + rho * np.array([0.0, -np.sin(gam), np.cos(gam)])
    pts = [q + rho * np.stack([np.zeros_like(alpha), np.sin(alpha), -np.cos(alpha)], 1)]
    arc = rho * (alpha - gam)
    end = pts[0][-1]
    st = np.linspace(0.0, h, ns + 1)[1:]
    pts.append(end + st[:, None] * np.array([0.0, np.cos(cant), np.sin(cant)]))
    path = np.vstack(pts)
    length = np.concatenate([arc, arc[-1] + st])
    f = length / length[-1]
    phi = np.concatenate([(alpha - gam) / (cant - gam) * cant, np.full(ns, cant)])
    sweep = np.tan(np.radians(p.winglet_sweep_deg))
    chord = c0 * (1 + f * (p.winglet_taper - 1))
    thick = t0 + f * (p.winglet_thickness - t0)
    rings = []
    for i in range(len(path)):
        le = path[i] + np.array([length[i] * sweep, 0.0, 0.0])
        u = np.array([1.0, 0.0, 0.0])
        wv = np.array([0.0, -np.sin(phi[i]), np.cos(phi[i])])
        af = airfoil(n, thick[i], w.camber * (1 - f[i]), w.camber_pos, w.te)
        le2, u2, w2 = _twisted(u, wv, le, chord[i], tw0)
        rings.append(section_points(af, le2, u2, w2, chord[i]))
    return np.array(rings), af, np.array([0.0, np.cos(cant), np.sin(cant)])


def _separate_winglet(sh: _Shape, p: AircraftParams, n: int):
    """A closed winglet (right side) through the wing tip: from below the wing to
    ``winglet_height`` above it, its chord plane leaning out at the cant angle."""
    w = sh.wing
    le0, c0, tw0, t0 = w.at(w.span)
    cant = np.radians(p.winglet_cant_deg)
    a = np.array([0.0, np.cos(cant), np.sin(cant)])
    wv = np.array([0.0, -np.sin(cant), np.cos(cant)])
    h = p.winglet_height * sh.b
    cw = p.winglet_chord * c0
    below = max(0.25 * h, 1.5 * (0.5 * t0 + w.camber) * c0 / np.sin(cant))
    span = below + h
    thick_root = max(p.winglet_thickness, 0.06)
    # mid plane a quarter of its thickness inboard of the tip; trailing edge 5 % of the tip chord
    # aft of the wing's
    origin = (np.array([le0[0] + c0 - cw + 0.05 * c0, le0[1], le0[2]]) - below * a
              + 0.25 * thick_root * cw * wv)
    ex = np.eye(3)[0]
    surf = _Surface(origin, a, ex, wv, span, np.array([0.0, span]), np.array([cw, p.winglet_taper * cw]),
                    np.array([0.0, span * np.tan(np.radians(p.winglet_sweep_deg))]), np.array([0.0, 0.0]),
                    (tw0, tw0), (thick_root, p.winglet_thickness), 0.0, 0.4, w.te)
    s = _stations(span, [0.0, span], span / 8)
    rings, af = _rings(surf, s, p, n)
    return _close(rings, af, [(0, -a, p.tip), (-1, a, p.tip)], p)


def aircraft_parts(params: AircraftParams) -> dict:
    """Each part as a closed, outward ``(points, triangles)``: ``wing`` (tip to tip, with blended
    winglets), ``fuselage``, ``htail``, ``fin``, ``right_winglet``/``left_winglet`` (separate)."""
    sh = _shape(params)
    p, n = params, params.n_chord
    out = {}
    w = sh.wing
    s = _stations(w.span, list(w.s_knots) + ([sh.y_body] if sh.y_body else []), p.span_step * sh.mean_chord)
    right, af = _rings(w, s, p, n)
    tip_out = np.array([0.0, 1.0, 0.0])
    if p.winglet == "blended":
        extra, af, tip_out = _winglet_rings(sh, p, n, right[-1])
        right = np.concatenate([right, extra])
    rings = np.concatenate([_mirror_rings(right)[:-1], right])
    left_out = tip_out * np.array([1.0, -1.0, 1.0])
    out["wing"] = _close(rings, af, [(0, left_out, p.tip), (-1, tip_out, p.tip)], p)
    if p.winglet == "separate":
        P, T = _separate_winglet(sh, p, n)
        out["right_winglet"] = (P, T)
        Pm = P * np.array([1.0, -1.0, 1.0])
        out["left_winglet"] = (Pm, T[:, ::-1].copy())
    if sh.fus is not None:
        f = sh.fus
        out["fuselage"] = body_of_revolution(f["x"], f["r"], np.zeros_like(f["x"]), p.n_around, f["width"],
                                             f["height"])
    if sh.htail is not None:
        ht = sh.htail
        s = _stations(ht.span, [0.0, sh.htail_base, ht.span], p.span_step * 0.5 * ht.chords.sum())
        right, af = _rings(ht, s, p, n)
        rings = np.concatenate([_mirror_rings(right)[:-1], right])
        out["htail"] = _close(rings, af, [(0, [0.0, -1.0, 0.0], p.tip), (-1, [0.0, 1.0, 0.0], p.tip)], p)
    if sh.fin is not None:
        fn = sh.fin
        s = _stations(fn.span, [0.0, sh.fin_base, fn.span], p.span_step * 0.5 * fn.chords.sum())
        rings, af = _rings(fn, s, p, n)
        # the root section lies inside the fuselage (the union removes it): a flat cap
        out["fin"] = _close(rings, af, [(0, [0.0, 0.0, -1.0], "flat"), (-1, [0.0, 0.0, 1.0], p.tip)], p)
    return out


def aircraft_surface(params: AircraftParams) -> ShellMesh:
    """The aircraft's skin: its parts (:func:`aircraft_parts`) united into one closed,
    consistently oriented (outward) triangulation without self-intersections (manifold3d),
    in canonical order; one component, ``skin``."""
    import manifold3d as m3

    parts = aircraft_parts(params)
    mans = []
    for name, (P, T) in parts.items():
        m = m3.Manifold(m3.Mesh64(np.ascontiguousarray(P, np.float64), np.ascontiguousarray(T, np.uint64)))
        if m.status() != m3.Error.NoError:
            raise RuntimeError(f"generated part {name!r} is not a closed manifold ({m.status()}): a generator bug")
        mans.append(m)
    U = mans[0] if len(mans) == 1 else m3.Manifold.batch_boolean(mans, m3.OpType.Add)
    out = U.to_mesh64()
    V = np.asarray(out.vert_properties, np.float64)[:, :3]
    T = np.asarray(out.tri_verts, np.int64).reshape(-1, 3)
    V, T, _ = canonical_triangles(V, T)
    return ShellMesh(V, T, np.zeros(len(T), np.int32), [SKIN])


# ------------------------------------------------------------------ layout
#: a wing's root rib lies this many element sizes outboard of where it leaves the fuselage (one
#: size from the symmetry plane without one) and its tip rib this many inboard of its tip cap or
#: winglet (as ``shellmesh wings`` places them)
STATION_MARGIN = 2.0
#: the tip rib lies where the wing is at least this many element sizes thick
TIP_THICKNESS = 0.6
#: with an element size, ribs at least this many sizes apart (fewer ribs than asked on a short surface)
RIB_GAP = 1.5
#: a surface whose root and tip stations are at most this many element sizes apart is too short for
#: a wing box at that size and gets no entry (as ``shellmesh wings`` writes none for it)
MIN_BOX = 2.0


def _station_entry(name, surf: _Surface, sign: float, s_root: float, s_end: float, h: float,
                   st: StructureParams, up, cranks=()) -> dict | None:
    """A station-given wing entry for ``surf`` between ``s_root`` and the tip station: two sizes
    inboard of ``s_end`` and where the surface is at least :data:`TIP_THICKNESS` sizes thick;
    None when those stations are at most :data:`MIN_BOX` sizes apart."""
    s_tip = s_end - STATION_MARGIN * h
    grid = np.linspace(s_root, s_tip, 257)
    _, c, _, t = surf.at(grid)
    thick = grid[t * c >= TIP_THICKNESS * h]
    if len(thick):
        s_tip = float(thick.max())
    if s_tip - s_root <= MIN_BOX * h:
        return None
    ax = int(np.argmax(np.abs(surf.axis)))
    base = float(surf.origin[ax])
    le, c, tw, t = surf.at(s_root)
    le2, u2, w2 = _twisted(surf.u, surf.w, le, c, tw)
    af = airfoil(16, t, surf.camber, surf.camber_pos, surf.te)
    i = int(np.argmin(np.abs(af.x - 0.35)))
    near = le2 + c * (af.x[i] * u2 + 0.5 * (af.upper[i] + af.lower[i]) * w2)
    if ax == 1:
        near[1] *= sign
    ribs = st.ribs if h is None else min(st.ribs, max(2, int(abs(s_tip - s_root) / (RIB_GAP * h)) + 1))

    def r(v):
        return round(float(v), 9) + 0.0

    entry = {"name": name, "axis": [r(v) for v in surf.axis], "root": r(sign * (base + s_root)),
             "tip": r(sign * (base + s_tip)), "up": [r(v) for v in up], "near": [r(v) for v in near],
             "ribs": {"count": int(ribs), "orientation": st.orientation},
             "spars": {"chord_fractions": [float(f) for f in st.spars]}}
    cr = [r(sign * (base + c)) for c in cranks if s_root < c < s_tip]
    if cr:
        entry["cranks"] = cr
    return entry


def aircraft_layout(params: AircraftParams, structure: StructureParams | None = None,
                    size: float | None = None) -> dict:
    """A layout of station-given wings for :func:`aircraft_surface` (module docstring): the wing
    halves ``right_wing`` and ``left_wing`` (span axis y), with ``structure.tails`` also
    ``right_htail``, ``left_htail`` (y) and ``fin`` (z); stations fitted to the element ``size``
    (without it: a hundredth of each surface's span); a surface too short for a box at that size
    (:data:`MIN_BOX`) has no entry."""
    st = structure or StructureParams()
    sh = _shape(params)
    p = params
    w = sh.wing
    h = size if size is not None else w.span / 100.0
    s_root = sh.y_body + STATION_MARGIN * h if p.fuselage else h
    s_end = w.span
    if p.winglet == "separate":
        P, _ = _separate_winglet(sh, p, 16)
        s_end = min(s_end, float(P[:, 1].min()))
    le_r, _, tw_r, _ = w.at(s_root)
    tau = np.radians(0.5 * (tw_r + w.at(s_end)[2]))
    up = [np.sin(tau), 0.0, np.cos(tau)]
    cranks = [sh.y_crank] if sh.y_crank is not None else []
    wings = [_station_entry(f"{side}_wing", w, sign, s_root, s_end, h, st, up, cranks)
             for side, sign in (("right", 1.0), ("left", -1.0))]
    if st.tails and sh.htail is not None:
        ht = sh.htail
        hh = size if size is not None else ht.span / 100.0
        wings += [_station_entry(f"{side}_htail", ht, sign, sh.htail_base + STATION_MARGIN * hh, ht.span, hh, st,
                                 [0.0, 0.0, 1.0]) for side, sign in (("right", 1.0), ("left", -1.0))]
    if st.tails and sh.fin is not None:
        fn = sh.fin
        hf = size if size is not None else fn.span / 100.0
        wings.append(_station_entry("fin", fn, 1.0, sh.fin_base + STATION_MARGIN * hf, fn.span, hf, st,
                                    [0.0, 1.0, 0.0]))
    return {"wings": [w for w in wings if w is not None]}


def random_aircraft(seed=None, size: float | None = None):
    """A random aircraft and its layout: ``(mesh, layout)`` from ``seed`` (an int, a sequence of
    ints or a ``numpy.random.Generator``): :func:`draw_aircraft` then :func:`draw_structure` from
    the same generator, :func:`aircraft_surface`, :func:`aircraft_layout` at ``size``."""
    rng = np.random.default_rng(seed)
    params = draw_aircraft(rng)
    structure = draw_structure(rng)
    return aircraft_surface(params), aircraft_layout(params, structure, size)
