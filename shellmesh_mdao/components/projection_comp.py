"""OpenMDAO component: load the skin, apply the layout and project the members onto the skin.

Core functions: :func:`shellmesh_mdao.pipeline.stage_load` (once per component instance and
``size``/solver options: the surface does not change during a study),
:func:`~shellmesh_mdao.pipeline.stage_layout` and the ``project`` stage.
"""
from __future__ import annotations

import copy
import dataclasses

import openmdao.api as om

from .layout_comp import case_errors

__all__ = ["ProjectionComp"]


class ProjectionComp(om.ExplicitComponent):
    """Skin + layout -> pipeline state after the ``project`` stage.

    Options: ``surface`` (path or :class:`~shellmesh_mdao.mesh.ShellMesh`), ``size`` (target
    quad edge length), ``solver_options`` (dict or
    :class:`~shellmesh_mdao.pipeline.PipelineOptions`). Discrete input ``layout`` (from
    :class:`~shellmesh_mdao.components.layout_comp.LayoutComp`), discrete output ``state``.

    The loaded skin and its BVH (``stage_load``) are kept in the component: the first run
    reads the surface, later runs reuse it. Errors of the load (missing file, bad size,
    unknown option) are raised as they are (they stop the study); errors of the layout and
    projection stages are ``om.AnalysisError`` (a failed case). No partials (discrete).
    """

    def initialize(self):
        self.options.declare("surface", desc="input skin: path of a surface file or a ShellMesh")
        self.options.declare("size", types=(int, float), desc="target quad edge length (surface units)")
        self.options.declare("solver_options", default=None, desc="PipelineOptions or a dict of them")
        self.options.declare("memoize", default=True, types=bool,
                             desc="give the previous output again when the input layout is the same object")
        # recorders pickle the options of every system: not the whole input surface
        self.recording_options["options_excludes"] = ["surface"]

    def setup(self):
        self.add_discrete_input("layout", val=None, desc="Layout of this design point")
        self.add_discrete_output("state", val=None, desc="pipeline state after the project stage")
        self._loaded = None
        self._memo = (None, None)
        self.n_runs = 0

    def loaded_state(self):
        """The pipeline state after ``stage_load`` (computed once, then reused)."""
        from ..pipeline import PipelineOptions, stage_load

        o = self.options
        key = (float(o["size"]), PipelineOptions.from_dict(o["solver_options"]))
        if self._loaded is None or self._loaded[0] != key:
            self._loaded = (key, stage_load(o["surface"], o["size"], key[1]))
        return self._loaded[1]

    def compute(self, inputs, outputs, discrete_inputs=None, discrete_outputs=None):
        from ..pipeline import run_stage, stage_layout

        layout = discrete_inputs["layout"]
        if layout is None:
            raise om.AnalysisError(f"{self.pathname}: no input layout: connect LayoutComp's 'layout' output")
        if self.options["memoize"] and self._memo[0] is layout:
            discrete_outputs["state"] = self._memo[1]
            return
        base = self.loaded_state()
        # a private copy of the report: stage_layout writes the layout into report["inputs"]
        base = dataclasses.replace(base, report=copy.deepcopy(base.report))
        self._memo = (None, None)
        with case_errors():
            st = stage_layout(base, layout)
            st = run_stage(st, "project")
        self._memo = (layout, st)
        self.n_runs += 1
        discrete_outputs["state"] = st
