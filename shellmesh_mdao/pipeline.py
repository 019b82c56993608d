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
from .quality import scaled_jacobian, warp

log = logging.getLogger("shellmesh_mdao")

#: Stages in order; ``--until`` takes one of these.
STAGES = ("load", "layout", "project", "remesh", "imprint", "members", "split", "merge", "smooth", "quad")

#: Elements at or below this scaled Jacobian are reported (count, ids) and logged as a warning.
POOR_JACOBIAN = 0.2

#: Skin nodes farther than this fraction of the model's bounding-box diagonal from the input
#: surface are reported (report key ``off_surface``) and logged as a warning.
OFF_SURFACE_TOL = 1e-6

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
    from .layout import load_layout
    from .members import member_infos

    lay = load_layout(layout)
    lay.validate(state.size)
    st = state.but(layout=lay, infos=member_infos(lay), stage="layout")
    st.report["inputs"]["layout"] = lay.to_dict()
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


def _supports_hold(before: ShellMesh, after: ShellMesh) -> bool:
    """Whether a stage's result keeps what the node supports are derived from: the points,
    feature edges (and their ids), fixed vertices and component names (with the same faces and
    components too, the split stage's; the merge changes faces only within a component)."""
    return (np.array_equal(after.points, before.points)
            and np.array_equal(after.feature_edges, before.feature_edges)
            and np.array_equal(after.feature_edge_ids, before.feature_edge_ids)
            and np.array_equal(after.fixed_vertices, before.fixed_vertices)
            and after.component_names == before.component_names)


def stage_split(state: PipelineState) -> PipelineState:
    """Splitting LP (paper eq. 1-3) on the whole mesh; chains, junctions and feature lines are
    never split. Derives the node supports (input skin, member planes, feature curves)."""
    from .core.threads import Background
    from .smooth import edge_midpoint_projector, pipeline_supports
    from .split import split_polygons

    _need(state, "split")
    before = state.mesh

    def supports_and_projector():
        s = pipeline_supports(before, state.locator, state.infos)
        return s, edge_midpoint_projector(before, s)

    # made in a second thread while split_polygons builds and solves its LP (HiGHS releases the
    # GIL): the same values as made before it (the target case's split stage 0.154 -> 0.139 s,
    # docs/benchmarks.md, fifteenth pass)
    made = Background(supports_and_projector)
    mesh, res = split_polygons(before, time_limit=state.options.split_time_limit,
                               project=lambda points, parent_edges: made.result()[1](points, parent_edges))
    sup = made.result()[0]
    # where no edge was split (the target case) the mesh is the same and so are its supports
    if not (_supports_hold(before, mesh) and np.array_equal(mesh.faces, before.faces)
            and np.array_equal(mesh.component, before.component)):
        sup = pipeline_supports(mesh, state.locator, state.infos)
    st = state.but(mesh=mesh, supports=sup, stage="split")
    st.report["split"] = {"status": res.status, "objective": float(res.objective), "used_mip": bool(res.used_mip),
                          "n_split_edges": int(res.n_split_edges), "seconds": round(res.seconds, 4)}
    return st


def stage_merge(state: PipelineState) -> PipelineState:
    """Triangle-merging MIP (paper eq. 4-5) on the whole mesh."""
    from .merge import merge_triangles
    from .smooth import PLANE, SURFACE, pipeline_supports

    _need(state, "merge")
    o = state.options
    # the valence term counts the nodes free to move within their surface or member plane: on
    # chains, feature lines and junctions the best valence is not 4
    sp = state.supports
    free = (np.flatnonzero(np.isin(sp.kind, (SURFACE, PLANE)))
            if sp is not None and sp.n == state.mesh.n_points else None)
    mesh, res = merge_triangles(state.mesh, time_limit=o.merge_time_limit, mip_gap=o.merge_mip_gap,
                                merge_bonus=o.merge_bonus, valence_weight=o.merge_valence_weight,
                                valence_vertices=free)
    # a merge joins two triangles of one component across an edge that is no feature edge: no
    # point, feature edge or fixed vertex changes, nor any vertex's set of incident supports, so
    # the split stage's supports hold as they are (the same arrays as deriving them again)
    same = state.supports is not None and state.supports.n == mesh.n_points and _supports_hold(state.mesh, mesh)
    sup = state.supports if same else pipeline_supports(mesh, state.locator, state.infos)
    st = state.but(mesh=mesh, supports=sup, stage="merge")
    # a gap that is not a number (no bound: the valence term in blocks; a solve cut short) is null
    gap = float(res.mip_gap) if np.isfinite(res.mip_gap) else None
    st.report["merge"] = {"status": res.status, "objective": float(res.objective), "mip_gap": gap,
                          "n_merged": int(res.n_merged), "n_candidates": int(res.n_candidates),
                          "quad_fraction": round(float(res.quad_fraction), 4), "seconds": round(res.seconds, 4),
                          "solve_seconds": round(res.solve_seconds, 4), "valence_weight": o.merge_valence_weight}
    return st


def stage_smooth(state: PipelineState) -> PipelineState:
    """Smoothing QP (paper eq. 6-8): tangent-plane steps, KKT solve, projection back onto the
    input skin / member planes / feature curves; no step folds an element."""
    from .smooth import smooth

    _need(state, "smooth")
    # a triangle's scaled Jacobian bounds its three child quads' after subdivision: keep every
    # element above smooth_jacobian (0.4: triangle angles >= ~20 deg, children above ~0.3)
    mesh, res = smooth(state.mesh, state.supports, iterations=state.options.smooth_iterations,
                       min_jacobian=state.options.smooth_jacobian, energy=state.options.smooth_energy,
                       target_edge=REMESH_FACTOR * state.size, warp_weight=state.options.smooth_warp_weight,
                       warp_from=state.options.warp_from, warp_spread=state.options.smooth_warp_spread)
    st = state.but(mesh=mesh, stage="smooth")
    st.report["smooth"] = _smooth_report(res)
    return st


def _warp_p99(mesh: ShellMesh, w: np.ndarray | None = None) -> float:
    """99th percentile of the quads' warp (degrees; 0 without quads), the acceptance's measure;
    ``w``: the warp of every face, if already measured."""
    if not mesh.n_quads:
        return 0.0
    return float(np.percentile(warp(mesh.points, mesh.faces)[~mesh.is_tri] if w is None else w[~mesh.is_tri], 99))


def stage_quad(state: PipelineState) -> PipelineState:
    """One subdivision to all quads (quad -> 4, triangle -> 3) over skin and members, new nodes
    projected onto their supports, then a final smoothing pass; elements still at or below
    :data:`POOR_JACOBIAN` are repaired locally (:func:`~shellmesh_mdao.smooth.untangle` on the two
    rings around them; report key ``poor_repair``), and what remains is reported and logged. Last,
    the free skin nodes around the quads still warped above ``warp_goal`` move along their normals,
    off the input by at most ``planar_offset`` times the size (:func:`~shellmesh_mdao.quad.planarize`;
    report key ``planarize``). Where the warp p99 is above ``warp_goal`` after the final smoothing
    and that last move alone does not bring it to the goal, a second smoothing pass with the quad
    planarity term runs, around the quads that move left above the goal (``final_warp_weight``;
    report key ``final_smooth.warp_term``), from the move's mesh with the nodes it may move put back
    where they were before the move; only those nodes are moved off the facets again after it
    (:func:`_finish_region`), and the result is kept only if its warp p99 is below the move alone's
    (``warp_term.kept``: ``"pass"`` or ``"planarize_alone"``)."""
    from .mesh import vertex_faces
    from .quad import subdivide_to_quads
    from .core.topology import face_rings
    from .smooth import mesh_figures, smooth

    _need(state, "quad")
    o = state.options
    q, sup = subdivide_to_quads(state.mesh, state.supports, guard_jacobian=o.guard_jacobian)
    warp_term = None
    done = None
    if o.final_iterations:
        # the first pass's figures after it are taken only if no second pass follows
        q, res = smooth(q, sup, iterations=o.final_iterations, energy=o.smooth_energy, target_edge=state.size,
                        ortho_weight=o.final_ortho_weight, refresh=o.final_refresh, figures="before")
        # the planarity term trades scaled Jacobian for flatness: a second pass with it, only
        # where the warp p99 acceptance is missed and the planarize move alone cannot meet it
        wq = warp(q.points, q.faces)
        p99 = _warp_p99(q, wq)
        warp_term = {"warp_p99_before": p99, "warp_goal": o.warp_goal, "applied": False}
        second_pass = o.final_warp_weight > 0 and (o.warp_goal <= 0 or p99 > o.warp_goal)
        trial = None
        if second_pass and o.planar_offset > 0 and o.warp_goal > 0:
            # first the cheap way: the planarize move (and the settle and repair before it) on
            # this pass's mesh; kept if it meets the goal, else the second pass runs on this
            # pass's mesh, around the quads that move left above the goal
            trial = _finish_quads(state, q, sup)
            alone = trial["planar"]["warp_p99_after"]
            warp_term["planarize_alone_p99"] = alone
            if alone <= o.warp_goal:
                done, second_pass = trial, False
        if second_pass:
            # only around the quads still warped (two rings): the rest of the mesh keeps the first
            # pass. With the planarize trial: the quads it left above the goal (it flattens the
            # others without the pass); without it, every quad in the planarity term
            vptr, vface = vertex_faces(q.faces, q.n_points)
            if trial is not None:
                tm = trial["mesh"]
                seeds = warp(tm.points, tm.faces) > o.warp_goal
            else:
                seeds = wq > o.warp_from
            warp_term["seed_quads"] = int(seeds.sum())
            warped = np.unique(q.faces[seeds])
            region = face_rings(q.faces, vptr, vface, warped[warped >= 0], 2)
            movable = np.unique(q.faces[region])
            movable = movable[movable >= 0]
            first = (q, res)
            if trial is not None:
                # the pass starts from the trial's mesh (settled, repaired, moved off the facets),
                # the region's nodes back where they were before the move: outside the region the
                # trial's result stands, and only the region is settled and moved again after it
                start = tm.points.copy()
                start[movable] = trial["before_planar"].points[movable]
                q = q.with_points(start)
            q, res2 = smooth(q, sup, iterations=o.final_warp_iterations, energy=o.smooth_energy,
                             target_edge=state.size, ortho_weight=o.final_ortho_weight,
                             warp_weight=o.final_warp_weight, warp_from=o.warp_from, vertices=movable,
                             figures="after")
            res = dataclasses.replace(
                res2, quality_before=res.quality_before, moves=res.moves + res2.moves,
                max_move=max(res.max_move, res2.max_move),
                **{f: getattr(res, f) + getattr(res2, f) for f in (
                    "iterations", "seconds", "factorisations", "n_step_halvings", "n_rejected", "n_fold_hits",
                    "n_jump_hits")})
            warp_term.update(applied=True, warp_p99_after=_warp_p99(q), vertices=int(len(movable)))
            if trial is not None:
                # the pass and the move after it must beat the move alone, else the move alone
                # on the first pass's mesh is kept (its scaled Jacobians are the better ones)
                done = _finish_region(state, q, sup, movable, trial)
                if done["planar"]["warp_p99_after"] >= trial["planar"]["warp_p99_after"]:
                    done, (q, res) = trial, first
                    res = dataclasses.replace(res, quality_after=mesh_figures(q, sup, state.size))
                    warp_term["kept"] = "planarize_alone"
                else:
                    warp_term["kept"] = "pass"
        else:
            res = dataclasses.replace(res, quality_after=mesh_figures(q, sup, state.size))
    if done is None:
        done = _finish_quads(state, q, sup)
    q, sj, poor = done["mesh"], done["sj"], done["poor"]
    off_surface, warning = _off_surface(state, done, sup)
    if warning:
        log.warning(warning)
    st = state.but(mesh=q, supports=sup, stage="quad")
    if o.final_iterations:
        st.report["final_smooth"] = _smooth_report(res)
        st.report["final_smooth"]["warp_term"] = warp_term
    if done["repair"] is not None:
        st.report["poor_repair"] = done["repair"]
    st.report["off_surface"] = off_surface
    st.report["planarize"] = done["planar"]
    st.report["poor_elements"] = {"threshold": POOR_JACOBIAN, "count": int(len(poor)),
                                  "folded": int((sj <= 0).sum()), "elements": poor[:100].tolist(),
                                  "min_scaled_jacobian": float(sj.min()) if len(sj) else None}
    if len(poor):
        where = sorted({q.component_names[c] for c in q.component[poor]})
        log.warning("%d element(s) with scaled Jacobian <= %.1f (min %.3f) in %s: they come from sliver triangles "
                    "of the imprint that no stage could remove; see the report's 'poor_elements' (0-based ids)",
                    len(poor), POOR_JACOBIAN, float(sj.min()), ", ".join(where[:5]))
    return st


def _repair_poor(q: ShellMesh, sup, sj):
    """Elements at or below :data:`POOR_JACOBIAN` (scaled Jacobians ``sj`` of ``q``) repaired by
    :func:`~shellmesh_mdao.smooth.untangle` on the two rings around them, kept if no worse.
    Returns ``(q, sj, poor, repair)`` (``repair`` the report's figures, None without poor elements)."""
    from .mesh import vertex_faces
    from .core.topology import face_rings
    from .smooth import untangle

    poor = np.flatnonzero(sj <= POOR_JACOBIAN)
    if not len(poor):
        return q, sj, poor, None
    # last resort: move the vertices within two rings of the poor elements along their supports
    # (smooth.untangle: no element at or below the goal gets worse, none above falls to it)
    vptr, vface = vertex_faces(q.faces, q.n_points)
    region = face_rings(q.faces, vptr, vface, np.unique(q.faces[poor][q.faces[poor] >= 0]), 2)
    q2, info = untangle(q, sup, goal=POOR_JACOBIAN + 0.1, faces=region)
    sj2 = scaled_jacobian(q2.points, q2.faces)
    repair = {"elements_before": int(len(poor)), "elements_after": int((sj2 <= POOR_JACOBIAN).sum()),
              "min_before": float(sj.min()), "min_after": float(sj2.min()), "moves": int(info["moves"])}
    n2 = int((sj2 <= POOR_JACOBIAN).sum())
    if n2 <= len(poor) and (n2 < len(poor) or sj2.min() > sj.min()):
        q, sj = q2, sj2
        poor = np.flatnonzero(sj <= POOR_JACOBIAN)
    return q, sj, poor, repair


def _planarize(state: PipelineState, q: ShellMesh, sup, sj, poor, vertices=None):
    """The quad stage's :func:`~shellmesh_mdao.quad.planarize` move on ``q`` (scaled Jacobians
    ``sj``, poor elements ``poor``), moving only ``vertices`` if given. Returns ``(q, planar, sj,
    poor)``, ``planar`` the report's figures (with the offset over the size and its bound)."""
    from .quad import planarize

    o = state.options
    q, planar = planarize(q, sup, max_offset=o.planar_offset * state.size, warp_above=o.warp_goal,
                          guard_jacobian=POOR_JACOBIAN + 0.1, vertices=vertices)
    planar.update(max_offset_over_size=planar["max_offset"] / state.size, bound_over_size=o.planar_offset)
    if planar["applied"]:
        sj = scaled_jacobian(q.points, q.faces)
        poor = np.flatnonzero(sj <= POOR_JACOBIAN)
    return q, planar, sj, poor


def _finish_region(state: PipelineState, q: ShellMesh, sup, movable, trial: dict) -> dict:
    """:func:`_finish_quads` after the second pass, which started from the planarize trial's
    mesh and moved only the nodes ``movable``: the elements at or below :data:`POOR_JACOBIAN`
    repaired, then :func:`~shellmesh_mdao.quad.planarize` moving only ``movable`` (outside the
    region the trial's move stands; the smoothing put the region's nodes on their supports, and
    the trial settled the rest). ``before_planar``: the nodes that kept the trial's positions at
    the trial's positions before its move. The same keys as :func:`_finish_quads`; ``planar``'s
    ``moved`` and ``max_offset`` count the trial's moves that stand as well, and ``repair`` is
    the trial's where the region needed none."""
    q, sj, poor, repair = _repair_poor(q, sup, scaled_jacobian(q.points, q.faces))
    held = np.ones(q.n_points, bool)
    held[movable] = False
    held &= (q.points == trial["mesh"].points).all(1)
    bp = q.points.copy()
    bp[held] = trial["before_planar"].points[held]
    before_planar = q.with_points(bp)
    q, planar, sj, poor = _planarize(state, q, sup, sj, poor, vertices=movable)
    # the report counts every node off the facets in the result: the region's moves and the
    # trial's that stand outside it ("nodes": the region's candidates and those)
    step = norm_rows(q.points - bp, axis=1)
    kept_out = int((step[held] > 0).sum())
    planar.update(applied=bool(planar["applied"] or kept_out), nodes=int(planar["nodes"]) + kept_out,
                  moved=int((step > 0).sum()), max_offset=float(step.max(initial=0.0)))
    planar.update(max_offset_over_size=planar["max_offset"] / state.size)
    # the trial's repair stands too (the pass started from its mesh)
    return {"mesh": q, "sj": sj, "poor": poor, "repair": trial["repair"] if repair is None else repair,
            "settled": trial["settled"], "before_planar": before_planar, "planar": planar}


def _finish_quads(state: PipelineState, q: ShellMesh, sup) -> dict:
    """The quad stage after its smoothing, on ``q``: skin nodes left off the surface settled,
    elements at or below :data:`POOR_JACOBIAN` repaired, then :func:`~shellmesh_mdao.quad.planarize`.
    Returns ``{"mesh", "sj", "poor", "repair", "settled", "before_planar", "planar"}``
    (``before_planar``: the mesh before planarize, whose nodes off the surface
    :func:`_off_surface` reports for the result the caller keeps); ``q`` and ``sup`` are not
    changed."""
    from .quad import settle_off_surface

    o = state.options
    # skin nodes the subdivision's fold guard left off the surface: once their neighbours have
    # been smoothed most of them can go onto it (the same settle, no element below the guard
    # made worse)
    q, settled = settle_off_surface(q, sup, tol=OFF_SURFACE_TOL, guard_jacobian=o.guard_jacobian)
    q, sj, poor, repair = _repair_poor(q, sup, scaled_jacobian(q.points, q.faces))
    before_planar = q
    # quads still warped above the goal straddle kinks of the faceted input that no move along it
    # can flatten: their free skin nodes leave the facets by at most planar_offset * size
    planar = None
    if o.planar_offset > 0:
        q, planar, sj, poor = _planarize(state, q, sup, sj, poor)
    return {"mesh": q, "sj": sj, "poor": poor, "repair": repair, "settled": settled, "before_planar": before_planar,
            "planar": planar}


def _off_surface(state: PipelineState, done: dict, sup) -> tuple[dict, str | None]:
    """The report's ``off_surface`` and its warning (None if no node is off) for the result of
    :func:`_finish_quads` the quad stage keeps (measured only for that one: a planarize trial
    that is not kept needs neither)."""
    from .smooth import SURFACE

    # skin nodes still off the input surface: the subdivision kept a new node at its linear position
    # where projecting it would fold a child, and neither its repair nor the one after the final
    # smoothing (settle_off_surface) could fix that (a parent face across a crease or a ridge much
    # tighter than the element size); measured before planarize, which moves nodes off on purpose
    q, settled = done["before_planar"], done["settled"]
    skin_nodes = np.flatnonzero(sup.kind == SURFACE)
    d = sup.distance(q.points, skin_nodes) if len(skin_nodes) else np.zeros(0)
    off = d > OFF_SURFACE_TOL * q.diagonal
    off_surface = {"count": int(off.sum()), "max_distance": float(d.max(initial=0.0)),
                   "before_settle": settled["before"], "settled": settled["before"] - settled["after"],
                   "max_distance_over_size": float(d.max(initial=0.0) / state.size),
                   "nodes": skin_nodes[off][:100].tolist()}
    warning = None
    if off.any():
        k = skin_nodes[off][np.argmax(d[off])]
        warning = (f"{int(off.sum())} skin node(s) off the input surface, up to {float(d[off].max()):.3g} "
                   f"({float(d[off].max() / state.size):.2f} element sizes) near "
                   f"{np.array2string(q.points[k], precision=4)}: a face spanned a crease or ridge much tighter "
                   "than the element size there; use a smaller --size or see the report's 'off_surface' (0-based ids)")
    return off_surface, warning


def _smooth_report(res) -> dict:
    return {"iterations": int(res.iterations), "seconds": round(res.seconds, 4), "max_move": float(res.max_move),
            "n_rejected": int(res.n_rejected), "quality_before": res.quality_before,
            "quality_after": res.quality_after}


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
