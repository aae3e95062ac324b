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
rows ``H_i Sigma`` instead, inverts the Cholesky factor of the ``q_i x q_i``
innovation covariance, forms ``V = L^{-1} H_i Sigma`` and subtracts the
rank-``q_i`` correction ``V^T V`` in place (no ``M x M`` temporary):
``O(M^2 q)`` per filter instead of the ``O(M^3)`` of a full ``M x M`` solve, and
exactly the update with ``H_i`` (tested against :func:`mascore.kalman.update` with the
explicit ``H_i``). The prediction uses ``F = I kron A + (I kron B) G`` with the
control Jacobian ``G = dU/dX`` (``nN x 2nN``, written in its final layout):
``F P F^T`` costs at most ``1.5 M^3`` (two matrix products, the symmetric
``G P G^T`` from its tiles on and above the diagonal) instead of ``4 M^3``, every
product by ``A`` or ``B`` being a scaled addition of rows or column blocks, and
one transpose making the result exactly symmetric. All N filters (and all Monte
Carlo runs) advance chunk by chunk, each chunk's update and prediction running
while its covariances are in cache, with the filter's work arrays reused between calls.

Threads: every product of the step is cut into tiles of at most ``2^18``
multiply-adds, which OpenBLAS (the BLAS of numpy's and scipy's wheels) runs on
the calling thread, and the innovation covariances are factored by blocks of
order at most 64 (one LAPACK thread). The step thus never wakes a BLAS thread
pool: its speed and its results are the same with the BLAS's default number of
threads as with one, on an idle or a busy machine, and no process-wide thread
setting is read or changed. (Handing each filter's products to a threaded BLAS
instead makes the pool synchronise at thousands of small calls per step, and
numpy's and scipy's pools, each with spinning threads, take the cores from each
other: several times slower than one thread.)

Shapes: team states are ``(..., N, 2n)`` (rows ``[p_j; v_j]``), covariances
``(..., 2nN, 2nN)`` in the matching flattened order; leading axes are the
estimating agent and Monte Carlo runs.

Checked model, owned work arrays
--------------------------------
:class:`EKFModel` checks the constant data once, at construction (``dt > 0``, a
:class:`~mascore.flocking.FlockingGains`, ``I_N kron Q`` symmetric positive semidefinite, ``R``
definite, sizes) and keeps read-only copies. :class:`FlockingEKF` checks a prior
in full once (finite estimates; covariances symmetric positive semidefinite by one
Cholesky factorisation of ``Sigma + 1e-8 max(1, max|Sigma|) I``, the tolerance of
:func:`mascore._validation.check_covariance`), owns a copy of the covariances that it
overwrites in place and the work arrays of the kernels; each call checks only its
measurements and the finiteness of the result (a result that overflows raises,
naming the inputs, instead of returning NaN or inf). Nothing is kept at module level:
independent filters run in parallel threads. :func:`ekf_predict`,
:func:`masked_update` and :func:`ekf_flocking_step` take plain arrays and check every
argument in full on every call, then run the same filter. Errors are ``ValueError``
or ``TypeError`` naming the argument. One agent (``N = 1``) and an isolated agent
(observing only itself) are defined: the update then uses the agent's own
measurement only.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg.blas import dgemm as _dgemm
from scipy.linalg.lapack import dpotrf as _dpotrf
from scipy.linalg.lapack import dtrtri as _dtrtri

from . import _flocking_core as _core
from ._flocking_core import FlockingGains
from ._flocking_core import check_dt as _check_dt
from ._flocking_core import check_gains as _check_gains
from ._flocking_core import check_range as _check_range
from ._flocking_core import check_steps as _check_steps
from ._flocking_core import check_team as _check_team
from ._flocking_core import float_array as _float_array
from ._progress import progress_bar
from ._validation import (
    SYMMETRY_RTOL,
    Frozen,
    agent_index,
    check_covariance,
    check_generator,
    check_positive_int,
    finite_result,
    frozen_copy,
    require_finite,
    state_view,
)
from .estimation import Message
from .flocking import FlockingRun
from .graphs import proximity_graph
from .sensing import measure, team_noise_covariance

__all__ = [
    "EKFModel",
    "EKFStep",
    "FlockingEKF",
    "ekf_predict",
    "masked_update",
    "ekf_flocking_step",
    "EstimatedFlockingRun",
    "simulate_estimation_based_flocking",
    "nees_against_q",
]


class EKFModel(Frozen):
    """The constant data of the agents' EKFs, checked once: team size, ``dt``, gains, ``I_N kron Q``, ``R``.

    The constructor checks every argument (``dt > 0``, a :class:`~mascore.flocking.FlockingGains`,
    covariances finite, symmetric, positive semidefinite -- ``R`` definite -- and of
    the team's size) and stores read-only copies (:func:`mascore._validation.frozen_copy`),
    so no later change to the caller's arrays can slip past the check. The prediction
    part (`dt`, `gains`, `Q_team`) and the measurement part (`R`) may be given alone
    (for :meth:`FlockingEKF.predict` or :meth:`FlockingEKF.update` only); a model holds no
    mutable state and may be shared between filters and threads.

    Parameters
    ----------
    n_agents : int
        Team size ``N`` (>= 1).
    dt : float, optional
        Sampling time (s), finite and > 0 (with `gains` and `Q_team`).
    gains : mascore.flocking.FlockingGains, optional
        The flocking gains of eq. (6).
    Q_team : (2nN, 2nN) array_like, optional
        Team process-noise covariance ``I_N kron Q`` (symmetric positive semidefinite).
    R : (2nN, 2nN) array_like, optional
        Measurement-noise covariance of ``nu_i`` (symmetric positive definite).
    state_dim : int, optional
        ``2n``, the size of one agent's state (default: from the covariances' size).

    Raises
    ------
    ValueError, TypeError
        Naming the argument that is refused.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> model = dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12))
    >>> model.state_dim, model.R.flags.writeable
    (4, False)
    """

    __slots__ = ("n_agents", "state_dim", "dt", "gains", "Q_team", "R", "Q_blocks")

    def __init__(
        self, n_agents: int, dt: float | None = None, gains: FlockingGains | None = None,
        Q_team: ArrayLike | None = None, R: ArrayLike | None = None, state_dim: int | None = None,
    ) -> None:
        N = check_positive_int(n_agents, "n_agents")
        motion = any(v is not None for v in (dt, gains, Q_team))  # then each of them is checked (None refused)
        if not motion and R is None:
            raise ValueError("give the prediction part (dt, gains, Q_team), the measurement part (R), or both")
        if state_dim is not None and check_positive_int(state_dim, "state_dim") % 2:
            raise ValueError(f"state_dim must be even (2n: positions and velocities); got {state_dim}")
        M = None if state_dim is None else N * state_dim
        Q = Qb = None
        for name, given, C, definite in (("Q_team", motion, Q_team, False), ("R", R is not None, R, True)):
            if not given:
                continue
            if name == "Q_team":
                dt = _check_dt(dt)
                _check_gains(gains)
            C = _constant_covariance(C, name, M, definite=definite)
            if M is None and (C.shape[0] % N or (C.shape[0] // N) % 2):
                raise ValueError(f"{name} must be (2nN, 2nN) for N = n_agents = {N}; got {C.shape}")
            M = C.shape[0]
            if name == "Q_team":
                Q = C
            else:
                R = C
        m = M // N
        if Q is not None:
            Qb = _block_diagonal(Q, N, m)
        self._set(n_agents=N, state_dim=m, dt=dt, gains=gains, Q_team=None if Q is None else frozen_copy(Q),
                  R=None if R is None else frozen_copy(R), Q_blocks=None if Qb is None else frozen_copy(Qb))

    def _args(self) -> tuple:
        return (self.n_agents, self.dt, self.gains, self.Q_team, self.R, self.state_dim)

    def __repr__(self) -> str:
        return (f"EKFModel(n_agents={self.n_agents}, state_dim={self.state_dim}, dt={self.dt!r}, "
                f"gains={self.gains!r}, Q_team={'given' if self.Q_team is not None else None}, "
                f"R={'given' if self.R is not None else None})")


class EKFStep(NamedTuple):
    """Result of :meth:`FlockingEKF.step`.

    Parameters
    ----------
    X_post : (..., N, N, 2n) ndarray
        Updated estimates (read-only).
    U : (..., N, n) ndarray or None
        ``U[..., i]``: agent ``i``'s control from its own updated estimate, eq. (39) (m/s^2);
        ``None`` without prediction.
    X_next : (..., N, N, 2n) ndarray or None
        Predicted estimates for the next step (read-only); ``None`` without prediction.
    variance : (..., N, 2nN) ndarray
        Diagonal of the updated covariances ``Sigma_post``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0]])   # 2 agents [p, v]
    >>> ekf = dekf.FlockingEKF(dekf.EKFModel(2, 0.1, gains, 0.01 * np.eye(8), np.eye(8)),
    ...                        np.broadcast_to(X, (2, 2, 4)), np.eye(8))
    >>> X_post, U, X_next, variance = ekf.step(X, np.ones((2, 2), bool), predict=False)   # a last step
    >>> U is None and X_next is None, variance.shape
    (True, (2, 8))
    """

    X_post: np.ndarray
    U: np.ndarray | None
    X_next: np.ndarray | None
    variance: np.ndarray


class FlockingEKF:
    """A bank of the agents' EKFs of the team state that owns its covariances and work arrays.

    The prior is checked in full once, here (finite estimates, covariances symmetric
    positive semidefinite, shapes); the filter keeps its own copy of the covariances
    and overwrites it in place at every step, with work arrays allocated once and passed
    to the kernels as ``out=``. :meth:`step` (update, own control, prediction, chunk by
    chunk while the covariances are in cache) is the fast path of
    :func:`simulate_estimation_based_flocking`; :meth:`update` and :meth:`predict` run the
    two halves separately. Each call checks only its measurements and the finiteness of
    the result (raising a ``ValueError`` that names the inputs).

    Parameters
    ----------
    model : EKFModel
        The checked constant data.
    X_hat : (..., N, 2n) array_like
        Prior estimates of the team, one per filter (leading axes: filters, runs). For
        :meth:`step` the last leading axis is the estimating agent: ``(..., N, N, 2n)``.
    Sigma : (2nN, 2nN) or (..., 2nN, 2nN) array_like
        Their covariances, broadcast against `X_hat`'s leading axes.

    Notes
    -----
    No state is shared between filters, so independent filters run in parallel threads.
    One filter object is not for concurrent use: its state and work arrays change at
    every call. :attr:`X_hat` and :attr:`Sigma` are copies of the filter's state (:meth:`view` gives a
    read-only view, changed by the next call); on an error the state is undefined.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Song et al., Table I
    >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents [p, v]
    >>> ekf = dekf.FlockingEKF(dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12)),
    ...                        np.broadcast_to(X, (3, 3, 4)), np.eye(12))
    >>> out = ekf.step(X + 0.1, np.ones((3, 3), bool))      # everyone sees everyone
    >>> out.U.shape, ekf.X_hat.shape, ekf.Sigma.shape
    ((3, 2), (3, 3, 4), (3, 12, 12))
    """

    def __init__(self, model: EKFModel, X_hat: ArrayLike, Sigma: ArrayLike) -> None:
        if not isinstance(model, EKFModel):
            raise TypeError(f"model must be a mascore.distributed_ekf.EKFModel; got {type(model).__name__}")
        X_hat = _check_team(X_hat, "X_hat")
        N, m = model.n_agents, model.state_dim
        if X_hat.shape[-2:] != (N, m):
            raise ValueError(f"X_hat must have shape (..., {N}, {m}) to match the model; got {X_hat.shape}")
        Sigma = _check_sigma(Sigma, "Sigma", N * m, X_hat.shape[:-2], "X_hat")
        self._adopt(model, X_hat, Sigma)

    @classmethod
    def _from_checked(cls, model: EKFModel, X_hat: np.ndarray, Sigma: np.ndarray) -> FlockingEKF:
        """A filter from a prior already checked in full by the caller (no second check)."""
        self = cls.__new__(cls)
        self._adopt(model, X_hat, Sigma)
        return self

    def _adopt(self, model, X_hat, Sigma):
        N, m = model.n_agents, model.state_dim
        M = N * m
        batch = np.broadcast_shapes(X_hat.shape[:-2], Sigma.shape[:-2])
        self._model = model
        self._batch = batch
        self._X = frozen_copy(np.broadcast_to(X_hat, (*batch, N, m)))
        self._P = np.array(np.broadcast_to(Sigma, (*batch, M, M)), dtype=float, order="C")  # owned, in place
        self._chunks = _chunks(int(np.prod(batch, dtype=np.int64)), M)
        self._work = _Scratch(self._chunks[0].stop if self._chunks else 1, N, m)

    @property
    def model(self) -> EKFModel:
        """The checked model."""
        return self._model

    @property
    def X_hat(self) -> np.ndarray:
        """``(..., N, 2n)`` current estimates (a copy; predicted after :meth:`step` or :meth:`predict`)."""
        return self._X.copy()

    @property
    def Sigma(self) -> np.ndarray:
        """``(..., 2nN, 2nN)`` current covariances (a copy; :meth:`view` gives the filter's own array)."""
        return self._P.copy()

    def view(self, name: str) -> np.ndarray:
        """The filter's own state array `name`, read-only and not copied (the fast read in a loop).

        Parameters
        ----------
        name : {"X_hat", "Sigma"}
            The state, as the property of that name.

        Returns
        -------
        ndarray
            A read-only view: the next call may replace or overwrite it in place (copy it to keep it).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import distributed_ekf as dekf
        >>> from mascore.flocking import FlockingGains
        >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
        >>> ekf = dekf.FlockingEKF(dekf.EKFModel(2, 0.1, gains, 0.01 * np.eye(8), np.eye(8)), np.zeros((2, 4)),
        ...                        np.eye(8))
        >>> ekf.view("Sigma").shape, ekf.view("Sigma").flags.writeable
        ((8, 8), False)
        """
        return state_view(self, name, {"X_hat": "_X", "Sigma": "_P"})

    def update(self, z: ArrayLike, observed: ArrayLike) -> np.ndarray:
        """Kalman update with the states of the `observed` agents, eqs. (16)-(20), in place.

        Parameters
        ----------
        z : (..., N, 2n) array_like
            Measured states (eq. (2)), broadcast to the filters; rows of unobserved agents are
            ignored (they must be finite).
        observed : (..., N) array_like of bool
            Which agents' states are in ``z_i`` (eq. (3)).

        Returns
        -------
        X_post : (..., N, 2n) ndarray
            Updated estimates (read-only; also :attr:`X_hat`). :attr:`Sigma` becomes
            ``(I - G_i H_i) Sigma_i^-`` of eq. (20), symmetrized.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import distributed_ekf as dekf
        >>> from mascore.flocking import FlockingGains
        >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
        >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents
        >>> model = dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12))
        >>> ekf = dekf.FlockingEKF(model, np.broadcast_to(X, (3, 3, 4)), np.eye(12))
        >>> seen = np.array([True, True, False])               # agent 2 is out of range
        >>> X_post = ekf.update(X + 0.5, seen)
        >>> bool(np.all(X_post[:, 2] == X[2])), bool(np.trace(ekf.Sigma[0]) < 12.0)   # only the seen agents move
        (True, True)
        """
        model = self._need("update", model_R=True)
        Z, obs = self._measurements(z, observed)
        X, P = self._flat()
        X_post = np.empty(X.shape)
        with np.errstate(over="ignore", invalid="ignore"):
            for ch in self._chunks:
                Pc = P[ch]
                X_post[ch] = _update_rows(X[ch], Pc, Z[ch], obs[ch], model.R, 0.5, self._work)  # Sigma_post / 2
                _symmetrize_sum(Pc, self._work.T[: Pc.shape[0]])  # (Sigma_post + Sigma_post^T) / 2
        _finite_all("EKF update (inputs X_hat, Sigma, z)", self._P, X_post)
        self._X = _read_only(X_post.reshape(self._X.shape))
        return self._X

    def predict(self) -> tuple[np.ndarray, np.ndarray]:
        """EKF time update through the fully-connected flocking dynamics, eqs. (38), (40), in place.

        Returns
        -------
        X_pred : (..., N, 2n) ndarray
            Predicted estimates (read-only; also :attr:`X_hat`); :attr:`Sigma` becomes
            ``F Sigma F^T + I_N kron Q``.
        U : (..., N, n) ndarray
            The control of every agent that each estimate implies (eq. (39) on the
            estimate, fully connected), m/s^2.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import distributed_ekf as dekf
        >>> from mascore.flocking import FlockingGains
        >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
        >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents
        >>> model = dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12))
        >>> ekf = dekf.FlockingEKF(model, np.broadcast_to(X, (3, 3, 4)), np.eye(12))
        >>> X_pred, U = ekf.predict()
        >>> X_pred.shape, U.shape
        ((3, 3, 4), (3, 3, 2))
        """
        model = self._need("predict")
        X, P = self._flat()
        N, m = model.n_agents, model.state_dim
        X_next, U = np.empty(X.shape), np.empty((X.shape[0], N, m // 2))
        with np.errstate(over="ignore", invalid="ignore"):
            for ch in self._chunks:
                Ph = np.multiply(P[ch], 0.5, out=P[ch])
                U[ch], X_next[ch], _ = _predict_half(X[ch], Ph, model, Ph, self._work)
        _finite_all("EKF prediction (inputs X_hat, Sigma)", self._P, X_next, U)
        self._X = _read_only(X_next.reshape(self._X.shape))
        return self._X, U.reshape(*self._batch, N, m // 2)

    def agent_inputs(self, z: ArrayLike, observed: ArrayLike, i: int) -> tuple[dict, tuple]:
        """Agent i's filter (its team estimate and covariance) and its measurements of one step (one run).

        Parameters
        ----------
        z : (N, N, 2n) array_like
            ``z[i, j]``: agent ``i``'s measurement of agent ``j`` (eq. (2)).
        observed : (N, N) array_like of bool
            Sensing mask.
        i : int
            The agent.

        Returns
        -------
        own : dict
            Its estimate ``X`` ``(N, 2n)``, covariance ``Sigma`` ``(2nN, 2nN)`` and measurements ``z``, ``observed``.
        messages : tuple
            Empty: an agent's EKF uses its own measurements only.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import distributed_ekf as dekf
        >>> from mascore.flocking import FlockingGains
        >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
        >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])
        >>> ekf = dekf.FlockingEKF(dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12)),
        ...                        np.broadcast_to(X, (3, 3, 4)), np.eye(12))
        >>> own, messages = ekf.agent_inputs(np.broadcast_to(X, (3, 3, 4)), np.ones((3, 3), bool), 0)
        >>> own["X"].shape, own["Sigma"].shape, messages
        ((3, 4), (12, 12), ())
        """
        if self._X.ndim != 3:
            raise ValueError(f"agent_inputs needs one run of one filter per agent, X_hat (N, N, 2n); got "
                             f"{self._X.shape}")
        z, observed = require_finite(_float_array(z, "z"), "z"), np.asarray(observed, dtype=bool)
        i = agent_index(i, len(self._X))
        return {"X": self._X[i].copy(), "Sigma": self._P[i].copy(), "z": z[i].copy(), "observed": observed[i].copy()}, ()

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """Agent i's EKF step alone: :meth:`update` with its measurements, then :meth:`predict` (eqs. (16)-(20), (38)-(40)).

        Parameters
        ----------
        i : int
            The agent.
        own, messages
            From :meth:`agent_inputs`.

        Returns
        -------
        X_i, Sigma_i : ndarray
            Its predicted team estimate ``(N, 2n)`` and covariance ``(2nN, 2nN)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import distributed_ekf as dekf
        >>> from mascore.flocking import FlockingGains
        >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
        >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])
        >>> model = dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12))
        >>> ekf = dekf.FlockingEKF(model, np.broadcast_to(X, (3, 3, 4)), np.eye(12))
        >>> z, seen = np.broadcast_to(X + 0.1, (3, 3, 4)), np.ones((3, 3), bool)
        >>> X1, S1 = ekf.agent_step(1, *ekf.agent_inputs(z, seen, 1))
        >>> _ = ekf.update(z, seen)                                       # every agent's filter, batched
        >>> X_all, _ = ekf.predict()
        >>> bool(np.allclose(X1, X_all[1]) and np.allclose(S1, ekf.Sigma[1]))
        True
        """
        filt = FlockingEKF._from_checked(self._model, own["X"], own["Sigma"].copy())
        filt.update(own["z"], own["observed"])
        X, _ = filt.predict()
        return X, filt.view("Sigma")

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        """What an agent sends per step: nothing (it senses its neighbours' states, eq. (2)).

        Parameters
        ----------
        i : int
            The agent (the same for all).

        Returns
        -------
        tuple of Message
            Empty.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import distributed_ekf as dekf
        >>> from mascore.flocking import FlockingGains
        >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
        >>> dekf.FlockingEKF(dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12)), np.zeros((3, 3, 4)),
        ...                  np.eye(12)).messages()
        ()
        """
        return ()

    def step(self, z: ArrayLike, observed: ArrayLike, predict: bool = True,
             posterior_out: np.ndarray | None = None) -> EKFStep:
        """One step of every agent's filter and control: eqs. (16)-(20), (39), then (38), (40).

        The update and the prediction of each chunk of filters run while its covariances are
        in cache, overwriting them in place; the filter then holds the predictions (with
        `predict`) or the updates (without).

        Parameters
        ----------
        z : (..., N, N, 2n) array_like
            ``z[..., i, j]``: agent ``i``'s measurement of agent ``j`` (eq. (2)).
        observed : (..., N, N) array_like of bool
            Sensing mask, ``observed[..., i, j]`` iff ``j`` in ``N_i bar``.
        predict : bool
            Also apply the control and predict (``False`` on a last step).
        posterior_out : (..., N, 2nN, 2nN) ndarray, optional
            Where to write the updated covariances ``Sigma_post`` (C-contiguous, of the
            filters' full shape); by default only their diagonal is returned.

        Returns
        -------
        EKFStep
            ``(X_post, U, X_next, variance)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import distributed_ekf as dekf
        >>> from mascore.flocking import FlockingGains
        >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
        >>> X = np.array([[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]])  # 3 agents
        >>> model = dekf.EKFModel(3, 0.1, gains, 0.01 * np.eye(12), np.eye(12))
        >>> ekf = dekf.FlockingEKF(model, np.broadcast_to(X, (3, 3, 4)), np.eye(12))
        >>> out = ekf.step(X + 0.1, np.ones((3, 3), bool))     # everyone sees everyone
        >>> out.U.shape, out.variance.shape, bool(np.all(out.X_next == ekf.X_hat))
        ((3, 2), (3, 12), True)
        """
        model = self._need("step", model_R=True, motion=bool(predict))
        N, m = model.n_agents, model.state_dim
        M, n = N * m, m // 2
        if len(self._batch) < 1 or self._batch[-1] != N:
            raise ValueError(f"step needs one filter per agent: X_hat of shape (..., {N}, {N}, {m}); "
                             f"got {(*self._batch, N, m)}")
        Z, obs = self._measurements(z, observed)
        X, P = self._flat()
        K = X.shape[0]
        post = None
        if posterior_out is not None:
            post = posterior_out.reshape(-1, M, M)
            if (posterior_out.shape != self._P.shape or not np.shares_memory(post, posterior_out)
                    or not posterior_out.flags.writeable):
                raise ValueError(f"posterior_out must be a writeable array of shape {self._P.shape}")
        own = np.arange(K) % N  # filter k is agent k % N's
        if not obs[np.arange(K), own].all():
            raise ValueError("observed must include every agent itself (observed[..., i, i] True): agent i's "
                             "closed neighbourhood holds i, whose own state its control uses (eq. (39))")
        X_post, diag = np.empty(X.shape), np.empty((K, M))
        U, X_next = (np.empty((K, n)), np.empty(X.shape)) if predict else (None, None)
        scale = 0.5 if predict else 1.0  # the prediction starts from Sigma_post / 2
        work = self._work
        sums = np.empty(len(self._chunks))  # of each chunk's new covariances, while they are in cache
        with np.errstate(over="ignore", invalid="ignore"):
            for i, ch in enumerate(self._chunks):
                Ph = P[ch]
                X_post[ch] = _update_rows(X[ch], Ph, Z[ch], obs[ch], model.R, scale, work)  # eqs. (16)-(20)
                diag[ch] = np.diagonal(Ph, axis1=-2, axis2=-1)
                if post is not None:
                    np.multiply(Ph, 1.0 / scale, out=post[ch])
                if predict:
                    diag[ch] *= 2.0
                    U_all, X_next[ch], _ = _predict_half(X_post[ch], Ph, model, Ph, work)  # eqs. (38)-(40)
                    U[ch] = U_all[np.arange(U_all.shape[0]), own[ch]]  # eq. (39): agent i's control, own estimate
                sums[i] = Ph.sum()
        what = "EKF step (inputs X_hat, Sigma, z)"
        if not np.isfinite(sums).all():  # a finite sum proves the chunk finite; else test the entries
            finite_result(what, self._P)
        outs = (X_post, diag) + ((U, X_next) if predict else ()) + ((post,) if post is not None else ())
        _finite_all(what, *outs)
        X_post = _read_only(X_post.reshape(*self._batch, N, m))
        if predict:
            X_next = self._X = _read_only(X_next.reshape(*self._batch, N, m))
            U = U.reshape(*self._batch, n)
        else:
            self._X = X_post
        return EKFStep(X_post, U, X_next, diag.reshape(*self._batch, M))

    # -- helpers (checks of the per-call data, results)

    def _need(self, what, model_R=False, motion=True):
        model = self._model
        if model_R and model.R is None:
            raise ValueError(f"{what} needs a model with R (the measurement-noise covariance)")
        if what != "update" and motion and model.Q_team is None:
            raise ValueError(f"{what} needs a model with dt, gains and Q_team")
        return model

    def _flat(self):
        M = self._model.n_agents * self._model.state_dim
        return self._X.reshape(-1, *self._X.shape[-2:]), self._P.reshape(-1, M, M)

    def _measurements(self, z, observed):
        N, m = self._model.n_agents, self._model.state_dim
        z, observed = _check_measurements(z, observed, N, m)
        batch = self._batch
        for name, got in (("z", z.shape[:-2]), ("observed", observed.shape[:-1])):
            try:
                ok = np.broadcast_shapes(got, batch) == batch
            except ValueError:
                ok = False
            if not ok:
                raise ValueError(f"{name} has batch axes {got} that do not broadcast to the filters' {batch}")
        Z = np.broadcast_to(z, (*batch, N, m)).reshape(-1, N, m)
        obs = np.broadcast_to(observed, (*batch, N)).reshape(-1, N)
        return Z, obs


def ekf_predict(
    X_hat: ArrayLike, Sigma: ArrayLike, dt: float, gains: FlockingGains, Q_team: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """EKF time update through the fully-connected flocking dynamics, eqs. (38), (40).

    Checks every argument in full on every call (the covariances by a Cholesky
    factorisation, ``Q_team`` by its eigenvalues), then runs :meth:`FlockingEKF.predict`;
    for many steps build an :class:`EKFModel` and a :class:`FlockingEKF` once.

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
    N, m = X_hat.shape[-2:]
    Sigma = _check_sigma(Sigma, "Sigma", N * m, X_hat.shape[:-2], "X_hat")
    ekf = FlockingEKF._from_checked(EKFModel(N, dt, gains, Q_team, state_dim=m), X_hat, Sigma)
    X_pred, _ = ekf.predict()
    return np.array(X_pred), ekf._P


def masked_update(
    X_pred: ArrayLike, Sigma_pred: ArrayLike, z: ArrayLike, observed: ArrayLike, R: ArrayLike, *, agent: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with the states of the `observed` agents, eqs. (16)-(20).

    Checks every argument in full on every call, then runs :meth:`FlockingEKF.update`;
    for many steps build an :class:`EKFModel` and a :class:`FlockingEKF` once.

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
        ``z_i = H_i (X + nu_i)`` (eq. (3)). It always holds the agent itself:
        ``observed[..., agent]`` must be True.
    R : (2nN, 2nN) array_like
        Measurement-noise covariance of ``nu_i`` (the paper's ``R``; m^2 and m^2/s^2
        on the position and velocity entries), symmetric positive definite.
    agent : int or (...) array_like of int
        Keyword only: the agent ``i`` running the filter, one for all filters or one
        per filter (e.g. ``np.arange(N)`` for a batch of one filter per agent).

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
    >>> seen = np.array([True, True, False])                  # agent 0's view: agent 2 is out of range
    >>> X_post, P_post = dekf.masked_update(X, 4.0 * np.eye(12), X + 0.5, seen, np.eye(12), agent=0)
    >>> bool(np.allclose(X_post[2], X[2])), bool(np.trace(P_post[:8, :8]) < 32.0)   # only the seen agents move
    (True, True)
    """
    X_pred = _check_team(X_pred, "X_pred")
    N, m = X_pred.shape[-2:]
    Sigma_pred = _check_sigma(Sigma_pred, "Sigma_pred", N * m, X_pred.shape[:-2], "X_pred")
    z, observed = _check_measurements(z, observed, N, m)
    batch = _common_batch(X_pred, Sigma_pred, z, observed)
    _check_self_observed(observed, agent, N, batch)
    R = _float_array(R, "R")
    ekf = FlockingEKF._from_checked(EKFModel(N, R=R, state_dim=m), np.broadcast_to(X_pred, (*batch, N, m)),
                                    Sigma_pred)
    X_post = ekf.update(z, observed)
    return np.array(X_post), ekf._P


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

    Checks every argument in full on every call (the covariances by a Cholesky
    factorisation, ``R`` and ``Q_team`` by their eigenvalues), then runs
    :meth:`FlockingEKF.step`; for many steps build an :class:`EKFModel` and a
    :class:`FlockingEKF` once: their step checks only the measurements and the result.

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
        Team process-noise covariance ``I_N kron Q`` (m^2, m^2/s^2), symmetric positive semidefinite.

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
    X_pred = _check_team(X_pred, "X_pred")
    N, m = X_pred.shape[-2:]
    if X_pred.ndim < 3 or X_pred.shape[-3] != N:
        raise ValueError(f"X_pred must have shape (..., N, N, 2n) (one team estimate per agent); got {X_pred.shape}")
    Sigma_pred = _check_sigma(Sigma_pred, "Sigma_pred", N * m, X_pred.shape[:-2], "X_pred")
    z, observed = _check_measurements(z, observed, N, m)
    batch = _common_batch(X_pred, Sigma_pred, z, observed)
    model = EKFModel(N, dt, gains, Q_team, _float_array(R, "R"), state_dim=m)
    ekf = FlockingEKF._from_checked(model, np.broadcast_to(X_pred, (*batch, N, m)), Sigma_pred)
    Sigma_post = np.empty(ekf._P.shape)
    out = ekf.step(z, observed, posterior_out=Sigma_post)
    return np.array(out.X_post), Sigma_post, out.U, np.array(out.X_next), ekf._P


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
    nees : (..., T+1) ndarray or None
        With ``record_nees=True``: the observer's NEES ``e^T Sigma^{-1} e`` of its
        updated team estimate (dimensionless; ``2nN`` on average for a consistent filter).
    estimates : (..., T+1, N, N, 2n) ndarray or None
        With ``return_estimates=True``: every agent's updated team estimate,
        ``estimates[..., k, i, j]`` agent ``i``'s estimate of agent ``j`` (m, m/s).

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
    nees: np.ndarray | None = None
    estimates: np.ndarray | None = None


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
    *,
    Q_filter: ArrayLike | None = None,
    record_nees: bool = False,
    return_estimates: bool = False,
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
        Process-noise covariance of one agent (team: ``I_N kron Q``), in m^2 and m^2/s^2
        on the position and velocity entries: the noise the agents move with and, unless
        `Q_filter` is given, the one the filters assume.
    R : (2n, 2n) or (2nN, 2nN) array_like
        Measurement-noise covariance per measured agent (team ``I_N kron R``)
        or the paper's full ``R`` (:func:`mascore.sensing.team_noise_covariance`), in m^2, m^2/s^2.
    rng : numpy.random.Generator or int
        Source of process and measurement noise.
    sensing_range : float
        ``r`` (m), finite and > 0.
    observer : int
        Agent whose estimate and covariance are recorded (0-based).
    progress : bool
        Show a ``tqdm`` progress bar over the steps.
    Q_filter : (2n, 2n) array_like, optional
        Keyword only: the process-noise covariance the filters *assume* (default `Q`).
        With the EKF it is a tuning knob: the linearization error of eq. (38) is not
        in the model, and at small `Q` the filter is overconfident unless `Q_filter`
        is inflated (:func:`nees_against_q`).
    record_nees : bool
        Keyword only: also record the observer's NEES at every step (``run.nees``).
    return_estimates : bool
        Keyword only: also keep every agent's updated team estimate at every step
        (``run.estimates``, ``8 (T+1) N^2 2n`` bytes per run).

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
    X_hat = _float_array(X_hat0, "X_hat0")
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
    for flag, value in (("record_nees", record_nees), ("return_estimates", return_estimates)):
        if not isinstance(value, (bool, np.bool_)):
            raise TypeError(f"{flag} must be True or False; got {type(value).__name__} {value!r}")
    Lq = _core.noise_factor(Q, "Q", m)
    Lf = Lq if Q_filter is None else _core.noise_factor(Q_filter, "Q_filter", m)
    model = EKFModel(N, dt, gains, np.kron(np.eye(N), Lf @ Lf.T), team_noise_covariance(_float_array(R, "R"), N, m),
                     state_dim=m)  # checked once: Q_team, R (definite)
    ekf = FlockingEKF._from_checked(model, X_hat, Sigma0)  # owns a copy of the covariances, overwritten in place

    Xs = np.empty((n_steps + 1, *X.shape))
    As = np.empty((n_steps + 1, *batch, N, N), dtype=bool)
    X_obs = np.empty((n_steps + 1, *batch, N, m))
    var_obs = np.empty((n_steps + 1, *batch, N))
    rms = np.empty((n_steps + 1, *batch))
    nees = np.empty((n_steps + 1, *batch)) if record_nees else None
    post = np.empty((*batch, N, M, M)) if record_nees else None  # the updated covariances, for the NEES
    X_all = np.empty((n_steps + 1, *batch, N, N, m)) if return_estimates else None
    pos_idx = (np.arange(N)[:, None] * m + np.arange(n)[None, :])  # (N, n) flat indices of positions
    for k in progress_bar(range(n_steps + 1), enabled=progress, desc="EKF flocking", leave=False):
        A_k = proximity_graph(X[..., :n], sensing_range).astype(bool)
        z, observed = measure(rng, X, A_k, model.R, allow_isolated=True)  # eqs. (2)-(3)
        last = k == n_steps
        # eqs. (16)-(20), then (unless last) eq. (39) and eqs. (38), (40); the covariances overwritten in place
        X_hat, U, X_next, diag = ekf.step(z, observed, predict=not last, posterior_out=post)
        Xs[k], As[k] = X, A_k
        X_obs[k] = X_hat[..., observer, :, :]
        if X_all is not None:
            X_all[k] = X_hat
        var_obs[k] = diag[..., observer, :][..., pos_idx].sum(-1)
        rms[k] = np.sqrt(np.mean(np.sum((X_hat[..., :n] - X[..., None, :, :n]) ** 2, axis=-1), axis=(-1, -2)))
        if nees is not None:  # the observer's updated estimate against its updated covariance
            e = (X - X_obs[k]).reshape(*batch, M)
            nees[k] = np.einsum("...i,...i->...", e, np.linalg.solve(post[..., observer, :, :], e[..., None])[..., 0])
        if last:
            break
        X = _core.propagate(X, U, dt) + rng.standard_normal((*batch, N, m)) @ Lq.T  # eq. (1)
        _core.check_divergence(X, k + 1, dt)
        _core.check_divergence(X_next, k + 1, dt, "estimate")
        _core.check_divergence(np.sqrt(np.abs(np.diagonal(ekf.view("Sigma"), axis1=-2, axis2=-1))), k + 1, dt,
                               "estimated std")
    t = dt * np.arange(n_steps + 1)
    mv = lambda a, nd: np.moveaxis(a, 0, a.ndim - nd - 1)  # noqa: E731  (put time after the batch axes)
    return EstimatedFlockingRun(
        t, mv(Xs, 2), mv(As, 2), int(observer), mv(X_obs, 2), mv(var_obs, 1), mv(rms, 0),
        None if nees is None else mv(nees, 0), None if X_all is None else mv(X_all, 3),
    )


def nees_against_q(
    q_values: ArrayLike,
    X0: ArrayLike,
    X_hat0: ArrayLike,
    Sigma0: ArrayLike,
    n_steps: int,
    dt: float,
    gains: FlockingGains,
    R: ArrayLike,
    sensing_range: float,
    seed: int,
    q_true: float | None = None,
    transient: int = 0,
    observer: int = 0,
) -> np.ndarray:
    """The EKF's consistency against its process-noise covariance ``Q = q I``: mean NEES / dof per `q`.

    Runs :func:`simulate_estimation_based_flocking` once per value of `q` (the same
    seed, so the same noise draws where the noise is the same) and averages the
    observer's NEES over the runs and the steps after `transient`, divided by its
    ``2nN`` degrees of freedom: 1 is consistent, above 1 overconfident (the filter's
    covariance is too small for its errors), below 1 pessimistic.

    Parameters
    ----------
    q_values : (K,) array_like
        Process-noise levels ``q`` (m^2 on positions, m^2/s^2 on velocities), > 0.
    X0, X_hat0, Sigma0 : array_like
        Initial states, priors and their covariance, as in
        :func:`simulate_estimation_based_flocking` (``X0`` ``(runs, N, 2n)``).
    n_steps : int
        Steps per run.
    dt : float
        Sampling time (s).
    gains : FlockingGains
        Flocking gains of eq. (6).
    R : (2n, 2n) or (2nN, 2nN) array_like
        Measurement-noise covariance (m^2, m^2/s^2).
    sensing_range : float
        ``r`` (m).
    seed : int
        Seed of the noise (one generator per `q`, all from this seed).
    q_true : float, optional
        The agents' true process noise ``q_true I``; the filters assume ``q I``. By
        default the truth follows ``q`` too (a model-matched filter at every ``q``).
    transient : int
        Steps left out at the start of each run (the prior's transient).
    observer : int
        The agent whose filter is scored (0-based).

    Returns
    -------
    (K,) ndarray
        Mean NEES / ``2nN`` for each `q`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import distributed_ekf as dekf
    >>> from mascore.flocking import FlockingGains
    >>> gains = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)   # Table I
    >>> X = np.array([[[0.0, 0.0, 1.0, 0.0], [100.0, 0.0, 0.0, 1.0], [0.0, 100.0, 0.0, 0.0]]])  # one run
    >>> ratio = dekf.nees_against_q([0.01, 1.0], X, np.broadcast_to(X[:, None], (1, 3, 3, 4)), np.eye(12), 30,
    ...                             0.1, gains, np.eye(4), 150.0, seed=0)
    >>> ratio.shape
    (2,)
    """
    q = _float_array(q_values, "q_values")
    if q.ndim != 1 or q.size == 0 or not np.all(np.isfinite(q)) or np.any(q <= 0):
        raise ValueError(f"q_values must be a non-empty 1-D array of finite values > 0; got {q_values!r}")
    seed = check_positive_int(seed, "seed", minimum=0)
    transient = check_positive_int(transient, "transient", minimum=0)
    if transient >= n_steps if isinstance(n_steps, (int, np.integer)) else False:
        raise ValueError(f"transient must be below n_steps = {n_steps}; got {transient}")
    if q_true is not None and not (isinstance(q_true, (int, float, np.integer, np.floating))
                                   and np.isfinite(q_true) and q_true > 0):
        raise ValueError(f"q_true must be a finite number > 0 (m^2, m^2/s^2) or None; got {q_true!r}")
    m = _float_array(X0, "X0").shape[-1]
    out = np.empty(q.size)
    for idx, qk in enumerate(q):
        truth = qk if q_true is None else float(q_true)
        run = simulate_estimation_based_flocking(
            X0, X_hat0, Sigma0, n_steps, dt, gains, truth * np.eye(m), R, np.random.default_rng(seed), sensing_range,
            observer, Q_filter=qk * np.eye(m), record_nees=True)
        dof = run.X.shape[-2] * run.X.shape[-1]
        out[idx] = float(np.mean(run.nees[..., transient:])) / dof
    return out


# ----------------------------------------------------------------------------- private


def _check_batch(got, batch, name, of):
    try:
        np.broadcast_shapes(got, batch)
    except ValueError:
        raise ValueError(f"{name} has batch axes {got} that do not match those of {of} {batch}") from None


def _constant_covariance(C, name, size, definite=False):
    """A constant ``(size, size)`` covariance (any square size if `size` is None), checked in full.

    Finite, symmetric and positive semidefinite by one Cholesky factorisation (:func:`_check_sigma`),
    definite (`definite`) by a second one of the matrix itself; a failure is reported by
    :func:`mascore._validation.check_covariance`, with the smallest eigenvalue.
    """
    C = _float_array(C, name)
    if C.ndim != 2 or C.shape[0] != C.shape[1] or (size is not None and C.shape[0] != size):
        want = "(M, M)" if size is None else f"({size}, {size})"
        raise ValueError(f"Incompatible dimensions of {name}; expected {want} but found {C.shape}")
    C = _check_sigma(C, name, C.shape[0], (), name)
    if definite:
        try:
            np.linalg.cholesky(C)
        except np.linalg.LinAlgError:
            check_covariance(C, name, definite=True)  # raises, with the smallest eigenvalue
    return C


def _check_measurements(z, observed, N, m):
    """Measured team states ``(..., N, m)`` (finite) and a boolean mask ``(..., N)``."""
    z = _check_team(z, "z")
    if z.shape[-2:] != (N, m):
        raise ValueError(f"Incompatible dimensions of z; expected (..., {N}, {m}) but found {z.shape}")
    if isinstance(observed, (str, bytes)) or observed is None:
        raise TypeError(f"observed must be a boolean array (..., {N}); got {type(observed).__name__}")
    observed = np.asarray(observed)
    if observed.dtype != bool or observed.ndim < 1 or observed.shape[-1] != N:
        raise ValueError(f"observed must be a boolean array (..., {N}); got {observed.dtype} {observed.shape}")
    return z, observed


def _check_self_observed(observed: np.ndarray, agent: object, N: int, batch: tuple) -> None:
    """``observed[..., agent]`` is True: an agent's closed neighbourhood holds the agent itself."""
    if isinstance(agent, (bool, np.bool_, str, bytes)) or agent is None:
        raise TypeError(f"agent must be an agent index (int) or an array of them; got {type(agent).__name__} {agent!r}")
    idx = np.asarray(agent)
    if idx.dtype.kind not in "iu":
        raise TypeError(f"agent must be an agent index (int) or an integer array; got dtype {idx.dtype}")
    if np.any(idx < 0) or np.any(idx >= N):
        raise ValueError(f"agent must index one of the N = {N} agents (0..{N - 1}); got {agent!r}")
    try:
        idx = np.broadcast_to(idx, batch)
    except ValueError:
        raise ValueError(f"agent {idx.shape} must be one index or one per filter, shape {batch}") from None
    own = np.take_along_axis(np.broadcast_to(observed, (*batch, N)), idx[..., None], axis=-1)[..., 0]
    if not np.all(own):
        where = tuple(int(v) for v in np.argwhere(~own)[0])
        raise ValueError(
            f"observed must hold the agent itself (its closed neighbourhood N_i bar contains i): observed[..., agent] "
            f"is False{' at batch index ' + str(where) if where else ''}"
        )


def _common_batch(X, Sigma, z, observed):
    """The broadcast leading axes of the arguments of the plain-array functions (named if they clash)."""
    batch = np.broadcast_shapes(X.shape[:-2], Sigma.shape[:-2])
    _check_batch(z.shape[:-2], batch, "z", "X_pred")
    _check_batch(observed.shape[:-1], batch, "observed", "X_pred")
    return np.broadcast_shapes(batch, z.shape[:-2], observed.shape[:-1])


def _read_only(a):
    """`a` (a fresh array of the filter) marked read-only."""
    a.flags.writeable = False
    return a


def _finite_all(what, *arrays):
    """Raise (through :func:`mascore._validation.finite_result`) if an array holds NaN or inf.

    A finite sum proves every entry finite; only when it is not (NaN, inf, or an overflowing
    sum of finite entries) are the entries tested one by one.
    """
    for a in arrays:
        with np.errstate(over="ignore", invalid="ignore"):
            total = a.sum()
        if not np.isfinite(total):
            finite_result(what, a)


def _check_sigma(S, name, M, batch, of):
    """A (..., M, M) stack of covariances: finite, symmetric, positive semidefinite (one Cholesky).

    Same tolerance as :func:`mascore._validation.check_covariance`: symmetric to
    ``1e-8 s`` and smallest eigenvalue ``>= -1e-8 s`` with ``s = max(1, max|S|)``.
    """
    S = _float_array(S, name)
    if S.ndim < 2 or S.shape[-2:] != (M, M):
        raise ValueError(f"Incompatible dimensions of {name}; expected (..., {M}, {M}) but found {S.shape}")
    _check_batch(S.shape[:-2], batch, name, of)
    flat = S.reshape(-1, M, M)
    chunks = _chunks(flat.shape[0], M)  # chunk by chunk: no temporaries of the size of S
    scale = float(np.max([[flat[ch].max(), -flat[ch].min()] for ch in chunks], initial=0.0))  # max |S|
    if not np.isfinite(scale):
        raise ValueError(f"{name} contains NaN or infinite entries")
    tol = SYMMETRY_RTOL * max(1.0, scale)
    if chunks:
        T = np.empty((chunks[0].stop, M, M))
        diag = np.arange(M)
    for ch in chunks:
        blk, Tc = flat[ch], T[: ch.stop - ch.start]
        _transpose_into(blk, Tc)
        Tc -= blk
        if not max(float(Tc.max()), -float(Tc.min())) <= tol:
            raise ValueError(f"{name} must be symmetric")
        np.copyto(Tc, blk)
        Tc[:, diag, diag] += tol
        try:
            np.linalg.cholesky(Tc)
        except np.linalg.LinAlgError:
            check_covariance(S, name)  # raises, with the smallest eigenvalue
    return S


#: Bytes of covariance handled per chunk of filters: each chunk runs its update and prediction while its
#: covariances are in cache (a few MB of L2/L3), instead of sweeping memory once per elementary operation.
_CHUNK_BYTES = 1 << 20


def _chunks(K, M):
    c = max(1, _CHUNK_BYTES // (8 * M * M))
    return [slice(s, min(s + c, K)) for s in range(0, K, c)]


#: Multiply-adds per BLAS call in the step's kernels. OpenBLAS (the BLAS of numpy's and scipy's wheels) runs a
#: matrix product of at most 65536 x 4 (its GEMM_MULTITHREAD_THRESHOLD) multiply-adds on the calling thread: the
#: per-filter products are cut into tiles of this size, so that the step never wakes a BLAS thread pool and runs
#: the same code, with the same results, whatever the BLAS's number of threads. (Large single products do gain
#: from threads; thousands of small ones synchronise the pool at every call, and numpy and scipy each bring
#: their own pool, whose spinning threads then take the cores from each other.)
_TILE_MACS = 1 << 18
#: Longest inner dimension of a tile (longer ones are summed over pieces): short tiles with a long inner
#: dimension run well below the BLAS's rate, as each call packs its operands anew.
_TILE_K = 128
#: Rows of a tile (its columns: as many as :data:`_TILE_MACS` allows).
_TILE_ROWS = 64
#: Largest factor handed to LAPACK in one call (OpenBLAS's Cholesky and triangular inverse run on one thread up
#: to this order); larger innovation covariances are factored by blocks (:func:`_cholesky_inverse`).
_LAPACK_ORDER = 64


def _tiled_matmul(A, B, out, acc, symmetric=False):
    """``out = A @ B`` for stacks ``(c, m, k) @ (c, k, n)``, as BLAS products of at most :data:`_TILE_MACS`.

    `acc` is a flat work array of at least ``c m n`` doubles (used when ``k > _TILE_K``: the pieces of the
    inner dimension are summed). The tiles of one row block are one batched ``np.matmul`` over strided views.
    With `symmetric` (``m = n`` and ``A @ B`` symmetric, such as ``Y G^T`` with ``Y = G Sigma``), only the tiles
    that reach the diagonal or lie above it are computed, and the blocks left of them are the transposes of
    blocks above (about 3/4 of the multiply-adds for ``m = 128``, fewer for larger ``m``).
    """
    c, m, k = A.shape
    n = B.shape[-1]
    kb = min(k, _TILE_K)
    r = min(m, _TILE_ROWS)
    b = max(1, min(n, _TILE_MACS // (r * kb)))
    acc = acc[: c * m * n].reshape(c, m, n)
    for i0 in range(0, m, r):
        j0 = (i0 // b) * b if symmetric else 0  # first column computed in this row block
        nb = (n - j0) // b
        for k0 in range(0, k, kb):
            k1 = min(k, k0 + kb)
            Di = (out if k0 == 0 else acc)[:, i0:i0 + r, j0:]
            Ai, Bk = A[:, i0:i0 + r, k0:k1], B[:, k0:k1, j0:]
            np.matmul(Ai[:, None], _column_tiles(Bk, nb, b), out=_column_tiles(Di, nb, b))
            if n - j0 > nb * b:
                np.matmul(Ai, Bk[:, :, nb * b:], out=Di[:, :, nb * b:])
            if k0:
                out[:, i0:i0 + r, j0:] += Di
        if symmetric and j0:
            np.copyto(out[:, i0:i0 + r, :j0], np.swapaxes(out[:, :j0, i0:i0 + r], -1, -2))
    return out


def _column_tiles(A, nb, b):
    """The first ``nb b`` columns of a stack ``A (c, k, n)`` as ``nb`` tiles of ``b`` columns, ``(c, nb, k, b)``.

    A view (splitting the column axis never copies), cheaper to build than ``as_strided``.
    """
    c, k, _ = A.shape
    return A[:, :, : nb * b].reshape(c, k, nb, b).swapaxes(1, 2)


def _cholesky_inverse(S):
    """``L^{-1}`` for ``S = L L^T`` (``(q, q)`` symmetric positive definite), lower triangular, zero above.

    Up to order :data:`_LAPACK_ORDER` by LAPACK (``potrf``, ``trtri``); above, by 2 x 2 blocks:
    ``L11 = chol(S11)``, ``L21 = S21 L11^{-T}``, ``L22 = chol(S22 - L21 L21^T)`` and
    ``(L^{-1})_21 = -L22^{-1} L21 L11^{-1}``, every product a tiled one (:func:`_tiled_matmul`).

    Raises
    ------
    numpy.linalg.LinAlgError
        If `S` is not positive definite.
    """
    q = S.shape[0]
    if q <= _LAPACK_ORDER:
        L, info = _dpotrf(S, lower=1, clean=1)  # S symmetric: its C order is its F order
        if info == 0:
            Li, info = _dtrtri(L, lower=1)
        if info != 0:
            raise np.linalg.LinAlgError("innovation covariance is not positive definite")
        return Li  # zero above the diagonal: potrf's clean=1 zeroed it and trtri (lower) leaves it
    h = q // 2
    acc = np.empty(q * q)
    Li = np.zeros((q, q))
    Li[:h, :h] = A = _cholesky_inverse(S[:h, :h])
    L21 = _tiled_matmul(S[None, h:, :h], A.T[None], np.empty((1, q - h, h)), acc)[0]  # S21 L11^{-T}
    S22 = S[h:, h:] - _tiled_matmul(L21[None], L21.T[None], np.empty((1, q - h, q - h)), acc)[0]
    Li[h:, h:] = D = _cholesky_inverse(S22)
    T = _tiled_matmul(L21[None], A[None], np.empty((1, q - h, h)), acc)  # L21 L11^{-1}
    Li[h:, :h] = -_tiled_matmul(D[None], T, np.empty((1, q - h, h)), acc)[0]
    return Li


def _subtract_gram(P, V, scale):
    """``P <- scale (P - V^T V)`` in place for a C-contiguous ``(M, M)`` `P` and a ``(q, M)`` `V`.

    By strips of rows of ``P`` (each one in-place BLAS call on the strip's transpose, Fortran order in the same
    memory), every call at most :data:`_TILE_MACS` multiply-adds: no ``M x M`` temporary and no extra pass.
    """
    q, M = V.shape
    rows = max(1, _TILE_MACS // (M * q))
    Vt = V.T
    for i0 in range(0, M, rows):
        strip = P[i0:i0 + rows].T  # (M, r), Fortran order
        out = _dgemm(-scale, Vt, V[:, i0:i0 + rows], beta=scale, c=strip, overwrite_c=1)
        if out is not strip:  # pragma: no cover  (BLAS worked on a copy)
            strip[...] = out


def _update_rows(X, P, z, observed, R, scale, work=None):
    """Eqs. (16)-(20) for a chunk of filters, the covariances updated in place.

    `X` ``(c, N, m)``, `P` ``(c, M, M)`` (C-contiguous, overwritten by ``scale * Sigma_post``),
    `z` ``(c, N, m)``, `observed` ``(c, N)`` bool. The observed rows ``H Sigma`` and the innovation
    covariances ``S = H (Sigma + R) H^T`` of the chunk are gathered at once (index lists padded to a common
    length ``q``); per filter, with its own ``q_i`` entries, ``L^{-1}`` of ``S = L L^T``
    (:func:`_cholesky_inverse`); then for the chunk at once ``V = L^{-1} H Sigma`` (zero in the padding) and per
    filter ``V^T V`` subtracted in place (:func:`_subtract_gram`): ``O(q_i^3 + q_i^2 M + q_i M^2)`` flops, every
    BLAS call a tile run on the calling thread.
    Returns the updated states ``(c, N, m)``.
    """
    c, N, m = X.shape
    M = N * m
    x = X.reshape(c, M)
    counts = observed.sum(axis=-1)
    qa = int(counts.max()) if c else 0
    if qa == 0:  # nothing observed in this chunk
        if scale != 1.0:
            P *= scale
        return X + 0.0
    agents = np.argsort(~observed, axis=-1, kind="stable")[:, :qa]  # observed agents first, in order
    idx = (agents[..., None] * m + np.arange(m)).reshape(c, qa * m)  # (c, q) observed state indices (padded)
    gather = ((np.arange(c) * M)[:, None] + idx).reshape(-1)
    if work is None:
        work = _Scratch(c, N, m)
    Ct = work.rows[: gather.size * M].reshape(gather.size, M)
    Ct = np.take(P.reshape(c * M, M), gather, axis=0, out=Ct).reshape(c, qa * m, M)  # H Sigma, (c, q, M)
    q_max = qa * m
    rows = (np.arange(c) * (q_max * M))[:, None, None] + (np.arange(q_max) * M)[None, :, None]
    S = np.take(Ct, rows + idx[:, None, :])  # H Sigma H^T, (c, q, q)
    pairs = idx[:, :, None] * M + idx[:, None, :]  # flat (row, column) indices of the observed block
    S += np.take(R, pairs)  # eq. (17); only the leading q_k x q_k block of filter k is used
    flat = (np.arange(c) * M)[:, None] + idx
    nu = np.take(z, flat) - np.take(x, flat)  # H (z - X), eq. (16)
    q = counts * m
    Li = np.zeros((c, q_max, q_max))  # L^{-1} of each filter, zero in the padding
    for k in range(c):
        if q[k]:
            Li[k, : q[k], : q[k]] = _cholesky_inverse(S[k, : q[k], : q[k]])
    V = _tiled_matmul(Li, Ct, work.V[: c * q_max * M].reshape(c, q_max, M), work.acc)  # L^{-1} H Sigma
    a = np.einsum("kij,kj->ki", Li, nu)  # L^{-1} nu
    for k in range(c):  # eq. (20): Sigma - V^T V (times scale), in place
        if q[k]:
            _subtract_gram(P[k], V[k, : q[k]], scale)
        elif scale != 1.0:
            P[k] *= scale
    x_post = x + np.einsum("kqm,kq->km", V, a)  # eq. (18): X + Sigma H^T S^{-1} nu = X + V^T L^{-1} nu
    return x_post.reshape(c, N, m)


def _column_blocks(A, N, n):
    """Views of the position and velocity columns of ``A (..., N*2n)`` (agent-major), each ``(..., N[, n])``.

    For ``n = 2`` the pairs of columns are viewed as complex numbers, so that an operation on a block runs one
    strided loop over the agents instead of one loop of length 2 per agent.
    """
    if n == 2:
        Ac = A.view(np.complex128).reshape(*A.shape[:-1], N, 2)
        return Ac[..., 0], Ac[..., 1]
    A5 = A.reshape(*A.shape[:-1], N, 2, n)
    return A5[..., 0, :], A5[..., 1, :]


def _pair_view(A, N, n):
    """``A (..., N*n)`` as ``(..., N)`` complex pairs (``n = 2``) or ``(..., N, n)`` reals."""
    if n == 2:
        return A.view(np.complex128)
    return A.reshape(*A.shape[:-1], N, n)


def _strip(M):
    """Rows per strip of a blocked transpose: a strip of ``M``-long rows spans a few pages (TLB friendly)."""
    return max(8, min(64, 4096 // M))


def _transpose_into(A, T):
    """``T = A^T`` for stacks of square matrices, in row strips."""
    M = A.shape[-1]
    b = _strip(M)
    for s in range(0, M, b):
        np.copyto(T[:, :, s:s + b], np.swapaxes(A[:, s:s + b, :], -1, -2))


def _symmetrize_sum(A, T):
    """``A <- A + A^T`` in place (exactly symmetric), through the work array `T` of `A`'s shape."""
    _transpose_into(A, T)
    A += T


class _Scratch:
    """Work arrays of one chunk of filters, owned by one :class:`FlockingEKF` and kept between its calls.

    Fresh large temporaries are expensive: the allocator returns freed memory to the system and the next
    first touch page-faults, so the kernels write into these instead.
    """

    def __init__(self, c, N, m):
        n, M = m // 2, N * m
        self.key = (c, N, m)
        self.G = np.empty((c, N, n, N, m))
        self.Y = np.empty((c, N * n, M))
        self.Z = np.empty((c, N * n, N * n))
        self.T = np.empty((c, M, M))
        self.half = np.empty(c * M * M // 2)
        self.rows = np.empty(c * M * M)
        self.V = np.empty(c * M * M)
        self.acc = np.empty(c * M * M)

    def buffer(self, like):
        """A contiguous temporary of the shape and type of `like` (at most half a chunk of covariances)."""
        size = like.size * like.itemsize // 8
        return self.half[:size].view(like.dtype).reshape(like.shape)


def _block_diagonal(Q, N, m):
    """The ``(N, m, m)`` diagonal blocks of `Q` if it is block diagonal (e.g. ``I_N kron Q``), else ``None``."""
    Q6 = Q.reshape(N, m, N, m)
    ar = np.arange(N)
    blocks = Q6[ar, :, ar, :].copy()
    off = Q6.copy()
    off[ar, :, ar, :] = 0.0
    return blocks if not np.any(off) else None


def _add_noise(S, Q, Qblocks, N, m, scale=1.0):
    """``S += scale Q`` for a chunk ``(c, M, M)``; only the diagonal blocks when `Q` is block diagonal."""
    if Qblocks is None:
        S += Q if scale == 1.0 else scale * Q
    else:
        s0, s1, s2 = S.strides
        blocks = np.lib.stride_tricks.as_strided(S, (S.shape[0], N, m, m), (s0, m * (s1 + s2), s1, s2))
        blocks += Qblocks if scale == 1.0 else scale * Qblocks


def _predict_half(X, Ph, model, out, work):
    """Eqs. (38), (40) for a chunk of filters from ``Ph = Sigma / 2`` (overwritten), using the rank of ``F - I kron A``.

    ``F = A' + B' G`` with ``A' = I kron A``, ``B' = I kron B`` (the double integrator) and the control
    Jacobian ``G = dU/dX`` (``nN x 2nN``, from :func:`mascore._flocking_core.control_and_jacobian`, scaled
    by ``dt``). With ``Y = G Sigma`` and ``Z = Y G^T`` (``M^3`` and at most ``M^3 / 2`` flops for ``M = 2nN``:
    ``Z`` is symmetric and only its tiles on and above the diagonal are computed),

        F Sigma F^T = X + X^T,   X = [A' Sigma/2 + B' (Y + Z C^T / 2)] A'^T,   C = A'^{-1} B',

    (``X`` carries half of ``A' Sigma A'^T`` and of ``B' Z B'^T`` and all of ``B' Y A'^T``). Every product by
    ``A'``, ``B'`` or ``C`` is a scaled addition of contiguous rows or of column blocks; the one transpose
    makes the result exactly symmetric (rounding would otherwise accumulate over long runs).

    Returns
    -------
    U : (c, N, n) every agent's control from each filter's estimate
    X_next : (c, N, m)
    out : (c, M, M) the predicted covariances ``F Sigma F^T + Q`` (may be `Ph` itself)
    """
    c, N, m = X.shape
    n, M, nN = m // 2, N * m, N * m // 2
    dt = model.dt
    U, G = _core.control_and_jacobian(X, model.gains, out=work.G[:c], scale=dt)  # eq. (39), and dt dU/dX
    X_next = _core.propagate(X, U, dt)  # eq. (40)
    G = G.reshape(c, nN, M)
    Y = _tiled_matmul(G, Ph, work.Y[:c], work.acc)  # dt G Sigma / 2
    Z = _tiled_matmul(Y, np.swapaxes(G, -1, -2), work.Z[:c], work.acc, symmetric=True)  # dt^2 G Sigma G^T / 2
    # Y <- Y + dt Z C^T / 2 (positions: -dt^2/2 Z dt / 2, velocities: dt Z dt / 2), with Z = G Sigma G^T
    Yp, Yv = _column_blocks(Y, N, n)
    Zc = _pair_view(Z, N, n)
    tz = work.buffer(Zc)
    np.multiply(Zc, -0.25 * dt, out=tz)
    Yp += tz
    np.multiply(Zc, 0.5, out=tz)
    Yv += tz
    # rows: W = A' Sigma/2 + B' (2 Y / dt): positions p + dt (v + y), velocities v + 2 y
    P4 = Ph.reshape(c, N, 2, n * M)
    Y3 = Y.reshape(c, N, n * M)
    t = work.buffer(Y3)
    np.add(P4[:, :, 1], Y3, out=t)
    np.add(t, Y3, out=P4[:, :, 1])
    t *= dt
    P4[:, :, 0] += t
    # columns: X = W A'^T (position columns + dt velocity columns)
    Wp, Wv = _column_blocks(Ph, N, n)
    tc = work.buffer(Wv)
    np.multiply(Wv, dt, out=tc)
    Wp += tc
    _add_noise(Ph, model.Q_team, model.Q_blocks, N, m, 0.5)  # eq. (40): Q / 2 in X, Q in X + X^T
    if out is not Ph and not np.shares_memory(out, Ph):
        np.copyto(out, Ph)
    _symmetrize_sum(out, work.T[:c])  # X + X^T = F Sigma F^T + Q, exactly symmetric
    return U, X_next, out
