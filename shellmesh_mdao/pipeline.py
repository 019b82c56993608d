"""The mesh pipeline: the stages in order, one function each, and one call that runs them.

load -> layout -> project -> remesh -> imprint -> members -> split -> merge -> smooth -> quad -> export

Each stage is a function ``stage_<name>(state)`` that takes a :class:`PipelineState` and returns
a new one (the input state is not modified), so the OpenMDAO components
(:mod:`shellmesh_mdao.components`) can pass the state between them as a discrete variable and
re-run only the stages downstream of a changed input. :func:`run_pipeline` is what the CLI
(``shellmesh mesh``), ``shellmesh demo`` and the studies call: it runs the stages up to
``until`` and returns a :class:`PipelineResult` with the mesh of the last stage run, the chains
and a JSON report (inputs, seconds per stage, components, counts, per-member figures, solver
statuses).
"""
from __future__ import annotations

import dataclasses
import logging
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from .errors import GuaranteeError, SizeError, ShellMeshError
from .families import SKIN
from .mesh import ShellMesh, norm_rows
from .options import PipelineOptions

log = logging.getLogger("shellmesh_mdao")

__all__ = ["STAGES", "REMESH_FACTOR", "PipelineOptions", "PipelineState", "PipelineResult", "one_blas_thread",
           "check_size", "gate", "stage_load", "stage_layout", "stage_project", "stage_remesh", "stage_imprint",
           "stage_members", "stage_split", "stage_merge", "stage_smooth", "stage_quad", "run_stage", "run_pipeline"]

#: Stages in order; ``--until`` takes one of these.
STAGES = ("load", "layout", "project", "remesh", "imprint", "members", "split", "merge", "smooth", "quad")

#: The skin is remeshed at this multiple of the final quad size: merging pairs triangles into
#: quads and the final subdivision halves every edge.
REMESH_FACTOR = 2.0


@dataclass(frozen=True)
class PipelineState:
    """What travels between stages. ``stage`` is the last stage run; fields a stage has not
    produced yet are None. ``mesh`` is the current mesh (the skin until ``members``, then skin
    and members together); ``surface`` and ``locator`` are the ORIGINAL input skin and its BVH;
    ``supports`` say where each node of ``mesh`` may move (from ``split`` on); ``size_field``
    (from ``project`` on) the local element sizes asked for below ``size``
    (:class:`~shellmesh_mdao.core.sizefield.SizeField`, in quad sizes; empty: ``size``
    everywhere)."""

    size: float
    options: PipelineOptions
    report: dict
    surface: ShellMesh | None = None
    locator: object = None
    layout: object = None
    projected: dict | None = None
    specs: list | None = None
    mesh: ShellMesh | None = None
    chains: list = field(default_factory=list)
    infos: list | None = None
    supports: object = None
    size_field: object = None
    stage: str = ""

    def but(self, **kw) -> "PipelineState":
        """A copy with some fields replaced (the report is copied one level deep)."""
        rep = dict(self.report)
        rep["stages"] = dict(self.report.get("stages", {}))
        return dataclasses.replace(self, report=rep, **kw)


@dataclass
class PipelineResult:
    mesh: ShellMesh
    report: dict
    surface: ShellMesh | None = None
    layout: object = None
    chains: list = field(default_factory=list)
    stage: str = ""
    state: PipelineState | None = None


#: the libraries one_blas_thread last listed, and how many modules were imported then
_BLAS_LIBS: dict = {"controller": None, "modules": -1}


@contextmanager
def one_blas_thread():
    """BLAS (numpy's and scipy's OpenBLAS, any other threadpoolctl finds) on one thread inside
    the block, the caller's setting restored after. The stages' dense products are small (3 x 3
    frames, a few columns), where OpenBLAS's worker threads mostly spin-wait between calls: on
    the target case they took 0.6-0.8 s of CPU a run (system time) and the second core from the
    closest-point queries and the trust-radius tree, and from a second pipeline process beside it
    (docs/benchmarks.md, thirteenth pass). The results do not depend on it: the determinism test
    runs one process with one BLAS thread and another with the default.

    The libraries are listed once (about 2.5 ms in a pipeline process, for each of a run's ten
    stages) and listed again only when modules were imported since: a native library, BLAS
    among them, comes with an extension module's import."""
    from threadpoolctl import ThreadpoolController

    if _BLAS_LIBS["modules"] != len(sys.modules):
        _BLAS_LIBS["controller"] = ThreadpoolController()
        _BLAS_LIBS["modules"] = len(sys.modules)
    with _BLAS_LIBS["controller"].limit(limits=1, user_api="blas"):
        yield


class _Stages:
    """Times stages (each with BLAS on one thread: :func:`one_blas_thread`) and shows a spinner
    on a terminal for stages longer than a second."""

    def __init__(self, progress: bool):
        self.progress = progress and sys.stderr.isatty()

    @contextmanager
    def __call__(self, name: str, seconds: dict):
        t0 = time.perf_counter()
        status = None
        if self.progress:
            from rich.console import Console

            status = Console(stderr=True).status(f"[bold]{name}[/bold] ...")
            status.start()
        try:
            with one_blas_thread():
                yield
        finally:
            if status is not None:
                status.stop()
            dt = time.perf_counter() - t0
            seconds[name] = round(dt, 4)
            log.info("%-8s %8.2f s", name, dt)


def check_size(size, diagonal: float) -> float:
    """The target quad edge length must be positive, finite and between 1e-4 and 0.25 of the
    surface's bounding-box diagonal."""
    try:
        h = float(size)
    except (TypeError, ValueError):
        raise SizeError(f"--size must be a number (target quad edge length), got {size!r}") from None
    if not np.isfinite(h) or h <= 0:
        raise SizeError(f"--size must be a positive length, got {size!r}")
    if h > 0.25 * diagonal:
        raise SizeError(f"--size {h:g} is too large for a surface whose bounding-box diagonal is {diagonal:.4g}; "
                        f"use at most {0.25 * diagonal:.4g} (a quarter of the diagonal)")
    if h < 1e-4 * diagonal:
        raise SizeError(f"--size {h:g} is too small for a surface whose bounding-box diagonal is {diagonal:.4g} "
                        f"(more than 1e4 elements along it); use at least {1e-4 * diagonal:.4g} or check the units")
    return h


def _need(state: PipelineState, stage: str) -> None:
    i = STAGES.index(stage)
    cur = STAGES.index(state.stage) if state.stage in STAGES else -1
    if cur < i - 1:
        raise ShellMeshError(f"stage '{stage}' needs the output of stage '{STAGES[i - 1]}' (the state is at "
                             f"'{state.stage or 'nothing'}'); run the stages in order: {' -> '.join(STAGES)}")


# ============================================================================ stages
def stage_load(surface, size, options=None) -> PipelineState:
    """Read the input skin (path or :class:`ShellMesh`), check ``size`` against it, split any
    quads into triangles and build its BVH locator."""
    from .load import repair_surface
    from .core.locator import SurfaceLocator

    opts = PipelineOptions.from_dict(options)
    report: dict = {"inputs": {"surface": str(surface) if not isinstance(surface, ShellMesh) else "<mesh>",
                               "size": size, "options": opts.to_dict()}, "stages": {}}
    # handles or refuses dirty CAD input: duplicates, orientation, intersecting bodies, half
    # models (docs/troubleshooting.md)
    skin_in, srep = repair_surface(surface, size=size)     # size: the tessellation of STEP/IGES
    report["surface"] = srep.to_dict()
    h = check_size(size, skin_in.diagonal)
    if skin_in.n_quads:
        tris, _ = skin_in.triangles()
        skin_in = ShellMesh(skin_in.points, tris, np.zeros(len(tris), np.int32), [SKIN])
    locator = SurfaceLocator(skin_in.points, skin_in.faces[:, :3])
    return PipelineState(h, opts, report, surface=skin_in, locator=locator, mesh=skin_in, stage="load")


def stage_layout(state: PipelineState, layout) -> PipelineState:
    """Read and validate the member layout (path, dict or :class:`~shellmesh_mdao.layout.Layout`)."""
    from .layout import load_layout, resolve_layout

    lay = resolve_layout(load_layout(layout), state.surface.points, state.surface.faces[:, :3], state.size)
    lay.validate(state.size)
    st = state.but(layout=lay, stage="layout")
    st.report["inputs"]["layout"] = lay.to_dict()
    if lay.station_wings:                  # wings measured from the skin: their planform and notes
        st.report["wings"] = {w.name: dict(w.planform.summary(), notes=list(w.notes)) for w in lay.station_wings}
    return st


def stage_project(state: PipelineState) -> PipelineState:
    """Cast every member's seed points onto the input skin and derive the curves to imprint;
    refuse spars too thin even for the finest local size (:func:`~shellmesh_mdao.project.check_member_heights`);
    the local element size between members closer than ``size``
    (:func:`~shellmesh_mdao.project.close_member_field`) and along spars too thin for it
    (:func:`~shellmesh_mdao.project.thin_member_field`), the report's ``size_field``."""
    from .imprint import chain_specs
    from .project import check_member_heights, close_member_field, project_layout, thin_member_field

    _need(state, "project")
    projected = project_layout(state.locator, state.layout)
    check_member_heights(state.locator, state.layout, state.size)
    field = close_member_field(state.locator, state.layout, state.size).union(
        thin_member_field(state.locator, state.layout, state.size))
    st = state.but(projected=projected, specs=chain_specs(state.layout, projected), size_field=field,
                   stage="project")
    st.report["size_field"] = field.summary(state.size)
    return st


def _working_field(state: PipelineState):
    """The state's size field in the working units of the remesh, imprint and members stages
    (``REMESH_FACTOR`` times the quad size); None when it asks for nothing."""
    f = state.size_field
    return None if f is None or f.empty else f.scaled(REMESH_FACTOR)


def stage_remesh(state: PipelineState, cache=None) -> PipelineState:
    """Isotropic, curvature-adapted remesh of the skin at ``REMESH_FACTOR * size``, finer where the
    state's size field asks for it. ``cache``: a
    :class:`~shellmesh_mdao.remesh.RemeshCache` to look the skin up in first and store it in (the
    report of a state built from it has ``remesh_cache = {"hit": True, "seconds": <the original
    remesh's time>}``); None remeshes."""
    from .remesh import remesh_skin

    _need(state, "remesh")
    o = state.options.remesh
    if not o.remesh:
        return state.but(mesh=state.surface, stage="remesh")
    field = _working_field(state)
    key = cache.key(state.surface, state.size, state.options, field) if cache is not None else None
    hit = cache.get(key) if cache is not None else None
    if hit is not None:
        st = state.but(mesh=hit.mesh, stage="remesh")
        st.report["remesh_cache"] = {"hit": True, "seconds": hit.seconds}
        _report_sizing(st, hit.sizing)
        return st
    t0 = time.perf_counter()
    rep = {}
    skin = remesh_skin(state.surface, REMESH_FACTOR * state.size, o, locator=state.locator, size_field=field,
                       report=rep)
    if cache is not None:
        cache.put(key, skin, time.perf_counter() - t0, rep.get("sizing"))
    st = state.but(mesh=skin, stage="remesh")
    _report_sizing(st, rep.get("sizing"))
    return st


def _report_sizing(state: PipelineState, sizing) -> None:
    """The report's ``size_field.skin``: the remesh's sizing summary (in units of its target)."""
    if sizing is not None:
        sf = dict(state.report.get("size_field") or {})
        sf["skin"] = {**sizing, "target": REMESH_FACTOR * state.size}
        state.report["size_field"] = sf


def stage_imprint(state: PipelineState) -> PipelineState:
    """Imprint every member's curves into the skin as chains of edges; name the skin bays."""
    from .imprint import chain_report, imprint_mesh, skin_families

    _need(state, "imprint")
    mesh, chains = imprint_mesh(state.mesh, state.surface, state.specs, REMESH_FACTOR * state.size,
                                state.options.imprint, locator=state.locator, size_field=_working_field(state))
    mesh = skin_families(mesh, state.layout)
    st = state.but(mesh=mesh, chains=chains, stage="imprint")
    st.report["members"] = chain_report(mesh, chains)
    return st


def stage_members(state: PipelineState) -> PipelineState:
    """Mesh every member (planar Delaunay or Coons patch) on its chains; split members at
    their junctions; one conforming triangle mesh of skin and members. Sets the state's
    ``infos`` (:func:`~shellmesh_mdao.members.member_infos` of the layout), which the later
    stages' node supports use."""
    from .members import build_members, member_infos, member_statistics

    _need(state, "members")
    infos = member_infos(state.layout)
    # members are flat or gently curved: meshed at the skin's flat-region edge length, graded
    # to the chain spacing at their boundary
    mesh = build_members(state.mesh, state.chains, infos, REMESH_FACTOR * state.size,
                         size_field=_working_field(state))
    st = state.but(mesh=mesh, infos=infos, stage="members")
    members = {k: dict(v) for k, v in st.report.get("members", {}).items()}
    for name, s in member_statistics(mesh, infos).items():
        members.setdefault(name, {"chains": []}).update(s)
    st.report["members"] = members
    return st


def stage_split(state: PipelineState) -> PipelineState:
    """Splitting LP (paper eq. 1-3) on the whole mesh; chains, junctions and feature lines are
    never split. Derives the node supports (input skin, member planes, feature curves)
    (:func:`~shellmesh_mdao.split.split_mesh`)."""
    from .split import split_mesh

    _need(state, "split")
    mesh, sup, report = split_mesh(state.mesh, state.locator, state.infos, state.options.split)
    st = state.but(mesh=mesh, supports=sup, stage="split")
    st.report["split"] = report
    return st


def stage_merge(state: PipelineState) -> PipelineState:
    """Triangle-merging MIP (paper eq. 4-5) on the whole mesh (:func:`~shellmesh_mdao.merge.merge_mesh`)."""
    from .merge import merge_mesh

    _need(state, "merge")
    mesh, sup, report = merge_mesh(state.mesh, state.supports, state.locator, state.infos, state.options.merge)
    st = state.but(mesh=mesh, supports=sup, stage="merge")
    st.report["merge"] = report
    return st


def stage_smooth(state: PipelineState) -> PipelineState:
    """Smoothing QP (paper eq. 6-8): tangent-plane steps, KKT solve, projection back onto the
    input skin / member planes / feature curves; no step folds an element
    (:func:`~shellmesh_mdao.smooth.smooth_mesh`)."""
    from .smooth import smooth_mesh

    _need(state, "smooth")
    mesh, report = smooth_mesh(state.mesh, state.supports, REMESH_FACTOR * state.size, state.options.smooth)
    st = state.but(mesh=mesh, stage="smooth")
    st.report["smooth"] = report
    return st


def stage_quad(state: PipelineState, check: bool = True) -> PipelineState:
    """One subdivision to all quads (quad -> 4, triangle -> 3) over skin and members, new nodes
    projected onto their supports, then the final smoothing, the repair of poor elements and the
    flattening of warped quads (:func:`~shellmesh_mdao.quad.quad_mesh`: the policy, its options
    and report keys). Then the gate (``check``, default True): :func:`gate` refuses a mesh that
    misses a guarantee."""
    from .quad import quad_mesh

    _need(state, "quad")
    q, sup, report = quad_mesh(state.mesh, state.supports, state.size, state.options.quad, state.options.smooth)
    st = state.but(mesh=q, supports=sup, stage="quad")
    st.report.update(report)
    if check:
        gate(st)
    return st


def gate(state: PipelineState) -> dict:
    """The guarantees of the final mesh (:func:`~shellmesh_mdao.guarantees.check_guarantees`,
    flags from the run: :func:`~shellmesh_mdao.guarantees.gate_flags`), their figures into the
    report's ``guarantees``. A mesh that misses one is refused: :class:`GuaranteeError` naming
    the guarantee, the figure and the place, and what to do; nothing is returned or written."""
    from .guarantees import check_guarantees

    res = PipelineResult(state.mesh, state.report, surface=state.surface, layout=state.layout,
                         chains=state.chains, stage=state.stage, state=state)
    try:
        figures = check_guarantees(res)
    except GuaranteeError as e:
        raise GuaranteeError(f"{e}. The mesh is refused (nothing written): a mesh that misses a guarantee of "
                             "the README is an error, not a warning. A slightly different --size (a few "
                             "per cent) or moving the nearest member by about an element may avoid it; "
                             "please report the input and the command, it is a defect of the mesher "
                             "(run_pipeline(..., check=False) returns the mesh for inspection)") from e
    state.report["guarantees"] = {k: v for k, v in figures.items() if k != "quality"}
    return figures


_STAGE_FUNCS = {"project": stage_project, "remesh": stage_remesh, "imprint": stage_imprint,
                "members": stage_members, "split": stage_split, "merge": stage_merge, "smooth": stage_smooth,
                "quad": stage_quad}


def run_stage(state: PipelineState, name: str, *, remesh_cache=None) -> PipelineState:
    """Run stage ``name`` (one after ``layout``) on ``state``, timing it into the report;
    ``remesh_cache``: the remesh stage's :class:`~shellmesh_mdao.remesh.RemeshCache` (None: none)."""
    if name not in _STAGE_FUNCS:
        raise ShellMeshError(f"unknown stage {name!r}; run_stage takes one of: {', '.join(_STAGE_FUNCS)}")
    seconds: dict = {}
    with _Stages(False)(name, seconds):
        st = stage_remesh(state, remesh_cache) if name == "remesh" else _STAGE_FUNCS[name](state)
    st.report["stages"][name] = seconds[name]
    return st


def run_pipeline(surface, layout, size, *, until: str = STAGES[-1], progress: bool = True,
                 remesh: bool = True, options: dict | PipelineOptions | None = None,
                 remesh_cache=True, check: bool = True) -> PipelineResult:
    """Run the stages up to ``until`` on ``surface`` (path or :class:`ShellMesh`) with the member
    ``layout`` (path, dict or :class:`~shellmesh_mdao.layout.Layout`) at target quad size
    ``size``. ``options``: :class:`PipelineOptions` or a dict of them (solver options);
    ``remesh=False`` imprints into the input triangulation as it is (for tests).

    ``remesh_cache``: True (default) keeps the remeshed skin in the process's
    :data:`~shellmesh_mdao.remesh.DEFAULT_REMESH_CACHE`, so a loop over layouts on one surface,
    size and options remeshes once (the skin does not depend on the layout; a hit is the same skin
    bit for bit); a :class:`~shellmesh_mdao.remesh.RemeshCache` uses that one; False or None
    remeshes every time.

    ``check`` (default True): a run to the last stage passes the gate (:func:`gate`): a mesh that
    misses a guarantee of the README raises :class:`~shellmesh_mdao.errors.GuaranteeError`
    instead of being returned; its figures are in the report's ``guarantees``. False returns
    such a mesh, for inspection only."""
    if until not in STAGES:
        raise ShellMeshError(f"unknown stage {until!r}; --until takes one of: {', '.join(STAGES)}")
    if remesh_cache is True:
        from .remesh.cache import DEFAULT_REMESH_CACHE as remesh_cache
    elif remesh_cache is False:
        remesh_cache = None
    opts = PipelineOptions.from_dict(options)
    if not remesh:
        opts = opts.replace(remesh=False)
    timer = _Stages(progress)
    seconds: dict = {}
    with timer("load", seconds):
        state = stage_load(surface, size, opts)
    state.report["inputs"]["until"] = until
    for name in STAGES[1:STAGES.index(until) + 1]:
        with timer(name, seconds):
            if name == "layout":
                state = stage_layout(state, layout)
            elif name == "remesh":
                state = stage_remesh(state, remesh_cache)
            elif name == "quad":
                state = stage_quad(state, check)
            else:
                state = _STAGE_FUNCS[name](state)
    state.report["stages"] = seconds
    return _finish(PipelineResult(state.mesh, state.report, surface=state.surface, layout=state.layout,
                                  chains=state.chains, stage=state.stage, state=state))


def _finish(result: PipelineResult) -> PipelineResult:
    m = result.mesh
    used = np.unique(m.component)
    result.report.update({
        "stage": result.stage,
        "components": {int(i): m.component_names[i] for i in range(len(m.component_names))},
        "counts": {"n_points": int(m.n_points), "n_faces": int(m.n_faces), "n_tris": int(m.n_tris),
                   "n_quads": int(m.n_quads), "n_feature_edges": int(len(m.feature_edges)),
                   "faces_per_component": {m.component_names[i]: int((m.component == i).sum()) for i in used}},
    })
    return result
