"""Component names and families (shellmesh_mdao.families): the builders and the parser agree for
every kind, every name the pipeline makes follows the scheme and has the expected family, explicit
member names cannot contain '/', and a name outside the scheme is refused where one is required."""
import numpy as np
import pytest

from shellmesh_mdao import families as F
from shellmesh_mdao.components.layout_comp import family_names
from shellmesh_mdao.config import ConfigError, check_thickness_names, thickness_by_component
from shellmesh_mdao.errors import LayoutError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.layout import load_layout
from shellmesh_mdao.mesh import ShellMesh
from shellmesh_mdao.pipeline import run_pipeline


# ============================================================================ builders and parser
@pytest.mark.parametrize("name, kind, wing, index, side, segment, member, family", [
    (F.rib_name("w", 0), "rib", "w", 0, None, None, "w/rib_0", "rib"),
    (F.rib_name("left wing", 12), "rib", "left wing", 12, None, None, "left wing/rib_12", "rib"),
    (F.spar_name("w", 2), "spar", "w", 2, None, None, "w/spar_2", "spar"),
    (F.segment_name(F.rib_name("w", 3), 1), "rib", "w", 3, None, 1, "w/rib_3", "rib"),
    (F.segment_name(F.spar_name("w", 1), 10), "spar", "w", 1, None, 10, "w/spar_1", "spar"),
    ("frame_3", "explicit", None, None, None, None, "frame_3", "member"),
    (F.segment_name("frame_3", 0), "explicit", None, None, None, 0, "frame_3", "member"),
    (F.bay_name("w", "upper", 0), "skin_bay", "w", 0, "upper", None, None, "upper skin"),
    (F.bay_name("w", "lower", 7), "skin_bay", "w", 7, "lower", None, None, "lower skin"),
    (F.SKIN, "skin", None, None, None, None, None, "skin"),
])
def test_build_parse_round_trip(name, kind, wing, index, side, segment, member, family):
    c = F.parse_component(name)
    assert (c.name, c.kind, c.wing, c.index, c.side, c.segment) == (name, kind, wing, index, side, segment)
    assert c.member == member and c.family == family == F.component_family(name)
    assert c.kind in F.KINDS and c.family in F.FAMILIES
    # rebuild the name from the parsed parts
    base = {"rib": lambda: F.rib_name(c.wing, c.index), "spar": lambda: F.spar_name(c.wing, c.index),
            "skin_bay": lambda: F.bay_name(c.wing, c.side, c.index), "explicit": lambda: F.member_of(name),
            "skin": lambda: F.SKIN}[kind]()
    assert (base if segment is None else F.segment_name(base, segment)) == name
    if c.member is not None:
        assert F.member_of(name) == c.member and F.is_piece_of(name, c.member)
        assert F.is_member(name, {c.member}) and not F.is_member(name, {c.member + "x"})
    assert F.is_skin(name) == (kind in ("skin", "skin_bay"))
    assert F.is_skin_bay(name) == (kind == "skin_bay")
    assert F.is_lower_skin_bay(name) == (side == "lower") and F.is_upper_skin_bay(name) == (side == "upper")
    assert F.is_rib_or_spar(name) == (kind in ("rib", "spar"))


@pytest.mark.parametrize("name, kind, index, side, part, segment, member", [
    (F.spar_part_name("w", 1, 2), "spar", 1, None, 2, None, "w/spar_1/part_2"),
    (F.segment_name(F.spar_part_name("w", 0, 1), 3), "spar", 0, None, 1, 3, "w/spar_0/part_1"),
    (F.web_name("w", "le"), "web", None, "le", None, None, "w/le_web"),
    (F.part_name(F.web_name("w", "te"), 1), "web", None, "te", 1, None, "w/te_web/part_1"),
    (F.segment_name(F.part_name(F.web_name("w", "le"), 0), 2), "web", None, "le", 0, 2, "w/le_web/part_0"),
])
def test_station_wing_pieces_parse(name, kind, index, side, part, segment, member):
    """The spar and edge-web pieces of a station-given wing (kinked at cranks, split at X-junctions)
    follow the scheme: spar or web family, members of the wing box."""
    c = F.parse_component(name)
    assert (c.kind, c.wing, c.index, c.side, c.part, c.segment) == (kind, "w", index, side, part, segment)
    assert c.member == member and c.family == "spar" and F.is_rib_or_spar(name) and not F.is_skin(name)


def test_names_outside_the_scheme():
    for bad in ("w/rib_x", "w/rib_01", "w/rib_-1", "w/ribs_1", "a/b/rib_1", "w/rib_1/seg_", "w/upper_skin",
                "w/middle_skin/bay_0", "w/upper_skin/bay_0/seg_1", "/rib_1", "w/", "w/spar_1/seg_1/seg_2",
                "w/le_web/part_x", "w/mid_web/part_0", "w/le_web/seg_0/part_1"):
        with pytest.raises(LayoutError, match="does not follow the naming scheme"):
            F.parse_component(bad)
        assert not (F.is_skin_bay(bad) or F.is_rib_or_spar(bad))
    for bad in ("", None, 3):
        with pytest.raises(LayoutError):
            F.parse_component(bad)
    with pytest.raises(ValueError, match="side"):
        F.bay_name("w", "middle", 0)
    # families of names from files (outside the scheme) as before
    assert [F.component_family(n) for n in ("fuselage_skin", "a/b/rib", "rib_2", "spar", "w/upper_skin",
                                            "component_3", "physical_7")] == \
        ["skin", "rib", "rib", "spar", "upper skin", "member", "member"]
    assert F.member_of("plain") == "plain" and not F.is_piece_of("w/rib_10", "w/rib_1")
    assert F.name_and_parents("w/rib_3/seg_1") == ["w/rib_3/seg_1", "w/rib_3", "w"]
    assert F.name_head("w/spar_0") == "w" and F.name_head("skin") == "skin"
    assert F.padded_names(["skin"], 3) == ["skin", "component_1", "component_2"]
    assert F.padded_names(["a", "b"], 1) == ["a", "b"]
    assert F.name_of(["a"], 0) == "a" and F.name_of(["a"], 4) == "component_4"
    assert F.physical_group_name(5) == "physical_5"


def test_explicit_member_and_wing_names_contain_no_slash():
    assert F.check_plain_name("frame_3", "members[0].name") == "frame_3"
    with pytest.raises(LayoutError, match=r"members\[0\]\.name = 'a/b' must not contain '/'"):
        F.check_plain_name("a/b", "members[0].name")
    with pytest.raises(LayoutError, match="non-empty string"):
        F.check_plain_name("  ", "wings[0].name")
    lay = naca_wing_layout(ribs=3)
    lay["members"] = [{"name": "frame/1", "upper": [[0.5, 1.0, 1.0], [1.0, 1.0, 1.0]],
                       "lower": [[0.5, 1.0, -1.0], [1.0, 1.0, -1.0]], "direction": [0, 0, -1]}]
    with pytest.raises(LayoutError, match="must not contain '/'"):
        load_layout(lay)
    lay = naca_wing_layout(ribs=3, name="left/wing")
    with pytest.raises(LayoutError, match=r"wings\[0\].*must not contain '/'"):
        load_layout(lay)


def test_thickness_keys_must_follow_the_scheme():
    lay = naca_wing_layout(ribs=3)
    check_thickness_names({"wing/upper_skin/bay_1": 1.0, "wing/rib_2": 2.0, "ribs": 3.0, "default": 4.0}, lay)
    for bad in ("wing/upper_skin/bay_01", "other/lower_skin/bay_0", "wing/rib_7", "wing/upper_skin"):
        with pytest.raises(ConfigError, match="names no component of this layout"):
            check_thickness_names({bad: 1.0}, lay)
    t = thickness_by_component({"wing/rib_1": 1.0, "spars": 2.0, "lower_skin": 3.0, "default": 4.0},
                               ["skin", "wing/rib_1/seg_0", "wing/rib_2", "wing/spar_1/seg_2", "wing/lower_skin/bay_0"])
    assert t == {"skin": 4.0, "wing/rib_1/seg_0": 1.0, "wing/rib_2": 4.0, "wing/spar_1/seg_2": 2.0,
                 "wing/lower_skin/bay_0": 3.0}


# ============================================================================ the pipeline's names
def _layout():
    """Three spars (the middle one split into bays, the inner ribs into front and rear pieces) and
    an explicit rib at eta 0.5 between the front and rear spars, crossed by the middle spar."""
    d = naca_wing_layout(ribs=4, spars=(0.15, 0.4, 0.65))
    w = load_layout(d).wings[0]
    up = np.asarray(d["wings"][0]["up"])
    p = w.chord_point(np.array([0.5, 0.5]), np.array([0.15, 0.65]))
    d["members"] = [{"name": "cross_rib", "upper": (p + 0.5 * up).tolist(), "lower": (p - 0.5 * up).tolist(),
                     "direction": (-up).tolist()}]
    return d


@pytest.fixture(scope="module")
def members_run():
    return run_pipeline(naca_wing(), _layout(), 0.2, until="members", progress=False)


def test_pipeline_names_follow_the_scheme(members_run):
    r = members_run
    names = list(r.mesh.component_names)
    members = set(r.layout.member_names())
    parsed = {n: F.parse_component(n) for n in names}          # every name parses
    fam = {n: F.component_family(n) for n in names}
    for n, c in parsed.items():
        if c.kind == "skin":
            assert fam[n] == "skin" and not F.is_member(n, members)
        elif c.kind == "skin_bay":
            assert c.wing == "wing" and fam[n] == f"{c.side} skin" and 0 <= c.index < 3
        else:
            assert c.member in members and F.is_member(n, members)
            assert fam[n] == {"rib": "rib", "spar": "spar", "explicit": "member"}[c.kind]
            assert F.is_rib_or_spar(n) == (c.kind != "explicit")
    kinds = {(c.kind, c.segment is not None) for c in parsed.values()}
    assert kinds == {("skin", False), ("skin_bay", False), ("rib", False), ("rib", True), ("spar", False),
                     ("spar", True), ("explicit", False), ("explicit", True)}
    # the member names themselves are built by the layout from the builders, in Layout.members() order
    assert r.layout.member_names() == [F.spar_name("wing", j) for j in range(3)] + \
        [F.rib_name("wing", k) for k in range(4)] + ["cross_rib"]
    assert {F.segment_name("cross_rib", 0), F.segment_name("cross_rib", 1)} <= set(names)
    assert {F.segment_name(F.spar_name("wing", 1), k) for k in range(3)} <= set(names)
    # every name of the layout's family list (skin, members, bays) is a mesh component
    assert set(family_names(_layout())) <= set(names)


def test_family_of_every_face(members_run):
    mesh = members_run.mesh
    fam = np.array([F.component_family(n) for n in mesh.component_names])[mesh.component]
    assert set(fam.tolist()) == set(F.FAMILIES)
    lower = np.array([F.is_lower_skin_bay(n) for n in mesh.component_names])[mesh.component]
    assert lower.any() and (fam[lower] == "lower skin").all()


def test_unnamed_components_are_padded():
    m = ShellMesh(np.eye(3), np.array([[0, 1, 2, -1]] * 3), np.array([0, 1, 2], np.int32), ["skin"])
    assert m.component_names == ["skin", "component_1", "component_2"]
