"""The commanded torque u_c recorded per sample (issue 10): against the NumPy reference loop."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from flight_reference import _tumbles, reference_loop

from mrpctl import OnCurrent, data, paper, simulate, simulate_batch
from mrpctl.flight import ActuatorModel, Hysteretic, Saturation, SensorModel

GAINS = 0.05 * paper.GAIN
LIMIT = np.array([0.5, 0.4, 0.6])
NORM = 0.7
W = np.array([0.01, 0.02, -0.01])


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


@pytest.mark.parametrize("mode", [Saturation.SCALE, Saturation.CLIP])
def test_command_equals_the_reference_loop_and_bounds_the_applied_torque(mode: Saturation) -> None:
    x0 = _tumbles(3, 4.0, 5)
    sensor = SensorModel(attitude_noise=0.02, rate_noise=1e-3, gyro_bias=[2e-3, 0.0, -1e-3], seed=3)
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        GAINS,
        x0,
        rate=100.0,
        t_final=5.0,
        delta=0.1,
        delays=5,
        sensors=sensor,
        u_max=LIMIT,
        norm_max=NORM,
        clip=mode is Saturation.CLIP,
        disturbance=W,
    )
    assert ref.u_command is not None and ref.saturated is not None
    saturated_somewhere = 0
    for i in range(len(x0)):
        run = simulate(
            paper.SPACECRAFT,
            GAINS,
            x0[i],
            tau=0.05,
            rate=100.0,
            rule=Hysteretic(0.1),
            t_final=5.0,
            actuator=ActuatorModel(LIMIT, norm_max=NORM, mode=mode),
            disturbance=W,
            sensor=sensor,
        )
        assert run.command is not None and run.command.shape == run.u.shape and not run.command.flags.writeable
        assert _relative(run.command, ref.u_command[i]) < 1e-12
        command, u = run.command, run.u
        over = (np.abs(command) > LIMIT).any(axis=1) | (np.linalg.norm(command, axis=1) > NORM)
        assert over.tolist() == ref.saturated[i].tolist()  # no sample of these runs sits on a limit
        saturated_somewhere += int(over.sum())
        # where no limit acts the applied torque is the command, bit for bit
        assert u[~over].tobytes() == command[~over].tobytes()
        # where one acts: |u_i| <= u_max,i, |u| <= u_norm (rounding), and |u| <= |u_c|
        assert np.all(np.abs(u[over]) <= LIMIT)
        assert np.all(np.linalg.norm(u[over], axis=1) <= NORM * (1 + 1e-15))
        assert np.all(np.linalg.norm(u[over], axis=1) <= np.linalg.norm(command[over], axis=1))
        peak = np.hstack((np.max(np.abs(command), axis=0), np.max(np.linalg.norm(command, axis=1))))
        assert run.peak_command is not None
        assert _relative(peak, run.peak_command) < 1e-15  # the summary is the max of the records
    assert saturated_somewhere > 50


def test_command_is_the_applied_torque_without_limits_and_decimates_like_u() -> None:
    x0 = _tumbles(2, 2.0, 7)
    common: dict[str, Any] = dict(tau=0.05, rate=100.0, t_final=4.0, rule=Hysteretic(0.1), disturbance=W)
    for i in range(len(x0)):
        every = simulate(paper.SPACECRAFT, GAINS, x0[i], **common)
        assert every.command is not None and every.command.tobytes() == every.u.tobytes()
        third = simulate(paper.SPACECRAFT, GAINS, x0[i], keep_every=3, **common)
        assert third.command is not None and third.command.tobytes() == every.command[::3].tobytes()
    batch = simulate_batch(
        paper.SPACECRAFT,
        GAINS,
        x0,
        actuator=ActuatorModel(LIMIT),
        trajectories=True,
        keep_every=2,
        threads=2,
        **common,
    )
    assert batch.runs is not None
    for i, run in enumerate(batch.runs):
        alone = simulate(paper.SPACECRAFT, GAINS, x0[i], actuator=ActuatorModel(LIMIT), keep_every=2, **common)
        assert run.command is not None and alone.command is not None
        assert run.command.tobytes() == alone.command.tobytes()
    metrics_only = simulate(paper.SPACECRAFT, GAINS, x0[0], keep_every=None, **common)
    assert metrics_only.command is None


def test_the_records_survive_save_and_load(tmp_path: Path) -> None:
    run = simulate(
        paper.SPACECRAFT,
        GAINS,
        _tumbles(1, 3.0, 2)[0],
        tau=0.05,
        rate=100.0,
        t_final=3.0,
        rule=Hysteretic(0.1),
        actuator=ActuatorModel(LIMIT),
        keep_every=2,
    )
    back = data.load(data.save(run, tmp_path / "run.nc"))
    for name in ("logic", "sigma_c", "delay_used", "command"):
        value, loaded = getattr(run, name), getattr(back, name)
        assert value is not None and loaded is not None and not loaded.flags.writeable
        assert loaded.dtype == value.dtype and loaded.tobytes() == value.tobytes(), name
    other = simulate(paper.SPACECRAFT, GAINS, paper.INITIAL_STATE, tau=0.05, rate=100.0, t_final=1.0, rule=OnCurrent())
    plain = data.load(data.save(other, tmp_path / "plain.nc"))
    assert plain.command is None and plain.logic is None
    frame = run.to_pandas()
    assert run.command is not None and run.logic is not None and run.delay_used is not None
    assert frame["u_c2"].to_numpy().tobytes() == run.command[:, 1].tobytes()
    assert frame["logic"].to_numpy().tolist() == run.logic.tolist()
    assert frame["delay_used"].to_numpy().tolist() == run.delay_used.tolist()
    assert "u_c1" not in other.to_pandas().columns
