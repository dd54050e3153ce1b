"""Reading and writing IRL logs: the shared noisy-Manhattan case, exact round trips, 3D
conventions against GTSAM, and one-line errors naming file and line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from egnc.errors import G2oFormatError, GraphError
from egnc.io import IrlLog, read_g2o, read_irl, write_irl
from egnc.io.irl import _quaternion_from_rzryrx, _rzryrx_from_rotation
from egnc.lie import so3
from egnc.nonlinear.factors import BetweenFactors, to_matrices

DATASETS = Path(__file__).parents[1] / "datasets"
ARRAYS = ("edge_ids", "measurements", "covariances", "is_odometry", "is_outlier", "has_null")

COV2 = "0.1 0.0 0.0 0.0 0.1 0.0 0.0 0.0 0.1"
HEADER = "tiny\n2024-01-02\n2\nnonlinear\nsome notes\n"
TINY = (
    HEADER
    + f"PRIOR 1 0 0 1.0 2.0 0.5 {COV2}\n"
    + f"ODOMETRY 1 0 0 1 1.0 0.0 0.0 {COV2}\n"
    + f"ODOMETRY 1 0 1 2 1.0 0.0 1.5707963267948966 {COV2}\n"
    + f"LOOP 2 0 2 0 -2.0 0.0 0.1 {COV2} NULL\n"
    + f"LOOP 2 1 2 1 5.0 5.0 0.0 {COV2} NULL\n"
    + f"LOOP 1 0 1 0 -1.0 0.0 0.0 {COV2}\n"
)


def write(tmp_path: Path, text: str, name: str = "log.irl") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def assert_same_log(a: IrlLog, b: IrlLog) -> None:
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.name, a.date, a.dim, a.notes) == (b.name, b.date, b.dim, b.notes)
    assert (a.prior is None) == (b.prior is None)
    if a.prior is not None:
        assert a.prior.vertex_id == b.prior.vertex_id
        np.testing.assert_array_equal(a.prior.pose, b.prior.pose)
        np.testing.assert_array_equal(a.prior.covariance, b.prior.covariance)


def test_tiny_log_fields_and_graph(tmp_path):
    log = read_irl(write(tmp_path, TINY))
    assert (log.name, log.date, log.dim, log.notes) == ("tiny", "2024-01-02", 2, "some notes")
    assert log.num_edges == 5
    np.testing.assert_array_equal(log.edge_ids, [[0, 1], [1, 2], [2, 0], [2, 1], [1, 0]])
    np.testing.assert_array_equal(log.is_odometry, [True, True, False, False, False])
    np.testing.assert_array_equal(log.is_outlier, [False, False, False, True, False])
    np.testing.assert_array_equal(log.has_null, [False, False, True, True, False])
    np.testing.assert_array_equal(log.entry_lines, [7, 8, 9, 10, 11])
    graph = log.graph
    np.testing.assert_allclose(graph.information, np.tile(10 * np.eye(3), (5, 1, 1)), rtol=1e-15)
    # The prior's pose sits at the prior; the others compose the odometry from there.
    np.testing.assert_allclose(graph.poses[0], [1.0, 2.0, 0.5])
    c, s = np.cos(0.5), np.sin(0.5)
    np.testing.assert_allclose(graph.poses[1], [1.0 + c, 2.0 + s, 0.5])
    np.testing.assert_allclose(graph.poses[2], [1.0 + 2 * c, 2.0 + 2 * s, 0.5 + np.pi / 2])
    assert not graph.fixed.any()  # the prior is on row 0, egnc's default gauge


def test_prior_on_a_later_pose_fixes_that_pose(tmp_path):
    text = HEADER + f"PRIOR 1 0 1 3.0 0.0 0.0 {COV2}\n" + f"ODOMETRY 1 0 0 1 1.0 0.0 0.0 {COV2}\n"
    graph = read_irl(write(tmp_path, text)).graph
    np.testing.assert_array_equal(graph.fixed, [False, True])
    np.testing.assert_allclose(graph.poses, [[2.0, 0.0, 0.0], [3.0, 0.0, 0.0]])


def test_shared_noisy_manhattan(dataset_path):
    log = read_irl(dataset_path("manhattan_noisy.irl"))
    assert (log.name, log.date, log.dim) == ("manhattan_noisy_0_random_0", "2023-09-13", 2)
    assert log.prior is not None and log.prior.vertex_id == 0
    np.testing.assert_array_equal(log.prior.covariance, 0.1 * np.eye(3))
    assert log.num_edges == 3499 + 733
    assert int(log.is_odometry.sum()) == 3499
    assert int(log.has_null.sum()) == 733  # every LOOP lists the NULL hypothesis
    assert int(log.is_outlier.sum()) == 223
    graph = log.graph
    assert graph.num_poses == 3500
    # ODOMETRY entries join consecutive ids, so egnc's default known inliers are the same edges.
    np.testing.assert_array_equal(graph.is_odometry, log.is_odometry)
    np.testing.assert_array_equal(graph.poses[1], log.measurements[0])
    np.testing.assert_allclose(graph.information[0], np.eye(3) / 0.022639800769753225, rtol=1e-14)


def test_round_trip_is_exact(tmp_path, dataset_path):
    source = dataset_path("manhattan_noisy.irl")
    log = read_irl(source)
    first, second = tmp_path / "first.irl", tmp_path / "second.irl"
    write_irl(log, first)
    again = read_irl(first)
    assert_same_log(log, again)
    np.testing.assert_array_equal(again.graph.poses, log.graph.poses)
    write_irl(again, second)
    assert first.read_bytes() == second.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["first.irl", "second.irl"]  # no temporaries


def test_round_trip_of_the_single_mode_loop(tmp_path):
    log = read_irl(write(tmp_path, TINY))
    write_irl(log, tmp_path / "out.irl")
    assert_same_log(log, read_irl(tmp_path / "out.irl"))
    assert (tmp_path / "out.irl").read_text().splitlines()[-1].startswith("LOOP 1 0 1 0 -1.0 ")


def test_3d_graph_round_trip_through_irl(tmp_path):
    graph = read_g2o(DATASETS / "grid3d.g2o")
    outliers = np.zeros(graph.num_edges, dtype=bool)
    outliers[np.flatnonzero(graph.is_loop_closure)[::7]] = True
    log = IrlLog.from_graph(graph, outliers, name="grid3d", date="2024-05-06")
    write_irl(log, tmp_path / "grid3d.irl")
    back = read_irl(tmp_path / "grid3d.irl")
    assert_same_log(log, back)
    np.testing.assert_array_equal(back.graph.edges, graph.edges)
    np.testing.assert_allclose(back.graph.information, graph.information, rtol=1e-9)
    # Same rotations (a quaternion and its negative are the same rotation).
    np.testing.assert_allclose(
        to_matrices(3, back.graph.measurements), to_matrices(3, graph.measurements), atol=1e-12
    )
    np.testing.assert_allclose(to_matrices(3, back.graph.poses[:1]), to_matrices(3, graph.poses[:1]), atol=1e-12)


def test_euler_angles_round_trip_including_gimbal_lock():
    rng = np.random.default_rng(0)
    angles = rng.uniform([-np.pi, -np.pi / 2, -np.pi], [np.pi, np.pi / 2, np.pi], size=(200, 3))
    angles[:3, 1] = [np.pi / 2, -np.pi / 2, 0.0]
    R = so3.from_quaternion(_quaternion_from_rzryrx(angles))
    back = so3.from_quaternion(_quaternion_from_rzryrx(_rzryrx_from_rotation(R)))
    np.testing.assert_allclose(back, R, atol=1e-12)
    np.testing.assert_allclose(_rzryrx_from_rotation(R)[3:], angles[3:], atol=1e-12)


def test_3d_conventions_match_gtsam():
    """egnc's whitened residuals of a 3D log equal GTSAM's factors built the way riSAM parses it."""
    gtsam = pytest.importorskip("gtsam")
    rng = np.random.default_rng(5)
    n = 6
    angles = rng.uniform(-1.0, 1.0, size=(n, 3))
    measurements = np.column_stack((rng.normal(size=(n, 3)), angles))
    A = rng.normal(size=(n, 6, 6))
    covariances = A @ A.swapaxes(1, 2) + 0.1 * np.eye(6)  # full, non-isotropic
    edge_ids = np.array([[0, 1], [1, 2], [2, 3], [3, 4], [4, 0], [1, 3]])
    log = IrlLog(
        name="t", date="2024-01-01", dim=3, notes="", edge_ids=edge_ids, measurements=measurements,
        covariances=covariances, is_odometry=edge_ids[:, 1] == edge_ids[:, 0] + 1,
        is_outlier=np.zeros(n, bool), has_null=np.zeros(n, bool),
    )  # fmt: skip
    poses = rng.normal(size=(5, 7))
    factors = BetweenFactors.from_graph(log.graph)
    r2 = factors.whitened_norms(factors.residuals(to_matrices(3, poses))) ** 2

    values = gtsam.Values()
    for key, p in enumerate(poses):
        q = p[3:] / np.linalg.norm(p[3:])
        values.insert(key, gtsam.Pose3(gtsam.Rot3.Quaternion(q[3], q[0], q[1], q[2]), p[:3]))
    for k, ((i, j), m, cov) in enumerate(zip(edge_ids, measurements, covariances)):
        Z = gtsam.Pose3(gtsam.Rot3.RzRyRx(*m[3:]), m[:3])
        factor = gtsam.BetweenFactorPose3(int(i), int(j), Z, gtsam.noiseModel.Gaussian.Covariance(cov))
        assert r2[k] == pytest.approx(2.0 * factor.error(values), rel=1e-9)
        quaternion = Z.rotation().toQuaternion()
        expected = np.array([quaternion.x(), quaternion.y(), quaternion.z(), quaternion.w()])
        np.testing.assert_allclose(log.graph.measurements[k, 3:], expected * np.sign(expected[3]), atol=1e-12)


BAD_INPUTS = {
    "short header": ("tiny\n2024-01-02\n", None, "header needs 5 lines"),
    "bad dimension": ("tiny\nd\n4\nnonlinear\n\n", 3, "must be 2 or 3"),
    "linear log": ("tiny\nd\n2\nlinear\n\n", 4, "nonlinear"),
    "unknown tag": (HEADER + "LANDMARK 1 0 0\n", 6, "unknown entry tag 'LANDMARK'"),
    "too few fields": (HEADER + "ODOMETRY 1 0 0 1 1.0 0.0 0.0\n", 6, "ODOMETRY needs 16 fields after the tag"),
    "bad number": (HEADER + f"ODOMETRY 1 0 0 1 1.0 zero 0.0 {COV2}\n", 6, "field 6 is 'zero'"),
    "not finite": (HEADER + f"ODOMETRY 1 0 0 1 1.0 nan 0.0 {COV2}\n", 6, "finite"),
    "bad id": (HEADER + f"ODOMETRY 1 0 0 -1 1.0 0.0 0.0 {COV2}\n", 6, "non-negative integer"),
    "bad correct mode": (HEADER + f"LOOP 2 2 1 0 1.0 0.0 0.0 {COV2} NULL\n", 6, "CORRECT_MODE"),
    "null first": (HEADER + f"LOOP 2 0 1 NULL 0 1.0 0.0 0.0 {COV2}\n", 6, "one measurement as mode 0"),
    "three modes": (HEADER + f"LOOP 3 0 1 0 1.0 0.0 0.0 {COV2} NULL NULL\n", 6, "multi-hypothesis"),
    "second mode not null": (HEADER + f"LOOP 2 0 1 0 1.0 0.0 0.0 {COV2} XX\n", 6, "NULL as the second mode"),
    "two priors": (HEADER + f"PRIOR 1 0 0 0 0 0 {COV2}\nPRIOR 1 0 0 0 0 0 {COV2}\n", 7, "second PRIOR"),
    "indefinite covariance": (
        HEADER + "ODOMETRY 1 0 0 1 1.0 0.0 0.0 1 0 0 0 -1 0 0 0 1\n", 6, "not symmetric positive definite"
    ),
    "covariance whose inverse overflows": (
        HEADER + "ODOMETRY 1 0 0 1 1.0 0.0 0.0 5e-324 0 0 0 5e-324 0 0 0 5e-324\n", 6, "inverse .* overflows"
    ),
    "underscore in a number": (HEADER + f"ODOMETRY 1 0 0 1 1_0 0.0 0.0 {COV2}\n", 6, "field 5 is '1_0'"),
    "leading plus": (HEADER + f"ODOMETRY 1 0 0 1 +1 0.0 0.0 {COV2}\n", 6, "field 5 is '[+]1'"),
    "plus on an id": (HEADER + f"ODOMETRY 1 0 0 +1 1 0.0 0.0 {COV2}\n", 6, "non-negative integer"),
    "unicode separator": (HEADER + f"ODOMETRY 1 0 0 1 1\u2028 0.0 0.0 {COV2}\n", 6, "character U[+]2028"),
    "no entries": (HEADER + f"PRIOR 1 0 0 0 0 0 {COV2}\n", None, "no ODOMETRY or LOOP"),
    "truncated": (HEADER + "ODOMETRY 1 0 0 1 1.0 0.0 0.0 0.1 0.0", 6, "truncated"),
    # Issue 19: without its notes line the PRIOR was read as the notes, and the prior was lost.
    "no notes line": (TINY.replace("some notes\n", ""), 5, "header line 5 [(]notes[)] is a PRIOR entry"),
    "id over 4300 digits": (HEADER + f"ODOMETRY 1 0 0 {'7' * 5000} 1.0 0.0 0.0 {COV2}\n", 6, "5000 characters"),
    "id above int64": (HEADER + f"ODOMETRY 1 0 0 9223372036854775808 1.0 0.0 0.0 {COV2}\n", 6, "int64 range"),
    "mode count over 4300 digits": (HEADER + f"LOOP {'2' * 4400} 0 1 0 1.0 0.0 0.0 {COV2}\n", 6, "NUM_MODES"),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_malformed_input_is_one_line_naming_file_and_line(tmp_path, case):
    text, line, message = BAD_INPUTS[case]
    path = write(tmp_path, text)
    with pytest.raises(G2oFormatError, match=message) as info:
        read_irl(path)
    assert info.value.path == str(path)
    assert info.value.line == line
    assert "\n" not in str(info.value)


def test_missing_file_and_odometry_gap(tmp_path):
    with pytest.raises(G2oFormatError, match="cannot read file"):
        read_irl(tmp_path / "missing.irl")
    gap = HEADER + f"ODOMETRY 1 0 0 1 1 0 0 {COV2}\nODOMETRY 1 0 2 3 1 0 0 {COV2}\nLOOP 1 0 3 0 1 0 0 {COV2}\n"
    path = write(tmp_path, gap)
    with pytest.raises(GraphError, match="odometry does not reach every pose") as info:
        read_irl(path)
    assert str(info.value).startswith(str(path))


def test_a_byte_order_mark_is_skipped(tmp_path):
    path = tmp_path / "bom.irl"
    path.write_bytes(b"\xef\xbb\xbf" + TINY.encode())
    log = read_irl(path)
    assert log.name == "tiny" and log.prior is not None and log.num_edges == 5
