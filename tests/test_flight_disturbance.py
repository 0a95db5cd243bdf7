"""Per-sample disturbance torques in the compiled flight sample (issue 10): streamed per slice like the noise."""

from __future__ import annotations

import numpy as np
import pytest
from flight_reference import _tumbles, reference_loop

from mrpctl import paper, simulate
from mrpctl.engines import scalar as _engine
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, SensorModel

GAINS = 0.05 * paper.GAIN
RATE, T_FINAL, N = 100.0, 8.0, 801


def _torque(n: int, seed: int) -> np.ndarray:
    t = np.arange(n) / RATE
    rng = np.random.default_rng(seed)
    return 0.02 * np.column_stack((np.sin(0.7 * t), np.cos(1.3 * t), -np.sin(0.2 * t))) + 0.01 * rng.normal(size=(n, 3))


def test_per_sample_disturbance_with_every_option_equals_the_reference_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    x0 = _tumbles(2, 4.0, 7)
    limit = np.array([0.5, 0.4, 0.6])
    sensor = SensorModel(attitude_noise=0.01, rate_noise=1e-4, gyro_bias=[1e-3, 0.0, -5e-4], seed=4)
    jitter = DelayModel.jitter(0.02, 0.12, seed=9)
    w = _torque(N, 1)
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 150)  # rows handed over slice by slice
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        GAINS,
        x0,
        rate=RATE,
        t_final=T_FINAL,
        delta=0.1,
        delays=jitter.samples(RATE, 0, N),
        history=12,
        sensors=sensor,
        u_max=limit,
        norm_max=0.7,
        disturbance=w,
    )
    assert np.sum(ref.logic_switch_count) >= 2 and np.all(ref.saturated_fraction > 0)
    assert ref.sigma is not None and ref.u_applied is not None
    for i in range(len(x0)):
        run = simulate(
            paper.SPACECRAFT,
            GAINS,
            x0[i],
            tau=0.12,
            rate=RATE,
            rule=Hysteretic(0.1),
            t_final=T_FINAL,
            actuator=ActuatorModel(limit, norm_max=0.7),
            disturbance=Disturbance(w),
            sensor=sensor,
            delay=jitter,
        )
        assert run.switch_indices.tolist() == ref.logic_switch_samples(i).tolist()
        assert run.saturated_fraction == ref.saturated_fraction[i]
        assert np.max(np.abs(ref.sigma[i] - run.sigma)) < 1e-12
        assert np.max(np.abs(ref.omega[i] - run.omega)) < 1e-12
        assert np.max(np.abs(ref.u_applied[i] - run.u)) < 1e-12


def test_per_sample_disturbance_changes_the_run_as_the_reference_says() -> None:
    """Without limits or noise (the specialised sample with a torque input) and with a plain array."""
    x0 = paper.INITIAL_STATE
    w = _torque(N, 2)
    ref = reference_loop(
        paper.SPACECRAFT.inertia, paper.GAIN, x0, rate=RATE, t_final=T_FINAL, delta=0.05, delays=50, disturbance=w
    )
    run = simulate(
        paper.SPACECRAFT, paper.GAIN, x0, tau=0.5, rate=RATE, rule=Hysteretic(0.05), t_final=T_FINAL, disturbance=w
    )
    free = simulate(paper.SPACECRAFT, paper.GAIN, x0, tau=0.5, rate=RATE, rule=Hysteretic(0.05), t_final=T_FINAL)
    assert ref.sigma is not None
    assert np.max(np.abs(ref.sigma[0] - run.sigma)) < 1e-12
    assert np.max(np.abs(free.sigma - run.sigma)) > 1e-6  # the torque acted


def test_constant_rows_equal_the_constant_disturbance_bit_for_bit() -> None:
    w = np.array([1e-2, -2e-2, 5e-3])
    common = dict(tau=0.5, rate=RATE, t_final=T_FINAL, rule=Hysteretic(0.0), keep_every=1)
    for actuator in (None, ActuatorModel([30.0, 30.0, 30.0])):
        rows = simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            paper.INITIAL_STATE,
            disturbance=np.tile(w, (N, 1)),
            actuator=actuator,
            **common,
        )
        constant = simulate(
            paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, disturbance=w, actuator=actuator, **common
        )
        for name in ("sigma", "omega", "u", "switch_indices", "logic", "sigma_c"):
            assert np.asarray(getattr(rows, name)).tobytes() == np.asarray(getattr(constant, name)).tobytes(), name
        assert rows.switch_count == 1


def test_per_sample_disturbance_refuses_bad_input() -> None:
    common = dict(tau=0.5, rate=RATE, t_final=T_FINAL, rule=Hysteretic(0.0))
    with pytest.raises(DimensionError, match=r"disturbance: expected shape \(n, 3\) = \(801, 3\)"):
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, disturbance=np.zeros((800, 3)), **common)
    with pytest.raises(DimensionError, match="torque"):
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, disturbance=np.zeros((N, 2)), **common)
    # simulate_batch and export take it too (tests/test_flight_batch_disturbance.py, test_export_flight.py),
    # and so does the predictor (tests/test_predictor_torque.py)


def _steps(t: np.ndarray) -> np.ndarray:
    """An elementwise w(t) (N m): a step at 2 s, a ramp and a parabola."""
    return np.column_stack((0.02 * (t > 2.0), -0.004 * t, 5e-4 * t * t))


def test_function_of_time_equals_its_rows_and_the_reference_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 97)  # evaluated slice by slice
    x0 = _tumbles(1, 2.0, 3)[0]
    times = np.arange(N) / RATE
    common = dict(tau=0.5, rate=RATE, t_final=T_FINAL, rule=Hysteretic(0.05), actuator=ActuatorModel([0.5, 0.5, 0.5]))
    function = simulate(paper.SPACECRAFT, GAINS, x0, disturbance=Disturbance(function=_steps), **common)
    rows = simulate(paper.SPACECRAFT, GAINS, x0, disturbance=Disturbance(_steps(times)), **common)
    for name in ("sigma", "omega", "u", "switch_indices", "logic", "sigma_c"):
        assert np.asarray(getattr(function, name)).tobytes() == np.asarray(getattr(rows, name)).tobytes(), name
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        GAINS,
        x0,
        rate=RATE,
        t_final=T_FINAL,
        delta=0.05,
        delays=50,
        u_max=[0.5, 0.5, 0.5],
        disturbance=_steps(times),
    )
    assert ref.sigma is not None and ref.u_applied is not None
    assert np.max(np.abs(ref.sigma[0] - function.sigma)) < 1e-12
    assert np.max(np.abs(ref.u_applied[0] - function.u)) < 1e-12
    assert function.switch_indices.tolist() == ref.logic_switch_samples(0).tolist()


def test_function_of_time_refuses_bad_input() -> None:
    common = dict(tau=0.5, rate=RATE, t_final=1.0, rule=Hysteretic(0.0))
    with pytest.raises(SpecificationError, match="function must be callable"):
        Disturbance(function=3.0)
    with pytest.raises(SpecificationError, match="not both"):
        Disturbance([0.0, 0.0, 0.0], function=_steps)
    with pytest.raises(SpecificationError, match="torque"):
        Disturbance()
    with pytest.raises(DimensionError, match="function"):
        simulate(
            paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, disturbance=Disturbance(function=lambda t: t), **common
        )
    with pytest.raises(SpecificationError, match="finite"):
        simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            paper.INITIAL_STATE,
            disturbance=Disturbance(function=lambda t: np.full((len(t), 3), np.nan)),
            **common,
        )
    # simulate_batch and the predictor take a function too (tests/test_predictor_torque.py)
