"""The cost of one agent: one agent, one run, one thread, per step; beside its analytic flops and memory.

A batch of Monte Carlo runs over a whole team hides what one agent pays: NumPy's
per-call overhead is spread over the runs and the agents, and a per-agent filter
looks N times cheaper (or dearer) than it is. Here each method's step is cut down
to what **one agent** computes (:func:`agent_step`): for the per-agent filters,
agent i's prediction, its correction with its own and its neighbours' data, and
each of the L consensus rounds it performs, with the neighbours' messages handed
in as given arrays (the neighbours' own work is not timed); for the whole-team
filters, the whole filter's step (the centre of ``centralized``; every agent of
Song et al.'s estimation-based filter, which needs the joint covariance of all
agents' team estimates, their Remark 4). An agent of Song et al.'s
measurement-based filter runs a filter of the whole team on its own: its step is
that filter's (its team estimate and its own team covariance), not the N of them
that the batched implementation computes together.
:meth:`AgentStep.reference` gives agent i's numbers from the team-wide filter on
the same state, so the cut-down step is checked against the filter it stands for.

:func:`agent_step_cost` times the step on one thread (BLAS pinned to one thread
with ``threadpoolctl`` when it is installed; else set ``OMP_NUM_THREADS=1``, as
the Makefile does), the median of several repeats after a warm-up.
:func:`agent_costs` tabulates it over N with each method's log-log slope, beside
the analytic flops per agent and step (:func:`agent_flops`, from
:func:`mascore.fusion_cost.filter_cost` for the fusion filters) and the orders of
:data:`AGENT_ORDER`.

Tasks and methods (:data:`AGENT_METHODS`): the team task of
:mod:`mascore.compare` (own states of a rendezvous team, n = 4 per agent), the
common target (n = 4) and cooperative localization (n = 2N), each on the ring
(degree d = 2). The agent timed is agent 0 (on the ring every agent has the
same degree; in localization agent 0 is also an anchor, with two more
measurements: the busiest).
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from . import estimation
from ._validation import check_budget, check_positive_int
from .compare.benchmark import SETTINGS, BenchmarkSettings, check_n_agents
from .compare.target import localization_model, target_model
from .compare.team import make_estimator, team_setup

__all__ = [
    "AGENT_METHODS",  # noqa: F822 (read from the specs by the module's __getattr__)
    "AGENT_ORDER",  # noqa: F822 (read from the specs by the module's __getattr__)
    "AGENT_TASKS",
    "TEAM_METHODS",  # noqa: F822 (read from the specs by the module's __getattr__)
    "agent_methods",
    "MAX_AGENTS",  # noqa: F822 (read from the specs by the module's __getattr__)
    "WHOLE_FILTER",  # noqa: F822 (read from the specs by the module's __getattr__)
    "AgentStep",
    "agent_costs",
    "agent_flops",
    "agent_memory",
    "agent_step",
    "agent_step_cost",
    "blas_pinned",
    "max_deviation",
    "slopes",
]

#: Tasks whose per-agent cost is measured.
AGENT_TASKS = ("team", "target", "localization")
#: Longest timing (s of CPU, repeats x min_time) :func:`agent_step_cost` accepts.
_MAX_TIMING_S = 3600.0

def agent_methods(task: str) -> tuple[str, ...]:
    """The methods whose per-agent cost is measured in `task`, in table order.

    Parameters
    ----------
    task : {"team", "target", "localization"}
        The scenario (:data:`AGENT_TASKS`).

    Returns
    -------
    tuple of str
        The names of the task's :class:`mascore.estimation.MethodSpec` at their own recipe
        (``role="recipe"``; a new filter module's included): the knobs' other settings are the same
        filters, whose costs follow from the counts.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.agent_methods("target")[:3]
    ('centralized', 'local', 'forwarding')
    """
    if task not in AGENT_TASKS:
        raise ValueError(f"task must be one of {AGENT_TASKS}; got {task!r}")
    return estimation.method_names(task, ("recipe",))


def __getattr__(name: str):
    """``TEAM_METHODS``, ``AGENT_METHODS``, ``WHOLE_FILTER``, ``AGENT_ORDER`` and ``MAX_AGENTS``, read from the specs
    when asked."""
    if name == "TEAM_METHODS":  # the team task's methods timed: at their own recipe (agent_methods("team"))
        return agent_methods("team")
    if name == "AGENT_METHODS":  # methods per task
        return {t: agent_methods(t) for t in AGENT_TASKS}
    if name == "WHOLE_FILTER":  # (task, method) whose busiest agent runs the whole filter
        return {(t, m) for t in AGENT_TASKS for m in agent_methods(t) if estimation.method_spec(m, t).whole_filter}
    if name == "AGENT_ORDER":  # (task, method) -> (work, memory) per agent and step
        return {(t, m): estimation.method_spec(m, t).order[t] for t in AGENT_TASKS for m in agent_methods(t)}
    if name == "MAX_AGENTS":  # (task, method) -> the largest N timed, and why (the others go to 128)
        return {(t, m): limit for t in AGENT_TASKS for m, limit in estimation.agent_limits(t, step=True).items()}
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass
class AgentStep:
    """One agent's step of a method, ready to time, with the team-wide filter's numbers to check it against.

    Built by :func:`agent_step`; the fields are the parameters. A plain (mutable) record: its ``run``
    calls a filter's ``agent_step`` (see that filter's notes on threads).

    Parameters
    ----------
    task, method : str
        As asked.
    n_agents : int
        N.
    agent : int
        The agent whose step is timed (i).
    degree : int
        Its number of neighbours d.
    scope : {"one agent", "whole filter"}
        What :attr:`run` computes.
    run : callable
        ``run()`` computes the step once and returns agent i's result (a tuple of arrays: its
        estimate and covariance or shape matrix after the step; the filter's state for a
        whole filter). Its inputs (the agent's prior, its measurements, its neighbours' messages
        of each round) were prepared beforehand and are not timed; repeated calls do the same work.
    reference : callable or None
        ``reference()``: agent i's result from the team-wide filter on the same state (None for a
        whole filter, where the step *is* the team-wide filter).

    Examples
    --------
    >>> from mascore import agent_cost
    >>> step = agent_cost.agent_step("target", "ci-L5", 8)
    >>> step.scope, step.degree
    ('one agent', 2)
    >>> bool(agent_cost.max_deviation(step) < 1e-12)   # agent i's numbers of the team-wide filter
    True
    """

    task: str
    method: str
    n_agents: int
    agent: int
    degree: int
    scope: str
    run: Callable[[], tuple]
    reference: Callable[[], tuple] | None = field(default=None, repr=False)

def _check_task_method(task: object, method: object) -> None:
    """Refuse a task or a method of that task that this module does not know, by name."""
    methods = agent_methods(task)
    if method not in methods:
        raise ValueError(f"method must be one of {methods} for task {task!r}; got {method!r}")


# --------------------------------------------------------------------------------------------
# one agent's step


def agent_step(task: str, method: str, n_agents: int, *, agent: int = 0, seed: int = 0,
               settings: BenchmarkSettings = SETTINGS) -> AgentStep:
    """Agent `agent`'s work per step of `method`, cut out of one run of the scenario.

    The scenario's model is built (:func:`mascore.compare.target_model`,
    :func:`~mascore.compare.localization_model`, or the team task's filters), the
    team-wide filter is run two steps from a seeded random state (untimed), and agent
    i's inputs of the next step are taken from it: its prior, its own and its
    neighbours' measurements, and for each of the L consensus rounds the messages its
    neighbours send in that round.

    Parameters
    ----------
    task : {"team", "target", "localization"}
        The scenario (:data:`AGENT_TASKS`).
    method : str
        One of ``AGENT_METHODS[task]``.
    n_agents : int
        Team size N >= 3 (a ring).
    agent : int
        The agent i, ``0 <= i < N``.
    seed : int
        Seed of the state and measurements.
    settings : mascore.BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    AgentStep
        ``run()`` computes the step; ``reference()`` gives the team-wide filter's numbers for agent i.

    Raises
    ------
    ValueError
        An unknown task or method, a bad N or agent index.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agent_cost
    >>> step = agent_cost.agent_step("target", "ci-L5", 8)
    >>> x, P = step.run()                                  # agent 0: predict, correct, 5 consensus rounds
    >>> x_ref, P_ref = step.reference()                    # agent 0's row of the team-wide filter
    >>> bool(np.allclose(x, x_ref) and np.allclose(P, P_ref))
    True
    """
    _check_task_method(task, method)
    N = check_n_agents(n_agents)
    i = check_positive_int(agent, "agent", minimum=0)
    if i >= N:
        raise ValueError(f"agent must be an agent index below n_agents = {N}; got {agent!r}")
    seed = check_positive_int(seed, "seed", minimum=0)
    if task == "team":
        return _team_step(method, N, i, seed, settings)
    return _fusion_step(task, method, N, i, seed, settings)


def _team_step(method: str, N: int, i: int, seed: int, s: BenchmarkSettings) -> AgentStep:
    """The team task: the estimator of :mod:`mascore.compare` run two steps, then agent i's next step."""
    from .rendezvous import consensus_control

    team = team_setup(N, "gaussian", 1.0, s, "ring")
    rng = np.random.default_rng(seed)
    x = np.concatenate([s.init_pos * rng.standard_normal((1, N, 2)), s.init_vel * rng.standard_normal((1, N, 2))],
                       axis=-1)
    x_hat0 = x + np.sqrt(s.p0) * rng.standard_normal(x.shape)
    est = make_estimator(method, team, x_hat0)
    S = (team.adjacency > 0) | np.eye(N, dtype=bool)
    S = S[None]
    hood = np.flatnonzero(S[0, i])
    nbrs = hood[hood != i]

    def measure():
        return np.where(S[..., None], x[:, None] + np.sqrt(s.r) * rng.standard_normal((1, N, N, 4)), 0.0)

    def control(Z):
        view = est.views(Z, S)
        return consensus_control(np.broadcast_to(view, (1, N, N, 4)), team.laplacian, team.K)

    for _ in range(2):  # two steps of the team-wide estimator: a state that is not the initial one
        Z = measure()
        est.update(Z, S)
        U = control(Z)
        est.predict(U)
        x = x @ team.A.T + U @ team.B.T + np.sqrt(np.diag(team.Q)) * rng.standard_normal(x.shape)
    Z = measure()
    if estimation.method_spec(method, "team").whole_filter:
        U = control(Z)  # the inputs of the timed step (from the views before the update: the work is the same)
        own, messages = est.agent_inputs(Z, S, U, i)
        return AgentStep("team", method, N, i, len(nbrs), "whole filter", lambda: est.agent_step(i, own, messages))
    before = copy.deepcopy(est)  # agent i's prior, and the team's views of this step, from the same state
    est.update(Z, S)
    U = control(Z)
    est.predict(U)
    own, messages = before.agent_inputs(Z, S, U, i)
    return AgentStep("team", method, N, i, len(nbrs), "one agent", lambda: before.agent_step(i, own, messages),
                     lambda: est.agent_state(i))


def _fusion_step(task: str, method: str, N: int, i: int, seed: int, s: BenchmarkSettings) -> AgentStep:
    """The target and localization tasks: the method's filter run two steps, then its own ``agent_step`` for agent i.

    The inputs of agent i's step (its own data, its neighbours' messages of each round) are cut out of
    the team-wide filter by the filter's ``agent_inputs`` (untimed); the timed step is its ``agent_step``.
    """
    spec = estimation.method_spec(method, task)
    model = (target_model if task == "target" else localization_model)(N, "ring", s)
    filt = spec.build(model)
    n = model.n_states
    rng = np.random.default_rng(seed)
    _, z = model.simulate(np.zeros(n), s.p0 * np.eye(n), 3, rng)
    x, P = model.check_state(np.zeros(n), s.p0 * np.eye(n), per_agent=not spec.whole_filter)
    if not spec.whole_filter:
        x = x + np.sqrt(s.p0) * rng.standard_normal(x.shape)  # the agents start apart
    for k in range(2):
        x, P = filt.update(*filt.predict(x, P), z[k])
    own, messages = filt.agent_inputs(x, P, z[2], i)
    degree = int((model.adjacency[i] > 0).sum())

    def run():
        return filt.agent_step(i, own, messages)

    if spec.whole_filter:
        return AgentStep(task, method, N, i, degree, "whole filter", run)

    def reference():
        xr, Pr = filt.update(*filt.predict(x, P), z[2])
        return xr[i], Pr[i]

    return AgentStep(task, method, N, i, degree, "one agent", run, reference)


def max_deviation(step: AgentStep) -> float:
    """Largest absolute difference between the one-agent step and agent i's row of the team-wide filter.

    Parameters
    ----------
    step : AgentStep
        From :func:`agent_step`.

    Returns
    -------
    float
        ``max |run() - reference()|`` over the arrays returned (rounding: about 1e-15 relative);
        NaN for a whole filter, which has no separate reference.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> bool(agent_cost.max_deviation(agent_cost.agent_step("team", "song-mb", 6, agent=2)) < 1e-12)
    True
    """
    if not isinstance(step, AgentStep):
        raise TypeError(f"step must be an AgentStep (from agent_step); got {type(step).__name__}")
    if step.reference is None:
        return float("nan")
    return max(float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in zip(step.run(), step.reference()))


# --------------------------------------------------------------------------------------------
# timing


def blas_pinned() -> str:
    """How BLAS is held to one thread: ``"threadpoolctl"`` if installed, else the ``OMP_NUM_THREADS`` value.

    Returns
    -------
    str
        ``"threadpoolctl"``, or ``"OMP_NUM_THREADS=<value>"`` (``<unset>`` when not set: the timing may
        then use several BLAS threads and count only this thread's CPU).

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.blas_pinned().startswith(("threadpoolctl", "OMP_NUM_THREADS="))
    True
    """
    try:
        import threadpoolctl  # noqa: F401
    except ImportError:
        return f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', '<unset>')}"
    return "threadpoolctl"


def agent_step_cost(task: str, method: str, n_agents: int, *, repeats: int = 7, min_time: float = 0.02,
                    agent: int = 0, seed: int = 0,
                    settings: BenchmarkSettings = SETTINGS) -> float:
    """CPU time (µs) of one agent's step (:func:`agent_step`): one run, one thread, median of `repeats`.

    After one warm-up call, each repeat calls the step enough times to last about
    `min_time` seconds of this thread's CPU (``time.thread_time``) and keeps the
    time per call; the median of the repeats is returned (robust to other processes on
    the machine). BLAS is held to one thread by ``threadpoolctl`` when installed; else
    the caller must set ``OMP_NUM_THREADS=1`` (see :func:`blas_pinned`).

    Parameters
    ----------
    task, method, n_agents, agent, seed, settings
        As :func:`agent_step`.
    repeats : int
        Timed repeats (>= 1).
    min_time : float
        Seconds of CPU per repeat (at least one call).

    Returns
    -------
    float
        µs per step.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.agent_step_cost("target", "local", 4, repeats=3, min_time=0.001) > 0
    True
    """
    repeats = check_positive_int(repeats, "repeats")
    if not (isinstance(min_time, (int, float)) and np.isfinite(min_time) and min_time >= 0):
        raise ValueError(f"min_time must be a finite number of seconds >= 0; got {min_time!r}")
    if repeats * min_time > _MAX_TIMING_S:
        raise ValueError(f"min_time: repeats x min_time = {repeats * min_time:.3g} s of timing is more than an hour "
                         f"({_MAX_TIMING_S:g} s); ask for fewer repeats or a shorter min_time")
    check_budget("repeats", repeats, what="timed repeats")
    step = agent_step(task, method, n_agents, agent=agent, seed=seed, settings=settings)
    with _one_thread():
        tic = time.thread_time()
        step.run()  # warm-up (and the cost of one call, to choose the number of calls per repeat)
        once = max(time.thread_time() - tic, 1e-7)
        number = max(1, int(min_time / once))
        samples = []
        for _ in range(repeats):
            tic = time.thread_time()
            for _ in range(number):
                step.run()
            samples.append((time.thread_time() - tic) / number)
    return 1e6 * float(np.median(samples))


class _one_thread:
    """``threadpoolctl.threadpool_limits(1)`` when installed; else nothing (OMP_NUM_THREADS must be 1)."""

    def __enter__(self):
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:
            self._ctx = None
            return self
        self._ctx = threadpool_limits(1)
        self._ctx.__enter__()
        return self

    def __exit__(self, *exc):
        if self._ctx is not None:
            self._ctx.__exit__(*exc)
        return False


# --------------------------------------------------------------------------------------------
# analytic counts


def agent_flops(task: str, method: str, n_agents: int, degree: int = 2) -> float:
    """Analytic floating-point operations of one agent per step (leading terms; a multiply-add is 2).

    Each method's spec counts them (``MethodSpec.cost``). The fusion filters
    (target and localization) count as :func:`mascore.fusion_cost.filter_cost` (n = 4, q = 1;
    localization n = 2N, q = 2d). The team task counts the textbook
    algorithm at n = 4: a Kalman step ``4 n^3`` (prediction) plus ``26/3 n^3`` (information
    update); forwarding one more inverse; the Vlahakis observer ``2 n^2 + 4 d``; Song et
    al.'s measurement-based filter one agent's own team covariance (dimension Nn, with its
    (d + 1) n measurements), the estimation-based one the joint covariance of all N team
    estimates (dimension N^2 n) predicted densely; the centralized filter N filters of n states
    (the own state separates: the inputs are known).

    Parameters
    ----------
    task : {"team", "target", "localization"}
        The scenario.
    method : str
        One of ``AGENT_METHODS[task]``.
    n_agents : int
        N.
    degree : int
        d (2 on the ring).

    Returns
    -------
    float
        Flops per step of the busiest agent.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.agent_flops("team", "song-eb", 16) / agent_cost.agent_flops("team", "song-eb", 8)  # O(N^6)
    64.0
    """
    _check_task_method(task, method)
    N = check_positive_int(n_agents, "n_agents")
    d = check_positive_int(degree, "degree", minimum=0)
    n, q = _dimensions(task, N, d)
    return float(estimation.method_spec(method, task).cost(n, q, d, N)[1])


def agent_memory(task: str, method: str, n_agents: int, degree: int = 2) -> float:
    """Floats one agent holds per step (its estimate, covariance and the messages of one round; leading terms).

    Parameters
    ----------
    task, method, n_agents, degree
        As :func:`agent_flops`.

    Returns
    -------
    float
        Floats (x 8 bytes).

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.agent_memory("team", "song-eb", 8) / agent_cost.agent_memory("team", "song-eb", 4)  # O(N^4)
    16.0
    """
    _check_task_method(task, method)
    N = check_positive_int(n_agents, "n_agents")
    d = check_positive_int(degree, "degree", minimum=0)
    n, q = _dimensions(task, N, d)
    spec = estimation.method_spec(method, task)
    return float(spec.memory(n, q, d, N)) if spec.memory else float("nan")


def _dimensions(task: str, n_agents: int, degree: int) -> tuple[int, int]:
    """State size n and measurements per agent q: team (4, 4: its own full state), target (4, 1), localization (2N, 2d)."""
    return {"team": (4, 4), "target": (4, 1)}.get(task, (2 * n_agents, 2 * degree))


# --------------------------------------------------------------------------------------------
# the table


def _order(task: str, method: str) -> tuple[str, str]:
    """The order of one agent's work and memory per step (the method's spec)."""
    return estimation.method_spec(method, task).order[task]


def _whole_filter(task: str, method: str) -> bool:
    return estimation.method_spec(method, task).whole_filter


def agent_costs(sizes: Sequence[int] = (4, 8, 16, 32, 64, 128), tasks: Sequence[str] = AGENT_TASKS,
                methods: Sequence[str] | None = None, *, repeats: int = 7, min_time: float = 0.02,
                settings: BenchmarkSettings = SETTINGS, progress: bool = False):
    """:func:`agent_step_cost` over team sizes, with log-log slopes and the analytic counts.

    Parameters
    ----------
    sizes : sequence of int
        Team sizes N (each >= 3). A method is measured up to its spec's limit for one step
        (:func:`mascore.estimation.agent_limits` with ``step=True``; ``MAX_AGENTS``).
    tasks : sequence of str
        Tasks (:data:`AGENT_TASKS`).
    methods : sequence of str, optional
        Methods (default: every method of each task); a method not in a task is skipped.
    repeats, min_time : int, float
        As :func:`agent_step_cost`.
    settings : mascore.BenchmarkSettings
        The benchmark's settings.
    progress : bool
        Print each measurement as it is made.

    Returns
    -------
    pandas.DataFrame
        One row per (task, method, N): ``us_per_step`` (NaN beyond the method's limit),
        ``flops`` (:func:`agent_flops`), ``memory_floats`` (:func:`agent_memory`), ``scope``,
        ``work`` and ``memory`` (the orders of :data:`AGENT_ORDER`), ``stops_at`` and ``why``.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> t = agent_cost.agent_costs((4, 8), ("target",), ("local",), repeats=3, min_time=0.001)
    >>> t[["task", "method", "n_agents"]].values.tolist()
    [['target', 'local', 4], ['target', 'local', 8]]
    """
    import pandas as pd

    for name, value in (("sizes", sizes), ("tasks", tasks), ("methods", methods)):
        if isinstance(value, (str, bytes)) or not (value is None and name == "methods"
                                                   or isinstance(value, (Sequence, np.ndarray))):
            raise TypeError(f"{name} must be a sequence (a list or a tuple); got {value!r}")
    if not sizes:
        raise ValueError("sizes must name at least one team size N")
    sizes = [check_n_agents(n) for n in sizes]
    for task in tasks:
        if task not in AGENT_TASKS:
            raise ValueError(f"tasks must be among {AGENT_TASKS}; got {task!r}")
    known_any = {m for task in tasks for m in agent_methods(task)}
    unknown = [m for m in (methods or ()) if m not in known_any]
    if unknown:
        raise ValueError(f"methods {unknown} are not methods of the tasks {tuple(tasks)}: one of {sorted(known_any)}")
    rows = []
    for task in tasks:
        known, limits = agent_methods(task), estimation.agent_limits(task, step=True)
        for m in (known if methods is None else [m for m in methods if m in known]):
            limit, why = limits.get(m, (max(sizes), ""))
            for N in sizes:
                us = agent_step_cost(task, m, N, repeats=repeats, min_time=min_time, settings=settings) \
                    if N <= limit else np.nan
                if progress:
                    print(f"{task:13s} {m:15s} N = {N:4d}: {us:12.1f} us", flush=True)
                work, mem = _order(task, m)
                rows.append({"task": task, "method": m, "n_agents": N, "us_per_step": us,
                             "flops": agent_flops(task, m, N), "memory_floats": agent_memory(task, m, N),
                             "scope": "whole filter" if _whole_filter(task, m) else "one agent",
                             "work": work, "memory": mem, "stops_at": min(limit, max(sizes)),
                             "why": why if limit < max(sizes) else ""})  # the reason where the limit is reached
    return pd.DataFrame(rows)


def slopes(table, top: int | None = None):
    """Log-log slopes in N of the measured time and of the analytic flops, per (task, method).

    Parameters
    ----------
    table : pandas.DataFrame
        :func:`agent_costs`' table.
    top : int, optional
        Fit only the `top` largest measured N (default: all), where flops outweigh the per-call overhead.

    Returns
    -------
    pandas.DataFrame
        Index ``(task, method)``; ``slope`` (measured), ``flops_slope`` (analytic, same N), ``measured_to`` (largest N).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import agent_cost
    >>> t = pd.DataFrame({"task": "team", "method": "x", "n_agents": [4, 8], "us_per_step": [1.0, 8.0],
    ...                   "flops": [1.0, 4.0]})
    >>> agent_cost.slopes(t)[["slope", "flops_slope"]].values.tolist()
    [[3.0, 2.0]]
    """
    import pandas as pd

    if top is not None and check_positive_int(top, "top") < 2:
        raise ValueError(f"top must be at least 2 (a slope needs two team sizes); got {top!r}")
    out = {}
    for (task, method), g in table.groupby(["task", "method"], sort=False):
        g = g.dropna(subset=["us_per_step"]).sort_values("n_agents")
        if top is not None:
            g = g.tail(int(top))
        out[(task, method)] = {"slope": _slope(g["n_agents"], g["us_per_step"]),
                               "flops_slope": _slope(g["n_agents"], g["flops"]),
                               "measured_to": int(g["n_agents"].max()) if len(g) else 0}
    result = pd.DataFrame.from_dict(out, orient="index")
    result.index = pd.MultiIndex.from_tuples(result.index, names=["task", "method"])
    return result


def _slope(n, y) -> float:
    """Least-squares slope of log y on log n (NaN with fewer than two points)."""
    n, y = np.asarray(n, float), np.asarray(y, float)
    return float(np.polyfit(np.log(n), np.log(y), 1)[0]) if len(n) > 1 else float("nan")
