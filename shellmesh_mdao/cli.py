"""The ``shellmesh`` command line.

Exit codes: 0 success; 2 user error (bad file, bad option, bad layout: one line on
stderr naming the problem and the fix, never a traceback); 1 internal error (a bug:
the message asks for a report).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import traceback

from . import __version__
from .errors import ShellMeshError

log = logging.getLogger("shellmesh_mdao")

ISSUE_URL = "the shellmesh_mdao issue tracker"


class _Parser(argparse.ArgumentParser):
    """argparse parser whose usage errors become ShellMeshError (exit 2, one line)."""

    def error(self, message):  # noqa: D401 - argparse API
        raise _UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


class _UsageError(ShellMeshError):
    pass


def _cmd_info(args) -> int:
    from .load import load_surface

    mesh, report = load_surface(args.surface)
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
    else:
        print("\n".join(report.summary_lines()))
    return 0


def _cmd_quality(args) -> int:
    from .load import load_mesh
    from .quality import format_summary, quality_summary

    mesh = load_mesh(args.meshfile)
    summary = quality_summary(mesh, by_component=args.by_component)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
    return 0


def _write_outputs(result, out, report_path):
    """Write the mesh and the JSON report (both atomic)."""
    from .export import write_mesh, write_text_atomic
    from .quality import quality_summary

    if out is not None:
        q = quality_summary(result.mesh, by_component=True)
        result.report["quality"] = q
        write_mesh(result.mesh, out)
        log.info("wrote %s (%d nodes, %d elements)", out, result.mesh.n_points, result.mesh.n_faces)
    if report_path is not None:
        write_text_atomic(report_path, json.dumps(result.report, indent=2, default=_jsonable))
        log.info("wrote %s", report_path)


def _jsonable(o):
    import numpy as np

    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _print_summary(result):
    r = result.report
    c = r["counts"]
    print(f"stage {r['stage']}: {c['n_points']} nodes, {c['n_faces']} elements "
          f"({c['n_tris']} triangles, {c['n_quads']} quads), {c['n_feature_edges']} chain/feature edges")
    print("seconds per stage: " + ", ".join(f"{k} {v:.2f}" for k, v in r["stages"].items()))
    for name, m in r.get("members", {}).items():
        line = "; ".join(f"{ch['side']} chain {ch['n_vertices']} nodes, length {ch['length']:.4g}" for ch in m["chains"])
        if "elements" in m:
            line += f"; mesh {m['nodes']} nodes, {m['elements']} elements"
        print(f"  {name}: {line}")


def _cmd_mesh(args) -> int:
    from .export import check_output_path
    from .pipeline import run_pipeline

    if args.out is None and args.report is None:
        raise _UsageError("shellmesh mesh: nothing to write; give --out MESH (.vtu .bdf .inp .msh) and/or "
                          "--report REPORT.json")
    if args.out is not None:
        check_output_path(args.out)
    if args.report is not None:
        check_output_path(args.report, formats={".json": "report"})
    result = run_pipeline(args.surface, args.layout, args.size, until=args.until, progress=not args.quiet)
    _write_outputs(result, args.out, args.report)
    if not args.quiet:
        _print_summary(result)
    return 0


def _cmd_demo(args) -> int:
    from pathlib import Path

    from .export import write_mesh
    from .geometry import naca_wing, naca_wing_layout
    from .pipeline import STAGES, run_pipeline
    from .quality import format_summary, quality_summary

    out_dir = Path(args.out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        from .errors import OutputError
        raise OutputError(f"cannot create output folder {out_dir}: {e.strerror}; choose another --out-dir") from None
    surface = naca_wing()
    layout = naca_wing_layout()
    write_mesh(surface, out_dir / "default_wing_surface.vtu")
    result = run_pipeline(surface, layout, args.size, until=STAGES[-1], progress=not args.quiet)
    result.report["inputs"]["surface"] = "bundled default wing (shellmesh_mdao.geometry.naca_wing)"
    _write_outputs(result, out_dir / "default_wing_mesh.vtu", out_dir / "default_wing_report.json")
    write_mesh(result.mesh, out_dir / "default_wing_mesh.bdf")
    _print_summary(result)
    print(format_summary(quality_summary(result.mesh)))     # per family: see the JSON report
    print(f"outputs in {out_dir}/: default_wing_surface.vtu, default_wing_mesh.vtu, "
          "default_wing_mesh.bdf, default_wing_report.json")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="shellmesh", description="Conforming all-quad shell meshes of aircraft skins and "
                                              "internal members (ribs, spars).")
    p.add_argument("--version", action="version", version=f"shellmesh_mdao {__version__}")
    p.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    p.add_argument("-v", "--verbose", action="store_true", help="debug logging")
    sub = p.add_subparsers(dest="command", parser_class=_Parser, metavar="COMMAND")

    pi = sub.add_parser("info", help="describe a surface triangulation: counts, bounding box, closed, "
                                     "open/non-manifold edges, bodies")
    pi.add_argument("surface", help="surface file (.stl .obj .ply .off .vtk .vtp .vtu .msh .bdf .nas .inp .step .iges)")
    pi.add_argument("--json", action="store_true", help="print one JSON object")
    pi.set_defaults(func=_cmd_info)

    pq = sub.add_parser("quality", help="element quality summary of a mesh file (.vtu .msh .bdf .nas .inp)")
    pq.add_argument("meshfile")
    pq.add_argument("--json", action="store_true", help="print one JSON object")
    pq.add_argument("--by-component", action="store_true", help="one summary per component family too")
    pq.set_defaults(func=_cmd_quality)

    from .pipeline import STAGES

    pm = sub.add_parser("mesh", help="mesh a surface with its member layout (stages: " + " -> ".join(STAGES) + ")")
    pm.add_argument("surface", help="surface triangulation (.stl .obj .ply .off .vtk .vtu .msh .bdf .step ...)")
    pm.add_argument("--layout", required=True, help="member layout file (.json or .yaml); see docs/layout.md")
    pm.add_argument("--size", required=True, help="target edge length of the final quads (surface units)")
    pm.add_argument("--out", help="mesh file to write; the extension picks the format (.vtu .bdf .inp .msh)")
    pm.add_argument("--report", help="JSON report to write (inputs, seconds per stage, components, counts, "
                                     "chains, quality)")
    pm.add_argument("--until", choices=STAGES, default=STAGES[-1],
                    help=f"stop after this stage (default: {STAGES[-1]}, the last stage implemented)")
    pm.set_defaults(func=_cmd_mesh)

    pd = sub.add_parser("demo", help="run the main job on the bundled default wing and write its outputs")
    pd.add_argument("--out-dir", default=".", help="folder for the outputs (created if missing; default: .)")
    pd.add_argument("--size", default=0.1, help="target quad edge length in metres (default 0.1)")
    pd.set_defaults(func=_cmd_demo)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except ShellMeshError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.DEBUG if args.verbose else logging.INFO,
                        format="%(message)s", stream=sys.stderr)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except ShellMeshError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # a bug: say so, ask for a report
        if args.verbose:
            traceback.print_exc()
        print(f"internal error: {type(e).__name__}: {e}\nThis is a bug in shellmesh_mdao "
              f"{__version__}; please report it on {ISSUE_URL} with the command line and input files "
              "(run with --verbose for the traceback).", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
