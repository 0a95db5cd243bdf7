"""The predictor's form (`PredictorForm`) wherever the predictor goes: the engines, the files, the command line, the
export, campaigns; and the one property both forms share, their linearisation (the FSA prediction), which is what
the predictor's stability tests certify.

The linear form's trajectories against an independent NumPy loop are in tests/test_predictor_linear.py.
"""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import pytest
from test_scenario_predictor import BASE as SCENARIO

from mrpctl import OnPredicted, Predictor, PredictorForm, data, paper, simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl._export import C_PREFIX, MANIFEST_NAME, export
from mrpctl.campaign import open_campaign, parse_campaign, replay, run_campaign
from mrpctl.campaign.sampling import run_inputs
from mrpctl.campaign.simulation import METRICS
from mrpctl.cli import USER_ERROR, main
from mrpctl.design import pd_gains
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, SensorModel
from mrpctl.loop.functions import InertiaInput, predictor_core_function
from mrpctl.loop.options import predictor_constants, predictor_memory
from mrpctl.predictor import perturbed_spacecraft
from mrpctl.reproduction import paper_scenarios
from mrpctl.scenario import parse_scenario, scenario_toml
from mrpctl.spacecraft import Spacecraft

needs_compiler = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")

SC = paper.SPACECRAFT
LINEAR = Predictor(model=SC, form=PredictorForm.LINEAR)
X0 = np.array([0.3, -0.5, 0.2, 1.0, -0.5, 0.75])
SKEW = np.array([0.2, 0.4, 0.6, 0.3 / 4, -0.2 / 4, 0.25 / 4])


def test_the_default_is_the_nonlinear_form_and_a_bad_form_is_named() -> None:
    assert Predictor(model=SC).form is PredictorForm.NONLINEAR
    assert Predictor(model=SC, form="linear").form is PredictorForm.LINEAR  # the value of the enum is accepted
    assert "linear model copy" in str(LINEAR) and "group correction" in str(Predictor(model=SC))
    with pytest.raises(SpecificationError, match=r"form \(the predictor form\) must be one of 'nonlinear', 'linear'"):
        Predictor(model=SC, form="smith")


# ------------------------------------------------------------------ the linearisation both forms share
@pytest.mark.parametrize("layout", [InertiaInput.DIAGONAL, InertiaInput.FULL])
def test_both_forms_linearise_to_the_fsa_prediction(layout: InertiaInput) -> None:
    """At the origin (by central differences of step 1e-6) u = K x̂ with x̂ = [σ_y + τ w_y + S_σ; w_y + S_w]
    (S_σ = z_σ(k) − z_σ(k−d) − τ z_w(k−d), S_w = z_w(k) − z_w(k−d)), written here by hand, for either form; so is
    the copy's step (the ZOH transition of the linearised model, which RK4 gives exactly since A² = 0)."""
    model = Spacecraft(np.array([[140.0, 2.0, -1.0], [2.0, 100.0, 0.5], [-1.0, 0.5, 80.0]]))
    model = model if layout is InertiaInput.FULL else SC
    d, h, tau = 5, 0.01, 0.05
    gain = pd_gains(SC, zeta=1.0, omega_n=2.0).K
    constants = predictor_constants(None, tau, model)
    jacobians = {}
    for form in PredictorForm:
        core = predictor_core_function(SC, d, h, 1, model_inertia=layout, limited=False, form=form)
        x, delayed = ca.SX.sym("x", 6), ca.SX.sym("delayed", 12)
        z = ca.SX.sym("z", 6)
        memory = ca.vertcat(ca.DM(predictor_memory(np.zeros(6))[0:10]), z)
        out = core(x, memory, delayed, ca.DM(gain), ca.DM([1.0]), ca.DM(constants))
        outputs = ca.Function("f", [ca.vertcat(x, z, delayed)], [ca.vertcat(out[3], out[1][10:16])])
        # central differences (the nonlinear form's exact Jacobian at 0 has sqrt(0) in both if_else branches)
        step = 1e-6
        columns = [
            (np.array(outputs(step * e)) - np.array(outputs(-step * e))).ravel() / (2 * step) for e in np.eye(24)
        ]
        jacobians[form] = np.array(columns).T
    eye, zero = np.eye(3), np.zeros((3, 3))
    d_y = np.block([[eye, tau * eye], [zero, eye]])  # ∂x̂/∂y
    d_z = np.eye(6)  # ∂x̂/∂z_k
    d_z_old = -np.block([[eye, tau * eye], [zero, eye]])  # ∂x̂/∂z_{k−d}
    du = np.hstack((np.zeros((3, 6)), gain @ d_z, gain @ d_y, gain @ d_z_old))
    j_inv = model.inertia_inverse
    gamma = np.vstack((h * h / 8 * j_inv, h / 4 * j_inv))  # the ZOH input matrix of the model
    phi = np.block([[eye, h * eye], [zero, eye]])
    dz = np.hstack((np.zeros((6, 6)), phi, np.zeros((6, 12)))) + gamma @ du
    for form, jac in jacobians.items():
        np.testing.assert_allclose(jac[0:3], du, rtol=0, atol=1e-8 * np.abs(du).max(), err_msg=form.value)
        np.testing.assert_allclose(jac[3:9], dz, rtol=0, atol=1e-8, err_msg=form.value)
    scale = np.abs(jacobians[PredictorForm.NONLINEAR]).max()
    np.testing.assert_allclose(jacobians[PredictorForm.LINEAR], jacobians[PredictorForm.NONLINEAR], atol=1e-8 * scale)


def test_the_forms_differ_away_from_the_origin() -> None:
    """Not a vacuous option: on a skew-axis tumble the forms give other torques (both settle)."""
    gain = pd_gains(SC, zeta=1.0, omega_n=1.0).K
    runs = [
        simulate(SC, gain, SKEW, tau=0.2, rule=OnPredicted(1.0), t_final=3.0, rate=100.0, predictor=p)
        for p in (Predictor(model=SC), LINEAR)
    ]
    assert not np.array_equal(runs[0].u, runs[1].u)
    assert np.max(np.abs(runs[0].u - runs[1].u)) > 1e-3 * np.max(np.abs(runs[0].u))


# ------------------------------------------------------------------ lanes, files, command line
@needs_compiler
def test_lanes_equal_the_scalar_engine_bit_for_bit() -> None:
    gain = pd_gains(SC, zeta=1.0, omega_n=3.0).K
    states = np.array([X0 / 4, SKEW, -SKEW, X0 / 8])
    plants = [perturbed_spacecraft(SC, e) for e in (0.0, 0.1, -0.1, 0.05)]
    call: dict[str, Any] = dict(tau=0.5, rule=OnPredicted(1.0), t_final=4.0, rate=100.0, predictor=LINEAR)
    call |= dict(actuator=ActuatorModel(u_max=40.0), sensor=SensorModel(attitude_noise=1e-4, seed=3))
    batch = simulate_batch(plants, gain, states, trajectories=True, **call)
    assert batch.runs is not None
    for plant, x0, run in zip(plants, states, batch.runs, strict=True):
        single = simulate(plant, gain, x0, **call)
        for name in ("sigma", "omega", "u", "switch_indices"):
            assert np.array_equal(getattr(run, name), getattr(single, name)), name


def _scenario(form: str | None) -> dict[str, Any]:
    """The predictor scenario of tests/test_scenario_predictor.py, with ``form`` in its [predictor] table."""
    return copy.deepcopy(SCENARIO) | {"predictor": {} if form is None else {"form": form}}


@pytest.mark.parametrize(("form", "expected"), [(None, PredictorForm.NONLINEAR), ("linear", PredictorForm.LINEAR)])
def test_scenario_files_carry_the_form(form: str | None, expected: PredictorForm) -> None:
    scenario = parse_scenario(_scenario(form))
    assert scenario.predictor is not None and scenario.predictor.form is expected
    text = scenario_toml(scenario)
    assert ('form = "linear"' in text) == (expected is PredictorForm.LINEAR)
    back = parse_scenario(tomllib.loads(text))
    assert back.predictor is not None and back.predictor.form is expected


def test_a_bad_form_in_a_scenario_names_the_table_and_the_choices() -> None:
    with pytest.raises(SpecificationError, match=r"\[predictor\] form .*'nonlinear', 'linear', got 'fast'"):
        parse_scenario(_scenario("fast"))


@needs_compiler
def test_saved_runs_keep_the_form(tmp_path: Path) -> None:
    run = simulate(SC, paper.GAIN, X0 / 4, tau=0.5, rule=OnPredicted(1.0), t_final=1.0, rate=100.0, predictor=LINEAR)
    back = data.load(data.save(run, tmp_path / "linear.nc"))
    assert back.predictor is not None and back.predictor.form is PredictorForm.LINEAR
    assert np.array_equal(back.sigma, run.sigma) and str(back) == str(run)


@needs_compiler
def test_the_command_line_option_reaches_simulate(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "--predictor-form", "linear", "--t-final", "1.5", "--rate", "100", "--json"]
    assert main(argv) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["scenario"]["predictor_form"] == "linear" and out["result"]["rule"] == "on-predicted"
    x0 = paper_scenarios()["delay_aware"].x0  # the paper's example, the command's default without a file
    direct = simulate(SC, paper.GAIN, x0, tau=0.5, rule=OnPredicted(1.0), t_final=1.5, rate=100.0, predictor=LINEAR)
    np.testing.assert_array_equal(out["result"]["final_omega"], direct.omega[-1])


def test_a_bad_form_on_the_command_line_is_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as raised:  # argparse's choices: its one-line error, exit 2
        main(["simulate", "--predictor-form", "fast"])
    assert raised.value.code == USER_ERROR
    err = capsys.readouterr().err
    assert err.startswith("mrpctl simulate: error:") and err.count("\n") == 1, err
    assert "--predictor-form" in err and "'nonlinear', 'linear'" in err


# ------------------------------------------------------------------ export and campaigns
@needs_compiler
def test_the_exported_linear_loop_reproduces_simulate_bit_for_bit(tmp_path: Path) -> None:
    """The exported ``sample`` (through the compiled library) and the flight-software pieces, with the caller's own
    delay line, give simulate's numbers; the manifest names the form."""
    case: dict[str, Any] = dict(tau=0.2, rate=100.0, rule=OnPredicted(1.0), predictor=LINEAR)
    case |= dict(actuator=ActuatorModel(u_max=[60.0, 50.0, 40.0]), disturbance=[0.2, -0.1, 0.05])
    plant, gain, n, d = perturbed_spacecraft(SC, 0.1), pd_gains(SC, zeta=1.0, omega_n=1.0).K, 201, 20
    result = export(plant, gain, tmp_path / "linear", **case)
    manifest = json.loads((result.folder / MANIFEST_NAME).read_text(encoding="utf-8"))
    assert manifest["predictor"]["form_name"] == "linear"
    reference = simulate(plant, gain, X0, t_final=2.0, **case)
    assert result.library is not None
    sample = ca.external(C_PREFIX + "sample", str(result.library))
    controller = ca.Function.load(str(result.folder / "predictor_controller.casadi"))
    step = ca.Function.load(str(result.folder / "step.casadi"))
    sensor = ca.Function.load(str(result.folder / "sensor.casadi"))
    x, memory, ring, states = X0.copy(), predictor_memory(X0), [], []
    x_pieces, z, previous, measured, copies, torques = X0.copy(), predictor_memory(X0)[10:16], X0[0:3], [], [], []
    for k in range(n):
        out = [np.array(v).ravel() for v in sample(x, memory, np.concatenate((X0, X0)) if k < d else ring[k - d], 0)]
        x, memory = out[0], out[1]
        states.append(out[2])
        ring.append(out[5])
        x_pieces, seen = (np.array(v).ravel() for v in sensor(x_pieces, np.zeros(sensor.size1_in(1))))
        measured.append(seen)
        copies.append(z)
        y, z_old = (X0, X0) if k < d else (measured[k - d], copies[k - d])
        u, _, x_hat, _, z = (np.array(v).ravel() for v in controller(y, z_old, z, previous))
        torques.append(u)
        previous = x_hat[0:3]
        x_pieces = np.array(step(x_pieces, u + np.array(case["disturbance"]))).ravel()
    truth = np.hstack((reference.sigma, reference.omega / 4))
    assert np.array_equal(np.array(states), truth)
    assert np.array_equal(np.array(torques), reference.u)


CAMPAIGN: dict[str, Any] = {
    "name": "linear-predictor",
    "count": 6,
    "seed": 13,
    "tau": 0.05,
    "rate": 100.0,
    "t_final": 4.0,
    "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
    "gains": {"K1": -16.0, "K2": -8.0},
    "rule": {"type": "on-predicted"},
    "predictor": {"inertia_error": 0.05, "form": "linear"},
    "dispersions": {
        "attitude": {"angle_deg": [150.0, 180.0]},
        "omega": {"magnitude": [0.0, 0.5]},
        "inertia": {"axis_tolerance": 0.2, "product_tolerance": 2.0},
    },
}


@needs_compiler
def test_a_campaign_of_the_linear_form_equals_simulate_batch_and_replays(tmp_path: Path) -> None:
    spec = parse_campaign(copy.deepcopy(CAMPAIGN))
    assert spec.predictor is not None and spec.predictor.form is PredictorForm.LINEAR
    run_campaign(spec, tmp_path / "store", chunk=4, threads=2)
    ds = open_campaign(tmp_path / "store")
    assert json.loads(ds.attrs["predictor_form"]) == "linear"
    inputs = run_inputs(spec, 0, spec.count)
    model = Spacecraft(np.diag(1.0 / np.sqrt(np.full(3, 1.05))) @ np.diag([140.0, 100.0, 80.0]) @ np.diag(
        1.0 / np.sqrt(np.full(3, 1.05))
    ))  # fmt: skip
    batch = simulate_batch(
        [Spacecraft(j) for j in inputs.inertia],
        inputs.gain_scale[:, None, None] * spec.base.K[None],
        inputs.x0,
        tau=0.05,
        rule=OnPredicted(1.0),
        t_final=4.0,
        rate=100.0,
        predictor=Predictor(model, form=PredictorForm.LINEAR),
    )
    for name in METRICS:
        assert np.asarray(getattr(batch, name)).tobytes() == ds[name].values.tobytes(), name
    result = replay(tmp_path / "store", 2, trajectory=True)
    assert result.matches, result.mismatches


def test_a_bad_form_in_a_campaign_is_named() -> None:
    spec = copy.deepcopy(CAMPAIGN)
    spec["predictor"]["form"] = "quick"
    with pytest.raises(SpecificationError, match=r"\[predictor\] form .*got 'quick'"):
        parse_campaign(spec)
