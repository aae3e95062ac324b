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

**Loss per direction** (:func:`lossy_graphs` with ``per_direction=True``, for measurement
forwarding (:func:`track_forwarding`) and the one-round filters of :func:`track_messages`):
each message ``j -> i`` is lost with probability ``p`` independently of ``i -> j``, of the other
links, of the steps and, with ``n_runs``, of the runs (one pattern per run). An agent does
not know what its neighbours received, so it cannot rebuild weights on the step's graph:
it keeps the weights of the ideal graph and gives the weight of a message it did not
receive to its own pair (the compensation of Fagnani and Zampieri (2009)), so each row is
still a convex combination of what it holds; forwarding fuses the measurements that
arrived, exactly.

**One-step latency**: every message arrives one step after it was sent; what is sent is what
the agent sends on ideal links, computed from what it holds when it sends. Two treatments,
each the standard one for what the message carries:

- *Consensus on pairs* (:func:`track_messages`: CI, HCMCI and ICF at any number of rounds, the
  filters whose messages are information pairs): agent i fuses its own fresh pairs with the
  pairs its neighbours sent, weighted as in one round::

      (Omega_i, q_i)^l = W_ii (Omega_i, q_i)^{l-1} + sum_j W_ij (Omega_j, q_j)^{l-1, received},

  for ``l = 1..L``. A received pair that is ``s`` steps old is the sender's density (mean
  ``Omega^{-1} q``, information ``c Omega``, ``c`` its ``pair_scales`` entry) predicted ``s`` steps
  with the model's F and Q, as Battistelli, Chisci and Selvi (2018) do with the last received
  estimate; a predicted density is still a consistent one, so CI stays consistent. HCMCI's
  novelty pair is a measurement's information, not a density: received late, it is the
  information of a measurement of the state of the step before, predicted as an information
  pair (``M = F^{-T} dOmega F^{-1}``, ``dOmega' = (I + M Q)^{-1} M``, ``dq' = (I + M Q)^{-1} F^{-T} dq``,
  which is the late measurement taken as one of the current state with the step's process noise
  added to its noise; F must be invertible); like HCMCI itself it ignores the correlation this
  noise has with the prior's. With ``L > 1`` the rounds are pipelined across steps: the message of
  round l at step k (the sender's pairs after round ``l - 1``) is fused in round l at step
  ``k + 1``, so information from l hops away is l steps old and each agent still sends L
  messages per step. At the first step nothing has arrived: each agent keeps its own pairs.
- *Forwarded measurements* (:func:`track_behind`: forwarding, the Kalman-consensus filter, the
  set-membership filter, the diffusion filters): a late measurement is not a density to predict;
  the exact way to use it is to filter it at the step it belongs to (the re-run that the one-lag
  out-of-sequence update of Bar-Shalom (2002) reproduces without re-running). The messages of
  step k have all arrived at step ``k + D`` (D the filter's ``exchanges``: the exchanges of one
  step that follow one another, 1, or 2 for the diffusion filters, whose estimates are computed
  from the measurements just exchanged), so each agent runs the method's own filter D steps
  behind, exactly as on ideal links, and takes it to the step with its own fresh measurements
  (its own Kalman update, or set update). For forwarding this is an exact Kalman filter on older
  data; for the Kalman-consensus filter it is Olfati-Saber's filter itself one step behind (an
  agent sends, with its measurement, the prediction of its filter behind, which is what the
  neighbours' consensus terms take).

**Send-on-delta** (:func:`track_messages`, for the filters whose agents send one density per step:
:class:`~mascore.fusion.ConsensusOnInformationFilter` at ``L = 1`` and
:class:`~mascore.fusion.InformationConsensusFilter` at ``K = 1``; with or without latency): agent j
re-sends only when the mean of its new pair has moved
from the mean of the last one it sent (predicted to the step, as its neighbours hold it) by
more than ``delta`` in the Mahalanobis distance under its predicted covariance ``P_j-`` (the
uncertainty it holds before the step, the same for every method),
``sqrt((m_j - m_sent)^T P_j-^{-1} (m_j - m_sent)) > delta`` (the first step always sends);
otherwise its neighbours use the last received. ``delta = 0`` sends at every step (almost
surely: a sure zero move never happens with noisy measurements). Over links that lose messages one
direction at a time, each receiver keeps its own copy of each neighbour's last pair that reached it
(predicted to the step), and a neighbour it has not heard from yet has its weight on its own pair.

.. rubric:: References

- Xiao, L., Boyd, S., Lall, S. (2005). A scheme for robust distributed sensor fusion based on average
  consensus. Proc. IPSN, 63-70.
- Fagnani, F., Zampieri, S. (2009). Average consensus with packet drop communication. SIAM J. Control
  Optim. 48(1), 102-133.
- Battistelli, G., Chisci, L., Selvi, D. (2018). A distributed Kalman filter with event-triggered
  communication and guaranteed stability. Automatica 93, 75-82.
- Bar-Shalom, Y. (2002). Update with out-of-sequence measurements in tracking: exact solution. IEEE Trans.
  Aerospace and Electronic Systems 38(3), 769-777.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from ._fusion_kernels import information_update, symmetric_part
from ._validation import (
    check_adjacency,
    check_fits_in_memory,
    check_generator,
    check_positive,
    check_positive_int,
    check_probability,
    check_steps,
    float_array,
    require_finite,
)
from .fusion import ConsensusOnInformationFilter, InformationConsensusFilter, MeasurementForwardingFilter
from .fusion_forwarding import SetMembershipForwardingFilter

__all__ = ["delivered_weights", "lossy_graphs", "track_behind", "track_forwarding", "track_messages"]


def lossy_graphs(adjacency: ArrayLike, loss: float, n_steps: int, rng: np.random.Generator | int, *,
                 per_direction: bool = False, n_runs: int | None = None) -> np.ndarray:
    """The graphs of the links that delivered at each step, each link lost with probability `loss`.

    One uniform number per undirected link and step decides: the link is lost at step k when
    its number is below `loss`, in both directions. The same generator state gives nested
    patterns (a link lost at ``loss = 0.1`` is lost at 0.3 too). With `per_direction` one
    number per message ``j -> i`` (``A[i, j] > 0``) decides instead: the graph of a step is
    directed (``G[k, i, j] > 0``: i received j's message). With `n_runs`, one pattern per run.

    Parameters
    ----------
    adjacency : (N, N) array_like or (K, N, N) array_like
        The graph (or one graph per step, e.g. a switching topology), undirected, entries 0 or positive.
    loss : float
        ``0 <= loss < 1``.
    n_steps : int
        K >= 1 steps (at most ``MAX_STEPS``).
    rng : numpy.random.Generator or int
        The source of the losses (a generator or a non-negative seed).
    per_direction : bool
        Lose each direction of a link independently (default: both at once).
    n_runs : int, optional
        R >= 1 runs, each with its own pattern (default: one pattern for every run).

    Returns
    -------
    (K, N, N) or (K, R, N, N) ndarray
        ``adjacency`` with the lost messages zeroed, per step (and run); symmetric unless `per_direction`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import fusion_links, graphs
    >>> G = fusion_links.lossy_graphs(graphs.ring_graph(8), 0.3, 200, rng=0)
    >>> G.shape, bool((G == G.transpose(0, 2, 1)).all()), round(float(1 - G.sum() / (200 * 16)), 2)
    ((200, 8, 8), True, 0.29)
    >>> D = fusion_links.lossy_graphs(graphs.ring_graph(8), 0.3, 200, rng=0, per_direction=True, n_runs=5)
    >>> D.shape, bool((D == D.transpose(0, 1, 3, 2)).all())
    ((200, 5, 8, 8), False)
    """
    K = check_steps(n_steps, "n_steps")
    p = check_probability(loss, "loss")
    if p >= 1.0:
        raise ValueError(f"loss must be a probability in [0, 1); got {loss!r}")
    rng = check_generator(rng, "rng")
    A = float_array(adjacency, "adjacency")
    if A.ndim == 2:
        A = np.broadcast_to(A, (K, *A.shape))
    if A.ndim != 3 or A.shape[0] != K:
        raise ValueError(f"adjacency must be (N, N) or (n_steps, N, N) = ({K}, N, N); got shape {A.shape}")
    for k in range(A.shape[0] if A.strides[0] else 1):
        check_adjacency(A[k], f"adjacency[{k}]" if A.strides[0] else "adjacency", size=A.shape[1],
                        undirected=True, why="a lost exchange is lost in both directions")
    runs = () if n_runs is None else (check_positive_int(n_runs, "n_runs"),)
    N = A.shape[1]
    check_fits_in_memory(2 * 8.0 * K * (runs[0] if runs else 1) * N * N, "n_runs" if runs else "n_steps",
                         "the graphs of every step (and run)")
    if runs:
        A = A[:, None]
    if per_direction:  # one number per ordered pair: a message j -> i is lost alone
        u = rng.random((K, *runs, N, N))
        return np.where(u >= p, A, 0.0)
    iu = np.triu_indices(N, 1)
    u = rng.random((K, *runs, len(iu[0])))
    keep = np.zeros((K, *runs, N, N), dtype=bool)
    keep[..., iu[0], iu[1]] = u >= p
    keep |= np.swapaxes(keep, -1, -2)
    return np.where(keep, A, 0.0)


def delivered_weights(W: ArrayLike, delivered: ArrayLike) -> np.ndarray:
    """One consensus round's weights when some messages are lost: a lost message's weight goes to the receiver.

    ``W'_ij = W_ij`` if i received j's message, else 0; ``W'_ii = 1 - sum_{j != i} W'_ij`` (Fagnani and
    Zampieri 2009): each row stays a convex combination when `W`'s rows are.

    Parameters
    ----------
    W : (N, N) array_like
        The weights on ideal links, rows summing to one.
    delivered : (..., N, N) array_like
        Positive where i received j's message (``delivered[..., i, j]``); the diagonal is ignored.

    Returns
    -------
    (..., N, N) ndarray
        The weights of each pattern.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore.fusion_links import delivered_weights
    >>> W = np.full((3, 3), 1 / 3)
    >>> delivered_weights(W, [[0, 1, 0], [1, 0, 1], [1, 1, 0]])[0]   # agent 0 lost agent 2's message
    array([0.66666667, 0.33333333, 0.        ])
    """
    W = require_finite(float_array(W, "W"), "W")
    D = require_finite(float_array(delivered, "delivered"), "delivered")
    if W.ndim != 2 or W.shape[0] != W.shape[1] or D.shape[-2:] != W.shape:
        raise ValueError(f"W must be (N, N) and delivered (..., N, N) of the same N; got {W.shape}, {D.shape}")
    off = np.where(D > 0, W - np.diag(np.diag(W)), 0.0)
    eye = np.eye(W.shape[0], dtype=bool)
    return np.where(eye, (1.0 - off.sum(-1))[..., None], off)


def track_messages(filters: Sequence[ConsensusOnInformationFilter | InformationConsensusFilter], x0: ArrayLike,
                   P0: ArrayLike, z: ArrayLike, *, latency: int = 0, send_delta: float | None = None,
                   delivered: ArrayLike | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Run a consensus filter on information pairs whose messages arrive late or only on change (see the module's text).

    Parameters
    ----------
    filters : sequence of K filters
        The filter of each step, one class and one setting, built on the step's graph (one filter
        repeated on a fixed graph): :class:`~mascore.fusion.ConsensusOnInformationFilter` (CI, or HCMCI
        with ``novelty_weight != 1``) or :class:`~mascore.fusion.InformationConsensusFilter`, any number
        of rounds; their sensing must be the same. With `send_delta` or `delivered`: one round and one
        density per step (CI at ``n_consensus = 1``, ICF at ``n_iterations = 1``).
    x0 : (..., N, n) or (n,) array_like
        Initial means.
    P0 : (..., N, n, n) or (n, n) array_like
        Initial covariances, symmetric positive definite.
    z : (K, ..., sum q_i) array_like
        Measurements of steps 1..K.
    latency : {0, 1}
        Steps a message takes to arrive (with several rounds: each round's message; the rounds are
        pipelined across steps). HCMCI with latency needs an invertible F.
    send_delta : float, optional
        Send-on-delta threshold (a Mahalanobis distance, in standard deviations, >= 0); None: every
        agent sends at every step.
    delivered : (K, ..., N, N) array_like, optional
        Positive where agent i received j's message at step k (:func:`lossy_graphs` with
        ``per_direction=True``, one pattern per run or one for all); the weight of a lost one goes to
        the receiver's own pair (:func:`delivered_weights`). None: every message arrives. With
        `send_delta` each receiver holds the last pair it received from each neighbour, predicted to
        the step, and fuses that; a neighbour it never heard from has its weight on the receiver's own
        pair. A sender decides from the last pair it sent. With `latency` the pattern of step k is
        that of the messages arriving at step k.

    Returns
    -------
    x : (K, ..., N, n) ndarray
        Each agent's estimate after each step.
    P : (K, ..., N, n, n) ndarray
        Their covariances (leading axes those of `P0`; with `send_delta` they depend on the data, with
        `delivered` on its pattern: one per run).
    sent : (K, ..., N) ndarray of bool
        Whether agent i sent its pair at step k (all True without `send_delta`).

    Raises
    ------
    ValueError, TypeError
        A filter of another kind, filters of different settings or sensing, several rounds or
        HCMCI with `send_delta` or `delivered`, HCMCI late with a singular F, a bad latency or
        threshold, shapes that do not fit.

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
    >>> hcmci = fusion.ConsensusOnInformationFilter(model, 5, novelty_weight="N")
    >>> x, P, _ = fusion_links.track_messages([hcmci] * 100, np.zeros(4), np.eye(4), z, latency=1)  # 5 rounds, late
    >>> bool(np.all(np.linalg.eigvalsh(P) > 0))
    True
    """
    filters = list(filters) if not isinstance(filters, (str, bytes)) else None
    if not filters:
        raise TypeError("filters must be a non-empty sequence of the step filters (one per step)")
    first = filters[0]
    kind = type(first)
    if kind not in (ConsensusOnInformationFilter, InformationConsensusFilter):
        raise ValueError("filters must all be ConsensusOnInformationFilter (CI, HCMCI) or all "
                         f"InformationConsensusFilter: consensus on information pairs; got {kind.__name__}")
    def setting(f):  # the rounds and the pairs (ICF's rate follows each step's graph)
        return type(f), f.exchanges, getattr(f, "novelty_weight", None)

    bad = [f for f in filters if setting(f) != setting(first)]
    if bad:
        raise ValueError(f"filters must all be {kind.__name__} with the same rounds and novelty weight; got "
                         f"{bad[0]!r} after {first!r}")
    one_density = first.exchanges == 1 and len(first.pair_scales) == 1
    if (send_delta is not None or delivered is not None) and not one_density:
        raise ValueError("send_delta and delivered need one density sent per step: ConsensusOnInformationFilter(model, 1) "
                         f"(CI) or InformationConsensusFilter(model, 1); got {first!r}")
    model = first.model
    if send_delta is not None and any(not np.array_equal(f.model.adjacency, model.adjacency) for f in filters):
        raise ValueError("send_delta needs one graph for every step: a sender's neighbours hold its last sent pair "
                         "only if every send reached them")
    if any(f.model.H_stacked.shape != model.H_stacked.shape or not np.array_equal(f.model.H_stacked, model.H_stacked)
           or not np.array_equal(f.model.R_stacked, model.R_stacked) for f in filters):
        raise ValueError("filters must share the sensing (H, R) of their models; only the graph may change")
    if latency not in (0, 1) or isinstance(latency, bool):
        raise ValueError(f"latency must be 0 or 1 (steps); got {latency!r}")
    if latency and None in first.pair_scales and np.linalg.cond(model.F) > 1e12:
        raise ValueError("latency with HCMCI needs an invertible F: its late novelty pair is a measurement of the state "
                         "of the step before, taken to the step through F^{-1}")
    if send_delta is not None:
        send_delta = check_positive(send_delta, "send_delta", allow_zero=True)
        if send_delta > 1e150:  # its square is the threshold of a squared distance
            raise ValueError(f"send_delta must be a distance from 0 to 1e150 or None; got {send_delta!r}")
    x, P = model.check_state(x0, P0, ("x0", "P0"), per_agent=True)
    z = require_finite(model._check_z(z), "z")
    if z.ndim < 2 or z.shape[0] != len(filters):
        raise ValueError(f"z must be (K, ..., {model.n_measurements}) with K = {len(filters)} (one filter per step); "
                         f"got shape {z.shape}")
    if send_delta is None and delivered is None:
        return (*_track_rounds(filters, x, P, z, latency), np.ones((*z.shape[:-1], model.n_agents), dtype=bool))
    N, n = model.n_agents, model.n_states
    if delivered is not None:
        delivered = require_finite(float_array(delivered, "delivered"), "delivered")
        if delivered.ndim < 3 or delivered.shape[0] != len(filters) or delivered.shape[-2:] != (N, N):
            raise ValueError(f"delivered must be (K, ..., N, N) = ({len(filters)}, ..., {N}, {N}); "
                             f"got shape {delivered.shape}")
    batch = np.broadcast_shapes(x.shape[:-2], P.shape[:-3], z.shape[1:-1],
                                () if delivered is None else delivered.shape[1:-2])
    x, P = np.broadcast_to(x, (*batch, N, n)), np.broadcast_to(P, (*batch, N, n, n))  # one covariance per run
    c = first.pair_scale
    held = None       # the pairs the neighbours hold of each sender: its last sent, predicted to this step
    arrived = None    # with latency: the pairs sent at the step before, predicted to this step
    sent_before = None  # with latency: who sent at the step before (their pairs arrive now)
    copies = None     # send-on-delta over lossy links: per link j -> i, i's copy of j's last pair (..., E, ...)
    heard = None      # per link, whether i has received a pair from j yet
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
        if latency:  # what arrives now: the pairs held at the step before, predicted
            received, arrived = arrived, _predict_pair(model, c, *held)
            source, sent_before = sent_before, sent
            if received is None:  # the first step: nothing has arrived, each agent keeps its own pair
                W = np.eye(N)
                received = held
        else:
            received, source = held, sent
        if delivered is not None and send_delta is not None:  # each receiver fuses its own copies, one per link
            if copies is None:  # the links j -> i of the graph; a placeholder copy until one arrives (weight 0)
                to, frm = np.nonzero((f.round_weights > 0) & ~np.eye(N, dtype=bool))
                into = (to[:, None] == np.arange(N)).T.astype(float)                  # (N, E): link e ends at i
                copies = (received[0][..., frm, :, :], received[1][..., frm, :])
                heard = np.zeros((*batch, len(to)), bool)
            else:
                copies = _predict_pair(model, c, *copies)
            arrive = (np.zeros(heard.shape, bool) if source is None
                      else source[..., frm] & (delivered[k][..., to, frm] > 0))      # (..., E)
            copies = (np.where(arrive[..., None, None], received[0][..., frm, :, :], copies[0]),
                      np.where(arrive[..., None], received[1][..., frm, :], copies[1]))
            heard = heard | arrive
            w_link = np.where(heard, f.round_weights[to, frm], 0.0)                   # (..., E)
            w_self = 1.0 - w_link @ into.T                                           # the rest on the own pair
            Om_f = w_self[..., None, None] * Om + np.einsum("ie,...e,...eab->...iab", into, w_link, copies[0])
            q_f = w_self[..., None] * q + np.einsum("ie,...e,...ea->...ia", into, w_link, copies[1])
        elif delivered is None:
            off = W - np.diag(np.diag(W))
            w_self = np.diag(W)
            Om_f = w_self[:, None, None] * Om + np.einsum("ij,...jab->...iab", off, received[0])
            q_f = w_self[:, None] * q + np.einsum("ij,...ja->...ia", off, received[1])
        else:  # the step's pattern: per run, the lost messages' weights on the receiver's own pair
            Wk = delivered_weights(W, delivered[k])
            w_self = np.diagonal(Wk, axis1=-2, axis2=-1)
            off = Wk * ~np.eye(N, dtype=bool)
            Om_f = w_self[..., None, None] * Om + np.einsum("...ij,...jab->...iab", off, received[0])
            q_f = w_self[..., None] * q + np.einsum("...ij,...ja->...ia", off, received[1])
        x, P = f.pair_estimate(symmetric_part(Om_f), q_f)
        xs.append(x)
        Ps.append(P)
        sents.append(sent)
    return np.stack(xs), np.stack(Ps), np.stack(sents)


def _track_rounds(filters: list, x: np.ndarray, P: np.ndarray, z: np.ndarray,
                  latency: int) -> tuple[np.ndarray, np.ndarray]:
    """Consensus on pairs, every message sent (see :func:`track_messages`): L rounds per step, late or not.

    Round l fuses each agent's pairs after round ``l - 1`` with its neighbours' after round ``l - 1``:
    of this step on ideal timing (the filter's own update, up to rounding: ``W`` applied L times
    instead of ``W^L``), of the step before predicted one step with `latency` (nothing at the first step).
    """
    model = filters[0].model
    scales, L = filters[0].pair_scales, filters[0].exchanges
    arrived = None  # with latency, per round: the neighbours' pairs sent in it at the step before, predicted
    xs, Ps = [], []
    for k, f in enumerate(filters):
        xp, Pp = f.predict(x, P)
        pairs = f.message_pairs(xp, Pp, z[k])
        W = f.round_weights
        w_self, off = np.diag(W), W - np.diag(np.diag(W))
        sent = []
        for r in range(L):
            sent.append(pairs)
            received = pairs if not latency else None if arrived is None else arrived[r]
            if received is not None:
                pairs = tuple((w_self[:, None, None] * Om + np.einsum("ij,...jab->...iab", off, rOm),
                               w_self[:, None] * q + np.einsum("ij,...ja->...ia", off, rq))
                              for (Om, q), (rOm, rq) in zip(pairs, received))
        if latency:
            arrived = [tuple(_late_pair(model, c, *pair) for c, pair in zip(scales, round_pairs))
                       for round_pairs in sent]
        x, P = f.pairs_estimate([(symmetric_part(Om), q) for Om, q in pairs])
        xs.append(x)
        Ps.append(P)
    return np.stack(xs), np.stack(Ps)


def track_behind(filters: Sequence, x0: ArrayLike, P0: ArrayLike, z: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Run a filter on forwarded measurements whose messages each take one step (see the module's text).

    Each agent runs the filter D steps behind (D = its ``exchanges``: the messages of step k have
    all arrived at step ``k + D``), exactly as on ideal links, and its estimate of step k is that
    filter's estimate of step ``k - D`` taken through steps ``k - D + 1 .. k`` by its own filter:
    the prediction and its own fresh measurement's update (a Kalman update: the ``local`` method's;
    for the set-membership filter its set update on its own measurement). Before step D nothing has
    arrived: each agent's own filter alone.

    Parameters
    ----------
    filters : sequence of K filters
        The filter of each step, one class (:class:`~mascore.fusion.MeasurementForwardingFilter`,
        :class:`~mascore.fusion_forwarding.KalmanConsensusNetworkFilter`,
        :class:`~mascore.fusion_forwarding.SetMembershipForwardingFilter`,
        :class:`~mascore.fusion.DiffusionKalmanFilter`, :class:`~mascore.fusion.CovarianceIntersectionFilter`
        or any other of the package's network filters), built on the graph of the step at which a step's
        last messages arrive (filter ``k + D`` runs the filter's step k); their sensing must be the same.
    x0 : (..., N, n) or (n,) array_like
        Initial means (set centres).
    P0 : (..., N, n, n) or (n, n) array_like
        Initial covariances (set shapes), symmetric positive definite.
    z : (K, ..., sum q_i) array_like
        Measurements of steps 1..K.

    Returns
    -------
    x : (K, ..., N, n) ndarray
        Each agent's estimate after each step.
    P : (K, ..., N, n, n) ndarray
        Their covariances (set shapes); leading axes those of `P0`.

    Raises
    ------
    ValueError, TypeError
        Filters of different classes or sensing, the centralized filter (it has no neighbours),
        shapes that do not fit.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import compare, fusion, fusion_links
    >>> model = compare.target_model(8)
    >>> _, z = model.simulate(np.zeros(4), np.eye(4), 50, rng=0, n_runs=3)
    >>> dkf = fusion.DiffusionKalmanFilter(model)
    >>> x, P = fusion_links.track_behind([dkf] * 50, np.zeros(4), np.eye(4), z)
    >>> xr, Pr = dkf.run(np.zeros(4), np.eye(4), z)        # two steps behind: the filter of step k - 2, then own data
    >>> local = fusion.ConsensusOnInformationFilter(model, 0)
    >>> xo, Po = local.update(*local.predict(xr[7], Pr[7]), z[8])
    >>> xo, Po = local.update(*local.predict(xo, Po), z[9])
    >>> bool(np.array_equal(x[9], xo) and np.array_equal(P[9], Po))
    True
    """
    filters = list(filters) if not isinstance(filters, (str, bytes)) else None
    if not filters:
        raise TypeError("filters must be a non-empty sequence of the step filters (one per step)")
    first = filters[0]
    if not first._per_agent:
        raise ValueError(f"filters must be per-agent network filters; got {type(first).__name__} (one estimate for the "
                         "team: the bound keeps ideal links)")
    def setting(f):  # its class and settings (the weights of the step's graph left out)
        return type(f), [a for a in f._args() if not isinstance(a, np.ndarray)]

    if any(setting(f) != setting(first) for f in filters):
        raise ValueError(f"filters must all be {type(first).__name__} of one setting; only the graph may change")
    model = first.model
    if any(not np.array_equal(f.model.H_stacked, model.H_stacked) or not np.array_equal(f.model.R_stacked, model.R_stacked)
           for f in filters):
        raise ValueError("filters must share the sensing (H, R) of their models; only the graph may change")
    x, P = model.check_state(x0, P0, ("x0", "P0"), per_agent=True)
    z = require_finite(model._check_z(z), "z")
    if z.ndim < 2 or z.shape[0] != len(filters):
        raise ValueError(f"z must be (K, ..., {model.n_measurements}) with K = {len(filters)} (one filter per step); "
                         f"got shape {z.shape}")
    if isinstance(first, SetMembershipForwardingFilter):  # its own set update: the filter on the graph without links
        own = SetMembershipForwardingFilter(model.on_graph(np.zeros((model.n_agents,) * 2)), first.confidence)
    else:  # each agent's own Kalman filter (the local method)
        own = ConsensusOnInformationFilter(model, 0)
    D = max(1, first.exchanges)
    K = len(filters)
    behind = (x, P)  # the filter after step k - D (the prior before its first step)
    xs, Ps = [], []
    for k in range(K):
        xo, Po = behind
        for j in range(max(0, k - D + 1), k + 1):  # the steps not yet arrived: own measurements only
            xo, Po = own.update(*own.predict(xo, Po), z[j])
        xs.append(xo)
        Ps.append(Po)
        j = k - D + 1  # the step whose last messages arrive at step k + 1
        if j >= 0 and k + 1 < K:
            f = filters[k + 1]
            behind = f.update(*f.predict(*behind), z[j])
    return np.stack(xs), np.stack(Ps)


def track_forwarding(model, x0: ArrayLike, P0: ArrayLike, z: ArrayLike, delivered: ArrayLike, *,
                     latency: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Measurement forwarding over links that lose messages one direction at a time (and may deliver them late).

    Agent i's update is the exact Kalman update on its own measurement and those of the
    neighbours whose messages it received (:class:`~mascore.fusion.MeasurementForwardingFilter`
    on the step's delivered graph). With ``latency = 1`` the neighbours' measurements of step k
    arrive at step k + 1: agent i runs a Kalman filter one step behind on them, predicts it and
    corrects it with its own fresh measurement (still an exact Kalman filter, on older data).

    Parameters
    ----------
    model : mascore.sensor_network.SensorNetworkModel
        The sensing (its graph is not used: `delivered` says who heard whom).
    x0 : (..., N, n) or (n,) array_like
        Initial means.
    P0 : (..., N, n, n) or (n, n) array_like
        Initial covariances, symmetric positive definite.
    z : (K, ..., sum q_i) array_like
        Measurements of steps 1..K.
    delivered : (K, ..., N, N) array_like
        Positive where agent i received j's measurement at step k (:func:`lossy_graphs`); the
        diagonal is ignored (an agent always has its own).
    latency : {0, 1}
        Steps a message takes to arrive.

    Returns
    -------
    x : (K, ..., N, n) ndarray
        Each agent's estimate after each step.
    P : (K, ..., N, n, n) ndarray
        Their covariances, the error covariances (one per run when `delivered` has one pattern per run).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import compare, fusion, fusion_links
    >>> model = compare.target_model(8)
    >>> x_true, z = model.simulate(np.zeros(4), np.eye(4), 50, rng=0, n_runs=3)
    >>> ideal = np.broadcast_to(model.adjacency, (50, 8, 8))
    >>> x, P = fusion_links.track_forwarding(model, np.zeros(4), np.eye(4), z, ideal)
    >>> xf, Pf = fusion.MeasurementForwardingFilter(model).run(np.zeros(4), np.eye(4), z)
    >>> bool(np.allclose(x, xf) and np.allclose(P, Pf[:, None]))
    True
    """
    forwarding = MeasurementForwardingFilter(model)
    if latency not in (0, 1) or isinstance(latency, bool):
        raise ValueError(f"latency must be 0 or 1 (steps); got {latency!r}")
    x, P = model.check_state(x0, P0, ("x0", "P0"), per_agent=True)
    z = require_finite(model._check_z(z), "z")
    N = model.n_agents
    D = require_finite(float_array(delivered, "delivered"), "delivered")
    if z.ndim < 2 or D.ndim < 3 or D.shape[0] != z.shape[0] or D.shape[-2:] != (N, N):
        raise ValueError(f"delivered must be (K, ..., {N}, {N}) with K = {z.shape[0] if z.ndim else '?'} (the "
                         f"steps of z); got shape {D.shape}")
    heard = np.where(np.eye(N, dtype=bool), 1.0, (D > 0).astype(float))  # (K, ..., N, N): own always
    batch = np.broadcast_shapes(x.shape[:-2], P.shape[:-3], z.shape[1:-1], D.shape[1:-2])
    n = model.n_states
    x, P = np.broadcast_to(x, (*batch, N, n)), np.broadcast_to(P, (*batch, N, n, n))  # one per run (pattern)

    info = model.information_matrices.reshape(N, n * n)

    def correct(x, P, zk, Dk):  # the exact update on the measurements of the agents in Dk's rows
        S = (Dk @ info).reshape(*Dk.shape[:-1], n, n)
        return information_update(x, P, S, Dk @ model._information_vectors(zk))

    own = np.eye(N)
    xs, Ps = [], []
    for k in range(z.shape[0]):
        xp, Pp = forwarding.predict(x, P)
        if latency:  # x, P: the filter one step behind; the own fresh measurement on top
            xo, Po = correct(xp, Pp, z[k], own)
            if k + 1 < z.shape[0]:  # the step's measurements reach the neighbours at the next step
                x, P = correct(xp, Pp, z[k], heard[k + 1])
        else:
            xo, Po = x, P = correct(xp, Pp, z[k], heard[k])
        xs.append(xo)
        Ps.append(Po)
    return np.stack(xs), np.stack(Ps)


def _late_pair(model, c: float | None, Om: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A pair sent one step before, as it is fused now: a density (scale `c`) or a measurement's information (None)."""
    return _predict_pair(model, c, Om, q) if c is not None else _predict_information(model, Om, q)


def _predict_information(model, Om: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """An information pair one step on, singular or not: ``M = F^-T Om F^-1``, ``((I + M Q)^-1 M, (I + M Q)^-1 F^-T q)``.

    For a measurement's information this is the measurement taken as one of the next state with the
    step's process noise added to its noise (F invertible: checked by the caller).
    """
    F_inv = np.linalg.inv(model.F)
    M = F_inv.T @ Om @ F_inv
    A = np.eye(model.n_states) + M @ model.Q
    return symmetric_part(np.linalg.solve(A, M)), np.linalg.solve(A, (F_inv.T @ q[..., None]))[..., 0]


def _predict_pair(model, c: float, Om: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A sent pair one step on: its density (mean ``Om^{-1} q``, information ``c Om``) predicted with F, Q."""
    Pc = symmetric_part(np.linalg.inv(c * Om))
    x = (Pc @ q[..., None])[..., 0] * c
    F, Q = model.F, model.Q
    x, Pc = x @ F.T, symmetric_part(F @ Pc @ F.T + Q)
    Om_new = symmetric_part(np.linalg.inv(Pc)) / c
    return Om_new, (Om_new @ x[..., None])[..., 0]
