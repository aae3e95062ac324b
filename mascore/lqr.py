"""Continuous-time LQR, and LQR for networks of identical agents.

Sign convention (python-control's): a gain ``K`` acts as ``u = -K x``. The
paper of Vlahakis and Halikias writes gains with the opposite sign
(``u = K x`` with ``K = -R^{-1} B^T P``, eq. (8)); every docstring below says
which equation a quantity comes from and flips the sign where needed.

Network notation (Vlahakis and Halikias, Sec. 2-3): N identical agents
``x_i' = A x_i + B u_i``, stacked as ``X' = (I_N (x) A) X + (I_N (x) B) U``
(eq. (3)), and the aggregate cost (7) with the weights of eqs. (10)-(12):
``Q~ = I_N (x) Q1 + Lap (x) Q2`` and ``R~ = I_N (x) R``, where ``Lap`` is the
graph Laplacian (for the complete graph this is exactly eq. (11)). Every
network controller here has the form ``U = -(I_N (x) K_self + Lap (x)
K_coupling) X``; since ``Lap = V diag(lambda) V^T`` with orthogonal ``V``, the
closed loop splits into N independent ``n``-state modes
``A - B (K_self + lambda_i K_coupling)`` and the costs are sums over modes.

That decomposition needs a *symmetric* Laplacian (orthogonal eigenvectors): every
network function here requires an undirected graph and says so when given a
directed one; an adjacency passed where a Laplacian is expected (or a Laplacian
where an adjacency is expected) is named as such. Arguments are checked on entry
(finite entries, shapes, symmetric positive (semi)definite weights, no
self-loops, non-negative weights) and the error names the argument.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla
from numpy.typing import ArrayLike

from ._systems import design_args
from ._validation import (
    Frozen,
    as_matrix,
    check_adjacency,
    check_covariance,
    check_fits_in_memory,
    check_laplacian,
    check_moderate,
    check_positive_int,
    frozen_copy,
)
from ._validation import as_matrix as _matrix
from ._validation import check_square as _square
from ._validation import float_array as _float_array
from .agents import is_system, system_matrices
from .exceptions import RiccatiError
from .graphs import WHY_UNDIRECTED as _WHY_SYMMETRIC
from .graphs import laplacian as _graph_laplacian
from .graphs import laplacian_spectrum
from .kalman import symmetrize
from .noise import psd_factor
from .riccati import is_stabilizable, solve_care, solve_dare

__all__ = [
    "BottomUpLQR",
    "DistributedGain",
    "TopDownLQR",
    "assemble_network_gain",
    "borrelli_keviczky_structure",
    "bottom_up_lqr",
    "centralized_network_cost",
    "centralized_network_lqr",
    "dlqr",
    "lqr",
    "network_controller_cost",
    "network_lqr_weights",
    "top_down_lqr",
]

def lqr(
    A: ArrayLike, B: ArrayLike | None = None, Q: ArrayLike | None = None, R: ArrayLike | None = None,
    N: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Continuous-time infinite-horizon LQR, python-control's ``K, S, E = lqr(A, B, Q, R[, N])``.

    Call as ``lqr(A, B, Q, R)``, ``lqr(A, B, Q, R, N)``, ``lqr(sys, Q, R)`` or
    ``lqr(sys, Q, R, N)`` (``N`` may also be passed by keyword), as python-control
    does. ``sys`` is any state-space object with attributes ``A``, ``B`` and ``dt``
    (a python-control ``StateSpace``, no import needed): ``dt`` 0 or None is
    continuous time; a discrete-time ``sys`` (``dt > 0`` or True) is passed on to
    :func:`dlqr`, like python-control.

    Minimizes ``int_0^inf (x^T Q x + u^T R u + 2 x^T N u) dt`` for ``x' = A x + B u``.
    ``Q`` and ``R`` are *cost weights* (not covariances): ``Q`` in (cost unit)/(state
    unit)^2 per second, ``R`` in (cost unit)/(input unit)^2 per second.

    Parameters
    ----------
    A : (n, n) array_like
        State matrix (1/s).
    B : (n, m) array_like
        Input matrix; ``(A, B)`` must be stabilizable.
    Q : (n, n) array_like
        State cost weight, symmetric positive semidefinite.
    R : (m, m) array_like
        Input cost weight, symmetric positive definite.
    N : (n, m) array_like, optional
        Cross weight of ``2 x^T N u``; ``[[Q, N], [N^T, R]]`` must be positive semidefinite.

    Returns
    -------
    K : (m, n) ndarray
        Optimal gain, ``u = -K x``, ``K = R^{-1} (B^T S + N^T)``.
    S : (n, n) ndarray
        Stabilizing solution of ``A^T S + S A - (S B + N) R^{-1} (B^T S + N^T) + Q = 0``.
    E : (n,) ndarray
        Closed-loop eigenvalues (of ``A - B K``).

    Raises
    ------
    ValueError
        Bad shapes, non-symmetric or indefinite weights, ``(A, B)`` not stabilizable,
        or entries so large that the Riccati equation overflows (the argument is named).
    RiccatiError
        No stabilizing solution (e.g. ``(Q, A)`` has unobservable modes on the
        imaginary axis) or a Riccati residual above :data:`mascore.riccati.RICCATI_RTOL`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import lqr
    >>> K, S, E = lqr.lqr([[0.0, 1.0], [0.0, 0.0]], [[0.0], [1.0]], np.eye(2), np.eye(1))
    >>> np.round(K, 4)                                           # [1, sqrt(3)]
    array([[1.    , 1.7321]])
    >>> import control                                           # doctest: +SKIP
    >>> K, S, E = lqr.lqr(control.ss([[0, 1], [0, 0]], [[0], [1]], np.eye(2), 0), np.eye(2), np.eye(1))  # doctest: +SKIP
    """
    A, B, Q, R, N, dt = _lqr_args("lqr", A, B, Q, R, N)
    discrete = dt is not None and (dt is True or dt != 0)  # python-control: dt = True or > 0 is discrete time
    return _solve_lqr(A, B, Q, R, N, discrete=discrete)


def dlqr(
    A: ArrayLike, B: ArrayLike | None = None, Q: ArrayLike | None = None, R: ArrayLike | None = None,
    N: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Discrete-time infinite-horizon LQR, python-control's ``K, S, E = dlqr(A, B, Q, R[, N])``.

    Call as ``dlqr(A, B, Q, R[, N])`` or ``dlqr(sys, Q, R[, N])`` with a discrete-time
    state-space ``sys`` (attributes ``A``, ``B``, ``dt``, e.g. a python-control
    ``StateSpace`` with ``dt > 0`` or True); a continuous-time ``sys`` is refused.

    Minimizes ``sum_k (x_k^T Q x_k + u_k^T R u_k + 2 x_k^T N u_k)`` for
    ``x_{k+1} = A x_k + B u_k``. ``Q`` and ``R`` are *cost weights* per step (not
    covariances): (cost unit)/(state unit)^2 and (cost unit)/(input unit)^2.

    Parameters
    ----------
    A : (n, n) array_like
        State matrix (dimensionless, one sampling period).
    B : (n, m) array_like
        Input matrix; ``(A, B)`` must be stabilizable (every mode with ``|z| >= 1`` controllable).
    Q : (n, n) array_like
        State cost weight, symmetric positive semidefinite.
    R : (m, m) array_like
        Input cost weight, symmetric positive definite.
    N : (n, m) array_like, optional
        Cross weight of ``2 x^T N u``; ``[[Q, N], [N^T, R]]`` must be positive semidefinite.

    Returns
    -------
    K : (m, n) ndarray
        Optimal gain, ``u_k = -K x_k``, ``K = (R + B^T S B)^{-1} (B^T S A + N^T)``.
    S : (n, n) ndarray
        Stabilizing solution of the discrete-time algebraic Riccati equation.
    E : (n,) ndarray
        Closed-loop eigenvalues (of ``A - B K``), inside the unit circle.

    Raises
    ------
    ValueError
        Bad shapes, non-symmetric or indefinite weights, ``(A, B)`` not stabilizable,
        a continuous-time ``sys``, or entries so large that the Riccati equation overflows.
    RiccatiError
        No stabilizing solution or a Riccati residual above :data:`mascore.riccati.RICCATI_RTOL`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, lqr
    >>> agent = agents.double_integrator(1, 0.1)           # position and velocity, dt = 0.1 s
    >>> K, S, E = lqr.dlqr(agent.A, agent.B, np.eye(2), np.eye(1))
    >>> bool(np.all(np.abs(E) < 1))
    True
    """
    A, B, Q, R, N, dt = _lqr_args("dlqr", A, B, Q, R, N)
    if dt is not None and dt is not True and dt == 0:
        raise ValueError("sys is a continuous-time system (dt = 0): use lqr, or sample it first "
                         "(control.c2d(sys, dt) or LTIAgent.from_continuous(sys.A, sys.B, dt))")
    return _solve_lqr(A, B, Q, R, N, discrete=True)


def _lqr_args(fname: str, A, B, Q, R, N):
    """``(A, B, Q, R, N, dt)`` from python-control's call forms ``(A, B, Q, R[, N])`` / ``(sys, Q, R[, N])``.

    With a system first, the positional slots after it hold ``Q, R[, N]`` (python-control's order);
    ``Q=``, ``R=``, ``N=`` by keyword work too.
    """
    if is_system(A):
        sys = A
        A_sys, B_sys, dt = system_matrices(sys, name="sys")
        if B is not None:  # (sys, Q, R[, N]) positionally: shift the slots
            rest = [v for v in (Q, R) if v is not None]
            if not rest:
                raise TypeError(f"{fname}(sys, Q, R[, N]) needs R")
            if len(rest) == 2 and N is not None:
                raise TypeError(f"{fname}(sys, Q, R[, N]): N given twice")
            Q, R, N = B, rest[0], (rest[1] if len(rest) == 2 else N)
        A, B = A_sys, B_sys
    else:
        dt = None
        if B is None:
            raise TypeError(f"{fname}() takes (A, B, Q, R[, N]) or (sys, Q, R[, N]); B is missing")
    for name, value in (("Q", Q), ("R", R)):
        if value is None:
            raise TypeError(f"{fname}() needs the cost weight {name}")
    return A, B, Q, R, N, dt


def _solve_lqr(A, B, Q, R, N, discrete: bool):
    A = _square(A, "A")
    n = A.shape[0]
    B = _matrix(B, "B", (n, None))
    m = B.shape[1]
    Q = _weight(Q, "Q", n)
    R = _weight(R, "R", m, definite=True)
    _check_scale(("A", A), ("B", B), ("Q", Q), ("R", R))
    if N is None:
        return _solved(solve_dare if discrete else solve_care, A, B, Q, R, discrete=discrete)
    N = _matrix(np.atleast_2d(_float_array(N, "N")), "N", (n, m))
    _check_scale(("N", N))
    # x^T Q x + u^T R u + 2 x^T N u = x^T (Q - N R^-1 N^T) x + v^T R v with v = u + R^-1 N^T x
    RinvNt = np.linalg.solve(R, N.T)
    Qt = symmetrize(Q - N @ RinvNt)
    scale = max(1.0, float(np.abs(Q).max()))
    if float(np.linalg.eigvalsh(Qt).min()) < -1e-10 * scale:
        raise ValueError("N: the cost weight [[Q, N], [N^T, R]] must be positive semidefinite "
                         "(Q - N R^-1 N^T has a negative eigenvalue)")
    At = A - B @ RinvNt
    Kt, S, E = _solved(solve_dare if discrete else solve_care, At, B, Qt, R, discrete=discrete)
    return Kt + RinvNt, S, E




def _check_scale(*named: tuple[str, np.ndarray]) -> None:
    """Refuse (naming it) an input whose entries overflow floating point once squared."""
    check_moderate(*named, what="the Riccati equation")


def _solved(solver, A, B, Q, R, discrete: bool):
    """Solve the Riccati equation; test stabilizability only when no stabilizing solution came out.

    A stabilizing solution (residual and closed-loop eigenvalues checked by `solver`) exists only for
    a stabilizable pair, so the test, one SVD per unstable mode, is needed only to explain a failure.
    """
    try:
        return solver(A, B, Q, R)
    except RiccatiError:
        if not is_stabilizable(A, B, discrete=discrete):
            unstable = "|z| >= 1" if discrete else "Re s >= 0"
            raise ValueError(f"(A, B) is not stabilizable (a mode with {unstable} is uncontrollable): "
                             "the LQR problem has no stabilizing solution") from None
        raise


def _undirected_laplacian(laplacian: ArrayLike, name: str, why: str) -> np.ndarray:
    """A symmetric graph Laplacian (an adjacency passed by mistake is named as such)."""
    return check_laplacian(laplacian, name, undirected=True, why=why)


def _undirected_adjacency(adjacency: ArrayLike, name: str = "adjacency") -> tuple[np.ndarray, np.ndarray]:
    """A symmetric adjacency (no self-loops, non-negative weights) and its Laplacian ``diag(A 1) - A``."""
    Adj = check_adjacency(adjacency, name, undirected=True, why=_WHY_SYMMETRIC)
    return Adj, _graph_laplacian(Adj)


def network_lqr_weights(
    Q1: ArrayLike, Q2: ArrayLike, R: ArrayLike, laplacian: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Aggregate weights of eqs. (10)-(12): ``Q~ = I (x) Q1 + Lap (x) Q2``, ``R~ = I (x) R``.

    With the complete graph's Laplacian this is eq. (11) entry by entry
    (``Q~_ii = Q1 + (N-1) Q2``, ``Q~_ij = -Q2``); with another graph it penalizes
    ``Q2`` only on the differences between neighbours.

    Parameters
    ----------
    Q1 : (n, n) array_like
        Cost weight on each agent's own state (symmetric PSD), not a covariance; (cost unit)/(state unit)^2/s.
    Q2 : (n, n) array_like
        Cost weight on the differences between neighbours (symmetric PSD), not a covariance;
        (cost unit)/(state unit)^2/s.
    R : (m, m) array_like
        Input cost weight (symmetric positive definite), not a covariance; (cost unit)/(input unit)^2/s.
    laplacian : (N, N) array_like
        Symmetric (undirected): ``Q~`` weighs a quadratic cost and must be symmetric itself.

    Returns
    -------
    Qt : (N n, N n) ndarray
        ``I (x) Q1 + Lap (x) Q2``.
    Rt : (N m, N m) ndarray
        ``I (x) R``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> Qt, Rt = lqr.network_lqr_weights(np.eye(2), np.eye(2), np.eye(1), graphs.laplacian(graphs.ring_graph(3)))
    >>> Qt.shape, Rt.shape
    ((6, 6), (3, 3))
    """
    Lap = _undirected_laplacian(laplacian, "laplacian",
                                "the cost weight I (x) Q1 + Lap (x) Q2 must be symmetric")
    Q1 = _weight(Q1, "Q1", atleast_2d=False)
    Q2 = _weight(Q2, "Q2", Q1.shape[0], atleast_2d=False)
    R = _weight(R, "R", definite=True, atleast_2d=False)
    N = Lap.shape[0]
    return np.kron(np.eye(N), Q1) + np.kron(Lap, Q2), np.kron(np.eye(N), R)


def centralized_network_lqr(
    A: ArrayLike, B: ArrayLike | None = None, Q1: ArrayLike | None = None, Q2: ArrayLike | None = None,
    R: ArrayLike | None = None, laplacian: ArrayLike | None = None, *, dt: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centralized network LQR, eqs. (7)-(9), solved as one ``N n``-state Riccati equation.

    This is the dense reference (cost ``O((N n)^3)``); use
    :func:`centralized_network_cost` for large N.

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix (continuous time unless `dt` is given), or the agent as a system
        (then B is left out: ``f(sys, Q1, Q2, R, ...)``; its ``dt`` sets the time base).
    B : (n, m) array_like, optional
        Agent input matrix (not with a system).
    Q1 : (n, n) array_like
        Cost weight on each agent's own state (symmetric PSD), not a covariance; (cost unit)/(state unit)^2/s.
    Q2 : (n, n) array_like
        Cost weight on the differences between neighbours (symmetric PSD), not a covariance;
        (cost unit)/(state unit)^2/s.
    R : (m, m) array_like
        Input cost weight (symmetric positive definite), not a covariance; (cost unit)/(input unit)^2/s.
    laplacian : (N, N) array_like
        Laplacian of a connected undirected graph.
    dt : float, optional
        Sampling time (s) of a discrete-time agent ``x_{k+1} = A x_k + B u_k``: the design is then in
        discrete time (costs per step, :func:`dlqr`'s Riccati equation). Default: the system's own
        time base; for arrays, continuous time, and an ``A`` whose every eigenvalue has a positive
        real part (the spectrum of a sampled matrix) is refused: give its `dt`, or ``dt=0`` if it is
        continuous time.

    Returns
    -------
    K : (N m, N n) ndarray
        ``U = -K X`` (the paper's eq. (8) is ``-K``).
    P : (N n, N n) ndarray
        Solution of eq. (9).
    E : (N n,) ndarray
        Closed-loop eigenvalues.

    Raises
    ------
    ValueError
        Bad shapes or weights, ``(A, B)`` not controllable, or `laplacian` not the
        Laplacian of a connected undirected graph.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> K, P, E = lqr.centralized_network_lqr(A, B, **w, laplacian=graphs.laplacian(graphs.ring_graph(4)))
    >>> K.shape, bool(E.real.max() < 0)
    ((4, 8), True)
    """
    A, B, (Q1, Q2, R, laplacian), dt = design_args("centralized_network_lqr", A, B,
        dict(Q1=Q1, Q2=Q2, R=R, laplacian=laplacian), dt)
    A, B, Q1, Q2, R = _check_agent(A, B, Q1, Q2, R, discrete=dt != 0)
    laplacian_spectrum(laplacian)  # symmetric Laplacian of a connected graph, else ValueError
    Qt, Rt = network_lqr_weights(Q1, Q2, R, laplacian)
    N = Qt.shape[0] // A.shape[0]
    return _riccati(dt)(np.kron(np.eye(N), A), np.kron(np.eye(N), B), Qt, Rt)


def borrelli_keviczky_structure(
    A: ArrayLike, B: ArrayLike | None = None, Q1: ArrayLike | None = None, Q2: ArrayLike | None = None,
    R: ArrayLike | None = None, n_agents: int | None = None, *, dt: float | None = None,
) -> dict:
    """Closed-form blocks of the centralized solution for all-to-all weights, eqs. (13)-(16).

    ``P`` solves the node ARE (14); ``P2~ = -Pbar / N`` where ``Pbar`` solves
    eq. (15), an ARE for ``(A - X P, B)`` with weight ``N Q2`` and
    ``X = B R^{-1} B^T``. The network solution is eq. (13): diagonal blocks
    ``P - (N-1) P2~``, off-diagonal blocks ``P2~``; the gain has the two-block
    pattern (16).

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix (continuous time unless `dt` is given), or the agent as a system
        (then B is left out: ``f(sys, Q1, Q2, R, ...)``; its ``dt`` sets the time base).
    B : (n, m) array_like, optional
        Agent input matrix (not with a system).
    Q1 : (n, n) array_like
        Cost weight on each agent's own state (symmetric PSD), not a covariance; (cost unit)/(state unit)^2/s.
    Q2 : (n, n) array_like
        Cost weight on the differences between neighbours (symmetric PSD), not a covariance;
        (cost unit)/(state unit)^2/s.
    R : (m, m) array_like
        Input cost weight (symmetric positive definite), not a covariance; (cost unit)/(input unit)^2/s.
    n_agents : int
        Team size N.
    dt : float, optional
        Sampling time (s) of a discrete-time agent ``x_{k+1} = A x_k + B u_k``: the design is then in
        discrete time (costs per step, :func:`dlqr`'s Riccati equation). Default: the system's own
        time base; for arrays, continuous time, and an ``A`` whose every eigenvalue has a positive
        real part (the spectrum of a sampled matrix) is refused: give its `dt`, or ``dt=0`` if it is
        continuous time.

    Returns
    -------
    dict
        ``P``, ``P2`` (= P2~), ``K1``, ``K2`` (blocks of ``K`` with ``U = -K X``),
        ``P_network`` (N n, N n) and ``K_network`` (N m, N n) assembled from them.

    Raises
    ------
    ValueError
        Bad shapes or weights, ``(A, B)`` not controllable, or `n_agents` not a positive integer
        (``TypeError`` for a float or another non-integer type).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> blocks = lqr.borrelli_keviczky_structure(A, B, **w, n_agents=3)
    >>> Lap = graphs.laplacian(graphs.complete_graph(3))
    >>> K, P, _ = lqr.centralized_network_lqr(A, B, **w, laplacian=Lap)
    >>> bool(np.allclose(blocks["P_network"], P))            # the closed form equals the dense solution
    True
    """
    A, B, (Q1, Q2, R, n_agents), dt = design_args("borrelli_keviczky_structure", A, B,
        dict(Q1=Q1, Q2=Q2, R=R, n_agents=n_agents), dt)
    A, B, Q1, Q2, R = _check_agent(A, B, Q1, Q2, R, discrete=dt != 0)
    N = _check_agents(n_agents)
    if dt != 0:
        return _modal_structure(A, B, Q1, Q2, R, N)
    Rinv_Bt = np.linalg.solve(R, B.T)
    _, P, _ = solve_care(A, B, Q1, R)  # eq. (14)
    _, Pbar, _ = solve_care(A - B @ Rinv_Bt @ P, B, N * Q2, R)  # eq. (15), Pbar = -N P2~
    P2 = -Pbar / N
    ones = np.ones((N, N))
    P_network = np.kron(np.eye(N), P - N * P2) + np.kron(ones, P2)  # eq. (13)
    K1, K2 = Rinv_Bt @ (P - (N - 1) * P2), Rinv_Bt @ P2  # eq. (16), sign flipped: U = -K X
    K_network = np.kron(np.eye(N), K1 - K2) + np.kron(ones, K2)
    return {"P": P, "P2": P2, "K1": K1, "K2": K2, "P_network": P_network, "K_network": K_network}


@dataclass(frozen=True, eq=False)
class DistributedGain(Frozen):
    """A network gain ``U = -(I_N (x) K_self + Lap (x) K_coupling) X``.

    Parameters
    ----------
    K_self : (m, n) ndarray
        Gain on the agent's own state.
    K_coupling : (m, n) ndarray
        Gain on the Laplacian-weighted neighbour states.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> gain = lqr.DistributedGain(np.array([[1.0, 2.0]]), np.array([[0.5, 0.0]]))
    >>> lqr.assemble_network_gain(gain, graphs.laplacian(graphs.path_graph(2))).shape
    (2, 4)
    """

    K_self: np.ndarray
    K_coupling: np.ndarray

    def __post_init__(self) -> None:
        # checked once when built (finite (m, n) blocks of one shape), kept as read-only copies
        Ks = as_matrix(_float_array(self.K_self, "K_self"), "K_self")
        Kc = as_matrix(_float_array(self.K_coupling, "K_coupling"), "K_coupling", Ks.shape)
        self._set(K_self=frozen_copy(Ks), K_coupling=frozen_copy(Kc))
        for name in ("lam", "Phi"):  # the arrays of the subclasses, kept frozen too
            if isinstance(getattr(self, name, None), np.ndarray):
                self._set(**{name: frozen_copy(getattr(self, name))})


@dataclass(frozen=True, eq=False)
class TopDownLQR(DistributedGain):
    """Borrelli-Keviczky distributed LQR (eq. (17)).

    Parameters
    ----------
    K_self : (m, n) ndarray
        ``R^{-1} B^T P``.
    K_coupling : (m, n) ndarray
        ``-R^{-1} B^T P2~``.
    n_local : int
        ``N_L = d_max + 1``, size of the all-to-all problem the gain is taken from.
    lam : (N,) ndarray
        Laplacian eigenvalues.
    condition_holds : bool
        The sufficient stability condition: every nonzero eigenvalue of the
        Laplacian exceeds ``N_L / 2``.
    spectral_abscissa : float
        Largest real part of the closed-loop eigenvalues (negative: stable).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> ctrl = lqr.top_down_lqr(A, B, **w, adjacency=graphs.ring_graph(4))
    >>> ctrl.n_local, bool(ctrl.spectral_abscissa < 0)                    # ring: degree 2, stable
    (3, True)
    """

    n_local: int = 0
    lam: np.ndarray | None = None
    condition_holds: bool = False
    spectral_abscissa: float = np.nan


@dataclass(frozen=True, eq=False)
class BottomUpLQR(DistributedGain):
    """Deshpande et al. bottom-up distributed LQR (eq. (18)): ``K_coupling = Phi K``.

    Parameters
    ----------
    K_self : (m, n) ndarray
        ``K``, the node LQR gain.
    K_coupling : (m, n) ndarray
        ``Phi K``.
    Phi : (m, m) ndarray
        The coupling found by the convex program.
    bound : float
        Optimal value of the convex program, an upper bound on the aggregate
        cost ``sum_i trace(P_i)`` (expected cost (7) for ``X(0) ~ N(0, I)``),
        traces taken in the agent's original coordinates.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> ctrl = lqr.bottom_up_lqr(A, B, **w, adjacency=graphs.ring_graph(4))
    >>> bool(np.allclose(ctrl.K_coupling, ctrl.Phi @ ctrl.K_self))
    True
    """

    Phi: np.ndarray | None = None
    bound: float = np.nan


def top_down_lqr(
    A: ArrayLike, B: ArrayLike | None = None, Q1: ArrayLike | None = None, Q2: ArrayLike | None = None,
    R: ArrayLike | None = None, adjacency: ArrayLike | None = None, *, dt: float | None = None,
) -> TopDownLQR:
    """Top-down distributed LQR of Borrelli and Keviczky (2008), eq. (17).

    Solves the all-to-all problem for ``N_L = d_max + 1`` agents (eqs. (14)-(15))
    and keeps its gain only on the graph's edges, with ``M`` the Laplacian:
    ``U = -(I (x) R^{-1} B^T P - Lap (x) R^{-1} B^T P2~) X``. Mode ``i`` of the
    closed loop is ``A - X P - (lambda_i / N_L) X Pbar``: an LQR loop for
    ``(A - X P, B)`` with its gain scaled by ``lambda_i / N_L``, stable when the
    scale is at least 1/2 (the LQR gain margin): the condition
    ``lambda_i > N_L / 2`` of eq. (17) is sufficient, not necessary. Both the
    condition and the actual closed-loop spectrum are returned.

    In discrete time (a sampled agent: `dt`, an :class:`~mascore.agents.LTIAgent` or a discrete
    ``StateSpace``) the all-to-all problem is solved by its two Laplacian modes with
    :func:`dlqr`'s Riccati equation: ``K_self = K(Q1)`` and ``K_coupling = (K(Q1 + N_L Q2) -
    K(Q1)) / N_L``, the same formulas as eqs. (14)-(17) give in continuous time. The gain margin
    behind eq. (17)'s condition is a continuous-time fact: ``condition_holds`` then says whether
    every closed-loop mode is stable, and ``spectral_abscissa`` is ``ln(rho) / dt``.

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix (continuous time unless `dt` is given), or the agent as a system
        (then B is left out: ``f(sys, Q1, Q2, R, ...)``; its ``dt`` sets the time base).
    B : (n, m) array_like, optional
        Agent input matrix (not with a system).
    Q1 : (n, n) array_like
        Cost weight on each agent's own state (symmetric PSD), not a covariance; (cost unit)/(state unit)^2/s.
    Q2 : (n, n) array_like
        Cost weight on the differences between neighbours (symmetric PSD), not a covariance;
        (cost unit)/(state unit)^2/s.
    R : (m, m) array_like
        Input cost weight (symmetric positive definite), not a covariance; (cost unit)/(input unit)^2/s.
    adjacency : (N, N) array_like
        Symmetric adjacency of a connected graph: non-negative weights, no self-loops
        (a self-loop would count in the degree ``d_max`` but not in the Laplacian).
    dt : float, optional
        Sampling time (s) of a discrete-time agent ``x_{k+1} = A x_k + B u_k``: the design is then in
        discrete time (costs per step, :func:`dlqr`'s Riccati equation). Default: the system's own
        time base; for arrays, continuous time, and an ``A`` whose every eigenvalue has a positive
        real part (the spectrum of a sampled matrix) is refused: give its `dt`, or ``dt=0`` if it is
        continuous time.

    Returns
    -------
    TopDownLQR
        The gains, the condition of eq. (17) and the closed loop's spectral abscissa.

    Raises
    ------
    ValueError
        Bad shapes or weights, ``(A, B)`` not controllable, a directed or disconnected graph,
        self-loops, or a Laplacian passed as `adjacency`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> lqr.top_down_lqr(A, B, **w, adjacency=graphs.star_graph(5)).condition_holds
    False
    >>> from mascore import agents
    >>> sampled = lqr.top_down_lqr(agents.double_integrator(1, 0.1), **w, adjacency=graphs.ring_graph(4))
    >>> bool(sampled.spectral_abscissa < 0)                               # discrete-time design, stable
    True
    """
    A, B, (Q1, Q2, R, adjacency), dt = design_args("top_down_lqr", A, B,
        dict(Q1=Q1, Q2=Q2, R=R, adjacency=adjacency), dt)
    A, B, Q1, Q2, R = _check_agent(A, B, Q1, Q2, R, discrete=dt != 0)
    Adj, Lap = _undirected_adjacency(adjacency)
    lam, _ = laplacian_spectrum(Lap, "adjacency")
    d_max = int(round(float((Adj > 0).sum(axis=1).max())))
    n_local = d_max + 1
    if dt != 0:  # the modes of the all-to-all problem: K_self = K(Q1), K_coupling = (K(Q1 + N_L Q2) - K(Q1)) / N_L
        blocks = _modal_structure(A, B, Q1, Q2, R, n_local)
        K_self, K_coupling = blocks["K1"] + (n_local - 1) * blocks["K2"], -blocks["K2"]
        abscissa = _spectral_abscissa(A, B, K_self, K_coupling, lam, dt)
        holds = bool(abscissa < 0)  # the gain margin behind eq. (17) is a continuous-time fact
    else:
        blocks = borrelli_keviczky_structure(A, B, Q1, Q2, R, n_local)
        Rinv_Bt = np.linalg.solve(R, B.T)
        K_self, K_coupling = Rinv_Bt @ blocks["P"], -Rinv_Bt @ blocks["P2"]
        abscissa = _spectral_abscissa(A, B, K_self, K_coupling, lam)
        holds = bool(np.all(lam[1:] > n_local / 2))
    return TopDownLQR(
        K_self=K_self, K_coupling=K_coupling, n_local=n_local, lam=lam,
        condition_holds=holds, spectral_abscissa=abscissa,
    )


def bottom_up_lqr(
    A: ArrayLike,
    B: ArrayLike | None = None,
    Q1: ArrayLike | None = None,
    Q2: ArrayLike | None = None,
    R: ArrayLike | None = None,
    adjacency: ArrayLike | None = None,
    solver_options: dict | None = None,
    *,
    dt: float | None = None,
) -> BottomUpLQR:
    """Bottom-up distributed LQR (eq. (18), Deshpande et al. 2011): ``U = -(I (x) K + Lap (x) Phi K) X``.

    Continuous time only (its convex program is a continuous-time Lyapunov inequality): a
    discrete-time system is refused by name; :func:`top_down_lqr` designs in either.

    ``K`` is the node LQR gain for ``(Q1, R)`` (eq. (14)); ``Phi`` (m x m)
    minimizes an upper bound on the aggregate cost with weights
    ``Q~ = I (x) Q1 + Lap (x) Q2``. The convex program is the transpose (dual)
    of the observer program of eqs. (56)-(62): mode ``i`` must satisfy
    ``A_i^T P_i + P_i A_i + Q1 + lambda_i Q2 + K_i^T R K_i <= 0`` with
    ``A_i = A - B (I + lambda_i Phi) K`` and ``K_i = (I + lambda_i Phi) K``,
    and ``sum_i trace(P_i)`` is minimized; it is solved by
    :func:`mascore.observers.coupled_gain_lmi` on ``(A^T, B^T)``.

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix in continuous time, or the agent as a continuous-time system
        (then B is left out: ``f(sys, Q1, Q2, R, ...)``; a discrete-time one is refused).
    B : (n, m) array_like, optional
        Agent input matrix (not with a system); ``(A, B)`` stabilizable.
    Q1 : (n, n) array_like
        Cost weight on each agent's own state (symmetric PSD), not a covariance; (cost unit)/(state unit)^2/s.
    Q2 : (n, n) array_like
        Cost weight on the differences between neighbours (symmetric PSD), not a covariance;
        (cost unit)/(state unit)^2/s.
    R : (m, m) array_like
        Input cost weight (symmetric positive definite), not a covariance; (cost unit)/(input unit)^2/s.
    adjacency : (N, N) array_like
        Symmetric (undirected), connected, non-negative weights, no self-loops.
    solver_options : dict, optional
        Settings passed to the conic solver (Clarabel) by name; default Clarabel's own.
    dt : 0, optional
        The design is in continuous time only. An array ``A`` whose every eigenvalue has a positive
        real part (the spectrum of a sampled matrix) is refused unless ``dt=0`` says that it is
        continuous time.

    Returns
    -------
    BottomUpLQR
        ``K_self = K``, ``K_coupling = Phi K``, ``Phi`` and the cost ``bound``.

    Raises
    ------
    ValueError
        Bad input, ``(A, B)`` not stabilizable, a directed or disconnected graph, self-loops,
        or a Laplacian passed as `adjacency`.
    mascore.SolverError
        The program is infeasible or not solved to optimality.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])
    >>> ctrl = lqr.bottom_up_lqr(A, B, np.eye(2), 0.5 * np.eye(2), np.eye(1), graphs.ring_graph(4))
    >>> ctrl.K_self.shape, ctrl.Phi.shape
    ((1, 2), (1, 1))
    """
    from .observers import coupled_gain_lmi

    A, B, (Q1, Q2, R, adjacency), dt = design_args("bottom_up_lqr", A, B,
        dict(Q1=Q1, Q2=Q2, R=R, adjacency=adjacency), dt, time="continuous")
    A, B, Q1, Q2, R = _check_agent(A, B, Q1, Q2, R)
    _, Lap = _undirected_adjacency(adjacency)
    lam, _ = laplacian_spectrum(Lap, "adjacency")
    K, _, _ = solve_care(A, B, Q1, R)
    Rinv = np.linalg.inv(R)
    # dual: process factor G_i with G_i G_i^T = Q1 + lam_i Q2, noise weight R^{-1}, gain K^T
    factors = [psd_factor(symmetrize(Q1 + l * Q2)) for l in lam]
    try:
        result = coupled_gain_lmi(A.T, B.T, K.T, lam, factors, [Rinv] * len(lam), trace_in="original",
                                  solver_options=solver_options,
                                  what="bottom-up LQR program")
    except ValueError as exc:
        if "L2" not in str(exc):
            raise
        raise ValueError(
            "the node LQR gain K from Q1 and R is singular on the input directions (the dual of eq. (32) "
            "needs it invertible there); choose Q1 so that the node LQR gain has full rank (e.g. Q1 positive "
            f"definite): {exc}"
        ) from None
    Phi = result["Phi"].T
    return BottomUpLQR(K_self=K, K_coupling=Phi @ K, Phi=Phi, bound=result["bound"])


def assemble_network_gain(gain: DistributedGain, laplacian: ArrayLike) -> np.ndarray:
    """The dense ``(N m, N n)`` matrix ``I (x) K_self + Lap (x) K_coupling``.

    Parameters
    ----------
    gain : DistributedGain
        Finite ``K_self`` and ``K_coupling`` of one shape (m, n).
    laplacian : (N, N) array_like
        Symmetric: the gain was designed mode by mode on the orthogonal eigenvectors of an
        undirected graph's Laplacian, so a directed Laplacian is refused.

    Returns
    -------
    (N m, N n) ndarray
        ``U = -K X``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> ctrl = lqr.top_down_lqr(A, B, **w, adjacency=graphs.ring_graph(4))
    >>> lqr.assemble_network_gain(ctrl, graphs.laplacian(graphs.ring_graph(4))).shape
    (4, 8)
    """
    _check_gain(gain)
    Lap = _undirected_laplacian(laplacian, "laplacian", _WHY_SYMMETRIC)
    return np.kron(np.eye(Lap.shape[0]), gain.K_self) + np.kron(Lap, gain.K_coupling)


def network_controller_cost(
    A: ArrayLike, B: ArrayLike | None = None, Q1: ArrayLike | None = None, Q2: ArrayLike | None = None,
    R: ArrayLike | None = None, laplacian: ArrayLike | None = None, gain: DistributedGain | None = None, *,
    dt: float | None = None,
) -> float:
    """Aggregate LQR cost ``trace(P_K)`` of a distributed gain, by Laplacian modes.

    ``P_K`` solves the closed-loop Lyapunov equation with the weights of
    :func:`network_lqr_weights`; ``trace(P_K)`` is the expected cost (7) for
    ``X(0) ~ N(0, I)``. Returns ``inf`` (a defined value, not an error: the cost of an
    unstable loop is infinite) if the closed loop is not stable. ``(A, B)`` need not be
    controllable (the gain is given).

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix (continuous time unless `dt` is given), or the agent as a system
        (then B is left out: ``f(sys, Q1, Q2, R, ...)``; its ``dt`` sets the time base).
    B : (n, m) array_like, optional
        Agent input matrix (not with a system).
    Q1 : (n, n) array_like
        Cost weight on each agent's own state (symmetric PSD), not a covariance; (cost unit)/(state unit)^2/s.
    Q2 : (n, n) array_like
        Cost weight on the differences between neighbours (symmetric PSD), not a covariance;
        (cost unit)/(state unit)^2/s.
    R : (m, m) array_like
        Input cost weight (symmetric positive definite), not a covariance; (cost unit)/(input unit)^2/s.
    laplacian : (N, N) array_like
        Laplacian of a connected undirected graph.
    gain : DistributedGain
        The controller.
    dt : float, optional
        Sampling time (s) of a discrete-time agent ``x_{k+1} = A x_k + B u_k``: the design is then in
        discrete time (costs per step, :func:`dlqr`'s Riccati equation). Default: the system's own
        time base; for arrays, continuous time, and an ``A`` whose every eigenvalue has a positive
        real part (the spectrum of a sampled matrix) is refused: give its `dt`, or ``dt=0`` if it is
        continuous time.

    Returns
    -------
    float
        ``trace(P_K)``, or ``inf`` for an unstable loop.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> Lap = graphs.laplacian(graphs.ring_graph(5))
    >>> td = lqr.top_down_lqr(A, B, **w, adjacency=graphs.ring_graph(5))
    >>> cost = lqr.network_controller_cost(A, B, **w, laplacian=Lap, gain=td)
    >>> bool(cost >= lqr.centralized_network_cost(A, B, **w, laplacian=Lap))     # the optimum is a lower bound
    True
    """
    A, B, (Q1, Q2, R, laplacian, gain), dt = design_args("network_controller_cost", A, B,
                                                             dict(Q1=Q1, Q2=Q2, R=R, laplacian=laplacian, gain=gain), dt)
    A, B, Q1, Q2, R = _check_agent(A, B, Q1, Q2, R, controllable=False)
    _check_gain(gain, B.shape[1], A.shape[0])
    lam, _ = laplacian_spectrum(laplacian)
    total = 0.0
    for l in lam:
        Ki = gain.K_self + l * gain.K_coupling
        Ai = A - B @ Ki
        weight = Q1 + l * Q2 + Ki.T @ R @ Ki
        if dt != 0:  # x_{k+1} = A_i x_k: P = A_i^T P A_i + weight
            if np.max(np.abs(np.linalg.eigvals(Ai))) >= 1:
                return float("inf")
            Pi = sla.solve_discrete_lyapunov(Ai.T, weight)
        else:
            if np.max(np.linalg.eigvals(Ai).real) >= 0:
                return float("inf")
            Pi = sla.solve_continuous_lyapunov(Ai.T, -weight)
        total += float(np.trace(Pi))
    return total


def centralized_network_cost(
    A: ArrayLike, B: ArrayLike | None = None, Q1: ArrayLike | None = None, Q2: ArrayLike | None = None,
    R: ArrayLike | None = None, laplacian: ArrayLike | None = None, *, dt: float | None = None,
) -> float:
    """Optimal aggregate cost ``trace(P~)`` of eq. (9), as ``sum_i trace(ARE(A, B, Q1 + lam_i Q2, R))``.

    Parameters
    ----------
    A : (n, n) array_like, or LTIAgent or StateSpace
        Agent state matrix (continuous time unless `dt` is given), or the agent as a system
        (then B is left out: ``f(sys, Q1, Q2, R, ...)``; its ``dt`` sets the time base).
    B : (n, m) array_like, optional
        Agent input matrix (not with a system).
    Q1 : (n, n) array_like
        Cost weight on each agent's own state (symmetric PSD), not a covariance; (cost unit)/(state unit)^2/s.
    Q2 : (n, n) array_like
        Cost weight on the differences between neighbours (symmetric PSD), not a covariance;
        (cost unit)/(state unit)^2/s.
    R : (m, m) array_like
        Input cost weight (symmetric positive definite), not a covariance; (cost unit)/(input unit)^2/s.
    laplacian : (N, N) array_like
        Laplacian of a connected undirected graph.
    dt : float, optional
        Sampling time (s) of a discrete-time agent ``x_{k+1} = A x_k + B u_k``: the design is then in
        discrete time (costs per step, :func:`dlqr`'s Riccati equation). Default: the system's own
        time base; for arrays, continuous time, and an ``A`` whose every eigenvalue has a positive
        real part (the spectrum of a sampled matrix) is refused: give its `dt`, or ``dt=0`` if it is
        continuous time.

    Returns
    -------
    float
        The optimal cost (one n-state Riccati equation per Laplacian mode).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, lqr
    >>> A, B = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]])      # double integrator
    >>> w = dict(Q1=np.eye(2), Q2=0.5 * np.eye(2), R=np.eye(1))
    >>> Lap = graphs.laplacian(graphs.ring_graph(5))
    >>> K, P, E = lqr.centralized_network_lqr(A, B, **w, laplacian=Lap)
    >>> bool(np.isclose(lqr.centralized_network_cost(A, B, **w, laplacian=Lap), np.trace(P)))   # modes = dense
    True

    Raises
    ------
    ValueError
        Bad shapes or weights, ``(A, B)`` not controllable, or `laplacian` not the
        Laplacian of a connected undirected graph.
    """
    A, B, (Q1, Q2, R, laplacian), dt = design_args("centralized_network_cost", A, B,
        dict(Q1=Q1, Q2=Q2, R=R, laplacian=laplacian), dt)
    A, B, Q1, Q2, R = _check_agent(A, B, Q1, Q2, R, discrete=dt != 0)
    lam, _ = laplacian_spectrum(laplacian)
    solve = _riccati(dt)
    return float(sum(np.trace(solve(A, B, Q1 + l * Q2, R)[1]) for l in lam))


def _check_agent(A, B, Q1, Q2, R, controllable: bool = True, discrete: bool = False):
    """Validate the agent and weights; with `controllable`, also require ``(A, B)`` stabilizable (PBH)."""
    A = _square(A, "A")
    n = A.shape[0]
    B = _matrix(B, "B", (n, None))
    if B.shape[1] == 0:
        raise ValueError(f"B must have at least one column; got shape {B.shape}")
    Q1 = _weight(Q1, "Q1", n)
    Q2 = _weight(Q2, "Q2", n)
    R = _weight(R, "R", B.shape[1], definite=True)
    _check_scale(("A", A), ("B", B), ("Q1", Q1), ("Q2", Q2), ("R", R))
    if controllable and not is_stabilizable(A, B, discrete=discrete):
        unstable = "|z| >= 1" if discrete else "Re s >= 0"
        raise ValueError(f"(A, B) is not stabilizable (a mode with {unstable} is uncontrollable): "
                         "the LQR problem has no stabilizing solution")
    return A, B, Q1, Q2, R


def _riccati(dt):
    """The algebraic Riccati solver of the time base (``dt`` 0: continuous)."""
    return solve_dare if dt != 0 else solve_care


def _modal_structure(A, B, Q1, Q2, R, N: int) -> dict:
    """:func:`borrelli_keviczky_structure` in discrete time, by the two modes of the complete graph.

    The complete graph's Laplacian has eigenvalues 0 (the mean) and N (the rest): the network
    Riccati solution is ``P_network = I (x) P_N + (1 1^T / N) (x) (P_0 - P_N)`` with ``P_l`` the
    node solution for the weight ``Q1 + l Q2``, and likewise for the gain.
    """
    K0, P0, _ = solve_dare(A, B, Q1, R)
    KN, PN, _ = solve_dare(A, B, Q1 + N * Q2, R)
    ones = np.ones((N, N)) / N
    P2, K2 = (P0 - PN) / N, (K0 - KN) / N
    P_network = np.kron(np.eye(N), PN) + np.kron(ones, P0 - PN)
    K_network = np.kron(np.eye(N), KN) + np.kron(ones, K0 - KN)
    return {"P": P0, "P2": P2, "K1": KN + K2, "K2": K2, "P_network": P_network, "K_network": K_network}


def _check_agents(n_agents: int, n: int = 1) -> int:
    n_agents = check_positive_int(n_agents, "n_agents")
    check_fits_in_memory(8.0 * (n_agents * n) ** 2, "n_agents", "the all-to-all problem's matrices")
    return n_agents


def _weight(M, name, size=None, definite=False, atleast_2d=True) -> np.ndarray:
    """A symmetric positive semidefinite (or definite) weight; a scalar is read as 1 x 1 if `atleast_2d`."""
    M = _float_array(M, name)
    M = np.atleast_2d(M) if atleast_2d else M
    if M.ndim != 2:
        raise ValueError(f"{name} must be a matrix ({size if size is not None else 'n'} x "
                         f"{size if size is not None else 'n'}); got shape {M.shape}")
    return check_covariance(M, name, size, definite=definite)


def _check_gain(gain, m: int | None = None, n: int | None = None) -> None:
    """A :class:`DistributedGain` with finite blocks of one shape (m, n)."""
    if not isinstance(gain, DistributedGain):
        raise TypeError(f"gain must be a DistributedGain (K_self, K_coupling); got {type(gain).__name__}")
    Ks = as_matrix(_float_array(gain.K_self, "gain.K_self"), "gain.K_self", (m, n))
    as_matrix(_float_array(gain.K_coupling, "gain.K_coupling"), "gain.K_coupling", Ks.shape)


def _spectral_abscissa(A, B, K_self, K_coupling, lam, dt=0.0) -> float:
    """Largest real part of the closed-loop modes; in discrete time ``ln(rho) / dt`` (per step if dt is True)."""
    if dt != 0:
        rho = max(np.max(np.abs(np.linalg.eigvals(A - B @ (K_self + l * K_coupling)))) for l in lam)
        return float(np.log(rho) / (1.0 if dt is True else dt)) if rho > 0 else -np.inf
    return float(max(np.max(np.linalg.eigvals(A - B @ (K_self + l * K_coupling)).real) for l in lam))
