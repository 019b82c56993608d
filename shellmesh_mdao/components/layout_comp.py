"""OpenMDAO component: the member layout from continuous rib stations and spar chord fractions.

:class:`LayoutComp` is the first stage of :class:`~shellmesh_mdao.components.group.ShellMeshGroup`.
This module also holds what every stage component shares (:class:`StageComp`, the base of
``ProjectionComp`` ... ``QuadComp``; :func:`case_errors`, which turns a user-caused failure of
one design point into an :class:`openmdao.api.AnalysisError`; :func:`family_names`, the
component families a layout gives, i.e. the order of the ``thickness`` vector of the
analysis components, and :func:`family_index`, which mesh family takes which thickness).

Failed design points. A design point that cannot be meshed (rib stations out of order or
coinciding at the element size, a member that cannot be imprinted at this size, ...) raises a
:class:`~shellmesh_mdao.errors.ShellMeshError` in the core function; the stage component
re-raises it as ``om.AnalysisError`` with the same message (prefixed by the component's
path). ``DOEDriver`` records such a case with ``success = 0`` and the message in ``msg``
and goes on with the next case; the components downstream of the failed one do not run, so
the recorded outputs of a failed case are stale: read ``case.success`` first. Errors that do
not depend on the design point (missing surface file, bad size for the surface, unknown
solver option, a layout file that does not parse) are raised as they are, when the problem
is set up or at the first run, and stop the study.
"""
from __future__ import annotations

import re
from contextlib import contextmanager

import numpy as np
import openmdao.api as om

from ..errors import LayoutError, ShellMeshError
from ..families import SIDES, SKIN, bay_name, name_and_parents, parse_component, rib_name, segment_name, \
    spar_name, web_name
from ..layout import Layout, load_layout

__all__ = ["LayoutComp", "StageComp", "case_errors", "family_names", "family_index", "layout_input_names"]

_VAR_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_\-]*$")


@contextmanager
def case_errors():
    """Re-raise a :class:`ShellMeshError` (a design point the core functions reject) as
    ``om.AnalysisError`` (message ``"<ErrorClass>: <message>"``; OpenMDAO prefixes the
    component's path) so drivers record the case as failed and continue."""
    try:
        yield
    except ShellMeshError as e:
        raise om.AnalysisError(f"{type(e).__name__}: {e}") from e


def family_names(layout) -> list:
    """The thickness families of ``layout`` (path, dict or :class:`~shellmesh_mdao.layout.Layout`):
    the order of the ``thickness`` vector of ``MassComp`` / ``CalculixShellAnalysis`` fed by a
    ShellMeshGroup. It is fixed by the layout (the wings, the numbers of ribs and spars, the
    explicit members), so it does not change when rib stations or spar chord fractions move, and
    it follows the order in which the pipeline creates the components:

    1. ``skin``;
    2. every member, :meth:`Layout.members` order: per corner-given wing its spars then its ribs;
       per station-given wing ``<wing>/le_web``, its spars, ``<wing>/te_web``, its ribs (the edge
       webs when the wing has fewer than two spars: an unresolved wing lists them, a wing resolved
       against the skin only when it has them); then the explicit members;
    3. per wing (corner-given first) and bay ``<wing>/upper_skin/bay_<k>``,
       ``<wing>/lower_skin/bay_<k>``;
    4. the X-junction pieces of corner-given wings, which the layout fixes: every spar the ribs
       cross (the middle spars; the only spar of a one-spar wing) in ``seg_<k>`` pieces, ``k`` the
       bay, and every inner rib in one piece more than it crosses spars, front to rear.

    For corner-given wings this is exactly ``mesh.component_names`` of a pipeline mesh. The
    pieces of station-given wings (``<spar>/part_<p>`` where a spar is kinked, their
    ``/seg_<j>`` where ribs cross it) and of members crossing explicit members depend on where
    the ribs are and on the element size, so they are not listed: the analysis components give
    each mesh family the thickness of its nearest listed name (:func:`family_index`), a spar
    piece that of its spar."""
    lay = load_layout(layout)
    names, pieces = [SKIN], []
    for w in lay.wings:
        names += [spar_name(w.name, j) for j in range(len(w.spar_chord))]
        names += [rib_name(w.name, k) for k in range(len(w.rib_eta))]
        pieces += _corner_pieces(w.name, len(w.spar_chord), len(w.rib_eta))
    for w in lay.station_wings:
        webs = (any(parse_component(m.name).kind == "web" for m in w.specs) if w.resolved
                else len(w.spar_chord) < 2)
        names += [web_name(w.name, "le")] if webs else []
        names += [spar_name(w.name, j) for j in range(len(w.spar_chord))]
        names += [web_name(w.name, "te")] if webs else []
        names += [rib_name(w.name, k) for k in range(len(w.rib_eta))]
    names += [m.name for m in lay.explicit]
    for w in lay.wings + lay.station_wings:
        for k in range(len(w.rib_eta) - 1):
            names += [bay_name(w.name, side, k) for side in SIDES]
    return names + pieces


def _corner_pieces(wing: str, n_spars: int, n_ribs: int) -> list:
    """X-junction pieces of a corner-given wing: a rib ends on the first and last spar (on the
    leading and trailing edge with fewer than two spars) and crosses the others, a spar ends on
    the root and tip ribs and is crossed by the inner ribs."""
    crossed = list(range(1, n_spars - 1)) if n_spars >= 2 else list(range(n_spars))
    if not crossed or n_ribs < 3:
        return []
    out = [segment_name(spar_name(wing, j), k) for j in crossed for k in range(n_ribs - 1)]
    return out + [segment_name(rib_name(wing, k), i) for k in range(1, n_ribs - 1) for i in range(len(crossed) + 1)]


def family_index(families, names) -> np.ndarray:
    """Position in ``families`` of each component name of ``names`` (a mesh's
    ``component_names``): the name's own, else that of its nearest parent in the list
    (:func:`~shellmesh_mdao.families.name_and_parents`: ``w/spar_0/part_1/seg_2`` ->
    ``w/spar_0/part_1`` -> ``w/spar_0``); -1 when neither it nor a parent is listed."""
    pos = {n: i for i, n in enumerate(families)}
    return np.array([next((pos[p] for p in name_and_parents(n) if p in pos), -1) for n in names], dtype=np.int64)


def layout_input_names(layout) -> dict:
    """``{input name: (wing, kind, initial values)}`` of the continuous layout inputs, per wing
    (corner-given, then station-given): ``<wing>:rib_eta`` for each wing with ribs and
    ``<wing>:spar_chord`` for each wing with spars (kind ``'rib_eta'``, ``'spar_chord'``); a
    station-given wing whose layout gives tip (and crank) chord fractions also gets
    ``<wing>:spar_chord_tip`` (``'spar_chord_tip'``) and ``<wing>:spar_chord_crank``
    (``'spar_chord_cranks'``, shape ``(n_cranks, n_spars)``). Wings without ribs/spars get no
    input: OpenMDAO has no zero-size variables."""
    lay = load_layout(layout)
    out = {}
    for w in lay.wings + lay.station_wings:
        if not _VAR_NAME.match(w.name):
            raise LayoutError(f"wing name '{w.name}' cannot be an OpenMDAO variable prefix ('{w.name}:rib_eta'): "
                              "use letters, digits, '_' and '-' only (start with a letter), e.g. 'right_wing'")
        if len(w.rib_eta):
            out[f"{w.name}:rib_eta"] = (w.name, "rib_eta", np.array(w.rib_eta, dtype=np.float64))
        if len(w.spar_chord):
            out[f"{w.name}:spar_chord"] = (w.name, "spar_chord", np.array(w.spar_chord, dtype=np.float64))
        if getattr(w, "spar_chord_tip", None) is not None and len(w.spar_chord):
            out[f"{w.name}:spar_chord_tip"] = (w.name, "spar_chord_tip", np.array(w.spar_chord_tip, dtype=np.float64))
        if getattr(w, "spar_chord_cranks", None) is not None and len(w.spar_chord) and len(w.spar_chord_cranks):
            out[f"{w.name}:spar_chord_crank"] = (w.name, "spar_chord_cranks",
                                                 np.array(w.spar_chord_cranks, dtype=np.float64))
    return out


_INPUT_DESC = {"rib_eta": "rib stations eta in [0, 1], root to tip",
               "spar_chord": "spar chord fractions in (0, 1), leading edge first (a station-given wing: at its root)",
               "spar_chord_tip": "spar chord fractions at the tip station, leading edge first",
               "spar_chord_cranks": "spar chord fractions at each crank station (one row per crank)"}


class LayoutComp(om.ExplicitComponent):
    """Layout of the current design point.

    Option ``layout`` (path, dict or Layout): the base layout; it fixes the wings and the
    numbers of ribs and spars. Continuous inputs ``<wing>:rib_eta`` (shape = number of ribs,
    stations in [0, 1], strictly increasing) and ``<wing>:spar_chord`` (shape = number of
    spars, in (0, 1), strictly increasing), for corner- and station-given wings, and a
    station-given wing's ``<wing>:spar_chord_tip`` / ``<wing>:spar_chord_crank`` when its layout
    gives tip / crank fractions (:func:`layout_input_names`), initialised from the base layout.
    Discrete output ``layout``: ``base.with_parameters(rib_eta=..., spar_chord=...,
    spar_chord_tip=..., spar_chord_cranks=...)`` (station-given wings unresolved: the
    projection component's layout stage measures them against the skin). The same
    input values give the same Layout object (so the stages downstream can skip work).
    An invalid design point is an ``om.AnalysisError`` (see the module docstring).

    Partials: none. The output is discrete; the mesh is not a differentiable function of
    the layout parameters (the element connectivity changes with them). Use DOE or
    gradient-free drivers for the layout parameters.
    """

    def initialize(self):
        self.options.declare("layout", desc="base layout (path, dict or Layout): wings and member counts")

    def setup(self):
        self._base: Layout = load_layout(self.options["layout"])
        self._layout_inputs = layout_input_names(self._base)
        for name, (wing, kind, val) in self._layout_inputs.items():
            self.add_input(name, val=val, shape=val.shape, desc=f"{wing}: {_INPUT_DESC[kind]}")
        self.add_discrete_output("layout", val=None, desc="the Layout of this design point")
        self._memo = (None, None)

    def compute(self, inputs, outputs, discrete_inputs=None, discrete_outputs=None):
        vals = {name: np.array(inputs[name], dtype=np.float64) for name in self._layout_inputs}
        key = b"".join(name.encode() + b"=" + v.tobytes() for name, v in vals.items())
        if self._memo[0] == key:
            discrete_outputs["layout"] = self._memo[1]
            return
        given = {kind: {} for kind in _INPUT_DESC}
        for n, (w, kind, _) in self._layout_inputs.items():
            given[kind][w] = vals[n]
        self._memo = (None, None)
        with case_errors():
            lay = self._base.with_parameters(**given)
        self._memo = (key, lay)
        discrete_outputs["layout"] = lay


class StageComp(om.ExplicitComponent):
    """Base of the mesh stage components: runs ``self.stages`` (names of
    :data:`shellmesh_mdao.pipeline.STAGES`) with :func:`~shellmesh_mdao.pipeline.run_stage` on the
    discrete input ``state_in`` and gives the discrete output ``state``
    (:class:`~shellmesh_mdao.pipeline.PipelineState`, frozen: never modified in place).

    The input is named ``state_in`` (OpenMDAO forbids an input and an output of the same
    name). When the input state is the very object of the previous run the previous output is
    given again without running anything (option ``memoize``, default True): a driver that
    changes only the thicknesses downstream of a ShellMeshGroup does not re-mesh.
    No partials: inputs and outputs are discrete."""

    stages: tuple = ()

    def initialize(self):
        self.options.declare("memoize", default=True, types=bool,
                             desc="give the previous output again when the input state is the same object")

    def setup(self):
        self.add_discrete_input("state_in", val=None, desc="pipeline state after the previous stage")
        self.add_discrete_output("state", val=None, desc=f"pipeline state after stage(s) {', '.join(self.stages)}")
        self._memo = (None, None)
        self.n_runs = 0             # stages actually run (not memoized)

    def compute(self, inputs, outputs, discrete_inputs=None, discrete_outputs=None):
        st = discrete_inputs["state_in"]
        if st is None:
            raise om.AnalysisError(f"{self.pathname}: no input state: connect the previous stage's 'state' output "
                                   "(ShellMeshGroup does) and run the model")
        if self.options["memoize"] and self._memo[0] is st:
            out = self._memo[1]
        else:
            self._memo = (None, None)
            with case_errors():
                out = self.run_stages(st)
            self._memo = (st, out)
            self.n_runs += 1
        discrete_outputs["state"] = out
        self.set_outputs(out, outputs, discrete_outputs)

    def run_stages(self, state):
        """Run this component's stages on ``state``; returns the new state."""
        from ..pipeline import run_stage

        for name in self.stages:
            state = run_stage(state, name)
        return state

    def set_outputs(self, state, outputs, discrete_outputs) -> None:
        """Derived outputs of a stage (none by default)."""
