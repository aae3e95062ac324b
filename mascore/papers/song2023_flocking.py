"""Song et al. (2023), nonlinear part: estimation-based flocking, Figs. 4-6.

Scenarios of Sec. V-B of Song, Lee, Kwon, Shin and Oh, "Distributed Estimation
of Stochastic Multi-Agent Systems for Cooperative Control With a Virtual
Network", IEEE Trans. Systems, Man, and Cybernetics: Systems 53(4), 2023.
Algorithms live in :mod:`mascore.flocking` (eqs. (6)-(7), (39)-(40)) and
:mod:`mascore.distributed_ekf` (eqs. (35)-(40) with the update of
eqs. (16)-(20)); this module holds the study of the book's flocking chapter,
:data:`FLOCKING_STUDY`: its settings (:class:`FlockingSettings`, every
parameter with where it comes from), one run (:func:`run`: Fig. 4, the Monte
Carlo of Figs. 5-6 and a sweep beyond the paper), the figures, tables and
ledger claims computed from that run.

Settings from the paper (Table I and Sec. V): N = 8 agents in the plane
(n = 2), dt = 0.1 s, r = 150 m, (rho3, rho4) = (3, 1), (rho5, rho6) = (2, 1),
beta = 0.33, R = 120 m; process noise Q = I_{2n}; measurement noise R = I for
Fig. 4 ("the same as in the previous rendezvous problem", i.e. Fig. 2) and
R = 10 I for Figs. 5-6; 50 Monte Carlo runs. The settings the paper leaves
out are marked ``source="chosen"`` in :class:`FlockingSettings`, with why.

The module constants (``N_AGENTS``, ``GAINS``, ...) are the default settings'
values, kept for the tests and the benchmark; the runs read the settings object.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from .._progress import progress_bar
from .._timing import median_time
from .._validation import (
    check_fits_in_memory,
    check_generator,
    check_positive,
    check_positive_int,
    check_seed,
    float_array,
    require_finite,
)
from ..distributed_ekf import EstimatedFlockingRun, ekf_flocking_step, simulate_estimation_based_flocking
from ..exceptions import DivergenceError
from ..flocking import (
    FlockingGains,
    FlockingRun,
    flock_spread,
    max_distance_from_centre,
    simulate_measured_flocking,
)
from ..graphs import is_connected, proximity_graph
from ..ledger import Claim, format_number
from ..registry import (
    FigureSpec,
    Study,
    TableSpec,
    check_settings,
    check_settings_type,
    documented_settings,
    setting,
)
from ..sensing import measure

if TYPE_CHECKING:  # the figures' type; pyplot is imported where a figure is drawn
    import matplotlib.pyplot as plt

__all__ = [
    "FLOCKING_ERRATA",
    "FlockingSettings",
    "SETTINGS",
    "N_AGENTS",
    "DT",
    "SENSING_RANGE",
    "N_RUNS",
    "initial_states",
    "Fig5Result",
    "FlockingResult",
    "run",
    "plot_fig5",
    "plot_fig6",
    "claims",
    "ekf_step_seconds",
    "FLOCKING_STUDY",
    "STUDY",
    "FIGURES",
    "TABLES",
]


@documented_settings
@dataclass(frozen=True)
class FlockingSettings:
    """Every parameter of the flocking study (Sec. V-B, Figs. 4-6, and the sweep beyond the paper).

    Show it with :func:`mascore.registry.show_settings`; derive variants with
    :func:`dataclasses.replace` (``replace(SETTINGS, n_runs=10)``).
    """

    n_agents: int = setting(8, where="Table I", note="number of agents $N$", low=2)
    n_dim: int = setting(2, where="Table I", note="dimension $n$ of the plane", low=1)
    dt: float = setting(0.1, where="Table I", unit="s", note="sampling time $\\Delta t$", low=0, low_open=True)
    sensing_range: float = setting(150.0, where="Table I", unit="m", note="sensing range $r$", low=0, low_open=True)
    rho3: float = setting(3.0, where="Table I", unit="1/s", note="velocity-alignment gain $\\rho_3$", low=0)
    rho4: float = setting(1.0, where="Table I", note="distance-keeping gain $\\rho_4$", low=0)
    rho5: float = setting(2.0, where="Table I", unit="1/s", note="radial damping gain $\\rho_5$ of $\\phi_2$", low=0)
    rho6: float = setting(1.0, where="Table I", unit="1/s²", note="spring gain $\\rho_6$ of $\\phi_2$", low=0)
    beta: float = setting(0.33, where="Table I", note="decay rate $\\beta$ of $\\phi_1$", low=0, low_open=True)
    spring_length: float = setting(120.0, where="Table I", unit="m",
                                   note="rest length $\\mathcal R$ of the spring; the flock's radius bound",
                                   low=0, low_open=True)
    process_noise: float = setting(1.0, where="Sec. V", note="$Q$ = this $\\times I_{2n}$ per agent", low=0)
    measurement_noise_fig4: float = setting(
        1.0, where="Sec. V-B: as the rendezvous example, Fig. 2",
        note="Fig. 4: $R$ = this $\\times I$ per measured agent", low=0, low_open=True)
    measurement_noise_fig5: float = setting(10.0, where="Sec. V-B",
                                            note="Figs. 5-6: $R$ = this $\\times I$ per measured agent",
                                            low=0, low_open=True)
    n_runs: int = setting(50, where="Sec. V-B", note="Monte Carlo runs of Figs. 5-6", low=1)
    observer: int = setting(1, where="Fig. 4", note="agent (numbered from 1) whose filter Fig. 4 shows", low=1)
    t_final: float = setting(60.0, source="chosen", where="not given; every case settles within about 20 s",
                             unit="s", note="horizon of every run", low=0, low_open=True)
    box: float = setting(300.0, source="chosen", where="'random' in the paper", unit="m",
                         note="Figs. 5-6: initial positions uniform in a square of this side (for N = 8; "
                              "scaled by $\\sqrt{N/8}$), redrawn until the proximity graph is connected",
                              low=0, low_open=True)
    v0_max: float = setting(5.0, source="chosen", where="not given", unit="m/s",
                            note="initial velocities uniform in $\\pm$ this per axis", low=0)
    fig4_spacing: float = setting(100.0, source="chosen", where="Fig. 4 shows its start only as a picture",
                                  unit="m", note="Fig. 4: $2\\times 4$ grid of this spacing, agent 1 at a corner",
                                  low=0, low_open=True)
    sigma0_position: float = setting(10.0, source="chosen", where="'carefully selected' in the paper", unit="m",
                                     note="std of every prior position error, same $\\Sigma_0$ for all agents "
                                          "(Assumption 2)", low=0, low_open=True)
    sigma0_velocity: float = setting(1.0, source="chosen", where="as above", unit="m/s",
                                     note="std of every prior velocity error", low=0, low_open=True)
    min_distance: float = setting(1e-6, source="chosen", where="coincident agents are not discussed", unit="m",
                                  note="$\\lVert p_{ij}\\rVert$ floored at this $d_{\\min}$ in $\\phi_2$",
                                  low=0, low_open=True)
    settled_window: float = setting(20.0, source="chosen", where="'converged' is not defined", unit="s",
                                    note="converged values: time average over the last window of the run",
                                    low=0, low_open=True)
    transient: float = setting(5.0, source="chosen", where="Fig. 4 claim", unit="s",
                               note="Fig. 4 errors are judged from this time on", low=0)
    similar_fraction: float = setting(
        0.25, source="chosen", where="'similar' in Fig. 5 is not quantified",
        note="(iii) similar to (ii): $\\lvert(iii)-(ii)\\rvert \\le$ this $\\times\\,((i)-(ii))$", low=0)
    beyond_sensing_ranges: tuple = setting((130.0, 150.0, 200.0, 250.0), source="chosen",
                                           where="beyond the paper", unit="m", note="sweep over $r$ with N = 8",
                                           low=0, low_open=True)
    beyond_sizes: tuple = setting((4, 8, 12, 16, 24), source="chosen", where="beyond the paper",
                                  note="sweep over $N$ with r = 150 m", low=2)
    beyond_runs: int = setting(2, source="chosen", where="beyond the paper", note="runs per point of the sweep", low=1)
    beyond_t_final: float = setting(40.0, source="chosen", where="beyond the paper", unit="s",
                                    note="horizon of the sweep's runs", low=0, low_open=True)

    def __post_init__(self) -> None:
        check_settings(self)
        if not self.observer <= self.n_agents:
            raise ValueError(f"FlockingSettings.observer must be an agent 1..n_agents (1..{self.n_agents}); "
                             f"got {self.observer}")
        for name in ("t_final", "beyond_t_final"):
            if int(round(getattr(self, name) / self.dt)) < 1:
                raise ValueError(f"FlockingSettings.{name} must be at least half a sampling time "
                                 f"({self.dt / 2:g} s) to give one step; got {getattr(self, name)!r}")
        m = 2 * self.n_dim
        per_step = 8.0 * (2 * self.n_agents * m + self.n_agents**2)  # states, estimates, graph
        check_fits_in_memory(3 * per_step * (self.t_final / self.dt + 1) * self.n_runs, "FlockingSettings.n_runs x t_final / dt",
                             "the states, estimates and graphs of every case, run and step")
        biggest = max(self.beyond_sizes)
        check_fits_in_memory(3 * 8.0 * (2 * biggest * m + biggest**2) * (self.beyond_t_final / self.dt + 1)
                             * self.beyond_runs, "FlockingSettings.beyond_runs x beyond_t_final / dt", "the runs of the sweep")

    @property
    def gains(self) -> FlockingGains:
        """The flocking gains of Table I (with ``d_min``)."""
        return FlockingGains(rho3=self.rho3, rho4=self.rho4, rho5=self.rho5, rho6=self.rho6, beta=self.beta,
                             R=self.spring_length, min_distance=self.min_distance)

    @property
    def Q(self) -> np.ndarray:
        """Process-noise covariance of one agent, ``(2n, 2n)``."""
        return self.process_noise * np.eye(2 * self.n_dim)

    @property
    def R_fig4(self) -> np.ndarray:
        """Measurement-noise covariance per measured agent, Fig. 4."""
        return self.measurement_noise_fig4 * np.eye(2 * self.n_dim)

    @property
    def R_fig5(self) -> np.ndarray:
        """Measurement-noise covariance per measured agent, Figs. 5-6."""
        return self.measurement_noise_fig5 * np.eye(2 * self.n_dim)

    @property
    def sigma0_agent(self) -> np.ndarray:
        """Prior covariance of one agent's state, ``diag(sp^2 I_n, sv^2 I_n)``."""
        n = self.n_dim
        return np.diag([self.sigma0_position**2] * n + [self.sigma0_velocity**2] * n)

    @property
    def n_steps(self) -> int:
        """Number of steps of the horizon ``t_final``."""
        return int(round(self.t_final / self.dt))


#: Most timed repeats the step-timing helpers accept (more would run for hours).
MAX_REPEAT = 10_000

#: The paper's settings (with our choices where it gives none).
SETTINGS = FlockingSettings()

# The default settings' values as module constants (tests, benchmark).
N_AGENTS = SETTINGS.n_agents
N_DIM = SETTINGS.n_dim
DT = SETTINGS.dt  # s
SENSING_RANGE = SETTINGS.sensing_range  # m
GAINS = SETTINGS.gains
Q_AGENT = SETTINGS.Q  # process noise of one agent, Q = I_{2n}
R_FIG4 = SETTINGS.R_fig4  # Fig. 4: R = I (noise "as in the rendezvous problem", Fig. 2)
R_FIG5 = SETTINGS.R_fig5  # Figs. 5-6: R = 10 I
N_RUNS = SETTINGS.n_runs
T_FINAL = SETTINGS.t_final  # s
SIGMA0_AGENT = SETTINGS.sigma0_agent

#: The three cases of Fig. 5.
CASES = ("(i) measured, proximity graph", "(ii) measured, fully connected", "(iii) estimated, virtual full")
_ROMAN = ("i", "ii", "iii")
_STYLES = ({"ls": "-"}, {"ls": "--"}, {"ls": ":", "lw": 2.0})  # (ii) and (iii) nearly coincide


# ----------------------------------------------------------------------------- initial conditions


def initial_states(
    rng: np.random.Generator, n_runs: int, settings: FlockingSettings = SETTINGS, max_tries: int = 10_000
) -> np.ndarray:
    """Random initial team states with a connected proximity graph.

    Positions uniform in a square of side ``box * sqrt(N / 8)`` (the paper's
    density for any N), redrawn until the graph of range ``sensing_range`` is
    connected; velocities uniform in ``[-v0_max, v0_max]`` per axis.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of randomness.
    n_runs : int
        Number of independent starts.
    settings : FlockingSettings
        The study's settings (default :data:`SETTINGS`).
    max_tries : int
        Largest number of draws per start.

    Returns
    -------
    (n_runs, N, 2n) ndarray
        Positions (m) then velocities (m/s) of every agent.

    Raises
    ------
    ValueError
        Bad `n_runs`, `max_tries` or settings, or no connected placement in
        `max_tries` draws (the sensing range is too short for the square).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> X0 = flocking_paper.initial_states(np.random.default_rng(0), 3)
    >>> X0.shape, all(graphs.is_connected(graphs.proximity_graph(x[:, :2], 150.0)) for x in X0)
    ((3, 8, 4), True)
    """
    check_settings_type(settings, FlockingSettings, "settings")
    rng = check_generator(rng)
    n_runs = check_positive_int(n_runs, "n_runs")
    max_tries = check_positive_int(max_tries, "max_tries")
    N, n = check_positive_int(settings.n_agents, "settings.n_agents"), settings.n_dim
    check_positive(settings.sensing_range, "settings.sensing_range", "m")
    side = settings.box * np.sqrt(N / N_AGENTS)
    positions = np.empty((n_runs, N, n))
    for k in range(n_runs):
        for _ in range(max_tries):
            p = rng.uniform(0.0, side, (N, n))
            if is_connected(proximity_graph(p, settings.sensing_range)):
                positions[k] = p
                break
        else:
            raise ValueError(f"no connected placement of {N} agents in a {side:.4g} m square with "
                             f"settings.sensing_range = {settings.sensing_range:g} m in {max_tries} draws "
                             "(max_tries); increase the sensing range")
    velocities = rng.uniform(-settings.v0_max, settings.v0_max, (n_runs, N, n))
    return np.concatenate([positions, velocities], axis=-1)


def fig4_initial_state(rng: np.random.Generator, settings: FlockingSettings = SETTINGS) -> np.ndarray:
    """Fig. 4 initial state: rows of 4 agents (2 x 4 for N = 8), ``fig4_spacing`` apart, random velocities."""
    check_settings_type(settings, FlockingSettings, "settings")
    rng = check_generator(rng)
    j = np.arange(settings.n_agents)
    p = settings.fig4_spacing * np.stack([j % 4, j // 4], axis=-1).astype(float)
    v = rng.uniform(-settings.v0_max, settings.v0_max, (settings.n_agents, settings.n_dim))
    return np.concatenate([p, v], axis=-1)


def initial_estimates(rng: np.random.Generator, X0: np.ndarray,
                      settings: FlockingSettings = SETTINGS) -> tuple[np.ndarray, np.ndarray]:
    """Every agent's prior of the team: truth + ``N(0, Sigma0)``; returns ``(X_hat0, Sigma0)``.

    ``X_hat0`` has shape ``(..., N, N, 2n)`` for ``X0`` ``(..., N, 2n)``;
    ``Sigma0 = I_N kron sigma0_agent``.
    """
    check_settings_type(settings, FlockingSettings, "settings")
    rng = check_generator(rng)
    X0 = require_finite(float_array(X0, "X0"), "X0")
    m = 2 * settings.n_dim
    if X0.ndim < 2 or X0.shape[-1] != m or X0.shape[-2] < 1:
        raise ValueError(f"X0 must have shape (..., N, {m}) with N >= 1; got {X0.shape}")
    N = X0.shape[-2]
    std = np.sqrt(np.diag(settings.sigma0_agent))
    X_hat0 = X0[..., None, :, :] + std * rng.standard_normal((*X0.shape[:-2], N, N, 2 * settings.n_dim))
    return X_hat0, np.kron(np.eye(N), settings.sigma0_agent)


# ----------------------------------------------------------------------------- runs


def run_fig4(settings: FlockingSettings = SETTINGS, seed: int = 1) -> EstimatedFlockingRun:
    """The single run of Fig. 4: estimation-based flocking (case (iii)), ``R_fig4``, recording ``observer``."""
    check_settings_type(settings, FlockingSettings, "settings")
    check_seed(seed, "seed")
    rng = np.random.default_rng([seed, 4])
    X0 = fig4_initial_state(rng, settings)
    X_hat0, Sigma0 = initial_estimates(rng, X0, settings)
    return simulate_estimation_based_flocking(
        X0, X_hat0, Sigma0, settings.n_steps, settings.dt, settings.gains, settings.Q, settings.R_fig4, rng,
        settings.sensing_range, observer=settings.observer - 1,
    )


@dataclass(frozen=True)
class Fig5Result:
    """The three cases of Fig. 5 over the Monte Carlo runs.

    Parameters
    ----------
    t : (T+1,) ndarray
        Times (s).
    std_p : (3, T+1) ndarray
        RMS over runs of the position spread (m), per case.
    std_v : (3, T+1) ndarray
        RMS over runs of the velocity spread (m/s), per case.
    final : (3, n_runs, N, 2n) ndarray
        Team states at the end, per case and run (Fig. 6).
    max_distance : (3, n_runs, T+1) ndarray
        Largest distance (m) of an agent from the centre of mass.
    trajectories : (3, T+1, N, 2n) ndarray
        True states of run 0 per case.
    rms_error : (n_runs, T+1) ndarray
        Case (iii): RMS position error (m) over all estimators and agents.
    diverged : tuple of 3 bool
        Cases whose sampled loop blew up (their arrays are NaN); never with
        the paper's settings, but from about N = 18 agents with Table I gains.
    window : float
        Length (s) of the final window averaged by :meth:`settled`.

    Examples
    --------
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> import dataclasses
    >>> quick = dataclasses.replace(flocking_paper.SETTINGS, n_runs=2, t_final=4.0, beyond_sizes=(4,),
    ...                             beyond_sensing_ranges=(150.0,), beyond_runs=1, beyond_t_final=2.0,
    ...                             settled_window=2.0, transient=1.0)         # a small run
    >>> result = flocking_paper.run(quick, seed=1)
    >>> result.fig5.std_p.shape
    (3, 41)
    """

    t: np.ndarray
    std_p: np.ndarray
    std_v: np.ndarray
    final: np.ndarray
    max_distance: np.ndarray
    trajectories: np.ndarray
    rms_error: np.ndarray
    diverged: tuple = (False, False, False)
    window: float = SETTINGS.settled_window

    def settled(self, series: np.ndarray) -> np.ndarray:
        """Time average of ``series[..., t]`` over the last ``window`` seconds.

        Parameters
        ----------
        series : (..., T+1) ndarray
            A time series on :attr:`t`.

        Returns
        -------
        (...) ndarray
            Its average over the final window (NaN where the series is: a case whose run diverged).

        Examples
        --------
        >>> import dataclasses
        >>> from mascore.papers import song2023_flocking as flocking_paper
        >>> quick = dataclasses.replace(flocking_paper.SETTINGS, n_runs=2, t_final=4.0, beyond_sizes=(4,),
        ...                             beyond_sensing_ranges=(150.0,), beyond_runs=1, beyond_t_final=2.0,
        ...                             settled_window=2.0, transient=1.0)
        >>> fig5 = flocking_paper.run(quick, seed=1).fig5
        >>> fig5.settled(fig5.std_p).shape                       # one value per case
        (3,)
        """
        series = float_array(series, "series")
        if series.shape[-1:] != self.t.shape:
            raise ValueError(f"series must be a time series on t, of shape (..., {self.t.size}); got {series.shape}")
        return series[..., self.t >= self.t[-1] - self.window].mean(axis=-1)  # NaN for a case that diverged


def run_fig5(settings: FlockingSettings = SETTINGS, seed: int = 1, progress: bool = False) -> Fig5Result:
    """Monte Carlo of the three cases of Fig. 5 (and the configurations of Fig. 6).

    ``settings.n_runs`` runs of ``settings.t_final`` s with ``R_fig5``; the
    three cases share their initial states (common random numbers) and draw
    their noise from independent streams.
    """
    check_settings_type(settings, FlockingSettings, "settings")
    check_seed(seed, "seed")
    root = np.random.SeedSequence([seed, 5])
    init_ss, *case_ss = root.spawn(4)
    rng0 = np.random.default_rng(init_ss)
    X0 = initial_states(rng0, settings.n_runs, settings)
    X_hat0, Sigma0 = initial_estimates(rng0, X0, settings)
    T, dt, gains, Q, R, r = (settings.n_steps, settings.dt, settings.gains, settings.Q, settings.R_fig5,
                             settings.sensing_range)
    rngs = [np.random.default_rng(ss) for ss in case_ss]
    simulations = (
        lambda: simulate_measured_flocking(X0, T, dt, gains, Q, R, rngs[0], r),
        lambda: simulate_measured_flocking(X0, T, dt, gains, Q, R, rngs[1], None),
        lambda: simulate_estimation_based_flocking(X0, X_hat0, Sigma0, T, dt, gains, Q, R, rngs[2], r,
                                                   progress=progress),
    )
    runs: list[FlockingRun | EstimatedFlockingRun | None] = []
    for simulate in simulations:
        try:
            runs.append(simulate())
        except DivergenceError:
            runs.append(None)
    nan_X = np.full((*X0.shape[:1], T + 1, *X0.shape[1:]), np.nan)
    Xs = [nan_X if r is None else r.X for r in runs]
    spreads = [flock_spread(X) for X in Xs]  # each (n_runs, T+1)
    rms = lambda a: np.sqrt(np.mean(a**2, axis=0))  # noqa: E731
    return Fig5Result(
        t=dt * np.arange(T + 1),
        std_p=np.stack([rms(sp[0]) for sp in spreads]),
        std_v=np.stack([rms(sp[1]) for sp in spreads]),
        final=np.stack([X[:, -1] for X in Xs]),
        max_distance=np.stack([max_distance_from_centre(X) for X in Xs]),
        trajectories=np.stack([X[0] for X in Xs]),
        rms_error=np.full(nan_X.shape[:2], np.nan) if runs[2] is None else runs[2].rms_error,
        diverged=tuple(r is None for r in runs),
        window=settings.settled_window,
    )


def beyond_study(settings: FlockingSettings = SETTINGS, seed: int = 1, progress: bool = False) -> pd.DataFrame:
    """Flock size and estimation error against the sensing range r (N = 8) and the team size N (r = 150 m).

    Not in the paper. For each point of ``settings.beyond_sensing_ranges``
    (with the paper's N) and ``settings.beyond_sizes`` (with the paper's r),
    :func:`run_fig5` with ``beyond_runs`` runs of ``beyond_t_final`` s.

    Returns
    -------
    pandas.DataFrame
        One row per (N, r), sorted: ``N``, ``r (m)``, the median over runs of
        the final largest distance from the centre of mass for cases
        (i)-(iii) (m), the settled RMS position error of all estimators in
        case (iii) (m), and which cases are unstable (raised
        ``DivergenceError``, or ended with an agent farther than 10 R from
        the centre of mass; their numbers are then meaningless).
    """
    check_settings_type(settings, FlockingSettings, "settings")
    check_seed(seed, "seed")
    points = [(settings.n_agents, r) for r in settings.beyond_sensing_ranges]
    points += [(N, settings.sensing_range) for N in settings.beyond_sizes if N != settings.n_agents]
    base = replace(settings, n_runs=settings.beyond_runs, t_final=settings.beyond_t_final)
    rows = []
    for N, r in progress_bar(points, enabled=progress, desc="beyond", leave=False):
        res = run_fig5(replace(base, n_agents=N, sensing_range=r), seed)
        d_end = np.median(res.max_distance[:, :, -1], axis=1)
        unstable = [c for c, d, dist in zip(_ROMAN, res.diverged, d_end) if d or dist > 10 * settings.spring_length]
        rows.append({
            "N": N, "r (m)": r,
            **{f"farthest agent ({c}) (m)": d for c, d in zip(_ROMAN, d_end)},
            "RMS estimation error (iii) (m)": float(res.settled(np.sqrt(np.mean(res.rms_error**2, axis=0)))),
            "unstable": ", ".join(f"({c})" for c in unstable) or "-",
        })
    return pd.DataFrame(rows).sort_values(["N", "r (m)"]).reset_index(drop=True)


@dataclass(frozen=True)
class FlockingResult:
    """Everything the flocking chapter shows, from one :func:`run`.

    Parameters
    ----------
    settings : FlockingSettings
        The settings of the run.
    fig4 : mascore.distributed_ekf.EstimatedFlockingRun
        The single run of Fig. 4.
    fig5 : Fig5Result
        The Monte Carlo of Figs. 5-6.
    beyond : pandas.DataFrame
        The sweep beyond the paper (team size and sensing range).
    seconds : dict
        Wall time (s) of each part, this machine (reported, never asserted).

    Examples
    --------
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> import dataclasses
    >>> quick = dataclasses.replace(flocking_paper.SETTINGS, n_runs=2, t_final=4.0, beyond_sizes=(4,),
    ...                             beyond_sensing_ranges=(150.0,), beyond_runs=1, beyond_t_final=2.0,
    ...                             settled_window=2.0, transient=1.0)         # a small run
    >>> result = flocking_paper.run(quick, seed=1)
    >>> sorted(result.seconds) == sorted(["fig4", "fig5", "beyond"])
    True
    """

    settings: FlockingSettings
    fig4: EstimatedFlockingRun
    fig5: Fig5Result
    beyond: pd.DataFrame
    seconds: dict


def run(settings: FlockingSettings = SETTINGS, seed: int = 1, progress: bool = False) -> FlockingResult:
    """The flocking study once: Fig. 4's run, the Monte Carlo of Figs. 5-6, the sweep beyond the paper.

    Parameters
    ----------
    settings : FlockingSettings
        The study's settings (default :data:`SETTINGS`).
    seed : int
        Seed of every random draw.
    progress : bool
        Show progress bars.

    Returns
    -------
    FlockingResult
        Everything the figures, tables and claims need.

    Examples
    --------
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> import dataclasses
    >>> quick = dataclasses.replace(flocking_paper.SETTINGS, n_runs=2, t_final=4.0, beyond_sizes=(4,),
    ...                             beyond_sensing_ranges=(150.0,), beyond_runs=1, beyond_t_final=2.0,
    ...                             settled_window=2.0, transient=1.0)         # a small run
    >>> result = flocking_paper.run(quick, seed=1)
    >>> result.fig5.diverged
    (False, False, False)
    """
    check_settings_type(settings, FlockingSettings, "settings")
    check_seed(seed, "seed")
    parts = (("fig4", lambda: run_fig4(settings, seed)),
             ("fig5", lambda: run_fig5(settings, seed, progress=progress)),
             ("beyond", lambda: beyond_study(settings, seed, progress=progress)))
    out, seconds = {}, {}
    for name, compute in parts:
        start = time.perf_counter()
        out[name] = compute()
        seconds[name] = time.perf_counter() - start
    return FlockingResult(settings, out["fig4"], out["fig5"], out["beyond"], seconds)


# ----------------------------------------------------------------------------- figures


def plot_fig4(run4: EstimatedFlockingRun, settings: FlockingSettings = SETTINGS) -> plt.Figure:
    """Song et al. 2023, Fig. 4 (a)-(f) from a :func:`run_fig4` run.

    (a), (b) proximity networks at the start and the end; (c) true and (d)
    estimated trajectories; (e) position error and (f) statistical error of
    the observer's filter for every other agent. Dashed: agents that are not
    the observer's neighbours at the end. One legend below the panels.
    """
    import matplotlib.pyplot as plt

    from ..plotting import agent_colors, plot_graph
    check_settings_type(settings, FlockingSettings, "settings")
    fig, axes = plt.subplots(3, 2, figsize=(7.5, 10.6), layout="constrained")
    X, Xh, A, t = run4.X, run4.X_hat, run4.adjacency, run4.t
    N, o = X.shape[-2], run4.observer
    colors = agent_colors(N)
    nbr_end = A[-1, o]
    style = ["-" if j == o or nbr_end[j] else "--" for j in range(N)]
    marker = ["^" if j == o else ("o" if nbr_end[j] else "s") for j in range(N)]
    for ax, k, title in ((axes[0, 0], 0, "(a) initial network"), (axes[0, 1], -1, "(b) network at the end")):
        plot_graph(X[k, :, :2], A[k], ax=ax, sensing_range=settings.sensing_range)
        ax.set_title(title + f" ({int(np.triu(A[k], 1).sum())} of {N * (N - 1) // 2} links)")
    for ax, P, title in ((axes[1, 0], X, "(c) true trajectories"),
                         (axes[1, 1], Xh, f"(d) trajectories estimated by agent {o + 1}")):
        for j in range(N):
            ax.plot(P[:, j, 0], P[:, j, 1], style[j], color=colors[j], lw=0.8)
            ax.plot(*P[-1, j, :2], marker[j], color=colors[j], ms=7, mfc="none" if marker[j] == "s" else colors[j])
        ax.set(xlabel="x (m)", ylabel="y (m)", title=title)
        ax.set_aspect("equal", adjustable="datalim")
    err = np.linalg.norm(Xh[..., :2] - X[..., :2], axis=-1)
    for ax, series, title, ylabel in (
        (axes[2, 0], err, f"(e) agent {o + 1}'s position error",
         rf"$\Vert\hat p_{{{o + 1},j}} - p_j\Vert$ (m)"),
        (axes[2, 1], np.sqrt(run4.position_variance), f"(f) agent {o + 1}'s statistical error",
         rf"$\sqrt{{\mathrm{{tr}}\,\Sigma_{{{o + 1},p_j}}}}$ (m)"),
    ):
        for j in range(N):
            if j != o:
                ax.plot(t, series[:, j], style[j], color=colors[j], lw=0.8)
        ax.set(xlabel="time (s)", ylabel=ylabel, title=title)
    handles = [plt.Line2D([], [], ls=style[j], marker=marker[j], color=colors[j], lw=0.8, ms=6,
                          mfc="none" if marker[j] == "s" else colors[j], label=f"agent {j + 1}") for j in range(N)]
    fig.legend(handles=handles, loc="outside lower center", ncol=4,
               title=f"end marker: ▲ agent {o + 1}, ● its neighbours at the end, □ (dashed) its non-neighbours")
    return fig


def plot_fig5(res: Fig5Result) -> plt.Figure:
    """Song et al. 2023, Fig. 5 (a) position and (b) velocity RMS STD over time (legend below the panels).

    Parameters
    ----------
    res : Fig5Result
        The Monte Carlo of :func:`run`.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> import dataclasses
    >>> quick = dataclasses.replace(flocking_paper.SETTINGS, n_runs=2, t_final=4.0, beyond_sizes=(4,),
    ...                             beyond_sensing_ranges=(150.0,), beyond_runs=1, beyond_t_final=2.0,
    ...                             settled_window=2.0, transient=1.0)         # a small run
    >>> result = flocking_paper.run(quick, seed=1)
    >>> len(flocking_paper.plot_fig5(result.fig5).axes) >= 2
    True
    >>> plt.close("all")
    """
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(7.5, 3.4), layout="constrained")
    for ax, series, ylabel, title in ((axes[0], res.std_p, "RMS STD of positions (m)", "(a) position"),
                                      (axes[1], res.std_v, "RMS STD of velocities (m/s)", "(b) velocity")):
        ax.axvspan(res.t[-1] - res.window, res.t[-1], color="0.92", lw=0, label="window of the settled values")
        for c, label in enumerate(CASES):
            ax.plot(res.t, series[c], color=f"C{c}", label=label, **_STYLES[c])
        ax.set(xlabel="time (s)", ylabel=ylabel, title=title)
    handles, labels = axes[0].get_legend_handles_labels()
    order = [labels.index(label) for label in (*CASES, "window of the settled values")]
    fig.legend([handles[k] for k in order], [labels[k] for k in order], loc="outside lower center", ncol=2)
    return fig


def plot_fig6(res: Fig5Result, settings: FlockingSettings = SETTINGS, run_index: int = 0) -> plt.Figure:
    """Song et al. 2023, Fig. 6: converged configurations of one run with the circle of radius R about the CoM.

    Panels: (a) case (i), (b) case (iii) as in the paper, (c) case (ii) for reference.

    Parameters
    ----------
    res : Fig5Result
        The Monte Carlo of :func:`run`.
    settings : FlockingSettings
        The study's settings (default :data:`SETTINGS`).
    run_index : int
        Which Monte Carlo run to draw.

    Returns
    -------
    matplotlib.figure.Figure
        The figure.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> import dataclasses
    >>> quick = dataclasses.replace(flocking_paper.SETTINGS, n_runs=2, t_final=4.0, beyond_sizes=(4,),
    ...                             beyond_sensing_ranges=(150.0,), beyond_runs=1, beyond_t_final=2.0,
    ...                             settled_window=2.0, transient=1.0)         # a small run
    >>> result = flocking_paper.run(quick, seed=1)
    >>> len(flocking_paper.plot_fig6(result.fig5, quick).axes) >= 3
    True
    >>> plt.close("all")
    """
    import matplotlib.pyplot as plt

    from ..plotting import plot_graph
    check_settings_type(settings, FlockingSettings, "settings")
    run_index = check_positive_int(run_index, "run_index", minimum=0)
    if run_index >= res.final.shape[1]:
        raise ValueError(f"run_index must be a run index in [0, {res.final.shape[1] - 1}]; got {run_index}")
    fig, axes = plt.subplots(1, 3, figsize=(7.5, 3.3), layout="constrained")
    for ax, c, letter in zip(axes, (0, 2, 1), "abc"):
        p = res.final[c, run_index, :, :2]
        plot_graph(p, proximity_graph(p, settings.sensing_range), ax=ax)
        com = p.mean(axis=0)
        ax.add_patch(plt.Circle(com, settings.spring_length, fill=False, color="k", lw=1.2))
        ax.plot(*com, "k+", ms=10)
        farthest = np.linalg.norm(p - com, axis=-1).max()
        ax.set_title(f"({letter}) case ({_ROMAN[c]})\nfarthest agent {farthest:.0f} m")
        ax.autoscale_view()
    return fig


def plot_beyond(table: pd.DataFrame, settings: FlockingSettings = SETTINGS) -> plt.Figure:
    """Farthest agent from the CoM and estimation error against r (N = 8) and N (r = 150 m).

    (a), (b) the median final largest distance from the centre of mass, cases
    (i)-(iii); (c), (d) the settled RMS position error of case (iii). Unstable
    cases are left out; a shaded band runs from the last point where every
    case is stable to the last point.
    """
    import matplotlib.pyplot as plt
    check_settings_type(settings, FlockingSettings, "settings")
    fig, axes = plt.subplots(2, 2, figsize=(7.5, 6.2), layout="constrained")
    by_r = table[table["N"] == settings.n_agents]
    by_n = table[table["r (m)"] == settings.sensing_range]
    for col, (x, data, xlabel) in enumerate((("r (m)", by_r, f"sensing range r (m), N = {settings.n_agents}"),
                                             ("N", by_n, f"number of agents N, r = {settings.sensing_range:.0f} m"))):
        ax_d, ax_e = axes[0, col], axes[1, col]
        for c, roman in enumerate(_ROMAN):
            stable = ~data["unstable"].str.contains(f"({roman})", regex=False)
            ax_d.plot(data[x][stable], data[f"farthest agent ({roman}) (m)"][stable], marker="os^"[c],
                      color=f"C{c}", label=CASES[c], **_STYLES[c])
        ax_d.axhline(settings.spring_length, color="k", lw=0.8,
                     label=rf"$\mathcal{{R}}$ = {settings.spring_length:.0f} m")
        stable = ~data["unstable"].str.contains("(iii)", regex=False)
        ax_e.plot(data[x][stable], data["RMS estimation error (iii) (m)"][stable], "^:", color="C2", lw=2.0)
        ax_d.set(xlabel=xlabel, ylabel="farthest agent from CoM (m)")
        ax_e.set(xlabel=xlabel, ylabel="RMS estimation error (iii) (m)")
        unstable = data.loc[data["unstable"] != "-", x]
        if len(unstable):  # from the last stable point to the last point
            for ax in (ax_d, ax_e):
                ax.axvspan(data.loc[data["unstable"] == "-", x].max(), unstable.min(), color="0.9", lw=0,
                           label="(ii), (iii) become unstable\nsomewhere in this band")
    for ax, letter in zip(axes.flat, "abcd"):
        ax.set_title(f"({letter})", loc="left")
    handles, labels = axes[0, 1].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3)
    return fig


# ----------------------------------------------------------------------------- claims


def fig4_statistics(run4: EstimatedFlockingRun, transient: float = SETTINGS.transient) -> dict:
    """Numbers of the Fig. 4 claim, from ``t >= transient`` and the agents other than the observer.

    Each time step is split by whether the agent is the observer's neighbour
    at that step. Errors in m; the statistical error is
    ``sqrt(trace Sigma_pos)`` of the observer's filter.
    """
    check_positive(transient, "transient", "s", allow_zero=True)
    o, dt = run4.observer, run4.t[1] - run4.t[0]
    late = run4.t >= transient
    others = np.arange(run4.X.shape[-2]) != o
    err = np.linalg.norm(run4.X_hat[..., :2] - run4.X[..., :2], axis=-1)[late][:, others]
    sig = np.sqrt(run4.position_variance)[late][:, others]
    nbr = run4.adjacency[late, o][:, others]
    if nbr.all() or not nbr.any():
        raise ValueError("the Fig. 4 run needs steps with both neighbours and non-neighbours of the observer")
    half = np.arange(late.sum()) >= late.sum() // 2
    sig_nn = np.where(~nbr, sig, 0.0)
    out_for = np.zeros_like(sig)  # seconds out of range so far
    for k in range(1, len(sig)):
        out_for[k] = np.where(nbr[k], 0.0, out_for[k - 1] + dt)
    enters = ~nbr[:-1] & nbr[1:] & (out_for[:-1] >= 1.0 - 1e-9)  # into range after >= 1 s out of it
    drops = sig[1:][enters] / sig[:-1][enters]
    return {
        "mean_error_neighbours": float(err[nbr].mean()),
        "mean_error_non_neighbours": float(err[~nbr].mean()),
        "max_error_non_neighbours": float(err[~nbr].max()),
        "mean_sigma_neighbours": float(sig[nbr].mean()),
        "mean_sigma_non_neighbours": float(sig[~nbr].mean()),
        "within_3_sigma_non_neighbours": float((err[~nbr] <= 3 * sig[~nbr]).mean()),
        "sigma_growth": float(sig_nn[half].max() / max(sig_nn[~half].max(), 1e-12)),
        "fraction_non_neighbour": float((~nbr).mean()),
        "entries_into_range": int(enters.sum()),
        "median_drop_on_entering": float(np.median(drops)) if drops.size else 1.0,
        "mse_over_variance": float((err**2).mean() / (sig**2).mean()),
    }


def fig4_claim(run4: EstimatedFlockingRun, settings: FlockingSettings = SETTINGS) -> Claim:
    """``song2023/fig4-non-neighbour-error-bounded`` from a :func:`run_fig4` run.

    Holds when (1) the mean position error is larger for non-neighbours than
    for neighbours, (2) at least 95 % of the non-neighbour errors lie within
    three statistical errors, (3) the non-neighbours' statistical error does
    not grow (maximum over the second half of the window at most 1.5 times
    that of the first half), and (4) it drops sharply when an agent comes back
    into range after at least 1 s out of it (median ratio after/before < 0.5).
    """
    check_settings_type(settings, FlockingSettings, "settings")
    s = fig4_statistics(run4, settings.transient)
    o = run4.observer + 1
    holds = (s["mean_error_non_neighbours"] > s["mean_error_neighbours"] and s["within_3_sigma_non_neighbours"] >= 0.95
             and s["sigma_growth"] <= 1.5 and s["median_drop_on_entering"] < 0.5)
    value = {
        "mean error of neighbours (m)": s["mean_error_neighbours"],
        "mean error of non-neighbours (m)": s["mean_error_non_neighbours"],
        "non-neighbour errors within 3σ (fraction)": s["within_3_sigma_non_neighbours"],
        "growth of non-neighbour σ, 2nd half / 1st half": s["sigma_growth"],
        "σ just after / just before entering range (median)": s["median_drop_on_entering"],
    }
    f, eye = format_number, _times_identity
    note = (
        f"One run, N = {settings.n_agents}, r = {f(settings.sensing_range)} m, Q = {eye(settings.process_noise)}, "
        f"R = {eye(settings.measurement_noise_fig4)} (the rendezvous noise levels, as the text says), "
        f"horizon {f(settings.t_final)} s, judged from t = {f(settings.transient)} s; "
        f"2 x 4 grid start with {f(settings.fig4_spacing)} m spacing (our choice). An agent is out of agent {o}'s "
        f"range in {f(100 * s['fraction_non_neighbour'], 3)} % of the agent-steps and comes back into range "
        f"{s['entries_into_range']} times after at least 1 s out; agent {o}'s statistical error σ averages "
        f"{f(s['mean_sigma_neighbours'])} m for neighbours and {f(s['mean_sigma_non_neighbours'])} m for "
        f"non-neighbours; the largest non-neighbour error is {f(s['max_error_non_neighbours'])} m."
        "\n\n"
        "'Bounded' is made checkable as: at least 95 % of the non-neighbour errors within 3σ, and no growth of "
        "σ between the two halves of the run (at most 1.5 times); 'sharp drop' as: the median ratio of σ just "
        "after to just before an agent enters range (after at least 1 s out) below 0.5."
        "\n\n"
        f"The filter is somewhat over-confident (mean squared error {f(s['mse_over_variance'], 3)} times its "
        "variance; 1.2-1.7 times over seeds 1-3) because eq. (38) ignores that the other agents act on their "
        "own estimates."
    )
    return Claim.qualitative(
        "song2023/fig4-non-neighbour-error-bounded", "Fig. 4(e)-(f), Sec. V-B",
        f"Agent {o}'s position errors of its non-neighbours are larger than those of its neighbours "
        "but stay bounded; its statistical error of an agent drops sharply when that agent comes into range.",
        value, holds, note,
        rule="non-neighbours' mean error > neighbours'; within 3σ ≥ 0.95; σ growth ≤ 1.5; σ after/before < 0.5",
    )


def fig5_claims(res: Fig5Result, settings: FlockingSettings = SETTINGS) -> list[Claim]:
    """``song2023/fig5-position-std`` and ``song2023/fig5-velocity-std``.

    Each holds when the settled RMS STD of cases (ii) and (iii) is below that
    of case (i) and (iii) is similar to (ii):
    ``|(iii) - (ii)| <= similar_fraction ((i) - (ii))``.
    """
    check_settings_type(settings, FlockingSettings, "settings")
    a = settings.similar_fraction
    shared = (
        f"Settled = time average over the last {format_number(settings.settled_window)} s of "
        f"{format_number(settings.t_final)} s; {settings.n_runs} runs, Q = {_times_identity(settings.process_noise)}, "
        f"R = {_times_identity(settings.measurement_noise_fig5)}. The STD of a run is the spread of the agents "
        "about their mean, sqrt(mean over i of the squared distance of x_i from the mean), RMS over runs (our "
        f"reading of 'root mean square STD'). 'Similar' is read as: abs((iii) - (ii)) at most {format_number(a)} "
        "times ((i) - (ii)). The paper prints no numbers, so the claim is qualitative."
    )
    out = []
    for key, plural, series, unit in (("position", "positions", res.std_p, "m"),
                                      ("velocity", "velocities", res.std_v, "m/s")):
        s = res.settled(series)
        gap = abs(s[2] - s[1]) / (s[0] - s[1]) if s[0] > s[1] else np.inf
        holds = s[1] < s[0] and s[2] < s[0] and gap <= a
        out.append(Claim.qualitative(
            f"song2023/fig5-{key}-std", f"Fig. 5({'a' if key == 'position' else 'b'}), Sec. V-B",
            f"The converged RMS STD of the agents' {plural} with estimation-based flocking (iii) is similar "
            "to that of flocking on a fixed fully-connected network (ii), and both are below "
            "conventional flocking on the proximity graph (i).",
            {f"case ({c})": float(v) for c, v in zip(_ROMAN, s)}, holds,
            f"(iii) differs from (ii) by {format_number(100 * gap, 3)} % of the gap between (i) and (ii).\n\n"
            + shared,
            unit=unit, rule=f"(ii) < (i), (iii) < (i), abs((iii) - (ii)) ≤ {format_number(a)} ((i) - (ii))",
        ))
    return out


def fig6_claim(res: Fig5Result, settings: FlockingSettings = SETTINGS) -> Claim:
    """``song2023/fig6-within-boundary``: largest distance from the CoM at the end vs R.

    Holds when, at the final step, every agent is within R of the centre of
    mass in at least 95 % of the runs for cases (ii) and (iii), and in at most
    5 % of the runs for case (i).
    """
    check_settings_type(settings, FlockingSettings, "settings")
    R, r = settings.spring_length, settings.sensing_range
    d_end = res.max_distance[:, :, -1]  # (3, runs)
    frac = (d_end <= R).mean(axis=1)
    med, worst = np.median(d_end, axis=1), d_end.max(axis=1)
    N = res.final.shape[2]
    bound = R * (N - 1) / N
    by_case = lambda a: {f"case {c}": float(v) for c, v in zip(_ROMAN, a)}  # noqa: E731
    value = {"runs within R (fraction)": by_case(frac), "median farthest agent (m)": by_case(med),
             "worst run's farthest agent (m)": by_case(worst)}
    holds = frac[1] >= 0.95 and frac[2] >= 0.95 and frac[0] <= 0.05
    f, eye = format_number, _times_identity
    note = (
        f"Farthest agent from the centre of mass at t = {f(res.t[-1])} s, over {d_end.shape[1]} runs "
        f"(Q = {eye(settings.process_noise)}, R = {eye(settings.measurement_noise_fig5)}); "
        "in run 0 (the one drawn in Fig. 6) "
        f"{f(d_end[0, 0])} m (i), {f(d_end[1, 0])} m (ii) and {f(d_end[2, 0])} m (iii). The noiseless bound "
        f"R (N-1)/N is {f(bound)} m for N = {N}; the worst run of (iii) ends "
        f"{'above' if worst[2] > bound else 'below'} it, that of (ii) {'above' if worst[1] > bound else 'below'}."
        "\n\n"
        "Without noise, a fully-connected equilibrium has N (p_i - CoM) = R times the sum over j of the unit "
        "vectors from p_j to p_i, so every agent is within R (N-1)/N of the centre of mass: the spring rest "
        "length R bounds the flock only when every pair interacts. Noise moves the flocks off that "
        "equilibrium, (iii) more than (ii) because its agents act on estimates and so feel perturbed "
        "springs; the margin to R is what the claim tests."
        "\n\n"
        f"On the proximity graph (r = {f(r)} m, only {f(r - R)} m above the rest length) agents settle about "
        "R from their neighbours and feel no pull from the others, so the flock spreads out as a lattice of "
        f"spacing about R (median {f(med[0])} m, {f(100 * frac[0], 3)} % of the runs within R). This depends "
        "on r, not on the estimator: at r = 200 m case (i) is as tight as (ii) (the chapter's study beyond "
        "the paper)."
    )
    return Claim.qualitative(
        "song2023/fig6-within-boundary", "Fig. 6, Sec. V-B",
        f"At convergence every agent lies within R = {f(R)} m of the centre of mass with estimation-based "
        "flocking (iii) (as with a fully-connected network (ii)), but not with conventional flocking on "
        "the proximity graph (i).",
        value, holds, note,
        rule="runs within R ≥ 0.95 for (ii) and (iii), ≤ 0.05 for (i)",
    )


def _times_identity(x: float) -> str:
    """``x`` times the identity as the notes write it (``I``, ``10 I``)."""
    return "I" if x == 1 else f"{format_number(x)} I"


def claims(result: FlockingResult) -> list[Claim]:
    """The four flocking claims of the ledger, from one :func:`run`.

    Parameters
    ----------
    result : FlockingResult
        The output of :func:`run`.

    Returns
    -------
    list of mascore.ledger.Claim
        The claims, verdicts computed.

    Examples
    --------
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> import dataclasses
    >>> quick = dataclasses.replace(flocking_paper.SETTINGS, n_runs=2, t_final=4.0, beyond_sizes=(4,),
    ...                             beyond_sensing_ranges=(150.0,), beyond_runs=1, beyond_t_final=2.0,
    ...                             settled_window=2.0, transient=1.0)         # a small run
    >>> result = flocking_paper.run(quick, seed=1)
    >>> len(flocking_paper.claims(result))
    4
    """
    st = result.settings
    return [fig4_claim(result.fig4, st), *fig5_claims(result.fig5, st), fig6_claim(result.fig5, st)]


# ----------------------------------------------------------------------------- tables


def settled_table(result: FlockingResult) -> pd.DataFrame:
    """Per case of Fig. 5: settled RMS STDs, and the final farthest agent from the CoM over the runs (Fig. 6)."""
    res, R = result.fig5, result.settings.spring_length
    d_end = res.max_distance[:, :, -1]
    return pd.DataFrame({
        "case": CASES,
        "settled position STD (m)": res.settled(res.std_p),
        "settled velocity STD (m/s)": res.settled(res.std_v),
        "median farthest agent (m)": np.median(d_end, axis=1),
        "worst run's farthest agent (m)": d_end.max(axis=1),
        "runs within R (fraction)": (d_end <= R).mean(axis=1),
    })


def beyond_table(result: FlockingResult) -> pd.DataFrame:
    """The sweep beyond the paper (:func:`beyond_study`) as computed in the run."""
    return result.beyond


# ----------------------------------------------------------------------------- cost (this machine)


def ekf_step_seconds(settings: FlockingSettings = SETTINGS, seed: int = 0, repeat: int = 5) -> float:
    """Median wall time (s) of one estimator step for all ``settings.n_agents`` agents, one run.

    One call of :func:`mascore.distributed_ekf.ekf_flocking_step` (update with
    the current neighbours, control on the own estimate, prediction with the
    Jacobian) on a random start of :func:`initial_states` with Fig. 5 noise,
    after one warm-up call; median of `repeat` calls. This machine, reported
    only (never asserted).

    Parameters
    ----------
    settings : FlockingSettings
        The study's settings (default :data:`SETTINGS`).
    seed : int
        Seed of the random start.
    repeat : int
        Timed calls.

    Returns
    -------
    float
        Seconds per step.

    Examples
    --------
    >>> from mascore.papers import song2023_flocking as flocking_paper
    >>> flocking_paper.ekf_step_seconds(repeat=1) > 0
    True
    """
    check_settings_type(settings, FlockingSettings, "settings")
    check_seed(seed, "seed")
    check_positive_int(repeat, "repeat")
    check_fits_in_memory(32.0 * repeat, "repeat", "the timings (one Python float each)")
    if repeat > MAX_REPEAT:
        raise ValueError(f"repeat must be an integer in [1, {MAX_REPEAT}] (timed repeats); got {repeat}")
    rng = np.random.default_rng([seed, 7])
    X = initial_states(rng, 1, settings)[0]
    X_hat, Sigma0 = initial_estimates(rng, X, settings)
    N = settings.n_agents
    Sigma = np.broadcast_to(Sigma0, (N, *Sigma0.shape))
    graph = proximity_graph(X[:, :settings.n_dim], settings.sensing_range)
    z, observed = measure(rng, X, graph, settings.R_fig5, allow_isolated=True)
    args = (X_hat, Sigma, z, observed, np.kron(np.eye(N), settings.R_fig5), settings.dt, settings.gains,
            np.kron(np.eye(N), settings.Q))
    return median_time(lambda: ekf_flocking_step(*args), repeat=repeat)


def _fig4_caption_values(result: FlockingResult) -> dict[str, float]:
    """The numbers the caption of Fig. 4 quotes: agent 1's statistical error in and out of range, the peak error."""
    s = fig4_statistics(result.fig4, result.settings.transient)
    return {"sigma_in": s["mean_sigma_neighbours"], "sigma_out": s["mean_sigma_non_neighbours"],
            "max_out": s["max_error_non_neighbours"], "transient": result.settings.transient}


def _beyond_caption_values(result: FlockingResult) -> dict[str, float]:
    """The band of the team-size sweep: the largest N with every case stable, the first N with one unstable."""
    by_n = result.beyond[result.beyond["r (m)"] == result.settings.sensing_range]
    stable = by_n["unstable"] == "-"
    unstable = by_n.loc[~stable, "N"]
    return {"n_stable": float(by_n.loc[stable, "N"].max()),
            "n_unstable": float(unstable.min()) if len(unstable) else float("nan")}


# ----------------------------------------------------------------------------- the study


FIGURES = (
    FigureSpec(
        "fig4", "Fig. 4",
        "One run of estimation-based flocking ($Q = I$, $R = I$, 2 x 4 grid start), seen by agent 1's filter: "
        "(a) initial and (b) final proximity networks with the sensing circles of radius $r = 150$ m; "
        "(c) true and (d) estimated trajectories (markers at the end: ▲ agent 1, ● its neighbours, "
        "□ and dashed lines its non-neighbours at the end); (e) agent 1's position error of every other agent "
        "and (f) its statistical error $\\sqrt{\\operatorname{tr}\\Sigma_{1,p_j}}$. Look for: (d) follows (c) "
        "closely; while an agent is in range, its statistical error (f) is small (on average {{sigma_in:.1f}} m "
        "after the first {{transient:.0f}} s); out of range it rises to a bounded plateau (on average "
        "{{sigma_out:.1f}} m), and the actual error (e) swings well above that plateau (up to {{max_out:.0f}} m after "
        "the first {{transient:.0f}} s); "
        "both drop at once when the agent comes back.",
        lambda result: plot_fig4(result.fig4, result.settings),
        lambda result: _fig4_caption_values(result),
    ),
    FigureSpec(
        "fig5", "Fig. 5",
        "RMS over 50 runs of the spread of (a) positions and (b) velocities about the team mean ($Q = I$, "
        "$R = 10\\,I$, the same initial states for the three cases): (i) flocking from measurements on the "
        "proximity graph, (ii) the same on a fixed fully-connected network, (iii) estimation-based flocking on "
        "the virtual fully-connected network. Look for: (ii) and (iii) (dashed and dotted) nearly coincide and "
        "settle far below (i) in position, somewhat below it in velocity; the shaded last 20 s give the settled "
        "values of the ledger.",
        lambda result: plot_fig5(result.fig5),
    ),
    FigureSpec(
        "fig6", "Fig. 6",
        "Final configurations of run 0 of the Monte Carlo of Fig. 5, with the proximity graph and the circle "
        "of radius $\\mathcal R = 120$ m about the centre of mass (+): (a) case (i), (b) case (iii), and "
        "(c) case (ii), which the paper does not draw. Look for: every agent of (b) and (c) inside the circle, "
        "the proximity-graph flock (a) spread well beyond it.",
        lambda result: plot_fig6(result.fig5, result.settings),
    ),
    FigureSpec(
        "flocking_beyond", "",
        "The three cases of Fig. 5 against the sensing range $r$ (left, $N = 8$) and the team size $N$ "
        "(right, $r = 150$ m), median of 2 runs of 40 s per point: (a), (b) farthest agent from the centre of "
        "mass at the end, with $\\mathcal R$; (c), (d) settled RMS position error of the estimators of (iii). "
        "Look for: (i) needs $r$ well above $\\mathcal R$ to stay inside it while (ii) and (iii) do not depend "
        "on $r$; the estimation error grows as $r$ shrinks or $N$ grows. The shaded band runs from "
        "the largest team at which all three cases are stable ($N$ = {{n_stable:.0f}}) to the first at which the "
        "fully-connected law, real (ii) or virtual (iii), has diverged with the paper's gains and $\\Delta t$ "
        "($N$ = {{n_unstable:.0f}}): stability is lost somewhere inside the band, and (ii) and (iii) have no point "
        "at its right end.",
        lambda result: plot_beyond(result.beyond, result.settings),
        lambda result: _beyond_caption_values(result),
    ),
)

TABLES = (
    TableSpec("fig5_fig6_flocking", "",
              "Per case of Fig. 5: settled RMS STDs (last 20 s) and the farthest agent from the centre of mass "
              "at the end (Fig. 6), over the 50 runs.", settled_table),
    TableSpec("flocking_beyond_sweep", "",
              "Beyond the paper: the sweep over the sensing range and the team size behind the figure "
              "flocking_beyond.", beyond_table),
)

#: The book's flocking chapter (``notebooks/song2023_flocking.ipynb``); ``REGISTRY`` of
#: :mod:`mascore.papers.song2023` holds it beside the rendezvous study.
STUDY = Study("flocking", "song2023_flocking", SETTINGS, run, FIGURES, TABLES, claims)

#: The flocking study under the name the chapter uses (its paper's registry is in :mod:`mascore.papers.song2023`).
FLOCKING_STUDY = STUDY


#: Errata and readings of the flocking part, for the report (appended to song2023's registry).
FLOCKING_ERRATA = (
    "Flocking, Fig. 4: the noise is 'the same as in the previous rendezvous problem'; we read it as Fig. 2's $R = I$, not Fig. 3's $R = 100\\,I$.",
    "Flocking, Fig. 5: the 'root-mean-square STD' is not defined; we read it as the spread of the agents about their mean, $\\sqrt{\\tfrac1N\\sum_i\\lVert p_i-\\bar p\\rVert^2}$, root-mean-square over the runs.",
    "Flocking, eqs. (38), (40): the EKF prediction assumes the other agents act on the true state, though each acts on its own estimate (the linear part carries this through eqs. (29)-(34)); the flocking filter is therefore somewhat over-confident: its mean squared error exceeds its variance in Fig. 4's run (the chapter gives the ratio).",
    "Flocking, Fig. 6: the bound $\\mathcal R$ holds only for a fully-connected flock: at a noiseless equilibrium every agent is within $\\mathcal R(N-1)/N$ of the centre of mass. With noise, case (iii) can exceed that in its worst run (the chapter gives the distances) but stays within $\\mathcal R$.",
    "Flocking, Fig. 6: case (i) fails because $r = 150$ m is only 30 m above $\\mathcal R$, not because it lacks an estimator: at $r = 200$ m the proximity-graph flock is as tight as the fully-connected one.",
)
