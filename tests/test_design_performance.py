"""Margins, H∞ (exact and LMI-certified), H₂ and pointing budgets of delayed loops, against independent references."""

from __future__ import annotations

import math

import control
import numpy as np
import pytest
import scipy.integrate

from mrpctl import paper
from mrpctl.design import delay_margin, linearized_loop
from mrpctl.design.performance import (
    hinf_bound,
    hinf_norm,
    loop_margins_delayed,
    spacecraft_margins,
)
from mrpctl.design.pointing import (
    ARCSEC,
    h2_norm,
    pointing_budget,
    torque_to_attitude,
)
from mrpctl.design.spectra import characteristic_roots
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.interop import loop_margins

THIRD_ORDER_A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, -2.0, -3.0]])
THIRD_ORDER_B = np.array([[0.0], [0.0], [1.0]])
THIRD_ORDER_K = np.array([[-4.0, 0.0, 0.0]])


def _sweep(a: np.ndarray, a_d: np.ndarray, tau: float, b: np.ndarray, c: np.ndarray, w: np.ndarray) -> np.ndarray:
    """σ_max(C (iωI − A − A_d e^{−iωτ})⁻¹ B) on the grid, batched (nothing shared with the module)."""
    n = a.shape[0]
    m = 1j * w[:, None, None] * np.eye(n) - a - np.exp(-1j * w * tau)[:, None, None] * a_d
    tf = c @ np.linalg.solve(m, np.broadcast_to(b, (len(w), *b.shape)))
    return np.linalg.svd(tf, compute_uv=False)[:, 0]


def _dense_peak(a, a_d, tau, b, c, top: float) -> float:
    w = np.linspace(0.0, top, 200_001)
    s = _sweep(a, a_d, tau, b, c, w)
    i = int(np.argmax(s))
    fine = np.linspace(w[max(i - 1, 0)], w[min(i + 1, len(w) - 1)], 20_001)
    return float(max(s.max(), _sweep(a, a_d, tau, b, c, fine).max()))


# ------------------------------------------------------------------------------ margins
def test_delay_free_margins_match_python_control() -> None:
    margins = loop_margins_delayed(THIRD_ORDER_A, THIRD_ORDER_B, THIRD_ORDER_K, 0.0)
    gm, pm, _, wpc, wgc, _ = control.stability_margins(control.ss(THIRD_ORDER_A, THIRD_ORDER_B, -THIRD_ORDER_K, 0))
    assert margins.gain_margin == pytest.approx(gm, rel=1e-9)
    assert margins.phase_crossover == pytest.approx(wpc, rel=1e-9)
    assert math.degrees(margins.phase_margin) == pytest.approx(pm, rel=1e-9)
    assert margins.gain_crossover == pytest.approx(wgc, rel=1e-9)
    k1 = -paper.GAIN_SIGMA / (4 * np.array(paper.INERTIA))
    k2 = -paper.GAIN_OMEGA / (4 * np.array(paper.INERTIA))
    for i, axis in enumerate(spacecraft_margins(paper.SPACECRAFT, paper.GAIN, 0.0).axes):
        gm, pm, _, _, wgc, _ = control.stability_margins(control.tf([k2[i], k1[i]], [1.0, 0.0, 0.0]))
        assert math.isinf(axis.gain_margin) and math.isinf(gm)
        assert math.degrees(axis.phase_margin) == pytest.approx(pm, rel=1e-9)
        assert axis.gain_crossover == pytest.approx(wgc, rel=1e-9)


def test_delayed_margins_agree_with_the_exact_delay_margin_and_the_spectrum() -> None:
    tau = paper.TAU
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    exact = delay_margin(loop.A, loop.A_d).margin
    result = spacecraft_margins(paper.SPACECRAFT, paper.GAIN, tau)
    assert result.coupled.stable
    assert tau + result.coupled.delay_margin == pytest.approx(exact, rel=1e-9)
    free = spacecraft_margins(paper.SPACECRAFT, paper.GAIN, 0.0)
    for axis, axis0, (a_i, a_d_i) in zip(result.axes, free.axes, loop.axes, strict=True):
        assert tau + axis.delay_margin == pytest.approx(delay_margin(a_i, a_d_i).margin, rel=1e-9)
        # |L(iω)| does not depend on τ: same crossover, phase lower by ω_c τ
        assert axis.gain_crossover == pytest.approx(axis0.gain_crossover, rel=1e-9)
        assert axis.phase_margin == pytest.approx(axis0.phase_margin - axis0.gain_crossover * tau, rel=1e-9)
        # K times the gain margin puts a root on the imaginary axis at the phase crossover
        spectrum = characteristic_roots(a_i, axis.gain_margin * a_d_i, tau, count=2)
        assert abs(spectrum.abscissa) <= 1e-8
        assert spectrum.rightmost.imag == pytest.approx(axis.phase_crossover, rel=1e-8)
    assert result.coupled.gain_margin == pytest.approx(min(a.gain_margin for a in result.axes), rel=1e-9)
    assert result.coupled.phase_margin == pytest.approx(min(a.phase_margin for a in result.axes), rel=1e-9)


def test_interop_loop_margins_keep_the_gain_margin_of_python_control() -> None:
    margins = loop_margins(paper.SPACECRAFT, paper.GAIN)
    for axis, inertia in zip(margins.axes, paper.INERTIA, strict=True):
        tf = control.tf([-paper.GAIN_OMEGA / (4 * inertia), -paper.GAIN_SIGMA / (4 * inertia)], [1.0, 0.0, 0.0])
        gm, _, _, wpc, _, _ = control.stability_margins(tf)
        assert axis.gain_margin == gm or (math.isinf(axis.gain_margin) and math.isinf(gm))
        assert math.isnan(axis.phase_crossover) == (not np.isfinite(wpc))


# ------------------------------------------------------------------------------ H-infinity
def test_hinf_of_the_paper_loop_bounds_and_matches_a_dense_sweep() -> None:
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    result = hinf_norm(a, a_d, paper.TAU, b, c)
    sweep = _dense_peak(a, a_d, paper.TAU, b, c, 5.0)
    assert result.finite
    assert result.value >= sweep * (1.0 - 1e-12)
    assert (result.value - sweep) / result.value <= 1e-6
    bound = hinf_bound(a, a_d, paper.TAU, b, c, order=2)
    assert bound.certified and bound.value >= result.value
    assert result.value / bound.value >= 0.99


def _random_stable(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray, float, np.ndarray, np.ndarray]:
    while True:
        a = rng.normal(size=(n, n)) - 1.5 * np.eye(n)
        a_d = 0.6 * rng.normal(size=(n, n))
        tau = float(rng.uniform(0.1, 2.0))
        spectrum = characteristic_roots(a, a_d, tau, count=2)
        if spectrum.certified and spectrum.abscissa < -0.05:
            return a, a_d, tau, rng.normal(size=(n, 1)), rng.normal(size=(1, n))


def test_hinf_of_random_systems_matches_a_dense_sweep() -> None:
    rng = np.random.default_rng(11)
    for _ in range(12):
        n = int(rng.integers(1, 4))
        a, a_d, tau, b, c = _random_stable(rng, n)
        result = hinf_norm(a, a_d, tau, b, c)
        top = float(np.linalg.norm(a, 2) + np.linalg.norm(a_d, 2) + 3.0)
        sweep = _dense_peak(a, a_d, tau, b, c, top)
        assert result.value >= sweep * (1.0 - 1e-12)
        assert (result.value - sweep) / result.value <= 1e-6


def test_lmi_bound_is_above_the_exact_norm_on_100_random_stable_systems() -> None:
    rng = np.random.default_rng(5)
    certified = 0
    for _ in range(100):
        a, a_d, tau, b, c = _random_stable(rng, 2)
        exact = hinf_norm(a, a_d, tau, b, c).value
        bound = hinf_bound(a, a_d, tau, b, c, order=1)
        if bound.certified:
            certified += 1
            assert bound.value >= exact * (1.0 - 1e-12)
        else:
            assert math.isinf(bound.value)
    assert certified >= 50


def test_unstable_loop_has_an_infinite_hinf_norm_not_a_number() -> None:
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    tau = 1.1 * delay_margin(loop.A, loop.A_d).margin
    result = hinf_norm(a, a_d, tau, b, c)
    assert not result.stable and math.isinf(result.value) and "infinite" in str(result)
    assert math.isinf(h2_norm(a, a_d, tau, b, c).value)
    assert not hinf_bound(a, a_d, tau, b, c, order=1).certified
    with pytest.raises(SpecificationError, match="not exponentially stable"):
        pointing_budget(paper.SPACECRAFT, paper.GAIN, tau, torque_psd=1.0)


# ------------------------------------------------------------------------------ H2 and pointing
def _h2_by_frequency(a, a_d, tau, b, c) -> float:
    n = a.shape[0]

    def f(w: float) -> float:
        return float(np.linalg.norm(c @ np.linalg.solve(1j * w * np.eye(n) - a - a_d * np.exp(-1j * w * tau), b)) ** 2)

    pieces = [(0.0, 1.0), (1.0, 10.0), (10.0, 100.0), (100.0, np.inf)]
    total = sum(scipy.integrate.quad(f, lo, hi, limit=400, epsrel=1e-11, epsabs=0.0)[0] for lo, hi in pieces)
    return math.sqrt(total / math.pi)


def test_h2_matches_the_frequency_integral() -> None:
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    assert h2_norm(a, a_d, paper.TAU, b, c).value == pytest.approx(_h2_by_frequency(a, a_d, paper.TAU, b, c), rel=1e-8)
    rng = np.random.default_rng(3)
    for _ in range(5):
        a, a_d, tau, b, c = _random_stable(rng, 2)
        assert h2_norm(a, a_d, tau, b, c).value == pytest.approx(_h2_by_frequency(a, a_d, tau, b, c), rel=1e-7)


def _simulated_variance(a, a_d, tau, noise, c, *, dt=0.01, runs=4000, settle=60.0, window=60.0, seed=1):
    """Stationary variance of z = c x for ẋ = A x + A_d x(t − τ) + noise·ξ (unit white ξ): Euler-Maruyama,
    an ensemble of runs, averaged over a window after the transient."""
    rng = np.random.default_rng(seed)
    n = a.shape[0]
    lag = round(tau / dt)
    history = np.zeros((lag, runs, n))  # a ring of the last lag states: slot k % lag holds x_{k − lag}
    x = np.zeros((runs, n))
    samples = []
    steps = round((settle + window) / dt)
    for k in range(steps):
        delayed = history[k % lag].copy()  # x(t − τ), read before the slot is overwritten
        history[k % lag] = x
        x = x + dt * (x @ a.T + delayed @ a_d.T) + math.sqrt(dt) * rng.normal(size=(runs, noise.shape[1])) @ noise.T
        if k * dt >= settle and k % 50 == 0:
            samples.append(np.var(x @ c.T, axis=0))
    return np.mean(samples, axis=0)


def test_h2_matches_the_covariance_of_a_simulated_delayed_loop() -> None:
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    a_d = np.array([[0.0, 0.0], [-0.5, -1.0]])
    b = np.array([[0.0], [1.0]])
    c = np.array([[1.0, 0.0]])
    tau = 0.5
    h2 = h2_norm(a, a_d, tau, b, c).value
    variance = _simulated_variance(a, a_d, tau, b, c, settle=30.0, window=40.0)
    assert variance[0] == pytest.approx(h2**2, rel=0.03)


def test_pointing_budget_matches_h2_and_a_simulated_axis() -> None:
    psd, att = 1e-6, 2e-5
    budget = pointing_budget(paper.SPACECRAFT, paper.GAIN, paper.TAU, torque_psd=psd, attitude_noise=att)
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    # torque alone: 3σ = 3 sqrt(G/2) ‖T_i‖₂ through the primal delay Lyapunov matrix
    for i in range(3):
        h2 = h2_norm(a, a_d, paper.TAU, b[:, [i]], c[[i], :]).value
        assert budget.contributions["torque"][i] == pytest.approx(3 * math.sqrt(psd / 2) * h2 * ARCSEC, rel=1e-8)
    # axis 3 simulated with both sources (independent NumPy delayed loop)
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    a_i, a_d_i = loop.axes[2]
    b_i = np.array([[0.0], [1.0 / (4.0 * paper.INERTIA[2])]])
    noise = np.hstack((b_i * math.sqrt(psd / 2), a_d_i[:, [0]] * (att / 4) / math.sqrt(2)))
    variance = _simulated_variance(a_i, a_d_i, paper.TAU, noise, np.array([[4.0, 0.0]]), settle=40.0, window=60.0)
    assert 3 * math.sqrt(variance[0]) * ARCSEC == pytest.approx(budget.three_sigma[2], rel=0.03)


# ------------------------------------------------------------------------------ bad input
def test_bad_input_is_refused_naming_the_parameter() -> None:
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    with pytest.raises(DimensionError, match="B"):
        hinf_norm(a, a_d, 0.5, b[:4], c)
    with pytest.raises(DimensionError, match="C"):
        h2_norm(a, a_d, 0.5, b, c[:, :4])
    with pytest.raises(SpecificationError, match="tau"):
        hinf_norm(a, a_d, -0.5, b, c)
    with pytest.raises(SpecificationError, match="A0"):
        hinf_norm(np.full((6, 6), np.nan), a_d, 0.5, b, c)
    with pytest.raises(SpecificationError, match="torque_psd"):
        pointing_budget(paper.SPACECRAFT, paper.GAIN, 0.5, torque_psd=-1.0)
    with pytest.raises(DimensionError, match="K"):
        loop_margins_delayed(THIRD_ORDER_A, THIRD_ORDER_B, np.ones((1, 2)), 0.1)
    with pytest.raises(SpecificationError, match="tau"):
        loop_margins_delayed(THIRD_ORDER_A, THIRD_ORDER_B, THIRD_ORDER_K, math.inf)


def test_hinf_pd_synthesis_beats_the_paper_gain_is_certified_and_locally_optimal() -> None:
    from mrpctl.design.pointing import synthesize_hinf_pd

    result = synthesize_hinf_pd(paper.SPACECRAFT, paper.TAU, starts=1)
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    assert result.exact.value < hinf_norm(a, a_d, paper.TAU, b, c).value
    assert result.certified.certified and result.certified.value >= result.exact.value
    inertia = np.diag(paper.INERTIA)
    for dw, dz in ((1.02, 1.0), (0.98, 1.0), (1.0, 1.02), (1.0, 0.98)):
        w, z = result.omega_n * dw, result.zeta * dz
        k = 4.0 * inertia @ np.hstack((-(w**2) * np.eye(3), -2.0 * z * w * np.eye(3)))
        a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, k)
        assert hinf_norm(a, a_d, paper.TAU, b, c).value >= result.exact.value * (1.0 - 1e-6)


def test_pointing_budget_matches_a_monte_carlo_of_the_nonlinear_flight_loop() -> None:
    # the compiled nonlinear loop (sampled at 200 Hz, delay of 100 samples) with a white torque held per sample
    # (variance G/2 * rate: the intensity G/2) and star-tracker noise of 1-sigma a sqrt(rate / 2) per sample
    from mrpctl import simulate
    from mrpctl.flight import Hysteretic, SensorModel

    rate, t_final, psd, asd = 200.0, 6000.0, 1e-6, 1e-5
    samples = round(rate * t_final) + 1
    rows = np.random.default_rng(4).normal(size=(samples, 3)) * math.sqrt(psd / 2 * rate)
    run = simulate(
        paper.SPACECRAFT,
        paper.GAIN,
        np.zeros(6),
        tau=paper.TAU,
        rule=Hysteretic(0.0),
        t_final=t_final,
        rate=rate,
        disturbance=rows,
        sensor=SensorModel(attitude_noise=asd * math.sqrt(rate / 2), seed=3),
        keep_every=20,
    )
    theta = 4.0 * np.asarray(run.sigma)[np.asarray(run.t) > 60.0]
    measured = 3.0 * np.sqrt(np.var(theta, axis=0)) * ARCSEC
    budget = pointing_budget(paper.SPACECRAFT, paper.GAIN, paper.TAU, torque_psd=psd, attitude_noise=asd)
    assert np.allclose(measured, budget.three_sigma, rtol=0.05)
