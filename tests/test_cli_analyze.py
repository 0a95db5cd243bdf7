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
        (["--period", "0"], "--period"),
        (["--period", "nan"], "--period"),
        (["--period", "0.3"], "--period"),
        (["--plot-sigma", "sigma.foo"], "--plot-sigma"),
        (["--synthesize", "pd-h2", "--starts", "0"], "starts"),
        (["--synthesize", "pid-hinf", "--torque-psd", "1e-6"], "--synthesize"),
        (["--synthesize", "pd-h2", "--k-sigma", "100", "100", "100", "--k-omega", "500", "500", "500"], "--synthesize"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, word, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and word in err


def test_analyze_sampled_loop_and_sigma_plot(capsys: pytest.CaptureFixture[str], tmp_path) -> None:
    figure = tmp_path / "sigma.png"
    assert main(["analyze", "--period", "0.05", "--plot-sigma", str(figure), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["delay_samples"] == 10
    # the library's sampled figures of the paper loop at 20 Hz (tests/test_design_sampled_performance.py checks them)
    assert payload["sampled_hinf"] == pytest.approx(0.0900822607, rel=1e-8)
    assert payload["sampled_h2"] == pytest.approx(0.05294702241, rel=1e-8)
    assert payload["sampled_hinf"] > payload["hinf_exact"]
    assert payload["sampled_l2_gain"] == pytest.approx(0.09008379608, rel=1e-8)
    assert payload["sampled_l2_bracket_certified"] is True
    # the coupled sampled margins are the library's (tests/test_design_sampled_margins.py checks them)
    from mrpctl import paper
    from mrpctl.design.sampled_margins import loop_margins_sampled
    from mrpctl.model import gain_matrix, plant_model

    plant = plant_model(paper.SPACECRAFT)
    margins = loop_margins_sampled(plant.A, plant.B, gain_matrix(paper.GAIN), 0.05, delay_samples=10)
    assert payload["sampled_gain_margin"] == margins.gain_margin
    assert payload["sampled_delay_margin_samples"] == margins.delay_margin_samples == 20
    assert payload["sampled_gain_margin"] < payload["gain_margin"]  # the hold costs margin
    assert figure.stat().st_size > 0


def test_analyze_unstable_sampled_loop_says_infinite_and_exits_1(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", "--tau", "2", "--period", "0.1"]) == 1
    out = capsys.readouterr().out
    assert "sampled-loop H-infinity norm infinite" in out and "sampled-data H2 norm infinite" in out
    assert "sampled-data L2 gain infinite" in out


def test_analyze_synthesizes_and_analyses_a_design(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", "--synthesize", "pd-h2", "--starts", "1", "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    assert payload["design"]["objective"] == "h2"
    # the H2-optimal PD has a lower H2 norm than the paper's gains (0.0524870196, design/performance.md)
    assert payload["h2"] < 0.0524870196
    assert main(["analyze", "--synthesize", "pid-abscissa", "--starts", "1"]) == 0
    out = capsys.readouterr().out
    assert "PID optimal for abscissa" in out and "H-infinity norm" in out
