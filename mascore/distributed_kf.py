"""Whole-team Kalman filters run by every agent (Song et al. 2023, Sec. III.A, IV).

Every agent ``i`` of a team of ``N`` linear agents estimates the *whole* team
state ``X`` (size ``M = m N``) from its own local measurements only (eq. (3)):
no estimate is exchanged. Two closed loops are covered.

**Measurement-based control** (eqs. (8)-(20)). The agents steer with raw
measurements (eq. (5)); agent ``i`` predicts with its own guess of the team's
control (eqs. (12)-(14)), ``X̂_i^- = F_1 X̂_i`` with
``F_1 = I_N ⊗ A - L ⊗ BK`` (eq. (11)), and adds the control-noise term of
eq. (15) to the covariance. Each agent only needs its own ``Σ_i``.

**Estimation-based control** (eqs. (21)-(34)). The agents steer with their own
estimates (eq. (21)), so the true team evolves as
``X+ = F_1 X + F_2 e + w`` (eq. (28)) with the *augmented* error
``e = [e_1; ...; e_N]`` and ``F_2 = (I_N ⊗ BK) L'``. Agent ``i``'s prediction
error is ``e_i^- = F_1 e_i + F_2 e + w``, so every agent must propagate the
full ``N M x N M`` covariance ``Σ`` of ``e`` with all cross-covariances
``Σ_ij`` (eqs. (29)-(34)); by Remark 4 it is the same for every agent.

**Any linear sensing.** With an output matrix per agent (``z_ij = C_j x_j + nu_ij``, e.g.
positions only; :func:`~mascore.team_model.team_filter_model` with ``C``), agent ``i``'s
measurement matrix is ``H_i = D_i blockdiag(C_1, ..., C_N)``, the rows of the agents it
senses, and eqs. (16)-(20), (33) hold as written with that ``H_i``. The estimation-based loop
takes it (the control, eq. (21), uses the estimates); the measurement-based loop does not
(its control, eq. (5), feeds the raw measurements through the state-feedback gain ``K``).
:class:`TeamFilter` checks that system (43) stays observable for every agent with these
outputs (:func:`mascore.team_observability.require_observable`) and refuses it by name
otherwise. The update runs the same dense or row-block kernels as below, with the sensed
outputs ``H_i Σ^-`` in place of the selected rows of ``Σ^-``.

Implementation (the "structured" path)
--------------------------------------
* Masks instead of ragged selection matrices: ``H_i^T H_i = diag(S_i) ⊗ I_m``
  and the gain ``G_i H_i = Σ^- D (D (Σ^- + R) D + I - D)^{-1} D`` with
  ``D = diag(S_i) ⊗ I_m``, so all agents (and Monte Carlo runs) update in
  one batched call.
* Kronecker factor: for the double integrator with ``Q``, ``R`` and the
  initial covariance of the form ``X̄ ⊗ I_n`` (per spatial axis), every
  covariance stays ``Σ̄ ⊗ I_n``; the recursion runs on ``Σ̄``, ``n`` times
  smaller per side (8x fewer flops in the plane).
* Tensor form of the augmented prediction: with ``e[i, j]`` agent ``i``'s error
  on agent ``j``, ``e^-[i, j] = A e[i, j] + BK ((L e)[j, j] - (L e)[i, j])``
  where ``(L e)[i, j] = sum_l L_jl e[i, l]``, i.e. ``e^-[i] = F_1 e[i] + F_2 e``:
  one ``m N x m N`` product per agent block plus a term shared by all blocks.
  Applying it to ``Σ`` costs ``O(N^5 m^3)`` in BLAS-friendly products instead
  of the ``O(N^6 m^3)`` of dense products with ``Φ``.
* The covariance recursion does not depend on the noise realization: for a
  fixed topology one ``Σ`` (batch axis of length 1) serves every Monte Carlo
  run, while the means carry a run axis.

Checked once, then stepped
--------------------------
:class:`~mascore.team_model.TeamFilterModel` checks ``A``, ``BK``, ``Q``, ``R`` when it is built and
keeps read-only copies. :class:`TeamFilter` (and
:class:`~mascore.centralized_team_filter.CentralizedTeamFilter`) checks the initial state once and
then owns it: a step checks only what changes (shapes, mask values) and tests its result for
NaN/inf. It keeps the
``Φ`` blocks of its topology and its work arrays, and updates a large
augmented covariance in place; filters share nothing, so independent filters
may run in parallel threads. The plain-array functions (:func:`eb_predict`,
:func:`eb_update`, :func:`mb_predict`, ...) run the same steps on a filter
built for the call, after checking every argument in full on every call
(an eigenvalue test of the covariance): convenient for one step, slow in a loop.

A plain implementation written straight from eqs. (29)-(34) with explicit
``F_1``, ``F_2``, ``H_i`` and ``G_i`` (``mascore._kf_reference``) is the
reference for the tests and the benchmark. Beside this module: the model in
:mod:`mascore.team_model`, the centralized Kalman filter over all agents' measurements
in :mod:`mascore.centralized_team_filter`, the observability test of system (43) and the
quantities of Theorem 1 (eqs. (45), (49)) in :mod:`mascore.team_observability`.

Shapes: ``X̂`` is ``(runs, N, N, m)`` (run, observer ``i``, target ``j``,
state), reduced covariances are ``(batch, N, M_r, M_r)`` per agent or
``(batch, N M_r, N M_r)`` augmented, with ``batch`` either 1 (shared) or
``runs``. (``B`` is always the agents' input matrix.)
"""

from __future__ import annotations

from collections.abc import Sequence
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from ._masked_gain import masked_gain, observed_indices
from ._team_kernels import (
    DENSE_MAX,
    F1_means,
    F1_rows,
    apply_gain,
    apply_output_gain,
    block_sandwich,
    check_batch,
    check_covariances,
    check_estimates,
    check_mask,
    check_measurements,
    check_model,
    check_runs,
    check_team_laplacian,
    diagonal_blocks,
    eb_predict_rows,
    eb_update_rows,
    finite_state,
    joseph,
    mask_vec,
    mb_noise,
    output_gain,
    phi_blocks,
    reduced_nees,
    team_output_matrix,
)
from ._validation import (
    check_covariance,
    check_flag,
    check_mask_values,
    finite_result,
    frozen_copy,
    state_view,
    symmetric_part,
)
from ._validation import float_array as _float_array
from ._validation import require_finite as _finite
from .estimation import Message, MethodSpec
from .fusion_cost import filter_cost
from .sensing import team_noise_covariance
from .team_model import TeamFilterModel, reduce_covariance, team_filter_model
from .team_observability import require_observable

__all__ = [
    "TeamFilter",
    "agent_update",
    "mb_predict",
    "mb_update",
    "eb_initial_covariance",
    "eb_predict",
    "eb_update",
    "agent_covariances",
    "team_nees",
    "f2_cross",
]




# ----------------------------------------------------------------------------
# the per-agent measurement update (the masked gain of mascore._masked_gain, which the EKF also uses)
# ----------------------------------------------------------------------------
def agent_update(
    X_pred: ArrayLike, Sigma_pred: ArrayLike, Z: ArrayLike, mask: ArrayLike, R: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every agent's Kalman update of its team estimate, eqs. (16)-(20), batched.

    Parameters
    ----------
    X_pred : (..., N, N, m) array_like
        Predicted team estimates, ``X_pred[..., i, j]`` = ``x̂^-_{i,j}``.
    Sigma_pred : (..., N, m N, m N) array_like
        Each agent's predicted covariance ``Σ_i^-``.
    Z : (..., N, N, m) array_like
        Measurements from :func:`mascore.sensing.measure` (unsensed entries
        are ignored).
    mask : (..., N, N) array_like of bool
        Sensing mask (closed neighbourhoods, diagonal true).
    R : (m, m) or (m N, m N) array_like
        Measurement-noise covariance (positive definite).

    Returns
    -------
    X_post : (..., N, N, m) ndarray
    Sigma_post : (..., N, m N, m N) ndarray
        Joseph form, equal to eq. (20) at the optimal gain.
    KH : (..., N, m N, m N) ndarray
        ``G_i H_i`` embedded in the team space (zero columns for unsensed agents).

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> X, Sig, KH = dkf.agent_update(X_pred, np.broadcast_to(np.eye(6), (1, 3, 6, 6)), Z, mask, np.eye(2))
    >>> bool(np.all(np.trace(Sig, axis1=-2, axis2=-1) < 6.0))   # every agent's uncertainty shrinks
    True
    """
    X = _finite(_float_array(X_pred, "X_pred"), "X_pred")
    if X.ndim < 3 or X.shape[-3] != X.shape[-2] or X.shape[-1] == 0 or X.shape[-2] == 0:
        raise ValueError(f"X_pred must have shape (..., N, N, m) with N, m >= 1; got {X.shape}")
    N, m = X.shape[-2:]
    Sig = check_covariance(_float_array(Sigma_pred, "Sigma_pred"), "Sigma_pred", size=m * N)
    R_team = team_noise_covariance(R, N, m)
    check_covariance(R_team, "R", definite=True)
    Zt = _finite(_float_array(Z, "Z"), "Z")
    if Zt.ndim < 3 or Zt.shape[-3:] != (N, N, m):
        raise ValueError(f"Incompatible dimensions of Z; expected (..., {N}, {N}, {m}) but found {Zt.shape}")
    S = check_mask_values(mask, "mask")
    if S.ndim < 2 or S.shape[-2:] != (N, N):
        raise ValueError(f"Incompatible dimensions of mask; expected (..., {N}, {N}) but found {S.shape}")
    if not np.all(S[..., np.arange(N), np.arange(N)]):
        raise ValueError("mask must include every agent itself (closed neighbourhoods); use sensing_mask(A)")
    try:
        d = np.repeat(S, m, axis=-1).astype(float)  # (..., N, mN)
        KH = masked_gain(Sig, d, R_team)
        lead = X.shape[:-3]
        innov = (Zt - X).reshape(*np.broadcast_shapes(lead, Zt.shape[:-3]), N, N * m, 1)
        X_post = X.reshape(*lead, N, N * m, 1) + KH @ innov
        Sig_post = joseph(Sig, KH, R_team)
    except ValueError:
        raise ValueError(
            f"the leading (batch) axes of X_pred {X.shape}, Sigma_pred {Sig.shape}, Z {Zt.shape} and "
            f"mask {S.shape} do not broadcast"
        ) from None
    return finite_result("agent update", X_post.reshape(*X_post.shape[:-3], N, N, m), Sig_post, KH)


# ----------------------------------------------------------------------------
# measurement-based control loop, eqs. (8)-(20)
# ----------------------------------------------------------------------------
def mb_predict(
    model: TeamFilterModel,
    X_hat: ArrayLike,
    Sigma: ArrayLike,
    laplacian: ArrayLike,
    KH_prev: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Prediction of the measurement-based loop, eqs. (14)-(15).

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(model, laplacian, x_hat0, P0, mode="mb")``, and call its :meth:`~TeamFilter.predict`: the fast path.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    X_hat : (runs, N, N, m) array_like
        Posterior team estimates of every agent, per Monte Carlo run.
    Sigma : (batch, N, M_r, M_r) array_like
        Reduced posterior covariances ``Σ̄_i`` (``batch`` = 1 or ``runs``).
    laplacian : (N, N) or (batch, N, N) array_like
        Topology at step k.
    KH_prev : (batch, N, M_r, M_r) array_like, optional
        Reduced ``G_i H_i`` of the update that produced `X_hat`. If given, the
        correlation between agent ``i``'s own measurement noise in its
        control (eq. (9)) and its posterior error is added (exact covariance);
        the paper's eq. (15) neglects it (``None``).

    Returns
    -------
    X_pred : (runs, N, N, m) ndarray
    Sigma_pred : (batch, N, M_r, M_r) ndarray

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> X, Sig = dkf.mb_predict(model, X_post, dkf.agent_covariances(model, Sigma_post), Lap)
    >>> Sig.shape
    (1, 3, 6, 6)
    """
    model = check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = check_team_laplacian(laplacian, N)
    X = check_estimates(model, X_hat, "X_hat")
    Sig = check_covariances(Sigma, "Sigma", (None, N, Mr, Mr), kron=model.kron)
    check_batch(L, Sig, "laplacian", "Sigma", X)
    KH = None
    if KH_prev is not None:
        KH = _finite(_float_array(KH_prev, "KH_prev"), "KH_prev")
        if KH.shape != Sig.shape:
            raise ValueError(
                f"Incompatible dimensions of KH_prev; expected {Sig.shape} (as Sigma) but found {KH.shape}"
            )
    filt = TeamFilter._from_checked(model, "mb", L, X, Sig, KH, exact_control_noise=KH is not None)
    filt.predict()
    return filt._X, filt._Sig


def mb_update(
    model: TeamFilterModel, X_pred: ArrayLike, Sigma_pred: ArrayLike, Z: ArrayLike, mask: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Update of every agent's filter (eqs. (16)-(20)) in reduced form.

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(..., mode="mb")``, and call its :meth:`~TeamFilter.update`: the fast path.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    X_pred : (runs, N, N, m) array_like
        Predicted team estimates.
    Sigma_pred : (batch, N, M_r, M_r) array_like
        Reduced predicted covariances.
    Z : (runs, N, N, p) array_like
        Measurements (:func:`mascore.sensing.measure`);
        ``p = m`` (full states) unless the model has an output matrix ``C``
        (``z_ij = C_j x_j + nu_ij``).
    mask : (N, N) or (batch, N, N) array_like of bool
        Sensing mask.

    Returns
    -------
    X_post : (runs, N, N, m) ndarray
        Updated estimates.
    Sigma_post : (batch, N, M_r, M_r) ndarray
        Reduced updated covariances.
    KH : (batch, N, M_r, M_r) ndarray
        Reduced ``G_i H_i``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> X, Sig = dkf.mb_predict(model, X_post, dkf.agent_covariances(model, Sigma_post), Lap)
    >>> X2, Sig2, KH2 = dkf.mb_update(model, X, Sig, Z, mask)
    >>> bool(np.allclose(Sig2, np.swapaxes(Sig2, -1, -2)))
    True
    """
    model = check_model(model)
    N, Mr = model.n_agents, model.M_r
    X = check_estimates(model, X_pred, "X_pred")
    Sig = check_covariances(Sigma_pred, "Sigma_pred", (None, N, Mr, Mr), kron=model.kron)
    Zt = check_measurements(model, Z, "Z")
    S = check_mask(mask, N)
    if S.shape[0] not in (1, Sig.shape[0]):
        raise ValueError(f"mask has {S.shape[0]} topologies but Sigma_pred has {Sig.shape[0]}")
    check_runs(X, Zt, "X_pred", "Z")
    if Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"Sigma_pred has batch {Sig.shape[0]} but X_pred has {X.shape[0]} runs")
    filt = TeamFilter._from_checked(model, "mb", None, X, Sig)
    filt.update(Zt, S)
    return filt._X, filt._Sig, filt._KH


# ----------------------------------------------------------------------------
# estimation-based control loop, eqs. (21)-(34)
# ----------------------------------------------------------------------------
def eb_initial_covariance(model: TeamFilterModel, P0: ArrayLike, common: bool = True) -> np.ndarray:
    """Initial augmented covariance ``Σ[0]`` (reduced), shape ``(1, N M_r, N M_r)``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    P0 : (m, m) or (m N, m N) array_like
        Covariance of one agent's initial team-estimate error (per agent block
        or full).
    common : bool
        True: all agents start from the *same* initial estimate, so
        ``e_i[0]`` coincide and ``Σ[0] = 1 1^T ⊗ P0`` (the reading of
        Assumption 2 that makes Lemma 1's ``e[0] = C_i[0] e_i[0]`` exact with
        ``C_i[0] = 1_N ⊗ I``). False: independent initial errors,
        ``Σ[0] = I_N ⊗ P0``.

    Returns
    -------
    (1, N M_r, N M_r) ndarray
        The reduced augmented covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> dkf.eb_initial_covariance(model, np.eye(2)).shape         # common start: 1 1^T (x) P0
    (1, 18, 18)
    """
    model = check_model(model)
    check_flag(common, "common")
    N, m = model.n_agents, model.m
    P0 = _finite(_float_array(P0, "P0"), "P0")
    if P0.shape == (m, m):
        P0 = np.kron(np.eye(N), P0)
    if P0.shape != (m * N, m * N):
        raise ValueError(
            f"Incompatible dimensions of P0; expected ({m}, {m}) per agent block or ({m * N}, {m * N}) "
            f"but found {P0.shape}"
        )
    P0 = check_covariance(P0, "P0", size=m * N)
    P0r = reduce_covariance(P0, model.kron, "P0")
    outer = np.ones((N, N)) if common else np.eye(N)
    return np.kron(outer, P0r)[None]


def eb_predict(
    model: TeamFilterModel, X_hat: ArrayLike, Sigma: ArrayLike, laplacian: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Prediction of the estimation-based loop: eq. (14) and eqs. (32), (34).

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(model, laplacian, x_hat0, P0)``, and call its :meth:`~TeamFilter.predict`: the fast path.

    ``Σ^- = Φ Σ Φ^T + (1 1^T) ⊗ 𝒬`` with ``Φ = I_N ⊗ F_1 + 1_N ⊗ F_2``
    (every block ``(i, j)`` of this is eq. (34); ``i = j`` gives eq. (32)),
    computed in tensor form (see module docstring).

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    X_hat : (runs, N, N, m) array_like
        Updated team estimates of every agent.
    Sigma : (batch, N M_r, N M_r) array_like
        Reduced augmented covariance.
    laplacian : (N, N) or (batch, N, N) array_like
        Topology at step k.

    Returns
    -------
    X_pred : (runs, N, N, m) ndarray
        Predicted estimates.
    Sigma_pred : (batch, N M_r, N M_r) ndarray
        Predicted augmented covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> Sigma_pred.shape
    (1, 18, 18)
    """
    model = check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = check_team_laplacian(laplacian, N)
    X = check_estimates(model, X_hat, "X_hat")
    Sig = check_covariances(Sigma, "Sigma", (None, N * Mr, N * Mr), kron=model.kron)
    check_batch(L, Sig, "laplacian", "Sigma", X)
    filt = TeamFilter._from_checked(model, "eb", L, X, Sig)
    filt.predict()
    return filt._X, filt._Sig


def eb_update(
    model: TeamFilterModel, X_pred: ArrayLike, Sigma_pred: ArrayLike, Z: ArrayLike, mask: ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Update of the estimation-based loop: eqs. (16)-(20) and (33).

    Checks every argument in full on every call (including an eigenvalue test of the
    covariance, which dominates the cost for a large team), then runs the same step as
    :class:`TeamFilter`. In a loop, build the filter once,
    ``TeamFilter(model, laplacian, x_hat0, P0)``, and call its :meth:`~TeamFilter.update`: the fast path.

    ``Σ_ij = (I - G_i H_i) Σ_ij^- (I - G_j H_j)^T + δ_ij G_i H_i R H_i^T G_i^T``:
    eq. (33) for ``i != j`` (measurement noises of different agents are
    independent) and the Joseph form of eq. (20) for ``i = j``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    X_pred : (runs, N, N, m) array_like
        Predicted team estimates.
    Sigma_pred : (batch, N M_r, N M_r) array_like
        Predicted augmented covariance.
    Z : (runs, N, N, p) array_like
        Measurements;
        ``p = m`` (full states) unless the model has an output matrix ``C``
        (``z_ij = C_j x_j + nu_ij``).
    mask : (N, N) or (batch, N, N) array_like of bool
        Sensing mask.

    Returns
    -------
    X_post : (runs, N, N, m) ndarray
        Updated estimates.
    Sigma_post : (batch, N M_r, N M_r) ndarray
        Updated augmented covariance.
    KH : (batch, N, M_r, M_r) ndarray
        Reduced ``G_i H_i``.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> bool(np.allclose(Sigma_post, np.swapaxes(Sigma_post, -1, -2)))
    True
    """
    model = check_model(model)
    N, Mr = model.n_agents, model.M_r
    X = check_estimates(model, X_pred, "X_pred")
    Sig = check_covariances(Sigma_pred, "Sigma_pred", (None, N * Mr, N * Mr), kron=model.kron)
    Zt = check_measurements(model, Z, "Z")
    S = check_mask(mask, N)
    if S.shape[0] not in (1, Sig.shape[0]):
        raise ValueError(
            f"mask has {S.shape[0]} topologies but Sigma_pred has {Sig.shape[0]}: the covariance batch must "
            "match the topology batch (pass the topology mask, not the per-run measurement mask)"
        )
    check_runs(X, Zt, "X_pred", "Z")
    if Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"Sigma_pred has batch {Sig.shape[0]} but X_pred has {X.shape[0]} runs")
    filt = TeamFilter._from_checked(model, "eb", None, X, Sig)
    filt.update(Zt, S)
    return filt._X, filt._Sig, filt._KH


def agent_covariances(model: TeamFilterModel, Sigma: ArrayLike) -> np.ndarray:
    """Diagonal blocks ``Σ̄_i`` of a reduced augmented covariance.

    Checks the covariance in full on every call (an eigenvalue test); a :class:`TeamFilter`
    gives the same from its own state without one: :meth:`TeamFilter.agent_covariances`.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    Sigma : (batch, N M_r, N M_r) array_like
        Reduced augmented covariance.

    Returns
    -------
    (batch, N, M_r, M_r) ndarray
        Each agent's own covariance.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> dkf.agent_covariances(model, Sigma_post).shape
    (1, 3, 6, 6)
    """
    model = check_model(model)
    N, Mr = model.n_agents, model.M_r
    Sig = check_covariances(Sigma, "Sigma", (None, N * Mr, N * Mr), kron=model.kron)
    return diagonal_blocks(model, Sig)


def team_nees(model: TeamFilterModel, X_true: ArrayLike, X_hat: ArrayLike, Sigma_i: ArrayLike) -> np.ndarray:
    """NEES of every agent's team estimate: ``(runs, N)``, chi-square with ``m N`` dof.

    Checks the covariance in full on every call (an eigenvalue test); a :class:`TeamFilter`
    gives the same from its own state without one: :meth:`TeamFilter.nees`.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    X_true : (runs, N, m) array_like
        True states.
    X_hat : (runs, N, N, m) array_like
        Every agent's team estimate.
    Sigma_i : (batch, N, M_r, M_r) array_like
        Their reduced covariances, positive definite.

    Returns
    -------
    (runs, N) ndarray
        The NEES of each agent's estimate.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> dkf.team_nees(model, np.zeros((1, 3, 2)), X_post, dkf.agent_covariances(model, Sigma_post)).shape
    (1, 3)
    """
    model = check_model(model)
    N, m, Mr = model.n_agents, model.m, model.M_r
    X_true = _finite(_float_array(X_true, "X_true"), "X_true")
    if X_true.ndim != 3 or X_true.shape[1:] != (N, m):
        raise ValueError(f"Incompatible dimensions of X_true; expected (runs, {N}, {m}) but found {X_true.shape}")
    X = check_estimates(model, X_hat, "X_hat")
    check_runs(X_true, X, "X_true", "X_hat")
    Sig = check_covariances(Sigma_i, "Sigma_i", (None, N, Mr, Mr), definite=True, kron=model.kron)
    if Sig.shape[0] not in (1, X.shape[0]):
        raise ValueError(f"Sigma_i has batch {Sig.shape[0]} but X_hat has {X.shape[0]} runs")
    return _team_nees(model, X_true, X, Sig)


def _team_nees(model, X_true, X_hat, Sigma_i):
    """:func:`team_nees` without checks."""
    with np.errstate(over="ignore", invalid="ignore"):
        e = (X_true[:, None] - X_hat).reshape(X_true.shape[0], model.n_agents, -1)
        out = reduced_nees(e, Sigma_i, model.kron)
    if not np.isfinite(out).all():
        raise ValueError(f"X_true: the NEES overflows floating point (largest error {float(np.abs(e).max()):.3g}); "
                         "the true states and the estimates must be of moderate magnitude (rescale the units)")
    return out


def f2_cross(model: TeamFilterModel, Sigma: ArrayLike, laplacian: ArrayLike) -> np.ndarray:
    """``F_2 E[e e_i^T]`` for every agent ``i``: reduced, shape ``(batch, N, M_r, M_r)``.

    Checks the covariance in full on every call (an eigenvalue test); a :class:`TeamFilter`
    gives the same from its own state without one: :meth:`TeamFilter.f2_cross`.

    Used to form the map ``C_i = E[e e_i^T] Σ_i^{-1}`` of Lemma 1 without
    storing the augmented covariance: ``F_2 C_i = F_2 E[e e_i^T] Σ_i^{-1}``.

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    Sigma : (batch, N M_r, N M_r) array_like
        Reduced augmented covariance.
    laplacian : (N, N) or (batch, N, N) array_like
        Topology.

    Returns
    -------
    (batch, N, M_r, M_r) ndarray
        ``F_2 E[e e_i^T]`` per agent.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3); Lap = graphs.laplacian(path)
    >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))           # one run
    >>> Sigma0 = dkf.eb_initial_covariance(model, np.eye(2))
    >>> X_pred, Sigma_pred = dkf.eb_predict(model, np.zeros((1, 3, 3, 2)), Sigma0, Lap)
    >>> X_post, Sigma_post, KH = dkf.eb_update(model, X_pred, Sigma_pred, Z, mask)
    >>> dkf.f2_cross(model, Sigma_post, Lap).shape
    (1, 3, 6, 6)
    """
    model = check_model(model)
    N, Mr = model.n_agents, model.M_r
    L = check_team_laplacian(laplacian, N, undirected=True)
    Sig = check_covariances(Sigma, "Sigma", (None, N * Mr, N * Mr), kron=model.kron)
    check_batch(L, Sig, "laplacian", "Sigma")
    return _f2_cross(model, Sig, L)


def _f2_cross(model, Sig, L):
    """:func:`f2_cross` without checks."""
    N, mr, Mr = model.n_agents, model.m_r, model.M_r
    Lb = L if L.ndim == 3 else L[None]
    nb = Sig.shape[0]
    T = Sig.reshape(nb, N, N, mr * N * Mr)
    U = (Lb[:, None] @ T).reshape(nb, N, N, mr, N * Mr)
    Ud = U[:, np.arange(N), np.arange(N)]  # (batch, N_j, mr, N*Mr): sum_l L_jl Σ[j, l]
    F2S = (model.BK_r @ Ud).reshape(nb, Mr, N, Mr)  # rows: F_2 Σ
    return np.moveaxis(F2S, 2, 1)  # (batch, N_i, Mr, Mr): column block i


# ----------------------------------------------------------------------------
# the whole-team filters: one object per run of filters, owning its state and work arrays
# ----------------------------------------------------------------------------
#: Why the measurement-based loop refuses an output matrix (and which methods take one).
_MB_NEEDS_FULL_STATE = (
    "mode='mb' (song-mb) needs full-state measurements: its control, eq. (5), steers with the raw "
    "measurements z_ij - z_ii through the state-feedback gain K, which outputs C_j x_j cannot feed. With an "
    "output matrix C use mode='eb' (song-eb: the control uses the estimates, eq. (21)) or "
    "centralized_team_filter.CentralizedTeamFilter"
)

#: The two loops of Song et al.: ``"eb"`` estimation-based (augmented covariance, eqs. (29)-(34)),
#: ``"mb"`` measurement-based (every agent's own covariance, eqs. (14)-(20)).
FILTER_MODES = ("eb", "mb")


class TeamFilter:
    """Every agent's whole-team Kalman filter, for the whole team (and Monte Carlo runs) at once.

    The fast path of Song et al.'s filters: the model was checked when it was built,
    the initial covariance is checked in full here, once; a step checks only what
    changes per call (shapes and mask values) and tests its result for NaN/inf,
    naming the input at fault. The filter holds its state (estimates, covariance,
    gains), the ``Φ`` blocks derived from the topology (recomputed only when the
    topology changes) and its work arrays, reused from step to step: the augmented
    covariance of a large team is updated in place. Filters share nothing, so
    independent filters may run in different threads; one filter object is not for
    concurrent use (its state and work arrays change at every step).

    Parameters
    ----------
    model : TeamFilterModel
        The team model (:func:`~mascore.team_model.team_filter_model`).
    laplacian : (N, N) or (batch, N, N) array_like
        Topology of the control law (eq. (11)): one for all runs, or one per covariance
        batch entry. Change it with the `laplacian` argument of :meth:`predict`.
    x_hat0 : (runs, N m) or (runs, N, N, m) array_like
        Initial estimates, per Monte Carlo run: one common team estimate of all agents,
        or every agent's own (``x_hat0[r, i, j]`` = agent i's estimate of agent j).
    P0 : (m, m) or (m N, m N) array_like, optional
        Covariance of one agent's initial team-estimate error, per agent block or full
        (see :func:`eb_initial_covariance`). Give `P0` or `Sigma0`.
    mode : {"eb", "mb"}
        Estimation-based loop (augmented covariance ``(batch, N M_r, N M_r)``,
        eqs. (29)-(34)) or measurement-based loop (each agent's own covariance
        ``(batch, N, M_r, M_r)``, eqs. (14)-(20)).
    Sigma0 : ndarray, optional
        The initial reduced covariance itself, of the mode's shape (with its batch
        axis); checked in full (symmetric positive semidefinite).
    common : bool
        With `P0`: all agents start from the same estimate (``Σ[0] = 1 1^T ⊗ P0``) or from
        independent ones (``I_N ⊗ P0``).
    exact_control_noise : bool
        ``"mb"`` only: add the correlation between an agent's own measurement noise in its
        control and its posterior error, which eq. (15) neglects (see :func:`mb_predict`).

    Raises
    ------
    ValueError
        Bad shapes, non-finite entries, a covariance that is not symmetric PSD, a
        Laplacian that is not one, batches that do not fit together. With an output
        matrix in the model (partial sensing): ``mode="mb"``, or a topology for which
        system (43) is not observable for some agent (Theorem 1's condition, named).
    TypeError
        `model` is not a :class:`~mascore.team_model.TeamFilterModel`.

    Examples
    --------
    >>> import numpy as np
    >>> from mascore import agents, graphs, rendezvous, sensing
    >>> from mascore import distributed_kf as dkf
    >>> from mascore import team_model
    >>> agent = agents.double_integrator(1, 0.1)                                  # 1-D: [p, v]
    >>> K = rendezvous.rendezvous_gain(0.5, 1.5, 1)
    >>> model = team_model.team_filter_model(agent.A, agent.B, K, 0.01 * np.eye(2), np.eye(2), n_agents=3)
    >>> path = graphs.path_graph(3)
    >>> filt = dkf.TeamFilter(model, graphs.laplacian(path), np.zeros((1, 6)), P0=np.eye(2))
    >>> for k in range(5):
    ...     filt.predict()
    ...     Z, mask = sensing.measure(k, np.zeros((1, 3, 2)), path, np.eye(2))
    ...     filt.update(Z, mask[0])
    >>> filt.Sigma.shape, filt.X_hat.shape                      # (batch, N M_r, N M_r), (runs, N, N, m)
    ((1, 18, 18), (1, 3, 3, 2))
    """

    def __init__(
        self,
        model: TeamFilterModel,
        laplacian: ArrayLike,
        x_hat0: ArrayLike,
        P0: ArrayLike | None = None,
        *,
        mode: str = "eb",
        Sigma0: ArrayLike | None = None,
        common: bool = True,
        exact_control_noise: bool = False,
    ) -> None:
        model = check_model(model)
        if not isinstance(mode, str) or mode not in FILTER_MODES:
            raise ValueError(f"mode must be one of {FILTER_MODES}; got {mode!r}")
        check_flag(common, "common")
        check_flag(exact_control_noise, "exact_control_noise")
        if exact_control_noise and mode != "mb":
            raise ValueError("exact_control_noise applies to the measurement-based loop (mode='mb') only")
        N, m, Mr = model.n_agents, model.m, model.M_r
        L = check_team_laplacian(laplacian, N, undirected=True)
        if mode == "mb" and not model.full_state:
            raise ValueError(_MB_NEEDS_FULL_STATE)
        if not model.full_state:  # partial sensing: every agent's filter must see the whole team (Theorem 1)
            for Lk in np.unique(L.reshape(-1, N, N), axis=0):
                require_observable(model.A, model.BK, np.where(np.eye(N, dtype=bool), 0.0, -Lk), C=model.C)
        X = _float_array(x_hat0, "x_hat0")
        if X.ndim == 2 and X.shape[1] == N * m:
            X = np.broadcast_to(X.reshape(X.shape[0], 1, N, m), (X.shape[0], N, N, m))
        if X.ndim != 4 or X.shape[1:] != (N, N, m) or X.shape[0] == 0:
            raise ValueError(f"Incompatible dimensions of x_hat0; expected (runs, {N * m}) or (runs, {N}, {N}, {m}) "
                             f"but found {X.shape}")
        X = _finite(np.array(X, dtype=float, order="C"), "x_hat0")
        if (P0 is None) == (Sigma0 is None):
            raise ValueError("give the initial covariance as exactly one of P0 (per agent or team) and Sigma0 "
                             "(reduced, with its batch axis)")
        if P0 is not None:
            Sig = eb_initial_covariance(model, P0, common=common)
            if mode == "mb":
                Sig = diagonal_blocks(model, Sig)
            nb = L.shape[0] if L.ndim == 3 else 1
            Sig = np.broadcast_to(Sig, (nb, *Sig.shape[1:])).copy()
        else:
            shape = (None, N * Mr, N * Mr) if mode == "eb" else (None, N, Mr, Mr)
            Sig = np.array(check_covariances(Sigma0, "Sigma0", shape, kron=model.kron), dtype=float, order="C")
        check_batch(L, Sig, "laplacian", "Sigma0" if P0 is None else "P0", X)
        self._init(model, mode, L, X, Sig, None, exact_control_noise)

    @classmethod
    def _from_checked(cls, model, mode, L, X, Sig, KH=None, exact_control_noise=False) -> TeamFilter:
        """A filter on arguments the caller has checked (the plain-array functions).

        The steps never write into `X` (they make new estimates) but may update the covariance in
        place: that one is copied (C-ordered, as the in-place row-block steps need).
        """
        self = cls.__new__(cls)
        self._init(model, mode, L, X, np.array(Sig, dtype=float, order="C"),
                   None if KH is None else np.array(KH, dtype=float), exact_control_noise)
        return self

    def _init(self, model, mode, L, X, Sig, KH, exact_control_noise) -> None:
        if mode == "mb" and not model.full_state:
            raise ValueError(_MB_NEEDS_FULL_STATE)
        self._model, self._mode, self._exact = model, mode, exact_control_noise
        self._H = None if model.full_state else team_output_matrix(model)
        self._X, self._Sig = X, Sig
        N, Mr = model.n_agents, model.M_r
        self._KH = np.zeros((Sig.shape[0], N, Mr, Mr)) if KH is None else KH
        self._work: dict[int, np.ndarray] = {}
        self._Qt = np.kron(np.eye(N), model.Q_r)
        self._set_topology(L)

    # ------------------------------------------------------------------ state

    @property
    def model(self) -> TeamFilterModel:
        """The team model."""
        return self._model

    @property
    def mode(self) -> str:
        """``"eb"`` (estimation-based) or ``"mb"`` (measurement-based)."""
        return self._mode

    @property
    def laplacian(self) -> np.ndarray:
        """The topology in force, ``(N, N)`` or ``(batch, N, N)`` (read-only)."""
        return self._L

    @property
    def X_hat(self) -> np.ndarray:
        """Every agent's team estimate, ``(runs, N, N, m)`` (a copy; :meth:`view` gives the filter's own array)."""
        return self._X.copy()

    @property
    def Sigma(self) -> np.ndarray:
        """The reduced covariance: ``(batch, N M_r, N M_r)`` (``"eb"``) or ``(batch, N, M_r, M_r)`` (``"mb"``).

        A copy, unchanged by later steps; :meth:`view` gives the filter's own array without copying.
        """
        return self._Sig.copy()

    @property
    def KH(self) -> np.ndarray:
        """Reduced ``G_i H_i`` of the last update, ``(batch, N, M_r, M_r)`` (zero before the first update; a copy)."""
        return self._KH.copy()

    def view(self, name: str) -> np.ndarray:
        """The filter's own state array `name`, read-only and not copied (the fast read in a loop).

        Parameters
        ----------
        name : {"X_hat", "Sigma", "KH"}
            The state, as the property of that name.

        Returns
        -------
        ndarray
            A read-only view: the next step may overwrite it in place (copy it to keep it).
            The memory is the filter's own: the flag only guards against a slip (a caller who sets it
            writeable again writes into the filter's state); to change values, take the property (a copy).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> from mascore import team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.view("Sigma").flags.writeable, np.array_equal(filt.view("Sigma"), filt.Sigma)
        (False, True)
        """
        return state_view(self, name, {"X_hat": "_X", "Sigma": "_Sig", "KH": "_KH"})

    def agent_covariances(self) -> np.ndarray:
        """Each agent's own reduced covariance ``Σ̄_i``, ``(batch, N, M_r, M_r)`` (a new array).

        Returns
        -------
        (batch, N, M_r, M_r) ndarray
            The diagonal blocks of the augmented covariance (``"eb"``) or the state itself (``"mb"``).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> from mascore import team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.agent_covariances().shape
        (1, 3, 6, 6)
        """
        return diagonal_blocks(self._model, self._Sig) if self._mode == "eb" else self._Sig.copy()

    def nees(self, X_true: ArrayLike) -> np.ndarray:
        """NEES of every agent's team estimate against the true states (see :func:`team_nees`).

        Parameters
        ----------
        X_true : (runs, N, m) array_like
            True states.

        Returns
        -------
        (runs, N) ndarray
            ``e_i^T Σ_i^{-1} e_i``, chi-square with ``m N`` dof for a consistent filter.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> from mascore import team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2),
        ...                       common=False)
        >>> filt.nees(np.ones((1, 3, 2)))                             # unit errors, unit covariance: 6 each
        array([[6., 6., 6.]])
        """
        model = self._model
        N, m = model.n_agents, model.m
        x = _finite(_float_array(X_true, "X_true"), "X_true")
        if x.shape != (self._X.shape[0], N, m):
            raise ValueError(f"Incompatible dimensions of X_true; expected ({self._X.shape[0]}, {N}, {m}) "
                             f"but found {x.shape}")
        Sig_i = diagonal_blocks(model, self._Sig) if self._mode == "eb" else self._Sig
        return _team_nees(model, x, self._X, Sig_i)

    def f2_cross(self, laplacian: ArrayLike | None = None) -> np.ndarray:
        """``F_2 E[e e_i^T]`` of the current augmented covariance (``"eb"`` only; see :func:`f2_cross`).

        Parameters
        ----------
        laplacian : (N, N) or (batch, N, N) array_like, optional
            The topology defining ``F_2``; default the one in force.

        Returns
        -------
        (batch, N, M_r, M_r) ndarray
            ``F_2 E[e e_i^T]`` per agent.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> from mascore import team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.f2_cross().shape
        (1, 3, 6, 6)
        """
        if self._mode != "eb":
            raise ValueError("f2_cross needs the augmented covariance of the estimation-based loop (mode='eb')")
        L = self._L if laplacian is None else check_team_laplacian(laplacian, self._model.n_agents, undirected=True)
        check_batch(L, self._Sig, "laplacian", "Sigma")
        return _f2_cross(self._model, self._Sig, L)

    # ------------------------------------------------------------------ steps

    def predict(self, laplacian: ArrayLike | None = None) -> None:
        """Prediction of every agent's estimate and of the covariance: eqs. (14)-(15) or (14), (32), (34).

        Parameters
        ----------
        laplacian : (N, N) or (batch, N, N) array_like, optional
            Topology of this step's control (switching topologies); default the one in
            force. It stays in force for the next steps.

        Raises
        ------
        ValueError
            A bad Laplacian, or a prediction that overflows to NaN/inf.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous
        >>> from mascore import distributed_kf as dkf
        >>> from mascore import team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2))
        >>> filt.predict(graphs.laplacian(graphs.ring_graph(3)))   # this step's topology
        >>> bool(np.trace(filt.Sigma[0]) > 18.0)                     # the uncertainty grows
        True
        """
        if laplacian is not None:
            L = check_team_laplacian(laplacian, self._model.n_agents, undirected=True)
            if L.shape != self._L.shape or not np.array_equal(L, self._L):
                check_batch(L, self._Sig, "laplacian", "Sigma", self._X)
                self._set_topology(L)
        if self._mode == "eb":
            self._eb_predict()
            what = "estimation-based prediction"
        else:
            self._mb_predict()
            what = "measurement-based prediction"
        finite_state(what, self._X, self._Sig, diagonal_only=self._mode == "eb" and self._rows)

    def update(self, Z: ArrayLike, mask: ArrayLike) -> None:
        """Every agent's Kalman update with its own measurements: eqs. (16)-(20) and (33).

        Parameters
        ----------
        Z : (runs, N, N, p) array_like
            Measurements (:func:`mascore.sensing.measure`; unsensed entries are ignored);
            ``p = m`` (full states) unless the model has an output matrix ``C``
            (``z_ij = C_j x_j + nu_ij``).
        mask : (N, N) or (batch, N, N) array_like of bool
            Sensing mask (closed neighbourhoods). A mask per run while the covariance is
            shared (batch 1) gives every run its own covariance from then on. A mask must hold
            every agent itself (its diagonal); a subset of the graph's closed neighbourhoods (lost
            links, sensors out of range, each agent sensing only itself) uses what was sensed.
            Theorem 1's observability, checked when the filter is built, is for the full
            neighbourhoods.

        Raises
        ------
        ValueError
            Bad shapes or mask values, or NaN/inf in the result (naming `Z` when it holds them).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous, sensing
        >>> from mascore import distributed_kf as dkf
        >>> from mascore import team_model
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> path = graphs.path_graph(3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(path), np.zeros((1, 6)), P0=np.eye(2))
        >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))
        >>> filt.update(Z, mask[0])
        >>> bool(np.trace(filt.Sigma[0]) < 18.0)                     # the uncertainty shrinks
        True
        """
        model = self._model
        N = model.n_agents
        p = model.p
        Zt = _float_array(Z, "Z")
        if Zt.shape != (*self._X.shape[:3], p):
            raise ValueError(f"Incompatible dimensions of Z; expected {(*self._X.shape[:3], p)} (runs, {N}, {N}, {p}) "
                             f"but found {Zt.shape}")
        S = check_mask(mask, N)
        nb = self._Sig.shape[0]
        if S.shape[0] > 1 and nb == 1 and self._L is not None and self._L.ndim == 2 and S.shape[0] == self._X.shape[0]:
            # masks per run (dropped links): from now on every run has its own covariance
            nb = S.shape[0]
            self._Sig = np.broadcast_to(self._Sig, (nb, *self._Sig.shape[1:])).copy()
            self._KH = np.broadcast_to(self._KH, (nb, *self._KH.shape[1:])).copy()
        if S.shape[0] not in (1, nb):
            raise ValueError(
                f"mask has {S.shape[0]} topologies but the covariance has batch {nb}: the covariance batch must "
                "match the topology batch (pass the topology mask, not the per-run measurement mask)"
            )
        if self._mode == "eb":
            self._eb_update(Zt, S)
            what = "estimation-based update"
        else:
            self._mb_update(Zt, S)
            what = "measurement-based update"
        if not np.isfinite(self._X).all():
            _finite(Zt, "Z")
        finite_state(what, self._X, self._Sig, self._KH)

    # ------------------------------------------------------------------ kernels

    # ------------------------------------------------------------------ one agent (the estimator protocol)

    def agent_inputs(self, Z: ArrayLike, mask: ArrayLike, i: int, run: int = 0) -> tuple[dict, tuple]:
        """Agent i's data of the next step (update with `Z`, then prediction), cut out of this filter's state.

        Measurement-based loop: agent i's own team estimate ``(N, m)`` and reduced covariance
        ``(M_r, M_r)``, its measurements of the team and which agents it measures, the topology
        and the process term of eq. (15) (which depends on the topology and the noise only).
        Estimation-based loop: the step needs the joint covariance of all agents' team
        estimates (Remark 4), so the agent's data is the whole filter's (the team's measurements).

        Parameters
        ----------
        Z : (runs, N, N, p) array_like
            The step's measurements;
            ``p = m`` (full states) unless the model has an output matrix ``C``
            (``z_ij = C_j x_j + nu_ij``).
        mask : (N, N) or (batch, N, N) array_like of bool
            The sensing mask.
        i : int
            The agent.
        run : int
            The Monte Carlo run whose agent i is cut out (measurement-based loop).

        Returns
        -------
        own : dict
            Its data (copies).
        messages : tuple
            Empty: the agents exchange no estimate (Song et al.'s filters use their own measurements only).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous, sensing, team_model
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> path = graphs.path_graph(3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(path), np.zeros((1, 6)), P0=np.eye(2), mode="mb")
        >>> Z, mask = sensing.measure(0, np.zeros((1, 3, 2)), path, np.eye(2))
        >>> own, messages = filt.agent_inputs(Z, mask[0], 1)
        >>> own["X"].shape, own["Sigma"].shape, messages
        ((3, 2), (6, 6), ())
        """
        model = self._model
        N = model.n_agents
        Zt = check_measurements(model, Z, "Z")
        S = check_mask(mask, N)
        if self._mode == "eb":
            return {"Z": Zt.copy(), "mask": S.copy()}, ()
        b = run if self._Sig.shape[0] > 1 else 0
        Lb = self._L if self._L.ndim == 3 else self._L[None]
        L = Lb[run if Lb.shape[0] > 1 else 0]
        return ({"X": self._X[run, i].copy(), "Sigma": self._Sig[b, i].copy(), "z": Zt[run, i].copy(),
                 "d": mask_vec(model, S[run if S.shape[0] > 1 else 0][None])[0, i], "L": np.array(L),
                 "noise": mb_noise(self._model, L[None])[0]}, ())

    def agent_step(self, i: int, own: dict, messages: Sequence) -> tuple[np.ndarray, np.ndarray]:
        """Agent i's update with its own measurements (eqs. (16)-(20)), then its prediction (eqs. (14)-(15)).

        Measurement-based loop: agent i's own team filter alone, the same kernels as
        :meth:`update` and :meth:`predict` on its estimate and covariance. Estimation-based loop:
        the whole filter's step (every agent needs all agents' joint covariance), which advances
        this filter.

        Parameters
        ----------
        i : int
            The agent.
        own, messages
            From :meth:`agent_inputs`.

        Returns
        -------
        X_i, Sigma_i : ndarray
            Its predicted team estimate ``(N, m)`` and reduced covariance ``(M_r, M_r)``; for the
            estimation-based loop the filter's ``X_hat`` and ``Sigma`` (read-only views).

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous, sensing, team_model
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> path = graphs.path_graph(3)
        >>> filt = dkf.TeamFilter(model, graphs.laplacian(path), np.zeros((1, 6)), P0=np.eye(2), mode="mb")
        >>> Z, mask = sensing.measure(1, np.ones((1, 3, 2)), path, np.eye(2))
        >>> X_1, Sigma_1 = filt.agent_step(1, *filt.agent_inputs(Z, mask[0], 1))
        >>> filt.update(Z, mask[0]); filt.predict()                   # the whole team, batched
        >>> bool(np.allclose(X_1, filt.X_hat[0, 1]) and np.allclose(Sigma_1, filt.Sigma[0, 1]))
        True
        """
        if self._mode == "eb":
            self.update(own["Z"], own["mask"])
            self.predict()
            return self.view("X_hat"), self.view("Sigma")
        model = self._model
        N, m, mr, Mr = model.n_agents, model.m, model.m_r, model.M_r
        X, Sig, L = own["X"], own["Sigma"], own["L"]
        KH = masked_gain(Sig, own["d"], model.R_r)  # eq. (19): its own measurements
        X = X + (KH @ (own["z"] - X).reshape(Mr, model.kron)).reshape(N, m)
        Sig = joseph(Sig, KH, model.R_r)  # eq. (20)
        X = X @ model.A.T - (L @ X) @ model.BK.T  # eq. (14): F_1 X̂_i
        T = F1_rows(model, Sig.reshape(N, mr, Mr), L).reshape(Mr, Mr).T
        Sig = F1_rows(model, T.reshape(N, mr, Mr), L).reshape(Mr, Mr) + own["noise"]  # eq. (15)
        return X, symmetric_part(Sig)

    def messages(self, i: int = 0) -> tuple[Message, ...]:
        """What an agent sends per step: nothing (its filter uses its own measurements only).

        Parameters
        ----------
        i : int
            The agent (the same for all).

        Returns
        -------
        tuple of Message
            Empty.

        Examples
        --------
        >>> import numpy as np
        >>> from mascore import agents, graphs, rendezvous, team_model
        >>> from mascore import distributed_kf as dkf
        >>> agent = agents.double_integrator(1, 0.1)
        >>> model = team_model.team_filter_model(agent.A, agent.B, rendezvous.rendezvous_gain(0.5, 1.5, 1),
        ...                                      0.01 * np.eye(2), np.eye(2), n_agents=3)
        >>> dkf.TeamFilter(model, graphs.laplacian(graphs.path_graph(3)), np.zeros((1, 6)), P0=np.eye(2)).messages()
        ()
        """
        return ()

    def _set_topology(self, L: np.ndarray | None) -> None:
        """Store the (checked) topology and, for the estimation-based loop, its ``Φ`` blocks.

        ``None``: a filter made for one update (the plain-array update functions) needs none.
        """
        model = self._model
        C = model.n_agents * model.M_r
        self._rows = C > DENSE_MAX
        self._L, self._blocks = None, None
        if L is None:
            return
        self._L = frozen_copy(L)
        if self._mode == "eb":
            Lb = self._L if self._L.ndim == 3 else self._L[None]
            self._blocks = [phi_blocks(model, Lk, self._rows) for Lk in Lb]

    def _buffer(self, slot: int, size: int) -> np.ndarray:
        """A flat work array of at least `size` floats, owned by this filter (grown when needed)."""
        a = self._work.get(slot)
        if a is None or a.size < size:
            a = self._work[slot] = np.empty(size)
        return a[:size]

    def _mb_predict(self) -> None:
        """Eqs. (14)-(15) in tensor form (and the exact control-noise correlation if asked)."""
        model, L, Sig = self._model, self._L, self._Sig
        N, Mr, mr = model.n_agents, model.M_r, model.m_r
        self._X = F1_means(model, self._X, L)
        Lb = L if L.ndim == 3 else L[None]
        # F_1 Σ_i F_1^T via the tensor form
        T = F1_rows(model, Sig.reshape(*Sig.shape[:2], N, mr, Mr), Lb[:, None])
        T = np.swapaxes(T.reshape(*Sig.shape), -1, -2)
        P = F1_rows(model, T.reshape(*Sig.shape[:2], N, mr, Mr), Lb[:, None]).reshape(*Sig.shape)
        # eq. (15): (I ⊗ BK) E[nu_bar nu_bar^T] (I ⊗ BK)^T + Q (block diagonal)
        Rr = model.R_r.reshape(N, mr, N, mr)
        P = P + mb_noise(self._model, Lb)[:, None]
        if self._exact:
            KH = self._KH
            # E[e_i nu_bar_i^T] = -KH_i R (L_i ⊗ I)^T, column block i of E[e_i nu_bar^T]
            RL = np.einsum("lakc,bik->bilac", Rr, Lb).reshape(Lb.shape[0], N, Mr, mr)  # R (L_i ⊗ I)^T
            Xc = -(KH @ RL)  # (batch, N, Mr, mr)
            F1Xc = F1_rows(model, Xc.reshape(*Xc.shape[:2], N, mr, mr), Lb[:, None]).reshape(Xc.shape)
            corr = -(F1Xc @ model.BK_r.T)  # -F1 E[e_i nu_bar_i^T] BK^T, (batch, N, Mr, mr)
            full = np.zeros((*corr.shape[:2], Mr, N, mr))
            full[:, np.arange(N), :, np.arange(N), :] = np.moveaxis(corr, 1, 0)
            full = full.reshape(*corr.shape[:2], Mr, Mr)
            P = P + full + np.swapaxes(full, -1, -2)
        self._Sig = symmetric_part(P)

    def _mb_update(self, Z: np.ndarray, S: np.ndarray) -> None:
        """Eqs. (16)-(20), Joseph form, all agents and runs at once."""
        model, Sig = self._model, self._Sig
        KH = masked_gain(Sig, mask_vec(model, S), model.R_r)
        self._X = apply_gain(model, self._X, Z, KH)
        self._Sig, self._KH = joseph(Sig, KH, model.R_r), KH

    def _eb_predict(self) -> None:
        """``Σ^- = Φ Σ Φ^T + (1 1^T) ⊗ 𝒬``: dense products for a small team, else row blocks in place.

        The row blocks: :func:`mascore._team_kernels.eb_predict_rows`.
        """
        model, Sig = self._model, self._Sig
        N, Mr = model.n_agents, model.M_r
        self._X = F1_means(model, self._X, self._L)
        blocks, Qt = self._blocks, self._Qt
        one = len(blocks) == 1
        if not self._rows:  # a small team: two dense products are cheapest
            out = np.empty_like(Sig)
            for b in range(Sig.shape[0]):
                Phi = blocks[0 if one else b][0]
                out[b] = Phi @ Sig[b] @ Phi.T
                out[b].reshape(N, Mr, N, Mr)[...] += Qt[None, :, None, :]
            self._Sig = out
            return
        for b in range(Sig.shape[0]):
            eb_predict_rows(model, Qt, Sig[b], blocks[0 if one else b], self._buffer)

    def _eb_update(self, Z: np.ndarray, S: np.ndarray) -> None:
        """Eqs. (16)-(20) and (33) on the augmented covariance.

        ``Ψ = blockdiag(I - G_i H_i)`` and ``G_i H_i = W_i E_i^T`` has rank ``q_i``
        (``E_i`` selects the observed entries ``idx_i``), so tile ``(i, i')`` of
        ``Ψ Σ Ψ^T`` is ``Σ_ii' - W_i V_ii' - Σ[i, idx_i'] W_i'^T`` with
        ``V_ii' = Σ[idx_i, i'] - Σ[idx_i, idx_i'] W_i'^T`` (all ``V`` computed once from the
        ``N q`` observed rows): ``O(N^2 M_r^2 q)`` work instead of the ``O(N^2 M_r^3)`` of dense
        products, one pass over Σ^- (in place) with one small batched product per row block.
        """
        if self._H is not None:
            return self._eb_update_outputs(Z, S)
        model = self._model
        d = mask_vec(model, S)
        KH = masked_gain(self._prior_blocks(), d, model.R_r)  # G_i H_i, eqs. (17), (19)
        if not self._rows:  # a small team: dense products of all row blocks at once are cheapest
            KRK = KH @ model.R_r @ np.swapaxes(KH, -1, -2)  # eq. (33): + δ_ij G_i H_i R H_i^T G_i^T
            self._Sig = block_sandwich(self._Sig, KH, KRK)
        else:
            self._update_rows(KH, observed_indices(d)[0])  # observed entries (batch, N, q)
        self._X = apply_gain(model, self._X, Z, KH)
        self._KH = KH

    def _eb_update_outputs(self, Z: np.ndarray, S: np.ndarray) -> None:
        """Eqs. (16)-(20) and (33) with partial sensing ``H_i = D_i blockdiag(C_j)``.

        ``Ψ = blockdiag(I - G_i H_i)``, ``Σ = Ψ Σ^- Ψ^T + blockdiag(G_i R G_i^T)``: the same
        recursion as the full-state update, with the gains of :func:`mascore._team_kernels.output_gain`;
        dense products for a small team, else the rank-q row blocks on the ``q`` outputs each agent senses.
        """
        model, H = self._model, self._H
        G, KH, GRG = output_gain(model, H, self._prior_blocks(), S)  # eqs. (17), (19)
        if not self._rows:
            self._Sig = symmetric_part(block_sandwich(self._Sig, KH, GRG))  # eq. (33): + δ_ij G_i R G_i^T
        else:
            idx, _ = observed_indices(np.repeat(S, model.C_r.shape[1], axis=-1).astype(float))  # (b, N, q) outputs
            self._update_rows(G, idx, H[idx])  # H[idx] (b, N, q, Mr): the rows of H each agent senses
        self._X = apply_output_gain(model, H, self._X, Z, G)
        self._KH = KH

    def _prior_blocks(self) -> np.ndarray:
        """The agents' blocks ``Σ_i^-`` of the augmented covariance, ``(batch, N, M_r, M_r)`` (a work array: row blocks)."""
        model, Sig = self._model, self._Sig
        if not self._rows:
            return diagonal_blocks(model, Sig)
        N, Mr, nb = model.n_agents, model.M_r, Sig.shape[0]
        blocks = Sig.reshape(nb, N, Mr, N, Mr)
        diag = self._buffer(1, nb * N * Mr * Mr).reshape(nb, N, Mr, Mr)
        for i in range(N):
            diag[:, i] = blocks[:, i, :, i, :]
        return diag

    def _update_rows(self, gain: np.ndarray, idx: np.ndarray, H_sel: np.ndarray | None = None) -> None:
        """Every covariance's update by rank-q row blocks (:func:`mascore._team_kernels.eb_update_rows`).

        `gain` ``(b, N, M_r, M_r or p N)``: its columns at `idx` ``(b, N, q)`` (observed entries or outputs;
        padding: zero columns) are ``W``.
        """
        q = idx.shape[-1]
        W = np.take_along_axis(gain, np.broadcast_to(idx[..., None, :], (*gain.shape[:-1], q)), axis=-1)  # (b, N, Mr, q)
        Wt = np.swapaxes(W, -1, -2)
        Rq = self._model.R_r[idx[..., :, None], idx[..., None, :]]  # R on the observed entries (padding: W is zero)
        for b in range(self._Sig.shape[0]):
            bi = b if idx.shape[0] > 1 else 0  # one mask for all covariances
            eb_update_rows(self._Sig[b], idx[bi], W[b], Wt[b], Rq[bi], None if H_sel is None else H_sel[bi],
                           self._buffer)

# ----------------------------------------------------------------------------
# the methods of the team task (mascore.compare's own-state rendezvous, mascore.agent_cost)
# ----------------------------------------------------------------------------

#: Why Song et al.'s filters do not apply elsewhere (the tables show it).
_SONG_NOT_APPLICABLE = MappingProxyType({
    "target": "estimates the agents' own states in a rendezvous loop; there is no common target",
    "localization": "needs absolute measurements of the neighbours' states (eq. (2)); here they are relative",
})
_SONG_MB_NOT_APPLICABLE = MappingProxyType({
    **_SONG_NOT_APPLICABLE,
    "position": "steers with its raw measurements of the neighbours (eq. (5)), which must be full states",
})
_SONG_EB_NOT_APPLICABLE = _SONG_NOT_APPLICABLE  # it takes positions only through C = [I 0]


def _song_filter(mode: str):
    """``build(team, x_hat0)``: Song et al.'s filter of the team scenario, every agent from the common estimate."""
    def build(team, x_hat0: np.ndarray) -> TeamFilter:
        C = None if team.sensing == "full" else team.C  # full states: the paper's model itself, bit for bit
        model = team_filter_model(team.A, team.B, team.K, team.Q_filter, team.R, team.N, C=C)
        runs, N, m = x_hat0.shape  # one common initial estimate; links dropping per run split the covariance
        return TeamFilter(model, team.laplacian, x_hat0.reshape(runs, N * m), team.P0, mode=mode)
    return build


METHODS = (
    MethodSpec("song-mb", ("team",), _song_filter("mb"),
               lambda n, q, d, N: (0.0, filter_cost("measurement-forwarding", n=N * n, q=n, degree=round(d)).flops),
               {"team": ("O(N^3 n^3): its own covariance of the whole team", "O(N^2 n^2)")},
               lambda n, q, d, N: float((N * n) ** 2 + N * n), _SONG_MB_NOT_APPLICABLE, position=3),
    MethodSpec("song-eb", ("team",), _song_filter("eb"), lambda n, q, d, N: (0.0, float(4 * (N * N * n) ** 3)),
               {"team": ("O(N^6 n^3): the joint covariance of all team estimates (dense)", "O(N^4 n^2)")},
               lambda n, q, d, N: float((N * N * n) ** 2), _SONG_EB_NOT_APPLICABLE, whole_filter=True, position=4,
               max_agents={"team": (32, "its joint covariance of all agents' team estimates holds (2 N^2)^2 floats "
                                        "(per axis): 0.5 GB at N = 64, 8.6 GB at 128")}),
)
