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
