"""Component names and families: the one module that knows the naming scheme.

Every face of a :class:`~shellmesh_mdao.mesh.ShellMesh` has a component id; ``component_names``
names it. The pipeline names its components so (``<wing>`` is a wing's ``name`` in the layout;
wing and explicit member names never contain ``/``, :func:`check_plain_name`):

=================================  ===========  ==============================================
name                               kind         made by
=================================  ===========  ==============================================
``skin``                           skin         the input skin (load); after imprint, the skin
                                                outside the wing boxes (:data:`SKIN`)
``<wing>/rib_<k>``                 rib          rib ``k`` (0 at the root), :func:`rib_name`
``<wing>/spar_<j>``                spar         spar ``j`` (0 at the leading edge), :func:`spar_name`
``<wing>/le_web``                  web          the leading- and trailing-edge webs of a
``<wing>/te_web``                  web          station-given wing with fewer than two spars and
                                                a sharp edge, :func:`web_name`
``<spar or web>/part_<p>``         (member's)   planar piece ``p`` (0 at the root) of a kinked
                                                spar or web of a station-given wing,
                                                :func:`spar_part_name`, :func:`part_name`
``<name>``                         explicit     an explicit member of the layout, its own name
``<member>/seg_<j>``               (member's)   piece ``j`` of a member split at X-junctions,
                                                along its direction, :func:`segment_name`
``<wing>/upper_skin/bay_<k>``      skin_bay     the upper skin between rib ``k`` and ``k + 1``
``<wing>/lower_skin/bay_<k>``      skin_bay     the lower skin of that bay, :func:`bay_name`
=================================  ===========  ==============================================

Indices are written in decimal without leading zeros. A split member keeps its own name in
``component_names`` too (the owner of its chain feature edges). Meshes read from files keep the
file's names; components a file leaves unnamed are ``component_<i>`` (:func:`unnamed_name`),
gmsh physical groups without a name ``physical_<tag>`` (:func:`physical_group_name`), and a
file without any groups is one component ``skin``.

:func:`parse_component` reads a name of the scheme back into a :class:`ComponentName` (kind,
wing, index, side, segment); :func:`member_of` strips a segment. :func:`component_family`
gives the family a name belongs to -- ``'skin'``, ``'upper skin'``, ``'lower skin'``, ``'rib'``,
``'spar'`` (spars, their pieces and the edge webs) or ``'member'`` (:data:`FAMILIES`) -- for any name, also names from a file: it is
what the pictures colour by, the report counts by and a config ``thickness`` mapping may name
(:data:`THICKNESS_FAMILIES`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

from .errors import LayoutError

__all__ = [
    "SKIN", "SIDES", "KINDS", "FAMILIES", "BOX_FAMILIES", "THICKNESS_FAMILIES", "LOWER_SKIN_PATTERN",
    "ROOT_RIB_PATTERN", "WEB_EDGES", "ComponentName", "rib_name", "spar_name", "spar_part_name", "part_name", "web_name", "bay_name",
    "segment_name", "unnamed_name", "physical_group_name", "padded_names", "name_of", "check_plain_name", "parse_component",
    "member_of", "is_piece_of", "is_member", "name_head", "name_and_parents", "component_family", "is_skin",
    "is_skin_bay", "is_lower_skin_bay", "is_upper_skin_bay", "is_rib_or_spar",
]

#: Name of the skin: the input skin, and after imprint the skin outside the wing boxes.
SKIN = "skin"
#: The skin sides of a bay, as in ``<wing>/<side>_skin/bay_<k>``.
SIDES = ("upper", "lower")
#: ``ComponentName.kind`` values.
KINDS = ("skin", "rib", "spar", "web", "explicit", "skin_bay")
#: The edges an edge web runs along (:func:`web_name`).
WEB_EDGES = ("le", "te")
#: The component families (:func:`component_family`), in the order the report lists them.
FAMILIES = ("skin", "upper skin", "lower skin", "rib", "spar", "member")
#: The families of a wing box: its skin bays, ribs and spars.
BOX_FAMILIES = ("upper skin", "lower skin", "rib", "spar")
#: Family keys a config ``thickness`` mapping may use besides component names -> family.
THICKNESS_FAMILIES = {"skin": "skin", "upper_skin": "upper skin", "lower_skin": "lower skin", "ribs": "rib",
                      "spars": "spar", "members": "member"}
#: ``fnmatch`` pattern of the lower skin bays (loaded by the default pressure load case).
LOWER_SKIN_PATTERN = "*/lower_skin/bay_*"
#: ``fnmatch`` pattern of the root ribs (``rib_0`` of every wing).
ROOT_RIB_PATTERN = "*/rib_0"

_SEG = "/seg_"
_INDEX = r"(0|[1-9][0-9]*)"
_PLAIN = r"([^/]+)"
_SCHEME = (
    ("rib", re.compile(rf"^{_PLAIN}/rib_{_INDEX}(?:/seg_{_INDEX})?$")),
    ("spar", re.compile(rf"^{_PLAIN}/spar_{_INDEX}(?:/seg_{_INDEX})?$")),
    ("spar_part", re.compile(rf"^{_PLAIN}/spar_{_INDEX}/part_{_INDEX}(?:/seg_{_INDEX})?$")),
    ("web", re.compile(rf"^{_PLAIN}/(le|te)_web(?:/seg_{_INDEX})?$")),
    ("web_part", re.compile(rf"^{_PLAIN}/(le|te)_web/part_{_INDEX}(?:/seg_{_INDEX})?$")),
    ("skin_bay", re.compile(rf"^{_PLAIN}/(upper|lower)_skin/bay_{_INDEX}$")),
    ("explicit", re.compile(rf"^{_PLAIN}/seg_{_INDEX}$")),
)
# component_family: a part "rib", "rib_<digits>", "spar", "spar_<digits>"
_RIB = re.compile(r"^rib(_\d+)?$")
_SPAR = re.compile(r"^spar(_\d+)?$")
_WEB = re.compile(r"^(le|te)_web$")


@dataclass(frozen=True)
class ComponentName:
    """A component name of the scheme, read by :func:`parse_component`.

    ``name``     the name itself.
    ``kind``     ``'skin'``, ``'rib'``, ``'spar'``, ``'web'``, ``'explicit'`` or ``'skin_bay'``.
    ``wing``     the wing of a rib, spar or bay; None for the skin and explicit members.
    ``index``    rib ``k``, spar ``j`` or bay ``k``; None for the skin and explicit members.
    ``side``     ``'upper'`` or ``'lower'`` for a bay, ``'le'`` or ``'te'`` for an edge web, else None.
    ``segment``  ``j`` of a member piece ``<member>/seg_<j>``, else None.
    ``part``     ``p`` of a spar or web piece (``<wing>/spar_<j>/part_<p>``, ``<wing>/le_web/part_<p>``),
                 else None.
    """

    name: str
    kind: str
    wing: str | None = None
    index: int | None = None
    side: str | None = None
    segment: int | None = None
    part: int | None = None

    @property
    def member(self) -> str | None:
        """The member's name (without the segment) for a rib, spar or explicit member, else None."""
        return member_of(self.name) if self.kind in ("rib", "spar", "web", "explicit") else None

    @property
    def family(self) -> str:
        """:func:`component_family` of the name."""
        return component_family(self.name)


# ----------------------------------------------------------------------------- builders
def rib_name(wing: str, k: int) -> str:
    """``<wing>/rib_<k>``: rib ``k`` of ``wing`` (0 at the root)."""
    return f"{wing}/rib_{k}"


def spar_name(wing: str, j: int) -> str:
    """``<wing>/spar_<j>``: spar ``j`` of ``wing`` (0 at the leading edge)."""
    return f"{wing}/spar_{j}"


def spar_part_name(wing: str, j: int, p: int) -> str:
    """``<wing>/spar_<j>/part_<p>``: planar piece ``p`` (0 at the root) of a kinked spar ``j``."""
    return part_name(spar_name(wing, j), p)


def part_name(member: str, p: int) -> str:
    """``<member>/part_<p>``: planar piece ``p`` of a kinked member of a station-given wing."""
    return f"{member}/part_{p}"


def web_name(wing: str, edge: str) -> str:
    """``<wing>/<edge>_web``: the web along the leading (``edge='le'``) or trailing (``'te'``) edge."""
    if edge not in WEB_EDGES:
        raise ValueError(f"web edge must be one of {WEB_EDGES}, got {edge!r}")
    return f"{wing}/{edge}_web"


def bay_name(wing: str, side: str, k: int) -> str:
    """``<wing>/<side>_skin/bay_<k>``: the ``side`` (``'upper'`` or ``'lower'``) skin of the bay
    between rib ``k`` and rib ``k + 1``."""
    if side not in SIDES:
        raise ValueError(f"bay side must be one of {SIDES}, got {side!r}")
    return f"{wing}/{side}_skin/bay_{k}"


def segment_name(member: str, j: int) -> str:
    """``<member>/seg_<j>``: piece ``j`` of a member split at X-junctions."""
    return f"{member}{_SEG}{j}"


def unnamed_name(i: int) -> str:
    """``component_<i>``: the name of component id ``i`` when the mesh (or its file) names none."""
    return f"component_{i}"


def physical_group_name(tag: int) -> str:
    """``physical_<tag>``: the name of a gmsh physical group the file does not name."""
    return f"physical_{tag}"


def padded_names(names, n: int) -> list:
    """``names`` as a list, then :func:`unnamed_name` for the ids ``len(names) .. n - 1`` (a mesh
    whose component ids run past its names)."""
    names = list(names)
    return names + [unnamed_name(i) for i in range(len(names), n)]


def name_of(names, i: int) -> str:
    """``names[i]``, or :func:`unnamed_name` of ``i`` past the end of ``names``."""
    return names[i] if i < len(names) else unnamed_name(i)


def check_plain_name(name, where: str) -> str:
    """``name`` when it can name a wing or an explicit member: a non-empty string without ``/``
    (``/`` separates the parts of the names the pipeline builds from it). Raises
    :class:`~shellmesh_mdao.errors.LayoutError` naming ``where`` otherwise."""
    if not isinstance(name, str) or not name.strip():
        raise LayoutError(f"{where} must be a non-empty string, got {name!r}")
    if "/" in name:
        raise LayoutError(f"{where} = {name!r} must not contain '/': member names are '<wing>/rib_<k>'; "
                          "rename it")
    return name


# ----------------------------------------------------------------------------- parser
def parse_component(name: str) -> ComponentName:
    """Read a component name of the scheme (module docstring). A name without ``/`` is the skin
    (``skin``) or an explicit member (any other name, also a file's own names). Raises
    :class:`~shellmesh_mdao.errors.LayoutError` for a name with ``/`` that is not a rib, spar,
    member piece or skin bay of the scheme."""
    if not isinstance(name, str) or not name:
        raise LayoutError(f"a component name must be a non-empty string, got {name!r}")
    if "/" not in name:
        return ComponentName(name, "skin" if name == SKIN else "explicit")
    for kind, rx in _SCHEME:
        m = rx.match(name)
        if m is None:
            continue
        if kind == "skin_bay":
            return ComponentName(name, kind, wing=m[1], index=int(m[3]), side=m[2])
        if kind == "explicit":
            return ComponentName(name, kind, segment=int(m[2]))
        if kind == "spar_part":
            return ComponentName(name, "spar", wing=m[1], index=int(m[2]), part=int(m[3]),
                                 segment=None if m[4] is None else int(m[4]))
        if kind == "web":
            return ComponentName(name, kind, wing=m[1], side=m[2], segment=None if m[3] is None else int(m[3]))
        if kind == "web_part":
            return ComponentName(name, "web", wing=m[1], side=m[2], part=int(m[3]),
                                 segment=None if m[4] is None else int(m[4]))
        return ComponentName(name, kind, wing=m[1], index=int(m[2]),
                             segment=None if m[3] is None else int(m[3]))
    raise LayoutError(f"component name {name!r} does not follow the naming scheme: '<wing>/rib_<k>', "
                      "'<wing>/spar_<j>', '<wing>/spar_<j>/part_<p>', '<wing>/le_web', '<wing>/te_web', "
                      "'<wing>/le_web/part_<p>', "
                      "'<member>/seg_<j>', '<wing>/upper_skin/bay_<k>', "
                      "'<wing>/lower_skin/bay_<k>', 'skin' or a name without '/'")


def _parsed(name: str) -> ComponentName | None:
    try:
        return parse_component(name)
    except LayoutError:
        return None


# ----------------------------------------------------------------------------- members
def member_of(name: str) -> str:
    """The member a component belongs to: ``name`` without its ``/seg_<j>`` piece suffix (other
    names unchanged)."""
    return name.split(_SEG)[0]


def is_piece_of(name: str, member: str) -> bool:
    """True when component ``name`` is ``member`` itself or one of its ``/seg_<j>`` pieces."""
    return name == member or name.startswith(member + _SEG)


def is_member(name: str, members) -> bool:
    """True when component ``name`` is one of the member names ``members`` (a set) or a piece of
    one."""
    return member_of(name) in members


def name_head(name: str) -> str:
    """The part of ``name`` before the first ``/``: the wing of a rib, spar or bay, the member of
    a piece, the whole name otherwise."""
    return name.split("/")[0]


def name_and_parents(name: str) -> list:
    """``name``, then its parents, longest first: ``w/rib_3/seg_1`` -> ``['w/rib_3/seg_1',
    'w/rib_3', 'w']``."""
    parts = name.split("/")
    return ["/".join(parts[:i]) for i in range(len(parts), 0, -1)]


# ----------------------------------------------------------------------------- families
def component_family(name: str) -> str:
    """Family of a component name: ``'upper skin'``, ``'lower skin'`` (``<wing>/upper_skin/bay_k``),
    ``'rib'``, ``'spar'`` (``<wing>/rib_k``, ``<wing>/spar_k``, and their segments
    ``<wing>/spar_k/seg_j``), ``'skin'`` (``skin``, the skin outside the wing boxes) or
    ``'member'`` (explicit members and anything else).

    Any name has a family, also a name from a file outside the scheme: a part ``upper_skin`` /
    ``lower_skin`` anywhere, a part ``rib``, ``rib_<k>``, ``spar`` or ``spar_<k>`` after the first
    (or the only part), a last part containing ``skin``; in that order of precedence."""
    parts = str(name).split("/")
    if "upper_skin" in parts:
        return "upper skin"
    if "lower_skin" in parts:
        return "lower skin"
    for part in parts[1:] or parts:      # "<wing>/rib_3", "<wing>/spar_1/seg_2"
        if _RIB.match(part):
            return "rib"
        if _SPAR.match(part) or _WEB.match(part):
            return "spar"
    if "skin" in parts[-1]:
        return "skin"
    return "member"


def is_skin(name: str) -> bool:
    """True for skin components: the family ``'skin'``, ``'upper skin'`` or ``'lower skin'``."""
    return component_family(name) in ("skin", "upper skin", "lower skin")


def is_skin_bay(name: str) -> bool:
    """True for a skin bay of the scheme, ``<wing>/upper_skin/bay_<k>`` or ``<wing>/lower_skin/bay_<k>``."""
    p = _parsed(name)
    return p is not None and p.kind == "skin_bay"


def is_lower_skin_bay(name: str) -> bool:
    """True for ``<wing>/lower_skin/bay_<k>``."""
    p = _parsed(name)
    return p is not None and p.kind == "skin_bay" and p.side == "lower"


def is_upper_skin_bay(name: str) -> bool:
    """True for ``<wing>/upper_skin/bay_<k>``."""
    p = _parsed(name)
    return p is not None and p.kind == "skin_bay" and p.side == "upper"


def is_rib_or_spar(name: str) -> bool:
    """True for a rib, spar or edge web of the scheme or one of its pieces (``<wing>/rib_<k>``,
    ``<wing>/spar_<j>``, ``<wing>/spar_<j>/part_<p>``, ``<wing>/le_web``, ``.../seg_<i>``); False for
    explicit members and the skin."""
    p = _parsed(name)
    return p is not None and p.kind in ("rib", "spar", "web")
