"""Fixed-order synthesis for performance (PD, PID, full matrix) against independent references."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate

from mrpctl import paper
from mrpctl.design.fixed_order import (
    hinf_gradient,
    refine_full_gain,
    synthesize_fixed_order,
)
from mrpctl.design.performance import hinf_norm
from mrpctl.errors import SpecificationError
from mrpctl.model import plant_model
from mrpctl.spacecraft import Spacecraft

COUPLED = Spacecraft(np.array([[140.0, 10.0, -5.0], [10.0, 100.0, 8.0], [-5.0, 8.0, 80.0]]))


def _axis_response(gains, structure: str, w: np.ndarray) -> np.ndarray:
    """|T(iω)| of the normalised axis from its transfer function λ/(λ³ + (dλ² + pλ + i)e^{−λ}) (or the PD one)."""
    lam = 1j * w
    if structure == "pd":
        p, d = gains
        return np.abs(1.0 / (lam**2 + (d * lam + p) * np.exp(-lam)))
    p, d, i = gains
    return np.abs(lam / (lam**3 + (d * lam**2 + p * lam + i) * np.exp(-lam)))


def _sweep_peak(gains, structure: str = "pd") -> float:
    w = np.linspace(0.0, 20.0, 200_001)
    s = _axis_response(gains, structure, w)
    k = int(np.argmax(s))
    fine = np.linspace(w[max(k - 1, 0)], w[k + 1], 20_001)
    return float(max(s.max(), _axis_response(gains, structure, fine).max()))


def _h2_integral(gains, structure: str = "pd") -> float:
    """‖T‖₂ = ((1/π) ∫₀^∞ |T(iω)|² dω)^{1/2} by adaptive quadrature (the tail beyond 200 is below 1e-7)."""
    value, _ = scipy.integrate.quad(
        lambda w: _axis_response(gains, structure, np.array([w]))[0] ** 2, 0, 200, limit=800
    )
    return math.sqrt(value / math.pi)


@pytest.fixture(scope="module")
def h2_pd():
    """The H2-optimal PD of the paper case: test_h2_pd checks it against the frequency integral, and the PID's
    H2 design is compared with it (the same call, once per module)."""
    return synthesize_fixed_order(paper.SPACECRAFT, 0.5, structure="pd", objective="h2", starts=1, order=None)


def test_hinf_pd_is_a_local_minimum_of_the_swept_norm_and_scales_to_the_loop() -> None:
    result = synthesize_fixed_order(paper.SPACECRAFT, 0.5, structure="pd", objective="hinf", starts=1, order=None)
    p, d = result.normalised
    centre = _sweep_peak((p, d))
    assert centre == pytest.approx(result.normalised_value, rel=1e-6)
    for dp, dd in [(1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (-1, -1), (1, -1), (-1, 1)]:
        assert _sweep_peak((p * (1 + 5e-3 * dp), d * (1 + 5e-3 * dd))) >= centre * (1.0 - 1e-9)
    # the loop's norm is τ²/J_min times the normalised one (θ̈ = d/J + ...)
    assert result.hinf.value == pytest.approx(0.5**2 / min(paper.INERTIA) * centre, rel=1e-6)
    # and it is the design synthesize_hinf_pd documents: ωₙ = √p/τ, ζ = d/(2√p)
    assert math.sqrt(p) / 0.5 == pytest.approx(1.04859, rel=2e-4)
    assert d / (2.0 * math.sqrt(p)) == pytest.approx(0.90422, rel=2e-4)


def test_h2_pd_is_a_local_minimum_of_the_frequency_integral(h2_pd) -> None:
    result = h2_pd
    p, d = result.normalised
    centre = _h2_integral((p, d))
    assert centre == pytest.approx(result.normalised_value, rel=1e-6)
    for dp, dd in [(1, 0), (-1, 0), (0, 1), (0, -1)]:
        assert _h2_integral((p * (1 + 1e-2 * dp), d * (1 + 1e-2 * dd))) >= centre
    # the loop's H2 is (τ³ Σ 1/J²)^{1/2} times the normalised one
    scale = math.sqrt(0.5**3 * sum(1.0 / j**2 for j in paper.INERTIA))
    assert result.h2.value == pytest.approx(scale * centre, rel=1e-6)


def test_pid_decay_optimum_is_the_quadruple_root_of_the_closed_form() -> None:
    # λ³ + (aλ² + bλ + c)e^{−λ} has a root of multiplicity 4 where (e^λλ³)''' = e^λ(λ³ + 9λ² + 18λ + 6) = 0;
    # the largest such λ is the best decay any PID can give (it is dominant: below)
    lam0 = float(max(np.roots([1.0, 9.0, 18.0, 6.0]).real))
    f0 = math.exp(lam0) * np.array([lam0**3, 3 * lam0**2 + lam0**3, 6 * lam0 + 6 * lam0**2 + lam0**3])
    a2 = -f0[2] / 2.0
    a1 = -f0[1] - 2.0 * a2 * lam0
    a0 = -f0[0] - a2 * lam0**2 - a1 * lam0

    def f(lam: np.ndarray) -> np.ndarray:
        return lam**3 + (a2 * lam**2 + a1 * lam + a0) * np.exp(-lam)

    def winding(contour: np.ndarray) -> int:
        phase = np.unwrap(np.angle(f(np.append(contour, contour[:1]))))
        return round((phase[-1] - phase[0]) / (2.0 * math.pi))

    t = np.linspace(0.0, 1.0, 40_001)[:-1]
    assert winding(lam0 + 1e-2 * np.exp(2j * math.pi * t)) == 4  # four roots within 0.01 of λ0
    # none with Re λ >= λ0 + 0.01: such a root has |λ|³ <= |q(λ)| e^{−Re λ}, so |λ| < 10; count the rectangle
    r0, big = lam0 + 1e-2, 10.0
    edges = [r0 - 1j * big, big - 1j * big, big + 1j * big, r0 + 1j * big]
    rectangle = np.concatenate([u + (v - u) * t for u, v in zip(edges, [*edges[1:], edges[0]], strict=True)])
    assert winding(rectangle) == 0
    result = synthesize_fixed_order(paper.SPACECRAFT, 0.5, structure="pid", objective="abscissa", starts=1, order=None)
    assert result.normalised_value >= lam0 - 1e-4
    assert result.normalised_value <= 0.98 * lam0
    assert result.abscissa == pytest.approx(result.normalised_value / 0.5, rel=1e-6)
    # integral action costs decay: the best PD root is −(2 − √2) (triple), to the left of the PID's
    assert -(2.0 - math.sqrt(2.0)) < lam0


def test_integral_action_does_not_lower_the_h2_norm(h2_pd) -> None:
    pid = synthesize_fixed_order(paper.SPACECRAFT, 0.5, structure="pid", objective="h2", starts=1, order=None)
    pd = h2_pd
    assert pid.normalised[2] < 1e-6  # the integral gain is driven to zero
    assert pid.normalised_value == pytest.approx(pd.normalised_value, rel=1e-5)
    assert pid.K_i is not None and pid.gain.shape == (3, 9)


def _loop(sc: Spacecraft) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    plant = plant_model(sc)
    return np.array(plant.A), np.array(plant.B), np.hstack((4.0 * np.eye(3), np.zeros((3, 3))))


def test_full_gain_gradient_matches_finite_differences() -> None:
    a, b, c = _loop(COUPLED)
    k = np.array(paper.GAIN)
    result = hinf_norm(a, b @ k, 0.5, b, c)
    grad = hinf_gradient(a, b, k, 0.5, b, c, result)
    eps = 1e-5 * float(np.abs(k).max())
    for i, j in [(0, 0), (2, 0), (1, 4), (2, 5), (0, 3)]:
        e = np.zeros_like(k)
        e[i, j] = eps
        fd = (hinf_norm(a, b @ (k + e), 0.5, b, c).value - hinf_norm(a, b @ (k - e), 0.5, b, c).value) / (2 * eps)
        assert grad[i, j] == pytest.approx(fd, rel=1e-5, abs=1e-9 * abs(grad).max())


def test_full_gain_refinement_lowers_the_swept_norm() -> None:
    a, b, c = _loop(COUPLED)
    k = np.array(paper.GAIN)
    refined = refine_full_gain(a, b, k, 0.5, b, c, iterations=4, restarts=1)
    assert refined.value < 0.8 * refined.start_value
    w = np.linspace(0.0, 10.0, 100_001)
    n = a.shape[0]
    m = 1j * w[:, None, None] * np.eye(n) - a - np.exp(-0.5j * w)[:, None, None] * (b @ refined.K)
    s = np.linalg.svd(c @ np.linalg.solve(m, np.broadcast_to(b, (len(w), 6, 3))), compute_uv=False)[:, 0]
    assert float(s.max()) <= refined.value * (1.0 + 1e-9)
    assert float(s.max()) == pytest.approx(refined.value, rel=1e-4)


def test_bad_input_is_refused_naming_the_parameter() -> None:
    with pytest.raises(SpecificationError, match="structure"):
        synthesize_fixed_order(paper.SPACECRAFT, 0.5, structure="lead-lag")
    with pytest.raises(SpecificationError, match="objective"):
        synthesize_fixed_order(paper.SPACECRAFT, 0.5, objective="settling")
    with pytest.raises(SpecificationError, match="tau"):
        synthesize_fixed_order(paper.SPACECRAFT, -0.5)
    with pytest.raises(SpecificationError, match="starts"):
        synthesize_fixed_order(paper.SPACECRAFT, 0.5, starts=0)
    a, b, c = _loop(paper.SPACECRAFT)
    with pytest.raises(SpecificationError, match="K"):
        refine_full_gain(a, b, 10.0 * np.array(paper.GAIN), 0.5, b, c)  # unstable start
