"""The benchmark's settings, its named constants, its graphs and the checks of a cell's arguments."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import estimation, graphs
from .._validation import (
    MAX_STEPS,
    check_budget,
    check_fits_in_memory,
    check_positive,
    check_positive_int,
    check_probability,
    check_seed,
)
from ..settings import check_settings, check_settings_type, setting

#: The roles of the methods in the headline tables and at every team size: the recipes and their shown variants.
SHOWN = ("recipe", "variant")
#: Sensing/communication graphs: a ring, or the proximity graph of a random layout.
GRAPHS = ("ring", "geometric")
#: Graphs of the common-target and shared tasks: the fixed ones, and a switching proximity topology.
SWITCHING_GRAPHS = (*GRAPHS, "switching")
#: Noise distributions, all with the covariance of the settings.
NOISES = ("gaussian", "uniform", "student-t")
#: Coordinates that choose a cell's random numbers (not the method, drop-out or q_scale: common random numbers).
SEED_AXES = ("task", "n_agents", "noise", "block")
#: What an agent of the team task measures of itself and its neighbours: the full state (Song et al. eq. (2)),
#: or the position only, ``z_ij = [I 0] x_j + nu_ij`` (a cell without a ``sensing`` coordinate is ``"full"``;
#: ``"position"`` joins the seed axes, so the cells of before keep their seeds).
SENSINGS = ("full", "position")
def _team_methods() -> tuple[str, ...]:
    shown = estimation.method_names("team", SHOWN)
    return shown + tuple(m for m in estimation.method_names("team") if m not in shown)


#: The names read from the methods' specs when asked (:func:`mascore.estimation.method_specs`: always current,
#: a new filter module's included; importing this module imports no filter): ``TEAM_METHODS``, the estimators of
#: the team task in table order; ``CORE_METHODS``, those at their own recipe (the figures'); ``ALL_TEAM_METHODS``,
#: with the knobs' settings (run at N = 8 in the studies ``scaling``, ``position``); ``POSITION_METHODS``, those
#: that apply under position-only sensing; ``POSITION_NOT_APPLICABLE`` and ``SWITCHING_NOT_APPLICABLE``, the
#: others with the reason; ``VLAHAKIS_PHI``, the Vlahakis observer's coupling gain per method (None: the LMI's
#: choice; -0.1 and 1 are the ends of the interval where its program's value is optimal on the ring of 8,
#: :func:`vlahakis_profile`); ``SM_CONFIDENCE``, the set-membership filter's confidence level per method (None:
#: ``settings.sm_confidence``; bounded noise: the guaranteed bound); ``SHARED_METHODS``, the shared task's at
#: their recipe and Ren et al.'s untuned Q = 0; ``ALL_SHARED_METHODS``, with the knob's settings; ``REN_Q``,
#: Ren et al.'s Q = Omega per method; ``FUSION_KNOB_METHODS``, the common-target and localization filters' knob
#: settings (``role="knob"``, by name; e.g. the consensus steps L = 2 and the graph's diameter beside the recipes'
#: L = 1 and 5, HCMCI's consistency-safe omega beside omega = N, the KCF's gain eps = 0.01 and 0.5 beside 0.1),
#: swept at N = 8 on the ring (2 seed blocks) while the headline tables keep the recipes; ``KNOBS``, every knob
#: swept within its recipe (:class:`Knob`).
_FROM_SPECS = {
    "TEAM_METHODS": lambda: estimation.method_names("team", SHOWN),
    "CORE_METHODS": lambda: estimation.method_names("team", ("recipe",)),
    "ALL_TEAM_METHODS": _team_methods,
    "POSITION_NOT_APPLICABLE": lambda: estimation.not_applicable("position"),
    "SWITCHING_NOT_APPLICABLE": lambda: estimation.not_applicable("switching"),
    "POSITION_METHODS": lambda: tuple(m for m in estimation.method_names("team")
                                      if m not in estimation.not_applicable("position")),
    "VLAHAKIS_PHI": lambda: estimation.knob_settings("vlahakis", "team"),
    "SM_CONFIDENCE": lambda: estimation.knob_settings("set-membership", "team"),
    "SHARED_METHODS": lambda: estimation.method_names("shared", SHOWN),
    "ALL_SHARED_METHODS": lambda: estimation.method_names("shared"),
    "REN_Q": lambda: estimation.knob_settings("ren-kc", "shared"),
    "FUSION_KNOB_METHODS": lambda: tuple(sorted({m for task in ("target", "localization")
                                                 for m in estimation.method_names(task, ("knob",))})),
    "KNOBS": lambda: _knobs(),
}


def __getattr__(name: str):
    if name in _FROM_SPECS:
        return _FROM_SPECS[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


#: Largest initial spread or noise std (m, m/s) the benchmark accepts: the squared errors stay far from overflow.
_MAX_SCALE = 1e6


@dataclass(frozen=True)
class BenchmarkSettings:
    """The common benchmark's settings (one place; the chapter shows them).

    Every field is checked when the settings are built or ``dataclasses.replace``-d
    (``mascore.settings.check_settings``): counts >= 1, variances and scales finite
    and non-negative (at most 1e6 m or m/s for the scales, 1e12 for the variances).

    Parameters
    ----------
    dt : float
        Sampling time (s).
    n_steps : int
        Steps per run of the team task.
    steady_from : int
        First step of the window over which the steady-state metrics are averaged.
    q_pos, q_vel : float
        Process-noise variance per step of each position and velocity entry (m², m²/s²).
    r : float
        Measurement-noise variance of each measured entry (m² or m²/s²).
    rho : tuple of float
        Rendezvous gain ``K = [rho_1 I, rho_2 I]`` (Song et al. eq. (4)).
    init_pos, init_vel : float
        Standard deviations of the initial positions (m) and velocities (m/s).
    p0 : float
        Initial estimation-error variance of every state entry (filters' ``P_0``).
    sensing_range, mean_degree : float
        The ``"geometric"`` graph: the proximity graph of range ``sensing_range``
        over a random layout in a square sized for this expected number of
        neighbours (see :func:`benchmark_graph`).
    sm_confidence : float
        Probability mass of the ellipsoid given to the set-membership filter as the
        noise bound when the noise is not bounded (Gaussian, Student-t).
    shared_steps : int
        Steps of the shared-quantity task.
    shared_var : tuple of float
        Range of the agents' prior variances in the shared task (m²), drawn log-uniformly.
    runs : int
        Monte Carlo runs per cell (one block of seeds).
    grid : {"quick", "full"}
        The sweep :func:`run` makes (:func:`grid_cells`): ``"quick"`` for the book and the
        published ledger, ``"full"`` for the command line.


    Examples
    --------
    >>> from mascore.compare import SETTINGS
    >>> SETTINGS.dt, SETTINGS.n_steps
    (0.1, 150)
    """

    dt: float = setting(0.1, source="chosen", unit="s", note="sampling time", low=0, low_open=True)
    n_steps: int = setting(150, source="chosen", note="steps per run of the team task", low=1, high=MAX_STEPS)
    steady_from: int = setting(75, source="chosen", note="first step of the steady-state window", low=0)
    q_pos: float = setting(1e-4, source="chosen", unit="m²", note="process-noise variance per position entry",
                           low=0, high=_MAX_SCALE**2)
    q_vel: float = setting(1e-4, source="chosen", unit="m²/s²", note="process-noise variance per velocity entry",
                           low=0, high=_MAX_SCALE**2)
    r: float = setting(0.01, source="chosen", note="measurement-noise variance of each measured entry",
                       low=0, low_open=True, high=_MAX_SCALE**2)
    rho: tuple[float, float] = setting((0.5, 1.5), source="chosen", where="Song et al. eq. (4)",
                                       note="rendezvous gain K = [rho_1 I, rho_2 I]", length=2, low=0, low_open=True)
    init_pos: float = setting(5.0, source="chosen", unit="m", note="std of the initial positions",
                              low=0, high=_MAX_SCALE)
    init_vel: float = setting(1.0, source="chosen", unit="m/s", note="std of the initial velocities",
                              low=0, high=_MAX_SCALE)
    p0: float = setting(1.0, source="chosen", note="initial estimation-error variance of every state entry",
                        low=0, low_open=True, high=_MAX_SCALE**2)
    sm_confidence: float = setting(0.997, source="chosen", note="probability mass of the set-membership bound",
                                   low=0, low_open=True, high=1, high_open=True)
    sensing_range: float = setting(1.0, source="chosen", unit="m", note="range of the geometric graph",
                                   low=0, low_open=True)
    mean_degree: float = setting(4.0, source="chosen", note="expected neighbours of the geometric graph",
                                 low=0, low_open=True)
    shared_steps: int = setting(30, source="chosen", note="steps of the shared-quantity task", low=1,
                                high=MAX_STEPS)
    shared_var: tuple[float, float] = setting((0.5, 5.0), source="chosen", unit="m²",
                                              note="range of the prior variances of the shared task",
                                              length=2, low=0, low_open=True)
    runs: int = setting(50, source="chosen", note="Monte Carlo runs per cell", low=1)
    grid: str = setting("quick", source="chosen", note="the sweep run makes", choices=("quick", "full"))

    def __post_init__(self) -> None:
        check_settings(self)
        if self.steady_from >= self.n_steps:
            raise ValueError(f"BenchmarkSettings.steady_from must be a step before n_steps ({self.n_steps}); "
                             f"got {self.steady_from}")
        if self.shared_var[0] > self.shared_var[1]:
            raise ValueError(f"BenchmarkSettings.shared_var must be a range (low, high) with low <= high; "
                             f"got {self.shared_var}")


#: The settings used by the chapter and the CLI (the study's settings, :data:`STUDY`).
SETTINGS = BenchmarkSettings()


@dataclass(frozen=True)
class Knob:
    """One method's knob, swept within its recipe: its settings, each a method of the sweep.

    Parameters
    ----------
    name : str
        The knob, as the chapter names it (e.g. ``"Ren et al.'s Q = Omega"``).
    task : {"team", "target", "localization", "shared"}
        The scenario it is swept on.
    settings : tuple of (str, str, str)
        ``(setting, study, method)`` per setting: the setting's label, the study of the sweep that
        holds its cells (N = 8, ring, no drop-out) and the method name of that setting.
    recipe : tuple of str
        The labels of the paper's own settings (those of the headline tables).

    Examples
    --------
    >>> from mascore.compare import KNOBS
    >>> [s for s, _, _ in KNOBS[0].settings]
    ['0', '0.1', '0.3', '0.6', '1']
    """

    name: str
    task: str
    settings: tuple[tuple[str, str, str], ...]
    recipe: tuple[str, ...]


def _fusion_knob(name: str, family: str, task: str, default: str = "diameter") -> Knob:
    """The knob of the fusion filter `family` in `task`, from its specs: its settings by value (None: `default`, last)."""
    specs = sorted((s for s in estimation.method_specs(task) if s.family == family),
                   key=lambda s: (s.setting is None, s.setting or 0.0))

    def label(spec: estimation.MethodSpec) -> str:
        return default if spec.setting is None else f"{spec.setting:g}"
    return Knob(name, task, tuple((label(s), task, s.name) for s in specs),
                tuple(label(s) for s in specs if s.role == "recipe"))


def _knobs() -> tuple[Knob, ...]:
    """Every knob swept within its recipe (the chapter's knob table, :func:`knob_table`), from the specs.

    A fusion filter's knob not named here (a new filter's) is listed under its family's name, with its
    specs' :attr:`~mascore.estimation.MethodSpec.knob`.
    """
    ren, phi = estimation.knob_settings("ren-kc", "shared"), estimation.knob_settings("vlahakis", "team")
    confidence = estimation.knob_settings("set-membership", "team")
    fusion = (
        *(_fusion_knob(f"{label}: consensus steps L", kind, task) for task in ("target", "localization")
          for kind, label in (("ci", "CI"), ("icf", "ICF"), ("hcmci", "HCMCI"))),
        *(Knob(f"HCMCI novelty weight omega (L = {L})", task, (("N", task, f"hcmci-L{L}"),
                                                              *(("safe", task, m) for m in estimation.knob_settings(
                                                                  f"hcmci-L{L}", task))), ("N",))
          for task in ("target", "localization") for L in (1, 5)),
        *(_fusion_knob("KCF consensus gain eps", "kcf", task) for task in ("target", "localization")),
    )
    named = {method for knob in fusion for _, _, method in knob.settings}
    new = {(s.family, task): s.knob for task in ("target", "localization")
           for s in estimation.method_specs(task) if s.role == "knob" and s.name not in named}
    return (
        Knob("Ren et al.'s Q = Omega", "shared", tuple((f"{q:g}", "shared", m) for m, q in sorted(
            ren.items(), key=lambda kv: kv[1])), ("0.1",)),
        Knob("Vlahakis's coupling gain Phi", "team", tuple(
            ("LMI" if p is None else f"{p:g}", "scaling", m) for m, p in phi.items()), ("LMI",)),
        Knob("set-membership confidence (positions only)", "team", tuple(
            (f"{SETTINGS.sm_confidence if c is None else c:g}", "position", m)
            for m, c in sorted(confidence.items(), key=lambda kv: SETTINGS.sm_confidence if kv[1] is None else kv[1])),
            (f"{SETTINGS.sm_confidence:g}",)),
        *fusion,
        *(_fusion_knob(f"{family}: {knob or 'setting'}", family, task, "default") for (family, task), knob in new.items()),
    )


def knob_variants() -> tuple[str, ...]:
    """The methods of every knob setting other than its paper's own (:data:`KNOBS`): not recommendations.

    Returns
    -------
    tuple of str
        Method names, e.g. ``"ren-kc-q0.6"`` or ``"hcmci-safe-L5"``.

    Examples
    --------
    >>> from mascore.compare import knob_variants
    >>> "ren-kc-q0.6" in knob_variants(), "ren-kc" in knob_variants()
    (True, False)
    """
    return tuple(sorted({method for knob in _knobs() for label, _, method in knob.settings if label not in knob.recipe}))


def benchmark_graph(kind: str, n_agents: int, settings: BenchmarkSettings = SETTINGS) -> np.ndarray:
    """The benchmark's sensing and communication graph, fixed during a run.

    Parameters
    ----------
    kind : {"ring", "geometric"}
        ``"ring"``: each agent senses its two ring neighbours. ``"geometric"``: the
        proximity graph (range ``settings.sensing_range``) of ``n_agents`` points
        drawn uniformly in a square whose side gives ``settings.mean_degree``
        expected neighbours; the layout is drawn from a seed fixed by ``n_agents``
        (the first connected one), so every cell and method of a sweep sees the same graph.
    n_agents : int
        Team size N >= 3.
    settings : BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    (N, N) ndarray
        Symmetric 0/1 adjacency of a connected graph.

    Examples
    --------
    >>> from mascore import compare, graphs
    >>> A = compare.benchmark_graph("geometric", 16)
    >>> graphs.is_connected(A), A.shape
    (True, (16, 16))
    """
    check_settings_type(settings, BenchmarkSettings)
    n_agents = check_n_agents(n_agents)
    if kind == "ring":
        return graphs.ring_graph(n_agents)
    if kind != "geometric":
        raise ValueError(f"kind must be one of {GRAPHS}; got {kind!r}")
    side = np.sqrt(n_agents * np.pi * settings.sensing_range**2 / settings.mean_degree)
    for attempt in range(1000):
        layout = np.random.default_rng([n_agents, attempt]).uniform(0.0, side, (n_agents, 2))
        A = graphs.proximity_graph(layout, settings.sensing_range)
        if graphs.is_connected(A):
            return A
    raise ValueError(f"no connected geometric graph of {n_agents} agents in 1000 layouts; raise mean_degree")


def switching_graphs(n_agents: int, n_steps: int, settings: BenchmarkSettings = SETTINGS) -> np.ndarray:
    """A switching proximity topology: the disk graphs of agents wandering in a square, one per step.

    The agents start as the ``"geometric"`` layout's square (sized for ``settings.mean_degree``
    expected neighbours) and each moves by a random walk of step ``0.1 settings.sensing_range``
    per step, reflected at the walls; the graph at step k links the agents closer than
    ``settings.sensing_range``. It is often disconnected at one step and connected over a few
    (the joint connectivity of Ren et al.'s and Song et al.'s switching-graph theorems). The
    walk's seed is fixed by `n_agents`, so every cell and method sees the same graphs.

    Parameters
    ----------
    n_agents : int
        Team size N >= 3.
    n_steps : int
        Steps (graphs).
    settings : BenchmarkSettings
        ``sensing_range`` and ``mean_degree``.

    Returns
    -------
    (n_steps, N, N) ndarray
        Symmetric 0/1 adjacencies.

    Examples
    --------
    >>> from mascore import compare
    >>> G = compare.switching_graphs(16, 30)
    >>> G.shape, bool((G != G[0]).any())
    ((30, 16, 16), True)
    """
    n_agents = check_n_agents(n_agents)
    n_steps = check_positive_int(n_steps, "n_steps")
    side = np.sqrt(n_agents * np.pi * settings.sensing_range**2 / settings.mean_degree)
    rng = np.random.default_rng([n_agents, 7919])
    p = rng.uniform(0.0, side, (n_agents, 2))
    out = np.empty((n_steps, n_agents, n_agents))
    for k in range(n_steps):
        out[k] = graphs.proximity_graph(p, settings.sensing_range)
        p = p + 0.1 * settings.sensing_range * rng.standard_normal(p.shape)
        p = np.abs(p)
        p = side - np.abs(side - p)  # reflect at 0 and at the side
    return out


def mean_degree(kind: str, n_agents: int, settings: BenchmarkSettings) -> float:
    if kind == "switching":
        return float(switching_graphs(n_agents, settings.n_steps, settings).sum(-1).mean())
    return float(benchmark_graph(kind, n_agents, settings).sum(1).mean())


def floats_per_step(method: str, n_agents: int, degree: float = 2.0, sensing: str = "full") -> float:
    """Floats one agent sends per step, by method (the communication cost): its spec's count.

    Parameters
    ----------
    method : str
        A method of the team task (:data:`ALL_TEAM_METHODS`) or of the shared one (:data:`ALL_SHARED_METHODS`).
    n_agents : int
        Team size N.
    degree : float
        Number of neighbours of the agent (2 on a ring; the mean degree of another graph).
    sensing : {"full", "position"}
        What a measurement holds (:data:`SENSINGS`): with positions only, a measurement
        is 2 floats instead of 4 (``centralized``: ``2 (degree + 1)`` up and
        ``4 (degree + 1)`` down; ``forwarding``: ``2 degree + 4``).

    Returns
    -------
    float
        ``centralized``: its measurements up, ``4 (degree + 1)``, plus the
        estimates it needs down, ``4 (degree + 1)``, counted once at each end;
        ``local``, ``vlahakis`` (every gain of :data:`VLAHAKIS_PHI`), ``set-membership``: one broadcast
        of the own estimate (4; Vlahakis's coupling uses its output part); ``forwarding``: each
        neighbour's measurement sent to that neighbour (``4 degree``) plus the broadcast estimate;
        ``song-mb``, ``song-eb``: 0 (they sense, they do not talk);
        Ren et al.'s Kalman consensus at every Q (:data:`REN_Q`): the estimate and its covariance (2 + 3);
        ``average-consensus``: 2; ``central-fusion``: 5 up, 2 down; ``no-fusion``: 0.

    Examples
    --------
    >>> from mascore.compare import floats_per_step
    >>> floats_per_step("centralized", 8), floats_per_step("song-eb", 8)
    (24.0, 0.0)
    >>> floats_per_step("centralized", 8, sensing="position"), floats_per_step("forwarding", 8, sensing="position")
    (18.0, 8.0)
    """
    check_n_agents(n_agents)
    degree = check_positive(degree, "degree", "(mean neighbours per agent)")
    if sensing not in SENSINGS:
        raise ValueError(f"sensing must be one of {SENSINGS}; got {sensing!r}")
    specs = estimation.method_specs()  # one scan of the package
    team = {s.name: s for s in specs if "team" in s.tasks}
    shared = {s.name: s for s in specs if "shared" in s.tasks}
    if method not in team and method not in shared:
        raise ValueError(f"method must be one of {tuple(team) + tuple(shared)}; got {method!r}")
    if method in shared:  # a 2-D quantity: n = q = 2
        return float(shared[method].cost(2, 2, degree, n_agents)[0])
    why = team[method].not_applicable.get("position")
    if sensing == "position" and why is not None:
        raise ValueError(f"method {method!r} does not apply under position-only sensing: {why}")
    measured = 4 if sensing == "full" else 2  # z_ij = x_j + nu_ij, or its position [I 0] x_j + nu_ij
    return float(team[method].cost(4, measured, degree, n_agents)[0])


def check_n_agents(n_agents: object) -> int:
    """A team size N >= 3 whose team covariances (a few (4N, 4N) arrays) fit in memory."""
    n_agents = check_positive_int(n_agents, "n_agents", minimum=3)
    check_fits_in_memory(8.0 * 4 * (4 * n_agents) ** 2, "n_agents", "a few of the team's (4N, 4N) covariances")
    return n_agents


def check_run(n_agents: object, noise: object, dropout: object, q_scale: object, runs: object,
               settings: BenchmarkSettings, seed: object = 0) -> tuple[int, int]:
    """The arguments of a simulation, checked: ``(n_agents, runs)``."""
    if not isinstance(seed, np.random.SeedSequence):
        check_seed(seed, "seed")
    check_settings_type(settings, BenchmarkSettings)
    n_agents = check_n_agents(n_agents)
    if noise not in NOISES:
        raise ValueError(f"noise must be one of {NOISES}; got {noise!r}")
    if check_probability(dropout, "dropout") >= 1.0:
        raise ValueError("dropout must be below 1 (every link lost at every step leaves nothing to compare)")
    check_positive(q_scale, "q_scale", "(the filters' Q over the true Q)")
    runs = check_positive_int(settings.runs if runs is None else runs, "runs")
    check_budget("runs", runs, settings.n_steps, n_agents, what="agent-steps (runs x BenchmarkSettings.n_steps x N)")
    # the team filters hold (runs, N, N, 4) views and up to (runs, 4N, 4N) covariances at once
    check_fits_in_memory(8.0 * runs * (n_agents**2 * 4 * 8 + (4 * n_agents) ** 2 * 3), "runs",
                         "the estimates and covariances of one step")
    return n_agents, runs


# --------------------------------------------------------------------------------------------
# noise


def check_cell(cell: object, name: str = "cell", full: bool = True) -> Mapping[str, Any]:
    """A cell of the grid, checked: its task, method, team size, drop-out and (`full`) noise and q_scale."""
    return _check_cell(cell, name, full, None)


def check_cells(cells: Sequence[object], full: bool = True) -> list[Mapping[str, Any]]:
    """:func:`check_cell` of every cell, each task's methods looked up once (each lookup scans the package)."""
    known: dict[str, tuple[str, ...]] = {}
    for cell in cells:
        task = cell.get("task") if isinstance(cell, Mapping) else None
        if isinstance(task, str) and task not in known:
            known.update(_methods_of(task))
    return [_check_cell(cell, "cell", full, known) for cell in cells]


def _check_cell(cell: object, name: str, full: bool, known: Mapping[str, tuple[str, ...]] | None) -> Mapping[str, Any]:
    """:func:`check_cell`, with the methods of the tasks in `known` given (None: looked up)."""
    if not isinstance(cell, Mapping):
        raise TypeError(f"{name} must be a mapping of the cell's coordinates (task, method, n_agents, noise, "
                        f"dropout, q_scale); got {type(cell).__name__}")
    task = cell.get("task")
    # the cell's task's methods only: each lookup scans the package
    methods_of = {task: known[task]} if known and isinstance(task, str) and task in known else _methods_of(task)
    if task not in methods_of:
        raise ValueError(f"{name}['task'] must be one of {tuple(methods_of)}; got {task!r}")
    required = ("method", "n_agents", "dropout") + (("noise",) if full else ()) + (
        ("q_scale",) if full and task == "team" else ())
    missing = [k for k in required if k not in cell]
    if missing:
        raise ValueError(f"{name} lacks the coordinates {missing} (a {task} cell needs {list(required)})")
    if cell["method"] not in methods_of[task]:
        raise ValueError(f"{name}['method'] of a {task} cell must be one of {methods_of[task]}; got {cell['method']!r}")
    check_positive_int(cell["n_agents"], f"{name}['n_agents']", minimum=3)
    if "noise" in cell and cell["noise"] not in NOISES:
        raise ValueError(f"{name}['noise'] must be one of {NOISES}; got {cell['noise']!r}")
    if check_probability(cell["dropout"], f"{name}['dropout']") >= 1.0:
        raise ValueError(f"{name}['dropout'] must be below 1; got {cell['dropout']!r}")
    if task == "team" and "q_scale" in cell:
        check_positive(cell["q_scale"], f"{name}['q_scale']")
    if cell.get("graph", "ring") not in SWITCHING_GRAPHS:
        raise ValueError(f"{name}['graph'] of a {task} cell must be one of {SWITCHING_GRAPHS}; "
                         f"got {cell.get('graph')!r}")
    if task == "team" and cell.get("graph") == "switching" and cell["method"] in estimation.not_applicable("switching"):
        raise ValueError(f"{name}: {cell['method']} does not apply on the switching graph "
                         "(SWITCHING_NOT_APPLICABLE)")
    sensing = cell.get("sensing", "full")
    if sensing not in SENSINGS or (task != "team" and sensing != "full"):
        raise ValueError(f"{name}['sensing'] must be one of {SENSINGS} (a team cell; other tasks have their own "
                         f"sensing model); got {sensing!r} for a {task} cell")
    why = estimation.not_applicable("position").get(cell["method"]) if sensing == "position" else None
    if why is not None:
        raise ValueError(f"{name}['method'] {cell['method']!r} does not apply under position-only sensing: {why}")
    return cell


def _methods_of(task: object) -> dict[str, tuple[str, ...]]:
    """``{task: its method names}`` for a known `task`, else every task's (for the message naming them)."""
    from .scenario import scenarios

    fixed = ("team", "shared", "target", "localization")
    if isinstance(task, str) and task in fixed:
        return {task: estimation.method_names(task)}
    found = scenarios()
    if isinstance(task, str) and task in found:
        return {task: found[task].methods()}
    return {**{t: estimation.method_names(t) for t in fixed}, **{t: s.methods() for t, s in found.items()}}


def draw_noise(rng: np.random.Generator, noise: str, shape: tuple) -> np.ndarray:
    """Zero-mean, unit-variance samples of the chosen distribution."""
    if noise == "gaussian":
        return rng.standard_normal(shape)
    if noise == "uniform":
        return rng.uniform(-np.sqrt(3.0), np.sqrt(3.0), shape)
    return rng.standard_t(3.0, shape) / np.sqrt(3.0)  # Student-t(3) has variance 3


def bound_scale(noise: str, dim: int, confidence: float) -> float:
    """``s`` such that the ellipsoid ``{w : w^T (s Cov)^{-1} w <= 1}`` is the bound given to the set-membership filter.

    Uniform noise: the box of half-widths ``sqrt(3 var)`` lies inside ``3 dim Cov``
    (a guaranteed bound). Otherwise the chi-square quantile at `confidence`.
    """
    if noise == "uniform":
        return 3.0 * dim
    from scipy.stats import chi2

    return float(chi2.ppf(confidence, dim))
