"""A tracking scenario's own keys of [reference] (error_time, feedforward, pointing_tolerance_deg): parsed,
written back by scenario_toml, refused naming the key; what `mrpctl simulate` prints and writes for it
(the tracking lines, the JSON keys, --pointing-plot); the shipped nadir-pointing scenario."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_assertions import one_line_error
from scipy.spatial.transform import Rotation

from mrpctl.cli import main
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.flight.tracking import DEFAULT_POINTING_TOLERANCE, ErrorTime
from mrpctl.guidance import EARTH_MU, EARTH_RADIUS, NadirPointing, reference_samples
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml

ROOT = Path(__file__).resolve().parents[1]
NADIR = ROOT / "examples" / "scenarios" / "nadir.toml"

REFERENCES: dict[str, dict[str, Any]] = {
    "inertial": {"type": "inertial", "sigma": [0.1, 0.0, 0.0]},
    "slew": {
        "type": "slew",
        "axis": [0.0, 0.0, 1.0],
        "angle_deg": 90.0,
        "rate_limit": 0.05,
        "acceleration_limit": 0.01,
    },
    "nadir": {"type": "nadir", "orbit_rate": 0.0011},
}


def _data(reference: dict[str, Any] | None) -> dict[str, Any]:
    data: dict[str, Any] = {
        "name": "tracking",
        "tau": 0.5,
        "rate": 10.0,
        "t_final": 20.0,
        "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
        "gains": {"k_sigma": -70.11, "k_omega": -163.08},
        "initial": {"sigma": [0.0, 0.0, 0.0], "omega": [0.0, 0.0, 0.0]},
        "rule": {"type": "hysteretic", "delta": 0.0},
    }
    if reference is not None:
        data["reference"] = reference
    return data


def _write(tmp_path: Path, data: dict[str, Any], name: str = "tracking.toml") -> Path:
    path = tmp_path / name
    path.write_text(scenario_toml(parse_scenario(data)), encoding="utf-8")
    return path


@pytest.mark.parametrize("kind", sorted(REFERENCES))
@pytest.mark.parametrize(
    ("keys", "expected"),
    [
        ({}, (None, False, DEFAULT_POINTING_TOLERANCE)),
        ({"error_time": "current"}, (ErrorTime.CURRENT, False, DEFAULT_POINTING_TOLERANCE)),
        ({"error_time": "measurement", "feedforward": True}, (ErrorTime.MEASUREMENT, True, DEFAULT_POINTING_TOLERANCE)),
        ({"feedforward": False, "pointing_tolerance_deg": 0.025}, (None, False, 0.025)),
        (
            {"error_time": "current", "feedforward": True, "pointing_tolerance_deg": 1.0 / 3.0},
            (ErrorTime.CURRENT, True, 1.0 / 3.0),
        ),
    ],
)  # fmt: skip
def test_the_tracking_keys_parse_and_read_back_bit_for_bit(
    tmp_path: Path, kind: str, keys: dict[str, Any], expected: tuple[Any, bool, float]
) -> None:
    scenario = parse_scenario(_data({**REFERENCES[kind], **keys}))
    assert (scenario.error_time, scenario.feedforward, scenario.pointing_tolerance) == expected
    text = scenario_toml(scenario)
    # only what differs from the defaults is written, inside [reference]
    reference_part = text.split("[reference]", 1)[1]
    assert ("error_time" in reference_part) == ("error_time" in keys)
    assert ("feedforward = true" in reference_part) == bool(keys.get("feedforward"))
    assert ("pointing_tolerance_deg" in reference_part) == ("pointing_tolerance_deg" in keys)
    path = tmp_path / "written.toml"
    path.write_text(text, encoding="utf-8")
    again = load_scenario(path)
    assert (again.error_time, again.feedforward, again.pointing_tolerance) == expected  # floats repr: exact
    assert scenario_toml(again) == text
    assert again.tracking_options == {
        "error_time": expected[0],
        "feedforward": expected[1],
        "pointing_tolerance": expected[2],
    }


def test_a_regulation_scenario_has_no_tracking_options() -> None:
    scenario = parse_scenario(_data(None))
    assert scenario.reference is None and scenario.tracking_options == {}
    assert "error_time" not in scenario_toml(scenario) and "feedforward" not in scenario_toml(scenario)


@pytest.mark.parametrize(
    ("key", "value", "words"),
    [
        ("error_time", "now", "must be one of ['current', 'measurement'], got 'now'"),
        ("error_time", "CURRENT", "got 'CURRENT'"),
        ("error_time", 1, "got 1"),
        ("feedforward", "true", "must be true or false, got 'true'"),
        ("feedforward", 1, "must be true or false, got 1"),
        ("pointing_tolerance_deg", 0.0, "must be > 0"),
        ("pointing_tolerance_deg", -0.1, "must be > 0"),
        ("pointing_tolerance_deg", 180.5, "must be at most 180"),
        ("pointing_tolerance_deg", "0.1", "real number"),
        ("pointing_tolerance_deg", True, "boolean"),
        ("pointing_tolerance_deg", math.nan, "finite"),
        ("pointing_tolerance", 0.1, "unknown key 'pointing_tolerance'"),
    ],
)
def test_bad_tracking_values_are_refused_naming_the_key(key: str, value: Any, words: str) -> None:
    with pytest.raises(SpecificationError) as info:
        parse_scenario(_data({**REFERENCES["nadir"], key: value}))
    message = str(info.value)
    assert "[reference]" in message and key in message and words in message, message


def test_the_cli_refuses_a_bad_key_and_a_pointing_plot_of_regulation_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bad.toml"
    good = _write(tmp_path, _data({**REFERENCES["inertial"]}))
    path.write_text(good.read_text(encoding="utf-8") + 'error_time = "later"\n', encoding="utf-8")
    assert main(["simulate", str(path)]) == 2
    one_line_error(capsys, "[reference] error_time", "'later'")
    regulation = _write(tmp_path, _data(None), "regulation.toml")
    assert main(["simulate", str(regulation), "--pointing-plot", str(tmp_path / "p.png")]) == 2
    one_line_error(capsys, "--pointing-plot", "[reference]")
    assert not (tmp_path / "p.png").exists()
    assert main(["simulate", str(good), "--pointing-plot", str(tmp_path / "p.txt")]) == 2
    one_line_error(capsys)


def _true_pointing_error(scenario: Any, sigma_bn: np.ndarray) -> np.ndarray:
    """Φ_B/R (deg) from the plant's σ_B/N and the reference rows, with scipy's rotations."""
    rows = reference_samples(scenario.reference, len(sigma_bn), scenario.rate)
    relative = Rotation.from_mrp(np.array(rows[:, :3])).inv() * Rotation.from_mrp(np.array(sigma_bn))
    return np.degrees(relative.magnitude())


def test_simulate_json_and_text_carry_the_tracking_figures(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = load_scenario(NADIR)
    run = scenario.simulate()
    phi = _true_pointing_error(scenario, run.sigma)
    np.testing.assert_allclose(run.pointing_error, phi, rtol=1e-9, atol=1e-12)
    settled = run.t >= run.settling_time
    plot = tmp_path / "pointing.png"
    assert main(["simulate", str(NADIR), "--json", "--pointing-plot", str(plot)]) == 0
    summary = json.loads(capsys.readouterr().out)
    result = summary["result"]
    assert summary["scenario"]["reference"] == str(scenario.reference) and "nadir pointing" in str(scenario.reference)
    assert result["error_time"] == "measurement" and result["feedforward"] is True
    assert result["pointing_tolerance_deg"] == 0.05
    assert result["pointing_max_deg"] == pytest.approx(phi[settled].max(), rel=1e-9)
    assert result["pointing_rms_deg"] == pytest.approx(math.sqrt(np.mean(phi[settled] ** 2)), rel=1e-9)
    above = np.flatnonzero(phi >= 0.05)
    assert result["slew_time"] == pytest.approx(run.t[above[-1] + 1], abs=1e-12)
    assert summary["files"]["pointing_plot"] == str(plot) and plot.stat().st_size > 10_000
    text = str(run)
    assert "max |sigma|  0.087489 (the tracking error sigma_B/R)" in text
    assert "tracking     error against the reference at the measurement's time, feedforward on" in text
    assert f"pointing     after settling max {phi[settled].max():.4g} deg, RMS {result['pointing_rms_deg']:.4g}" in text
    assert f"slew time    {result['slew_time']:.3f} s (pointing error within 0.05 deg from then on)" in text
    # a regulation run's JSON has none of these keys
    regulation = _write(tmp_path, _data(None), "regulation.toml")
    assert main(["simulate", str(regulation), "--json"]) == 0
    regulation_summary = json.loads(capsys.readouterr().out)
    assert regulation_summary["scenario"]["reference"] is None
    keys = set(regulation_summary["result"])
    assert not keys & {"error_time", "feedforward", "pointing_max_deg", "pointing_rms_deg", "slew_time"}


def test_a_run_that_never_holds_the_tolerance_says_never(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """A 90 degree slew cut at 20 s holds 0.1 deg only at the very end or never: the text says which."""
    path = _write(tmp_path, _data({**REFERENCES["slew"], "pointing_tolerance_deg": 1e-6}))
    run = load_scenario(path).simulate()
    assert run.slew_time is None
    assert "slew time    never (pointing error within 1e-06 deg from then on)" in str(run)


def test_the_shipped_nadir_scenario() -> None:
    """examples/scenarios/nadir.toml: the paper spacecraft and gain, the Hill frame of a 500 km orbit, the body
    20 deg off about the along-track axis turning with the orbit, feedforward, the reference of the measurement's
    time; it settles and its error falls below 1e-6 deg."""
    scenario = load_scenario(NADIR)
    n = math.sqrt(EARTH_MU / (EARTH_RADIUS + 500e3) ** 3)
    assert isinstance(scenario.reference, NadirPointing)
    assert scenario.reference.orbit_rate == pytest.approx(n, rel=1e-12)
    assert (scenario.tau, scenario.rate, scenario.error_time, scenario.feedforward) == (
        0.5,
        20.0,
        ErrorTime.MEASUREMENT,
        True,
    )
    assert isinstance(scenario.rule, Hysteretic) and scenario.rule.delta == 0.0
    np.testing.assert_allclose(scenario.sigma0, [0.0, math.tan(math.radians(20.0) / 4), 0.0], rtol=1e-12)
    np.testing.assert_allclose(scenario.omega0, [0.0, 0.0, n], rtol=1e-5)
    run = scenario.simulate()
    assert run.settling_time is not None and not run.diverged and run.switch_count == 0
    assert run.pointing_error[0] == pytest.approx(20.0, rel=1e-9)
    assert run.pointing_error[-1] < 1e-6


def test_export_of_a_tracking_scenario_is_the_tracking_controller(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`mrpctl export nadir` writes the tracking loop of the scenario's error time and feedforward; its
    tracking_controller gives u = K [σ_B/R; ω_B/R/4] + ω × Jω + J([BN]ω̇_R − ω × [BN]ω_R), here recomputed with
    scipy's rotations (σ_B/R of [BR] = [BN][RN]ᵀ), for a measurement off a reference row of the nadir profile."""
    import casadi as ca

    out = tmp_path / "export"
    assert main(["export", str(NADIR), "--out", str(out), "--no-compile"]) == 0
    printed = capsys.readouterr().out
    assert "reference input: one row (sigma_RN, omega_RN_N, domega_RN_N) per sample, of the measurement time" in printed
    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    assert manifest["tracking"]["error_time"] == "measurement" and manifest["tracking"]["feedforward"] is True
    assert "tracking_controller" in manifest["functions"] and "flight_controller" not in manifest["functions"]
    scenario = load_scenario(NADIR)
    rows = np.array(reference_samples(scenario.reference, 2001, scenario.rate))
    row = rows[2000]  # t = 100 s: the Hill frame has turned by n t
    rot_r = Rotation.from_mrp(row[:3])
    rot_b = Rotation.from_rotvec([0.01, -0.02, 0.015]) * rot_r  # 1.5 deg off the reference
    sigma_b, omega_b = rot_b.as_mrp(), np.array([1e-3, -2e-3, 3e-3])
    controller = ca.Function.load(str(out / "tracking_controller.casadi"))
    sigma_br = (rot_r.inv() * rot_b).as_mrp()
    memory = np.concatenate(([1.0, 1.0], sigma_br))  # h = c = +1, the previous error this one
    u = np.asarray(controller(np.concatenate((sigma_b, omega_b / 4)), memory, row, 0.0)[0]).ravel()
    bn = rot_b.as_matrix().T  # [BN], passive
    omega_br = omega_b - bn @ row[3:6]
    j = scenario.spacecraft.inertia
    feedforward = np.cross(omega_b, j @ omega_b) + j @ (bn @ row[6:9] - np.cross(omega_b, bn @ row[3:6]))
    expected = scenario.K @ np.concatenate((sigma_br, omega_br / 4)) + feedforward
    np.testing.assert_allclose(u, expected, rtol=1e-12, atol=1e-14)
    assert np.linalg.norm(bn @ row[3:6]) == pytest.approx(scenario.reference.orbit_rate, rel=1e-12)


@pytest.mark.parametrize(
    ("rule", "extra"),
    [('type = "on-predicted"\nalpha = 1.0', "\n[predictor]\n"), ('type = "on-delayed"', "")],
)
def test_export_refuses_what_the_tracking_export_does_not_have_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], rule: str, extra: str
) -> None:
    """The tracking export is the flight loop's: the predictor's tracking loop and plant-side rules are refused."""
    text = NADIR.read_text(encoding="utf-8").replace('type = "hysteretic"\ndelta = 0.0', rule) + extra
    path = tmp_path / "scenario.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["export", str(path), "--out", str(tmp_path / "out"), "--no-compile"]) == 2
    one_line_error(capsys, "tracking: the tracking loop is the flight loop's", "Hysteretic(delta)")
    assert not (tmp_path / "out").exists()
