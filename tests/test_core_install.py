"""The lean core: what `pip install mascore` (no extras) needs, loads and says when an extra is missing.

Runs in the project's environment and, by `make test-min`, in a fresh one holding only the
core's minimum versions (numpy 1.26, scipy 1.11, networkx 3.2), where the optional packages
are really absent.
"""

from __future__ import annotations

import importlib.metadata
import json
import subprocess
import sys
import textwrap

import pytest

#: Modules a user of the filters, consensus and closed forms imports (no extra needed).
CORE_MODULES = (
    "agents", "graphs", "noise", "kalman", "sensing", "consensus", "rendezvous", "flocking",
    "synchronization", "lqr", "team_model", "distributed_kf", "centralized_team_filter", "team_observability",
    "distributed_ekf", "sensor_network", "fusion", "fusion_cost", "ellipsoids", "set_membership",
)
#: Optional packages (and slow-to-import parts of required ones) that the core must not load.
HEAVY = ("cvxpy", "clarabel", "matplotlib", "pandas", "tqdm", "dask", "distributed", "scipy.stats", "networkx")


def _run(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=120)


def test_core_dependencies_are_numpy_scipy_networkx():
    requires = importlib.metadata.requires("mascore") or []
    core = sorted({r.split(";")[0].split(">")[0].split("=")[0].split("<")[0].strip().lower()
                   for r in requires if "extra ==" not in r})
    assert core == ["networkx", "numpy", "scipy"]


def test_core_modules_load_no_optional_package():
    """Importing the core and running a closed-form filter loads none of the heavy packages."""
    proc = _run(f"""
        import json, sys, numpy as np
        import importlib
        for m in {CORE_MODULES!r}:
            importlib.import_module("mascore." + m)
        from mascore import set_membership as sm
        c, P, L = sm.correct(np.zeros(2), np.eye(2), np.array([0.1]), [[1.0, 0.0]], [[1.0]], [[1.0]],
                             method="closed_form")
        assert np.isfinite(P).all()
        print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))
    """)
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout.strip().splitlines()[-1]) == []


@pytest.mark.parametrize(
    ("blocked", "statement", "extra"),
    [
        ("matplotlib", "import mascore.plotting", "plot"),
        ("pandas", "import mascore.papers", "plot"),
        ("clarabel", "import mascore.observers", "sdp"),  # its LMIs are Clarabel programs; cvxpy is imported
                                                         # only where a cvxpy program is solved
        ("cvxpy", "from mascore import set_membership as sm; import numpy as np; "
                  "sm.correct(np.zeros(2), np.eye(2), np.array([0.1]), [[1.0, 0.0]], [[1.0]], [[1.0]], method='sdp')",
         "sdp"),
    ],
)
def test_missing_extra_names_the_extra_to_install(blocked, statement, extra):
    proc = _run(f"""
        import sys
        sys.modules[{blocked!r}] = None  # as if not installed
        {statement}
    """)
    assert proc.returncode != 0
    last = proc.stderr.strip().splitlines()[-1]
    assert "ModuleNotFoundError" in last and f"pip install 'mascore[{extra}]'" in last, proc.stderr[-2000:]
