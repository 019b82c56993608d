"""The whole pipeline, load -> quad: the all-quad conforming mesh and its guarantees.

On a small generated wing (2 and 3 spars, so T- and X-junctions) and, marked slow, on every
corpus geometry at the issue's sizes: 100 % quads, no element with scaled Jacobian <= 0.2,
no duplicate points, no hanging nodes, skin-member junction edges with 3 faces and member
crossings with 4, the skin closed where the input was, every node on its support (input
skin, member plane, feature curve), solver statuses in the report, and the same mesh bit for
bit on a second run. The stage functions run one by one give the same mesh as run_pipeline.
"""
from __future__ import annotations

import numpy as np
import pytest

from shellmesh_mdao import pipeline as pl
from shellmesh_mdao.errors import ShellMeshError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.guarantees import check_guarantees
from shellmesh_mdao.layout import layout_from_manifest
from shellmesh_mdao.quality import element_quality, scaled_jacobian
from shellmesh_mdao.core.supports import CURVE, FIXED, PLANE, SURFACE

WING = dict(span=2.0, root_chord=1.0, tip_chord=0.6, sweep_deg=10.0, dihedral_deg=3.0)
SIZE = 0.05


def small_wing():
    return naca_wing(naca="2412", n_chord=32, n_span=16, **WING)


def small_layout(spars=(0.15, 0.65)):
    return naca_wing_layout(ribs=5, spars=spars, **WING)


_CACHE: dict = {}


def run_small(spars):
    key = tuple(spars)
    if key not in _CACHE:
        _CACHE[key] = pl.run_pipeline(small_wing(), small_layout(spars), SIZE, progress=False)
    return _CACHE[key]


@pytest.mark.parametrize("spars", [(0.15, 0.65), (0.15, 0.4, 0.65)])
def test_small_wing_all_quad_conforming(spars):
    res = run_small(spars)
    eq = check_guarantees(res)["quality"]
    q = res.mesh
    topo = q.topology()
    fe = q.feature_edges[q.feature_edge_ids >= 0]
    val = topo.valence[topo.edge_ids(fe)]
    assert (val == 3).sum() > 0, "skin-member junction edges have 3 faces"
    if len(spars) == 3:
        assert (val == 4).sum() > 0, "a rib crossing the middle spar shares 4-face edges"
        assert any("/seg_" in c for c in q.component_names)
    # every member and every bay is present in the final mesh
    names = {q.component_names[i] for i in np.unique(q.component)}
    for k in range(5):
        assert any(n.startswith(f"wing/rib_{k}") for n in names)
    for j in range(len(spars)):
        assert any(n.startswith(f"wing/spar_{j}") for n in names)
    assert "wing/upper_skin/bay_0" in names and "wing/lower_skin/bay_3" in names
    # the quality a user sees on a coarse, thick wing
    assert eq["scaled_jacobian"].mean() > 0.88
    rep = res.report
    assert rep["split"]["status"] == "Optimal" and rep["merge"]["status"] == "Optimal"
    assert rep["merge"]["mip_gap"] <= 0.01
    assert set(pl.STAGES) <= set(rep["stages"])
    assert rep["counts"]["n_quads"] == q.n_faces


def test_deterministic_and_stagewise_equal():
    a = run_small((0.15, 0.65)).mesh
    st = pl.stage_load(small_wing(), SIZE)
    st = pl.stage_layout(st, small_layout())
    for name in pl.STAGES[2:]:
        st = pl.run_stage(st, name)
    b = st.mesh
    assert np.array_equal(a.points, b.points) and np.array_equal(a.faces, b.faces)
    assert np.array_equal(a.component, b.component) and a.component_names == b.component_names


def test_stage_order_and_options_errors():
    st = pl.stage_load(small_wing(), SIZE)
    with pytest.raises(ShellMeshError, match="needs the output of stage 'layout'"):
        pl.run_stage(st, "project")
    with pytest.raises(ShellMeshError, match="unknown solver option"):
        pl.run_pipeline(small_wing(), small_layout(), SIZE, options={"merge_gap": 0.1})
    with pytest.raises(ShellMeshError, match="must be a float"):
        pl.PipelineOptions.from_dict({"merge_mip_gap": "tight"})
    with pytest.raises(ShellMeshError, match="--until takes one of"):
        pl.run_pipeline(small_wing(), small_layout(), SIZE, until="export")
    with pytest.raises(ShellMeshError, match="'final_refresh' must be at least 1"):
        pl.PipelineOptions.from_dict({"final_refresh": 0})


def test_final_pass_refreshes_every_final_refresh_steps(monkeypatch):
    """The final pass (final_iterations steps, default 4) rebuilds its frames, weights and matrix
    every final_refresh steps (default 2): 2 matrices for 4 steps, 4 with final_refresh 1."""
    import shellmesh_mdao.quad.finish as F

    o = pl.PipelineOptions()
    assert (o.quad.final_iterations, o.quad.final_refresh) == (4, 2)
    st = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, until="smooth").state
    seen = []
    real = F.smooth

    def recording(mesh, supports, **kw):
        out, res = real(mesh, supports, **kw)
        if kw.get("figures") == "before":                      # the final pass
            seen.append((kw.get("refresh"), res.iterations, res.factorisations))
        return out, res

    monkeypatch.setattr(F, "smooth", recording)
    pl.run_stage(st, "quad")
    pl.run_stage(st.but(options=o.replace(final_refresh=1)), "quad")
    assert seen[0][0] == 2 and seen[1][0] == 1
    assert seen[0][1] == seen[1][1] == 4 and (seen[0][2], seen[1][2]) == (2, 4)


def _chain_side_edges(res):
    """Lengths of the skin edges joining a chain vertex to a vertex off the chains."""
    m = res.mesh
    cv = np.unique(np.concatenate([c.vertices for c in res.chains]))
    E = m.edges()
    on = np.isin(E, cv)
    E = E[on.any(1) & ~on.all(1)]
    return np.linalg.norm(m.points[E[:, 0]] - m.points[E[:, 1]], axis=1)


def test_snap_option_keeps_the_edges_beside_chains_long():
    """Solver option snap (default 0.4): the imprint moves a vertex onto a member plane when it lies
    within snap x its shortest incident edge of it, so a larger snap cuts fewer short edges beside the
    chains (on this wing at 0.4 against 0.25: 5th percentile 0.55 against 0.52 of the remesh edge, 683
    against 719 nodes); values of 0.5 and more are refused."""
    assert pl.PipelineOptions().imprint.snap == 0.4
    with pytest.raises(ShellMeshError, match="'snap' must be below 0.5"):
        pl.PipelineOptions.from_dict({"snap": 0.5})
    runs = [pl.run_pipeline(small_wing(), small_layout(), SIZE, until="imprint", progress=False, options=o)
            for o in ({"snap": 0.25}, None)]
    lo, hi = (np.percentile(_chain_side_edges(r), 5) / (pl.REMESH_FACTOR * SIZE) for r in runs)
    assert hi > lo and hi >= 0.5
    assert runs[1].mesh.n_points < runs[0].mesh.n_points


def test_final_ortho_weight_option_lifts_the_quads():
    """Solver option final_ortho_weight (default 3) is the orthogonality weight of the smoothing
    after subdivision: against weight 1 (smooth()'s default) the mean scaled Jacobian of the
    smoothed mesh is higher (on this wing, with the warp moves after the smoothing off so that the
    smoothing alone is compared: 0.9463 against 0.9442; its worst element is not better, 0.317
    against 0.336)."""
    assert pl.PipelineOptions().quad.final_ortho_weight == 3.0
    only = {"planar_offset": 0.0, "final_warp_weight": 0.0}
    base = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, options=only).mesh
    one = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False,
                          options=dict(only, final_ortho_weight=1.0)).mesh
    assert np.array_equal(base.faces, one.faces)           # the option only moves nodes
    a = element_quality(base.points, base.faces)["scaled_jacobian"]
    b = element_quality(one.points, one.faces)["scaled_jacobian"]
    assert a.mean() > b.mean() + 0.001


def test_warp_options_flatten_the_quads():
    """Solver options final_warp_weight (default 300), smooth_warp_weight (default 300),
    smooth_warp_spread (75 deg), warp_from (7 deg) and warp_goal (10 deg): after the final
    smoothing a second pass with the quad planarity term runs only while the warp p99 is above
    warp_goal (and, with planar_offset > 0, the planarize move alone does not meet it; off here),
    and moves only the nodes within two rings of the quads warped above warp_from (on
    this wing 13.2 -> 10.6 deg, 920 of 3,203 nodes; the planarize move, off here, does the rest
    by default); a goal the mesh already meets leaves the
    mesh exactly as without the term; smooth_warp_weight puts the term in the smoothing before
    subdivision (pre-subdivision warp p99 10.6 -> 8.0 deg at 300; 13.9 -> 7.3 before the merge's
    valence term, whose quads are flatter to begin with)."""
    o = pl.PipelineOptions().to_dict()
    names = ("smooth_warp_weight", "final_warp_weight", "smooth_warp_spread", "warp_from", "warp_goal")
    assert tuple(o[k] for k in names) == (300.0, 300.0, 75.0, 7.0, 10.0)
    res = run_flat_off()                     # planarize (after the pass) off: the pass alone
    wt = res.report["final_smooth"]["warp_term"]
    p99 = np.percentile(element_quality(res.mesh.points, res.mesh.faces)["warp"], 99)
    assert wt["applied"] and wt["warp_p99_before"] > 10.0 and p99 == pytest.approx(wt["warp_p99_after"])
    assert p99 < 0.85 * wt["warp_p99_before"]
    check_guarantees(res)
    met = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False,
                          options={"warp_goal": 30.0, "planar_offset": 0.0})
    off = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False,
                          options={"final_warp_weight": 0.0, "planar_offset": 0.0})
    assert not met.report["final_smooth"]["warp_term"]["applied"]
    assert not off.report["final_smooth"]["warp_term"]["applied"]
    assert met.mesh.points.tobytes() == off.mesh.points.tobytes()
    assert np.array_equal(off.mesh.faces, res.mesh.faces)               # the pass only moves nodes
    assert np.percentile(element_quality(off.mesh.points, off.mesh.faces)["warp"], 99) > 10.0
    moved = np.any(res.mesh.points != off.mesh.points, axis=1)          # the pass's region only
    assert 0 < moved.sum() <= wt["vertices"] < 0.8 * res.mesh.n_points
    w = element_quality(off.mesh.points, off.mesh.faces)["warp"]
    near = np.zeros(res.mesh.n_points, bool)
    near[off.mesh.faces[w > o["warp_from"]]] = True
    for _ in range(2):                                                  # two rings of faces
        near[off.mesh.faces[near[off.mesh.faces].any(1)]] = True
    assert near[moved].all()

    def pre_p99(options):
        m = pl.run_pipeline(small_wing(), small_layout(), SIZE, until="smooth", progress=False, options=options).mesh
        return np.percentile(element_quality(m.points, m.faces[~m.is_tri])["warp"], 99)

    assert pre_p99(None) < 0.8 * pre_p99({"smooth_warp_weight": 0.0})
    with pytest.raises(ShellMeshError, match="smooth_warp_spread"):
        pl.PipelineOptions.from_dict({"smooth_warp_spread": 0.0})


def run_flat_off():
    if "planar_off" not in _CACHE:
        _CACHE["planar_off"] = pl.run_pipeline(small_wing(), small_layout((0.15, 0.65)), SIZE, progress=False,
                                               options={"planar_offset": 0.0})
    return _CACHE["planar_off"]


def run_pass_one_only():
    if "pass_one" not in _CACHE:
        _CACHE["pass_one"] = pl.run_pipeline(small_wing(), small_layout((0.15, 0.65)), SIZE, progress=False,
                                             options={"planar_offset": 0.0, "final_warp_weight": 0.0})
    return _CACHE["pass_one"]


def test_planarize_moves_free_skin_nodes_off_the_input_within_the_bound():
    """Solver option planar_offset (default 0.05 of the size): after the final smoothing, the
    free skin nodes around the quads still warped above warp_goal move along their normals, off
    the input by at most 0.05 * size, to flatten quads that straddle kinks of the faceted input.
    On this wing that move alone meets warp_goal, so the second smoothing pass does not run.
    Against the same run with planar_offset 0 and no second pass: the same faces; only SURFACE
    nodes moved (chain, junction, feature and member nodes where they were), each by at most the
    bound; fewer quads above 10 degrees, as reported; the off-surface report (measured before)
    the same."""
    assert pl.PipelineOptions().quad.planar_offset == 0.05
    res, flat = run_small((0.15, 0.65)), run_pass_one_only()
    assert not res.report["final_smooth"]["warp_term"]["applied"]
    q, q0, sup = res.mesh, flat.mesh, res.state.supports
    rep = res.report["planarize"]
    assert flat.report["planarize"] is None
    assert np.array_equal(q.faces, q0.faces) and np.array_equal(q.component, q0.component)
    step = np.linalg.norm(q.points - q0.points, axis=1)
    moved = step > 0
    assert rep["applied"] and rep["moved"] == int(moved.sum()) > 0
    assert (sup.kind[moved] == SURFACE).all()
    assert step.max() == pytest.approx(rep["max_offset"], rel=1e-12) and step.max() <= 0.05 * SIZE * (1 + 1e-12)
    d = sup.distance(q.points)
    assert d[moved].max() <= 0.05 * SIZE * (1 + 1e-9) and d[~moved & (sup.kind == SURFACE)].max() <= 1e-6 * q.diagonal
    w, w0 = (element_quality(m.points, m.faces)["warp"] for m in (q, q0))
    assert rep["quads_above_before"] == int((w0 > 10).sum()) > rep["quads_above_after"] == int((w > 10).sum())
    assert rep["warp_p99_after"] == pytest.approx(np.percentile(w, 99)) and rep["warp_p99_after"] < rep["warp_p99_before"]
    assert res.report["off_surface"] == flat.report["off_surface"]
    sj, sj0 = (scaled_jacobian(m.points, m.faces) for m in (q, q0))
    assert sj.min() >= min(sj0.min(), 0.3)                     # no element falls to 0.3 or below
    with pytest.raises(ShellMeshError, match="planar_offset"):
        pl.PipelineOptions.from_dict({"planar_offset": 0.3})


def test_warp_pass_is_centred_on_the_quads_planarize_left_warped(monkeypatch):
    """Where the planarize move alone misses warp_goal, the second final pass moves exactly the
    nodes of the faces within two rings of the quads that move left above the goal (it flattens
    the others without the pass), and the report counts those quads (warp_term.seed_quads). The
    pass starts from the trial's mesh with those nodes back where they were before the move;
    the move after it moves only those nodes, so every other node keeps the trial's position;
    its report counts the quads warped before every move it counts (the trial's that stand too)
    and after."""
    import shellmesh_mdao.quad.finish as F
    from shellmesh_mdao.mesh import vertex_faces

    trials, passes, regions = [], [], []
    finish, region_finish, smooth = F.finish_quads, F.finish_region, F.smooth

    def record_finish(q, sup, size, **kw):
        out = finish(q, sup, size, **kw)
        trials.append((q, out))
        return out

    def record_region(q, sup, size, movable, trial, **kw):
        out = region_finish(q, sup, size, movable, trial, **kw)
        regions.append((q, out))
        return out

    def record_smooth(mesh, supports, **kw):
        if kw.get("warp_weight", 0) > 0 and kw.get("vertices") is not None:     # the second final pass
            passes.append((mesh, kw["vertices"]))
        return smooth(mesh, supports, **kw)

    monkeypatch.setattr(F, "finish_quads", record_finish)
    monkeypatch.setattr(F, "finish_region", record_region)
    monkeypatch.setattr(F, "smooth", record_smooth)
    res = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, options={"warp_goal": 5.0})
    wt = res.report["final_smooth"]["warp_term"]
    assert wt["applied"] and len(passes) == 1 and len(trials) == 1 and len(regions) == 1
    q, trial = trials[0]
    tm = trial["mesh"]
    seeds = element_quality(tm.points, tm.faces)["warp"] > 5.0
    assert wt["seed_quads"] == int(seeds.sum()) == trial["planar"]["quads_above_after"] > 0
    vptr, vface = vertex_faces(q.faces, q.n_points)
    ring = np.zeros(q.n_faces, bool)
    ring[seeds] = True
    for _ in range(2):                                         # two rings of faces around the seeds
        nodes = np.unique(q.faces[ring][q.faces[ring] >= 0])
        ring[np.concatenate([vface[vptr[v]:vptr[v + 1]] for v in nodes])] = True
    expect = np.unique(q.faces[ring][q.faces[ring] >= 0])
    assert np.array_equal(np.sort(passes[0][1]), expect) and wt["vertices"] == len(expect)
    # fewer than the old rule (every quad above warp_from in the first pass's mesh) would move
    assert (element_quality(q.points, q.faces)["warp"] > res.state.options.smooth.warp_from).sum() > seeds.sum()
    # the pass's start: the trial's mesh, the region's nodes at their positions before its move
    inside = np.zeros(q.n_points, bool)
    inside[expect] = True
    start = passes[0][0].points
    assert np.array_equal(start[~inside], tm.points[~inside])
    assert np.array_equal(start[inside], trial["before_planar"].points[inside])
    assert not np.array_equal(start[inside], tm.points[inside])        # the trial had moved some of them
    # the move after the pass: only the region's nodes; the rest keep the trial's positions, and
    # the nodes reported as off the surface are measured where they were before any move
    after, done = regions[0]
    out = done["mesh"].points
    assert np.array_equal(out[~inside], tm.points[~inside]) and not np.array_equal(out[inside], after.points[inside])
    assert np.array_equal(done["before_planar"].points[~inside], trial["before_planar"].points[~inside])
    assert np.array_equal(done["before_planar"].points[inside], after.points[inside])
    # its figures: before every move it counts (the guarantee compares them), after in the result
    bq = done["before_planar"]
    wb, wa = (element_quality(m.points, m.faces)["warp"][m.faces[:, 3] >= 0] for m in (bq, done["mesh"]))
    rep = done["planar"]
    assert rep["moved"] == int((np.linalg.norm(out - bq.points, axis=1) > 0).sum())
    assert rep["quads_above_before"] == int((wb > 5.0).sum()) and rep["quads_above_after"] == int((wa > 5.0).sum())
    assert rep["warp_p99_before"] == pytest.approx(np.percentile(wb, 99))
    if wt["kept"] == "pass":
        assert res.mesh.points.tobytes() == out.tobytes()


def test_warp_pass_runs_only_where_planarize_alone_misses_the_goal(monkeypatch):
    """The second final smoothing pass (the quad planarity term) costs as much as the first; the
    planarize move is cheap and, where it meets warp_goal alone, keeps the better scaled
    Jacobians. So the quad stage tries it first on the first pass's mesh and keeps it when the
    warp p99 is then at or below the goal (the default on this wing: 13.2 -> 8.05 deg); otherwise
    (warp_goal 5: 6.82 deg alone) it runs the pass around the quads the move left above the goal
    (from the move's mesh, the pass's nodes put back), then the move on the pass's nodes, and
    keeps that only when it beats the move alone (on this wing 6.63 deg: the pass is kept). Each
    way of that rule is checked below whatever the wing's mesh,
    by reporting one side's warp worse than it is. The settle / repair / planarize tail changes
    neither the mesh nor the supports it is given."""
    import shellmesh_mdao.quad.finish as F

    res = run_small((0.15, 0.65))
    wt, rep = res.report["final_smooth"]["warp_term"], res.report["planarize"]
    assert wt["warp_p99_before"] > 10.0 and not wt["applied"]
    assert wt["planarize_alone_p99"] == rep["warp_p99_after"] <= 10.0 < rep["warp_p99_before"]
    quads = res.mesh.faces[:, 3] >= 0
    w = element_quality(res.mesh.points, res.mesh.faces)["warp"][quads]
    assert np.percentile(w, 99) == pytest.approx(wt["planarize_alone_p99"])

    def strict_run(fake_call=None):
        """The wing at warp_goal 5; with ``fake_call`` (1: the planarize trial, 2: the move after
        the pass) that call's warp p99 is reported as 1e9. Returns the result and the calls."""
        calls = []
        orig, orig_region = F.finish_quads, F.finish_region

        def record(out):
            calls.append(out)
            if len(calls) == fake_call:
                out = dict(out, planar=dict(out["planar"], warp_p99_after=1e9))
            return out
        with monkeypatch.context() as m:
            m.setattr(F, "finish_quads", lambda q, sup, size, **kw: record(orig(q, sup, size, **kw)))
            m.setattr(F, "finish_region", lambda q, sup, size, movable, trial, **kw: record(
                orig_region(q, sup, size, movable, trial, **kw)))
            r = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, options={"warp_goal": 5.0})
        return r, calls

    strict, calls = strict_run()
    ws = strict.report["final_smooth"]["warp_term"]
    assert ws["applied"] and ws["planarize_alone_p99"] > 5.0 and ws["vertices"] > 0 and len(calls) == 2
    sq = strict.mesh.faces[:, 3] >= 0
    final = np.percentile(element_quality(strict.mesh.points, strict.mesh.faces)["warp"][sq], 99)
    assert final == pytest.approx(strict.report["planarize"]["warp_p99_after"])
    assert strict.report["planarize"]["warp_p99_after"] <= ws["planarize_alone_p99"]
    kept = calls[0] if ws["kept"] == "planarize_alone" else calls[1]
    assert kept["planar"]["warp_p99_after"] == min(c["planar"]["warp_p99_after"] for c in calls)
    check_guarantees(strict)
    # the trial reported hopeless: the pass and the move after it are kept
    r1, c1 = strict_run(1)
    assert r1.report["final_smooth"]["warp_term"]["kept"] == "pass" and r1.report["planarize"] == c1[1]["planar"]
    assert r1.mesh.points.tobytes() == c1[1]["mesh"].points.tobytes()
    # the move after the pass reported hopeless: the move alone on the first pass's mesh is kept
    r2, c2 = strict_run(2)
    assert r2.report["final_smooth"]["warp_term"]["kept"] == "planarize_alone"
    assert r2.mesh.points.tobytes() == c2[0]["mesh"].points.tobytes() and r2.report["planarize"] == c2[0]["planar"]
    # the tail is pure: twice on the same input, the same output, the input untouched
    st = res.state
    q, sup = st.mesh, st.supports
    keep = (q.points.copy(), sup.kind.copy(), sup.ref.copy())
    o = st.options.quad
    a, b = F.finish_quads(q, sup, st.size, options=o), F.finish_quads(q, sup, st.size, options=o)
    assert a["mesh"].points.tobytes() == b["mesh"].points.tobytes() and a["planar"] == b["planar"]
    assert np.array_equal(q.points, keep[0]) and np.array_equal(sup.kind, keep[1]) and np.array_equal(sup.ref, keep[2])


@pytest.mark.parametrize("remesh", [True, False])
def test_split_supports_are_those_of_its_mesh(remesh):
    """The split stage derives the supports before the LP (for the new midpoints) and again on
    its result, unless no edge was split (then the mesh, and so its supports, are the same: the
    remeshed wing here, and the target case); either way they equal supports derived afresh."""
    from shellmesh_mdao.core.supports import pipeline_supports
    st = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, until="split", remesh=remesh).state
    assert (st.report["split"]["n_split_edges"] == 0) == remesh
    again = pipeline_supports(st.mesh, st.locator, st.infos)
    assert again.n == st.mesh.n_points
    for name in ("kind", "ref", "comp_kind", "comp_ref", "edge_pairs", "edge_curve"):
        assert getattr(again, name).tobytes() == getattr(st.supports, name).tobytes(), name


@pytest.mark.parametrize("remesh", [True, False])
def test_split_supports_are_made_beside_its_lp(monkeypatch, remesh):
    """The supports before the split LP and the midpoint projector made of them come from a
    second thread while the LP is built and solved: the split mesh is the one made with them
    made first in the caller's thread, bit for bit (the wing without remesh splits edges, so
    its new nodes go through the projector)."""
    import threading

    import shellmesh_mdao.split as S
    from shellmesh_mdao.core.supports import edge_midpoint_projector, pipeline_supports

    st = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, until="members", remesh=remesh).state
    sup0 = pipeline_supports(st.mesh, st.locator, st.infos)
    eager, _ = S.split_polygons(st.mesh, time_limit=st.options.split.split_time_limit,
                                project=edge_midpoint_projector(st.mesh, sup0))
    threads = []
    real = S.pipeline_supports

    def recording(*a, **k):
        threads.append(threading.get_ident())
        return real(*a, **k)

    monkeypatch.setattr(S, "pipeline_supports", recording)
    out = pl.run_stage(st, "split")
    assert threads and threads[0] != threading.get_ident()
    assert (out.report["split"]["n_split_edges"] > 0) == (not remesh)
    assert out.mesh.points.tobytes() == eager.points.tobytes() and np.array_equal(out.mesh.faces, eager.faces)


def test_merge_report_is_strict_json_without_a_gap(monkeypatch):
    """With the merge's valence term in blocks (a problem above merge.VALENCE_ONE_PIECE candidate
    edges) there is no global bound: the report's gap is null, not NaN, so the JSON report stays
    standard JSON."""
    import json

    import shellmesh_mdao.merge.triangles as M
    st = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, until="split").state
    monkeypatch.setattr(M, "VALENCE_ONE_PIECE", 500)
    monkeypatch.setattr(M, "VALENCE_BLOCK", 400)
    rep = pl.run_stage(st, "merge").report["merge"]
    assert rep["status"].endswith("blocks)") and rep["mip_gap"] is None and rep["n_merged"] > 0
    json.dumps(rep, allow_nan=False)


def test_merge_keeps_the_split_supports():
    """The merge stage hands on the split stage's supports: merging two triangles of one
    component changes no point, feature edge or fixed vertex, nor any vertex's supports. They are
    the same arrays and curves as deriving them again on the merged mesh."""
    from shellmesh_mdao.core.supports import pipeline_supports
    st = pl.run_pipeline(small_wing(), small_layout(), SIZE, progress=False, until="split").state
    merged = pl.run_stage(st, "merge")
    assert merged.supports is st.supports and merged.mesh.n_quads > 0
    again = pipeline_supports(merged.mesh, st.locator, st.infos)
    for name in ("kind", "ref", "comp_kind", "comp_ref", "edge_pairs", "edge_curve"):
        assert getattr(again, name).tobytes() == getattr(merged.supports, name).tobytes(), name
    assert len(again.curves) == len(merged.supports.curves)
    for a, b in zip(again.curves, merged.supports.curves):
        assert a.points.tobytes() == b.points.tobytes() and a.closed == b.closed
    assert (np.asarray(again.kind) == SURFACE).any() and (np.asarray(again.kind) == CURVE).any()


def test_stage_outputs_are_not_mutated():
    st = pl.stage_load(small_wing(), SIZE)
    st = pl.stage_layout(st, small_layout())
    st = pl.run_stage(pl.run_stage(st, "project"), "remesh")
    before = st.mesh.points.copy()
    after = pl.run_stage(st, "imprint")
    assert after is not st and st.stage == "remesh" and np.array_equal(st.mesh.points, before)
    assert "imprint" not in st.report["stages"] and "imprint" in after.report["stages"]


CORPUS_SIZES = {"cessna210": 0.25, "swept_wing": 0.02, "straight_wing": 0.02, "bwb": 0.3}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(CORPUS_SIZES))
def test_corpus_all_quad(geometry_dir, manifest, name):
    lay = layout_from_manifest(manifest, name, ribs=10)
    path = geometry_dir / manifest["geometries"][name]["file"]
    res = pl.run_pipeline(path, lay, CORPUS_SIZES[name], progress=False)
    check_guarantees(res)
    again = pl.run_pipeline(path, lay, CORPUS_SIZES[name], progress=False, remesh_cache=False).mesh
    assert np.array_equal(res.mesh.points, again.points) and np.array_equal(res.mesh.faces, again.faces)


@pytest.mark.slow
def test_explicit_members_to_all_quads():
    """The default wing with planar and kinked explicit members (T- and X-junctions with the
    generated ribs and spars) through every stage: the same guarantees, except that where two
    member curves cross at a shallow angle (here about 9 degrees, a wedge no mesh can avoid)
    an element may fall to the crossing angle: it is never folded, and it is reported. Such a
    mesh misses the 0.2 guarantee, so the pipeline's gate refuses it (GuaranteeError naming the
    element); check=False returns it for inspection."""
    from shellmesh_mdao.errors import GuaranteeError
    from test_explicit_members import WING_SIZE, wing_with_explicit_members

    surface = naca_wing()
    with pytest.raises(GuaranteeError, match=r"mesh guarantee 'scaled Jacobian' missed: .* at element \d+ .*"
                                             r"The mesh is refused \(nothing written\)"):
        pl.run_pipeline(surface, wing_with_explicit_members(surface), WING_SIZE, progress=False)
    res = pl.run_pipeline(surface, wing_with_explicit_members(surface), WING_SIZE, progress=False, check=False)
    assert "guarantees" not in res.report
    eq = check_guarantees(res, min_sj=0.1)["quality"]     # free edges, non-planar members fixed: from the run
    assert (eq["scaled_jacobian"] <= 0.2).sum() <= 5
    names = {res.mesh.component_names[i].split("/seg_")[0] for i in np.unique(res.mesh.component)}
    explicit = {m.name for m in res.layout.members() if m.kind == "explicit"}
    assert explicit and explicit <= names


def test_stages_run_with_one_blas_thread_and_restore_the_callers(monkeypatch):
    """Every stage runs with BLAS on one thread (its small products only spin OpenBLAS's workers,
    which took the second core from the closest-point threads); the caller's thread count is
    back after the stage, also when the stage raises."""
    import types

    import scipy.sparse.linalg  # noqa: F401 -- scipy's own OpenBLAS loaded too
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return sorted(d["num_threads"] for d in threadpool_info() if d["user_api"] == "blas")

    seen = []

    def stage(state):
        seen.append(blas_threads())
        if state is None:
            raise ShellMeshError("bad input")
        return types.SimpleNamespace(report={"stages": {}})

    monkeypatch.setitem(pl._STAGE_FUNCS, "project", stage)
    with threadpool_limits(limits=2, user_api="blas"):
        before = blas_threads()
        if not before or max(before) < 2:
            pytest.skip("this BLAS runs on one thread only: nothing to limit")
        pl.run_stage(object(), "project")
        with pytest.raises(ShellMeshError):
            pl.run_stage(None, "project")
        assert blas_threads() == before
    assert seen == [[1] * len(before)] * 2


def test_bundled_wing_leading_edge_quads_are_not_stretched():
    """Issue 41: at size 0.1 the bundled wing's skin quads along the mid-span leading edge came out
    of aspect 30-36 and warp 43-61 degrees: the smoothing pulled the nose's graded elements towards
    the flat-region length. Each edge now aims at the local size at its ends: aspect <= 20 (the
    issue's bound) and warp below 35 degrees (33 measured; the issue asks 30) on every one."""
    res = pl.run_pipeline(naca_wing(), naca_wing_layout(), 0.1, progress=False)
    P, F = res.mesh.points, res.mesh.faces
    c = P[F].mean(1)
    y = c[:, 1]
    skin = np.asarray(res.mesh.component_names)[res.mesh.component] == "skin"
    le = skin & (y > 0.5) & (y < 5.0) & (c[:, 0] - y * np.tan(np.radians(10.0)) < 0.05 * (2.0 - y / 6.0))
    q = element_quality(P, F[le])
    assert le.sum() > 1000
    assert q["aspect"].max() <= 20.0 and q["warp"].max() < 35.0
    assert np.percentile(q["warp"], 99) < 20.0


@pytest.mark.parametrize("size, seed", [(0.2, None), (0.1, 2)])
def test_bundled_wing_leading_edge_meets_the_guarantees(size, seed):
    """Issue 41: the bundled wing (NACA 2412, leading-edge radius 16-32 mm) at size 0.2 with
    its default layout gave an element of scaled Jacobian 0.162, and at size 0.1 with layout
    seed 2 of the issue's jittered nine-rib layouts a skin node 0.06 off the input near the
    leading edge (the smoothing turned faces across the nose). Every guarantee holds, no skin
    node is off the input."""
    lay = naca_wing_layout()
    if seed is not None:            # nine ribs jittered by up to 0.03 of the span, front spar 0.12-0.2
        rng = np.random.default_rng(seed)
        eta = np.linspace(0, 1, 9)
        eta[1:-1] += rng.uniform(-0.03, 0.03, 7)
        lay["wings"][0]["ribs"] = {"eta": [float(e) for e in eta]}
        lay["wings"][0]["spars"] = {"chord_fractions": [float(rng.uniform(0.12, 0.2)), 0.65]}
    res = pl.run_pipeline(naca_wing(), lay, size, progress=False)
    g = check_guarantees(res)
    assert g["min_scaled_jacobian"] > 0.2
    assert res.report["off_surface"]["count"] == 0


def test_report_size_field_skin_is_the_remesh_sizing_and_survives_a_cache_hit():
    """report['size_field']['skin']: the skin's sizing in units of the remesh target (min <= median
    <= max = 1 on this wing, refined where its nose turns and its tip is thin), the refined area
    split by reason (the shares add up to the refined share); a cache hit reports the same."""
    from shellmesh_mdao.remesh import RemeshCache
    from shellmesh_mdao.remesh.surface import SIZING_REASONS

    cache = RemeshCache(1)
    runs = [pl.run_pipeline(small_wing(), small_layout(), SIZE, until="remesh", progress=False, remesh_cache=cache)
            for _ in range(2)]
    assert cache.hits == 1 and runs[1].report["remesh_cache"]["hit"]
    sk = runs[0].report["size_field"]["skin"]
    assert sk["target"] == pytest.approx(pl.REMESH_FACTOR * SIZE)
    assert 0.0 < sk["min"] < 0.95 <= sk["median"] <= sk["max"] == pytest.approx(1.0)
    assert set(sk["refined_by"]) == set(SIZING_REASONS)
    assert 0.0 < sk["refined"] < 0.5
    assert sum(sk["refined_by"].values()) == pytest.approx(sk["refined"])
    assert sk["refined_by"]["grading"] > 0.0
    assert runs[1].report["size_field"]["skin"] == sk
