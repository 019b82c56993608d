"""Morph: a finished mesh follows a change of its layout's rib stations and spar chord fractions,
its connectivity unchanged.

A :class:`MorphReference` is the mesh of one layout (the *reference*: :func:`morph_reference` runs the
pipeline once) with what the morph needs of it. :func:`morph` gives the node coordinates of the same
elements for other values of the corner-given wings' ``rib_eta`` and ``spar_chord``;
:func:`morph_jacobian` their exact derivatives with respect to those values (complex step through
the same arithmetic, the choices of input triangles held). The rules (docs/openmdao.md, 'Morph'):

* **Planform map.** Each wing has plan coordinates ``(r, c)``: ``r = n_rib . x`` (every rib plane is
  ``r = r_k``) and ``c`` the chord fraction of the reference surface ``S(eta, c)`` (every spar plane
  is ``c = c_j``), ``x`` projected along the wing's ``up``. A layout change moves the knots ``r_k``,
  ``c_j``; a node moves to ``r' = r + w_c w_r D_r(r)``, ``c' = c + w_r D_c(c)``, ``D_r``, ``D_c`` the
  piecewise-linear interpolations of the knots' moves (``D_c`` zero from the leading edge to halfway
  to the first spar and from halfway after the last spar to the trailing edge), ``w_c``, ``w_r`` weights
  that fade the move out over a quarter chord beyond the leading and trailing edges, over one rib
  pitch beyond the end ribs (the last quarter of the way to the wing's root or tip stays: its end
  caps do not move), and between a quarter and half a chord above or below the reference surface (a
  body the wing passes through stays where it is). A node follows the wing that moves it most. Its
  displacement is ``S(eta(r', c'), c') - S(eta(r, c), c)``: a rib's nodes land in its new plane, a
  spar's in its.
* **Skin nodes** go along their reference normal onto the input surface (the triangle decided in
  float64 among those around the ray's hit); nodes of the input's creases slide along the crease by
  the move's component along it (:class:`~shellmesh_mdao.morph.creases.Creases`); a member's skin
  nodes then slide on their triangle's plane (or crease) into their member's new plane, nodes of two
  members onto both. Every skin node keeps its offset from where this rule puts it at the reference
  (the quad stage's planarize moves some off the input on purpose).
* **Member nodes** (off the skin) keep their relative height between the skins below and above
  them: at the new plan point, the heights of the input surface along ``-up`` and ``+up`` (ray casts
  from the section's middle) bound them at the same fraction; then they are projected onto their
  member's plane (onto the line of their two members' planes).
* Nodes whose move is zero keep their coordinates bit for bit: the reference layout gives the
  reference mesh, and the morph is continuous there.

The morphed mesh is checked (:func:`morph_check`: scaled Jacobian of every element above 0.2, skin
nodes no farther from the input than at the reference, member nodes on their planes, no moved skin
node on an input triangle facing away from its side); a caller that gets a failed check builds a new
mesh instead (:class:`~shellmesh_mdao.components.morph_comp.MorphComp` does, and records it).

Supported: corner-given wings (root/tip corners, ``ribs``, ``spars``). A layout with station-given
wings or explicit members is refused with a :class:`~shellmesh_mdao.errors.LayoutError` naming it.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..core.locator import closest_point_on_triangles
from ..errors import LayoutError, ShellMeshError
from ..families import member_of, rib_name, spar_name
from ..guarantees import PLANE_TOL, POOR_JACOBIAN, SURFACE_TOL
from ..layout import Layout, load_layout
from ..mesh import ShellMesh
from ..quality import element_quality
from .creases import CREASE_ANGLE, Creases
from .place import CHAIN_NODE, MEMBER_NODE, SIDE_STEP, SKIN_NODE, Choices, NoSkinError, choose_skin, \
    member_rays, onto_planes, side_choices, skin_heights, skin_positions, tri_frame
from .plan import CHORD_FADE, END_STILL, HEIGHT_FADE, WingFrame, chord_knots, dot, fade, hat_interp, \
    plan_coordinates, plan_point, rib_knots_and_planes, span_fade

__all__ = ["MorphReference", "MorphCheck", "morph_reference", "morph", "morph_jacobian", "morph_check",
           "morph_parameters", "on_facing_triangle", "CHORD_FADE", "HEIGHT_FADE", "END_STILL", "COMPLEX_STEP",
           "SIDE_STEP", "CREASE_ANGLE"]

#: the complex step of :func:`morph_jacobian` (exact to rounding for any step this small)
COMPLEX_STEP = 1e-30


@dataclass
class MorphReference:
    """A reference mesh and what :func:`morph` needs of it (built by :func:`morph_reference`).

    ``mesh`` the reference mesh (the pipeline's, gate passed), ``layout`` its layout, ``size`` its
    element size; ``wing_of`` (n,) the wing (index into ``wings``) whose move each node follows (-1:
    none); ``kind`` (n,) skin / skin node of a member / member node; ``planes`` (n, 2) the member
    planes of each node (index into the wing's members, -1: none); ``r``, ``c`` the plan coordinates
    and ``weight_r``, ``weight_c`` the fades of each node. ``locator`` the input surface."""

    mesh: ShellMesh
    layout: Layout
    size: float
    locator: object
    wings: list
    wing_of: np.ndarray
    kind: np.ndarray
    planes: np.ndarray
    r: np.ndarray
    c: np.ndarray
    weight_r: np.ndarray
    weight_c: np.ndarray
    tau: np.ndarray
    mid: np.ndarray
    skin_normals: np.ndarray
    feature: np.ndarray
    offset: np.ndarray
    member_names: list = field(default_factory=list)
    member_wing: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    surface: ShellMesh | None = None
    options: object = None
    creases: object = None
    crease_seg: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    crease_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    facing_away: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def layout_for(self, params: dict) -> Layout:
        """The reference layout with the parameters ``params`` (``{wing: (rib_eta, spar_chord)}``),
        validated at the reference's element size (:class:`~shellmesh_mdao.errors.LayoutError` for
        stations out of order or members that coincide at this size)."""
        lay = self.layout.with_parameters(rib_eta={w: np.asarray(p[0], np.float64) for w, p in params.items()},
                                          spar_chord={w: np.asarray(p[1], np.float64) for w, p in params.items()})
        return lay.validate(self.size)

    def remesh(self, params: dict):
        """A new mesh (a new topology) of the reference's surface with the parameters ``params``:
        :func:`~shellmesh_mdao.pipeline.run_pipeline` of :meth:`layout_for` at the reference's size
        and options (the gate on). Returns the :class:`~shellmesh_mdao.pipeline.PipelineResult`."""
        from ..pipeline import run_pipeline

        return run_pipeline(self.surface, self.layout_for(params), self.size, options=self.options, progress=False)

    @property
    def n_points(self) -> int:
        return self.mesh.n_points

    def parameters(self) -> dict:
        """The reference layout's parameters: ``{wing: (rib_eta, spar_chord)}`` (float arrays)."""
        return {w.name: (w.rib_eta.copy(), w.spar_chord.copy()) for w in self.wings}


@dataclass
class MorphCheck:
    """What :func:`morph_check` measured: ``ok`` and the figures (``min_scaled_jacobian``,
    ``max_surface_distance``, ``max_plane_distance``, ``n_flipped``) and ``reason`` (empty when ok)."""

    ok: bool
    min_scaled_jacobian: float
    max_surface_distance: float
    max_plane_distance: float
    n_flipped: int
    reason: str = ""


# ----------------------------------------------------------------------------- reference
def morph_reference(surface, layout, size, *, options=None, result=None) -> MorphReference:
    """Mesh ``surface`` with ``layout`` at ``size`` (:func:`~shellmesh_mdao.pipeline.run_pipeline`, the
    gate on) and keep what :func:`morph` needs; ``result`` a finished
    :class:`~shellmesh_mdao.pipeline.PipelineResult` of the same to use instead of running it.
    Raises :class:`~shellmesh_mdao.errors.LayoutError` for a layout the morph does not follow
    (station-given wings, explicit members)."""
    lay = layout if isinstance(layout, Layout) else load_layout(layout)
    check_supported(lay)
    if result is None:
        from ..pipeline import run_pipeline

        result = run_pipeline(surface, lay, size, options=options, progress=False)
    if result.stage != "quad":
        raise ShellMeshError("morph_reference needs a finished mesh (a run to the quad stage)")
    lay = result.layout if isinstance(result.layout, Layout) else lay
    ref = build_reference(result.mesh, lay, float(result.state.size), result.state.supports.surfaces[0])
    ref.surface, ref.options = result.surface, result.state.options
    return ref


def check_supported(lay: Layout) -> None:
    for w in lay.station_wings:
        raise LayoutError(f"morph: wing '{w.name}' is given by stations; the morph follows corner-given "
                          "wings (root_le/root_te/tip_le/tip_te, ribs, spars) only: mesh each design point "
                          "anew (ShellMeshGroup) for this layout")
    if not lay.wings:
        raise LayoutError("morph: the layout has no wing; the morph follows the ribs and spars of corner-given "
                          "wings")
    if any(m.kind == "explicit" for m in lay.members()):
        raise LayoutError("morph: the layout has explicit members, which the morph does not move: mesh each "
                          "design point anew (ShellMeshGroup) for this layout")


def build_reference(mesh: ShellMesh, lay: Layout, size: float, locator) -> MorphReference:
    n = mesh.n_points
    names = list(mesh.component_names)
    specs = lay.members()
    spec_index = {s.name: i for i, s in enumerate(specs)}
    comp_member = np.array([spec_index.get(member_of(nm), -1) for nm in names] + [-1], np.int64)
    wings = []
    for w in lay.wings:
        up = np.asarray(lay.wing_up(w), np.float64)
        n_rib = np.asarray(w.rib_normal(up), np.float64)
        e2 = np.cross(up, n_rib)
        W = WingFrame(w.name, w.corners(), up, n_rib, e2 / np.linalg.norm(e2), np.asarray(w.rib_eta, np.float64),
                  np.asarray(w.spar_chord, np.float64), np.zeros(0), np.zeros(0))
        rk, _ = rib_knots_and_planes(W, W.rib_eta, W.spar_chord)
        wings.append((W, rk))
    # member sets of each node: up to two members (a third: the node does not move)
    f = mesh.faces
    valid = f >= 0
    node = f[valid]
    face = np.repeat(np.arange(mesh.n_faces), 4).reshape(-1, 4)[valid]
    mem = comp_member[mesh.component[face]]
    is_member_face = comp_member[mesh.component] >= 0
    skin_node = np.zeros(n, bool)
    skin_node[node[~is_member_face[face]]] = True
    pairs = np.unique(np.stack([node[mem >= 0], mem[mem >= 0]], 1), axis=0)
    count = np.bincount(pairs[:, 0], minlength=n)
    planes = np.full((n, 2), -1, np.int64)
    first = np.searchsorted(pairs[:, 0], np.arange(n))
    has1 = count >= 1
    planes[has1, 0] = pairs[first[has1], 1]
    has2 = count >= 2
    planes[has2, 1] = pairs[first[has2] + 1, 1]
    kind = np.where(count == 0, SKIN_NODE, np.where(skin_node, CHAIN_NODE, MEMBER_NODE)).astype(np.int8)
    frozen = count > 2
    # the wing each node follows and its plan coordinates
    P = mesh.points
    wing_of = np.full(n, -1, np.int64)
    r = np.zeros(n)
    c = np.zeros(n)
    wr = np.zeros(n)
    wc = np.zeros(n)
    wing_names = [w.name for w in lay.wings]
    member_wing = np.array([wing_names.index(s.wing) if s.wing in wing_names else -1 for s in specs], np.int64)
    out_wings = []
    best = np.zeros(n)                     # the largest move weight of a wing at each node so far
    m0 = planes[:, 0]
    for wi, (W, rk) in enumerate(wings):
        pitch_lo = rk[1] - rk[0] if len(rk) > 1 else 0.0
        pitch_hi = rk[-1] - rk[-2] if len(rk) > 1 else 0.0
        W.r_knots = np.concatenate([[rk[0] - pitch_lo], rk, [rk[-1] + pitch_hi]]) if len(rk) else np.zeros(0)
        W.c_knots = chord_knots(W.spar_chord)
        out_wings.append(W)
        ri, ci, etai = plan_coordinates(W, P)
        base, _ = plan_point(W, ri, ci)
        chord = np.linalg.norm((W.corners[1] - W.corners[0]) + etai[:, None] * (
            (W.corners[3] - W.corners[2]) - (W.corners[1] - W.corners[0])), axis=1)
        hgt = np.abs((P - base) @ W.up) / np.maximum(chord, 1e-300)
        w_h = np.clip(2.0 - hgt / HEIGHT_FADE, 0.0, 1.0)
        w_c = fade(ci, 0.0, 1.0, CHORD_FADE, CHORD_FADE) * w_h
        w_r = span_fade(W, rk, ri, ci, etai, w_c > 0) * w_h
        # member nodes follow their own wing; any other node the wing that moves it most (a wing's fade
        # beyond its end ribs does not reach into another wing's box, where that wing's weight is 1)
        weight = np.where(m0 >= 0, np.where(member_wing[np.maximum(m0, 0)] == wi, 2.0, 0.0), w_r * w_c)
        own = (weight > best) & ~frozen
        best = np.maximum(best, np.where(frozen, 0.0, weight))
        wing_of[own] = wi
        r[own], c[own] = ri[own], ci[own]
        mnode = m0[own] >= 0
        wr[own] = np.where(mnode, 1.0, w_r[own])
        wc[own] = np.where(mnode, 1.0, w_c[own] * w_r[own])
    # skin normals at the reference (a moved skin node's input triangle must face the same way)
    av = np.where(is_member_face[:, None], 0.0, mesh.face_area_vectors())
    nrm = np.zeros((n, 3))
    for dim in range(3):
        nrm[:, dim] = np.bincount(node, weights=np.repeat(av[:, dim], 4).reshape(-1, 4)[valid], minlength=n)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
    # nodes of geometric feature lines (trailing edges, creases): they keep to the input's crease
    feature = np.zeros(n, bool)
    feature[mesh.feature_edges[mesh.feature_edge_ids < 0].reshape(-1)] = True
    feature &= skin_node
    creases = Creases(locator, CREASE_ANGLE)
    crease_seg, crease_s = creases.locate(P, feature, 1e-6 * mesh.diagonal)
    feature &= crease_seg >= 0
    # member nodes: relative height between the skins below and above
    tau = np.zeros(n)
    mid = np.zeros(n)
    mn = np.flatnonzero((kind == MEMBER_NODE) & (wing_of >= 0))
    if len(mn):
        for wi, W in enumerate(out_wings):
            rows = mn[wing_of[mn] == wi]
            if not len(rows):
                continue
            lo_h, hi_h = skin_heights(locator, P[rows], W.up, P[rows] @ W.up)
            if not (np.isfinite(lo_h).all() and np.isfinite(hi_h).all()):
                bad = rows[~(np.isfinite(lo_h) & np.isfinite(hi_h))][0]
                raise ShellMeshError(f"morph: member node {bad} at {P[bad].round(4).tolist()} has no skin above "
                                     "or below it along up; the morph cannot follow this mesh")
            h = P[rows] @ W.up
            tau[rows] = (h - lo_h) / (hi_h - lo_h)
            mid[rows] = 0.5 * (lo_h + hi_h)
    ref = MorphReference(mesh=mesh, layout=lay, size=size, locator=locator, wings=out_wings, wing_of=wing_of,
                         kind=kind, planes=planes, r=r, c=c, weight_r=wr, weight_c=wc, tau=tau, mid=mid,
                         skin_normals=nrm, feature=feature, offset=np.zeros((n, 3)), creases=creases,
                         crease_seg=crease_seg, crease_s=crease_s, facing_away=np.zeros(n, bool),
                         member_names=[s.name for s in specs], member_wing=member_wing)
    # offsets of the skin nodes from the surface where the morph's rule places them
    rows = np.flatnonzero((wing_of >= 0) & (kind != MEMBER_NODE))
    if len(rows):
        ch = Choices(np.zeros(n, bool), np.full(n, -1, np.int64), np.full(n, -1, np.int64),
                      np.full(n, -1, np.int64), np.full(n, -1, np.int64))
        _, pp, pn = displacement(ref, ref.parameters())
        choose_skin(ref, ch, rows, P[rows], pp, pn)
        hit = rows[ch.skin_tri[rows] >= 0]
        ref.offset[hit] = P[hit] - skin_positions(ref, ch, hit, P[hit], pp, pn)
        # nodes whose ray already meets a triangle facing away at the reference (a face across a nose)
        ray = hit[~(ref.feature[hit] | ch.closest[hit])]
        nt = tri_frame(ref, ch.skin_tri[ray])[3]
        ref.facing_away[ray] = (nt * ref.skin_normals[ray]).sum(1) <= 0
    return ref


# ----------------------------------------------------------------------------- parameters
def morph_parameters(reference: MorphReference, layout=None, **given) -> dict:
    """``{wing: (rib_eta, spar_chord)}`` float arrays: those of ``layout`` (a Layout, dict or path of the
    same wings and member counts) or the reference's with ``given`` overrides
    ``{"<wing>:rib_eta": ..., "<wing>:spar_chord": ...}``."""
    out = reference.parameters()
    if layout is not None:
        lay = layout if isinstance(layout, Layout) else load_layout(layout)
        for w in lay.wings:
            if w.name not in out:
                raise LayoutError(f"morph: wing '{w.name}' is not a wing of the reference layout "
                                  f"({', '.join(out)})")
            out[w.name] = (np.asarray(w.rib_eta, np.float64), np.asarray(w.spar_chord, np.float64))
    for key, val in given.items():
        wing, _, what = key.rpartition(":")
        if wing not in out or what not in ("rib_eta", "spar_chord"):
            raise LayoutError(f"morph: unknown parameter '{key}'; give '<wing>:rib_eta' or '<wing>:spar_chord' "
                              f"of the wings {', '.join(out)}")
        eta, ch = out[wing]
        out[wing] = (np.asarray(val, np.float64), ch) if what == "rib_eta" else (eta, np.asarray(val, np.float64))
    for W in reference.wings:
        eta, ch = out[W.name]
        if eta.shape != W.rib_eta.shape or ch.shape != W.spar_chord.shape:
            raise LayoutError(f"morph: wing '{W.name}' needs {len(W.rib_eta)} rib stations and "
                              f"{len(W.spar_chord)} spar chord fractions (the reference's), got {len(eta)} and "
                              f"{len(ch)}: a change of the member counts is a new mesh, not a morph")
    return out


# ----------------------------------------------------------------------------- the morph
def displacement(ref: MorphReference, params: dict):
    """Plan displacement of every node (complex allowed) and its plane data: returns (delta (n, 3),
    plane points (m, 3), plane normals (m, 3)) for the reference's members."""
    n = ref.n_points
    dtype = np.result_type(*[np.asarray(v).dtype for p in params.values() for v in p], np.float64)
    delta = np.zeros((n, 3), dtype)
    m = len(ref.member_names)
    pp = np.zeros((m, 3), dtype)
    pn = np.zeros((m, 3), dtype)
    name_pos = {nm: i for i, nm in enumerate(ref.member_names)}
    for wi, W in enumerate(ref.wings):
        eta, ch = params[W.name]
        rk_new, planes = rib_knots_and_planes(W, np.asarray(eta), np.asarray(ch))
        for (what, k), (p, nv) in planes.items():
            nm = rib_name(W.name, k) if what == "rib" else spar_name(W.name, k)
            if nm in name_pos:
                pp[name_pos[nm]], pn[name_pos[nm]] = p, nv
        rows = np.flatnonzero(ref.wing_of == wi)
        if not len(rows):
            continue
        rk_ref = W.r_knots[1:-1]
        dr = np.concatenate([[0.0 * rk_new[0]], rk_new - rk_ref, [0.0 * rk_new[0]]])
        zc = 0.0 * np.sum(ch)
        dc = np.concatenate([[zc, zc], np.asarray(ch) - W.spar_chord, [zc, zc]])
        r, c = ref.r[rows], ref.c[rows]
        r2 = r + ref.weight_c[rows] * hat_interp(W.r_knots, r, dr)
        c2 = c + ref.weight_r[rows] * hat_interp(W.c_knots, c, dc)
        a, _ = plan_point(W, r2, c2)
        b, _ = plan_point(W, r + 0.0 * r2, c + 0.0 * c2)
        d = a - b
        same = (r2 == r) & (c2 == c)
        d[same] = 0.0
        delta[rows] = d
    return delta, pp, pn


def evaluate(ref: MorphReference, params: dict, ch: Choices | None):
    """Node coordinates for ``params``; ``ch`` None: the real evaluation that makes the choices."""
    P = ref.mesh.points
    delta, pp, pn = displacement(ref, params)
    moved = np.any(delta != 0, axis=1) if ch is None else ch.moved
    x = P.astype(delta.dtype).copy()
    n = len(P)
    if ch is None:
        ch = Choices(moved, np.full(n, -1, np.int64), np.full(n, -1, np.int64), np.full(n, -1, np.int64),
                      np.full(n, -1, np.int64))
        make = True
    else:
        make = False
    skin = np.flatnonzero(moved & (ref.kind != MEMBER_NODE))
    if len(skin):
        y = P[skin] + delta[skin]
        if make:
            choose_skin(ref, ch, skin, y.real, pp.real, pn.real)
        q = skin_positions(ref, ch, skin, y, pp, pn)
        # every skin node keeps its offset from where this rule puts it at the reference (planarize
        # moves some off the surface on purpose), so the morph is continuous at the reference layout;
        # a member's skin node then goes back into its plane(s)
        q = q + ref.offset[skin]
        rows = np.flatnonzero((ref.kind[skin] == CHAIN_NODE) & ref.offset[skin].any(axis=1))
        for two in (False, True):
            sel = rows[(ref.planes[skin[rows], 1] >= 0) == two]
            if len(sel):
                q[sel] = onto_planes(q[sel], ref.planes[skin[sel]], pp, pn, two)
        x[skin] = q
    mem = np.flatnonzero(moved & (ref.kind == MEMBER_NODE))
    if len(mem):
        for wi, W in enumerate(ref.wings):
            rows = mem[ref.wing_of[mem] == wi]
            if not len(rows):
                continue
            d = delta[rows]
            du = d @ W.up
            base = P[rows] + d - du[:, None] * W.up - (P[rows] @ W.up)[:, None] * W.up   # plan point, height 0
            h_mid = ref.mid[rows] + du
            o = base + h_mid[:, None] * W.up
            if make:
                ch.ray_lo[rows], ch.ray_hi[rows] = member_rays(ref, o.real, W.up)
            t_hi, t_lo = ch.ray_hi[rows], ch.ray_lo[rows]
            if (t_hi < 0).any() or (t_lo < 0).any():
                raise NoSkinError(rows[(t_hi < 0) | (t_lo < 0)][0])
            s = []
            for t in (t_lo, t_hi):
                a, _, _, nt = tri_frame(ref, t)
                s.append(dot(a - o, nt) / (nt @ W.up))
            hh = s[0] + ref.tau[rows] * (s[1] - s[0])
            x[rows] = o + hh[:, None] * W.up
        # onto the member plane, or the line of two
        for two in (False, True):
            sel = mem[(ref.planes[mem, 1] >= 0) == two]
            if len(sel):
                x[sel] = onto_planes(x[sel], ref.planes[sel], pp, pn, two)
    return x, ch, pp, pn


def morph(reference: MorphReference, params=None, *, check: bool = True, min_sj: float = POOR_JACOBIAN):
    """Node coordinates (n, 3) of the reference mesh's elements for the layout parameters ``params``
    (``{wing: (rib_eta, spar_chord)}``, :func:`morph_parameters`; None: the reference's, which gives
    the reference mesh bit for bit) and the :class:`MorphCheck` (``check``; None without; ``min_sj``
    its scaled Jacobian bound, default the README's 0.2)."""
    params = reference.parameters() if params is None else params
    try:
        x, ch, pp, pn = evaluate(reference, params, None)
    except NoSkinError as e:
        P = reference.mesh.points.copy()
        return P, (MorphCheck(False, float("nan"), float("nan"), float("nan"), 0, str(e)) if check else None)
    x = np.ascontiguousarray(x.real)
    return x, (morph_check(reference, x, ch, pp.real, pn.real, min_sj=min_sj) if check else None)


def morph_jacobian(reference: MorphReference, params=None, wrt=None) -> dict:
    """Exact derivatives of :func:`morph`'s coordinates (flattened, (3n,)) with respect to each
    layout parameter: ``{"<wing>:rib_eta": (3n, K), "<wing>:spar_chord": (3n, J)}`` (``wrt``: a subset
    of those names). Complex step through the morph's arithmetic with the input triangles of the
    real evaluation held: exact to rounding wherever a node stays on one input triangle, edge or
    vertex; where a node sits on an input edge or vertex (a kink of the faceted input), the mean of
    the derivatives from either side, which is what a central difference converges to."""
    params = reference.parameters() if params is None else {k: (np.asarray(a, np.float64), np.asarray(b, np.float64))
                                                              for k, (a, b) in params.items()}
    _, ch, pp_r, pn_r = evaluate(reference, params, None)
    delta_r, _, _ = displacement(reference, params)
    out = {}
    h = COMPLEX_STEP
    for W in reference.wings:
        for what, pos in (("rib_eta", 0), ("spar_chord", 1)):
            name = f"{W.name}:{what}"
            if wrt is not None and name not in wrt:
                continue
            base = params[W.name][pos]
            J = np.zeros((3 * reference.n_points, len(base)))
            for i in range(len(base)):
                v = base.astype(np.complex128)
                v[i] += 1j * h
                p = {k: (a.astype(np.complex128), b.astype(np.complex128)) for k, (a, b) in params.items()}
                p[W.name] = (v, p[W.name][1]) if pos == 0 else (p[W.name][0], v)
                delta, _, _ = displacement(reference, p)
                # the mean of the two one-sided derivatives (equal but where a node sits on an input
                # edge or vertex, a kink: there the mean is what a central difference converges to)
                for side in (1.0, -1.0):
                    x, _, _, _ = evaluate(reference, p, side_choices(reference, ch, delta_r, delta.imag, side,
                                                                            pp_r, pn_r))
                    J[:, i] += 0.5 * (x.imag / h).reshape(-1)
            out[name] = J
    return out


def on_facing_triangle(ref: MorphReference, rows, tri, x, tol: float) -> np.ndarray:
    """(k,) bool: node ``rows[i]`` at ``x[i]`` lies within ``tol`` of an input triangle that faces its
    reference side, among the triangles around the vertices of input triangle ``tri[i]`` (a node on a sharp
    edge, such as a trailing edge, is on the triangles of both sides: the ray's pick of the other
    side's is no fold)."""
    rows = np.asarray(rows, np.int64)
    if not len(rows):
        return np.zeros(0, bool)
    owner, cand = ref.locator.triangle_neighbourhoods(tri)
    a, b, c, nt = tri_frame(ref, cand)
    facing = (nt * ref.skin_normals[rows[owner]]).sum(1) > 0
    d = np.linalg.norm(closest_point_on_triangles(x[owner], a, b, c) - x[owner], axis=1)
    ok = np.zeros(len(rows), bool)
    np.logical_or.at(ok, owner, facing & (d <= tol))
    return ok


def morph_check(reference: MorphReference, x, ch=None, plane_points=None, plane_normals=None,
                min_sj: float = POOR_JACOBIAN) -> MorphCheck:
    """The checks of a morphed mesh (coordinates ``x``): every element's scaled Jacobian above
    ``min_sj``, moved skin nodes no farther from the input surface than their offset at the reference
    (0 but for planarize's nodes; plus the gate's tolerance), member nodes on their planes (within 1e-7
    of the model's size), no moved skin node on an input triangle facing away from its reference normal (unless
    it did so at the reference already: a face across a nose much tighter than the element)."""
    ref = reference
    sj = element_quality(x, ref.mesh.faces, metrics=("scaled_jacobian",))["scaled_jacobian"]
    diag = ref.mesh.diagonal
    moved = np.any(x != ref.mesh.points, axis=1)
    sk = np.flatnonzero(moved & (ref.kind != MEMBER_NODE))
    dist = ref.locator.closest(x[sk])[2] if len(sk) else np.zeros(0)
    flipped = 0
    if ch is not None and len(sk):
        ray = sk[~(ref.feature[sk] | ch.closest[sk] | ref.facing_away[sk])]
        _, _, _, nt = tri_frame(ref, np.maximum(ch.skin_tri[ray], 0))
        away = ray[(nt * ref.skin_normals[ray]).sum(1) <= 0]
        flipped = int(len(away) - on_facing_triangle(ref, away, np.maximum(ch.skin_tri[away], 0), x[away],
                                                        PLANE_TOL * diag).sum())
    dplane = np.zeros(0)
    if plane_points is not None:
        mem = np.flatnonzero(moved & (ref.planes[:, 0] >= 0))
        ds = []
        for col in (0, 1):
            rows = mem[ref.planes[mem, col] >= 0]
            m = ref.planes[rows, col]
            ds.append(np.abs(dot(x[rows] - plane_points[m], plane_normals[m])))
        dplane = np.concatenate(ds)
    msj = float(sj.min()) if len(sj) else float("nan")
    dmax = float(dist.max(initial=0.0))
    pmax = float(dplane.max(initial=0.0))
    reasons = []
    if not msj > min_sj:
        k = int(np.argmin(sj))
        reasons.append(f"{int((sj <= min_sj).sum())} elements with scaled Jacobian <= {min_sj:g} (the lowest "
                       f"{msj:.3f}, element {k})")
    # a skin node is as far from the input as at the reference (planarize's offsets), no farther
    allowed = np.linalg.norm(ref.offset[sk], axis=1) + SURFACE_TOL * diag if len(sk) else np.zeros(0)
    if len(sk) and not (dist <= allowed).all():
        k = int(np.argmax(dist - allowed))
        reasons.append(f"a skin node {dist[k]:.3g} off the input surface ({allowed[k]:.3g} at the reference)")
    if not pmax <= PLANE_TOL * diag * 100:
        reasons.append(f"a member node {pmax:.3g} off its plane")
    if flipped:
        reasons.append(f"{flipped} skin nodes on input triangles facing away from their reference side")
    return MorphCheck(not reasons, msj, dmax, pmax, flipped, "; ".join(reasons))
