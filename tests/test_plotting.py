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


def test_figures_fit_the_book_column_with_legible_ticks():
    """A figure drawn wider than the column is narrowed, fonts kept: its tick labels render at 9 px or more."""
    plotting.use_style()
    for layout in ("constrained", None):
        fig, axes = plt.subplots(1, 3, figsize=(13, 3.8), layout=layout)
        assert fig.get_size_inches()[0] == pytest.approx(plotting.COLUMN_WIDTH)
        fig.canvas.draw()
        png_width = fig.get_size_inches()[0] * fig.dpi
        shown = min(1.0, 660 / png_width)  # the text column holds 660 px of image at 1280 px
        tick_px = axes[0].get_xticklabels()[0].get_fontsize() * fig.dpi / 72 * shown
        assert 0.72 * tick_px >= 9, f"digits {0.72 * tick_px:.1f} px high"
        plt.close(fig)


def test_long_titles_wrap_instead_of_running_together():
    plotting.use_style()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3), layout="constrained")
    for ax in axes:
        ax.set_title("(a) a title far too long to fit over a panel half the column wide, $x_{k+1}$ kept")
    fig.canvas.draw()
    assert all("\n" in ax.get_title() for ax in axes)
    assert all(ax.get_title().count("$") == 2 and "$x_{k+1}$" in ax.get_title() for ax in axes)
    plt.close(fig)


def test_crowded_agents_keep_their_numbers_visible():
    plotting.use_style()
    pos = np.array([[0.0, 0.0], [5.0, 0.0], [300.0, 300.0]])
    ax = plotting.plot_graph(pos, graphs.proximity_graph(pos, 50.0), sensing_range=50.0)
    offsets = {t.get_text(): t.get_position() for t in ax.texts}
    assert set(offsets) == {"1", "2", "3"}
    crowded = [t for t in ax.texts if t.get_text() in "12"]
    assert all(t.get_anncoords() == "offset points" for t in crowded)  # beside the marker, not under it
    plt.close("all")


def test_legend_overlap_is_measured_from_the_artists():
    """A legend over a line, over scatter markers, or a figure legend over a panel is found; one outside is not."""
    plotting.use_style()
    fig, (a, b) = plt.subplots(1, 2, figsize=(6.4, 3))
    a.plot([0, 1], [0.5, 0.5], label="flat")  # crosses the middle of the panel, between its two vertices only
    a.legend(loc="center")
    b.scatter([0.5], [0.5], label="dot")
    b.set(xlim=(0, 1), ylim=(0, 1))
    b.legend(loc="center")
    found = plotting.legend_overlaps(fig)
    assert found == ["panel 1: legend covers line 'flat'", "panel 2: legend covers markers 'dot'"], found
    for ax in (a, b):
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0))
    assert plotting.legend_overlaps(fig) == []
    a.get_legend().remove()
    b.get_legend().remove()
    fig.legend(*a.get_legend_handles_labels(), loc="center", bbox_to_anchor=(0.3, 0.5))  # a figure legend over panel 1
    a.set_xlim(-1, 2)
    assert any("line 'flat'" in o for o in plotting.legend_overlaps(fig))
    plt.close(fig)


def test_saved_figures_have_two_device_pixels_per_css_pixel(tmp_path):
    """A saved figure has twice the pixels of its layout at 100 dpi (the book shows it at that size)."""
    plotting.use_style()
    fig, ax = plt.subplots(figsize=(5.0, 3.0))
    ax.plot([0, 1], [0, 1])
    fig.canvas.draw()
    inches = fig.get_tightbbox(fig.canvas.get_renderer()).width
    path = plotting.save_figure(fig, tmp_path / "f.png")
    width = int.from_bytes(path.read_bytes()[16:20], "big")  # PNG header: IHDR width
    inches += 2 * matplotlib.rcParams["savefig.pad_inches"]  # the tight box and its padding
    assert width == pytest.approx(plotting.PIXEL_RATIO * 100 * inches, abs=3)
    assert plotting.PIXEL_RATIO >= 2


def test_legend_overlap_counts_patch_outlines_and_near_misses():
    plotting.use_style()
    fig, ax = plt.subplots(figsize=(4, 4))
    ax.add_patch(plt.Circle((0.5, 0.5), 0.05, fill=False, label="circle"))
    ax.set(xlim=(0, 1), ylim=(0, 1))
    ax.plot([0.5], [0.5], "o", label="centre")
    ax.legend(loc="center")
    assert any("outline" in o for o in plotting.legend_overlaps(fig))
    plt.close(fig)


def test_lines_labelled_by_a_shared_legend_of_colours_count_as_labelled():
    plotting.use_style()
    fig, (a, b) = plt.subplots(1, 2)
    for ax in (a, b):
        for i in range(6):
            ax.plot([0, 1, 2], [i, i + 1, i], color=f"C{i}")
    assert len(plotting.unlabelled_lines(fig)) == 2
    proxies = [plt.Line2D([], [], color=f"C{i}", label=f"agent {i + 1}") for i in range(6)]
    fig.legend(handles=proxies, loc="outside lower center", ncol=6)
    assert plotting.unlabelled_lines(fig) == []
    plt.close(fig)


def test_legend_covers_a_line_that_crosses_it_between_two_far_vertices():
    # the samples along each segment find it, horizontal and vertical segments (a zero step) included
    plotting.use_style()
    fig, ax = plt.subplots(figsize=(4, 4))
    ax.set(xlim=(0, 1), ylim=(0, 1))
    ax.plot([0.0, 1.0], [0.5, 0.5], label="across")                # horizontal, through the centre
    ax.plot([0.5, 0.5], [0.0, 1.0], label="up")                    # vertical, through the centre
    ax.plot([0.0, 0.2, 1.0], [0.02, 0.02, 0.03], label="below")     # along the bottom edge
    ax.legend(loc="center")
    found = plotting.legend_overlaps(fig)
    assert any("'across'" in o for o in found) and any("'up'" in o for o in found)
    assert not any("'below'" in o for o in found)
    plt.close(fig)
