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


# ----------------------------------------------------------------------------- config files, flags
import re  # noqa: E402
from pathlib import Path  # noqa: E402

import yaml  # noqa: E402

from shellmesh_mdao.config import (ConfigError, StudyConfig, load_config, merge_flags, parse_config,  # noqa: E402
                                   thickness_by_component, write_config)

DOCS = Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def doc_example(name):
    """The YAML block that follows '<!-- example: NAME -->' in docs/cli.md."""
    text = DOCS.read_text()
    m = re.search(r"<!-- example: " + re.escape(name) + r" -->\s*```yaml\n(.*?)```", text, re.S)
    assert m, f"docs/cli.md has no example {name}"
    return yaml.safe_load(m.group(1))


@pytest.fixture()
def study(wing_files, tmp_path):
    """A config in tmp/study/ whose paths are relative to that folder."""
    surf, lay = wing_files
    d = tmp_path / "study"
    d.mkdir()
    cfg = {"surface": "../wing.vtu", "layout": "../layout.json", "size": 0.15, "out": ["m.vtu", "m.bdf"],
           "report": "r.json", "until": "layout"}
    p = d / "study.yaml"
    p.write_text(yaml.safe_dump(cfg))
    return p


def test_config_paths_are_relative_to_the_config_file(study, tmp_path, capsys, monkeypatch):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    rc, out, err = run(["mesh", "--config", str(study)], capsys)
    assert rc == 0, err
    d = study.parent
    assert (d / "m.vtu").is_file() and (d / "m.bdf").is_file() and (d / "r.json").is_file()
    assert not list(elsewhere.iterdir())
    r = json.loads((d / "r.json").read_text())
    assert r["stage"] == "layout" and r["inputs"]["config"] == str(study.resolve())
    assert r["outputs"][-1] == str(d / "r.json") and r["families"] == {
        "skin": {"components": 1, "elements": r["counts"]["n_faces"], "quads": 0, "tris": r["counts"]["n_faces"]}}
    # flags override the config: --out replaces the list, --until the stage; flag paths are cwd-relative
    rc, out, err = run(["mesh", "--config", str(study), "--out", "flag.vtu", "--until", "load", "--report",
                        "flag.json"], capsys)
    assert rc == 0, err
    assert (elsewhere / "flag.vtu").is_file() and json.loads((elsewhere / "flag.json").read_text())["stage"] == "load"


def test_config_run_to_members_with_html_report(study, capsys):
    d = study.parent
    rc, out, err = run(["-q", "mesh", "--config", str(study), "--until", "members", "--html", str(d / "r.html"),
                        "--no-pictures", "--option", "merge_time_limit=5"], capsys)
    assert rc == 0, err
    assert err == ""                                                  # --quiet: no info lines
    html = (d / "r.html").read_text()
    for link in ("m.vtu", "m.bdf", "r.json", "r_histograms.png"):
        assert link in html and (d / link).is_file()
    r = json.loads((d / "r.json").read_text())
    assert r["inputs"]["solver"] == {"merge_time_limit": 5.0}
    assert r["families"]["rib"]["components"] == 4 and r["families"]["spar"]["components"] == 2
    assert len(r["worst_elements"]) == 10 and r["quality"]["components"]
    assert set(r["output_seconds"]) == {"export", "report"}


def test_quiet_and_verbose(study, capsys):
    rc, out, err = run(["mesh", "--config", str(study)], capsys)
    assert rc == 0 and "wrote" in err and "load" in err               # info lines by default
    for args in (["-q", "mesh", "--config", str(study)], ["mesh", "--config", str(study), "--quiet"]):
        rc, out, err = run(args, capsys)
        assert rc == 0 and err == "" and out == "", args


def _cfg_error_cases():
    base = {"surface": "../wing.vtu", "layout": "../layout.json", "size": 0.15, "out": "m.vtu"}
    return [
        ({**base, "sise": 0.1}, ["unknown key 'sise'", "did you mean 'size'"]),
        ({k: v for k, v in base.items() if k != "surface"}, ["no surface", "'surface:'"]),
        ({k: v for k, v in base.items() if k != "size"}, ["no size", "--size"]),
        ({**base, "size": [1, 2]}, ["'size'", "number"]),
        ({**base, "size": "abc"}, ["'size'", "number"]),
        ({**base, "size": -2}, ["'size'", "positive"]),
        ({**base, "out": 3}, ["'out'", "path"]),
        ({**base, "out": ["m.xyz"]}, ["'out[0]'", "extension"]),
        ({**base, "pictures": "yes"}, ["'pictures'", "true or false"]),
        ({**base, "layout": 5}, ["'layout'", "path"]),
        ({**base, "layout": {"wings": [{"name": "w"}]}}, ["'layout'", "missing key"]),
        ({**base, "until": "bogus"}, ["'until'", "quad"]),
        ({**base, "solver": {"merge_time_limit": "abc"}}, ["solver.merge_time_limit", "number"]),
        ({**base, "solver": {"mip_gap": 0.1}}, ["unknown key 'mip_gap'", "merge_mip_gap"]),
        ({**base, "solver": {"remesh": 3}}, ["solver.remesh", "true or false"]),
        ({**base, "thickness": {"ribz": 0.1}}, ["thickness.ribz", "did you mean 'ribs'"]),
        ({**base, "thickness": {"ribs": 0}}, ["thickness.ribs", "positive"]),
        ({**base, "material": {"E": 1e9, "poisson": 0.3}}, ["unknown key 'poisson'"]),
        ([1, 2], ["must be a mapping"]),
    ]


@pytest.mark.parametrize("data,needles", _cfg_error_cases())
def test_config_errors_exit_2_naming_the_key(wing_files, tmp_path, capsys, data, needles):
    d = tmp_path / "study"
    d.mkdir()
    p = d / "study.yaml"
    p.write_text(yaml.safe_dump(data))
    rc, out, err = run(["mesh", "--config", str(p)], capsys)
    assert rc == 2, err
    assert err.startswith("error: ") and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    for n in needles:
        assert n in err, (n, err)
    assert sorted(x.name for x in d.iterdir()) == ["study.yaml"]        # nothing written


@pytest.mark.parametrize("text,name,needle", [
    ("size: [1, 2\n", "s.yaml", "invalid YAML at line"),
    ('{"size": 1,}', "s.json", "invalid JSON at line 1"),
    ("size: 1\n", "s.toml", "extension"),
    (None, "missing.yaml", "config file not found"),
])
def test_config_file_errors(tmp_path, capsys, text, name, needle):
    p = tmp_path / name
    if text is not None:
        p.write_text(text)
    rc, out, err = run(["mesh", "--config", str(p)], capsys)
    assert rc == 2 and needle in err and "Traceback" not in err


def test_option_flag_errors(study, capsys):
    rc, _, err = run(["mesh", "--config", str(study), "--option", "bogus=1"], capsys)
    assert rc == 2 and "--option" in err and "unknown key 'bogus'" in err
    rc, _, err = run(["mesh", "--config", str(study), "--option", "merge_time_limit"], capsys)
    assert rc == 2 and "NAME=VALUE" in err


def test_config_round_trip(tmp_path):
    (tmp_path / "a").mkdir()
    data = {"surface": "geo/wing.stl", "layout": {"up": [0, 0, 1], "wings": [
        {"name": "w", "root_le": [0, 0, 0], "root_te": [1, 0, 0], "tip_le": [0, 5, 0], "tip_te": [1, 5, 0],
         "ribs": {"count": 3}}]}, "size": "1e-1", "out": ["o/m.vtu", "o/m.bdf"], "report": "o/r.json",
            "html": "o/r.md", "until": "imprint", "pictures": False, "thickness": {"ribs": 0.004, "default": 0.002},
            "material": {"name": "Al", "E": 7e10, "nu": 0.3, "rho": 2700}, "solver": {"merge_time_limit": 5}}
    cfg = parse_config(data, tmp_path / "a", source="x.yaml")
    assert cfg.surface == tmp_path / "a" / "geo" / "wing.stl" and cfg.size == 0.1
    assert cfg.out == [tmp_path / "a" / "o" / "m.vtu", tmp_path / "a" / "o" / "m.bdf"]
    assert cfg.solver == {"merge_time_limit": 5.0} and cfg.pictures is False
    for name in ("b/study.yaml", "c/study.json"):
        p = tmp_path / name
        p.parent.mkdir()
        write_config(cfg, p)
        back = load_config(p)
        assert back.source == p.resolve()
        for f in StudyConfig.__dataclass_fields__:
            if f != "source":
                assert getattr(back, f) == getattr(cfg, f), (name, f)
        assert not Path(yaml.safe_load(p.read_text())["surface"]).is_absolute()   # written relative


def test_merge_flags_and_thickness_families():
    base = parse_config({"surface": "s.stl", "layout": "l.json", "size": 1, "out": ["a.vtu"]}, "/base")
    m = merge_flags(base, size="2", out=["x.bdf"], surface=None, until="imprint")
    assert m.size == "2" and m.out == [Path("x.bdf")] and m.surface == Path("/base/s.stl")
    assert m.until == "imprint" and base.out == [Path("/base/a.vtu")]         # the original is unchanged
    names = ["skin", "w/rib_0", "w/spar_1/seg_0", "w/spar_0", "w/upper_skin/bay_0", "frame"]
    t = thickness_by_component({"ribs": 3, "w/spar_1": 5, "skin": 2, "default": 1}, names)
    assert t == {"skin": 2, "w/rib_0": 3, "w/spar_1/seg_0": 5, "w/spar_0": 1, "w/upper_skin/bay_0": 1, "frame": 1}
    assert thickness_by_component(0.3, names) == 0.3
    with pytest.raises(ConfigError, match="unknown key 'sise'"):
        parse_config({"sise": 1})


def test_docs_example_config_loads_and_runs(geometry_dir, tmp_path, capsys):
    """The complete example of docs/cli.md is valid and starts a real run (to the layout stage)."""
    repo = DOCS.parents[1]
    data = doc_example("cessna_study.yaml")
    cfg = parse_config(data, repo, source="cessna_study.yaml")
    assert cfg.surface.resolve() == (geometry_dir / "cessna210.stl").resolve()
    assert cfg.size == 0.25 and len(cfg.layout["wings"]) == 2 and len(cfg.out) == 2 and cfg.html.suffix == ".html"
    assert set(cfg.solver) <= set(__import__("shellmesh_mdao.config", fromlist=["x"]).solver_options())
    data["surface"] = str(geometry_dir / "cessna210.stl")
    (tmp_path / "cessna_out").mkdir()
    p = tmp_path / "cessna_study.yaml"
    p.write_text(yaml.safe_dump(data))
    rc, out, err = run(["-q", "mesh", "--config", str(p), "--until", "layout", "--no-pictures"], capsys)
    assert rc == 0, err
    r = json.loads((tmp_path / "cessna_out" / "cessna_report.json").read_text())
    assert [w["name"] for w in r["inputs"]["layout"]["wings"]] == ["right_wing", "left_wing"]
    assert (tmp_path / "cessna_out" / "cessna.bdf").is_file() and (tmp_path / "cessna_out" / "cessna_report.html").is_file()
    for name in ("straight_wing_study.yaml", "bwb_study.yaml"):
        parse_config(doc_example(name), repo, source=name)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["straight_wing_study.yaml", "bwb_study.yaml", "cessna_study.yaml"])
def test_docs_corpus_configs_mesh_to_the_end(geometry_dir, tmp_path, capsys, name):
    data = doc_example(name)
    data["surface"] = str(geometry_dir / Path(data["surface"]).name)
    out_dir = Path(data["html"]).parent
    (tmp_path / out_dir).mkdir()
    p = tmp_path / name
    p.write_text(yaml.safe_dump(data))
    rc, out, err = run(["-q", "mesh", "--config", str(p)], capsys)
    assert rc == 0, err
    r = json.loads((tmp_path / data["report"]).read_text())
    assert r["stage"] == r["inputs"]["until"] and r["counts"]["n_quads"] == r["counts"]["n_faces"] > 0
    html = (tmp_path / data["html"]).read_text()
    assert all((tmp_path / out_dir / s).is_file() for s in re.findall(r'<img src="([^"]+)"', html))


# ----------------------------------------------------------------------------- quality, render, errors
def _mesh_with_bad_rib(tmp_path):
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0],
                  [0, 0, 1], [1, 0, 1], [0.95, 0, 0.05]], float)
    faces = [[0, 1, 2, 3], [1, 4, 5, 2], [0, 1, 7, 6], [0, 1, 8, -1]]
    m = ShellMesh(p, faces, [0, 0, 1, 1], ["skin", "w/rib_0"])
    return m, write_mesh(m, tmp_path / "bad.vtu")


def test_quality_by_component_flags(tmp_path, capsys):
    from shellmesh_mdao.render import element_ids

    m, f = _mesh_with_bad_rib(tmp_path)
    rc, out, err = run(["quality", str(f), "--by-component", "--flagged"], capsys)
    assert rc == 0, err
    lines = out.splitlines()
    assert any(re.match(r"^\* w/rib_0\s", ln) for ln in lines)
    assert any(re.match(r"^  skin\s", ln) for ln in lines)
    assert "1 of 2 components have elements outside an acceptance range" in out
    eid = int(element_ids(m)[3])
    assert "1 elements outside an acceptance range" in out and re.search(rf"element\s+{eid}\s+w/rib_0", out)
    rc, out, err = run(["quality", str(f), "--json", "--by-component", "--flagged", "5"], capsys)
    d = json.loads(out)
    assert d["components"]["w/rib_0"]["n_flagged"] == 1 and d["components"]["skin"]["n_flagged"] == 0
    assert [e["element_id"] for e in d["flagged_elements"]] == [eid]
    assert "scaled_jacobian" in d["flagged_elements"][0]["failed"]


def test_render_command(tmp_path, capsys):
    from PIL import Image

    m, f = _mesh_with_bad_rib(tmp_path)
    out = tmp_path / "p.png"
    rc, o, err = run(["render", str(f), "--out", str(out), "--window", "320x240", "--color", "min_angle"], capsys)
    assert rc == 0, err
    assert Image.open(out).size == (320, 240) and "p.png" in o
    plain = write_mesh(naca_wing(n_chord=8, n_span=3), tmp_path / "plain.vtu")     # skin only: no wing box
    for src, args, needle in ((f, ["--color", "bogus"], "invalid choice"), (plain, ["--view", "wingbox"], "wingbox"),
                              (f, ["--window", "10x10"], "--window"), (f, ["--up", "0,0"], "--up")):
        rc, o, err = run(["render", str(src), "--out", str(tmp_path / "q.png")] + args, capsys)
        assert rc == 2 and needle in err and "Traceback" not in err, args
    assert not (tmp_path / "q.png").exists()
    rc, o, err = run(["render", str(tmp_path / "none.vtu"), "--out", str(out)], capsys)
    assert rc == 2 and "not found" in err


def test_internal_error_exit_1_asks_for_a_report(tmp_path, capsys, monkeypatch):
    import shellmesh_mdao.quality as quality

    m, f = _mesh_with_bad_rib(tmp_path)

    def bug(*a, **k):
        raise RuntimeError("index out of range in a helper")
    monkeypatch.setattr(quality, "quality_summary", bug)
    rc, out, err = run(["quality", str(f)], capsys)
    assert rc == 1
    assert "internal error: RuntimeError: index out of range" in err and "please report" in err
    assert "Traceback" not in err
    rc, out, err = run(["quality", str(f), "--verbose"], capsys)
    assert rc == 1 and "Traceback" in err and "please report" in err


@pytest.mark.slow
def test_demo_writes_mesh_pictures_and_report(tmp_path, capsys):
    rc, out, err = run(["demo", "--out-dir", str(tmp_path / "demo")], capsys)
    assert rc == 0, err
    d = tmp_path / "demo"
    for n in ("default_wing_mesh.vtu", "default_wing_mesh.bdf", "default_wing_report.json",
              "default_wing_report.html", "default_wing_report_iso.png", "default_wing_report_wingbox.png",
              "default_wing_study.yaml"):
        assert (d / n).is_file(), n
    html = (d / "default_wing_report.html").read_text()
    assert all((d / s).is_file() for s in re.findall(r'<img src="([^"]+)"', html))
    cfg = load_config(d / "default_wing_study.yaml")
    assert cfg.surface.is_file() and cfg.layout.is_file() and cfg.html == (d / "default_wing_report.html").resolve()
    assert json.loads((d / "default_wing_report.json").read_text())["counts"]["n_quads"] > 0
