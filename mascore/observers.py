"""Minimum-energy observers and the LQR-dual distributed observer of Vlahakis and Halikias.

Agents (eq. (26)): ``x_i' = A x_i + Bbar d_i``, ``y_i = C x_i + n_i`` with a
disturbance ``d_i`` weighted by ``R`` and a measurement noise ``n_i`` weighted
by ``Q`` in the minimum-energy cost (20). The single-agent optimal observer
(eqs. (23)-(25)) is ``x_e' = (A - L C) x_e + L y`` with ``L = S C^T Q`` and
``S`` the solution of the dual ARE ``A S + S A^T + Bbar R^{-1} Bbar^T -
S C^T Q C S = 0``; its optimal cost is ``trace(S)``.

The distributed observer (eq. (37), network form (42)) adds a coupling through
the graph Laplacian ``Lap``: the estimation errors obey
``E' = A_e E + ...`` with ``A_e = I_N (x) (A - L C) - Lap (x) L Phi C``.
With ``Lap = V diag(lambda) V^T`` the design splits into N ``n``-state modes
(eqs. (43)-(55)); ``Phi`` (m x m) comes from the LMI program (56)-(62), which
is solved once per *distinct* Laplacian eigenvalue, so a ring of 100 agents
needs 51 small blocks, not a 200-state problem.
:func:`simulate_network_observer` runs the plants and the observer (42) on the
measurements, so that ``X - X_hat`` can be checked against ``A_e``.

The mode decomposition needs a symmetric Laplacian (orthogonal eigenvectors):
the design, the error matrix and the simulation all require an undirected graph
and refuse a directed one (or an adjacency passed as a Laplacian, and the
reverse) with a message that says so. Every public function checks its
arguments and names the one at fault.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from numpy.typing import ArrayLike

from ._conic import ConicProgram, clarabel, solve, svec, svec_size, sym_basis
from ._optional import require
from ._solver import SolverError
from ._systems import design_args
from ._validation import Frozen, as_matrix, check_adjacency, check_covariance, check_laplacian, check_moderate, finite_result
from ._validation import as_matrix as _matrix
from ._validation import check_square as _square
from ._validation import float_array as _float_array
from .graphs import laplacian as graph_laplacian
from .graphs import laplacian_spectrum
from .riccati import RICCATI_RTOL, is_controllable, solve_care, solve_dare

#: Why the observer functions need an undirected graph (quoted in their errors).
_WHY_SYMMETRIC = ("the observer (42) is designed mode by mode on the orthogonal eigenvectors of a symmetric "
                  "Laplacian (eqs. (43)-(55)), which a directed graph does not have")

__all__ = [
    "READINGS",
    "DistributedObserver",
    "MinEnergyObserver",
    "achieved_cost",
    "bound_at_fixed_phi",
    "coupled_gain_lmi",
    "disagreement",
    "distributed_observer",
    "is_observable",
    "min_energy_observer",
    "observer_error_matrix",
    "simulate_estimation_errors",
    "simulate_network_observer",
]

#: Margin of the strict inequalities (57)/(61) in the scaled coordinates of :func:`coupled_gain_lmi`.
#: With ``LMI_EPS`` (1e-9) the program is degenerate when the local gain is optimal for the
#: lambda = 0 mode (that mode's block is then tight at the optimum) and Clarabel stops at
#: 'optimal_inaccurate' for some N; 1e-5 keeps it well posed and moves the bound by ~1e-5.
STRICT_MARGIN = 1e-5

#: Weight of the |Y2| tie-break term of :func:`coupled_gain_lmi` (relative to the traces).
TIE_BREAK = 1e-6

#: Readings of eqs. (29)-(30) for the local gain L (see :func:`distributed_observer`).
READINGS = ("as-printed", "inverse-weight-are")


def is_observable(A: ArrayLike, C: ArrayLike) -> bool:
    """PBH test of observability of ``(A, C)`` (controllability of ``(A^T, C^T)``).

    Parameters
    ----------
    A : (n, n) array_like
        State matrix.
    C : (m, n) array_like
        Output matrix.

    Returns
    -------
    bool
        True if ``(A, C)`` is observable.

    Examples
    --------
    >>> from mascore import observers
    >>> observers.is_observable([[0.0, 1.0], [0.0, 0.0]], [[1.0, 0.0]]), observers.is_observable(
    ...     [[0.0, 1.0], [0.0, 0.0]], [[0.0, 1.0]])
    (True, False)
    """
    A = _square(A, "A")
    C = _matrix(C, "C", (None, A.shape[0]))
    return is_controllable(A.T, C.T)


@dataclass(frozen=True, eq=False)
class MinEnergyObserver(Frozen):
    """Minimum-energy observer, eqs. (23)-(25).

    Parameters
    ----------
    L : (n, m) ndarray
        Gain ``L = S C^T Q``.
    S : (n, n) ndarray
        Solution of the dual ARE (23).
    cost : float
        Optimal cost ``trace(S)`` (eq. (25)).
    E : (n,) ndarray
        Eigenvalues of ``A - L C``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> me = observers.min_energy_observer(A, Bbar, C, np.eye(1), np.eye(1))
    >>> bool(me.E.real.max() < 0), bool(np.isclose(me.cost, np.trace(me.S)))
    (True, True)
    """

    L: np.ndarray
    S: np.ndarray
    cost: float
    E: np.ndarray

    def __post_init__(self) -> None:
        self._freeze_arrays()


def min_energy_observer(
    A: ArrayLike, Bbar: ArrayLike | None = None, C: ArrayLike | None = None, Q: ArrayLike | None = None,
    R: ArrayLike | None = None, *, dt: float | None = None,
) -> MinEnergyObserver:
    """Minimum-energy (deterministic Kalman-Bucy) observer, eqs. (19)-(25).

    In discrete time (`dt`, or a sampled system) the dual of :func:`mascore.lqr.dlqr`: ``S``
    solves the discrete-time Riccati equation of ``(A^T, C^T, Bbar R^{-1} Bbar^T, Q^{-1})``
    and ``L = A S C^T (C S C^T + Q^{-1})^{-1}``, the predictor ``x_{k+1} = A x_k + L (y_k - C x_k)``.

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix (continuous time unless `dt` is given), or the agent as a system whose
        ``B`` is the disturbance input: then call ``min_energy_observer(sys, C, Q, R)``.
    Bbar : (n, q) array_like, optional
        Disturbance input (not with a system); ``(A, Bbar)`` must be controllable.
    C : (m, n) array_like
        ``(A, C)`` must be observable.
    Q : (m, m) array_like
        Cost weight on the measurement noise ``n`` in the minimum-energy cost (20), symmetric positive
        definite (large: trust the measurements). A weight, not a covariance: in the Kalman-Bucy reading it is
        the *inverse* measurement-noise intensity, in 1/(output unit)^2 (``L = S C^T Q``).
    R : (q, q) array_like
        Cost weight on the disturbance ``d`` in cost (20), symmetric positive definite (large: trust the
        model). A weight, not a covariance: the *inverse* disturbance intensity, in 1/(disturbance unit)^2.
    dt : float, optional
        Sampling time (s) of a discrete-time agent. Default: the system's own time base; for arrays,
        continuous time, and an ``A`` whose every eigenvalue has a positive real part (the spectrum
        of a sampled matrix) is refused: give its `dt`, or ``dt=0`` if it is continuous time.

    Returns
    -------
    MinEnergyObserver
        Gain, ARE solution, cost and closed-loop eigenvalues.

    Raises
    ------
    ValueError
        Bad shapes or weights, ``(A, Bbar)`` not controllable or ``(A, C)`` not observable.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> me = observers.min_energy_observer(A, Bbar, C, np.eye(1), np.eye(1))
    >>> me.L.shape
    (2, 1)
    >>> sampled = observers.min_energy_observer(A, Bbar, C, np.eye(1), np.eye(1), dt=0.1)   # A read per step
    >>> bool(np.abs(sampled.E).max() < 1)
    True
    """
    A, Bbar, (C, Q, R), dt = design_args("min_energy_observer", A, Bbar, dict(C=C, Q=Q, R=R), dt, bname="Bbar")
    A, Bbar, C, Q, R = _check_observer(A, Bbar, C, Q, R)
    solve = solve_dare if dt != 0 else solve_care
    K, S, E = solve(A.T, C.T, Bbar @ np.linalg.solve(R, Bbar.T), np.linalg.inv(Q))
    return MinEnergyObserver(L=K.T, S=S, cost=float(np.trace(S)), E=E)


@dataclass(frozen=True, eq=False)
class DistributedObserver(Frozen):
    """Result of :func:`distributed_observer` (Vlahakis and Halikias, Sec. 4.2).

    Parameters
    ----------
    L : (n, m) ndarray
        Local gain in the agent's original coordinates.
    Phi : (m, m) ndarray
        Coupling gain from the LMI program (62).
    bound : float
        Optimal value of (62), an upper bound on the aggregate cost (55).
    cost : float
        Cost the observer actually achieves: ``sum_i trace(S_i)`` with ``S_i``
        from the mode Lyapunov equations (57) taken with equality.
    centralized_cost : float
        Optimum of the network dual ARE (40), ``sum_i trace`` of eq. (53).
    local_cost : float
        Cost of ``Phi = 0`` (agents do not couple), ``inf`` if unstable.
    lam : (N,) ndarray
        Laplacian eigenvalues.
    T : (n, n) ndarray
        Coordinate change ``x_hat = T x`` of eqs. (27) and (32).
    A_hat : (n, n) ndarray
        The agent in the ``x_hat`` coordinates (eqs. (33)-(34)).
    Bbar_hat : (n, q) ndarray
        Its disturbance input there.
    C_hat : (m, n) ndarray
        Its output matrix there, ``(0 C2)``.
    L_hat : (n, m) ndarray
        The gain there, ``[0; L2]``.
    spectral_abscissa : float
        Largest real part of the eigenvalues of ``A_e``.
    disagreement_abscissa : float
        Same over the modes with ``lambda_i > 0`` only: the decay rate of the
        differences between the agents' errors.
    reading : str
        Which reading of eqs. (29)-(30) produced ``L``.
    trace_in : str
        Coordinates of the traces (``"transformed"``: ``x_hat``, as in eq. (57)).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> obs = observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
    ...                                     graphs.ring_graph(5))
    >>> obs.L.shape, obs.Phi.shape, bool(obs.bound >= obs.centralized_cost)
    ((2, 1), (1, 1), True)
    """

    L: np.ndarray
    Phi: np.ndarray
    bound: float
    cost: float
    centralized_cost: float
    local_cost: float
    lam: np.ndarray
    T: np.ndarray
    A_hat: np.ndarray
    Bbar_hat: np.ndarray
    C_hat: np.ndarray
    L_hat: np.ndarray
    spectral_abscissa: float
    disagreement_abscissa: float
    reading: str
    trace_in: str

    def __post_init__(self) -> None:
        self._freeze_arrays()

    @property
    def hurwitz(self) -> bool:
        """True if ``A_e`` is Hurwitz (all estimation errors decay).

        Returns
        -------
        bool
            ``spectral_abscissa < 0``.
        """
        return self.spectral_abscissa < 0


def distributed_observer(
    A: ArrayLike,
    Bbar: ArrayLike | None = None,
    C: ArrayLike | None = None,
    Q1: ArrayLike | None = None,
    Q2: ArrayLike | None = None,
    R: ArrayLike | None = None,
    adjacency: ArrayLike | None = None,
    reading: str = "as-printed",
    trace_in: str = "transformed",
    solver_options: dict | None = None,
    *,
    dt: float | None = None,
) -> DistributedObserver:
    """LQR-dual distributed observer by the bottom-up method (Sec. 4.2, eqs. (26)-(62)).

    1. Local gain: ``L = S C^T Q1`` with ``S`` from the dual ARE (29).
    2. Coordinates: rotation (27) so that ``C = (0 C2)``, then eq. (32) so that
       ``L_hat = [0; L2]`` (and ``S_hat`` block diagonal).
    3. Modes: the Laplacian eigenvalues ``lambda_i`` (eqs. (43)-(55)).
    4. LMI (56)-(62) for ``W_i = diag(W_i1, W2)``, ``Y2 = W2 L2 Phi`` and
       slack ``Z_i``; ``Phi = L2^{-1} W2^{-1} Y2``. Mode ``i`` uses the noise
       weight ``Q_i = Q1 + lambda_i Q2`` (eq. (61)).

    Continuous time only (the LMI (56)-(62) is a continuous-time Lyapunov inequality): in place
    of ``(A, Bbar)`` a continuous-time python-control ``StateSpace`` or an
    :class:`~mascore.agents.LTIAgent` that carries its continuous-time matrices
    (``LTIAgent.from_continuous``) is accepted, ``distributed_observer(sys, C, Q1, Q2, R, adjacency)``;
    a discrete-time one is refused by name (:func:`min_energy_observer` designs in either).

    Parameters
    ----------
    A, Bbar, C : agent matrices, shapes (n, n), (n, q), (m, n), with ``m < n``,
        ``(A, Bbar)`` controllable and ``(A, C)`` observable (or a system in place of ``(A, Bbar)``).
    Q1, Q2 : (m, m) array_like
        Weights on the absolute and on the relative output errors (eq. (38));
        ``Q1`` positive definite, ``Q2`` positive semidefinite.
    R : (q, q) array_like
        Cost weight on the disturbance ``d`` in cost (20) (the inverse disturbance intensity, not a
        covariance), positive definite, in 1/(disturbance unit)^2.
    adjacency : (N, N) array_like
        Symmetric adjacency of a connected undirected graph of N >= 2 agents (non-negative
        weights, no self-loops). One agent is refused: it has no disagreement modes
        (``lambda_i > 0``), so ``Phi`` is not determined; use :func:`min_energy_observer`.
    reading : {"as-printed", "inverse-weight-are"}
        ``"as-printed"``: eqs. (29)-(30) as printed. ``"inverse-weight-are"``:
        ``S`` from eq. (29) with ``Q1^{-1}`` in place of ``Q1`` (``Q1`` read as a
        noise covariance, Kalman style) but ``L = S C^T Q1`` as in eq. (30):
        not a consistent reading of eqs. (29)-(30) but the mixed convention
        (``Q1^2`` times the consistent gain) that gives the paper's printed
        ``L`` of Example 1. The LMI uses ``Q1 + lambda_i Q2`` in both readings.
    trace_in : {"transformed", "original"}
        Coordinates in which ``trace(S_i)`` is measured: ``x_hat`` as in
        eq. (57), or the agent's original ones.
    solver_options : dict, optional
        Settings passed to the conic solver (Clarabel) by name, e.g. ``{"max_iter": 500}``;
        default Clarabel's own (``mascore._solver.SOLVER_OPTIONS``). A
        :class:`~mascore.exceptions.SolverError` with status ``optimal_inaccurate`` is the cue to change them.
    dt : 0, optional
        The observer is designed in continuous time only. An array ``A`` whose every eigenvalue has a
        positive real part (the spectrum of a sampled matrix) is refused unless ``dt=0`` says that it
        is continuous time.

    Returns
    -------
    DistributedObserver
        The gains ``L`` and ``Phi``, the cost bound, the achieved and reference costs.

    Raises
    ------
    ValueError
        Bad input, uncontrollable/unobservable pair, a directed or disconnected graph, one agent.
    mascore.SolverError
        The LMI program is infeasible or not solved to optimality.

    Notes
    -----
    With several outputs (``m >= 2``) the program is often degenerate and
    Clarabel stops at 'optimal_inaccurate' (gap about 5e-8 instead of 1e-8),
    which is refused with a :class:`~mascore.exceptions.SolverError` (pass looser tolerances in
    `solver_options` to accept it); single-output agents, such as Example 1, solve
    cleanly for the graphs and weights we tried.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
    >>> obs = observers.distributed_observer(A, Bbar, C, Q1=10.0 * np.eye(1), Q2=5.0 * np.eye(1), R=np.eye(1),
    ...                                      adjacency=graphs.ring_graph(5))
    >>> obs.hurwitz, bool(obs.centralized_cost <= obs.cost <= obs.local_cost)
    (True, True)
    """
    A, Bbar, (C, Q1, Q2, R, adjacency), _ = design_args("distributed_observer", A, Bbar,
        dict(C=C, Q1=Q1, Q2=Q2, R=R, adjacency=adjacency), dt, time="continuous", bname="Bbar")
    A, Bbar, C, Q1, R = _check_observer(A, Bbar, C, Q1, R, qname="Q1")
    m = C.shape[0]
    Q2 = check_covariance(np.atleast_2d(_float_array(Q2, "Q2")), "Q2", m)
    check_moderate(("Q2", Q2), what="the LMI (62)")
    if not isinstance(reading, str) or reading not in READINGS:
        raise ValueError(f"reading must be one of {READINGS}; got {reading!r}")
    _check_trace_in(trace_in)
    Lap = graph_laplacian(check_adjacency(adjacency, "adjacency", undirected=True, why=_WHY_SYMMETRIC))
    if Lap.shape[0] < 2:
        raise ValueError(
            "adjacency describes one agent: the distributed observer needs N >= 2 agents (one agent has no "
            "disagreement modes, so the coupling Phi is not determined); use min_energy_observer instead"
        )
    lam, _ = laplacian_spectrum(Lap, "adjacency")
    BRB = Bbar @ np.linalg.solve(R, Bbar.T)
    are_weight = Q1 if reading == "as-printed" else np.linalg.inv(Q1)
    _, S, _ = solve_care(A.T, C.T, BRB, np.linalg.inv(are_weight))  # eq. (29)
    L = S @ C.T @ Q1  # eq. (30)
    G = Bbar @ np.real(sla.sqrtm(np.linalg.inv(R)))
    noise = [Q1 + l * Q2 for l in lam]
    res = _coupled_gain(A, C, L, lam, [G] * len(lam), noise, trace_in, "distributed observer LMI (62)",
                        solver_options)
    Phi = res["Phi"]
    T = res["T"]
    T_tr = T if trace_in == "transformed" else None
    cost = _mode_costs(A, C, L, Phi, lam, BRB, noise, T_tr)
    local = _mode_costs(A, C, L, np.zeros_like(Phi), lam, BRB, noise, T_tr)
    central = _centralized_cost(A, C, BRB, noise, T_tr)  # eq. (53)
    absc = np.linalg.eigvals(A - L @ (np.eye(m) + lam[:, None, None] * Phi) @ C).real.max(axis=1)
    Tinv = np.linalg.inv(T)
    return DistributedObserver(
        L=L, Phi=Phi, bound=res["bound"], cost=cost, centralized_cost=float(central), local_cost=local,
        lam=lam, T=T, A_hat=T @ A @ Tinv, Bbar_hat=T @ Bbar, C_hat=C @ Tinv, L_hat=T @ L,
        spectral_abscissa=float(max(absc)), disagreement_abscissa=float(max(absc[1:])),
        reading=reading, trace_in=trace_in,
    )


def coupled_gain_lmi(
    A: ArrayLike,
    C: ArrayLike,
    L: ArrayLike,
    lam: ArrayLike,
    process_factors: Sequence[ArrayLike],
    noise_weights: Sequence[ArrayLike],
    trace_in: str = "transformed",
    what: str = "coupled-gain LMI",
    solver_options: dict | None = None,
) -> dict:
    """The LMI program (56)-(62) for the coupling ``Phi`` of gains ``L (I + lambda_i Phi)``.

    For each Laplacian eigenvalue ``lambda_i`` the mode
    ``A_i = A - L (I + lambda_i Phi) C`` must admit ``S_i > 0`` with

        A_i S_i + S_i A_i^T + G_i G_i^T + L (I + lambda_i Phi) Q_i^{-1} (...)^T < 0   (57)

    and ``sum_i trace(S_i)`` is minimized. In the coordinates of eqs. (27) and
    (32), where ``C_hat = (0 C2)`` and ``L_hat = (0; L2)``, restricting
    ``S_i^{-1} = W_i = diag(W_i1, W2)`` with a common ``W2`` makes the product
    ``W_i L_hat Phi = (0; W2 L2 Phi)`` a single linear variable ``Y2`` (eq. (60));
    the Schur complement gives eq. (61) and the slack ``Z_i >= W_i^{-1}``
    eq. (62). Modes with equal ``lambda`` share their variables (the program is
    separable given ``W2`` and ``Y2``), weighted by their multiplicity. The conic data are
    assembled with numpy and handed to Clarabel directly (the very data cvxpy would build for
    the same program, without its compilation, which cost ~70 times the solve for large graphs).

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    C : (m, n) array_like
        Output matrix, full row rank ``m < n``.
    L : (n, m) array_like
        Local gain; ``L2`` (the part of ``T L`` on the output coordinates) must be invertible.
    lam : (N,) array_like
        Laplacian eigenvalues (>= 0).
    process_factors : sequence of N (n, q_i) arrays
        ``G_i`` (``Bbar R^{-1/2}`` for the observer of eq. (61)).
    noise_weights : sequence of N (m, m) arrays
        ``Q_i`` (``Q1 + lambda_i Q2`` in eq. (61)), positive definite.
    trace_in : {"transformed", "original"}
        Minimize the traces in the ``x_hat`` coordinates (as printed) or in the original ones.
    what : str
        Name used in solver errors.
    solver_options : dict, optional
        Settings passed to the conic solver (Clarabel) by name, e.g. ``{"max_iter": 500}``;
        default Clarabel's own (``mascore._solver.SOLVER_OPTIONS``). A
        :class:`~mascore.exceptions.SolverError` with status ``optimal_inaccurate`` is the cue to change them.

    Returns
    -------
    dict
        ``Phi`` (m, m), ``bound`` (float), ``T`` (n, n) with ``x_hat = T x``,
        ``W`` (list of the W_i per distinct lambda, in ``x_hat`` scaled to unit
        diagonal of the first mode's ``Phi = 0`` Lyapunov solution), ``lam_unique``, ``multiplicity``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> obs = observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
    ...                                     graphs.ring_graph(5))
    >>> res = observers.coupled_gain_lmi(A, C, obs.L, obs.lam, [Bbar] * 5,
    ...                                  [10.0 * np.eye(1) + l * 5.0 * np.eye(1) for l in obs.lam])
    >>> res["lam_unique"].size                                   # one LMI block per distinct eigenvalue
    3
    """
    A, C, L, lam, factors, noise = _check_mode_program(A, C, L, lam, process_factors, noise_weights, trace_in)
    return _coupled_gain(A, C, L, lam, factors, noise, trace_in, what, solver_options)


def _coupled_gain(A: np.ndarray, C: np.ndarray, L: np.ndarray, lam: np.ndarray, factors: Sequence[np.ndarray],
                  noise: Sequence[np.ndarray], trace_in: str, what: str, solver_options: dict | None) -> dict:
    """:func:`coupled_gain_lmi` on arguments already checked (float arrays of matching shapes)."""
    n, m = L.shape
    n1 = n - m
    T = _node_coordinates(C, L)
    Tinv = np.linalg.inv(T)
    A_hat, C_hat, L_hat = T @ A @ Tinv, C @ Tinv, T @ L
    # Diagonal scaling (keeps the block structure; Phi is unchanged): unit diagonal for the Phi = 0
    # Lyapunov solution of the first mode, which conditions the program near its optimum.
    k0 = int(np.argmin(lam))
    G0 = T @ factors[k0]
    Ac0 = A_hat - L_hat @ C_hat
    D = np.ones(n)
    if np.max(np.linalg.eigvals(Ac0).real) < 0:
        Q0 = noise[k0]
        S0 = sla.solve_continuous_lyapunov(Ac0, -(G0 @ G0.T + L_hat @ np.linalg.solve(Q0, L_hat.T)))
        if np.all(np.diag(S0) > 0):
            D = np.sqrt(np.diag(S0))
    T_coords = T
    T = np.diag(1 / D) @ T
    Tinv = np.linalg.inv(T)
    A_hat, C_hat, L_hat = T @ A @ Tinv, C @ Tinv, T @ L
    L2 = L_hat[n1:]
    Ac = A_hat - L_hat @ C_hat
    # distinct eigenvalues with multiplicities (identical blocks share variables)
    groups: list[list[int]] = []
    for i in np.argsort(lam):
        if groups and abs(lam[i] - lam[groups[-1][0]]) <= 1e-9 * max(1.0, abs(lam[i])):
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    # trace of S in the requested coordinates: S_hat = Ds S Ds, S_orig = Tinv S Tinv^T
    weight = Tinv.T @ Tinv if trace_in == "original" else np.diag(D**2)
    modes = []
    for g in groups:
        k = g[0]
        modes.append((float(lam[k]), len(g), T @ factors[k], noise[k]))
    program, unpack = _lmi_program(Ac, C_hat, L_hat, weight, modes)
    solve(program, what, solver_options)
    W2, Y2, Ws, bound = unpack(program.x)
    Phi = np.linalg.solve(L2, np.linalg.solve(W2, Y2))
    return {
        "Phi": Phi, "bound": bound, "T": T_coords, "W": Ws,
        "lam_unique": np.array([lam[g[0]] for g in groups]),
        "multiplicity": np.array([len(g) for g in groups]),
    }


def _lmi_program(Ac: np.ndarray, C_hat: np.ndarray, L_hat: np.ndarray, weight: np.ndarray,
                 modes: Sequence[tuple[float, int, np.ndarray, np.ndarray]]) -> tuple[ConicProgram, Callable]:
    """Clarabel's data for the LMI program (56)-(62), assembled block by block.

    Parameters
    ----------
    Ac : (n, n) ndarray
        ``A_hat - L_hat C_hat`` in the scaled coordinates of :func:`coupled_gain_lmi`.
    C_hat : (m, n) ndarray
        ``(0 C2)``.
    L_hat : (n, m) ndarray
        ``(0; L2)``.
    weight : (n, n) ndarray
        The objective is ``sum_i multiplicity_i trace(weight Z_i)``.
    modes : sequence of (lambda_i, multiplicity_i, G_i, Q_i)
        One entry per distinct Laplacian eigenvalue: the eigenvalue, how many modes share it,
        the process factor ``G_i`` (n, q_i) and the noise weight ``Q_i`` (m, m).

    Returns
    -------
    program : ConicProgram
        ``min sum_i multiplicity_i trace(weight Z_i) + TIE_BREAK |Y2|_F`` subject to, per mode,
        eq. (61) with the margin :data:`STRICT_MARGIN` and eq. (62).
    unpack : callable
        ``unpack(x) -> (W2, Y2, [W_i], bound)`` from a solution ``x`` (``bound`` without the tie-break).

    Notes
    -----
    The variables and rows are laid out as cvxpy lays out the same program written with
    ``cvxpy.Variable`` (``Z_i`` for all modes, the epigraph variable of ``|Y2|_F``, ``Y2``, then
    ``W_i1`` with ``W2`` after the first; rows: the second-order cone, then eqs. (61) and (62)
    mode by mode), so Clarabel sees the very data the modelling layer would hand it. Each
    matrix inequality ``M(x) = M_0 + sum_j x_j M_j >= 0`` becomes ``s = svec(M(x))``, that is
    ``b = svec(M_0)`` and column ``j`` of ``A`` equal to ``-svec(M_j)``.
    """
    n, m = L_hat.shape
    n1 = n - m
    sn, s1, sm = svec_size(n), svec_size(n1), svec_size(m)
    K = len(modes)
    # columns: Z_1..Z_K, t, Y2 (column-major), W_11, W2, W_21, ..., W_K1
    z0, t_col = 0, K * sn
    y_cols = t_col + 1 + np.arange(m * m)
    w_start = t_col + 1 + m * m
    w2_cols = w_start + s1 + np.arange(sm)
    w1_cols = [w_start + s1 * i + (sm if i else 0) + np.arange(s1) for i in range(K)]
    nx = w_start + K * s1 + sm
    # basis of the local variables: W = diag(W1, W2) and Y = (0; Y2)
    EW = np.zeros((s1 + sm, n, n))
    EW[:s1, :n1, :n1] = sym_basis(n1)
    EW[s1:, n1:, n1:] = sym_basis(m)
    EY = np.zeros((m * m, n, m))
    a, b = np.arange(m * m) % m, np.arange(m * m) // m
    EY[np.arange(m * m), n1 + a, b] = 1.0
    EZ = sym_basis(n)
    WAc, WL, YC = EW @ Ac, EW @ L_hat, EY @ C_hat
    # eq. (62): [[Z, I], [I, W]] >= 0
    lmi2 = np.zeros((sn + s1 + sm, 2 * n, 2 * n))
    lmi2[:sn, :n, :n] = EZ
    lmi2[sn:, n:, n:] = EW
    A2 = -svec(lmi2).T
    b2 = svec(np.block([[np.zeros((n, n)), np.eye(n)], [np.eye(n), np.zeros((n, n))]]))
    c = np.zeros(nx)
    c[t_col] = TIE_BREAK
    trace_Z = np.einsum("ij,pji->p", weight, EZ)
    # ||Y2||_F <= t: s = (t, vec Y2) in the second-order cone (rows 0..m^2, b = 0)
    r = 1 + m * m
    rows, cols, vals, offsets = [np.arange(r)], [np.r_[t_col, y_cols]], [-np.ones(r)], [np.zeros(r)]
    cones = [clarabel.SecondOrderConeT(r)]
    for i, (li, mult, G, Qi) in enumerate(modes):
        q = G.shape[1]
        k = n + q + m
        # eq. (61): linear part in (W_i1, W2) and in Y2, constant part diag(0, -I, -Q_i)
        M = np.zeros((s1 + sm + m * m, k, k))
        MW, MY = M[: s1 + sm], M[s1 + sm:]
        MW[:, :n, :n] = WAc + WAc.transpose(0, 2, 1)
        MW[:, :n, n:n + q] = EW @ G
        MW[:, :n, n + q:] = WL
        MY[:, :n, :n] = -li * (YC + YC.transpose(0, 2, 1))
        MY[:, :n, n + q:] = li * EY
        M[:, n:, :n] = M[:, :n, n:].transpose(0, 2, 1)
        M0 = np.zeros((k, k))
        M0[n:n + q, n:n + q] = -np.eye(q)
        M0[n + q:, n + q:] = -(Qi + Qi.T) / 2
        # eq. (61) with margin: -STRICT_MARGIN I - lmi >= 0
        A1 = svec(M).T
        b1 = svec(-STRICT_MARGIN * np.eye(k) - M0)
        c[z0 + i * sn: z0 + (i + 1) * sn] = mult * trace_Z
        for Ablk, local in ((A1, np.r_[w1_cols[i], w2_cols, y_cols]),
                            (A2, np.r_[z0 + i * sn + np.arange(sn), w1_cols[i], w2_cols])):
            rr, cc = np.nonzero(Ablk)
            rows.append(r + rr)
            cols.append(local[cc])
            vals.append(Ablk[rr, cc])
            r += Ablk.shape[0]
        offsets += [b1, b2]
        cones += [clarabel.PSDTriangleConeT(k), clarabel.PSDTriangleConeT(2 * n)]
    A = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(r, nx))
    b = np.concatenate(offsets)
    z_cols = [z0 + i * sn + np.arange(sn) for i in range(K)]
    mults = np.array([mode[1] for mode in modes], dtype=float)

    def unpack(x: np.ndarray):
        W2 = np.tensordot(x[w2_cols], sym_basis(m), 1)
        Y2 = x[y_cols].reshape(m, m, order="F")
        W = np.zeros((K, n, n))
        W[:, :n1, :n1] = np.tensordot(x[np.array(w1_cols)], sym_basis(n1), 1)
        W[:, n1:, n1:] = W2
        bound = float(sum(mult * (trace_Z @ x[z]) for mult, z in zip(mults, z_cols)))
        return W2, Y2, list(W), bound

    return ConicProgram(c, A, b, cones), unpack


def bound_at_fixed_phi(
    A: ArrayLike,
    C: ArrayLike,
    L: ArrayLike,
    lam: ArrayLike,
    process_factors: Sequence[ArrayLike],
    noise_weights: Sequence[ArrayLike],
    Phi: ArrayLike,
    trace_in: str = "transformed",
    what: str = "fixed-Phi program (56)-(58)",
    solver_options: dict | None = None,
) -> float | np.ndarray:
    """Optimum of the program (56)-(58) for *given* ``Phi``, written in ``S_i`` directly.

    For fixed ``Phi`` the Lyapunov inequalities (57) are linear in ``S_i``, so
    ``min sum_i trace(S_i)`` over ``S_i = diag(S_i1, S2) >= 0`` (common ``S2``,
    eq. (56)) is an SDP without the change of variables ``W_i = S_i^{-1}``,
    ``Y2 = W2 L2 Phi`` of eqs. (59)-(62). Its minimum over ``Phi`` is the optimum
    of :func:`coupled_gain_lmi`: an independent check of that program, and the
    profile ``Gamma(Phi)`` that shows how sharply the optimum determines ``Phi``.
    The inequalities are taken non-strict (the closure; the value is the infimum
    of the strict program). Several gains share one compiled (parametrized) problem.

    Parameters
    ----------
    A, C, L, lam, process_factors, noise_weights, trace_in
        As in :func:`coupled_gain_lmi`.
    Phi : array_like
        One coupling gain, ``(m, m)`` (or a float when ``m = 1``), or several:
        ``(K, m, m)``, or ``(K,)`` when ``m = 1``.
    what : str
        Name used in solver errors.
    solver_options : dict, optional
        Settings passed to the conic solver (Clarabel) by name, e.g. ``{"max_iter": 500}``;
        default Clarabel's own (``mascore._solver.SOLVER_OPTIONS``). A
        :class:`~mascore.exceptions.SolverError` with status ``optimal_inaccurate`` is the cue to change them.

    Returns
    -------
    float, or (K,) ndarray for several gains
        ``min sum_i trace(S_i)``; ``+inf`` if no ``S_i`` of the structure (56)
        exists (a mode ``A - L (I + lambda_i Phi) C`` not Hurwitz, or the program
        proved infeasible).

    Raises
    ------
    ValueError
        Bad shapes (as :func:`coupled_gain_lmi`).
    mascore.SolverError
        The program is neither solved to optimality nor proved infeasible.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> obs = observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
    ...                                     graphs.ring_graph(5))
    >>> G = [Bbar] * 5
    >>> Rw = [10.0 * np.eye(1) + l * 5.0 * np.eye(1) for l in obs.lam]
    >>> at_lmi = observers.bound_at_fixed_phi(A, C, obs.L, obs.lam, G, Rw, obs.Phi)
    >>> bool(np.isclose(at_lmi, obs.bound, rtol=1e-4))          # the LMI's Phi attains its bound
    True
    """
    A, C, L, lam, _, _ = _check_mode_program(A, C, L, lam, process_factors, noise_weights, trace_in)
    n, m = L.shape
    phis = _float_array(Phi, "Phi")
    single = phis.ndim == 0 or phis.shape == (m, m)
    if single or (m == 1 and phis.ndim == 1):
        phis = phis.reshape(-1, m, m)
    check_moderate(("Phi", phis), what="the fixed-Phi program")
    if phis.ndim != 3 or phis.shape[1:] != (m, m) or not np.all(np.isfinite(phis)):
        raise ValueError(f"Phi must be finite, one ({m}, {m}) gain or a (K, {m}, {m}) stack; got shape "
                         f"{np.shape(Phi)}")
    T = _node_coordinates(C, L)
    Tinv = np.linalg.inv(T)
    A_hat, C_hat, L_hat = T @ A @ Tinv, C @ Tinv, T @ L
    n1 = n - m
    GG = [T @ as_matrix(g, f"process_factors[{k}]", (n, None)) for k, g in enumerate(process_factors)]
    GG = [G @ G.T for G in GG]
    Qinv = [np.linalg.inv(check_covariance(np.atleast_2d(q), f"noise_weights[{k}]", m, definite=True))
            for k, q in enumerate(noise_weights)]
    weight = Tinv.T @ Tinv if trace_in == "original" else np.eye(n)
    cp = require("cvxpy", "mascore.observers.bound_at_fixed_phi (the program of eqs. (56)-(58))")
    # one parametrized problem: mode matrix A_i and constant term of eq. (57) per mode
    S2 = cp.Variable((m, m), symmetric=True)
    constraints, objective, params = [S2 >> 0], 0, []
    for _ in lam:
        Ai, Mi = cp.Parameter((n, n)), cp.Parameter((n, n))
        S1 = cp.Variable((n1, n1), symmetric=True)
        S = cp.bmat([[S1, np.zeros((n1, m))], [np.zeros((m, n1)), S2]])
        M = Ai @ S + S @ Ai.T + Mi  # eq. (57)
        constraints += [(M + M.T) / 2 << 0, S1 >> 0]
        objective = objective + cp.trace(weight @ S)
        params.append((Ai, Mi))
    problem = cp.Problem(cp.Minimize(objective), constraints)
    out = np.empty(len(phis))
    for j, phi in enumerate(phis):
        stable = True
        for (Ai, Mi), li, GGi, Qi in zip(params, lam, GG, Qinv):
            Li = L_hat @ (np.eye(m) + li * phi)
            Ai.value = A_hat - Li @ C_hat
            Mi.value = GGi + Li @ Qi @ Li.T
            stable = stable and np.max(np.linalg.eigvals(Ai.value).real) < 0
        if not stable:
            out[j] = np.inf
            continue
        try:
            out[j] = solve(problem, what, solver_options)
        except SolverError:
            if problem.status != cp.INFEASIBLE:
                raise
            out[j] = np.inf  # no S_i with the structure (56)
    return float(out[0]) if single else out


def _check_mode_program(A, C, L, lam, process_factors, noise_weights, trace_in):
    """Validate the inputs shared by the mode programs (56)-(62).

    Returns ``A, C, L, lam`` as arrays and the lists of process factors (n, q_i) and noise
    weights (m, m) as float arrays.
    """
    A = _square(A, "A")
    n = A.shape[0]
    C = _matrix(C, "C", (None, n))
    L = _matrix(L, "L", (n, C.shape[0]))
    lam = _eigenvalues(lam)
    _check_sequence(process_factors, "process_factors", lam.size)
    _check_sequence(noise_weights, "noise_weights", lam.size)
    m = C.shape[0]
    factors, noise = [], []
    for k in range(lam.size):
        factors.append(_matrix(process_factors[k], f"process_factors[{k}]", (n, None)))
        noise.append(check_covariance(np.atleast_2d(_float_array(noise_weights[k], f"noise_weights[{k}]")),
                                      f"noise_weights[{k}]", m, definite=True))
    _check_trace_in(trace_in)
    check_moderate(("A", A), ("C", C), ("L", L), ("lam", lam), *((f"process_factors[{k}]", f) for k, f in enumerate(factors)),
                   *((f"noise_weights[{k}]", w) for k, w in enumerate(noise)), what="the mode program")
    return A, C, L, lam, factors, noise


def _node_coordinates(C: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``T = T_hat T_rot`` of eqs. (27) and (32): ``C T^-1 = (0 C2)`` and ``T L = (0; L2)``."""
    m, n = C.shape
    if m >= n:
        raise ValueError(f"C must have fewer rows than columns (m < n); got shape {C.shape}")
    n1 = n - m
    # eq. (27): rotation making C = (0 C2)
    _, sv, Vt = np.linalg.svd(C)
    if sv[-1] <= 1e-10 * max(1.0, sv[0]):
        raise ValueError("C must have full row rank")
    swap = np.block([[np.zeros((n1, m)), np.eye(n1)], [np.eye(m), np.zeros((m, n1))]])
    T_rot = swap @ Vt
    L_rot = T_rot @ L
    L1, L2 = L_rot[:n1], L_rot[n1:]
    if np.linalg.cond(L2) > 1e12:
        raise ValueError("the output part L2 of the local gain is singular; eq. (32) needs it invertible")
    # eq. (32), written through L (L1 L2^{-1} = S12 S22^{-1} when L = S C^T Q1)
    T_hat = np.block([[np.eye(n1), -L1 @ np.linalg.inv(L2)], [np.zeros((m, n1)), np.eye(m)]])
    return T_hat @ T_rot


def observer_error_matrix(
    A: ArrayLike, L: ArrayLike, C: ArrayLike, Phi: ArrayLike, laplacian: ArrayLike
) -> np.ndarray:
    """``A_e = I_N (x) (A - L C) - Lap (x) L Phi C`` (Example 1; error form of eq. (42)).

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    L : (n, m) array_like
        Local gain.
    C : (m, n) array_like
        Output matrix.
    Phi : (m, m) array_like or float
        Coupling gain.
    laplacian : (N, N) array_like
        Must be symmetric (an undirected graph).

    Returns
    -------
    (N n, N n) ndarray
        ``A_e``.

    Notes
    -----
    `laplacian` must be symmetric: the gains ``L``, ``Phi``
    and the error analysis come from the mode decomposition by its orthogonal eigenvectors.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> obs = observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
    ...                                     graphs.ring_graph(5))
    >>> Ae = observers.observer_error_matrix(A, obs.L, C, obs.Phi, graphs.laplacian(graphs.ring_graph(5)))
    >>> Ae.shape, bool(np.linalg.eigvals(Ae).real.max() < 0)
    ((10, 10), True)
    """
    A = _square(A, "A")
    n = A.shape[0]
    C = _matrix(C, "C", (None, n))
    m = C.shape[0]
    L = _matrix(L, "L", (n, m))
    Phi = as_matrix(np.atleast_2d(_float_array(Phi, "Phi")), "Phi", (m, m))
    Lap = check_laplacian(laplacian, "laplacian", undirected=True, why=_WHY_SYMMETRIC)
    return _error_matrix(A, L, C, Phi, Lap)


def _error_matrix(A: np.ndarray, L: np.ndarray, C: np.ndarray, Phi: np.ndarray, Lap: np.ndarray) -> np.ndarray:
    """``A_e = I_N (x) (A - L C) - Lap (x) L Phi C``, the one place it is built (arguments checked)."""
    return np.kron(np.eye(Lap.shape[0]), A - L @ C) - np.kron(Lap, L @ Phi @ C)


def simulate_estimation_errors(A_e: ArrayLike, e0: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Noise-free network estimation errors ``e(t) = expm(A_e t) e(0)`` on a uniform grid.

    Parameters
    ----------
    A_e : (N n, N n) array_like
        Error matrix (:func:`observer_error_matrix`).
    e0 : (N, n) array_like
        Initial estimation error of each agent.
    t : (T,) array_like
        Uniform time grid starting at 0, seconds.

    Returns
    -------
    (T, N, n) ndarray
        The errors on the grid.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> obs = observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
    ...                                     graphs.ring_graph(5))
    >>> Ae = observers.observer_error_matrix(A, obs.L, C, obs.Phi, graphs.laplacian(graphs.ring_graph(5)))
    >>> e = observers.simulate_estimation_errors(Ae, np.ones((5, 2)), np.linspace(0.0, 20.0, 201))
    >>> bool(np.abs(e[-1]).max() < 1e-3 * np.abs(e[0]).max())
    True
    """
    A_e = _square(A_e, "A_e")
    check_moderate(("A_e", A_e), what="the matrix exponential")
    e0 = _matrix(e0, "e0")
    if e0.size != A_e.shape[0]:
        raise ValueError(f"e0 must have N*n = {A_e.shape[0]} entries; got shape {e0.shape}")
    t = _float_array(t, "t")
    if t.ndim != 1 or t.size < 2 or t[0] != 0:
        raise ValueError("t must be a 1-D grid of at least two times starting at 0")
    if not np.all(np.isfinite(t)):
        raise ValueError("t contains NaN or infinite entries")
    dt = np.diff(t)
    if not np.allclose(dt, dt[0], rtol=1e-9) or dt[0] <= 0:
        raise ValueError("t must be uniform and increasing")
    step = sla.expm(A_e * dt[0])
    out = np.empty((t.size, e0.size))
    out[0] = e0.ravel()
    for k in range(1, t.size):
        out[k] = step @ out[k - 1]
    finite_result("estimation errors", out, advice=_GROWTH_ADVICE)
    return out.reshape(t.size, *e0.shape)


def simulate_network_observer(
    A: ArrayLike,
    C: ArrayLike,
    L: ArrayLike,
    Phi: ArrayLike,
    laplacian: ArrayLike,
    x0: ArrayLike,
    x_hat0: ArrayLike,
    t: ArrayLike,
    Bbar: ArrayLike | None = None,
    disturbance: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Plant and distributed observer (eq. (42)) driven by the measurements, simulated exactly.

    Plant (eqs. (26), (41)): ``X' = (I_N (x) A) X + (I_N (x) Bbar) D``, outputs
    ``Y = (I_N (x) C) X`` (noise free). Observer, eq. (42) in the agent's
    original coordinates::

        X_hat' = (I_N (x) (A - L C) - Lap (x) L Phi C) X_hat + (I_N (x) L + Lap (x) L Phi) Y

    i.e. agent ``i`` adds ``L Phi sum_{j in N_i} ((y_i - C x_hat_i) - (y_j - C x_hat_j))``.
    Eq. (37) as printed writes the summand as ``(y_j - C x_hat_i) - (y_j - C x_hat_j)``,
    in which the measurements cancel; we follow eq. (42), the form whose error
    ``E = X - X_hat`` obeys ``E' = A_e E + (I_N (x) Bbar) D`` with ``A_e`` of
    :func:`observer_error_matrix`. The joint ``2 N n``-state linear system is
    propagated by its matrix exponential (disturbance held constant between
    grid points, which is exact for a piecewise-constant ``D``).

    Parameters
    ----------
    A : (n, n) array_like
        Agent dynamics, 1/s.
    C : (m, n) array_like
        Output matrix.
    L : (n, m) array_like
        Local observer gain, 1/s.
    Phi : (m, m) array_like or float
        Coupling gain (dimensionless).
    laplacian : (N, N) array_like
        Laplacian of an undirected graph (symmetric, rows sum to zero): ``L`` and ``Phi``
        come from the mode decomposition by its orthogonal eigenvectors, which a directed
        graph does not have, so a directed Laplacian is refused.
    x0 : (N, n) array_like
        True states at ``t[0]``.
    x_hat0 : (N, n) array_like
        Estimates at ``t[0]``.
    t : (T,) array_like
        Increasing time grid, seconds (need not be uniform).
    Bbar : (n, q) array_like, optional
        Disturbance input matrix; required with `disturbance`.
    disturbance : (T, N, q) array_like, optional
        Disturbance ``d_i`` of each agent, held constant on ``[t[k], t[k+1])``
        (the last sample is not used). Default: zero.

    Returns
    -------
    X : (T, N, n) ndarray
        True states on the grid.
    X_hat : (T, N, n) ndarray
        Estimates on the grid.

    Raises
    ------
    ValueError
        Bad shapes, a `laplacian` that is not the Laplacian of an undirected graph (an
        adjacency, a directed Laplacian), a grid that is not 1-D and increasing, or
        `disturbance` without `Bbar`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> obs = observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
    ...                                     graphs.ring_graph(5))
    >>> t = np.linspace(0.0, 20.0, 201)
    >>> X, Xh = observers.simulate_network_observer(A, C, obs.L, obs.Phi, graphs.laplacian(graphs.ring_graph(5)),
    ...                                              np.ones((5, 2)), np.zeros((5, 2)), t)
    >>> bool(np.abs(X[-1] - Xh[-1]).max() < 1e-3)
    True
    """
    A = _square(A, "A")
    n = A.shape[0]
    C = _matrix(C, "C", (None, n))
    m = C.shape[0]
    L = _matrix(L, "L", (n, m))
    Phi = as_matrix(np.atleast_2d(_float_array(Phi, "Phi")), "Phi", (m, m))
    check_moderate(("A", A), ("C", C), ("L", L), ("Phi", Phi), what="the simulation")
    Lap = check_laplacian(laplacian, "laplacian", undirected=True, why=_WHY_SYMMETRIC)
    N = Lap.shape[0]
    x0 = _matrix(x0, "x0", (N, n))
    x_hat0 = _matrix(x_hat0, "x_hat0", (N, n))
    t = _float_array(t, "t")
    if t.ndim != 1 or t.size < 2 or not np.all(np.isfinite(t)):
        raise ValueError(f"t must be a finite 1-D grid of at least two times; got shape {t.shape}")
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise ValueError("t must be strictly increasing")
    I_N = np.eye(N)
    A_obs = _error_matrix(A, L, C, Phi, Lap)  # eq. (42), state term (the error matrix A_e)
    B_obs = np.kron(I_N, L) + np.kron(Lap, L @ Phi)  # eq. (42), input term (acts on Y)
    Nn = N * n
    M = np.block([[np.kron(I_N, A), np.zeros((Nn, Nn))], [B_obs @ np.kron(I_N, C), A_obs]])
    if disturbance is None:
        q, G, D = 0, np.zeros((2 * Nn, 0)), np.zeros((t.size, 0))
    else:
        if Bbar is None:
            raise ValueError("disturbance needs Bbar (the disturbance input matrix)")
        Bbar = _matrix(Bbar, "Bbar", (n, None))
        q = Bbar.shape[1]
        D = _float_array(disturbance, "disturbance")
        if D.shape != (t.size, N, q):
            raise ValueError(f"disturbance must have shape (T, N, q) = {(t.size, N, q)}; got {D.shape}")
        if not np.all(np.isfinite(D)):
            raise ValueError("disturbance must be finite")
        G = np.vstack([np.kron(I_N, Bbar), np.zeros((Nn, N * q))])
        D = D.reshape(t.size, N * q)
    # augmented exponential expm([[M, G], [0, 0]] h) = [[Phi_h, Gamma_h], [0, I]] (Van Loan)
    M_aug = np.zeros((2 * Nn + N * q, 2 * Nn + N * q))
    M_aug[: 2 * Nn, : 2 * Nn] = M
    M_aug[: 2 * Nn, 2 * Nn:] = G
    uniform = np.allclose(dt, dt[0], rtol=1e-9, atol=0)
    steps = {}
    for h in ([dt[0]] if uniform else np.unique(dt)):
        F = sla.expm(M_aug * h)
        steps[float(h)] = (F[: 2 * Nn, : 2 * Nn], F[: 2 * Nn, 2 * Nn:])
    z = np.empty((t.size, 2 * Nn))
    z[0] = np.concatenate([x0.ravel(), x_hat0.ravel()])
    for k in range(1, t.size):
        Fz, Fd = steps[float(dt[0] if uniform else dt[k - 1])]
        z[k] = Fz @ z[k - 1] + Fd @ D[k - 1]
    finite_result("simulated states", z, advice=_GROWTH_ADVICE)
    return z[:, :Nn].reshape(t.size, N, n), z[:, Nn:].reshape(t.size, N, n)


def disagreement(errors: ArrayLike) -> np.ndarray:
    """Errors minus their mean over the agents (axis -2).

    Parameters
    ----------
    errors : (..., N, n) array_like
        Estimation errors, finite.

    Returns
    -------
    (..., N, n) ndarray
        The disagreement part (zero when every agent has the same error).

    Examples
    --------
    >>> from mascore import observers
    >>> observers.disagreement([[1.0, 0.0], [3.0, 0.0]])
    array([[-1.,  0.],
           [ 1.,  0.]])
    """
    errors = _float_array(errors, "errors")
    if errors.ndim < 2 or errors.shape[-2] == 0:
        raise ValueError(f"errors must be an array (..., N, n) with N >= 1 agents; got shape {errors.shape}")
    if not np.all(np.isfinite(errors)):
        raise ValueError("errors contains NaN or infinite entries")
    return errors - errors.mean(axis=-2, keepdims=True)


def achieved_cost(
    A: ArrayLike, Bbar: ArrayLike, C: ArrayLike, R: ArrayLike, L: ArrayLike, Phi: ArrayLike,
    lam: ArrayLike, noise_weights: Sequence[ArrayLike], T: ArrayLike | None = None,
) -> float:
    """Aggregate cost (55) that gains ``L`` and ``Phi`` actually achieve: ``sum_i trace(S_i)``.

    ``S_i`` solves the Lyapunov equation (57) taken with equality for the mode
    ``A - L (I + lambda_i Phi) C`` with noise weight ``Q_i = noise_weights[i]``.

    Parameters
    ----------
    A : (n, n) array_like
        Agent state matrix.
    Bbar : (n, q) array_like
        Disturbance input matrix.
    C : (m, n) array_like
        Output matrix.
    R : (q, q) array_like
        Cost weight on the disturbance (the inverse disturbance intensity, not a covariance), positive
        definite, in 1/(disturbance unit)^2.
    L : (n, m) array_like
        Local gain.
    Phi : (m, m) array_like or float
        Coupling gain.
    lam : (N,) array_like
        Laplacian eigenvalues.
    noise_weights : sequence of N (m, m) arrays
        ``Q_i``, positive definite.
    T : (n, n) array_like, optional
        Measure ``trace(T S_i T^T)`` (e.g. ``DistributedObserver.T``, the
        coordinates of eq. (32)); default: the agent's original coordinates.

    Returns
    -------
    float
        ``inf`` (a defined value: the cost of an unstable mode is infinite) if some mode
        is not Hurwitz.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, observers
    >>> A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])  # Example 1
    >>> obs = observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1),
    ...                                     graphs.ring_graph(5))
    >>> Rw = [10.0 * np.eye(1) + l * 5.0 * np.eye(1) for l in obs.lam]
    >>> cost = observers.achieved_cost(A, Bbar, C, np.eye(1), obs.L, obs.Phi, obs.lam, Rw, T=obs.T)
    >>> bool(np.isclose(cost, obs.cost))
    True
    """
    A = _square(A, "A")
    n = A.shape[0]
    Bbar = _matrix(Bbar, "Bbar", (n, None))
    C = _matrix(C, "C", (None, n))
    m = C.shape[0]
    R = check_covariance(np.atleast_2d(_float_array(R, "R")), "R", Bbar.shape[1], definite=True)
    L = _matrix(L, "L", (n, m))
    Phi = as_matrix(np.atleast_2d(_float_array(Phi, "Phi")), "Phi", (m, m))
    lam = _eigenvalues(lam)
    _check_sequence(noise_weights, "noise_weights", lam.size)
    noise = [check_covariance(np.atleast_2d(_float_array(q, f"noise_weights[{k}]")), f"noise_weights[{k}]", m,
                              definite=True)
             for k, q in enumerate(noise_weights)]
    if T is not None:
        T = _matrix(T, "T", (n, n))
    return _mode_costs(A, C, L, Phi, lam, Bbar @ np.linalg.solve(R, Bbar.T), noise, T)


#: Largest state dimension for which a stack of Lyapunov equations is solved as one batch of
#: Kronecker systems (``n^2 x n^2``); larger ones go one by one to Bartels-Stewart.
_KRON_MAX = 8


def _lyapunov_stack(Acl: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``S_k`` with ``Acl_k S_k + S_k Acl_k^T + M_k = 0`` for stacks ``Acl``, ``M`` of shape (K, n, n)."""
    K, n, _ = Acl.shape
    if n > _KRON_MAX:
        return np.stack([sla.solve_continuous_lyapunov(a, -q) for a, q in zip(Acl, M)])
    eye = np.eye(n)
    # row-major vec: vec(Acl S) = (Acl (x) I) vec(S), vec(S Acl^T) = (I (x) Acl) vec(S)
    op = np.einsum("kij,ab->kiajb", Acl, eye) + np.einsum("ij,kab->kiajb", eye, Acl)
    return np.linalg.solve(op.reshape(K, n * n, n * n), -M.reshape(K, n * n, 1)).reshape(K, n, n)


def _traces(S: np.ndarray, T: np.ndarray | None) -> list[float]:
    """``trace(S_k)``, or ``trace(T S_k T^T)``, for a stack ``S`` (K, n, n)."""
    if T is not None:
        S = T @ S @ T.T
    return np.trace(S, axis1=1, axis2=2).tolist()


def _mode_costs(A, C, L, Phi, lam, BRB, noise, T=None) -> float:
    """sum_i trace(S_i) (or trace(T S_i T^T)), S_i from eq. (57) with equality; inf if a mode is unstable."""
    m = C.shape[0]
    Li = L @ (np.eye(m) + np.asarray(lam)[:, None, None] * Phi)  # (N, n, m): the gain of each mode
    Ai = A - Li @ C
    if np.max(np.linalg.eigvals(Ai).real) >= 0:
        return float("inf")
    S = _lyapunov_stack(Ai, BRB + Li @ np.linalg.solve(np.stack(noise), Li.transpose(0, 2, 1)))
    return float(sum(_traces(S, T)))


def _centralized_cost(A, C, BRB, noise, T=None) -> float:
    """sum_i trace(S_i) (or trace(T S_i T^T)) of the mode AREs (53): ``A S + S A^T - S C^T Q_i C S + BRB = 0``.

    All modes at once: the stable invariant subspace of each Hamiltonian from one batched
    eigen-decomposition, polished by one Newton (Kleinman) step. A mode whose solution fails the
    checks of :func:`mascore.riccati.solve_care` (relative residual, stabilizing) is solved again by
    :func:`~mascore.riccati.solve_care`, which raises if it has no stabilizing solution.
    """
    n = A.shape[0]
    K = len(noise)
    G = C.T @ np.stack(noise) @ C  # (K, n, n): C^T Q_i C
    H = np.empty((K, 2 * n, 2 * n))
    H[:, :n, :n], H[:, :n, n:], H[:, n:, :n], H[:, n:, n:] = A.T, -G, -BRB, -A
    with np.errstate(all="ignore"):
        try:
            w, V = np.linalg.eig(H)
            U = np.take_along_axis(V, np.argsort(w.real, axis=1)[:, None, :n], axis=2)
            S = np.linalg.solve(U[:, :n].transpose(0, 2, 1), U[:, n:].transpose(0, 2, 1)).real  # (U2 U1^-1)^T
            S = (S + S.transpose(0, 2, 1)) / 2
            S = S + _lyapunov_stack(A - S @ G, A @ S + S @ A.T - S @ G @ S + BRB)  # Newton step
            S = (S + S.transpose(0, 2, 1)) / 2
        except np.linalg.LinAlgError:  # a singular U1 or Newton step: every mode falls back below
            S = np.full((K, n, n), np.nan)
        SGS = S @ G @ S
        residual = np.linalg.norm(A @ S + S @ A.T - SGS + BRB, axis=(1, 2))
        scale = np.maximum.reduce([np.ones(K), np.full(K, np.linalg.norm(BRB)), np.linalg.norm(A @ S, axis=(1, 2)),
                                   np.linalg.norm(SGS, axis=(1, 2))])
        good = residual <= RICCATI_RTOL * scale
        good[good] = np.linalg.eigvals(A.T - G[good] @ S[good]).real.max(axis=1) < 0
    for k in np.flatnonzero(~good):
        S[k] = solve_care(A.T, C.T, BRB, np.linalg.inv(noise[k]))[1]
    return float(sum(_traces(S, T)))


def _check_observer(A, Bbar, C, Q, R, qname="Q"):
    A = _square(A, "A")
    n = A.shape[0]
    Bbar = _matrix(Bbar, "Bbar", (n, None))
    C = _matrix(C, "C", (None, n))
    if Bbar.shape[1] == 0 or C.shape[0] == 0:
        raise ValueError(f"Bbar needs at least one column and C at least one row; got shapes {Bbar.shape}, {C.shape}")
    Q = check_covariance(np.atleast_2d(_float_array(Q, qname)), qname, C.shape[0], definite=True)
    R = check_covariance(np.atleast_2d(_float_array(R, "R")), "R", Bbar.shape[1], definite=True)
    check_moderate(("A", A), ("Bbar", Bbar), ("C", C), (qname, Q), ("R", R), what="the observer's Riccati equation")
    if not is_controllable(A, Bbar):
        raise ValueError("(A, Bbar) is not controllable: the minimum-energy ARE has no positive definite solution")
    if not is_controllable(A.T, C.T):
        raise ValueError("(A, C) is not observable: no observer gain makes the error decay")
    return A, Bbar, C, Q, R


# --------------------------------------------------------------------------- argument checks


def _eigenvalues(lam) -> np.ndarray:
    """Laplacian eigenvalues: a finite, non-empty 1-D array, each >= 0."""
    lam = _float_array(lam, "lam")
    if lam.ndim != 1 or lam.size == 0:
        raise ValueError(f"lam must be a non-empty 1-D array of Laplacian eigenvalues; got shape {lam.shape}")
    if not np.all(np.isfinite(lam)):
        raise ValueError("lam contains NaN or infinite entries")
    if np.any(lam < -1e-12):
        raise ValueError(f"lam must hold non-negative Laplacian eigenvalues; smallest is {lam.min():.3g}")
    return lam


def _check_sequence(seq, name: str, size: int) -> None:
    if isinstance(seq, (str, bytes)) or not hasattr(seq, "__len__") or not hasattr(seq, "__getitem__"):
        raise TypeError(f"{name} must be a sequence of arrays, one per eigenvalue in lam; got {type(seq).__name__}")
    if len(seq) != size:
        raise ValueError(f"{name} needs one entry per eigenvalue in lam ({size}); got {len(seq)}")


#: What an overflow of a simulated error or state calls for (the message of :func:`_validation.finite_result`).
_GROWTH_ADVICE = "the error matrix grows too fast over this horizon; shorten t or rescale"


def _check_trace_in(trace_in) -> None:
    if not isinstance(trace_in, str) or trace_in not in ("transformed", "original"):
        raise ValueError(f"trace_in must be 'transformed' or 'original'; got {trace_in!r}")
