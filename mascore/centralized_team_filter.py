"""The centralized Kalman filter over all agents' measurements: the reference of the team filters.

One filter sees every agent's measurements of the team (Song et al. 2023, eq. (3)) and knows
the inputs the agents applied: its covariance is a lower bound of every agent's in
:mod:`mascore.distributed_kf`. It runs in information form: each observer's measurement
information ``H_i^T (H_i R H_i^T)^{-1} H_i`` is formed on the ``q_i`` entries it observes (a
``q_i x q_i`` inverse, not an ``M_r x M_r`` one), and when the task separates into independent
agents (:attr:`CentralizedTeamFilter.separable`) the filter is N small filters.
:class:`CentralizedTeamFilter` is the fast path (checked once, then stepped);
:func:`centralized_predict` and :func:`centralized_update` check every argument on every call.
Shapes: estimates ``(runs, N, m)``, reduced covariance ``(batch, M_r, M_r)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._masked_gain import observed_indices
from ._team_kernels import (
    check_covariances,
    check_mask,
    check_measurements,
    check_model,
    finite_state,
    mask_vec,
    team_output_matrix,
)
from ._validation import (
    as_matrix,
    check_covariance,
    check_positive_int,
    finite_result,
    frozen_copy,
    state_view,
    symmetric_part,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .estimation import Message, MethodSpec
from .own_state import CentralizedOutputFilter
from .team_model import TeamFilterModel, reduce_covariance, team_filter_model

__all__ = [
    "CentralizedTeamFilter",
    "centralized_predict",
    "centralized_update",
]


class CentralizedTeamFilter:
    """The centralized Kalman filter over all agents' measurements, applied inputs known (the reference).

    Holds the team estimate and its reduced covariance; :meth:`predict` and
    :meth:`update` run :func:`centralized_predict` and :func:`centralized_update`
    without re-checking the state this filter produced (the model, `B` and `P0` are
    checked here, once). Filters share nothing, so independent filters may run in different
    threads; one filter object is not for concurrent use (its state changes at every step).

    **Any linear sensing.** A model with an output matrix (``z_ij = C_j x_j + nu_ij``,
    :func:`~mascore.team_model.team_filter_model` with ``C``) is filtered with the same outputs as
    the agents' filters, so the two compare on the same data: agent j's measurement information
    is ``c_j C_j^T R_jj^{-1} C_j`` on the separable centre, ``H^T (sum_i W_i) H`` with
    ``H = blockdiag(C_j)`` otherwise.

    **The separable centre.** When one observer's noise is independent across the agents it
    measures (``R`` block-diagonal over agents, e.g. ``I_N ⊗ R_j``) the information of agent j's
    measurements is ``c_j R_jj^{-1}``, with ``c_j`` the number of agents that measure j: the
    inverses ``R_jj^{-1}`` are computed here, once. If `P0` is block-diagonal over agents too, the
    prediction keeps it so (the inputs are known: the agents' errors evolve apart), and the filter
    is N filters of ``m_r`` states, ``O(N m_r^3)`` per step instead of ``O((N m_r)^3)``
    (:attr:`separable`; the same numbers to rounding). Otherwise it is one information filter of the
    team whose observers' information is formed on their observed entries:
    ``O(N q^3 + (N m_r)^3)`` per step, with q the most entries an agent observes.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
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
    >>> from mascore import centralized_team_filter, team_model
    >>> agent = agents.double_integrator(1, 0.1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
    ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> central = centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
    >>> central.predict(np.zeros((1, 3, 1)))
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), graphs.path_graph(3), np.eye(2))
    >>> central.update(Z, mask[0])
    >>> central.x_hat.shape, central.P.shape
    ((1, 3, 2), (1, 6, 6))
    """

    def __init__(self, model: TeamFilterModel, B: ArrayLike, x_hat0: ArrayLike, P0: ArrayLike,
                 batch: int = 1) -> None:
        model = check_model(model)
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
        inverses = _agent_noise_inverses(model)
        blocks = None if inverses is None else _agent_blocks(P, N, model.m_r)
        self._model, self._B, self._x = model, frozen_copy(B), x
        self._H = None if model.full_state else team_output_matrix(model)
        self._Rinv = None if blocks is None else frozen_copy(inverses)  # (N, m_r, m_r): R_jj^{-1}, once
        self._CtRinv = None  # (N, m_r, p_r): C_j^T R_jj^{-1} of partial sensing, once
        if blocks is not None and not model.full_state:
            CtRinv = np.swapaxes(model.C_r, -1, -2) @ inverses
            self._CtRinv, self._Rinv = frozen_copy(CtRinv), frozen_copy(CtRinv @ model.C_r)
        P = P if blocks is None else blocks
        self._P = np.broadcast_to(P, (batch, *P.shape)).copy()

    @property
    def model(self) -> TeamFilterModel:
        """The team model."""
        return self._model

    @property
    def separable(self) -> bool:
        """Whether the filter runs as N separate filters of ``m_r`` states (see the class notes).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, rendezvous
        >>> from mascore import centralized_team_filter, team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2)).separable
        True
        """
        return self._Rinv is not None

    @property
    def x_hat(self) -> np.ndarray:
        """Team estimates ``(runs, N, m)`` (a copy; :meth:`view` gives the filter's own array)."""
        return self._x.copy()

    @property
    def P(self) -> np.ndarray:
        """Reduced covariance ``(batch, M_r, M_r)`` (a copy; block-diagonal when :attr:`separable`)."""
        return _block_diagonal(self._P) if self.separable else self._P.copy()

    def view(self, name: str) -> np.ndarray:
        """The filter's own state array `name`, read-only and not copied (the fast read in a loop).

        Parameters
        ----------
        name : {"x_hat", "P", "P_blocks"}
            The state, as the property of that name; ``"P_blocks"``: the N diagonal blocks
            ``(batch, N, m_r, m_r)`` a :attr:`separable` filter holds (its own array; for ``"P"`` it
            assembles them, a new read-only array).

        Returns
        -------
        ndarray
            A read-only view, replaced or overwritten by the next step (copy it to keep it).
            The memory is the filter's own: the flag only guards against a slip (a caller who sets it
            writeable again writes into the filter's state); to change values, take the property (a copy).

        Raises
        ------
        ValueError
            An unknown name, or ``"P_blocks"`` of a filter that is not separable.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, rendezvous
        >>> from mascore import centralized_team_filter, team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> central.view("P").shape, central.view("P").flags.writeable, central.view("P_blocks").shape
        ((1, 6, 6), False, (1, 3, 2, 2))
        """
        if name == "P_blocks" and not self.separable:
            raise ValueError("name 'P_blocks' needs a separable filter (R and P0 block-diagonal over agents); "
                             "use 'P'")
        if name == "P" and self.separable:
            P = _block_diagonal(self._P)
            P.flags.writeable = False
            return P
        return state_view(self, name, {"x_hat": "_x", "P": "_P", "P_blocks": "_P"})

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
        >>> from mascore import centralized_team_filter, team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> central.predict(np.ones((1, 3, 1)))                    # p = dt^2 / 2, v = dt
        >>> central.x_hat[0, 0]
        array([0.005, 0.1  ])
        """
        model, B = self._model, self._B
        Ut = _float_array(U, "U")
        if Ut.shape != (self._x.shape[0], model.n_agents, B.shape[1]):
            raise ValueError(f"Incompatible dimensions of U; expected ({self._x.shape[0]}, {model.n_agents}, "
                             f"{B.shape[1]}) but found {Ut.shape}")
        if self.separable:
            self._x, self._P = _separable_predict(model, self._x, self._P, Ut, B)
        else:
            self._x, self._P = _centralized_predict(model, self._x, self._P, Ut, B)
        if not np.isfinite(self._x).all():
            _finite(Ut, "U")
        finite_state("centralized prediction", self._x, self._P)

    def update(self, Z: ArrayLike, mask: ArrayLike) -> None:
        """Update with every agent's measurements (information form).

        Parameters
        ----------
        Z : (runs, N, N, p) array_like
            Every agent's measurements;
            ``p = m`` (full states) unless the model has an output matrix ``C``
            (``z_ij = C_j x_j + nu_ij``).
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
        >>> from mascore import centralized_team_filter, team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), graphs.path_graph(3), np.eye(2))
        >>> central.update(Z, mask[0])
        >>> bool(np.trace(central.P[0]) < 6.0)
        True
        """
        model = self._model
        N, p = model.n_agents, model.p
        Zt = _float_array(Z, "Z")
        if Zt.shape != (self._x.shape[0], N, N, p):
            raise ValueError(f"Incompatible dimensions of Z; expected ({self._x.shape[0]}, {N}, {N}, {p}) "
                             f"but found {Zt.shape}")
        S = check_mask(mask, N)
        if S.shape[0] not in (1, self._x.shape[0]) or self._P.shape[0] not in (1, S.shape[0], self._x.shape[0]):
            raise ValueError(f"mask has batch {S.shape[0]} but there are {self._x.shape[0]} runs and "
                             f"{self._P.shape[0]} covariances")
        if self.separable and self._CtRinv is not None:
            self._x, self._P = _separable_output_update(model, self._Rinv, self._CtRinv, self._x, self._P, Zt, S)
        elif self.separable:
            self._x, self._P = _separable_update(model, self._Rinv, self._x, self._P, Zt, S)
        elif self._H is not None:
            self._x, self._P = _output_update(model, self._H, self._x, self._P, Zt, S)
        else:
            self._x, self._P = _centralized_update(model, self._x, self._P, Zt, S)
        if not np.isfinite(self._x).all():
            _finite(Zt, "Z")
        finite_state("centralized update", self._x, self._P)


    # ------------------------------------------------------------------ the centre (the estimator protocol)

    def agent_inputs(self, Z: ArrayLike, mask: ArrayLike, U: ArrayLike, i: int) -> tuple[dict, tuple]:
        """The centre's data of one step: the team's measurements and the inputs applied (it is the busiest node).

        Parameters
        ----------
        Z : (runs, N, N, p) array_like
            Every agent's measurements;
            ``p = m`` (full states) unless the model has an output matrix ``C``
            (``z_ij = C_j x_j + nu_ij``).
        mask : (N, N) or (batch, N, N) array_like of bool
            The sensing mask.
        U : (runs, N, p) array_like
            The inputs applied at the step.
        i : int
            Unused: the centre's step is the same whichever agent asks.

        Returns
        -------
        own : dict
            ``Z``, ``mask`` and ``U`` (copies).
        messages : tuple
            Empty: the measurements sent to the centre are part of its data.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, centralized_team_filter, graphs, rendezvous, sensing, team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), graphs.path_graph(3), np.eye(2))
        >>> own, messages = central.agent_inputs(Z, mask[0], np.zeros((1, 3, 1)), 0)
        >>> sorted(own), messages
        (['U', 'Z', 'mask'], ())
        """
        return {"Z": _finite(np.array(_float_array(Z, "Z")), "Z"), "mask": np.array(mask),
                "U": _finite(np.array(_float_array(U, "U")), "U")}, ()

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """The centre's step: :meth:`update` with the team's measurements, then :meth:`predict` (advances this filter).

        Parameters
        ----------
        i : int
            Unused (the centre).
        own, messages
            From :meth:`agent_inputs`.

        Returns
        -------
        x_hat, P : ndarray
            The team estimates ``(runs, N, m)`` and the filter's own covariance after the step
            (read-only views, as :meth:`view`): the reduced ``(batch, M_r, M_r)``, or the N blocks
            ``(batch, N, m_r, m_r)`` of a :attr:`separable` filter.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, centralized_team_filter, graphs, rendezvous, sensing, team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), graphs.path_graph(3), np.eye(2))
        >>> x, P = central.agent_step(0, *central.agent_inputs(Z, mask[0], np.zeros((1, 3, 1)), 0))
        >>> x.shape, P.shape                                     # separable: 3 filters of one agent's axis
        ((1, 3, 2), (1, 3, 2, 2))
        """
        self.update(own["Z"], own["mask"])
        self.predict(own["U"])
        return self.view("x_hat"), self.view("P_blocks" if self.separable else "P")

    def messages(self, i: int = 0, n_measured: int = 1) -> tuple[Message, ...]:
        """What an agent sends per step, its measurements to the centre, and receives: the estimates it uses.

        Parameters
        ----------
        i : int
            The agent (the same for all).
        n_measured : int
            How many agents it measures (itself and its neighbours: degree + 1).

        Returns
        -------
        tuple of Message
            Its ``n_measured`` measurements of ``m`` numbers each, up; the centre's estimates of the same
            agents (its own and its neighbours', what its control uses), down.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, centralized_team_filter, rendezvous, team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> central = centralized_team_filter.CentralizedTeamFilter(model, agent.B, np.zeros((1, 6)), np.eye(2))
        >>> [m.floats for m in central.messages(0, n_measured=3)]
        [6, 6]
        """
        floats = check_positive_int(n_measured, "n_measured") * self._model.p
        return (Message("its measurements z_ij of itself and its neighbours, to the centre", floats),
                Message("the centre's estimates of itself and its neighbours, back to it", floats))


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
        The team model (:func:`~mascore.team_model.team_filter_model`).
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
    >>> from mascore import centralized_team_filter, team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> x, P = centralized_team_filter.centralized_predict(model, np.zeros((1, 3, 2)), np.eye(6)[None],
    ...                                                    np.zeros((1, 3, 1)), agent.B)
    >>> x.shape, P.shape
    ((1, 3, 2), (1, 6, 6))
    """
    model = check_model(model)
    N, m, Mr = model.n_agents, model.m, model.M_r
    x = _finite(_float_array(x, "x"), "x")
    if x.ndim != 3 or x.shape[1:] != (N, m):
        raise ValueError(f"Incompatible dimensions of x; expected (runs, {N}, {m}) but found {x.shape}")
    P = check_covariances(P, "P", (None, Mr, Mr), kron=model.kron)
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

    ``P^{-1} = (P^-)^{-1} + sum_i H_i^T (H_i R H_i^T)^{-1} H_i``,
    ``x = x^- + P sum_i H_i^T (H_i R H_i^T)^{-1} (z_i - H_i x^-)``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    x_pred : (runs, N, m) array_like
        Predicted team estimates.
    P_pred : (batch, M_r, M_r) array_like
        Reduced predicted covariance, positive definite.
    Z : (runs, N, N, p) array_like
        Every agent's measurements;
        ``p = m`` (full states) unless the model has an output matrix ``C``
        (``z_ij = C_j x_j + nu_ij``).
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
    >>> from mascore import centralized_team_filter, team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> x, P = centralized_team_filter.centralized_update(model, np.zeros((1, 3, 2)), np.eye(6)[None], Z, mask)
    >>> bool(np.trace(P[0]) < 6.0)
    True
    """
    model = check_model(model)
    N, m, Mr = model.n_agents, model.m, model.M_r
    x_pred = _finite(_float_array(x_pred, "x_pred"), "x_pred")
    if x_pred.ndim != 3 or x_pred.shape[1:] != (N, m):
        raise ValueError(f"Incompatible dimensions of x_pred; expected (runs, {N}, {m}) but found {x_pred.shape}")
    P_pred = check_covariances(P_pred, "P_pred", (None, Mr, Mr), definite=True, kron=model.kron)
    Zt = check_measurements(model, Z, "Z")
    S = check_mask(mask, N)
    if Zt.shape[0] != x_pred.shape[0]:
        raise ValueError(f"Z has {Zt.shape[0]} runs but x_pred has {x_pred.shape[0]}")
    for name, b in (("mask", S.shape[0]), ("Z", Zt.shape[0])):
        if P_pred.shape[0] not in (1, b) and b != 1:
            raise ValueError(f"{name} has batch {b} but P_pred has {P_pred.shape[0]}")
    if not model.full_state:
        return finite_result("centralized update",
                             *_output_update(model, team_output_matrix(model), x_pred, P_pred, Zt, S))
    return finite_result("centralized update", *_centralized_update(model, x_pred, P_pred, Zt, S))


def _output_update(model, H, x_pred, P_pred, Z, S):
    """:func:`centralized_update` of partial sensing without checks: ``H_i = D_i H``, ``H = blockdiag(C_r_j)``.

    ``P = ((P^-)^{-1} + H^T (sum_i W_i) H)^{-1}``, ``x = x^- + P H^T sum_i W_i (z_i - H x^-)`` with
    ``W_i = D (D R D + I - D)^{-1} D`` the information of observer i's sensed outputs.
    """
    N, m, k, Mr = model.n_agents, model.m, model.kron, model.M_r
    runs = x_pred.shape[0]
    d = np.repeat(S, model.C_r.shape[1], axis=-1).astype(float)  # (batch, N, N p_r)
    pair = d[..., :, None] * d[..., None, :]
    Wy = np.linalg.inv(pair * model.R_r + np.eye(H.shape[0]) * (1.0 - d[..., None])) * pair
    innov = Z.reshape(runs, N, H.shape[0], k) - (H @ x_pred.reshape(runs, Mr, k))[:, None]
    total = H.T @ (Wy @ innov).sum(axis=1)  # (runs, Mr, k)
    P = symmetric_part(np.linalg.inv(np.linalg.inv(P_pred) + H.T @ Wy.sum(axis=1) @ H))
    return x_pred + (P @ total).reshape(runs, N, m), P


def _centralized_update(model, x_pred, P_pred, Z, S):
    """:func:`centralized_update` without checks (`S` a (batch, N, N) bool mask): information form.

    ``P = ((P^-)^{-1} + sum_i W_i)^{-1}``, ``x = x^- + P sum_i W_i (z_i - x^-)`` with each observer's
    ``W_i = H_i^T (H_i R H_i^T)^{-1} H_i`` formed on its ``q`` observed reduced entries only.
    """
    N, m, k, Mr = model.n_agents, model.m, model.kron, model.M_r
    idx, Wq, W = _measurement_information(model, S)  # (b, N, q), (b, N, q, q), (b, Mr, Mr)
    runs = x_pred.shape[0]
    innov = (Z - x_pred[:, None]).reshape(runs, N, Mr, k)
    gathered = np.take_along_axis(innov, idx[..., None], axis=2)  # (runs, N, q, k): what each agent observes
    rows = np.broadcast_to(idx, (runs, *idx.shape[1:]))
    total = np.zeros((runs, Mr, k))
    np.add.at(total, (np.arange(runs)[:, None, None], rows), Wq @ gathered)  # sum_i W_i (z_i - x^-)
    P = symmetric_part(np.linalg.inv(np.linalg.inv(P_pred) + W))
    return x_pred + (P @ total).reshape(runs, N, m), P


def _measurement_information(model, S):
    """Each observer's measurement information on the reduced entries it observes, and their sum.

    Returns
    -------
    idx : (batch, N, q) ndarray of int
        Observer i's observed reduced entries (padded, :func:`mascore._masked_gain.observed_indices`).
    Wq : (batch, N, q, q) ndarray
        ``(H_i R H_i^T)^{-1}`` on them (zero on the padding).
    W : (batch, M_r, M_r) ndarray
        ``sum_i H_i^T (H_i R H_i^T)^{-1} H_i``.
    """
    idx, valid = observed_indices(mask_vec(model, S))
    pair = valid[..., :, None] * valid[..., None, :]
    q = idx.shape[-1]
    Rq = model.R_r[idx[..., :, None], idx[..., None, :]] * pair + np.eye(q) * (1.0 - valid[..., None])
    Wq = np.linalg.inv(Rq) * pair
    W = np.zeros((S.shape[0], model.M_r, model.M_r))
    np.add.at(W, (np.arange(S.shape[0])[:, None, None, None], idx[..., :, None], idx[..., None, :]), Wq)
    return idx, Wq, W


def _agent_noise_inverses(model) -> np.ndarray | None:
    """``R_jj^{-1}`` per measured agent ``(N, p_r, p_r)`` if one observer's noise is independent across agents, else None.

    ``p_r = m_r`` for full-state sensing.
    """
    N = model.n_agents
    mr = model.m_r if model.full_state else model.C_r.shape[1]
    R = model.R_r.reshape(N, mr, N, mr)
    off = R.copy()
    off[np.arange(N), :, np.arange(N), :] = 0.0
    return None if np.any(off) else np.linalg.inv(R[np.arange(N), :, np.arange(N), :])


def _agent_blocks(P: np.ndarray, N: int, mr: int) -> np.ndarray | None:
    """The diagonal blocks ``(N, m_r, m_r)`` of a reduced team covariance that is block-diagonal over agents, else None."""
    P4 = P.reshape(N, mr, N, mr)
    blocks = P4[np.arange(N), :, np.arange(N), :]
    off = P4.copy()
    off[np.arange(N), :, np.arange(N), :] = 0.0
    return None if np.any(off) else np.array(blocks)


def _block_diagonal(blocks: np.ndarray) -> np.ndarray:
    """``(batch, N, m_r, m_r)`` blocks -> the ``(batch, N m_r, N m_r)`` block-diagonal matrices."""
    b, N, mr, _ = blocks.shape
    out = np.zeros((b, N, mr, N, mr))
    out[:, np.arange(N), :, np.arange(N), :] = np.moveaxis(blocks, 1, 0)
    return out.reshape(b, N * mr, N * mr)


def _separable_predict(model, x, P, U, B):
    """The prediction of N separate filters: ``P_j = A_r P_j A_r^T + Q_r`` per agent ``(batch, N, m_r, m_r)``."""
    return x @ model.A.T + U @ B.T, symmetric_part(model.A_r @ P @ model.A_r.T + model.Q_r)


def _separable_update(model, Rinv, x_pred, P, Z, S):
    """The update of N separate filters in information form: agent j's ``c_j`` measurements, ``c_j R_jj^{-1}``.

    `P` is ``(batch, N, m_r, m_r)``, `Rinv` ``(N, m_r, m_r)``; ``c_j`` counts the observers of j in `S`.
    """
    N, m, k, mr = model.n_agents, model.m, model.kron, model.m_r
    runs = x_pred.shape[0]
    count = S.sum(axis=-2).astype(float)  # (b, N): how many agents measure agent j
    P_new = symmetric_part(np.linalg.inv(np.linalg.inv(P) + count[..., None, None] * Rinv))
    measured = (S[..., None] * Z).sum(axis=1)  # (runs, N, m): the sum of the measurements of each agent
    innov = (measured - count[..., None] * x_pred).reshape(runs, N, mr, k)
    return x_pred + (P_new @ (Rinv @ innov)).reshape(runs, N, m), P_new


def _separable_output_update(model, info, CtRinv, x_pred, P, Z, S):
    """:func:`_separable_update` of partial sensing: agent j's ``c_j`` outputs, information ``c_j C_j^T R_jj^{-1} C_j``.

    `info` is ``C_j^T R_jj^{-1} C_j`` ``(N, m_r, m_r)``, `CtRinv` ``C_j^T R_jj^{-1}`` ``(N, m_r, p_r)``.
    """
    N, m, k, mr = model.n_agents, model.m, model.kron, model.m_r
    runs, pr = x_pred.shape[0], CtRinv.shape[-1]
    count = S.sum(axis=-2).astype(float)  # (b, N): how many agents measure agent j
    P_new = symmetric_part(np.linalg.inv(np.linalg.inv(P) + count[..., None, None] * info))
    measured = (S[..., None] * Z).sum(axis=1).reshape(runs, N, pr, k)  # the sum of agent j's outputs
    x_r = x_pred.reshape(runs, N, mr, k)
    innov = CtRinv @ measured - count[..., None, None] * (info @ x_r)  # C_j^T R^{-1} (sum_i z_ij - c_j C_j x_j)
    return x_pred + (P_new @ innov).reshape(runs, N, m), P_new


#: The centralized filter of the team task (mascore.compare's own-state rendezvous, mascore.agent_cost): the bound.
METHODS = (
    MethodSpec("centralized", ("team",),
               lambda team, x_hat0: _centralized_filter(team, x_hat0),
               lambda n, q, d, N: (float((n + q) * (d + 1)), _separable_centre_flops(n, d, N)),
               {"team": ("O(N n^3) at the centre: N separate filters (the own state separates)", "O(N n^2)")},
               lambda n, q, d, N: float(N * (n**2 + n)), whole_filter=True, position=0),
)


def _centralized_filter(team, x_hat0: np.ndarray) -> CentralizedTeamFilter | CentralizedOutputFilter:
    """``build(team, x_hat0)``: the centre's filter of the team task (positions only: its output filter)."""
    if team.sensing == "position":
        return CentralizedOutputFilter(team.A, team.B, team.Q_filter, team.C, team.R[0, 0], team.N)
    return CentralizedTeamFilter(team_filter_model(team.A, team.B, team.K, team.Q_filter, team.R, team.N), team.B,
                                 x_hat0, team.P0)


def _separable_centre_flops(n: int, d: int, N: int) -> float:
    """The separable centre's flops per step: N filters of n states, agent j's d + 1 measurements each.

    Per filter a prediction ``4 n^3 + 2 n^2`` and an information update ``26/3 n^3 + 8 n^2``
    (:func:`mascore.fusion_cost.filter_cost`'s counts), plus the sum of its ``d + 1`` measurements.
    """
    return float(N * (4 * n**3 + 2 * n**2 + 26 / 3 * n**3 + 8 * n**2 + 2 * (d + 1) * n))
