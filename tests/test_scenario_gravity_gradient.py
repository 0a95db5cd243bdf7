"""``[reference] gravity_gradient = true``: the scenario flies the gravity-gradient torque of its nadir orbit
(``simulate(..., gravity_gradient=reference)``), is written back, and is refused where it has no meaning (no orbit,
a bad value, an orbit-rate dispersion that would leave the batch's one orbit behind, the export's plant)."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl import simulate
from mrpctl.campaign import open_campaign, parse_campaign, run_campaign
from mrpctl.cli import main
from mrpctl.errors import SpecificationError
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml

NADIR = {"type": "nadir", "orbit_rate": 0.0011, "feedforward": True}


def _data(reference: dict[str, Any]) -> dict[str, Any]:
    return {
        "name": "gravity",
        "tau": 0.5,
        "rate": 10.0,
        "t_final": 40.0,
        # products of inertia: the gravity gradient has a torque the feedforward does not cancel at the reference
        "spacecraft": {"inertia": [[140.0, 5.0, -3.0], [5.0, 100.0, 2.0], [-3.0, 2.0, 80.0]]},
        "gains": {"k_sigma": -70.11, "k_omega": -163.08},
        "initial": {"sigma": [0.05, -0.02, 0.01], "omega": [0.0, 0.0, 0.0011]},
        "rule": {"type": "hysteretic", "delta": 0.0},
        "reference": reference,
    }


def test_the_key_flies_the_orbit_s_gravity_gradient_and_reads_back(tmp_path: Path) -> None:
    scenario = parse_scenario(_data({**NADIR, "gravity_gradient": True}))
    assert scenario.gravity_gradient and scenario.tracking_options["gravity_gradient"] is scenario.reference
    run = scenario.simulate()
    direct = simulate(
        scenario.spacecraft,
        scenario.K,
        sigma0=scenario.sigma0,
        omega0=scenario.omega0,
        tau=scenario.tau,
        rate=scenario.rate,
        t_final=scenario.t_final,
        rule=scenario.rule,
        reference=scenario.reference,
        feedforward=True,
        gravity_gradient=scenario.reference,
    )
    without = parse_scenario(_data(NADIR)).simulate()
    assert np.array_equal(run.sigma, direct.sigma) and np.array_equal(run.omega, direct.omega)
    assert np.abs(run.sigma - without.sigma).max() > 1e-9  # the torque is flown
    text = scenario_toml(scenario)
    assert "gravity_gradient = true" in text.split("[reference]", 1)[1]
    path = tmp_path / "again.toml"
    path.write_text(text, encoding="utf-8")
    again = load_scenario(path)
    assert again.gravity_gradient and scenario_toml(again) == text
    assert np.array_equal(again.simulate().sigma, run.sigma)
    assert "gravity_gradient" not in scenario_toml(parse_scenario(_data(NADIR)))


@pytest.mark.parametrize(
    ("reference", "words"),
    [
        ({**NADIR, "gravity_gradient": "yes"}, "must be true or false, got 'yes'"),
        ({**NADIR, "gravity_gradient": 1}, "must be true or false, got 1"),
        ({"type": "inertial", "sigma": [0.1, 0.0, 0.0], "gravity_gradient": True}, "type = 'nadir' only"),
    ],
)
def test_bad_values_are_refused_naming_the_key(reference: dict[str, Any], words: str) -> None:
    with pytest.raises(SpecificationError) as info:
        parse_scenario(_data(reference))
    message = str(info.value)
    assert "[reference] gravity_gradient" in message and words in message, message
    # false on another type is allowed (it says what the default says)
    parse_scenario(_data({"type": "inertial", "sigma": [0.1, 0.0, 0.0], "gravity_gradient": False}))


def _toml(reference: str) -> str:
    return f"""
name = "gg"
count = 4
seed = 3
tau = 0.5
rate = 10.0
t_final = 10.0
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -70.11
k_omega = -163.08
[rule]
type = "hysteretic"
delta = 0.0
[reference]
type = "nadir"
orbit_rate = 0.0011
gravity_gradient = true
{reference}
"""


def test_a_campaign_flies_it_and_refuses_an_orbit_rate_dispersion_with_it(tmp_path: Path) -> None:
    spec = parse_campaign(tomllib.loads(_toml("")), name="gg")  # one orbit for every run: taken
    run_campaign(spec, tmp_path / "out", chunk=2)
    stored = open_campaign(tmp_path / "out")
    base = spec.base
    alone = simulate(
        base.spacecraft,
        base.K,
        sigma0=base.sigma0,
        omega0=base.omega0,
        tau=base.tau,
        rate=base.rate,
        t_final=base.t_final,
        rule=base.rule,
        reference=base.reference,
        gravity_gradient=base.reference,
    )
    without = simulate(
        base.spacecraft, base.K, sigma0=base.sigma0, omega0=base.omega0, tau=base.tau, rate=base.rate,
        t_final=base.t_final, rule=base.rule, reference=base.reference,
    )  # fmt: skip
    assert alone.pointing_max != without.pointing_max  # the torque shows in the stored metric
    assert np.all(stored["pointing_max"].values == alone.pointing_max)  # every run is the base run: no dispersion
    assert np.all(stored["max_sigma"].values == alone.max_sigma)
    dispersed = _toml('[dispersions.reference]\norbit_rate = {distribution = "uniform", low = 1e-3, high = 1.2e-3}')
    with pytest.raises(SpecificationError, match="gravity_gradient = true: the runs of a batch share one orbit"):
        parse_campaign(tomllib.loads(dispersed), name="gg")


def test_export_refuses_it_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "gg.toml"
    path.write_text(scenario_toml(parse_scenario(_data({**NADIR, "gravity_gradient": True}))), encoding="utf-8")
    assert main(["export", str(path), "--out", str(tmp_path / "out"), "--no-compile"]) == 2
    assert "do not model the gravity-gradient torque" in one_line_error(capsys)
