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

from .errors import SizeError, ShellMeshError
from .mesh import ShellMesh, norm_rows

log = logging.getLogger("shellmesh_mdao")

#: Stages in order; ``--until`` takes one of these.
STAGES = ("load", "layout", "project", "remesh", "imprint", "members", "split", "merge", "smooth", "quad")

#: The skin is remeshed at this multiple of the final quad size: merging pairs triangles into
#: quads and the final subdivision halves every edge.
REMESH_FACTOR = 2.0


@dataclass(frozen=True)
class PipelineOptions:
    """Options of the stages after ``load`` (the CLI's and the components' solver options).

    ``remesh``            remesh the skin before imprinting (False: imprint into the input
                          triangulation as it is; for tests).
    ``remesh_deviation``  chordal deviation allowed between the remeshed skin and the input, as a
                          fraction of the remesh edge length (edges shrink where curvature needs it).
    ``remesh_pass_fraction`` the remesh's deviation passes (which shrink the sizing where edges
                          still deviate more than that and re-run four sweeps over the whole skin)
                          run only while more than this fraction of the edges deviate
                          (``deviation_pass_fraction`` of :func:`~shellmesh_mdao.remesh.remesh_skin`);
                          fewer are split where they are by its last-resort deviation splits, which
                          hold the bound either way. Default 0.02: the corpus has at most 0.7 % (its
                          passes cost 0.45 s of the target case's remesh, and the merge's valence term
                          more than makes up the scaled Jacobian they bought), the default wing
                          4 %; 0 runs them for any deviating edge (docs/benchmarks.md).
    ``snap``              the imprint moves a skin vertex onto a member plane when it lies within
                          this fraction of its shortest incident edge of it (instead of cutting a
                          sliver beside it); below 0.5, default 0.4 (fewer triangles beside the
                          chains than at 0.25: swept_wing skin mean scaled Jacobian 0.9507 against
                          0.9468). A chain whose cut misses one of its crossing vertices at a
                          distance above 0.25 is cut again at 0.25 (``imprint.SNAP_FALLBACK``; the
                          report's per-chain ``snap`` says which was used).
    ``chain_deviation``   above 0: after the cut, member chain edges whose exact section bulges more
                          than this fraction of the remesh edge length from the chord are split
                          (:func:`~shellmesh_mdao.imprint.refine_chains`). Default 0.01; 0 turns it off.
    ``chain_depth_deviation`` with ``chain_deviation`` on, a chain edge is also split where its exact
                          section bulges more than this fraction of its member's depth (the distance
                          to the member's other chain, :func:`~shellmesh_mdao.imprint.chain_depths`):
                          the chords then cut off at most about 4/3 of it of the member's area, 1 %
                          at the default 0.0075, however thin the section against the element size.
                          Worst corpus member area error 0.58 % (bwb's outer ribs; 1.0 % with 0, off).
    ``split_time_limit``  HiGHS time limit (s) of the splitting LP/MIP.
    ``merge_time_limit``, ``merge_mip_gap``: HiGHS time limit (s) and relative gap of the
                          merging MIP.
    ``merge_bonus``       reward per merged triangle pair (in units of the eq.-5 energy): above
                          0 the MIP prefers quads even where two triangles score slightly better,
                          which leaves fewer triangles for the final subdivision (each gives
                          three 120-degree-cornered quads).
    ``merge_valence_weight`` weight of the merge's valence term (beyond the paper): each free
                          skin and member node (not on a chain, feature line or junction) adds this
                          times ``|valence - 4|``, its valence counted after the merge, to the
                          merge's objective (:func:`~shellmesh_mdao.merge.merge_triangles`'s
                          ``valence_weight``): the subdivided quads around a node of valence 3, 5
                          or 6 cannot all be square. Default 0.5 (the corpus's skin mean scaled
                          Jacobian +0.004 to +0.008, docs/benchmarks.md); 0 turns it off.
    ``smooth_iterations`` trust-region steps of the smoothing QP before subdivision (default 10);
                          ``final_iterations`` after it (default 4), ``final_warp_iterations`` in
                          the second final pass with the quad planarity term (default 10; see
                          ``final_warp_weight``).
    ``final_refresh``     steps of the final pass (``final_iterations``) between rebuilding its
                          tangent frames, edge weights and matrix (``refresh`` of
                          :func:`~shellmesh_mdao.smooth.smooth`; default 2, at least 1).
    ``guard_jacobian``    a subdivided element whose projected new nodes would bring its scaled
                          Jacobian to or below this keeps them at their linear position.
    ``smooth_energy``     energy of both smoothing passes: ``"squared"`` (default: edges aim at the
                          target length, twice ``size`` before subdivision, ``size`` after) or
                          ``"length"`` (sum of edge lengths, scale-free: the paper's words); see
                          :func:`~shellmesh_mdao.smooth.smooth` and docs/optimisation.md.
    ``smooth_jacobian``   no smoothing step before subdivision may bring an element to or below
                          this scaled Jacobian (nor lower one already below it).
    ``final_ortho_weight`` weight of the quad-corner orthogonality term in the smoothing after
                          subdivision (``ortho_weight`` of :func:`~shellmesh_mdao.smooth.smooth`;
                          the pass before subdivision keeps smooth()'s default 1). 3 lifts the
                          worst and the mean scaled Jacobian (docs/benchmarks.md); 0 drops the term.
    ``final_warp_weight`` weight of the quad planarity term (``warp_weight`` of
                          :func:`~shellmesh_mdao.smooth.smooth`: the corners of quads warped more than
                          ``warp_from`` degrees slide along the input facets until the quad is
                          flatter) in a second smoothing pass after subdivision, run only while more
                          than 1 % of the quads are warped more than ``warp_goal`` degrees after the
                          first (the warp p99 acceptance; ``warp_goal`` 0: always) and the
                          ``planar_offset`` move alone does not bring them to it (tried first on the
                          first pass's mesh: cheaper, and it keeps the scaled Jacobians; on the corpus
                          only straight_wing needs the pass), moving only the nodes within two rings of
                          the quads that move left warped more than ``warp_goal`` (with
                          ``planar_offset`` 0: of the quads warped more than ``warp_from``). Default
                          300; 0 drops the pass.
    ``smooth_warp_weight`` the same term in the smoothing before subdivision. Default 300 (bwb's
                          warp p99 10.5 -> 9.7 degrees); 0 drops it.
    ``smooth_warp_spread`` the term before subdivision leaves out the quads that share a vertex with
                          a face whose corners' input facets are turned more than this many degrees
                          apart (a face draped over a tip cap or nose much tighter than itself:
                          pulling there dragged nodes across the crease, and the subdivision then left
                          nodes off the surface). Default 75.
    ``warp_from``         warp (degrees) above which a quad is in the planarity term; default 7.
    ``warp_goal``         warp p99 (degrees) the final smoothing's planarity term works towards;
                          default 10 (:data:`~shellmesh_mdao.quality.ACCEPTANCE`).
    ``planar_offset``     after the final smoothing, the free skin nodes (not on chains, junctions,
                          feature lines or members) around the quads still warped more than
                          ``warp_goal`` degrees may move along their normal, off the input facets, by
                          at most this fraction of ``size`` (and 0.15 of their local quad edge) to
                          flatten those quads (:func:`~shellmesh_mdao.quad.planarize`; report key
                          ``planarize``). 0.05 is the chordal deviation the remesh already accepts
                          (``remesh_deviation`` 0.1 of the remesh edge, a quarter of it at the final
                          quads). Default 0.05; 0 keeps every skin node on the input.
    """

    remesh: bool = True
    remesh_deviation: float = 0.1
    remesh_pass_fraction: float = 0.02
    snap: float = 0.4
    chain_deviation: float = 0.01
    chain_depth_deviation: float = 0.0075
    split_time_limit: float = 60.0
    merge_time_limit: float = 60.0
    merge_mip_gap: float = 0.01
    merge_bonus: float = 1.0
    merge_valence_weight: float = 0.5
    smooth_iterations: int = 10
    final_iterations: int = 4
    final_refresh: int = 2
    final_warp_iterations: int = 10
    guard_jacobian: float = 0.2
    smooth_jacobian: float = 0.4
    smooth_energy: str = "squared"
    final_ortho_weight: float = 3.0
    smooth_warp_weight: float = 300.0
    final_warp_weight: float = 300.0
    smooth_warp_spread: float = 75.0
    warp_from: float = 7.0
    warp_goal: float = 10.0
    planar_offset: float = 0.05

    @classmethod
    def from_dict(cls, d: dict | None) -> "PipelineOptions":
        """Options from a dict; unknown names are a :class:`ShellMeshError` naming them."""
        if d is None:
            return cls()
        if isinstance(d, PipelineOptions):
            return d
        known = {f.name: f for f in dataclasses.fields(cls)}
        bad = sorted(set(d) - set(known))
        if bad:
            raise ShellMeshError(f"unknown solver option(s) {bad}; known: {', '.join(known)}")
        out = {}
        for k, v in d.items():
            typ = type(getattr(cls(), k))
            try:
                out[k] = typ(v) if typ is not bool else bool(v)
            except (TypeError, ValueError):
                raise ShellMeshError(f"solver option {k!r} must be a {typ.__name__}, got {v!r}") from None
            if typ in (int, float) and not (np.isfinite(out[k]) and out[k] >= 0):
                raise ShellMeshError(f"solver option {k!r} must be a finite non-negative number, got {v!r}")
        if not out.get("snap", 0.0) < 0.5:
            raise ShellMeshError(f"solver option 'snap' must be below 0.5 (a fraction of a vertex's shortest "
                                 f"incident edge), got {out['snap']!r}")
        if not out.get("planar_offset", 0.0) <= 0.25:
            raise ShellMeshError(f"solver option 'planar_offset' must be at most 0.25 (a fraction of the size by "
                                 f"which skin nodes may leave the input to flatten warped quads), got "
                                 f"{out['planar_offset']!r}")
        if out.get("final_refresh", 2) < 1:
            raise ShellMeshError(f"solver option 'final_refresh' must be at least 1 (steps between rebuilding the "
                                 f"final pass's frames and matrix), got {out['final_refresh']!r}")
        if not 0 < out.get("smooth_warp_spread", 75.0) <= 180:
            raise ShellMeshError(f"solver option 'smooth_warp_spread' must be in (0, 180] degrees, got "
                                 f"{out['smooth_warp_spread']!r}")
        if out.get("smooth_energy", "length") not in ("length", "squared"):
            raise ShellMeshError(f"solver option 'smooth_energy' must be 'length' or 'squared', got "
                                 f"{out['smooth_energy']!r}")
        return cls(**out)


@dataclass(frozen=True)
class PipelineState:
    """What travels between stages. ``stage`` is the last stage run; fields a stage has not
    produced yet are None. ``mesh`` is the current mesh (the skin until ``members``, then skin
    and members together); ``surface`` and ``locator`` are the ORIGINAL input skin and its BVH;
    ``supports`` say where each node of ``mesh`` may move (from ``split`` on)."""

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
    from .project import SurfaceLocator

    opts = PipelineOptions.from_dict(options)
    report: dict = {"inputs": {"surface": str(surface) if not isinstance(surface, ShellMesh) else "<mesh>",
                               "size": size, "options": dataclasses.asdict(opts)}, "stages": {}}
    # handles or refuses dirty CAD input: duplicates, orientation, intersecting bodies, half
    # models (docs/troubleshooting.md)
    skin_in, srep = repair_surface(surface)
    report["surface"] = srep.to_dict()
    h = check_size(size, skin_in.diagonal)
    if skin_in.n_quads:
        tris, _ = skin_in.triangles()
        skin_in = ShellMesh(skin_in.points, tris, np.zeros(len(tris), np.int32), ["skin"])
    locator = SurfaceLocator(skin_in.points, skin_in.faces[:, :3])
    return PipelineState(h, opts, report, surface=skin_in, locator=locator, mesh=skin_in, stage="load")


def stage_layout(state: PipelineState, layout) -> PipelineState:
    """Read and validate the member layout (path, dict or :class:`~shellmesh_mdao.layout.Layout`)."""
    from .layout import load_layout, resolve_layout
    from .members import member_infos

    lay = resolve_layout(load_layout(layout), state.surface.points, state.surface.faces[:, :3], state.size)
    lay.validate(state.size)
    st = state.but(layout=lay, infos=member_infos(lay), stage="layout")
    st.report["inputs"]["layout"] = lay.to_dict()
    if lay.station_wings:                  # wings measured from the skin: their planform and notes
        st.report["wings"] = {w.name: dict(w.planform.summary(), notes=list(w.notes)) for w in lay.station_wings}
    return st


def stage_project(state: PipelineState) -> PipelineState:
    """Cast every member's seed points onto the input skin and derive the curves to imprint;
    refuse spars too thin for the element size (:func:`~shellmesh_mdao.project.check_member_heights`)."""
    from .imprint import chain_specs
    from .project import check_member_heights, project_layout

    _need(state, "project")
    projected = project_layout(state.locator, state.layout)
    check_member_heights(state.locator, state.layout, state.size)
    return state.but(projected=projected, specs=chain_specs(state.layout, projected), stage="project")


def stage_remesh(state: PipelineState) -> PipelineState:
    """Isotropic, curvature-adapted remesh of the skin at ``REMESH_FACTOR * size``."""
    from .remesh import remesh_skin

    _need(state, "remesh")
    skin = state.surface
    if state.options.remesh:
        target = REMESH_FACTOR * state.size
        skin = remesh_skin(state.surface, target, max_deviation=state.options.remesh_deviation * target,
                           deviation_pass_fraction=state.options.remesh_pass_fraction,
                           locator=state.locator)
    return state.but(mesh=skin, stage="remesh")


def stage_imprint(state: PipelineState) -> PipelineState:
    """Imprint every member's curves into the skin as chains of edges; name the skin bays."""
    from .imprint import (chain_report, coarsen_chains, imprint_chains, refine_chains, skin_families,
                          split_member_bridges)

    _need(state, "imprint")
    P, T = state.surface.points, state.surface.faces[:, :3]
    mesh, chains = imprint_chains(state.mesh, P, T, state.specs, snap=state.options.snap, locator=state.locator)
    if state.options.chain_deviation > 0:
        mesh = refine_chains(mesh, chains, state.options.chain_deviation * REMESH_FACTOR * state.size,
                             depth_fraction=state.options.chain_depth_deviation)
    mesh = coarsen_chains(mesh, state.locator, chains, REMESH_FACTOR * state.size)
    mesh = split_member_bridges(mesh, chains, state.locator)
    mesh = skin_families(mesh, state.layout)
    st = state.but(mesh=mesh, chains=chains, stage="imprint")
    st.report["members"] = chain_report(mesh, chains)
    return st


def stage_members(state: PipelineState) -> PipelineState:
    """Mesh every member (planar Delaunay or Coons patch) on its chains; split members at
    their junctions; one conforming triangle mesh of skin and members."""
    from .members import build_members, member_statistics

    _need(state, "members")
    # members are flat or gently curved: meshed at the skin's flat-region edge length, graded
    # to the chain spacing at their boundary
    mesh = build_members(state.mesh, state.chains, state.infos, REMESH_FACTOR * state.size)
    st = state.but(mesh=mesh, stage="members")
    members = {k: dict(v) for k, v in st.report.get("members", {}).items()}
    for name, s in member_statistics(mesh, state.infos).items():
        members.setdefault(name, {"chains": []}).update(s)
    st.report["members"] = members
    return st


def stage_split(state: PipelineState) -> PipelineState:
    """Splitting LP (paper eq. 1-3) on the whole mesh; chains, junctions and feature lines are
    never split. Derives the node supports (input skin, member planes, feature curves)
    (:func:`~shellmesh_mdao.split.split_mesh`)."""
    from .split import split_mesh

    _need(state, "split")
    mesh, sup, report = split_mesh(state.mesh, state.locator, state.infos,
                                   time_limit=state.options.split_time_limit)
    st = state.but(mesh=mesh, supports=sup, stage="split")
    st.report["split"] = report
    return st


def stage_merge(state: PipelineState) -> PipelineState:
    """Triangle-merging MIP (paper eq. 4-5) on the whole mesh (:func:`~shellmesh_mdao.merge.merge_mesh`)."""
    from .merge import merge_mesh

    _need(state, "merge")
    o = state.options
    mesh, sup, report = merge_mesh(state.mesh, state.supports, state.locator, state.infos,
                                   time_limit=o.merge_time_limit, mip_gap=o.merge_mip_gap, merge_bonus=o.merge_bonus,
                                   valence_weight=o.merge_valence_weight)
    st = state.but(mesh=mesh, supports=sup, stage="merge")
    st.report["merge"] = report
    return st


def stage_smooth(state: PipelineState) -> PipelineState:
    """Smoothing QP (paper eq. 6-8): tangent-plane steps, KKT solve, projection back onto the
    input skin / member planes / feature curves; no step folds an element."""
    from .smooth import smooth, smooth_report

    _need(state, "smooth")
    # a triangle's scaled Jacobian bounds its three child quads' after subdivision: keep every
    # element above smooth_jacobian (0.4: triangle angles >= ~20 deg, children above ~0.3)
    mesh, res = smooth(state.mesh, state.supports, iterations=state.options.smooth_iterations,
                       min_jacobian=state.options.smooth_jacobian, energy=state.options.smooth_energy,
                       target_edge=REMESH_FACTOR * state.size, warp_weight=state.options.smooth_warp_weight,
                       warp_from=state.options.warp_from, warp_spread=state.options.smooth_warp_spread)
    st = state.but(mesh=mesh, stage="smooth")
    st.report["smooth"] = smooth_report(res)
    return st


def stage_quad(state: PipelineState) -> PipelineState:
    """One subdivision to all quads (quad -> 4, triangle -> 3) over skin and members, new nodes
    projected onto their supports, then the final smoothing, the repair of poor elements and the
    flattening of warped quads (:func:`~shellmesh_mdao.quad.quad_mesh`: the policy, its options
    and report keys)."""
    from .quad import quad_mesh

    _need(state, "quad")
    o = state.options
    q, sup, report = quad_mesh(state.mesh, state.supports, state.size, guard_jacobian=o.guard_jacobian,
                               final_iterations=o.final_iterations, final_refresh=o.final_refresh,
                               final_warp_iterations=o.final_warp_iterations, smooth_energy=o.smooth_energy,
                               final_ortho_weight=o.final_ortho_weight, final_warp_weight=o.final_warp_weight,
                               warp_from=o.warp_from, warp_goal=o.warp_goal, planar_offset=o.planar_offset)
    st = state.but(mesh=q, supports=sup, stage="quad")
    st.report.update(report)
    return st


_STAGE_FUNCS = {"project": stage_project, "remesh": stage_remesh, "imprint": stage_imprint,
                "members": stage_members, "split": stage_split, "merge": stage_merge, "smooth": stage_smooth,
                "quad": stage_quad}


def run_stage(state: PipelineState, name: str) -> PipelineState:
    """Run stage ``name`` (one after ``layout``) on ``state``, timing it into the report."""
    if name not in _STAGE_FUNCS:
        raise ShellMeshError(f"unknown stage {name!r}; run_stage takes one of: {', '.join(_STAGE_FUNCS)}")
    seconds: dict = {}
    with _Stages(False)(name, seconds):
        st = _STAGE_FUNCS[name](state)
    st.report["stages"][name] = seconds[name]
    return st


def run_pipeline(surface, layout, size, *, until: str = STAGES[-1], progress: bool = True,
                 remesh: bool = True, options: dict | PipelineOptions | None = None) -> PipelineResult:
    """Run the stages up to ``until`` on ``surface`` (path or :class:`ShellMesh`) with the member
    ``layout`` (path, dict or :class:`~shellmesh_mdao.layout.Layout`) at target quad size
    ``size``. ``options``: :class:`PipelineOptions` or a dict of them (solver options);
    ``remesh=False`` imprints into the input triangulation as it is (for tests)."""
    if until not in STAGES:
        raise ShellMeshError(f"unknown stage {until!r}; --until takes one of: {', '.join(STAGES)}")
    opts = PipelineOptions.from_dict(options)
    if not remesh:
        opts = dataclasses.replace(opts, remesh=False)
    timer = _Stages(progress)
    seconds: dict = {}
    with timer("load", seconds):
        state = stage_load(surface, size, opts)
    state.report["inputs"]["until"] = until
    for name in STAGES[1:STAGES.index(until) + 1]:
        with timer(name, seconds):
            state = stage_layout(state, layout) if name == "layout" else _STAGE_FUNCS[name](state)
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
