"""Two filters on forwarded measurements: Olfati-Saber's Kalman-consensus filter and a set-membership filter.

Both start from :class:`~mascore.fusion.MeasurementForwardingFilter` (agent i hears the
measurements of its neighbourhood ``N_i ∪ {i}``) on the same
:class:`~mascore.sensor_network.SensorNetworkModel` as every filter of :mod:`mascore.fusion`,
with the same ``predict`` / ``update`` / ``run``, the same checks and the same per-agent protocol:

==========================================  ===========================================================
:class:`KalmanConsensusNetworkFilter`       forwarding, then one consensus step on the neighbours'
                                            predictions (Olfati-Saber 2007)
:class:`SetMembershipForwardingFilter`      forwarding into an outer ellipsoid per agent (set-membership,
                                            Bhattacharjee and Subbarao 2021's closed-form steps)
==========================================  ===========================================================

.. rubric:: References

- Olfati-Saber, R. (2007). Distributed Kalman filtering for sensor networks. Proc. 46th IEEE Conference on
  Decision & Control (CDC), 5492-5498.
- Olfati-Saber, R., Fax, J. A., Murray, R. M. (2007). Consensus and cooperation in networked multi-agent
  systems. Proc. IEEE 95(1), 215-233.
- Bhattacharjee, D., Subbarao, K. (2021). Set-membership filtering-based leader-follower synchronization of
  discrete-time linear multi-agent systems. ASME J. Dyn. Sys., Meas., Control 143(6).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from . import _ellipsoid_kernels as ellipsoid_kernels
from ._fusion_base import TASKS, NetworkFilter, spec_memory, spec_orders
from ._fusion_kernels import information_update, mix
from ._validation import check_covariance, check_positive, float_array, frozen_copy, require_finite
from .estimation import Message, MethodSpec
from .fusion_cost import filter_cost
from .sensor_network import SensorNetworkModel

__all__ = ["KalmanConsensusNetworkFilter", "SetMembershipForwardingFilter", "METHODS"]


class KalmanConsensusNetworkFilter(NetworkFilter):
    """The Kalman-consensus filter (KCF) of Olfati-Saber (2007), Algorithm 1.

    Per step, agent i corrects its prediction ``(xbar_i, P_i)`` with the measurements
    of ``J_i = N_i ∪ {i}`` (as :class:`~mascore.fusion.MeasurementForwardingFilter`), then adds a
    consensus term on the neighbours' predictions::

        u_j = H_j^T R_j^{-1} z_j,   U_j = H_j^T R_j^{-1} H_j,        j in J_i
        y_i = sum_j u_j,   S_i = sum_j U_j,   M_i = (P_i^{-1} + S_i)^{-1}
        x_i = xbar_i + M_i (y_i - S_i xbar_i) + gamma_i M_i sum_{j in N_i} (xbar_j - xbar_i),
        gamma_i = eps / (1 + ||M_i||),   ||X|| = (trace X^T X)^{1/2}  (Frobenius)
        P_i <- F M_i F^T + Q,   xbar_i <- F x_i                       (:meth:`predict`)

    The covariance returned is ``M_i``, the paper's: the error covariance of the
    forwarding estimate, not of ``x_i`` (the consensus term and the correlation it
    brings are left out), so it need not bound the error. With ``eps = 0`` the filter
    **is** :class:`~mascore.fusion.MeasurementForwardingFilter`, to the last bit. Olfati-Saber's Theorem 2
    (proven for the continuous-time form of the filter) states that without noise the
    estimation errors tend to zero and the agents' estimates reach a consensus. Each agent
    sends its ``q_i`` measurement numbers and its prediction ``xbar_i`` (n numbers) per step.

    Since ``||gamma_i M_i||_2 <= gamma_i ||M_i|| < eps``, the consensus step moves
    ``xbar_i`` toward its neighbours by less than ``eps`` of each difference, and
    ``eps <= 1 / d_max`` (``d_max`` the largest degree) keeps it a convex combination with
    matrix weights (``I - d_i gamma_i M_i`` and ``gamma_i M_i``, positive semidefinite, summing
    to the identity) for every ``M_i``: the step size of the Perron matrix ``I - eps L`` of
    Olfati-Saber, Fax and Murray (2007). The normalization makes the step ``eps M_i`` when
    ``||M_i||`` is small (a well-measured state), so on accurate sensing the term is weak.

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph.
    eps : float
        The consensus gain, ``>= 0`` (default 0.1 = one sampling time of the benchmark: the
        step of the continuous-time consensus term discretized; ``0``: forwarding).

    Attributes
    ----------
    eps : float
        As given.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion_forwarding, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.path_graph(3))
    >>> x, P = fusion_forwarding.KalmanConsensusNetworkFilter(model, eps=0.5).update([[3.0], [0.0], [0.0]], np.ones((3, 1, 1)),
    ...                                                            [3.0, 0.0, 0.0])
    >>> x[:, 0]                         # forwarding's (2, 0.75, 0), each pulled toward its neighbours' predictions
    array([1.625, 1.05 , 0.   ])
    """

    __slots__ = ("eps", "_S", "_links")
    _what = "Kalman-consensus update"

    def _args(self) -> tuple:
        return (self.eps,)

    def __init__(self, model: SensorNetworkModel, eps: float = 0.1) -> None:
        super().__init__(model)
        eps = check_positive(eps, "eps", "(the consensus gain of Olfati-Saber's KCF)", allow_zero=True)
        links = (model.adjacency > 0).astype(float)
        self._set(eps=eps, _S=frozen_copy(mix(model._neighbourhood, model.information_matrices, 2)),
                  _links=frozen_copy(links - np.diag(links.sum(axis=1))))  # row i: sum_j x_j - d_i x_i

    def _correct(self, x, P, z):
        xf, M = information_update(x, P, self._S, mix(self.model._neighbourhood,
                                                      self.model._information_vectors(z), 1))
        gamma = self.eps / (1.0 + np.linalg.norm(M, axis=(-2, -1)))  # (..., N)
        pull = (M @ mix(self._links, x, 1)[..., None])[..., 0]      # M_i sum_j (xbar_j - xbar_i)
        return xf + gamma[..., None] * pull, M

    def _messages(self, q, pair):
        return (Message("measurement z_i, to each neighbour", q),
                Message("prediction xbar_i", float(self.model.n_states)))

    def _agent_messages(self, own, xm, Pm, z, i):
        return (*super()._agent_messages(own, xm, Pm, z, i), xm[own["nbrs"]].copy())

    def _agent_step(self, i, own, messages):
        xf, M = self._incremental(own, messages[0])
        xbar = self.model.F @ own["x"]
        gamma = self.eps / (1.0 + np.linalg.norm(M))
        return xf + gamma * (M @ (messages[1].sum(axis=0) - len(own["nbrs"]) * xbar)), M


class SetMembershipForwardingFilter(NetworkFilter):
    """A set-membership filter on forwarded measurements: each agent bounds the state by an ellipsoid.

    Agent i holds the ellipsoid ``E(c_i, E_i) = {x : (x - c_i)^T E_i^{-1} (x - c_i) <= 1}``.
    Per step it predicts it (the trace-optimal outer ellipsoid of ``F E(c_i, E_i) + W_Q``,
    ``SetMembershipModel.predict``), then intersects it with the set
    the measurements of ``N_i ∪ {i}`` allow (the trace-optimal outer ellipsoid of the
    intersection with ``{x : (y_i - C_i x)^T W_i^{-1} (y_i - C_i x) <= 1}``, ``C_i`` and
    ``y_i`` the stacked ``H_j``, ``z_j``: ``SetMembershipModel.correct``,
    Bhattacharjee and Subbarao 2021, eqs. (2), (4), (6)-(8) in closed form). The shapes and gains
    depend on the shapes only, not on the data: they are computed once per agent and step
    and the gain applied to every run. Each agent sends its ``q_i`` measurement numbers, as
    :class:`~mascore.fusion.MeasurementForwardingFilter` (whose Kalman update it replaces by the set update).

    **Bounds of Gaussian noise.** The model's noise is Gaussian; a set-membership filter needs
    sets. The bounds are the covariance ellipsoids scaled by chi-square quantiles at
    `confidence`: ``W_Q = chi2_n(c) Q`` for the process noise (n numbers),
    ``W_i = chi2_{p_i}(c) blockdiag(R_j, j in N_i ∪ {i})`` for agent i's ``p_i`` stacked
    measurements, and the initial set :meth:`initial_shape` ``chi2_n(c) P0``: each holds its
    noise with probability c at one step. So the ellipsoid is **not** a guaranteed bound:
    a step whose noise leaves its set can leave the true state outside, and what the set
    delivers is measured (its containment rate), not promised. Under noise truly bounded by
    those sets it is a guaranteed bound.

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph; Q positive definite.
    confidence : float
        c in (0, 1), the probability mass of each bound (default 0.997, the benchmark's
        ``sm_confidence``).

    Attributes
    ----------
    confidence : float
        c.

    Raises
    ------
    ValueError
        A confidence outside (0, 1), or a singular Q.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion_forwarding, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.01]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.path_graph(3))
    >>> smf = fusion_forwarding.SetMembershipForwardingFilter(model)
    >>> c, E = smf.run(np.zeros(1), smf.initial_shape(np.eye(1)), np.zeros((20, 3)))
    >>> bool(E[-1, 0, 0, 0] > E[-1, 1, 0, 0])                 # the end agent hears two measurements, the middle three
    True
    """

    __slots__ = ("confidence", "_motion", "_groups", "_rows")
    _what = "set-membership forwarding update"
    _per_run_sensing = False  # its shapes and gains are computed once per agent and step, for every run

    def _args(self) -> tuple:
        return (self.confidence,)

    def __init__(self, model: SensorNetworkModel, confidence: float = 0.997) -> None:
        from scipy.stats import chi2

        from .set_membership import SetMembershipModel

        super().__init__(model)
        c = check_positive(confidence, "confidence", "(the probability mass of each noise bound)")
        if c >= 1.0:
            raise ValueError(f"confidence must lie in (0, 1) (the probability mass of each noise bound); got {confidence!r}")
        n = model.n_states
        if np.linalg.eigvalsh(model.Q).min() <= 0:
            raise ValueError("model.Q must be positive definite for a set-membership filter (its noise bound is an "
                             "ellipsoid of shape chi2_n(c) Q); got a singular Q")
        motion = SetMembershipModel(A=model.F, G=np.eye(n), Q=float(chi2.ppf(c, n)) * model.Q)
        rows = []  # agent i's rows of the stacked measurement: those of N_i and i, in agent order
        for i in range(model.n_agents):
            hood = np.flatnonzero(model._neighbourhood[i])
            rows.append(frozen_copy(np.concatenate([np.arange(model.n_measurements)[model._slices[j]] for j in hood]),
                                    int))
        groups = []  # the agents with p stacked measurements, p > 0: their C_i (g, p, n) and W_i (g, p, p), at once
        for p in sorted({r.size for r in rows} - {0}):
            agents = np.array([i for i, r in enumerate(rows) if r.size == p])
            idx = np.stack([rows[i] for i in agents])
            W = float(chi2.ppf(c, p)) * model.R_stacked[idx[:, :, None], idx[:, None, :]]  # R_j positive definite
            groups.append((frozen_copy(agents, int), frozen_copy(idx, int), frozen_copy(model.H_stacked[idx]),
                           frozen_copy(W)))
        self._set(confidence=c, _motion=motion, _groups=tuple(groups), _rows=tuple(rows))

    def initial_shape(self, P0: ArrayLike) -> np.ndarray:
        """The initial set's shape for an initial error of covariance `P0`: ``chi2_n(c) P0``.

        Parameters
        ----------
        P0 : (..., n, n) array_like
            The covariance of the initial error, symmetric positive definite.

        Returns
        -------
        (..., n, n) ndarray
            The shape matrix holding a Gaussian initial error with probability c.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import compare, fusion_forwarding
        >>> smf = fusion_forwarding.SetMembershipForwardingFilter(compare.target_model(4))
        >>> round(float(smf.initial_shape(np.eye(4))[0, 0]), 3)
        16.014
        """
        from scipy.stats import chi2

        P0 = check_covariance(float_array(P0, "P0"), "P0", size=self.model.n_states, definite=True)
        return float(chi2.ppf(self.confidence, self.model.n_states)) * P0

    def predict(self, x: ArrayLike, P: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Every agent's predicted set: centre ``F c``, the trace-optimal outer shape of ``F E F^T + W_Q`` (eq. (8)).

        Parameters
        ----------
        x : (..., N, n) array_like
            The centres.
        P : (..., N, n, n) array_like
            The shape matrices, positive definite.

        Returns
        -------
        x_pred, P_pred : ndarray
            The predicted centres and shapes, same shapes.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion_forwarding, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.01]], [[[1.0]]] * 2, [[[1.0]]] * 2, graphs.path_graph(2))
        >>> x, E = fusion_forwarding.SetMembershipForwardingFilter(model).predict(np.ones((2, 1)), np.ones((2, 1, 1)))
        >>> x[:, 0], np.round(E[:, 0, 0], 4)                       # (1 + sqrt(chi2_1(0.997) 0.01))^2
        (array([1., 1.]), array([1.6816, 1.6816]))
        """
        x, P = self._check_xP(x, P)
        require_finite(x, "x")  # the shape's prediction does not see the centre
        require_finite(P, "P")
        _, shape = self._motion.predict(np.zeros(self.model.n_states), P)
        return x @ self.model.F.T, shape

    def _set_update(self, P: np.ndarray, group: tuple) -> tuple[np.ndarray, np.ndarray]:
        """The shapes and gains of one group's agents, from their shapes ``(..., g, n, n)`` alone (eqs. (6)-(7))."""
        _, idx, C, W = group
        h, m = ellipsoid_kernels.trace_profile(P, C, W)
        t = ellipsoid_kernels.newton_trace(h, m, 1e-13, 100)
        _, shape, L = ellipsoid_kernels.gain_form(np.zeros(P.shape[:-1]), P, C, np.zeros(idx.shape), W, t, False)
        return shape, L

    def _correct(self, x, P, z):
        batch = np.broadcast_shapes(x.shape[:-2], z.shape[:-1])
        x_new = np.array(np.broadcast_to(x, (*batch, *x.shape[-2:])))
        P_new = np.array(P)
        for group in self._groups:
            agents, idx, C, _ = group
            P_new[..., agents, :, :], L = self._set_update(P[..., agents, :, :], group)
            nu = z[..., idx] - np.einsum("gpn,...gn->...gp", C, x_new[..., agents, :])
            x_new[..., agents, :] += np.einsum("...gnp,...gp->...gn", L, nu)  # eq. (2), every run
        return x_new, P_new

    def _agent_step(self, i, own, messages):
        _, shape = self._motion.predict(np.zeros(self.model.n_states), own["P"])
        c = self.model.F @ own["x"]
        if not self._rows[i].size:  # nothing sensed in the neighbourhood: the prediction stands
            return c, shape
        agents, _, C, W = next(g for g in self._groups if i in g[0])
        k = int(np.flatnonzero(agents == i)[0])
        zs = list(messages[0])
        zs.insert(own["index"], own["z"])
        shape, L = self._set_update(shape[None], (None, self._rows[i][None], C[k:k + 1], W[k:k + 1]))
        return c + L[0] @ (np.concatenate(zs) - C[k] @ c), shape[0]


def _kcf_cost(n: int, q: int, d: int, n_agents: int) -> tuple[float, float]:
    """Forwarding's count (:func:`~mascore.fusion_cost.filter_cost`), plus the prediction sent and the consensus term.

    The term: the sum of d differences (``d n``), its product with M (``2 n^2``), the norm of M (``2 n^2``).
    """
    c = filter_cost("measurement-forwarding", n=n, q=q, degree=d, n_agents=n_agents)
    return c.floats_sent + n, c.flops + d * n + 4 * n**2


def _kcf_spec(name: str, eps: float, position: float, role: str = "recipe") -> MethodSpec:
    """Olfati-Saber's KCF at consensus gain `eps` (its knob)."""
    return MethodSpec(name, TASKS, lambda model: KalmanConsensusNetworkFilter(model, eps), _kcf_cost,
                      spec_orders(("O(d q n + n^3)", "O(n^2 + d n)"), ("O(N^3)", "O(N^2)")), spec_memory(),
                      position=position, role=role, family="kcf", setting=eps)


def _sm_forwarding_cost(n: int, q: int, d: int, n_agents: int) -> tuple[float, float]:
    """Forwarding's floats; flops: the trace-optimal sum (``4 n^3``), the intersection's Cholesky factor and
    eigen-decomposition of the n x n prior (``n^3 / 3 + 9 n^3``), its gain and Joseph-form shape
    (``2 p n^2 + 2 p^2 n + 8/3 p^3 + 6 n^3``) for the ``p = (d + 1) q`` stacked measurements, and the centre.
    """
    c = filter_cost("measurement-forwarding", n=n, q=q, degree=d, n_agents=n_agents)
    p = (d + 1) * q
    return c.floats_sent, 4 * n**3 + (1 / 3 + 9 + 6) * n**3 + 2 * p * n**2 + 2 * p**2 * n + 8 / 3 * p**3 + 2 * p * n


#: Olfati-Saber's Kalman-consensus filter at its default gain, the set-membership filter on forwarded
#: measurements (its containment in place of the NEES), then the KCF's gain swept (knob settings: 0.5 = 1 / d_max
#: on the ring, the largest that keeps its consensus step a convex combination for every covariance).
METHODS = (
    _kcf_spec("kcf", 0.1, 10.5),
    MethodSpec("sm-forwarding", TASKS, SetMembershipForwardingFilter, _sm_forwarding_cost,
               spec_orders(("O(n^3 + d^3 q^3)", "O(n^2 + d q)"), ("O(N^3)", "O(N^2)")), spec_memory(), position=10.6),
    *(_kcf_spec(f"kcf-eps{eps:g}", eps, 19 + j, "knob") for j, eps in enumerate((0.01, 0.5))),
)
