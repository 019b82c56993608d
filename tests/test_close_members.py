"""Members closer than the element size are meshed, not refused (issue 40, item 5).

Two ribs 0.4 element sizes apart and two spars 0.5 apart (at the tip; their chord fractions
are constant, so about 1 apart at the root) on the bundled wing, corner-given and station-given:
the project stage asks for a local element size of 0.7 times the gap between them
(``close_member_field``, the report's ``size_field``), the remesh, imprint and members stages
follow it, every guarantee holds, the skin quads between the two members are about the gap in
size (0.6 of it: two rows across, 0.7 of it along) and grow back to the element size without a
jump. Members that coincide (closer than ``MIN_MEMBER_GAP`` element sizes) or cross are still
refused, every pair named in one error.
"""
from __future__ import annotations

import numpy as np
import pytest

from shellmesh_mdao.core.sizefield import SIZE_GRADING, SizeField
from shellmesh_mdao.core.locator import SurfaceLocator
from shellmesh_mdao.errors import LayoutError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.guarantees import check_guarantees
from shellmesh_mdao.layout import MIN_MEMBER_GAP, load_layout, resolve_layout
from shellmesh_mdao.pipeline import run_pipeline
from shellmesh_mdao.project import CLOSE_SIZE, close_member_field
from shellmesh_mdao.remesh import RemeshCache

H = 0.1
BOX_SPAN = 5.64          # naca_wing_layout's wing box: 0.03 to 0.97 of the 6 m span
TIP_CHORD = 1.03         # ... its tip chord


def corner_layout(rib_gap=0.4, spar_gap=0.5):
    """The bundled wing's layout with a rib ``rib_gap`` element sizes behind rib 3 and a spar
    ``spar_gap`` element sizes (at the tip) ahead of the rear spar."""
    lay = naca_wing_layout()
    w = lay["wings"][0]
    eta = list(np.linspace(0.0, 1.0, 8))
    eta.insert(4, eta[3] + rib_gap * H / BOX_SPAN)
    w["ribs"] = {"eta": [float(e) for e in eta]}
    w["spars"] = {"chord_fractions": [0.15, 0.65 - spar_gap * H / TIP_CHORD, 0.65]}
    return lay


def station_layout(rib_gap=0.4, spar_gap=0.5):
    """The same members on a wing given by its stations (y from 0.2 to 5.8)."""
    eta = list(np.linspace(0.0, 1.0, 8))
    eta.insert(4, eta[3] + rib_gap * H / 5.6)
    return {"wings": [{"name": "w", "axis": "y", "root": 0.2, "tip": 5.8, "up": [0, 0, 1],
                       "ribs": {"eta": [float(e) for e in eta]},
                       "spars": {"chord_fractions": [0.15, 0.65 - spar_gap * H / 1.033, 0.65]}}]}


@pytest.fixture(scope="module")
def wing():
    return naca_wing()


@pytest.fixture(scope="module", params=["corner", "station"])
def run(request, wing):
    lay = corner_layout() if request.param == "corner" else station_layout()
    r = run_pipeline(wing, lay, H, progress=False, remesh_cache=False)
    return r, ("wing" if request.param == "corner" else "w")


# ============================================================================ the size field
def test_size_field_is_exact_and_scales():
    rng = np.random.default_rng(0)
    pts, sizes = rng.uniform(-1, 1, (40, 3)), rng.uniform(0.05, 0.3, 40)
    f = SizeField(pts, sizes)
    x = rng.uniform(-2, 2, (500, 3))
    brute = np.minimum(0.4, (sizes[None] + SIZE_GRADING * np.linalg.norm(x[:, None] - pts[None], axis=2)).min(1))
    assert np.allclose(f.at(x, 0.4), brute, rtol=0, atol=1e-12)
    g = f.scaled(2.0)                                # the remesh's units: sizes and grading doubled
    assert np.allclose(g.at(x, 0.8), 2.0 * brute, rtol=0, atol=1e-12)
    assert (SizeField().at(x, 0.4) == 0.4).all() and SizeField().empty
    assert f.digest() == SizeField(pts.copy(), sizes.copy()).digest() != g.digest()
    with pytest.raises(ValueError, match="one size per point"):
        SizeField(pts, sizes[:3])


def test_close_member_field_on_the_bundled_wing(wing):
    loc = SurfaceLocator(wing.points, wing.faces[:, :3])
    assert close_member_field(loc, load_layout(naca_wing_layout()), H).empty      # members apart: nothing
    f = close_member_field(loc, load_layout(corner_layout()), H)
    why = {tuple(r["members"]): r for r in f.reasons}
    assert set(why) == {("wing/spar_1", "wing/spar_2"), ("wing/rib_3", "wing/rib_4")}
    rib = why[("wing/rib_3", "wing/rib_4")]
    assert 0.39 * H < rib["gap"] < 0.42 * H and rib["size"] == pytest.approx(CLOSE_SIZE * rib["gap"])
    assert 0.49 * H < why[("wing/spar_1", "wing/spar_2")]["gap"] < 0.52 * H     # at the tip
    assert f.sizes.min() == pytest.approx(CLOSE_SIZE * rib["gap"]) and f.sizes.max() < CLOSE_SIZE * H
    # the field asks for the element size again a few sizes away from both pairs
    far = np.array([[0.8, 4.5, 0.3]])
    assert f.at(far, H)[0] == H


def test_the_remesh_cache_tells_close_layouts_apart(wing):
    f = SizeField(np.zeros((1, 3)), [0.05])
    k0 = RemeshCache.key(wing, H, None)
    assert RemeshCache.key(wing, H, None, SizeField()) == k0 != RemeshCache.key(wing, H, None, f)


# ============================================================================ refusals that remain
def test_coincident_members_are_refused_naming_every_pair():
    lay = naca_wing_layout()
    w = lay["wings"][0]
    w["ribs"] = {"eta": [0.0, 0.3, 0.3001, 0.6, 0.6002, 1.0]}
    w["spars"] = {"chord_fractions": [0.15, 0.1502, 0.65]}
    with pytest.raises(LayoutError) as e:
        load_layout(lay).validate(H)
    msg = str(e.value)
    assert msg.startswith(f"members coincide or cross at element size {H:g} (closer than {MIN_MEMBER_GAP:g} element "
                          "sizes")
    for pair in ("ribs 'wing/rib_1' (eta=0.3) and 'wing/rib_2' (eta=0.3001)",
                 "ribs 'wing/rib_3' (eta=0.6) and 'wing/rib_4' (eta=0.6002)",
                 "spars 'wing/spar_0' (c=0.15) and 'wing/spar_1' (c=0.1502)"):
        assert pair in msg
    assert "remove one member of each pair or move them apart" in msg and "element size below" in msg
    # the same layout meshes at a size 20x smaller; members 0.2-1 element sizes apart pass the validator
    load_layout(lay).validate(H / 100)
    load_layout(corner_layout(0.25, 0.3)).validate(H)


def test_coincident_station_ribs_are_refused_naming_every_pair(wing):
    d = station_layout()
    d["wings"][0]["ribs"] = {"eta": [0.0, 0.3, 0.3005, 0.6, 0.6002, 1.0]}
    with pytest.raises(LayoutError, match=r"members coincide or cross at element size 0.1 .*ribs 'w/rib_1' and "
                                          r"'w/rib_2' are .* apart at a spar; ribs 'w/rib_3' and 'w/rib_4' are .* "
                                          r"apart at a spar: remove one member of each pair"):
        resolve_layout(load_layout(d), wing.points, wing.faces[:, :3], H)
    # 0.4 element sizes apart: resolved, the ribs keep their stations' spacing at the spars
    lay = resolve_layout(load_layout(station_layout()), wing.points, wing.faces[:, :3], H)
    assert not lay.station_wings[0].close_pairs


# ============================================================================ meshed, graded
def _skin_quads(mesh):
    P, F = mesh.points, mesh.faces[:, :4]
    member = np.array([("/rib_" in n or "/spar_" in n or "_web" in n) for n in mesh.component_names])
    skin = ~member[mesh.component]
    size = np.sqrt(0.5 * np.linalg.norm(np.cross(P[F[:, 2]] - P[F[:, 0]], P[F[:, 3]] - P[F[:, 1]]), axis=1))
    L = np.linalg.norm(P[F] - P[np.roll(F, -1, axis=1)], axis=2)
    return skin, P[F].mean(1), size, L.max(1) / L.min(1)


def _around(result, a, b):
    """Per skin quad: its distance (in element sizes) from the stretch between members ``a`` and
    ``b`` (0 between them), and whether it is at least an element size from every other member
    and inside ``a``'s bounds."""
    skin, C, _, _ = _skin_quads(result.mesh)
    M = {m.name: m for m in result.layout.members()}
    ma, mb = M[a], M[b]
    sa = np.sign((mb.plane_point - ma.plane_point) @ ma.plane_normal)
    sb = np.sign((ma.plane_point - mb.plane_point) @ mb.plane_normal)
    da, db = sa * ((C - ma.plane_point) @ ma.plane_normal), sb * ((C - mb.plane_point) @ mb.plane_normal)
    dist = np.where((da > 0) & (db > 0), 0.0, np.minimum(np.abs(da), np.abs(db))) / H
    ok = skin.copy()
    for m in M.values():
        if m.name not in (a, b):
            ok &= np.abs((C - m.plane_point) @ m.plane_normal) > H
    for p, n in ma.bound_planes:
        ok &= (C - p) @ n > H
    return dist, ok


def test_close_members_mesh_with_every_guarantee(run):
    r, w = run
    g = check_guarantees(r)
    assert g["min_scaled_jacobian"] > 0.2 and g["n_poor"] == 0
    sf = r.report["size_field"]
    assert {tuple(x["members"]) for x in sf["reasons"]} == {(f"{w}/rib_3", f"{w}/rib_4"), (f"{w}/spar_1", f"{w}/spar_2")}
    assert sf["max"] == H and sf["min"] == pytest.approx(CLOSE_SIZE * 0.4 * H, rel=0.03)
    names = set(r.mesh.component_names)
    assert {f"{w}/rib_3", f"{w}/rib_4", f"{w}/spar_1", f"{w}/spar_2"} <= names


def test_elements_between_close_ribs_are_about_the_gap_and_grow_back(run):
    r, w = run
    _, _, size, aspect = _skin_quads(r.mesh)
    dist, ok = _around(r, f"{w}/rib_3", f"{w}/rib_4")
    gap = 0.4 * H
    between = ok & (dist == 0)
    assert between.sum() >= 30
    med = float(np.median(size[between]))
    assert 0.45 * gap < med < 0.9 * gap, med / gap
    assert np.median(aspect[between]) < 2.0 and aspect[between].max() < 4.0
    # graded back: sizes grow with the distance from the pair, to the element size's share
    # of this wing (its quads away from any member: 0.6-0.7 element sizes) 4-8 sizes away
    rings = [float(np.median(size[ok & (dist > lo) & (dist <= hi)])) for lo, hi in ((0, 1), (1, 3), (3, 5), (5, 8))]
    assert med < rings[0] < rings[1] < rings[2] * 1.05 and rings[3] > 0.55 * H, rings
    # without a jump: neighbouring skin quads within 6 sizes differ as they do on the plain wing
    F = r.mesh.faces[:, :4]
    E = np.stack([F, np.roll(F, -1, axis=1)], 2).reshape(-1, 2)
    key = np.sort(E, axis=1) @ np.array([r.mesh.n_points, 1])
    fid = np.repeat(np.arange(len(F)), 4)
    o = np.argsort(key, kind="stable")
    same = key[o][1:] == key[o][:-1]
    f0, f1 = fid[o][:-1][same], fid[o][1:][same]
    near = ok & (dist < 6)
    sel = near[f0] & near[f1]
    ratio = np.maximum(size[f0], size[f1])[sel] / np.minimum(size[f0], size[f1])[sel]
    assert np.percentile(ratio, 90) < 1.5


def test_elements_between_close_spars_follow_their_gap(run):
    r, w = run
    _, C, size, aspect = _skin_quads(r.mesh)
    dist, ok = _around(r, f"{w}/spar_1", f"{w}/spar_2")
    between = ok & (dist == 0)
    # the spars are 0.5 element sizes apart at the tip and about 1 at the root: the quads between
    # them are about 0.6 of the local gap, smaller towards the tip
    assert between.sum() >= 50
    y = C[:, 1]
    tip = between & (y > 4.8)
    root = between & (y < 1.5)
    assert np.median(size[tip]) < 0.4 * H and np.median(size[tip]) < np.median(size[root]) < 0.75 * H
    assert np.median(aspect[between]) < 1.8
