"""mascore's kernels against the library a user would pick instead, and against the FLOP floor.

Every row is a ratio measured in this one run, with the repeats of the two sides interleaved
(medians), on one BLAS thread: Kalman predict + update against filterpy (one filter, and a batch
of 100 filters against a loop of filterpy filters), ``lqr``/``dlqr`` against python-control,
the distributed-observer design against the time Clarabel itself spends in it, and the rows of
the Song filters (:mod:`benchmarks.bench_song2023_flocking`, :mod:`benchmarks.bench_song2023`).

``python -m benchmarks`` (``make bench``) prints the table and writes it to
``results/benchmarks/bench_peers.csv``; ``python -m benchmarks.bench_peers --snapshot`` also
writes the committed snapshot ``benchmarks/data/peers.csv`` (with ``peers_machine.json``) that the
book's Performance page shows. Timings are reported, never asserted.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd

from benchmarks.timing import cpu_model

DATA = Path(__file__).resolve().parent / "data"


def _interleaved(fa: Callable[[], object], fb: Callable[[], object], repeat: int, number: int = 1) -> tuple[float, float]:
    """Median seconds per call of `fa` and of `fb`, their repeats interleaved (one warm-up each)."""
    fa(), fb()
    ta, tb = [], []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fa()
        ta.append((time.perf_counter() - t0) / number)
        t0 = time.perf_counter()
        for _ in range(number):
            fb()
        tb.append((time.perf_counter() - t0) / number)
    return float(np.median(ta)), float(np.median(tb))


def _row(work: str, size: str, ours: float, reference: str, ref: float, target: str, met: bool) -> dict:
    return {"work": work, "size": size, "ours_ms": 1e3 * ours, "reference": reference, "reference_ms": 1e3 * ref,
            "ratio": ours / ref, "target": target, "met": bool(met)}


def _spd(rng: np.random.Generator, n: int) -> np.ndarray:
    G = rng.standard_normal((n, n)) / np.sqrt(n)
    return G @ G.T + np.eye(n)


def kalman_rows() -> list[dict]:
    """One predict + update against filterpy's, and a batch of 100 against a loop of filterpy filters."""
    from filterpy.kalman import KalmanFilter

    from mascore import kalman

    rows = []
    rng = np.random.default_rng(0)
    for n in (4, 16, 64):
        q = n // 2
        F = np.eye(n) + 0.01 * rng.standard_normal((n, n))
        Q, R, H = 0.01 * _spd(rng, n), _spd(rng, q), rng.standard_normal((q, n))
        x0, P0, z = np.zeros(n), _spd(rng, n), rng.standard_normal(q)
        kf = KalmanFilter(dim_x=n, dim_z=q)
        kf.F, kf.Q, kf.H, kf.R, kf.x, kf.P = F, Q, H, R, x0.copy(), P0.copy()
        model = kalman.LinearGaussianModel(F, Q, H, R)  # checked once, here
        state = [*model.check_state(x0, P0)]

        def ours():  # a filter loop through the public functions on the checked model
            x, P = kalman.predict(state[0], state[1], model)
            state[:] = kalman.update(x, P, z, model)

        def peer():
            kf.predict()
            kf.update(z)

        t_ours, t_peer = _interleaved(ours, peer, repeat=15, number=50 if n < 64 else 10)
        rows.append(_row("Kalman predict + update, one filter", f"n = {n}", t_ours, "filterpy", t_peer,
                         "<= 1.05x filterpy (checks on)", t_ours <= 1.05 * t_peer))
    for n in (16, 64):
        q, B = n // 2, 100
        F = np.eye(n) + 0.01 * rng.standard_normal((n, n))
        Q, R, H = 0.01 * _spd(rng, n), _spd(rng, q), rng.standard_normal((q, n))
        X0 = rng.standard_normal((B, n))
        P0 = np.broadcast_to(_spd(rng, n), (B, n, n)).copy()
        Z = rng.standard_normal((B, q))
        model = kalman.LinearGaussianModel(F, Q, H, R)
        filters = []
        for _ in range(B):
            kf = KalmanFilter(dim_x=n, dim_z=q)
            kf.F, kf.Q, kf.H, kf.R = F, Q, H, R
            filters.append(kf)

        def ours_batch():
            x, P = kalman.predict(X0, P0, model)
            return kalman.update(x, P, Z, model)

        def peer_loop():
            for i, kf in enumerate(filters):
                kf.x, kf.P = X0[i].copy(), P0[i].copy()
                kf.predict()
                kf.update(Z[i])

        t_ours, t_peer = _interleaved(ours_batch, peer_loop, repeat=7)
        target = ">= 5x faster than the loop" if n == 16 else "reported"
        rows.append(_row("batched Kalman, 100 filters (per filter)", f"n = {n}", t_ours / B, "loop of filterpy",
                         t_peer / B, target, t_peer >= 5 * t_ours if n == 16 else True))
    return rows


def _stabilizable_pair(rng: np.random.Generator, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    return rng.standard_normal((n, n)) / np.sqrt(n), rng.standard_normal((n, m))


def lqr_rows() -> list[dict]:
    """``lqr`` and ``dlqr`` against python-control's, with the gains compared to 1e-10."""
    import control

    from mascore import lqr

    rows = []
    rng = np.random.default_rng(1)
    for n, m in ((6, 2), (50, 5)):
        A, B = _stabilizable_pair(rng, n, m)
        Q, R = np.eye(n), np.eye(m)
        K, _, _ = lqr.lqr(A, B, Q, R)
        K_ref, _, _ = control.lqr(A, B, Q, R)
        same = np.allclose(K, K_ref, rtol=1e-10, atol=1e-10 * np.abs(K_ref).max())
        t_ours, t_peer = _interleaved(lambda: lqr.lqr(A, B, Q, R), lambda: control.lqr(A, B, Q, R), repeat=15)
        rows.append(_row("lqr", f"n = {n}", t_ours, "control.lqr", t_peer,
                         "<= 1.1x, same K to 1e-10", same and t_ours <= 1.1 * t_peer))
        Ad = np.eye(n) + 0.1 * A
        t_ours, t_peer = _interleaved(lambda: lqr.dlqr(Ad, B, Q, R), lambda: control.dlqr(Ad, B, Q, R), repeat=15)
        Kd, _, _ = lqr.dlqr(Ad, B, Q, R)
        Kd_ref, _, _ = control.dlqr(Ad, B, Q, R)
        same = np.allclose(Kd, Kd_ref, rtol=1e-10, atol=1e-10 * np.abs(Kd_ref).max())
        rows.append(_row("dlqr", f"n = {n}", t_ours, "control.dlqr", t_peer, "reported (same K to 1e-10)", same))
    return rows


def observer_rows(sizes: tuple[int, ...] = (5, 20, 100, 300)) -> list[dict]:
    """The Vlahakis observer design on a ring against the time Clarabel itself spends solving."""
    from mascore import graphs, observers

    A, Bbar, C = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
    solve_seconds: list[float] = []
    original = observers.solve

    def timed_solve(problem, what, options=None):
        value = original(problem, what, options)
        solve_seconds.append(float(problem.solver_stats.solve_time or 0.0))
        return value

    rows = []
    observers.solve = timed_solve
    try:
        for N in sizes:
            ring = graphs.ring_graph(N)
            repeat = 3 if N <= 100 else 1
            totals, solver = [], []
            for _ in range(repeat):
                solve_seconds.clear()
                t0 = time.perf_counter()
                observers.distributed_observer(A, Bbar, C, 10.0 * np.eye(1), 5.0 * np.eye(1), np.eye(1), ring)
                totals.append(time.perf_counter() - t0)
                solver.append(sum(solve_seconds))
            total, inner = float(np.median(totals)), float(np.median(solver))
            target = {100: "<= 3x the solver's time", 300: "< 500 ms"}.get(N, "reported")
            met = {100: total <= 3 * inner, 300: total < 0.5}.get(N, True)
            rows.append(_row("Vlahakis observer design, ring", f"N = {N}", total, "Clarabel solve inside", inner,
                             target, met))
    finally:
        observers.solve = original
    return rows


def song_rows() -> list[dict]:
    """The rows of the Song filters (EKF against its FLOP floor, linear filter structured against plain)."""
    from benchmarks import bench_song2023, bench_song2023_flocking

    return bench_song2023_flocking.peer_rows() + bench_song2023.peer_rows()


def run() -> pd.DataFrame:
    """Every row of the comparison, in one run."""
    rows = kalman_rows() + lqr_rows() + observer_rows() + song_rows()
    return pd.DataFrame(rows)


def machine() -> dict:
    """Where and with what the table was measured."""
    import scipy

    cpu = cpu_model()
    return {"date": time.strftime("%Y-%m-%d"), "cpu": cpu, "cores": os.cpu_count(),
            "python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS") or os.environ.get("OMP_NUM_THREADS") or "unset"}


def write_snapshot(table: pd.DataFrame) -> None:
    """The committed snapshot the Performance page reads."""
    DATA.mkdir(exist_ok=True)
    table.to_csv(DATA / "peers.csv", index=False, float_format="%.6g")
    (DATA / "peers_machine.json").write_text(json.dumps(machine(), indent=2) + "\n")


if __name__ == "__main__":  # pragma: no cover
    result = run()
    print(result.to_string(index=False))
    if "--snapshot" in sys.argv[1:]:
        write_snapshot(result)
