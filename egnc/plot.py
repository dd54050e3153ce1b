"""Figures of a solve and of the SIG kernel, drawn with matplotlib (the `plot` extra).

- `plot_trajectory`: the optimized trajectory (2D or 3D), optionally the initial guess and a
  reference, with accepted and rejected loop closures, each in its own colour, and a legend;
  `size` (inches) for a new figure, equal scale on every axis (also in 3D).
- `plot_mu_stages`: per-stage statistics of the kernel parameter `mu` and a histogram of the
  final per-factor `mu`.
- `plot_kernel`: the SIG kernel `rho(r; mu)` and its second derivative for several `mu`.
- `plot_mu_star`: the convexity boundary `mu*(r)` and its asymptote 1/2.
- `save_figure`: write a figure atomically (the file is complete or not there), at a chosen `dpi`.

matplotlib is imported inside the functions, so `import egnc.plot` works without it; calling a
plot function without it raises `EgncError` with the install command. The figures are plain
`matplotlib.figure.Figure` objects, not pyplot figures: they need no GUI backend and are freed
like any object. To draw into a pyplot window instead, pass `ax` (or `axes`) made by pyplot.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from egnc.api import Result
from egnc.errors import EgncError
from egnc.graph import PoseGraph
from egnc.io.atomic import atomic_binary_file
from egnc.robust.kernels import make_kernel
from egnc.robust.mu_star import mu_star

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d import Axes3D

__all__ = [
    "crowd_style",
    "plot_kernel",
    "plot_mu_stages",
    "plot_mu_star",
    "plot_trajectory",
    "require_matplotlib",
    "save_figure",
]

INSTALL_HINT = "pip install 'egnc[plot]'"
"""How to get matplotlib; quoted in the error raised without it."""

# One palette for every figure, so a colour means the same thing everywhere; each element of a
# trajectory figure has its own: a dark blue result over a grey guess, green and red loops.
RESULT_COLOR = "#1f3b73"
INITIAL_COLOR = "0.6"
REFERENCE_COLOR = "#9467bd"
ACCEPTED_COLOR = "#009e73"
REJECTED_COLOR = "#d62728"

THREE_D_ZOOM = 1.15
"""Scale of the 3D box in its axes: matplotlib's 1 leaves a wide empty margin; more cuts the labels."""

CROWD_ALPHA = (0.12, 0.9)
"""Opacity range of a set of loop-closure lines: opaque when few, down to the floor when many."""
CROWD_WIDTH = (0.3, 1.0)
"""Line width range in points of a set of loop-closure lines, thinner as they get more."""


def require_matplotlib() -> None:
    """Check that matplotlib can be imported.

    Raises:
        EgncError: matplotlib is not installed (the message says `pip install 'egnc[plot]'`).
    """
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise EgncError(f"plotting needs matplotlib, which is not installed: {INSTALL_HINT}") from None


def figure_format(path: str | Path) -> str:
    """The file format a figure at `path` is written in: its suffix, `png` without one.

    Raises:
        EgncError: matplotlib is missing, or cannot write that format.
    """
    require_matplotlib()
    from matplotlib.backend_bases import FigureCanvasBase

    path = Path(path)
    file_format = path.suffix[1:].lower() or "png"
    supported = FigureCanvasBase.get_supported_filetypes()
    if file_format not in supported:
        raise EgncError(f"{path}: cannot write figures as {file_format!r}; use one of {', '.join(sorted(supported))}")
    return file_format


def plot_trajectory(
    result_or_graph: Result | PoseGraph,
    *,
    initial: PoseGraph | np.ndarray | None = None,
    reference: PoseGraph | np.ndarray | None = None,
    inliers: np.ndarray | None = None,
    known_inliers: np.ndarray | None = None,
    ax: Axes | None = None,
    size: tuple[float, float] | None = None,
) -> Figure:
    """Draw a trajectory with its loop closures: x-y for a 2D graph, x-y-z (3D axes) for a 3D one.

    The trajectory is the line through the poses in id order, in dark blue; the initial guess is
    grey and a reference purple and dotted. Loop closures (edges that are not known inliers,
    odometry by default) are drawn between their poses on that trajectory, accepted ones in green
    and rejected ones in red-orange; the more there are of a kind, the thinner and more
    translucent its lines (`crowd_style`), so hundreds of rejected loops do not hide the map. The
    legend names each element with its count. Both kinds of axes have an equal scale on every
    axis (in 3D, the box takes the data's proportions).

    Args:
        result_or_graph: a `Result` (its optimized graph, `inliers` and `known_inliers` are used,
            and its method and rejection count become the title) or a `PoseGraph`.
        initial: the trajectory before optimization, drawn in grey: a `PoseGraph` or its
            `(N, P)` poses (P = 3 in 2D, 7 in 3D), same rows as the graph.
        reference: a reference trajectory (e.g. ground truth), drawn in purple; same forms.
        inliers: `(E,)` bool, false for rejected edges; defaults to the result's (a bare graph has
            no rejected edges).
        known_inliers: `(E,)` bool, edges that are not drawn as loop closures; defaults to the
            result's, or to the graph's odometry.
        ax: draw here instead of in a new figure; must be a 3D axes (`projection="3d"`) for a
            3D graph and a 2D one for a 2D graph.
        size: `(width, height)` of the new figure in inches; default `(6.4, 6.0)` in 2D and
            `(7.0, 5.6)` in 3D. Not with `ax` (its figure has a size already).

    Returns:
        The `Figure` holding the axes.

    Raises:
        EgncError: matplotlib is missing, or an argument has the wrong shape, value or axes type.
    """
    require_matplotlib()
    if size is not None:
        if ax is not None:
            raise EgncError("size sets the size of a new figure; it cannot be given with ax")
        size = _figure_size(size)
    graph = result_or_graph if isinstance(result_or_graph, PoseGraph) else result_or_graph.graph
    result = None if isinstance(result_or_graph, PoseGraph) else result_or_graph
    candidates, accepted, rejected = _loop_closure_masks(graph, result, inliers, known_inliers)

    own_figure = ax is None
    default_size = (7.0, 5.6) if graph.dim == 3 else (6.4, 6.0)
    figure, ax = _single_axes(ax, three_d=graph.dim == 3, figsize=size or default_size)
    if (ax.name == "3d") != (graph.dim == 3):
        raise EgncError(f"a {graph.dim}D graph needs a {'3D' if graph.dim == 3 else '2D'} axes")
    drawn = _draw_lines(ax, graph, result is not None, initial, reference, accepted, rejected)
    _label_axes(ax, graph.dim, drawn)
    if result is not None and not ax.get_title():
        ax.set_title(f"{result.method}: rejected {int(rejected.sum())} of {int(candidates.sum())} loop closures")
    _add_legend(figure, ax, own_figure)
    return figure


def _draw_lines(
    ax: Axes,
    graph: PoseGraph,
    solved: bool,
    initial: PoseGraph | np.ndarray | None,
    reference: PoseGraph | np.ndarray | None,
    accepted: np.ndarray,
    rejected: np.ndarray,
) -> np.ndarray:
    """Draw `plot_trajectory`'s lines, bottom to top: accepted loops, guess, reference, trajectory,
    rejected loops; `solved` names them as a result's. Returns the `(M, dim)` points drawn."""
    position = _positions(graph, graph.poses, "result")
    segments = np.stack([position[graph.edges[:, 0]], position[graph.edges[:, 1]]], axis=1)
    _add_segments(
        ax,
        segments[accepted],
        color=ACCEPTED_COLOR,
        zorder=1,
        label=f"accepted loop closures ({int(accepted.sum())})" if solved else "loop closures",
        **crowd_style(int(accepted.sum())),
    )
    drawn = [position]
    if initial is not None:
        drawn.append(_positions(graph, initial, "initial"))
        _draw_path(ax, drawn[-1], color=INITIAL_COLOR, linewidth=0.8, zorder=2, label="initial guess")
    if reference is not None:
        drawn.append(_positions(graph, reference, "reference"))
        _draw_path(ax, drawn[-1], color=REFERENCE_COLOR, linewidth=1.0, linestyle=":", zorder=3, label="reference")
    _draw_path(ax, position, color=RESULT_COLOR, linewidth=1.1, zorder=4, label="result" if solved else "trajectory")
    if rejected.any():
        _add_segments(
            ax,
            segments[rejected],
            color=REJECTED_COLOR,
            zorder=5,
            label=f"rejected loop closures ({int(rejected.sum())})",
            **crowd_style(int(rejected.sum())),
        )
    return np.concatenate(drawn)


def _loop_closure_masks(
    graph: PoseGraph, result: Result | None, inliers: np.ndarray | None, known_inliers: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`(candidates, accepted, rejected)`, `(E,)` bool each: the loop closures `plot_trajectory`
    draws, from the given masks or else the result's (a bare graph: none rejected, odometry known)."""
    n_edges = graph.num_edges
    if inliers is None:
        inliers = result.inliers if result is not None else np.ones(n_edges, dtype=bool)
    if known_inliers is None:
        known_inliers = result.known_inliers if result is not None else graph.is_odometry
    inliers = _edge_mask("inliers", inliers, n_edges)
    known_inliers = _edge_mask("known_inliers", known_inliers, n_edges)
    candidates = ~known_inliers
    # Accepted odometry would only retrace the trajectory line; rejected edges are always shown.
    accepted = candidates & inliers & graph.is_loop_closure
    rejected = candidates & ~inliers
    return candidates, accepted, rejected


def _label_axes(ax: Axes, dim: int, drawn: np.ndarray) -> None:
    """Name the axes in metres and give them an equal scale over the `(M, dim)` points `drawn`."""
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    if dim == 3:
        ax3d = cast("Axes3D", ax)
        ax3d.set_zlabel("z [m]")
        _equal_3d(ax3d, drawn)
    else:
        ax.set_aspect("equal", adjustable="datalim")


def _add_legend(figure: Figure, ax: Axes, own_figure: bool) -> None:
    """The legend: below the axes of a figure of our own, in a corner of the caller's axes."""
    if own_figure:  # below the axes, off the trajectory
        legend = figure.legend(loc="outside lower center", ncol=2, fontsize="small", frameon=False)
    else:  # an explicit corner: "best" scans every segment, which is slow on large graphs
        legend = ax.legend(loc="upper right", fontsize="small", framealpha=0.9)
    for handle in legend.legend_handles:  # the key shows the colour, however faint the lines
        if handle is not None:
            handle.set_alpha(1.0)
            handle.set_linewidth(max(handle.get_linewidth(), 1.5))  # type: ignore[attr-defined]


def crowd_style(count: int) -> dict[str, float]:
    """Line width (points) and opacity for `count` loop-closure lines, as `plot` keywords.

    1 pt and 0.9 up to 15 lines; beyond, the width falls as `2 / count^(1/4)` down to 0.3 pt
    (from about 2000 lines) and the opacity as `3.5 / sqrt(count)` down to 0.12 (from about 850).
    """
    count = max(count, 1)
    return {
        "linewidth": float(np.clip(2.0 / count**0.25, *CROWD_WIDTH)),
        "alpha": float(np.clip(3.5 / math.sqrt(count), *CROWD_ALPHA)),
    }


def plot_mu_stages(result: Result, *, axes: Sequence[Axes] | None = None) -> Figure:
    """Draw the kernel parameter of each stage (min, mean, max) and a histogram of the final `mu`.

    Left panel: per stage, the min, mean and max of the loop closures' `mu`; stages without a
    kernel parameter (least squares, e.g. the final refinement) are shaded. `mu` is in [0, 1] for
    the SIG methods (`egnc`, `risam`); GNC-GM/TLS use Yang et al.'s `mu`, shown on a log scale.
    Right panel: histogram of `result.mu` over the loop closures, split into accepted and rejected.

    Args:
        result: a solve's `Result`.
        axes: two axes to draw into (stages, histogram) instead of a new figure.

    Returns:
        The `Figure` holding the axes.

    Raises:
        EgncError: matplotlib is missing, or `axes` is not two axes.
    """
    require_matplotlib()
    figure, (ax_stages, ax_hist) = _two_axes(axes, figsize=(9.0, 3.6))
    _draw_mu_per_stage(ax_stages, result)
    _draw_final_mu(ax_hist, result)
    return figure


def _draw_mu_per_stage(ax_stages: Axes, result: Result) -> None:
    """`plot_mu_stages`' left panel: min, mean and max `mu` per stage, stages without one shaded."""
    from matplotlib.ticker import MaxNLocator

    stages = result.stages
    number = np.arange(1, len(stages) + 1)
    low = np.array([stage.mu_min for stage in stages], dtype=float)
    mean = np.array([stage.mu_mean for stage in stages], dtype=float)
    high = np.array([stage.mu_max for stage in stages], dtype=float)
    has_mu = np.isfinite(mean)
    values = np.concatenate([low[has_mu], mean[has_mu], high[has_mu]])
    log_scale = bool(values.size and (values.max() > 1.0) and np.all(values[np.isfinite(values)] > 0.0))

    for k in np.flatnonzero(~has_mu):
        ax_stages.axvspan(number[k] - 0.4, number[k] + 0.4, color="0.92", zorder=0)
        where: dict[str, Any] = {"transform": ax_stages.get_xaxis_transform(), "ha": "center", "va": "center"}
        ax_stages.text(number[k], 0.5, "least squares", rotation=90, fontsize="small", color="0.4", **where)
    if has_mu.any():
        ax_stages.fill_between(
            number, low, high, where=has_mu, color=ACCEPTED_COLOR, alpha=0.35, linewidth=0, label="min to max"
        )
        ax_stages.plot(number, high, "^", color=RESULT_COLOR, markersize=4, label="max")
        ax_stages.plot(number, mean, "o-", color=RESULT_COLOR, markersize=4, linewidth=1.0, label="mean")
        ax_stages.plot(number, low, "v", color=RESULT_COLOR, markersize=4, label="min")
        ax_stages.legend(loc="best", fontsize="small")
    else:
        message = f"method {result.method!r} has no kernel parameter mu"
        ax_stages.text(0.5, 0.5, message, ha="center", va="center", transform=ax_stages.transAxes)
    if log_scale:
        ax_stages.set_yscale("log")
    else:
        ax_stages.set_ylim(-0.05, 1.05)
    ax_stages.xaxis.set_major_locator(MaxNLocator(nbins=12, integer=True))
    ax_stages.set_xlim(0.4, len(stages) + 0.6)
    ax_stages.set_xlabel("stage")
    ax_stages.set_ylabel(r"$\mu$ of the loop closures")
    ax_stages.set_title(rf"{result.method}: $\mu$ per stage")


def _draw_final_mu(ax_hist: Axes, result: Result) -> None:
    """`plot_mu_stages`' right panel: the histogram of the loop closures' final `mu`, accepted and rejected."""
    robust = ~result.known_inliers
    finite = robust & np.isfinite(result.mu)
    groups = [result.mu[finite & result.inliers], result.mu[finite & ~result.inliers]]
    if finite.any():
        in_unit = np.all((result.mu[finite] >= 0.0) & (result.mu[finite] <= 1.0))
        bins = np.linspace(0.0, 1.0, 21).tolist() if in_unit else 20
        ax_hist.hist(
            groups,
            bins=bins,
            stacked=True,
            color=[ACCEPTED_COLOR, REJECTED_COLOR],
            label=[f"accepted ({groups[0].size})", f"rejected ({groups[1].size})"],
        )
        ax_hist.legend(loc="upper left", fontsize="small")
    else:
        ax_hist.text(
            0.5, 0.5, "no final mu (no graduated kernel)", ha="center", va="center", transform=ax_hist.transAxes
        )
    ax_hist.set_xlabel(r"final $\mu$")
    ax_hist.set_ylabel("loop closures")
    ax_hist.set_title(r"final $\mu$ per loop closure")


def plot_kernel(
    c: float = 3.0,
    mus: Sequence[float] = (0.0, 0.25, 0.5, 0.75, 1.0),
    r_max: float = 10.0,
    *,
    axes: Sequence[Axes] | None = None,
) -> Figure:
    """Draw the SIG kernel `rho(r; mu)` and `d2rho/dr2` over `r` for several `mu` (two panels).

    The dotted vertical line is `r = c / sqrt(3)`: below it the kernel is convex for every `mu`;
    beyond it `d2rho` turns negative once `mu` exceeds `mu*(r)` (see `plot_mu_star`).

    Args:
        c: SIG shape parameter, > 0 (riSAM and egnc use 3).
        mus: the `mu` values to draw, each in [0, 1].
        r_max: largest whitened residual norm `r` drawn, > 0.
        axes: two axes to draw into (rho, d2rho) instead of a new figure.

    Returns:
        The `Figure` holding the axes.

    Raises:
        EgncError: matplotlib is missing, or a parameter is out of range.
    """
    require_matplotlib()
    from matplotlib import colormaps

    kernel = make_kernel("sig", c=c)
    c = kernel.params["c"]
    r_max = _positive_finite("r_max", r_max)
    mu_values = np.asarray(mus, dtype=float).ravel()
    if mu_values.size == 0 or not np.all((mu_values >= 0.0) & (mu_values <= 1.0)):
        raise EgncError(f"mus must be a non-empty list of values in [0, 1], got {mu_values.tolist()}")
    figure, (ax_rho, ax_d2) = _two_axes(axes, figsize=(9.0, 3.6))
    r = np.linspace(0.0, r_max, 600)
    colors = colormaps["viridis"](np.linspace(0.0, 0.9, mu_values.size))
    for mu, color in zip(mu_values, colors):
        ax_rho.plot(r, kernel.rho(r, mu), color=color, linewidth=1.3, label=rf"$\mu$ = {mu:g}")
        ax_d2.plot(r, kernel.d2rho(r, mu), color=color, linewidth=1.3, label=rf"$\mu$ = {mu:g}")
    boundary = c / math.sqrt(3.0)
    # The label sits where the curves are not: low in the rho panel, high in the d2rho panel.
    for ax, height, align in ((ax_rho, 0.03, "bottom"), (ax_d2, 0.97, "top")):
        ax.axvline(boundary, color="0.3", linestyle=":", linewidth=1.0)
        ax.text(
            boundary,
            height,
            rf" $r = c/\sqrt{{3}}$ = {boundary:.3g}",
            transform=ax.get_xaxis_transform(),
            ha="left",
            va=align,
            fontsize="small",
            color="0.3",
        )
        ax.set_xlim(0.0, r_max)
        ax.set_xlabel(r"$r$ (whitened residual norm)")
    ax_d2.axhline(0.0, color="0.3", linewidth=0.8)
    ax_rho.set_ylabel(r"$\rho(r; \mu)$")
    ax_d2.set_ylabel(r"$d^2\rho / dr^2$")
    ax_rho.set_title(rf"SIG kernel $\rho(r; \mu) = \frac{{1}}{{2}} \frac{{c^2 r^2}}{{c^2 + r^{{2\mu}}}}$, $c$ = {c:g}")
    ax_d2.set_title(r"second derivative ($< 0$: non-convex at $r$)")
    ax_rho.legend(loc="upper left", fontsize="small")
    return figure


def plot_mu_star(c: float = 3.0, r_max: float = 100.0, *, ax: Axes | None = None) -> Figure:
    """Draw the convexity boundary `mu*(r)` of the SIG kernel and its asymptote `mu = 1/2`.

    Below the curve (`mu <= mu*(r)`) the kernel is convex at `r`: `mu* = 1` up to
    `r = c / sqrt(3)`, then it falls towards 1/2 as `r` grows. `r` is on a log scale from
    `c / 30` to `r_max`, so the corner and the tail are both visible.

    Args:
        c: SIG shape parameter, > 0.
        r_max: largest whitened residual norm `r` drawn, > `c / 30`.
        ax: draw here instead of in a new figure.

    Returns:
        The `Figure` holding the axes.

    Raises:
        EgncError: matplotlib is missing, or a parameter is out of range.
    """
    require_matplotlib()
    c = _positive_finite("c", c)
    r_min = c / 30.0
    r_max = _positive_finite("r_max", r_max)
    if r_max <= r_min:
        raise EgncError(f"r_max must exceed c / 30 = {r_min:g}, got {r_max!r}")
    figure, ax = _single_axes(ax, three_d=False, figsize=(6.0, 3.8))
    r = np.geomspace(r_min, r_max, 1000)
    boundary = mu_star(r, c=c)
    ax.fill_between(
        r, 0.0, boundary, color=ACCEPTED_COLOR, alpha=0.3, linewidth=0, label=r"convex at $r$ ($\mu \leq \mu^*$)"
    )
    ax.plot(r, boundary, color=RESULT_COLOR, linewidth=1.5, label=r"$\mu^*(r)$")
    ax.axhline(0.5, color=REJECTED_COLOR, linestyle="--", linewidth=1.0, label=r"asymptote $\mu = 1/2$")
    corner = c / math.sqrt(3.0)
    ax.axvline(corner, color="0.3", linestyle=":", linewidth=1.0)
    ax.text(corner, 0.25, rf" $r = c/\sqrt{{3}}$ = {corner:.3g}", fontsize="small", color="0.3")
    ax.text(0.97, 0.75, r"non-convex at $r$ ($\mu > \mu^*$)", transform=ax.transAxes, ha="right", color="0.3")
    ax.set_xscale("log")
    ax.set_xlim(r_min, r_max)
    ax.set_ylim(0.0, 1.05)
    ax.set_xlabel(r"$r$ (whitened residual norm, log scale)")
    ax.set_ylabel(r"$\mu$")
    ax.set_title(rf"SIG convexity boundary $\mu^*(r)$, $c$ = {c:g}")
    ax.legend(loc="lower left", fontsize="small")
    return figure


def save_figure(figure: Figure, path: str | Path, *, dpi: float = 100) -> Path:
    """Write a figure to `path` atomically; the format comes from the suffix (PNG without one).

    Args:
        figure: the figure to write (e.g. from `plot_trajectory`).
        path: output file, e.g. `"trajectory.png"` (any format matplotlib writes: png, pdf, svg...).
        dpi: resolution in dots per inch for raster formats.

    Returns:
        `path` as a `Path`.

    Raises:
        EgncError: matplotlib is missing, `dpi` is not positive, the format is unknown, or the file
            cannot be written.
    """
    dpi = _positive_finite("dpi", dpi)
    path = Path(path)
    file_format = figure_format(path)
    # Line art compresses much better with zlib's best effort (Pillow's `optimize`).
    options: dict[str, Any] = {"pil_kwargs": {"optimize": True}} if file_format == "png" else {}
    with atomic_binary_file(path) as out:
        figure.savefig(out, format=file_format, dpi=dpi, **options)
    return path


# ----------------------------------------------------------------------------- helpers


def _single_axes(ax: Axes | None, *, three_d: bool, figsize: tuple[float, float] = (6.4, 6.0)) -> tuple[Figure, Axes]:
    """`ax` and its figure, or a new figure with one (3D if asked) axes."""
    if ax is not None:
        return _root_figure(ax), ax
    from matplotlib.figure import Figure

    figure = Figure(figsize=figsize, layout="constrained")
    return figure, figure.add_subplot(projection="3d" if three_d else None)


def _two_axes(axes: Sequence[Axes] | None, *, figsize: tuple[float, float]) -> tuple[Figure, Sequence[Axes]]:
    """The two given axes and their figure, or a new figure with two side by side."""
    if axes is not None:
        if len(axes) != 2:
            raise EgncError(f"axes must be two matplotlib axes, got {len(axes)}")
        return _root_figure(axes[0]), axes
    from matplotlib.figure import Figure

    figure = Figure(figsize=figsize, layout="constrained")
    return figure, figure.subplots(1, 2)


def _root_figure(ax: Axes) -> Figure:
    """The top-level figure of `ax`, also when it sits in a subfigure (`SubFigure.figure` is the root)."""
    return cast("Figure", ax.figure.figure)


def _positions(graph: PoseGraph, poses: PoseGraph | np.ndarray, name: str) -> np.ndarray:
    """`(N, dim)` positions of `poses` (a graph or an `(N, P)` array) matching `graph`'s rows."""
    if isinstance(poses, PoseGraph):
        poses = poses.poses
    poses = np.asarray(poses, dtype=float)
    expected = (graph.num_poses, graph.poses.shape[1])
    if poses.shape != expected:
        raise EgncError(f"{name} poses have shape {poses.shape}, expected {expected} like the graph")
    return poses[:, : graph.dim]


def _edge_mask(name: str, mask: np.ndarray, n_edges: int) -> np.ndarray:
    """Validate an `(E,)` bool edge mask."""
    mask = np.asarray(mask)
    if mask.shape != (n_edges,) or mask.dtype != bool:
        raise EgncError(f"{name} must be an ({n_edges},) bool array, got {mask.dtype} of shape {mask.shape}")
    return mask


def _figure_size(size: tuple[float, float]) -> tuple[float, float]:
    """Validate a `(width, height)` in inches."""
    try:
        width, height = size
    except (TypeError, ValueError):
        raise EgncError(f"size must be (width, height) in inches, got {size!r}") from None
    return _positive_finite("width", width), _positive_finite("height", height)


def _equal_3d(ax: Axes3D, points: np.ndarray) -> None:
    """One metre is as long on every axis: limits around `(K, 3)` points, and a box with their
    proportions (an extent below 5 % of the largest is raised to it, so flat data stays visible)."""
    low, high = points.min(axis=0), points.max(axis=0)
    extent = high - low
    extent = np.maximum(extent, 0.05 * extent.max() if extent.max() > 0 else 1.0)
    center = (low + high) / 2
    margin = 1.02  # the lines at the edges stay inside the box
    for set_limits, c, e in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), center, extent):
        set_limits(c - margin * e / 2, c + margin * e / 2)
    ax.set_box_aspect(tuple(extent), zoom=THREE_D_ZOOM)


def _positive_finite(name: str, value: float) -> float:
    """Validate a positive, finite scalar."""
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise EgncError(f"{name} must be a number, got {value!r}") from None
    if not (math.isfinite(value) and value > 0.0):
        raise EgncError(f"{name} must be positive and finite, got {value!r}")
    return value


def _draw_path(ax: Axes, position: np.ndarray, **style) -> None:
    """One polyline through `(N, 2|3)` positions."""
    ax.plot(*position.T, **style)


def _add_segments(ax: Axes, segments: np.ndarray, **style) -> None:
    """One line collection of `(K, 2, 2|3)` segments (one artist however many edges)."""
    if segments.shape[-1] == 3 and not len(segments):
        # matplotlib cannot draw a Line3DCollection of no segments (a ValueError from np.concatenate
        # when the figure is saved): an empty line keeps the legend entry instead.
        ax.plot([], [], [], **style)
        return
    if segments.shape[-1] == 3:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        cast("Axes3D", ax).add_collection3d(Line3DCollection(list(segments), **style))
    else:
        from matplotlib.collections import LineCollection

        ax.add_collection(LineCollection(list(segments), **style))
