"""Bay families: the skin patches the member chains cut out, named by wing, skin side and bay
(:func:`skin_families`)."""
from __future__ import annotations

import numpy as np

from ..families import bay_name, rib_name, spar_name
from ..mesh import ShellMesh

__all__ = ["skin_families"]


def skin_families(mesh: ShellMesh, layout) -> ShellMesh:
    """Name the skin patches the member chains cut out: ``<wing>/upper_skin/bay_<k>`` and
    ``<wing>/lower_skin/bay_<k>`` (bay k between rib k and rib k+1, between the first and
    last spar; with fewer than two spars over the whole chord; :func:`~shellmesh_mdao.families.bay_name`);
    every other face keeps its component.

    A patch is a set of faces connected across edges that are not member chains. It is a bay
    when at least 99% of its face centroids lie inside the bay's box (between the two rib
    planes and, with two or more spars, the first and last spar planes); its faces are then
    split into upper and lower by their side (along ``up``) of the bay's mid-chord point.

    A wing given by stations (``layout.station_wings``, resolved) is named the same way; its bay is
    the patch between two consecutive rib planes (its ribs may have any orientation and its spars
    kinks; the spar and edge-web chains close the patch), split at the ribs' mid-chord points.
    """
    topo = mesh.topology()
    chain_e = mesh.feature_edges[mesh.feature_edge_ids >= 0]
    is_chain = np.zeros(len(topo.edges), bool)
    if len(chain_e):
        ids = topo.edge_ids(chain_e)
        is_chain[ids[ids >= 0]] = True
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    man = np.flatnonzero((topo.valence == 2) & ~is_chain)
    f0 = topo.edge_faces[topo.edge_faces_ptr[man]]
    f1 = topo.edge_faces[topo.edge_faces_ptr[man] + 1]
    g = sparse.coo_matrix((np.ones(len(man)), (f0, f1)), shape=(mesh.n_faces, mesh.n_faces))
    _, patch = connected_components(g, directed=False)
    cen = mesh.face_centroids()
    names = list(mesh.component_names)
    comp = mesh.component.copy()
    members = {m.name: m for m in layout.members()}
    for w in layout.wings:
        up = layout.wing_up(w)
        ribs = [members[rib_name(w.name, k)] for k in range(len(w.rib_eta))]
        spars = [members[spar_name(w.name, j)] for j in range(len(w.spar_chord))]
        cmid = 0.5 * (w.spar_chord[0] + w.spar_chord[-1]) if len(spars) >= 2 else 0.5
        for k in range(len(ribs) - 1):
            # the bay's own mid-chord point: follows dihedral and twist along the span
            chord_pt = 0.5 * (w.chord_point(w.rib_eta[k], cmid) + w.chord_point(w.rib_eta[k + 1], cmid))
            inside = (cen - ribs[k].plane_point) @ ribs[k].plane_normal >= 0
            inside &= (cen - ribs[k + 1].plane_point) @ ribs[k + 1].plane_normal <= 0
            if len(spars) >= 2:
                inside &= (cen - spars[0].plane_point) @ spars[0].plane_normal >= 0
                inside &= (cen - spars[-1].plane_point) @ spars[-1].plane_normal <= 0
            frac = np.bincount(patch, weights=inside.astype(float)) / np.bincount(patch)
            box = frac[patch] >= 0.99
            upper = (cen - chord_pt) @ up >= 0
            for side, mask in (("upper", box & upper), ("lower", box & ~upper)):
                if mask.any():
                    comp[mask] = len(names)
                    names.append(bay_name(w.name, side, k))
    for w in getattr(layout, "station_wings", ()):
        # a wing given by stations: its ribs may be oriented any way (normal to a spar, streamwise,
        # fanned at the root) and its spars kinked, so a bay is the patch between two rib planes
        # alone (the spar and web chains close it); each rib normal is turned towards the next rib
        ribs = [members[n] for n in (rib_name(w.name, k) for k in range(len(w.rib_eta))) if n in members]
        for k in range(len(ribs) - 1):
            a, b = ribs[k], ribs[k + 1]
            step = b.plane_point - a.plane_point
            na = a.plane_normal if step @ a.plane_normal >= 0 else -a.plane_normal
            nb = b.plane_normal if step @ b.plane_normal >= 0 else -b.plane_normal
            inside = ((cen - a.plane_point) @ na >= 0) & ((cen - b.plane_point) @ nb <= 0)
            frac = np.bincount(patch, weights=inside.astype(float)) / np.bincount(patch)
            box = frac[patch] >= 0.99
            # the ribs' middle seeds lie on the wing's chord surface
            upper = (cen - 0.5 * (a.plane_point + b.plane_point)) @ a.up >= 0
            for side, mask in (("upper", box & upper), ("lower", box & ~upper)):
                if mask.any():
                    comp[mask] = len(names)
                    names.append(bay_name(w.name, side, k))
    return ShellMesh(mesh.points, mesh.faces, comp, names, mesh.fixed_vertices, mesh.feature_edges,
                     mesh.feature_edge_ids)
