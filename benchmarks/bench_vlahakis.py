"""Design time of the LQR-dual distributed observer (Vlahakis and Halikias, Sec. 4.2) against N.

The Laplacian eigen-decomposition (eqs. (43)-(55)) splits the LMI program (62) into one small block
per distinct eigenvalue (a ring of N agents has floor(N/2) + 1), so the design scales with the number
of distinct eigenvalues, not with (N n)^3. For comparison: the dense network Riccati equation (40),
which gives the centralized optimum only.
"""

import numpy as np
import pandas as pd
import scipy.linalg as sla

from benchmarks.timing import median_time
from mascore import graphs, observers
from mascore.papers import vlahakis as vl

E = vl.EXAMPLE1


def _dense_are(N: int) -> None:
    Lap = graphs.laplacian(graphs.ring_graph(N))
    A_net = np.kron(np.eye(N), E["A"])
    W = np.kron(np.eye(N), E["Bbar"] @ E["Bbar"].T)
    C_net = np.kron(np.eye(N), E["C"])
    Q_net = np.kron(np.eye(N), [[E["Q1"]]]) + np.kron(Lap, [[5.0]])
    sla.solve_continuous_are(A_net.T, C_net.T, W, np.linalg.inv(Q_net))


def run() -> pd.DataFrame:
    rows = []
    for N, repeat in ((5, 5), (20, 3), (100, 1)):
        adj = graphs.ring_graph(N)
        design = observers.distributed_observer(E["A"], E["Bbar"], E["C"], E["Q1"], 5.0, E["R"], adj,
                                                reading=vl.L_READING)
        rows.append({
            "case": f"observer design (LMI (62) by modes), ring N = {N}",
            "N": N,
            "lmi_blocks": N // 2 + 1,
            "median_s": median_time(lambda adj=adj: observers.distributed_observer(
                E["A"], E["Bbar"], E["C"], E["Q1"], 5.0, E["R"], adj, reading=vl.L_READING), repeat=repeat),
            "Phi": design.Phi.item(),
            "hurwitz": design.hurwitz,
        })
        rows.append({"case": f"dense network ARE (40), {2 * N} states", "N": N, "lmi_blocks": 0,
                     "median_s": median_time(lambda N=N: _dense_are(N), repeat=max(repeat, 3)),
                     "Phi": np.nan, "hurwitz": np.nan})
    return pd.DataFrame(rows)


if __name__ == "__main__":
    print(run().to_string(index=False))
