"""Progress bars for long runs, in one place.

``tqdm.auto`` draws a widget in Jupyter when ``ipywidgets`` is installed and a
text bar otherwise; without ``ipywidgets`` it warns on import ("IProgress not
found"), which would land in every rendered notebook that imports a module
using it. Importing it here, lazily and with that warning silenced, keeps the
book clean and the package importable without tqdm's notebook extras.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import TypeVar

__all__ = ["progress_bar"]

T = TypeVar("T")


def progress_bar(iterable: Iterable[T], enabled: bool = True, **tqdm_kwargs) -> Iterable[T]:
    """Wrap `iterable` in a tqdm progress bar when `enabled`; return it unchanged otherwise.

    Parameters
    ----------
    iterable : iterable
        What to iterate over.
    enabled : bool
        Draw the bar (default) or not.
    **tqdm_kwargs
        Passed to ``tqdm`` (``desc``, ``unit``, ``leave``, ...).

    Returns
    -------
    iterable
        The tqdm wrapper, or `iterable` itself when disabled or when tqdm is not installed
        (the bar is a convenience: the core runs without it).
    """
    if not enabled:
        return iterable
    try:
        from tqdm import TqdmWarning
    except ModuleNotFoundError:  # tqdm is in the `plot` extra: without it, no bar
        return iterable

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TqdmWarning)
        from tqdm.auto import tqdm
    return tqdm(iterable, **tqdm_kwargs)
