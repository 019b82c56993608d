"""The random family of aircraft (issue 41): the generator's surfaces are valid closed skins for
every draw, its parameters stay in their ranges, the same seed gives the same mesh, and a sample of
draws runs through the whole pipeline to a mesh that meets every guarantee or to a clear refusal.

The seeds were drawn once at random (``numpy.random.default_rng(2041).integers(0, 100000, 12)``)
and fixed; the corpus of the project is a sample, not the target.
"""
import dataclasses
import hashlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from shellmesh_mdao.errors import ShellMeshError
from shellmesh_mdao.geometry import (AircraftParams, StructureParams, aircraft_layout, aircraft_surface,
                                     draw_aircraft, draw_structure, random_aircraft, self_intersections,
                                     surface_defects)
from shellmesh_mdao.geometry.aircraft import (CHOICES, MIN_BOX, ORIENTATIONS, RANGES, aircraft_parts, wing_planform,
                                              wing_section)

#: drawn once at random, then fixed (module docstring)
SEEDS = [51439, 57998, 78953, 84493, 13339, 11050, 72540, 61906, 69828, 61354, 92199, 82570]


def _valid(defects: dict) -> bool:
    return (defects["open_edges"] == 0 and defects["repeated_edges"] == 0 and defects["degenerate_faces"] == 0
            and defects["self_intersections"] == 0 and defects["volume"] > 0)


def _digest(mesh) -> str:
    h = hashlib.sha1()
    for a in (mesh.points, mesh.faces, mesh.component):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


# ------------------------------------------------------------------ parameters
@settings(max_examples=200, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**63 - 1))
def test_draws_stay_in_their_ranges(seed):
    p = draw_aircraft(seed)
    for name, (lo, hi) in RANGES.items():
        assert lo <= getattr(p, name) <= hi, name
    for name, (opts, _) in CHOICES.items():
        assert getattr(p, name) in opts, name
    p.check()
    s = draw_structure(seed)
    assert 3 <= s.ribs <= 15 and 1 <= len(s.spars) <= 3 and s.orientation in ORIENTATIONS
    assert all(0.1 <= f <= 0.75 for f in s.spars) and list(s.spars) == sorted(s.spars)


def test_the_draws_cover_every_choice():
    """Over 200 draws every option of every choice appears (the family is not stuck in a corner)."""
    seen = {name: set() for name in CHOICES}
    for seed in range(200):
        p = draw_aircraft(seed)
        for name in CHOICES:
            seen[name].add(getattr(p, name))
    assert seen == {name: set(opts) for name, (opts, _) in CHOICES.items()}


def test_out_of_range_parameters_are_named():
    with pytest.raises(ValueError, match=r"AircraftParams.sweep_deg = 75 is outside its range \[0, 60\]"):
        aircraft_surface(AircraftParams(sweep_deg=75))
    with pytest.raises(ValueError, match="AircraftParams.tip = 'square'"):
        aircraft_surface(AircraftParams(tip="square"))


# ------------------------------------------------------------------ surfaces
@pytest.mark.parametrize("seed", SEEDS[:8])
def test_random_aircraft_is_a_valid_closed_skin(seed):
    """One closed, consistently and outward oriented triangulation without self-intersections, of a
    reasonable size, whose every part is valid too; the layout's stations lie on the wing."""
    mesh, lay = random_aircraft(seed, size=0.1)
    d = surface_defects(mesh)
    assert _valid(d), d
    assert 2_000 < mesh.n_faces < 100_000
    assert mesh.n_bodies() == 1
    p = draw_aircraft(np.random.default_rng(seed))
    vol = sum(surface_defects(P, T, intersections=False)["volume"] for P, T in aircraft_parts(p).values())
    assert d["volume"] <= vol * (1 + 1e-9)
    if p.fuselage:                      # the wing runs through the fuselage: the union holds less than the parts
        assert d["volume"] < vol * (1 - 1e-6)
    pf = wing_planform(p)
    right = next(w for w in lay["wings"] if w["name"] == "right_wing")
    assert pf["body_half_width"] < right["root"] < right["tip"] < pf["semi_span"]
    left = next(w for w in lay["wings"] if w["name"] == "left_wing")
    assert left["root"] == -right["root"] and left["tip"] == -right["tip"]


VARIANTS = [dict(winglet="blended", tip="round", blunt_te=True, fuselage=True, cranked=True),
            dict(winglet="separate", tip="round", blunt_te=True, fuselage=False, cranked=False),
            dict(winglet="separate", tip="flat", blunt_te=False, fuselage=True, cranked=True),
            dict(winglet="none", tip="round", blunt_te=False, fuselage=False, cranked=False),
            dict(winglet="blended", tip="flat", blunt_te=True, fuselage=True, cranked=False, htail=False)]


@pytest.mark.parametrize("corner", ["low", "high"])
@pytest.mark.parametrize("variant", range(len(VARIANTS)))
def test_corners_of_the_parameter_box_are_valid(corner, variant):
    """Every number at the low (or high) end of its range, with each kind of tip, trailing edge,
    winglet and body: still one valid closed skin."""
    vals = {name: (lo if corner == "low" else hi) for name, (lo, hi) in RANGES.items()}
    p = AircraftParams(**vals, **VARIANTS[variant])
    d = surface_defects(aircraft_surface(p))
    assert _valid(d), d


def test_same_seed_same_mesh_bit_for_bit():
    a, la = random_aircraft(SEEDS[0], size=0.2)
    b, lb = random_aircraft(np.random.default_rng(SEEDS[0]), size=0.2)
    assert _digest(a) == _digest(b) and la == lb
    c, _ = random_aircraft(SEEDS[1], size=0.2)
    assert _digest(c) != _digest(a)


def test_self_intersection_check_finds_crossing_parts():
    """The check is not blind: the wing and the fuselage before their union cross each other."""
    parts = aircraft_parts(AircraftParams())
    (P1, T1), (P2, T2) = parts["wing"], parts["fuselage"]
    pairs = self_intersections(np.vstack([P1, P2]), np.vstack([T1, T2 + len(P1)]))
    assert len(pairs) > 0 and (pairs[:, 0] < len(T1)).all() and (pairs[:, 1] >= len(T1)).all()
    assert len(self_intersections(P1, T1)) == 0


def test_layout_follows_the_structure_and_the_size():
    p = AircraftParams()
    s = StructureParams(ribs=15, spars=(0.2, 0.6), orientation="streamwise", tails=True)
    fine = aircraft_layout(p, s, size=0.05)
    assert [w["name"] for w in fine["wings"]] == ["right_wing", "left_wing", "right_htail", "left_htail", "fin"]
    assert all(w["ribs"]["orientation"] == "streamwise" and w["spars"]["chord_fractions"] == [0.2, 0.6]
               for w in fine["wings"])
    assert fine["wings"][0]["ribs"]["count"] == 15 and "cranks" in fine["wings"][0]
    coarse = aircraft_layout(p, dataclasses.replace(s, tails=False), size=0.6)
    assert [w["name"] for w in coarse["wings"]] == ["right_wing", "left_wing"]
    w = coarse["wings"][0]
    # ribs at least 1.5 sizes apart; the root two sizes outboard of the body
    assert (w["ribs"]["count"] - 1) * 1.5 * 0.6 <= w["tip"] - w["root"] + 1e-9 < 15 * 1.5 * 0.6
    assert w["root"] == pytest.approx(wing_planform(p)["body_half_width"] + 1.2)
    # a surface too short for a box at the size (its stations at most MIN_BOX sizes apart) gets no entry, as
    # `shellmesh wings` writes none: the fin at 0.3, the tails at 0.4
    assert [w["name"] for w in aircraft_layout(p, s, size=0.3)["wings"]] == \
        ["right_wing", "left_wing", "right_htail", "left_htail"]
    for size in (0.05, 0.3, 0.4):
        assert all(abs(w["tip"] - w["root"]) > MIN_BOX * size for w in aircraft_layout(p, s, size=size)["wings"])
    assert [w["name"] for w in aircraft_layout(p, s, size=0.4)["wings"]] == ["right_wing", "left_wing"]


def test_layout_stage_measures_the_generated_planform():
    """The layout stage, measuring the skin at the stations, finds the generator's chords."""
    from shellmesh_mdao.layout import load_layout, resolve_layout

    p = dataclasses.replace(draw_aircraft(SEEDS[2]), winglet="none", twist_deg=0.0)
    mesh = aircraft_surface(p)
    size = wing_planform(p)["mean_chord"] / 10
    lay = resolve_layout(load_layout(aircraft_layout(p, StructureParams(), size)), mesh.points, mesh.faces[:, :3],
                         size)
    wing = next(w for w in lay.station_wings if w.name == "right_wing")
    s = wing.planform.summary()
    for end in ("root", "tip"):
        sec = wing_section(p, s[end])
        assert s[f"{end}_chord"] == pytest.approx(sec["chord"], rel=0.01), end
        assert s[f"{end}_thickness"] == pytest.approx(sec["depth"], rel=0.01), end


# ------------------------------------------------------------------ through the pipeline
#: the first seeds of :data:`SEEDS`, meshed at mean chord / 8 (coarse: seconds each)
PIPELINE_SEEDS = SEEDS[:3]


@pytest.mark.parametrize("seed", PIPELINE_SEEDS)
def test_random_aircraft_meshes_or_is_refused_clearly(seed):
    """The whole pipeline on a random aircraft and its station-given layout: a mesh that meets every
    guarantee, or a refusal (a ShellMeshError naming the member and the fix) -- never a crash."""
    from shellmesh_mdao.guarantees import check_guarantees
    from shellmesh_mdao.pipeline import run_pipeline

    size = wing_planform(draw_aircraft(np.random.default_rng(seed)))["mean_chord"] / 8
    mesh, lay = random_aircraft(seed, size=size)
    try:
        res = run_pipeline(mesh, lay, size, progress=False)
    except ShellMeshError as e:
        msg = str(e)                    # names a member of the layout, or the element size to change
        assert any(f"'{w['name']}" in msg for w in lay["wings"]) or "--size" in msg, msg
        return
    g = check_guarantees(res)
    assert g["min_scaled_jacobian"] > 0.2


@pytest.mark.xfail(strict=True, reason="defect: the members stage refuses a full-chord rib of a wing with a blunt "
                   "trailing edge (0.6 % of the chord, under an element size tall) for a 0.4 deg corner of its "
                   "chain on the remeshed skin, saying the upper and lower skin meet at that angle, where the "
                   "exact section's sharpest corner is 94.5 deg (the layout stage had judged the edges blunt "
                   "enough for full-chord ribs); seed 5 of the random family at mean chord / 30")
def test_a_sharp_edge_refusal_names_a_sharp_edge_of_the_skin():
    """When the pipeline refuses a full-chord rib because it cuts a sharp edge, the skin has that
    edge: the exact plane section of the input surface has a corner that sharp."""
    from shellmesh_mdao.benchmarks.random_family import draw_case
    from shellmesh_mdao.core.section import section_arc
    from shellmesh_mdao.errors import LayoutError
    from shellmesh_mdao.imprint import MIN_LOOP_CORNER, loop_corner
    from shellmesh_mdao.pipeline import run_pipeline

    case = draw_case(5)
    size = case["mean_chord"] / 30
    skin = aircraft_surface(case["params"])
    lay = aircraft_layout(case["params"], case["structure"], size)
    try:
        run_pipeline(skin, lay, size, progress=False)
        return
    except LayoutError as e:
        if "cuts a sharp edge of the skin" not in str(e) and "cut a sharp edge of the skin" not in str(e):
            return
        named = [w.split("'")[1] for w in str(e).split(": ", 1)[1].split("; ") if w.startswith("'")]
    res = run_pipeline(skin, lay, size, until="project", progress=False)
    P, T = res.surface.points, res.surface.faces[:, :3]
    for spec in res.state.specs:
        if spec.member in named:
            arc = section_arc(P, T, spec.plane, spec.bounds, seed=spec.seed, seed_tri=spec.seed_tri, name=spec.member)
            angle, _ = loop_corner(arc.points, 1e-9 * res.surface.diagonal)
            assert angle < MIN_LOOP_CORNER, f"{spec.member}: the exact section's sharpest corner is {angle:.1f} deg"
