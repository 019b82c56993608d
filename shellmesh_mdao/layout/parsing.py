"""Parsing helpers of the layout schema: keys, numbers, vectors, names and station lists read
from a layout mapping with messages naming the offending item (``docs/layout.md``, 'Errors and
fixes')."""
from __future__ import annotations

import difflib
import math

import numpy as np

from ..errors import LayoutError
from ..families import check_plain_name

__all__ = ["MAX_RIBS", "Vec", "check_keys", "number", "vec3", "number_list", "member_name", "unit", "check_eta",
           "check_chord"]

#: Upper bound of ``ribs.count`` (a typo guard: more ribs than this cannot be meshed anyway).
MAX_RIBS = 10000

Vec = tuple  # tuple of 3 floats


def check_keys(d, allowed, required, where):
    """``d`` is a mapping with only ``allowed`` keys (the closest one suggested) and every ``required`` one."""
    if not isinstance(d, dict):
        raise LayoutError(f"{where} must be a mapping (JSON object / YAML mapping) with keys "
                          f"{', '.join(allowed)}; got {type(d).__name__}")
    for k in d:
        if k not in allowed:
            close = difflib.get_close_matches(str(k), allowed, n=1, cutoff=0.5)
            hint = f"did you mean '{close[0]}'?" if close else f"valid keys are: {', '.join(allowed)}"
            raise LayoutError(f"unknown key '{k}' in {where}: {hint}")
    for k in required:
        if k not in d:
            raise LayoutError(f"missing key '{k}' in {where}: add it (required keys: {', '.join(required)})")


def number(x, where) -> float:
    """A finite number (not a bool, not a quoted number)."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        hint = ""
        if isinstance(x, str):
            try:
                float(x)
                hint = " (YAML reads '1e-3' as text: write 1.0e-3, or drop the quotes)"
            except ValueError:
                pass
        raise LayoutError(f"{where} must be a number, got {type(x).__name__} {x!r}{hint}")
    v = float(x)
    if not math.isfinite(v):
        raise LayoutError(f"{where} must be a finite number, got {v}: give a real value")
    return v


def vec3(x, where) -> Vec:
    """A list of 3 numbers."""
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if not isinstance(x, (list, tuple)):
        raise LayoutError(f"{where} must be a list of 3 numbers [x, y, z], got {type(x).__name__} {x!r}")
    if len(x) != 3:
        raise LayoutError(f"{where} must have 3 components [x, y, z], got {len(x)}: {list(x)!r}")
    return tuple(number(v, f"{where}[{i}]") for i, v in enumerate(x))


def number_list(x, where) -> tuple:
    """A list of numbers."""
    if isinstance(x, np.ndarray):
        x = x.tolist()
    if not isinstance(x, (list, tuple)):
        raise LayoutError(f"{where} must be a list of numbers, got {type(x).__name__} {x!r}")
    return tuple(number(v, f"{where}[{i}]") for i, v in enumerate(x))


def member_name(x, where) -> str:
    """A non-empty name without '/' (:func:`~shellmesh_mdao.families.check_plain_name`)."""
    return check_plain_name(x, where)


def unit(v) -> np.ndarray:
    """``v`` normalised."""
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def check_eta(eta, where):
    """Span fractions in [0, 1], strictly increasing."""
    for i, e in enumerate(eta):
        if e < 0.0 or e > 1.0:
            raise LayoutError(f"{where}[{i}] = {e:g} is outside [0, 1]: stations run from 0 (root) to 1 (tip)")
    for i in range(1, len(eta)):
        if eta[i] <= eta[i - 1]:
            what = "repeated" if eta[i] == eta[i - 1] else "out of order"
            raise LayoutError(f"{where}[{i}] = {eta[i]:g} is {what} (after {eta[i - 1]:g}): stations must be "
                              "strictly increasing from root to tip; sort them and remove duplicates")


def check_chord(c, where):
    """Chord fractions in (0, 1), strictly increasing."""
    for i, v in enumerate(c):
        if not (0.0 < v < 1.0):
            raise LayoutError(f"{where}[{i}] = {v:g} is outside (0, 1): a spar lies strictly between the "
                              "leading edge (0) and the trailing edge (1)")
    for i in range(1, len(c)):
        if c[i] <= c[i - 1]:
            raise LayoutError(f"{where}[{i}] = {c[i]:g} is not greater than {where}[{i - 1}] = {c[i - 1]:g}: "
                              "chord fractions must be strictly increasing from the leading edge")


# ----------------------------------------------------------------------------- parsing
