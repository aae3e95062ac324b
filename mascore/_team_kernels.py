"""The checks and structured kernels shared by the team filters (no checks of their own: callers check).

Used by :mod:`mascore.distributed_kf`, :mod:`mascore.centralized_team_filter` and
:mod:`mascore.team_observability`; shapes as in :mod:`mascore.distributed_kf` (reduced
covariances ``(batch, N, M_r, M_r)`` per agent or ``(batch, N M_r, N M_r)`` augmented). The last section
holds the steps of :class:`~mascore.distributed_kf.TeamFilter` on its own arrays (row blocks in place).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike

from ._validation import (
    check_covariance,
    check_mask_values,
    finite_result,
    symmetric_part,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .team_model import TeamFilterModel


def finite_state(what: str, *arrays: np.ndarray, diagonal_only: bool = False) -> None:
    """:func:`mascore._validation.finite_result` on a step's results (estimates first, covariance second).

    With `diagonal_only` the covariance is tested on its diagonal only: the update that follows
    every prediction tests all of it (a NaN of the prediction stays in place through the update).
    """
    if diagonal_only:
        arrays = (arrays[0], np.diagonal(arrays[1], axis1=-2, axis2=-1), *arrays[2:])
    finite_result(what, *arrays)


def check_model(model: object) -> TeamFilterModel:
    if not isinstance(model, TeamFilterModel):
        raise TypeError(
            f"model must be a TeamFilterModel (build it with team_filter_model); got {type(model).__name__}"
        )
    return model


def check_estimates(model: TeamFilterModel, X: ArrayLike, name: str) -> np.ndarray:
    """Team estimates or measurements ``(runs, N, N, m)``, finite."""
    X = _float_array(X, name)
    N, m = model.n_agents, model.m
    if X.ndim != 4 or X.shape[1:] != (N, N, m):
        raise ValueError(f"Incompatible dimensions of {name}; expected (runs, {N}, {N}, {m}) but found {X.shape}")
    return _finite(X, name)


def check_measurements(model: TeamFilterModel, Z: ArrayLike, name: str = "Z") -> np.ndarray:
    """Every agent's measurements ``(runs, N, N, p)`` (``p = m`` for full states), finite."""
    if model.full_state:
        return check_estimates(model, Z, name)
    Z = _float_array(Z, name)
    N, p = model.n_agents, model.p
    if Z.ndim != 4 or Z.shape[1:] != (N, N, p):
        raise ValueError(f"Incompatible dimensions of {name}; expected (runs, {N}, {N}, {p}) (p = {p} outputs "
                         f"C_j x_j per measured agent) but found {Z.shape}")
    return _finite(Z, name)


def team_output_matrix(model: TeamFilterModel) -> np.ndarray:
    """``H = blockdiag(C_r_1, ..., C_r_N)`` ``(N p_r, M_r)``: every agent's outputs of the reduced team state."""
    N, mr = model.n_agents, model.m_r
    pr = model.C_r.shape[1]
    H = np.zeros((N, pr, N, mr))
    H[np.arange(N), :, np.arange(N), :] = model.C_r
    return H.reshape(N * pr, N * mr)


def output_gain(model: TeamFilterModel, H: np.ndarray, Sig: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, ...]:
    """Each agent's gain of partial sensing, eq. (19) with ``H_i = D_i H`` (its sensed rows of ``H``).

    ``G_i = Σ_i^- H^T D (D (H Σ_i^- H^T + R) D + I - D)^{-1} D``: the masked rows of the sensed agents'
    outputs (``D = diag(S_i) ⊗ I_{p_r}``); a row not sensed has a zero column in ``G_i``.

    Parameters
    ----------
    model : TeamFilterModel
        A model with output matrices (reduced ``C_r``, ``R_r`` of size ``N p_r``).
    H : (N p_r, M_r) ndarray
        :func:`team_output_matrix`.
    Sig : (batch, N, M_r, M_r) ndarray
        Each agent's predicted reduced covariance ``Σ̄_i^-``.
    S : (batch, N, N) ndarray of bool
        Sensing mask.

    Returns
    -------
    G : (batch, N, M_r, N p_r) ndarray
        The gains on the stacked outputs.
    KH : (batch, N, M_r, M_r) ndarray
        ``G_i H``.
    GRG : (batch, N, M_r, M_r) ndarray
        ``G_i R G_i^T`` (the noise term of the Joseph form, eq. (20)).
    """
    R = model.R_r
    d = np.repeat(S, model.C_r.shape[1], axis=-1).astype(float)  # (batch, N, N p_r)
    HS = H @ Sig  # (batch, N, N p_r, M_r)
    S_tilde = (d[..., :, None] * d[..., None, :]) * (HS @ H.T + R) + np.eye(H.shape[0]) * (1.0 - d[..., None])
    G = np.swapaxes(np.linalg.solve(S_tilde, d[..., :, None] * HS), -1, -2) * d[..., None, :]
    return G, G @ H, G @ R @ np.swapaxes(G, -1, -2)


def apply_output_gain(model: TeamFilterModel, H: np.ndarray, X_pred: np.ndarray, Z: np.ndarray,
                      G: np.ndarray) -> np.ndarray:
    """``X̂_i = X̂_i^- + G_i (z_i - H X̂_i^-)`` (eq. (18)) with the reduced gain on the Kronecker axes."""
    N, k, Mr = model.n_agents, model.kron, model.M_r
    runs = X_pred.shape[0]
    X = X_pred.reshape(runs, N, Mr, k)
    innov = Z.reshape(runs, N, H.shape[0], k) - H @ X
    return (X + G @ innov).reshape(X_pred.shape)


def check_covariances(P: ArrayLike, name: str, shape: tuple, definite: bool = False, kron: int = 1) -> np.ndarray:
    """A stack of covariances of the given shape (None: any batch size >= 1), symmetric PSD (or PD), checked in full.

    The error says what to do for the two common slips: a missing batch axis, and a full covariance
    where the model works on the reduced one (``kron > 1``).
    """
    P = _float_array(P, name)
    if P.ndim != len(shape) or any(w is not None and g != w for g, w in zip(P.shape, shape)) or P.shape[0] == 0:
        want = tuple("batch" if w is None else w for w in shape)
        hint = ""
        if P.ndim == len(shape) - 1 and P.shape == tuple(shape[1:]):
            hint = f"; add the leading batch axis ({name}[None]) for one run"
        elif kron > 1 and P.ndim >= 2 and P.shape[-1] == kron * shape[-1]:
            hint = (f"; this model works on the reduced covariance (its Kronecker factor is {kron}): "
                    f"pass mascore.team_model.reduce_covariance({name}, {kron})")
        raise ValueError(f"Incompatible dimensions of {name}; expected {want} but found {P.shape}".replace("'", "")
                         + hint)
    return check_covariance(P, name, definite=definite)


def check_runs(X: np.ndarray, Y: np.ndarray, xname: str, yname: str) -> None:
    if X.shape[0] != Y.shape[0]:
        raise ValueError(f"{yname} has {Y.shape[0]} runs but {xname} has {X.shape[0]}")


def check_batch(L: np.ndarray, Sig: np.ndarray, lname: str, sname: str, X: np.ndarray | None = None) -> None:
    """A batch of topologies must match the covariance batch and the runs (or be a single topology)."""
    if L.ndim == 3 and L.shape[0] not in (1, Sig.shape[0]):
        raise ValueError(
            f"{lname} has {L.shape[0]} topologies but {sname} has batch {Sig.shape[0]}: one covariance per "
            "topology (or a single topology for all)"
        )
    if X is not None and L.ndim == 3 and L.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"{lname} has {L.shape[0]} topologies but there are {X.shape[0]} runs")
    if X is not None and Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"{sname} has batch {Sig.shape[0]} but there are {X.shape[0]} runs")


def check_team_laplacian(L: ArrayLike, N: int, name: str = "laplacian", any_batch: bool = False,
                     undirected: bool = False) -> np.ndarray:
    """One Laplacian ``(N, N)`` or a batch ``(batch, N, N)`` (``(..., N, N)`` with `any_batch`): finite, rows
    summing to zero, off-diagonal entries <= 0.

    Directed graphs are allowed unless `undirected` (the team filter: Song et al. assume a common sensing
    range, hence an undirected graph). An adjacency matrix passed by mistake is named as such.
    """
    L = _float_array(L, name)
    if (L.ndim < 2 or (L.ndim > 3 and not any_batch) or L.shape[-2:] != (N, N) or L.size == 0):
        want = f"(..., {N}, {N})" if any_batch else f"({N}, {N}) or (batch, {N}, {N})"
        raise ValueError(f"Incompatible dimensions of {name}; expected {want} but found {L.shape}")
    _finite(L, name)
    tol = 1e-8 * max(1.0, float(np.abs(L).max()))
    off = L.copy()
    off[..., np.arange(N), np.arange(N)] = 0.0
    if off.max() > tol or np.abs(L.sum(axis=-1)).max() > tol:
        if np.all(L >= 0) and np.all(L[..., np.arange(N), np.arange(N)] == 0):
            raise ValueError(f"{name} looks like an adjacency matrix; pass mascore.graphs.laplacian(A) instead")
        raise ValueError(
            f"{name} must be a graph Laplacian: rows summing to zero and off-diagonal entries <= 0 "
            "(pass mascore.graphs.laplacian(A))"
        )
    if undirected and np.abs(L - np.swapaxes(L, -1, -2)).max() > tol:
        raise ValueError(undirected_message(name, "a directed Laplacian"))
    return L


def undirected_message(name: str, got: str) -> str:
    """Why Song et al.'s team filter refuses a directed graph, and what to do (for `name`, which is `got`)."""
    return (f"{name} must be symmetric (an undirected graph): Song et al.'s team filter assumes that every agent "
            f"senses the agents that sense it (a common sensing range, Sec. II); got {got} (symmetrize the "
            f"adjacency, e.g. A + A.T > 0)")


def check_mask(mask: ArrayLike, N: int) -> np.ndarray:
    S = check_mask_values(mask, "mask")
    if S.shape[-2:] != (N, N) or S.ndim not in (2, 3):
        raise ValueError(
            f"Incompatible dimensions of mask; expected ({N}, {N}) or (batch, {N}, {N}) but found {S.shape}"
        )
    if not np.all(S[..., np.arange(N), np.arange(N)]):
        raise ValueError("mask must include every agent itself (closed neighbourhoods); use sensing_mask(A)")
    return S if S.ndim == 3 else S[None]


def control_inputs(Y: np.ndarray, L: np.ndarray, K: np.ndarray) -> np.ndarray:
    """``u_i = -K sum_j L_ij Y[i, j]``: views ``(..., N, N, m)``, Laplacian ``(..., N, N)``, gain ``(p, m)``.

    Returns the inputs ``(..., N, p)`` (:func:`mascore.rendezvous.consensus_control`, which checks its arguments).
    """
    return -np.einsum("...ij,...ijm->...im", L, Y) @ K.T


def mask_vec(model: TeamFilterModel, S: np.ndarray) -> np.ndarray:
    """(batch, N, N) mask -> (batch, N, M_r) 0/1 vectors ``diag(D_i)`` in reduced coordinates."""
    return np.repeat(S, model.m_r, axis=-1).astype(float)


def joseph(Sig: np.ndarray, KH: np.ndarray, R: np.ndarray) -> np.ndarray:
    Psi = np.eye(Sig.shape[-1]) - KH
    KHt = np.swapaxes(KH, -1, -2)
    return symmetric_part(Psi @ Sig @ np.swapaxes(Psi, -1, -2) + KH @ R @ KHt)


def apply_gain(model: TeamFilterModel, X_pred: np.ndarray, Z: np.ndarray, KH: np.ndarray) -> np.ndarray:
    """``X̂_i = X̂_i^- + G_i H_i (Z_i - X̂_i^-)`` with the reduced gain on the Kronecker axes."""
    N, k, Mr = model.n_agents, model.kron, model.M_r
    innov = (Z - X_pred).reshape(X_pred.shape[0], N, Mr, k)
    return X_pred + (KH @ innov).reshape(X_pred.shape)


def F1_means(model: TeamFilterModel, X: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``F_1 X̂_i`` for every run and agent: ``A x̂_{i,j} - BK sum_l L_jl x̂_{i,l}`` (eq. (14))."""
    N, m = model.n_agents, model.m
    Lx = L[:, None] if L.ndim == 3 else L  # (batch,1,N,N) or (N,N)
    LX = Lx @ X.reshape(X.shape[0], N, N, m) if L.ndim == 2 else np.matmul(Lx, X)
    return X @ model.A.T - LX @ model.BK.T


def F1_rows(model: TeamFilterModel, T: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Apply ``F_1`` (reduced) to tensors ``T[..., j, a, c]`` along (j, a).

    ``(F_1 T)[j] = A T[j] - BK sum_l L_jl T[l]``; `L` broadcasts as ``(..., N, N)``.
    """
    shp = T.shape
    N, mr, C = shp[-3:]
    LT = (L @ T.reshape(*shp[:-3], N, mr * C)).reshape(*np.broadcast_shapes(L.shape[:-2], shp[:-3]), N, mr, C)
    return model.A_r @ T - model.BK_r @ LT


def diagonal_blocks(model: TeamFilterModel, Sig: np.ndarray) -> np.ndarray:
    """Diagonal blocks of reduced augmented covariances ``(batch, N M_r, N M_r)`` -> ``(batch, N, M_r, M_r)``."""
    N, Mr = model.n_agents, model.M_r
    blocks = Sig.reshape(Sig.shape[0], N, Mr, N, Mr)
    return np.moveaxis(blocks[:, np.arange(N), :, np.arange(N), :], 0, 1)


#: Augmented covariances up to this size (N M_r) are propagated with dense products, larger ones one row
#: block at a time with the sparse F_1, F_2 (the crossover on one core is near N M_r = 256-512).
DENSE_MAX = 384


def phi_blocks(model: TeamFilterModel, L: np.ndarray, rows: bool) -> tuple:
    """What the estimation-based prediction needs of one topology ``L`` ``(N, N)``.

    ``Φ = I_N ⊗ F_1 + 1_N ⊗ F_2`` with ``F_1 = I ⊗ A - L ⊗ BK`` and ``(F_2 e)[j] = BK sum_l L_jl e[j, l]``:
    a row of either block has about ``m_r (1 + nnz(L_j))`` non-zeros instead of ``M_r``.

    Returns ``(Φ,)`` dense for a small team; for the row-block path ``(F1aug, F_1, F_1^T, F_2, K2t)``:
    ``F1aug = [F_1, I]`` sparse ``(M_r, 2 M_r)`` with the identity entry first in every row, dense
    ``F_1`` and ``F_1^T``, sparse ``F_2`` ``(M_r, N M_r)`` and ``K2t[j] = (L_j ⊗ BK)^T`` ``(N, M_r, m_r)``
    (column block ``j`` of ``X F_2^T`` is ``X[:, j] @ K2t[j]`` for ``X`` of shape ``(M_r, N M_r)``).
    """
    from scipy import sparse

    N, mr, Mr = model.n_agents, model.m_r, model.M_r
    F1 = sparse.csr_array(sparse.kron(sparse.identity(N), model.A_r) - sparse.kron(sparse.csr_array(L), model.BK_r))
    j, l = np.nonzero(L)
    a, b = np.nonzero(np.ones((mr, mr)))
    rws = (j[:, None] * mr + a[None, :]).ravel()
    cols = (j[:, None] * Mr + l[:, None] * mr + b[None, :]).ravel()
    vals = (L[j, l][:, None] * model.BK_r[a, b][None, :]).ravel()
    F2 = sparse.csr_array((vals, (rws, cols)), shape=(Mr, N * Mr))
    if not rows:
        return (np.kron(np.eye(N), F1.toarray()) + np.kron(np.ones((N, 1)), F2.toarray()),)
    counts = np.diff(F1.indptr)
    indptr = np.concatenate([[0], np.cumsum(counts + 1)]).astype(F1.indptr.dtype)
    first = indptr[:-1]
    rest = np.ones(indptr[-1], dtype=bool)
    rest[first] = False
    indices = np.empty(indptr[-1], dtype=F1.indices.dtype)
    data = np.empty(indptr[-1])
    indices[first], data[first] = Mr + np.arange(Mr), 1.0
    indices[rest], data[rest] = F1.indices, F1.data
    F1aug = sparse.csr_array((data, indices, indptr), shape=(Mr, 2 * Mr))
    F1d = F1.toarray()
    K2 = (L[:, None, :, None] * model.BK_r[None, :, None, :]).reshape(N, mr, Mr)
    K2t = np.ascontiguousarray(np.swapaxes(K2, -1, -2))
    return F1aug, F1d, F1d.T, F2, K2t


def gemm_acc(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> None:
    """``C += A @ B`` in place for C-contiguous `C` (BLAS ``dgemm`` with ``beta = 1`` on the transposes)."""
    from scipy.linalg.blas import dgemm

    Ct = C.T  # Fortran-contiguous: Ct += B^T A^T
    r = dgemm(1.0, B.T, A.T, 1.0, Ct, overwrite_c=1)
    if r.ctypes.data != Ct.ctypes.data:  # pragma: no cover - dgemm had to copy
        Ct[...] = r


def reduced_nees(e, P, kron):
    """:func:`~mascore.team_observability.lyapunov_v` without checks."""
    Mr = P.shape[-1]
    E = e.reshape(*e.shape[:-1], Mr, kron)
    sol = np.linalg.solve(P, E)
    return np.einsum("...ik,...ik->...", E, sol)


# ---------------------------------------------------------------- the steps of TeamFilter (its arrays, in place)


def mb_noise(model: TeamFilterModel, Lb: np.ndarray) -> np.ndarray:
    """The process term of eq. (15), ``(I ⊗ BK) E[nu_bar nu_bar^T] (I ⊗ BK)^T + Q``: ``(batch, M_r, M_r)``.

    Block diagonal; it depends on the topology `Lb` ``(batch, N, N)`` and the noise only.
    """
    N, mr, Mr = model.n_agents, model.m_r, model.M_r
    Rr = model.R_r.reshape(N, mr, N, mr)
    # cov of (L_j ⊗ I) nu_j: sum_{l,l'} L_jl L_jl' R[l, l']
    Cj = np.einsum("bjl,bjk,lakc->bjac", Lb, Lb, Rr)  # (batch, N, mr, mr)
    noise = model.BK_r @ Cj @ model.BK_r.T + model.Q_r  # (batch, N, mr, mr)
    blk = np.zeros((Lb.shape[0], N, mr, N, mr))
    blk[:, np.arange(N), :, np.arange(N), :] = np.moveaxis(noise, 1, 0)
    return blk.reshape(Lb.shape[0], Mr, Mr)


def eb_predict_rows(model: TeamFilterModel, Qt: np.ndarray, Sb: np.ndarray, blk: tuple,
                    buffer: Callable[[int, int], np.ndarray]) -> None:
    """``Σ^- = Φ Σ Φ^T + (1 1^T) ⊗ 𝒬`` of one topology, in place in `Sb` ``(C, C)``, by row blocks.

    With ``G_i = Σ[i] F_2^T = (F_2 Σ[:, i])^T`` (``F_2 Σ`` computed once with the sparse ``F_2``)
    and ``H = F_2 Σ F_2^T``, tile ``(i, i')`` is ``(F_1 Σ_ii' + (F_2 Σ)_i') F_1^T + F_1 G_i + H + 𝒬``.
    Σ^- is symmetric, so only the tiles ``i' >= i`` of row block ``i`` are computed (two products
    with ``F_1``) and written transposed into column block ``i``. Row block ``i`` reads only the
    tiles ``i' >= i`` of Σ, which no earlier row block wrote: the recursion runs in place.

    `Qt` is ``𝒬 = I_N ⊗ Q_r`` ``(M_r, M_r)``, `blk` the topology's :func:`phi_blocks` (row-block
    path), ``buffer(slot, size)`` a flat work array of `size` floats owned by the caller.
    """
    N, Mr = model.n_agents, model.M_r
    C = N * Mr
    F1aug, F1, F1t, F2s, K2t = blk
    work = buffer(0, 3 * Mr * C + N * Mr * Mr)
    XP, Q = work[:2 * Mr * C], work[2 * Mr * C:3 * Mr * C]
    # F_2 Σ, shared by every row block: (Φ Σ)[i] = F_1 Σ[i] + F_2 Σ
    F2S = F2s @ Sb
    F2S3 = F2S.reshape(Mr, N, Mr)
    # H = F_2 Σ F_2^T: column (j, α) sums BK[α, β] L_jl (F_2 Σ)[:, (j, l, β)]
    H = np.swapaxes(np.matmul(np.swapaxes(F2S3, 0, 1), K2t), 0, 1).reshape(Mr, Mr)
    # the part of tile (i, i') shared by the whole row block: F_1 G_i + H + 𝒬, G_i = (F_2 Σ)[:, i]^T
    shared = np.matmul(F1, F2S3.transpose(1, 2, 0), out=work[3 * Mr * C:].reshape(N, Mr, Mr))
    shared += H + Qt
    o4 = Sb.reshape(N, Mr, N, Mr)
    for i in range(N):
        n, c0 = N - i, i * Mr
        XPi = XP[:2 * Mr * n * Mr].reshape(2 * Mr, n * Mr)
        np.copyto(XPi[:Mr], Sb[c0:c0 + Mr, c0:])  # Σ_ii', i' >= i (read before anything is written there)
        np.copyto(XPi[Mr:], F2S[:, c0:])
        # (Φ Σ)_ii' = (F_2 Σ)_i' + F_1 Σ_ii' (eq. (34); eq. (32) for i' = i): [F_1, I] has its identity
        # entry first in every row, so the sparse product adds F_1's terms to (F_2 Σ)_i' in order
        Pi = F1aug @ XPi
        Qi = Q[:Mr * n * Mr].reshape(Mr * n, Mr)
        Q3 = Qi.reshape(Mr, n, Mr)
        np.copyto(Q3, shared[i][:, None, :])
        # tile (i, i') = (Φ Σ)_ii' F_1^T + shared (BLAS adds the product to the preset)
        gemm_acc(Pi.reshape(Mr * n, Mr), F1t, Qi)
        np.copyto(o4[i, :, i:, :], Q3)
        if n > 1:  # tile (i', i) = tile (i, i')^T
            np.copyto(o4[i + 1:, :, i, :], Q3[:, 1:, :].transpose(1, 2, 0))


def eb_update_rows(Sb: np.ndarray, idx: np.ndarray, W: np.ndarray, Wt: np.ndarray, Rq: np.ndarray,
                   H_sel: np.ndarray | None, buffer: Callable[[int, int], np.ndarray]) -> None:
    """``Ψ Σ^- Ψ^T + blockdiag(G_i H_i R H_i^T G_i^T)`` of one covariance, in place in `Sb`.

    Full states: ``H_i`` selects the entries `idx` of agent i's block. Partial sensing:
    `H_sel` ``(N, q, M_r)`` holds the rows of ``H`` that agent i senses (padding rows meet
    zero columns of `W`), and the "observed rows" ``H_i Σ^-`` replace the selected rows of Σ^-.
    ``buffer(slot, size)``: a flat work array of `size` floats owned by the caller.
    """
    N, Mr, q = W.shape
    C, Nq = N * Mr, N * q
    work = buffer(2, 2 * Nq * C + Nq * Nq + 4 * N * Mr * q + Mr * C)
    if H_sel is None:
        cidx = (np.arange(N)[:, None] * Mr + idx).ravel()  # observed rows/columns (i, idx_i) of Σ^-
        R = np.take(Sb, cidx, axis=0, out=work[:Nq * C].reshape(Nq, C), mode="clip")  # observed rows (N q, C)
        Rc = np.take(R, cidx, axis=1, out=work[Nq * C:Nq * C + Nq * Nq].reshape(Nq, Nq), mode="clip")
    else:  # H_i Σ^-: row block i of Σ^- seen through agent i's sensed outputs, and (H_i Σ^- H_i'^T)
        R = np.matmul(H_sel, Sb.reshape(N, Mr, C), out=work[:Nq * C].reshape(N, q, C)).reshape(Nq, C)
        Rc3 = np.matmul(R.reshape(Nq, N, Mr).transpose(1, 0, 2), np.swapaxes(H_sel, -1, -2))  # (N, Nq, q)
        Rc = work[Nq * C:Nq * C + Nq * Nq].reshape(Nq, Nq)
        Rc.reshape(Nq, N, q)[...] = Rc3.transpose(1, 0, 2)
    # V_i[:, i'] = Σ[idx_i, i'] - Σ[idx_i, idx_i'] W_i'^T: the rows of (I - G_i H_i) Σ^- that meet W_i'
    Vt = np.matmul(Rc.reshape(Nq, N, q).transpose(1, 0, 2), Wt,
                   out=work[Nq * C + Nq * Nq:2 * Nq * C + Nq * Nq].reshape(N, Nq, Mr))
    np.subtract(R.reshape(Nq, N, Mr).transpose(1, 0, 2), Vt, out=Vt)  # Vt[i', (i, k)] = V_i[k, i']
    # tile (i, i') = Σ_ii' - [W_i, Σ[i, idx_i']] [V_ii'; W_i'^T]: one batched product over i' per row block,
    # with Σ[i, idx_i'] = Σ[idx_i', i]^T (Σ^- is symmetric) taken from the observed rows
    rest = work[2 * Nq * C + Nq * Nq:]
    Ab = rest[:N * Mr * 2 * q].reshape(N, Mr, 2 * q)
    Bb = rest[N * Mr * 2 * q:4 * N * Mr * q].reshape(N, 2 * q, Mr)
    O = rest[4 * N * Mr * q:].reshape(Mr, C)
    O3 = O.reshape(Mr, N, Mr).transpose(1, 0, 2)
    Bb[:, q:, :] = Wt
    R3 = R.reshape(N, q, C)
    for i in range(N):
        rows = slice(i * Mr, (i + 1) * Mr)
        Ab[:, :, :q] = W[i]
        Ab[:, :, q:] = R3[:, :, rows].transpose(0, 2, 1)
        Bb[:, :q, :] = Vt[:, i * q:(i + 1) * q]
        np.matmul(Ab, Bb, out=O3)
        Si = Sb[rows]  # row block i of Σ^-: read here only, so it is overwritten with its update
        np.subtract(Si, O, out=Si)
        Si[:, rows] += W[i] @ Rq[i] @ Wt[i]  # eq. (33): + δ_ij G_i H_i R H_i^T G_i^T


def block_sandwich(Sig: np.ndarray, KH: np.ndarray, added: np.ndarray) -> np.ndarray:
    """``Ψ Σ^- Ψ^T + blockdiag(added_i)`` with ``Ψ = blockdiag(I - KH_i)``, by dense products (a small team).

    `Sig` ``(batch, C, C)`` with ``C = N M_r``, `KH` and `added` ``(batch, N, M_r, M_r)``; returns ``(batch, C, C)``.
    """
    nb, C = Sig.shape[0], Sig.shape[-1]
    N, Mr = KH.shape[-3], KH.shape[-1]
    Psi = np.eye(Mr) - KH  # (batch, N, Mr, Mr)
    T = Psi @ Sig.reshape(nb, N, Mr, C)  # rows
    T = np.swapaxes(T.reshape(nb, C, C), -1, -2)
    T = (Psi @ T.reshape(nb, N, Mr, C)).reshape(nb, N, Mr, N, Mr)  # columns (by symmetry of Σ^-)
    T[:, np.arange(N), :, np.arange(N), :] += np.moveaxis(added, 1, 0)
    return T.reshape(nb, C, C)
