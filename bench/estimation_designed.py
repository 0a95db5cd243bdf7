"""The estimated loop's comparison with each loop's own designed gain, beside the same-gain comparison.

``bench/estimation_loop.py`` flies the paper's gain K = [−70.11 I, −163.08 I] in all three loops. Here each
loop flies the gain that mrpctl's design procedure gives for the delay its own control law sees. The rule,
fixed before anything was measured, and applied alike to the three loops:

* **The design.** ``synthesize_pd(paper.SPACECRAFT, tau_d, zeta=1.0, tolerance=0.1, period=h)`` (``mrpctl design
  --inertia 140 100 80 --tau tau_d --inertia-tolerance 0.1 --sampled 10 --order 3``): the decay-optimal critically
  damped delayed PD (ωₙ τ_d = 0.444854), kept when the polytope certificate of the sampled loop (zero-order hold
  at h = 0.1 s, the sawtooth delay τ(t) ∈ [τ_d, τ_d + h]) holds over every inertia within ±10 % per axis, else
  the largest ωₙ below it that is certified; then checked by the exact lifted spectral radius at the box ends.
* **The design delay** τ_d of a loop: the age, at the controller sample where it arrives, of the oldest signal
  its law acts on, in whole controller samples (rounded up: the sampled design needs τ_d/h whole). The torque's
  hold is the sawtooth's [0, h] on top.

  - (a) PD on the delayed star tracker: the attitude is the tracker's, τ = 0.5 s old when it arrives (the rate is
    the gyro's mean rate, h/2 old). τ_d = 0.5 s. The 2 Hz tracker's hold between arrivals (0.1 to 0.4 s more) is
    not in the design model; the exact check of the loop as flown below covers it.
  - (b) the model predictor: it carries the arrived measurement over its age to t_k with the nominal model, so
    with the nominal inertia its law acts on the attitude at t_k and the gyro's mean rate of the measurement's
    time carried to t_k: h/2 old. τ_d = h = 0.1 s. The model error is not a delay: it is the certificate's
    business (mrpctl's predictor certificate at ±10 %).
  - (c) the MEKF loop: σ̂ is the estimate at t_k, ω̂ = ω̃ − β̂ the mean rate over the last period, h/2 old.
    τ_d = h = 0.1 s, the same design input as (b).

* **The certificates**, for the loop each gain flies, at the true inertia (1 + e) J per axis, e within ±10 %:
  the design's own (the polytope certificate of the sampled PD loop at τ_d, and the exact lifted radius);
  for (b) mrpctl's predictor certificate (``predictor_stability``, sampled at 10 Hz: the exact lifted test of the
  predictor loop with the nominal model against the perturbed plant) at each age the held measurement has
  (τ = 0.5 … 0.9 s); no mrpctl certificate covers the estimator loop (the filter's linearised loop is not
  analysed in mrpctl). For all three, the exact spectral radius of the linearised loop *as flown* (below,
  ``flown_radius``: the 2 Hz tracker's hold, the gyro's mean rate, the predictor's varying age; the MEKF loop
  by separation, see there) at e = −10 %, −5 %, 0, +5 %, +10 % per axis.
* **If a certificate fails** the gain is still flown and the failure reported (no back-off is added after the
  fact).

Then the table of ``bench/estimation_loop.py`` (the same plant, sensors, gyro bias, initial tumble, 300 s, 10 Hz,
pointing RMS over t ∈ [150, 300] s, the last time above 0.01 rad) for both gain choices, with the peak torque
(there is no actuator limit in the estimated loop, and the paper states none).

``python bench/estimation_designed.py [seeds]`` (default 10).
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from estimation_loop import (
    ESTIMATOR,
    GYRO,
    RATE,
    SETTLED,
    SUBSTEPS,
    T_FINAL,
    TRACKER,
    true_state_loop,
)

from mrpctl import paper
from mrpctl.design import synthesize_pd
from mrpctl.estimation import Sensors
from mrpctl.predictor import perturbed_spacecraft, predictor_stability
from mrpctl.simulation.estimated import simulate_estimated
from mrpctl.spacecraft import Spacecraft

H = 1.0 / RATE
TRACKER_PERIOD = round(RATE / TRACKER.rate)  # controller samples between tracker measurements (5)
LATENCY = round(TRACKER.latency * RATE)  # the tracker's latency in controller samples (5)
TOLERANCE = 0.1
ERRORS = (-0.10, -0.05, 0.0, 0.05, 0.10)
ARCSEC = 180 * 3600 / np.pi

#: (label, mode, design delay τ_d (s)) of the three loops, by the rule of the module's docstring.
LOOPS = (
    ("(a) PD on the delayed star tracker", "pd", LATENCY * H),
    ("(b) model predictor", "predictor", H),
    ("(c) MEKF loop", "estimator", H),
)


# ------------------------------------------------------------------------------------------------------------
# The linearised loop as flown, per axis (exact ZOH discretisation), and its spectral radius.
#
# Per axis σ̇ = ω/4, J ω̇ = u, u held over [t_k, t_k + h]: σ_{k+1} = σ_k + h ω_k/4 + h² u_k/(8J), ω_{k+1} = ω_k
# + h u_k/J. The gyro's mean rate over [t_{k−1}, t_k] is 4 (σ_k − σ_{k−1})/h = (ω_{k−1} + ω_k)/2. The tracker
# measures at the samples ≡ 0 (mod n) and its measurement arrives ℓ samples later, held until the next one:
# at the sample of phase q = 0 … n−1 after an arrival the held attitude is σ_{k−a}, a = ℓ + q. Laws, u_k:
#   "pd"        k_σ σ_{k−a} + k_ω ω̄_k/4                                       (a)
#   "predictor" k_σ σ̂ + k_ω ω̂/4, (σ̂, ω̂) = Φᵃ (σ_{k−a}, ω̄_{k−a}) + Σ_{i=k−a}^{k−1} Φ^{k−1−i} Γ_m u_i   (b)
#               (the linearisation of ``prediction_expr``: the model copy enters through z_k − Φᵃ z_{k−a},
#               which is that sum over the nominal model's Γ_m)
#   "now"       k_σ σ_k + k_ω ω̄_k/4                                            (c), by separation
#   "delayed"   k_σ σ_{k−a} + k_ω ω_{k−a}/4 (n = 1, point rate): mrpctl's sampled PD model, as a cross-check
# The MEKF loop: the filter runs on the gyro, not on a model, so its linearised error (δθ, Δβ) obeys its own
# recursion, driven by the sensor noise and not by u (the gyro reads the motion u produced). The loop is then
# block-triangular: the law on the true σ_k and ω̄_k ("now"), plus the filter's error dynamics, stable on their
# own (the filter's consistency, design/estimation.md). Its radius is the larger of the two; only "now" depends
# on the gain.
# The state is the history s_k = (σ_k … σ_{k−M}, ω_k … ω_{k−M}, u_{k−1} … u_{k−M}); the loop is periodic over
# n samples, so the radius per sample is ρ(M_{n−1} ⋯ M_0)^{1/n}.
# ------------------------------------------------------------------------------------------------------------


def flown_radius(
    law: str,
    k_sigma: float,
    k_omega: float,
    inertia: float,
    model_inertia: float,
    *,
    period: int = TRACKER_PERIOD,
    latency: int = LATENCY,
    mean_rate: bool = True,
) -> float:
    """Spectral radius per sample of one axis of the linearised loop as flown (see the comment above)."""
    m = latency + period + 1
    size = 3 * m + 2  # σ_0..σ_m, ω_0..ω_m, u_1..u_m  (index i: value at k − i)
    sig = lambda i: i  # noqa: E731
    om = lambda i: m + 1 + i  # noqa: E731
    uu = lambda i: 2 * m + 1 + i  # noqa: E731  (i >= 1)

    def rate(i: int) -> np.ndarray:
        row = np.zeros(size)
        if mean_rate:
            row[om(i)] += 0.5
            row[om(i + 1)] += 0.5
        else:
            row[om(i)] = 1.0
        return row

    monodromy = np.eye(size)
    for q in range(period):
        a = latency + q
        c = np.zeros(size)  # u_k = c · s_k
        if law == "now":
            c[sig(0)] = k_sigma
            c += k_omega / 4 * rate(0)
        elif law == "pd":
            c[sig(a)] = k_sigma
            c += k_omega / 4 * rate(0)
        elif law == "delayed":
            c[sig(a)] = k_sigma
            c += k_omega / 4 * rate(a)
        elif law == "predictor":
            s_hat = np.zeros(size)
            s_hat[sig(a)] = 1.0
            s_hat += a * H / 4 * rate(a)
            w_hat = rate(a).copy()
            for i in range(1, a + 1):  # u_{k−i}, i = 1..a: Φ^{i−1} Γ_m
                s_hat[uu(i)] += H * H / (8 * model_inertia) + (i - 1) * H * H / (4 * model_inertia)
                w_hat[uu(i)] += H / model_inertia
            c = k_sigma * s_hat + k_omega / 4 * w_hat
        else:
            raise ValueError(law)
        step = np.zeros((size, size))
        # the plant
        step[sig(0), sig(0)] = 1.0
        step[sig(0), om(0)] = H / 4
        step[sig(0)] += H * H / (8 * inertia) * c
        step[om(0), om(0)] = 1.0
        step[om(0)] += H / inertia * c
        # the histories shift by one
        for i in range(1, m + 1):
            step[sig(i), sig(i - 1)] = 1.0
            step[om(i), om(i - 1)] = 1.0
        step[uu(1)] = c
        for i in range(2, m + 1):
            step[uu(i), uu(i - 1)] = 1.0
        monodromy = step @ monodromy
    return float(np.max(np.abs(np.linalg.eigvals(monodromy))) ** (1.0 / period))


def axis_gains(K: np.ndarray) -> list[tuple[float, float]]:
    """(k_σ, k_ω) per axis of a diagonal-block gain on x = [σ; ω/4]."""
    return [(float(K[i, i]), float(K[i, 3 + i])) for i in range(3)]


def worst_flown(law: str, K: np.ndarray, errors: tuple[float, ...] = ERRORS) -> dict[float, float]:
    """Largest per-sample radius over the axes at each uniform relative inertia error e (the axes split, so a
    uniform e covers each axis' own error of the same size)."""
    return {
        e: max(
            flown_radius(law, ks, kw, (1 + e) * j, j) for (ks, kw), j in zip(axis_gains(K), paper.INERTIA, strict=True)
        )
        for e in errors
    }


def cross_checks(K: np.ndarray) -> list[str]:
    """The as-flown model against mrpctl's own exact tests where both describe the same loop."""
    lines = []
    for e in (-TOLERANCE, 0.0, TOLERANCE):
        plant = perturbed_spacecraft(paper.SPACECRAFT, e)
        for d in (1, 5):
            theirs = predictor_stability(paper.SPACECRAFT, K, d * H, plant=plant, rate=RATE, radius=True)
            mine = max(
                flown_radius("predictor", ks, kw, (1 + e) * j, j, period=1, latency=d, mean_rate=False)
                for (ks, kw), j in zip(axis_gains(K), paper.INERTIA, strict=True)
            )
            assert abs(theirs.spectral_radius - mine) < 1e-4, (d, e, theirs.spectral_radius, mine)
            lines.append(
                f"  predictor, measurement every sample, point rate, d = {d}, e = {e:+.0%}: "
                f"predictor_stability radius {theirs.spectral_radius:.6f}, flown_radius {mine:.6f}"
            )
    for e in (-TOLERANCE, 0.0, TOLERANCE):
        mine = max(
            flown_radius("delayed", ks, kw, (1 + e) * j, j, period=1, latency=1, mean_rate=False)
            for (ks, kw), j in zip(axis_gains(K), paper.INERTIA, strict=True)
        )
        lines.append(f"  mrpctl's sampled PD model (u_k = K x_(k-1)), e = {e:+.0%}: flown_radius {mine:.9f}")
    return lines


# ------------------------------------------------------------------------------------------------------------
# The runs.
# ------------------------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Row:
    rms: float  # rad
    settling: float  # s
    peak_torque: float  # N m, the largest |u_i| over the runs
    torque_rms: float  # N m, RMS of u over t >= 150 s (all axes, mean over the runs)
    estimation: float  # rad, RMS of the attitude estimation error's norm over t >= 150 s (the MEKF loop; else nan)


def run_row(mode: str, K: np.ndarray, scale: float, seeds: int, *, exact_model: bool = False) -> Row:
    plant = Spacecraft(np.array(paper.INERTIA) * scale)
    rms, settling, peak, estimation, torque = [], [], 0.0, [], []
    for seed in range(seeds):
        run = simulate_estimated(
            plant,
            K,
            paper.INITIAL_STATE,
            sensors=Sensors(TRACKER, GYRO, seed),
            t_final=T_FINAL,
            rate=RATE,
            estimator=ESTIMATOR,
            substeps=SUBSTEPS,
            mode=mode,
            model_spacecraft=plant if exact_model else paper.SPACECRAFT,
        )
        rms.append(run.pointing_rms(150.0))
        settling.append(run.settling_time(SETTLED))
        peak = max(peak, float(np.max(np.abs(run.u))))
        torque.append(float(np.sqrt(np.mean(run.u[run.t >= 150.0] ** 2))))
        if mode == "estimator":
            error = np.linalg.norm(run.estimation_error[run.t >= 150.0], axis=1)
            estimation.append(float(np.sqrt(np.mean(error**2))))
    mean_estimation = float(np.mean(estimation)) if estimation else np.nan
    return Row(float(np.mean(rms)), float(np.mean(settling)), peak, float(np.mean(torque)), mean_estimation)


def _inertia(scale: float) -> str:
    return "nominal" if scale == 1.0 else f"{scale - 1:+.0%}"


def table(title: str, gains: dict[str, np.ndarray], seeds: int) -> None:
    print(title)
    print(
        f"| controller | inertia | pointing RMS, t >= 150 s (arcsec) | settling time to {SETTLED} rad (s) "
        "| peak torque (N m) | torque RMS, t >= 150 s (N m) |"
    )
    print("|---|---|---|---|---|---|")
    rows = [(label, mode, False) for label, mode, _ in LOOPS]
    rows.insert(2, ("(b') model predictor, exact model (J_m = J)", "predictor", True))
    notes = []
    for label, mode, exact in rows:
        for scale in (1.0, 1.1, 0.9):
            row = run_row(mode, gains[mode], scale, seeds, exact_model=exact)
            if mode == "estimator":
                notes.append(f"{_inertia(scale)} {row.estimation * ARCSEC:.2f}")
            print(
                f"| {label} | {_inertia(scale)} | {row.rms * ARCSEC:.1f} | {row.settling:.1f} "
                f"| {row.peak_torque:.3g} | {row.torque_rms:.2g} |",
                flush=True,
            )
    truth = (("(d) PD on the true state at t_k", "now"), ("(d') PD on the true attitude and mean rate", "mean"))
    for label, at in truth:
        for scale in (1.0, 1.1, 0.9):
            rms, settling = true_state_loop(scale, at=at, gain=gains["estimator"])
            print(f"| {label} | {_inertia(scale)} | {rms * ARCSEC:.1f} | {settling:.1f} | | |", flush=True)
    print("the MEKF loop's attitude estimation error, RMS of its norm over t >= 150 s (arcsec): " + ", ".join(notes))
    print()


def main(seeds: int) -> None:
    print("the rule: synthesize_pd(paper.SPACECRAFT, tau_d, zeta=1.0, tolerance=0.1, period=0.1)")
    designs = {}
    for tau_d in sorted({tau for _, _, tau in LOOPS}):
        start = time.perf_counter()
        nominal = synthesize_pd(paper.SPACECRAFT, tau_d, zeta=1.0)
        robust = synthesize_pd(paper.SPACECRAFT, tau_d, zeta=1.0, tolerance=TOLERANCE, period=H)
        designs[tau_d] = robust
        print(f"tau_d = {tau_d:g} s ({time.perf_counter() - start:.0f} s):")
        print(
            f"  nominal design: omega_n = {nominal.omega_n:.6g} rad/s, exact delay margin {nominal.margin.margin:.6g} s"
        )
        print("  " + str(robust).replace("\n", "\n  "))
    gains = {}
    for label, mode, tau_d in LOOPS:
        design = designs[tau_d]
        assert design.gains is not None, f"{label}: no gains for tau_d = {tau_d}"
        gains[mode] = np.asarray(design.gains.K)
        k = gains[mode]
        print(
            f"{label}: tau_d = {tau_d:g} s, omega_n = {design.omega_n:.6g} rad/s, zeta = 1; "
            f"K_sigma = {np.diag(k[:, :3]).round(2).tolist()}, K_omega/4-gain = {np.diag(k[:, 3:]).round(2).tolist()}; "
            f"design status: {design.status.value}"
        )
    print()
    print("mrpctl's predictor certificate for (b) (predictor_stability, 10 Hz, nominal model, plant (1+e) J):")
    for d in range(LATENCY, LATENCY + TRACKER_PERIOD):
        verdicts = []
        for j in range(-10, 11):
            e = TOLERANCE * j / 10
            result = predictor_stability(
                paper.SPACECRAFT, gains["predictor"], d * H, plant=perturbed_spacecraft(paper.SPACECRAFT, e), rate=RATE
            )
            verdicts.append(result.status.value)
        print(f"  age {d * H:.1f} s: e = -10 % .. +10 % in steps of 1 %: {sorted(set(verdicts))}")
    print()
    print("the same check of the paper's gain, for the same-gain comparison:")
    paper_gain = np.asarray(paper.GAIN)
    for d in range(LATENCY, LATENCY + TRACKER_PERIOD):
        verdicts = {
            predictor_stability(
                paper.SPACECRAFT, paper_gain, d * H, plant=perturbed_spacecraft(paper.SPACECRAFT, e), rate=RATE
            ).status.value
            for e in (-TOLERANCE, 0.0, TOLERANCE)
        }
        print(f"  age {d * H:.1f} s: e = -10 %, 0, +10 %: {sorted(verdicts)}")
    print()
    print("the as-flown model against mrpctl's predictor test (same loop when measured every sample at a point rate):")
    for line in cross_checks(gains["predictor"]):
        print(line)
    print()
    print("exact spectral radius per sample of the linearised loop as flown (largest over the axes; < 1 is stable):")
    print("| loop | gain | " + " | ".join(f"e = {e:+.0%}" for e in ERRORS) + " |")
    print("|---|---|" + "---|" * len(ERRORS))
    for (label, mode, _), law in zip(LOOPS, ("pd", "predictor", "now"), strict=True):
        for gain_label, k in (("paper", paper_gain), ("designed", gains[mode])):
            radii = worst_flown(law, k)
            print(f"| {label} | {gain_label} | " + " | ".join(f"{radii[e]:.5f}" for e in ERRORS) + " |")
    print()
    print("factors, designed gain of (b) and (c): radius per sample (decay rate -ln(radius)/h, 1/s):")
    print("| loop | e = -10% | e = +0% | e = +10% |")
    print("|---|---|---|---|")
    factors = (
        ("(b) as flown (mean-rate reading carried over the age 0.5-0.9 s)", "predictor", True, False),
        ("(b') as flown with the exact model (J_m = J)", "predictor", True, True),
        ("(b) with a point-rate reading omega_j (no half-period lag)", "predictor", False, False),
        ("(c) = (d') law on sigma_k and the mean rate", "now", True, False),
        ("(d) law on sigma_k and omega_k", "now", False, False),
    )
    for label, law, mean, exact in factors:
        cells = []
        for e in (-TOLERANCE, 0.0, TOLERANCE):
            radius = max(
                flown_radius(law, ks, kw, (1 + e) * j, (1 + e) * j if exact else j, mean_rate=mean)
                for (ks, kw), j in zip(axis_gains(gains["estimator"]), paper.INERTIA, strict=True)
            )
            cells.append(f"{radius:.4f} ({-np.log(radius) / H:.2f})")
        print(f"| {label} | " + " | ".join(cells) + " |")
    print()
    table(
        f"same gain (the paper's K in every loop; {seeds} seeds):",
        {mode: paper_gain for _, mode, _ in LOOPS},
        seeds,
    )
    table(f"designed gains (the rule above; {seeds} seeds):", gains, seeds)


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
