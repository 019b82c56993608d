"""Benchmark and stress harness: the pipeline measured on the corpus (../shared/geometry).

Not part of the meshing pipeline; the scripts ``run_scripts/benchmark.py`` and
``run_scripts/stress_layouts.py`` and the tests run it.

* :mod:`.figures` -- quality figures of a mesh (:func:`mesh_figures`) and the issue's acceptance
  targets (:data:`TARGETS`, :func:`target_checks`);
* :mod:`.child` -- :func:`run_in_child`: a call in a fresh spawned process with a time limit (a
  hang or a crash is a result; the peak memory is the call's own);
* :mod:`.corpus` -- the benchmark: every corpus geometry meshed by the pipeline and by Gmsh's
  all-quad remesh side by side, the performance, memory and robustness cases
  (:func:`run_benchmark`); Gmsh is optional (``pip install -e ".[test]"``);
* :mod:`.page` -- the page docs/benchmarks.md of its figures (:func:`render_page`,
  :func:`write_outputs`);
* :mod:`.real_wings` -- the real-wings matrix (issue 40): every corpus geometry meshed from the
  layout ``shellmesh wings`` writes (wings given by stations), three layouts, three rib
  orientations, two sizes, classified ok / guarantee / refused / crash, and its page
  docs/real_wings.md (``run_scripts/real_wings.py``; imported as
  ``shellmesh_mdao.benchmarks.real_wings``);
* :mod:`.stress` -- the stress sweep: random layouts drawn per seed (:func:`draw_case`), run end
  to end and classified ok / invalid layout / FAIL (:func:`run_case`), with independent checks of
  the layout (:func:`layout_tightness`) and the page docs/stress_layouts.md (:func:`write_page`).

The functions that run in child processes are module-level functions of these modules, so the
spawned children import them by name. This package imports the light modules only (numpy and
the mesh type: a Gmsh child's peak memory is Gmsh's); :mod:`.stress`, which needs the whole
pipeline, is imported as ``shellmesh_mdao.benchmarks.stress``.
"""
from .child import run_in_child
from .corpus import (CORPUS_SIZES, compare_case, gmsh_quad_remesh, import_gmsh, perf_pairs, perturbed_surface,
                     refine_surface, run_benchmark, run_gmsh, run_shellmesh)
from .figures import TARGETS, member_face_mask, mesh_figures, target_checks
from .page import KEEP_MARKER, kept_part, render_page, write_outputs

__all__ = ["CORPUS_SIZES", "KEEP_MARKER", "TARGETS", "compare_case", "gmsh_quad_remesh", "import_gmsh", "kept_part",
           "member_face_mask", "mesh_figures", "perf_pairs", "perturbed_surface", "refine_surface", "render_page",
           "run_benchmark", "run_gmsh", "run_in_child", "run_shellmesh", "target_checks", "write_outputs"]
