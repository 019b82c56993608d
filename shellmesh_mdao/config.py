"""Study configuration files for ``shellmesh mesh --config study.yaml``.

A config file (YAML, or JSON when it ends in ``.json``) names everything one meshing run
needs, so a study can be repeated with one command and kept under version control::

    surface: ../geometry/cessna210.stl     # relative paths: against this file's folder
    layout: cessna_layout.yaml              # a path, or the layout mapping inline
    size: 0.25                              # target quad edge length (surface units)
    out: [cessna.vtu, cessna.bdf]           # one path or a list; extension picks the format
    report: cessna_report.json              # JSON report
    html: cessna_report.html                # human report (.html, or .md for markdown)

The full key reference, with a complete example, is ``docs/cli.md``.  :func:`load_config`
reads and validates a file, :func:`parse_config` a mapping, :func:`merge_flags` lays the
command-line flags over it (a flag given on the command line wins), :func:`write_config`
writes one back.  Every problem raises :class:`ConfigError` (an
:class:`~shellmesh_mdao.errors.InputFileError`, CLI exit code 2) naming the file, the key
and the fix.
"""
from __future__ import annotations

import difflib
import json
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

from .errors import InputFileError, LayoutError
from .families import SKIN, THICKNESS_FAMILIES, component_family, name_and_parents, parse_component

__all__ = ["ConfigError", "StudyConfig", "CONFIG_KEYS", "REPORT_FORMATS", "THICKNESS_FAMILIES", "solver_options",
           "thickness_by_component", "check_thickness_names",
           "load_config", "parse_config", "merge_flags", "write_config"]


class ConfigError(InputFileError):
    """A study config file is missing, unreadable, or has an unknown key or a value of the wrong type."""


#: Top-level keys of a config file and what they hold (the docs table mirrors this).
CONFIG_KEYS = {
    "surface": "surface triangulation file (.stl .obj .ply .vtu .msh .bdf .step ...)",
    "layout": "member layout: a .json/.yaml file path, or the layout mapping inline (docs/layout.md)",
    "size": "target quad edge length, a positive number in surface units",
    "out": "mesh file(s) to write: one path or a list (.vtu .bdf .nas .inp .msh)",
    "report": "JSON report path (.json)",
    "html": "human report path (.html, or .md for markdown); pictures go next to it",
    "until": "last pipeline stage to run (default: the last stage)",
    "pictures": "true/false: render pictures into the human report (default true)",
    "thickness": "shell thickness for .bdf/.inp: one number, or a mapping of component names or families "
                 "(skin, upper_skin, lower_skin, ribs, spars, members, default) -> number",
    "material": "material for .bdf/.inp: mapping with name, E, nu, rho, G, ys",
    "solver": "solver options (mapping name -> value), see solver_options()",
}

def solver_options() -> dict:
    """Known solver options: name -> default value (its type is the option's type). They are the
    fields of the stages' options classes (:mod:`shellmesh_mdao.options`, by their flat names:
    :meth:`~shellmesh_mdao.options.PipelineOptions.to_dict`), passed to
    :func:`~shellmesh_mdao.pipeline.run_pipeline` as ``options``."""
    from .options import PipelineOptions

    return PipelineOptions().to_dict()


#: Human report extensions and their format.
REPORT_FORMATS = {".html": "html", ".htm": "html", ".md": "markdown", ".markdown": "markdown"}

_MESH_EXT = (".vtu", ".bdf", ".nas", ".inp", ".msh")
_MATERIAL_KEYS = ("name", "E", "nu", "rho", "G", "ys")


@dataclass
class StudyConfig:
    """One meshing run. Paths are absolute :class:`~pathlib.Path` objects once resolved;
    ``layout`` is a path or an inline layout mapping; ``out`` a list of paths; ``None``
    means not given (the CLI then uses its default or asks for the value)."""

    surface: Path | None = None
    layout: Path | dict | None = None
    size: float | None = None
    out: list = field(default_factory=list)
    report: Path | None = None
    html: Path | None = None
    until: str | None = None
    pictures: bool = True
    thickness: float | dict | None = None
    material: dict | None = None
    solver: dict = field(default_factory=dict)
    source: Path | None = None          # the config file, when read from one

    def to_dict(self, relative_to=None) -> dict:
        """Plain mapping in the config-file schema (keys not set left out). With
        ``relative_to`` (a folder), paths are written relative to it where possible."""
        def p(x):
            if x is None:
                return None
            x = Path(x)
            if relative_to is not None:
                try:
                    return Path(os.path.relpath(x, relative_to)).as_posix()
                except ValueError:          # another drive on Windows
                    return str(x)
            return str(x)

        d = {"surface": p(self.surface),
             "layout": self.layout if isinstance(self.layout, dict) else p(self.layout),
             "size": self.size,
             "out": [p(o) for o in self.out] or None,
             "report": p(self.report), "html": p(self.html), "until": self.until,
             "pictures": None if self.pictures else False,
             "thickness": self.thickness, "material": self.material, "solver": dict(self.solver) or None}
        return {k: v for k, v in d.items() if v is not None}


# ----------------------------------------------------------------------------- helpers
def _where(source) -> str:
    if source is not None and str(source).startswith("--"):      # a command-line flag
        return str(source)
    return f"config {source}" if source is not None else "config"


def _err(source, key, problem, fix) -> ConfigError:
    return ConfigError(f"{_where(source)}: key '{key}' {problem}; {fix}")


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _number(v, key, source, *, positive=False, lo=None, hi=None, hi_open=False, integer=False):
    x = v
    if isinstance(v, str):                  # YAML 1.1 reads 1e-3 as a string: accept numeric text
        try:
            x = float(v)
        except ValueError:
            raise _err(source, key, f"must be a number, got the text {v!r}", "write a number") from None
    elif not _is_number(v):
        raise _err(source, key, f"must be a number, got {type(v).__name__} {v!r}", "write a number")
    if integer:
        if float(x) != int(x):
            raise _err(source, key, f"must be an integer, got {v!r}", "write a whole number")
        x = int(x)
    else:
        x = float(x)
    if not math.isfinite(x):
        raise _err(source, key, f"must be finite, got {v!r}", "write a finite number")
    if positive and x <= 0:
        raise _err(source, key, f"must be positive, got {v!r}", "write a number greater than 0")
    if lo is not None and x < lo:
        raise _err(source, key, f"must be at least {lo}, got {v!r}", f"write a number >= {lo}")
    if hi is not None and (x >= hi if hi_open else x > hi):
        raise _err(source, key, f"must be {'below' if hi_open else 'at most'} {hi}, got {v!r}",
                   f"write a number {'<' if hi_open else '<='} {hi}")
    return x


def _path(v, key, source, base: Path, exts=None, what="file") -> Path:
    if not isinstance(v, (str, os.PathLike)) or (isinstance(v, str) and not v.strip()):
        raise _err(source, key, f"must be a {what} path (text), got {type(v).__name__} {v!r}",
                   f"write the path of the {what}")
    p = Path(os.path.expanduser(str(v)))
    if not p.is_absolute():
        p = base / p
    if exts is not None and p.suffix.lower() not in exts:
        raise _err(source, key, f"has the extension {p.suffix or '(none)'!r}",
                   f"use one of {', '.join(exts)}")
    return Path(os.path.normpath(p))


def _unknown(key, allowed, where) -> ConfigError:
    close = difflib.get_close_matches(str(key), list(allowed), n=1)
    hint = f"did you mean '{close[0]}'?" if close else f"the keys are: {', '.join(allowed)}"
    return ConfigError(f"{where}: unknown key '{key}'; {hint}")


def _stages() -> tuple:
    from .pipeline import STAGES

    return tuple(STAGES)


def thickness_by_component(thickness, names) -> float | dict | None:
    """Resolve a config ``thickness`` for the components ``names``: a number stays a number;
    a mapping may name components (``wing/rib_3``, which covers its segments
    ``wing/rib_3/seg_j``) or families (``skin`` (the skin outside the wing boxes),
    ``upper_skin``, ``lower_skin``, ``ribs``, ``spars``, ``members``) and ``default``; a
    component name wins over its family. Returns a number, or a mapping
    component name -> thickness for :func:`~shellmesh_mdao.export.write_mesh`."""
    if thickness is None or not isinstance(thickness, dict):
        return thickness
    inv = {v: k for k, v in THICKNESS_FAMILIES.items()}
    out = {}
    for n in names:
        prefixes = name_and_parents(n)
        hit = next((p for p in prefixes if p in thickness and p not in THICKNESS_FAMILIES), None)
        if hit is not None:                  # a member's segments take the member's thickness
            out[n] = thickness[hit]
        elif inv.get(component_family(n)) in thickness:
            out[n] = thickness[inv[component_family(n)]]
        elif "default" in thickness:
            out[n] = thickness["default"]
    return out


def check_thickness_names(thickness, layout, source=None) -> None:
    """Fail before meshing when a ``thickness`` mapping names a component the layout cannot
    produce (a typo found only at export would waste the whole run)."""
    if not isinstance(thickness, dict):
        return
    from .layout import load_layout

    lay = load_layout(layout if isinstance(layout, dict) else str(layout))
    members = set(lay.member_names())        # a station-given wing: the names it will have
    wings = {w.name for w in lay.wings} | {w.name for w in lay.station_wings}
    for k in thickness:
        if k in THICKNESS_FAMILIES or k == "default" or k in members or _is_bay_of(k, wings):
            continue
        close = difflib.get_close_matches(k, sorted(members) + list(THICKNESS_FAMILIES) + ["default"], n=1)
        hint = f"did you mean '{close[0]}'?" if close else (
            "use a family (" + ", ".join(THICKNESS_FAMILIES) + ", default) or a component name such as "
            + (sorted(members)[0] if members else SKIN))
        raise ConfigError(f"{_where(source)}: key 'thickness.{k}' names no component of this layout; {hint}")


def _is_bay_of(key, wings) -> bool:
    """True when ``key`` names a skin bay (``<wing>/upper_skin/bay_<k>``) of one of ``wings``."""
    try:
        c = parse_component(key)
    except LayoutError:
        return False
    return c.kind == "skin_bay" and c.wing in wings


# ----------------------------------------------------------------------------- public API
def parse_config(data, base_dir=".", source=None) -> StudyConfig:
    """Validate a config mapping and return a :class:`StudyConfig`; relative paths are
    resolved against ``base_dir`` (the config file's folder). ``source`` names the file in
    error messages. Raises :class:`ConfigError`."""
    base = Path(base_dir).resolve()
    if data is None:
        raise ConfigError(f"{_where(source)} is empty: give at least 'surface', 'layout' and 'size' "
                          "(see docs/cli.md)")
    if not isinstance(data, dict):
        raise ConfigError(f"{_where(source)} must be a mapping of keys ({', '.join(CONFIG_KEYS)}), "
                          f"got {type(data).__name__}; see docs/cli.md")
    for k in data:
        if k not in CONFIG_KEYS:
            raise _unknown(k, CONFIG_KEYS, _where(source))
    cfg = StudyConfig(source=Path(source).resolve() if source is not None else None)
    g = data.get
    if g("surface") is not None:
        cfg.surface = _path(g("surface"), "surface", source, base, what="surface file")
    lay = g("layout")
    if lay is not None:
        if isinstance(lay, dict):
            from .layout import load_layout

            try:
                load_layout(lay)
            except LayoutError as e:
                raise ConfigError(f"{_where(source)}: key 'layout' (inline): {e}") from None
            cfg.layout = lay
        else:
            cfg.layout = _path(lay, "layout", source, base, exts=(".json", ".yaml", ".yml"),
                               what="layout file (or an inline layout mapping)")
    if g("size") is not None:
        cfg.size = _number(g("size"), "size", source, positive=True)
    out = g("out")
    if out is not None:
        items = out if isinstance(out, list) else [out]
        if not items:
            raise _err(source, "out", "is an empty list", "name at least one mesh file, or leave the key out")
        cfg.out = [_path(o, f"out[{i}]" if isinstance(out, list) else "out", source, base, exts=_MESH_EXT,
                         what="mesh file") for i, o in enumerate(items)]
    if g("report") is not None:
        cfg.report = _path(g("report"), "report", source, base, exts=(".json",), what="JSON report")
    if g("html") is not None:
        cfg.html = _path(g("html"), "html", source, base, exts=tuple(REPORT_FORMATS), what="human report")
    if g("until") is not None:
        st = _stages()
        if g("until") not in st:
            raise _err(source, "until", f"is {g('until')!r}, not a stage", f"use one of: {', '.join(st)}")
        cfg.until = g("until")
    if g("pictures") is not None:
        if not isinstance(g("pictures"), bool):
            raise _err(source, "pictures", f"must be true or false, got {g('pictures')!r}", "write true or false")
        cfg.pictures = g("pictures")
    th = g("thickness")
    if th is not None:
        if isinstance(th, dict):
            cfg.thickness = {str(n): _number(t, f"thickness.{n}", source, positive=True) for n, t in th.items()}
        else:
            cfg.thickness = _number(th, "thickness", source, positive=True)
    mat = g("material")
    if mat is not None:
        if not isinstance(mat, dict):
            raise _err(source, "material", f"must be a mapping, got {type(mat).__name__}",
                       f"give keys among {', '.join(_MATERIAL_KEYS)}")
        for k in mat:
            if k not in _MATERIAL_KEYS:
                raise _unknown(k, _MATERIAL_KEYS, f"{_where(source)}: material")
        from .export import resolve_material
        from .errors import OutputError

        m = {k: (str(v) if k == "name" else _number(v, f"material.{k}", source)) for k, v in mat.items()}
        try:
            resolve_material(m)
        except OutputError as e:
            raise ConfigError(f"{_where(source)}: key 'material': {e}") from None
        cfg.material = m
    sol = g("solver")
    if sol is not None:
        if not isinstance(sol, dict):
            raise _err(source, "solver", f"must be a mapping, got {type(sol).__name__}",
                       f"give options among {', '.join(solver_options())}")
        known = solver_options()
        out_s = {}
        for k, v in sol.items():
            key = f"solver.{k}"
            if k not in known:
                raise _unknown(k, known, f"{_where(source)}: solver")
            default = known[k]
            if isinstance(default, bool):
                if not isinstance(v, bool):
                    raise _err(source, key, f"must be true or false, got {v!r}", "write true or false")
                out_s[k] = v
            elif isinstance(default, str):          # smooth_energy: its class checks the word
                out_s[k] = str(v)
            elif isinstance(default, int):
                out_s[k] = _number(v, key, source, lo=0, integer=True)
            else:
                out_s[k] = _number(v, key, source, lo=0.0)
        cfg.solver = out_s
    return cfg


def load_config(path) -> StudyConfig:
    """Read and validate a config file (``.yaml``/``.yml``, or ``.json``); relative paths in it
    are resolved against the file's folder. Raises :class:`ConfigError`."""
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"config file not found: {p}; check the path (see docs/cli.md for the format)")
    if p.is_dir():
        raise ConfigError(f"config {p} is a folder; give the config file (.yaml or .json)")
    if p.suffix.lower() not in (".yaml", ".yml", ".json"):
        raise ConfigError(f"config {p}: unknown extension {p.suffix or '(none)'!r}; use .yaml, .yml or .json")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(f"cannot read config {p}: {getattr(e, 'strerror', None) or e}; "
                          "check the file and its permissions") from None
    try:
        if p.suffix.lower() == ".json":
            data = json.loads(text)
        else:
            import yaml

            data = yaml.safe_load(text)
    except json.JSONDecodeError as e:
        raise ConfigError(f"config {p}: invalid JSON at line {e.lineno}, column {e.colno}: {e.msg}; "
                          "fix the syntax") from None
    except Exception as e:  # yaml.YAMLError
        mark = getattr(e, "problem_mark", None)
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        raise ConfigError(f"config {p}: invalid YAML{at}: {getattr(e, 'problem', None) or e}; "
                          "fix the syntax") from None
    return parse_config(data, p.resolve().parent, source=p)


def merge_flags(cfg: StudyConfig | None, **flags) -> StudyConfig:
    """``cfg`` with the command-line values laid over it: every flag that is not ``None``
    replaces the config value (``out`` replaces the whole list). Flag paths are taken as
    given (relative to the current folder); ``layout`` may be a path or a mapping."""
    cfg = StudyConfig() if cfg is None else replace(cfg)
    known = {f for f in StudyConfig.__dataclass_fields__ if f != "source"}
    for k, v in flags.items():
        if k not in known:
            raise TypeError(f"merge_flags: unknown field {k!r}")
        if v is None:
            continue
        if k in ("surface", "report", "html"):
            v = Path(v)
        elif k == "layout" and not isinstance(v, dict):
            v = Path(v)
        elif k == "out":
            v = [Path(o) for o in (v if isinstance(v, (list, tuple)) else [v])]
        setattr(cfg, k, v)
    return cfg


def write_config(cfg: StudyConfig, path) -> Path:
    """Write ``cfg`` as YAML (or JSON for ``.json``), atomically, with paths relative to the
    file's folder, so that :func:`load_config` reads the same config back."""
    from .export import write_text_atomic

    p = Path(path)
    d = cfg.to_dict(relative_to=p.resolve().parent)
    if p.suffix.lower() == ".json":
        text = json.dumps(d, indent=2) + "\n"
    else:
        import yaml

        text = yaml.safe_dump(d, sort_keys=False, default_flow_style=None)
    return write_text_atomic(p, text)
