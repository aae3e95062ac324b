"""One module per paper: its registry (settings, runs, figures, tables, claims) and scenarios.

Each module declares ``REGISTRY`` (:class:`mascore.registry.PaperRegistry`),
which ``python -m mascore reproduce``, the book's chapters and the tests all
use, plus the scenario functions that the notebooks and tests call.
"""

from .._optional import require as _require

for _module in ("matplotlib", "pandas"):  # every paper draws figures and writes tables
    _require(_module, "mascore.papers (the papers' figures and tables)")
del _module
