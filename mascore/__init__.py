"""mascore: distributed estimation and cooperative control of multi-agent systems.

A reproducible companion to Song et al. (2023), Ren, Beard and Kingston (2005),
Bhattacharjee and Subbarao (2021) and Vlahakis and Halikias. The concept
modules hold general algorithms; :mod:`mascore.papers` holds each paper's
exact scenarios.

Submodules are imported on first use (``mascore.observers`` works after a bare
``import mascore``), so that importing the package does not pay for cvxpy
unless an SDP is actually needed.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__version__ = "0.1.0"

#: Public submodules, grouped by concept.
SUBMODULES = (
    # shared building blocks
    "agents", "graphs", "kalman", "noise", "plotting", "settings", "claims", "ledger", "reproduce",
    # consensus and cooperative control
    "consensus", "consensus_filters", "rendezvous", "flocking", "synchronization", "lqr",
    # estimation
    "estimation", "sensing", "team_model", "distributed_kf", "centralized_team_filter", "team_observability",
    "distributed_ekf", "sensor_network", "fusion", "fusion_cost", "own_state", "ellipsoids", "set_membership",
    "observers", "network_observer", "riccati",
    # comparing the methods, sweeps on Dask
    "compare", "agent_cost", "sweep",
    # errors
    "exceptions",
    # the papers' scenarios
    "papers",
)

#: Names exported from the package itself: the exceptions (cheap: no optional dependency).
EXCEPTIONS = ("ConsensusBreakdownError", "DivergenceError", "IsolatedAgentError", "RiccatiError", "SolverError")

__all__ = ["__version__", *EXCEPTIONS, *SUBMODULES]


def __getattr__(name: str) -> ModuleType | type:
    if name in EXCEPTIONS:
        from . import exceptions

        return getattr(exceptions, name)
    if name in SUBMODULES:
        module = importlib.import_module(f".{name}", __name__)
        globals()[name] = module
        return module
    raise AttributeError(f"module 'mascore' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(SUBMODULES))
