"""`mrpctl design --inertia-tolerance / --product-bound / --sampled`: robust gains, checked independently."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_assertions import one_line_error as _one_line_error

from mrpctl.cli import USER_ERROR, main
from mrpctl.design import delay_margin
from mrpctl.design.sampled import sampled_stability
from mrpctl.scenario import load_scenario

J = np.array([140.0, 100.0, 80.0])
BASE = ["design", "--inertia", "140", "100", "80"]


def test_inertia_tolerance_gains_are_stable_at_every_box_end(capsys: pytest.CaptureFixture[str]) -> None:
    argv = [*BASE, "--tau", "0.5", "--inertia-tolerance", "0.2", "--order", "1", "--rtol", "0.05"]
    assert main([*argv, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["status"] == "SYNTHESIZED" and data["certified"] is True and data["model"] == "CONSTANT"
    assert data["inertia_tolerance"] == 0.2 and data["order"] == 1
    k = np.array(data["K"])
    w = data["omega_n"]
    # Independent of the polytope code: K = [4 J K1, 4 J K2] (nominal J), and each axis' 2x2 loop with
    # J_ii scaled by 0.8 and 1.2 (the worst ends of the segment for a PD loop) has an exact margin > tau.
    np.testing.assert_allclose(np.diag(k[:, :3]), 4 * J * -(w**2), rtol=1e-12)
    for i in range(3):
        for scale in (0.8, 1.0, 1.2):
            jj = scale * J[i]
            a_d = [[0.0, 0.0], [k[i, i] / (4 * jj), k[i, 3 + i] / (4 * jj)]]
            assert delay_margin([[0.0, 1.0], [0.0, 0.0]], a_d).margin > 0.5
    assert "vertex-dependent" in data["certificate"] and "exact worst" in data["exact_check"]
    assert main([*argv[:-1], "0.3"]) == 0  # the text form, coarser bracket
    out = capsys.readouterr().out
    assert "robust PD (constant delay" in out and "inertia +/-20 %" in out and "polytope certificate" in out
    assert "K (3x6, N m)" in out and "axis 3: K1 = " in out


def test_sampled_gains_are_stable_when_lifted(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    toml = tmp_path / "robust.toml"
    argv = [*BASE, "--tau", "0.05", "--sampled", "100", "--rtol", "0.1", "--toml", str(toml), "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["model"] == "SAMPLED" and data["sampled_rate"] == 100.0 and data["order"] == 0
    assert data["tau_min"] == pytest.approx(0.05) and data["tau_max"] == pytest.approx(0.06)
    k = np.array(data["K"])
    # Exact lifted check of each axis at h = 10 ms, d = 5 samples (the loop as simulated).
    a = np.array([[0.0, 1.0], [0.0, 0.0]])
    for i in range(3):
        b = np.array([[0.0], [1.0 / (4 * J[i])]])
        assert sampled_stability(a, b, np.array([[k[i, i], k[i, 3 + i]]]), 0.01, delay_samples=5).stable
    scenario = load_scenario(toml)
    np.testing.assert_array_equal(scenario.K, k)
    assert scenario.rate == 100.0 and scenario.tau == 0.05
    assert "--sampled 100" in toml.read_text()


@pytest.mark.parametrize(
    ("extra", "needles"),
    [
        (["--tau", "0.5", "--product-bound", "2"], ("--product-bound applies only with --inertia-tolerance",)),
        (["--tau", "0.5", "--rtol", "0.1"], ("--rtol applies only with",)),
        (["--tau", "0.5", "--inertia-tolerance", "1.5"], ("--inertia-tolerance must be < 1",)),
        (["--tau", "0.5", "--inertia-tolerance", "-0.1"], ("--inertia-tolerance",)),
        (["--tau", "0.0105", "--sampled", "1000"], ("--sampled: tau * HZ must be a whole number",)),
        (
            ["--tau", "0.5", "--sampled", "1000", "--rate", "500", "--toml", "never-written.toml"],
            ("--rate 500 differs from --sampled 1000",),
        ),
        (["--tau", "0.5", "--inertia-tolerance", "0.1", "--rtol", "0"], ("--rtol",)),
    ],
)
def test_one_line_errors(extra: list[str], needles: tuple[str, ...], capsys: pytest.CaptureFixture[str]) -> None:
    assert main([*BASE, *extra]) == USER_ERROR
    _one_line_error(capsys, *needles)


def test_coupled_nominal_inertia_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["design", "--inertia", "140", "1", "0", "1", "100", "0", "0", "0", "80", "--tau", "0.5"]
    assert main([*argv, "--inertia-tolerance", "0.1"]) == USER_ERROR
    _one_line_error(capsys, "diagonal nominal inertia")


def test_no_robust_gain_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    import mrpctl.design.robust as robust
    import mrpctl.design.synthesis as synthesis

    real = robust.synthesize_robust_pd

    orders: list[object] = []

    def infeasible(*args: object, **kwargs: object) -> object:
        orders.append(kwargs["order"])
        # The real function, made to find nothing: every certificate test reports "not certified".
        monkeypatch.setattr(robust, "certify_polytope", lambda *a, **k: _NotCertified())
        return real(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(synthesis, "synthesize_robust_pd", infeasible)  # the CLI goes through synthesize_pd
    assert main([*BASE, "--tau", "0.5", "--inertia-tolerance", "0.2"]) == USER_ERROR
    _one_line_error(capsys, "no robustly certified gains", "inertia +-20 %", "no omega_n down to 1 %")
    assert main([*BASE, "--tau", "0.5", "--inertia-tolerance", "0.2", "--order", "3"]) == USER_ERROR
    assert orders == [2, 3]  # the robust default order is 2; an explicit --order 3 is kept


class _NotCertified:
    from mrpctl.design.lmi import CertificateStatus

    certified = False
    status = CertificateStatus.NOT_CERTIFIED
