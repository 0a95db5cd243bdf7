"""What the controller saw, recorded in the results (the delayed measurement after the noise; with the predictor,
the prediction); the batch's switch indices; switch_count (the rule's switches) beside plant_set_changes."""

from __future__ import annotations

import numpy as np
import pytest

from mrpctl import OnCurrent, OnDelayed, OnPredicted, Predictor, data, mrp, paper, simulate, simulate_batch
from mrpctl.flight import Hysteretic, SensorModel, measurement_function

SC = paper.SPACECRAFT
X0 = paper.INITIAL_STATE
D = 50
COMMON = dict(tau=0.5, rate=100.0, t_final=6.0)


def test_the_flight_loop_records_the_delayed_noisy_measurement_it_read() -> None:
    sensor = SensorModel(attitude_noise=0.01, rate_noise=1e-3, gyro_bias=[1e-3, 0.0, -1e-3], seed=3)
    run = simulate(SC, paper.GAIN, X0, rule=Hysteretic(0.1), sensor=sensor, **COMMON)
    assert run.sigma_measured is not None and run.omega_measured is not None and run.command is not None
    noise = sensor.noise_rows(0, len(run.t))
    measure = measurement_function()
    for k in range(D, len(run.t), 37):
        x = np.concatenate((run.sigma[k - D], run.omega[k - D] / 4.0))
        m = np.asarray(measure(x, noise[k - D, :3], noise[k - D, 3:], sensor.gyro_bias)[0]).ravel()
        assert np.max(np.abs(run.sigma_measured[k] - m[:3])) <= 1e-15
        assert np.max(np.abs(run.omega_measured[k] - 4.0 * m[3:])) <= 1e-15
        assert np.linalg.norm(run.sigma_measured[k]) <= 1.0  # the short set, before the selection
    # the noise is in it, not in the true state
    assert np.max(np.abs(run.sigma_measured[D:] - run.sigma[:-D])) > 1e-3
    # the command is K on what the controller used
    used = np.hstack((run.sigma_c, run.omega_measured / 4.0))
    assert np.max(np.abs(run.command - used @ paper.GAIN.T)) <= 1e-12 * np.max(np.abs(run.command))


def test_the_predictor_records_its_measurement_and_prediction() -> None:
    run = simulate(SC, paper.GAIN, X0, rule=OnPredicted(), predictor=Predictor(model=SC), **COMMON)
    assert run.sigma_predicted is not None and run.omega_predicted is not None and run.sigma_measured is not None
    # an exact model predicts the present state (up to rounding); the measurement is the state d samples ago
    assert np.max(np.abs(run.sigma_predicted - run.sigma)) <= 1e-12
    assert np.max(np.abs(run.omega_predicted - run.omega)) <= 1e-12
    assert np.max(np.abs(mrp.short(run.sigma_measured[D:]) - run.sigma[:-D])) <= 1e-15
    assert np.array_equal(run.omega_measured[D:], run.omega[:-D])
    used = np.hstack((run.sigma_predicted, run.omega_predicted / 4.0))
    assert np.max(np.abs(run.command - used @ paper.GAIN.T)) <= 1e-12 * np.max(np.abs(run.command))
    # the predictor has no logic variable; the MRP its law used is the prediction's (tracking: the predicted error)
    assert run.logic is None and np.array_equal(run.sigma_c, run.sigma_predicted)


def test_records_survive_save_and_load(tmp_path) -> None:
    run = simulate(SC, paper.GAIN, X0, rule=OnPredicted(), predictor=Predictor(model=SC), **COMMON)
    back = data.load(data.save(run, tmp_path / "run.nc"))
    for name in ("sigma_measured", "omega_measured", "sigma_predicted", "omega_predicted", "command"):
        assert np.array_equal(getattr(back, name), getattr(run, name)), name


def test_a_batch_carries_the_switch_indices() -> None:
    x0 = np.stack([X0, 0.9 * X0, X0 * [1, 1, 1, -1, 1, 1]])
    rules = [OnCurrent(), OnDelayed(), Hysteretic(0.0)]
    lanes = simulate_batch(SC, paper.GAIN, x0, rule=rules, **COMMON)
    assert lanes.switch_indices is None
    kept = simulate_batch(SC, paper.GAIN, x0, rule=rules, switches=True, **COMMON)
    traced = simulate_batch(SC, paper.GAIN, x0, rule=rules, trajectories=True, **COMMON)
    assert kept.switch_indices is not None and traced.switch_indices is not None
    for i in range(3):
        alone = simulate(SC, paper.GAIN, x0[i], rule=rules[i], **COMMON)
        assert kept.switch_indices[i].tolist() == traced.switch_indices[i].tolist() == alone.switch_indices.tolist()
        assert len(kept.switch_indices[i]) == kept.switch_count[i]
    for name in ("switch_count", "plant_set_changes", "settling_time", "max_sigma", "peak_torque"):
        assert np.array_equal(getattr(kept, name), getattr(lanes, name), equal_nan=True), name
    with pytest.raises(Exception, match="switches must be True or False"):
        simulate_batch(SC, paper.GAIN, X0, rule=OnCurrent(), switches=1, **COMMON)


def test_switch_count_is_the_rules_and_plant_set_changes_the_plants() -> None:
    common = dict(tau=0.5, rate=1000.0, t_final=3.0)
    plant = simulate(SC, paper.GAIN, X0, rule=OnCurrent(), **common)
    assert plant.switch_count == plant.plant_set_changes == 1 and plant.switch_indices.tolist() == [444]
    flight = simulate(SC, paper.GAIN, X0, rule=Hysteretic(0.0), **common)
    assert flight.switch_count == 1 and flight.plant_set_changes == 1  # the logic switch one delay later
    held = simulate(SC, paper.GAIN, X0, rule=Hysteretic(0.5), **common)
    # hysteresis: no logic switch, the controller steers back through 180 deg: the plant crosses there and back
    assert held.switch_count == 0 and held.plant_set_changes == 2
    noisy = simulate(
        SC, paper.GAIN, X0, rule=Hysteretic(0.0), sensor=SensorModel(attitude_noise=0.01, seed=1), **common
    )
    assert noisy.switch_count > 10 and noisy.plant_set_changes <= 3  # noise switches the controller, not the plant
    batch = simulate_batch(SC, paper.GAIN, np.stack([X0, X0]), rule=[Hysteretic(0.5), OnCurrent()], **common)
    assert batch.switch_count.tolist() == [0, 1] and batch.plant_set_changes.tolist() == [2, 1]
