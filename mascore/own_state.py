"""Filters of each agent's own state from the measurements its team takes of it.

N agents with the same linear dynamics ``x_i[k+1] = A x_i[k] + B u_i[k] + w_i[k]``; at a
step, agent j measures agent i (itself included) on each link that delivers,
``z_ji = H x_i + nu_ji``, ``nu_ji ~ N(0, R)`` independent. With the inputs known, the
team's filter splits into one filter per agent, and agent i's exact Kalman filter fuses
the measurements of x_i that reach it over one hop:

=====================================  ==========================================================
:class:`OwnStateForwardingFilter`      agent i: its prior and every delivered ``z_ji``, in
                                       information form (one covariance per agent and run)
:class:`CentralizedOutputFilter`       one Kalman filter of the team's states with every
                                       delivered output measurement ``z_ji = C x_i + nu_ji``
                                       (the bound: the centre's)
=====================================  ==========================================================

Shapes: estimates ``(R, N, n)`` (R runs), covariances ``(R, N, n, n)``, measurements
``Z[r, j, i] = z_ji`` of shape ``(R, N, N, m)``, delivered links ``S[r, j, i]`` (bool,
``(R or 1, N, N)``, the diagonal true: an agent measures itself).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._validation import (
    Frozen,
    agent_index,
    as_matrix,
    check_covariance,
    check_fits_in_memory,
    check_positive,
    check_positive_int,
    check_square,
    finite_result,
    float_array,
    frozen_copy,
    require_finite,
)
from .estimation import Message, MethodSpec, protocol_docs
from .fusion_cost import kalman_step_flops

__all__ = ["CentralizedOutputFilter", "OwnStateForwardingFilter"]


@protocol_docs
class OwnStateForwardingFilter(Frozen):
    """Measurement forwarding on the own states: agent i corrects with every delivered measurement of x_i.

    ``P_i+ = (P_i-^{-1} + c_i H^T R^{-1} H)^{-1}``, ``x_i+ = P_i+ (P_i-^{-1} x_i- + H^T R^{-1} sum_j z_ji)``,
    with ``c_i`` the number of delivered measurements of x_i (its own and its neighbours'); then
    ``x_i- = A x_i + B u_i``, ``P_i- = A P_i A^T + Q``. Each neighbour sends agent i its ``m``
    numbers ``z_ji`` per step. With full-state sensing (``H = I``) this one-hop filter *is* the
    centralized filter of the team.

    Parameters
    ----------
    A : (n, n) array_like
        One agent's dynamics.
    B : (n, k) array_like
        Its input matrix.
    Q : (n, n) array_like
        The process-noise covariance the filter assumes.
    H : (m, n) array_like
        The output each measurement sees.
    R : (m, m) array_like
        The covariance of one measurement's noise, positive definite.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.own_state import OwnStateForwardingFilter
    >>> f = OwnStateForwardingFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), np.eye(1))
    >>> S = np.ones((1, 2, 2), bool)                                # both measure both
    >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])            # z_ji = 1 for agent 0, 3 for agent 1
    >>> x, P = f.update(np.zeros((1, 2, 1)), np.ones((1, 2, 1, 1)), Z, S)
    >>> x[0, :, 0], P[0, :, 0, 0]                                   # prior 0 with information 1, two at 1 or 3
    (array([0.66666667, 2.        ]), array([0.33333333, 0.33333333]))
    """

    __slots__ = ("A", "B", "Q", "H", "R", "information", "to_state")

    def __init__(self, A: ArrayLike, B: ArrayLike, Q: ArrayLike, H: ArrayLike, R: ArrayLike) -> None:
        A = check_square(A, "A")
        n = A.shape[0]
        B, H = as_matrix(B, "B"), as_matrix(H, "H")
        if B.shape[0] != n or H.shape[1] != n:
            raise ValueError(f"B must have n = {n} rows and H n columns; got B {B.shape}, H {H.shape}")
        Q = check_covariance(Q, "Q", n)
        R = check_covariance(R, "R", H.shape[0], definite=True)
        Rinv = np.linalg.inv(R)
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused by name just below
            information = H.T @ Rinv @ H
        information = _finite_information(information, "H")
        self._set(A=frozen_copy(A), B=frozen_copy(B), Q=frozen_copy(Q), H=frozen_copy(H), R=frozen_copy(R),
                  information=frozen_copy(information), to_state=frozen_copy(Rinv.T @ H))

    def _args(self) -> tuple:
        return (self.A, self.B, self.Q, self.H, self.R)

    def update(self, x: np.ndarray, P: np.ndarray, Z: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Every agent's correction with the delivered measurements of its own state, batched over runs.

        Parameters
        ----------
        x : (R, N, n) ndarray
            Predicted estimates.
        P : (R, N, n, n) ndarray
            Their covariances.
        Z : (R, N, N, m) ndarray
            ``Z[r, j, i] = z_ji``, agent j's measurement of agent i.
        S : (R or 1, N, N) bool ndarray
            ``S[r, j, i]``: z_ji delivered.

        Returns
        -------
        x, P : ndarray
            The corrected estimates ``(R, N, n)`` and covariances ``(R, N, n, n)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.own_state import OwnStateForwardingFilter
        >>> f = OwnStateForwardingFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), np.eye(1))
        >>> x, P, S = np.zeros((1, 2, 1)), np.ones((1, 2, 1, 1)), np.ones((1, 2, 2), bool)
        >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])      # z_ji = 1 for agent 0, 3 for agent 1
        >>> f.update(x, P, Z, S)[0][0, :, 0]
        array([0.66666667, 2.        ])
        """
        x, P, Z, S = _step_inputs(self, x=x, P=P, Z=Z, S=S)
        St = np.swapaxes(np.broadcast_to(S, (Z.shape[0], *S.shape[1:])), -1, -2)  # St[r, i, j] = S[r, j, i]
        count = St.sum(-1).astype(float)                                        # (R, N)
        zsum = np.einsum("rij,rjid->rid", St, Z)                                 # sum_j z_ji
        prior_info = _inverse(P)
        P_new = np.linalg.inv(prior_info + count[..., None, None] * self.information)
        P_new = 0.5 * (P_new + np.swapaxes(P_new, -1, -2))
        rhs = np.einsum("...ij,...j->...i", prior_info, x) + zsum @ self.to_state
        return finite_result("own-state update", np.einsum("...ij,...j->...i", P_new, rhs), P_new,
                             inputs=((x, "x"), (P, "P"), (Z, "Z")))

    def predict(self, x: np.ndarray, P: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The prediction ``x_i <- A x_i + B u_i``, ``P_i <- A P_i A^T + Q`` of every agent and run.

        Parameters
        ----------
        x : (R, N, n) ndarray
            The estimates.
        P : (R, N, n, n) ndarray
            Their covariances.
        u : (R, N, k) ndarray
            The inputs applied.

        Returns
        -------
        x, P : ndarray
            The predictions, same shapes.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.own_state import OwnStateForwardingFilter
        >>> f = OwnStateForwardingFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), np.eye(1))
        >>> x, P, S = np.zeros((1, 2, 1)), np.ones((1, 2, 1, 1)), np.ones((1, 2, 2), bool)
        >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])      # z_ji = 1 for agent 0, 3 for agent 1
        >>> f.predict(x, P, np.ones((1, 2, 1)))[0][0, :, 0]
        array([1., 1.])
        """
        x, P, u = _step_inputs(self, x=x, P=P, u=u)
        return finite_result("own-state prediction", x @ self.A.T + u @ self.B.T, self.A @ P @ self.A.T + self.Q,
                             inputs=((x, "x"), (u, "u"), (P, "P")))

    def agent_inputs(self, x: np.ndarray, P: np.ndarray, Z: np.ndarray, S: np.ndarray, u: np.ndarray,
                     i: int) -> tuple[dict, tuple]:
        """Agent i's prior, own measurement and input, and the measurements of x_i its neighbours send it.

        Parameters
        ----------
        x : (N, n) ndarray
            The team's estimates before the step (one run).
        P : (N, n, n) ndarray
            Their covariances.
        Z : (N, N, m) ndarray
            The step's measurements, ``Z[j, i] = z_ji``.
        S : (N, N) bool ndarray
            The delivered links, ``S[j, i]``.
        u : (N, k) ndarray
            The inputs applied at the step.
        i : int
            The agent.

        Returns
        -------
        own : dict
            Its prior ``x``, ``P``, its input ``u`` and its own measurement ``z``.
        messages : tuple
            One round: the neighbours' delivered measurements ``z_ji`` of x_i, ``(c_i - 1, m)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.own_state import OwnStateForwardingFilter
        >>> f = OwnStateForwardingFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), np.eye(1))
        >>> x, P, S = np.zeros((1, 2, 1)), np.ones((1, 2, 1, 1)), np.ones((1, 2, 2), bool)
        >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])      # z_ji = 1 for agent 0, 3 for agent 1
        >>> own, messages = f.agent_inputs(x[0], P[0], Z[0], S[0], np.zeros((2, 1)), 1)
        >>> messages[0]                                            # agent 0's measurement of agent 1
        array([[3.]])
        """
        x, P, Z, S, u = _step_inputs(self, False, x=x, P=P, Z=Z, S=S, u=u)
        i = agent_index(i, x.shape[0])
        senders = np.flatnonzero(S[:, i])  # i and the neighbours whose z_ji reached it, ascending
        return ({"x": x[i].copy(), "P": P[i].copy(), "u": u[i].copy(), "z": Z[i, i].copy()},
                (Z[senders[senders != i], i].copy(),))

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        # correction with its own and the received measurements of x_i, then prediction: x_i (n,), P_i (n, n)
        received = messages[0]
        info = np.linalg.inv(own["P"])
        P = np.linalg.inv(info + (len(received) + 1) * self.information)
        P = 0.5 * (P + P.T)
        x = P @ (info @ own["x"] + self.to_state.T @ (own["z"] + received.sum(0)))
        return self.A @ x + self.B @ own["u"], self.A @ P @ self.A.T + self.Q

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        # to each neighbour, its measurement of that neighbour: m floats
        return (Message("measurement z_ij of each neighbour j", float(self.to_state.shape[0])),)


@protocol_docs
class CentralizedOutputFilter(Frozen):
    """One Kalman filter over the team state ``(N n,)`` with every delivered output measurement (information form).

    ``P^{-1} = P-^{-1} + H^T R^{-1} H`` with one row block ``[0 .. C .. 0]`` per delivered
    ``z_ji`` (block i), ``R = r I``; ``x = x- + P H^T R^{-1} (z - H x-)``; then
    ``x- = (I_N kron A) x + (I_N kron B) u``, ``P- = (I_N kron A) P (I_N kron A)^T + I_N kron Q``.
    The team covariance is ``(B, N n, N n)``: shared by the runs (B = 1) or one per run when
    links drop. Each agent sends its measurements to the centre.

    Parameters
    ----------
    A : (n, n) array_like
        One agent's dynamics.
    B : (n, k) array_like
        Its input matrix.
    Q : (n, n) array_like
        The process-noise covariance the filter assumes (the agents' noises independent).
    C : (p, n) array_like
        The output each measurement sees.
    r : float
        The variance of each output's noise (``R = r I_p``), > 0.
    n_agents : int
        N.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.own_state import CentralizedOutputFilter
    >>> f = CentralizedOutputFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), 1.0, 2)
    >>> S = np.ones((1, 2, 2), bool)
    >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])
    >>> x, P = f.update(np.zeros((1, 2, 1)), np.eye(2)[None], Z, S)
    >>> x[0, :, 0], np.diag(P[0])                          # as forwarding: the agents are independent
    (array([0.66666667, 2.        ]), array([0.33333333, 0.33333333]))
    """

    __slots__ = ("A", "B", "Q", "C", "r", "n_agents", "A_team", "Q_team", "information")

    def __init__(self, A: ArrayLike, B: ArrayLike, Q: ArrayLike, C: ArrayLike, r: float, n_agents: int) -> None:
        A = check_square(A, "A")
        n = A.shape[0]
        B, C = as_matrix(B, "B"), as_matrix(C, "C")
        if B.shape[0] != n or C.shape[1] != n:
            raise ValueError(f"B must have n = {n} rows and C n columns; got B {B.shape}, C {C.shape}")
        Q = check_covariance(Q, "Q", n)
        r = check_positive(r, "r")
        N = check_positive_int(n_agents, "n_agents")
        check_fits_in_memory(2 * 8.0 * (N * n) ** 2, "n_agents", f"the ({N * n}, {N * n}) team matrices")
        with np.errstate(over="ignore", invalid="ignore"):  # an overflow is refused by name in _set below
            information = C.T @ C / r
        self._set(A=frozen_copy(A), B=frozen_copy(B), Q=frozen_copy(Q), C=frozen_copy(C),
                  A_team=frozen_copy(np.kron(np.eye(N), A)), Q_team=frozen_copy(np.kron(np.eye(N), Q)),
                  information=frozen_copy(_finite_information(information, "C")), r=float(r), n_agents=N)

    def _args(self) -> tuple:
        return (self.A, self.B, self.Q, self.C, self.r, self.n_agents)

    def update(self, x: np.ndarray, P: np.ndarray, Z: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The centre's correction with every delivered measurement.

        Parameters
        ----------
        x : (R, N, n) ndarray
            The team's predicted states, per run.
        P : (B, N n, N n) ndarray
            The team covariance (B = 1: shared by the runs).
        Z : (R, N, N, p) ndarray
            ``Z[r, j, i] = z_ji``.
        S : (R or 1, N, N) bool ndarray
            ``S[r, j, i]``: z_ji delivered.

        Returns
        -------
        x, P : ndarray
            ``(R, N, n)``, and ``(B', N n, N n)`` with ``B'`` the runs of `S` (one covariance per run when links drop).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.own_state import CentralizedOutputFilter
        >>> f = CentralizedOutputFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), 1.0, 2)
        >>> x, P, S = np.zeros((1, 2, 1)), np.eye(2)[None], np.ones((1, 2, 2), bool)
        >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])
        >>> f.update(x, P, Z, S)[0][0, :, 0]
        array([0.66666667, 2.        ])
        """
        x, P, Z, S = _step_inputs(self, x=x, P=P, Z=Z, S=S)
        R_, N, n = x.shape
        count = S.sum(-2).astype(float)                                   # (B, N): measurements of x_j
        info = _inverse(P)
        if info.shape[0] != count.shape[0]:                               # links drop per run: one P per run
            info = np.broadcast_to(info, (count.shape[0], *info.shape[1:])).copy()
        diag = count[..., None, None] * self.information                  # (B, N, n, n)
        idx = np.arange(N)
        blocks = info.reshape(-1, N, n, N, n)
        blocks[:, idx, :, idx, :] += np.moveaxis(diag, 1, 0)              # H^T R^-1 H is block-diagonal
        P = np.linalg.inv(blocks.reshape(info.shape))
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        resid = np.where(S[..., None], Z - (x @ self.C.T)[:, None], 0.0)   # z_ji - C x_i, (R, N, N, p)
        rhs = resid.sum(1) @ self.C / self.r                              # H^T R^-1 (z - H x), (R, N, n)
        return finite_result("centralized update", x + (P @ rhs.reshape(R_, n * N, 1)).reshape(R_, N, n), P,
                             inputs=((x, "x"), (info, "P"), (Z, "Z")))

    def predict(self, x: np.ndarray, P: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The team's prediction.

        Parameters
        ----------
        x : (R, N, n) ndarray
            The states.
        P : (B, N n, N n) ndarray
            The team covariance.
        u : (R, N, k) ndarray
            The inputs applied.

        Returns
        -------
        x, P : ndarray
            The predictions, same shapes.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.own_state import CentralizedOutputFilter
        >>> f = CentralizedOutputFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), 1.0, 2)
        >>> x, P, S = np.zeros((1, 2, 1)), np.eye(2)[None], np.ones((1, 2, 2), bool)
        >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])
        >>> f.predict(x, P, np.ones((1, 2, 1)))[0][0, :, 0]
        array([1., 1.])
        """
        x, P, u = _step_inputs(self, x=x, P=P, u=u)
        return finite_result("centralized prediction", x @ self.A.T + u @ self.B.T,
                             self.A_team @ P @ self.A_team.T + self.Q_team, inputs=((x, "x"), (u, "u"), (P, "P")))

    def own_covariances(self, P: np.ndarray) -> np.ndarray:
        """Agent i's own block of the team covariance, for every agent.

        Parameters
        ----------
        P : (B, N n, N n) ndarray
            The team covariance.

        Returns
        -------
        (B, N, n, n) ndarray
            The diagonal blocks.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.own_state import CentralizedOutputFilter
        >>> f = CentralizedOutputFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), 1.0, 2)
        >>> x, P, S = np.zeros((1, 2, 1)), np.eye(2)[None], np.ones((1, 2, 2), bool)
        >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])
        >>> f.own_covariances(2 * P)[0, :, 0, 0]
        array([2., 2.])
        """
        N, n = self.n_agents, self.A.shape[0]
        idx = np.arange(N)
        (P,) = _step_inputs(self, P=P)
        return np.moveaxis(P.reshape(-1, N, n, N, n)[:, idx, :, idx, :], 0, 1)

    def agent_inputs(self, x: np.ndarray, P: np.ndarray, Z: np.ndarray, S: np.ndarray, u: np.ndarray,
                     i: int) -> tuple[dict, tuple]:
        """The centre's data of one step (the whole filter's: it is the busiest node).

        Parameters
        ----------
        x : (N, n) ndarray
            The team's states before the step (one run).
        P : (N n, N n) ndarray
            The team covariance.
        Z : (N, N, p) ndarray
            The step's measurements.
        S : (N, N) bool ndarray
            The delivered links.
        u : (N, k) ndarray
            The inputs applied.
        i : int
            Unused: the centre's step is the same for every agent.

        Returns
        -------
        own : dict
            The team's data, with a run axis of one.
        messages : tuple
            Empty: the measurements are part of the centre's data.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore.own_state import CentralizedOutputFilter
        >>> f = CentralizedOutputFilter(np.eye(1), np.eye(1), np.zeros((1, 1)), np.eye(1), 1.0, 2)
        >>> x, P, S = np.zeros((1, 2, 1)), np.eye(2)[None], np.ones((1, 2, 2), bool)
        >>> Z = np.array([[[[1.0], [3.0]], [[1.0], [3.0]]]])
        >>> own, messages = f.agent_inputs(x[0], P[0], Z[0], S[0], np.zeros((2, 1)), 0)
        >>> own["x"].shape, messages
        ((1, 2, 1), ())
        """
        x, P, Z, S, u = _step_inputs(self, False, x=x, P=P, Z=Z, S=S, u=u)
        return {"x": x[None].copy(), "P": P[None].copy(), "Z": Z[None].copy(), "S": S[None].copy(),
                "u": u[None].copy()}, ()

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        # the centre's step, the team's correction and prediction: states (1, N, n), covariance (1, N n, N n)
        return self.predict(*self.update(own["x"], own["P"], own["Z"], own["S"]), own["u"])

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        # to the centre: p floats per agent it measures, itself included
        return (Message("measurements z_ij of itself and its neighbours, to the centre", float(self.C.shape[0])),)


#: ``forwarding`` on the team task: the one-hop filter of each agent's own state (its neighbours' measurements of it).
METHODS = (
    MethodSpec("forwarding", ("team",),
               lambda team, x_hat0: OwnStateForwardingFilter(team.A, team.B, team.Q_filter, team.C, team.R),
               lambda n, q, d, N: (float(q * d + n), kalman_step_flops(n) + n**3 + 2 * (d + 1) * n),
               {"team": ("O(d n + n^3)", "O(n^2 + d n)")}, lambda n, q, d, N: float(n**2 + n + d * n), position=2),
)


def _finite_information(information: np.ndarray, name: str) -> np.ndarray:
    """The measurement information ``H^T R^-1 H`` of a model, refused (naming `name`) if it overflows."""
    if not np.isfinite(information).all():
        raise ValueError(f"{name} is too large: the measurement information {name}^T R^-1 {name} overflows "
                         f"floating point; rescale the measurement units")
    return information


def _inverse(P: np.ndarray) -> np.ndarray:
    """``P^-1`` of a step's covariance(s), refused by name if singular."""
    try:
        return np.linalg.inv(P)
    except np.linalg.LinAlgError:
        raise ValueError("P must be positive definite (invertible); got a singular covariance") from None


def _step_inputs(filt, runs: bool = True, **named) -> tuple[np.ndarray, ...]:
    """A step's inputs, refused by name: finite floats of the filter's sizes, and boolean links ``S``.

    With `runs`, each has a leading run axis (``S`` and a centralized ``P`` may have one run for all).
    """
    n, k = filt.A.shape[0], filt.B.shape[1]
    p = (filt.H if hasattr(filt, "H") else filt.C).shape[0]
    team = getattr(filt, "n_agents", None)
    N = team if team is not None else (np.shape(named["x"])[-2] if "x" in named and np.ndim(named["x"]) >= 2
                                       else None)
    per_agent = {"x": (N, n), "u": (N, k), "Z": (N, N, p), "S": (N, N),
                 "P": (N, n, n) if team is None else (team * n, team * n)}
    out = []
    for name, value in named.items():
        if name == "S":
            arr = np.asarray(value)
            if arr.dtype.kind not in "bui":
                raise TypeError(f"S must be a boolean array of delivered links; got {type(value).__name__} of dtype "
                                f"{arr.dtype}")
        else:
            arr = require_finite(float_array(value, name), name)
        want = per_agent[name]
        if arr.ndim != len(want) + runs or any(w is not None and a != w for a, w in zip(arr.shape[runs:], want)):
            shape = ", ".join(["R"] * runs + ["N" if w is None else str(w) for w in want])
            raise ValueError(f"{name} must have shape ({shape}); got {arr.shape}")
        out.append(arr)
    return tuple(out)
