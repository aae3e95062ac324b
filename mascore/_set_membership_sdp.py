"""The SDPs of the set-membership filter, eqs. (6)-(8), built with cvxpy ``Parameter`` s.

Kept apart from :mod:`mascore.set_membership` so that its closed form runs without
importing cvxpy: this module is imported only when ``method="sdp"``.

No module-level cache: :func:`correction_sdp` and :func:`prediction_sdp` build a new program
each call; its owner (one call of the filter, or the caller's ``programs`` dict, never the
model) reuses it step after step. A program holds its parameter values and solution between
``__call__`` and return, so one object must not be solved from two threads at once.
"""

from __future__ import annotations

import numpy as np

from ._optional import require
from ._solver import CVXPY_PURPOSE, LMI_EPS, solve
from ._validation import symmetric_part

__all__ = ["correction_sdp", "prediction_sdp"]

cp = require("cvxpy", CVXPY_PURPOSE)


class _CorrectionSDP:
    """Eqs. (6)-(7), compiled once for sizes (n, p, v)."""

    def __init__(self, n: int, p: int, nv: int) -> None:
        self.P = cp.Variable((n, n), symmetric=True, name="P_kk")
        self.L = cp.Variable((n, p), name="L_k")
        self.tau = cp.Variable(2, name="tau")
        self.E = cp.Parameter((n, n), name="E_pred")
        self.CE = cp.Parameter((p, n), name="CE_pred")
        self.D = cp.Parameter((p, nv), name="D")
        self.Rinv = cp.Parameter((nv, nv), symmetric=True, name="R_inv")
        Pi = cp.hstack([np.zeros((n, 1)), self.E - self.L @ self.CE, -self.L @ self.D])  # eq. (7)
        t1, t2 = self.tau[0], self.tau[1]
        Theta = cp.bmat([
            [cp.reshape(1 - t1 - t2, (1, 1), order="F"), np.zeros((1, n)), np.zeros((1, nv))],
            [np.zeros((n, 1)), t1 * np.eye(n), np.zeros((n, nv))],
            [np.zeros((nv, 1)), np.zeros((nv, n)), t2 * self.Rinv],
        ])
        M = cp.bmat([[self.P, -Pi], [-Pi.T, Theta]])  # minus the matrix of eq. (6)
        self.problem = cp.Problem(
            cp.Minimize(cp.trace(self.P)),
            [0.5 * (M + M.T) >> 0, self.P >> LMI_EPS * np.eye(n), self.tau >= 0],
        )
        assert self.problem.is_dcp(dpp=True)

    def __call__(self, E, C, D, Rinv, where, options=None):
        self.E.value = E
        self.CE.value = C @ E
        self.D.value = D
        self.Rinv.value = symmetric_part(Rinv)
        solve(self.problem, where, options)
        P = self.P.value
        return symmetric_part(P), np.asarray(self.L.value)


class _PredictionSDP:
    """Eq. (8), compiled once for sizes (n, w)."""

    def __init__(self, n: int, nw: int) -> None:
        self.P = cp.Variable((n, n), symmetric=True, name="P_pred")
        self.tau = cp.Variable(2, name="tau")
        self.AE = cp.Parameter((n, n), name="AE_corr")
        self.G = cp.Parameter((n, nw), name="G_disturbance")
        self.Qinv = cp.Parameter((nw, nw), symmetric=True, name="Q_inv")
        Pi = cp.hstack([np.zeros((n, 1)), self.AE, self.G])
        t3, t4 = self.tau[0], self.tau[1]
        Psi = cp.bmat([
            [cp.reshape(1 - t3 - t4, (1, 1), order="F"), np.zeros((1, n)), np.zeros((1, nw))],
            [np.zeros((n, 1)), t3 * np.eye(n), np.zeros((n, nw))],
            [np.zeros((nw, 1)), np.zeros((nw, n)), t4 * self.Qinv],
        ])
        M = cp.bmat([[self.P, -Pi], [-Pi.T, Psi]])
        self.problem = cp.Problem(
            cp.Minimize(cp.trace(self.P)),
            [0.5 * (M + M.T) >> 0, self.P >> LMI_EPS * np.eye(n), self.tau >= 0],
        )
        assert self.problem.is_dcp(dpp=True)

    def __call__(self, AE, G, Qinv, where, options=None):
        self.AE.value = AE
        self.G.value = G
        self.Qinv.value = symmetric_part(Qinv)
        solve(self.problem, where, options)
        P = self.P.value
        return symmetric_part(P)


def correction_sdp(n: int, p: int, nv: int) -> _CorrectionSDP:
    """A new compiled correction SDP, eqs. (6)-(7), for state size `n`, `p` outputs, `nv` disturbances."""
    return _CorrectionSDP(n, p, nv)


def prediction_sdp(n: int, nw: int) -> _PredictionSDP:
    """A new compiled prediction SDP, eq. (8), for state size `n` and `nw` disturbances."""
    return _PredictionSDP(n, nw)
