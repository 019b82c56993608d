"""Known answers of the NACA 0012 wing box meshed by the pipeline (issue 41, item 5).

The straight wing ``naca_wing(span=6, root_chord=1, tip_chord=1, sweep=0, dihedral=0, "0012")``
with ``naca_wing_layout(..., ribs=8, spars=[0.15, 0.65])``, t = 2 mm, E = 70 GPa, root clamped
(rule ``"root"``), a pure bending moment M about the chordwise axis x applied at the tip.

Beam theory, computed from the section (nothing hard-coded): the skin's
``I_s = t * oint (z - z_c)^2 ds`` over the NACA 0012 outline (sampled finely), the box's
``I_b = I_s + sum t h^3 / 12 + t h (z_web - z_c)^2`` with the spar webs (h = the section height at
x = 0.15c and 0.65c). The spars run from the root rib to the tip rib (y = 0.18 .. 5.82 m), so the
rotation at station y is ``theta(y) = (M / E) int_0^y dy / I(y)`` with I = I_s outside the box.
The FE rotation at a station is the least-squares slope dv/dz of the spanwise displacement of the
section's nodes (v = a + b x + theta z).

Mass: the skin area of the mesh against the input triangulation's area (what the mesh
discretises), the member area against the ribs and spar webs of the input's sections.
"""
import numpy as np
import pytest

from shellmesh_mdao.analysis import analyse_shell, family_areas
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.geometry.naca import naca4

from conftest import needs_ccx

SPAN, CHORD, CODE, SPARS, RIBS = 6.0, 1.0, "0012", (0.15, 0.65), 8
T, E, NU, M = 0.002, 70.0e9, 0.33, 1000.0
GEOMETRY = dict(span=SPAN, root_chord=CHORD, tip_chord=CHORD, sweep_deg=0.0, dihedral_deg=0.0)
N_CHORD = 48                               # naca_wing's default airfoil points per side


# --------------------------------------------------------------------------- beam theory
def contour_inertia(loop, t=T):
    """Closed polygon (k, 2) of (x, z): length, length-weighted centroid z_c and
    ``t * oint (z - z_c)^2 ds`` (exact on each straight segment)."""
    a, b = loop, np.roll(loop, -1, 0)
    ds = np.linalg.norm(b - a, axis=1)
    zc = float((ds * (a[:, 1] + b[:, 1]) / 2).sum() / ds.sum())
    za, zb = a[:, 1] - zc, b[:, 1] - zc
    return float(ds.sum()), zc, float(t * (ds * (za * za + za * zb + zb * zb) / 3).sum())


def section_height(loop, x):
    """Upper minus lower z of a closed (x, z) airfoil loop at chord station x, and its mid z."""
    up = loop[loop[:, 1] >= 0]
    lo = loop[loop[:, 1] <= 0]
    zu = np.interp(x, *up[np.argsort(up[:, 0])].T)
    zl = np.interp(x, *lo[np.argsort(lo[:, 0])].T)
    return zu - zl, (zu + zl) / 2


def wing_box_theory(n_points=20000):
    """(I_s, I_b, z_c, theta(y)) for the wing box: skin-only outside the spars' span."""
    loop = naca4(CODE, n_points) * CHORD
    _, zc, i_skin = contour_inertia(loop)
    i_box = i_skin
    for f in SPARS:
        h, zm = section_height(loop, f * CHORD)
        i_box += T * h ** 3 / 12 + T * h * (zm - zc) ** 2
    lay = naca_wing_layout(**GEOMETRY, ribs=RIBS, spars=list(SPARS))["wings"][0]
    y0, y1 = lay["root_le"][1], lay["tip_le"][1]

    def theta(y):
        y = np.asarray(y, dtype=np.float64)
        return M / E * ((np.minimum(y, y0) / i_skin) + (np.clip(y, y0, y1) - y0) / i_box
                        + np.maximum(y - y1, 0.0) / i_skin)

    return i_skin, i_box, zc, theta


def input_member_area():
    """Ribs (spar to spar) and spar webs (root rib to tip rib) cut from the input's sections
    (the 48-point airfoil naca_wing is built from)."""
    loop = naca4(CODE, N_CHORD) * CHORD
    x = np.linspace(SPARS[0], SPARS[1], 20001) * CHORD
    rib = np.trapezoid(section_height(loop, x)[0], x) if hasattr(np, "trapezoid") else \
        np.trapz(section_height(loop, x)[0], x)
    lay = naca_wing_layout(**GEOMETRY, ribs=RIBS, spars=list(SPARS))["wings"][0]
    box = lay["tip_le"][1] - lay["root_le"][1]
    return RIBS * rib + box * sum(section_height(loop, f * CHORD)[0] for f in SPARS)


# --------------------------------------------------------------------------- FE model
def tip_moment(mesh, moment=M, t=T, span=SPAN):
    """Spanwise nodal forces on the tip section (the nodes of the skin's edge on the tip cap):
    the consistent loads of a linear stress ``sigma = a + b z + c x`` along the ring's edges,
    with a, b, c solved so the forces sum to zero, their moment about x is ``moment`` and about
    z is zero. Returns (node ids, (k, 3) forces)."""
    P, F = mesh.points, mesh.faces
    on_tip = np.abs(P[:, 1] - span) < 1e-9 * span
    valid = F >= 0
    nv = valid.sum(1)
    lateral = ~np.where(valid, on_tip[np.where(valid, F, 0)], True).all(1)   # a node off the tip plane
    edges = []
    for k in (3, 4):
        f = F[lateral & (nv == k)][:, :k]
        e = np.stack([f, np.roll(f, -1, 1)], 2).reshape(-1, 2)
        edges.append(e[on_tip[e].all(1)])
    e = np.unique(np.sort(np.vstack(edges), 1), axis=0)
    ids = np.unique(e)
    i, j = np.searchsorted(ids, e).T
    ln = np.linalg.norm(P[e[:, 0]] - P[e[:, 1]], axis=1)
    basis = np.stack([np.ones(len(ids)), P[ids, 2], P[ids, 0]], 1)
    # consistent load of a linear edge stress: F_i = t l (2 s_i + s_j) / 6
    per_coef = np.zeros((len(ids), 3))
    np.add.at(per_coef, i, (t * ln / 6)[:, None] * (2 * basis[i] + basis[j]))
    np.add.at(per_coef, j, (t * ln / 6)[:, None] * (basis[i] + 2 * basis[j]))
    sums = np.stack([per_coef.sum(0), P[ids, 2] @ per_coef, P[ids, 0] @ per_coef])
    coef = np.linalg.solve(sums, [0.0, moment, 0.0])
    f = np.zeros((len(ids), 3))
    f[:, 1] = per_coef @ coef
    return ids, f


def section_rotation(points, v, nodes):
    """Least-squares dv/dz of the spanwise displacement v over ``nodes`` (v = a + b x + c z)."""
    X = np.stack([np.ones(len(nodes)), points[nodes, 0], points[nodes, 2]], 1)
    return float(np.linalg.lstsq(X, v[nodes], rcond=None)[0][2])


def is_skin(names):
    return np.array([n == "skin" or "_skin/" in n for n in names])


_MESHES: dict = {}


def wing_mesh(size):
    if size not in _MESHES:
        from shellmesh_mdao.pipeline import run_pipeline

        surface = naca_wing(**GEOMETRY, naca=CODE)
        layout = naca_wing_layout(**GEOMETRY, ribs=RIBS, spars=list(SPARS))
        _MESHES[size] = (surface, layout, run_pipeline(surface, layout, size, progress=False).mesh)
    return _MESHES[size]


# --------------------------------------------------------------------------- tests
def test_beam_theory_section():
    """The section figures the known answer rests on: the polygon of the input (48 points a side)
    is within 0.2 % of the exact outline; the webs add their t h^3 / 12."""
    i_s, i_b, zc, theta = wing_box_theory()
    assert abs(zc) < 1e-12                                   # symmetric section
    assert contour_inertia(naca4(CODE, N_CHORD))[2] == pytest.approx(i_s, rel=2e-3)
    h = [section_height(naca4(CODE, 20000), f)[0] for f in SPARS]
    assert i_b - i_s == pytest.approx(T * (h[0] ** 3 + h[1] ** 3) / 12, rel=1e-12)
    assert theta(SPAN) > M * SPAN / (E * i_b)                # skin-only ends are more flexible


@pytest.mark.parametrize("size", [0.1, pytest.param(0.2, marks=pytest.mark.slow)])
@needs_ccx
def test_pure_tip_moment_rotation_matches_beam_theory(size):
    """Rotation dv/dz under a pure tip moment within 2 % of beam theory at chord/10 and chord/5:
    at every rib (root rib excepted: its rotation is the clamped stub's, a few per mille of the
    tip's) and at the tip section."""
    _, layout, mesh = wing_mesh(size)
    ids, f = tip_moment(mesh)
    P = mesh.points
    assert abs(f[:, 1].sum()) < 1e-9 * M
    assert (f[:, 1] * P[ids, 2]).sum() == pytest.approx(M, rel=1e-12)
    assert abs((f[:, 1] * P[ids, 0]).sum()) < 1e-9 * M
    r = analyse_shell(mesh, T, material={"E": E, "nu": NU}, layout=layout, nodal_forces=(ids, f), tip_nodes=ids)
    assert np.all(P[r.clamped, 1] <= 1e-4 * mesh.diagonal)       # the root section (rule 'root')
    v = r.displacement[:, 1]
    _, _, _, theta = wing_box_theory()
    ratios = {}
    for k, name in enumerate(mesh.component_names):
        if "/rib_" in name and not name.endswith("/rib_0"):
            fam = mesh.faces[mesh.component == k]
            nodes = np.unique(fam[fam >= 0])
            ratios[name] = section_rotation(P, v, nodes) / float(theta(P[nodes, 1].mean()))
    ratios["tip"] = section_rotation(P, v, ids) / float(theta(SPAN))
    assert len(ratios) == RIBS
    bad = {k: round(x, 4) for k, x in ratios.items() if abs(x - 1) > 0.02}
    assert not bad, bad


def _area_ratios(size):
    surface, _, mesh = wing_mesh(size)
    a = family_areas(mesh)
    skin = is_skin(mesh.component_names)
    return a[skin].sum() / surface.face_areas().sum(), a[~skin].sum() / input_member_area()


def test_mesh_area_matches_the_input_at_chord_over_10():
    """Mass = area x t x rho: the skin's area within 0.3 % of the input triangulation's, the
    members' within 0.3 % of the ribs and webs cut from the input's sections."""
    skin, members = _area_ratios(0.1)
    assert abs(skin - 1) < 3e-3, skin
    assert abs(members - 1) < 3e-3, members


@pytest.mark.slow
def test_mesh_area_matches_the_input_at_chord_over_5():
    """The same at chord/5, where the element is 12 times the leading-edge radius: no skin face
    may cut across the nose (bridging it or standing across it changes the area)."""
    skin, members = _area_ratios(0.2)
    assert abs(skin - 1) < 3e-3, skin
    assert abs(members - 1) < 3e-3, members
