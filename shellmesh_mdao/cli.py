"""The ``shellmesh`` command line.

Commands: ``info`` (describe a surface), ``wings`` (its lifting surfaces and a starting
layout given by stations), ``mesh`` (run the pipeline from flags or a study config file), ``demo`` (the bundled default wing end to end), ``render`` (off-screen pictures
of a mesh), ``quality`` (element quality tables, per component, flagged elements) and
``report`` (the HTML/Markdown report of an existing mesh file). The reference is
``docs/cli.md``.

Exit codes: 0 success; 2 user error (bad file, bad option, bad layout or config: one line on
stderr naming the problem and the fix, never a traceback); 1 internal error (a bug: the
message asks for a report). ``-q/--quiet`` keeps warnings and errors only, ``-v/--verbose``
adds debug messages (and the traceback of an internal error); both work before or after
the command name.
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
import traceback
from contextlib import contextmanager
from pathlib import Path

from . import __version__
from .errors import ShellMeshError
from .study import display_path, jsonable, relative_path, run_study, status

__all__ = ["main", "build_parser"]

log = logging.getLogger("shellmesh_mdao")

ISSUE_URL = "the shellmesh_mdao issue tracker"


class _Parser(argparse.ArgumentParser):
    """argparse parser whose usage errors become ShellMeshError (exit 2, one line)."""

    def error(self, message):  # noqa: D401 - argparse API
        raise _UsageError(f"{self.prog}: {message} (see '{self.prog} --help')")


class _UsageError(ShellMeshError):
    pass


# ----------------------------------------------------------------------------- logging, progress
class _StderrHandler(logging.Handler):
    """Writes to whatever ``sys.stderr`` is when a record is emitted (so redirection works)."""

    def emit(self, record):
        try:
            sys.stderr.write(self.format(record) + "\n")
        except Exception:  # pragma: no cover - logging must never raise
            self.handleError(record)


@contextmanager
def _logging(quiet: bool, verbose: bool):
    """The package logger prints to stderr while a command runs: warnings only (quiet), info
    (default) or debug (verbose); its previous state comes back afterwards (main() may be
    called in-process, e.g. by tests)."""
    saved = (log.level, log.propagate)
    h = _StderrHandler()
    h.setFormatter(logging.Formatter("%(message)s"))
    log.addHandler(h)
    log.setLevel(logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO)
    log.propagate = False               # no second copy through a root handler someone configured
    try:
        yield
    finally:
        log.removeHandler(h)
        log.setLevel(saved[0])
        log.propagate = saved[1]


# ----------------------------------------------------------------------------- info, quality
def _cmd_info(args) -> int:
    from .load import load_surface

    mesh, report = load_surface(args.surface)
    if args.json:
        print(json.dumps(report.to_dict(), indent=2))
    else:
        print("\n".join(report.summary_lines()))
    return 0


def _format_components(summary: dict) -> str:
    from .report import component_rows

    head, rows, flags = component_rows(summary)
    table = [head] + rows
    w = [max(len(str(r[i])) for r in table) for i in range(len(head))]
    lines = ["  " + "  ".join(str(c).ljust(w[i]) if i < 2 else str(c).rjust(w[i]) for i, c in enumerate(head))]
    for r, f in zip(rows, flags):
        lines.append(("* " if f else "  ")
                     + "  ".join(str(c).ljust(w[i]) if i < 2 else str(c).rjust(w[i]) for i, c in enumerate(r)))
    n = sum(flags)
    lines.append(f"{n} of {len(rows)} components have elements outside an acceptance range (marked *)")
    return "\n".join(lines)


def _format_flagged(n_flagged: int, rows: list) -> str:
    if not n_flagged:
        return "no element is outside an acceptance range"
    lines = [f"{n_flagged} elements outside an acceptance range; the {len(rows)} with the lowest scaled Jacobian "
             "(element id as in .bdf/.inp/.msh):"]
    for r in rows:
        lines.append(f"  element {r['element_id']:>8}  {r['component']:<28} {r['type']:<4} "
                     f"SJ {r['scaled_jacobian']:.3g}  angles {r['min_angle']:.0f}-{r['max_angle']:.0f}  "
                     f"aspect {r['aspect'] if r['aspect'] is None else round(r['aspect'], 3)}  "
                     f"warp {r['warp']:.3g}  fails: {', '.join(r['failed'])}")
    return "\n".join(lines)


def _cmd_quality(args) -> int:
    from .load import load_mesh
    from .quality import element_quality, format_summary, quality_summary
    from .report import flagged_table

    mesh = load_mesh(args.meshfile)
    summary = quality_summary(mesh, by_component=args.by_component)
    flagged = None
    if args.flagged is not None:
        if args.flagged < 0:
            raise _UsageError(f"--flagged must be a count >= 0, got {args.flagged}")
        flagged = flagged_table(mesh, args.flagged, element_quality(mesh.points, mesh.faces))
    if args.json:
        if flagged is not None:
            summary["flagged_elements"] = flagged[1]
        print(json.dumps(summary, indent=2))
        return 0
    if args.by_component:
        comps = summary.pop("components")
        print(format_summary(summary))
        print()
        print("per component:")
        print(_format_components({**summary, "components": comps}))
    else:
        print(format_summary(summary))
    if flagged is not None:
        print()
        print(_format_flagged(*flagged))
    return 0


# ----------------------------------------------------------------------------- mesh
def _parse_options(items) -> dict:
    """``NAME=VALUE`` solver options from the command line (values read as YAML scalars)."""
    import yaml

    out = {}
    for it in items or []:
        if "=" not in it:
            raise _UsageError(f"--option {it!r}: write NAME=VALUE, e.g. --option merge_time_limit=30")
        k, v = it.split("=", 1)
        try:
            out[k.strip()] = yaml.safe_load(v)
        except yaml.YAMLError:
            out[k.strip()] = v
    return out


def _study_from_args(args):
    """The study config of ``shellmesh mesh``: the --config file (if any) with the flags over it."""
    from .config import load_config, merge_flags, parse_config

    cfg = load_config(args.config) if args.config else None
    cfg = merge_flags(cfg, surface=args.surface, layout=args.layout, size=args.size, out=args.out,
                      report=args.report, html=args.html, until=args.until,
                      pictures=False if args.no_pictures else None)
    opts = _parse_options(args.option)
    if opts:
        checked = parse_config({"solver": opts}, ".", source="--option").solver
        cfg.solver = {**cfg.solver, **checked}
    return cfg


def _print_summary(result):
    r = result.report
    c = r["counts"]
    print(f"stage {r['stage']}: {c['n_points']} nodes, {c['n_faces']} elements "
          f"({c['n_tris']} triangles, {c['n_quads']} quads), {c['n_feature_edges']} chain/feature edges")
    print("seconds per stage: " + ", ".join(f"{k} {v:.2f}" for k, v in r["stages"].items()))
    for name, m in r.get("members", {}).items():
        line = "; ".join(f"{ch['side']} chain {ch['n_vertices']} nodes, length {ch['length']:.4g}"
                         for ch in m.get("chains", []))
        if "elements" in m:
            line += f"; mesh {m['nodes']} nodes, {m['elements']} elements"
        log.debug("  %s: %s", name, line)


def _cmd_mesh(args) -> int:
    cfg = _study_from_args(args)
    result, written = run_study(cfg, args.quiet, where="shellmesh mesh")
    if not args.quiet:
        _print_summary(result)
        print("outputs: " + ", ".join(display_path(p) for p in written))
    return 0


# ----------------------------------------------------------------------------- demo
def _cmd_demo(args) -> int:
    from .config import StudyConfig, write_config
    from .errors import OutputError
    from .export import write_mesh, write_text_atomic
    from .geometry import naca_wing, naca_wing_layout
    from .quality import format_summary

    out_dir = Path(args.out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"cannot create output folder {out_dir}: {e.strerror}; choose another --out-dir") from None
    surface = naca_wing()
    layout = naca_wing_layout()
    stem = "default_wing"
    surf_path = write_mesh(surface, out_dir / f"{stem}_surface.vtu")
    lay_path = write_text_atomic(out_dir / f"{stem}_layout.json", json.dumps(layout, indent=2) + "\n")
    cfg = StudyConfig(surface=surf_path.resolve(), layout=lay_path.resolve(), size=float(args.size),
                      out=[(out_dir / f"{stem}_mesh.vtu").resolve(), (out_dir / f"{stem}_mesh.bdf").resolve()],
                      report=(out_dir / f"{stem}_report.json").resolve(),
                      html=(out_dir / f"{stem}_report.html").resolve(), pictures=not args.no_pictures)
    study = write_config(cfg, out_dir / f"{stem}_study.yaml")
    result, written = run_study(cfg, args.quiet, where="shellmesh demo")
    if not args.quiet:
        _print_summary(result)
        qs = result.report["quality"]
        print(format_summary({k: v for k, v in qs.items() if k != "components"}))
        print(_format_components(qs))
        names = [surf_path, lay_path, study] + written
        print(f"outputs in {display_path(out_dir)}/: " + ", ".join(Path(p).name for p in names))
        print(f"open {display_path(cfg.html)} for the report and pictures; re-run the study with "
              f"'shellmesh mesh --config {display_path(study)}'")
    return 0


# ----------------------------------------------------------------------------- wings
def _cmd_wings(args) -> int:
    """Find the lifting surfaces of a surface and write a starting layout for them."""
    from .export import write_text_atomic
    from .layout.finder import find_wings, starting_layout
    from .load import load_surface
    from .study import display_path, status

    size = None
    if args.size is not None:
        try:
            size = float(args.size)
            if not size > 0 or size != size or size == float("inf"):
                raise ValueError
        except ValueError:
            raise _UsageError(f"--size {args.size!r}: give a positive length (the target quad edge length)") from None
    try:
        spars = [float(v) for v in args.spars.split(",")] if args.spars.strip() else []
    except ValueError:
        raise _UsageError(f"--spars {args.spars!r}: give chord fractions separated by commas, e.g. 0.15,0.65") from None
    if args.ribs < 2:
        raise _UsageError(f"--ribs {args.ribs}: give at least 2 (the root and tip ribs)")
    out = Path(args.out) if args.out else None
    if out is not None and out.suffix.lower() not in (".yaml", ".yml", ".json"):
        raise _UsageError(f"--out {out.name}: a layout is a .yaml, .yml or .json file")
    mesh, _ = load_surface(args.surface)
    with status("finding lifting surfaces ...", args.quiet):
        wings = find_wings(mesh.points, mesh.faces[:, :3], args.axis, size=size)
    layout = starting_layout(wings, ribs=args.ribs, spars=spars, orientation=args.orientation)
    if args.json:
        print(json.dumps({"wings": [{"name": w.name, "root": w.root, "tip": w.tip, "extent": [w.start, w.end],
                                     "root_chord": w.root_chord, "tip_chord": w.tip_chord,
                                     "max_thickness": w.max_thickness, "up": w.up.tolist(),
                                     "near": w.near.tolist(), "mirror": w.mirror} for w in wings],
                          "layout": layout}, indent=2))
    elif not args.quiet:
        print(f"{len(wings)} lifting surface(s) along {args.axis}" + (f", stations fitted to size {size:g}"
                                                                     if size is not None else ""))
        head = ("name", "root", "tip", "extent", "root chord", "tip chord", "max thickness", "mirror")
        rows = [(w.name, f"{w.root:.6g}", f"{w.tip:.6g}", f"{w.start:.4g} .. {w.end:.4g}", f"{w.root_chord:.4g}",
                 f"{w.tip_chord:.4g}", f"{w.max_thickness:.4g}", w.mirror or "-") for w in wings]
        wd = [max(len(str(r[i])) for r in [head] + rows) for i in range(len(head))]
        for r in [head] + rows:
            print("  " + "  ".join(str(c).ljust(wd[i]) for i, c in enumerate(r)))
    if out is not None:
        if out.suffix.lower() == ".json":
            text = json.dumps(layout, indent=2) + "\n"
        else:
            import yaml

            text = ("# starting layout written by 'shellmesh wings' (docs/layout.md, 'Station-given wing');\n"
                    "# edit the ribs, spars and stations, then: shellmesh mesh SURFACE --layout THIS --size H\n"
                    + yaml.safe_dump(layout, sort_keys=False, default_flow_style=None))
        write_text_atomic(out, text)
        if not args.quiet:
            print(f"wrote {display_path(out)}")
    return 0


# ----------------------------------------------------------------------------- render, report
def _window(text: str):
    try:
        w, h = (int(x) for x in text.lower().split("x"))
        if w < 64 or h < 64 or w > 8192 or h > 8192:
            raise ValueError
    except ValueError:
        raise _UsageError(f"--window {text!r}: give WIDTHxHEIGHT in pixels, each 64..8192, e.g. 1600x1000") from None
    return (w, h)


def _vector(text: str):
    try:
        v = [float(x) for x in text.split(",")]
        if len(v) != 3 or not any(v):
            raise ValueError
    except ValueError:
        raise _UsageError(f"--up {text!r}: give three numbers X,Y,Z (not all zero), e.g. 0,0,1") from None
    return v


def _cmd_render(args) -> int:
    from .errors import OutputError
    from .render import load_any, render_mesh, render_views, render_worst, render_worst_closeups

    out = Path(args.out)
    if out.suffix.lower() != ".png":
        raise OutputError(f"cannot write {out.name}: pictures are PNG files; give --out NAME.png")
    win = _window(args.window)
    up = _vector(args.up) if args.up else None
    mesh = load_any(args.meshfile)
    with status("rendering ...", args.quiet):
        if args.view == "all":
            paths = render_views(mesh, out.parent, out.stem, up=up, worst=args.worst, window_size=win)
        elif args.view == "worst":
            paths = [render_worst(mesh, out, args.worst, up=up, window_size=win)]
        elif args.view == "closeups":
            paths = [render_worst_closeups(mesh, out, min(args.worst, 9))]
        else:
            paths = [render_mesh(mesh, out, args.color, args.view, window_size=win, edges=args.edges, up=up)]
    if not args.quiet:
        print("wrote " + ", ".join(display_path(p) for p in paths))
    return 0


def _cmd_report(args) -> int:
    from .config import REPORT_FORMATS
    from .export import check_output_path, write_text_atomic
    from .report import report_data, write_report
    from .render import load_any

    check_output_path(args.html, formats=REPORT_FORMATS)
    if args.json:
        check_output_path(args.json, formats={".json": "report"})
    mesh = load_any(args.meshfile)
    data = report_data(mesh)
    data["inputs"] = {"mesh": str(args.meshfile)}
    with status("drawing pictures and writing the report ...", args.quiet):
        write_report(mesh, args.html, pictures=not args.no_pictures, data=data,
                     links=[(Path(args.meshfile).name, relative_path(args.meshfile, Path(args.html).resolve().parent))])
    if args.json:
        write_text_atomic(args.json, json.dumps(data, indent=2, default=jsonable))
    if not args.quiet:
        print(f"wrote {display_path(args.html)}" + (f", {display_path(args.json)}" if args.json else ""))
    return 0


# ----------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    from .pipeline import STAGES
    from .render import COLOR_OPTIONS

    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                        help="only warnings and errors")
    common.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                        help="debug messages, and the traceback of an internal error")

    p = _Parser(prog="shellmesh", description="Conforming all-quad shell meshes of aircraft skins and "
                                              "internal members (ribs, spars). Reference: docs/cli.md.")
    p.add_argument("--version", action="version", version=f"shellmesh_mdao {__version__}")
    p.add_argument("-q", "--quiet", action="store_true", help="only warnings and errors")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="debug messages, and the traceback of an internal error")
    sub = p.add_subparsers(dest="command", parser_class=_Parser, metavar="COMMAND")

    pi = sub.add_parser("info", parents=[common], help="describe a surface triangulation: counts, bounding box, "
                                                       "closed, open/non-manifold edges, bodies")
    pi.add_argument("surface", help="surface file (.stl .obj .ply .off .vtk .vtp .vtu .msh .bdf .nas .inp .step .iges)")
    pi.add_argument("--json", action="store_true", help="print one JSON object")
    pi.set_defaults(func=_cmd_info)

    pq = sub.add_parser("quality", parents=[common],
                        help="element quality summary of a mesh file (.vtu .msh .bdf .nas .inp)")
    pq.add_argument("meshfile")
    pq.add_argument("--json", action="store_true", help="print one JSON object")
    pq.add_argument("--by-component", action="store_true",
                    help="one row per component too, components with elements outside an acceptance range "
                         "marked *")
    pq.add_argument("--flagged", type=int, nargs="?", const=20, default=None, metavar="N",
                    help="list the elements outside an acceptance range (the N, default 20, with the lowest "
                         "scaled Jacobian)")
    pq.set_defaults(func=_cmd_quality)

    from .config import solver_options

    pm = sub.add_parser("mesh", parents=[common],
                        help="mesh a surface with its member layout (stages: " + " -> ".join(STAGES) + ")",
                        description="Mesh a surface with its member layout. Inputs come from flags or from a "
                                    "study config file (--config); a flag given on the command line overrides "
                                    "the config value. See docs/cli.md.")
    pm.add_argument("surface", nargs="?", help="surface triangulation (.stl .obj .ply .off .vtk .vtu .msh .bdf "
                                               ".step ...); or 'surface:' in the config")
    pm.add_argument("--config", help="study config file (.yaml or .json) naming surface, layout, size, outputs "
                                     "and solver options; see docs/cli.md")
    pm.add_argument("--layout", help="member layout file (.json or .yaml); see docs/layout.md")
    pm.add_argument("--size", help="target edge length of the final quads (surface units)")
    pm.add_argument("--out", action="append", metavar="MESH",
                    help="mesh file to write; the extension picks the format (.vtu .bdf .nas .inp .msh); "
                         "repeat for several")
    pm.add_argument("--report", help="JSON report to write (inputs, seconds per stage, components, counts, "
                                     "chains, quality, worst elements)")
    pm.add_argument("--html", metavar="REPORT", help="human report to write (.html, or .md for markdown) with "
                                                     "tables, histograms and pictures next to it")
    pm.add_argument("--no-pictures", action="store_true", help="no rendered pictures in the human report")
    pm.add_argument("--until", choices=STAGES, default=None,
                    help=f"stop after this stage (default: {STAGES[-1]}, the last stage)")
    pm.add_argument("--option", action="append", metavar="NAME=VALUE",
                    help="solver option (repeatable); names: " + ", ".join(solver_options()))
    pm.set_defaults(func=_cmd_mesh)

    pd = sub.add_parser("demo", parents=[common],
                        help="run the main job on the bundled default wing and write its mesh, pictures "
                             "and report")
    pd.add_argument("--out-dir", default=".", help="folder for the outputs (created if missing; default: .)")
    pd.add_argument("--size", default=0.1, type=float, help="target quad edge length in metres (default 0.1)")
    pd.add_argument("--no-pictures", action="store_true", help="no rendered pictures in the report")
    pd.set_defaults(func=_cmd_demo)

    pw = sub.add_parser("wings", parents=[common],
                        help="find the lifting surfaces of a surface (station range, chords, thickness) and write "
                             "a starting layout given by stations",
                        description="Slice the surface along the span axis, find its thin elongated sections "
                                    "(wings, tails; a fin with --axis z) and print their station range, root and tip "
                                    "chord and thickness; --out writes a starting layout (docs/layout.md, "
                                    "'Station-given wing'). See docs/cli.md.")
    pw.add_argument("surface", help="surface file (.stl .obj .ply .vtk .msh .step .iges ...)")
    pw.add_argument("--axis", default="y", help="span axis: x, y or z (default y; z for a fin)")
    pw.add_argument("--size", help="element size the layout is for: the stations keep the ribs and spars meshable "
                                   "at it (default: a hundredth of each surface's span)")
    pw.add_argument("--out", help="starting layout to write (.yaml or .json)")
    pw.add_argument("--ribs", type=int, default=10, help="ribs per wing in the starting layout (default 10)")
    pw.add_argument("--spars", default="0.15,0.65", help="spar chord fractions (default 0.15,0.65)")
    pw.add_argument("--orientation", default="normal_to_spar",
                    choices=("normal_to_spar", "streamwise", "normal_to_midchord"),
                    help="rib orientation in the starting layout (default normal_to_spar)")
    pw.add_argument("--json", action="store_true", help="print one JSON object (the surfaces and the layout)")
    pw.set_defaults(func=_cmd_wings)

    pr = sub.add_parser("render", parents=[common], help="draw a mesh off-screen into a PNG")
    pr.add_argument("meshfile", help="mesh file (.vtu .msh .bdf .nas .inp) or surface file (.stl .obj ...)")
    pr.add_argument("--out", required=True, help="PNG to write (with --view all: the stem of the PNGs)")
    pr.add_argument("--color", choices=COLOR_OPTIONS, default="component",
                    help="colour by component family (legend) or by a quality metric (colour bar)")
    pr.add_argument("--view", choices=("iso", "top", "wingbox", "worst", "closeups", "all"), default="iso",
                    help="iso (default), top, wingbox (upper skin hidden), worst (worst elements on the model), "
                         "closeups (each worst element), all (every view: <stem>_iso.png, ...)")
    pr.add_argument("--window", default="1600x1000", help="picture size WIDTHxHEIGHT (default 1600x1000)")
    pr.add_argument("--worst", type=int, default=10, help="number of worst elements to mark (default 10)")
    pr.add_argument("--up", help="the model's up direction X,Y,Z (default: the axis of smallest extent)")
    pr.add_argument("--edges", action=argparse.BooleanOptionalAction, default=None,
                    help="draw element edges (default: when elements are large enough on screen)")
    pr.set_defaults(func=_cmd_render)

    pp = sub.add_parser("report", parents=[common], help="write the HTML/Markdown quality report of a mesh file")
    pp.add_argument("meshfile", help="mesh file (.vtu .msh .bdf .nas .inp)")
    pp.add_argument("--html", required=True, metavar="REPORT", help="report to write (.html, or .md)")
    pp.add_argument("--json", help="also write the report data as JSON")
    pp.add_argument("--no-pictures", action="store_true", help="tables and histograms only")
    pp.set_defaults(func=_cmd_report)
    return p


def main(argv=None) -> int:
    """Run the command line; returns the exit code (0 ok, 2 user error, 1 internal error)."""
    verbose = "-v" in (argv if argv is not None else sys.argv[1:]) or "--verbose" in (
        argv if argv is not None else sys.argv[1:])
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
    except ShellMeshError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except Exception as e:  # a bug while building the parser
        return _internal_error(e, verbose)
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return 2
    try:
        with _logging(args.quiet, args.verbose):
            return int(args.func(args) or 0)
    except ShellMeshError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # a bug: say so, ask for a report
        return _internal_error(e, args.verbose)


def _internal_error(e: Exception, verbose: bool) -> int:
    if verbose:
        traceback.print_exc()
    print(f"internal error: {type(e).__name__}: {e}\nThis is a bug in shellmesh_mdao "
          f"{__version__}; please report it on {ISSUE_URL} with the command line and input files "
          "(run with --verbose for the traceback).", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
