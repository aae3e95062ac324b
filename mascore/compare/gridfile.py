"""A sweep of your own: the comparison's cells read from a TOML file (``mascore compare --grid FILE.toml``).

The file names the Monte Carlo runs per cell, the seed blocks, and one or more studies; each
study gives the axes of its cells (a value or a list of values). Axes left out take the
baseline's values: a ring, Gaussian noise, no drop-out, the correct process noise.

.. code-block:: toml

    runs = 20            # Monte Carlo runs per cell and seed block
    blocks = [0, 1]      # seed blocks: each block draws its own runs

    [[study]]
    name = "my-target"   # a label for the cells of this study
    task = "target"      # team, shared, target or localization
    method = ["centralized", "ci-L1", "hcmci-L5", "icf-L5"]
    n_agents = [8, 12]
    graph = ["ring", "geometric"]

    [[study]]
    name = "my-team"
    task = "team"
    method = ["centralized", "local", "song-mb"]
    n_agents = 10
    dropout = [0.0, 0.2]

Every cell is checked before anything runs (:func:`read_grid`), so a misspelt method or graph
is named with the choices at once, and so is a team too large for a method (its spec's
``max_agents``) or for memory. A study named as one of the link studies of the comparison
(``"latency"``, ``"send-on-delta-0.5"``, ...: :data:`~mascore.compare.LINK_STUDIES`) runs its cells over those
links, and its methods are checked for them too. Every study includes the reference of its ratios, the
centralized filter (``central-fusion`` on the shared task): it is added where a study leaves it out.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .. import estimation
from .._validation import STEP_BUDGET, check_positive_int
from ..sweep import Grid
from .benchmark import SETTINGS, check_run
from .scenario import reference_method
from .target import check_link_cell

__all__ = ["GridFile", "read_grid"]

#: The axes a study of a grid file may set, and the baseline's value of each.
AXES: dict[str, Any] = {"task": None, "method": None, "n_agents": None, "graph": "ring", "noise": "gaussian",
                        "dropout": 0.0, "q_scale": 1.0, "sensing": "full"}


@dataclass(frozen=True)
class GridFile:
    """A grid read from a TOML file.

    Parameters
    ----------
    name : str
        The file's stem (``my_grid`` for ``my_grid.toml``): the name of its table and summary.
    runs : int
        Monte Carlo runs per cell and seed block.
    cells : tuple of dict
        The cells, checked (:func:`mascore.compare.check_cell`), each with its ``study`` and ``block``.
    """

    name: str
    runs: int
    cells: tuple[dict[str, Any], ...]

    @property
    def settings(self):
        """The comparison's settings with this file's runs per cell (:class:`mascore.compare.BenchmarkSettings`)."""
        import dataclasses

        return dataclasses.replace(SETTINGS, runs=self.runs)


def read_grid(path: str | Path) -> GridFile:
    """Read and check a grid file (the format is in the module's text).

    Parameters
    ----------
    path : str or pathlib.Path
        A ``.toml`` file.

    Returns
    -------
    GridFile
        Its name, runs per cell and checked cells.

    Raises
    ------
    ValueError
        The file is missing or not TOML, a key is unknown, or a cell names a task, method,
        graph, noise or team size that does not exist (the message names the study and the choices).

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from mascore.compare.gridfile import read_grid
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "mine.toml"
    >>> _ = path.write_text('runs = 5\\n[[study]]\\nname = "t"\\ntask = "target"\\n'
    ...                     'method = ["centralized", "ci-L1"]\\nn_agents = [8, 12]\\n')
    >>> grid = read_grid(path)
    >>> grid.name, grid.runs, len(grid.cells)
    ('mine', 5, 4)
    >>> grid.cells[0]["graph"], grid.cells[0]["block"]
    ('ring', 0)
    """
    path = Path(path)
    if path.suffix != ".toml" or not path.is_file():
        raise ValueError(f"grid must be 'quick', 'full' or an existing .toml file; got {str(path)!r}")
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"{path}: not a TOML file ({exc})") from None
    unknown = set(data) - {"runs", "blocks", "study"}
    if unknown:
        raise ValueError(f"{path}: unknown keys {sorted(unknown)}; a grid file has runs, blocks and [[study]] tables")
    runs = check_positive_int(data.get("runs", SETTINGS.runs), f"{path}: runs", minimum=2)
    blocks = _values(data.get("blocks", [0]), f"{path}: blocks")
    for b in blocks:
        check_positive_int(b, f"{path}: blocks", minimum=0)
    studies = data.get("study")
    if not isinstance(studies, list) or not studies:
        raise ValueError(f"{path}: no [[study]] table (each names a task, methods and team sizes)")
    cells, limits = [], {}
    spec_tasks = {t for spec in estimation.method_specs() for t in spec.tasks}  # a scenario's task has no specs
    for k, study in enumerate(studies):
        where = f"{path}: study {study.get('name', k + 1)!r}"
        unknown = set(study) - set(AXES) - {"name"}
        if unknown:
            raise ValueError(f"{where}: unknown axes {sorted(unknown)}; the axes are {sorted(AXES)}")
        missing = [a for a, default in AXES.items() if default is None and a not in study]
        if missing:
            raise ValueError(f"{where}: missing {missing} (every study names its task, methods and team sizes)")
        axes = {a: _values(study.get(a, default), f"{where}: {a}") for a, default in AXES.items()}
        axes["method"] = _with_reference(axes["method"], axes["task"])
        for cell in Grid({**axes, "block": blocks}).cells():
            cell = check_link_cell({"study": str(study.get("name", f"study-{k + 1}")), **cell}, where)
            task = cell["task"]
            if task not in limits:
                limits[task] = estimation.agent_limits(task) if task in spec_tasks else {}
            _check_size(cell, runs, where, limits[task])
            cells.append(cell)
    steps = runs * SETTINGS.n_steps * len(cells)
    if steps > STEP_BUDGET:
        raise ValueError(f"{path}: {len(cells)} cells x {runs} runs x {SETTINGS.n_steps} steps = {steps:.3g} "
                         f"simulated steps is beyond the budget of {STEP_BUDGET:.3g}; fewer cells or runs")
    return GridFile(path.stem, runs, tuple(cells))


def _with_reference(methods: list, tasks: list) -> list:
    """`methods` with the reference of a study's one task first (the ratios' denominator), if it is missing."""
    if len(tasks) != 1 or not isinstance(tasks[0], str):
        return methods  # a study of several tasks names each one's methods itself
    try:
        ref = reference_method(tasks[0])
    except ValueError:  # an unknown task: the cell check names it, with the file and the study
        return methods
    return methods if ref in methods else [ref, *methods]


def _check_size(cell: dict, runs: int, where: str, limits: dict) -> None:
    """Refuse up front a cell whose team is beyond its method's limit (`limits`: its task's
    :func:`mascore.estimation.agent_limits`) or beyond memory."""
    limit = limits.get(cell["method"])
    if limit is not None and cell["n_agents"] > limit[0]:
        raise ValueError(f"{where}: {cell['method']} runs teams of at most {limit[0]} agents in the comparison "
                         f"({limit[1]}); got n_agents = {cell['n_agents']}")
    try:
        check_run(cell["n_agents"], cell["noise"], cell["dropout"], cell["q_scale"], runs, SETTINGS)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _values(value: Any, name: str) -> list:
    values = value if isinstance(value, list) else [value]
    if not values:
        raise ValueError(f"{name}: an empty list; give a value or a list of values")
    return values
