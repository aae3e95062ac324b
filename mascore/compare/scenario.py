"""A scenario of the comparison declared in one module: its methods, its simulation, its cells and its cost.

The four scenarios of the book (``team``, ``shared``, ``target``, ``localization``) are
wired into :func:`~mascore.compare.run_cell` and :func:`~mascore.compare.grid_cells`
directly. Any other is one module of :mod:`mascore.compare` with a module-level
``SCENARIO``, a :class:`Scenario`: :func:`scenarios` finds it (the source is read, and
only a module that assigns ``SCENARIO`` is imported), the cell check accepts its
methods, :func:`~mascore.compare.run_cell` runs its cells,
:func:`~mascore.compare.grid_cells` adds its cells to the named sweeps and
:func:`~mascore.compare.headline` gives its table.
"""

from __future__ import annotations

import importlib
import pkgutil
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from .stats import NEES_DIMENSION

__all__ = ["Scenario", "scenarios", "reference_method", "nees_dimension"]

#: The scenarios wired in by hand (a module may not declare one of these names).
BUILT_IN = ("team", "shared", "target", "localization")
#: Names taken by the built-in scenarios' variants (the headline tables and the specs' ``not_applicable`` keys).
_RESERVED = (*BUILT_IN, "position", "switching")

#: The reference of a built-in task's ratios where it is not ``"centralized"``.
_REFERENCE = {"shared": "central-fusion"}


@dataclass(frozen=True)
class Scenario:
    """A scenario: what :func:`~mascore.compare.run_cell` and :func:`~mascore.compare.grid_cells` need of it.

    Parameters
    ----------
    task : str
        Its name, the cells' ``task`` coordinate.
    methods : callable
        ``methods()``: the names of its methods, in table order (e.g. read from the specs of the task).
    simulate : callable
        ``simulate(method, n_agents, seed, *, noise, dropout, graph, settings)``: per-run metrics, a dict of
        ``(runs,)`` arrays with at least ``rmse_own`` (and ``cpu_s``, ``nees_own`` where it has them).
    floats : callable
        ``floats(method, n_agents, degree)``: floats one agent sends per step.
    cells : callable
        ``cells(name)``: its cells of the sweep ``name`` (``"quick"`` or ``"full"``), each a dict of
        coordinates with ``study``.
    headline : mapping of str to object
        The coordinates of the cells of its headline table (default: N = 8, no drop-out, on the ring).
    reference : str
        The method whose RMSE every ratio of the scenario is taken against, run in the same cells (default
        ``"centralized"``): one of ``methods()``.
    nees_dimension : int, optional
        Dimension d of the state whose NEES ``simulate`` records as ``nees_own``, which is the NEES per
        degree of freedom (the NEES divided by d, averaged over the run's steps); the consistency verdicts
        use the chi-square bounds of d. None (default): no NEES, and no verdict.

    Examples
    --------
    >>> from mascore.compare.scenario import BUILT_IN, scenarios
    >>> [task for task in BUILT_IN if task in scenarios()]    # the book's four scenarios are built in
    []
    """

    task: str
    methods: Callable[[], tuple[str, ...]]
    simulate: Callable[..., dict[str, np.ndarray]]
    floats: Callable[[str, int, float], float]
    cells: Callable[[str], list[dict[str, Any]]]
    headline: Mapping[str, Any] = field(default_factory=lambda: {"n_agents": 8, "dropout": 0.0, "graph": "ring"})
    reference: str = "centralized"
    nees_dimension: int | None = None

    def __post_init__(self) -> None:
        if not (isinstance(self.task, str) and self.task) or self.task in _RESERVED:
            raise ValueError(f"task must be a new scenario's name (not one of {_RESERVED}); got {self.task!r}")
        if not (isinstance(self.reference, str) and self.reference):
            raise ValueError(f"reference of scenario {self.task!r} must be a method's name; got {self.reference!r}")
        d = self.nees_dimension
        if d is not None and (isinstance(d, bool) or not isinstance(d, (int, np.integer)) or d < 1):
            raise ValueError(f"nees_dimension of scenario {self.task!r} must be an integer >= 1 or None; got {d!r}")
        for attr in ("methods", "simulate", "floats", "cells"):
            if not callable(getattr(self, attr)):
                raise TypeError(f"{attr} of scenario {self.task!r} must be callable")
        object.__setattr__(self, "headline", MappingProxyType(dict(self.headline)))  # read-only: it is shared

    def __copy__(self) -> Scenario:  # immutable: a copy is itself (its mappings are read-only)
        return self

    def __deepcopy__(self, memo: dict) -> Scenario:
        return self

    def __hash__(self) -> int:  # one scenario per task
        return hash(self.task)


def scenarios() -> dict[str, Scenario]:
    """The scenarios declared by the modules of :mod:`mascore.compare` (a module-level ``SCENARIO``), by task.

    Returns
    -------
    dict of str to Scenario
        Task name -> its scenario (none in the package itself: the book's four are built in).

    Raises
    ------
    ValueError
        Two modules declare one task, or a scenario's reference is not one of its methods.

    Examples
    --------
    >>> from mascore.compare.scenario import scenarios
    >>> "target" in scenarios()                               # built in: not a module's
    False
    """
    from mascore import compare as package

    found: dict[str, Scenario] = {}
    for info in pkgutil.iter_modules(package.__path__):
        if info.name.startswith("_") or info.ispkg:
            continue
        name = f"{package.__name__}.{info.name}"
        module = sys.modules.get(name)
        if module is None:
            path = Path(getattr(info.module_finder, "path", "")) / f"{info.name}.py"
            try:
                source = path.read_bytes()
                if b"SCENARIO" not in source or _SCENARIO_LINE.search(source) is None:  # the plain search first
                    continue
            except OSError:
                pass
            module = importlib.import_module(name)
        scenario = getattr(module, "SCENARIO", None)
        if isinstance(scenario, Scenario):
            if scenario.task in found and found[scenario.task] is not scenario:
                raise ValueError(f"two modules declare the scenario {scenario.task!r} (one is {name})")
            if scenario.reference not in scenario.methods():
                raise ValueError(f"scenario {scenario.task!r} ({name}): its reference {scenario.reference!r}, which "
                                 f"every ratio is taken against, is not one of its methods {scenario.methods()}; "
                                 "name it with Scenario(..., reference=...)")
            found[scenario.task] = scenario
    return found


_SCENARIO_LINE = re.compile(rb"^SCENARIO\s*(?::[^=\n]*)?=", re.M)


def reference_method(task: str) -> str:
    """The method whose RMSE every ratio of `task` is taken against: its centralized filter, unless it says otherwise.

    Raises
    ------
    ValueError
        A task neither built in nor declared by a scenario module.

    Examples
    --------
    >>> from mascore.compare.scenario import reference_method
    >>> reference_method("target"), reference_method("shared")
    ('centralized', 'central-fusion')
    """
    if task in BUILT_IN:
        return _REFERENCE.get(task, "centralized")
    return _scenario(task).reference


def nees_dimension(task: str) -> int | None:
    """Dimension of the state whose NEES the cells of `task` record (None: no NEES recorded).

    Raises
    ------
    ValueError
        A task neither built in nor declared by a scenario module.

    Examples
    --------
    >>> from mascore.compare.scenario import nees_dimension
    >>> nees_dimension("target"), nees_dimension("localization")
    (4, 2)
    """
    if task in NEES_DIMENSION:
        return NEES_DIMENSION[task]
    return _scenario(task).nees_dimension


def _scenario(task: object) -> Scenario:
    """The scenario of a task that is not built in, or a clear refusal."""
    found = scenarios()
    if task not in found:
        raise ValueError(f"task must be one of {(*BUILT_IN, *found)}; got {task!r}")
    return found[task]
