"""The OpenMDAO stage components, one by one, on a small wing.

Every component runs in its own ``om.Problem`` on the state the pipeline functions give
before its stage, and must give exactly (bit for bit) the pipeline's state after it; plus
each component's own behaviour: LayoutComp's inputs and failed design points
(``om.AnalysisError``), ProjectionComp's load cache and user errors, ImprintComp's remesh
cache (a hit gives the same mesh as a fresh remesh, the cached arrays are read-only),
memoization of unchanged inputs, QuadComp's derived outputs, and MassComp with the mesh as
the discrete input ``shell_mesh`` (value and check_partials).
"""
from __future__ import annotations

import numpy as np
import openmdao.api as om
import pytest
from openmdao.utils.assert_utils import assert_check_partials

from shellmesh_mdao import pipeline as pl
from shellmesh_mdao.components.imprint_comp import ImprintComp
from shellmesh_mdao.components.layout_comp import LayoutComp, family_names
from shellmesh_mdao.components.mass_comp import MassComp
from shellmesh_mdao.components.member_mesh_comp import MemberMeshComp
from shellmesh_mdao.components.merge_comp import MergeComp
from shellmesh_mdao.components.projection_comp import ProjectionComp
from shellmesh_mdao.components.quad_comp import QuadComp
from shellmesh_mdao.components.smooth_comp import SmoothComp
from shellmesh_mdao.components.split_comp import SplitComp
from shellmesh_mdao.errors import InputFileError, LayoutError, ShellMeshError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.layout import load_layout
from shellmesh_mdao.quality import scaled_jacobian

SIZE = 0.25
SURFACE = naca_wing(n_chord=24, n_span=16)          # the default wing's shape, coarsely triangulated
LAYOUT = naca_wing_layout(ribs=3)                   # 3 ribs, spars at 15 % and 65 % chord


@pytest.fixture(autouse=True)
def _openmdao_out(tmp_path, monkeypatch):
    monkeypatch.setenv("OPENMDAO_WORKDIR", str(tmp_path))     # OpenMDAO's <name>_out folders


@pytest.fixture(scope="module")
def states():
    """The pipeline's state after every stage (stage functions called directly)."""
    st = pl.stage_load(SURFACE, SIZE)
    out = {"load": st}
    st = pl.stage_layout(st, LAYOUT)
    out["layout"] = st
    for name in pl.STAGES[2:]:
        st = pl.run_stage(st, name)
        out[name] = st
    return out


def same_mesh(a, b) -> bool:
    return (np.array_equal(a.points, b.points) and np.array_equal(a.faces, b.faces)
            and np.array_equal(a.component, b.component) and a.component_names == b.component_names
            and np.array_equal(a.feature_edges, b.feature_edges))


def run_comp(comp, state_in=None, layout=None):
    """Run one stage component in a Problem fed by a discrete IndepVarComp; returns the problem."""
    p = om.Problem(reports=False)
    ivc = p.model.add_subsystem("src", om.IndepVarComp())
    if layout is not None:
        ivc.add_discrete_output("layout", val=None)
        p.model.add_subsystem("c", comp)
        p.model.connect("src.layout", "c.layout")
    else:
        ivc.add_discrete_output("state", val=None)
        p.model.add_subsystem("c", comp)
        p.model.connect("src.state", "c.state_in")
    p.setup()
    p.set_val("src.layout" if layout is not None else "src.state", layout if layout is not None else state_in)
    p.run_model()
    return p


# ----------------------------------------------------------------------------- LayoutComp
def test_layout_comp_inputs_and_failed_design_point():
    p = om.Problem(reports=False)
    p.model.add_subsystem("lay", LayoutComp(layout=LAYOUT), promotes=["*"])
    p.setup()
    # inputs <wing>:rib_eta and <wing>:spar_chord, initialised from the layout (counts fixed)
    np.testing.assert_array_equal(p.get_val("wing:rib_eta"), [0.0, 0.5, 1.0])
    np.testing.assert_array_equal(p.get_val("wing:spar_chord"), [0.15, 0.65])
    p.run_model()
    first = p.get_val("layout")
    base = load_layout(LAYOUT)
    assert first.wings[0].rib_eta == base.wings[0].rib_eta and first.wings[0].spar_chord == base.wings[0].spar_chord
    assert first.wings[0].root_le == base.wings[0].root_le and first.up == base.up
    p.run_model()
    assert p.get_val("layout") is first                   # same inputs -> the same object
    p.set_val("wing:rib_eta", [0.0, 0.3, 1.0])
    p.set_val("wing:spar_chord", [0.2, 0.6])
    p.run_model()
    lay = p.get_val("layout")
    assert lay.wings[0].rib_eta == (0.0, 0.3, 1.0) and lay.wings[0].spar_chord == (0.2, 0.6)
    # an invalid design point is a failed case, not a crash: AnalysisError naming the fix
    p.set_val("wing:rib_eta", [0.0, 0.9, 0.3])
    with pytest.raises(om.AnalysisError, match=r"LayoutError: rib_eta\['wing'\]\[2\] = 0.3 is out of order"):
        p.run_model()
    p.set_val("wing:spar_chord", [0.2, 1.2])
    p.set_val("wing:rib_eta", [0.0, 0.5, 1.0])
    with pytest.raises(om.AnalysisError, match=r"outside \(0, 1\)"):
        p.run_model()


def test_layout_comp_rejects_wing_names_openmdao_cannot_use():
    bad = naca_wing_layout(ribs=3, name="wing.1")
    p = om.Problem(reports=False)
    p.model.add_subsystem("lay", LayoutComp(layout=bad))
    with pytest.raises(LayoutError, match="cannot be an OpenMDAO variable prefix"):
        p.setup()


def test_family_names_match_the_pipeline_mesh(states):
    assert family_names(LAYOUT) == states["imprint"].mesh.component_names == states["quad"].mesh.component_names


# ----------------------------------------------------------------------------- ProjectionComp
def test_projection_comp(states):
    comp = ProjectionComp(surface=SURFACE, size=SIZE)
    lay = load_layout(LAYOUT)
    p = run_comp(comp, layout=lay)
    st = p.get_val("c.state")
    ref = states["project"]
    assert st.stage == "project"
    assert [(c.member, c.side) for c in st.specs] == [(c.member, c.side) for c in ref.specs]
    for a, b in zip(ref.specs, st.specs):                  # the same seeds on the skin, bit for bit
        assert np.array_equal(a.seed, b.seed) and a.seed_tri == b.seed_tri
    assert sorted(st.projected) == sorted(ref.projected)
    for k, a in ref.projected.items():
        b = st.projected[k]
        assert np.array_equal(a.upper, b.upper) and np.array_equal(a.lower, b.lower)
    loaded = comp.loaded_state()
    # a new layout: no new load (the skin is read once per component), a new projection
    p.set_val("src.layout", lay.with_parameters(rib_eta={"wing": [0.0, 0.4, 1.0]}))
    p.run_model()
    assert comp.loaded_state() is loaded and comp.n_runs == 2
    assert p.get_val("c.state").layout.wings[0].rib_eta == (0.0, 0.4, 1.0)
    # ribs that coincide at the element size (0.11 of it apart): a failed case
    p.set_val("src.layout", lay.with_parameters(rib_eta={"wing": [0.0, 0.005, 1.0]}))
    with pytest.raises(om.AnalysisError, match="members coincide or cross at element size"):
        p.run_model()


def test_projection_comp_user_errors_stop_the_study(tmp_path):
    with pytest.raises(InputFileError, match="not found"):
        run_comp(ProjectionComp(surface=str(tmp_path / "missing.stl"), size=SIZE), layout=load_layout(LAYOUT))
    with pytest.raises(ShellMeshError, match="too large"):
        run_comp(ProjectionComp(surface=SURFACE, size=100.0), layout=load_layout(LAYOUT))


# ----------------------------------------------------------------------------- ImprintComp
def test_imprint_comp_and_remesh_cache(states):
    comp = ImprintComp()
    p = run_comp(comp, states["project"])
    st = p.get_val("c.state")
    assert st.stage == "imprint" and same_mesh(st.mesh, states["imprint"].mesh)
    assert comp.remesh_stats["misses"] == 1 and comp.remesh_stats["hits"] == 0
    # the same input object again: memoized, nothing runs
    p.run_model()
    assert p.get_val("c.state") is st and comp.n_runs == 1
    # another layout on the same surface: the remeshed skin comes from the cache ...
    moved = pl.run_stage(pl.stage_layout(states["load"], load_layout(LAYOUT).with_parameters(
        rib_eta={"wing": [0.0, 0.4, 1.0]}, spar_chord={"wing": [0.2, 0.6]})), "project")
    p.set_val("src.state", moved)
    p.run_model()
    hit = p.get_val("c.state")
    assert comp.remesh_stats["hits"] == 1 and hit.report["remesh_cache"]["hit"]
    # ... and is exactly the skin a fresh remesh gives
    fresh = pl.run_stage(pl.run_stage(moved, "remesh"), "imprint")
    assert same_mesh(hit.mesh, fresh.mesh)
    cached = comp.remesh_cache.skins()[0].mesh
    assert not cached.points.flags.writeable and not cached.faces.flags.writeable
    # without the cache every run remeshes
    comp2 = ImprintComp(remesh_cache=False)
    p2 = run_comp(comp2, moved)
    assert comp2.remesh_stats["misses"] == 1 and same_mesh(p2.get_val("c.state").mesh, fresh.mesh)


# ----------------------------------------------------------------------------- the middle stages
@pytest.mark.parametrize("cls,stage", [(MemberMeshComp, "members"), (SplitComp, "split"), (MergeComp, "merge"),
                                       (SmoothComp, "smooth")])
def test_stage_component_matches_pipeline(states, cls, stage):
    before = states[pl.STAGES[pl.STAGES.index(stage) - 1]]
    comp = cls()
    p = run_comp(comp, before)
    st = p.get_val("c.state")
    assert st.stage == stage and same_mesh(st.mesh, states[stage].mesh)
    assert st.report["stages"][stage] >= 0.0
    assert before.stage == pl.STAGES[pl.STAGES.index(stage) - 1]        # the input state is not modified


def test_stage_error_is_a_failed_case(states):
    # a state that is not ready for the stage (members before imprint) is a ShellMeshError of
    # the core function: the component raises it as AnalysisError
    with pytest.raises(om.AnalysisError, match="needs the output of stage 'imprint'"):
        run_comp(MemberMeshComp(), states["project"])
    with pytest.raises(om.AnalysisError, match="no input state"):
        run_comp(SplitComp(), None)


# ----------------------------------------------------------------------------- QuadComp
def test_quad_comp_outputs(states):
    comp = QuadComp()
    p = run_comp(comp, states["smooth"])
    m = p.get_val("c.shell_mesh")
    ref = states["quad"].mesh
    assert same_mesh(m, ref) and m.n_tris == 0
    assert p.get_val("c.n_elements")[0] == ref.n_faces
    assert p.get_val("c.n_nodes")[0] == len(np.unique(ref.faces[ref.faces >= 0]))
    assert p.get_val("c.min_scaled_jacobian")[0] == pytest.approx(scaled_jacobian(ref).min(), abs=0)
    assert p.get_val("c.min_scaled_jacobian")[0] > 0.2


# ----------------------------------------------------------------------------- MassComp, discrete mesh
def test_mass_comp_with_discrete_mesh(states):
    mesh = states["quad"].mesh
    names = family_names(LAYOUT)
    p = om.Problem(reports=False)
    ivc = p.model.add_subsystem("src", om.IndepVarComp())
    ivc.add_discrete_output("shell_mesh", val=None)
    p.model.add_subsystem("m", MassComp(layout=LAYOUT))
    p.model.connect("src.shell_mesh", "m.shell_mesh")
    p.setup(force_alloc_complex=True)
    p.set_val("src.shell_mesh", mesh)
    t = np.linspace(0.001, 0.004, len(names))
    p.set_val("m.thickness", t)
    p.run_model()
    assert p.model.m.family_names == names
    expect = 2700.0 * float((mesh.face_areas() * t[mesh.component]).sum())
    assert p.get_val("m.mass")[0] == pytest.approx(expect, rel=1e-12)
    assert_check_partials(p.check_partials(out_stream=None, method="cs"), atol=1e-8, rtol=1e-10)
    # the thickness goes by family NAME: a mesh with the families in another order gives the same mass
    perm = np.arange(len(mesh.component_names))[::-1]
    inv = np.argsort(perm)
    shuffled = type(mesh)(mesh.points, mesh.faces, inv[mesh.component].astype(np.int32),
                          [mesh.component_names[i] for i in perm])
    p.set_val("src.shell_mesh", shuffled)
    p.run_model()
    assert p.get_val("m.mass")[0] == pytest.approx(expect, rel=1e-12)
    # a family the thickness vector does not name is an error naming the fix
    p2 = om.Problem(reports=False)
    ivc = p2.model.add_subsystem("src", om.IndepVarComp())
    ivc.add_discrete_output("shell_mesh", val=None)
    p2.model.add_subsystem("m", MassComp(family_names=["skin"]))
    p2.model.connect("src.shell_mesh", "m.shell_mesh")
    p2.setup()
    p2.set_val("src.shell_mesh", mesh)
    with pytest.raises(ShellMeshError, match="add it to family_names"):
        p2.run_model()
    with pytest.raises(ShellMeshError, match="needs the mesh"):
        p3 = om.Problem(reports=False)
        p3.model.add_subsystem("m", MassComp())
        p3.setup()


from conftest import needs_ccx  # noqa: E402


@needs_ccx
def test_calculix_comp_discrete_mesh_matches_option_route(states):
    from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis

    mesh = states["quad"].mesh
    names = family_names(LAYOUT)
    t = np.linspace(0.002, 0.004, len(names))
    opt = om.Problem(reports=False)
    opt.model.add_subsystem("fea", CalculixShellAnalysis(mesh=mesh, layout=LAYOUT))
    opt.setup()
    opt.set_val("fea.thickness", t)
    opt.run_model()
    # the same mesh through the discrete input, its families listed in another order
    perm = np.arange(len(mesh.component_names))[::-1]
    shuffled = type(mesh)(mesh.points, mesh.faces, np.argsort(perm)[mesh.component].astype(np.int32),
                          [mesh.component_names[i] for i in perm])
    dis = om.Problem(reports=False)
    ivc = dis.model.add_subsystem("src", om.IndepVarComp())
    ivc.add_discrete_output("shell_mesh", val=None)
    dis.model.add_subsystem("fea", CalculixShellAnalysis(layout=LAYOUT))
    dis.model.connect("src.shell_mesh", "fea.shell_mesh")
    dis.setup()
    dis.set_val("src.shell_mesh", shuffled)
    dis.set_val("fea.thickness", t)
    dis.run_model()
    assert dis.model.fea.family_names == names
    for out in ("mass", "max_von_mises", "tip_deflection", "ks_von_mises"):
        np.testing.assert_allclose(dis.get_val(f"fea.{out}"), opt.get_val(f"fea.{out}"), rtol=1e-6)
    # a new mesh object re-derives the clamped nodes and drops the cached results
    dis.set_val("src.shell_mesh", mesh)
    dis.run_model()
    np.testing.assert_allclose(dis.get_val("fea.ks_von_mises"), opt.get_val("fea.ks_von_mises"), rtol=1e-6)
