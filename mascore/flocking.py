"""Augmented Cucker-Smale flocking: control law, its Jacobian and closed-loop simulation.

The control of Song et al. (2023), Sec. II-D, eq. (6), after Cucker and Smale
(2007) and Park et al. (their ref. [19]): agent ``i`` with position ``p_i`` and
velocity ``v_i`` (both in R^n) applies the acceleration::

    u_i = rho3 sum_j a_ij phi1(p_ij) (v_j - v_i) + rho4 sum_j a_ij phi2(p_ij, v_ij) (p_j - p_i)

    phi1(p)    = 1 / (1 + |p|^2)^beta
    phi2(p, v) = rho5 / (2 |p|^2) <v, p> + rho6 / (2 |p|) (|p| - R)

with ``p_ij = p_i - p_j`` and ``v_ij = v_i - v_j``. The second term is a
damped spring of rest length ``R`` along the line of sight. ``a_ij`` is the
adjacency of the proximity graph (eq. (6)/(7)) or 1 for every ``j != i`` (the
fully-connected law, and eq. (39) when evaluated on an estimate).

Conventions
-----------
* A team state is an array ``X`` of shape ``(..., N, 2n)`` whose row ``i`` is
  ``x_i = [p_i; v_i]`` (m, m/s). Flattening the last two axes gives the paper's
  ``X = [x_1; ...; x_N]`` of eq. (3); leading axes are Monte Carlo runs (or
  estimating agents) and are broadcast everywhere.
* A set of *views* is an array ``(..., N, N, 2n)``: ``views[..., i, j, :]`` is
  agent ``i``'s knowledge of agent ``j``'s state -- its measurement ``z_{i,x_j}``
  (eq. (7)) or its estimate ``x_hat_{i,j}`` (eq. (39)). Agent ``i`` then applies
  the law to the differences ``views[i, i] - views[i, j]``.

When two agents meet
--------------------
``phi2`` divides by ``|p_ij|``: the unit vector ``p_ij / |p_ij|`` of the
line of sight is undefined when two agents (or two estimated or measured
positions) coincide. The ``phi2`` part of the pair term itself stays bounded
near contact: for ``|p_ij| <= R`` its size is at most
``rho4 (rho5 |v_ij| + rho6 R) / 2``. mascore replaces ``|p_ij|`` by
``max(|p_ij|, d_min)`` everywhere in ``phi2`` (``FlockingGains.min_distance``,
default 1e-6 m). Closer than ``d_min`` the damper and spring therefore shrink
linearly to exactly zero at contact -- finite, deterministic, no NaN -- while
the alignment term ``phi1`` is smooth and unchanged; farther than ``d_min`` the
law is exactly as printed. The Jacobian is the exact
derivative of this regularised law on both sides of ``d_min``; inside
``d_min`` the spring's slope is about ``rho4 rho6 R / (2 d_min)`` (6e7 s^-2
with Table I gains), the honest price of a law whose direction flips at
contact: an EKF linearised at two coincident estimates inflates its
covariance accordingly (and the simulators raise ``DivergenceError`` if it
blows up). In the paper's scenarios no two agents (nor two estimates) come
closer than a few metres (closest pair over 20 Monte Carlo runs of the three
cases of Fig. 5: about 7 m), so the regularisation is never active there.

Input checks
------------
Every public function checks its arguments (finite entries, shapes, ``dt > 0``,
a :class:`FlockingGains`, non-negative adjacency weights -- a graph Laplacian
passed by mistake is named as such) and raises a ``ValueError`` or
``TypeError`` naming the argument; the simulators then loop over unchecked
private kernels. A self-loop ``a_ii`` is accepted and ignored: the pair term
of an agent with itself is exactly zero. One agent (``N = 1``) or an isolated
agent feels no pair term: its control is zero. A result that overflows (inputs
too large for floating point) raises instead of returning NaN or inf.

Symbols follow the paper; equations are cited as ``eq. (N)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._validation import float_array as _float_array
from ._validation import check_covariance, check_generator, check_positive, check_positive_int
from .graphs import complete_graph, proximity_graph
from .sensing import measure, team_noise_covariance

__all__ = [
    "DivergenceError",
    "DIVERGENCE_LIMIT",
    "MAX_STEPS",
    "FlockingGains",
    "phi1",
    "phi2",
    "pair_term",
    "pair_term_jacobian",
    "flocking_control",
    "control_from_views",
    "closed_loop_step",
    "closed_loop_jacobian",
    "FlockingRun",
    "simulate_measured_flocking",
    "flock_spread",
    "max_distance_from_centre",
]


#: A simulated state component (m or m/s) larger than this means the closed loop diverged.
DIVERGENCE_LIMIT = 1e7
#: Largest number of steps of a simulation ("absurdly many" beyond).
MAX_STEPS = 10_000_000


class DivergenceError(FloatingPointError):
    """The sampled closed loop blew up (raised instead of returning overflowed states).

    With the fully-connected law every agent feels N - 1 springs and dampers,
    so the loop gain grows with N; with the gains of Song et al. (2023),
    Table I, and dt = 0.1 s the sampled loop is unstable from about N = 18.
    """


@dataclass(frozen=True)
class FlockingGains:
    """Gains of the augmented Cucker-Smale law, eq. (6).

    Parameters
    ----------
    rho3 : float
        Velocity-consensus gain (1/s), positive.
    rho4 : float
        Distance-keeping gain, positive.
    rho5 : float
        Radial damping gain of ``phi2`` (1/s), positive.
    rho6 : float
        Spring gain of ``phi2`` (1/s^2), positive.
    beta : float
        Communication decay rate of ``phi1``, ``0 <= beta`` (stable for
        ``beta < 1/2``).
    R : float
        Spring rest length (m): the distance of two agents at rest, and for
        N > 2 fully-connected agents the bound on every agent's distance from
        the centre of mass (Sec. II-D).
    min_distance : float
        ``d_min`` (m) below which ``|p_ij|`` is replaced by ``d_min`` in the
        denominators (see the module docstring). Positive.
    """

    rho3: float
    rho4: float
    rho5: float
    rho6: float
    beta: float
    R: float
    min_distance: float = 1e-6

    def __post_init__(self) -> None:
        for name in ("rho3", "rho4", "rho5", "rho6", "R", "min_distance", "beta"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise TypeError(f"{name} must be a real number; got {type(value).__name__} {value!r}")
        for name in ("rho3", "rho4", "rho5", "rho6", "R", "min_distance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a positive number; got {value!r}")
        if not np.isfinite(self.beta) or self.beta < 0:
            raise ValueError(f"beta must be a non-negative number; got {self.beta!r}")


def phi1(p: ArrayLike, beta: float) -> np.ndarray:
    """Communication weight ``1 / (1 + |p|^2)^beta`` of eq. (6), shape ``(...)`` for ``p`` ``(..., n)``."""
    p = _vectors(p, "p")
    beta = check_positive(beta, "beta", allow_zero=True)
    with np.errstate(over="ignore"):
        return _finite_result(_phi1(p, beta), "phi1", "p")


def _phi1(p, beta):
    return (1.0 + np.einsum("...i,...i->...", p, p)) ** (-beta)


def phi2(p: ArrayLike, v: ArrayLike, gains: FlockingGains) -> np.ndarray:
    """Spring-damper weight of eq. (6), with ``|p|`` replaced by ``max(|p|, gains.min_distance)``.

    Parameters
    ----------
    p, v : (..., n) array_like
        Relative position ``p_ij`` (m) and velocity ``v_ij`` (m/s).

    Returns
    -------
    (...) ndarray
    """
    p, v = _pair_args(p, v, gains)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_phi2(p, v, gains), "phi2", "p, v")


def _phi2(p, v, gains):
    de = np.maximum(np.sqrt(np.einsum("...i,...i->...", p, p)), gains.min_distance)
    return gains.rho5 / (2 * de**2) * np.einsum("...i,...i->...", v, p) + gains.rho6 / (2 * de) * (de - gains.R)


def pair_term(p: ArrayLike, v: ArrayLike, gains: FlockingGains) -> np.ndarray:
    """Contribution of neighbour ``j`` to ``u_i`` for ``p = p_ij``, ``v = v_ij``.

    ``g = -rho3 phi1(p) v - rho4 phi2(p, v) p`` (eq. (6) with ``v_j - v_i = -v``
    and ``p_j - p_i = -p``). Odd: ``g(-p, -v) = -g(p, v)``.

    Parameters
    ----------
    p, v : (..., n) array_like

    Returns
    -------
    (..., n) ndarray
        Acceleration (m/s^2).
    """
    p, v = _pair_args(p, v, gains)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_pair_term(p, v, gains), "pair_term", "p, v")


def _pair_term(p, v, gains):
    return -gains.rho3 * _phi1(p, gains.beta)[..., None] * v - gains.rho4 * _phi2(p, v, gains)[..., None] * p


def pair_term_jacobian(p: ArrayLike, v: ArrayLike, gains: FlockingGains) -> np.ndarray:
    """Analytic Jacobian of :func:`pair_term` with respect to ``[p; v]``.

    Returns
    -------
    (..., n, 2n) ndarray
        ``[dg/dp, dg/dv]``. Even in ``(p, v)``.
    """
    p, v = _pair_args(p, v, gains)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_pair_term_jacobian(p, v, gains), "pair_term_jacobian", "p, v")


def _pair_term_jacobian(p, v, gains):
    n = p.shape[-1]
    eye = np.eye(n)
    d2 = np.einsum("...i,...i->...", p, p)
    d = np.sqrt(d2)
    far = (d > gains.min_distance)[..., None, None]
    de = np.maximum(d, gains.min_distance)[..., None, None]
    vp = np.einsum("...i,...i->...", v, p)[..., None, None]
    ppT = p[..., :, None] * p[..., None, :]
    pvT = p[..., :, None] * v[..., None, :]
    vpT = v[..., :, None] * p[..., None, :]
    f1 = _phi1(p, gains.beta)[..., None, None]
    c5 = gains.rho4 * gains.rho5 / 2
    c6 = gains.rho4 * gains.rho6 / 2
    # term -rho3 phi1(p) v
    dA_dp = 2 * gains.beta * gains.rho3 * f1 / (1 + d2[..., None, None]) * vpT
    dA_dv = -gains.rho3 * f1 * eye
    # term -c5 <v, p> p / de^2   (de = |p| when far, d_min otherwise)
    dB_dp = -c5 * (vp / de**2 * eye + pvT / de**2 - np.where(far, 2 * vp / de**4 * ppT, 0.0))
    dB_dv = -c5 * ppT / de**2
    # term -c6 (1 - R / de) p
    dC_dp = -c6 * (eye - gains.R / de * (eye - np.where(far, ppT / de**2, 0.0)))
    return np.concatenate([dA_dp + dB_dp + dC_dp, dA_dv + dB_dv], axis=-1)


def flocking_control(X: ArrayLike, gains: FlockingGains, adjacency: ArrayLike | None = None) -> np.ndarray:
    """Control of every agent from a common team state, eq. (6).

    Parameters
    ----------
    X : (..., N, 2n) array_like
        Team state, rows ``[p_i; v_i]``.
    gains : FlockingGains
    adjacency : (N, N) or (..., N, N) array_like, optional
        ``a_ij``; ``None`` means fully connected (every ``j != i``), the law
        that eq. (40) applies to an estimate.

    Returns
    -------
    U : (..., N, n) ndarray
        Accelerations (m/s^2).
    """
    X = _check_team(X, "X")
    _check_gains(gains)
    weights = _check_weights(adjacency, X.shape[-2], "adjacency", X.shape[:-2])
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_flocking_control(X, gains, weights), "flocking_control", "X")


def _flocking_control(X, gains, weights):
    diff = X[..., :, None, :] - X[..., None, :, :]  # x_i - x_j
    return _sum_pairs(diff, gains, weights, X.shape[-2])


def control_from_views(views: ArrayLike, gains: FlockingGains, adjacency: ArrayLike | None = None) -> np.ndarray:
    """Each agent's control from its own view of the team, eq. (7) or eq. (39).

    Parameters
    ----------
    views : (..., N, N, 2n) array_like
        ``views[..., i, j, :]``: agent ``i``'s measurement (eq. (7)) or estimate
        (eq. (39)) of agent ``j``'s state ``[p_j; v_j]``. Entries for ``j`` that
        agent ``i`` does not use (``a_ij = 0``) are ignored but must be finite.
    gains : FlockingGains
    adjacency : (N, N) or (..., N, N) array_like, optional
        ``None``: every ``j != i`` (virtual fully-connected network, eq. (39)).

    Returns
    -------
    U : (..., N, n) ndarray
        ``U[..., i, :] = u_i`` computed by agent ``i`` from ``views[..., i]``.
    """
    views = _float_array(views, "views")
    if views.ndim < 3 or views.shape[-3] != views.shape[-2] or views.shape[-1] % 2 or 0 in views.shape[-3:]:
        raise ValueError(f"views must have shape (..., N, N, 2n); got {views.shape}")
    if not np.all(np.isfinite(views)):
        raise ValueError("views contains NaN or infinite entries")
    _check_gains(gains)
    weights = _check_weights(adjacency, views.shape[-2], "adjacency", views.shape[:-3])
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_control_from_views(views, gains, weights), "control_from_views", "views")


def _control_from_views(views, gains, weights):
    N = views.shape[-2]
    own = np.diagonal(views, axis1=-3, axis2=-2)  # (..., 2n, N)
    own = np.moveaxis(own, -1, -2)  # (..., N, 2n): views[i, i]
    diff = own[..., :, None, :] - views  # x_hat_{i,i} - x_hat_{i,j}
    return _sum_pairs(diff, gains, weights, N)


def closed_loop_step(X: ArrayLike, dt: float, gains: FlockingGains) -> np.ndarray:
    """``f'(X) = (I_N kron A) X + (I_N kron B) U(X)`` of eq. (40), fully connected.

    ``A``, ``B`` are the double integrator of eq. (1) with step `dt` (s).

    Parameters
    ----------
    X : (..., N, 2n) array_like
    dt : float
        Sampling time (s), finite and > 0.
    gains : FlockingGains

    Returns
    -------
    (..., N, 2n) ndarray
    """
    X = _check_team(X, "X")
    dt = _check_dt(dt)
    _check_gains(gains)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_closed_loop_step(X, dt, gains), "closed_loop_step", "X")


def _closed_loop_step(X, dt, gains):
    n = X.shape[-1] // 2
    U = _flocking_control(X, gains, None)
    p, v = X[..., :n], X[..., n:]
    return np.concatenate([p + dt * v + 0.5 * dt**2 * U, v + dt * U], axis=-1)


def closed_loop_jacobian(X: ArrayLike, dt: float, gains: FlockingGains) -> np.ndarray:
    """Analytic Jacobian ``dF'/dX`` of eq. (40) (the matrix of eq. (38)).

    Parameters
    ----------
    X : (..., N, 2n) array_like
    dt : float
        Sampling time (s), finite and > 0.
    gains : FlockingGains

    Returns
    -------
    F : (..., 2nN, 2nN) ndarray
        Block ``(i, j)`` (size 2n) is ``delta_ij A + B dU_i/dx_j`` where
        ``dU_i/dx_j = -J(x_i - x_j)`` for ``j != i`` and
        ``dU_i/dx_i = sum_{j != i} J(x_i - x_j)``, ``J`` the pair Jacobian.
    """
    X = _check_team(X, "X")
    dt = _check_dt(dt)
    _check_gains(gains)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite_result(_closed_loop_jacobian(X, dt, gains), "closed_loop_jacobian", "X")


def _closed_loop_jacobian(X, dt, gains):
    N, m = X.shape[-2], X.shape[-1]
    n = m // 2
    # J(x_i - x_j) is even, so one evaluation per unordered pair i < j
    iu, ju = np.triu_indices(N, 1)
    diff = X[..., iu, :] - X[..., ju, :]
    J = _pair_term_jacobian(diff[..., :n], diff[..., n:], gains)  # (..., P, n, 2n)
    BJ = np.concatenate([0.5 * dt**2 * J, dt * J], axis=-2)  # B J: (..., P, 2n, 2n)
    blocks = np.zeros((*X.shape[:-2], N, N, m, m))
    blocks[..., iu, ju, :, :] = -BJ
    blocks[..., ju, iu, :, :] = -BJ
    A = np.block([[np.eye(n), dt * np.eye(n)], [np.zeros((n, n)), np.eye(n)]])
    idx = np.arange(N)
    blocks[..., idx, idx, :, :] = A - blocks.sum(axis=-3)
    return np.swapaxes(blocks, -3, -2).reshape(*X.shape[:-2], N * m, N * m)


@dataclass(frozen=True)
class FlockingRun:
    """Outcome of a flocking simulation.

    Attributes
    ----------
    t : (T+1,) ndarray
        Times (s).
    X : (..., T+1, N, 2n) ndarray
        True team states.
    adjacency : (..., T+1, N, N) ndarray of bool
        Proximity graph of the true positions at each step (who measures whom).
    """

    t: np.ndarray
    X: np.ndarray
    adjacency: np.ndarray


def simulate_measured_flocking(
    X0: ArrayLike,
    n_steps: int,
    dt: float,
    gains: FlockingGains,
    Q: ArrayLike,
    R: ArrayLike,
    rng: np.random.Generator | int,
    sensing_range: float | None,
) -> FlockingRun:
    """Conventional flocking from noisy measurements, eq. (7), on eq. (1).

    Each step, agent ``i`` measures itself and its current neighbours,
    ``z_{i,x_j} = x_j + nu_ij`` (eq. (2)), and applies eq. (7) to those
    measurements; the team then moves by eq. (1) with process noise.

    Parameters
    ----------
    X0 : (..., N, 2n) array_like
        Initial team states (leading axes: Monte Carlo runs).
    n_steps : int
        Number of steps T (1 to :data:`MAX_STEPS`).
    dt : float
        Sampling time (s), finite and > 0.
    gains : FlockingGains
    Q : (2n, 2n) array_like
        Process-noise covariance of one agent.
    R : (2n, 2n) or (2nN, 2nN) array_like
        Measurement-noise covariance: per measured agent (team ``I_N kron R``)
        or the paper's full ``R`` (see :func:`mascore.sensing.team_noise_covariance`).
    rng : numpy.random.Generator or int
    sensing_range : float or None
        ``r`` (m) of the proximity graph (case (i) of Fig. 5), finite and > 0;
        ``None`` for a fixed fully-connected network (case (ii)).

    Returns
    -------
    FlockingRun

    Raises
    ------
    DivergenceError
        If a state component exceeds ``DIVERGENCE_LIMIT`` (unstable sampled loop).
    """
    rng = check_generator(rng)
    X = _check_team(X0, "X0").copy()
    m = X.shape[-1]
    n, N = m // 2, X.shape[-2]
    n_steps = _check_steps(n_steps)
    dt = _check_dt(dt)
    _check_gains(gains)
    Lq = _chol(Q, "Q", m)
    team_noise_covariance(_float_array(R, "R"), N, m)  # validates R early
    if sensing_range is not None:
        sensing_range = _check_range(sensing_range, "use None for a fully connected network")
    batch = X.shape[:-2]
    Xs = np.empty((n_steps + 1, *X.shape))
    As = np.empty((n_steps + 1, *batch, N, N), dtype=bool)
    full = complete_graph(N).astype(bool)
    for k in range(n_steps + 1):
        A_k = full if sensing_range is None else proximity_graph(X[..., :n], sensing_range).astype(bool)
        Xs[k] = X
        As[k] = A_k
        if k == n_steps:
            break
        views, _ = measure(rng, X, A_k, R, allow_isolated=True)  # eq. (2)
        U = _control_from_views(views, gains, A_k)  # eq. (7)
        X = _propagate(X, U, dt) + rng.standard_normal((*batch, N, m)) @ Lq.T
        _check_divergence(X, k + 1, dt)
    t = dt * np.arange(n_steps + 1)
    return FlockingRun(t, np.moveaxis(Xs, 0, -3), np.moveaxis(As, 0, -3))


def flock_spread(X: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviation of positions and of velocities across the agents.

    ``std_p = sqrt(mean_i |p_i - mean_j p_j|^2)`` and likewise for velocities.

    Parameters
    ----------
    X : (..., N, 2n) array_like
        Team states; a NaN entry marks a missing state (e.g. the placeholder of
        a diverged run) and gives NaN statistics for that team. Infinite
        entries are refused.

    Returns
    -------
    std_p, std_v : (...) ndarrays
        In m and m/s.
    """
    X = _check_team(X, "X", allow_nan=True)
    n = X.shape[-1] // 2
    with np.errstate(over="ignore", invalid="ignore"):
        dev = X - X.mean(axis=-2, keepdims=True)
        sq = dev**2
        out = np.sqrt(sq[..., :n].sum(-1).mean(-1)), np.sqrt(sq[..., n:].sum(-1).mean(-1))
    _finite_where_input_is(out[0], X, "flock_spread")
    _finite_where_input_is(out[1], X, "flock_spread")
    return out


def max_distance_from_centre(X: ArrayLike) -> np.ndarray:
    """Largest distance (m) of an agent from the centre of mass, shape ``(...)``.

    A NaN entry of `X` marks a missing state (a diverged run's placeholder) and
    gives NaN for that team; infinite entries are refused.
    """
    X = _check_team(X, "X", allow_nan=True)
    n = X.shape[-1] // 2
    p = X[..., :n]
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.linalg.norm(p - p.mean(axis=-2, keepdims=True), axis=-1).max(axis=-1)
    _finite_where_input_is(out, X, "max_distance_from_centre")
    return out


# ----------------------------------------------------------------------------- private


def _sum_pairs(diff: np.ndarray, gains: FlockingGains, adjacency: np.ndarray | None, N: int) -> np.ndarray:
    """sum_j a_ij g(x_i - x_j) on checked arguments; `adjacency` a float or boolean (..., N, N) array or None."""
    n = diff.shape[-1] // 2
    g = _pair_term(diff[..., :n], diff[..., n:], gains)  # (..., N, N, n)
    if adjacency is None:
        weights = (~np.eye(N, dtype=bool)).astype(float)
    else:
        weights = np.asarray(adjacency, dtype=float)
        weights = weights * (~np.eye(N, dtype=bool))
    return np.einsum("...ij,...ijk->...ik", weights, g)


def _propagate(X: np.ndarray, U: np.ndarray, dt: float) -> np.ndarray:
    n = U.shape[-1]
    p, v = X[..., :n], X[..., n:]
    return np.concatenate([p + dt * v + 0.5 * dt**2 * U, v + dt * U], axis=-1)


def _check_divergence(X: np.ndarray, k: int, dt: float, what: str = "team state") -> None:
    if not np.all(np.abs(X) < DIVERGENCE_LIMIT):
        raise DivergenceError(
            f"the closed loop diverged: the {what} exceeded {DIVERGENCE_LIMIT:g} at step {k} (t = {k * dt:g} s); "
            "the sampled flocking law is unstable for these gains, dt and number of agents"
        )


def _check_team(X: ArrayLike, name: str, allow_nan: bool = False) -> np.ndarray:
    X = _float_array(X, name)
    if X.ndim < 2 or X.shape[-1] % 2 or X.shape[-1] == 0 or X.shape[-2] == 0:
        raise ValueError(f"{name} must have shape (..., N, 2n) with rows [p_i; v_i]; got {X.shape}")
    if allow_nan:
        if np.any(np.isinf(X)):
            raise ValueError(f"{name} contains infinite entries")
    elif not np.all(np.isfinite(X)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    return X


def _finite_where_input_is(out: np.ndarray, X: np.ndarray, what: str) -> None:
    """Overflow check of a statistic over the last two axes of X: finite wherever X[..., :, :] is."""
    known = np.isfinite(X).all(axis=(-1, -2))
    if not np.all(np.isfinite(out[known])):
        raise ValueError(f"{what} overflowed although X is finite: X holds values too large for floating "
                         "point; rescale it")


def _chol(C: ArrayLike, name: str, size: int) -> np.ndarray:
    C = check_covariance(_float_array(C, name), name, size=size)
    w, V = np.linalg.eigh(C)
    return V * np.sqrt(np.clip(w, 0, None))  # C = L L^T, works for semidefinite C


def _check_steps(n_steps: int) -> int:
    n_steps = check_positive_int(n_steps, "n_steps", minimum=1)
    if n_steps > MAX_STEPS:
        raise ValueError(f"n_steps = {n_steps} is more than MAX_STEPS = {MAX_STEPS}; run fewer steps")
    return n_steps




def _check_dt(dt: object) -> float:
    if isinstance(dt, np.ndarray) and dt.ndim == 0:
        dt = dt[()]
    return check_positive(dt, "dt", "s")


def _check_range(r: object, hint: str = "") -> float:
    if isinstance(r, np.ndarray) and r.ndim == 0:
        r = r[()]
    if isinstance(r, (int, float, np.integer, np.floating)) and not isinstance(r, bool) and np.isinf(r) and hint:
        raise ValueError(f"sensing_range must be a finite number > 0 m; got {r!r} ({hint})")
    return check_positive(r, "sensing_range", "m")


def _check_gains(gains: object) -> None:
    if not isinstance(gains, FlockingGains):
        raise TypeError(f"gains must be a mascore.flocking.FlockingGains; got {type(gains).__name__}")


def _vectors(x: ArrayLike, name: str) -> np.ndarray:
    x = _float_array(x, name)
    if x.ndim < 1 or x.shape[-1] == 0:
        raise ValueError(f"{name} must have shape (..., n) with n >= 1; got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    return x


def _pair_args(p: ArrayLike, v: ArrayLike, gains: object) -> tuple[np.ndarray, np.ndarray]:
    p, v = _vectors(p, "p"), _vectors(v, "v")
    try:
        np.broadcast_shapes(p.shape, v.shape)
    except ValueError:
        raise ValueError(f"v must have the shape of p {p.shape} (or broadcast against it); got {v.shape}") from None
    if v.shape[-1] != p.shape[-1]:
        raise ValueError(f"v must have the shape of p {p.shape}; got {v.shape}")
    _check_gains(gains)
    return p, v


def _check_weights(adjacency: ArrayLike | None, N: int, name: str, batch: tuple = ()) -> np.ndarray | None:
    """A (..., N, N) adjacency a_ij >= 0, finite (None passes through: fully connected)."""
    if adjacency is None:
        return None
    A = _float_array(adjacency, name)
    if A.ndim < 2 or A.shape[-2:] != (N, N):
        raise ValueError(f"{name} must have shape (..., {N}, {N}); got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    if np.any(A < 0):
        diag = np.diagonal(A, axis1=-2, axis2=-1)
        if np.all(diag >= 0) and np.any(diag > 0) and np.allclose(A.sum(axis=-1), 0.0):
            raise ValueError(f"{name} looks like a graph Laplacian (negative off-diagonal entries, rows summing "
                             "to zero); pass the adjacency matrix instead (A = diag(diag(L)) - L)")
        raise ValueError(f"{name} must have non-negative weights a_ij; smallest entry is {A.min():.3g}")
    try:
        np.broadcast_shapes(A.shape[:-2], batch)
    except ValueError:
        raise ValueError(f"{name} has batch axes {A.shape[:-2]} that do not match the team's {batch}") from None
    return A


def _finite_result(out, what: str, names: str):
    """Return `out` (an array or a tuple of arrays) if finite; else name the overflow."""
    arrays = out if isinstance(out, tuple) else (out,)
    if not all(np.all(np.isfinite(a)) for a in arrays):
        raise ValueError(f"{what} overflowed (NaN or inf in the result) although every input is finite: "
                         f"{names} hold values too large for floating point; rescale them")
    return out
