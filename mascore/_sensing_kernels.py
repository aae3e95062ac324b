"""The noise and the masked measurements of :mod:`mascore.sensing`, on arguments checked by the caller.

:func:`mascore.sensing.measure` and :func:`mascore.sensing.measurement_noise` check their arguments, then
call these; a simulation that checked its sensing once (:mod:`mascore.rendezvous`) calls them every step.
"""

from __future__ import annotations

import numpy as np

from ._fusion_kernels import psd_factor

__all__ = ["masked_measurement", "team_noise"]


def team_noise(rng: np.random.Generator, R_team: np.ndarray, shape: tuple, n_agents: int, m: int) -> np.ndarray:
    """:func:`mascore.sensing.measurement_noise` without checks (`R_team` the full ``(m N, m N)`` covariance)."""
    root = psd_factor(R_team, cholesky_first=True)
    std = rng.standard_normal((*shape, n_agents, n_agents * m))
    nu = std @ root.T
    return nu.reshape(*shape, n_agents, n_agents, m)


def masked_measurement(rng: np.random.Generator, x: np.ndarray, S: np.ndarray, R_team: np.ndarray,
                       ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`mascore.sensing.measure` without checks: `S` the sensing mask, `R_team` the full ``(m N, m N)`` covariance."""
    n_agents, m = x.shape[-2:]
    batch = np.broadcast_shapes(x.shape[:-2], S.shape[:-2])
    nu = team_noise(rng, R_team, batch, n_agents, m)
    Z = np.broadcast_to(x[..., None, :, :], (*batch, n_agents, n_agents, m)) + nu
    S = np.broadcast_to(S, (*batch, n_agents, n_agents)).copy()
    return np.where(S[..., None], Z, 0.0), S
