"""Per-run flight models in one ``simulate_batch`` call: each run's own sensor (noise seed, noise levels, gyro bias),
its own jitter sequence, actuator limits, inertia and disturbance, on the lane engine (each lane streamed its own
run's noise rows and newest-arrived schedule) and on the scalar path.

Every run must equal [`simulate`][mrpctl.simulation.simulate] (and a one-run ``simulate_batch`` call, what a
campaign made before) with its own models bit for bit: the replay contract of a campaign.
"""

from __future__ import annotations

import numpy as np
import pytest
from lane_assertions import assert_row_is_the_run, assert_same_bits, one_run, scalar_batch
from lane_cases import dispersed

from mrpctl import simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.engines import lanes as lane_engines
from mrpctl.engines.lane_streams import lane_newest_arrived
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, Saturation, SensorModel, newest_arrived
from mrpctl.simulation import _batch
from mrpctl.spacecraft import Spacecraft

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="the lane engine needs a C compiler")

COUNT = 19  # three batches of W = 8, the last one padded


def _case(mode: Saturation | None = Saturation.SCALE) -> dict:
    """A fully dispersed batch: own inertia, gain, δ, disturbance, sensor (seed, levels, bias), jitter seed and
    u_max per run; a few runs noiseless, one with a constant delay (None: no jitter) among jittered ones."""
    x0, gains = dispersed(COUNT, 11, diverging_every=7)
    rng = np.random.default_rng(5)
    crafts = [Spacecraft(np.diag(rng.uniform(90.0, 150.0, 3))) for _ in range(COUNT)]
    sensors: list[SensorModel | None] = [
        SensorModel(
            attitude_noise=float(rng.uniform(0.0, 0.03)),
            rate_noise=float(rng.uniform(0.0, 2e-3)),
            gyro_bias=rng.normal(scale=1e-3, size=3),
            seed=int(rng.integers(0, 2**63)),
        )
        for _ in range(COUNT)
    ]
    sensors[3] = SensorModel(gyro_bias=[1e-3, 0.0, 0.0])  # noiseless, biased
    sensors[12] = None  # an ideal sensor
    delays: list[DelayModel | None] = [
        DelayModel.jitter(0.02, 0.05, seed=int(rng.integers(0, 2**63))) for _ in range(COUNT)
    ]
    delays[5] = None  # the constant delay tau
    actuators: list[ActuatorModel | None] = [
        None if mode is None else ActuatorModel(rng.uniform(0.3, 0.8, 3), norm_max=0.9, mode=mode) for _ in range(COUNT)
    ]
    return dict(
        spacecraft=crafts,
        K=gains,
        x0=x0,
        rule=[Hysteretic(delta) for delta in np.linspace(0.0, 0.3, COUNT)],
        disturbance=[rng.normal(scale=0.01, size=3) for _ in range(COUNT)],
        sensor=sensors,
        delay=delays,
        actuator=actuators,
    )


COMMON = dict(tau=0.05, rate=100.0, t_final=12.0)


@pytest.mark.parametrize("mode", [None, Saturation.CLIP])
def test_a_fully_dispersed_batch_equals_each_run_alone_bit_for_bit(mode, monkeypatch):
    case = _case(mode)
    packed: list[tuple[int, bool, bool]] = []  # the lane groups: runs, noise per lane, schedule per lane
    pack = lane_engines.closed_loop_batches

    def spy(engine, x0, *args, **kwargs):
        packed.append((len(x0), isinstance(kwargs["sensor"], list), isinstance(kwargs["delay"], list)))
        return pack(engine, x0, *args, **kwargs)

    monkeypatch.setattr(lane_engines, "closed_loop_batches", spy)
    on_two = simulate_batch(**case, **COMMON, threads=2)
    assert packed == [(COUNT, True, True)]  # one lane group: every run on the lanes, each lane its own streams
    in_series = simulate_batch(**case, **COMMON, threads=1)
    assert_same_bits(on_two, in_series)
    scalar = scalar_batch(**case, **COMMON, threads=2)
    assert_same_bits(on_two, scalar)
    for i in range(COUNT):  # each run as a call of its own (what a campaign made) and as simulate
        alone = simulate_batch(**one_run(case, i), **COMMON, threads=1)
        assert_same_bits(on_two, alone, [i])
        run = simulate(**one_run(case, i), **COMMON)
        assert_row_is_the_run(on_two, i, run)
    # the batch covers what it must: switching, diverging and (with limits) saturated runs; the streams matter
    assert (on_two.switch_count[~on_two.diverged] >= 2).sum() >= 5
    if mode is None:
        assert on_two.diverged.sum() >= 2
    else:
        assert np.all(on_two.saturated_fraction > 0.0)
    swapped = dict(case, sensor=case["sensor"][1:] + case["sensor"][:1], delay=case["delay"][1:] + case["delay"][:1])
    other = simulate_batch(**swapped, **COMMON, threads=2)
    assert not np.array_equal(other.max_sigma, on_two.max_sigma)


def test_per_run_models_on_a_sliced_horizon_and_a_shared_model_list_change_no_bit(monkeypatch):
    case = _case()
    whole = simulate_batch(**case, **COMMON)
    monkeypatch.setattr(_batch, "slice_samples", lambda substeps: 97)  # noise rows and schedules slice by slice
    sliced = simulate_batch(**case, **COMMON)
    assert_same_bits(whole, sliced)
    # a list of one model is that model shared (the lanes stream it once per batch)
    shared = dict(case, sensor=[case["sensor"][0]], delay=[case["delay"][0]])
    listed = simulate_batch(**shared, **COMMON)
    given = simulate_batch(**dict(shared, sensor=case["sensor"][0], delay=case["delay"][0]), **COMMON)
    assert_same_bits(listed, given)


def test_per_lane_schedules_are_each_runs_newest_arrived_measurements():
    """The driver's per-lane delayed input against the schedule of ``newest_arrived`` written independently: a lane
    whose j*(k) comes from the history (k < d) and from the ring, two different jitter sequences side by side."""
    rate, d, n = 100.0, 5, 40
    models = [DelayModel.jitter(0.01, 0.05, seed=1), DelayModel.jitter(0.01, 0.05, seed=2), None]
    runs = np.array([0, 1, 2, 0])
    got = lane_newest_arrived(models, rate, d, 0, n, np.full(4, -1 - d), runs)
    for lane, run in enumerate(runs):
        model = models[run]
        want = np.arange(n) - d if model is None else newest_arrived(model.samples(rate, 0, n), history=d)[0]
        assert np.array_equal(got[:, lane], want), lane
    assert not np.array_equal(got[:, 0], got[:, 1])


def test_per_run_models_alone_give_the_number_of_runs():
    """One initial state, gain and rule with N sensors and N delay models: N runs, each its own models."""
    case = _case()
    given = dict(case, x0=case["x0"][1], K=case["K"][1], spacecraft=case["spacecraft"][1], rule=case["rule"][1])
    batch = simulate_batch(**given, **COMMON)
    assert len(batch.max_sigma) == COUNT
    for i in (0, 7):
        own = {name: case[name][i] for name in ("sensor", "delay", "actuator", "disturbance")}
        assert_same_bits(batch, simulate_batch(**dict(given, **own), **COMMON), [i])
    assert not np.array_equal(batch.max_sigma[0], batch.max_sigma[7])


def test_per_run_models_are_checked():
    case = _case()
    with pytest.raises(DimensionError, match="sensor: expected 1 or 19 entries"):
        simulate_batch(**dict(case, sensor=case["sensor"][:3]), **COMMON)
    with pytest.raises(SpecificationError, match=r"delay\[2\] must be a mrpctl.flight.DelayModel"):
        simulate_batch(**dict(case, delay=[None, None, 0.05] + [None] * 16), **COMMON)
    mixed = [ActuatorModel([1.0] * 3, mode=Saturation.CLIP), ActuatorModel([1.0] * 3)] * 9 + [None]
    with pytest.raises(SpecificationError, match="share the saturation mode"):
        simulate_batch(**dict(case, actuator=mixed), **COMMON)
    with pytest.raises(SpecificationError, match=r"tau must equal delay\.tau_max"):
        late = [DelayModel.jitter(0.02, 0.04, seed=1), *case["delay"][1:]]
        simulate_batch(**dict(case, delay=late), **COMMON)


def test_per_lane_streams_are_in_the_memory_budget(monkeypatch):
    """The per-lane noise rows and schedules of a slice per worker are estimated up front: a limit that the shared
    models' batch fits in refuses the per-run models' batch before anything runs."""
    case = _case()
    long = dict(tau=0.05, rate=1000.0, t_final=20.0, threads=2)
    shared = dict(case, sensor=case["sensor"][0], delay=case["delay"][0])
    estimates: list[float] = []
    check = _batch.check_memory

    def record(estimate, limit, **kwargs):
        estimates.append(estimate)
        return check(estimate, limit, **kwargs)

    monkeypatch.setattr(_batch, "check_memory", record)
    simulate_batch(**shared, **long)
    streams = _batch.lane_stream_bytes(20001, 50, 1, 2, noise=True, jitter=True)
    # per worker: the noise block of 64 rows of 8 lanes and one lane's, the keys; the jitter state and a slice's
    # per-lane schedule with its checks and one run's arrival arrays
    assert streams == 8 * 2 * (64 * 6 * 9 + 4 * 8 + 54 * 8 + 3 * 8 * 20001 + 5 * 20051)
    limit = max(estimates) + streams / 2
    simulate_batch(**shared, **long, memory_limit=limit)
    ran = []
    monkeypatch.setattr(lane_engines, "closed_loop_batches", lambda *args, **kwargs: ran.append(1))
    with pytest.raises(SpecificationError, match="memory_limit"):
        simulate_batch(**case, **long, memory_limit=limit)
    assert not ran


def _rotating(n: int, rate: float, spin: float, axis: tuple[float, float, float]) -> np.ndarray:
    """Reference rows (σ_R/N, ω_R/N, ω̇_R/N) of a frame spinning at ``spin`` rad/s about a fixed axis (|σ| <= 1)."""
    e = np.asarray(axis, float) / np.linalg.norm(axis)
    angle = np.mod(spin * np.arange(n) / rate + np.pi, 2.0 * np.pi) - np.pi  # the short set: |angle| <= π
    rows = np.zeros((n, 9))
    rows[:, 0:3] = np.tan(angle / 4.0)[:, None] * e
    rows[:, 3:6] = spin * e
    return rows


@pytest.mark.parametrize("per_run_reference", [False, True])
def test_per_run_sequences_and_tracking_with_own_noise_equal_each_run_alone(per_run_reference, monkeypatch):
    """Given delay sequences per run (each lane's schedule from NumPy beside its own noise drawn by the driver), and
    a tracked reference (shared, or one per run) beside the runs' own sensors: each run as its own call."""
    case = _case()
    rate, n = 100.0, 1201
    rng = np.random.default_rng(9)
    sequences = [DelayModel.sequence(rng.integers(2, 6, n) / rate, tau_min=0.02, tau_max=0.05) for _ in range(COUNT)]
    sequences[4] = None
    references: object = [_rotating(n, rate, spin, (1.0, i, 0.5)) for i, spin in enumerate(np.linspace(0.01, 0.2, 19))]
    if not per_run_reference:
        references = references[0]  # type: ignore[index]
    given = dict(case, delay=sequences)
    packed: list[tuple[int, bool]] = []
    pack = lane_engines.closed_loop_batches

    def spy(engine, x0, *args, **kwargs):
        packed.append((len(x0), engine.own_streams))
        return pack(engine, x0, *args, **kwargs)

    for extra in ({}, {"reference": references}):
        monkeypatch.setattr(lane_engines, "closed_loop_batches", spy)
        batch = simulate_batch(**given, **extra, **COMMON, threads=2)
        monkeypatch.setattr(lane_engines, "closed_loop_batches", pack)
        assert packed.pop() == (COUNT, True) and not packed  # every run on one own-streams lane group
        for i in range(COUNT):
            one = {"reference": references[i] if per_run_reference else references} if extra else {}  # type: ignore[index]
            alone = simulate_batch(**one_run(given, i), **one, **COMMON, threads=1)
            assert_same_bits(batch, alone, [i])


def test_per_run_jitter_without_a_sensor_equals_each_run_alone():
    """Each lane's own jitter on an engine without a noise input (no sensor: the driver draws no noise)."""
    case = dict(_case(), sensor=None)
    batch = simulate_batch(**case, **COMMON, threads=2)
    for i in range(COUNT):
        assert_same_bits(batch, simulate_batch(**one_run(case, i), **COMMON, threads=1), [i])
    engines = [engine for key, engine in lane_engines._ENGINES.items() if "own streams" in key]
    assert any(engine.own_noise is None for engine in engines)
