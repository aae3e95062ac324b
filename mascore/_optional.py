"""Optional dependencies: imported where used, with a message that says which extra installs them.

The core (filters, consensus, graphs, closed forms) needs only numpy, scipy and networkx.
SDPs and LMIs need the ``sdp`` extra (cvxpy, Clarabel); figures, tables, the ledger and the
papers' scenarios the ``plot`` extra (matplotlib, pandas, tqdm); sweeps the ``compare`` extra
(dask.distributed).
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["EXTRAS", "require"]

#: Which extra of ``pip install 'mascore[EXTRA]'`` provides each optional top-level package.
EXTRAS = {
    "cvxpy": "sdp",
    "clarabel": "sdp",
    "matplotlib": "plot",
    "pandas": "plot",
    "tqdm": "plot",
    "dask": "compare",
    "distributed": "compare",
}


def require(module: str, purpose: str) -> ModuleType:
    """Import `module`, or raise an ImportError that names the extra to install.

    Parameters
    ----------
    module : str
        Dotted module name, e.g. ``"cvxpy"`` or ``"matplotlib.pyplot"``.
    purpose : str
        What needs it, for the message (e.g. ``"mascore.observers (the LMI of eq. (55))"``).

    Returns
    -------
    module
        The imported module.

    Raises
    ------
    ModuleNotFoundError
        If `module` (or one of its own dependencies) is not installed; the message says
        ``pip install 'mascore[EXTRA]'``.

    Examples
    --------
    >>> from mascore._optional import require
    >>> require("numpy", "this example").__name__
    'numpy'
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        top = (exc.name or module).split(".")[0]
        extra = EXTRAS.get(top) or EXTRAS.get(module.split(".")[0])
        hint = f"pip install 'mascore[{extra}]'" if extra else f"pip install {top}"
        raise ModuleNotFoundError(
            f"{purpose} needs the optional package {top!r}, which is not installed; install it with: {hint}",
            name=exc.name,
        ) from exc
