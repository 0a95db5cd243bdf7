"""Design for the actuator, measured: the 12U cubesat with a 5 mN m body torque limit and τ = 0.2 s.

300 runs (SO(3)-uniform attitude, |ω₀| uniform in [0, 0.05] rad/s about a uniform axis), rule
Hysteretic(0), ActuatorModel(5e-3) (per axis, direction-preserving), 1000 Hz; settling is mrpctl's
(|σ| < 1e-2, |ω| < 1e-3 rad/s, the last unsettled sample). Two laws: the PD gains of
``synthesize_pd(sc, 0.2, zeta=1)`` alone (horizon 300 s), and the steering law of
``design_for_actuator`` with the same K (horizon 120 s). Per run the minimum-time bound is
2 √(θ J_e / u), θ the initial principal angle, J_e = êᵀJê about its axis, u = 5 mN m (the
rest-to-rest bang-bang time; ω₀ ignored). Prints the fraction settled within 60 s with its
Clopper-Pearson 95 % interval (scipy.stats.binomtest), the median settling time, and the median
of the per-run ratio to the bound.

    PYTHONPATH=$PWD python bench/actuator_design.py [runs] [seed]
"""

from __future__ import annotations

import sys
import time

import numpy as np
from scipy.stats import binomtest

from mrpctl import Spacecraft, simulate_batch
from mrpctl.design.actuator import design_for_actuator, slew_lower_bound
from mrpctl.flight import ActuatorModel, Hysteretic

INERTIA = np.diag([0.2, 0.25, 0.15])
TAU, TORQUE, MAX_RATE, GOAL = 0.2, 5e-3, 0.05, 60.0


def envelope_sample(runs: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(x0 (runs, 6), the per-run minimum-time bound (s)) of the envelope."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(runs, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]  # SO(3)-uniform (Haar) quaternions
    q[q[:, 0] < 0] *= -1.0
    sigma = q[:, 1:] / (1.0 + q[:, 0:1])
    axis = rng.normal(size=(runs, 3))
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    omega = rng.uniform(0.0, MAX_RATE, runs)[:, None] * axis
    size = np.linalg.norm(sigma, axis=1)
    angle = 4.0 * np.arctan(size)
    e = sigma / size[:, None]
    inertia = np.einsum("ni,ij,nj->n", e, INERTIA, e)
    bound = np.array([slew_lower_bound(a, j, TORQUE) for a, j in zip(angle, inertia, strict=True)])
    return np.hstack((sigma, omega / 4.0)), bound


def report(name: str, settling: np.ndarray, bound: np.ndarray, seconds: float) -> None:
    settled = np.isfinite(settling) & (settling <= GOAL)
    test = binomtest(int(settled.sum()), len(settling))
    low, high = test.proportion_ci(confidence_level=0.95, method="exact")
    ratio = settling / bound
    print(
        f"{name}: settled within {GOAL:g} s on {settled.sum()}/{len(settling)} = {100 * settled.mean():.1f} % "
        f"(95 % CI {100 * low:.1f}-{100 * high:.1f} %); never settled in the horizon {np.sum(~np.isfinite(settling))}; "
        f"settling time median {np.nanmedian(settling):.1f} s, worst {np.nanmax(settling):.1f} s; "
        f"ratio to the per-run bound median {np.nanmedian(ratio):.2f}, worst {np.nanmax(ratio):.2f} "
        f"(bound median {np.median(bound):.1f} s); {seconds:.1f} s wall"
    )


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 300
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    spacecraft = Spacecraft(INERTIA)
    actuator = ActuatorModel(TORQUE)
    design = design_for_actuator(spacecraft, TAU, actuator, max_rate=MAX_RATE, settling_time=GOAL)
    print(design)
    x0, bound = envelope_sample(runs, seed)
    for name, law, horizon in (("PD (synthesize_pd) alone", None, 300.0), ("steering law", design.law, 120.0)):
        start = time.perf_counter()
        batch = simulate_batch(
            spacecraft, design.K, x0, tau=TAU, rule=Hysteretic(0.0), t_final=horizon, actuator=actuator, law=law
        )
        report(name, np.asarray(batch.settling_time), bound, time.perf_counter() - start)


if __name__ == "__main__":
    main()
