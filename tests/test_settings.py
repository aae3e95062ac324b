"""Settings that check themselves: every settings dataclass refuses a bad field by name, range and unit.

Issue "Hostile inputs", part 1: the settings of the papers and of the comparison are checked when
built and when ``dataclasses.replace``-d, from the same ``setting(...)`` declaration the book's
settings tables show.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mascore import _validation, compare
from mascore.registry import (
    allowed_values,
    check_settings,
    check_settings_type,
    documented_settings,
    setting,
    show_settings,
    study_modules,
)

SETTINGS = [m.SETTINGS for m in study_modules()] + [compare.SETTINGS]
IDS = [type(s).__name__ for s in SETTINGS]
FIELDS = [(s, f) for s in SETTINGS for f in dataclasses.fields(s)]


def _bad_values(f: dataclasses.Field, value):
    """Values the field's declaration forbids, each with the error expected."""
    meta = f.metadata
    kind, low, high = meta["kind"], meta["low"], meta["high"]
    if kind == "bool":
        return [("yes", TypeError)]
    if kind == "text":
        return [(3, TypeError)]
    if kind == "choice":
        return [("no such choice", ValueError)]
    if kind in ("real", "integer"):
        out = [("1", TypeError), (float("nan") if kind == "real" else 2.5, ValueError if kind == "real" else TypeError)]
        if low is not None:
            out.append((low - 1 if kind == "integer" else low - 1.0, ValueError))
        if high is not None:
            out.append((high + 1 if kind == "integer" else high * 2.0 + 1.0, ValueError))
        return out
    if kind in ("reals", "integers"):
        return [((), ValueError), (tuple(value[:-1]) + ("x",), TypeError)] + (
            [(tuple(value[:-1]) + (float("nan"),), ValueError if kind == "reals" else TypeError)])
    assert kind == "matrix"
    nan = tuple(tuple(row) for row in value[:-1]) + (tuple([float("nan")] * len(value[-1])),)
    return [(nan, ValueError), ("matrix", TypeError), (((1.0,), (1.0, 2.0)), TypeError)]


def test_every_settings_field_declares_what_it_accepts():
    for settings, f in FIELDS:
        assert f.metadata.get("kind"), f"{type(settings).__name__}.{f.name} is not declared with setting(...)"
        assert allowed_values(f.metadata)


@pytest.mark.parametrize("settings", SETTINGS, ids=IDS)
def test_defaults_pass_and_replace_keeps_them(settings):
    check_settings(settings)
    assert dataclasses.replace(settings) == settings
    hash(settings)


@pytest.mark.parametrize("settings,field", FIELDS, ids=[f"{type(s).__name__}.{f.name}" for s, f in FIELDS])
def test_replace_refuses_a_bad_field_by_its_name(settings, field):
    name = f"{type(settings).__name__}.{field.name}"
    for bad, error in _bad_values(field, getattr(settings, field.name)):
        with pytest.raises(error, match=name.replace(".", r"\.")):
            dataclasses.replace(settings, **{field.name: bad})


def test_message_has_range_and_unit():
    from mascore.papers import song2023

    with pytest.raises(ValueError, match=r"^RendezvousSettings\.dt must be a finite number > 0 s; got -0\.1$"):
        dataclasses.replace(song2023.SETTINGS, dt=-0.1)
    with pytest.raises(ValueError, match=r"fig2_max_edge_fraction must be a finite number in \(0, 1\]"):
        dataclasses.replace(song2023.SETTINGS, fig2_max_edge_fraction=1.5)
    with pytest.raises(TypeError, match=r"RendezvousSettings\.fig3_runs must be an integer >= 1; got 2\.5"):
        song2023.RendezvousSettings(fig3_runs=2.5)


def test_lists_and_arrays_become_tuples():
    from mascore.papers import song2023_flocking as flock

    s = dataclasses.replace(flock.SETTINGS, beyond_sizes=[4, 8], beyond_sensing_ranges=np.array([150.0, 200.0]))
    assert s.beyond_sizes == (4, 8) and s.beyond_sensing_ranges == (150.0, 200.0)
    hash(s)


def test_settings_table_shows_the_allowed_values():
    from mascore.papers import ren2005

    table = str(show_settings(ren2005.SETTINGS))
    assert table.splitlines()[0] == "| setting | value | allowed values | from | note |"
    assert "| `n_steps` | 100 | whole number \u2265 1 |" in table  # a reader's words, not the validator's
    assert "finite" not in table and "tuple" not in table
    assert "Allowed: a finite number > 0 h²." in ren2005.KalmanConsensusSettings.__doc__


def test_documented_settings_needs_a_post_init_that_checks():
    @dataclasses.dataclass(frozen=True)
    class Unchecked:
        dt: float = setting(0.1, unit="s", low=0, low_open=True)

    with pytest.raises(TypeError, match="check_settings"):
        documented_settings(Unchecked)


def test_setting_declarations_are_checked():
    with pytest.raises(ValueError, match="kind"):
        setting(0.1, kind="complex")
    with pytest.raises(ValueError, match="choices"):
        setting("a", kind="choice")
    with pytest.raises(ValueError, match="infer"):
        setting(None)


def test_check_settings_type_names_the_argument():
    from mascore.papers import ren2005

    with pytest.raises(TypeError, match="settings must be a KalmanConsensusSettings"):
        ren2005.fig1_initial(True, settings="settings")
    with pytest.raises(TypeError, match="scenario must be a Sentinel"):
        check_settings_type(3, type("Sentinel", (), {}), "scenario")


def test_memory_guard_refuses_what_cannot_fit():
    assert _validation.available_memory_bytes() > 0
    _validation.check_fits_in_memory(1024, "n_runs")
    with pytest.raises(ValueError, match="n_runs asks for too much"):
        _validation.check_fits_in_memory(1e30, "n_runs", "the states")
    with pytest.raises(ValueError, match="n_runs"):
        _validation.check_fits_in_memory(math.inf, "n_runs")


def test_sizes_that_multiply_are_refused_up_front():
    from mascore.papers import ren2005, song2023, song2023_flocking

    with pytest.raises(ValueError, match=r"KalmanConsensusSettings\.noise_runs x noise_steps asks for too much"):
        dataclasses.replace(ren2005.SETTINGS, noise_runs=10**12)
    with pytest.raises(ValueError, match=r"RendezvousSettings\.fig3_runs x horizon / dt asks for too much"):
        dataclasses.replace(song2023.SETTINGS, fig3_runs=10**12)
    with pytest.raises(ValueError, match=r"FlockingSettings\.n_runs x t_final / dt asks for too much"):
        dataclasses.replace(song2023_flocking.SETTINGS, n_runs=10**12)
    with pytest.raises(ValueError, match=r"KalmanConsensusSettings\.bias_runs x n_steps asks for too much"):
        dataclasses.replace(ren2005.SETTINGS, n_steps=10**12)  # the setting changed is in the name it gives
