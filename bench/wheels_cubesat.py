"""The 12U cubesat on three reaction wheels against the same loop on an ideal 5 mN m torque limit; prints one table.

J = diag(0.2, 0.25, 0.15) kg m², star-tracker latency tau = 0.2 s at 50 Hz, ``Hysteretic(0.1)``, three orthogonal
wheels of 5 mN m and 20 mN m s at 6 000 rpm (Js = 3.18e-5 kg m²), starting at rest. Runs: an SO(3)-uniform
attitude and |ω₀| uniform in [0, 0.05] rad/s about a uniform axis (seeded), 300 s each. Gains: ``synthesize_pd(sc,
0.2, zeta=1)`` (the certified gains of the ideal-torque design, which never hears of the actuator) and, for
comparison, a hand-picked low-bandwidth PD (σ̈ = −0.01 σ − 0.2 σ̇ per axis). For each: runs settled within 60 s
(|σ| < 1e-2, |ω| < 1e-3 rad/s to the end) with a Wilson 95 % interval, the median and worst settling time, the
largest peak wheel speed over the runs and the runs that reached the wheels' speed limit; and the minimum-time
bound 2√(θ J_min/u) of each run's rest-to-rest slew (θ its angle from the target; J_min = 0.15 kg m²) for scale.

Run: ``.venv/bin/python bench/wheels_cubesat.py [runs]`` (default 300; about a minute).
"""

from __future__ import annotations

import math
import sys

import numpy as np

from mrpctl import simulate
from mrpctl.design import synthesize_pd
from mrpctl.flight import ActuatorModel, Hysteretic, Saturation
from mrpctl.model import gain_from_pd, state
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

SPACECRAFT = Spacecraft(np.diag([0.2, 0.25, 0.15]))
TAU = 0.2
RATE = 50.0
T_FINAL = 300.0
SPEED_LIMIT = 6000.0 * 2.0 * math.pi / 60.0
WHEELS = WheelCluster.orthogonal(0.020 / SPEED_LIMIT, 5e-3, SPEED_LIMIT)
ACTUATOR = ActuatorModel(5e-3, mode=Saturation.CLIP)
RULE = Hysteretic(0.1)


def initial_states(runs: int, seed: int = 25) -> tuple[np.ndarray, np.ndarray]:
    """(x0 (runs, 6), angle from the target (runs,) rad): uniform quaternions, |ω| uniform in [0, 0.05]."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(runs, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1.0
    sigma = q[:, 1:4] / (1.0 + q[:, 0:1])
    axis = rng.normal(size=(runs, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    omega = axis * rng.uniform(0.0, 0.05, size=(runs, 1))
    return state(sigma, omega), 2.0 * np.arccos(np.clip(q[:, 0], -1.0, 1.0))


def wilson(successes: int, total: int, z: float = 1.96) -> tuple[float, float]:
    p = successes / total
    centre = (p + z * z / (2 * total)) / (1 + z * z / total)
    half = z * math.sqrt(p * (1 - p) / total + z * z / (4 * total * total)) / (1 + z * z / total)
    return centre - half, centre + half


def main() -> int:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 300
    x0s, angles = initial_states(runs)
    bound = 2.0 * np.sqrt(angles * 0.15 / 5e-3)
    designed = synthesize_pd(SPACECRAFT, TAU, zeta=1.0)
    gains = {
        "synthesize_pd(zeta=1)": designed.gains.K,
        "PD -0.01, -0.2 (by hand)": gain_from_pd(SPACECRAFT, -0.01 * np.ones(3), -0.2 * np.ones(3)),
    }
    print(
        f"cubesat, tau = {TAU} s at {RATE:g} Hz, Hysteretic(0.1), {runs} runs of {T_FINAL:g} s; minimum-time bound "
        f"median {np.median(bound):.1f} s, worst {bound.max():.1f} s"
    )
    print(
        f"{'gain':26s} {'actuator':22s} {'<= 60 s':>8s} {'95 % interval':>15s} {'median s':>9s} {'worst s':>8s} "
        f"{'unsettled':>9s} {'peak rpm':>9s} {'at limit':>8s}"
    )
    for label, K in gains.items():
        for name, options in (("ideal torque 5 mN m", {"actuator": ACTUATOR}), ("3 wheels", {"wheels": WHEELS})):
            times, peaks, limited = [], [], 0
            for x0 in x0s:
                run = simulate(
                    SPACECRAFT, K, x0, tau=TAU, rule=RULE, t_final=T_FINAL, rate=RATE, keep_every=None, **options
                )
                times.append(math.inf if run.settling_time is None else run.settling_time)
                if run.wheels is not None:
                    peaks.append(float(run.wheels.peak_speed.max()))
                    limited += bool(run.wheels.speed_limited_time.max() > 0.0)
            settled = np.array(times)
            inside = int(np.sum(settled <= 60.0))
            low, high = wilson(inside, runs)
            finite = settled[np.isfinite(settled)]
            median = float(np.median(settled))
            worst = float(finite.max()) if finite.size else math.nan
            peak = f"{max(peaks) * 60 / (2 * math.pi):9.0f}" if peaks else f"{'-':>9s}"
            at_limit = f"{limited:8d}" if peaks else f"{'-':>8s}"
            print(
                f"{label:26s} {name:22s} {inside / runs:8.1%} {f'[{low:.1%}, {high:.1%}]':>15s} {median:9.1f} "
                f"{worst:8.1f} {runs - finite.size:9d} {peak} {at_limit}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
