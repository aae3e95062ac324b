"""The shared task (Ren et al.): fusing priors of one common quantity."""

from __future__ import annotations

import time

import numpy as np

from .. import consensus
from ..estimation import method_spec
from .benchmark import (
    REN_Q,
    SETTINGS,
    SHARED_METHODS,
    BenchmarkSettings,
    benchmark_graph,
    check_run,
    draw_noise,
    switching_graphs,
)

# --------------------------------------------------------------------------------------------
# the shared task


def simulate_shared(
    method: str,
    n_agents: int,
    seed: np.random.SeedSequence | int,
    *,
    noise: str = "gaussian",
    dropout: float = 0.0,
    runs: int | None = None,
    settings: BenchmarkSettings = SETTINGS,
    graph: str = "ring",
) -> dict[str, np.ndarray]:
    """Fuse the agents' priors of one common 2-D quantity over a graph (Ren et al.'s task).

    Parameters
    ----------
    method : str
        One of :data:`SHARED_METHODS`.
    n_agents : int
        Team size N (a ring, N >= 3).
    seed : numpy.random.SeedSequence or int
        Source of the priors and drop-outs (the same for every method).
    noise : {"gaussian", "uniform", "student-t"}
        Distribution of the prior errors (covariance ``p_i I``).
    dropout : float
        Probability that a link's message is lost at a step.
    runs : int, optional
        Monte Carlo runs (default ``settings.runs``).
    settings : BenchmarkSettings
        The benchmark's settings (``shared_steps``, ``shared_var``).
    graph : {"ring", "geometric", "switching"}
        The communication graph (``"switching"``: a new proximity graph at every step,
        :func:`switching_graphs`).

    Returns
    -------
    dict of str to ndarray
        Per run: ``rmse_own`` (m), RMS error of the agents' final estimates;
        ``nees_own``, their NEES per degree of freedom (NaN for average consensus,
        which carries no covariance); ``cpu_s``.

    Examples
    --------
    >>> from mascore import compare
    >>> best = compare.simulate_shared("central-fusion", 6, 0, runs=200)
    >>> ren = compare.simulate_shared("ren-kc", 6, 0, runs=200)
    >>> bool(best["rmse_own"].mean() <= ren["rmse_own"].mean())
    True
    """
    n_agents, runs = check_run(n_agents, noise, dropout, 1.0, runs, settings, seed)
    if method not in SHARED_METHODS:
        raise ValueError(f"method must be one of {SHARED_METHODS}; got {method!r}")
    start = time.thread_time()
    init_rng, _, _, drop_rng = np.random.default_rng(seed).spawn(4)
    N = int(n_agents)
    lo, hi = np.log(settings.shared_var[0]), np.log(settings.shared_var[1])
    var = np.exp(init_rng.uniform(lo, hi, (runs, N)))
    xi = np.sqrt(var)[..., None] * draw_noise(init_rng, noise, (runs, N, 2))  # truth is 0
    P = var[..., None, None] * np.eye(2)
    adjacency = switching_graphs(N, settings.shared_steps, settings) if graph == "switching" else \
        benchmark_graph(graph, N, settings)
    nan = np.full(runs, np.nan)
    if method == "central-fusion":
        xi, P = consensus.central_fusion(xi, P)
        xi = np.broadcast_to(xi[:, None], (runs, N, 2))
        P = np.broadcast_to(P[:, None], (runs, N, 2, 2))
    elif method == "average-consensus" or method in REN_Q:
        A_k = adjacency[:, None] if adjacency.ndim == 3 else adjacency  # (steps, 1, N, N) when switching
        G = A_k * (drop_rng.random((settings.shared_steps, runs, N, N)) >= dropout)
        filt = method_spec(method, "shared").build(None)  # REN_Q: the paper's Q = Omega = 0.1 (Sec. 5), and 0
        if method == "average-consensus":
            for G_k in G:
                xi = filt.update(xi, G_k)
            P = None
        else:
            for G_k in G:  # noise-free messages
                xi, P = filt.update(xi, P, G_k)
    err = np.sum(xi**2, -1)
    nees = nan if P is None else np.mean(np.einsum("...i,...i->...", xi, np.linalg.solve(P, xi[..., None])[..., 0]),
                                         -1) / 2
    cpu = time.thread_time() - start
    return {"rmse_own": np.sqrt(err.mean(-1)), "nees_own": nees, "cpu_s": np.full(runs, cpu)}
