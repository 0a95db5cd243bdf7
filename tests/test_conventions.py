"""The physical interface (σ, ω in rad/s; PD gains P_σ in N m, P_ω in N m s) against the paper's x / K form.

The conversions against values computed by hand; every physical-form entry point (simulate, simulate_batch,
scenario files, the command line, the export, python-control) against today's x / K run, bit for bit (the
bytes of every array, so the sign of every zero counts); bad input refused with the parameter named.
"""

from __future__ import annotations

import json
import re
import tomllib
from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from cli_assertions import one_line_error

import mrpctl
from mrpctl import paper
from mrpctl.cli import USER_ERROR, main
from mrpctl.conventions import (
    PDGains,
    feedback_gain,
    gain_from_parts,
    gain_parts,
    initial_state,
    physical_function,
    physical_port_names,
    state,
    state_parts,
)
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.loop import closed_loop_functions
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml

SIGMA0 = np.array([0.93, 0.0, 0.0])
OMEGA0 = np.array([0.46, 0.0, 0.0])


def _same_bytes(a: np.ndarray, b: np.ndarray) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


# ------------------------------------------------------------------------------ conversions by hand
def test_the_paper_gain_is_70_11_n_m_and_40_77_n_m_s() -> None:
    gains = PDGains.from_gain(paper.GAIN)
    # by hand: P_sigma = -K_sigma = 70.11 N m; P_omega = -K_x2 / 4 = 163.08 / 4 = 40.77 N m s
    assert np.array_equal(gains.attitude, 70.11 * np.eye(3)) and np.array_equal(gains.rate, 40.77 * np.eye(3))
    assert _same_bytes(PDGains(attitude=70.11, rate=40.77).gain(), paper.GAIN)  # -0.0 off the diagonal too
    assert _same_bytes(PDGains(attitude=[70.11] * 3, rate=[40.77] * 3).gain(), paper.GAIN)
    assert "70.11" in str(gains) and "40.77" in str(gains) and gains.is_diagonal


def test_a_full_gain_by_hand() -> None:
    attitude = np.array([[3.0, 0.5, 0.0], [-0.25, 2.0, 1.0], [0.0, 0.0, 1.5]])
    rate = np.array([[1.0, 0.0, -0.5], [0.0, 4.0, 0.0], [0.75, 0.0, 2.0]])
    K = PDGains(attitude=attitude, rate=rate).gain()
    expected = np.array(
        [
            [-3.0, -0.5, 0.0, -4.0, 0.0, 2.0],
            [0.25, -2.0, -1.0, 0.0, -16.0, 0.0],
            [0.0, 0.0, -1.5, -3.0, 0.0, -8.0],
        ]
    )
    assert np.array_equal(K, expected)
    # u = K x = -P_sigma sigma - P_omega omega on a state written out by hand
    sigma, omega = np.array([0.1, -0.2, 0.3]), np.array([0.4, 0.8, -1.2])
    x = np.array([0.1, -0.2, 0.3, 0.1, 0.2, -0.3])
    assert np.array_equal(state(sigma, omega), x)
    assert np.allclose(K @ x, -attitude @ sigma - rate @ omega, rtol=0, atol=1e-15)
    assert not PDGains(attitude=attitude, rate=rate).is_diagonal


def test_loop_gains_to_physical_by_hand() -> None:
    # sigma'' = K1 sigma + K2 sigma' with K1 = -0.64, K2 = -1.6 (zeta = 1, omega_n = 0.8 rad/s) on J = diag(12, 15, 9):
    # P_sigma = -4 J K1 = 2.56 J, P_omega = -J K2 = 1.6 J
    spacecraft = mrpctl.Spacecraft([12.0, 15.0, 9.0])
    gains = PDGains.from_loop_gains(spacecraft, [-0.64] * 3, [-1.6] * 3)
    assert np.allclose(np.diag(gains.attitude), [30.72, 38.4, 23.04], rtol=1e-15, atol=0)
    assert np.allclose(np.diag(gains.rate), [19.2, 24.0, 14.4], rtol=1e-15, atol=0)


def test_round_trips_keep_every_bit() -> None:
    rng = np.random.default_rng(24)
    for K in (paper.GAIN, rng.normal(size=(3, 6)) * 100, np.where(rng.random((3, 6)) < 0.5, -0.0, 0.0)):
        assert _same_bytes(PDGains.from_gain(K).gain(), np.asarray(K, dtype=float))
        assert _same_bytes(gain_from_parts(*gain_parts(K)), np.asarray(K, dtype=float))
    x = rng.normal(size=(5, 6))
    assert _same_bytes(state(*state_parts(x)), x)
    batch = rng.normal(size=(4, 3, 6))
    attitude, rate = gain_parts(batch)
    assert attitude.shape == rate.shape == (4, 3, 3) and _same_bytes(gain_from_parts(attitude, rate), batch)
    assert _same_bytes(feedback_gain(PDGains.from_gain(batch[0])), batch[0])


def test_initial_state_forms() -> None:
    x = state(SIGMA0, OMEGA0)
    assert _same_bytes(initial_state(sigma0=SIGMA0, omega0=OMEGA0), x)
    assert _same_bytes(initial_state(x), x)
    assert np.array_equal(initial_state(sigma0=SIGMA0), np.concatenate((SIGMA0, np.zeros(3))))  # at rest
    many = initial_state(sigma0=np.tile(SIGMA0, (4, 1)), omega0=OMEGA0, batch=True)
    assert many.shape == (4, 6) and all(_same_bytes(row, x) for row in many)


@pytest.mark.parametrize(
    ("build", "error", "pattern"),
    [
        (lambda: PDGains(attitude=-70.11, rate=40.77), SpecificationError, r"^attitude must be > 0"),
        (lambda: PDGains(attitude=70.11, rate=[40.77, 0.0, 1.0]), SpecificationError, r"^rate must be > 0"),
        (lambda: PDGains(attitude=[1.0, 2.0], rate=1.0), DimensionError, r"^attitude: expected a scalar, 3"),
        (lambda: PDGains(attitude=1.0, rate=np.ones((3, 4))), DimensionError, r"^rate: expected"),
        (lambda: PDGains(attitude=np.nan, rate=1.0), SpecificationError, r"^attitude must be finite"),
        (lambda: PDGains(attitude=1.0, rate=[1.0, np.inf, 1.0]), SpecificationError, r"^rate must be finite"),
        (lambda: PDGains.from_gain(np.ones((3, 5))), DimensionError, r"^K: expected shape \(3, 6\)"),
        (lambda: initial_state(), SpecificationError, r"^x0: give the initial state"),
        (lambda: initial_state(np.zeros(6), sigma0=SIGMA0), SpecificationError, r"^x0 and sigma0"),
        (lambda: initial_state(omega0=OMEGA0), SpecificationError, r"^sigma0: omega0 needs sigma0"),
        (lambda: initial_state(sigma0=[0.1, 0.2]), DimensionError, r"^sigma0: expected shape \(3\)"),
        (lambda: initial_state(sigma0=SIGMA0, omega0=[np.nan] * 3), SpecificationError, r"^omega0 must be finite"),
        (
            lambda: initial_state(sigma0=np.zeros((2, 3)), omega0=np.zeros((3, 3)), batch=True),
            DimensionError,
            r"^sigma0, omega0: one per run",
        ),
        (lambda: physical_port_names("x", 5), DimensionError, r"^x: a state port holds 6-row blocks"),
    ],
)
def test_bad_input_names_the_parameter(build, error, pattern) -> None:
    with pytest.raises(error, match=pattern):
        build()


def test_a_matrix_gain_is_taken_as_given() -> None:
    # A designed, coupled gain has no per-entry sign rule: a 3x3 matrix with a negative entry is accepted
    matrix = np.array([[2.0, -0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert np.array_equal(PDGains(attitude=matrix, rate=matrix).attitude, matrix)


# ------------------------------------------------------------------------------ simulate, simulate_batch
def test_simulate_in_physical_form_equals_the_x_k_run_bit_for_bit() -> None:
    rule = mrpctl.OnDelayed()
    common = dict(tau=0.5, rule=rule, t_final=3.0)
    today = mrpctl.simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common)
    sigma0, omega0 = paper.INITIAL_SIGMA, paper.INITIAL_OMEGA
    physical = mrpctl.simulate(paper.SPACECRAFT, PDGains(70.11, 40.77), sigma0=sigma0, omega0=omega0, **common)
    for name in ("t", "sigma", "omega", "u", "switch_indices", "sign_flips", "K", "x0"):
        assert _same_bytes(getattr(physical, name), getattr(today, name)), name
    assert physical.switch_count == today.switch_count > 0 and physical.max_sigma == today.max_sigma
    assert _same_bytes(physical.sigma0, sigma0) and _same_bytes(physical.omega0, omega0)
    assert _same_bytes(physical.gains.attitude, 70.11 * np.eye(3))
    assert _same_bytes(physical.x, today.x)


def test_simulate_of_the_flight_loop_in_physical_form() -> None:
    common = dict(tau=0.1, rule=Hysteretic(0.1), t_final=2.0, rate=100.0)
    today = mrpctl.simulate(paper.SPACECRAFT, paper.GAIN, state(SIGMA0, OMEGA0), **common)
    physical = mrpctl.simulate(paper.SPACECRAFT, PDGains.from_gain(paper.GAIN), sigma0=SIGMA0, omega0=OMEGA0, **common)
    for name in ("sigma", "omega", "u", "sigma_c", "command"):
        assert _same_bytes(getattr(physical, name), getattr(today, name)), name


def test_simulate_refuses_two_initial_states() -> None:
    with pytest.raises(SpecificationError, match="x0 and sigma0"):
        mrpctl.simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            paper.INITIAL_STATE,
            sigma0=SIGMA0,
            tau=0.0,
            rule=mrpctl.OnDelayed(),
            t_final=1,
        )
    with pytest.raises(SpecificationError, match=r"^x0: give the initial state"):
        mrpctl.simulate(paper.SPACECRAFT, paper.GAIN, tau=0.0, rule=mrpctl.OnDelayed(), t_final=1)
    with pytest.raises(SpecificationError, match=r"^attitude must be > 0"):
        PDGains(-70.11, -40.77)  # the paper-form numbers given as physical gains


@pytest.mark.parametrize("trajectories", [False, True])
def test_simulate_batch_in_physical_form_equals_the_x_k_batch(trajectories: bool) -> None:
    rng = np.random.default_rng(3)
    sigma0 = rng.uniform(-0.9, 0.9, (5, 3))
    omega0 = rng.uniform(-0.5, 0.5, (5, 3))
    gains = [PDGains(attitude=s * 70.11, rate=s * 40.77) for s in (0.9, 1.0, 1.1, 1.2, 0.8)]
    K = np.stack([g.gain() for g in gains])
    common = dict(tau=0.1, rule=mrpctl.DelayAware(), t_final=2.0, trajectories=trajectories, threads=1)
    today = mrpctl.simulate_batch(paper.SPACECRAFT, K, state(sigma0, omega0), **common)
    physical = mrpctl.simulate_batch(paper.SPACECRAFT, gains, sigma0=sigma0, omega0=omega0, **common)
    for name in ("x0", "K", "switch_count", "settling_time", "max_sigma", "peak_torque", "sign_flips"):
        assert _same_bytes(getattr(physical, name), getattr(today, name)), name
    assert _same_bytes(physical.sigma0, sigma0) and _same_bytes(physical.omega0, omega0)
    assert _same_bytes(physical.attitude_gain, np.stack([g.attitude for g in gains]))
    assert _same_bytes(physical.rate_gain, np.stack([g.rate for g in gains]))
    if trajectories:
        assert physical.runs is not None and today.runs is not None
        for a, b in zip(physical.runs, today.runs, strict=True):
            assert _same_bytes(a.omega, b.omega) and _same_bytes(a.u, b.u)
    one = mrpctl.simulate_batch(paper.SPACECRAFT, gains[1], sigma0=sigma0, omega0=omega0, **common)
    assert _same_bytes(one.K, np.broadcast_to(paper.GAIN, (5, 3, 6)))


# ------------------------------------------------------------------------------ scenarios
def test_a_scenario_with_physical_gains_is_the_paper_scenario() -> None:
    shipped = load_scenario("paper_fig4_on_delayed")
    data = tomllib.loads(Path(str(mrpctl.scenario.shipped_scenarios()["paper_fig4_on_delayed"])).read_text())
    data["gains"] = {"attitude": 70.11, "rate": 40.77}
    physical = parse_scenario(data)
    assert _same_bytes(physical.K, shipped.K) and _same_bytes(physical.x0, shipped.x0)
    assert _same_bytes(physical.gains.rate, 40.77 * np.eye(3)) and _same_bytes(physical.omega0, OMEGA0)
    short = replace(physical, t_final=2.0).simulate()
    reference = replace(shipped, t_final=2.0).simulate()
    assert _same_bytes(short.u, reference.u) and _same_bytes(short.sigma, reference.sigma)
    for bad, error, pattern in (
        ({"attitude": -70.11, "rate": 40.77}, SpecificationError, "attitude must be > 0"),
        ({"attitude": 70.11}, SpecificationError, r"\[gains\] must give exactly one of: attitude and rate"),
        ({"attitude": 70.11, "rate": 40.77, "K1": -1.0}, SpecificationError, r"\[gains\] must give exactly one"),
        ({"attitude": [1.0, 2.0], "rate": 1.0}, DimensionError, "attitude: expected a scalar"),
    ):
        with pytest.raises(error, match=pattern):
            parse_scenario({**data, "gains": bad})


def test_scenario_toml_writes_the_physical_form_and_reads_back_bit_for_bit() -> None:
    rng = np.random.default_rng(11)
    base = load_scenario("paper_fig4_on_delayed")
    for K in (base.K, rng.normal(size=(3, 6)) * 50, np.diag([-1.0, -2.0, -3.0]) @ np.hstack((np.eye(3), np.eye(3)))):
        scenario = replace(base, K=np.asarray(K))
        assert "\nK = [" in scenario_toml(scenario)  # the paper's K by default, the physical gains as comments
        text = scenario_toml(scenario, physical=True)
        assert "\nattitude = " in text and "\nrate = " in text and "\nK = [" not in text
        back = parse_scenario(tomllib.loads(text))
        assert _same_bytes(back.K, scenario.K)
    assert "\nattitude = [70.11, 70.11, 70.11]" in scenario_toml(base, physical=True)
    assert "#   attitude = [70.11, 70.11, 70.11]" in scenario_toml(base)
    unstable = replace(base, K=-base.K)  # positive K entries: written as 3x3 matrices, still exact
    assert _same_bytes(parse_scenario(tomllib.loads(scenario_toml(unstable, physical=True))).K, unstable.K)
    with pytest.raises(SpecificationError, match="physical must be True or False"):
        scenario_toml(base, physical="yes")


# ------------------------------------------------------------------------------ command line
def _simulate_json(argv: list[str], capsys: pytest.CaptureFixture[str]) -> dict:
    assert main(["simulate", *argv, "--tau", "0.1", "--t-final", "2", "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_the_cli_physical_gains_equal_the_paper_form(capsys: pytest.CaptureFixture[str]) -> None:
    state_args = ["--sigma", "0.5", "0.1", "0", "--omega", "0.2", "0", "-0.1"]
    physical = _simulate_json(["--attitude-gain", "70.11", "--rate-gain", "40.77", *state_args], capsys)
    paper_form = _simulate_json(["--k-sigma", "-70.11", "--k-omega", "-163.08", *state_args], capsys)
    assert physical["result"] == paper_form["result"] and physical["scenario"]["K"] == paper_form["scenario"]["K"]
    assert physical["scenario"]["attitude_gain"] == (70.11 * np.eye(3)).tolist()
    assert physical["scenario"]["rate_gain"] == (40.77 * np.eye(3)).tolist()
    assert physical["scenario"]["omega0"] == [0.2, 0.0, -0.1]


@pytest.mark.parametrize(
    ("argv", "needles"),
    [
        (["--attitude-gain", "-70.11", "--rate-gain", "40.77"], ("--attitude-gain", "must be > 0")),
        (["--attitude-gain", "70.11", "--rate-gain", "1", "2"], ("--rate-gain", "expected 1 value, 3")),
        (["--attitude-gain", "70.11"], ("--attitude-gain and --rate-gain go together",)),
        (["--attitude-gain", "1", "--rate-gain", "1", "--k-sigma", "-1", "--k-omega", "-1"], ("--k-sigma",)),
        (["--attitude-gain", "nan", "--rate-gain", "1"], ("--attitude-gain", "finite")),
    ],
)
def test_the_cli_refuses_bad_physical_gains(argv, needles, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", *argv, "--t-final", "1"]) == USER_ERROR
    one_line_error(capsys, *needles)


def test_verify_takes_the_physical_gains(capsys: pytest.CaptureFixture[str]) -> None:
    runs = []
    for gain in (["--attitude-gain", "70.11", "--rate-gain", "40.77"], ["--k-sigma", "-70.11", "--k-omega", "-163.08"]):
        assert main(["verify", *gain, "--orders", "1", "--json"]) in (0, 1)
        runs.append(re.sub(r"[0-9.]+ ms", "(time)", capsys.readouterr().out))  # solver times differ run to run
    assert runs[0] == runs[1] and json.loads(runs[0])["K"] == paper.GAIN.tolist()


# ------------------------------------------------------------------------------ export
def _cases() -> list[dict]:
    return [
        dict(rule=mrpctl.OnDelayed()),
        dict(rule=Hysteretic(0.1)),
        dict(rule=mrpctl.OnPredicted(1.0), predictor=mrpctl.Predictor(model=paper.SPACECRAFT)),
    ]


@pytest.mark.parametrize("case", range(3))
def test_physical_functions_equal_the_paper_functions_bit_for_bit(case: int) -> None:
    rng = np.random.default_rng(case)
    closed = closed_loop_functions(paper.SPACECRAFT, paper.GAIN, tau=0.003, rate=1000.0, **_cases()[case])
    for name, function in closed.functions().items():
        converted = physical_function(function)
        assert converted.name() == function.name()
        arguments = [rng.normal(size=function.size_in(i)) * 0.3 for i in range(function.n_in())]
        physical_arguments = []
        for i, value in enumerate(arguments):
            port = function.name_in(i)
            if port not in mrpctl.conventions.STATE_PORTS:
                physical_arguments.append(value)
                continue
            for block in range(value.shape[0] // 6):
                sigma, omega = state_parts(value[6 * block : 6 * block + 6].T)
                physical_arguments += [sigma.T, omega.T]
        expected = [np.array(out) for out in function.call([ca.DM(a) for a in arguments])]
        got = [np.array(out) for out in converted.call([ca.DM(a) for a in physical_arguments])]
        flat = []
        for i, value in enumerate(expected):
            if function.name_out(i) not in mrpctl.conventions.STATE_PORTS:
                flat.append(value)
                continue
            for block in range(value.shape[0] // 6):
                sigma, omega = state_parts(value[6 * block : 6 * block + 6].T)
                flat += [sigma.T, omega.T]
        assert len(flat) == len(got), name
        for a, b in zip(flat, got, strict=True):
            assert _same_bytes(np.ascontiguousarray(a), np.ascontiguousarray(b)), name


def test_physical_port_names() -> None:
    assert physical_port_names("x", 6) == ("sigma", "omega")
    assert physical_port_names("x_meas", 6) == ("sigma_meas", "omega_meas")
    assert physical_port_names("xdot", 6) == ("sigma_dot", "omega_dot")
    assert physical_port_names("history", 6) == ("history_sigma", "history_omega")
    assert physical_port_names("x_delayed", 12) == (
        "sigma_delayed",
        "omega_delayed",
        "z_sigma_delayed",
        "z_omega_delayed",
    )


def test_export_physical_writes_sigma_omega_ports(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "physical"
    assert main(["export", "paper_fig4_on_delayed", "--out", str(out), "--physical", "--tau", "0.005", "--json"]) == 0
    capsys.readouterr()
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["ports"]["form"] == "physical" and "rad/s" in manifest["state"]
    controller = manifest["functions"]["controller"]
    assert [p["name"] for p in controller["inputs"]] == ["sigma_meas", "omega_meas"]
    assert manifest["parameters"]["attitude_gain"] == (70.11 * np.eye(3)).tolist()
    assert manifest["parameters"]["rate_gain"] == (40.77 * np.eye(3)).tolist()
    loaded = ca.Function.load(str(out / "controller.casadi"))
    paper_controller = closed_loop_functions(
        paper.SPACECRAFT, paper.GAIN, tau=0.005, rule=mrpctl.OnDelayed()
    ).functions()["controller"]
    sigma, omega = np.array([0.3, -0.2, 0.1]), np.array([0.05, 0.4, -0.3])
    expected = np.array(paper_controller(state(sigma, omega)))
    assert _same_bytes(np.array(loaded(sigma, omega)), expected)
    if manifest["c"]["library"] is not None:
        external = ca.external("mrpctl_controller", str(out / manifest["c"]["library"]))
        assert external.name_in() == ["sigma_meas", "omega_meas"]
        assert _same_bytes(np.array(external(sigma, omega)), expected)
    with pytest.raises(SpecificationError, match="physical must be True or False"):
        mrpctl.export(paper.SPACECRAFT, paper.GAIN, tmp_path / "x", tau=0.0, rule=mrpctl.OnDelayed(), physical=1)


# ------------------------------------------------------------------------------ python-control
def test_python_control_in_physical_form() -> None:
    pytest.importorskip("control")
    from mrpctl.interop import PHYSICAL_LABELS, delayed_loop, from_time_response, to_time_response

    run = mrpctl.simulate(
        paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=0.5, rule=mrpctl.OnDelayed(), t_final=1
    )
    response = to_time_response(run, physical=True)
    assert (
        tuple(response.output_labels) == PHYSICAL_LABELS == ("sigma1", "sigma2", "sigma3", "omega1", "omega2", "omega3")
    )
    assert _same_bytes(np.ascontiguousarray(np.asarray(response.outputs).T[:, 3:]), run.omega)
    _, x, u = from_time_response(response)
    assert _same_bytes(np.ascontiguousarray(x), run.x) and _same_bytes(np.ascontiguousarray(u), run.u)
    paper_loop = delayed_loop(paper.SPACECRAFT, paper.GAIN, tau=0.5)
    physical_loop = delayed_loop(paper.SPACECRAFT, PDGains(70.11, 40.77), tau=0.5, physical=True)
    assert tuple(physical_loop.plant.state_labels) == PHYSICAL_LABELS
    assert np.array_equal(physical_loop.K, np.hstack((-70.11 * np.eye(3), -40.77 * np.eye(3))))
    assert np.array_equal(physical_loop.B[3:], paper.SPACECRAFT.inertia_inverse)
    # the same loop: the undelayed closed-loop poles and the Pade poles agree
    poles = np.sort_complex(np.linalg.eigvals(paper_loop.A + paper_loop.A_d))
    assert np.allclose(np.sort_complex(np.linalg.eigvals(physical_loop.A + physical_loop.A_d)), poles, atol=1e-12)
    pade = np.sort_complex(paper_loop.pade(4).poles())
    assert np.allclose(np.sort_complex(physical_loop.pade(4).poles()), pade, atol=1e-9)


# ------------------------------------------------------------------------------ campaigns
def test_a_campaign_with_physical_gains_runs_the_paper_form_bit_for_bit() -> None:
    from mrpctl.campaign import parse_campaign, run_inputs, simulate_chunk

    base = {
        "name": "units",
        "count": 4,
        "seed": 1,
        "tau": 0.05,
        "rate": 100.0,
        "t_final": 1.0,
        "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
        "rule": {"type": "on-delayed"},
        "initial": {"sigma": [0.5, 0.0, 0.0], "omega": [0.1, 0.0, 0.0]},
        "dispersions": {"omega": {"magnitude": [0.0, 0.2]}, "gains": {"scale": [0.9, 1.1]}},
    }
    physical = parse_campaign({**base, "gains": {"attitude": 70.11, "rate": 40.77}})
    paper_form = parse_campaign({**base, "gains": {"k_sigma": -70.11, "k_omega": -163.08}})
    assert _same_bytes(physical.base.K, paper_form.base.K)
    inputs = run_inputs(physical, 0, 4)
    assert _same_bytes(inputs.omega0, run_inputs(paper_form, 0, 4).omega0)
    # the rate dispersion is in rad/s: |omega0 - [0.1, 0, 0]| within the magnitude interval
    assert np.all(np.linalg.norm(inputs.omega0 - [0.1, 0.0, 0.0], axis=1) <= 0.2 + 1e-15)
    a, b = simulate_chunk(physical, 0, 4, threads=1), simulate_chunk(paper_form, 0, 4, threads=1)
    assert a.keys() == b.keys() and all(_same_bytes(a[key], b[key]) for key in a)
