"""Tests of mascore.plotting: figures carry labelled axes and refuse bad shapes."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from mascore import graphs, plotting  # noqa: E402


def test_trajectories_and_graph_are_labelled(tmp_path):
    plotting.use_style()
    p = np.cumsum(np.random.default_rng(0).standard_normal((20, 3, 2)), axis=0)
    ax = plotting.plot_trajectories(p)
    assert ax.get_xlabel() == "x (m)" and ax.get_ylabel() == "y (m)"
    assert len(ax.get_legend_handles_labels()[1]) == 3
    ax2 = plotting.plot_graph(p[0], graphs.complete_graph(3), sensing_range=1.0)
    assert len(ax2.patches) == 3  # one sensing circle per agent
    path = plotting.save_figure(ax2.figure, tmp_path / "sub" / "g.png")
    assert path.stat().st_size > 0
    plt.close("all")


def test_band_and_bad_shapes():
    t = np.linspace(0, 1, 5)
    ax = plotting.plot_band(t, t, t - 1, t + 1, label="x")
    assert len(ax.collections) == 1
    with pytest.raises(ValueError, match="center"):
        plotting.plot_band(t, t[:3])
    with pytest.raises(ValueError, match=r"\(T, N, 2\)"):
        plotting.plot_trajectories(np.zeros((4, 3)))
    with pytest.raises(ValueError, match="A"):
        plotting.plot_graph(np.zeros((3, 2)), np.zeros((2, 2)))
    plt.close("all")
