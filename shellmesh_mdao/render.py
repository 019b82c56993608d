"""Off-screen pictures of shell meshes with pyvista/VTK (no display needed).

:func:`render_mesh` draws one view of a mesh into a PNG: the whole model from above and
to the side (``"iso"``), from above (``"top"``), or a close-up of a wing box with its upper
skin bays hidden so the ribs and spars show (``"wingbox"``). Faces are coloured by
component family (``color="component"``: skin, upper/lower skin bays, ribs, spars, each
component a shade of its family colour, with a legend) or by one quality metric of
:func:`shellmesh_mdao.quality.element_quality` (with a colour bar). :func:`render_worst`
marks the N elements with the lowest scaled Jacobian on the whole aircraft,
:func:`render_worst_closeups` shows each of them in its neighbourhood, and
:func:`render_views` writes the standard set of pictures for a report.

Off-screen OpenGL: on Linux without ``DISPLAY`` the module asks VTK for an EGL window
(Mesa's software renderer works: Debian packages ``libegl1 libgl1-mesa-dri``); without
EGL, VTK falls back to OSMesa (``libosmesa6``) or X (``xvfb``). Every picture is written
atomically; a blank picture (no working OpenGL context) raises :class:`OutputError` with
the install step.
"""
from __future__ import annotations

import ctypes.util
import logging
import os
import sys
import time
from pathlib import Path

import numpy as np

from .errors import OutputError
from .families import BOX_FAMILIES, component_family, name_head
from .mesh import ShellMesh
from .quality import ACCEPTANCE, METRICS, element_quality

log = logging.getLogger("shellmesh_mdao")

# component_family is re-exported from .families (its home)
__all__ = ["COLOR_OPTIONS", "VIEWS", "FAMILY_COLORS", "component_family", "component_colors",
           "element_ids", "worst_elements", "to_pyvista", "load_any", "render_mesh", "render_worst",
           "render_worst_closeups", "render_views", "check_offscreen", "OFFSCREEN_HELP"]

#: ``color=`` choices: component families, or one quality metric per element.
COLOR_OPTIONS = ("component",) + tuple(METRICS)

#: ``view=`` choices of :func:`render_mesh`.
VIEWS = ("iso", "top", "wingbox")

#: Base colours of the component families and their alternating shades (RGB 0..255).
FAMILY_COLORS = {
    "skin": [(205, 205, 205), (190, 190, 190), (215, 215, 215)],
    "upper skin": [(107, 174, 214), (66, 146, 198), (158, 202, 225)],
    "lower skin": [(116, 196, 118), (65, 171, 93), (161, 217, 155)],
    "rib": [(253, 141, 60), (230, 85, 13), (253, 174, 107)],
    "spar": [(158, 154, 200), (117, 107, 177), (188, 189, 220)],
    "member": [(231, 186, 82), (189, 158, 57), (231, 203, 148)],
}

#: Colour map, colour limits and label of each metric (values outside the limits clamp).
METRIC_STYLE = {
    "scaled_jacobian": ("RdYlGn", (0.0, 1.0), "scaled Jacobian"),
    "min_angle": ("RdYlGn", (0.0, 90.0), "min corner angle [deg]"),
    "max_angle": ("RdYlGn_r", (90.0, 180.0), "max corner angle [deg]"),
    "aspect": ("RdYlGn_r", (1.0, 6.0), "aspect ratio"),
    "skew": ("RdYlGn_r", (0.0, 60.0), "skew [deg]"),
    "warp": ("RdYlGn_r", (0.0, 15.0), "warp [deg]"),
    "taper": ("RdYlGn_r", (0.0, 1.0), "taper"),
}

#: The install step printed when no off-screen OpenGL context can be made.
OFFSCREEN_HELP = ("install an off-screen OpenGL: 'sudo apt-get install -y libegl1 libgl1-mesa-dri' "
                  "(EGL, used by default without a display), or 'libosmesa6', or run under "
                  "'xvfb-run'; or pass --no-pictures")

_BACKGROUND = (255, 255, 255)
_LIGHT = dict(ambient=0.35, diffuse=0.7, specular=0.0)
_WINDOW = (1600, 1000)


# ----------------------------------------------------------------------------- helpers
def _select_window() -> None:
    """Without a display on Linux, ask VTK for an EGL window (when libEGL is installed)."""
    if (sys.platform.startswith("linux") and not os.environ.get("DISPLAY")
            and not os.environ.get("WAYLAND_DISPLAY") and "VTK_DEFAULT_OPENGL_WINDOW" not in os.environ
            and ctypes.util.find_library("EGL")):
        os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = "vtkEGLRenderWindow"


def _pyvista():
    """Import pyvista set up for off-screen rendering (EGL when there is no display)."""
    _select_window()
    import pyvista as pv

    pv.OFF_SCREEN = True
    return pv


_PROBE_CODE = ("import sys, pyvista as pv\n"
               "pl = pv.Plotter(off_screen=True, window_size=(64, 48))\n"
               "pl.add_mesh(pv.Sphere())\n"
               "img = pl.screenshot(None, return_img=True)\n"
               "pl.close()\n"
               "sys.exit(0 if img.std() > 0 else 3)\n")
_probe_result: tuple | None = None


def check_offscreen() -> None:
    """Raise :class:`OutputError` with the install step when no off-screen OpenGL context
    works. Probed once per process by a tiny render in a subprocess, because VTK crashes the
    process (segmentation fault) when it finds no usable OpenGL library."""
    global _probe_result
    if _probe_result is None:
        import subprocess

        _select_window()
        try:
            r = subprocess.run([sys.executable, "-c", _PROBE_CODE], capture_output=True, text=True, timeout=180)
            if r.returncode == 0:
                _probe_result = (True, "")
            elif r.returncode == 3:
                _probe_result = (False, "a test render came out blank")
            elif r.returncode < 0:
                _probe_result = (False, f"a test render crashed (signal {-r.returncode})")
            else:
                last = (r.stderr.strip().splitlines() or ["?"])[-1][:200]
                _probe_result = (False, f"a test render failed: {last}")
        except (OSError, subprocess.TimeoutExpired) as e:
            _probe_result = (False, f"a test render could not run ({type(e).__name__})")
    if not _probe_result[0]:
        raise OutputError(f"no working off-screen OpenGL ({_probe_result[1]}); " + OFFSCREEN_HELP)


def component_colors(names) -> tuple[np.ndarray, list[str]]:
    """``(rgb, family)``: an (ncomp, 3) uint8 colour per component (its family colour, the
    shade alternating between successive components of a family) and the family names."""
    fam = [component_family(n) for n in names]
    seen: dict[str, int] = {}
    rgb = np.zeros((len(names), 3), np.uint8)
    for i, f in enumerate(fam):
        k = seen.get(f, 0)
        seen[f] = k + 1
        shades = FAMILY_COLORS[f]
        rgb[i] = shades[k % len(shades)]
    return rgb, fam


def element_ids(mesh: ShellMesh) -> np.ndarray:
    """(m,) element id of every face in the written files: every writer puts the faces in
    :func:`~shellmesh_mdao.export.export_order` and .bdf/.inp/.msh number them from 1 (in a
    .vtu the id is the cell index + 1)."""
    from .export import export_order

    eid = np.empty(mesh.n_faces, np.int64)
    eid[export_order(mesh)] = np.arange(1, mesh.n_faces + 1)
    return eid


_WORSE_HIGH = {"aspect", "max_angle", "skew", "warp", "taper"}


def worst_elements(mesh: ShellMesh, n: int = 10, metric: str = "scaled_jacobian",
                   metrics: dict | None = None) -> np.ndarray:
    """Indices of the ``n`` worst faces by ``metric`` (lowest scaled Jacobian / min angle,
    highest aspect, max angle, skew, warp, taper), worst first; ties by face index."""
    if metric not in METRICS:
        raise OutputError(f"unknown metric {metric!r}; use one of {', '.join(METRICS)}")
    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    v = np.nan_to_num(np.asarray(q[metric], float), nan=np.inf, posinf=np.inf, neginf=-np.inf)
    key = -v if metric in _WORSE_HIGH else v
    order = np.argsort(key, kind="stable")
    return order[:max(0, min(int(n), mesh.n_faces))]


def to_pyvista(mesh: ShellMesh, faces: np.ndarray | None = None):
    """``pyvista.PolyData`` of the mesh (all faces, or the face indices ``faces``) with cell
    data ``component``; triangles and quads as they are."""
    pv = _pyvista()
    sel = np.arange(mesh.n_faces) if faces is None else np.asarray(faces, np.int64)
    f = mesh.faces[sel]
    n = np.where(f[:, 3] >= 0, 4, 3)
    arr = np.column_stack([n, f])
    flat = arr[arr >= 0]                 # row-major: drops the -1 slot of every triangle
    poly = pv.PolyData(mesh.points, faces=flat)
    poly.cell_data["component"] = mesh.component[sel]
    return poly


def load_any(path) -> ShellMesh:
    """A mesh file written by shellmesh (.vtu .msh .bdf .nas .inp, exactly) or any surface
    file :func:`~shellmesh_mdao.load.load_surface` reads (.stl .obj ...)."""
    from .errors import InputFileError
    from .load import MESH_FORMATS, load_mesh, load_surface

    p = Path(path)
    if p.suffix.lower() in MESH_FORMATS:
        try:
            return load_mesh(p)
        except InputFileError:
            if not p.is_file():
                raise
    return load_surface(p)[0]


def _frame(points: np.ndarray, up=None):
    """Centre and three orthonormal axes: longest extent, middle extent, up (the axis of the
    smallest bounding-box extent unless ``up`` is given)."""
    lo, hi = points.min(0), points.max(0)
    ext = hi - lo
    center = 0.5 * (lo + hi)
    axes = np.eye(3)
    if up is None:
        u = axes[int(np.argmin(ext))]
    else:
        u = np.asarray(up, float)
        u = u / np.linalg.norm(u)
    # the remaining axes: coordinate axes made orthogonal to up, ordered by extent
    cand = axes - np.outer(axes @ u, u)
    norms = np.linalg.norm(cand, axis=1)
    proj_ext = np.abs(ext @ np.abs(cand.T / np.maximum(norms, 1e-12)))
    proj_ext[norms < 0.3] = -1.0
    i_long = int(np.argmax(proj_ext))
    e_long = cand[i_long] / norms[i_long]
    e_mid = np.cross(u, e_long)
    if e_mid @ axes[int(np.argmax(np.abs(e_mid)))] < 0:
        e_mid = -e_mid                   # keep the middle axis along a positive coordinate axis
    return center, e_long, e_mid, u


def _fit_camera(pl, pts: np.ndarray, d: np.ndarray, vup: np.ndarray, *, center=None, parallel=False,
                margin: float = 1.06):
    """Look along ``-d`` (``d`` points from the scene to the camera) with ``vup`` up and frame
    ``pts`` tightly in the current viewport (centred on ``center`` when given)."""
    d = np.asarray(d, float) / np.linalg.norm(d)
    up = np.asarray(vup, float) - (np.asarray(vup, float) @ d) * d
    up /= np.linalg.norm(up)
    right = np.cross(-d, up)
    c = 0.5 * (pts.min(0) + pts.max(0)) if center is None else np.asarray(center, float)
    rel = pts - c
    x, y, z = rel @ right, rel @ up, rel @ d
    if center is None:                   # centre the projected box
        c = c + right * 0.5 * (x.max() + x.min()) + up * 0.5 * (y.max() + y.min())
        x = x - 0.5 * (x.max() + x.min())
        y = y - 0.5 * (y.max() + y.min())
        half_w, half_h = 0.5 * float(np.ptp(x)), 0.5 * float(np.ptp(y))
    else:
        half_w, half_h = float(np.abs(x).max()), float(np.abs(y).max())
    w, h = pl.renderer.GetSize() if hasattr(pl.renderer, "GetSize") else pl.window_size
    aspect = w / max(h, 1)
    H = max(half_h, half_w / aspect, 1e-12) * margin
    depth = float(np.abs(z).max()) if len(z) else 0.0
    cam = pl.camera
    if parallel:
        pl.enable_parallel_projection()
        dist = 2.0 * depth + 4.0 * H
        cam.parallel_scale = H
    else:
        dist = H / np.tan(np.radians(cam.view_angle) / 2.0) + float(z.max())
    cam.focal_point = c
    cam.position = c + dist * d
    cam.up = up
    pl.renderer.reset_camera_clipping_range()


def _to_pixels(pl, pts: np.ndarray, window_size) -> np.ndarray:
    """(k, 2) pixel coordinates (origin lower left) of world points in the current view."""
    w, h = window_size
    m = pl.camera.GetCompositeProjectionTransformMatrix(w / h, -1, 1)
    M = np.array([[m.GetElement(i, j) for j in range(4)] for i in range(4)])
    ph = np.column_stack([pts, np.ones(len(pts))]) @ M.T
    ndc = ph[:, :2] / ph[:, 3:4]
    return (ndc + 1.0) * 0.5 * np.array([w, h], float)


def _rank_labels(pl, pts: np.ndarray, window_size, min_px: float = 36.0):
    """Numbered labels (1 = first point) at ``pts``; points closer than ``min_px`` on screen
    share one label ``"3,4"`` so none hides another."""
    xy = _to_pixels(pl, pts, window_size)
    groups: list[list[int]] = []
    anchors: list[np.ndarray] = []
    for i in range(len(xy)):
        for g, a in zip(groups, anchors):
            if np.linalg.norm(xy[i] - a) < min_px:
                g.append(i)
                break
        else:
            groups.append([i])
            anchors.append(xy[i])
    w, h = window_size
    for g, a in zip(groups, anchors):
        x = int(np.clip(a[0] + 10, 0, w - 60))
        y = int(np.clip(a[1] + 8, 0, h - 24))
        actor = pl.add_text(",".join(str(i + 1) for i in g), position=(x, y), font_size=13, color="white")
        tp = actor.GetTextProperty()
        tp.SetBackgroundColor(0.75, 0.0, 0.0)
        tp.SetBackgroundOpacity(0.9)
        tp.SetBold(True)


def _view_direction(view: str, e_long, e_mid, u):
    """(d, vup) of a named view: ``top`` looks down ``-up``; ``iso`` from above, ahead and aside."""
    if view == "top":
        return u, -e_mid
    d = -0.62 * e_mid - 0.55 * e_long + 0.56 * u
    return d / np.linalg.norm(d), u


def _plotter(window_size):
    check_offscreen()
    pv = _pyvista()
    try:
        pl = pv.Plotter(off_screen=True, window_size=list(window_size))
    except Exception as e:  # no OpenGL context at all
        raise OutputError(f"cannot open an off-screen render window ({type(e).__name__}: {e}); "
                          + OFFSCREEN_HELP) from None
    pl.set_background(tuple(c / 255 for c in _BACKGROUND))
    return pl


def _save(pl, out_png) -> Path:
    """Screenshot to ``out_png`` atomically; raise OutputError for a blank image."""
    from PIL import Image

    from .export import atomic_write

    out_png = Path(out_png)
    if out_png.suffix.lower() != ".png":
        raise OutputError(f"cannot write {out_png.name}: pictures are PNG files; give a name ending in .png")
    try:
        img = pl.screenshot(None, return_img=True)
    except Exception as e:
        raise OutputError(f"rendering failed ({type(e).__name__}: {e}); " + OFFSCREEN_HELP) from None
    finally:
        pl.close()
    img = np.asarray(img)
    if img.size == 0 or int(img.max()) == int(img.min()):
        raise OutputError("rendering produced a blank picture: no working off-screen OpenGL; " + OFFSCREEN_HELP)
    return atomic_write(out_png, lambda p: Image.fromarray(img).save(p, format="PNG"))


def _edges_auto(n_visible: int, window_size) -> bool:
    """Element edges stay readable while an element covers about 30 pixels or more."""
    return n_visible <= window_size[0] * window_size[1] / 30


def _box_faces(mesh: ShellMesh, fam: list[str]):
    """(wing prefix, mask of its box faces, mask of upper-skin faces) for the first wing with a
    box (upper/lower skin bays, ribs or spars)."""
    names = mesh.component_names
    fam_arr = np.array(fam + ["member"] * max(0, int(mesh.component.max(initial=-1)) + 1 - len(fam)))
    box_c = [i for i, f in enumerate(fam) if f in BOX_FAMILIES]
    if not box_c:
        return None, None, None
    present = set(np.unique(mesh.component).tolist())
    box_c = [i for i in box_c if i in present]
    if not box_c:
        return None, None, None
    wing = name_head(names[box_c[0]]) if "/" in names[box_c[0]] else ""
    in_wing = np.array([(name_head(n) == wing) if wing else True for n in names] + [False] * (len(fam_arr) - len(names)))
    cf = fam_arr[mesh.component]
    box = np.isin(cf, list(BOX_FAMILIES)) & in_wing[mesh.component]
    upper = np.isin(cf, ["upper skin"])
    return wing, box, upper


def _add_legend(pl, fam, present):
    labels = []
    seen = set()
    for i in present:
        f = fam[i] if i < len(fam) else "member"
        if f in seen:
            continue
        seen.add(f)
        labels.append([f, tuple(c / 255 for c in FAMILY_COLORS[f][0])])
    order = list(FAMILY_COLORS)
    labels.sort(key=lambda x: order.index(x[0]))
    if labels:
        leg = pl.add_legend(labels=labels, bcolor="white", border=True, size=(0.13, 0.035 * len(labels) + 0.01),
                            loc="upper right", face="rectangle")
        _dark_legend_text(leg, labels)


def _dark_legend_text(leg, labels):
    """Legend entries with dark text: the entry colour goes to the text, the swatch keeps its
    colour as cell scalars of the symbol."""
    pv = _pyvista()
    for i, (_, c) in enumerate(labels):
        sym = pv.wrap(leg.GetEntrySymbol(i)).copy()
        sym.cell_data["rgb"] = np.tile(np.round(np.asarray(c) * 255).astype(np.uint8), (sym.n_cells, 1))
        sym.cell_data.active_scalars_name = "rgb"
        leg.SetEntrySymbol(i, sym)
        leg.SetEntryColor(i, 0.1, 0.1, 0.1)


def _metric_values(mesh: ShellMesh, color: str, metrics: dict | None) -> np.ndarray:
    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    cmap, clim, _ = METRIC_STYLE[color]
    v = np.asarray(q[color], float)
    return np.clip(np.nan_to_num(v, nan=clim[0], posinf=clim[1], neginf=clim[0]), clim[0], clim[1])


def _acceptance_text(color: str) -> str:
    qa, ta = ACCEPTANCE["quad"][color], ACCEPTANCE["tri"][color]

    def rng(r):
        lo, hi = r
        return f">= {lo:g}" if hi is None else (f"<= {hi:g}" if lo is None else f"[{lo:g}, {hi:g}]")
    return f"acceptance: quads {rng(qa)}, triangles {rng(ta)}"


# ----------------------------------------------------------------------------- public API
def render_mesh(mesh, out_png, color: str = "component", view: str = "iso", *,
                window_size=_WINDOW, edges: bool | None = None, up=None, title: str | None = None,
                metrics: dict | None = None, highlight=None) -> Path:
    """Draw ``mesh`` (a :class:`ShellMesh` or a mesh/surface file) off-screen into ``out_png``.

    ``color``: ``"component"`` (family colours, legend) or a metric of :data:`COLOR_OPTIONS`
    (colour bar). ``view``: ``"iso"`` (whole model from above, front and side), ``"top"``
    (parallel projection along ``up``) or ``"wingbox"`` (close-up of the first wing box,
    upper skin bays hidden, the rest of the skin faint). ``edges``: draw element edges
    (default: when elements are big enough on screen; else the feature/chain lines are
    drawn). ``up``: the model's up direction (default: the axis of smallest extent).
    ``metrics`` may pass a precomputed :func:`element_quality`; ``highlight`` face indices
    drawn red. Returns the written path. Raises :class:`OutputError` (unknown option,
    unwritable path, no off-screen OpenGL)."""
    t0 = time.perf_counter()
    if color not in COLOR_OPTIONS:
        raise OutputError(f"unknown colour {color!r}; use one of {', '.join(COLOR_OPTIONS)}")
    if view not in VIEWS:
        raise OutputError(f"unknown view {view!r}; use one of {', '.join(VIEWS)}")
    if not isinstance(mesh, ShellMesh):
        mesh = load_any(mesh)
    if mesh.n_faces == 0:
        raise OutputError("the mesh has no faces: nothing to draw")
    out_png = Path(out_png)
    if out_png.suffix.lower() != ".png":
        raise OutputError(f"cannot write {out_png.name}: pictures are PNG files; give a name ending in .png")
    rgb, fam = component_colors(mesh.component_names)
    center, e_long, e_mid, u = _frame(mesh.points, up)
    shown = np.ones(mesh.n_faces, bool)
    faint = np.zeros(mesh.n_faces, bool)
    focus = mesh.points
    label = ""
    if view == "wingbox":
        wing, box, upper = _box_faces(mesh, fam)
        if box is None or not box.any():
            raise OutputError("view 'wingbox' needs a mesh with wing-box components (<wing>/upper_skin/..., "
                              "ribs, spars): mesh with a layout first, or use --view iso/top")
        fam_arr = np.array([component_family(n) for n in mesh.component_names])
        cf = fam_arr[mesh.component]
        shown = ~upper & (cf != "skin")
        faint = cf == "skin"
        used = np.unique(mesh.faces[box][:, :3].ravel())
        focus = mesh.points[used]
        label = f"wing box of {wing}: upper skin hidden" if wing else "wing box: upper skin hidden"
    pl = _plotter(window_size)
    try:
        idx = np.flatnonzero(shown)
        poly = to_pyvista(mesh, idx)
        in_focus = idx
        if view == "wingbox":
            lo, hi = focus.min(0), focus.max(0)
            c = mesh.face_centroids()[idx]
            in_focus = idx[np.all((c >= lo) & (c <= hi), axis=1)]
        show_edges = _edges_auto(len(in_focus), window_size) if edges is None else bool(edges)
        kw = dict(show_edges=show_edges, edge_color=(0.15, 0.15, 0.15), line_width=1, **_LIGHT)
        if color == "component":
            poly.cell_data["rgb"] = rgb[mesh.component[idx]]
            actor = pl.add_mesh(poly, scalars="rgb", rgb=True, **kw)
            _add_legend(pl, fam, np.unique(mesh.component[idx]).tolist())
        else:
            cmap, clim, lab = METRIC_STYLE[color]
            poly.cell_data[color] = _metric_values(mesh, color, metrics)[idx]
            actor = pl.add_mesh(poly, scalars=color, cmap=cmap, clim=clim, show_scalar_bar=False, **kw)
            pl.add_scalar_bar(title=lab, n_labels=6, fmt="%.3g", vertical=False, position_x=0.3,
                              position_y=0.03, width=0.4, height=0.07, color="black",
                              title_font_size=18, label_font_size=16)
            label = (label + "; " if label else "") + _acceptance_text(color)
        if faint.any():
            pl.add_mesh(to_pyvista(mesh, np.flatnonzero(faint)), color=(0.75, 0.75, 0.75), opacity=0.18,
                        show_edges=False, lighting=False)
        if not show_edges and len(mesh.feature_edges):
            fe = mesh.feature_edges
            if view == "wingbox":            # only the chains on faces that are drawn
                vis = np.zeros(mesh.n_points, bool)
                vis[mesh.faces[idx][mesh.faces[idx] >= 0]] = True
                fe = fe[vis[fe].all(1)]
            if len(fe):
                pv = _pyvista()
                lines = pv.PolyData(mesh.points, lines=np.column_stack([np.full(len(fe), 2), fe]).ravel())
                # push the faces back a little so the chains lying on them are not hidden
                actor.mapper.SetResolveCoincidentTopologyToPolygonOffset()
                actor.mapper.SetRelativeCoincidentTopologyPolygonOffsetParameters(2.0, 2.0)
                pl.add_mesh(lines, color=(0.1, 0.1, 0.1), line_width=1.5)
        if highlight is not None and len(highlight):
            pl.add_mesh(to_pyvista(mesh, np.asarray(highlight)), color=(0.9, 0.0, 0.0), show_edges=True,
                        edge_color=(0.4, 0, 0), line_width=2)
        head = title if title is not None else (
            f"{mesh.n_faces} elements ({mesh.n_quads} quads, {mesh.n_tris} triangles), {mesh.n_points} nodes")
        pl.add_text(head + (f"\n{label}" if label else ""), position="upper_left", font_size=11, color="black")
        d, vup = _view_direction(view, e_long, e_mid, u)
        # leave room for the colour bar at the bottom
        _fit_camera(pl, focus, d, vup, parallel=view == "top", margin=1.06 if color == "component" else 1.25)
    except BaseException:
        pl.close()
        raise
    out = _save(pl, out_png)
    log.debug("rendered %s (%s, %s view, %d faces) in %.2f s", out, color, view, len(idx), time.perf_counter() - t0)
    return out


def render_worst(mesh: ShellMesh, out_png, n: int = 10, metric: str = "scaled_jacobian", *,
                 window_size=_WINDOW, up=None, metrics: dict | None = None) -> Path:
    """The ``n`` worst elements by ``metric`` (default lowest scaled Jacobian) marked on the
    whole model: the model faint and see-through, each worst element red with a numbered
    marker (1 = worst). Returns the written path."""
    t0 = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        mesh = load_any(mesh)
    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    worst = worst_elements(mesh, n, metric, q)
    center, e_long, e_mid, u = _frame(mesh.points, up)
    pv = _pyvista()
    pl = _plotter(window_size)
    try:
        rgb, _ = component_colors(mesh.component_names)
        poly = to_pyvista(mesh)
        poly.cell_data["rgb"] = rgb[mesh.component]
        pl.add_mesh(poly, scalars="rgb", rgb=True, opacity=0.35, show_edges=False)
        if len(worst):
            pl.add_mesh(to_pyvista(mesh, worst), color=(0.9, 0, 0), show_edges=True, edge_color=(0.4, 0, 0),
                        line_width=3)
            cen = mesh.face_centroids()[worst]
            pts = pv.PolyData(cen)
            pl.add_mesh(pts, color=(0.9, 0, 0), point_size=14, render_points_as_spheres=True)
        lab = METRIC_STYLE[metric][2]
        vals = ", ".join(f"{i + 1}: {q[metric][w]:.3g}" for i, w in enumerate(worst[:10]))
        pl.add_text(f"{len(worst)} worst elements by {lab} (1 = worst)\n{vals}", position="upper_left",
                    font_size=11, color="black")
        d, vup = _view_direction("iso", e_long, e_mid, u)
        _fit_camera(pl, mesh.points, d, vup)
        if len(worst):
            _rank_labels(pl, mesh.face_centroids()[worst], window_size)
    except BaseException:
        pl.close()
        raise
    out = _save(pl, out_png)
    log.debug("rendered %s (%d worst elements) in %.2f s", out, len(worst), time.perf_counter() - t0)
    return out


def render_worst_closeups(mesh: ShellMesh, out_png, n: int = 6, metric: str = "scaled_jacobian", *,
                          window_size=(1800, 1100), metrics: dict | None = None) -> Path:
    """One panel per worst element (up to ``n``, at most 3 columns): the element red, its
    neighbourhood (about 4 element sizes around it) in component colours with edges, and a
    caption with its rank, file element id, component and metric values. Returns the path."""
    t0 = time.perf_counter()
    if not isinstance(mesh, ShellMesh):
        mesh = load_any(mesh)
    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    worst = worst_elements(mesh, n, metric, q)
    if not len(worst):
        raise OutputError("the mesh has no elements: no close-ups to draw")
    k = len(worst)
    cols = min(3, k)
    rows = (k + cols - 1) // cols
    check_offscreen()
    pv = _pyvista()
    try:
        pl = pv.Plotter(off_screen=True, window_size=list(window_size), shape=(rows, cols), border=True)
    except Exception as e:
        raise OutputError(f"cannot open an off-screen render window ({type(e).__name__}: {e}); "
                          + OFFSCREEN_HELP) from None
    try:
        pl.set_background(tuple(c / 255 for c in _BACKGROUND))
        rgb, _ = component_colors(mesh.component_names)
        cen = mesh.face_centroids()
        corners = mesh.face_corners()
        nrm = mesh.face_normals()
        eid = element_ids(mesh)
        e = mesh.edges()
        med = float(np.median(np.linalg.norm(mesh.points[e[:, 0]] - mesh.points[e[:, 1]], axis=1))) if len(e) else 1.0
        for r, w in enumerate(worst):
            pl.subplot(r // cols, r % cols)
            size = float(np.linalg.norm(corners[w] - cen[w], axis=1).max())
            rad = 2.5 * max(size, 0.6 * med)
            near = np.flatnonzero(np.linalg.norm(cen - cen[w], axis=1) <= rad)
            n_w = nrm[w] if np.linalg.norm(nrm[w]) > 0 else np.array([0.0, 0.0, 1.0])
            # drop faces that would hide the element: in front of its plane and facing away
            # (the far side of a thin trailing edge)
            front = (cen[near] - cen[w]) @ n_w > 0.05 * size
            near = near[~(front & (nrm[near] @ n_w < -0.2))]
            poly = to_pyvista(mesh, near)
            poly.cell_data["rgb"] = rgb[mesh.component[near]]
            pl.add_mesh(poly, scalars="rgb", rgb=True, show_edges=True, edge_color=(0.15, 0.15, 0.15),
                        line_width=1, **_LIGHT)
            pl.add_mesh(to_pyvista(mesh, [w]), color=(0.9, 0, 0), show_edges=True, edge_color=(0.9, 0, 0),
                        line_width=5)
            pl.add_mesh(pv.PolyData(cen[w][None, :]), color=(0.9, 0, 0), point_size=12,
                        render_points_as_spheres=True)
            name = mesh.component_names[mesh.component[w]] if mesh.component[w] < len(mesh.component_names) else "?"
            pl.add_text(f"#{r + 1}  element {eid[w]}  {name}\nscaled Jacobian {q['scaled_jacobian'][w]:.3g}, "
                        f"angles {q['min_angle'][w]:.0f}-{q['max_angle'][w]:.0f} deg, aspect {q['aspect'][w]:.3g}",
                        position="upper_left", font_size=9, color="black")
            tilt = np.cross(n_w, np.eye(3)[int(np.argmin(np.abs(n_w)))])
            tilt /= np.linalg.norm(tilt)
            d = n_w + 0.4 * tilt
            pts = mesh.points[np.unique(mesh.faces[near][mesh.faces[near] >= 0])]
            _fit_camera(pl, np.vstack([pts, cen[w]]), d, np.cross(tilt, n_w), parallel=True, margin=1.04)
    except BaseException:
        pl.close()
        raise
    out = _save(pl, out_png)
    log.debug("rendered %s (%d close-ups) in %.2f s", out, k, time.perf_counter() - t0)
    return out


def render_views(mesh, out_dir, stem: str, *, up=None, worst: int = 10, closeups: int = 6,
                 window_size=_WINDOW, metrics: dict | None = None) -> list[Path]:
    """The standard pictures of a mesh into ``out_dir``, named ``<stem>_<view>.png``: ``iso``
    and ``top`` (component colours), ``wingbox`` (when the mesh has a wing box), ``quality``
    (scaled Jacobian, iso), ``worst`` (the ``worst`` lowest-scaled-Jacobian elements on the
    model) and ``worst_closeups``. Returns the written paths in that order."""
    if not isinstance(mesh, ShellMesh):
        mesh = load_any(mesh)
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise OutputError(f"cannot create the picture folder {out_dir}: {e.strerror}; choose another folder") from None
    q = element_quality(mesh.points, mesh.faces) if metrics is None else metrics
    paths = [render_mesh(mesh, out_dir / f"{stem}_iso.png", "component", "iso", up=up, window_size=window_size),
             render_mesh(mesh, out_dir / f"{stem}_top.png", "component", "top", up=up, window_size=window_size)]
    _, fam = component_colors(mesh.component_names)
    wing, box, _ = _box_faces(mesh, fam)
    if box is not None and box.any():
        paths.append(render_mesh(mesh, out_dir / f"{stem}_wingbox.png", "component", "wingbox", up=up,
                                 window_size=window_size))
    paths.append(render_mesh(mesh, out_dir / f"{stem}_quality.png", "scaled_jacobian", "iso", up=up,
                             window_size=window_size, metrics=q))
    if worst > 0:
        paths.append(render_worst(mesh, out_dir / f"{stem}_worst.png", worst, up=up, window_size=window_size,
                                  metrics=q))
    if closeups > 0:
        paths.append(render_worst_closeups(mesh, out_dir / f"{stem}_worst_closeups.png", closeups, metrics=q))
    return paths

