"""The kernels of :class:`mascore.distributed_ekf.FlockingEKF`: its update and prediction on chunks of filters.

Plain functions on arrays the filter has checked and owns (no checks here): the update of eqs. (16)-(20)
by the Cholesky factor of the innovation covariance (:func:`update_rows`), the prediction of eqs. (38)-(40)
through the rank of ``F - I kron A`` (:func:`predict_half`), and the tiled BLAS products, blocked
transposes and work arrays (:class:`Scratch`) they run on. Every BLAS or LAPACK call is cut to a size
that OpenBLAS runs on the calling thread (:data:`TILE_MACS`, :data:`LAPACK_ORDER`): the step gives
the same bytes whatever the BLAS's number of threads. Matrix-vector products stay with numpy's own loops
(``einsum``): OpenBLAS threads a ``gemv`` from ``2304 x 4`` multiply-adds on.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg.blas import dgemm
from scipy.linalg.lapack import dpotrf, dtrtri

from . import _flocking_core as flocking_core

__all__ = ["CHUNK_BYTES", "GRAM_BATCH_ORDER", "LAPACK_ORDER", "TILE_K", "TILE_MACS", "TILE_ROWS", "Scratch",
           "add_noise", "block_diagonal", "cholesky_inverse", "chunks", "column_blocks", "column_tiles", "pair_view",
           "predict_half", "strip", "subtract_gram", "symmetrize_sum", "tiled_matmul", "transpose_into", "update_rows"]


#: Bytes of covariance handled per chunk of filters: each chunk runs its update and prediction while its
#: covariances are in cache (a few MB of L2/L3), instead of sweeping memory once per elementary operation.
#: 2 MB (4 filters at N = 64): half the numpy calls per step of 1 MB chunks, the chunk's work arrays still in L3.
CHUNK_BYTES = 1 << 21


def chunks(K, M):
    c = max(1, CHUNK_BYTES // (8 * M * M))
    return [slice(s, min(s + c, K)) for s in range(0, K, c)]


#: Multiply-adds per BLAS call in the step's kernels. OpenBLAS (the BLAS of numpy's and scipy's wheels) runs a
#: matrix product of at most 65536 x 4 (its GEMM_MULTITHREAD_THRESHOLD) multiply-adds on the calling thread: the
#: per-filter products are cut into tiles of this size, so that the step never wakes a BLAS thread pool and runs
#: the same code, with the same results, whatever the BLAS's number of threads. (Large single products do gain
#: from threads; thousands of small ones synchronise the pool at every call, and numpy and scipy each bring
#: their own pool, whose spinning threads then take the cores from each other.)
TILE_MACS = 1 << 18
#: Longest inner dimension of a tile (longer ones are summed over pieces): short tiles with a long inner
#: dimension run well below the BLAS's rate, as each call packs its operands anew.
TILE_K = 128
#: Rows of a tile (its columns: as many as :data:`TILE_MACS` allows).
TILE_ROWS = 64
#: Largest state size ``M`` whose rank-q downdates ``Sigma - V^T V`` are one batched product per chunk (the
#: chunk's ``V^T V``, then two passes over its covariances); above it, per filter in place (:func:`subtract_gram`),
#: where a pass over the chunk costs more than the per-filter calls. Same bytes either way (``scale`` is 1 or 1/2).
GRAM_BATCH_ORDER = 64
#: Largest factor handed to LAPACK in one call (OpenBLAS's Cholesky and triangular inverse run on one thread up
#: to this order); larger innovation covariances are factored by blocks (:func:`cholesky_inverse`).
LAPACK_ORDER = 64


def tiled_matmul(A, B, out, acc, symmetric=False):
    """``out = A @ B`` for stacks ``(c, m, k) @ (c, k, n)``, as BLAS products of at most :data:`TILE_MACS`.

    `acc` is a flat work array of at least ``c m n`` doubles (used when ``k > TILE_K``, ``2 TILE_K`` with
    `symmetric`: the pieces of the inner dimension are summed). The tiles of one row block are one batched
    ``np.matmul`` over strided views.
    With `symmetric` (``m = n`` and ``A @ B`` symmetric, such as ``Y G^T`` with ``Y = G Sigma``), only the tiles
    that reach the diagonal or lie above it are computed, in row blocks of ``TILE_ROWS / 2`` rows, and the blocks
    left of them are the transposes of blocks above (5/8 of the multiply-adds for ``m = 128``, fewer for larger
    ``m``).
    """
    c, m, k = A.shape
    n = B.shape[-1]
    # symmetric: half-height row blocks and twice the inner depth (the same multiply-adds per tile): more of the
    # triangle is skipped (5/8 of the products at m = 128 instead of 3/4) and no partial sums for k <= 2 TILE_K
    kb = min(k, 2 * TILE_K if symmetric else TILE_K)
    r = min(m, TILE_ROWS // 2 if symmetric else TILE_ROWS)
    b = max(1, min(n, TILE_MACS // (r * kb)))
    acc = acc[: c * m * n].reshape(c, m, n)
    for i0 in range(0, m, r):
        j0 = (i0 // b) * b if symmetric else 0  # first column computed in this row block
        nb = (n - j0) // b
        for k0 in range(0, k, kb):
            k1 = min(k, k0 + kb)
            Di = (out if k0 == 0 else acc)[:, i0:i0 + r, j0:]
            Ai, Bk = A[:, i0:i0 + r, k0:k1], B[:, k0:k1, j0:]
            np.matmul(Ai[:, None], column_tiles(Bk, nb, b), out=column_tiles(Di, nb, b))
            if n - j0 > nb * b:
                np.matmul(Ai, Bk[:, :, nb * b:], out=Di[:, :, nb * b:])
            if k0:
                out[:, i0:i0 + r, j0:] += Di
        if symmetric and j0:
            np.copyto(out[:, i0:i0 + r, :j0], np.swapaxes(out[:, :j0, i0:i0 + r], -1, -2))
    return out


def column_tiles(A, nb, b):
    """The first ``nb b`` columns of a stack ``A (c, k, n)`` as ``nb`` tiles of ``b`` columns, ``(c, nb, k, b)``.

    A view (splitting the column axis never copies), cheaper to build than ``as_strided``.
    """
    c, k, _ = A.shape
    return A[:, :, : nb * b].reshape(c, k, nb, b).swapaxes(1, 2)


def cholesky_inverse(S):
    """``L^{-1}`` for ``S = L L^T`` (``(q, q)`` symmetric positive definite), lower triangular, zero above.

    Up to order :data:`LAPACK_ORDER` by LAPACK (``potrf``, ``trtri``); above, by 2 x 2 blocks:
    ``L11 = chol(S11)``, ``L21 = S21 L11^{-T}``, ``L22 = chol(S22 - L21 L21^T)`` and
    ``(L^{-1})_21 = -L22^{-1} L21 L11^{-1}``, every product a tiled one (:func:`tiled_matmul`).

    Raises
    ------
    numpy.linalg.LinAlgError
        If `S` is not positive definite.
    """
    q = S.shape[0]
    if q <= LAPACK_ORDER:
        L, info = dpotrf(S, lower=1, clean=1)  # S symmetric: its C order is its F order
        if info == 0:
            Li, info = dtrtri(L, lower=1)
        if info != 0:
            raise np.linalg.LinAlgError("innovation covariance is not positive definite")
        return Li  # zero above the diagonal: potrf's clean=1 zeroed it and trtri (lower) leaves it
    h = q // 2
    acc = np.empty(q * q)
    Li = np.zeros((q, q))
    Li[:h, :h] = A = cholesky_inverse(S[:h, :h])
    L21 = tiled_matmul(S[None, h:, :h], A.T[None], np.empty((1, q - h, h)), acc)[0]  # S21 L11^{-T}
    S22 = S[h:, h:] - tiled_matmul(L21[None], L21.T[None], np.empty((1, q - h, q - h)), acc)[0]
    Li[h:, h:] = D = cholesky_inverse(S22)
    T = tiled_matmul(L21[None], A[None], np.empty((1, q - h, h)), acc)  # L21 L11^{-1}
    Li[h:, :h] = -tiled_matmul(D[None], T, np.empty((1, q - h, h)), acc)[0]
    return Li


def subtract_gram(P, V, scale):
    """``P <- scale (P - V^T V)`` in place for a C-contiguous ``(M, M)`` `P` and a ``(q, M)`` `V`.

    By strips of rows of ``P`` (each one in-place BLAS call on the strip's transpose, Fortran order in the same
    memory), every call at most :data:`TILE_MACS` multiply-adds: no ``M x M`` temporary and no extra pass.
    """
    q, M = V.shape
    rows = max(1, TILE_MACS // (M * q))
    Vt = V.T
    for i0 in range(0, M, rows):
        strip = P[i0:i0 + rows].T  # (M, r), Fortran order
        out = dgemm(-scale, Vt, V[:, i0:i0 + rows], beta=scale, c=strip, overwrite_c=1)
        if out is not strip:  # pragma: no cover  (BLAS worked on a copy)
            strip[...] = out


def update_rows(X, P, z, observed, R, scale, work=None):
    """Eqs. (16)-(20) for a chunk of filters, the covariances updated in place.

    `X` ``(c, N, m)``, `P` ``(c, M, M)`` (C-contiguous, overwritten by ``scale * Sigma_post``),
    `z` ``(c, N, m)``, `observed` ``(c, N)`` bool. The observed rows ``H Sigma`` and the innovation
    covariances ``S = H (Sigma + R) H^T`` of the chunk are gathered at once (index lists padded to a common
    length ``q``); per filter, with its own ``q_i`` entries, ``L^{-1}`` of ``S = L L^T``
    (:func:`cholesky_inverse`); then for the chunk at once ``V = L^{-1} H Sigma`` (zero in the padding) and
    ``V^T V`` subtracted: per filter in place (:func:`subtract_gram`), or for ``M <= GRAM_BATCH_ORDER`` as one
    tiled product for the chunk: ``O(q_i^3 + q_i^2 M + q_i M^2)`` flops, every BLAS call a tile run on the
    calling thread.
    Returns the updated states ``(c, N, m)``.
    """
    c, N, m = X.shape
    M = N * m
    x = X.reshape(c, M)
    counts = observed.sum(axis=-1)
    qa = int(counts.max()) if c else 0
    if qa == 0:  # nothing observed in this chunk
        if scale != 1.0:
            P *= scale
        return X + 0.0
    agents = np.argsort(~observed, axis=-1, kind="stable")[:, :qa]  # observed agents first, in order
    idx = (agents[..., None] * m + np.arange(m)).reshape(c, qa * m)  # (c, q) observed state indices (padded)
    gather = ((np.arange(c) * M)[:, None] + idx).reshape(-1)
    if work is None:
        work = Scratch(c, N, m)
    Ct = work.rows[: gather.size * M].reshape(gather.size, M)
    # mode="clip": the indices are in range, and numpy buffers `out` in the default mode ("raise"), a second copy
    Ct = np.take(P.reshape(c * M, M), gather, axis=0, out=Ct, mode="clip").reshape(c, qa * m, M)  # H Sigma
    q_max = qa * m
    # the (c, q, q) gathers run in the chunk's work arrays: fresh arrays of that size (2 MB at N = 8, 256 filters)
    # cost a page fault per 4 kB on every call. Each is dead before its array's own use below: the flat indices
    # (in V, as integers) before V, S (in T) after the Cholesky factors, H R H^T (in acc) before any product.
    nq = c * q_max * q_max
    ij = work.V.view(np.intp)[:nq].reshape(c, q_max, q_max)
    rows = (np.arange(c) * (q_max * M))[:, None, None] + (np.arange(q_max) * M)[None, :, None]
    np.add(rows, idx[:, None, :], out=ij)  # flat indices of H Sigma H^T in Ct
    S = np.take(Ct, ij, out=work.T.reshape(-1)[:nq].reshape(c, q_max, q_max), mode="clip")  # H Sigma H^T
    np.multiply(idx[:, :, None], M, out=ij)
    ij += idx[:, None, :]  # flat (row, column) indices of the observed block in R
    S += np.take(R, ij, out=work.acc[:nq].reshape(c, q_max, q_max), mode="clip")  # eq. (17): + H R H^T
    flat = (np.arange(c) * M)[:, None] + idx
    nu = np.take(z, flat) - np.take(x, flat)  # H (z - X), eq. (16)
    q = counts * m
    Li = np.zeros((c, q_max, q_max))  # L^{-1} of each filter, zero in the padding
    for k in range(c):
        if q[k]:
            Li[k, : q[k], : q[k]] = cholesky_inverse(S[k, : q[k], : q[k]])
    V = tiled_matmul(Li, Ct, work.V[: c * q_max * M].reshape(c, q_max, M), work.acc)  # L^{-1} H Sigma
    a = np.einsum("kij,kj->ki", Li, nu)  # L^{-1} nu
    if M <= GRAM_BATCH_ORDER:  # eq. (20) for many small filters: V^T V of the chunk at once (V zero in the padding)
        P -= tiled_matmul(np.swapaxes(V, -1, -2), V, work.T[:c], work.acc)
        if scale != 1.0:
            P *= scale
    else:
        for k in range(c):  # eq. (20): Sigma - V^T V (times scale), in place
            if q[k]:
                subtract_gram(P[k], V[k, : q[k]], scale)
            elif scale != 1.0:
                P[k] *= scale
    x_post = x + np.einsum("kqm,kq->km", V, a)  # eq. (18): X + Sigma H^T S^{-1} nu = X + V^T L^{-1} nu
    return x_post.reshape(c, N, m)


def column_blocks(A, N, n):
    """Views of the position and velocity columns of ``A (..., N*2n)`` (agent-major), each ``(..., N[, n])``.

    For ``n = 2`` the pairs of columns are viewed as complex numbers, so that an operation on a block runs one
    strided loop over the agents instead of one loop of length 2 per agent.
    """
    if n == 2:
        Ac = A.view(np.complex128).reshape(*A.shape[:-1], N, 2)
        return Ac[..., 0], Ac[..., 1]
    A5 = A.reshape(*A.shape[:-1], N, 2, n)
    return A5[..., 0, :], A5[..., 1, :]


def pair_view(A, N, n):
    """``A (..., N*n)`` as ``(..., N)`` complex pairs (``n = 2``) or ``(..., N, n)`` reals."""
    if n == 2:
        return A.view(np.complex128)
    return A.reshape(*A.shape[:-1], N, n)


def strip(M):
    """Rows per strip of a blocked transpose: a strip of ``M``-long rows spans a few pages (TLB friendly)."""
    return max(8, min(64, 8192 // M))


def transpose_into(A, T):
    """``T = A^T`` for stacks of square matrices, in row strips."""
    M = A.shape[-1]
    b = strip(M)
    for s in range(0, M, b):
        np.copyto(T[:, :, s:s + b], np.swapaxes(A[:, s:s + b, :], -1, -2))


def symmetrize_sum(A, T):
    """``A <- A + A^T`` in place (exactly symmetric), through the work array `T` of `A`'s shape."""
    transpose_into(A, T)
    A += T


class Scratch:
    """Work arrays of one chunk of filters, owned by one :class:`FlockingEKF` and kept between its calls.

    Fresh large temporaries are expensive: the allocator returns freed memory to the system and the next
    first touch page-faults, so the kernels write into these instead. :func:`update_rows` also runs its
    ``(c, q, q)`` gathers in `V`, `T` and `acc` before their main use.
    """

    def __init__(self, c, N, m):
        n, M = m // 2, N * m
        self.key = (c, N, m)
        self.G = np.empty((c, N, n, N, m))
        self.Y = np.empty((c, N * n, M))
        self.Z = np.empty((c, N * n, N * n))
        self.T = np.empty((c, M, M))
        self.half = np.empty(c * M * M // 2)
        self.rows = np.empty(c * M * M)
        self.V = np.empty(c * M * M)
        self.acc = np.empty(c * M * M)

    def buffer(self, like):
        """A contiguous temporary of the shape and type of `like` (at most half a chunk of covariances)."""
        size = like.size * like.itemsize // 8
        return self.half[:size].view(like.dtype).reshape(like.shape)


def block_diagonal(Q, N, m):
    """The ``(N, m, m)`` diagonal blocks of `Q` if it is block diagonal (e.g. ``I_N kron Q``), else ``None``."""
    Q6 = Q.reshape(N, m, N, m)
    ar = np.arange(N)
    blocks = Q6[ar, :, ar, :].copy()
    off = Q6.copy()
    off[ar, :, ar, :] = 0.0
    return blocks if not np.any(off) else None


def add_noise(S, Q, Qblocks, N, m, scale=1.0):
    """``S += scale Q`` for a chunk ``(c, M, M)``; only the diagonal blocks when `Q` is block diagonal."""
    if Qblocks is None:
        S += Q if scale == 1.0 else scale * Q
    else:
        s0, s1, s2 = S.strides
        blocks = np.lib.stride_tricks.as_strided(S, (S.shape[0], N, m, m), (s0, m * (s1 + s2), s1, s2))
        blocks += Qblocks if scale == 1.0 else scale * Qblocks


def predict_half(X, Ph, model, out, work):
    """Eqs. (38), (40) for a chunk of filters from ``Ph = Sigma / 2`` (overwritten), using the rank of ``F - I kron A``.

    ``F = A' + B' G`` with ``A' = I kron A``, ``B' = I kron B`` (the double integrator) and the control
    Jacobian ``G = dU/dX`` (``nN x 2nN``, from :func:`mascore._flockingflocking_core.control_and_jacobian`, scaled
    by ``dt``). With ``Y = G Sigma`` and ``Z = Y G^T`` (``M^3`` and at most ``M^3 / 2`` flops for ``M = 2nN``:
    ``Z`` is symmetric and only its tiles on and above the diagonal are computed),

        F Sigma F^T = X + X^T,   X = [A' Sigma/2 + B' (Y + Z C^T / 2)] A'^T,   C = A'^{-1} B',

    (``X`` carries half of ``A' Sigma A'^T`` and of ``B' Z B'^T`` and all of ``B' Y A'^T``). Every product by
    ``A'``, ``B'`` or ``C`` is a scaled addition of contiguous rows or of column blocks; the one transpose
    makes the result exactly symmetric (rounding would otherwise accumulate over long runs).

    Returns
    -------
    U : (c, N, n) every agent's control from each filter's estimate
    X_next : (c, N, m)
    out : (c, M, M) the predicted covariances ``F Sigma F^T + Q`` (may be `Ph` itself)
    """
    c, N, m = X.shape
    n, M, nN = m // 2, N * m, N * m // 2
    dt = model.dt
    U, G = flocking_core.control_and_jacobian(X, model.gains, out=work.G[:c], scale=dt)  # eq. (39), and dt dU/dX
    X_next = flocking_core.propagate(X, U, dt)  # eq. (40)
    G = G.reshape(c, nN, M)
    Y = tiled_matmul(G, Ph, work.Y[:c], work.acc)  # dt G Sigma / 2
    Z = tiled_matmul(Y, np.swapaxes(G, -1, -2), work.Z[:c], work.acc, symmetric=True)  # dt^2 G Sigma G^T / 2
    # Y <- Y + dt Z C^T / 2 (positions: -dt^2/2 Z dt / 2, velocities: dt Z dt / 2), with Z = G Sigma G^T
    Yp, Yv = column_blocks(Y, N, n)
    Zc = pair_view(Z, N, n)
    tz = work.buffer(Zc)
    np.multiply(Zc, -0.25 * dt, out=tz)
    Yp += tz
    np.multiply(Zc, 0.5, out=tz)
    Yv += tz
    # rows: W = A' Sigma/2 + B' (2 Y / dt): positions p + dt (v + y), velocities v + 2 y
    P4 = Ph.reshape(c, N, 2, n * M)
    Y3 = Y.reshape(c, N, n * M)
    t = work.buffer(Y3)
    np.add(P4[:, :, 1], Y3, out=t)
    np.add(t, Y3, out=P4[:, :, 1])
    t *= dt
    P4[:, :, 0] += t
    # columns: X = W A'^T (position columns + dt velocity columns)
    Wp, Wv = column_blocks(Ph, N, n)
    tc = work.buffer(Wv)
    np.multiply(Wv, dt, out=tc)
    Wp += tc
    add_noise(Ph, model.Q_team, model.Q_blocks, N, m, 0.5)  # eq. (40): Q / 2 in X, Q in X + X^T
    if out is not Ph and not np.shares_memory(out, Ph):
        np.copyto(out, Ph)
    symmetrize_sum(out, work.T[:c])  # X + X^T = F Sigma F^T + Q, exactly symmetric
    return U, X_next, out
