"""What the input checks cost in a long filter run: a 10^4-step predict + update loop of one Kalman
filter (n = 4 states, 2 measurements), three ways, against the same loop on the bare kernels
(``kalman._predict_one``, ``kalman._update_one``: the arithmetic alone, no check at all):

* on a :class:`mascore.kalman.LinearGaussianModel`, checked once when it is built: each call checks
  the shapes of the state and measurement and that the result is finite, about 0.5 us a call (target:
  within 10 % of the bare kernels at this smallest size, where that overhead weighs most; the
  comparison with filterpy is in :mod:`benchmarks.bench_peers`);
* with plain arrays, ``predict(x, P, F, Q)`` / ``update(x, P, z, H, R)``: every argument checked in
  full on every call (eigenvalues of P, Q and R each step; reported, the price of not building a model);
* :func:`mascore.kalman.run_filter`, the run-level entry point (model and initial state checked once).

Every loop gives the same numbers, bit for bit (checked here). The loops are timed in alternation
(interleaved repeats, so that a change in machine load hits all of them) and the medians compared.
Timings are reported, never asserted."""

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


def _loops() -> dict:
    """name -> function() running the N_STEPS loop and returning the final (x, P)."""
    F, Q, H, R, z = _problem()
    model = kalman.LinearGaussianModel(F, Q, H, R)
    I = np.eye(4)

    def kernels():
        x, P = np.zeros(4), 10.0 * np.eye(4)
        for k in range(N_STEPS):
            x, P, _ = kalman._predict_one(x, P, F, Q, None, None)
            x, P, _ = kalman._update_one(x, P, z[k], H, R, I)
        return x, P

    def on_model():
        x, P = model.check_state(np.zeros(4), 10.0 * np.eye(4))
        for k in range(N_STEPS):
            x, P = kalman.predict(x, P, model)
            x, P = kalman.update(x, P, z[k], model)
        return x, P

    def plain_arrays():
        x, P = np.zeros(4), 10.0 * np.eye(4)
        for k in range(N_STEPS):
            x, P = kalman.predict(x, P, F, Q)
            x, P = kalman.update(x, P, z[k], H, R)
        return x, P

    def run_filter():
        xs, Ps = kalman.run_filter(np.zeros(4), 10.0 * np.eye(4), z, F, Q, H, R)
        return xs[-1], Ps[-1]

    return {"kernels": kernels, "on_model": on_model, "plain_arrays": plain_arrays, "run_filter": run_filter}


LABELS = {"on_model": "predict + update on a LinearGaussianModel (checked once)",
          "plain_arrays": "predict + update on plain arrays (checked in full every call)",
          "run_filter": "run_filter (checked once)"}


def run(repeat: int = REPEAT) -> pd.DataFrame:
    """One row per checked loop: microseconds per step, and the ratio to the bare kernels."""
    loops = _loops()
    results = {name: fn() for name, fn in loops.items()}  # warm-up, and the numbers to compare
    ref = results["kernels"]
    times: dict[str, list[float]] = {name: [] for name in loops}
    for r in range(repeat):
        for name in (list(loops) if r % 2 == 0 else list(loops)[::-1]):
            start = time.perf_counter()
            loops[name]()
            times[name].append(time.perf_counter() - start)
    med = {name: float(np.median(t)) for name, t in times.items()}
    return pd.DataFrame([
        {"loop": LABELS[name], "steps": N_STEPS, "us_per_step": 1e6 * med[name] / N_STEPS,
         "kernels_us_per_step": 1e6 * med["kernels"] / N_STEPS, "ratio_to_kernels": med[name] / med["kernels"],
         "same_numbers": all(np.array_equal(a, b) for a, b in zip(results[name], ref))}
        for name in LABELS])


if __name__ == "__main__":
    table = run()
    print(table.to_string(index=False))
    print("target: the loop on a model within 10 % of the bare kernels (ratio <= 1.10)")
