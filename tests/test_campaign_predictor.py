"""Campaigns with the predictor controller: the model is the nominal spacecraft, the plant is dispersed."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from mrpctl import simulate_batch
from mrpctl.campaign import open_campaign, parse_campaign, replay, run_campaign
from mrpctl.campaign.sampling import run_inputs
from mrpctl.campaign.simulation import METRICS
from mrpctl.errors import SpecificationError
from mrpctl.predictor import OnPredicted, Predictor
from mrpctl.spacecraft import Spacecraft

NOMINAL = np.diag([140.0, 100.0, 80.0])
#: The documented model of inertia_error = e: the nominal J = S J_m S with S = diag(sqrt(1 + e)), so
#: J_m = S⁻¹ J S⁻¹ (about J / (1 + e)).
SCALE = np.diag(1.0 / np.sqrt(np.full(3, 1.05)))
MODEL = SCALE @ NOMINAL @ SCALE

SPEC = {
    "name": "predicted",
    "count": 6,
    "seed": 13,
    "tau": 0.05,
    "rate": 100.0,
    "t_final": 5.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"K1": -16.0, "K2": -8.0},  # zeta = 1, omega_n = 4 rad/s
    "rule": {"type": "on-predicted"},
    "predictor": {"inertia_error": 0.05},
    "dispersions": {
        "attitude": {"angle_deg": [150.0, 180.0]},
        "omega": {"magnitude": [0.0, 0.5]},
        "inertia": {"axis_tolerance": 0.2, "product_tolerance": 2.0},
        "tau": {"range": [0.04, 0.05], "step": 0.01},
        "rule": {"rules": ["on-predicted", "on-predicted:1.2"]},
    },
}


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    out = tmp_path_factory.mktemp("predicted")
    spec = parse_campaign(copy.deepcopy(SPEC))
    run_campaign(spec, out, chunk=4, threads=2)
    return spec, out, open_campaign(out)


def test_the_model_is_the_nominal_spacecraft_and_the_plant_is_dispersed(stored):
    spec, _, ds = stored
    assert isinstance(spec.predictor, Predictor)
    # inertia_error = e relates the model to the nominal J (not to a run's plant): J_nominal = (1 + e) J_m
    assert np.array_equal(spec.predictor.model.inertia, MODEL)
    assert np.allclose(MODEL, NOMINAL / 1.05, rtol=1e-14, atol=0.0)
    assert json.loads(ds.attrs["predictor_model_inertia"]) == MODEL.tolist()
    plants = ds["inertia"].values
    assert len({p.tobytes() for p in plants}) == spec.cases  # every case its own plant
    assert not any(np.array_equal(p, spec.predictor.model.inertia) for p in plants)
    assert json.loads(ds.attrs["rules"]) == ["on-predicted", "on-predicted:1.2"]
    assert ds["rule"].values.tolist() == [0, 1, 0, 1, 0, 1]
    assert [type(r) for r in spec.rule_list] == [OnPredicted, OnPredicted]
    assert [r.alpha for r in spec.rule_list] == [1.0, 1.2]


def test_metrics_equal_an_independent_simulate_batch_call_and_replay_is_bit_for_bit(stored):
    spec, out, ds = stored
    inputs = run_inputs(spec, 0, spec.count)
    model = Predictor(Spacecraft(MODEL))  # built here, not taken from the spec
    batch = simulate_batch(
        [Spacecraft(J) for J in inputs.inertia],
        inputs.gain_scale[:, None, None] * spec.base.K[None],
        inputs.x0,
        tau=inputs.tau,
        rule=[OnPredicted(1.0), OnPredicted(1.2)] * 3,
        t_final=5.0,
        rate=100.0,
        predictor=model,
    )
    for name in METRICS:
        assert np.asarray(getattr(batch, name)).tobytes() == ds[name].values.tobytes(), name
    assert np.isfinite(ds["peak_torque"].values).all() and ds["converged"].values.any()
    for run in (1, 4):
        result = replay(out, run, trajectory=True)
        assert result.matches, result.mismatches
        assert result.trajectory is not None
        assert result.trajectory.switch_count == int(ds["switch_count"].values[run])


def test_the_predictor_changes_the_runs():
    """The model error is used: a campaign with the exact nominal model gives other metrics."""
    from mrpctl.campaign._task import simulate_chunk

    exact = copy.deepcopy(SPEC)
    exact["predictor"] = {}
    one = simulate_chunk(parse_campaign(copy.deepcopy(SPEC)), 0, 2, threads=1)
    other = simulate_chunk(parse_campaign(exact), 0, 2, threads=1)
    assert np.array_equal(one["inertia"], other["inertia"]) and np.array_equal(one["sigma0"], other["sigma0"])
    assert one["converged"].all() and not np.array_equal(one["settling_time"], other["settling_time"])


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"predictor": None}, r"'on-predicted' needs a \[predictor\] table"),
        ({"dispersions": {"rule": {"rules": ["on-predicted", "on-delayed"]}}}, "every rule must be 'on-predicted'"),
        ({"rule": {"type": "delay-aware"}, "dispersions": {"rule": None}}, r"\[predictor\] applies only with"),
        ({"predictor": {"inertia": [140.0, -1.0, 80.0]}}, r"\[predictor\] .*inertia"),
        ({"predictor": {"inertia_error": -1.5}}, r"\[predictor\] inertia_error: each relative error must be > -1"),
        ({"predictor": {"inertia_error": 0.1, "inertia": [1.0, 1.0, 1.0]}}, r"\[predictor\] give inertia"),
        ({"predictor": {"colour": 1}}, "unknown key 'colour' in \\[predictor\\]"),
        ({"history": "zero-input"}, r"\[predictor\] needs history = 'constant'"),
        ({"dispersions": {"rule": {"rules": ["on-predicted:0.5"]}}}, "alpha .* must be >= 1"),
        ({"dispersions": {"rule": {"rules": ["on-predicted", "on-predicted:1.0"]}}}, "listed twice"),
        (
            {"flight": {"jitter": [0.04, 0.05]}, "dispersions": {"tau": None}},
            "jitter does not apply with the predictor",
        ),
    ],
)
def test_refusals_are_named_when_the_file_is_read(change, message):
    data = copy.deepcopy(SPEC)
    for key, value in change.items():
        if key == "dispersions":
            data["dispersions"] = {**data["dispersions"], **value}
            data["dispersions"] = {k: v for k, v in data["dispersions"].items() if v is not None}
        elif value is None:
            data.pop(key)
        else:
            data[key] = value
    with pytest.raises(SpecificationError, match=message):
        parse_campaign(data)


def test_never_switch_round_trips_as_a_label():
    data = copy.deepcopy(SPEC)
    data["dispersions"]["rule"] = {"rules": ["on-predicted:inf", {"type": "on-predicted", "alpha": 1.5}]}
    spec = parse_campaign(data)
    assert spec.rule_labels == ("on-predicted:inf", "on-predicted:1.5")
    assert spec.rule_list[0].alpha is None
    again = parse_campaign({**data, "dispersions": {**data["dispersions"], "rule": {"rules": list(spec.rule_labels)}}})
    assert again.rule_labels == spec.rule_labels


def test_a_torque_limit_and_a_disturbance_reach_the_predictor_runs():
    """[flight] models other than jitter run with the predictor (it uses the applied torque): an independent
    simulate_batch call with the models written by hand gives the chunk's metrics."""
    from mrpctl.campaign._task import simulate_chunk
    from mrpctl.flight import ActuatorModel, Disturbance, Saturation

    data = copy.deepcopy(SPEC)
    data["flight"] = {"u_max": 0.5, "disturbance": [0.01, 0.0, -0.02]}
    spec = parse_campaign(data)
    chunk = simulate_chunk(spec, 0, 2, threads=1)
    inputs = run_inputs(spec, 0, 2)
    batch = simulate_batch(
        [Spacecraft(J) for J in inputs.inertia],
        inputs.gain_scale[:, None, None] * spec.base.K[None],
        inputs.x0,
        tau=inputs.tau,
        rule=[OnPredicted(1.0), OnPredicted(1.2)],
        t_final=5.0,
        rate=100.0,
        predictor=Predictor(Spacecraft(MODEL)),
        actuator=ActuatorModel(0.5, mode=Saturation.SCALE),
        disturbance=Disturbance(np.array([0.01, 0.0, -0.02])),
    )
    for name in METRICS:
        assert np.asarray(getattr(batch, name)).tobytes() == chunk[name].tobytes(), name
    assert (chunk["peak_torque"] <= 0.5 * (1 + 1e-12)).all()
    plain = simulate_chunk(parse_campaign(copy.deepcopy(SPEC)), 0, 2, threads=1)
    assert not np.array_equal(plain["settling_time"], chunk["settling_time"], equal_nan=True)
