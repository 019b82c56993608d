"""Helpers that several stages share, with public names: compiled kernels used by more than one
stage, mesh topology (face rings), polylines and 2-D polygons, HiGHS calls, background threads.

A stage's own helpers live in the stage's module or subpackage; only what two or more stages use
is here, so no stage imports another stage's private names.
"""
