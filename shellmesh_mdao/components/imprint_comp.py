"""OpenMDAO component: remesh the skin (cached across runs) and imprint the member curves.

Core functions: the ``remesh`` and ``imprint`` stages of :mod:`shellmesh_mdao.pipeline`. The
remeshed skin does not depend on the layout, only on the input surface, the size and the solver
options (and the local sizes between members closer than the size, when there are such members), so
the component keeps it in a :class:`~shellmesh_mdao.remesh.RemeshCache` (the pipeline
layer's cache, which :func:`~shellmesh_mdao.pipeline.run_pipeline` uses too) and a DOE over rib
stations or spar chord fractions remeshes once (see docs/openmdao.md for the measured saving).
"""
from __future__ import annotations

from .layout_comp import StageComp

__all__ = ["ImprintComp"]


class ImprintComp(StageComp):
    """State after ``project`` -> state after ``remesh`` and ``imprint``.

    Option ``remesh_cache`` (default True): reuse the remeshed skin of an earlier run with
    the same surface, size and solver options (``cache_size`` entries, default 2), kept in this
    component's own :class:`~shellmesh_mdao.remesh.RemeshCache` (``self.remesh_cache``).
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
        from ..remesh.cache import RemeshCache

        super().setup()
        # kept across setups (the surface does not change); a new size makes a new cache
        size = max(1, self.options["cache_size"])
        if getattr(self, "remesh_cache", None) is None or self.remesh_cache.max_entries != size:
            self.remesh_cache = RemeshCache(size)
            self._uncached = {"hits": 0, "misses": 0, "seconds": 0.0}

    @property
    def remesh_stats(self) -> dict:
        """``{"hits", "misses", "seconds"}`` of this component's remeshes (cached or not)."""
        c = self.remesh_cache.stats
        return {k: c[k] + self._uncached[k] for k in c}

    def run_stages(self, state):
        import time

        from ..pipeline import run_stage

        if not self.options["remesh_cache"]:
            t0 = time.perf_counter()
            st = run_stage(state, "remesh")
            self._uncached["misses"] += 1
            self._uncached["seconds"] += time.perf_counter() - t0
            return run_stage(st, "imprint")
        st = run_stage(state, "remesh", remesh_cache=self.remesh_cache)
        if st.report.get("remesh_cache", {}).get("hit"):
            st.report["stages"]["remesh"] = 0.0
        return run_stage(st, "imprint")
