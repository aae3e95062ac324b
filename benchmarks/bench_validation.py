"""What the input checks cost in a long filter run: a 10^4-step predict + update loop of one Kalman
filter (n = 4 states, 2 measurements) through the public, checked :func:`mascore.kalman.predict` and
:func:`mascore.kalman.update` against the same loop through the private, unchecked kernels
(``kalman._predict``, ``kalman._update``) that compute the same numbers.

A second row times :func:`mascore.kalman.run_filter`, the run-level entry point, which checks its
arguments once and loops on the kernels.

The constant matrices (F, Q, H, R) are checked once per distinct value, and a mean or covariance that
a filter step returned is recognised when it comes back, so a long run pays a few dictionary look-ups
and one finiteness test of each result per step (issue 14 target: checked within 5 % of unchecked).
The two loops are timed in alternation (interleaved repeats, so that a change in machine load hits
both) and the medians are compared."""

import time

import numpy as np
import pandas as pd

from mascore import agents, kalman

N_STEPS = 10_000
REPEAT = 9


def _problem():
    model = agents.double_integrator(2, 0.1)  # n = 4 states
    H = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
    Q, R = 0.01 * np.eye(4), 0.25 * np.eye(2)
    z = np.random.default_rng(0).standard_normal((N_STEPS, 2))  # measurements drawn once, outside the timing
    return model.A, Q, H, R, z


def filter_loop(predict, update, F, Q, H, R, z):
    """``N_STEPS`` predict + update steps of one filter; returns the final mean and covariance."""
    x, P = np.zeros(4), 10.0 * np.eye(4)
    for k in range(z.shape[0]):
        x, P = predict(x, P, F, Q)
        x, P = update(x, P, z[k], H, R)
    return x, P


def compare(checked, unchecked, repeat: int = REPEAT) -> dict:
    """Median wall-clock seconds of the two loops, timed in alternation after one warm-up each."""
    F, Q, H, R, z = _problem()
    runs = {"checked": checked, "unchecked": unchecked}
    results = {name: filter_loop(*fns, F, Q, H, R, z) for name, fns in runs.items()}  # warm-up
    same = all(np.array_equal(a, b) for a, b in zip(results["checked"], results["unchecked"]))
    times: dict[str, list[float]] = {name: [] for name in runs}
    for r in range(repeat):
        order = list(runs) if r % 2 == 0 else list(runs)[::-1]
        for name in order:
            start = time.perf_counter()
            filter_loop(*runs[name], F, Q, H, R, z)
            times[name].append(time.perf_counter() - start)
    med = {name: float(np.median(t)) for name, t in times.items()}
    return {"median_s": med, "identical": same}


def run_level(repeat: int = REPEAT) -> dict:
    """Median seconds of :func:`mascore.kalman.run_filter` (checked once) against the kernel loop."""
    F, Q, H, R, z = _problem()
    x0, P0 = np.zeros(4), 10.0 * np.eye(4)
    xs, _ = kalman.run_filter(x0, P0, z, F, Q, H, R)
    same = np.array_equal(xs[-1], filter_loop(kalman._predict, kalman._update, F, Q, H, R, z)[0])
    times: dict[str, list[float]] = {"run_filter": [], "unchecked": []}
    for r in range(repeat):
        for name in (("run_filter", "unchecked") if r % 2 == 0 else ("unchecked", "run_filter")):
            start = time.perf_counter()
            if name == "run_filter":
                kalman.run_filter(x0, P0, z, F, Q, H, R)
            else:
                filter_loop(kalman._predict, kalman._update, F, Q, H, R, z)
            times[name].append(time.perf_counter() - start)
    return {"median_s": {k: float(np.median(v)) for k, v in times.items()}, "identical": same}


def run() -> pd.DataFrame:
    """Rows: public steps in a loop (checked every call), run_filter (checked once), and the kernels."""
    rows = []
    for label, res in (("predict + update, checked every step", compare(
            (kalman.predict, kalman.update), (kalman._predict, kalman._update))),
            ("run_filter, checked once", run_level())):
        med = res["median_s"]
        checked = next(k for k in med if k != "unchecked")
        rows.append({"loop": label, "steps": N_STEPS, "us_per_step": 1e6 * med[checked] / N_STEPS,
                     "unchecked_us_per_step": 1e6 * med["unchecked"] / N_STEPS,
                     "ratio_to_unchecked": med[checked] / med["unchecked"], "same_numbers": res["identical"]})
    return pd.DataFrame(rows)


if __name__ == "__main__":
    table = run()
    print(table.to_string(index=False))
    print("target: a long run with checks within 5 % of the unchecked kernels (ratio <= 1.05)")
