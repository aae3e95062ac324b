"""Ren, Beard and Kingston (2005), "Multi-agent Kalman consensus with relative uncertainty".

The scenarios of the paper in one place: the meet-for-dinner example (Fig. 1),
the directed graphs of Figs. 2-3 and switching sequences built from them (the
hypotheses of Theorems 3.2 and 3.9), the effect of communication noise, and
two studies beyond the paper: how far the agreed value is from what a central
fusion centre would compute, and how far the agents' variances are from the
actual ones.

Every parameter sits in :data:`SETTINGS` (a :class:`KalmanConsensusSettings`;
the ones the paper leaves out are marked as our choice); :func:`run` computes
everything random or expensive once, and :data:`REGISTRY` draws the figures,
builds the tables and decides the claims from its result, for both
``python -m mascore reproduce ren2005`` and the chapter
``ren2005_kalman_consensus``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from .. import consensus as cs
from .._progress import progress_bar
from .._validation import (
    as_matrix,
    check_adjacency,
    check_fits_in_memory,
    check_positive,
    check_positive_int,
    check_seed,
    float_array,
    require_finite,
)
from ..graphs import adjacency_from_edges, has_spanning_tree, is_connected, spanning_tree_roots
from ..ledger import Claim, format_number
from ..registry import (
    FigureSpec,
    PaperRegistry,
    Study,
    TableSpec,
    check_settings,
    check_settings_type,
    documented_settings,
    setting,
)

if TYPE_CHECKING:  # the figures' type; pyplot is imported where a figure is drawn
    import matplotlib.pyplot as plt

__all__ = [
    "REGISTRY", "SETTINGS", "STUDY", "FIGURES", "TABLES", "Fig1Result", "KalmanConsensusResult",
    "KalmanConsensusSettings", "SwitchingDemo", "claims", "fig1", "fig1_initial", "fig2_graph", "fig3a_graph",
    "fig3b_graph", "fixed_graph_run", "no_union_sequence", "noise_continuous", "overconfidence", "plot_fig1",
    "prose_values", "run", "switching_demo", "union_sequence",
]


# --------------------------------------------------------------------------- settings


@documented_settings
@dataclass(frozen=True)
class KalmanConsensusSettings:
    """Every parameter of the ren2005 runs: the paper's (Sec. II-C) and the ones we chose."""

    # Fig. 1, the meet-for-dinner example
    n_agents: int = setting(10, where="Sec. II-C", note="friends meeting for dinner (Fig. 1)", low=2)
    Q: float = setting(0.1, where="Sec. II-C", unit="h²", note="process noise of the consensus value", low=0)
    Omega: float = setting(0.1, where="Sec. II-C", unit="h²", note="communication noise Ω_ij, every link",
                           low=0, low_open=True)
    xi0: tuple[float, ...] = setting(
        tuple(float(x) for x in range(1, 11)), source="chosen", where='paper: "uniformly assigned"', unit="h",
        note="initial meeting times ξ_i(0) of agents 1..10", kind="reals")
    P_equal: float = setting(1.0, source="chosen", where='paper: "uniformly assigned"', unit="h²",
                             note="initial variances (left column; all but agent 7 in the right)", low=0, low_open=True)
    confident_agent: int = setting(7, source="derived", where="the agent whose ξ_i(0) = 7",
                                   note="the confident agent of Fig. 1's right column (1-based)", low=1)
    P_confident: float = setting(0.001, where="Sec. II-C", unit="h²", note="its initial variance", low=0, low_open=True)
    n_steps: int = setting(100, source="chosen", where="not given", note="horizon of Fig. 1 (steps)", low=1)
    max_call: int = setting(5, source="chosen", where='paper: "a random length of time"', unit="steps",
                            note="calls last 1..max_call steps, uniformly; the whole team is re-paired at once", low=1)
    fig1_noise: bool = setting(False, source="chosen", where="not said; the figure shows exact agreement",
                               note="draw communication noise in Fig. 1 (Ω enters the weights either way)")
    include_self: bool = setting(True, where="eqs. (1), (4): g_ii = 1",
                                 note="keep an agent's own term (no noise drawn on it)")
    # Theorems 3.2 and 3.9 on switching graphs
    switch_xi0: tuple[float, ...] = setting(
        tuple(float(x) for x in range(1, 7)), source="chosen", where="the paper simulates no switching",
        note="initial states of the six agents of Figs. 2-3", length=6)
    switch_P0: float = setting(1.0, source="chosen", where="the paper simulates no switching",
                               note="their initial variances", low=0, low_open=True)
    dwell_steps: int = setting(2, source="chosen", where="the paper simulates no switching",
                               note="steps per graph, discrete time", low=1)
    switch_steps: int = setting(800, source="chosen", where="the paper simulates no switching",
                                note="horizon, discrete time (steps)", low=1)
    dwell_time: float = setting(1.0, source="chosen", where="the paper simulates no switching", unit="s",
                                note="time per graph, continuous time", low=0, low_open=True)
    t_final: float = setting(200.0, source="chosen", where="the paper simulates no switching", unit="s",
                             note="horizon, continuous time", low=0, low_open=True)
    # communication noise (the paper's model, not simulated there)
    noise_runs: int = setting(200, source="chosen", where="the paper shows no noisy run",
                              note="pairing schedules, discrete noise study (Fig. 1 setting, equal P)", low=1)
    noise_steps: int = setting(300, source="chosen", where="the paper shows no noisy run",
                               note="their horizon (steps)", low=1)
    noise_Omega_small: float = setting(0.01, source="chosen", where="the paper shows no noisy run", unit="h²",
                                       note="the smaller Ω compared with the paper's", low=0, low_open=True)
    noise_paths: int = setting(100, source="chosen", where="the paper shows no noisy run",
                               note="paths, continuous-time noise on the fixed Fig. 2 graph", low=1)
    noise_t_final: float = setting(40.0, source="chosen", where="the paper shows no noisy run", unit="s",
                                   note="their horizon", low=0, low_open=True)
    noise_dt: float = setting(0.01, source="chosen", where="the paper shows no noisy run", unit="s",
                              note="Euler-Maruyama step", low=0, low_open=True)
    # beyond the paper
    bias_runs: int = setting(1000, source="chosen", where="beyond the paper",
                             note="pairing schedules in the bias study (Fig. 1 right-column data)", low=1)
    ideal_Omega: float = setting(1e-6, source="chosen", where="beyond the paper", unit="h²",
                                 note="Ω of the variant closest to central fusion (Q = 0, no self term)",
                                 low=0, low_open=True)

    def __post_init__(self) -> None:
        check_settings(self)
        if len(self.xi0) != self.n_agents:
            example = tuple(float(x) for x in range(1, self.n_agents + 1))
            raise ValueError(f"KalmanConsensusSettings.xi0 must hold one initial time per agent (n_agents = "
                             f"{self.n_agents}); got {len(self.xi0)}: change the two together, e.g. "
                             f"--set n_agents={self.n_agents} xi0=\"{example}\"")
        if not 1 <= self.confident_agent <= self.n_agents:
            raise ValueError(f"KalmanConsensusSettings.confident_agent must be an agent 1..n_agents "
                             f"(1..{self.n_agents}); got {self.confident_agent}: set it too, e.g. "
                             f"--set confident_agent={self.n_agents}")
        if self.noise_dt > self.noise_t_final:
            raise ValueError(f"KalmanConsensusSettings.noise_dt must be at most noise_t_final "
                             f"({self.noise_t_final} s); got {self.noise_dt}")
        n2 = 8.0 * self.n_agents**2
        check_fits_in_memory(n2 * self.noise_runs * (self.noise_steps + 1), "KalmanConsensusSettings.noise_runs x noise_steps",
                             "the pairings and states of the noise study")
        check_fits_in_memory(n2 * min(self.bias_runs, 500) * (self.n_steps + 1), "KalmanConsensusSettings.bias_runs x n_steps",
                             "the pairings of one chunk of the bias study")
        check_fits_in_memory(8.0 * 2 * len(self.switch_xi0) * self.noise_paths * 401,
                             "KalmanConsensusSettings.noise_paths", "the Euler-Maruyama paths at 401 times")

    @property
    def fig1_xi0(self) -> np.ndarray:
        """Initial meeting times as an array: (n,) ndarray, the meeting times (h)."""
        return np.asarray(self.xi0, dtype=float)


#: The paper's settings and our choices; the one place the run reads from.
SETTINGS = KalmanConsensusSettings()
#: Index of the agent whose initial value is 7 (0-based).
CONFIDENT_AGENT = SETTINGS.confident_agent - 1
#: Aliases of :data:`SETTINGS` for older callers (the benchmark): Fig. 1 and the theorem demos.
FIG1 = dict(n_agents=SETTINGS.n_agents, Q=SETTINGS.Q, Omega=SETTINGS.Omega, P_equal=SETTINGS.P_equal,
            P_confident=SETTINGS.P_confident, n_steps=SETTINGS.n_steps, max_duration=SETTINGS.max_call)
THEOREM = dict(xi0=np.asarray(SETTINGS.switch_xi0), P0=SETTINGS.switch_P0, Q=SETTINGS.Q, Omega=SETTINGS.Omega,
               dwell_steps=SETTINGS.dwell_steps, n_steps=SETTINGS.switch_steps,
               dwell_time=SETTINGS.dwell_time, t_final=SETTINGS.t_final)


def variant_label(Q: float, Omega: float, include_self: bool = True, paper: bool = False) -> str:
    """A short name of a variant of the scheme: ``"Q = 0, Ω = 0.1"``, ``"... no self term"``, ``"(paper)"``."""
    check_positive(Q, "Q", "h²", allow_zero=True)
    check_positive(Omega, "Omega", "h²", allow_zero=True)
    label = f"Q = {format_number(Q)}, Ω = {format_number(Omega)}"
    label += "" if include_self else ", no self term"
    return label + (" (paper)" if paper else "")


# --------------------------------------------------------------------------- graphs of Figs. 2-3

# Node positions for drawing the six-agent graphs (agents 1..6).
FIG2_LAYOUT = np.array([[0.0, 1.0], [1.0, 1.6], [2.0, 1.0], [0.0, -0.2], [1.0, 0.4], [2.0, -0.2]])
FIG3_LAYOUT = np.array([[0.0, 1.0], [1.0, 1.0], [2.0, 1.0], [0.0, 0.0], [1.0, 0.0], [2.0, 0.0]])

#: Edges (j, i) of the highlighted spanning tree of Fig. 2, rooted at agent 5 (0-based 4).
FIG2_TREE = [(4, 0), (0, 3), (0, 1), (1, 2), (4, 5)]


def fig2_graph() -> np.ndarray:
    """Fig. 2 redrawn: a directed graph with several spanning trees, not strongly connected.

    Drawn to satisfy the paper's caption, which fixes that a spanning tree can
    be rooted at A5, A1 or A4. Ours: the cycle 1 -> 4 -> 5 -> 1
    (the possible roots) feeding 2, 3 and 6, with nothing flowing back.

    Returns
    -------
    (6, 6) ndarray
        Adjacency, ``A[i, j] > 0`` for ``j -> i``.

    Examples
    --------
    >>> from mascore import graphs
    >>> from mascore.papers import ren2005
    >>> (graphs.spanning_tree_roots(ren2005.fig2_graph()) + 1).tolist()    # 1-based, as in the paper
    [1, 4, 5]
    """
    edges = [(0, 3), (3, 4), (4, 0), (4, 5), (0, 1), (1, 2), (5, 2)]
    return adjacency_from_edges(6, edges, directed=True)


def fig3a_graph() -> np.ndarray:
    """Fig. 3(a) redrawn: two leaders (agents 1 and 4 hear nobody); chains 1->2->3, 4->5->6, bridge 3->6.

    Returns
    -------
    (6, 6) ndarray
        Adjacency, ``A[i, j] > 0`` for ``j -> i``.

    Examples
    --------
    >>> from mascore import graphs
    >>> from mascore.papers import ren2005
    >>> graphs.has_spanning_tree(ren2005.fig3a_graph())
    False
    """
    return adjacency_from_edges(6, [(0, 1), (1, 2), (3, 4), (4, 5), (2, 5)], directed=True)


def fig3b_graph() -> np.ndarray:
    """Fig. 3(b) redrawn: two isolated groups {1, 2, 3} and {4, 5, 6} (two-way chains).

    Returns
    -------
    (6, 6) ndarray
        Adjacency, ``A[i, j] > 0`` for ``j -> i``.

    Examples
    --------
    >>> from mascore import graphs
    >>> from mascore.papers import ren2005
    >>> graphs.has_spanning_tree(ren2005.fig3b_graph())
    False
    """
    return adjacency_from_edges(6, [(0, 1), (1, 2), (3, 4), (4, 5)], directed=False)


def union_sequence() -> np.ndarray:
    """Fig. 3(a) and Fig. 3(b) alternating: neither has a spanning tree, their union does.

    Returns
    -------
    (2, 6, 6) ndarray
        The two graphs, cycled by :func:`switching_demo`.

    Examples
    --------
    >>> from mascore import graphs
    >>> from mascore.papers import ren2005
    >>> graphs.has_spanning_tree(graphs.graph_union(ren2005.union_sequence()))
    True
    """
    return np.stack([fig3a_graph(), fig3b_graph()])


def no_union_sequence() -> np.ndarray:
    """Fig. 3(b) and Fig. 3(a) without its bridge 3->6: every union is two isolated groups.

    Returns
    -------
    (2, 6, 6) ndarray
        The two graphs, cycled by :func:`switching_demo`.

    Examples
    --------
    >>> from mascore import graphs
    >>> from mascore.papers import ren2005
    >>> graphs.has_spanning_tree(graphs.graph_union(ren2005.no_union_sequence()))
    False
    """
    a = fig3a_graph()
    a[5, 2] = 0.0
    return np.stack([a, fig3b_graph()])


# --------------------------------------------------------------------------- Fig. 1


@dataclass(frozen=True)
class Fig1Result:
    """Both columns of Fig. 1 plus the equal-weight comparison, on the same pairings.

    Parameters
    ----------
    pairings : (K, n, n) ndarray
        The random one-to-one pairings, one graph per step.
    equal : mascore.consensus.ConsensusResult
        Left column: equal initial variances.
    confident : mascore.consensus.ConsensusResult
        Right column: agent 7 confident (small initial variance).
    average : mascore.consensus.ConsensusResult
        Ordinary average consensus on the same pairings (the comparison).
    fused_confident : float
        What a fusion centre would compute from the right column's initial data.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> res = ren2005.fig1(seed=1)
    >>> res.pairings.shape, res.confident.xi.shape
    ((100, 10, 10), (101, 10))
    """

    pairings: np.ndarray  # (K, n, n)
    equal: cs.ConsensusResult  # left column
    confident: cs.ConsensusResult  # right column
    average: cs.ConsensusResult  # ordinary average consensus on the same pairings
    fused_confident: float  # inverse-variance weighted mean of the right column's initial data


def fig1_initial(confident: bool, settings: KalmanConsensusSettings = SETTINGS) -> tuple[np.ndarray, np.ndarray]:
    """Initial times and variances of Fig. 1 (the confident agent at `P_confident` if `confident`).

    Parameters
    ----------
    confident : bool
        Right column (agent 7 confident) or left column (equal variances).
    settings : KalmanConsensusSettings
        The study's settings (default :data:`SETTINGS`).

    Returns
    -------
    xi0 : (n,) ndarray
        Initial meeting times (h).
    P0 : (n,) ndarray
        Initial variances (h²).

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> xi0, P0 = ren2005.fig1_initial(confident=True)
    >>> float(P0[6]), float(P0[0])
    (0.001, 1.0)
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    xi0 = settings.fig1_xi0
    P0 = np.full(settings.n_agents, settings.P_equal)
    if confident:
        P0[settings.confident_agent - 1] = settings.P_confident
    return xi0, P0


def _pairings(settings: KalmanConsensusSettings, rng: np.random.Generator, n_steps: int,
              size: int | None = None) -> np.ndarray:
    """Random one-to-one pairings of the Fig. 1 team, calls of 1..max_call steps."""
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    return cs.random_pairings(settings.n_agents, n_steps, rng, max_duration=settings.max_call, size=size)


def fig1(seed: int = 1, noise: bool | None = None, settings: KalmanConsensusSettings = SETTINGS) -> Fig1Result:
    """The meet-for-dinner simulation of Fig. 1 (discrete time, eqs. (4)-(5)).

    Parameters
    ----------
    seed : int
        Seed of the pairing schedule (and of the communication noise).
    noise : bool, optional
        Draw communication noise ``nu_ij ~ N(0, Omega)`` (default: ``settings.fig1_noise``,
        False). The paper's Fig. 1 uses Omega = 0.1 in the weights; whether noise
        was also injected is not said.
    settings : KalmanConsensusSettings
        The study's settings (default :data:`SETTINGS`).

    Returns
    -------
    Fig1Result
        Both columns of Fig. 1 and the equal-weight comparison.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.papers import ren2005
    >>> res = ren2005.fig1(seed=1)
    >>> final = res.confident.xi[-1]
    >>> bool(np.ptp(final) < 0.01), round(float(final.mean()), 1)   # all agree; the average 5.5 h is pulled to 7 h
    (True, 5.8)
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    check_seed(seed, "seed")
    noise = settings.fig1_noise if noise is None else noise
    rng = np.random.default_rng(seed)
    G = _pairings(settings, rng, settings.n_steps)
    runs = {}
    for name, confident in (("equal", False), ("confident", True)):
        xi0, P0 = fig1_initial(confident, settings)
        runs[name] = cs.kalman_consensus_discrete(xi0, P0, G, settings.Q, settings.Omega,
                                                  rng=rng if noise else None, include_self=settings.include_self)
    xi0, P0 = fig1_initial(True, settings)
    return Fig1Result(G, runs["equal"], runs["confident"], cs.average_consensus(xi0, G),
                      float(cs.central_fusion(xi0, P0)[0]))


# --------------------------------------------------------------------------- theorems


@dataclass(frozen=True)
class SwitchingDemo:
    """Discrete and continuous runs on one switching sequence.

    Parameters
    ----------
    graphs : (S, n, n) ndarray
        The graphs cycled through.
    sequence : (K, n, n) ndarray
        The discrete-time sequence (each graph held ``dwell_steps``).
    union_ok : bool
        Whether every window's union has a spanning tree.
    discrete : mascore.consensus.ConsensusResult
        Eqs. (4)-(5) on `sequence`.
    continuous : mascore.consensus.ConsensusResult
        Eqs. (1)-(3), each graph held ``dwell_time`` s.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> demo = ren2005.switching_demo(ren2005.union_sequence())
    >>> demo.union_ok, bool(demo.discrete.spread[-1] < 1e-3)
    (True, True)
    """

    graphs: np.ndarray  # (S, n, n) graphs cycled through
    sequence: np.ndarray  # (K, n, n) discrete sequence
    union_ok: bool  # hypothesis of Thms 3.2/3.9 with window = one cycle
    discrete: cs.ConsensusResult
    continuous: cs.ConsensusResult


def _check_graph_stack(graphs: np.ndarray, n: int) -> np.ndarray:
    """`graphs` as a float (S, n, n) stack of adjacency matrices (S >= 1), each checked."""
    arr = float_array(graphs, "graphs")
    if arr.ndim != 3 or arr.shape[0] == 0 or arr.shape[1:] != (n, n):
        raise ValueError(f"graphs must be a stack of adjacency matrices of shape (S, {n}, {n}) with S >= 1 "
                         f"(one row and column per agent of settings.switch_xi0); got shape {arr.shape}")
    for k, g in enumerate(arr):
        check_adjacency(g, f"graphs[{k}]")
    return arr


def switching_demo(graphs: np.ndarray, settings: KalmanConsensusSettings = SETTINGS) -> SwitchingDemo:
    """Kalman consensus, eqs. (1)-(3) and (4)-(5), while cycling through `graphs`.

    Parameters
    ----------
    graphs : (S, n, n) ndarray
        The graphs to cycle through (e.g. :func:`union_sequence`).
    settings : KalmanConsensusSettings
        The study's settings (default :data:`SETTINGS`).

    Returns
    -------
    SwitchingDemo
        The discrete and continuous runs.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> ren2005.switching_demo(ren2005.no_union_sequence()).union_ok
    False
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    s = settings
    xi0 = np.asarray(s.switch_xi0, dtype=float)
    graphs = _check_graph_stack(graphs, xi0.size)
    P0 = np.full(graphs.shape[-1], s.switch_P0)
    seq = cs.periodic_sequence(graphs, s.dwell_steps, s.switch_steps)
    disc = cs.kalman_consensus_discrete(xi0, P0, seq, s.Q, s.Omega, include_self=s.include_self)
    topo = cs.SwitchingTopology.periodic(graphs, s.dwell_time, s.t_final)
    cont = cs.kalman_consensus_continuous(xi0, P0, topo, s.t_final, s.Q, s.Omega, include_self=s.include_self,
                                          t_eval=np.linspace(0, s.t_final, 401))
    window = s.dwell_steps * graphs.shape[0]
    return SwitchingDemo(graphs, seq, cs.union_condition_holds(seq, window), disc, cont)


def fixed_graph_run(settings: KalmanConsensusSettings = SETTINGS) -> cs.ConsensusResult:
    """Continuous-time Kalman consensus on the fixed Fig. 2 graph (it has a spanning tree).

    Parameters
    ----------
    settings : KalmanConsensusSettings
        The study's settings (default :data:`SETTINGS`).

    Returns
    -------
    mascore.consensus.ConsensusResult
        The run, ``t_final`` s long.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> bool(ren2005.fixed_graph_run().spread[-1] < 1e-3)
    True
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    s = settings
    xi0 = np.asarray(s.switch_xi0, dtype=float)
    return cs.kalman_consensus_continuous(xi0, np.full(xi0.size, s.switch_P0), fig2_graph(), s.t_final, s.Q,
                                          s.Omega, include_self=s.include_self)


def decay_rate(t: np.ndarray, spread: np.ndarray) -> float:
    """Least-squares slope of log(spread) over the second half of the run (per step or per s)."""
    t = require_finite(float_array(t, "t"), "t")
    spread = require_finite(float_array(spread, "spread"), "spread")
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"t must be a 1-D array of at least 3 times; got shape {t.shape}")
    if spread.shape != t.shape:
        raise ValueError(f"spread must have the shape of t, {t.shape}; got shape {spread.shape}")
    if np.any(spread < 0):
        raise ValueError(f"spread must be non-negative (max - min over the agents); smallest entry {spread.min():.3g}")
    half = len(t) // 2
    return float(np.polyfit(np.asarray(t[half:], float), np.log(np.maximum(spread[half:], 1e-300)), 1)[0])


# --------------------------------------------------------------------------- noise, bias, overconfidence


def _rms_disagreement(xi: np.ndarray) -> np.ndarray:
    """RMS deviation of the agents from the team mean, averaged over any batch axes: shape (T,)."""
    dev = xi - xi.mean(axis=-1, keepdims=True)
    rms = np.sqrt((dev**2).mean(axis=-1))
    return rms.reshape(rms.shape[0], -1).mean(axis=-1)


def noise_study(seed: int = 1, n_runs: int | None = None, n_steps: int | None = None, Omega: float | None = None,
                Q: float | None = None, settings: KalmanConsensusSettings = SETTINGS) -> dict:
    """Disagreement with communication noise on the Fig. 1 pairings, over `n_runs` schedules.

    Equal initial variances (Fig. 1, left column); `n_runs`, `n_steps`, `Omega`
    and `Q` default to the settings (``noise_runs``, ``noise_steps``, ``Omega``, ``Q``).

    Returns
    -------
    dict
        ``rms``: the RMS deviation of the agents from the team mean, averaged over
        runs, per step; ``floor`` and ``floor_q3``: its average over the last and
        the third quarter of the horizon; ``slope``: the least-squares slope of
        log(rms) against log(k) over the second half (about 0 for a stationary
        floor, -1/2 for a disagreement that decays like 1/sqrt(k)); ``team_mean``.
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    s = settings
    check_seed(seed, "seed")
    n_runs = check_positive_int(s.noise_runs if n_runs is None else n_runs, "n_runs")
    # the floors average the last and third quarters of the horizon: at least 4 steps
    n_steps = check_positive_int(s.noise_steps if n_steps is None else n_steps, "n_steps", minimum=4)
    check_fits_in_memory(8.0 * s.n_agents**2 * n_runs * (n_steps + 1), "n_runs", "the pairings and states")
    Q = s.Q if Q is None else Q
    Omega = s.Omega if Omega is None else Omega
    rng = np.random.default_rng(seed)
    G = _pairings(s, rng, n_steps, size=n_runs)
    xi0, P0 = fig1_initial(False, s)
    n = s.n_agents
    res = cs.kalman_consensus_discrete(np.broadcast_to(xi0, (n_runs, n)), np.broadcast_to(P0, (n_runs, n)),
                                       G, Q, Omega, rng=rng, include_self=s.include_self)
    rms = _rms_disagreement(res.xi)
    q = n_steps // 4
    k = np.arange(n_steps // 2, n_steps + 1)
    slope = float(np.polyfit(np.log(k), np.log(rms[k]), 1)[0])
    return dict(rms=rms, floor=float(rms[-q:].mean()), floor_q3=float(rms[2 * q:3 * q].mean()), slope=slope,
                team_mean=res.xi.mean(axis=-1), Q=Q, Omega=Omega)


def noise_continuous(seed: int = 1, settings: KalmanConsensusSettings = SETTINGS) -> dict:
    """Continuous-time Kalman consensus with communication noise on the fixed Fig. 2 graph.

    ``settings.noise_paths`` Euler-Maruyama paths of eqs. (1)-(3) (white noise of
    intensity Omega, step ``noise_dt``) next to the noise-free run (RK45).

    Parameters
    ----------
    seed : int
        Seed of the communication noise.
    settings : KalmanConsensusSettings
        The study's settings (default :data:`SETTINGS`).

    Returns
    -------
    dict
        ``t``; ``path``: the states of the first noisy path, (T, 6); ``rms`` and
        ``rms_quiet``: RMS disagreement with noise (mean over paths) and without;
        ``floor`` and ``floor_quiet``: their means over the second half.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import ren2005
    >>> quick = dataclasses.replace(ren2005.SETTINGS, noise_paths=5, noise_t_final=5.0)
    >>> out = ren2005.noise_continuous(seed=1, settings=quick)
    >>> bool(out['floor'] > out['floor_quiet'])                 # noise leaves a disagreement floor
    True
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    s = settings
    xi0 = np.asarray(s.switch_xi0, dtype=float)
    t = np.linspace(0.0, s.noise_t_final, 401)
    batch = (s.noise_paths, xi0.size)
    paths = cs.kalman_consensus_continuous(np.broadcast_to(xi0, batch), np.full(batch, s.switch_P0), fig2_graph(),
                                           s.noise_t_final, s.Q, s.Omega, t_eval=t, rng=seed, dt=s.noise_dt,
                                           include_self=s.include_self)
    quiet = cs.kalman_consensus_continuous(xi0, np.full(xi0.size, s.switch_P0), fig2_graph(), s.noise_t_final,
                                           s.Q, s.Omega, t_eval=t, include_self=s.include_self)
    rms, rms_quiet = _rms_disagreement(paths.xi), _rms_disagreement(quiet.xi)
    late = t >= s.noise_t_final / 2
    return dict(t=t, path=paths.xi[:, 0], rms=rms, rms_quiet=rms_quiet, floor=float(rms[late].mean()),
                floor_quiet=float(rms_quiet[late].mean()))


def bias_study(seed: int = 1, n_runs: int | None = None, n_steps: int | None = None, Q: float | None = None,
               Omega: float | None = None, include_self: bool = True,
               settings: KalmanConsensusSettings = SETTINGS) -> dict:
    """Beyond the paper: agreed value vs the central inverse-variance fusion, over pairing schedules.

    Fig. 1 right column's initial data (times 1..10, agent 7 with P = 0.001);
    only the random pairing schedule changes between runs; noise-free messages.
    `n_runs`, `n_steps`, `Q` and `Omega` default to the settings (``bias_runs``,
    ``n_steps``, ``Q``, ``Omega``).

    Returns
    -------
    dict with ``values`` (n_runs,) agreed values, ``fused`` the central value,
    ``average`` the plain mean of the initial times, ``bias`` mean(values) - fused,
    ``se`` its standard error, ``std``, ``max_spread`` the worst final disagreement.
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    s = settings
    check_seed(seed, "seed")
    # the standard error needs two schedules at least
    n_runs = check_positive_int(s.bias_runs if n_runs is None else n_runs, "n_runs", minimum=2)
    n_steps = check_positive_int(s.n_steps if n_steps is None else n_steps, "n_steps")
    check_fits_in_memory(8.0 * s.n_agents**2 * min(n_runs, 500) * (n_steps + 1), "n_steps", "one chunk of pairings")
    check_fits_in_memory(64.0 * n_runs, "n_runs", "the agreed values")
    Q = s.Q if Q is None else Q
    Omega = s.Omega if Omega is None else Omega
    rng = np.random.default_rng(seed)
    n = s.n_agents
    xi0, P0 = fig1_initial(True, s)
    values, spreads = [], []
    for chunk in np.array_split(np.arange(n_runs), max(1, n_runs // 250)):
        G = _pairings(s, rng, n_steps, size=chunk.size)
        res = cs.kalman_consensus_discrete(np.broadcast_to(xi0, (chunk.size, n)),
                                           np.broadcast_to(P0, (chunk.size, n)), G, Q, Omega,
                                           include_self=include_self)
        values.append(res.final_value)
        spreads.append(res.spread[-1])
    values = np.concatenate(values)
    fused = float(cs.central_fusion(xi0, P0)[0])
    return dict(values=values, fused=fused, average=float(xi0.mean()), bias=float(values.mean() - fused),
                se=float(values.std(ddof=1) / np.sqrt(values.size)), std=float(values.std(ddof=1)),
                max_spread=float(np.concatenate(spreads).max()), Q=Q, Omega=Omega, include_self=include_self)


def overconfidence(seed: int = 1, settings: KalmanConsensusSettings = SETTINGS,
                   fig1_result: Fig1Result | None = None) -> dict:
    """Beyond the paper: what the block-diagonal R_i costs, on the Fig. 1 pairings (noise-free).

    For the right column's initial data (the confident agent 7) and two variants
    of the scheme, the variance each agent believes (``P_i[k]``, eq. (4)) next to
    the actual variance of its error when the initial errors are independent
    with variances ``P_i(0)`` and the meeting time is fixed
    (:func:`mascore.consensus.error_covariance`).

    Parameters
    ----------
    seed : int
        Seed of the Fig. 1 pairings (unused if `fig1_result` is given).
    settings : KalmanConsensusSettings
        The study's settings.
    fig1_result : Fig1Result, optional
        The Fig. 1 run whose pairings to use (default: ``fig1(seed, settings=settings)``).

    Returns
    -------
    dict with ``variants``: key -> dict(label, actual=(K+1, n), believed=(K+1, n)),
    keys ``"paper"`` and ``"ideal"`` (Q = 0, Omega = ``ideal_Omega``, no self term),
    and ``fused_variance``, the central-fusion variance (the smallest any
    combination of the initial data can reach).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.papers import ren2005
    >>> out = ren2005.overconfidence(seed=1)
    >>> paper = out['variants']['paper']
    >>> bool(np.all(paper['actual'][-1] >= paper['believed'][-1]))   # the agents believe they know more
    True
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    s = settings
    check_seed(seed, "seed")
    res = fig1(seed, settings=s) if fig1_result is None else fig1_result
    xi0, P0 = fig1_initial(True, s)
    kinds = {"paper": dict(Q=s.Q, Omega=s.Omega, include_self=s.include_self),
             "ideal": dict(Q=0.0, Omega=s.ideal_Omega, include_self=False)}
    variants = {}
    for key, kw in kinds.items():
        actual, believed = cs.error_covariance(P0, res.pairings, **kw)
        variants[key] = dict(label=variant_label(**kw, paper=key == "paper"), actual=actual, believed=believed)
    return dict(variants=variants, fused_variance=float(cs.central_fusion(xi0, P0)[1]))


# --------------------------------------------------------------------------- the run


@dataclass(frozen=True)
class KalmanConsensusResult:
    """Everything the figures, tables and claims of ren2005 are computed from (one seed).

    Parameters
    ----------
    settings : KalmanConsensusSettings
        The settings of the run.
    seed : int
        The seed.
    fig1 : Fig1Result
        Fig. 1.
    union : SwitchingDemo
        Switching graphs whose unions have a spanning tree (Theorems 3.2, 3.9).
    no_union : SwitchingDemo
        Switching graphs whose unions do not.
    fixed : mascore.consensus.ConsensusResult
        The fixed Fig. 2 graph.
    noise : dict
        Discrete-time communication-noise study.
    noise_continuous : dict
        Continuous-time communication-noise study (:func:`noise_continuous`).
    bias : dict
        Bias of the consensus value against central fusion.
    overconfidence : dict
        Believed against actual variances (:func:`overconfidence`).
    noise_free_rms : ndarray
        RMS disagreement of the noise-free Fig. 1 run (equal variances) per step, the
        reference line of the noise figure.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> ren2005.KalmanConsensusResult.__dataclass_fields__.keys() >= {"fig1", "union", "bias"}
    True
    """

    settings: KalmanConsensusSettings
    seed: int
    fig1: Fig1Result
    union: SwitchingDemo  # Fig. 3(a)/3(b) alternating: the theorems' hypothesis holds
    no_union: SwitchingDemo  # no union has a spanning tree
    fixed: cs.ConsensusResult  # continuous time on the fixed Fig. 2 graph
    noise: dict  # "paper", "small_Omega", "Q0" -> noise_study
    noise_continuous: dict  # noise_continuous
    bias: dict  # "paper", "Q0", "ideal" -> bias_study
    overconfidence: dict  # overconfidence
    noise_free_rms: np.ndarray  # _rms_disagreement of fig1.equal


def _noise_variants(s: KalmanConsensusSettings) -> dict[str, dict]:
    return {"paper": dict(Q=s.Q, Omega=s.Omega), "small_Omega": dict(Q=s.Q, Omega=s.noise_Omega_small),
            "Q0": dict(Q=0.0, Omega=s.Omega)}


def _bias_variants(s: KalmanConsensusSettings) -> dict[str, dict]:
    return {"paper": dict(Q=s.Q, Omega=s.Omega, include_self=s.include_self),
            "Q0": dict(Q=0.0, Omega=s.Omega, include_self=s.include_self),
            "ideal": dict(Q=0.0, Omega=s.ideal_Omega, include_self=False)}


def run(settings: KalmanConsensusSettings = SETTINGS, seed: int = 1, progress: bool = False) -> KalmanConsensusResult:
    """Every run of the study, once: Fig. 1, the theorem demos, the noise, bias and overconfidence studies.

    Parameters
    ----------
    settings : KalmanConsensusSettings
        :data:`SETTINGS` or a copy changed with :func:`dataclasses.replace`.
    seed : int
        Seed of the pairing schedules and of the communication noise (each study
        starts its own generator from it).
    progress : bool
        Show a progress bar over the studies.

    Returns
    -------
    KalmanConsensusResult
        Every run the figures, tables and claims are computed from.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import ren2005
    >>> fewer = dataclasses.replace(ren2005.SETTINGS, noise_runs=20, noise_paths=4, bias_runs=50,
    ...                             switch_steps=100, t_final=20.0)  # fewer runs, shorter switching demos
    >>> result = ren2005.run(fewer, seed=1)
    >>> result.union.union_ok, result.no_union.union_ok      # whether every window's union has a spanning tree
    (True, False)
    """
    check_settings_type(settings, KalmanConsensusSettings, "settings")
    s = settings
    check_seed(seed, "seed")
    tasks = {
        "fig1": lambda: fig1(seed, settings=s),
        "union": lambda: switching_demo(union_sequence(), s),
        "no_union": lambda: switching_demo(no_union_sequence(), s),
        "fixed": lambda: fixed_graph_run(s),
        "noise": lambda: {k: noise_study(seed, settings=s, **kw) for k, kw in _noise_variants(s).items()},
        "noise_continuous": lambda: noise_continuous(seed, s),
        "bias": lambda: {k: bias_study(seed, settings=s, **kw) for k, kw in _bias_variants(s).items()},
    }
    out = {name: task() for name, task in progress_bar(list(tasks.items()), enabled=progress, desc="ren2005",
                                                       unit="study", leave=False)}
    return KalmanConsensusResult(settings=s, seed=seed, **out,
                                 overconfidence=overconfidence(seed, s, fig1_result=out["fig1"]),
                                 noise_free_rms=_rms_disagreement(out["fig1"].equal.xi))


# --------------------------------------------------------------------------- plots


def _check_agent(agent: object, name: str, n: int) -> int:
    """A 1-based agent number in 1..n."""
    agent = check_positive_int(agent, name)
    if agent > n:
        raise ValueError(f"{name} must be a 1-based agent number in 1..{n}; got {agent}")
    return agent


def plot_fig1(res: Fig1Result, axes=None, confident_agent: int = SETTINGS.confident_agent):
    """2 x 2 panels: states (top) and variances (bottom); equal (left) and confident (right).

    Parameters
    ----------
    res : Fig1Result
        The output of :func:`fig1`.
    axes : (2, 2) array of matplotlib Axes, optional
        Where to draw (default: a new figure).
    confident_agent : int
        The confident agent (1-based), highlighted.

    Returns
    -------
    (2, 2) ndarray of matplotlib.axes.Axes
        The panels.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore.papers import ren2005
    >>> axes = ren2005.plot_fig1(ren2005.fig1(seed=1))
    >>> axes.shape
    (2, 2)
    >>> plt.close("all")
    """
    import matplotlib.pyplot as plt

    from ..plotting import agent_colors
    _check_agent(confident_agent, "confident_agent", res.equal.xi.shape[-1])
    if axes is None:
        _, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True, layout="constrained")
    colors = agent_colors(res.equal.xi.shape[-1])
    columns = ((res.equal, "equal initial variances"),
               (res.confident, f"agent {confident_agent} starts with $P_{{{confident_agent}}}(0)=0.001$"))
    for col, (result, title) in enumerate(columns):
        for i, c in enumerate(colors):
            axes[0, col].plot(result.t, result.xi[:, i], color=c, lw=1.0)
            axes[1, col].semilogy(result.t, result.P[:, i], color=c, lw=1.0)
        axes[0, col].set_title(f"({'ab'[col]}) meeting times,\n{title}", fontsize="small")
        axes[1, col].set_title(f"({'cd'[col]}) variances,\n{title}", fontsize="small")
        axes[0, col].set_ylabel("meeting time $\\xi_i$ (h)")
        axes[1, col].set_ylabel("variance $P_i$ (h$^2$)")
        axes[1, col].set_xlabel("step k")
    axes[0, 1].axhline(res.fused_confident, color="k", ls=":", lw=1, label="central fusion")
    axes[0, 1].legend(loc="upper right")
    agents = axes[0, 0].get_lines()[:len(colors)]  # ten lines a panel: a key below the panels
    axes[0, 0].figure.legend(agents, [f"agent {i + 1}" for i in range(len(colors))], loc="outside lower center",
                             ncol=5, fontsize="small")
    return axes


def plot_average(res: Fig1Result, axes=None):
    """Ordinary average consensus (left) and Kalman consensus with the confident agent (right), same pairings."""
    import matplotlib.pyplot as plt

    from ..plotting import agent_colors
    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=(10, 3.2), sharey=True, layout="constrained")
    for ax, (result, title) in zip(axes, ((res.average, "(a) average consensus"),
                                          (res.confident, "(b) Kalman consensus, agent 7 confident"))):
        for i, c in enumerate(agent_colors(result.xi.shape[-1])):
            ax.plot(result.t, result.xi[:, i], color=c, lw=1, label=f"agent {i + 1}")
        ax.set_title(f"{title}: agrees on {format_number(float(result.final_value), 3)}")
        ax.set_xlabel("step k")
    axes[0].set_ylabel("meeting time $\\xi_i$ (h)")
    axes[0].figure.legend(*axes[0].get_legend_handles_labels(), loc="outside lower center", ncol=5, fontsize="small")
    return axes


def plot_directed(A, layout, ax=None, highlight=(), title=None):
    """Draw a small directed graph; `highlight` edges (j, i) are drawn bold (the paper's double arrows)."""
    from ..plotting import new_axes
    A = check_adjacency(A, "A")
    n = A.shape[0]
    layout = as_matrix(layout, "layout", shape=(n, 2))
    edges = float_array(highlight, "highlight")
    if edges.size and (edges.ndim != 2 or edges.shape[1] != 2 or not np.all(np.isfinite(edges))
                       or np.any(edges != np.round(edges)) or edges.min() < 0 or edges.max() >= n):
        raise ValueError(f"highlight must be a sequence of edges (j, i) with agent indices in 0..{n - 1}; "
                         f"got {highlight!r}")
    ax = new_axes(ax)
    hl = {(int(j), int(i)) for j, i in highlight}
    for i, j in zip(*np.nonzero(A)):
        bold = (int(j), int(i)) in hl
        two_way = A[j, i] > 0
        ax.annotate("", xy=layout[i], xytext=layout[j], arrowprops=dict(
            arrowstyle="-|>", color="C3" if bold else "0.45", lw=2.6 if bold else 1.0,
            shrinkA=11, shrinkB=11, connectionstyle="arc3,rad=0.15" if two_way else "arc3"))
    for i, p in enumerate(layout):
        ax.plot(*p, "o", ms=20, color="C0", zorder=3)
        ax.annotate(f"A{i + 1}", p, ha="center", va="center", color="white", fontsize=8, zorder=4)
    ax.set_xlim(layout[:, 0].min() - 0.4, layout[:, 0].max() + 0.4)
    ax.set_ylim(layout[:, 1].min() - 0.4, layout[:, 1].max() + 0.4)
    ax.set_aspect("equal")
    ax.axis("off")
    if title:
        ax.set_title(title)
    return ax


def plot_fig2_fig3(axes=None):
    """Fig. 2 (with one spanning tree in bold) and Fig. 3(a), 3(b) side by side."""
    import matplotlib.pyplot as plt
    if axes is None:
        _, axes = plt.subplots(1, 3, figsize=(9, 3.0), layout="constrained")
    roots = ", ".join(f"A{r + 1}" for r in spanning_tree_roots(fig2_graph()))
    plot_directed(fig2_graph(), FIG2_LAYOUT, axes[0], FIG2_TREE, f"Fig. 2: roots {roots}")
    plot_directed(fig3a_graph(), FIG3_LAYOUT, axes[1], title="Fig. 3(a): two leaders")
    plot_directed(fig3b_graph(), FIG3_LAYOUT, axes[2], title="Fig. 3(b): two isolated groups")
    return axes


def plot_switching(demo: SwitchingDemo, axes=None, label=""):
    """States of the discrete (left) and continuous (right) runs."""
    import matplotlib.pyplot as plt

    from ..plotting import agent_colors
    if axes is None:
        _, axes = plt.subplots(1, 2, figsize=(10, 3.4), layout="constrained")
    colors = agent_colors(demo.discrete.xi.shape[-1])
    for i, c in enumerate(colors):
        axes[0].plot(demo.discrete.t, demo.discrete.xi[:, i], color=c, label=f"A{i + 1}")
        axes[1].plot(demo.continuous.t, demo.continuous.xi[:, i], color=c)
    axes[0].set_xlabel("step k")
    axes[1].set_xlabel("time t (s)")
    for ax, kind in zip(axes, ("discrete, eqs. (4)-(5)", "continuous, eqs. (1)-(3)")):
        ax.set_ylabel("$\\xi_i$")
        ax.set_title(f"{label}: {kind}" if label else kind)
    return axes


def plot_overconfidence(study: dict, axes=None, confident_agent: int = SETTINGS.confident_agent):
    """Believed (dashed) and actual (solid) variance of the confident agent and of agent 1, per variant."""
    import matplotlib.pyplot as plt
    variants = list(study["variants"].values())
    _check_agent(confident_agent, "confident_agent", np.shape(variants[0]["actual"])[-1])
    if axes is None:
        _, axes = plt.subplots(1, len(variants), figsize=(10, 3.4), sharey=True, layout="constrained")
    for n, (ax, v) in enumerate(zip(axes, variants)):
        for i, c in ((confident_agent - 1, "C3"), (0, "C0")):
            ax.semilogy(v["actual"][:, i], color=c, label=f"A{i + 1} actual")
            ax.semilogy(v["believed"][:, i], color=c, ls="--", label=f"A{i + 1} believed $P_i$")
        ax.axhline(study["fused_variance"], color="k", ls=":", label="central fusion")
        ax.set_title(f"({'abcd'[n]}) {v['label']}")
        ax.set_xlabel("step k")
    axes[0].set_ylabel("error variance (h$^2$)")
    axes[0].legend(loc="lower left")
    return axes


def plot_bias(studies: dict, ax=None):
    """Histograms of the agreed values of several variants, with the central fusion and the plain average."""
    from ..plotting import new_axes
    ax = new_axes(ax)
    for st in studies.values():
        ax.hist(st["values"], bins=40, alpha=0.5,
                label=variant_label(st["Q"], st["Omega"], st["include_self"], paper=st is studies.get("paper")))
    first = next(iter(studies.values()))
    ax.axvline(first["fused"], color="k", ls=":", label="central fusion")
    ax.axvline(first["average"], color="0.5", ls="--", label="plain average")
    ax.set_xlabel("agreed meeting time (h)")
    ax.set_ylabel(f"schedules (of {first['values'].size})")
    return ax


def _draw_fig1(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 2, figsize=(10, 6), sharex=True, layout="constrained")
    plot_fig1(result.fig1, axes, result.settings.confident_agent)
    return fig


def _draw_average(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2), sharey=True, layout="constrained")
    plot_average(result.fig1, axes)
    return fig


def _draw_fig2_fig3(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(9, 3.0), layout="constrained")
    plot_fig2_fig3(axes)
    return fig


def _draw_theorems(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 2, figsize=(10, 6.5), sharey=True, layout="constrained")
    plot_switching(result.union, axes[0], "Fig. 3(a)/3(b) alternating")
    plot_switching(result.no_union, axes[1], "no union has a spanning tree")
    fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="outside right center", title="agent")
    return fig


def _draw_noise(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 3.6), layout="constrained")
    for key, st in result.noise.items():
        ax.semilogy(st["rms"], label=variant_label(st["Q"], st["Omega"], paper=key == "paper"))
    ax.semilogy(result.noise_free_rms, "k:", label="no noise (the Fig. 1 run)")
    ax.set_xlabel("step k")
    ax.set_ylabel("RMS disagreement (h)")
    fig.legend(loc="outside right upper")
    return fig


def _draw_noise_continuous(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt

    from ..plotting import agent_colors
    nc = result.noise_continuous
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.2), layout="constrained")
    for i, c in enumerate(agent_colors(nc["path"].shape[-1])):
        axes[0].plot(nc["t"], nc["path"][:, i], color=c, lw=0.8)
    axes[0].set_title("(a) one noisy path, six agents")
    axes[0].set_ylabel("$\\xi_i$")
    axes[1].semilogy(nc["t"], nc["rms"], label=f"with noise, mean of {result.settings.noise_paths} paths")
    axes[1].semilogy(nc["t"], nc["rms_quiet"], "k:", label="no communication noise")
    axes[1].set_title("(b) RMS disagreement")
    axes[1].set_ylabel("RMS disagreement")
    fig.legend(*axes[1].get_legend_handles_labels(), loc="outside lower center", ncol=2)  # below, off the data
    for ax in axes:
        ax.set_xlabel("time t (s)")
    return fig


def _draw_bias(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(8, 3.6), layout="constrained")
    plot_bias(result.bias, ax)
    fig.legend(loc="outside right upper")
    return fig


def _draw_overconfidence(result: KalmanConsensusResult) -> plt.Figure:
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.4), sharey=True, layout="constrained")
    plot_overconfidence(result.overconfidence, axes, result.settings.confident_agent)
    return fig


# --------------------------------------------------------------------------- tables


def _fig1_table(result: KalmanConsensusResult) -> pd.DataFrame:
    res = result.fig1
    return pd.DataFrame({"agent": np.arange(1, res.equal.xi.shape[-1] + 1), "xi0": result.settings.fig1_xi0,
                         "final_equal": res.equal.xi[-1], "final_confident": res.confident.xi[-1],
                         "final_average_consensus": res.average.xi[-1],
                         "P_final_equal": res.equal.P[-1], "P_final_confident": res.confident.P[-1]})


def _theorems_table(result: KalmanConsensusResult) -> pd.DataFrame:
    return pd.DataFrame([{"sequence": name, "union_condition": demo.union_ok,
                          "discrete_final_spread": demo.discrete.spread[-1],
                          "continuous_final_spread": demo.continuous.spread[-1]}
                         for name, demo in (("union_sequence", result.union),
                                            ("no_union_sequence", result.no_union))])


def _noise_table(result: KalmanConsensusResult) -> pd.DataFrame:
    return pd.DataFrame([{"variant": variant_label(st["Q"], st["Omega"], paper=key == "paper"),
                          "RMS floor, last quarter (h)": st["floor"],
                          "RMS floor, third quarter (h)": st["floor_q3"],
                          "log-log slope, second half": st["slope"]} for key, st in result.noise.items()])


def _bias_table(result: KalmanConsensusResult) -> pd.DataFrame:
    return pd.DataFrame([{"variant": variant_label(v["Q"], v["Omega"], v["include_self"], paper=k == "paper"),
                          "mean agreed value (h)": v["values"].mean(), "std over schedules (h)": v["std"],
                          "central fusion (h)": v["fused"], "bias (h)": v["bias"], "standard error (h)": v["se"],
                          "share above the plain average": float((v["values"] > v["average"]).mean()),
                          "largest final spread (h)": v["max_spread"]} for k, v in result.bias.items()])


def _overconfidence_table(result: KalmanConsensusResult) -> pd.DataFrame:
    oc = result.overconfidence
    k = result.settings.n_steps
    return pd.DataFrame([{"variant": v["label"], f"believed P_i at k = {k} (h²)": v["believed"][-1].mean(),
                          f"actual variance at k = {k} (h²)": v["actual"][-1].mean(),
                          "actual / believed": (v["actual"][-1] / v["believed"][-1]).mean(),
                          "central fusion variance (h²)": oc["fused_variance"]}
                         for v in oc["variants"].values()])


# --------------------------------------------------------------------------- claims


def _spread_ratio(run_: cs.ConsensusResult, reference: float) -> float:
    return float(run_.spread[-1]) / reference


def _fig1_choices(s: KalmanConsensusSettings) -> str:
    """The shared note paragraph of the Fig. 1 claims: what the paper leaves out."""
    return (f"Our choices (the paper does not give them): initial times {format_number(s.xi0[0])}, ..., "
            f"{format_number(s.xi0[-1])}; P_i(0) = {format_number(s.P_equal)}; calls of 1 to {s.max_call} steps; "
            f"{s.n_steps} steps; noise-free messages (Ω = {format_number(s.Omega)} only in the weights).")


def _switching_choices(s: KalmanConsensusSettings) -> str:
    """The shared note paragraph of the theorem claims."""
    return (f"Switching demos (our choices; the paper simulates none): six agents start at "
            f"{format_number(s.switch_xi0[0])}, ..., {format_number(s.switch_xi0[-1])} with P_i(0) = "
            f"{format_number(s.switch_P0)}; Fig. 3(a) and 3(b) alternate every {s.dwell_steps} steps for "
            f"{s.switch_steps} steps (discrete) or every {format_number(s.dwell_time)} s for "
            f"{format_number(s.t_final)} s (continuous, scipy RK45 with rtol 10⁻⁸, restarted at each switch). "
            "The spread is max - min over the agents, its ratio final / initial; decay rates are least-squares "
            "slopes of log(spread) over the second half of the run.")


_BEYOND = ("Beyond the paper, on Fig. 1's right-column data (agent 7 starts at 7 with P = 0.001), noise-free. "
           "Sec. II-A takes the agents' estimation errors as uncorrelated, so R_i is block diagonal: "
           "information already shared is counted again, which pairs met first changes the outcome, and the "
           "P_i shrink faster than the information they hold.")


def _fig1_claims(result: KalmanConsensusResult) -> list[Claim]:
    s, res = result.settings, result.fig1
    spread0, spread_end = float(res.equal.spread[0]), float(res.equal.spread[-1])
    equal = Claim.qualitative(
        "ren2005/fig1-consensus-equal", "Sec. II-C, Fig. 1 (left)",
        "With equal initial variances and random one-to-one pairings, the ten meeting times reach consensus.",
        {"initial_spread": spread0, "final_spread": spread_end, "agreed_value": float(res.equal.final_value)},
        spread_end < 1e-3 * spread0,
        "With equal variances every pair averages symmetrically, so the agreed value is the plain average "
        f"{format_number(float(s.fig1_xi0.mean()))}.\n\n" + _fig1_choices(s),
        rule="final spread < 10⁻³ × initial spread (spread = max - min over the agents)", unit="h")
    target = s.xi0[s.confident_agent - 1]
    d_eq = abs(float(res.equal.final_value) - target)
    d_conf = abs(float(res.confident.final_value) - target)
    values = result.bias["paper"]["values"]
    share = float(np.mean(np.abs(values - target) < d_eq))
    confident = Claim.qualitative(
        "ren2005/fig1-confident-agent-dominates", "Sec. II-C, Fig. 1 (right)",
        "When the agent starting at 7 has P = 0.001, the consensus value is pulled towards 7.",
        {"distance to 7, equal P (h)": d_eq, "distance to 7, agent 7 confident (h)": d_conf,
         "agreed value, agent 7 confident (h)": float(res.confident.final_value),
         "central fusion (h)": res.fused_confident, "share of schedules closer to 7": share},
        d_conf < d_eq and share > 0.5,
        f"On this seed the agreed value is {format_number(d_conf)} h from 7, against {format_number(d_eq)} h "
        f"with equal variances; over the {values.size} pairing schedules of the bias study, "
        f"{format_number(100 * share, 3)} % of the agreed values are closer to 7 than {format_number(d_eq)} h. "
        "The pull is modest: Q erodes agent 7's advantage at its first step (P + Q = "
        f"{format_number(s.P_confident + s.Q)}), so the agreed value stays far from the central fusion value "
        "(see the claim on the bias of the agreed value); on some schedules it lands below the plain average.\n\n"
        + _fig1_choices(s),
        rule="distance to 7 (agent 7 confident) < distance to 7 (equal P), and share of schedules closer "
             "to 7 > 0.5")
    return [equal, confident]


def _graph_claim() -> Claim:
    A2, A3a, A3b = fig2_graph(), fig3a_graph(), fig3b_graph()
    roots = [int(r) + 1 for r in spanning_tree_roots(A2)]
    return Claim.qualitative(
        "ren2005/fig2-fig3-graphs", "Sec. III-A, Figs. 2-3",
        "Fig. 2 has spanning trees rooted at A1, A4 and A5 but is not strongly connected; "
        "Figs. 3(a) and 3(b) have no spanning tree.",
        {"Fig. 2 roots": ", ".join(f"A{r}" for r in roots), "Fig. 2 strongly connected": len(roots) == 6,
         "Fig. 3(a) has a spanning tree": has_spanning_tree(A3a),
         "Fig. 3(b) has a spanning tree": has_spanning_tree(A3b), "Fig. 3(b) connected": is_connected(A3b),
         "union of Figs. 3(a), 3(b) has a spanning tree": has_spanning_tree(A3a + A3b)},
        roots == [1, 4, 5] and not has_spanning_tree(A3a) and not has_spanning_tree(A3b),
        "The paper's drawings are not reproduced here; we drew graphs that satisfy its captions and "
        "checked them: Fig. 2, the cycle A1 → A4 → A5 → A1 feeding A2, A3 and A6 with nothing flowing back; "
        "Fig. 3(a), the chains A1 → A2 → A3 and A4 → A5 → A6 with the bridge A3 → A6; Fig. 3(b), two-way "
        "chains A1 - A2 - A3 and A4 - A5 - A6.",
        rule="Fig. 2 roots = A1, A4, A5, and neither Fig. 3(a) nor Fig. 3(b) has a spanning tree")


def _theorem_claims(result: KalmanConsensusResult) -> list[Claim]:
    s, good, bad = result.settings, result.union, result.no_union
    s0 = float(good.continuous.spread[0])
    alone = [has_spanning_tree(g) for g in good.graphs]
    r_cont, r_fixed = _spread_ratio(good.continuous, s0), _spread_ratio(result.fixed, s0)
    rate_cont = decay_rate(good.continuous.t, good.continuous.spread)
    shared = _switching_choices(s)
    thm32 = Claim.qualitative(
        "ren2005/thm32-continuous-consensus", "Sec. III-B, Theorem 3.2",
        "Continuous-time Kalman consensus (eqs. (1)-(3)) reaches consensus when the union of the graphs over "
        "bounded intervals has a spanning tree, even if no single graph has one.",
        {"Fig. 3(a) has a spanning tree": alone[0], "Fig. 3(b) has a spanning tree": alone[1],
         "union condition": good.union_ok, "decay rate (1/s)": rate_cont,
         f"spread ratio at {format_number(s.t_final)} s, switching": r_cont,
         f"spread ratio at {format_number(s.t_final)} s, fixed Fig. 2": r_fixed},
        good.union_ok and not any(alone) and r_cont < 1e-2 and rate_cont < 0 and r_fixed < 1e-3,
        "Also the fixed Fig. 2 graph, which has a spanning tree. The switching case is slow: information from "
        "the root group A1, A2, A3 crosses to the other group only over the single edge A3 → A6, present half "
        "of the time.\n\n" + shared,
        rule="union condition holds and no single graph has a spanning tree; decay rate < 0; spread ratio "
             "< 10⁻² (switching) and < 10⁻³ (fixed Fig. 2)")
    res = result.fig1
    r_disc = _spread_ratio(good.discrete, s0)
    rate_disc = decay_rate(good.discrete.t, good.discrete.spread)
    windows = cs.spanning_tree_windows(res.pairings, 10)
    r_fig1 = _spread_ratio(res.equal, float(res.equal.spread[0]))
    thm39 = Claim.qualitative(
        "ren2005/thm39-switching-union-consensus", "Sec. III-C, Theorem 3.9",
        "Discrete-time Kalman consensus (eqs. (4)-(5)) reaches consensus under switching topologies whose "
        "unions over bounded windows have spanning trees.",
        {"union condition": good.union_ok, "decay rate (1/step)": rate_disc,
         f"spread ratio at step {s.switch_steps}": r_disc,
         "Fig. 1: single pairing has a spanning tree": has_spanning_tree(res.pairings[0]),
         "Fig. 1: share of 10-step windows with a spanning tree": float(windows.mean()),
         "Fig. 1: spread ratio": r_fig1},
        good.union_ok and r_disc < 1e-5 and rate_disc < 0 and r_fig1 < 1e-3,
        "The Fig. 1 pairings are a second example: a single pairing never has a spanning tree (it is five "
        "disjoint edges), but the union over a window of 10 steps usually has one.\n\n" + shared,
        rule="union condition holds; decay rate < 0; spread ratio < 10⁻⁵ (Fig. 3 sequence) and < 10⁻³ "
             "(Fig. 1 pairings, equal variances)")
    whole_union = has_spanning_tree(bad.sequence.sum(axis=0))
    rb_d, rb_c = _spread_ratio(bad.discrete, s0), _spread_ratio(bad.continuous, s0)
    converse = Claim.qualitative(
        "ren2005/no-spanning-tree-no-consensus", "Sec. III, Fig. 3 and Theorems 3.2/3.9 (converse direction)",
        "If no union of the switching graphs has a spanning tree (two isolated groups), consensus is not reached.",
        {"union of the whole sequence has a spanning tree": whole_union,
         "spread ratio, discrete": rb_d, "spread ratio, continuous": rb_c},
        (not whole_union) and rb_d > 0.1 and rb_c > 0.1,
        "Not a theorem of the paper (its condition is sufficient); we check the example, Fig. 3(b) alternating "
        "with Fig. 3(a) stripped of its bridge A3 → A6: each group agrees internally, the two groups keep "
        "different values.\n\n" + shared,
        rule="no union has a spanning tree, and spread ratio > 0.1 in both time bases",
        own_check="the converse of the paper's sufficient condition, on its own example")
    return [thm32, thm39, converse]


def _noise_claim(result: KalmanConsensusResult) -> Claim:
    s = result.settings
    noisy, quiet, q0 = (result.noise[k] for k in ("paper", "small_Omega", "Q0"))
    big, small = format_number(s.Omega), format_number(s.noise_Omega_small)
    stationary = abs(noisy["slope"]) < 0.1 and abs(quiet["slope"]) < 0.1
    return Claim.qualitative(
        "ren2005/noise-consensus-approximate", "Sec. II (eqs. (3), (5) with ν_ij), Fig. 1 settings",
        "With Q > 0 and communication noise, Kalman consensus is only approximate: the disagreement settles "
        "at a non-zero floor instead of vanishing.",
        {f"RMS floor, Ω = {big} (h)": noisy["floor"], f"RMS floor, Ω = {small} (h)": quiet["floor"],
         f"log-log slope, Ω = {big}": noisy["slope"], f"log-log slope, Ω = {small}": quiet["slope"],
         "log-log slope, Q = 0": q0["slope"]},
        noisy["floor"] > 1e-2 and stationary and quiet["floor"] < noisy["floor"] and q0["slope"] < -0.3,
        "We measured, the paper does not say: the RMS deviation of the agents from the team mean, averaged "
        f"over {s.noise_runs} pairing schedules (Fig. 1 setting, equal variances) and over the last quarter of "
        f"{s.noise_steps} steps (the floor); the slope is that of log RMS against log k over the second half. "
        "With Q > 0 the covariances stay bounded away from 0, so the gains never vanish and fresh noise enters "
        "every step: a stationary floor that shrinks with Ω. With Q = 0 (outside the paper's assumption Q > 0) "
        "the gains decay like 1/k and the disagreement keeps shrinking like 1/√k: consensus is then reached "
        "in mean square, slowly.",
        rule=f"floor (Ω = {big}) > 10⁻² h and > floor (Ω = {small}); "
             "abs(slope) < 0.1 for both Ω; slope (Q = 0) < -0.3",
        own_check="measured on the paper's equations; the paper does not say what noise does to consensus")


def _beyond_claims(result: KalmanConsensusResult) -> list[Claim]:
    s = result.settings
    study = result.bias["paper"]
    ideal_name = variant_label(0.0, s.ideal_Omega, include_self=False)
    bias = Claim.qualitative(
        "ren2005/beyond-fusion-bias", "beyond the paper (Fig. 1 right column data)",
        "The Kalman-consensus value is a biased estimate of the central inverse-variance fusion of the "
        "initial data under random pairings.",
        {"central fusion": study["fused"], "mean agreed value": float(study["values"].mean()),
         "bias": study["bias"], "standard error": study["se"], "bias, Q = 0": result.bias["Q0"]["bias"],
         f"bias, {ideal_name}": result.bias["ideal"]["bias"]},
        abs(study["bias"]) > 5 * study["se"],
        f"{study['values'].size} pairing schedules (standard deviation {format_number(study['std'])} h over "
        "them). The bias shrinks when Q = 0 and nearly vanishes when also Ω → 0 and the self term is dropped; "
        "a schedule-dependent scatter remains. With Q = 0 the run has not finished agreeing after "
        f"{s.n_steps} steps (the largest final spread in the table of the variants of the scheme).\n\n" + _BEYOND,
        rule="abs(bias) > 5 standard errors", unit="h", own_check="a result beyond the paper, on its Fig. 1 data")
    oc = result.overconfidence
    ratio = {k: float(np.mean(v["actual"][-1] / v["believed"][-1])) for k, v in oc["variants"].items()}
    paper_v, ideal_v = oc["variants"]["paper"], oc["variants"]["ideal"]
    overconfident = Claim.qualitative(
        "ren2005/beyond-overconfidence",
        "beyond the paper (Sec. II-A assumption E[(ξ_i − ξ∗)(ξ_j − ξ∗)ᵀ] = 0)",
        "Because R_i is taken block diagonal, information already shared is counted again: after a few calls "
        "the agents' P_i understate the actual variance of their errors.",
        {"believed P, paper (h²)": float(paper_v["believed"][-1].mean()),
         "actual variance, paper (h²)": float(paper_v["actual"][-1].mean()),
         "actual / believed, paper": ratio["paper"],
         "believed P, ideal variant (h²)": float(ideal_v["believed"][-1].mean()),
         "actual variance, ideal variant (h²)": float(ideal_v["actual"][-1].mean()),
         "actual / believed, ideal variant": ratio["ideal"]},
        ratio["paper"] > 1.2 and ratio["ideal"] > 100,
        f"Values at step {s.n_steps}, averaged over the agents, on the Fig. 1 pairings (same seed); the ideal "
        f"variant is {ideal_name}. The true meeting time is fixed and the initial errors independent with "
        "variances P_i(0); the actual variance is the diagonal of Φ[k] diag(P(0)) Φ[k]ᵀ, with Φ[k] the product "
        "of the D[k] of eq. (8). In the ideal variant the agreed value is nearly the fused one, but P_i keeps "
        "shrinking far below the central-fusion variance "
        f"{format_number(oc['fused_variance'])} h², which no estimate from these data can beat.\n\n" + _BEYOND,
        rule="actual / believed > 1.2 (paper) and > 100 (ideal variant)",
        own_check="a result beyond the paper: how its covariances compare with the actual errors")
    return [bias, overconfident]


def claims(result: KalmanConsensusResult) -> list[Claim]:
    """The nine ledger claims of ren2005, from one :func:`run` (all qualitative: the paper prints no numbers).

    Parameters
    ----------
    result : KalmanConsensusResult
        The output of :func:`run`.

    Returns
    -------
    list of mascore.ledger.Claim
        Each with its rule and computed verdict.

    Examples
    --------
    >>> import dataclasses
    >>> from mascore.papers import ren2005
    >>> fewer = dataclasses.replace(ren2005.SETTINGS, noise_runs=20, noise_paths=4, bias_runs=50)  # fewer runs
    >>> claims = ren2005.claims(ren2005.run(fewer, seed=1))
    >>> len(claims), sorted({c.verdict for c in claims})
    (9, ['holds'])
    """
    return [*_fig1_claims(result), _graph_claim(), *_theorem_claims(result), _noise_claim(result),
            *_beyond_claims(result)]


def prose_values(result: KalmanConsensusResult) -> dict[str, float]:
    """The numbers the chapter's prose quotes, computed from one :func:`run` (glued by the book).

    Parameters
    ----------
    result : KalmanConsensusResult
        The output of :func:`run`.

    Returns
    -------
    dict
        Name -> value (hours, h², shares): the Fig. 1 values (``average``, ``agreed_equal``,
        ``agreed_confident``, ``fused``, ``first_P`` agent 7's variance after its first time update,
        ``settled``), the noise study (``floor_paper``, ``floor_small``, ``slope_paper``, ``slope_q0``,
        ``floor_continuous``), the bias study (``bias``, ``mean_paper``, ``se_paper``, ``std_paper``,
        ``above_average`` and ``below_average`` shares, ``bias_ideal``), the overconfidence study
        (``believed``, ``actual``, ``overconfidence`` = actual / believed, ``times_fused``,
        ``fused_variance``, ``ideal_actual``, ``ideal_believed``, ``ideal_below_fused`` = fused_variance /
        ideal_believed), the theorem runs' final spreads
        (``spread_union_continuous``) and the confidence ratio ``p_ratio`` = P_equal / P_confident.

    Examples
    --------
    >>> from mascore.papers import ren2005
    >>> values = ren2005.prose_values(ren2005.run(seed=1))  # doctest: +SKIP
    >>> round(values["fused"], 3)  # doctest: +SKIP
    6.985
    """
    s, res = result.settings, result.fig1
    paper, ideal = result.bias["paper"], result.bias["ideal"]
    oc = result.overconfidence
    oc_paper, oc_ideal = list(oc["variants"].values())
    noise = result.noise
    out = {
        "average": float(res.equal.xi[0].mean()), "agreed_equal": float(res.equal.final_value),
        "agreed_confident": float(res.confident.final_value), "fused": res.fused_confident,
        "first_P": s.P_confident + s.Q, "settled": float(np.median(res.equal.P[-1])),
        "floor_paper": noise["paper"]["floor"], "floor_small": noise["small_Omega"]["floor"],
        "slope_paper": noise["paper"]["slope"], "slope_q0": noise["Q0"]["slope"],
        "floor_continuous": result.noise_continuous["floor"],
        "bias": paper["bias"], "mean_paper": float(paper["values"].mean()), "se_paper": paper["se"],
        "std_paper": paper["std"], "above_average": float((paper["values"] > paper["average"]).mean()),
        "bias_ideal": ideal["bias"],
        "believed": float(oc_paper["believed"][-1].mean()), "actual": float(oc_paper["actual"][-1].mean()),
        "fused_variance": oc["fused_variance"], "ideal_actual": float(oc_ideal["actual"][-1].mean()),
        "ideal_believed": float(oc_ideal["believed"][-1].mean()),
        "spread_union_continuous": float(result.union.continuous.spread[-1]),
        "p_ratio": s.P_equal / s.P_confident,
    }
    out["ideal_below_fused"] = out["fused_variance"] / out["ideal_believed"]
    out["below_average"] = 1 - out["above_average"]
    out["bias_below"] = -out["bias"]
    out.update(max_call=s.max_call, Q=s.Q, Omega=s.Omega, noise_runs=s.noise_runs, noise_paths=s.noise_paths,
               noise_dt=s.noise_dt, bias_runs=s.bias_runs, n_steps=s.n_steps, noise_steps=s.noise_steps,
               Omega_small=s.noise_Omega_small, ideal_Omega=s.ideal_Omega, dwell_steps=s.dwell_steps,
               dwell_time=s.dwell_time)
    out["overconfidence"] = out["actual"] / out["believed"]
    out["times_fused"] = out["actual"] / out["fused_variance"]
    return {k: float(v) for k, v in out.items()}


# --------------------------------------------------------------------------- registry


FIGURES = (
    FigureSpec(
        "fig1", "Fig. 1",
        "The meet-for-dinner example: ten agents, paired at random for calls of random length (1 to "
        "{{max_call:.0f}} steps), run eqs. (4)-(5) with $Q=\\Omega$ (here {{Q:g}} h²). Top: meeting times $\\xi_i$; bottom: variances $P_i$, log scale. (a), (c): equal "
        "initial variances $P_i(0)=1$; (b), (d): agent 7, which starts at 7, has $P_7(0)=0.001$. Look for: "
        "both teams agree, in (a) on the plain average (here {{average:.3g}}), in (b) only a little higher and "
        "far below the central-fusion value (dotted, {{fused:.4g}}); within a few calls every variance settles "
        "at the same value (here {{settled:.2g}} h²; the curves coincide), agent 7's included, which is why its "
        "advantage fades.",
        _draw_fig1, values=prose_values),
    FigureSpec(
        "average", "",
        "Ordinary average consensus on the pairing schedule of Fig. 1: (a) every call replaces both values by "
        "their mean, whatever the agents' confidence, and the team agrees on the plain average (here "
        "{{average:.3g}}); (b) Kalman consensus with agent 7 confident (Fig. 1 (b) again) weights the calls by the variances and "
        "ends a little higher.",
        _draw_average, values=prose_values),
    FigureSpec(
        "fig2_fig3", "Figs. 2-3",
        "The six-agent graphs of Figs. 2-3, drawn to satisfy the paper's captions (the paper's own drawings are "
        "not reproduced here); arrows point the way information flows. Left, Fig. 2: spanning trees can be rooted at "
        "A1, A4 or A5 (bold: the one rooted at A5), yet the graph is not strongly connected, since nothing "
        "flows back into the cycle A1 → A4 → A5. Middle, Fig. 3(a): two leaders, A1 and A4, hear nobody. "
        "Right, Fig. 3(b): two isolated groups. Look for: neither Fig. 3 graph has a spanning tree, but their "
        "union does, through the edge A3 → A6.",
        _draw_fig2_fig3),
    FigureSpec(
        "theorems", "Theorems 3.2 and 3.9 (our check)",
        "Theorems 3.9 (left, discrete time, eqs. (4)-(5)) and 3.2 (right, continuous time, eqs. (1)-(3)) on "
        "switching graphs; six agents start at $\\xi_i(0)=i$ with $P_i(0)=1$. Top: Fig. 3(a) and 3(b) "
        "alternate, every 2 steps or every 1 s; no single graph has a spanning tree but their union does, and "
        "all six agents agree, slowly, on a value near the root group's. Bottom: Fig. 3(b) alternates with "
        "Fig. 3(a) stripped of its bridge A3 → A6, so no union has a spanning tree: each group agrees "
        "internally (its curves merge), the two groups never do.",
        _draw_theorems),
    FigureSpec(
        "noise", "",
        "Communication noise $\\nu_{ij}\\sim\\mathcal N(0,\\Omega)$ on every message, Fig. 1 setting with equal "
        "variances: RMS deviation of the ten agents from their mean, averaged over random pairing schedules "
        "(here {{noise_runs:.0f}}), log scale. Look for: with $Q>0$ the disagreement stops decaying at a floor, lower for the smaller "
        "$\\Omega$; with $Q=0$ it keeps falling, like $1/\\sqrt k$; without noise (dotted, the Fig. 1 run) it "
        "vanishes.",
        _draw_noise, values=prose_values),
    FigureSpec(
        "noise_continuous", "",
        "Continuous-time Kalman consensus, eqs. (1)-(3), with communication noise of intensity $\\Omega$ (here "
        "{{Omega:g}} h²; Euler-Maruyama, step {{noise_dt:g}} s) on the fixed Fig. 2 graph. (a) One noisy path of "
        "the six agents; (b) the RMS disagreement, mean over many paths (here {{noise_paths:.0f}}, solid), and "
        "without noise (dotted). Look for: the agents stay "
        "close but never agree exactly, while the noise-free disagreement shrinks exponentially.",
        _draw_noise_continuous, values=prose_values),
    FigureSpec(
        "bias", "",
        "Agreed value over random pairing schedules (here {{bias_runs:.0f}}), on Fig. 1's right-column data (agent 7 starts at 7 "
        "with $P_7(0)=0.001$), noise-free, for the paper's scheme and two variants. Dotted: the central "
        "inverse-variance fusion of the initial data ({{fused:.4g}}); dashed: the plain average ({{average:.3g}}). "
        "Look for: the "
        "paper's scheme lands far below the fused value, often near the plain average; dropping $Q$ helps a "
        "little; dropping also $\\Omega$ and the self term puts almost every run on the fused value (the "
        "narrow spike on the dotted line).",
        _draw_bias, values=prose_values),
    FigureSpec(
        "overconfidence", "",
        "Believed ($P_i$, dashed) and actual (solid) error variance of agent 7 (red) and agent 1 (blue) on the "
        "Fig. 1 pairings with agent 7 confident, noise-free; dotted: the central-fusion variance, below which "
        "no estimate from the initial data can go. (a) The paper's settings: the agents' believed variance "
        "settles below their actual one (here {{believed:.2g}} h² against {{actual:.2g}} h²). (b) $Q=0$, a tiny "
        "$\\Omega$, no self term: the actual variances come down to the fused one (the solid lines end on the "
        "dotted line), but the believed $P_i$ fall through it (here {{ideal_below_fused:,.0f}} times below it).",
        _draw_overconfidence, values=prose_values),
)

TABLES = (
    TableSpec("fig1_final", "", "Fig. 1: initial and final meeting times and variances per agent.", _fig1_table),
    TableSpec("theorem_spreads", "", "Theorem demos: whether the union condition holds and the final spread of the agents' values, per sequence.", _theorems_table),
    TableSpec("noise_floors", "", "Communication noise: RMS floors and log-log slopes per variant.", _noise_table),
    TableSpec("bias_by_variant", "", "Agreed value against central fusion, per variant of the scheme.", _bias_table),
    TableSpec("overconfidence_variances", "", "Believed and actual error variances at the last step.",
              _overconfidence_table),
)

#: The one study of the chapter ``ren2005_kalman_consensus``.
STUDY = Study("kalman-consensus", "ren2005_kalman_consensus", SETTINGS, run, FIGURES, TABLES, claims)

#: Errata and readings, for the reproduction report.
ERRATA = (
    "**Figs. 2-3** are not reproduced here; we drew graphs that satisfy the paper's captions (Fig. 2: "
    "spanning trees rooted at A1, A4 and A5, not strongly connected; Fig. 3: two graphs without a spanning "
    "tree whose union has one).",
    "**Fig. 1** gives $n=10$, $Q=\\Omega=0.1$ and $P=0.001$ for the agent starting at 7, and leaves out the "
    "other initial values and variances, the call lengths and the horizon. We read \"uniformly assigned\" as "
    "times $1,\\dots,10$ with $P_i(0)=1$, and $\\Omega$ as entering the weights only (noise-free messages), "
    "since the figure shows exact agreement.",
    "**The self term** $g_{ii}=1$ in eqs. (1) and (4) counts an agent's own prior a second time, as a "
    "measurement whose error is the prior error itself: the independence assumption at its most literal. It "
    "keeps $P_i$ bounded for an agent that hears nobody and the proof of Theorem 3.2 relies on it, so we keep it.",
    "**Continuous-time noise**: eqs. (1)-(3) add $\\Omega_{ij}$ to the covariance $P_j$, as the discrete "
    "eqs. (4)-(5) do, but in continuous time white noise has an intensity, not a covariance, and the two have "
    "different units. We keep the paper's form and read $\\nu_{ij}$ as white noise of intensity $\\Omega_{ij}$.",
    "**The independence assumption** (block-diagonal $R_i$, Sec. II-A) is not harmless: on Fig. 1's data the "
    "agreed value lands well below the central fusion of the initial data (the chapter's bias figure measures "
    "the gap), and the agents' $P_i$ understate their actual error variances (beyond the paper).",
)

#: The paper's registry: one study, its figures, tables and claims.
REGISTRY = PaperRegistry("ren2005", "Ren, Beard and Kingston 2005", studies=(STUDY,), errata=ERRATA, position=2)
