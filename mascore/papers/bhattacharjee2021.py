"""Bhattacharjee and Subbarao (2021): the simulation example of Section 5.

Four agents ``x_{k+1} = A x_k + B u_k + G w_k``, ``y_k = C x_k + D v_k`` with
eq. (23), the directed ring of eq. (24) pinned at agent 1, each agent running
the set-membership filter of Algorithm 1 and the Riccati-designed law of
Sec. 4.2 on its corrected estimate. Everything the paper's Figs. 1-6 and
Table 1 need is computed here (:func:`simulate`, :func:`table1_study`) and
drawn by the ``plot_fig*`` functions; :func:`reproduce` writes the figures,
``tables/table1.csv`` and the ledger claims.

Settings the paper leaves out (chosen here):

* Horizon: k = 0..T_f with T_f = 60 (Table 1's ``T = 61`` steps); the figures use the same.
* Order of one time step: correct with y_k, compute u_k from the corrected
  centres and the leader state x^(0)_k, then propagate the agents and predict.
* Random draws: the true initial states, w_k (k = 0..T_f - 1) and v_k
  (k = 0..T_f) are uniform as in Sec. 5; each Monte Carlo run r uses its own
  generator ``default_rng(SeedSequence(seed).spawn(n_runs)[r])``, so run 0 is
  the same draw in every study and on both filter paths. The three Table 1 rows
  share the unit draws (scaled by alpha_w, alpha_v): common random numbers.
* Fig. 6's "about 1.5" is compared with trace P_{k|k} at k = T_f averaged over agents.
* alpha = 1.1, mu = 0.9, p0 = 2, q_bar = 0.1 are the paper's (Sec. 5).
* Graph: the Laplacian of eq. (24) as printed. The reading with reversed edges
  (adjacency transposed) fits Table 1's means better and its RMS values worse; it is
  computed alongside (:func:`table1_readings`, ``tables/table1_edges_reversed.csv``)
  and quoted in the notes, never used for a verdict.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from .. import set_membership as smf
from .. import synchronization as sync
from .._progress import progress_bar
from ..ledger import Claim
from ..plotting import agent_colors, save_figure, use_style

__all__ = [
    "ALPHA", "A", "ADJACENCY", "B", "C", "C0", "D", "G_DIST", "LEADER_X0", "MU", "N_AGENTS",
    "P0", "P0_BOUND", "PINNING", "Q_BAR", "Q_RICCATI", "R0", "SETTINGS", "T_F", "X0_HAT",
    "ClosedLoopRun", "DisturbanceSetting", "Draw", "design", "draw", "ledger_claims", "noise_free_metrics", "plot_fig1",
    "plot_fig2", "plot_fig3_4", "plot_fig5", "plot_fig6", "reproduce", "simulate", "table1_readings", "table1_study",
]

# ---------------------------------------------------------------- eq. (23)
A = np.array([[0.0, -1.0], [1.0, 0.0]])
B = np.eye(2)
C = np.array([[1.0, 0.0]])
D = np.eye(1)
#: Disturbance matrix G of eqs. (1), (9), (23) (not the pinning gains).
G_DIST = np.eye(2)

# ---------------------------------------------------------------- eq. (24), Fig. 1(a)
N_AGENTS = 4
#: adjacency[i, j] = 1: agent i+1 receives from agent j+1 (rows of L in eq. (24)).
ADJACENCY = np.array([[0, 0, 0, 1], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]], dtype=float)
#: Pinning gains g_i: calligraphic G = diag(1, 0, 0, 0) (only agent 1 hears the leader).
PINNING = np.array([1.0, 0.0, 0.0, 0.0])

# ---------------------------------------------------------------- Lemma 2 and Corollary 1 (Sec. 5)
Q_RICCATI = 0.1 * np.eye(2)
C0, R0 = 2.0 / 3.0, 0.6
ALPHA, MU = 1.1, 0.9
P0_BOUND, Q_BAR = 2.0, 0.1

# ---------------------------------------------------------------- filters and initial conditions
T_F = 60
P0 = 2.0 * np.eye(2)
X0_HAT = np.array([[50.0, -50.0], [50.0, -50.0], [-50.0, 50.0], [-50.0, 50.0]])
#: True x_0^(i) uniform in [X0_HAT, X0_HAT + 1] componentwise (Sec. 5).
X0_BOX = 1.0
LEADER_X0 = np.array([5.0, 5.0])


@dataclass(frozen=True)
class DisturbanceSetting:
    """One row of Table 1: uniform w in [-a_w, a_w]^2, v in [-a_v, a_v]; filter bounds Q, R."""

    alpha_w: float
    alpha_v: float
    q: float  # Q_k = q I_2
    r: float  # R_k = r
    paper_mean: float
    paper_rms: float

    @property
    def Q(self) -> np.ndarray:
        return self.q * np.eye(2)

    @property
    def R(self) -> np.ndarray:
        return self.r * np.eye(1)


#: Table 1 rows (row 1 is the setting of Figs. 2-6).
SETTINGS = (
    DisturbanceSetting(0.05, 0.05, 0.1, 0.1, 0.3706, 1.1985),
    DisturbanceSetting(0.5, 0.5, 1.0, 1.0, 0.4219, 1.2052),
    DisturbanceSetting(1.0, 1.0, 2.0, 1.0, 0.4730, 1.2124),
)


def design() -> sync.SyncDesign:
    """Lemma 2 for the example: P = Q = 0.1 I (B = I), K = A, c = 1.5, r = 1."""
    return sync.design_synchronization(A, B, Q_RICCATI, ADJACENCY, PINNING, C0, R0)


@dataclass(frozen=True)
class Draw:
    """Unit random draws of a batch of runs (scaled by a setting when simulated)."""

    x0: np.ndarray  # (R, N, 2) true initial states
    w_unit: np.ndarray  # (R, T_F, N, 2) in [-1, 1]
    v_unit: np.ndarray  # (R, T_F + 1, N, 1) in [-1, 1]


def draw(seed: int, n_runs: int = 1) -> Draw:
    """Random draws of `n_runs` runs; run r uses ``SeedSequence(seed).spawn(n_runs)[r]``."""
    children = np.random.SeedSequence(int(seed)).spawn(n_runs)
    x0, w, v = [], [], []
    for child in children:
        rng = np.random.default_rng(child)
        x0.append(X0_HAT + X0_BOX * rng.random((N_AGENTS, 2)))
        w.append(rng.uniform(-1.0, 1.0, (T_F, N_AGENTS, 2)))
        v.append(rng.uniform(-1.0, 1.0, (T_F + 1, N_AGENTS, 1)))
    return Draw(np.array(x0), np.array(w), np.array(v))


@dataclass(frozen=True)
class ClosedLoopRun:
    """Trajectories of a batch of closed-loop runs, k = 0..T_F.

    Attributes
    ----------
    k : (T+1,) time steps
    x : (R, T+1, N, 2) true agent states;  leader : (T+1, 2) leader state
    x0_hat : (N, 2) initial estimates
    xhat : (R, T+1, N, 2) corrected centres;  P : (R, T+1, N, 2, 2) corrected shapes
    xpred, Ppred : same shapes, the prior (predicted) ellipsoids each correction started from
    u : (R, T, N, 2) control inputs
    delta_norm : (R, T+1) |delta_k|;  delta_bar : (R, T+1) |delta_k| / mu_bar
    """

    k: np.ndarray
    x: np.ndarray
    leader: np.ndarray
    x0_hat: np.ndarray
    xhat: np.ndarray
    P: np.ndarray
    xpred: np.ndarray
    Ppred: np.ndarray
    u: np.ndarray
    delta_norm: np.ndarray
    delta_bar: np.ndarray

    @property
    def error(self) -> np.ndarray:
        """Estimation errors e_k = x_k - xhat_{k|k}; (R, T+1, N, 2)."""
        return self.x - self.xhat

    @property
    def containment(self) -> np.ndarray:
        """``e^T P^{-1} e`` for every run, step and agent; <= 1 means contained."""
        e = self.error
        return np.einsum("...i,...i->...", e, np.linalg.solve(self.P, e[..., None])[..., 0])

    def table1_metrics(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and RMS of |delta_bar_k| over k = 0..T_F, per run (Table 1)."""
        return self.delta_bar.mean(axis=-1), np.sqrt((self.delta_bar**2).mean(axis=-1))


def simulate(
    setting: DisturbanceSetting = SETTINGS[0], seed: int = 1, n_runs: int = 1,
    method: str = "closed_form", draws: Draw | None = None, progress: bool = False,
    adjacency: np.ndarray = ADJACENCY,
) -> ClosedLoopRun:
    """Closed loop of Sec. 5 for `n_runs` runs, vectorized over runs and agents.

    Parameters
    ----------
    setting : DisturbanceSetting
        Disturbance amplitudes and filter bounds (a Table 1 row).
    seed, n_runs : int
        Random draws (see :func:`draw`); ignored if `draws` is given.
    method : {"sdp", "closed_form"}
        Filter implementation (:mod:`mascore.set_membership`).
    adjacency : (N, N) array
        Interaction graph (default: eq. (24)); any other must satisfy Assumption 4
        and Lemma 2 with the example's circle (checked).
    """
    des = design() if adjacency is ADJACENCY else sync.design_synchronization(
        A, B, Q_RICCATI, adjacency, PINNING, C0, R0)
    draws = draws if draws is not None else draw(seed, n_runs)
    R = draws.x0.shape[0]
    agent = np.arange(1, N_AGENTS + 1)  # 1-based labels in error messages, as in the paper
    w = setting.alpha_w * draws.w_unit
    v = setting.alpha_v * draws.v_unit
    Q, Rm = setting.Q, setting.R
    x = draws.x0.copy()
    c = np.broadcast_to(X0_HAT, x.shape).copy()
    P = np.broadcast_to(P0, (*x.shape, 2)).copy()
    leader = LEADER_X0.copy()
    xs, xh, Ps, us, ls, xp, Pp = [], [], [], [], [], [], []
    for k in progress_bar(range(T_F + 1), enabled=progress, desc=f"closed loop ({method})", leave=False):
        y = x @ C.T + v[:, k] @ D.T
        xp.append(c)
        Pp.append(P)
        c, P, _ = smf.correct(c, P, y, C, D, Rm, method=method, step=k, agent=agent)
        xs.append(x)
        xh.append(c)
        Ps.append(P)
        ls.append(leader)
        if k == T_F:
            break
        u = sync.local_control(c, leader, adjacency, PINNING, des.K, des.c)
        x = x @ A.T + u @ B.T + w[:, k] @ G_DIST.T
        c, P = smf.predict(c, P, A, G_DIST, Q, B=B, u=u, method=method, step=k, agent=agent)
        leader = A @ leader
        us.append(u)
    x, xhat, P = np.stack(xs, 1), np.stack(xh, 1), np.stack(Ps, 1)
    lead = np.array(ls)
    delta = x - lead[None, :, None, :]
    dnorm = np.sqrt(np.sum(delta**2, axis=(-1, -2)))
    mbar = sync.mu_bar(ALPHA, MU, N_AGENTS)
    return ClosedLoopRun(np.arange(T_F + 1), x, lead, X0_HAT.copy(), xhat, P, np.stack(xp, 1),
                         np.stack(Pp, 1), np.stack(us, 1),
                         dnorm, dnorm / mbar)


def table1_study(
    seed: int = 1, n_runs: int = 100, progress: bool = False, adjacency: np.ndarray = ADJACENCY,
) -> tuple[pd.DataFrame, list[ClosedLoopRun]]:
    """Table 1 on the fast path: each row over `n_runs` seeds (common random numbers).

    `adjacency` is passed to :func:`simulate` (default: the graph of eq. (24)).

    Returns
    -------
    table : DataFrame, one row per setting: the paper's values, ours for run 0
        and the spread (mean, std, 5/50/95 % quantiles, min, max) over the runs.
    runs : the :class:`ClosedLoopRun` of each row.
    """
    draws = draw(seed, n_runs)
    rows, runs = [], []
    for i, s in enumerate(progress_bar(SETTINGS, enabled=progress, desc="Table 1")):
        run = simulate(s, draws=draws, method="closed_form", adjacency=adjacency)
        runs.append(run)
        mean, rms = run.table1_metrics()
        row = {"row": i + 1, "alpha_w": s.alpha_w, "alpha_v": s.alpha_v, "Q": f"{s.q:g} I_2", "R": f"{s.r:g}",
               "paper_mean": s.paper_mean, "paper_rms": s.paper_rms, "n_runs": n_runs,
               "mean_run0": mean[0], "rms_run0": rms[0]}
        for name, vals in (("mean", mean), ("rms", rms)):
            q05, q50, q95 = np.quantile(vals, [0.05, 0.5, 0.95])
            row |= {f"{name}_avg": vals.mean(), f"{name}_std": vals.std(ddof=1), f"{name}_q05": q05,
                    f"{name}_q50": q50, f"{name}_q95": q95, f"{name}_min": vals.min(), f"{name}_max": vals.max()}
        rows.append(row)
    return pd.DataFrame(rows), runs


def noise_free_metrics(
    x0: np.ndarray, adjacency: np.ndarray = ADJACENCY, c: float | None = None, leader_shift: int = 0,
    first_k: int = 0,
) -> tuple[float, float]:
    """Table 1's mean and RMS of ``|delta_k| / mu_bar`` without disturbances and with exact estimates.

    The law of Sec. 4.2 on the true states (``w = v = 0``, ``xhat = x``), i.e. the
    transient ``A_c^k delta_0`` of eq. (14), averaged over ``k = first_k .. first_k + T_F``.

    Parameters
    ----------
    x0 : (N, 2) true initial states
    adjacency : (N, N) interaction graph (default: eq. (24))
    c : coupling gain (default: Lemma 2's ``1 / c0`` = 1.5)
    leader_shift : the law uses ``x^(0)_{k + leader_shift}`` instead of ``x^(0)_k``
    first_k : first time step of the average (0 in our reading)
    """
    des = design()
    c = des.c if c is None else float(c)
    lead_op = np.linalg.matrix_power(A, leader_shift) if leader_shift >= 0 else np.linalg.matrix_power(A.T, -leader_shift)
    x, lead, norms = np.asarray(x0, dtype=float), LEADER_X0.copy(), []
    for _ in range(first_k + T_F + 1):
        norms.append(np.linalg.norm(x - lead))
        u = sync.local_control(x, lead_op @ lead, adjacency, PINNING, des.K, c)
        x = x @ A.T + u @ B.T
        lead = A @ lead
    s = np.array(norms[first_k:]) / sync.mu_bar(ALPHA, MU, N_AGENTS)
    return float(s.mean()), float(np.sqrt((s**2).mean()))


def table1_readings(x0: np.ndarray | None = None) -> pd.DataFrame:
    """Other readings of the paper tried against Table 1 row 1 (noise-free transient, see :func:`noise_free_metrics`).

    ``x0`` defaults to the centre of the boxes the true initial states are drawn from.
    (A is orthogonal, so ``A^T = A^{-1}`` moves the leader one step back.)
    """
    x0 = X0_HAT + 0.5 * X0_BOX if x0 is None else np.asarray(x0, dtype=float)
    readings = [
        ("as printed (ours)", dict(x0=x0)),
        ("x_0 = xhat_0 (lower box corner)", dict(x0=X0_HAT)),
        ("x_0 = xhat_0 + 1 (upper box corner)", dict(x0=X0_HAT + X0_BOX)),
        ("edges reversed (adjacency transposed)", dict(x0=x0, adjacency=ADJACENCY.T)),
        ("coupling gain c = 1", dict(x0=x0, c=1.0)),
        ("leader one step ahead in the law", dict(x0=x0, leader_shift=1)),
        ("leader one step behind in the law", dict(x0=x0, leader_shift=-1)),
        ("average over k = 1..61 (k = 0 left out)", dict(x0=x0, first_k=1)),
    ]
    s = SETTINGS[0]
    rows = []
    for name, kw in readings:
        mean, rms = noise_free_metrics(**kw)
        rows.append({"reading": name, "mean": mean, "rms": rms,
                     "mean_rel_diff": mean / s.paper_mean - 1, "rms_rel_diff": rms / s.paper_rms - 1})
    return pd.DataFrame(rows)


# ---------------------------------------------------------------- figures


def plot_fig1(des: sync.SyncDesign | None = None) -> plt.Figure:
    """Fig. 1: (a) the interaction graph with the leader, (b) eigenvalues of Gamma in C(c0, r0)."""
    des = des if des is not None else design()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9.5, 4.0))
    ang = np.pi / 2 - np.arange(N_AGENTS) * 2 * np.pi / N_AGENTS
    pos = np.c_[np.cos(ang), np.sin(ang)]
    lead = np.array([0.0, 2.0])
    colors = agent_colors(N_AGENTS)
    arrow = dict(arrowstyle="-|>", color="0.35", lw=1.2, shrinkA=13, shrinkB=13)
    for i, j in zip(*np.nonzero(ADJACENCY)):
        ax1.annotate("", xy=pos[i], xytext=pos[j], arrowprops=arrow)
    for i in np.flatnonzero(PINNING):
        ax1.annotate("", xy=pos[i], xytext=lead, arrowprops=arrow | {"ls": "--"})
        ax1.text(*(0.5 * (pos[i] + lead) + [0.12, 0]), f"$g_{i + 1}={PINNING[i]:g}$", fontsize=8)
    ax1.plot(*lead, "s", ms=20, color="k")
    ax1.text(*lead, "0", color="w", ha="center", va="center")
    for i in range(N_AGENTS):
        ax1.plot(*pos[i], "o", ms=20, color=colors[i])
        ax1.text(*pos[i], str(i + 1), color="w", ha="center", va="center")
    ax1.set_xlim(-1.6, 1.6)
    ax1.set_ylim(-1.5, 2.5)
    ax1.set_aspect("equal")
    ax1.axis("off")
    ax1.set_title("(a) interaction graph (0 = leader)")
    th = np.linspace(0, 2 * np.pi, 400)
    ax2.plot(des.c0 + des.r0 * np.cos(th), des.r0 * np.sin(th), "k--", lw=1, label=f"$C(c_0, r_0)$, $c_0$={des.c0:.3g}, $r_0$={des.r0:g}")
    ax2.plot(des.eigs.real, des.eigs.imag, "x", ms=9, mew=2, color="C3", label=r"eigenvalues $\Lambda_i$ of $\Gamma$")
    ax2.set_xlabel("real part")
    ax2.set_ylabel("imaginary part")
    ax2.set_aspect("equal")
    ax2.legend(loc="lower left", fontsize=7)
    ax2.set_title(r"(b) eigenvalues of $\Gamma$")
    fig.tight_layout()
    return fig


def plot_fig2(run: ClosedLoopRun, des: sync.SyncDesign | None = None, k_max: int = 60) -> plt.Figure:
    """Fig. 2: (a) leader and agent states, (b) |delta_bar_k| with the bound of eq. (21), (c) |A_c^k|."""
    des = des if des is not None else design()
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    colors = agent_colors(N_AGENTS)
    for comp, ax in enumerate(axes[0]):
        for i in range(N_AGENTS):
            ax.plot(run.k, run.x[0, :, i, comp], color=colors[i], label=f"agent {i + 1}")
        ax.plot(run.k, run.leader[:, comp], "k--", label="leader")
        ax.set_xlabel("time step k")
        ax.set_ylabel(f"$x_{{{comp + 1}k}}$ (state units)")
        ax.set_title(f"(a) true states, component {comp + 1}")
    axes[0, 0].legend(ncol=2)
    bound = sync.bound_eq21(des.B_c, G_DIST, P0_BOUND, Q_BAR)
    ax = axes[1, 0]
    ax.plot(run.k, run.delta_bar[0], label=r"$|\bar\delta_k|$")
    ax.axhline(bound, color="k", ls=":", label=f"bound eq. (21) = {bound:.3f}")
    ax.set_xlabel("time step k")
    ax.set_ylabel(r"$|\bar\delta_k|$ (state units)")
    ax.set_title("(b) normalized global disagreement error")
    ax.legend()
    ax = axes[1, 1]
    kk = np.arange(k_max + 1)
    ax.semilogy(kk, sync.power_norms(des.A_c, k_max), label=r"$|A_c^k|$")
    ax.semilogy(kk, ALPHA * MU**kk, "k--", label=rf"$\alpha\mu^k$ = {ALPHA} $\cdot$ {MU}$^k$")
    ax.set_xlabel("k")
    ax.set_ylabel("induced 2-norm")
    ax.set_title(r"(c) $|A_c^k|$ and its bound")
    ax.legend()
    fig.tight_layout()
    return fig


def plot_fig3_4(run: ClosedLoopRun, agents: tuple[int, int]) -> plt.Figure:
    """Figs. 3-4: errors e_{jk} of two agents (1-based) with the bounds +-sqrt(P_jj)."""
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True)
    for row, a in enumerate(agents):
        i = a - 1
        e = run.error[0, :, i]
        for comp in range(2):
            ax = axes[row, comp]
            s = np.sqrt(run.P[0, :, i, comp, comp])
            ax.fill_between(run.k, -s, s, color="C0", alpha=0.2, lw=0, label=r"$\pm\sqrt{(P_{k|k})_{jj}}$")
            ax.plot(run.k, e[:, comp], "C3", label=f"$e_{{{comp + 1}k}}$")
            ax.set_ylabel(f"agent {a}: $e_{{{comp + 1}k}}$ (state units)")
            ax.set_xlabel("time step k")
        axes[row, 0].legend(loc="upper right")
    fig.tight_layout()
    return fig


def plot_fig5(run: ClosedLoopRun) -> plt.Figure:
    """Fig. 5: estimation error norms |e_k| of the four agents."""
    fig, ax = plt.subplots(figsize=(6.4, 4))
    colors = agent_colors(N_AGENTS)
    for i in range(N_AGENTS):
        ax.plot(run.k, np.linalg.norm(run.error[0, :, i], axis=-1), color=colors[i], label=f"agent {i + 1}")
    ax.set_xlabel("time step k")
    ax.set_ylabel(r"$|e_k^{(i)}|$ (state units)")
    ax.legend()
    return fig


def plot_fig6(run: ClosedLoopRun) -> plt.Figure:
    """Fig. 6: trace of the correction shape matrices P_{k|k}^(i)."""
    fig, ax = plt.subplots(figsize=(6.4, 4))
    colors = agent_colors(N_AGENTS)
    tr = np.trace(run.P[0], axis1=-2, axis2=-1)
    for i in range(N_AGENTS):
        ax.plot(run.k, tr[:, i], color=colors[i], label=f"agent {i + 1}")
    ax.axhline(np.trace(P0), color="0.5", ls=":", label=r"trace $P_0$ = 4")
    ax.set_xlabel("time step k")
    ax.set_ylabel(r"trace $P_{k|k}^{(i)}$ (state units$^2$)")
    ax.legend()
    return fig


# ---------------------------------------------------------------- ledger


def reproduce(out_dir: Path, seed: int) -> list[Claim]:
    """Figs. 1-6 (SDP path), Table 1 (fast path, 100 seeds per row) and the ledger."""
    out_dir = Path(out_dir)
    use_style()
    des = design()
    # figures: run 0 of `seed` on the SDP path (the paper's solver route)
    run_sdp = simulate(SETTINGS[0], seed=seed, n_runs=1, method="sdp", progress=True)
    figs = {"fig1": plot_fig1(des), "fig2": plot_fig2(run_sdp, des), "fig3": plot_fig3_4(run_sdp, (1, 2)),
            "fig4": plot_fig3_4(run_sdp, (3, 4)), "fig5": plot_fig5(run_sdp), "fig6": plot_fig6(run_sdp)}
    for name, fig in figs.items():
        save_figure(fig, out_dir / "figures" / f"{name}.png")
    table, runs = table1_study(seed, n_runs=100, progress=True)
    # the same study with the edges of eq. (24) reversed: a reading that fits the means (see the notes)
    table_rev, _ = table1_study(seed, n_runs=100, adjacency=ADJACENCY.T)
    (out_dir / "tables").mkdir(parents=True, exist_ok=True)
    table.to_csv(out_dir / "tables" / "table1.csv", index=False, float_format="%.6g")
    table_rev.to_csv(out_dir / "tables" / "table1_edges_reversed.csv", index=False, float_format="%.6g")
    return ledger_claims(des, run_sdp, table, runs, seed, table_reversed=table_rev)


def ledger_claims(
    des: sync.SyncDesign, run_sdp: ClosedLoopRun, table: pd.DataFrame, runs: list[ClosedLoopRun], seed: int,
    table_reversed: pd.DataFrame | None = None,
) -> list[Claim]:
    """The ledger claims from the design, the SDP figure run and the Table 1 study (see :func:`reproduce`).

    `table_reversed`, if given, is :func:`table1_study` with ``adjacency=ADJACENCY.T``; its run-0
    values are quoted in the Table 1 notes.
    """
    n_runs = int(table["n_runs"].iloc[0])
    claims = [
        Claim("bhattacharjee2021/lemma2-r", "Sec. 5, text", "Lemma 2's r for the example (Q = 0.1 I, B = I).",
              1.0, des.r, {"abs": 1e-9},
              f"P of eq. (16) solved by scipy's DARE with zero input weight (residual {des.residual:.1e}); with "
              "B = I it equals Q, and r = 1 exactly."),
        Claim("bhattacharjee2021/coupling-gain-c", "Sec. 5, text",
              "Coupling gain c = 1/c0 with all eigenvalues of Gamma in C(2/3, 0.6) and r0/c0 = 0.9 < r.",
              1.5, des.c, {"abs": 1e-12},
              f"Eigenvalues of Gamma {np.round(des.eigs, 4).tolist()} all lie in the open circle "
              f"(distances to c0: {np.round(np.abs(des.eigs - des.c0), 4).tolist()} < 0.6); rho(A_c) = {des.rho:.4f}."),
    ]
    bound = sync.bound_eq21(des.B_c, G_DIST, P0_BOUND, Q_BAR)
    claims.append(Claim(
        "bhattacharjee2021/bound-eq21", "Sec. 5, text (Fig. 2(b))",
        "Conservative limit bound |B_c| sqrt(p0) + |G| sqrt(q_bar) of eq. (21), p0 = 2, q_bar = 0.1.",
        2.462, bound, {"abs": 5e-4},
        f"|B_c| = {np.linalg.norm(des.B_c, 2):.5f} (spectral norm), |G| = 1 (disturbance matrix I_2); "
        "the paper prints three decimals."))
    kmax = 400
    ratio = sync.exponential_bound_ratio(des.A_c, ALPHA, MU, kmax)
    claims.append(Claim.qualitative(
        "bhattacharjee2021/fig2c-Ac-bound", "Fig. 2(c)", "|A_c^k| <= 1.1 * 0.9^k for all k.",
        {"max_ratio": ratio, "k_max": kmax, "smallest_alpha_for_mu_0.9": sync.fit_alpha(des.A_c, MU)}, ratio <= 1.0,
        f"Checked for k = 0..{kmax} (0.9^{kmax} ~ 5e-19, and rho(A_c) = {des.rho:.4f} < 0.9)."))
    tr_sdp_run = np.trace(run_sdp.P[0], axis1=-2, axis2=-1).mean(axis=-1)
    tr_end = float(tr_sdp_run[-1])
    trace_settle = float(np.ptp(tr_sdp_run[-11:]))
    claims.append(Claim(
        "bhattacharjee2021/fig6-trace-limit", "Fig. 6 and Sec. 5, text",
        "Trace of the correction shape matrices settles at about 1.5 (from trace P_0 = 4).",
        1.5, tr_end, {"abs": 0.05},
        f"Ours: trace P_{{k|k}} at k = {T_F}, mean over the four agents, SDP path; the paper reads the value "
        f"off its plot ('approximately 1.5'; its {4 / 1.5:.3f}-fold decrease is 4 / 1.5, so it carries no further "
        f"digits); ours is a {4 / tr_end:.3f}-fold decrease. The gap of {tr_end - 1.5:.3f} is not numerical: the trace "
        f"does not depend on the noise draw (the SDPs use only P, Q, R), has settled by k = 10 (change over the last "
        f"10 steps {trace_settle:.1e}), and the closed-form twins give the same value (claim sdp-closed-form-agree). "
        "We read the paper's 1.5 as a rounded reading of its plot and keep the 0.05 tolerance fixed beforehand."))
    # the noise-free transient |A_c^k delta_0| / mu_bar from run 0's initial states: what dominates Table 1
    d0 = (runs[0].x[0, 0] - LEADER_X0).ravel()
    transient = np.array([np.linalg.norm(np.linalg.matrix_power(des.A_c, k) @ d0) for k in range(T_F + 1)])
    transient /= sync.mu_bar(ALPHA, MU, N_AGENTS)
    tr_mean, tr_rms = transient.mean(), np.sqrt((transient**2).mean())
    readings = table1_readings().set_index("reading")
    within = (readings["mean_rel_diff"].abs() <= 0.05) & (readings["rms_rel_diff"].abs() <= 0.05)
    rev_name = "edges reversed (adjacency transposed)"
    others = readings.iloc[1:].drop(index=rev_name)
    tried = "; ".join(f"{name} {r['mean']:.3f} / {r['rms']:.3f}" for name, r in others.iterrows())
    tried += "; " + ("none is within 5 % on both" if not within[others.index].any()
                     else f"within 5 % on both: {', '.join(others.index[within[others.index]])}")
    rev = readings.loc[rev_name]
    rev_note = (f"Reversing the edges of eq. (24) (adjacency transposed, an easy slip in the edge convention; Gamma keeps "
                f"its eigenvalues, so Fig. 1(b) cannot tell) gives {rev['mean']:.3f} / {rev['rms']:.3f} noise-free")
    if table_reversed is not None:
        dm = table_reversed["mean_run0"] / table_reversed["paper_mean"] - 1
        dr = table_reversed["rms_run0"] / table_reversed["paper_rms"] - 1
        om = table["mean_run0"] / table["paper_mean"] - 1
        orr = table["rms_run0"] / table["paper_rms"] - 1
        rev_note += (f". The full study with reversed edges (run 0, tables/table1_edges_reversed.csv) puts the means "
                     f"{dm.min():+.1%} to {dm.max():+.1%} and the RMS values {dr.min():+.1%} to {dr.max():+.1%} from "
                     f"the paper's (as printed: means {om.min():+.1%} to {om.max():+.1%}, RMS {orr.min():+.1%} to "
                     f"{orr.max():+.1%}): largest gap {max(dm.abs().max(), dr.abs().max()):.1%} with reversed edges "
                     f"against {max(om.abs().max(), orr.abs().max()):.1%} as printed. Reversed edges fit the means but "
                     "put every RMS value low where the printed graph puts it high, so neither graph matches both "
                     "columns closely; the paper prints the Laplacian of eq. (24) explicitly, so we keep it and the "
                     "verdicts are for it.")
    else:
        rev_note += ": closer on the mean, further on the RMS; we keep eq. (24) as printed."
    for i, row in table.iterrows():
        for metric in ("mean", "rms"):
            claims.append(Claim(
                f"bhattacharjee2021/table1-row{i + 1}-{metric}", f"Table 1, row {i + 1}",
                f"{'Mean' if metric == 'mean' else 'RMS'} of |delta_bar_k| over k = 0..60 with alpha_w = alpha_v = "
                f"{row.alpha_w:g}, Q = {row.Q}, R = {row.R}.",
                float(row[f"paper_{metric}"]), float(row[f"{metric}_run0"]), {"rel": 0.05},
                f"Ours is run 0 (one uniform draw, the paper's kind of draw; closed-form filter path). Over "
                f"{n_runs} seeds: mean {row[f'{metric}_avg']:.4f}, std {row[f'{metric}_std']:.4f}, 5-95% "
                f"[{row[f'{metric}_q05']:.4f}, {row[f'{metric}_q95']:.4f}], range [{row[f'{metric}_min']:.4f}, "
                f"{row[f'{metric}_max']:.4f}]. The paper gives one unseeded MATLAB draw; the tolerance (5 %) was "
                "fixed before comparing. The gap is systematic, not a draw effect: the metrics are dominated by the "
                f"noise-free transient A_c^k delta_0 (alone: mean {tr_mean:.4f}, RMS {tr_rms:.4f}), which the paper's "
                "A_c, delta_0 and mu_bar fix. Other readings tried, noise-free mean / RMS against row 1's "
                f"0.3706 / 1.1985: {tried}. {rev_note}"))
    forms = [r.containment for r in runs] + [run_sdp.containment]
    worst = float(max(f.max() for f in forms))
    n_checks = int(sum(f.size for f in forms))
    claims.append(Claim.qualitative(
        "bhattacharjee2021/containment", "Figs. 3-4 and Sec. 5, text",
        "The true state lies in every agent's correction ellipsoid at every step.",
        {"max_e_Pinv_e": worst, "n_checks": n_checks, "runs": 3 * n_runs + 1}, worst <= 1.0 + 1e-6,
        f"e^T P_{{k|k}}^-1 e over all 3 x {n_runs} Table 1 runs (closed form) and the SDP figure run, all agents, "
        "k = 0..60 (tolerance 1e-6 for the SDP solver accuracy)."))
    # Fig. 5 / proof of Corollary 1: sup_k |e_k^(g)| <= |e_0^(g)| (stacked over agents)
    def sup_over_e0(run):
        e0 = np.linalg.norm(run.x[:, 0] - X0_HAT, axis=(-1, -2))
        return np.linalg.norm(run.error, axis=(-1, -2)).max(axis=1) / e0
    ratio_fig = float(sup_over_e0(run_sdp)[0])
    frac = [float(np.mean(sup_over_e0(r) <= 1.0)) for r in runs]
    claims.append(Claim.qualitative(
        "bhattacharjee2021/fig5-error-below-initial", "Fig. 5 and Sec. 5, text",
        "The global estimation error never exceeds its initial value: sup_k |e_k^(g)| <= |e_0^(g)| (used for eq. (21)).",
        {"sup_over_e0_figure_run": ratio_fig, "fraction_of_seeds_holding_rows_1_2_3": frac}, ratio_fig <= 1.0,
        f"Decided on the figure run (row 1, SDP path). Over {n_runs} seeds it holds in a fraction {frac} of the runs of "
        "rows 1-3: when the random x_0 falls close to xhat_0 the initial error is tiny and later errors, driven by "
        "v_k, exceed it, so the step in the proof of Corollary 1 is an assumption about the draw, not a guarantee."))
    # the closed-form twins against the SDPs, step by step from the same inputs (the SDP run's ellipsoids)
    # (the correction shape does not depend on y_k, so y = C xpred is used)
    _, Pc_cf, _ = smf.correct(run_sdp.xpred[0], run_sdp.Ppred[0], run_sdp.xpred[0] @ C.T,
                              C, D, SETTINGS[0].R, method="closed_form")
    rel_corr = float(np.max(np.abs(np.trace(Pc_cf - run_sdp.P[0], axis1=-2, axis2=-1))
                            / np.trace(Pc_cf, axis1=-2, axis2=-1)))
    _, Pp_cf = smf.predict(run_sdp.xhat[0, :-1], run_sdp.P[0, :-1], A, G_DIST, SETTINGS[0].Q, method="closed_form")
    rel_pred = float(np.max(np.abs(np.trace(Pp_cf - run_sdp.Ppred[0, 1:], axis1=-2, axis2=-1))
                            / np.trace(Pp_cf, axis1=-2, axis2=-1)))
    run_fast = simulate(SETTINGS[0], seed=seed, n_runs=1, method="closed_form")
    tr_sdp = np.trace(run_sdp.P, axis1=-2, axis2=-1)
    tr_fast = np.trace(run_fast.P, axis1=-2, axis2=-1)
    drift = float(np.max(np.abs(tr_sdp - tr_fast) / tr_fast))
    claims.append(Claim.qualitative(
        "bhattacharjee2021/sdp-closed-form-agree", "Sec. 3, eqs. (6)-(8)",
        "The closed-form twins reach the SDP optima: same trace from the same ellipsoid at every step.",
        {"max_rel_trace_diff_correction": rel_corr, "max_rel_trace_diff_prediction": rel_pred,
         "closed_loop_max_rel_trace_diff": drift}, max(rel_corr, rel_pred) <= 1e-6,
        "Every correction (eqs. (6)-(7)) and prediction (eq. (8)) of the SDP figure run redone in closed form from the "
        "same input ellipsoid (Clarabel's tolerances are 1e-8). Run separately in closed loop the two paths drift apart "
        f"by up to {drift:.1e} in trace: the trace is flat at its optimum, so a solver tolerance eps moves the "
        "optimal Minkowski-sum parameter, and the shape, by O(sqrt(eps))."))
    return claims
