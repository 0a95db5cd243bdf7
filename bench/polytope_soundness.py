"""Soundness of the polytope criterion on 200 seeded random polytopes, checked by the exact grid method (issue 11).

Run: python bench/polytope_soundness.py [count]. Two families, count/2 each (seed 20261201):

- inertia boxes: random diagonal J0 (1 to 200 kg m^2 per axis, triangle inequality kept), random per-axis PD gains
  (omega_n 0.1 to 3 rad/s, zeta 0.5 to 2, K = [4 J0 K1, 4 J0 K2]) and a random tolerance 2 % to 60 %;
  certify_polytope (3 axes, 2 vertices each); reference exact_polytope_margin (41 grid inertias per axis);
- general segments: two random 2x2 plants (A, A_d) near a random stable one; certify_vertices;
  reference: the exact delay margin at 41 points of the segment (min; plants unstable without delay
  make the system skipped).

Each system is tested at tau = f x (exact reference) for f in FRACTIONS with the vertex-dependent
functional and the common one. A violation is a certificate at a tau where some grid point is not
stable (none expected). Prints a markdown table (counts certified per fraction) and the time per
certificate.
"""

from __future__ import annotations

import sys
import time

import numpy as np

from mrpctl import Spacecraft
from mrpctl.design import delay_margin
from mrpctl.design.gains import pd_gains
from mrpctl.design.lmi import CertificateStatus
from mrpctl.design.polytope import (
    Functional,
    PolytopeCertificate,
    certify_polytope,
    certify_vertices,
    exact_polytope_margin,
    inertia_polytope,
)

FRACTIONS = (0.9, 0.99, 1.01)
FUNCTIONALS = (Functional.VERTEX, Functional.COMMON)


def _segment(rng: np.random.Generator) -> tuple[list[tuple[np.ndarray, np.ndarray]], float] | None:
    a0, ad0 = rng.normal(size=(2, 2)), rng.normal(size=(2, 2))
    spread = rng.uniform(0.05, 0.5)
    ends = [(a0 + spread * rng.normal(size=(2, 2)), ad0 + spread * rng.normal(size=(2, 2))) for _ in range(2)]
    worst = np.inf
    for lam in np.linspace(0.0, 1.0, 41):
        m = delay_margin((1 - lam) * ends[0][0] + lam * ends[1][0], (1 - lam) * ends[0][1] + lam * ends[1][1])
        if not m.stable_without_delay:
            return None
        worst = min(worst, m.margin)
    return (ends, worst) if np.isfinite(worst) else None


def _grid_stable(ends: list[tuple[np.ndarray, np.ndarray]], tau: float) -> bool:
    for lam in np.linspace(0.0, 1.0, 41):
        m = delay_margin((1 - lam) * ends[0][0] + lam * ends[1][0], (1 - lam) * ends[0][1] + lam * ends[1][1])
        if not any(lo <= tau < hi for lo, hi in m.stable_intervals):
            return False
    return True


def main(count: int = 200) -> None:
    rng = np.random.default_rng(20261201)
    stats: dict[tuple[str, Functional, float], int] = {}
    failed: dict[tuple[str, Functional], int] = {}
    times: dict[tuple[str, Functional], list[float]] = {}
    violations: list[str] = []
    systems = {"inertia box": 0, "segment": 0}

    def record(family: str, fn: Functional, f: float, cert: PolytopeCertificate, stable: bool) -> None:
        key = (family, fn, f)
        stats[key] = stats.get(key, 0) + int(cert.certified)
        times.setdefault((family, fn), []).append(cert.solve_time)
        if cert.status is CertificateStatus.SOLVER_FAILED:
            failed[(family, fn)] = failed.get((family, fn), 0) + 1
        if cert.certified and not stable:
            violations.append(f"{family} #{systems[family]} {fn.name} at {f} x exact: {cert.reason}")

    while systems["inertia box"] < count // 2:
        j0 = rng.uniform(1.0, 200.0, size=3)
        if np.sort(j0)[2] > np.sort(j0)[0] + np.sort(j0)[1]:
            continue  # not a rigid body (triangle inequality)
        w, zeta = rng.uniform(0.1, 3.0), rng.uniform(0.5, 2.0)
        k = pd_gains(Spacecraft(j0), zeta=zeta, omega_n=w, allow_underdamped=True).K
        poly = inertia_polytope(Spacecraft(j0), rng.uniform(0.02, 0.6))
        exact = exact_polytope_margin(poly, k, points=41)
        if not np.isfinite(exact):
            continue
        for f in FRACTIONS:
            stable = exact > f * exact  # the grid is stable exactly below its smallest margin (PD loops)
            for fn in FUNCTIONALS:
                record("inertia box", fn, f, certify_polytope(poly, k, f * exact, order=2, functional=fn), stable)
        systems["inertia box"] += 1
    while systems["segment"] < count - count // 2:
        case = _segment(rng)
        if case is None:
            continue
        ends, exact = case
        for f in FRACTIONS:
            stable = _grid_stable(ends, f * exact)
            for fn in FUNCTIONALS:
                record("segment", fn, f, certify_vertices(ends, f * exact, order=2, functional=fn), stable)
        systems["segment"] += 1

    print(
        f"| family (systems) | functional | {' | '.join(f'certified at {f} x exact' for f in FRACTIONS)} "
        "| solver failed | median time / certificate (s) |"
    )
    print("|---|---|" + "---|" * (len(FRACTIONS) + 2))
    for family, n in systems.items():
        for fn in FUNCTIONALS:
            counts = " | ".join(f"{stats.get((family, fn, f), 0)}/{n}" for f in FRACTIONS)
            med = float(np.median(times[(family, fn)]))
            print(f"| {family} ({n}) | {fn.name.lower()} | {counts} | {failed.get((family, fn), 0)} | {med:.3f} |")
    print(f"violations: {len(violations)}")
    for v in violations:
        print("  " + v)


if __name__ == "__main__":
    start = time.perf_counter()
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
    print(f"total {time.perf_counter() - start:.0f} s")
