"""Random family of aircraft (issue 41): N random draws of geometry x element size x layout, meshed end to end.

    python run_scripts/random_family.py                      # seeds 0..199, several hours on 2 cores
    python run_scripts/random_family.py -n 20                # seeds 0..19
    python run_scripts/random_family.py --seeds 17 42        # these draws only (reproduce a case)
    python run_scripts/random_family.py --from-json docs/random_family.json   # re-render the page

The draws and their classification (ok / guarantee / refused / crash) are the package's
:mod:`shellmesh_mdao.benchmarks.random_family`; this script runs each case in its own child process
with a time limit and writes docs/random_family.md (rewritten after every case) and
docs/random_family.json (every case's full parameters). Exit code 1 when a case is not ok.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from shellmesh_mdao.benchmarks.random_family import run_case_in_child, write_page

REPO = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("-n", type=int, default=200, help="number of draws: seeds FIRST .. FIRST+N-1")
    ap.add_argument("--first", type=int, default=0, help="first seed")
    ap.add_argument("--seeds", nargs="+", type=int, help="these seeds instead")
    ap.add_argument("--timeout", type=float, default=1800.0, help="time limit per case in seconds")
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "random_family.md", help="page to write")
    ap.add_argument("--from-json", type=Path, help="re-render the page from a JSON written before")
    a = ap.parse_args(argv)
    json_path = a.out.with_suffix(".json")
    if a.from_json:
        data = json.loads(a.from_json.read_text())
        write_page(data["results"], data["meta"], a.out)
        return 0
    seeds = a.seeds if a.seeds else list(range(a.first, a.first + a.n))
    results, t0 = [], time.perf_counter()
    label = " ".join(map(str, seeds)) if a.seeds else f"{seeds[0]}..{seeds[-1]}"
    meta = {"date": time.strftime("%Y-%m-%d"), "seconds": 0.0, "seeds": label}
    for k, seed in enumerate(seeds):
        r = run_case_in_child(seed, timeout=a.timeout)
        results.append(r)
        size = f"size {r['size']:.4g} (chord/{r['divisor']:.1f})" if "size" in r else ""
        print(f"[{k + 1}/{len(seeds)}] seed {seed} {size}: {r['outcome']} {r.get('seconds', '')} s "
              f"{r.get('error', '')[:200]}", flush=True)
        meta["seconds"] = time.perf_counter() - t0
        write_page(results, meta, a.out)
        json_path.write_text(json.dumps({"meta": meta, "results": results}, indent=1) + "\n")
    return 0 if all(r["outcome"] == "ok" for r in results) else 1


if __name__ == "__main__":
    sys.exit(main())
