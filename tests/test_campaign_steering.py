"""Campaigns with the steering law: every run flies the file's [steering] law, as simulate of its inputs."""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

from mrpctl import simulate
from mrpctl.campaign import parse_campaign, run_campaign, simulate_chunk
from mrpctl.campaign.report import replay
from mrpctl.campaign.sampling import run_inputs
from mrpctl.campaign.store import open_campaign
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.flight.steering import SteeringLaw
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

RPM = 2.0 * math.pi / 60.0
INERTIA = [0.2, 0.25, 0.15]
STEERING = {"rate_limit": 0.19416259125556992, "acceleration": 0.012, "lag": 0.424792990260496}
SPEC = {
    "name": "cubesat_steering",
    "count": 6,
    "seed": 5,
    "tau": 0.2,
    "rate": 50.0,
    "t_final": 40.0,
    "spacecraft": {"inertia": INERTIA},
    "gains": {"attitude": [3.958, 4.947, 2.968], "rate": [0.8897, 1.1121, 0.6673]},
    "rule": {"type": "hysteretic", "delta": 0.0},
    "wheels": {"layout": "orthogonal", "spin_inertia": 3.1831e-5, "torque_limit": 5e-3, "speed_limit_rpm": 6000.0},
    "steering": {**STEERING, "momentum_limit": 0.02},
    "dispersions": {
        "attitude": {"angle_deg": [0.0, 180.0]},
        "omega": {"magnitude": [0.0, 0.05]},
        "gains": {"scale": [0.9, 1.1]},
        "rule": {"rules": ["hysteretic:0.0", "hysteretic:0.1"]},
    },
}
RULES = [Hysteretic(0.0), Hysteretic(0.1)]


def _law(momentum: bool) -> SteeringLaw:
    if momentum:
        return SteeringLaw(**STEERING, momentum_limit=0.02, spacecraft=Spacecraft(INERTIA))
    return SteeringLaw(**STEERING)


def _direct(spec, i: int, **options):
    """Run i as simulate of its inputs (written out here: the scale times the nominal gain, the run's rule)."""
    inputs = run_inputs(spec, i, i + 1)
    return simulate(
        Spacecraft(inputs.inertia[0]),
        float(inputs.gain_scale[0]) * spec.base.K,
        inputs.x0[0],
        tau=float(inputs.tau[0]),
        rule=RULES[int(inputs.rule[0])],
        t_final=spec.base.t_final,
        rate=50.0,
        **options,
    )


def _same(stored: float, value: float | None) -> bool:
    return (value is None and math.isnan(stored)) or stored == value


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    out = tmp_path_factory.mktemp("steering")
    result = run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=4, threads=1)
    assert result.complete and result.verified
    return out


def test_every_run_on_the_wheels_is_simulate_of_its_inputs(stored) -> None:
    spec = parse_campaign(copy.deepcopy(SPEC))
    assert spec.base.law == _law(True)
    dataset = open_campaign(stored)
    cluster = WheelCluster.orthogonal(3.1831e-5, 5e-3, 6000.0 * RPM)
    differs = 0
    for i in range(SPEC["count"]):
        run = _direct(spec, i, wheels=cluster, law=_law(True))
        assert run.wheels is not None
        for name in ("settling_time", "max_sigma", "switch_count", "peak_torque"):
            assert _same(float(dataset[name].values[i]), getattr(run, name)), (i, name)
        assert dataset["wheel_peak_speed"].values[i].tobytes() == np.asarray(run.wheels.peak_speed).tobytes()
        assert dataset["wheel_peak_momentum"].values[i] == run.wheels.peak_momentum
        pd = _direct(spec, i, wheels=cluster)
        differs += dataset["max_sigma"].values[i] != pd.max_sigma or not _same(
            float(dataset["settling_time"].values[i]), pd.settling_time
        )
    assert differs > 0  # the law flew, not the PD law
    replayed = replay(stored, 5, trajectory=True)  # the stored trajectories fly the law too
    assert replayed.matches and replayed.trajectory is not None
    assert _same(float(dataset["max_sigma"].values[5]), replayed.trajectory.max_sigma)
    assert replayed.trajectory.wheels is not None
    assert replayed.trajectory.wheels.peak_momentum == dataset["wheel_peak_momentum"].values[5]


def test_every_run_on_a_torque_limit_is_simulate_of_its_inputs() -> None:
    data = copy.deepcopy(SPEC)
    del data["wheels"]
    data["steering"] = dict(STEERING)
    data["flight"] = {"u_max": 5e-3}
    data["t_final"] = 30.0
    data["count"] = 4
    spec = parse_campaign(data)
    values = simulate_chunk(spec, 0, 4, threads=1)
    for i in range(4):
        run = _direct(spec, i, actuator=ActuatorModel(5e-3), law=_law(False))
        for name in ("settling_time", "max_sigma", "switch_count", "peak_torque"):
            assert _same(float(values[name][i]), getattr(run, name)), (i, name)


@pytest.mark.parametrize(
    ("change", "needle"),
    [
        ({"dispersions": {"rule": {"rules": ["hysteretic:0.1", "on-current"]}}}, "got 'on-current'"),
        ({"rule": {"type": "boundary-layer", "eps": 0.1}, "wheels": None}, "controller-side rule only"),
        ({"reference": {"type": "inertial", "sigma": [0.1, 0.0, 0.0]}, "wheels": None}, "[steering] and [reference]"),
        ({"steering": {"rate_limit": 0.2}}, "[steering] needs acceleration"),
        ({"steering": {**STEERING, "lag": -0.1}}, "[steering] lag"),
    ],
)
def test_what_a_campaign_with_the_law_refuses(change: dict, needle: str) -> None:
    data = copy.deepcopy(SPEC)
    if "rule" in change:  # the [rule] alone, not the dispersion's rules
        del data["dispersions"]["rule"]
    for key, value in change.items():
        if value is None:
            del data[key]
        elif key == "dispersions":
            data["dispersions"].update(value)
        else:
            data[key] = value
    with pytest.raises(SpecificationError) as error:
        parse_campaign(data)
    assert needle in str(error.value)


def test_the_example_campaign_flies_the_design_for_its_wheels() -> None:
    from mrpctl.campaign import load_campaign
    from mrpctl.design.actuator import design_for_actuator

    spec = load_campaign(Path(__file__).parents[1] / "examples" / "campaigns" / "wheels" / "cubesat_steering.toml")
    speed = 6000.0 * RPM
    cluster = WheelCluster.orthogonal(0.020 / speed, 5e-3, speed)  # 20 mN m s at 6000 rpm, exactly
    design = design_for_actuator(Spacecraft(INERTIA), 0.2, cluster, max_rate=0.05, settling_time=120.0)
    assert spec.base.wheels is not None and spec.base.wheels.key() == cluster.key()
    assert spec.base.law == design.law and np.array_equal(spec.base.K, design.K)
    assert spec.count == 300 and spec.base.rule == Hysteretic(0.0) and spec.base.t_final == 300.0
    assert spec.attitude is not None and spec.attitude.full and spec.omega is not None
