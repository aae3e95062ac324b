"""The sweep: its named grids, one cell's runs, the summary with intervals, and the whole comparison's run."""

from __future__ import annotations

import contextlib
import functools
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from .. import estimation
from .._runstore import read_run, run_digest, write_run
from ..settings import check_settings_type
from ..sweep import Grid, cell_id, cell_seed
from .benchmark import (
    REN_Q,
    SEED_AXES,
    SETTINGS,
    SHOWN,
    VLAHAKIS_PHI,
    BenchmarkSettings,
    check_cell,
    check_cells,
    floats_per_step,
    mean_degree,
)
from .scenario import scenarios
from .shared import simulate_shared
from .summary import summarize
from .tables import fitted_slopes
from .target import (
    DIRECTION_LOSS_METHODS,
    LINK_STUDIES,
    SEND_ON_DELTA_METHODS,
    latency_methods,
    link_options,
    simulate_target,
    target_cost,
    target_methods,
)
from .team import simulate_team, vlahakis_profile
from .verdicts import compare_claims

# --------------------------------------------------------------------------------------------
# grids and cells

#: The largest team whose common-target or localization methods run together (:func:`cell_group`): their
#: data drawn once; a larger team's methods run apart, each a task of its own (a cluster balances them).
SHARED_DATA_MAX = 16

#: The team sizes and graphs of the full grid's scale study of the common-target and localization tasks.
SCALE_SIZES = (8, 16, 32, 64)
SCALE_GRAPHS = ("ring", "geometric", "switching")
#: Graphs that stop before the largest scale size, with the largest N and the reason.
SCALE_GRAPH_LIMITS = {"geometric": (32, "no layout of 64 agents in 1000 gives a connected proximity graph at the "
                                        "benchmark's mean degree (benchmark_graph): it would need a denser layout, "
                                        "and so another graph than at the smaller sizes")}


def grid_cells(name: str = "quick") -> list[dict[str, Any]]:
    """The cells of a named sweep: ``"quick"`` (the book, the tests) or ``"full"`` (the CLI).

    Both are unions of one-factor studies around the baseline (ring, Gaussian
    noise, no drop-out, correct Q): ``scaling`` over N (with the Vlahakis
    observer's coupling knob), ``graph`` (the geometric graph at N = 16, and 32
    in the full grid), ``dropout``, ``noise`` and ``wrong-q`` at N = 8, the
    ``shared`` task, the common-``target`` task and cooperative ``localization``
    (:func:`simulate_target`), and ``position``: the own-state task at N = 8 with
    position-only sensing (:data:`POSITION_METHODS`, with the set-membership filter's
    confidence knob, under Gaussian noise; the centralized, local and set-membership
    filters under uniform noise, where its bound is guaranteed);
    and the switching topology (:func:`switching_graphs`): the shared and target tasks at
    N = 16, the own state at N = 16 (study ``switching``, without the Vlahakis observers,
    :data:`SWITCHING_NOT_APPLICABLE`) and localization at N = 8 (quick: 2 blocks) and 16
    (full grid only); the set-membership filter on forwarded measurements (``sm-forwarding``) in the
    quick grid at N = 8 on the ring only; every knob of :data:`KNOBS` at each of its settings, at N = 8 on the ring
    (Ren et al.'s Q and the fusion filters' variants, :data:`FUSION_KNOB_METHODS`, in their task's
    study, Ren et al.'s also on the geometric and switching graphs of 16; the other Vlahakis gains in
    the scaling study at N = 8 only; 4 blocks in both grids, as the recipes beside them);
    each with ``blocks x settings.runs`` seeds (quick: 2 x 50, full: 4 x 50, N up to
    64), and 4 x 50 = 200 seeds in both grids for the headline cells (own state at
    N = 8, position sensing, the shared, target and localization tasks); and the links
    of the target and localization tasks at N = 8 on the ring (:data:`LINK_STUDIES`: ``loss``,
    ``loss-direction``, ``latency``, ``send-on-delta-<delta>``, ``lossy-send-on-delta-0.5``,
    ``late-send-on-delta-0.5``; a cell's
    ``dropout`` is the packet loss; quick: the target task only, a few methods; full: both tasks;
    4 blocks in both, :func:`_link_studies`). The full grid adds the
    scale study of both fusion tasks: every method at N in :data:`SCALE_SIZES` on every graph of
    :data:`SCALE_GRAPHS`, each up to the team size its spec allows
    (:func:`mascore.estimation.agent_limits`, with the reason).

    Parameters
    ----------
    name : {"quick", "full"}
        Which sweep.

    Returns
    -------
    list of dict
        One dictionary of coordinates per cell.

    Examples
    --------
    >>> from mascore.compare import grid_cells
    >>> len(grid_cells("quick")) < len(grid_cells("full"))
    True
    """
    if name not in ("quick", "full"):
        raise ValueError(f"name must be 'quick' or 'full'; got {name!r}")
    quick = name == "quick"
    blocks = [0, 1] if quick else [0, 1, 2, 3]
    blocks200 = [0, 1, 2, 3]  # the headline cells: 200 seeds in both grids
    sizes = [4, 16] if quick else [4, 16, 32, 64]
    base = {"task": ["team"], "graph": ["ring"], "noise": ["gaussian"], "dropout": [0.0], "q_scale": [1.0],
            "block": blocks}
    # the methods as their specs declare them now (a new filter module's included)
    team, core = list(estimation.method_names("team", SHOWN)), list(estimation.method_names("team", ("recipe",)))
    shared = list(estimation.method_names("shared", SHOWN))
    position = [m for m in estimation.method_names("team") if m not in estimation.not_applicable("position")]
    switching = [m for m in core if m not in estimation.not_applicable("switching")]
    # the quick grid runs the set-membership filter on forwarded measurements (a trace search per agent and step,
    # rebuilt at every step of a switching graph) at N = 8 on the ring only: the headline's cells; the full grid all
    skip = {"sm-forwarding": {"geometric", "switching", 16}} if quick else {}
    studies = [
        ("scaling", {**base, "method": team, "n_agents": [8], "block": blocks200}),
        ("scaling", {**base, "method": team, "n_agents": sizes}),
        ("graph", {**base, "method": core, "graph": ["geometric"], "n_agents": [16] if quick else [16, 32]}),
        ("dropout", {**base, "method": core, "n_agents": [8], "dropout": [0.1, 0.3]}),
        ("noise", {**base, "method": core, "n_agents": [8], "noise": ["uniform", "student-t"]}),
        ("wrong-q", {**base, "method": core, "n_agents": [8], "q_scale": [0.1, 10.0]}),
        ("shared", {**base, "task": ["shared"], "method": shared, "n_agents": [8],
                    "dropout": [0.0, 0.1, 0.3], "block": blocks200}),
        ("shared", {**base, "task": ["shared"], "method": shared, "n_agents": [16],
                    "graph": ["geometric", "switching"], "block": blocks200}),
        ("target", {**base, "task": ["target"], "method": list(target_methods("target")), "n_agents": [8, 16],
                    "block": blocks200}),
        ("target", {**base, "task": ["target"], "method": list(target_methods("target")),
                    "graph": ["geometric", "switching"],
                    "n_agents": [16], "block": blocks200}),
        ("localization", {**base, "task": ["localization"], "method": list(target_methods("localization")),
                          "n_agents": [8] if quick else [8, 16], "block": blocks200}),
        ("position", {**base, "sensing": ["position"], "method": position, "n_agents": [8],
                      "block": blocks200}),
        ("position", {**base, "sensing": ["position"], "method": ["centralized", "local", "set-membership"],
                      "noise": ["uniform"], "n_agents": [8], "block": blocks200}),
        # the switching topology (switching_graphs) for the own state and localization; the quick grid runs
        # localization at N = 8 only (at 16 covariance intersection's weight search costs 6 s of CPU per block)
        ("switching", {**base, "method": switching, "graph": ["switching"],
                       "n_agents": [16], "block": blocks if quick else blocks200}),
        ("localization", {**base, "task": ["localization"], "method": list(target_methods("localization")),
                          "graph": ["switching"], "n_agents": [8], "block": blocks if quick else blocks200}),
        # every knob swept within its recipe (KNOBS): at N = 8 on the ring, 200 seeds as the recipes beside them
        # (the claims that read a knob's settings are decided on the held-out blocks 2-3)
        ("scaling", {**base, "method": [m for m in VLAHAKIS_PHI if m not in team], "n_agents": [8],
                     "block": blocks200}),
        ("shared", {**base, "task": ["shared"], "method": [m for m in REN_Q if m not in shared],
                    "n_agents": [8], "block": blocks200}),
        ("shared", {**base, "task": ["shared"], "method": [m for m in REN_Q if m not in shared],
                    "n_agents": [16], "graph": ["geometric", "switching"], "block": blocks200}),
        *((task, {**base, "task": [task], "method": sorted(estimation.method_names(task, ("knob",))), "n_agents": [8],
                  "block": blocks200}) for task in ("target", "localization")),
    ]
    studies += _link_studies(quick, base, blocks200)
    if not quick:
        studies.append(("localization", {**base, "task": ["localization"], "method": list(target_methods("localization")),
                                         "graph": ["switching"], "n_agents": [16], "block": blocks200}))
        # scale: both fusion tasks at N = 8 to 64 on every graph (a method up to its spec's max_agents)
        studies += [(task, {**base, "task": [task], "method": list(target_methods(task)), "graph": list(SCALE_GRAPHS),
                            "n_agents": list(SCALE_SIZES), "block": blocks200}) for task in ("target", "localization")]
    limits = {task: estimation.agent_limits(task) for task in ("team", "shared", "target", "localization")}
    cells, seen = [], set()
    for study, axes in studies:
        for cell in Grid(axes).cells():
            if skip.get(cell["method"], set()) & {cell["graph"], cell["n_agents"]}:
                continue
            if cell["n_agents"] > limits.get(cell["task"], {}).get(cell["method"], (np.inf,))[0]:
                continue  # beyond the method's max_agents (its spec says why)
            if study in ("target", "localization") and cell["n_agents"] > SCALE_GRAPH_LIMITS.get(
                    cell.get("graph", "ring"), (np.inf,))[0]:
                continue  # beyond the graph's largest size (SCALE_GRAPH_LIMITS says why)
            cell = {"study": study, **cell}
            if cell_id(cell) not in seen:  # a scale cell the other studies already hold
                seen.add(cell_id(cell))
                cells.append(cell)
    for scenario in scenarios().values():  # the scenarios declared in their own modules, after the book's
        cells += [dict(c) for c in scenario.cells(name)]
    return cells


def _link_studies(quick: bool, base: dict, blocks200: list) -> list[tuple[str, dict]]:
    """The studies of the target and localization tasks over lossy, late and event-triggered links (N = 8, ring).

    Quick: the target task only, loss 0.1 and 0.3 for the bound, forwarding, CI and ICF at one step
    (a link lost in both directions at once, and each direction alone: ``loss-direction``); latency
    without loss (every method of :func:`~mascore.compare.latency_methods`: the claims' five on 4 blocks, the
    others on block 0);
    send-on-delta at 0.5 and 1. Full: both tasks, every method of :data:`LOSS_METHODS`
    at both losses (each direction alone: :data:`DIRECTION_LOSS_METHODS` but local), every method of
    :func:`~mascore.compare.latency_methods` late at loss 0, 0.1 and 0.3, and send-on-delta at 0.5, 1 and 2; send-on-delta
    at 0.5 with each message lost alone (``lossy-send-on-delta-0.5``), quick: at loss 0.3 on blocks 0-1
    (no claim reads it), full: at 0.1 and 0.3; send-on-delta at 0.5 with every message late
    (``late-send-on-delta-0.5``; quick: block 0).
    Both grids run 4 blocks (but that one): the link claims are written from blocks 0-1 and decided
    on 2-3 (:mod:`mascore.compare.verdicts`).
    """
    tasks = ["target"] if quick else ["target", "localization"]
    ring8 = {**base, "n_agents": [8], "block": blocks200}
    deltas = [s for s in LINK_STUDIES if s.startswith("send-on-delta")][:2 if quick else 3]
    out = []
    for task in tasks:
        loss_methods = ["centralized", "forwarding", "ci-L1", "icf-L1"] if quick else list(target_methods(task))
        late = latency_methods(task)
        out.append(("loss", {**ring8, "task": [task], "method": loss_methods, "dropout": [0.1, 0.3]}))
        out.append(("loss-direction", {**ring8, "task": [task], "method": [m for m in DIRECTION_LOSS_METHODS
                                                                           if m != "local"], "dropout": [0.1, 0.3]}))
        if quick:  # the claims' methods on 4 blocks; the others' latency on block 0 (no claim reads it: CPU)
            claimed = ["centralized", "local", "forwarding", "ci-L1", "icf-L1"]
            out.append(("latency", {**ring8, "task": [task], "method": claimed, "dropout": [0.0]}))
            out.append(("latency", {**ring8, "task": [task], "dropout": [0.0], "block": blocks200[:1],
                                    "method": [m for m in late if m not in claimed]}))
        else:
            out.append(("latency", {**ring8, "task": [task], "method": list(late),
                                    "dropout": [0.0, 0.1, 0.3]}))
        out += [(study, {**ring8, "task": [task], "method": list(SEND_ON_DELTA_METHODS)}) for study in deltas]
        out.append(("lossy-send-on-delta-0.5", {**ring8, "task": [task], "method": list(SEND_ON_DELTA_METHODS),
                                                "dropout": [0.3] if quick else [0.1, 0.3],
                                                "block": blocks200[:2] if quick else blocks200}))
        out.append(("late-send-on-delta-0.5", {**ring8, "task": [task], "method": list(SEND_ON_DELTA_METHODS),
                                               "block": blocks200[:1] if quick else blocks200}))
    return out


def run_cell(cell: Mapping[str, Any], base_seed: int = 0, settings: BenchmarkSettings = SETTINGS) -> list[dict[str, Any]]:
    """Run one cell of a sweep: one row of metrics per Monte Carlo run.

    Parameters
    ----------
    cell : mapping
        Coordinates ``study, task, method, n_agents, graph, noise, dropout, q_scale, block``
        (``graph`` may be left out: a ring), and for the team task optionally ``sensing``
        (:data:`SENSINGS`; left out: ``"full"``, and the cell's seed is that of before; any
        other sensing joins the seed axes).
    base_seed : int
        The sweep's seed.
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    list of dict
        Rows with ``run`` (index inside the block), the metrics of
        :func:`simulate_team` or :func:`simulate_shared` (those a task does not have are NaN),
        ``floats``, and ``sensing`` (the team task's; NaN for the others), so that every
        row of a sweep has the same columns.

    Examples
    --------
    >>> from mascore.compare import run_cell
    >>> rows = run_cell({"study": "scaling", "task": "team", "method": "local", "n_agents": 4,
    ...                  "noise": "gaussian", "dropout": 0.0, "q_scale": 1.0, "block": 0})
    >>> len(rows), sorted(rows[0])[:3]
    (50, ['containment', 'cpu_s', 'floats'])
    """
    check_cell(cell)
    check_settings_type(settings, BenchmarkSettings)
    return _run_cell(cell, base_seed, settings)


def _run_cell(cell: Mapping[str, Any], base_seed: int, settings: BenchmarkSettings) -> list[dict[str, Any]]:
    """:func:`run_cell` of a checked cell and settings."""
    sensing = cell.get("sensing", "full")
    seed = cell_seed(cell, SEED_AXES if sensing == "full" else (*SEED_AXES, "sensing"), base_seed)
    common = {"noise": cell["noise"], "dropout": float(cell["dropout"])}
    new = scenarios()
    if cell["task"] in ("target", "localization"):  # dropout: packet loss; the study: latency or send-on-delta
        metrics = simulate_target(cell["method"], int(cell["n_agents"]), seed, graph=cell.get("graph", "ring"),
                                  settings=settings, task=cell["task"], loss=float(cell["dropout"]),
                                  **link_options(cell.get("study", "")))
        nan = np.full_like(metrics["rmse_own"], np.nan)  # a set-membership filter has its containment and set size
        metrics.update({k: metrics.pop(k, nan) for k in ("rmse_view", "containment", "spread", "rmse_far", "set_size")})
    elif cell["task"] in new:  # a scenario declared in its own module
        metrics = dict(new[cell["task"]].simulate(cell["method"], int(cell["n_agents"]), seed, settings=settings,
                                                  graph=cell.get("graph", "ring"), **common))
        nan = np.full_like(metrics["rmse_own"], np.nan)
        for k in ("rmse_view", "containment", "spread", "rmse_far", "set_size", "nees_own", "cpu_s"):
            metrics.setdefault(k, nan)
    elif cell["task"] == "team":
        metrics = simulate_team(cell["method"], int(cell["n_agents"]), seed, q_scale=float(cell["q_scale"]),
                                graph=cell.get("graph", "ring"), settings=settings, sensing=sensing, **common)
    else:
        metrics = simulate_shared(cell["method"], int(cell["n_agents"]), seed, settings=settings,
                                  graph=cell.get("graph", "ring"), **common)
        metrics.update(rmse_view=np.full_like(metrics["rmse_own"], np.nan), containment=metrics["rmse_own"] * np.nan,
                       spread=metrics["rmse_own"] * np.nan, rmse_far=metrics["rmse_own"] * np.nan,
                       set_size=metrics["rmse_own"] * np.nan)
    degree = mean_degree(cell.get("graph", "ring"), int(cell["n_agents"]), settings)
    if cell["task"] in ("target", "localization"):
        floats = target_cost(cell["method"], int(cell["n_agents"]), degree, cell["task"])[0]
    elif cell["task"] in new:
        floats = float(new[cell["task"]].floats(cell["method"], int(cell["n_agents"]), degree))
    else:
        floats = floats_per_step(cell["method"], int(cell["n_agents"]), degree=degree, sensing=sensing)
    runs = len(metrics["rmse_own"])
    label = sensing if cell["task"] == "team" else float("nan")
    return [{"run": r, "floats": floats, "sensing": label, **{k: float(v[r]) for k, v in metrics.items()}}
            for r in range(runs)]


def cell_group(cell: Mapping[str, Any]) -> tuple | None:
    """The cells :func:`run_cells` runs together: a method's seed blocks of one cell.

    Parameters
    ----------
    cell : mapping
        A cell's coordinates (:func:`run_cell`).

    Returns
    -------
    tuple or None
        For the target and localization tasks, whose filters' covariances do not depend on the data
        (:func:`simulate_target`: one computation serves every block), ``(task, n_agents, graph)`` up to
        :data:`SHARED_DATA_MAX` agents: every method's blocks together, the target's path, the
        measurements and a switching graph's step models drawn and built once for all the methods (they
        do not depend on the method); ``(task, method, n_agents, graph)`` beyond (each method a task of
        its own: a cluster balances them). For the team task, ``("team", (coordinate, value), ...)``:
        every coordinate but the block (:func:`simulate_team` draws each block from its own seed's
        streams, and steps them as one batch). None for the other tasks and for lossy or late links
        (each cell alone).

    Examples
    --------
    >>> from mascore.compare import cell_group
    >>> cell_group({"task": "target", "method": "ci-L5", "n_agents": 8, "block": 2})
    ('target', 8, 'ring')
    >>> cell_group({"task": "target", "method": "ci-L5", "n_agents": 32, "block": 2})
    ('target', 'ci-L5', 32, 'ring')
    >>> cell_group({"task": "team", "method": "local", "n_agents": 8, "block": 2})
    ('team', ('method', 'local'), ('n_agents', 8), ('task', 'team'))
    """
    if cell.get("task") == "team":
        return ("team", *sorted((k, v) for k, v in cell.items() if k != "block"))
    if cell.get("task") not in ("target", "localization") or link_options(cell.get("study", "")) \
            or float(cell.get("dropout", 0.0)) > 0:
        return None  # lossy or late links draw their own streams per seed block: each cell alone
    if cell["n_agents"] <= SHARED_DATA_MAX:
        return (cell["task"], cell["n_agents"], cell.get("graph", "ring"))
    return (cell["task"], cell["method"], cell["n_agents"], cell.get("graph", "ring"))


def run_cells(cells: Sequence[Mapping[str, Any]], base_seed: int = 0,
              settings: BenchmarkSettings = SETTINGS) -> list[list[dict[str, Any]]]:
    """Run cells of one :func:`cell_group` together: each cell's rows, as :func:`run_cell` gives them.

    The seed blocks of a target or localization method run as one batch of their runs (each block's
    data from its own seed), so that the filter's covariances and weights, which do not depend on the
    data, are computed once, and the methods of a small team share each block's data (drawn once,
    :func:`cell_group`); so do a team-task cell's blocks (the loop's work per step, the filter's
    design and a covariance shared by the runs done once). Each block's rows are those of
    :func:`run_cell` on its cell, number for number, except ``cpu_s``, the block's share of the
    batch's CPU. Other cells run one by one.

    Parameters
    ----------
    cells : sequence of mapping
        Cells (:func:`run_cell`); for a batch, of one :func:`cell_group` key.
    base_seed : int
        The sweep's seed.
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    list of list of dict
        Each cell's rows, in the order of `cells`.

    Examples
    --------
    >>> from mascore.compare import run_cell, run_cells
    >>> cells = [{"study": "target", "task": "target", "method": "ci-L1", "n_agents": 8, "noise": "gaussian",
    ...           "dropout": 0.0, "q_scale": 1.0, "block": b} for b in (0, 1)]
    >>> together = run_cells(cells)
    >>> together[1][3]["rmse_own"] == run_cell(cells[1])[3]["rmse_own"]
    True
    """
    cells = check_cells(cells)
    check_settings_type(settings, BenchmarkSettings)
    keys = {cell_group(c) for c in cells}
    if len(cells) < 2 or None in keys:
        return [_run_cell(c, base_seed, settings) for c in cells]
    if len(keys) > 1:
        raise ValueError(f"cells must share one cell_group key to run together; got {sorted(keys, key=str)}")
    first = cells[0]
    if first["task"] == "team":
        return _team_blocks(cells, base_seed, settings)
    task, n_agents, graph = first["task"], int(first["n_agents"]), first.get("graph", "ring")
    degree = mean_degree(graph, n_agents, settings)
    memo: dict = {}  # the model, each block's data and a switching graph's step models, shared by the methods
    methods: dict[str, list[int]] = {}  # each method's cells (its blocks), in the order given
    for i, c in enumerate(cells):
        methods.setdefault(c["method"], []).append(i)
    out: list = [None] * len(cells)
    for method, idx in methods.items():
        seeds = [cell_seed(cells[i], SEED_AXES, base_seed) for i in idx]
        metrics = simulate_target(method, n_agents, seeds, graph=graph, settings=settings, task=task, memo=memo)
        nan = np.full_like(metrics["rmse_own"], np.nan)  # a set-membership filter has its containment and set size
        metrics.update({k: metrics.pop(k, nan) for k in ("rmse_view", "containment", "spread", "rmse_far",
                                                         "set_size")})
        floats = target_cost(method, n_agents, degree, task)[0]
        for i, rows in zip(idx, _block_rows(metrics, len(idx), floats, float("nan"))):
            out[i] = rows
    return out


def _team_blocks(cells: Sequence[Mapping[str, Any]], base_seed: int,
                 settings: BenchmarkSettings) -> list[list[dict[str, Any]]]:
    """The team-task cells of one :func:`cell_group` key (its seed blocks) as one :func:`simulate_team` batch."""
    first = cells[0]
    sensing = first.get("sensing", "full")
    axes = SEED_AXES if sensing == "full" else (*SEED_AXES, "sensing")
    graph = first.get("graph", "ring")
    metrics = simulate_team(first["method"], int(first["n_agents"]), [cell_seed(c, axes, base_seed) for c in cells],
                            noise=first["noise"], dropout=float(first["dropout"]), q_scale=float(first["q_scale"]),
                            graph=graph, settings=settings, sensing=sensing)
    floats = floats_per_step(first["method"], int(first["n_agents"]),
                             degree=mean_degree(graph, int(first["n_agents"]), settings), sensing=sensing)
    return _block_rows(metrics, len(cells), floats, sensing)


def _block_rows(metrics: dict[str, np.ndarray], blocks: int, floats: float,
                sensing: str | float) -> list[list[dict[str, Any]]]:
    """Each block's rows from the metrics of a batch of `blocks` equal blocks of runs (:func:`run_cell`'s columns).

    ``cpu_s``, the batch's CPU, becomes each block's share.
    """
    metrics = {**metrics, "cpu_s": metrics["cpu_s"] / blocks}
    runs = len(metrics["rmse_own"]) // blocks
    return [[{"run": r, "floats": floats, "sensing": sensing, **{k: float(v[b * runs + r]) for k, v in metrics.items()}}
             for r in range(runs)] for b in range(blocks)]


# --------------------------------------------------------------------------------------------
# the whole comparison: sweep, summary, claims, figures


def run_compare(
    grid: str = "quick",
    out: str | Path = "results",
    *,
    workers: int = 0,
    scheduler: str | None = None,
    seed: int = 0,
    progress: bool = True,
):
    """Run a named sweep (resuming), and return its table and summary.

    Parameters
    ----------
    grid : {"quick", "full"}
        The sweep (:func:`grid_cells`).
    out : str or pathlib.Path
        Results folder; the table goes to ``out/compare/table-GRID-SEED.csv`` (the whole result is
        stored and read back under its key, see :func:`run`).
    workers : int
        0: serially in this process; K: a local Dask cluster of K processes.
    scheduler : str, optional
        Address of a running Dask scheduler (overrides `workers`).
    seed : int
        The sweep's base seed.
    progress : bool
        Progress bar over cells.

    Returns
    -------
    table : pandas.DataFrame
        One row per Monte Carlo run and cell.
    summary : pandas.DataFrame
        :func:`summarize` of the table.

    Examples
    --------
    >>> import tempfile
    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", tempfile.mkdtemp(), progress=False)  # doctest: +SKIP
    """
    result = run(replace(SETTINGS, grid=grid), seed, progress, out=out, workers=workers, scheduler=scheduler)
    return result.table, result.summary


def scale_limits(task: str) -> dict[str, tuple[int, str]]:
    """Where the full grid's scale study of `task` stops before N = 64, and why: its methods' and its graphs' limits.

    Parameters
    ----------
    task : {"target", "localization"}
        The scenario.

    Returns
    -------
    dict of str to (int, str)
        ``"METHOD"`` or ``"GRAPH graph"`` -> (largest N run, why not beyond): the methods' from their
        specs (:func:`mascore.estimation.agent_limits`), the graphs' from :data:`SCALE_GRAPH_LIMITS`.

    Examples
    --------
    >>> from mascore.compare import scale_limits
    >>> scale_limits("localization")["ci-diffusion"][0], scale_limits("target")["geometric graph"][0]
    (32, 32)
    """
    if task not in ("target", "localization"):
        raise ValueError(f"task must be 'target' or 'localization'; got {task!r}")
    return {**estimation.agent_limits(task), **{f"{g} graph": v for g, v in SCALE_GRAPH_LIMITS.items()}}


def stored_summary(grid: str, out: str | Path = "results", seed: int = 0):
    """The summary a run of ``mascore compare --grid GRID`` stored under `out`, if there is one.

    Parameters
    ----------
    grid : str
        The sweep's name (``"quick"``, ``"full"`` or a grid file's).
    out : str or pathlib.Path
        The results folder of that run (its ``compare/summary-GRID-SEED.csv``).
    seed : int
        The sweep's base seed.

    Returns
    -------
    pandas.DataFrame or None
        :func:`summarize`'s table as stored, or None when no such run was stored.

    Examples
    --------
    >>> import tempfile
    >>> from mascore.compare import stored_summary
    >>> print(stored_summary("full", tempfile.mkdtemp()))
    None
    """
    import pandas as pd

    path = Path(out) / "compare" / f"summary-{grid}-{int(seed)}.csv"
    return pd.read_csv(path) if path.is_file() else None


@dataclass(frozen=True, eq=False)
class CompareResult:
    """The comparison's sweep, once: its table and summary (see :func:`run`).

    Parameters
    ----------
    settings : BenchmarkSettings
        The run's settings (``settings.grid`` is the sweep).
    seed : int
        The sweep's base seed.
    table : pandas.DataFrame
        One row per Monte Carlo run and cell.
    summary : pandas.DataFrame
        :func:`summarize` of the table on ideal links (every study but :data:`LINK_STUDIES`).
    slopes : dict
        Method -> fitted CPU slope in N (:func:`fitted_slopes`).
    phi : dict
        The Vlahakis program's value at fixed coupling gains on the ring of 8 (:func:`vlahakis_profile`).
    links : pandas.DataFrame or None
        :func:`link_summary` of the table: the studies over lossy, late and event-triggered links.
    claims : tuple of mascore.ledger.Claim
        :func:`mascore.compare.compare_claims` of the table (with `phi`): the comparison's ledger,
        decided once, when the sweep was summarized.

    Examples
    --------
    >>> from mascore.compare import CompareResult
    >>> sorted(CompareResult.__dataclass_fields__)[:3]
    ['claims', 'links', 'phi']
    """

    settings: BenchmarkSettings
    seed: int
    table: Any
    summary: Any
    slopes: dict
    phi: dict
    links: Any = None
    claims: tuple = ()


def run(settings: BenchmarkSettings = SETTINGS, seed: int = 0, progress: bool = False, *,
        out: str | Path | None = None, workers: int = 0, scheduler: str | None = None) -> CompareResult:
    """The comparison's study: the sweep ``settings.grid`` (resuming from `out`), its summary, slopes and gains.

    Parameters
    ----------
    settings : BenchmarkSettings
        The benchmark and the sweep (default :data:`SETTINGS`, the quick grid).
    seed : int
        The sweep's base seed (the published ledger's is 0).
    progress : bool
        Progress bar over cells.
    out : str or pathlib.Path, optional
        Results folder; the table goes to ``out/compare/table-GRID-SEED.csv`` and a later
        run resumes from it. The result is stored in ``out/compare/runs/`` under a key (the
        settings, the seed, the package's source and the table's bytes, as
        ``mascore.registry.Study.run_key``) and returned from there by a later call with the
        same key, neither swept nor summarized again. Only read folders you wrote yourself (a pickle).
        Default: a temporary folder (nothing is kept).
    workers : int
        0: serially in this process; K: a local Dask cluster of K processes.
    scheduler : str, optional
        Address of a running Dask scheduler (overrides `workers`).

    Returns
    -------
    CompareResult
        Everything the figures, tables and claims need.

    Examples
    --------
    >>> from mascore import compare
    >>> result = compare.run(seed=0)  # doctest: +SKIP
    >>> result.summary["study"].unique().tolist()  # doctest: +SKIP
    ['dropout', 'graph', 'noise', 'scaling', 'shared', 'wrong-q']
    """
    check_settings_type(settings, BenchmarkSettings)
    import tempfile

    from ..sweep import run_sweep

    if settings.grid not in ("quick", "full"):
        raise ValueError(f"settings.grid must be 'quick' or 'full'; got {settings.grid!r}")
    key = None if out is None else _stored_run_key(settings, seed, out)
    if key is not None:  # this very run, stored by an earlier call: read back, not swept and summarized again
        found, result = read_run(_stored_run_path(settings, seed, out), key)
        if found:
            return result
    # On Dask workers this process only waits for the sweep: it solves the Vlahakis programs meanwhile (they do
    # not depend on the sweep) in a thread of its own, rather than after the sweep with the workers idle.
    side = ThreadPoolExecutor(1, thread_name_prefix="mascore-compare") if workers or scheduler else None
    with side or contextlib.nullcontext(), tempfile.TemporaryDirectory(prefix="mascore-compare-") as scratch:
        profile = side.submit(vlahakis_profile, 8, settings=settings) if side else None
        folder = Path(scratch if out is None else out) / "compare"
        cells = grid_cells(settings.grid)
        costs = {cell_id(c): _cell_cost(c) for c in check_cells(cells, full=False)}  # one lookup of each task's methods
        table = run_sweep(cells, functools.partial(run_cells, base_seed=seed, settings=settings),
                          folder / f"table-{settings.grid}-{seed}.csv", workers=workers, scheduler=scheduler,
                          progress=progress, cost=lambda cell: costs[cell_id(cell)], group=cell_group)
    profile = profile.result() if profile is not None else vlahakis_profile(8, settings=settings)
    lossy = table["study"].isin(LINK_STUDIES)
    summary = summarize(table[~lossy], settings=settings)
    links = link_summary(table, settings) if lossy.any() else None
    claims = tuple(compare_claims(table, phi=profile))
    result = CompareResult(settings, int(seed), table, summary, fitted_slopes(summary), profile, links, claims)
    if out is not None:
        write_run(_stored_run_path(settings, seed, out), _stored_run_key(settings, seed, out), result)
    return result


def _stored_run_path(settings: BenchmarkSettings, seed: int, out: str | Path) -> Path:
    """Where :func:`run` stores its result under `out`: ``out/compare/runs/compare-GRID-SEED.pickle``."""
    return Path(out) / "compare" / "runs" / f"compare-{settings.grid}-{int(seed)}.pickle"


def _stored_run_key(settings: BenchmarkSettings, seed: int, out: str | Path) -> str | None:
    """The key of :func:`run`'s result: its settings, seed, the package's source and the sweep's table at `out`.

    As a paper's run key (``mascore.registry.Study.run_key``), plus the bytes of the table the
    result was summarized from (a table resumed, extended or deleted since gives another key).

    Returns
    -------
    str or None
        64 hexadecimal digits; None when `out` holds no table yet (no stored result can match).
    """
    table = Path(out) / "compare" / f"table-{settings.grid}-{int(seed)}.csv"
    if not table.is_file():
        return None
    kind = f"{type(settings).__module__}.{type(settings).__qualname__}"
    return run_digest(("compare", kind, settings, int(seed)), [table])


def link_summary(table, settings: BenchmarkSettings = SETTINGS):
    """:func:`summarize` of the studies over lossy, late and event-triggered links (:data:`LINK_STUDIES`) alone.

    They are summarized apart from the rest (:attr:`CompareResult.summary`), whose rows they would
    otherwise share on the coordinates the headline tables select by (task, N, ring, no drop-out).

    Parameters
    ----------
    table : pandas.DataFrame
        The sweep's per-run table (:func:`run_compare`'s first output).
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    pandas.DataFrame
        One row per link study, task, method and loss (``dropout``), as :func:`summarize`; each ratio is
        to the centralized filter of the same study and loss (it keeps ideal links).

    Examples
    --------
    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", "results", workers=2)  # doctest: +SKIP
    >>> compare.link_table(summary, compare.link_summary(table))  # doctest: +SKIP
    """
    import pandas as pd

    if not isinstance(table, pd.DataFrame) or "study" not in table:
        raise TypeError("table must be the sweep's per-run table (a pandas DataFrame with a 'study' column)")
    rows = table[table["study"].isin(LINK_STUDIES)]
    if rows.empty:
        raise ValueError(f"table has no row of the link studies {tuple(LINK_STUDIES)}: rerun the sweep (grid_cells)")
    return summarize(rows, settings=settings)


def cell_cost(cell: Mapping[str, Any]) -> float:
    """A rough relative run time of a cell, to start the longest cells first on a cluster.

    Parameters
    ----------
    cell : mapping
        Coordinates with ``task``, ``method``, ``n_agents`` and ``dropout``.

    Returns
    -------
    float
        Proportional to the flops of one step for a block of runs: the whole-team
        filters grow like ``N^3``-``N^4`` (and keep one covariance per run when links drop),
        the per-agent ones like ``N``.

    Examples
    --------
    >>> from mascore.compare import cell_cost
    >>> base = {"task": "team", "n_agents": 32, "dropout": 0.0}
    >>> cell_cost({**base, "method": "song-eb"}) > cell_cost({**base, "method": "local"})
    True
    """
    return _cell_cost(check_cell(cell, full=False))


def _cell_cost(cell: Mapping[str, Any]) -> float:
    """:func:`cell_cost` of a checked cell."""
    if cell["task"] in ("target", "localization"):  # per agent: n = 4, or n = 2N (N^3 flops a step)
        size = cell["n_agents"] / 8 if cell["task"] == "target" else (cell["n_agents"] / 8) ** 4
        return (1600.0 if cell["method"] == "ci-diffusion" else 150.0) * size  # ci: its weight search
    if cell["task"] != "team":
        return 1.0
    n = float(cell["n_agents"])
    whole_team = {"song-eb": n**4, "song-mb": n**3.5, "centralized": n**3}
    per_run = 20.0 if cell["dropout"] > 0 and cell["method"] in whole_team else 1.0
    return whole_team.get(cell["method"], 50.0 * n) * per_run
