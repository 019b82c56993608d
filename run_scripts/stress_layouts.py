"""Property sweep: random valid layouts on every corpus geometry, end to end (issue 8, section 1).

    python run_scripts/stress_layouts.py --cases 24 --seed 0            # 6 per geometry, ~10-20 min
    python run_scripts/stress_layouts.py --cases 8 --only bwb --timeout 300
    python run_scripts/stress_layouts.py --from-json docs/stress_layouts.json   # re-render the page

(``--from-json`` also renders the list of lines ``meta.notes`` of the JSON as a "Findings" section.)

The sweep is the package's :mod:`shellmesh_mdao.benchmarks.stress` (how cases are drawn and
classified ok / invalid layout / FAIL: its docstring); this script parses the options, runs each
case in its own child process with a time limit and writes docs/stress_layouts.md (a table,
rewritten after every case) and docs/stress_layouts.json. Exit code 1 when a case FAILs.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

from shellmesh_mdao.benchmarks.stress import (GEOMETRIES, SIZE_FACTORS, reclassify, run_case_in_child, sweep_cases,
                                              write_page)

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=24, help="number of cases (default 24: 6 per geometry)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the first case (case i uses seed+i)")
    ap.add_argument("--only", choices=GEOMETRIES, help="one geometry only")
    ap.add_argument("--timeout", type=float, default=600.0, help="time limit per case in seconds")
    ap.add_argument("--geometry-dir", type=Path, default=REPO.parent / "shared" / "geometry",
                    help="corpus folder with manifest.json (default ../shared/geometry beside the repo)")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "stress_layouts.md", help="page to write")
    ap.add_argument("--from-json", type=Path, help="re-render the page from a JSON written before")
    a = ap.parse_args(argv)
    if a.from_json:
        d = json.loads(a.from_json.read_text())
        write_page([reclassify(r) for r in d["cases"]], d["meta"], a.out)
        return 0
    if not (a.geometry_dir / "manifest.json").is_file():
        ap.error(f"no manifest.json in {a.geometry_dir}: pass --geometry-dir (the corpus folder)")
    meta = {"argv": " ".join(sys.argv[1:] if argv is None else argv), "timeout": a.timeout,
            "size_factors": list(SIZE_FACTORS), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "machine": f"{os.cpu_count()} cores, Python {platform.python_version()}"}
    results = []
    for case in sweep_cases(a.cases, a.seed, a.only, geometry_dir=a.geometry_dir):
        r = run_case_in_child(case, a.timeout, geometry_dir=a.geometry_dir)
        results.append(r)
        print(f"seed {r['seed']:4d} {r['geometry']:14s} ribs {len(r['ribs']):2d} spars {len(r['spars'])} "
              f"size {r['size']:<7g} {r['outcome']:15s} {r.get('seconds') or 0:6.1f} s  {r['reason']} "
              f"{str(r['error'])[:200]}", flush=True)
        write_page(results, meta, a.out)          # after every case: a partial sweep is still a page
    return int(any(r["outcome"] == "FAIL" for r in results))


if __name__ == "__main__":
    sys.exit(main())
