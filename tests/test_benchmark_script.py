"""Smoke tests of the benchmark harness (shellmesh_mdao.benchmarks, run by run_scripts/benchmark.py):
figures on known meshes, the child-process guard (errors, crashes, time limits), the
1M-triangle refinement on a tiny surface, and one small side-by-side case (pipeline + Gmsh)
written as page + JSON, then re-rendered by the script."""
import copy
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import shellmesh_mdao.benchmarks as B
from shellmesh_mdao.benchmarks import corpus
from shellmesh_mdao.benchmarks.page import robustness_section
from shellmesh_mdao.mesh import ShellMesh

REPO = Path(__file__).resolve().parents[1]


def _grid(nx, ny, h=1.0, z=None):
    """nx x ny unit quads of edge h in the z=0 plane (or lifted by z(x, y))."""
    x, y = np.meshgrid(np.arange(nx + 1) * h, np.arange(ny + 1) * h, indexing="ij")
    pts = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size) if z is None else z(x.ravel(), y.ravel())])
    idx = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    quads = np.column_stack([idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(),
                             idx[:-1, 1:].ravel()])
    return pts, quads


def test_member_mask_and_figures_of_a_square_grid():
    pts, quads = _grid(4, 3, h=0.5)
    comp = np.array([0] * 6 + [1] * 3 + [2] * 3, np.int32)
    names = ["wing/upper_skin/bay_0", "wing/rib_1", "wing/spar_0/seg_2"]
    mesh = ShellMesh(pts, quads, comp, names)
    mask = B.member_face_mask(mesh.component, mesh.component_names)
    assert mask.tolist() == [False] * 6 + [True] * 6
    f = B.mesh_figures(mesh, 0.5)
    assert (f["n_elements"], f["n_quads"], f["n_tris"], f["n_skin"], f["n_members"]) == (12, 12, 0, 6, 6)
    assert f["quad_percent"] == 100.0 and f["n_folded"] == 0 and f["n_sj_le_0.2"] == 0
    assert f["sj_mean"] == pytest.approx(1.0) and f["mean_sj_skin"] == pytest.approx(1.0)
    assert f["mean_sj_members"] == pytest.approx(1.0)
    assert f["min_angle"] == pytest.approx(90.0) and f["max_angle"] == pytest.approx(90.0)
    assert f["angles_ok_percent"] == 100.0 and f["warp_p99"] == pytest.approx(0.0, abs=1e-9)
    assert f["median_edge_ratio"] == pytest.approx(1.0) and f["valid"] and f["problems"] == []
    assert all(B.target_checks(f).values())
    # a skin-only mesh has no member figure: its target is "not applicable", not a failure
    f1 = B.mesh_figures(ShellMesh(pts, quads), 1.0)
    assert f1["mean_sj_members"] is None and B.target_checks(f1)["mean_sj_members"] is None
    assert B.target_checks(f1)["median_edge_ratio"] is False          # edges are half the size


def test_figures_count_folded_and_triangles():
    pts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],            # unit square
                    [2, 0, 0], [3, 0, 0], [2.2, 0.2, 0], [2, 1, 0],        # dart: reflex corner at node 6
                    [0, 2, 0]], float)
    faces = np.array([[0, 1, 2, 3], [4, 5, 6, 7], [3, 2, 8, -1]])
    f = B.mesh_figures(ShellMesh(pts, faces), 1.0)
    assert (f["n_quads"], f["n_tris"]) == (2, 1)
    assert f["quad_percent"] == pytest.approx(200 / 3)
    assert f["n_folded"] == 1 and f["n_sj_le_0.2"] == 1 and f["sj_min"] <= 0
    assert f["max_angle"] > 180 and f["angles_ok_percent"] == 50.0
    t = B.target_checks(f)
    assert t["quad_percent"] is False and t["n_sj_le_0.2"] is False and t["angles_ok_percent"] is False


def test_warp_p99_of_a_twisted_grid():
    pts, quads = _grid(10, 10, h=0.1, z=lambda x, y: 0.5 * x * y)     # hyperbolic paraboloid
    f = B.mesh_figures(ShellMesh(pts, quads), 0.1)
    assert 0 < f["warp_p99"] < 10 and f["n_folded"] == 0


def test_run_in_child_reports_errors_crashes_and_timeouts():
    # limits far above what the children need (they return at once), so a loaded machine that is
    # slow to start a process changes nothing; the sleeping child is killed long before its end
    r = B.run_in_child(math.sqrt, -1.0, timeout=900)          # raises ValueError in the child
    assert r["status"] == "error" and "ValueError" in r["error"] and r["peak_rss_mb"] > 0
    r = B.run_in_child(os._exit, 3, timeout=900)               # the child dies without a result
    assert r["status"] == "crashed" and r["exit_code"] == 3
    t0 = time.perf_counter()
    r = B.run_in_child(time.sleep, 3600, timeout=3)            # killed at the time limit
    assert r["status"] == "timeout" and time.perf_counter() - t0 < 600


def test_refine_surface_keeps_the_surface(tmp_path):
    import trimesh

    src = tmp_path / "box.stl"
    trimesh.creation.box(extents=(1.0, 2.0, 3.0)).export(str(src))
    out = B.refine_surface(src, 100, tmp_path / "refined.stl")
    assert (out["n_triangles"], out["levels"]) == (192, 2)          # 12 -> 48 -> 192
    ref = trimesh.load(out["path"], force="mesh")
    assert len(ref.faces) == 192 and ref.is_watertight
    assert ref.area == pytest.approx(22.0) and ref.volume == pytest.approx(6.0)
    mtime = Path(out["path"]).stat().st_mtime_ns
    assert B.refine_surface(src, 100, tmp_path / "refined.stl") == out    # reused, not rewritten
    assert Path(out["path"]).stat().st_mtime_ns == mtime


def test_quick_case_writes_page_and_json(geometry_dir, tmp_path):
    """One small case side by side (Gmsh, then the pipeline, in child processes), written as
    page + JSON, keeping the hand-kept part of the page; perf/memory sections rendered too."""
    out = tmp_path / "benchmarks.md"
    out.write_text("# old page\n\n" + B.KEEP_MARKER + "\n\n## Building blocks\n\nkept table\n")
    B.write_outputs(B.run_benchmark(geometry_dir, only="straight_wing", quick=True), out)
    res = json.loads(out.with_suffix(".json").read_text())
    assert res["quick"] and [c["name"] for c in res["corpus"]] == ["straight_wing"]
    case = res["corpus"][0]
    o, g = case["ours"], case["gmsh"]
    assert o["status"] == "ok" and g["status"] == "ok"
    fo, fg = o["figures"], g["figures"]
    # the pipeline's output is all quads, conforming, with members; Gmsh's is skin only
    assert fo["quad_percent"] == 100.0 and fo["valid"] and fo["n_members"] > 0 and fo["n_folded"] == 0
    assert fg["n_members"] == 0 and fg["n_elements"] > 1000 and fg["quad_percent"] > 99
    assert 0.5 < fg["median_edge_ratio"] < 1.5                      # Gmsh's quads come out at ~size
    assert set(o["stages"]) >= {"load", "remesh", "merge", "quad"} and o["merge"]["status"]
    assert case["time_ratio"] == pytest.approx(o["wall_s"] / g["wall_s"])
    assert set(case["targets"]) == set(B.TARGETS)
    page = out.read_text()
    assert "## Quality targets" in page and "Gmsh (skin only)" in page and f"{fo['n_elements']:,}" in page
    assert page.rstrip().endswith("kept table") and "# old page" not in page
    # the script's --from-json re-renders the same page without running anything
    again = tmp_path / "again.md"
    run = subprocess.run([sys.executable, str(REPO / "run_scripts" / "benchmark.py"), "--from-json",
                          str(out.with_suffix(".json")), "--out", str(again)], capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert again.read_text() == page.replace(B.KEEP_MARKER + "\n\n## Building blocks\n\nkept table\n", "").rstrip() + "\n"
    # deterministic page for the same figures; the performance and memory sections render
    res2 = copy.deepcopy(res)
    res2["performance"] = copy.deepcopy(case)
    res2["memory"] = {"name": "straight_wing", "size": 0.05, "refined": {"levels": 3, "n_triangles": 1_000_000},
                      "ours": copy.deepcopy(o), "load_before": 1.0, "load_after": 2.0, "within_budget": True}
    p2 = B.render_page(res2)
    assert B.render_page(res2) == p2
    assert "## Performance target" in p2 and "Result: **" in p2 and "## Memory target" in p2


def test_perturbed_surface_is_the_same_geometry_with_other_rounding(geometry_dir):
    """--perturb's inputs: the corpus surface with every coordinate moved by about 1e-10 of
    itself, the same faces; one seed gives the same copy every time, two seeds two copies."""
    from shellmesh_mdao.load import load_surface

    path = geometry_dir / "bwb.stl"
    ref, _ = load_surface(path)
    a, b, c = (B.perturbed_surface(path, s) for s in (0, 0, 1))
    assert np.array_equal(a.faces, ref.faces) and np.array_equal(a.component, ref.component)
    rel = np.abs(a.points - ref.points) / np.maximum(np.abs(ref.points), 1e-300)
    assert 0 < rel.max() < 1e-8 and np.median(rel[ref.points != 0]) > 1e-12
    assert a.points.tobytes() == b.points.tobytes() and a.points.tobytes() != c.points.tobytes()


def test_robustness_section_counts_the_runs_meeting_each_target():
    """The robustness table: per target the range of the figure over the perturbed runs and how
    many meet it; all-target and second-pass counts; a failed run counts as not meeting."""
    fig = {"quad_percent": 100.0, "n_sj_le_0.2": 0, "mean_sj_skin": 0.9512, "mean_sj_members": 0.96,
           "angles_ok_percent": 98.0, "warp_p99": 9.5, "median_edge_ratio": 0.76}
    low = dict(fig, mean_sj_skin=0.9497, warp_p99=10.4)
    runs = [{"status": "ok", "figures": fig, "wall_s": 3.0, "second_pass": False},
            {"status": "ok", "figures": low, "wall_s": 4.0, "second_pass": True},
            {"status": "error", "error": "boom"}]
    rows = [r for r in robustness_section([{"name": "swept_wing", "size": 0.02, "ribs_per_wing": 10,
                                                "scale": 1e-10, "runs": runs}]) if r.startswith("| swept_wing")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    col = {k: 3 + i for i, k in enumerate(B.TARGETS)}
    assert cells[col["mean_sj_skin"]] == "0.9497–0.9512; 1/3"
    assert cells[col["warp_p99"]] == "9.50–10.40; 1/3"
    assert cells[col["quad_percent"]] == "100.00; 2/3"
    assert cells[-3:] == ["1/3", "1/2", "3.0–4.0"]


def _fake_case(k, wall, gwall, status="ok"):
    """A compare_case result with wall times ``wall`` (ours) and ``gwall`` (Gmsh); CPU = 1.5 x wall."""
    o = {"status": status, "wall_s": wall, "cpu_s": 1.5 * wall, "peak_rss_mb": 300.0, "second_pass": False,
         "stages": {"remesh": 0.7, "quad": 0.9}, "figures": {"n_elements": 25_000}}
    g = {"status": "ok", "wall_s": gwall, "cpu_s": 1.5 * gwall, "peak_rss_mb": 200.0,
         "figures": {"n_elements": 18_000}}
    ok = status == "ok"
    return {"name": "cessna210", "size": 0.25, "ribs_per_wing": 12, "spars": [0.15, 0.65], "load_before": 1.0 + k,
            "load_after": 1.5 + k, "gmsh": g, "ours": o, "time_ratio": wall / gwall if ok else None,
            "cpu_ratio": wall / gwall if ok else None, "targets": None}


def test_perf_pairs_verdict_on_the_median_of_the_pair_ratios(monkeypatch):
    """The performance case as side-by-side pairs: every pair is run and listed, the first pair's
    result (figures, stages) is kept, the verdict is on the median of the pairs' wall-time ratios
    (not on one pair, nor on a ratio of medians), and a pair in which the pipeline failed is
    listed but does not count."""
    walls = [(3.0, 2.0), (2.4, 2.6), (2.5, 2.4), (9.9, 1.0), (2.0, 2.5)]
    calls = []

    def fake(surface, manifest, name, size, ribs, spars, **kw):
        k = len(calls)
        calls.append(k)
        return _fake_case(k, *walls[k], status="error" if k == 3 else "ok")

    monkeypatch.setattr(corpus, "compare_case", fake)
    p = corpus.perf_pairs("x.stl", {}, "cessna210", 0.25, 12, pairs=5)
    assert calls == [0, 1, 2, 3, 4] and p["ours"]["wall_s"] == 3.0 and len(p["pairs"]) == 5
    assert p["pairs"][3]["status"] == "error" and p["pairs"][3]["time_ratio"] is None
    ratios = sorted(w / g for i, (w, g) in enumerate(walls) if i != 3)     # 0.8, 0.923, 1.042, 1.5
    med = p["median"]
    assert med["n"] == 4 and med["time_ratio"] == pytest.approx(0.5 * (ratios[1] + ratios[2]))
    assert med["time_ratio_range"] == pytest.approx([ratios[0], ratios[-1]])
    assert med["wall_s"] == pytest.approx(2.45) and med["gmsh_wall_s"] == pytest.approx(2.45)
    res = {"machine": {"cpus": 2, "memory_gb": 24, "python": "3.11", "numpy": "1", "scipy": "1", "trimesh": "1",
                       "gmsh": "4"}, "started": "now", "load_start": 1.0, "load_end": 1.0, "total_s": 60.0,
           "corpus": [], "performance": p}
    page = B.render_page(res)
    assert "5 such pairs" in page and "| median (4 of 5) |" in page and "| 4 | error |" in page
    assert "Result: **met** — median over 4 pairs" in page          # median ratio 0.98 < 1
    # the same pairs with the last one slower: the median ratio goes above 1, not met
    walls[4] = (2.8, 2.5)
    calls.clear()
    p2 = corpus.perf_pairs("x.stl", {}, "cessna210", 0.25, 12, pairs=5)
    assert p2["median"]["time_ratio"] > 1
    assert "Result: **not met**" in B.render_page(dict(res, performance=p2))
    with pytest.raises(ValueError, match="at least one pair"):
        corpus.perf_pairs("x.stl", {}, "cessna210", 0.25, 12, pairs=0)


def test_missing_gmsh_names_the_extra(monkeypatch):
    """Gmsh is optional (the test and cad extras): without it the comparison stops with one error
    naming the extra to install, and the benchmark script says so before running anything."""
    monkeypatch.setitem(sys.modules, "gmsh", None)             # "import gmsh" raises ImportError
    with pytest.raises(ImportError, match=r'pip install -e "\.\[test\]" \(or "\.\[cad\]"\)'):
        corpus.import_gmsh()
    with pytest.raises(ImportError, match="optional dependency"):
        B.gmsh_quad_remesh("x.stl", 0.1)
