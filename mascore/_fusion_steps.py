"""The per-step inputs of :func:`mascore.fusion.track`, checked: one graph, one sensing mask and one
``(H, R)`` per step of the measurements.

Each function raises a ``ValueError`` or ``TypeError`` naming the argument (and the step) at fault;
the run loop itself is :func:`mascore.fusion.track`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._fusion_kernels import broadcast_batch
from ._validation import check_adjacency, check_covariance, float_array
from .sensor_network import SensorNetworkModel

__all__ = ["step_graphs", "step_sensing", "step_values"]


def step_graphs(graphs: Sequence[object] | ArrayLike | None, K: int, N: int, fixed: np.ndarray) -> list[np.ndarray]:
    """`mascore.fusion.track`'s graphs, one checked (N, N) adjacency per step (the model's when None)."""
    if graphs is None:
        return [fixed] * K
    if isinstance(graphs, (str, bytes)) or not hasattr(graphs, "__len__"):
        raise TypeError(f"graphs must be a sequence of K = {K} adjacency matrices or networkx graphs (one per "
                        f"step); got {type(graphs).__name__}")
    if len(graphs) != K:
        raise ValueError(f"graphs must hold one graph per step: K = {K} (the steps of z); got {len(graphs)}")
    return [check_adjacency(float_array(graphs[k], f"graphs[{k}]"), f"graphs[{k}]", size=N, undirected=True,
                            why="the consensus weights and the information exchange are symmetric")
            for k in range(K)]


def step_sensing(sensing: ArrayLike | None, K: int, N: int) -> np.ndarray:
    """`mascore.fusion.track`'s sensing mask, checked: (K, N) bool (every agent at every step when None)."""
    if sensing is None:
        return np.ones((K, N), dtype=bool)
    mask = np.asarray(sensing)
    if mask.dtype != bool:
        raise TypeError(f"sensing must be a (K, N) array of bool (True: the agent measures at that step); got "
                        f"dtype {mask.dtype}")
    if mask.shape != (K, N):
        raise ValueError(f"sensing must be (K, N) = ({K}, {N}): one row per step of z, one column per agent; got "
                         f"shape {mask.shape}")
    return mask


def step_values(H: ArrayLike | None, R: ArrayLike | None, model: SensorNetworkModel, rows: np.ndarray,
                 ) -> tuple[list[tuple[np.ndarray, np.ndarray] | None], tuple[int, ...]]:
    """`mascore.fusion.track`'s per-step ``(H(k), R(k))``, checked where `rows` ``(K, sum q_i)`` are read (None at a step whose
    values are the model's), and their run axes.

    The rows (and blocks) of an agent that does not sense at a step are not read; they are
    replaced by the model's, so that a step equal to the model's where read is the model's.
    """
    K, q, n = rows.shape[0], model.n_measurements, model.n_states
    if H is None and R is None:
        return [None] * K, ()
    H_k = np.broadcast_to(model.H_stacked, (K, q, n)) if H is None else float_array(H, "H")
    R_k = np.broadcast_to(model.R_stacked, (K, q, q)) if R is None else float_array(R, "R")
    for name, value, tail, what in (("H", H_k, (q, n), "[H_1(k); ...; H_N(k)]"),
                                    ("R", R_k, (q, q), "blockdiag(R_1(k), ..., R_N(k))")):
        if value.ndim < 3 or value.shape[0] != K or value.shape[-2:] != tail:
            raise ValueError(f"{name} must be (K, ..., {tail[0]}, {tail[1]}) with K = {K}: one stacked {what} per step "
                             f"of z (and per run, on axes between; agents' measurement sizes "
                             f"{model.measurement_sizes}); got shape {value.shape}")
    runs = broadcast_batch("H", H_k.shape[1:-2], "R", R_k.shape[1:-2])
    H_k, R_k = (np.broadcast_to(v.reshape(K, *(1,) * (len(runs) + 3 - v.ndim), *v.shape[1:]), (K, *runs, q, cols))
                for v, cols in ((H_k, n), (R_k, q)))  # the run axes aligned on the right, as numpy's
    used = rows.reshape(K, *(1,) * len(runs), q)
    H_k = np.where(used[..., :, None], H_k, model.H_stacked)
    R_k = np.where(used[..., :, None] & used[..., None, :], R_k, model.R_stacked)
    bad = ~np.isfinite(H_k).reshape(K, -1).all(axis=1)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ValueError(f"H[{k}] (step {k}) contains NaN or infinite entries in the rows of an agent that senses")
    block = np.zeros((q, q), dtype=bool)  # the entries of R(k) on an agent's block
    for sl in model._slices:
        block[sl, sl] = True
    off = (R_k != 0) & ~block
    if off.any():
        at = tuple(int(v) for v in np.argwhere(off)[0])
        raise ValueError(f"R[{at[0]}] (step {at[0]}) must be block diagonal, one block per agent (the agents' noises "
                         f"are independent); got R{list(at)} = {R_k[at]:.3g} off the blocks")
    for i, sl in enumerate(model._slices):
        if sl.stop > sl.start:
            try:
                check_covariance(R_k[..., sl, sl], "R", definite=True)
            except ValueError:
                for k in range(K):  # the first step at fault, named
                    check_covariance(R_k[k, ..., sl, sl], f"R[{k}] (step {k}), agent {i}'s block "
                                     f"[{sl.start}:{sl.stop}, {sl.start}:{sl.stop}],", definite=True)
                raise
    same = (H_k == model.H_stacked).reshape(K, -1).all(axis=1) & (R_k == model.R_stacked).reshape(K, -1).all(axis=1)
    return [None if same[k] else (H_k[k], R_k[k]) for k in range(K)], runs
