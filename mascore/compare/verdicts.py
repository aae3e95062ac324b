"""The comparison's claims: one small function each, decided by intervals against bands on held-out seeds.

Every claim was written from the seed blocks :data:`WRITTEN_FROM` of the quick sweep and is decided
on the held-out blocks :data:`HELD_OUT` wherever the sweep has them (the quick grid has them for its
200-seed headline cells, the full grid for every cell); elsewhere it is decided on the blocks it
was written from, and says so (:attr:`Claim.decided_on`). A rule is a band for an interval
(:func:`inside`, :func:`above`, :func:`below`, :func:`before`): the interval inside the band holds,
outside it fails, across its edge is undecided; a claim holds if all its conditions hold, fails if
one fails, and is undecided otherwise. An undecided claim is not shown by the data: its ledger
verdict is ``fails``, its record says ``"undecided": true`` and its why says which interval
crosses which edge. Consistency is the ANEES inside its chi-square bounds
(:func:`mascore.compare.stats.anees_bounds`). Four claims were changed after their data were seen;
they say what changed (:attr:`Claim.post_hoc`).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from .benchmark import REN_Q, SETTINGS, SM_CONFIDENCE, VLAHAKIS_PHI
from .stats import Interval, mean_interval, rms_ratio
from .summary import summarize
from .tables import position_only_kf_rmse
from .target import LINK_STUDIES, TARGET_METHODS
from .team import vlahakis_profile

#: The seed blocks every claim was written from (the quick sweep's, when the claims were first written).
WRITTEN_FROM = (0, 1)

#: The held-out seed blocks that decide the claims where the sweep has them.
HELD_OUT = (2, 3)

_WHERE = "Comparing the methods"
_CELL = ("study", "task", "method", "graph", "n_agents", "noise", "dropout", "q_scale", "sensing")
_RUN = ("block", "run")

# --------------------------------------------------------------------------------------------
# three-valued rules: True (holds), False (fails), None (undecided)


def inside(iv: Interval, lo: float = -np.inf, hi: float = np.inf) -> bool | None:
    """Whether an interval lies in the band ``(lo, hi)``: True inside, False outside, None across an edge.

    Parameters
    ----------
    iv : Interval
        A 95 % interval (its point value is not used).
    lo, hi : float
        The band's ends.

    Returns
    -------
    bool or None

    Examples
    --------
    >>> from mascore.compare.stats import Interval
    >>> from mascore.compare.verdicts import inside
    >>> inside(Interval(1.0, 0.98, 1.02), 0.9, 1.1), inside(Interval(1.2, 1.15, 1.25), 0.9, 1.1)
    (True, False)
    >>> print(inside(Interval(1.1, 1.05, 1.15), 0.9, 1.1))
    None
    """
    if not (np.isfinite(iv.lo) and np.isfinite(iv.hi)):
        return None
    if lo < iv.lo and iv.hi < hi:
        return True
    if iv.hi <= lo or iv.lo >= hi:
        return False
    return None


def above(iv: Interval, x: float) -> bool | None:
    """:func:`inside` the band ``(x, inf)``."""
    return inside(iv, x, np.inf)


def below(iv: Interval, x: float) -> bool | None:
    """:func:`inside` the band ``(-inf, x)``."""
    return inside(iv, -np.inf, x)


def before(a: Interval, b: Interval) -> bool | None:
    """Whether `a` is less than `b`: True when the intervals are apart in that order, False apart the other way.

    Overlapping intervals are undecided (a conservative reading of two intervals).

    Examples
    --------
    >>> from mascore.compare.stats import Interval
    >>> from mascore.compare.verdicts import before
    >>> before(Interval(1.0, 0.9, 1.1), Interval(2.0, 1.9, 2.1)), before(Interval(2.0, 1.9, 2.1), Interval(1.0, 0.9, 1.1))
    (True, False)
    """
    if a.hi < b.lo:
        return True
    if a.lo > b.hi:
        return False
    return None


def all_of(conditions: Iterable[bool | None]) -> bool | None:
    """Three-valued AND: False if any condition fails, None if any is undecided, else True (all are evaluated)."""
    values = list(conditions)
    if any(c is not None and not c for c in values):
        return False
    return None if any(c is None for c in values) else True


def scaled(iv: Interval, factor: float) -> Interval:
    """An interval times a positive constant (a known reference, such as a DARE value)."""
    return Interval(iv.value * factor, iv.lo * factor, iv.hi * factor)


def _text(iv: Interval) -> str:
    return f"{iv.value:.4g} [{iv.lo:.4g}, {iv.hi:.4g}]"


def _shown(iv: Interval) -> list[float]:
    """An interval as the ledger shows it: ``[value, lo, hi]``, 4 significant digits."""
    return [float(f"{v:.4g}") for v in iv]


# --------------------------------------------------------------------------------------------
# the evidence a claim is decided on


class _Missing(LookupError):
    """The sweep has no row a claim needs (the claim is left out)."""


class Evidence:
    """The data of one claim: the sweep's summary of the deciding blocks, the runs, and the blocks read.

    Build one per claim (it records which blocks the claim read; not shared between threads).

    Parameters
    ----------
    summary : pandas.DataFrame
        :func:`mascore.compare.summarize` of `runs`, with a column ``blocks`` naming each group's blocks.
    runs : pandas.DataFrame
        The sweep's per-run rows on the deciding blocks (:func:`deciding_runs`).
    phi : dict
        The Vlahakis program's values (:func:`mascore.compare.vlahakis_profile`).
    by_method : mapping, optional
        `runs` split by method (:func:`_by_method`), to select a method's runs from its own rows
        (the same rows, in the same order, as from `runs`). Default: selected from `runs`.
    """

    def __init__(self, summary, runs, phi: Mapping[str, float], by_method: Mapping[str, Any] | None = None):
        self.summary, self.runs, self.phi = summary, runs, phi
        self.by_method = by_method
        self.blocks: set[str] = set()
        self.missed: list[tuple[bool | None, str]] = []

    def check(self, label: str, result: bool | None) -> bool | None:
        """Record a condition's outcome (`label` says what it tests) and return it."""
        if result is not True:
            self.missed.append((result, label))
        return result

    def inside(self, label: str, iv: Interval, lo: float, hi: float) -> bool | None:
        """:func:`inside`, recorded under `label`."""
        return self.check(f"{label} {_text(iv)} against ({lo:g}, {hi:g})", inside(iv, lo, hi))

    def above(self, label: str, iv: Interval, x: float) -> bool | None:
        """:func:`above`, recorded under `label`."""
        return self.check(f"{label} {_text(iv)} against > {x:.4g}", above(iv, x))

    def below(self, label: str, iv: Interval, x: float) -> bool | None:
        """:func:`below`, recorded under `label`."""
        return self.check(f"{label} {_text(iv)} against < {x:.4g}", below(iv, x))

    def before(self, label: str, a: Interval, b: Interval) -> bool | None:
        """:func:`before`, recorded under `label` (``"a < b"``)."""
        return self.check(f"{label}: {_text(a)} against {_text(b)}", before(a, b))

    def rows(self, **where: Any):
        """The summary's rows with the given coordinates (a list or tuple: any of those values)."""
        s = _select(self.summary, where)
        if s.empty:
            raise _Missing(f"no summary row with {where}")
        self.blocks.update(s["blocks"])
        return s

    def row(self, method: str, **where: Any):
        """The one summary row of `method` at the given coordinates."""
        s = self.rows(method=method, **where)
        if len(s) != 1:
            raise ValueError(f"{method} at {where}: {len(s)} summary rows, expected one (name more coordinates)")
        return s.iloc[0]

    def ratio(self, method: str, **where: Any) -> Interval:
        """RMS-error ratio to the bound with its 95 % interval (the summary's)."""
        r = self.row(method, **where)
        return Interval(float(r["ratio_mean"]), float(r["ratio_lo"]), float(r["ratio_hi"]))

    def mean(self, column: str, method: str, **where: Any) -> Interval:
        """A metric's mean with its 95 % interval (``nees_own`` is the ANEES)."""
        r = self.row(method, **where)
        return Interval(*(float(r[f"{column}_{k}"]) for k in ("mean", "lo", "hi")))

    def consistent(self, method: str, **where: Any) -> bool:
        """Whether the ANEES lies inside its two-sided 95 % chi-square bounds (recorded)."""
        r = self.row(method, **where)
        at = ", ".join(f"{k} = {v}" for k, v in where.items() if k in ("n_agents", "graph", "dropout") and v != "ring")
        label = (f"{method}{' (' + at + ')' if at else ''} ANEES {r['nees_own_mean']:.4g} against its chi-square "
                 f"bounds [{r['nees_bound_lo']:.4g}, {r['nees_bound_hi']:.4g}]")
        return bool(self.check(label, bool(r["nees_bound_lo"] <= r["nees_own_mean"] <= r["nees_bound_hi"])))

    def versus(self, method: str, reference: str, column: str = "rmse_own", ref_column: str = "rmse_own",
               **where: Any) -> Interval:
        """RMS ratio of `method`'s `column` to `reference`'s `ref_column` on the same runs (paired bootstrap)."""
        self.row(method, **where), self.row(reference, **where)
        a = self._runs_of(method, where).sort_values(list(_RUN))
        b = self._runs_of(reference, where).sort_values(list(_RUN))
        if len(a) != len(b) or not np.array_equal(a[list(_RUN)].to_numpy(), b[list(_RUN)].to_numpy()):
            raise ValueError(f"{method} and {reference} at {where} do not share their runs")
        return rms_ratio(a[column].to_numpy(), b[ref_column].to_numpy())

    def paired(self, method: str, at: Mapping[str, Any], against: Mapping[str, Any], **where: Any) -> Interval:
        """RMS-error ratio of `method` at the coordinates `at` to itself at `against`, on the same runs.

        The runs of two studies (e.g. ``latency`` and ``loss``) share their seeds (:data:`SEED_AXES
        <mascore.compare.SEED_AXES>` leave out the study and the loss), so the ratio is paired, with its
        bootstrap interval (:func:`mascore.compare.stats.rms_ratio`).
        """
        self.row(method, **where, **at), self.row(method, **where, **against)
        a, b = (self._runs_of(method, {**where, **c}).sort_values(list(_RUN)) for c in (at, against))
        if len(a) != len(b) or not np.array_equal(a[list(_RUN)].to_numpy(), b[list(_RUN)].to_numpy()):
            raise ValueError(f"{method} at {at} and at {against} do not share their runs")
        return rms_ratio(a["rmse_own"].to_numpy(), b["rmse_own"].to_numpy())

    def run_mean(self, column: str, method: str, **where: Any) -> Interval:
        """The mean over the deciding runs of a per-run `column` (e.g. ``floats`` as sent), bootstrap 95 % interval."""
        self.row(method, **where)
        return mean_interval(self._runs_of(method, where)[column].to_numpy(dtype=float))

    def _runs_of(self, method: str, where: Mapping[str, Any]):
        """The runs of `method` at the coordinates `where` (from its own rows when split by method)."""
        rows = self.runs if self.by_method is None else self.by_method.get(method, self.runs.iloc[:0])
        return _select(rows, {**where, "method": method})

    def claim(self, short: str, statement: str, value: Any, holds: bool | None, rule: str, **extra: str):
        """The claim ``compare/<short>``, with the blocks it was written from and decided on."""
        from ..claims import Claim

        written = _blocks_text(WRITTEN_FROM)
        held = _blocks_text(HELD_OUT)
        if self.blocks <= {held}:
            decided = f"seed blocks {held} (held out)"
        elif held in self.blocks:
            decided = (f"seed blocks {held} (held out) where the sweep has them, else {written} (the blocks it "
                       f"was written from: the quick grid has no others for those cells)")
        else:
            decided = f"seed blocks {written}: the blocks it was written from (the quick grid has no others here)"
        failed = [label for result, label in self.missed if result is False]
        open_ = [label for result, label in self.missed if result is None]
        why = ("Fails: " + "; ".join(failed) + "." if holds is False and failed else
               "Undecided: the 95 % interval crosses the band's edge: " + "; ".join(open_) + "." if holds is None
               and open_ else "")
        return Claim.qualitative(f"compare/{short}", _WHERE, statement, value, holds, rule=rule, why=why,
                                 written_from=f"seed blocks {written}", decided_on=decided, **extra)


def _select(frame, where: Mapping[str, Any]):
    """The rows of `frame` whose column ``key`` equals each value of `where` (a list or tuple: any of them)."""
    mask = np.ones(len(frame), dtype=bool)
    for key, v in where.items():
        col = frame[key]
        mask &= col.isin(v).to_numpy() if isinstance(v, list | tuple) else col.to_numpy() == v
    return frame[mask]


def _by_method(runs) -> dict[str, Any]:
    """`runs` split by method: each method's rows, in their order in `runs`."""
    return dict(tuple(runs.groupby("method", sort=False)))


def _blocks_text(blocks: Sequence[int]) -> str:
    return f"{min(blocks)}-{max(blocks)}" if len(blocks) > 1 else str(blocks[0])


def deciding_runs(table, held_out: Sequence[int] = HELD_OUT, written_from: Sequence[int] = WRITTEN_FROM):
    """The runs that decide the claims: per cell, the held-out blocks where it has them, else the written ones.

    Parameters
    ----------
    table : pandas.DataFrame
        The sweep's per-run rows (:func:`mascore.compare.run_cell` with cell coordinates).
    held_out, written_from : sequence of int
        The seed blocks.

    Returns
    -------
    pandas.DataFrame
        The selected rows, with a column ``blocks`` (``"2-3"`` or ``"0-1"``).

    Examples
    --------
    >>> import pandas as pd
    >>> from mascore.compare.verdicts import deciding_runs
    >>> t = pd.DataFrame({"study": "s", "task": "team", "method": "m", "block": [0, 1, 2, 3], "run": 0})
    >>> deciding_runs(t)["block"].tolist()
    [2, 3]
    """
    t = table.copy()
    keys = [c for c in _CELL if c in t]
    for c in keys:
        t[c] = t[c].astype(object).where(t[c].notna(), "")  # group NaN coordinates (no sensing) together
    has = t["block"].isin(held_out).groupby([t[c] for c in keys]).transform("any")
    keep = (has & t["block"].isin(held_out)) | (~has & t["block"].isin(written_from))
    out = table[keep.to_numpy()].copy()
    out["blocks"] = np.where(has[keep].to_numpy(), _blocks_text(held_out), _blocks_text(written_from))
    return out


# --------------------------------------------------------------------------------------------
# the claims, one function each

_CONSENSUS = [f"{m}-L{L}" for m in ("ci", "hcmci", "icf") for L in (1, 5)]
_STOCHASTIC = ("centralized", "local", "forwarding", "song-mb", "song-eb")
_HONEST = ("centralized", "local", "forwarding", "song-eb")
_TEAM = {"task": "team", "sensing": "full"}
_BASE8 = {**_TEAM, "study": "scaling", "n_agents": 8}


def centralized_bound(ev: Evidence):
    """The centralized filter's RMS error is the lowest in every own-state, target and localization cell."""
    s = ev.rows(task=["team", "target", "localization"])
    s = s[s["method"] != "centralized"]
    worst, verdicts = {}, []
    for (task, m), g in s.groupby(["task", "method"]):
        worst[f"{task}: {m}"] = round(float(g["ratio_lo"].min()), 6)
        verdicts += [ev.above(f"{task}: {m}", Interval(v, lo, hi), 1.0 - 1e-9)
                     for v, lo, hi in g[["ratio_mean", "ratio_lo", "ratio_hi"]].to_numpy()]
    worst = dict(sorted(worst.items(), key=lambda kv: kv[1]))  # the closest to the bound first
    return ev.claim(
        "centralized-bound",
        "The centralized Kalman filter's RMSE lower-bounds every other method's in every condition of the own-state, "
        "common-target and localization sweeps (the 95 % interval of the ratio of RMS errors at or above 1; shown: "
        "each method's lowest lower end over its conditions, the closest to 1 first).",
        worst, all_of(verdicts), "ratio interval above 1 for every method and condition",
        note="Under a wrong Q the centralized filter is wrong too; the ratio is still taken to it.")


def own_state_separable(ev: Evidence):
    """Forwarding is the centralized filter on the own-state task (ratio 1 to rounding)."""
    fwd = ev.rows(method="forwarding", **_TEAM)
    gap = float((fwd[["ratio_lo", "ratio_hi"]] - 1.0).abs().to_numpy().max())
    return ev.claim(
        "own-state-separable",
        "On the own-state task cooperation cannot beat one hop: every agent measures its own full state and the "
        "controls are known, so the team filter splits into one filter per agent, and forwarding to agent i its "
        "neighbours' measurements of i gives the centralized filter's estimates (in every condition, drop-outs "
        "included), with 4 floats per neighbour and a broadcast estimate instead of all-to-all links.",
        {"max |ratio - 1|": gap, "floats": float(fwd["floats"].iloc[0])},
        ev.check(f"max |ratio - 1| = {gap:.3g}", gap < 1e-9), "|ratio - 1| < 1e-9")


def set_membership_is_the_measurement(ev: Evidence):
    """With H = I the set-membership centre is the raw measurement, at every Q."""
    raw = float(np.sqrt(2 * SETTINGS.r))
    sm = ev.rows(method="set-membership", noise="gaussian", dropout=0.0, n_agents=8, study=["scaling", "wrong-q"],
                 **_TEAM)
    over = {f"Q x {q:g}": scaled(ev.mean("rmse_own", "set-membership", study=study, q_scale=q, noise="gaussian",
                                         dropout=0.0, n_agents=8, **_TEAM), 1 / raw)
            for study, q in sm[["study", "q_scale"]].itertuples(index=False)}
    return ev.claim(
        "set-membership-is-the-measurement",
        "With the full state measured (H = I) the set-membership correction returns L = I: the set's centre is the "
        "raw measurement, whatever the filter's Q (its RMSE over the measurement's, sqrt(2 r), at three settings of "
        "Q). The containment figures below describe the measurement ellipsoid, not the filter; this benchmark "
        "cannot test the paper's filter, whose own scenario (a partial output C) is in its chapter.",
        {k: _shown(v) for k, v in over.items()},
        all_of([ev.check("three settings of Q", len(over) >= 3)] + [ev.inside(k, v, 0.97, 1.03) for k, v in over.items()]),
        "RMSE / sqrt(2 r) inside (0.97, 1.03) at every Q")


def set_membership_contains(ev: Evidence):
    """Under bounded noise the set-membership ellipsoid always holds the truth."""
    c = ev.rows(method="set-membership", noise="uniform", **_TEAM)
    c = c[c["study"] != "position"]["containment_mean"]
    return ev.claim(
        "set-membership-contains",
        "Under bounded (uniform) noise the set-membership ellipsoid (here: the measurement's) contains the true state "
        "at every agent-step of every run.", {"containment": float(c.min())},
        ev.check(f"containment {float(c.min()):.6g}", float(c.min()) == 1.0),
        "containment == 1 (a guarantee: every run, no interval)")


def set_membership_unbounded(ev: Evidence):
    """Under Student-t noise the 99.7 % ellipsoid loses the truth more than 0.3 % of the time."""
    iv = ev.mean("containment", "set-membership", study="noise", noise="student-t", **_TEAM)
    return ev.claim(
        "set-membership-unbounded",
        "Given a 99.7 % ellipsoid for heavy-tailed (Student-t) noise, the set-membership ellipsoid loses the true "
        "state more often than the 0.3 % the bound admits.", {"containment": _shown(iv)}, ev.below("containment", iv, 0.997),
        "containment interval below 0.997")


def _nees_table(ev: Evidence, methods: Sequence[str], **where: Any) -> dict:
    return {m: _shown(ev.mean("nees_own", m, **where)) for m in methods}


def consistent_baseline(ev: Evidence):
    """On the baseline the Kalman-type filters are consistent; song-mb is overconfident."""
    nees = _nees_table(ev, _STOCHASTIC, **_BASE8)
    bounds = ev.row("centralized", **_BASE8)[["nees_bound_lo", "nees_bound_hi"]].round(4).tolist()
    return ev.claim(
        "consistent-baseline",
        "On the own-state baseline (Gaussian noise, correct Q, no drop-outs) the centralized, local, forwarding and "
        "estimation-based filters are consistent (ANEES inside its 95 % chi-square bounds); Song et al.'s "
        "measurement-based filter is not: eq. (15) neglects the correlation of an agent's own measurement noise in "
        "its control and in its estimate.", {"nees": nees, "chi-square bounds": bounds},
        all_of([ev.consistent(m, **_BASE8) for m in _HONEST]
               + [ev.above("song-mb ANEES", ev.mean("nees_own", "song-mb", **_BASE8), 1.1)]),
        "ANEES inside its chi-square bounds for centralized, local, forwarding, song-eb; song-mb interval above 1.1")


def consistent_dropouts(ev: Evidence):
    """With 30 % drop-outs the consistent filters stay consistent."""
    at = {**_TEAM, "study": "dropout", "dropout": 0.3}
    return ev.claim(
        "consistent-dropouts",
        "With 30 % of the links dropping at every step, the filters that were consistent stay consistent: "
        "the filters condition on the measurements that arrive.",
        {"nees": _nees_table(ev, _STOCHASTIC, **at), "consistent": sorted(m for m in _STOCHASTIC
                                                                          if ev.consistent(m, **at))},
        all_of(ev.consistent(m, **at) for m in _HONEST),
        "ANEES inside its chi-square bounds for centralized, local, forwarding, song-eb")


def wrong_q(ev: Evidence):
    """A Q ten times too small makes every filter overconfident; ten times too large, conservative."""
    low, high = ({**_TEAM, "study": "wrong-q", "q_scale": q} for q in (0.1, 10.0))
    return ev.claim(
        "wrong-q",
        "The filters' Q is the knob of every Kalman-type filter here: ten times too small, every one becomes "
        "overconfident (NEES per dof above 1.1); ten times too large, every one becomes conservative (below 0.9).",
        {"Q x 0.1": _nees_table(ev, _STOCHASTIC, **low), "Q x 10": _nees_table(ev, _STOCHASTIC, **high)},
        all_of([ev.above(f"{m} ANEES at Q x 0.1", ev.mean("nees_own", m, **low), 1.1) for m in _STOCHASTIC]
               + [ev.below(f"{m} ANEES at Q x 10", ev.mean("nees_own", m, **high), 0.9) for m in _STOCHASTIC]),
        "ANEES interval above 1.1 at Q x 0.1 and below 0.9 at Q x 10, for all")


def song_own_state(ev: Evidence):
    """Song et al.'s filters estimate an agent's own state as a local Kalman filter does."""
    gain = {m: ev.versus(m, "local", **_BASE8) for m in ("song-mb", "song-eb")}
    return ev.claim(
        "song-own-state",
        "Song et al.'s filters estimate the whole team, but an agent's estimate of its own state is no better than "
        "a local Kalman filter's (within 3 %): the neighbours' measurements of agent i are never sent to i. "
        "What they buy is the estimate of the others, without any communication.",
        {m: _shown(v) for m, v in gain.items()}, all_of(ev.inside(f"{m} / local", v, 0.97, 1.03) for m, v in gain.items()),
        "RMS ratio to the local filter inside (0.97, 1.03)")


def song_non_neighbours(ev: Evidence):
    """Song et al.'s estimate of the non-neighbours: far worse than the own state, of the team's spread."""
    at = {**_TEAM, "study": "scaling"}
    sizes = sorted(int(n) for n in ev.rows(method="song-eb", **at)["n_agents"].unique())
    far = {(m, n): ev.versus(m, m, "rmse_far", "rmse_own", n_agents=n, **at) for m in ("song-mb", "song-eb")
           for n in sizes}
    spread = {(m, n): ev.versus(m, m, "rmse_far", "spread", n_agents=n, **at) for m, n in far}
    grows = [ev.before(f"{m} far / own, N = {min(sizes)} < N = {max(sizes)}", far[m, min(sizes)], far[m, max(sizes)])
             for m in ("song-mb", "song-eb")]
    return ev.claim(
        "song-non-neighbours",
        "What Song et al.'s filters sell, an estimate of the agents one neither senses nor hears from, is measured "
        "here: its RMSE is at least 1.5 times the agent's own-state RMSE, a factor that grows with the team "
        "(the non-neighbours are more hops away), and it is of the order of the team's spread around its centroid "
        "(between half of it and the spread itself), the error of an agent that would only know where the "
        "team's centre is.",
        {f"{m}, N = {n}": {"far / own": _shown(far[m, n]), "far / spread": _shown(spread[m, n])} for m, n in far},
        all_of([ev.check("two team sizes", len(sizes) >= 2)]
               + [ev.above(f"{m} far / own, N = {n}", v, 1.5) for (m, n), v in far.items()]
               + [ev.inside(f"{m} far / spread, N = {n}", v, 0.5, 1.0) for (m, n), v in spread.items()] + grows),
        "far / own above 1.5 and far / spread inside (0.5, 1) for song-mb and song-eb at every N; far / own "
        "larger at the largest N than at the smallest",
        post_hoc="The band of far / spread (0.5 to 1) was fitted to the sweep's values after they were seen.")


def vlahakis_phi_undetermined(ev: Evidence):
    """The Vlahakis program is flat in Phi while equally optimal gains differ in accuracy."""
    gammas = [v for k, v in ev.phi.items() if k.startswith("Phi =")]
    flat = (max(gammas) - min(gammas)) / min(gammas)
    jump = ev.versus("vlahakis-phi1", "vlahakis", **_BASE8)
    return ev.claim(
        "vlahakis-phi-undetermined",
        "On this benchmark the Vlahakis program (56)-(58) does not determine the coupling gain: its value Gamma(Phi) "
        "is the same for every Phi from -0.1 to 1 (relative spread below 1e-4), so the Phi near 0 our solver returns "
        "comes from its |Y2| tie-break (ours, not the paper's). Equally optimal gains give very different accuracy: "
        "the own-position RMSE grows from the LMI's Phi to Phi = 1 by more than 50 %.",
        {"Gamma relative spread": flat, "RMSE(Phi = 1) / RMSE(LMI)": _shown(jump),
         "RMSE / local": {m: _shown(ev.versus(m, "local", **_BASE8)) for m in VLAHAKIS_PHI}},
        all_of([ev.check(f"Gamma's relative spread {flat:.3g}", flat < 1e-4),
                ev.above("RMSE(Phi = 1) / RMSE(LMI)", jump, 1.5)]), "spread < 1e-4; RMS ratio Phi = 1 to the LMI's above 1.5")


def vlahakis_position_only(ev: Evidence):
    """The Vlahakis observer is as accurate as a position-only Kalman filter (DARE)."""
    pos_only, full = position_only_kf_rmse()
    kf = pos_only / full
    vl = {m: ev.versus(m, "local", **_BASE8) for m in ("vlahakis", "vlahakis-phi0")}
    return ev.claim(
        "vlahakis-position-only",
        "The Vlahakis design needs a partial output (m < n), so the observer is given positions only; at the LMI's "
        "Phi (and at Phi = 0) it is as accurate as a discrete Kalman filter on position only (within 3 %, the DARE's "
        "value), which is itself less accurate than the local filter that also measures velocity. Its deficit "
        "here is the sensing, not the design.",
        {"RMSE / local": {m: _shown(v) for m, v in vl.items()}, "position-only KF / local (DARE)": kf},
        all_of(ev.inside(f"{m} / position-only KF", scaled(v, 1 / kf), 0.97, 1.03) for m, v in vl.items()),
        "ratio / ratio_KF,position inside (0.97, 1.03) at Phi = LMI and 0")


_POS = {"task": "team", "study": "position", "sensing": "position"}


def _confidence_names() -> dict[str, tuple[float, str]]:
    level = {m: SETTINGS.sm_confidence if c is None else c for m, c in SM_CONFIDENCE.items()}
    return {m: (level[m], f"confidence {level[m]:g}") for m in SM_CONFIDENCE}


def position_set_membership_accuracy(ev: Evidence):
    """With positions only the set-membership centre beats the raw measurement, not the local KF."""
    raw = float(np.sqrt(2 * SETTINGS.r))
    names = _confidence_names()
    cases = {name: ({**_POS, "noise": "gaussian"}, m) for m, (_, name) in names.items()}
    cases["uniform noise"] = ({**_POS, "noise": "uniform"}, "set-membership")
    over_raw = {k: scaled(ev.mean("rmse_own", m, **at), 1 / raw) for k, (at, m) in cases.items()}
    over_local = {k: ev.versus(m, "local", **at) for k, (at, m) in cases.items()}
    return ev.claim(
        "position-set-membership-accuracy",
        "With positions only (C = [I 0]) the set-membership correction does real work: the set's centre is more "
        "accurate than the raw position measurement (RMSE below 0.8 sqrt(2 r)) at every confidence level and under "
        "bounded noise. It is not as accurate as the local Kalman filter on the same measurements: its RMSE is more "
        "than 1.3 times the local filter's at every setting (the centre of a worst-case set is not a "
        "minimum-variance estimate; the confidence level barely moves it).",
        {"RMSE / sqrt(2 r)": {k: _shown(v) for k, v in over_raw.items()},
         "RMSE / local KF": {k: _shown(v) for k, v in over_local.items()}},
        all_of([ev.below(f"{k}: RMSE / sqrt(2 r)", v, 0.8) for k, v in over_raw.items()]
               + [ev.above(f"{k}: RMSE / local", v, 1.3) for k, v in over_local.items()]),
        "RMSE / sqrt(2 r) interval below 0.8 and RMS ratio to the local filter above 1.3 at confidence 0.9, 0.997, "
        "0.99999 and uniform")


def position_set_membership_contains(ev: Evidence):
    """With positions only the set holds the truth as often as its confidence, at a price in size."""
    names = _confidence_names()
    gauss, uni = {**_POS, "noise": "gaussian"}, {**_POS, "noise": "uniform"}
    size = {name: ev.mean("set_size", m, **gauss) for m, (_, name) in names.items()}
    inside_g = {name: ev.mean("containment", m, **gauss) for m, (_, name) in names.items()}
    bounded = float(ev.row("set-membership", **uni)["containment_mean"])
    per_rmse = scaled(ev.mean("set_size", "set-membership", **uni),
                      1 / float(ev.row("set-membership", **uni)["rmse_own_mean"]))
    order = [names[m][1] for m in ("set-membership-c90", "set-membership", "set-membership-c99999")]
    return ev.claim(
        "position-set-membership-contains",
        "With positions only and a guaranteed bound (uniform noise) the set contains the true state at every "
        "agent-step of every run; the price is its size: its largest position semi-axis is several times (more "
        "than 3) the centre's RMSE. Under Gaussian noise, given the ellipsoids of confidence 0.9, 0.997 and "
        "0.99999 as bounds, it holds the truth at least as often as that confidence, and the set grows with it.",
        {"containment, uniform": bounded, "containment, Gaussian": {k: _shown(v) for k, v in inside_g.items()},
         "set size (m)": {k: _shown(v) for k, v in size.items()}, "set size / RMSE, uniform": _shown(per_rmse)},
        all_of([ev.check(f"containment under uniform noise {bounded:.6g}", bounded == 1.0),
                ev.above("set size / RMSE, uniform", per_rmse, 3.0)]
               + [ev.above(f"containment at {name}", inside_g[name], level) for level, name in names.values()]
               + [ev.before(f"set size, {a} < {b}", size[a], size[b]) for a, b in zip(order, order[1:])]),
        "containment == 1 under uniform noise and its interval above the confidence under Gaussian noise; "
        "size / RMSE above 3; size increasing in the confidence")


def position_vlahakis_vs_local(ev: Evidence):
    """With positions only the Vlahakis observer at the LMI's Phi is the local Kalman filter."""
    pos_only, _ = position_only_kf_rmse()
    gauss = {**_POS, "noise": "gaussian"}
    vl = {m: ev.versus(m, "local", **gauss) for m in VLAHAKIS_PHI}
    local = scaled(ev.mean("rmse_own", "local", **gauss), 1 / pos_only)
    return ev.claim(
        "position-vlahakis-vs-local",
        "On the same position measurements (200 seeds) the Vlahakis observer at the LMI's Phi and at Phi = 0 is as "
        "accurate as the simulated position-only local Kalman filter (within 3 %), whose RMSE is within 3 % of the "
        "DARE's value; at Phi = 1, an equally optimal point of its program, it is more than 1.5 times less "
        "accurate. Its relative measurements add nothing at the LMI's gains: the observer is a local filter.",
        {"RMSE / local KF (simulated)": {m: _shown(v) for m, v in vl.items()}, "local KF / DARE": _shown(local)},
        all_of([ev.inside(f"{m} / local", vl[m], 0.97, 1.03) for m in ("vlahakis", "vlahakis-phi0")]
               + [ev.above("vlahakis-phi1 / local", vl["vlahakis-phi1"], 1.5),
                  ev.inside("local / DARE", local, 0.97, 1.03)]),
        "RMS ratio inside (0.97, 1.03) at Phi = LMI and 0, above 1.5 at Phi = 1; local / DARE inside (0.97, 1.03)")


def position_separable(ev: Evidence):
    """With positions only forwarding is still the centralized filter."""
    fwd = ev.rows(method="forwarding", **_POS)
    gap = float((fwd[["ratio_lo", "ratio_hi"]] - 1.0).abs().to_numpy().max())
    local = ev.ratio("local", noise="gaussian", **_POS)
    return ev.claim(
        "position-separable",
        "With positions only the own-state task still splits into one filter per agent (the controls are known): "
        "forwarding to agent i its neighbours' position measurements of i gives the centralized filter's estimates, "
        "and the centralized filter's gain over the local one is the neighbours' measurements of i.",
        {"max |ratio - 1|": gap, "local ratio": _shown(local)}, all_of([ev.check(f"max |ratio - 1| = {gap:.3g}", gap < 1e-9),
                                                              ev.above("local ratio", local, 1.0)]),
        "|ratio - 1| < 1e-9 for forwarding; the local filter's ratio above 1")


_SHARED8 = {"task": "shared", "dropout": 0.0, "graph": "ring", "n_agents": 8}


def _knob_values() -> str:
    """Ren et al.'s Q = Omega settings of the sweep, in words (``"0, 0.1, 0.3, 0.6 and 1"``)."""
    values = sorted(REN_Q.values())
    words = [f"{v:g}" for v in values]
    return ", ".join(words[:-1]) + " and " + words[-1] if len(words) > 1 else words[0]


def ren_accurate_overconfident(ev: Evidence):
    """Ren et al.'s Kalman consensus: within 5 % of the central fusion, overconfident."""
    ratio = {m: ev.ratio(m, **_SHARED8) for m in REN_Q}
    nees = {m: ev.mean("nees_own", m, **_SHARED8) for m in REN_Q}
    return ev.claim(
        "ren-accurate-overconfident",
        "On the shared quantity Ren et al.'s Kalman consensus comes within 5 % of the central fusion's accuracy "
        "and its P is overconfident (ANEES above 2: it counts the same information again), at every setting of "
        f"its Q = Omega knob ({_knob_values()}); without process noise by many orders of magnitude more than at "
        "the paper's Q = Omega = 0.1. Written from the paper's setting and Q = Omega = 0 only.",
        {m: {"ratio": _shown(ratio[m]), "nees": _shown(nees[m])} for m in REN_Q},
        all_of([ev.inside(f"{m} ratio", ratio[m], 0.95, 1.05) for m in REN_Q]
               + [ev.above(f"{m} ANEES", nees[m], 2.0) for m in REN_Q]
               + [ev.above("ren-kc-q0 ANEES over 1e3 ren-kc's", nees["ren-kc-q0"], 1e3 * nees["ren-kc"].hi)]),
        "ratio inside (0.95, 1.05) and ANEES above 2 at every setting; ANEES(Q = 0) above 1e3 ANEES(Q = 0.1)",
        note="Noise-free messages; Omega weights them as in the paper's Fig. 1.",
        post_hoc="Loosened after the data were seen: first written as 'within 2 %, NEES above 10'.")


_TARGET = {"task": "target", "graph": "ring"}


def _sizes(ev: Evidence, **where: Any) -> list[int]:
    return sorted(int(n) for n in ev.rows(**where)["n_agents"].unique())


def target_needs_cooperation(ev: Evidence):
    """On the common target the local filter diverges and one hop of forwarding suffices."""
    sizes = _sizes(ev, **_TARGET)
    local = {n: ev.ratio("local", n_agents=n, **_TARGET) for n in sizes}
    fwd = {n: ev.ratio("forwarding", n_agents=n, **_TARGET) for n in sizes}
    return ev.claim(
        "target-needs-cooperation",
        "On the common target no agent can do without its neighbours: each senses one coordinate, and its local "
        "filter's error grows without bound (RMSE ratio above 10 after the run); one hop of forwarded measurements "
        "already makes the target observable.",
        {"local": {f"N = {n}": _shown(v) for n, v in local.items()},
         "forwarding": {f"N = {n}": _shown(v) for n, v in fwd.items()}},
        all_of([ev.above(f"local, N = {n}", v, 10) for n, v in local.items()]
               + [ev.below(f"forwarding, N = {n}", v, 2) for n, v in fwd.items()]),
        "local ratio above 10, forwarding below 2")


def target_consensus_steps(ev: Evidence):
    """On the common target more consensus steps bring every consensus filter closer to the centre."""
    at = {**_TARGET, "n_agents": 8}
    knob = {m: {L: ev.ratio(f"{m}-L{L}", **at) for L in (1, 5)} for m in ("ci", "hcmci", "icf")}
    return ev.claim(
        "target-consensus-steps",
        "More consensus steps buy accuracy at a linear price in messages: from L = 1 to L = 5 every consensus filter "
        "gets closer to the centralized one, and the hybrid (HCMCI) and information-weighted (ICF) filters come "
        "within 10 % of it at L = 5 while consensus on information alone stays further away (N = 8, ring).",
        {m: {L: _shown(v) for L, v in d.items()} for m, d in knob.items()},
        all_of([ev.before(f"{m}: L = 5 < L = 1", v[5], v[1]) for m, v in knob.items()]
               + [ev.below("hcmci-L5", knob["hcmci"][5], 1.1), ev.below("icf-L5", knob["icf"][5], 1.1),
                  ev.before("hcmci-L5 < ci-L5", knob["hcmci"][5], knob["ci"][5])]),
        "ratio(L = 5) below ratio(L = 1); HCMCI, ICF below 1.1 at L = 5; CI above HCMCI at L = 5")


def target_consistency(ev: Evidence):
    """On the common target CI is conservative, HCMCI and ICF overconfident at L = 1, the KFs consistent."""
    sizes = _sizes(ev, **_TARGET)
    shown = ("ci-L1", "ci-L5", "ci-diffusion", "hcmci-L1", "hcmci-L5", "icf-L1", "icf-L5", "forwarding",
             "centralized")
    nees = {n: {m: ev.mean("nees_own", m, n_agents=n, **_TARGET) for m in shown} for n in sizes}
    return ev.claim(
        "target-consistency",
        "Consistency on the common target depends on the rule: consensus on information and covariance "
        "intersection are conservative at every L and N (NEES per dof below 0.9), as their theory guarantees; HCMCI "
        "and ICF are overconfident until the consensus has nearly converged (above 1.1 at L = 1 for every N; at "
        "L = 5 consistent on the ring of 8); the Kalman filters (centralized, forwarding) are consistent.",
        {f"N = {n}": {m: _shown(v) for m, v in d.items()} for n, d in nees.items()},
        all_of([ev.below(f"{m} ANEES, N = {n}", d[m], 0.9) for n, d in nees.items()
                for m in ("ci-L1", "ci-L5", "ci-diffusion")]
               + [ev.above(f"{m} ANEES, N = {n}", d[m], 1.1) for n, d in nees.items() for m in ("hcmci-L1", "icf-L1")]
               + [ev.consistent(m, n_agents=8, **_TARGET) for m in ("hcmci-L5", "icf-L5")]
               + [ev.consistent(m, n_agents=n, **_TARGET) for n in sizes for m in ("forwarding", "centralized")]),
        "CI intervals below 0.9 at all L, N; HCMCI, ICF above 1.1 at L = 1; ANEES inside its chi-square bounds "
        "for HCMCI, ICF at L = 5, N = 8 and for the Kalman filters at every N",
        note=_excludes_one(nees.get(8, {}), ("hcmci-L5", "icf-L5")),
        post_hoc="Narrowed after the data were seen: 'consistent at L = 5' was first claimed at every N, and "
                 "narrowed to N = 8 when N = 16 gave an ANEES of 1.32.")


def _excludes_one(nees: Mapping[str, Interval], methods: Sequence[str]) -> str:
    """A note on the filters whose ANEES interval excludes 1 although the chi-square bounds accept them."""
    off = [f"{m} {_text(nees[m])}" for m in methods if m in nees and not nees[m].lo <= 1.0 <= nees[m].hi]
    if not off:
        return ""
    return ("At N = 8 the ANEES interval of " + ", ".join(off) + " excludes 1: a small overconfidence that the "
            "chi-square bounds (one NEES per run, see mascore.compare.stats.anees_bounds) do not reject.")


def switching_target(ev: Evidence):
    """On the switching topology CI filters stay conservative, diffusion becomes overconfident."""
    sw = {"task": "target", "graph": "switching", "n_agents": 16}  # the full grid adds other team sizes
    ran = set(ev.rows(**sw)["method"])  # the quick grid runs the set-membership filter on the ring only
    nees = {m: ev.mean("nees_own", m, **sw) for m in TARGET_METHODS if m in ran}
    nees = {m: v for m, v in nees.items() if np.isfinite(v.value)}  # a set-membership filter has no NEES
    ruled = ("ci-L1", "ci-L5", "ci-diffusion", "diffusion", "hcmci-L1", "hcmci-L5", "icf-L1", "icf-L5")
    shown_nees = {m: nees[m] for m in ruled if m in nees}  # the values the rule reads, all of them shown
    ratio = {m: ev.ratio(m, **sw) for m in TARGET_METHODS if m in ran}
    ring = ev.ratio("diffusion", task="target", graph="ring", n_agents=16)
    return ev.claim(
        "switching-target",
        "On a switching proximity topology (16 sensors whose graph changes at every step and is rarely connected) "
        "the filters built on covariance intersection keep their guarantee: consensus on information stays "
        "conservative (NEES per dof below 0.9 at L = 1 and 5) and CI-diffusion honest (below 1.1); the diffusion "
        "Kalman filter, conservative on fixed graphs, becomes overconfident (above 2) and its RMSE over the "
        "centralized filter's more than triples against the fixed ring of 16; HCMCI and ICF are overconfident "
        "(above 1.5) at L = 1 and L = 5.",
        {"nees": {m: _shown(v) for m, v in shown_nees.items()}, "diffusion ratio": _shown(ratio["diffusion"]),
         "diffusion ratio, ring of 16": _shown(ring)},
        all_of([ev.below(f"{m} ANEES", nees[m], 0.9) for m in ("ci-L1", "ci-L5")]
               + [ev.below("ci-diffusion ANEES", nees["ci-diffusion"], 1.1),
                  ev.above("diffusion ANEES", nees["diffusion"], 2.0),
                  ev.above("diffusion ratio over 3 x the ring's", ratio["diffusion"], 3 * ring.hi)]
               + [ev.above(f"{m}-L{L} ANEES", nees[f"{m}-L{L}"], 1.5) for m in ("hcmci", "icf") for L in (1, 5)]),
        "CI below 0.9 (L = 1, 5), CI-diffusion below 1.1; diffusion ANEES above 2 and ratio above 3 x the ring's "
        "upper end; HCMCI, ICF above 1.5")


def switching_ren(ev: Evidence):
    """On the switching topology Ren et al.'s consensus stays far from the central fusion."""
    at = {"task": "shared", "dropout": 0.0, "n_agents": 16}
    ev.rows(graph=["geometric", "switching"], **at)
    ren = {m: {g: ev.ratio(m, graph=g, **at) for g in ("geometric", "switching")} for m in REN_Q}
    return ev.claim(
        "switching-ren",
        "Ren et al.'s theorem is about switching graphs that are connected over time; over the shared task's "
        "steps on the switching topology of 16 Ren et al.'s Kalman consensus stays more than 1.5 times the "
        "central fusion's RMSE, further from it than on the fixed geometric graph of 16, at every setting of "
        f"its Q = Omega knob ({_knob_values()}).", {m: {g: _shown(v) for g, v in d.items()} for m, d in ren.items()},
        all_of([ev.above(f"{m} on the switching graph", v["switching"], 1.5) for m, v in ren.items()]
               + [ev.before(f"{m}: geometric < switching", v["geometric"], v["switching"]) for m, v in ren.items()]),
        "ratio above 1.5 on the switching graph and above the fixed graph's, at every Q = Omega")


def switching_own_state(ev: Evidence):
    """On the switching topology the own-state results of the fixed ring hold."""
    at = {**_TEAM, "graph": "switching"}
    song = {m: ev.versus(m, "local", **at) for m in ("song-mb", "song-eb")}
    return ev.claim(
        "switching-own-state",
        "On the switching topology of 16 (the rendezvous law, the sensing and Song et al.'s prediction all on "
        "the graph of the step) Song et al.'s filters keep their own-state accuracy, that of a local Kalman "
        "filter (within 3 %, measurement- and estimation-based alike), and the centralized, local, forwarding "
        "and estimation-based filters stay consistent (ANEES inside its chi-square bounds).",
        {"RMSE / local": {m: _shown(v) for m, v in song.items()}, "nees": _nees_table(ev, _STOCHASTIC, **at)},
        all_of([ev.inside(f"{m} / local", v, 0.97, 1.03) for m, v in song.items()]
               + [ev.consistent(m, **at) for m in _HONEST]),
        "RMS ratio to the local filter inside (0.97, 1.03) for song-mb, song-eb; ANEES inside its chi-square "
        "bounds for centralized, local, forwarding, song-eb")


def switching_localization_consensus(ev: Evidence):
    """In localization on the switching topology the consensus filters keep their accuracy."""
    at = {"task": "localization", "graph": "switching"}
    sizes = _sizes(ev, **at)
    ratio = {n: {m: ev.ratio(m, n_agents=n, **at) for m in _CONSENSUS} for n in sizes}
    nees = {n: {m: ev.mean("nees_own", m, n_agents=n, **at) for m in ("ci-L1", "ci-L5")} for n in sizes}
    return ev.claim(
        "switching-localization-consensus",
        "In cooperative localization on the switching topology (relative measurements on the links of the step "
        "only) the consensus filters keep their accuracy: every one comes within 25 % of the centralized filter "
        "at L = 1 and L = 5, as on the fixed ring, and consensus on information stays conservative (NEES per "
        "dof below 0.9) at both.",
        {f"N = {n}": {"ratio": {m: _shown(v) for m, v in ratio[n].items()},
                      "nees CI": {m: _shown(v) for m, v in nees[n].items()}} for n in sizes},
        all_of([ev.below(f"{m}, N = {n}", v, 1.25) for n, d in ratio.items() for m, v in d.items()]
               + [ev.below(f"{m} ANEES, N = {n}", v, 0.9) for n, d in nees.items() for m, v in d.items()]),
        "ratio below 1.25 for CI, HCMCI, ICF at L = 1 and 5; CI ANEES below 0.9 at L = 1 and 5; at every N")


def switching_localization_diffusion(ev: Evidence):
    """In localization on the switching topology the diffusion filter does not break."""
    at = {"task": "localization", "method": "diffusion"}
    sizes = sorted(set(_sizes(ev, graph="switching", **at)) & set(_sizes(ev, graph="ring", **at)))
    if not sizes:
        raise _Missing("no size with both graphs")
    diff = {n: {"switching": ev.ratio("diffusion", task="localization", graph="switching", n_agents=n),
                "ring": ev.ratio("diffusion", task="localization", graph="ring", n_agents=n),
                "nees": ev.mean("nees_own", "diffusion", task="localization", graph="switching", n_agents=n)}
            for n in sizes}
    return ev.claim(
        "switching-localization-diffusion",
        "The diffusion Kalman filter does not break in localization on the switching topology as it does "
        "on the common target: its NEES per dof stays below 2 and its RMSE over the centralized filter's "
        "below 3 times its value on the fixed ring of the same size (the target's thresholds, negated).",
        {f"N = {n}": {"ratio, switching": _shown(d["switching"]), "ratio, ring": _shown(d["ring"]),
                      "nees, switching": _shown(d["nees"])} for n, d in diff.items()},
        all_of([ev.below(f"ANEES, N = {n}", d["nees"], 2.0) for n, d in diff.items()]
               + [ev.below(f"ratio over 3 x the ring's, N = {n}", d["switching"], 3 * d["ring"].lo)
                  for n, d in diff.items()]),
        "ANEES below 2 and ratio below 3 x the ring's lower end, at every N with both graphs",
        note="The quick grid decides it at N = 8 only; the full grid adds larger teams, and the rule fails "
             "at 32 and 64 agents, where the diffusion filter's NEES per dof on the switching graph is above 2.")


_LOC8 = {"task": "localization", "n_agents": 8, "graph": "ring"}


def localization_needs_hops(ev: Evidence):
    """In localization one hop of forwarding is not enough; consensus is."""
    ratio = {m: ev.ratio(m, **_LOC8) for m in ("forwarding", "local", *_CONSENSUS)}
    return ev.claim(
        "localization-needs-hops",
        "In cooperative localization (relative measurements, two anchors, the ring of 8) one hop is not enough: "
        "an agent's own position is fixed by chains of relative measurements to the anchors, so forwarding the "
        "neighbours' measurements stays more than twice the centralized RMSE, while the consensus filters, which "
        "carry information over many hops, come within 25 % at both L = 1 and L = 5.",
        {"forwarding": _shown(ratio["forwarding"]), "local": _shown(ratio["local"]),
         "consensus": {m: _shown(ratio[m]) for m in _CONSENSUS}},
        all_of([ev.above("forwarding", ratio["forwarding"], 2.0),
                ev.before("forwarding < local", ratio["forwarding"], ratio["local"])]
               + [ev.below(m, ratio[m], 1.25) for m in _CONSENSUS]),
        "forwarding above 2 and below local; every consensus filter below 1.25 at L = 1 and 5")


def localization_knob(ev: Evidence):
    """In localization more consensus steps help HCMCI and ICF but not CI."""
    ratio = {m: {L: ev.ratio(f"{m}-L{L}", **_LOC8) for L in (1, 5)} for m in ("ci", "hcmci", "icf")}
    nees = {m: ev.mean("nees_own", m, **_LOC8) for m in _CONSENSUS}
    return ev.claim(
        "localization-knob",
        "The consensus steps do not buy the same thing in every scenario: in localization more steps bring HCMCI "
        "and ICF closer to the centralized filter but make consensus on information less accurate (its weights "
        "tend to 1/N per measurement); HCMCI and ICF are overconfident at L = 1 (NEES per dof above 1.1) and less so "
        "at L = 5, while consensus on information stays conservative at both (below 0.9).",
        {"ratio": {m: {L: _shown(v) for L, v in d.items()} for m, d in ratio.items()},
         "nees": {m: _shown(v) for m, v in nees.items()}},
        all_of([ev.before(f"{m} ratio: L = 5 < L = 1", ratio[m][5], ratio[m][1]) for m in ("hcmci", "icf")]
               + [ev.before("ci ratio: L = 1 < L = 5", ratio["ci"][1], ratio["ci"][5])]
               + [c for m in ("hcmci", "icf") for c in (
                   ev.above(f"{m}-L1 ANEES", nees[f"{m}-L1"], 1.1), ev.above(f"{m}-L5 ANEES", nees[f"{m}-L5"], 1.0),
                   ev.before(f"{m} ANEES: L = 5 < L = 1", nees[f"{m}-L5"], nees[f"{m}-L1"]))]
               + [ev.below(f"ci-L{L} ANEES", nees[f"ci-L{L}"], 0.9) for L in (1, 5)]),
        "ratio falls with L for HCMCI, ICF and rises for CI; HCMCI, ICF: ANEES above 1.1 at L = 1, above 1 and below "
        "that at L = 5; CI below 0.9 at L = 1, 5",
        post_hoc="Its bands (the NEES at L = 5 'between 1 and that at L = 1') were fitted to the sweep's values "
                 "after they were seen.")


# --------------------------------------------------------------------------------------------
# the claims of the link studies (LINK_STUDIES: each ratio to the bound of its own study and loss)

_LINKS = {"task": "target", "n_agents": 8, "graph": "ring"}
_ONE_ROUND = ("ci-L1", "icf-L1")
_LOSSY = {"loss 0.1": {"study": "loss", "dropout": 0.1}, "loss 0.3": {"study": "loss", "dropout": 0.3},
          "late": {"study": "latency", "dropout": 0.0}}


def links_latency_costs_more(ev: Evidence):
    """One step of latency costs CI and ICF at one step more than 30 % loss; forwarding about as much."""
    late, lossy = {"study": "latency", "dropout": 0.0}, {"study": "loss", "dropout": 0.3}
    ratio = {m: ev.paired(m, late, lossy, **_LINKS) for m in ("forwarding", *_ONE_ROUND)}
    return ev.claim(
        "links-latency-costs-more",
        "On the common target (N = 8, ring), one step of latency costs consensus on information and ICF at one "
        "consensus step more accuracy than losing 30 % of the exchanges: on the same runs each one's RMSE with "
        "every message a step late is more than 2 % above its RMSE at 30 % loss; for measurement forwarding, an "
        "exact Kalman filter on data a step old, the two cost about the same (within 5 %).",
        {f"{m}: RMSE late / RMSE at loss 0.3": _shown(v) for m, v in ratio.items()},
        all_of([ev.above(f"{m}: late / loss 0.3", ratio[m], 1.02) for m in _ONE_ROUND]
               + [ev.inside("forwarding: late / loss 0.3", ratio["forwarding"], 0.95, 1.05)]),
        "paired RMS ratio late / loss 0.3 above 1.02 for ci-L1 and icf-L1, inside (0.95, 1.05) for forwarding")


def links_send_on_delta(ev: Evidence):
    """Sending on delta 0.5 halves CI's floats at its accuracy; ICF saves little."""
    at, ideal = {"study": "send-on-delta-0.5", "dropout": 0.0}, {"study": "target", "dropout": 0.0}
    plain = {m: float(ev.row(m, **ideal, **_LINKS)["floats"]) for m in _ONE_ROUND}
    sent = {m: scaled(ev.run_mean("floats", m, **at, **_LINKS), 1 / plain[m]) for m in _ONE_ROUND}
    accuracy = ev.paired("ci-L1", at, ideal, **_LINKS)
    return ev.claim(
        "links-send-on-delta",
        "Sending only on change (a threshold delta = 0.5 standard deviations of the sender's prediction), "
        "consensus on information (one step) sends less than 60 % of the floats it sends at every step and "
        "keeps its accuracy (its RMSE within 5 % of its own on ideal links, on the same runs); ICF saves less "
        "than a quarter of its floats, because its message moves with every measurement.",
        {"floats sent / every step": {m: _shown(v) for m, v in sent.items()},
         "ci-L1: RMSE / RMSE on ideal links": _shown(accuracy)},
        all_of([ev.below("ci-L1 floats sent / every step", sent["ci-L1"], 0.6),
                ev.inside("ci-L1 RMSE / ideal links", accuracy, 0.95, 1.05),
                ev.above("icf-L1 floats sent / every step", sent["icf-L1"], 0.75)]),
        "ci-L1 at delta 0.5: floats fraction interval below 0.6 and paired RMS ratio to ideal links inside "
        "(0.95, 1.05); icf-L1: floats fraction above 0.75")


def links_consistency(ev: Evidence):
    """Under loss and latency forwarding stays consistent, CI conservative, ICF overconfident and more so with loss."""
    fwd = {k: ev.row("forwarding", **c, **_LINKS) for k, c in _LOSSY.items()}
    nees = {m: {k: ev.mean("nees_own", m, **c, **_LINKS) for k, c in _LOSSY.items()} for m in _ONE_ROUND}
    icf_ideal = ev.mean("nees_own", "icf-L1", study="target", dropout=0.0, **_LINKS)
    inside_bounds = [ev.check(f"forwarding ({k}) ANEES {r['nees_own_mean']:.4g} against its chi-square bounds "
                              f"[{r['nees_bound_lo']:.4g}, {r['nees_bound_hi']:.4g}]",
                              bool(r["nees_bound_lo"] <= r["nees_own_mean"] <= r["nees_bound_hi"]))
                     for k, r in fwd.items()]
    return ev.claim(
        "links-consistency",
        "Under 10 % and 30 % packet loss and under one step of latency, measurement forwarding stays consistent "
        "(ANEES inside its chi-square bounds: a Kalman filter on what arrives), consensus on information at one "
        "step stays conservative (ANEES below 1), and ICF at one step is overconfident (above 1.1), more so at "
        "30 % loss than on ideal links.",
        {"forwarding": {k: round(float(r["nees_own_mean"]), 4) for k, r in fwd.items()},
         **{m: {k: _shown(v) for k, v in d.items()} for m, d in nees.items()}, "icf-L1, ideal links": _shown(icf_ideal)},
        all_of(inside_bounds + [ev.below(f"ci-L1 ({k}) ANEES", v, 1.0) for k, v in nees["ci-L1"].items()]
               + [ev.above(f"icf-L1 ({k}) ANEES", v, 1.1) for k, v in nees["icf-L1"].items()]
               + [ev.before("icf-L1 ANEES: ideal < loss 0.3", icf_ideal, nees["icf-L1"]["loss 0.3"])]),
        "forwarding ANEES inside its chi-square bounds, ci-L1 below 1, icf-L1 above 1.1, at loss 0.1, 0.3 and "
        "late; icf-L1 ANEES at loss 0.3 above its ideal-links interval")


def links_loss_one_way(ev: Evidence):
    """Losing each direction alone costs what losing both at once does; the consistency verdicts hold under it."""
    both, one_way = ({"study": study} for study in ("loss", "loss-direction"))
    ratio = {m: {p: ev.paired(m, {**one_way, "dropout": p}, {**both, "dropout": p}, **_LINKS) for p in (0.1, 0.3)}
             for m in ("forwarding", *_ONE_ROUND)}
    fwd = {p: ev.row("forwarding", **one_way, dropout=p, **_LINKS) for p in (0.1, 0.3)}
    nees = {m: {p: ev.mean("nees_own", m, **one_way, dropout=p, **_LINKS) for p in (0.1, 0.3)} for m in _ONE_ROUND}
    return ev.claim(
        "links-loss-one-way",
        "Which loss model is used barely matters: with each message lost alone (one pattern per run, a lost "
        "message's weight on the receiver's own pair) forwarding, consensus on information and ICF at one step "
        "come within 5 % of their RMSE with each link lost in both directions at once at the same probability "
        "(10 % and 30 %, on the same runs), and forwarding stays consistent (ANEES inside its chi-square bounds), "
        "consensus on information conservative (below 1) and ICF overconfident (above 1.1).",
        {"RMSE one-way / both directions": {m: {f"loss {p:g}": _shown(v) for p, v in d.items()}
                                            for m, d in ratio.items()},
         "nees, one-way": {"forwarding": {f"loss {p:g}": round(float(r["nees_own_mean"]), 4) for p, r in fwd.items()},
                           **{m: {f"loss {p:g}": _shown(v) for p, v in d.items()} for m, d in nees.items()}}},
        all_of([ev.inside(f"{m} one-way / both at loss {p:g}", v, 0.95, 1.05)
                for m, d in ratio.items() for p, v in d.items()]
               + [ev.check(f"forwarding (one-way loss {p:g}) ANEES {r['nees_own_mean']:.4g} against its chi-square "
                           f"bounds [{r['nees_bound_lo']:.4g}, {r['nees_bound_hi']:.4g}]",
                           bool(r["nees_bound_lo"] <= r["nees_own_mean"] <= r["nees_bound_hi"])) for p, r in fwd.items()]
               + [ev.below(f"ci-L1 (one-way loss {p:g}) ANEES", v, 1.0) for p, v in nees["ci-L1"].items()]
               + [ev.above(f"icf-L1 (one-way loss {p:g}) ANEES", v, 1.1) for p, v in nees["icf-L1"].items()]),
        "paired RMS ratio one-way / both directions inside (0.95, 1.05) for forwarding, ci-L1, icf-L1 at loss 0.1 "
        "and 0.3; one-way: forwarding ANEES inside its chi-square bounds, ci-L1 below 1, icf-L1 above 1.1")


#: The claims of the link studies, after :data:`CLAIMS` in the ledger; decided on the link studies' summary
#: (each ratio to the centralized filter of the same study and loss) beside the ideal links' cells.
LINK_CLAIMS: tuple[Callable[[Evidence], Any], ...] = (links_latency_costs_more, links_send_on_delta, links_consistency,
                                                     links_loss_one_way)

#: The comparison's claims, in the ledger's order: one function each, from an :class:`Evidence` to a Claim.
CLAIMS: tuple[Callable[[Evidence], Any], ...] = (
    centralized_bound, own_state_separable, set_membership_is_the_measurement, set_membership_contains,
    set_membership_unbounded, consistent_baseline, consistent_dropouts, wrong_q, song_own_state,
    song_non_neighbours, vlahakis_phi_undetermined, vlahakis_position_only, position_set_membership_accuracy,
    position_set_membership_contains, position_vlahakis_vs_local, position_separable, ren_accurate_overconfident,
    target_needs_cooperation, target_consensus_steps, target_consistency, switching_target, switching_ren,
    switching_own_state, switching_localization_consensus, switching_localization_diffusion,
    localization_needs_hops, localization_knob,
)


def compare_claims(table, phi: dict | None = None, *, held_out: Sequence[int] = HELD_OUT,
                   written_from: Sequence[int] = WRITTEN_FROM,
                   which: Sequence[Callable[[Evidence], Any]] | None = None) -> list:
    """The comparison's claims (``compare/...``), decided on held-out seed blocks by intervals against bands.

    Each claim of :data:`CLAIMS` that depends on a method's tuning knob is decided at two or more
    settings of that knob and holds only if it holds at all of them; a claim whose data the
    sweep lacks is left out.

    Parameters
    ----------
    table : pandas.DataFrame
        The sweep's per-run table (:func:`mascore.compare.run_compare`'s first output; not its summary:
        the held-out blocks are chosen run by run).
    phi : dict, optional
        The Vlahakis program's value at fixed coupling gains (:func:`vlahakis_profile`,
        :attr:`CompareResult.phi`); computed here if not given.
    held_out, written_from : sequence of int
        The seed blocks that decide the claims, and those they were written from (used where a
        cell has no held-out block).
    which : sequence of callables, optional
        Only these claims of :data:`CLAIMS` and :data:`LINK_CLAIMS` (e.g. ``LINK_CLAIMS`` for the links
        page; the Vlahakis program is then computed only if one of them is in :data:`CLAIMS`).

    Returns
    -------
    list of mascore.ledger.Claim
        Qualitative claims (``holds`` or ``fails``; an undecided one fails, flagged ``undecided``),
        each with the quantities that decide it, the blocks it was written from and decided on, and what was changed after
        the data were seen.

    Examples
    --------
    On the quick sweep (the chapter "Comparing the methods" shows them all):

    >>> from mascore import compare
    >>> table, summary = compare.run_compare("quick", "results", workers=2)  # doctest: +SKIP
    >>> [c.verdict for c in compare.compare_claims(table)][:2]  # doctest: +SKIP
    ['holds', 'holds']
    """
    import pandas as pd

    if not isinstance(table, pd.DataFrame) or not {"block", "run", "rmse_own"} <= set(table.columns):
        raise TypeError("table must be the sweep's per-run table (run_compare's first output, with columns "
                        "'block', 'run', 'rmse_own'), not its summary")
    every = deciding_runs(table, held_out, written_from)
    if "sensing" not in every:
        every["sensing"] = np.nan
    team = every["task"] == "team"
    every["sensing"] = every["sensing"].astype(object).where(every["sensing"].notna(), np.where(team, "full", ""))
    lossy = every["study"].isin(LINK_STUDIES)
    runs = every[~lossy].copy()  # the link studies are summarized apart (link_summary), for LINK_CLAIMS only
    chosen = set(CLAIMS + LINK_CLAIMS if which is None else which)
    if not chosen <= set(CLAIMS + LINK_CLAIMS):
        raise ValueError("which must hold claims of CLAIMS or LINK_CLAIMS (mascore.compare.verdicts)")
    main = [c for c in CLAIMS if c in chosen] if len(runs) else []
    summary = _summary(runs) if len(runs) else None
    if phi is None and main:
        phi = vlahakis_profile(8)
    claims = []
    split = _by_method(runs) if main else None
    for claim in main:
        try:
            claims.append(claim(Evidence(summary, runs, phi, split)))
        except _Missing:
            continue
    if lossy.any():
        links = pd.concat([summary, _summary(every[lossy])], ignore_index=True)
        split = _by_method(every)
        for claim in (c for c in LINK_CLAIMS if c in chosen):
            try:
                claims.append(claim(Evidence(links, every, phi, split)))
            except _Missing:
                continue
    return claims


def _summary(runs):
    """:func:`mascore.compare.summarize` of deciding runs, by cell and sensing, with the blocks of each group."""

    by = list(_CELL)
    blocks = runs.groupby(by, dropna=False, sort=False)["blocks"].first().rename("blocks")
    return summarize(runs, by=by).join(blocks, on=by)


def differing_claims(first: Iterable, second: Iterable) -> list[dict[str, str]]:
    """The claims whose verdicts differ between two ledgers (e.g. the quick and the full grid).

    Parameters
    ----------
    first, second : iterable of Claim or dict
        Two lists of claims (:class:`mascore.ledger.Claim` or their records).

    Returns
    -------
    list of dict
        Per claim id in both with different verdicts: ``id``, ``first`` and ``second`` verdicts
        (``"fails (undecided)"`` for a claim its data cannot decide); a claim in one list only is
        listed with ``"absent"`` on the other side.

    Examples
    --------
    >>> from mascore.compare.verdicts import differing_claims
    >>> differing_claims([{"id": "compare/a", "verdict": "holds"}], [{"id": "compare/a", "verdict": "fails"}])
    [{'id': 'compare/a', 'first': 'holds', 'second': 'fails'}]
    """
    def verdicts(claims) -> dict[str, str]:
        out = {}
        for c in claims:
            record = c if isinstance(c, Mapping) else c.to_dict()
            out[str(record["id"])] = str(record["verdict"]) + (" (undecided)" if record.get("undecided") else "")
        return out

    a, b = verdicts(first), verdicts(second)
    return [{"id": i, "first": a.get(i, "absent"), "second": b.get(i, "absent")}
            for i in sorted(a.keys() | b.keys()) if a.get(i, "absent") != b.get(i, "absent")]
