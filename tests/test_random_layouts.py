"""Random layouts on the corpus, end to end (issue 8, section 1): the fixed-seed CI subset.

Case ``i`` is ``draw_case(seed=i, geometry=GEOMETRIES[i])`` of shellmesh_mdao.benchmarks.stress for
i = 0..3 (bwb, cessna210, straight_wing, swept_wing): seeds 0..3 taken as they come, not chosen
by their outcome. Sizes are drawn in the upper half of the sweep's 4x range (x1.4 .. x2.8 of the
benchmark size, :data:`CI_SIZE_FACTORS`) to keep the four runs near a minute. Each run must be
``ok`` (``shellmesh_mdao.guarantees.check_guarantees``: all quads, no scaled Jacobian <= 0.2, no
duplicate points or hanging nodes, conforming junctions) or ``invalid layout`` (a documented
ShellMeshError that the layout genuinely deserves, checked independently of the package); never
``FAIL``. The larger sweep is ``python run_scripts/stress_layouts.py`` (docs/stress_layouts.md).

The fast tests check the draw (ranges, determinism) and the classifier on known inputs.
"""
from __future__ import annotations

import pytest

from shellmesh_mdao.benchmarks import stress as SL

CI_SIZE_FACTORS = (1.4, 2.8)

#: measured FAILs of the package on the CI draws, kept as strict xfails (a run returning a mesh below the
#: quality guarantee instead of meshing it or refusing it with a documented error): none since 2026-11-22
#: 09:20 UTC (cessna210 seed 1 is refused for its 0.15-element spar web, straight_wing seed 2 and swept_wing
#: seed 3 mesh with min SJ 0.300 / 0.249). Strict: a fixed package XPASSes and the mark must go.
KNOWN_FAILS: dict = {}
CI_CASES = [pytest.param(i, g, id=g, marks=[pytest.mark.xfail(strict=True, reason=KNOWN_FAILS[g])]
                         if g in KNOWN_FAILS else []) for i, g in enumerate(SL.GEOMETRIES)]


def test_draw_ranges_and_determinism(manifest, geometry_dir):
    cases = [SL.draw_case(s, None, manifest=manifest, geometry_dir=geometry_dir) for s in range(24)]
    again = [SL.draw_case(s, None, manifest=manifest, geometry_dir=geometry_dir) for s in range(24)]
    assert cases == again, "the draw is deterministic per seed"
    assert {c["geometry"] for c in cases} == set(SL.GEOMETRIES)
    for c in cases:
        f = c["size"] / SL.BASE_SIZES[c["geometry"]]
        assert 0.7 * 0.999 <= f <= 2.8 * 1.001
        t = SL.layout_tightness(manifest, c, geometry_dir)
        if c["spacing"] == "spaced":
            # spaced draws are valid for the validator: every gap at least the element size
            assert t["rib_gap"] >= 1.0 and t["spar_gap"] >= 1.0
    # the draws cover the ranges: 1-20 ribs and 1, 2 and 3 spars all occur in 24 seeds
    n_ribs = [len(c["ribs"]) for c in cases]
    assert min(n_ribs) <= 3 and max(n_ribs) >= 15
    assert {len(c["spars"]) for c in cases} == {1, 2, 3}
    # the fixed seed of case 0 is pinned: a change of the draw changes the CI subset
    c0 = SL.draw_case(0, "bwb", CI_SIZE_FACTORS, manifest=manifest, geometry_dir=geometry_dir)
    assert c0["ribs"][:2] == [0.0027, 0.0336] and c0["spars"] == [0.871] and c0["size"] == 0.5064


def test_classifier_on_known_messages(manifest, geometry_dir):
    assert SL.is_documented("members coincide or cross at element size 0.1 (closer than 0.2 element sizes, 0.02): "
                            "ribs 'wing/rib_3' (eta=0.31) and 'wing/rib_4' (eta=0.3101) are 0.0005 apart; spars "
                            "'wing/spar_0' (c=0.2) and 'wing/spar_1' (c=0.201) are 0.002 apart: remove one member of "
                            "each pair or move them apart (members at least 0.2 element sizes apart are meshed, with "
                            "smaller elements between them), or use an element size below 0.0025")
    assert SL.is_documented("wing/spar_0 (upper): its plane cuts the surface only outside the member's bounds; "
                            "check the layout's stations and chord fractions")
    assert not SL.is_documented("index 7 is out of bounds for axis 0 with size 3")
    # one rib and two spars: zero-length spars, a tight layout whatever the size
    t = SL.layout_tightness(manifest, {"geometry": "straight_wing", "ribs": [0.5], "spars": [0.2, 0.6],
                                       "size": 0.02}, geometry_dir)
    assert t["zero_length_spars"] and "single rib" in t["tight"]
    proj = ("member 'right_wing/rib_0': rays miss the skin upward (+up) from [5.7, 2.2, 3.0]: the member's "
            "chord-plane points must lie inside the wing; check the wing corners (root_le/root_te/tip_le/tip_te), "
            "'up', the stations and the chord fractions")
    inside = {"outside": [], "zero_length_spars": False, "tight": "rib gap 1.50 element sizes (< 2)"}
    assert SL.classify_refusal("ProjectionError", proj, "project", inside)[0] == "FAIL", \
        "a projection refusal needs a member outside the wing, not just a tight layout"
    assert SL.classify_refusal("ProjectionError", proj, "project", dict(inside, outside=["right_wing/rib_0"]))[0] \
        == "invalid layout"
    assert SL.classify_refusal("ImprintError", "x: the imprinted curve is broken into pieces; use a smaller --size [near [0.1, 0.2, 0.3]; "
                              "within two skin edges of 'w/spar_0']",
                               "imprint", inside)[0] == "invalid layout"
    assert SL.classify_refusal("ImprintError", "x: the imprinted curve is broken into pieces; use a smaller --size [near [0.1, 0.2, 0.3]; "
                              "within two skin edges of 'w/spar_0']",
                               "imprint", dict(inside, tight=""))[0] == "FAIL"
    assert SL.classify_refusal("ImprintError", "something new went wrong", "imprint", inside)[0] == "FAIL"
    # ribs 0.001 apart on the straight wing (span 3.9): 0.0039 apart, 0.195 of the size 0.02: they coincide
    case = {"seed": -1, "geometry": "straight_wing", "ribs": [0.0, 0.5, 0.501, 1.0], "spars": [0.2, 0.6],
            "size": 0.02, "size_factor": 1.0}
    r = SL.run_case(case, geometry_dir, manifest)
    assert r["outcome"] == "invalid layout" and r["stage"] == "layout", r
    assert r["error"].startswith("LayoutError: members coincide or cross at element size 0.02") and \
        "members that coincide at this size (smallest rib gap 0.195 h" in r["reason"]
    # the validator's refusal is backed only by an independent gap below 0.2 element sizes
    msg = r["error"].split(": ", 1)[1]
    assert SL.classify_refusal("LayoutError", msg, "layout", {"rib_gap": 0.5, "spar_gap": 3.0})[0] == "FAIL"
    # a spar web lower than 0.03 element sizes (straight wing, c=0.03: 0.0036 tall at size 0.2) is refused by
    # the project stage, and the independent ray casts agree that the web is low (tight); at size 0.02 (0.18
    # sizes) it is meshed with smaller elements around it, and is not tight
    case = dict(case, ribs=[0.0, 0.5, 1.0], spars=[0.03, 0.5])
    assert SL.layout_tightness(manifest, case, geometry_dir)["spar_height"] > SL.HEIGHT_TIGHT
    case = dict(case, size=0.2)
    t = SL.layout_tightness(manifest, case, geometry_dir)
    assert 0.01 < t["spar_height"] < 0.025 and "a spar web 0." in t["tight"]
    r = SL.run_case(case, geometry_dir, manifest)
    assert r["outcome"] == "invalid layout" and r["stage"] == "project", r
    assert r["error"].startswith("LayoutError: spar 'wing/spar_0' (c=0.03) is only") and "spar web" in r["reason"]
    # the refusal names its cause (the web): only the independent web height may back it, not other tight gaps
    msg = r["error"].split(": ", 1)[1]
    assert SL.classify_refusal("LayoutError", msg, "project", dict(t, spar_height=1.5))[0] == "FAIL"
    assert SL.classify_refusal("LayoutError", msg, "project",
                               dict(t, spar_height=1.5, tight="rib gap 1.50 element sizes (< 2)"))[0] == "FAIL"


@pytest.mark.slow
@pytest.mark.parametrize("seed,geometry", CI_CASES)
def test_random_layout_end_to_end(manifest, geometry_dir, seed, geometry):
    case = SL.draw_case(seed, geometry, CI_SIZE_FACTORS, manifest=manifest, geometry_dir=geometry_dir)
    r = SL.run_case(case, geometry_dir, manifest)
    assert r["outcome"] in ("ok", "invalid layout"), \
        f"{case}: {r['outcome']} at stage {r['stage']}: {r['reason']}: {r['error']}\n{r.get('traceback', '')}"
    if r["outcome"] == "invalid layout":
        assert r["reason"] and r["error"]
    else:
        assert r["min_sj"] > 0.2 and r["n_poor"] == 0 and r["n_elements"] > 0


@pytest.mark.slow
@pytest.mark.parametrize("seed", [24, 148])
def test_bwb_sweep_layouts_found_by_the_imprint_fixes(manifest, geometry_dir, seed):
    """Two bwb layouts of the 192-seed sweep (sizes x1.23 and x1.50 of the benchmark size), refused
    as "imprinted curve broken into pieces" until the snap distance was fixed (d5b79c3), then meshed
    with faults that the sweep's checks caught: seed 24, a rib crossing the sharp trailing edge snapped
    a skin vertex onto the edge opposite it (zero-area triangles, 5 folded quads); seed 148, spar_0
    (c=0.075) one skin edge behind the rounded leading edge, so its web ran along a skin edge (edges
    with 4 and 5 faces). Seed 24 must now meet every guarantee. Seed 148's spar_0 is 0.37 element
    sizes behind the leading edge (its web 0.36 sizes tall, meshed with smaller elements around it):
    whether its upper and lower chains keep apart behind the leading edge depends on the last bits of
    the skin (meshed until 2026-11-24; since the closest points pick the lowest of equally near input
    triangles, its lower chain runs into the upper one's vertices there), so it must meet every
    guarantee or be refused at the imprint as a tight layout (the spar that close to the edge), never
    give a faulty mesh."""
    case = SL.draw_case(seed, "bwb", manifest=manifest, geometry_dir=geometry_dir)
    r = SL.run_case(case, geometry_dir, manifest)
    if seed == 148 and r["outcome"] == "invalid layout":
        assert r["stage"] == "imprint" and "spar to leading/trailing edge 0.37 element sizes" in r["reason"], r
        return
    assert r["outcome"] == "ok", f"{case}: {r['outcome']} at stage {r['stage']}: {r['reason']}: {r['error']}"
    assert r["min_sj"] > 0.2 and r["n_poor"] == 0


@pytest.mark.slow
def test_cessna210_sweep_layout_with_a_rib_crossing_the_trailing_edge(manifest, geometry_dir):
    """cessna210 seed 41 of the 192-seed sweep (18 ribs 1.73 element sizes apart, one spar, size
    0.507): rib_2's chain crosses the trailing-edge crease at a fixed skin vertex whose 38-degree
    corner in one bay a ladder split of rib_3's thin chain edge cut into 17.2, 10.5 and 10.3
    degrees; the 10.5-degree corner stayed in a final quad of scaled Jacobian 0.183 (members stage,
    fixed apexes keep min_fan_angle). It must meet every guarantee."""
    case = SL.draw_case(41, "cessna210", manifest=manifest, geometry_dir=geometry_dir)
    r = SL.run_case(case, geometry_dir, manifest)
    assert r["outcome"] == "ok", f"{case}: {r['outcome']} at stage {r['stage']}: {r['reason']}: {r['error']}"
    assert r["min_sj"] > 0.2 and r["n_poor"] == 0
