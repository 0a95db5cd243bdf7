"""Wheel-cluster runs with their own models on the lane engine with own streams: each run's sensor (noise seed,
noise levels, gyro bias) and jitter seed drawn and scheduled by the lane driver (``lanes_own.c``), per-run gains,
δ and constant torques, two spacecraft inertias (one wheel library each).

Every run must equal the scalar engine's and [`simulate`][mrpctl.simulation.simulate]'s with its own models bit
for bit (the replay contract of a campaign), and a wheel campaign chunk with its own noise seeds is one
``simulate_batch`` call.
"""

from __future__ import annotations

import numpy as np
import pytest
from lane_assertions import assert_row_is_the_run, assert_same_bits, one_run, scalar_batch

from mrpctl import simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.campaign import simulation as campaign_simulation
from mrpctl.campaign.simulation import simulate_runs
from mrpctl.engines import lanes as lane_engines
from mrpctl.flight import DelayModel, Hysteretic, SensorModel
from mrpctl.model import gain_from_pd, state
from mrpctl.simulation import BatchResult, _batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="the lane engine needs a C compiler")

#: A 4-wheel pyramid with friction, null-space management and the gyroscopic term: its speed and torque limits act.
WHEELS = WheelCluster.pyramid(
    2e-4, 5e-3, 200.0, speeds=[10.0, -20.0, 30.0, 5.0], viscous=1e-7, coulomb=1e-5, null_gain=0.02, gyroscopic=True
)
CRAFTS = (Spacecraft(np.diag([0.2, 0.25, 0.15])), Spacecraft(np.diag([0.21, 0.24, 0.16])))
COUNT = 19  # 10 runs on the first inertia (two batches of W = 8), 9 on the second
COMMON = dict(tau=0.3, rate=10.0, t_final=40.0, wheels=WHEELS)
#: The batch metrics of a wheel run that its SimulationResult keeps too.
_SUMMARIES = ("switch_count", "settling_time", "diverged", "max_sigma", "saturated_fraction")
_WHEEL_FIELDS = ("peak_speed", "final_speeds", "torque_limited_time", "speed_limited_time", "peak_momentum")


def _case() -> dict:
    """A dispersed wheel batch: own gain, δ, constant torque, sensor (seed, levels, bias) and jitter seed per run,
    the runs alternating between two inertias; one run noiseless but biased, one with an ideal sensor, one with the
    constant delay among jittered ones."""
    rng = np.random.default_rng(17)
    crafts = [CRAFTS[i % 2] for i in range(COUNT)]
    gains = np.array(
        [
            gain_from_pd(craft, -rng.uniform(0.03, 0.05) * np.ones(3), -rng.uniform(0.3, 0.5) * np.ones(3))
            for craft in crafts
        ]
    )
    direction = rng.normal(size=(COUNT, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    sigma = direction * rng.uniform(0.85, 1.0, (COUNT, 1))  # near the shadow set, turning outward: some switch
    omega = direction * rng.uniform(0.1, 0.25, (COUNT, 1))
    sensors: list[SensorModel | None] = [
        SensorModel(
            attitude_noise=float(rng.uniform(0.0, 0.01)),
            rate_noise=float(rng.uniform(0.0, 1e-3)),
            gyro_bias=rng.normal(scale=1e-4, size=3),
            seed=int(rng.integers(0, 2**63)),
        )
        for _ in range(COUNT)
    ]
    sensors[3] = SensorModel(gyro_bias=[1e-4, 0.0, -1e-4])  # noiseless, biased
    sensors[12] = None  # an ideal sensor
    delays: list[DelayModel | None] = [
        DelayModel.jitter(0.1, 0.3, seed=int(rng.integers(0, 2**63))) for _ in range(COUNT)
    ]
    delays[5] = None  # the constant delay tau
    return dict(
        spacecraft=crafts,
        K=gains,
        x0=state(sigma, omega),
        rule=[Hysteretic(delta) for delta in np.linspace(0.0, 0.3, COUNT)],
        disturbance=[rng.normal(scale=2e-6, size=3) for _ in range(COUNT)],
        sensor=sensors,
        delay=delays,
    )


def _bits(value: object) -> bytes:
    return np.ascontiguousarray(np.asarray(value, dtype=float)).tobytes()


def _assert_same_bits(got: BatchResult, want: BatchResult, rows: slice | list[int] = slice(None)) -> None:
    assert_same_bits(got, want, rows)
    assert got.wheels is not None and want.wheels is not None
    picked = list(range(len(got.wheels)))[rows] if isinstance(rows, slice) else rows
    assert len(picked) == len(want.wheels)
    for i, theirs in zip(picked, want.wheels, strict=True):
        for name in _WHEEL_FIELDS:
            assert _bits(getattr(got.wheels[i], name)) == _bits(getattr(theirs, name)), (i, name)


def test_a_dispersed_wheel_batch_is_on_the_lanes_and_equals_each_run_alone_bit_for_bit(monkeypatch):
    case = _case()
    packed: list[tuple[int, bool, bool, bool]] = []  # the lane groups: runs, own streams, noise and schedule per lane
    pack = lane_engines.closed_loop_batches

    def spy(engine, x0, *args, **kwargs):
        packed.append(
            (len(x0), engine.own_streams, isinstance(kwargs["sensor"], list), isinstance(kwargs["delay"], list))
        )
        return pack(engine, x0, *args, **kwargs)

    monkeypatch.setattr(lane_engines, "closed_loop_batches", spy)
    on_two = simulate_batch(**case, **COMMON, threads=2)
    # one lane group per inertia (J is compiled in): every run on the lanes, each lane its own streams
    assert sorted(packed) == [(9, True, True, True), (10, True, True, True)]
    in_series = simulate_batch(**case, **COMMON, threads=1)
    _assert_same_bits(on_two, in_series)
    scalar = scalar_batch(**case, **COMMON, threads=2)
    _assert_same_bits(on_two, scalar)
    for i in range(COUNT):  # each run as simulate, its wheel metrics and its summaries
        run = simulate(**one_run(case, i), **COMMON)
        assert run.wheels is not None and on_two.wheels is not None
        for name in _WHEEL_FIELDS:
            assert _bits(getattr(on_two.wheels[i], name)) == _bits(getattr(run.wheels, name)), (i, name)
        assert_row_is_the_run(on_two, i, run, _SUMMARIES)
    for i in (3, 5, 12):  # the noiseless, the constant-delay and the ideal-sensor runs as one-run batches
        _assert_same_bits(on_two, simulate_batch(**one_run(case, i), **COMMON, threads=1), [i])
    # the batch covers what it must: switching runs, the wheels' limits acting; the streams matter
    assert (on_two.switch_count >= 1).sum() >= 5
    assert sum(float(np.max(record.torque_limited_time)) > 0.0 for record in on_two.wheels or ()) >= 10
    assert sum(float(np.max(record.speed_limited_time)) > 0.0 for record in on_two.wheels or ()) >= 3
    swapped = dict(case, sensor=case["sensor"][1:] + case["sensor"][:1], delay=case["delay"][1:] + case["delay"][:1])
    other = simulate_batch(**swapped, **COMMON, threads=2)
    assert not np.array_equal(other.max_sigma, on_two.max_sigma)


def test_a_sliced_horizon_changes_no_bit(monkeypatch):
    """Each lane's noise block and arrival ring carried across slices of 97 samples (slices end inside a block)."""
    case = _case()
    whole = simulate_batch(**case, **COMMON)
    monkeypatch.setattr(_batch, "slice_samples", lambda substeps: 97)
    _assert_same_bits(simulate_batch(**case, **COMMON), whole)


def test_per_run_delay_sequences_and_own_noise_on_the_wheel_lanes_equal_simulate(monkeypatch):
    """Given delay sequences per run (each lane's schedule from its own sequence, computed per slice) beside own
    noise and a run with the constant delay: on the wheel lanes with own streams, each run simulate's bit for bit."""
    case = _case()
    n = 401  # 40 s at 10 Hz
    rng = np.random.default_rng(2)
    sequences: list[DelayModel | None] = [
        DelayModel.sequence(rng.integers(1, 4, n) / 10.0, tau_min=0.1, tau_max=0.3) for _ in range(COUNT)
    ]
    sequences[7] = None
    picked = [0, 1, 4, 7, 9, 12]  # one inertia and the other, the constant delay, an ideal sensor
    given = {name: [value[i] for i in picked] for name, value in case.items()}
    given["delay"] = [sequences[i] for i in picked]
    packed: list[bool] = []
    pack = lane_engines.closed_loop_batches

    def spy(engine, x0, *args, **kwargs):
        packed.append(engine.own_streams)
        return pack(engine, x0, *args, **kwargs)

    monkeypatch.setattr(lane_engines, "closed_loop_batches", spy)
    batch = simulate_batch(**given, **COMMON, threads=2)
    assert packed == [True, True]
    assert batch.wheels is not None
    for row in range(len(picked)):
        run = simulate(**one_run(given, row), **COMMON)
        assert run.wheels is not None and run.delay_used is not None
        for name in _WHEEL_FIELDS:
            assert _bits(getattr(batch.wheels[row], name)) == _bits(getattr(run.wheels, name)), (row, name)
        assert _bits(batch.max_sigma[row]) == _bits(run.max_sigma)
        assert _bits(batch.saturated_fraction[row]) == _bits(run.saturated_fraction)
    assert len(set(np.asarray(batch.max_sigma).tolist())) == len(picked)


def test_a_wheel_campaign_chunk_with_own_noise_seeds_is_one_call_equal_to_each_run_alone(monkeypatch):
    """simulate_runs groups the wheel runs by their models' structure, as the flight loop's: a chunk whose runs have
    their own sensor seeds and jitter seeds is one simulate_batch call, each run its own call's numbers."""
    case = _case()
    inertia = np.array([CRAFTS[0].inertia] * COUNT)
    tau = np.full(COUNT, COMMON["tau"])
    sensors = [one if one is not None else SensorModel() for one in case["sensor"]]  # a campaign's: never None
    models = [
        {"actuator": None, "sensor": sensors[i], "delay": case["delay"][i], "disturbance": case["disturbance"][i]}
        for i in range(COUNT)
    ]
    options = dict(t_final=COMMON["t_final"], rate=COMMON["rate"], history="constant", substeps=1, wheels=WHEELS)
    calls: list[int] = []
    batch = campaign_simulation._batch

    def count(crafts, *args, **kwargs):
        calls.append(len(crafts))
        return batch(crafts, *args, **kwargs)

    monkeypatch.setattr(campaign_simulation, "_batch", count)
    together = simulate_runs(inertia, case["K"], case["x0"], tau, case["rule"], flight=models, **options)
    assert calls == [COUNT]  # one call for the chunk
    calls.clear()
    for i in range(COUNT):
        alone = simulate_runs(
            inertia[[i]], case["K"][[i]], case["x0"][[i]], tau[[i]], [case["rule"][i]], flight=[models[i]], **options
        )
        for name, values in alone.items():
            assert np.asarray(together[name][i]).tobytes() == np.asarray(values[0]).tobytes(), (i, name)
    assert calls == [1] * COUNT
    assert len({together["max_sigma"][i] for i in range(COUNT)}) == COUNT
    assert len({float(np.max(together["wheel_peak_speed"][i])) for i in range(COUNT)}) == COUNT
