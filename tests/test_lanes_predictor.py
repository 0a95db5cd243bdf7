"""Metrics-only predictor batches on the lane engine: dispersed runs (own plant, gain, state, delay, actuator,
sensor, disturbance), a model unlike the plant, on two threads and in series, each run bit for bit the scalar
engine's run (``simulate``, and the batch with the lanes switched off)."""

from __future__ import annotations

import numpy as np
import pytest
from lane_assertions import assert_row_is_the_run, assert_same_bits, one_run, scalar_batch

from mrpctl import paper, simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.design import pd_gains
from mrpctl.engines import lanes as lane_engines
from mrpctl.flight import ActuatorModel, Disturbance, SensorModel
from mrpctl.predictor import OnPredicted, Predictor, perturbed_spacecraft
from mrpctl.simulation import _batch
from mrpctl.spacecraft import Spacecraft

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="the lane engine needs a C compiler")

COUNT = 19  # W = 8: full and padded batches in each lane group
SC = paper.SPACECRAFT
FAST = pd_gains(SC, zeta=1.0, omega_n=12.85).K
COMMON = dict(rate=200.0, t_final=4.0)


def _case() -> dict:
    """Dispersed predictor runs: own diagonal plant inertia (5-15 % off the model), gain, initial state, delay (0 to
    0.25 s), u_max (or none), sensor (seed, levels, bias; or none) and disturbance (constant, per-sample rows or a
    function of time); one run, unlimited, with 40x the gain (it diverges)."""
    rng = np.random.default_rng(11)
    x0 = np.array(paper.INITIAL_STATE, dtype=float) + 0.05 * rng.standard_normal((COUNT, 6))
    gains = FAST[None] * rng.uniform(0.7, 1.3, (COUNT, 1, 1))
    gains[9] *= 40.0
    crafts = [perturbed_spacecraft(SC, float(e)) for e in rng.uniform(0.05, 0.15, COUNT)]
    sensors: list[SensorModel | None] = [
        SensorModel(
            attitude_noise=float(rng.uniform(0.0, 2e-3)),
            rate_noise=float(rng.uniform(0.0, 2e-4)),
            gyro_bias=rng.normal(scale=1e-4, size=3),
            seed=int(rng.integers(0, 2**63)),
        )
        for _ in range(COUNT)
    ]
    sensors[4] = SensorModel(gyro_bias=[1e-4, 0.0, 0.0])  # noiseless, biased
    sensors[7] = sensors[15] = None  # no sensor: another lane group
    actuators: list[ActuatorModel | None] = [ActuatorModel(rng.uniform(150.0, 400.0, 3)) for _ in range(COUNT)]
    actuators[2] = actuators[9] = actuators[11] = None  # unlimited: another lane group
    rows = 0.5 * rng.standard_normal((int(COMMON["rate"] * COMMON["t_final"]) + 1, 3))
    disturbance: list = [rng.normal(scale=0.5, size=3) for _ in range(COUNT)]
    disturbance[3] = rows
    disturbance[8] = Disturbance(function=lambda t: np.stack([np.sin(t), np.cos(2 * t), 0.1 * t], axis=-1))
    return dict(
        spacecraft=crafts,
        K=gains,
        x0=x0,
        tau=[[0.0, 0.05, 0.1, 0.25][i % 4] for i in range(COUNT)],
        rule=[OnPredicted(1.0 if i % 3 else 1.2) for i in range(COUNT)],
        sensor=sensors,
        actuator=actuators,
        disturbance=disturbance,
    )


@pytest.mark.parametrize("model", [SC, Spacecraft(np.array([[95.0, 2.0, -1.0], [2.0, 105.0, 1.5], [-1.0, 1.5, 98.0]]))])
def test_dispersed_predictor_runs_on_the_lanes_equal_the_scalar_engine_bit_for_bit(model, monkeypatch):
    case = dict(_case(), predictor=Predictor(model=model))
    packed: list[int] = []
    pack = lane_engines.closed_loop_batches

    def spy(engine, x0, *args, **kwargs):
        assert engine.measured == 12  # the predictor's delayed entries (m, z)
        packed.append(len(x0))
        return pack(engine, x0, *args, **kwargs)

    monkeypatch.setattr(lane_engines, "closed_loop_batches", spy)
    on_two = simulate_batch(**case, **COMMON, threads=2)
    assert sum(packed) == COUNT  # every run on the lanes, in groups of delay and structure
    in_series = simulate_batch(**case, **COMMON, threads=1)
    assert_same_bits(on_two, in_series)
    assert_same_bits(on_two, scalar_batch(**case, **COMMON, threads=2))
    for i in range(COUNT):  # each run alone: the scalar engine's simulate
        run = simulate(**one_run(case, i), **COMMON)
        assert_row_is_the_run(on_two, i, run)
    # the batch covers what it must: switching, a diverging run, saturated runs, the noise matters
    assert (on_two.switch_count[~on_two.diverged] >= 1).sum() >= 3
    assert on_two.diverged[9] and on_two.diverged.sum() < COUNT // 2
    assert np.sum(on_two.saturated_fraction > 0.0) >= 3
    swapped = dict(case, sensor=case["sensor"][1:] + case["sensor"][:1])
    assert not np.array_equal(simulate_batch(**swapped, **COMMON).max_sigma, on_two.max_sigma)


def test_shared_models_and_a_shared_torque_function_on_the_lanes_equal_the_scalar_engine():
    rng = np.random.default_rng(3)
    states = np.array(paper.INITIAL_STATE, dtype=float) + 0.02 * rng.standard_normal((11, 6))
    case = dict(
        spacecraft=perturbed_spacecraft(SC, 0.1),
        K=FAST,
        x0=states,
        tau=0.1,
        rule=OnPredicted(1.0),
        predictor=Predictor(model=SC),
        sensor=SensorModel(attitude_noise=1e-3, rate_noise=1e-4, seed=5),
        actuator=ActuatorModel([250.0, 250.0, 250.0]),
        disturbance=Disturbance(function=lambda t: np.stack([np.sin(t), 0.0 * t, np.cos(t)], axis=-1)),
    )
    lanes = simulate_batch(**case, **COMMON, threads=2)
    assert_same_bits(lanes, scalar_batch(**case, **COMMON, threads=1))
    run = simulate(**dict(case, x0=states[4]), **COMMON)
    assert np.asarray(lanes.max_sigma)[4].tobytes() == np.asarray(run.max_sigma).tobytes()


def test_a_predictor_campaign_chunk_with_each_runs_own_noise_is_one_lane_call_equal_to_each_run_alone(monkeypatch):
    """A chunk of predictor runs with dispersed sensor noise (each run its own seed), torque limits and disturbances
    is one simulate_batch call on the lanes; each run equals simulate with the run's models (the replay contract)."""
    from mrpctl.campaign import parse_campaign
    from mrpctl.campaign import simulation as campaign_simulation
    from mrpctl.campaign._task import run_models, simulate_chunk
    from mrpctl.campaign.sampling import run_inputs
    from mrpctl.campaign.simulation import METRICS, flight_keywords

    spec = parse_campaign(
        {
            "name": "predicted-noise",
            "count": 11,
            "seed": 5,
            "tau": 0.05,
            "rate": 100.0,
            "t_final": 5.0,
            "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
            "gains": {"K1": -16.0, "K2": -8.0},
            "rule": {"type": "on-predicted"},
            "predictor": {"inertia_error": 0.05},
            "flight": {"attitude_noise": 1e-3, "rate_noise": 1e-4},
            "dispersions": {
                "attitude": {"angle_deg": [150.0, 180.0]},
                "inertia": {"axis_tolerance": 0.2, "product_tolerance": 2.0},
                "actuator": {"u_max": [0.3, 2.0]},
                "disturbance": {"magnitude": [0.0, 0.05]},
                "sensor": {"attitude_noise": [0.0, 2e-3], "gyro_bias": [0.0, 1e-3]},
            },
        }
    )
    calls: list[int] = []
    batch = campaign_simulation.simulate_batch

    def spy(*args, **kwargs):
        calls.append(len(kwargs["x0"] if "x0" in kwargs else args[2]))
        return batch(*args, **kwargs)

    monkeypatch.setattr(campaign_simulation, "simulate_batch", spy)
    chunk = simulate_chunk(spec, 0, spec.count, threads=2)
    assert calls == [spec.count]  # one call: each run's own actuator, sensor and torque on the lanes
    inputs = run_inputs(spec, 0, spec.count)
    seeds = {run_models(spec, inputs, j)[1]["sensor"].seed for j in range(spec.count)}  # type: ignore[index]
    assert len(seeds) == spec.count
    for j in range(spec.count):
        rule, models = run_models(spec, inputs, j)
        assert models is not None
        run = simulate(
            Spacecraft(inputs.inertia[j]),
            inputs.gain_scale[j] * spec.base.K,
            inputs.x0[j],
            tau=float(inputs.tau[j]),
            rule=rule,
            rate=100.0,
            t_final=5.0,
            predictor=spec.predictor,
            **flight_keywords(models),
        )
        settled = np.nan if run.settling_time is None else run.settling_time
        assert np.asarray(settled, np.float64).tobytes() == chunk["settling_time"][j].tobytes(), j
        assert run.switch_count == chunk["switch_count"][j], j
        assert np.asarray(run.max_sigma, np.float64).tobytes() == chunk["max_sigma"][j].tobytes(), j
    _batch._LANES = False
    try:
        scalar = simulate_chunk(spec, 0, spec.count, threads=1)
    finally:
        _batch._LANES = True
    for name in METRICS:
        assert np.asarray(chunk[name]).tobytes() == np.asarray(scalar[name]).tobytes(), name
