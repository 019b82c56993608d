"""The real-wings matrix (shellmesh_mdao.benchmarks.real_wings, run_scripts/real_wings.py): a sample of
its cases end to end (the layout 'shellmesh wings' writes, meshed, every guarantee checked), the
page and the script's re-rendering."""
import json
import subprocess
import sys
from pathlib import Path

import pytest

from shellmesh_mdao.benchmarks.real_wings import (DIVISORS, LAYOUTS, matrix_cases, run_case, summary_counts, write_page)

REPO = Path(__file__).resolve().parents[1]
GEOMETRY = REPO.parent / "shared" / "geometry"
needs_corpus = pytest.mark.skipif(not (GEOMETRY / "manifest.json").is_file(), reason="corpus not present")
L10, L15, L4 = list(LAYOUTS)


@needs_corpus
@pytest.mark.parametrize("geometry, layout, orientation", [
    ("swept_wing_and_tail", L10, "normal_to_spar"),       # wing halves meeting at the symmetry plane + tail
    ("bwb", L4, "streamwise"),                              # curved, cranked planform; edge webs
    ("f22_half", L15, "normal_to_midchord"),                # a half model, thin wing, a wing-body junction
])
def test_matrix_sample(geometry, layout, orientation):
    r = run_case(GEOMETRY, geometry, layout, orientation, 40)
    assert r["outcome"] == "ok", r
    assert r["min_sj"] > 0.2 and r["n_elements"] > 1000


def test_page_and_counts(tmp_path):
    rows = [dict(geometry="a", layout=L10, orientation="streamwise", divisor=40, outcome="ok"),
            dict(geometry="a", layout=L4, orientation="streamwise", divisor=80, outcome="refused", stage="layout",
                 error="LayoutError: spar 'w/spar_0' | is only 0.01 tall"),
            dict(geometry="b", layout=L15, orientation="normal_to_spar", divisor=40, outcome="crash", error="X",
                 notes=["wing 'w': edge webs"])]
    c = summary_counts(rows)
    assert c["a"] == {"ok": 1, "guarantee": 0, "refused": 1, "crash": 0} and c["total"]["crash"] == 1
    out = tmp_path / "p.md"
    write_page(rows, {"date": "today", "seconds": 1.0}, out)
    text = out.read_text()
    assert "| a | 2 | 1 | 0 | 1 | 0 |" in text and "| **total** | 3 | 1 | 0 | 1 | 1 |" in text
    assert "spar 'w/spar_0' \\| is only" in text and "edge webs" in text
    js = tmp_path / "p.json"
    js.write_text(json.dumps({"meta": {"date": "today", "seconds": 1.0}, "results": rows}))
    again = tmp_path / "q.md"
    subprocess.run([sys.executable, str(REPO / "run_scripts" / "real_wings.py"), "--from-json", str(js), "--out",
                    str(again)], check=True, cwd=REPO)
    assert again.read_text() == text


def test_matrix_cases():
    manifest = {"geometries": {"a": {}, "b": {}}}
    cases = matrix_cases(manifest)
    assert len(cases) == 2 * 3 * 3 * len(DIVISORS) and cases[0] == ("a", L10, "normal_to_spar", DIVISORS[0])
    assert matrix_cases(manifest, only=["b"], divisors=[80])[0] == ("b", L10, "normal_to_spar", 80)
