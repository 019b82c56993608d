"""Full-chord ribs (a wing with fewer than two spars: each rib is one closed loop around the
section, leading edge to trailing edge), issue 8.

* projection: the loop's end seeds are the wing-box corners' leading/trailing-edge points,
  which lie ON the skin, so the +-up rays from them graze it; they now go to their closest
  skin point (cessna210 root rib, stress sweep seeds 33/41/89: used to raise ProjectionError);
* thin wedges: ``split_thin`` used to split the loop's chain edges near a sharp edge into up
  to 16 pieces, fanning the skin triangles there (skin angles down to 3 degrees, scaled
  Jacobian 0.05); a fan now keeps at least 15 degrees of the skin angle per piece;
* end to end on the stress sweep's draws (slow): swept_wing seed 3 meets every guarantee;
* a sharp edge: the straight wing's leading edge is a 6.9-degree wedge, where no quad can have
  a scaled Jacobian above sin(6.9 deg) = 0.12; full-chord ribs through it are refused with a
  documented LayoutError (stress seed 42 used to leave one such quad per rib).
"""
from __future__ import annotations

import numpy as np
import pytest

from shellmesh_mdao import pipeline as pl
from shellmesh_mdao.benchmarks import stress as SL
from shellmesh_mdao.errors import ProjectionError
from shellmesh_mdao.guarantees import check_guarantees
from shellmesh_mdao.imprint import chain_specs, imprint_chains
from shellmesh_mdao.layout import layout_from_manifest
from shellmesh_mdao.members.spacing import split_thin_chain_edges
from shellmesh_mdao.project import project_layout, project_wing_stations
from shellmesh_mdao.quality import element_quality


def _surface(geometry_dir, manifest, name):
    st = pl.stage_load(geometry_dir / manifest["geometries"][name]["file"], SL.BASE_SIZES[name])
    return st


def test_full_chord_root_rib_projects(geometry_dir, manifest):
    """cessna210, one spar, a rib at eta 0.0102 (stress seed 33): its leading- and trailing-edge
    seeds lie on the skin, the rays from them miss; the projection takes their closest skin
    points and the rib's loop is imprinted closed."""
    lay = layout_from_manifest(manifest, "cessna210", ribs=[0.0102, 0.5, 0.8501], spars=[0.73])
    st = _surface(geometry_dir, manifest, "cessna210")
    loc = st.locator
    rib = next(m for m in lay.members() if m.name == "right_wing/rib_0")
    seeds = rib.seed_points(5)
    # the cause: the end seeds are on the skin (closest distance ~0) and the rays graze it
    _, _, d = loc.closest(seeds[[0, -1]])
    assert d.max() <= 1e-4 * loc.diagonal
    with pytest.raises(ProjectionError, match="rays miss the skin"):
        project_wing_stations(loc, rib, seeds, name=rib.name)
    pr = project_layout(loc, lay)
    pm = pr["right_wing/rib_0"]
    assert (pm.upper_tri >= 0).all() and (pm.lower_tri >= 0).all()
    # ends: the closest skin point, the same for both sides
    assert np.array_equal(pm.upper[[0, -1]], pm.lower[[0, -1]])
    assert np.linalg.norm(pm.upper[[0, -1]] - seeds[[0, -1]], axis=1).max() <= 1e-4 * loc.diagonal
    # interior seeds still ray-cast: upper above lower
    up = rib.up
    assert ((pm.upper[1:-1] - pm.lower[1:-1]) @ up > 0).all()
    specs = [s for s in chain_specs(lay, pr) if s.member == "right_wing/rib_0"]
    assert [s.side for s in specs] == ["loop"]
    P, T = st.surface.points, st.surface.faces[:, :3]
    _, res = imprint_chains(st.surface, P, T, specs, snap=0.25, locator=loc)
    assert res[0].arc.closed and len(res[0].vertices) >= 10


def test_rib_outside_the_wing_still_refused(geometry_dir, manifest):
    """Only the two outline ends are exempt: a full-chord rib beyond the tip still raises."""
    lay = layout_from_manifest(manifest, "swept_wing", ribs=[0.2, 0.6], spars=[0.4])
    st = _surface(geometry_dir, manifest, "swept_wing")
    w = lay.wings[0]
    import dataclasses
    far = dataclasses.replace(w, tip_le=tuple(np.add(w.tip_le, (0, 0, 1.0))),
                              tip_te=tuple(np.add(w.tip_te, (0, 0, 1.0))))
    bad = dataclasses.replace(lay, wings=(far,) + lay.wings[1:])
    with pytest.raises(ProjectionError, match="rays miss the skin"):
        project_layout(st.locator, bad)


def _fan_case():
    """A flat strip: a thin member side (chain 0-1, opposite chain far below it) whose chain
    edge is long; the two skin triangles on it have apex angles ~53 and ~8 degrees."""
    from types import SimpleNamespace

    P = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 1.0, 0], [0.5, -7.0, 0]])
    F = np.array([[0, 1, 2], [1, 0, 3]])
    C = np.zeros(2, np.int32)
    FE = np.array([[0, 1]])
    FID = np.zeros(1, np.int32)
    arc = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    other = np.array([[0.0, -0.05, 0], [1.0, -0.05, 0]])
    m = SimpleNamespace(sides=[np.array([0, 1]), np.array([4, 5])], side_arcs=[arc, None], name="m")
    P = np.vstack([P, other])
    return P, F, C, FE, FID, m


def test_split_thin_limits_fans():
    """A chain edge 20x longer than the member height wants 14 pieces; the skin angle opposite
    it is ~8 degrees on one side, so it is not split (the old rule fanned it into 14 triangles
    of under 1 degree); with a 53-degree apex on both sides it is split into 3 pieces, every
    fan triangle keeping 15 degrees."""
    P, F, C, FE, FID, m = _fan_case()
    P2, F2, *_ = split_thin_chain_edges(P.copy(), F.copy(), C, FE, FID, [m], size=0.1)
    assert len(P2) == len(P) and np.array_equal(F2, F)
    P[3] = [0.5, -1.0, 0]                                   # apex angles ~53 degrees on both sides
    P3, F3, *_ = split_thin_chain_edges(P.copy(), F.copy(), C, FE, FID, [m], size=0.1)
    k = len(F3) // 2
    assert k == 3                                           # floor(53.1 / 15)
    ang = element_quality(P3, F3)["min_angle"]
    assert ang.min() >= 15.0 and len(P3) == len(P) + k - 1


def test_split_thin_keeps_fans_at_a_fixed_apex_open():
    """A ladder split of a thin chain edge (the opposite side's vertices at x = 0.4 and 0.5 across
    it) would cut the 90-degree apex angles of both skin faces into 33.7, 11.3 and 45 degrees:
    above the imprint's 10-degree floor, so it is taken while the apex may move. When the apex
    is a fixed skin vertex (a chain's crossing with a crease: the final quad at that corner keeps
    the angle, and a quad with an 11.3-degree corner has a scaled Jacobian of at most 0.196) no
    fan triangle may have an angle there below min_fan_angle (15): the best single ladder point
    (x = 0.5, 45 and 45 degrees) is taken instead (cessna210 stress seed 41: a 10.5-degree corner
    at a rib's trailing-edge crossing, a final quad of 0.183)."""
    from types import SimpleNamespace

    P = np.array([[0.0, 0, 0], [1.0, 0, 0], [0.5, 0.5, 0], [0.5, -0.5, 0],
                  [0.0, -0.05, 0], [0.4, -0.05, 0], [0.5, -0.05, 0], [1.0, -0.05, 0]])
    F = np.array([[0, 1, 2], [1, 0, 3]])
    C = np.zeros(2, np.int32)
    FE, FID = np.array([[0, 1]]), np.zeros(1, np.int32)

    def split(fixed):                                       # one round: the first split only
        m = SimpleNamespace(sides=[np.array([0, 1]), np.array([4, 5, 6, 7])],
                            side_arcs=[np.array([[0.0, 0, 0], [1.0, 0, 0]]), None], name="m")
        P2, F2, *_ = split_thin_chain_edges(P.copy(), F.copy(), C, FE, FID, [m], size=0.1, rounds=1, fixed=fixed)
        return P2[len(P):], P2, F2

    free = np.zeros(len(P), bool)
    new, _, _ = split(free)
    assert np.allclose(np.sort(new[:, 0]), [0.4, 0.5])
    fixed = free.copy()
    fixed[[2, 3]] = True
    new, P2, F2 = split(fixed)
    assert np.allclose(new[:, 0], [0.5]) and len(F2) == 4
    apex = np.isin(F2, [2, 3])
    ang = element_quality(P2, F2)["min_angle"]
    assert ang.min() >= 15.0 and apex.any(1).all()


def _run_draw(geometry_dir, manifest, seed, geometry, options=None):
    c = SL.draw_case(seed, geometry, manifest=manifest, geometry_dir=geometry_dir)
    lay = layout_from_manifest(manifest, geometry, ribs=list(c["ribs"]), spars=list(c["spars"]))
    res = pl.run_pipeline(geometry_dir / manifest["geometries"][geometry]["file"], lay, c["size"], progress=False,
                          options=options)
    return c, res


@pytest.mark.slow
def test_swept_wing_seed3(geometry_dir, manifest):
    """Stress seed 3 (3 ribs, one spar at 0.474, size 0.0194): was 36 poor elements (min 0.049)
    beside the ribs near the thin trailing edge."""
    c, res = _run_draw(geometry_dir, manifest, 3, "swept_wing")
    assert len(c["spars"]) == 1
    check_guarantees(res)


@pytest.mark.slow
def test_full_chord_rib_through_a_sharp_edge_is_refused(geometry_dir, manifest):
    """The straight wing's leading edge is a 6.9-degree wedge: a full-chord rib (one spar) has a
    corner that sharp, where no quad can have a scaled Jacobian above sin(6.9 deg) = 0.12 (stress
    seed 42 left one such quad per rib). The imprint refuses it from the exact sections, naming
    every such rib, its corner and the fix; the sweep's independent section check agrees that the
    layout is tight."""
    from shellmesh_mdao.errors import LayoutError
    lay = layout_from_manifest(manifest, "straight_wing", ribs=[0.2, 0.5, 0.8], spars=[0.5])
    with pytest.raises(LayoutError, match=r"full-chord members cut a sharp edge of the skin: 'wing/rib_0': a "
                                          r"[5-9]\.\d deg corner at \[-0.75, .*'wing/rib_1'.*'wing/rib_2'.*below "
                                          r"the 0.2 scaled-Jacobian guarantee at any element size; end the ribs on "
                                          r"spars"):
        pl.run_pipeline(geometry_dir / "straight_wing.stl", lay, 0.05, until="members", progress=False)
    t = SL.layout_tightness(manifest, {"geometry": "straight_wing", "ribs": [0.2, 0.5, 0.8], "spars": [0.5],
                                       "size": 0.05}, geometry_dir)
    assert 6.0 < t["wedge"] < 8.0 and "full-chord rib section" in t["tight"]
    # with two spars the ribs end on them: no loop, no sharp corner
    lay2 = layout_from_manifest(manifest, "straight_wing", ribs=[0.2, 0.5, 0.8], spars=[0.3, 0.6])
    res = pl.run_pipeline(geometry_dir / "straight_wing.stl", lay2, 0.05, until="members", progress=False)
    assert res.stage == "members"



@pytest.mark.slow
def test_cessna_one_spar_trailing_edge_members(geometry_dir, manifest):
    """cessna210 with one spar (stress seed 89): the full-chord ribs' thin trailing-edge wedges
    kept a long chain edge opposite short ones (no fan of the skin allowed), so the members stage
    left 7-degree rib triangles in the corners. ``split_thin`` now splits such an edge at the
    opposite side's vertices (a ladder): member triangles keep the skin's 10-degree floor. (They
    were all at or above the rib's own 14.3-degree trailing-edge corner until the imprint's snap
    fix, d5b79c3, moved the chain vertices: one rib triangle is now 11.4 degrees, in a trapezoid
    of the wedge 0.2 to 0.08 tall and 0.41 long whose long lower side cannot be fanned, the skin
    angle opposite it being 20 degrees.)"""
    from shellmesh_mdao.members.meshing import tri_min_angles
    c = SL.draw_case(89, "cessna210", manifest=manifest, geometry_dir=geometry_dir)
    lay = layout_from_manifest(manifest, "cessna210", ribs=list(c["ribs"]), spars=list(c["spars"]))
    res = pl.run_pipeline(geometry_dir / manifest["geometries"]["cessna210"]["file"], lay, c["size"],
                          until="members", progress=False)
    m = res.mesh
    m.validate()
    ang = tri_min_angles(m.points, m.faces[:, :3])
    skin = np.array(["skin" in m.component_names[i] for i in m.component])
    assert ang[~skin].min() >= 10.0
    assert ang[skin].min() >= 9.99


@pytest.mark.slow
def test_cessna_one_spar_seed33(geometry_dir, manifest):
    """cessna210, one spar at 0.73 (stress seed 33): was 1 poor quad (0.188) from an 8-degree rib
    triangle in a trailing-edge corner; now every guarantee holds."""
    c, res = _run_draw(geometry_dir, manifest, 33, "cessna210")
    assert len(c["spars"]) == 1
    sj = element_quality(res.mesh.points, res.mesh.faces)["scaled_jacobian"]
    assert sj.min() > 0.2
    check_guarantees(res)


@pytest.mark.slow
def test_cessna_one_spar_seed89_end_to_end(geometry_dir, manifest):
    """Stress seed 89 (12 ribs from eta 0.001 to 0.9997, one spar at 0.75, size 0.5088): was 2 poor
    elements (min 0.150) in the ribs' thin trailing-edge corners; every guarantee holds now."""
    c, res = _run_draw(geometry_dir, manifest, 89, "cessna210")
    assert len(c["spars"]) == 1
    check_guarantees(res)


@pytest.mark.slow
def test_cessna_rib_at_the_tip_keeps_its_trailing_edge_corner(geometry_dir, manifest):
    """Stress seed 157 (6 ribs from eta 0 to 1, one spar at 0.077, size 0.578): the full-chord rib
    at eta 1.0 lies where the trailing edge is thinner than the skin faces. The closest points of
    two of its chain vertices on the exact section were on the far side of it (once in the cut,
    then in the smoothing rounds of improve_skin), so its outline ran back along the lower skin
    and forth again: a 0.2-degree corner, refused as a sharp edge of the skin while the section's
    trailing-edge wedge is 14.3 degrees. Chain vertices now keep their order along the arc: the
    outline keeps the 14.3-degree corner and every guarantee holds."""
    c, res = _run_draw(geometry_dir, manifest, 157, "cessna210")
    assert len(c["spars"]) == 1 and 1.0 in c["ribs"]
    check_guarantees(res)


@pytest.mark.slow
def test_quad_stage_repairs_a_poor_element(geometry_dir, manifest, monkeypatch):
    """The quad stage's last resort. No run of the corpus leaves a poor element for it now (with
    smooth_energy='squared', 2 final steps and the imprint's snap at 0.25 stress seed 89 had one at
    0.196 until the closest points' tie rule of 2026-11-24), so one is made: after the final
    smoothing, a member node is moved in its plane towards the far corner of one of its quads
    until an element's scaled Jacobian is between 0.05 and 0.2. untangle on the two rings around
    it moves vertices along their supports and lifts every element above 0.2 (report key
    ``poor_repair``), and the moved nodes stay on their supports."""
    from shellmesh_mdao.mesh import ShellMesh
    from shellmesh_mdao.quality import scaled_jacobian
    import shellmesh_mdao.quad.finish as F
    from shellmesh_mdao.core.supports import PLANE
    finish = F.finish_quads
    made = []

    def with_a_poor_element(q, sup, size, **kw):
        # a member quad with a node free in its plane (v) and the corner across from it (w, on
        # the member too: the plane, or its outline)
        quads = q.faces[q.faces[:, 3] >= 0]
        fi, ki = np.nonzero(sup.kind[quads] == PLANE)
        j = len(fi) // 2
        v, w = quads[fi[j], ki[j]], quads[fi[j], (ki[j] + 2) % 4]
        for t in np.linspace(0.05, 0.95, 91):
            P = q.points.copy()
            P[v] += t * (P[w] - P[v])
            sj = scaled_jacobian(P, q.faces)
            if sj.min() <= 0.2:
                break
        made.append(float(sj.min()))
        return finish(ShellMesh(P, q.faces, q.component, list(q.component_names), q.fixed_vertices,
                                q.feature_edges, q.feature_edge_ids), sup, size, **kw)

    monkeypatch.setattr(F, "finish_quads", with_a_poor_element)
    _, res = _run_draw(geometry_dir, manifest, 89, "cessna210")
    assert made and all(0.05 <= m <= 0.2 for m in made)
    rep = res.report["poor_repair"]
    assert rep["elements_before"] >= 1 and rep["min_before"] in made
    assert rep["elements_after"] == 0 and rep["min_after"] > 0.2 and rep["moves"] > 0
    q = res.mesh
    assert scaled_jacobian(q.points, q.faces).min() > 0.2 and res.report["poor_elements"]["count"] == 0
    sup = res.state.supports
    assert sup.distance(q.points)[sup.kind == PLANE].max() <= 1e-9 * q.diagonal
