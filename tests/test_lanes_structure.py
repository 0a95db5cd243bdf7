"""The lane engine specialised by structure, as the scalar engine is (issue 10 leftover).

A lane batch compiles the flight sample of the union of its runs' structures
(:func:`mrpctl.loop.options.flight_structure`: sensor / limited / disturbed); each lane must
give the scalar engine's bits, and the scalar engine of each run is specialised to that run alone
(so a union engine is checked against narrower ones). The scalar engine is itself checked against
the NumPy reference loop in tests/test_flight_engine.py.
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest
from lane_cases import dispersed

from mrpctl import paper, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.engines import lanes as _vectorize
from mrpctl.engines.scalar import engine
from mrpctl.errors import SpecificationError
from mrpctl.flight import FLIGHT_MEMORY_SIZE, ActuatorModel, Disturbance, Hysteretic, SensorModel
from mrpctl.loop.options import NO_FLIGHT_OPTIONS, flight_memory, flight_structure
from mrpctl.simulation import BatchResult, _batch

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="the lane engine needs a C compiler")

RATE = 100.0
TAU = 0.05  # d = 5
T_FINAL = 3.0
NOISY = SensorModel(attitude_noise=0.02, rate_noise=1e-3, seed=5)
BIASED = SensorModel(gyro_bias=[2e-3, 0.0, -1e-3])
ACTUATOR = ActuatorModel([0.5, 0.4, 0.6], norm_max=0.7)
TORQUE = [0.01, 0.02, -0.01]


def _dispersed(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    return dispersed(count, seed, diverging_every=4)


def _arrays(batch: BatchResult) -> dict[str, np.ndarray]:
    """Every array the batch result keeps (metrics, flight summaries, inputs)."""
    found = {}
    for field in dataclasses.fields(batch):
        value = getattr(batch, field.name)
        if isinstance(value, np.ndarray):
            found[field.name] = value
    return found


def _assert_same_bits(lanes: BatchResult, scalar: BatchResult) -> None:
    got, want = _arrays(lanes), _arrays(scalar)
    assert set(got) == set(want)
    assert {"switch_count", "max_sigma", "peak_torque", "saturated_fraction", "peak_command"} <= set(got)
    for name, value in want.items():
        assert got[name].shape == value.shape, name
        assert got[name].dtype == value.dtype, name
        assert np.array_equal(
            np.ascontiguousarray(got[name]).view(np.uint8), np.ascontiguousarray(value).view(np.uint8)
        ), name


def _both(monkeypatch: pytest.MonkeyPatch, *args, **kwargs) -> tuple[BatchResult, BatchResult, list]:
    """The batch on the lane engine (recording the lane engines it asked for), then on the scalar engine."""
    built: list = []
    original = _vectorize.lane_engine

    def spy(*a, **k):
        found = original(*a, **k)
        built.append(found)
        return found

    with monkeypatch.context() as patch:
        patch.setattr(_vectorize, "lane_engine", spy)
        lanes = simulate_batch(*args, **kwargs)
    with monkeypatch.context() as patch:
        patch.setattr(_batch, "_LANES", False)
        scalar = simulate_batch(*args, **kwargs)
    return lanes, scalar, built


_STRUCTURES = list(itertools.product((None, NOISY), (None, ACTUATOR), (None, TORQUE)))


@pytest.mark.parametrize(("sensor", "actuator", "disturbance"), _STRUCTURES)
def test_each_structure_is_the_scalar_engine_bit_for_bit(monkeypatch, sensor, actuator, disturbance):
    """Ideal / noisy sensor x limited / unlimited x disturbed / free: one lane engine of exactly that
    structure (its ports say so), every metric and kept array the scalar engine's."""
    x0, gains = _dispersed(9, 11)  # 2 batches of W = 8, the second padded
    rules = [Hysteretic(delta) for delta in np.linspace(0.0, 0.3, len(x0))]
    lanes, scalar, built = _both(
        monkeypatch,
        paper.SPACECRAFT,
        gains,
        x0,
        tau=TAU,
        rate=RATE,
        rule=rules,
        t_final=T_FINAL,
        actuator=actuator,
        disturbance=disturbance,
        sensor=sensor,
        threads=2,
    )
    _assert_same_bits(lanes, scalar)
    want = {"sensor": sensor is not None, "limited": actuator is not None, "disturbed": disturbance is not None}
    assert len(built) == 1 and built[0].structure == want
    name = built[0].library.name
    assert ("_ideal" in name) != want["sensor"] and ("_unlimited" in name) != want["limited"]
    assert ("_free" in name) != want["disturbed"]
    assert ("noise" in built[0].streamed) == want["sensor"]  # no noise stream for an ideal sensor
    assert ("flight" in built[0].constants) and "x_delayed" not in built[0].constants
    assert (lanes.switch_count[~lanes.diverged] >= 1).any()
    if actuator is not None:  # the high-gain runs saturate
        assert np.all(lanes.saturated_fraction > 0.0)
    else:  # the high-gain runs diverge: lanes masked mid-batch
        assert lanes.diverged.any() and not lanes.diverged.all()
        assert np.all(lanes.saturated_fraction == 0.0)


def test_a_bias_alone_needs_the_sensor_and_gets_it(monkeypatch):
    x0, gains = _dispersed(5, 12)
    lanes, scalar, built = _both(
        monkeypatch,
        paper.SPACECRAFT,
        gains,
        x0,
        tau=TAU,
        rate=RATE,
        rule=Hysteretic(0.1),
        t_final=T_FINAL,
        sensor=BIASED,
    )
    _assert_same_bits(lanes, scalar)
    assert built[0].structure == {"sensor": True, "limited": False, "disturbed": False}
    assert "noise" in built[0].streamed  # the zero noise rows, as the scalar engine has


def test_runs_that_differ_in_structure_share_the_union_engine(monkeypatch):
    """Per-run disturbances: free runs (None, a zero torque) beside disturbed ones; one lane engine,
    disturbed; each run equals its own scalar engine (specialised to that run: free or disturbed)."""
    x0, gains = _dispersed(10, 13)
    per_run = [None, TORQUE, Disturbance([0.0, 0.0, 0.0]), None, [0.0, -0.02, 0.01]] * 2
    per_run[1] = Disturbance(TORQUE)
    lanes, scalar, built = _both(
        monkeypatch,
        paper.SPACECRAFT,
        gains,
        x0,
        tau=TAU,
        rate=RATE,
        rule=Hysteretic(0.05),
        t_final=T_FINAL,
        disturbance=per_run,
        threads=2,
    )
    _assert_same_bits(lanes, scalar)
    assert len(built) == 1 and built[0].structure == {"sensor": False, "limited": False, "disturbed": True}
    assert "_free" not in built[0].library.name and "_ideal" in built[0].library.name
    # and a batch whose runs are all free gets the free engine
    free, scalar_free, built = _both(
        monkeypatch, paper.SPACECRAFT, gains, x0, tau=TAU, rate=RATE, rule=Hysteretic(0.05), t_final=T_FINAL,
        disturbance=[None, Disturbance([0.0, 0.0, 0.0])] * 5,
    )  # fmt: skip
    _assert_same_bits(free, scalar_free)
    assert built[0].structure == {"sensor": False, "limited": False, "disturbed": False}
    same = [i for i, w in enumerate(per_run) if w is None]  # the free runs of the mixed batch: the same numbers
    assert np.array_equal(free.max_sigma[same], lanes.max_sigma[same])


@pytest.mark.parametrize("per_lane", [False, True])
def test_a_per_sample_torque_without_a_sensor_streams_the_torque_alone(monkeypatch, per_lane):
    x0, gains = _dispersed(9, 14)
    n = round(T_FINAL * RATE) + 1
    rows = 0.02 * np.sin(np.arange(n)[:, None] * np.array([0.01, 0.02, 0.03]))
    disturbance = [Disturbance(rows * (1 + i)) for i in range(len(x0))] if per_lane else Disturbance(rows)
    lanes, scalar, built = _both(
        monkeypatch, paper.SPACECRAFT, gains, x0, tau=TAU, rate=RATE, rule=Hysteretic(0.1), t_final=T_FINAL,
        disturbance=disturbance, actuator=ACTUATOR,
    )  # fmt: skip
    _assert_same_bits(lanes, scalar)
    engine_ = built[0]
    assert engine_.structure == {"sensor": False, "limited": True, "disturbed": True}
    if per_lane:
        assert not engine_.streamed and set(engine_.lane_streamed) == {"torque"}
        assert engine_.stream_size == 3 * engine_.width
    else:
        assert set(engine_.streamed) == {"torque"} and engine_.stream_size == 3


def test_per_run_rows_of_every_kind_in_one_batch_equal_each_run_s_own_scalar_engine():
    """(N, 10) flight constants mixing a limit, a torque and a gyro bias per run: the union engine
    (all three) gives each run the bits of the scalar engine of that run's own structure, the
    narrowest one (an ideal, unlimited, free run on the ideal/unlimited/free sample)."""
    x0, gains = _dispersed(8, 15)
    rows = np.tile(NO_FLIGHT_OPTIONS, (len(x0), 1))
    rows[1, 0:4] = [0.5, 0.4, 0.6, 0.7]  # limited
    rows[2, 4:7] = TORQUE  # disturbed
    rows[3, 7:10] = [2e-3, 0.0, -1e-3]  # a bias: the sensor
    rows[4, 0:4], rows[4, 4:7], rows[4, 7:10] = rows[1, 0:4], rows[2, 4:7], rows[3, 7:10]  # all three
    union = flight_structure(rows, None)
    assert union == {"sensor": True, "limited": True, "disturbed": True}
    assert flight_structure(rows[0], None) == {"sensor": False, "limited": False, "disturbed": False}
    d, n = 5, 300
    lanes = _vectorize.lane_engine(paper.SPACECRAFT, Hysteretic(), d, 1.0 / RATE, 1, **union)
    rules = [Hysteretic(0.1)] * len(x0)
    history = x0[:, :, None]  # (N, 6, 1): a constant history
    memory0 = np.array([flight_memory(x0[i], x0[i][None, :], d) for i in range(len(x0))])
    packed = _vectorize.closed_loop_batches(
        lanes,
        x0,
        memory0,
        history,
        gains,
        np.array([r.parameters() for r in rules]),
        n,
        spacecraft=paper.SPACECRAFT,
        flight_options=rows,
    )
    for b in range(packed.count):
        assert packed.run(b)
    stats, memory = _vectorize.lane_stats(packed), _vectorize.lane_memory(packed)
    assert memory.shape == (len(x0), FLIGHT_MEMORY_SIZE)
    for i in range(len(x0)):
        own = flight_structure(rows[i], None)
        scalar = engine(paper.SPACECRAFT, rules[i], d, 1.0 / RATE, 1, **own)
        output = scalar.run(
            x0[i],
            0.0,
            x0[i][None, :],  # (columns, 6): a constant history
            gains[i],
            np.array(rules[i].parameters()),
            n,
            spacecraft=paper.SPACECRAFT,
            keep_every=None,
            workspace=scalar.workspace(n, switches=False),
            flight_options=rows[i],
        )
        assert np.array_equal(stats[i].view(np.uint64), output.stats.view(np.uint64)), i
        assert np.array_equal(memory[i].view(np.uint64), output.memory.view(np.uint64)), i
    assert memory[1, 5] > 0 and memory[4, 5] > 0 and memory[0, 5] == 0  # the saturated counts


def test_an_engine_without_what_a_run_needs_refuses_it_naming_it():
    x0, gains = _dispersed(2, 16)
    d = 5
    ideal = _vectorize.lane_engine(
        paper.SPACECRAFT, Hysteretic(), d, 1.0 / RATE, 1, sensor=False, limited=False, disturbed=False
    )
    assert "noise" not in ideal.streamed and ideal.stream_size == 0
    memory0 = np.array([flight_memory(x, x[None, :], d) for x in x0])
    common = (x0, memory0, x0[:, :, None], gains, np.zeros((2, 1)), 10)
    limited, disturbed, biased = (NO_FLIGHT_OPTIONS.copy() for _ in range(3))
    limited[3], disturbed[5], biased[8] = 1.0, 1e-3, 1e-4
    per_run = np.stack((NO_FLIGHT_OPTIONS, disturbed))  # one run of two needs the disturbance
    for options, sensor, word in (
        (limited, None, "limited=True"),
        (per_run, None, "disturbed=True"),
        (biased, None, "sensor=True"),
        (None, NOISY, "sensor=True"),
    ):
        with pytest.raises(SpecificationError, match=word):
            _vectorize.closed_loop_batches(
                ideal, *common, spacecraft=paper.SPACECRAFT, flight_options=options, sensor=sensor
            )
    # an ideal SensorModel (no noise, no bias) is served by the sample without a sensor
    packed = _vectorize.closed_loop_batches(ideal, *common, spacecraft=paper.SPACECRAFT, sensor=SensorModel())
    assert packed.run(0)
    full = _vectorize.lane_engine(paper.SPACECRAFT, Hysteretic(), d, 1.0 / RATE, 1)  # the default: the full sample
    assert full.structure == {"sensor": True, "limited": True, "disturbed": True} and full is not ideal
