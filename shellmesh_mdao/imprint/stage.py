"""The imprint stage's cut and chain finishing (:func:`imprint_mesh`): every member's curves cut into
the skin, the chains refined toward their exact curves, coarsened toward the skin's spacing, and
the skin edges bridging a member's chains split."""
from __future__ import annotations

from ..mesh import ShellMesh
from ..options import ImprintOptions
from .bridges import split_member_bridges
from .cut import imprint_chains
from .refine import coarsen_chains, refine_chains

__all__ = ["imprint_mesh"]


def imprint_mesh(skin: ShellMesh, surface: ShellMesh, specs, target_edge: float,
                 options: ImprintOptions = ImprintOptions(), *, locator, size_field=None) -> tuple[ShellMesh, list]:
    """The pipeline's imprint stage on the (remeshed) ``skin``: the chains of ``specs``
    (:class:`~shellmesh_mdao.imprint.ChainSpec`) cut into it (:func:`imprint_chains` with the
    option ``snap``), their edges split where the exact section bulges more than
    ``chain_deviation`` times ``target_edge`` (the remesh edge length) from them, or more than
    ``chain_depth_deviation`` of their member's depth (:func:`refine_chains`; not at all with
    ``chain_deviation`` 0), the chains coarsened toward ``target_edge`` (:func:`coarsen_chains`; toward
    the local size where ``size_field``, a :class:`~shellmesh_mdao.core.sizefield.SizeField` in the
    units of ``target_edge``, asks for less)
    and the skin edges joining two vertices of one member's chains split
    (:func:`split_member_bridges`). ``surface``: the input skin, on which every new vertex
    lies; ``locator``: its :class:`~shellmesh_mdao.project.SurfaceLocator`; ``options``: the
    stage's :class:`~shellmesh_mdao.options.ImprintOptions`.

    Returns ``(mesh, chains)``: the imprinted skin and one :class:`~shellmesh_mdao.imprint.ChainResult`
    per chain spec."""
    P, T = surface.points, surface.faces[:, :3]
    mesh, chains = imprint_chains(skin, P, T, specs, snap=options.snap, locator=locator)
    if options.chain_deviation > 0:
        mesh = refine_chains(mesh, chains, options.chain_deviation * target_edge,
                             depth_fraction=options.chain_depth_deviation)
    mesh = coarsen_chains(mesh, locator, chains, target_edge, size_field=size_field)
    mesh = split_member_bridges(mesh, chains, locator)
    return mesh, chains
