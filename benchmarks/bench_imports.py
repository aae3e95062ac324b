"""Import time of the core modules in a fresh interpreter (target: under 0.3 s each).

Each import runs in its own ``python -c`` process, so nothing is cached between them;
the median of five processes is reported, next to the optional packages the import
loaded (none for the core: cvxpy, matplotlib, pandas, tqdm and dask are extras).
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys

import pandas as pd

MODULES = ("mascore", "mascore.kalman", "mascore.graphs", "mascore.set_membership", "mascore.consensus",
           "mascore.distributed_kf", "mascore.team_model", "mascore.lqr", "mascore.observers", "mascore.papers.song2023")
HEAVY = ("cvxpy", "matplotlib", "pandas", "scipy.stats", "networkx", "dask")
REPEATS = 5

_PROBE = """
import json, sys, time
t = time.perf_counter()
import {module}
dt = time.perf_counter() - t
print(json.dumps([dt, sorted(m for m in {heavy!r} if m in sys.modules)]))
"""


def _once(module: str) -> tuple[float, list[str]]:
    code = _PROBE.format(module=module, heavy=HEAVY)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    seconds, loaded = json.loads(out.strip().splitlines()[-1])
    return seconds, loaded


def run() -> pd.DataFrame:
    rows = []
    for module in MODULES:
        samples = [_once(module) for _ in range(REPEATS)]
        rows.append({
            "module": module,
            "import_s": round(statistics.median(s for s, _ in samples), 3),
            "target_s": 0.3 if module in ("mascore.kalman", "mascore.graphs", "mascore.set_membership") else None,
            "optional_packages_loaded": ", ".join(samples[0][1]) or "none",
        })
    return pd.DataFrame(rows)


if __name__ == "__main__":
    print(run().to_string(index=False))
