"""Links that lose, delay or withhold messages: packet loss, one-step latency and send-on-delta for the fusion filters.

Three departures from the ideal links of :mod:`mascore.fusion`, each stated once here:

**Packet loss** (:func:`lossy_graphs`): at every step each link of the graph is lost with
probability ``p``, independently across links and steps, in both directions at once (a
failed exchange; the loss is symmetric, so the step's graph stays undirected). A lost
message is not received that step and nothing stands in for it: each filter fuses what
arrived, with its own weights recomputed on the graph of the links that delivered (the
Metropolis weights ``1 / (1 + max(d_i, d_j))`` of Xiao, Boyd and Lall (2005), whose rule
is built for links that fail, so each row is again a convex combination of the received
neighbours and the agent itself; ICF's ``I - eps L`` with its default ``eps = 0.65 / d_max``
of that graph). That is the switching-graph mechanism: the step's filter is the method's
own, built on the step's graph (:func:`mascore.fusion.track`).

**One-step latency** and **send-on-delta** (:func:`track_messages`), for the filters whose
agents send one density per step (:class:`~mascore.fusion.ConsensusOnInformationFilter` at
``L = 1`` and :class:`~mascore.fusion.InformationConsensusFilter` at ``K = 1``): agent i
fuses its own fresh pair with the pairs its neighbours sent, weighted as in one round::

    (Omega_i, q_i)+ = W_ii (Omega_i, q_i) + sum_j W_ij (Omega_j, q_j)^received.

A received pair that is ``s`` steps old is the sender's density (mean ``Omega^{-1} q``,
information ``c Omega``, ``c = pair_scale``) predicted ``s`` steps with the model's F and Q, as
Battistelli, Chisci and Selvi (2018) do with the last received estimate; a predicted
density is still a consistent one, so CI stays consistent. With latency every pair arrives
one step after it was sent (at the first step none has arrived: each agent fuses its own
alone). Under send-on-delta agent j re-sends only when the mean of its new pair has moved
from the mean of the last one it sent (predicted to the step, as its neighbours hold it) by
more than ``delta`` in the Mahalanobis distance under its predicted covariance ``P_j-`` (the
uncertainty it holds before the step, the same for every method),
``sqrt((m_j - m_sent)^T P_j-^{-1} (m_j - m_sent)) > delta`` (the first step always sends);
otherwise its neighbours use the last received. ``delta = 0`` sends at every step (almost
surely: a sure zero move never happens with noisy measurements).

.. rubric:: References

- Xiao, L., Boyd, S., Lall, S. (2005). A scheme for robust distributed sensor fusion based on average
  consensus. Proc. IPSN, 63-70.
- Battistelli, G., Chisci, L., Selvi, D. (2018). A distributed Kalman filter with event-triggered
  communication and guaranteed stability. Automatica 93, 75-82.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._fusion_kernels import symmetric_part
from ._validation import check_adjacency, check_positive_int, float_array, require_finite
from .fusion import ConsensusOnInformationFilter, InformationConsensusFilter

__all__ = ["lossy_graphs", "track_messages"]


def lossy_graphs(adjacency: ArrayLike, loss: float, n_steps: int, rng: np.random.Generator | int | None,
                 ) -> np.ndarray:
    """The graphs of the links that delivered at each step, each link lost with probability `loss`.

    One uniform number per undirected link and step decides: the link is lost at step k when
    its number is below `loss`, in both directions. The same generator state gives nested
    patterns (a link lost at ``loss = 0.1`` is lost at 0.3 too).

    Parameters
    ----------
    adjacency : (N, N) array_like or (K, N, N) array_like
        The graph (or one graph per step, e.g. a switching topology), undirected, entries 0 or positive.
    loss : float
        ``0 <= loss < 1``.
    n_steps : int
        K >= 1 steps.
    rng : numpy.random.Generator or int or None
        The source of the losses.

    Returns
    -------
    (K, N, N) ndarray
        ``adjacency`` with the lost links zeroed, per step, symmetric.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion_links, graphs
    >>> G = fusion_links.lossy_graphs(graphs.ring_graph(8), 0.3, 200, rng=0)
    >>> G.shape, bool((G == G.transpose(0, 2, 1)).all()), round(float(1 - G.sum() / (200 * 16)), 2)
    ((200, 8, 8), True, 0.29)
    """
    K = check_positive_int(n_steps, "n_steps")
    A = float_array(adjacency, "adjacency")
    if A.ndim == 2:
        A = np.broadcast_to(A, (K, *A.shape))
    if A.ndim != 3 or A.shape[0] != K:
        raise ValueError(f"adjacency must be (N, N) or (n_steps, N, N) = ({K}, N, N); got shape {A.shape}")
    for k in range(A.shape[0] if A.strides[0] else 1):
        check_adjacency(A[k], f"adjacency[{k}]" if A.strides[0] else "adjacency", size=A.shape[1],
                        undirected=True, why="a lost exchange is lost in both directions")
    p = float(loss)
    if not 0.0 <= p < 1.0:
        raise ValueError(f"loss must be a probability in [0, 1); got {loss!r}")
    N = A.shape[1]
    iu = np.triu_indices(N, 1)
    u = np.random.default_rng(rng).random((K, len(iu[0])))
    keep = np.zeros((K, N, N), dtype=bool)
    keep[:, iu[0], iu[1]] = u >= p
    keep |= keep.transpose(0, 2, 1)
    return np.where(keep, A, 0.0)


def track_messages(filters: Sequence[ConsensusOnInformationFilter | InformationConsensusFilter], x0: ArrayLike,
                   P0: ArrayLike, z: ArrayLike, *, latency: int = 0, send_delta: float | None = None,
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run a one-round consensus filter whose messages arrive late or only on change (see the module's text).

    Parameters
    ----------
    filters : sequence of K filters
        The filter of each step, one class, built on the step's graph (one filter repeated on a fixed
        graph): :class:`~mascore.fusion.ConsensusOnInformationFilter` with ``n_consensus = 1`` and
        ``novelty_weight = 1``, or :class:`~mascore.fusion.InformationConsensusFilter` with
        ``n_iterations = 1``; their sensing must be the same.
    x0 : (..., N, n) or (n,) array_like
        Initial means.
    P0 : (..., N, n, n) or (n, n) array_like
        Initial covariances, symmetric positive definite.
    z : (K, ..., sum q_i) array_like
        Measurements of steps 1..K.
    latency : {0, 1}
        Steps a message takes to arrive.
    send_delta : float, optional
        Send-on-delta threshold (a Mahalanobis distance, in standard deviations, >= 0); None: every
        agent sends at every step.

    Returns
    -------
    x : (K, ..., N, n) ndarray
        Each agent's estimate after each step.
    P : (K, ..., N, n, n) ndarray
        Their covariances (leading axes those of `P0`; with `send_delta` they depend on the data: one per run).
    sent : (K, ..., N) ndarray of bool
        Whether agent i sent its pair at step k (all True without `send_delta`).

    Raises
    ------
    ValueError, TypeError
        A filter of another kind or with more rounds, filters of different sensing, a bad latency
        or threshold, shapes that do not fit.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import compare, fusion, fusion_links
    >>> model = compare.target_model(8)
    >>> x_true, z = model.simulate(np.zeros(4), np.eye(4), 100, rng=0, n_runs=5)
    >>> ci = fusion.ConsensusOnInformationFilter(model, 1)
    >>> x, P, sent = fusion_links.track_messages([ci] * 100, np.zeros(4), np.eye(4), z, send_delta=0.5)
    >>> x.shape, P.shape, bool(0 < sent.mean() < 1)
    ((100, 5, 8, 4), (100, 5, 8, 4, 4), True)
    >>> xa, Pa = ci.run(np.zeros(4), np.eye(4), z)
    >>> xb, Pb, _ = fusion_links.track_messages([ci] * 100, np.zeros(4), np.eye(4), z)   # ideal links: CI
    >>> bool(np.allclose(xa, xb) and np.allclose(Pa, Pb))
    True
    """
    filters = list(filters) if not isinstance(filters, (str, bytes)) else None
    if not filters:
        raise TypeError("filters must be a non-empty sequence of the step filters (one per step)")
    first = filters[0]
    kind = type(first)
    if kind is ConsensusOnInformationFilter:
        bad = [f for f in filters if type(f) is not kind or f.n_consensus != 1 or f.novelty_weight != 1.0]
    elif kind is InformationConsensusFilter:
        bad = [f for f in filters if type(f) is not kind or f.n_iterations != 1]
    else:
        bad = [first]
    if bad:
        raise ValueError("filters must all be ConsensusOnInformationFilter(model, 1) (CI) or all "
                         "InformationConsensusFilter(model, 1): one density sent per step; got "
                         f"{type(bad[0]).__name__}")
    model = first.model
    if send_delta is not None and any(not np.array_equal(f.model.adjacency, model.adjacency) for f in filters):
        raise ValueError("send_delta needs one graph for every step: a sender's neighbours hold its last sent pair "
                         "only if every send reached them")
    if any(f.model.H_stacked.shape != model.H_stacked.shape or not np.array_equal(f.model.H_stacked, model.H_stacked)
           or not np.array_equal(f.model.R_stacked, model.R_stacked) for f in filters):
        raise ValueError("filters must share the sensing (H, R) of their models; only the graph may change")
    if latency not in (0, 1) or isinstance(latency, bool):
        raise ValueError(f"latency must be 0 or 1 (steps); got {latency!r}")
    if send_delta is not None:
        send_delta = float(send_delta)
        if not (np.isfinite(send_delta) and send_delta >= 0):
            raise ValueError(f"send_delta must be a finite distance >= 0 or None; got {send_delta!r}")
    x, P = model.check_state(x0, P0, ("x0", "P0"), per_agent=True)
    z = require_finite(model._check_z(z), "z")
    if z.ndim < 2 or z.shape[0] != len(filters):
        raise ValueError(f"z must be (K, ..., {model.n_measurements}) with K = {len(filters)} (one filter per step); "
                         f"got shape {z.shape}")
    batch = np.broadcast_shapes(x.shape[:-2], P.shape[:-3], z.shape[1:-1])
    N, n = model.n_agents, model.n_states
    if send_delta is not None:  # the sends depend on the data, and then so do the covariances: one per run
        x, P = np.broadcast_to(x, (*batch, N, n)), np.broadcast_to(P, (*batch, N, n, n))
    c = first.pair_scale
    held = None       # the pairs the neighbours hold of each sender: its last sent, predicted to this step
    arrived = None    # with latency: the pairs sent at the step before, predicted to this step
    xs, Ps, sents = [], [], []
    for k, f in enumerate(filters):
        xp, Pp = f.predict(x, P)
        Om, q = f.message_pair(xp, Pp, z[k])
        sent = np.ones((*batch, N), dtype=bool)
        if held is not None and send_delta is not None:  # the new pair's mean against the one the neighbours hold
            held = _predict_pair(model, c, *held)
            d = np.linalg.solve(Om, q[..., None])[..., 0] - np.linalg.solve(held[0], held[1][..., None])[..., 0]
            sent = np.einsum("...a,...a->...", d, np.linalg.solve(Pp, d[..., None])[..., 0]) > send_delta**2
        held = (Om, q) if held is None or send_delta is None else (np.where(sent[..., None, None], Om, held[0]),
                                             np.where(sent[..., None], q, held[1]))
        W = f.round_weights
        if latency:
            received, arrived = arrived, _predict_pair(model, c, *held)
            if received is None:  # the first step: nothing has arrived, each agent keeps its own pair
                W = np.eye(N)
                received = held
        else:
            received = held
        off = W - np.diag(np.diag(W))
        w_self = np.diag(W)
        Om_f = w_self[:, None, None] * Om + np.einsum("ij,...jab->...iab", off, received[0])
        q_f = w_self[:, None] * q + np.einsum("ij,...ja->...ia", off, received[1])
        x, P = f.pair_estimate(symmetric_part(Om_f), q_f)
        xs.append(x)
        Ps.append(P)
        sents.append(sent)
    return np.stack(xs), np.stack(Ps), np.stack(sents)


def _predict_pair(model, c: float, Om: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A sent pair one step on: its density (mean ``Om^{-1} q``, information ``c Om``) predicted with F, Q."""
    Pc = symmetric_part(np.linalg.inv(c * Om))
    x = (Pc @ q[..., None])[..., 0] * c
    F, Q = model.F, model.Q
    x, Pc = x @ F.T, symmetric_part(F @ Pc @ F.T + Q)
    Om_new = symmetric_part(np.linalg.inv(Pc)) / c
    return Om_new, (Om_new @ x[..., None])[..., 0]
