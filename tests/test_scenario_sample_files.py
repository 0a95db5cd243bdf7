"""Per-sample files of the loop as flown (issue 10): ``[disturbance] torque_file``, ``[delay] sequence_file``,
and ``mrpctl simulate/export --disturbance-file F --delay-file F``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrpctl import paper, simulate
from mrpctl.cli import USER_ERROR, main
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import DelayKind, DelayModel, Disturbance, Hysteretic, newest_arrived
from mrpctl.scenario import load_scenario, shipped_scenarios

RATE, T_FINAL, TAU = 100.0, 3.0, 0.1
N = 301
ROWS = np.column_stack((0.5 * np.sin(np.arange(N) / 7.0), np.linspace(-0.3, 0.3, N), np.full(N, 0.1)))
DELAYS = (1 + (np.arange(N) * 7) % 10) / RATE  # 0.01 .. 0.10 s, whole periods

SCENARIO = f"""
tau = {TAU}
rate = {RATE}
t_final = {T_FINAL}
[spacecraft]
inertia = [140.0, 100.0, 80.0]
[gains]
k_sigma = -7.011
k_omega = -16.308
[initial]
sigma = [0.6, -0.2, 0.1]
omega = [0.3, 0.1, 0.0]
[rule]
type = "hysteretic"
delta = 0.05
"""


def _write(folder: Path, extra: str) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "s.toml"
    path.write_text(SCENARIO + extra, encoding="utf-8")
    return path


def _expected(**options: Any) -> Any:
    return simulate(
        paper.SPACECRAFT,
        np.hstack((-7.011 * np.eye(3), -16.308 * np.eye(3))),
        np.array([0.6, -0.2, 0.1, 0.075, 0.025, 0.0]),
        tau=TAU,
        rate=RATE,
        t_final=T_FINAL,
        rule=Hysteretic(0.05),
        **options,
    )


def _csv(path: Path, array: np.ndarray) -> Path:
    np.savetxt(path, array, delimiter=",", fmt="%.17g", header="written by the test")
    return path


@pytest.mark.parametrize("suffix", [".csv", ".npy"])
def test_scenario_files_give_the_per_sample_torque_and_delays(tmp_path: Path, suffix: str) -> None:
    data = tmp_path / "data"
    data.mkdir()
    if suffix == ".npy":
        np.save(data / "w.npy", ROWS)
        np.save(data / "d.npy", DELAYS)
    else:
        _csv(data / "w.csv", ROWS)
        _csv(data / "d.csv", DELAYS)
    # relative to the scenario file, not to the working directory
    path = _write(
        tmp_path / "case",
        f'[disturbance]\ntorque_file = "../data/w{suffix}"\n[delay]\nsequence_file = "../data/d{suffix}"\n',
    )
    scenario = load_scenario(path)
    assert scenario.disturbance is not None and scenario.delay is not None
    assert scenario.disturbance.torque.tobytes() == ROWS.tobytes()
    assert scenario.delay.kind is DelayKind.SEQUENCE and scenario.delay.delays is not None
    assert scenario.delay.delays.tobytes() == DELAYS.tobytes()
    assert (scenario.delay.tau_min, scenario.delay.tau_max) == (1.0 / RATE, TAU)
    run = scenario.simulate()
    expected = _expected(
        disturbance=Disturbance(ROWS), delay=DelayModel.sequence(DELAYS, tau_min=1.0 / RATE, tau_max=TAU)
    )
    assert run.sigma.tobytes() == expected.sigma.tobytes() and run.u.tobytes() == expected.u.tobytes()
    _, used_delay = newest_arrived(np.rint(DELAYS * RATE).astype(np.int64), history=10)
    assert run.delay_used is not None and run.delay_used.tolist() == used_delay.tolist()
    assert len(set(run.delay_used.tolist())) >= 5  # the delay used varies


@pytest.mark.parametrize(
    ("extra", "files", "error", "pattern"),
    [
        (
            '[disturbance]\ntorque_file = "missing.csv"\n',
            {},
            SpecificationError,
            r"\[disturbance\] torque_file: no file .*missing\.csv",
        ),
        (
            '[disturbance]\ntorque_file = "w.csv"\n',
            {"w.csv": ROWS[:-1]},
            DimensionError,
            r"\[disturbance\] torque_file: expected n rows of 3 .*\(301, 3\).*\(300, 3\)",
        ),
        (
            '[disturbance]\ntorque_file = "w.csv"\n',
            {"w.csv": ROWS[:, :2]},
            DimensionError,
            r"\[disturbance\] torque_file: .*\(301, 2\)",
        ),
        (
            '[disturbance]\ntorque_file = "w.json"\n',
            {"w.json": ROWS},
            SpecificationError,
            r"\[disturbance\] torque_file: .* must be a \.npy or a \.csv",
        ),
        ("[disturbance]\ntorque_file = 3\n", {}, SpecificationError, r"\[disturbance\] torque_file must be a file"),
        (
            '[disturbance]\ntorque = [0.0, 0.0, 0.0]\ntorque_file = "w.csv"\n',
            {"w.csv": ROWS},
            SpecificationError,
            r"\[disturbance\] needs torque .* or torque_file .*one of them",
        ),
        (
            '[disturbance]\ntorque_file = "w.csv"\n',
            {"w.csv": np.where(ROWS > 0.4, np.nan, ROWS)},
            SpecificationError,
            r"\[disturbance\] torque_file .* must be finite",
        ),
        (
            '[delay]\nsequence_file = "d.csv"\n',
            {"d.csv": DELAYS[:-2]},
            DimensionError,
            r"\[delay\] sequence_file: expected n delays .*= 301",
        ),
        (
            '[delay]\nsequence_file = "d.csv"\n',
            {"d.csv": DELAYS + 0.05},
            SpecificationError,
            r"\[delay\] delays must lie in \[tau_min, tau_max\]",
        ),
        (
            '[delay]\nsequence_file = "d.csv"\n',
            {"d.csv": np.where(np.arange(N) == 5, 0.0504, DELAYS)},
            SpecificationError,
            r"\[delay\] sequence_file: .*whole number",
        ),
        (
            '[delay]\nsequence_file = "d.csv"\nseed = 2\n',
            {"d.csv": DELAYS},
            SpecificationError,
            r"\[delay\] seed applies to the jitter",
        ),
        (
            '[delay]\nsequence_file = "d.csv"\ntau_min = 0.0\n',
            {"d.csv": DELAYS},
            SpecificationError,
            r"\[delay\] tau_min must be >= 1/rate",
        ),
    ],
)
def test_bad_sample_files_are_refused_naming_the_key(
    tmp_path: Path, extra: str, files: dict[str, np.ndarray], error: type, pattern: str
) -> None:
    for name, array in files.items():
        _csv(tmp_path / name, array)
    with pytest.raises(error, match=pattern):
        load_scenario(_write(tmp_path, extra))


def test_the_shipped_scenarios_have_no_sample_files() -> None:
    for path in shipped_scenarios().values():
        text = path.read_text(encoding="utf-8")
        assert "torque_file" not in text and "sequence_file" not in text


def test_cli_simulate_takes_the_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    np.save(tmp_path / "w.npy", ROWS)
    _csv(tmp_path / "d.csv", DELAYS)
    scenario = _write(tmp_path, "")
    argv = ["simulate", str(scenario), "--disturbance-file", str(tmp_path / "w.npy")]
    argv += ["--delay-file", str(tmp_path / "d.csv"), "--json"]
    assert main(argv) == 0
    result = json.loads(capsys.readouterr().out)["result"]
    expected = _expected(
        disturbance=Disturbance(ROWS), delay=DelayModel.sequence(DELAYS, tau_min=1.0 / RATE, tau_max=TAU)
    )
    assert result["final_sigma"] == expected.sigma[-1].tolist() and result["switch_count"] == expected.switch_count


def test_cli_export_names_the_torque_input(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _csv(tmp_path / "w.csv", ROWS)
    out = tmp_path / "out"
    argv = ["export", str(_write(tmp_path, "")), "--out", str(out), "--no-compile"]
    assert main([*argv, "--disturbance-file", str(tmp_path / "w.csv"), "--json"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["flight"]["disturbance"]["input"] == "torque" and manifest["flight"]["disturbance"]["samples"] == N
    assert [port["name"] for port in manifest["functions"]["chunk"]["inputs"]][-1] == "torque"


@pytest.mark.parametrize(
    ("options", "needles"),
    [
        (["--disturbance-file", "nowhere.csv"], ("--disturbance-file", "no file", "nowhere.csv")),
        (["--disturbance-file", "{w}", "--disturbance", "0", "0", "0"], ("--disturbance", "--disturbance-file")),
        (["--disturbance-file", "{short}"], ("--disturbance-file", "(301, 3)", "(300, 3)")),
        (["--delay-file", "{d}", "--jitter", "0.05", "0.1"], ("--jitter", "--delay-file")),
        (["--delay-file", "{w}"], ("--delay-file", "expected n delays")),
    ],
)
def test_bad_cli_files_exit_2_with_one_line(
    tmp_path: Path, options: list[str], needles: tuple[str, ...], capsys: pytest.CaptureFixture[str]
) -> None:
    files = {"w": _csv(tmp_path / "w.csv", ROWS), "d": _csv(tmp_path / "d.csv", DELAYS)}
    files["short"] = _csv(tmp_path / "short.csv", ROWS[:-1])
    argv = ["simulate", str(_write(tmp_path, "")), *[o.format(**files) for o in options]]
    assert main(argv) == USER_ERROR
    err = capsys.readouterr().err
    assert err.startswith("mrpctl: error:") and err.count("\n") == 1, err
    for needle in needles:
        assert needle in err, err
