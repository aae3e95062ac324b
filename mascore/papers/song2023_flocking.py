"""Song et al. (2023), nonlinear part: estimation-based flocking, Figs. 4-6.

Scenarios of Sec. V-B of Song, Lee, Kwon, Shin and Oh, "Distributed Estimation
of Stochastic Multi-Agent Systems for Cooperative Control With a Virtual
Network", IEEE Trans. Systems, Man, and Cybernetics: Systems 53(4), 2023.
Algorithms live in :mod:`mascore.flocking` (eqs. (6)-(7), (39)-(40)) and
:mod:`mascore.distributed_ekf` (eqs. (35)-(40) with the update of
eqs. (16)-(20)); this module holds the paper's settings, the three cases of
Fig. 5, the figures and the ledger claims.

Settings from the paper (Table I and Sec. V): N = 8 agents in the plane
(n = 2), dt = 0.1 s, r = 150 m, (rho3, rho4) = (3, 1), (rho5, rho6) = (2, 1),
beta = 0.33, R = 120 m; process noise Q = I_{2n}; measurement noise R = I for
Fig. 4 ("the same as in the previous rendezvous problem", i.e. Fig. 2) and
R = 10 I for Figs. 5-6; 50 Monte Carlo runs.

Settings the paper leaves out, chosen here (one place):

* horizon ``T_FINAL`` = 60 s (600 steps): every case has settled by ~20 s;
* Monte Carlo initial positions uniform in a 300 m x 300 m square, redrawn
  until the proximity graph (r = 150 m) is connected; initial velocities
  uniform in [-5, 5] m/s per axis; the same initial states for all three
  cases (common random numbers), independent noise streams per case;
* Fig. 4 initial positions: a 2 x 4 grid with 100 m spacing (agent 1 at a
  corner, so that it starts with non-neighbours), velocities drawn as above;
* initial estimates: every agent's prior of the team is the truth plus a draw
  from ``N(0, Sigma0)``, ``Sigma0 = I_N kron diag(10^2, 10^2, 1, 1)``
  (10 m, 1 m/s), the same ``Sigma0`` for all agents (Assumption 2);
* ``d_min`` = 1e-6 m for coincident agents (see :mod:`mascore.flocking`);
* "root-mean-square STD": the spread of the agents about their mean,
  ``sqrt(mean_i |p_i - p_bar|^2)`` (and likewise for velocities), RMS over
  the runs, reported as its time average over the last 20 s.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from ..distributed_ekf import EstimatedFlockingRun, ekf_flocking_step, simulate_estimation_based_flocking
from ..flocking import (
    DivergenceError,
    FlockingGains,
    FlockingRun,
    flock_spread,
    max_distance_from_centre,
    simulate_measured_flocking,
)
from ..graphs import is_connected, proximity_graph
from .._progress import progress_bar
from .._timing import median_time
from ..ledger import Claim
from ..plotting import agent_colors, plot_graph, save_figure
from ..sensing import measure

__all__ = [
    "N_AGENTS",
    "N_DIM",
    "DT",
    "SENSING_RANGE",
    "GAINS",
    "Q_AGENT",
    "R_FIG4",
    "R_FIG5",
    "T_FINAL",
    "N_RUNS",
    "SIGMA0_AGENT",
    "CASES",
    "initial_states",
    "fig4_initial_state",
    "initial_estimates",
    "Fig5Result",
    "run_fig4",
    "run_fig5",
    "plot_fig4",
    "plot_fig5",
    "plot_fig6",
    "fig4_claim",
    "fig5_claims",
    "fig6_claim",
    "flocking_claims_and_figures",
    "ekf_step_seconds",
    "beyond_study",
    "plot_beyond",
]

# --- Table I
N_AGENTS = 8
N_DIM = 2
DT = 0.1  # s
SENSING_RANGE = 150.0  # m
GAINS = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
# --- Sec. V
Q_AGENT = np.eye(2 * N_DIM)  # process noise of one agent, Q = I_{2n}
R_FIG4 = np.eye(2 * N_DIM)  # Fig. 4: R = I (noise "as in the rendezvous problem", Fig. 2)
R_FIG5 = 10.0 * np.eye(2 * N_DIM)  # Figs. 5-6: R = 10 I
N_RUNS = 50
# --- chosen here (the paper does not state them)
T_FINAL = 60.0  # s
BOX = 300.0  # m, side of the square of initial positions
V0_MAX = 5.0  # m/s, initial velocities uniform in [-V0_MAX, V0_MAX] per axis
SIGMA0_AGENT = np.diag([10.0**2, 10.0**2, 1.0, 1.0])  # prior covariance of one agent's state
SETTLED_WINDOW = 20.0  # s, window at the end over which converged values are averaged

#: The three cases of Fig. 5.
CASES = ("(i) measured, proximity graph", "(ii) measured, fully connected", "(iii) estimated, virtual full")


def n_steps(t_final: float = T_FINAL) -> int:
    """Number of steps of the horizon `t_final` (s)."""
    return int(round(t_final / DT))


def initial_states(rng: np.random.Generator, n_runs: int, n_agents: int = N_AGENTS) -> np.ndarray:
    """Random initial team states with a connected proximity graph, ``(n_runs, N, 4)``."""
    positions = np.empty((n_runs, n_agents, N_DIM))
    for k in range(n_runs):
        while True:
            p = rng.uniform(0.0, BOX * np.sqrt(n_agents / N_AGENTS), (n_agents, N_DIM))
            if is_connected(proximity_graph(p, SENSING_RANGE)):
                positions[k] = p
                break
    velocities = rng.uniform(-V0_MAX, V0_MAX, (n_runs, n_agents, N_DIM))
    return np.concatenate([positions, velocities], axis=-1)


def fig4_initial_state(rng: np.random.Generator) -> np.ndarray:
    """Fig. 4 initial state: 2 x 4 grid, 100 m spacing, random velocities, ``(N, 4)``."""
    cols, rows = np.meshgrid(np.arange(4), np.arange(2))
    p = 100.0 * np.stack([cols.ravel(), rows.ravel()], axis=-1)
    v = rng.uniform(-V0_MAX, V0_MAX, (N_AGENTS, N_DIM))
    return np.concatenate([p, v], axis=-1)


def initial_estimates(rng: np.random.Generator, X0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every agent's prior of the team: truth + ``N(0, Sigma0)``; returns ``(X_hat0, Sigma0)``.

    ``X_hat0`` has shape ``(..., N, N, 4)`` for ``X0`` ``(..., N, 4)``.
    """
    N = X0.shape[-2]
    std = np.sqrt(np.diag(SIGMA0_AGENT))
    X_hat0 = X0[..., None, :, :] + std * rng.standard_normal((*X0.shape[:-2], N, N, 2 * N_DIM))
    return X_hat0, np.kron(np.eye(N), SIGMA0_AGENT)


def run_fig4(seed: int, sensing_range: float = SENSING_RANGE) -> EstimatedFlockingRun:
    """The single run of Fig. 4: estimation-based flocking (case (iii)), R = I, observer agent 1."""
    rng = np.random.default_rng([seed, 4])
    X0 = fig4_initial_state(rng)
    X_hat0, Sigma0 = initial_estimates(rng, X0)
    return simulate_estimation_based_flocking(
        X0, X_hat0, Sigma0, n_steps(), DT, GAINS, Q_AGENT, R_FIG4, rng, sensing_range, observer=0
    )


@dataclass(frozen=True)
class Fig5Result:
    """The three cases of Fig. 5 over the Monte Carlo runs.

    Attributes
    ----------
    t : (T+1,) ndarray
        Times (s).
    std_p, std_v : (3, T+1) ndarrays
        RMS over runs of the position (m) and velocity (m/s) spread, per case.
    final : (3, n_runs, N, 4) ndarray
        Team states at the end, per case and run (Fig. 6).
    max_distance : (3, n_runs, T+1) ndarray
        Largest distance (m) of an agent from the centre of mass.
    trajectories : (3, T+1, N, 4) ndarray
        True states of run 0 per case (shown in Fig. 6).
    rms_error : (n_runs, T+1) ndarray
        Case (iii): RMS position error (m) over all estimators and agents.
    diverged : tuple of 3 bool
        Cases whose sampled loop blew up (their arrays are NaN); never with
        the paper's settings, but from about N = 18 agents with Table I gains.
    """

    t: np.ndarray
    std_p: np.ndarray
    std_v: np.ndarray
    final: np.ndarray
    max_distance: np.ndarray
    trajectories: np.ndarray
    rms_error: np.ndarray
    diverged: tuple = (False, False, False)

    def settled(self, series: np.ndarray) -> np.ndarray:
        """Time average of ``series[..., t]`` over the last ``SETTLED_WINDOW`` seconds."""
        return series[..., self.t >= self.t[-1] - SETTLED_WINDOW].mean(axis=-1)


def run_fig5(seed: int, n_runs: int = N_RUNS, sensing_range: float = SENSING_RANGE,
             n_agents: int = N_AGENTS, R: np.ndarray = R_FIG5, t_final: float = T_FINAL,
             progress: bool = False) -> Fig5Result:
    """Monte Carlo of the three cases of Fig. 5 (and the configurations of Fig. 6).

    The defaults are the paper's settings; `n_runs`, `sensing_range`,
    `n_agents` (initial square scaled by ``sqrt(N / 8)`` to keep the density),
    `R` (measurement noise per agent) and `t_final` (s) may be changed.
    """
    root = np.random.SeedSequence([seed, 5])
    init_ss, *case_ss = root.spawn(4)
    rng0 = np.random.default_rng(init_ss)
    X0 = initial_states(rng0, n_runs, n_agents)
    X_hat0, Sigma0 = initial_estimates(rng0, X0)
    T = n_steps(t_final)
    simulations = (
        lambda: simulate_measured_flocking(X0, T, DT, GAINS, Q_AGENT, R, np.random.default_rng(case_ss[0]),
                                           sensing_range),
        lambda: simulate_measured_flocking(X0, T, DT, GAINS, Q_AGENT, R, np.random.default_rng(case_ss[1]), None),
        lambda: simulate_estimation_based_flocking(X0, X_hat0, Sigma0, T, DT, GAINS, Q_AGENT, R,
                                                   np.random.default_rng(case_ss[2]), sensing_range,
                                                   progress=progress),
    )
    runs: list[FlockingRun | EstimatedFlockingRun | None] = []
    for simulate in simulations:
        try:
            runs.append(simulate())
        except DivergenceError:
            runs.append(None)
    nan_X = np.full((n_runs, T + 1, n_agents, 2 * N_DIM), np.nan)
    Xs = [nan_X if r is None else r.X for r in runs]
    spreads = [flock_spread(X) for X in Xs]  # each (n_runs, T+1)
    rms = lambda a: np.sqrt(np.mean(a**2, axis=0))  # noqa: E731
    return Fig5Result(
        t=DT * np.arange(T + 1),
        std_p=np.stack([rms(sp[0]) for sp in spreads]),
        std_v=np.stack([rms(sp[1]) for sp in spreads]),
        final=np.stack([X[:, -1] for X in Xs]),
        max_distance=np.stack([max_distance_from_centre(X) for X in Xs]),
        trajectories=np.stack([X[0] for X in Xs]),
        rms_error=np.full((n_runs, T + 1), np.nan) if runs[2] is None else runs[2].rms_error,
        diverged=tuple(r is None for r in runs),
    )


# ----------------------------------------------------------------------------- figures


def plot_fig4(run: EstimatedFlockingRun, fig: plt.Figure | None = None) -> plt.Figure:
    """Song et al. 2023, Fig. 4 (a)-(f) from a :func:`run_fig4` run."""
    fig = fig or plt.figure(figsize=(13, 8.5))
    axes = fig.subplots(2, 3)
    X, Xh, A, t = run.X, run.X_hat, run.adjacency, run.t
    N = X.shape[-2]
    o = run.observer
    colors = agent_colors(N)
    plot_graph(X[0, :, :2], A[0], ax=axes[0, 0], sensing_range=SENSING_RANGE)
    axes[0, 0].set_title("(a) initial network")
    plot_graph(X[-1, :, :2], A[-1], ax=axes[0, 1], sensing_range=SENSING_RANGE)
    links = int(np.triu(A[-1], 1).sum())
    axes[0, 1].set_title(f"(b) network at the end ({links} of {N * (N - 1) // 2} links)")
    nbr_end = A[-1, o]
    for ax, P, title in ((axes[0, 2], X, "(c) true trajectories"),
                         (axes[1, 0], Xh, f"(d) trajectories estimated by agent {o + 1}")):
        for j in range(N):
            ax.plot(P[:, j, 0], P[:, j, 1], color=colors[j], lw=0.8)
            marker = "^" if j == o else ("o" if nbr_end[j] else "s")
            ax.plot(*P[-1, j, :2], marker, color=colors[j], ms=7, mfc="none" if marker == "s" else colors[j])
        ax.set_xlabel("x (m)")
        ax.set_ylabel("y (m)")
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(title)
    handles = [plt.Line2D([], [], ls="none", marker=mk, color="0.3", mfc=fc, label=lab)
               for mk, fc, lab in (("^", "0.3", f"agent {o + 1}"), ("o", "0.3", f"neighbour of {o + 1} at the end"),
                                   ("s", "none", f"non-neighbour of {o + 1} at the end"))]
    axes[1, 0].legend(handles=handles, fontsize="x-small", loc="best")
    err = np.linalg.norm(Xh[..., :2] - X[..., :2], axis=-1)
    stat = np.sqrt(run.position_variance)
    for j in range(N):
        if j == o:
            continue
        style = "-" if nbr_end[j] else "--"
        axes[1, 1].plot(t, err[:, j], style, color=colors[j], lw=0.8, label=f"agent {j + 1}")
        axes[1, 2].plot(t, stat[:, j], style, color=colors[j], lw=0.8, label=f"agent {j + 1}")
    axes[1, 1].set_title(f"(e) agent {o + 1}'s position error")
    axes[1, 2].set_title(f"(f) agent {o + 1}'s statistical error")
    axes[1, 1].set_ylabel("|p_hat - p| (m)")
    axes[1, 2].set_ylabel("sqrt(trace Sigma_pos) (m)")
    for ax in axes[1, 1:]:
        ax.set_xlabel("time (s)")
        ax.legend(ncol=2, fontsize="x-small")
    fig.tight_layout()
    return fig


def plot_fig5(res: Fig5Result, fig: plt.Figure | None = None) -> plt.Figure:
    """Song et al. 2023, Fig. 5 (a) position and (b) velocity RMS STD over time."""
    fig = fig or plt.figure(figsize=(11, 3.8))
    axes = fig.subplots(1, 2)
    for c, label in enumerate(CASES):
        axes[0].plot(res.t, res.std_p[c], label=label)
        axes[1].plot(res.t, res.std_v[c], label=label)
    axes[0].set_ylabel("RMS STD of positions (m)")
    axes[1].set_ylabel("RMS STD of velocities (m/s)")
    axes[0].set_title("(a) position")
    axes[1].set_title("(b) velocity")
    for ax in axes:
        ax.set_xlabel("time (s)")
        ax.legend()
    fig.tight_layout()
    return fig


def plot_fig6(res: Fig5Result, run: int = 0, fig: plt.Figure | None = None) -> plt.Figure:
    """Song et al. 2023, Fig. 6: converged configurations with the circle of radius R about the CoM.

    Panels: (a) case (i), (b) case (iii) as in the paper, plus case (ii) for reference.
    """
    fig = fig or plt.figure(figsize=(13, 4.4))
    axes = fig.subplots(1, 3)
    for ax, c, title in zip(axes, (0, 2, 1), ("(a) case (i)", "(b) case (iii)", "case (ii) (reference)")):
        p = res.final[c, run, :, :2]
        A = proximity_graph(p, SENSING_RANGE)
        plot_graph(p, A, ax=ax)
        com = p.mean(axis=0)
        ax.add_patch(plt.Circle(com, GAINS.R, fill=False, color="k", lw=1.2))
        ax.plot(*com, "k+", ms=10)
        dmax = np.linalg.norm(p - com, axis=-1).max()
        ax.set_title(f"{title}\nmax |p_i - CoM| = {dmax:.0f} m (R = {GAINS.R:.0f} m)")
        ax.autoscale_view()
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- claims


def fig4_claim(run: EstimatedFlockingRun, transient: float = 5.0) -> Claim:
    """``song2023/fig4-non-neighbour-error-bounded`` from a :func:`run_fig4` run.

    Over ``t >= transient`` and the agents other than the observer, split the
    time steps by whether the agent is the observer's neighbour at that step.
    Holds when (1) the mean position error is larger for non-neighbours than
    for neighbours, (2) at least 95 % of the non-neighbour errors lie within
    three statistical errors ``3 sqrt(trace Sigma_pos)``, (3) that
    statistical error does not grow: its maximum over the second half of the
    window is at most 1.5 times its maximum over the first half, and (4) it
    drops sharply when an agent comes back into range after at least 1 s
    out of it: the median ratio of the statistical error just after to just
    before is below 0.5.
    """
    o = run.observer
    late = run.t >= transient
    others = np.arange(run.X.shape[-2]) != o
    err = np.linalg.norm(run.X_hat[..., :2] - run.X[..., :2], axis=-1)[late][:, others]
    sig = np.sqrt(run.position_variance)[late][:, others]
    nbr = run.adjacency[late, o][:, others]
    if nbr.all() or not nbr.any():
        raise ValueError("the Fig. 4 run needs steps with both neighbours and non-neighbours of the observer")
    half = np.arange(late.sum()) >= late.sum() // 2
    sig_nn = np.where(~nbr, sig, 0.0)
    # statistical error just after / just before an agent comes into range after >= 1 s out of it
    out_for = np.zeros_like(sig)  # seconds out of range so far
    for k in range(1, len(sig)):
        out_for[k] = np.where(nbr[k], 0.0, out_for[k - 1] + DT)
    enters = ~nbr[:-1] & nbr[1:] & (out_for[:-1] >= 1.0)
    drops = sig[1:][enters] / sig[:-1][enters]
    value = {
        "mean_error_neighbours_m": float(err[nbr].mean()),
        "mean_error_non_neighbours_m": float(err[~nbr].mean()),
        "max_error_non_neighbours_m": float(err[~nbr].max()),
        "mean_statistical_error_neighbours_m": float(sig[nbr].mean()),
        "mean_statistical_error_non_neighbours_m": float(sig[~nbr].mean()),
        "fraction_non_neighbour_errors_within_3_sigma": float((err[~nbr] <= 3 * sig[~nbr]).mean()),
        "max_statistical_error_non_neighbours_first_half_m": float(sig_nn[~half].max()),
        "max_statistical_error_non_neighbours_second_half_m": float(sig_nn[half].max()),
        "fraction_of_steps_non_neighbour": float((~nbr).mean()),
        "entries_into_range_after_1s_out": int(enters.sum()),
        "median_drop_ratio_of_statistical_error_on_entering_range": float(np.median(drops)) if drops.size else 1.0,
        "mean_squared_error_over_mean_variance": float((err**2).mean() / (sig**2).mean()),
    }
    holds = (
        value["mean_error_non_neighbours_m"] > value["mean_error_neighbours_m"]
        and value["fraction_non_neighbour_errors_within_3_sigma"] >= 0.95
        and value["max_statistical_error_non_neighbours_second_half_m"]
        <= 1.5 * value["max_statistical_error_non_neighbours_first_half_m"]
        and value["median_drop_ratio_of_statistical_error_on_entering_range"] < 0.5
    )
    return Claim.qualitative(
        "song2023/fig4-non-neighbour-error-bounded", "Fig. 4(e)-(f), Sec. V-B",
        "Agent 1's position errors of its non-neighbours are larger than those of its neighbours "
        "but stay bounded; its statistical error of an agent drops sharply when that agent comes into range.",
        value, holds,
        note=(f"One run, N=8, r=150 m, Q=I, R=I (the rendezvous noise levels, as the text says), "
              f"horizon {T_FINAL:.0f} s, t >= {transient:.0f} s; 2x4 grid start with 100 m spacing (our choice). "
              "'Bounded' is made checkable as: >= 95 % of non-neighbour errors within 3 statistical errors "
              "and no growth of the statistical error between the two halves of the run (<= 1.5x); "
              "'sharp drop' as: median ratio after/before an agent enters range (after >= 1 s out) < 0.5. The filter is "
              f"somewhat over-confident (mean squared error {value['mean_squared_error_over_mean_variance']:.2f}x "
              "its variance; 1.2-1.7x over seeds 1-3) because eq. (38) "
              "ignores that the other agents act on their own estimates."),
    )


def fig5_claims(res: Fig5Result) -> list[Claim]:
    """``song2023/fig5-position-std`` and ``song2023/fig5-velocity-std``.

    Each holds when the settled RMS STD of cases (ii) and (iii) is below that
    of case (i) and case (iii) recovers at least 75 % of the improvement of
    (ii) over (i): ``|(iii) - (ii)| <= 0.25 ((i) - (ii))``.
    """
    claims = []
    for key, plural, series, unit in (("position", "positions", res.std_p, "m"),
                                      ("velocity", "velocities", res.std_v, "m/s")):
        s = res.settled(series)
        holds = s[1] < s[0] and s[2] < s[0] and abs(s[2] - s[1]) <= 0.25 * (s[0] - s[1])
        claims.append(Claim.qualitative(
            f"song2023/fig5-{key}-std", f"Fig. 5({'a' if key == 'position' else 'b'}), Sec. V-B",
            f"The converged RMS STD of the agents' {plural} with estimation-based flocking (iii) is similar "
            f"to that of flocking on a fixed fully-connected network (ii), and both are below "
            f"conventional flocking on the proximity graph (i).",
            [float(v) for v in s], holds,
            note=(f"value = settled RMS STD ({unit}) of cases [(i), (ii), (iii)], time average over the last "
                  f"{SETTLED_WINDOW:.0f} s of {T_FINAL:.0f} s, {res.final.shape[1]} runs, Q=I, R=10I. "
                  "STD = sqrt(mean_i |x_i - mean_j x_j|^2), RMS over runs (our reading of 'root mean "
                  "square STD'). 'Similar' read as |(iii)-(ii)| <= 0.25 ((i)-(ii)). The paper prints no "
                  "numbers, so the claim is qualitative."),
        ))
    return claims


def fig6_claim(res: Fig5Result) -> Claim:
    """``song2023/fig6-within-boundary``: largest distance from the CoM at the end vs R.

    Holds when, at the final step, every agent is within R of the centre of
    mass in at least 95 % of the runs for cases (ii) and (iii), and in at most
    5 % of the runs for case (i).
    """
    d_end = res.max_distance[:, :, -1]  # (3, runs)
    frac = (d_end <= GAINS.R).mean(axis=1)
    value = {
        "max_distance_run0_m": [float(v) for v in d_end[:, 0]],
        "max_distance_median_over_runs_m": [float(v) for v in np.median(d_end, axis=1)],
        "max_distance_worst_run_m": [float(v) for v in d_end.max(axis=1)],
        "fraction_of_runs_within_R": [float(v) for v in frac],
        "R_m": GAINS.R,
        "equilibrium_bound_R_(N-1)/N_m": GAINS.R * (res.final.shape[2] - 1) / res.final.shape[2],
    }
    holds = frac[1] >= 0.95 and frac[2] >= 0.95 and frac[0] <= 0.05
    N = res.final.shape[2]
    bound = GAINS.R * (N - 1) / N
    med, worst = np.median(d_end, axis=1), d_end.max(axis=1)
    return Claim.qualitative(
        "song2023/fig6-within-boundary", "Fig. 6, Sec. V-B",
        "At convergence every agent lies within R = 120 m of the centre of mass with estimation-based "
        "flocking (iii) (as with a fully-connected network (ii)), but not with conventional flocking on "
        "the proximity graph (i).",
        value, holds,
        note=("Lists are cases [(i), (ii), (iii)] at t = "
              f"{res.t[-1]:.0f} s over {d_end.shape[1]} runs (Q=I, R=10I); verdict: holds when >= 95 % of the "
              "runs end with every agent within R for (ii) and (iii), and <= 5 % do for (i). Without noise, a "
              "fully-connected equilibrium has N (p_i - CoM) = R sum_j (p_i - p_j)/|p_i - p_j|, so "
              f"|p_i - CoM| <= R (N-1)/N = {bound:.0f} m for N = {N}: the spring rest length R bounds the flock "
              "only when every pair interacts. Noise moves the flocks off that equilibrium: medians "
              f"{med[1]:.0f} m (ii) and {med[2]:.0f} m (iii), worst runs {worst[1]:.0f} m and {worst[2]:.0f} m "
              f"({'above' if worst[2] > bound else 'below'} the noiseless bound for (iii), whose agents act on "
              "estimates and so feel perturbed springs; the margin to R is what the claim tests). "
              f"On the proximity graph (r = {SENSING_RANGE:.0f} m, only {SENSING_RANGE - GAINS.R:.0f} m above the "
              "rest length) agents settle about R from their neighbours and feel no pull from the others, so "
              f"the flock spreads out as a lattice of spacing ~R (median {med[0]:.0f} m, "
              f"{100 * frac[0]:.0f} % of runs within R). This depends on r, not on the estimator: at r = 200 m "
              "case (i) is as tight as (ii) (see the notebook's beyond-the-paper study)."),
    )


def flocking_claims_and_figures(out_dir: Path | str, seed: int) -> list[Claim]:
    """Rebuild Figs. 4-6 into ``out_dir/figures`` and return the four flocking claims."""
    out_dir = Path(out_dir)
    run4 = run_fig4(seed)
    save_figure(plot_fig4(run4), out_dir / "figures" / "fig4.png")
    res = run_fig5(seed, progress=True)
    save_figure(plot_fig5(res), out_dir / "figures" / "fig5.png")
    save_figure(plot_fig6(res), out_dir / "figures" / "fig6.png")
    tables = out_dir / "tables"
    tables.mkdir(parents=True, exist_ok=True)
    rows = ["case,settled_std_position_m,settled_std_velocity_m_per_s,median_final_max_distance_m"]
    for c, label in enumerate(CASES):
        rows.append(f"\"{label}\",{res.settled(res.std_p[c]):.4f},{res.settled(res.std_v[c]):.4f},"
                    f"{np.median(res.max_distance[c, :, -1]):.4f}")
    (tables / "fig5_fig6_flocking.csv").write_text("\n".join(rows) + "\n")
    return [fig4_claim(run4), *fig5_claims(res), fig6_claim(res)]


# ----------------------------------------------------------------------------- beyond the paper


def ekf_step_seconds(n_agents: int = N_AGENTS, sensing_range: float = SENSING_RANGE, seed: int = 0,
                     repeat: int = 5) -> float:
    """Median wall time (s) of one estimator step for all `n_agents` agents, one run.

    One call of :func:`mascore.distributed_ekf.ekf_flocking_step` (update with
    the current neighbours, control on the own estimate, prediction with the
    Jacobian) on a random start of :func:`initial_states` with Fig. 5 noise,
    after one warm-up call; median of `repeat` calls. This machine, reported
    only (never asserted).
    """
    rng = np.random.default_rng([seed, 7])
    X = initial_states(rng, 1, n_agents)[0]
    X_hat, Sigma0 = initial_estimates(rng, X)
    Sigma = np.broadcast_to(Sigma0, (n_agents, *Sigma0.shape))
    z, observed = measure(rng, X, proximity_graph(X[:, :N_DIM], sensing_range), R_FIG5, allow_isolated=True)
    args = (X_hat, Sigma, z, observed, np.kron(np.eye(n_agents), R_FIG5), DT, GAINS,
            np.kron(np.eye(n_agents), Q_AGENT))
    return median_time(lambda: ekf_flocking_step(*args), repeat=repeat)


def beyond_study(seed: int, sensing_ranges=(130.0, 150.0, 200.0, 250.0), sizes=(4, 8, 12, 16, 20, 32),
                 n_runs: int = 4, t_final: float = 40.0, progress: bool = False):
    """Flock size and estimation error against the sensing range r (N = 8) and the team size N (r = 150 m).

    Not in the paper. For each setting, the three cases of Fig. 5 are run with
    the Fig. 5 noise (Q = I, R = 10 I); reported: the median over runs of the
    final largest distance from the centre of mass for cases (i)-(iii), the
    settled RMS position error of all estimators in case (iii), which cases
    are unstable (blew up past ``DIVERGENCE_LIMIT``, or ended with an agent
    farther than 10 R from the centre of mass), and the wall time per step of
    the three cases together (all runs, this machine; a diverged case stops
    early, so compare it only between stable settings) and the cost of one
    step of the estimator, :func:`ekf_step_seconds` (N filters of size 4N).

    Returns
    -------
    pandas.DataFrame
        One row per (N, r).
    """
    import time

    import pandas as pd

    settings = [(N_AGENTS, r) for r in sensing_ranges] + [(N, SENSING_RANGE) for N in sizes if N != N_AGENTS]
    rows = []
    for N, r in progress_bar(settings, enabled=progress, desc="beyond"):
        start = time.perf_counter()
        res = run_fig5(seed, n_runs=n_runs, sensing_range=r, n_agents=N, t_final=t_final)
        elapsed = time.perf_counter() - start
        d_end = np.median(res.max_distance[:, :, -1], axis=1)
        rows.append({
            "N": N, "r_m": r,
            "max_dist_i_m": d_end[0], "max_dist_ii_m": d_end[1], "max_dist_iii_m": d_end[2],
            "rms_est_error_iii_m": float(res.settled(np.sqrt(np.mean(res.rms_error**2, axis=0)))),
            "unstable": ",".join(c for c, d, dist in zip(("(i)", "(ii)", "(iii)"), res.diverged, d_end)
                                 if d or dist > 10 * GAINS.R) or "-",
            "wall_s_per_step_all_cases": elapsed / n_steps(t_final),
            "ekf_step_ms": 1e3 * ekf_step_seconds(N, r, seed),
        })
    return pd.DataFrame(rows).sort_values(["N", "r_m"]).reset_index(drop=True)


def plot_beyond(table, fig: plt.Figure | None = None) -> plt.Figure:
    """Largest distance from the CoM, estimation error and estimator cost against r (N = 8) and N (r = 150 m)."""
    fig = fig or plt.figure(figsize=(16, 3.8))
    axes = fig.subplots(1, 4)
    by_r = table[table["N"] == N_AGENTS]
    by_n = table[table["r_m"] == SENSING_RANGE]
    for ax, data, x, xlabel in ((axes[0], by_r, "r_m", "sensing range r (m), N = 8"),
                                (axes[1], by_n, "N", "number of agents N, r = 150 m")):
        for col, label in (("max_dist_i_m", "(i)"), ("max_dist_ii_m", "(ii)"), ("max_dist_iii_m", "(iii)")):
            ax.plot(data[x], data[col], "o-", label=label)
        ax.axhline(GAINS.R, color="k", ls=":", label="R")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("final max |p_i - CoM| (m)")
        ax.legend()
    axes[2].plot(by_n["N"], by_n["rms_est_error_iii_m"], "o-", label="vs N (r = 150 m)")
    axes[2].set_xlabel("number of agents N")
    axes[2].set_ylabel("settled RMS position error, case (iii) (m)")
    ax2 = axes[2].twiny()
    ax2.plot(by_r["r_m"], by_r["rms_est_error_iii_m"], "s--", color="C3", label="vs r (N = 8)")
    ax2.set_xlabel("sensing range r (m)")
    ax2.grid(False)
    lines = axes[2].get_lines() + ax2.get_lines()
    axes[2].legend(lines, [ln.get_label() for ln in lines])
    if "ekf_step_ms" in by_n:
        axes[3].loglog(by_n["N"], by_n["ekf_step_ms"], "o-", label="one step, all N filters")
        ref = by_n["ekf_step_ms"].iloc[-1] * (by_n["N"] / by_n["N"].iloc[-1]) ** 4
        axes[3].loglog(by_n["N"], ref, "k:", label="~ N^4")
        axes[3].set_xlabel("number of agents N")
        axes[3].set_ylabel("estimator cost per step (ms)")
        axes[3].legend()
    fig.tight_layout()
    return fig
