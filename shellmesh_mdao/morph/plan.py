"""The morph's plan geometry: a wing's plan coordinates ``(r, c)`` (rib coordinate and chord fraction
of its reference surface), the knots of the moves and their fades. Every function takes complex
values where the layout parameters enter (the complex step of the derivatives)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WingFrame", "dot", "chord_line", "plan_point", "plan_coordinates", "hat_interp", "chord_knots", "fade",
           "rib_knots_and_planes", "span_fade", "CHORD_FADE", "HEIGHT_FADE", "END_STILL"]

#: the move fades out over this many local chords beyond the leading and the trailing edge
CHORD_FADE = 0.25
#: ... and between ``HEIGHT_FADE`` and twice that (local chords) above or below the reference surface
HEIGHT_FADE = 0.25
#: the share of the way from an end rib to the wing's end (root, tip) next to the end that does not move
END_STILL = 0.25


@dataclass
class WingFrame:
    """Plan frame of one corner-given wing and its reference knots."""

    name: str
    corners: np.ndarray          # (4, 3) root_le, root_te, tip_le, tip_te
    up: np.ndarray
    n_rib: np.ndarray
    e2: np.ndarray               # up x n_rib: the chordwise axis of the plan
    rib_eta: np.ndarray          # reference values
    spar_chord: np.ndarray
    r_knots: np.ndarray          # reference rib coordinates with the fade ends: (K + 2,)
    c_knots: np.ndarray          # 0, spar fractions, 1




def dot(a, b):
    return (a * b).sum(-1)


def chord_line(W, c):
    """S(0, c) and S(1, c) - S(0, c) for chord fractions c (k,) -> (k, 3) each."""
    rl, rt, tl, tt = W.corners
    c = np.asarray(c)[..., None]
    s0 = rl + c * (rt - rl)
    s1 = tl + c * (tt - tl)
    return s0, s1 - s0


def plan_point(W, r, c):
    """The reference-surface point of plan coordinates (r, c): ``S(eta, c)`` with ``n_rib . S = r``."""
    s0, ds = chord_line(W, c)
    eta = (r - dot(s0, W.n_rib)) / dot(ds, W.n_rib)
    return s0 + eta[..., None] * ds, eta


def plan_coordinates(W, x):
    """(r, c, eta) of points x (k, 3): r = n_rib . x, c solved by Newton (x - S(eta, c) along up)."""
    r = x @ W.n_rib
    target = x @ W.e2
    c = np.full(len(x), 0.5)
    for _ in range(60):
        p, _ = plan_point(W, r, c)
        g = p @ W.e2 - target
        h = 1e-7
        p2, _ = plan_point(W, r, c + h)
        dg = (p2 @ W.e2 - target - g) / h
        step = g / np.where(np.abs(dg) > 1e-300, dg, 1e-300)
        c = c - np.clip(step, -1.0, 1.0)
        if np.abs(step).max(initial=0.0) < 1e-15:
            break
    _, eta = plan_point(W, r, c)
    return r, c, eta


def hat_interp(xk, x, dk):
    """Piecewise-linear interpolation of the knot values ``dk`` (complex allowed) at ``x`` (real),
    knots ``xk`` (real, increasing); zero outside [xk[0], xk[-1]]."""
    i = np.clip(np.searchsorted(xk, x, side="right") - 1, 0, len(xk) - 2)
    t = (x - xk[i]) / (xk[i + 1] - xk[i])
    inside = (x >= xk[0]) & (x <= xk[-1])
    out = (1 - t) * dk[i] + t * dk[i + 1]
    return np.where(inside, out, 0.0 * dk[0])


def chord_knots(spar_chord):
    """Knots of the chordwise move: the leading edge, halfway to the first spar, the spars, halfway
    from the last spar to the trailing edge, the trailing edge; the move is zero at the first two
    and the last two, so the nose and the trailing edge keep their nodes when a spar moves (at
    the nose a chordwise move in plan is a move across the surface, not along it)."""
    c = np.asarray(spar_chord, np.float64)
    if not len(c):
        return np.array([0.0, 1.0])
    return np.concatenate([[0.0, 0.5 * c[0]], c, [0.5 * (c[-1] + 1.0), 1.0]])


def fade(x, lo, hi, width_lo, width_hi):
    """1 on [lo, hi], linear to 0 at lo - width_lo and hi + width_hi (real)."""
    a = np.clip((x - (lo - width_lo)) / max(width_lo, 1e-300), 0.0, 1.0) if width_lo > 0 else (x >= lo) * 1.0
    b = np.clip(((hi + width_hi) - x) / max(width_hi, 1e-300), 0.0, 1.0) if width_hi > 0 else (x <= hi) * 1.0
    return np.minimum(a, b)


def rib_knots_and_planes(W, rib_eta, spar_chord):
    """Rib coordinates r_k (complex allowed) of a wing's ribs at ``rib_eta`` with spars ``spar_chord``
    (each rib passes through ``S(eta_k, c_mid)``, ``c_mid`` the middle of its chord range) and the
    member planes: ``{("rib", k): (point, normal), ("spar", j): (point, normal)}``."""
    c = np.asarray(spar_chord)
    cmid = 0.5 * (c[0] + c[-1]) if len(c) >= 2 else 0.5 + 0.0 * np.sum(c)
    rl, rt, tl, tt = W.corners
    eta = np.asarray(rib_eta)
    pts = ((1 - eta)[:, None] * ((1 - cmid) * rl + cmid * rt) + eta[:, None] * ((1 - cmid) * tl + cmid * tt))
    rk = pts @ W.n_rib
    planes = {}
    for k in range(len(eta)):
        planes[("rib", k)] = (pts[k], W.n_rib + 0.0 * pts[k])
    aft_dir = 0.5 * (rt + tt) - 0.5 * (rl + tl)
    for j in range(len(c)):
        r0 = rl + c[j] * (rt - rl)
        t0 = tl + c[j] * (tt - tl)
        nrm = np.cross(t0 - r0, W.up)
        nrm = nrm / np.sqrt(dot(nrm, nrm))
        if (nrm.real @ aft_dir) < 0:
            nrm = -nrm
        planes[("spar", j)] = (r0, nrm)
    return rk, planes


def span_fade(W, rk, r, c, eta, near):
    """1 between the end ribs, linear to 0 at the wing's ends beyond them: its root or tip (the
    lowest or highest station of the nodes ``near`` it) or one rib pitch beyond, whichever is
    nearer, along the chord line of each node (``r``, ``c``, ``eta`` its plan coordinates)."""
    if not len(rk):
        return np.zeros(len(r))
    s0, ds = chord_line(W, c)
    den = ds @ W.n_rib
    e_first = (rk[0] - s0 @ W.n_rib) / den
    e_last = (rk[-1] - s0 @ W.n_rib) / den
    pitch_lo = (rk[1] - rk[0]) / den if len(rk) > 1 else 0.0 * den
    pitch_hi = (rk[-1] - rk[-2]) / den if len(rk) > 1 else 0.0 * den
    e_min = eta[near].min() if near.any() else -np.inf
    e_max = eta[near].max() if near.any() else np.inf
    # the last quarter of the way to the wing's end stays: its end cap and outline do not move
    lo_end = np.maximum(e_first - pitch_lo, e_min + END_STILL * (e_first - e_min))
    hi_end = np.minimum(e_last + pitch_hi, e_max - END_STILL * (e_max - e_last))
    a = np.where(eta >= e_first, 1.0, np.clip((eta - lo_end) / np.maximum(e_first - lo_end, 1e-300), 0.0, 1.0))
    b = np.where(eta <= e_last, 1.0, np.clip((hi_end - eta) / np.maximum(hi_end - e_last, 1e-300), 0.0, 1.0))
    return np.minimum(a, b)
