"""The scenario's [reference] table: each type parsed into its guidance profile, written back by
scenario_toml, and every bad table refused naming [reference] and the key."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.guidance import (
    EARTH_MU,
    EARTH_RADIUS,
    CircularOrbit,
    EigenaxisSlew,
    FileReference,
    InertialPointing,
    NadirPointing,
)
from mrpctl.scenario import load_scenario, parse_scenario, scenario_toml


def _data(reference: dict[str, Any] | None = None, **top: Any) -> dict[str, Any]:
    data: dict[str, Any] = {
        "name": "tracking",
        "tau": 0.5,
        "rate": 10.0,
        "t_final": 2.0,
        "spacecraft": {"inertia": [140.0, 100.0, 80.0]},
        "gains": {"k_sigma": -70.11, "k_omega": -163.08},
        "initial": {"sigma": [0.0, 0.0, 0.0], "omega": [0.0, 0.0, 0.0]},
        "rule": {"type": "delay-aware"},
    }
    data.update(top)
    if reference is not None:
        data["reference"] = reference
    return data


def _round_trip(tmp_path: Path, data: dict[str, Any]) -> Any:
    scenario = parse_scenario(data, base=tmp_path)
    path = tmp_path / "written.toml"
    path.write_text(scenario_toml(scenario), encoding="utf-8")
    return scenario, load_scenario(path)


def test_no_reference_is_regulation() -> None:
    assert parse_scenario(_data()).reference is None


def test_inertial_reference(tmp_path: Path) -> None:
    scenario, again = _round_trip(tmp_path, _data({"type": "inertial", "sigma": [0.1, 0.2, -0.3]}))
    assert isinstance(scenario.reference, InertialPointing)
    np.testing.assert_array_equal(scenario.reference.sigma, [0.1, 0.2, -0.3])
    np.testing.assert_array_equal(again.reference.sigma, scenario.reference.sigma)
    assert "reference: inertial pointing" in str(scenario)


def test_slew_reference_by_axis_and_by_target(tmp_path: Path) -> None:
    table = {
        "type": "slew",
        "axis": [0.0, 0.0, 1.0],
        "angle_deg": 270.0,
        "rate_limit": 0.05,
        "acceleration_limit": 0.01,
        "t_start": 1.0,
    }
    scenario, again = _round_trip(tmp_path, _data(table))
    slew = scenario.reference
    assert isinstance(slew, EigenaxisSlew)
    assert slew.angle == math.radians(270.0) and slew.t_start == 1.0
    np.testing.assert_array_equal(slew.start, 0.0)
    assert again.reference.angle == pytest.approx(slew.angle, rel=1e-15)
    t = np.linspace(0.0, 120.0, 50)
    np.testing.assert_allclose(again.reference.samples(t), slew.samples(t), rtol=0, atol=1e-14)
    by_target = {"type": "slew", "start": [0.1, 0.0, 0.0], "target": [0.0, 0.3, 0.0], "rate_limit": 0.1}
    by_target["acceleration_limit"] = 0.02
    scenario, again = _round_trip(tmp_path, _data(by_target))
    np.testing.assert_array_equal(again.reference.target, [0.0, 0.3, 0.0])
    assert again.reference.angle == scenario.reference.angle


@pytest.mark.parametrize(
    ("orbit", "rate"),
    [
        ({"orbit_rate": 1.1e-3}, 1.1e-3),
        ({"altitude": 500e3}, math.sqrt(EARTH_MU / (EARTH_RADIUS + 500e3) ** 3)),
        ({"radius": 7.0e6, "mu": 4.0e14}, math.sqrt(4.0e14 / 7.0e6**3)),
    ],
)
def test_nadir_reference(tmp_path: Path, orbit: dict[str, float], rate: float) -> None:
    table = {"type": "nadir", "inclination_deg": 97.4, "raan_deg": 30.0, "latitude_deg": -10.0, **orbit}
    scenario, again = _round_trip(tmp_path, _data(table))
    nadir = scenario.reference
    assert isinstance(nadir, NadirPointing)
    assert nadir.orbit_rate == rate
    assert nadir.orbit.inclination == math.radians(97.4)
    assert again.reference.orbit_rate == rate
    t = np.linspace(0.0, 6000.0, 7)
    np.testing.assert_allclose(again.reference.samples(t), nadir.samples(t), rtol=0, atol=1e-14)


def test_file_reference_has_one_row_per_sample(tmp_path: Path) -> None:
    rows = NadirPointing(CircularOrbit(1e-3)).samples(np.arange(21) / 10.0)  # t_final 2 s at 10 Hz: 21 samples
    np.save(tmp_path / "ref.npy", rows)
    scenario, again = _round_trip(tmp_path, _data({"type": "file", "file": "ref.npy"}))
    assert isinstance(scenario.reference, FileReference)
    np.testing.assert_array_equal(scenario.reference.rows, rows)
    np.testing.assert_array_equal(again.reference.rows, rows)
    with pytest.raises(DimensionError, match=r"\[reference\] file: expected n rows of 9.*\(31, 9\).*\(21, 9\)"):
        parse_scenario(_data({"type": "file", "file": "ref.npy"}, t_final=3.0), base=tmp_path)
    with pytest.raises(SpecificationError, match=r"\[reference\] file: no file"):
        parse_scenario(_data({"type": "file", "file": "missing.csv"}), base=tmp_path)


@pytest.mark.parametrize(
    ("table", "error", "words"),
    [
        ([1, 2], SpecificationError, "must be a table"),
        ({"sigma": [0.0, 0.0, 0.0]}, SpecificationError, "needs type"),
        ({"type": "lvlh"}, SpecificationError, "needs type"),
        ({"type": "inertial"}, SpecificationError, "needs sigma"),
        ({"type": "inertial", "sigma": [0.0, 0.0, 3.0]}, SpecificationError, "sigma must be a short-set"),
        ({"type": "inertial", "sigma": [0.0, 0.0, 0.0], "axis": [1, 0, 0]}, SpecificationError, "unknown key 'axis'"),
        ({"type": "slew", "axis": [0, 0, 1], "angle_deg": 90.0, "rate_limit": 0.1}, SpecificationError, "needs"),
        (
            {"type": "slew", "axis": [0, 0, 1], "angle_deg": 90.0, "rate_limit": 0.0, "acceleration_limit": 1.0},
            SpecificationError,
            "rate_limit must be > 0",
        ),
        (
            {"type": "slew", "axis": [0, 0, 1], "angle_deg": 90.0, "target": [0, 0, 0.1], "rate_limit": 1.0}
            | {"acceleration_limit": 1.0},
            SpecificationError,
            "one of them",
        ),
        (
            {"type": "slew", "axis": [0, 0, 3], "angle_deg": 90.0, "rate_limit": 1.0, "acceleration_limit": 1.0},
            SpecificationError,
            "axis must be a unit vector",
        ),
        ({"type": "nadir"}, SpecificationError, "needs one of orbit_rate"),
        ({"type": "nadir", "orbit_rate": 0.0}, SpecificationError, "orbit_rate must be > 0"),
        ({"type": "nadir", "orbit_rate": -1e-3}, SpecificationError, "orbit_rate must be > 0"),
        ({"type": "nadir", "orbit_rate": 1e-3, "altitude": 5e5}, SpecificationError, "needs one of"),
        ({"type": "nadir", "orbit_rate": 1e-3, "mu": 4e14}, SpecificationError, "mu applies"),
        ({"type": "nadir", "altitude": 5e5, "inclination_deg": 200.0}, SpecificationError, "inclination"),
        ({"type": "file"}, SpecificationError, "needs file"),
    ],
)
def test_bad_reference_tables_are_refused_naming_the_key(table: Any, error: type, words: str) -> None:
    with pytest.raises(error, match=r"\[reference\]") as info:
        parse_scenario(_data(table))
    assert words in str(info.value)


def test_a_tracking_scenario_flies_the_tracking_loop_and_a_plant_side_rule_is_refused() -> None:
    from mrpctl.simulation import simulate

    scenario = parse_scenario(_data({"type": "inertial", "sigma": [0.1, 0.0, 0.0]}))
    with pytest.raises(SpecificationError, match="Hysteretic"):  # delay-aware acts on the plant: not for tracking
        scenario.simulate()
    tracking = parse_scenario(_data({"type": "inertial", "sigma": [0.1, 0.0, 0.0]}, rule={"type": "hysteretic"}))
    run = tracking.simulate()
    assert run.pointing_error is not None and run.pointing_error[0] == pytest.approx(math.degrees(4 * math.atan(0.1)))
    same = simulate(
        tracking.spacecraft,
        tracking.K,
        tracking.x0,
        tau=tracking.tau,
        rule=tracking.rule,
        t_final=tracking.t_final,
        rate=tracking.rate,
        reference=InertialPointing([0.1, 0.0, 0.0]),
    )
    assert np.array_equal(run.sigma, same.sigma) and np.array_equal(run.pointing_error, same.pointing_error)


def test_a_profile_without_a_file_is_not_written() -> None:
    scenario = parse_scenario(_data())
    rows = np.zeros((21, 9))
    with pytest.raises(SpecificationError, match=r"reference: a FileReference is not written"):
        scenario_toml(replace(scenario, reference=FileReference(rows=rows, rate=10.0)))
