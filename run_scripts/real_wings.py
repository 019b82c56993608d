"""Real wings (issue 40): every corpus geometry meshed from the layout 'shellmesh wings' writes.

    python run_scripts/real_wings.py                       # the whole matrix, about an hour
    python run_scripts/real_wings.py --only bwb cessna210 --divisors 40
    python run_scripts/real_wings.py --from-json docs/real_wings.json   # re-render the page

(``--from-json`` also renders the list of lines ``meta.findings`` of the JSON as a "Findings" section.)

The matrix and its classification (ok / guarantee / refused / crash) are the package's
:mod:`shellmesh_mdao.benchmarks.real_wings`; this script runs each case in its own child process
with a time limit and writes docs/real_wings.md (rewritten after every case) and
docs/real_wings.json. Exit code 1 when a case is not ok.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from shellmesh_mdao.benchmarks.real_wings import (DIVISORS, LAYOUTS, ORIENTATIONS, matrix_cases, run_case_in_child,
                                                  write_page)

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--geometry-dir", type=Path, default=REPO.parent / "shared" / "geometry",
                    help="corpus folder with manifest.json (default ../shared/geometry beside the repo)")
    ap.add_argument("--only", nargs="+", help="these geometries only")
    ap.add_argument("--divisors", nargs="+", type=int, default=list(DIVISORS), help="size = semi-span / divisor")
    ap.add_argument("--orientations", nargs="+", default=list(ORIENTATIONS), choices=ORIENTATIONS)
    ap.add_argument("--timeout", type=float, default=1800.0, help="time limit per case in seconds")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "real_wings.md", help="page to write")
    ap.add_argument("--from-json", type=Path, help="re-render the page from a JSON written before")
    a = ap.parse_args(argv)
    json_path = a.out.with_suffix(".json")
    if a.from_json:
        data = json.loads(a.from_json.read_text())
        write_page(data["results"], data["meta"], a.out)
        return 0
    manifest = json.loads((a.geometry_dir / "manifest.json").read_text())
    cases = matrix_cases(manifest, a.only, list(LAYOUTS), a.orientations, a.divisors)
    results, t0 = [], time.perf_counter()
    meta = {"date": time.strftime("%Y-%m-%d"), "seconds": 0.0}
    for k, (g, lay, o, d) in enumerate(cases):
        r = run_case_in_child(a.geometry_dir, g, lay, o, d, timeout=a.timeout)
        results.append(r)
        print(f"[{k + 1}/{len(cases)}] {g} | {lay} | {o} | /{d}: {r['outcome']} {r.get('error', '')[:160]}",
              flush=True)
        meta["seconds"] = time.perf_counter() - t0
        write_page(results, meta, a.out)
        json_path.write_text(json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    return 0 if all(r["outcome"] == "ok" for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
