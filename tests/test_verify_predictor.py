"""``mrpctl verify`` of a predictor scenario: the verdict is the predictor loop's, against a lifted matrix built here.

The sampled predictor loop per axis (diagonal J, J_m and gain): x̂_{k+1} = F₀ x̂_k + F₁ x̂_{k−d} with
F₀ = Φ + Γ_m K_i, F₁ = Φ^d (Γ − Γ_m) K_i, Φ = [1 h; 0 1], Γ = [h²/8; h/4]/J (design/predictor.md); its
block-companion matrix of size 2 (d + 1) is written and its eigenvalues taken with NumPy here.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_assertions import one_line_error

from mrpctl.cli import USER_ERROR, main
from mrpctl.cli.common import NOT_VERIFIED
from mrpctl.scenario import load_scenario

INERTIA = np.array([140.0, 100.0, 80.0])
K1, K2 = -16.0, -8.0  # the scenario's PD gains (ζ = 1, ωₙ = 4 rad/s); the (3, 6) K is the scenario's own
RATE, TAU = 100.0, 0.5


def _scenario(tmp_path: Path, error: float, extra: str = "") -> Path:
    text = f"""
tau = {TAU}
rate = {RATE}
t_final = 2.0

[spacecraft]
inertia = [140.0, 100.0, 80.0]

[gains]
K1 = {K1}
K2 = {K2}

[initial]
sigma = [0.3, 0.0, 0.0]
omega = [0.0, 0.0, 0.0]

[rule]
type = "on-predicted"

[predictor]
inertia_error = {error}
{extra}
"""
    path = tmp_path / f"predictor_{error}{'_flown' if extra else ''}.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _lifted_radius(tmp_path: Path, error: float) -> float:
    """The largest |λ| of the per-axis lifted predictor loops (plant J, model J / (1 + e), the scenario's K)."""
    k = load_scenario(_scenario(tmp_path, error)).K
    h = 1.0 / RATE
    d = round(TAU * RATE)
    phi = np.array([[1.0, h], [0.0, 1.0]])
    worst = 0.0
    for axis, plant in enumerate(INERTIA):
        gain = k[axis : axis + 1, [axis, axis + 3]]
        assert np.count_nonzero(k[axis]) == 2  # the loop splits per axis
        model = plant / (1.0 + error)
        gamma, gamma_m = np.array([[h * h / 8], [h / 4]]) / plant, np.array([[h * h / 8], [h / 4]]) / model
        f0 = phi + gamma_m @ gain
        f1 = np.linalg.matrix_power(phi, d) @ (gamma - gamma_m) @ gain
        size = 2 * (d + 1)
        lifted = np.zeros((size, size))
        lifted[0:2, 0:2] = f0
        lifted[0:2, 2 * d : 2 * d + 2] = f1
        lifted[2:, :-2] = np.eye(size - 2)
        worst = max(worst, float(np.max(np.abs(np.linalg.eigvals(lifted)))))
    return worst


@pytest.mark.parametrize("error", [0.0, 0.1, 1.5, -0.5])
def test_the_verdict_is_the_predictor_loops(tmp_path: Path, capsys: pytest.CaptureFixture[str], error: float) -> None:
    radius = _lifted_radius(tmp_path, error)
    assert abs(radius - 1.0) > 1e-3  # each case is clearly on one side
    code = main(["verify", str(_scenario(tmp_path, error)), "--json"])
    out = json.loads(capsys.readouterr().out)
    assert out["stable"] == (radius < 1.0) and out["verified"] == (radius < 1.0)
    assert code == (0 if radius < 1.0 else NOT_VERIFIED)
    assert "either predictor form" in out["covers"] and out["delay_samples"] == 50
    assert out["mismatch_margin"]["uniform"][0] < 0 < out["mismatch_margin"]["uniform"][1]
    # the margin brackets the verdict: stable inside it, unstable beyond it
    lower, upper = out["mismatch_margin"]["uniform"]
    assert (lower < error < upper) == (radius < 1.0)


def test_an_unstable_case_says_so_and_names_what_is_not_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert _lifted_radius(tmp_path, -0.5) > 1.0
    assert main(["verify", str(_scenario(tmp_path, -0.5))]) == NOT_VERIFIED
    text = capsys.readouterr().out
    assert "predictor verdict: NOT VERIFIED (UNSTABLE)" in text
    assert "not run: the plain delayed loop's delay margin, LMI criteria" in text
    assert "not checked (the verdict is local)" in text


def test_flight_models_are_named_and_not_verified(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _scenario(tmp_path, 0.0, "\n[actuator]\nu_max = 50.0\n")
    assert _lifted_radius(tmp_path, 0.0) < 1.0
    assert main(["verify", str(path), "--json"]) == NOT_VERIFIED
    out = json.loads(capsys.readouterr().out)
    assert out["stable"] and not out["verified"]
    assert any("actuator" in item for item in out["not_covered"])


def test_the_plain_loops_options_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", str(_scenario(tmp_path, 0.0)), "--jitter", "0.45"]) == USER_ERROR
    one_line_error(capsys, "--jitter", "predictor scenario")
