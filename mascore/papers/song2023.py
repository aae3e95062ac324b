"""Song, Lee, Kwon, Shin and Oh (2023), linear part: estimation-based rendezvous.

The scenarios of Sec. V.A in one place: Table I, Fig. 2 (fixed topology, every
agent's whole-team estimate, error vs. its covariance) and Fig. 3 (50-run Monte
Carlo, spread of the team with measurement-based vs estimation-based control),
plus the checks of Theorem 1 and of filter consistency (NEES).

Settings the paper leaves out are chosen here and marked "(our choice)".
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from .. import distributed_kf as dkf
from .._timing import median_time
from ..agents import double_integrator
from ..graphs import is_connected, laplacian, proximity_graph, ring_graph
from ..kalman import nees_interval
from ..ledger import Claim
from ..plotting import agent_colors, plot_graph, plot_trajectories, save_figure
from ..rendezvous import (
    RendezvousResult,
    expected_spread,
    rendezvous_gain,
    simulate_rendezvous,
    team_spread,
)
from ..sensing import measure, stacked_measurement

__all__ = [
    "TABLE_I",
    "SETTINGS",
    "RendezvousSetup",
    "setup",
    "random_initial_states",
    "estimator_step_seconds",
    "Fig2Result",
    "fig2",
    "Fig3Result",
    "fig3",
    "theorem1",
    "process_noise_study",
    "plot_fig2",
    "plot_fig3",
    "plot_theorem1",
    "linear_claims",
    "reproduce",
]

#: Table I of the paper (rendezvous rows; the flocking rows are used by
#: :mod:`mascore.papers.song2023_flocking`).
TABLE_I = {
    "N": 8,            # number of agents
    "n": 2,            # spatial dimension
    "dt": 0.1,         # sampling time (s)
    "r": 150.0,        # sensing/communication range (m)
    "rho1": 0.5,       # rendezvous gain on positions
    "rho2": 1.5,       # rendezvous gain on velocities
    "rho3": 3.0, "rho4": 1.0, "rho5": 2.0, "rho6": 1.0, "beta": 0.33, "R_flock": 120.0,
}

#: Settings of Figs. 2-3. Q and R are the paper's (Sec. V.A); the rest is our choice.
SETTINGS = {
    "fig2": {"q": 1.0, "r": 1.0, "n_runs": 50},   # Q = I_2n, R = I_2nN (paper)
    "fig3": {"q": 1.0, "r": 100.0, "n_runs": 50},  # Q = I_2n, R = 100 I_2nN, 50 runs (paper)
    "horizon": 40.0,          # s (our choice; the spread settles within about 15 s)
    "converged_from": 20.0,   # s: "converged" STD = time average over [20, 40] s (our choice)
    "box": 400.0,             # initial positions uniform in [0, box]^2 m (our choice)
    "v0": 5.0,                # initial velocities uniform in [-v0, v0]^2 m/s (our choice)
    "sigma_p0": 10.0,         # initial estimate error std of each position coordinate, m (our choice)
    "sigma_v0": 1.0,          # ... of each velocity coordinate, m/s (our choice)
    "max_edge_fraction": 0.6,  # Fig. 2 topology: at most 60 % of the pairs are neighbours (our choice)
}


@dataclass(frozen=True)
class RendezvousSetup:
    """Agent model and gains from Table I."""

    A: np.ndarray
    B: np.ndarray
    K: np.ndarray
    n_agents: int
    n: int
    dt: float
    sensing_range: float

    @property
    def m(self) -> int:
        """Agent state dimension 2n."""
        return 2 * self.n

    @property
    def BK(self) -> np.ndarray:
        return self.B @ self.K

    def P0(self) -> np.ndarray:
        """Per-agent block of the initial estimate covariance (our choice)."""
        n = self.n
        return np.diag([SETTINGS["sigma_p0"] ** 2] * n + [SETTINGS["sigma_v0"] ** 2] * n)


def setup(n_agents: int | None = None) -> RendezvousSetup:
    """Table I model: double integrator, ``K = [rho1 I, rho2 I]``."""
    t = TABLE_I
    agent = double_integrator(t["n"], t["dt"])
    return RendezvousSetup(
        A=agent.A, B=agent.B, K=rendezvous_gain(t["rho1"], t["rho2"], t["n"]),
        n_agents=t["N"] if n_agents is None else n_agents, n=t["n"], dt=t["dt"], sensing_range=t["r"],
    )


def estimator_step_seconds(n_agents: int, repeat: int = 5, plain_repeat: int = 3) -> dict[str, float]:
    """Median wall time (s) of one estimation-based filter step, structured against plain.

    Both advance all ``n_agents`` whole-team estimates and the full augmented
    covariance (eqs. (14), (29)-(34), (16)-(20)) once, on a ring with Q = R = I:
    the structured path (:func:`mascore.distributed_kf.eb_predict` +
    ``eb_update``) and the one written straight from the equations
    (``plain_estimation_based_step``). This machine; reported, never asserted.

    Returns
    -------
    dict
        ``structured_s``, ``plain_s`` (s per step) and ``speedup``.
    """
    s = setup(n_agents)
    noise = np.eye(2 * s.n)
    model = dkf.team_filter_model(s.A, s.B, s.K, noise, noise, n_agents)
    rng = np.random.default_rng(n_agents)
    adj = ring_graph(n_agents)
    L = laplacian(adj)
    Sig = dkf.eb_initial_covariance(model, s.P0(), common=False)
    X_hat = rng.normal(size=(1, n_agents, n_agents, 2 * s.n))
    Z, S = measure(rng, rng.normal(size=(1, n_agents, 2 * s.n)), adj, noise)
    Sig_full = dkf.expand_covariance(Sig[0], model.kron)
    z = [stacked_measurement(Z[0], S[0], i) for i in range(n_agents)]
    structured = median_time(lambda: dkf.eb_update(model, *dkf.eb_predict(model, X_hat, Sig, L), Z, S[0]),
                             repeat=repeat)
    plain = median_time(lambda: dkf.plain_estimation_based_step(
        X_hat[0].reshape(n_agents, -1), Sig_full, s.A, model.BK, noise, model.R, adj, z), repeat=plain_repeat)
    return {"structured_s": structured, "plain_s": plain, "speedup": plain / structured}


def random_initial_states(
    rng: np.random.Generator, s: RendezvousSetup, max_edge_fraction: float = 1.0, max_tries: int = 10_000
) -> tuple[np.ndarray, np.ndarray]:
    """Random initial states whose proximity graph is connected and makes (43) observable.

    Positions uniform in ``[0, box]^2`` m, velocities uniform in
    ``[-v0, v0]^2`` m/s (our choice); rejected and redrawn until the graph is
    connected, system (43) is observable for every agent (Sec. V.A: "chosen to
    meet the connectivity and observability requirements") and at most
    `max_edge_fraction` of the pairs are neighbours.

    Returns
    -------
    x0 : (N, 2n) initial states, adjacency : (N, N)
    """
    N, n = s.n_agents, s.n
    for _ in range(max_tries):
        p = rng.uniform(0.0, SETTINGS["box"], (N, n))
        v = rng.uniform(-SETTINGS["v0"], SETTINGS["v0"], (N, n))
        A = proximity_graph(p, s.sensing_range)
        if not is_connected(A) or A.sum() > max_edge_fraction * N * (N - 1):
            continue
        if np.all(dkf.observable_agents(s.A, s.BK, A)):
            return np.hstack([p, v]), A
    raise RuntimeError(f"no connected, observable configuration found in {max_tries} draws")


def _initial_estimates(rng: np.random.Generator, s: RendezvousSetup, x0: np.ndarray) -> np.ndarray:
    """Common initial team estimate ``x̂_0 = x_0 + N(0, P0)`` per run, ``(R, N 2n)`` (our choice)."""
    std = np.sqrt(np.diag(s.P0()))
    return (x0 + rng.standard_normal(x0.shape) * std).reshape(x0.shape[0], -1)


# ----------------------------------------------------------------------------
# Fig. 2
# ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Fig2Result:
    """Fig. 2 scenario: one topology, Monte Carlo runs sharing the covariance recursion."""

    setup: RendezvousSetup
    adjacency: np.ndarray
    estimation: RendezvousResult    # eq. (21) loop, all runs (run 0 is the one plotted)
    measurement: RendezvousResult   # eq. (5) loop with the filters of eqs. (8)-(20)
    converged_from: float

    def error_to_std_ratio(self, res: RendezvousResult | None = None) -> np.ndarray:
        """Per agent: RMS position error over runs and converged time / mean sqrt(trace)."""
        res = self.estimation if res is None else res
        k0 = int(round(self.converged_from / res.dt))
        rms = np.sqrt(np.mean(res.pos_error[k0:] ** 2, axis=(0, 1)))
        return rms / np.sqrt(np.mean(res.pos_std[k0:, 0] ** 2, axis=0))

    def nees_summary(self, res: RendezvousResult | None = None) -> dict[str, float]:
        """Run-averaged NEES per (step, agent) against its 95 % chi-square interval."""
        res = self.estimation if res is None else res
        n_runs, N = res.nees.shape[1:]
        dof = res.model.m * N
        lo, hi = nees_interval(dof, n_runs)
        avg = res.nees[1:].mean(axis=1)
        return {"mean_nees": float(avg.mean()), "dof": dof, "low": lo, "high": hi,
                "fraction_inside": float(np.mean((avg >= lo) & (avg <= hi)))}


def fig2(seed: int = 0, n_runs: int | None = None, horizon: float | None = None) -> Fig2Result:
    """Fig. 2: fixed topology from the initial positions, Q = I, R = I.

    The covariance recursion is shared by all `n_runs` runs (fixed topology);
    the runs differ only in noise and initial estimate, which gives the NEES
    statistics of both loops for free.
    """
    rng = np.random.default_rng([seed, 2])
    s = setup()
    cfg = SETTINGS["fig2"]
    n_runs = cfg["n_runs"] if n_runs is None else n_runs
    n_steps = int(round((SETTINGS["horizon"] if horizon is None else horizon) / s.dt))
    x0, A = random_initial_states(rng, s, SETTINGS["max_edge_fraction"])
    X0 = np.broadcast_to(x0, (n_runs, *x0.shape)).copy()
    xh0 = _initial_estimates(rng, s, X0)
    Q, R = cfg["q"] * np.eye(s.m), cfg["r"] * np.eye(s.m)
    common = dict(A=s.A, B=s.B, K=s.K, Q=Q, R=R, n_steps=n_steps, dt=s.dt, x_hat0=xh0, P0=s.P0())
    est = simulate_rendezvous(np.random.default_rng([seed, 20]), X0, A, mode="estimation", central=True, **common)
    meas = simulate_rendezvous(np.random.default_rng([seed, 21]), X0, A, mode="measurement-filter", **common)
    return Fig2Result(s, A, est, meas, min(SETTINGS["converged_from"], 0.5 * n_steps * s.dt))


def theorem1(res: Fig2Result) -> dict[str, np.ndarray]:
    """Smallest eigenvalues of ``M_i[k+1]`` (eq. (49)) along the Fig. 2 run."""
    e = res.estimation
    return dkf.theorem1_min_eigenvalues(e.model, laplacian(res.adjacency), e.gains, e.sigma_i, e.f2_cross)


def plot_fig2(res: Fig2Result, axes=None):
    """Song et al. 2023, Fig. 2 (a)-(d) from :func:`fig2` (run 0)."""
    if axes is None:
        _, axes = plt.subplots(2, 2, figsize=(11, 9), layout="constrained")
    ax = np.asarray(axes).reshape(-1)
    e = res.estimation
    p = e.states[:, 0, :, : res.setup.n]
    plot_graph(p[0], res.adjacency, ax=ax[0], sensing_range=res.setup.sensing_range)
    ax[0].set_title("(a) initial topology and sensing ranges")
    plot_trajectories(p, ax=ax[1])
    ax[1].set_title("(b) trajectories (estimation-based control)")
    colors = agent_colors(res.setup.n_agents)
    for i, c in enumerate(colors):
        ax[2].plot(e.time, e.pos_error[:, 0, i], color=c, lw=0.8, label=f"agent {i + 1}")
        ax[3].plot(e.time, e.pos_std[:, 0, i], color=c, lw=1.0)
    ax[3].plot(e.time, e.central_pos_std[:, 0], "k--", lw=1.0, label="centralized KF")
    ax[2].set_title("(c) position estimation error of the team")
    ax[3].set_title("(d) statistical error sqrt(trace Σ_i,pos)")
    for a in ax[2:]:
        a.set_xlabel("time (s)")
        a.set_ylabel("error (m)")
        a.set_yscale("log")
    ax[2].legend(ncol=2, fontsize=7)
    ax[3].legend(fontsize=8)
    return axes


# ----------------------------------------------------------------------------
# Fig. 3
# ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Fig3Result:
    """Fig. 3: RMS (over runs) of the team's position / velocity spread, per law."""

    time: np.ndarray
    pos_std: dict[str, np.ndarray]   # law -> (T+1,) m
    vel_std: dict[str, np.ndarray]   # law -> (T+1,) m/s
    converged_from: float
    pos_runs: dict[str, np.ndarray]  # law -> (T+1, R) spread per run, m
    vel_runs: dict[str, np.ndarray]  # law -> (T+1, R) spread per run, m/s
    # laws (4) and (5) only: exact sqrt(E[spread^2]) per run, no sampling (rendezvous.expected_spread)
    exact_pos_runs: dict[str, np.ndarray]  # law -> (T+1, R), m
    exact_vel_runs: dict[str, np.ndarray]  # law -> (T+1, R), m/s

    def paired_difference(self, a: str, b: str, which: str = "pos") -> tuple[float, float]:
        """Mean and standard error over runs of (converged mean-square spread of `a` minus `b`)."""
        data = self.pos_runs if which == "pos" else self.vel_runs
        k0 = np.searchsorted(self.time, self.converged_from)
        d = np.mean(data[a][k0:] ** 2, axis=0) - np.mean(data[b][k0:] ** 2, axis=0)
        return float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))

    def z_vs_exact(self, law: str, which: str = "pos") -> float:
        """Monte Carlo minus exact converged mean-square spread of `law`, in standard errors over runs."""
        mc = (self.pos_runs if which == "pos" else self.vel_runs)[law]
        ex = (self.exact_pos_runs if which == "pos" else self.exact_vel_runs)[law]
        k0 = np.searchsorted(self.time, self.converged_from)
        d = np.mean(mc[k0:] ** 2, axis=0) - np.mean(ex[k0:] ** 2, axis=0)
        return float(d.mean() / (d.std(ddof=1) / np.sqrt(d.size)))

    def converged(self, which: str = "pos", exact: bool = False) -> dict[str, float]:
        """Time average of the RMS spread from `converged_from` on.

        ``exact=True``: the same statistic from the exact expectations
        (``sqrt(mean_runs E[spread^2])``), for the laws that have one.
        """
        if exact:
            runs = self.exact_pos_runs if which == "pos" else self.exact_vel_runs
            data = {law: np.sqrt(np.mean(v**2, axis=1)) for law, v in runs.items()}
        else:
            data = self.pos_std if which == "pos" else self.vel_std
        k0 = np.searchsorted(self.time, self.converged_from)
        return {law: float(np.mean(v[k0:])) for law, v in data.items()}


def fig3(seed: int = 0, n_runs: int | None = None, horizon: float | None = None,
         progress: bool = False) -> Fig3Result:
    """Fig. 3: 50 runs with random initial positions, Q = I, R = 100 I.

    Each run has its own topology fixed from its initial positions (connected,
    (43) observable). The laws share the initial states and the noise
    realizations (common random numbers). ``"true states"`` (eq. (4) without
    measurement noise) is an extra reference the paper does not plot.
    """
    rng = np.random.default_rng([seed, 3])
    s = setup()
    cfg = SETTINGS["fig3"]
    n_runs = cfg["n_runs"] if n_runs is None else n_runs
    n_steps = int(round((SETTINGS["horizon"] if horizon is None else horizon) / s.dt))
    draws = [random_initial_states(rng, s) for _ in range(n_runs)]
    X0 = np.stack([d[0] for d in draws])
    A = np.stack([d[1] for d in draws])
    xh0 = _initial_estimates(rng, s, X0)
    Q, R = cfg["q"] * np.eye(s.m), cfg["r"] * np.eye(s.m)
    common = dict(A=s.A, B=s.B, K=s.K, Q=Q, R=R, n_steps=n_steps, dt=s.dt, progress=progress)
    runs = {
        "conventional (eq. (5))": simulate_rendezvous(np.random.default_rng([seed, 30]), X0, A,
                                                      mode="measurement", **common),
        "estimation-based (eq. (21))": simulate_rendezvous(np.random.default_rng([seed, 30]), X0, A,
                                                           mode="estimation", x_hat0=xh0, P0=s.P0(), **common),
        "true states (eq. (4), reference)": simulate_rendezvous(np.random.default_rng([seed, 30]), X0, A,
                                                                mode="true", **common),
    }
    n = s.n
    pos_runs = {k: team_spread(r.states[..., :n]) for k, r in runs.items()}
    vel_runs = {k: team_spread(r.states[..., n:]) for k, r in runs.items()}
    pos = {k: np.sqrt(np.mean(v**2, axis=1)) for k, v in pos_runs.items()}
    vel = {k: np.sqrt(np.mean(v**2, axis=1)) for k, v in vel_runs.items()}
    exact = {law: expected_spread(X0, A, s.A, s.B, s.K, Q, R, n_steps, mode)
             for law, mode in (("conventional (eq. (5))", "measurement"), ("true states (eq. (4), reference)", "true"))}
    exact_pos = {k: np.sqrt(v[..., :n].sum(-1)) for k, v in exact.items()}
    exact_vel = {k: np.sqrt(v[..., n:].sum(-1)) for k, v in exact.items()}
    t = runs["conventional (eq. (5))"].time
    return Fig3Result(t, pos, vel, min(SETTINGS["converged_from"], 0.5 * t[-1]), pos_runs, vel_runs,
                      exact_pos, exact_vel)


def process_noise_study(seed: int = 0, q_values=(1.0, 0.1, 0.01), n_runs: int = 10,
                        horizon: float = 30.0) -> pd.DataFrame:
    """Beyond the paper: converged spreads of both laws as the process noise ``Q = q I`` shrinks.

    Same setting as Fig. 3 otherwise (R = 100 I, random connected and observable
    topologies, common random numbers); converged = RMS over runs and over the
    second half of the horizon.

    Returns
    -------
    DataFrame with columns ``q``, ``law``, ``pos_std_m``, ``vel_std_mps``.
    """
    rng = np.random.default_rng([seed, 4])
    s = setup()
    draws = [random_initial_states(rng, s) for _ in range(n_runs)]
    X0 = np.stack([d[0] for d in draws])
    A = np.stack([d[1] for d in draws])
    xh0 = _initial_estimates(rng, s, X0)
    n_steps = int(round(horizon / s.dt))
    k0 = n_steps // 2
    rows = []
    for q in q_values:
        for mode, law in (("measurement", "conventional (eq. (5))"), ("estimation", "estimation-based (eq. (21))")):
            r = simulate_rendezvous(np.random.default_rng([seed, 40]), X0, A, s.A, s.B, s.K, q * np.eye(s.m),
                                    SETTINGS["fig3"]["r"] * np.eye(s.m), n_steps, mode, s.dt,
                                    x_hat0=xh0, P0=s.P0())
            rows.append({"q": q, "law": law,
                         "pos_std_m": float(np.sqrt(np.mean(team_spread(r.states[k0:, ..., : s.n]) ** 2))),
                         "vel_std_mps": float(np.sqrt(np.mean(team_spread(r.states[k0:, ..., s.n:]) ** 2)))})
    return pd.DataFrame(rows)


def plot_fig3(res: Fig3Result, axes=None):
    """Song et al. 2023, Fig. 3 (a) position and (b) velocity RMS STD."""
    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    styles = {"conventional": "-", "estimation": "-", "true": ":"}
    for ax, data, unit, title in ((axes[0], res.pos_std, "m", "(a) position"),
                                  (axes[1], res.vel_std, "m/s", "(b) velocity")):
        for law, v in data.items():
            ax.plot(res.time, v, styles[law.split()[0].split("-")[0]], label=law)
        ax.set_yscale("log")
        ax.set_xlabel("time (s)")
        ax.set_ylabel(f"RMS STD ({unit})")
        ax.set_title(f"{title} STD over {next(iter(res.pos_runs.values())).shape[1]} runs")
        ax.axvspan(res.converged_from, res.time[-1], color="0.9", zorder=0)
    axes[0].legend(fontsize=8)
    return axes


def plot_theorem1(res: Fig2Result, th: dict[str, np.ndarray], agent: int = 0, axes=None):
    """Theorem 1 made visible: ``min eig M_i`` for every agent and ``V`` (eq. (45)) of one agent."""
    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    e = res.estimation
    t = e.time[1:]
    for i, c in enumerate(agent_colors(res.setup.n_agents)):
        axes[0].plot(t, th["min_eig"][:, i], color=c, lw=0.8)
    axes[0].set_yscale("log")
    axes[0].set_xlabel("time (s)")
    axes[0].set_ylabel("min eig M_i[k+1] (1/m^2)")
    axes[0].set_title("smallest eigenvalue of M_i, eq. (49)")
    V = e.nees[:, 0, agent]
    axes[1].plot(e.time, V, lw=0.8, label=f"V of agent {agent + 1}, run 1")
    axes[1].plot(e.time, e.nees[:, :, agent].mean(axis=1), lw=1.2, label="mean over runs")
    axes[1].axhline(e.model.m * res.setup.n_agents, color="k", ls="--", lw=0.8, label="dof = 2nN")
    axes[1].set_yscale("log")
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel("V = e_i^T Σ_i^-1 e_i")
    axes[1].set_title("Lyapunov function, eq. (45)")
    axes[1].legend(fontsize=8)
    return axes


# ----------------------------------------------------------------------------
# reproduce
# ----------------------------------------------------------------------------


def reproduce(out_dir: Path, seed: int) -> list[Claim]:
    """Rebuild Figs. 2-3, the Theorem 1 check and the linear-part ledger claims."""
    out_dir = Path(out_dir)
    claims = _linear_reproduce(out_dir, seed)
    from .song2023_flocking import flocking_claims_and_figures  # Figs. 4-6 (issue 4): keep this line
    claims += flocking_claims_and_figures(out_dir, seed)
    return claims


def _linear_reproduce(out_dir: Path, seed: int) -> list[Claim]:
    fig_dir, tab_dir = out_dir / "figures", out_dir / "tables"
    tab_dir.mkdir(parents=True, exist_ok=True)
    pd.DataFrame([{"parameter": k, "value": v} for k, v in TABLE_I.items()]).to_csv(
        tab_dir / "table1.csv", index=False)
    r2 = fig2(seed)
    th = theorem1(r2)
    r3 = fig3(seed, progress=True)
    fig, axes = plt.subplots(2, 2, figsize=(11, 9), layout="constrained")
    plot_fig2(r2, axes)
    save_figure(fig, fig_dir / "fig2.png")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    plot_theorem1(r2, th, axes=axes)
    save_figure(fig, fig_dir / "theorem1.png")
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
    plot_fig3(r3, axes)
    save_figure(fig, fig_dir / "fig3.png")
    pd.DataFrame({"time_s": r3.time, **{f"pos_std_m[{k}]": v for k, v in r3.pos_std.items()},
                  **{f"vel_std_mps[{k}]": v for k, v in r3.vel_std.items()}}).iloc[::10].to_csv(
        tab_dir / "fig3_std.csv", index=False)
    return linear_claims(r2, th, r3)


def linear_claims(r2: Fig2Result, th: dict[str, np.ndarray], r3: Fig3Result) -> list[Claim]:
    """The ledger claims of the linear part from computed results (:func:`fig2`, :func:`theorem1`, :func:`fig3`)."""
    claims: list[Claim] = []

    # Fig. 2 ---------------------------------------------------------------------
    ratio = r2.error_to_std_ratio()
    ratio_mb = r2.error_to_std_ratio(r2.measurement)
    k0 = int(round(r2.converged_from / r2.setup.dt))
    single = float(np.mean(np.sqrt(np.mean(r2.estimation.pos_error[k0:, 0] ** 2, axis=0))
                           / np.sqrt(np.mean(r2.estimation.pos_std[k0:, 0] ** 2, axis=0))))
    claims.append(Claim(
        "song2023/fig2-error-matches-covariance", "Sec. V.A, Fig. 2(c)-(d)",
        "With estimation-based rendezvous the agents' actual position errors of the team match the "
        "statistical error sqrt(trace) of their covariances.",
        1.0, float(np.mean(ratio)), {"rel": 0.05},
        f"Value: RMS (over {r2.estimation.states.shape[1]} runs sharing the Fig. 2 topology and over "
        f"t >= {r2.converged_from:g} s) of ||p - p_hat_i|| divided by the RMS of sqrt(trace of the position "
        f"block of Sigma_i), averaged over the agents (per agent: {np.round(ratio, 3).tolist()}); the single "
        f"plotted run gives {single:.3f}. The paper only says 'similar' (ratio 1 is our reading). Same ratio "
        f"for the measurement-based loop: {float(np.mean(ratio_mb)):.3f}. Initial positions, velocities, "
        "horizon, common initial estimate and P0 are our choices (see SETTINGS)."))
    for key, res, where, label in (
        ("song2023/nees-rendezvous", r2.estimation, "Sec. III.A.2, eqs. (29)-(34)", "estimation-based"),
        ("song2023/nees-rendezvous-measurement-based", r2.measurement, "Sec. III.A.1, eqs. (8)-(20)",
         "measurement-based"),
    ):
        ns = r2.nees_summary(res)
        claims.append(Claim.qualitative(
            key, where,
            f"The whole-team filters of the {label} loop are consistent: their covariances match their "
            "actual errors (NEES within its chi-square interval).",
            {"mean_nees": round(ns["mean_nees"], 3), "dof": ns["dof"],
             "interval_95": [round(ns["low"], 3), round(ns["high"], 3)],
             "fraction_inside": round(ns["fraction_inside"], 4)},
            ns["low"] <= ns["mean_nees"] <= ns["high"] and ns["fraction_inside"] >= 0.90,
            f"Fig. 2 topology, Q = I, R = I, {res.states.shape[1]} runs sharing one covariance recursion. "
            "For every (agent, step) the NEES averaged over the runs is compared with the 95 % interval of "
            "the run-average; holds if the grand mean lies in that interval and at least 90 % of the "
            "(agent, step) averages do (about 95 % expected). Not a claim the paper makes: our consistency "
            "check of " + ("the cross-covariance recursion." if label == "estimation-based" else
                           "eq. (15), which neglects the correlation between an agent's own measurement noise "
                           "in its control and its estimate (mb_predict(KH_prev=...) adds it; the effect is "
                           "small here).")))
    min_eig, min_rel = float(th["min_eig"].min()), float(th["min_eig_rel"].min())
    claims.append(Claim.qualitative(
        "song2023/theorem1-lyapunov-decrease", "Sec. IV, Theorem 1, eqs. (49), (59)",
        "Along an estimation-based rendezvous run with an observable topology, M_i[k+1] of eq. (49) is "
        "positive definite for every agent and step, so V of eq. (45) decreases in conditional mean.",
        {"min_eig_M": min_eig, "min_eig_rel": min_rel,
         "steps": int(th["min_eig"].shape[0]), "agents": int(th["min_eig"].shape[1])},
        min_eig > 0,
        "Smallest eigenvalue of M_i[k+1] over all agents and steps of the Fig. 2 run (min_eig_rel: of "
        "Sigma_i^1/2 M_i Sigma_i^1/2, scale-free). Reading: C_i of Lemma 1 taken as the regression map "
        "E[e e_i^T] Sigma_i^-1 (equal to the paper's C_i[0] = 1 kron I at k = 0 with a common initial "
        "estimate), which makes alpha_i uncorrelated with e_i as eqs. (48) and (51) require; the literal "
        "recursion for C_i[k+1] grows without bound within a few steps and then gives negative "
        "eigenvalues. Topology checked observable (system (43)) for every agent."))
    Pmin = float(np.min(r2.estimation.pos_std[:, 0] - r2.estimation.central_pos_std[:, :1]))
    claims.append(Claim.qualitative(
        "song2023/centralized-bound", "Sec. III.A (reference, not in the paper)",
        "No agent's whole-team estimate is more certain than a centralized Kalman filter that fuses every "
        "agent's measurements and knows the applied inputs.",
        {"min_std_gap_m": Pmin}, Pmin >= -1e-9,
        "Smallest difference sqrt(trace Sigma_i,pos) - sqrt(trace P_central,pos) over agents and steps of "
        "the Fig. 2 scenario."))

    # Fig. 3 ---------------------------------------------------------------------
    conv = "conventional (eq. (5))"
    est = "estimation-based (eq. (21))"
    true = "true states (eq. (4), reference)"
    # share of the excess mean-square spread over the noise-free-measurement law (4) that the
    # estimation-based law removes (1: all of it, 0: none)
    removed = {}
    for which in ("pos", "vel"):
        c = r3.converged(which)
        removed[which] = 1.0 - (c[est] ** 2 - c[true] ** 2) / (c[conv] ** 2 - c[true] ** 2)
    for which, unit in (("pos", "m"), ("vel", "m/s")):
        c = r3.converged(which)
        ex = r3.converged(which, exact=True)
        diff, se = r3.paired_difference(est, conv, which)
        name = "position" if which == "pos" else "velocity"
        claims.append(Claim.qualitative(
            f"song2023/fig3-{name}-std", "Sec. V.A, Fig. 3" + ("(a)" if which == "pos" else "(b)"),
            f"At the converged state the RMS {name} STD of the team is smaller with estimation-based "
            "rendezvous than with the conventional measurement-based law (Q = I, R = 100 I, 50 runs).",
            {"estimation_based": round(c[est], 4), "conventional": round(c[conv], 4),
             "true_state_reference": round(c[true], 4), "unit": unit,
             "conventional_exact": round(ex[conv], 4), "true_state_exact": round(ex[true], 4),
             "paired_diff_mean_square": round(diff, 3), "paired_diff_std_error": round(se, 3),
             "excess_removed_fraction": round(removed[which], 3)},
            c[est] < c[conv] and diff < -2.0 * se,
            f"Converged = time average over t >= {r3.converged_from:g} s of the RMS over runs of "
            "sqrt(mean_i ||y_i - mean_j y_j||^2) (the team's spread about its mean, all axes; a per-axis or "
            "N-1 normalisation would rescale both laws alike). Holds if the estimation-based value is smaller "
            "AND the run-paired difference of converged mean-square spreads (same initial states and noise "
            "for both laws) is below -2 standard errors. The paper gives no numbers, only the ordering. "
            f"Check of the computation: laws (4) and (5) are linear with white noise, so their expected "
            f"spread is also propagated exactly (mean and covariance, same graphs, no sampling): "
            f"{ex[conv]:.2f} and {ex[true]:.2f} {unit} against the Monte Carlo {c[conv]:.2f} and "
            f"{c[true]:.2f} {unit} ({r3.z_vs_exact(conv, which):+.1f} and {r3.z_vs_exact(true, which):+.1f} "
            "standard errors over runs; the position spread of one run is dominated by a few slow modes, so "
            "50 runs pin it down only to a few per cent). "
            "excess_removed_fraction = 1 - (est^2 - true^2) / (conv^2 - true^2): the "
            "share of the spread added by measurement noise that estimation-based control removes. Horizon, "
            "initial states (uniform positions in a 400 m square, redrawn until connected and observable; "
            "velocities uniform in [-5, 5] m/s) and initial estimates are our choices."
            + (" Why position fails: of the mean-square spread that measurement noise adds on top of the "
               f"true-state law, the estimation-based law removes {removed['vel']:.0%} in velocity but "
               f"{removed['pos']:.0%} in position (negative: it adds). "
               "The position spread is dominated by slow components (Q = I_2n puts 1 m of position noise per "
               "0.1 s step on every agent; the true-state law alone keeps about half of the spread). Eq. (5) "
               "feeds white measurement noise into the accelerations, and the loop averages most of it out "
               "before it reaches the positions; the estimation-based law feeds the filters' estimation "
               "errors instead, which are smaller but correlated over many steps (the filter must trust the "
               "measurements to follow that much process noise), so the loop follows them. The two laws end "
               "up statistically indistinguishable in position: the sign of the paired difference changes with "
               "the seed (seeds 0 and 2 give the paper's ordering, seed 1 the reverse, each within 2 standard "
               "errors), and the conventional Monte Carlo "
               "value itself scatters by several per cent around its exact expectation (above). With smaller "
               "process noise (Q = 0.1 I or 0.01 I, process_noise_study, shown in the "
               "notebook) the paper's ordering appears clearly."
               if which == "pos" else "")))
    return claims
