"""The cost of one agent: one agent, one run, one thread, per step; beside its analytic flops and memory.

A batch of Monte Carlo runs over a whole team hides what one agent pays: NumPy's
per-call overhead is spread over the runs and the agents, and a per-agent filter
looks N times cheaper (or dearer) than it is. Here each method's step is cut down
to what **one agent** computes (:func:`agent_step`): for the per-agent filters,
agent i's prediction, its correction with its own and its neighbours' data, and
each of the L consensus rounds it performs, with the neighbours' messages handed
in as given arrays (the neighbours' own work is not timed); for the whole-team
filters, the whole filter's step (the centre of ``centralized``; every agent of
Song et al.'s estimation-based filter, which needs the joint covariance of all
agents' team estimates, their Remark 4). An agent of Song et al.'s
measurement-based filter runs a filter of the whole team on its own: its step is
that filter's (its team estimate and its own team covariance), not the N of them
that the batched implementation computes together.
:meth:`AgentStep.reference` gives agent i's numbers from the team-wide filter on
the same state, so the cut-down step is checked against the filter it stands for.

:func:`agent_step_cost` times the step on one thread (BLAS pinned to one thread
with ``threadpoolctl`` when it is installed; else set ``OMP_NUM_THREADS=1``, as
the Makefile does), the median of several repeats after a warm-up.
:func:`agent_costs` tabulates it over N with each method's log-log slope, beside
the analytic flops per agent and step (:func:`agent_flops`, from
:func:`mascore.fusion.filter_cost` for the fusion filters) and the orders of
:data:`AGENT_ORDER`.

Tasks and methods (:data:`AGENT_METHODS`): the team task of
:mod:`mascore.compare` (own states of a rendezvous team, n = 4 per agent), the
common target (n = 4) and cooperative localization (n = 2N), each on the ring
(degree d = 2). The agent timed is agent 0 (on the ring every agent has the
same degree; in localization agent 0 is also an anchor, with two more
measurements: the busiest).
"""

from __future__ import annotations

import copy
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from . import compare, fusion, kalman, rendezvous, set_membership
from . import distributed_kf as dkf
from ._validation import check_positive_int

__all__ = [
    "AGENT_METHODS",
    "AGENT_ORDER",
    "AGENT_TASKS",
    "MAX_AGENTS",
    "WHOLE_FILTER",
    "AgentStep",
    "agent_costs",
    "agent_flops",
    "agent_memory",
    "agent_step",
    "agent_step_cost",
    "blas_pinned",
    "max_deviation",
    "slopes",
]

#: Tasks whose per-agent cost is measured.
AGENT_TASKS = ("team", "target", "localization")
#: Methods per task (the team task's own recipes; the fusion filters of the target and localization tasks).
AGENT_METHODS = {
    "team": ("centralized", "local", "forwarding", "song-mb", "song-eb", "vlahakis", "set-membership"),
    "target": ("centralized", "local", "forwarding", "ci-L1", "ci-L5", "hcmci-L1", "hcmci-L5", "icf-L1", "icf-L5",
               "diffusion", "ci-diffusion"),
    "localization": ("centralized", "local", "forwarding", "ci-L1", "ci-L5", "hcmci-L1", "hcmci-L5", "icf-L1",
                     "icf-L5", "diffusion", "ci-diffusion"),
}
#: Methods whose busiest agent runs the whole filter: the centre, or every agent of Song et al.'s estimation-based
#: filter, which needs the joint covariance of all agents' team estimates (their Remark 4).
WHOLE_FILTER = {("team", "centralized"), ("team", "song-eb"), ("target", "centralized"),
                ("localization", "centralized")}
#: Largest N measured per (task, method), with the reason; the others go to 128.
MAX_AGENTS = {
    ("team", "song-eb"): (32, "its joint covariance of all agents' team estimates holds (2 N^2)^2 floats (per "
                              "axis): 0.5 GB at N = 64, 8.6 GB at 128"),
}

#: Leading-order work and memory of one agent per step (n the state size: 4 in the team and target tasks,
#: 2N in localization; d the degree, L the consensus rounds, N the team size; q_i = O(d) measurements).
AGENT_ORDER = {
    ("team", "centralized"): ("O(N^3 n^3) at the centre", "O(N^2 n^2)"),
    ("team", "local"): ("O(n^3)", "O(n^2)"),
    ("team", "forwarding"): ("O(d n + n^3)", "O(n^2 + d n)"),
    ("team", "song-mb"): ("O(N^3 n^3): its own covariance of the whole team", "O(N^2 n^2)"),
    ("team", "song-eb"): ("O(N^6 n^3): the joint covariance of all team estimates (dense)", "O(N^4 n^2)"),
    ("team", "vlahakis"): ("O(n^2 + d n)", "O(n + d n)"),
    ("team", "set-membership"): ("O(n^3)", "O(n^2)"),
    ("target", "centralized"): ("O(N q^2 + n^3) at the centre", "O(n^2 + N q)"),
    ("target", "local"): ("O(n^3)", "O(n^2)"),
    ("target", "forwarding"): ("O(d q n + n^3)", "O(n^2 + d q)"),
    ("target", "ci"): ("O(n^3 + L d n^2)", "O(d n^2)"),
    ("target", "hcmci"): ("O(n^3 + L d n^2)", "O(d n^2)"),
    ("target", "icf"): ("O(n^3 + L d n^2)", "O(d n^2)"),
    ("target", "diffusion"): ("O(d q n + n^3)", "O(n^2 + d n)"),
    ("target", "ci-diffusion"): ("O(n^3 + s d n^2): s weight-search evaluations", "O(d n^2)"),
    ("localization", "centralized"): ("O(N^3) at the centre (n = 2N, N d q)", "O(N^2)"),
    ("localization", "local"): ("O(N^3): n = 2N", "O(N^2)"),
    ("localization", "forwarding"): ("O(N^3)", "O(N^2)"),
    ("localization", "ci"): ("O(N^3 + L d N^2)", "O(d N^2)"),
    ("localization", "hcmci"): ("O(N^3 + L d N^2)", "O(d N^2)"),
    ("localization", "icf"): ("O(N^3 + L d N^2)", "O(d N^2)"),
    ("localization", "diffusion"): ("O(N^3)", "O(N^2)"),
    ("localization", "ci-diffusion"): ("O(N^3 + s d N^2)", "O(d N^2)"),
}


@dataclass
class AgentStep:
    """One agent's step of a method, ready to time, with the team-wide filter's numbers to check it against.

    Built by :func:`agent_step`; the fields are the parameters.

    Parameters
    ----------
    task, method : str
        As asked.
    n_agents : int
        N.
    agent : int
        The agent whose step is timed (i).
    degree : int
        Its number of neighbours d.
    scope : {"one agent", "whole filter"}
        What :attr:`run` computes.
    run : callable
        ``run()`` computes the step once and returns agent i's result (a tuple of arrays: its
        estimate and covariance or shape matrix after the step; the filter's state for a
        whole filter). Its inputs (the agent's prior, its measurements, its neighbours' messages
        of each round) were prepared beforehand and are not timed; repeated calls do the same work.
    reference : callable or None
        ``reference()``: agent i's result from the team-wide filter on the same state (None for a
        whole filter, where the step *is* the team-wide filter).

    Examples
    --------
    >>> from mascore import agent_cost
    >>> step = agent_cost.agent_step("target", "ci-L5", 8)
    >>> step.scope, step.degree
    ('one agent', 2)
    >>> bool(agent_cost.max_deviation(step) < 1e-12)   # agent i's numbers of the team-wide filter
    True
    """

    task: str
    method: str
    n_agents: int
    agent: int
    degree: int
    scope: str
    run: Callable[[], tuple]
    reference: Callable[[], tuple] | None = field(default=None, repr=False)

def _check_task_method(task: object, method: object) -> None:
    """Refuse a task or a method of that task that this module does not know, by name."""
    if task not in AGENT_TASKS:
        raise ValueError(f"task must be one of {AGENT_TASKS}; got {task!r}")
    if method not in AGENT_METHODS[task]:
        raise ValueError(f"method must be one of {AGENT_METHODS[task]} for task {task!r}; got {method!r}")


# --------------------------------------------------------------------------------------------
# one agent's step


def agent_step(task: str, method: str, n_agents: int, *, agent: int = 0, seed: int = 0,
               settings: compare.BenchmarkSettings = compare.SETTINGS) -> AgentStep:
    """Agent `agent`'s work per step of `method`, cut out of one run of the scenario.

    The scenario's model is built (:func:`mascore.compare.target_model`,
    :func:`~mascore.compare.localization_model`, or the team task's filters), the
    team-wide filter is run two steps from a seeded random state (untimed), and agent
    i's inputs of the next step are taken from it: its prior, its own and its
    neighbours' measurements, and for each of the L consensus rounds the messages its
    neighbours send in that round.

    Parameters
    ----------
    task : {"team", "target", "localization"}
        The scenario (:data:`AGENT_TASKS`).
    method : str
        One of ``AGENT_METHODS[task]``.
    n_agents : int
        Team size N >= 3 (a ring).
    agent : int
        The agent i, ``0 <= i < N``.
    seed : int
        Seed of the state and measurements.
    settings : mascore.compare.BenchmarkSettings
        The benchmark's settings.

    Returns
    -------
    AgentStep
        ``run()`` computes the step; ``reference()`` gives the team-wide filter's numbers for agent i.

    Raises
    ------
    ValueError
        An unknown task or method, a bad N or agent index.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agent_cost
    >>> step = agent_cost.agent_step("target", "ci-L5", 8)
    >>> x, P = step.run()                                  # agent 0: predict, correct, 5 consensus rounds
    >>> x_ref, P_ref = step.reference()                    # agent 0's row of the team-wide filter
    >>> bool(np.allclose(x, x_ref) and np.allclose(P, P_ref))
    True
    """
    _check_task_method(task, method)
    N = compare._check_n_agents(n_agents)
    i = check_positive_int(agent, "agent", minimum=0)
    if i >= N:
        raise ValueError(f"agent must be an agent index below n_agents = {N}; got {agent!r}")
    seed = check_positive_int(seed, "seed", minimum=0)
    if task == "team":
        return _team_step(method, N, i, seed, settings)
    return _fusion_step(task, method, N, i, seed, settings)


def _team_step(method: str, N: int, i: int, seed: int, s: compare.BenchmarkSettings) -> AgentStep:
    """The team task: the estimator of :mod:`mascore.compare` run two steps, then agent i's next step."""
    team = compare._team(N, "gaussian", 1.0, s, "ring")
    rng = np.random.default_rng(seed)
    x = np.concatenate([s.init_pos * rng.standard_normal((1, N, 2)), s.init_vel * rng.standard_normal((1, N, 2))],
                       axis=-1)
    x_hat0 = x + np.sqrt(s.p0) * rng.standard_normal(x.shape)
    est = compare._make(method, team, x_hat0)
    S = (team.adjacency > 0) | np.eye(N, dtype=bool)
    S = S[None]
    hood = np.flatnonzero(S[0, i])
    nbrs = hood[hood != i]

    def measure():
        return np.where(S[..., None], x[:, None] + np.sqrt(s.r) * rng.standard_normal((1, N, N, 4)), 0.0)

    def control(Z):
        view = est.views(Z, S)
        return rendezvous.consensus_control(np.broadcast_to(view, (1, N, N, 4)), team.laplacian, team.K)

    for _ in range(2):  # two steps of the team-wide estimator: a state that is not the initial one
        Z = measure()
        est.update(Z, S)
        U = control(Z)
        est.predict(U)
        x = x @ team.A.T + U @ team.B.T + np.sqrt(np.diag(team.Q)) * rng.standard_normal(x.shape)
    Z = measure()
    if (("team", method)) in WHOLE_FILTER:
        U = control(Z)  # the inputs of the timed step (from the views before the update: the work is the same)
        filt = est.filter

        def run():
            filt.update(Z, S)
            if method == "centralized":
                filt.predict(U)
                return filt.view("x_hat"), filt.view("P")
            filt.predict()
            return filt.view("X_hat"), filt.view("Sigma")

        return AgentStep("team", method, N, i, len(nbrs), "whole filter", run)

    before = copy.deepcopy(est)  # agent i's prior, and the team's views of this step, from the same state
    est.update(Z, S)
    U = control(Z)
    u_i = U[0, i].copy()
    est.predict(U)
    z_own = Z[0, i, i].copy()
    if method == "song-mb":
        return _song_mb_step(before.filter, est.filter, Z[0, i].copy(), S[0, i], i, len(nbrs))
    if method == "local":
        model = kalman.LinearGaussianModel(team.A, team.Q_filter, np.eye(4), team.R, team.B)
        x_i, P_i = before.own[0, i].copy(), np.array(before.P, dtype=float)

        def run():
            xu, Pu = kalman.update(x_i, P_i, z_own, model)
            return kalman.predict(xu, Pu, model, u_i)

        return AgentStep("team", method, N, i, len(nbrs), "one agent", run, lambda: (est.own[0, i], est.P))
    if method == "forwarding":
        x_i, P_i = before.own[0, i].copy(), before.P[0, i].copy()
        z_in = Z[0, hood, i].copy()  # (d + 1, 4): z_ji, the measurements of x_i by i and by its neighbours
        Rinv, A, B, Qf = np.linalg.inv(team.R), team.A, team.B, team.Q_filter

        def run():
            info = np.linalg.inv(P_i)
            P = np.linalg.inv(info + len(z_in) * Rinv)
            P = 0.5 * (P + P.T)
            xp = P @ (info @ x_i + Rinv @ z_in.sum(0))
            return A @ xp + B @ u_i, A @ P @ A.T + Qf

        return AgentStep("team", method, N, i, len(nbrs), "one agent", run, lambda: (est.own[0, i], est.P[0, i]))
    if method == "vlahakis":
        x_i = before.own[0, i].copy()
        p_nb = before.own[0, nbrs, :2].copy()  # the neighbours' broadcast position estimates (messages)
        z_own_pos, z_nb = z_own[:2].copy(), Z[0, i, nbrs, :2].copy()
        gain, Phi, A, B = before.gain, before.Phi, team.A, team.B
        a = team.adjacency[i, nbrs].copy()

        def run():
            p = x_i[:2]
            coupling = a @ ((z_own_pos - z_nb) - (p - p_nb))
            xu = x_i + gain @ ((z_own_pos - p) + Phi * coupling)
            return (A @ xu + B @ u_i,)

        return AgentStep("team", method, N, i, len(nbrs), "one agent", run, lambda: (est.own[0, i],))
    # set-membership: the filter's public one-agent model
    sm = set_membership.SetMembershipModel(A=team.A, G=np.eye(4), C=np.eye(4), D=np.eye(4), Q=before.W_proc,
                                           R=before.W_meas, B=team.B)
    c_i, E_i = before.own[0, i].copy(), before.shape[0, i].copy()

    def run():
        c, E, _ = sm.correct(c_i, E_i, z_own, check_consistency=False)
        return sm.predict(c, E, u_i)

    return AgentStep("team", method, N, i, len(nbrs), "one agent", run, lambda: (est.own[0, i], est.shape[0, i]))


def _song_mb_step(before: dkf.TeamFilter, after: dkf.TeamFilter, Z_i: np.ndarray, seen: np.ndarray, i: int,
                  degree: int) -> AgentStep:
    """Agent i of Song et al.'s measurement-based filter: eqs. (16)-(20), then (14)-(15), on its own team filter.

    The same kernels as :class:`mascore.distributed_kf.TeamFilter` with ``mode="mb"``, on agent i's
    team estimate ``(N, m)`` and reduced covariance ``(N m_r, N m_r)`` only. The block-diagonal
    process term of eq. (15) depends on the topology and the noise only: computed once.
    """
    from ._masked_gain import masked_gain

    model = before.model
    N, m, mr, Mr, k = model.n_agents, model.m, model.m_r, model.M_r, model.kron
    L = np.array(before.laplacian, dtype=float)
    X_i = np.array(before.X_hat[0, i])  # (N, m)
    Sig_i = np.array(before.Sigma[0, i])  # (Mr, Mr)
    d = np.repeat(seen, mr).astype(float)  # diag(D_i): the agents it measures
    Rr = model.R_r.reshape(N, mr, N, mr)
    Cj = np.einsum("jl,jk,lakc->jac", L, L, Rr)
    noise = np.zeros((N, mr, N, mr))
    noise[np.arange(N), :, np.arange(N), :] = model.BK_r @ Cj @ model.BK_r.T + model.Q_r
    noise = noise.reshape(Mr, Mr)
    A, BK = model.A, model.BK

    def run():
        KH = masked_gain(Sig_i, d, model.R_r)  # eq. (19): its own measurements
        X = X_i + (KH @ (Z_i - X_i).reshape(Mr, k)).reshape(N, m)
        Psi = np.eye(Mr) - KH
        Sig = Psi @ Sig_i @ Psi.T + KH @ model.R_r @ KH.T  # Joseph form, eq. (20)
        X = X @ A.T - (L @ X) @ BK.T  # eq. (14)
        T = dkf._F1_rows(model, Sig.reshape(N, mr, Mr), L).reshape(Mr, Mr).T
        Sig = dkf._F1_rows(model, T.reshape(N, mr, Mr), L).reshape(Mr, Mr) + noise  # eq. (15)
        return X, 0.5 * (Sig + Sig.T)

    return AgentStep("team", "song-mb", N, i, degree, "one agent", run,
                     lambda: (after.X_hat[0, i], after.Sigma[0, i]))


def _fusion_step(task: str, method: str, N: int, i: int, seed: int, s: compare.BenchmarkSettings) -> AgentStep:
    """The target and localization tasks: a :mod:`mascore.fusion` filter run two steps, then agent i's next step."""
    model = (compare.target_model if task == "target" else compare.localization_model)(N, "ring", s)
    filt = compare.target_filter(method, model)
    n = model.n_states
    rng = np.random.default_rng(seed)
    _, z = model.simulate(np.zeros(n), s.p0 * np.eye(n), 3, rng)
    if method == "centralized":
        x, P = model.check_state(np.zeros(n), s.p0 * np.eye(n), per_agent=False)
        for k in range(2):
            x, P = filt.update(*filt.predict(x, P), z[k])

        def run():
            return filt.update(*filt.predict(x, P), z[2])

        return AgentStep(task, method, N, i, int((model.adjacency[i] > 0).sum()), "whole filter", run)
    x, P = model.check_state(np.zeros(n), s.p0 * np.eye(n))
    x = x + np.sqrt(s.p0) * rng.standard_normal(x.shape)  # the agents start apart
    for k in range(2):
        x, P = filt.update(*filt.predict(x, P), z[k])
    zk = z[2]
    xm, Pm = filt.predict(x, P)  # the team's predictions: the source of the neighbours' messages (untimed)
    hood = np.flatnonzero(model._neighbourhood[i])
    nbrs = hood[hood != i]
    x_i, P_i = x[i].copy(), P[i].copy()
    F, Q = model.F, model.Q
    z_hood = [model.agent_measurement(zk, j).copy() for j in hood]  # own and received measurements
    HtRinv = [model.H[j].T @ np.linalg.inv(model.R[j]) if model.H[j].shape[0] else np.zeros((n, 0)) for j in hood]
    own = int(np.flatnonzero(hood == i)[0])
    I_i = model.information_matrices[i]

    def predict():
        return F @ x_i, F @ P_i @ F.T + Q

    def info_vec(j):
        return HtRinv[j] @ z_hood[j]

    def reference():
        xr, Pr = filt.update(xm, Pm, zk)
        return xr[i], Pr[i]

    step = dict(task=task, method=method, n_agents=N, agent=i, degree=len(nbrs), scope="one agent",
                reference=reference)
    if method in ("forwarding", "diffusion", "ci-diffusion"):
        S_i = sum(model.information_matrices[j] for j in hood)  # time-invariant: known beforehand
        eye = np.eye(n)

        def incremental():
            xp, Pp = predict()
            iv = sum(info_vec(k) for k in range(len(hood)))
            Pn = np.linalg.solve(eye + Pp @ S_i, Pp)
            Pn = 0.5 * (Pn + Pn.T)
            return xp + Pn @ (iv - S_i @ xp), Pn

        if method == "forwarding":
            return AgentStep(run=incremental, **step)
        # the neighbours' incremental estimates of this step (their messages), from the team-wide update
        hood_S = fusion._mix(model._neighbourhood, model.information_matrices, 2)
        psi_all, Ploc_all = fusion._information_update(
            xm, Pm, hood_S, fusion._mix(model._neighbourhood, model._information_vectors(zk), 1))
        if method == "diffusion":
            c_self, c_nb = filt.weights[i, i], filt.weights[i, nbrs]
            psi_nb = psi_all[nbrs].copy()

            def run():
                psi, Pn = incremental()
                return c_self * psi + c_nb @ psi_nb, Pn

            return AgentStep(run=run, **step)
        Om_all = np.linalg.inv(Ploc_all)
        Om_all = 0.5 * (Om_all + np.swapaxes(Om_all, -1, -2))
        Om_nb, q_nb = Om_all[nbrs].copy(), (Om_all[nbrs] @ psi_all[nbrs][..., None])[..., 0]

        def run():
            psi, Pn = incremental()
            Om = np.linalg.inv(Pn)
            Om = 0.5 * (Om + Om.T)
            infos = np.insert(Om_nb, own, Om, axis=0)
            qs = np.insert(q_nb, own, Om @ psi, axis=0)
            w = fusion._ci_weights(infos, filt.criterion)
            Pf = np.linalg.inv(np.einsum("k,kab->ab", w, infos))
            Pf = 0.5 * (Pf + Pf.T)
            return Pf @ (w @ qs), Pf

        return AgentStep(run=run, **step)
    # consensus filters: L rounds; round l's messages are the neighbours' pairs after l rounds (the team-wide mix)
    kind, L = ("ci", 0) if method == "local" else (method.rsplit("-L", 1)[0], int(method.rsplit("-L", 1)[1]))
    Om_m = np.linalg.inv(Pm)
    Om_m = 0.5 * (Om_m + np.swapaxes(Om_m, -1, -2))
    q_m = (Om_m @ xm[..., None])[..., 0]
    ivs = model._information_vectors(zk)
    if kind == "icf":
        eps = filt.rate
        W = np.eye(N) - eps * (np.diag((model.adjacency > 0).sum(1)) - (model.adjacency > 0))
        pairs = [(Om_m / N + model.information_matrices, q_m / N + ivs)]
    else:
        W = model.weights
        if kind == "ci":
            pairs = [(Om_m + model.information_matrices, q_m + ivs)]
        else:  # hcmci: the prior and the novelty pairs
            pairs = [(Om_m, q_m), (np.broadcast_to(model.information_matrices, Om_m.shape), ivs)]
    msgs = []  # msgs[l][p] = (neighbours' matrices (d, n, n), vectors (d, n)) of pair p in round l
    for _ in range(L):
        msgs.append([(M[nbrs].copy(), v[nbrs].copy()) for M, v in pairs])
        pairs = [(fusion._mix(W, M, 2), fusion._mix(W, v, 1)) for M, v in pairs]
    w_self, w_nb = W[i, i], W[i, nbrs].copy()
    w_nov = filt.novelty_weight if kind == "hcmci" else 1.0
    z_own = z_hood[own]
    HtR = HtRinv[own]

    def run():
        xp, Pp = predict()
        Om = np.linalg.inv(Pp)
        Om = 0.5 * (Om + Om.T)
        qv = Om @ xp
        iv = HtR @ z_own
        if kind == "icf":
            cur = [(Om / N + I_i, qv / N + iv)]
        elif kind == "ci":
            cur = [(Om + I_i, qv + iv)]
        else:
            cur = [(Om, qv), (I_i, iv)]
        for rnd in msgs:  # one consensus round: own pair weighted, plus the neighbours' received pairs
            cur = [(w_self * M + np.einsum("k,kab->ab", w_nb, Mn), w_self * v + w_nb @ vn)
                   for (M, v), (Mn, vn) in zip(cur, rnd)]
        if kind == "hcmci":
            Om_f, q_f = cur[0][0] + w_nov * cur[1][0], cur[0][1] + w_nov * cur[1][1]
        else:
            Om_f, q_f = cur[0]
        Pf = np.linalg.inv(Om_f)
        Pf = 0.5 * (Pf + Pf.T)
        if kind == "icf":
            return Pf @ q_f, Pf / N
        return Pf @ q_f, Pf

    return AgentStep(run=run, **step)


def max_deviation(step: AgentStep) -> float:
    """Largest absolute difference between the one-agent step and agent i's row of the team-wide filter.

    Parameters
    ----------
    step : AgentStep
        From :func:`agent_step`.

    Returns
    -------
    float
        ``max |run() - reference()|`` over the arrays returned (rounding: about 1e-15 relative);
        NaN for a whole filter, which has no separate reference.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> bool(agent_cost.max_deviation(agent_cost.agent_step("team", "song-mb", 6, agent=2)) < 1e-12)
    True
    """
    if not isinstance(step, AgentStep):
        raise TypeError(f"step must be an AgentStep (from agent_step); got {type(step).__name__}")
    if step.reference is None:
        return float("nan")
    return max(float(np.max(np.abs(np.asarray(a) - np.asarray(b)))) for a, b in zip(step.run(), step.reference()))


# --------------------------------------------------------------------------------------------
# timing


def blas_pinned() -> str:
    """How BLAS is held to one thread: ``"threadpoolctl"`` if installed, else the ``OMP_NUM_THREADS`` value.

    Returns
    -------
    str
        ``"threadpoolctl"``, or ``"OMP_NUM_THREADS=<value>"`` (``<unset>`` when not set: the timing may
        then use several BLAS threads and count only this thread's CPU).

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.blas_pinned().startswith(("threadpoolctl", "OMP_NUM_THREADS="))
    True
    """
    try:
        import threadpoolctl  # noqa: F401
    except ImportError:
        return f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', '<unset>')}"
    return "threadpoolctl"


def agent_step_cost(task: str, method: str, n_agents: int, *, repeats: int = 7, min_time: float = 0.02,
                    agent: int = 0, seed: int = 0,
                    settings: compare.BenchmarkSettings = compare.SETTINGS) -> float:
    """CPU time (µs) of one agent's step (:func:`agent_step`): one run, one thread, median of `repeats`.

    After one warm-up call, each repeat calls the step enough times to last about
    `min_time` seconds of this thread's CPU (``time.thread_time``) and keeps the
    time per call; the median of the repeats is returned (robust to other processes on
    the machine). BLAS is held to one thread by ``threadpoolctl`` when installed; else
    the caller must set ``OMP_NUM_THREADS=1`` (see :func:`blas_pinned`).

    Parameters
    ----------
    task, method, n_agents, agent, seed, settings
        As :func:`agent_step`.
    repeats : int
        Timed repeats (>= 1).
    min_time : float
        Seconds of CPU per repeat (at least one call).

    Returns
    -------
    float
        µs per step.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.agent_step_cost("target", "local", 4, repeats=3, min_time=0.001) > 0
    True
    """
    repeats = check_positive_int(repeats, "repeats")
    if not (isinstance(min_time, (int, float)) and np.isfinite(min_time) and min_time >= 0):
        raise ValueError(f"min_time must be a finite number of seconds >= 0; got {min_time!r}")
    step = agent_step(task, method, n_agents, agent=agent, seed=seed, settings=settings)
    with _one_thread():
        tic = time.thread_time()
        step.run()  # warm-up (and the cost of one call, to choose the number of calls per repeat)
        once = max(time.thread_time() - tic, 1e-7)
        number = max(1, int(min_time / once))
        samples = []
        for _ in range(repeats):
            tic = time.thread_time()
            for _ in range(number):
                step.run()
            samples.append((time.thread_time() - tic) / number)
    return 1e6 * float(np.median(samples))


class _one_thread:
    """``threadpoolctl.threadpool_limits(1)`` when installed; else nothing (OMP_NUM_THREADS must be 1)."""

    def __enter__(self):
        try:
            from threadpoolctl import threadpool_limits
        except ImportError:
            self._ctx = None
            return self
        self._ctx = threadpool_limits(1)
        self._ctx.__enter__()
        return self

    def __exit__(self, *exc):
        if self._ctx is not None:
            self._ctx.__exit__(*exc)
        return False


# --------------------------------------------------------------------------------------------
# analytic counts


def _kind(method: str) -> str:
    return method.rsplit("-L", 1)[0] if "-L" in method else method


def agent_flops(task: str, method: str, n_agents: int, degree: int = 2) -> float:
    """Analytic floating-point operations of one agent per step (leading terms; a multiply-add is 2).

    The fusion filters (target and localization) count as :func:`mascore.fusion.filter_cost`
    (n = 4, q = 1; localization n = 2N, q = 2d). The team task counts the textbook
    algorithm at n = 4: a Kalman step ``4 n^3`` (prediction) plus ``26/3 n^3`` (information
    update); forwarding one more inverse; the Vlahakis observer ``2 n^2 + 4 d``; Song et
    al.'s measurement-based filter one agent's own team covariance (dimension Nn, with its
    (d + 1) n measurements), the estimation-based one the joint covariance of all N team
    estimates (dimension N^2 n) predicted densely; the centralized filter the team's.

    Parameters
    ----------
    task : {"team", "target", "localization"}
        The scenario.
    method : str
        One of ``AGENT_METHODS[task]``.
    n_agents : int
        N.
    degree : int
        d (2 on the ring).

    Returns
    -------
    float
        Flops per step of the busiest agent.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.agent_flops("team", "song-eb", 16) / agent_cost.agent_flops("team", "song-eb", 8)  # O(N^6)
    64.0
    """
    _check_task_method(task, method)
    N = check_positive_int(n_agents, "n_agents")
    d = check_positive_int(degree, "degree", minimum=0)
    if task != "team":
        return float(compare.target_cost(method, N, d, task)[1])
    n = 4
    kf = 4 * n**3 + 2 * n**2 + 26 / 3 * n**3 + 8 * n**2  # prediction + information update
    if method == "local":
        return float(kf)
    if method == "forwarding":
        return float(kf + n**3 + 2 * (d + 1) * n)
    if method == "set-membership":
        return float(kf + 2 * n**3)  # the closed-form correction, and the prediction's two products
    if method == "vlahakis":
        return float(2 * n**2 + 2 * n * 2 + 4 * d + 2 * n)
    if method == "centralized":
        return float(fusion.filter_cost("centralized", n=N * n, q=(d + 1) * n, degree=d, n_agents=N).flops)
    if method == "song-mb":  # one agent's own team covariance, dimension N n, its (d + 1) n measurements
        return float(fusion.filter_cost("measurement-forwarding", n=N * n, q=n, degree=d).flops)
    M = N * N * n  # song-eb: the joint covariance, predicted densely (two products of M^3 each)
    return float(4 * M**3)


def agent_memory(task: str, method: str, n_agents: int, degree: int = 2) -> float:
    """Floats one agent holds per step (its estimate, covariance and the messages of one round; leading terms).

    Parameters
    ----------
    task, method, n_agents, degree
        As :func:`agent_flops`.

    Returns
    -------
    float
        Floats (x 8 bytes).

    Examples
    --------
    >>> from mascore import agent_cost
    >>> agent_cost.agent_memory("team", "song-eb", 8) / agent_cost.agent_memory("team", "song-eb", 4)  # O(N^4)
    16.0
    """
    _check_task_method(task, method)
    N = check_positive_int(n_agents, "n_agents")
    d = check_positive_int(degree, "degree", minimum=0)
    n = 4 if task != "localization" else 2 * N
    kind = _kind(method)
    if (task, method) in WHOLE_FILTER:
        if method == "song-eb":
            return float((N * N * n) ** 2)
        if task == "team":
            return float((N * n) ** 2 + N * n)
        return float(n**2 + n)
    if method == "song-mb":  # its team estimate and its own covariance of the whole team
        return float((N * n) ** 2 + N * n)
    if kind in ("ci", "hcmci", "icf", "ci-diffusion"):
        pairs = 2 if kind == "hcmci" else 1
        return float((d + 1) * pairs * (n**2 + n))
    if method == "vlahakis":
        return float(n + d * n)
    return float(n**2 + n + d * n)


# --------------------------------------------------------------------------------------------
# the table


def _order_key(task: str, method: str) -> tuple[str, str]:
    return (task, method) if (task, method) in AGENT_ORDER else (task, _kind(method))


def agent_costs(sizes: Sequence[int] = (4, 8, 16, 32, 64, 128), tasks: Sequence[str] = AGENT_TASKS,
                methods: Sequence[str] | None = None, *, repeats: int = 7, min_time: float = 0.02,
                settings: compare.BenchmarkSettings = compare.SETTINGS, progress: bool = False):
    """:func:`agent_step_cost` over team sizes, with log-log slopes and the analytic counts.

    Parameters
    ----------
    sizes : sequence of int
        Team sizes N (each >= 3). A method is measured up to its :data:`MAX_AGENTS` limit.
    tasks : sequence of str
        Tasks (:data:`AGENT_TASKS`).
    methods : sequence of str, optional
        Methods (default: every method of each task); a method not in a task is skipped.
    repeats, min_time : int, float
        As :func:`agent_step_cost`.
    settings : mascore.compare.BenchmarkSettings
        The benchmark's settings.
    progress : bool
        Print each measurement as it is made.

    Returns
    -------
    pandas.DataFrame
        One row per (task, method, N): ``us_per_step`` (NaN beyond the method's limit),
        ``flops`` (:func:`agent_flops`), ``memory_floats`` (:func:`agent_memory`), ``scope``,
        ``work`` and ``memory`` (the orders of :data:`AGENT_ORDER`), ``stops_at`` and ``why``.

    Examples
    --------
    >>> from mascore import agent_cost
    >>> t = agent_cost.agent_costs((4, 8), ("target",), ("local",), repeats=3, min_time=0.001)
    >>> t[["task", "method", "n_agents"]].values.tolist()
    [['target', 'local', 4], ['target', 'local', 8]]
    """
    import pandas as pd

    sizes = [compare._check_n_agents(n) for n in sizes]
    rows = []
    for task in tasks:
        if task not in AGENT_TASKS:
            raise ValueError(f"tasks must be among {AGENT_TASKS}; got {task!r}")
        for m in (AGENT_METHODS[task] if methods is None else [m for m in methods if m in AGENT_METHODS[task]]):
            limit, why = MAX_AGENTS.get((task, m), (max(sizes), ""))
            for N in sizes:
                us = agent_step_cost(task, m, N, repeats=repeats, min_time=min_time, settings=settings) \
                    if N <= limit else np.nan
                if progress:
                    print(f"{task:13s} {m:15s} N = {N:4d}: {us:12.1f} us", flush=True)
                work, mem = AGENT_ORDER[_order_key(task, m)]
                rows.append({"task": task, "method": m, "n_agents": N, "us_per_step": us,
                             "flops": agent_flops(task, m, N), "memory_floats": agent_memory(task, m, N),
                             "scope": "whole filter" if (task, m) in WHOLE_FILTER else "one agent",
                             "work": work, "memory": mem, "stops_at": min(limit, max(sizes)), "why": why})
    return pd.DataFrame(rows)


def slopes(table, top: int | None = None):
    """Log-log slopes in N of the measured time and of the analytic flops, per (task, method).

    Parameters
    ----------
    table : pandas.DataFrame
        :func:`agent_costs`' table.
    top : int, optional
        Fit only the `top` largest measured N (default: all), where flops outweigh the per-call overhead.

    Returns
    -------
    pandas.DataFrame
        Index ``(task, method)``; ``slope`` (measured), ``flops_slope`` (analytic, same N), ``measured_to`` (largest N).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore import agent_cost
    >>> t = pd.DataFrame({"task": "team", "method": "x", "n_agents": [4, 8], "us_per_step": [1.0, 8.0],
    ...                   "flops": [1.0, 4.0]})
    >>> agent_cost.slopes(t)[["slope", "flops_slope"]].values.tolist()
    [[3.0, 2.0]]
    """
    import pandas as pd

    out = {}
    for (task, method), g in table.groupby(["task", "method"], sort=False):
        g = g.dropna(subset=["us_per_step"]).sort_values("n_agents")
        if top is not None:
            g = g.tail(int(top))
        out[(task, method)] = {"slope": _slope(g["n_agents"], g["us_per_step"]),
                               "flops_slope": _slope(g["n_agents"], g["flops"]),
                               "measured_to": int(g["n_agents"].max()) if len(g) else 0}
    result = pd.DataFrame.from_dict(out, orient="index")
    result.index = pd.MultiIndex.from_tuples(result.index, names=["task", "method"])
    return result


def _slope(n, y) -> float:
    """Least-squares slope of log y on log n (NaN with fewer than two points)."""
    n, y = np.asarray(n, float), np.asarray(y, float)
    return float(np.polyfit(np.log(n), np.log(y), 1)[0]) if len(n) > 1 else float("nan")
