"""The solver options: one frozen dataclass per stage that has options, and :class:`PipelineOptions`
made of them.

Each option is documented once, in its stage's class docstring, and checked there: every
field is coerced to its default's type and numbers must be finite and non-negative, plus the
stage's own bounds (a :class:`~shellmesh_mdao.errors.ShellMeshError` naming the option and the
fix). Each stage's entry function takes its stage's object (``options=MergeOptions()`` and
so on), so the stage's defaults ARE the pipeline's; the lower-level functions a stage calls
keep neutral keyword names (``time_limit``, ``iterations`` ...) whose defaults are read from
these classes.

The option names are flat and unique over the stages: the CLI's ``--option NAME=VALUE``, a
study config's ``solver:`` mapping, :meth:`PipelineOptions.from_dict` and the report's
``inputs.options`` (:meth:`PipelineOptions.to_dict`) use them; ``PipelineOptions().merge``
is the merge stage's :class:`MergeOptions`, ``PipelineOptions().merge.merge_time_limit`` one
option. docs/cli.md's table lists them (tests/test_options.py checks it against these classes).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .errors import ShellMeshError

__all__ = ["RemeshOptions", "ImprintOptions", "SplitOptions", "MergeOptions", "SmoothOptions", "QuadOptions",
           "PipelineOptions"]


def _coerce(opts) -> None:
    """Coerce every field of the frozen dataclass ``opts`` to its default's type (``bool(v)`` for a
    bool); numbers must be finite and non-negative."""
    for f in dataclasses.fields(opts):
        v = getattr(opts, f.name)
        typ = type(f.default)
        try:
            x = typ(v) if typ is not bool else bool(v)
        except (TypeError, ValueError, OverflowError):
            raise ShellMeshError(f"solver option {f.name!r} must be a {typ.__name__}, got {v!r}") from None
        if typ in (int, float) and not (np.isfinite(x) and x >= 0):
            raise ShellMeshError(f"solver option {f.name!r} must be a finite non-negative number, got {v!r}")
        object.__setattr__(opts, f.name, x)


@dataclass(frozen=True)
class RemeshOptions:
    """Options of the remesh stage (:func:`~shellmesh_mdao.remesh.remesh_skin`).

    ``remesh``            remesh the skin before imprinting (False: the stage imprints into the
                          input triangulation as it is; for tests). The remesh stage reads it;
                          :func:`~shellmesh_mdao.remesh.remesh_skin` itself always remeshes.
    ``remesh_deviation``  chordal deviation allowed between the remeshed skin and the input, as a
                          fraction of the remesh edge length (edges shrink where curvature needs it).
    ``remesh_pass_fraction`` the remesh's deviation passes (which shrink the sizing where edges
                          still deviate more than that and re-run four sweeps over the whole skin)
                          run only while more than this fraction of the edges deviate; fewer are
                          split where they are by its last-resort deviation splits, which hold the
                          bound either way. Default 0.02: the corpus has at most 0.7 % (its passes
                          cost 0.45 s of the target case's remesh, and the merge's valence term more
                          than makes up the scaled Jacobian they bought), the default wing 4 %; 0
                          runs them for any deviating edge (docs/benchmarks.md).
    """

    remesh: bool = True
    remesh_deviation: float = 0.1
    remesh_pass_fraction: float = 0.02

    def __post_init__(self):
        _coerce(self)


@dataclass(frozen=True)
class ImprintOptions:
    """Options of the imprint stage (:func:`~shellmesh_mdao.imprint.imprint_mesh`).

    ``snap``              the imprint moves a skin vertex onto a member plane when it lies within
                          this fraction of its shortest incident edge of it (instead of cutting a
                          sliver beside it); below 0.5, default 0.4 (fewer triangles beside the
                          chains than at 0.25: swept_wing skin mean scaled Jacobian 0.9507 against
                          0.9468). A chain whose cut misses one of its crossing vertices at a
                          distance above 0.25 is cut again at 0.25 (``imprint.SNAP_FALLBACK``; the
                          report's per-chain ``snap`` says which was used).
    ``chain_deviation``   above 0: after the cut, member chain edges whose exact section bulges more
                          than this fraction of the remesh edge length from the chord are split
                          (:func:`~shellmesh_mdao.imprint.refine_chains`). Default 0.01; 0 turns it off.
    ``chain_depth_deviation`` with ``chain_deviation`` on, a chain edge is also split where its exact
                          section bulges more than this fraction of its member's depth (the distance
                          to the member's other chain, :func:`~shellmesh_mdao.imprint.chain_depths`):
                          the chords then cut off at most about 4/3 of it of the member's area, 1 %
                          at the default 0.0075, however thin the section against the element size.
                          Worst corpus member area error 0.58 % (bwb's outer ribs; 1.0 % with 0, off).
    """

    snap: float = 0.4
    chain_deviation: float = 0.01
    chain_depth_deviation: float = 0.0075

    def __post_init__(self):
        _coerce(self)
        if not self.snap < 0.5:
            raise ShellMeshError(f"solver option 'snap' must be below 0.5 (a fraction of a vertex's shortest "
                                 f"incident edge), got {self.snap!r}")


@dataclass(frozen=True)
class SplitOptions:
    """Options of the split stage (:func:`~shellmesh_mdao.split.split_mesh`).

    ``split_time_limit``  HiGHS time limit (s) of the splitting LP/MIP.
    """

    split_time_limit: float = 60.0

    def __post_init__(self):
        _coerce(self)


@dataclass(frozen=True)
class MergeOptions:
    """Options of the merge stage (:func:`~shellmesh_mdao.merge.merge_mesh`).

    ``merge_time_limit``, ``merge_mip_gap``: HiGHS time limit (s) and relative gap of the
                          merging MIP.
    ``merge_bonus``       reward per merged triangle pair (in units of the eq.-5 energy): above
                          0 the MIP prefers quads even where two triangles score slightly better,
                          which leaves fewer triangles for the final subdivision (each gives
                          three 120-degree-cornered quads).
    ``merge_valence_weight`` weight of the merge's valence term (beyond the paper): each free
                          skin and member node (not on a chain, feature line or junction) adds this
                          times ``|valence - 4|``, its valence counted after the merge, to the
                          merge's objective (:func:`~shellmesh_mdao.merge.merge_triangles`'s
                          ``valence_weight``): the subdivided quads around a node of valence 3, 5
                          or 6 cannot all be square. Default 0.5 (the corpus's skin mean scaled
                          Jacobian +0.004 to +0.008, docs/benchmarks.md); 0 turns it off.
    """

    merge_time_limit: float = 60.0
    merge_mip_gap: float = 0.01
    merge_bonus: float = 1.0
    merge_valence_weight: float = 0.5

    def __post_init__(self):
        _coerce(self)


@dataclass(frozen=True)
class SmoothOptions:
    """Options of the smooth stage (:func:`~shellmesh_mdao.smooth.smooth_mesh`); ``smooth_energy``
    and ``warp_from`` are the quad stage's final passes' too
    (:func:`~shellmesh_mdao.quad.quad_mesh`).

    ``smooth_iterations`` trust-region steps of the smoothing QP before subdivision (default 10).
    ``smooth_jacobian``   no smoothing step before subdivision may bring an element to or below
                          this scaled Jacobian (nor lower one already below it).
    ``smooth_energy``     energy of both smoothing passes: ``"squared"`` (default: each edge aims at
                          the local size at its ends, the mean length of the edges at a vertex,
                          at most twice ``size`` before subdivision, ``size`` after) or
                          ``"length"`` (sum of edge lengths, scale-free: the paper's words); see
                          :func:`~shellmesh_mdao.smooth.smooth` and docs/optimisation.md.
    ``smooth_warp_weight`` the quad planarity term (``warp_weight`` of
                          :func:`~shellmesh_mdao.smooth.smooth`; :class:`QuadOptions`'
                          ``final_warp_weight`` says what it does) in the smoothing before
                          subdivision. Default 300 (bwb's warp p99 10.5 -> 9.7 degrees); 0 drops it.
    ``smooth_warp_spread`` the term before subdivision leaves out the quads that share a vertex with
                          a face whose corners' input facets are turned more than this many degrees
                          apart (a face draped over a tip cap or nose much tighter than itself:
                          pulling there dragged nodes across the crease, and the subdivision then left
                          nodes off the surface). Default 75.
    ``warp_from``         warp (degrees) above which a quad is in the planarity term; default 7.
    """

    smooth_iterations: int = 10
    smooth_jacobian: float = 0.4
    smooth_energy: str = "squared"
    smooth_warp_weight: float = 300.0
    smooth_warp_spread: float = 75.0
    warp_from: float = 7.0

    def __post_init__(self):
        _coerce(self)
        if not 0 < self.smooth_warp_spread <= 180:
            raise ShellMeshError(f"solver option 'smooth_warp_spread' must be in (0, 180] degrees, got "
                                 f"{self.smooth_warp_spread!r}")
        if self.smooth_energy not in ("length", "squared"):
            raise ShellMeshError(f"solver option 'smooth_energy' must be 'length' or 'squared', got "
                                 f"{self.smooth_energy!r}")


@dataclass(frozen=True)
class QuadOptions:
    """Options of the quad stage (:func:`~shellmesh_mdao.quad.quad_mesh`: the subdivision, its final
    smoothing passes, their repairs and the flattening of warped quads; the passes use
    :class:`SmoothOptions`' ``smooth_energy`` and ``warp_from``).

    ``final_iterations``  smoothing steps after subdivision (default 4).
    ``final_refresh``     steps of the final pass (``final_iterations``) between rebuilding its
                          tangent frames, edge weights and matrix (``refresh`` of
                          :func:`~shellmesh_mdao.smooth.smooth`; default 2, at least 1).
    ``final_warp_iterations`` steps of the second final pass, the one with the quad planarity term
                          (default 10; see ``final_warp_weight``).
    ``guard_jacobian``    a subdivided element whose projected new nodes would bring its scaled
                          Jacobian to or below this keeps them at their linear position.
    ``final_ortho_weight`` weight of the quad-corner orthogonality term in the smoothing after
                          subdivision (``ortho_weight`` of :func:`~shellmesh_mdao.smooth.smooth`;
                          the pass before subdivision keeps smooth()'s default 1). 3 lifts the
                          worst and the mean scaled Jacobian (docs/benchmarks.md); 0 drops the term.
    ``final_warp_weight`` weight of the quad planarity term (``warp_weight`` of
                          :func:`~shellmesh_mdao.smooth.smooth`: the corners of quads warped more than
                          ``warp_from`` degrees slide along the input facets until the quad is
                          flatter) in a second smoothing pass after subdivision, run only while more
                          than 1 % of the quads are warped more than ``warp_goal`` degrees after the
                          first (the warp p99 acceptance; ``warp_goal`` 0: always) and the
                          ``planar_offset`` move alone does not bring them to it (tried first on the
                          first pass's mesh: cheaper, and it keeps the scaled Jacobians; on the corpus
                          only straight_wing needs the pass), moving only the nodes within two rings of
                          the quads that move left warped more than ``warp_goal`` (with
                          ``planar_offset`` 0: of the quads warped more than ``warp_from``). Default
                          300; 0 drops the pass.
    ``warp_goal``         warp p99 (degrees) the final smoothing's planarity term works towards;
                          default 10 (:data:`~shellmesh_mdao.quality.ACCEPTANCE`).
    ``planar_offset``     after the final smoothing, the free skin nodes (not on chains, junctions,
                          feature lines or members) around the quads still warped more than
                          ``warp_goal`` degrees may move along their normal, off the input facets, by
                          at most this fraction of ``size`` (and 0.15 of their local quad edge) to
                          flatten those quads (:func:`~shellmesh_mdao.quad.planarize`; report key
                          ``planarize``). 0.05 is the chordal deviation the remesh already accepts
                          (``remesh_deviation`` 0.1 of the remesh edge, a quarter of it at the final
                          quads). Default 0.05; 0 keeps every skin node on the input. At most 0.25.
    """

    final_iterations: int = 4
    final_refresh: int = 2
    final_warp_iterations: int = 10
    guard_jacobian: float = 0.2
    final_ortho_weight: float = 3.0
    final_warp_weight: float = 300.0
    warp_goal: float = 10.0
    planar_offset: float = 0.05

    def __post_init__(self):
        _coerce(self)
        if not self.planar_offset <= 0.25:
            raise ShellMeshError(f"solver option 'planar_offset' must be at most 0.25 (a fraction of the size by "
                                 f"which skin nodes may leave the input to flatten warped quads), got "
                                 f"{self.planar_offset!r}")
        if self.final_refresh < 1:
            raise ShellMeshError(f"solver option 'final_refresh' must be at least 1 (steps between rebuilding the "
                                 f"final pass's frames and matrix), got {self.final_refresh!r}")


@dataclass(frozen=True)
class PipelineOptions:
    """Options of the stages after ``load`` (the CLI's and the components' solver options): one
    field per stage that has options, named after the stage, each that stage's options object
    (its class documents every option). ``PipelineOptions().quad.planar_offset`` is one option;
    :meth:`from_dict`, :meth:`to_dict` and :meth:`replace` take the flat option names."""

    remesh: RemeshOptions = field(default_factory=RemeshOptions)
    imprint: ImprintOptions = field(default_factory=ImprintOptions)
    split: SplitOptions = field(default_factory=SplitOptions)
    merge: MergeOptions = field(default_factory=MergeOptions)
    smooth: SmoothOptions = field(default_factory=SmoothOptions)
    quad: QuadOptions = field(default_factory=QuadOptions)

    def __post_init__(self):
        for f in dataclasses.fields(self):
            if not isinstance(getattr(self, f.name), f.default_factory):
                raise TypeError(f"PipelineOptions.{f.name} must be a {f.default_factory.__name__}, got "
                                f"{getattr(self, f.name)!r}; build options from a dict of option names with "
                                f"PipelineOptions.from_dict")

    @classmethod
    def stages(cls) -> dict:
        """Stage name -> its options class, in pipeline order."""
        return {f.name: f.default_factory for f in dataclasses.fields(cls)}

    @classmethod
    def from_dict(cls, d: dict | None) -> "PipelineOptions":
        """Options from a dict of option names (flat: ``{"merge_time_limit": 30, "snap": 0.3}``);
        unknown names are a :class:`ShellMeshError` naming them; None: the defaults."""
        if d is None:
            return cls()
        if isinstance(d, PipelineOptions):
            return d
        known = {f.name: stage for stage, oc in cls.stages().items() for f in dataclasses.fields(oc)}
        bad = sorted(set(d) - set(known))
        if bad:
            raise ShellMeshError(f"unknown solver option(s) {bad}; known: {', '.join(known)}")
        return cls(**{stage: oc(**{k: v for k, v in d.items() if known[k] == stage})
                      for stage, oc in cls.stages().items()})

    def to_dict(self) -> dict:
        """Every option by its flat name, stage by stage (the report's ``inputs.options``)."""
        return {k: v for stage in self.stages() for k, v in dataclasses.asdict(getattr(self, stage)).items()}

    def replace(self, **changes) -> "PipelineOptions":
        """A copy with the options named in ``changes`` (flat names) replaced."""
        return PipelineOptions.from_dict({**self.to_dict(), **changes})
