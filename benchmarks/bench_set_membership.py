"""Time per set-membership filter step (correction + prediction, Bhattacharjee and Subbarao 2021):
the SDPs of eqs. (6)-(8) (Clarabel via cvxpy, compiled once with Parameters) against their closed-form
twins, for one agent per call and for a batch of agents x Monte Carlo runs in one call.

Per agent-step the batched closed form is thousands of times faster than the SDPs. With one agent per
call the ratio is much smaller: the call is then a fixed sequence of small NumPy operations on 2 x 2
arrays (input checks, Cholesky tests of positive definiteness, the consistency test, the closed forms),
each with a fixed per-call cost that does not shrink with the data, against two cvxpy/Clarabel solves.
The system matrices are checked once, in a :class:`mascore.set_membership.SetMembershipModel` built
before the timing (the compiled SDPs are kept in a `programs` dict passed to every call), so the
per-call checks are the ones on the changing data (centre, shape, measurement, input); the plain-array functions would check the
matrices (and build the SDPs) on every call."""


import numpy as np
import pandas as pd

from benchmarks.timing import median_time
from mascore import set_membership as smf
from mascore.papers import bhattacharjee2021 as paper


def _step(model, c, P, y, method, programs=None):
    c, P, _ = model.correct(c, P, y, method=method, programs=programs)
    return model.predict(c, P, u=np.zeros_like(c), method=method, programs=programs)


def run() -> pd.DataFrame:
    s = paper.ROWS[0]
    rng = np.random.default_rng(0)
    c1, P1 = np.array([50.0, -50.0]), paper.P0
    y1 = np.array([50.4])
    nb = 400  # 100 runs x 4 agents, the Table 1 study's batch
    cb = c1 + rng.random((nb, 2))
    Pb = np.broadcast_to(P1, (nb, 2, 2))
    yb = cb[:, :1] + rng.uniform(-0.05, 0.05, (nb, 1))
    model = smf.SetMembershipModel(A=paper.A, G=paper.G_DIST, C=paper.C, D=paper.D, Q=s.Q, R=s.R, B=paper.B)
    programs: dict = {}  # the compiled SDPs, kept by the caller across the timed calls
    cases = [
        ("sdp", 1, lambda: _step(model, c1, P1, y1, "sdp", programs), 7),
        ("closed_form", 1, lambda: _step(model, c1, P1, y1, "closed_form"), 51),
        ("closed_form", nb, lambda: _step(model, cb, Pb, yb, "closed_form"), 21),
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
