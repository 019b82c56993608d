"""The benchmark harness: the pipeline against Gmsh's all-quad remesh on the corpus.

``python run_scripts/benchmark.py`` runs it (its ``--help`` lists the options) and writes
docs/benchmarks.md with :mod:`shellmesh_mdao.benchmarks.page`. Gmsh is an optional dependency
(the ``test`` and ``cad`` extras): it is imported by the functions that run it
(:func:`import_gmsh`).

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

Quality figures (:func:`~shellmesh_mdao.benchmarks.figures.mesh_figures`) are computed with
:mod:`shellmesh_mdao.quality` on both meshes; members are the ribs and spars (``<wing>/rib_<k>``,
``<wing>/spar_<j>`` and their pieces), the rest is skin. :data:`~shellmesh_mdao.benchmarks.figures.TARGETS` are
the issue's acceptance targets; :func:`~shellmesh_mdao.benchmarks.figures.target_checks` gives
pass/fail per geometry.

:func:`run_benchmark` returns every raw figure (what ``docs/benchmarks.json`` holds);
:func:`~shellmesh_mdao.benchmarks.page.write_outputs` writes the page and the JSON. Mesh figures
are deterministic (same input, same mesh); times and memory are measured and vary with the
machine load, which the page states (load average).
"""
from __future__ import annotations

import importlib
import json
import math
import os
import platform
import time
from pathlib import Path

import numpy as np

from .child import run_in_child
from .figures import mesh_figures, target_checks

__all__ = ["CORPUS_SIZES", "GMSH_FEATURE_ANGLE", "MEMORY_BUDGET_GB", "MEMORY_CASE", "PERF_CASE", "PERF_PAIRS",
           "PERTURB_SCALE", "PIPELINE_LAZY_IMPORTS", "PIPELINE_STAGE_MODULES", "QUICK_CASES", "RIBS", "SPARS", "compare_case", "gmsh_quad_remesh", "import_gmsh", "load_average", "log",
           "pair_medians", "pair_row", "perf_pairs", "perturbed_surface", "refine_surface", "run_benchmark",
           "run_gmsh", "run_shellmesh"]

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
    from ..load import load_surface
    from ..mesh import ShellMesh

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
    from ..layout import layout_from_manifest
    from ..pipeline import run_pipeline

    # the libraries the stages import on first use (STL reader, triangulator, MIP solver,
    # AABB tree) are imported before the clock starts, as Gmsh's module is for its run
    for mod in PIPELINE_LAZY_IMPORTS + PIPELINE_STAGE_MODULES:
        try:
            importlib.import_module(mod)
        except ImportError:
            pass
    from ..kernels import warm_up
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


def import_gmsh():
    """The ``gmsh`` module; an ImportError naming the extra that installs it when it is missing."""
    try:
        import gmsh
    except ImportError as exc:
        raise ImportError('the Gmsh comparison needs the gmsh package, an optional dependency: '
                          'pip install -e ".[test]" (or ".[cad]")') from exc
    return gmsh


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
    gmsh = import_gmsh()
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
    from ..families import SKIN
    from ..mesh import ShellMesh

    gmsh = import_gmsh()            # imported before the clock starts, like the pipeline's modules
    c0 = time.process_time()
    points, faces, seconds = gmsh_quad_remesh(surface, size, feature_angle)
    cpu = time.process_time() - c0
    used = np.unique(faces[faces >= 0])
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(len(used))
    faces = np.where(faces >= 0, remap[np.maximum(faces, 0)], -1)
    mesh = ShellMesh(points[used], faces, np.zeros(len(faces), np.int32), [SKIN])
    return {"wall_s": seconds, "cpu_s": cpu, "gmsh_version": gmsh.__version__,
            "options": {"feature_angle": feature_angle, "Mesh.Algorithm": 8, "Mesh.RecombinationAlgorithm": 1,
                        "Mesh.SubdivisionAlgorithm": 1, "Mesh.MeshSize": 2.0 * size},
            "figures": mesh_figures(mesh, size)}


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
def load_average() -> float:
    """The 1-minute load average, rounded to 0.01."""
    return round(os.getloadavg()[0], 2)


def log(msg: str) -> None:
    """Print ``msg`` with the time of day (the benchmark's progress lines)."""
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", flush=True)


def _ratio(v) -> str:
    return "—" if v is None else f"{v:.2f}"


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
    out = {"name": name, "size": size, "ribs_per_wing": ribs, "spars": list(spars), "load_before": load_average()}
    if gmsh:
        out["gmsh"] = run_in_child(run_gmsh, str(surface), size, timeout=gmsh_timeout)
        log(f"  gmsh {name} @ {size}: {_summary(out['gmsh'])}")
    out["ours"] = run_in_child(run_shellmesh, str(surface), manifest, name, size, ribs, tuple(spars), timeout=timeout)
    log(f"  ours {name} @ {size}, {ribs} ribs: {_summary(out['ours'])}")
    out["load_after"] = load_average()
    g, o = out.get("gmsh", {}), out["ours"]
    ok = g.get("status") == "ok" and o.get("status") == "ok"
    out["time_ratio"] = o["wall_s"] / g["wall_s"] if ok else None
    out["cpu_ratio"] = o["cpu_s"] / g["cpu_s"] if ok else None
    out["targets"] = target_checks(o["figures"]) if o.get("status") == "ok" else None
    return out


def pair_row(case: dict) -> dict:
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
    list of every pair's :func:`pair_row`, and :func:`pair_medians` of them under ``median``."""
    if int(pairs) < 1:
        raise ValueError(f"perf_pairs needs at least one pair, got {pairs!r}")
    cases = []
    for k in range(int(pairs)):
        cases.append(compare_case(surface, manifest, name, size, ribs, spars, timeout=timeout,
                                  gmsh_timeout=gmsh_timeout))
        log(f"  pair {k + 1}/{int(pairs)}: time ratio {_ratio(cases[-1].get('time_ratio'))}")
    rows = [pair_row(c) for c in cases]
    first = cases[0]
    first["pairs"] = rows
    first["median"] = pair_medians(rows)
    return first


def pair_medians(rows: list) -> dict:
    """Medians over the pairs ``rows`` (:func:`pair_row`) in which both runs finished: wall and CPU
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
        raise ValueError(f"only={only!r}: no such geometry in {gdir / 'manifest.json'} (known: {', '.join(geos)})")
    gmsh = import_gmsh()
    import scipy
    import trimesh

    from .. import pipeline

    res = {"machine": {"cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
                       "numpy": np.__version__, "scipy": scipy.__version__, "trimesh": trimesh.__version__,
                       "gmsh": gmsh.__version__,
                       "memory_gb": round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)},
           "started": time.strftime("%Y-%m-%d %H:%M"), "load_start": load_average(), "quick": bool(quick),
           "only": only, "corpus": [], "performance": None, "memory": None, "robustness": [],
           "remesh_factor": pipeline.REMESH_FACTOR}
    if quick:
        cases = [(n, s, r) for n, s, r in QUICK_CASES if only in (None, n)]
        perf = memory = False
    else:
        cases = [(n, s, RIBS) for n, s in CORPUS_SIZES.items() if n in geos and only in (None, n)]
    t_all = time.perf_counter()
    for name, size, ribs in cases:
        log(f"corpus: {name} at size {size}, {ribs} ribs + {len(SPARS)} spars per wing")
        res["corpus"].append(compare_case(gdir / geos[name]["file"], manifest, name, size, ribs,
                                          timeout=timeout, gmsh_timeout=gmsh_timeout))
    pname, psize, pribs = PERF_CASE
    if perf and only in (None, pname) and pname in geos:
        log(f"performance target: {pname} at size {psize}, {pribs} ribs + {len(SPARS)} spars per wing")
        res["performance"] = perf_pairs(gdir / geos[pname]["file"], manifest, pname, psize, pribs, pairs,
                                        timeout=timeout, gmsh_timeout=gmsh_timeout)
    rob = list(cases) + ([PERF_CASE] if res["performance"] is not None else [])
    for name, size, ribs in (rob if perturb > 0 else []):
        runs = []
        for seed in range(int(perturb)):
            o = run_in_child(run_shellmesh, str(gdir / geos[name]["file"]), manifest, name, size, ribs, SPARS,
                             perturb=seed, timeout=timeout)
            runs.append(o)
            log(f"  perturbed {name} @ {size}, {ribs} ribs, seed {seed}: {_summary(o)}")
        res["robustness"].append({"name": name, "size": size, "ribs_per_wing": ribs, "scale": PERTURB_SCALE,
                                  "runs": runs})
    mname, mtris, msize = MEMORY_CASE
    if memory and only in (None, mname) and mname in geos:
        wdir = Path(work_dir) if work_dir else Path(tempfile.gettempdir()) / "shellmesh_benchmark"
        log(f"memory target: {mname} refined to >= {mtris:,} triangles")
        t0 = time.perf_counter()
        ref = refine_surface(gdir / geos[mname]["file"], mtris, wdir / f"{mname}_{mtris}.stl")
        ref["refine_s"] = time.perf_counter() - t0
        case = {"name": mname, "size": msize, "refined": ref, "load_before": load_average()}
        case["ours"] = run_in_child(run_shellmesh, ref["path"], manifest, mname, msize, RIBS, SPARS,
                                    timeout=max(timeout, 7200.0))
        case["load_after"] = load_average()
        log(f"  ours {mname} {ref['n_triangles']:,} triangles: {_summary(case['ours'])}")
        o = case["ours"]
        case["within_budget"] = (o.get("status") == "ok" and o["peak_rss_mb"] / 1024 < MEMORY_BUDGET_GB)
        res["memory"] = case
    res["total_s"] = time.perf_counter() - t_all
    res["load_end"] = load_average()
    return res
