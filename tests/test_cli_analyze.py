"""``mrpctl analyze``: the figures of the delayed loop, one line and exit 2 on bad input, exit 1 when unstable."""

from __future__ import annotations

import json

import pytest

from mrpctl.cli import main


def test_analyze_prints_the_figures_of_the_paper_loop(capsys: pytest.CaptureFixture[str], tmp_path) -> None:
    figure = tmp_path / "roots.png"
    assert main(["analyze", "--torque-psd", "1e-6", "--attitude-noise", "1e-5", "--plot", str(figure)]) == 0
    out = capsys.readouterr().out
    assert "spectral abscissa -0.12967" in out
    assert "H-infinity norm 0.0890910918" in out
    assert "certified by the bounded-real LMI" in out
    assert "pointing 3-sigma" in out
    assert figure.stat().st_size > 0


def test_analyze_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["stable"] is True
    assert payload["hinf_certified"] >= payload["hinf_exact"]
    assert payload["hinf_ratio"] >= 0.99


def test_analyze_unstable_loop_says_infinite_and_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", "--tau", "2"]) == 1
    assert "infinite" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "word"),
    [
        (["--tau", "-1"], "--tau"),
        (["--tau", "nan"], "--tau"),
        (["--torque-psd", "-1"], "--torque-psd"),
        (["--attitude-noise", "inf"], "--attitude-noise"),
        (["--inertia", "1", "2"], "--inertia"),
        (["--order", "-1"], "order"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, word, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and word in err
