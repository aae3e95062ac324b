"""The estimators of a shared quantity: Ren et al.'s Kalman consensus and Metropolis average consensus.

Each of N agents holds an estimate ``xi_i`` (size m) of one common quantity; at every step
it mixes what the neighbours it hears at that step (``G[i, j] > 0``) send it.
:class:`KalmanConsensusFilter` is the discrete Kalman consensus of Ren, Beard and Kingston
(2005), eqs. (4)-(5) (:func:`mascore.consensus.kalman_consensus_step`), with its covariance;
:class:`AverageConsensusFilter` the average with Metropolis weights on the delivered links
(Xiao, Boyd and Lall 2005), without one. Both implement the estimator protocol
(:mod:`mascore.estimation`) and declare their methods of the comparison's ``shared`` task.

Shapes: ``xi`` ``(..., N, m)``, ``P`` ``(..., N, m, m)``, ``G`` ``(..., N, N)`` (zero diagonal).
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from ._validation import Frozen, agent_index, check_positive, check_positive_int, require_finite
from ._validation import float_array as _float_array
from .consensus import kalman_consensus_step
from .estimation import Message, MethodSpec

__all__ = ["KalmanConsensusFilter", "AverageConsensusFilter", "METHODS"]


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
        """Agent i's step: eqs. (4)-(5) on itself and the neighbours it heard (the same kernel as :meth:`update`).

        Parameters
        ----------
        i : int
            The agent.
        own, messages
            From :meth:`agent_inputs`.

        Returns
        -------
        xi_i, P_i : ndarray
            Its estimate ``(m,)`` and covariance ``(m, m)`` after the step.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import KalmanConsensusFilter
        >>> f = KalmanConsensusFilter(0.1, 0.1)
        >>> xi, P, G = np.array([[0.0], [2.0], [4.0]]), np.ones((3, 1, 1)), graphs.path_graph(3)
        >>> x1, P1 = f.agent_step(1, *f.agent_inputs(xi, P, G, 1))
        >>> bool(np.allclose(x1, f.update(xi, P, G)[0][1]))
        True
        """
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
        """Agent i's row of ``W xi``.

        Parameters
        ----------
        i : int
            The agent.
        own, messages
            From :meth:`agent_inputs`.

        Returns
        -------
        tuple of ndarray
            Its estimate after the step ``(m,)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs
        >>> from mascore.consensus_filters import AverageConsensusFilter
        >>> f, xi, G = AverageConsensusFilter(), np.array([[0.0], [3.0], [6.0]]), graphs.path_graph(3)
        >>> bool(np.allclose(f.agent_step(0, *f.agent_inputs(xi, G, 0))[0], f.update(xi, G)[0]))
        True
        """
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
    MethodSpec("average-consensus", ("shared",), lambda scenario: AverageConsensusFilter(),
               lambda n, q, d, N: (float(n), float(2 * (d + 1) * n)), {"shared": ("O(d m)", "O(d m)")},
               lambda n, q, d, N: float(n + d * n), position=12),
    MethodSpec("ren-kc", ("shared",), lambda scenario: KalmanConsensusFilter(0.1, 0.1), _floats_flops_ren,
               {"shared": ("O(d m^3)", "O(d m^2)")}, lambda n, q, d, N: float((d + 1) * (n**2 + n)), _REN_NOT_APPLICABLE,
               position=13),
    MethodSpec("ren-kc-q0", ("shared",), lambda scenario: KalmanConsensusFilter(0.0, 0.0), _floats_flops_ren,
               {"shared": ("O(d m^3)", "O(d m^2)")}, lambda n, q, d, N: float((d + 1) * (n**2 + n)), position=14),
    # the knob Q = Omega swept further (mascore.compare.KNOBS)
    *(MethodSpec(f"ren-kc-q{q:g}", ("shared",), lambda scenario, q=q: KalmanConsensusFilter(q, q), _floats_flops_ren,
                 {"shared": ("O(d m^3)", "O(d m^2)")}, lambda n, q, d, N: float((d + 1) * (n**2 + n)),
                 position=14 + k) for k, q in enumerate((0.3, 0.6, 1.0), start=1)),
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
