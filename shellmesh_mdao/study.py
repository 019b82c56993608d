"""Run a study: the pipeline of a :class:`~shellmesh_mdao.config.StudyConfig` and its outputs.

:func:`run_study` is what ``shellmesh mesh`` and ``shellmesh demo`` call, and what a script
calls to repeat a study from its config file::

    from shellmesh_mdao import run_study
    result, written = run_study("default_wing_study.yaml")   # the config `shellmesh demo` writes

It checks the config (:func:`check_study`), runs :func:`~shellmesh_mdao.pipeline.run_pipeline`
up to the config's ``until``, then writes the meshes, the human report (pictures) and the JSON
report last (it records the seconds of the other outputs too). Every problem with the config
raises :class:`~shellmesh_mdao.config.ConfigError` (a
:class:`~shellmesh_mdao.errors.ShellMeshError`) before anything is meshed or written.

The small helpers the command line shares with it are public here: :func:`status` (a spinner
on a terminal), :func:`jsonable` (``json.dumps`` default for numpy values) and
:func:`display_path` / :func:`relative_path` (paths as a user reads them).
"""
from __future__ import annotations

import json
import logging
import os
import sys
import time
from contextlib import contextmanager
from pathlib import Path

__all__ = ["run_study", "check_study", "status", "jsonable", "display_path", "relative_path"]

log = logging.getLogger("shellmesh_mdao")


@contextmanager
def status(message: str, quiet: bool):
    """A spinner on stderr while a long step runs (terminals only, not with ``quiet``)."""
    spinner = None
    if not quiet and sys.stderr.isatty():
        try:
            from rich.console import Console

            spinner = Console(stderr=True).status(message)
            spinner.start()
        except Exception:  # rich missing or no terminal: no spinner
            spinner = None
    try:
        yield
    finally:
        if spinner is not None:
            spinner.stop()


def jsonable(o):
    """``default`` for :func:`json.dumps`: numpy scalars and arrays as Python values, anything
    else as its text."""
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def display_path(p) -> str:
    """A path as the user will recognise it: relative to the current folder when inside it."""
    p = Path(p)
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(p)


def relative_path(p, folder: Path) -> str:
    """``p`` relative to ``folder`` (POSIX separators, for links in a report), or ``p`` itself
    when there is no relative path (another drive)."""
    try:
        return Path(os.path.relpath(Path(p).resolve(), folder)).as_posix()
    except ValueError:
        return str(p)


def check_study(cfg, where: str = "run_study") -> None:
    """Fail before meshing when the study cannot run or write its outputs: no surface, layout
    or size, nothing to write, an output path that cannot be written or has an unknown
    extension, an unknown material, a thickness naming no component of the layout. ``where``
    names the caller in the messages (``shellmesh mesh``). Raises
    :class:`~shellmesh_mdao.config.ConfigError` (or the export's
    :class:`~shellmesh_mdao.errors.OutputError` for an output path)."""
    from .config import REPORT_FORMATS, ConfigError
    from .export import check_output_path

    src = f" or '{{key}}:' in {display_path(cfg.source)}" if cfg.source is not None else " or use --config FILE"
    if cfg.surface is None:
        raise ConfigError(f"{where}: no surface given; give SURFACE on the command line"
                          + src.format(key="surface"))
    if cfg.layout is None:
        raise ConfigError(f"{where}: no layout given; give --layout FILE (.json/.yaml, see docs/layout.md)"
                          + src.format(key="layout"))
    if cfg.size is None:
        raise ConfigError(f"{where}: no size given; give --size H (target quad edge length)"
                          + src.format(key="size"))
    if not cfg.out and cfg.report is None and cfg.html is None:
        raise ConfigError(f"{where}: nothing to write; give --out MESH (.vtu .bdf .inp .msh), --report "
                          "REPORT.json and/or --html REPORT.html" + src.format(key="out"))
    for o in cfg.out:
        check_output_path(o)
    if cfg.report is not None:
        check_output_path(cfg.report, formats={".json": "report"})
    if cfg.html is not None:
        check_output_path(cfg.html, formats=REPORT_FORMATS)
    if cfg.material is not None:
        from .export import resolve_material

        resolve_material(cfg.material)
    if isinstance(cfg.thickness, dict):
        from .config import check_thickness_names

        check_thickness_names(cfg.thickness, cfg.layout, cfg.source)


def run_study(cfg, quiet: bool = False, *, where: str = "run_study"):
    """Run the pipeline of a study and write its outputs: meshes, then the human report
    (pictures), then the JSON report last (it records the seconds of the outputs too).

    ``cfg`` is a :class:`~shellmesh_mdao.config.StudyConfig` or the path of a study config file
    (``.yaml``/``.json``, read with :func:`~shellmesh_mdao.config.load_config`); it is checked
    first (:func:`check_study`). ``quiet`` turns off the stage progress and the spinners.
    Returns ``(result, written)``: the :class:`~shellmesh_mdao.pipeline.PipelineResult` (its
    ``report`` is the JSON report's content) and the paths written, in order."""
    from .config import StudyConfig, load_config, thickness_by_component
    from .export import write_mesh, write_text_atomic
    from .pipeline import STAGES, run_pipeline
    from .quality import element_quality, quality_summary
    from .report import report_data, write_report

    if not isinstance(cfg, StudyConfig):
        cfg = load_config(cfg)
    check_study(cfg, where)
    until = cfg.until or STAGES[-1]
    result = run_pipeline(str(cfg.surface), cfg.layout if isinstance(cfg.layout, dict) else str(cfg.layout),
                          cfg.size, until=until, progress=not quiet, options=cfg.solver or None)
    mesh = result.mesh
    rep = result.report
    if cfg.source is not None:
        rep["inputs"]["config"] = str(cfg.source)
    if cfg.solver:
        rep["inputs"]["solver"] = dict(cfg.solver)
    out_seconds: dict = {}
    t0 = time.perf_counter()
    q = element_quality(mesh.points, mesh.faces)
    rep["quality"] = quality_summary(mesh, by_component=True)
    thickness = thickness_by_component(cfg.thickness, mesh.component_names)
    written = []
    with status("writing the mesh ...", quiet):
        for o in cfg.out:
            write_mesh(mesh, o, thickness=thickness, material=cfg.material,
                       quality=q if Path(o).suffix.lower() == ".vtu" else None)
            log.info("wrote %s (%d nodes, %d elements)", display_path(o), mesh.n_points, mesh.n_faces)
            written.append(Path(o))
    out_seconds["export"] = round(time.perf_counter() - t0, 4)
    data = report_data(result, metrics=q)
    rep["families"] = data["families"]
    rep["worst_elements"] = data["worst_elements"]
    if cfg.html is not None:
        t1 = time.perf_counter()
        html_dir = Path(cfg.html).resolve().parent
        links = [(Path(p).name, relative_path(p, html_dir)) for p in written]
        if cfg.report is not None:
            links.append((Path(cfg.report).name, relative_path(cfg.report, html_dir)))
        with status("drawing pictures and writing the report ...", quiet):
            write_report(result, cfg.html, pictures=cfg.pictures, links=links, data=data)
        out_seconds["report"] = round(time.perf_counter() - t1, 4)
        written.append(Path(cfg.html))
    rep["output_seconds"] = out_seconds
    rep["outputs"] = [str(p) for p in written] + ([str(cfg.report)] if cfg.report is not None else [])
    if cfg.report is not None:
        write_text_atomic(cfg.report, json.dumps(rep, indent=2, default=jsonable))
        log.info("wrote %s", display_path(cfg.report))
        written.append(Path(cfg.report))
    return result, written
