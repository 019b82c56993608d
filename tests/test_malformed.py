"""Bad input, clear error, nothing lost.

Every malformed input (surface file, layout, size, output path) gives exit code 2 from the
CLI with one ``error:`` line naming the offending item and the fix, the library raises the
exact :class:`ShellMeshError` subclass, and no output file (nor temporary file) is left.
The last test keeps docs/troubleshooting.md complete: every ``raise <ShellMeshError
subclass>(...)`` message of the package must be listed there.
"""
import ast
import errno
import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
import trimesh

from shellmesh_mdao import errors
from shellmesh_mdao.cli import main
from shellmesh_mdao.errors import (InputFileError, LayoutError, MeshValidationError, OutputError,
                                   ProjectionError, ShellMeshError, SizeError)
from shellmesh_mdao.export import check_output_path, write_mesh
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.layout import load_layout
from shellmesh_mdao.pipeline import run_pipeline

REPO = Path(__file__).resolve().parents[1]
SIZE = "0.15"

_WING = naca_wing(n_chord=24, n_span=16)


# ------------------------------------------------------------------ inputs
def _stl_bytes() -> bytes:
    import io

    buf = io.BytesIO()
    trimesh.Trimesh(_WING.points, _WING.faces[:, :3], process=False).export(buf, file_type="stl")
    return buf.getvalue()


def _text(name, data):
    def make(d: Path) -> Path:
        p = d / name
        (p.write_bytes if isinstance(data, bytes) else p.write_text)(data)
        return p
    return make


def _garbage(name, n=3000, seed=0):
    return _text(name, np.random.default_rng(seed).integers(0, 256, n, dtype=np.uint8).tobytes())


def _good_surface(d: Path) -> Path:
    return write_mesh(_WING, d / "wing.vtu")


def _vtu_prefix(n):
    def make(d: Path) -> Path:
        data = _good_surface(d).read_bytes()
        p = d / "cut.vtu"
        p.write_bytes(data[:n])
        return p
    return make


def _stl_prefix(n, name="cut.stl"):
    return lambda d: _text(name, _stl_bytes()[:n])(d)


def _layout(change=None, name="layout.json", raw=None):
    """A layout file: the default wing layout, changed by ``change(dict)``, or ``raw`` text/bytes."""
    def make(d: Path) -> Path:
        p = d / name
        if raw is not None:
            (p.write_bytes if isinstance(raw, bytes) else p.write_text)(raw)
            return p
        lay = naca_wing_layout(ribs=4)
        if change is not None:
            lay = change(lay) or lay
        p.write_text(json.dumps(lay))
        return p
    return make


def _wing(**kw):
    def change(lay):
        lay["wings"][0].update(kw)
    return change


def _add_member(**kw):
    def change(lay):
        m = {"name": "frame", "upper": [[0.6, 2.0, 0.3], [1.2, 2.0, 0.3]],
             "lower": [[0.6, 2.0, -0.3], [1.2, 2.0, -0.3]], "direction": [0.0, 0.0, -1.0]}
        m.update(kw)
        lay["members"] = [m]
    return change


def _read_only_folder(d: Path, monkeypatch) -> Path:
    ro = d / "readonly"
    ro.mkdir(exist_ok=True)
    ro.chmod(0o555)
    if os.geteuid() == 0:      # root writes anyway: make the temporary-file probe fail like EACCES
        import tempfile

        real = tempfile.mkstemp

        def mkstemp(*a, **k):
            if Path(k.get("dir", "")).resolve() == ro.resolve():
                raise PermissionError(errno.EACCES, "Permission denied")
            return real(*a, **k)
        monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    return ro


# ------------------------------------------------------------------ the cases
# Each case: surface maker, layout maker, size, output (name relative to the empty output
# folder, or a callable), --until, exact error class, words the message must contain (the
# offending item and the fix), and the library call that raises it.
def C(id, err, needles, surface=_good_surface, layout=_layout(), size=SIZE, out="o.vtu", until="layout",
      lib="pipeline"):
    return pytest.param(dict(surface=surface, layout=layout, size=size, out=out, until=until, err=err,
                             needles=needles, lib=lib), id=id)


CASES = [
    # --- surface files: missing, unreadable, truncated, garbage, empty, NaN
    C("surface-missing", InputFileError, ["missing.stl", "not found", "check the path"],
      surface=lambda d: d / "missing.stl"),
    C("surface-is-folder", InputFileError, ["is a folder", "give the file itself"],
      surface=lambda d: (d / "afolder.stl").mkdir() or d / "afolder.stl"),
    C("surface-unknown-extension", InputFileError, ["x.xyz", "unknown extension", "supported: .stl"],
      surface=_text("x.xyz", "1 2 3\n")),
    C("surface-empty-file", InputFileError, ["empty.stl", "empty (0 bytes)", "re-export"],
      surface=_text("empty.stl", b"")),
    C("stl-binary-truncated", InputFileError, ["cut.stl", "truncated", "re-export"],
      surface=_stl_prefix(1000)),
    C("stl-too-short", InputFileError, ["cut.stl", "too short", "re-export"], surface=_stl_prefix(40)),
    C("stl-ascii-truncated", InputFileError, ["t.stl", "truncated", "re-export"],
      surface=_text("t.stl", "solid w\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0")),
    C("stl-binary-garbage", InputFileError, ["g.stl", "corrupt", "re-export"], surface=_garbage("g.stl")),
    C("obj-binary-garbage", InputFileError, ["g.obj", "no triangles or quads", "give a surface mesh file"],
      surface=_garbage("g.obj")),
    C("ply-binary-garbage", InputFileError, ["g.ply", "cannot read", "re-export"], surface=_garbage("g.ply")),
    C("off-binary-garbage", InputFileError, ["g.off", "cannot read", "re-export"], surface=_garbage("g.off")),
    C("vtu-binary-garbage", InputFileError, ["g.vtu", "cannot read", "re-export"], surface=_garbage("g.vtu")),
    C("vtu-truncated", InputFileError, ["cut.vtu", "cannot read", "re-export"], surface=_vtu_prefix(600)),
    C("vtk-binary-garbage", InputFileError, ["g.vtk", "cannot read", "re-export"], surface=_garbage("g.vtk")),
    C("msh-binary-garbage", InputFileError, ["g.msh", "cannot read", "re-export"], surface=_garbage("g.msh")),
    C("bdf-binary-garbage", InputFileError, ["g.bdf", "cannot read", "re-export"], surface=_garbage("g.bdf")),
    C("inp-binary-garbage", InputFileError, ["g.inp", "no triangles or quads", "give a surface mesh file"],
      surface=_garbage("g.inp")),
    C("inp-undefined-nodes", InputFileError, ["u.inp", "undefined node numbers", "truncated"],
      surface=_text("u.inp", "*NODE\n1, 0., 0., 0.\n2, 1., 0., 0.\n3, 0., 1., 0.\n"
                             "*ELEMENT, TYPE=S3\n1, 1, 2, 7\n")),
    C("obj-no-faces", InputFileError, ["pts.obj", "no triangles or quads", "give a surface mesh file"],
      surface=_text("pts.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n")),
    C("obj-bad-vertex-index", InputFileError, ["idx.obj", "corrupt", "re-export"],
      surface=_text("idx.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n")),
    C("obj-collapsed-faces", InputFileError, ["col.obj", "every face is degenerate", "re-export"],
      surface=_text("col.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 1 2\nf 3 3 3\n")),
    C("obj-nan-coordinates", MeshValidationError, ["nan.obj", "NaN/inf", "fix or re-export"],
      surface=_text("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")),
    C("obj-inf-coordinates", MeshValidationError, ["inf.obj", "NaN/inf", "fix or re-export"],
      surface=_text("inf.obj", "v 0 0 0\nv inf 0 0\nv 0 1 0\nf 1 2 3\n")),
    C("obj-overflowing-coordinates", MeshValidationError, ["big.obj", "not lengths in any unit", "re-export"],
      surface=_text("big.obj", "v 1e200 0 0\nv 0 1e200 0\nv 0 0 1e200\nf 1 2 3\n")),
    # --- layouts: unreadable, missing keys, wrong types, out of range, outside the aircraft
    C("layout-missing", LayoutError, ["nope.json", "not found", "check the path"],
      layout=lambda d: d / "nope.json", lib="layout"),
    C("layout-is-folder", LayoutError, ["is a folder", "give the .json or .yaml file"],
      layout=lambda d: (d / "lay.json").mkdir() or d / "lay.json", lib="layout"),
    C("layout-invalid-json", LayoutError, ["invalid JSON at line 1", "fix the syntax"],
      layout=_layout(raw='{"wings": [}'), lib="layout"),
    C("layout-invalid-yaml", LayoutError, ["invalid YAML at line", "fix the syntax"],
      layout=_layout(raw="wings:\n  - name: [a\n", name="layout.yaml"), lib="layout"),
    C("layout-binary-garbage", LayoutError, ["not a text file", "JSON or YAML"],
      layout=_layout(raw=bytes(range(256)) * 4), lib="layout"),
    C("layout-empty", LayoutError, ["layout is empty", "give at least one wing"],
      layout=_layout(raw="", name="layout.yaml"), lib="layout"),
    C("layout-not-a-mapping", LayoutError, ["the layout must be a mapping", "got list"],
      layout=_layout(raw="[1, 2]"), lib="layout"),
    C("layout-missing-key", LayoutError, ["missing key 'root_le'", "wings[0]", "add it"],
      layout=_layout(lambda lay: lay["wings"][0].pop("root_le") and None), lib="layout"),
    C("layout-unknown-key", LayoutError, ["unknown key 'spar'", "did you mean 'spars'"],
      layout=_layout(_wing(spar={"chord_fractions": [0.2]})), lib="layout"),
    C("layout-wrong-type-point", LayoutError, ["wings[0] ('wing').root_le", "list of 3 numbers", "'0,0,0'"],
      layout=_layout(_wing(root_le="0,0,0")), lib="layout"),
    C("layout-wrong-type-count", LayoutError, ["ribs.count must be an integer", "4.5"],
      layout=_layout(_wing(ribs={"count": 4.5})), lib="layout"),
    C("layout-wrong-type-eta", LayoutError, ["ribs.eta must be a list of numbers", "'0.5'"],
      layout=_layout(_wing(ribs={"eta": "0.5"})), lib="layout"),
    C("layout-nan-coordinate", LayoutError, ["root_le[0] must be a finite number", "give a real value"],
      layout=_layout(_wing(root_le=[float("nan"), 0.0, 0.0])), lib="layout"),
    C("layout-ribs-beyond-tip", LayoutError, ["ribs.eta[2] = 1.2 is outside [0, 1]", "1 (tip)"],
      layout=_layout(_wing(ribs={"eta": [0.0, 0.5, 1.2]})), lib="layout"),
    C("layout-spar-outside-chord", LayoutError, ["chord_fractions[1] = 1.5 is outside (0, 1)", "trailing edge"],
      layout=_layout(_wing(spars={"chord_fractions": [0.2, 1.5]})), lib="layout"),
    C("layout-up-along-span", LayoutError, ["'up'", "nearly parallel to the span", "normal of the wing's chord"],
      layout=_layout(_wing(up=[0.0, 1.0, 0.0])), lib="layout"),
    C("layout-duplicate-wing", LayoutError, ["duplicate wing name 'wing'", "rename one"],
      layout=_layout(lambda lay: lay["wings"].append(dict(lay["wings"][0])) and None), lib="layout"),
    C("layout-absurd-rib-count", LayoutError, ["ribs.count = 1000000000", "more than 10000"],
      layout=_layout(_wing(ribs={"count": 10 ** 9})), lib="layout"),
    C("layout-ribs-coincide", LayoutError, ["members coincide or cross at element size", "'wing/rib_1' (eta=0.5)",
                                            "remove one member of each pair"],
      layout=_layout(_wing(ribs={"eta": [0.0, 0.5, 0.501, 1.0]})), lib="layout"),
    C("members-beyond-the-tip", ProjectionError, ["wing/spar_0", "miss the skin", "check the wing corners"],
      layout=_layout(_wing(tip_le=[1.5, 12.0, 0.3], tip_te=[2.5, 12.0, 0.3])), until="project"),
    C("members-outside-the-aircraft", ProjectionError, ["wing/spar_0", "miss the skin", "check the wing corners"],
      layout=_layout(_wing(root_le=[10.0, 0.2, 0.0], root_te=[12.0, 0.2, 0.0], tip_le=[11.0, 5.8, 0.0],
                           tip_te=[12.0, 5.8, 0.0])), until="project"),
    C("explicit-member-misses-the-skin", ProjectionError, ["member 'frame'", "misses the skin",
                                                            "omit 'direction'"],
      layout=_layout(_add_member(direction=[1.0, 0.0, 0.0], upper=[[30.0, 2.0, 0.3], [31.0, 2.0, 0.3]],
                                 lower=[[30.0, 2.0, -0.3], [31.0, 2.0, -0.3]])), until="project"),
    # --- size
    C("size-zero", SizeError, ["--size must be a positive length", "'0'"], size="0", lib="size"),
    C("size-negative", SizeError, ["--size must be a positive length", "'-1'"], size="-1", lib="size"),
    C("size-nan", SizeError, ["--size must be a positive length", "'nan'"], size="nan", lib="size"),
    C("size-not-a-number", SizeError, ["--size must be a number", "'abc'"], size="abc", lib="size"),
    C("size-larger-than-aircraft", SizeError, ["--size 100 is too large", "use at most"], size="100",
      lib="size"),
    C("size-tiny", SizeError, ["--size 1e-09 is too small", "check the units"], size="1e-9", lib="size"),
    # --- output paths
    C("out-missing-folder", OutputError, ["nowhere", "does not exist", "mkdir -p"], out="nowhere/o.vtu",
      lib="output"),
    C("out-parent-is-a-file", OutputError, ["is a file, not a folder", "existing folder"],
      out=lambda d, o: (o / "file.txt").write_text("x") and o / "file.txt" / "o.vtu", lib="output"),
    C("out-is-a-folder", OutputError, ["it is an existing folder", "give a file name"],
      out=lambda d, o: (o / "dir.vtu").mkdir() or o / "dir.vtu", lib="output"),
    C("out-unknown-extension", OutputError, ["o.xyz", "unknown output extension", "use one of"], out="o.xyz",
      lib="output"),
    C("out-read-only-folder", OutputError, ["is not writable", "choose a writable folder"], out="readonly",
      lib="output"),
]


def _snapshot(d: Path) -> set:
    return {p.relative_to(d) for p in d.rglob("*")}


@pytest.mark.parametrize("case", CASES)
def test_malformed_input_gives_one_clear_error_and_writes_nothing(case, tmp_path, capsys, monkeypatch):
    inp = tmp_path / "in"
    out_dir = tmp_path / "out"
    inp.mkdir()
    out_dir.mkdir()
    surface = case["surface"](inp)
    layout = case["layout"](inp)
    if case["out"] == "readonly":
        out = _read_only_folder(tmp_path, monkeypatch) / "o.vtu"
    elif callable(case["out"]):
        out = case["out"](inp, out_dir)
    else:
        out = out_dir / case["out"]
    monkeypatch.chdir(out_dir)
    before = _snapshot(tmp_path)
    rc = main(["-q", "mesh", str(surface), "--layout", str(layout), "--size", case["size"], "--out", str(out),
               "--until", case["until"]])
    err = capsys.readouterr().err
    assert rc == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err, err
    for needle in case["needles"]:
        assert needle in lines[0], (needle, lines[0])
    assert _snapshot(tmp_path) == before          # no output, no temporary file, nothing else
    # the library raises the exact error class
    with pytest.raises(ShellMeshError) as ei:
        if case["lib"] == "output":
            check_output_path(out)
        elif case["lib"] == "layout":
            load_layout(layout).validate(float(case["size"]))
        else:
            run_pipeline(surface, layout, case["size"], until=case["until"], progress=False)
    assert type(ei.value) is case["err"], (type(ei.value), ei.value)
    for needle in case["needles"]:
        if not needle.startswith("--size"):
            assert needle in str(ei.value)
    assert _snapshot(tmp_path) == before


def test_there_are_at_least_30_cases():
    assert len(CASES) >= 30
    assert len({c.values[0]["err"] for c in CASES}) >= 6


# ------------------------------------------------------------------ nothing lost
def test_failed_run_keeps_an_existing_output_untouched(tmp_path, capsys):
    surf = _good_surface(tmp_path)
    out = tmp_path / "o.vtu"
    out.write_text("previous result")
    lay = _layout(_wing(ribs={"eta": [0.0, 1.5]}))(tmp_path)
    assert main(["-q", "mesh", str(surf), "--layout", str(lay), "--size", SIZE, "--out", str(out),
                 "--until", "layout"]) == 2
    assert out.read_text() == "previous result"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["layout.json", "o.vtu", "wing.vtu"]


def test_write_failing_midway_leaves_no_partial_file(tmp_path, capsys, monkeypatch):
    """A disk-full error while the mesh is written: exit 2, no output and no temporary file."""
    from shellmesh_mdao import export

    def broken(mesh, path, *a, **k):
        Path(path).write_bytes(b"<VTKFile partial")
        raise OSError(errno.ENOSPC, "No space left on device")
    surf = _good_surface(tmp_path)
    monkeypatch.setattr(export, "_write_vtu", broken)
    lay = _layout()(tmp_path)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    rc = main(["-q", "mesh", str(surf), "--layout", str(lay), "--size", SIZE, "--out", str(out_dir / "o.vtu"),
               "--until", "load"])
    err = capsys.readouterr().err
    assert rc == 2 and "No space left on device" in err and "choose another folder" in err
    assert list(out_dir.iterdir()) == []


@pytest.mark.parametrize("where", ["missing", "readonly"])
def test_report_path_in_a_missing_or_read_only_folder(where, tmp_path, capsys, monkeypatch):
    surf = _good_surface(tmp_path)
    lay = _layout()(tmp_path)
    folder = tmp_path / "nowhere" if where == "missing" else _read_only_folder(tmp_path, monkeypatch)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    before = _snapshot(tmp_path)
    rc = main(["-q", "mesh", str(surf), "--layout", str(lay), "--size", SIZE, "--out", str(out_dir / "o.vtu"),
               "--report", str(folder / "r.json"), "--until", "layout"])
    err = capsys.readouterr().err
    assert rc == 2 and str(folder) in err
    assert ("does not exist" in err) if where == "missing" else ("not writable" in err)
    assert _snapshot(tmp_path) == before          # the mesh is not written either
    with pytest.raises(OutputError):
        check_output_path(folder / "r.json", formats={".json": "report"})


def test_info_on_bad_files_exits_2(tmp_path, capsys):
    for make in (_garbage("g.ply"), _text("nan.obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
                 lambda d: d / "missing.vtu"):
        rc = main(["info", str(make(tmp_path))])
        err = capsys.readouterr().err
        assert rc == 2 and err.startswith("error: ") and len(err.strip().splitlines()) == 1


# ------------------------------------------------------------------ troubleshooting page is complete
def _error_classes(trees) -> set:
    names = {n for n in dir(errors) if isinstance(getattr(errors, n), type)
             and issubclass(getattr(errors, n), ShellMeshError)}
    classes = [(n.name, {b.id for b in n.bases if isinstance(b, ast.Name)})
               for t in trees.values() for n in t.body if isinstance(n, ast.ClassDef)]
    grew = True
    while grew:
        grew = False
        for name, bases in classes:
            if name not in names and bases & names:
                names.add(name)
                grew = True
    return names


def _template(node) -> list:
    """The message of a raise as literal text with ``{}`` for every formatted part; one per
    branch of a conditional expression."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.JoinedStr):
        return ["".join(v.value if isinstance(v, ast.Constant) else "{}" for v in node.values)]
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return [a + b for a in _template(node.left) for b in _template(node.right)]
    if isinstance(node, ast.IfExp):
        return _template(node.body) + _template(node.orelse)
    return ["{}"]


def message_key(template: str) -> str:
    """The first literal words of a message template: it is normalised (every ``{...}``
    placeholder becomes ``{}``, whitespace collapsed), leading placeholders and punctuation
    are dropped, and the first 40 characters are kept."""
    s = re.sub(r"\{[^{}]*\}", "{}", template)
    s = re.sub(r"\s+", " ", s)
    s = re.sub(r"^(?:\{\}|[\s:;,.'\"()\[\]=-])+", "", s)
    return s[:40].strip()


def raise_sites():
    """(file:line, class, key) of every ``raise <ShellMeshError subclass>(...)`` in the package."""
    files = sorted((REPO / "shellmesh_mdao").rglob("*.py"))
    trees = {f: ast.parse(f.read_text(encoding="utf-8")) for f in files}
    names = _error_classes(trees)
    out = []
    for f, t in trees.items():
        for n in ast.walk(t):
            if isinstance(n, ast.Raise) and isinstance(n.exc, ast.Call) and isinstance(n.exc.func, ast.Name) \
                    and n.exc.func.id in names and n.exc.args:
                for tpl in _template(n.exc.args[0]):
                    key = message_key(tpl)
                    if key and key != "{}":
                        out.append((f"{f.relative_to(REPO)}:{n.lineno}", n.exc.func.id, key))
    return out


def test_every_error_message_is_in_the_troubleshooting_page():
    page = (REPO / "docs" / "troubleshooting.md").read_text(encoding="utf-8")
    doc = re.sub(r"\s+", " ", re.sub(r"\{[^{}]*\}", "{}", page))
    sites = raise_sites()
    assert len(sites) > 100
    missing = [f"{where} {cls}: {key!r}" for where, cls, key in sites if key not in doc]
    assert not missing, ("error messages missing from docs/troubleshooting.md (add each with its cause and "
                         "fix):\n" + "\n".join(missing))
