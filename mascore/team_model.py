"""The team model every agent knows (Song et al. 2023, Assumption 1), checked once when built.

:class:`TeamFilterModel` holds the agent dynamics ``A``, the closed-loop term ``BK``, the
per-agent process noise ``Q`` and the noise ``R`` of one observer's measurement vector, with
the Kronecker factor the structured recursions run on (``A = A_r ⊗ I_kron``, one factor per
spatial axis) and, for partial sensing, the agents' output matrices ``C_j`` (``z_ij = C_j x_j + nu_ij``;
none: full states, eq. (2)). :func:`team_filter_model` builds it from the agent, its gain and its noises
and finds the factor; :func:`closed_loop_matrices` gives the dense ``F_1`` and ``F_2`` of
eqs. (11), (28); :func:`reduce_covariance` and :func:`expand_covariance` move a covariance
between the full and the per-axis form. The filters that run on this model are in
:mod:`mascore.distributed_kf` (every agent's whole-team filter),
:mod:`mascore.centralized_team_filter` (the reference) and :mod:`mascore.team_observability`
(when Theorem 1 applies).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from ._systems import design_args, full_state_only, output_matrices
from ._validation import (
    Frozen,
    as_matrix,
    check_covariance,
    check_flag,
    check_laplacian,
    check_positive_int,
    check_square,
    frozen_copy,
    kron_factor,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .sensing import team_noise_covariance

__all__ = [
    "TeamFilterModel",
    "team_filter_model",
    "closed_loop_matrices",
    "reduce_covariance",
    "expand_covariance",
]


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
    R : (p N, p N) array_like
        Covariance of one observer's noise vector ``nu_i``, symmetric positive definite
        (``p = m`` for full-state sensing).
    n_agents : int
        N >= 2.
    kron : int
        Kronecker factor used by the structured recursions: ``A``, ``BK``, ``Q``, ``R``
        (and ``C``) must all be of the form ``X_r ⊗ I_kron``.
    C : (N, p, m) array_like, optional
        Output matrix of every agent, ``z_ij = C_j x_j + nu_ij`` (partial sensing); ``None``
        (default): full states, ``C_j = I_m`` (Song et al. eq. (2)).

    Attributes
    ----------
    A_r, BK_r, Q_r, R_r : ndarray
        The reduced matrices (read-only views of the full ones).
    C_r : (N, p_r, m_r) ndarray or None
        The reduced output matrices (``None`` for full-state sensing).

    Raises
    ------
    ValueError
        Shapes that do not fit together, non-finite entries, a covariance that is not
        symmetric positive (semi)definite, or a matrix not of the form ``X_r ⊗ I_kron``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
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
    C: np.ndarray | None = None
    A_r: np.ndarray = field(init=False, repr=False, compare=False)
    BK_r: np.ndarray = field(init=False, repr=False, compare=False)
    Q_r: np.ndarray = field(init=False, repr=False, compare=False)
    R_r: np.ndarray = field(init=False, repr=False, compare=False)
    C_r: np.ndarray | None = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        A = check_square(_float_array(self.A, "A"), "A")
        m = A.shape[0]
        BK = check_square(_float_array(self.BK, "BK"), "BK", m)
        Q = check_covariance(_float_array(self.Q, "Q"), "Q", size=m)
        if Q.ndim != 2:
            raise ValueError(f"Q must be a single ({m}, {m}) matrix; got shape {Q.shape}")
        n_agents = check_positive_int(self.n_agents, "n_agents", minimum=2)
        C = None if self.C is None else output_matrices(self.C, m, n_agents)
        p = m if C is None else C.shape[1]
        R = check_covariance(_float_array(self.R, "R"), "R", size=p * n_agents, definite=True)
        if R.ndim != 2:
            raise ValueError(f"R must be a single ({p * n_agents}, {p * n_agents}) matrix; got shape {R.shape}")
        kron = check_positive_int(self.kron, "kron")
        if m % kron:
            raise ValueError(f"kron must divide the agent state size m = {m}; got kron={kron}")
        full = {"A": frozen_copy(A), "BK": frozen_copy(BK), "Q": frozen_copy(Q), "R": frozen_copy(R)}
        if C is not None:
            full["C"] = frozen_copy(C)
        for name, M in full.items():
            red = kron_factor(M, kron)
            if red is None:
                raise ValueError(f"{name} is not of the form {name}_r ⊗ I_{kron} (kron={kron}); "
                                 "build the model with team_filter_model, which finds the factor")
            self._set(**{name: M, f"{name}_r": red})  # a view of the read-only copy: read-only too
        if C is None:
            self._set(C=None, C_r=None)
        self._set(n_agents=n_agents, kron=kron)

    @property
    def m(self) -> int:
        """Agent state dimension."""
        return self.A.shape[0]

    @property
    def p(self) -> int:
        """Size of one measurement ``z_ij`` (``m`` for full-state sensing)."""
        return self.m if self.C is None else self.C.shape[1]

    @property
    def full_state(self) -> bool:
        """Whether every measurement is a full state (Song et al. eq. (2)), i.e. no output matrix."""
        return self.C is None

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
    *,
    C: ArrayLike | None = None,
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
    R : (p, p) or (p N, p N) array_like
        Measurement-noise covariance per measured agent, or of the whole
        vector ``nu_i`` (the paper's ``R``); symmetric positive definite.
        ``p = m`` without `C`.
    n_agents : int
        N >= 2.
    reduce : bool
        Look for a factor ``A = A_r ⊗ I_k`` shared by ``A, BK, Q, R`` (and `C`) (true by
        default); ``False`` forces the unreduced recursion. An output matrix not of the form
        ``C_r ⊗ I_k`` lowers the factor (down to 1: the full form).
    C : (p, m) or (N, p, m) array_like, optional
        Output matrix of the measurements, ``z_ij = C_j x_j + nu_ij``: one for every agent or
        one per agent (e.g. positions only of a planar double integrator,
        ``C = [I_2 0]``). ``None`` (default) or the identity: full states, Song et al.'s eq. (2).
        Taken by the estimation-based loop and the centralized team filter; the
        measurement-based loop refuses it (its control, eq. (5), steers with full-state
        measurements).

    Returns
    -------
    TeamFilterModel
        The validated model with its Kronecker factor.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, rendezvous
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(2, 0.1)                       # planar: the x and y axes decouple
    >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 2), np.eye(4),
    ...                                      np.eye(4), n_agents=5)
    >>> model.kron, model.M_r                                   # the recursions run on one axis
    (2, 10)
    >>> C = np.hstack([np.eye(2), np.zeros((2, 2))])                  # positions only: [I 0] = [1 0] ⊗ I_2
    >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 2), np.eye(4),
    ...                                      np.eye(2), n_agents=5, C=C)
    >>> model.p, model.kron, model.C_r.shape
    (2, 2, (5, 1, 2))
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
    check_flag(reduce, "reduce")
    C_all = None if C is None else output_matrices(C, m, n_agents)
    if C_all is not None and C_all.shape[1] == m and np.array_equal(C_all, np.broadcast_to(np.eye(m), C_all.shape)):
        C_all = None  # the identity: full states, the paper's own path
    R_arr = _float_array(R, "R")
    if C_all is None and R_arr.ndim == 2 and R_arr.shape[0] == R_arr.shape[1] and 0 < R_arr.shape[0] < m:
        raise ValueError(full_state_only(m, R_arr.shape))  # partial sensing without an output matrix
    p = m if C_all is None else C_all.shape[1]
    try:
        R_team = team_noise_covariance(R, n_agents, p)
    except ValueError as exc:
        if C_all is None:
            raise
        raise ValueError(f"{exc} (p = {p}: the rows of the output matrix C)") from None
    check_covariance(R_team, "R", definite=True)
    BK = B @ K
    kron = 1
    if reduce:
        for k in range(m, 1, -1):
            if m % k == 0 and all(kron_factor(X, k) is not None
                                  for X in (A, BK, Q, R_team, *(() if C_all is None else (C_all,)))):
                kron = k
                break
    return TeamFilterModel(A=A, BK=BK, Q=Q, R=R_team, n_agents=int(n_agents), kron=kron, C=C_all)


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
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> F1, F2 = team_model.closed_loop_matrices(agent.A, agent.B @ K, Lap)
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
    >>> from mascore import team_model
    >>> team_model.reduce_covariance(np.kron([[2.0, 1.0], [1.0, 2.0]], np.eye(2)), kron=2)
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
    red = kron_factor(P, kron)
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
    >>> from mascore import team_model
    >>> P = team_model.expand_covariance([[2.0, 1.0], [1.0, 2.0]], kron=2)
    >>> P.shape, bool(np.allclose(team_model.reduce_covariance(P, 2), [[2.0, 1.0], [1.0, 2.0]]))
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
