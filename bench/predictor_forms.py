"""Accuracy of the two predictor forms (`PredictorForm`) on the compiled engine: the table of ``design/predictor.md``.

Cases: the paper's spacecraft J = diag(140, 100, 80) kg m² as the controller's model, the plant (1 + e) J for
e = 0, +10 %, −10 %; τ = 0.5 s, 20 s, `OnPredicted(1)`, ζ = 1 gains ωₙ = 3 and 12.85 rad/s, at 100 Hz and 1 kHz;
two initial states: the paper's (0.93, 0, 0), 0.46 rad/s about x (every rotation of the loop is about that
principal axis, so they commute and there is no gyroscopic torque) and a skew one (150° about (1, 2, 3)/√14,
ω0 = (0.3, −0.2, 0.25) rad/s). Printed per run and form: the prediction error, the angle between the predicted
attitude σ̂_k the law used and the true σ_k for t > τ (scipy `Rotation`; max over the run, max over its last
second), the rate error max |ω̂ − ω| (rad/s), the settling time (|σ| < 1e-2 and |ω| < 1e-3 rad/s from then on),
the switches and the final |σ|. Then the 48 dispersed cases of ``bench/predictor_lanes.py`` (full-inertia plants
J_ii ± 15 %, products ± 2 kg m², fast gains, 1 kHz): how many settle within 20 s, their median settling time, and
how many still turn faster than 1 rad/s at the end.

Run: ``.venv/bin/python bench/predictor_forms.py [--quick]`` (``--quick``: 100 Hz only, no dispersed cases).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from mrpctl import OnPredicted, Predictor, PredictorForm, paper, simulate, simulate_batch
from mrpctl.design import pd_gains
from mrpctl.spacecraft import Spacecraft

sys.path.insert(0, str(Path(__file__).parent))
from predictor_lanes import NOMINAL, cases

TAU, T_FINAL = 0.5, 20.0
_AXIS = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
STATES = {
    "paper": np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0]),
    "skew": np.concatenate((_AXIS * np.tan(np.radians(150.0) / 4), np.array([0.3, -0.2, 0.25]) / 4)),
}


def prediction_errors(run, rate: float) -> tuple[float, float, float]:
    """(max angle, max angle over the last second, max rate error) between the prediction and the truth, t > τ."""
    after = run.t > TAU + 0.5 / rate
    truth = Rotation.from_mrp(run.sigma[after])
    predicted = Rotation.from_mrp(run.sigma_predicted[after])
    angles = (predicted * truth.inv()).magnitude()
    rate_error = np.linalg.norm(run.omega_predicted[after] - run.omega[after], axis=1)
    last = run.t[after] > T_FINAL - 1.0
    return float(angles.max()), float(angles[last].max()), float(rate_error.max())


def table(rates: tuple[float, ...]) -> None:
    model = paper.SPACECRAFT
    print(
        f"{'x0':>5s} {'rate':>5s} {'wn':>6s} {'e':>5s} {'form':>9s} {'err max':>9s} {'err end':>9s} "
        f"{'rate err':>9s} {'settling':>9s} {'sw':>3s} {'final |s|':>10s}"
    )
    for name, x0 in STATES.items():
        for rate in rates:
            for omega_n in (3.0, 12.85):
                gain = pd_gains(model, zeta=1.0, omega_n=omega_n).K
                for e in (0.0, 0.1, -0.1):
                    plant = Spacecraft(model.inertia * (1.0 + e))
                    for form in PredictorForm:
                        run = simulate(
                            plant, gain, x0, tau=TAU, rule=OnPredicted(1.0), t_final=T_FINAL, rate=rate,
                            predictor=Predictor(model, form=form),
                        )  # fmt: skip
                        worst, end, rate_error = prediction_errors(run, rate)
                        settling = "-" if run.settling_time is None else f"{run.settling_time:.3f}"
                        final = float(np.linalg.norm(run.sigma[-1]))
                        print(
                            f"{name:>5s} {rate:5.0f} {omega_n:6.2f} {e:+5.0%} {form.value:>9s} {worst:9.2e} "
                            f"{end:9.2e} {rate_error:9.2e} {settling:>9s} {run.switch_count:3d} {final:10.2e}",
                            flush=True,
                        )


def dispersed() -> None:
    case = cases(48)
    rules = [OnPredicted(1.0 if i % 2 == 0 else 1.2) for i in range(48)]
    print("48 dispersed cases (bench/predictor_lanes.py), 1 kHz, 20 s:")
    for form in PredictorForm:
        batch = simulate_batch(**case, rule=rules, predictor=Predictor(NOMINAL, form=form), trajectories=True)
        assert batch.runs is not None
        settled = np.isfinite(batch.settling_time)
        fast = sum(float(np.linalg.norm(run.omega[-1])) > 1.0 for run in batch.runs)
        unsettled = [
            float(np.linalg.norm(run.sigma[-1])) for run, ok in zip(batch.runs, settled, strict=True) if not ok
        ]
        rest = f"; the others' final |sigma| median {np.median(unsettled):.2g}" if unsettled else ""
        print(
            f"  {form.value:9s}: settled {int(settled.sum())}/48, median settling "
            f"{np.median(batch.settling_time[settled]):.3f} s, |omega| > 1 rad/s at the end: {fast}{rest}"
        )


def main() -> None:
    quick = "--quick" in sys.argv[1:]
    table((100.0,) if quick else (100.0, 1000.0))
    if not quick:
        dispersed()


if __name__ == "__main__":
    main()
