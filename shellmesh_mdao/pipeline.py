"""The mesh pipeline: one call runs the stages in order and reports on each.

load -> layout -> project -> remesh -> imprint -> members -> (split -> merge -> smooth -> quad) -> export

:func:`run_pipeline` is what the CLI (``shellmesh mesh``), ``shellmesh demo`` and the
OpenMDAO components call. ``until`` stops after a stage; the result is a
:class:`PipelineResult` with the mesh of the last stage run, the chains, and a JSON
report (inputs, seconds per stage, components, counts, per-member chain figures).
"""
from __future__ import annotations

import logging
import sys
import time
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from .errors import SizeError, ShellMeshError
from .mesh import ShellMesh

log = logging.getLogger("shellmesh_mdao")

#: Stages in order; ``--until`` takes one of these.
STAGES = ("load", "layout", "project", "remesh", "imprint", "members")

#: The skin is remeshed at this multiple of the final quad size: merging pairs triangles into
#: quads and the final subdivision halves every edge.
REMESH_FACTOR = 2.0


@dataclass
class PipelineResult:
    mesh: ShellMesh
    report: dict
    surface: ShellMesh | None = None
    layout: object = None
    chains: list = field(default_factory=list)
    stage: str = ""


class _Stages:
    """Times stages and shows a spinner on a terminal for stages longer than a second."""

    def __init__(self, progress: bool):
        self.seconds: dict[str, float] = {}
        self.progress = progress and sys.stderr.isatty()

    @contextmanager
    def __call__(self, name: str):
        t0 = time.perf_counter()
        status = None
        if self.progress:
            from rich.console import Console

            status = Console(stderr=True).status(f"[bold]{name}[/bold] ...")
            status.start()
        try:
            yield
        finally:
            if status is not None:
                status.stop()
            dt = time.perf_counter() - t0
            self.seconds[name] = round(dt, 4)
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


def run_pipeline(surface, layout, size, *, until: str = "imprint", progress: bool = True,
                 remesh: bool = True) -> PipelineResult:
    """Run the stages up to ``until`` on ``surface`` (path or :class:`ShellMesh`) with the member
    ``layout`` (path, dict or :class:`~shellmesh_mdao.layout.Layout`) at target quad size
    ``size``. ``remesh=False`` imprints into the input triangulation as it is (for tests)."""
    from .imprint import chain_specs, improve_skin, imprint_chains, skin_families
    from .layout import load_layout
    from .load import load_surface
    from .project import SurfaceLocator, project_layout
    from .remesh import remesh_skin

    if until not in STAGES:
        raise ShellMeshError(f"unknown stage {until!r}; --until takes one of: {', '.join(STAGES)}")
    stage = _Stages(progress)
    report: dict = {"inputs": {"surface": str(surface) if not isinstance(surface, ShellMesh) else "<mesh>",
                               "size": size, "until": until}, "stages": stage.seconds}
    with stage("load"):
        if isinstance(surface, ShellMesh):
            skin_in = surface
        else:
            skin_in, srep = load_surface(surface)
            report["surface"] = srep.to_dict()
        h = check_size(size, skin_in.diagonal)
        if skin_in.n_quads:
            tris, _ = skin_in.triangles()
            skin_in = ShellMesh(skin_in.points, tris, np.zeros(len(tris), np.int32), ["skin"])
    result = PipelineResult(skin_in, report, surface=skin_in, stage="load")
    if until == "load":
        return _finish(result)
    with stage("layout"):
        lay = load_layout(layout)
        lay.validate(h)
        report["inputs"]["layout"] = lay.to_dict()
    result.layout, result.stage = lay, "layout"
    if until == "layout":
        return _finish(result)
    with stage("project"):
        P, T = skin_in.points, skin_in.faces[:, :3]
        locator = SurfaceLocator(P, T)
        projected = project_layout(locator, lay)
        specs = chain_specs(lay, projected)
    result.stage = "project"
    if until == "project":
        return _finish(result)
    with stage("remesh"):
        skin = remesh_skin(skin_in, REMESH_FACTOR * h, locator=locator) if remesh else skin_in
    result.mesh, result.stage = skin, "remesh"
    if until == "remesh":
        return _finish(result)
    with stage("imprint"):
        mesh, chains = imprint_chains(skin, P, T, specs, locator=locator)
        mesh = improve_skin(mesh, locator, chains)
        mesh = skin_families(mesh, lay)
    result.mesh, result.chains, result.stage = mesh, chains, "imprint"
    members: dict = {}
    for c in chains:
        e = members.setdefault(c.member, {"chains": []})
        e["chains"].append({"side": c.side, "n_vertices": int(c.n_vertices),
                            "length": float(np.linalg.norm(np.diff(mesh.points[c.vertices], axis=0), axis=1).sum())})
    report["members"] = members
    if until == "imprint":
        return _finish(result)
    from .members import build_members, member_infos, member_statistics

    with stage("members"):
        infos = member_infos(lay)
        e = mesh.edges()
        work = float(np.median(np.linalg.norm(mesh.points[e[:, 0]] - mesh.points[e[:, 1]], axis=1)))
        mesh = build_members(mesh, chains, infos, work)
    result.mesh, result.stage = mesh, "members"
    for name, st in member_statistics(mesh, infos).items():
        members.setdefault(name, {"chains": []}).update(st)
    return _finish(result)


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
