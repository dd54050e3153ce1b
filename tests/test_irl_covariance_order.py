"""The two readings of a 3D IRL log's covariances (GTSAM's order and g2o's), chosen on purpose, and
the one warning when a log leaves the choice ambiguous."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from test_bench import read_csv
from test_cli import egnc_solve

from egnc.errors import EgncError, EgncWarning
from egnc.io import IrlLog, read_g2o, read_irl, write_irl
from egnc.io.irl_covariance import ANISOTROPY_RATIO, declared_order, reading_warning

DATASETS = Path(__file__).parents[1] / "datasets"


def read_recording(path: Path, covariance_order: str | None = None) -> tuple[IrlLog, list[str]]:
    """`read_irl` and the messages of the `EgncWarning`s it gave."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_irl(path, covariance_order)  # type: ignore[arg-type]
    return log, [str(w.message) for w in caught if issubclass(w.category, EgncWarning)]


@pytest.fixture(scope="module")
def grid3d():
    """grid3d.g2o: translation information 400, rotation 10000, so the two orders differ."""
    return read_g2o(DATASETS / "grid3d.g2o")


def converter_log(graph, path: Path) -> Path:
    """`graph` as riSAM's g2o-2-irl writes it: covariances in g2o's order, notes without a declaration."""
    log = IrlLog.from_graph(graph, name="grid3d", date="2024-05-06", covariance_order="g2o")
    write_irl(log, path)
    lines = path.read_text().split("\n")
    lines[4] = "Add notes here."
    path.write_text("\n".join(lines))
    return path


def test_g2o_reading_keeps_the_g2o_noise_model_and_the_default_warns_once(grid3d, tmp_path):
    path = converter_log(grid3d, tmp_path / "converted.irl")
    default, messages = read_recording(path)
    assert len(messages) == 1
    assert all(word in messages[0] for word in ("'gtsam'", "'g2o'", "--irl-covariance-order", str(path)))
    assert default.covariance_order == "gtsam"
    # Read riSAM's way, the rotation variances become the translation's: 25x too precise here.
    np.testing.assert_allclose(default.graph.information[:, :3, :3], grid3d.information[:, 3:, 3:], rtol=1e-9)
    as_g2o, messages = read_recording(path, "g2o")
    assert messages == [] and as_g2o.covariance_order == "g2o"
    np.testing.assert_allclose(as_g2o.graph.information, grid3d.information, rtol=1e-9)
    as_gtsam, messages = read_recording(path, "gtsam")  # chosen on purpose: no warning
    assert messages == []
    np.testing.assert_array_equal(as_gtsam.graph.information, default.graph.information)


@pytest.mark.parametrize("order", ["gtsam", "g2o"], ids=["rotation-first", "translation-first"])
def test_writing_back_reproduces_the_file_under_either_reading(grid3d, tmp_path, order):
    path = converter_log(grid3d, tmp_path / "converted.irl")
    log, _ = read_recording(path, order)
    write_irl(log, tmp_path / "back.irl")
    assert (tmp_path / "back.irl").read_bytes() == path.read_bytes()
    again, _ = read_recording(tmp_path / "back.irl", order)
    np.testing.assert_array_equal(again.graph.information, log.graph.information)


@pytest.mark.parametrize("order", ["gtsam", "g2o"], ids=["rotation-first", "translation-first"])
def test_egncs_own_logs_declare_their_order_and_stay_silent(grid3d, tmp_path, order):
    path = tmp_path / "own.irl"
    write_irl(IrlLog.from_graph(grid3d, name="grid3d", date="2024-05-06", covariance_order=order), path)
    log, messages = read_recording(path, order)
    assert messages == [] and declared_order(log.notes) == order
    np.testing.assert_allclose(log.graph.information, grid3d.information, rtol=1e-9)
    if order == "gtsam":  # the default reading is the declared one
        assert read_recording(path)[1] == []
    else:  # read against its declaration: said
        (message,) = read_recording(path)[1]
        assert "declare covariance order 'g2o'" in message


def test_isotropic_3d_logs_stay_silent(grid3d, tmp_path):
    isotropic = type(grid3d)(
        dim=3,
        vertex_ids=grid3d.vertex_ids,
        poses=grid3d.poses,
        edges=grid3d.edges,
        measurements=grid3d.measurements,
        information=np.tile(50.0 * np.eye(6), (grid3d.num_edges, 1, 1)),
    )
    path = converter_log(isotropic, tmp_path / "isotropic.irl")
    assert read_recording(path)[1] == []


def test_2d_logs_stay_silent_whatever_the_reading(dataset_path):
    assert read_recording(dataset_path("manhattan_noisy.irl"))[1] == []
    assert read_recording(dataset_path("manhattan_noisy.irl"), "g2o")[0].covariance_order == "g2o"


def test_the_rule_compares_the_mean_variances_of_the_two_blocks():
    def covariances(first: float, second: float) -> np.ndarray:
        return np.diag([first] * 3 + [second] * 3)[None]

    assert reading_warning(covariances(1.0, 1.0), 3, "", None) is None
    assert reading_warning(covariances(1.0, 0.9 * ANISOTROPY_RATIO), 3, "", None) is None
    assert reading_warning(covariances(1.1 * ANISOTROPY_RATIO, 1.0), 3, "", None) is not None
    assert reading_warning(covariances(0.1, 1.0), 3, "", "gtsam") is None  # chosen
    assert reading_warning(np.eye(3)[None], 2, "", None) is None


def test_an_unknown_order_is_refused(grid3d, tmp_path):
    path = converter_log(grid3d, tmp_path / "converted.irl")
    with pytest.raises(EgncError, match="'gtsam' or 'g2o'"):
        read_irl(path, "rzryrx")  # type: ignore[arg-type]
    with pytest.raises(EgncError, match="'gtsam' or 'g2o'"):
        IrlLog.from_graph(grid3d, covariance_order="xyz")  # type: ignore[arg-type]


def test_cli_option_warning_and_checkpoint_of_another_reading(grid3d, tmp_path):
    path = converter_log(grid3d, tmp_path / "converted.irl")
    report = tmp_path / "report.json"
    run = egnc_solve(path, "--report", report, "-q")
    assert run.returncode == 0, run.stderr
    assert "--irl-covariance-order" in run.stderr
    assert any("--irl-covariance-order" in note for note in json.loads(report.read_text())["warnings"])
    checkpoint = tmp_path / "run.ckpt"
    run = egnc_solve(path, "--irl-covariance-order", "g2o", "--online", "--checkpoint", checkpoint, "-q")
    assert run.returncode == 0 and run.stderr == "", run.stderr
    run = egnc_solve(path, "--irl-covariance-order", "gtsam", "--online", "--checkpoint", checkpoint, "-q")
    assert run.returncode == 1 and "another graph" in run.stderr and "Traceback" not in run.stderr
    run = egnc_solve(DATASETS / "grid3d.g2o", "--irl-covariance-order", "g2o")
    assert run.returncode == 1 and "applies to IRL logs" in run.stderr


def test_bench_takes_the_reading_of_an_irl_log(grid3d, tmp_path):
    """`egnc-bench --irl` reads a converted log the way it is told: the default reading warns (it
    is the ambiguous one), a chosen one does not, and the option is refused without `--irl`."""
    path = converter_log(grid3d, tmp_path / "converted.irl")
    command = [sys.executable, "-m", "egnc.cli.bench", "--irl", str(path), "--methods", "l2", "-q"]
    runs = {}
    for order in (None, "g2o", "gtsam"):
        chosen = [] if order is None else ["--irl-covariance-order", order]
        out = tmp_path / f"out-{order}"
        runs[order] = subprocess.run(
            [*command, *chosen, "--out", str(out)], capture_output=True, text=True, timeout=300
        )
        assert runs[order].returncode == 0, runs[order].stderr
        (row,) = read_csv(out / "results.csv")
        assert row["status"] == "ok"
    assert "--irl-covariance-order" in runs[None].stderr
    assert runs["g2o"].stderr == "" and runs["gtsam"].stderr == ""
    wrong = [sys.executable, "-m", "egnc.cli.bench", "--datasets", "grid3d", "--irl-covariance-order", "g2o"]
    run = subprocess.run(wrong, capture_output=True, text=True, timeout=300)
    assert run.returncode == 2 and "applies to --irl logs" in run.stderr
