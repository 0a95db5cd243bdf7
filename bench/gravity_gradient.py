"""The gravity-gradient torque in the flown plant (``simulate(..., gravity_gradient=orbit)``): what it does and
what it costs.

* ``physics``: the pitch libration of a body in the Hill frame (the fast orbit of the tests, n = 0.05 rad/s,
  J = diag(80, 100, 140) in the Hill axes, K = 0, 20 Hz): the period from the zero crossings against
  2π/ω_p, ω_p = n √(3 (J_y − J_x)/J_z), and the exact pendulum period (4/ω_p) K(sin² θ₀); the equilibrium of the
  aligned body over two orbits; and the paper loop's nadir pointing at 500 km (τ = 0.5 s, 200 Hz, feedforward,
  120 s) with J of products of inertia: the simulated steady σ_B/R against the linear steady state
  (A + A_d)⁻¹ B L_unbalanced of ``mrpctl.design.tracking``.
* ``cost``: the paper case (60 001 samples at 1 kHz, ``Hysteretic(0.0)``, ``keep_every=None``, compiled
  scalar engine) regulating and tracking the 500 km Hill frame (its rows made before the timing), each with and
  without the gravity gradient,
  interleaved round by round, process CPU time, min over the rounds; and a metrics-only batch of 64 runs on the
  lanes (one thread) with and without it.

Run: ``PYTHONPATH=. .venv/bin/python bench/gravity_gradient.py [physics|cost] [rounds]``.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.special import ellipk

from mrpctl import paper, simulate, simulate_batch
from mrpctl.design.tracking import tracking_linearization
from mrpctl.flight import Hysteretic
from mrpctl.guidance import CircularOrbit, NadirPointing, reference_samples
from mrpctl.spacecraft import Spacecraft

FAST = CircularOrbit(orbit_rate=0.05, inclination=0.7, raan=0.4, latitude=0.3)
STABLE_J = (80.0, 100.0, 140.0)
FULL_J = np.array([[140.0, 4.0, -2.0], [4.0, 100.0, 3.0], [-2.0, 3.0, 80.0]])


def _hill_start(orbit: CircularOrbit, pitch: float) -> np.ndarray:
    hn = Rotation.from_mrp(NadirPointing(orbit).samples([0.0])[0, 0:3]).as_matrix().T
    bh = Rotation.from_rotvec([0.0, 0.0, pitch]).as_matrix().T
    sigma = Rotation.from_matrix((bh @ hn).T).as_mrp()
    return np.concatenate((sigma, [0.0, 0.0, orbit.orbit_rate / 4.0]))


def _hill_angles(run: object, orbit: CircularOrbit) -> np.ndarray:
    t, sigma = np.asarray(run.t), np.array(run.sigma)  # type: ignore[attr-defined]
    nh = np.swapaxes(orbit.hill_dcm(t), 1, 2)
    bn = Rotation.from_mrp(sigma).as_matrix().transpose(0, 2, 1)
    return Rotation.from_matrix(np.swapaxes(bn @ nh, 1, 2)).as_rotvec()


def _period(t: np.ndarray, angle: np.ndarray) -> float:
    at = np.flatnonzero(np.signbit(angle[:-1]) != np.signbit(angle[1:]))
    crossings = t[at] - angle[at] * (t[at + 1] - t[at]) / (angle[at + 1] - angle[at])
    return float(2.0 * (crossings[-1] - crossings[0]) / (len(crossings) - 1))


def physics() -> None:
    spacecraft = Spacecraft(STABLE_J)
    jx, jy, jz = STABLE_J
    omega_p = FAST.orbit_rate * math.sqrt(3.0 * (jy - jx) / jz)
    print(f"pitch libration, n = {FAST.orbit_rate} rad/s, J = diag{STABLE_J}: omega_p = {omega_p:.9g} rad/s")
    print("| theta0 (rad) | period (s) | exact (4/omega_p) K(sin^2 theta0) | rel. | linear 2 pi/omega_p | rel. |")
    print("|---|---|---|---|---|---|")
    for pitch in (1e-3, 0.1, 0.3):
        run = simulate(
            spacecraft, np.zeros((3, 6)), _hill_start(FAST, pitch), tau=0.0, rule=Hysteretic(0.0), t_final=700.0,
            rate=20.0, gravity_gradient=FAST,
        )  # fmt: skip
        measured = _period(np.asarray(run.t), _hill_angles(run, FAST)[:, 2])
        exact = 4.0 / omega_p * ellipk(math.sin(pitch) ** 2)
        linear = 2.0 * math.pi / omega_p
        print(
            f"| {pitch:g} | {measured:.9f} | {exact:.9f} | {measured / exact - 1:.1e} | {linear:.9f} | "
            f"{measured / linear - 1:.1e} |"
        )
    run = simulate(
        spacecraft, np.zeros((3, 6)), _hill_start(FAST, 0.0), tau=0.0, rule=Hysteretic(0.0),
        t_final=2 * FAST.period, rate=100.0, gravity_gradient=FAST,
    )  # fmt: skip
    angles = _hill_angles(run, FAST)
    omega = np.asarray(run.omega)
    print(
        f"aligned body, two orbits at 100 Hz: max angle from the Hill frame {np.max(np.abs(angles)):.2e} rad, "
        f"max roll/yaw rate {np.max(np.abs(omega[:, 0:2])):.2e} rad/s, max |omega_z - n| "
        f"{np.max(np.abs(omega[:, 2] - FAST.orbit_rate)):.2e} rad/s"
    )

    orbit = CircularOrbit.from_altitude(500e3, inclination=1.2, raan=0.5)
    reference = NadirPointing(orbit)
    rows = reference.samples([0.0])[0]
    print(f"nadir pointing at 500 km (n = {orbit.orbit_rate:.6g} rad/s), paper gain, tau = 0.5 s, feedforward:")
    for name, inertia, gravity in (
        ("J with products of inertia, gravity gradient", FULL_J, orbit),
        ("J with products of inertia, no gravity gradient", FULL_J, None),
        ("paper J (diagonal in the Hill axes), gravity gradient", paper.INERTIA, orbit),
    ):
        craft = Spacecraft(inertia)
        x0 = np.concatenate((rows[0:3], Rotation.from_mrp(rows[0:3]).as_matrix().T @ rows[3:6] / 4.0))
        run = simulate(
            craft, paper.GAIN, x0, tau=0.5, rule=Hysteretic(0.0), t_final=120.0, rate=200.0, reference=reference,
            feedforward=True, gravity_gradient=gravity, keep_every=100,
        )  # fmt: skip
        rn = Rotation.from_mrp(reference.samples(np.asarray(run.t))[:, 0:3])
        sigma_br = (rn.inv() * Rotation.from_mrp(np.array(run.sigma))).as_mrp()
        line = f"  {name}: steady sigma_BR = {np.array2string(sigma_br[-1], precision=6)}"
        line += f" ({4 * math.degrees(math.atan(np.linalg.norm(sigma_br[-1]))):.3e} deg)"
        if gravity is not None and inertia is FULL_J:
            linear = tracking_linearization(craft, paper.GAIN, reference, feedforward=True)
            predicted = np.linalg.solve(linear.A + linear.A_d, linear.B @ linear.unbalanced_torque)[0:3]
            line += f"; linear (A + A_d)^-1 B L = {np.array2string(predicted, precision=6)}"
            relative = np.linalg.norm(sigma_br[-1] - predicted) / np.linalg.norm(predicted)
            line += f", |difference|/|linear| = {relative:.1e}"
            line += f"; L_unbalanced = {np.array2string(np.asarray(linear.unbalanced_torque), precision=4)} N m"
        print(line)


def cost(rounds: int) -> None:
    orbit = CircularOrbit.from_altitude(500e3, inclination=1.2, raan=0.5)
    reference = reference_samples(NadirPointing(orbit), 60_001, 1000.0)  # the rows once, before the timing
    common = dict(tau=0.5, rule=Hysteretic(0.0), t_final=60.0, rate=1000.0, keep_every=None)
    variants = {
        "regulation": {},
        "regulation + gravity gradient": {"gravity_gradient": orbit},
        "nadir tracking + feedforward": {"reference": reference, "feedforward": True},
        "nadir tracking + feedforward + gravity gradient": {
            "reference": reference, "feedforward": True, "gravity_gradient": orbit,
        },
    }  # fmt: skip
    for options in variants.values():
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common, **options)
    times: dict[str, list[float]] = {name: [] for name in variants}
    for _ in range(rounds):
        for name, options in variants.items():
            start = time.process_time()
            simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common, **options)
            times[name].append(time.process_time() - start)
    base = min(times["regulation"])
    print(f"scalar engine, 60 001 samples, min of {rounds} rounds (process CPU time):")
    for name, values in times.items():
        print(f"  {name}: {min(values) / 60_001 * 1e9:.0f} ns/sample ({min(values) / base:.2f} x regulation)")
    rng = np.random.default_rng(1)
    x0 = np.hstack((rng.normal(size=(64, 3)) * 0.3, rng.normal(size=(64, 3)) * 0.02))
    batch = dict(tau=0.5, rule=Hysteretic(0.0), t_final=20.0, rate=1000.0, threads=1)
    for options in ({}, {"gravity_gradient": orbit}):
        simulate_batch(paper.SPACECRAFT, paper.GAIN, x0[:8], **{**batch, "t_final": 1.0}, **options)
        best = math.inf
        for _ in range(max(1, rounds // 3)):
            start = time.process_time()
            simulate_batch(paper.SPACECRAFT, paper.GAIN, x0, **batch, **options)
            best = min(best, time.process_time() - start)
        label = "with" if options else "without"
        per_sample = best / 64 / 20_001 * 1e9
        print(f"  lanes, 64 runs of 20 001 samples {label} the gravity gradient: {per_sample:.0f} ns/sample")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "physics"
    if what == "physics":
        physics()
    else:
        cost(int(sys.argv[2]) if len(sys.argv) > 2 else 7)
