"""Per-agent extended Kalman filters over the whole team, and estimation-based flocking.

Song et al. (2023), Sec. III-B: every agent ``i`` runs its own EKF of the
*whole* team state ``X`` (size ``2nN``), from measurements of itself and of its
current neighbours only (eqs. (2)-(3)).

* Prediction, eqs. (37)-(38) and (40): ``X_hat_i^- = f'(X_hat_i)`` with
  ``f'(X) = (I_N kron A) X + (I_N kron B) U(X)``, ``U`` the fully-connected
  flocking law (eq. (39) applied to the common argument ``X``), and
  ``Sigma_i^- = F_i Sigma_i F_i^T + I_N kron Q`` with ``F_i = df'/dX`` at
  ``X_hat_i`` (:func:`mascore.flocking.closed_loop_jacobian`).
* Update, eqs. (16)-(20): the linear Kalman update with the selection matrix
  ``H_i`` of the agent's current closed neighbourhood.
* Control, eq. (39): agent ``i`` applies the flocking law to its own estimate,
  treating *every* other agent as a neighbour (the virtual fully-connected
  network).

Batched, fixed-size update
--------------------------
``H_i`` has a size that changes with the neighbourhood, which would force a
Python loop over agents. :func:`masked_update` uses the equivalent fixed-size
form: with the diagonal 0/1 mask ``M_i = H_i^T H_i``,
``S~ = M_i (Sigma + R) M_i + (I - M_i)`` is, up to a permutation,
``blockdiag(S_i, I)``, so ``Sigma M_i S~^{-1}`` equals ``Sigma H_i^T S_i^{-1} H_i``
and the update (eqs. (18)-(20), covariance ``(I - G_i H_i) Sigma_i^-`` as in
eq. (20)) is exactly the one with ``H_i`` (tested against :func:`mascore.kalman.update` with the explicit ``H_i``). All
N filters (and all Monte Carlo runs) then advance in a handful of batched
``matmul``/``solve`` calls.

Shapes: team states are ``(..., N, 2n)`` (rows ``[p_j; v_j]``), covariances
``(..., 2nN, 2nN)`` in the matching flattened order; leading axes are the
estimating agent and Monte Carlo runs.

Input checks
------------
The public functions check every argument and raise a ``ValueError`` or
``TypeError`` naming it: finite states, ``dt > 0``, covariances symmetric
positive semidefinite (``R`` definite). The constant matrices (``Q_team``,
``R``) are checked once per distinct value; a covariance that changes every
step (``Sigma``) is checked by one Cholesky factorisation of
``Sigma + 1e-8 max(1, max|Sigma|) I`` (the tolerance of
:func:`mascore._validation.check_covariance`, a few times cheaper than its
eigenvalues). The simulator checks once and then runs unchecked kernels. One
agent (``N = 1``) and an isolated agent (observing only itself) are defined: the
update then uses the agent's own measurement only. A result that overflows
raises instead of returning NaN or inf.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._progress import progress_bar
from ._validation import SYMMETRY_RTOL, cached_covariance, check_covariance, check_generator, check_positive_int
from .flocking import (
    FlockingGains,
    FlockingRun,
    _check_divergence,
    _check_dt,
    _check_gains,
    _check_range,
    _check_steps,
    _check_team,
    _chol,
    _closed_loop_jacobian,
    _closed_loop_step,
    _control_from_views,
    _finite_result,
    _float_array,
    _propagate,
)
from .graphs import proximity_graph
from .sensing import measure, team_noise_covariance

__all__ = [
    "ekf_predict",
    "masked_update",
    "ekf_flocking_step",
    "EstimatedFlockingRun",
    "simulate_estimation_based_flocking",
]


def ekf_predict(
    X_hat: ArrayLike, Sigma: ArrayLike, dt: float, gains: FlockingGains, Q_team: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """EKF time update through the fully-connected flocking dynamics, eqs. (38), (40).

    Parameters
    ----------
    X_hat : (..., N, 2n) array_like
        Updated estimates of the team (one per estimating agent / run).
    Sigma : (..., 2nN, 2nN) array_like
        Their error covariances (symmetric positive semidefinite).
    dt : float
        Sampling time (s), finite and > 0.
    gains : FlockingGains
    Q_team : (2nN, 2nN) array_like
        Team process-noise covariance ``I_N kron Q`` (symmetric positive semidefinite).

    Returns
    -------
    X_pred : (..., N, 2n) ndarray
    Sigma_pred : (..., 2nN, 2nN) ndarray
    """
    X_hat = _check_team(X_hat, "X_hat")
    M = X_hat.shape[-1] * X_hat.shape[-2]
    Sigma = _check_sigma(Sigma, "Sigma", M, X_hat.shape[:-2], "X_hat")
    dt = _check_dt(dt)
    _check_gains(gains)
    Q_team = _constant_covariance(Q_team, "Q_team", M)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_predict(X_hat, Sigma, dt, gains, Q_team), "ekf_predict", "X_hat, Sigma")


def masked_update(
    X_pred: ArrayLike, Sigma_pred: ArrayLike, z: ArrayLike, observed: ArrayLike, R: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with the states of the `observed` agents, eqs. (16)-(20).

    Parameters
    ----------
    X_pred : (..., N, 2n) array_like
        Predicted team estimate(s).
    Sigma_pred : (..., 2nN, 2nN) array_like
        Predicted covariance(s).
    z : (..., N, 2n) array_like
        Measured states ``z_{i,x_j} = x_j + nu_ij`` (eq. (2)); rows of agents
        that are not observed are ignored (they must be finite).
    observed : (..., N) array_like of bool
        The closed neighbourhood ``N_i bar``: which agents' states are in
        ``z_i = H_i (X + nu_i)`` (eq. (3)).
    R : (2nN, 2nN) array_like
        Measurement-noise covariance of ``nu_i`` (the paper's ``R``).

    Returns
    -------
    X_post : (..., N, 2n) ndarray
    Sigma_post : (..., 2nN, 2nN) ndarray
        ``(I - G_i H_i) Sigma_i^-`` of eq. (20) (equal to the Joseph form for
        this optimal gain), symmetrized.
    """
    X_pred, Sigma_pred, z, observed, R = _update_args(X_pred, Sigma_pred, z, observed, R)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_update(X_pred, Sigma_pred, z, observed, R), "masked_update", "X_pred, Sigma_pred, z")


def _update_args(X_pred, Sigma_pred, z, observed, R):
    """Check the arguments of :func:`masked_update`."""
    X_pred = _check_team(X_pred, "X_pred")
    N, m = X_pred.shape[-2:]
    M = N * m
    batch = X_pred.shape[:-2]
    Sigma_pred = _check_sigma(Sigma_pred, "Sigma_pred", M, batch, "X_pred")
    z = _check_team(z, "z")
    if z.shape[-2:] != (N, m):
        raise ValueError(f"Incompatible dimensions of z; expected (..., {N}, {m}) but found {z.shape}")
    _check_batch(z.shape[:-2], batch, "z", "X_pred")
    if isinstance(observed, (str, bytes)) or observed is None:
        raise TypeError(f"observed must be a boolean array (..., {N}); got {type(observed).__name__}")
    observed = np.asarray(observed)
    if observed.dtype != bool or observed.ndim < 1 or observed.shape[-1] != N:
        raise ValueError(f"observed must be a boolean array (..., {N}); got {observed.dtype} {observed.shape}")
    _check_batch(observed.shape[:-1], batch, "observed", "X_pred")
    R = _constant_covariance(R, "R", M, definite=True)
    return X_pred, Sigma_pred, z, observed, R


def ekf_flocking_step(
    X_pred: ArrayLike,
    Sigma_pred: ArrayLike,
    z: ArrayLike,
    observed: ArrayLike,
    R: ArrayLike,
    dt: float,
    gains: FlockingGains,
    Q_team: ArrayLike,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One step of every agent's filter and control, batched over agents (and runs).

    Update with the current measurements (eqs. (16)-(20)), control of each agent
    on its own updated estimate (eq. (39)), prediction to the next step
    (eqs. (38), (40)).

    Parameters
    ----------
    X_pred : (..., N, N, 2n) array_like
        ``X_pred[..., i]``: agent ``i``'s predicted team state.
    Sigma_pred : (..., N, 2nN, 2nN) array_like
        Their covariances.
    z : (..., N, N, 2n) array_like
        ``z[..., i, j]``: agent ``i``'s measurement of agent ``j`` (eq. (2)).
    observed : (..., N, N) array_like of bool
        Sensing mask, ``observed[..., i, j]`` iff ``j`` in ``N_i bar``.
    R : (2nN, 2nN) array_like
        Measurement-noise covariance of ``nu_i``.
    dt : float
        Sampling time (s).
    gains : FlockingGains
    Q_team : (2nN, 2nN) array_like
        ``I_N kron Q``.

    Returns
    -------
    X_post, Sigma_post : updated estimates and covariances
    U : (..., N, n) ndarray
        ``U[..., i]``: agent ``i``'s control (m/s^2).
    X_next, Sigma_next : predictions for the next step
    """
    X_pred, Sigma_pred, z, observed, R = _update_args(X_pred, Sigma_pred, z, observed, R)
    N, m = X_pred.shape[-2:]
    if X_pred.ndim < 3 or X_pred.shape[-3] != N:
        raise ValueError(f"X_pred must have shape (..., N, N, 2n) (one team estimate per agent); got {X_pred.shape}")
    dt = _check_dt(dt)
    _check_gains(gains)
    Q_team = _constant_covariance(Q_team, "Q_team", N * m)
    with np.errstate(over="ignore", invalid="ignore"):
        X_post, Sigma_post = _update(X_pred, Sigma_pred, z, observed, R)
        U = _control_from_views(X_post, gains, None)
        X_next, Sigma_next = _predict(X_post, Sigma_post, dt, gains, Q_team)
    return _finite_result((X_post, Sigma_post, U, X_next, Sigma_next), "ekf_flocking_step",
                          "X_pred, Sigma_pred, z")


@dataclass(frozen=True)
class EstimatedFlockingRun(FlockingRun):
    """Outcome of :func:`simulate_estimation_based_flocking`.

    Attributes
    ----------
    t, X, adjacency
        As in :class:`mascore.flocking.FlockingRun`.
    observer : int
        Index of the agent whose filter is recorded.
    X_hat : (..., T+1, N, 2n) ndarray
        The observer's updated estimate of the team at each step.
    position_variance : (..., T+1, N) ndarray
        Trace of the position block of the observer's covariance, per agent
        (m^2); its square root is the "statistical error" of Fig. 4(f).
    rms_error : (..., T+1) ndarray
        Root-mean-square position error (m) over every estimating agent and
        every estimated agent, ``sqrt(mean_{i,j} |p_hat_{i,j} - p_j|^2)``.
    """

    observer: int
    X_hat: np.ndarray
    position_variance: np.ndarray
    rms_error: np.ndarray


def simulate_estimation_based_flocking(
    X0: ArrayLike,
    X_hat0: ArrayLike,
    Sigma0: ArrayLike,
    n_steps: int,
    dt: float,
    gains: FlockingGains,
    Q: ArrayLike,
    R: ArrayLike,
    rng: np.random.Generator | int,
    sensing_range: float,
    observer: int = 0,
    progress: bool = False,
) -> EstimatedFlockingRun:
    """Estimation-based flocking over a virtual fully-connected network, Sec. III-B.

    Step ``k``: (1) the proximity graph of the true positions gives each
    agent's closed neighbourhood; (2) agent ``i`` measures those states with
    noise (eq. (2)) and updates its EKF (eqs. (16)-(20)); (3) it applies eq. (39)
    to its updated estimate; (4) the team moves by eq. (1) with process noise;
    (5) every EKF predicts through eq. (40) with the Jacobian of eq. (38).

    Parameters
    ----------
    X0 : (..., N, 2n) array_like
        True initial states (leading axes: Monte Carlo runs).
    X_hat0 : (..., N, N, 2n) array_like
        Prior estimates at step 0: ``X_hat0[..., i]`` is agent ``i``'s.
    Sigma0 : (2nN, 2nN) array_like
        Their common error covariance (Assumption 2).
    n_steps : int
        Number of steps (1 to :data:`mascore.flocking.MAX_STEPS`).
    dt : float
        Sampling time (s), finite and > 0.
    gains : FlockingGains
    Q : (2n, 2n) array_like
        Process-noise covariance of one agent (team: ``I_N kron Q``).
    R : (2n, 2n) or (2nN, 2nN) array_like
        Measurement-noise covariance per measured agent (team ``I_N kron R``)
        or the paper's full ``R`` (:func:`mascore.sensing.team_noise_covariance`).
    rng : numpy.random.Generator or int
    sensing_range : float
        ``r`` (m), finite and > 0.
    observer : int
        Agent whose estimate and covariance are recorded (0-based).
    progress : bool
        Show a ``tqdm`` progress bar over the steps.

    Raises
    ------
    mascore.flocking.DivergenceError
        If the true state, an estimate or an estimated standard deviation
        exceeds ``DIVERGENCE_LIMIT`` (the sampled loop is unstable).
    """
    rng = check_generator(rng)
    X = _check_team(X0, "X0").copy()
    N, m = X.shape[-2:]
    n = m // 2
    M = N * m
    batch = X.shape[:-2]
    X_hat = _float_array(X_hat0, "X_hat0").copy()
    if X_hat.shape != (*batch, N, N, m) or not np.all(np.isfinite(X_hat)):
        raise ValueError(f"X_hat0 must be finite with shape {(*batch, N, N, m)} (one team estimate per agent, "
                         f"to match X0 of shape {X.shape}); got {X_hat.shape}")
    Sigma0 = check_covariance(_float_array(Sigma0, "Sigma0"), "Sigma0", size=M)
    try:
        np.broadcast_to(Sigma0, (*batch, N, M, M))
    except ValueError:
        raise ValueError(f"Sigma0 must be a ({M}, {M}) covariance common to every filter (or broadcast to "
                         f"{(*batch, N, M, M)}); got shape {Sigma0.shape}") from None
    observer = check_positive_int(observer, "observer", minimum=0)
    if not observer < N:
        raise ValueError(f"observer must be in 0..{N - 1}; got {observer}")
    n_steps = _check_steps(n_steps)
    dt = _check_dt(dt)
    _check_gains(gains)
    sensing_range = _check_range(sensing_range)
    if not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be True or False; got {type(progress).__name__} {progress!r}")
    Lq = _chol(Q, "Q", m)
    Q_team = np.kron(np.eye(N), Lq @ Lq.T)
    R_team = check_covariance(team_noise_covariance(_float_array(R, "R"), N, m), "R", definite=True)
    Sigma = np.broadcast_to(Sigma0, (*batch, N, M, M)).copy()

    Xs = np.empty((n_steps + 1, *X.shape))
    As = np.empty((n_steps + 1, *batch, N, N), dtype=bool)
    X_obs = np.empty((n_steps + 1, *batch, N, m))
    var_obs = np.empty((n_steps + 1, *batch, N))
    rms = np.empty((n_steps + 1, *batch))
    pos_idx = (np.arange(N)[:, None] * m + np.arange(n)[None, :])  # (N, n) flat indices of positions
    for k in progress_bar(range(n_steps + 1), enabled=progress, desc="EKF flocking", leave=False):
        A_k = proximity_graph(X[..., :n], sensing_range).astype(bool)
        z, observed = measure(rng, X, A_k, R_team, allow_isolated=True)  # eqs. (2)-(3)
        X_hat, Sigma = _update(X_hat, Sigma, z, observed, R_team)  # eqs. (16)-(20)
        Xs[k], As[k] = X, A_k
        X_obs[k] = X_hat[..., observer, :, :]
        diag = np.diagonal(Sigma[..., observer, :, :], axis1=-2, axis2=-1)
        var_obs[k] = diag[..., pos_idx].sum(-1)
        rms[k] = np.sqrt(np.mean(np.sum((X_hat[..., :n] - X[..., None, :, :n]) ** 2, axis=-1), axis=(-1, -2)))
        if k == n_steps:
            break
        U = _control_from_views(X_hat, gains, None)  # eq. (39), virtual fully-connected network
        X = _propagate(X, U, dt) + rng.standard_normal((*batch, N, m)) @ Lq.T  # eq. (1)
        X_hat, Sigma = _predict(X_hat, Sigma, dt, gains, Q_team)  # eqs. (38), (40)
        _check_divergence(X, k + 1, dt)
        _check_divergence(X_hat, k + 1, dt, "estimate")
        _check_divergence(np.sqrt(np.abs(np.diagonal(Sigma, axis1=-2, axis2=-1))), k + 1, dt, "estimated std")
    t = dt * np.arange(n_steps + 1)
    mv = lambda a, nd: np.moveaxis(a, 0, a.ndim - nd - 1)  # noqa: E731  (put time after the batch axes)
    return EstimatedFlockingRun(
        t, mv(Xs, 2), mv(As, 2), int(observer), mv(X_obs, 2), mv(var_obs, 1), mv(rms, 0)
    )


# ----------------------------------------------------------------------------- private


def _symmetrize(P):
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def _check_batch(got, batch, name, of):
    try:
        np.broadcast_shapes(got, batch)
    except ValueError:
        raise ValueError(f"{name} has batch axes {got} that do not match those of {of} {batch}") from None


def _constant_covariance(C, name, size, definite=False):
    """A constant (size, size) covariance, checked once per distinct value."""
    C = _float_array(C, name)
    if C.shape != (size, size):
        raise ValueError(f"Incompatible dimensions of {name}; expected ({size}, {size}) but found {C.shape}")
    return cached_covariance(C, name, size=size, definite=definite)


def _check_sigma(S, name, M, batch, of):
    """A (..., M, M) stack of covariances: finite, symmetric, positive semidefinite (one Cholesky).

    Same tolerance as :func:`mascore._validation.check_covariance`: symmetric to
    ``1e-8 s`` and smallest eigenvalue ``>= -1e-8 s`` with ``s = max(1, max|S|)``.
    """
    S = _float_array(S, name)
    if S.ndim < 2 or S.shape[-2:] != (M, M):
        raise ValueError(f"Incompatible dimensions of {name}; expected (..., {M}, {M}) but found {S.shape}")
    _check_batch(S.shape[:-2], batch, name, of)
    scale = float(np.abs(S).max())
    if not np.isfinite(scale):
        raise ValueError(f"{name} contains NaN or infinite entries")
    tol = SYMMETRY_RTOL * max(1.0, scale)
    if float(np.abs(S - np.swapaxes(S, -1, -2)).max()) > tol:
        raise ValueError(f"{name} must be symmetric")
    try:
        np.linalg.cholesky(S + tol * np.eye(M))
    except np.linalg.LinAlgError:
        check_covariance(S, name)  # raises, with the smallest eigenvalue
    return S


def _predict(X_hat, Sigma, dt, gains, Q_team):
    F = _closed_loop_jacobian(X_hat, dt, gains)  # eq. (38)
    X_pred = _closed_loop_step(X_hat, dt, gains)  # eq. (40)
    Sigma_pred = F @ Sigma @ np.swapaxes(F, -1, -2) + Q_team
    return X_pred, _symmetrize(Sigma_pred)


def _update(X_pred, Sigma, z, observed, R):
    shape = X_pred.shape
    m = shape[-1]
    M = shape[-2] * m
    mask = np.repeat(observed, m, axis=-1).astype(float)  # diagonal of M_i = H_i^T H_i
    both = mask[..., :, None] * mask[..., None, :]
    S = both * (Sigma + R)  # M (Sigma + R) M
    idx = np.arange(M)
    S[..., idx, idx] += 1.0 - mask  # + (I - M): S~ = blockdiag(S_i, I) up to a permutation
    K = np.swapaxes(np.linalg.solve(S, mask[..., :, None] * Sigma), -1, -2)  # eq. (19): Sigma M S~^-1
    innovation = mask * (z - X_pred).reshape(*shape[:-2], M)  # eq. (16)
    X_post = X_pred + np.einsum("...ij,...j->...i", K, innovation).reshape(shape)  # eq. (18)
    Sigma_post = Sigma - K @ (mask[..., :, None] * Sigma)  # eq. (20): (I - G_i H_i) Sigma_i^-
    return X_post, _symmetrize(Sigma_post)
