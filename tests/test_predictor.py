"""Tests of mrpctl.predictor against the independent NumPy reference loop (tests/predictor_reference.py)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from mrpctl import paper, simulate
from mrpctl.design import pd_gains
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.predictor import (
    StabilityMethod,
    inertia_mismatch_margin,
    lifted_spectral_radius,
    perturbed_spacecraft,
    predictor_loop_matrices,
    predictor_stability,
    sampled_predictor_matrices,
    synthesize_predictor_pd,
)
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnCurrent

sys.path.insert(0, str(Path(__file__).parent))
import predictor_reference as ref

SC = paper.SPACECRAFT
J = np.diag(SC.inertia)
X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])


def _gain(omega_n: float) -> np.ndarray:
    return pd_gains(SC, zeta=1.0, omega_n=omega_n).K


# ------------------------------------------------------------------ exact stability tests
@pytest.mark.parametrize("e", [0.0, 0.3, -0.5, -0.65, 5.0])
def test_axis_polynomial_agrees_with_lifted_matrix(e: float) -> None:
    plant = perturbed_spacecraft(SC, e)
    f0, f1, d = sampled_predictor_matrices(SC, _gain(1.0), 0.5, plant=plant, rate=20.0)
    lifted = lifted_spectral_radius(f0, f1, d)  # eigenvalues of the 6(d+1) block companion
    axis = predictor_stability(SC, _gain(1.0), 0.5, plant=plant, rate=20.0, radius=True)
    assert axis.method is StabilityMethod.AXIS_POLYNOMIAL
    assert axis.spectral_radius == pytest.approx(lifted, rel=1e-4)
    assert axis.stable == (lifted < 1.0)


def test_sampled_recursion_equals_closed_form_fsa_prediction() -> None:
    """x̂_{k+1} = F₀ x̂_k + F₁ x̂_{k−d} reproduces the finite-spectrum-assignment sums (expm, augmented matrix)."""
    model, plant = SC, perturbed_spacecraft(SC, 0.2)
    gain = _gain(2.0)
    rate, tau = 20.0, 0.5
    d = round(tau * rate)
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    b = np.vstack((np.zeros((3, 3)), np.linalg.inv(plant.inertia) / 4))
    b_m = np.vstack((np.zeros((3, 3)), np.linalg.inv(model.inertia) / 4))
    _, preds = ref.linear_run(a, b, b_m, gain, X0 * 1e-3, d=d, h=1 / rate, n=6 * d)
    f0, f1, _ = sampled_predictor_matrices(model, gain, tau, plant=plant, rate=rate)
    for k in range(2 * d, 6 * d - 1):
        expected = preds[k + 1]
        got = f0 @ preds[k] + f1 @ preds[k - d]
        assert np.allclose(got, expected, rtol=1e-9, atol=1e-12 * np.max(np.abs(preds)))


def test_continuous_matrices_match_derivative_of_prediction() -> None:
    """dx̂/dt = A₀ x̂ + A₁ x̂(t − τ): A₀ = A + B_m K, A₁ = e^{Aτ}(B − B_m)K; with J = J_m, A₁ = 0."""
    a0, a1 = predictor_loop_matrices(SC, _gain(1.0), 0.5)
    assert not np.any(a1)
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    plant = perturbed_spacecraft(SC, 0.1)
    b = np.vstack((np.zeros((3, 3)), np.linalg.inv(plant.inertia) / 4))
    b_m = np.vstack((np.zeros((3, 3)), np.linalg.inv(SC.inertia) / 4))
    _, a1 = predictor_loop_matrices(SC, _gain(1.0), 0.5, plant=plant)
    assert np.allclose(a1, scipy.linalg.expm(0.5 * a) @ (b - b_m) @ _gain(1.0), rtol=1e-12)
    assert np.allclose(a0, a + b_m @ _gain(1.0), rtol=1e-12)


@pytest.mark.slow
def test_continuous_margin_is_the_limit_of_the_sampled_margins() -> None:
    gain = _gain(1.0)
    cont = inertia_mismatch_margin(SC, gain, 0.5, rate=None, per_axis=False, e_max=1.0)
    fine = inertia_mismatch_margin(SC, gain, 0.5, rate=200.0, per_axis=False, e_max=1.0)
    coarse = inertia_mismatch_margin(SC, gain, 0.5, rate=20.0, per_axis=False, e_max=1.0)
    assert cont.uniform.lower == pytest.approx(fine.uniform.lower, rel=5e-3)
    assert abs(fine.uniform.lower - cont.uniform.lower) < abs(coarse.uniform.lower - cont.uniform.lower)
    assert cont.uniform.upper_capped and fine.uniform.upper_capped  # heavier plants: stable to e_max


# ------------------------------------------------------------------ margin against a simulation sweep
def _linear_growth(e: float, gain: np.ndarray, rate: float, seconds: float) -> float:
    plant = perturbed_spacecraft(SC, e)
    d = round(0.5 * rate)
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    b = np.vstack((np.zeros((3, 3)), np.linalg.inv(plant.inertia) / 4))
    b_m = np.vstack((np.zeros((3, 3)), np.linalg.inv(SC.inertia) / 4))
    n = round(seconds * rate)
    xs, _ = ref.linear_run(a, b, b_m, gain, np.array([1e-3, -2e-3, 1e-3, 0, 0, 0]), d=d, h=1 / rate, n=n)
    late = np.max(np.abs(xs[-d:]))
    early = np.max(np.abs(xs[d : 2 * d]))
    return late / early


def test_mismatch_margin_brackets_the_instability_of_a_simulation_sweep() -> None:
    gain, rate = _gain(12.85), 20.0
    margin = inertia_mismatch_margin(SC, gain, 0.5, rate=rate, per_axis=False)
    lower, upper = margin.uniform.lower, margin.uniform.upper
    assert -0.5 < lower < 0.0 < upper < 1.0 and not margin.uniform.upper_capped
    assert _linear_growth(0.8 * lower, gain, rate, 40.0) < 0.5  # inside: decays
    assert _linear_growth(1.2 * lower, gain, rate, 40.0) > 2.0  # outside: grows
    assert _linear_growth(0.8 * upper, gain, rate, 40.0) < 0.5
    assert _linear_growth(1.2 * upper, gain, rate, 40.0) > 2.0


@pytest.mark.slow
def test_per_axis_margin_of_a_coupled_model_uses_the_6x6_loop() -> None:
    coupled = Spacecraft([[140.0, 5.0, 0.0], [5.0, 100.0, 3.0], [0.0, 3.0, 80.0]])  # type: ignore[arg-type]
    gain = pd_gains(coupled, zeta=1.0, omega_n=4.0).K
    margin = inertia_mismatch_margin(coupled, gain, 0.5, rate=None, e_max=1.0)
    assert len(margin.per_axis) == 3
    assert margin.symmetric > 0.0
    # just outside the uniform lower end the loop is unstable, just inside it is stable
    lo = margin.uniform.lower
    assert predictor_stability(coupled, gain, 0.5, plant=perturbed_spacecraft(coupled, 0.99 * lo), rate=None).stable
    assert not predictor_stability(coupled, gain, 0.5, plant=perturbed_spacecraft(coupled, 1.01 * lo), rate=None).stable


@pytest.mark.slow
def test_design_returns_the_fastest_gain_keeping_the_margin() -> None:
    design = synthesize_predictor_pd(SC, 0.5, mismatch=0.2, rate=20.0, rtol=1e-3)
    assert design.margin.symmetric >= 0.2
    faster = pd_gains(SC, zeta=1.0, omega_n=design.omega_n * 1.01).K
    assert inertia_mismatch_margin(SC, faster, 0.5, rate=20.0, per_axis=False).uniform.symmetric < 0.2


# ------------------------------------------------------------------ the nonlinear reference loop
def test_exact_model_predictor_loop_equals_the_undelayed_loop() -> None:
    """J_m = J: for t >= τ the predictor loop is the undelayed loop started from its state at τ.

    Plant and model are integrated by the same RK4 step, so the prediction error is rounding only
    (bound 1e-12 rad); the uncompensated delayed loop differs by O(1).
    """
    rate, tau, d = 100.0, 0.5, 50
    pred = ref.run(J, J, paper.GAIN, X0, tau=tau, rate=rate, t_final=3.0, form="model-copy", alpha=1.0)
    assert np.max(pred.attitude_error) < 1e-12 and np.max(pred.rate_error) < 1e-12
    undelayed = ref.run(J, J, paper.GAIN, pred.x[d], tau=0.0, rate=rate, t_final=2.5, form="none", alpha=1.0)
    assert np.max(np.abs(pred.x[d:] - undelayed.x)) < 1e-10
    delayed = ref.run(J, J, paper.GAIN, X0, tau=tau, rate=rate, t_final=3.0, form="none", alpha=1.0)
    assert np.max(np.abs(delayed.x - pred.x)) > 1e-2


def test_switching_on_the_predicted_attitude_matches_the_engine_without_delay() -> None:
    """With an exact model the predicted switch is the τ = 0 switch of mrpctl's compiled engine (OnCurrent)."""
    rate = 100.0
    pred = ref.run(J, J, paper.GAIN, X0, tau=0.5, rate=rate, t_final=2.0, form="model-copy", alpha=1.0)
    engine = simulate(SC, paper.GAIN, X0, tau=0.0, rule=OnCurrent(), t_final=2.0, rate=rate)
    assert pred.switches == engine.switch_indices.tolist() and len(pred.switches) == 1
    # the engine's state after its switch is in the shadow set; compare attitudes on the rotation group
    for k in range(len(engine.t)):
        assert ref.angle_between(ref.dcm(engine.sigma[k]), ref.dcm(pred.x[k, :3])) < 1e-9
    assert np.allclose(engine.omega, 4 * pred.x[:, 3:], atol=1e-9)


def test_hysteresis_delays_the_switch_on_the_prediction() -> None:
    plain = ref.run(J, J, paper.GAIN, X0, tau=0.5, rate=100.0, t_final=2.0, form="model-copy", alpha=1.0)
    hysteretic = ref.run(J, J, paper.GAIN, X0, tau=0.5, rate=100.0, t_final=2.0, form="model-copy", alpha=1.01)
    assert len(hysteretic.switches) == 1 and hysteretic.switches[0] > plain.switches[0]
    k = hysteretic.switches[0]
    assert np.linalg.norm(hysteretic.sigma_hat[k - 1]) < 1.01 <= 1.0 / np.linalg.norm(hysteretic.sigma_hat[k])


def test_prediction_error_is_the_integration_error_of_the_prediction() -> None:
    """A finer plant (10 RK4 substeps): the prediction error is the model's one-step RK4 error over τ.

    The bound: the model copy's error is at most 3 times that of exact re-integration over τ (form (a),
    whose error *is* the integration error of the prediction), and that is O(h⁴): halving h divides it
    by about 16.
    """
    errors = {}
    for rate in (20.0, 40.0):
        runs = {
            form: ref.run(J, J, paper.GAIN, X0, tau=0.5, rate=rate, t_final=2.0, form=form, plant_substeps=10)
            for form in ("model-copy", "reintegrate")
        }
        d = round(0.5 * rate)
        copy_err = np.max(runs["model-copy"].attitude_error[d:])
        integ_err = np.max(runs["reintegrate"].attitude_error[d:])
        assert 0.0 < copy_err <= 3.0 * integ_err
        errors[rate] = integ_err
    assert 8.0 < errors[20.0] / errors[40.0] < 32.0


def test_linearised_nonlinear_predictor_is_the_fsa_prediction() -> None:
    """Small angles, 10 % inertia error: the model-copy predictor (group correction and τ δω transport)
    matches e^{Aτ} y + Σ e^{A(t_k − t_{j+1})} Γ_m u_j (expm of the augmented matrix) to O(|x|); the
    textbook Smith correction (no transport) does not."""
    rate, tau, d = 20.0, 0.5, 10
    x0 = np.array([2e-5, -1e-5, 1e-5, 1e-5, 2e-5, -1e-5])
    gain = _gain(2.0)
    plant_j = J * 1.1
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [np.zeros((3, 3)), np.zeros((3, 3))]])
    b_m = np.vstack((np.zeros((3, 3)), np.diag(1 / J) / 4))
    h = 1 / rate
    aug = np.zeros((9, 9))
    aug[:6, :6] = a
    aug[:6, 6:] = b_m
    e = scipy.linalg.expm(aug * h)
    gamma_m = e[:6, 6:]
    for form, should_match in (("model-copy", True), ("smith", False)):
        r = ref.run(plant_j, J, gain, x0, tau=tau, rate=rate, t_final=4.0, form=form, alpha=None)
        worst = 0.0
        for k in range(2 * d, len(r.t)):
            fsa = scipy.linalg.expm(a * tau) @ r.x[k - d]
            for j in range(k - d, k):
                fsa = fsa + scipy.linalg.expm(a * (k - 1 - j) * h) @ gamma_m @ r.u[j]
            worst = max(worst, float(np.max(np.abs(r.x_hat[k] - fsa)) / np.max(np.abs(fsa))))
        assert (worst < 1e-3) == should_match, (form, worst)


# ------------------------------------------------------------------ bad input
def test_bad_input_names_the_parameter() -> None:
    with pytest.raises(SpecificationError, match="spacecraft"):
        predictor_stability(np.diag([1.0, 2.0, 3.0]), _gain(1.0), 0.5)  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="plant"):
        predictor_stability(SC, _gain(1.0), 0.5, plant=[1.0, 2.0, 3.0])  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="tau"):
        sampled_predictor_matrices(SC, _gain(1.0), 0.5005, rate=1000.0 / 3.0)
    with pytest.raises(SpecificationError, match="tau"):
        inertia_mismatch_margin(SC, _gain(1.0), 0.0123, rate=100.0)
    with pytest.raises(DimensionError, match="K"):
        predictor_stability(SC, np.ones((3, 3)), 0.5)
    with pytest.raises(SpecificationError, match="mismatch"):
        synthesize_predictor_pd(SC, 0.5, mismatch=1.5)
    with pytest.raises(SpecificationError, match="e "):
        perturbed_spacecraft(SC, -1.0)
    with pytest.raises(SpecificationError, match="per_axis"):
        inertia_mismatch_margin(SC, _gain(1.0), 0.5, per_axis="yes")  # type: ignore[arg-type]
    unstable = -_gain(1.0)
    with pytest.raises(SpecificationError, match="not stable"):
        inertia_mismatch_margin(SC, unstable, 0.5, rate=20.0)
    assert math.isnan(predictor_stability(SC, _gain(1.0), 0.5, rate=None).spectral_radius)
