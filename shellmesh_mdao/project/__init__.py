"""Projection of member curves onto the skin (paper Sec. IV.B, "projection of points").

:class:`~shellmesh_mdao.core.locator.SurfaceLocator` (shared by every stage that queries the input skin) answers the two queries of the paper's octree on a triangle
surface, vectorised over many query points:

* :meth:`SurfaceLocator.closest` -- the exact closest point of the triangle set
  (a compiled bounding-volume hierarchy, :class:`~shellmesh_mdao.core.bvh.TriangleBVH`,
  float64, on coordinates shifted to the bounding-box centre). Among equally near
  triangles (a point on a shared edge or vertex) the lowest index is taken, whatever the
  tree, the order of the queries or the number of threads. Measured on the 2-core
  machine, 100k queries within 1e-3 of cessna210's surface: 23.5k triangles 0.06 s on two
  threads, 0.12 s on one (libigl's AABB tree, used before: 0.15 s on two; VTK's cell
  locator 1.9-4 s; trimesh.proximity ~80 s); subdivided to 1.5M triangles: tree 2.5 s
  (231 MB), queries 0.17 s (libigl: 3.4-10 s);
* :meth:`SurfaceLocator.raycast` -- the nearest hit along each ray (Embree through
  ``embreex`` finds the triangle in float32; every hit is then recomputed in float64
  by Moller-Trumbore on that triangle, falling back to the triangles around it when
  the float32 hit lies on or near a shared edge, so hit points lie on their triangle to
  float64 precision and ties go to the lowest triangle index). 100k rays: 0.05 s on 25k
  triangles; 1.5M triangles: scene 1.3 s, rays 0.2-3 s.

The pipeline functions on top (:func:`project_wing_stations`, :func:`project_polyline`,
:func:`project_layout`) turn a :class:`~shellmesh_mdao.layout.Layout` into projected
seed points on the skin.

Modules: ``seeds`` (the projection of the layout's members and the spar-height check), ``close``
(:func:`close_member_field`: the local element size between members closer than the element size), ``thin``
(:func:`thin_member_field`: the local element size along spars too thin for a web of quads of the element size). The
locator and its compiled kernels are shared helpers: :mod:`shellmesh_mdao.core.locator`,
:mod:`shellmesh_mdao.core.bvh`.
"""
from __future__ import annotations

from .close import CLOSE_SIZE, close_member_field
from .thin import THIN_HEIGHT, THIN_STEP, thin_member_field
from .seeds import (MIN_MEMBER_HEIGHT, ProjectedMember, check_member_heights, project_layout, project_polyline,
                    seed_curve_length, spar_heights,
                    project_wing_stations)

__all__ = ["project_wing_stations", "project_polyline", "project_layout", "ProjectedMember", "MIN_MEMBER_HEIGHT",
           "check_member_heights", "close_member_field", "CLOSE_SIZE", "thin_member_field", "THIN_STEP", "THIN_HEIGHT",
           "spar_heights", "seed_curve_length"]
