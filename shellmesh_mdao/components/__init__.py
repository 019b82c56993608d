"""OpenMDAO wrappers of the pipeline stages, one component per file (OpenAeroStruct style).

Each component calls the same core function as the CLI stage of the same name
(:mod:`shellmesh_mdao.pipeline`). The components arrive with the OpenMDAO issue; until
then this package holds none.
"""
