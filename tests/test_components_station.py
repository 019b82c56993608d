"""The OpenMDAO components on wings given by stations, and the thickness families of every kind
of wing.

* ``family_names(layout)`` is the pipeline mesh's family list, in order: exactly for corner-given
  wings (the default wing; three spars and one spar, whose X-junction pieces the layout fixes)
  and for the wings ``shellmesh wings`` finds on the Cessna 210; for a station-given wing with a
  crank and one spar (edge webs; the spar and webs kinked at the crank, crossed by the ribs) the
  mesh's families reduce to it, each piece to its member, none left out;
* the layout inputs of station-given wings (``rib_eta``, ``spar_chord``, ``spar_chord_tip``,
  ``spar_chord_crank``) through ``Layout.with_parameters`` and ``LayoutComp``, and their errors;
* ShellMeshGroup + MassComp (+ CalculixShellAnalysis when ccx is installed) on a station-given
  wing end to end, at two design points whose spar pieces differ: the thickness vector keeps its
  order, each piece takes its member's thickness (mass, KS stress per member), check_partials.
"""
from __future__ import annotations

import copy

import numpy as np
import openmdao.api as om
import pytest
from openmdao.utils.assert_utils import assert_check_partials

from shellmesh_mdao.analysis import ANALYSIS_MATERIAL
from shellmesh_mdao.components.group import ShellMeshGroup
from shellmesh_mdao.components.layout_comp import LayoutComp, family_index, family_names, layout_input_names
from shellmesh_mdao.components.mass_comp import MassComp
from shellmesh_mdao.errors import LayoutError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.layout import load_layout, resolve_layout
from shellmesh_mdao.pipeline import run_pipeline

from conftest import _have_ccx, needs_ccx

SIZE = 0.2
SURFACE = naca_wing(n_chord=24, n_span=16)          # the default wing's shape, coarsely triangulated
#: a crank at 2.4 m, one spar from 30 % of the chord at the root to 40 % at the tip: the sharp
#: trailing edge gives the wing its two edge webs; spar and webs kink at the crank
STATION = {"wings": [{"name": "w", "axis": "y", "root": 0.2, "tip": 5.0, "up": [0, 0, 1], "cranks": [2.4],
                      "ribs": {"count": 5}, "spars": {"chord_fractions": [0.3], "tip_chord_fractions": [0.4]}}]}
#: rib 2 moved inboard of the crank: the inner spar part is crossed by two ribs, the outer by one
MOVED_ETA = [0.0, 0.25, 0.4, 0.75, 1.0]


def pieces(names) -> set:
    return {n for n in names if "/part_" in n or "/seg_" in n}


# ============================================================================ family_names
@pytest.mark.parametrize("layout", [naca_wing_layout(), naca_wing_layout(ribs=4, spars=(0.15, 0.4, 0.65)),
                                    naca_wing_layout(ribs=4, spars=(0.4,))], ids=["default", "3spars", "1spar"])
def test_family_names_of_corner_wings_are_the_mesh_families(layout):
    mesh = run_pipeline(SURFACE, layout, 0.25, until="members", progress=False).mesh
    names = family_names(layout)
    assert names == list(mesh.component_names)
    n_spars = len(layout["wings"][0]["spars"]["chord_fractions"])
    assert bool(pieces(names)) == (n_spars != 2)         # the crossed spar and the inner ribs in pieces


def test_family_names_of_the_wings_shellmesh_wings_finds(geometry_dir):
    from shellmesh_mdao.layout.finder import find_wings, starting_layout
    from shellmesh_mdao.load import load_surface

    surface, _ = load_surface(geometry_dir / "cessna210.stl")
    layout = starting_layout(find_wings(surface.points, surface.faces[:, :3], "y", size=0.5), ribs=4)
    assert len(layout["wings"]) == 4                      # wing and horizontal-tail halves
    r = run_pipeline(surface, layout, 0.5, until="members", progress=False)
    assert family_names(layout) == list(r.mesh.component_names) == family_names(r.layout)


@pytest.fixture(scope="module")
def group_run():
    """ShellMeshGroup + MassComp (+ CalculixShellAnalysis with ccx) on STATION, run at its own rib
    stations and at MOVED_ETA; the meshes, masses and analysis results of both points."""
    p = om.Problem(reports=False)
    p.model.add_subsystem("mesh", ShellMeshGroup(surface=SURFACE, layout=STATION, size=SIZE), promotes=["*"])
    p.model.add_subsystem("mass", MassComp(layout=STATION), promotes_inputs=["shell_mesh", "thickness"])
    if _have_ccx():
        from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis

        p.model.add_subsystem("fea", CalculixShellAnalysis(layout=STATION), promotes_inputs=["shell_mesh", "thickness"])
    p.setup(force_alloc_complex=True)
    names = family_names(STATION)
    t = np.linspace(0.001, 0.004, len(names))
    p.set_val("thickness", t)
    out = {"problem": p, "names": names, "t": t, "points": []}
    for eta in (None, MOVED_ETA):
        if eta is not None:
            p.set_val("w:rib_eta", eta)
        p.run_model()
        pt = {"mesh": p.get_val("shell_mesh"), "mass": float(p.get_val("mass.mass")[0])}
        if _have_ccx():
            pt.update(fea={k: np.array(p.get_val(f"fea.{k}")) for k in ("mass", "tip_deflection", "ks_von_mises")},
                      result=p.model.fea.last_result)
        out["points"].append(pt)
    return out


def test_family_names_of_a_station_wing_with_a_crank_and_one_spar(group_run):
    names = family_names(STATION)
    mesh = group_run["points"][0]["mesh"]
    mesh_names = list(mesh.component_names)
    pos = family_index(names, mesh_names)
    # every mesh family is a listed family or a piece of one (a part, a part's segment) ...
    assert (pos >= 0).all()
    assert all(n == names[i] or n.startswith(names[i] + "/") for n, i in zip(mesh_names, pos))
    # ... and the listed families are the mesh's, in the pipeline's order, none left out
    assert list(dict.fromkeys(names[i] for i in pos)) == names
    assert names[:4] == ["skin", "w/le_web", "w/spar_0", "w/te_web"]
    assert {"w/le_web/part_1", "w/spar_0/part_1/seg_0", "w/te_web/part_0", "w/rib_1/seg_1"} <= set(mesh_names)
    # the layout resolved against the skin (it has its webs) gives the same families
    lay = resolve_layout(load_layout(STATION), SURFACE.points, SURFACE.faces[:, :3], SIZE)
    assert lay.station_wings[0].resolved and family_names(lay) == names
    # without two spars an unresolved wing lists its edge webs; with two it has none
    two = copy.deepcopy(STATION)
    two["wings"][0]["spars"] = {"chord_fractions": [0.15, 0.6]}
    assert family_names(two)[:4] == ["skin", "w/spar_0", "w/spar_1", "w/rib_0"]


# ============================================================================ layout inputs
def _three_station_fractions() -> dict:
    d = copy.deepcopy(STATION)
    d["wings"][0]["spars"] = {"chord_fractions": [0.15, 0.6], "tip_chord_fractions": [0.2, 0.55],
                              "crank_chord_fractions": [[0.18, 0.58]]}
    d["wings"].insert(0, naca_wing_layout(ribs=3, name="fin")["wings"][0])
    d["up"] = [0, 0, 1]
    return d


def test_station_wing_layout_inputs():
    d = _three_station_fractions()
    inputs = layout_input_names(d)
    assert list(inputs) == ["fin:rib_eta", "fin:spar_chord", "w:rib_eta", "w:spar_chord", "w:spar_chord_tip",
                            "w:spar_chord_crank"]
    assert inputs["w:spar_chord_crank"][2].tolist() == [[0.18, 0.58]]
    p = om.Problem(reports=False)
    p.model.add_subsystem("lay", LayoutComp(layout=d), promotes=["*"])
    p.setup()
    np.testing.assert_array_equal(p.get_val("w:rib_eta"), np.linspace(0, 1, 5))
    p.set_val("w:rib_eta", MOVED_ETA)
    p.set_val("w:spar_chord", [0.2, 0.62])
    p.set_val("w:spar_chord_tip", [0.25, 0.5])
    p.set_val("w:spar_chord_crank", [[0.21, 0.57]])
    p.run_model()
    lay = p.get_val("layout")
    w = lay.station_wings[0]
    assert (w.rib_eta, w.rib_count, w.spar_chord, w.spar_chord_tip, w.spar_chord_cranks) == \
        (tuple(MOVED_ETA), None, (0.2, 0.62), (0.25, 0.5), ((0.21, 0.57),))
    base = load_layout(d)
    assert (w.axis, w.root, w.tip, w.cranks) == (base.station_wings[0].axis, 0.2, 5.0, (2.4,))
    fin = lay.wings[0]                                    # the corner-given wing keeps its values
    assert (fin.rib_eta, fin.spar_chord, fin.root_le) == (base.wings[0].rib_eta, base.wings[0].spar_chord,
                                                          base.wings[0].root_le)
    assert load_layout(lay.to_dict()) == lay
    p.run_model()
    assert p.get_val("layout") is lay                     # same inputs -> the same object
    # an invalid design point of a station-given wing is a failed case naming the input
    p.set_val("w:spar_chord_tip", [0.5, 0.25])
    with pytest.raises(om.AnalysisError, match=r"spar_chord_tip\['w'\]\[1\] = 0.25 is not greater than"):
        p.run_model()


def test_with_parameters_of_station_wings():
    d = _three_station_fractions()
    lay = load_layout(d)
    eta, chord = lay.parameters()
    assert set(eta) == set(chord) == {"fin", "w"} and chord["w"].tolist() == [0.15, 0.6]
    # a wing resolved against the skin is laid out again when its values change, kept otherwise
    res = resolve_layout(lay, SURFACE.points, SURFACE.faces[:, :3], SIZE)
    assert res.station_wings[0].resolved
    assert res.with_parameters(rib_eta={"fin": [0.0, 0.4, 1.0]}).station_wings[0].resolved
    moved = res.with_parameters(rib_eta={"w": MOVED_ETA})
    assert not moved.station_wings[0].resolved and moved.member_names() == lay.member_names()
    for kw, match in [
        (dict(rib_eta={"w": [0, 0.5, 1]}), r"rib_eta\['w'\] has 3 entries but the wing has 5 ribs"),
        (dict(spar_chord_tip={"w": [0.3]}), r"spar_chord_tip\['w'\] has 1 entries but the wing has 2 spars"),
        (dict(spar_chord_cranks={"w": [[0.2, 0.5], [0.3, 0.6]]}), r"has 4 values but the wing has 1 crank"),
        (dict(spar_chord_cranks={"w": [[0.2, 1.5]]}), r"spar_chord_cranks\['w'\]\[0\]\[1\] = 1.5 is outside"),
        (dict(spar_chord_tip={"fin": [0.2, 0.6]}), "names wing 'fin', which has no tip chord fractions"),
        (dict(spar_chord={"ww": [0.2, 0.6]}), "unknown wing 'ww'"),
    ]:
        with pytest.raises(LayoutError, match=match):
            lay.with_parameters(**kw)
    plain = copy.deepcopy(STATION)                        # fractions constant along the span: no tip input
    plain["wings"][0]["spars"] = {"chord_fractions": [0.3]}
    assert list(layout_input_names(plain)) == ["w:rib_eta", "w:spar_chord"]
    with pytest.raises(LayoutError, match="names wing 'w', which has no tip chord fractions"):
        load_layout(plain).with_parameters(spar_chord_tip={"w": [0.35]})
    with pytest.raises(LayoutError, match="names wing 'w', which has no crank chord fractions"):
        load_layout(STATION).with_parameters(spar_chord_cranks={"w": [[0.35]]})


# ============================================================================ the group end to end
def test_group_and_mass_on_a_station_wing(group_run):
    p, names, t = group_run["problem"], group_run["names"], group_run["t"]
    (a, b) = group_run["points"]
    assert p.model.mesh.family_names == names and p.model.mass.family_names == names
    assert p.model.mesh.layout_inputs == ["w:rib_eta", "w:spar_chord", "w:spar_chord_tip"]
    # the moved rib changes the spar's pieces, not the thickness vector's order
    assert pieces(a["mesh"].component_names) != pieces(b["mesh"].component_names)
    assert p.get_val("thickness").shape == (len(names),)
    for pt in (a, b):
        m = pt["mesh"]
        assert m.n_tris == 0
        pos = family_index(names, m.component_names)
        expect = ANALYSIS_MATERIAL["rho"] * float((m.face_areas() * t[pos[m.component]]).sum())
        assert pt["mass"] == pytest.approx(expect, rel=1e-12)
    # the group's mesh at the moved design point is the pipeline's mesh of that layout
    moved = copy.deepcopy(STATION)
    moved["wings"][0]["ribs"] = {"eta": MOVED_ETA}
    ref = run_pipeline(SURFACE, moved, SIZE, progress=False).mesh
    m = b["mesh"]
    assert np.array_equal(m.points, ref.points) and np.array_equal(m.faces, ref.faces)
    assert m.component_names == ref.component_names and np.array_equal(m.component, ref.component)
    data = p.check_partials(includes=["mass"], out_stream=None, method="cs")
    assert_check_partials(data, atol=1e-8, rtol=1e-10)


@needs_ccx
def test_calculix_on_a_station_wing(group_run):
    p, names, t = group_run["problem"], group_run["names"], group_run["t"]
    spar = names.index("w/spar_0")
    for pt in group_run["points"]:
        m, r, fea = pt["mesh"], pt["result"], pt["fea"]
        assert fea["mass"][0] == pytest.approx(pt["mass"], rel=1e-12)
        # the root station's cap is clamped (the span axis of the station-given wing), the tip rises
        assert np.abs(m.points[r.clamped, 1]).max() < 1e-6 and fea["tip_deflection"][0] > 0
        # KS per member over all its pieces
        pos = family_index(names, m.component_names)[m.component]
        mine = (pos == spar) & ~r.in_clamp_band                 # the stress outputs leave out the clamp band
        vmax = r.von_mises[mine].max()
        assert vmax <= fea["ks_von_mises"][spar] <= vmax * (1 + np.log(mine.sum()) / 50)
    # the spar's thickness reaches every piece: a thicker spar adds its pieces' area x dt of mass
    fea = p.model.fea
    assert spar in fea._nonempty                          # its finite-difference partials are declared
    m = group_run["points"][-1]["mesh"]
    pos = family_index(names, m.component_names)[m.component]
    t2 = t.copy()
    t2[spar] += 0.002
    p.set_val("thickness", t2)
    p.run_model()
    area = float(m.face_areas()[pos == spar].sum())
    assert p.get_val("fea.mass")[0] - group_run["points"][-1]["fea"]["mass"][0] == \
        pytest.approx(ANALYSIS_MATERIAL["rho"] * area * 0.002, rel=1e-9)
    assert p.get_val("fea.tip_deflection")[0] < group_run["points"][-1]["fea"]["tip_deflection"][0]
    assert p.model.mesh.quad.n_runs == 2                  # a thickness change re-meshes nothing
    p.set_val("thickness", t)
