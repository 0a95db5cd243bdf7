"""The steering law designed for the wheel cluster, flown on it: the 12U cubesat on three reaction wheels.

J = diag(0.2, 0.25, 0.15) kg m², τ = 0.2 s, ``Hysteretic(0)``, three orthogonal wheels of 5 mN m and 20 mN m s at
6 000 rpm (Js = 3.18e-5 kg m², starting at rest). Runs: an SO(3)-uniform attitude (``scipy.spatial.transform.
Rotation.random``) and |ω₀| uniform in [0, 0.05] rad/s about a uniform axis, seeded; horizon 300 s; settling is
mrpctl's (|σ| < 1e-2, |ω| < 1e-3 rad/s after the last unsettled sample). Three laws on the same K
(``synthesize_pd(sc, 0.2, zeta=1)``, the design's): the PD law alone, the steering law designed for an ideal
5 mN m torque (``design_for_actuator(sc, 0.2, ActuatorModel(5e-3))``, which never hears of the wheels), and the
steering law designed for the cluster (``design_for_actuator(sc, 0.2, wheels)``: the same U, the rate limit
bounded by the wheels' momentum). Per run the minimum-time bound is ``slew_lower_bound(θ, J_e, 5e-3)`` =
2 √(θ J_e / u), θ the initial principal angle, J_e = êᵀJê about its axis (rest to rest, ω₀ and the momentum
limit ignored). Prints per law the fraction settled within 60 s with its Clopper-Pearson 95 % interval
(``scipy.stats.binomtest(...).proportion_ci(method="exact")``), the median and worst settling time, the median
and worst of t_s / bound, and the runs in which a wheel reached its speed limit.

    PYTHONPATH=$PWD python bench/wheels_steering.py [runs] [seed] [rate_hz]   (default 300 1 50)
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import binomtest

from mrpctl import Spacecraft, simulate_batch
from mrpctl.design.actuator import design_for_actuator, slew_lower_bound
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.model import state
from mrpctl.wheels import WheelCluster

INERTIA = np.diag([0.2, 0.25, 0.15])
TAU, TORQUE, MAX_RATE, GOAL, HORIZON = 0.2, 5e-3, 0.05, 60.0, 300.0
SPEED_LIMIT = 6000.0 * 2.0 * math.pi / 60.0  # rad/s
WHEELS = WheelCluster.orthogonal(0.020 / SPEED_LIMIT, TORQUE, SPEED_LIMIT)


def envelope_sample(runs: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(x0 (runs, 6), the per-run minimum-time bound (s)) of the envelope."""
    rng = np.random.default_rng(seed)
    rotation = Rotation.random(runs, random_state=rng)
    rotvec = rotation.as_rotvec()  # principal angle in [0, π] about its axis
    angle = np.linalg.norm(rotvec, axis=1)
    axis = rotvec / angle[:, None]
    sigma = np.tan(angle / 4.0)[:, None] * axis
    spin = rng.normal(size=(runs, 3))
    spin /= np.linalg.norm(spin, axis=1)[:, None]
    omega = rng.uniform(0.0, MAX_RATE, runs)[:, None] * spin
    inertia = np.einsum("ni,ij,nj->n", axis, INERTIA, axis)
    bound = np.array([slew_lower_bound(a, j, TORQUE) for a, j in zip(angle, inertia, strict=True)])
    return state(sigma, omega), bound


def report(name: str, settling: np.ndarray, bound: np.ndarray, at_limit: int, seconds: float) -> None:
    settled = np.isfinite(settling) & (settling <= GOAL)
    test = binomtest(int(settled.sum()), len(settling))
    low, high = test.proportion_ci(confidence_level=0.95, method="exact")
    ratio = settling / bound
    print(
        f"{name}: settled within {GOAL:g} s on {settled.sum()}/{len(settling)} = {100 * settled.mean():.1f} % "
        f"(95 % CI {100 * low:.1f}-{100 * high:.1f} %); never settled in {HORIZON:g} s "
        f"{np.sum(~np.isfinite(settling))}; "
        f"settling median {np.nanmedian(settling):.1f} s, worst {np.nanmax(settling):.1f} s; t_s / bound median "
        f"{np.nanmedian(ratio):.2f}, worst {np.nanmax(ratio):.2f}; a wheel at its speed limit in {at_limit} runs; "
        f"{seconds:.1f} s wall"
    )


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 300
    seed = int(sys.argv[2]) if len(sys.argv) > 2 else 1
    rate = float(sys.argv[3]) if len(sys.argv) > 3 else 50.0
    spacecraft = Spacecraft(INERTIA)
    ideal = design_for_actuator(spacecraft, TAU, ActuatorModel(TORQUE), max_rate=MAX_RATE, settling_time=GOAL)
    design = design_for_actuator(spacecraft, TAU, WHEELS, max_rate=MAX_RATE, settling_time=GOAL)
    print(design)
    x0, bound = envelope_sample(runs, seed)
    print(
        f"{runs} runs, seed {seed}, {rate:g} Hz; per-run bound median {np.median(bound):.1f} s, "
        f"worst {bound.max():.1f} s"
    )
    laws = (
        ("PD alone", None),
        ("law designed for 5 mN m (ideal)", ideal.law),
        ("law designed for the wheels", design.law),
    )
    for name, law in laws:
        start = time.perf_counter()
        batch = simulate_batch(
            spacecraft, design.K, x0, tau=TAU, rule=Hysteretic(0.0), t_final=HORIZON, rate=rate, wheels=WHEELS, law=law
        )
        assert batch.wheels is not None
        at_limit = sum(bool(record.speed_limited_time.max() > 0.0) for record in batch.wheels)
        report(name, np.asarray(batch.settling_time), bound, at_limit, time.perf_counter() - start)


if __name__ == "__main__":
    main()
