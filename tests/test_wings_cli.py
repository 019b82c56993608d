"""Lifting surfaces found in a skin and the starting layout (shellmesh_mdao.layout.finder,
``shellmesh wings``)."""
import numpy as np
import pytest
import yaml

from shellmesh_mdao.cli import main
from shellmesh_mdao.errors import LayoutError
from shellmesh_mdao.export import write_mesh
from shellmesh_mdao.geometry import naca_wing
from shellmesh_mdao.layout import load_layout
from shellmesh_mdao.layout.finder import find_wings, starting_layout
from shellmesh_mdao.mesh import ShellMesh


def mirrored(m: ShellMesh) -> ShellMesh:
    """``m`` and its mirror image in y = 0, one surface of two bodies."""
    P = np.vstack([m.points, m.points * [1, -1, 1]])
    F = np.vstack([m.faces[:, :3], m.faces[:, [2, 1, 0]] + len(m.points)])
    return ShellMesh(P, F, np.zeros(len(F), np.int32), ["skin"])


@pytest.fixture(scope="module")
def aircraft():
    """Two wing halves beside the symmetry plane y = 0 and, behind them, two tail halves."""
    wing = naca_wing(y0=0.05)
    tail = naca_wing(span=2.0, root_chord=0.8, tip_chord=0.5, sweep_deg=15.0, dihedral_deg=0.0, y0=0.05)
    tail = ShellMesh(tail.points + [6.0, 0.0, 0.3], tail.faces, tail.component, ["skin"])
    both = ShellMesh(np.vstack([wing.points, tail.points]),
                     np.vstack([wing.faces[:, :3], tail.faces[:, :3] + len(wing.points)]),
                     np.zeros(len(wing.faces) + len(tail.faces), np.int32), ["skin"])
    return mirrored(both)


def test_find_wings_and_tails(aircraft):
    ws = find_wings(aircraft.points, aircraft.faces[:, :3], "y", size=0.1)
    names = [w.name for w in ws]
    assert sorted(names) == ["left_surface_1", "left_surface_2", "right_surface_1", "right_surface_2"]
    by = {w.name: w for w in ws}
    r1, l1, r2 = by["right_surface_1"], by["left_surface_1"], by["right_surface_2"]
    assert r1.mirror == "left_surface_1" and l1.mirror == "right_surface_1"
    # the wing: from the body's end near the symmetry plane (two sizes out) to two sizes in from its tip
    assert 0.05 + 0.2 - 0.1 <= r1.root <= 0.05 + 0.2 + 0.1 and r1.tip == pytest.approx(-l1.tip)
    assert 6.05 - 0.4 <= r1.tip <= 6.05 - 0.2
    assert r1.root_chord == pytest.approx(2.0 - (r1.root - 0.05) / 6.0, rel=5e-3)
    assert abs(r1.up[2]) > 0.99 and r1.up[2] > 0
    assert r2.root_chord < 0.85 and r2.near[0] > 5.5                       # the tail, behind
    lay = load_layout(starting_layout(ws))
    assert [w.name for w in lay.station_wings] == names
    w = lay.station_wings[0]
    assert w.rib_orientation == "normal_to_spar" and w.spar_chord == (0.15, 0.65)
    assert len(lay.station_wings[names.index("right_surface_2")].rib_eta) <= 10   # as many ribs as fit


def test_find_wings_errors(aircraft):
    with pytest.raises(LayoutError, match="no lifting surface along the axis"):
        find_wings(aircraft.points, aircraft.faces[:, :3], "x", size=0.1)
    with pytest.raises(LayoutError, match="give x, y or z"):
        find_wings(aircraft.points, aircraft.faces[:, :3], "w")


def test_cli_wings(aircraft, tmp_path, capsys):
    src = write_mesh(aircraft, tmp_path / "plane.vtu")
    out = tmp_path / "layout.yaml"
    assert main(["wings", str(src), "--size", "0.1", "--out", str(out), "--ribs", "6"]) == 0
    text = capsys.readouterr().out
    assert "4 lifting surface(s) along y" in text and "right_surface_1" in text and "wrote" in text
    d = yaml.safe_load(out.read_text())
    assert len(d["wings"]) == 4 and d["wings"][0]["ribs"]["count"] == 6
    assert "-0.0" not in out.read_text()
    lay = load_layout(out)
    assert len(lay.station_wings) == 4
    assert main(["wings", str(src), "--json"]) == 0
    assert '"layout"' in capsys.readouterr().out


@pytest.mark.parametrize("args, msg", [
    (["wings", "missing.stl"], "not found"),
    (["wings", "{src}", "--axis", "q"], "give x, y or z"),
    (["wings", "{src}", "--out", "layout.txt"], ".yaml, .yml or .json"),
    (["wings", "{src}", "--size", "-1"], "positive length"),
    (["wings", "{src}", "--spars", "a,b"], "chord fractions"),
])
def test_cli_wings_errors(aircraft, tmp_path, capsys, args, msg):
    src = write_mesh(aircraft, tmp_path / "plane.vtu")
    assert main([a.format(src=src) for a in args]) == 2
    err = capsys.readouterr().err.strip()
    assert msg in err and len(err.splitlines()) == 1


GEOMETRY = __import__("pathlib").Path(__file__).resolve().parents[2] / "shared" / "geometry"


@pytest.mark.skipif(not (GEOMETRY / "f22_half.vtk").is_file(), reason="corpus not present")
def test_root_clear_of_a_wing_body_junction():
    """The F-22's wing leaves its body along a crease line near y = -2.15: the root rib is put two
    element sizes outboard of it (not two sizes from where the sections first look like a wing)."""
    from shellmesh_mdao.load import load_surface

    S, _ = load_surface(GEOMETRY / "f22_half.vtk")
    for size in (0.17, 0.085):
        ws = find_wings(S.points, S.faces[:, :3], "y", size=size)
        wing = max(ws, key=lambda w: w.root_chord)
        assert wing.tip < wing.root < -2.12 - 2 * size + 0.05
        assert wing.root_chord > 6.0 and wing.mirror is None
