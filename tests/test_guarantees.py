"""shellmesh_mdao.guarantees.check_guarantees: it accepts the pipeline's mesh of a small wing and
returns its figures, and it rejects, with a MeshValidationError naming the guarantee, a copy of
that result broken in one way each: a folded quad, a triangle, a node off the surface, an
unshared junction, a hole in the skin, ..."""
from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from shellmesh_mdao import pipeline as pl
from shellmesh_mdao.errors import MeshValidationError, ShellMeshError
from shellmesh_mdao.geometry import naca_wing, naca_wing_layout
from shellmesh_mdao.guarantees import GUARANTEES, check_guarantees, member_faces
from shellmesh_mdao.mesh import ShellMesh
from shellmesh_mdao.quality import scaled_jacobian
from shellmesh_mdao.core.supports import PLANE, SURFACE

WING = dict(span=2.0, root_chord=1.0, tip_chord=0.6, sweep_deg=10.0, dihedral_deg=3.0)
SIZE = 0.05


@pytest.fixture(scope="module")
def good():
    """The small wing with three spars (T- and X-junctions), meshed to the end."""
    surface = naca_wing(naca="2412", n_chord=32, n_span=16, **WING)
    return pl.run_pipeline(surface, naca_wing_layout(ribs=5, spars=(0.15, 0.4, 0.65), **WING), SIZE,
                           progress=False)


def edited(res, points=None, faces=None, component=None, feature_edges=None, feature_edge_ids=None, **report):
    """``res`` with its mesh rebuilt from the given arrays (the others kept) and report keys replaced."""
    q = res.mesh
    mesh = ShellMesh(q.points if points is None else points, q.faces if faces is None else faces,
                     q.component if component is None else component, list(q.component_names), q.fixed_vertices,
                     q.feature_edges if feature_edges is None else feature_edges,
                     q.feature_edge_ids if feature_edge_ids is None else feature_edge_ids)
    rep = copy.deepcopy(res.report)
    rep.update(report)
    return dataclasses.replace(res, mesh=mesh, report=rep)


def missed(res, name, **kw):
    with pytest.raises(MeshValidationError, match=f"mesh guarantee '{name}' missed") as e:
        check_guarantees(res, **kw)
    return str(e.value)


def best_face(res, members: bool):
    """The quad of the highest scaled Jacobian among the member (or skin) faces with no side on a
    feature edge (a face inside a member or a skin bay)."""
    q = res.mesh
    topo = q.topology()
    feature = np.zeros(len(topo.edges) + 1, bool)
    feature[topo.edge_ids(q.feature_edges)] = True
    feature[-1] = False                                  # the -1 side of triangles
    sel = (member_faces(q, res.state.infos) == members) & ~feature[topo.face_edges].any(axis=1)
    assert sel.any()
    sj = np.where(sel, scaled_jacobian(q.points, q.faces), -np.inf)
    return int(np.argmax(sj))


@pytest.fixture(scope="module")
def on_surface(good):
    """``good`` with every skin node projected onto the input surface (undoing planarize's moves
    off it) and the report saying so: it meets every guarantee too."""
    q, sup = good.mesh, good.state.supports
    skin = np.flatnonzero(sup.kind == SURFACE)
    pts = q.points.copy()
    pts[skin] = sup.project(q.points, skin)[0]
    off = dict(good.report["off_surface"], count=0, max_distance=float(sup.distance(pts, skin).max()))
    res = edited(good, points=pts, off_surface=off, planarize=None)
    check_guarantees(res)
    return res


def test_accepts_the_pipeline_mesh_and_returns_its_figures(good):
    f = check_guarantees(good)
    q = good.mesh
    assert f["n_elements"] == q.n_faces and f["n_points"] == q.n_points
    assert f["min_scaled_jacobian"] > 0.2 and f["n_poor"] == 0
    assert f["quality"]["scaled_jacobian"].shape == (q.n_faces,)
    assert set(f["junction_valence"]) <= {2, 3, 4} and f["junction_valence"][3] > 0 and f["junction_valence"][4] > 0
    assert f["skin_boundary_edges"] == 0 and f["boundary_edges"] == 0
    assert f["max_plane_distance"] <= 1e-9 * q.diagonal and f["max_skin_distance"] <= 5e-3 * q.diagonal
    # planarize moved skin nodes off the input on purpose, by at most planar_offset * size
    moved = good.report["planarize"]["moved"]
    assert 0 < f["skin_nodes_off"] <= moved and f["planarize_moved"] == moved
    assert f["max_skin_distance"] <= good.state.options.quad.planar_offset * SIZE * (1 + 1e-9)
    assert 0 < f["skin_on_surface_share"] < 1 and 0 < f["fixed_share"] < 0.05
    assert issubclass(MeshValidationError, ShellMeshError) and len(set(GUARANTEES)) == 17


def test_rejects_a_result_that_is_not_the_final_mesh(good):
    msg = missed(dataclasses.replace(good, stage="smooth"), "final mesh")
    assert "'smooth'" in msg


def test_rejects_a_triangle(good):
    q = good.mesh
    k = best_face(good, members=False)
    a, b, c, d = q.faces[k]
    faces = np.vstack([q.faces, [[a, c, d, -1]]])
    faces[k] = [a, b, c, -1]
    msg = missed(edited(good, faces=faces, component=np.append(q.component, q.component[k])), "all quads")
    assert f"at element {k} " in msg and "2 triangles" in msg


def test_rejects_a_folded_quad(good):
    q = good.mesh
    k = best_face(good, members=False)
    faces = q.faces.copy()
    faces[k] = faces[k][[0, 2, 1, 3]]                   # a bow tie
    msg = missed(edited(good, faces=faces), "scaled Jacobian")
    assert f"at element {k} " in msg and "lowest -" in msg
    # with a bound below every element (as for a layout of shallow crossings), the report is the next miss
    missed(edited(good, faces=faces), "poor elements reported", min_sj=-2.0)


def test_rejects_an_unreported_poor_element(good):
    poor = dict(good.report["poor_elements"], count=1, elements=[7])
    missed(edited(good, poor_elements=poor), "poor elements reported")


def test_rejects_duplicate_hanging_and_unreferenced_nodes(good):
    q = good.mesh
    msg = missed(edited(good, points=np.vstack([q.points, q.points[5]])), "no duplicate points")
    assert f"nodes 5 and {q.n_points}" in msg
    far = q.points.max(axis=0) + 1.0
    msg = missed(edited(good, points=np.vstack([q.points, far])), "no unreferenced points")
    assert f"node {q.n_points} at" in msg
    # a skin quad cut in two by the midpoints of two opposite sides: its neighbours across those
    # sides keep the whole edges, so the midpoints hang
    k = best_face(good, members=False)
    a, b, c, d = q.faces[k]
    n = q.n_points
    pts = np.vstack([q.points, 0.5 * (q.points[a] + q.points[b]), 0.5 * (q.points[c] + q.points[d])])
    faces = np.vstack([q.faces, [[n, b, c, n + 1]]])
    faces[k] = [a, n, n + 1, d]
    msg = missed(edited(good, points=pts, faces=faces, component=np.append(q.component, q.component[k])),
                 "no hanging nodes")
    assert f"node {n} " in msg or f"node {n + 1} " in msg


def test_rejects_an_open_skin_and_a_free_member_edge(good):
    q = good.mesh
    keep = np.ones(q.n_faces, bool)
    keep[best_face(good, members=False)] = False
    hole = edited(good, faces=q.faces[keep], component=q.component[keep])
    assert "boundary edges of the skin" in missed(hole, "closed skin")
    missed(hole, "no free member edge", input_closed=False)      # an open input: the skin may be open
    keep = np.ones(q.n_faces, bool)
    keep[best_face(good, members=True)] = False
    missed(edited(good, faces=q.faces[keep], component=q.component[keep]), "no free member edge")
    # explicit members may end inside the wing: free edges allowed
    check_guarantees(edited(good, faces=q.faces[keep], component=q.component[keep]), free_edges=True)


def test_rejects_unshared_junctions(good):
    q = good.mesh
    topo = q.topology()
    fe = q.feature_edges[q.feature_edge_ids >= 0]
    # a junction that is not a mesh edge: a diagonal of a member quad marked as a member's feature edge
    k = best_face(good, members=True)
    diag = q.faces[k][[0, 2]]
    msg = missed(edited(good, feature_edges=np.vstack([q.feature_edges, diag]),
                        feature_edge_ids=np.append(q.feature_edge_ids, 0)), "junctions are mesh edges")
    assert f"edge {min(diag)}-{max(diag)}" in msg
    # a member face twice along a skin-member junction: 5 faces on that edge
    e = fe[np.flatnonzero(topo.valence[topo.edge_ids(fe)] == 3)[0]]
    mem = member_faces(q, good.state.infos)
    f = next(i for i in topo.faces_of(int(topo.edge_ids(e[None])[0])) if mem[i])
    faces = np.vstack([q.faces, q.faces[[f, f]]])
    msg = missed(edited(good, faces=faces, component=np.append(q.component, q.component[[f, f]])),
                 "junction valence")
    assert "has 5" in msg and f"edge {e.min()}-{e.max()}" in msg


def test_rejects_nodes_off_their_supports(good, on_surface):
    q, sup = good.mesh, good.state.supports
    diag = q.diagonal
    # a member node moved off its plane by 1e-6 of the diagonal, along the plane's normal
    v = int(np.flatnonzero(sup.kind == PLANE)[0])
    pts = q.points.copy()
    pts[v] += 1e-6 * diag * sup.planes[sup.ref[v], 1]
    assert f"node {v} " in missed(edited(good, points=pts), "nodes on member planes")
    # a skin node 4 % of an element size off the input, along the normal, that the report does not count
    q = on_surface.mesh
    v = next(int(u) for u in q.faces[best_face(on_surface, members=False)] if sup.kind[u] == SURFACE)
    pts = q.points.copy()
    pts[v] += 0.04 * SIZE * q.vertex_normals()[v]
    assert f"node {v} " in missed(edited(on_surface, points=pts), "off-surface nodes reported")
    # too many skin nodes off the input, though reported: 1 % of them, by 1e-5 of the diagonal
    skin = np.flatnonzero(sup.kind == SURFACE)
    nodes = skin[:: 97][: len(skin) // 100 + 1]
    pts = q.points.copy()
    pts[nodes] += 1e-5 * diag * q.vertex_normals()[nodes]
    d = sup.distance(pts, skin)
    off = dict(on_surface.report["off_surface"], count=int((d > 1e-6 * diag).sum()), max_distance=float(d.max()))
    msg = missed(edited(on_surface, points=pts, off_surface=off), "skin nodes on the surface")
    assert "% of the skin nodes on the input surface" in msg
    # one node far off (1 % of the diagonal), reported
    pts = q.points.copy()
    pts[v] += 0.01 * diag * q.vertex_normals()[v]
    off = dict(off, count=1, max_distance=float(sup.distance(pts, skin).max()))
    msg = missed(edited(on_surface, points=pts, off_surface=off), "skin nodes on the surface")
    assert f"node {v} " in msg and "of the diagonal" in msg


def test_rejects_planarize_beyond_its_bound_and_too_many_fixed_nodes(good):
    bound = good.state.options.quad.planar_offset * good.state.size
    planar = {"moved": 0, "max_offset": 2 * bound, "quads_above_before": 3, "quads_above_after": 1}
    missed(edited(good, planarize=planar), "planarize bound")
    assert "nodes fixed" in missed(good, "few fixed nodes", max_fixed=1e-6)
