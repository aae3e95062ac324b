"""One benchmark for every estimator: accuracy, consistency, messages and CPU, side by side.

**The team task.** ``N`` identical planar double integrators (``dt = 0.1`` s,
state ``[p_x, p_y, v_x, v_y]``) run the rendezvous law of Song et al. eq. (4),
``u_i = -K sum_j a_ij (x_i - x_j)``, on a ring (or a geometric graph,
:func:`benchmark_graph`, or the switching proximity topology, :func:`switching_graphs`,
where the Vlahakis observer does not apply: :data:`SWITCHING_NOT_APPLICABLE`), with each agent's *views* of
itself and of its neighbours in place of the true states. Agent ``i`` measures
its own state and, on every link of the graph, its neighbours' states,
``z_ij = x_j + nu_ij`` (Song et al. eq. (2)). The methods differ only in how an
agent forms its views:

=================== ========================================================================
``centralized``     one Kalman filter over the whole team with every measurement (the bound)
``local``           a Kalman filter per agent on its own state from its own measurement; the
                    neighbours' views are their broadcast estimates (no cooperation)
``forwarding``      a Kalman filter per agent on its own state from its own measurement and its
                    neighbours' measurements of it, sent over one hop: on this task it *is* the
                    centralized filter (the own state is the case where cooperation cannot help)
``song-mb``         Song et al.'s whole-team filter on every agent, control on measurements
                    (eqs. (5), (8)-(20))
``song-eb``         Song et al.'s estimation-based filter, control on the agent's own team
                    estimate (eqs. (21), (29)-(34))
``vlahakis``        the LQR-dual distributed observer (Vlahakis and Halikias), designed per
                    axis in continuous time on the filter's Q and discretized (forward Euler),
                    with own and relative position measurements (its design needs m < n);
                    ``vlahakis-phi0`` and ``vlahakis-phi1``: other points of its optimal Phi set
``set-membership``  the closed-form set-membership filter of Bhattacharjee and Subbarao on
                    each agent's own state, given an ellipsoidal noise bound: on full-state
                    sensing (H = I) its correction returns the measurement; with positions
                    only it filters (see below); ``set-membership-c90`` and ``-c99999``: its
                    confidence knob (:data:`SM_CONFIDENCE`)
=================== ========================================================================

**Position-only sensing** (``sensing="position"``, the study ``position``): the same task
with every measurement a position, ``z_ij = [I 0] x_j + nu_ij`` (the set-membership paper's
partial output), for every method: the centralized, local and forwarding Kalman filters on
positions, the Vlahakis observer (already on positions), the set-membership filter with
``C = [I 0]``, whose set's size is reported (``set_size``); Song et al.'s filters measure full
neighbour states and are listed as not applicable (:data:`POSITION_NOT_APPLICABLE`).

**The shared task** (Ren et al.): every agent holds a prior estimate of one
common 2-D quantity, with its own covariance; the methods are the central
fusion (the bound), no fusion, average consensus and Ren et al.'s discrete
Kalman consensus at the paper's Q = Omega = 0.1 (``ren-kc``) and at 0
(``ren-kc-q0``), over the ring, a geometric graph or a switching one.

**Every knob within its recipe** (:data:`KNOBS`, :func:`knob_table`): Ren et al.'s Q = Omega in
{0, 0.1, 0.3, 0.6, 1}, the Vlahakis gain Phi over its optimal interval, the set-membership
confidence, the consensus steps L of CI, ICF and HCMCI in {1, 2, 5} and the graph's diameter,
and HCMCI's novelty weight at N and at its consistency-safe value, each at N = 8 on the ring,
with a verdict per setting.

**The common target** (:func:`target_model`) and **cooperative localization**
(:func:`localization_model`): the field's filters of :mod:`mascore.fusion`
(:data:`TARGET_METHODS`) on a target that no agent observes alone, and on the
team's positions from relative measurements and two anchors, over the ring, a geometric
graph or the switching topology (in localization the graph is the sensing too: a step's
relative measurements are those of its current links); the papers'
methods that do not apply are listed with the reason
(:data:`TARGET_NOT_APPLICABLE`, :data:`LOCALIZATION_NOT_APPLICABLE`).

**Links of the target and localization tasks** (:data:`LINK_STUDIES`, :mod:`mascore.fusion_links`): packet
loss per link and step (a lost message is not received; each filter fuses what arrived, with its weights on
the links that delivered), loss per direction and run (:data:`DIRECTION_LOSS_METHODS`: a message lost alone,
its weight on the receiver's own pair), one-step latency for every network filter of the tables (:data:`LATENCY_METHODS`,
:func:`latency_model`; the others in :data:`LATENCY_NOT_MODELLED`, with the reason) and send-on-delta messages
for CI and ICF at one consensus step (:data:`SEND_ON_DELTA_METHODS`,
floats counted as sent; with latency too), at N = 8 on the ring.

**Robustness axes**: link drop-outs (each link's measurement and message lost with
probability ``dropout`` at each step; a lost message leaves the last received
view in place), noise distribution (Gaussian, bounded uniform, Student-t with 3
degrees of freedom, all with the same covariance) and a wrong process-noise
covariance in the filters (``q_scale`` times the true one).

**Statistics** (``mascore.compare.stats``): accuracy is the ratio of RMS errors over a cell's
runs to the centralized filter's on the same runs, with a 95 % paired bootstrap interval;
consistency is the ANEES with the two-sided 95 % chi-square bounds of a consistent filter. The
claims (:func:`compare_claims`, one function each in :data:`mascore.compare.verdicts.CLAIMS` and
:data:`~mascore.compare.verdicts.LINK_CLAIMS`) were
written from seed blocks 0-1 and are decided on the held-out blocks 2-3 where the sweep has them,
by intervals against bands: inside holds, outside fails, across an edge is undecided.

Every random number of a cell comes from :func:`mascore.sweep.cell_seed` on the
seed axes :data:`SEED_AXES`, which leave out the method, the drop-out probability
and ``q_scale``: all methods see the same noise (common random numbers), and the
drop-out patterns are nested (a link lost at ``p = 0.1`` is also lost at ``0.3``).
"""

from __future__ import annotations

import importlib

__all__ = [
    "GRAPHS",
    "SEED_AXES",
    "SETTINGS",
    "SHARED_METHODS",
    "TARGET_METHODS",
    "target_methods",
    "TARGET_NOT_APPLICABLE",
    "DIRECTION_LOSS_METHODS",
    "LATENCY_METHODS",
    "LATENCY_NOT_MODELLED",
    "check_link_cell",
    "latency_methods",
    "latency_model",
    "latency_not_modelled",
    "LINK_STUDIES",
    "LOSS_METHODS",
    "SEND_ON_DELTA_METHODS",
    "link_options",
    "link_summary",
    "link_table",
    "send_on_delta_table",
    "plot_send_on_delta",
    "TEAM_METHODS",
    "make_estimator",
    "team_setup",
    "ALL_TEAM_METHODS",
    "VLAHAKIS_PHI",
    "REN_Q",
    "ALL_SHARED_METHODS",
    "FUSION_KNOB_METHODS",
    "KNOBS",
    "Knob",
    "knob_table",
    "knob_variants",
    "per_agent_costs",
    "CORE_METHODS",
    "BenchmarkSettings",
    "CompareResult",
    "benchmark_graph",
    "cell_cost",
    "cell_group",
    "compare_claims",
    "differing_claims",
    "anees_bounds",
    "rms_ratio",
    "fitted_slopes",
    "floats_per_step",
    "grid_cells",
    "LOCALIZATION_NOT_APPLICABLE",
    "headline",
    "interval_table",
    "ratio_text",
    "localization_model",
    "localization_riccati",
    "node_cost",
    "node_costs",
    "NODE_ORDER",
    "POSITION_METHODS",
    "POSITION_NOT_APPLICABLE",
    "SENSINGS",
    "SM_CONFIDENCE",
    "plot_cost",
    "plot_pareto",
    "plot_robustness",
    "plot_scale",
    "run",
    "run_cell",
    "run_cells",
    "run_compare",
    "simulate_shared",
    "simulate_team",
    "simulate_target",
    "scale_limits",
    "stored_summary",
    "summarize",
    "switching_graphs",
    "SWITCHING_GRAPHS",
    "SCALE_SIZES",
    "SCALE_GRAPHS",
    "SCALE_GRAPH_LIMITS",
    "SHARED_DATA_MAX",
    "SWITCHING_NOT_APPLICABLE",
    "target_cost",
    "target_filter",
    "target_model",
    "vlahakis_profile",
]

#: The submodule of each name of the comparison (imported on first use: ``import mascore.compare`` is cheap).
_NAMES = {
    'benchmark': (
        'ALL_SHARED_METHODS', 'ALL_TEAM_METHODS', 'BenchmarkSettings', 'CORE_METHODS', 'FUSION_KNOB_METHODS', 'GRAPHS',
        'KNOBS', 'Knob', 'NOISES', 'POSITION_METHODS',
        'POSITION_NOT_APPLICABLE', 'REN_Q', 'SEED_AXES', 'SENSINGS', 'SETTINGS', 'SHARED_METHODS', 'SM_CONFIDENCE',
        'SHOWN', 'SWITCHING_GRAPHS', 'SWITCHING_NOT_APPLICABLE', 'TEAM_METHODS', 'VLAHAKIS_PHI', '_MAX_SCALE',
        'benchmark_graph', 'bound_scale',
        'check_cell', 'check_n_agents', 'check_run', 'draw_noise', 'floats_per_step', 'knob_variants', 'mean_degree',
        'switching_graphs'
    ),
    'team': (
        'TeamEstimator', 'TeamTask', '_C_POS', '_accumulate', '_own_blocks', '_vlahakis_gains', 'make_estimator',
        'simulate_team', 'team_setup', 'vlahakis_profile'
    ),
    'shared': (
        'simulate_shared',
    ),
    'target': (
        'DIRECTION_LOSS_METHODS', 'LATENCY_METHODS', 'LATENCY_NOT_MODELLED', 'LINK_STUDIES',
        'LOCALIZATION_NOT_APPLICABLE', 'LOSS_METHODS',
        'SEND_ON_DELTA_METHODS', 'TARGET_METHODS', 'TARGET_NOT_APPLICABLE', '_localization_switching',
        'check_link_cell', 'latency_methods', 'latency_model', 'latency_not_modelled', 'link_options', 'localization_model',
        'localization_riccati', 'simulate_target', 'target_cost',
        'target_filter', 'target_methods', 'target_model'
    ),
    'grid': (
        'CompareResult', 'cell_cost', 'cell_group', 'grid_cells', 'link_summary', 'run', 'run_cell',
        'run_cells', 'run_compare', 'scale_limits', 'stored_summary', 'SCALE_SIZES', 'SCALE_GRAPHS',
        'SCALE_GRAPH_LIMITS', 'SHARED_DATA_MAX'
    ),
    'tables': (
        'CPU_COLUMN', 'NEAR_BOUND', '_position_headline', 'fitted_slopes', 'headline', 'interval_table', 'knob_table',
        'link_table', 'position_only_kf_rmse', 'ratio_text', 'send_on_delta_table'
    ),
    'verdicts': (
        'CLAIMS', 'HELD_OUT', 'LINK_CLAIMS', 'WRITTEN_FROM', 'compare_claims', 'deciding_runs', 'differing_claims'
    ),
    'summary': (
        'summarize',
    ),
    'stats': (
        'BOOTSTRAP_RESAMPLES', 'BOOTSTRAP_SEED', 'Interval', 'NEES_DIMENSION', 'anees_bounds', 'mean_interval',
        'rms_ratio'
    ),
    'plots': (
        '_concat', '_order', '_plain_ticks', '_plt', 'plot_cost', 'plot_pareto', 'plot_robustness', 'plot_scale',
        'plot_send_on_delta'
    ),
    'cost': (
        'NODE_ORDER', 'node_cost', 'node_costs', 'per_agent_costs'
    ),
}
_WHERE = {name: module for module, names in _NAMES.items() for name in names}


def __getattr__(name: str):
    if name in _WHERE:
        module = importlib.import_module(f"{__name__}.{_WHERE[name]}")
        value = getattr(module, name)
        if name in vars(module):  # not one read from the specs when asked (those stay current)
            globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
