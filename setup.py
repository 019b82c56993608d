from pathlib import Path

from setuptools import find_packages, setup

setup(
    name="shellmesh_mdao",
    version="0.1.0",
    description="Conforming all-quad shell-element meshes of aircraft skins and internal members, for OpenMDAO studies",
    long_description=Path(__file__).with_name("README.md").read_text(encoding="utf-8"),
    long_description_content_type="text/markdown",
    python_requires=">=3.10",
    packages=find_packages(include=["shellmesh_mdao", "shellmesh_mdao.*"]),
    include_package_data=True,
    package_data={"shellmesh_mdao": ["data/*", "data/licenses/*"]},
    install_requires=[
        "numpy>=1.24",
        "numba>=0.59",
        "scipy>=1.10",
        "openmdao>=3.30",
        "trimesh>=4.0",
        "embreex>=2.17",
        "rtree>=1.0",
        "pyvista>=0.43",
        "highspy>=1.7",
        "qdldl>=0.1.9",
        "threadpoolctl>=3.1",
        "meshio>=5.3",
        "pyNastran>=1.4",
        "pyyaml>=6.0",
        "triangle>=20230923",
        "matplotlib>=3.7",
        "rich>=13.0",
        "manifold3d>=2.3",
        "pyDOE3>=1.0",
        "pillow>=9.0",
    ],
    extras_require={
        "test": ["pytest>=7", "pytest-xdist>=3", "hypothesis>=6", "pytest-timeout>=2.1", "gmsh>=4.11",
                 "mpi4py>=3.1"],
        "mpi": ["mpi4py>=3.1"],
        "cad": ["gmsh>=4.11"],
    },
    entry_points={"console_scripts": ["shellmesh=shellmesh_mdao.cli:main"]},
)
