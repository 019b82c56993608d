"""The morph (shellmesh_mdao.morph, components.MorphComp): a finished mesh follows moved ribs and spars
with its connectivity unchanged.

* the reference layout gives the reference mesh bit for bit, and the morph is continuous there;
* moved ribs and spars: every member node on its member's new plane (the plane the layout gives),
  every skin node on the input surface (as far from it as at the reference, no farther), every
  element above the README's scaled Jacobian 0.2;
* the derivatives of the node coordinates (complex step) equal central differences;
* the mass follows a rib move smoothly (the pipeline's new mesh per point jumped by 75 times the
  trend per step between neighbouring points);
* MorphComp + MassComp on ``x_struct0``: compute_totals of the mass with respect to rib stations and
  spar chord fractions equals central differences; check_partials of both components;
* a morph that misses its checks is a new mesh of the moved layout (``remeshed`` = 1) or a failed
  case; layouts the morph does not follow are refused by name.
"""
from __future__ import annotations

import copy

import numpy as np
import openmdao.api as om
import pytest
from openmdao.utils.assert_utils import assert_check_partials

from conftest import needs_ccx
from shellmesh_mdao import load_layout, naca_wing, naca_wing_layout, run_pipeline
from shellmesh_mdao.components import MassComp, MorphComp
from shellmesh_mdao.errors import LayoutError
from shellmesh_mdao.morph import morph, morph_jacobian, morph_parameters, morph_reference

SIZE = 0.1


@pytest.fixture(scope="module")
def ref():
    return morph_reference(naca_wing(), naca_wing_layout(), SIZE)


@pytest.fixture(scope="module")
def ref_inner():
    """A coarser reference whose end ribs are inside (0, 1), so every input can be stepped both ways."""
    lay = naca_wing_layout(ribs=5)
    lay["wings"][0]["ribs"] = {"eta": [0.05, 0.3, 0.5, 0.7, 0.95]}
    return morph_reference(naca_wing(), lay, 0.2)


def _moved(ref, d_rib=0.0, d_spar=0.0, rib=3, spar=0):
    eta, ch = ref.parameters()["wing"]
    eta, ch = eta.copy(), ch.copy()
    eta[rib] += d_rib
    ch[spar] += d_spar
    return {"wing": (eta, ch)}


def test_reference_layout_gives_the_reference_mesh_bit_for_bit(ref):
    x, chk = morph(ref)
    assert chk.ok
    assert np.array_equal(x, ref.mesh.points)
    x2, _ = morph(ref, morph_parameters(ref, naca_wing_layout()))
    assert np.array_equal(x2, ref.mesh.points)


def test_morph_is_continuous_at_the_reference(ref):
    for d in (1e-9, -1e-9):
        for kw in ({"d_rib": d}, {"d_spar": d}):
            x, _ = morph(ref, _moved(ref, **kw), check=False)
            assert np.abs(x - ref.mesh.points).max() < 1e-7, kw


@pytest.mark.parametrize("d_rib,d_spar", [(0.02, 0.0), (-0.02, 0.0), (0.0, 0.02), (0.0, -0.02), (0.04, 0.04)])
def test_moved_members_keep_every_node_on_its_support(ref, d_rib, d_spar):
    params = _moved(ref, d_rib, d_spar)
    x, chk = morph(ref, params)
    assert chk.ok, chk.reason
    assert chk.min_scaled_jacobian > 0.2
    moved = np.any(x != ref.mesh.points, axis=1)
    assert moved.sum() > 500
    # member nodes on the planes of the moved layout (its own MemberSpecs)
    specs = {s.name: s for s in ref.layout_for(params).members()}
    m = ref.mesh
    diag = m.diagonal
    for ci, name in enumerate(m.component_names):
        if name not in specs:
            continue
        s = specs[name]
        nodes = np.unique(m.faces[m.component == ci])
        nodes = nodes[nodes >= 0]
        dist = np.abs((x[nodes] - s.plane_point) @ s.plane_normal)
        assert dist.max() < 1e-9 * diag, name
    # skin nodes on the input surface stay on it; those planarize moved off it stay within its bound
    skin = np.flatnonzero(moved & (ref.kind != 2))
    d_now = ref.locator.closest(x[skin])[2]
    d_ref = ref.locator.closest(ref.mesh.points[skin])[2]
    on = d_ref < 1e-6 * diag
    assert on.sum() > 0.5 * len(skin)
    assert (d_now[on] < 1e-6 * diag).all()
    assert (d_now <= ref.options.quad.planar_offset * SIZE + 1e-6 * diag).all()


def test_jacobian_equals_central_differences(ref):
    J = morph_jacobian(ref)
    h = 1e-7
    for name, pos, i in (("wing:rib_eta", 0, 3), ("wing:rib_eta", 0, 6), ("wing:spar_chord", 1, 0),
                         ("wing:spar_chord", 1, 1)):
        base = ref.parameters()["wing"]
        plus = [base[0].copy(), base[1].copy()]
        minus = [base[0].copy(), base[1].copy()]
        plus[pos][i] += h
        minus[pos][i] -= h
        xp, _ = morph(ref, {"wing": tuple(plus)}, check=False)
        xm, _ = morph(ref, {"wing": tuple(minus)}, check=False)
        fd = ((xp - xm) / (2 * h)).reshape(-1)
        assert np.abs(J[name][:, i]).max() > 0.1
        assert np.abs(J[name][:, i] - fd).max() < 1e-6 * np.abs(fd).max(), (name, i)


def test_mass_follows_a_rib_smoothly(ref):
    """11 points over +-0.02 of rib 3's station: the largest step of the skin + member area between
    neighbouring points is within twice the trend per step."""
    m = ref.mesh
    areas = []
    for d in np.linspace(-0.02, 0.02, 11):
        x, chk = morph(ref, _moved(ref, d_rib=d))
        assert chk.ok
        from dataclasses import replace

        areas.append(replace(m, points=x).face_areas().sum())
    steps = np.diff(areas)
    trend = (areas[-1] - areas[0]) / 10
    assert abs(trend) > 0
    assert np.abs(steps).max() <= 2 * abs(trend)


def _problem(ref, **kw):
    p = om.Problem()
    p.model.add_subsystem("morph", MorphComp(reference=ref, **kw), promotes=["*"])
    p.model.add_subsystem("mass", MassComp(mesh=ref.mesh, coordinates=True), promotes=["*"])
    p.setup(force_alloc_complex=True)
    return p


def test_component_totals_and_partials(ref_inner):
    p = _problem(ref_inner)
    p.run_model()
    assert p["remeshed"][0] == 0
    assert (p["n_nodes"][0], p["n_elements"][0]) == (ref_inner.n_points, ref_inner.mesh.n_faces)
    assert p["mass"][0] == pytest.approx(2700 * 0.002 * ref_inner.mesh.face_areas().sum(), rel=1e-12)
    tot = p.compute_totals(["mass"], ["wing:rib_eta", "wing:spar_chord"])
    h = 1e-6
    for name in ("wing:rib_eta", "wing:spar_chord"):
        base = p[name].copy()
        fd = []
        for i in range(len(base)):
            vals = []
            for s in (h, -h):
                v = base.copy()
                v[i] += s
                p[name] = v
                p.run_model()
                vals.append(p["mass"][0])
            fd.append((vals[0] - vals[1]) / (2 * h))
        p[name] = base
        fd = np.array(fd)
        assert np.allclose(tot["mass", name][0], fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max()), name
    p.run_model()
    data = p.check_partials(out_stream=None, method="fd", step=1e-7, form="central", includes=["morph"])
    checked = 0
    for key, val in data["morph"].items():
        if key[0] != "x_struct0":
            continue
        J, Jfd = np.asarray(val["J_fwd"]), np.asarray(val["J_fd"])
        assert np.abs(J - Jfd).max() < 1e-6 * np.abs(J).max(), key
        checked += 1
    assert checked == 2


def test_mass_partials_with_respect_to_the_coordinates():
    """MassComp(coordinates=True) on quads and a triangle: partials exact (complex step), mass as
    shell_mass's."""
    from shellmesh_mdao.analysis import shell_mass
    from shellmesh_mdao.mesh import ShellMesh

    rng = np.random.default_rng(0)
    m = ShellMesh(rng.random((7, 3)), np.array([[0, 1, 2, 3], [2, 3, 4, -1], [1, 4, 5, 6]]),
                  component=np.array([0, 1, 0]), component_names=["a", "b"])
    p = om.Problem()
    p.model.add_subsystem("mass", MassComp(mesh=m, coordinates=True), promotes=["*"])
    p.setup(force_alloc_complex=True)
    x = m.points + 0.05 * rng.standard_normal(m.points.shape)
    p["x_struct0"] = x.reshape(-1)
    p["thickness"] = [0.002, 0.003]
    p.run_model()
    from dataclasses import replace

    assert p["mass"][0] == pytest.approx(shell_mass(replace(m, points=x), [0.002, 0.003], 2700.0), rel=1e-13)
    assert_check_partials(p.check_partials(out_stream=None, method="cs"), atol=1e-10, rtol=1e-10)
    with pytest.raises(Exception, match="coordinates=True needs the option mesh"):
        q = om.Problem()
        q.model.add_subsystem("mass", MassComp(coordinates=True, family_names=["skin"]))
        q.setup()


def test_a_morph_that_misses_its_checks_is_a_new_mesh_or_a_failed_case(ref_inner):
    p = _problem(ref_inner, min_scaled_jacobian=0.99)      # every moved mesh misses this
    eta = ref_inner.parameters()["wing"][0].copy()
    eta[2] += 0.02
    p["wing:rib_eta"] = eta
    p.run_model()
    assert p["remeshed"][0] == 1
    new = p.model.morph._discrete_outputs["shell_mesh"]
    want = run_pipeline(naca_wing(), ref_inner.layout_for(_moved(ref_inner, d_rib=0.02, rib=2)), 0.2,
                        progress=False).mesh
    assert np.array_equal(new.points, want.points) and np.array_equal(new.faces, want.faces)
    assert len(p["x_struct0"]) == 3 * ref_inner.n_points
    assert (p["n_nodes"][0], p["n_elements"][0]) == (want.n_points, want.n_faces) != (ref_inner.n_points,
                                                                                       ref_inner.mesh.n_faces)
    q = _problem(ref_inner, min_scaled_jacobian=0.99, on_failure="error")
    q["wing:rib_eta"] = eta
    with pytest.raises(om.AnalysisError, match="misses its checks"):
        q.run_model()


def test_layout_the_pipeline_refuses_is_a_failed_case(ref_inner):
    p = _problem(ref_inner)
    eta = ref_inner.parameters()["wing"][0].copy()
    eta[1], eta[2] = eta[2], eta[1]
    p["wing:rib_eta"] = eta
    with pytest.raises(om.AnalysisError, match="LayoutError"):
        p.run_model()


def test_layouts_the_morph_does_not_follow_are_refused():
    d = copy.deepcopy(naca_wing_layout())
    d["members"] = [{"name": "extra", "upper": [[0.6, 1.0, 0.3], [0.6, 2.0, 0.3]],
                     "lower": [[0.6, 1.0, -0.3], [0.6, 2.0, -0.3]]}]
    with pytest.raises(LayoutError, match="explicit members"):
        morph_reference(naca_wing(), load_layout(d), SIZE)
    with pytest.raises(LayoutError, match="rib stations"):
        ref_params = {"wing:rib_eta": [0.0, 0.5, 1.0]}
        morph_parameters(_FakeRef(), **ref_params)


class _FakeRef:
    """The parameters of the default layout, for the count check of morph_parameters."""

    def __init__(self):
        w = load_layout(naca_wing_layout()).wings[0]
        self.wings = [type("W", (), {"name": w.name, "rib_eta": np.array(w.rib_eta), "spar_chord":
                                     np.array(w.spar_chord)})()]

    def parameters(self):
        return {w.name: (w.rib_eta.copy(), w.spar_chord.copy()) for w in self.wings}


@needs_ccx
def test_analysis_on_the_morphed_coordinates_has_layout_derivatives(ref_inner):
    """CalculixShellAnalysis(coordinates=True) on x_struct0: the same results as on the discrete morphed
    mesh, and compute_totals of the tip deflection and the KS stresses with respect to the rib stations
    and spar fractions (finite differences of the whole model over the morph, steps 1e-3 and 5e-4) agree
    within 1 % (tip deflection) and 2 % (KS stresses) of their largest entry."""
    from shellmesh_mdao.components import CalculixShellAnalysis
    from shellmesh_mdao.components.layout_comp import family_names

    lay = ref_inner.layout
    eta = ref_inner.parameters()["wing"][0].copy()
    eta[2] += 0.01

    def model(coords: bool, step: float = 1e-3):
        p = om.Problem(reports=False)
        p.model.add_subsystem("morph", MorphComp(reference=ref_inner, on_failure="error"), promotes=["*"])
        if coords:
            fea = CalculixShellAnalysis(mesh=ref_inner.mesh, coordinates=True, layout=lay)
            p.model.add_subsystem("fea", fea, promotes_inputs=["x_struct0"])
        else:
            fea = CalculixShellAnalysis(layout=lay, family_names=family_names(lay))
            p.model.add_subsystem("fea", fea)
            p.model.connect("shell_mesh", "fea.shell_mesh")
        p.model.approx_totals(method="fd", step=step, form="central")
        p.setup()
        p["wing:rib_eta"] = eta
        p.run_model()
        return p

    a, b = model(True), model(False)
    for k in ("tip_deflection", "max_von_mises", "ks_von_mises", "mass"):
        assert np.allclose(a[f"fea.{k}"], b[f"fea.{k}"], rtol=1e-12), k
    outs = ["fea.tip_deflection", "fea.ks_von_mises"]
    t1 = a.compute_totals(outs, ["wing:rib_eta", "wing:spar_chord"])
    t2 = model(True, step=5e-4).compute_totals(outs, ["wing:rib_eta", "wing:spar_chord"])
    for key in t1:
        d1, d2 = np.asarray(t1[key]), np.asarray(t2[key])
        assert np.abs(d1).max() > 0, key
        # within 1 % (tip deflection) and 2 % (KS stresses, element by element: a node crossing an edge of
        # the faceted input is a kink of the slope) of the largest entry
        tol = 1e-2 if "tip" in key[0] else 2e-2
        assert np.abs(d1 - d2).max() <= tol * np.abs(d1).max(), key


def test_each_wing_of_a_two_wing_aircraft_follows_its_own_ribs(geometry_dir, manifest):
    """The corpus's swept wing pair (right and left wing meeting at the centreline), 10 ribs each: a rib
    of either wing moved by +-0.02 moves that wing's nodes only (the other wing's nodes stay bit for
    bit), every member node on its new plane, every element above 0.2."""
    from shellmesh_mdao.layout import layout_from_manifest

    lay = layout_from_manifest(manifest, "swept_wing", ribs=10, spars=[0.15, 0.65])
    w = lay.wings[0]
    size = float(np.linalg.norm(np.asarray(w.tip_le) - np.asarray(w.root_le))) / 40
    ref = morph_reference(geometry_dir / manifest["geometries"]["swept_wing"]["file"], lay, size)
    assert [W.name for W in ref.wings] == ["right_wing", "left_wing"]
    m = ref.mesh
    for wi, W in enumerate(ref.wings):
        for d in (0.02, -0.02):
            p = ref.parameters()
            eta = p[W.name][0].copy()
            eta[4] += d
            p[W.name] = (eta, p[W.name][1])
            x, chk = morph(ref, p)
            assert chk.ok, (W.name, d, chk.reason)
            moved = np.any(x != m.points, axis=1)
            assert moved.sum() > 100
            assert (ref.wing_of[moved] == wi).all()
            specs = {s.name: s for s in ref.layout_for(p).members()}
            checked = 0
            for ci, name in enumerate(m.component_names):
                nodes = np.unique(m.faces[m.component == ci])
                if name in specs and len(nodes):
                    dist = np.abs((x[nodes] - specs[name].plane_point) @ specs[name].plane_normal)
                    assert dist.max() < 1e-9 * m.diagonal, name
                    checked += 1
            assert checked >= 20


def test_a_node_on_a_sharp_trailing_edge_is_on_the_triangles_of_both_sides():
    """The facing check: a skin node on the sharp trailing edge whose ray lands on the other side's triangle
    (within rounding of the edge) lies on a triangle facing its own side too, and the morph passes; the same
    node 1e-3 m off the edge is on no facing triangle."""
    from shellmesh_mdao.morph import MEMBER_NODE, evaluate, on_facing_triangle
    from shellmesh_mdao.morph.place import tri_frame

    r = morph_reference(naca_wing(n_chord=24, n_span=16), naca_wing_layout(ribs=3), 0.25)
    params = {"wing": (np.array([0.0, 0.46372033759818315, 1.0]), np.array([0.15084676374380224, 0.6404302573099999]))}
    x, ch, _, _ = evaluate(r, params, None)
    moved = np.flatnonzero(np.any(x != r.mesh.points, axis=1) & (r.kind != MEMBER_NODE))
    ray = moved[~(r.feature[moved] | ch.closest[moved] | r.facing_away[moved])]
    nt = tri_frame(r, ch.skin_tri[ray])[3]
    away = ray[(nt * r.skin_normals[ray]).sum(1) <= 0]
    assert len(away) >= 1
    assert np.allclose(r.c[away], 1.0, atol=1e-9)                        # on the trailing edge
    assert on_facing_triangle(r, away, ch.skin_tri[away], x[away], 1e-9 * r.mesh.diagonal).all()
    off = x[away] - 1e-3 * r.skin_normals[away]                          # 1 mm off the edge
    assert not on_facing_triangle(r, away, ch.skin_tri[away], off, 1e-9 * r.mesh.diagonal).any()
    _, chk = morph(r, params)
    assert chk.ok and chk.n_flipped == 0, chk.reason
