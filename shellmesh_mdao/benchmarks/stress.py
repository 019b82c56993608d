"""The stress sweep: random valid layouts on every corpus geometry, end to end (issue 8, section 1).

``python run_scripts/stress_layouts.py`` runs a sweep (its ``--help`` lists the options) and
writes docs/stress_layouts.md with :func:`write_page`; tests/test_random_layouts.py runs a
fixed-seed subset. Every function that reads the corpus takes its folder ``geometry_dir`` (the
one with ``manifest.json``); the documented messages come from docs/troubleshooting.md of the
source checkout (:data:`TROUBLESHOOTING`).

Case ``i`` of a sweep uses seed ``S + i`` and geometry ``GEOMETRIES[i % 4]`` (or ``--only``);
:func:`draw_case` turns (seed, geometry) into a layout deterministically:

* ribs: 1 to 20 at random distinct stations ``eta`` in [0, 1] (stratified jitter: the k-th of n in
  ``[k/n, (k+1)/n)``; for n >= 2, with probability 1/2 a root rib at 0 and a tip rib at 1 and the
  others jittered in between), rounded to 1e-4;
* spars: 1 to 3 at random distinct chord fractions in (0.05, 0.95), sorted, rounded to 1e-3;
* size: the geometry's benchmark size (:data:`BASE_SIZES`) times a log-uniform factor in
  [0.7, 2.8] (a 4x range).

Every case runs in its own spawned child process with a time limit; :func:`run_case` classifies
it as

* ``ok``: the pipeline ran and :func:`~shellmesh_mdao.guarantees.check_guarantees` holds (100 %
  quads, no element with scaled Jacobian <= 0.2, duplicate-free, no hanging nodes, conforming
  junctions with valence 3/4, closed skin, nodes on their supports);
* ``invalid layout``: a :class:`~shellmesh_mdao.errors.ShellMeshError` whose message is a
  documented message of docs/troubleshooting.md AND that the layout genuinely deserves,
  checked independently of the package (:func:`layout_tightness`): a rib gap or spar gap
  below :data:`~shellmesh_mdao.layout.MIN_MEMBER_GAP` element sizes for the validator's LayoutError
  (members that coincide at that size; closer members are meshed), or, for a refusal by a later stage
  (imprint, members, ...), a layout that is *tight*: members closer than
  :data:`TIGHT` element sizes to each other or a spar that close to the leading/trailing
  edge, or a single rib with spars (the spars, bounded by the first and the last rib, have
  zero length);
* ``FAIL``: anything else -- a guarantee that does not hold, an exception that is not a
  ShellMeshError, an undocumented message, a documented refusal of a layout that is not tight,
  a time-out or a crashed child.

:func:`write_page` writes the results as a table page and its JSON (docs/stress_layouts.md and
docs/stress_layouts.json for the script).
"""
from __future__ import annotations

import json
import math
import re
import time
import traceback
from pathlib import Path

import numpy as np

from ..errors import ShellMeshError
from ..families import rib_name, spar_name
from ..guarantees import check_guarantees
from ..layout import MIN_MEMBER_GAP
from .child import failing_stage, run_in_child
from .corpus import CORPUS_SIZES

__all__ = ["BASE_SIZES", "GEOMETRIES", "HEIGHT_TIGHT", "SIZE_FACTORS", "TIGHT", "TROUBLESHOOTING", "WEDGE_TIGHT",
           "classify_refusal", "documented_patterns", "draw_case", "is_documented", "layout_tightness",
           "load_manifest", "reclassify", "run_case", "run_case_in_child", "sweep_cases", "write_page"]

#: benchmark element size of each corpus geometry (the benchmark's), in name order
BASE_SIZES = {name: CORPUS_SIZES[name] for name in sorted(CORPUS_SIZES)}
GEOMETRIES = tuple(BASE_SIZES)
#: the page of documented error messages, docs/troubleshooting.md of the source checkout this
#: package runs from (the sweep, like the corpus beside it, needs a checkout: ``pip install -e .``)
TROUBLESHOOTING = Path(__file__).resolve().parents[2] / "docs" / "troubleshooting.md"
#: size factor range of the sweep (a 4x range around the benchmark size)
SIZE_FACTORS = (0.7, 2.8)
#: a later-stage refusal is "genuine" only when members come closer than this many element sizes
TIGHT = 2.0
#: ... or when a spar web is less than this many element sizes tall somewhere (the package
#: refuses below 0.03: :data:`shellmesh_mdao.project.MIN_MEMBER_HEIGHT` local sizes of the finest,
#: :data:`shellmesh_mdao.layout.MIN_LOCAL_SIZE` element sizes; a web lower than 0.3 sizes is meshed
#: with smaller elements)
HEIGHT_TIGHT = 0.04
#: ... or when a full-chord rib's section (the input skin cut by its plane) has a corner sharper
#: than asin(0.2) degrees (a quad in it cannot have a scaled Jacobian above 0.2)
WEDGE_TIGHT = math.degrees(math.asin(0.2))
#: drawn ribs and spars are at least ``gap`` element sizes apart, ``gap`` uniform in this range
#: (per case; "free" draws have no minimum spacing)
GAP_RANGE = (1.05, 3.0)
MAX_ATTEMPTS = 50
MAX_RIBS, MAX_SPARS = 20, 3
CHORD_RANGE = (0.05, 0.95)


# ============================================================================ drawing a case
def _spaced(rng, n: int, lo: float, hi: float, gap: float) -> np.ndarray:
    """``n`` sorted points in [lo, hi] at least ``gap`` apart, uniform over such sets (``n``
    uniform draws in the shortened interval, sorted, the k-th shifted by ``k * gap``)."""
    if n <= 0:
        return np.zeros(0)
    free = max(hi - lo - (n - 1) * gap, 0.0)
    return lo + np.sort(rng.uniform(0.0, free, n)) + gap * np.arange(n)


def _wing_rates(manifest: dict, geometry: str):
    """Per wing: chord lengths (root, tip) and the function cm -> rib-plane offset per unit eta."""
    g = manifest["geometries"][geometry]
    out = []
    for w in g["wings"]:
        rle, rte, tle, tte = (np.asarray(w[k], dtype=np.float64) for k in ("root_le", "root_te", "tip_le", "tip_te"))
        up = _unit(w.get("up", g.get("up")))
        s = 0.5 * (tle + tte) - 0.5 * (rle + rte)
        n = _unit(s - (s @ up) * up)
        rate = (lambda cm, rle=rle, rte=rte, tle=tle, tte=tte, n=n:
                float((((1 - cm) * tle + cm * tte) - ((1 - cm) * rle + cm * rte)) @ n))
        out.append((np.linalg.norm(rte - rle), np.linalg.norm(tte - tle), rate))
    return out


def load_manifest(geometry_dir) -> dict:
    """The corpus manifest, ``manifest.json`` of the folder ``geometry_dir``."""
    return json.loads((Path(geometry_dir) / "manifest.json").read_text())


def draw_case(seed: int, geometry: str | None = None, size_factors=SIZE_FACTORS, manifest: dict | None = None, *,
              geometry_dir) -> dict:
    """A random layout, deterministic per ``(seed, geometry, size_factors)``:
    ``{"seed", "geometry", "ribs" (sorted distinct etas in [0, 1], 1-20), "spars" (sorted
    distinct chord fractions in (0.05, 0.95), 1-3), "size", "size_factor", "spacing"}``.

    With ``geometry`` None it is drawn too (uniformly from :data:`GEOMETRIES`). The draw aims
    at valid layouts: ribs are drawn at least ``min_gap`` element sizes apart (rib-plane offset;
    ``min_gap`` uniform in :data:`GAP_RANGE` per case) and spars at least that far apart along
    the shorter of the root and tip chords (``spacing`` "spaced"; fewer ribs/spars when that many
    do not fit); one draw in eight ignores the spacing (``spacing`` "free", ``min_gap`` 0: it
    may be genuinely invalid, to exercise the refusals). A spaced draw whose members leave the
    wing (``outside`` of :func:`layout_tightness`: the manifest's straight leading/trailing
    edge lines are the wing box, and on the bwb the trailing-edge line runs outside the kinked
    planform) is drawn again from the same stream, up to :data:`MAX_ATTEMPTS` times
    (``attempts``; the last draw is kept even if outside). ``geometry_dir``: the corpus folder
    (``manifest`` defaults to its manifest)."""
    manifest = manifest or load_manifest(geometry_dir)
    rng = np.random.default_rng(seed)
    g = GEOMETRIES[int(rng.integers(len(GEOMETRIES)))]      # always drawn: same stream either way
    geometry = g if geometry is None else geometry
    if geometry not in BASE_SIZES:
        raise ValueError(f"unknown geometry {geometry!r}; one of {GEOMETRIES}")
    lo, hi = size_factors
    f = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    size = float(f"{BASE_SIZES[geometry] * f:.4g}")
    free = rng.random() < 0.125
    wings = _wing_rates(manifest, geometry)
    for attempt in range(1, MAX_ATTEMPTS + 1):
        n = int(rng.integers(1, MAX_RIBS + 1))
        ns = int(rng.integers(1, MAX_SPARS + 1))
        ends = n >= 2 and rng.random() < 0.5
        gap = 0.0 if free else float(rng.uniform(*GAP_RANGE))
        # spars
        cmin, cmax = CHORD_RANGE[0] + 1e-3, CHORD_RANGE[1] - 1e-3
        gc = gap * size / min(min(r, t) for r, t, _ in wings)
        ns = max(1, min(ns, int((cmax - cmin) / gc) + 1 if gc > 0 else ns))
        c = np.unique(np.round(_spaced(rng, ns, cmin, cmax, gc), 3))
        # ribs
        cm = 0.5 * (c[0] + c[-1]) if len(c) >= 2 else 0.5
        ge = gap * size / min(rate(cm) for _, _, rate in wings)
        if ends:
            n = max(2, min(n, int(1.0 / ge) + 1 if ge > 0 else n))
            eta = np.concatenate([[0.0], _spaced(rng, n - 2, ge, 1.0 - ge, ge), [1.0]])
        else:
            n = max(1, min(n, int(1.0 / ge) + 1 if ge > 0 else n))
            eta = _spaced(rng, n, 0.0, 1.0, ge)
        eta = np.unique(np.clip(np.round(eta, 4), 0.0, 1.0))
        case = {"seed": int(seed), "geometry": geometry, "ribs": [float(e) for e in eta],
                "spars": [float(v) for v in c], "size": size, "size_factor": round(f, 4),
                "spacing": "free" if free else "spaced", "min_gap": round(gap, 3), "attempts": attempt}
        if free or not layout_tightness(manifest, case, geometry_dir)["outside"]:
            break
    return case



def sweep_cases(n: int, seed: int = 0, only: str | None = None, size_factors=SIZE_FACTORS,
                manifest: dict | None = None, *, geometry_dir) -> list:
    """The ``n`` cases of a sweep on the corpus in ``geometry_dir``: case ``i`` is
    ``draw_case(seed + i, GEOMETRIES[i % 4])`` (or ``only``)."""
    manifest = manifest or load_manifest(geometry_dir)
    return [draw_case(seed + i, only or GEOMETRIES[i % len(GEOMETRIES)], size_factors, manifest,
                      geometry_dir=geometry_dir) for i in range(n)]


# ============================================================================ independent checks
def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


_SURF: dict = {}


def _surface(geometry_dir, file):
    key = str(Path(geometry_dir) / file)
    if key not in _SURF:
        import trimesh
        _SURF[key] = trimesh.load(key, force="mesh")
    return _SURF[key]


def _surface_vertices(geometry_dir, file) -> np.ndarray:
    return np.asarray(_surface(geometry_dir, file).vertices, dtype=np.float64)


def _outside(geometry_dir, file, pts: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Per point: True when a ray along +up or along -up from it misses the skin (the point
    is not inside the wing; what the projection stage needs)."""
    ray = _surface(geometry_dir, file).ray
    o = np.vstack([pts, pts])
    d = np.vstack([np.tile(up, (len(pts), 1)), np.tile(-up, (len(pts), 1))])
    hit = ray.intersects_any(o, d)
    return ~(hit[:len(pts)] & hit[len(pts):])


def _first_hit(geometry_dir, file, pts: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Per point: distance along the unit direction ``d`` to the first skin hit (inf: none)."""
    loc, idx, _ = _surface(geometry_dir, file).ray.intersects_location(
        pts, np.tile(d, (len(pts), 1)), multiple_hits=True)
    out = np.full(len(pts), np.inf)
    if len(idx):
        t = np.einsum("ij,j->i", loc - pts[idx], d)
        ok = t > 1e-9
        np.minimum.at(out, idx[ok], t[ok])
    return out


def _section_corner(geometry_dir, file, origin: np.ndarray, normal: np.ndarray) -> float:
    """Smallest corner angle (degrees) of the closed section of the skin by the plane through
    ``origin`` (a point inside the wing) with ``normal``: of the section's loops, the smallest
    one whose bounding box holds ``origin`` (the wing's airfoil, not a fuselage around it)."""
    sec = _surface(geometry_dir, file).section(plane_origin=origin, plane_normal=normal)
    if sec is None:
        return math.inf
    best, area = math.inf, math.inf
    for loop in sec.discrete:
        L = np.asarray(loop, dtype=np.float64)
        if len(L) < 4 or not np.allclose(L[0], L[-1]):
            continue
        lo, hi = L.min(axis=0), L.max(axis=0)
        if not ((lo - 1e-9 <= origin) & (origin <= hi + 1e-9)).all():
            continue
        L = L[:-1]
        u, v = np.roll(L, 1, axis=0) - L, np.roll(L, -1, axis=0) - L
        lu, lv = np.linalg.norm(u, axis=1), np.linalg.norm(v, axis=1)
        ok = (lu > 0) & (lv > 0)
        ang = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", u[ok], v[ok]) / (lu[ok] * lv[ok]), -1, 1)))
        a = float(np.prod(np.sort(hi - lo)[1:]))
        if len(ang) and a < area:
            best, area = float(ang.min()), a
    return best


def layout_tightness(manifest: dict, case: dict, geometry_dir) -> dict:
    """How close the members of ``case`` come to each other and to the ends of the wing,
    computed from the manifest's wing corners and the surface file (trimesh ray casts), not
    with the package. Geometry as in docs/layout.md: the reference surface ``S(eta, c)``, rib
    planes through ``S(eta_k, c_mid)`` with the normal ``n`` (span projected normal to ``up``),
    ribs spanning the chord range of the first and last spars (or 0..1), spars running between
    the first and the last rib plane. Per wing:

    * ``rib_gap``: smallest distance between consecutive rib planes;
    * ``spar_gap``: smallest distance between consecutive spars along the root and tip chords;
    * ``edge_gap``: the first/last spar to the leading/trailing edge along the chords of the first
      and the last rib (root and tip without ribs), where the spars run;
    * ``end_gap``: the outermost ribs to the end of the skin (first skin hit of rays along -n
      from the first rib's curve and along +n from the last rib's curve, 21 points each);
    * ``spar_height``: the smallest spar web height (distance between the first skin hits along
      +up and -up from its 41 points between the rib planes);
    * ``wedge``: with fewer than two spars (full-chord ribs), the sharpest corner (degrees) of
      the rib planes' sections of the skin;
    * ``outside``: members whose curve (41 points, spars along their true extent between the
      rib planes) has a point from which a ray along +up or -up misses the skin -- the member
      leaves the wing (what the projection stage refuses);
    * ``zero_length_spars``: one rib and spars (the spars run from that rib plane to itself).

    Gaps are in element sizes (inf when undefined). ``tight`` is "" or the reasons the layout
    is tight: outside members, zero-length spars, a gap below :data:`TIGHT`, a spar web lower
    than :data:`HEIGHT_TIGHT` or a full-chord rib section corner below :data:`WEDGE_TIGHT`."""
    g = manifest["geometries"][case["geometry"]]
    h = case["size"]
    f = g["file"]
    end_gap = math.inf
    outside = []
    eta = np.asarray(case["ribs"], dtype=np.float64)
    c = np.asarray(case["spars"], dtype=np.float64)
    rib_gap = spar_gap = edge_gap = spar_height = wedge = math.inf
    tt = np.linspace(0.0, 1.0, 41)
    for w in g["wings"]:
        rle, rte, tle, tte = (np.asarray(w[k], dtype=np.float64) for k in ("root_le", "root_te", "tip_le", "tip_te"))
        up = _unit(w.get("up", g.get("up")))
        s = 0.5 * (tle + tte) - 0.5 * (rle + rte)
        n = _unit(s - (s @ up) * up)
        cm = 0.5 * (c[0] + c[-1]) if len(c) >= 2 else 0.5

        def S(e, cc):
            e, cc = np.broadcast_arrays(np.asarray(e, dtype=np.float64), np.asarray(cc, dtype=np.float64))
            e, cc = e[..., None], cc[..., None]
            return (1 - cc) * ((1 - e) * rle + e * tle) + cc * ((1 - e) * rte + e * tte)

        def eta_on(cc, p):
            """eta where the line S(., cc) crosses the plane through p with normal n."""
            a = S(0.0, cc)
            return ((p - a) @ n) / ((S(1.0, cc) - a) @ n)

        ca, cb = (c[0], c[-1]) if len(c) >= 2 else (0.02, 0.98)
        cr = ca + (cb - ca) * tt
        planes = [S(e, cm) for e in eta]
        if len(eta) >= 2:
            rib_gap = min(rib_gap, float(np.diff([p @ n for p in planes]).min()) / h)
        rib_curves = [S(eta_on(cr, p), cr) for p in planes]
        if len(c) < 2:                          # full-chord ribs: the sharpest corner of their sections
            for p in planes:
                wedge = min(wedge, _section_corner(geometry_dir, f, p, n))
        for k, pts in enumerate(rib_curves):
            if _outside(geometry_dir, f, pts, up).any():
                outside.append(rib_name(w["name"], k))
        if len(eta):
            ends = [_first_hit(geometry_dir, f, rib_curves[0][::2], -n).min(),
                    _first_hit(geometry_dir, f, rib_curves[-1][::2], n).min()]
            end_gap = min(end_gap, min(ends) / h)
        for j, cj in enumerate(c):
            e0, e1 = (eta_on(cj, planes[0]), eta_on(cj, planes[-1])) if len(eta) else (0.0, 1.0)
            pts = S(e0 + (e1 - e0) * tt, cj)
            if _outside(geometry_dir, f, pts, up).any():
                outside.append(spar_name(w["name"], j))
            else:
                web = _first_hit(geometry_dir, f, pts, up) + _first_hit(geometry_dir, f, pts, -up)
                spar_height = min(spar_height, float(web.min()) / h)
        chords = (np.linalg.norm(rte - rle), np.linalg.norm(tte - tle))
        if len(c) >= 2:
            spar_gap = min(spar_gap, min(float(np.diff(c).min()) * L for L in chords) / h)
        if len(c):
            # along the chords where the spars run: at the first and the last rib (root and tip without ribs)
            ends = (float(eta.min()), float(eta.max())) if len(eta) else (0.0, 1.0)
            run = [float(np.linalg.norm(S(e, 1.0) - S(e, 0.0))) for e in ends]
            edge_gap = min(edge_gap, min(min(float(c[0]), 1 - float(c[-1])) * L for L in run) / h)
    zero = len(eta) == 1 and len(c) > 0
    reasons = []
    if outside:
        reasons.append(f"members outside the wing (a ray along +-up from their chord-plane curve misses the skin): "
                       f"{', '.join(outside[:6])}{' ...' if len(outside) > 6 else ''}")
    if zero:
        reasons.append(f"a single rib with {len(c)} spar(s): the spars, bounded by the first and the last rib, "
                       "have zero length")
    for what, v in (("rib gap", rib_gap), ("spar gap", spar_gap), ("spar to leading/trailing edge", edge_gap),
                    ("outermost rib to the end of the skin", end_gap)):
        if v < TIGHT:
            reasons.append(f"{what} {v:.2f} element sizes (< {TIGHT:g})")
    if spar_height < HEIGHT_TIGHT:
        reasons.append(f"a spar web {spar_height:.2f} element sizes tall (< {HEIGHT_TIGHT:g})")
    if wedge < WEDGE_TIGHT:
        reasons.append(f"a full-chord rib section with a {wedge:.1f} deg corner (< {WEDGE_TIGHT:.1f}: no quad in it "
                       "has a scaled Jacobian above 0.2)")
    return {"rib_gap": rib_gap, "spar_gap": spar_gap, "edge_gap": edge_gap, "end_gap": end_gap,
            "spar_height": spar_height, "wedge": wedge,
            "zero_length_spars": zero, "outside": outside, "tight": "; ".join(reasons)}


_DOC_PATTERNS: list | None = None


def documented_patterns(path: Path | None = None) -> list:
    """Regular expressions of every message quoted in docs/troubleshooting.md (``path``, default
    :data:`TROUBLESHOOTING`; each backtick-quoted text with a space in it; ``{placeholder}``
    matches anything)."""
    global _DOC_PATTERNS
    if path is None and _DOC_PATTERNS is not None:
        return _DOC_PATTERNS
    page = Path(path or TROUBLESHOOTING)
    if not page.is_file():
        raise FileNotFoundError(f"{page} not found: the stress sweep classifies refusals by the messages of "
                                "docs/troubleshooting.md, so it runs from a source checkout (pip install -e .)")
    text = page.read_text()
    pats = []
    for q in re.findall(r"`([^`]+)`", text):
        q = " ".join(q.split())
        if " " not in q or len(q) < 12:
            continue
        parts = re.split(r"\{[^{}]*\}", q)
        pats.append(re.compile("(.+?)".join(re.escape(p) for p in parts), re.S))
    if path is None:
        _DOC_PATTERNS = pats
    return pats


def is_documented(message: str) -> bool:
    """True when ``message`` (whitespace normalised) matches a message of docs/troubleshooting.md."""
    m = " ".join(str(message).split())
    return any(p.fullmatch(m) for p in documented_patterns())


def classify_refusal(cls: str, message: str, stage: str, t: dict) -> tuple:
    """``(outcome, reason)`` of a run that raised the ShellMeshError ``cls`` (class name) with
    ``message`` at ``stage``, given the layout's :func:`layout_tightness` ``t`` (gaps may be
    None for inf). "invalid layout" only when the message is documented and the layout
    genuinely deserves it:

    * the validator (stage "layout", LayoutError/SizeError): members that coincide at this size
      (ribs, spars or both named), confirmed by the independent rib (spar) gap below
      :data:`~shellmesh_mdao.layout.MIN_MEMBER_GAP` element sizes for every kind it names (members
      from there up to one element size apart are meshed, not refused);
    * ProjectionError: a member outside the wing (``outside``) or zero-length spars;
    * any other documented error of a later stage (imprint, members, ...): a tight layout
      (:data:`TIGHT`); a refusal that names its own cause needs that cause's independent
      figure: a spar web refusal ``spar_height`` < :data:`HEIGHT_TIGHT`, a sharp-edge refusal
      of a full-chord rib ``wedge`` < :data:`WEDGE_TIGHT`.

    Otherwise "FAIL"."""
    g = {k: (math.inf if t.get(k) is None else t[k]) for k in ("rib_gap", "spar_gap")}
    if not is_documented(message):
        return "FAIL", "undocumented error message (not in docs/troubleshooting.md)"
    if stage == "layout" and cls in ("LayoutError", "SizeError"):
        kinds = [k for k in ("rib", "spar") if f"{k}s '" in message]
        if message.startswith("members coincide or cross at element size") and kinds:
            ok = all(g[f"{k}_gap"] < MIN_MEMBER_GAP for k in kinds)
            why = "members that coincide at this size (" + ", ".join(
                f"smallest {k} gap {g[f'{k}_gap']:.3f} h" for k in kinds) + f"; below {MIN_MEMBER_GAP:g} h)"
        else:
            ok, why = False, "the validator refused a layout drawn valid"
        if ok:
            return "invalid layout", why
        return "FAIL", f"{why}: the independent check disagrees (rib gap {g['rib_gap']:.2f} h, " \
                       f"spar gap {g['spar_gap']:.2f} h)"
    if cls == "ProjectionError":
        if t.get("outside") or t.get("zero_length_spars"):
            return "invalid layout", f"documented refusal of a layout with members outside the wing: {t['tight']}"
        return "FAIL", "ProjectionError for a layout whose members all lie inside the wing (rays along +-up " \
                       "from 41 points of every member curve hit the skin; full-chord ribs sampled for c in [0.02, 0.98])"
    # refusals that name their own cause must be backed by the independent figure of that cause
    evidence = (("is only", "tall near", "spar_height", HEIGHT_TIGHT, "a spar web"),
                ("a sharp edge of the skin", "full-chord", "wedge", WEDGE_TIGHT, "a full-chord rib section corner"))
    for a, b, key, bound, what in evidence:
        if a in message and b in message:
            v = math.inf if t.get(key) is None else t[key]
            if v < bound:
                return "invalid layout", f"documented refusal of a tight layout: {t['tight']}"
            return "FAIL", f"{what} refusal, but the independent check finds {key} = {v:.3g} (>= {bound:.3g})"
    if t.get("tight"):
        return "invalid layout", f"documented refusal of a tight layout: {t['tight']}"
    return "FAIL", f"documented refusal of a layout that is not tight (all gaps >= {TIGHT:g} element sizes, " \
                   "no member outside the wing)"


def reclassify(r: dict) -> dict:
    """Classify a stored result again with the current :func:`classify_refusal` (refusals only)."""
    err = str(r.get("error") or "")
    if r.get("outcome") == "ok" or r.get("stage") in ("guarantees", "") or ": " not in err:
        return r
    cls, msg = err.split(": ", 1)
    if not cls.endswith("Error") or cls in ("AssertionError",) or "traceback" in r or \
            r.get("reason", "").startswith(("runner crashed", "time-out", "child process")):
        return r
    r = dict(r)
    r["outcome"], r["reason"] = classify_refusal(cls, msg, r["stage"], r)
    return r


# ============================================================================ one case


def run_case(case: dict, geometry_dir, manifest: dict | None = None) -> dict:
    """Run one case on the corpus in ``geometry_dir`` end to end and classify it; never raises.
    Returns the case with ``outcome`` ("ok" | "invalid layout" | "FAIL"), ``reason``, ``error``
    (class: message), ``stage`` ("guarantees" when :func:`check_guarantees` raised), ``seconds``,
    ``min_sj``, ``n_elements``, ``n_poor`` and the tightness figures."""
    from .. import pipeline as pl
    from ..layout import layout_from_manifest
    from ..quality import element_quality

    if manifest is None:
        manifest = load_manifest(geometry_dir)
    out = dict(case)
    t = layout_tightness(manifest, case, geometry_dir)
    out.update({k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in t.items()})
    out.update(outcome="FAIL", reason="", error="", stage="", min_sj=None, n_elements=None, n_poor=None)
    path = Path(geometry_dir) / manifest["geometries"][case["geometry"]]["file"]
    t0 = time.perf_counter()
    try:
        out["stage"] = "layout"
        lay = layout_from_manifest(manifest, case["geometry"], ribs=list(case["ribs"]), spars=list(case["spars"]))
        lay.validate(case["size"])            # the layout stage's own check, run first to know the stage
        out["stage"] = "pipeline"
        res = pl.run_pipeline(path, lay, case["size"], progress=False, check=False)   # classified below
        q = res.mesh
        out["n_elements"] = int(q.n_faces)
        if q.n_faces:
            sj = element_quality(q.points, q.faces)["scaled_jacobian"]
            out["min_sj"] = float(sj.min())
            out["n_poor"] = int((sj <= 0.2).sum())
        out["stage"] = "guarantees"
        check_guarantees(res)
        out["outcome"], out["stage"] = "ok", ""
    except ShellMeshError as e:
        out["error"] = f"{type(e).__name__}: {e}"
        if out["stage"] == "guarantees":          # the mesh misses a guarantee: a FAIL
            out["reason"] = "a guarantee does not hold"
        else:
            if out["stage"] == "pipeline":
                out["stage"] = failing_stage(e.__traceback__, "pipeline")
            out["outcome"], out["reason"] = classify_refusal(type(e).__name__, str(e), out["stage"], t)
    except Exception as e:  # noqa: BLE001 -- any other exception is a FAIL, recorded with its traceback
        out["error"] = f"{type(e).__name__}: {e}"
        out["reason"] = "unexpected exception (not a ShellMeshError)"
        out["traceback"] = traceback.format_exc()[-3000:]
    out["seconds"] = round(time.perf_counter() - t0, 2)
    return out


# ============================================================================ child processes
def _run_case_guarded(case, geometry_dir):
    """:func:`run_case` that reports a crash of the runner itself as a FAIL row (never raises)."""
    try:
        return run_case(case, Path(geometry_dir))
    except BaseException as e:  # noqa: BLE001
        return dict(case, outcome="FAIL", reason="runner crashed", error=f"{type(e).__name__}: {e}")


def run_case_in_child(case: dict, timeout: float = 600.0, *, geometry_dir) -> dict:
    """:func:`run_case` in a fresh spawned process with a time limit
    (:func:`~shellmesh_mdao.benchmarks.child.run_in_child`); a time-out or a crash of the child is
    a FAIL."""
    out = run_in_child(_run_case_guarded, case, str(geometry_dir), timeout=timeout)
    status, elapsed, exit_code = out.pop("status"), out.pop("process_wall_s"), out.pop("exit_code", None)
    for k in ("peak_rss_mb", "child_cpu_s"):
        out.pop(k, None)
    if status in ("timeout", "crashed"):
        what = f"time-out: no result after {timeout:g} s (killed)" if status == "timeout" else \
            f"child process died (exit code {exit_code})"
        out = dict(case, outcome="FAIL", reason=what, error=what, seconds=round(elapsed, 2))
    out["process_seconds"] = round(elapsed, 2)
    return out


# ============================================================================ page
def _fmt(v, f="{:.3f}"):
    return "-" if v is None else f.format(v)


def write_page(results: list, meta: dict, md_path: Path) -> None:
    """Write the table page ``md_path`` and the JSON beside it (same stem)."""
    md_path = Path(md_path)
    md_path.with_suffix(".json").write_text(json.dumps({"meta": meta, "cases": results}, indent=1))
    n = len(results)
    cnt = {k: sum(r["outcome"] == k for r in results) for k in ("ok", "invalid layout", "FAIL")}
    valid = cnt["ok"] + cnt["FAIL"]
    secs = [r.get("seconds") or 0.0 for r in results]
    L = ["# Random layouts on the corpus: stress sweep", "",
         "Generated by `python run_scripts/stress_layouts.py " + meta.get("argv", "") + "` on " + meta["date"] +
         f" ({meta['machine']}). Each case runs the whole pipeline (load -> quad) in its own child process "
         f"with a {meta['timeout']:g} s limit. How cases are drawn and classified: the docstring of "
         "`shellmesh_mdao/benchmarks/stress.py` (ribs 1-20 at random stations, spars 1-3 at random chord fractions "
         f"in (0.05, 0.95), size = benchmark size x a log-uniform factor in [{meta['size_factors'][0]:g}, "
         f"{meta['size_factors'][1]:g}]). The fixed-seed CI subset is tests/test_random_layouts.py.", "",
         "## Result", "",
         f"**{cnt['ok']} of {n} cases ok, {cnt['invalid layout']} refused as invalid layouts (documented error, "
         f"genuinely invalid), {cnt['FAIL']} FAIL.** Of the {valid} cases that were not invalid, {cnt['ok']} "
         f"({100.0 * cnt['ok'] / max(valid, 1):.0f} %) met every guarantee. Total {sum(secs):.0f} s of case time "
         f"(median {float(np.median(secs)) if secs else 0:.1f} s, max {max(secs, default=0):.1f} s).", "",
         "ok = all quads, no element with scaled Jacobian <= 0.2, no duplicate points, no hanging nodes, "
         "conforming junctions (`shellmesh_mdao.guarantees.check_guarantees`). Gaps are in element sizes h "
         "(independent of the package: rib-plane offsets, spar chord distances at root/tip, spar to LE/TE, "
         f"outermost rib to the skin's end along the rib normal, smallest spar web height); a layout is *tight* "
         f"when a gap is below {TIGHT:g} h, a spar web below {HEIGHT_TIGHT:g} h or a full-chord rib's section has a "
         f"corner below {WEDGE_TIGHT:.1f} degrees.",
         "",
         "| seed | geometry | ribs (eta) | spars (c) | size (x base) | outcome | seconds | min SJ | elements | "
         "gaps: rib / spar / spar-edge / rib-end / spar height (h) |",
         "| ---: | --- | --- | --- | --- | --- | ---: | ---: | ---: | --- |"]
    for r in results:
        ribs = r["ribs"]
        rs = ", ".join(f"{e:g}" for e in ribs) if len(ribs) <= 6 else \
            f"{len(ribs)}: {ribs[0]:g}, {ribs[1]:g} ... {ribs[-1]:g}"
        if len(ribs) <= 6:
            rs = f"{len(ribs)}: {rs}"
        gaps = " / ".join(_fmt(r.get(k), "{:.2f}") for k in ("rib_gap", "spar_gap", "edge_gap", "end_gap", "spar_height"))
        oc = r["outcome"] if r["outcome"] != "FAIL" else "**FAIL**"
        L.append(f"| {r['seed']} | {r['geometry']} | {rs} | {', '.join(f'{c:g}' for c in r['spars'])} | "
                 f"{r['size']:g} ({r['size_factor']:.2f}) | {oc} | {_fmt(r.get('seconds'), '{:.1f}')} | "
                 f"{_fmt(r.get('min_sj'))} | {_fmt(r.get('n_elements'), '{:d}')} | {gaps} |")
    if meta.get("notes"):
        L += ["", "## Findings", ""] + list(meta["notes"])
    bad = [r for r in results if r["outcome"] != "ok"]
    if bad:
        L += ["", "## Refusals and failures", ""]
        for r in bad:
            lay = f"ribs {r['ribs']}, spars {r['spars']}"
            tight = f"layout tight: {r['tight']}" if r.get("tight") else "layout not tight (every gap >= " \
                f"{TIGHT:g} h, no member outside the wing)"
            L.append(f"- seed {r['seed']} ({r['geometry']}, {lay}, size {r['size']:g}) **{r['outcome']}** at "
                     f"stage `{r.get('stage') or '-'}`: {r['reason']}. Error: "
                     f"`{' '.join(str(r['error']).split())[:400]}`" + (f". {tight}." if r["outcome"] == "FAIL" else ""))
    md_path.write_text("\n".join(L) + "\n")
