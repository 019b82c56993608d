"""shellmesh_mdao: conforming all-quad shell meshes of aircraft skins and internal members.

Pipeline stages (one module each): load -> layout -> project -> imprint -> members ->
split -> merge -> smooth -> quad -> export.
"""
from .errors import ShellMeshError
from .mesh import ShellMesh, concatenate

__version__ = "0.1.0"
__all__ = ["ShellMesh", "ShellMeshError", "concatenate", "__version__"]
