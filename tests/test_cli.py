"""The mrpctl command, run through main(argv): each subcommand, and user errors as exit code 2."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from mrpctl import paper
from mrpctl.cli import USER_ERROR, main

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "scenarios"
FIG4 = EXAMPLES / "paper_fig4_on_delayed.toml"


def test_example(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["example"]) == 0
    assert "diag(140, 100, 80)" in capsys.readouterr().out


def test_simulate_writes_plot_and_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plot, table = tmp_path / "run.png", tmp_path / "run.csv"
    argv = [
        "simulate",
        str(FIG4),
        "--rule",
        "delay-aware",
        "--t-final",
        "3",
        "--plot",
        str(plot),
        "--csv",
        str(table),
    ]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "DelayAware" in out and "switches     2" in out
    assert plot.read_bytes()[:4] == b"\x89PNG"
    with table.open(encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    assert rows[0][:2] == ["t_s", "sigma1"]
    assert len(rows) == 1 + 3001
    assert float(rows[1][1]) == pytest.approx(paper.INITIAL_SIGMA[0], abs=1e-15)


def test_verify_reports_each_criterion(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", str(FIG4), "--orders", "0", "1"]) == 0
    out = capsys.readouterr().out
    assert "exact delay margin: 1.555" in out
    assert "Jensen (N=0)" in out and "Wirtinger (N=1)" in out and "CERTIFIED" in out


def test_verify_beyond_the_margin_is_not_certified(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", "--inertia", "140", "100", "80", "--tau", "2.0", "--orders", "1"]) == 0
    out = capsys.readouterr().out
    assert "stable at tau = 2 s: False" in out and "NOT_CERTIFIED" in out


def test_sweep_eps_table_plot_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["sweep", "eps", "--values", "0.005", "0.2", "--t-final", "10", "--plot", str(tmp_path / "s.png")]
    argv += ["--csv", str(tmp_path / "s.csv")]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "[" in captured.err and "2/2" in captured.err  # progress bar
    assert "0.005" in captured.out and "0.2" in captured.out
    assert (tmp_path / "s.png").exists()
    with (tmp_path / "s.csv").open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert [float(r["value"]) for r in rows] == [0.005, 0.2]
    assert int(rows[1]["switches"]) > int(rows[0]["switches"])


def test_sweep_tumble(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["sweep", "tumble", "--count", "4", "--rule", "delay-aware", "--t-final", "20"]) == 0
    assert "runs converged" in capsys.readouterr().out


def test_reproduce_writes_results(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["reproduce", "--out", str(tmp_path), "--t-final", "15"]) == 0
    assert (tmp_path / "claims.md").exists() and (tmp_path / "fig5_on_delayed_zoom.png").exists()
    assert "claims" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["simulate", "missing.toml"], "scenario file not found"),
        (["simulate", str(FIG4), "--eps", "0.1"], "--eps and --alpha need --rule"),
        (["simulate", str(FIG4), "--rule", "boundary-layer"], "needs eps"),
        (["simulate", str(FIG4), "--tau", "0.0005"], "tau"),
        (["simulate", str(FIG4), "--tau", "-1"], "tau"),
        (["sweep", "tau"], "needs --values"),
        (["verify", "--inertia", "1", "-1", "1"], "inertia must be positive definite"),
    ],
)
def test_user_errors_are_one_line(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == USER_ERROR
    err = capsys.readouterr().err
    assert err.startswith("mrpctl: error:") and message in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_design_synthesizes_certified_gains(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "--inertia", "140", "100", "80", "--tau", "0.5", "--order", "1"]) == 0
    out = capsys.readouterr().out
    assert "tau = 0.5 s" in out and "verified" in out and "omega_n" in out
    assert "gain analysis" in out


def test_design_rejects_underdamped_request(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "--inertia", "140", "100", "80", "--tau", "0.5", "--zeta", "0.5"]) == USER_ERROR
    assert "zeta" in capsys.readouterr().err


def test_export_writes_folder_and_refuses_to_overwrite(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "export"
    assert main(["export", str(FIG4), "--out", str(out), "--no-compile"]) == 0
    assert (out / "manifest.json").exists() and (out / "step.casadi").exists()
    assert not (out / "libmrpctl_model.so").exists()
    capsys.readouterr()
    assert main(["export", str(FIG4), "--out", str(out)]) == USER_ERROR
    assert "--overwrite" in capsys.readouterr().err
    assert main(["export", str(FIG4), "--out", str(out), "--overwrite", "--no-compile"]) == 0
