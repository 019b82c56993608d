"""The quad stage: one all-quad subdivision of the whole mesh (:mod:`.subdivide`: quad -> 4,
triangle -> 3, new nodes on their supports, the fold guard and its settle), the flattening of
quads still warped (:mod:`.planar`), and the stage's finishing policy (:mod:`.finish`: the final
smoothing passes, repairs and report; :func:`quad_mesh` is the pipeline's quad stage).
"""
from .finish import FINAL_MIN_JACOBIAN, OFF_SURFACE_TOL, POOR_JACOBIAN, finish_quads, finish_region, quad_mesh
from .planar import planarize
from .subdivide import settle_off_surface, subdivide_faces, subdivide_to_quads

__all__ = ["subdivide_to_quads", "subdivide_faces", "settle_off_surface", "planarize", "quad_mesh", "finish_quads",
           "finish_region", "POOR_JACOBIAN", "OFF_SURFACE_TOL", "FINAL_MIN_JACOBIAN"]
