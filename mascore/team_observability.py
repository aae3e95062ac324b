"""When the team filters work (Song et al. 2023, Theorem 1): observability of system (43) and eq. (49).

:func:`observable_agents` and :func:`require_observable` test the pairs ``(F_1, H_i)`` of
system (43) on the sensing graph; :func:`lyapunov_v` is the Lyapunov function of eq. (45)
and :func:`theorem1_min_eigenvalues` the smallest eigenvalues of ``M_i[k+1]`` (eq. (49))
along a run of :class:`mascore.distributed_kf.TeamFilter`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ._systems import output_matrices
from ._team_kernels import (
    check_covariances,
    check_model,
    check_team_laplacian,
    reduced_nees,
)
from ._validation import (
    check_adjacency_stack,
    check_covariance,
    check_positive,
    check_positive_int,
    check_square,
    finite_result,
    kron_factor,
    symmetric_part,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .graphs import laplacian as graph_laplacian
from .sensing import sensing_mask
from .team_model import TeamFilterModel, closed_loop_matrices

__all__ = [
    "observable_agents",
    "require_observable",
    "lyapunov_v",
    "theorem1_min_eigenvalues",
]


def observable_agents(A: ArrayLike, BK: ArrayLike, adjacency: ArrayLike, tol: float = 1e-8, *,
                      C: ArrayLike | None = None) -> np.ndarray:
    """Which agents' pairs ``(F_1, H_i)`` of system (43) are observable.

    ``H_i`` takes the outputs ``C_j x_j`` of the agents ``j`` in agent i's closed neighbourhood
    ``N̄_i`` (full states, ``C_j = I``, by default: Song et al.'s eq. (2)).

    For an undirected graph, ``L = V Λ V^T`` block-diagonalizes
    ``F_1 = (V ⊗ I)(I ⊗ A - Λ ⊗ BK)(V ⊗ I)^T``. When the blocks
    ``A - λ BK`` of different Laplacian eigenvalues share no eigenvalue and
    each is non-derogatory (true for the double integrator with positive
    gains), the PBH test reduces to the graph: ``(F_1, H_i)`` is observable
    iff, for every Laplacian eigenvalue ``λ`` with eigenvector basis
    ``V_λ``, the rows of ``V_λ`` of the agents in ``N̄_i`` have full column
    rank. Symmetric "twin" agents outside ``N̄_i`` (same neighbours) break it.
    This test is well conditioned; otherwise (directed graphs, or the
    conditions fail) a rank test of the observability matrix of the shifted
    system is used, which can call weakly observable pairs unobservable.
    With output matrices ``C_j`` the eigenvectors are still ``v ⊗ w`` (``w`` an
    eigenvector of ``A - λ BK``, times ``I_k`` on the spatial axes when
    ``A = A_r ⊗ I_k``), seen by agent i only through the outputs ``C_j w`` of the
    agents ``j`` in ``N̄_i``: with one ``C`` for all, the pair ``(A - λ BK, C)``
    must be observable for every Laplacian eigenvalue ``λ`` (positions only of the
    double integrator pass; velocities only do not: the team's common position is
    unseen). The fallback with outputs is a dense PBH test.

    Parameters
    ----------
    A : (m, m) array_like
        Agent transition matrix.
    BK : (m, m) array_like
        Input matrix times consensus gain.
    adjacency : (N, N) array_like
        Fixed topology (defines ``F_1`` and ``H_i``).
    tol : float
        Relative tolerance of the rank decisions.
    C : (p, m) or (N, p, m) array_like, optional
        Output matrix of the measurements (one for all agents or one per agent); default the
        identity (full states).

    Returns
    -------
    (N,) ndarray of bool

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import team_model, team_observability
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> team_observability.observable_agents(agent.A, agent.B @ K, graphs.star_graph(4))   # leaves see twin leaves
    array([ True, False, False, False])
    """
    A = check_square(_float_array(A, "A"), "A")
    BK = check_square(_float_array(BK, "BK"), "BK", A.shape[0])
    if A.shape[0] == 0:
        raise ValueError("A must be at least 1 x 1 (an agent with no state)")
    tol = check_positive(tol, "tol", "(relative rank tolerance)")
    m = A.shape[0]
    Adj = check_adjacency_stack(adjacency)
    if Adj.ndim != 2:
        raise ValueError(f"adjacency must be a single (N, N) topology here; got shape {Adj.shape}")
    S = sensing_mask(Adj, allow_isolated=True)
    L = graph_laplacian(Adj)
    if C is not None:
        return _observable_with_outputs(A, BK, Adj, S, L, output_matrices(C, m, Adj.shape[0]), tol)
    # work on the per-axis factor when A = A_r ⊗ I_k and BK = BK_r ⊗ I_k (same rank test)
    for k in range(m, 0, -1):
        if m % k == 0 and kron_factor(A, k) is not None and kron_factor(BK, k) is not None:
            A, BK, m = kron_factor(A, k), kron_factor(BK, k), m // k
            break
    if np.allclose(Adj, Adj.T):
        graph_test = _graph_observability(A, BK, L, S, tol)
        if graph_test is not None:
            return graph_test
    F1, _ = closed_loop_matrices(A, BK, L)
    out = []
    for row in S:
        H = np.kron(np.eye(row.size)[row], np.eye(m))
        out.append(_observable(F1, H, tol))
    return np.array(out)


def _observable_with_outputs(A, BK, Adj, S, L, C, tol) -> np.ndarray:
    """:func:`observable_agents` with output matrices `C` ``(N, p, m)``.

    With ``A = A_r ⊗ I_k`` and ``BK = BK_r ⊗ I_k`` (whatever `C`), ``F_1``'s eigenspace of a
    Laplacian eigenvalue ``λ`` (basis ``V_λ``) and an eigenvalue of ``A_r - λ BK_r`` (eigenvector
    ``w``, the block non-derogatory) is ``{(V_λ ⊗ w ⊗ I_k) c}``, and agent i sees all of it iff
    the stack over ``j`` in ``N̄_i`` of ``V_λ[j] ⊗ (C_j (w ⊗ I_k))`` has full column rank (PBH).
    Otherwise (a directed graph, or blocks that share eigenvalues) a dense PBH test.
    """
    m = A.shape[0]
    k = next(f for f in range(m, 0, -1)
             if m % f == 0 and kron_factor(A, f) is not None and kron_factor(BK, f) is not None)
    if np.allclose(Adj, Adj.T):
        blocks = _eigen_blocks(kron_factor(A, k), kron_factor(BK, k), L)
        if blocks is not None:
            V, groups, W = blocks
            N, p = C.shape[:2]
            Cn = C / max(1.0, float(np.abs(C).max()))
            out = np.ones(N, dtype=bool)
            for gi, g in enumerate(groups):
                for w in W[gi].T:  # every eigenvector of the block (one per eigenvalue)
                    T = Cn @ np.kron(w[:, None], np.eye(k))  # (N, p, k): C_j (w ⊗ I_k)
                    blk = V[:, g][:, :, None, None] * T[:, None]  # (N, |g|, p, k): V_λ[j, a] T_j
                    rows = np.moveaxis(blk, 2, 1).reshape(N, p, len(g) * k)  # agent j's p rows
                    O = (S[:, :, None, None] * rows[None]).reshape(N, N * p, len(g) * k)  # zero rows: j not in N̄_i
                    out &= np.linalg.svd(O, compute_uv=False)[:, -1] > tol
            return out
    F1, _ = closed_loop_matrices(A, BK, L)
    N, p = C.shape[:2]
    H = np.zeros((N, p, N, m))
    H[np.arange(N), :, np.arange(N), :] = C
    H = H.reshape(N * p, N * m)
    return np.array([_pbh_observable(F1, H[np.repeat(row, p)]) for row in S])


def _eigen_blocks(A, BK, L):
    """``(V, groups, W)``: Laplacian eigenvectors, their eigenvalue groups and each group's eigenvectors of
    ``A - λ BK`` (columns of ``W[g]``, unit norm), or None when the blocks are derogatory or share eigenvalues.

    The zero Laplacian eigenvalue is taken exactly and each eigenvector is the null vector of
    ``A - λ BK - μ I`` at the mean of ``μ``'s rounding cluster (a Jordan block's eigenvalue splits).
    """
    lam, V = np.linalg.eigh(L)
    scale = max(1.0, float(np.max(np.abs(lam))))
    cuts = np.flatnonzero(np.diff(lam) > 1e-7 * scale) + 1
    groups = np.split(np.arange(lam.size), cuts)
    m = A.shape[0]
    lam_g = np.array([lam[g].mean() for g in groups])
    lam_g = np.where(np.abs(lam_g) <= 1e-7 * scale, 0.0, lam_g)
    M = A[None] - lam_g[:, None, None] * BK[None]  # (G, m, m)
    mu = np.linalg.eigvals(M)  # (G, m)
    near = np.abs(mu[:, :, None] - mu[:, None, :]) < 1e-6
    mu = np.einsum("gab,gb->ga", near, mu) / near.sum(axis=-1)  # cluster means
    if m > 1:  # non-derogatory: every eigenvalue has a one-dimensional eigenspace
        sv = np.linalg.svd(M[:, None] - mu[:, :, None, None] * np.eye(m), compute_uv=False)
        if np.any(sv[..., m - 2] <= 1e-6 * np.maximum(1.0, sv[..., 0])):
            return None
    gid = np.repeat(np.arange(len(groups)), m)
    dist = np.abs(mu.reshape(-1)[:, None] - mu.reshape(-1)[None, :])
    if np.any(dist[gid[:, None] != gid[None, :]] < 1e-6):
        return None
    _, _, Vh = np.linalg.svd(M[:, None].astype(complex) - mu[:, :, None, None] * np.eye(m))
    W = np.swapaxes(np.conj(Vh[..., -1, :]), -1, -2)  # (G, m, m): column e is the null vector of eigenvalue e
    return V, groups, W


def _graph_observability(A, BK, L, S, tol) -> np.ndarray | None:
    """PBH test through the Laplacian eigenvectors (see :func:`observable_agents`); None if not applicable."""
    lam, V = np.linalg.eigh(L)
    scale = max(1.0, float(np.max(np.abs(lam))))
    cuts = np.flatnonzero(np.diff(lam) > 1e-7 * scale) + 1
    groups = np.split(np.arange(lam.size), cuts)
    m = A.shape[0]
    lam_g = np.array([lam[g].mean() for g in groups])
    M = A[None] - lam_g[:, None, None] * BK[None]  # (G, m, m)
    mu = np.linalg.eigvals(M)  # (G, m)
    if m > 1:  # non-derogatory: every eigenvalue has a one-dimensional eigenspace
        sv = np.linalg.svd(M[:, None] - mu[:, :, None, None] * np.eye(m), compute_uv=False)
        if np.any(sv[..., m - 2] <= 1e-6 * np.maximum(1.0, sv[..., 0])):
            return None
    gid = np.repeat(np.arange(len(groups)), m)
    dist = np.abs(mu.reshape(-1)[:, None] - mu.reshape(-1)[None, :])
    if np.any(dist[gid[:, None] != gid[None, :]] < 1e-6):
        return None
    Sf = S.astype(float)
    out = np.ones(S.shape[0], dtype=bool)
    for g in groups:
        Vg = V[:, g]
        rows = Sf[:, :, None] * Vg[None]  # rows of V_g outside N̄_i zeroed (singular values unchanged)
        out &= np.linalg.svd(rows, compute_uv=False)[:, -1] > tol
    return out


def require_observable(A: ArrayLike, BK: ArrayLike, adjacency: ArrayLike, *, C: ArrayLike | None = None) -> None:
    """Raise ``ValueError`` naming the agents for which system (43) is unobservable.

    Parameters
    ----------
    A : (m, m) array_like
        Agent transition matrix.
    BK : (m, m) array_like
        Input matrix times consensus gain.
    adjacency : (N, N) array_like
        Sensing graph.
    C : (p, m) or (N, p, m) array_like, optional
        Output matrix of the measurements (default: full states).

    Raises
    ------
    ValueError
        Naming the agents whose filter cannot estimate the team.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import team_model, team_observability
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> try:
    ...     team_observability.require_observable(agent.A, agent.B @ K, graphs.star_graph(4))
    ... except ValueError as exc:
    ...     print(str(exc)[:22])
    system (43) (F_1, H_i)
    """
    Adj = check_adjacency_stack(adjacency)
    if Adj.ndim != 2:
        raise ValueError(f"adjacency must be a single (N, N) topology here; got shape {Adj.shape}")
    sensing_mask(Adj)  # isolated agents first, with their own message
    ok = observable_agents(A, BK, adjacency, C=C)
    if not np.all(ok):
        bad = np.flatnonzero(~ok).tolist()
        if C is None:
            raise ValueError(
                f"system (43) (F_1, H_i) is not observable for agent(s) {bad} with this topology (F_1 from A, BK "
                "and the adjacency's Laplacian, H_i from the adjacency): "
                "Theorem 1 does not apply and the estimation-based loop needs an observable graph "
                "(symmetric neighbourhoods, e.g. a star seen from a leaf, hide modes)"
            )
        raise ValueError(
            f"system (43) (F_1, H_i) is not observable for agent(s) {bad} with this topology and output matrix C "
            "(F_1 from A, BK and the adjacency's Laplacian, H_i = the outputs C_j x_j of agent i and its "
            "neighbours): Theorem 1 does not apply and agent i's whole-team filter cannot estimate the team. "
            "Measure more states (C must see every mode of A - λ BK, for every Laplacian eigenvalue λ: "
            "positions of a double integrator do, velocities alone do not) or change the graph (symmetric "
            "neighbourhoods, e.g. a star seen from a leaf, hide modes)"
        )


def lyapunov_v(error: ArrayLike, Sigma_r: ArrayLike, kron: int = 1) -> np.ndarray:
    """Lyapunov function of eq. (45), ``V = e_i^T Σ_i^{-1} e_i`` (= the NEES).

    Parameters
    ----------
    error : (..., M) array_like
        ``e_i = X - X̂_i`` (full team dimension ``M = kron M_r``).
    Sigma_r : (..., M_r, M_r) array_like
        Reduced covariance ``Σ̄_i`` (``Σ_i = Σ̄_i ⊗ I_kron``).
    kron : int
        Kronecker factor of the model.

    Returns
    -------
    (...) ndarray
        ``V``, chi-square distributed with ``M`` dof for a consistent filter.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import team_observability
    >>> float(team_observability.lyapunov_v(np.ones(6), np.eye(6)))
    6.0
    """
    kron = check_positive_int(kron, "kron")
    e = _finite(_float_array(error, "error"), "error")
    P = check_covariance(_float_array(Sigma_r, "Sigma_r"), "Sigma_r", definite=True)
    Mr = P.shape[-1]
    if e.ndim < 1 or e.shape[-1] != Mr * kron:
        raise ValueError(
            f"Incompatible dimensions of error; expected (..., {Mr * kron}) = Sigma_r size {Mr} x kron {kron} "
            f"but found {e.shape}"
        )
    try:
        np.broadcast_shapes(e.shape[:-1], P.shape[:-2])
    except ValueError:
        raise ValueError(f"the batch axes of error {e.shape} and Sigma_r {P.shape} do not broadcast") from None
    if e.size and np.abs(e).max() > 1e150:
        raise ValueError(f"error has entries of magnitude {np.abs(e).max():.3g}: squared they overflow floating "
                         f"point; rescale its units")
    return reduced_nees(e, P, kron)


def theorem1_min_eigenvalues(
    model: TeamFilterModel, laplacian: ArrayLike, KH: ArrayLike, Sigma_i: ArrayLike, F2_cross: ArrayLike
) -> dict[str, np.ndarray]:
    """Smallest eigenvalues of ``M_i[k+1]`` (eq. (49)) along a run.

    ``M_i[k+1] = Σ_i[k]^{-1} - 𝓕_{i,1}^T 𝓕_{i,2}^T Σ_i[k+1]^{-1} 𝓕_{i,2} 𝓕_{i,1}``
    with ``𝓕_{i,1}[k] = F_1 + F_2 C_i[k]`` and ``𝓕_{i,2}[k+1] = I - G_i H_i[k+1]``.

    ``C_i`` of Lemma 1 (eq. (44)) is taken as the regression map
    ``C_i[k] = E[e e_i^T] Σ_i[k]^{-1}``: then ``α_i = e - C_i e_i`` is
    uncorrelated with ``e_i``, which eqs. (48) and (51) of the proof need, and
    ``C_i[0] = 1_N ⊗ I`` when all agents start from a common estimate. (The
    literal recursion ``C_i[k+1] = 𝓕 C_i (𝓕_{i,2} 𝓕_{i,1})^{-1}`` is a ratio of
    different agents' error-transition products and grows without bound within a
    few steps.) With this choice eq. (59) shows ``M_i`` is positive definite
    whenever the covariance recursion is right, so the check is a consistency
    test of eqs. (29)-(34).

    Parameters
    ----------
    model : TeamFilterModel
        The team model.
    laplacian : (N, N) array_like
        Fixed topology.
    KH : (T+1, N, M_r, M_r) array_like
        Reduced ``G_i H_i[k]`` (entry 0 unused).
    Sigma_i : (T+1, N, M_r, M_r) array_like
        Reduced posterior ``Σ̄_i[k]``.
    F2_cross : (T+1, N, M_r, M_r) array_like
        ``F_2 E[e e_i^T]`` from :func:`~mascore.distributed_kf.f2_cross`.

    Returns
    -------
    dict with
        ``min_eig`` (T, N): smallest eigenvalue of ``M_i[k+1]``;
        ``min_eig_rel`` (T, N): smallest eigenvalue of
        ``Σ_i^{1/2} M_i Σ_i^{1/2}`` (scale-free, at most 1).

    Examples
    --------
    >>> from mascore.papers import song2023
    >>> r = song2023.fig2(seed=0, n_runs=2, horizon=4.0)
    >>> sorted(song2023.theorem1(r))                                # via this function
    ['min_eig', 'min_eig_rel']
    """
    model = check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = check_team_laplacian(laplacian, N)
    if L.ndim != 2:
        raise ValueError(f"laplacian must be a single fixed ({N}, {N}) topology here; got shape {L.shape}")
    KH = _finite(_float_array(KH, "KH"), "KH")
    Sig = check_covariances(Sigma_i, "Sigma_i", (None, N, Mr, Mr), definite=True, kron=model.kron)
    F2C_all = _finite(_float_array(F2_cross, "F2_cross"), "F2_cross")
    if Sig.shape[0] < 2:
        raise ValueError(f"Sigma_i must hold at least two steps (T+1 >= 2); got shape {Sig.shape}")
    for name, arr in (("KH", KH), ("F2_cross", F2C_all)):
        if arr.shape != Sig.shape:
            raise ValueError(
                f"Incompatible dimensions of {name}; KH, Sigma_i and F2_cross must all have shape "
                f"(T+1, {N}, {Mr}, {Mr}); got {name} {arr.shape} and Sigma_i {Sig.shape}"
            )
    F1 = np.kron(np.eye(N), model.A_r) - np.kron(L, model.BK_r)
    eye = np.eye(Mr)
    Sig_inv = np.linalg.inv(Sig)
    F2C = F2C_all[:-1] @ Sig_inv[:-1]  # F_2 C_i[k]
    T = (eye - KH[1:]) @ (F1 + F2C)  # 𝓕_{i,2}[k+1] 𝓕_{i,1}[k], (T, N, Mr, Mr)
    M = Sig_inv[:-1] - np.swapaxes(T, -1, -2) @ Sig_inv[1:] @ T
    root = np.linalg.cholesky(Sig[:-1])
    rel = np.swapaxes(root, -1, -2) @ M @ root
    out = {
        "min_eig": np.linalg.eigvalsh(symmetric_part(M))[..., 0],
        "min_eig_rel": np.linalg.eigvalsh(symmetric_part(rel))[..., 0],
    }
    finite_result("Theorem 1 eigenvalue computation", *out.values())
    return out


def _pbh_observable(F: np.ndarray, H: np.ndarray) -> bool:
    """PBH test: ``[F - mu I; H]`` of full column rank at every eigenvalue ``mu`` of ``F``.

    Rounding splits a Jordan block's eigenvalue into a cluster; the test runs at each cluster's mean
    (which recovers the eigenvalue to high accuracy). The rank is decided at ``1e-6`` relative to
    ``max(1, |F - I|, |H|)``: weakly observable modes count as unobservable. ``O(n^4)`` work: the
    fallback of small or unstructured teams.
    """
    n = F.shape[0]
    mu = np.linalg.eigvals(F)
    near = np.abs(mu[:, None] - mu[None, :]) < 1e-6
    shifts = np.unique(np.round((near @ mu) / near.sum(axis=1), 12))
    stacked = np.concatenate([F[None].astype(complex) - shifts[:, None, None] * np.eye(n),
                              np.broadcast_to(H.astype(complex), (shifts.size, *H.shape))], axis=1)
    smallest = np.linalg.svd(stacked, compute_uv=False)[:, -1]
    size = max(1.0, float(np.abs(F - np.eye(n)).max()), float(np.abs(H).max()))
    return bool(np.all(smallest > 1e-6 * size))


def _observable(F: np.ndarray, H: np.ndarray, tol: float) -> bool:
    """Rank test of the observability matrix ``[H; H F; ...; H F^{n-1}]``.

    ``(F, H)`` and ``(F - I, H)`` have the same unobservable subspace; the
    shifted matrix is used, scaled to unit norm, because a sampled system has
    ``F ≈ I`` and its plain powers hide the information in tiny differences.
    Each block is also rescaled (rank unchanged); one SVD decides.
    """
    n = F.shape[0]
    G = F - np.eye(n)
    gn = np.linalg.norm(G)
    F = G / gn if gn > 0 else G
    blocks, blk = [], H
    for _ in range(n):
        nrm = np.linalg.norm(blk)
        if nrm == 0:
            break
        blk = blk / nrm
        blocks.append(blk)
        blk = blk @ F
    s = np.linalg.svd(np.vstack(blocks), compute_uv=False)
    return int(np.sum(s > tol * s[0])) == n
