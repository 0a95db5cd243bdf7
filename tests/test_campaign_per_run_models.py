"""A fully dispersed flown chunk (each run its own noise seed, jitter seed, inertia, disturbance, u_max, δ) is one
``simulate_batch`` call that fills the lanes, and every run equals its inputs simulated alone bit for bit."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from mrpctl import simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.campaign import _task, parse_campaign, run_inputs
from mrpctl.campaign import simulation as campaign_simulation
from mrpctl.campaign.simulation import METRICS, flight_keywords
from mrpctl.spacecraft import Spacecraft

pytestmark = pytest.mark.skipif(find_compiler() is None, reason="the lane engine needs a C compiler")

DISPERSED = {
    "name": "dispersed",
    "count": 21,
    "seed": 8,
    "tau": 0.05,
    "rate": 100.0,
    "t_final": 4.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"k_sigma": -70.11, "k_omega": -163.08},
    "rule": {"type": "hysteretic", "delta": 0.05},
    "flight": {
        "u_max": 40.0,
        "saturation": "scale",
        "attitude_noise": 2e-3,
        "rate_noise": 1e-4,
        "jitter": [0.02, 0.05],
    },
    "dispersions": {
        "attitude": {"angle_deg": [150.0, 180.0]},
        "omega": {"magnitude": [0.0, 0.5]},
        "inertia": {"axis_tolerance": 0.05},
        "hysteresis": {"delta": [0.0, 0.2]},
        "actuator": {"u_max": [20.0, 60.0]},
        "disturbance": {"magnitude": [0.5, 1.0]},
        "sensor": {"attitude_noise": [1e-3, 3e-3], "gyro_bias": [1e-3, 2e-3]},
    },
}


@pytest.mark.parametrize("threads", [1, 2])
def test_a_dispersed_chunk_is_one_call_and_each_run_equals_its_inputs_alone(threads, monkeypatch):
    spec = parse_campaign(copy.deepcopy(DISPERSED))
    calls: list[int] = []
    batch = campaign_simulation.simulate_batch

    def counted(spacecraft, *args, **kwargs):
        calls.append(len(spacecraft))
        return batch(spacecraft, *args, **kwargs)

    monkeypatch.setattr(campaign_simulation, "simulate_batch", counted)
    chunk = _task.simulate_chunk(spec, 0, 21, threads=threads)
    assert calls == [21]  # one call for the chunk (it was one per run)
    inputs = run_inputs(spec, 0, 21)
    assert len(set(inputs.noise_seed.tolist())) == 21 and len(set(inputs.jitter_seed.tolist())) == 21
    assert len({J.tobytes() for J in inputs.inertia}) == 21 and len({w.tobytes() for w in inputs.disturbance}) == 21
    for i in range(21):  # each run as a call of its own, its models rebuilt from its stored inputs
        rule, models = _task.run_models(spec, inputs, i)
        assert models is not None
        alone = batch(
            Spacecraft(inputs.inertia[i]),
            inputs.gain_scale[i] * spec.base.K,
            inputs.x0[i],
            tau=float(inputs.tau[i]),
            rule=rule,
            t_final=spec.base.t_final,
            rate=spec.base.rate,
            threads=1,
            **flight_keywords(models),
        )
        for name in METRICS:
            assert chunk[name][i].tobytes() == np.asarray(getattr(alone, name))[0].tobytes(), (i, name)
    assert len(set(chunk["max_sigma"].tolist())) == 21 and np.isfinite(chunk["peak_torque"]).all()


def test_undispersed_models_still_share_one_object_per_call(monkeypatch):
    """Runs whose models are equal get one shared model (streamed once per batch), not a list of copies."""
    source = copy.deepcopy(DISPERSED)
    source["flight"] = {"u_max": 40.0, "saturation": "scale"}  # an ideal sensor, no jitter
    source["dispersions"] = {"attitude": {"angle_deg": [150.0, 180.0]}}
    spec = parse_campaign(source)
    seen: list[dict] = []

    def spy(spacecraft, *args, **kwargs):
        seen.append(kwargs)
        return simulate_batch(spacecraft, *args, **kwargs)

    monkeypatch.setattr(campaign_simulation, "simulate_batch", spy)
    _task.simulate_chunk(spec, 0, 9, threads=1)
    assert len(seen) == 1
    assert not isinstance(seen[0]["sensor"], list) and not isinstance(seen[0]["actuator"], list)
