"""The README's quick start runs as written: every fenced ``bash`` and ``python`` block of its "Quick start"
section, each in a fresh folder (bash through ``bash -e``, with ``shellmesh`` this repository's CLI; python in a
child interpreter), so the front page and the code cannot drift apart."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"


def quick_start_blocks():
    """``(language, code)`` of the fenced bash/python blocks between '## Quick start' and the next '## '."""
    text = README.read_text(encoding="utf-8")
    m = re.search(r"^## Quick start\n(.*?)(?=^## )", text, re.S | re.M)
    assert m, "README.md has no '## Quick start' section"
    return [(lang, code) for lang, code in re.findall(r"^```(bash|python)\n(.*?)^```", m.group(1), re.S | re.M)]


def _env():
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO)] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env["MPLBACKEND"] = "Agg"
    return env


def test_quick_start_has_cli_python_and_openmdao():
    blocks = quick_start_blocks()
    langs = [lang for lang, _ in blocks]
    assert langs.count("bash") >= 1 and langs.count("python") >= 2, langs
    code = "\n".join(c for _, c in blocks)
    assert "shellmesh mesh" in code and "run_pipeline" in code and "ShellMeshGroup" in code


@pytest.mark.parametrize("index", range(len(quick_start_blocks())))
def test_quick_start_block_runs(index, tmp_path):
    lang, code = quick_start_blocks()[index]
    if lang == "bash":
        # `shellmesh` is this checkout's CLI, whatever is installed; the corpus path as the README writes it
        code = code.replace("../shared/geometry/", str(REPO.parent / "shared" / "geometry") + "/")
        script = f'shellmesh() {{ "{sys.executable}" -m shellmesh_mdao.cli "$@"; }}\n' + code
        cmd = ["bash", "-e", "-c", script]
    else:
        cmd = [sys.executable, "-c", code]
    r = subprocess.run(cmd, cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, f"README quick-start block {index} ({lang}) failed:\n{code}\n--- stdout\n" \
                              f"{r.stdout[-3000:]}\n--- stderr\n{r.stderr[-3000:]}"
    if lang == "bash":
        for name in re.findall(r"--out\s+(\S+)|--report\s+(\S+)", code):
            path = tmp_path / next(n for n in name if n)
            assert path.is_file() and path.stat().st_size > 0, path
