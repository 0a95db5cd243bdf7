"""Exact delay margin: analytic margins, literature values and an independent spectral method."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest

from mrpctl import paper
from mrpctl.design import delay_margin, linearized_loop
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import pd_from_gain

BENCH_A = np.array([[-2.0, 0.0], [0.0, -0.9]])
BENCH_AD = np.array([[-1.0, 0.0], [-1.0, -1.0]])
# Gu, Kharitonov & Chen (2003), Example: unstable without delay, stable for 0.10017 < tau < 1.71785.
GU_A = np.array([[0.0, 1.0], [-2.0, 0.1]])
GU_AD = np.array([[0.0, 0.0], [1.0, 0.0]])


def _cheb(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Trefethen's Chebyshev differentiation matrix on the m + 1 points cos(j pi / m)."""
    x = np.cos(np.pi * np.arange(m + 1) / m)
    c = np.hstack([2.0, np.ones(m - 1), 2.0]) * (-1.0) ** np.arange(m + 1)
    dx = x[:, None] - x[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(m + 1))
    return d - np.diag(d.sum(axis=1)), x


def rightmost_root(a: np.ndarray, a_d: np.ndarray, tau: float, m: int = 40) -> float:
    """Real part of the rightmost characteristic root by spectral discretisation of the
    infinitesimal generator (Breda, Maset & Vermiglio 2005): independent of the crossing method."""
    a = np.atleast_2d(a)
    a_d = np.atleast_2d(a_d)
    n = a.shape[0]
    d, _ = _cheb(m)
    gen = np.kron(d * (2.0 / tau), np.eye(n))  # theta = tau (x - 1) / 2, row j = theta_j
    gen[:n, :] = 0.0
    gen[:n, :n] = a
    gen[:n, m * n :] = a_d
    return float(np.max(np.linalg.eigvals(gen).real))


@pytest.mark.parametrize(("a", "b"), [(0.0, -1.0), (-0.5, -2.0), (0.5, -1.5), (1.0, -3.0)])
def test_scalar_margin_matches_analytic_formula(a: float, b: float) -> None:
    # xdot = a x + b x(t - tau), b < -|a|: tau* = arccos(-a/b) / sqrt(b^2 - a^2).
    expected = math.acos(-a / b) / math.sqrt(b * b - a * a)
    result = delay_margin(a, b)
    assert result.stable_without_delay
    assert result.margin == pytest.approx(expected, rel=1e-10)
    assert result.crossings[0].frequency == pytest.approx(math.sqrt(b * b - a * a), rel=1e-10)


def test_pure_delay_integrator_is_pi_over_two() -> None:
    assert delay_margin(0.0, -1.0).margin == pytest.approx(math.pi / 2, rel=1e-12)


def test_classic_benchmark_margin_and_spectral_cross_check() -> None:
    result = delay_margin(BENCH_A, BENCH_AD)
    assert result.margin == pytest.approx(6.1725, abs=1e-4)  # literature: 6.1725
    assert rightmost_root(BENCH_A, BENCH_AD, result.margin * (1 - 1e-3)) < 0.0
    assert rightmost_root(BENCH_A, BENCH_AD, result.margin * (1 + 1e-3)) > 0.0
    assert rightmost_root(BENCH_A, BENCH_AD, result.margin) == pytest.approx(0.0, abs=1e-8)


def test_paper_margin_analytic_per_axis_and_singular_delay_matrix() -> None:
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    assert np.linalg.matrix_rank(loop.A_d) == 3
    result = loop.delay_margin()
    # Per axis s^2 + (b s + a) e^{-s tau} = 0: omega^4 = a^2 + b^2 omega^2, tau = atan2(b omega, a) / omega.
    analytic = []
    for inertia in paper.INERTIA:
        a = -paper.GAIN_SIGMA / (4 * inertia)
        b = -paper.GAIN_OMEGA / (4 * inertia)
        omega = math.sqrt((b * b + math.sqrt(b**4 + 4 * a * a)) / 2)
        analytic.append(math.atan2(b * omega, a) / omega)
    assert result.margin == pytest.approx(min(analytic), rel=1e-9)
    assert int(np.argmin(analytic)) == 2  # the J = 80 axis sets it
    assert result.margin == pytest.approx(1.5555, abs=1e-4)
    assert sorted(c.delay for c in result.crossings) == pytest.approx(sorted(analytic), rel=1e-9)
    assert rightmost_root(loop.A, loop.A_d, result.margin * 0.999) < 0.0
    assert rightmost_root(loop.A, loop.A_d, result.margin * 1.001) > 0.0


def test_stability_interval_of_a_system_unstable_without_delay() -> None:
    result = delay_margin(GU_A, GU_AD)
    assert not result.stable_without_delay
    assert result.margin == 0.0
    assert len(result.stable_intervals) == 1
    lo, hi = result.stable_intervals[0]
    assert lo == pytest.approx(0.10017, abs=1e-5)
    assert hi == pytest.approx(1.71785, abs=1e-5)
    for tau, stable in [
        (0.05, False),
        (0.5, True),
        (1.5, True),
        (2.0, False),
        (lo * 0.99, False),
        (hi * 1.01, False),
    ]:
        assert (rightmost_root(GU_A, GU_AD, tau) < 0.0) is stable
        assert result.is_stable(tau) is stable


def test_delay_independent_and_never_stable_systems() -> None:
    independent = delay_margin(-2.0 * np.eye(2), 0.5 * np.eye(2))
    assert independent.delay_independent
    assert independent.stable_intervals == ((0.0, math.inf),)
    assert rightmost_root(-2.0 * np.eye(2), 0.5 * np.eye(2), 50.0) < 0.0
    never = delay_margin(np.eye(2), np.zeros((2, 2)))
    assert not never.stable_for_some_delay
    assert "unstable for every delay" in never.reason
    singular = delay_margin([[0.0, 1.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, -1.0]])
    assert not singular.stable_for_some_delay
    assert "singular" in singular.reason
    assert "stable" in str(independent)


def test_random_margins_agree_with_spectral_method(rng: np.random.Generator) -> None:
    checked = 0
    while checked < 10:
        a = rng.normal(size=(3, 3)) - 1.5 * np.eye(3)
        a_d = rng.normal(size=(3, 3))
        result = delay_margin(a, a_d)
        if not result.stable_without_delay or math.isinf(result.margin):
            continue
        tau = result.margin
        assert rightmost_root(a, a_d, tau * (1 - 1e-4), m=60) < 0.0
        assert rightmost_root(a, a_d, tau * (1 + 1e-4), m=60) > 0.0
        checked += 1


@pytest.mark.parametrize(
    ("a", "a_d", "error", "match"),
    [
        (np.zeros((2, 3)), np.zeros((2, 3)), DimensionError, "A: expected a square"),
        (np.zeros((2, 2)), np.zeros((3, 3)), DimensionError, "A_d: expected shape"),
        (np.array([[np.nan, 0.0], [0.0, 1.0]]), np.eye(2), SpecificationError, "A must be finite"),
    ],
)
def test_bad_input(a: np.ndarray, a_d: np.ndarray, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        delay_margin(a, a_d)


def test_per_axis_margins_match_python_control_phase_margin() -> None:
    """Independent check: delay margin = phase margin / crossover of L(s) = -(K2 s + K1)/s^2 (python-control)."""
    k1, k2 = pd_from_gain(paper.SPACECRAFT, paper.GAIN)
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    margins = []
    for i, (a, a_d) in enumerate(loop.axes):
        _, phase_margin_deg, _, crossover = control.margin(control.tf([-k2[i, i], -k1[i, i]], [1.0, 0.0, 0.0]))
        expected = math.radians(phase_margin_deg) / crossover
        margins.append(expected)
        assert delay_margin(a, a_d).margin == pytest.approx(expected, rel=1e-9)
    assert loop.delay_margin().margin == pytest.approx(min(margins), rel=1e-9)


# ---- issue 9: scale, stiffness, termination ----------------------------------------------------


@pytest.mark.parametrize("c", [1e-8, 1e-6, 1e-4, 1e-2, 1e2, 1e4, 1e6, 1e8])
def test_margin_of_scaled_system_is_margin_over_c(c: float) -> None:
    # Time scaling: c (A, A_d) has the roots c s at the delays tau / c. Main answered "not Hurwitz,
    # no delay stabilises" for c = 1e-8 (absolute eigenvalue tolerances).
    for a, a_d in ((BENCH_A, BENCH_AD), (GU_A, GU_AD)):
        ref = delay_margin(a, a_d)
        scaled = delay_margin(c * a, c * a_d)
        assert scaled.stable_without_delay is ref.stable_without_delay
        assert scaled.margin * c == pytest.approx(ref.margin, rel=1e-9, abs=0.0)
        assert len(scaled.stable_intervals) == len(ref.stable_intervals)
        for (lo, hi), (lo_ref, hi_ref) in zip(scaled.stable_intervals, ref.stable_intervals, strict=True):
            assert (lo * c, hi * c) == pytest.approx((lo_ref, hi_ref), rel=1e-9)


def test_stiff_system_fast_mode_beside_slow_one() -> None:
    # Block triangular: (s + 1e7 + 5e6 e^{-s tau}) (s + e^{-s tau}). The fast factor is stable for
    # every delay (|5e6| < 1e7), the slow one is x' = -x(t - tau): margin pi / 2 exactly.
    a = np.diag([-1e7, 0.0])
    a_d = np.array([[-5e6, 0.0], [1.0, -1.0]])
    result = delay_margin(a, a_d)
    assert result.stable_without_delay
    assert result.margin == pytest.approx(math.pi / 2, rel=1e-9)
    assert result.complete
    assert rightmost_root(a, a_d, 0.99 * math.pi / 2) < 0.0 < rightmost_root(a, a_d, 1.01 * math.pi / 2)


def test_paper_loop_with_a_huge_inertia() -> None:
    # mrpctl verify --inertia 1e9 1e9 1e9 answered margin 0 ("not Hurwitz") on main.
    from mrpctl import Spacecraft

    sc = Spacecraft([1e9, 1e9, 1e9])
    loop = linearized_loop(sc, paper.GAIN)
    result = loop.delay_margin()
    k1, k2 = pd_from_gain(sc, paper.GAIN)
    a, b = -k1[0, 0], -k2[0, 0]
    omega = math.sqrt((b * b + math.sqrt(b**4 + 4 * a * a)) / 2)
    assert result.margin == pytest.approx(math.atan2(b * omega, a) / omega, rel=1e-9)


def test_slow_mode_beside_pure_delay_terminates_with_the_right_margin() -> None:
    # Main grew past 4 GB in 10 s: the 1e-8 rad/s family pushed the sweep horizon to ~1e9 s.
    a, a_d = np.zeros((2, 2)), np.diag([-1.0, -1e-8])
    result = delay_margin(a, a_d)
    assert result.margin == pytest.approx(math.pi / 2, rel=1e-12)
    assert len(result.stable_intervals) == 1
    assert result.stable_intervals[0] == pytest.approx((0.0, math.pi / 2), rel=1e-12)
    assert result.complete
    assert sorted(c.frequency for c in result.crossings) == pytest.approx([1e-8, 1.0], rel=1e-9)
    assert rightmost_root(a, a_d, 0.99 * math.pi / 2) < 0.0 < rightmost_root(a, a_d, 1.01 * math.pi / 2)


def test_rank_deficient_coupled_gain_terminates_with_the_right_answer() -> None:
    # K = 1..18 (mrpctl verify --K $(seq 1 18)): main grew past 8 GB in 25 s.
    loop = linearized_loop(paper.SPACECRAFT, np.arange(1.0, 19.0).reshape(3, 6))
    result = loop.delay_margin()
    assert result.margin == 0.0
    assert not result.stable_for_some_delay
    # s = 0 is a root at every delay: the spectral abscissa is >= 0 (up to its accuracy) everywhere.
    for tau in (0.01, 0.5, 5.0):
        assert rightmost_root(loop.A, loop.A_d, tau) > -1e-9


def test_event_cap_gives_an_honest_partial_answer() -> None:
    # Two destabilising families and one stabilising family at nearly the frequency of one of them:
    # the count returns to zero only rarely. With a tiny cap the sweep must stop and say so.
    result = delay_margin(GU_A, GU_AD, max_events=1)
    assert not result.complete
    assert math.isfinite(result.resolved_to)
    assert "could not be determined beyond" in result.reason
    full = delay_margin(GU_A, GU_AD)
    assert full.complete
    # The partial intervals agree with the full ones below resolved_to.
    assert all(hi <= result.resolved_to for _, hi in result.stable_intervals)
    with pytest.raises(SpecificationError, match="max_events"):
        delay_margin(GU_A, GU_AD, max_events=0)


def test_seeded_sweep_of_scaled_and_rank_deficient_systems(rng: np.random.Generator) -> None:
    """Termination and correctness over scalings 1e-8..1e8 and rank-deficient delay matrices."""
    checked = 0
    for trial in range(60):
        n = int(rng.integers(1, 4))
        a = rng.normal(size=(n, n)) - rng.uniform(0.0, 2.0) * np.eye(n)
        if trial % 3 == 0:  # rank-one delayed term
            a_d = np.outer(rng.normal(size=n), rng.normal(size=n))
        elif trial % 3 == 1 and n > 1:  # a zero row (an unactuated state)
            a_d = rng.normal(size=(n, n))
            a_d[0] = 0.0
        else:
            a_d = rng.normal(size=(n, n))
        c = 10.0 ** rng.uniform(-8.0, 8.0)
        ref = delay_margin(a, a_d)
        scaled = delay_margin(c * a, c * a_d)
        assert scaled.complete and ref.complete
        assert scaled.stable_without_delay is ref.stable_without_delay
        if math.isfinite(ref.margin):
            assert scaled.margin * c == pytest.approx(ref.margin, rel=1e-7)
        else:
            assert math.isinf(scaled.margin)
        if ref.stable_without_delay and math.isfinite(ref.margin):
            tau = ref.margin
            assert rightmost_root(a, a_d, tau * (1 - 1e-3), m=60) < 0.0
            assert rightmost_root(a, a_d, tau * (1 + 1e-3), m=60) > 0.0
            checked += 1
        elif ref.delay_independent:
            assert rightmost_root(a, a_d, 20.0, m=60) < 0.0
    assert checked >= 10


@pytest.mark.parametrize("copies", [2, 3])
def test_identical_decoupled_axes_count_every_root_pair(copies: int) -> None:
    """k identical decoupled blocks have the stable intervals of one block: each crossing carries k pairs.

    Regression: crossings of identical axes were merged into one family counted once, so a loop unstable
    at tau = 0 and stabilised by the delay (found by the predictor analysis) had no stable interval in 6x6.
    """
    from mrpctl import Spacecraft
    from mrpctl.design import pd_gains
    from mrpctl.predictor import perturbed_spacecraft, predictor_loop_matrices

    sc = Spacecraft([100.0, 100.0, 100.0])
    gain = pd_gains(sc, zeta=1.0, omega_n=1.0).K
    a0, a1 = predictor_loop_matrices(sc, gain, 0.5, plant=perturbed_spacecraft(sc, 5.0))
    idx = [0, 3]
    block = (a0[np.ix_(idx, idx)], a1[np.ix_(idx, idx)])
    single = delay_margin(*block)
    stacked = delay_margin(np.kron(np.eye(copies), block[0]), np.kron(np.eye(copies), block[1]))
    assert single.stable_intervals and not single.stable_without_delay
    assert np.allclose(stacked.stable_intervals, single.stable_intervals, rtol=1e-9)
    assert all(c.multiplicity == copies for c in stacked.crossings)
    # A loop stable at tau = 0 with stability switches: the same margin and intervals too.
    a, a_d = np.array([[0.0, 1.0], [-1.0, -0.1]]), np.array([[0.0, 0.0], [0.0, -0.5]])
    one, many = delay_margin(a, a_d), delay_margin(np.kron(np.eye(copies), a), np.kron(np.eye(copies), a_d))
    assert many.margin == pytest.approx(one.margin, rel=1e-9)
    assert np.allclose(many.stable_intervals, one.stable_intervals, rtol=1e-9)
