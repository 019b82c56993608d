"""Remeshed skins kept across pipeline runs.

The remeshed skin depends on the input surface, the size and the solver options only, and on the
layout only where members come closer than the element size (the local sizes between them, part of
the key), so a study that varies the layout (a DOE over rib stations, an optimisation) needs it once
while its members stay an element size apart.
:class:`RemeshCache` keeps the last few: the pipeline's remesh stage looks a skin up before
remeshing and stores what it made. :func:`~shellmesh_mdao.pipeline.run_pipeline` uses the process's
:data:`DEFAULT_REMESH_CACHE` unless told otherwise; each
:class:`~shellmesh_mdao.components.ImprintComp` keeps one of its own (so two OpenMDAO problems in one
process do not share their counts).

A hit gives the very skin a fresh remesh gives (the remesh is deterministic), with its arrays made
read-only: a later stage that tried to modify them in place would raise instead of corrupting the
cache.
"""
from __future__ import annotations

import hashlib
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

__all__ = ["RemeshCache", "CachedSkin", "DEFAULT_REMESH_CACHE", "surface_digest", "freeze"]


def surface_digest(surface) -> str:
    """SHA-1 of a surface's points and faces (dtype, shape and bytes): equal digests, equal inputs."""
    h = hashlib.sha1()
    for a in (surface.points, surface.faces):
        a = np.ascontiguousarray(a)
        h.update(str(a.dtype).encode() + str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def freeze(mesh) -> None:
    """Make a mesh's arrays read-only (in place)."""
    for name in ("points", "faces", "component", "fixed_vertices", "feature_edges", "feature_edge_ids"):
        a = getattr(mesh, name, None)
        if isinstance(a, np.ndarray):
            a.flags.writeable = False


@dataclass(frozen=True)
class CachedSkin:
    """A remeshed skin, the seconds its remesh took and its sizing summary (the remesh report's
    ``sizing``, the pipeline report's ``size_field.skin``; None when not given)."""

    mesh: object
    seconds: float
    sizing: dict | None = None


class RemeshCache:
    """The last ``max_entries`` remeshed skins (least recently used dropped first), keyed by
    :meth:`key`. ``hits``, ``misses`` and ``seconds`` (spent remeshing on misses) count its use."""

    def __init__(self, max_entries: int = 2):
        if int(max_entries) < 1:
            raise ValueError(f"RemeshCache keeps at least 1 skin, got max_entries={max_entries!r}")
        self.max_entries = int(max_entries)
        self._entries: OrderedDict = OrderedDict()
        self.hits = 0
        self.misses = 0
        self.seconds = 0.0

    @staticmethod
    def key(surface, size: float, options, size_field=None) -> tuple:
        """The key of the skin remeshed from ``surface`` at quad size ``size`` with the solver
        ``options`` (a frozen, hashable options object) and the local sizes ``size_field`` (a
        :class:`~shellmesh_mdao.core.sizefield.SizeField`; None or empty: none)."""
        f = None if size_field is None or size_field.empty else size_field.digest()
        return surface_digest(surface), float(size), options, f

    def get(self, key) -> CachedSkin | None:
        """The skin stored under ``key`` (counted as a hit), or None (a miss is counted by :meth:`put`)."""
        hit = self._entries.get(key)
        if hit is not None:
            self._entries.move_to_end(key)
            self.hits += 1
        return hit

    def put(self, key, mesh, seconds: float, sizing: dict | None = None) -> None:
        """Store ``mesh`` (made read-only) under ``key``; ``seconds``: its remesh time; ``sizing``:
        its sizing summary (kept with it, so that a hit reports it too)."""
        freeze(mesh)
        self.misses += 1
        self.seconds += float(seconds)
        self._entries[key] = CachedSkin(mesh, float(seconds), None if sizing is None else dict(sizing))
        self._entries.move_to_end(key)
        while len(self._entries) > self.max_entries:
            self._entries.popitem(last=False)

    def skins(self) -> list:
        """The stored :class:`CachedSkin` entries, least recently used first."""
        return list(self._entries.values())

    def clear(self) -> None:
        """Forget every skin (the counts stay)."""
        self._entries.clear()

    def __len__(self) -> int:
        return len(self._entries)

    @property
    def stats(self) -> dict:
        """``{"hits", "misses", "seconds"}``."""
        return {"hits": self.hits, "misses": self.misses, "seconds": self.seconds}


#: The cache :func:`~shellmesh_mdao.pipeline.run_pipeline` uses by default (two skins).
DEFAULT_REMESH_CACHE = RemeshCache(2)
