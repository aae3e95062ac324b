"""Timings of Kalman consensus (Ren, Beard and Kingston 2005): the Fig. 1 run, the theorem demos, batched
Monte Carlo, continuous time between switches (one run and a batch of noisy paths), and one vector step on a
larger team."""

import numpy as np
import pandas as pd

from benchmarks.timing import median_time
from mascore import consensus as cs
from mascore.papers import ren2005 as ren


def run() -> pd.DataFrame:
    rng = np.random.default_rng(0)
    G100 = cs.random_pairings(100, 1, rng)[0]
    xi100, P100 = rng.standard_normal((100, 3)), np.broadcast_to(np.eye(3), (100, 3, 3))
    G_mc = cs.random_pairings(10, 100, rng, size=1000)
    xi0, P0 = ren.fig1_initial(True)
    topo = cs.SwitchingTopology.periodic(ren.union_sequence(), 1.0, 30.0)

    def fig1_and_theorems():
        ren.fig1(1)
        ren.switching_demo(ren.union_sequence())
        ren.switching_demo(ren.no_union_sequence())
        cs.kalman_consensus_continuous(ren.THEOREM["xi0"], np.ones(6), ren.fig2_graph(), ren.THEOREM["t_final"],
                                       0.1, 0.1)

    cases = {
        "Fig. 1, both columns (10 agents, 100 steps)": (lambda: ren.fig1(1), 5),
        "Fig. 1 + theorem demos (2 switching sequences x 2 time bases, fixed Fig. 2)": (fig1_and_theorems, 3),
        "1000 schedules x 100 steps, batched (scalar)": (
            lambda: cs.kalman_consensus_discrete(np.broadcast_to(xi0, (1000, 10)), np.broadcast_to(P0, (1000, 10)),
                                                 G_mc, 0.1, 0.1), 3),
        "continuous, 6 agents, 30 switches (RK45)": (
            lambda: cs.kalman_consensus_continuous(ren.THEOREM["xi0"], np.ones(6), topo, 30.0, 0.1, 0.1), 3),
        "continuous with noise, Euler-Maruyama 3000 steps": (
            lambda: cs.kalman_consensus_continuous(ren.THEOREM["xi0"], np.ones(6), topo, 30.0, 0.1, 0.1,
                                                   rng=0, dt=1e-2), 3),
        "100 noisy paths batched, Euler-Maruyama 3000 steps": (
            lambda: cs.kalman_consensus_continuous(np.broadcast_to(ren.THEOREM["xi0"], (100, 6)), np.ones((100, 6)),
                                                   topo, 30.0, 0.1, 0.1, rng=0, dt=1e-2), 3),
        "one step, 100 agents, m = 3": (lambda: cs.kalman_consensus_step(xi100, P100, G100, 0.1, 0.1), 7),
    }
    rows = [{"case": name, "median_s": median_time(fn, repeat=rep)} for name, (fn, rep) in cases.items()]
    return pd.DataFrame(rows)
