"""Generated aircraft surfaces: the bundled default wing, and a parametric family of aircraft.

* :mod:`~shellmesh_mdao.geometry.naca` -- :func:`naca_wing`, the bundled default wing of
  ``shellmesh demo`` (a closed triangulation with NACA 4-digit sections and flat end caps) and
  its corner-given layout :func:`naca_wing_layout`; a source of wings of any proportions for tests.
* :mod:`~shellmesh_mdao.geometry.aircraft` -- :class:`AircraftParams`, :func:`aircraft_surface`
  (fuselage, wing, tails, fin, winglets united into one closed surface), :func:`aircraft_layout`
  (a layout given by stations) and :func:`random_aircraft` (parameters drawn in their ranges):
  a random family of aircraft for property-based tests and the random-family benchmark.
* :mod:`~shellmesh_mdao.geometry.lofts` -- the building blocks: airfoil sections, lofts between
  them, flat and round end caps, bodies of revolution.
* :mod:`~shellmesh_mdao.geometry.checks` -- is a triangulation closed, consistently oriented
  and free of self-intersections.

Geometry is not a stage: it makes input surfaces and imports no stage.
"""
from __future__ import annotations

from .aircraft import (AircraftParams, StructureParams, aircraft_layout, aircraft_surface, draw_aircraft,
                       draw_structure, random_aircraft)
from .checks import surface_defects, self_intersections
from .naca import DEFAULT_WING, naca4, naca_wing, naca_wing_layout

__all__ = ["naca4", "naca_wing", "naca_wing_layout", "DEFAULT_WING", "AircraftParams", "StructureParams",
           "aircraft_surface", "aircraft_layout", "draw_aircraft", "draw_structure", "random_aircraft",
           "surface_defects", "self_intersections"]
