"""``verify`` prints the joint verdict on the loop as flown and exits 1 when it is not VERIFIED;
``design --rate R --toml`` verifies the loop at the rate it writes (independent lifted check here)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mrpctl import paper
from mrpctl.cli import NOT_VERIFIED, main
from mrpctl.design import pd_gains
from mrpctl.spacecraft import Spacecraft

SC = Spacecraft(np.diag(paper.INERTIA))


def _lifted_radius(inertia: float, k1: float, k2: float, h: float, d: int) -> float:
    """One axis, double integrator held over h: Phi = [[1, h], [0, 1]], Gamma = b [h^2/2; h], b = 1/(4J)."""
    b = 0.25 / inertia
    n = 2 * (d + 1)
    m = np.zeros((n, n))
    m[:2, :2] = [[1.0, h], [0.0, 1.0]]
    m[:2, 2 * d :] += b * np.array([[h * h / 2.0], [h]]) @ np.array([[k1, k2]])
    if d:
        m[2:, :-2] = np.eye(2 * d)
    return float(np.max(np.abs(np.linalg.eigvals(m))))


def _gain_options(omega_n: float) -> list[str]:
    k = pd_gains(SC, zeta=1.0, omega_n=omega_n).K
    return [
        "--k-sigma",
        *(repr(float(k[i, i])) for i in range(3)),
        "--k-omega",
        *(repr(float(k[i, 3 + i])) for i in range(3)),
    ]


def test_verify_20hz_box_is_unstable_jointly_and_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["verify", *_gain_options(1.06), "--tau", "0.5", "--orders", "1", "--sampled", "20"]
    assert main([*argv, "--inertia-tolerance", "0.2", "--json"]) == NOT_VERIFIED
    data = json.loads(capsys.readouterr().out)
    # Each part alone is certified, as before; the joint verdict is not.
    assert all(row["certified"] for row in data["flown"])
    joint = data["joint"]
    assert joint["status"] == "UNSTABLE" and data["exit_code"] == NOT_VERIFIED
    witness = joint["witness"]
    j = np.diag(np.array(witness["inertia"]))
    assert np.allclose(j, 0.8 * np.array(paper.INERTIA))
    k = pd_gains(SC, zeta=1.0, omega_n=1.06).K
    reference = max(_lifted_radius(j[i], k[i, i], k[i, 3 + i], 0.05, 10) for i in range(3))
    assert reference > 1.0 and witness["spectral_radius"] == pytest.approx(reference, abs=1e-9)
    # Without the box the same loop is verified (exit 0), and the text names the axes.
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "joint verdict: VERIFIED" in out and "axis 3 (J = 80 kg m^2)" in out and "exit code 0" in out


def test_verify_not_certified_says_why_in_plain_words(capsys: pytest.CaptureFixture[str]) -> None:
    # 2 Hz, d = 1 with the design gains: exactly unstable (1.0244), so the sampled row says so.
    argv = ["verify", *_gain_options(0.889707), "--tau", "0.5", "--orders", "1", "--sampled", "2"]
    assert main(argv) == NOT_VERIFIED
    out = capsys.readouterr().out
    assert "sampled (--sampled): NOT certified: the sampled loop is unstable" in out
    assert "no certificate can exist" in out and "joint verdict: UNSTABLE" in out


def test_verify_help_documents_exit_code_1(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["verify", "--help"])
    out = capsys.readouterr().out
    assert "1    checked, but not verified" in out


@pytest.mark.parametrize(("rate", "verified"), [(2.0, False), (20.0, True)])
def test_design_verifies_at_the_rate_it_writes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], rate: float, verified: bool
) -> None:
    path = tmp_path / "d.toml"
    argv = ["design", "--inertia", "140", "100", "80", "--tau", "0.5", "--rate", f"{rate:g}", "--toml", str(path)]
    assert main([*argv, "--json"]) == 0
    captured = capsys.readouterr()
    data = json.loads(captured.out)
    k = np.array(data["K"])
    d = round(0.5 * rate)
    reference = max(_lifted_radius(paper.INERTIA[i], k[i, i], k[i, 3 + i], 1.0 / rate, d) for i in range(3))
    assert (reference < 1.0) is verified
    assert data["written_verdict"]["status"] == ("VERIFIED" if verified else "UNSTABLE")
    header = "\n".join(line for line in path.read_text(encoding="utf-8").splitlines() if line.startswith("#"))
    description = next(line for line in path.read_text(encoding="utf-8").splitlines() if line.startswith("description"))
    if verified:
        assert "verified jointly" in header and "warning" not in captured.err
    else:
        assert "verified" not in description and "NOT verified at 2 Hz" in header
        assert "synthesized and verified" not in header
        assert "warning" in captured.err and "not verified at its rate 2 Hz" in captured.err


def test_design_sampled_without_tolerance_prints_nominal_inertia(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "--inertia", "140", "100", "80", "--tau", "0.5", "--sampled", "20"]) == 0
    out = capsys.readouterr().out
    assert "+/-0 %" not in out and "nominal inertia" in out
