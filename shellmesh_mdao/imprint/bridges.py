"""Member bridges: a skin edge joining two vertices of one member's chains without being one of its
chain edges is flipped or split, so no member mesh can run along a skin edge
(:func:`split_member_bridges`)."""
from __future__ import annotations

import numpy as np

from ..mesh import ShellMesh, norm_rows, unique_edges
from .common import edge_keys, has_edge, tri_angles_min, unit_normals
from .cut import split_at_surface_midpoints, split_feature_edges

__all__ = ["split_member_bridges"]


def split_member_bridges(mesh: ShellMesh, chains, locator) -> ShellMesh:
    """Split every skin edge that joins two vertices of the same member's chains without being
    one of its chain edges (a *bridge*), at its midpoint projected onto the input surface.

    A member is meshed on its chain vertices; where two of them are also joined by a skin
    edge (a spar a fraction of an element behind a rounded leading edge: its upper and lower
    lines one skin edge apart around the nose; the upper and lower crossing of a rib with it),
    the member mesh may use the same segment, which then carries two skin faces and the
    member's own two (or a rib's too): not a junction, and not a valid shell mesh. After the
    split the two vertices are two edges apart. Feature edges lying on a split edge are split
    with it; chain vertex lists are unchanged (new vertices are appended)."""
    P, T, C = mesh.points, mesh.faces[:, :3], mesh.component
    if not len(chains) or not len(T):
        return mesh
    members = sorted({c.member for c in chains})
    col = {m: i for i, m in enumerate(members)}
    rows = np.concatenate([np.asarray(c.vertices, np.int64) for c in chains])
    cols = np.concatenate([np.full(len(c.vertices), col[c.member], np.int64) for c in chains])
    on = np.zeros((len(P), len(members)), bool)
    on[rows, cols] = True
    e = unique_edges(T.ravel(), np.roll(T, -1, axis=1).ravel())
    cand = e[on[e[:, 0]].any(1) & on[e[:, 1]].any(1)]
    if not len(cand):
        return mesh
    fe = np.sort(np.asarray(mesh.feature_edges, np.int64).reshape(-1, 2), axis=1)
    fid = np.asarray(mesh.feature_edge_ids)
    n = len(P)
    # chain edges (feature edges tagged with a member's component id) stay
    chain_keys = fe[fid >= 0, 0] * n + fe[fid >= 0, 1]
    bridge = (on[cand[:, 0]] & on[cand[:, 1]]).any(1) & ~np.isin(cand[:, 0] * n + cand[:, 1], chain_keys)
    split = cand[bridge]
    if not len(split):
        return mesh
    T, split = _flip_bridges(P, T, C, split, on, fe, locator)
    if not len(split):
        return ShellMesh(P, T, C, list(mesh.component_names), mesh.fixed_vertices, fe, fid)
    P2, T2, C2, new_id = split_at_surface_midpoints(P, T, C, split, locator)
    fe2, fid2 = split_feature_edges(fe, fid, split, new_id) if len(fe) else (fe, fid)
    return ShellMesh(P2, T2, C2, list(mesh.component_names), mesh.fixed_vertices, fe2, fid2)


def _flip_bridges(P, T, C, bridges, on, fe, locator, near: float = 0.25, min_angle: float = 5.0):
    """Bridges whose surface midpoint lies within ``near`` x their length of the opposite vertex
    of one of their two triangles (a chord across a rounded nose whose middle is already a
    vertex) are flipped instead of split: splitting there would put a new vertex beside that
    one and leave slivers (cessna210 stress seed 41: 0.14 and 0.67 degrees). A flip is made
    only between two triangles of one component, when the new edge is new, not a bridge
    itself, both new triangles keep their orientation and have angles of ``min_angle`` or more,
    and no other candidate flip shares a triangle with it. Returns ``(T, bridges still to split)``."""
    n = len(P)
    a, b = T, np.roll(T, -1, axis=1)
    key = (a * n + b).ravel()                                   # directed half-edges
    order = np.argsort(key, kind="stable")
    ks = key[order]

    def half(u, v):
        i = np.searchsorted(ks, u * n + v)
        i = np.minimum(i, len(ks) - 1)
        return np.where(ks[i] == u * n + v, order[i], -1)

    u, v = bridges[:, 0], bridges[:, 1]
    h0, h1 = half(u, v), half(v, u)                             # t0 runs u->v, t1 runs v->u
    ok = (h0 >= 0) & (h1 >= 0)
    if len(fe):
        ok &= ~has_edge(edge_keys(fe, n), u, v, n)               # a crease: never flipped
    t0, t1 = np.where(ok, h0 // 3, 0), np.where(ok, h1 // 3, 0)
    w0 = T[t0, (h0 % 3 + 2) % 3]
    w1 = T[t1, (h1 % 3 + 2) % 3]
    ok &= (C[t0] == C[t1]) & (t0 != t1) & (w0 != w1)
    mid = locator.closest(0.5 * (P[u] + P[v]))[0]
    L = norm_rows(P[v] - P[u], axis=1)
    dw = np.minimum(norm_rows(mid - P[w0], axis=1), norm_rows(mid - P[w1], axis=1))
    ok &= dw < near * L
    ok &= ~(on[w0] & on[w1]).any(1)                             # the new edge is no bridge
    ok &= ~has_edge(edge_keys(T, n), w0, w1, n)
    new0 = np.stack([u, w1, w0], 1)
    new1 = np.stack([v, w0, w1], 1)
    n_old = unit_normals(P[T[t0]]) + unit_normals(P[T[t1]])
    ok &= (np.einsum("ij,ij->i", unit_normals(P[new0]), n_old) > 0) & \
          (np.einsum("ij,ij->i", unit_normals(P[new1]), n_old) > 0)
    ok &= np.minimum(tri_angles_min(P, new0), tri_angles_min(P, new1)) >= min_angle
    # flips share no triangle: a bridge whose triangle another candidate also has is split instead
    idx = np.flatnonzero(ok)
    tris = np.concatenate([t0[idx], t1[idx]])
    alone = np.bincount(tris, minlength=len(T))[tris] == 1
    take = idx[alone[:len(idx)] & alone[len(idx):]]
    if not len(take):
        return T, bridges
    T = T.copy()
    T[t0[take]] = new0[take]
    T[t1[take]] = new1[take]
    rest = np.ones(len(bridges), bool)
    rest[take] = False
    return T, bridges[rest]
