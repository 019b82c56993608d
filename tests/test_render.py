"""Off-screen pictures: non-blank PNGs, family colours, views, worst elements, element ids."""
import colorsys
import time

import numpy as np
import pytest
from PIL import Image

from shellmesh_mdao.errors import OutputError
from shellmesh_mdao.export import write_mesh
from shellmesh_mdao.geometry import naca_wing
from shellmesh_mdao.load import load_mesh
from shellmesh_mdao.mesh import ShellMesh, concatenate
from shellmesh_mdao.render import (component_colors, component_family, element_ids, render_mesh, render_views,
                                   render_worst, render_worst_closeups, to_pyvista, worst_elements)

WIN = (480, 320)


def plate(p0, du, dv, nu, nv, name):
    """Structured quad grid p0 + i/nu du + j/nv dv as a one-component ShellMesh."""
    i, j = np.meshgrid(np.arange(nu + 1), np.arange(nv + 1), indexing="ij")
    pts = np.asarray(p0, float) + (i[..., None] / nu) * np.asarray(du, float) + (j[..., None] / nv) * np.asarray(dv, float)
    pts = pts.reshape(-1, 3)
    a = (i[:-1, :-1] * (nv + 1) + j[:-1, :-1]).ravel()
    q = np.stack([a, a + nv + 1, a + nv + 2, a + 1], 1)
    return ShellMesh(pts, q, np.zeros(len(q), np.int32), [name])


def box_mesh(n_bays=3):
    """A small wing box: upper and lower skin bays, two spars, ribs, and leading-edge skin."""
    parts = []
    for k in range(n_bays):
        parts.append(plate([0, k, 1], [1, 0, 0], [0, 1, 0], 6, 6, f"w/upper_skin/bay_{k}"))
        parts.append(plate([0, k, 0], [1, 0, 0], [0, 1, 0], 6, 6, f"w/lower_skin/bay_{k}"))
    for k in range(n_bays + 1):
        parts.append(plate([0, k, 0], [1, 0, 0], [0, 0, 1], 6, 6, f"w/rib_{k}"))
    parts.append(plate([0, 0, 0], [0, n_bays, 0], [0, 0, 1], 6 * n_bays, 6, "w/spar_0"))
    parts.append(plate([1, 0, 0], [0, n_bays, 0], [0, 0, 1], 6 * n_bays, 6, "w/spar_1"))
    parts.append(plate([-0.5, 0, 0.5], [0.5, 0, 0.5], [0, n_bays, 0], 3, 6 * n_bays, "skin"))
    return concatenate(parts)


def pixels(path):
    img = np.asarray(Image.open(path).convert("RGB"))
    return img


def saturated_hues(img, min_count=150):
    """Hue bins (30 degrees wide) holding at least ``min_count`` clearly coloured pixels."""
    px = img.reshape(-1, 3).astype(float) / 255.0
    mx, mn = px.max(1), px.min(1)
    sat = (mx - mn) / np.maximum(mx, 1e-9)
    keep = (sat > 0.2) & (mx > 0.25)
    hues = np.array([colorsys.rgb_to_hsv(*p)[0] for p in px[keep][::7]])   # subsample: speed
    counts = np.bincount((hues * 12).astype(int) % 12, minlength=12) * 7
    return set(np.flatnonzero(counts >= min_count).tolist())


def test_family_names_and_alternating_shades():
    names = ["skin", "w/upper_skin/bay_0", "w/upper_skin/bay_1", "w/lower_skin/bay_0", "w/rib_0", "w/rib_1",
             "w/spar_0", "frame_3"]
    assert [component_family(n) for n in names] == ["skin", "upper skin", "upper skin", "lower skin", "rib", "rib",
                                                     "spar", "member"]
    rgb, fam = component_colors(names)
    assert rgb.shape == (8, 3) and rgb.dtype == np.uint8
    assert (rgb[1] != rgb[2]).any() and (rgb[4] != rgb[5]).any()     # neighbours in a family differ
    assert len({tuple(rgb[i]) for i in (0, 1, 3, 4, 6, 7)}) == 6        # families differ


def test_to_pyvista_keeps_mixed_faces():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    m = ShellMesh(p, [[0, 1, 2, 3], [1, 4, 2, -1]], [0, 1], ["skin", "w/rib_0"])
    poly = to_pyvista(m)
    assert poly.n_cells == 2 and poly.n_points == 5
    assert poly.get_cell(0).n_points == 4 and poly.get_cell(1).n_points == 3
    assert poly.cell_data["component"].tolist() == [0, 1]
    sub = to_pyvista(m, [1])
    assert sub.n_cells == 1 and sub.cell_data["component"].tolist() == [1]


def test_worst_elements_and_element_ids(tmp_path):
    m = box_mesh(2)
    # fold one rib quad into a dart: its scaled Jacobian goes negative
    f = m.faces[np.flatnonzero(m.component == m.component_names.index("w/rib_1"))[7]]
    pts = m.points.copy()
    pts[f[2]] = 0.25 * pts[f[0]] + 0.75 * (pts[f[1]] + pts[f[3]]) / 2 - 0.6 * (pts[f[2]] - pts[f[0]])
    bad = ShellMesh(pts, m.faces, m.component, m.component_names)
    w = worst_elements(bad, 3)
    assert (bad.faces[w[0]] == f).all()
    # the element id is the element's number in the written file
    eid = element_ids(bad)
    assert sorted(eid.tolist()) == list(range(1, bad.n_faces + 1))
    back = load_mesh(write_mesh(bad, tmp_path / "b.bdf"))
    assert (back.faces[eid[w[0]] - 1] == f).all()


def test_component_picture_is_clear(tmp_path):
    out = render_mesh(box_mesh(), tmp_path / "iso.png", window_size=WIN)
    img = pixels(out)
    assert img.shape == (WIN[1], WIN[0], 3)
    assert img.std() > 20                                   # not blank
    # upper skin blue, rib orange and spar purple show as separate hues
    hues = saturated_hues(img)
    assert len(hues) >= 3 and hues & {6, 7} and hues & {0, 1} and hues & {8, 9}


def test_metric_colouring_and_views(tmp_path):
    m = box_mesh()
    a = pixels(render_mesh(m, tmp_path / "sj.png", color="scaled_jacobian", window_size=WIN))
    b = pixels(render_mesh(m, tmp_path / "top.png", view="top", window_size=WIN))
    c = pixels(render_mesh(m, tmp_path / "box.png", view="wingbox", window_size=WIN))
    for img in (a, b, c):
        assert img.std() > 20
    assert not np.array_equal(b, c)
    # the wing-box view hides the upper skin: less of its blue than the top view, which shows it
    def blue(img):
        px = img.reshape(-1, 3).astype(int)
        return int(((px[:, 2] > px[:, 0] + 60) & (px[:, 2] > px[:, 1] + 15)).sum())
    assert blue(c) < 0.5 * blue(b)


def test_bad_options_are_user_errors(tmp_path):
    m = box_mesh(1)
    with pytest.raises(OutputError, match="colour"):
        render_mesh(m, tmp_path / "x.png", color="beauty")
    with pytest.raises(OutputError, match="view"):
        render_mesh(m, tmp_path / "x.png", view="side")
    with pytest.raises(OutputError, match="PNG"):
        render_mesh(m, tmp_path / "x.jpg")
    with pytest.raises(OutputError, match="wingbox"):
        render_mesh(naca_wing(n_chord=8, n_span=3), tmp_path / "x.png", view="wingbox")
    with pytest.raises(OutputError, match="does not exist"):
        render_mesh(m, tmp_path / "nope" / "x.png", window_size=WIN)
    assert not list(tmp_path.rglob("*.png"))


def test_render_views_and_worst_pictures(tmp_path):
    m = box_mesh(2)
    paths = render_views(m, tmp_path / "pics", "box", worst=5, closeups=2, window_size=WIN)
    assert [p.name for p in paths] == ["box_iso.png", "box_top.png", "box_wingbox.png", "box_quality.png",
                                       "box_worst.png", "box_worst_closeups.png"]
    for p in paths:
        assert p.is_file() and pixels(p).std() > 10
    # the worst elements are marked red
    w = pixels(paths[4]).reshape(-1, 3).astype(int)
    assert ((w[:, 0] > 150) & (w[:, 1] < 60) & (w[:, 2] < 60)).sum() > 50
    # no wing box in a plain surface: no wingbox picture
    paths = render_views(naca_wing(n_chord=10, n_span=4), tmp_path, "plain", worst=0, closeups=0, window_size=WIN)
    assert [p.name for p in paths] == ["plain_iso.png", "plain_top.png", "plain_quality.png"]


def test_loads_files(tmp_path):
    f = write_mesh(box_mesh(1), tmp_path / "m.vtu")
    out = render_worst(f, tmp_path / "w.png", 3, window_size=WIN)
    assert pixels(out).std() > 10
    out = render_worst_closeups(f, tmp_path / "c.png", 2, window_size=WIN)
    assert pixels(out).std() > 10


@pytest.mark.slow
def test_large_mesh_renders_in_seconds(tmp_path):
    # CPU seconds of this process (every thread; 0.7 s on the reference machine), after a small
    # render has imported pyvista and probed the renderer: the machine's load does not count
    m = naca_wing(n_chord=200, n_span=250)
    assert m.n_faces > 190_000
    render_mesh(naca_wing(n_chord=8, n_span=4), tmp_path / "small.png")
    c0 = time.process_time()
    render_mesh(m, tmp_path / "big.png")
    assert time.process_time() - c0 < 30


def test_no_offscreen_opengl_is_a_user_error_with_the_install_step(tmp_path, monkeypatch):
    import shellmesh_mdao.render as render

    monkeypatch.setattr(render, "_probe_result", (False, "a test render crashed (signal 11)"))
    with pytest.raises(OutputError, match="apt-get install -y libegl1 libgl1-mesa-dri"):
        render_mesh(box_mesh(1), tmp_path / "x.png", window_size=WIN)
    with pytest.raises(OutputError, match="signal 11"):
        render_worst_closeups(box_mesh(1), tmp_path / "y.png", 2)
    assert not list(tmp_path.iterdir())
