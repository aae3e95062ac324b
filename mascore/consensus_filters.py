"""The estimators of a shared quantity: Ren et al.'s Kalman consensus and Metropolis average consensus.

Each of N agents holds an estimate ``xi_i`` (size m) of one common quantity; at every step
it mixes what the neighbours it hears at that step (``G[i, j] > 0``) send it.
:class:`KalmanConsensusFilter` is the discrete Kalman consensus of Ren, Beard and Kingston
(2005), eqs. (4)-(5) (:func:`mascore.consensus.kalman_consensus_step`), with its covariance;
:class:`AverageConsensusFilter` the average with Metropolis weights on the delivered links
(Xiao, Boyd and Lall 2005), without one; ``CentralFusionFilter`` (the bound) and
``NoFusionFilter`` the two ends. All implement the estimator protocol
(:mod:`mascore.estimation`), with ``fuse(xi, P, G)`` the shared task's whole run, and declare
their methods of the comparison's ``shared`` task.

Shapes: ``xi`` ``(..., N, m)``, ``P`` ``(..., N, m, m)``, ``G`` ``(..., N, N)`` (zero diagonal).
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from ._validation import Frozen, agent_index, check_positive, check_positive_int, require_finite
from ._validation import float_array as _float_array
from .consensus import central_fusion, kalman_consensus_discrete, kalman_consensus_step
from .estimation import Message, MethodSpec, protocol_docs

__all__ = ["KalmanConsensusFilter", "AverageConsensusFilter", "METHODS"]


@protocol_docs
class KalmanConsensusFilter(Frozen):
    """Ren et al.'s discrete Kalman consensus, noise-free messages: one step per :meth:`update`.

    Parameters
    ----------
    Q : float
        Process-noise covariance per step, ``Q I`` ((state unit)^2), >= 0.
    Omega : float
        Communication-noise covariance weighting a received state, ``Omega I``, >= 0.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs
    >>> from mascore.consensus_filters import KalmanConsensusFilter
    >>> f = KalmanConsensusFilter(0.1, 0.1)
    >>> xi, P = f.update(np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1)), graphs.path_graph(3))
    >>> xi[:, 0].round(3)
    array([0.667, 2.   , 3.333])
    """

    def __init__(self, Q: float, Omega: float) -> None:
        self._set(Q=check_positive(Q, "Q", allow_zero=True), Omega=check_positive(Omega, "Omega", allow_zero=True))

    def _args(self) -> tuple:
        return (self.Q, self.Omega)

    def predict(self, xi: ArrayLike, P: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The quantity does not move: the prediction ``P + Q`` is inside eq. (4) of :meth:`update` (identity here).

        Parameters
        ----------
        xi : (..., N, m) array_like
            The estimates.
        P : (..., N, m, m) array_like
            Their covariances.

        Returns
        -------
        xi, P : ndarray
            The same, as float arrays.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import KalmanConsensusFilter
        >>> f, G = KalmanConsensusFilter(0.1, 0.1), graphs.path_graph(3)
        >>> xi, P = np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1))
        >>> f.predict(xi, P)[0].shape
        (3, 1)
        """
        return _finite(xi, "xi"), _finite(P, "P")

    def update(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """One step of eqs. (4)-(5) with the messages delivered on `G` (:func:`~mascore.consensus.kalman_consensus_step`).

        Parameters
        ----------
        xi : (..., N, m) array_like
            The estimates before the step.
        P : (..., N, m, m) array_like
            Their covariances.
        G : (..., N, N) array_like
            The links delivered at the step (``G[i, j] > 0``: i hears j).

        Returns
        -------
        xi, P : ndarray
            After the step.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import KalmanConsensusFilter
        >>> f, G = KalmanConsensusFilter(0.1, 0.1), graphs.path_graph(3)
        >>> xi, P = np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1))
        >>> f.update(xi, P, G)[1][:, 0, 0].round(3)
        array([0.367, 0.275, 0.367])
        """
        return kalman_consensus_step(xi, P, G, Q=self.Q, Omega=self.Omega)

    def fuse(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The shared task's run: one :meth:`update` per step of the delivered links `G`.

        Parameters
        ----------
        xi : (..., N, m) array_like
            The priors.
        P : (..., N, m, m) array_like
            Their covariances.
        G : (steps, ..., N, N) array_like
            The links delivered at each step.

        Returns
        -------
        xi, P : ndarray
            After the last step.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import KalmanConsensusFilter
        >>> f, G = KalmanConsensusFilter(0.0, 0.0), np.stack([graphs.path_graph(3)] * 50)
        >>> f.fuse(np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1)), G)[0][:, 0].round(3)
        array([2., 2., 2.])
        """
        # noise-free messages; the arguments checked once, the steps those of update (the trajectory checked at the end)
        run = kalman_consensus_discrete(*_run(xi, P, G), Q=self.Q, Omega=self.Omega)
        return run.xi[-1], run.P[-1]

    def agent_inputs(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike, i: int) -> tuple[dict, tuple]:
        """Agent i's state and the states and covariances its neighbours send it at the step (one run).

        Parameters
        ----------
        xi : (N, m) array_like
            The estimates before the step.
        P : (N, m, m) array_like
            Their covariances.
        G : (N, N) array_like
            The links delivered at the step.
        i : int
            The agent.

        Returns
        -------
        own : dict
            Its ``xi`` and ``P``.
        messages : tuple
            One round: the neighbours' ``(xi_j, P_j)`` stacked, ``(d, m)`` and ``(d, m, m)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import KalmanConsensusFilter
        >>> f, G = KalmanConsensusFilter(0.1, 0.1), graphs.path_graph(3)
        >>> xi, P = np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1))
        >>> own, messages = f.agent_inputs(xi, P, G, 1)
        >>> messages[0][0][:, 0]                                  # agents 0 and 2 send their states
        array([0., 4.])
        """
        xi, G, P = _team(xi, G, P)
        i = agent_index(i, len(xi))
        heard = np.flatnonzero(G[i] > 0)
        return {"xi": xi[i].copy(), "P": P[i].copy()}, ((xi[heard].copy(), P[heard].copy()),)

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        # eqs. (4)-(5) on agent i and the neighbours it heard: xi_i (m,), P_i (m, m)
        xi_n, P_n = messages[0]
        d = len(xi_n)
        g = np.zeros((d + 1, d + 1))
        g[0, 1:] = 1.0  # agent i hears its d neighbours; their own rows are not computed for it
        xi, P = kalman_consensus_step(np.concatenate([own["xi"][None], xi_n]), np.concatenate([own["P"][None], P_n]),
                                      g, Q=self.Q, Omega=self.Omega)
        return xi[0], P[0]

    def messages(self, i: int = 0, m: int = 2) -> tuple[Message, ...]:
        """What an agent broadcasts per step: its state and covariance.

        Parameters
        ----------
        i : int
            The agent (the same for all).
        m : int
            The size of the quantity.

        Returns
        -------
        tuple of Message
            ``m + m (m + 1) / 2`` floats.

        Examples
        --------
        >>> from mascore.consensus_filters import KalmanConsensusFilter
        >>> KalmanConsensusFilter(0.1, 0.1).messages(m=2)[0].floats
        5.0
        """
        m = check_positive_int(m, "m")
        return (Message("state xi_i and covariance P_i", float(m + m * (m + 1) // 2)),)


@protocol_docs
class AverageConsensusFilter(Frozen):
    """Average consensus with Metropolis weights on the links delivered at each step; no covariance.

    ``W[i, j] = 1 / (1 + max(d_i, d_j))`` for each delivered link, ``W[i, i] = 1 - sum_j W[i, j]``
    (the degrees of that step's delivered graph); ``xi+ = W xi``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs
    >>> from mascore.consensus_filters import AverageConsensusFilter
    >>> AverageConsensusFilter().update(np.array([[0.0], [3.0]]), graphs.path_graph(2))[:, 0]
    array([1.5, 1.5])
    """

    def __init__(self) -> None:
        pass

    def _args(self) -> tuple:
        return ()

    def predict(self, xi: ArrayLike) -> np.ndarray:
        """The quantity does not move (identity).

        Parameters
        ----------
        xi : (..., N, m) array_like
            The estimates.

        Returns
        -------
        ndarray
            The same, as a float array.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import AverageConsensusFilter
        >>> f, xi, G = AverageConsensusFilter(), np.array([[0.0], [3.0], [6.0]]), graphs.path_graph(3)
        >>> f.predict(xi).shape
        (3, 1)
        """
        return _finite(xi, "xi")

    def update(self, xi: ArrayLike, G: ArrayLike) -> np.ndarray:
        """One mixing step ``W xi`` on the delivered links `G`.

        Parameters
        ----------
        xi : (..., N, m) array_like
            The estimates before the step.
        G : (..., N, N) array_like
            The links delivered at the step.

        Returns
        -------
        ndarray
            ``W xi``, the shape of `xi`.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import AverageConsensusFilter
        >>> f, xi, G = AverageConsensusFilter(), np.array([[0.0], [3.0], [6.0]]), graphs.path_graph(3)
        >>> f.update(xi, G)[:, 0]
        array([1., 3., 5.])
        """
        xi, G_k, _ = _team(xi, G, batched=True)
        deg = G_k.sum(-1)
        W = G_k / (1.0 + np.maximum(deg[..., :, None], deg[..., None, :]))
        W = W + np.eye(G_k.shape[-1]) * (1.0 - W.sum(-1))[..., None]
        return W @ xi

    def fuse(self, xi: ArrayLike, P: ArrayLike | None, G: ArrayLike) -> tuple[np.ndarray, None]:
        """The shared task's run: one :meth:`update` per step of the delivered links `G`.

        Parameters
        ----------
        xi : (..., N, m) array_like
            The priors.
        P : array_like or None
            Unused (the average carries no covariance).
        G : (steps, ..., N, N) array_like
            The links delivered at each step.

        Returns
        -------
        xi : ndarray
            After the last step.
        None
            No covariance.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import AverageConsensusFilter
        >>> G = np.stack([graphs.path_graph(3)] * 60)
        >>> AverageConsensusFilter().fuse(np.array([[0.0], [3.0], [6.0]]), None, G)[0][:, 0].round(3)
        array([3., 3., 3.])
        """
        for G_k in G:
            xi = self.update(xi, G_k)
        return xi, None

    def agent_inputs(self, xi: ArrayLike, G: ArrayLike, i: int) -> tuple[dict, tuple]:
        """Agent i's state and degree, and its neighbours' states and degrees at the step (one run).

        Parameters
        ----------
        xi : (N, m) array_like
            The estimates before the step.
        G : (N, N) array_like
            The links delivered at the step.
        i : int
            The agent.

        Returns
        -------
        own : dict
            Its ``xi`` and ``degree``.
        messages : tuple
            One round: the neighbours' states ``(d, m)`` and degrees ``(d,)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import AverageConsensusFilter
        >>> f, xi, G = AverageConsensusFilter(), np.array([[0.0], [3.0], [6.0]]), graphs.path_graph(3)
        >>> f.agent_inputs(xi, G, 1)[1][0][1]                    # its neighbours' degrees
        array([1., 1.])
        """
        xi, G, _ = _team(xi, G)
        i = agent_index(i, len(xi))
        heard = np.flatnonzero(G[i] > 0)
        deg = G.sum(-1)
        return {"xi": xi[i].copy(), "degree": deg[i]}, ((xi[heard].copy(), deg[heard].copy()),)

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray]:
        # agent i's row of W xi: (xi_i,), (m,)
        xi_n, deg_n = messages[0]
        w = 1.0 / (1.0 + np.maximum(own["degree"], deg_n))
        return ((1.0 - w.sum()) * own["xi"] + w @ xi_n,)

    def messages(self, i: int = 0, m: int = 2) -> tuple[Message, ...]:
        """What an agent broadcasts per step: its state.

        Parameters
        ----------
        i : int
            The agent (the same for all).
        m : int
            The size of the quantity.

        Returns
        -------
        tuple of Message
            ``m`` floats.

        Examples
        --------
        >>> from mascore.consensus_filters import AverageConsensusFilter
        >>> AverageConsensusFilter().messages(m=2)[0].floats
        2.0
        """
        return (Message("state xi_i", float(check_positive_int(m, "m"))),)


class CentralFusionFilter(Frozen):
    """The bound of the shared task: a centre receives every prior and returns the fused one to all.

    The inverse-covariance weighted mean (:func:`mascore.consensus.central_fusion`), once: the links
    do not matter (each agent sends its prior up and receives the fused estimate down).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.consensus_filters import CentralFusionFilter
    >>> xi, P = CentralFusionFilter().update(np.array([[0.0], [3.0]]), np.array([[[1.0]], [[2.0]]]), None)
    >>> xi[:, 0], P[:, 0, 0].round(4)
    (array([1., 1.]), array([0.6667, 0.6667]))
    """

    def _args(self) -> tuple:
        return ()

    def predict(self, xi: ArrayLike, P: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The quantity does not move (identity); see :class:`mascore.estimation.Estimator`."""
        return np.asarray(xi, dtype=float), np.asarray(P, dtype=float)

    def update(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike | None) -> tuple[np.ndarray, np.ndarray]:
        """Every agent's estimate ``(..., N, m)`` and covariance ``(..., N, m, m)`` replaced by the fused ones."""
        xi_f, P_f = central_fusion(xi, P)
        N = np.shape(xi)[-2]
        return (np.broadcast_to(xi_f[..., None, :], (*xi_f.shape[:-1], N, xi_f.shape[-1])),
                np.broadcast_to(P_f[..., None, :, :], (*P_f.shape[:-2], N, *P_f.shape[-2:])))

    def fuse(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The shared task's run: the fusion once, whatever the steps of `G`."""
        return self.update(xi, P, None)

    def agent_inputs(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike | None, i: int) -> tuple[dict, tuple]:
        """The centre's data: every prior ``(N, m)``, ``(N, m, m)`` (see :class:`mascore.estimation.Estimator`)."""
        return {"xi": _float_array(xi, "xi").copy(), "P": _float_array(P, "P").copy()}, ()

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """The centre's step: the fused ``(m,)`` estimate and ``(m, m)`` covariance."""
        return central_fusion(own["xi"], own["P"])

    def messages(self, i: int = 0, m: int = 2) -> tuple[Message, ...]:
        """Up: the prior and its covariance; down: the fused estimate (``2 m + m (m + 1) / 2`` floats)."""
        return (Message("prior xi_i and P_i up", float(m + m * (m + 1) // 2)), Message("fused estimate down", float(m)))


class NoFusionFilter(Frozen):
    """No fusion: every agent keeps its prior (the reference without communication).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.consensus_filters import NoFusionFilter
    >>> NoFusionFilter().update(np.zeros((3, 2)), np.ones((3, 2, 2)), None)[0].shape
    (3, 2)
    """

    def _args(self) -> tuple:
        return ()

    def predict(self, xi: ArrayLike, P: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Identity; see :class:`mascore.estimation.Estimator`."""
        return np.asarray(xi, dtype=float), np.asarray(P, dtype=float)

    def update(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike | None) -> tuple[np.ndarray, np.ndarray]:
        """Identity: no link is used."""
        return np.asarray(xi, dtype=float), np.asarray(P, dtype=float)

    fuse = update

    def agent_inputs(self, xi: ArrayLike, P: ArrayLike, G: ArrayLike | None, i: int) -> tuple[dict, tuple]:
        """Agent i's prior; no message (see :class:`mascore.estimation.Estimator`)."""
        return {"xi": _float_array(xi, "xi")[i].copy(), "P": _float_array(P, "P")[i].copy()}, ()

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """Its prior, unchanged."""
        return own["xi"], own["P"]

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        """Nothing."""
        return ()


#: Why Ren et al.'s Kalman consensus does not apply elsewhere (the tables show it).
_REN_NOT_APPLICABLE = MappingProxyType({
    "target": "fuses priors of a quantity nobody measures; with measurements it becomes the consensus filters above",
    "localization": "fuses priors of a quantity nobody measures; there is no common quantity here",
})


def _floats_flops_ren(n: int, q: int, d: int, N: int) -> tuple[float, float]:
    # d + 1 inverses of P_j + Omega, one of P_i + Q, one of the information; the weighted innovations
    return float(n + n * (n + 1) // 2), float((d + 3) * n**3 + 2 * (d + 1) * n**2)


#: The consensus methods of the shared task: Ren et al.'s (Q = Omega = 0.1, the paper's; 0, the knob's other end;
#: 0.3, 0.6 and 1, the knob swept) and the average.
METHODS = (
    MethodSpec("central-fusion", ("shared",), lambda scenario: CentralFusionFilter(),
               lambda n, q, d, N: (float(2 * n + n * (n + 1) // 2), float(N * (n**3 + 2 * n**2))),
               {"shared": ("O(N m^3) at the centre", "O(N m^2)")}, lambda n, q, d, N: float(N * (n**2 + n)),
               whole_filter=True, position=10),
    MethodSpec("no-fusion", ("shared",), lambda scenario: NoFusionFilter(), lambda n, q, d, N: (0.0, 0.0),
               {"shared": ("O(1)", "O(m^2)")}, lambda n, q, d, N: float(n**2 + n), position=11),
    MethodSpec("average-consensus", ("shared",), lambda scenario: AverageConsensusFilter(),
               lambda n, q, d, N: (float(n), float(2 * (d + 1) * n)), {"shared": ("O(d m)", "O(d m)")},
               lambda n, q, d, N: float(n + d * n), position=12),
    MethodSpec("ren-kc", ("shared",), lambda scenario: KalmanConsensusFilter(0.1, 0.1), _floats_flops_ren,
               {"shared": ("O(d m^3)", "O(d m^2)")}, lambda n, q, d, N: float((d + 1) * (n**2 + n)), _REN_NOT_APPLICABLE,
               position=13, family="ren-kc", setting=0.1),
    MethodSpec("ren-kc-q0", ("shared",), lambda scenario: KalmanConsensusFilter(0.0, 0.0), _floats_flops_ren,
               {"shared": ("O(d m^3)", "O(d m^2)")}, lambda n, q, d, N: float((d + 1) * (n**2 + n)), position=14,
               role="variant", family="ren-kc", setting=0.0),
    # the knob Q = Omega swept further (mascore.compare.KNOBS)
    *(MethodSpec(f"ren-kc-q{q:g}", ("shared",), lambda scenario, q=q: KalmanConsensusFilter(q, q), _floats_flops_ren,
                 {"shared": ("O(d m^3)", "O(d m^2)")}, lambda n, q, d, N: float((d + 1) * (n**2 + n)),
                 position=14 + k, role="knob", family="ren-kc", setting=q) for k, q in enumerate((0.3, 0.6, 1.0), start=1)),
)


def _finite(value: ArrayLike, name: str) -> np.ndarray:
    """`value` as a float array, refused by name if it holds NaN or inf (a step's own input)."""
    return require_finite(_float_array(value, name), name)


def _links(G: ArrayLike) -> np.ndarray:
    """The delivered links of a step: finite, non-negative weights."""
    G = _finite(G, "G")
    if (G < 0).any():
        raise ValueError("G must hold non-negative link weights (G[i, j] > 0: agent i heard agent j)")
    return G


def _run(xi: ArrayLike, P: ArrayLike, G: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A run's priors ``(..., N, m)``, their covariances ``(..., N, m, m)`` and its links ``(steps, ..., N, N)``,
    refused by the names of :meth:`KalmanConsensusFilter.fuse`."""
    xi, P, G = _finite(xi, "xi"), _finite(P, "P"), _links(G)
    if xi.ndim < 2 or xi.shape[-1] == 0:
        raise ValueError(f"xi must have shape (..., N, m) with m >= 1; got {xi.shape}")
    N, m = xi.shape[-2:]
    if P.shape != (*xi.shape, m):
        raise ValueError(f"P must have shape (..., N, m, m) = {(*xi.shape, m)} for xi of shape {xi.shape}; got {P.shape}")
    if G.ndim < 3 or G.shape[-2:] != (N, N):
        raise ValueError(f"G must have shape (steps, ..., N, N) = (steps, ..., {N}, {N}) for xi of shape {xi.shape}; "
                         f"got {G.shape}")
    if np.diagonal(G, axis1=-2, axis2=-1).any():
        raise ValueError("G must have a zero diagonal (an agent always uses its own state)")
    return xi, P, G


def _team(xi: ArrayLike, G: ArrayLike, P: ArrayLike | None = None,
          batched: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A step's estimates ``(N, m)`` (``(..., N, m)`` if batched), links ``(N, N)`` and covariances ``(N, m, m)``."""
    xi, G = _finite(xi, "xi"), _links(G)
    if xi.ndim < 2 or (not batched and xi.ndim != 2):
        raise ValueError(f"xi must have shape {'(..., N, m)' if batched else '(N, m)'}; got {xi.shape}")
    N, m = xi.shape[-2:]
    if G.shape[-2:] != (N, N) or (not batched and G.ndim != 2):
        raise ValueError(f"G must have shape (N, N) = ({N}, {N}) for xi of shape {xi.shape}; got {G.shape}")
    if P is not None:
        P = _finite(P, "P")
        if P.shape != (N, m, m):
            raise ValueError(f"P must have shape (N, m, m) = ({N}, {m}, {m}) for xi of shape {xi.shape}; got {P.shape}")
    return xi, G, P
