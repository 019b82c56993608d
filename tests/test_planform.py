"""Planforms measured from the skin (shellmesh_mdao.layout.sections / .planform): wing sections
cut at span stations, their leading and trailing edge, chord, thickness and twist, on generated
wings with known answers and on corpus files."""
import json
from pathlib import Path

import numpy as np
import pytest

from shellmesh_mdao.errors import LayoutError
from shellmesh_mdao.geometry import naca_wing
from shellmesh_mdao.layout import measure_planform, section_loops
from shellmesh_mdao.mesh import ShellMesh

GEOMETRY = Path(__file__).resolve().parents[2] / "shared" / "geometry"
SPAN, ROOT_C, TIP_C, SWEEP, DIHEDRAL = 6.0, 2.0, 1.0, 10.0, 3.0


def exact_le(y):
    """Leading edge of naca_wing's defaults: x = y tan(sweep), z = y tan(dihedral)."""
    return np.array([y * np.tan(np.radians(SWEEP)), y, y * np.tan(np.radians(DIHEDRAL))])


@pytest.fixture(scope="module")
def wing():
    return naca_wing()


def test_default_wing_planform(wing):
    pf = measure_planform(wing.points, wing.faces[:, :3], [0, 1, 0], 0.2, 5.8, up=[0, 0, 1],
                          name="w")
    assert pf.stations[0] == pytest.approx(0.2) and pf.stations[-1] == pytest.approx(5.8)
    for s in pf.shapes:
        y = s.station
        chord = ROOT_C + (TIP_C - ROOT_C) * y / SPAN
        assert s.chord == pytest.approx(chord, rel=2e-3)
        assert np.linalg.norm(s.le - exact_le(y)) <= 2e-3 * chord
        assert s.thickness == pytest.approx(0.12 * chord, rel=0.02)      # NACA 2412: 12 %
        assert not s.blunt and abs(s.twist_deg) < 0.05
    assert pf.aft == 1.0                                                 # the sharp edge trails (+x)
    # interpolation between stations: the mean point lies between the skins
    hu, hl = pf.heights(3.0, np.array([0.15, 0.65]))
    assert (hu > 0).all() and (hl < 0).all()


def test_tip_before_root_and_no_up(wing):
    """A wing running towards -axis, and up measured (chord-plane normal, largest component +)."""
    m = ShellMesh(wing.points * [1, -1, 1], wing.faces[:, [2, 1, 0]], wing.component, ["skin"])
    pf = measure_planform(m.points, m.faces[:, :3], [0, 1, 0], -0.5, -5.5, name="w")
    assert pf.axis @ [0, -1, 0] == pytest.approx(1.0)
    assert pf.up[2] > 0.99
    assert pf.shapes[0].chord == pytest.approx(ROOT_C + (TIP_C - ROOT_C) * 0.5 / SPAN, rel=2e-3)


def test_crank_twist_and_blunt_trailing_edge():
    S = naca_wing(twist_deg=-4.0, crank=(0.4, 1.3), te_thickness=0.01, sweep_deg=25.0)
    P, T = S.points, S.faces[:, :3]
    pf = measure_planform(P, T, [0, 1, 0], 0.1, 5.9, cranks=[2.4], up=[0, 0, 1], tol=0.005, name="w")
    assert 2.4 in pf.stations                                            # a crank is always measured
    k = int(np.flatnonzero(pf.stations == 2.4)[0])
    assert pf.shapes[k].chord == pytest.approx(1.3, rel=2e-3)
    # the trailing edge follows the kink: chords on both sides interpolate exactly
    for y in (1.2, 4.0):
        chord = np.interp(y / SPAN, [0, 0.4, 1], [2.0, 1.3, 1.0])
        assert pf.chord(y) == pytest.approx(chord, rel=3e-3)
    # twist: nose down 4 deg at the tip, linear
    assert pf.shapes[-1].twist_deg == pytest.approx(-4.0 * 5.9 / SPAN, abs=0.05)
    # blunt: the base's two corners are te_thickness * chord apart
    s = pf.shapes[k]
    assert s.blunt and (s.te_upper - s.te_lower) @ pf.up == pytest.approx(0.01 * 1.3, rel=0.02)
    # without the crank declared, the refinement finds the kink within the tolerance
    pf2 = measure_planform(P, T, [0, 1, 0], 0.1, 5.9, up=[0, 0, 1], tol=0.002, name="w")
    ts = np.linspace(0.1, 5.9, 200)
    exact = np.interp(ts / SPAN, [0, 0.4, 1], [2.0, 1.3, 1.0])
    assert np.abs(pf2.chord(ts) - exact).max() <= 0.01


def test_section_of_unsewn_patches_is_one_loop(wing):
    """Upper and lower skin as separate patches (vertices not shared, a CAD input): the open arcs
    of a station's section are joined into one loop."""
    P, F = wing.points, wing.faces[:, :3]
    up_face = np.cross(P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]])[:, 2] > 0
    P2 = np.vstack([P, P])
    F2 = np.where(up_face[:, None], F, F + len(P))
    loops = section_loops(P2, F2, [0, 3.0, 0], [0, 1, 0])
    assert len(loops) == 1
    ref = section_loops(P, F, [0, 3.0, 0], [0, 1, 0])
    assert np.ptp(loops[0], axis=0) == pytest.approx(np.ptp(ref[0], axis=0), rel=1e-9)


def test_loop_pick_near_and_largest(wing):
    """Two bodies cut by the same plane: the largest wing-like loop without a hint, the one around
    ``near`` with it (a tail behind a wing)."""
    tail = naca_wing(span=3.0, root_chord=0.8, tip_chord=0.5, sweep_deg=5.0, dihedral_deg=0.0)
    tp = tail.points + [6.0, 0.0, 0.5]
    P = np.vstack([wing.points, tp])
    T = np.vstack([wing.faces[:, :3], tail.faces[:, :3] + len(wing.points)])
    big = measure_planform(P, T, [0, 1, 0], 0.2, 2.5, up=[0, 0, 1], name="w")
    assert big.shapes[0].chord == pytest.approx(ROOT_C + (TIP_C - ROOT_C) * 0.2 / SPAN, rel=2e-3)
    small = measure_planform(P, T, [0, 1, 0], 0.2, 2.5, up=[0, 0, 1], near=[6.3, 0.2, 0.5], name="t")
    assert small.shapes[0].chord == pytest.approx(0.8 - 0.3 * 0.2 / 3.0, rel=2e-3)
    assert small.shapes[-1].le[0] > 5.9


def test_errors_name_the_wing(wing):
    P, T = wing.points, wing.faces[:, :3]
    with pytest.raises(LayoutError, match="'w'.*does not cut the skin"):
        measure_planform(P, T, [0, 1, 0], -1.0, 3.0, up=[0, 0, 1], name="w")
    with pytest.raises(LayoutError, match="'w'.*lost at station"):
        measure_planform(P, T, [0, 1, 0], 0.5, 7.0, up=[0, 0, 1], name="w")
    with pytest.raises(LayoutError, match="parallel to the span axis"):
        measure_planform(P, T, [0, 1, 0], 0.5, 5.0, up=[0, 1, 0], name="w")
    with pytest.raises(LayoutError, match="both 1"):
        measure_planform(P, T, [0, 1, 0], 1.0, 1.0, name="w")


@pytest.mark.skipif(not (GEOMETRY / "manifest.json").is_file(), reason="corpus not present")
@pytest.mark.parametrize("name", ["cessna210", "bwb", "swept_wing_and_tail", "supersonic_wing_body"])
def test_corpus_planform_matches_the_manifest_corners(name):
    """The manifest's wing-box corners are the edges of the sections at its root and tip
    stations: the measured leading and trailing edges (in the chord direction) match them."""
    from shellmesh_mdao.load import load_surface

    g = json.loads((GEOMETRY / "manifest.json").read_text())["geometries"][name]
    S, _ = load_surface(GEOMETRY / g["file"])
    for w in g["wings"]:
        up = np.asarray(w.get("up", g["up"]), float)
        a = np.eye(3)[int(np.argmax(np.abs(np.cross(up, np.subtract(w["root_te"], w["root_le"])))))]
        near = 0.5 * (np.asarray(w["root_le"]) + np.asarray(w["root_te"]))
        pf = measure_planform(S.points, S.faces[:, :3], a, np.dot(w["root_le"], a), np.dot(w["tip_le"], a), up=up,
                              near=near, name=w["name"])
        for s, st in ((pf.shapes[0], "root"), (pf.shapes[-1], "tip")):
            corners = np.array([w[f"{st}_le"], w[f"{st}_te"]])
            chord = np.linalg.norm(corners[1] - corners[0])
            got = sorted([s.le, s.te], key=lambda p: p @ pf.e)
            want = sorted(corners, key=lambda p: p @ pf.e)
            for g_, w_ in zip(got, want):
                assert abs((g_ - w_) @ pf.e) <= 0.01 * chord, (name, w["name"], st)
