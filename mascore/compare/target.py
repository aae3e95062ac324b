"""The common-target and cooperative-localization tasks: their models, and the fusion filters run on them."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from .. import estimation, fusion_links
from .._fusion_base import NetworkFilter
from .._validation import check_positive, check_positive_int
from ..agents import double_integrator
from ..ellipsoids import contains
from .benchmark import (
    SETTINGS,
    SHOWN,
    SWITCHING_GRAPHS,
    BenchmarkSettings,
    benchmark_graph,
    check_cell,
    check_n_agents,
    check_run,
    switching_graphs,
)

# --------------------------------------------------------------------------------------------
# the common-target task (mascore.fusion)


#: Read from the specs when asked (importing this module imports no filter): ``TARGET_METHODS``, the filters of
#: the common-target task at their recipes in table order (``-L<k>``: k consensus steps per update;
#: :func:`target_methods`); ``TARGET_NOT_APPLICABLE`` and ``LOCALIZATION_NOT_APPLICABLE``, the papers' methods
#: that do not apply to the common target or to cooperative localization, with the reason; ``LOSS_METHODS``, the
#: methods of the loss study: every filter of the target tables, whose steps follow any graph (not ``-Ldiam``,
#: whose L is the diameter of a graph that loss may disconnect, nor ``hcmci-safe-*``, whose weight is the graph's);
#: ``LATENCY_METHODS``, the methods with one-step latency: every filter of the target tables that is a fusion
#: network filter (the bound and ``local`` unaffected; the consensus filters on pairs by
#: :func:`mascore.fusion_links.track_messages`, the filters on forwarded measurements by
#: :func:`mascore.fusion_links.track_behind`; :func:`latency_methods`); ``LATENCY_NOT_MODELLED``, the others, with
#: the reason.
_FROM_SPECS = {
    "TARGET_METHODS": lambda: target_methods("target"),
    "LOSS_METHODS": lambda: target_methods("target"),
    "LATENCY_METHODS": lambda: latency_methods("target"),
    "LATENCY_NOT_MODELLED": lambda: latency_not_modelled("target"),
    "TARGET_NOT_APPLICABLE": lambda: estimation.not_applicable("target"),
    "LOCALIZATION_NOT_APPLICABLE": lambda: estimation.not_applicable("localization"),
}


def __getattr__(name: str):
    if name in _FROM_SPECS:
        return _FROM_SPECS[name]()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def target_methods(task: str = "target", knobs: bool = False) -> tuple[str, ...]:
    """The methods of the common-target (or localization) task, in table order, from their specs.

    Parameters
    ----------
    task : {"target", "localization"}
        The scenario.
    knobs : bool
        Include the knobs' settings (``role="knob"``: :data:`FUSION_KNOB_METHODS`, swept at N = 8 only).

    Returns
    -------
    tuple of str
        The names of the :class:`mascore.estimation.MethodSpec` of that task (a new filter module's included).

    Examples
    --------
    >>> from mascore import compare
    >>> compare.target_methods()[:3]
    ('centralized', 'local', 'forwarding')
    >>> "hcmci-safe-L1" in compare.target_methods(knobs=True), "hcmci-safe-L1" in compare.target_methods()
    (True, False)
    """
    return estimation.method_names(task, estimation.ROLES if knobs else SHOWN)


def target_model(n_agents: int, graph: str = "ring", settings: BenchmarkSettings = SETTINGS):
    """The common target: a planar double integrator; agent i measures one position coordinate (x if i is even).

    Parameters
    ----------
    n_agents : int
        Sensors N >= 3.
    graph : {"ring", "geometric"}
        Their communication graph (:func:`benchmark_graph`).
    settings : BenchmarkSettings
        ``dt``, ``q_pos``, ``q_vel`` (the target's process noise) and ``r`` (each measurement's variance).

    Returns
    -------
    mascore.sensor_network.SensorNetworkModel
        No agent observes the target alone; the team does.

    Examples
    --------
    >>> from mascore import compare
    >>> compare.target_model(8)
    SensorNetworkModel(N = 8 agents, n = 4 states, q = (1, 1, 1, 1, 1, 1, 1, 1) measurements)
    """
    from .. import sensor_network

    n_agents = check_n_agents(n_agents)
    s = settings
    F = double_integrator(2, s.dt).A
    Q = np.diag([s.q_pos, s.q_pos, s.q_vel, s.q_vel])
    H = [np.eye(4)[[i % 2]] for i in range(n_agents)]
    R = [s.r * np.eye(1)] * n_agents
    return sensor_network.SensorNetworkModel(F, Q, H, R, benchmark_graph(graph, n_agents, s))




def localization_model(n_agents: int, graph: str = "ring", settings: BenchmarkSettings = SETTINGS):
    """Cooperative localization: the team's positions, relative measurements on the links, absolute at two anchors.

    The state is every agent's planar position, ``(p_1, ..., p_N)`` (2N numbers), each a
    random walk of variance ``q_pos`` per step. Agent i measures ``z_ij = p_j - p_i + noise``
    (variance ``r`` per coordinate) to each neighbour j, and the anchors (agents 0 and
    N // 2) also their own position. Every filter of :mod:`mascore.fusion` then applies
    as to a common target (the team's positions); each agent is scored on its own position.

    Parameters
    ----------
    n_agents : int
        Team size N >= 3.
    graph : {"ring", "geometric"}
        The sensing and communication graph (:func:`benchmark_graph`).
    settings : BenchmarkSettings
        ``q_pos`` and ``r``.

    Returns
    -------
    mascore.sensor_network.SensorNetworkModel
        Without the anchors the positions would be observable only up to a common shift.

    Examples
    --------
    >>> from mascore import compare
    >>> compare.localization_model(4).measurement_sizes
    (6, 4, 6, 4)
    """
    from .. import sensor_network

    n_agents = check_n_agents(n_agents)
    s = settings
    A = benchmark_graph(graph, n_agents, s)
    n = 2 * n_agents
    I2 = np.eye(2)
    H, R = [], []
    for i in range(n_agents):
        rows = []
        if i in (0, n_agents // 2):
            rows.append(np.kron(np.eye(n_agents)[i], I2))
        for j in np.flatnonzero(A[i]):
            rows.append(np.kron(np.eye(n_agents)[j] - np.eye(n_agents)[i], I2))
        H.append(np.vstack(rows))
        R.append(s.r * np.eye(H[-1].shape[0]))
    return sensor_network.SensorNetworkModel(np.eye(n), s.q_pos * np.eye(n), H, R, A)


def _localization_switching(n_agents: int, settings: BenchmarkSettings):
    """Cooperative localization on :func:`switching_graphs`: one model over every link the run ever has,
    and each step's model with the rows of its current links.

    Returns
    -------
    union : mascore.sensor_network.SensorNetworkModel
        :func:`localization_model`'s sensing over the union of the step graphs (it draws the data:
        each possible link's measurement has its own noise; a step keeps its current links' rows).
    step : callable
        ``step(k) -> (model, rows)``: the model of graph k (anchors' rows, then the relative rows of its
        current links, as :func:`localization_model` orders them) and the indices ``rows`` of its rows in
        ``union``'s stacked measurement; built when asked (one step's model at a time in memory: each
        holds ``(N, 2N, 2N)`` information matrices).
    """
    from .. import sensor_network

    G = switching_graphs(n_agents, settings.n_steps, settings) > 0
    union_adj = G.any(0)
    n = 2 * n_agents
    I2, eye = np.eye(2), np.eye(n_agents)
    H, R, rows_of = [], [], []  # rows_of[i]: {"anchor" or j: agent i's stacked row indices in the union}
    start = 0
    for i in range(n_agents):
        blocks, where = [], {}
        if i in (0, n_agents // 2):
            blocks.append(np.kron(eye[i], I2))
            where["anchor"] = start + np.arange(2)
            start += 2
        for j in np.flatnonzero(union_adj[i]):
            blocks.append(np.kron(eye[j] - eye[i], I2))
            where[int(j)] = start + np.arange(2)
            start += 2
        H.append(np.vstack(blocks) if blocks else np.zeros((0, n)))
        R.append(settings.r * np.eye(H[-1].shape[0]) if blocks else None)
        rows_of.append(where)
    F, Q = np.eye(n), settings.q_pos * np.eye(n)
    union = sensor_network.SensorNetworkModel(F, Q, H, R, union_adj.astype(float))
    def step(k: int):
        A = G[k]
        Hk, Rk, idx = [], [], []
        for i in range(n_agents):
            keep = [j for j in rows_of[i] if j == "anchor" or A[i, j]]
            rows = np.concatenate([rows_of[i][j] for j in keep]) if keep else np.zeros(0, int)
            idx.append(rows)
            Hk.append(union.H_stacked[rows])
            Rk.append(settings.r * np.eye(len(rows)) if len(rows) else None)
        return sensor_network.SensorNetworkModel(F, Q, Hk, Rk, A.astype(float)), np.concatenate(idx)

    return union, step


def localization_riccati(n_agents: int, graph: str = "ring",
                         settings: BenchmarkSettings = SETTINGS) -> dict[str, float]:
    """Exact own-position errors of the two Kalman filters of cooperative localization, without Monte Carlo.

    The centralized filter and measurement forwarding are Kalman filters (on all the
    measurements of a step, and on those of agent i's closed neighbourhood of that step),
    so their covariances are their error covariances, and they follow a time-varying
    Riccati recursion over the graph sequence (a switching graph has no steady state: no
    DARE). The recursion is built here from the graph alone (agent i's rows: its anchor
    row if it is agent 0 or N // 2, and ``p_j - p_i`` for its links of the step), not from
    :func:`localization_model`, so it checks :func:`simulate_target` independently.

    Parameters
    ----------
    n_agents : int
        Team size N >= 3.
    graph : {"ring", "geometric", "switching"}
        The sensing and communication graph; ``"switching"``: graph k of :func:`switching_graphs` at step k.
    settings : BenchmarkSettings
        ``p0``, ``q_pos``, ``r``, ``n_steps``, ``steady_from``.

    Returns
    -------
    dict of str to float
        ``"centralized"``, ``"forwarding"`` (m^2): the mean over the steady window and the agents of the
        variance of an agent's own position (trace of its 2 x 2 block), what :func:`simulate_target`'s
        ``rmse_own ** 2`` estimates; ``"forwarding ratio"``: the square root of their quotient;
        ``"anchor reach"``: the fraction of agent-steps with an anchor in the closed neighbourhood, and
        ``"anchor reach, least"``: the same for the agent that has one least often.

    Examples
    --------
    >>> from mascore import compare
    >>> e = compare.localization_riccati(8)
    >>> bool(e["forwarding"] > e["centralized"] > 0), e["anchor reach, least"]   # ring: agents 2 and 6
    (True, 0.0)
    """
    N = check_n_agents(n_agents)
    s = settings
    if graph not in SWITCHING_GRAPHS:
        raise ValueError(f"graph must be one of {SWITCHING_GRAPHS}; got {graph!r}")
    G = (switching_graphs(N, s.n_steps, s) if graph == "switching"
         else np.broadcast_to(benchmark_graph(graph, N, s), (s.n_steps, N, N))) > 0
    n, eye = 2 * N, np.eye(N)
    anchors = (0, N // 2)
    own = 2 * np.arange(N)[:, None] + np.arange(2)                     # (N, 2): agent i's coordinates
    Pc = s.p0 * np.eye(n)
    Pf = np.broadcast_to(Pc, (N, n, n)).copy()
    central, forwarding, reach = [], [], []
    for A in G:
        info = np.zeros((N, n, n))                                     # agent j's H_j^T R^-1 H_j at this step
        for j in range(N):
            rows = [eye[j]] if j in anchors else []
            rows += [eye[m] - eye[j] for m in np.flatnonzero(A[j])]
            if rows:
                H = np.kron(np.array(rows), np.eye(2))
                info[j] = H.T @ H / s.r
        closed = A | np.eye(N, dtype=bool)
        Pc = np.linalg.inv(np.linalg.inv(Pc + s.q_pos * np.eye(n)) + info.sum(0))
        Pf = np.linalg.inv(np.linalg.inv(Pf + s.q_pos * np.eye(n)) + np.einsum("ij,jab->iab", closed, info))
        central.append(np.trace(Pc) / N)
        forwarding.append(np.mean(np.trace(Pf[np.arange(N)[:, None, None], own[:, :, None], own[:, None, :]],
                                           axis1=1, axis2=2)))
        reach.append(closed[:, list(anchors)].any(1))
    w = slice(s.steady_from, s.n_steps)
    c, f = float(np.mean(central[w])), float(np.mean(forwarding[w]))
    reach = np.array(reach)
    return {"centralized": c, "forwarding": f, "forwarding ratio": float(np.sqrt(f / c)),
            "anchor reach": float(reach.mean()), "anchor reach, least": float(reach.mean(0).min())}


def _own_position(n_agents: int, whole: bool) -> tuple:
    """``(of_x, of_P)``: each agent's estimate of its own position ``(..., N, 2)`` and its covariance ``(..., N, 2, 2)``.

    From the localization filters' estimates of the team ``(..., N, 2N)`` (one per agent) or ``(..., 2N)``
    (`whole`: one for every agent), and their covariances; only these parts are scored.
    """
    own = np.arange(n_agents)
    idx = 2 * own[:, None] + np.arange(2)                      # (N, 2): agent i's own coordinates
    if whole:
        return (lambda x: x[..., idx]), (lambda P: P[..., idx[:, :, None], idx[:, None, :]])
    return (lambda x: x[..., own[:, None], idx]), (lambda P: P[..., own[:, None, None], idx[:, :, None], idx[:, None, :]])


def _agent_major(a: np.ndarray, trailing: int) -> np.ndarray:
    """`a` ``(K', runs, ...)`` copied into memory with its `trailing` axes outermost (the same shape)."""
    order = (*range(2, 2 + trailing), 0, 1)
    return np.ascontiguousarray(a.transpose(order)).transpose(np.argsort(order))


def target_filter(method: str, model, task: str = "target"):
    """The filter of a common-target method on `model`, as its spec builds it (:func:`mascore.estimation.method_spec`).

    Parameters
    ----------
    method : str
        One of :func:`target_methods`.
    model : mascore.sensor_network.SensorNetworkModel
        The sensing and the graph.
    task : {"target", "localization"}
        The scenario whose methods are searched.

    Returns
    -------
    filter
        ``local`` is consensus on information with no consensus step (each agent's own Kalman filter).

    Examples
    --------
    >>> from mascore import compare
    >>> compare.target_filter("ci-L5", compare.target_model(8)).n_consensus
    5
    """
    return estimation.method_spec(method, task).build(model)


def target_cost(method: str, n_agents: int, degree: float, task: str = "target") -> tuple[float, float]:
    """Floats sent and flops per agent per step of a common-target method (:func:`mascore.fusion_cost.filter_cost`).

    Parameters
    ----------
    method : str
        One of :data:`TARGET_METHODS`.
    n_agents : int
        N.
    degree : float
        Mean number of neighbours (rounded for the count).
    task : {"target", "localization"}
        The model: n = 4 and one measurement per agent, or n = 2N and ``2 degree`` measurements
        per agent (the anchors' two more are left out of the count).

    Returns
    -------
    (float, float)
        Floats sent, flops (``local``: none sent; the flops of its own filter).

    Examples
    --------
    >>> from mascore.compare import target_cost
    >>> target_cost("local", 8, 2)[0], target_cost("ci-L5", 8, 2)[0]
    (0.0, 70.0)
    """
    n_agents, d = check_positive_int(n_agents, "n_agents"), int(round(check_positive(degree, "degree", allow_zero=True)))
    n, q = (4, 1) if task == "target" else (2 * int(n_agents), 2 * d)
    floats, flops = estimation.method_spec(method, task).cost(n, q, d, int(n_agents))
    return float(floats), float(flops)


def simulate_target(
    method: str,
    n_agents: int,
    seed: np.random.SeedSequence | int | Sequence[np.random.SeedSequence | int],
    *,
    graph: str = "ring",
    runs: int | None = None,
    settings: BenchmarkSettings = SETTINGS,
    task: str = "target",
    loss: float = 0.0,
    latency: int = 0,
    send_delta: float | None = None,
    loss_model: str = "link",
    memo: dict | None = None,
) -> dict[str, np.ndarray]:
    """Track the common target (or localize the team) with one filter of :mod:`mascore.fusion`, batched over runs.

    Parameters
    ----------
    method : str
        One of :data:`TARGET_METHODS`.
    n_agents : int
        Sensors N >= 3.
    seed : numpy.random.SeedSequence or int, or a sequence of them
        Source of the target's path and the measurements (the same for every method). A sequence:
        one block of `runs` runs per seed, the blocks' runs in order (each block's numbers as with
        its seed alone: the filters' covariances, which do not depend on the data, serve all blocks).
    graph : {"ring", "geometric", "switching"}
        The communication graph (``"switching"``: graph k of :func:`switching_graphs` at step k; in
        localization it is the sensing graph too, so a step's relative measurements are those of its
        current links, the anchors' always; the data are drawn once over every link the sequence has).
    runs : int, optional
        Monte Carlo runs (default ``settings.runs``).
    settings : BenchmarkSettings
        The benchmark's settings (``n_steps``, ``steady_from``, ``p0``).
    task : {"target", "localization"}
        :func:`target_model` or :func:`localization_model`.
    loss : float
        Packet loss: each link lost with this probability at each step, in both directions
        (:func:`mascore.fusion_links.lossy_graphs`; the filters fuse what arrived, with their weights
        on the links that delivered). The pattern comes from `seed` (a stream of its own, so the
        target's path and the measurements are those of ``loss = 0``) and is shared by the runs;
        patterns are nested in `loss`. The centralized filter is the bound and keeps ideal links,
        ``local`` sends nothing: both are unaffected.
    latency : {0, 1}
        Steps a message takes (:data:`LATENCY_METHODS`): the consensus filters on information pairs
        (CI, HCMCI, ICF, any number of rounds) fuse the neighbours' pairs of the step before, predicted
        one step, their rounds pipelined across steps (:func:`mascore.fusion_links.track_messages`);
        the filters on forwarded measurements (forwarding, KCF, the set-membership filter, the two
        diffusion filters) run their own filter one step behind (two for the diffusion filters, whose
        estimates follow the measurements' exchange), predicted and corrected with the agent's own
        fresh measurement (:func:`mascore.fusion_links.track_behind`). With `send_delta` too.
    send_delta : float, optional
        Send-on-delta threshold of ``ci-L1`` and ``icf-L1`` (:data:`SEND_ON_DELTA_METHODS`): an agent
        re-sends only when its estimate moved by more than this Mahalanobis distance since its last
        send (on a fixed graph; with loss only per direction, ``loss_model="direction"``: each receiver
        then fuses the last pair it received from each neighbour, predicted; with `latency`, the pairs
        sent at the step before).
    loss_model : {"link", "direction"}
        ``"link"``: as above, a link lost in both directions at once, one pattern per seed shared by
        its runs, every method. ``"direction"`` (:data:`DIRECTION_LOSS_METHODS`): each message
        ``j -> i`` lost alone, one pattern per run (:func:`mascore.fusion_links.lossy_graphs` with
        ``per_direction=True``); forwarding fuses the measurements that arrived
        (:func:`mascore.fusion_links.track_forwarding`), ``ci-L1`` and ``icf-L1`` keep their
        ideal-link weights and give a lost message's weight to the receiver's own pair
        (:func:`mascore.fusion_links.delivered_weights`); with `latency` too.
    memo : dict, optional
        A dictionary the caller keeps between calls on one task, team size and graph with the same
        settings (say, every method of one cell): the model, each seed's data (the target's path and the
        measurements, which do not depend on the method) and, for teams up to 16, the models of a
        switching graph's steps are computed once and kept in it. The numbers are those of a call
        without it. Default: nothing is kept.

    Returns
    -------
    dict of str to ndarray
        Per run: ``rmse_own`` (m), RMS position error of the agents' estimates over the
        steady window (of the target; of its own position for localization); ``nees_own``,
        NEES per degree of freedom with each agent's own P (of that position);
        ``cpu_s``, CPU of the whole batch's filtering (one value, repeated); with `send_delta`
        also ``floats``: the floats sent per agent and step over the steady window, as sent. A set-membership
        filter (one with ``initial_shape``: its P is an ellipsoid's shape, started at
        ``initial_shape(p0 I)``) has ``nees_own`` NaN and instead ``containment``, the fraction of
        agent-steps of the window whose true state (localization: own position, in the projected
        ellipsoid) lies in the agent's set, and ``set_size`` (m), the largest position semi-axis
        of the set, averaged over the window and the agents.

    Examples
    --------
    >>> from mascore import compare
    >>> m = compare.simulate_target("centralized", 8, 0, runs=20)
    >>> bool(0.5 < m["nees_own"].mean() < 1.5)
    True
    """
    seeds = list(seed) if isinstance(seed, (list, tuple)) else [seed]
    if not seeds:
        raise ValueError("seed must be a seed or a non-empty sequence of seeds (one per block of runs)")
    n_agents, runs = check_run(n_agents, "gaussian", 0.0, 1.0, runs, settings)
    check_run(n_agents, "gaussian", 0.0, 1.0, runs * len(seeds), settings)  # every block at once
    _check_fusion_task(task)
    spec = estimation.method_spec(method, task)
    s = settings
    if graph not in SWITCHING_GRAPHS:
        raise ValueError(f"graph must be one of {SWITCHING_GRAPHS}; got {graph!r}")
    links = _check_links(method, loss, latency, send_delta, graph, task, loss_model)
    if memo is not None and not isinstance(memo, dict):
        raise TypeError(f"memo must be a dict (kept by the caller between calls) or None; got {type(memo).__name__}")
    memo = {} if memo is None else memo
    model, step_of = _task_model(task, n_agents, graph, s, memo)
    n = model.n_states
    P0 = s.p0 * np.eye(n)
    if links and len(seeds) > 1:
        raise ValueError("loss, latency and send-on-delta draw their own streams per seed: give one seed")
    blocks = [_seed_data(model, sd, runs, s, memo, (task, n_agents, graph)) for sd in seeds]
    x_true, z = (np.concatenate(parts, axis=1) for parts in zip(*blocks))  # (K + 1 or K, blocks x runs, ...)
    first = spec.build(model)
    set_valued = hasattr(first, "initial_shape")  # a set-membership filter: its state is an ellipsoid, not a Gaussian
    if set_valued:
        P0 = first.initial_shape(P0)
    own = _own_position(n_agents, spec.whole_filter) if task == "localization" else None
    sent = None
    if links:
        G = switching_graphs(n_agents, s.n_steps, s) if graph == "switching" else model.adjacency
        rng = np.random.default_rng(_loss_seed(seeds[0]))
        if loss_model == "direction":  # one pattern per run, each message j -> i lost alone
            D = fusion_links.lossy_graphs(G, loss, s.n_steps, rng, per_direction=True, n_runs=runs)
            x, P, cpu, sent = _filter_delivered(method, model, task, G, D, z, P0, latency, send_delta)
        else:
            G = fusion_links.lossy_graphs(G, loss, s.n_steps, rng)
            x, P, cpu, sent = _filter_links(method, model, task, G, z, P0, latency, send_delta)
        x, P = x[s.steady_from:], P[s.steady_from:]
        if own is not None:
            x, P = own[0](x), own[1](P)
    else:  # step by step, keeping the steady window's estimates (localization: each agent's own position only)
        xk, Pk = model.check_state(np.zeros(n), P0, per_agent=not spec.whole_filter)
        xs, Ps = [], []
        cpu, f, last = 0.0, first, model
        for k in range(s.n_steps):
            m, rows = step_of(k)
            if m is not last:  # the filters hold no state: one per step's graph (switching), built when needed
                f, last = spec.build(m), m  # the spec found once (a lookup scans the package)
            tic = time.thread_time()
            xk, Pk = f.update(*f.predict(xk, Pk), z[k][..., rows])
            cpu += time.thread_time() - tic
            if k >= s.steady_from:
                xs.append(xk if own is None else own[0](xk))
                Ps.append(Pk if own is None else own[1](Pk))
        x, P = np.stack(xs), np.stack(Ps)
    truth = x_true[1:][s.steady_from:]                         # (K', runs, n)
    if task == "target":
        if spec.whole_filter:
            x, P = x[:, :, None], P[:, None]                   # one estimate, shared by every agent
        e = truth[:, :, None] - x                              # (K', runs, N', n)
        P = np.broadcast_to(P[:, None] if P.ndim == 4 else P, (*e.shape, n))
        e_nees, P_nees, dof = e, P, 4                          # NEES of the whole state, RMSE of the position
        e = e[..., :2]
    else:
        idx = 2 * np.arange(n_agents)[:, None] + np.arange(2)  # (N, 2): agent i's own coordinates
        # laid out agent and coordinate first, as a gather of the whole estimates lays them out: the sums
        # below add in the order they always have, so the tables keep their numbers bit for bit
        e = _agent_major(truth[..., idx] - x, 2)               # (K', runs, N, 2)
        P = _agent_major(np.broadcast_to(P[:, None] if P.ndim == 4 else P, (*e.shape, 2)), 3)
        e_nees, P_nees, dof = e, P, 2
    out = {"rmse_own": np.sqrt(np.mean(np.sum(e ** 2, -1), axis=(0, 2)))}
    if set_valued:  # the containment of the true state (target) or own position (localization), and the set's size
        out["nees_own"] = np.full(runs * len(seeds), np.nan)
        out["containment"] = contains(e_nees, np.zeros(e_nees.shape[-1]), P_nees).mean(axis=(0, 2))
        position = P_nees[..., :2, :2]
        out["set_size"] = np.sqrt(np.linalg.eigvalsh(position)[..., -1]).mean(axis=(0, 2))
    else:
        nees = np.einsum("...i,...i->...", e_nees, np.linalg.solve(P_nees, e_nees[..., None])[..., 0]) / dof
        out["nees_own"] = nees.mean(axis=(0, 2))
    out["cpu_s"] = np.full(runs * len(seeds), cpu)
    if sent is not None and send_delta is not None:  # the floats as sent: one pair per send
        pair = sum(m.floats for m in first.messages())
        out["floats"] = pair * sent[s.steady_from:].mean(axis=(0, 2))
    return out


def _task_model(task: str, n_agents: int, graph: str, s: BenchmarkSettings, memo: dict) -> tuple:
    """``(model, step_of)`` of :func:`simulate_target`, built once per `memo` (``step_of(k) -> (model_k, rows)``).

    The models of a switching graph's steps are kept once built for the common target and for teams
    up to 16 (a localization model holds ``(N, 2N, 2N)`` information matrices: beyond, one at a time).
    """
    key = ("model", task, n_agents, graph, s)
    if key not in memo:
        if graph == "switching" and task == "localization":  # the sensing switches too: each step's links' rows
            model, step_of = _localization_switching(n_agents, s)
        else:
            model = (target_model if task == "target" else localization_model)(
                n_agents, "ring" if graph == "switching" else graph, s)
            G = switching_graphs(n_agents, s.n_steps, s) if graph == "switching" else None
            step_of = (lambda k: (model, slice(None))) if G is None else (lambda k: (model.on_graph(G[k]), slice(None)))
        if graph == "switching" and (task == "target" or n_agents <= 16):
            step_of = _kept(step_of)
        memo[key] = (model, step_of)
    return memo[key]


def _kept(step_of):
    """`step_of`, each step's result kept once computed (the models of a switching graph's steps)."""
    built: dict[int, tuple] = {}

    def kept(k: int) -> tuple:
        if k not in built:
            built[k] = step_of(k)
        return built[k]
    return kept


def _seed_data(model, seed: np.random.SeedSequence | int, runs: int, s: BenchmarkSettings, memo: dict,
               where: tuple) -> tuple[np.ndarray, np.ndarray]:
    """One seed's ``model.simulate`` (the path ``(K + 1, runs, n)`` and measurements ``(K, runs, q)``), once per `memo`."""
    n = model.n_states
    if isinstance(seed, np.random.SeedSequence):
        who = ("seq", tuple(np.atleast_1d(seed.entropy).tolist()), seed.spawn_key, seed.pool_size)
    elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
        who = ("int", int(seed))
    else:  # anything else default_rng takes (or refuses): drawn, not kept
        return model.simulate(np.zeros(n), s.p0 * np.eye(n), s.n_steps, np.random.default_rng(seed), n_runs=runs)
    key = ("data", *where, s, runs, who)
    if key not in memo:
        memo[key] = model.simulate(np.zeros(n), s.p0 * np.eye(n), s.n_steps, np.random.default_rng(seed), n_runs=runs)
    return memo[key]


#: The studies of the target and localization tasks over their links, and what each sets of
#: :func:`simulate_target` (a cell's ``dropout`` is the packet loss ``loss``): ``loss`` (ideal timing, a link
#: lost in both directions), ``loss-direction`` (each message lost alone, one pattern per run),
#: ``latency`` (every message one step late), ``send-on-delta-<delta>`` (fixed graph, no loss),
#: ``lossy-send-on-delta-0.5`` (send-on-delta with each message lost alone) and ``late-send-on-delta-0.5``
#: (send-on-delta with every message one step late).
LINK_STUDIES = {"loss": {}, "loss-direction": {"loss_model": "direction"}, "latency": {"latency": 1},
                **{f"send-on-delta-{d:g}": {"send_delta": d} for d in (0.5, 1.0, 2.0)},
                "lossy-send-on-delta-0.5": {"send_delta": 0.5, "loss_model": "direction"},
                "late-send-on-delta-0.5": {"send_delta": 0.5, "latency": 1}}


def link_options(study: str) -> dict[str, float]:
    """The link settings of a study of the target or localization task (:data:`LINK_STUDIES`; others: ideal links).

    Parameters
    ----------
    study : str
        The cell's study.

    Returns
    -------
    dict
        Keyword arguments ``latency``, ``send_delta`` and ``loss_model`` of :func:`simulate_target`
        (empty: ideal links, or loss on both directions at once).

    Examples
    --------
    >>> from mascore.compare.target import link_options
    >>> link_options("latency"), link_options("send-on-delta-0.5"), link_options("target")
    ({'latency': 1}, {'send_delta': 0.5}, {})
    """
    return dict(LINK_STUDIES.get(study, {}))


#: Methods with loss per direction (:func:`simulate_target`'s ``loss_model="direction"``): the bound and ``local``
#: (unaffected), measurement forwarding, and the consensus filters that send one density per step.
DIRECTION_LOSS_METHODS = ("centralized", "local", "forwarding", "ci-L1", "icf-L1")
#: Methods with send-on-delta messages (:func:`simulate_target`), and the bound.
SEND_ON_DELTA_METHODS = ("centralized", "ci-L1", "icf-L1")
#: Why a method has no model of late messages: its filter does not say how many exchanges of a step follow one
#: another, nor how it is rebuilt on another graph (what :mod:`mascore.fusion_links` reads of a network filter).
_NO_LATENCY_MODEL = ("its filter is not a network filter of mascore.fusion (no count of the exchanges that follow "
                     "one another in a step): mascore.fusion_links has no treatment of its late messages")


def latency_methods(task: str = "target") -> tuple[str, ...]:
    """The methods of `task` with a model of one-step latency (:func:`latency_model`), in table order.

    Every filter of the tables that is a network filter of :mod:`mascore.fusion` (the bound and ``local``
    unaffected); a filter written on the estimator protocol alone is left out, with the reason
    (:func:`latency_not_modelled`). Latency is not modelled on the switching localization task (its
    sensing switches with the graph), for any method.

    Parameters
    ----------
    task : {"target", "localization"}
        The scenario.

    Returns
    -------
    tuple of str
        The methods' names.

    Raises
    ------
    ValueError
        A task other than ``"target"`` and ``"localization"``.

    Examples
    --------
    >>> from mascore.compare.target import latency_methods
    >>> latency_methods()[:4]
    ('centralized', 'local', 'forwarding', 'ci-L1')
    """
    return tuple(m for m, ok in _takes_late(target_methods(task), task).items() if ok)


def latency_not_modelled(task: str = "target") -> dict[str, str]:
    """The methods of `task` without a model of one-step latency, each with the reason (none of the book's).

    Parameters
    ----------
    task : {"target", "localization"}
        The scenario.

    Returns
    -------
    dict of str to str
        Method name -> why its messages cannot be taken late.

    Raises
    ------
    ValueError
        A task other than ``"target"`` and ``"localization"``.

    Examples
    --------
    >>> from mascore.compare.target import latency_not_modelled
    >>> [m for m in ("ci-L1", "diffusion", "kcf", "sm-forwarding") if m in latency_not_modelled()]   # the book's: none
    []
    """
    return {m: _NO_LATENCY_MODEL for m, ok in _takes_late(target_methods(task), task).items() if not ok}


def _check_fusion_task(task: object) -> None:
    """Refuse a task other than the two of the fusion filters, by name."""
    if task not in ("target", "localization"):
        raise ValueError(f"task must be 'target' or 'localization'; got {task!r}")


def _takes_late(methods, task: str) -> dict[str, bool]:
    """Whether :mod:`mascore.fusion_links` can take each method's messages late: its filter is a network filter.

    A spec built by its filter class says so without a filter; the others are built once, on one small model.
    """
    _check_fusion_task(task)
    model, out = None, {}
    for method in methods:
        build = estimation.method_spec(method, task).build
        if isinstance(build, type):
            out[method] = issubclass(build, NetworkFilter)
            continue
        if model is None:
            model = target_model(4) if task == "target" else localization_model(4)
        out[method] = isinstance(build(model), NetworkFilter)
    return out


def latency_model(method: str, task: str = "target") -> str:
    """How a method's messages are taken when each arrives one step late (:func:`simulate_target`'s `latency`).

    Parameters
    ----------
    method : str
        One of :data:`LATENCY_METHODS` (or a knob's setting).
    task : {"target", "localization"}
        The scenario.

    Returns
    -------
    str
        The treatment, from the method's filter: the bound and ``local`` are unaffected; a consensus
        filter on information pairs fuses its neighbours' pairs of the step before, predicted, its
        rounds pipelined (:func:`mascore.fusion_links.track_messages`); a filter on forwarded
        measurements runs one step behind, or as many as its exchanges follow one another
        (:func:`mascore.fusion_links.track_behind`).

    Raises
    ------
    ValueError
        An unknown task or method, or a method whose filter has no model of late messages
        (:func:`latency_not_modelled`).

    Examples
    --------
    >>> from mascore.compare.target import latency_model
    >>> latency_model("diffusion")
    'its own filter two steps behind (measurements, then estimates), then its own fresh measurements'
    """
    _check_fusion_task(task)
    if method == "centralized":
        return "the bound: ideal links"
    # built on the latency study's team, the ring of 8 (the rounds of an -Ldiam filter are its diameter)
    filt = target_filter(method, target_model(8) if task == "target" else localization_model(8), task)
    if not isinstance(filt, NetworkFilter):
        raise ValueError(f"method {method!r} has no model of late messages: {_NO_LATENCY_MODEL}")
    rounds = filt.exchanges
    if rounds == 0:
        return "sends nothing"
    if hasattr(filt, "message_pairs"):
        hybrid = len(filt.pair_scales) > 1
        return (f"the neighbours' {'prior and novelty pairs' if hybrid else 'pairs'} of the step before, predicted "
                f"one step{' (the novelty as a late measurement)' if hybrid else ''}"
                + (f"; {rounds} rounds pipelined across steps" if rounds > 1 else ""))
    if rounds == 2:
        return "its own filter two steps behind (measurements, then estimates), then its own fresh measurements"
    if rounds > 2:
        return f"its own filter {rounds} steps behind, then its own fresh measurements"
    return "its own filter one step behind, then its own fresh measurement"


def check_link_cell(cell: dict, name: str = "cell") -> dict:
    """Refuse up front a cell of the target or localization task whose method cannot run over its study's links.

    A cell's study sets its links when it is one of :data:`LINK_STUDIES` (``"latency"``: one step late;
    ``"send-on-delta-0.5"``: ...), and its ``dropout`` is the packet loss: the checks of
    :func:`simulate_target` for those settings, made before a sweep runs.

    Parameters
    ----------
    cell : mapping
        A cell of the grid (``check_cell`` checks its coordinates first): ``task``, ``method``,
        ``n_agents``, ``dropout``, ``noise``, and ``study`` and ``graph`` (default: none, the ring).
    name : str
        What the messages call the cell (e.g. a grid file's study).

    Returns
    -------
    dict
        The cell, checked.

    Raises
    ------
    ValueError
        A bad coordinate; the method has no model of those links (e.g. one-step latency for a filter on the
        estimator protocol alone), or the links do not go with the graph or the task.
    TypeError
        `cell` is not a mapping.

    Examples
    --------
    >>> from mascore.compare.target import check_link_cell
    >>> check_link_cell({"task": "target", "method": "ci-L5", "n_agents": 8, "dropout": 0.0, "noise": "gaussian",
    ...                  "study": "send-on-delta-0.5"})
    Traceback (most recent call last):
    ...
    ValueError: cell: send_delta: method must be one of ('centralized', 'ci-L1', 'icf-L1'); got 'ci-L5'
    """
    cell = check_cell(cell, name)
    if cell["task"] in ("target", "localization"):
        options = link_options(str(cell.get("study", "")))
        try:
            _check_links(cell["method"], float(cell.get("dropout", 0.0)), options.get("latency", 0),
                         options.get("send_delta"), cell.get("graph", "ring"), cell["task"],
                         options.get("loss_model", "link"))
        except ValueError as err:
            raise ValueError(f"{name}: {err}") from None
    return dict(cell)


def _check_links(method: str, loss: object, latency: object, send_delta: object, graph: str, task: str,
                 loss_model: object = "link") -> bool:
    """The link arguments of :func:`simulate_target`, checked; True if they depart from ideal links."""
    if loss_model not in ("link", "direction"):
        raise ValueError(f"loss_model must be 'link' or 'direction'; got {loss_model!r}")
    if loss_model == "direction" and method not in DIRECTION_LOSS_METHODS:
        raise ValueError(f"loss_model='direction': method must be one of {DIRECTION_LOSS_METHODS}; got {method!r}")
    loss = float(loss) if isinstance(loss, (int, float, np.floating)) and not isinstance(loss, bool) else loss
    if not isinstance(loss, float) or not 0.0 <= loss < 1.0:
        raise ValueError(f"loss must be a probability in [0, 1); got {loss!r}")
    if isinstance(latency, bool) or latency not in (0, 1):
        raise ValueError(f"latency must be 0 or 1 (steps); got {latency!r}")
    if latency and method not in ("centralized", "local") and not _takes_late([method], task)[method]:
        raise ValueError(f"latency: method {method!r} has no model of late messages: {_NO_LATENCY_MODEL}")
    if send_delta is not None:
        if isinstance(send_delta, bool) or not isinstance(send_delta, (int, float, np.floating)) \
                or not np.isfinite(send_delta) or send_delta < 0:
            raise ValueError(f"send_delta must be a finite Mahalanobis distance >= 0 or None; got {send_delta!r}")
        if method not in SEND_ON_DELTA_METHODS:
            raise ValueError(f"send_delta: method must be one of {SEND_ON_DELTA_METHODS}; got {method!r}")
        if (loss and loss_model != "direction") or graph == "switching":
            raise ValueError("send_delta needs a fixed graph, and loss only with loss_model='direction' (each "
                             "receiver then holds its own copy of a sender's last pair); got "
                             f"loss={loss}, graph={graph!r}")
    links = bool(loss or latency or send_delta is not None)
    if links and graph == "switching" and task == "localization":
        raise ValueError("loss, latency and send-on-delta are not modelled on the switching localization task "
                         "(its sensing switches with the graph)")
    return links


def _loss_seed(seed: np.random.SeedSequence | int) -> np.random.SeedSequence:
    """The losses' own stream of a cell's seed (the path and the measurements keep theirs)."""
    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    return np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, 0x1055))


def _filter_delivered(method: str, model, task: str, G: np.ndarray, D: np.ndarray, z: np.ndarray, P0: np.ndarray,
                      latency: int, send_delta: float | None = None) -> tuple[np.ndarray, np.ndarray, float, Any]:
    """Run `method` over messages lost one direction at a time: `D` ``(K, runs, N, N)``, within the graph(s) `G`.

    Returns the estimates ``(K, runs, N, n)``, covariances, the CPU (s) and the sends ``(K, runs, N)``
    (None unless `send_delta`).
    """
    if method in ("centralized", "local"):  # the bound keeps ideal links; local sends nothing
        return _filter_links(method, model, task, G, z, P0, 0, None)
    x0 = np.zeros(model.n_states)
    tic = time.thread_time()
    if method == "forwarding":
        x, P = fusion_links.track_forwarding(model, x0, P0, z, D, latency=latency)
    else:  # the method's own filter of each step's graph, its weights compensated for the lost messages
        spec = estimation.method_spec(method, task)
        if np.ndim(G) == 2:
            filters = [spec.build(model)] * len(z)
        else:
            filters = [spec.build(model.on_graph(A)) for A in G]
        x, P, sent = fusion_links.track_messages(filters, x0, P0, z, latency=latency, send_delta=send_delta,
                                                 delivered=D)
        return x, P, time.thread_time() - tic, sent if send_delta is not None else None
    return x, P, time.thread_time() - tic, None


def _filter_links(method: str, model, task: str, G: np.ndarray, z: np.ndarray, P0: np.ndarray, latency: int,
                  send_delta: float | None) -> tuple[np.ndarray, np.ndarray, float, np.ndarray | None]:
    """Run `method` over the delivered graphs `G` (K, N, N) with the latency and send-on-delta given.

    Returns the estimates ``(K, runs, N, n)``, covariances, the CPU (s) and the sends ``(K, runs, N)``
    (None unless `send_delta`).
    """
    from .. import fusion_links

    spec = estimation.method_spec(method, task)
    n = model.n_states
    x0 = np.zeros(n)
    built: dict[bytes, object] = {}

    def step_filter(A: np.ndarray):  # the method's own filter on the step's graph (its weights, its rule)
        key = A.tobytes()
        if key not in built:
            built[key] = spec.build(model.on_graph(A))
        return built[key]

    if method in ("centralized", "local"):  # the bound keeps ideal links; local sends nothing
        filt = target_filter(method, model, task)
        tic = time.thread_time()
        x, P = filt.run(x0, P0, z)
        return x, P, time.thread_time() - tic, None
    filters = [step_filter(A) for A in G]
    tic = time.thread_time()
    sent = None
    pairs = hasattr(filters[0], "message_pairs")  # consensus on information pairs (CI, HCMCI, ICF)
    if pairs and (latency or send_delta is not None):  # their pairs late (predicted) or sent on delta
        x, P, sent = fusion_links.track_messages(filters, x0, P0, z, latency=latency, send_delta=send_delta)
    elif latency:  # on forwarded measurements: the filter a step behind, then the own fresh measurement
        x, P = fusion_links.track_behind(filters, x0, P0, z)
    else:
        xk, Pk = model.check_state(x0, P0, per_agent=not spec.whole_filter)
        xs, Ps = [], []
        for k, f in enumerate(filters):
            xk, Pk = f.update(*f.predict(xk, Pk), z[k])
            xs.append(xk)
            Ps.append(Pk)
        x, P = np.stack(xs), np.stack(Ps)
    return x, P, time.thread_time() - tic, sent
