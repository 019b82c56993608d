"""One source of options: the stages' option classes (shellmesh_mdao.options), the flat names users
give (CLI ``--option``, a study's ``solver:``, ``PipelineOptions.from_dict``, the report's
``inputs.options``), docs/cli.md's table of them, and the stage functions' defaults, which are
the options' own."""
from __future__ import annotations

import dataclasses
import inspect
import re
from pathlib import Path

import pytest

from shellmesh_mdao import pipeline as pl
from shellmesh_mdao.errors import ShellMeshError
from shellmesh_mdao.imprint import cut_chain, imprint_chains, imprint_mesh, refine_chains
from shellmesh_mdao.merge import merge_mesh, merge_triangles
from shellmesh_mdao.options import (ImprintOptions, MergeOptions, PipelineOptions, QuadOptions, RemeshOptions,
                                    SmoothOptions, SplitOptions)
from shellmesh_mdao.quad import (finish_quads, finish_region, planarize, quad_mesh, settle_off_surface,
                                 subdivide_to_quads)
from shellmesh_mdao.remesh import remesh_skin
from shellmesh_mdao.smooth import smooth, smooth_mesh
from shellmesh_mdao.split import split_mesh, split_polygons

REPO = Path(__file__).resolve().parents[1]

#: each stage's entry function: the parameter that takes the stage's options object
ENTRY = [(remesh_skin, "options", RemeshOptions), (imprint_mesh, "options", ImprintOptions),
         (split_mesh, "options", SplitOptions), (merge_mesh, "options", MergeOptions),
         (smooth_mesh, "options", SmoothOptions), (quad_mesh, "options", QuadOptions),
         (quad_mesh, "smooth_options", SmoothOptions), (finish_quads, "options", QuadOptions),
         (finish_region, "options", QuadOptions)]

#: the lower-level functions the stages call, by their neutral keyword: the option whose value
#: the stage passes there
LOWER = [(imprint_chains, "snap", "snap"), (cut_chain, "snap", "snap"),
         (refine_chains, "depth_fraction", "chain_depth_deviation"),
         (split_polygons, "time_limit", "split_time_limit"),
         (merge_triangles, "time_limit", "merge_time_limit"), (merge_triangles, "mip_gap", "merge_mip_gap"),
         (merge_triangles, "merge_bonus", "merge_bonus"), (merge_triangles, "valence_weight", "merge_valence_weight"),
         (smooth, "iterations", "smooth_iterations"), (smooth, "energy", "smooth_energy"),
         (smooth, "min_jacobian", "smooth_jacobian"), (smooth, "warp_weight", "smooth_warp_weight"),
         (smooth, "warp_from", "warp_from"), (smooth, "warp_spread", "smooth_warp_spread"),
         (subdivide_to_quads, "guard_jacobian", "guard_jacobian"),
         (settle_off_surface, "guard_jacobian", "guard_jacobian"), (planarize, "warp_above", "warp_goal")]


def _default(func, name):
    p = inspect.signature(func).parameters[name]
    assert p.default is not inspect.Parameter.empty, f"{func.__name__}({name}) has no default"
    return p.default


def _fmt(v) -> str:
    """A default as docs/cli.md writes it (YAML's words for booleans)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    return v if isinstance(v, str) else repr(v)


def _options():
    """(name, stage, class, default) of every option, stage by stage."""
    return [(f.name, stage, oc, f.default) for stage, oc in PipelineOptions.stages().items()
            for f in dataclasses.fields(oc)]


def test_the_options_are_the_stage_classes_fields_with_unique_flat_names():
    opts = _options()
    names = [n for n, *_ in opts]
    assert len(names) == len(set(names)) == 25
    assert list(PipelineOptions.stages()) == ["remesh", "imprint", "split", "merge", "smooth", "quad"]
    assert all(s in pl.STAGES for s in PipelineOptions.stages())
    o = PipelineOptions()
    assert o.to_dict() == {n: d for n, _, _, d in opts}
    assert o.merge.merge_time_limit == 60.0 and o.quad.planar_offset == 0.05 and o.remesh == RemeshOptions()
    # the flat names round trip; a replace changes one option in its stage's object
    assert PipelineOptions.from_dict(o.to_dict()) == o and PipelineOptions.from_dict(None) == o
    r = o.replace(final_refresh=1, snap=0.3)
    assert (r.quad.final_refresh, r.imprint.snap, r.merge) == (1, 0.3, o.merge)
    assert PipelineOptions.from_dict({"smooth_iterations": "3", "merge_bonus": 2}).to_dict() == dict(
        o.to_dict(), smooth_iterations=3, merge_bonus=2.0)
    with pytest.raises(TypeError, match="from_dict"):
        PipelineOptions(merge={"merge_bonus": 2.0})
    from shellmesh_mdao.config import solver_options
    assert solver_options() == o.to_dict()


def test_docs_cli_table_lists_every_option_with_its_stage_type_and_default():
    text = (REPO / "docs" / "cli.md").read_text(encoding="utf-8")
    section = text.split("### Solver options", 1)[1].split("\n### ", 1)[0]
    rows = [[c.strip() for c in line.strip().strip("|").split(" | ")] for line in section.splitlines()
            if line.startswith("| `")]
    assert rows, "docs/cli.md has no solver options table"
    listed = [r[0].strip("`") for r in rows]
    names = [n for n, *_ in _options()]
    assert sorted(set(listed)) == sorted(listed), "an option is listed twice"
    assert not set(listed) - set(names), f"unknown options listed: {sorted(set(listed) - set(names))}"
    assert not set(names) - set(listed), f"options missing from the table: {sorted(set(names) - set(listed))}"
    assert listed == names                                                   # stage by stage, in order
    for (name, stage, _, default), r in zip(_options(), rows):
        assert r[1:4] == [stage, type(default).__name__, _fmt(default)], (name, r[1:4])
        assert r[4], f"{name}: no meaning"


@pytest.mark.parametrize("func,name,cls", ENTRY, ids=lambda x: getattr(x, "__name__", x))
def test_stage_functions_take_their_options_object(func, name, cls):
    assert _default(func, name) == cls()
    # no keyword of an entry function repeats one of its options
    assert not set(inspect.signature(func).parameters) & {f.name for f in dataclasses.fields(cls)}


@pytest.mark.parametrize("func,name,option", LOWER, ids=lambda x: getattr(x, "__name__", x))
def test_lower_level_defaults_are_the_pipeline_stage_defaults(func, name, option):
    assert _default(func, name) == PipelineOptions().to_dict()[option]


def test_the_pipeline_stages_call_with_their_options_object():
    """Every stage function of pipeline.py with options hands ``state.options.<stage>`` to its
    stage, and none reads an option by itself (tests/test_pipeline.py checks that options set
    in the state change the stages' results)."""
    src = inspect.getsource(pl)
    for stage in PipelineOptions.stages():
        body = inspect.getsource(getattr(pl, f"stage_{stage}"))
        assert f"state.options.{stage}" in body, stage
    # no stage function reads an option by itself (all go through the stage's object)
    assert not re.search(r"state\.options\.(?!(" + "|".join(PipelineOptions.stages()) + r")\b)", src)


BAD = [({"merge_gap": 0.1}, "merge_gap", "known: remesh, remesh_deviation"),
       ({"merge_mip_gap": "tight"}, "merge_mip_gap", "must be a float"),
       ({"smooth_iterations": float("inf")}, "smooth_iterations", "must be a int"),
       ({"snap": -1}, "snap", "finite non-negative number"),
       ({"snap": 0.5}, "snap", "must be below 0.5"),
       ({"planar_offset": 0.3}, "planar_offset", "must be at most 0.25"),
       ({"final_refresh": 0}, "final_refresh", "must be at least 1"),
       ({"smooth_warp_spread": 0.0}, "smooth_warp_spread", "must be in (0, 180] degrees"),
       ({"smooth_energy": "cubic"}, "smooth_energy", "must be 'length' or 'squared'")]


@pytest.mark.parametrize("bad,name,fix", BAD, ids=[b[1] for b in BAD])
def test_from_dict_errors_name_the_option_and_the_fix(bad, name, fix):
    with pytest.raises(ShellMeshError) as e:
        PipelineOptions.from_dict(bad)
    msg = str(e.value)
    assert name in msg and fix in msg
    # the same from the stage's own class, and the message is listed in docs/troubleshooting.md
    if name != "merge_gap":
        stage = {f.name: s for s, oc in PipelineOptions.stages().items() for f in dataclasses.fields(oc)}[name]
        with pytest.raises(ShellMeshError, match=re.escape(fix)):
            PipelineOptions.stages()[stage](**bad)
    page = re.sub(r"\s+", " ", (REPO / "docs" / "troubleshooting.md").read_text(encoding="utf-8"))
    listed = [re.compile(re.sub(r"\\\{[^{}]*\\\}", ".+", re.escape(t))) for t in re.findall(r"`([^`]+)`", page)
              if "{" in t]
    assert any(p.fullmatch(msg) for p in listed), f"not in docs/troubleshooting.md: {msg}"


def test_report_inputs_options_are_the_flat_names():
    from shellmesh_mdao.geometry import naca_wing
    st = pl.stage_load(naca_wing(n_chord=12, n_span=6), 0.15, {"snap": 0.3, "merge_time_limit": 5})
    assert st.report["inputs"]["options"] == dict(PipelineOptions().to_dict(), snap=0.3, merge_time_limit=5.0)
    assert st.options.imprint.snap == 0.3 and st.options.merge.merge_time_limit == 5.0


def test_config_and_cli_take_the_text_option():
    """``smooth_energy`` (the one text option) from a study's ``solver:`` mapping or --option."""
    from shellmesh_mdao.config import parse_config
    assert parse_config({"solver": {"smooth_energy": "length"}}, ".", source="--option").solver == {
        "smooth_energy": "length"}
    assert PipelineOptions.from_dict({"smooth_energy": "length"}).smooth.smooth_energy == "length"
