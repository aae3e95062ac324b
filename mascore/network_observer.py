"""The Vlahakis and Halikias observer in discrete time on a team: one class, stepped per agent, and its specs.

:class:`DiscreteNetworkObserver` is the distributed observer of :mod:`mascore.observers`
(eq. (3) of the paper), discretized by forward Euler and run on N agents at once: what the
comparison's team task runs. Its gains come from the continuous-time design of
:func:`mascore.observers.distributed_observer`; ``METHODS`` declares it for the team task.
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from ._validation import Frozen, agent_index, as_matrix, check_adjacency, finite_result, frozen_copy, step_arrays
from ._validation import check_square as _square
from .estimation import Message, MethodSpec, protocol_docs

__all__ = ["DiscreteNetworkObserver", "METHODS"]


# --------------------------------------------------------------------------------------------
# the observer in discrete time, on a team (the comparison's estimator)


@protocol_docs
class DiscreteNetworkObserver(Frozen):
    """The distributed observer of Vlahakis and Halikias, discretized (forward Euler), on N agents at once.

    Agent i measures its own output ``z_ii = C x_i + nu_i`` and, on each link delivered at
    the step, the output of neighbour j, ``z_ij = C x_j + nu_ij``; it receives the output
    estimates ``C x_hat_j`` its neighbours broadcast. Its correction is eq. (3) of the paper
    in discrete time::

        x_i <- x_i + G ((z_ii - C x_i) + Phi sum_j a_ij s_ij ((z_ii - z_ij) - C (x_i - x_j))),

    with ``G = dt L`` the discretized gain and ``s_ij`` 1 if the link delivered; the
    prediction is ``x_i <- A x_i + B u_i``. The gains come from :func:`mascore.observers.distributed_observer`
    (the design), so this object holds no estimate: each step returns a new one.

    Parameters
    ----------
    gain : (n, p) array_like
        G: the correction's gain on the output innovation.
    coupling : float
        Phi, the gain of the relative-output term.
    adjacency : (N, N) array_like
        The weights ``a_ij`` of the graph.
    A : (n, n) array_like
        The discrete-time dynamics of one agent.
    B : (n, k) array_like
        Its input matrix.
    C : (p, n) array_like
        Its output matrix.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import graphs, network_observer
    >>> obs = network_observer.DiscreteNetworkObserver([[0.5], [0.1]], 0.2, graphs.ring_graph(3), [[1, 0.1], [0, 1]],
    ...                                         [[0.0], [0.1]], [[1.0, 0.0]])
    >>> x = np.zeros((1, 3, 2))
    >>> z = np.ones((1, 3, 3, 1))                          # every output measured as 1
    >>> obs.update(x, z, np.ones((1, 3, 3)))[0, :, 0]      # G (z_ii - C x_i): the relative terms cancel
    array([0.5, 0.5, 0.5])
    """

    __slots__ = ("gain", "coupling", "adjacency", "A", "B", "C")

    def __init__(self, gain: ArrayLike, coupling: float, adjacency: ArrayLike, A: ArrayLike, B: ArrayLike,
                 C: ArrayLike) -> None:
        A = _square(A, "A")
        n = A.shape[0]
        C = as_matrix(C, "C")
        if C.shape[1] != n:
            raise ValueError(f"C must have n = {n} columns (the state of A); got shape {C.shape}")
        gain = as_matrix(gain, "gain")
        if gain.shape != (n, C.shape[0]):
            raise ValueError(f"gain must be (n, p) = ({n}, {C.shape[0]}); got shape {gain.shape}")
        B = as_matrix(B, "B")
        if B.shape[0] != n:
            raise ValueError(f"B must have n = {n} rows; got shape {B.shape}")
        if isinstance(coupling, bool) or not isinstance(coupling, (int, float, np.integer, np.floating)) \
                or not np.isfinite(coupling):
            raise ValueError(f"coupling must be a finite number; got {coupling!r}")
        self._set(gain=frozen_copy(gain), coupling=float(coupling), adjacency=frozen_copy(check_adjacency(adjacency)),
                  A=frozen_copy(A), B=frozen_copy(B), C=frozen_copy(C))

    def _args(self) -> tuple:
        return (self.gain, self.coupling, self.adjacency, self.A, self.B, self.C)

    def update(self, x_hat: np.ndarray, z: np.ndarray, links: np.ndarray) -> np.ndarray:
        """Every agent's correction, batched over runs.

        Parameters
        ----------
        x_hat : (R, N, n) ndarray
            The estimates.
        z : (R, N, N, p) ndarray
            ``z[r, i, j]``: agent i's measurement of agent j's output (``z[r, i, i]`` its own).
        links : (R, N, N) ndarray
            1 where the link (i, j) delivered at this step, else 0.

        Returns
        -------
        (R, N, n) ndarray
            The corrected estimates.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, network_observer
        >>> obs = network_observer.DiscreteNetworkObserver([[0.5], [0.1]], 0.2, graphs.ring_graph(3), [[1, 0.1], [0, 1]],
        ...                                         [[0.0], [0.1]], [[1.0, 0.0]])
        >>> obs.update(np.zeros((1, 3, 2)), np.ones((1, 3, 3, 1)), np.ones((1, 3, 3))).shape
        (1, 3, 2)
        """
        x_hat, z, links = self._inputs(x_hat=x_hat, z=z, links=links)
        N = x_hat.shape[-2]
        p_hat = x_hat @ self.C.T
        own_z = z[:, np.arange(N), np.arange(N)]
        delivered = self.adjacency * links              # links delivered at this step, (R, N, N)
        rel_meas = own_z[:, :, None] - z                # y_i - y_j measured
        rel_est = p_hat[:, :, None] - p_hat[:, None]
        coupling = np.einsum("rij,rijd->rid", delivered, rel_meas - rel_est)
        innovation = (own_z - p_hat) + self.coupling * coupling
        return finite_result("observer update", x_hat + innovation @ self.gain.T,
                             inputs=((x_hat, "x_hat"), (z, "z"), (links, "links")))

    def _inputs(self, runs: bool = True, **named) -> tuple[np.ndarray, ...]:
        """A step's inputs as finite float arrays of this observer's sizes (with a leading run axis if `runs`)."""
        N = len(self.adjacency)
        sizes = {"x_hat": (N, self.A.shape[0]), "u": (N, self.B.shape[1]), "z": (N, N, self.C.shape[0]),
                 "links": (N, N)}
        arrays = step_arrays(**named)
        for (name, arr) in zip(named, arrays):
            if arr.shape[runs:] != sizes[name] or arr.ndim != len(sizes[name]) + runs:
                raise ValueError(f"{name} must have shape ({'R, ' if runs else ''}"
                                 f"{', '.join(map(str, sizes[name]))}); got {arr.shape}")
        return arrays

    def predict(self, x_hat: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The prediction ``x_i <- A x_i + B u_i`` of every agent.

        Parameters
        ----------
        x_hat : (R, N, n) ndarray
            The estimates.
        u : (R, N, k) ndarray
            The inputs applied.

        Returns
        -------
        (R, N, n) ndarray
            The predictions.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, network_observer
        >>> obs = network_observer.DiscreteNetworkObserver([[0.5], [0.1]], 0.2, graphs.ring_graph(3), [[1, 0.1], [0, 1]],
        ...                                         [[0.0], [0.1]], [[1.0, 0.0]])
        >>> obs.predict(np.ones((1, 3, 2)), np.zeros((1, 3, 1)))[0, 0]
        array([1.1, 1. ])
        """
        x_hat, u = self._inputs(x_hat=x_hat, u=u)
        return finite_result("observer prediction", x_hat @ self.A.T + u @ self.B.T, inputs=((x_hat, "x_hat"), (u, "u")))

    def agent_inputs(self, x_hat: np.ndarray, z: np.ndarray, u: np.ndarray, i: int) -> tuple[dict, tuple]:
        """Agent i's own data (its estimate, its measurements, its input) and its neighbours' broadcast outputs.

        Parameters
        ----------
        x_hat : (N, n) ndarray
            The team's estimates before the step (one run).
        z : (N, N, p) ndarray
            The measurements of the step.
        u : (N, k) ndarray
            The inputs applied.
        i : int
            The agent.

        Returns
        -------
        own : dict
            ``x``, ``z`` (its own output measurement), ``z_nbrs`` (its measurements of its neighbours),
            ``u``, ``a`` (its weights of its neighbours).
        messages : tuple
            One round: the neighbours' broadcast output estimates ``C x_hat_j``, ``(d, p)``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import graphs, network_observer
        >>> obs = network_observer.DiscreteNetworkObserver([[0.5], [0.1]], 0.2, graphs.ring_graph(3), [[1, 0.1], [0, 1]],
        ...                                         [[0.0], [0.1]], [[1.0, 0.0]])
        >>> own, messages = obs.agent_inputs(np.zeros((3, 2)), np.ones((3, 3, 1)), np.zeros((3, 1)), 0)
        >>> messages[0].shape                                  # two neighbours, one output each
        (2, 1)
        """
        x_hat, z, u = self._inputs(False, x_hat=x_hat, z=z, u=u)
        i = agent_index(i, len(self.adjacency))
        nbrs = np.flatnonzero(self.adjacency[i])
        own = {"x": x_hat[i].copy(), "z": z[i, i].copy(), "z_nbrs": z[i, nbrs].copy(), "u": u[i].copy(),
               "a": self.adjacency[i, nbrs].copy()}
        return own, ((x_hat[nbrs] @ self.C.T).copy(),)

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray]:
        # correction with its neighbours' output estimates, then prediction: (x_i,), (n,)
        p = self.C @ own["x"]
        coupling = own["a"] @ ((own["z"] - own["z_nbrs"]) - (p - messages[0]))
        xu = own["x"] + self.gain @ ((own["z"] - p) + self.coupling * coupling)
        return (self.A @ xu + self.B @ own["u"],)

    def messages(self, i: int = 0) -> tuple:
        # its output estimate C x_hat_i, p floats, broadcast
        return (Message("output estimate C x_i", float(self.C.shape[0])),)


# --------------------------------------------------------------------------------------------
# the methods of the team task (mascore.compare's own-state rendezvous, mascore.agent_cost)

#: Why the Vlahakis observer does not apply elsewhere (the tables show it).
_VLAHAKIS_NOT_APPLICABLE = MappingProxyType({
    "target": "an observer of each agent's own state, coupled by relative outputs; there is no common target",
    "localization": "needs every agent to measure its own output (the Q1 term); here only the anchors do",
    "switching": "its gains come from an LMI over the eigenvalues of one fixed Laplacian (eqs. (56)-(62)); for a "
    "graph that changes at every step, often disconnected, the paper gives no design and no stability guarantee",
})


def _team_observer(phi: float | None):
    """``build(team, x_hat0)``: the observer with the scenario's design of LMI (56)-(62) at coupling `phi`.

    ``team.vlahakis_design(phi)`` gives the discrete gain, the coupling ``Phi`` and the output matrix of the
    scenario (its noise weights and sampling time); None is the LMI's own ``Phi``.
    """
    def build(team, x_hat0: np.ndarray) -> DiscreteNetworkObserver:
        gain, Phi, C = team.vlahakis_design(phi)
        return DiscreteNetworkObserver(gain, Phi, team.adjacency, team.A, team.B, C)
    return build


def _vlahakis_spec(name: str, phi: float | None, position: float, role: str = "recipe") -> MethodSpec:
    return MethodSpec(name, ("team",), _team_observer(phi),
                      lambda n, q, d, N: (float(n), float(2 * n**2 + 2 * n * 2 + 4 * d + 2 * n)),
                      {"team": ("O(n^2 + d n)", "O(n + d n)")}, lambda n, q, d, N: float(n + d * n),
                      _VLAHAKIS_NOT_APPLICABLE if phi is None else {"switching": _VLAHAKIS_NOT_APPLICABLE["switching"]},
                      position=position, role=role, family="vlahakis", setting=phi)


#: The Vlahakis observer at the LMI's coupling, and across the interval where its program is optimal on the
#: comparison's ring of 8 (the knob, :func:`mascore.compare.vlahakis_profile`): its ends -0.1 and 1, and 0, 0.5.
METHODS = (_vlahakis_spec("vlahakis", None, 5), _vlahakis_spec("vlahakis-phi0", 0.0, 6, "variant"),
           _vlahakis_spec("vlahakis-phi1", 1.0, 7, "variant"), _vlahakis_spec("vlahakis-phi-0.1", -0.1, 7.1, "knob"),
           _vlahakis_spec("vlahakis-phi0.5", 0.5, 7.2, "knob"))
