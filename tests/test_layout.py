"""Layout loading, validation, member resolution and the docs/layout.md examples."""
import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from shellmesh_mdao.errors import LayoutError, SizeError
from shellmesh_mdao.layout import (ExplicitMember, Layout, MemberSpec, WingLayout, layout_from_manifest,
                                   load_layout)

DOC = Path(__file__).resolve().parents[1] / "docs" / "layout.md"

WING = {"name": "w", "root_le": [0.0, 0.0, 0.0], "root_te": [2.0, 0.0, 0.0],
        "tip_le": [1.0, 5.0, 0.5], "tip_te": [2.0, 5.0, 0.5],
        "ribs": {"count": 6}, "spars": {"chord_fractions": [0.2, 0.7]}}


def base(**wing_over):
    w = copy.deepcopy(WING)
    for k, v in wing_over.items():
        if v is None:
            w.pop(k, None)
        else:
            w[k] = v
    return {"up": [0, 0, 1], "wings": [w]}


def err(d, *fragments, exc=LayoutError):
    with pytest.raises(exc) as e:
        load_layout(d)
    msg = str(e.value)
    for f in fragments:
        assert f in msg, f"{f!r} not in {msg!r}"
    return msg


# ----------------------------------------------------------------------------- resolution
def test_names_order_and_counts():
    lay = load_layout(base())
    names = lay.member_names()
    assert names == ["w/spar_0", "w/spar_1"] + [f"w/rib_{k}" for k in range(6)]
    specs = lay.members()
    assert [m.kind for m in specs] == ["spar"] * 2 + ["rib"] * 6
    assert [m.index for m in specs] == [0, 1, 0, 1, 2, 3, 4, 5]
    np.testing.assert_allclose([m.parameter for m in specs if m.kind == "rib"], np.linspace(0, 1, 6))
    assert specs[0].bounds == ("w/rib_0", "w/rib_5")
    assert specs[3].bounds == ("w/spar_0", "w/spar_1")


def test_rib_planes_follow_the_wing():
    lay = load_layout(base())
    w = lay.wings[0]
    up = np.array([0, 0, 1.0])
    s = w.span_vector()
    s_proj = s - (s @ up) * up
    for m in lay.members():
        n = m.plane_normal
        assert abs(np.linalg.norm(n) - 1) < 1e-14
        assert abs(n @ up) < 1e-14                         # every member plane contains up
        if m.kind == "rib":
            np.testing.assert_allclose(n, s_proj / np.linalg.norm(s_proj), atol=1e-14)
            # the rib plane passes through S(eta, c_mid)
            cm = 0.5 * (0.2 + 0.7)
            assert abs((w.chord_point(m.parameter, cm) - m.plane_point) @ n) < 1e-12
            # ends on the two spar lines S(., 0.2), S(., 0.7) and in the rib plane
            for p, c in ((m.start, 0.2), (m.end, 0.7)):
                assert abs((p - m.plane_point) @ n) < 1e-12
                spar = [x for x in lay.members() if x.kind == "spar" and x.parameter == c][0]
                assert abs((p - spar.plane_point) @ spar.plane_normal) < 1e-12
            seeds = m.seed_points(7)
            assert np.abs((seeds - m.plane_point) @ n).max() < 1e-12
        else:
            # spar plane contains its root and tip chord points
            for p in (m.root_point, m.tip_point, m.start, m.end):
                assert abs((p - m.plane_point) @ n) < 1e-12
            np.testing.assert_allclose(m.root_point, w.chord_point(0.0, m.parameter))
            np.testing.assert_allclose(m.tip_point, w.chord_point(1.0, m.parameter))
            # oriented aft
            assert n @ (np.array(WING["root_te"]) - WING["root_le"]) > 0
            # ends on the first and last rib planes
            ribs = [x for x in lay.members() if x.kind == "rib"]
            assert abs((m.start - ribs[0].plane_point) @ ribs[0].plane_normal) < 1e-12
            assert abs((m.end - ribs[-1].plane_point) @ ribs[-1].plane_normal) < 1e-12
            seeds = m.seed_points(4)
            assert np.abs((seeds - m.plane_point) @ n).max() < 1e-12
        # the bounding half-spaces contain the member's ends
        for p in (m.start, m.end):
            for q, nn in m.bound_planes:
                assert (p - q) @ nn >= -1e-12


def test_no_spars_ribs_span_le_to_te_and_no_ribs_spars_span_root_to_tip():
    lay = load_layout(base(spars=None))
    rib = lay.members()[0]
    assert rib.bounds == ("LE", "TE") and rib.chord_range == (0.0, 1.0) and rib.bound_planes == ()
    lay = load_layout(base(ribs=None, spars={"chord_fractions": [0.5]}))
    (spar,) = lay.members()
    assert spar.bounds == ("root", "tip")
    np.testing.assert_allclose(spar.start, spar.root_point)
    np.testing.assert_allclose(spar.end, spar.tip_point)
    # a single spar: ribs still run LE to TE
    lay = load_layout(base(spars={"chord_fractions": [0.5]}))
    assert [m.bounds for m in lay.members() if m.kind == "rib"][0] == ("LE", "TE")


def test_up_default_and_override():
    d = base()
    d["up"] = [0, 0, 2.0]
    assert np.allclose(load_layout(d).members()[0].up, [0, 0, 1])
    d["wings"][0]["up"] = [0, -0.1, 1.0]
    assert np.allclose(load_layout(d).members()[0].up, np.array([0, -0.1, 1]) / np.hypot(0.1, 1))


def test_explicit_members():
    d = base()
    d["members"] = [{"name": "frame", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]],
                     "direction": [0, 0, -1]},
                    {"name": "free", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]]}]
    lay = load_layout(d)
    specs = lay.members()
    assert [m.name for m in specs[-2:]] == ["frame", "free"]
    f = specs[-2]
    assert f.kind == "explicit" and f.plane_normal is None
    np.testing.assert_array_equal(f.direction, [0, 0, -1])
    np.testing.assert_array_equal(f.lower_direction, [0, 0, 1])      # defaults to -direction
    assert specs[-1].direction is None and specs[-1].lower_direction is None
    with pytest.raises(LayoutError, match="frame"):
        f.seed_points()


# ----------------------------------------------------------------------------- round trips
def test_to_dict_round_trip_json_yaml(tmp_path):
    d = base()
    d["wings"].append(dict(copy.deepcopy(WING), name="v", ribs={"eta": [0.0, 0.3, 1.0]},
                           up=[0.0, 0.1, 1.0]))
    d["members"] = [{"name": "m", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]],
                     "direction": [0, 0, -1], "lower_direction": [0, 0.1, 1]}]
    lay = load_layout(d)
    assert load_layout(lay.to_dict()) == lay
    assert load_layout(json.loads(json.dumps(lay.to_dict()))) == lay
    pj = tmp_path / "l.json"
    pj.write_text(lay.to_json())
    py = tmp_path / "l.yaml"
    py.write_text(yaml.safe_dump(lay.to_dict()))
    assert load_layout(pj) == lay
    assert load_layout(str(py)) == lay
    assert lay.to_dict()["wings"][0]["ribs"] == {"count": 6}


def test_with_parameters():
    lay = load_layout(base())
    eta, chord = lay.parameters()
    assert set(eta) == {"w"} and len(eta["w"]) == 6 and np.allclose(chord["w"], [0.2, 0.7])
    new = lay.with_parameters(rib_eta={"w": np.array([0.0, 0.1, 0.3, 0.5, 0.8, 1.0])},
                              spar_chord={"w": [0.25, 0.6]})
    assert new.wings[0].rib_eta == (0.0, 0.1, 0.3, 0.5, 0.8, 1.0)
    assert new.wings[0].spar_chord == (0.25, 0.6)
    assert lay.wings[0].spar_chord == (0.2, 0.7)                      # original untouched
    assert [m.name for m in new.members()] == [m.name for m in lay.members()]
    assert load_layout(new.to_dict()) == new
    with pytest.raises(LayoutError, match=r"rib_eta\['w'\] has 3 entries but the wing has 6 ribs"):
        lay.with_parameters(rib_eta={"w": [0, 0.5, 1]})
    with pytest.raises(LayoutError, match=r"unknown wing 'ww'.*did you mean 'w'"):
        lay.with_parameters(spar_chord={"ww": [0.2, 0.7]})
    with pytest.raises(LayoutError, match=r"spar_chord\['w'\]\[1\] = 1.2 is outside \(0, 1\)"):
        lay.with_parameters(spar_chord={"w": [0.2, 1.2]})
    with pytest.raises(LayoutError, match=r"rib_eta\['w'\]\[2\] = 0.1 is out of order"):
        lay.with_parameters(rib_eta={"w": [0, 0.2, 0.1, 0.5, 0.8, 1.0]})


def test_validate_size():
    """Ribs (spars) closer than the element size are meshed with smaller elements between them;
    only members that coincide at the size (closer than MIN_MEMBER_GAP element sizes) are
    refused, every pair in one error, with the size below which they would mesh."""
    lay = load_layout(base(ribs={"eta": [0.0, 0.5, 0.51, 1.0]}))      # 0.0503 apart
    lay.validate(0.01)
    lay.validate(0.1)
    with pytest.raises(LayoutError, match=r"members coincide or cross at element size 0.3 \(closer than 0.2 element "
                                          r"sizes, 0.06\): ribs 'w/rib_1' \(eta=0.5\) and 'w/rib_2' \(eta=0.51\) are "
                                          r"0.0503 apart: .* or use an element size below 0.2515"):
        lay.validate(0.3)
    lay = load_layout(base(ribs={"eta": [0.0, 0.5, 0.51, 1.0]}, spars={"chord_fractions": [0.2, 0.25, 0.7]}))
    lay.validate(0.09)
    with pytest.raises(LayoutError, match=r"ribs 'w/rib_1' \(eta=0.5\) and 'w/rib_2' \(eta=0.51\) are 0.0503 apart; "
                                          r"spars 'w/spar_0' \(c=0.2\) and 'w/spar_1' \(c=0.25\) are 0.05 apart: remove "
                                          r"one member of each pair"):
        lay.validate(0.3)
    for bad in (0, -1.0, float("nan"), "1"):
        with pytest.raises(SizeError):
            lay.validate(bad)


# ----------------------------------------------------------------------------- manifest
def test_manifest_wings_are_valid_layout_wings(manifest):
    for g, geo in manifest["geometries"].items():
        d = {"up": geo["up"], "wings": geo["wings"]}
        lay = load_layout(d)
        assert [w.name for w in lay.wings] == [w["name"] for w in geo["wings"]]
        lay = layout_from_manifest(manifest, g, ribs=10, spars=[0.15, 0.65])
        specs = lay.members()
        assert len(specs) == 12 * len(geo["wings"])
        ups = {w["name"]: np.asarray(w.get("up", geo["up"]), float) for w in geo["wings"]}
        for m in specs:
            # every member plane contains its wing's up direction (a wing may give its own)
            assert abs(m.plane_normal @ ups[m.wing]) < 1e-12
    # bwb: up is y and span is z, so rib normals are along +-z
    lay = layout_from_manifest(manifest, "bwb", ribs=3, spars=[])
    for m in lay.members():
        assert abs(abs(m.plane_normal[2]) - 1) < 0.05
    with pytest.raises(LayoutError, match="did you mean 'cessna210'"):
        layout_from_manifest(manifest, "cesna210")


# ----------------------------------------------------------------------------- errors
def test_error_eta_outside_and_repeated():
    err(base(ribs={"eta": [0.0, 0.5, 1.2]}), "wings[0] ('w').ribs.eta[2] = 1.2 is outside [0, 1]")
    err(base(ribs={"eta": [-0.1, 0.5]}), "ribs.eta[0] = -0.1 is outside [0, 1]")
    err(base(ribs={"eta": [0.0, 0.5, 0.5, 1.0]}), "ribs.eta[2] = 0.5 is repeated")
    err(base(ribs={"eta": [0.0, 0.6, 0.5]}), "ribs.eta[2] = 0.5 is out of order")


def test_error_chord_fractions():
    err(base(spars={"chord_fractions": [0.7, 0.2]}), "spars.chord_fractions[1] = 0.2 is not greater than")
    err(base(spars={"chord_fractions": [0.2, 0.2]}), "spars.chord_fractions[1] = 0.2 is not greater than")
    err(base(spars={"chord_fractions": [0.0, 0.5]}), "spars.chord_fractions[0] = 0 is outside (0, 1)")
    err(base(spars={"chord_fractions": [0.5, 1.0]}), "spars.chord_fractions[1] = 1 is outside (0, 1)")


def test_error_up_parallel_to_span_and_missing_up():
    d = base(up=[0.0, 1.0, 0.05])
    err(d, "wing 'w'", "nearly parallel to the span")
    d = base()
    del d["up"]
    err(d, "wing 'w' has no 'up'")
    err(base(up=[0, 0, 0]), "wings[0] ('w').up is the zero vector")


def test_error_zero_length_segments():
    err(base(root_te=[0.0, 0.0, 0.0]), "wing 'w'", "root chord", "zero length")
    err(base(tip_te=[1.0, 5.0, 0.5]), "wing 'w'", "tip chord", "zero length")
    err(base(tip_le=[0.0, 0.0, 0.0], tip_te=[2.0, 0.0, 0.0]), "wing 'w'", "span line", "zero length")
    d = base()
    d["members"] = [{"name": "frame", "upper": [[0, 0, 3], [0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]]}]
    err(d, "members[0] ('frame').upper: segment 0", "zero length")
    d["members"] = [{"name": "frame", "upper": [[0, 0, 3]], "lower": [[0, 0, -3], [0, 1, -3]]}]
    err(d, "members[0] ('frame').upper must be a list of at least 2 points")


def test_error_swapped_corners():
    # the leading edge runs from root to tip against the span line (tip_le given on the wrong side)
    err(base(root_le=[0.0, 0.0, 0.0], tip_le=[0.0, -5.0, 0.0], root_te=[2.0, 0.0, 0.0], tip_te=[2.0, 12.0, 0.0]),
        "wing 'w'", "leading edge from root to tip runs against the span direction")


def test_error_missing_keys():
    err(base(tip_te=None), "missing key 'tip_te' in wings[0] ('w')")
    d = base()
    del d["wings"][0]["name"]
    err(d, "missing key 'name' in wings[0]")
    d = base()
    d["members"] = [{"name": "frame", "upper": [[0, 0, 3], [0, 1, 3]]}]
    err(d, "missing key 'lower' in members[0] ('frame')")
    err(base(spars={}), "missing key 'chord_fractions' in wings[0] ('w').spars")
    err(base(ribs={}), "wings[0] ('w').ribs needs exactly one of 'count'")
    err(base(ribs={"count": 3, "eta": [0, 1]}), "wings[0] ('w').ribs needs exactly one of 'count'")
    err({}, "no wings and no members")
    err({"up": [0, 0, 1], "wings": []}, "no wings and no members")


def test_error_wrong_types():
    err(base(root_le=[0.0, "a", 0.0]), "wings[0] ('w').root_le[1] must be a number, got str 'a'")
    msg = err(base(ribs={"eta": [0.0, "1e-3"]}), "ribs.eta[1] must be a number")
    assert "1.0e-3" in msg
    err(base(root_le=[0.0, 0.0]), "wings[0] ('w').root_le must have 3 components")
    err(base(root_le=[0.0, 0.0, 0.0, 1.0]), "root_le must have 3 components")
    err(base(root_le=5.0), "root_le must be a list of 3 numbers")
    err(base(root_te=[2.0, float("nan"), 0.0]), "wings[0] ('w').root_te[1] must be a finite number")
    err(base(ribs={"count": 5.0}), "wings[0] ('w').ribs.count must be an integer")
    err(base(ribs={"count": True}), "ribs.count must be an integer")
    err(base(ribs={"count": 1}), "ribs.count = 1 but needs at least 2")
    err(base(name=3), "wings[0].name must be a non-empty string")
    err(base(name="a/b"), "must not contain '/'")
    err(base(spars={"chord_fractions": 0.5}), "spars.chord_fractions must be a list of numbers")
    err({"wings": {"name": "w"}}, "'wings' must be a list")
    err({"wings": [WING], "members": {"name": "m"}}, "'members' must be a list")
    d = base()
    d["up"] = [0, 0, 0]
    err(d, "up is the zero vector")
    err(dict(base(), members=[{"name": "", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]]}]),
        "members[0].name must be a non-empty string")
    err({"wings": ["w"]}, "wings[0] must be a mapping")
    d = base()
    d["members"] = [{"name": "m", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]],
                     "direction": [0, 0, 0]}]
    err(d, "members[0] ('m').direction is the zero vector")
    d["members"][0]["direction"] = [0, 0, None]
    err(d, "members[0] ('m').direction[2] must be a number, got NoneType")
    d["members"][0]["direction"] = None
    d["members"][0]["lower_direction"] = [0, 0, 1]
    err(d, "members[0] ('m') has 'lower_direction' without 'direction'")


def test_error_duplicate_names():
    d = base()
    d["wings"].append(copy.deepcopy(WING))
    err(d, "duplicate wing name 'w'")
    d = base()
    d["members"] = [{"name": "m", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]]}] * 2
    err(d, "duplicate member name 'm'")


def test_error_unknown_keys_suggest_closest():
    err(base(rbs={"count": 3}), "unknown key 'rbs' in wings[0] ('w')", "did you mean 'ribs'")
    err(base(ribs={"cont": 3}), "unknown key 'cont' in wings[0] ('w').ribs", "did you mean 'count'")
    err(base(spars={"chord_fraction": [0.5]}), "unknown key 'chord_fraction'", "did you mean 'chord_fractions'")
    d = base()
    d["wing"] = d.pop("wings")
    err(d, "unknown key 'wing' in the layout", "did you mean 'wings'")
    d = base()
    d["members"] = [{"name": "m", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]],
                     "directon": [0, 0, 1]}]
    err(d, "unknown key 'directon' in members[0] ('m')", "did you mean 'direction'")
    err(base(zzz=1), "unknown key 'zzz'", "valid keys are")


def test_error_files(tmp_path):
    with pytest.raises(LayoutError, match="layout file not found"):
        load_layout(tmp_path / "nope.yaml")
    p = tmp_path / "bad.json"
    p.write_text('{"wings": [}')
    with pytest.raises(LayoutError, match=r"invalid JSON at line 1"):
        load_layout(p)
    p = tmp_path / "bad.yaml"
    p.write_text("wings:\n  - name: [a\n")
    with pytest.raises(LayoutError, match=r"invalid YAML at line"):
        load_layout(p)
    p = tmp_path / "empty.yaml"
    p.write_text("")
    with pytest.raises(LayoutError, match="empty"):
        load_layout(p)


def test_dataclasses_are_the_public_types():
    lay = load_layout(base())
    assert isinstance(lay, Layout) and isinstance(lay.wings[0], WingLayout)
    assert all(isinstance(m, MemberSpec) for m in lay.members())
    d = base()
    d["members"] = [{"name": "m", "upper": [[0, 0, 3], [0, 1, 3]], "lower": [[0, 0, -3], [0, 1, -3]]}]
    assert isinstance(load_layout(d).explicit[0], ExplicitMember)


# ----------------------------------------------------------------------------- docs
def _doc_blocks(lang):
    return re.findall(rf"```{lang}\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def test_doc_examples_load(tmp_path):
    js = _doc_blocks("json")
    ys = _doc_blocks("yaml")
    assert js and ys
    for i, b in enumerate(js):
        p = tmp_path / f"ex{i}.json"
        p.write_text(b)
        lay = load_layout(p)
        assert lay.wings and lay.members()
    stations = 0
    for i, b in enumerate(ys):
        p = tmp_path / f"ex{i}.yaml"
        p.write_text(b)
        lay = load_layout(p)
        if lay.station_wings:                # members known once resolved against the skin
            stations += 1
            assert lay.member_names()
        else:
            assert lay.wings and lay.members()
    assert stations == 1
    lay = load_layout(yaml.safe_load(next(b for b in ys if "# bwb" in b)))
    assert [w.rib_eta for w in lay.wings] == [(0.0, 0.25, 0.5, 0.75, 1.0), (0.0, 0.25, 0.5, 0.75, 1.0)]
    assert "bulkhead_1" in load_layout(json.loads(js[0])).member_names()


def test_doc_lists_every_key():
    text = DOC.read_text(encoding="utf-8")
    from shellmesh_mdao.layout import schema as L, stations as S
    for k in (L._TOP_KEYS + L._WING_KEYS + L._RIB_KEYS + L._SPAR_KEYS + L._MEMBER_KEYS + S._STATION_KEYS
              + S._STATION_RIB_KEYS + S._STATION_SPAR_KEYS + S.RIB_ORIENTATIONS + S.END_RIBS):
        assert f"`{k}`" in text or f"`ribs.{k}`" in text or f"`spars.{k}`" in text, k


GEOMETRY = Path(__file__).resolve().parents[2] / "shared" / "geometry"


@pytest.mark.skipif(not (GEOMETRY / "cessna210.stl").is_file(), reason="corpus not present")
def test_doc_station_example_resolves_on_the_cessna():
    """The docs' station-given example is a real layout: resolved against cessna210.stl, the wing and
    the tail (picked by 'near' where the tail's root plane cuts the wing too) have their members."""
    from shellmesh_mdao.layout import resolve_layout
    from shellmesh_mdao.load import load_surface

    block = next(b for b in _doc_blocks("yaml") if "root:" in b)
    S, _ = load_surface(GEOMETRY / "cessna210.stl")
    lay = resolve_layout(load_layout(yaml.safe_load(block)), S.points, S.faces[:, :3], 0.25)
    names = lay.member_names()
    assert "right_wing/rib_9" in names and "right_tail/rib_4" in names
    tail = lay.station_wings[1].planform
    assert tail.shapes[0].le[0] > 20.0 and tail.shapes[0].chord < 4.5       # the tail, not the wing
