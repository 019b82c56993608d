"""Helpers that several stages share, with public names.

A stage's own helpers live in the stage's module or subpackage; only what two or more stages use is
here, so no stage imports another stage's private names, and no stage imports a later one.

Modules: :mod:`.kernels` (compiled kernels several stages use), :mod:`.bvh` (compiled closest points on
the input skin), :mod:`.locator` (:class:`~.locator.SurfaceLocator`: closest points and ray casts on the
input skin), :mod:`.section` (exact plane sections of a triangulation), :mod:`.supports` (where each node
may move: input skin, member planes, feature curves), :mod:`.topology` (faces around vertices, rings,
fixed edges), :mod:`.polyline` and :mod:`.polygon` (polylines and 2-D polygons), :mod:`.highs` (HiGHS
LP/MIP calls), :mod:`.threads` (a call in a thread of its own), :mod:`.formats` (the INP ELSET naming
rule of the reader and the writer), :mod:`.sizefield` (:class:`~.sizefield.SizeField`: local element
sizes asked for at points, graded back to the element size). Import them by module; this package itself exports nothing.
"""

__all__: list[str] = []
