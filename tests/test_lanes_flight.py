"""The flight loop on the lane engine behind ``simulate_batch`` (issue 12 item 1 for issue 10's loop).

Each lane must give the scalar engine's bits (the scalar engine is itself checked against the
NumPy reference loop in tests/test_flight_engine.py); the flight summaries against the reference.
"""

from __future__ import annotations

import numpy as np
import pytest
from flight_reference import reference_loop
from lane_assertions import BATCH_FIELDS, assert_same_bits, scalar_batch
from lane_cases import dispersed

from mrpctl import OnCurrent, paper, simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, Saturation, SensorModel
from mrpctl.simulation import BatchResult, _batch

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="the lane engine needs a C compiler")

#: The metrics compared here: every batch metric but the plant-set changes (tests/test_lanes_structure.py
#: compares every array a batch keeps).
_FIELDS = tuple(name for name in BATCH_FIELDS if name != "plant_set_changes")
SENSOR = SensorModel(attitude_noise=0.02, rate_noise=1e-3, gyro_bias=[2e-3, 0.0, -1e-3], seed=3)


def _dispersed(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    return dispersed(count, seed, diverging_every=5)


def _both(*args, **kwargs) -> tuple[BatchResult, BatchResult]:
    return simulate_batch(*args, **kwargs), scalar_batch(*args, **kwargs)


def _assert_same_bits(lanes: BatchResult, scalar: BatchResult) -> None:
    assert_same_bits(lanes, scalar, fields=_FIELDS)


@pytest.mark.parametrize("mode", [None, Saturation.SCALE, Saturation.CLIP])
def test_every_option_on_a_dispersed_batch_is_the_scalar_engine_bit_for_bit(mode):
    """Noise, bias, jitter, disturbance, per-run delta; with limits (both modes) or without (the
    high-gain runs then diverge: lanes masked mid-batch)."""
    x0, gains = _dispersed(19, 7)  # 3 batches of W = 8, the last one padded
    rules = [Hysteretic(delta) for delta in np.linspace(0.0, 0.3, len(x0))]
    lanes, scalar = _both(
        paper.SPACECRAFT,
        gains,
        x0,
        tau=0.05,
        rate=100.0,
        rule=rules,
        t_final=15.0,
        actuator=None if mode is None else ActuatorModel([0.5, 0.4, 0.6], norm_max=0.7, mode=mode),
        disturbance=[0.01, 0.02, -0.01],
        sensor=SENSOR,
        delay=DelayModel.jitter(0.02, 0.05, seed=4),
        threads=2,
    )
    _assert_same_bits(lanes, scalar)
    # the batch covers what it must: diverging runs, switching runs, saturated runs
    assert (lanes.switch_count[~lanes.diverged] >= 3).sum() >= 5
    if mode is None:
        assert 2 <= lanes.diverged.sum() < len(x0) and np.all(lanes.saturated_fraction == 0.0)
    else:
        assert np.all(lanes.saturated_fraction > 0.0)


def test_plain_flight_runs_and_a_full_inertia_at_zero_delay_are_the_scalar_engine_bit_for_bit():
    x0, gains = _dispersed(9, 8)
    for spacecraft, tau in ((paper.SPACECRAFT, 0.05), (_full_inertia(), 0.0)):
        lanes, scalar = _both(spacecraft, gains, x0, tau=tau, rate=100.0, rule=Hysteretic(0.05), t_final=10.0)
        _assert_same_bits(lanes, scalar)
        assert np.all(lanes.saturated_fraction == 0.0)  # no limit: never saturated


def _full_inertia():
    from mrpctl.spacecraft import Spacecraft

    return Spacecraft(np.array([[140.0, 4.0, -2.0], [4.0, 100.0, 3.0], [-2.0, 3.0, 80.0]]))


def test_a_noise_slice_boundary_inside_the_horizon_changes_no_bit(monkeypatch):
    x0, gains = _dispersed(8, 9)
    kwargs = dict(tau=0.05, rate=100.0, rule=Hysteretic(0.1), t_final=12.0, sensor=SENSOR)
    whole = simulate_batch(paper.SPACECRAFT, gains, x0, **kwargs)
    monkeypatch.setattr(_batch, "slice_samples", lambda substeps: 97)  # lane slices of 97 samples
    sliced = simulate_batch(paper.SPACECRAFT, gains, x0, **kwargs)
    _assert_same_bits(whole, sliced)


def test_batch_saturation_and_peak_command_equal_the_reference_loop_and_simulate():
    x0, _ = _dispersed(4, 10)
    gains = 0.05 * paper.GAIN
    limit = np.array([0.5, 0.4, 0.6])
    common = dict(tau=0.05, rate=100.0, rule=Hysteretic(0.1), t_final=8.0, disturbance=[0.01, 0.02, -0.01])
    batch = simulate_batch(
        paper.SPACECRAFT, gains, x0, actuator=ActuatorModel(limit, norm_max=0.7), sensor=SENSOR, **common
    )
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        gains,
        x0,
        rate=100.0,
        t_final=8.0,
        delta=0.1,
        delays=5,
        sensors=SENSOR,
        u_max=limit,
        norm_max=0.7,
        disturbance=[0.01, 0.02, -0.01],
        trajectories=False,
    )
    assert batch.saturated_fraction.shape == (4,) and batch.peak_command.shape == (4, 4)
    assert np.array_equal(batch.saturated_fraction, ref.saturated_fraction)
    np.testing.assert_allclose(batch.peak_command[:, 0:3], ref.peak_command, rtol=1e-12)
    np.testing.assert_allclose(batch.peak_command[:, 3], ref.peak_command_norm, rtol=1e-12)
    for i in range(len(x0)):
        run = simulate(
            paper.SPACECRAFT,
            gains,
            x0[i],
            actuator=ActuatorModel(limit, norm_max=0.7),
            sensor=SENSOR,
            keep_every=None,
            **common,
        )
        assert run.saturated_fraction == batch.saturated_fraction[i]
        assert np.array_equal(run.peak_command, batch.peak_command[i])


def test_batches_without_flight_runs_have_no_flight_summaries_and_concatenation_keeps_them():
    x0, gains = _dispersed(3, 11)
    plain = simulate_batch(paper.SPACECRAFT, gains, x0, tau=0.05, rate=100.0, rule=OnCurrent(), t_final=2.0)
    assert plain.saturated_fraction is None and plain.peak_command is None
    flight = simulate_batch(paper.SPACECRAFT, gains, x0, tau=0.05, rate=100.0, rule=Hysteretic(0.0), t_final=2.0)
    both = BatchResult.concatenate([plain, flight])
    assert both.saturated_fraction is not None and both.peak_command is not None
    assert np.all(np.isnan(both.saturated_fraction[:3])) and np.array_equal(both.saturated_fraction[3:], [0, 0, 0])
    assert np.array_equal(both.peak_command[3:], flight.peak_command)


def test_the_lane_engine_refuses_flight_inputs_it_does_not_run():
    from mrpctl.engines import lanes as _vectorize

    engine = _vectorize.lane_engine(paper.SPACECRAFT, OnCurrent(), 5, 0.01, 1)
    x0, gains = _dispersed(2, 12)
    with pytest.raises(SpecificationError, match="flight sample"):
        _vectorize.closed_loop_batches(
            engine,
            x0,
            np.zeros(2),
            x0[:, :, None],
            gains,
            np.zeros((2, 2)),
            10,
            spacecraft=paper.SPACECRAFT,
            sensor=SENSOR,
        )
