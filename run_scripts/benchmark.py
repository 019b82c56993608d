"""Benchmark the pipeline on the corpus against Gmsh's all-quad remesh of the bare skin; write docs/benchmarks.md.

    python run_scripts/benchmark.py                       # whole benchmark (~15-25 min on 2 busy cores)
    python run_scripts/benchmark.py --quick               # two small cases, no 1M-triangle run (~2 min)
    python run_scripts/benchmark.py --only bwb            # one corpus geometry
    python run_scripts/benchmark.py --no-memory           # skip the 1M-triangle peak-memory run
    python run_scripts/benchmark.py --only bwb --perturb 3   # bwb, then 3 perturbed copies of its input
    python run_scripts/benchmark.py --only cessna210 --no-memory --perf-pairs 9   # the speed target, 9 pairs
    python run_scripts/benchmark.py --from-json docs/benchmarks.json   # re-render the page only

What it runs, each case in its own fresh child process (``multiprocessing`` "spawn") with a time
limit, so a hang or crash (of Gmsh, say) is recorded in the table instead of stopping the script,
and so the peak resident memory of every case (``ru_maxrss`` of the child) is its own:

1. **Corpus** -- every geometry of ``manifest.json`` at its benchmark size (:data:`CORPUS_SIZES`)
   with 10 ribs and 2 spars (chord 0.15 and 0.65) per wing: :func:`run_shellmesh` (the whole
   pipeline, read to all-quad mesh) and :func:`run_gmsh` (Gmsh's all-quad remesh of the bare skin
   STL: ``classifySurfaces`` + ``createGeometry``, Frontal-Delaunay for quads, Blossom
   recombination, one all-quad subdivision; see :func:`gmsh_quad_remesh`).
2. **Performance target** -- cessna210, 2 wings x (12 ribs + 2 spars), size 0.25, run right
   after Gmsh's skin-only remesh of the same file at the same size, as :data:`PERF_PAIRS`
   such pairs one after the other (:func:`perf_pairs`); the verdict is on the median of the
   pairs' time ratios, since one pair's ratio moves by up to a third with the machine's load.
3. **Memory target** -- cessna210 midpoint-subdivided to >= 1M triangles (:func:`refine_surface`,
   the same faceted surface, so the same mesh is expected), the pipeline at size 0.25 with its
   peak RSS and time.
4. **Robustness** (``--perturb K``, default 3 in a full run) -- every corpus case and the
   performance case again on K copies of its input with coordinates multiplied by
   ``1 + 1e-10 g`` (:func:`perturbed_surface`): how many runs meet each target, and the range of
   each figure; a target met with less margin than the run-to-run spread shows here.

"Same size" for Gmsh: it triangulates at ``2 * size`` and its subdivision halves every edge, so its
final quads have edges of about ``size`` -- what the pipeline does too (remesh at
``REMESH_FACTOR * size``, merge, subdivide). The median edge / size column of the page checks it
for both.

Quality figures (:func:`mesh_figures`) are computed with :mod:`shellmesh_mdao.quality` on both
meshes; members are the components whose names contain ``/rib_`` or ``/spar_``
(:func:`member_face_mask`), the rest is skin. :data:`TARGETS` are the issue's acceptance targets;
:func:`target_checks` gives pass/fail per geometry.

Outputs: ``docs/benchmarks.md`` (the page; a hand-kept part below the line
:data:`KEEP_MARKER` of the existing page is carried over unchanged) and ``docs/benchmarks.json``
(every raw figure). ``--quick`` and ``--only`` runs print the page instead of overwriting the
docs unless ``--out`` is given. Mesh figures are deterministic (same input, same mesh); times and
memory are measured and vary with the machine load, which the page states (load average).
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import platform
import resource
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

#: Corpus geometries in table order and their benchmark quad size (surface units).
CORPUS_SIZES = {"straight_wing": 0.02, "swept_wing": 0.02, "bwb": 0.3, "cessna210": 0.25}
#: Smaller cases of ``--quick``: (geometry, size, ribs per wing).
QUICK_CASES = (("straight_wing", 0.05, 4), ("bwb", 0.6, 4))
RIBS = 10
SPARS = (0.15, 0.65)
#: Performance target case: geometry, size, ribs per wing (2 spars).
PERF_CASE = ("cessna210", 0.25, 12)
#: The performance case runs as this many side-by-side pairs (Gmsh, then the pipeline, each in a
#: fresh process); the verdict is on the median of the pairs' time ratios (``--perf-pairs``).
PERF_PAIRS = 5
#: Memory target: geometry refined to at least this many triangles, meshed at this size.
MEMORY_CASE = ("cessna210", 1_000_000, 0.25)
#: Budget of the memory target (GB).
MEMORY_BUDGET_GB = 24.0
#: Relative size of the coordinate perturbation of the robustness runs (``--perturb``).
PERTURB_SCALE = 1e-10
#: Feature angle of Gmsh's classifySurfaces (degrees).
GMSH_FEATURE_ANGLE = 40.0
KEEP_MARKER = "<!-- everything below this line is kept by run_scripts/benchmark.py -->"

#: Acceptance targets: key -> (label, kind, bound). kind "min": value >= bound; "max": value <=
#: bound; "range": lo <= value <= hi.
TARGETS = {
    "quad_percent": ("% quads", "min", 100.0),
    "n_sj_le_0.2": ("elements SJ ≤ 0.2", "max", 0),
    "mean_sj_skin": ("mean SJ skin", "min", 0.95),
    "mean_sj_members": ("mean SJ members", "min", 0.90),
    "angles_ok_percent": ("% quads, angles in [45, 135]", "min", 97.0),
    "warp_p99": ("warp p99 (deg)", "max", 10.0),
    "median_edge_ratio": ("median edge / size", "range", (0.7, 1.3)),
}


# ============================================================================ figures
def member_face_mask(component: np.ndarray, component_names) -> np.ndarray:
    """(m,) bool: True for the faces of a member (component name containing ``/rib_`` or
    ``/spar_``), False for skin."""
    is_member = np.array([("/rib_" in n) or ("/spar_" in n) for n in component_names], bool)
    if not len(is_member):
        return np.zeros(len(component), bool)
    return is_member[np.asarray(component)]


def mesh_figures(mesh, size: float, members: np.ndarray | None = None) -> dict:
    """Quality figures of a :class:`~shellmesh_mdao.mesh.ShellMesh` built for target quad
    edge ``size``: element counts, ``quad_percent``, ``n_folded`` (scaled Jacobian <= 0),
    ``n_sj_le_0.2``, scaled Jacobian ``sj_min`` / ``sj_p1`` / ``sj_mean``, ``mean_sj_skin`` and
    ``mean_sj_members`` (None without members), corner angles ``min_angle`` / ``max_angle``
    (extremes over all elements) and ``angles_ok_percent`` (quads with every corner in
    [45, 135] deg), ``warp_p99`` / ``warp_max`` (quads, degrees), ``aspect_p99``,
    ``median_edge`` and ``median_edge_ratio`` (median unique-edge length / ``size``),
    ``valid`` (``mesh.check().ok``) and ``problems`` (its lines). ``members``: (m,) bool member-face mask (default from
    the component names, :func:`member_face_mask`)."""
    from shellmesh_mdao.quality import QUAD_ANGLE_RANGE, element_quality

    m = mesh.n_faces
    if members is None:
        members = member_face_mask(mesh.component, mesh.component_names)
    q = element_quality(mesh.points, mesh.faces)
    sj = q["scaled_jacobian"]
    quad = mesh.is_quad
    lo, hi = QUAD_ANGLE_RANGE
    ok = quad & (q["min_angle"] >= lo) & (q["max_angle"] <= hi)
    nq = int(quad.sum())
    med = float(np.median(mesh.edge_lengths())) if m else float("nan")
    problems = mesh.check().problems()

    def mean(sel):
        return float(sj[sel].mean()) if sel.any() else None

    return {
        "n_elements": int(m), "n_quads": nq, "n_tris": int(m - nq),
        "n_skin": int((~members).sum()), "n_members": int(members.sum()), "n_points": int(mesh.n_points),
        "quad_percent": 100.0 * nq / m if m else 0.0,
        "n_folded": int((sj <= 0).sum()),
        "n_sj_le_0.2": int((sj <= 0.2).sum()),
        "sj_min": float(sj.min()) if m else None,
        "sj_p1": float(np.percentile(sj, 1)) if m else None,
        "sj_mean": float(sj.mean()) if m else None,
        "mean_sj_skin": mean(~members),
        "mean_sj_members": mean(members),
        "min_angle": float(q["min_angle"].min()) if m else None,
        "max_angle": float(q["max_angle"].max()) if m else None,
        "angles_ok_percent": 100.0 * ok.sum() / nq if nq else None,
        "warp_p99": float(np.percentile(q["warp"][quad], 99)) if nq else None,
        "warp_max": float(q["warp"][quad].max()) if nq else None,
        "aspect_p99": float(np.percentile(q["aspect"], 99)) if m else None,
        "median_edge": med,
        "median_edge_ratio": med / float(size),
        "valid": not problems,
        "problems": problems,
    }


def target_checks(fig: dict) -> dict:
    """Pass/fail of every target in :data:`TARGETS` for figures ``fig`` of :func:`mesh_figures`:
    ``{key: True/False}``, or None where the figure does not exist (no members)."""
    out = {}
    for key, (_, kind, bound) in TARGETS.items():
        v = fig.get(key)
        if v is None:
            out[key] = None
        elif kind == "min":
            out[key] = bool(v >= bound)
        elif kind == "max":
            out[key] = bool(v <= bound)
        else:
            out[key] = bool(bound[0] <= v <= bound[1])
    return out


# ============================================================================ the two meshers
#: modules the pipeline's stages import lazily; imported before the clock (imports are excluded
#: from both meshers' times)
PIPELINE_LAZY_IMPORTS = ("trimesh", "triangle", "highspy", "scipy.sparse.csgraph")
#: the pipeline's own stage modules, which run_pipeline imports as each stage starts; imported
#: before the clock too (where Python writes no bytecode cache, e.g. PYTHONDONTWRITEBYTECODE, an
#: import compiles the module's source: 25-30 ms each for remesh and imprint)
PIPELINE_STAGE_MODULES = tuple(f"shellmesh_mdao.{m}" for m in (
    "load", "layout", "project", "remesh", "imprint", "members", "split", "merge", "smooth", "quad", "quality"))


def perturbed_surface(surface, seed: int, scale: float = PERTURB_SCALE):
    """The surface at ``surface`` (path) with every coordinate multiplied by ``1 + scale * g``,
    ``g`` standard normal from ``numpy.random.default_rng(seed)``: the same geometry to far below
    any tolerance of the pipeline, other rounding (what another machine's maths library or
    another CAD export would give)."""
    from shellmesh_mdao.load import load_surface
    from shellmesh_mdao.mesh import ShellMesh

    mesh, _ = load_surface(surface)
    P = mesh.points * (1.0 + scale * np.random.default_rng(seed).standard_normal(mesh.points.shape))
    return ShellMesh(P, mesh.faces, mesh.component, list(mesh.component_names))


def run_shellmesh(surface, manifest: dict, name: str, size: float, ribs: int = RIBS, spars=SPARS,
                  perturb: int | None = None) -> dict:
    """Run the whole pipeline on ``surface`` (path) with the layout of geometry ``name`` in
    ``manifest`` (``ribs`` per wing, spars at chord fractions ``spars``) at quad size ``size``;
    ``perturb``: the seed of :func:`perturbed_surface` (read before the clock starts).
    Returns wall and CPU seconds (``time.process_time``: every thread of the process), seconds per
    stage, the split/merge solver statuses, whether the quad stage's second final pass ran, the
    input triangle count and :func:`mesh_figures`."""
    from shellmesh_mdao.layout import layout_from_manifest
    from shellmesh_mdao.pipeline import run_pipeline

    import importlib
    # the libraries the stages import on first use (STL reader, triangulator, MIP solver,
    # AABB tree) are imported before the clock starts, as Gmsh's module is for its run
    for mod in PIPELINE_LAZY_IMPORTS + PIPELINE_STAGE_MODULES:
        try:
            importlib.import_module(mod)
        except ImportError:
            pass
    from shellmesh_mdao.kernels import warm_up
    # the numba kernels: loaded from their cache (compiled on a new install), like an import
    jit_s = warm_up()
    layout = layout_from_manifest(manifest, name, ribs=ribs, spars=spars)
    src = str(surface) if perturb is None else perturbed_surface(surface, perturb)
    t0, c0 = time.perf_counter(), time.process_time()
    res = run_pipeline(src, layout, size, progress=False)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    rep = res.report
    return {"wall_s": wall, "cpu_s": cpu, "jit_load_s": round(jit_s, 3), "stages": dict(rep.get("stages", {})),
            "split": rep.get("split"), "merge": rep.get("merge"),
            "second_pass": bool(((rep.get("final_smooth") or {}).get("warp_term") or {}).get("applied")),
            "n_input_triangles": (rep.get("surface") or {}).get("n_triangles"),
            "ribs_per_wing": ribs, "spars": list(spars), "figures": mesh_figures(res.mesh, size)}


def gmsh_quad_remesh(surface, size: float, feature_angle: float = GMSH_FEATURE_ANGLE, threads: int = 1):
    """Gmsh's all-quad remesh of a triangulated surface (STL) whose final quads have edge ~``size``.

    ``classifySurfaces(feature_angle, boundary=True, forReparametrization=True, curveAngle=pi)``
    and ``createGeometry()`` turn the triangulation into reparametrised patches; each is meshed by
    Frontal-Delaunay for quads (``Mesh.Algorithm = 8``) at uniform size ``2 * size``, recombined
    by Blossom (``Mesh.RecombinationAlgorithm = 1``, ``Mesh.RecombineAll = 1``) and split once
    into all quads (``Mesh.SubdivisionAlgorithm = 1``), which halves the edges. Call it in a
    fresh process (Gmsh keeps global state): :func:`run_gmsh` does. Returns ``(points (n, 3),
    faces (m, 4), seconds)`` with triangles, if any, padded with -1; ``seconds`` covers merge to
    extracted arrays.
    """
    import gmsh

    gmsh.initialize(["-nopopup"], readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", int(threads))
        t0 = time.perf_counter()
        gmsh.merge(str(surface))
        gmsh.model.mesh.classifySurfaces(math.radians(feature_angle), True, True, math.pi)
        gmsh.model.mesh.createGeometry()
        for k, v in (("Mesh.Algorithm", 8), ("Mesh.RecombinationAlgorithm", 1), ("Mesh.RecombineAll", 1),
                     ("Mesh.SubdivisionAlgorithm", 1), ("Mesh.MeshSizeMin", 2.0 * size),
                     ("Mesh.MeshSizeMax", 2.0 * size), ("Mesh.MeshSizeFromPoints", 0),
                     ("Mesh.MeshSizeFromCurvature", 0), ("Mesh.MeshSizeExtendFromBoundary", 0)):
            gmsh.option.setNumber(k, v)
        gmsh.model.mesh.generate(2)
        tags, coords, _ = gmsh.model.mesh.getNodes()
        types, _, enodes = gmsh.model.mesh.getElements(2)
        seconds = time.perf_counter() - t0
    finally:
        gmsh.finalize()
    order = np.argsort(tags, kind="stable")
    index = np.full(int(tags.max()) + 1 if len(tags) else 1, -1, np.int64)
    index[tags[order]] = np.arange(len(tags))
    points = coords.reshape(-1, 3)[order]
    blocks = []
    for t, nodes in zip(types, enodes):
        k = {2: 3, 3: 4}.get(int(t))
        if k is None:
            continue
        f = index[np.asarray(nodes, np.int64).reshape(-1, k)]
        if k == 3:
            f = np.hstack([f, np.full((len(f), 1), -1, np.int64)])
        blocks.append(f)
    faces = np.vstack(blocks) if blocks else np.zeros((0, 4), np.int64)
    return points, faces, seconds


def run_gmsh(surface, size: float, feature_angle: float = GMSH_FEATURE_ANGLE) -> dict:
    """:func:`gmsh_quad_remesh` of ``surface`` timed (wall and CPU) with :func:`mesh_figures`
    of its mesh (all skin). Run it in a fresh process (:func:`run_in_child`)."""
    from shellmesh_mdao.mesh import ShellMesh

    import gmsh  # noqa: F401  (imported before the clock starts, like the pipeline's modules)

    c0 = time.process_time()
    points, faces, seconds = gmsh_quad_remesh(surface, size, feature_angle)
    cpu = time.process_time() - c0
    used = np.unique(faces[faces >= 0])
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    faces = np.where(faces >= 0, remap[np.maximum(faces, 0)], -1)
    mesh = ShellMesh(points[used], faces, np.zeros(len(faces), np.int32), ["skin"])
    return {"wall_s": seconds, "cpu_s": cpu, "gmsh_version": gmsh.__version__,
            "options": {"feature_angle": feature_angle, "Mesh.Algorithm": 8, "Mesh.RecombinationAlgorithm": 1,
                        "Mesh.SubdivisionAlgorithm": 1, "Mesh.MeshSize": 2.0 * size},
            "figures": mesh_figures(mesh, size)}


# ============================================================================ child processes
def _child(conn, fn, args, kwargs):
    try:
        out = fn(*args, **kwargs)
        out["status"] = "ok"
    except BaseException as e:  # noqa: BLE001 -- report any failure of the case, never raise
        out = {"status": "error", "error": f"{type(e).__name__}: {e}"}
    ru = resource.getrusage(resource.RUSAGE_SELF)
    out["peak_rss_mb"] = ru.ru_maxrss / 1024.0         # Linux: kilobytes
    out["child_cpu_s"] = ru.ru_utime + ru.ru_stime
    conn.send(out)
    conn.close()


def run_in_child(fn, *args, timeout: float = 3600.0, **kwargs) -> dict:
    """Call ``fn(*args, **kwargs)`` (module-level, returning a dict) in a fresh spawned process
    with a time limit. Returns its dict with ``status`` "ok", ``peak_rss_mb`` (peak resident
    memory of the child, imports included) and ``child_cpu_s``; or ``{"status": "error",
    "error": ...}`` when it raised, ``"timeout"`` when it ran over ``timeout`` seconds (it is
    killed), ``"crashed"`` when the process died (``exit_code``)."""
    ctx = mp.get_context("spawn")
    recv, send = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(send, fn, args, kwargs), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    send.close()
    out = None
    if recv.poll(timeout):
        try:
            out = recv.recv()
        except EOFError:
            out = None
    elapsed = time.perf_counter() - t0
    proc.join(10 if out is not None else 0.5)
    if proc.is_alive():
        proc.kill()
        proc.join()
    recv.close()
    if out is None:
        if elapsed >= timeout:
            out = {"status": "timeout", "error": f"no result after {timeout:g} s (killed)"}
        else:
            out = {"status": "crashed", "exit_code": proc.exitcode,
                   "error": f"child process died (exit code {proc.exitcode})"}
    out["process_wall_s"] = elapsed
    return out


# ============================================================================ 1M-triangle input
def refine_surface(surface, min_triangles: int, out_path) -> dict:
    """Midpoint-subdivide the triangulation in ``surface`` (each triangle -> 4) until it has at
    least ``min_triangles``; write it as a binary STL at ``out_path`` (reused when it exists
    with the same triangle count). The refined surface is the same faceted surface. Returns
    ``{"path", "n_triangles", "levels"}``."""
    import trimesh
    from trimesh.remesh import subdivide

    mesh = trimesh.load(str(surface), force="mesh", process=True)
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    levels = 0
    while len(f) < min_triangles:
        v, f = subdivide(v, f)
        levels += 1
    out = Path(out_path)
    n = len(f)
    if not (out.is_file() and out.stat().st_size == 84 + 50 * n):
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(".tmp.stl")
        trimesh.Trimesh(v, f, process=False).export(str(tmp), file_type="stl")
        os.replace(tmp, out)
    return {"path": str(out), "n_triangles": int(n), "levels": levels}


# ============================================================================ the benchmark
def _load():
    return round(os.getloadavg()[0], 2)


def _log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def _summary(r: dict) -> str:
    if r.get("status") != "ok":
        return f"{r.get('status')}: {r.get('error')}"
    f = r["figures"]
    return (f"{f['n_elements']} elements, {r['wall_s']:.1f} s wall / {r['cpu_s']:.1f} s CPU, "
            f"peak {r['peak_rss_mb']:.0f} MB, mean SJ {f['sj_mean']:.3f}")


def compare_case(surface, manifest, name, size, ribs=RIBS, spars=SPARS, *, timeout=3600.0,
                 gmsh_timeout=1800.0, gmsh: bool = True) -> dict:
    """Gmsh's skin remesh, then the pipeline, of one geometry, side by side (each in its own
    child process). Returns ``{"name", "size", "load_before", "gmsh", "ours", "time_ratio",
    "cpu_ratio", "targets"}`` (ratios: ours / Gmsh; None if either failed)."""
    out = {"name": name, "size": size, "ribs_per_wing": ribs, "spars": list(spars), "load_before": _load()}
    if gmsh:
        out["gmsh"] = run_in_child(run_gmsh, str(surface), size, timeout=gmsh_timeout)
        _log(f"  gmsh {name} @ {size}: {_summary(out['gmsh'])}")
    out["ours"] = run_in_child(run_shellmesh, str(surface), manifest, name, size, ribs, tuple(spars), timeout=timeout)
    _log(f"  ours {name} @ {size}, {ribs} ribs: {_summary(out['ours'])}")
    out["load_after"] = _load()
    g, o = out.get("gmsh", {}), out["ours"]
    ok = g.get("status") == "ok" and o.get("status") == "ok"
    out["time_ratio"] = o["wall_s"] / g["wall_s"] if ok else None
    out["cpu_ratio"] = o["cpu_s"] / g["cpu_s"] if ok else None
    out["targets"] = target_checks(o["figures"]) if o.get("status") == "ok" else None
    return out


def _pair(case: dict) -> dict:
    """One side-by-side pair of :func:`compare_case`'s result ``case``: both runs' wall and CPU
    seconds, their ratios (ours / Gmsh; None unless both ran), statuses, the load and the
    pipeline's element count."""
    g, o = case.get("gmsh") or {}, case["ours"]
    return {"gmsh_status": g.get("status", "not run"), "status": o.get("status"),
            "gmsh_wall_s": g.get("wall_s"), "gmsh_cpu_s": g.get("cpu_s"), "wall_s": o.get("wall_s"),
            "cpu_s": o.get("cpu_s"), "time_ratio": case.get("time_ratio"), "cpu_ratio": case.get("cpu_ratio"),
            "n_elements": (o.get("figures") or {}).get("n_elements"), "second_pass": o.get("second_pass"),
            "load_before": case.get("load_before"), "load_after": case.get("load_after")}


def perf_pairs(surface, manifest, name, size, ribs, pairs: int = PERF_PAIRS, spars=SPARS, *,
               timeout: float = 3600.0, gmsh_timeout: float = 1800.0) -> dict:
    """The performance case: ``pairs`` (>= 1) runs of :func:`compare_case` one after the other
    (Gmsh, then the pipeline, each in a fresh process). Returns the first pair's result (its
    figures, stages and solver statuses: the mesh is the same in every pair) with ``pairs``, the
    list of every pair's :func:`_pair`, and :func:`pair_medians` of them under ``median``."""
    if int(pairs) < 1:
        raise ValueError(f"perf_pairs needs at least one pair, got {pairs!r}")
    cases = []
    for k in range(int(pairs)):
        cases.append(compare_case(surface, manifest, name, size, ribs, spars, timeout=timeout,
                                  gmsh_timeout=gmsh_timeout))
        _log(f"  pair {k + 1}/{int(pairs)}: time ratio {_f(cases[-1].get('time_ratio'), '{:.2f}')}")
    rows = [_pair(c) for c in cases]
    first = cases[0]
    first["pairs"] = rows
    first["median"] = pair_medians(rows)
    return first


def pair_medians(rows: list) -> dict:
    """Medians over the pairs ``rows`` (:func:`_pair`) in which both runs finished: wall and CPU
    seconds of each side and the pairs' own time ratios (``n``: how many pairs count; None
    values when none does)."""
    ok = [r for r in rows if r.get("time_ratio") is not None]
    keys = ("wall_s", "cpu_s", "gmsh_wall_s", "gmsh_cpu_s", "time_ratio", "cpu_ratio")
    out = {k: (float(np.median([r[k] for r in ok])) if ok else None) for k in keys}
    out["n"] = len(ok)
    out["time_ratio_range"] = [min(r["time_ratio"] for r in ok), max(r["time_ratio"] for r in ok)] if ok else None
    return out


def run_benchmark(geometry_dir, *, only=None, quick: bool = False, perf: bool = True, memory: bool = True,
                  work_dir=None, timeout: float = 3600.0, gmsh_timeout: float = 1800.0, perturb: int = 0,
                  pairs: int = PERF_PAIRS) -> dict:
    """Run the benchmark and return the raw figures (what docs/benchmarks.json holds).

    ``only``: one corpus geometry (its corpus case; plus the performance / memory case when
    they use it). ``quick``: :data:`QUICK_CASES` only. ``perf``/``memory``: run the performance
    and 1M-triangle memory cases. ``work_dir``: where the refined STL goes (default a folder in
    the temporary directory). ``perturb``: run every corpus case and the performance case again
    on that many perturbed copies of its input (:func:`perturbed_surface`, seeds 0, 1, ...).
    ``pairs``: side-by-side pairs of the performance case (:func:`perf_pairs`)."""
    import tempfile

    gdir = Path(geometry_dir)
    manifest = json.loads((gdir / "manifest.json").read_text())
    geos = manifest["geometries"]
    if only is not None and only not in geos:
        raise SystemExit(f"--only {only!r}: no such geometry in {gdir / 'manifest.json'} (known: {', '.join(geos)})")
    import gmsh
    import scipy
    import trimesh

    from shellmesh_mdao import pipeline

    res = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                       "numpy": np.__version__, "scipy": scipy.__version__, "trimesh": trimesh.__version__,
                       "gmsh": gmsh.__version__,
                       "memory_gb": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)},
           "started": time.strftime("%Y-%m-%d %H:%M"), "load_start": _load(), "quick": bool(quick),
           "only": only, "corpus": [], "performance": None, "memory": None, "robustness": [],
           "remesh_factor": pipeline.REMESH_FACTOR}
    if quick:
        cases = [(n, s, r) for n, s, r in QUICK_CASES if only in (None, n)]
        perf = memory = False
    else:
        cases = [(n, s, RIBS) for n, s in CORPUS_SIZES.items() if n in geos and only in (None, n)]
    t_all = time.perf_counter()
    for name, size, ribs in cases:
        _log(f"corpus: {name} at size {size}, {ribs} ribs + {len(SPARS)} spars per wing")
        res["corpus"].append(compare_case(gdir / geos[name]["file"], manifest, name, size, ribs,
                                          timeout=timeout, gmsh_timeout=gmsh_timeout))
    pname, psize, pribs = PERF_CASE
    if perf and only in (None, pname) and pname in geos:
        _log(f"performance target: {pname} at size {psize}, {pribs} ribs + {len(SPARS)} spars per wing")
        res["performance"] = perf_pairs(gdir / geos[pname]["file"], manifest, pname, psize, pribs, pairs,
                                        timeout=timeout, gmsh_timeout=gmsh_timeout)
    rob = list(cases) + ([PERF_CASE] if res["performance"] is not None else [])
    for name, size, ribs in (rob if perturb > 0 else []):
        runs = []
        for seed in range(int(perturb)):
            o = run_in_child(run_shellmesh, str(gdir / geos[name]["file"]), manifest, name, size, ribs, SPARS,
                             perturb=seed, timeout=timeout)
            runs.append(o)
            _log(f"  perturbed {name} @ {size}, {ribs} ribs, seed {seed}: {_summary(o)}")
        res["robustness"].append({"name": name, "size": size, "ribs_per_wing": ribs, "scale": PERTURB_SCALE,
                                  "runs": runs})
    mname, mtris, msize = MEMORY_CASE
    if memory and only in (None, mname) and mname in geos:
        wdir = Path(work_dir) if work_dir else Path(tempfile.gettempdir()) / "shellmesh_benchmark"
        _log(f"memory target: {mname} refined to >= {mtris:,} triangles")
        t0 = time.perf_counter()
        ref = refine_surface(gdir / geos[mname]["file"], mtris, wdir / f"{mname}_{mtris}.stl")
        ref["refine_s"] = time.perf_counter() - t0
        case = {"name": mname, "size": msize, "refined": ref, "load_before": _load()}
        case["ours"] = run_in_child(run_shellmesh, ref["path"], manifest, mname, msize, RIBS, SPARS,
                                    timeout=max(timeout, 7200.0))
        case["load_after"] = _load()
        _log(f"  ours {mname} {ref['n_triangles']:,} triangles: {_summary(case['ours'])}")
        o = case["ours"]
        case["within_budget"] = (o.get("status") == "ok" and o["peak_rss_mb"] / 1024 < MEMORY_BUDGET_GB)
        res["memory"] = case
    res["total_s"] = time.perf_counter() - t_all
    res["load_end"] = _load()
    return res


# ============================================================================ the page
def _f(v, fmt="{:.3f}", none="—"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return none
    return fmt.format(v)


def _i(v):
    return "—" if v is None else f"{int(v):,}"


def _mark(ok):
    return "—" if ok is None else ("pass" if ok else "**FAIL**")


def _status(r):
    return r.get("status", "not run") if r else "not run"


def _bound_text(kind, bound):
    if kind == "min":
        return f"≥ {bound:g}"
    if kind == "max":
        return f"≤ {bound:g}"
    return f"{bound[0]:g}–{bound[1]:g}"


def _target_value(key, f):
    v = f.get(key)
    if key in ("quad_percent", "angles_ok_percent"):
        return _f(v, "{:.2f} %")
    if key == "n_sj_le_0.2":
        return _i(v)
    if key == "warp_p99":
        return _f(v, "{:.2f}°")
    return _f(v)


def _stage_items(stages: dict) -> list[tuple[str, float]]:
    """(stage, seconds) in pipeline order (the JSON's keys are sorted)."""
    from shellmesh_mdao.pipeline import STAGES

    rank = {k: i for i, k in enumerate(STAGES)}
    return sorted(stages.items(), key=lambda kv: (rank.get(kv[0], len(rank)), kv[0]))


def _quality_rows(case: dict) -> list[str]:
    rows = []
    for who, label in (("ours", "shellmesh (skin + members)"), ("gmsh", "Gmsh (skin only)")):
        r = case.get(who)
        if r is None:
            continue
        head = f"| {case['name']} | {case['size']:g} | {label} "
        if r.get("status") != "ok":
            rows.append(head + f"| {r.get('status')}: {r.get('error', '')} " + "| " * 13 + "|")
            continue
        f = r["figures"]
        rows.append(head + "| " + " | ".join([
            _i(f["n_elements"]), _i(f["n_skin"]), _f(f["quad_percent"], "{:.2f} %"), _i(f["n_folded"]),
            _i(f["n_sj_le_0.2"]), _f(f["sj_min"]), _f(f["sj_mean"]), _f(f["min_angle"], "{:.1f}°"),
            _f(f["max_angle"], "{:.1f}°"), _f(f["angles_ok_percent"], "{:.2f} %"), _f(f["warp_p99"], "{:.2f}°"),
            _f(f["median_edge_ratio"], "{:.2f}"), "yes" if f["valid"] else "**no**"]) + " |")
    return rows


def _time_row(case: dict) -> str:
    g, o = case.get("gmsh") or {}, case["ours"]

    def t(r):
        if r.get("status") != "ok":
            return f"{r.get('status', 'not run')}", "—", "—"
        return f"{r['wall_s']:.1f}", f"{r['cpu_s']:.1f}", f"{r['peak_rss_mb']:,.0f}"

    ow, oc, om = t(o)
    gw, gc, gm = t(g) if g else ("not run", "—", "—")
    return (f"| {case['name']} | {case['size']:g} | {case['ribs_per_wing']} | {ow} | {oc} | {om} | {gw} | {gc} | {gm} | "
            f"{_f(case.get('time_ratio'), '{:.1f}')} | {_f(case.get('cpu_ratio'), '{:.1f}')} | "
            f"{case['load_before']:.1f} / {case['load_after']:.1f} |")


def _robustness_section(rob: list) -> list[str]:
    """The page's section on the perturbed runs: per case and target, how many runs meet it and
    the range of its figure; the wall-time range and how many runs needed the second final pass."""
    scale = rob[0].get("scale", PERTURB_SCALE)
    L = ["## Robustness under input perturbation", "",
         (f"Each case again on {len(rob[0]['runs'])} copies of its input whose coordinates are multiplied by "
         f"`1 + {scale:g} g` (`g` standard normal, seeds 0, 1, ...; `--perturb`): the same geometry to far below "
         "any tolerance, other rounding, as another machine's maths library or another export of the same CAD "
         "would give. The meshes differ (the discrete stages branch on rounding), so each figure below is a "
         "range, followed by how many runs meet its target. A target met in the table above but not in every "
         "run here has a margin below the run-to-run spread."), "",
         "| geometry | size | ribs / wing | " + " | ".join(f"{TARGETS[k][0]} ({_bound_text(*TARGETS[k][1:])})"
                                                    for k in TARGETS) + " | all targets | second final pass | wall s |",
         "| --- | --- | --- | " + " | ".join("---" for _ in TARGETS) + " | --- | --- | --- |"]
    for c in rob:
        ok = [r for r in c["runs"] if r.get("status") == "ok"]
        n = len(c["runs"])
        if not ok:
            L.append(f"| {c['name']} | {c['size']:g} | {c['ribs_per_wing']} | no run finished: "
                     f"{_status(c['runs'][0]) if c['runs'] else '—'} |" + " — |" * (len(TARGETS) + 2))
            continue
        cells = []
        for k in TARGETS:
            vals = [r["figures"][k] for r in ok if r["figures"].get(k) is not None]
            if not vals:
                cells.append("—")
                continue
            met = sum(bool(target_checks(r["figures"])[k]) for r in ok)
            fmt = "{:.0f}" if k == "n_sj_le_0.2" else ("{:.2f}" if k in ("quad_percent", "angles_ok_percent",
                                                                         "warp_p99") else "{:.4f}")
            rng = fmt.format(min(vals)) if min(vals) == max(vals) else f"{fmt.format(min(vals))}–{fmt.format(max(vals))}"
            cells.append(f"{rng}; {met}/{n}")
        allm = sum(all(v is not False for v in target_checks(r["figures"]).values()) for r in ok)
        walls = [r["wall_s"] for r in ok]
        L.append(f"| {c['name']} | {c['size']:g} | {c['ribs_per_wing']} | " + " | ".join(cells)
                 + f" | {allm}/{n} | {sum(bool(r.get('second_pass')) for r in ok)}/{len(ok)} | "
                 f"{min(walls):.1f}–{max(walls):.1f} |")
    return L + [""]


def render_page(res: dict, keep: str = "") -> str:
    """The Markdown page of the results ``res`` of :func:`run_benchmark`; ``keep`` (the
    hand-kept part of the previous page) is appended after :data:`KEEP_MARKER`."""
    m = res["machine"]
    L = ["# Benchmarks", ""]
    mode = " (`--quick`: small cases)" if res.get("quick") else (f" (`--only {res['only']}`)" if res.get("only") else "")
    L += [f"Generated by `python run_scripts/benchmark.py`{mode} on {res['started']}: {m['cpus']} cores, "
          f"{m['memory_gb']} GB, Python {m['python']}, numpy {m['numpy']}, scipy {m['scipy']}, trimesh {m['trimesh']}, "
          f"Gmsh {m['gmsh']}. The machine was shared with other jobs: 1-minute load average {res['load_start']:.1f} at "
          f"the start, {res['load_end']:.1f} at the end, per case below; with 2 cores, a load above 2 means every "
          f"process got less than a core, so wall times are inflated (compare the CPU times, and allow ±30 %). "
          f"Whole run: {res['total_s'] / 60:.1f} min. Mesh figures are deterministic; times and memory are not.", ""]
    L += ["Each case runs in its own fresh process (imports excluded from the times, included in the peak "
          "memory; the libraries the stages import on first use, "
          + ", ".join(f"`{m}`" for m in PIPELINE_LAZY_IMPORTS) + ", and the pipeline's own stage modules "
          "(`shellmesh_mdao.remesh`, `.imprint`, ...) are imported before the clock starts, as `gmsh` is, and "
          "the compiled kernels of `shellmesh_mdao.kernels` are loaded from numba's cache by "
          "`kernels.warm_up()`, about 0.3 s, compiled on a new install). Layouts: "
          "`layout_from_manifest(manifest, name, ribs, spars=(0.15, 0.65))`, i.e. ribs per wing and 2 spars. "
          "Gmsh remeshes the bare skin STL: `classifySurfaces` "
          f"({GMSH_FEATURE_ANGLE:g}° feature angle, reparametrisation) + `createGeometry`, Frontal-Delaunay for quads "
          "(`Mesh.Algorithm = 8`), Blossom (`Mesh.RecombinationAlgorithm = 1`, `RecombineAll`), one all-quad "
          "subdivision (`Mesh.SubdivisionAlgorithm = 1`), one thread. Gmsh meshes at `2 × size`, the pipeline at "
          f"`{res.get('remesh_factor', 2.0):g} × size` (`pipeline.REMESH_FACTOR`); both subdivide once, so both aim "
          "at quads of edge `size` (median edge / size checks it).", ""]

    # ---- targets
    L += ["## Quality targets (the pipeline's final mesh)", ""]
    keys = list(TARGETS)
    L += ["| geometry | size | " + " | ".join(f"{TARGETS[k][0]} ({_bound_text(*TARGETS[k][1:])})" for k in keys)
          + " | all pass |",
          "| --- | --- | " + " | ".join("---" for _ in keys) + " | --- |"]
    for case in res["corpus"]:
        o = case["ours"]
        if o.get("status") != "ok":
            L.append(f"| {case['name']} | {case['size']:g} | {o.get('status')}: {o.get('error', '')} |"
                     + " |" * len(keys))
            continue
        f, t = o["figures"], case["targets"]
        cells = [f"{_target_value(k, f)} {_mark(t[k])}" if t[k] is not None else "—" for k in keys]
        allok = all(v for v in t.values() if v is not None)
        L.append(f"| {case['name']} | {case['size']:g} | " + " | ".join(cells) + f" | {'yes' if allok else '**no**'} |")
    L += ["", "SJ = scaled Jacobian (Verdict; 1 for a square, ≤ 0 folded). Members are the components named "
          "`<wing>/rib_k` or `<wing>/spar_j` (and their segments); the rest is skin. Warp p99 over quads; median "
          "edge over unique edges.", ""]

    # ---- comparison
    L += ["## Side by side with Gmsh's all-quad remesh of the skin", "",
          "| geometry | size | mesher | elements | skin elements | quads | folded (SJ ≤ 0) | SJ ≤ 0.2 | min SJ "
          "| mean SJ | min angle | max angle | quads, angles in [45°, 135°] | warp p99 | median edge / size | valid |",
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for case in res["corpus"]:
        L += _quality_rows(case)
    L += ["", "\"valid\": `ShellMesh.check()` finds no duplicate node, degenerate face, inconsistent orientation "
          "or hanging node. The quality figures do not depend on orientation (corner angles and Jacobians are "
          "measured against each element's own normal).", ""]
    probs = [(c["name"], who, r["figures"]["problems"]) for c in res["corpus"] for who, r in
             (("shellmesh", c["ours"]), ("Gmsh", c.get("gmsh") or {})) if r.get("status") == "ok"
             and r["figures"].get("problems")]
    if probs:
        L += ["Problems `check()` found:", ""] + [f"- {n}, {who}: " + "; ".join(p) for n, who, p in probs] + [""]
    L += ["### Time and memory", "",
          "| geometry | size | ribs / wing | shellmesh wall s | CPU s | peak MB | Gmsh wall s | CPU s | peak MB "
          "| time ratio (wall) | time ratio (CPU) | load before / after |",
          "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for case in res["corpus"]:
        L.append(_time_row(case))
    L += ["", "Time ratio = shellmesh / Gmsh (below 1: the pipeline is faster). shellmesh's time is the whole "
          "`run_pipeline` (read, repair, project, remesh, imprint, members, split, merge, smooth, subdivide; skin "
          "and members); Gmsh's from `merge` to the extracted arrays (skin only). CPU time counts every thread of "
          "the process.", ""]

    # ---- stages
    stages = [c for c in res["corpus"] if c["ours"].get("status") == "ok"]
    if stages:
        names = [k for k, _ in _stage_items({k: 0 for c in stages for k in c["ours"]["stages"]})]
        L += ["### Pipeline stages (wall seconds)", "",
              "| geometry | input triangles | " + " | ".join(names) + " | split LP | merge MIP (gap) |",
              "| --- | --- | " + " | ".join("---" for _ in names) + " | --- | --- |"]
        for c in stages:
            o = c["ours"]
            sp, me = o.get("split") or {}, o.get("merge") or {}
            L.append(f"| {c['name']} | {_i(o.get('n_input_triangles'))} | "
                     + " | ".join(_f(o["stages"].get(k), "{:.1f}") for k in names)
                     + f" | {sp.get('status', '—')} | {me.get('status', '—')} ({_f(me.get('mip_gap'), '{:.3f}')}) |")
        L.append("")

    # ---- performance target
    p = res.get("performance")
    if p is not None:
        g, o = p.get("gmsh") or {}, p["ours"]
        rows = p.get("pairs") or [_pair(p)]            # pages of runs before the pairs: their one pair
        med = p.get("median") or pair_medians(rows)
        L += ["## Performance target", "",
              f"Target: the full run on {p['name']} with 2 wings × ({p['ribs_per_wing']} ribs + {len(p['spars'])} "
              f"spars) at size {p['size']:g} takes less time than Gmsh's skin-only remesh of the same file at the same "
              "size, measured side by side: Gmsh first, then the pipeline, in consecutive processes, "
              f"{len(rows)} such pair{'s' if len(rows) != 1 else ''} one after the other. The verdict is on the median "
              "of the pairs' time ratios: one pair's ratio moves by up to a third with the machine's load.", "",
              "| pair | shellmesh wall s | CPU s | Gmsh wall s | CPU s | time ratio (wall) | time ratio (CPU) "
              "| load before / after |",
              "| --- | --- | --- | --- | --- | --- | --- | --- |"]
        for k, r in enumerate(rows, 1):
            ow = _f(r.get("wall_s"), "{:.2f}") if r.get("status") == "ok" else str(r.get("status"))
            gw = _f(r.get("gmsh_wall_s"), "{:.2f}") if r.get("gmsh_status") == "ok" else str(r.get("gmsh_status"))
            L.append(f"| {k} | {ow} | {_f(r.get('cpu_s'), '{:.2f}')} | {gw} | {_f(r.get('gmsh_cpu_s'), '{:.2f}')} | "
                     f"{_f(r.get('time_ratio'), '{:.2f}')} | {_f(r.get('cpu_ratio'), '{:.2f}')} | "
                     f"{_f(r.get('load_before'), '{:.1f}')} / {_f(r.get('load_after'), '{:.1f}')} |")
        L.append(f"| median ({med['n']} of {len(rows)}) | {_f(med['wall_s'], '{:.2f}')} | "
                 f"{_f(med['cpu_s'], '{:.2f}')} | "
                 f"{_f(med['gmsh_wall_s'], '{:.2f}')} | {_f(med['gmsh_cpu_s'], '{:.2f}')} | "
                 f"{_f(med['time_ratio'], '{:.2f}')} | {_f(med['cpu_ratio'], '{:.2f}')} | |")
        L.append("")
        if med["time_ratio"] is not None:
            met = med["time_ratio"] < 1.0
            lo, hi = med["time_ratio_range"]
            plural = "s" if med["n"] != 1 else ""
            L += [f"Result: **{'met' if met else 'not met'}** — median over {med['n']} pair{plural}: the pipeline "
                  f"{med['wall_s']:.2f} s ({med['cpu_s']:.2f} s CPU) for "
                  f"{_i((o.get('figures') or {}).get('n_elements'))} quads of skin and members, Gmsh "
                  f"{med['gmsh_wall_s']:.2f} s ({med['gmsh_cpu_s']:.2f} s CPU) for "
                  f"{_i((g.get('figures') or {}).get('n_elements'))} quads of skin: {med['time_ratio']:.2f}× (wall; "
                  f"the pairs {lo:.2f}–{hi:.2f}×), {med['cpu_ratio']:.2f}× (CPU). Peak memory (first pair): the "
                  f"pipeline {_f(o.get('peak_rss_mb'), '{:,.0f}')} MB, Gmsh {_f(g.get('peak_rss_mb'), '{:,.0f}')} MB. "
                  "Stages (first pair): " + ", ".join(f"{k} {v:.1f}" for k, v in _stage_items(o.get("stages") or {}))
                  + " s.", ""]
        else:
            L += [f"Result: not measured (shellmesh: {_status(o)}, Gmsh: {_status(g)}).", ""]

    # ---- robustness
    if res.get("robustness"):
        L += _robustness_section(res["robustness"])

    # ---- memory target
    mm = res.get("memory")
    if mm is not None:
        o, ref = mm["ours"], mm["refined"]
        L += ["## Memory target", "",
              f"Target: a run on a 1M-triangle input completes within {MEMORY_BUDGET_GB:g} GB. Input: {mm['name']} "
              f"midpoint-subdivided {ref['levels']} times (`trimesh.remesh.subdivide`, each triangle → 4, the same "
              f"faceted surface) to {ref['n_triangles']:,} triangles; the pipeline at size {mm['size']:g} with "
              f"{RIBS} ribs + {len(SPARS)} spars per wing, in a fresh process; peak = `ru_maxrss` of that process.", ""]
        if o.get("status") == "ok":
            f = o["figures"]
            L += ["| input triangles | peak memory | wall s | CPU s | output quads | mean SJ | SJ ≤ 0.2 | median edge / "
                  "size | load before / after | within budget |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
                  f"| {ref['n_triangles']:,} | {o['peak_rss_mb'] / 1024:.2f} GB | {o['wall_s']:.0f} | {o['cpu_s']:.0f} | "
                  f"{f['n_elements']:,} | {f['sj_mean']:.3f} | {f['n_sj_le_0.2']:,} | {f['median_edge_ratio']:.2f} | "
                  f"{mm['load_before']:.1f} / {mm['load_after']:.1f} | {'yes' if mm['within_budget'] else '**no**'} |",
                  "", "Stages (s): " + ", ".join(f"{k} {v:.1f}" for k, v in _stage_items(o["stages"])) + ".", ""]
            base = [c for c in res["corpus"] if c["name"] == mm["name"] and c["size"] == mm["size"]
                    and c["ribs_per_wing"] == RIBS and c["ours"].get("status") == "ok"]
            if base:
                b = base[0]["ours"]
                L += [f"The same geometry from its original {_i(b.get('n_input_triangles'))} triangles (corpus run "
                      f"above): {b['figures']['n_elements']:,} quads, mean SJ {b['figures']['sj_mean']:.3f}, "
                      f"{b['wall_s']:.0f} s, peak {b['peak_rss_mb'] / 1024:.2f} GB: the output follows the size, "
                      "not the input's triangle count.", ""]
        else:
            L += [f"Result: {o.get('status')}: {o.get('error', '')} (peak {o.get('peak_rss_mb', float('nan')):.0f} MB).",
                  ""]

    L += ["Raw figures of every case: [benchmarks.json](benchmarks.json).", ""]
    if keep.strip():
        L += [KEEP_MARKER, "", keep.strip("\n"), ""]
    return "\n".join(L)


def kept_part(page_path) -> str:
    """The hand-kept part of an existing page: everything after :data:`KEEP_MARKER` ('' if none)."""
    p = Path(page_path)
    if not p.is_file():
        return ""
    text = p.read_text()
    i = text.find(KEEP_MARKER)
    return text[i + len(KEEP_MARKER):] if i >= 0 else ""


def write_outputs(res: dict, out_md) -> tuple[Path, Path]:
    """Write the page (keeping the hand-kept part of the existing one) and the JSON beside it
    (same stem, ``.json``; keys sorted). Returns both paths."""
    out_md = Path(out_md)
    page = render_page(res, kept_part(out_md))
    out_md.parent.mkdir(parents=True, exist_ok=True)
    out_md.write_text(page)
    js = out_md.with_suffix(".json")
    js.write_text(json.dumps(res, indent=1, sort_keys=True, default=float) + "\n")
    return out_md, js


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--geometry-dir", default=str(REPO.parent / "shared" / "geometry"),
                    help="benchmark corpus folder with manifest.json (default ../shared/geometry beside the repo)")
    ap.add_argument("--quick", action="store_true", help="two small cases only (no performance / memory case)")
    ap.add_argument("--only", metavar="NAME", help="one corpus geometry (e.g. bwb)")
    ap.add_argument("--no-perf", action="store_true", help="skip the performance-target case")
    ap.add_argument("--no-memory", action="store_true", help="skip the 1M-triangle memory case")
    ap.add_argument("--out", help="page to write (default docs/benchmarks.md for a full run; --quick/--only "
                                  "print the page unless --out is given); the JSON goes beside it")
    ap.add_argument("--work-dir", help="folder for the refined 1M-triangle STL (default: temporary directory)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="time limit per pipeline case (s)")
    ap.add_argument("--gmsh-timeout", type=float, default=1800.0, help="time limit per Gmsh case (s)")
    ap.add_argument("--perturb", type=int, default=None, metavar="K",
                    help="run every corpus case and the performance case again on K perturbed copies of its input "
                         "(coordinates x (1 + 1e-10 g)); default 3 for a full run, 0 for --quick / --only")
    ap.add_argument("--perf-pairs", type=int, default=PERF_PAIRS, metavar="N",
                    help=f"side-by-side pairs (Gmsh, then the pipeline) of the performance case; the verdict is on "
                         f"the median of their time ratios (default {PERF_PAIRS})")
    ap.add_argument("--from-json", metavar="JSON", help="re-render the page from the raw figures of an earlier run "
                                                         "(written beside it; nothing is run)")
    args = ap.parse_args(argv)
    if args.from_json:
        res = json.loads(Path(args.from_json).read_text())
        out = Path(args.out) if args.out else Path(args.from_json).with_suffix(".md")
        out.write_text(render_page(res, kept_part(out)))
        _log(f"wrote {out}")
        return 0
    if args.perf_pairs < 1:
        ap.error(f"--perf-pairs needs at least 1, got {args.perf_pairs}")
    gdir = Path(args.geometry_dir)
    if not (gdir / "manifest.json").is_file():
        ap.error(f"no manifest.json in {gdir}: pass --geometry-dir (the benchmark corpus folder)")
    res = run_benchmark(gdir, only=args.only, quick=args.quick, perf=not args.no_perf, memory=not args.no_memory,
                        work_dir=args.work_dir, timeout=args.timeout, gmsh_timeout=args.gmsh_timeout,
                        perturb=(0 if (args.quick or args.only) else 3) if args.perturb is None else args.perturb,
                        pairs=args.perf_pairs)
    out = args.out or (None if (args.quick or args.only) else REPO / "docs" / "benchmarks.md")
    if out is None:
        print(render_page(res))
    else:
        md, js = write_outputs(res, out)
        _log(f"wrote {md} and {js}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
