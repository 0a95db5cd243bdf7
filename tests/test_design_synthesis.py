"""Gain synthesis: certified PD gains and descriptor-method state feedback, re-checked independently."""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrpctl import Spacecraft, paper, plant_model
from mrpctl.design import (
    JENSEN,
    WIRTINGER,
    SynthesisStatus,
    max_certified_delay,
    synthesize_lmi,
    synthesize_pd,
)
from mrpctl.errors import SpecificationError
from mrpctl.model import pd_from_gain


def _cheb(m: int) -> np.ndarray:
    x = np.cos(np.pi * np.arange(m + 1) / m)
    c = np.hstack([2.0, np.ones(m - 1), 2.0]) * (-1.0) ** np.arange(m + 1)
    dx = x[:, None] - x[None, :]
    d = np.outer(c, 1.0 / c) / (dx + np.eye(m + 1))
    return d - np.diag(d.sum(axis=1))


def rightmost_root(a: np.ndarray, a_d: np.ndarray, tau: float, m: int = 40) -> float:
    """Spectral abscissa by Chebyshev discretisation of the infinitesimal generator (independent)."""
    n = a.shape[0]
    gen = np.kron(_cheb(m) * (2.0 / tau), np.eye(n))
    gen[:n, :] = 0.0
    gen[:n, :n] = a
    gen[:n, m * n :] = a_d
    return float(np.max(np.linalg.eigvals(gen).real))


def analytic_margin(k1: float, k2: float) -> float:
    """Exact margin of sigma_ddot = k1 sigma(t - tau) + k2 sigma_dot(t - tau), k1, k2 < 0."""
    a, b = -k1, -k2
    omega = math.sqrt((b * b + math.sqrt(b**4 + 4 * a * a)) / 2)
    return math.atan2(b * omega, a) / omega


@pytest.mark.parametrize(("zeta", "order"), [(1.0, 3), (1.5, WIRTINGER)])
def test_synthesize_pd_matches_time_scaling_of_the_unit_loop(zeta: float, order: int) -> None:
    tau = paper.TAU
    result = synthesize_pd(paper.SPACECRAFT, tau, zeta=zeta, order=order)
    assert result.status is SynthesisStatus.SYNTHESIZED
    assert result.certificate.certified
    # Independent: the certified delay of the omega_n = 1 loop, scaled by 1/omega_n (time scaling).
    unit = max_certified_delay([[0.0, 1.0], [0.0, 0.0]], [[0.0, 0.0], [-1.0, -2.0 * zeta]], order=order)
    assert result.omega_n == pytest.approx(unit.upper / tau, rel=1e-3)
    # The exact margin of the synthesized loop, analytically, is at least tau.
    expected = analytic_margin(-(result.omega_n**2), -2 * zeta * result.omega_n)
    assert result.margin.margin == pytest.approx(expected, rel=1e-9)
    assert tau < expected
    assert result.gains.overdamped
    assert "omega_n" in str(result)


def test_synthesize_pd_bad_input() -> None:
    with pytest.raises(SpecificationError, match="allow_underdamped"):
        synthesize_pd(paper.SPACECRAFT, 0.5, zeta=0.5)
    with pytest.raises(SpecificationError, match="tau must be > 0"):
        synthesize_pd(paper.SPACECRAFT, -0.5)
    with pytest.raises(SpecificationError, match="tau must be finite"):
        synthesize_pd(paper.SPACECRAFT, math.nan)
    with pytest.raises(SpecificationError, match="zeta must be > 0"):
        synthesize_pd(paper.SPACECRAFT, 0.5, zeta=-1.0)


@pytest.mark.parametrize(("order", "alpha"), [(JENSEN, 0.0), (JENSEN, 0.2), (WIRTINGER, 0.0), (WIRTINGER, 0.3)])
def test_synthesize_lmi_gains_are_stable_with_the_decay_rate(order: int, alpha: float) -> None:
    tau = paper.TAU
    result = synthesize_lmi(paper.SPACECRAFT, tau, decay_rate=alpha, order=order)
    assert result.status is SynthesisStatus.SYNTHESIZED, str(result)
    assert result.certificate.certified and result.decay_certificate.certified
    # Independent checks: analytic per-axis margin and the spectral abscissa of the 6x6 delayed loop.
    k1, k2 = pd_from_gain(paper.SPACECRAFT, result.K)
    np.testing.assert_allclose(k1, np.diag(np.diag(k1)), atol=1e-12)
    margins = [analytic_margin(k1[i, i], k2[i, i]) for i in range(3)]
    assert result.margin.margin == pytest.approx(min(margins), rel=1e-8)
    assert min(margins) > tau
    a, a_d = plant_model(paper.SPACECRAFT).closed_loop_matrices(result.K)
    assert rightmost_root(a, a_d, tau) < -alpha
    assert "descriptor" in str(result)


def test_larger_decay_rate_gives_faster_loop() -> None:
    tau = paper.TAU
    slow = synthesize_lmi(paper.SPACECRAFT, tau, decay_rate=0.05, order=WIRTINGER)
    fast = synthesize_lmi(paper.SPACECRAFT, tau, decay_rate=0.4, order=WIRTINGER)
    assert slow.synthesized and fast.synthesized
    a, a_d_slow = plant_model(paper.SPACECRAFT).closed_loop_matrices(slow.K)
    _, a_d_fast = plant_model(paper.SPACECRAFT).closed_loop_matrices(fast.K)
    assert rightmost_root(a, a_d_fast, tau) < -0.4
    assert rightmost_root(a, a_d_fast, tau) < rightmost_root(a, a_d_slow, tau) < -0.05


def test_unreachable_decay_rate_is_infeasible_not_a_crash() -> None:
    # alpha tau = 5: e^{5} amplifies the delayed term; the closed loop cannot decay that fast.
    result = synthesize_lmi(paper.SPACECRAFT, paper.TAU, decay_rate=10.0, order=JENSEN)
    assert result.status in (SynthesisStatus.INFEASIBLE, SynthesisStatus.SOLVER_FAILED)
    assert result.K is None
    assert "epsilon" in result.reason


def test_synthesize_lmi_coupled_inertia_uses_the_full_loop() -> None:
    spacecraft = Spacecraft([[12.0, 1.0, 0.0], [1.0, 10.0, 0.5], [0.0, 0.5, 9.0]])
    tau = 0.4
    result = synthesize_lmi(spacecraft, tau, decay_rate=0.1, order=JENSEN, epsilons=[0.3, 0.6, 1.2])
    assert result.status is SynthesisStatus.SYNTHESIZED, str(result)
    assert result.epsilon in (0.3, 0.6, 1.2)
    a, a_d = plant_model(spacecraft).closed_loop_matrices(result.K)
    assert rightmost_root(a, a_d, tau) < -0.1
    assert result.margin.margin > tau


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"tau": 0.5, "decay_rate": -0.1}, SpecificationError, "decay_rate must be >= 0"),
        ({"tau": 0.0, "decay_rate": 0.1}, SpecificationError, "tau must be > 0"),
        ({"tau": 0.5, "decay_rate": math.nan}, SpecificationError, "decay_rate must be finite"),
        ({"tau": 0.5, "decay_rate": 0.1, "epsilons": [-1.0]}, SpecificationError, "epsilons"),
        ({"tau": 0.5, "decay_rate": 0.1, "order": -2}, SpecificationError, "order"),
    ],
)
def test_synthesize_lmi_bad_input(kwargs: dict, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        synthesize_lmi(paper.SPACECRAFT, **kwargs)


def test_decay_rate_is_required() -> None:
    with pytest.raises(TypeError):
        synthesize_lmi(paper.SPACECRAFT, 0.5)  # type: ignore[call-arg]
