"""One estimation-based filter step (Song et al. 2023, eqs. (14), (29)-(34), (16)-(20)) against N.

Compares the structured recursion through the public object users call
(:class:`mascore.distributed_kf.TeamFilter` on a checked model: ``predict()`` +
``update(Z, mask)``, what :func:`mascore.rendezvous.simulate_rendezvous` runs at
every step: sparse ``F_1``, ``F_2`` in the cross-covariance recursion, the
Kronecker factor of the double integrator, rank-q updates one row block at a
time, in place in the filter's own arrays, with the per-step shape and mask
checks and the finiteness test of the result) with the plain one written
straight from the equations (``mascore._kf_reference.plain_estimation_based_kernel``:
dense ``F_1``, ``F_2``, ``H_i``, ``G_i`` and a loop over agent pairs, no checks).
Both advance the full augmented covariance of all ``N`` agents' whole-team
estimates (size ``2nN^2``) and all N estimates for one topology (a ring,
Q = R = I); the repeats of the two are interleaved, medians.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pandas as pd

from mascore import _kf_reference as ref
from mascore import distributed_kf as dkf
from mascore import team_model
from mascore.graphs import laplacian, ring_graph
from mascore.papers.song2023 import setup
from mascore.sensing import measure, stacked_measurement

SIZES = (4, 8, 16, 32, 64)
#: Targets of issue 16 by N.
TARGETS = {32: ("structured >= 30x faster", lambda speedup: speedup >= 30.0), 64: ("measured", lambda speedup: True)}


def _case(N: int):
    s = setup(N)
    noise = np.eye(2 * s.n)
    model = team_model.team_filter_model(s.A, s.B, s.K, noise, noise, N)
    rng = np.random.default_rng(N)
    adj = ring_graph(N)
    L = laplacian(adj)
    X_hat = rng.normal(size=(1, N, N, 2 * s.n))
    Z, S = measure(rng, rng.normal(size=(1, N, 2 * s.n)), adj, noise)
    team = dkf.TeamFilter(model, L, X_hat, s.P0(), common=False)  # P0 checked here, once
    structured = (team, Z, S[0])
    z = [stacked_measurement(Z[0], S[0], i) for i in range(N)]
    plain = (X_hat[0].reshape(N, -1), None, s.A, model.BK, noise, model.R, adj, z, adj)
    return structured, plain, model


def _structured(team: dkf.TeamFilter, Z: np.ndarray, S: np.ndarray) -> float:
    """One step of the public filter object (the state advances; every step costs the same)."""
    t = time.perf_counter()
    team.predict()
    team.update(Z, S)
    return time.perf_counter() - t


def _plain(args, Sig_full) -> float:
    t = time.perf_counter()
    ref.plain_estimation_based_kernel(args[0], Sig_full, *args[2:])
    return time.perf_counter() - t


def _memory_gb() -> float:
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 1e9
    except (ValueError, OSError, AttributeError):  # pragma: no cover
        return np.inf


def run(sizes=SIZES) -> pd.DataFrame:
    """Milliseconds per estimator step for each N, structured vs plain (plain: 1 repeat at N = 64)."""
    rows = []
    for N in sizes:
        (team, Z, S), plain, model = _case(N)
        Sig_full = team_model.expand_covariance(team.Sigma[0], model.kron)  # the initial covariance, full size
        need_gb = 5 * Sig_full.nbytes / 1e9  # the plain step holds about five augmented covariances
        plain_repeat = 0 if need_gb > 0.6 * _memory_gb() else (5 if N <= 16 else (3 if N <= 32 else 1))
        repeat = max(plain_repeat, 5 if N <= 32 else 3)
        _structured(team, Z, S)  # warm-up
        ts, tp = [], []
        for r in range(repeat):
            ts.append(_structured(team, Z, S))
            if r < plain_repeat:
                tp.append(_plain(plain, Sig_full))
        del Sig_full
        structured_ms = 1e3 * float(np.median(ts))
        plain_ms = 1e3 * float(np.median(tp)) if tp else np.nan
        rows.append({"work": "Song linear filter step (estimation-based), ring", "N": N,
                     "structured_ms": structured_ms, "plain_ms": plain_ms, "speedup": plain_ms / structured_ms,
                     "plain_repeats": len(tp)})
    return pd.DataFrame(rows)


def peer_rows(table: pd.DataFrame | None = None) -> list[dict]:
    """The rows of issue 16's table in the common shape (reference: the plain recursion)."""
    table = run() if table is None else table
    out = []
    for row in table.itertuples():
        text, ok = TARGETS.get(row.N, ("reported", lambda speedup: True))
        out.append({"work": "Song linear filter, structured vs plain", "size": f"N = {row.N}",
                    "ours_ms": float(row.structured_ms), "reference": "plain recursion",
                    "reference_ms": float(row.plain_ms), "ratio": float(row.structured_ms / row.plain_ms),
                    "target": text, "met": bool(np.isfinite(row.speedup) and ok(row.speedup))})
    return out


if __name__ == "__main__":  # pragma: no cover
    print(run().to_string(index=False))
