"""OpenMDAO components MassComp and CalculixShellAnalysis on a small NACA wing meshed by the
pipeline, and the finite-difference partials of the analysis on a small box."""
import numpy as np
import openmdao.api as om
import pytest
from openmdao.utils.assert_utils import assert_check_partials

from shellmesh_mdao.analysis import ANALYSIS_MATERIAL
from shellmesh_mdao.components import calculix_comp
from shellmesh_mdao.components.calculix_comp import CalculixShellAnalysis
from shellmesh_mdao.components.mass_comp import MassComp
from shellmesh_mdao.errors import SolverError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.mesh import ShellMesh


from conftest import _have_ccx, needs_ccx  # noqa: E402

SPAN = 6.0


@pytest.fixture(scope="module")
def wing():
    """Default NACA wing (6 m semi-span), 3 ribs, 2 spars, meshed by the pipeline at 0.2 m."""
    from shellmesh_mdao.pipeline import run_pipeline

    layout = naca_wing_layout(span=SPAN, ribs=3)
    res = run_pipeline(naca_wing(span=SPAN, n_chord=24, n_span=16), layout, 0.2, progress=False)
    return res.mesh, layout


def _face_thickness_mass(mesh: ShellMesh, t, rho):
    return rho * float((mesh.face_areas() * np.asarray(t)[mesh.component]).sum())


def test_mass_comp_value_and_partials(wing):
    mesh, _ = wing
    n = len(mesh.component_names)
    p = om.Problem()
    p.model.add_subsystem("m", MassComp(mesh=mesh), promotes=["*"])
    p.setup(force_alloc_complex=True)
    t = np.linspace(0.001, 0.004, n)
    p.set_val("thickness", t)
    p.set_val("density", 2810.0)
    p.run_model()
    assert p.get_val("mass")[0] == pytest.approx(_face_thickness_mass(mesh, t, 2810.0), rel=1e-12)
    assert p.model.m.family_names == list(mesh.component_names)
    data = p.check_partials(out_stream=None, method="cs")
    assert_check_partials(data, atol=1e-8, rtol=1e-10)
    data = p.check_partials(out_stream=None, method="fd")
    assert_check_partials(data, atol=1e-4, rtol=1e-5)


@needs_ccx
def test_calculix_comp_on_pipeline_wing(wing, tmp_path):
    mesh, layout = wing
    n = len(mesh.component_names)
    p = om.Problem()
    p.model.add_subsystem("fea", CalculixShellAnalysis(mesh=mesh, layout=layout, pressure=1.0e4,
                                                       workdir=str(tmp_path / "run")), promotes=["*"])
    p.model.add_subsystem("mass", MassComp(mesh=mesh), promotes_inputs=["thickness"])
    p.setup()
    t = np.full(n, 0.003)
    p.set_val("thickness", t)
    p.run_model()
    r = p.model.fea.last_result
    # mass agrees with MassComp (same aluminium density)
    assert p.get_val("mass")[0] == pytest.approx(p.get_val("mass.mass")[0], rel=1e-12)
    assert p.get_val("mass")[0] == pytest.approx(_face_thickness_mass(mesh, t, ANALYSIS_MATERIAL["rho"]))
    # the lift-like pressure on the lower bays pushes the wing up; the largest deflection is at the tip
    up = np.asarray(layout["wings"][0]["up"])
    assert p.get_val("tip_deflection")[0] > 0
    k = np.argmax(np.abs(r.displacement @ up))
    assert mesh.points[k, 1] > 0.9 * SPAN
    assert p.get_val("max_deflection")[0] == pytest.approx((r.displacement @ up)[k], rel=1e-12)
    assert p.get_val("ccx_seconds")[0] == r.seconds > 0                  # the run's wall time, recorded
    # the tip deflection is the mean u.up of the tip rib (wing/rib_2 of 3 ribs) and its chains on the skin
    rib = mesh.component_names.index("wing/rib_2")
    f = mesh.faces[mesh.component == rib]
    assert set(f[f >= 0].tolist()) <= set(r.tip_nodes.tolist())
    q = mesh.points[r.tip_nodes]
    assert np.linalg.svd(q - q.mean(0), compute_uv=False)[-1] < 1e-6 * len(q) and q[:, 1].min() > 0.95 * SPAN  # a plane
    assert p.get_val("tip_deflection")[0] == pytest.approx((r.displacement[r.tip_nodes] @ up).mean(), rel=1e-12)
    assert 0 < p.get_val("tip_deflection")[0] < p.get_val("max_deflection")[0]
    # the root (the end cap at y = 0) is clamped
    assert np.all(mesh.points[r.clamped, 1] < 1e-6)
    assert np.abs(r.displacement[r.clamped]).max() < 1e-12 * np.abs(r.displacement).max()
    np.testing.assert_allclose(r.load / np.linalg.norm(r.load), up, atol=1e-12)
    # stresses, outside the clamp band: the KS of each family bounds that family's largest element
    # stress there; families without faces there give 0
    ks = p.get_val("ks_von_mises")
    out = ~r.in_clamp_band
    assert 0 < out.sum() < mesh.n_faces and r.clamp_band == pytest.approx(0.3, rel=0.02)   # 5 % of ~6 m
    counts = np.bincount(mesh.component, minlength=n)
    for f in range(n):
        sel = (mesh.component == f) & out
        vmax = r.von_mises[sel].max() if sel.any() else 0.0
        assert vmax * (1 - 1e-12) <= ks[f] <= vmax * (1 + np.log(max(counts[f], 1)) / 50) + 1e-9
    assert p.get_val("max_von_mises")[0] == pytest.approx(r.von_mises[out].max())
    assert 0 < p.get_val("max_von_mises")[0] < r.peak_von_mises == r.von_mises.max()   # the clamp peak is left out
    # the kept deck is all S4 (the pipeline mesh is all quads) with one shell section per non-empty family
    deck = (tmp_path / "run" / "shell.inp").read_text()
    assert deck.count("*SHELL SECTION") == int((counts > 0).sum())
    assert ("TYPE=S3" in deck) == bool(mesh.n_tris) and "TYPE=S4" in deck


@needs_ccx
def test_calculix_comp_root_rib_clamp_and_tip_nodes(wing):
    """clamp='root_rib' holds the wing at its root rib (3% span): every rib_0 node is clamped; the
    tip deflection is measured at the given tip-cap nodes (the one of largest |u.up|)."""
    mesh, layout = wing
    rib0 = mesh.component_names.index("wing/rib_0")
    tip = np.flatnonzero(mesh.points[:, 1] > SPAN - 1e-6)
    tip = tip[np.isin(tip, mesh.faces)]
    p = om.Problem()
    p.model.add_subsystem("fea", CalculixShellAnalysis(mesh=mesh, layout=layout, clamp="root_rib", tip_nodes=tip,
                                                       pressure=2.0e4), promotes=["*"])
    p.setup()
    p.run_model()
    r = p.model.fea.last_result
    f = mesh.faces[mesh.component == rib0]
    assert set(f[f >= 0].tolist()) <= set(r.clamped.tolist())
    d = r.displacement[tip] @ np.asarray(layout["wings"][0]["up"])
    assert p.get_val("tip_deflection")[0] == pytest.approx(d.mean(), rel=1e-12) and d.min() > 0


def _box_with_families() -> ShellMesh:
    """Small closed quad box (x 0.4, y 2, z in +-0.05; 10 cm quads) with families 'skin' (webs and
    caps), top flange, bottom flange and an empty 'box/rib_0'."""
    B, L, H = 0.4, 2.0, 0.1
    xs, ys, zs = np.linspace(0, B, 5), np.linspace(0, L, 21), np.linspace(-H / 2, H / 2, 2)
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    on = (np.isclose(pts[:, 0], 0) | np.isclose(pts[:, 0], B) | np.isclose(pts[:, 1], 0) | np.isclose(pts[:, 1], L)
          | np.isclose(np.abs(pts[:, 2]), H / 2))
    idx = np.full(len(pts), -1)
    idx[on] = np.arange(on.sum())
    shape = (len(xs), len(ys), len(zs))
    faces = []
    for ax in range(3):                       # axis-aligned unit squares of the lattice on the box surface
        a1, a2 = [d for d in range(3) if d != ax]
        for side in (0, shape[ax] - 1):
            r1, r2 = np.meshgrid(np.arange(shape[a1] - 1), np.arange(shape[a2] - 1), indexing="ij")
            c = np.zeros((r1.size, 3), np.int64)
            c[:, ax], c[:, a1], c[:, a2] = side, r1.ravel(), r2.ravel()
            corners = []
            for d1, d2 in ((0, 0), (1, 0), (1, 1), (0, 1)):
                cc = c.copy()
                cc[:, a1] += d1
                cc[:, a2] += d2
                corners.append(idx[np.ravel_multi_index(cc.T, shape)])
            faces.append(np.stack(corners, 1))
    f = np.vstack(faces)
    q = pts[on]
    cen = q[f].mean(1)
    nrm = np.cross(q[f[:, 2]] - q[f[:, 0]], q[f[:, 3]] - q[f[:, 1]])
    inward = np.einsum("ij,ij->i", nrm, cen - [B / 2, L / 2, 0.0]) < 0
    f[inward] = f[inward, ::-1]               # outward normals, consistent orientation
    comp = np.zeros(len(f), np.int32)
    comp[np.isclose(cen[:, 2], H / 2)] = 1
    comp[np.isclose(cen[:, 2], -H / 2)] = 2
    return ShellMesh(pts[on], f, comp, ["skin", "box/upper_skin/bay_0", "box/lower_skin/bay_0", "box/rib_0"])


@needs_ccx
def test_calculix_comp_fd_partials(monkeypatch):
    m = _box_with_families()
    calls = []
    real = calculix_comp.analyse_shell
    monkeypatch.setattr(calculix_comp, "analyse_shell", lambda *a, **k: calls.append(1) or real(*a, **k))
    p = om.Problem()
    p.model.add_subsystem("fea", CalculixShellAnalysis(mesh=m, up=[0, 0, 1], axis=1, pressure=1000.0),
                          promotes=["*"])
    p.setup()
    p.set_val("thickness", [0.002, 0.003, 0.002, 0.001])
    p.run_model()
    calls.clear()
    J = p.compute_totals(of=["mass", "tip_deflection", "ks_von_mises"], wrt=["thickness"])
    assert len(calls) == 6                       # two ccx runs (central) per non-empty family; none for the empty one
    rho = ANALYSIS_MATERIAL["rho"]
    areas = np.bincount(m.component, weights=m.face_areas(), minlength=4)
    np.testing.assert_allclose(J["mass", "thickness"][0], rho * areas, rtol=1e-6)
    dtip = J["tip_deflection", "thickness"][0]
    assert np.all(dtip[:3] < 0) and dtip[3] == 0  # thicker walls deflect less; the empty family does nothing
    assert dtip[2] < dtip[1]                     # the loaded, stretched bottom flange matters most here
    dks = J["ks_von_mises", "thickness"]
    assert np.all(dks[3] == 0) and np.all(dks[:, 3] == 0)
    assert dks[2, 2] < 0                         # a thicker bottom flange lowers its own stress


@needs_ccx
def test_calculix_comp_thickness_partials_accuracy():
    """The default partials (central differences, relative step 1e-2) against a fourth-order reference
    (steps of 5 % and 10 %, analyse_shell): the tip deflection and every KS entry (smooth with a fixed
    ks_ref) whose relative sensitivity |t/f df/dt| is at least 0.1 within 1e-3, the others down to 0.005
    within 5e-3 (the rounding of the 7-digit .dat output and the step's truncation)."""
    from shellmesh_mdao.analysis import analyse_shell

    m = _box_with_families()
    t0 = np.array([0.002, 0.003, 0.002, 0.001])
    kw = dict(up=[0, 0, 1], axis=1, pressure=1000.0, ks_ref=1.0e8)
    p = om.Problem(reports=False)
    p.model.add_subsystem("fea", CalculixShellAnalysis(mesh=m, **kw), promotes=["*"])
    p.setup()
    p.set_val("thickness", t0)
    p.run_model()
    J = p.compute_totals(of=["tip_deflection", "ks_von_mises"], wrt=["thickness"])

    def f(t):
        r = analyse_shell(m, t, **kw)
        return np.concatenate([[r.tip_deflection], r.ks_von_mises[:3]])

    base = f(t0)
    checked = 0
    for i in range(3):
        h = 0.05 * t0[i]
        v = {k: f(t0 + k * h * np.eye(4)[i]) for k in (-2, -1, 1, 2)}
        ref = (8 * (v[1] - v[-1]) - (v[2] - v[-2])) / (12 * h)
        got = np.concatenate([J["tip_deflection", "thickness"][:, i], J["ks_von_mises", "thickness"][:3, i]])
        sens = np.abs(ref * t0[i] / base)
        err = np.abs(got / ref - 1)
        assert np.all(err[sens >= 0.1] < 1e-3), (i, sens, err)
        assert np.all(err[sens >= 0.005] < 5e-3), (i, sens, err)
        checked += int((sens >= 0.005).sum())
    assert checked >= 10


@needs_ccx
def test_calculix_comp_buckling_outputs():
    """buckling=n: the n lowest buckling factors of the load case and their KS, as analyse_shell gives them;
    the thicker the walls, the higher the factors."""
    m = _box_with_families()
    p = om.Problem()
    p.model.add_subsystem("fea", CalculixShellAnalysis(mesh=m, up=[0, 0, 1], axis=1, pressure=1.0e5, buckling=2),
                          promotes=["*"])
    p.setup()
    p.set_val("thickness", [0.002, 0.002, 0.002, 0.002])
    p.run_model()
    lam = p.get_val("buckling_factors").copy()
    assert lam.shape == (2,) and 0 < lam[0] <= lam[1]
    np.testing.assert_array_equal(lam, p.model.fea.last_result.buckling_factors)
    # the KS (rho 50, reference the largest) of the load ratios 1 / lambda, written out here
    v = 1 / lam
    assert p.get_val("ks_buckling")[0] == pytest.approx(v[0] * (1 + np.log(np.exp(50 * (v / v[0] - 1)).sum()) / 50),
                                                        rel=1e-12)
    p.set_val("thickness", [0.003, 0.003, 0.003, 0.003])
    p.run_model()
    assert p.get_val("buckling_factors")[0] > 2 * lam[0]       # plate buckling goes with t^3 under a fixed load


def test_calculix_comp_setup_errors(tmp_path, monkeypatch):
    m = _box_with_families()
    p = om.Problem()
    p.model.add_subsystem("fea", CalculixShellAnalysis(mesh=m, axis=1))
    if _have_ccx():
        with pytest.raises(SolverError, match="up"):
            p.setup()
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("SHELLMESH_CCX", raising=False)
    p = om.Problem()
    p.model.add_subsystem("fea", CalculixShellAnalysis(mesh=m, up=[0, 0, 1]))
    with pytest.raises(SolverError, match="apt-get install calculix-ccx"):
        p.setup()
