"""Whole-team Kalman filters run by every agent (Song et al. 2023, Sec. III.A, IV).

Every agent ``i`` of a team of ``N`` linear agents estimates the *whole* team
state ``X`` (size ``M = m N``) from its own local measurements only (eq. (3)):
no estimate is exchanged. Two closed loops are covered.

**Measurement-based control** (eqs. (8)-(20)). The agents steer with raw
measurements (eq. (5)); agent ``i`` predicts with its own guess of the team's
control (eqs. (12)-(14)), ``X̂_i^- = F_1 X̂_i`` with
``F_1 = I_N ⊗ A - L ⊗ BK`` (eq. (11)), and adds the control-noise term of
eq. (15) to the covariance. Each agent only needs its own ``Σ_i``.

**Estimation-based control** (eqs. (21)-(34)). The agents steer with their own
estimates (eq. (21)), so the true team evolves as
``X+ = F_1 X + F_2 e + w`` (eq. (28)) with the *augmented* error
``e = [e_1; ...; e_N]`` and ``F_2 = (I_N ⊗ BK) L'``. Agent ``i``'s prediction
error is ``e_i^- = F_1 e_i + F_2 e + w``, so every agent must propagate the
full ``N M x N M`` covariance ``Σ`` of ``e`` with all cross-covariances
``Σ_ij`` (eqs. (29)-(34)); by Remark 4 it is the same for every agent.

Implementation (the "structured" path)
--------------------------------------
* Masks instead of ragged selection matrices: ``H_i^T H_i = diag(S_i) ⊗ I_m``
  and the gain ``G_i H_i = Σ^- D (D (Σ^- + R) D + I - D)^{-1} D`` with
  ``D = diag(S_i) ⊗ I_m``, so all agents (and Monte Carlo runs) update in
  one batched call.
* Kronecker factor: for the double integrator with ``Q``, ``R`` and the
  initial covariance of the form ``X̄ ⊗ I_n`` (per spatial axis), every
  covariance stays ``Σ̄ ⊗ I_n``; the recursion runs on ``Σ̄``, ``n`` times
  smaller per side (8x fewer flops in the plane).
* Tensor form of the augmented prediction: with ``e[i, j]`` agent ``i``'s error
  on agent ``j``, ``e^-[i, j] = A e[i, j] + BK ((L e)[j, j] - (L e)[i, j])``
  where ``(L e)[i, j] = sum_l L_jl e[i, l]``, i.e. ``e^-[i] = F_1 e[i] + F_2 e``:
  one ``m N x m N`` product per agent block plus a term shared by all blocks.
  Applying it to ``Σ`` costs ``O(N^5 m^3)`` in BLAS-friendly products instead
  of the ``O(N^6 m^3)`` of dense products with ``Φ``.
* The covariance recursion does not depend on the noise realization: for a
  fixed topology one ``Σ`` (batch axis of length 1) serves every Monte Carlo
  run, while the means carry a run axis.

Checked once, then stepped
--------------------------
:class:`TeamFilterModel` checks ``A``, ``BK``, ``Q``, ``R`` when it is built and
keeps read-only copies. :class:`TeamFilter` (and :class:`CentralizedTeamFilter`)
checks the initial state once and then owns it: a step checks only what
changes (shapes, mask values) and tests its result for NaN/inf. It keeps the
``Φ`` blocks of its topology and its work arrays, and updates a large
augmented covariance in place; filters share nothing, so independent filters
may run in parallel threads. The plain-array functions (:func:`eb_predict`,
:func:`eb_update`, :func:`mb_predict`, ...) run the same steps on a filter
built for the call, after checking every argument in full on every call
(an eigenvalue test of the covariance): convenient for one step, slow in a loop.

A plain implementation written straight from eqs. (29)-(34) with explicit
``F_1``, ``F_2``, ``H_i`` and ``G_i`` (``mascore._kf_reference``) is the
reference for the tests and the benchmark. This module also has a
centralized Kalman filter over all agents' measurements
(:func:`centralized_update`), the observability test of system (43) and the
Lyapunov quantities of Theorem 1 (eqs. (45), (49)).

Shapes: ``X̂`` is ``(runs, N, N, m)`` (run, observer ``i``, target ``j``,
state), reduced covariances are ``(batch, N, M_r, M_r)`` per agent or
``(batch, N M_r, N M_r)`` augmented, with ``batch`` either 1 (shared) or
``runs``. (``B`` is always the agents' input matrix.)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ._masked_gain import masked_gain, observed_indices
from ._systems import design_args, full_state_only
from ._validation import (
    Frozen,
    as_matrix,
    check_covariance,
    check_laplacian,
    check_positive,
    check_positive_int,
    check_square,
    finite_result,
    frozen_copy,
    state_view,
    symmetric_part,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .graphs import laplacian as graph_laplacian
from .sensing import (
    _check_adjacency,
    _check_flag,
    _check_mask_values,
    sensing_mask,
    team_noise_covariance,
)

__all__ = [
    "TeamFilterModel",
    "team_filter_model",
    "TeamFilter",
    "CentralizedTeamFilter",
    "closed_loop_matrices",
    "reduce_covariance",
    "expand_covariance",
    "agent_update",
    "mb_predict",
    "mb_update",
    "eb_initial_covariance",
    "eb_predict",
    "eb_update",
    "agent_covariances",
    "centralized_predict",
    "centralized_update",
    "observable_agents",
    "require_observable",
    "lyapunov_v",
    "team_nees",
    "f2_cross",
    "theorem1_min_eigenvalues",
]


# ----------------------------------------------------------------------------
# model
# ----------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class TeamFilterModel(Frozen):
    """What every agent knows (Assumption 1): ``A``, ``BK``, ``Q``, ``R``, checked once when built.

    Build it with :func:`team_filter_model` (which also finds the Kronecker factor) or
    directly. The constructor checks everything once (shapes, finiteness, symmetry,
    definiteness, the Kronecker form) and stores read-only copies, so no later change
    can slip past the check: writing into ``model.R_r`` raises. The ``*_r`` fields are
    the per-axis Kronecker factors (``A = A_r ⊗ I_kron`` etc.), derived from the full
    matrices; ``kron = 1`` means no reduction.

    Parameters
    ----------
    A : (m, m) array_like
        Agent transition matrix.
    BK : (m, m) array_like
        Product of the input matrix and the consensus gain.
    Q : (m, m) array_like
        Per-agent process-noise covariance, symmetric positive semidefinite.
    R : (m N, m N) array_like
        Covariance of one observer's noise vector ``nu_i``, symmetric positive definite.
    n_agents : int
        N >= 2.
    kron : int
        Kronecker factor used by the structured recursions: ``A``, ``BK``, ``Q`` and
        ``R`` must all be of the form ``X_r ⊗ I_kron``.

    Attributes
    ----------
    A_r, BK_r, Q_r, R_r : ndarray
        The reduced matrices (read-only views of the full ones).

    Raises
    ------
    ValueError
        Shapes that do not fit together, non-finite entries, a covariance that is not
        symmetric positive (semi)definite, or a matrix not of the form ``X_r ⊗ I_kron``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> model.n_agents, model.kron
    (3, 1)
    >>> model.R_r.flags.writeable                               # checked once, then read-only
    False
    """

    A: np.ndarray
    BK: np.ndarray
    Q: np.ndarray
    R: np.ndarray
    n_agents: int
    kron: int = 1
    A_r: np.ndarray = field(init=False, repr=False, compare=False)
    BK_r: np.ndarray = field(init=False, repr=False, compare=False)
    Q_r: np.ndarray = field(init=False, repr=False, compare=False)
    R_r: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        A = check_square(_float_array(self.A, "A"), "A")
        m = A.shape[0]
        BK = check_square(_float_array(self.BK, "BK"), "BK", m)
        Q = check_covariance(_float_array(self.Q, "Q"), "Q", size=m)
        if Q.ndim != 2:
            raise ValueError(f"Q must be a single ({m}, {m}) matrix; got shape {Q.shape}")
        n_agents = check_positive_int(self.n_agents, "n_agents", minimum=2)
        R = check_covariance(_float_array(self.R, "R"), "R", size=m * n_agents, definite=True)
        if R.ndim != 2:
            raise ValueError(f"R must be a single ({m * n_agents}, {m * n_agents}) matrix; got shape {R.shape}")
        kron = check_positive_int(self.kron, "kron")
        if m % kron:
            raise ValueError(f"kron must divide the agent state size m = {m}; got kron={kron}")
        full = {"A": frozen_copy(A), "BK": frozen_copy(BK), "Q": frozen_copy(Q), "R": frozen_copy(R)}
        for name, M in full.items():
            red = _kron_factor(M, kron)
            if red is None:
                raise ValueError(f"{name} is not of the form {name}_r ⊗ I_{kron} (kron={kron}); "
                                 "build the model with team_filter_model, which finds the factor")
            self._set(**{name: M, f"{name}_r": red})  # a view of the read-only copy: read-only too
        self._set(n_agents=n_agents, kron=kron)

    @property
    def m(self) -> int:
        """Agent state dimension."""
        return self.A.shape[0]

    @property
    def m_r(self) -> int:
        """Reduced agent state dimension ``m / kron``."""
        return self.A_r.shape[0]

    @property
    def M_r(self) -> int:
        """Reduced team state dimension ``N m_r``."""
        return self.n_agents * self.m_r


def team_filter_model(
    A: ArrayLike,
    B: ArrayLike | None = None,
    K: ArrayLike | None = None,
    Q: ArrayLike | None = None,
    R: ArrayLike | None = None,
    n_agents: int | None = None,
    reduce: bool = True,
) -> TeamFilterModel:
    """Validate the team model and find its Kronecker factor.

    Parameters
    ----------
    A : (m, m) array_like, or LTIAgent or StateSpace
        Agent transition matrix (eq. (1)), or the discrete-time agent as a system (an
        :class:`~mascore.agents.LTIAgent` or a discrete python-control ``StateSpace``), then
        without B: ``team_filter_model(agent, K, Q, R, n_agents)``.
    B : (m, p) array_like, optional
        Agent input matrix (not with a system).
    K : (p, m) array_like
        Consensus gain of eq. (4).
    Q : (m, m) array_like
        Per-agent process-noise covariance, symmetric PSD.
    R : (m, m) or (m N, m N) array_like
        Measurement-noise covariance per measured agent, or of the whole
        vector ``nu_i`` (the paper's ``R``); symmetric positive definite.
    n_agents : int
        N >= 2.
    reduce : bool
        Look for a factor ``A = A_r ⊗ I_k`` shared by ``A, BK, Q, R`` (true by
        default); ``False`` forces the unreduced recursion.

    Returns
    -------
    TeamFilterModel
        The validated model with its Kronecker factor.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, rendezvous
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(2, 0.1)                       # planar: the x and y axes decouple
    >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 2), np.eye(4),
    ...                               np.eye(4), n_agents=5)
    >>> model.kron, model.M_r                                   # the recursions run on one axis
    (2, 10)
    """
    A, B, (K, Q, R, n_agents), _ = design_args("team_filter_model", A, B, dict(K=K, Q=Q, R=R, n_agents=n_agents), None,
                                               time="discrete")
    A = check_square(_float_array(A, "A"), "A")
    m = A.shape[0]
    if m == 0:
        raise ValueError("A must be at least 1 x 1 (an agent with no state)")
    B = as_matrix(_float_array(B, "B"), "B", (m, None))
    K = as_matrix(_float_array(K, "K"), "K", (B.shape[1], m))
    Q = check_covariance(_float_array(Q, "Q"), "Q", size=m)
    n_agents = check_positive_int(n_agents, "n_agents", minimum=2)
    _check_flag(reduce, "reduce")
    R_arr = _float_array(R, "R")
    if R_arr.ndim == 2 and R_arr.shape[0] == R_arr.shape[1] and 0 < R_arr.shape[0] < m:  # partial sensing
        raise ValueError(full_state_only(m, R_arr.shape))
    R_team = team_noise_covariance(R, n_agents, m)
    check_covariance(R_team, "R", definite=True)
    BK = B @ K
    kron = 1
    if reduce:
        for k in range(m, 1, -1):
            if m % k == 0 and all(_kron_factor(X, k) is not None for X in (A, BK, Q, R_team)):
                kron = k
                break
    return TeamFilterModel(A=A, BK=BK, Q=Q, R=R_team, n_agents=int(n_agents), kron=kron)



def closed_loop_matrices(A: ArrayLike, BK: ArrayLike, laplacian: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Dense ``F_1 = I_N ⊗ A - L ⊗ BK`` (eq. (11)) and ``F_2 = (I_N ⊗ BK) L'`` (eq. (28)).

    Parameters
    ----------
    A, BK : (m, m) array_like
        Agent transition matrix and input matrix times gain.
    laplacian : (N, N) array_like
        Graph Laplacian ``L = D - A`` (rows summing to zero, off-diagonal
        entries <= 0; directed graphs allowed): pass
        ``mascore.graphs.laplacian(adjacency)``, not the adjacency.

    Returns
    -------
    F1 : (m N, m N) ndarray
    F2 : (m N, m N^2) ndarray
        ``L' = diag(L_1 ⊗ I_m, ..., L_N ⊗ I_m)`` with ``L_i`` the i-th row.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> F1, F2 = dkf.closed_loop_matrices(agent.A, agent.B @ K, Lap)
    >>> F1.shape, F2.shape
    ((6, 6), (6, 18))
    """
    A = check_square(_float_array(A, "A"), "A")
    BK = check_square(_float_array(BK, "BK"), "BK", A.shape[0])
    L = check_laplacian(_float_array(laplacian, "laplacian"), "laplacian")
    if L.shape[0] == 0 or A.shape[0] == 0:
        raise ValueError(f"laplacian and A must be at least 1 x 1; got {L.shape} and {A.shape}")
    N, m = L.shape[0], A.shape[0]
    F1 = np.kron(np.eye(N), A) - np.kron(L, BK)
    Lp = np.zeros((m * N, m * N * N))
    for i in range(N):
        Lp[i * m:(i + 1) * m, i * m * N:(i + 1) * m * N] = np.kron(L[i:i + 1], np.eye(m))
    F2 = np.kron(np.eye(N), BK) @ Lp
    return F1, F2


def reduce_covariance(P: ArrayLike, kron: int, name: str = "P") -> np.ndarray:
    """``P̄`` with ``P = P̄ ⊗ I_kron`` over the last two axes (error if not of that form).

    Parameters
    ----------
    P : (..., n, n) array_like
        A covariance (or a stack of them): finite, symmetric, positive semidefinite, of a
        size divisible by `kron`.
    kron : int
        The Kronecker factor.
    name : str
        Names `P` in error messages.

    Returns
    -------
    (..., n / kron, n / kron) ndarray
        The reduced covariance.

    Raises
    ------
    ValueError
        `P` is not of the form ``P̄ ⊗ I_kron``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_kf as dkf
    >>> dkf.reduce_covariance(np.kron([[2.0, 1.0], [1.0, 2.0]], np.eye(2)), kron=2)
    array([[2., 1.],
           [1., 2.]])
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a string (the argument name used in messages); got {name!r}")
    kron = check_positive_int(kron, "kron")
    P = check_covariance(_float_array(P, name), name)
    if P.shape[-1] % kron:
        raise ValueError(f"{name} has size {P.shape[-1]}, not a multiple of kron={kron}")
    if kron == 1:
        return P
    red = _kron_factor(P, kron)
    if red is None:
        raise ValueError(
            f"{name} is not of the form P_r ⊗ I_{kron} (same covariance on every spatial axis, "
            "no coupling between axes) that the reduced model needs; build the model with reduce=False"
        )
    return red


def expand_covariance(P_r: ArrayLike, kron: int) -> np.ndarray:
    """``P_r ⊗ I_kron`` over the last two axes.

    Parameters
    ----------
    P_r : (..., n, n) array_like
        Reduced covariance, finite.
    kron : int
        Kronecker factor, >= 1.

    Returns
    -------
    (..., n kron, n kron) ndarray
        The full covariance; :func:`reduce_covariance` undoes it.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_kf as dkf
    >>> P = dkf.expand_covariance([[2.0, 1.0], [1.0, 2.0]], kron=2)
    >>> P.shape, bool(np.allclose(dkf.reduce_covariance(P, 2), [[2.0, 1.0], [1.0, 2.0]]))
    ((4, 4), True)
    """
    kron = check_positive_int(kron, "kron")
    P_r = _finite(_float_array(P_r, "P_r"), "P_r")
    if P_r.ndim < 2 or P_r.shape[-1] != P_r.shape[-2]:
        raise ValueError(f"P_r must be a (..., n, n) array of square matrices; got shape {P_r.shape}")
    if kron == 1:
        return P_r
    out = P_r[..., :, None, :, None] * np.eye(kron)[:, None, :]
    s = P_r.shape
    return out.reshape(*s[:-2], s[-2] * kron, s[-1] * kron)


# ----------------------------------------------------------------------------
# the per-agent measurement update (the masked gain of mascore._masked_gain, which the EKF also uses)
# ----------------------------------------------------------------------------


def agent_update(
    X_pred: ArrayLike, Sigma_pred: ArrayLike, Z: ArrayLike, mask: ArrayLike, R: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every agent's Kalman update of its team estimate, eqs. (16)-(20), batched.

    Parameters
    ----------
    X_pred : (..., N, N, m) array_like
        Predicted team estimates, ``X_pred[..., i, j]`` = ``x̂^-_{i,j}``.
    Sigma_pred : (..., N, m N, m N) array_like
        Each agent's predicted covariance ``Σ_i^-``.
    Z : (..., N, N, m) array_like
        Measurements from :func:`mascore.sensing.measure` (unsensed entries
        are ignored).
    mask : (..., N, N) array_like of bool
        Sensing mask (closed neighbourhoods, diagonal true).
    R : (m, m) or (m N, m N) array_like
        Measurement-noise covariance (positive definite).

    Returns
    -------
    X_post : (..., N, N, m) ndarray
    Sigma_post : (..., N, m N, m N) ndarray
        Joseph form, equal to eq. (20) at the optimal gain.
    KH : (..., N, m N, m N) ndarray
        ``G_i H_i`` embedded in the team space (zero columns for unsensed agents).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> X, Sig, KH = dkf.agent_update(X_pred, np.broadcast_to(np.eye(6), (1, 3, 6, 6)), Z, mask, np.eye(2))
    >>> bool(np.all(np.trace(Sig, axis1=-2, axis2=-1) < 6.0))   # every agent's uncertainty shrinks
    True
    """
    X = _finite(_float_array(X_pred, "X_pred"), "X_pred")
    if X.ndim < 3 or X.shape[-3] != X.shape[-2] or X.shape[-1] == 0 or X.shape[-2] == 0:
        raise ValueError(f"X_pred must have shape (..., N, N, m) with N, m >= 1; got {X.shape}")
    N, m = X.shape[-2:]
    Sig = check_covariance(_float_array(Sigma_pred, "Sigma_pred"), "Sigma_pred", size=m * N)
    R_team = team_noise_covariance(R, N, m)
    check_covariance(R_team, "R", definite=True)
    Zt = _finite(_float_array(Z, "Z"), "Z")
    if Zt.ndim < 3 or Zt.shape[-3:] != (N, N, m):
        raise ValueError(f"Incompatible dimensions of Z; expected (..., {N}, {N}, {m}) but found {Zt.shape}")
    S = _check_mask_values(mask, "mask")
    if S.ndim < 2 or S.shape[-2:] != (N, N):
        raise ValueError(f"Incompatible dimensions of mask; expected (..., {N}, {N}) but found {S.shape}")
    if not np.all(S[..., np.arange(N), np.arange(N)]):
        raise ValueError("mask must include every agent itself (closed neighbourhoods); use sensing_mask(A)")
    try:
        d = np.repeat(S, m, axis=-1).astype(float)  # (..., N, mN)
        KH = masked_gain(Sig, d, R_team)
        lead = X.shape[:-3]
        innov = (Zt - X).reshape(*np.broadcast_shapes(lead, Zt.shape[:-3]), N, N * m, 1)
        X_post = X.reshape(*lead, N, N * m, 1) + KH @ innov
        Sig_post = _joseph(Sig, KH, R_team)
    except ValueError:
        raise ValueError(
            f"the leading (batch) axes of X_pred {X.shape}, Sigma_pred {Sig.shape}, Z {Zt.shape} and "
            f"mask {S.shape} do not broadcast"
        ) from None
    return finite_result("agent update", X_post.reshape(*X_post.shape[:-3], N, N, m), Sig_post, KH)


# ----------------------------------------------------------------------------
# measurement-based control loop, eqs. (8)-(20)
# ----------------------------------------------------------------------------


def mb_predict(
    model: TeamFilterModel,
    X_hat: ArrayLike,
    Sigma: ArrayLike,
    laplacian: ArrayLike,
    KH_prev: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Prediction of the measurement-based loop, eqs. (14)-(15).

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(model, laplacian, x_hat0, P0, mode="mb")``, and call its :meth:`~TeamFilter.predict`: the fast path.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    X_hat : (runs, N, N, m) array_like
        Posterior team estimates of every agent, per Monte Carlo run.
    Sigma : (batch, N, M_r, M_r) array_like
        Reduced posterior covariances ``Σ̄_i`` (``batch`` = 1 or ``runs``).
    laplacian : (N, N) or (batch, N, N) array_like
        Topology at step k.
    KH_prev : (batch, N, M_r, M_r) array_like, optional
        Reduced ``G_i H_i`` of the update that produced `X_hat`. If given, the
        correlation between agent ``i``'s own measurement noise in its
        control (eq. (9)) and its posterior error is added (exact covariance);
        the paper's eq. (15) neglects it (``None``).

    Returns
    -------
    X_pred : (runs, N, N, m) ndarray
    Sigma_pred : (batch, N, M_r, M_r) ndarray

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> X, Sig = dkf.mb_predict(model, X_post, dkf.agent_covariances(model, Sigma_post), Lap)
    >>> Sig.shape
    (1, 3, 6, 6)
    """
    model = _check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = _check_laplacian(laplacian, N)
    X = _check_estimates(model, X_hat, "X_hat")
    Sig = _check_covariances(Sigma, "Sigma", (None, N, Mr, Mr), kron=model.kron)
    _check_batch(L, Sig, "laplacian", "Sigma", X)
    KH = None
    if KH_prev is not None:
        KH = _finite(_float_array(KH_prev, "KH_prev"), "KH_prev")
        if KH.shape != Sig.shape:
            raise ValueError(
                f"Incompatible dimensions of KH_prev; expected {Sig.shape} (as Sigma) but found {KH.shape}"
            )
    filt = TeamFilter._from_checked(model, "mb", L, X, Sig, KH, exact_control_noise=KH is not None)
    filt.predict()
    return filt._X, filt._Sig



def mb_update(
    model: TeamFilterModel, X_pred: ArrayLike, Sigma_pred: ArrayLike, Z: ArrayLike, mask: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Update of every agent's filter (eqs. (16)-(20)) in reduced form.

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(..., mode="mb")``, and call its :meth:`~TeamFilter.update`: the fast path.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    X_pred : (runs, N, N, m) array_like
        Predicted team estimates.
    Sigma_pred : (batch, N, M_r, M_r) array_like
        Reduced predicted covariances.
    Z : (runs, N, N, m) array_like
        Measurements (:func:`mascore.sensing.measure`).
    mask : (N, N) or (batch, N, N) array_like of bool
        Sensing mask.

    Returns
    -------
    X_post : (runs, N, N, m) ndarray
        Updated estimates.
    Sigma_post : (batch, N, M_r, M_r) ndarray
        Reduced updated covariances.
    KH : (batch, N, M_r, M_r) ndarray
        Reduced ``G_i H_i``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> X, Sig = dkf.mb_predict(model, X_post, dkf.agent_covariances(model, Sigma_post), Lap)
    >>> X2, Sig2, KH2 = dkf.mb_update(model, X, Sig, Z, mask)
    >>> bool(np.allclose(Sig2, np.swapaxes(Sig2, -1, -2)))
    True
    """
    model = _check_model(model)
    N, Mr = model.n_agents, model.M_r
    X = _check_estimates(model, X_pred, "X_pred")
    Sig = _check_covariances(Sigma_pred, "Sigma_pred", (None, N, Mr, Mr), kron=model.kron)
    Zt = _check_estimates(model, Z, "Z")
    S = _check_mask(mask, N)
    if S.shape[0] not in (1, Sig.shape[0]):
        raise ValueError(f"mask has {S.shape[0]} topologies but Sigma_pred has {Sig.shape[0]}")
    _check_runs(X, Zt, "X_pred", "Z")
    if Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"Sigma_pred has batch {Sig.shape[0]} but X_pred has {X.shape[0]} runs")
    filt = TeamFilter._from_checked(model, "mb", None, X, Sig)
    filt.update(Zt, S)
    return filt._X, filt._Sig, filt._KH



# ----------------------------------------------------------------------------
# estimation-based control loop, eqs. (21)-(34)
# ----------------------------------------------------------------------------


def eb_initial_covariance(model: TeamFilterModel, P0: ArrayLike, common: bool = True) -> np.ndarray:
    """Initial augmented covariance ``Σ[0]`` (reduced), shape ``(1, N M_r, N M_r)``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    P0 : (m, m) or (m N, m N) array_like
        Covariance of one agent's initial team-estimate error (per agent block
        or full).
    common : bool
        True: all agents start from the *same* initial estimate, so
        ``e_i[0]`` coincide and ``Σ[0] = 1 1^T ⊗ P0`` (the reading of
        Assumption 2 that makes Lemma 1's ``e[0] = C_i[0] e_i[0]`` exact with
        ``C_i[0] = 1_N ⊗ I``). False: independent initial errors,
        ``Σ[0] = I_N ⊗ P0``.

    Returns
    -------
    (1, N M_r, N M_r) ndarray
        The reduced augmented covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> dkf.eb_initial_covariance(model, np.eye(2)).shape         # common start: 1 1^T (x) P0
    (1, 18, 18)
    """
    model = _check_model(model)
    _check_flag(common, "common")
    N, m = model.n_agents, model.m
    P0 = _finite(_float_array(P0, "P0"), "P0")
    if P0.shape == (m, m):
        P0 = np.kron(np.eye(N), P0)
    if P0.shape != (m * N, m * N):
        raise ValueError(
            f"Incompatible dimensions of P0; expected ({m}, {m}) per agent block or ({m * N}, {m * N}) "
            f"but found {P0.shape}"
        )
    P0 = check_covariance(P0, "P0", size=m * N)
    P0r = reduce_covariance(P0, model.kron, "P0")
    outer = np.ones((N, N)) if common else np.eye(N)
    return np.kron(outer, P0r)[None]


def eb_predict(
    model: TeamFilterModel, X_hat: ArrayLike, Sigma: ArrayLike, laplacian: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Prediction of the estimation-based loop: eq. (14) and eqs. (32), (34).

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(model, laplacian, x_hat0, P0)``, and call its :meth:`~TeamFilter.predict`: the fast path.

    ``Σ^- = Φ Σ Φ^T + (1 1^T) ⊗ 𝒬`` with ``Φ = I_N ⊗ F_1 + 1_N ⊗ F_2``
    (every block ``(i, j)`` of this is eq. (34); ``i = j`` gives eq. (32)),
    computed in tensor form (see module docstring).

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    X_hat : (runs, N, N, m) array_like
        Updated team estimates of every agent.
    Sigma : (batch, N M_r, N M_r) array_like
        Reduced augmented covariance.
    laplacian : (N, N) or (batch, N, N) array_like
        Topology at step k.

    Returns
    -------
    X_pred : (runs, N, N, m) ndarray
        Predicted estimates.
    Sigma_pred : (batch, N M_r, N M_r) ndarray
        Predicted augmented covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> Sigma_pred.shape
    (1, 18, 18)
    """
    model = _check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = _check_laplacian(laplacian, N)
    X = _check_estimates(model, X_hat, "X_hat")
    Sig = _check_covariances(Sigma, "Sigma", (None, N * Mr, N * Mr), kron=model.kron)
    _check_batch(L, Sig, "laplacian", "Sigma", X)
    filt = TeamFilter._from_checked(model, "eb", L, X, Sig)
    filt.predict()
    return filt._X, filt._Sig




def eb_update(
    model: TeamFilterModel, X_pred: ArrayLike, Sigma_pred: ArrayLike, Z: ArrayLike, mask: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Update of the estimation-based loop: eqs. (16)-(20) and (33).

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(model, laplacian, x_hat0, P0)``, and call its :meth:`~TeamFilter.update`: the fast path.

    ``Σ_ij = (I - G_i H_i) Σ_ij^- (I - G_j H_j)^T + δ_ij G_i H_i R H_i^T G_i^T``:
    eq. (33) for ``i != j`` (measurement noises of different agents are
    independent) and the Joseph form of eq. (20) for ``i = j``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    X_pred : (runs, N, N, m) array_like
        Predicted team estimates.
    Sigma_pred : (batch, N M_r, N M_r) array_like
        Predicted augmented covariance.
    Z : (runs, N, N, m) array_like
        Measurements.
    mask : (N, N) or (batch, N, N) array_like of bool
        Sensing mask.

    Returns
    -------
    X_post : (runs, N, N, m) ndarray
        Updated estimates.
    Sigma_post : (batch, N M_r, N M_r) ndarray
        Updated augmented covariance.
    KH : (batch, N, M_r, M_r) ndarray
        Reduced ``G_i H_i``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> bool(np.allclose(Sigma_post, np.swapaxes(Sigma_post, -1, -2)))
    True
    """
    model = _check_model(model)
    N, Mr = model.n_agents, model.M_r
    X = _check_estimates(model, X_pred, "X_pred")
    Sig = _check_covariances(Sigma_pred, "Sigma_pred", (None, N * Mr, N * Mr), kron=model.kron)
    Zt = _check_estimates(model, Z, "Z")
    S = _check_mask(mask, N)
    if S.shape[0] not in (1, Sig.shape[0]):
        raise ValueError(
            f"mask has {S.shape[0]} topologies but Sigma_pred has {Sig.shape[0]}: the covariance batch must "
            "match the topology batch (pass the topology mask, not the per-run measurement mask)"
        )
    _check_runs(X, Zt, "X_pred", "Z")
    if Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"Sigma_pred has batch {Sig.shape[0]} but X_pred has {X.shape[0]} runs")
    filt = TeamFilter._from_checked(model, "eb", None, X, Sig)
    filt.update(Zt, S)
    return filt._X, filt._Sig, filt._KH




def agent_covariances(model: TeamFilterModel, Sigma: ArrayLike) -> np.ndarray:
    """Diagonal blocks ``Σ̄_i`` of a reduced augmented covariance.

    Checks the covariance in full on every call (an eigenvalue test); a :class:`TeamFilter`
    gives the same from its own state without one: :meth:`TeamFilter.agent_covariances`.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    Sigma : (batch, N M_r, N M_r) array_like
        Reduced augmented covariance.

    Returns
    -------
    (batch, N, M_r, M_r) ndarray
        Each agent's own covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> dkf.agent_covariances(model, Sigma_post).shape
    (1, 3, 6, 6)
    """
    model = _check_model(model)
    N, Mr = model.n_agents, model.M_r
    Sig = _check_covariances(Sigma, "Sigma", (None, N * Mr, N * Mr), kron=model.kron)
    return _agent_covariances(model, Sig)


# ----------------------------------------------------------------------------
# the whole-team filters: one object per run of filters, owning its state and work arrays
# ----------------------------------------------------------------------------

#: The two loops of Song et al.: ``"eb"`` estimation-based (augmented covariance, eqs. (29)-(34)),
#: ``"mb"`` measurement-based (every agent's own covariance, eqs. (14)-(20)).
FILTER_MODES = ("eb", "mb")


class TeamFilter:
    """Every agent's whole-team Kalman filter, for the whole team (and Monte Carlo runs) at once.

    The fast path of Song et al.'s filters: the model was checked when it was built,
    the initial covariance is checked in full here, once; a step checks only what
    changes per call (shapes and mask values) and tests its result for NaN/inf,
    naming the input at fault. The filter holds its state (estimates, covariance,
    gains), the ``Φ`` blocks derived from the topology (recomputed only when the
    topology changes) and its work arrays, reused from step to step: the augmented
    covariance of a large team is updated in place. Filters share nothing, so
    independent filters may run in different threads.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    laplacian : (N, N) or (batch, N, N) array_like
        Topology of the control law (eq. (11)): one for all runs, or one per covariance
        batch entry. Change it with the `laplacian` argument of :meth:`predict`.
    x_hat0 : (runs, N m) or (runs, N, N, m) array_like
        Initial estimates, per Monte Carlo run: one common team estimate of all agents,
        or every agent's own (``x_hat0[r, i, j]`` = agent i's estimate of agent j).
    P0 : (m, m) or (m N, m N) array_like, optional
        Covariance of one agent's initial team-estimate error, per agent block or full
        (see :func:`eb_initial_covariance`). Give `P0` or `Sigma0`.
    mode : {"eb", "mb"}
        Estimation-based loop (augmented covariance ``(batch, N M_r, N M_r)``,
        eqs. (29)-(34)) or measurement-based loop (each agent's own covariance
        ``(batch, N, M_r, M_r)``, eqs. (14)-(20)).
    Sigma0 : ndarray, optional
        The initial reduced covariance itself, of the mode's shape (with its batch
        axis); checked in full (symmetric positive semidefinite).
    common : bool
        With `P0`: all agents start from the same estimate (``Σ[0] = 1 1^T ⊗ P0``) or from
        independent ones (``I_N ⊗ P0``).
    exact_control_noise : bool
        ``"mb"`` only: add the correlation between an agent's own measurement noise in its
        control and its posterior error, which eq. (15) neglects (see :func:`mb_predict`).

    Raises
    ------
    ValueError
        Bad shapes, non-finite entries, a covariance that is not symmetric PSD, a
        Laplacian that is not one, batches that do not fit together.
    TypeError
        `model` is not a :class:`TeamFilterModel`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3)
    >>> filt = dkf.TeamFilter(model, graphs.laplacian(path), np.zeros((1, 6)), P0=np.eye(2))
    >>> for k in range(5):
    ...     filt.predict()
    ...     Z, mask = sensing.measure(k, np.zeros((1, 3, 2)), path, np.eye(2))
    ...     filt.update(Z, mask[0])
    >>> filt.Sigma.shape, filt.X_hat.shape                      # (batch, N M_r, N M_r), (runs, N, N, m)
    ((1, 18, 18), (1, 3, 3, 2))
    """

    def __init__(
        self,
        model: TeamFilterModel,
        laplacian: ArrayLike,
        x_hat0: ArrayLike,
        P0: ArrayLike | None = None,
        *,
        mode: str = "eb",
        Sigma0: ArrayLike | None = None,
        common: bool = True,
        exact_control_noise: bool = False,
    ) -> None:
        model = _check_model(model)
        if not isinstance(mode, str) or mode not in FILTER_MODES:
            raise ValueError(f"mode must be one of {FILTER_MODES}; got {mode!r}")
        _check_flag(common, "common")
        _check_flag(exact_control_noise, "exact_control_noise")
        if exact_control_noise and mode != "mb":
            raise ValueError("exact_control_noise applies to the measurement-based loop (mode='mb') only")
        N, m, Mr = model.n_agents, model.m, model.M_r
        L = _check_laplacian(laplacian, N, undirected=True)
        X = _float_array(x_hat0, "x_hat0")
        if X.ndim == 2 and X.shape[1] == N * m:
            X = np.broadcast_to(X.reshape(X.shape[0], 1, N, m), (X.shape[0], N, N, m))
        if X.ndim != 4 or X.shape[1:] != (N, N, m) or X.shape[0] == 0:
            raise ValueError(f"Incompatible dimensions of x_hat0; expected (runs, {N * m}) or (runs, {N}, {N}, {m}) "
                             f"but found {X.shape}")
        X = _finite(np.array(X, dtype=float, order="C"), "x_hat0")
        if (P0 is None) == (Sigma0 is None):
            raise ValueError("give the initial covariance as exactly one of P0 (per agent or team) and Sigma0 "
                             "(reduced, with its batch axis)")
        if P0 is not None:
            Sig = eb_initial_covariance(model, P0, common=common)
            if mode == "mb":
                Sig = _agent_covariances(model, Sig)
            nb = L.shape[0] if L.ndim == 3 else 1
            Sig = np.broadcast_to(Sig, (nb, *Sig.shape[1:])).copy()
        else:
            shape = (None, N * Mr, N * Mr) if mode == "eb" else (None, N, Mr, Mr)
            Sig = np.array(_check_covariances(Sigma0, "Sigma0", shape, kron=model.kron), dtype=float, order="C")
        _check_batch(L, Sig, "laplacian", "Sigma0" if P0 is None else "P0", X)
        self._init(model, mode, L, X, Sig, None, exact_control_noise)

    @classmethod
    def _from_checked(cls, model, mode, L, X, Sig, KH=None, exact_control_noise=False) -> TeamFilter:
        """A filter on arguments the caller has checked (the plain-array functions).

        The steps never write into `X` (they make new estimates) but may update the covariance in
        place: that one is copied (C-ordered, as the in-place row-block steps need).
        """
        self = cls.__new__(cls)
        self._init(model, mode, L, X, np.array(Sig, dtype=float, order="C"),
                   None if KH is None else np.array(KH, dtype=float), exact_control_noise)
        return self

    def _init(self, model, mode, L, X, Sig, KH, exact_control_noise) -> None:
        self._model, self._mode, self._exact = model, mode, exact_control_noise
        self._X, self._Sig = X, Sig
        N, Mr = model.n_agents, model.M_r
        self._KH = np.zeros((Sig.shape[0], N, Mr, Mr)) if KH is None else KH
        self._work: dict[int, np.ndarray] = {}
        self._Qt = np.kron(np.eye(N), model.Q_r)
        self._set_topology(L)

    # ------------------------------------------------------------------ state

    @property
    def model(self) -> TeamFilterModel:
        """The team model."""
        return self._model

    @property
    def mode(self) -> str:
        """``"eb"`` (estimation-based) or ``"mb"`` (measurement-based)."""
        return self._mode

    @property
    def laplacian(self) -> np.ndarray:
        """The topology in force, ``(N, N)`` or ``(batch, N, N)`` (read-only)."""
        return self._L

    @property
    def X_hat(self) -> np.ndarray:
        """Every agent's team estimate, ``(runs, N, N, m)`` (a copy; :meth:`view` gives the filter's own array)."""
        return self._X.copy()

    @property
    def Sigma(self) -> np.ndarray:
        """The reduced covariance: ``(batch, N M_r, N M_r)`` (``"eb"``) or ``(batch, N, M_r, M_r)`` (``"mb"``).

        A copy, unchanged by later steps; :meth:`view` gives the filter's own array without copying.
        """
        return self._Sig.copy()

    @property
    def KH(self) -> np.ndarray:
        """Reduced ``G_i H_i`` of the last update, ``(batch, N, M_r, M_r)`` (zero before the first update; a copy)."""
        return self._KH.copy()

    def view(self, name: str) -> np.ndarray:
        """The filter's own state array `name`, read-only and not copied (the fast read in a loop).

        Parameters
        ----------
        name : {"X_hat", "Sigma", "KH"}
            The state, as the property of that name.

        Returns
        -------
        ndarray
            A read-only view: the next step may overwrite it in place (copy it to keep it).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.view("Sigma").flags.writeable, np.array_equal(filt.view("Sigma"), filt.Sigma)
        (False, True)
        """
        return state_view(self, name, {"X_hat": "_X", "Sigma": "_Sig", "KH": "_KH"})

    def agent_covariances(self) -> np.ndarray:
        """Each agent's own reduced covariance ``Σ̄_i``, ``(batch, N, M_r, M_r)`` (a new array).

        Returns
        -------
        (batch, N, M_r, M_r) ndarray
            The diagonal blocks of the augmented covariance (``"eb"``) or the state itself (``"mb"``).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.agent_covariances().shape
        (1, 3, 6, 6)
        """
        return _agent_covariances(self._model, self._Sig) if self._mode == "eb" else self._Sig.copy()

    def nees(self, X_true: ArrayLike) -> np.ndarray:
        """NEES of every agent's team estimate against the true states (see :func:`team_nees`).

        Parameters
        ----------
        X_true : (runs, N, m) array_like
            True states.

        Returns
        -------
        (runs, N) ndarray
            ``e_i^T Σ_i^{-1} e_i``, chi-square with ``m N`` dof for a consistent filter.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2),
        ...                       common=False)
        >>> filt.nees(np.ones((1, 3, 2)))                             # unit errors, unit covariance: 6 each
        array([[6., 6., 6.]])
        """
        model = self._model
        N, m = model.n_agents, model.m
        x = _finite(_float_array(X_true, "X_true"), "X_true")
        if x.shape != (self._X.shape[0], N, m):
            raise ValueError(f"Incompatible dimensions of X_true; expected ({self._X.shape[0]}, {N}, {m}) "
                             f"but found {x.shape}")
        Sig_i = _agent_covariances(model, self._Sig) if self._mode == "eb" else self._Sig
        return _team_nees(model, x, self._X, Sig_i)

    def f2_cross(self, laplacian: ArrayLike | None = None) -> np.ndarray:
        """``F_2 E[e e_i^T]`` of the current augmented covariance (``"eb"`` only; see :func:`f2_cross`).

        Parameters
        ----------
        laplacian : (N, N) or (batch, N, N) array_like, optional
            The topology defining ``F_2``; default the one in force.

        Returns
        -------
        (batch, N, M_r, M_r) ndarray
            ``F_2 E[e e_i^T]`` per agent.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.f2_cross().shape
        (1, 3, 6, 6)
        """
        if self._mode != "eb":
            raise ValueError("f2_cross needs the augmented covariance of the estimation-based loop (mode='eb')")
        L = self._L if laplacian is None else _check_laplacian(laplacian, self._model.n_agents, undirected=True)
        _check_batch(L, self._Sig, "laplacian", "Sigma")
        return _f2_cross(self._model, self._Sig, L)

    # ------------------------------------------------------------------ steps

    def predict(self, laplacian: ArrayLike | None = None) -> None:
        """Prediction of every agent's estimate and of the covariance: eqs. (14)-(15) or (14), (32), (34).

        Parameters
        ----------
        laplacian : (N, N) or (batch, N, N) array_like, optional
            Topology of this step's control (switching topologies); default the one in
            force. It stays in force for the next steps.

        Raises
        ------
        ValueError
            A bad Laplacian, or a prediction that overflows to NaN/inf.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.predict(graphs.laplacian(graphs.ring_graph(3)))   # this step's topology
        >>> bool(np.trace(filt.Sigma[0]) > 18.0)                     # the uncertainty grows
        True
        """
        if laplacian is not None:
            L = _check_laplacian(laplacian, self._model.n_agents, undirected=True)
            if L.shape != self._L.shape or not np.array_equal(L, self._L):
                _check_batch(L, self._Sig, "laplacian", "Sigma", self._X)
                self._set_topology(L)
        if self._mode == "eb":
            self._eb_predict()
            what = "estimation-based prediction"
        else:
            self._mb_predict()
            what = "measurement-based prediction"
        _finite_state(what, self._X, self._Sig, diagonal_only=self._mode == "eb" and self._rows)

    def update(self, Z: ArrayLike, mask: ArrayLike) -> None:
        """Every agent's Kalman update with its own measurements: eqs. (16)-(20) and (33).

        Parameters
        ----------
        Z : (runs, N, N, m) array_like
            Measurements (:func:`mascore.sensing.measure`; unsensed entries are ignored).
        mask : (N, N) or (batch, N, N) array_like of bool
            Sensing mask (closed neighbourhoods). A mask per run while the covariance is
            shared (batch 1) gives every run its own covariance from then on.

        Raises
        ------
        ValueError
            Bad shapes or mask values, or NaN/inf in the result (naming `Z` when it holds them).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous, sensing
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> path = graphs.path_graph(3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(path), np.zeros((1, 6)), P0=np.eye(2))
        >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))
        >>> filt.update(Z, mask[0])
        >>> bool(np.trace(filt.Sigma[0]) < 18.0)                     # the uncertainty shrinks
        True
        """
        model = self._model
        N, m = model.n_agents, model.m
        Zt = _float_array(Z, "Z")
        if Zt.shape != self._X.shape:
            raise ValueError(f"Incompatible dimensions of Z; expected {self._X.shape} (runs, {N}, {N}, {m}) "
                             f"but found {Zt.shape}")
        S = _check_mask(mask, N)
        nb = self._Sig.shape[0]
        if S.shape[0] > 1 and nb == 1 and self._L is not None and self._L.ndim == 2 and S.shape[0] == self._X.shape[0]:
            # masks per run (dropped links): from now on every run has its own covariance
            nb = S.shape[0]
            self._Sig = np.broadcast_to(self._Sig, (nb, *self._Sig.shape[1:])).copy()
            self._KH = np.broadcast_to(self._KH, (nb, *self._KH.shape[1:])).copy()
        if S.shape[0] not in (1, nb):
            raise ValueError(
                f"mask has {S.shape[0]} topologies but the covariance has batch {nb}: the covariance batch must "
                "match the topology batch (pass the topology mask, not the per-run measurement mask)"
            )
        if self._mode == "eb":
            self._eb_update(Zt, S)
            what = "estimation-based update"
        else:
            self._mb_update(Zt, S)
            what = "measurement-based update"
        if not np.isfinite(self._X).all():
            _finite(Zt, "Z")
        _finite_state(what, self._X, self._Sig, self._KH)

    # ------------------------------------------------------------------ kernels

    def _set_topology(self, L: np.ndarray | None) -> None:
        """Store the (checked) topology and, for the estimation-based loop, its ``Φ`` blocks.

        ``None``: a filter made for one update (the plain-array update functions) needs none.
        """
        model = self._model
        C = model.n_agents * model.M_r
        self._rows = C > _DENSE_MAX
        self._L, self._blocks = None, None
        if L is None:
            return
        self._L = frozen_copy(L)
        if self._mode == "eb":
            Lb = self._L if self._L.ndim == 3 else self._L[None]
            self._blocks = [_phi_blocks(model, Lk, self._rows) for Lk in Lb]

    def _buffer(self, slot: int, size: int) -> np.ndarray:
        """A flat work array of at least `size` floats, owned by this filter (grown when needed)."""
        a = self._work.get(slot)
        if a is None or a.size < size:
            a = self._work[slot] = np.empty(size)
        return a[:size]

    def _mb_predict(self) -> None:
        """Eqs. (14)-(15) in tensor form (and the exact control-noise correlation if asked)."""
        model, L, Sig = self._model, self._L, self._Sig
        N, Mr, mr = model.n_agents, model.M_r, model.m_r
        self._X = _F1_means(model, self._X, L)
        Lb = L if L.ndim == 3 else L[None]
        # F_1 Σ_i F_1^T via the tensor form
        T = _F1_rows(model, Sig.reshape(*Sig.shape[:2], N, mr, Mr), Lb[:, None])
        T = np.swapaxes(T.reshape(*Sig.shape), -1, -2)
        P = _F1_rows(model, T.reshape(*Sig.shape[:2], N, mr, Mr), Lb[:, None]).reshape(*Sig.shape)
        # eq. (15): (I ⊗ BK) E[nu_bar nu_bar^T] (I ⊗ BK)^T + Q (block diagonal)
        Rr = model.R_r.reshape(N, mr, N, mr)
        # cov of (L_j ⊗ I) nu_j: sum_{l,l'} L_jl L_jl' R[l, l']
        Cj = np.einsum("bjl,bjk,lakc->bjac", Lb, Lb, Rr)  # (batch, N, mr, mr)
        noise = model.BK_r @ Cj @ model.BK_r.T + model.Q_r  # (batch, N, mr, mr)
        blk = np.zeros((Lb.shape[0], N, mr, N, mr))
        blk[:, np.arange(N), :, np.arange(N), :] = np.moveaxis(noise, 1, 0)
        P = P + blk.reshape(Lb.shape[0], 1, Mr, Mr)
        if self._exact:
            KH = self._KH
            # E[e_i nu_bar_i^T] = -KH_i R (L_i ⊗ I)^T, column block i of E[e_i nu_bar^T]
            RL = np.einsum("lakc,bik->bilac", Rr, Lb).reshape(Lb.shape[0], N, Mr, mr)  # R (L_i ⊗ I)^T
            Xc = -(KH @ RL)  # (batch, N, Mr, mr)
            F1Xc = _F1_rows(model, Xc.reshape(*Xc.shape[:2], N, mr, mr), Lb[:, None]).reshape(Xc.shape)
            corr = -(F1Xc @ model.BK_r.T)  # -F1 E[e_i nu_bar_i^T] BK^T, (batch, N, Mr, mr)
            full = np.zeros((*corr.shape[:2], Mr, N, mr))
            full[:, np.arange(N), :, np.arange(N), :] = np.moveaxis(corr, 1, 0)
            full = full.reshape(*corr.shape[:2], Mr, Mr)
            P = P + full + np.swapaxes(full, -1, -2)
        self._Sig = symmetric_part(P)

    def _mb_update(self, Z: np.ndarray, S: np.ndarray) -> None:
        """Eqs. (16)-(20), Joseph form, all agents and runs at once."""
        model, Sig = self._model, self._Sig
        KH = masked_gain(Sig, _mask_vec(model, S), model.R_r)
        self._X = _apply_gain(model, self._X, Z, KH)
        self._Sig, self._KH = _joseph(Sig, KH, model.R_r), KH

    def _eb_predict(self) -> None:
        """``Σ^- = Φ Σ Φ^T + (1 1^T) ⊗ 𝒬``: dense products for a small team, else row blocks in place.

        Row blocks: with ``G_i = Σ[i] F_2^T = (F_2 Σ[:, i])^T`` (``F_2 Σ`` computed once with
        the sparse ``F_2``) and ``H = F_2 Σ F_2^T``, tile ``(i, i')`` is
        ``(F_1 Σ_ii' + (F_2 Σ)_i') F_1^T + F_1 G_i + H + 𝒬``. Σ^- is symmetric, so only the
        tiles ``i' >= i`` of row block ``i`` are computed (two products with ``F_1``) and
        written transposed into column block ``i``. Row block ``i`` reads only the tiles
        ``i' >= i`` of Σ, which no earlier row block wrote: the recursion runs in place.
        """
        model, Sig = self._model, self._Sig
        N, Mr = model.n_agents, model.M_r
        self._X = _F1_means(model, self._X, self._L)
        blocks, Qt = self._blocks, self._Qt
        one = len(blocks) == 1
        if not self._rows:  # a small team: two dense products are cheapest
            out = np.empty_like(Sig)
            for b in range(Sig.shape[0]):
                Phi = blocks[0 if one else b][0]
                out[b] = Phi @ Sig[b] @ Phi.T
                out[b].reshape(N, Mr, N, Mr)[...] += Qt[None, :, None, :]
            self._Sig = out
            return
        for b in range(Sig.shape[0]):
            self._eb_predict_rows(Sig[b], blocks[0 if one else b])

    def _eb_predict_rows(self, Sb: np.ndarray, blk: tuple) -> None:
        """Σ^- of one topology, in place in `Sb` ``(C, C)`` (see :meth:`_eb_predict`)."""
        model, Qt = self._model, self._Qt
        N, Mr = model.n_agents, model.M_r
        C = N * Mr
        F1aug, F1, F1t, F2s, K2t = blk
        work = self._buffer(0, 3 * Mr * C + N * Mr * Mr)
        XP, Q = work[:2 * Mr * C], work[2 * Mr * C:3 * Mr * C]
        # F_2 Σ, shared by every row block: (Φ Σ)[i] = F_1 Σ[i] + F_2 Σ
        F2S = F2s @ Sb
        F2S3 = F2S.reshape(Mr, N, Mr)
        # H = F_2 Σ F_2^T: column (j, α) sums BK[α, β] L_jl (F_2 Σ)[:, (j, l, β)]
        H = np.swapaxes(np.matmul(np.swapaxes(F2S3, 0, 1), K2t), 0, 1).reshape(Mr, Mr)
        # the part of tile (i, i') shared by the whole row block: F_1 G_i + H + 𝒬, G_i = (F_2 Σ)[:, i]^T
        shared = np.matmul(F1, F2S3.transpose(1, 2, 0), out=work[3 * Mr * C:].reshape(N, Mr, Mr))
        shared += H + Qt
        o4 = Sb.reshape(N, Mr, N, Mr)
        for i in range(N):
            n, c0 = N - i, i * Mr
            XPi = XP[:2 * Mr * n * Mr].reshape(2 * Mr, n * Mr)
            np.copyto(XPi[:Mr], Sb[c0:c0 + Mr, c0:])  # Σ_ii', i' >= i (read before anything is written there)
            np.copyto(XPi[Mr:], F2S[:, c0:])
            # (Φ Σ)_ii' = (F_2 Σ)_i' + F_1 Σ_ii' (eq. (34); eq. (32) for i' = i): [F_1, I] has its identity
            # entry first in every row, so the sparse product adds F_1's terms to (F_2 Σ)_i' in order
            Pi = F1aug @ XPi
            Qi = Q[:Mr * n * Mr].reshape(Mr * n, Mr)
            Q3 = Qi.reshape(Mr, n, Mr)
            np.copyto(Q3, shared[i][:, None, :])
            # tile (i, i') = (Φ Σ)_ii' F_1^T + shared (BLAS adds the product to the preset)
            _gemm_acc(Pi.reshape(Mr * n, Mr), F1t, Qi)
            np.copyto(o4[i, :, i:, :], Q3)
            if n > 1:  # tile (i', i) = tile (i, i')^T
                np.copyto(o4[i + 1:, :, i, :], Q3[:, 1:, :].transpose(1, 2, 0))

    def _eb_update(self, Z: np.ndarray, S: np.ndarray) -> None:
        """Eqs. (16)-(20) and (33) on the augmented covariance.

        ``Ψ = blockdiag(I - G_i H_i)`` and ``G_i H_i = W_i E_i^T`` has rank ``q_i``
        (``E_i`` selects the observed entries ``idx_i``), so tile ``(i, i')`` of
        ``Ψ Σ Ψ^T`` is ``Σ_ii' - W_i V_ii' - Σ[i, idx_i'] W_i'^T`` with
        ``V_ii' = Σ[idx_i, i'] - Σ[idx_i, idx_i'] W_i'^T`` (all ``V`` computed once from the
        ``N q`` observed rows): ``O(N^2 M_r^2 q)`` work instead of the ``O(N^2 M_r^3)`` of dense
        products, one pass over Σ^- (in place) with one small batched product per row block.
        """
        model, Sig = self._model, self._Sig
        N, Mr = model.n_agents, model.M_r
        nb, C = Sig.shape[0], N * Mr
        blocks = Sig.reshape(nb, N, Mr, N, Mr)
        if not self._rows:
            diag = np.moveaxis(blocks[:, np.arange(N), :, np.arange(N), :], 0, 1)  # Σ_i^-, (batch, N, Mr, Mr)
        else:  # the same, in a work array
            diag = self._buffer(1, nb * N * Mr * Mr).reshape(nb, N, Mr, Mr)
            for i in range(N):
                diag[:, i] = blocks[:, i, :, i, :]
        d = _mask_vec(model, S)
        KH = masked_gain(diag, d, model.R_r)  # G_i H_i, eqs. (17), (19)
        if not self._rows:  # a small team: dense products of all row blocks at once are cheapest
            KRK = KH @ model.R_r @ np.swapaxes(KH, -1, -2)  # eq. (33): + δ_ij G_i H_i R H_i^T G_i^T
            Psi = np.eye(Mr) - KH  # (batch, N, Mr, Mr)
            T = Psi @ Sig.reshape(nb, N, Mr, C)  # rows
            T = np.swapaxes(T.reshape(nb, C, C), -1, -2)
            T = (Psi @ T.reshape(nb, N, Mr, C)).reshape(nb, N, Mr, N, Mr)  # columns (by symmetry of Σ^-)
            T[:, np.arange(N), :, np.arange(N), :] += np.moveaxis(KRK, 1, 0)
            self._X = _apply_gain(model, self._X, Z, KH)
            self._Sig, self._KH = T.reshape(nb, C, C), KH
            return
        idx, valid = observed_indices(d)  # (batch, N, q)
        q = idx.shape[-1]
        W = np.take_along_axis(KH, np.broadcast_to(idx[..., None, :], (*KH.shape[:-1], q)), axis=-1)  # (b, N, Mr, q)
        Wt = np.swapaxes(W, -1, -2)
        Rq = model.R_r[idx[..., :, None], idx[..., None, :]]  # R on the observed entries (padding: W is zero there)
        for b in range(nb):
            bi = b if idx.shape[0] > 1 else 0  # one mask for all covariances
            self._eb_update_rows(Sig[b], idx[bi], W[b], Wt[b], Rq[bi])
        self._X = _apply_gain(model, self._X, Z, KH)
        self._KH = KH

    def _eb_update_rows(self, Sb: np.ndarray, idx: np.ndarray, W: np.ndarray, Wt: np.ndarray,
                        Rq: np.ndarray) -> None:
        """``Ψ Σ^- Ψ^T + blockdiag(G_i H_i R H_i^T G_i^T)`` of one covariance, in place in `Sb`."""
        N, Mr, q = W.shape
        C, Nq = N * Mr, N * q
        cidx = (np.arange(N)[:, None] * Mr + idx).ravel()  # observed rows/columns (i, idx_i) of Σ^-
        work = self._buffer(2, 2 * Nq * C + Nq * Nq + 4 * N * Mr * q + Mr * C)
        R = np.take(Sb, cidx, axis=0, out=work[:Nq * C].reshape(Nq, C))  # the observed rows, (N q, C)
        Rc = np.take(R, cidx, axis=1, out=work[Nq * C:Nq * C + Nq * Nq].reshape(Nq, Nq))
        # V_i[:, i'] = Σ[idx_i, i'] - Σ[idx_i, idx_i'] W_i'^T: the rows of (I - G_i H_i) Σ^- that meet W_i'
        Vt = np.matmul(Rc.reshape(Nq, N, q).transpose(1, 0, 2), Wt,
                       out=work[Nq * C + Nq * Nq:2 * Nq * C + Nq * Nq].reshape(N, Nq, Mr))
        np.subtract(R.reshape(Nq, N, Mr).transpose(1, 0, 2), Vt, out=Vt)  # Vt[i', (i, k)] = V_i[k, i']
        # tile (i, i') = Σ_ii' - [W_i, Σ[i, idx_i']] [V_ii'; W_i'^T]: one batched product over i' per row block,
        # with Σ[i, idx_i'] = Σ[idx_i', i]^T (Σ^- is symmetric) taken from the observed rows
        rest = work[2 * Nq * C + Nq * Nq:]
        Ab = rest[:N * Mr * 2 * q].reshape(N, Mr, 2 * q)
        Bb = rest[N * Mr * 2 * q:4 * N * Mr * q].reshape(N, 2 * q, Mr)
        O = rest[4 * N * Mr * q:].reshape(Mr, C)
        O3 = O.reshape(Mr, N, Mr).transpose(1, 0, 2)
        Bb[:, q:, :] = Wt
        R3 = R.reshape(N, q, C)
        for i in range(N):
            rows = slice(i * Mr, (i + 1) * Mr)
            Ab[:, :, :q] = W[i]
            Ab[:, :, q:] = R3[:, :, rows].transpose(0, 2, 1)
            Bb[:, :q, :] = Vt[:, i * q:(i + 1) * q]
            np.matmul(Ab, Bb, out=O3)
            Si = Sb[rows]  # row block i of Σ^-: read here only, so it is overwritten with its update
            np.subtract(Si, O, out=Si)
            Si[:, rows] += W[i] @ Rq[i] @ Wt[i]  # eq. (33): + δ_ij G_i H_i R H_i^T G_i^T


class CentralizedTeamFilter:
    """The centralized Kalman filter over all agents' measurements, applied inputs known (the reference).

    Holds the team estimate and its reduced covariance; :meth:`predict` and
    :meth:`update` run :func:`centralized_predict` and :func:`centralized_update`
    without re-checking the state this filter produced (the model, `B` and `P0` are
    checked here, once).

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    B : (m, p) array_like
        Input matrix of one agent.
    x_hat0 : (runs, N m) or (runs, N, m) array_like
        Initial team estimate, per run.
    P0 : (m, m) or (m N, m N) array_like
        Covariance of the initial estimate error, per agent or of the team; positive definite.
    batch : int
        Number of covariances kept (1: shared by all runs, or one per run).

    Raises
    ------
    ValueError
        Bad shapes or values, or `P0` not positive definite.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
    ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> central = dkf.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
    >>> central.predict(np.zeros((1, 3, 1)))
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), graphs.path_graph(3), np.eye(2))
    >>> central.update(Z, mask[0])
    >>> central.x_hat.shape, central.P.shape
    ((1, 3, 2), (1, 6, 6))
    """

    def __init__(self, model: TeamFilterModel, B: ArrayLike, x_hat0: ArrayLike, P0: ArrayLike,
                 batch: int = 1) -> None:
        model = _check_model(model)
        N, m = model.n_agents, model.m
        B = as_matrix(_float_array(B, "B"), "B", (m, None))
        x = _float_array(x_hat0, "x_hat0")
        if x.ndim == 2 and x.shape[1] == N * m:
            x = x.reshape(x.shape[0], N, m)
        if x.ndim != 3 or x.shape[1:] != (N, m) or x.shape[0] == 0:
            raise ValueError(f"Incompatible dimensions of x_hat0; expected (runs, {N * m}) or (runs, {N}, {m}) "
                             f"but found {x.shape}")
        x = _finite(np.array(x, dtype=float, order="C"), "x_hat0")
        batch = check_positive_int(batch, "batch")
        P0 = _finite(_float_array(P0, "P0"), "P0")
        if P0.shape == (m, m):
            P = np.kron(np.eye(N), reduce_covariance(check_covariance(P0, "P0", definite=True), model.kron, "P0"))
        elif P0.shape == (m * N, m * N):
            P = reduce_covariance(check_covariance(P0, "P0", definite=True), model.kron, "P0")
        else:
            raise ValueError(f"Incompatible dimensions of P0; expected ({m}, {m}) per agent or ({m * N}, {m * N}) "
                             f"but found {P0.shape}")
        self._model, self._B, self._x = model, frozen_copy(B), x
        self._P = np.broadcast_to(P, (batch, *P.shape)).copy()

    @property
    def x_hat(self) -> np.ndarray:
        """Team estimates ``(runs, N, m)`` (a copy; :meth:`view` gives the filter's own array)."""
        return self._x.copy()

    @property
    def P(self) -> np.ndarray:
        """Reduced covariance ``(batch, M_r, M_r)`` (a copy; :meth:`view` gives the filter's own array)."""
        return self._P.copy()

    def view(self, name: str) -> np.ndarray:
        """The filter's own state array `name`, read-only and not copied (the fast read in a loop).

        Parameters
        ----------
        name : {"x_hat", "P"}
            The state, as the property of that name.

        Returns
        -------
        ndarray
            A read-only view, replaced or overwritten by the next step (copy it to keep it).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = dkf.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> central.view("P").shape, central.view("P").flags.writeable
        ((1, 6, 6), False)
        """
        return state_view(self, name, {"x_hat": "_x", "P": "_P"})

    def predict(self, U: ArrayLike) -> None:
        """Prediction with the applied inputs.

        Parameters
        ----------
        U : (runs, N, p) array_like
            The inputs every agent applied.

        Raises
        ------
        ValueError
            Bad shape of `U`, or NaN/inf in the result (naming `U` when it holds them).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = dkf.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> central.predict(np.ones((1, 3, 1)))                    # p = dt^2 / 2, v = dt
        >>> central.x_hat[0, 0]
        array([0.005, 0.1  ])
        """
        model, B = self._model, self._B
        Ut = _float_array(U, "U")
        if Ut.shape != (self._x.shape[0], model.n_agents, B.shape[1]):
            raise ValueError(f"Incompatible dimensions of U; expected ({self._x.shape[0]}, {model.n_agents}, "
                             f"{B.shape[1]}) but found {Ut.shape}")
        self._x, self._P = _centralized_predict(model, self._x, self._P, Ut, B)
        if not np.isfinite(self._x).all():
            _finite(Ut, "U")
        _finite_state("centralized prediction", self._x, self._P)

    def update(self, Z: ArrayLike, mask: ArrayLike) -> None:
        """Update with every agent's measurements (information form).

        Parameters
        ----------
        Z : (runs, N, N, m) array_like
            Every agent's measurements.
        mask : (N, N) or (batch, N, N) array_like of bool
            Sensing mask; a mask per run gives every run its own covariance.

        Raises
        ------
        ValueError
            Bad shapes or mask values, or NaN/inf in the result (naming `Z` when it holds them).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous, sensing
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = dkf.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                               0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = dkf.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), graphs.path_graph(3), np.eye(2))
        >>> central.update(Z, mask[0])
        >>> bool(np.trace(central.P[0]) < 6.0)
        True
        """
        model = self._model
        N, m = model.n_agents, model.m
        Zt = _float_array(Z, "Z")
        if Zt.shape != (self._x.shape[0], N, N, m):
            raise ValueError(f"Incompatible dimensions of Z; expected ({self._x.shape[0]}, {N}, {N}, {m}) "
                             f"but found {Zt.shape}")
        S = _check_mask(mask, N)
        if S.shape[0] not in (1, self._x.shape[0]) or self._P.shape[0] not in (1, S.shape[0], self._x.shape[0]):
            raise ValueError(f"mask has batch {S.shape[0]} but there are {self._x.shape[0]} runs and "
                             f"{self._P.shape[0]} covariances")
        self._x, self._P = _centralized_update(model, self._x, self._P, Zt, S)
        if not np.isfinite(self._x).all():
            _finite(Zt, "Z")
        _finite_state("centralized update", self._x, self._P)


# ----------------------------------------------------------------------------
# centralized reference
# ----------------------------------------------------------------------------


def centralized_predict(
    model: TeamFilterModel, x: ArrayLike, P: ArrayLike, U: ArrayLike, B: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Centralized prediction with the applied inputs known exactly.

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`CentralizedTeamFilter`. In a loop, build the filter once,
    ``CentralizedTeamFilter(model, B, x_hat0, P0)``, and call its :meth:`~CentralizedTeamFilter.predict`: the fast path.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    x : (runs, N, m) array_like
        Team estimates.
    P : (batch, M_r, M_r) array_like
        Reduced covariance.
    U : (runs, N, p) array_like
        Applied inputs.
    B : (m, p) array_like
        Input matrix.

    Returns
    -------
    x_pred : (runs, N, m) ndarray
        Predicted estimates.
    P_pred : (batch, M_r, M_r) ndarray
        Predicted covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> x, P = dkf.centralized_predict(model, np.zeros((1, 3, 2)), np.eye(6)[None], np.zeros((1, 3, 1)), agent.B)
    >>> x.shape, P.shape
    ((1, 3, 2), (1, 6, 6))
    """
    model = _check_model(model)
    N, m, Mr = model.n_agents, model.m, model.M_r
    x = _finite(_float_array(x, "x"), "x")
    if x.ndim != 3 or x.shape[1:] != (N, m):
        raise ValueError(f"Incompatible dimensions of x; expected (runs, {N}, {m}) but found {x.shape}")
    P = _check_covariances(P, "P", (None, Mr, Mr), kron=model.kron)
    B = as_matrix(_float_array(B, "B"), "B", (m, None))
    U = _finite(_float_array(U, "U"), "U")
    if U.shape != (x.shape[0], N, B.shape[1]):
        raise ValueError(
            f"Incompatible dimensions of U; expected ({x.shape[0]}, {N}, {B.shape[1]}) but found {U.shape}"
        )
    return finite_result("centralized prediction", *_centralized_predict(model, x, P, U, B))


def _centralized_predict(model, x, P, U, B):
    """:func:`centralized_predict` without checks."""
    N, mr = model.n_agents, model.m_r
    x_pred = x @ model.A.T + U @ B.T
    T = (model.A_r @ P.reshape(P.shape[0], N, mr, N * mr)).reshape(P.shape)
    T = (model.A_r @ np.swapaxes(T, -1, -2).reshape(P.shape[0], N, mr, N * mr)).reshape(P.shape)
    return x_pred, symmetric_part(T + np.kron(np.eye(N), model.Q_r))


def centralized_update(
    model: TeamFilterModel, x_pred: ArrayLike, P_pred: ArrayLike, Z: ArrayLike, mask: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Centralized update with *all* agents' measurements (information form).

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`CentralizedTeamFilter`. In a loop, build the filter once,
    ``CentralizedTeamFilter(model, B, x_hat0, P0)``, and call its :meth:`~CentralizedTeamFilter.update`: the fast path.

    ``P^{-1} = P^-^{-1} + sum_i H_i^T (H_i R H_i^T)^{-1} H_i``,
    ``x = x^- + P sum_i H_i^T (H_i R H_i^T)^{-1} (z_i - H_i x^-)``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    x_pred : (runs, N, m) array_like
        Predicted team estimates.
    P_pred : (batch, M_r, M_r) array_like
        Reduced predicted covariance, positive definite.
    Z : (runs, N, N, m) array_like
        Every agent's measurements.
    mask : (N, N) or (batch, N, N) array_like of bool
        Sensing mask.

    Returns
    -------
    x : (runs, N, m) ndarray
        Updated estimates.
    P : (batch, M_r, M_r) ndarray
        Updated covariance: a lower bound of every agent's.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> x, P = dkf.centralized_update(model, np.zeros((1, 3, 2)), np.eye(6)[None], Z, mask)
    >>> bool(np.trace(P[0]) < 6.0)
    True
    """
    model = _check_model(model)
    N, m, Mr = model.n_agents, model.m, model.M_r
    x_pred = _finite(_float_array(x_pred, "x_pred"), "x_pred")
    if x_pred.ndim != 3 or x_pred.shape[1:] != (N, m):
        raise ValueError(f"Incompatible dimensions of x_pred; expected (runs, {N}, {m}) but found {x_pred.shape}")
    P_pred = _check_covariances(P_pred, "P_pred", (None, Mr, Mr), definite=True, kron=model.kron)
    Zt = _check_estimates(model, Z, "Z")
    S = _check_mask(mask, N)
    if Zt.shape[0] != x_pred.shape[0]:
        raise ValueError(f"Z has {Zt.shape[0]} runs but x_pred has {x_pred.shape[0]}")
    for name, b in (("mask", S.shape[0]), ("Z", Zt.shape[0])):
        if P_pred.shape[0] not in (1, b) and b != 1:
            raise ValueError(f"{name} has batch {b} but P_pred has {P_pred.shape[0]}")
    return finite_result("centralized update", *_centralized_update(model, x_pred, P_pred, Zt, S))


def _centralized_update(model, x_pred, P_pred, Z, S):
    """:func:`centralized_update` without checks (`S` a (batch, N, N) bool mask)."""
    N, m, k = model.n_agents, model.m, model.kron
    Mr = model.M_r
    d = _mask_vec(model, S)  # (batch, N, Mr)
    Dm = d[..., :, None] * d[..., None, :]
    W = np.linalg.inv(Dm * model.R_r + np.eye(Mr) * (1 - d[..., None])) * Dm  # (batch, N, Mr, Mr)
    info = np.linalg.inv(P_pred) + W.sum(axis=1)
    P = symmetric_part(np.linalg.inv(info))
    R_ = x_pred.shape[0]
    innov = (Z - x_pred[:, None]).reshape(R_, N, Mr, k)
    total = (W @ innov).sum(axis=1)  # (runs, Mr, k); W broadcasts over runs when batch = 1
    x = x_pred + (P @ total).reshape(R_, N, m)
    return x, P


# ----------------------------------------------------------------------------
# observability of system (43), Theorem 1
# ----------------------------------------------------------------------------


def observable_agents(A: ArrayLike, BK: ArrayLike, adjacency: ArrayLike, tol: float = 1e-8) -> np.ndarray:
    """Which agents' pairs ``(F_1, H_i)`` of system (43) are observable.

    For an undirected graph, ``L = V Λ V^T`` block-diagonalizes
    ``F_1 = (V ⊗ I)(I ⊗ A - Λ ⊗ BK)(V ⊗ I)^T``. When the blocks
    ``A - λ BK`` of different Laplacian eigenvalues share no eigenvalue and
    each is non-derogatory (true for the double integrator with positive
    gains), the PBH test reduces to the graph: ``(F_1, H_i)`` is observable
    iff, for every Laplacian eigenvalue ``λ`` with eigenvector basis
    ``V_λ``, the rows of ``V_λ`` of the agents in ``N̄_i`` have full column
    rank. Symmetric "twin" agents outside ``N̄_i`` (same neighbours) break it.
    This test is well conditioned; otherwise (directed graphs, or the
    conditions fail) a rank test of the observability matrix of the shifted
    system is used, which can call weakly observable pairs unobservable.

    Parameters
    ----------
    A : (m, m) array_like
        Agent transition matrix.
    BK : (m, m) array_like
        Input matrix times consensus gain.
    adjacency : (N, N) array_like
        Fixed topology (defines ``F_1`` and ``H_i``).
    tol : float
        Relative tolerance of the rank decisions.

    Returns
    -------
    (N,) ndarray of bool

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> dkf.observable_agents(agent.A, agent.B @ K, graphs.star_graph(4))   # leaves see twin leaves
    array([ True, False, False, False])
    """
    A = check_square(_float_array(A, "A"), "A")
    BK = check_square(_float_array(BK, "BK"), "BK", A.shape[0])
    if A.shape[0] == 0:
        raise ValueError("A must be at least 1 x 1 (an agent with no state)")
    tol = check_positive(tol, "tol", "(relative rank tolerance)")
    m = A.shape[0]
    Adj = _check_adjacency(adjacency)
    if Adj.ndim != 2:
        raise ValueError(f"adjacency must be a single (N, N) topology here; got shape {Adj.shape}")
    S = sensing_mask(Adj, allow_isolated=True)
    L = graph_laplacian(Adj)
    # work on the per-axis factor when A = A_r ⊗ I_k and BK = BK_r ⊗ I_k (same rank test)
    for k in range(m, 0, -1):
        if m % k == 0 and _kron_factor(A, k) is not None and _kron_factor(BK, k) is not None:
            A, BK, m = _kron_factor(A, k), _kron_factor(BK, k), m // k
            break
    if np.allclose(Adj, Adj.T):
        graph_test = _graph_observability(A, BK, L, S, tol)
        if graph_test is not None:
            return graph_test
    F1, _ = closed_loop_matrices(A, BK, L)
    out = []
    for row in S:
        H = np.kron(np.eye(row.size)[row], np.eye(m))
        out.append(_observable(F1, H, tol))
    return np.array(out)


def _graph_observability(A, BK, L, S, tol) -> np.ndarray | None:
    """PBH test through the Laplacian eigenvectors (see :func:`observable_agents`); None if not applicable."""
    lam, V = np.linalg.eigh(L)
    scale = max(1.0, float(np.max(np.abs(lam))))
    cuts = np.flatnonzero(np.diff(lam) > 1e-7 * scale) + 1
    groups = np.split(np.arange(lam.size), cuts)
    m = A.shape[0]
    lam_g = np.array([lam[g].mean() for g in groups])
    M = A[None] - lam_g[:, None, None] * BK[None]  # (G, m, m)
    mu = np.linalg.eigvals(M)  # (G, m)
    if m > 1:  # non-derogatory: every eigenvalue has a one-dimensional eigenspace
        sv = np.linalg.svd(M[:, None] - mu[:, :, None, None] * np.eye(m), compute_uv=False)
        if np.any(sv[..., m - 2] <= 1e-6 * np.maximum(1.0, sv[..., 0])):
            return None
    gid = np.repeat(np.arange(len(groups)), m)
    dist = np.abs(mu.reshape(-1)[:, None] - mu.reshape(-1)[None, :])
    if np.any(dist[gid[:, None] != gid[None, :]] < 1e-6):
        return None
    Sf = S.astype(float)
    out = np.ones(S.shape[0], dtype=bool)
    for g in groups:
        Vg = V[:, g]
        rows = Sf[:, :, None] * Vg[None]  # rows of V_g outside N̄_i zeroed (singular values unchanged)
        out &= np.linalg.svd(rows, compute_uv=False)[:, -1] > tol
    return out


def require_observable(A: ArrayLike, BK: ArrayLike, adjacency: ArrayLike) -> None:
    """Raise ``ValueError`` naming the agents for which system (43) is unobservable.

    Parameters
    ----------
    A : (m, m) array_like
        Agent transition matrix.
    BK : (m, m) array_like
        Input matrix times consensus gain.
    adjacency : (N, N) array_like
        Sensing graph.

    Raises
    ------
    ValueError
        Naming the agents whose filter cannot estimate the team.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> try:
    ...     dkf.require_observable(agent.A, agent.B @ K, graphs.star_graph(4))
    ... except ValueError as exc:
    ...     print(str(exc)[:22])
    system (43) (F_1, H_i)
    """
    Adj = _check_adjacency(adjacency)
    if Adj.ndim != 2:
        raise ValueError(f"adjacency must be a single (N, N) topology here; got shape {Adj.shape}")
    sensing_mask(Adj)  # isolated agents first, with their own message
    ok = observable_agents(A, BK, adjacency)
    if not np.all(ok):
        bad = np.flatnonzero(~ok).tolist()
        raise ValueError(
            f"system (43) (F_1, H_i) is not observable for agent(s) {bad} with this topology (F_1 from A, BK "
            "and the adjacency's Laplacian, H_i from the adjacency): "
            "Theorem 1 does not apply and the estimation-based loop needs an observable graph "
            "(symmetric neighbourhoods, e.g. a star seen from a leaf, hide modes)"
        )


def lyapunov_v(error: ArrayLike, Sigma_r: ArrayLike, kron: int = 1) -> np.ndarray:
    """Lyapunov function of eq. (45), ``V = e_i^T Σ_i^{-1} e_i`` (= the NEES).

    Parameters
    ----------
    error : (..., M) array_like
        ``e_i = X - X̂_i`` (full team dimension ``M = kron M_r``).
    Sigma_r : (..., M_r, M_r) array_like
        Reduced covariance ``Σ̄_i`` (``Σ_i = Σ̄_i ⊗ I_kron``).
    kron : int
        Kronecker factor of the model.

    Returns
    -------
    (...) ndarray
        ``V``, chi-square distributed with ``M`` dof for a consistent filter.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_kf as dkf
    >>> float(dkf.lyapunov_v(np.ones(6), np.eye(6)))
    6.0
    """
    kron = check_positive_int(kron, "kron")
    e = _finite(_float_array(error, "error"), "error")
    P = check_covariance(_float_array(Sigma_r, "Sigma_r"), "Sigma_r", definite=True)
    Mr = P.shape[-1]
    if e.ndim < 1 or e.shape[-1] != Mr * kron:
        raise ValueError(
            f"Incompatible dimensions of error; expected (..., {Mr * kron}) = Sigma_r size {Mr} x kron {kron} "
            f"but found {e.shape}"
        )
    try:
        np.broadcast_shapes(e.shape[:-1], P.shape[:-2])
    except ValueError:
        raise ValueError(f"the batch axes of error {e.shape} and Sigma_r {P.shape} do not broadcast") from None
    return _lyapunov_v(e, P, kron)


def _lyapunov_v(e, P, kron):
    """:func:`lyapunov_v` without checks."""
    Mr = P.shape[-1]
    E = e.reshape(*e.shape[:-1], Mr, kron)
    sol = np.linalg.solve(P, E)
    return np.einsum("...ik,...ik->...", E, sol)


def team_nees(model: TeamFilterModel, X_true: ArrayLike, X_hat: ArrayLike, Sigma_i: ArrayLike) -> np.ndarray:
    """NEES of every agent's team estimate: ``(runs, N)``, chi-square with ``m N`` dof.

    Checks the covariance in full on every call (an eigenvalue test); a :class:`TeamFilter`
    gives the same from its own state without one: :meth:`TeamFilter.nees`.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    X_true : (runs, N, m) array_like
        True states.
    X_hat : (runs, N, N, m) array_like
        Every agent's team estimate.
    Sigma_i : (batch, N, M_r, M_r) array_like
        Their reduced covariances, positive definite.

    Returns
    -------
    (runs, N) ndarray
        The NEES of each agent's estimate.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> dkf.team_nees(model, np.zeros((1, 3, 2)), X_post, dkf.agent_covariances(model, Sigma_post)).shape
    (1, 3)
    """
    model = _check_model(model)
    N, m, Mr = model.n_agents, model.m, model.M_r
    X_true = _finite(_float_array(X_true, "X_true"), "X_true")
    if X_true.ndim != 3 or X_true.shape[1:] != (N, m):
        raise ValueError(f"Incompatible dimensions of X_true; expected (runs, {N}, {m}) but found {X_true.shape}")
    X = _check_estimates(model, X_hat, "X_hat")
    _check_runs(X_true, X, "X_true", "X_hat")
    Sig = _check_covariances(Sigma_i, "Sigma_i", (None, N, Mr, Mr), definite=True, kron=model.kron)
    if Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"Sigma_i has batch {Sig.shape[0]} but X_hat has {X.shape[0]} runs")
    return _team_nees(model, X_true, X, Sig)


def _team_nees(model, X_true, X_hat, Sigma_i):
    """:func:`team_nees` without checks."""
    with np.errstate(over="ignore", invalid="ignore"):
        e = (X_true[:, None] - X_hat).reshape(X_true.shape[0], model.n_agents, -1)
        out = _lyapunov_v(e, Sigma_i, model.kron)
    if not np.isfinite(out).all():
        raise ValueError(f"X_true: the NEES overflows floating point (largest error {float(np.abs(e).max()):.3g}); "
                         "the true states and the estimates must be of moderate magnitude (rescale the units)")
    return out


def f2_cross(model: TeamFilterModel, Sigma: ArrayLike, laplacian: ArrayLike) -> np.ndarray:
    """``F_2 E[e e_i^T]`` for every agent ``i``: reduced, shape ``(batch, N, M_r, M_r)``.

    Checks the covariance in full on every call (an eigenvalue test); a :class:`TeamFilter`
    gives the same from its own state without one: :meth:`TeamFilter.f2_cross`.

    Used to form the map ``C_i = E[e e_i^T] Σ_i^{-1}`` of Lemma 1 without
    storing the augmented covariance: ``F_2 C_i = F_2 E[e e_i^T] Σ_i^{-1}``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`team_filter_model`).
    Sigma : (batch, N M_r, N M_r) array_like
        Reduced augmented covariance.
    laplacian : (N, N) or (batch, N, N) array_like
        Topology.

    Returns
    -------
    (batch, N, M_r, M_r) ndarray
        ``F_2 E[e e_i^T]`` per agent.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = dkf.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> dkf.f2_cross(model, Sigma_post, Lap).shape
    (1, 3, 6, 6)
    """
    model = _check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = _check_laplacian(laplacian, N, undirected=True)
    Sig = _check_covariances(Sigma, "Sigma", (None, N * Mr, N * Mr), kron=model.kron)
    _check_batch(L, Sig, "laplacian", "Sigma")
    return _f2_cross(model, Sig, L)


def _f2_cross(model, Sig, L):
    """:func:`f2_cross` without checks."""
    N, mr, Mr = model.n_agents, model.m_r, model.M_r
    Lb = L if L.ndim == 3 else L[None]
    nb = Sig.shape[0]
    T = Sig.reshape(nb, N, N, mr * N * Mr)
    U = (Lb[:, None] @ T).reshape(nb, N, N, mr, N * Mr)
    Ud = U[:, np.arange(N), np.arange(N)]  # (batch, N_j, mr, N*Mr): sum_l L_jl Σ[j, l]
    F2S = (model.BK_r @ Ud).reshape(nb, Mr, N, Mr)  # rows: F_2 Σ
    return np.moveaxis(F2S, 2, 1)  # (batch, N_i, Mr, Mr): column block i


def theorem1_min_eigenvalues(
    model: TeamFilterModel, laplacian: ArrayLike, KH: ArrayLike, Sigma_i: ArrayLike, F2_cross: ArrayLike
) -> dict[str, np.ndarray]:
    """Smallest eigenvalues of ``M_i[k+1]`` (eq. (49)) along a run.

    ``M_i[k+1] = Σ_i[k]^{-1} - 𝓕_{i,1}^T 𝓕_{i,2}^T Σ_i[k+1]^{-1} 𝓕_{i,2} 𝓕_{i,1}``
    with ``𝓕_{i,1}[k] = F_1 + F_2 C_i[k]`` and ``𝓕_{i,2}[k+1] = I - G_i H_i[k+1]``.

    ``C_i`` of Lemma 1 (eq. (44)) is taken as the regression map
    ``C_i[k] = E[e e_i^T] Σ_i[k]^{-1}``: then ``α_i = e - C_i e_i`` is
    uncorrelated with ``e_i``, which eqs. (48) and (51) of the proof need, and
    ``C_i[0] = 1_N ⊗ I`` when all agents start from a common estimate. (The
    literal recursion ``C_i[k+1] = 𝓕 C_i (𝓕_{i,2} 𝓕_{i,1})^{-1}`` is a ratio of
    different agents' error-transition products and grows without bound within a
    few steps.) With this choice eq. (59) shows ``M_i`` is positive definite
    whenever the covariance recursion is right, so the check is a consistency
    test of eqs. (29)-(34).

    Parameters
    ----------
    model : TeamFilterModel
        The team model.
    laplacian : (N, N) array_like
        Fixed topology.
    KH : (T+1, N, M_r, M_r) array_like
        Reduced ``G_i H_i[k]`` (entry 0 unused).
    Sigma_i : (T+1, N, M_r, M_r) array_like
        Reduced posterior ``Σ̄_i[k]``.
    F2_cross : (T+1, N, M_r, M_r) array_like
        ``F_2 E[e e_i^T]`` from :func:`f2_cross`.

    Returns
    -------
    dict with
        ``min_eig`` (T, N): smallest eigenvalue of ``M_i[k+1]``;
        ``min_eig_rel`` (T, N): smallest eigenvalue of
        ``Σ_i^{1/2} M_i Σ_i^{1/2}`` (scale-free, at most 1).

    Examples
    --------
    >>> from mascore.papers import song2023
    >>> r = song2023.fig2(seed=0, n_runs=2, horizon=4.0)
    >>> sorted(song2023.theorem1(r))                                # via this function
    ['min_eig', 'min_eig_rel']
    """
    model = _check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = _check_laplacian(laplacian, N)
    if L.ndim != 2:
        raise ValueError(f"laplacian must be a single fixed ({N}, {N}) topology here; got shape {L.shape}")
    KH = _finite(_float_array(KH, "KH"), "KH")
    Sig = _check_covariances(Sigma_i, "Sigma_i", (None, N, Mr, Mr), definite=True, kron=model.kron)
    F2C_all = _finite(_float_array(F2_cross, "F2_cross"), "F2_cross")
    if Sig.shape[0] < 2:
        raise ValueError(f"Sigma_i must hold at least two steps (T+1 >= 2); got shape {Sig.shape}")
    for name, arr in (("KH", KH), ("F2_cross", F2C_all)):
        if arr.shape != Sig.shape:
            raise ValueError(
                f"Incompatible dimensions of {name}; KH, Sigma_i and F2_cross must all have shape "
                f"(T+1, {N}, {Mr}, {Mr}); got {name} {arr.shape} and Sigma_i {Sig.shape}"
            )
    F1 = np.kron(np.eye(N), model.A_r) - np.kron(L, model.BK_r)
    eye = np.eye(Mr)
    Sig_inv = np.linalg.inv(Sig)
    F2C = F2C_all[:-1] @ Sig_inv[:-1]  # F_2 C_i[k]
    T = (eye - KH[1:]) @ (F1 + F2C)  # 𝓕_{i,2}[k+1] 𝓕_{i,1}[k], (T, N, Mr, Mr)
    M = Sig_inv[:-1] - np.swapaxes(T, -1, -2) @ Sig_inv[1:] @ T
    root = np.linalg.cholesky(Sig[:-1])
    rel = np.swapaxes(root, -1, -2) @ M @ root
    out = {
        "min_eig": np.linalg.eigvalsh(symmetric_part(M))[..., 0],
        "min_eig_rel": np.linalg.eigvalsh(symmetric_part(rel))[..., 0],
    }
    finite_result("Theorem 1 eigenvalue computation", *out.values())
    return out


# ----------------------------------------------------------------------------
# private helpers
# ----------------------------------------------------------------------------


def _kron_factor(M: np.ndarray, k: int) -> np.ndarray | None:
    """``M_r`` with ``M = M_r ⊗ I_k`` over the last two axes, or ``None``."""
    M = np.asarray(M, dtype=float)
    if k == 1:
        return M
    r, c = M.shape[-2:]
    if r % k or c % k:
        return None
    blocks = M.reshape(*M.shape[:-2], r // k, k, c // k, k)
    red = blocks[..., :, 0, :, 0]
    rebuilt = red[..., :, None, :, None] * np.eye(k)[:, None, :]
    scale = max(1.0, float(np.max(np.abs(M)))) if M.size else 1.0
    if np.allclose(blocks, rebuilt, rtol=0, atol=1e-12 * scale):
        return red
    return None


def _finite_state(what: str, *arrays: np.ndarray, diagonal_only: bool = False) -> None:
    """:func:`mascore._validation.finite_result` on a step's results (estimates first, covariance second).

    With `diagonal_only` the covariance is tested on its diagonal only: the update that follows
    every prediction tests all of it (a NaN of the prediction stays in place through the update).
    """
    if diagonal_only:
        arrays = (arrays[0], np.diagonal(arrays[1], axis1=-2, axis2=-1), *arrays[2:])
    finite_result(what, *arrays)


def _check_model(model: object) -> TeamFilterModel:
    if not isinstance(model, TeamFilterModel):
        raise TypeError(
            f"model must be a TeamFilterModel (build it with team_filter_model); got {type(model).__name__}"
        )
    return model


def _check_estimates(model: TeamFilterModel, X: ArrayLike, name: str) -> np.ndarray:
    """Team estimates or measurements ``(runs, N, N, m)``, finite."""
    X = _float_array(X, name)
    N, m = model.n_agents, model.m
    if X.ndim != 4 or X.shape[1:] != (N, N, m):
        raise ValueError(f"Incompatible dimensions of {name}; expected (runs, {N}, {N}, {m}) but found {X.shape}")
    return _finite(X, name)


def _check_covariances(P: ArrayLike, name: str, shape: tuple, definite: bool = False, kron: int = 1) -> np.ndarray:
    """A stack of covariances of the given shape (None: any batch size >= 1), symmetric PSD (or PD), checked in full.

    The error says what to do for the two common slips: a missing batch axis, and a full covariance
    where the model works on the reduced one (``kron > 1``).
    """
    P = _float_array(P, name)
    if P.ndim != len(shape) or any(w is not None and g != w for g, w in zip(P.shape, shape)) or P.shape[0] == 0:
        want = tuple("batch" if w is None else w for w in shape)
        hint = ""
        if P.ndim == len(shape) - 1 and P.shape == tuple(shape[1:]):
            hint = f"; add the leading batch axis ({name}[None]) for one run"
        elif kron > 1 and P.ndim >= 2 and P.shape[-1] == kron * shape[-1]:
            hint = (f"; this model works on the reduced covariance (its Kronecker factor is {kron}): "
                    f"pass mascore.distributed_kf.reduce_covariance({name}, {kron})")
        raise ValueError(f"Incompatible dimensions of {name}; expected {want} but found {P.shape}".replace("'", "")
                         + hint)
    return check_covariance(P, name, definite=definite)


def _check_runs(X: np.ndarray, Y: np.ndarray, xname: str, yname: str) -> None:
    if X.shape[0] != Y.shape[0]:
        raise ValueError(f"{yname} has {Y.shape[0]} runs but {xname} has {X.shape[0]}")


def _check_batch(L: np.ndarray, Sig: np.ndarray, lname: str, sname: str, X: np.ndarray | None = None) -> None:
    """A batch of topologies must match the covariance batch and the runs (or be a single topology)."""
    if L.ndim == 3 and L.shape[0] not in (1, Sig.shape[0]):
        raise ValueError(
            f"{lname} has {L.shape[0]} topologies but {sname} has batch {Sig.shape[0]}: one covariance per "
            "topology (or a single topology for all)"
        )
    if X is not None and L.ndim == 3 and L.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"{lname} has {L.shape[0]} topologies but there are {X.shape[0]} runs")
    if X is not None and Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"{sname} has batch {Sig.shape[0]} but there are {X.shape[0]} runs")


def _check_laplacian(L: ArrayLike, N: int, name: str = "laplacian", any_batch: bool = False,
                     undirected: bool = False) -> np.ndarray:
    """One Laplacian ``(N, N)`` or a batch ``(batch, N, N)`` (``(..., N, N)`` with `any_batch`): finite, rows
    summing to zero, off-diagonal entries <= 0.

    Directed graphs are allowed unless `undirected` (the team filter: Song et al. assume a common sensing
    range, hence an undirected graph). An adjacency matrix passed by mistake is named as such.
    """
    L = _float_array(L, name)
    if (L.ndim < 2 or (L.ndim > 3 and not any_batch) or L.shape[-2:] != (N, N) or L.size == 0):
        want = f"(..., {N}, {N})" if any_batch else f"({N}, {N}) or (batch, {N}, {N})"
        raise ValueError(f"Incompatible dimensions of {name}; expected {want} but found {L.shape}")
    _finite(L, name)
    tol = 1e-8 * max(1.0, float(np.abs(L).max()))
    off = L.copy()
    off[..., np.arange(N), np.arange(N)] = 0.0
    if off.max() > tol or np.abs(L.sum(axis=-1)).max() > tol:
        if np.all(L >= 0) and np.all(L[..., np.arange(N), np.arange(N)] == 0):
            raise ValueError(f"{name} looks like an adjacency matrix; pass mascore.graphs.laplacian(A) instead")
        raise ValueError(
            f"{name} must be a graph Laplacian: rows summing to zero and off-diagonal entries <= 0 "
            "(pass mascore.graphs.laplacian(A))"
        )
    if undirected and np.abs(L - np.swapaxes(L, -1, -2)).max() > tol:
        raise ValueError(f"{name} must be symmetric (an undirected graph): Song et al.'s team filter assumes that "
                         f"every agent senses the agents that sense it (a common sensing range, Sec. II); got a "
                         f"directed Laplacian (symmetrize the adjacency, e.g. A + A.T > 0)")
    return L


def _check_mask(mask: ArrayLike, N: int) -> np.ndarray:
    S = _check_mask_values(mask, "mask")
    if S.shape[-2:] != (N, N) or S.ndim not in (2, 3):
        raise ValueError(
            f"Incompatible dimensions of mask; expected ({N}, {N}) or (batch, {N}, {N}) but found {S.shape}"
        )
    if not np.all(S[..., np.arange(N), np.arange(N)]):
        raise ValueError("mask must include every agent itself (closed neighbourhoods); use sensing_mask(A)")
    return S if S.ndim == 3 else S[None]


def _mask_vec(model: TeamFilterModel, S: np.ndarray) -> np.ndarray:
    """(batch, N, N) mask -> (batch, N, M_r) 0/1 vectors ``diag(D_i)`` in reduced coordinates."""
    return np.repeat(S, model.m_r, axis=-1).astype(float)


def _joseph(Sig: np.ndarray, KH: np.ndarray, R: np.ndarray) -> np.ndarray:
    Psi = np.eye(Sig.shape[-1]) - KH
    KHt = np.swapaxes(KH, -1, -2)
    return symmetric_part(Psi @ Sig @ np.swapaxes(Psi, -1, -2) + KH @ R @ KHt)


def _apply_gain(model: TeamFilterModel, X_pred: np.ndarray, Z: np.ndarray, KH: np.ndarray) -> np.ndarray:
    """``X̂_i = X̂_i^- + G_i H_i (Z_i - X̂_i^-)`` with the reduced gain on the Kronecker axes."""
    N, k, Mr = model.n_agents, model.kron, model.M_r
    innov = (Z - X_pred).reshape(X_pred.shape[0], N, Mr, k)
    return X_pred + (KH @ innov).reshape(X_pred.shape)


def _F1_means(model: TeamFilterModel, X: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``F_1 X̂_i`` for every run and agent: ``A x̂_{i,j} - BK sum_l L_jl x̂_{i,l}`` (eq. (14))."""
    N, m = model.n_agents, model.m
    Lx = L[:, None] if L.ndim == 3 else L  # (batch,1,N,N) or (N,N)
    LX = Lx @ X.reshape(X.shape[0], N, N, m) if L.ndim == 2 else np.matmul(Lx, X)
    return X @ model.A.T - LX @ model.BK.T


def _F1_rows(model: TeamFilterModel, T: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Apply ``F_1`` (reduced) to tensors ``T[..., j, a, c]`` along (j, a).

    ``(F_1 T)[j] = A T[j] - BK sum_l L_jl T[l]``; `L` broadcasts as ``(..., N, N)``.
    """
    shp = T.shape
    N, mr, C = shp[-3:]
    LT = (L @ T.reshape(*shp[:-3], N, mr * C)).reshape(*np.broadcast_shapes(L.shape[:-2], shp[:-3]), N, mr, C)
    return model.A_r @ T - model.BK_r @ LT


def _agent_covariances(model: TeamFilterModel, Sig: np.ndarray) -> np.ndarray:
    """Diagonal blocks of reduced augmented covariances ``(batch, N M_r, N M_r)`` -> ``(batch, N, M_r, M_r)``."""
    N, Mr = model.n_agents, model.M_r
    blocks = Sig.reshape(Sig.shape[0], N, Mr, N, Mr)
    return np.moveaxis(blocks[:, np.arange(N), :, np.arange(N), :], 0, 1)


#: Augmented covariances up to this size (N M_r) are propagated with dense products, larger ones one row
#: block at a time with the sparse F_1, F_2 (the crossover on one core is near N M_r = 256-512).
_DENSE_MAX = 384


def _phi_blocks(model: TeamFilterModel, L: np.ndarray, rows: bool) -> tuple:
    """What the estimation-based prediction needs of one topology ``L`` ``(N, N)``.

    ``Φ = I_N ⊗ F_1 + 1_N ⊗ F_2`` with ``F_1 = I ⊗ A - L ⊗ BK`` and ``(F_2 e)[j] = BK sum_l L_jl e[j, l]``:
    a row of either block has about ``m_r (1 + nnz(L_j))`` non-zeros instead of ``M_r``.

    Returns ``(Φ,)`` dense for a small team; for the row-block path ``(F1aug, F_1, F_1^T, F_2, K2t)``:
    ``F1aug = [F_1, I]`` sparse ``(M_r, 2 M_r)`` with the identity entry first in every row, dense
    ``F_1`` and ``F_1^T``, sparse ``F_2`` ``(M_r, N M_r)`` and ``K2t[j] = (L_j ⊗ BK)^T`` ``(N, M_r, m_r)``
    (column block ``j`` of ``X F_2^T`` is ``X[:, j] @ K2t[j]`` for ``X`` of shape ``(M_r, N M_r)``).
    """
    from scipy import sparse

    N, mr, Mr = model.n_agents, model.m_r, model.M_r
    F1 = sparse.csr_array(sparse.kron(sparse.identity(N), model.A_r) - sparse.kron(sparse.csr_array(L), model.BK_r))
    j, l = np.nonzero(L)
    a, b = np.nonzero(np.ones((mr, mr)))
    rws = (j[:, None] * mr + a[None, :]).ravel()
    cols = (j[:, None] * Mr + l[:, None] * mr + b[None, :]).ravel()
    vals = (L[j, l][:, None] * model.BK_r[a, b][None, :]).ravel()
    F2 = sparse.csr_array((vals, (rws, cols)), shape=(Mr, N * Mr))
    if not rows:
        return (np.kron(np.eye(N), F1.toarray()) + np.kron(np.ones((N, 1)), F2.toarray()),)
    counts = np.diff(F1.indptr)
    indptr = np.concatenate([[0], np.cumsum(counts + 1)]).astype(F1.indptr.dtype)
    first = indptr[:-1]
    rest = np.ones(indptr[-1], dtype=bool)
    rest[first] = False
    indices = np.empty(indptr[-1], dtype=F1.indices.dtype)
    data = np.empty(indptr[-1])
    indices[first], data[first] = Mr + np.arange(Mr), 1.0
    indices[rest], data[rest] = F1.indices, F1.data
    F1aug = sparse.csr_array((data, indices, indptr), shape=(Mr, 2 * Mr))
    F1d = F1.toarray()
    K2 = (L[:, None, :, None] * model.BK_r[None, :, None, :]).reshape(N, mr, Mr)
    K2t = np.ascontiguousarray(np.swapaxes(K2, -1, -2))
    return F1aug, F1d, F1d.T, F2, K2t


def _gemm_acc(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> None:
    """``C += A @ B`` in place for C-contiguous `C` (BLAS ``dgemm`` with ``beta = 1`` on the transposes)."""
    from scipy.linalg.blas import dgemm

    Ct = C.T  # Fortran-contiguous: Ct += B^T A^T
    r = dgemm(1.0, B.T, A.T, 1.0, Ct, overwrite_c=1)
    if r.ctypes.data != Ct.ctypes.data:  # pragma: no cover - dgemm had to copy
        Ct[...] = r


def _observable(F: np.ndarray, H: np.ndarray, tol: float) -> bool:
    """Rank test of the observability matrix ``[H; H F; ...; H F^{n-1}]``.

    ``(F, H)`` and ``(F - I, H)`` have the same unobservable subspace; the
    shifted matrix is used, scaled to unit norm, because a sampled system has
    ``F ≈ I`` and its plain powers hide the information in tiny differences.
    Each block is also rescaled (rank unchanged); one SVD decides.
    """
    n = F.shape[0]
    G = F - np.eye(n)
    gn = np.linalg.norm(G)
    F = G / gn if gn > 0 else G
    blocks, blk = [], H
    for _ in range(n):
        nrm = np.linalg.norm(blk)
        if nrm == 0:
            break
        blk = blk / nrm
        blocks.append(blk)
        blk = blk @ F
    s = np.linalg.svd(np.vstack(blocks), compute_uv=False)
    return int(np.sum(s > tol * s[0])) == n
