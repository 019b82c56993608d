"""Wings given by their span axis and stations (shellmesh_mdao.layout.schema.StationWing,
shellmesh_mdao.layout.wingbox): the schema, the members laid out in the measured planform
(spars at local chord fractions, kinked at cranks; rib orientations; root and tip ribs along
their stations; every member in its box), the checks before meshing, and a run end to end."""
import copy

import numpy as np
import pytest

from shellmesh_mdao.errors import LayoutError
from shellmesh_mdao.geometry import naca_wing
from shellmesh_mdao.layout import load_layout, resolve_layout
from shellmesh_mdao.layout.wingbox import MIN_EDGE_ANGLE, SPAR_TOL

SIZE = 0.1
WING = {"name": "w", "axis": "y", "root": 0.2, "tip": 5.8, "up": [0, 0, 1],
        "ribs": {"count": 8}, "spars": {"chord_fractions": [0.15, 0.65]}}


def layout(**over):
    w = copy.deepcopy(WING)
    for k, v in over.items():
        if v is None:
            w.pop(k, None)
        else:
            w[k] = v
    return {"wings": [w]}


@pytest.fixture(scope="module")
def wing():
    return naca_wing()


def resolve(surface, d, size=SIZE):
    return resolve_layout(load_layout(d), surface.points, surface.faces[:, :3], size)


def by_name(lay):
    return {m.name: m for m in lay.members()}


# ============================================================================ schema
def test_parse_and_round_trip():
    d = layout(cranks=[2.4], near=[1.0, 0.2, 0.0], aft=[1, 0, 0],
               ribs={"count": 5, "orientation": [0.1, 1.0, 0.0], "end_ribs": "same"},
               spars={"chord_fractions": [0.15, 0.65], "tip_chord_fractions": [0.2, 0.6],
                      "crank_chord_fractions": [[0.18, 0.62]]})
    lay = load_layout(d)
    w = lay.station_wings[0]
    assert not lay.wings and w.axis == (0.0, 1.0, 0.0) and w.cranks == (2.4,)
    assert load_layout(lay.to_dict()) == lay
    assert w.spar_fractions(np.array([0.0, (2.4 - 0.2) / 5.6, 1.0])).round(6).tolist() == \
        [[0.15, 0.65], [0.18, 0.62], [0.2, 0.6]]
    # names are known before the planform is measured; the members are not
    assert lay.member_names() == ["w/spar_0", "w/spar_1"] + [f"w/rib_{k}" for k in range(5)]
    with pytest.raises(LayoutError, match="resolve the layout against the surface"):
        lay.members()


@pytest.mark.parametrize("over, match", [
    (dict(root_le=[0, 0, 0]), "both wing-box corners .* and stations"),
    (dict(tip=0.2), "root and tip are both 0.2"),
    (dict(axis="w"), "give 'x', 'y' or 'z'"),
    (dict(cranks=[7.0]), r"cranks\[0\] = 7 is not between the root"),
    (dict(ribs={"count": 5, "orientation": "normal_to_spars"}), "did you mean 'normal_to_spar'"),
    (dict(ribs={"count": 5, "spar": 2}), r"ribs.spar = 2: the wing has 2 spar"),
    (dict(ribs={"count": 5, "end_ribs": "root"}), "give 'station'"),
    (dict(spars={"chord_fractions": [0.15, 0.65], "tip_chord_fractions": [0.2]}), "one tip fraction per spar"),
    (dict(spars={"chord_fractions": [0.15], "crank_chord_fractions": [[0.2]]}), "without tip_chord_fractions"),
    (dict(up=[0, 0, 0]), "up is the zero vector"),
    (dict(rootx=1), "unknown key 'rootx'"),
])
def test_schema_errors(over, match):
    with pytest.raises(LayoutError, match=match):
        load_layout(layout(**over))


# ============================================================================ the wing box
def planform_xt(pf, p):
    return np.asarray(p) @ pf.axis, pf.x_of(p)


@pytest.mark.parametrize("orientation", ["normal_to_spar", "streamwise", "normal_to_midchord"])
def test_members_follow_the_planform(wing, orientation):
    lay = resolve(wing, layout(ribs={"count": 8, "orientation": orientation}))
    w = lay.station_wings[0]
    pf, up = w.planform, w.planform.up
    m = by_name(lay)
    assert list(m) == ["w/spar_0", "w/spar_1"] + [f"w/rib_{k}" for k in range(8)]
    for spec in m.values():
        assert abs(spec.plane_normal @ up) < 1e-12                      # every member plane contains up
        seeds = spec.seed_points(9)
        assert np.abs((seeds - spec.plane_point) @ spec.plane_normal).max() < 1e-9
        t = seeds @ pf.axis                                               # inside the wing and the station range
        assert (t >= pf.root - 1e-9).all() and (t <= pf.tip + 1e-9).all()
        hu, hl = pf.heights(t, pf.chord_fraction_at(t, pf.x_of(seeds)))
        v = (seeds - pf.chord_point(t, pf.chord_fraction_at(t, pf.x_of(seeds)))) @ up
        assert (v < hu).all() and (v > hl).all()
    # spars at their local chord fraction (straight within SPAR_TOL sizes on this trapezoid: exact)
    for j, c in enumerate((0.15, 0.65)):
        s = m[f"w/spar_{j}"].seed_points(21)
        t = s @ pf.axis
        assert np.abs(pf.chord_fraction_at(t, pf.x_of(s)) - c).max() * pf.chord(t).max() <= SPAR_TOL * SIZE
        assert m[f"w/spar_{j}"].bounds == ("w/rib_0", "w/rib_7")
    # root and tip ribs along their stations, the others as asked
    for k in (0, 7):
        assert abs(m[f"w/rib_{k}"].plane_normal @ pf.axis) == pytest.approx(1.0)
    rear = m["w/spar_1"].end - m["w/spar_1"].start
    rear = rear - (rear @ up) * up
    for k in range(1, 7):
        n = m[f"w/rib_{k}"].plane_normal
        if orientation == "streamwise":
            assert n @ pf.axis == pytest.approx(1.0)
        elif orientation == "normal_to_spar":
            assert abs(n @ rear) / np.linalg.norm(rear) == pytest.approx(1.0, abs=1e-9)
        # ribs end on the spar planes
        r = m[f"w/rib_{k}"]
        assert r.bounds == ("w/spar_0", "w/spar_1")
        for p, (q, nb) in zip((r.start, r.end), r.bound_planes):
            assert abs((p - q) @ nb) < 1e-9


def test_normal_to_spar_fans_out_at_the_root_of_a_swept_wing():
    """On a wing swept 45 deg with close ribs, ribs normal to the rear spar would cross the root and
    tip ribs: the ones that would come closer than half a spacing turn towards the station."""
    S = naca_wing(span=4.0, root_chord=1.0, tip_chord=1.0, sweep_deg=45.0, dihedral_deg=0.0)
    lay = resolve(S, {"wings": [dict(WING, root=0.1, tip=3.9, ribs={"count": 20})]}, size=0.05)
    pf = lay.station_wings[0].planform
    ribs = [s for s in lay.members() if "/rib_" in s.name]
    ang = [np.degrees(np.arccos(min(1.0, abs(r.plane_normal @ pf.axis)))) for r in ribs]
    assert ang[0] == pytest.approx(0.0, abs=1e-9) and ang[-1] == pytest.approx(0.0, abs=1e-9)
    assert max(ang) == pytest.approx(45.0, abs=0.5)                       # normal to the spar mid-span
    assert 0 < ang[1] < 45.0                                              # the fan
    ends = np.array([[r.start @ pf.axis, r.end @ pf.axis] for r in ribs])
    gap = np.diff(ends, axis=0).min(axis=1)
    assert (gap >= 0.5 * (3.8 / 19) - 1e-9).all()                         # half a spacing at both spars


def _fin(span, root_chord, tip_chord, sweep_deg, naca):
    """A fin: a swept NACA wing turned about x, its span along z (up lateral)."""
    from shellmesh_mdao.mesh import ShellMesh

    S = naca_wing(span=span, root_chord=root_chord, tip_chord=tip_chord, sweep_deg=sweep_deg, dihedral_deg=0.0,
                  naca=naca)
    return ShellMesh(S.points[:, [0, 2, 1]] * [1, -1, 1], S.faces, S.component, ["skin"])


def _rib_ends_on_spars(lay, wing):
    """Stations (along the span axis) where each rib meets its first and last spar: (n, 2)."""
    pf = next(w for w in lay.station_wings if w.name == wing).planform
    ribs = sorted((m for m in lay.members() if m.kind == "rib"), key=lambda m: m.index)
    return pf, np.array([[r.start @ pf.axis, r.end @ pf.axis] for r in ribs]), ribs


@pytest.mark.parametrize("end_ribs", ["same", "station"])
def test_ribs_of_a_short_highly_swept_fin_stay_apart(end_ribs):
    """A fin swept 60 deg, 1.4 long between its stations at element size 0.25 with four ribs normal
    to the rear spar: ribs normal to the spar reach across the whole station range, so the root
    and tip ribs (with end_ribs: same too) turn towards their stations until every two neighbours
    are at least half their spacing and an element size apart at both spars; the root and tip
    ribs still touch their stations, and the notes name the ribs turned."""
    fin = _fin(1.5, 2.5, 1.9, 60.0, "0016")
    d = {"wings": [{"name": "fin", "axis": "z", "root": 0.05, "tip": 1.45, "up": [0, 1, 0],
                    "ribs": {"count": 4, "orientation": "normal_to_spar", "end_ribs": end_ribs},
                    "spars": {"chord_fractions": [0.17, 0.5, 0.73]}}]}
    lay = resolve(fin, d, size=0.25)
    w = lay.station_wings[0]
    assert not w.close_pairs
    pf, ends, ribs = _rib_ends_on_spars(lay, "fin")
    gap = np.diff(ends, axis=0)
    assert (gap >= max(0.5 * 1.4 / 3, 0.25) - 1e-9).all(), gap                 # apart at both spars
    assert ends.min() == pytest.approx(0.05, abs=1e-9) and ends.max() == pytest.approx(1.45, abs=1e-9)
    assert ends[0].min() == pytest.approx(0.05, abs=1e-9)                       # the root rib touches the root
    assert ends[-1].max() == pytest.approx(1.45, abs=1e-9)                      # and the tip rib the tip station
    rear = next(m for m in lay.members() if m.name == "fin/spar_2")
    rear = (rear.end - rear.start) / np.linalg.norm(rear.end - rear.start)
    normal = [abs(r.plane_normal @ rear) > 1 - 1e-9 for r in ribs]
    assert not all(normal)                                                      # some turned ...
    turned = [r.name for r, nr in zip(ribs, normal) if not nr and (end_ribs == "same" or 0 < r.index < 3)]
    note = next(n for n in w.notes if "turned from normal_to_spar towards the station direction" in n)
    assert all(f"'{name}'" in note for name in turned)                          # ... and named
    if end_ribs == "same":
        assert "'fin/rib_0'" in note and "'fin/rib_3'" in note


def test_a_wing_too_short_for_a_box_at_the_size_says_so(wing):
    """Root and tip stations closer than 0.2 element sizes: the root and tip ribs coincide, the wing
    cannot carry a box at that size; the error says so and gives the size that would do."""
    with pytest.raises(LayoutError, match=r"wing 'w' is only 0\.01 long between its root and tip stations \(0\.100 "
                                          r"element sizes, .* too short for a wing box at that size; .*element size "
                                          r"below 0\.05"):
        resolve(wing, layout(root=3.0, tip=3.01, ribs={"count": 2}))


def _web_heights(lay, wing, size):
    """Smallest height (in element sizes) of each edge web (or piece of one) over its span, and its
    chord fraction."""
    pf = next(w for w in lay.station_wings if w.name == wing).planform
    out = {}
    for m in lay.members():
        if m.name.split("/part_")[0].endswith("_web"):
            p = m.seed_points(41)[1:-1]
            t = p @ pf.axis
            c = pf.chord_fraction_at(t, pf.x_of(p))
            out[m.name] = (float(pf.thickness(t, c).min()) / size, float(np.median(c)))
    return out


def test_edge_webs_go_where_the_wing_is_tall_enough():
    """A thin tail (NACA 0006, tip chord 0.6) with one spar at a coarse size: the webs' preferred
    place (the rear web at 0.76 of the chord) is less than 0.3 element sizes tall at the tip, so
    the rear web moves towards the spar to where it is tall enough (the web's place is the
    tool's choice, not the user's); at a size where no place between the edge and the spar is
    0.3 sizes tall, the webs go where they are tallest (the mesh refines around them: see
    test_project's thin-member tests); on a NACA 0001 tail, where no place is even 0.3 of the
    finest local size (0.1 element sizes) tall, the error says the wing is too thin for a box at
    that size and gives a size that does."""
    from shellmesh_mdao.layout import MIN_LOCAL_SIZE
    from shellmesh_mdao.layout.wingbox import MIN_WEB_HEIGHT, WEB_GAP

    tail = naca_wing(span=2.0, root_chord=1.0, tip_chord=0.6, sweep_deg=30.0, naca="0006")
    d = layout(root=0.05, tip=1.95, ribs={"count": 4}, spars={"chord_fractions": [0.35]})
    lay = resolve(tail, d, size=0.1)
    webs = _web_heights(lay, "w", 0.1)
    assert set(webs) == {"w/le_web", "w/te_web"}
    assert all(h >= MIN_WEB_HEIGHT for h, _ in webs.values()), webs
    assert 0.35 < webs["w/te_web"][1] < 0.7 and webs["w/le_web"][1] < 0.35     # each on its side of the spar
    assert (webs["w/te_web"][1] - 0.35) * 0.6 >= WEB_GAP * 0.1 - 1e-9          # apart from the spar
    assert any("edge webs" in n and "'w/te_web' at 0.5" in n for n in lay.station_wings[0].notes)
    webs = _web_heights(resolve(tail, d, size=0.2), "w", 0.2)                  # thin: refined, not refused
    assert all(MIN_WEB_HEIGHT * MIN_LOCAL_SIZE <= h < MIN_WEB_HEIGHT for h, _ in webs.values()), webs
    thinner = naca_wing(span=2.0, root_chord=1.0, tip_chord=0.6, sweep_deg=30.0, naca="0001")
    with pytest.raises(LayoutError, match=r"wing 'w': with fewer than two spars and a sharp trailing edge the ribs "
                                          r"end on edge webs, but between its leading edge and its spar at 0\.35 of "
                                          r"the chord the wing is nowhere at least 0\.03 element sizes .* too thin to "
                                          r"carry a box at element size 0\.25; use an element size of at most") as e:
        resolve(thinner, d, size=0.25)
    fit = float(str(e.value).split("of at most ")[1].split(",")[0])
    assert 0.05 < fit < 0.25
    lay = resolve(thinner, d, size=fit)                                         # the size given does
    assert all(h >= MIN_WEB_HEIGHT * MIN_LOCAL_SIZE for h, _ in _web_heights(lay, "w", fit).values())


def test_crank_kinks_the_spars(wing):
    S = naca_wing(crank=(0.4, 1.3), sweep_deg=20.0)
    # a rib meets the spar 0.04 from the crank: the kink moves to a station a size from it
    lay = resolve(S, layout(cranks=[2.4], ribs={"count": 6}))
    kink = by_name(lay)["w/spar_1/part_0"].end @ [0, 1, 0]
    assert kink != pytest.approx(2.4, abs=1e-6) and kink == pytest.approx(2.4, abs=2 * SIZE)
    lay = resolve(S, layout(cranks=[2.4], ribs={"count": 5}))           # no rib near the crank
    names = [m.name for m in lay.members()]
    assert "w/spar_1/part_0" in names and "w/spar_1/part_1" in names and "w/spar_1" not in names
    m = by_name(lay)
    a, b = m["w/spar_1/part_0"], m["w/spar_1/part_1"]
    assert a.end @ [0, 1, 0] == pytest.approx(2.4, abs=1e-9)             # the kink at the crank
    assert np.linalg.norm(a.end - b.start) < 1e-9 * 10
    assert b.bounds[0] == "w/spar_1/part_0" and a.bounds[1] == "w/spar_1/part_1"
    assert np.cross(a.plane_normal, b.plane_normal) @ [0, 0, 1] != pytest.approx(0.0, abs=1e-3)
    # both pieces at 65 % of the local chord at their ends
    pf = lay.station_wings[0].planform
    for p in (a.start, a.end, b.end):
        t = p @ pf.axis
        assert pf.chord_fraction_at(t, pf.x_of(p)) == pytest.approx(0.65, abs=0.01)


def test_spars_kink_at_ribs_that_crowd_a_crank():
    """Ribs within an element size of every station near a crank (none left for the kink): the
    spars kink as near the crank as half a size from the ribs allows, never on a rib, and stay on
    their chord fractions (the kink was dropped and a spar ran 1.6 sizes off its fraction, an edge
    web out of the wing: random-family seed 3)."""
    S = naca_wing(crank=(0.4, 1.3), sweep_deg=20.0)
    ribs_at = (2.26, 2.42, 2.56)
    eta = [0.0, 0.2] + [(t - 0.2) / 5.6 for t in ribs_at] + [0.7, 1.0]
    lay = resolve(S, layout(cranks=[2.4], ribs={"eta": eta, "orientation": "streamwise"}))
    pf = lay.station_wings[0].planform
    for j, frac in enumerate((0.15, 0.65)):
        pieces = sorted((m for m in lay.members() if m.name.startswith(f"w/spar_{j}/part_")),
                        key=lambda m: m.start @ pf.axis)
        kinks = [m.end @ pf.axis for m in pieces[:-1]]
        assert len(kinks) == 1 and abs(kinks[0] - 2.4) <= 2 * SIZE                      # crank 2.4
        assert min(abs(kinks[0] - t) for t in ribs_at) >= SIZE / 2 - 1e-9                # not on a rib
        for m in pieces:
            for s in np.linspace(0.0, 1.0, 41):
                p = m.start + s * (m.end - m.start)
                t = p @ pf.axis
                c = pf.chord_fraction_at(t, pf.x_of(p))
                off = abs(c - frac) * float(pf.chord(np.array([t]))[0])
                assert off <= SPAR_TOL * SIZE + 1e-9, (m.name, t, off)


def test_fewer_than_two_spars(wing):
    """Full-chord ribs where both edges are round or blunt; edge webs at a sharp edge."""
    lay = resolve(wing, layout(spars={"chord_fractions": [0.35]}, ribs={"count": 4}))
    w = lay.station_wings[0]
    assert [m.name for m in lay.members()][:3] == ["w/le_web", "w/spar_0", "w/te_web"]
    assert any("edge webs" in n and f"{MIN_EDGE_ANGLE:.1f}" in n for n in w.notes)
    blunt = naca_wing(te_thickness=0.12)                                 # a base above the element size
    lay = resolve(blunt, layout(spars={"chord_fractions": [0.35]}, ribs={"count": 4}))
    ribs = [m for m in lay.members() if "/rib_" in m.name]
    assert all(r.kind == "rib" and not r.bound_planes for r in ribs)     # closed sections
    assert not lay.station_wings[0].notes


def test_blunt_trailing_edge_below_the_element_size_is_sharp():
    """A blunt trailing edge whose base is lower than the element size is, at that size, the
    wedge of its upper and lower skin (the skin cannot hold the base): with one spar the ribs
    end on edge webs, not on that wedge; at a size below the base they are closed sections."""
    thin = naca_wing(te_thickness=0.03)                # base 0.06 at the root, 0.03 at the tip
    d = layout(spars={"chord_fractions": [0.35]}, ribs={"count": 4})
    assert resolve(thin, d).station_wings[0].planform.shapes[0].blunt
    lay = resolve(thin, d, size=0.1)
    assert [m.name for m in lay.members()][:3] == ["w/le_web", "w/spar_0", "w/te_web"]
    assert any("trailing edge is sharper" in n for n in lay.station_wings[0].notes)
    assert all(m.bound_planes for m in lay.members() if "/rib_" in m.name)  # the ribs end on the webs
    lay = resolve(thin, d, size=0.025)
    assert all(not m.bound_planes for m in lay.members() if "/rib_" in m.name)
    assert not lay.station_wings[0].notes


def test_checks_before_meshing(wing):
    # a spar 0.015 element sizes tall would need elements of 0.05 sizes: below the finest local size (0.1)
    with pytest.raises(LayoutError, match=r"spar 'w/spar_1' .* is only 0.0015\d+ tall .*0.015 element sizes: a web of "
                                          r"quads needs elements of at most 0.0051\d+ there .*below the smallest local "
                                          r"size the mesh refines to \(0.1 element sizes, 0.01\); move the spar away "
                                          r"from the trailing edge.* or use an element size below 0.0510"):
        resolve(wing, layout(spars={"chord_fractions": [0.15, 0.995]}))
    # 60 ribs 0.095 apart at size 0.1 are laid out (and meshed with smaller elements between them);
    # 400 coincide at that size: every pair is named
    assert not resolve(wing, layout(ribs={"count": 60})).station_wings[0].close_pairs
    with pytest.raises(LayoutError, match=r"members coincide or cross at element size 0.1 .*ribs 'w/rib_0' and 'w/rib_1' "
                                          r"are .* apart at a spar; .*ribs 'w/rib_398' and 'w/rib_399' are .* apart"):
        resolve(wing, layout(ribs={"count": 400}))
    two = {"wings": [dict(WING, name="a"), dict(WING, name="b", root=3.0, tip=5.0)]}
    with pytest.raises(LayoutError, match="wing 'a' reaches into wing 'b'|wing 'b' reaches into wing 'a'"):
        resolve(wing, two)


def test_corner_layouts_are_untouched(wing):
    from shellmesh_mdao.geometry import naca_wing_layout

    lay = load_layout(naca_wing_layout())
    assert resolve_layout(lay, wing.points, wing.faces[:, :3], SIZE) is lay


# ============================================================================ end to end
def test_station_wing_end_to_end(wing):
    from shellmesh_mdao.guarantees import check_guarantees
    from shellmesh_mdao.pipeline import run_pipeline

    r = run_pipeline(wing, layout(ribs={"count": 6}), SIZE, progress=False)
    g = check_guarantees(r)
    assert g["min_scaled_jacobian"] > 0.2
    names = set(r.mesh.component_names)
    assert {"w/spar_0", "w/spar_1", "w/rib_0", "w/rib_5"} <= names
    assert r.report["wings"]["w"]["root"] == pytest.approx(0.2)
    assert r.report["inputs"]["layout"]["wings"][0]["root"] == 0.2


def test_cranked_wing_with_a_thin_blunt_trailing_edge_meshes():
    """A swept, cranked wing whose blunt trailing edge is far lower than the element size (a CAD
    wing such as the uCRM) with one spar: its ribs end on edge webs and it meshes, every
    guarantee met (full-chord ribs through that edge were refused at the members stage: the
    rib outline on the skin has a corner of the edge's wedge, about 10 deg). The 5 % wing is
    less than 0.4 element sizes thick at its webs' preferred place (half its largest thickness,
    0.77 of the chord): there the remesh cuts across from the upper to the lower skin, and the
    rear web imprinted into those faces left an element of scaled Jacobian 0.1 (at size 0.1;
    at 0.09 its lower curve broke), so both webs stand where the wing is at least 0.4 element
    sizes thick."""
    from shellmesh_mdao.guarantees import check_guarantees
    from shellmesh_mdao.layout.wingbox import EDGE_WEB_HEIGHT
    from shellmesh_mdao.pipeline import run_pipeline

    S = naca_wing(naca="0005", te_thickness=0.003, tip_chord=1.2, crank=(0.35, 1.4), sweep_deg=30.0)
    d = layout(spars={"chord_fractions": [0.35]}, ribs={"count": 4})
    webs = _web_heights(resolve(S, d), "w", SIZE)
    assert {n.split("/part_")[0] for n in webs} == {"w/le_web", "w/te_web"}
    assert all(h >= EDGE_WEB_HEIGHT for h, _ in webs.values()), webs
    r = run_pipeline(S, d, SIZE, progress=False)
    assert check_guarantees(r)["min_scaled_jacobian"] > 0.2
    assert {"w/le_web", "w/te_web"} <= {n.split("/part_")[0] for n in r.mesh.component_names}
    assert any("edge webs" in n for n in r.report["wings"]["w"]["notes"])


def test_fin_and_fractions_along_the_span(wing):
    """A vertical fin (span along z, up lateral) is a wing like any other; spar fractions may vary
    from the root to the tip."""
    from shellmesh_mdao.mesh import ShellMesh

    P = wing.points[:, [0, 2, 1]] * [1, -1, 1]                           # turned about x: span along z
    fin = ShellMesh(P, wing.faces, wing.component, ["skin"])
    d = {"wings": [{"name": "fin", "axis": "z", "root": 0.3, "tip": 5.5, "up": [0, 1, 0],
                    "ribs": {"count": 5, "orientation": "streamwise"},
                    "spars": {"chord_fractions": [0.15, 0.65], "tip_chord_fractions": [0.25, 0.6]}}]}
    lay = resolve(fin, d)
    pf = lay.station_wings[0].planform
    assert abs(pf.up @ [0, 1, 0]) == pytest.approx(1.0)
    m = by_name(lay)
    for k in range(5):
        assert abs(m[f"fin/rib_{k}"].plane_normal @ [0, 0, 1]) == pytest.approx(1.0)
    for name, (c0, c1) in (("fin/spar_0", (0.15, 0.25)), ("fin/spar_1", (0.65, 0.6))):
        s = m[name]
        for p, c in ((s.start, c0), (s.end, c1)):
            t = p @ pf.axis
            assert pf.chord_fraction_at(t, pf.x_of(p)) == pytest.approx(c, abs=SPAR_TOL * SIZE / pf.chord(t))


def test_station_wing_skin_bays(wing):
    """A wing given by stations gets its skin bays, as a corner-given wing does: upper and lower
    skin between each pair of consecutive ribs, each on its side of the chord (face normals along
    +up on the upper bays, -up on the lower), the rest of the skin outside the box."""
    from shellmesh_mdao.families import bay_name
    from shellmesh_mdao.pipeline import run_pipeline

    r = run_pipeline(wing, layout(ribs={"count": 5, "orientation": "streamwise"}), SIZE, until="imprint",
                     progress=False)
    m = r.mesh
    names = list(m.component_names)
    n = m.face_normals()
    for k in range(4):
        for side, sign in (("upper", 1.0), ("lower", -1.0)):
            cid = names.index(bay_name("w", side, k))
            faces = m.component == cid
            assert faces.sum() > 10, (side, k)
            assert sign * (n[faces] @ np.array([0.0, 0.0, 1.0])).mean() > 0.9, (side, k)
    assert (m.component == names.index("skin")).any()
