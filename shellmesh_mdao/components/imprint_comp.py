"""OpenMDAO component: remesh the skin (cached across runs) and imprint the member curves.

Core functions: the ``remesh`` and ``imprint`` stages of :mod:`shellmesh_mdao.pipeline`.
The remeshed skin does not depend on the layout, only on the input surface, the size and
the solver options, so the component keeps it (key: a SHA-1 of the surface's points and
faces, the size and the options) and a DOE over rib stations or spar chord fractions
remeshes once (see docs/openmdao.md for the measured saving).
"""
from __future__ import annotations

import hashlib
import time

import numpy as np

from .layout_comp import StageComp

__all__ = ["ImprintComp", "surface_key"]


def surface_key(state) -> tuple:
    """Cache key of the remeshed skin of ``state``: (SHA-1 of the input surface's points and
    faces, size, solver options). Equal keys give bit-identical remeshed skins."""
    s = state.surface
    h = hashlib.sha1()
    for a in (s.points, s.faces):
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest(), float(state.size), state.options


def _freeze(mesh) -> None:
    """Make the arrays of a cached mesh read-only: a later stage that tried to modify them in
    place would raise instead of silently corrupting the cache."""
    for name in ("points", "faces", "component", "fixed_vertices", "feature_edges", "feature_edge_ids"):
        a = getattr(mesh, name, None)
        if isinstance(a, np.ndarray):
            a.flags.writeable = False


class ImprintComp(StageComp):
    """State after ``project`` -> state after ``remesh`` and ``imprint``.

    Option ``remesh_cache`` (default True): reuse the remeshed skin of an earlier run with
    the same surface, size and solver options (``cache_size`` entries, default 2).
    ``self.remesh_stats`` counts ``hits`` and ``misses`` and the ``seconds`` spent remeshing;
    the report of a state built from the cache has ``report["remesh_cache"] = {"hit": True,
    "seconds": <time of the original remesh>}``. Discrete input ``state_in``, output ``state``; no partials.
    """

    stages = ("remesh", "imprint")

    def initialize(self):
        super().initialize()
        self.options.declare("remesh_cache", default=True, types=bool, desc="reuse the remeshed skin across runs")
        self.options.declare("cache_size", default=2, types=int, desc="number of remeshed skins kept")

    def setup(self):
        super().setup()
        if not hasattr(self, "_remesh_cache"):      # kept across setups: the surface does not change
            self._remesh_cache = {}
            self.remesh_stats = {"hits": 0, "misses": 0, "seconds": 0.0}

    def run_stages(self, state):
        from ..pipeline import run_stage

        if not self.options["remesh_cache"]:
            t0 = time.perf_counter()
            st = run_stage(state, "remesh")
            self.remesh_stats["misses"] += 1
            self.remesh_stats["seconds"] += time.perf_counter() - t0
            return run_stage(st, "imprint")
        key = surface_key(state)
        hit = self._remesh_cache.get(key)
        if hit is None:
            t0 = time.perf_counter()
            st = run_stage(state, "remesh")
            dt = time.perf_counter() - t0
            self.remesh_stats["misses"] += 1
            self.remesh_stats["seconds"] += dt
            _freeze(st.mesh)
            self._remesh_cache[key] = (st.mesh, st.report["stages"]["remesh"])
            while len(self._remesh_cache) > max(1, self.options["cache_size"]):
                self._remesh_cache.pop(next(iter(self._remesh_cache)))
        else:
            mesh, seconds = hit
            self.remesh_stats["hits"] += 1
            st = state.but(mesh=mesh, stage="remesh")
            st.report["stages"]["remesh"] = 0.0
            st.report["remesh_cache"] = {"hit": True, "seconds": seconds}
        return run_stage(st, "imprint")
