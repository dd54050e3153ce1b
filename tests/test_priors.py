"""Priors: storage and checks, Jacobians against central differences, the gauge rule, g2o records,
least squares with priors, and costs and optima against GTSAM (long tier)."""

import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import egnc
from egnc.errors import EgncWarning, G2oFormatError, GraphError
from egnc.graph import PoseGraph
from egnc.graph.priors import Priors, unpinned_directions
from egnc.io.g2o import read_g2o, write_g2o
from egnc.nonlinear.factors import BetweenFactors, group_of, to_matrices
from egnc.nonlinear.least_squares import Problem, SolverOptions, solve_least_squares
from egnc.nonlinear.prior_factors import PriorFactors

PROPERTY = settings(max_examples=25, deadline=None)


def random_priors(dim: int, rng: np.random.Generator, num_poses: int, count: int = 6) -> Priors:
    """`count` priors of both kinds on random poses, measured anywhere (angles up to about 3 rad)."""
    d = 3 if dim == 2 else 6
    group = group_of(dim)
    rows = rng.integers(0, num_poses, size=count)
    kinds = ["pose" if k % 2 == 0 else "position" for k in range(count)]
    Z = group.exp(rng.normal(scale=1.0, size=(count, d)))
    params = group.to_xytheta(Z) if dim == 2 else group.to_xyz_quat(Z)
    measurements, information = [], []
    for k, kind in enumerate(kinds):
        m = d if kind == "pose" else dim
        A = rng.normal(size=(m, m))
        measurements.append(params[k] if kind == "pose" else params[k, :dim])
        information.append(A @ A.T + m * np.eye(m))
    return Priors.from_lists(dim, rows.tolist(), kinds, measurements, information)  # type: ignore[arg-type]


def chain_graph(dim: int, rng: np.random.Generator, num_poses: int = 8, priors: Priors | None = None) -> PoseGraph:
    """A noisy chain with two loop closures, poses spread on a curve, and `priors`."""
    d = 3 if dim == 2 else 6
    group = group_of(dim)
    steps = np.zeros((num_poses, d))
    steps[:, 0], steps[:, d - 1] = 1.0, 0.3
    truth = [group.exp(np.zeros(d))]
    for k in range(1, num_poses):
        truth.append(truth[-1] @ group.exp(steps[k]))
    T = np.array(truth)
    edges = np.array([[k, k + 1] for k in range(num_poses - 1)] + [[0, num_poses - 1], [1, num_poses - 2]])
    Z = group.between(T[edges[:, 0]], T[edges[:, 1]]) @ group.exp(rng.normal(scale=0.05, size=(len(edges), d)))
    to_params = group.to_xytheta if dim == 2 else group.to_xyz_quat
    guess = T @ group.exp(rng.normal(scale=0.1, size=(num_poses, d)))
    return PoseGraph(
        dim,
        np.arange(num_poses),
        to_params(guess),
        edges,
        to_params(Z),
        np.tile(np.eye(d) * 10, (len(edges), 1, 1)),
        priors=priors,
    )


@PROPERTY
@given(seed=st.integers(0, 2**32 - 1), dim=st.sampled_from([2, 3]))
def test_prior_jacobians_match_central_differences(seed, dim):
    rng = np.random.default_rng(seed)
    group = group_of(dim)
    d = 3 if dim == 2 else 6
    num_poses = 5
    priors = PriorFactors.from_priors(random_priors(dim, rng, num_poses))
    T = group.exp(rng.normal(scale=1.0, size=(num_poses, d)))
    lin = priors.linearize(T)
    assert not lin.J_e_xi.any()  # the fixed virtual pose
    np.testing.assert_array_equal(lin.residuals, priors.residuals(T))
    h = 1e-6
    for k in range(d):
        delta = np.zeros(d)
        delta[k] = h
        numeric = np.empty((len(priors), d))
        for p, row in enumerate(priors.rows):
            plus, minus = T.copy(), T.copy()
            plus[row] = group.rplus(T[row], delta)
            minus[row] = group.rplus(T[row], -delta)
            numeric[p] = (priors.residuals(plus)[p] - priors.residuals(minus)[p]) / (2 * h)
        np.testing.assert_allclose(lin.J_e_xj[:, :, k], numeric, atol=1e-6, rtol=1e-6)


def test_position_prior_residual_is_translation_minus_measurement():
    priors = Priors.from_lists(3, [0], ["position"], [np.array([1.0, 2.0, 3.0])], [np.diag([1.0, 4.0, 9.0])])
    factors = PriorFactors.from_priors(priors)
    T = group_of(3).exp(np.array([[2.0, 2.0, 2.0, 0.3, -0.2, 0.1]]))
    e = factors.residuals(T)
    np.testing.assert_allclose(e[0, :3], T[0, :3, 3] - [1.0, 2.0, 3.0])
    assert not e[0, 3:].any()
    assert factors.whitened_norms(e)[0] == pytest.approx(np.sqrt(e[0, :3] ** 2 @ [1.0, 4.0, 9.0]))


def test_priors_are_checked_in_egnc_words():
    with pytest.raises(GraphError, match="prior 0: .*positive definite"):
        Priors.from_lists(2, [0], ["position"], [np.zeros(2)], [-np.eye(2)])
    with pytest.raises(GraphError, match="prior 0: .*not finite"):
        Priors.from_lists(2, [0], ["pose"], [np.array([np.nan, 0, 0])], [np.eye(3)])
    rng = np.random.default_rng(0)
    with pytest.raises(GraphError, match="outside"):
        chain_graph(2, rng, priors=Priors.from_lists(2, [99], ["position"], [np.zeros(2)], [np.eye(2)]))
    with pytest.raises(GraphError, match="3D but the graph is 2D"):
        chain_graph(2, rng, priors=Priors.from_lists(3, [0], ["position"], [np.zeros(3)], [np.eye(3)]))


def test_factor_index_is_file_order_and_the_edge_index_without_priors():
    rng = np.random.default_rng(1)
    graph = chain_graph(2, rng)
    np.testing.assert_array_equal(graph.edge_factor_index, np.arange(graph.num_edges))
    assert graph.prior_factor_index.shape == (0,)
    priors = Priors.from_lists(2, [0, 3], ["position"] * 2, [np.zeros(2)] * 2, [np.eye(2)] * 2)
    with_priors = chain_graph(2, rng, priors=priors)  # no lines: edges first
    np.testing.assert_array_equal(with_priors.prior_factor_index, [9, 10])


@pytest.mark.parametrize(
    ("dim", "positions", "free"),
    [
        (2, [[0.0, 0.0]], "heading"),
        (2, [[1.0, 2.0], [1.0, 2.0]], "heading"),
        (2, [[0.0, 0.0], [5.0, 0.0]], None),
        (3, [[0.0, 0.0, 0.0]], "single prior position"),
        (3, [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [3.0, 3.0, 3.0]], "collinear"),
        (3, [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1e3, 0.0]], None),
    ],
)
def test_gauge_rule_names_what_position_priors_leave_free(dim, positions, free):
    priors = Priors.from_lists(dim, [0] * len(positions), ["position"] * len(positions), positions,
                               [np.eye(dim)] * len(positions))  # fmt: skip
    found = unpinned_directions(priors)
    assert (found is None) if free is None else (free in found)


def test_a_pose_prior_pins_the_gauge_and_no_pose_is_fixed():
    rng = np.random.default_rng(2)
    graph = chain_graph(3, rng, priors=random_priors(3, rng, 8, count=1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        problem = Problem.from_graph(graph)
    assert not problem.fixed.any()
    result = solve_least_squares(problem, to_matrices(3, graph.poses), options=SolverOptions(gradient_tol=1e-10))
    assert result.converged and result.prior_norms is not None


def test_a_single_position_prior_holds_pose_zero_and_warns():
    rng = np.random.default_rng(3)
    priors = Priors.from_lists(2, [4], ["position"], [np.array([1.0, 1.0])], [np.eye(2)])
    with pytest.warns(EgncWarning, match="do not pin down the heading.*vertex 0 is held fixed"):
        problem = Problem.from_graph(chain_graph(2, rng, priors=priors))
    np.testing.assert_array_equal(np.flatnonzero(problem.fixed), [0])


@pytest.mark.parametrize("dim", [2, 3])
def test_least_squares_with_priors_reaches_a_stationary_point_of_the_full_cost(dim):
    rng = np.random.default_rng(dim + 10)
    graph = chain_graph(dim, rng, priors=random_priors(dim, rng, 8, count=4))
    problem = Problem.from_graph(graph)
    tight = SolverOptions(rel_cost_tol=0.0, gradient_tol=1e-9, max_iterations=200)
    result = solve_least_squares(problem, to_matrices(dim, graph.poses), options=tight)
    assert result.converged, result.message
    group, d = group_of(dim), graph.tangent_dim
    edges, priors = BetweenFactors.from_graph(graph), PriorFactors.from_priors(graph.priors)

    def cost(T):
        return 0.5 * np.sum(edges.whitened_norms(edges.residuals(T)) ** 2) + 0.5 * np.sum(
            priors.whitened_norms(priors.residuals(T)) ** 2
        )

    T = result.poses
    assert cost(T) == pytest.approx(result.cost, rel=1e-12)
    for pose in range(graph.num_poses):  # no single-pose move lowers the cost: a stationary point
        for k in range(d):
            delta = np.zeros(d)
            delta[k] = 1e-5
            plus, minus = T.copy(), T.copy()
            plus[pose] = group.rplus(T[pose], delta)
            minus[pose] = group.rplus(T[pose], -delta)
            assert abs(cost(plus) - cost(minus)) / 2e-5 < 1e-5


G2O_2D = """VERTEX_SE2 0 0 0 0
VERTEX_SE2 1 1 0 0.1
VERTEX_SE2 2 2 0.1 0.2
EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1
EDGE_SE2_XYPRIOR 0 0.1 0.2 4 0 4
EDGE_SE2 1 2 1 0 0.1 1 0 0 1 0 1
EDGE_SE2_PRIOR 2 2 0 0.3 10 0 0 10 0 5
EDGE_SE2 0 2 2 0 0.1 1 0 0 1 0 1
"""

G2O_3D = """PARAMS_SE3OFFSET 7 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1
VERTEX_SE3:QUAT 1 1 0 0 0 0 0 1
EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1
EDGE_SE3_XYZPRIOR 1 7 1 0.1 0 4 0 0 4 0 4
EDGE_SE3_PRIOR 0 7 0 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 1
"""


@pytest.mark.parametrize("text", [G2O_2D, G2O_3D])
def test_g2o_priors_are_read_and_written_back_in_file_order(tmp_path, text):
    path = tmp_path / "in.g2o"
    path.write_text(text)
    graph = read_g2o(path)
    assert graph.num_priors == 2 and graph.priors.counts() == {"pose": 1, "position": 1}
    factor_lines = [line for line in text.splitlines() if line.startswith("EDGE")]
    assert [factor_lines[k].split()[0] for k in graph.prior_factor_index] == [
        line.split()[0] for line in factor_lines if "PRIOR" in line
    ]
    write_g2o(graph, tmp_path / "out.g2o")
    again = read_g2o(tmp_path / "out.g2o")
    written = [line.split()[0] for line in (tmp_path / "out.g2o").read_text().splitlines() if line.startswith("EDGE")]
    assert written == [line.split()[0] for line in factor_lines]
    for name in ("rows", "kinds", "measurements", "information", "param_ids"):
        np.testing.assert_array_equal(getattr(again.priors, name), getattr(graph.priors, name))


def test_g2o_refuses_a_non_identity_offset_and_unknown_vertices(tmp_path):
    path = tmp_path / "bad.g2o"
    path.write_text(G2O_3D.replace("PARAMS_SE3OFFSET 7 0 0 0", "PARAMS_SE3OFFSET 7 0.5 0 0"))
    with pytest.raises(
        G2oFormatError, match=r"bad.g2o:6: EDGE_SE3_PRIOR names PARAMS_SE3OFFSET 7 \(line 1\), which is not"
    ):
        read_g2o(path)
    path.write_text(G2O_2D.replace("EDGE_SE2_XYPRIOR 0", "EDGE_SE2_XYPRIOR 9"))
    with pytest.raises(G2oFormatError, match=r"bad.g2o:5: EDGE_SE2_XYPRIOR names vertex 9"):
        read_g2o(path)
    path.write_text(G2O_2D.replace("EDGE_SE2_XYPRIOR 0 0.1 0.2 4 0 4", "EDGE_SE2_XYPRIOR 0 0.1 0.2 4 0"))
    with pytest.raises(G2oFormatError, match=r"bad.g2o:5: EDGE_SE2_XYPRIOR needs 6 fields"):
        read_g2o(path)


def test_robust_solve_on_a_graph_with_priors_holds_them_and_reports_factor_indices(tmp_path):
    path = tmp_path / "in.g2o"
    path.write_text(G2O_2D)
    result = egnc.solve(read_g2o(path))
    assert result.converged, result.message
    assert result.rejected_priors.shape == (0,)
    assert set(result.rejected_edges.tolist()) <= set(result.graph.edge_factor_index.tolist())


# GTSAM cross-checks (long tier: the test ids name gtsam).


def gtsam_graph(graph: PoseGraph):  # type: ignore[no-untyped-def]
    """GTSAM's factors and values for `graph`: between factors, `PriorFactorPose2/3`, `GPSFactor` (3D)
    and a `CustomFactor` position prior (2D); information rotation-first for Pose3."""
    gtsam = pytest.importorskip("gtsam")
    factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    perm = np.arange(3) if graph.dim == 2 else np.array([3, 4, 5, 0, 1, 2])

    def from_matrix(T):  # type: ignore[no-untyped-def]
        if graph.dim == 2:
            return gtsam.Pose2(T[0, 2], T[1, 2], np.arctan2(T[1, 0], T[0, 0]))
        return gtsam.Pose3(gtsam.Rot3(T[:3, :3]), T[:3, 3])

    def pose(params):  # type: ignore[no-untyped-def]
        return from_matrix(to_matrices(graph.dim, params))

    def noise(info):  # type: ignore[no-untyped-def]
        return gtsam.noiseModel.Gaussian.Information(info)

    for k, T in enumerate(to_matrices(graph.dim, graph.poses)):
        values.insert(k, from_matrix(T))
    for (i, j), z, info in zip(graph.edges, graph.measurements, graph.information):
        Between = gtsam.BetweenFactorPose2 if graph.dim == 2 else gtsam.BetweenFactorPose3
        factors.add(Between(int(i), int(j), pose(z), noise(info[np.ix_(perm, perm)])))
    priors = graph.priors
    for k in range(len(priors)):
        row, info = int(priors.rows[k]), priors.information[k]
        if priors.kinds[k] == 0:
            Prior = gtsam.PriorFactorPose2 if graph.dim == 2 else gtsam.PriorFactorPose3
            factors.add(Prior(row, pose(priors.measurements[k]), noise(info[np.ix_(perm, perm)])))
        elif graph.dim == 3:
            factors.add(gtsam.GPSFactor(row, priors.measurements[k, :3], noise(info[:3, :3])))
        else:
            factors.add(gtsam.CustomFactor(noise(info[:2, :2]), [row], _position_error_2d(priors.measurements[k, :2])))
    return factors, values


def _position_error_2d(z):  # type: ignore[no-untyped-def]
    def error(this, values, jacobians):  # type: ignore[no-untyped-def]
        p = values.atPose2(this.keys()[0])
        if jacobians is not None:
            c, s = np.cos(p.theta()), np.sin(p.theta())
            jacobians[0] = np.array([[c, -s, 0.0], [s, c, 0.0]])
        return np.array([p.x() - z[0], p.y() - z[1]])

    return error


@pytest.mark.parametrize("dim", [2, 3])
def test_costs_with_priors_equal_gtsam(tmp_path, dim):
    rng = np.random.default_rng(20 + dim)
    graph = chain_graph(dim, rng, priors=random_priors(dim, rng, 8, count=6))
    write_g2o(graph, tmp_path / "priors.g2o")
    graph = read_g2o(tmp_path / "priors.g2o")
    factors, values = gtsam_graph(graph)
    problem = Problem.from_graph(graph)
    for scale in (0.0, 0.3, 1.0):  # at the guess and at poses moved away from it
        d = graph.tangent_dim
        T = group_of(dim).rplus(to_matrices(dim, graph.poses), rng.normal(scale=scale, size=(graph.num_poses, d)))
        moved = graph.with_poses(group_of(dim).to_xytheta(T) if dim == 2 else group_of(dim).to_xyz_quat(T))
        factors, values = gtsam_graph(moved)
        once = SolverOptions(max_iterations=1)
        ours = solve_least_squares(problem, to_matrices(dim, moved.poses), options=once).cost_history[0]
        assert ours == pytest.approx(factors.error(values), rel=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_least_squares_optimum_with_priors_equals_gtsam(dim):
    gtsam = pytest.importorskip("gtsam")
    rng = np.random.default_rng(30 + dim)
    graph = chain_graph(dim, rng, priors=random_priors(dim, rng, 8, count=6))
    factors, values = gtsam_graph(graph)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-14)
    params.setAbsoluteErrorTol(1e-14)
    expected = gtsam.LevenbergMarquardtOptimizer(factors, values, params).optimize()
    tight = SolverOptions(rel_cost_tol=1e-14, gradient_tol=1e-10, max_iterations=200)
    result = solve_least_squares(Problem.from_graph(graph), to_matrices(dim, graph.poses), options=tight)
    assert result.cost == pytest.approx(factors.error(expected), rel=1e-8)
    for k in range(graph.num_poses):
        pose = expected.atPose2(k) if dim == 2 else expected.atPose3(k)
        np.testing.assert_allclose(result.poses[k], pose.matrix(), atol=1e-6)


def test_gnss_priors_from_a_clean_optimum_change_nothing_and_are_never_rejected(tmp_path):
    from egnc.datasets import add_position_priors, grid_world

    graph = grid_world(2, num_poses=60, seed=4).graph
    optimum = egnc.solve(graph, "l2").graph.poses
    with_priors = add_position_priors(graph, optimum, every=10, sigma=0.01, seed=1)
    assert with_priors.num_priors == 6
    np.testing.assert_array_equal(with_priors.prior_factor_index, graph.num_edges + np.arange(6))
    result = egnc.solve(with_priors)
    assert result.converged and len(result.rejected_edges) == 0
    least_squares = solve_least_squares(Problem.from_graph(with_priors), to_matrices(2, with_priors.poses))
    assert result.cost == pytest.approx(least_squares.cost, rel=1e-6)
    write_g2o(with_priors, tmp_path / "gnss.g2o")
    assert read_g2o(tmp_path / "gnss.g2o").priors.counts() == {"pose": 0, "position": 6}


def test_marginal_covariances_of_a_graph_held_by_priors(tmp_path):
    path = tmp_path / "in.g2o"
    path.write_text(G2O_2D)
    result = egnc.solve(read_g2o(path), "l2")
    covariances = egnc.marginal_covariances(result)
    assert covariances.shape == (3, 3, 3) and np.all(np.linalg.eigvalsh(covariances) > 0)
    assert np.linalg.eigvalsh(covariances[0]).max() < 1.0  # pose 0 is held by its prior, not fixed
