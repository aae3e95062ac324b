"""The base of the sensor-network filters of :mod:`mascore.fusion` and :mod:`mascore.fusion_forwarding`.

:class:`NetworkFilter` holds what every filter shares: the checked model, ``predict``,
``update`` (which calls the filter's ``_correct``), ``run``, and the per-agent protocol
(``agent_inputs``, ``agent_step``, ``messages``; :class:`mascore.estimation.Estimator`). The
helpers below it build the parts of a :class:`~mascore.estimation.MethodSpec` of the
common-target and localization tasks from :func:`~mascore.fusion_cost.filter_cost`; the last two
check arguments the filters share (consensus weights, information pairs).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from . import kalman
from ._fusion_kernels import broadcast_batch
from ._validation import (
    Frozen,
    check_fits_in_memory,
    check_positive_int,
    check_square,
    finite_result,
    float_array,
    require_finite,
)
from .estimation import Message
from .fusion_cost import filter_cost
from .sensor_network import SensorNetworkModel

__all__ = ["NetworkFilter", "TASKS", "centre_memory", "check_stochastic", "pair_list", "spec_cost", "spec_memory",
           "spec_orders"]


class NetworkFilter(Frozen):
    """Shared predict / update / run of the filters (each defines ``_correct``)."""

    __slots__ = ("model",)
    _what = "filter update"
    _per_agent = True
    _per_run_sensing = True  # its correction broadcasts a model's sensing with run axes (fusion.track)

    def __init__(self, model: SensorNetworkModel) -> None:
        if not isinstance(model, SensorNetworkModel):
            raise TypeError(f"model must be a SensorNetworkModel; got {type(model).__name__}")
        self._set(model=model)

    def __reduce__(self) -> tuple:
        return (type(self), (self.model, *self._args()))

    def __repr__(self) -> str:
        args = "".join(f", {a!r}" for a in self._args() if not isinstance(a, np.ndarray))
        return f"{type(self).__name__}({self.model!r}{args})"

    def _args(self) -> tuple:
        """The constructor's arguments after the model (pickling, repr)."""
        return ()

    def predict(self, x: ArrayLike, P: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Time update of every agent: ``x- = F x``, ``P- = F P F^T + Q`` (:func:`mascore.kalman.predict`).

        Parameters
        ----------
        x : (..., N, n) array_like
            Means (``(..., n)`` for the centralized filter).
        P : (..., N, n, n) array_like
            Covariances (``(..., n, n)`` for the centralized filter).

        Returns
        -------
        x_pred, P_pred : ndarray
            The predictions, same shapes.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.5]], [[[1.0]]] * 2, [[[1.0]]] * 2, graphs.path_graph(2))
        >>> x, P = fusion.MeasurementForwardingFilter(model).predict(np.ones((2, 1)), np.ones((2, 1, 1)))
        >>> P[:, 0, 0]                                             # 1 + Q
        array([1.5, 1.5])
        """
        x, P = self._check_xP(x, P)
        return kalman.predict(x, P, self.model._kf)

    def update(self, x: ArrayLike, P: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Measurement update with the filter's communication round(s).

        Parameters
        ----------
        x : (..., N, n) array_like
            Predicted means (``(..., n)`` for the centralized filter).
        P : (..., N, n, n) array_like
            Predicted covariances, symmetric positive definite.
        z : (..., sum q_i) array_like
            The stacked measurements of every agent, finite.

        Returns
        -------
        x_post : ndarray
            Corrected means; their batch axes are those of `x`, `P` and `z` broadcast.
        P_post : ndarray
            Corrected covariances; their batch axes are those of `P` (and `x`): the
            covariances do not depend on the data.

        Raises
        ------
        ValueError
            A bad shape, a NaN or inf in `x`, `P` or `z`, or a result that overflowed.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 2, [[[1.0]]] * 2, graphs.path_graph(2))
        >>> x, P = fusion.MeasurementForwardingFilter(model).update(np.zeros((2, 1)), np.ones((2, 1, 1)), [3.0, 0.0])
        >>> x[:, 0], P[:, 0, 0]                                    # both hear both: information 1 + 2
        (array([1., 1.]), array([0.33333333, 0.33333333]))
        """
        x, P = self._check_xP(x, P)
        require_finite(P, "P")  # an information form would turn an infinite variance into silent zeros
        z = self.model._check_z(z)
        axis = 2 if self._per_agent else 1
        broadcast_batch("x", x.shape[:-axis], "z", z.shape[:-1])
        try:
            with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
                out = self._correct(x, P, z)
        except np.linalg.LinAlgError:
            out = None
        if out is None:
            for value, name in ((x, "x"), (P, "P"), (z, "z")):
                require_finite(value, name)
            raise ValueError(f"the {self._what} met a singular matrix: the predicted covariances must be positive "
                             "definite (Q positive definite or F invertible)")
        return finite_result(self._what, *out, inputs=((x, "x"), (P, "P"), (z, "z")))

    def run(self, x0: ArrayLike, P0: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """A whole run: predict, then update, for each measurement.

        Parameters
        ----------
        x0 : (..., N, n) or (n,) array_like
            Initial means (one ``(n,)`` mean for every agent allowed).
        P0 : (..., N, n, n) or (n, n) array_like
            Initial covariances, symmetric positive definite.
        z : (K, ..., sum q_i) array_like
            Measurements of steps 1..K (as ``SensorNetworkModel.simulate`` returns).

        Returns
        -------
        x : (K, ..., N, n) ndarray
            Corrected means after each step (``(K, ..., n)`` for the centralized filter).
        P : (K, ..., N, n, n) ndarray
            Corrected covariances. Their leading axes are those of `P0` and `x0`, not of `z`:
            the covariances do not depend on the data, so runs that share an initial state
            share them.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), 0.01 * np.eye(2), [np.eye(2)] * 3, [np.eye(2)] * 3,
        ...                                           graphs.ring_graph(3))
        >>> x_true, z = model.simulate(np.zeros(2), np.eye(2), 50, rng=0, n_runs=10)   # the same data for all
        >>> x, P = fusion.ConsensusOnInformationFilter(model, 2).run(np.zeros(2), np.eye(2), z)
        >>> x.shape, P.shape                                       # (K, runs, N, n); P shared by the runs
        ((50, 10, 3, 2), (50, 3, 2, 2))
        """
        x, P = self.model.check_state(x0, P0, ("x0", "P0"), per_agent=self._per_agent)
        z = self.model._check_z(z)
        if z.ndim < 2:
            raise ValueError(f"z must be (K, ..., {self.model.n_measurements}): one stacked measurement per step; "
                             f"got shape {z.shape}")
        axis = 2 if self._per_agent else 1
        batch = broadcast_batch("x0", x.shape[:-axis], "z", z.shape[1:-1])
        n = self.model.n_states
        per_run = n * (1 + n) * (self.model.n_agents if self._per_agent else 1)
        check_fits_in_memory(8.0 * z.shape[0] * math.prod(batch) * per_run, "z",
                             "the estimates and covariances of every step and run")
        require_finite(z, "z")
        xs, Ps = [], []
        for k in range(z.shape[0]):
            x, P = self.predict(x, P)
            x, P = self.update(x, P, z[k])
            xs.append(x)
            Ps.append(P)
        return np.stack(xs), np.stack(Ps)

    def agent_inputs(self, x: ArrayLike, P: ArrayLike, z: ArrayLike, i: int) -> tuple[dict, tuple]:
        """Agent i's own data and the messages it receives at one step, cut out of the team-wide filter.

        The team's predictions of the step are the source of the neighbours' messages (each
        round's, in order): what agent i would receive from them. This is the untimed part of
        a per-agent measurement (:mod:`mascore.agent_cost`); :meth:`agent_step` is the timed one.

        Parameters
        ----------
        x : (N, n) array_like
            Every agent's estimate before the step (``(n,)`` for the centralized filter).
        P : (N, n, n) array_like
            Their covariances, symmetric positive definite (``(n, n)`` for the centralized filter).
        z : (sum q_i,) array_like
            The step's stacked measurement.
        i : int
            The agent, ``0 <= i < N``.

        Returns
        -------
        own : dict
            Agent i's own data: ``x``, ``P`` (its estimate before the step), ``z`` (its
            measurement), its neighbourhood ``hood`` (i included, ascending), ``nbrs``,
            ``index`` (of i in ``hood``), ``HtRinv`` (``H_j^T R_j^{-1}`` of each j in ``hood``),
            ``S`` (their ``sum H_j^T R_j^{-1} H_j``), ``I`` (its own ``H_i^T R_i^{-1} H_i``), and for a
            filter that mixes its neighbours' messages ``w_self`` and ``w_nb`` (its row of the mixing
            weights): the model's constant parts are known to the agent beforehand.
        messages : tuple
            One entry per communication round: the neighbours' messages of that round.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), 0.1 * np.eye(2), [np.eye(2)] * 4, [np.eye(2)] * 4,
        ...                                           graphs.ring_graph(4))
        >>> filt = fusion.ConsensusOnInformationFilter(model, 3)
        >>> x, P, z = np.zeros((4, 2)), np.broadcast_to(np.eye(2), (4, 2, 2)), np.arange(8.0)
        >>> own, messages = filt.agent_inputs(x, P, z, 1)
        >>> len(messages), own["nbrs"].tolist()                       # 3 rounds from neighbours 0 and 2
        (3, [0, 2])
        >>> x1, P1 = filt.agent_step(1, own, messages)
        >>> xr, Pr = filt.update(*filt.predict(x, P), z)               # agent 1's row of the team-wide filter
        >>> bool(np.allclose(x1, xr[1]) and np.allclose(P1, Pr[1]))
        True
        """
        x, P = self._check_xP(x, P)
        z = require_finite(self.model._check_z(z), "z")
        batch = x.shape[:-2] + P.shape[:-3] if self._per_agent else x.shape[:-1] + P.shape[:-2]
        if z.ndim != 1 or batch:
            one = "N, " if self._per_agent else ""
            raise ValueError(f"agent_inputs takes one run: x ({one}n), P ({one}n, n) and z (sum q_i,); got x {x.shape}, "
                             f"P {P.shape}, z {z.shape}")
        x, P = self.model.check_state(x, P, ("x", "P"), per_agent=self._per_agent)  # finite, P positive definite
        N, n = self.model.n_agents, self.model.n_states
        i = check_positive_int(i, "i", minimum=0)
        if i >= N:
            raise ValueError(f"i must be an agent index below N = {N}; got {i}")
        if not self._per_agent:
            return {"x": x, "P": P, "z": z}, ()
        m = self.model
        hood = np.flatnonzero(m._neighbourhood[i])
        HtRinv = tuple(m.H[j].T @ np.linalg.inv(m.R[j]) if m.H[j].shape[0] else np.zeros((n, 0)) for j in hood)
        own = {"x": x[i].copy(), "P": P[i].copy(), "z": m.agent_measurement(z, i).copy(), "hood": hood,
               "nbrs": hood[hood != i], "index": int(np.flatnonzero(hood == i)[0]), "HtRinv": HtRinv,
               "S": sum(m.information_matrices[j] for j in hood), "I": m.information_matrices[i]}
        W = self._mixing_weights()
        if W is not None:
            own["w_self"], own["w_nb"] = float(W[i, i]), W[i, own["nbrs"]].copy()
        return own, self._agent_messages(own, *self.predict(x, P), z, i)

    def _mixing_weights(self) -> np.ndarray | None:
        """The (N, N) weights with which an agent mixes its own and its neighbours' messages (None: it does not):
        a consensus filter's weights of one round, ``round_weights``."""
        return getattr(self, "round_weights", None)

    def agent_step(self, i: int, own_data: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """Agent i's step alone: its prediction, its correction with its own data and its neighbours' messages.

        Parameters
        ----------
        i : int
            The agent.
        own_data, messages
            From :meth:`agent_inputs` (not checked again: this is the step that is timed).

        Returns
        -------
        x_i : (n,) ndarray
            Agent i's estimate after the step (the centralized filter: the team's ``(n,)``).
        P_i : (n, n) ndarray
            Its covariance.
        """
        if not self._per_agent:  # the centre runs the whole filter
            return self.update(*self.predict(own_data["x"], own_data["P"]), own_data["z"])
        return self._agent_step(i, own_data, messages)

    @property
    def exchanges(self) -> int:
        """The exchanges of one step that follow one another: each needs what the one before delivered.

        1 here (one message per step, or several sent at once); a filter whose step has more in
        sequence says so (consensus rounds, or measurements and then the estimates computed from
        them). Over links that take a step per message, the messages of one step arrive this many
        steps later (:func:`mascore.fusion_links.track_behind`).
        """
        return 1

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        """What agent i sends per step (and a centre's reply to it), with the floats of each message.

        A symmetric matrix counts as ``n (n + 1) / 2`` floats.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(1, 2)] * 3, [np.eye(1)] * 3,
        ...                                           graphs.ring_graph(3))
        >>> fusion.ConsensusOnInformationFilter(model, 2).messages()
        (Message(what='information pair (Omega, q), per consensus round', floats=10.0),)
        """
        q, n = float(self.model.measurement_sizes[i]), self.model.n_states
        return self._messages(q, n * (n + 1) / 2 + n)

    def _messages(self, q: float, pair: float) -> tuple[Message, ...]:
        return (Message("measurement z_i, to each neighbour", q),)

    def _agent_messages(self, own: dict, xm: np.ndarray, Pm: np.ndarray, z: np.ndarray, i: int) -> tuple:
        """The neighbours' messages of each round, from the team's predictions `xm`, `Pm`."""
        return (tuple(self.model.agent_measurement(z, j).copy() for j in own["nbrs"]),)

    def _agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        return self._incremental(own, messages[0])

    def _incremental(self, own: dict, received: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """Prediction, then the correction with the neighbourhood's measurements (information form)."""
        F, Q = self.model.F, self.model.Q
        xp, Pp = F @ own["x"], F @ own["P"] @ F.T + Q
        zs = list(received)
        zs.insert(own["index"], own["z"])
        iv = sum(h @ zj for h, zj in zip(own["HtRinv"], zs))
        S = own["S"]
        Pn = np.linalg.solve(np.eye(len(xp)) + Pp @ S, Pp)
        Pn = 0.5 * (Pn + Pn.T)
        return xp + Pn @ (iv - S @ xp), Pn

    def _check_xP(self, x: ArrayLike, P: ArrayLike, names: tuple[str, str] = ("x", "P")
                  ) -> tuple[np.ndarray, np.ndarray]:
        """`x` ``(..., N, n)`` and `P` ``(..., N, n, n)`` (``(..., n)``, ``(..., n, n)`` for the centralized filter)
        as float arrays of the model's sizes with broadcasting batch axes; `names` in the messages."""
        xname, Pname = names
        x, P = float_array(x, xname), float_array(P, Pname)
        n, N = self.model.n_states, self.model.n_agents
        if self._per_agent:
            if x.ndim < 2 or x.shape[-2:] != (N, n):
                raise ValueError(f"Incompatible dimensions of {xname}; expected (..., N, n) = (..., {N}, {n}) but "
                                 f"found {x.shape}")
            if P.ndim < 3 or P.shape[-3:] != (N, n, n):
                raise ValueError(f"Incompatible dimensions of {Pname}; expected (..., N, n, n) = (..., {N}, {n}, {n}) "
                                 f"but found {P.shape}")
            broadcast_batch(xname, x.shape[:-2], Pname, P.shape[:-3])
        else:
            if x.ndim < 1 or x.shape[-1] != n:
                raise ValueError(f"Incompatible dimensions of {xname}; expected (..., {n}) but found {x.shape}")
            if P.ndim < 2 or P.shape[-2:] != (n, n):
                raise ValueError(f"Incompatible dimensions of {Pname}; expected (..., {n}, {n}) but found {P.shape}")
            broadcast_batch(xname, x.shape[:-1], Pname, P.shape[:-2])
        return x, P

    def _check_step(self, x: ArrayLike, P: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A step's predictions `x`, `P` and measurement `z` (the public message methods): shapes, batch axes
        that broadcast, finite entries (an information form would turn an infinite variance into silent zeros)."""
        x, P = self._check_xP(x, P)
        z = self.model._check_z(z)
        broadcast_batch("x", x.shape[:-2], "z", z.shape[:-1])
        return require_finite(x, "x"), require_finite(P, "P"), require_finite(z, "z")

    def _check_pair(self, Om: ArrayLike, q: ArrayLike, names: tuple[str, str]) -> tuple[np.ndarray, np.ndarray]:
        """An information pair ``(Omega, q)`` given to a public method: ``(..., N, n, n)`` and ``(..., N, n)``,
        batch axes that broadcast, finite entries; `names` in the messages."""
        q, Om = self._check_xP(q, Om, names[::-1])
        return require_finite(Om, names[0]), require_finite(q, names[1])

    def _pair_result(self, kernel, Om: np.ndarray, q: np.ndarray, names: tuple[str, str]
                     ) -> tuple[np.ndarray, np.ndarray]:
        """``kernel(Om, q)`` (the estimate of a checked pair), refusing a singular `Om` or a result that overflows."""
        try:
            with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
                out = kernel(Om, q)
        except np.linalg.LinAlgError:
            raise ValueError(f"{names[0]} must be positive definite (invertible); got a singular matrix") from None
        return finite_result("estimate of the information pair", *out,
                             advice=f"{names[0]} is too close to singular or the values overflow floating point")

    def _correct(self, x: np.ndarray, P: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError


# --------------------------------------------------------------------------------------------
# the parts of the specs of the common-target and localization tasks (mascore.compare, mascore.agent_cost)


def spec_cost(name: str, iterations: int | None = 1, degree: bool = True):
    """``cost(n, q, degree, n_agents) -> (floats, flops)`` of :func:`~mascore.fusion_cost.filter_cost` for `name`.

    `iterations` None: the ring's diameter ``N // 2`` (the graph of the cost tables); no neighbours if not `degree`.
    """
    def cost(n: int, q: int, d: int, n_agents: int) -> tuple[float, float]:
        steps = max(1, n_agents // 2) if iterations is None else iterations
        c = filter_cost(name, n=n, q=q, degree=d if degree else 0, iterations=steps, n_agents=n_agents)
        return c.floats_sent, c.flops
    return cost


def spec_orders(target: tuple[str, str], localization: tuple[str, str]) -> dict[str, tuple[str, str]]:
    return {"target": target, "localization": localization}


def spec_memory(pairs: int = 0):
    """``memory(n, q, degree, n_agents)``: an estimate and covariance and d messages (`pairs` > 0: d + 1 pairs each)."""
    def memory(n: int, q: int, d: int, n_agents: int) -> float:
        return float((d + 1) * pairs * (n**2 + n)) if pairs else float(n**2 + n + d * n)
    return memory


def centre_memory(n: int, q: int, d: int, n_agents: int) -> float:
    return float(n**2 + n)


TASKS = ("target", "localization")


# --------------------------------------------------------------------------------------------
# argument checks shared by the filters of mascore.fusion


def check_stochastic(C: ArrayLike, name: str, model: SensorNetworkModel) -> np.ndarray:
    """Row-stochastic weights on the graph and the diagonal."""
    N = model.n_agents
    C = check_square(C, name, N)
    if np.any(C < 0) or not np.allclose(C.sum(axis=1), 1.0, rtol=0, atol=1e-9):
        raise ValueError(f"{name} must be non-negative with rows summing to 1 (convex combinations); "
                         f"row sums {np.round(C.sum(axis=1), 6).tolist()}")
    if np.any((C > 0) & (model._neighbourhood == 0)):
        raise ValueError(f"{name} must be zero where the graph has no link (C[i, l] > 0 needs l = i or "
                         "adjacency[i, l] > 0)")
    return C


def pair_list(pairs: object, count: int) -> list[tuple[object, object]]:
    """`pairs` as a list of `count` ``(Omega, q)`` pairs (what :meth:`pairs_estimate` takes), else a named error."""
    if (isinstance(pairs, (str, bytes)) or not isinstance(pairs, Sequence) or len(pairs) != count
            or not all(isinstance(p, Sequence) and not isinstance(p, (str, bytes)) and len(p) == 2 for p in pairs)):
        raise TypeError(f"pairs must be a sequence of {count} (Omega, q) pair(s), as message_pairs gives; got "
                        f"{type(pairs).__name__} {pairs!r:.80}")
    return [tuple(p) for p in pairs]
