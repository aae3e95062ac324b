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
while its covariances are in cache, with the filter's work arrays reused between calls (these
kernels: ``mascore._ekf_kernels``).

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

from . import _ekf_kernels as kernels
from . import _flocking_core as _core
from ._flocking_core import FlockingGains
from ._flocking_core import check_dt as _check_dt
from ._flocking_core import check_gains as _check_gains
from ._flocking_core import check_range as _check_range
from ._flocking_core import check_steps as _check_steps
from ._flocking_core import check_team as _check_team
from ._flocking_core import float_array as _float_array
from ._progress import progress_bar
from ._sensing_kernels import masked_measurement
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
from .sensing import team_noise_covariance

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
            Qb = kernels.block_diagonal(Q, N, m)
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
        self._chunks = kernels.chunks(int(np.prod(batch, dtype=np.int64)), M)
        self._work = kernels.Scratch(self._chunks[0].stop if self._chunks else 1, N, m)

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
            The memory is the filter's own: the flag only guards against a slip (a caller who sets it
            writeable again writes into the filter's state); to change values, take the property (a copy).

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
                X_post[ch] = kernels.update_rows(X[ch], Pc, Z[ch], obs[ch], model.R, 0.5, self._work)  # Sigma_post / 2
                kernels.symmetrize_sum(Pc, self._work.T[: Pc.shape[0]])  # (Sigma_post + Sigma_post^T) / 2
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
                U[ch], X_next[ch], _ = kernels.predict_half(X[ch], Ph, model, Ph, self._work)
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
                X_post[ch] = kernels.update_rows(X[ch], Ph, Z[ch], obs[ch], model.R, scale, work)  # eqs. (16)-(20)
                diag[ch] = np.diagonal(Ph, axis1=-2, axis2=-1)
                if post is not None:
                    np.multiply(Ph, 1.0 / scale, out=post[ch])
                if predict:
                    diag[ch] *= 2.0
                    U_all, X_next[ch], _ = kernels.predict_half(X_post[ch], Ph, model, Ph, work)  # eqs. (38)-(40)
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

    A run's output: its arrays are the caller's, writeable and shared with no model or filter.

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
    if not isinstance(record_nees, (bool, np.bool_)):
        raise TypeError(f"record_nees must be True or False; got {type(record_nees).__name__} {record_nees!r}")
    # the NEES inverts the observer's covariance, which keeps the prior's where nothing is measured
    Sigma0 = check_covariance(_float_array(Sigma0, "Sigma0"), "Sigma0" + (" (record_nees inverts it)" if record_nees
                                                                          else ""), size=M, definite=bool(record_nees))
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
    if not isinstance(return_estimates, (bool, np.bool_)):  # record_nees is checked with Sigma0, which it reads
        raise TypeError(f"return_estimates must be True or False; got {type(return_estimates).__name__} "
                        f"{return_estimates!r}")
    Lq = _core.noise_factor(Q, "Q", m)
    Lf = Lq if Q_filter is None else _core.noise_factor(Q_filter, "Q_filter", m)
    # values a run would flag as diverged at its first step, refused by name before it starts
    for name, values, what in (("X0", X, "entries"), ("X_hat0", X_hat, "entries"),
                               ("Sigma0", np.sqrt(np.abs(np.diagonal(Sigma0, axis1=-2, axis2=-1))), "standard deviations"),
                               ("Q", np.sqrt(np.diag(Lq @ Lq.T)), "standard deviations per step"),
                               ("Q_filter", np.sqrt(np.diag(Lf @ Lf.T)), "standard deviations per step")):
        _core.check_within_limit(values, name, what)
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
    closed = np.eye(N, dtype=bool)  # every agent measures itself
    for k in progress_bar(range(n_steps + 1), enabled=progress, desc="EKF flocking", leave=False):
        A_k = proximity_graph(X[..., :n], sensing_range).astype(bool)
        z, observed = masked_measurement(rng, X, A_k | closed, model.R)  # eqs. (2)-(3), closed neighbourhoods
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
    _core.check_within_limit(np.sqrt(q), "q_values", "standard deviations per step")
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
        raise ValueError(f"Incompatible dimensions of {name}; expected (..., {M}, {M}) (from {of}'s team of "
                         f"{M} states: fix whichever of the two is wrong) but found {S.shape}")
    _check_batch(S.shape[:-2], batch, name, of)
    flat = S.reshape(-1, M, M)
    chunks = kernels.chunks(flat.shape[0], M)  # chunk by chunk: no temporaries of the size of S
    scale = float(np.max([[flat[ch].max(), -flat[ch].min()] for ch in chunks], initial=0.0))  # max |S|
    if not np.isfinite(scale):
        raise ValueError(f"{name} contains NaN or infinite entries")
    tol = SYMMETRY_RTOL * max(1.0, scale)
    if chunks:
        T = np.empty((chunks[0].stop, M, M))
        diag = np.arange(M)
    for ch in chunks:
        blk, Tc = flat[ch], T[: ch.stop - ch.start]
        kernels.transpose_into(blk, Tc)
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
