"""Benchmark the pipeline on the corpus against Gmsh's all-quad remesh of the bare skin; write docs/benchmarks.md.

    python run_scripts/benchmark.py                       # whole benchmark (~15-25 min on 2 busy cores)
    python run_scripts/benchmark.py --quick               # two small cases, no 1M-triangle run (~2 min)
    python run_scripts/benchmark.py --only bwb            # one corpus geometry
    python run_scripts/benchmark.py --no-memory           # skip the 1M-triangle peak-memory run
    python run_scripts/benchmark.py --only bwb --perturb 3   # bwb, then 3 perturbed copies of its input
    python run_scripts/benchmark.py --only cessna210 --no-memory --perf-pairs 9   # the speed target, 9 pairs
    python run_scripts/benchmark.py --from-json docs/benchmarks.json   # re-render the page only

The harness is the package's :mod:`shellmesh_mdao.benchmarks` (what each case runs and measures:
the docstring of ``shellmesh_mdao/benchmarks/corpus.py``); this script parses the options, runs
it and writes ``docs/benchmarks.md`` (a hand-kept part below the page's marker line is carried
over) and ``docs/benchmarks.json`` (every raw figure). ``--quick`` and ``--only`` runs print the
page instead of overwriting the docs unless ``--out`` is given. Gmsh is needed (the ``test`` or
``cad`` extra: ``pip install -e ".[test]"``).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from shellmesh_mdao.benchmarks.corpus import PERF_PAIRS, import_gmsh, log, run_benchmark
from shellmesh_mdao.benchmarks.page import kept_part, render_page, write_outputs

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--geometry-dir", default=str(REPO.parent / "shared" / "geometry"),
                    help="benchmark corpus folder with manifest.json (default ../shared/geometry beside the repo)")
    ap.add_argument("--quick", action="store_true", help="two small cases only (no performance / memory case)")
    ap.add_argument("--only", metavar="NAME", help="one corpus geometry (e.g. bwb)")
    ap.add_argument("--no-perf", action="store_true", help="skip the performance-target case")
    ap.add_argument("--no-memory", action="store_true", help="skip the 1M-triangle memory case")
    ap.add_argument("--out", help="page to write (default docs/benchmarks.md for a full run; --quick/--only "
                                  "print the page unless --out is given); the JSON goes beside it")
    ap.add_argument("--work-dir", help="folder for the refined 1M-triangle STL (default: temporary directory)")
    ap.add_argument("--timeout", type=float, default=3600.0, help="time limit per pipeline case (s)")
    ap.add_argument("--gmsh-timeout", type=float, default=1800.0, help="time limit per Gmsh case (s)")
    ap.add_argument("--perturb", type=int, default=None, metavar="K",
                    help="run every corpus case and the performance case again on K perturbed copies of its input "
                         "(coordinates x (1 + 1e-10 g)); default 3 for a full run, 0 for --quick / --only")
    ap.add_argument("--perf-pairs", type=int, default=PERF_PAIRS, metavar="N",
                    help=f"side-by-side pairs (Gmsh, then the pipeline) of the performance case; the verdict is on "
                         f"the median of their time ratios (default {PERF_PAIRS})")
    ap.add_argument("--from-json", metavar="JSON", help="re-render the page from the raw figures of an earlier run "
                                                         "(written beside it; nothing is run)")
    args = ap.parse_args(argv)
    if args.from_json:
        res = json.loads(Path(args.from_json).read_text())
        out = Path(args.out) if args.out else Path(args.from_json).with_suffix(".md")
        out.write_text(render_page(res, kept_part(out)))
        log(f"wrote {out}")
        return 0
    if args.perf_pairs < 1:
        ap.error(f"--perf-pairs needs at least 1, got {args.perf_pairs}")
    gdir = Path(args.geometry_dir)
    if not (gdir / "manifest.json").is_file():
        ap.error(f"no manifest.json in {gdir}: pass --geometry-dir (the benchmark corpus folder)")
    known = json.loads((gdir / "manifest.json").read_text())["geometries"]
    if args.only is not None and args.only not in known:
        ap.error(f"--only {args.only!r}: no such geometry in {gdir / 'manifest.json'} (known: {', '.join(known)})")
    try:
        import_gmsh()
    except ImportError as exc:
        ap.error(str(exc))
    res = run_benchmark(gdir, only=args.only, quick=args.quick, perf=not args.no_perf, memory=not args.no_memory,
                        work_dir=args.work_dir, timeout=args.timeout, gmsh_timeout=args.gmsh_timeout,
                        perturb=(0 if (args.quick or args.only) else 3) if args.perturb is None else args.perturb,
                        pairs=args.perf_pairs)
    out = args.out or (None if (args.quick or args.only) else REPO / "docs" / "benchmarks.md")
    if out is None:
        print(render_page(res))
    else:
        md, js = write_outputs(res, out)
        log(f"wrote {md} and {js}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
