"""Generated aircraft surfaces: the bundled default wing and wings for tests.

:func:`naca_wing` builds a closed, consistently oriented triangulation of a tapered,
swept wing with NACA 4-digit sections and flat end caps, plus the matching wing-box
corner points for a layout (:func:`naca_wing_layout`). It is the bundled default
geometry of ``shellmesh demo`` (no licence attached: we generate it) and a source of
wings of any proportions for tests.
"""
from __future__ import annotations

import numpy as np

from ..errors import SizeError
from ..families import SKIN
from ..mesh import ShellMesh

__all__ = ["naca4", "naca_wing", "naca_wing_layout", "DEFAULT_WING"]

#: Parameters of the bundled default wing (metres): a small transport-like semi-span.
DEFAULT_WING = dict(span=6.0, root_chord=2.0, tip_chord=1.0, sweep_deg=10.0, dihedral_deg=3.0,
                    naca="2412", n_chord=48, n_span=40)


def naca4(code: str, n: int) -> np.ndarray:
    """Closed NACA 4-digit airfoil, unit chord, ``2n`` points counter-clockwise starting at the
    trailing edge along the lower surface (x, z). Cosine spacing, sharp trailing edge."""
    if len(code) != 4 or not code.isdigit():
        raise SizeError(f"NACA code must have 4 digits, got {code!r}; use e.g. '2412'")
    m, p, t = int(code[0]) / 100, int(code[1]) / 10, int(code[2:]) / 100
    beta = np.linspace(0.0, np.pi, n + 1)
    x = 0.5 * (1 - np.cos(beta))
    yt = 5 * t * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4)
    if m > 0 and p > 0:
        yc = np.where(x < p, m / p**2 * (2 * p * x - x**2), m / (1 - p) ** 2 * ((1 - 2 * p) + 2 * p * x - x**2))
        dyc = np.where(x < p, 2 * m / p**2 * (p - x), 2 * m / (1 - p) ** 2 * (p - x))
    else:
        yc = np.zeros_like(x)
        dyc = np.zeros_like(x)
    th = np.arctan(dyc)
    xu, zu = x - yt * np.sin(th), yc + yt * np.cos(th)
    xl, zl = x + yt * np.sin(th), yc - yt * np.cos(th)
    # lower surface from TE to LE, then upper from LE (exclusive) to TE (exclusive: TE shared)
    lower = np.stack([xl[::-1], zl[::-1]], 1)            # TE -> LE, n+1 points
    upper = np.stack([xu[1:-1], zu[1:-1]], 1)            # after LE ... before TE
    pts = np.vstack([lower, upper])
    pts[0] = [1.0, 0.0] if m == 0 else pts[0]
    return pts


def _cap(loop_xyz: np.ndarray, loop_2d: np.ndarray, flip: bool, offset: int):
    import triangle as tr

    n = len(loop_2d)
    seg = np.stack([np.arange(n), (np.arange(n) + 1) % n], 1)
    t = tr.triangulate({"vertices": loop_2d, "segments": seg}, "pQ")
    if len(t["vertices"]) != n:
        raise RuntimeError("end-cap triangulation added points")  # 'p' without 'q'/'a' never does
    f = t["triangles"]
    if flip:
        f = f[:, ::-1]
    return f + offset


def naca_wing(span: float = DEFAULT_WING["span"], root_chord: float = DEFAULT_WING["root_chord"],
              tip_chord: float = DEFAULT_WING["tip_chord"], sweep_deg: float = DEFAULT_WING["sweep_deg"],
              dihedral_deg: float = DEFAULT_WING["dihedral_deg"], naca: str = DEFAULT_WING["naca"],
              n_chord: int = DEFAULT_WING["n_chord"], n_span: int = DEFAULT_WING["n_span"],
              y0: float = 0.0, twist_deg: float = 0.0, crank=None, te_thickness: float = 0.0) -> ShellMesh:
    """Closed triangulated semi-span wing: x aft, y spanwise from ``y0`` to ``y0 + span``, z up.

    Leading-edge sweep ``sweep_deg``, linear taper, dihedral ``dihedral_deg``; ``n_chord``
    points per airfoil side (cosine spaced) and ``n_span`` sections. Faces are oriented
    with outward normals; one component named ``skin``. Options for tests of measured
    planforms (all off by default): ``twist_deg`` the tip's twist (linear from 0 at the root;
    each section turned about its leading edge, positive nose up), ``crank`` a pair
    ``(span fraction, chord)``: the chord runs linearly from the root to that station and on to
    the tip (a kink of the trailing edge; a section lies at the crank), ``te_thickness`` a
    blunt trailing edge of that share of the chord (the sections opened linearly from the
    leading edge, the base a straight segment).
    """
    for name, v in [("span", span), ("root_chord", root_chord), ("tip_chord", tip_chord)]:
        if not np.isfinite(v) or v <= 0:
            raise SizeError(f"{name} must be a positive length, got {v}")
    if n_chord < 4 or n_span < 2:
        raise SizeError(f"need n_chord >= 4 and n_span >= 2, got {n_chord}, {n_span}")
    af = naca4(naca, n_chord)                      # (2n, 2), closed loop
    if te_thickness > 0:                           # lower TE..LE (n+1 points), upper side, upper TE
        te_z = af[0, 1]
        sign = np.where(np.arange(len(af)) <= n_chord, -1.0, 1.0)
        af = af + np.stack([np.zeros(len(af)), 0.5 * te_thickness * af[:, 0] * sign], 1)
        af = np.vstack([af, [[1.0, te_z + 0.5 * te_thickness]]])
    k = len(af)
    s = np.linspace(0.0, 1.0, n_span)
    if crank is not None:
        s = np.unique(np.concatenate([s, [float(crank[0])]]))
        chord = np.interp(s, [0.0, float(crank[0]), 1.0], [root_chord, float(crank[1]), tip_chord])
    else:
        chord = root_chord + (tip_chord - root_chord) * s
    n_span = len(s)
    y = y0 + span * s
    x_le = span * s * np.tan(np.radians(sweep_deg))
    z_le = span * s * np.tan(np.radians(dihedral_deg))
    X = x_le[:, None] + chord[:, None] * af[None, :, 0]
    Z = z_le[:, None] + chord[:, None] * af[None, :, 1]
    if twist_deg != 0:                             # turn each section about its leading edge
        th = np.radians(twist_deg) * s[:, None]
        dx, dz = X - x_le[:, None], Z - z_le[:, None]
        X = x_le[:, None] + dx * np.cos(th) + dz * np.sin(th)
        Z = z_le[:, None] - dx * np.sin(th) + dz * np.cos(th)
    Y = np.broadcast_to(y[:, None], X.shape)
    pts = np.stack([X, Y, Z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_span - 1), np.arange(k), indexing="ij")
    a = (i * k + j).ravel()
    b = (i * k + (j + 1) % k).ravel()
    c = b + k
    d = a + k
    # airfoil runs counter-clockwise seen from +y (x right, z up => looking from -y...) ; orient outward below
    tris = np.vstack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    root = _cap(pts[:k], af, flip=False, offset=0)
    tip = _cap(pts[-k:], af, flip=True, offset=(n_span - 1) * k)
    faces = np.vstack([tris, root, tip])
    m = ShellMesh(pts, faces, np.zeros(len(faces), np.int32), [SKIN])
    # orient outward: signed volume must be positive
    v = m.points[m.faces[:, :3]]
    vol = np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0
    if vol < 0:
        m = ShellMesh(pts, faces[:, ::-1], m.component, [SKIN])
    return m


def naca_wing_layout(span: float = DEFAULT_WING["span"], root_chord: float = DEFAULT_WING["root_chord"],
                     tip_chord: float = DEFAULT_WING["tip_chord"], sweep_deg: float = DEFAULT_WING["sweep_deg"],
                     dihedral_deg: float = DEFAULT_WING["dihedral_deg"], y0: float = 0.0,
                     inset: float = 0.03, ribs: int = 8, spars=(0.15, 0.65), name: str = "wing") -> dict:
    """A layout dict for :func:`naca_wing` with the same parameters: the wing box runs from
    ``inset`` to ``1 - inset`` of the span (so the root and tip ribs are not the end caps),
    ``ribs`` evenly spaced ribs and spars at the given chord fractions."""
    def chord_point(s, frac):
        c = root_chord + (tip_chord - root_chord) * s
        x = span * s * np.tan(np.radians(sweep_deg)) + frac * c
        z = span * s * np.tan(np.radians(dihedral_deg))
        return [float(x), float(y0 + span * s), float(z)]

    s0, s1 = inset, 1.0 - inset
    up = [0.0, -np.sin(np.radians(dihedral_deg)), np.cos(np.radians(dihedral_deg))]
    return {"wings": [{"name": name, "root_le": chord_point(s0, 0.0), "root_te": chord_point(s0, 1.0),
                       "tip_le": chord_point(s1, 0.0), "tip_te": chord_point(s1, 1.0),
                       "up": [float(u) for u in up],
                       "ribs": {"count": int(ribs)}, "spars": {"chord_fractions": [float(f) for f in spars]}}]}
