"""Human reports: self-contained folder, tables with known counts, atomic writes."""
import re

import numpy as np
import pytest
from PIL import Image

from shellmesh_mdao import report as report_mod
from shellmesh_mdao.errors import OutputError
from shellmesh_mdao.mesh import ShellMesh, concatenate
from shellmesh_mdao.quality import quality_summary
from shellmesh_mdao.report import (family_counts, flagged_table, report_data, worst_table, write_histograms,
                                   write_report)

WIN = (400, 280)


def plate(p0, du, dv, nu, nv, name):
    i, j = np.meshgrid(np.arange(nu + 1), np.arange(nv + 1), indexing="ij")
    pts = np.asarray(p0, float) + (i[..., None] / nu) * np.asarray(du, float) + (j[..., None] / nv) * np.asarray(dv, float)
    a = (i[:-1, :-1] * (nv + 1) + j[:-1, :-1]).ravel()
    q = np.stack([a, a + nv + 1, a + nv + 2, a + 1], 1)
    return ShellMesh(pts.reshape(-1, 3), q, np.zeros(len(q), np.int32), [name])


def box_mesh():
    """Wing box of 2 bays (upper/lower skin 4x4 quads each), 3 ribs (4x2), 2 spars (8x2), LE skin (2x8),
    with one rib quad squashed to a sliver (the worst element)."""
    parts = []
    for k in range(2):
        parts.append(plate([0, k, 0.5], [1, 0, 0], [0, 1, 0], 4, 4, f"w/upper_skin/bay_{k}"))
        parts.append(plate([0, k, 0], [1, 0, 0], [0, 1, 0], 4, 4, f"w/lower_skin/bay_{k}"))
    for k in range(3):
        parts.append(plate([0, k, 0], [1, 0, 0], [0, 0, 0.5], 4, 2, f"w/rib_{k}"))
    parts.append(plate([0, 0, 0], [0, 2, 0], [0, 0, 0.5], 8, 2, "w/spar_0"))
    parts.append(plate([1, 0, 0], [0, 2, 0], [0, 0, 0.5], 8, 2, "w/spar_1"))
    parts.append(plate([-0.3, 0, 0.25], [0.3, 0, 0.25], [0, 2, 0], 2, 8, "skin"))
    m = concatenate(parts)
    return m


def squashed(m):
    """Move one interior node of rib_1 so that one of its quads becomes a thin sliver."""
    rib = m.component_names.index("w/rib_1")
    f = m.faces[np.flatnonzero(m.component == rib)[1]]
    pts = m.points.copy()
    pts[f[2]] = pts[f[1]] + 0.97 * (pts[f[3]] - pts[f[1]]) + 0.01 * (pts[f[2]] - pts[f[1]])
    return ShellMesh(pts, m.faces, m.component, m.component_names), f


def test_family_counts_known_answer():
    fc = family_counts(box_mesh())
    assert list(fc) == ["skin", "upper skin", "lower skin", "rib", "spar"]
    assert fc["upper skin"] == {"components": 2, "elements": 32, "quads": 32, "tris": 0}
    assert fc["rib"]["elements"] == 3 * 8 and fc["spar"]["elements"] == 2 * 16 and fc["skin"]["elements"] == 16


def test_worst_and_flagged_tables():
    m, f = squashed(box_mesh())
    wt = worst_table(m, 3)
    assert [w["rank"] for w in wt] == [1, 2, 3]
    assert wt[0]["component"] == "w/rib_1" and (m.faces[wt[0]["index"]] == f).all()
    assert wt[0]["scaled_jacobian"] <= wt[1]["scaled_jacobian"] <= wt[2]["scaled_jacobian"]
    assert "scaled_jacobian" in wt[0]["failed"]
    n, rows = flagged_table(m, 100)
    assert n == quality_summary(m)["n_flagged"] > 0 and len(rows) == n
    assert rows[0]["element_id"] == wt[0]["element_id"]
    assert all(r["failed"] for r in rows)


def test_html_report_is_self_contained(tmp_path):
    m, _ = squashed(box_mesh())
    out = write_report(m, tmp_path / "rep.html", window_size=WIN, worst=4)
    text = out.read_text()
    srcs = re.findall(r'<img src="([^"]+)"', text)
    assert len(srcs) == 7 and "rep_histograms.png" in srcs and "rep_wingbox.png" in srcs
    for s in srcs:
        p = tmp_path / s
        assert p.is_file() and "/" not in s
        assert np.asarray(Image.open(p).convert("L")).std() > 5
    # the tables: per family, per component (flagged rib highlighted), worst elements
    assert "upper skin" in text and "w/rib_1" in text and 'class="flag"' in text
    assert "Worst elements" in text and "acceptance quad | tri" in text
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]     # no temporary folder left


def test_markdown_report_without_pictures(tmp_path):
    m = box_mesh()
    out = write_report(m, tmp_path / "rep.md", pictures=False)
    text = out.read_text()
    assert "| metric | min |" in text and "![" in text
    imgs = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert imgs == ["rep_histograms.png"] and (tmp_path / imgs[0]).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rep.md", "rep_histograms.png"]


def test_report_of_pipeline_result_lists_inputs_and_stages(tmp_path):
    from types import SimpleNamespace

    m = box_mesh()
    rep = {"inputs": {"surface": "/x/wing.stl", "size": 0.1, "until": "quad",
                      "layout": {"wings": [{"name": "w", "up": [0, 0, 1], "ribs": {"count": 3},
                                            "spars": {"chord_fractions": [0.2, 0.6]}}]}},
           "stages": {"load": 0.5, "remesh": 2.25}, "stage": "quad"}
    res = SimpleNamespace(mesh=m, report=rep)
    d = report_data(res)
    assert d["stages"] == {"load": 0.5, "remesh": 2.25} and d["counts"]["n_faces"] == m.n_faces
    text = write_report(res, tmp_path / "r.html", pictures=False).read_text()
    assert "wing.stl" in text and "w: 3 ribs, 2 spars" in text and "2.75" in text      # total seconds


def test_no_pictures_note_when_rendering_fails(tmp_path, monkeypatch):
    import shellmesh_mdao.render as render

    def broken(*a, **k):
        raise OutputError("rendering produced a blank picture: no working off-screen OpenGL; install ...")
    monkeypatch.setattr(render, "render_views", broken)
    text = write_report(box_mesh(), tmp_path / "r.html").read_text()
    assert "No pictures" in text and "OpenGL" in text
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.html", "r_histograms.png"]


def test_nothing_written_on_error(tmp_path, monkeypatch):
    with pytest.raises(OutputError, match="does not exist"):
        write_report(box_mesh(), tmp_path / "missing" / "r.html")
    with pytest.raises(OutputError, match="extension"):
        write_report(box_mesh(), tmp_path / "r.pdf")

    def boom(*a, **k):
        raise RuntimeError("bug")
    monkeypatch.setattr(report_mod, "_render_html", boom)
    with pytest.raises(RuntimeError):
        write_report(box_mesh(), tmp_path / "r.html", pictures=False)
    assert list(tmp_path.iterdir()) == []


def test_histograms_png(tmp_path):
    p = write_histograms(squashed(box_mesh())[0], tmp_path / "h.png")
    img = np.asarray(Image.open(p).convert("RGB"))
    assert img.shape[0] > 500 and img.std() > 10
    # quads drawn in blue and the acceptance limits in red
    px = img.reshape(-1, 3).astype(int)
    assert ((px[:, 2] > 150) & (px[:, 0] < 100)).sum() > 1000
    assert ((px[:, 0] > 150) & (px[:, 1] < 40) & (px[:, 2] < 40)).sum() > 100
