"""The cost of one node, one run, one thread (the whole team's step timed per node)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from .. import estimation
from .._validation import check_budget, check_positive_int, check_steps
from .benchmark import CORE_METHODS, SETTINGS, BenchmarkSettings, check_n_agents
from .team import simulate_team


def __getattr__(name: str):
    """``NODE_ORDER``: the leading-order work and memory per node and step of each team method (its spec's)."""
    if name == "NODE_ORDER":
        return {s.name: s.order["team"] for s in estimation.method_specs("team")}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# --------------------------------------------------------------------------------------------
# the cost of one node, one run, one thread

def node_cost(method: str, n_agents: int, n_steps: int = 20, repeats: int = 3, seed: int = 0,
              settings: BenchmarkSettings = SETTINGS) -> float:
    """CPU (µs) per step of the busiest node: one run, this thread only, the best of `repeats`.

    Not a batch of runs (batching amortizes Python's overhead over the runs and
    hides the algorithm): ``runs = 1``. The thread's CPU time does not count other
    BLAS threads, so pin them (``OMP_NUM_THREADS=1``, as the command line and the tests
    do). The busiest node of the whole-team filters runs the whole filter: the centre
    (``centralized``), or every agent, which computes the team's covariance itself
    (Song et al., Remark 4; our implementation computes it once for the team, so its
    whole cost is charged to each agent). For the per-agent filters the value is the
    team's CPU, an upper bound on one agent's: a node would make the same numpy calls
    on one agent, and at these sizes a call costs its overhead, not its flops, so
    dividing by N would report the batching, not the algorithm.

    Parameters
    ----------
    method : str
        One of :data:`TEAM_METHODS`.
    n_agents : int
        Team size N.
    n_steps : int
        Steps timed (the first, with the filters' set-up, included).
    repeats : int
        Runs timed; the smallest is kept (the least disturbed by other processes).
    seed : int
        Seed of the run.
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    float
        µs per step.

    See Also
    --------
    mascore.agent_cost.agent_step_cost : one agent's own work per step (its neighbours' messages given),
        for every task; the chapter's table.

    Examples
    --------
    >>> from mascore import compare
    >>> compare.node_cost("local", 8, n_steps=5) > 0
    True
    """
    n_steps = check_steps(n_steps)
    repeats = check_positive_int(repeats, "repeats")
    check_budget("repeats", repeats, n_steps, what="timed steps (repeats x n_steps)")
    short = replace(settings, n_steps=n_steps, steady_from=0)
    best = min(float(simulate_team(method, n_agents, seed, runs=1, settings=short)["cpu_s"][0])
               for _ in range(repeats))
    return 1e6 * best / short.n_steps


def node_costs(sizes: Sequence[int] = (4, 8, 16), methods: Sequence[str] = CORE_METHODS, n_steps: int = 20,
               settings: BenchmarkSettings = SETTINGS):
    """:func:`node_cost` over team sizes, with each method's log-log slope in N.

    Parameters
    ----------
    sizes : sequence of int
        Team sizes (a method is skipped beyond its spec's ``max_agents``: song-eb's covariance needs 0.5 GB at 64).
    methods : sequence of str
        Team methods.
    n_steps : int
        Steps timed per run.
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    pandas.DataFrame
        µs per step on the busiest node, one row per method, one column per N, ``slope`` (log-log
        in N) and the analytic ``work`` and ``memory`` orders of its spec (:data:`NODE_ORDER`).

    See Also
    --------
    mascore.agent_cost.agent_costs : one agent's cost over N = 4 ... 128 with slopes and analytic counts.

    Examples
    --------
    >>> from mascore import compare
    >>> t = compare.node_costs((4, 8), ("local",), n_steps=5)
    >>> list(t.columns)
    ['N = 4', 'N = 8', 'slope', 'work', 'memory']
    """
    import pandas as pd

    sizes = [check_n_agents(n) for n in sizes]
    if len(sizes) < 2:
        raise ValueError(f"sizes must hold at least two team sizes (a slope in N needs two); got {sizes!r}")
    methods = list(methods)
    if not methods:
        raise ValueError("methods must name at least one method of TEAM_METHODS; got none")
    n_steps = check_steps(n_steps)
    check_budget("n_steps", n_steps, len(sizes), len(methods), what="timed steps (n_steps x sizes x methods)")
    rows = {}
    for m in methods:
        largest = estimation.agent_limits("team").get(m, (np.inf,))[0]  # its spec's (song-eb's memory)
        costs = {n: node_cost(m, n, n_steps, settings=settings) for n in sizes if n <= largest}
        row = {f"N = {n}": costs.get(n, np.nan) for n in sizes}
        ns = sorted(costs)
        row["slope"] = float(np.polyfit(np.log(ns), np.log([costs[n] for n in ns]), 1)[0]) if len(ns) > 1 else np.nan
        row["work"], row["memory"] = estimation.method_spec(m, "team").order["team"]
        rows[m] = row
    return pd.DataFrame.from_dict(rows, orient="index")


def per_agent_costs(path: str | Path | None = None):
    """The committed snapshot of one agent's CPU per step (one run, one thread): the comparison's one CPU column.

    ``benchmarks/bench_agent_cost.py --snapshot`` measures it (:func:`mascore.agent_cost.agent_costs`
    over N = 4 ... 128, the median of 7 repeats, BLAS on one thread) and commits it beside the
    benchmarks; the headline tables (:func:`headline`), the cost figure (:func:`plot_cost`) and the
    chapter's cost page all read this one table, so their numbers agree.

    Parameters
    ----------
    path : str or pathlib.Path, optional
        The CSV (default: ``benchmarks/data/agent_cost.csv`` of the source checkout this package
        is imported from).

    Returns
    -------
    pandas.DataFrame
        :func:`mascore.agent_cost.agent_costs`' columns (``task, method, n_agents, us_per_step,
        flops, ...``).

    Raises
    ------
    FileNotFoundError
        No snapshot there (an installed package has none: measure with
        ``mascore.agent_cost.agent_costs``, or pass the path of a snapshot).

    Examples
    --------
    >>> from mascore import compare
    >>> costs = compare.per_agent_costs()                       # doctest: +SKIP
    >>> costs.set_index(["task", "method", "n_agents"]).loc[("team", "local", 8), "us_per_step"]  # doctest: +SKIP
    """
    import pandas as pd

    default = Path(__file__).resolve().parents[2] / "benchmarks" / "data" / "agent_cost.csv"
    where = default if path is None else Path(path)
    if not where.is_file():
        raise FileNotFoundError(f"no per-agent cost snapshot at {where} (python -m benchmarks.bench_agent_cost "
                                "--snapshot writes it; or measure with mascore.agent_cost.agent_costs)")
    return pd.read_csv(where)
