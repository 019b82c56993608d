"""Skin preparation: isotropic remeshing of the input skin to a target edge length.

The later stages subdivide once at the end (triangles merged into quads, every quad
split into four), so the skin triangulation handed to the imprint stage is built at
``target_edge`` (about ``2 H`` for a final quad size ``H``). :func:`remesh_skin` is a
vectorised Botsch--Kobbelt remesher ("A remeshing approach to multiresolution
modeling", SGP 2004) with

* **batched independent sets**: every split / collapse / flip round selects, in one
  pass over numpy arrays, a set of operations whose neighbourhoods do not overlap
  (local priority maxima), applies them all at once and rebuilds the edge table;
* **feature lines**: input edges with a dihedral angle above ``feature_angle``, open
  boundary edges and component borders are chained into polylines; remesh vertices on
  them are parametrised by arc length along their polyline and only move along it;
  chain end points and junctions (*corners*) never move;
* **exact projection**: every other vertex is put on the closest point of the input
  triangles, restricted to the triangles of its own feature-bounded patch whose normal
  faces the same way as the vertex normal (so a vertex of the upper skin of a 5 % thick
  wing never snaps onto the lower skin across a sharp trailing edge);
* **curvature adaptation**: a sizing field on the input vertices shrinks the edge
  length where the chordal deviation at ``target_edge`` would exceed
  ``max_deviation`` (leading edges, fillets), graded so that neighbouring sizes differ
  by at most ``gradation`` times their distance; after remeshing, edges whose midpoint
  is still farther than ``max_deviation`` from the input shrink the field there and the
  remesher runs again (at most ``deviation_passes`` times).

:func:`improve_triangles` exposes the local clean-up (angle-improving flips of nearly
coplanar triangle pairs, tangential relaxation with projection, inversion checks) for
the imprint stage, which calls it with member chains as extra constrained edges.

Modules: ``common`` (thresholds, vertex kinds, small array helpers, the edge table),
``surface`` (the input skin: patches, feature chains, sizing field, projection), ``work``
(the working mesh and the services the operations share), ``operations`` (batched splits,
collapses and flips), ``relax`` (tangential relaxation), ``driver`` (:func:`remesh_skin`,
:func:`remesh_statistics`), ``improve`` (:func:`improve_triangles`), ``cache`` (:class:`RemeshCache`:
remeshed skins kept across runs), ``kernels`` (the compiled loops only the remesh uses).
"""
from __future__ import annotations

from .cache import DEFAULT_REMESH_CACHE, RemeshCache
from .driver import DEFAULT_MIN_EDGE_FRACTION, remesh_skin, remesh_statistics
from .improve import improve_triangles

__all__ = ["remesh_skin", "improve_triangles", "remesh_statistics", "DEFAULT_MIN_EDGE_FRACTION", "RemeshCache",
           "DEFAULT_REMESH_CACHE"]
