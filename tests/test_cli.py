"""The mrpctl command, run through main(argv): each subcommand, and user errors as exit code 2."""

from __future__ import annotations

import csv
import io
import json
import re
import subprocess
import sys
import tomllib
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from cli_assertions import one_line_error as _one_line_error

from mrpctl import __version__, paper
from mrpctl.cli import EXIT_BROKEN_PIPE, EXIT_DIVERGED, NOT_VERIFIED, USER_ERROR, main
from mrpctl.scenario import load_scenario, shipped_scenarios
from mrpctl.switching import BoundaryLayer

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "scenarios"
FIG4 = EXAMPLES / "paper_fig4_on_delayed.toml"
FIG2 = EXAMPLES / "paper_fig2_tau0_on_current.toml"


def test_example(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["example"]) == 0
    assert "diag(140, 100, 80)" in capsys.readouterr().out
    assert main(["example", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["K"] == paper.GAIN.tolist() and data["tau"] == paper.TAU


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["--version"])
    assert exit_info.value.code == 0
    assert capsys.readouterr().out.strip() == f"mrpctl {__version__}"


def test_help_shows_defaults_and_exit_codes(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["design", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "(default: 1.0)" in out  # --zeta
    assert "default 3, with --inertia-tolerance 2, with --sampled 0" in out  # --order depends on the certificate
    assert "critically damped" in out and "overdamped" not in out
    assert "exit codes:" in out and "--fail-on-divergence" in out
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "(default: 25)" in out and "(default: None)" not in out


def test_simulate_writes_plot_and_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    plot, table = tmp_path / "run.png", tmp_path / "run.csv"
    argv = ["simulate", str(FIG4), "--rule", "delay-aware", "--t-final", "3", "--plot", str(plot), "--csv", str(table)]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "DelayAware" in out and "switches     2" in out
    assert plot.read_bytes()[:4] == b"\x89PNG"
    with table.open(encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    assert rows[0][:2] == ["t_s", "sigma1"]
    assert len(rows) == 1 + 3001
    assert float(rows[1][1]) == paper.INITIAL_SIGMA[0]  # written to full precision
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv", "run.png"]  # no temporary file left


def test_interrupted_csv_keeps_the_old_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Ctrl-C while the CSV is written: exit 130, the old file intact, no temporary file left."""
    table = tmp_path / "run.csv"
    table.write_text("old\n", encoding="utf-8")

    def interrupted(stream: io.TextIOBase, *_: object, **__: object) -> None:
        stream.write("0,0.93,")  # half a row, then Ctrl-C
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savetxt", interrupted)
    assert main(["simulate", "delay_aware", "--t-final", "0.1", "--csv", str(table)]) == 130
    assert capsys.readouterr().err == "mrpctl: interrupted\n"
    assert table.read_text(encoding="utf-8") == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["run.csv"]


def test_simulate_json_and_shipped_name(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "paper_fig4_on_delayed", "--t-final", "2", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["scenario"]["rule"] == "on-delayed" and data["scenario"]["tau"] == 0.5
    assert data["result"]["switch_count"] >= 1 and data["result"]["diverged"] is False
    assert data["result"]["settling_time"] is None  # not settled in 2 s: null, not NaN


def test_simulate_without_a_file(capsys: pytest.CaptureFixture[str]) -> None:
    """--inertia, --K, --tau, --rule, --sigma, --omega give the whole run."""
    k = np.hstack((-10.0 * np.eye(3), -20.0 * np.eye(3)))
    argv = ["simulate", "--inertia", "12", "15", "9", "--K", *map(str, k.ravel()), "--tau", "0.2"]
    argv += ["--rule", "none", "--sigma", "0.1", "0", "0", "--omega", "0", "0.01", "0", "--t-final", "1", "--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["scenario"]["inertia"] == np.diag([12.0, 15.0, 9.0]).tolist()
    assert data["scenario"]["K"] == k.tolist() and data["scenario"]["rule"] == "none"
    assert data["scenario"]["sigma0"] == [0.1, 0.0, 0.0] and data["scenario"]["omega0"] == [0.0, 0.01, 0.0]
    assert data["result"]["tau"] == 0.2 and data["result"]["switch_count"] == 0


def test_simulate_run_overrides(capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["simulate", "delay_aware", "--rate", "500", "--substeps", "2", "--history", "zero-input", "--t-final", "1"]
    assert main([*argv, "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert (data["scenario"]["rate"], data["scenario"]["substeps"], data["scenario"]["history"]) == (
        500.0,
        2,
        "zero-input",
    )
    assert data["result"]["rate"] == 500.0
    assert main(["simulate", "delay_aware", "--substeps", "0"]) == USER_ERROR
    _one_line_error(capsys, "--substeps must be >= 1")


def test_fail_on_divergence(capsys: pytest.CaptureFixture[str]) -> None:
    """A positive-feedback gain diverges: exit 0 by default (a result), 1 with --fail-on-divergence."""
    argv = ["simulate", "--k-sigma", "1e4", "--k-omega", "1e4", "--tau", "0", "--rule", "none", "--t-final", "20"]
    assert main(argv) == 0
    assert "DIVERGED" in capsys.readouterr().out
    assert main([*argv, "--fail-on-divergence"]) == EXIT_DIVERGED
    assert "diverged" in capsys.readouterr().err


def test_verify_reports_each_criterion(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["verify", str(FIG4), "--orders", "0", "1", "--no-flown"]) == 0  # the idealised loop only
    out = capsys.readouterr().out
    assert "exact delay margin: 1.555" in out
    assert "Jensen (N=0)" in out and "Wirtinger (N=1)" in out and "CERTIFIED" in out


def test_verify_tau_zero_scenario(capsys: pytest.CaptureFixture[str]) -> None:
    """The shipped tau = 0 scenario: no certificate is needed; the undelayed loop is reported (exit 0)."""
    assert main(["verify", str(FIG2), "--orders", "1"]) == 0
    out = capsys.readouterr().out
    assert "tau = 0: no delay, so no delay certificate is needed" in out
    assert "undelayed loop is stable" in out and "exact delay margin: 1.555" in out
    assert main(["verify", str(FIG2), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["tau"] == 0.0 and data["undelayed_stable"] is True and data["criteria"] == []
    # Independent check: the undelayed poles of s^2 - K2 s - K1 per axis, K = [4 J K1, 4 J K2].
    j = np.array(paper.INERTIA)
    k1, k2 = paper.GAIN_SIGMA / (4 * j), paper.GAIN_OMEGA / (4 * j)
    poles = np.concatenate([np.roots([1.0, -b, -a]) for a, b in zip(k1, k2, strict=True)])
    assert max(data["undelayed_poles_real"]) == pytest.approx(poles.real.max(), rel=1e-9)


def test_verify_per_axis_gains(capsys: pytest.CaptureFixture[str]) -> None:
    """--k-sigma/--k-omega with 3 values each give the same verdict as the equal 18-number --K."""
    ks, kw = [-50.0, -60.0, -70.0], [-150.0, -160.0, -170.0]
    k = np.hstack((np.diag(ks), np.diag(kw)))
    assert main(["verify", "--k-sigma", *map(str, ks), "--k-omega", *map(str, kw), "--orders", "1", "--json"]) == 0
    per_axis = json.loads(capsys.readouterr().out)
    assert main(["verify", "--K", *map(str, k.ravel()), "--orders", "1", "--json"]) == 0
    full = json.loads(capsys.readouterr().out)
    assert per_axis["K"] == k.tolist() == full["K"]
    assert per_axis["exact_delay_margin"] == full["exact_delay_margin"] > 0.5
    assert per_axis["criteria"] == full["criteria"] and full["criteria"][0]["certified"] is True


def test_verify_prints_phase_margins(capsys: pytest.CaptureFixture[str]) -> None:
    """Per-axis phase margins (python-control) give the exact delay margin as min PM/crossover."""
    assert main(["verify", "--orders", "1", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    implied = [m["phase_margin_deg"] * np.pi / 180 / m["crossover_rad_s"] for m in out["phase_margins"]]
    assert np.allclose(implied, [m["delay_margin_s"] for m in out["phase_margins"]], rtol=1e-12)
    assert min(implied) == pytest.approx(out["exact_delay_margin"], rel=1e-8)
    # Coupled axes have no per-axis phase margin: reported as null, not an error.
    assert (
        main(["verify", "--K", *map(str, np.arange(1.0, 19.0) * -1.0), "--orders", "1", "--json"]) == NOT_VERIFIED
    )  # checked: not stable, so exit 1
    assert json.loads(capsys.readouterr().out)["phase_margins"] is None


def test_verify_the_loop_as_flown(capsys: pytest.CaptureFixture[str]) -> None:
    """--jitter, --sampled and --inertia-tolerance add certificates, checked against the exact answers."""
    from mrpctl.design import sampled_stability, spacecraft_axes

    argv = ["verify", "--tau", "0.5", "--orders", "1", "--json", "--jitter", "0.4", "--sampled", "100"]
    assert main([*argv, "--inertia-tolerance", "0.1"]) == 0
    flown = {row["check"]: row for row in json.loads(capsys.readouterr().out)["flown"]}
    assert flown["jitter"]["certified"] and flown["inertia"]["certified"]
    exact = [
        sampled_stability(a, b, k, 0.01, delay_samples=50) for a, b, k in spacecraft_axes(paper.SPACECRAFT, paper.GAIN)
    ]
    assert flown["sampled"]["exact_stable"] and flown["sampled"]["certified"]
    assert flown["sampled"]["spectral_radius"] == max(e.spectral_radius for e in exact) < 1.0
    # Beyond the exact limit nothing is certified: at tau = 1.6 s the continuous loop is unstable (margin 1.5555 s).
    assert (
        main(["verify", "--tau", "1.6", "--orders", "1", "--json", "--sampled", "100"]) == NOT_VERIFIED
    )  # checked: not stable, so exit 1
    beyond = json.loads(capsys.readouterr().out)["flown"][0]
    assert not beyond["exact_stable"] and not beyond["certified"]
    assert main(["verify", "--jitter-rate", "0.5"]) == USER_ERROR
    _one_line_error(capsys, "--jitter-rate")
    assert main(["verify", "--tau", "0.5", "--jitter", "0.6"]) == USER_ERROR
    _one_line_error(capsys, "--jitter")


def test_verify_beyond_the_margin_is_not_certified(capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(["verify", "--inertia", "140", "100", "80", "--tau", "2.0", "--orders", "1"]) == NOT_VERIFIED
    )  # checked: not stable, so exit 1
    out = capsys.readouterr().out
    assert "stable at tau = 2 s: False" in out and "NOT_CERTIFIED" in out


def test_warnings_are_one_line(capsys: pytest.CaptureFixture[str]) -> None:
    """An inertia breaking the triangle inequality warns on one line, without a file path."""
    assert main(["verify", "--inertia", "1", "1", "5", "--tau", "0"]) == 0
    err = capsys.readouterr().err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("mrpctl: warning: inertia violates")
    assert lines[0].endswith("(InertiaWarning)") and ".py" not in err


def test_sweep_eps_table_plot_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["sweep", "eps", "--values", "0.005", "0.2", "--t-final", "10", "--plot", str(tmp_path / "s.png")]
    argv += ["--csv", str(tmp_path / "s.csv")]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert captured.err == ""  # stderr is not a terminal: no progress frames
    assert "0.005" in captured.out and "0.2" in captured.out
    assert (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG"
    with (tmp_path / "s.csv").open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    assert [float(r["value"]) for r in rows] == [0.005, 0.2]
    assert int(rows[1]["switches"]) > int(rows[0]["switches"])
    assert [r["diverged"] for r in rows] == ["False", "False"]
    assert [float(rows[0][f"sigma0_{i}"]) for i in (1, 2, 3)] == paper.INITIAL_SIGMA.tolist()
    assert [float(rows[0][f"omega0_{i}_rad_s"]) for i in (1, 2, 3)] == paper.INITIAL_OMEGA.tolist()


def test_sweep_progress_on_a_terminal(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    class Terminal(io.StringIO):
        def isatty(self) -> bool:
            return True

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert main(["sweep", "tau", "--values", "0.1", "0.2", "--t-final", "1", "--chunk", "1"]) == 0
    assert "sweep tau" in terminal.getvalue() and "2/2" in terminal.getvalue()
    assert "runs converged" in capsys.readouterr().out


def test_sweep_tumble_csv_and_ranges(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = tmp_path / "t.csv"
    argv = ["sweep", "tumble", "--count", "4", "--seed", "2", "--rule", "delay-aware", "--t-final", "5"]
    argv += ["--angle-range", "120", "130", "--rate-range", "0.1", "0.2", "--cross-rate", "0", "--csv", str(table)]
    argv += ["--json"]
    assert main(argv) == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["runs"]) == 4 and data["diverged"] == 0
    with table.open(encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:
        sigma = np.array([float(row[f"sigma0_{i}"]) for i in (1, 2, 3)])
        angle = np.degrees(4 * np.arctan(np.linalg.norm(sigma)))
        assert 120.0 <= angle <= 130.0
        omega = np.array([float(row[f"omega0_{i}_rad_s"]) for i in (1, 2, 3)])
        assert np.linalg.norm(np.cross(omega, sigma)) <= 1e-12 * np.linalg.norm(sigma)  # --cross-rate 0
        assert 0.1 <= np.linalg.norm(omega) <= 0.2
        assert row["diverged"] == "False"


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["sweep", "eps", "--rule", "on-delayed"], "--rule does not apply to 'sweep eps'"),
        (["sweep", "tumble", "--values", "1", "2"], "--values does not apply to 'sweep tumble'"),
        (["sweep", "eps", "--count", "3"], "--count applies only to 'sweep tumble'"),
        (["sweep", "tau", "--values", "0.1", "--tau", "0.2"], "--tau does not apply to 'sweep tau'"),
        (["sweep", "tau", "--values", "0.1", "--seed", "3"], "--seed applies only to 'sweep tumble'"),
        (["sweep", "tau", "--scenario", "flight-paper", "--values", "0.3", "0.5"], "sweep tau with a jittering delay"),
        (["verify", str(FIG4), "--K", *["1"] * 18], "--K does not apply with a scenario file"),
        (["design", "--inertia", "1", "2", "2", "--tau", "0.1", "--rate", "100"], "--rate applies only with --toml"),
    ],
)
def test_flags_that_do_not_apply(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == USER_ERROR
    _one_line_error(capsys, message)


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
        (["verify", "--inertia", "1", "2"], "--inertia: expected 3 principal values or 9"),
        (["verify", "--K", "1", "2", "3"], "--K: expected 18 numbers"),
        (["verify", "--k-sigma", "-1", "-2"], "--k-sigma and --k-omega go together"),
        (["verify", "--k-sigma", "-1", "-2", "--k-omega", "-1"], "--k-sigma: expected 1 value or 3"),
        # issue 9: each of these was a traceback
        (["sweep", "tumble", "--seed", "-1", "--count", "2"], "seed must be >= 0, got -1"),
        (["sweep", "tumble", "--count", "1000000000000"], "choose a smaller --count"),
        (["sweep", "tumble", "--count", "2", "--t-final", "1e12"], "choose a shorter --t-final"),
        (["sweep", "tau", "--values", "0.5", "1e15"], "delays up to 1e+15 s at 1000 Hz would keep about"),
        (["sweep", "tumble", "--chunk", "0"], "--chunk must be >= 1"),
        (["simulate", str(FIG4), "--t-final", "1e12"], "choose a shorter --t-final"),
        (["simulate", str(FIG4), "--t-final", "1", "--plot", "x.jpg2000"], "unknown image format 'jpg2000'"),
        (["sweep", "eps", "--values", "0.1", "--plot", "x.jpg2000"], "unknown image format"),
        (["design", "--inertia", "140", "100", "80", "--tau", "0.5", "--zeta", "0.7"], "--allow-underdamped"),
        (["design", "--inertia", "140", "100", "80", "--tau", "nan"], "--tau must be finite"),
        (["design", "--inertia", "140", "100", "80", "--tau", "0"], "--tau must be > 0"),
    ],
)
def test_user_errors_are_one_line(argv: list[str], message: str, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(argv) == USER_ERROR
    err = _one_line_error(capsys, message)
    assert "allow_underdamped=True" not in err  # CLI wording, not API wording


def test_bad_scenario_files_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Non-UTF-8, rate = 1e300 and tau = true: one line naming the problem (issue 9)."""
    text = FIG4.read_text(encoding="utf-8")
    latin1 = tmp_path / "latin1.toml"
    latin1.write_bytes(text.replace("kg m^2", "kg m\u00b2").encode("latin-1"))
    assert main(["simulate", str(latin1)]) == USER_ERROR
    _one_line_error(capsys, "is not UTF-8 text")
    huge_rate = tmp_path / "rate.toml"
    huge_rate.write_text(text.replace("rate = 1000.0", "rate = 1e300"), encoding="utf-8")
    assert main(["simulate", str(huge_rate)]) == USER_ERROR
    _one_line_error(capsys, "choose a shorter --t-final or a lower rate")
    assert main(["export", str(huge_rate), "--out", str(tmp_path / "e"), "--no-compile"]) == USER_ERROR
    _one_line_error(capsys, "choose a lower rate")
    boolean = tmp_path / "bool.toml"
    boolean.write_text(text.replace("tau = 0.5", "tau = true"), encoding="utf-8")
    assert main(["simulate", str(boolean)]) == USER_ERROR
    _one_line_error(capsys, "tau must be a real number, got the boolean True")


def test_design_synthesizes_certified_gains(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["design", "--inertia", "140", "100", "80", "--tau", "0.5", "--order", "1"]) == 0
    out = capsys.readouterr().out
    assert "tau = 0.5 s" in out and "verified" in out and "omega_n" in out
    assert "K (3x6, N m)" in out and "axis 3: K1 = " in out and "critically damped" in out
    assert main(["design", "--inertia", "140", "100", "80", "--tau", "0.5", "--order", "1", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    k = np.array(data["K"])
    j = np.array([140.0, 100.0, 80.0])
    # Independent: K = [4 J K1, 4 J K2] with K1 = -omega_n^2, K2 = -2 zeta omega_n (zeta = 1).
    w = data["omega_n"]
    assert np.allclose(np.diag(k[:, :3]), 4 * j * -(w**2), rtol=1e-12)
    assert np.allclose(np.diag(k[:, 3:]), 4 * j * -2 * w, rtol=1e-12)
    assert np.allclose(data["K1"], [-(w**2)] * 3, rtol=1e-12) and np.allclose(data["K2"], [-2 * w] * 3, rtol=1e-12)
    assert data["synthesized"] is True and data["exact_delay_margin"] > 0.5


def test_design_full_inertia_and_underdamped(capsys: pytest.CaptureFixture[str]) -> None:
    j = np.array([[12.0, 1.0, 0.0], [1.0, 15.0, 0.5], [0.0, 0.5, 9.0]])
    argv = ["design", "--inertia", *map(str, j.ravel()), "--tau", "0.2", "--order", "1", "--zeta", "0.7"]
    assert main([*argv, "--allow-underdamped", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    w = data["omega_n"]
    k1, k2 = -(w**2) * np.eye(3), -2 * 0.7 * w * np.eye(3)
    assert np.allclose(data["K"], 4 * j @ np.hstack((k1, k2)), rtol=1e-12, atol=1e-12)
    assert np.allclose(data["zeta"], 0.7, rtol=1e-12)


def test_damping_words() -> None:
    from mrpctl.cli.design import _damping_kind

    assert _damping_kind(1.0) == _damping_kind(1.0 + 1e-12) == "critically damped"
    assert (_damping_kind(0.7), _damping_kind(1.2), _damping_kind(float("nan"))) == (
        "underdamped",
        "overdamped",
        "no restoring gain",
    )


def test_design_without_gains_is_one_line(monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """synthesize_pd finding nothing (gains None) was an AttributeError traceback (issue 9)."""
    import mrpctl.design

    def nothing(*_: object, **__: object) -> SimpleNamespace:
        return SimpleNamespace(
            status=SimpleNamespace(value="infeasible", name="INFEASIBLE"),
            synthesized=False,
            gains=None,
            certificate=None,
            margin=None,
            reason="no omega_n down to 1% of the exact bound is certified",
        )

    monkeypatch.setattr(mrpctl.design, "synthesize_pd", nothing)
    assert main(["design", "--inertia", "140", "100", "80", "--tau", "0.5"]) == USER_ERROR
    _one_line_error(capsys, "no certified gains for tau = 0.5 s", "(infeasible)", "1% of the exact bound")


@pytest.mark.slow
def test_design_verify_simulate_flow(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys) -> None:
    """Issue 14's three commands for J = diag(12, 15, 9) kg m^2, tau = 0.2 s."""
    monkeypatch.chdir(tmp_path)
    assert main(["design", "--inertia", "12", "15", "9", "--tau", "0.2", "--toml", "s.toml"]) == 0
    out = capsys.readouterr().out
    assert "scenario written to s.toml" in out
    written = load_scenario("s.toml")
    data = tomllib.loads(Path("s.toml").read_text(encoding="utf-8"))
    assert np.array(data["gains"]["K"]).shape == (3, 6)
    block = out.split("u = K x(t - tau):\n", 1)[1].split("per axis")[0]
    printed = np.array([float(v) for v in re.findall(r"-?\d+\.?\d*(?:e[-+]?\d+)?", block)]).reshape(3, 6)
    assert np.allclose(printed, written.K, rtol=1e-5, atol=1e-12)
    assert written.spacecraft.inertia.tolist() == np.diag([12.0, 15.0, 9.0]).tolist() and written.tau == 0.2
    assert main(["verify", "s.toml", "--orders", "3", "--json"]) == 0
    verdict = json.loads(capsys.readouterr().out)
    assert verdict["tau"] == 0.2 and verdict["criteria"][0]["certified"] is True
    assert verdict["exact_delay_margin"] > 0.2
    assert main(["simulate", "s.toml", "--json"]) == 0  # a diverged run is a result: exit 0
    run = json.loads(capsys.readouterr().out)
    assert run["scenario"]["K"] == written.K.tolist() and run["scenario"]["tau"] == 0.2
    code = main(["simulate", "s.toml", "--fail-on-divergence"])
    assert code == (EXIT_DIVERGED if run["result"]["diverged"] else 0)
    capsys.readouterr()
    if "certified decay rate" in out:
        # A design with a certified decay (issue 9's decay-optimal synthesize_pd) must bring the
        # paper's tumble to rest; the boundary design of today's main (margin = tau) diverges.
        assert run["result"]["converged"] is True
    assert main(["design", "--inertia", "12", "15", "9", "--tau", "0.2", "--toml", "s.toml"]) == USER_ERROR
    _one_line_error(capsys, "--toml s.toml already exists", "--overwrite")
    argv = ["design", "--inertia", "12", "15", "9", "--tau", "0.2", "--toml", "s.toml", "--overwrite", "--order", "1"]
    argv += ["--rule", "boundary-layer", "--eps", "0.01", "--t-final", "5", "--rate", "500"]
    assert main(argv) == 0
    again = load_scenario("s.toml")
    assert again.rule == BoundaryLayer(eps=0.01)
    assert (again.t_final, again.rate, again.tau) == (5.0, 500.0, 0.2)


def test_init_writes_a_runnable_starter(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "starter.toml"
    assert main(["init", str(path)]) == 0
    assert "scenario written to" in capsys.readouterr().out
    text = path.read_text(encoding="utf-8")
    assert text.count("\n#") + text.count("  #") > 10  # commented
    scenario = load_scenario(path)
    assert scenario.tau == 0.2 and scenario.spacecraft.inertia.tolist() == np.diag([12.0, 15.0, 9.0]).tolist()
    assert main(["init", str(path)]) == USER_ERROR
    _one_line_error(capsys, "already exists", "--overwrite")
    assert main(["init", str(path), "--from", "paper_fig7_boundary_layer", "--overwrite", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["source"] == "paper_fig7_boundary_layer"
    assert path.read_bytes() == shipped_scenarios()["paper_fig7_boundary_layer"].read_bytes()
    assert main(["simulate", str(path), "--t-final", "1"]) == 0


def test_reproduce_refuses_and_overwrites(
    paper_reproduction,
    blank_figures: None,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """The session's runs (conftest) go through `mrpctl reproduce`; a user's claims.md is kept without --overwrite."""
    _, computed = paper_reproduction
    calls: list[float] = []

    def shared(*, t_final: float) -> object:
        calls.append(t_final)
        return computed

    monkeypatch.setattr("mrpctl.reproduction.run_reproduction", shared)
    out = tmp_path / "results"
    assert main(["reproduce", "--out", str(out)]) == 0
    assert (out / "claims.md").exists() and (out / "fig5_on_delayed_zoom.png").read_bytes()[:4] == b"\x89PNG"
    assert "claims" in capsys.readouterr().out
    (out / "claims.md").write_text("my own claims\n", encoding="utf-8")
    assert main(["reproduce", "--out", str(out)]) == USER_ERROR
    _one_line_error(capsys, "already holds", "claims.md", "--overwrite")
    assert (out / "claims.md").read_text(encoding="utf-8") == "my own claims\n"
    assert calls == [60.0]  # refused before computing
    assert main(["reproduce", "--out", str(out), "--overwrite", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert len(data["claims"]) == len(computed.claims) and data["agreeing"] == computed.agreeing
    assert (out / "claims.md").read_text(encoding="utf-8").startswith("# Paper claims")


def test_export_writes_folder_and_refuses_to_overwrite(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "export"
    assert main(["export", str(FIG4), "--out", str(out), "--no-compile"]) == 0
    assert (out / "manifest.json").exists() and (out / "step.casadi").exists()
    assert not (out / "libmrpctl_model.so").exists()
    capsys.readouterr()
    assert main(["export", str(FIG4), "--out", str(out)]) == USER_ERROR
    assert "--overwrite" in capsys.readouterr().err
    assert main(["export", str(FIG4), "--out", str(out), "--overwrite", "--no-compile", "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["library"] is None and any(f.endswith("manifest.json") for f in data["files"])


def test_closed_pipe_ends_quietly() -> None:
    """`mrpctl example | head`: the reader goes away; no "Broken pipe", no traceback."""
    code = "import sys; from mrpctl.cli import main; sys.exit(main(['example', '--json']))"
    process = subprocess.Popen(
        [sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=Path(__file__).parent
    )
    assert process.stdout is not None and process.stderr is not None
    process.stdout.close()  # the reader is gone before mrpctl writes
    err = process.stderr.read().decode()
    assert process.wait(timeout=120) == EXIT_BROKEN_PIPE
    assert err == "", err
