"""The layout stage: which ribs, spars and explicit members to build, and where.

A layout is a JSON or YAML file (same schema) or a dict; :func:`load_layout` turns it into a
validated :class:`Layout` (:mod:`.schema`). Wings are given by their wing-box corners, or by
their span axis and stations, the planform then measured from the skin
(:mod:`.planform`, :mod:`.sections`). The file reference is ``docs/layout.md``.
"""
from .schema import (MIN_LOCAL_SIZE, MIN_MEMBER_GAP, MIN_UP_SPAN_ANGLE_DEG, ExplicitMember, Layout, MemberSpec, WingLayout,
                     coincident_parts, explicit_plane, layout_from_manifest, load_layout)
from .sections import SectionShape, measure_section, section_loops
from .planform import Planform, measure_planform
from .wingbox import resolve_layout, resolve_station_wing
from .schema import resample_polyline
from .stations import END_RIBS, RIB_ORIENTATIONS, StationWing

__all__ = ["Layout", "WingLayout", "ExplicitMember", "MemberSpec", "load_layout", "layout_from_manifest",
           "explicit_plane", "MIN_UP_SPAN_ANGLE_DEG", "SectionShape", "measure_section", "section_loops",
           "Planform", "measure_planform", "resolve_layout", "resolve_station_wing", "StationWing",
           "resample_polyline", "RIB_ORIENTATIONS", "END_RIBS", "MIN_MEMBER_GAP", "MIN_LOCAL_SIZE", "coincident_parts"]
