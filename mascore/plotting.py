"""One figure style for the whole book, and the plots every paper reuses.

Functions take data and an optional matplotlib ``Axes`` and return the Axes
(compute and draw stay apart). Call :func:`use_style` once per notebook.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ._optional import require
from ._validation import as_matrix, check_fits_in_memory, check_positive, check_positive_int, float_array

mpl = require("matplotlib", "mascore.plotting")
plt = require("matplotlib.pyplot", "mascore.plotting")
from matplotlib.layout_engine import ConstrainedLayoutEngine, TightLayoutEngine  # noqa: E402  (after the check)

__all__ = [
    "COLUMN_WIDTH",
    "PIXEL_RATIO",
    "STYLE",
    "agent_colors",
    "fit_to_column",
    "legend_overlaps",
    "new_axes",
    "plot_band",
    "plot_graph",
    "plot_trajectories",
    "save_figure",
    "unlabelled_lines",
    "use_style",
]

#: Width (inches) of the book's figures at 100 dpi: a figure's image is 650 CSS px wide at most, the
#: text column of a 1280 px window. A wider figure would be shrunk by the browser, and its 10 pt tick
#: labels with it (below 9 px at 13 in).
COLUMN_WIDTH = 6.5

#: Device pixels per CSS pixel of the book's images: every figure is rendered at twice its size
#: (200 dpi for a 100 dpi layout) and shown at its size, sharp on a HiDPI ("retina") screen.
PIXEL_RATIO = 2

#: rcParams of the book's figures. ``figure.hooks`` fits every pyplot figure to the column
#: (:func:`fit_to_column`), so a figure drawn wider keeps its fonts readable. Files are saved at
#: :data:`PIXEL_RATIO` x 100 dpi; a notebook shows its figures the same way (:func:`use_style`).
STYLE = {
    "figure.figsize": (6.4, 4.0),
    "figure.dpi": 100,
    "savefig.dpi": 100 * PIXEL_RATIO,
    "savefig.bbox": "tight",
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "axes.titlesize": "medium",
    "axes.labelsize": "medium",
    "legend.fontsize": "small",
    "legend.frameon": False,
    "lines.linewidth": 1.4,
    "image.cmap": "viridis",
    "figure.autolayout": True,  # tight layout unless a figure asks for another (e.g. constrained)
    "figure.hooks": ["mascore.plotting:fit_to_column"],
}


def use_style() -> None:
    """Apply the book's figure style (:data:`STYLE`) to matplotlib's global rcParams.

    Call it once per notebook, before drawing. In a notebook (IPython's inline backend) it also
    shows figures at twice their pixels ("retina" PNG: 200 dpi, displayed at the size of 100 dpi),
    as the files of :func:`save_figure` are saved.

    Examples
    --------
    >>> import matplotlib as mpl
    >>> from mascore.plotting import STYLE, use_style
    >>> use_style()
    >>> all(mpl.rcParams[key] == value for key, value in STYLE.items() if not isinstance(value, (list, tuple)))
    True
    """
    mpl.rcParams.update(STYLE)
    _inline_at_pixel_ratio()


def _inline_at_pixel_ratio() -> None:
    """Inline figures of a running IPython kernel as 2x PNG shown at 1x (nothing outside IPython)."""
    import sys

    if "IPython" not in sys.modules:
        return
    from IPython import get_ipython

    shell = get_ipython()
    if shell is None or getattr(shell, "kernel", None) is None:
        return
    from matplotlib_inline.backend_inline import set_matplotlib_formats

    set_matplotlib_formats("retina")


def fit_to_column(fig: plt.Figure, width: float = COLUMN_WIDTH) -> plt.Figure:
    """Narrow a figure wider than the book's text column to the column's width.

    The fonts keep their size, so they are read at their size in the book instead of
    being shrunk with the image. The height shrinks by the square root of the width's
    factor (panels side by side stay tall enough); the figure's layout engine (constrained,
    or tight by the style's ``figure.autolayout``) fits the labels to the new size, after
    breaking any Axes title wider than its Axes into two lines.
    :func:`use_style` runs it on every figure pyplot creates (rcParams ``figure.hooks``).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure (typically still empty, just created).
    width : float
        Largest width in inches (default :data:`COLUMN_WIDTH`).

    Returns
    -------
    matplotlib.figure.Figure
        `fig`, resized in place.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore.plotting import fit_to_column
    >>> fig = fit_to_column(plt.figure(figsize=(13.6, 4.0)))
    >>> [round(float(v), 2) for v in fig.get_size_inches()]
    [6.5, 2.77]
    >>> plt.close("all")
    """
    w, h = fig.get_size_inches()
    if w > width:
        fig.set_size_inches(width, h * np.sqrt(width / w))
    engine = fig.get_layout_engine()
    if type(engine) is ConstrainedLayoutEngine:
        fig.set_layout_engine(_TitleWrappingConstrained(**engine.get(), compress=engine._compress))
    elif type(engine) is TightLayoutEngine:
        fig.set_layout_engine(_TitleWrappingTight(**engine.get()))
    return fig


def _wrap_titles(fig: plt.Figure) -> None:
    """Break an Axes title (or x label) wider than its Axes into two lines, at the space (outside math) nearest
    its middle: a figure narrowed to the column would otherwise run neighbouring titles together."""
    renderer = fig._get_renderer()
    for ax in fig.findobj(mpl.axes.Axes):
        width = ax.get_window_extent(renderer).width
        for title in (ax.title, getattr(ax, "_left_title", None), getattr(ax, "_right_title", None), ax.xaxis.label):
            text = title.get_text() if title is not None else ""
            if not text or "\n" in text or title.get_window_extent(renderer).width <= 0.95 * width:
                continue
            spaces = [i for i, c in enumerate(text) if c == " " and text[:i].count("$") % 2 == 0]
            if spaces:
                cut = min(spaces, key=lambda i: abs(i - len(text) / 2))
                title.set_text(text[:cut] + "\n" + text[cut + 1:])


class _TitleWrappingConstrained(ConstrainedLayoutEngine):
    """The constrained layout, after :func:`_wrap_titles`."""

    def execute(self, fig):
        _wrap_titles(fig)
        return super().execute(fig)


class _TitleWrappingTight(TightLayoutEngine):
    """The tight layout, after :func:`_wrap_titles`."""

    def execute(self, fig):
        _wrap_titles(fig)
        return super().execute(fig)


def agent_colors(n_agents: int) -> list:
    """N distinguishable colours, the same agent always getting the same one.

    Parameters
    ----------
    n_agents : int
        Number of agents N (tab10 up to 10 agents, tab20 beyond, cycling).

    Returns
    -------
    list of RGBA tuples
        Colour of agent ``i`` at index ``i``.

    Examples
    --------
    >>> from mascore.plotting import agent_colors
    >>> colors = agent_colors(3)
    >>> len(colors), len(colors[0])
    (3, 4)
    """
    n_agents = check_positive_int(n_agents, "n_agents")
    check_fits_in_memory(100.0 * n_agents, "n_agents", "one colour per agent")
    cmap = plt.get_cmap("tab10" if n_agents <= 10 else "tab20")
    return [cmap(i % cmap.N) for i in range(n_agents)]


def new_axes(ax: plt.Axes | None = None, **subplots_kw) -> plt.Axes:
    """Return `ax`, or a fresh Axes in a new figure.

    Parameters
    ----------
    ax : matplotlib.axes.Axes, optional
        Axes to draw on.
    **subplots_kw
        Passed to ``plt.subplots`` when a new figure is made (e.g. ``figsize``).

    Returns
    -------
    matplotlib.axes.Axes
        `ax` itself, or the new Axes.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore.plotting import new_axes
    >>> ax = new_axes(figsize=(3, 2))
    >>> new_axes(ax) is ax
    True
    >>> plt.close("all")
    """
    if ax is not None:
        return ax
    _, ax = plt.subplots(**subplots_kw)
    return ax


def plot_trajectories(
    positions: ArrayLike,
    ax: plt.Axes | None = None,
    labels: Sequence[str] | None = None,
    marker_start: str = "o",
    marker_end: str = "s",
    unit: str = "m",
    **line_kw,
) -> plt.Axes:
    """Plot planar trajectories of a team: one colour per agent, start and end marked.

    Parameters
    ----------
    positions : (T, N, 2) array_like
        Positions over time (in `unit`).
    ax : matplotlib.axes.Axes, optional
        Axes to draw on (default: a new figure).
    labels : sequence of str, optional
        Legend labels per agent (default "agent 1", ...).
    marker_start, marker_end : str
        Markers of the first and last positions.
    unit : str
        Unit of the positions, for the axis labels.
    **line_kw
        Passed to ``Axes.plot`` for the paths.

    Returns
    -------
    matplotlib.axes.Axes
        The axes, with equal aspect and labelled ``x (unit)``, ``y (unit)``.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> import numpy as np
    >>> from mascore.plotting import plot_trajectories
    >>> ax = plot_trajectories(np.cumsum(np.ones((10, 3, 2)), axis=0))
    >>> ax.get_xlabel()
    'x (m)'
    >>> plt.close("all")
    """
    p = float_array(positions, "positions")
    if p.ndim != 3 or p.shape[-1] != 2:
        raise ValueError(f"positions must have shape (T, N, 2); got {p.shape}")
    ax = new_axes(ax)
    n_agents = p.shape[1]
    labels = labels or [f"agent {i + 1}" for i in range(n_agents)]
    for i, color in enumerate(agent_colors(n_agents)):
        ax.plot(p[:, i, 0], p[:, i, 1], color=color, label=labels[i], **line_kw)
        ax.plot(*p[0, i], marker_start, color=color, ms=5)
        ax.plot(*p[-1, i], marker_end, color=color, ms=5, mfc="none")
    return _plane_axes(ax, unit)


def plot_graph(
    positions: ArrayLike,
    A: ArrayLike,
    ax: plt.Axes | None = None,
    sensing_range: float | None = None,
    unit: str = "m",
    directed: bool | None = None,
    node_labels: bool = True,
) -> plt.Axes:
    """Draw a graph at given node positions, optionally with sensing circles.

    Parameters
    ----------
    positions : (N, 2) array_like
        Node positions (in `unit`).
    A : (N, N) array_like
        Adjacency, ``A[i, j] > 0`` for the edge ``j -> i``.
    ax : matplotlib.axes.Axes, optional
        Axes to draw on (default: a new figure).
    sensing_range : float, optional
        Radius of a dashed circle drawn around each agent.
    unit : str
        Unit of the positions, for the axis labels.
    directed : bool, optional
        Draw arrows; defaults to "is `A` asymmetric".
    node_labels : bool
        Number the agents from 1.

    Returns
    -------
    matplotlib.axes.Axes
        The axes.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore import graphs
    >>> from mascore.plotting import plot_graph
    >>> pos = [[0.0, 0.0], [100.0, 0.0], [50.0, 80.0]]
    >>> ax = plot_graph(pos, graphs.proximity_graph(pos, 150.0), sensing_range=150.0)
    >>> len(ax.patches)                                   # one sensing circle per agent
    3
    >>> plt.close("all")
    """
    p = as_matrix(positions, "positions", (None, 2))
    A = as_matrix(A, "A", (p.shape[0], p.shape[0]))
    if sensing_range is not None:
        sensing_range = check_positive(sensing_range, "sensing_range")
    ax = new_axes(ax)
    colors = agent_colors(p.shape[0])
    directed = (not np.allclose(A, A.T)) if directed is None else directed
    for i, j in zip(*np.nonzero(A)):
        if directed:
            ax.annotate("", xy=p[i], xytext=p[j],
                        arrowprops=dict(arrowstyle="-|>", color="0.4", lw=1.0, shrinkA=7, shrinkB=7))
        elif i > j:
            ax.plot(*p[[i, j]].T, color="0.5", lw=1.0, zorder=1)
    for i, color in enumerate(colors):
        if sensing_range is not None:
            ax.add_patch(plt.Circle(p[i], sensing_range, fill=False, ls="--", lw=0.8, color=color))
        ax.plot(*p[i], "o", color=color, ms=9, zorder=2)
    if node_labels:
        _node_labels(ax, p, colors, np.argwhere(A + A.T > 0))
    return _plane_axes(ax, unit)


def _node_labels(ax: plt.Axes, p: np.ndarray, colors: list, edges: np.ndarray) -> None:
    """Number the agents inside their markers; an agent crowded by a neighbour gets its number
    beside the marker, in the free direction: of eight around it, the one farthest from the other
    agents, the edges (pairs of agent indices) and the numbers already placed, so that no number is
    covered or runs into another."""
    ax.autoscale_view()
    span = max(np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()))
    d = np.linalg.norm(p[:, None] - p[None], axis=-1) + np.diag(np.full(len(p), np.inf))
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    compass = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    placed: list[np.ndarray] = []
    for i, color in enumerate(colors):
        if len(p) > 1 and d[i].min() < 0.08 * span:
            spots = p[i] + 0.045 * span * compass
            obstacles = [np.delete(p, i, axis=0), *placed]
            clearance = np.min(np.linalg.norm(spots[:, None] - np.concatenate(
                [np.reshape(o, (-1, 2)) for o in obstacles])[None], axis=-1), axis=1)
            for a, b in edges:
                clearance = np.minimum(clearance, _distance_to_segment(spots, p[a], p[b]))
            away = compass[int(np.argmax(clearance))]
            placed.append(spots[int(np.argmax(clearance))])
            ax.annotate(str(i + 1), p[i], xytext=11 * away, textcoords="offset points", ha="center", va="center",
                        fontsize=8, fontweight="bold", color=color, zorder=3)
        else:
            ax.annotate(str(i + 1), p[i], ha="center", va="center", fontsize=7, color="white", zorder=3)


def _distance_to_segment(x: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point of `x` (k, 2) to the segment from `a` to `b`."""
    ab = b - a
    t = np.clip(((x - a) @ ab) / max(float(ab @ ab), 1e-300), 0.0, 1.0)
    return np.linalg.norm(x - (a + t[:, None] * ab), axis=1)


def _plane_axes(ax: plt.Axes, unit: str) -> plt.Axes:
    """Label the x-y plane in `unit` and keep its aspect ratio."""
    ax.set_xlabel(f"x ({unit})")
    ax.set_ylabel(f"y ({unit})")
    ax.set_aspect("equal", adjustable="datalim")
    return ax


def plot_band(
    t: ArrayLike,
    center: ArrayLike,
    low: ArrayLike | None = None,
    high: ArrayLike | None = None,
    ax: plt.Axes | None = None,
    label: str | None = None,
    color=None,
    alpha: float = 0.25,
) -> plt.Axes:
    """A time series with a shaded band (e.g. a mean and a percentile range).

    Parameters
    ----------
    t : (T,) array_like
        Time axis.
    center : (T,) array_like
        The line.
    low, high : (T,) array_like, optional
        Lower and upper edge of the band (both or neither).
    ax : matplotlib.axes.Axes, optional
        Axes to draw on (default: a new figure).
    label : str, optional
        Legend label of the line.
    color : optional
        Colour of line and band (default: the next colour of the cycle).
    alpha : float
        Opacity of the band.

    Returns
    -------
    matplotlib.axes.Axes
        The axes.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> import numpy as np
    >>> from mascore.plotting import plot_band
    >>> t = np.linspace(0.0, 1.0, 5)
    >>> ax = plot_band(t, t, t - 0.1, t + 0.1, label="mean")
    >>> len(ax.lines), len(ax.collections)
    (1, 1)
    >>> plt.close("all")
    """
    t, center = float_array(t, "t"), float_array(center, "center")
    for name, value in (("center", center), ("low", low), ("high", high)):
        if value is not None and float_array(value, name).shape != t.shape:
            raise ValueError(f"{name} must have the shape of t {t.shape}; got {float_array(value, name).shape}")
    ax = new_axes(ax)
    (line,) = ax.plot(t, center, color=color, label=label)
    if low is not None and high is not None:
        ax.fill_between(t, low, high, color=line.get_color(), alpha=alpha, lw=0)
    return ax


def save_figure(fig: plt.Figure, path: str | Path) -> Path:
    """Save `fig` (creating folders) and close it.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    path : str or pathlib.Path
        File to write; the format follows the suffix.

    Returns
    -------
    pathlib.Path
        The path written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> import matplotlib.pyplot as plt
    >>> from mascore.plotting import save_figure
    >>> fig, ax = plt.subplots()
    >>> out = save_figure(fig, pathlib.Path(tempfile.mkdtemp()) / "sub" / "fig.png")
    >>> out.exists()
    True
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def legend_overlaps(fig: plt.Figure, samples_per_px: float = 0.5, margin_px: float = 2.0) -> list[str]:
    """Legends of `fig` that cover plotted data: one line per (legend, artist) pair that overlaps.

    Every legend (of an Axes or of the figure) is checked against the data of every Axes it
    lies over, in display pixels after the figure is drawn: the vertices of each visible line
    and the segments between them (sampled every ``1 / samples_per_px`` px, so a line crossing
    the legend between two vertices counts), the outlines of its patches (circles, ellipses,
    polygons) and the points of each scatter. Grid lines and a legend's own handles do not
    count. A legend placed outside the axes covers nothing.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure, as it will be saved.
    samples_per_px : float
        Sampling density of line segments (points per display pixel).
    margin_px : float
        Data closer than this to the legend's box counts as covered (display pixels at the
        figure's dpi): a legend touching a curve reads as lying on it.

    Returns
    -------
    list of str
        ``"panel 2 ('title'): legend covers line 'agent 3'"`` for each overlap; empty when no
        legend covers data.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore.plotting import legend_overlaps
    >>> fig, ax = plt.subplots()
    >>> _ = ax.plot([0, 1], [0, 1], label="rising")
    >>> _ = ax.legend(loc="center")
    >>> legend_overlaps(fig)
    ["panel 1: legend covers line 'rising'"]
    >>> _ = ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1))
    >>> legend_overlaps(fig)
    []
    >>> plt.close(fig)
    """
    if not isinstance(fig, mpl.figure.Figure):
        raise TypeError(f"fig must be a matplotlib Figure; got {type(fig).__name__}")
    fig.draw_without_rendering()  # the layout and every artist's extent, without rasterizing the figure
    axes = [ax for ax in fig.axes if ax.get_visible()]
    legends = [(ax.get_legend(), [ax]) for ax in axes if ax.get_legend() is not None]
    legends += [(leg, axes) for leg in fig.legends]
    out = []
    for legend, covered in legends:
        if not legend.get_visible():
            continue
        box = legend.get_window_extent().padded(margin_px)
        for ax in covered:
            name = f"panel {fig.axes.index(ax) + 1}" + (f" ({ax.get_title()!r})" if ax.get_title() else "")
            for artist, kind, points in _data_points(ax, samples_per_px):
                inside = ((points[:, 0] > box.x0) & (points[:, 0] < box.x1)
                          & (points[:, 1] > box.y0) & (points[:, 1] < box.y1))
                clip = ax.get_window_extent()  # data outside the panel is not drawn
                inside &= ((points[:, 0] >= clip.x0) & (points[:, 0] <= clip.x1)
                           & (points[:, 1] >= clip.y0) & (points[:, 1] <= clip.y1))
                if inside.any():
                    label = artist.get_label()
                    out.append(f"{name}: legend covers {kind}" + (f" {label!r}" if not label.startswith("_") else ""))
    return out


def _style(line) -> tuple[str, str]:
    """Colour and line style of a line, the way a legend entry shows it."""
    return mpl.colors.to_hex(line.get_color()), str(line.get_linestyle())


def _data_points(ax: plt.Axes, samples_per_px: float):
    """(artist, kind, display points) of the visible lines and patch outlines (sampled along their
    segments) and scatters."""
    for line in ax.get_lines():
        if not line.get_visible():
            continue
        xy = line.get_transform().transform(np.asarray(line.get_xydata(), dtype=float))
        if line.get_linestyle() not in ("None", "none", "", " "):
            xy = _along(xy, samples_per_px)
        if len(xy):
            yield line, "line", xy[np.all(np.isfinite(xy), axis=1)]
    for patch in ax.patches:
        if patch.get_visible():
            path = patch.get_path().interpolated(8)
            xy = _along(patch.get_transform().transform(path.vertices), samples_per_px)
            if len(xy):
                yield patch, "outline", xy
    for coll in ax.collections:
        if coll.get_visible() and isinstance(coll, mpl.collections.PathCollection) and len(coll.get_offsets()):
            xy = coll.get_offset_transform().transform(np.asarray(coll.get_offsets(), dtype=float))
            yield coll, "markers", xy[np.all(np.isfinite(xy), axis=1)]


def _along(xy: np.ndarray, samples_per_px: float) -> np.ndarray:
    """Points along the polyline `xy` (k, 2), about `samples_per_px` per pixel (non-finite vertices dropped)."""
    xy = xy[np.all(np.isfinite(xy), axis=1)]
    if len(xy) < 2:
        return xy
    steps = np.maximum(np.ceil(np.linalg.norm(np.diff(xy, axis=0), axis=1) * samples_per_px), 1).astype(int)
    # every segment's np.linspace(a, b, n, endpoint=False) at once, with its arithmetic: j (b - a) / n, or
    # (j / n) (b - a) for a segment with a zero step in x or y, plus a
    a, delta = xy[:-1], np.diff(xy, axis=0)
    step = delta / steps[:, None]
    first = np.repeat(np.cumsum(steps) - steps, steps)
    j = (np.arange(first.size) - first).astype(float)[:, None]  # the sample's index in its segment
    seg = np.repeat(np.arange(len(steps)), steps)
    flat = np.any(step == 0, axis=1)[seg, None]
    points = np.where(flat, j / steps[seg, None] * delta[seg], j * step[seg]) + a[seg]
    return np.concatenate([points, xy[-1:]])


def unlabelled_lines(fig: plt.Figure, limit: int = 5) -> list[str]:
    """Panels of `fig` with more than `limit` data lines a reader cannot tell apart by a legend entry.

    A line counts as labelled when its label is the text of an entry of a legend of the figure (its
    panel's or a figure legend), or when it has the colour and line style of an entry's handle (a
    legend of the agents' colours drawn once for all panels); reference lines drawn across the whole panel (``axhline``,
    ``axvline``, any line of two points) do not count.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
        The figure.
    limit : int
        Most unlabelled lines a panel may show.

    Returns
    -------
    list of str
        ``"panel 2 ('title'): 8 unlabelled lines"`` for each panel over the limit.

    Examples
    --------
    >>> import matplotlib.pyplot as plt
    >>> from mascore.plotting import unlabelled_lines
    >>> fig, ax = plt.subplots()
    >>> _ = ax.plot([[0, 1, 2, 3, 4, 5]] * 3)  # six lines of three points
    >>> unlabelled_lines(fig)
    ['panel 1: 6 unlabelled lines']
    >>> for i, line in enumerate(ax.get_lines()):
    ...     line.set_label(f"agent {i}")
    >>> _ = ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0))
    >>> unlabelled_lines(fig)
    []
    >>> plt.close(fig)
    """
    if not isinstance(fig, mpl.figure.Figure):
        raise TypeError(f"fig must be a matplotlib Figure; got {type(fig).__name__}")
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None] + list(fig.legends)
    entries = {t.get_text() for leg in legends for t in leg.get_texts()}
    styles = {_style(h) for leg in legends for h in leg.legend_handles if isinstance(h, mpl.lines.Line2D)}
    out = []
    for n, ax in enumerate(fig.axes, 1):
        lines = [ln for ln in ax.get_lines() if ln.get_visible() and len(ln.get_xydata()) > 2
                 and ln.get_label() not in entries and _style(ln) not in styles]
        if len(lines) > limit:
            out.append(f"panel {n}" + (f" ({ax.get_title()!r})" if ax.get_title() else "")
                       + f": {len(lines)} unlabelled lines")
    return out
