"""Gain synthesis: certified PD gains and descriptor-method state feedback, re-checked independently."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pytest

from mrpctl import Spacecraft, paper, plant_model
from mrpctl.design import (
    JENSEN,
    WIRTINGER,
    SynthesisStatus,
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


def _unit_abscissa(w: float, zeta: float) -> float:
    """Rightmost Re(s tau) of the per-axis loop at unit delay, by the Chebyshev method above (m = 32)."""
    return rightmost_root(np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0, 0.0], [-w * w, -2 * zeta * w]]), 1.0, 32)


def _golden_min(f: Callable[[float], float], lo: float, hi: float, tol: float) -> float:
    """Plain golden-section search (written here, independent of scipy's bounded Brent)."""
    g = (math.sqrt(5.0) - 1.0) / 2.0
    c, d = hi - g * (hi - lo), lo + g * (hi - lo)
    fc, fd = f(c), f(d)
    while hi - lo > tol:
        if fc < fd:
            hi, d, fd = d, c, fc
            c = hi - g * (hi - lo)
            fc = f(c)
        else:
            lo, c, fc = c, d, fd
            d = lo + g * (hi - lo)
            fd = f(d)
    return 0.5 * (lo + hi)


def test_zeta_one_design_is_the_exact_decay_optimum_and_certified_below_it() -> None:
    tau = paper.TAU
    result = synthesize_pd(paper.SPACECRAFT, tau, zeta=1.0)
    assert result.status is SynthesisStatus.SYNTHESIZED, str(result)
    assert result.decay_certificate is not None
    assert result.certificate.certified and result.decay_certificate.certified
    assert result.zeta == 1.0 and "critically damped" in str(result)
    # Independent optimum: golden section on the Chebyshev spectral abscissa of the unit-delay loop.
    w_ref = _golden_min(lambda w: _unit_abscissa(w, 1.0), 0.05, 0.64, 1e-6)
    assert result.omega_n * tau == pytest.approx(w_ref, rel=1e-3)
    assert result.omega_n * tau == pytest.approx(0.445, abs=5e-4)  # the value
    # The exact rightmost root, checked on the 6x6 loop by the spectral method.
    a, a_d = plant_model(paper.SPACECRAFT).closed_loop_matrices(result.gains.K)
    spectral = rightmost_root(a, a_d, tau, 48)
    assert result.rightmost_root.real == pytest.approx(spectral, rel=1e-6)
    assert result.rightmost_root.real * tau == pytest.approx(_unit_abscissa(w_ref, 1.0), rel=1e-4)
    # Soundness: the certified decay rate is below the exact one (and close to it here).
    assert 0.9 * result.exact_decay_rate < result.decay_rate < result.exact_decay_rate
    assert spectral < -result.decay_rate
    # Not on the stability boundary any more (the old design had margin / tau = 1.00004).
    expected = analytic_margin(-(result.omega_n**2), -2 * result.omega_n)
    assert result.margin.margin == pytest.approx(expected, rel=1e-9)
    assert result.margin.margin > 1.4 * tau


def test_zeta_free_design_is_the_triple_root_of_multiplicity_induced_dominancy() -> None:
    # f(l) = l^2 + (b l + a) e^{-l}, l = s tau, a = (omega_n tau)^2, b = 2 zeta omega_n tau.
    # f = f' = f'' = 0: f'' = (l^2 - 4 l + 2 - ... ) -> e^{l} f = l^2 e^{l} + b l + a, whose second
    # derivative (l^2 + 4 l + 2) e^{l} vanishes at l = -2 + sqrt(2); then b = -(l^2 + 2 l) e^{l}
    # from the first derivative and a = (l^3 + l^2) e^{l} from the function itself.
    lam = -2.0 + math.sqrt(2.0)
    b = -(lam * lam + 2 * lam) * math.exp(lam)
    a = (lam**3 + lam * lam) * math.exp(lam)
    w_exact, zeta_exact = math.sqrt(a), b / (2 * math.sqrt(a))
    assert (w_exact, zeta_exact) == pytest.approx((0.281, 0.820), abs=1e-3)  # the numbers
    tau = paper.TAU
    result = synthesize_pd(paper.SPACECRAFT, tau, zeta=None, allow_underdamped=True)
    assert result.status is SynthesisStatus.SYNTHESIZED, str(result)
    assert result.omega_n * tau == pytest.approx(w_exact, rel=1e-3)
    assert result.zeta == pytest.approx(zeta_exact, rel=1e-3)
    assert result.rightmost_root.real * tau == pytest.approx(lam, rel=1e-3)
    assert 0.0 < result.decay_rate < result.exact_decay_rate
    a6, a_d6 = plant_model(paper.SPACECRAFT).closed_loop_matrices(result.gains.K)
    assert rightmost_root(a6, a_d6, tau, 48) < -result.decay_rate
    # Without allow_underdamped the search stays at zeta >= 1 and ends on its boundary.
    bounded = synthesize_pd(paper.SPACECRAFT, tau, zeta=None)
    assert bounded.zeta == 1.0
    assert bounded.omega_n == pytest.approx(synthesize_pd(paper.SPACECRAFT, tau).omega_n, rel=1e-12)


def test_synthesize_pd_is_scale_invariant_in_tau() -> None:
    # The issue: INFEASIBLE at 1e-4 s and 100 s, 122 rad/s at 1e-3 s where ~647 was certifiable.
    taus = [1e-4, 1e-3, 0.5, 100.0, 1e3]
    results = [synthesize_pd(paper.SPACECRAFT, tau, order=2) for tau in taus]
    for tau, r in zip(taus, results, strict=True):
        assert r.status is SynthesisStatus.SYNTHESIZED, (tau, str(r))
        assert r.decay_certificate is not None
        assert r.certificate.certified and r.decay_certificate.certified
        assert r.margin.margin > tau
    w = [r.omega_n * tau for tau, r in zip(taus, results, strict=True)]
    assert w == pytest.approx([w[0]] * len(w), rel=1e-12)
    alpha_tau = [r.decay_rate * tau for tau, r in zip(taus, results, strict=True)]
    assert alpha_tau == pytest.approx([alpha_tau[0]] * len(w), rel=1e-3)
    root_tau = [r.rightmost_root.real * tau for tau, r in zip(taus, results, strict=True)]
    assert root_tau == pytest.approx([root_tau[0]] * len(w), rel=1e-12)


def test_zeta_above_one_and_wirtinger_order() -> None:
    result = synthesize_pd(paper.SPACECRAFT, 2.0, zeta=1.5, order=WIRTINGER)
    assert result.status is SynthesisStatus.SYNTHESIZED, str(result)
    w_ref = _golden_min(lambda w: _unit_abscissa(w, 1.5), 0.02, 0.5, 1e-6)
    assert result.omega_n * 2.0 == pytest.approx(w_ref, rel=1e-3)
    assert result.decay_rate < result.exact_decay_rate
    assert result.gains.overdamped and "overdamped" in str(result)


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
    assert result.certificate is not None and result.decay_certificate is not None and result.margin is not None
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
    assert result.margin is not None and result.margin.margin > tau


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


@pytest.mark.slow
def test_decay_optimal_gains_converge_on_random_tumbles() -> None:
    # The issue: the old "fastest certified" gains (omega_n = 1.29477 at tau = 0.5 s, exact margin
    # 0.500019 s) converged on none of 200 random tumbles in 120 s. Nonlinear simulation, 24 runs.
    from mrpctl import NoSwitching, mrp, simulate_batch
    from mrpctl.design import pd_gains
    from mrpctl.model import state

    rng = np.random.default_rng(9)
    x0 = []
    for _ in range(24):
        axis = rng.normal(size=3)
        sigma = mrp.from_principal_rotation(axis / np.linalg.norm(axis), rng.uniform(0.0, np.pi))
        w = rng.normal(size=3)
        x0.append(state(sigma, w * rng.uniform(0.0, 0.5) / np.linalg.norm(w)))
    design = synthesize_pd(paper.SPACECRAFT, 0.5)
    new = simulate_batch(
        paper.SPACECRAFT, design.gains.K, np.array(x0), tau=0.5, rule=NoSwitching(), t_final=60.0, rate=200.0
    )
    old_k = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=1.29477).K
    old = simulate_batch(paper.SPACECRAFT, old_k, np.array(x0), tau=0.5, rule=NoSwitching(), t_final=60.0, rate=200.0)
    assert bool(np.all(new.converged))
    assert not bool(np.any(old.converged))
