"""Tests of the Vlahakis and Halikias study (Example 1, Figs. 1-2): registry, run, figures, ledger claims."""

import dataclasses
import json

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mascore import observers  # noqa: E402
from mascore.ledger import format_number, show_claims  # noqa: E402
from mascore.papers import vlahakis as v  # noqa: E402
from mascore.reproduce import results_dir  # noqa: E402

E = v.EXAMPLE1
REQUIRED = [
    "vlahakis/example1-L", "vlahakis/example1-phi-q2-5", "vlahakis/example1-J-q2-5",
    "vlahakis/example1-phi-q2-25", "vlahakis/example1-J-q2-25", "vlahakis/example1-hurwitz",
    "vlahakis/fig2-faster-than-fig1", "vlahakis/structure-eq13",
]
#: The documented state of the reproduction: L only through the mixed convention, Phi and J not at all
#: (with the printed L), the printed Phi optimal but not determined as printed; the rest holds.
EXPECTED_VERDICTS = {
    "example1-L": "does-not-reproduce",
    "example1-L-mixed-convention": "holds",
    "example1-phi-q2-5": "does-not-reproduce",
    "example1-J-q2-5": "does-not-reproduce",
    "example1-phi-q2-25": "does-not-reproduce",
    "example1-J-q2-25": "does-not-reproduce",
    "example1-printed-phi-optimal-as-printed": "holds",
    "example1-hurwitz": "holds",
    "fig2-faster-than-fig1": "holds",
    "observer-cost-ordering": "holds",
    "structure-eq13": "holds",
    "bottom-up-cost-bounded": "holds",
}


@pytest.fixture(scope="module")
def result():
    """The published run (seed 1): the one `make test` stored in results/vlahakis, else computed here."""
    return v.STUDY.load_or_run(v.SETTINGS, 1, store=results_dir() / "vlahakis")


@pytest.fixture(scope="module")
def claims(result):
    return {c.id.split("/")[1]: c for c in v.claims(result)}


# ---------------------------------------------------------------- the registry


def test_registry_declares_the_study():
    assert v.REGISTRY.key == "vlahakis" and v.REGISTRY.citation == "Vlahakis and Halikias"
    study = v.REGISTRY.study("distributed-observer")
    assert study is v.STUDY and study.chapter == "vlahakis_distributed_observer"
    assert [(f.name, f.number) for f in study.figures] == [("fig1", "Fig. 1"), ("fig2", "Fig. 2"), ("phi-profile", "")]
    assert {t.name for t in study.tables} == {"example1_readings", "example1_lmi_variants", "fig1_position_errors",
                                             "fig2_position_errors", "lqr_costs"}
    assert len(v.REGISTRY.errata) >= 3
    assert not hasattr(v, "reproduce")


def test_settings_document_every_field():
    for f in dataclasses.fields(v.ObserverSettings):
        assert f.metadata["source"] in ("paper", "chosen", "derived"), f.name
        assert f.metadata["where"], f.name
    assert hash(v.SETTINGS) == hash(v.ObserverSettings())  # frozen and hashable
    assert v.EXAMPLE1["Q1"] == v.SETTINGS.Q1 and v.EXAMPLE1["Q2"] == v.SETTINGS.Q2


def test_run_needs_the_printed_cases():
    with pytest.raises(ValueError, match="printed cases"):
        v.run(dataclasses.replace(v.SETTINGS, Q2=(5.0,)), 1)


def test_every_figure_draws_with_labelled_axes(result):
    for spec in v.STUDY.figures:
        fig = v.STUDY.draw(spec.name, result)
        assert isinstance(fig, plt.Figure), spec.name
        axes = [ax for ax in fig.axes if ax.has_data()]
        assert len(axes) == 2, spec.name
        for ax in axes:
            assert ax.get_xlabel(), spec.name
        assert axes[0].get_ylabel(), spec.name
        assert [ax.get_title()[:3] for ax in axes] == ["(a)", "(b)"], spec.name
        assert not any(ax.get_legend() for ax in axes), f"{spec.name}: legend over the data"
        assert spec.caption and not spec.caption.startswith("Vlahakis"), spec.name
        plt.close(fig)


def test_tables_build_from_the_result(result):
    for spec in v.STUDY.tables:
        table = v.STUDY.build(spec.name, result)
        assert len(table) > 0, spec.name
    errors = v.STUDY.build("fig1_position_errors", result)
    assert errors.t.diff().iloc[1] == pytest.approx(0.02)


# ---------------------------------------------------------------- the gain L


def test_printed_L_is_the_mixed_convention_gain():
    """Sec. 5 prints L = [2.6004; 22.8051] (velocity gain first, rotated coordinates of eq. (27))."""
    d = v.design(5.0, reading="inverse-weight-are")
    np.testing.assert_allclose([d.L[1, 0], d.L[0, 0]], [2.6004, 22.8051], atol=5e-5)
    # Q1^2 times the consistent (Kalman) gain of the same Riccati equation
    kalman = observers.min_energy_observer(E["A"], E["Bbar"], E["C"], [[1 / E["Q1"]]], [[E["R"]]])
    np.testing.assert_allclose(d.L, E["Q1"] ** 2 * kalman.L, rtol=1e-10)


def test_as_printed_L_is_the_min_energy_gain_with_its_poles():
    d = v.design(5.0, reading="as-printed")
    obs = observers.min_energy_observer(E["A"], E["Bbar"], E["C"], [[10.0]], [[1.0]])
    np.testing.assert_allclose(d.L, obs.L, rtol=1e-12)
    np.testing.assert_allclose(d.L.ravel(), [2.0548, 2.1111], atol=1e-4)
    poles = np.linalg.eigvals(E["A"] - d.L @ E["C"])
    np.testing.assert_allclose(sorted(poles, key=np.imag), [-1.0774 - 1.4683j, -1.0774 + 1.4683j], atol=1e-4)


def test_slow_pole_near_origin_only_with_the_printed_L():
    """Sec. 5: 'the slowest pole being near the origin' fits the printed L, not the as-printed one."""
    slow = {}
    for reading in observers.READINGS:
        d = v.design(5.0, reading=reading)
        slow[reading] = np.max(np.linalg.eigvals(E["A"] - d.L @ E["C"]).real)
    assert -0.3 < slow["inverse-weight-are"] < -0.2
    assert slow["as-printed"] < -1.0


# ---------------------------------------------------------------- Phi and J


def test_as_printed_bound_is_node_optimum_times_N(result):
    """As printed, the LMI optimum equals N trace(S_hat) whatever Q2 (Phi undetermined)."""
    for Q2 in E["Q2"]:
        assert v.design(Q2).bound == pytest.approx(result.n_trace_s_hat, rel=1e-4)


def test_as_printed_optimal_phi_interval(result):
    """As printed the optimum N trace(S_hat) is attained by every Phi of the closed-form interval (the printed
    Phi included) and by none outside: checked by the program at fixed Phi in S_i, an independent route."""
    for Q2 in E["Q2"]:
        lo, hi = result.intervals[Q2]
        assert lo < 0 < v.PUBLISHED["Phi"][Q2] < hi
        inside = v.phi_profile(Q2, "as-printed", [lo + 1e-3, 0.0, v.PUBLISHED["Phi"][Q2], hi - 1e-3])
        np.testing.assert_allclose(inside, result.n_trace_s_hat, rtol=1e-7)
        outside = v.phi_profile(Q2, "as-printed", [lo - 0.02, hi + 0.02])
        assert np.all(outside > result.n_trace_s_hat * (1 + 1e-4))


def test_printed_L_determines_phi(result):
    """Fed the printed L the program determines Phi (weakly): the LMI's Phi is the profile's minimum."""
    for Q2 in E["Q2"]:
        d = result.designs[(v.L_READING, Q2)]
        assert result.phi_argmin[Q2] == pytest.approx(d.Phi.item(), abs=2e-3)
        assert result.gamma_at_lmi[Q2] == pytest.approx(d.bound, rel=1e-3)
        assert result.gamma_at_lmi[Q2] < result.gamma_at_printed[(v.L_READING, Q2)]


def test_readings_table_reports_the_free_interval_not_the_tie_break(result):
    table = result.readings
    free = table[table.reading == "as-printed"]
    assert free.Phi.isna().all()
    for _, row in free.iterrows():
        assert (row.Phi_free_low, row.Phi_free_high) == pytest.approx(result.intervals[row.Q2])
    fixed = table[table.reading == v.L_READING]
    assert fixed.Phi.notna().all() and fixed.Phi_free_low.isna().all()


def test_lmi_variants_printed_row_agrees_with_design(result):
    """Two routes to the same program: lmi_variants_table's printed row and distributed_observer."""
    table = result.variants
    rows = table[table.variant == "Q1 + lam Q2 (as printed)"].set_index(["L_reading", "Q2"])
    d = v.design(5.0, v.L_READING)
    assert rows.loc[(v.L_READING, 5.0), "J"] == pytest.approx(d.bound, rel=1e-5)
    assert rows.loc[(v.L_READING, 5.0), "Phi"] == pytest.approx(d.Phi.item(), abs=1e-3)
    assert not rows.loc[("as-printed", 5.0), "Phi_determined"]
    assert (table.status == "optimal").all()


# ---------------------------------------------------------------- Figs. 1-2 and the LQR checks


def test_fig12_deterministic_and_faster_for_larger_Q2():
    a, b = v.fig12(3), v.fig12(3)
    np.testing.assert_array_equal(a[0].ours, b[0].ours)
    assert not np.array_equal(a[0].ours, v.fig12(4)[0].ours)
    assert a[1].settling["ours_iae"] < a[0].settling["ours_iae"]
    assert a[1].settling["paper_iae"] < a[0].settling["paper_iae"]
    assert np.abs(a[0].ours[-1]).max() < 1e-2 * np.abs(a[0].ours[0]).max()


def test_structure_and_controller_costs():
    dev = v.structure_check(4)
    assert dev["P_deviation"] < 1e-10 and dev["K_deviation"] < 1e-10
    comp = v.controller_comparison().set_index("controller")
    cen = comp.loc["centralized (eq. 9)", "cost"]
    assert cen <= comp.loc["bottom-up (eq. 18)", "cost"] <= comp.loc["bottom-up (eq. 18)", "bound"]
    assert cen <= comp.loc["top-down (eq. 17)", "cost"]


def test_settling_time():
    t = np.linspace(0, 10, 1001)
    sig = np.exp(-t)[:, None]
    assert v.settling_time(t, sig, 0.05) == pytest.approx(np.log(20), abs=0.011)


# ---------------------------------------------------------------- the ledger


def test_claims_and_verdicts(claims):
    assert set(claims) == set(EXPECTED_VERDICTS)
    assert {k: c.verdict for k, c in claims.items()} == EXPECTED_VERDICTS
    assert claims["example1-phi-q2-5"].value == pytest.approx(0.1205, abs=1e-3)
    assert claims["example1-J-q2-5"].value == pytest.approx(19.17, rel=1e-3)
    for c in claims.values():
        assert c.tolerance is None or c.tolerance.get("approx_rel", c.tolerance.get("approx_abs")) <= 3 * max(
            c.tolerance.get("rel", 0), c.tolerance.get("abs", 0)) * (1 + 1e-12)


def test_shared_note_paragraph_printed_once(claims):
    keys = ["example1-phi-q2-5", "example1-J-q2-5", "example1-phi-q2-25", "example1-J-q2-25"]
    shared = [set(claims[k].note.split("\n\n")[1:]) for k in keys]
    assert all(s == shared[0] for s in shared) and len(shared[0]) == 2
    text = str(show_claims(list(claims.values())))
    for paragraph in shared[0]:
        assert text.count(" ".join(paragraph.split())[:80]) == 1
    assert "-1.077 ± 1.468j" in text and "-1.03" not in text


def test_errata_numbers_match_the_run(result):
    errata = " ".join(v.REGISTRY.errata)
    for Q2 in E["Q2"]:
        lo, hi = result.intervals[Q2]
        assert f"[{format_number(lo)}, {format_number(hi)}]" in errata
        assert format_number(result.designs[(v.L_READING, Q2)].bound) in errata
        assert format_number(result.designs[(v.L_READING, Q2)].Phi.item()) in errata
        assert format_number(result.printed_cost[Q2]) in errata
    assert format_number(result.n_trace_s_hat) in errata
    assert "-1.077 \\pm 1.468j" in errata


@pytest.mark.slow
def test_reproduce_writes_ledger(published, claims):
    """The published results (results/vlahakis, seed 1) hold the run's claims, figures and tables."""
    out, published_claims = published("vlahakis")
    assert set(REQUIRED) <= {c.id for c in published_claims}
    assert {c.study for c in published_claims} == {"distributed-observer"}
    assert [c.to_dict() for c in claims.values()] == [{k: v for k, v in c.to_dict().items() if k != "study"}
                                                      for c in published_claims]
    for name in ("fig1", "fig2", "phi-profile"):
        assert (out / "figures" / f"{name}.png").exists()
    for name in ("example1_readings", "example1_lmi_variants", "lqr_costs", "fig1_position_errors"):
        assert (out / "tables" / f"{name}.csv").exists()
    verdicts = {c["id"]: c["verdict"] for c in json.loads((out / "claims.json").read_text())["claims"]}
    assert verdicts == {f"vlahakis/{k}": v_ for k, v_ in EXPECTED_VERDICTS.items()}


# ---------------------------------------------------------------- bad input is refused by name (issue 14)

_T = np.linspace(0.0, 1.0, 5)
_SIG = np.exp(-_T)[:, None] * np.ones((1, 3))


@pytest.mark.parametrize("call, name", [
    *[(lambda bad=bad, f=f: f(bad), "Q2") for bad in (np.nan, np.inf, -1.0, "5")
      for f in (v.design, v.as_printed_phi_interval)],
    (lambda: v.as_printed_phi_interval(5.0, n_agents=2.5), "n_agents"),
    (lambda: v.design(5.0, n_agents="5"), "n_agents"),
    (lambda: v.phi_profile("5", "as-printed", [0.5]), "Q2"),
    (lambda: v.phi_profile(5.0, "as-printed", [np.nan, 0.5]), "phis"),
    (lambda: v.phi_profile(5.0, "as-printed", [0.5, np.inf]), "phis"),
    (lambda: v.phi_profile(5.0, "as-printed", "phis"), "phis"),
    (lambda: v.phi_profile(5.0, "as-printed", []), "phis"),
    (lambda: v.phi_profile(5.0, "as-printed", np.ones((2, 2))), "phis"),
    (lambda: v.profile_argmin("5", v.L_READING, (0.0, 1.0)), "Q2"),
    (lambda: v.profile_argmin(5.0, v.L_READING, (0.0, np.nan)), "bounds"),
    (lambda: v.profile_argmin(5.0, v.L_READING, (1.0, 0.0)), "bounds"),
    (lambda: v.profile_argmin(5.0, v.L_READING, (0.0, 1.0, 2.0)), "bounds"),
    (lambda: v.profile_argmin(5.0, v.L_READING, (0.0, 1.0), points=1), "points"),
    (lambda: v.profile_argmin(5.0, v.L_READING, (0.0, 1.0), rounds=0), "rounds"),
    (lambda: v.settling_time(np.where(_T == 0, np.nan, _T), _SIG, 0.05), "t"),
    (lambda: v.settling_time(np.where(_T == 1, np.inf, _T), _SIG, 0.05), "t"),
    (lambda: v.settling_time("t", _SIG, 0.05), "t"),
    (lambda: v.settling_time(_T[::-1], _SIG, 0.05), "t"),
    (lambda: v.settling_time(_T[:-1], _SIG, 0.05), "signal"),
    (lambda: v.settling_time(_T, _SIG[:-1], 0.05), "signal"),
    (lambda: v.settling_time(_T, _SIG[:, 0], 0.05), "signal"),
    (lambda: v.settling_time(_T, np.where(_SIG == _SIG[0, 0], np.nan, _SIG), 0.05), "signal"),
    (lambda: v.settling_time(_T, _SIG * np.inf, 0.05), "signal"),
    (lambda: v.settling_time(_T, "signal", 0.05), "signal"),
    *[(lambda bad=bad: v.settling_time(_T, _SIG, bad), "fraction") for bad in (np.nan, np.inf, 0.0, -0.5, "0.1")],
    (lambda: v.run(seed=-1), "seed"),
    (lambda: v.run(seed="1"), "seed"),
    (lambda: v.structure_check(n_agents=4.5), "n_agents"),
    (lambda: v.controller_comparison(n_agents="5"), "n_agents"),
])
def test_bad_input_is_refused_by_name(call, name):
    with pytest.raises((ValueError, TypeError), match=rf"\b{name}\b"):
        call()


def test_zero_Q2_is_a_valid_limit():
    """Q2 = 0 decouples the agents: only Phi = 0 is optimal (a documented limit, not an error)."""
    assert v.as_printed_phi_interval(0.0) == (0.0, 0.0)
