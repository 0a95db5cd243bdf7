"""Interval time-varying delay criteria: Myshkis-Yorke, the published benchmark, soundness, thread pool, scale."""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from mrpctl.design import certify, delay_margin
from mrpctl.design.interval import DelayRate, RateKind, certify_interval, interval_blocks
from mrpctl.errors import SpecificationError

BENCH_A = np.array([[-2.0, 0.0], [0.0, -0.9]])
BENCH_AD = np.array([[-1.0, 0.0], [-1.0, -1.0]])
#: Seuret & Gouaisbaut (Automatica 49, 2013), Wirtinger-based theorem for time-varying delay in [0, h],
#: |τ̇| <= μ, on this benchmark: h_max for μ = 0.1, 0.5, 0.8 (see design/lmi.md section 7).
WIRTINGER_TABLE = {0.1: 4.703, 0.5: 2.420, 0.8: 2.137}


def test_myshkis_yorke_bound_is_never_exceeded() -> None:
    # x' = -x(t - tau(t)), tau(t) in [0, h] arbitrary: stable exactly for h < 3/2 (Myshkis 1949, Yorke 1970).
    for order in (0, 1):
        assert not certify_interval([[0.0]], [[-1.0]], 1.5, order=order).certified
    # ... and the test is not vacuous: the Wirtinger criterion certifies a large part of [0, 3/2).
    assert certify_interval([[0.0]], [[-1.0]], 1.2, order=1).certified


@pytest.mark.parametrize("mu", sorted(WIRTINGER_TABLE))
def test_wirtinger_matches_published_table(mu: float) -> None:
    published = WIRTINGER_TABLE[mu]
    assert certify_interval(BENCH_A, BENCH_AD, 0.998 * published, delay_rate=mu, order=1).certified
    assert not certify_interval(BENCH_A, BENCH_AD, 1.002 * published, delay_rate=mu, order=1).certified


def test_time_varying_at_zero_rate_never_beats_constant_delay() -> None:
    # Constant-delay criteria of the same order certify 4.47131 (N=0), 6.05874 (N=1, strict) and 6.16882 (N=2,
    # relaxed, the default positivity), design/lmi.md section 5.
    for order, tau_const in ((0, 4.47131), (1, 6.05874), (2, 6.16882)):
        assert certify(BENCH_A, BENCH_AD, 0.9995 * tau_const, order=order).certified
        assert not certify_interval(BENCH_A, BENCH_AD, 1.0005 * tau_const, delay_rate=0.0, order=order).certified


def test_soundness_on_random_systems_against_exact_margin(rng: np.random.Generator) -> None:
    # A certificate for tau(t) in [0, h] covers every constant delay in [0, h]: h must stay below the exact margin.
    checked = 0
    rates: list[float | None] = [0.0, 0.5, None]
    while checked < 9:
        a = rng.normal(size=(2, 2))
        a_d = rng.normal(size=(2, 2))
        exact = delay_margin(a, a_d)
        if not exact.stable_without_delay or not np.isfinite(exact.margin):
            continue
        rate = rates[checked % 3]
        order = checked % 3
        assert not certify_interval(a, a_d, 1.01 * exact.margin, delay_rate=rate, order=order).certified
        checked += 1


def test_float64_recheck_decides_and_blocks_are_negative_for_a_bad_point() -> None:
    cert = certify_interval(BENCH_A, BENCH_AD, 2.0, delay_rate=0.5, order=1)
    assert cert.certified and cert.solver_status == "optimal"
    rate = DelayRate.bounded(0.5)
    blocks = interval_blocks([(2.0 * BENCH_A, 2.0 * BENCH_AD)], 0.0, rate, dict(cert.matrices), order=1)
    assert min(float(np.linalg.eigvalsh(b)[0]) for b in blocks.values()) > 0.0
    # The same matrices do not prove a four times longer interval.
    far = interval_blocks([(8.0 * BENCH_A, 8.0 * BENCH_AD)], 0.0, rate, dict(cert.matrices), order=1)
    assert min(float(np.linalg.eigvalsh(b)[0]) for b in far.values()) < 0.0


def test_interval_with_positive_lower_end_and_scale_invariance() -> None:
    base = certify_interval(BENCH_A, BENCH_AD, 3.0, tau_min=1.0, delay_rate=0.2, order=1)
    scaled = certify_interval(1e3 * BENCH_A, 1e3 * BENCH_AD, 3e-3, tau_min=1e-3, delay_rate=0.2, order=1)
    assert base.certified and scaled.certified
    assert scaled.solver_margin == pytest.approx(base.solver_margin, rel=1e-5)


def test_thread_pool_gives_the_serial_answers() -> None:
    cases = [(2.0, 0.5), (2.3, 0.5), (1.8, None)]
    serial = [certify_interval(BENCH_A, BENCH_AD, h, delay_rate=r).solver_margin for h, r in cases]
    with ThreadPoolExecutor(max_workers=2) as pool:
        threaded = list(
            pool.map(lambda c: certify_interval(BENCH_A, BENCH_AD, c[0], delay_rate=c[1]).solver_margin, cases)
        )
    assert threaded == serial


def test_bad_input_is_refused() -> None:
    with pytest.raises(SpecificationError, match="tau_max must exceed tau_min"):
        certify_interval(BENCH_A, BENCH_AD, 1.0, tau_min=1.0)
    with pytest.raises(SpecificationError, match="rate"):
        certify_interval(BENCH_A, BENCH_AD, 1.0, delay_rate=True)  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="lower <= upper"):
        DelayRate.between(1.0, 0.0)
    with pytest.raises(SpecificationError, match="must contain 0"):
        DelayRate.between(1.0, 1.0)
    assert DelayRate.sawtooth().kind is RateKind.SAWTOOTH and DelayRate.unknown().vertices == ()
