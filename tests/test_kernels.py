"""Kernel registry: values against literal formulas, derivatives against complex-step and finite
differences, special cases, extreme inputs, and GTSAM's loss functions where the wheel exists."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.stats import chi2

from egnc.errors import EgncError
from egnc.robust.kernels import KERNELS, Kernel, gnc_barc2, make_kernel

BARC2_3D = 0.5 * chi2.ppf(0.99, 3)
R_GRID = np.logspace(-6, 6, 241)

# ---------------------------------------------------------------- reference formulas
# Written straight from the papers and complex-capable, so that Im(rho(r + i h)) / h is rho'(r)
# (complex step). Branches are chosen on the real part. A complex step is exact only if the
# formula's own derivative does not cancel, so saturating kernels also get a second form,
# `0.5 c^2 r^(2 - 2 mu) u / (c^2 + u)`, whose product-rule terms are all non-negative, with the
# saturating ratio taken as `1 - c^2 / (c^2 + u)` once `u > c^2`.


def saturating_ratio(u, c2):
    """`u / (c2 + u)`, arranged so that neither its value nor its complex step cancels."""
    return np.where(u.real < c2, u / (c2 + u), 1.0 - c2 / (c2 + u))


def ref_l2(r, mu, p):
    return 0.5 * r * r


def ref_huber(r, mu, p):
    k = p["k"]
    return np.where(r.real <= k, 0.5 * r * r, k * (r - 0.5 * k))


def ref_cauchy(r, mu, p):
    t = r * r / p["k"] ** 2
    # numpy's complex log1p drops the real part of tiny arguments; the complex step needs only Im.
    return 0.5 * p["k"] ** 2 * (np.log1p(t) if np.isrealobj(t) else np.log(1.0 + t))


def ref_gm(r, mu, p):
    c = p["c"]
    return 0.5 * c**2 * r**2 / (c**2 + r**2)


def ref_gm_smooth(r, mu, p):
    c2 = p["c"] ** 2
    return 0.5 * c2 * saturating_ratio(r**2, c2)


def ref_sig(r, mu, p):
    c = p["c"]
    return 0.5 * c**2 * r**2 / (c**2 + np.power(r**2, mu))


def ref_sig_smooth(r, mu, p):
    c2 = p["c"] ** 2
    return 0.5 * c2 * np.power(r**2, 1.0 - mu) * saturating_ratio(np.power(r**2, mu), c2)


def ref_gnc_gm(r, mu, p):
    # Yang et al. 2020 eq. (12) with the GTSAM factor error f = 0.5 r^2 in place of r^2.
    a, f = mu * p["barc2"], 0.5 * r * r
    return a * f / (a + f)


def ref_gnc_gm_smooth(r, mu, p):
    a, f = mu * p["barc2"], 0.5 * r * r
    return a * saturating_ratio(f, a)


def ref_gnc_tls(r, mu, p):
    # Yang et al. 2020 eq. (14) with f = 0.5 r^2.
    c2, f = p["barc2"], 0.5 * r * r
    lo, hi = mu / (mu + 1.0) * c2, (mu + 1.0) / mu * c2
    middle = 2.0 * np.sqrt(c2 * mu * (mu + 1.0) * f) - mu * (c2 + f)
    return np.where(f.real <= lo, f, np.where(f.real >= hi, c2, middle))


# (name, params, literal rho, complex-step-safe rho, mus, kinks in r or None for TLS's own)
CASES = [
    ("l2", {}, ref_l2, ref_l2, [None], []),
    ("huber", {"k": 1.345}, ref_huber, ref_huber, [None], [1.345]),
    ("cauchy", {"k": 2.3849}, ref_cauchy, ref_cauchy, [None], []),
    ("gm", {"c": 3.0}, ref_gm, ref_gm_smooth, [None], []),
    ("sig", {"c": 3.0}, ref_sig, ref_sig_smooth, [0.0, 0.25, 0.5, 0.7, 0.923, 1.0], []),
    ("sig", {"c": 1.0}, ref_sig, ref_sig_smooth, [0.0, 0.6, 1.0], []),
    ("gnc-gm", {"barc2": BARC2_3D}, ref_gnc_gm, ref_gnc_gm_smooth, [1.0, 1.4, 10.0, 1e3], []),
    ("gnc-tls", {"barc2": BARC2_3D}, ref_gnc_tls, ref_gnc_tls, [1e-6, 0.03, 1.0, 10.0, 1e4], None),
]
CASE_IDS = [f"{name}-{'-'.join(f'{v:g}' for v in p.values())}" for name, p, *_ in CASES]


def kinks(name, params, mu, extra):
    """r values where the kernel switches formula (finite differences must not straddle them)."""
    if extra is not None:
        return np.asarray(extra, dtype=float)
    c2 = params["barc2"]
    return np.sqrt(2.0 * np.array([mu / (mu + 1.0) * c2, (mu + 1.0) / mu * c2]))


def smooth_points(r, kink_r, rel=1e-3):
    """Mask of r farther than `rel * r` from every kink."""
    keep = np.ones(r.shape, dtype=bool)
    for k in np.atleast_1d(kink_r):
        keep &= np.abs(r - k) > rel * r
    return keep


def complex_step_derivative(fun, r):
    """d fun / dr by the complex step, exact to rounding for analytic `fun`."""
    h = 1e-30 * r
    return fun(r + 1j * h).imag / h


def cases(smooth=False):
    """`(name, params, reference rho, mu, kinks)` for every kernel and mu under test."""
    return [
        pytest.param(name, params, ref_smooth if smooth else ref, mu, extra, id=f"{cid}-mu{mu}")
        for (name, params, ref, ref_smooth, mus, extra), cid in zip(CASES, CASE_IDS)
        for mu in mus
    ]


# ---------------------------------------------------------------- registry


def test_registry_names():
    assert set(KERNELS) == {"l2", "huber", "cauchy", "gm", "sig", "gnc-gm", "gnc-tls"}
    for name in KERNELS:
        params = {"d": 3} if name.startswith("gnc") else {}
        kernel = make_kernel(name, **params)
        assert isinstance(kernel, Kernel) and kernel.name == name
    assert make_kernel("sig").graduated and make_kernel("sig").mu_target == 1.0
    assert make_kernel("gnc-tls", d=3).mu_target == math.inf
    assert not make_kernel("huber").graduated


def test_unknown_name_lists_valid_names():
    with pytest.raises(EgncError, match="unknown kernel 'tukey'.*cauchy, gm, gnc-gm"):
        make_kernel("tukey")


@pytest.mark.parametrize(
    "name, params, message",
    [
        ("sig", {"k": 1.0}, "valid parameters: c"),
        ("huber", {"c": 1.0}, "valid parameters: k"),
        ("l2", {"c": 1.0}, "valid parameters: none"),
        ("sig", {"c": 0.0}, "positive"),
        ("cauchy", {"k": -1.0}, "positive"),
        ("gm", {"c": math.nan}, "positive"),
        ("sig", {"c": "three"}, "number"),
        ("gnc-gm", {}, "exactly one of d"),
        ("gnc-tls", {"d": 3, "barc2": 1.0}, "exactly one of d"),
        ("gnc-tls", {"d": 0}, "positive integer"),
        ("gnc-gm", {"d": 3, "p": 1.0}, "in \\(0, 1\\)"),
    ],
)
def test_invalid_parameters_raise(name, params, message):
    with pytest.raises(EgncError, match=message):
        make_kernel(name, **params)


def test_gnc_threshold_is_gtsam_default():
    assert gnc_barc2(3) == pytest.approx(0.5 * chi2.ppf(0.99, 3), rel=1e-15)
    assert make_kernel("gnc-gm", d=6).params["barc2"] == pytest.approx(0.5 * chi2.ppf(0.99, 6))
    assert make_kernel("gnc-tls", d=3, p=0.95).params["barc2"] == pytest.approx(
        0.5 * chi2.ppf(0.95, 3)
    )
    assert make_kernel("gnc-tls", barc2=2.5).params["barc2"] == 2.5


def test_shapes_and_broadcasting():
    r = np.linspace(0.0, 10.0, 7)
    sig = make_kernel("sig")
    assert sig.weight(r, 0.3).shape == (7,)
    assert sig.weight(r, np.linspace(0, 1, 7)).shape == (7,)
    assert sig.rho(2.0).shape == ()
    huber = make_kernel("huber")
    assert huber.rho(r, np.zeros(7)).shape == (7,)
    np.testing.assert_array_equal(sig.rho(r), sig.rho(r, 1.0))


# ---------------------------------------------------------------- values and derivatives


@pytest.mark.parametrize("name, params, ref, mu, extra", cases())
def test_rho_matches_literal_formula(name, params, ref, mu, extra):
    kernel = make_kernel(name, **params)
    expected = ref(R_GRID, mu, params)
    # TLS's literal middle piece subtracts two terms of size mu * barc2.
    rtol = 1e-10 if name == "gnc-tls" else 1e-13
    np.testing.assert_allclose(kernel.rho(R_GRID, mu), expected, rtol=rtol, atol=1e-300)


@pytest.mark.parametrize("name, params, ref, mu, extra", cases(smooth=True))
def test_weight_is_rho_prime_over_r(name, params, ref, mu, extra):
    """Against the complex-step derivative of the literal rho (exact to rounding)."""
    kernel = make_kernel(name, **params)
    r = R_GRID[smooth_points(R_GRID, kinks(name, params, mu, extra), rel=1e-12)]
    rho_prime = complex_step_derivative(lambda z: ref(z, mu, params), r)
    rtol = 1e-8 if name == "gnc-tls" else 1e-11
    np.testing.assert_allclose(kernel.weight(r, mu) * r, rho_prime, rtol=rtol, atol=1e-300)


@pytest.mark.parametrize("name, params, ref, mu, extra", cases(smooth=True))
def test_d2rho_matches_fd_of_rho_prime(name, params, ref, mu, extra):
    """Central differences (step 1e-5 r) of the complex-step rho'."""
    kernel = make_kernel(name, **params)
    r = R_GRID[smooth_points(R_GRID, kinks(name, params, mu, extra))]
    h = 1e-5 * r

    def rho_prime(x):
        return complex_step_derivative(lambda z: ref(z, mu, params), x)

    fd = (rho_prime(r + h) - rho_prime(r - h)) / (2.0 * h)
    # Truncation ~ h^2 rho'''' and rounding ~ eps |rho'| / h, both below 1e-6 of this scale.
    scale = np.abs(fd) + np.abs(rho_prime(r)) / r
    np.testing.assert_array_less(np.abs(kernel.d2rho(r, mu) - fd), 1e-6 * scale + 1e-300)


@pytest.mark.parametrize("name, params, ref, mu, extra", cases())
def test_own_functions_are_consistent_by_finite_differences(name, params, ref, mu, extra):
    """weight * r is the central difference of the kernel's own rho, d2rho that of weight * r."""
    kernel = make_kernel(name, **params)
    r = R_GRID[smooth_points(R_GRID, kinks(name, params, mu, extra))]
    h = 1e-5 * r
    fd1 = (kernel.rho(r + h, mu) - kernel.rho(r - h, mu)) / (2.0 * h)
    scale1 = np.abs(fd1) + np.abs(kernel.rho(r, mu)) / r
    np.testing.assert_array_less(np.abs(kernel.weight(r, mu) * r - fd1), 1e-6 * scale1 + 1e-300)

    def grad(x):
        return kernel.weight(x, mu) * x

    fd2 = (grad(r + h) - grad(r - h)) / (2.0 * h)
    scale2 = np.abs(fd2) + np.abs(grad(r)) / r
    np.testing.assert_array_less(np.abs(kernel.d2rho(r, mu) - fd2), 1e-6 * scale2 + 1e-300)


# ---------------------------------------------------------------- special cases


@pytest.mark.parametrize("c", [1.0, 3.0, 6.0])
def test_sig_at_one_is_geman_mcclure(c):
    sig, gm = make_kernel("sig", c=c), make_kernel("gm", c=c)
    r = np.concatenate([[0.0], R_GRID])
    c2, r2 = c * c, r * r
    np.testing.assert_allclose(sig.rho(r, 1.0), 0.5 * c2 * r2 / (c2 + r2), rtol=1e-14)
    np.testing.assert_allclose(sig.weight(r, 1.0), c2**2 / (c2 + r2) ** 2, rtol=1e-13)
    np.testing.assert_allclose(
        sig.d2rho(r, 1.0), c2**2 * (c2 - 3 * r2) / (c2 + r2) ** 3, rtol=1e-12, atol=1e-300
    )
    for fn in ("rho", "weight", "d2rho"):
        np.testing.assert_array_equal(getattr(sig, fn)(r, 1.0), getattr(gm, fn)(r))


@pytest.mark.parametrize("c", [1.0, 3.0, 6.0])
def test_sig_at_zero_is_scaled_quadratic(c):
    sig = make_kernel("sig", c=c)
    r = np.concatenate([[0.0], R_GRID])
    scale = c * c / (c * c + 1.0)
    np.testing.assert_allclose(sig.rho(r, 0.0), 0.5 * scale * r * r, rtol=1e-14)
    np.testing.assert_allclose(sig.weight(r, 0.0), scale, rtol=1e-14)
    np.testing.assert_allclose(sig.d2rho(r, 0.0), scale, rtol=1e-14)


def test_zero_residual_is_exact():
    for name in KERNELS:
        kernel = make_kernel(name, **({"d": 3} if name.startswith("gnc") else {}))
        mus = {"sig": [0.0, 0.5, 1.0], "gnc-gm": [1.0, 1e3, math.inf]}.get(name, [None])
        if name == "gnc-tls":
            mus = [0.0, 1e-6, 1.0, math.inf]
        for mu in mus:
            assert kernel.rho(0.0, mu) == 0.0
            expected = 1.0 if name != "sig" or mu != 0.0 else 9.0 / 10.0
            assert kernel.weight(0.0, mu) == pytest.approx(expected, rel=1e-15)


def test_graduated_limits():
    """gnc-gm -> least squares as mu -> inf; gnc-tls -> truncated quadratic at mu = inf."""
    gm, tls = make_kernel("gnc-gm", barc2=2.0), make_kernel("gnc-tls", barc2=2.0)
    r = np.array([0.0, 0.5, 1.9, 2.0, 2.1, 10.0])
    np.testing.assert_array_equal(gm.weight(r, math.inf), 1.0)
    np.testing.assert_array_equal(gm.rho(r, math.inf), 0.5 * r * r)
    np.testing.assert_allclose(gm.weight(r, 1e12), 1.0, rtol=1e-10)
    # f = 0.5 r^2 <= barc2 = 2  <=>  r <= 2 (the boundary counts as an inlier).
    np.testing.assert_array_equal(tls.weight(r, math.inf), [1, 1, 1, 1, 0, 0])
    np.testing.assert_array_equal(tls.rho(r, math.inf), np.minimum(0.5 * r * r, 2.0))
    np.testing.assert_array_equal(tls.d2rho(r, math.inf), [1, 1, 1, 1, 0, 0])


def test_tls_weights_at_the_thresholds():
    """GTSAM: weight 1 at f <= mu/(mu+1) barc2, 0 at f >= (mu+1)/mu barc2, continuous between."""
    barc2, mu = 3.0, 0.7
    tls = make_kernel("gnc-tls", barc2=barc2)
    lo, hi = mu / (mu + 1) * barc2, (mu + 1) / mu * barc2
    r_lo, r_hi = math.sqrt(2 * lo), math.sqrt(2 * hi)
    # sqrt(2 lo) ** 2 / 2 may round either side of lo, the weight is continuous there anyway.
    assert tls.weight(r_lo, mu) == pytest.approx(1.0, abs=1e-12)
    assert tls.weight(r_hi, mu) == pytest.approx(0.0, abs=1e-12)
    assert tls.weight(r_lo * (1 - 1e-9), mu) == 1.0
    assert tls.weight(r_hi * (1 + 1e-9), mu) == 0.0
    assert tls.weight(r_lo * (1 + 1e-9), mu) == pytest.approx(1.0, abs=1e-8)
    assert tls.weight(r_hi * (1 - 1e-9), mu) == pytest.approx(0.0, abs=1e-8)
    assert tls.rho(r_hi, mu) == pytest.approx(barc2, rel=1e-12)
    assert tls.rho(r_hi * (1 - 1e-9), mu) == pytest.approx(barc2, rel=1e-12)
    assert tls.rho(r_lo * (1 + 1e-9), mu) == pytest.approx(lo, rel=1e-8)


# ---------------------------------------------------------------- extreme inputs

R_EXTREME = np.array([0.0, 5e-324, 1e-300, 1e-150, 1e-6, 1.0, 3.0, 1e6, 1e100, 1e150])
EXTREME_MUS = {
    "sig": [0.0, 1e-12, 1e-3, 0.5, 0.999, 1.0],
    "gnc-gm": [0.0, 1.0, 1.4, 1e16, 1e300, math.inf],
    "gnc-tls": [0.0, 1e-300, 1e-6, 1.0, 1e16, 1e300, math.inf],
}


@pytest.mark.parametrize("name", sorted(KERNELS))
def test_no_overflow_nan_or_warning(name):
    kernel = make_kernel(name, **({"d": 6} if name.startswith("gnc") else {}))
    for mu in EXTREME_MUS.get(name, [None]):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with np.errstate(over="raise", invalid="raise", divide="raise"):
                rho = kernel.rho(R_EXTREME, mu)
                weight = kernel.weight(R_EXTREME, mu)
                d2rho = kernel.d2rho(R_EXTREME, mu)
        for values in (rho, weight, d2rho):
            assert np.all(np.isfinite(values)), (name, mu, values)
        assert np.all(rho >= 0.0) and np.all((weight >= 0.0) & (weight <= 1.0))
        assert np.all(rho <= 0.5 * R_EXTREME**2 * (1 + 1e-14))


def test_sig_asymptotics_at_huge_residuals():
    sig = make_kernel("sig", c=3.0)
    r = 1e150
    assert sig.rho(r, 1.0) == pytest.approx(4.5, rel=1e-14)
    assert sig.rho(r, 0.5) == pytest.approx(4.5 * r, rel=1e-14)
    assert sig.weight(r, 0.5) == pytest.approx(4.5 / r, rel=1e-13)
    assert sig.rho(r, 0.0) == pytest.approx(0.45 * r * r, rel=1e-14)
    # d2rho at mu = 1/2 is q^3 > 0 (q = c^2 / (c^2 + r)); at r = 1e150 it underflows to 0.
    assert sig.d2rho(1e90, 0.5) == pytest.approx((9.0 / (9.0 + 1e90)) ** 3, rel=1e-12)


# ---------------------------------------------------------------- properties


@settings(max_examples=200, deadline=None)
@given(
    r=st.floats(0.0, 1e12),
    mu=st.floats(0.0, 1.0),
    c=st.floats(0.1, 20.0),
)
def test_sig_weight_and_value_bounds(r, mu, c):
    sig = make_kernel("sig", c=c)
    w = float(sig.weight(r, mu))
    assert 0.0 <= w <= 1.0
    assert 0.0 <= float(sig.rho(r, mu)) <= 0.5 * r * r * (1 + 1e-15)
    # rho is non-decreasing in r because rho' = w r >= 0 (up to rounding once it saturates).
    assert float(sig.rho(r * 1.01 + 1e-9, mu)) >= float(sig.rho(r, mu)) * (1 - 1e-14)


@settings(max_examples=200, deadline=None)
@given(r=st.floats(0.0, 1e12), mu=st.floats(1e-8, 1e8), barc2=st.floats(0.1, 20.0))
def test_gnc_weight_and_value_bounds(r, mu, barc2):
    for name in ("gnc-gm", "gnc-tls"):
        kernel = make_kernel(name, barc2=barc2)
        m = max(mu, 1.0) if name == "gnc-gm" else mu
        assert 0.0 <= float(kernel.weight(r, m)) <= 1.0
        assert 0.0 <= float(kernel.rho(r, m)) <= 0.5 * r * r * (1 + 1e-12) + 1e-300


# ---------------------------------------------------------------- GTSAM


def _gtsam_mestimator():
    gtsam = pytest.importorskip("gtsam")
    return gtsam.noiseModel.mEstimator


def _loop(fun, r):
    return np.array([fun(float(x)) for x in r])


R_GTSAM = np.logspace(-4, 5, 91)


def test_fixed_kernels_match_gtsam():
    m = _gtsam_mestimator()
    for ours, theirs in [
        (make_kernel("huber", k=1.345), m.Huber.Create(1.345)),
        (make_kernel("cauchy", k=2.3849), m.Cauchy.Create(2.3849)),
        (make_kernel("gm", c=3.0), m.GemanMcClure.Create(3.0)),
    ]:
        np.testing.assert_allclose(ours.rho(R_GTSAM), _loop(theirs.loss, R_GTSAM), rtol=1e-12)
        np.testing.assert_allclose(ours.weight(R_GTSAM), _loop(theirs.weight, R_GTSAM), rtol=1e-12)


@pytest.mark.parametrize("mu", [0.0, 0.3, 0.5, 0.8, 1.0])
def test_sig_matches_gtsam_scale_invariant_gm(mu):
    """GTSAM 4.3 ships SIG as GemanMcClure with GradScheme.SCALE_INVARIANT."""
    m = _gtsam_mestimator()
    theirs = m.GemanMcClure.Create(3.0, m.GemanMcClure.GradScheme.SCALE_INVARIANT)
    ours = make_kernel("sig", c=3.0)
    np.testing.assert_allclose(
        ours.rho(R_GTSAM, mu), _loop(lambda x: theirs.graduatedLoss(x, mu), R_GTSAM), rtol=1e-12
    )
    np.testing.assert_allclose(
        ours.weight(R_GTSAM, mu), _loop(lambda x: theirs.graduatedWeight(x, mu), R_GTSAM),
        rtol=1e-12,
    )


@pytest.mark.parametrize("mu", [1.0, 1.4, 7.3, 30.0, 1e4])
def test_gnc_gm_matches_gtsam(mu):
    """GTSAM 4.3 normalizes GNC's mu: Yang's GM mu is 1 / m. Its loss is on r with c^2 = 2 barc2."""
    m = _gtsam_mestimator()
    theirs = m.GemanMcClure.Create(math.sqrt(2 * BARC2_3D), m.GemanMcClure.GradScheme.STANDARD)
    ours = make_kernel("gnc-gm", d=3)
    np.testing.assert_allclose(
        ours.weight(R_GTSAM, mu), _loop(lambda x: theirs.graduatedWeight(x, 1 / mu), R_GTSAM),
        rtol=1e-12,
    )
    np.testing.assert_allclose(
        ours.rho(R_GTSAM, mu), _loop(lambda x: theirs.graduatedLoss(x, 1 / mu), R_GTSAM),
        rtol=1e-12,
    )
    # GncOptimizer's classic weight, eq. (12), on the factor error f = 0.5 r^2.
    f = 0.5 * R_GTSAM**2
    classic = (mu * BARC2_3D / (f + mu * BARC2_3D)) ** 2
    np.testing.assert_allclose(ours.weight(R_GTSAM, mu), classic, rtol=1e-13)


@pytest.mark.parametrize("mu", [1e-6, 0.0343, 0.3, 1.0, 5.0, 1e3])
def test_gnc_tls_matches_gtsam(mu):
    """GTSAM 4.3 normalizes GNC's mu: Yang's TLS mu is m / (1 - m), i.e. m = mu / (1 + mu)."""
    m = _gtsam_mestimator()
    theirs = m.TruncatedLeastSquares.Create(
        math.sqrt(2 * BARC2_3D), m.TruncatedLeastSquares.GradScheme.GNC_LINEAR
    )
    ours = make_kernel("gnc-tls", d=3)
    norm = mu / (1 + mu)
    np.testing.assert_allclose(
        ours.weight(R_GTSAM, mu), _loop(lambda x: theirs.graduatedWeight(x, norm), R_GTSAM),
        rtol=1e-9, atol=1e-12,
    )
    np.testing.assert_allclose(
        ours.rho(R_GTSAM, mu), _loop(lambda x: theirs.graduatedLoss(x, norm), R_GTSAM),
        rtol=1e-9, atol=1e-12,
    )
    # GncOptimizer's classic weight, eq. (14), on the factor error f = 0.5 r^2.
    f = 0.5 * R_GTSAM**2
    lo, hi = mu / (mu + 1) * BARC2_3D, (mu + 1) / mu * BARC2_3D
    middle = np.sqrt(BARC2_3D * mu * (mu + 1) / f) - mu
    classic = np.where(f >= hi, 0.0, np.where(f <= lo, 1.0, middle))
    np.testing.assert_allclose(ours.weight(R_GTSAM, mu), classic, rtol=1e-13, atol=1e-15)


def test_tabulated_chi2_quantiles_are_scipys_bit_for_bit():
    from scipy.special import chdtri

    from egnc.robust.kernels import CHI2_QUANTILES, chi2_quantile

    for (quantile, d), value in CHI2_QUANTILES.items():
        assert value == float(chdtri(d, 1.0 - quantile)), (quantile, d)
        assert chi2_quantile(quantile, np.int64(d)) == value
    assert chi2_quantile(0.95, 3) == float(chdtri(3, 1.0 - 0.95))  # not tabulated: computed
