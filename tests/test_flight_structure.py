"""The flight sample specialised by structure (issue 10, speed): the same bits as the full sample."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from mrpctl import paper, simulate, simulate_batch
from mrpctl.engines import scalar as _engine
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel
from mrpctl.loop.options import flight_constants, flight_structure
from mrpctl.simulation import _batch, _simulate

X0 = np.array(paper.INITIAL_STATE, dtype=float)
LIMITS = ActuatorModel([20.0, 25.0, 30.0], norm_max=35.0)
TORQUE = Disturbance([1e-2, -2e-2, 5e-3])
FULL = {"sensor": True, "limited": True, "disturbed": True}


def _bytes(result: Any) -> list[bytes]:
    arrays = [result.t, result.sigma, result.omega, result.u, result.switch_indices, result.sign_flips]
    arrays.append(np.asarray(result.peak_command, dtype=float))
    arrays.append(np.array([result.saturated_fraction, result.max_sigma, result.peak_torque], dtype=float))
    return [np.ascontiguousarray(a).tobytes() for a in arrays]  # tobytes: the sign of zero counts


def _full(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_simulate, "flight_structure", lambda options, sensor: dict(FULL))
    monkeypatch.setattr(_batch, "flight_structure", lambda options, sensor: dict(FULL))


CASES = [
    {},
    {"disturbance": TORQUE},
    {"disturbance": [0.0, 0.0, 0.0], "sensor": SensorModel()},
    {"actuator": LIMITS},
    {"actuator": ActuatorModel([20.0, 25.0, 30.0], mode=Saturation.CLIP), "disturbance": TORQUE},
    {"sensor": SensorModel(gyro_bias=[1e-4, -2e-4, 5e-5])},
    {"sensor": SensorModel(attitude_noise=0.01, rate_noise=1e-4, seed=3), "delay": DelayModel.jitter(0.4, 0.5, seed=2)},
]


@pytest.mark.parametrize("options", CASES, ids=range(len(CASES)))
def test_specialised_sample_equals_the_full_sample_bit_for_bit(
    options: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    kwargs = dict(tau=0.5, rate=200.0, t_final=6.0, rule=Hysteretic(0.0), **options)
    specialised = simulate(paper.SPACECRAFT, paper.GAIN, X0, **kwargs)
    with monkeypatch.context() as patch:
        _full(patch)
        full = simulate(paper.SPACECRAFT, paper.GAIN, X0, **kwargs)
    assert specialised.switch_count >= 1  # the paper case crosses: the rule acted
    assert _bytes(specialised) == _bytes(full)


def test_batch_of_specialised_samples_equals_the_full_sample(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(5)
    x0s = X0 + 0.01 * rng.standard_normal((5, 6))
    kwargs = dict(
        tau=0.5, rate=200.0, t_final=6.0, rule=Hysteretic(0.05), disturbance=TORQUE, keep_every=7, trajectories=True
    )
    specialised = simulate_batch(paper.SPACECRAFT, paper.GAIN, x0s, **kwargs)
    _full(monkeypatch)
    full = simulate_batch(paper.SPACECRAFT, paper.GAIN, x0s, **kwargs)
    assert specialised.runs is not None and full.runs is not None
    for a, b in zip(specialised.runs, full.runs, strict=True):
        assert _bytes(a) == _bytes(b)


def test_structure_of_the_constants() -> None:
    none = flight_structure(None, None)
    assert none == {"sensor": False, "limited": False, "disturbed": False}
    options, _ = flight_constants(LIMITS, TORQUE, SensorModel())
    assert flight_structure(options, SensorModel()) == {"sensor": False, "limited": True, "disturbed": True}
    options, _ = flight_constants(ActuatorModel([1e300] * 3), None, None)
    assert flight_structure(options, None)["limited"]  # a finite limit, however large
    noisy = SensorModel(rate_noise=1e-4)
    options, _ = flight_constants(None, None, noisy)
    assert flight_structure(options, noisy) == {"sensor": True, "limited": False, "disturbed": False}


def test_specialised_sample_is_smaller() -> None:
    period = 1.0 / 200.0
    full = _engine.engine(paper.SPACECRAFT, Hysteretic(0.0), 100, period, 1, **FULL)
    ideal = _engine.engine(
        paper.SPACECRAFT, Hysteretic(0.0), 100, period, 1, sensor=False, limited=False, disturbed=False
    )
    assert ideal is not full
    assert "noise" in full.sample.name_in() and "noise" not in ideal.sample.name_in()
    assert ideal.sample.n_instructions() < 0.9 * full.sample.n_instructions()
