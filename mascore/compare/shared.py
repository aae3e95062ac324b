"""The shared task (Ren et al.): fusing priors of one common quantity."""

from __future__ import annotations

import time

import numpy as np

from .. import estimation
from ..estimation import method_spec
from .benchmark import (
    SETTINGS,
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
        One of the methods of the shared task (:data:`ALL_SHARED_METHODS`: their specs').
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
    methods = estimation.method_names("shared")
    if method not in methods:
        raise ValueError(f"method must be one of {methods}; got {method!r}")
    start = time.thread_time()
    init_rng, _, _, drop_rng = np.random.default_rng(seed).spawn(4)
    N = int(n_agents)
    lo, hi = np.log(settings.shared_var[0]), np.log(settings.shared_var[1])
    var = np.exp(init_rng.uniform(lo, hi, (runs, N)))
    xi = np.sqrt(var)[..., None] * draw_noise(init_rng, noise, (runs, N, 2))  # truth is 0
    P = var[..., None, None] * np.eye(2)
    adjacency = switching_graphs(N, settings.shared_steps, settings) if graph == "switching" else \
        benchmark_graph(graph, N, settings)
    A_k = adjacency[:, None] if adjacency.ndim == 3 else adjacency  # (steps, 1, N, N) when switching
    G = A_k * (drop_rng.random((settings.shared_steps, runs, N, N)) >= dropout)
    xi, P = method_spec(method, "shared").build(None).fuse(xi, P, G)  # noise-free messages
    err = np.sum(xi**2, -1)
    nees = np.full(runs, np.nan) if P is None else \
        np.mean(np.einsum("...i,...i->...", xi, np.linalg.solve(P, xi[..., None])[..., 0]), -1) / 2
    cpu = time.thread_time() - start
    return {"rmse_own": np.sqrt(err.mean(-1)), "nees_own": nees, "cpu_s": np.full(runs, cpu)}
