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

Batched update and prediction
-----------------------------
``H_i`` has a size that changes with the neighbourhood, which would force a
Python loop over agents. The update gathers each filter's ``q_i`` observed
entries instead (index lists padded to a common length, a padded slot
changing nothing), factors the ``q x q`` innovation covariance and subtracts
the rank-``q`` correction (:mod:`mascore._masked_gain`, shared with
:mod:`mascore.distributed_kf`): ``O(M^2 q)`` per filter instead of the
``O(M^3)`` of a full ``M x M`` solve, and exactly the update with ``H_i``
(tested against :func:`mascore.kalman.update` with the explicit ``H_i``). The
prediction uses ``F = I kron A + (I kron B) G`` with the control Jacobian
``G = dU/dX`` (``nN x 2nN``, written in its final layout): ``F P F^T`` costs
``1.5 M^3`` instead of ``4 M^3``. All N filters (and all Monte Carlo runs)
advance chunk by chunk, each chunk's update and prediction running while its
covariances are in cache.

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

from . import _flocking_core as _core
from ._flocking_core import FlockingGains
from ._flocking_core import check_dt as _check_dt
from ._flocking_core import check_gains as _check_gains
from ._flocking_core import check_range as _check_range
from ._flocking_core import check_steps as _check_steps
from ._flocking_core import check_team as _check_team
from ._flocking_core import finite_result as _finite_result
from ._flocking_core import float_array as _float_array
from ._masked_gain import masked_update as _masked_update
from ._progress import progress_bar
from ._validation import SYMMETRY_RTOL, cached_covariance, check_covariance, check_generator, check_positive_int
from .flocking import FlockingRun
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
        The flocking gains of eq. (6).
    Q_team : (2nN, 2nN) array_like
        Team process-noise covariance ``I_N kron Q`` (symmetric positive semidefinite).

    Returns
    -------
    X_pred : (..., N, 2n) ndarray
        Predicted team estimates.
    Sigma_pred : (..., 2nN, 2nN) ndarray
        Their covariances.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents [p, v]
    >>> X_pred, P_pred = dekf.ekf_predict(X, np.eye(12), 0.1, gains, 0.01 * np.eye(12))
    >>> X_pred.shape, bool(np.allclose(P_pred, P_pred.T))
    ((3, 4), True)
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
        Updated team estimates.
    Sigma_post : (..., 2nN, 2nN) ndarray
        ``(I - G_i H_i) Sigma_i^-`` of eq. (20) (equal to the Joseph form for
        this optimal gain), symmetrized.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents [p, v]
    >>> seen = np.array([True, True, False])                  # agent 2 is out of range
    >>> X_post, P_post = dekf.masked_update(X, 4.0 * np.eye(12), X + 0.5, seen, np.eye(12))
    >>> bool(np.allclose(X_post[2], X[2])), bool(np.trace(P_post[:8, :8]) < 32.0)   # only the seen agents move
    (True, True)
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
        The flocking gains of eq. (6).
    Q_team : (2nN, 2nN) array_like
        ``I_N kron Q``.

    Returns
    -------
    X_post, Sigma_post : updated estimates and covariances
    U : (..., N, n) ndarray
        ``U[..., i]``: agent ``i``'s control (m/s^2).
    X_next, Sigma_next : predictions for the next step

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents [p, v]
    >>> X_i = np.broadcast_to(X, (3, 3, 4)).copy()             # every agent's team estimate
    >>> P_i = np.broadcast_to(np.eye(12), (3, 12, 12)).copy()
    >>> out = dekf.ekf_flocking_step(X_i, P_i, X_i, np.ones((3, 3), bool), np.eye(12), 0.1, gains, 0.01 * np.eye(12))
    >>> [a.shape for a in out]
    [(3, 3, 4), (3, 12, 12), (3, 2), (3, 3, 4), (3, 12, 12)]
    """
    X_pred, Sigma_pred, z, observed, R = _update_args(X_pred, Sigma_pred, z, observed, R)
    N, m = X_pred.shape[-2:]
    if X_pred.ndim < 3 or X_pred.shape[-3] != N:
        raise ValueError(f"X_pred must have shape (..., N, N, 2n) (one team estimate per agent); got {X_pred.shape}")
    dt = _check_dt(dt)
    _check_gains(gains)
    Q_team = _constant_covariance(Q_team, "Q_team", N * m)
    with np.errstate(over="ignore", invalid="ignore"):
        out = _step(X_pred, Sigma_pred, z, observed, R, dt, gains, Q_team)
    return _finite_result(out, "ekf_flocking_step", "X_pred, Sigma_pred, z")


@dataclass(frozen=True)
class EstimatedFlockingRun(FlockingRun):
    """Outcome of :func:`simulate_estimation_based_flocking`.

    Parameters
    ----------
    t : (T+1,) ndarray
        Time (s).
    X : (..., T+1, N, 2n) ndarray
        True states.
    adjacency : (..., T+1, N, N) ndarray
        The proximity graph at each step.
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

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents [p, v]
    >>> run = dekf.simulate_estimation_based_flocking(X, np.broadcast_to(X, (3, 3, 4)), np.eye(12), 20, 0.1, gains,
    ...                                               0.01 * np.eye(4), np.eye(4), np.random.default_rng(0), 150.0)
    >>> run.X_hat.shape, run.rms_error.shape
    ((21, 3, 4), (21,))
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
        The flocking gains of eq. (6).
    Q : (2n, 2n) array_like
        Process-noise covariance of one agent (team: ``I_N kron Q``).
    R : (2n, 2n) or (2nN, 2nN) array_like
        Measurement-noise covariance per measured agent (team ``I_N kron R``)
        or the paper's full ``R`` (:func:`mascore.sensing.team_noise_covariance`).
    rng : numpy.random.Generator or int
        Source of process and measurement noise.
    sensing_range : float
        ``r`` (m), finite and > 0.
    observer : int
        Agent whose estimate and covariance are recorded (0-based).
    progress : bool
        Show a ``tqdm`` progress bar over the steps.

    Returns
    -------
    EstimatedFlockingRun
        True states, graphs and the observer's estimates, variances and the team RMS error.

    Raises
    ------
    mascore.DivergenceError
        If the true state, an estimate or an estimated standard deviation
        exceeds ``DIVERGENCE_LIMIT`` (the sampled loop is unstable).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents [p, v]
    >>> run = dekf.simulate_estimation_based_flocking(X, np.broadcast_to(X, (3, 3, 4)), np.eye(12), 50, 0.1, gains,
    ...                                               0.01 * np.eye(4), np.eye(4), np.random.default_rng(0), 150.0)
    >>> bool(run.rms_error[-1] < 3.0)                         # metres, with unit measurement noise
    True
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
    Lq = _core.noise_factor(Q, "Q", m)
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
        last = k == n_steps
        # eqs. (16)-(20), then (unless last) eq. (39) and eqs. (38), (40); Sigma is overwritten in place
        X_hat, U, X_next, diag = _step(X_hat, Sigma, z, observed, R_team, dt, gains, Q_team,
                                      in_place=True, predict=not last)
        Xs[k], As[k] = X, A_k
        X_obs[k] = X_hat[..., observer, :, :]
        var_obs[k] = diag[..., observer, :][..., pos_idx].sum(-1)
        rms[k] = np.sqrt(np.mean(np.sum((X_hat[..., :n] - X[..., None, :, :n]) ** 2, axis=-1), axis=(-1, -2)))
        if last:
            break
        X = _core.propagate(X, U, dt) + rng.standard_normal((*batch, N, m)) @ Lq.T  # eq. (1)
        X_hat = X_next
        _core.check_divergence(X, k + 1, dt)
        _core.check_divergence(X_hat, k + 1, dt, "estimate")
        _core.check_divergence(np.sqrt(np.abs(np.diagonal(Sigma, axis1=-2, axis2=-1))), k + 1, dt, "estimated std")
    t = dt * np.arange(n_steps + 1)
    mv = lambda a, nd: np.moveaxis(a, 0, a.ndim - nd - 1)  # noqa: E731  (put time after the batch axes)
    return EstimatedFlockingRun(
        t, mv(Xs, 2), mv(As, 2), int(observer), mv(X_obs, 2), mv(var_obs, 1), mv(rms, 0)
    )


# ----------------------------------------------------------------------------- private


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


#: Bytes of covariance handled per chunk of filters: each chunk runs its update and prediction while its
#: covariances are in cache (a few MB of L2/L3), instead of sweeping memory once per elementary operation.
_CHUNK_BYTES = 1 << 20


def _chunks(K, M):
    c = max(1, _CHUNK_BYTES // (8 * M * M))
    return [slice(s, min(s + c, K)) for s in range(0, K, c)]


def _flat(batch, X, Sigma, z=None, observed=None):
    """Broadcast to the common batch and flatten it: (K, N, m), (K, M, M), (K, N, m), (K, M) mask."""
    N, m = X.shape[-2:]
    M = N * m
    X = np.broadcast_to(X, (*batch, N, m)).reshape(-1, N, m)
    Sigma = np.broadcast_to(Sigma, (*batch, M, M)).reshape(-1, M, M)
    if z is None:
        return X, Sigma
    z = np.broadcast_to(z, (*batch, N, m)).reshape(-1, N, m)
    d = np.repeat(np.broadcast_to(observed, (*batch, N)).reshape(-1, N), m, axis=-1).astype(float)
    return X, Sigma, z, d


def _update_chunk(X, P, z, d, R):
    """Eqs. (16)-(20) for a chunk of filters: (c, N, m), (c, M, M), (c, N, m), (c, M) -> X_post, P_post."""
    c, N, m = X.shape
    x = X.reshape(c, N * m)
    x_post, P_post = _masked_update(x, P, z.reshape(c, N * m) - x, d, R)
    return x_post.reshape(c, N, m), P_post


def _predict_chunk(X, P, dt, gains, Q_team, out=None):
    """Eqs. (38), (40) for a chunk of filters, using the rank of ``F - I kron A``.

    ``F = I kron A + (I kron B) G`` with ``G = dU/dX`` (``nN x 2nN``, from
    :func:`mascore._flocking_core.control_and_jacobian` in its final layout).
    With ``Y = G P`` and ``Z = Y G^T`` (``1.5 M^3`` flops for ``M = 2nN``,
    instead of ``4 M^3`` for ``F P F^T`` with a dense ``F``):
    ``T = F P = A P + B Y``, ``W = T G^T = F Y^T = A Y^T + B Z`` and
    ``F P F^T = F T^T = A T^T + B W^T``. The products by the double
    integrator's ``A`` and ``B`` are scaled additions of contiguous rows; the
    result is symmetrized.

    Returns
    -------
    U : (c, N, n) every agent's control from each filter's estimate
    X_next : (c, N, m)
    P_next : (c, M, M), written into `out` if given
    """
    c, N, m = X.shape
    n, M, nN = m // 2, N * m, N * m // 2
    h = 0.5 * dt**2
    U, G = _core.control_and_jacobian(X, gains)  # eq. (39) on every agent, and dU/dX
    X_next = _core.propagate(X, U, dt)  # eq. (40)
    G = G.reshape(c, nN, M)
    Y = G @ P  # (c, nN, M)
    Z = Y @ np.swapaxes(G, -1, -2)  # (c, nN, nN), = G P G^T
    T = _apply_AB(P, Y, dt, h, N, n)  # F P, (c, M, M)
    W = _apply_AB(_transposed(Y), Z, dt, h, N, n)  # F Y^T = T G^T, (c, M, nN)
    S = _apply_AB(_transposed(T), _transposed(W), dt, h, N, n, out=out)  # F T^T = F P F^T
    S += Q_team  # eq. (40)
    S += np.swapaxes(S, -1, -2)  # symmetrize (rounding would otherwise accumulate over long runs)
    S *= 0.5
    return U, X_next, S


def _transposed(A):
    """The contiguous transpose of a stack of matrices."""
    out = np.empty((*A.shape[:-2], A.shape[-1], A.shape[-2]))
    np.copyto(out, np.swapaxes(A, -1, -2))
    return out


def _apply_AB(P, Y, dt, h, N, n, out=None):
    """``(I kron A) P + (I kron B) Y`` for the double integrator on contiguous ``(c, 2nN, K)``, ``(c, nN, K)``.

    Rows are (agent, [p; v], axis): the p rows become ``p + dt v + dt^2/2 y`` and
    the v rows ``v + dt y``.
    """
    c, K = P.shape[0], P.shape[-1]
    P4 = P.reshape(c, N, 2, n * K)
    Y3 = Y.reshape(c, N, n * K)
    T = np.empty((c, N, 2, n * K)) if out is None else out.reshape(c, N, 2, n * K)
    np.multiply(P4[:, :, 1], dt, out=T[:, :, 0])
    T[:, :, 0] += P4[:, :, 0]
    T[:, :, 0] += h * Y3
    np.multiply(Y3, dt, out=T[:, :, 1])
    T[:, :, 1] += P4[:, :, 1]
    return T.reshape(c, 2 * n * N, K)


def _predict(X_hat, Sigma, dt, gains, Q_team):
    """Eqs. (38), (40) on checked arrays: ``(..., N, 2n)``, ``(..., M, M)`` (batches broadcast)."""
    batch = np.broadcast_shapes(X_hat.shape[:-2], Sigma.shape[:-2])
    X, P = _flat(batch, X_hat, Sigma)
    X_next, P_next = np.empty(X.shape), np.empty(P.shape)
    for ch in _chunks(*P.shape[:2]):
        _, X_next[ch], _ = _predict_chunk(X[ch], P[ch], dt, gains, Q_team, out=P_next[ch])
    N, m = X_hat.shape[-2:]
    return X_next.reshape(*batch, N, m), P_next.reshape(*batch, N * m, N * m)


def _update(X_pred, Sigma, z, observed, R):
    """Eqs. (16)-(20) on checked arrays (batches broadcast); the covariance symmetrized."""
    batch = np.broadcast_shapes(X_pred.shape[:-2], Sigma.shape[:-2], z.shape[:-2], observed.shape[:-1])
    X, P, Z, d = _flat(batch, X_pred, Sigma, z, observed)
    X_post, P_post = np.empty(X.shape), np.empty(P.shape)
    for ch in _chunks(*P.shape[:2]):
        X_post[ch], Pc = _update_chunk(X[ch], P[ch], Z[ch], d[ch], R)
        np.add(Pc, np.swapaxes(Pc, -1, -2), out=P_post[ch])
        P_post[ch] *= 0.5
    N, m = X_pred.shape[-2:]
    return X_post.reshape(*batch, N, m), P_post.reshape(*batch, N * m, N * m)


def _step(X_pred, Sigma, z, observed, R, dt, gains, Q_team, in_place=False, predict=True):
    """Update, own control and prediction of every agent's filter, one chunk of filters at a time.

    Checked arrays: `X_pred` ``(..., N, N, m)`` (filter ``i`` of each run is
    agent ``i``'s), `Sigma` ``(..., N, M, M)``, `z` ``(..., N, N, m)``,
    `observed` ``(..., N, N)``.

    Returns ``(X_post, Sigma_post, U, X_next, Sigma_next)`` as
    :func:`ekf_flocking_step`; with `in_place` (`Sigma` a writeable array of
    the full batch shape) ``Sigma_next`` overwrites `Sigma`, ``Sigma_post`` is
    not kept, and ``(X_post, U, X_next, diag(Sigma_post))`` is returned
    (``U``, ``X_next`` ``None`` without `predict`; `Sigma` then holds
    ``Sigma_post``).
    """
    N, m = X_pred.shape[-2:]
    M = N * m
    batch = np.broadcast_shapes(X_pred.shape[:-2], Sigma.shape[:-2], z.shape[:-2], observed.shape[:-1])
    X, P, Z, d = _flat(batch, X_pred, Sigma, z, observed)
    if in_place:  # Sigma_next goes into Sigma itself
        P = Sigma.reshape(-1, M, M)
        if not np.shares_memory(P, Sigma) or P.shape[0] != X.shape[0]:
            raise ValueError("in_place needs Sigma as a contiguous array of the full batch shape")
    K = X.shape[0]
    own = np.arange(K) % N  # filter k is agent k % N's
    n = m // 2
    X_post, U, X_next = np.empty(X.shape), np.empty((K, n)), np.empty(X.shape)
    if in_place:
        P_next, diag = P, np.empty((K, M))
    else:
        P_post, P_next = np.empty(P.shape), np.empty(P.shape)
    for ch in _chunks(K, M):
        X_post[ch], Pc = _update_chunk(X[ch], P[ch], Z[ch], d[ch], R)  # eqs. (16)-(20)
        if in_place:
            diag[ch] = np.diagonal(Pc, axis1=-2, axis2=-1)
        else:
            P_post[ch] = Pc
        if not predict:
            if in_place:
                P_next[ch] = Pc
            continue
        U_all, X_next[ch], _ = _predict_chunk(X_post[ch], Pc, dt, gains, Q_team, out=P_next[ch])  # eqs. (38)-(40)
        U[ch] = U_all[np.arange(U_all.shape[0]), own[ch]]  # eq. (39): agent i's control from its own estimate
    shape = (*batch, N, m)
    if in_place:
        if not predict:
            return X_post.reshape(shape), None, None, diag.reshape(*batch, M)
        return X_post.reshape(shape), U.reshape(*batch, n), X_next.reshape(shape), diag.reshape(*batch, M)
    return (X_post.reshape(shape), P_post.reshape(*batch, M, M), U.reshape(*batch, n), X_next.reshape(shape),
            P_next.reshape(*batch, M, M))
