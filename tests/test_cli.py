"""The shellmesh command line: outputs, JSON keys and the exit-code contract (0 ok, 2 user error)."""
import json
import subprocess
import sys

import numpy as np
import pytest

from shellmesh_mdao.cli import main
from shellmesh_mdao.export import write_mesh
from shellmesh_mdao.geometry import naca_wing
from shellmesh_mdao.mesh import ShellMesh


def run(args, capsys):
    rc = main(args)
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_info_cessna_reports_counts_and_closed(geometry_dir, capsys):
    rc, out, err = run(["info", str(geometry_dir / "cessna210.stl"), "--json"], capsys)
    assert rc == 0, err
    d = json.loads(out)
    assert d["n_triangles"] == 23536
    assert d["closed"] is True and d["n_open_boundary_edges"] == 0 and d["n_nonmanifold_edges"] == 0
    assert d["n_bodies"] == 1
    rc, out, err = run(["info", str(geometry_dir / "cessna210.stl")], capsys)
    assert rc == 0 and "23536 triangles" in out and "closed" in out


def test_quality_json_keys(tmp_path, capsys):
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    m = ShellMesh(p, [[0, 1, 2, 3], [1, 4, 2, -1]], [0, 1], ["skin", "rib"])
    f = write_mesh(m, tmp_path / "m.vtu")
    rc, out, err = run(["quality", str(f), "--json"], capsys)
    assert rc == 0, err
    d = json.loads(out)
    assert d["n_quads"] == 1 and d["n_tris"] == 1
    for k in ("aspect", "min_angle", "max_angle", "skew", "warp", "taper", "scaled_jacobian"):
        assert set(d[k]) >= {"min", "p1", "mean", "median", "max"}, k
    # unit square: 1; right isosceles triangle: min corner 45 deg -> sin(45)*2/sqrt(3)
    assert d["scaled_jacobian"]["min"] == pytest.approx(np.sin(np.pi / 4) * 2 / np.sqrt(3))
    assert d["scaled_jacobian"]["max"] == pytest.approx(1.0)
    rc, out, err = run(["quality", str(f), "--by-component"], capsys)
    assert rc == 0 and "rib" in out and "skin" in out


def _file(name, data):
    def make(d):
        p = d / name
        (p.write_bytes if isinstance(data, bytes) else p.write_text)(data)
        return p
    return make


@pytest.mark.parametrize("make,needle", [
    (lambda d: d / "missing.stl", "not found"),
    (_file("x.xyz", "1 2 3"), ".xyz"),
    (_file("garbage.stl", b"\x00\xff" * 50), "garbage.stl"),
    (_file("empty.obj", ""), "empty.obj"),
    (lambda d: d, "folder"),
])
def test_info_user_errors_exit_2_one_line(tmp_path, capsys, make, needle):
    rc, out, err = run(["info", str(make(tmp_path))], capsys)
    assert rc == 2
    assert err.startswith("error: ") and needle.lower() in err.lower()
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_bad_options_exit_2(capsys):
    for args in (["frobnicate"], ["quality"], ["info", "--bogus", "x.stl"], []):
        rc, out, err = run(args, capsys)
        assert rc == 2, args
        assert "Traceback" not in err


def test_console_script_exit_code(tmp_path):
    """The installed module entry point behaves like main(): exit code 2 and one line on stderr."""
    r = subprocess.run([sys.executable, "-m", "shellmesh_mdao.cli", "info", str(tmp_path / "nope.stl")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "not found" in r.stderr and "Traceback" not in r.stderr


def test_quality_of_generated_wing_bdf(tmp_path, capsys):
    f = write_mesh(naca_wing(n_chord=12, n_span=6), tmp_path / "w.bdf")
    rc, out, err = run(["quality", str(f), "--json"], capsys)
    d = json.loads(out)
    assert rc == 0 and d["n_quads"] == 0 and d["n_tris"] == naca_wing(n_chord=12, n_span=6).n_faces


@pytest.fixture()
def wing_files(tmp_path):
    from shellmesh_mdao.geometry import naca_wing_layout

    surf = write_mesh(naca_wing(n_chord=24, n_span=16), tmp_path / "wing.vtu")
    lay = tmp_path / "layout.json"
    lay.write_text(json.dumps(naca_wing_layout(ribs=4)))
    return surf, lay


@pytest.mark.parametrize("extra,needle", [
    (["--size", "-1", "--out", "o.vtu"], "positive"),
    (["--size", "abc", "--out", "o.vtu"], "number"),
    (["--size", "100", "--out", "o.vtu"], "too large"),
    (["--size", "0.1", "--out", "/nonexistent_dir/x.vtu"], "does not exist"),
    (["--size", "0.1", "--out", "out.xyz"], "extension"),
    (["--size", "0.1"], "nothing to write"),
    (["--size", "0.1", "--out", "o.vtu", "--until", "bogus"], "invalid choice"),
])
def test_mesh_user_errors(wing_files, tmp_path, capsys, monkeypatch, extra, needle):
    monkeypatch.chdir(tmp_path)
    surf, lay = wing_files
    rc, out, err = run(["mesh", str(surf), "--layout", str(lay)] + extra, capsys)
    assert rc == 2, err
    assert needle in err and "Traceback" not in err
    assert not list(tmp_path.glob("o.vtu")) and not list(tmp_path.glob("out.xyz"))


def test_mesh_bad_layout_writes_nothing(wing_files, tmp_path, capsys):
    surf, lay = wing_files
    d = json.loads(lay.read_text())
    d["wings"][0]["ribs"] = {"eta": [0.0, 0.5, 1.5]}
    lay.write_text(json.dumps(d))
    out = tmp_path / "o.vtu"
    rc, _, err = run(["mesh", str(surf), "--layout", str(lay), "--size", "0.1", "--out", str(out)], capsys)
    assert rc == 2 and "eta" in err
    assert not out.exists() and not list(tmp_path.glob(".o.vtu*"))


def test_mesh_until_members_writes_conforming_mesh_and_report(wing_files, tmp_path, capsys):
    from shellmesh_mdao.load import load_mesh

    surf, lay = wing_files
    out, rep = tmp_path / "m.vtu", tmp_path / "r.json"
    rc, _, err = run(["-q", "mesh", str(surf), "--layout", str(lay), "--size", "0.15", "--out", str(out),
                      "--report", str(rep), "--until", "members"], capsys)
    assert rc == 0, err
    m = load_mesh(out)
    r = json.loads(rep.read_text())
    assert r["stage"] == "members" and set(r["stages"]) >= {"load", "remesh", "imprint", "members"}
    # ribs and spars are in the mesh and share nodes with the skin: junction edges have 3 faces
    names = set(m.component_names[i] for i in np.unique(m.component))
    assert {"wing/rib_0", "wing/spar_0", "wing/spar_1"} <= names
    assert (m.topology().valence == 3).any()
    c = m.check()
    assert len(c.duplicate_points) == 0 and len(c.hanging_nodes) == 0
    assert r["members"]["wing/rib_0"]["elements"] > 0 and r["members"]["wing/rib_0"]["chains"]
