"""The predictor controller in the compiled engine against the independent NumPy reference loop.

The reference (tests/predictor_reference.py) composes attitudes as direction cosine matrices and
converts through Shepperd's quaternion; the engine composes quaternions in generated C. Both
integrate plant and model copy by RK4 with the same step, so they agree to rounding: the bound
used below is 1e-14 relative to the largest state component (or torque) of the run (measured: at most
6.5e-16), and the switch
samples must be identical.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrpctl import OnPredicted, Predictor, SimulationResult, paper, simulate, simulate_batch
from mrpctl.design import pd_gains
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, Saturation, SensorModel
from mrpctl.predictor import perturbed_spacecraft
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnCurrent, OnDelayed

sys.path.insert(0, str(Path(__file__).parent))
import predictor_reference as ref

SC = paper.SPACECRAFT
J = np.diag(SC.inertia)
X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])
TUMBLE = np.array([0.3, -0.5, 0.2, 4.0 / 4, -2.0 / 4, 3.0 / 4])  # |ω| = 5.4 rad/s
TUMBLE2 = np.array([-0.6, 0.1, 0.7, -2.0 / 4, 3.0 / 4, 1.0 / 4])
RTOL = 1e-14  # measured at most 6.5e-16 on these cases (design/predictor.md)


def _gain(omega_n: float) -> np.ndarray:
    return pd_gains(SC, zeta=1.0, omega_n=omega_n).K


def _engine_state(result: SimulationResult) -> np.ndarray:
    return np.hstack((result.sigma, result.omega / 4.0))


def _assert_matches(result: SimulationResult, reference: ref.Run, gain: np.ndarray) -> None:
    assert result.switch_indices.tolist() == reference.switches
    assert result.switch_count == len(reference.switches)
    x = _engine_state(result)
    assert x.shape == reference.x.shape
    scale = np.max(np.abs(reference.x))
    assert np.max(np.abs(x - reference.x)) <= RTOL * scale
    # u = sat(K x̂): its error is bounded by ‖K‖∞ times the error of x̂, so its scale is ‖K‖∞ max|x̂| (or the
    # torque itself, if larger), not max|u|: with ‖K‖∞ = 4480 a one-ulp x̂ (2e-16) moves a 6.5 N m torque by
    # 7e-13 (measured on a Zen 4 host, whose NumPy/BLAS kernels round the reference differently)
    torque = max(np.max(np.abs(reference.u)), np.max(np.sum(np.abs(gain), axis=1)) * np.max(np.abs(reference.x_hat)))
    assert np.max(np.abs(result.u - reference.u)) <= RTOL * torque


CASES = [
    # (x0, gain, plant inertia error e, alpha, t_final, switches in the reference: not a vacuous comparison)
    pytest.param(X0, paper.GAIN, 0.0, 1.0, 3.0, 1, id="paper-exact-model"),
    pytest.param(X0, paper.GAIN, 0.1, 1.0, 3.0, 1, id="paper-plant+10%"),
    pytest.param(X0, _gain(3.0), -0.1, 1.0, 3.0, 0, id="paper-fast-plant-10%"),
    pytest.param(TUMBLE, _gain(1.0), 0.0, 1.0, 4.0, 1, id="tumble-exact-model"),
    pytest.param(TUMBLE, _gain(0.2), 0.1, 1.0, 6.0, 2, id="tumble-slow-plant+10%"),
    pytest.param(TUMBLE2, _gain(0.2), 0.1, 1.0, 6.0, 2, id="tumble2-slow-plant+10%"),
    pytest.param(TUMBLE2, _gain(2.0), -0.15, 1.0, 4.0, None, id="tumble2-plant-15%"),
    pytest.param(TUMBLE2, _gain(0.2), 0.1, 1.05, 6.0, 1, id="tumble2-hysteresis"),  # one switch, later than α = 1
    pytest.param(TUMBLE, _gain(1.0), 0.1, None, 4.0, 0, id="tumble-never-switch"),
]


@pytest.mark.parametrize(("x0", "gain", "e", "alpha", "t_final", "switches"), CASES)
def test_engine_equals_the_reference_loop(
    x0: np.ndarray, gain: np.ndarray, e: float, alpha: float | None, t_final: float, switches: int | None
) -> None:
    """Model ≠ plant when e ≠ 0: the plant is (1 + e) J_model; identical switch samples, states to 1e-12."""
    plant = perturbed_spacecraft(SC, e)
    result = simulate(
        plant,
        gain,
        x0,
        tau=0.5,
        rule=OnPredicted(alpha),
        t_final=t_final,
        rate=100.0,
        predictor=Predictor(model=SC),
    )
    reference = ref.run(
        np.diag(plant.inertia), J, gain, x0, tau=0.5, rate=100.0, t_final=t_final, form="model-copy", alpha=alpha
    )
    _assert_matches(result, reference, gain)
    if switches is not None:
        assert len(reference.switches) == switches


def test_exact_model_equals_the_undelayed_loop_after_tau() -> None:
    """J_m = J at 1 kHz: for t >= τ the predictor loop is the undelayed loop started from x(τ).

    Plant and model copy are the same RK4 step of the same inertia, so the prediction error is
    rounding only; the bound stated and tested is 1e-10 (relative to max |x|) over 3 s after τ. The
    plain delayed loop differs by more than 1e-2.
    """
    tau, rate, d = 0.5, 1000.0, 500
    pred = simulate(
        SC, paper.GAIN, X0, tau=tau, rule=OnPredicted(), t_final=3.5, rate=rate, predictor=Predictor(model=SC)
    )
    x = _engine_state(pred)
    undelayed = simulate(SC, paper.GAIN, x[d], tau=0.0, rule=OnCurrent(), t_final=3.0, rate=rate)
    assert np.max(np.abs(x[d:] - _engine_state(undelayed))) <= 1e-10 * np.max(np.abs(x))
    late = pred.switch_indices[pred.switch_indices >= d] - d
    assert np.array_equal(late, undelayed.switch_indices)
    # The copy starts at x0, the constant history, so the prediction is exact from t = 0: the whole run
    # (its switch at 0.438 s < τ included) is the undelayed run from x0.
    from_start = simulate(SC, paper.GAIN, X0, tau=0.0, rule=OnCurrent(), t_final=3.5, rate=rate)
    assert pred.switch_indices.tolist() == from_start.switch_indices.tolist() == [438]
    assert np.max(np.abs(x - _engine_state(from_start))) <= 1e-10 * np.max(np.abs(x))
    delayed = simulate(SC, paper.GAIN, X0, tau=tau, rule=OnCurrent(), t_final=3.5, rate=rate)
    assert np.max(np.abs(_engine_state(delayed) - x)) > 1e-2


def test_batch_equals_simulate() -> None:
    """simulate_batch with a predictor (scalar engine, thread pool) gives simulate's bits, per run."""
    states = np.array([X0, TUMBLE, TUMBLE2])
    plants = [perturbed_spacecraft(SC, e) for e in (0.0, 0.1, -0.1)]
    predictor = Predictor(model=SC)
    gain = _gain(1.0)
    singles = [
        simulate(plants[i], gain, states[i], tau=0.2, rule=OnPredicted(), t_final=2.0, rate=100.0, predictor=predictor)
        for i in range(3)
    ]
    for trajectories in (True, False):
        batch = simulate_batch(
            plants,
            gain,
            states,
            tau=0.2,
            rule=OnPredicted(),
            t_final=2.0,
            rate=100.0,
            predictor=predictor,
            trajectories=trajectories,
            threads=2,
        )
        assert batch.switch_count.tolist() == [s.switch_count for s in singles]
        assert np.array_equal(batch.max_sigma, [s.max_sigma for s in singles])
        if trajectories:
            assert batch.runs is not None
            for run, single in zip(batch.runs, singles, strict=True):
                assert np.array_equal(run.sigma, single.sigma) and np.array_equal(run.u, single.u)
                assert np.array_equal(run.switch_indices, single.switch_indices)
    assert sum(s.switch_count for s in singles) >= 1


def test_actuator_limits_drive_the_model_copy_with_the_applied_torque() -> None:
    """Per-axis clipping: the engine equals the reference, which feeds the clipped torque to plant and copy."""
    plant = perturbed_spacecraft(SC, 0.1)
    gain = _gain(2.0)
    result = simulate(
        plant,
        gain,
        TUMBLE,
        tau=0.5,
        rule=OnPredicted(),
        t_final=4.0,
        rate=100.0,
        predictor=Predictor(model=SC),
        actuator=ActuatorModel(u_max=50.0, mode=Saturation.CLIP),
    )
    reference = ref.run(np.diag(plant.inertia), J, gain, TUMBLE, tau=0.5, rate=100.0, t_final=4.0, u_max=50.0)
    _assert_matches(result, reference, gain)
    assert np.max(np.abs(result.u)) == 50.0
    assert result.saturated_fraction is not None and result.saturated_fraction > 0.1
    assert result.peak_command is not None and result.peak_command[3] > 50.0


def test_disturbance_acts_on_the_plant_only() -> None:
    w = np.array([0.3, -0.2, 0.1])
    result = simulate(
        SC,
        _gain(1.0),
        TUMBLE,
        tau=0.5,
        rule=OnPredicted(),
        t_final=4.0,
        rate=100.0,
        predictor=Predictor(model=SC),
        disturbance=w,
    )
    reference = ref.run(J, J, _gain(1.0), TUMBLE, tau=0.5, rate=100.0, t_final=4.0, disturbance=w)
    _assert_matches(result, reference, _gain(1.0))


def test_sensor_noise_and_bias_enter_the_correction() -> None:
    """The noisy measurement is what the copy is corrected with (the same noise stream in the reference)."""
    sensor = SensorModel(attitude_noise=1e-3, rate_noise=1e-3, gyro_bias=[1e-3, -2e-3, 0.5e-3], seed=7)
    n = 401
    theta, eta = sensor.noise(0, n)
    result = simulate(
        perturbed_spacecraft(SC, 0.1),
        _gain(1.0),
        TUMBLE,
        tau=0.5,
        rule=OnPredicted(),
        t_final=4.0,
        rate=100.0,
        predictor=Predictor(model=SC),
        sensor=sensor,
    )
    reference = ref.run(
        J * 1.1,
        J,
        _gain(1.0),
        TUMBLE,
        tau=0.5,
        rate=100.0,
        t_final=4.0,
        noise=(theta, eta, np.asarray(sensor.gyro_bias)),
    )
    assert result.switch_indices.tolist() == reference.switches
    x = _engine_state(result)
    # The sensor composes MRPs where the reference multiplies DCMs: the same bound holds.
    assert np.max(np.abs(x - reference.x)) <= RTOL * np.max(np.abs(reference.x))
    noiseless = ref.run(J * 1.1, J, _gain(1.0), TUMBLE, tau=0.5, rate=100.0, t_final=4.0)
    assert np.max(np.abs(noiseless.x - reference.x)) > 1e-6  # the noise is not vacuous


def test_full_inertia_model_and_plant() -> None:
    """A coupled (non-diagonal) model and plant: the full-inertia layouts of both RK4 steps."""
    coupled = Spacecraft(np.array([[140.0, 5.0, 0.0], [5.0, 100.0, 3.0], [0.0, 3.0, 80.0]]))
    plant = perturbed_spacecraft(coupled, 0.1, axis=1)
    gain = pd_gains(coupled, zeta=1.0, omega_n=1.0).K
    result = simulate(
        plant, gain, TUMBLE, tau=0.3, rule=OnPredicted(), t_final=3.0, rate=100.0, predictor=Predictor(model=coupled)
    )
    reference = ref.run(plant.inertia, coupled.inertia, gain, TUMBLE, tau=0.3, rate=100.0, t_final=3.0)
    _assert_matches(result, reference, gain)


def test_no_delay_predicts_the_measurement() -> None:
    """τ = 0: the correction is the identity, x̂ = y, and the loop is OnCurrent's undelayed loop."""
    pred = simulate(SC, paper.GAIN, X0, tau=0.0, rule=OnPredicted(), t_final=2.0, rate=100.0, predictor=Predictor(SC))
    plain = simulate(SC, paper.GAIN, X0, tau=0.0, rule=OnCurrent(), t_final=2.0, rate=100.0)
    assert pred.switch_indices.tolist() == plain.switch_indices.tolist()
    assert np.max(np.abs(_engine_state(pred) - _engine_state(plain))) <= 1e-12


def test_bad_input_names_the_parameter() -> None:
    common: dict[str, Any] = dict(tau=0.5, t_final=1.0, rate=100.0)
    with pytest.raises(SpecificationError, match="model"):
        Predictor(model=np.eye(3))  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="alpha"):
        OnPredicted(0.5)
    with pytest.raises(SpecificationError, match="predictor"):
        simulate(SC, paper.GAIN, X0, rule=OnPredicted(), **common, predictor=SC)  # type: ignore[arg-type]
    with pytest.raises(SpecificationError, match="rule"):
        simulate(SC, paper.GAIN, X0, rule=OnDelayed(), **common, predictor=Predictor(SC))
    with pytest.raises(SpecificationError, match="rule"):
        simulate(SC, paper.GAIN, X0, rule=Hysteretic(0.1), **common, predictor=Predictor(SC))
    with pytest.raises(SpecificationError, match="predictor="):
        simulate(SC, paper.GAIN, X0, rule=OnPredicted(), **common)
    with pytest.raises(SpecificationError, match="history"):
        simulate(SC, paper.GAIN, X0, rule=OnPredicted(), **common, history="zero-input", predictor=Predictor(SC))
    with pytest.raises(SpecificationError, match="history"):
        simulate(SC, paper.GAIN, X0, rule=OnPredicted(), **common, history=np.zeros((50, 6)), predictor=Predictor(SC))
    jitter = DelayModel.jitter(0.4, 0.5, seed=1)
    with pytest.raises(SpecificationError, match="delay"):
        simulate(SC, paper.GAIN, X0, rule=OnPredicted(), **common, delay=jitter, predictor=Predictor(SC))
    with pytest.raises(SpecificationError, match="tau"):
        simulate(SC, paper.GAIN, X0, rule=OnPredicted(), tau=0.505, t_final=1.0, rate=100.0, predictor=Predictor(SC))
    with pytest.raises(SpecificationError, match="rule"):
        simulate_batch(SC, paper.GAIN, X0, rule=[OnPredicted(), OnCurrent()], **common, predictor=Predictor(SC))


@pytest.mark.parametrize("trajectories", [False, True])
def test_a_predictor_batch_reports_the_actuator_summaries_of_its_runs(trajectories: bool) -> None:
    """saturated_fraction and peak_command of a predictor batch are the runs' (they were None: a second audit)."""
    options = dict(tau=0.5, rule=OnPredicted(1.2), predictor=Predictor(model=SC), t_final=5.0)
    states = np.array([X0, TUMBLE])
    for actuator in (ActuatorModel(u_max=20.0), None):
        batch = simulate_batch(SC, paper.GAIN, states, actuator=actuator, trajectories=trajectories, **options)
        assert batch.saturated_fraction is not None and batch.peak_command is not None
        for i, x0 in enumerate(states):
            run = simulate(SC, paper.GAIN, x0, actuator=actuator, **options)
            assert batch.saturated_fraction[i] == run.saturated_fraction
            np.testing.assert_array_equal(batch.peak_command[i], run.peak_command)
        if actuator is not None:
            assert np.all(batch.saturated_fraction > 0.1)
