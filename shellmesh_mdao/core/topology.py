"""Mesh topology helpers the stages share: the faces around a set of vertices, and rings of them."""
from __future__ import annotations

import numpy as np

from .kernels import faces_at

__all__ = ["faces_of", "face_rings"]

def faces_of(ptr, vf, verts, m):
    """Sorted ids of the faces incident to ``verts`` (CSR ``ptr``/``vf`` of ``m`` faces; a
    compiled pass, :func:`~shellmesh_mdao.kernels.faces_at`)."""
    return faces_at(ptr, vf, verts, m)


def face_rings(faces, ptr, vf, verts, rings: int = 2):
    """Sorted ids of the faces within ``rings`` rings of ``verts``: the faces incident to
    them, then (``rings`` >= 2) the faces incident to those faces' vertices, and so on."""
    region = faces_of(ptr, vf, np.asarray(verts, np.int64), len(faces))
    for _ in range(rings - 1):
        v = faces[region]
        region = faces_of(ptr, vf, np.unique(v[v >= 0]), len(faces))
    return region
