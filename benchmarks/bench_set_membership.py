"""Time per set-membership filter step (correction + prediction, Bhattacharjee and Subbarao 2021):
the SDPs of eqs. (6)-(8) (Clarabel via cvxpy, compiled once with Parameters) against their closed-form
twins, for one agent per call and for a batch of agents x Monte Carlo runs in one call.

Per agent-step the batched closed form is thousands of times faster than the SDPs. With one agent per
call the ratio is much smaller: the call is then a fixed sequence of small NumPy operations on 2 x 2
arrays (input checks, Cholesky tests of positive definiteness, the consistency test, the closed forms),
each with a fixed per-call cost that does not shrink with the data, against two cvxpy/Clarabel solves.
The system matrices are validated once per distinct value (cached), so the per-call checks are the
ones on the changing data (centre, shape, measurement, input)."""


import numpy as np
import pandas as pd

from benchmarks.timing import median_time
from mascore import set_membership as smf
from mascore.papers import bhattacharjee2021 as paper


def _step(c, P, y, method, Q, R):
    c, P, _ = smf.correct(c, P, y, paper.C, paper.D, R, method=method)
    return smf.predict(c, P, paper.A, paper.G_DIST, Q, B=paper.B, u=np.zeros_like(c), method=method)


def run() -> pd.DataFrame:
    s = paper.ROWS[0]
    rng = np.random.default_rng(0)
    c1, P1 = np.array([50.0, -50.0]), paper.P0
    y1 = np.array([50.4])
    nb = 400  # 100 runs x 4 agents, the Table 1 study's batch
    cb = c1 + rng.random((nb, 2))
    Pb = np.broadcast_to(P1, (nb, 2, 2))
    yb = cb[:, :1] + rng.uniform(-0.05, 0.05, (nb, 1))
    cases = [
        ("sdp", 1, lambda: _step(c1, P1, y1, "sdp", s.Q, s.R), 7),
        ("closed_form", 1, lambda: _step(c1, P1, y1, "closed_form", s.Q, s.R), 51),
        ("closed_form", nb, lambda: _step(cb, Pb, yb, "closed_form", s.Q, s.R), 21),
    ]
    rows = []
    for method, batch, fn, rep in cases:
        t = median_time(fn, repeat=rep)
        rows.append({"method": method, "agents_per_call": batch, "median_s_per_call": t,
                     "s_per_agent_step": t / batch})
    df = pd.DataFrame(rows)
    sdp = df.loc[df.method == "sdp", "s_per_agent_step"].iloc[0]
    df["speedup_vs_sdp"] = sdp / df["s_per_agent_step"]
    return df


if __name__ == "__main__":
    print(run().to_string(index=False))
