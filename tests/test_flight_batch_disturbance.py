"""Per-sample disturbance torques in ``simulate_batch`` (issue 10): shared and per run, scalar and lane engines."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from flight_reference import _tumbles, reference_loop

from mrpctl import paper, simulate, simulate_batch
from mrpctl.engines import scalar as _engine
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, Disturbance, Hysteretic, SensorModel
from mrpctl.simulation import _batch_inputs

GAINS = 0.05 * paper.GAIN
RATE, T_FINAL, TAU = 100.0, 4.0, 0.05
N = 401
X0 = _tumbles(3, 3.0, 11)
ACTUATOR = ActuatorModel([0.5, 0.4, 0.6], norm_max=0.7)
SENSOR = SensorModel(attitude_noise=0.01, rate_noise=1e-3, seed=4)
COMMON: dict[str, Any] = dict(
    tau=TAU, rate=RATE, t_final=T_FINAL, rule=Hysteretic(0.1), actuator=ACTUATOR, sensor=SENSOR
)


def _rows(seed: int) -> np.ndarray:
    return 0.05 * np.random.default_rng(seed).standard_normal((N, 3))


def _gust(t: np.ndarray) -> np.ndarray:
    return np.stack((0.03 * np.sin(2.0 * t), 0.02 * np.cos(3.0 * t), 0.01 * np.ones_like(t)), axis=1)


def _same_run(a: Any, b: Any) -> None:
    for name in ("sigma", "omega", "u", "command", "sigma_c", "logic", "switch_indices"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    assert a.saturated_fraction == b.saturated_fraction
    assert a.peak_command.tobytes() == b.peak_command.tobytes()


def _same_metrics(batch: Any, runs: list[Any]) -> None:
    for i, run in enumerate(runs):
        assert batch.switch_count[i] == run.switch_count
        assert batch.max_sigma[i] == run.max_sigma and batch.peak_torque[i] == run.peak_torque
        assert batch.sign_flips[i].tolist() == run.sign_flips.tolist()
        assert batch.saturated_fraction[i] == run.saturated_fraction
        assert batch.peak_command[i].tobytes() == run.peak_command.tobytes()
        assert np.array_equal(
            batch.settling_time[i], np.nan if run.settling_time is None else run.settling_time, equal_nan=True
        )


@pytest.mark.parametrize("shared", ["rows", "function"])
def test_a_shared_per_sample_torque_equals_simulate_run_by_run(shared: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 97)  # the rows are streamed slice by slice
    torque: Any = _rows(1) if shared == "rows" else Disturbance(function=_gust)
    alone = [simulate(paper.SPACECRAFT, GAINS, x, disturbance=torque, **COMMON) for x in X0]
    plain = simulate(paper.SPACECRAFT, GAINS, X0[0], **COMMON)
    assert alone[0].u.tobytes() != plain.u.tobytes()  # the torque acts
    for threads in (1, 2):
        batch = simulate_batch(
            paper.SPACECRAFT, GAINS, X0, disturbance=torque, trajectories=True, threads=threads, **COMMON
        )
        assert batch.runs is not None
        for run, one in zip(batch.runs, alone, strict=True):
            _same_run(run, one)
        metrics = simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=torque, threads=threads, **COMMON)
        _same_metrics(metrics, alone)  # the lane engine, the rows streamed beside the noise


@pytest.mark.parametrize("shared", [True, False])
def test_the_lanes_take_the_torques(shared: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """Metrics-only batches with a per-sample torque (shared, or one per run) run on the lanes, not on the scalar
    engine."""
    runs: list[int] = []
    original = _engine.Engine.run

    def counted(self: Any, *args: Any, **kwargs: Any) -> Any:
        runs.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(_engine.Engine, "run", counted)
    torque: Any = _rows(2) if shared else [_rows(2), None, Disturbance(function=_gust)]
    batch = simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=torque, **COMMON)
    assert runs == [] and batch.saturated_fraction is not None


def test_the_lane_torque_equals_the_reference_loop() -> None:
    rows = _rows(3)
    ref = reference_loop(
        paper.SPACECRAFT.inertia,
        GAINS,
        X0,
        rate=RATE,
        t_final=T_FINAL,
        delta=0.1,
        delays=5,
        disturbance=rows,
        trajectories=False,
    )
    batch = simulate_batch(
        paper.SPACECRAFT, GAINS, X0, tau=TAU, rate=RATE, t_final=T_FINAL, rule=Hysteretic(0.1), disturbance=rows
    )
    assert batch.switch_count.tolist() == ref.logic_switch_count.tolist()
    assert batch.peak_command is not None
    np.testing.assert_allclose(batch.peak_command[:, 0:3], ref.peak_command, rtol=1e-12, atol=0)


def test_per_run_torques_equal_simulate_run_by_run(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 97)
    # 11 runs: two lane batches of W = 8 with per-lane torques (the second padded), constants and None
    items: list[Any] = [None, np.array([0.02, -0.01, 0.03]), _rows(4), Disturbance(function=_gust)]
    items += [_rows(20 + i) for i in range(7)]
    x0 = _tumbles(len(items), 3.0, 12)
    alone = [simulate(paper.SPACECRAFT, GAINS, x, disturbance=w, **COMMON) for x, w in zip(x0, items, strict=True)]
    serial = simulate_batch(paper.SPACECRAFT, GAINS, x0, disturbance=items, trajectories=True, threads=1, **COMMON)
    pooled = simulate_batch(paper.SPACECRAFT, GAINS, x0, disturbance=items, trajectories=True, threads=2, **COMMON)
    assert serial.runs is not None and pooled.runs is not None
    for a, b, one in zip(serial.runs, pooled.runs, alone, strict=True):
        _same_run(a, one)
        _same_run(b, one)
    for threads in (1, 2):
        _same_metrics(simulate_batch(paper.SPACECRAFT, GAINS, x0, disturbance=items, threads=threads, **COMMON), alone)


def test_a_runs_by_samples_array_is_read_through_views() -> None:
    torques = np.stack([_rows(5), _rows(6), _rows(7)])
    per_run = _batch_inputs.per_run_disturbances(torques, 3, N)
    assert per_run is not None
    for i, each in enumerate(per_run):
        assert each is not None and np.shares_memory(each.torque, torques[i]) and not each.torque.flags.writeable
    assert torques.flags.writeable  # the caller's array is left as it was
    alone = [simulate(paper.SPACECRAFT, GAINS, x, disturbance=torques[i], **COMMON) for i, x in enumerate(X0)]
    batch = simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=torques, trajectories=True, threads=2, **COMMON)
    assert batch.runs is not None
    for run, one in zip(batch.runs, alone, strict=True):
        _same_run(run, one)
    _same_metrics(simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=torques, threads=2, **COMMON), alone)


def test_a_function_is_evaluated_per_slice(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_engine, "SLICE_SAMPLES", 97)
    lengths: list[int] = []

    def gust(t: np.ndarray) -> np.ndarray:
        lengths.append(len(t))
        return _gust(t)

    for trajectories in (True, False):
        lengths.clear()
        simulate_batch(
            paper.SPACECRAFT, GAINS, X0, disturbance=Disturbance(function=gust), trajectories=trajectories, **COMMON
        )
        assert lengths and max(lengths) <= 97


def test_bad_batch_torques_are_refused_naming_the_parameter() -> None:
    with pytest.raises(DimensionError, match=r"disturbance: expected 1 or 3 entries"):
        simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=[None, _rows(1)], **COMMON)
    with pytest.raises(DimensionError, match=r"disturbance: a per-run per-sample torque has shape"):
        simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=np.zeros((3, N - 1, 3)), **COMMON)
    bad = np.zeros((3, N, 3))
    bad[1, 7, 2] = np.nan
    with pytest.raises(SpecificationError, match=r"disturbance\[1\] must be finite"):
        simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=bad, **COMMON)
    with pytest.raises(DimensionError, match=r"disturbance\[2\]: torque: expected shape"):
        simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=[None, None, np.array([1.0, 2.0])], **COMMON)
    with pytest.raises(DimensionError, match=r"disturbance: expected shape \(n, 3\) = \(401, 3\)"):
        simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=np.zeros((N + 1, 3)), **COMMON)
    # one run's rows of the wrong length name that run; a list of lists is one shared series, and says so
    with pytest.raises(DimensionError, match=r"disturbance\[1\]: expected shape \(n, 3\) = \(401, 3\)"):
        simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=[None, np.zeros((N - 1, 3)), None], **COMMON)
    with pytest.raises(DimensionError, match=r"a list of lists is one torque series shared by the runs"):
        simulate_batch(paper.SPACECRAFT, GAINS, X0, disturbance=[[1e-3, 0, 0], [0, 1e-3, 0], [0, 0, 1e-3]], **COMMON)
