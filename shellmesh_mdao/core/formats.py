"""Naming rules of the solver file formats, which the writers (:mod:`shellmesh_mdao.export`) follow and the
readers (:mod:`shellmesh_mdao.load`) undo: CalculiX ELSET names of the components."""
from __future__ import annotations

import re

from ..families import padded_names, unnamed_name
from ..mesh import ShellMesh

__all__ = ["n_components", "sanitise_name", "inp_elset_names"]


def n_components(mesh: ShellMesh) -> int:
    """Number of components of ``mesh``: its names, or more if a face uses a higher id."""
    m = int(mesh.component.max()) + 1 if mesh.n_faces else 0
    return max(len(mesh.component_names), m)


def sanitise_name(name: str, maxlen: int, taken: set, fallback: str) -> str:
    """``name`` as a solver deck allows it: letters, digits and ``_``, starting with a letter, at most
    ``maxlen`` characters, not in ``taken`` ignoring case (added to it); ``fallback`` for an empty name."""
    s = re.sub(r"[^A-Za-z0-9_]", "_", name.strip()) or fallback
    if not s[0].isalpha():
        s = "C_" + s
    s = s[:maxlen]
    base, k = s, 1
    while s.upper() in taken:
        suffix = f"_{k}"
        s = base[:maxlen - len(suffix)] + suffix
        k += 1
    taken.add(s.upper())
    return s


def inp_elset_names(mesh: ShellMesh) -> list[str]:
    """CalculiX ELSET name of each component: letters, digits and ``_`` only, starting with a
    letter, at most 80 characters, unique ignoring case (CalculiX upper-cases names), never
    ``EALL``/``NALL``."""
    taken = {"EALL", "NALL"}
    names = padded_names(mesh.component_names, n_components(mesh))
    return [sanitise_name(n, 80, taken, unnamed_name(i)) for i, n in enumerate(names)]
