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

Conventions of the flocking functions
-------------------------------------
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

Input checks of the flocking functions
--------------------------------------
Every public function checks its arguments (finite entries, shapes, ``dt > 0``,
a :class:`FlockingGains`, non-negative adjacency weights -- a graph Laplacian
passed by mistake is named as such) and raises a ``ValueError`` or
``TypeError`` naming the argument, then runs plain code: each step of the law has
one implementation, these functions (the gains are a checked frozen
:class:`FlockingGains`, so a call checks only the states), and the simulator calls
them too. A self-loop ``a_ii`` is accepted and ignored: the pair term
of an agent with itself is exactly zero. One agent (``N = 1``) or an isolated
agent feels no pair term: its control is zero. A result that overflows (inputs
too large for floating point) raises instead of returning NaN or inf.

Symbols follow the paper; equations are cited as ``eq. (N)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from . import _flocking_core as _core
from ._flocking_core import DIVERGENCE_LIMIT, MAX_STEPS, FlockingGains
from ._flocking_core import check_dt as _check_dt
from ._flocking_core import check_gains as _check_gains
from ._flocking_core import check_pair_args as _pair_args
from ._flocking_core import check_range as _check_range
from ._flocking_core import check_steps as _check_steps
from ._flocking_core import check_team as _check_team
from ._flocking_core import check_vectors as _vectors
from ._flocking_core import check_weights as _check_weights
from ._flocking_core import finite_where_input_is as _finite_where_input_is
from ._flocking_core import float_array as _float_array
from ._sensing_kernels import masked_measurement
from ._validation import check_generator, check_positive, finite_result
from .graphs import complete_graph, proximity_graph
from .sensing import team_noise_covariance

__all__ = [
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


def phi1(p: ArrayLike, beta: float) -> np.ndarray:
    """Communication weight ``1 / (1 + |p|^2)^beta`` of eq. (6).

    Parameters
    ----------
    p : (..., n) array_like
        Relative position (m).
    beta : float
        Decay rate, >= 0.

    Returns
    -------
    (...) ndarray
        The weight, 1 at ``p = 0``.

    Examples
    --------
    >>> from mascore import flocking
    >>> float(flocking.phi1([3.0, 4.0], beta=0.5))            # 1 / sqrt(1 + 25)
    0.19611613513818404
    """
    p = _vectors(p, "p")
    beta = check_positive(beta, "beta", allow_zero=True)
    with np.errstate(over="ignore"):
        return finite_result("phi1 of p", _phi1_of(np.einsum("...i,...i->...", p, p), beta))


def phi2(p: ArrayLike, v: ArrayLike, gains: FlockingGains) -> np.ndarray:
    """Spring-damper weight of eq. (6), with ``|p|`` replaced by ``max(|p|, gains.min_distance)``.

    Parameters
    ----------
    p : (..., n) array_like
        Relative position ``p_ij`` (m).
    v : (..., n) array_like
        Relative velocity ``v_ij`` (m/s).
    gains : FlockingGains
        The gains of eq. (6).

    Returns
    -------
    (...) ndarray
        The weight.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> float(flocking.phi2([120.0, 0.0], [0.0, 0.0], gains))       # at rest length, no relative motion
    0.0
    """
    p, v = _pair_args(p, v, gains)
    with np.errstate(over="ignore", invalid="ignore"):
        return finite_result("phi2 of p, v", _phi2_of(p, v, gains))


def pair_term(p: ArrayLike, v: ArrayLike, gains: FlockingGains) -> np.ndarray:
    """Contribution of neighbour ``j`` to ``u_i`` for ``p = p_ij``, ``v = v_ij``.

    ``g = -rho3 phi1(p) v - rho4 phi2(p, v) p`` (eq. (6) with ``v_j - v_i = -v``
    and ``p_j - p_i = -p``). Odd: ``g(-p, -v) = -g(p, v)``.

    Parameters
    ----------
    p : (..., n) array_like
        Relative position (m).
    v : (..., n) array_like
        Relative velocity (m/s).
    gains : FlockingGains
        The gains of eq. (6).

    Returns
    -------
    (..., n) ndarray
        Acceleration (m/s^2).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> g = flocking.pair_term(np.array([50.0, 0.0]), np.array([1.0, 0.0]), gains)
    >>> bool(np.allclose(flocking.pair_term(-np.array([50.0, 0.0]), -np.array([1.0, 0.0]), gains), -g))   # odd
    True
    """
    p, v = _pair_args(p, v, gains)
    with np.errstate(over="ignore", invalid="ignore"):
        return finite_result("pair_term of p, v", _pair_terms(p, v, gains))


def pair_term_jacobian(p: ArrayLike, v: ArrayLike, gains: FlockingGains) -> np.ndarray:
    """Analytic Jacobian of :func:`pair_term` with respect to ``[p; v]``.

    Parameters
    ----------
    p : (..., n) array_like
        Relative position (m).
    v : (..., n) array_like
        Relative velocity (m/s).
    gains : FlockingGains
        The gains of eq. (6).

    Returns
    -------
    (..., n, 2n) ndarray
        ``[dg/dp, dg/dv]``. Even in ``(p, v)``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> p, v, h = np.array([50.0, 10.0]), np.array([1.0, -1.0]), 1e-6
    >>> J = flocking.pair_term_jacobian(p, v, gains)
    >>> fd = (flocking.pair_term(p + [h, 0.0], v, gains) - flocking.pair_term(p - [h, 0.0], v, gains)) / (2 * h)
    >>> bool(np.allclose(J[:, 0], fd, atol=1e-7))               # matches finite differences
    True
    """
    p, v = _pair_args(p, v, gains)
    n = p.shape[-1]
    eye = np.eye(n)
    with np.errstate(over="ignore", invalid="ignore"):
        d2 = np.einsum("...i,...i->...", p, p)
        d = np.sqrt(d2)
        far = (d > gains.min_distance)[..., None, None]
        de = np.maximum(d, gains.min_distance)[..., None, None]
        vp = np.einsum("...i,...i->...", v, p)[..., None, None]
        ppT = p[..., :, None] * p[..., None, :]
        pvT = p[..., :, None] * v[..., None, :]
        vpT = v[..., :, None] * p[..., None, :]
        f1 = _phi1_of(np.einsum("...i,...i->...", p, p), gains.beta)[..., None, None]
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
        J = np.concatenate([dA_dp + dB_dp + dC_dp, dA_dv + dB_dv], axis=-1)
    return finite_result("pair_term_jacobian of p, v", J)


def flocking_control(X: ArrayLike, gains: FlockingGains, adjacency: ArrayLike | None = None) -> np.ndarray:
    """Control of every agent from a common team state, eq. (6).

    Parameters
    ----------
    X : (..., N, 2n) array_like
        Team state, rows ``[p_i; v_i]``.
    gains : FlockingGains
        The gains of eq. (6).
    adjacency : (N, N) or (..., N, N) array_like, optional
        ``a_ij``; ``None`` means fully connected (every ``j != i``), the law
        that eq. (40) applies to an estimate.

    Returns
    -------
    U : (..., N, n) ndarray
        Accelerations (m/s^2).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])   # [p, v] of 3 agents
    >>> U = flocking.flocking_control(X, gains)
    >>> U.shape, bool(np.allclose(U.sum(axis=0), 0))           # pairwise terms cancel in the sum
    ((3, 2), True)
    """
    X = _check_team(X, "X")
    _check_gains(gains)
    weights = _check_weights(adjacency, X.shape[-2], "adjacency", X.shape[:-2])
    with np.errstate(over="ignore", invalid="ignore"):
        return finite_result("flocking_control of X", _sum_pairs(_differences(X), gains, weights, X.shape[-2]))


def control_from_views(views: ArrayLike, gains: FlockingGains, adjacency: ArrayLike | None = None) -> np.ndarray:
    """Each agent's control from its own view of the team, eq. (7) or eq. (39).

    Parameters
    ----------
    views : (..., N, N, 2n) array_like
        ``views[..., i, j, :]``: agent ``i``'s measurement (eq. (7)) or estimate
        (eq. (39)) of agent ``j``'s state ``[p_j; v_j]``. Entries for ``j`` that
        agent ``i`` does not use (``a_ij = 0``) are ignored but must be finite.
    gains : FlockingGains
        The gains of eq. (6).
    adjacency : (N, N) or (..., N, N) array_like, optional
        ``None``: every ``j != i`` (virtual fully-connected network, eq. (39)).

    Returns
    -------
    U : (..., N, n) ndarray
        ``U[..., i, :] = u_i`` computed by agent ``i`` from ``views[..., i]``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])   # [p, v] of 3 agents
    >>> views = np.broadcast_to(X, (3, 3, 4))                  # everyone sees the true states
    >>> bool(np.allclose(flocking.control_from_views(views, gains), flocking.flocking_control(X, gains)))
    True
    """
    views = _float_array(views, "views")
    if views.ndim < 3 or views.shape[-3] != views.shape[-2] or views.shape[-1] % 2 or 0 in views.shape[-3:]:
        raise ValueError(f"views must have shape (..., N, N, 2n); got {views.shape}")
    if not np.all(np.isfinite(views)):
        raise ValueError("views contains NaN or infinite entries")
    _check_gains(gains)
    weights = _check_weights(adjacency, views.shape[-2], "adjacency", views.shape[:-3])
    N = views.shape[-2]
    own = np.moveaxis(np.diagonal(views, axis1=-3, axis2=-2), -1, -2)  # (..., N, 2n): views[i, i]
    with np.errstate(over="ignore", invalid="ignore"):
        diff = own[..., :, None, :] - views  # x_hat_{i,i} - x_hat_{i,j}
        return finite_result("control_from_views of views", _sum_pairs(diff, gains, weights, N))


def closed_loop_step(X: ArrayLike, dt: float, gains: FlockingGains) -> np.ndarray:
    """``f'(X) = (I_N kron A) X + (I_N kron B) U(X)`` of eq. (40), fully connected.

    ``A``, ``B`` are the double integrator of eq. (1) with step `dt` (s).

    Parameters
    ----------
    X : (..., N, 2n) array_like
        Team states.
    dt : float
        Sampling time (s), finite and > 0.
    gains : FlockingGains
        The gains of eq. (6).

    Returns
    -------
    (..., N, 2n) ndarray
        The next team states.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])   # [p, v] of 3 agents
    >>> flocking.closed_loop_step(X, 0.1, gains).shape
    (3, 4)
    """
    X = _check_team(X, "X")
    dt = _check_dt(dt)
    _check_gains(gains)
    with np.errstate(over="ignore", invalid="ignore"):
        U = _sum_pairs(_differences(X), gains, None, X.shape[-2])  # the fully-connected law
        return finite_result("closed_loop_step of X", _core.propagate(X, U, dt))


def closed_loop_jacobian(X: ArrayLike, dt: float, gains: FlockingGains) -> np.ndarray:
    """Analytic Jacobian ``dF'/dX`` of eq. (40) (the matrix of eq. (38)).

    Parameters
    ----------
    X : (..., N, 2n) array_like
        Team states where the Jacobian is taken.
    dt : float
        Sampling time (s), finite and > 0.
    gains : FlockingGains
        The gains of eq. (6).

    Returns
    -------
    F : (..., 2nN, 2nN) ndarray
        Block ``(i, j)`` (size 2n) is ``delta_ij A + B dU_i/dx_j`` where
        ``dU_i/dx_j = -J(x_i - x_j)`` for ``j != i`` and
        ``dU_i/dx_i = sum_{j != i} J(x_i - x_j)``, ``J`` the pair Jacobian.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])   # [p, v] of 3 agents
    >>> F = flocking.closed_loop_jacobian(X, 0.1, gains)
    >>> h, e = 1e-6, np.zeros(12); e[0] = 1.0
    >>> fd = (flocking.closed_loop_step(X + h * e.reshape(3, 4), 0.1, gains)
    ...       - flocking.closed_loop_step(X - h * e.reshape(3, 4), 0.1, gains)).ravel() / (2 * h)
    >>> bool(np.allclose(F[:, 0], fd, atol=1e-6))
    True
    """
    X = _check_team(X, "X")
    dt = _check_dt(dt)
    _check_gains(gains)
    N, m = X.shape[-2:]
    n = m // 2
    with np.errstate(over="ignore", invalid="ignore"):
        G = _core.control_and_jacobian(X, gains, with_control=False)[1]  # (..., N, n, N, m), du_i/dx_j
        F = np.empty((*X.shape[:-2], N, m, N, m))
        np.multiply(G, 0.5 * dt**2, out=F[..., :n, :, :])
        np.multiply(G, dt, out=F[..., n:, :, :])
        A = np.block([[np.eye(n), dt * np.eye(n)], [np.zeros((n, n)), np.eye(n)]])
        diag = np.arange(N)
        F[..., diag, :, diag, :] += A
    return finite_result("closed_loop_jacobian of X", F.reshape(*X.shape[:-2], N * m, N * m))


@dataclass(frozen=True)
class FlockingRun:
    """Outcome of a flocking simulation.

    A run's output: its arrays are the caller's, writeable and shared with no model or filter.

    Parameters
    ----------
    t : (T+1,) ndarray
        Times (s).
    X : (..., T+1, N, 2n) ndarray
        True team states.
    adjacency : (..., T+1, N, N) ndarray of bool
        Proximity graph of the true positions at each step (who measures whom).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])   # [p, v] of 3 agents
    >>> run = flocking.simulate_measured_flocking(X, 20, 0.1, gains, 0.01 * np.eye(4), np.eye(4), 0, 150.0)
    >>> run.X.shape, run.adjacency.shape
    ((21, 3, 4), (21, 3, 3))
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
        The gains of eq. (6).
    Q : (2n, 2n) array_like
        Process-noise covariance of one agent.
    R : (2n, 2n) or (2nN, 2nN) array_like
        Measurement-noise covariance: per measured agent (team ``I_N kron R``)
        or the paper's full ``R`` (see :func:`mascore.sensing.team_noise_covariance`).
    rng : numpy.random.Generator or int
        Source of process and measurement noise.
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

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import flocking
    >>> gains = flocking.FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])   # [p, v] of 3 agents
    >>> run = flocking.simulate_measured_flocking(X, 600, 0.1, gains, 0.01 * np.eye(4), np.eye(4), 0, 150.0)
    >>> std_p, std_v = flocking.flock_spread(run.X[-1])
    >>> bool(std_v < 1.0)                                       # velocities agree
    True
    """
    rng = check_generator(rng)
    X = _check_team(X0, "X0").copy()
    m = X.shape[-1]
    n, N = m // 2, X.shape[-2]
    n_steps = _check_steps(n_steps)
    dt = _check_dt(dt)
    _check_gains(gains)
    Lq = _core.noise_factor(Q, "Q", m)
    R_team = team_noise_covariance(_float_array(R, "R"), N, m)  # checked once; the loop runs the kernels
    if sensing_range is not None:
        sensing_range = _check_range(sensing_range, "use None for a fully connected network")
    batch = X.shape[:-2]
    Xs = np.empty((n_steps + 1, *X.shape))
    As = np.empty((n_steps + 1, *batch, N, N), dtype=bool)
    full = complete_graph(N).astype(bool)
    closed = np.eye(N, dtype=bool)  # every agent measures itself
    for k in range(n_steps + 1):
        A_k = full if sensing_range is None else proximity_graph(X[..., :n], sensing_range).astype(bool)
        Xs[k] = X
        As[k] = A_k
        if k == n_steps:
            break
        views, _ = masked_measurement(rng, X, A_k | closed, R_team)  # eq. (2), closed neighbourhoods
        U = control_from_views(views, gains, A_k)  # eq. (7)
        X = _core.propagate(X, U, dt) + rng.standard_normal((*batch, N, m)) @ Lq.T
        _core.check_divergence(X, k + 1, dt)
    t = dt * np.arange(n_steps + 1)
    return FlockingRun(t, np.moveaxis(Xs, 0, -3), np.moveaxis(As, 0, -3))


def flock_spread(X: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviation of positions and of velocities across the agents.

    ``std_p = sqrt(mean_i |p_i - mean_j p_j|^2)`` and likewise for velocities.

    Parameters
    ----------
    X : (..., N, 2n) array_like
        Team states (m, m/s); a team whose entries are *all* NaN marks a missing
        team (the placeholder of a diverged run) and gives NaN statistics for
        that team. A team with only some NaN entries, or any infinite entry, is
        refused (``ValueError`` naming `X`).

    Returns
    -------
    std_p, std_v : (...) ndarrays
        In m and m/s.

    Examples
    --------
    >>> from mascore import flocking
    >>> std_p, std_v = flocking.flock_spread([[0.0, 0.0, 1.0, 0.0], [2.0, 0.0, 1.0, 0.0]])
    >>> float(std_p), float(std_v)
    (1.0, 0.0)
    """
    X = _check_missing_teams(_check_team(X, "X", allow_nan=True))
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

    A team of `X` whose entries are all NaN marks a missing team (a diverged
    run's placeholder) and gives NaN for that team; a team with only some NaN
    entries, or an infinite entry, is refused.

    Parameters
    ----------
    X : (..., N, 2n) array_like
        Team states.

    Returns
    -------
    (...) ndarray
        The largest distance (m).

    Examples
    --------
    >>> from mascore import flocking
    >>> float(flocking.max_distance_from_centre([[0.0, 0.0, 0.0, 0.0], [2.0, 0.0, 0.0, 0.0]]))
    1.0
    """
    X = _check_missing_teams(_check_team(X, "X", allow_nan=True))
    n = X.shape[-1] // 2
    p = X[..., :n]
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.linalg.norm(p - p.mean(axis=-2, keepdims=True), axis=-1).max(axis=-1)
    _finite_where_input_is(out, X, "max_distance_from_centre")
    return out


def _check_missing_teams(X: np.ndarray) -> np.ndarray:
    """Refuse a team ``X[..., :, :]`` with some but not all entries NaN (only a whole team may be missing)."""
    nan = np.isnan(X)
    if nan.any():
        partial = nan.any(axis=(-1, -2)) & ~nan.all(axis=(-1, -2))
        if partial.any():
            where = tuple(int(v) for v in np.argwhere(partial)[0])
            raise ValueError(
                f"X contains NaN entries in team {where if where else '(the only one)'} beside finite ones: only a "
                "team whose entries are all NaN is read as missing (a diverged run's placeholder)"
            )
    return X


# ----------------------------------------------------------------------------- the law's plain math (checked input)


def _phi1_of(d2: np.ndarray, beta: float) -> np.ndarray:
    """``phi1`` from the squared distance ``d2 = |p|^2``."""
    return (1.0 + d2) ** (-beta)


def _phi2_of(p: np.ndarray, v: np.ndarray, gains: FlockingGains) -> np.ndarray:
    """``phi2(p, v)`` of eq. (6) with ``|p|`` replaced by ``max(|p|, d_min)``, for checked `p`, `v` ``(..., n)``."""
    de = np.maximum(np.sqrt(np.einsum("...i,...i->...", p, p)), gains.min_distance)
    return gains.rho5 / (2 * de**2) * np.einsum("...i,...i->...", v, p) + gains.rho6 / (2 * de) * (de - gains.R)


def _pair_terms(p: np.ndarray, v: np.ndarray, gains: FlockingGains) -> np.ndarray:
    """``g = -rho3 phi1(p) v - rho4 phi2(p, v) p`` for checked `p`, `v` ``(..., n)`` (every pair at once)."""
    f1 = _phi1_of(np.einsum("...i,...i->...", p, p), gains.beta)
    return -gains.rho3 * f1[..., None] * v - gains.rho4 * _phi2_of(p, v, gains)[..., None] * p


def _differences(X: np.ndarray) -> np.ndarray:
    """``x_i - x_j`` of a team state ``(..., N, 2n)``: ``(..., N, N, 2n)``."""
    return X[..., :, None, :] - X[..., None, :, :]


def _sum_pairs(diff: np.ndarray, gains: FlockingGains, adjacency: np.ndarray | None, N: int) -> np.ndarray:
    """``sum_j a_ij g(x_i - x_j)`` from ``diff[..., i, j, :] = x_i - x_j`` (``None``: every ``j != i``)."""
    n = diff.shape[-1] // 2
    g = _pair_terms(diff[..., :n], diff[..., n:], gains)  # (..., N, N, n)
    if adjacency is None:
        weights = (~np.eye(N, dtype=bool)).astype(float)
    else:
        weights = np.asarray(adjacency, dtype=float)
        weights = weights * (~np.eye(N, dtype=bool))
    return np.einsum("...ij,...ijk->...ik", weights, g)
