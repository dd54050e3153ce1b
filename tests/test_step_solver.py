"""Conjugate gradients preconditioned by the trusted edges: the same steps and results as a direct solve."""

from __future__ import annotations

import numpy as np
import pytest

from egnc.api import solve
from egnc.datasets import add_false_loops, grid_world
from egnc.errors import OptionError
from egnc.linalg.linear_solvers import cholmod_available, rslab_available
from egnc.linalg.normal_equations import edge_products
from egnc.nonlinear.factors import to_matrices
from egnc.nonlinear.least_squares import Problem, SolverOptions, solve_least_squares
from egnc.robust.kernels import make_kernel
from egnc.robust.losses import KernelLoss

BACKENDS = [
    "scipy",
    pytest.param("cholmod", marks=pytest.mark.skipif(not cholmod_available(), reason="no scikit-sparse")),
    pytest.param("rslab", marks=pytest.mark.skipif(not rslab_available(), reason="no rslab")),
]


@pytest.fixture(scope="module", params=[2, 3], ids=["2d", "3d"])
def corrupted(request):
    """A grid world with 30% false loop closures (false loops join distant poses)."""
    world = grid_world(request.param, 300, seed=5, noise_scale=0.3)
    clean = solve(world.graph, "l2")
    return add_false_loops(world.graph, 30, seed=6, reference_poses=clean.graph.poses)


def products_and_weights(problem: Problem, graph, poses):
    """Per-edge products and Geman-McClure weights at `poses`."""
    linearization = problem.factors.linearize(poses)
    r = problem.factors.whitened_norms(linearization.residuals)
    weights = np.where(graph.is_loop_closure, make_kernel("gm", c=3.0).weight(r, np.ones_like(r)), 1.0)
    return edge_products(linearization, problem.factors.information, weights), weights


def linearized_system(problem: Problem, graph, poses):
    """`H` data, gradient, per-edge products and Geman-McClure weights at `poses`."""
    products, weights = products_and_weights(problem, graph, poses)
    data, gradient = problem.pattern.scatter(products)
    return data, gradient, products, weights


def damped_system_and_direct_step(graph, backend: str):
    """The step solver of `graph`, its linearized system at the file's poses, an LM shift, and the direct step."""
    problem = Problem.from_graph(graph, backend)
    data, gradient, products, weights = linearized_system(problem, graph, to_matrices(graph.dim, graph.poses))
    steps = problem.step_solver
    shift = 1e-6 * np.clip(data[problem.pattern.diagonal_slots], 1e-6, 1e32)
    steps.set_system(products, weights, "direct")
    return steps, data, gradient, products, weights, shift, steps.solve(shift, gradient)


@pytest.mark.parametrize("backend", BACKENDS)
def test_preconditioned_step_equals_the_direct_step(corrupted, backend):
    graph = corrupted.graph
    problem = Problem.from_graph(graph, backend)
    data, gradient, products, weights = linearized_system(problem, graph, to_matrices(graph.dim, graph.poses))
    assert (weights < 1e-4).sum() > 0.5 * corrupted.is_outlier.sum()  # most false loops are switched off
    shift = 1e-6 * np.clip(data[problem.pattern.diagonal_slots], 1e-6, 1e32)
    steps = problem.step_solver
    steps.set_system(products, weights, "direct")
    direct = steps.solve(shift, gradient)
    steps.set_system(products, weights, "auto", trust_weight=1e-4)
    preconditioned = steps.solve(shift, gradient)
    assert steps.statistics.cg_solves == 1 and steps.statistics.cg_fallbacks == 0
    assert 0 < steps.statistics.cg_iterations <= 50
    np.testing.assert_allclose(preconditioned, direct, rtol=0, atol=1e-8 * np.abs(direct).max())


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_preconditioned_step_builds_no_whole_pattern_and_sums_the_same_gradient(corrupted, backend, monkeypatch):
    """CG's operator is the trusted system plus the other edges' products: the pattern of every
    edge (false loops' fill-in included) is not built, and the gradient and diagonal of `H` that
    `set_system` returns are the whole pattern's, bit for bit."""
    import egnc.linalg.step_solver as step_solver

    graph = corrupted.graph
    built = []
    build = step_solver.NormalEquationsPattern.build

    def recorded_build(edges, *args, **kwargs):
        built.append(len(edges))
        return build(edges, *args, **kwargs)

    monkeypatch.setattr(step_solver.NormalEquationsPattern, "build", recorded_build)
    problem = Problem.from_graph(graph, backend)
    products, weights = products_and_weights(problem, graph, to_matrices(graph.dim, graph.poses))
    steps = problem.step_solver
    gradient, diagonal = steps.set_system(products, weights, "auto", trust_weight=1e-4)
    shift = 1e-6 * np.clip(diagonal, 1e-6, 1e32)
    preconditioned = steps.solve(shift, gradient)
    assert steps.statistics.cg_solves == 1 and steps.statistics.cg_fallbacks == 0
    assert len(built) == 1 and built[0] < graph.num_edges  # the trusted edges' pattern only
    data, whole_gradient = problem.pattern.scatter(products)
    assert built[1:] == [graph.num_edges]  # built when read
    np.testing.assert_array_equal(gradient, whole_gradient)
    np.testing.assert_array_equal(diagonal, data[problem.pattern.diagonal_slots])
    steps.set_system(products, weights, "direct")
    direct = steps.solve(shift, gradient)
    np.testing.assert_allclose(preconditioned, direct, rtol=0, atol=1e-8 * np.abs(direct).max())


@pytest.mark.parametrize("backend", BACKENDS)
def test_conjugate_gradients_that_stall_fall_back_to_the_direct_solve(corrupted, backend):
    graph = corrupted.graph
    problem = Problem.from_graph(graph, backend)
    data, gradient, products, weights = linearized_system(problem, graph, to_matrices(graph.dim, graph.poses))
    shift = np.full(problem.pattern.size, 1e-3)
    steps = problem.step_solver
    steps.set_system(products, weights, "direct")
    direct = steps.solve(shift, gradient)
    steps.set_system(products, weights, "auto", trust_weight=0.5)
    step = steps.solve(shift, gradient, max_cg_iterations=1)
    assert steps.statistics.cg_fallbacks == 1 and steps.statistics.direct_solves == 2
    np.testing.assert_allclose(step, direct, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_given_set_that_leaves_out_edges_whose_weight_came_back_is_widened_by_them(corrupted, backend):
    """A given trusted set without the heavy loop closures: CG on it stops after
    `WIDEN_AFTER_ITERATIONS`, starts again on the set widened by every edge at `trust_weight` or
    more and lands on the direct step; the next linearization of the same solve is widened at once."""
    from egnc.linalg.step_solver import WIDEN_AFTER_ITERATIONS

    graph = corrupted.graph
    steps, data, gradient, products, weights, shift, direct = damped_system_and_direct_step(graph, backend)
    trust = 1e-4
    given = weights >= trust
    given[graph.is_loop_closure] = False  # every loop the kernel keeps came back
    steps.start_solve()
    steps.set_system(products, weights, "auto", trust_weight=trust, trusted=given)
    step = steps.solve(shift, gradient)
    statistics = steps.statistics
    assert (statistics.widened_steps, statistics.cg_solves, statistics.cg_fallbacks) == (1, 2, 0)
    assert statistics.cg_iterations > WIDEN_AFTER_ITERATIONS
    np.testing.assert_allclose(step, direct, rtol=0, atol=1e-8 * np.abs(direct).max())
    analyses, spent = steps.analyses, statistics.cg_iterations
    steps.set_system(products, weights, "auto", trust_weight=trust, trusted=given)
    step = steps.solve(shift, gradient)
    assert statistics.widened_steps == 2 and steps.analyses == analyses  # the widened analysis, reused
    assert statistics.cg_iterations - spent < WIDEN_AFTER_ITERATIONS
    np.testing.assert_allclose(step, direct, rtol=0, atol=1e-8 * np.abs(direct).max())
    steps.start_solve()  # a new solve starts from the given set again
    steps.set_system(products, weights, "auto", trust_weight=trust, trusted=weights >= trust)
    steps.solve(shift, gradient)
    assert steps.statistics.widened_steps == 0


def test_a_given_set_on_which_cg_converges_in_time_is_not_widened(corrupted, monkeypatch):
    """CG that converges within `WIDEN_AFTER_ITERATIONS` on a given set leaving out some returned
    edges gives the step it gave without the bound, bit for bit."""
    import egnc.linalg.step_solver as step_solver

    graph = corrupted.graph
    steps, data, gradient, products, weights, shift, direct = damped_system_and_direct_step(graph, "scipy")
    given = weights >= 1e-4
    given[np.flatnonzero(graph.is_loop_closure & given)[:3]] = False
    results = {}
    for bound in (step_solver.WIDEN_AFTER_ITERATIONS, 10**6):
        monkeypatch.setattr(step_solver, "WIDEN_AFTER_ITERATIONS", bound)
        steps.start_solve()
        steps.set_system(products, weights, "auto", trusted=given)
        results[bound] = steps.solve(shift, gradient)
        assert steps.statistics.widened_steps == 0 and steps.statistics.cg_iterations < 20
    np.testing.assert_array_equal(*results.values())


def test_a_nonlinear_solve_on_a_given_set_that_misses_heavy_edges_ends_where_the_direct_one_does(corrupted):
    """The online solver's case: one trusted set for a whole solve. Left without the loops the
    kernel keeps, the solve widens it and ends at the direct solve's poses, and says so."""
    graph = corrupted.graph
    problem = Problem.from_graph(graph, "scipy")
    loss = KernelLoss(make_kernel("gm", c=3.0), np.ones(graph.num_edges), graph.is_loop_closure)
    poses = to_matrices(graph.dim, graph.poses)
    given = ~graph.is_loop_closure
    direct = solve_least_squares(problem, poses, loss, SolverOptions(linear_method="direct"))
    widened = solve_least_squares(problem, poses, loss, SolverOptions(), trusted=given)
    assert widened.linear.widened_steps >= 1 and widened.linear.cg_fallbacks == 0
    assert widened.iterations == direct.iterations
    np.testing.assert_allclose(widened.poses, direct.poses, rtol=0, atol=1e-8)


def test_trusted_edges_that_leave_a_pose_loose_are_not_a_preconditioner(corrupted):
    graph = corrupted.graph
    problem = Problem.from_graph(graph, "scipy")
    data, gradient, products, weights = linearized_system(problem, graph, to_matrices(graph.dim, graph.poses))
    weights = weights.copy()
    weights[np.flatnonzero(graph.is_odometry)[5]] = 1e-9  # cuts the odometry chain where no trusted loop bridges
    weights[graph.is_loop_closure] = 1e-9
    steps = problem.step_solver
    steps.set_system(products, weights, "auto", trust_weight=1e-4)
    steps.solve(np.full(problem.pattern.size, 1e-3), gradient)
    assert steps.statistics.cg_solves == 0 and steps.statistics.direct_solves == 1


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", ["egnc", "gm", "gnc-tls"])
def test_robust_solves_are_the_same_with_either_linear_method(corrupted, backend, method):
    results = {
        linear: solve(corrupted.graph, method, linear_solver=backend, options=SolverOptions(linear_method=linear))
        for linear in ("direct", "auto")
    }
    direct, auto = results["direct"], results["auto"]
    np.testing.assert_array_equal(auto.inliers, direct.inliers)
    np.testing.assert_allclose(auto.graph.poses, direct.graph.poses, rtol=0, atol=1e-8)
    assert [s.iterations for s in auto.stages] == [s.iterations for s in direct.stages]


def test_linear_method_options_are_checked():
    with pytest.raises(OptionError, match="linear_method"):
        SolverOptions(linear_method="cg")  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="trust_weight"):
        SolverOptions(trust_weight=0.0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_trusted_set_inside_an_analysed_one_reuses_it_and_no_other_does(corrupted, backend):
    graph = corrupted.graph
    steps, data, gradient, products, weights, shift, direct = damped_system_and_direct_step(graph, backend)
    trust = 1e-4
    loops = np.flatnonzero(graph.is_loop_closure)
    trusted_loops, untrusted_loops = loops[weights[loops] >= trust], loops[weights[loops] < trust]
    assert len(trusted_loops) >= 3 and len(untrusted_loops)
    weights = weights.copy()
    weights[untrusted_loops[0]] = 0.5 * trust  # just below the trust weight

    def step_with(moved: np.ndarray) -> None:
        steps.set_system(products, moved, "auto", trust_weight=trust)
        np.testing.assert_allclose(steps.solve(shift, gradient), direct, rtol=0, atol=1e-8 * np.abs(direct).max())

    step_with(weights)
    # a trusted set inside the analysed one (loops that lost their trust): the same analysis
    shrunk = weights.copy()
    shrunk[trusted_loops[:3]] = 0.1 * trust
    step_with(shrunk)
    assert steps.analyses == 1 and steps.statistics.cg_fallbacks == 0
    # the loop that was just below the trust weight was not in the pattern: it needs a new one
    grown = weights.copy()
    grown[untrusted_loops[0]] = trust
    step_with(grown)
    assert steps.analyses == 2


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_given_trusted_set_is_analysed_once_across_solves(corrupted, backend):
    graph = corrupted.graph
    steps, data, gradient, products, weights, shift, direct = damped_system_and_direct_step(graph, backend)
    # The online solver's set: every edge but a few loops of full weight (new loops), which CG takes.
    given = np.ones(graph.num_edges, dtype=bool)
    given[np.flatnonzero(graph.is_loop_closure)[:5]] = False
    for _ in range(2):  # two nonlinear solves: the given set's analysis outlives start_solve
        steps.start_solve()
        steps.set_system(products, weights, "auto", trusted=given)
        step = steps.solve(shift, gradient)
        np.testing.assert_allclose(step, direct, rtol=0, atol=1e-8 * np.abs(direct).max())
        assert steps.statistics.cg_solves == 1 and steps.statistics.cg_fallbacks == 0
    assert steps.analyses == 1
    steps.set_system(products, weights, "auto", trusted=np.ones(graph.num_edges, dtype=bool))
    steps.solve(shift, gradient)
    assert steps.statistics.direct_solves == 1  # every edge given: the direct path


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_system_left_in_pose_row_order_gives_the_same_steps(corrupted, backend):
    """`fill_reducing=False` (the online solver's whole system): the pattern is in pose-row order,
    and both the preconditioned step and the fallback's direct step equal the ordered problem's."""
    graph = corrupted.graph
    steps_by_order = {}
    for fill_reducing in (True, False):
        problem = Problem.from_graph(graph, backend, fill_reducing=fill_reducing)
        data, gradient, products, weights = linearized_system(problem, graph, to_matrices(graph.dim, graph.poses))
        shift = 1e-6 * np.clip(data[problem.pattern.diagonal_slots], 1e-6, 1e32)
        steps = problem.step_solver
        steps.set_system(products, weights, "auto", trusted=weights >= 1e-4)
        preconditioned = steps.solve(shift, gradient)
        steps.set_system(products, weights, "direct")
        direct = steps.solve(shift, gradient)
        assert steps.statistics.cg_solves == 1 and steps.statistics.direct_solves == 1
        # Per pose, in pose-row order: unknown block free_index[p] belongs to pose p.
        free = problem.pattern.free_index >= 0
        blocks = problem.pattern.free_index[free]
        per_pose = [step.reshape(-1, graph.tangent_dim)[blocks] for step in (preconditioned, direct)]
        steps_by_order[fill_reducing] = per_pose
        if not fill_reducing:
            np.testing.assert_array_equal(blocks, np.arange(len(blocks)))
    for ordered, row_order in zip(steps_by_order[True], steps_by_order[False]):
        np.testing.assert_allclose(row_order, ordered, rtol=0, atol=1e-8 * np.abs(ordered).max())


def test_scipy_orders_a_system_at_its_first_factorization_and_solves_it_as_if_built_in_that_order(
    corrupted, monkeypatch
):
    """SuperLU's block order costs a factorization: a pattern stays in pose-row order until it is
    factorized, and its direct step then equals, bit for bit, that of the pattern built in order."""
    import egnc.linalg.analysis as analysis
    import egnc.linalg.step_solver as step_solver

    graph = corrupted.graph
    orders = []
    block_order = step_solver.block_order

    def counted_block_order(*args):
        orders.append(args)
        return block_order(*args)

    for module in (step_solver, analysis):  # at analysis, or at the first factorization
        monkeypatch.setattr(module, "block_order", counted_block_order)
    direct_steps = {}
    for deferred in (False, True):
        monkeypatch.setattr(step_solver, "orders_by_factorizing", lambda name, deferred=deferred: deferred)
        orders.clear()
        problem = Problem.from_graph(graph, "scipy")
        free = problem.pattern.free_index >= 0
        blocks = problem.pattern.free_index[free]
        assert np.array_equal(blocks, np.arange(len(blocks))) == deferred
        assert len(orders) == (0 if deferred else 1)
        data, gradient, products, weights = linearized_system(problem, graph, to_matrices(graph.dim, graph.poses))
        shift = 1e-6 * np.clip(data[problem.pattern.diagonal_slots], 1e-6, 1e32)
        steps = problem.step_solver
        steps.set_system(products, weights, "direct")
        direct_steps[deferred] = [steps.solve(shift, gradient).reshape(-1, graph.tangent_dim)[blocks]]
        assert len(orders) == 1
        # Many right-hand sides (as the marginal covariances solve), given in pose-row order.
        unknowns = (blocks[:, None] * graph.tangent_dim + np.arange(graph.tangent_dim)).ravel()
        rhs = np.random.default_rng(0).normal(size=(len(unknowns), 70))
        laid_out = np.empty_like(rhs)
        laid_out[unknowns] = rhs
        direct_steps[deferred].append(problem.linear_solver.factorize(data)(laid_out)[unknowns])
        assert len(orders) == 1  # a second factorization reuses the order
    for deferred_step, ordered_step in zip(direct_steps[True], direct_steps[False]):
        np.testing.assert_array_equal(deferred_step, ordered_step)
