"""``mrpctl verify SCENARIO`` certifies the loop the scenario flies (issue 11, deliverable 5).

The scenario's sample rate (sampled-data loop: exact lifted check + certificate), its ``[delay]``
bounds (interval certificate, rate unknown) and its ``[uncertainty]`` inertia box are certified
without flags; the flags override them; ``--no-flown`` keeps the idealised loop. The exact answers
the tests compare with are computed here, independently (scipy's expm and NumPy eigenvalues for the
lifted loop, the closed-form per-axis delay margin for the inertia box).
"""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from cli_assertions import one_line_error as _one_line_error

from mrpctl import paper
from mrpctl.cli import NOT_VERIFIED, USER_ERROR, main
from mrpctl.errors import SpecificationError
from mrpctl.flight import DelayModel
from mrpctl.scenario import InertiaUncertainty, load_scenario, parse_scenario, scenario_toml


def _lifted_radius(inertia: float, k_sigma: float, k_omega: float, h: float, d: int) -> float:
    """Spectral radius of the lifted loop of one axis, written out here: x_{k+1} = Φ x_k + Γ K x_{k-d}."""
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    b = np.array([[0.0], [0.25 / inertia]])
    k = np.array([[k_sigma, k_omega]])
    block = scipy.linalg.expm(np.block([[a, b], [np.zeros((1, 3))]]) * h)
    phi, gamma = block[:2, :2], block[:2, 2:]
    n = 2 * (d + 1)
    companion = np.zeros((n, n))
    companion[:2, :2] = phi
    companion[:2, -2:] += gamma @ k
    companion[2:, :-2] = np.eye(n - 2)
    return float(np.max(np.abs(np.linalg.eigvals(companion))))


def _axis_margin(inertia: float, k_sigma: float, k_omega: float) -> float:
    """Exact delay margin of σ̈ = K₁σ(t − τ) + K₂σ̇(t − τ): ω⁴ = K₁² + K₂²ω², τ = atan2(−K₂ω, −K₁)/ω."""
    k1, k2 = k_sigma / (4 * inertia), k_omega / (4 * inertia)
    omega = math.sqrt((k2**2 + math.sqrt(k2**4 + 4 * k1**2)) / 2)
    return math.atan2(-k2 * omega, -k1) / omega


def _write(path: Path, **changes: object) -> Path:
    """flight-paper with ``changes`` (a 100 Hz loop keeps the lifted checks small), as a scenario file."""
    scenario = replace(load_scenario("flight-paper"), **changes)  # type: ignore[arg-type]
    path.write_text(scenario_toml(scenario), encoding="utf-8")
    return path


def _flown(capsys: pytest.CaptureFixture[str], *argv: str, code: int = 0) -> dict[str, dict[str, object]]:
    assert main(["verify", *argv, "--orders", "1", "--json"]) == code
    return {row["check"]: row for row in json.loads(capsys.readouterr().out)["flown"]}


@pytest.mark.slow
def test_flight_paper_is_verified_as_flown_end_to_end(capsys: pytest.CaptureFixture[str]) -> None:
    """The shipped flight-paper: 1 kHz with d = 500, jitter [0.45, 0.5] s, J within ±5 %: all certified."""
    flown = _flown(capsys, "flight-paper")
    assert set(flown) == {"sampled", "jitter", "inertia"}
    sampled = flown["sampled"]
    assert sampled["source"] == "rate" and sampled["rate_hz"] == 1000.0 and sampled["delay_samples"] == 500
    assert sampled["certified"] is True and sampled["exact_stable"] is True
    # The largest radius is axis 1's (J = 140): the independent lifted loop gives the same number.
    reference = _lifted_radius(paper.INERTIA[0], paper.GAIN_SIGMA, paper.GAIN_OMEGA, 1e-3, 500)
    assert sampled["spectral_radius"] == pytest.approx(reference, rel=1e-9) and reference < 1.0
    jitter = flown["jitter"]
    # The held torque adds one period to the measurement's delay: tau(t) in [0.45, 0.501) s, jumping.
    assert jitter["source"] == "[delay] tau_min" and jitter["certified"] is True
    assert jitter["tau_min"] == 0.45 and jitter["tau_max"] == pytest.approx(0.501, rel=1e-12)
    assert jitter["delay_rate"] == "rate unknown"
    inertia = flown["inertia"]
    assert inertia["source"] == "[uncertainty]" and inertia["inertia_tolerance"] == 0.05
    assert inertia["certified"] is True
    # Certified => exactly stable at the ends of the box (the closed-form margin of every axis > tau).
    for j in paper.INERTIA:
        for scale in (0.95, 1.05):
            assert _axis_margin(scale * j, paper.GAIN_SIGMA, paper.GAIN_OMEGA) > 0.5


def test_no_flown_keeps_the_idealised_loop(capsys: pytest.CaptureFixture[str]) -> None:
    assert _flown(capsys, "flight-paper", "--no-flown") == {}
    assert main(["verify", "flight-paper", "--no-flown", "--sampled", "100"]) == USER_ERROR
    _one_line_error(capsys, "--sampled", "--no-flown")


def test_options_override_the_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(
        tmp_path / "s.toml",
        tau=0.2,
        rate=100.0,
        delay=DelayModel.jitter(0.1, 0.2, seed=2),
        uncertainty=InertiaUncertainty(0.05),
    )
    from_file = _flown(capsys, str(path))
    assert from_file["sampled"]["delay_samples"] == 20 and from_file["sampled"]["source"] == "rate"
    assert from_file["jitter"]["tau_min"] == 0.1 and from_file["jitter"]["tau_max"] == pytest.approx(0.21)
    assert from_file["inertia"]["source"] == "[uncertainty]"
    assert all(row["certified"] for row in from_file.values())
    assert main(["verify", str(path), "--orders", "1"]) == 0
    out = capsys.readouterr().out
    assert "sampled (rate): certified" in out and "jitter ([delay] tau_min): certified" in out
    assert "inertia ([uncertainty]): certified" in out
    argv = [str(path), "--sampled", "50", "--jitter", "0.15", "--jitter-rate", "0.5", "--inertia-tolerance", "0.1"]
    flags = _flown(capsys, *argv)
    assert flags["sampled"]["source"] == "--sampled" and flags["sampled"]["delay_samples"] == 10
    assert flags["jitter"]["source"] == "--jitter" and flags["jitter"]["tau_min"] == 0.15
    assert flags["jitter"]["tau_max"] == pytest.approx(0.22) and "0.5" in str(flags["jitter"]["delay_rate"])
    assert flags["inertia"]["source"] == "--inertia-tolerance" and flags["inertia"]["inertia_tolerance"] == 0.1
    reference = max(_lifted_radius(j, paper.GAIN_SIGMA, paper.GAIN_OMEGA, 0.02, 10) for j in paper.INERTIA)
    assert flags["sampled"]["spectral_radius"] == pytest.approx(reference, rel=1e-9)
    # The rate of a scenario's jitter may be bounded from the command line; without [delay] it needs --jitter.
    plain = _write(tmp_path / "plain.toml", tau=0.2, rate=100.0, delay=None)
    assert main(["verify", str(plain), "--jitter-rate", "0.5"]) == USER_ERROR
    _one_line_error(capsys, "--jitter-rate")


def test_beyond_the_exact_limits_nothing_is_certified(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """tau = 1.6 s is past the exact margin (1.5555 s): the sampled and jitter rows fail, as the exact check."""
    path = _write(tmp_path / "far.toml", tau=1.6, rate=100.0, delay=DelayModel.jitter(1.0, 1.6, seed=2))
    flown = _flown(capsys, str(path), code=NOT_VERIFIED)
    assert flown["sampled"]["exact_stable"] is False and flown["sampled"]["certified"] is False
    assert _lifted_radius(paper.INERTIA[2], paper.GAIN_SIGMA, paper.GAIN_OMEGA, 0.01, 160) > 1.0
    assert flown["jitter"]["certified"] is False
    # An inertia box past the exact limit (±81.86 % at tau = 0.5 s, design/lmi.md 7.4) is never certified:
    # at J3 (1 - 0.9) the closed-form margin is below 0.5 s.
    assert _axis_margin(0.1 * paper.INERTIA[2], paper.GAIN_SIGMA, paper.GAIN_OMEGA) < 0.5
    wide = _write(tmp_path / "wide.toml", tau=0.5, rate=100.0, delay=None, uncertainty=InertiaUncertainty(0.9))
    assert _flown(capsys, str(wide), code=NOT_VERIFIED)["inertia"]["certified"] is False


def test_tau_zero_scenario_still_checks_the_sampled_loop(capsys: pytest.CaptureFixture[str]) -> None:
    """At tau = 0 the loop is still sampled and held (d = 0): that row is there, stable and certified."""
    flown = _flown(capsys, "paper_fig2_tau0_on_current")
    assert set(flown) == {"sampled"}
    assert flown["sampled"]["delay_samples"] == 0 and flown["sampled"]["exact_stable"] is True
    reference = max(_lifted_radius(j, paper.GAIN_SIGMA, paper.GAIN_OMEGA, 1e-3, 0) for j in paper.INERTIA)
    assert flown["sampled"]["spectral_radius"] == pytest.approx(reference, rel=1e-9)
    assert flown["sampled"]["certified"] is True


@pytest.mark.parametrize(
    ("table", "needle"),
    [
        ("[uncertainty]\ntolerance = 0.1\n", "tolerance"),
        ("[uncertainty]\nproduct_bound = 1.0\n", "inertia_tolerance"),
        ("[uncertainty]\ninertia_tolerance = 1.5\n", "inertia_tolerance"),
        ("[uncertainty]\ninertia_tolerance = -0.1\n", "inertia_tolerance"),
        ("[uncertainty]\ninertia_tolerance = 0.1\nproduct_bound = -2.0\n", "product_bound"),
        ("[uncertainty]\ninertia_tolerance = true\n", "inertia_tolerance"),
        ("uncertainty = 0.1\n", "[uncertainty]"),
    ],
)
def test_bad_uncertainty_keys_name_the_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], table: str, needle: str
) -> None:
    text = scenario_toml(load_scenario("flight-paper")).replace("[uncertainty]", "[old_uncertainty]")
    text = text.split("\n[old_uncertainty]")[0]
    if table.startswith("uncertainty ="):  # a top-level key must come before the tables
        text = table + text
    else:
        text += "\n" + table
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["verify", str(path)]) == USER_ERROR
    _one_line_error(capsys, needle)


def test_uncertainty_needs_a_diagonal_nominal_inertia(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    text = scenario_toml(load_scenario("flight-paper")).replace(
        "inertia = [140.0, 100.0, 80.0]", "inertia = [[140.0, 1.0, 0.0], [1.0, 100.0, 0.0], [0.0, 0.0, 80.0]]"
    )
    assert "[[140.0, 1.0" in text
    path = tmp_path / "coupled.toml"
    path.write_text(text, encoding="utf-8")
    assert main(["verify", str(path)]) == USER_ERROR
    _one_line_error(capsys, "[uncertainty]", "diagonal")


def test_uncertainty_round_trips_and_is_shown() -> None:
    scenario = load_scenario("flight-paper")
    assert scenario.uncertainty == InertiaUncertainty(0.05, 0.0)
    again = replace(scenario, uncertainty=InertiaUncertainty(0.1, 2.5))
    parsed = parse_scenario(tomllib.loads(scenario_toml(again)))
    assert parsed.uncertainty == InertiaUncertainty(0.1, 2.5)
    assert "J_ii within +-10 %" in str(parsed) and "|J_ij| <= 2.5 kg m^2" in str(parsed)
    assert replace(scenario, uncertainty=None).uncertainty is None
    assert "[uncertainty]" not in scenario_toml(replace(scenario, uncertainty=None))


def test_the_documented_table_is_what_the_parser_reads() -> None:
    """docs/how-to/certify.md shows the [uncertainty] table: appended to a scenario it parses as documented."""
    page = (Path(__file__).resolve().parents[1] / "docs" / "how-to" / "certify.md").read_text(encoding="utf-8")
    block = page.split("```toml\n", 1)[1].split("```", 1)[0]
    base = scenario_toml(replace(load_scenario("flight-paper"), uncertainty=None))
    parsed = parse_scenario(tomllib.loads(base + "\n" + block))
    assert parsed.uncertainty == InertiaUncertainty(0.05, 0.0)


def test_a_lifted_loop_too_large_is_refused_up_front(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """d = 2500 samples per axis is a 5002-row companion matrix (> MAX_LIFTED_SIZE): one line, with the way out."""
    path = _write(tmp_path / "long.toml", tau=2.5, rate=1000.0, delay=None, uncertainty=None)
    assert main(["verify", str(path), "--orders", "1"]) == USER_ERROR
    _one_line_error(capsys, "rate = 1000 Hz", "5002x5002", "--no-flown")


@pytest.mark.parametrize(
    ("tolerance", "bound", "needle"),
    [
        (1.0, 0.0, "inertia_tolerance"),
        (0.0, 0.0, "inertia_tolerance"),
        (True, 0.0, "inertia_tolerance"),
        (0.1, -1.0, "product_bound"),
        (0.1, math.nan, "product_bound"),
    ],
)
def test_inertia_uncertainty_checks_its_values(tolerance: float, bound: float, needle: str) -> None:
    with pytest.raises(SpecificationError, match=needle):
        InertiaUncertainty(tolerance, bound)
