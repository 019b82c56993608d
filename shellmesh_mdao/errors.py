"""One error family for everything a user can get wrong.

Every error a user can cause (bad file, bad layout, bad size, unwritable output)
is a :class:`ShellMeshError` subclass. Its message names the problem and the fix.
The CLI turns these into one line on stderr and exit code 2; any other exception
is an internal error (exit code 1, with a request to report it).
"""

__all__ = ["ShellMeshError", "InputFileError", "MeshValidationError", "LayoutError", "ProjectionError",
           "ImprintError", "SizeError", "OutputError", "SolverError", "GuaranteeError"]


class ShellMeshError(Exception):
    """Base class of all user-facing errors (CLI exit code 2)."""


class InputFileError(ShellMeshError):
    """A surface or mesh file is missing, unreadable, empty or of an unknown format."""


class MeshValidationError(ShellMeshError):
    """A mesh violates a topological or geometric requirement (open, non-manifold, NaN, ...)."""


class GuaranteeError(MeshValidationError):
    """A finished mesh misses one of the README's guarantees
    (:func:`~shellmesh_mdao.guarantees.check_guarantees`): the pipeline refuses it instead of
    returning or writing it."""


class LayoutError(ShellMeshError):
    """A member layout is malformed or inconsistent with the surface."""


class ProjectionError(ShellMeshError):
    """A member curve cannot be projected onto the skin (it misses the surface)."""


class ImprintError(ShellMeshError):
    """A member curve cannot be imprinted into the skin."""


class SizeError(ShellMeshError):
    """The requested element size is non-positive, non-finite or out of proportion to the surface."""


class OutputError(ShellMeshError):
    """An output file cannot be written (missing folder, read-only location, unknown extension)."""


class SolverError(ShellMeshError):
    """An external solver (HiGHS, CalculiX) is missing or failed."""
