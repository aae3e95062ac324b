"""The Kalman gain of a filter that observes a subset of its state, in rank-q form.

Used by the linear team filters of Song et al. (2023)
(:mod:`mascore.distributed_kf`): agent ``i`` measures the states of its closed
neighbourhood, so its measurement matrix ``H_i`` selects ``q_i`` entries of the
team state (eq. (3)) and ``H_i^T H_i = D_i`` is a diagonal 0/1 mask. With ``R``
the covariance of the whole noise vector ``nu_i`` (``H_i R H_i^T`` that of the
measured part), the gain of eq. (19) embedded in the team space is

    G_i H_i = Sigma H_i^T S_i^{-1} H_i,   S_i = H_i (Sigma + R) H_i^T      (eq. (17))

Here ``H_i`` is never formed: the ``q_i`` observed indices are gathered
(``C = Sigma H_i^T``, ``M x q``; ``S_i``, ``q x q``) and ``C S_i^{-1}`` is one
``q x q`` solve: ``O(M q^2)`` work instead of the ``O(M^3)`` of a full
``M x M`` solve. Filters with different numbers of observed entries are
batched by padding the index lists to the largest ``q``: a padded slot has a
zero column in ``C`` and a unit diagonal entry in ``S``, so it changes nothing
(``S`` is ``blockdiag(S_i, I)`` up to a permutation).

All functions take checked arrays; the masks are 0/1 float arrays ``d`` of
shape ``(..., M)`` (``diag(D_i)``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["observed_indices", "innovation_factors", "masked_gain"]

#: Up to this many states the gain uses one masked ``M x M`` solve (cheaper than gathering at that size).
_SMALL = 48


def observed_indices(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Observed indices of 0/1 masks, padded to a common length.

    Parameters
    ----------
    d : (..., M) ndarray
        0/1 masks (``diag(H^T H)``).

    Returns
    -------
    idx : (..., q) ndarray of int
        The observed indices in increasing order, then padding (indices of
        unobserved entries); ``q`` is the largest number of observed entries.
    valid : (..., q) ndarray of float
        1 for an observed index, 0 for padding.

    Examples
    --------
    >>> idx, valid = observed_indices(np.array([[0.0, 1, 1, 0], [1, 0, 0, 0]]))
    >>> idx, valid
    (array([[1, 2],
           [0, 1]]), array([[1., 1.],
           [1., 0.]]))
    """
    obs = d > 0.5
    q = int(obs.sum(axis=-1).max()) if obs.size else 0
    idx = np.argsort(~obs, axis=-1, kind="stable")[..., :q]
    return idx, np.take_along_axis(obs, idx, axis=-1).astype(float)


def innovation_factors(
    Sigma: np.ndarray, R: np.ndarray, idx: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``C = Sigma H^T`` and the padded innovation covariance ``S = H (Sigma + R) H^T``.

    Parameters
    ----------
    Sigma : (..., M, M) ndarray
        Predicted covariances.
    R : (M, M) ndarray
        Covariance of the whole noise vector (only the observed block is used).
    idx, valid : (..., q) ndarrays
        From :func:`observed_indices`.

    Returns
    -------
    C : (..., M, q) ndarray
        Columns ``idx`` of `Sigma`, zero in the padded slots.
    S : (..., q, q) ndarray
        ``Sigma[idx, idx] + R[idx, idx]`` on the observed slots, identity on the padding.

    Examples
    --------
    >>> C, S = innovation_factors(np.eye(3), 2 * np.eye(3), np.array([2, 0]), np.array([1.0, 0.0]))
    >>> C.T, S
    (array([[0., 0., 1.],
           [0., 0., 0.]]), array([[3., 0.],
           [0., 1.]]))
    """
    C = np.take_along_axis(Sigma, idx[..., None, :], axis=-1)
    C *= valid[..., None, :]
    both = valid[..., :, None] * valid[..., None, :]
    S = np.take_along_axis(C, idx[..., :, None], axis=-2)
    S *= valid[..., :, None]
    S += R[idx[..., :, None], idx[..., None, :]] * both
    diag = np.arange(idx.shape[-1])
    S[..., diag, diag] += 1.0 - valid
    return C, S


def masked_gain(Sigma: np.ndarray, d: np.ndarray, R: np.ndarray) -> np.ndarray:
    """``G H = Sigma D S~^{-1} D`` embedded in the team space, from the ``q x q`` innovation covariance.

    Parameters
    ----------
    Sigma : (..., M, M) ndarray
        Predicted covariances.
    d : (..., M) ndarray
        0/1 masks ``diag(D)`` (batch axes as `Sigma`'s).
    R : (M, M) ndarray
        Measurement-noise covariance of the whole vector ``nu``.

    Returns
    -------
    (..., M, M) ndarray
        ``G H``: zero columns for the unobserved entries.

    Examples
    --------
    >>> np.round(masked_gain(np.eye(2), np.array([1.0, 0.0]), np.eye(2)), 3)  # scalar gain 1 / (1 + 1)
    array([[0.5, 0. ],
           [0. , 0. ]])
    """
    M = Sigma.shape[-1]
    if M <= _SMALL:  # few states: one masked M x M solve costs less than gathering
        both = d[..., :, None] * d[..., None, :]
        S_tilde = both * (Sigma + R) + np.eye(M) * (1.0 - d[..., None])  # blockdiag(S, I) up to a permutation
        Y = np.linalg.solve(S_tilde, d[..., :, None] * Sigma)  # S~^{-1} D Sigma
        return np.swapaxes(Y, -1, -2) * d[..., None, :]
    idx, valid = observed_indices(d)
    C, S = innovation_factors(Sigma, R, idx, valid)
    W = np.swapaxes(np.linalg.solve(S, np.swapaxes(C, -1, -2)), -1, -2)  # C S^{-1}, eq. (19)
    out = np.zeros((*W.shape[:-2], M, M + 1))
    cols = np.where(valid > 0, idx, M)  # padding goes to a spare column, dropped below
    np.put_along_axis(out, np.broadcast_to(cols[..., None, :], W.shape), W, axis=-1)
    return out[..., :M]

