"""OpenMDAO group: the whole mesh pipeline, one component per stage.

:class:`ShellMeshGroup` wires, in order,

    layout (LayoutComp) -> project (ProjectionComp) -> imprint (ImprintComp: remesh + imprint)
    -> members (MemberMeshComp) -> split (SplitComp) -> merge (MergeComp) -> smooth (SmoothComp)
    -> quad (QuadComp)

passing the layout and the :class:`~shellmesh_mdao.pipeline.PipelineState` as discrete
variables. It promotes the continuous layout inputs ``<wing>:rib_eta`` and
``<wing>:spar_chord`` (and a station-given wing's ``<wing>:spar_chord_tip``,
``<wing>:spar_chord_crank``: :func:`~shellmesh_mdao.components.layout_comp.layout_input_names`),
the discrete output ``shell_mesh`` and the continuous outputs
``n_nodes``, ``n_elements`` and ``min_scaled_jacobian``. See docs/openmdao.md.
"""
from __future__ import annotations

import openmdao.api as om
from openmdao.vectors.default_vector import DefaultVector

from .imprint_comp import ImprintComp
from .layout_comp import LayoutComp, family_names, layout_input_names
from .member_mesh_comp import MemberMeshComp
from .merge_comp import MergeComp
from .projection_comp import ProjectionComp
from .quad_comp import QuadComp
from .smooth_comp import SmoothComp
from .split_comp import SplitComp

__all__ = ["ShellMeshGroup", "STAGE_COMPONENTS", "family_names", "OneProcessModelVector", "DOEDriver"]

#: Subsystem name -> component class, in pipeline order (after ``layout`` and ``project``).
STAGE_COMPONENTS = {"imprint": ImprintComp, "members": MemberMeshComp, "split": SplitComp, "merge": MergeComp,
                    "smooth": SmoothComp, "quad": QuadComp}

#: Outputs the group promotes.
PROMOTED_OUTPUTS = ["shell_mesh", "n_nodes", "n_elements", "min_scaled_jacobian"]


class DOEDriver(om.DOEDriver):
    """``om.DOEDriver`` that records whether each case succeeded.

    ``om.DOEDriver`` catches an ``AnalysisError`` (or any exception) of a case, keeps
    ``success = 0`` and the traceback as the case's metadata and goes on with the next case,
    but OpenMDAO 3.41 no longer passes that metadata to the recorders (the method that did,
    ``_get_recorder_metadata``, moved to ``AnalysisDriver``), so every recorded case reads
    ``success = 1``. This subclass passes it again: a recorded case has ``case.success``
    False and ``case.msg`` the traceback (ending with the ShellMeshError's message) when its
    design point could not be meshed or analysed. Use it like ``om.DOEDriver``.
    """

    def _parallel_generator(self, design_vars, model=None):
        """The cases of this process (every ``ncolors``-th, as OpenMDAO deals them), each with its
        index in the whole design (kept for the case name)."""
        ncolors = self._problem_comm.size // self.options["procs_per_model"]
        for i, case in enumerate(self.options["generator"](design_vars, model)):
            if i % ncolors == self._color:
                self._case_index = i
                yield case

    def _run_case(self, case):
        """Run one case under a name unique across the processes of a parallel DOE:
        ``rank<r>:<driver name>|<i>``, ``r`` the rank in the problem's communicator and ``i`` the
        index of the case in the whole design (the generator's order). OpenMDAO names them with the
        rank in the one-process model communicator (always 0) and the process's own counter, so
        the files of two processes both hold ``rank0:...|0``, ``|1``, ... A serial run keeps
        OpenMDAO's names (``rank0:...|i``). ``iter_count`` still counts this process's cases."""
        local = self.iter_count
        index = getattr(self, "_case_index", None)
        if self.options["run_parallel"] and index is not None:
            self.iter_count = index
        self._recording_iter.rank = self._problem_comm.rank
        try:
            super()._run_case(case)
        finally:
            self.iter_count = local
            self._case_index = None

    def _get_recorder_metadata(self, case_name):
        meta = getattr(self, "_metadata", None)
        if not isinstance(meta, dict) or "success" not in meta:
            return super()._get_recorder_metadata(case_name)
        return {**super()._get_recorder_metadata(case_name), "success": meta["success"], "msg": meta["msg"]}


class OneProcessModelVector(DefaultVector):
    """``distributed_vector_class`` for ``prob.setup`` under MPI without petsc4py, when every
    model instance runs on one process (``DOEDriver(run_parallel=True, procs_per_model=1)``).

    OpenMDAO's ``Problem.setup`` refuses a communicator of more than one process unless a
    distributed vector class (normally ``PETScVector``, from petsc4py) is given, although it
    uses that class only for groups whose own communicator spans several processes. With
    ``procs_per_model=1`` there are none, so this class only passes the check; if OpenMDAO
    ever tried to build one, it raises with the fix instead of computing something wrong.
    """

    distributed = True

    def __init__(self, *args, **kwargs):
        raise RuntimeError("a model group spans several MPI processes, which needs distributed vectors: install "
                           "petsc4py, or run the DOE with procs_per_model=1 (one process per case)")


class ShellMeshGroup(om.Group):
    """Surface + layout parameters -> conforming all-quad shell mesh.

    Options: ``surface`` (path or ShellMesh), ``layout`` (path, dict or Layout: wings and
    member counts, initial rib stations and spar chord fractions), ``size`` (target quad
    edge length), ``solver_options`` (dict or PipelineOptions), ``remesh_cache`` (reuse the
    remeshed skin across runs, default True), ``memoize`` (stages skip work when their input
    object is unchanged, default True).

    Promoted: inputs ``<wing>:rib_eta``, ``<wing>:spar_chord`` (station-given wings also
    ``<wing>:spar_chord_tip``, ``<wing>:spar_chord_crank`` when their layout gives tip / crank
    fractions; :attr:`layout_inputs` after setup); outputs ``shell_mesh`` (discrete),
    ``n_nodes``, ``n_elements``, ``min_scaled_jacobian``. :attr:`family_names` (after setup) is
    the ``thickness`` order of analysis components fed by ``shell_mesh``, fixed by the layout
    (:func:`~shellmesh_mdao.components.layout_comp.family_names`).
    """

    def initialize(self):
        o = self.options
        o.declare("surface", desc="input skin: path of a surface file or a ShellMesh")
        o.declare("layout", desc="base layout (path, dict or Layout)")
        o.declare("size", types=(int, float), desc="target quad edge length (surface units)")
        o.declare("solver_options", default=None, desc="PipelineOptions or a dict of them")
        o.declare("remesh_cache", default=True, types=bool, desc="reuse the remeshed skin across runs")
        o.declare("memoize", default=True, types=bool, desc="skip a stage whose input object is unchanged")
        self.recording_options["options_excludes"] = ["surface"]     # recorders: not the whole input surface

    def setup(self):
        o = self.options
        self.family_names = family_names(o["layout"])
        self.layout_inputs = list(layout_input_names(o["layout"]))
        self.add_subsystem("layout", LayoutComp(layout=o["layout"]), promotes_inputs=self.layout_inputs)
        self.add_subsystem("project", ProjectionComp(surface=o["surface"], size=o["size"],
                                                     solver_options=o["solver_options"], memoize=o["memoize"]))
        self.connect("layout.layout", "project.layout")
        prev = "project"
        for name, cls in STAGE_COMPONENTS.items():
            kw = {"memoize": o["memoize"]}
            if cls is ImprintComp:
                kw["remesh_cache"] = o["remesh_cache"]
            promotes = PROMOTED_OUTPUTS if cls is QuadComp else None
            self.add_subsystem(name, cls(**kw), promotes_outputs=promotes)
            self.connect(f"{prev}.state", f"{name}.state_in")
            prev = name
