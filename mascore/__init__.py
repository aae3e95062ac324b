"""mascore: distributed estimation and cooperative control of multi-agent systems.

A reproducible companion to Song et al. (2023), Ren, Beard and Kingston (2005),
Bhattacharjee and Subbarao (2021) and Vlahakis and Halikias. The concept
modules hold general algorithms; :mod:`mascore.papers` holds each paper's
exact scenarios.
"""

from . import agents, graphs, kalman, ledger, noise

__version__ = "0.1.0"

__all__ = ["__version__", "agents", "graphs", "kalman", "ledger", "noise"]
