"""Robust synthesis through synthesize_pd and synthesize_lmi (issue 11, deliverable 4).

Every certified gain is checked against references written here, independent of mrpctl.design:
the analytic margin of the per-axis loop at every inertia of a fine grid, the Chebyshev spectral
abscissa of the delayed loop, and the lifted discrete-time companion matrix of the sampled loop.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrpctl import Spacecraft, paper
from mrpctl.design import SynthesisStatus, synthesize_lmi, synthesize_pd
from mrpctl.design.polytope import PolytopeCertificate
from mrpctl.design.robust import DelayModel, RobustPDSynthesis, RobustStatus
from mrpctl.errors import SpecificationError
from mrpctl.model import pd_from_gain

TAU = 0.5
#: 2 - sqrt(2): the best s tau of any delayed PD loop (the triple root); alpha tau above it is impossible.
DECAY_LIMIT = 2.0 - math.sqrt(2.0)


def analytic_margin(k1: float, k2: float) -> float:
    """Exact delay margin of sigma'' = k1 sigma(t - tau) + k2 sigma'(t - tau), k1, k2 < 0."""
    a, b = -k1, -k2
    omega = math.sqrt((b * b + math.sqrt(b**4 + 4 * a * a)) / 2)
    return math.atan2(b * omega, a) / omega


def abscissa(k1: float, k2: float, tau: float, m: int = 40) -> float:
    """Rightmost Re s of the per-axis delayed loop (Chebyshev discretisation of the generator)."""
    x = np.cos(np.pi * np.arange(m + 1) / m)
    c = np.hstack([2.0, np.ones(m - 1), 2.0]) * (-1.0) ** np.arange(m + 1)
    dx = x[:, None] - x[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(m + 1))
    d = d - np.diag(d.sum(axis=1))
    gen = np.kron(d * (2.0 / tau), np.eye(2))
    gen[:2, :] = 0.0
    gen[0, 1] = 1.0
    gen[1, 2 * m] = k1
    gen[1, 2 * m + 1] = k2
    return float(np.max(np.linalg.eigvals(gen).real))


def lifted_radius(k1: float, k2: float, h: float, d: int) -> float:
    """Spectral radius of the sampled loop x_{j+1} = F x_j + g [k1, k2] x_{j-d} (double integrator, ZOH)."""
    f = np.array([[1.0, h], [0.0, 1.0]])
    g = np.array([[h * h / 2.0], [h]])
    k = np.array([[k1, k2]])
    size = 2 * (d + 1)
    comp = np.zeros((size, size))
    comp[:2, :2] = f
    comp[:2, 2 * d : 2 * d + 2] += g @ k
    comp[2:, :-2] = np.eye(size - 2)
    return float(np.max(np.abs(np.linalg.eigvals(comp))))


def axis_gains(K: np.ndarray) -> tuple[float, float]:
    k1, k2 = pd_from_gain(paper.SPACECRAFT, K)
    np.testing.assert_allclose(k1, k1[0, 0] * np.eye(3), rtol=1e-12)
    np.testing.assert_allclose(k2, k2[0, 0] * np.eye(3), rtol=1e-12)
    return float(k1[0, 0]), float(k2[0, 0])


def input_gains(tolerance: float, points: int) -> np.ndarray:
    """b = J0 / J over a grid of J in [(1 - tol) J0, (1 + tol) J0]."""
    return 1.0 / np.linspace(1.0 - tolerance, 1.0 + tolerance, points)


def test_lmi_over_a_10_percent_inertia_box_is_stable_and_decays_on_a_fine_grid() -> None:
    alpha = 0.3
    res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=alpha, order=1, tolerance=0.1, epsilons=[1.2])
    assert res.status is SynthesisStatus.SYNTHESIZED, str(res)
    assert isinstance(res.certificate, PolytopeCertificate) and res.certificate.certified
    assert isinstance(res.decay_certificate, PolytopeCertificate) and res.decay_certificate.certified
    assert res.tolerance == 0.1 and res.model is DelayModel.CONSTANT and "exact worst" in res.exact_check
    k1, k2 = axis_gains(np.asarray(res.K))
    for b in input_gains(0.1, 41):
        assert analytic_margin(b * k1, b * k2) > TAU
    for b in input_gains(0.1, 5):
        assert abscissa(b * k1, b * k2, TAU) < -alpha
    assert "inertia +/-10 %" in str(res)


def test_zero_tolerance_and_tau_min_equal_to_tau_reproduce_the_nominal_lmi_design() -> None:
    nominal = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=0.2, order=0, epsilons=[0.6])
    for kwargs in ({"tolerance": 0.0}, {"tau_min": TAU}, {"tolerance": 0.0, "product_bound": 0.0, "tau_min": TAU}):
        again = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=0.2, order=0, epsilons=[0.6], **kwargs)
        assert again.status is nominal.status is SynthesisStatus.SYNTHESIZED
        np.testing.assert_array_equal(again.K, nominal.K)
        assert again.epsilon == nominal.epsilon and not again.robust


@pytest.mark.parametrize("order", [0, pytest.param(1, marks=pytest.mark.slow)])
def test_jitter_design_is_stable_at_every_constant_delay_of_the_interval(order: int) -> None:
    alpha = 0.3
    # two ε of the search, as a user's search tries several: Clarabel fails numerically at ε = 0.5 on some hosts
    # (measured on a Zen 4 host: "solver failed" at 0.4 and 0.5, synthesized at 0.6) and not on others
    res = synthesize_lmi(
        paper.SPACECRAFT, TAU, decay_rate=alpha, order=order, tau_min=0.4, tolerance=0.05, epsilons=[0.5, 0.6]
    )
    assert res.status is SynthesisStatus.SYNTHESIZED, str(res)
    assert res.model is DelayModel.INTERVAL and (res.tau_min, res.tau_max) == (0.4, TAU)
    assert isinstance(res.certificate, PolytopeCertificate) and len(res.certificate.interval) == 3
    k1, k2 = axis_gains(np.asarray(res.K))
    # A time-varying certificate implies every constant delay of the interval decays at alpha.
    for b in input_gains(0.05, 21):
        assert analytic_margin(b * k1, b * k2) > TAU
    for b in input_gains(0.05, 3):
        for tau in (0.4, 0.45, 0.5):
            assert abscissa(b * k1, b * k2, tau) < -alpha


@pytest.mark.parametrize("order", [0, pytest.param(1, marks=pytest.mark.slow)])
def test_sampled_design_at_10_hz_is_stable_and_decays_when_lifted(order: int) -> None:
    alpha, h, d = 0.3, 0.1, 5
    res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=alpha, order=order, period=h, tolerance=0.05, epsilons=[0.6])
    assert res.status is SynthesisStatus.SYNTHESIZED, str(res)
    assert res.model is DelayModel.SAMPLED and res.tau_max == pytest.approx(TAU + h, rel=1e-15)
    k1, k2 = axis_gains(np.asarray(res.K))
    for b in input_gains(0.05, 11):
        # The certified decay e^{-alpha t} bounds the lifted radius by e^{-alpha h}.
        assert lifted_radius(b * k1, b * k2, h, d) < math.exp(-alpha * h)


@pytest.mark.parametrize("kwargs", [{"tolerance": 0.2}, {"tau_min": 0.4}, {"period": 0.1}])
def test_a_decay_rate_no_pd_loop_reaches_is_never_synthesized(kwargs: dict) -> None:
    # Exact limit: no delayed PD loop has s tau < -(2 - sqrt(2)) (the triple root), for any inertia.
    res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=1.05 * DECAY_LIMIT / TAU, order=0, epsilons=[0.5], **kwargs)
    assert res.status in (SynthesisStatus.INFEASIBLE, SynthesisStatus.SOLVER_FAILED)
    assert res.K is None and "robust synthesis LMI" in res.reason


def test_a_tolerance_beyond_the_exact_limit_is_never_synthesized() -> None:
    # Per axis the loop gain is b (K1, K2), b = J0/J in [1/(1+tol), 1/(1-tol)]: a segment of a ray
    # through the origin of the (K1, K2) plane. At unit delay and decay beta = alpha tau = 0.25 the
    # scales s on each ray whose loop decays at beta are measured here (K1 >= 0 never decays, since
    # the characteristic function is <= 0 at s = 0). The largest ratio of such scales is about 1.6
    # (tol ~ 0.24); tol = 0.8 needs (1 + tol)/(1 - tol) = 9.
    beta = 0.25
    scales = np.geomspace(1e-2, 3.0, 40)  # step factor 1.158
    best_ratio = 0.0
    for theta in np.linspace(0.0, math.pi, 62)[1:-1]:
        ok = np.array([abscissa(-s * math.sin(theta), -s * math.cos(theta), 1.0, 16) < -beta for s in scales])
        assert not (ok[0] or ok[-1])  # the decaying scales lie inside the grid
        if ok.any():
            inside = scales[ok]
            best_ratio = max(best_ratio, float(inside[-1] / inside[0]))
    # One grid step at each end, and a factor 2 for the resolution in theta.
    assert 1.0 < 2.0 * best_ratio * 1.158**2 < 9.0
    res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=beta / TAU, tolerance=0.8, epsilons=[0.3, 0.6, 1.2])
    assert res.status is not SynthesisStatus.SYNTHESIZED


def test_synthesize_pd_with_an_inertia_tolerance_returns_the_robust_result() -> None:
    nominal = synthesize_pd(paper.SPACECRAFT, TAU, order=1)
    res = synthesize_pd(paper.SPACECRAFT, TAU, order=1, tolerance=0.2)
    assert isinstance(res, RobustPDSynthesis) and res.status is RobustStatus.SYNTHESIZED
    assert res.certificate is not None and res.certificate.certified and res.gains is not None
    # The decay-optimal nominal design is certified over +-20 %: it is returned unchanged.
    assert res.omega_n == nominal.omega_n
    np.testing.assert_array_equal(res.gains.K, nominal.gains.K)
    k1, k2 = axis_gains(res.gains.K)
    for b in input_gains(0.2, 41):
        assert analytic_margin(b * k1, b * k2) > TAU
    zero = synthesize_pd(paper.SPACECRAFT, TAU, order=1, tolerance=0.0)
    assert isinstance(zero, RobustPDSynthesis) and zero.omega_n == nominal.omega_n


def test_synthesize_pd_searches_below_the_nominal_design_when_it_is_not_certified() -> None:
    # tau(t) in [0, 0.5] s varying arbitrarily: the nominal omega_n is not certified; the answer is
    # the largest certified omega_n below it, stable at every constant delay and inertia.
    nominal_w = synthesize_pd(paper.SPACECRAFT, TAU, order=0).omega_n
    res = synthesize_pd(paper.SPACECRAFT, TAU, order=0, tolerance=0.3, tau_min=0.0, rtol=0.05)
    assert isinstance(res, RobustPDSynthesis) and res.status is RobustStatus.SYNTHESIZED, str(res)
    assert res.gains is not None and 0.0 < res.omega_n < nominal_w
    k1, k2 = axis_gains(res.gains.K)
    for b in input_gains(0.3, 41):
        assert analytic_margin(b * k1, b * k2) > TAU


def _coupled() -> Spacecraft:
    return Spacecraft([[12.0, 1.0, 0.0], [1.0, 10.0, 0.5], [0.0, 0.5, 9.0]])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"tolerance": -0.1}, "tolerance must be >= 0"),
        ({"tolerance": 1.0}, "tolerance must be < 1"),
        ({"tolerance": float("nan")}, "tolerance"),
        ({"product_bound": -1.0}, "product_bound must be >= 0"),
        ({"period": 0.3}, "tau / period must be an integer"),
        ({"period": -0.1}, "period must be > 0"),
        ({"period": 0.1, "tau_min": 0.4}, "either period"),
        ({"tau_min": 0.6}, "tau_min must not exceed tau"),
        ({"tau_min": -0.1}, "tau_min must be >= 0"),
        ({"delay_rate": 0.5}, "delay_rate applies only with tau_min"),
    ],
)
def test_bad_robust_input_names_the_parameter(kwargs: dict, match: str) -> None:
    with pytest.raises(SpecificationError, match=match):
        synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=0.1, **kwargs)
    with pytest.raises(SpecificationError, match=match):
        synthesize_pd(paper.SPACECRAFT, TAU, **kwargs)


def test_robust_options_need_a_diagonal_nominal_inertia() -> None:
    with pytest.raises(SpecificationError, match="diagonal"):
        synthesize_lmi(_coupled(), 0.4, decay_rate=0.1, tolerance=0.1)
    with pytest.raises(SpecificationError, match="diagonal"):
        synthesize_pd(_coupled(), 0.4, tolerance=0.1)


@pytest.mark.slow
def test_sampled_design_at_1_khz_is_stable_when_lifted() -> None:
    alpha, h, d = 0.3, 1e-3, 500
    res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=alpha, order=0, period=h, epsilons=[1.188])
    assert res.status is SynthesisStatus.SYNTHESIZED, str(res)
    k1, k2 = axis_gains(np.asarray(res.K))
    assert lifted_radius(k1, k2, h, d) < math.exp(-alpha * h)


@pytest.mark.slow
def test_robust_lmi_synthesis_is_identical_from_a_thread_pool() -> None:
    from concurrent.futures import ThreadPoolExecutor

    def run(tol: float) -> np.ndarray:
        res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=0.2, order=0, tolerance=tol, epsilons=[0.6])
        assert res.status is SynthesisStatus.SYNTHESIZED and res.K is not None
        return np.asarray(res.K)

    tols = [0.05, 0.15]
    serial = [run(t) for t in tols]
    with ThreadPoolExecutor(max_workers=2) as pool:
        pooled = list(pool.map(run, tols))
    for a, b in zip(serial, pooled, strict=True):
        np.testing.assert_array_equal(a, b)
