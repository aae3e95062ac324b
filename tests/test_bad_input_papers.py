"""Bad input to the paper scenarios: clear errors naming the argument, and no unbounded retry loop."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mascore.papers import song2023 as rdv
from mascore.papers import song2023_flocking as flock


def test_flocking_initial_states_gives_up_with_a_clear_error_instead_of_hanging():
    """Issue 'Nothing silent': a sensing range that never connects the team used to loop forever."""
    tiny = dataclasses.replace(flock.SETTINGS, sensing_range=1e-3)
    with pytest.raises(ValueError, match="sensing_range"):
        flock.initial_states(np.random.default_rng(0), 1, tiny, max_tries=50)


@pytest.mark.parametrize("kwargs,name,error", [
    (dict(n_runs=0), "n_runs", ValueError),
    (dict(n_runs=1.5), "n_runs", TypeError),
    (dict(rng=-1), "rng", ValueError),
    (dict(settings=dataclasses.replace(flock.SETTINGS, n_agents=0)), "n_agents", ValueError),
])
def test_flocking_initial_states_names_bad_arguments(kwargs, name, error):
    args = dict(rng=np.random.default_rng(0), n_runs=1) | kwargs
    with pytest.raises(error, match=name):
        flock.initial_states(**args)


def test_rendezvous_initial_states_take_a_seed_and_name_bad_arguments():
    s = rdv.setup()
    x0_a, A_a = rdv.random_initial_states(5, s)
    x0_b, A_b = rdv.random_initial_states(np.random.default_rng(5), s)
    assert np.array_equal(x0_a, x0_b) and np.array_equal(A_a, A_b)
    with pytest.raises(ValueError, match="rng"):
        rdv.random_initial_states(-1, s)
    with pytest.raises(TypeError, match="RendezvousSetup"):
        rdv.random_initial_states(5, 3)
    with pytest.raises(ValueError, match="max_tries"):
        rdv.random_initial_states(5, s, max_tries=0)
