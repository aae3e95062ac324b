"""One module per paper, holding the exact scenarios of its figures and tables.

Each module exposes ``reproduce(out_dir, seed) -> list[Claim]`` (see
:mod:`mascore.reproduce`) plus the scenario functions that the notebooks and
tests call.
"""
