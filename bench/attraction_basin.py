"""The certified region of attraction against the sampled basin, for the cubesat of bench/actuator_design.py.

K = synthesize_pd(sc, 0.2, zeta=1)'s gains, ActuatorModel(5e-3), τ = 0.2 s, rule Hysteretic(0), 1000 Hz,
constant history; the ellipsoid certified for the design's steering law too (``law=``). 1. ``runs``
initial states on the boundary of the certified ellipsoid (scaled by 0.999), simulated with the
nonlinear compiled loop (MRP kinematics, gyroscopic torque, sample and hold), with the PD law and
with the steering law: how many fail to settle within the horizon. 2. Along ``directions`` of those boundary points,
the sampled basin: the largest factor λ (bisection, 8 steps in [1, 10⁴]) with λ x_boundary settling
within the horizon; its min, median and max are the basin's size against the ellipsoid's along the
direction.

    PYTHONPATH=$PWD python bench/attraction_basin.py [runs] [directions]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from mrpctl import Spacecraft, simulate_batch
from mrpctl.design.actuator import design_for_actuator
from mrpctl.design.attraction import AttractionRegion, certify_attraction
from mrpctl.flight import ActuatorModel, Hysteretic
from mrpctl.flight.steering import SteeringLaw

INERTIA = np.diag([0.2, 0.25, 0.15])
TAU, TORQUE, HORIZON = 0.2, 5e-3, 60.0


def boundary_states(region: AttractionRegion, runs: int, seed: int = 0, shrink: float = 0.999) -> np.ndarray:
    """``runs`` states x = [σ; ω/4] uniform in direction on {xᵀ M x = shrink² c}."""
    assert region.matrix is not None
    rng = np.random.default_rng(seed)
    v = rng.normal(size=(runs, 6))
    quadratic = np.einsum("ni,ij,nj->n", v, region.matrix, v)
    return v * (shrink * np.sqrt(region.level / quadratic))[:, None]


def settled(
    spacecraft: Spacecraft, K: np.ndarray, x0: np.ndarray, actuator: ActuatorModel, law: SteeringLaw | None = None
) -> np.ndarray:
    batch = simulate_batch(
        spacecraft, K, x0, tau=TAU, rule=Hysteretic(0.0), t_final=HORIZON, actuator=actuator, law=law
    )
    return np.isfinite(np.asarray(batch.settling_time)) & (np.asarray(batch.settling_time) < HORIZON - 1.0)


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 300
    directions = int(sys.argv[2]) if len(sys.argv) > 2 else 40
    spacecraft, actuator = Spacecraft(INERTIA), ActuatorModel(TORQUE)
    design = design_for_actuator(spacecraft, TAU, actuator, max_rate=0.05)
    start = time.perf_counter()
    region = certify_attraction(spacecraft, design.K, TAU, actuator, law=design.law)
    print(region, f"\n  ({time.perf_counter() - start:.1f} s)")
    x0 = boundary_states(region, runs)
    ok = settled(spacecraft, design.K, x0, actuator)
    print(f"boundary, PD law: {ok.sum()}/{runs} runs settle within {HORIZON:g} s, {runs - ok.sum()} fail")
    steered = settled(spacecraft, design.K, x0, actuator, design.law)
    print(
        f"boundary, steering law: {steered.sum()}/{runs} runs settle within {HORIZON:g} s, {runs - steered.sum()} fail"
    )
    picked = x0[:directions]
    low, high = np.ones(directions), np.full(directions, 1e4)
    for _ in range(8):  # bisection in log λ, every direction at once
        middle = np.sqrt(low * high)
        good = settled(spacecraft, design.K, picked * middle[:, None], actuator)
        low, high = np.where(good, middle, low), np.where(good, high, middle)
    print(
        f"sampled basin along {directions} directions: the largest settling factor lambda (x = lambda x_boundary) "
        f"min {low.min():.3g}, median {np.median(low):.3g}, max {low.max():.3g} "
        f"(bracket to x{1e4 ** (1 / 256):.3f})"
    )
    rate = 4.0 * np.linalg.norm(picked[:, 3:6] * low[:, None], axis=1)
    angle = 4.0 * np.degrees(np.arctan(np.linalg.norm(picked[:, 0:3] * low[:, None], axis=1)))
    print(f"  at the basin's edge: angle median {np.median(angle):.3g} deg, rate median {np.median(rate):.3g} rad/s")


if __name__ == "__main__":
    main()
