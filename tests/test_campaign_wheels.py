"""Campaigns on reaction wheels: each run as simulate of its inputs, the wheel metrics stored, checked and reported."""

from __future__ import annotations

import copy
import math
import shutil

import numpy as np
import pytest

from mrpctl import simulate
from mrpctl.campaign import parse_campaign, run_campaign
from mrpctl.campaign.integrity import StoreDamagedError
from mrpctl.campaign.report import replay, report
from mrpctl.campaign.store import STORE_NAME, open_campaign
from mrpctl.campaign.trajectories import store_trajectories
from mrpctl.data import load
from mrpctl.errors import SpecificationError
from mrpctl.flight import DelayModel, Hysteretic, SensorModel
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

RPM = 2.0 * math.pi / 60.0
WHEELS = {"layout": "orthogonal", "spin_inertia": 3.1831e-5, "torque_limit": 5e-3, "speed_limit_rpm": 6000.0}
SPEC = {
    "name": "cubesat_wheels",
    "count": 8,
    "seed": 11,
    "tau": 0.2,
    "rate": 50.0,
    "t_final": 60.0,
    "spacecraft": {"inertia": [0.2, 0.25, 0.15]},
    "gains": {"attitude": [3.958, 4.947, 2.968], "rate": [0.8897, 1.1121, 0.6673]},
    "rule": {"type": "hysteretic", "delta": 0.1},
    "wheels": WHEELS,
    "dispersions": {
        "attitude": {"angle_deg": [0.0, 180.0]},
        "omega": {"magnitude": [0.0, 0.05]},
        "gains": {"scale": [0.9, 1.1]},
        "rule": {"rules": ["hysteretic:0.1", "hysteretic:0.0"]},
    },
}
CHUNK = 3


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    out = tmp_path_factory.mktemp("wheels")
    result = run_campaign(parse_campaign(copy.deepcopy(SPEC)), out, chunk=CHUNK, threads=1)
    assert result.complete and result.verified
    return out


def _direct(dataset, i: int, cluster: WheelCluster, **options):
    """Run i of the store as simulate of its stored inputs (the gain: the scale times the nominal gain)."""
    base = parse_campaign(copy.deepcopy(SPEC)).base
    rules = [Hysteretic(0.1), Hysteretic(0.0)]
    x0 = np.concatenate((dataset["sigma0"].values[i], dataset["omega0"].values[i] / 4.0))
    return simulate(
        Spacecraft(dataset["inertia"].values[i]),
        float(dataset["gain_scale"].values[i]) * base.K,
        x0,
        tau=float(dataset["tau"].values[i]),
        rule=rules[int(dataset["rule"].values[i])],
        t_final=60.0,
        rate=50.0,
        wheels=cluster,
        **options,
    )


def test_every_run_is_simulate_of_its_inputs(stored) -> None:
    dataset = open_campaign(stored)
    cluster = WheelCluster.orthogonal(3.1831e-5, 5e-3, 6000.0 * RPM)
    assert dataset.sizes["wheel"] == 3 and dataset["wheel_peak_speed"].attrs["units"] == "rad/s"
    for i in range(SPEC["count"]):
        run = _direct(dataset, i, cluster)
        assert run.wheels is not None
        for name, value in (
            ("settling_time", run.settling_time),
            ("max_sigma", run.max_sigma),
            ("switch_count", run.switch_count),
            ("converged", run.converged),
            ("peak_torque", run.peak_torque),
            ("wheel_peak_momentum", run.wheels.peak_momentum),
            ("worst_wheel", run.wheels.worst_wheel),
        ):
            stored_value = dataset[name].values[i]
            if value is None:  # not settled: None from simulate, NaN in the store
                assert name == "settling_time" and np.isnan(stored_value), (i, name)
            else:
                assert stored_value == value, (i, name)
        for name, value in (
            ("wheel_peak_speed", run.wheels.peak_speed),
            ("wheel_final_speed", run.wheels.final_speeds),
            ("wheel_torque_limited_time", run.wheels.torque_limited_time),
            ("wheel_speed_limited_time", run.wheels.speed_limited_time),
        ):
            assert dataset[name].values[i].tobytes() == np.asarray(value).tobytes(), (i, name)
        # and the peaks are the trajectory's: max |Omega_i| over the kept samples
        assert np.array_equal(dataset["wheel_peak_speed"].values[i], np.max(np.abs(run.wheels.speeds), axis=0))
    assert replay(stored, 4).matches


def test_the_report_summarises_the_wheels(stored) -> None:
    dataset = open_campaign(stored)
    summary = report(stored)
    assert summary.wheels is not None
    peaks = dataset["wheel_peak_speed"].values / RPM
    limited = dataset["wheel_speed_limited_time"].values
    for i, wheel in enumerate(summary.wheels["wheels"]):
        assert wheel["wheel"] == i + 1 and wheel["speed_limit_rpm"] == pytest.approx(6000.0, rel=1e-15)
        assert wheel["peak_speed_rpm"]["max"] == pytest.approx(float(np.max(peaks[:, i])), rel=1e-15)
        assert wheel["peak_speed_rpm"]["median"] == pytest.approx(float(np.median(peaks[:, i])), rel=1e-15)
        assert wheel["runs_at_speed_limit"] == int(np.count_nonzero(limited[:, i]))
        assert wheel["worst_in_runs"] == int(np.count_nonzero(dataset["worst_wheel"].values == i))
    assert sum(w["worst_in_runs"] for w in summary.wheels["wheels"]) == SPEC["count"]
    assert summary.summary()["wheels"]["momentum_capacity_Nms"] == pytest.approx([3.1831e-5 * 200 * math.pi] * 3)
    text = str(summary)
    assert "wheels        3; peak stored momentum" in text and "runs_at_speed_lim" in text
    # each run's momentum load at rest, independent of the zonotope gauge: three orthogonal wheels hold Js Omega_max
    # per body axis, so the load of H_N = [BN]^T J omega is the largest |H_N,i| / (Js Omega_max)
    from mrpctl.mrp import to_dcm

    h_n = [
        to_dcm(dataset["sigma0"].values[i]).T @ (dataset["inertia"].values[i] @ dataset["omega0"].values[i])
        for i in range(SPEC["count"])
    ]
    loads = np.max(np.abs(h_n), axis=1) / (3.1831e-5 * 200 * math.pi)
    assert summary.wheels["initial_momentum_load"]["max"] == pytest.approx(float(np.max(loads)), rel=1e-12)
    assert summary.wheels["runs_beyond_capacity"] == int(np.sum(loads > 1.0)) == 0  # |omega0| <= 0.05 rad/s
    assert "cannot settle" not in text


def test_a_stored_trajectory_holds_the_wheels(stored, tmp_path) -> None:
    out = tmp_path / "copy"
    shutil.copytree(stored, out)
    written = store_trajectories(out, [5])
    run = load(written.files[0])
    direct = _direct(open_campaign(out), 5, WheelCluster.orthogonal(3.1831e-5, 5e-3, 6000.0 * RPM))
    assert run.wheels is not None and direct.wheels is not None
    assert np.array_equal(run.wheels.speeds, direct.wheels.speeds)
    assert np.array_equal(run.wheels.motor_torque, direct.wheels.motor_torque)
    assert run.wheels.cluster.key() == direct.wheels.cluster.key()


def test_a_damaged_wheel_chunk_is_found(stored, tmp_path) -> None:
    out = tmp_path / "out"
    shutil.copytree(stored, out)
    path = out / STORE_NAME / "wheel_peak_speed" / "c" / "1" / "0"
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(StoreDamagedError, match="array wheel_peak_speed"):
        report(out)


def test_flight_models_on_wheels(tmp_path) -> None:
    spec = copy.deepcopy(SPEC) | {"count": 4, "t_final": 10.0}
    spec["flight"] = {"attitude_noise": 1e-4, "rate_noise": 1e-5, "jitter": [0.1, 0.2]}
    del spec["dispersions"]["rule"]
    run_campaign(parse_campaign(spec), tmp_path, chunk=2, threads=1)
    dataset = open_campaign(tmp_path)
    cluster = WheelCluster.orthogonal(3.1831e-5, 5e-3, 6000.0 * RPM)
    for i in range(4):
        sensor = SensorModel(1e-4, 1e-5, seed=int(dataset["noise_seed"].values[i]))
        delay = DelayModel.jitter(0.1, 0.2, seed=int(dataset["jitter_seed"].values[i]))
        run = simulate(
            Spacecraft(dataset["inertia"].values[i]),
            float(dataset["gain_scale"].values[i]) * parse_campaign(copy.deepcopy(spec)).base.K,
            np.concatenate((dataset["sigma0"].values[i], dataset["omega0"].values[i] / 4.0)),
            tau=0.2,
            rule=Hysteretic(0.1),
            t_final=10.0,
            rate=50.0,
            wheels=cluster,
            sensor=sensor,
            delay=delay,
            disturbance=np.zeros(3),
        )
        assert run.wheels is not None
        assert dataset["max_sigma"].values[i] == run.max_sigma
        assert dataset["wheel_peak_speed"].values[i].tobytes() == run.wheels.peak_speed.tobytes()
        assert dataset["wheel_torque_limited_time"].values[i].tobytes() == run.wheels.torque_limited_time.tobytes()


@pytest.mark.parametrize(
    ("changes", "needles"),
    [
        ({"dispersions": {"rule": {"rules": ["hysteretic:0.1", "on-delayed"]}}}, ["rule only", "'on-delayed'"]),
        ({"rule": {"type": "on-current"}}, ["rule only", "'on-current'"]),
        ({"flight": {"u_max": 5e-3}}, ["flight.u_max", "the wheels' own"]),
        ({"dispersions": {"actuator": {"u_max": [1e-3, 5e-3]}}}, ["[dispersions.actuator]", "the wheels' own"]),
        ({"dispersions": {"inertia": {"axis_tolerance": 0.05}}}, ["[dispersions.inertia]", "nominal inertia"]),
        ({"rule": {"type": "on-predicted"}, "predictor": {}}, ["predictor is not modelled"]),
        ({"wheels": WHEELS | {"torque_limit": 0.0}}, ["[wheels] torque_limit must be > 0"]),
        ({"wheels": WHEELS | {"speed_limit": 600.0}}, ["unknown key 'speed_limit' in [wheels]"]),
    ],
    ids=["rule-list", "paper-rule", "flight-u-max", "actuator-dispersion", "inertia", "predictor", "bad-key", "key"],
)
def test_what_a_campaign_on_wheels_does_not_run(changes: dict, needles: list[str]) -> None:
    spec = copy.deepcopy(SPEC)
    spec["dispersions"] = {"attitude": {"angle_deg": [0.0, 180.0]}}
    for key, value in changes.items():
        if key == "dispersions":
            spec["dispersions"].update(value)
        else:
            spec[key] = value
    with pytest.raises(SpecificationError) as caught:
        parse_campaign(spec)
    for needle in needles:
        assert needle in str(caught.value), str(caught.value)


def test_the_report_says_which_runs_the_wheels_cannot_hold() -> None:
    from mrpctl.campaign.wheels import wheel_summary, wheel_summary_lines

    runs = {
        "wheel_peak_speed": np.zeros((3, 3)),
        "wheel_torque_limited_time": np.zeros((3, 3)),
        "wheel_speed_limited_time": np.zeros((3, 3)),
        "worst_wheel": np.zeros(3, dtype=np.int64),
        "wheel_peak_momentum": np.zeros(3),
    }
    summary = wheel_summary(runs, None, None, loads=np.array([0.5, 2.5, np.nan]))
    assert summary is not None and summary["runs_beyond_capacity"] == 1
    assert summary["initial_momentum_load"]["max"] == 2.5
    lines = wheel_summary_lines(summary)
    assert "1 of 3 runs start with more angular momentum than the wheels hold at rest (load up to 2.5)" in lines[1]
