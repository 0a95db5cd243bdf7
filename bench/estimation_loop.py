"""The estimated loop against PD on the delayed star tracker and the model predictor; the estimator's cost.

The paper's spacecraft, gain and initial tumble (Φ = 171.7° about x at 0.46 rad/s), a 2 Hz star tracker of
10 arcsec (1σ per axis) delivered τ = 0.5 s late, a rate-integrating gyro (σ_v = 1e-5 rad/√s, σ_u = 1e-7
rad/s^{3/2}, initial bias (5, −3, 2)·1e-4 rad/s), the controller at 10 Hz (4 RK4 substeps), the controller-side
rule Hysteretic(0). The true inertia is the nominal one, +10 % or −10 %; the gain and the predictor's model
stay nominal. Three controllers on the same sensors (``mrpctl.loop.estimated``):

* (a) PD on the delayed star tracker: the last measurement to arrive (held) and the raw gyro rate;
* (b) the model predictor: the last arrived measurement carried to now by the nominal model copy;
* (c) the MEKF loop: PD on the MEKF's estimate (delayed update by buffered re-propagation), started with
  1σ errors of 1e-3 rad and 2e-3 rad/s.

Per case, ``seeds`` sensor-noise seeds (default 10): pointing RMS (principal angle of the true attitude)
over t ∈ [150, 300] s, and the settling time (the last time the pointing error exceeds 0.01 rad), mean over
the seeds. Three more rows give the factors: (b') the predictor with the exact model (J_m = J), (d) the same
PD law on the true state at t_k (perfect knowledge: no sensor, no delay, no noise), and
(d') on the true attitude with the body's mean rate over the last period (what the noise-free gyro reads), (d'')
on the true state predicted to the middle of the torque's hold period. Then
the settling time of (b), (c) and (d) against the true inertia from −20 % to +20 %.
Then the cost of one sample (CPU time of the whole call over 30 001 samples, median of 5): the
MEKF and MRP-EKF loops' samples against the same loop's plain sample (a), and against ``simulate``'s flight loop
(Hysteretic(0) with a noisy, biased sensor at the same rate and substeps: the compiled engine's plain sample).

``python bench/estimation_loop.py [seeds]`` prints the markdown table of ``design/estimation.md``;
``python bench/estimation_loop.py figures FOLDER`` writes the estimation error of one MEKF loop run with its
±3σ envelope and the NEES of 100 runs (seeds 0..99, nominal inertia) with its 95 % χ² band, and prints the
NEES's statistics after t = 20 s.
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable

import casadi as ca
import numpy as np

from mrpctl import mrp, paper, simulate
from mrpctl.estimation import ARCSEC, Estimator, Gyro, Sensors, StarTracker, relative_rotation_expr
from mrpctl.flight import Hysteretic, SensorModel
from mrpctl.loop import InertiaInput, step_function
from mrpctl.loop.estimated import estimated_sample
from mrpctl.simulation.estimated import simulate_estimated
from mrpctl.spacecraft import Spacecraft

TRACKER = StarTracker.from_arcsec(10.0, 2.0, 0.5)
GYRO = Gyro(1e-5, 1e-7, (5e-4, -3e-4, 2e-4))
ESTIMATOR = Estimator(attitude_error=1e-3, bias_error=2e-3)
MRP_ESTIMATOR = Estimator(kind="mrp_ekf", attitude_error=1e-3, bias_error=2e-3)
RATE, SUBSTEPS, T_FINAL = 10.0, 4, 300.0
MODES = (
    ("(a) PD on the delayed star tracker", "pd", ESTIMATOR),
    ("(b) model predictor", "predictor", ESTIMATOR),
    ("(c) MEKF loop", "estimator", ESTIMATOR),
    ("(c') MRP-EKF loop", "estimator", MRP_ESTIMATOR),
)
SETTLED = 0.01


def metrics(
    mode: str, estimator: Estimator, scale: float, seed: int, *, exact_model: bool = False
) -> tuple[float, float]:
    """(pointing RMS over t >= 150 s (rad), settling time to 0.01 rad (s)) of one run; the predictor's model is
    the nominal spacecraft, or the plant itself with ``exact_model``."""
    plant = Spacecraft(np.array(paper.INERTIA) * scale)
    run = simulate_estimated(
        plant,
        paper.GAIN,
        paper.INITIAL_STATE,
        sensors=Sensors(TRACKER, GYRO, seed),
        t_final=T_FINAL,
        rate=RATE,
        estimator=estimator,
        substeps=SUBSTEPS,
        mode=mode,
        model_spacecraft=plant if exact_model else paper.SPACECRAFT,
    )
    return run.pointing_rms(150.0), run.settling_time(SETTLED)


def true_state_loop(scale: float, *, at: str = "now", gain: np.ndarray | None = None) -> tuple[float, float]:
    """The same plant, gain and rule under u_k = K [σ; ω/4] of the true state: no sensor, no delay, no noise
    (perfect knowledge). ``at``: ``"now"``, the state at t_k; ``"mean"``, the attitude at t_k and the body's mean
    rate over [t_{k-1}, t_k] (what the noise-free gyro reads, and the estimator's ω̂ = ω̃ − β̂ carries);
    ``"mid"``, the state predicted to the middle of the hold period t_k + h/2 by the nominal model under the last
    torque (a compensation of the zero-order hold's h/2). The plant is ``mrpctl.loop.step_function``'s RK4 (the
    estimated loop's); the loop runs in Python. ``gain``: the paper's by default."""
    inertia, model = np.array(paper.INERTIA) * scale, np.array(paper.INERTIA)
    step = step_function(paper.SPACECRAFT, 1 / RATE, SUBSTEPS, inertia=InertiaInput.DIAGONAL)
    half = step_function(paper.SPACECRAFT, 0.5 / RATE, SUBSTEPS // 2, inertia=InertiaInput.DIAGONAL)
    a, b = ca.SX.sym("a", 3), ca.SX.sym("b", 3)
    rotation = ca.Function("rotation", [a, b], [relative_rotation_expr(a, b)])
    gain = np.asarray(paper.GAIN if gain is None else gain)
    x = np.array(paper.INITIAL_STATE, dtype=float)
    mean, u = 4 * x[3:6], np.zeros(3)  # before t = 0 the body turned at its initial rate
    n = round(T_FINAL * RATE) + 1
    error = np.empty(n)
    for k in range(n):
        x[0:3] = mrp.short(x[0:3])  # Hysteretic(0) on the true attitude: the short set
        error[k] = 4 * np.arctan(np.linalg.norm(x[0:3]))
        if at == "mid":
            seen = np.asarray(half(x, u, model, 1 / model)).ravel()
            seen[0:3] = mrp.short(seen[0:3])
        else:
            seen = np.concatenate((x[0:3], mean / 4 if at == "mean" else x[3:6]))
        u = gain @ seen
        x_next = np.asarray(step(x, u, inertia, 1 / inertia)).ravel()
        mean = np.asarray(rotation(x[0:3], x_next[0:3])).ravel() * RATE
        x = x_next
    t = np.arange(n) / RATE
    above = np.nonzero(error > SETTLED)[0]
    return float(np.sqrt(np.mean(error[t >= 150.0] ** 2))), float(t[above[-1] + 1]) if len(above) else 0.0


def lobes(mode: str, scale: float, *, exact_model: bool = False) -> list[tuple[float, float]]:
    """(time (s), pointing error (rad)) of the local maxima above 0.003 rad after 5 s of one run (seed 0): the
    lobes of the decaying oscillation whose last one above 0.01 rad sets the settling time."""
    plant = Spacecraft(np.array(paper.INERTIA) * scale)
    run = simulate_estimated(
        plant, paper.GAIN, paper.INITIAL_STATE, sensors=Sensors(TRACKER, GYRO, 0), t_final=80.0, rate=RATE,
        estimator=ESTIMATOR, substeps=SUBSTEPS, mode=mode, model_spacecraft=plant if exact_model else paper.SPACECRAFT,
    )  # fmt: skip
    e = run.pointing_error
    peaks = [i for i in range(1, len(e) - 1) if e[i - 1] <= e[i] >= e[i + 1] and run.t[i] > 5.0 and e[i] > 0.003]
    return [(float(run.t[i]), float(e[i])) for i in peaks]


def _mean(mode: str, estimator: Estimator, scale: float, seeds: int, exact_model: bool = False) -> tuple[float, float]:
    values = np.array([metrics(mode, estimator, scale, seed, exact_model=exact_model) for seed in range(seeds)])
    return float(values[:, 0].mean()), float(values[:, 1].mean())


def _median_cpu(call: Callable[[], object]) -> float:
    call()  # build and compile once
    times = []
    for _ in range(5):
        start = time.process_time()
        call()
        times.append(time.process_time() - start)
    return statistics.median(times)


def cost(mode: str, estimator: Estimator = ESTIMATOR) -> float:
    """CPU seconds per sample of the estimated loop over 30 001 samples (the whole call)."""
    common = dict(sensors=Sensors(TRACKER, GYRO, 0), t_final=3000.0, rate=RATE, substeps=SUBSTEPS)
    return (
        _median_cpu(
            lambda: simulate_estimated(
                paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, estimator=estimator, mode=mode, **common
            )
        )
        / 30001
    )


def flight_cost() -> float:
    """CPU seconds per sample of simulate's flight loop (Hysteretic(0), a noisy biased sensor, no delay model)
    at the same rate, substeps and length: the plain sample of the compiled engine."""
    sensor = SensorModel(
        attitude_noise=10 * ARCSEC, rate_noise=GYRO.sample_noise(1 / RATE)[0], gyro_bias=GYRO.initial_bias
    )
    return (
        _median_cpu(
            lambda: simulate(
                paper.SPACECRAFT,
                paper.GAIN,
                paper.INITIAL_STATE,
                tau=0.5,
                rule=Hysteretic(),
                t_final=3000.0,
                rate=RATE,
                substeps=SUBSTEPS,
                sensor=sensor,
            )
        )
        / 30001
    )


def _inertia(scale: float) -> str:
    return "nominal" if scale == 1.0 else f"{scale - 1:+.0%}"


def main(seeds: int) -> None:
    arcsec = 180 * 3600 / np.pi
    print(f"| controller | inertia | pointing RMS, t >= 150 s (arcsec) | settling time to {SETTLED} rad (s) |")
    print("|---|---|---|---|")
    rows: list[tuple[str, Callable[[float], tuple[float, float]]]] = [
        (label, lambda scale, mode=mode, estimator=estimator: _mean(mode, estimator, scale, seeds))
        for label, mode, estimator in MODES
    ]
    rows.insert(
        2, ("(b') model predictor, exact model (J_m = J)", lambda s: _mean("predictor", ESTIMATOR, s, seeds, True))
    )
    rows.append(("(d) PD on the true state at t_k (no sensor)", true_state_loop))
    rows.append(("(d') PD on the true attitude and mean rate", lambda s: true_state_loop(s, at="mean")))
    rows.append(("(d'') PD on the true state predicted to t_k + h/2", lambda s: true_state_loop(s, at="mid")))
    for label, measure in rows:
        for scale in (1.0, 1.1, 0.9):
            rms, settling = measure(scale)
            print(f"| {label} | {_inertia(scale)} | {rms * arcsec:.1f} | {settling:.1f} |")
    print()
    scan_seeds = min(seeds, 3)
    print(f"settling time to {SETTLED} rad (s) against the true inertia ({scan_seeds} seeds; the model nominal):")
    print("| inertia | (b) model predictor | (c) MEKF loop | (d) PD on the true state |")
    print("|---|---|---|---|")
    for scale in (0.8, 0.85, 0.9, 0.95, 1.0, 1.05, 1.1, 1.15, 1.2):
        cells = [_mean(mode, ESTIMATOR, scale, scan_seeds)[1] for mode in ("predictor", "estimator")]
        cells.append(true_state_loop(scale)[1])
        print(f"| {_inertia(scale)} | " + " | ".join(f"{c:.1f}" for c in cells) + " |")
    print()
    print("the lobes of the pointing error at -10 % (seed 0; time s, peak rad):")
    for label, mode, exact in (("(b)", "predictor", False), ("(b')", "predictor", True), ("(c)", "estimator", False)):
        print(f"  {label} " + ", ".join(f"{t:.1f} s {e:.4f}" for t, e in lobes(mode, 0.9, exact_model=exact)))
    lean = Estimator(attitude_error=1e-3, bias_error=2e-3, covariance_now=False)
    plain, flight = cost("pd"), flight_cost()
    print()
    print(
        f"cost per sample (CPU, whole call over 30 001 samples): the estimated loop's plain sample (a) "
        f"{plain * 1e6:.2f} us"
    )
    print(f"simulate's flight loop (the compiled engine's plain sample): {flight * 1e6:.2f} us")
    functions = ESTIMATOR.functions(TRACKER, GYRO, RATE)
    plain_size = estimated_sample(paper.SPACECRAFT, functions, SUBSTEPS, "pd")[0].n_instructions()
    for label, estimator in (("MEKF", ESTIMATOR), ("MEKF, covariance at t_m", lean), ("MRP-EKF", MRP_ESTIMATOR)):
        seconds = cost("estimator", estimator)
        size = estimated_sample(paper.SPACECRAFT, estimator.functions(TRACKER, GYRO, RATE), SUBSTEPS, "estimator")[
            0
        ].n_instructions()
        print(
            f"{label} loop: {seconds * 1e6:.2f} us ({seconds / plain:.2f}x (a), {seconds / flight:.2f}x the engine's); "
            f"{size} SX instructions against {plain_size} ({size / plain_size:.2f}x)"
        )


def figures(folder: str) -> None:
    from pathlib import Path

    from scipy.stats import chi2

    from mrpctl.plots import plot_estimation_error, plot_nees, save_figure

    runs = []
    for seed in range(100):
        runs.append(
            simulate_estimated(
                paper.SPACECRAFT,
                paper.GAIN,
                paper.INITIAL_STATE,
                sensors=Sensors(TRACKER, GYRO, seed),
                t_final=T_FINAL,
                rate=RATE,
                estimator=ESTIMATOR,
                substeps=SUBSTEPS,
            )
        )
    first = runs[0]
    sigma = np.sqrt(np.diagonal(first.covariance, axis1=1, axis2=2)[:, :3])
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    figure = plot_estimation_error(first.t, first.estimation_error, sigma, title="MEKF loop, tau = 0.5 s, 2 Hz tracker")
    save_figure(figure, out / "estimation_error.png")
    nees = []
    for run in runs:
        e = np.concatenate((run.estimation_error, run.bias - run.bias_hat), axis=1)
        nees.append(np.einsum("ki,ki->k", e, np.linalg.solve(run.covariance, e[:, :, None])[:, :, 0]))
    nees_array = np.array(nees)
    save_figure(plot_nees(first.t, nees_array, dimension=6, title="MEKF loop, 100 runs"), out / "nees.png")
    after = first.t >= 20.0
    average = nees_array[:, after].mean(axis=0)
    low, high = chi2.ppf([0.025, 0.975], 600) / 100
    inside = np.mean((average >= low) & (average <= high))
    print(f"closed-loop NEES after 20 s: inside the 95% band on {inside:.1%}, grand mean {average.mean():.3f}")


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "figures":
        figures(sys.argv[2])
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
