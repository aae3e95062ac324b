"""What the input checks cost in a long filter run: a 10^4-step predict + update loop of one Kalman
filter (n = 4 states, 2 measurements) through the public, checked :func:`mascore.kalman.predict` and
:func:`mascore.kalman.update` against the same loop through the private, unchecked kernels
(``kalman._predict``, ``kalman._update``) that compute the same numbers.

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


def run() -> pd.DataFrame:
    res = compare((kalman.predict, kalman.update), (kalman._predict, kalman._update))
    med = res["median_s"]
    rows = [
        {"loop": name, "steps": N_STEPS, "median_s_per_run": t, "us_per_step": 1e6 * t / N_STEPS,
         "ratio_to_unchecked": t / med["unchecked"], "same_numbers": res["identical"]}
        for name, t in med.items()
    ]
    return pd.DataFrame(rows)


if __name__ == "__main__":
    table = run()
    print(table.to_string(index=False))
    ratio = table.loc[table.loop == "checked", "ratio_to_unchecked"].iloc[0]
    print(f"checked / unchecked = {ratio:.3f} (target <= 1.05)")
