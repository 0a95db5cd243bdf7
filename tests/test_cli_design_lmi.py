"""`mrpctl design --method lmi` and `design --jitter`: robust options reaching the synthesis, checked independently."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from mrpctl.cli import USER_ERROR, main
from mrpctl.scenario import load_scenario

J = np.array([140.0, 100.0, 80.0])
BASE = ["design", "--inertia", "140", "100", "80", "--tau", "0.5"]


def _margin(k1: float, k2: float) -> float:
    """Exact delay margin of sigma'' = k1 sigma(t - tau) + k2 sigma'(t - tau), k1, k2 < 0."""
    a, b = -k1, -k2
    omega = math.sqrt((b * b + math.sqrt(b**4 + 4 * a * a)) / 2)
    return math.atan2(b * omega, a) / omega


def test_lmi_with_an_inertia_tolerance_is_stable_over_the_box(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    toml = tmp_path / "lmi.toml"
    argv = [*BASE, "--method", "lmi", "--decay-rate", "0.2", "--inertia-tolerance", "0.1", "--order", "0"]
    assert main([*argv, "--toml", str(toml), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["status"] == "SYNTHESIZED" and data["method"] == "lmi" and data["certified"] is True
    assert data["inertia_tolerance"] == 0.1 and data["model"] == "CONSTANT" and data["decay_rate"] == 0.2
    k = np.array(data["K"])
    for i in range(3):
        k1, k2 = k[i, i] / (4 * J[i]), k[i, 3 + i] / (4 * J[i])
        for scale in np.linspace(0.9, 1.1, 11):
            assert _margin(k1 / scale, k2 / scale) > 0.5
    scenario = load_scenario(toml)
    np.testing.assert_array_equal(scenario.K, k)
    assert "--method lmi" in toml.read_text() and "--inertia-tolerance 0.1" in toml.read_text()


def test_lmi_jitter_reaches_synthesize_lmi(capsys: pytest.CaptureFixture[str]) -> None:
    argv = [*BASE, "--method", "lmi", "--decay-rate", "0.2", "--jitter", "0.4", "--order", "0"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "interval time-varying delay, tau in [0.4, 0.5] s" in out and "synthesized and verified" in out
    assert "polytope certificate" in out and "axis 3: K1 = " in out


def test_pd_jitter_reaches_the_robust_pd_design(capsys: pytest.CaptureFixture[str]) -> None:
    argv = [*BASE, "--jitter", "0.4", "--jitter-rate", "0.5", "--order", "0", "--rtol", "0.3", "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["model"] == "INTERVAL" and data["tau_min"] == 0.4 and data["tau_max"] == 0.5
    assert data["status"] == "SYNTHESIZED"
    k = np.array(data["K"])
    for i in range(3):
        assert _margin(k[i, i] / (4 * J[i]), k[i, 3 + i] / (4 * J[i])) > 0.5


@pytest.mark.parametrize(
    ("extra", "needles"),
    [
        (["--decay-rate", "0.2"], ("--decay-rate applies only with --method lmi",)),
        (["--method", "lmi"], ("--method lmi needs --decay-rate",)),
        (["--method", "lmi", "--decay-rate", "-1"], ("--decay-rate must be >= 0",)),
        (["--method", "lmi", "--decay-rate", "0.1", "--rtol", "0.1"], ("--rtol applies only with --method pd",)),
        (["--jitter-rate", "0.5"], ("--jitter-rate applies only with --jitter",)),
        (["--jitter", "0.6"], ("--jitter TAU_MIN must be < tau",)),
        (["--jitter", "0.4", "--sampled", "10"], ("either --jitter",)),
        (
            ["--method", "lmi", "--decay-rate", "0.1", "--inertia-tolerance", "1.5"],
            ("--inertia-tolerance must be < 1",),
        ),
        (["--method", "lmi", "--decay-rate", "0.1", "--sampled", "3"], ("whole number of samples",)),
        (["--method", "lmi", "--decay-rate", "2.0", "--order", "0", "--inertia-tolerance", "0.1"], ("no certified",)),
    ],
)
def test_bad_lmi_and_jitter_options_are_one_line_errors(
    extra: list[str], needles: tuple[str, ...], capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*BASE, *extra]) == USER_ERROR
    err = capsys.readouterr().err
    assert err.startswith("mrpctl: error:") and err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
