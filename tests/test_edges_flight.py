"""The edges of the loop as flown and of the predictor: a right answer or a clear refusal.

An audit of issue 10's "Bad input" list and of the brief's trustworthiness rules for
``mrpctl.flight`` (Hysteretic, SensorModel, ActuatorModel, Disturbance, DelayModel) and
``mrpctl.predictor`` (Predictor, OnPredicted), through the Python API, scenario files and the
command line: every bad value is an error from :mod:`mrpctl.errors` naming the parameter (the CLI:
one line, exit 2); runs far from the paper's numbers (1 ms delay, 1 Hz and 100 kHz, J = 1e9 kg m²,
noise of 1e-300 and 10 rad) agree with the independent NumPy reference loops; thread pools and
concurrent callers give the serial bits; a damaged compile cache is rebuilt; a run that would not
fit is refused up front; an interrupted export keeps the old folder; saved runs keep their records.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import predictor_reference
import pytest
from flight_reference import reference_loop

from mrpctl import OnPredicted, Predictor, Spacecraft, data, mrp, paper, simulate, simulate_batch
from mrpctl._compile import find_compiler
from mrpctl.cli import main
from mrpctl.engines import scalar as _engine
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel
from mrpctl.scenario import parse_scenario, shipped_scenarios

needs_compiler = pytest.mark.skipif(find_compiler() is None, reason="no C compiler on this machine")

SC, K, X0 = paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE
REPO = Path(__file__).resolve().parents[1]


def _x(result: Any) -> np.ndarray:
    return np.hstack((result.sigma, result.omega / 4.0))


# ============================================================ bad input: the Python API
def _run(**options: Any) -> Any:
    base: dict[str, Any] = dict(tau=0.01, rule=Hysteretic(0.0), t_final=0.1)
    base.update(options)
    return simulate(SC, K, X0, **base)


BAD_API = [
    (
        "negative attitude noise",
        lambda: SensorModel(attitude_noise=-1e-3),
        SpecificationError,
        r"attitude_noise must be >= 0",
    ),
    (
        "NaN attitude noise",
        lambda: SensorModel(attitude_noise=math.nan),
        SpecificationError,
        r"attitude_noise must be finite",
    ),
    # before the fix: accepted, the squared error angle overflowed and the run was "DIVERGED at 0.011 s"
    (
        "attitude noise 1e160 rad",
        lambda: SensorModel(attitude_noise=1e160),
        SpecificationError,
        r"attitude_noise must be <=",
    ),
    ("NaN rate noise", lambda: SensorModel(rate_noise=math.nan), SpecificationError, r"rate_noise must be finite"),
    ("infinite rate noise", lambda: SensorModel(rate_noise=math.inf), SpecificationError, r"rate_noise must be finite"),
    ("gyro bias of 2", lambda: SensorModel(gyro_bias=[1e-3, 0.0]), DimensionError, r"gyro_bias: expected shape"),
    ("negative seed", lambda: SensorModel(seed=-1), SpecificationError, r"seed must be >= 0"),
    ("delta = 1", lambda: Hysteretic(1.0), SpecificationError, r"delta .* must be in \[0, 1\)"),
    ("delta < 0", lambda: Hysteretic(-0.1), SpecificationError, r"delta .* must be in \[0, 1\)"),
    ("NaN delta", lambda: Hysteretic(math.nan), SpecificationError, r"delta must be finite"),
    ("boolean delta", lambda: Hysteretic(True), SpecificationError, r"delta must be a real number"),
    ("alpha < 1", lambda: Hysteretic.from_alpha(0.5), SpecificationError, r"alpha .* must be >= 1"),
    ("infinite alpha", lambda: Hysteretic.from_alpha(math.inf), SpecificationError, r"alpha must be finite"),
    # before the fix: OverflowError from alpha**2 (not a ValueError, a traceback in the CLI)
    ("alpha = 1e200", lambda: Hysteretic.from_alpha(1e200), SpecificationError, r"alpha .* too large"),
    # before the fix: "delta ... must be in [0, 1), got 1.0" for an alpha the user gave
    ("alpha = 1e8", lambda: Hysteretic.from_alpha(1e8), SpecificationError, r"alpha .* = 1e\+08 is too large"),
    ("u_max = 0", lambda: ActuatorModel(0.0), SpecificationError, r"u_max .* must be > 0"),
    ("u_max < 0 on one axis", lambda: ActuatorModel([1.0, -1.0, 1.0]), SpecificationError, r"u_max .* must be > 0"),
    ("NaN u_max", lambda: ActuatorModel(math.nan), SpecificationError, r"u_max must be finite"),
    ("u_max of 2", lambda: ActuatorModel([1.0, 2.0]), DimensionError, r"u_max: expected a scalar or shape \(3,\)"),
    ("norm_max = 0", lambda: ActuatorModel(1.0, norm_max=0.0), SpecificationError, r"norm_max must be > 0"),
    (
        "mode as a string",
        lambda: ActuatorModel(1.0, mode="clip"),  # type: ignore[arg-type]
        SpecificationError,
        r"mode must be",
    ),
    (
        "delay outside [tau_min, tau_max]",
        lambda: DelayModel.sequence([0.1, 0.6], tau_min=0.1, tau_max=0.5),
        SpecificationError,
        r"delays must lie in \[tau_min, tau_max\].*delays\[1\]",
    ),
    (
        "delays (1, 1)",
        lambda: DelayModel.sequence([[0.1]], tau_min=0.1, tau_max=0.5),
        DimensionError,
        r"delays: expected",
    ),
    ("no delays", lambda: DelayModel.sequence([], tau_min=0.1, tau_max=0.5), DimensionError, r"delays: expected"),
    ("tau_min < 0", lambda: DelayModel.jitter(-0.1, 0.5), SpecificationError, r"tau_min must be >= 0"),
    ("tau_max < tau_min", lambda: DelayModel.jitter(0.5, 0.1), SpecificationError, r"tau_max must be >= tau_min"),
    ("NaN tau_min", lambda: DelayModel.jitter(math.nan, 0.5), SpecificationError, r"tau_min must be finite"),
    ("torque (2,)", lambda: Disturbance([1.0, 2.0]), DimensionError, r"torque: expected shape \(3,\) or \(n, 3\)"),
    ("torque (0, 3)", lambda: Disturbance(np.zeros((0, 3))), DimensionError, r"torque: expected shape"),
    ("torque (2, 2, 3)", lambda: Disturbance(np.zeros((2, 2, 3))), DimensionError, r"torque: expected shape"),
    ("NaN torque", lambda: Disturbance([math.nan, 0.0, 0.0]), SpecificationError, r"torque must be finite"),
    ("raw NaN torque", lambda: _run(disturbance=[math.nan, 0.0, 0.0]), SpecificationError, r"torque must be finite"),
    ("raw torque (2,)", lambda: _run(disturbance=[1.0, 0.0]), DimensionError, r"torque: expected shape"),
    ("torque rows != n", lambda: _run(disturbance=np.zeros((50, 3))), DimensionError, r"\(n, 3\) = \(101, 3\)"),
    (
        "w(t) of the wrong shape",
        lambda: _run(disturbance=Disturbance(function=lambda t: np.zeros(len(t)))),
        DimensionError,
        r"function .* expected shape \(101, 3\)",
    ),
    (
        "delays != n",
        lambda: _run(tau=0.5, delay=DelayModel.sequence(np.full(50, 0.5), tau_min=0.4, tau_max=0.5)),
        DimensionError,
        r"delays: expected shape \(n,\) = \(101,\)",
    ),
    (
        "delays not whole periods",
        lambda: _run(tau=0.5, delay=DelayModel.sequence(np.full(101, 0.4505), tau_min=0.4, tau_max=0.5)),
        SpecificationError,
        r"delays must be whole numbers of measurement periods",
    ),
    (
        "jitter not whole periods",
        lambda: _run(tau=0.5, delay=DelayModel.jitter(0.4505, 0.5)),
        SpecificationError,
        r"tau_min, tau_max must be whole numbers",
    ),
    ("tau != tau_max", lambda: _run(tau=0.4, delay=DelayModel.jitter(0.4, 0.5)), SpecificationError, r"tau_max"),
    ("jitter tau_min = 0", lambda: _run(tau=0.5, delay=DelayModel.jitter(0.0, 0.5)), SpecificationError, r"tau_min"),
    ("tau < 1/rate", lambda: _run(tau=0.0005), SpecificationError, r"tau \* rate must be a whole number"),
    ("tau not a multiple of 1/rate", lambda: _run(tau=0.0015), SpecificationError, r"tau \* rate"),
    (
        "predictor model not a Spacecraft",
        lambda: Predictor(model=[1, 2, 3]),  # type: ignore[arg-type]
        SpecificationError,
        r"model must be",
    ),
    ("OnPredicted alpha < 1", lambda: OnPredicted(0.5), SpecificationError, r"alpha .* must be >= 1"),
    ("OnPredicted NaN alpha", lambda: OnPredicted(math.nan), SpecificationError, r"alpha must be finite"),
    (
        "predictor, tau not whole periods",
        lambda: _run(tau=0.0015, rule=OnPredicted(), predictor=Predictor(SC)),
        SpecificationError,
        r"tau \* rate",
    ),
    (
        "predictor with Hysteretic",
        lambda: _run(predictor=Predictor(SC)),
        SpecificationError,
        r"rule: with a predictor .*OnPredicted",
    ),
    (
        "predictor with jitter",
        lambda: _run(tau=0.5, rule=OnPredicted(), predictor=Predictor(SC), delay=DelayModel.jitter(0.4, 0.5)),
        SpecificationError,
        r"delay: the predictor runs with the constant delay",
    ),
    # a second audit (this session): NumPy reads [20, 20, True] as [20, 20, 1] and "0.5" as 0.5
    ("a boolean among u_max", lambda: ActuatorModel([20, 20, True]), SpecificationError, r"u_max .* booleans"),
    ("a boolean among a torque", lambda: Disturbance([1e-3, 0, True]), SpecificationError, r"torque .* booleans"),
    (
        "a boolean in x0",
        lambda: simulate(SC, K, [*X0[:5], True], tau=0.01, rule=Hysteretic(0.0), t_final=0.1),
        SpecificationError,
        r"x0 must be numeric, got booleans",
    ),
    ("a string noise", lambda: SensorModel(attitude_noise="0.01"), SpecificationError, r"attitude_noise .* string"),
    ("a string u_max", lambda: ActuatorModel("20"), SpecificationError, r"u_max must be numeric, got strings"),
    ("a string in gyro_bias", lambda: SensorModel(gyro_bias=[0, "1", 0]), SpecificationError, r"gyro_bias .* str"),
    ("a string delta", lambda: Hysteretic("0.5"), SpecificationError, r"delta must be a real number"),
    ("a string rate", lambda: _run(rate="1000"), SpecificationError, r"rate must be a real number"),
    ("rate noise 1e7", lambda: SensorModel(rate_noise=1e7), SpecificationError, r"rate_noise must be <= 1e\+06"),
    ("gyro bias 1e153", lambda: SensorModel(gyro_bias=[1e153, 0, 0]), SpecificationError, r"gyro_bias must be <="),
    (
        "t_final 1e300",
        lambda: _run(t_final=1e300, keep_every=None),
        SpecificationError,
        r"t_final: .*\(limit 1e\+12 samples",
    ),
    (
        "a long horizon, metrics only",
        lambda: _run(t_final=1e17, keep_every=10**18),
        SpecificationError,
        r"t_final \* rate = 1e\+20 samples",
    ),
    ("tau * rate = inf", lambda: _run(tau=1e300, rate=1e10), SpecificationError, r"below 2\^53"),
    (
        "jitter's arrival ring beyond memory",
        lambda: _run(tau=5000.0, rate=1e6, t_final=1e-3, delay=DelayModel.jitter(1e-6, 5000.0), memory_limit=1e9),
        SpecificationError,
        r"needs about 40 GB .* the delay's buffers",
    ),
]


@pytest.mark.parametrize(("case", "build", "error", "match"), BAD_API, ids=[case[0] for case in BAD_API])
def test_bad_input_is_a_clear_error_naming_the_parameter(case, build, error, match):
    with pytest.raises(error, match=match):
        build()


def test_a_delay_of_millions_of_samples_is_a_whole_number_to_a_relative_tolerance():
    """16.3441 s at 1 MHz is 16 344 100 periods; the product's rounding (16344100.000000002) is 2e-9 absolute, far
    below one ulp's relative size: accepted, as the scenario loader accepts it (both relative, 1e-9)."""
    from mrpctl.loop import delay_samples

    assert delay_samples(16.3441, 1e6) == 16_344_100
    assert tuple(DelayModel.jitter(16.3441, 16.3441).bounds(1e6)) == (16_344_100, 16_344_100)
    with pytest.raises(SpecificationError, match=r"tau \* rate must be a whole number"):
        delay_samples(16.3441 + 1e-7, 1e6)


def test_the_largest_alpha_that_is_accepted_keeps_its_bound():
    # alpha up to ~9.7e7 gives delta < 1; the rule's bound sqrt((1 + delta)/(1 - delta)) is then
    # alpha to the resolution of delta near 1 (an ulp of 1 - delta), so compare with that accuracy.
    for alpha in (1.0, 1.2, 10.0, 1e3, 1e7):
        rule = Hysteretic.from_alpha(alpha)
        resolution = np.spacing(1.0) / (1.0 - rule.delta)
        assert 0.0 <= rule.delta < 1.0
        assert rule.alpha == pytest.approx(alpha, rel=max(4e-16, resolution))


# ============================================================== bad input: scenario files
def _flight_paper() -> dict[str, Any]:
    return tomllib.loads(shipped_scenarios()["flight-paper"].read_text())


def _predictor_paper() -> dict[str, Any]:
    return tomllib.loads(shipped_scenarios()["predictor-paper"].read_text())


BAD_TOML = [
    # (table, key, value, match); table None: the top level
    ("actuator", "saturation", ["scale"], r"\[actuator\] saturation must be one of"),  # was TypeError: unhashable
    ("actuator", "saturation", {"mode": "scale"}, r"\[actuator\] saturation must be one of"),  # was TypeError
    ("actuator", "saturation", 3, r"\[actuator\] saturation must be one of"),
    ("actuator", "u_max", 0.0, r"\[actuator\] u_max .* must be > 0"),
    ("actuator", "u_max", [1.0, 2.0], r"\[actuator\] u_max: expected"),
    ("actuator", "u_norm", "x", r"\[actuator\] u_norm must be a real number"),
    ("sensor", "attitude_noise", -0.01, r"\[sensor\] attitude_noise must be >= 0"),
    ("sensor", "attitude_noise", math.nan, r"\[sensor\] attitude_noise must be finite"),
    ("sensor", "gyro_bias", [0.0, 0.0], r"\[sensor\] gyro_bias: expected"),
    ("sensor", "seed", -1, r"\[sensor\] seed must be >= 0"),
    ("sensor", "seed", 1.5, r"\[sensor\] seed must be an integer"),
    ("disturbance", "torque", [1e-3, 0.0], r"\[disturbance\] torque: expected"),
    ("disturbance", "torque", [[1e-3, 0.0, 0.0]], r"\[disturbance\] torque: expected"),
    ("disturbance", "torque", [math.nan, 0.0, 0.0], r"\[disturbance\] torque must be finite"),
    ("delay", "tau_min", 0.0, r"\[delay\] tau_min must be >= 1/rate"),
    ("delay", "tau_min", -0.1, r"\[delay\] tau_min must be >= 0"),
    ("delay", "tau_min", 0.6, r"\[delay\] tau_max must be >= tau_min"),
    ("delay", "tau_min", 0.4505, r"\[delay\] tau_min: delays must be whole numbers of measurement periods"),
    ("delay", "tau_max", 0.4, r"\[delay\] tau_max must equal the scenario's tau"),
    ("rule", "alpha", 1e200, r"\[rule\] alpha .* too large"),  # was OverflowError
    ("rule", "alpha", [1.2], r"\[rule\] alpha must be a real number"),
    (None, "tau", 0.0005, r"tau \* rate must be a whole number"),
]


@pytest.mark.parametrize(
    ("table", "key", "value", "match"), BAD_TOML, ids=[f"{c[0]}.{c[1]}={c[2]!r}" for c in BAD_TOML]
)
def test_bad_scenario_values_name_the_table_and_key(table, key, value, match):
    scenario = _flight_paper()
    (scenario if table is None else scenario[table])[key] = value
    with pytest.raises((SpecificationError, DimensionError), match=match):
        parse_scenario(scenario)


def test_bad_predictor_scenario_values_name_the_table_and_key():
    for key, value, match in (
        ("inertia_error", -1.0, r"\[predictor\] inertia_error: each relative error must be > -1"),
        ("inertia_error", [0.1, 0.2], r"\[predictor\] inertia_error: expected"),
        ("inertia", [1.0, -2.0, 3.0], r"\[predictor\] .*positive definite"),
    ):
        scenario = _predictor_paper()
        scenario["predictor"] = {key: value}
        with pytest.raises((SpecificationError, DimensionError), match=match):
            parse_scenario(scenario)


def test_a_campaign_saturation_that_is_not_a_string_is_refused():
    from mrpctl.campaign.spec import parse_campaign

    text = (REPO / "examples" / "campaigns" / "tumble.toml").read_text()
    campaign = tomllib.loads(text)
    campaign["flight"] = {"u_max": 20.0, "saturation": ["clip"]}  # was TypeError: unhashable type: 'list'
    with pytest.raises(SpecificationError, match=r"flight.saturation must be one of"):
        parse_campaign(campaign)


# ===================================================================== bad input: the CLI
def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = main(argv)
    return code, capsys.readouterr().err


BAD_CLI = [
    (["--attitude-noise", "-1"], "--attitude-noise: attitude_noise must be >= 0"),
    (["--attitude-noise", "nan"], "--attitude-noise: attitude_noise must be finite"),
    (["--rate-noise", "inf"], "--rate-noise: rate_noise must be finite"),
    (["--gyro-bias", "1", "2", "nan"], "--gyro-bias: gyro_bias must be finite"),
    (["--noise-seed", "-3"], "--noise-seed: seed must be >= 0"),
    (["--hysteresis", "1"], "--hysteresis: delta"),
    (["--hysteresis", "nan"], "--hysteresis: delta must be finite"),
    (
        ["--rule", "hysteretic", "--alpha", "1e200"],
        "alpha (bound on |sigma_c|) = 1e+200 is too large",
    ),  # was a traceback
    (["--rule", "hysteretic", "--alpha", "1e8"], "alpha (bound on |sigma_c|) = 1e+08 is too large"),
    (["--torque-limit", "0"], "--torque-limit: u_max"),
    (["--torque-limit", "1", "2"], "--torque-limit: expected 1 or 3 values"),
    (["--torque-limit", "nan"], "--torque-limit: u_max must be finite"),
    (["--torque-norm", "0"], "--torque-norm: norm_max must be > 0"),
    (["--disturbance", "nan", "0", "0"], "--disturbance: torque must be finite"),
    (["--jitter", "0", "0.5"], "--jitter: TMIN must be >= 1/rate"),
    (["--jitter", "0.5", "0.4"], "--jitter: tau_max must be >= tau_min"),
    (["--jitter", "0.4505", "0.5"], "--jitter: tau_min, tau_max must be whole numbers"),
    (["--jitter", "0.4", "0.5", "--jitter-seed", "-1"], "--jitter: seed must be >= 0"),
    (["--tau", "0.3"], "tau_max = 0.5 s must equal tau = 0.3 s"),
    (["--rate", "0"], "rate must be > 0"),  # was "--jitter: rate must be > 0": the scenario's jitter was blamed
    (["--t-final", "1e9"], "more than the"),  # refused up front with the estimate
    # the flag that is wrong, not the first one of its model (a second audit)
    (["--torque-limit", "1", "2", "3", "--torque-norm", "nan"], "--torque-norm: norm_max must be finite"),
    (["--attitude-noise", "0.01", "--rate-noise", "nan"], "--rate-noise: rate_noise must be finite"),
    (["--rate", "999"], "the scenario's [delay] at rate = 999 Hz: tau_min, tau_max must be whole numbers"),
]


@pytest.mark.parametrize(("options", "message"), BAD_CLI, ids=[" ".join(c[0]) for c in BAD_CLI])
def test_cli_bad_flight_options_print_one_line_and_exit_2(options, message, capsys):
    code, err = _cli(["simulate", "flight-paper", "--t-final", "0.5", *options], capsys)
    assert code == 2
    assert err.startswith("mrpctl: error: ") and err.count("\n") == 1, err
    assert message in err
    if options[0] == "--rate":
        assert "--jitter" not in err
    if options[0] == "--torque-limit" and "--torque-norm" in options:
        assert "--torque-limit" not in err
    if options[0] == "--t-final":
        assert "TB" in err and "--t-final" in err  # the estimate and the way out


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--attitude-noise", "abc"], "argument --attitude-noise: invalid float value: 'abc'"),
        (["--noise-seed", "1.5"], "argument --noise-seed: invalid int value: '1.5'"),
        (["--gyro-bias", "0", "0"], "argument --gyro-bias: expected 3 arguments"),
        (["--saturation", "foo"], "argument --saturation: invalid choice: 'foo'"),
    ],
)
def test_cli_usage_errors_are_one_line_too(options, message, capsys):
    """argparse's own refusals (a value of the wrong type, too few values) printed the whole usage first."""
    with pytest.raises(SystemExit) as exit_info:
        main(["simulate", "flight-paper", "--t-final", "0.5", *options])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2
    assert err.startswith("mrpctl simulate: error: ") and err.count("\n") == 1, err
    assert message in err and "(see mrpctl simulate --help)" in err


@pytest.mark.parametrize(
    ("options", "message"),
    [
        (["--predictor-error", "-1"], "--predictor-error: inertia_error: each relative error must be > -1"),
        (["--predictor-error", "1", "2"], "--predictor-error: expected 1 or 3"),
        (["--predictor-inertia", "1", "-2", "3"], "--predictor-inertia: inertia must be positive definite"),
        (["--predictor-inertia", "1", "2", "3", "4"], "--predictor-inertia: expected 3 principal values or 9"),
        (["--tau", "0.0015"], "tau * rate must be a whole number"),
        (["--jitter", "0.4", "0.5"], "--jitter does not apply with the predictor"),
        (["--history", "zero-input"], "--history zero-input"),
    ],
)
def test_cli_bad_predictor_options_print_one_line_and_exit_2(options, message, capsys):
    code, err = _cli(["simulate", "predictor-paper", "--t-final", "0.5", *options], capsys)
    assert code == 2 and err.startswith("mrpctl: error: ") and err.count("\n") == 1, err
    assert message in err


def test_cli_bad_scenario_file_values_print_one_line(tmp_path, capsys):
    text = shipped_scenarios()["flight-paper"].read_text()
    for old, new, message in (
        ('saturation = "scale"', 'saturation = ["scale"]', "[actuator] saturation must be one of"),
        ("alpha = 1.2", "alpha = 1e200", "[rule] alpha (bound on |sigma_c|) = 1e+200 is too large"),
    ):
        assert old in text
        path = tmp_path / "bad.toml"
        path.write_text(text.replace(old, new))
        code, err = _cli(["simulate", str(path)], capsys)
        assert code == 2 and err.count("\n") == 1 and message in err, err


def test_cli_overrides_that_change_n_name_the_scenario_s_per_sample_file(tmp_path, capsys):
    """A second audit: --t-final / --rate against a scenario's torque_file or sequence_file was refused as
    "torque: expected shape (n, 3) = (2001, 3) ..." without naming the file or the override."""
    text = shipped_scenarios()["flight-paper"].read_text().replace("t_final = 60.0", "t_final = 1.0")
    np.save(tmp_path / "rows.npy", np.zeros((1001, 3)))
    np.save(tmp_path / "d.npy", np.full(1001, 0.5))
    files = {
        "[disturbance] torque_file": text.replace("torque = [1e-3, 0.0, 0.0]", 'torque_file = "rows.npy"'),
        "[delay] sequence_file": text.replace("seed = 2\n", 'sequence_file = "d.npy"\n'),
    }
    for where, scenario in files.items():
        assert scenario != text
        path = tmp_path / "scenario.toml"
        path.write_text(scenario)
        for option in (["--t-final", "2"], ["--rate", "2000"]):
            code, err = _cli(["simulate", str(path), *option], capsys)
            assert code == 2 and err.count("\n") == 1, err
            assert f"{option[0]} {option[1]} gives n = 2001 samples, but the scenario's {where} has 1001 rows" in err


# ======================================================== scale: against the reference loops
@needs_compiler
def test_one_sample_delay_at_1khz_with_noise_equals_the_reference():
    sensor = SensorModel(0.01, 1e-3, seed=4)
    run = simulate(SC, K, X0, tau=0.001, rule=Hysteretic(0.05), t_final=1.0, sensor=sensor)
    ref = reference_loop(SC.inertia, K, X0, rate=1000.0, t_final=1.0, delta=0.05, delays=1, sensors=sensor)
    assert run.delay_samples == 1 and run.delay_used.tolist() == ref.delay_used.tolist()
    assert run.switch_indices.tolist() == ref.logic_switch_samples().tolist()
    assert np.max(np.abs(run.sigma - ref.sigma[0])) < 1e-12
    assert np.max(np.abs(run.omega - ref.omega[0])) < 1e-12 * np.max(np.abs(ref.omega[0]))


@needs_compiler
@pytest.mark.parametrize(("tau", "substeps"), [(1.0, 1), (2.0, 8)])
def test_1hz_flight_loop_equals_the_reference(tau, substeps):
    # 1 Hz: the paper's gains sample far too slowly, the run tumbles through several logic switches
    sensor = SensorModel(0.01, 1e-3, seed=4)
    common = dict(rate=1.0, t_final=30.0, substeps=substeps)
    run = simulate(SC, K, X0, tau=tau, rule=Hysteretic(0.0), sensor=sensor, **common)
    ref = reference_loop(SC.inertia, K, X0, delta=0.0, delays=round(tau), sensors=sensor, **common)
    assert run.switch_count >= 2
    assert run.switch_indices.tolist() == ref.logic_switch_samples().tolist()
    assert np.max(np.abs(run.sigma - ref.sigma[0])) < 1e-13
    assert np.max(np.abs(run.omega - ref.omega[0])) < 1e-13 * np.max(np.abs(ref.omega[0]))


@needs_compiler
def test_100khz_jitter_below_a_millisecond_equals_the_reference():
    rate, t_final = 1e5, 0.02
    n = math.floor(t_final * rate + 1e-9) + 1
    jitter = DelayModel.jitter(0.0005, 0.001, seed=7)  # 50 … 100 samples
    sensor = SensorModel(0.01, 1e-3, seed=3)
    run = simulate(SC, K, X0, tau=0.001, rate=rate, rule=Hysteretic(0.1), t_final=t_final, sensor=sensor, delay=jitter)
    ref = reference_loop(
        SC.inertia,
        K,
        X0,
        rate=rate,
        t_final=t_final,
        delta=0.1,
        delays=jitter.samples(rate, 0, n),
        history=100,
        sensors=sensor,
    )
    assert len(run.t) == n and set(run.delay_used[100:].tolist()) <= set(range(50, 101))
    assert run.delay_used.tolist() == ref.delay_used.tolist()
    assert np.max(np.abs(run.sigma - ref.sigma[0])) < 1e-13
    assert np.max(np.abs(run.omega - ref.omega[0])) < 1e-13 * np.max(np.abs(ref.omega[0]))


@needs_compiler
def test_jitter_with_tau_min_equal_to_tau_max_is_the_constant_delay():
    sensor = SensorModel(0.01, seed=1)
    common = dict(tau=0.5, rule=Hysteretic(0.0), t_final=1.5, sensor=sensor)
    fixed = simulate(SC, K, X0, **common)
    jitter = simulate(SC, K, X0, delay=DelayModel.jitter(0.5, 0.5, seed=7), **common)
    assert set(jitter.delay_used.tolist()) == {500}
    assert np.array_equal(jitter.sigma, fixed.sigma) and np.array_equal(jitter.u, fixed.u)
    assert jitter.switch_indices.tolist() == fixed.switch_indices.tolist()


@needs_compiler
def test_huge_inertia_with_huge_limits_is_the_scaled_paper_loop():
    # J, K and u_max all times 1e7 (J = 1.4e9 kg m^2): the same MRP trajectory, torques times 1e7
    sensor = SensorModel(0.01, 1e-3, seed=4)
    common = dict(tau=0.5, rule=Hysteretic(0.1), t_final=1.5, sensor=sensor)
    small = simulate(SC, K, X0, actuator=ActuatorModel(20.0), **common)
    big = simulate(Spacecraft(SC.inertia * 1e7), K * 1e7, X0, actuator=ActuatorModel(2e8), **common)
    assert small.saturated_fraction == big.saturated_fraction > 0.1
    assert big.switch_indices.tolist() == small.switch_indices.tolist()
    assert np.max(np.abs(big.sigma - small.sigma)) < 1e-14
    assert np.max(np.abs(big.u - 1e7 * small.u)) < 1e-14 * np.max(np.abs(big.u))
    ref = reference_loop(
        SC.inertia * 1e7, K * 1e7, X0, rate=1000.0, t_final=1.5, delta=0.1, delays=500, sensors=sensor, u_max=2e8
    )
    assert np.max(np.abs(big.sigma - ref.sigma[0])) < 1e-12
    assert np.max(np.abs(big.u - ref.u_applied[0])) < 1e-12 * np.max(np.abs(ref.u_applied[0]))


@needs_compiler
def test_tiny_noise_is_a_tiny_perturbation_and_huge_noise_matches_the_reference():
    quiet = simulate(SC, K, X0, tau=0.5, rule=Hysteretic(0.0), t_final=1.5)
    tiny = simulate(SC, K, X0, tau=0.5, rule=Hysteretic(0.0), t_final=1.5, sensor=SensorModel(1e-300, 1e-300, seed=1))
    assert tiny.switch_indices.tolist() == quiet.switch_indices.tolist() == [944]
    assert 0.0 < np.max(np.abs(tiny.sigma - quiet.sigma)) < 1e-290  # noise present, subnormal-safe
    # pi rad per axis (the largest accepted): rotations of any angle (|theta| > 2 pi included), composed through MRPs
    loud = SensorModel(math.pi, 0.0, seed=2)
    run = simulate(SC, K, X0, tau=0.01, rule=Hysteretic(0.2), t_final=0.5, sensor=loud)
    ref = reference_loop(SC.inertia, K, X0, rate=1000.0, t_final=0.5, delta=0.2, delays=10, sensors=loud)
    assert run.switch_count > 50 and np.all(np.isfinite(run.u))
    assert run.switch_indices.tolist() == ref.logic_switch_samples().tolist()
    assert np.max(np.abs(run.u - ref.u_applied[0])) < 1e-12 * np.max(np.abs(ref.u_applied[0]))
    # the largest accepted 1 sigma still gives finite measurements, the reference's
    widest = SensorModel(math.pi, 0.0, seed=2)
    run = simulate(SC, K, X0, tau=0.01, rule=Hysteretic(0.2), t_final=0.1, sensor=widest)
    ref = reference_loop(SC.inertia, K, X0, rate=1000.0, t_final=0.1, delta=0.2, delays=10, sensors=widest)
    assert not run.diverged and not ref.diverged[0] and run.switch_count > 5
    assert run.switch_indices.tolist() == ref.logic_switch_samples().tolist()
    assert np.max(np.abs(run.u - ref.u_applied[0])) < 1e-12 * np.max(np.abs(ref.u_applied[0]))


@needs_compiler
def test_a_horizon_shorter_than_tau_and_keep_every_beyond_n():
    # Only the constant history arrives before tau: u = K x0 at every sample, exactly.
    flown = simulate(SC, K, X0, tau=0.5, rule=Hysteretic(0.0), t_final=0.1)
    assert len(flown.t) == 101 and flown.switch_count == 0
    assert np.array_equal(flown.u, np.broadcast_to(K @ X0, flown.u.shape))
    ref = predictor_reference.run(SC.inertia, SC.inertia.diagonal(), K, X0, tau=0.5, rate=1000.0, t_final=0.1)
    predicted = simulate(SC, K, X0, tau=0.5, rule=OnPredicted(), t_final=0.1, predictor=Predictor(SC))
    assert np.max(np.abs(_x(predicted) - ref.x)) < 1e-14
    assert np.max(np.abs(predicted.u - ref.u)) < 1e-14 * np.max(np.abs(ref.u))
    # keep_every > n keeps sample 0 only; the metrics are those of every sample
    for rule, extra in ((Hysteretic(0.0), {}), (OnPredicted(), {"predictor": Predictor(SC)})):
        full = simulate(SC, K, X0, tau=0.5, rule=rule, t_final=2.0, **extra)
        sparse = simulate(SC, K, X0, tau=0.5, rule=rule, t_final=2.0, keep_every=10**6, **extra)
        assert sparse.t.tolist() == [0.0] and np.array_equal(sparse.sigma, full.sigma[:1])
        assert sparse.switch_indices.tolist() == full.switch_indices.tolist()
        assert sparse.peak_torque == full.peak_torque and sparse.max_sigma == full.max_sigma


@needs_compiler
@pytest.mark.parametrize(
    ("tau", "rate", "t_final", "switches"), [(2.0, 1.0, 60.0, 1), (0.001, 1000.0, 0.8, 1), (0.001, 1e5, 0.01, 0)]
)
def test_predictor_at_1hz_100khz_and_one_sample_delay_equals_the_reference(tau, rate, t_final, switches):
    model = np.array([150.0, 95.0, 85.0])
    run = simulate(
        SC, K, X0, tau=tau, rate=rate, rule=OnPredicted(), t_final=t_final, predictor=Predictor(Spacecraft(model))
    )
    ref = predictor_reference.run(SC.inertia, model, K, X0, tau=tau, rate=rate, t_final=t_final)
    assert run.switch_indices.tolist() == ref.switches and len(ref.switches) == switches
    assert np.max(np.abs(_x(run) - ref.x)) < 1e-14
    assert np.max(np.abs(run.u - ref.u)) < 1e-12 * np.max(np.abs(ref.u))


# ====================================================================== thread pools
def _states(count: int) -> np.ndarray:
    rng = np.random.default_rng(5)
    return np.hstack((mrp.short(rng.normal(size=(count, 3))), rng.normal(size=(count, 3)) / 4.0))


def _same_metrics(a: Any, b: Any) -> bool:
    names = ("switch_count", "settling_time", "max_sigma", "saturated_fraction", "peak_command", "diverged")
    return all(
        (getattr(a, f) is None and getattr(b, f) is None)
        or np.array_equal(getattr(a, f), getattr(b, f), equal_nan=True)
        for f in names
    )


@needs_compiler
def test_batches_with_every_flight_option_and_the_predictor_equal_the_serial_runs():
    xs = _states(4)
    flight = dict(
        tau=0.05,
        t_final=2.0,
        rule=[Hysteretic(0.0), Hysteretic(0.3)] * 2,
        actuator=ActuatorModel(30.0, norm_max=40.0),
        disturbance=[1e-3, -2e-3, 0.0],
        sensor=SensorModel(0.01, 1e-3, [1e-4, 0.0, 0.0], seed=9),
        delay=DelayModel.jitter(0.02, 0.05, seed=3),
    )
    predicted = dict(
        tau=0.05,
        t_final=2.0,
        rule=[OnPredicted(1.0), OnPredicted(None)] * 2,
        predictor=Predictor(Spacecraft([150.0, 95.0, 85.0])),
        actuator=ActuatorModel(30.0),
        sensor=SensorModel(0.01, 1e-3, seed=2),
    )
    for options in (flight, predicted):
        lanes_1 = simulate_batch(SC, K, xs, threads=1, **options)
        lanes_2 = simulate_batch(SC, K, xs, threads=2, **options)
        pooled = simulate_batch(SC, K, xs, threads=2, trajectories=True, **options)
        assert _same_metrics(lanes_1, lanes_2) and _same_metrics(lanes_1, pooled)
        assert pooled.runs is not None
        for i, run in enumerate(pooled.runs):
            alone = simulate(SC, K, xs[i], **{**options, "rule": options["rule"][i]})
            assert np.array_equal(run.sigma, alone.sigma) and np.array_equal(run.u, alone.u)
            assert run.switch_indices.tolist() == alone.switch_indices.tolist()
            if options is flight:
                assert np.array_equal(run.sigma_c, alone.sigma_c) and np.array_equal(run.delay_used, alone.delay_used)


@needs_compiler
def test_concurrent_simulate_calls_with_different_flight_options_get_their_own_engines():
    # Each structure is its own engine (cache key); ten threads start at once on an empty
    # in-process cache and each must get the serial run's bits.
    cases: list[dict[str, Any]] = [
        dict(rule=Hysteretic(0.1), actuator=ActuatorModel(5.0)),
        dict(rule=Hysteretic(0.1), actuator=ActuatorModel(5.0, mode=Saturation.CLIP)),
        dict(rule=Hysteretic(0.1), sensor=SensorModel(0.01, seed=1)),
        dict(rule=Hysteretic(0.1), disturbance=[0.5, 0.0, 0.0]),
        dict(rule=Hysteretic(0.1), disturbance=np.tile([0.5, 0.0, 0.0], (2001, 1))),
        dict(rule=Hysteretic(0.1)),
        dict(rule=Hysteretic(0.1), delay=DelayModel.jitter(0.03, 0.05, seed=1)),
        dict(rule=OnPredicted(1.0), predictor=Predictor(SC)),
        dict(rule=OnPredicted(1.0), predictor=Predictor(SC), actuator=ActuatorModel(5.0)),
        dict(rule=OnPredicted(1.0), predictor=Predictor(SC), sensor=SensorModel(0.01, seed=1)),
    ]
    common = dict(tau=0.05, t_final=2.0)
    x0 = _states(1)[0]  # a tumble: torques on every axis, so that SCALE and CLIP differ
    serial = [simulate(SC, K, x0, **common, **case) for case in cases]
    # the options matter (distinct runs), except the constant and per-sample forms of one torque
    assert len({run.u.tobytes() for run in serial}) == len(cases) - 1
    assert np.array_equal(serial[3].u, serial[4].u)
    _engine.clear_engines()
    results: list[Any] = [None] * len(cases)
    errors: list[BaseException] = []
    barrier = threading.Barrier(len(cases))

    def work(i: int) -> None:
        try:
            barrier.wait()
            results[i] = simulate(SC, K, x0, **common, **cases[i])
        except BaseException as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(len(cases))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    for got, expected in zip(results, serial, strict=True):
        assert np.array_equal(got.sigma, expected.sigma) and np.array_equal(got.u, expected.u)


# ===================================================================== damaged compile cache
_CACHE_CHILD = textwrap.dedent(
    """
    import hashlib, sys, warnings
    import numpy as np
    from mrpctl import OnPredicted, Predictor, paper, simulate, simulate_batch
    from mrpctl.flight import ActuatorModel, Hysteretic, SensorModel
    sc, K, x0 = paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE
    common = dict(tau=0.05, rate=100.0, t_final=3.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        flown = simulate(sc, K, x0, rule=Hysteretic(0.1), sensor=SensorModel(0.01, seed=1), **common)
        predicted = simulate(sc, K, x0, rule=OnPredicted(), predictor=Predictor(sc), **common)
        lanes = simulate_batch(sc, K, np.tile(x0, (3, 1)), rule=Hysteretic(0.1), actuator=ActuatorModel(20.0), **common)
    digest = hashlib.sha256()
    for array in (flown.sigma, flown.u, flown.sigma_c, predicted.sigma, predicted.u, lanes.max_sigma,
                  lanes.saturated_fraction):
        digest.update(np.ascontiguousarray(array).tobytes())
    print(digest.hexdigest())
    for warning in caught:
        if warning.category.__name__ == "CacheWarning":
            print("CacheWarning", str(warning.message).replace(chr(10), " "))
    """
)


def _child(cache: Path) -> tuple[str, list[str]]:
    env = {**os.environ, "MRPCTL_CACHE_DIR": str(cache), "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    child = subprocess.run(
        [sys.executable, "-c", _CACHE_CHILD], capture_output=True, text=True, timeout=600, env=env, cwd=REPO
    )
    assert child.returncode == 0, (child.returncode, child.stderr[-3000:])
    digest, *warned = child.stdout.splitlines()
    return digest, warned


@needs_compiler
@pytest.mark.slow
def test_a_damaged_flight_or_predictor_library_in_the_cache_is_rebuilt(tmp_path):
    # Children: truncating a library this process has mapped would crash it (SIGBUS).
    cache = tmp_path / "cache"
    digest, warned = _child(cache)
    assert warned == []
    libraries = {
        kind: next(cache.glob(f"mrpctl_{kind}*.so"))
        for kind in ("sample_hysteretic", "sample_onpredicted", "lanes_hysteretic")
    }
    good = {kind: path.read_bytes() for kind, path in libraries.items()}
    # a truncated flight library, a truncated checksum record (the cache's manifest) of the
    # predictor's, and garbage of the right size in place of the lane engine's
    flight, predictor, lanes = (
        libraries["sample_hysteretic"],
        libraries["sample_onpredicted"],
        libraries["lanes_hysteretic"],
    )
    flight.write_bytes(good["sample_hysteretic"][: len(good["sample_hysteretic"]) // 3])
    record = predictor.with_name(predictor.name + ".sha256")
    record.write_text(record.read_text()[:20])
    lanes.write_bytes(bytes(len(good["lanes_hysteretic"])))
    again, warned = _child(cache)
    assert again == digest  # the same numbers, not a crash and not a silent wrong answer
    assert len(warned) == 3, warned
    assert any("truncated" in w and flight.name in w for w in warned)
    assert any("unreadable checksum file" in w and predictor.name in w for w in warned)
    assert any("SHA-256 differs" in w and lanes.name in w for w in warned)
    assert {kind: path.read_bytes() for kind, path in libraries.items()} == good  # rebuilt, same bytes
    third, warned = _child(cache)
    assert third == digest and warned == []  # verified hits now


# ===================================================================== memory
@pytest.mark.parametrize(
    "options",
    [
        dict(rule=Hysteretic(0.1), sensor=SensorModel(0.01, seed=1), delay=DelayModel.jitter(0.4, 0.5)),
        dict(rule=OnPredicted(), predictor=Predictor(SC)),
    ],
    ids=["flight", "predictor"],
)
def test_runs_that_would_not_fit_are_refused_up_front_with_the_estimate(options):
    with pytest.raises(SpecificationError, match=r"needs about \d+ GB .*keep_every=None"):
        simulate(SC, K, X0, tau=0.5, t_final=2e6, memory_limit=1e9, **options)
    with pytest.raises(SpecificationError, match=r"needs about \d+(\.\d+)? GB for 50 runs"):
        simulate_batch(
            SC, K, np.tile(X0, (50, 1)), tau=0.5, t_final=2e4, trajectories=True, memory_limit=1e9, **options
        )
    # 1e5 kept samples: 104 B each, and 256 B of records (the flight loop, the predictor: what the controller saw)
    with pytest.raises(SpecificationError, match=r"0\.0[1-4]\d* GB .* limit of 0\.001 GB"):
        simulate(SC, K, X0, tau=0.5, t_final=100.0, memory_limit=1e6, **options)


def test_batches_of_millions_of_runs_are_refused_before_their_per_run_objects_are_made(monkeypatch):
    """A second audit: 3e7 metrics-only runs took 9 GB and 109 s of per-run objects before the refusal, and a
    trajectory batch's per-run results (≈ 5 KB each, measured) were not counted (4e5 runs: 0.52 GB estimated,
    2.45 GB used)."""
    from mrpctl.simulation import _batch

    converted: list[float] = []
    original = _batch.delay_samples
    monkeypatch.setattr(_batch, "delay_samples", lambda tau, rate: converted.append(tau) or original(tau, rate))
    with pytest.raises(SpecificationError, match=r"for 3000000 runs .*give fewer runs per call"):
        simulate_batch(SC, K, X0, tau=np.full(3_000_000, 0.01), rule=Hysteretic(0.1), t_final=0.02, memory_limit=1e8)
    assert converted == []  # refused before the first run's delay was converted
    with pytest.raises(SpecificationError, match=r"needs about 3\.\d+ GB for 400000 runs"):
        simulate_batch(
            SC, K, np.broadcast_to(X0, (400_000, 6)), tau=0.01, rule=Hysteretic(0.1), t_final=0.05,
            trajectories=True, keep_every=None, memory_limit=2e9,
        )  # fmt: skip


# ===================================================================== export
def _export_folder(path: Path) -> dict[str, bytes]:
    return {p.relative_to(path).as_posix(): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


@needs_compiler
@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["predictor-paper", "flight-paper"])
def test_ctrl_c_during_an_export_overwrite_leaves_the_old_export(scenario, tmp_path, capsys):
    out = tmp_path / "export"
    assert main(["export", "paper_fig4_on_delayed", "--out", str(out), "--no-compile"]) == 0
    (out / "notes.txt").write_text("mine")
    before = _export_folder(out)
    code, err = _cli(["export", scenario, "--out", str(out)], capsys)
    assert code == 2 and "not empty" in err and "--overwrite" in err and err.count("\n") == 1
    (tmp_path / "a_file").write_text("x")
    code, err = _cli(["export", scenario, "--out", str(tmp_path / "a_file"), "--overwrite"], capsys)
    assert code == 2 and err.count("\n") == 1
    assert _export_folder(out) == before
    env = {**os.environ, "MRPCTL_CACHE_DIR": str(tmp_path / "cache"), "OMP_NUM_THREADS": "1"}
    child = subprocess.Popen(
        [sys.executable, "-m", "mrpctl", "export", scenario, "--out", str(out), "--overwrite"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        cwd=REPO,
        # xdist's workers ignore SIGINT and a child inherits that (Python then installs no handler)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 300
    while not list(tmp_path.glob(".export.export-*")) and child.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert child.poll() is None, "the export finished before it could be interrupted"
    time.sleep(0.3)  # into the export (C code or the compiler)
    child.send_signal(signal.SIGINT)
    _, stderr = child.communicate(timeout=300)
    assert child.returncode == 130, stderr[-2000:]
    assert stderr.strip().splitlines()[-1] == "mrpctl: interrupted"
    assert _export_folder(out) == before
    # a complete overwrite then replaces the previous export whole; the user's own file is carried over
    assert main(["export", scenario, "--out", str(out), "--overwrite", "--no-compile"]) == 0
    capsys.readouterr()
    manifest = json.loads((out / "manifest.json").read_text())
    after = _export_folder(out)
    assert after.pop("notes.txt") == b"mine" and after.pop("manifest.json")
    assert set(after) == set(manifest["files"])  # nothing of the plain export is left (e.g. its controller)
    assert set(before) - {"notes.txt", "manifest.json"} - set(manifest["files"])
    assert ("predictor" if scenario == "predictor-paper" else "flight") in manifest


# ===================================================================== saved runs
@needs_compiler
def test_saved_flight_and_predictor_runs_round_trip_with_their_records(tmp_path):
    flown = simulate(
        SC,
        K,
        X0,
        tau=0.5,
        rule=Hysteretic(0.0),
        t_final=2.0,
        keep_every=3,
        actuator=ActuatorModel(20.0),
        sensor=SensorModel(0.01, seed=1),
        delay=DelayModel.jitter(0.4, 0.5, seed=1),
    )
    predicted = simulate(
        SC, K, X0, tau=0.5, rule=OnPredicted(1.2), t_final=2.0, predictor=Predictor(Spacecraft([150, 95, 85]))
    )
    assert flown.logic is not None and flown.switch_count > 0 and len(set(flown.delay_used.tolist())) > 1
    for run in (flown, predicted):
        back = data.load(data.save(run, tmp_path / f"{run.rule.label}.nc"))
        for name in ("t", "sigma", "omega", "u", "switch_indices", "peak_command", "logic", "sigma_c", "delay_used"):
            mine, theirs = getattr(run, name), getattr(back, name)
            assert (mine is None) == (theirs is None), name
            if mine is not None:
                assert np.array_equal(mine, theirs) and theirs.dtype == mine.dtype, name  # before: records lost
        assert back.saturated_fraction == run.saturated_fraction and back.keep_every == run.keep_every
        assert type(back.rule) is type(run.rule) and back.rule.parameters() == run.rule.parameters()
        if run.predictor is not None:
            assert back.predictor is not None
            assert np.array_equal(back.predictor.model.inertia, run.predictor.model.inertia)
        else:
            assert back.predictor is None
    dataset = flown.to_xarray()
    assert dataset["delay_used"].dims == ("time",) and dataset["sigma_c"].dims == ("time", "axis")


@pytest.mark.parametrize("value", [[math.inf, 0.0, 0.0], [math.nan, 0.0, 0.0]])
def test_a_non_finite_disturbance_is_refused_naming_the_parameter(value):
    with pytest.raises(SpecificationError, match=r"^disturbance: torque must be finite"):
        simulate(SC, K, X0, tau=0.01, rule=Hysteretic(0.1), t_final=0.1, disturbance=value)
