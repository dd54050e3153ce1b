"""mu*: against scalar brentq on DESIGN.md's F, the published values, its limits and shape, and
the convexity it promises."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from egnc.errors import EgncError
from egnc.robust.kernels import make_kernel
from egnc.robust.mu_star import _margin_and_slope, convexity_margin, mu_star


def design_f(mu, r, c):
    """DESIGN.md section 2, literally: sign(F) = sign(d2rho/dr2) of SIG at r."""
    u = r ** (2.0 * mu)
    c2 = c * c
    return (c2 + u - 3.0 * mu * u - 2.0 * mu**2 * u) * (c2 + u) + 4.0 * mu**2 * u**2


def reference_mu_star(r, c):
    if r <= c / math.sqrt(3.0):
        return 1.0
    return brentq(design_f, 0.0, 1.0, args=(r, c), xtol=1e-15, rtol=4 * np.finfo(float).eps)


@pytest.mark.parametrize("c", [1.0, 2.0, 3.0, 6.0])
def test_matches_scalar_brentq(c):
    rng = np.random.default_rng(int(c * 10))
    r = 10.0 ** rng.uniform(-3.0, 4.0, 300)
    expected = np.array([reference_mu_star(x, c) for x in r])
    np.testing.assert_allclose(mu_star(r, c), expected, rtol=0.0, atol=1e-10)


def test_published_values():
    """DESIGN.md section 2 (c = 3): r = 2 -> 0.923, r = 5 -> 0.673, r = 50 -> 0.515."""
    got = np.round(mu_star([2.0, 5.0, 50.0], 3.0), 3)
    np.testing.assert_array_equal(got, [0.923, 0.673, 0.515])


@pytest.mark.parametrize("c", [1.0, 3.0, 6.0])
def test_one_inside_the_always_convex_radius(c):
    edge = c / math.sqrt(3.0)
    r = np.array([0.0, 1e-300, 0.5 * edge, edge])
    np.testing.assert_array_equal(mu_star(r, c), 1.0)
    just_above = mu_star(edge * (1 + 1e-6), c)
    assert 0.99 < just_above < 1.0


def test_tends_to_one_half():
    r = np.logspace(1, 8, 15)
    m = mu_star(r, 3.0)
    assert np.all(m >= 0.5)
    assert m[-1] - 0.5 < 1e-13
    # Leading order of G = 0 for large r: mu* - 1/2 = c^4 / r^2.
    big = np.logspace(4, 6, 9)
    np.testing.assert_allclose(mu_star(big, 3.0) - 0.5, 81.0 / big**2, rtol=1e-2)
    assert mu_star(1e150, 3.0) == pytest.approx(0.5, abs=1e-14)


@pytest.mark.parametrize("c", [1.0, 2.0, 3.0, 6.0])
def test_monotone_non_increasing(c):
    r = np.logspace(-3, 8, 2000)
    assert np.all(np.diff(mu_star(r, c)) <= 2e-14)


@pytest.mark.parametrize("c", [1.0, 2.0, 3.0, 6.0])
def test_single_sign_change_on_unit_interval(c):
    """The premise of the bracketing solve, checked on DESIGN.md's F itself."""
    mu = np.linspace(0.0, 1.0, 4001)
    for r in np.logspace(math.log10(c / math.sqrt(3.0)) + 0.01, 4.0, 80):
        signs = np.sign(design_f(mu, r, c))
        assert np.count_nonzero(np.diff(signs[signs != 0]) != 0) == 1, r


@pytest.mark.parametrize("c", [1.0, 3.0, 6.0])
def test_kernel_is_flat_at_mu_star(c):
    """At mu* SIG's second derivative vanishes; just below it is convex, just above it is not."""
    sig = make_kernel("sig", c=c)
    r = np.logspace(math.log10(c / math.sqrt(3.0)) + 0.05, 4.0, 60)
    m = mu_star(r, c)
    at, below, above = sig.d2rho(r, m), sig.d2rho(r, m - 1e-6), sig.d2rho(r, m + 1e-6)
    assert np.all(below > 0.0) and np.all(above < 0.0)
    assert np.all(np.abs(at) < 1e-6 * np.minimum(below, -above))


def test_margin_is_f_over_d_squared():
    r = np.logspace(-2, 3, 50)[:, None]
    mu = np.linspace(0.0, 1.0, 11)[None, :]
    c = 3.0
    expected = design_f(mu, r, c) / (c * c + r ** (2 * mu)) ** 2
    got = convexity_margin(mu, 2 * np.log(r), 2 * math.log(c))
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-12)


def test_slope_matches_finite_differences():
    """The Newton solve's dG/dmu against central differences of G, across the bracket and r."""
    r = np.logspace(0, 3, 40)[:, None]
    mu = np.linspace(0.5, 1.0, 11)[None, :]
    log_r2, log_c2, h = 2 * np.log(r), 2 * math.log(3.0), 1e-6
    _, slope = _margin_and_slope(mu, log_r2, log_c2)
    central = (convexity_margin(mu + h, log_r2, log_c2) - convexity_margin(mu - h, log_r2, log_c2)) / (2 * h)
    np.testing.assert_allclose(slope, central, rtol=1e-6, atol=1e-9)


def test_shapes_and_extremes():
    assert mu_star([]).shape == (0,)
    assert mu_star(2.0).shape == ()
    grid = np.array([[0.0, 2.0], [5.0, 1e150]])
    np.testing.assert_allclose(mu_star(grid), [[1.0, 0.923462], [0.672674, 0.5]], atol=1e-6)
    # c^2 / r below 1e-160: G(1/2) underflows and mu* is 1/2 to the last bit.
    assert mu_star(1e150, c=1e-6) == 0.5


@pytest.mark.parametrize(
    "r, c", [([-1.0], 3.0), ([np.nan], 3.0), ([np.inf], 3.0), ([1.0], 0.0), ([1.0], -2.0)]
)
def test_invalid_input_raises(r, c):
    with pytest.raises(EgncError):
        mu_star(r, c)
