"""What :mod:`mascore.flocking` and :mod:`mascore.distributed_ekf` share: gains, checks, shared kernels.

Only what has no public twin lives here: :class:`FlockingGains` (exported from
:mod:`mascore.flocking`), the argument checks, the double integrator
(:func:`propagate`), the fused control and Jacobian of the fully-connected law
(:func:`control_and_jacobian`, the EKF's prediction kernel), the divergence test
and the noise factor. The flocking law itself (``phi1``, ``phi2``, the pair term,
the controls, the closed loop and its Jacobian) has one implementation, the public
functions of :mod:`mascore.flocking`, which check their arguments at the boundary
and then run plain code. Checks raise ``ValueError`` or ``TypeError`` naming the
argument.

Layouts: a team state is ``(..., N, 2n)`` with rows ``[p_i; v_i]``; the
control Jacobian of :func:`control_and_jacobian` is ``(..., N, n, N, 2n)``
(agent ``i``, acceleration component ``a``, agent ``j``, state component
``b``), which reshapes without copying to the ``(nN, 2nN)`` matrix
``dU/dX`` of the flattened team state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ._validation import MAX_STEPS, Frozen, check_covariance, check_positive, check_positive_int, float_array
from .exceptions import DivergenceError

__all__ = [
    "DIVERGENCE_LIMIT",
    "MAX_STEPS",
    "DivergenceError",
    "FlockingGains",
    "propagate",
    "control_and_jacobian",
    "float_array",
    "check_team",
    "check_dt",
    "check_range",
    "check_steps",
    "check_gains",
    "check_vectors",
    "check_pair_args",
    "check_weights",
    "check_divergence",
    "check_within_limit",
    "noise_factor",
    "finite_where_input_is",
]

#: A simulated state component (m or m/s) larger than this means the closed loop diverged.
DIVERGENCE_LIMIT = 1e7


@dataclass(frozen=True, eq=False)
class FlockingGains(Frozen):
    """Gains of the augmented Cucker-Smale law, eq. (6).

    Parameters
    ----------
    rho3 : float
        Velocity-consensus gain (1/s), positive.
    rho4 : float
        Distance-keeping gain, positive.
    rho5 : float
        Radial damping gain of ``phi2`` (1/s), positive.
    rho6 : float
        Spring gain of ``phi2`` (1/s^2), positive.
    beta : float
        Communication decay rate of ``phi1``, ``0 <= beta`` (stable for
        ``beta < 1/2``).
    R : float
        Spring rest length (m): the distance of two agents at rest, and for
        N > 2 fully-connected agents the bound on every agent's distance from
        the centre of mass (Sec. II-D).
    min_distance : float
        ``d_min`` (m) below which ``|p_ij|`` is replaced by ``d_min`` in the
        denominators (see :mod:`mascore.flocking`). Positive.

    Raises
    ------
    TypeError
        If a gain is not a real number.
    ValueError
        If a gain is not finite and positive (``beta``: non-negative).

    Examples
    --------
    >>> FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0).R
    120.0
    """

    rho3: float
    rho4: float
    rho5: float
    rho6: float
    beta: float
    R: float
    min_distance: float = 1e-6

    def __post_init__(self) -> None:
        for name in ("rho3", "rho4", "rho5", "rho6", "R", "min_distance", "beta"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
                raise TypeError(f"{name} must be a real number; got {type(value).__name__} {value!r}")
        for name in ("rho3", "rho4", "rho5", "rho6", "R", "min_distance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"{name} must be a positive number; got {value!r}")
        if not np.isfinite(self.beta) or self.beta < 0:
            raise ValueError(f"beta must be a non-negative number; got {self.beta!r}")


FlockingGains.__module__ = "mascore.flocking"


# ----------------------------------------------------------------------------- shared kernels


def propagate(X: np.ndarray, U: np.ndarray, dt: float) -> np.ndarray:
    """Double integrator of eq. (1): ``p + dt v + dt^2/2 u``, ``v + dt u``; shape of ``X``.

    Examples
    --------
    >>> propagate(np.array([[0.0, 0.0, 1.0, 0.0]]), np.array([[2.0, 0.0]]), 0.5)
    array([[0.75, 0.  , 2.  , 0.  ]])
    """
    n = U.shape[-1]
    p, v = X[..., :n], X[..., n:]
    return np.concatenate([p + dt * v + 0.5 * dt**2 * U, v + dt * U], axis=-1)


def control_and_jacobian(X: np.ndarray, gains: FlockingGains, with_control: bool = True,
                         out: np.ndarray | None = None, scale: float = 1.0):
    """Fully-connected control of every agent and its Jacobian, from one set of pair quantities.

    Parameters
    ----------
    X : (..., N, 2n) ndarray
        Checked team states.
    gains : FlockingGains
    with_control : bool
        Also return the control (else ``None`` in its place).
    out : (..., N, n, N, 2n) ndarray, optional
        Where to write ``G`` (C-contiguous).
    scale : float
        Return ``scale * G`` instead of ``G`` (the control is not scaled).

    Returns
    -------
    U : (..., N, n) ndarray or None
        ``u_i = sum_{j != i} g(x_i - x_j)`` (m/s^2), as :func:`mascore.flocking.flocking_control`.
    G : (..., N, n, N, 2n) ndarray
        ``G[..., i, :, j, :] = du_i/dx_j``: ``-J(x_i - x_j)`` for ``j != i`` and
        ``sum_{j != i} J(x_i - x_j)`` for ``j = i``, ``J`` the pair Jacobian of
        :func:`mascore.flocking.pair_term_jacobian`. Written entry by entry into its final
        layout from ``(..., r, N)`` arrays of pair scalars (no scatter), ``r``
        rows at a time (temporaries of at most ~64 kB: fresh large temporaries
        cost page faults): ``J = s_I [I 0] + z_I [0 I] + v [c_vp p, 0]^T + p [c_pv v + c_pp p, c_pv p]^T``,
        each entry symmetric in ``(i, j)``.

    Examples
    --------
    >>> g = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
    >>> X = np.array([[0.0, 0, 1, 0], [100.0, 0, 0, 0], [50.0, 80, 0, 1]])
    >>> U, G = control_and_jacobian(X, g)
    >>> U.shape, G.shape, bool(np.allclose(G.sum(axis=-2), 0))  # translation invariance: sum_j du_i/dx_j = 0
    ((3, 2), (3, 2, 3, 4), True)
    """
    N, m = X.shape[-2:]
    n = m // 2
    batch = X.shape[:-2]
    U = np.empty((*batch, N, n)) if with_control else None
    G = np.empty((*batch, N, n, N, m)) if out is None else out
    Xt = np.ascontiguousarray(np.swapaxes(X, -1, -2))  # (..., m, N)
    # the diagonal blocks du_i/dx_i = sum_{j != i} J(x_i - x_j) of G, as one strided view (..., N, n, m)
    st = G.strides
    D = np.lib.stride_tricks.as_strided(G, (*batch, N, n, m), (*st[:-4], st[-4] + st[-2], st[-3], st[-1]))
    rows = max(1, min(N, _PAIR_BLOCK // max(1, int(np.prod(batch, dtype=np.int64)) * N)))
    for i0 in range(0, N, rows):
        _control_and_jacobian_rows(Xt, gains, i0, min(N, i0 + rows), U, G, D, scale)
    return U, G


#: Pair scalars per temporary array of :func:`control_and_jacobian` (8192 doubles = 64 kB).
_PAIR_BLOCK = 8192


def _control_and_jacobian_rows(Xt, gains, i0, i1, U, G, D, scale=1.0):
    """Rows ``i0:i1`` (agents ``i``) of :func:`control_and_jacobian`, from ``Xt = X^T`` ``(..., m, N)``.

    `D` is the ``(..., N, n, m)`` strided view of `G`'s diagonal blocks.
    """
    m, N = Xt.shape[-2:]
    n = m // 2
    batch = Xt.shape[:-2]
    r = i1 - i0
    # components of x_i - x_j as (..., r, N) arrays: p[a], v[a] (each below the allocator's mmap threshold)
    p = [Xt[..., a, i0:i1, None] - Xt[..., a, None, :] for a in range(n)]
    v = [Xt[..., n + a, i0:i1, None] - Xt[..., n + a, None, :] for a in range(n)]
    d2 = p[0] * p[0]
    vp = v[0] * p[0]
    t = np.empty(d2.shape)
    for a in range(1, n):
        d2 += np.multiply(p[a], p[a], out=t)
        vp += np.multiply(v[a], p[a], out=t)
    dmin = gains.min_distance
    de = np.sqrt(d2)
    self_pairs = _self_pairs(i0, r, N)  # the pairs (i, i) of an agent with itself, as an index of (..., r*N)
    de.reshape(*batch, r * N)[..., self_pairs] = 1.0  # any finite value there (p = v = 0)
    any_near = bool(de.min() <= dmin) if de.size else False
    if any_near:  # distinct agents closer than d_min: |p| replaced by d_min, the p p^T term dropped
        near = de <= dmin
        np.maximum(de, dmin, out=de)
    one_d2 = d2
    one_d2 += 1.0
    f1 = np.log2(one_d2)  # base 2: numpy's exp2 is vectorized, its exp (and log1p) are not
    f1 *= -gains.beta
    np.exp2(f1, out=f1)  # phi1 = (1 + |p|^2)^(-beta)
    c5 = gains.rho4 * gains.rho5 / 2
    c6 = gains.rho4 * gains.rho6 / 2
    # pair scalars with the signs of -J (G = -J off the diagonal), times `scale`: J = s_I [I 0] + z_I [0 I]
    #   + v [c_vp p, 0]^T + p [c_pv v + c_pp p, c_pv p]^T, and -s_I = c5 <v,p>/de^2 + c6 (1 - R/de) = rho4 phi2
    k = scale
    inv2 = np.multiply(de, de)
    np.divide(k, inv2, out=inv2)  # k / de^2
    r_de = np.divide(k * c6 * gains.R, de, out=de)  # k c6 R / de
    t1 = np.multiply(vp, inv2, out=vp)  # k <v,p> / de^2
    ns_I = np.multiply(t1, c5)
    ns_I += k * c6
    ns_I -= r_de  # -k s_I
    nc_pp = np.multiply(t1, -2.0 * c5)
    nc_pp += r_de
    nc_pp *= inv2
    nc_pp *= 1.0 / k  # -k c_pp
    if any_near:
        nc_pp[near] = 0.0
    nc_pv = np.multiply(inv2, c5, out=t1)  # -k c_pv
    nz_I = np.multiply(f1, k * gains.rho3, out=f1)  # -k z_I = k rho3 phi1
    nc_vp = np.multiply(nz_I, -2.0 * gains.beta, out=inv2)
    nc_vp /= one_d2  # -k c_vp
    ns_I.reshape(*batch, r * N)[..., self_pairs] = 0.0  # the pair term of an agent with itself is zero
    nz_I.reshape(*batch, r * N)[..., self_pairs] = 0.0
    if U is not None:  # the pair term of eq. (6), g = -rho3 phi1 v - rho4 phi2 p = -(nz_I v + ns_I p) / k
        for a in range(n):
            Ua = U[..., i0:i1, a]
            Ua[...] = np.einsum("...ij,...ij->...i", nz_I, v[a])
            Ua += np.einsum("...ij,...ij->...i", ns_I, p[a])
            Ua *= -1.0 / k
    Gr = G[..., i0:i1, :, :, :]
    D = D[..., i0:i1, :, :]  # the diagonal blocks of these rows
    t2 = np.empty(t.shape)
    for b in range(n):  # each entry of -J computed in contiguous arrays, then written once into its slot of G
        pb = p[b]
        A_b = np.multiply(nc_vp, pb)  # -c_vp p_b
        B_b = np.multiply(nc_pv, v[b])
        B_b += np.multiply(nc_pp, pb, out=t)  # -(c_pv v_b + c_pp p_b)
        C_b = np.multiply(nc_pv, pb)  # -c_pv p_b
        for a in range(n):
            np.multiply(v[a], A_b, out=t)  # du_a/dp_b = -J
            t += np.multiply(p[a], B_b, out=t2)
            if a == b:
                t += ns_I
            np.copyto(Gr[..., :, a, :, b], t)
            np.negative(t.sum(axis=-1), out=D[..., a, b])  # (the entries (i, i) of t are zero)
            if a <= b:  # du_a/dv_b = -J, symmetric in (a, b)
                np.multiply(p[a], C_b, out=t)
                if a == b:
                    t += nz_I
                np.copyto(Gr[..., :, a, :, n + b], t)
                np.negative(t.sum(axis=-1), out=D[..., a, n + b])
                if a < b:
                    np.copyto(Gr[..., :, b, :, n + a], t)
                    D[..., b, n + a] = D[..., a, n + b]


def _self_pairs(i0, r, N):
    """Flat indices ``k N + i0 + k`` (``k < r``) of the pairs ``(i0 + k, i0 + k)`` in a ``(r, N)`` block of pairs."""
    return slice(i0, i0 + r * (N + 1), N + 1)


# ----------------------------------------------------------------------------- checks


def check_team(X: ArrayLike, name: str, allow_nan: bool = False) -> np.ndarray:
    """A team state ``(..., N, 2n)`` as a float array, finite (NaN allowed with `allow_nan`).

    Raises
    ------
    ValueError
        Wrong shape, or non-finite entries.

    Examples
    --------
    >>> check_team([[0.0, 0.0, 1.0, 0.0]], "X").shape
    (1, 4)
    """
    X = float_array(X, name)
    if X.ndim < 2 or X.shape[-1] % 2 or X.shape[-1] == 0 or X.shape[-2] == 0:
        raise ValueError(f"{name} must have shape (..., N, 2n) with rows [p_i; v_i]; got {X.shape}")
    if allow_nan:
        if np.any(np.isinf(X)):
            raise ValueError(f"{name} contains infinite entries")
    elif not np.all(np.isfinite(X)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    return X


def check_dt(dt: object) -> float:
    """The sampling time ``dt`` (s), finite and > 0 (a 0-d array is accepted).

    Examples
    --------
    >>> check_dt(np.array(0.1))
    0.1
    """
    if isinstance(dt, np.ndarray) and dt.ndim == 0:
        dt = dt[()]
    dt = check_positive(dt, "dt", "s")
    if not np.isfinite(dt * dt):  # the double integrator uses dt^2 / 2
        raise ValueError(f"dt must be a sampling time whose square is finite (s); got {dt!r}")
    return dt


def check_range(r: object, hint: str = "") -> float:
    """The sensing range ``r`` (m), finite and > 0; `hint` is added to the message for ``inf``.

    Examples
    --------
    >>> check_range(150)
    150.0
    """
    if isinstance(r, np.ndarray) and r.ndim == 0:
        r = r[()]
    if isinstance(r, (int, float, np.integer, np.floating)) and not isinstance(r, bool) and np.isinf(r) and hint:
        raise ValueError(f"sensing_range must be a finite number > 0 m; got {r!r} ({hint})")
    return check_positive(r, "sensing_range", "m")


def check_steps(n_steps: object) -> int:
    """A number of steps, 1 to :data:`MAX_STEPS`.

    Examples
    --------
    >>> check_steps(10)
    10
    """
    n_steps = check_positive_int(n_steps, "n_steps", minimum=1)
    if n_steps > MAX_STEPS:
        raise ValueError(f"n_steps = {n_steps} is more than MAX_STEPS = {MAX_STEPS}; run fewer steps")
    return n_steps


def check_gains(gains: object) -> None:
    """Raise ``TypeError`` unless `gains` is a :class:`FlockingGains`.

    Examples
    --------
    >>> check_gains(FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0))
    """
    if not isinstance(gains, FlockingGains):
        raise TypeError(f"gains must be a mascore.flocking.FlockingGains; got {type(gains).__name__}")


def check_vectors(x: ArrayLike, name: str) -> np.ndarray:
    """A finite ``(..., n)`` float array with ``n >= 1``.

    Examples
    --------
    >>> check_vectors([1.0, 2.0], "p")
    array([1., 2.])
    """
    x = float_array(x, name)
    if x.ndim < 1 or x.shape[-1] == 0:
        raise ValueError(f"{name} must have shape (..., n) with n >= 1; got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    return x


def check_pair_args(p: ArrayLike, v: ArrayLike, gains: object) -> tuple[np.ndarray, np.ndarray]:
    """Relative position and velocity of a pair (broadcastable, same ``n``) and the gains.

    Examples
    --------
    >>> g = FlockingGains(rho3=3.0, rho4=1.0, rho5=2.0, rho6=1.0, beta=0.33, R=120.0)
    >>> [a.shape for a in check_pair_args([1.0, 0.0], [[0.0, 1.0]], g)]
    [(2,), (1, 2)]
    """
    p, v = check_vectors(p, "p"), check_vectors(v, "v")
    try:
        np.broadcast_shapes(p.shape, v.shape)
    except ValueError:
        raise ValueError(f"v must have the shape of p {p.shape} (or broadcast against it); got {v.shape}") from None
    if v.shape[-1] != p.shape[-1]:
        raise ValueError(f"v must have the shape of p {p.shape}; got {v.shape}")
    check_gains(gains)
    return p, v


def check_weights(adjacency: ArrayLike | None, N: int, name: str, batch: tuple = ()) -> np.ndarray | None:
    """A ``(..., N, N)`` adjacency ``a_ij >= 0``, finite (``None`` passes through: fully connected).

    A graph Laplacian passed by mistake is named as such.

    Examples
    --------
    >>> check_weights(None, 3, "adjacency") is None
    True
    """
    if adjacency is None:
        return None
    A = float_array(adjacency, name)
    if A.ndim < 2 or A.shape[-2:] != (N, N):
        raise ValueError(f"{name} must have shape (..., {N}, {N}); got {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError(f"{name} contains NaN or infinite entries")
    if np.any(A < 0):
        diag = np.diagonal(A, axis1=-2, axis2=-1)
        if np.all(diag >= 0) and np.any(diag > 0) and np.allclose(A.sum(axis=-1), 0.0):
            raise ValueError(f"{name} looks like a graph Laplacian (negative off-diagonal entries, rows summing "
                             "to zero); pass the adjacency matrix instead (A = diag(diag(L)) - L)")
        raise ValueError(f"{name} must have non-negative weights a_ij; smallest entry is {A.min():.3g}")
    try:
        np.broadcast_shapes(A.shape[:-2], batch)
    except ValueError:
        raise ValueError(f"{name} has batch axes {A.shape[:-2]} that do not match the team's {batch}") from None
    return A


def check_divergence(X: np.ndarray, k: int, dt: float, what: str = "team state") -> None:
    """Raise :class:`DivergenceError` if a component of `X` reaches :data:`DIVERGENCE_LIMIT` at step `k`.

    Examples
    --------
    >>> check_divergence(np.zeros(3), 1, 0.1)
    """
    if not np.all(np.abs(X) < DIVERGENCE_LIMIT):
        raise DivergenceError(
            f"the closed loop diverged: the {what} exceeded {DIVERGENCE_LIMIT:g} at step {k} (t = {k * dt:g} s); "
            "the sampled flocking law is unstable for these gains, dt and number of agents"
        )


def check_within_limit(values: np.ndarray, name: str, what: str = "entries") -> None:
    """Refuse up front `values` at or beyond :data:`DIVERGENCE_LIMIT`, where a run would count as diverged.

    Examples
    --------
    >>> check_within_limit(np.array([1.0, -2.0]), "X0")
    >>> check_within_limit(np.array([1e300]), "X0")
    Traceback (most recent call last):
    ...
    ValueError: X0 has entries of 1e+300, at or beyond DIVERGENCE_LIMIT = 1e+07 where a run counts as diverged; ...
    """
    big = float(np.max(np.abs(values), initial=0.0))
    if not big < DIVERGENCE_LIMIT:
        raise ValueError(f"{name} has {what} of {big:.3g}, at or beyond DIVERGENCE_LIMIT = {DIVERGENCE_LIMIT:g} "
                         f"where a run counts as diverged; use smaller units (km instead of m) or check the values")


def noise_factor(C: ArrayLike, name: str, size: int) -> np.ndarray:
    """``L`` with ``C = L L^T`` for a checked (possibly semidefinite) ``(size, size)`` covariance `C`.

    Examples
    --------
    >>> L = noise_factor(np.diag([4.0, 0.0]), "Q", 2)
    >>> np.round(L @ L.T, 12)
    array([[4., 0.],
           [0., 0.]])
    """
    C = float_array(C, name)
    if C.ndim != 2:
        raise ValueError(f"Incompatible dimensions of {name}; expected ({size}, {size}) but found {C.shape}")
    C = check_covariance(C, name, size=size)
    w, V = np.linalg.eigh(C)
    return V * np.sqrt(np.clip(w, 0, None))


def finite_where_input_is(out: np.ndarray, X: np.ndarray, what: str) -> None:
    """Overflow check of a statistic over the last two axes of `X`: finite wherever ``X[..., :, :]`` is.

    Examples
    --------
    >>> finite_where_input_is(np.array([1.0, np.nan]), np.array([[[0.0]], [[np.nan]]]), "f")
    """
    known = np.isfinite(X).all(axis=(-1, -2))
    if not np.all(np.isfinite(out[known])):
        raise ValueError(f"{what} overflowed although X is finite: X holds values too large for floating "
                         "point; rescale it")
