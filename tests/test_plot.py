"""egnc.plot: the figures' artists, atomic saving, `egnc-solve --plot`, and life without matplotlib."""

from __future__ import annotations

import importlib
import importlib.util
import math
import os
import struct
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import egnc
from egnc import plot
from egnc.errors import EgncError
from egnc.robust.mu_star import mu_star

DATASETS = Path(__file__).parents[1] / "datasets"
DOCS = Path(__file__).parents[1] / "docs"
MAX_FIGURE_BYTES = 300_000
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
INSTALL_HINT = "pip install 'egnc[plot]'"


@pytest.fixture(scope="module")
def mpl():
    """matplotlib on the Agg backend (the figures need no GUI); skips without it."""
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    return matplotlib


@pytest.fixture(scope="module")
def solved2d() -> tuple[egnc.PoseGraph, egnc.Result]:
    """The shipped 2D grid with 30 % false loops and its egnc solve (about 0.1 s)."""
    graph = egnc.read_g2o(DATASETS / "grid2d_outliers.g2o")
    return graph, egnc.solve(graph)


@pytest.fixture(scope="module")
def solved3d() -> tuple[egnc.PoseGraph, egnc.Result]:
    """The shipped 3D grid with 30 % false loops and its egnc solve."""
    graph = egnc.read_g2o(DATASETS / "grid3d_outliers.g2o")
    return graph, egnc.solve(graph)


def collection(ax, label_start: str):
    """The one line collection whose legend label starts with `label_start`."""
    (found,) = [c for c in ax.collections if c.get_label().startswith(label_start)]
    return found


def line(ax, label: str):
    """The one line with this legend label."""
    (found,) = [item for item in ax.lines if item.get_label() == label]
    return found


# ----------------------------------------------------------------------------- trajectory


def test_trajectory_2d_draws_result_initial_and_each_loop_once(mpl, solved2d):
    from matplotlib.figure import Figure

    graph, result = solved2d
    figure = plot.plot_trajectory(result, initial=graph)
    assert isinstance(figure, Figure)
    (ax,) = figure.axes
    assert ax.name != "3d"
    rejected = collection(ax, "rejected")
    accepted = collection(ax, "accepted")
    assert len(rejected.get_segments()) == len(result.rejected_edges) > 0
    assert len(accepted.get_segments()) == int((result.inliers & ~result.known_inliers).sum())
    # Each rejected segment joins the optimized positions of its edge's poses.
    first = result.rejected_edges[0]
    i, j = graph.edges[first]
    np.testing.assert_allclose(rejected.get_segments()[0], result.graph.poses[[i, j], :2])
    np.testing.assert_allclose(line(ax, "result").get_xydata(), result.graph.poses[:, :2])
    np.testing.assert_allclose(line(ax, "initial guess").get_xydata(), graph.poses[:, :2])
    legend_labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert legend_labels[-1] == f"rejected loop closures ({len(result.rejected_edges)})"
    assert str(len(result.rejected_edges)) in ax.get_title()


def test_trajectory_elements_have_distinct_colours_and_a_legend(mpl, solved2d):
    from matplotlib.colors import to_hex

    graph, result = solved2d
    figure = plot.plot_trajectory(result, initial=graph, reference=result.graph)
    (ax,) = figure.axes
    colours = {
        "initial guess": line(ax, "initial guess").get_color(),
        "result": line(ax, "result").get_color(),
        "reference": line(ax, "reference").get_color(),
        "accepted": collection(ax, "accepted").get_colors()[0],
        "rejected": collection(ax, "rejected").get_colors()[0],
    }
    assert len({to_hex(colour, keep_alpha=False) for colour in colours.values()}) == len(colours)
    labels = [text.get_text() for text in figure.legends[0].get_texts()]
    assert labels == [
        f"accepted loop closures ({int((result.inliers & ~result.known_inliers).sum())})",
        "initial guess",
        "reference",
        "result",
        f"rejected loop closures ({len(result.rejected_edges)})",
    ]
    assert all(handle.get_alpha() == 1.0 for handle in figure.legends[0].legend_handles)  # keys stay legible


def test_many_loop_closures_are_thinner_and_fainter(mpl):
    counts = [1, 10, 100, 1000, 100_000]
    styles = [plot.crowd_style(count) for count in counts]
    widths, alphas = [s["linewidth"] for s in styles], [s["alpha"] for s in styles]
    assert widths == sorted(widths, reverse=True) and alphas == sorted(alphas, reverse=True)
    assert alphas[-1] < alphas[1] / 4 and widths[-1] < widths[1] / 2
    assert (widths[-1], alphas[-1]) == (plot.CROWD_WIDTH[0], plot.CROWD_ALPHA[0])  # still drawn


def test_trajectory_3d_uses_3d_axes_with_equal_scale(mpl, solved3d):
    graph, result = solved3d
    figure = plot.plot_trajectory(result, initial=graph.poses)
    (ax,) = figure.axes
    assert ax.name == "3d"
    figure.draw_without_rendering()  # 3D collections project their segments at draw time
    assert len(collection(ax, "rejected").get_segments()) == len(result.rejected_edges) > 0
    x, y, z = line(ax, "result").get_data_3d()
    np.testing.assert_allclose(np.stack([x, y, z], axis=1), result.graph.poses[:, :3])
    # One metre is as long on every axis: the box has the proportions of the axis limits.
    spans = np.array([np.ptp(ax.get_xlim()), np.ptp(ax.get_ylim()), np.ptp(ax.get_zlim())])
    box = np.asarray(ax.get_box_aspect())
    np.testing.assert_allclose(box / box[0], spans / spans[0], rtol=1e-9)
    drawn = np.concatenate([result.graph.poses[:, :3], graph.poses[:, :3]])
    assert np.all(ax.get_xlim()[0] <= drawn[:, 0].min()) and np.all(drawn[:, 2].max() <= ax.get_zlim()[1])


def test_trajectory_size_and_saved_dpi(mpl, solved2d, tmp_path):
    from PIL import Image

    graph, result = solved2d
    figure = plot.plot_trajectory(result, size=(4.0, 3.0))
    assert tuple(figure.get_size_inches()) == (4.0, 3.0)
    plot.save_figure(figure, tmp_path / "small.png", dpi=50)
    assert Image.open(tmp_path / "small.png").size == (200, 150)
    with pytest.raises(EgncError, match="width must be positive"):
        plot.plot_trajectory(result, size=(0, 3))
    with pytest.raises(EgncError, match="size must be"):
        plot.plot_trajectory(result, size=5)
    with pytest.raises(EgncError, match="cannot be given with ax"):
        plot.plot_trajectory(result, size=(4, 3), ax=figure.axes[0])
    with pytest.raises(EgncError, match="dpi must be positive"):
        plot.save_figure(figure, tmp_path / "x.png", dpi=0)


def test_trajectory_of_a_bare_graph_with_reference_into_given_axes(mpl, solved2d):
    from matplotlib.figure import Figure

    graph, result = solved2d
    figure = Figure()
    ax = figure.add_subplot()
    assert plot.plot_trajectory(graph, reference=result.graph, ax=ax) is figure
    assert [c.get_label() for c in ax.collections] == ["loop closures"]  # nothing is rejected
    assert len(ax.collections[0].get_segments()) == int(graph.is_loop_closure.sum())
    assert {item.get_label() for item in ax.lines} == {"trajectory", "reference"}
    assert ax.get_legend() is not None


def test_trajectory_rejects_bad_arguments(mpl, solved2d, solved3d):
    from matplotlib.figure import Figure

    graph, result = solved2d
    with pytest.raises(EgncError, match="initial poses have shape"):
        plot.plot_trajectory(result, initial=graph.poses[:-1])
    with pytest.raises(EgncError, match="inliers must be"):
        plot.plot_trajectory(graph, inliers=np.ones(3, dtype=bool))
    with pytest.raises(EgncError, match="3D axes"):
        plot.plot_trajectory(solved3d[1], ax=Figure().add_subplot())


# ----------------------------------------------------------------------------- mu, kernel, mu*


def test_mu_stages_plots_each_stage_and_every_loop_closure(mpl, solved2d):
    _, result = solved2d
    figure = plot.plot_mu_stages(result)
    ax_stages, ax_hist = figure.axes
    mean = line(ax_stages, "mean").get_ydata()
    np.testing.assert_array_equal(mean, [stage.mu_mean for stage in result.stages])
    assert math.isnan(mean[-1])  # the least-squares refinement has no mu
    heights = sum(patch.get_height() for patch in ax_hist.patches)
    assert heights == int((~result.known_inliers).sum())


def test_mu_stages_of_a_method_without_mu(mpl, solved2d):
    graph, _ = solved2d
    figure = plot.plot_mu_stages(egnc.solve(graph, "l2"))
    texts = [text.get_text() for ax in figure.axes for text in ax.texts]
    assert any("no kernel parameter" in text for text in texts)


def test_kernel_draws_rho_and_d2rho_per_mu(mpl):
    mus = (0.0, 0.5, 1.0)
    figure = plot.plot_kernel(c=3.0, mus=mus, r_max=8.0)
    ax_rho, ax_d2 = figure.axes
    kernel = egnc.robust.kernels.make_kernel("sig", c=3.0)
    for ax, function in ((ax_rho, kernel.rho), (ax_d2, kernel.d2rho)):
        curves = [item for item in ax.lines if item.get_label().startswith("$\\mu$")]
        assert len(curves) == len(mus)
        for curve, mu in zip(curves, mus):
            r, value = curve.get_xydata().T
            np.testing.assert_allclose(value, function(r, mu))
        boundaries = [item.get_xdata()[0] for item in ax.lines if item.get_linestyle() == ":"]
        assert boundaries == [pytest.approx(3.0 / math.sqrt(3.0))]
    with pytest.raises(EgncError, match="mus"):
        plot.plot_kernel(mus=(0.5, 1.5))


def test_mu_star_curve_and_asymptote(mpl):
    figure = plot.plot_mu_star(c=3.0, r_max=100.0)
    (ax,) = figure.axes
    r, mu = line(ax, "$\\mu^*(r)$").get_xydata().T
    np.testing.assert_allclose(mu, mu_star(r, c=3.0))
    assert mu.min() >= 0.5 and mu.max() == 1.0
    assert line(ax, "asymptote $\\mu = 1/2$").get_ydata()[0] == 0.5
    with pytest.raises(EgncError, match="r_max"):
        plot.plot_mu_star(r_max=-1.0)


# ----------------------------------------------------------------------------- saving, CLI


def test_save_figure_writes_png_atomically(mpl, tmp_path):
    path = plot.save_figure(plot.plot_mu_star(r_max=10.0), tmp_path / "mu_star.png")
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    with pytest.raises(EgncError, match="cannot write figures as 'xyz'"):
        plot.save_figure(plot.plot_mu_star(r_max=10.0), tmp_path / "figure.xyz")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mu_star.png"]  # no temporary left


def test_cli_plot_writes_png(mpl, tmp_path):
    out = tmp_path / "trajectory.png"
    run = subprocess.run(
        [sys.executable, "-m", "egnc.cli.solve", str(DATASETS / "grid2d_outliers.g2o"), "--plot", str(out), "-q"],
        capture_output=True,
        check=False,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert run.returncode == 0, run.stderr
    assert out.read_bytes()[:8] == PNG_SIGNATURE


def test_3d_graph_without_loop_closures_plots(mpl, tmp_path):
    # Issue 19: an empty Line3DCollection made savefig raise ValueError (need at least one array).
    graph = egnc.read_g2o(DATASETS / "grid3d.g2o")
    odometry_only = graph.subgraph_edges(graph.is_odometry)
    figure = plot.plot_trajectory(egnc.solve(odometry_only, "l2"), initial=odometry_only)
    path = plot.save_figure(figure, tmp_path / "odometry3d.png")
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    labels = [handle.get_label() for handle in figure.legends[0].legend_handles if handle is not None]
    assert "accepted loop closures (0)" in [text.get_text() for text in figure.legends[0].get_texts()], labels


FAILING_PLOT = """
import egnc.cli.outputs as outputs
def broken(*args, **kwargs):
    raise ValueError("need at least one array\\nto concatenate")
outputs.plot_trajectory = broken
"""


def test_cli_failed_plot_is_a_warning_and_the_outputs_are_written(mpl, tmp_path):
    out, report, png = tmp_path / "out.g2o", tmp_path / "report.json", tmp_path / "trajectory.png"
    script = "import sys\nimport egnc.cli.solve as cli\n" + FAILING_PLOT + "\nsys.exit(cli.main(sys.argv[1:]))\n"
    args = [str(DATASETS / "grid2d.g2o"), "--method", "l2", "-q", "-o", str(out), "--report", str(report)]
    run = subprocess.run(
        [sys.executable, "-c", script, *args, "--plot", str(png)],
        capture_output=True,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
        env={**os.environ, "MPLBACKEND": "Agg"},
    )
    assert run.returncode == 0, run.stderr
    assert run.stderr.splitlines() == [
        f"warning: {png}: --plot failed, no figure written (ValueError: need at least one array to concatenate)"
    ]
    assert egnc.read_g2o(out).num_poses == egnc.read_g2o(DATASETS / "grid2d.g2o").num_poses
    assert report.is_file() and not png.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.g2o", "report.json"]  # no temporary left


def test_docs_figures_regenerate_small(mpl, tmp_path, capsys):
    pytest.importorskip("PIL")  # matplotlib's own dependency
    spec = importlib.util.spec_from_file_location("make_figures", DOCS / "make_figures.py")
    make_figures = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(make_figures)
    # Without the shared datasets the Intel figure is skipped, with a message.
    assert make_figures.main(["--out", str(tmp_path), "--data-dir", str(tmp_path / "nowhere")]) == 0
    assert "skipping trajectory_intel30.png" in capsys.readouterr().err
    names = {"trajectory_grid2d.png", "trajectory_grid3d.png", "kernel.png", "mu_star.png"}
    assert {path.name for path in tmp_path.iterdir()} == names
    for name in names:
        content = (tmp_path / name).read_bytes()
        assert content[:8] == PNG_SIGNATURE and len(content) < MAX_FIGURE_BYTES, name


def test_committed_docs_figures_are_small_pngs():
    figures = sorted(DOCS.glob("*.png"))
    assert {"trajectory_intel30.png", "trajectory_grid3d.png"} <= {path.name for path in figures}
    for path in figures:
        content = path.read_bytes()
        assert content[:8] == PNG_SIGNATURE and len(content) < MAX_FIGURE_BYTES, path.name


# ----------------------------------------------------------------------------- no matplotlib


def test_plot_functions_without_matplotlib_raise_install_hint(monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # `import matplotlib` now fails
    monkeypatch.delitem(sys.modules, "egnc.plot")
    monkeypatch.delattr(egnc, "plot")  # both are restored after the test
    fresh = importlib.import_module("egnc.plot")  # importing the module still works
    graph = egnc.read_g2o(DATASETS / "grid2d.g2o")
    calls = [
        lambda: fresh.plot_trajectory(graph),
        lambda: fresh.plot_kernel(),
        lambda: fresh.plot_mu_star(),
        lambda: fresh.save_figure(None, "x.png"),
    ]
    for call in calls:
        with pytest.raises(EgncError, match=r"pip install 'egnc\[plot\]'"):
            call()


def test_cli_plot_without_matplotlib_fails_in_one_line_before_solving(tmp_path):
    # matplotlib is blocked and `solve` is replaced by a tripwire: the error must come first.
    script = textwrap.dedent(
        """
        import sys
        sys.modules["matplotlib"] = None
        import egnc.cli.solve as cli

        def tripwire(*args, **kwargs):
            raise SystemExit("solve was called")

        cli.solve = tripwire
        sys.exit(cli.main(sys.argv[1:]))
        """
    )
    out = tmp_path / "solved.g2o"
    run = subprocess.run(
        [sys.executable, "-c", script, str(DATASETS / "grid2d.g2o"), "-o", str(out), "--plot", str(tmp_path / "t.png")],
        capture_output=True,
        check=False,
        text=True,
        timeout=120,
        stdin=subprocess.DEVNULL,
    )
    assert run.returncode == 1
    assert run.stdout == ""
    assert run.stderr.count("\n") == 1 and run.stderr.startswith("egnc-solve: error: ")
    assert INSTALL_HINT in run.stderr
    assert list(tmp_path.iterdir()) == []


def test_cli_plot_size_and_dpi_set_the_image_size(tmp_path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "t.png"
    run = subprocess.run(
        [sys.executable, "-m", "egnc.cli.solve", str(DATASETS / "grid2d.g2o"), "--plot", str(out),
         "--plot-size", "4", "3", "--dpi", "50", "-q"],  # fmt: skip
        capture_output=True,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    width, height = struct.unpack(">II", out.read_bytes()[16:24])  # the PNG header's IHDR size
    assert (width, height) == (200, 150)
