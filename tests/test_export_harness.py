"""examples/export_harness.c on every kind of export, built with -Wall -Wextra -Werror, against simulate.

The harness is compiled with ``-Wall -Wextra -Werror``; the exported ``mrpctl_model.c`` with the same
flags and ``-Wno-unused-parameter`` only: every function CasADi generates takes the work arrays ``iw``,
``w`` and the memory index ``mem`` whether it uses them or not (CasADi's code, not mrpctl's).
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrpctl import OnPredicted, Predictor, paper, simulate
from mrpctl._compile import find_compiler
from mrpctl._export import SOURCE_NAME, export
from mrpctl.design import pd_gains
from mrpctl.flight import ActuatorModel, Disturbance, Hysteretic, SensorModel
from mrpctl.loop import closed_loop_functions
from mrpctl.loop.options import predictor_memory
from mrpctl.predictor import perturbed_spacecraft
from mrpctl.switching import OnDelayed

COMPILER = find_compiler()
pytestmark = pytest.mark.skipif(COMPILER is None, reason="no C compiler on this machine")
HARNESS = Path(__file__).resolve().parents[1] / "examples" / "export_harness.c"
STRICT = ["-O2", "-Wall", "-Wextra", "-Werror"]
CASADI_CODE = [*STRICT, "-Wno-unused-parameter"]  # CasADi's generated signatures: iw, w, mem unused

SC = paper.SPACECRAFT
CASES: dict[str, tuple[Any, Any, np.ndarray, float, dict[str, Any]]] = {
    # the paper's rule-based loop: OnDelayed switches from t = 0.944 s, inside the first second
    "plain": (SC, paper.GAIN, np.asarray(paper.INITIAL_STATE), 1.0, dict(tau=paper.TAU, rate=1000.0, rule=OnDelayed())),
    # the flown loop with hysteresis, a torque limit that acts, a constant disturbance and a gyro bias
    "flight": (
        SC,
        paper.GAIN,
        np.asarray(paper.INITIAL_STATE),
        1.5,  # one set change of the controller, the torque limit acting on 96 % of the samples
        dict(
            tau=paper.TAU,
            rate=1000.0,
            rule=Hysteretic(0.02),
            actuator=ActuatorModel(u_max=[60.0, 50.0, 40.0], norm_max=70.0),
            disturbance=Disturbance([1e-3, -2e-3, 5e-4]),
            sensor=SensorModel(gyro_bias=[1e-4, 0.0, -2e-4]),
        ),
    ),
    # the predictor with a 10 % inertia error, a torque limit and a disturbance
    "predictor": (
        perturbed_spacecraft(SC, 0.1),
        pd_gains(SC, zeta=1.0, omega_n=1.0).K,
        np.array([0.3, -0.5, 0.2, 1.0, -0.5, 0.75]),
        2.0,
        dict(
            tau=0.2,
            rate=100.0,
            rule=OnPredicted(1.0),
            predictor=Predictor(model=SC),
            actuator=ActuatorModel(u_max=[60.0, 50.0, 40.0]),
            disturbance=[0.2, -0.1, 0.05],
        ),
    ),
}


def _memory0(kind: str, spacecraft: Any, gain: Any, x0: np.ndarray, options: dict[str, Any], d: int) -> list[float]:
    if kind == "plain":
        return [float(options["rule"].initial_memory(delay_samples=d))]
    if kind == "flight":
        return closed_loop_functions(spacecraft, gain, **options).flight.initial_memory(x0, d).tolist()
    return predictor_memory(x0).tolist()


def _build(folder: Path, tmp_path: Path) -> Path:
    harness, model, binary = tmp_path / "harness.o", tmp_path / "model.o", tmp_path / "harness"
    for flags, source, target in ((STRICT, HARNESS, harness), (CASADI_CODE, folder / SOURCE_NAME, model)):
        done = subprocess.run(
            [COMPILER, *flags, "-c", "-I", str(folder), str(source), "-o", str(target)],
            capture_output=True,
            text=True,
            check=False,
        )
        assert done.returncode == 0, done.stderr  # a warning is an error here
    subprocess.run([COMPILER, str(harness), str(model), "-lm", "-o", str(binary)], check=True)
    return binary


@pytest.mark.parametrize("kind", list(CASES))
def test_harness_compiles_strictly_and_matches_simulate(kind: str, tmp_path: Path) -> None:
    spacecraft, gain, x0, t_final, options = CASES[kind]
    folder = export(spacecraft, gain, tmp_path / "export", **options).folder
    binary = _build(folder, tmp_path)
    d, n = round(options["tau"] * options["rate"]), round(t_final * options["rate"])
    arguments = [str(d), str(n), *(repr(float(v)) for v in x0)]
    arguments += [repr(v) for v in _memory0(kind, spacecraft, gain, x0, options, d)]
    run = subprocess.run([str(binary), *arguments], capture_output=True, text=True, check=True, timeout=60)
    final = np.array([float(value) for value in run.stdout.split()])

    reference = simulate(spacecraft, gain, x0, t_final=t_final, **options)
    assert reference.switch_count > 0 and len(reference.t) == n + 1  # the switching logic did act
    expected = np.concatenate((reference.sigma[n], reference.omega[n] / 4.0))
    assert final.shape == (6,) and np.max(np.abs(final - expected)) <= 1e-12


def test_harness_refuses_a_wrong_argument_count(tmp_path: Path) -> None:
    spacecraft, gain, _, _, options = CASES["plain"]
    binary = _build(export(spacecraft, gain, tmp_path / "export", **options).folder, tmp_path)
    run = subprocess.run([str(binary), "500", "10", "0.1"], capture_output=True, text=True, check=False)
    assert run.returncode == 2 and "usage" in run.stderr and "memory0[0..0]" in run.stderr
