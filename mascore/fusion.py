"""The field's standard distributed filters and fusion rules, on one sensor network.

N agents track one common target ``x[k+1] = F x[k] + w[k]``, ``w ~ N(0, Q)``;
agent i senses ``z_i[k] = H_i x[k] + v_i[k]``, ``v_i ~ N(0, R_i)`` (``q_i``
numbers; ``q_i = 0`` for an agent that does not sense), the noises independent
across agents and time. A :class:`~mascore.sensor_network.SensorNetworkModel` holds this sensing and
an undirected communication graph, checked once; every filter below is built on
the same model, so every method sees exactly the same sensing.

=======================================  ==========================================================
:class:`CentralizedFilter`               all measurements at one node: the bound (Kalman 1960)
:class:`MeasurementForwardingFilter`     own and neighbours' measurements, one hop (exact local KF)
:class:`ConsensusOnInformationFilter`    L consensus steps on the information pair (Battistelli and
                                         Chisci 2014); with ``novelty_weight="N"`` the hybrid HCMCI
                                         of Battistelli et al. (2015)
:class:`InformationConsensusFilter`      information-weighted consensus (Kamal, Farrell and
                                         Roy-Chowdhury 2013)
:class:`DiffusionKalmanFilter`           incremental update, then diffusion of the estimates
                                         (Cattivelli and Sayed 2010)
:class:`CovarianceIntersectionFilter`    incremental update, then covariance intersection of the
                                         neighbours' estimates (Hu, Xie and Zhang 2012)
:mod:`mascore.fusion_forwarding`         forwarding, then a consensus step (Olfati-Saber's Kalman-consensus
                                         filter) or a set update (an outer ellipsoid per agent)
:func:`covariance_intersection`          fusion under unknown correlation (Julier and Uhlmann 1997)
:func:`error_covariance`                 a filter's exact error covariance (no Monte Carlo)
:mod:`mascore.fusion_cost`               floats sent and flops per agent per step
:mod:`mascore.fusion_links`              packet loss, one-step latency and send-on-delta messages
=======================================  ==========================================================

Shapes: every distributed filter's state is ``x`` of shape ``(..., N, n)`` and
``P`` of shape ``(..., N, n, n)`` (agent i's mean and covariance in row i; the
leading axes are independent runs, e.g. Monte Carlo); the centralized filter's is
``(..., n)``, ``(..., n, n)``. A measurement is the stacked vector
``z = (z_1, ..., z_N)`` of shape ``(..., sum q_i)``. Units are those of the
state and the measurements; the filters add none.

Each filter has ``predict(x, P)`` (``x- = F x``, ``P- = F P F^T + Q``, by
:func:`mascore.kalman.predict`), ``update(x, P, z)`` (the correction with its
communication round(s)) and ``run(x0, P0, z)``. The model is checked once, when
it is built (shapes, finite entries, symmetric positive (semi)definite
covariances, a symmetric graph) and keeps read-only copies; a step checks only
the shapes of what it is given, that its covariances and measurements are finite
(one pass over each) and that its result is finite (naming the input that holds
a NaN or inf). The message and pair methods that :mod:`mascore.fusion_links` calls
per step check their inputs the same way. Filters hold no estimates and no caches: a filter
object is immutable and safe to share between threads. Randomness
(``SensorNetworkModel.simulate``) comes only from the generator passed in.

References
----------
- Battistelli, G., Chisci, L. (2014). Kullback-Leibler average, consensus on probability densities, and
  distributed state estimation with guaranteed stability. Automatica 50(3), 707-718.
- Battistelli, G., Chisci, L., Mugnai, G., Farina, A., Graziano, A. (2015). Consensus-based linear and
  nonlinear filtering. IEEE Trans. Automatic Control 60(5), 1410-1415.
- Kamal, A. T., Farrell, J. A., Roy-Chowdhury, A. K. (2013). Information weighted consensus filters and
  their application in distributed camera networks. IEEE Trans. Automatic Control 58(12), 3112-3125.
- Cattivelli, F. S., Sayed, A. H. (2010). Diffusion strategies for distributed Kalman filtering and
  smoothing. IEEE Trans. Automatic Control 55(9), 2069-2084.
- Hu, J., Xie, L., Zhang, C. (2012). Diffusion Kalman filtering based on covariance intersection. IEEE
  Trans. Signal Processing 60(2), 891-902.
- Julier, S. J., Uhlmann, J. K. (1997). A non-divergent estimation algorithm in the presence of unknown
  correlations. Proc. American Control Conference, 2369-2373.
- Xiao, L., Boyd, S., Lall, S. (2005). A scheme for robust distributed sensor fusion based on average
  consensus. Proc. IPSN, 63-70 (Metropolis weights).

Consensus weights are Metropolis weights (:func:`~mascore.sensor_network.metropolis_weights`), symmetric
and doubly stochastic; L consensus steps are applied as the precomputed power
``W^L`` (the same numbers as L rounds, up to rounding).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from . import kalman
from ._fusion_base import TASKS, centre_memory, check_stochastic, pair_list, spec_cost, spec_memory, spec_orders
from ._fusion_base import NetworkFilter as _NetworkFilter
from ._fusion_kernels import (
    broadcast_batch,
    ci_weights,
    consensus_agent,
    consensus_rounds,
    from_information,
    information_pair,
    information_update,
    mix,
    psd_sqrt,
)
from ._fusion_steps import step_graphs, step_sensing, step_values
from ._validation import (
    check_covariance,
    check_fits_in_memory,
    check_positive,
    check_positive_int,
    finite_result,
    float_array,
    frozen_copy,
    require_finite,
    symmetric_part,
)
from .estimation import Message, MethodSpec
from .fusion_forwarding import KalmanConsensusNetworkFilter, SetMembershipForwardingFilter  # noqa: F401 (their old home)
from .sensor_network import SensorNetworkModel

__all__ = [
    "CentralizedFilter",
    "MeasurementForwardingFilter",
    "ConsensusOnInformationFilter",
    "InformationConsensusFilter",
    "DiffusionKalmanFilter",
    "CovarianceIntersectionFilter",
    "covariance_intersection",
    "error_covariance",
    "track",
    "graph_diameter",
    "safe_novelty_weight",
    "METHODS",
]


# --------------------------------------------------------------------------------------------
# the filters



class CentralizedFilter(_NetworkFilter):
    """The centralized Kalman filter: one node fuses every agent's measurement (the bound).

    The update is :func:`mascore.kalman.update` with the stacked model
    ``H = [H_1; ...; H_N]``, ``R = blockdiag(R_i)`` (Kalman 1960; in information
    form ``P+^{-1} = P-^{-1} + sum_i H_i^T R_i^{-1} H_i``). Its state is one mean
    ``(..., n)`` and covariance ``(..., n, n)``, not one per agent. Each agent
    sends its ``q_i`` numbers to the centre.

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing (the graph is not used).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 4, [[[1.0]]] * 4, graphs.ring_graph(4))
    >>> x, P = fusion.CentralizedFilter(model).run([0.0], [[1.0]], np.ones((1, 4)))
    >>> x[-1], P[-1]                                           # prior 1 and four unit measurements: 1/5
    (array([0.8]), array([[0.2]]))
    """

    __slots__ = ()
    _what = "centralized update"
    _per_agent = False

    def _messages(self, q, pair):
        return (Message("measurement z_i, to the centre", q),
                Message("the estimate x, from the centre back to agent i", float(self.model.n_states)))

    def _correct(self, x, P, z):
        return kalman.update(x, P, z, self.model._kf)


class MeasurementForwardingFilter(_NetworkFilter):
    """Measurement forwarding: each agent fuses its own and its neighbours' measurements, one hop.

    Agent i's update is the exact Kalman update on the measurements of
    ``N_i ∪ {i}`` (information form)::

        P_i+^{-1} = P_i-^{-1} + sum_{j in N_i ∪ {i}} H_j^T R_j^{-1} H_j,
        x_i+ = x_i- + P_i+ sum_j H_j^T R_j^{-1} (z_j - H_j x_i-),

    computed as ``P_i+ = (I + P_i- S_i)^{-1} P_i-`` (no inverse of ``P_i-``). Its
    covariance is the true error covariance of its estimate (a local Kalman filter
    with neighbour data); on a complete graph it is the centralized filter. Each
    agent sends its ``q_i`` measurement numbers per step (the ``H_j``, ``R_j`` of
    neighbours are known beforehand).

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 4, [[[1.0]]] * 4, graphs.path_graph(4))
    >>> x, P = fusion.MeasurementForwardingFilter(model).run([0.0], [[1.0]], np.ones((1, 4)))
    >>> P[-1, :, 0, 0]                                         # end agents hear 2 measurements, inner ones 3
    array([0.33333333, 0.25      , 0.25      , 0.33333333])
    """

    __slots__ = ("_S",)
    _what = "measurement-forwarding update"

    def __init__(self, model: SensorNetworkModel) -> None:
        super().__init__(model)
        self._set(_S=frozen_copy(mix(model._neighbourhood, model.information_matrices, 2)))

    def _correct(self, x, P, z):
        i = mix(self.model._neighbourhood, self.model._information_vectors(z), 1)
        return information_update(x, P, self._S, i)


class DiffusionKalmanFilter(_NetworkFilter):
    """The diffusion Kalman filter of Cattivelli and Sayed (2010), computed in information form.

    Step 1, incremental update: agent i corrects its prediction with the
    measurements of ``N_i ∪ {i}`` (the update of :class:`MeasurementForwardingFilter`),
    giving ``psi_i`` and ``P_i``. Step 2, diffusion: ``x_i = sum_l c_{l,i} psi_l``
    over ``l in N_i ∪ {i}``, with convex weights (``sum_l c_{l,i} = 1``). The
    covariance returned is the paper's ``P_i`` of step 1: it is **not** the
    error covariance of the diffused estimate ``x_i`` (Cattivelli and Sayed
    analyse the diffused estimate's error separately); compare it with the
    error, do not take it as a bound. On a complete graph it equals the
    centralized filter (from a common prior). Each agent sends its ``q_i``
    measurement numbers and its ``n``-vector ``psi_i`` per step.

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph.
    weights : "metropolis" or (N, N) array_like
        Diffusion weights as a row-stochastic matrix ``C[i, l] = c_{l,i}``:
        non-negative, rows summing to 1, zero off the graph and the diagonal.
        Default: the model's Metropolis weights.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.path_graph(3))
    >>> dkf = fusion.DiffusionKalmanFilter(model)
    >>> x, P = dkf.update(np.zeros((3, 1)), np.ones((3, 1, 1)), [3.0, 0.0, 0.0])
    >>> x[:, 0]                                   # psi = (1, 0.75, 0), then mixed with the Metropolis weights
    array([0.91666667, 0.58333333, 0.25      ])
    """

    __slots__ = ("_S", "weights")
    _what = "diffusion Kalman update"

    def _args(self) -> tuple:
        return (self.weights,)

    def __init__(self, model: SensorNetworkModel, weights: str | ArrayLike = "metropolis") -> None:
        super().__init__(model)
        if isinstance(weights, str):
            if weights != "metropolis":
                raise ValueError(f"weights must be 'metropolis' or an (N, N) matrix; got {weights!r}")
            C = model.weights
        else:
            C = check_stochastic(weights, "weights", model)
        self._set(weights=frozen_copy(C), _S=frozen_copy(mix(model._neighbourhood, model.information_matrices, 2)))

    def _correct(self, x, P, z):
        i = mix(self.model._neighbourhood, self.model._information_vectors(z), 1)
        psi, P_new = information_update(x, P, self._S, i)
        return mix(self.weights, psi, 1), P_new

    @property
    def exchanges(self) -> int:
        """2: the measurements, then the incremental estimates computed from them."""
        return 2

    def _messages(self, q, pair):
        return (Message("measurement z_i", q), Message("incremental estimate psi_i", float(self.model.n_states)))

    def _agent_messages(self, own, xm, Pm, z, i):
        psi, _ = information_update(xm, Pm, self._S, mix(self.model._neighbourhood,
                                                     self.model._information_vectors(z), 1))
        return (*super()._agent_messages(own, xm, Pm, z, i), psi[own["nbrs"]].copy())

    def _agent_step(self, i, own, messages):
        psi, Pn = self._incremental(own, messages[0])
        return own["w_self"] * psi + own["w_nb"] @ messages[1], Pn

    def _mixing_weights(self):
        return self.weights


class ConsensusOnInformationFilter(_NetworkFilter):
    """Consensus on information (CI) of Battistelli and Chisci (2014); the hybrid HCMCI of Battistelli et al. (2015).

    Per step, with ``Omega_i- = P_i-^{-1}`` and ``q_i- = Omega_i- x_i-``
    (the HCMCI of Battistelli, Chisci, Mugnai, Farina and Graziano 2015)::

        prior pair:    (Omega_i, q_i)^0 = (Omega_i-, q_i-)
        novelty pair:  (dOmega_i, dq_i)^0 = (H_i^T R_i^{-1} H_i, H_i^T R_i^{-1} z_i)
        L consensus steps on both:  (.)_i^{l+1} = sum_j pi_ij (.)_j^l       (Metropolis pi)
        Omega_i+ = Omega_i^L + w dOmega_i^L,   q_i+ = q_i^L + w dq_i^L,
        P_i+ = Omega_i+^{-1},  x_i+ = P_i+ q_i+.

    With ``novelty_weight`` ``w = 1`` this is CI (Battistelli and Chisci 2014,
    local correction, then L steps on the information
    pair; consensus is linear, so mixing the two pairs separately is the same).
    CI is consistent for every ``L >= 0`` (``L = 0``: each agent's local filter):
    a convex combination of consistent information pairs is consistent whatever
    their correlation (the covariance-intersection argument of the paper),
    so ``P_i+ >= E[e_i e_i^T]`` in the PSD sense. As ``L -> inf`` on a connected
    graph CI tends to the centralized filter with every ``R_i`` multiplied by N
    (each agent keeps 1/N of the team's measurement information).

    With ``w = N`` (``novelty_weight="N"``, HCMCI) the novelty is rescaled so
    that ``L -> inf`` gives the centralized filter itself. Consistency then holds
    if ``w [W^L]_ij <= 1`` for every agent i and every sensing agent j (the
    measurement part of the argument above: agent j's noise enters agent i's
    information ``w [W^L]_ij`` times and its variance ``(w [W^L]_ij)^2`` times);
    with ``w = N`` that holds only in the limit.

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph.
    n_consensus : int
        L >= 0 consensus steps per measurement update.
    novelty_weight : float or "N"
        ``w >= 1`` (default 1: CI); ``"N"``: the number of agents (HCMCI).

    Attributes
    ----------
    n_consensus : int
        L.
    novelty_weight : float
        w.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 4, [[[1.0]]] * 4, graphs.complete_graph(4))
    >>> ci = fusion.ConsensusOnInformationFilter(model, n_consensus=1)
    >>> x, P = ci.update(np.zeros((4, 1)), np.ones((4, 1, 1)), [4.0, 0.0, 0.0, 0.0])
    >>> x[:, 0], P[:, 0, 0]                       # prior 1 + the average measurement information 1
    (array([0.5, 0.5, 0.5, 0.5]), array([0.5, 0.5, 0.5, 0.5]))
    >>> hcmci = fusion.ConsensusOnInformationFilter(model, n_consensus=1, novelty_weight="N")
    >>> hcmci.update(np.zeros((4, 1)), np.ones((4, 1, 1)), [4.0, 0.0, 0.0, 0.0])[0][:, 0]   # = centralized
    array([0.8, 0.8, 0.8, 0.8])
    """

    __slots__ = ("n_consensus", "novelty_weight", "_WL", "_SL")
    _what = "consensus-on-information update"

    def _args(self) -> tuple:
        return (self.n_consensus, self.novelty_weight)

    def __init__(self, model: SensorNetworkModel, n_consensus: int, novelty_weight: float | str = 1.0) -> None:
        super().__init__(model)
        L = check_positive_int(n_consensus, "n_consensus", minimum=0)
        if isinstance(novelty_weight, str):
            if novelty_weight != "N":
                raise ValueError(f"novelty_weight must be a number >= 1 or 'N'; got {novelty_weight!r}")
            w = float(model.n_agents)
        else:
            w = check_positive(novelty_weight, "novelty_weight")
            if w < 1:
                raise ValueError(f"novelty_weight must be >= 1 (1: CI, N: HCMCI); got {novelty_weight!r}")
        WL = np.linalg.matrix_power(model.weights, L)
        self._set(n_consensus=L, novelty_weight=w, _WL=frozen_copy(WL))
        self._set(_SL=frozen_copy(w * mix(WL, model.information_matrices, 2)))

    def _messages(self, q, pair):
        pairs = "the prior and the novelty pairs" if self.novelty_weight != 1.0 else "information pair (Omega, q)"
        k = 2 if self.novelty_weight != 1.0 else 1
        return (Message(f"{pairs}, per consensus round", k * self.n_consensus * pair),)

    def _agent_messages(self, own, xm, Pm, z, i):
        Om, q = information_pair(xm, Pm)
        I, iv = self.model.information_matrices, self.model._information_vectors(z)
        pairs = [(Om, q), (np.broadcast_to(I, Om.shape), iv)] if self.novelty_weight != 1.0 else [(Om + I, q + iv)]
        return consensus_rounds(self.model.weights, pairs, own["nbrs"], self.n_consensus)

    def _agent_step(self, i, own, messages):
        xp, Pp = self.model.F @ own["x"], self.model.F @ own["P"] @ self.model.F.T + self.model.Q
        Om, qv = information_pair(xp, Pp)
        iv = own["HtRinv"][own["index"]] @ own["z"]
        cur = [(Om, qv), (own["I"], iv)] if self.novelty_weight != 1.0 else [(Om + own["I"], qv + iv)]
        if messages:  # L rounds (none at L = 0: each agent's local filter)
            cur = consensus_agent(cur, messages, own["w_self"], own["w_nb"])
        if self.novelty_weight != 1.0:
            return from_information(cur[0][0] + self.novelty_weight * cur[1][0], cur[0][1] + self.novelty_weight * cur[1][1])
        return from_information(*cur[0])

    # one round of messages, exposed for links that lose, delay or withhold them (mascore.fusion_links)

    @property
    def round_weights(self) -> np.ndarray:
        """The (N, N) weights of one consensus round: the Metropolis weights of the model's graph."""
        return self.model.weights

    @property
    def pair_scale(self) -> float:
        """``c``: a pair ``(Omega, q)`` sent is the density of mean ``Omega^{-1} q`` and information ``c Omega`` (1)."""
        return 1.0

    def message_pair(self, x: ArrayLike, P: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Each agent's message of its one round: its prediction's information pair plus its measurement's.

        Parameters
        ----------
        x : (..., N, n) array_like
            Predicted means.
        P : (..., N, n, n) array_like
            Predicted covariances, positive definite.
        z : (..., sum q_i) array_like
            The step's stacked measurement.

        Returns
        -------
        Omega : (..., N, n, n) ndarray
            ``P_i-^{-1} + H_i^T R_i^{-1} H_i``.
        q : (..., N, n) ndarray
            ``P_i-^{-1} x_i- + H_i^T R_i^{-1} z_i``.

        Raises
        ------
        ValueError
            HCMCI (``novelty_weight != 1``) sends two pairs per round, not one density.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.ring_graph(3))
        >>> ci = fusion.ConsensusOnInformationFilter(model, 1)
        >>> Om, q = ci.message_pair(np.zeros((3, 1)), np.ones((3, 1, 1)), [3.0, 0.0, 0.0])
        >>> x, P = ci.pair_estimate(np.einsum("ij,jab->iab", ci.round_weights, Om), ci.round_weights @ q)
        >>> bool(np.allclose(x, ci.update(np.zeros((3, 1)), np.ones((3, 1, 1)), [3.0, 0.0, 0.0])[0]))
        True
        """
        if self.novelty_weight != 1.0:
            raise ValueError("message_pair: HCMCI (novelty_weight != 1) sends a prior and a novelty pair per round, "
                             "not one density; use novelty_weight=1 (CI)")
        return self._message_pair(*self._check_step(x, P, z))

    def _message_pair(self, x: np.ndarray, P: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Om, q = information_pair(x, P)
        return finite_result("message pair", Om + self.model.information_matrices,
                             q + self.model._information_vectors(z), advice="P is too close to singular")

    def pair_estimate(self, Om: ArrayLike, q: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The estimate of a fused information pair: ``x = Omega^{-1} q``, ``P = Omega^{-1}``.

        Parameters
        ----------
        Om : (..., N, n, n) array_like
            Information matrices, finite and positive definite (e.g. weighted sums of
            :meth:`message_pair`'s; a singular one is refused, definiteness is not checked).
        q : (..., N, n) array_like
            Information vectors, finite.

        Returns
        -------
        x : (..., N, n) ndarray
            Means.
        P : (..., N, n, n) ndarray
            Covariances.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.ring_graph(3))
        >>> fusion.ConsensusOnInformationFilter(model, 1).pair_estimate(np.full((3, 1, 1), 4.0), np.full((3, 1), 2.0))
        (array([[0.5],
               [0.5],
               [0.5]]), array([[[0.25]],
        <BLANKLINE>
               [[0.25]],
        <BLANKLINE>
               [[0.25]]]))
        """
        return self._pair_result(from_information, *self._check_pair(Om, q, ("Om", "q")), ("Om", "q"))

    @property
    def exchanges(self) -> int:
        """L: each consensus round needs the one before."""
        return self.n_consensus

    @property
    def pair_scales(self) -> tuple[float | None, ...]:
        """What each pair of :meth:`message_pairs` is: ``c`` for a density (mean ``Omega^{-1} q``, information
        ``c Omega``), None for a measurement's information (HCMCI's novelty pair)."""
        return (1.0,) if self.novelty_weight == 1.0 else (1.0, None)

    def message_pairs(self, x: ArrayLike, P: ArrayLike, z: ArrayLike) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """The pairs each agent sends in its first round: CI one (:meth:`message_pair`), HCMCI two.

        HCMCI sends its prior pair ``(P_i-^{-1}, P_i-^{-1} x_i-)`` and its novelty pair
        ``(H_i^T R_i^{-1} H_i, H_i^T R_i^{-1} z_i)``; each round mixes each pair with the same weights.

        Parameters
        ----------
        x : (..., N, n) array_like
            Predicted means.
        P : (..., N, n, n) array_like
            Predicted covariances, positive definite.
        z : (..., sum q_i) array_like
            The step's stacked measurement.

        Returns
        -------
        tuple of (Omega, q)
            ``Omega`` ``(..., N, n, n)``, ``q`` ``(..., N, n)``; one pair per entry of :attr:`pair_scales`.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.ring_graph(3))
        >>> hcmci = fusion.ConsensusOnInformationFilter(model, 1, novelty_weight="N")
        >>> pairs = hcmci.message_pairs(np.zeros((3, 1)), np.ones((3, 1, 1)), [3.0, 0.0, 0.0])
        >>> W = hcmci.round_weights
        >>> mixed = [(np.einsum("ij,jab->iab", W, Om), W @ q) for Om, q in pairs]
        >>> bool(np.allclose(hcmci.pairs_estimate(mixed)[0], hcmci.update(np.zeros((3, 1)), np.ones((3, 1, 1)),
        ...                                                               [3.0, 0.0, 0.0])[0]))
        True
        """
        x, P, z = self._check_step(x, P, z)
        if self.novelty_weight == 1.0:
            return (self._message_pair(x, P, z),)
        Om, q = finite_result("message pair", *information_pair(x, P), advice="P is too close to singular")
        return (Om, q), (np.broadcast_to(self.model.information_matrices, Om.shape),
                         self.model._information_vectors(z))

    def pairs_estimate(self, pairs: Sequence[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
        """The estimate of the pairs after the rounds: CI :meth:`pair_estimate`; HCMCI ``Omega + w dOmega``, ``q + w dq``.

        Parameters
        ----------
        pairs : sequence of (Omega, q)
            As :meth:`message_pairs` gives them, after the consensus rounds.

        Returns
        -------
        x : (..., N, n) ndarray
            Means.
        P : (..., N, n, n) ndarray
            Covariances.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.ring_graph(3))
        >>> hcmci = fusion.ConsensusOnInformationFilter(model, 1, novelty_weight="N")
        >>> prior, novelty = (np.ones((3, 1, 1)), np.zeros((3, 1))), (np.ones((3, 1, 1)), np.full((3, 1), 2.0))
        >>> x, P = hcmci.pairs_estimate([prior, novelty])             # information 1 + 3 x 1, vector 3 x 2
        >>> x[:, 0], P[:, 0, 0]
        (array([1.5, 1.5, 1.5]), array([0.25, 0.25, 0.25]))
        """
        names = (("pairs[0][0]", "pairs[0][1]"), ("pairs[1][0]", "pairs[1][1]"))
        pairs = [self._check_pair(Om, q, name) for (Om, q), name in zip(pair_list(pairs, len(self.pair_scales)), names)]
        if self.novelty_weight == 1.0:
            return self._pair_result(from_information, *pairs[0], names[0])
        (Om, q), (dOm, dq) = pairs
        w = self.novelty_weight
        return self._pair_result(from_information, symmetric_part(Om + w * dOm), q + w * dq, names[0])

    def _correct(self, x, P, z):
        Om, q = information_pair(x, P)
        Om = mix(self._WL, Om, 2) + self._SL
        q = mix(self._WL, q, 1) + self.novelty_weight * mix(self._WL, self.model._information_vectors(z), 1)
        return from_information(Om, q)


class InformationConsensusFilter(_NetworkFilter):
    """The information-weighted consensus filter (ICF) of Kamal, Farrell and Roy-Chowdhury (2013).

    Per step, with ``J_i- = P_i-^{-1}``::

        V_i^0 = J_i- / N + H_i^T R_i^{-1} H_i,    v_i^0 = J_i- x_i- / N + H_i^T R_i^{-1} z_i,
        K iterations:  (.)_i^{k+1} = (.)_i^k + eps sum_{j in N_i} ((.)_j^k - (.)_i^k),
        x_i+ = (V_i^K)^{-1} v_i^K,   J_i+ = N V_i^K,   P_i+ = J_i+^{-1}.

    The prior's 1/N weighting accounts for the agents' priors being (in the
    limit) the same information; as ``K -> inf`` on a connected graph, from a
    common prior, each agent's estimate tends to the centralized one (the
    paper's convergence result). For finite K it need not be consistent. (It is the
    HCMCI form of :class:`ConsensusOnInformationFilter` with ``w = N`` and the
    consensus matrix ``I - eps L`` in place of Metropolis weights.)

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph.
    n_iterations : int
        K >= 0 consensus iterations per step.
    rate : float, optional
        eps, in ``(0, 1 / d_max)`` (``d_max`` the largest degree); default
        ``0.65 / d_max``.

    Attributes
    ----------
    n_iterations : int
        K.
    rate : float
        eps.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 4, [[[1.0]]] * 4, graphs.ring_graph(4))
    >>> icf = fusion.InformationConsensusFilter(model, n_iterations=60)
    >>> x, P = icf.update(np.zeros((4, 1)), np.ones((4, 1, 1)), [4.0, 0.0, 0.0, 0.0])
    >>> np.round(x[:, 0], 6), np.round(P[:, 0, 0], 6)         # centralized: 0.8, 0.2
    (array([0.8, 0.8, 0.8, 0.8]), array([0.2, 0.2, 0.2, 0.2]))
    """

    __slots__ = ("n_iterations", "rate", "_W", "_WK", "_SK")
    _what = "information consensus (ICF) update"

    def _args(self) -> tuple:
        return (self.n_iterations, self.rate or None)  # rate 0: a graph without links (the default)

    def __init__(self, model: SensorNetworkModel, n_iterations: int, rate: float | None = None) -> None:
        super().__init__(model)
        K = check_positive_int(n_iterations, "n_iterations", minimum=0)
        links = model.adjacency > 0
        d_max = int(links.sum(axis=1).max())
        if rate is None:
            eps = 0.65 / d_max if d_max else 0.0
        else:
            eps = check_positive(rate, "rate")
            if d_max and eps >= 1.0 / d_max:
                raise ValueError(f"rate must lie in (0, 1 / d_max) = (0, {1.0 / d_max:.4g}) for the largest degree "
                                 f"d_max = {d_max}; got {rate!r}")
        Lap = np.diag(links.sum(axis=1).astype(float)) - links
        W = np.eye(model.n_agents) - eps * Lap
        self._set(n_iterations=K, rate=eps, _W=frozen_copy(W), _WK=frozen_copy(np.linalg.matrix_power(W, K)))
        self._set(_SK=frozen_copy(mix(self._WK, model.information_matrices, 2)))

    def _messages(self, q, pair):
        return (Message("information pair (V, v), per consensus iteration", self.n_iterations * pair),)

    def _agent_messages(self, own, xm, Pm, z, i):
        N = self.model.n_agents
        Om, q = information_pair(xm, Pm)
        pairs = [(Om / N + self.model.information_matrices, q / N + self.model._information_vectors(z))]
        return consensus_rounds(self._W, pairs, own["nbrs"], self.n_iterations)

    def _agent_step(self, i, own, messages):
        N = self.model.n_agents
        xp, Pp = self.model.F @ own["x"], self.model.F @ own["P"] @ self.model.F.T + self.model.Q
        Om, qv = information_pair(xp, Pp)
        iv = own["HtRinv"][own["index"]] @ own["z"]
        (Om_f, q_f), = consensus_agent([(Om / N + own["I"], qv / N + iv)], messages, own["w_self"], own["w_nb"])
        x_f, P_f = from_information(Om_f, q_f)
        return x_f, P_f / N

    # one round of messages, exposed for links that lose, delay or withhold them (mascore.fusion_links)

    @property
    def round_weights(self) -> np.ndarray:
        """The (N, N) weights of one consensus iteration, ``I - eps L`` (L the graph's Laplacian), read-only."""
        return self._W

    @property
    def pair_scale(self) -> float:
        """``c = N``: a pair ``(V, v)`` sent is the density of mean ``V^{-1} v`` and information ``N V``."""
        return float(self.model.n_agents)

    def message_pair(self, x: ArrayLike, P: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Each agent's message of its first iteration: ``(J_i- / N + H_i^T R_i^{-1} H_i, J_i- x_i- / N + H_i^T R_i^{-1} z_i)``.

        Parameters
        ----------
        x : (..., N, n) array_like
            Predicted means.
        P : (..., N, n, n) array_like
            Predicted covariances, positive definite.
        z : (..., sum q_i) array_like
            The step's stacked measurement.

        Returns
        -------
        V : (..., N, n, n) ndarray
            The information matrices sent.
        v : (..., N, n) ndarray
            The information vectors sent.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.ring_graph(3))
        >>> icf = fusion.InformationConsensusFilter(model, 1)
        >>> V, v = icf.message_pair(np.zeros((3, 1)), np.ones((3, 1, 1)), [3.0, 0.0, 0.0])
        >>> x, P = icf.pair_estimate(np.einsum("ij,jab->iab", icf.round_weights, V), icf.round_weights @ v)
        >>> bool(np.allclose(P, icf.update(np.zeros((3, 1)), np.ones((3, 1, 1)), [3.0, 0.0, 0.0])[1]))
        True
        """
        x, P, z = self._check_step(x, P, z)
        N = self.model.n_agents
        J, q = information_pair(x, P)
        return finite_result("message pair", J / N + self.model.information_matrices,
                             q / N + self.model._information_vectors(z), advice="P is too close to singular")

    def pair_estimate(self, V: ArrayLike, v: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The estimate of a fused pair: ``x = V^{-1} v``, ``P = (N V)^{-1}``.

        Parameters
        ----------
        V : (..., N, n, n) array_like
            Information matrices, finite and positive definite (e.g. weighted sums of
            :meth:`message_pair`'s; a singular one is refused, definiteness is not checked).
        v : (..., N, n) array_like
            Information vectors, finite.

        Returns
        -------
        x : (..., N, n) ndarray
            Means.
        P : (..., N, n, n) ndarray
            Covariances.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 4, [[[1.0]]] * 4, graphs.ring_graph(4))
        >>> x, P = fusion.InformationConsensusFilter(model, 1).pair_estimate(np.ones((4, 1, 1)), np.full((4, 1), 2.0))
        >>> x[:, 0], P[:, 0, 0]                                   # P = 1 / (N V)
        (array([2., 2., 2., 2.]), array([0.25, 0.25, 0.25, 0.25]))
        """
        return self._pair_result(self._pair_estimate, *self._check_pair(V, v, ("V", "v")), ("V", "v"))

    def _pair_estimate(self, V: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        Vinv = symmetric_part(np.linalg.inv(V))
        return (Vinv @ v[..., None])[..., 0], Vinv / self.model.n_agents

    @property
    def exchanges(self) -> int:
        """K: each consensus iteration needs the one before."""
        return self.n_iterations

    @property
    def pair_scales(self) -> tuple[float]:
        """``(N,)``: the one pair of :meth:`message_pairs` is a density of information ``N V``."""
        return (self.pair_scale,)

    def message_pairs(self, x: ArrayLike, P: ArrayLike, z: ArrayLike) -> tuple[tuple[np.ndarray, np.ndarray]]:
        """``(message_pair(x, P, z),)``: the one pair of each iteration (as CI's ``message_pairs``).

        Parameters
        ----------
        x : (..., N, n) array_like
            Predicted means.
        P : (..., N, n, n) array_like
            Predicted covariances, positive definite.
        z : (..., sum q_i) array_like
            The step's stacked measurement.

        Returns
        -------
        tuple of one (V, v)
            ``V`` ``(..., N, n, n)``, ``v`` ``(..., N, n)``: :meth:`message_pair`.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.ring_graph(3))
        >>> (V, v), = fusion.InformationConsensusFilter(model, 1).message_pairs(np.zeros((3, 1)), np.ones((3, 1, 1)),
        ...                                                                    [3.0, 0.0, 0.0])
        >>> V[:, 0, 0]                                             # J / N + H^T R^-1 H = 1/3 + 1
        array([1.33333333, 1.33333333, 1.33333333])
        """
        return (self.message_pair(x, P, z),)

    def pairs_estimate(self, pairs: Sequence[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`pair_estimate` of the one pair after the iterations.

        Parameters
        ----------
        pairs : sequence of one (V, v)
            ``V`` ``(..., N, n, n)`` positive definite, ``v`` ``(..., N, n)``.

        Returns
        -------
        x : (..., N, n) ndarray
            Means.
        P : (..., N, n, n) ndarray
            Covariances, ``(N V)^{-1}``.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 4, [[[1.0]]] * 4, graphs.ring_graph(4))
        >>> x, P = fusion.InformationConsensusFilter(model, 1).pairs_estimate([(np.ones((4, 1, 1)), np.full((4, 1), 2.0))])
        >>> P[:, 0, 0]
        array([0.25, 0.25, 0.25, 0.25])
        """
        (V, v), = pair_list(pairs, 1)
        return self.pair_estimate(V, v)

    def _correct(self, x, P, z):
        N = self.model.n_agents
        J, q = information_pair(x, P)
        V = mix(self._WK, J, 2) / N + self._SK
        v = mix(self._WK, q, 1) / N + mix(self._WK, self.model._information_vectors(z), 1)
        return self._pair_estimate(V, v)


class CovarianceIntersectionFilter(_NetworkFilter):
    """Diffusion Kalman filtering with covariance intersection (Hu, Xie and Zhang 2012).

    Step 1, incremental update: agent i corrects its prediction with the
    measurements of ``N_i ∪ {i}`` (``measurements="neighbourhood"``, as Hu, Xie
    and Zhang) or with its own only (``"own"``),
    giving ``(psi_i, P_i)``. Step 2: agent i fuses the estimates
    ``(psi_j, P_j)``, ``j in N_i ∪ {i}``, by :func:`covariance_intersection`
    (Julier and Uhlmann 1997) with weights minimizing the trace or the
    determinant of the result. Since covariance intersection is consistent
    whatever the correlation between its inputs, every agent's ``P_i`` bounds
    its error covariance at every step, from a consistent prior.

    The weights depend only on the covariances, not on the data: with a batch
    of runs sharing one covariance per agent they are computed once per agent
    and step; the searches of all agents with neighbourhoods of one size (and
    of every batch element of covariances with batch axes) run at once, as one
    batched Newton iteration on the simplex (:func:`covariance_intersection`).

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph.
    criterion : {"trace", "det"} or None
        What the weights minimize (None: equal weights ``1 / (d_i + 1)``).
    measurements : {"neighbourhood", "own"}
        Which measurements step 1 uses.

    Attributes
    ----------
    criterion : str or None
        As given.
    measurements : str
        As given.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 3, [[[1.0]]] * 3, graphs.path_graph(3))
    >>> cif = fusion.CovarianceIntersectionFilter(model, measurements="own")
    >>> x, P = cif.update(np.zeros((3, 1)), np.ones((3, 1, 1)), [3.0, 0.0, 0.0])
    >>> x[:, 0], P[:, 0, 0]              # local estimates 1.5, 0, 0, all with P = 1/2: equal weights
    (array([0.75, 0.5 , 0.  ]), array([0.5, 0.5, 0.5]))
    """

    __slots__ = ("criterion", "measurements", "_S", "_hood")
    _what = "covariance-intersection diffusion update"

    def _args(self) -> tuple:
        return (self.criterion, self.measurements)

    def __init__(self, model: SensorNetworkModel, criterion: str | None = "trace",
                 measurements: str = "neighbourhood") -> None:
        super().__init__(model)
        if criterion not in ("trace", "det", None):
            raise ValueError(f"criterion must be 'trace', 'det' or None; got {criterion!r}")
        if measurements not in ("neighbourhood", "own"):
            raise ValueError(f"measurements must be 'neighbourhood' or 'own'; got {measurements!r}")
        M = model._neighbourhood if measurements == "neighbourhood" else np.eye(model.n_agents)
        self._set(criterion=criterion, measurements=measurements, _S=frozen_copy(mix(M, model.information_matrices, 2)),
                  _hood=tuple(frozen_copy(np.flatnonzero(row), int) for row in model._neighbourhood))

    def _correct(self, x, P, z):
        M = self.model._neighbourhood if self.measurements == "neighbourhood" else np.eye(self.model.n_agents)
        psi, P_loc = information_update(x, P, self._S, mix(M, self.model._information_vectors(z), 1))
        Om, q = information_pair(psi, P_loc)  # (..., N, n, n), (..., N, n)
        N = self.model.n_agents
        C = np.zeros((*P_loc.shape[:-3], N, N))  # the weights: from the covariances only
        flat, Om_flat = C.reshape(-1, N, N), Om.reshape(-1, *Om.shape[-3:])
        for size in sorted({len(hood) for hood in self._hood}):  # the agents of one neighbourhood size at once
            agents = np.array([i for i, hood in enumerate(self._hood) if len(hood) == size])
            hoods = np.stack([self._hood[i] for i in agents])  # (g, size)
            if self.criterion is None:
                flat[:, agents[:, None], hoods] = 1.0 / size
            else:
                flat[:, agents[:, None], hoods] = ci_weights(Om_flat[:, hoods], self.criterion)
        # agent i: Omega_i = sum_j C_ij Omega_j, q_i = sum_j C_ij q_j
        Om_f = np.einsum("...ij,...jab->...iab", C, Om)
        q_f = np.einsum("...ij,...ja->...ia", C, q)
        return from_information(Om_f, q_f)

    @property
    def exchanges(self) -> int:
        """2 (the measurements, then the incremental estimates), 1 with ``measurements="own"``."""
        return 2 if self.measurements == "neighbourhood" else 1

    def _messages(self, q, pair):
        return (Message("measurement z_i", q if self.measurements == "neighbourhood" else 0.0),
                Message("information pair of the incremental estimate", pair))

    def _agent_messages(self, own, xm, Pm, z, i):
        M = self.model._neighbourhood if self.measurements == "neighbourhood" else np.eye(self.model.n_agents)
        psi, P_loc = information_update(xm, Pm, self._S, mix(M, self.model._information_vectors(z), 1))
        Om, q = information_pair(psi[own["nbrs"]], P_loc[own["nbrs"]])
        received = super()._agent_messages(own, xm, Pm, z, i)
        return (received[0] if self.measurements == "neighbourhood" else (), (Om, q))

    def agent_inputs(self, x: ArrayLike, P: ArrayLike, z: ArrayLike, i: int) -> tuple[dict, tuple]:
        """Agent i's own data and its neighbours' messages of one step (as for every filter of this module).

        See :meth:`~mascore._fusion_base.NetworkFilter.agent_inputs`.

        With ``measurements="own"`` the incremental step uses agent i's own measurement only.

        Parameters
        ----------
        x : (N, n) array_like
            Every agent's estimate before the step.
        P : (N, n, n) array_like
            Their covariances, symmetric positive definite.
        z : (sum q_i,) array_like
            The step's stacked measurement.
        i : int
            The agent.

        Returns
        -------
        own : dict
            Agent i's own data.
        messages : tuple
            The neighbours' measurements, then their incremental estimates as information pairs.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import fusion, graphs, sensor_network
        >>> model = sensor_network.SensorNetworkModel(np.eye(2), np.eye(2), [np.eye(2)] * 3, [np.eye(2)] * 3,
        ...                                           graphs.ring_graph(3))
        >>> filt = fusion.CovarianceIntersectionFilter(model)
        >>> own, messages = filt.agent_inputs(np.zeros((3, 2)), np.broadcast_to(np.eye(2), (3, 2, 2)), np.ones(6), 0)
        >>> len(messages[0]), messages[1][0].shape                  # two measurements; two information matrices
        (2, (2, 2, 2))
        """
        own, messages = super().agent_inputs(x, P, z, i)
        if self.measurements == "own":  # the incremental step with its own measurement only
            own.update(hood=np.array([i]), index=0, HtRinv=(own["HtRinv"][own["index"]],), S=own["I"])
        return own, messages

    def _agent_step(self, i, own, messages):
        psi, Pn = self._incremental(own, messages[0])
        Om, qv = information_pair(psi, Pn)
        Om_nb, q_nb = messages[1]
        k = int((own["nbrs"] < i).sum())  # i's place in its neighbourhood
        infos = np.insert(Om_nb, k, Om, axis=0)
        qs = np.insert(q_nb, k, qv, axis=0)
        if self.criterion is None:
            w = np.full(len(infos), 1.0 / len(infos))
        else:
            w = ci_weights(infos, self.criterion)
        return from_information(np.einsum("k,kab->ab", w, infos), w @ qs)



def track(filt: _NetworkFilter, x0: ArrayLike, P0: ArrayLike, z: ArrayLike,
          graphs: Sequence[object] | ArrayLike | None = None, sensing: ArrayLike | None = None,
          H: ArrayLike | None = None, R: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Run a sensor-network filter over measurements, with fixed or per-step graphs and sensing.

    The one run loop for a user's own network: step k predicts, then fuses ``z[k]``
    over graph k (the filter's own graph when `graphs` is None) from the agents that
    sense at step k (all of them when `sensing` is None), each with its ``H_i`` and ``R_i``
    of step k (the model's when `H` and `R` are None). A step whose graph or sensing is not
    the model's rebuilds the filter, with its own settings, on the model of that step: that
    graph, and ``H_i(k)``, ``R_i(k)`` of the agents that sense (an agent that does not has no
    measurement rows: ``H_i`` of shape ``(0, n)``); each distinct (graph, sensing) of a call
    once, and a step whose values equal the model's is the model's (no rebuild). Every
    filter of this module and of :mod:`mascore.fusion_forwarding` takes per-step sensing
    (each uses ``H_i`` and ``R_i`` only within the step), and all but the
    :class:`~mascore.fusion_forwarding.SetMembershipForwardingFilter` (whose update is computed
    once per agent and step for every run) take values that differ between the runs of a
    batch. Everything is checked before the first step.

    Parameters
    ----------
    filt : fusion filter
        One of this module's filters (e.g. :class:`ConsensusOnInformationFilter`), built on the
        network's :class:`~mascore.sensor_network.SensorNetworkModel`.
    x0 : (..., N, n) or (n,) array_like
        Initial means (one ``(n,)`` mean for every agent allowed), finite.
    P0 : (..., N, n, n) or (n, n) array_like
        Initial covariances, symmetric positive definite.
    z : (K, ..., sum q_i) array_like
        Measurements of steps 1..K (as ``SensorNetworkModel.simulate`` returns). Finite where
        used; the entries of an agent that does not sense at a step are not read (NaN allowed).
    graphs : sequence of K adjacency matrices or networkx graphs, or (K, N, N) array_like, optional
        The communication graph of each step (undirected, N agents; ``A[i, j] > 0``: i and j
        exchange). Default: the model's graph at every step.
    sensing : (K, N) array_like of bool, optional
        ``sensing[k, i]``: agent i measures at step k (a target within its range, say); False:
        it measures nothing at that step and only takes part in the exchange. Default: every
        agent at every step. At a step where no agent senses the filter predicts only
        (nothing to fuse, nothing exchanged).
    H : (K, ..., sum q_i, n) array_like, optional
        The stacked measurement matrix ``[H_1(k); ...; H_N(k)]`` of each step (agent i's
        ``q_i`` rows where the model has them; units of the measurement per unit of the
        state): a sensor that moves, or a range or bearing sensor linearized about a
        trajectory known before the run (then ``z`` holds the linearized measurements
        ``z_i - h_i(x_ref) + H_i x_ref``). Axes between the first and the last two: one value
        per run, broadcast with the runs of `x0` and `z` (a range to each run's own target).
        Finite where the agent senses. Default: the model's ``H_i`` at every step.
    R : (K, ..., sum q_i, sum q_i) array_like, optional
        The block-diagonal ``blockdiag(R_1(k), ..., R_N(k))`` of each step (measurement units
        squared; run axes as for `H`): a noise variance that grows with the distance to the
        target, say. Each block of an agent that senses symmetric positive definite, zero off
        the blocks (the agents' noises are independent). Default: the model's ``R_i``.

    Returns
    -------
    x : (K, ..., N, n) ndarray
        Each agent's corrected mean after each step (``(K, ..., n)`` for the centralized filter).
    P : (K, ..., N, n, n) ndarray
        Their covariances (leading axes those of `P0` and `x0`, and the run axes of `H` and `R`:
        they do not depend on the data).

    Raises
    ------
    ValueError, TypeError
        A bad filter, state, measurement, graph, sensing mask, ``H`` or ``R`` (named; a graph
        and a step's sensing by their step), or more graphs or steps than memory holds.

    Notes
    -----
    Per-step ``H`` and ``R`` are values known before the run (per run, if they differ); a
    sensing mask is one for all runs (a mask that differs between runs is one call per run).
    An extended Kalman filter, which linearizes about each agent's own prediction during the
    run, is not this loop: its ``H_i(k)`` depends on the estimates.

    Examples
    --------
    >>> import networkx as nx
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel(np.eye(2), 0.01 * np.eye(2), [np.eye(2)] * 4, [np.eye(2)] * 4,
    ...                                           graphs.ring_graph(4))
    >>> x_true, z = model.simulate(np.zeros(2), np.eye(2), 20, rng=0)
    >>> switching = [nx.path_graph(4) if k % 2 else nx.cycle_graph(4) for k in range(20)]
    >>> x, P = fusion.track(fusion.ConsensusOnInformationFilter(model, 2), np.zeros(2), np.eye(2), z, switching)
    >>> x.shape, P.shape
    ((20, 4, 2), (20, 4, 2, 2))

    Agents 0 and 1 in range of the target for the first ten steps only:

    >>> in_range = np.ones((20, 4), dtype=bool)
    >>> in_range[10:, :2] = False
    >>> x, P = fusion.track(fusion.CentralizedFilter(model), np.zeros(2), np.eye(2), z, sensing=in_range)
    >>> bool(P[-1, 0, 0] > P[9, 0, 0])          # fewer measurements, larger covariance
    True

    A noise variance that doubles at step 10 (``R`` of shape ``(K, sum q_i, sum q_i)``):

    >>> R = np.broadcast_to(model.R_stacked, (20, 8, 8)) * np.where(np.arange(20) < 10, 1.0, 2.0)[:, None, None]
    >>> x, P = fusion.track(fusion.CentralizedFilter(model), np.zeros(2), np.eye(2), z, R=R)
    >>> bool(P[-1, 0, 0] > P[9, 0, 0])
    True
    """
    if not isinstance(filt, _NetworkFilter):
        raise TypeError(f"filt must be one of mascore.fusion's filters (e.g. ConsensusOnInformationFilter(model, "
                        f"L)); got {type(filt).__name__}")
    if graphs is None and sensing is None and H is None and R is None:
        return filt.run(x0, P0, z)
    model = filt.model
    x, P = model.check_state(x0, P0, ("x0", "P0"), per_agent=filt._per_agent)
    z = model._check_z(z)
    if z.ndim < 2:
        raise ValueError(f"z must be (K, ..., {model.n_measurements}): one stacked measurement per step; "
                         f"got shape {z.shape}")
    K = z.shape[0]
    axis = 2 if filt._per_agent else 1
    batch = broadcast_batch("x0", x.shape[:-axis], "z", z.shape[1:-1])
    n, N = model.n_states, model.n_agents
    check_fits_in_memory(8.0 * K * math.prod(batch) * n * (1 + n) * (N if filt._per_agent else 1), "z",
                         "the estimates and covariances of every step and run")
    adjacency = step_graphs(graphs, K, N, model.adjacency)
    senses = step_sensing(sensing, K, N)
    rows = np.repeat(senses, model.measurement_sizes, axis=1)  # (K, sum q_i): the entries of z that are read
    used = rows.reshape((K,) + (1,) * (z.ndim - 2) + (rows.shape[1],))
    if not np.all(np.isfinite(z) | ~used):
        require_finite(np.where(used, z, 0.0), "z" if sensing is None else "z (where the agent senses)")
    values, runs = step_values(H, R, model, rows)
    if runs:
        every = broadcast_batch("x0 and z", batch, "H and R", runs)
        check_fits_in_memory(8.0 * K * math.prod(every) * n * (1 + n) * (N if filt._per_agent else 1), "H and R",
                             "the estimates and covariances of every step and run")
        if not filt._per_run_sensing:
            raise ValueError(f"filt: a {type(filt).__name__} takes one H and R per step for all runs (its update is "
                             f"computed once per agent and step, shared by the runs); got H or R with run axes {runs}: "
                             "call track once per run")
    built: dict[tuple[bytes, ...], _NetworkFilter | None] = {}
    xs, Ps = [], []
    for k in range(K):
        own = values[k]
        key = (adjacency[k].tobytes(), senses[k].tobytes(), *(() if own is None else (own[0].tobytes(),
                                                                                      own[1].tobytes())))
        if key not in built:
            try:
                built[key] = _filter_of_step(filt, adjacency[k], senses[k], own)
            except ValueError as exc:  # e.g. an R(k) too close to singular to invert
                raise ValueError(f"step {k}: {exc}") from None
        step = built[key]
        x, P = filt.predict(x, P) if step is None else step.predict(x, P)
        if step is not None:
            x, P = step.update(x, P, z[k] if rows[k].all() else z[k][..., rows[k]])
        xs.append(x)
        Ps.append(P)
    if runs:  # the steps before the first with per-run values have fewer batch axes
        xs, Ps = np.broadcast_arrays(*xs), np.broadcast_arrays(*Ps)
    return np.stack(xs), np.stack(Ps)





def _filter_of_step(filt: _NetworkFilter, A: np.ndarray, senses: np.ndarray,
                    values: tuple[np.ndarray, np.ndarray] | None = None) -> _NetworkFilter | None:
    """`filt` on a step's graph with only the sensing agents' measurements, with the step's ``H``, ``R`` when given
    (None: nobody senses)."""
    model = filt.model
    if not senses.any():
        return None
    same_graph = np.array_equal(A, model.adjacency)  # then the filter's own settings hold as they are
    if senses.all() and same_graph and values is None:
        return filt
    step_model = model if same_graph else model.on_graph(A)
    if values is not None or not senses.all():  # the step's own sensing (checked by track)
        H, R = (model.H_stacked, model.R_stacked) if values is None else values
        rows = np.repeat(senses, model.measurement_sizes)  # the rows of the agents that sense
        step_model = step_model._with_stacked_sensing(H[..., rows, :], R[..., rows, :][..., rows],
                                                      [q if s else 0 for q, s in zip(model.measurement_sizes, senses)])
    return type(filt)(step_model, *(filt._args() if same_graph else _settings_for_any_graph(filt)))


def error_covariance(filt: _NetworkFilter, P0: ArrayLike, n_steps: int, P0_true: ArrayLike | None = None,
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The exact error covariance ``E[e_i e_i^T]`` of a filter's estimates, without Monte Carlo.

    Every filter of this module is linear in the data for given covariances, and
    its covariances do not depend on the data. So the error of each agent is a
    linear map of the noise sources (initial error, process noise, measurement
    noise), and running the filter once per source direction, scaled by the
    square roots of ``P0_true``, Q and R (a batch of runs from the mean 0), gives
    ``E[e e^T] = sum_d e_d e_d^T`` to rounding. Only the second moment of the
    joint vector (truth, every agent's estimate) carries over to the next step,
    so after each step the batch is replaced by a square root of it (QR): at most
    ``n (N + 2) + sum q_i`` runs per step (``3 n + sum q_i`` for the centralized
    filter), instead of one per source drawn so far. Compare the result with the
    filter's own P: a consistent filter has ``P - E[e e^T] >= 0``.

    Parameters
    ----------
    filt : filter of this module
        E.g. a :class:`ConsensusOnInformationFilter`.
    P0 : (n, n) or (N, n, n) array_like
        The filter's initial covariance(s), symmetric positive definite.
    n_steps : int
        K >= 1 steps.
    P0_true : (n, n) array_like, optional
        The covariance of the true initial error (every agent starts from the
        same mean); default `P0` (which must then be one (n, n) matrix).

    Returns
    -------
    C : (K, N, n, n) ndarray
        ``E[e_i e_i^T]`` after each update, per agent (``(K, n, n)`` for the
        centralized filter).
    P : (K, N, n, n) ndarray
        The filter's covariances, same shape.

    Raises
    ------
    ValueError, TypeError
        A bad filter or covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs, sensor_network
    >>> model = sensor_network.SensorNetworkModel(np.eye(2), 0.1 * np.eye(2), [np.eye(2), np.eye(1, 2), np.zeros((0, 2))],
    ...                                           [np.eye(2), np.eye(1), None], graphs.path_graph(3))
    >>> C, P = fusion.error_covariance(fusion.ConsensusOnInformationFilter(model, 2), np.eye(2), 20)
    >>> bool(np.linalg.eigvalsh(P - C).min() >= 0)             # consistent
    True
    >>> C, P = fusion.error_covariance(fusion.MeasurementForwardingFilter(model), np.eye(2), 20)
    >>> bool(np.allclose(P, C))                                 # a Kalman filter: P is its error covariance
    True
    """
    if not isinstance(filt, _NetworkFilter):
        raise TypeError(f"filt must be a filter of mascore.fusion; got {type(filt).__name__}")
    from ._validation import check_steps

    model = filt.model
    K = check_steps(n_steps)
    n, q = model.n_states, model.n_measurements
    x, P = model.check_state(np.zeros(n), P0, ("x0", "P0"), per_agent=filt._per_agent)
    if P0_true is None:
        P0_true = float_array(P0, "P0")
        if P0_true.ndim != 2:
            raise ValueError("P0_true (the covariance of the true initial error) is needed when P0 is per agent")
    P0_true = check_covariance(float_array(P0_true, "P0_true"), "P0_true", size=n)
    if P0_true.ndim != 2:
        raise ValueError(f"P0_true must be one ({n}, {n}) covariance; got shape {P0_true.shape}")
    shape = x.shape                                  # one estimate: (N, n), or (n,) for the centralized filter
    truth = psd_sqrt(P0_true).T                      # (D, n): one run per source direction, D = n at the start
    x = np.zeros((n, *shape))                        # (D, *shape): the estimates of those runs (from the mean 0)
    C_out = np.empty((K, *P.shape))
    P_out = np.empty((K, *P.shape))
    sub = "dia,dib->iab" if filt._per_agent else "da,db->ab"
    new_rows = np.zeros((n + q, *shape))             # the step's new sources have no estimate yet
    for k in range(K):
        truth = np.concatenate([truth @ model.F.T, model._sqrt_Q.T, np.zeros((q, n))])  # + process noise, + R's rows
        z = truth @ model.H_stacked.T
        z[len(z) - q:] += model._sqrt_R.T
        x, P = filt.update(*filt.predict(np.concatenate([x, new_rows]), P), z)
        if P.ndim > P_out.ndim - 1:  # a filter that returned one covariance per run: they are all equal
            P = P[0]
        e = (truth[:, None, :] if filt._per_agent else truth) - x
        C_out[k] = np.einsum(sub, e, e)
        P_out[k] = P
        if len(truth) > n + x[0].size:  # keep R of the QR of [truth, x]: the same R^T R, at most n + x[0].size rows
            r = np.linalg.qr(np.concatenate([truth, x.reshape(len(x), -1)], axis=1), mode="r")
            truth, x = r[:, :n], r[:, n:].reshape(-1, *shape)
    return C_out, P_out


# --------------------------------------------------------------------------------------------
# covariance intersection


def covariance_intersection(means: ArrayLike, covs: ArrayLike, weights: str | ArrayLike | None = "trace",
                            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Covariance intersection of k estimates with unknown cross-correlation (Julier and Uhlmann 1997).

    ``P^{-1} = sum_k w_k P_k^{-1}``, ``x = P sum_k w_k P_k^{-1} x_k`` with ``w`` on
    the simplex. If each ``P_k`` bounds its estimate's error covariance, then
    ``P >= E[e e^T]`` (PSD) for *every* joint error covariance with those
    marginals (Julier and Uhlmann 1997; Chen, Arambel and Mehra 2002).
    The weights minimize ``trace(P)`` or ``det(P)`` (both convex in w).

    Parameters
    ----------
    means : (k, n) array_like
        The estimates, finite.
    covs : (k, n, n) array_like
        Their covariances, symmetric positive definite.
    weights : "trace", "det", None or (k,) array_like
        ``"trace"`` (default) or ``"det"``: the weights minimizing that of P
        (Newton's method on the simplex with an active set, to machine precision; equal
        weights unless they are beaten, so a flat criterion gives ``1/k``; with more than
        ``n (n + 1) / 2`` estimates the optimal P is unique, its weights need not be);
        None: equal weights ``1/k``; an array: given weights, non-negative,
        summing to 1.

    Returns
    -------
    x : (n,) ndarray
        Fused mean.
    P : (n, n) ndarray
        Fused covariance.
    w : (k,) ndarray
        The weights used.

    Raises
    ------
    ValueError, TypeError
        Bad shapes, a covariance not positive definite, weights off the simplex.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion
    >>> x, P, w = fusion.covariance_intersection([[0.0, 0.0], [1.0, 1.0]],
    ...                                          [np.diag([1.0, 4.0]), np.diag([4.0, 1.0])])
    >>> np.round(w, 6), np.round(x, 6)
    (array([0.5, 0.5]), array([0.2, 0.8]))
    >>> np.round(P, 6)
    array([[1.6, 0. ],
           [0. , 1.6]])
    """
    means = require_finite(float_array(means, "means"), "means")
    if means.ndim != 2 or 0 in means.shape:
        raise ValueError(f"means must be a (k, n) array of k >= 1 estimates; got shape {means.shape}")
    k, n = means.shape
    covs = float_array(covs, "covs")
    if covs.shape != (k, n, n):
        raise ValueError(f"Incompatible dimensions of covs; expected (k, n, n) = ({k}, {n}, {n}) for means of "
                         f"shape {means.shape} but found {covs.shape}")
    check_covariance(covs, "covs", definite=True)
    infos = symmetric_part(np.linalg.inv(covs))
    if isinstance(weights, str) or weights is None:
        if weights is None:
            w = np.full(k, 1.0 / k)
        elif weights in ("trace", "det"):
            w = ci_weights(infos, weights)
        else:
            raise ValueError(f"weights must be 'trace', 'det', None or a (k,) array; got {weights!r}")
    else:
        w = require_finite(float_array(weights, "weights"), "weights")
        if w.shape != (k,):
            raise ValueError(f"Incompatible dimensions of weights; expected ({k},) but found {w.shape}")
        if np.any(w < 0) or abs(w.sum() - 1.0) > 1e-9:
            raise ValueError(f"weights must be non-negative and sum to 1; got {w.tolist()}")
    info = np.einsum("k,kij->ij", w, infos)
    P = symmetric_part(np.linalg.inv(info))
    x = P @ np.einsum("k,kij,kj->i", w, infos, means)
    return finite_result("covariance intersection", x, P, w, advice="the covariances are too close to singular")


# --------------------------------------------------------------------------------------------
# the methods of the common-target and localization tasks (mascore.compare, mascore.agent_cost)


_CONSENSUS = {  # kind -> (filter of L steps, filter_cost name)
    "ci": (lambda m, L: ConsensusOnInformationFilter(m, L), "consensus-on-information"),
    "hcmci": (lambda m, L: ConsensusOnInformationFilter(m, L, novelty_weight="N"), "hcmci"),
    "icf": (lambda m, L: InformationConsensusFilter(m, L), "information-consensus"),
}


def _consensus_spec(kind: str, L: int | str, position: float, role: str = "recipe") -> MethodSpec:
    """The spec of `kind` at L consensus steps, or at ``L = "diam"``: the diameter of the model's graph.

    Its knob is L (family `kind`; the setting None: the diameter). The count of ``-Ldiam`` takes the
    ring's diameter, ``N // 2`` (the graph of the cost tables).
    """
    build, cost_name = _CONSENSUS[kind]
    steps = graph_diameter if L == "diam" else (lambda model, L=L: L)
    return MethodSpec(f"{kind}-L{L}", TASKS, lambda model: build(model, steps(model)),
                      spec_cost(cost_name, None if L == "diam" else L),
                      spec_orders(("O(n^3 + L d n^2)", "O(d n^2)"), ("O(N^3 + L d N^2)", "O(d N^2)")),
                      spec_memory(2 if kind == "hcmci" else 1), position=position, role=role, family=kind,
                      setting=None if L == "diam" else float(L))


def _safe_hcmci_spec(L: int, position: float) -> MethodSpec:
    """HCMCI at L steps with the largest novelty weight its consistency condition allows (:func:`safe_novelty_weight`).

    A setting of the knob omega of ``hcmci-L<L>`` (the setting None: computed for the model's graph).
    """
    return MethodSpec(f"hcmci-safe-L{L}", TASKS,
                      lambda model: ConsensusOnInformationFilter(model, L, novelty_weight=safe_novelty_weight(model, L)),
                      spec_cost("hcmci", L), spec_orders(("O(n^3 + L d n^2)", "O(d n^2)"), ("O(N^3 + L d N^2)", "O(d N^2)")),
                      spec_memory(2), position=position, role="knob", family=f"hcmci-L{L}")


def graph_diameter(model: SensorNetworkModel) -> int:
    """The diameter of the model's communication graph: the most hops between two agents.

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph (connected).

    Returns
    -------
    int
        The largest shortest-path length; L = diameter consensus steps let every agent's
        information reach every other.

    Raises
    ------
    ValueError
        The graph is not connected (no diameter).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion, graphs
    >>> model = fusion.SensorNetworkModel([[1.0]], [[0.0]], [[[1.0]]] * 8, [[[1.0]]] * 8, graphs.ring_graph(8))
    >>> fusion.graph_diameter(model)
    4
    """
    N = model.n_agents
    step = (np.asarray(model.adjacency) > 0) | np.eye(N, dtype=bool)
    reach, hops = np.eye(N, dtype=bool), 0
    while not reach.all():
        grown = (reach.astype(int) @ step.astype(int)) > 0
        if (grown == reach).all():
            raise ValueError("the model's graph is not connected: it has no diameter")
        reach, hops = grown, hops + 1
    return hops


def safe_novelty_weight(model: SensorNetworkModel, n_consensus: int) -> float:
    """HCMCI's largest novelty weight that keeps it consistent: ``1 / max [W^L]_ij`` over agents i and sensors j.

    :class:`ConsensusOnInformationFilter`'s condition: agent j's measurement noise enters agent
    i's information ``w [W^L]_ij`` times, so ``w [W^L]_ij <= 1`` for every agent i and every
    agent j that senses keeps the covariance-intersection argument (CI is ``w = 1``; HCMCI's
    ``w = N`` meets it only as L grows without bound).

    Parameters
    ----------
    model : SensorNetworkModel
        The sensing and the graph (its Metropolis weights W).
    n_consensus : int
        L >= 0.

    Returns
    -------
    float
        ``w >= 1``.

    Examples
    --------
    >>> from mascore import compare, fusion
    >>> round(fusion.safe_novelty_weight(compare.target_model(8), 1), 6)    # the ring's Metropolis weights are 1/3
    3.0
    """
    L = check_positive_int(n_consensus, "n_consensus", minimum=0)
    WL = np.linalg.matrix_power(model.weights, L)
    sensing = np.array([H.shape[0] > 0 for H in model.H])
    return float(1.0 / WL[:, sensing].max())


#: The methods of the common-target and localization tasks, in table order (``-L<k>``: k consensus steps per update).
METHODS = (
    MethodSpec("centralized", TASKS, CentralizedFilter, spec_cost("centralized"),
               spec_orders(("O(N q^2 + n^3) at the centre", "O(n^2 + N q)"),
                       ("O(N^3) at the centre (n = 2N, N d q)", "O(N^2)")), centre_memory, whole_filter=True,
               position=0),
    MethodSpec("local", TASKS, lambda model: ConsensusOnInformationFilter(model, 0),
               spec_cost("consensus-on-information", 0, degree=False),
               spec_orders(("O(n^3)", "O(n^2)"), ("O(N^3): n = 2N", "O(N^2)")), spec_memory(), position=1),
    MethodSpec("forwarding", TASKS, MeasurementForwardingFilter, spec_cost("measurement-forwarding"),
               spec_orders(("O(d q n + n^3)", "O(n^2 + d q)"), ("O(N^3)", "O(N^2)")), spec_memory(), position=2),
    *(_consensus_spec(kind, L, 3 + 2 * k + j) for k, kind in enumerate(_CONSENSUS) for j, L in enumerate((1, 5))),
    MethodSpec("diffusion", TASKS, DiffusionKalmanFilter, spec_cost("diffusion-kf"),
               spec_orders(("O(d q n + n^3)", "O(n^2 + d n)"), ("O(N^3)", "O(N^2)")), spec_memory(), position=9),
    MethodSpec("ci-diffusion", TASKS, CovarianceIntersectionFilter, spec_cost("covariance-intersection", 20),
               spec_orders(("O(n^3 + s d n^2): s weight-search evaluations", "O(d n^2)"), ("O(N^3 + s d N^2)", "O(d N^2)")),
               spec_memory(1), position=10,
               max_agents={"localization": (32, "its covariance-intersection weight search (Newton steps over the d + 1 "
                                                "information matrices of 2N x 2N, per agent and step) grows as N^4 per "
                                                "agent: at N = 64 one method would take most of the full grid's time")},
               step_max_agents={}),  # one agent's step, timed alone, to N = 128
    # the knobs' other settings (the comparison sweeps them at N = 8: mascore.compare.FUSION_KNOB_METHODS)
    *(_consensus_spec(kind, L, 11 + 2 * k + j, "knob") for k, kind in enumerate(_CONSENSUS)
      for j, L in enumerate((2, "diam"))),
    *(_safe_hcmci_spec(L, 17 + j) for j, L in enumerate((1, 5))),
    # then mascore.fusion_forwarding's: the Kalman-consensus filter and the set-membership filter
)


# --------------------------------------------------------------------------------------------
# kernels (checked arguments)


def _settings_for_any_graph(filt: _NetworkFilter) -> tuple:
    """A filter's constructor arguments after the model, with its graph-dependent defaults left to the new graph."""
    model = filt.model
    if isinstance(filt, DiffusionKalmanFilter):
        if not np.array_equal(filt.weights, model.weights):
            raise ValueError("filt: a DiffusionKalmanFilter with its own weights matrix belongs to one graph; build it "
                             "with weights='metropolis' to follow a switching graph")
        return ("metropolis",)
    if isinstance(filt, InformationConsensusFilter):
        d_max = int((model.adjacency > 0).sum(axis=1).max())
        default = 0.65 / d_max if d_max else 0.0
        return (filt.n_iterations, None if filt.rate == default else filt.rate)
    return filt._args()
