"""The "Done when" table of issue 11, measured: the loop as flown, certified and checked exactly.

Run: python bench/flown_certificates.py [part ...] with parts among ``sampled``, ``benchmark``,
``inertia``, ``speed`` (default: all). Prints markdown tables (design/lmi.md section 7.8 quotes them).

- ``sampled``: the paper's loop at 1 kHz (tau = 0.5 s, d = 500), per axis: the exact lifted check at
  d = 500 (spectral radius), the exact largest stable d of the binding axis (J = 80) checked by dense
  eigenvalues at that d and d + 1, and the largest d certified by each input-delay criterion (Jensen,
  Wirtinger, Bessel-Legendre N = 2, 3; with the preconditioned retries) and, at d = 500, whether each
  certifies plain and with the preconditioned retries. The looped functional is for d = 0 only: its
  largest certified period against the exact one.
- ``benchmark``: the classic time-varying-delay benchmark for mu in {0.1, 0.5, 0.8} and the sampled-data
  benchmark, against the published values.
- ``inertia``: the largest relative inertia tolerance certified for the paper's K at tau = 0.5 s
  (vertex-dependent functional, N = 2 and 3) and the exact one (41-point grid per axis).
- ``speed``: the median wall time of one certify call of each kind, in this process (warm).
"""

from __future__ import annotations

import functools
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mrpctl import paper
from mrpctl.design import (
    certify_interval,
    certify_looped,
    certify_polytope,
    certify_sampled,
    delay_margin,
    inertia_polytope,
    linearized_loop,
    max_certified_delay_samples,
    max_certified_interval_delay,
    max_certified_period,
    max_certified_tolerance,
    max_looped_period,
    max_stable_period,
    max_stable_tolerance,
    sampled_stability,
    spacecraft_axes,
)
from mrpctl.design.lmi import criterion_name
from mrpctl.spacecraft import Spacecraft

H = 1e-3  # 1 kHz
D = round(paper.TAU / H)  # 500 samples


def _timed(function: Callable[[], Any]) -> tuple[Any, float]:
    start = time.perf_counter()
    value = function()
    return value, time.perf_counter() - start


def sampled_part() -> None:
    spacecraft = Spacecraft(paper.INERTIA)
    axes = spacecraft_axes(spacecraft, paper.GAIN)
    print(f"## Paper loop at 1 kHz (h = {H:g} s, tau = {paper.TAU:g} s, d = {D})\n")
    print("| axis (J) | continuous exact margin (s) | exact lifted at d = 500 | time (s) |")
    print("|---|---|---|---|")
    for index, (a, b, k) in enumerate(axes):
        margin = delay_margin(a, b @ k).margin
        exact, seconds = _timed(functools.partial(sampled_stability, a, b, k, H, delay_samples=D))
        print(
            f"| {index + 1} ({paper.INERTIA[index]:g}) | {margin:.6g} | "
            f"{'stable' if exact.stable else 'UNSTABLE'}, rho = {exact.spectral_radius:.9f} | {seconds:.2f} |"
        )
    a, b, k = axes[2]
    margin = delay_margin(a, b @ k).margin
    d_exact = int(np.floor(margin / H - 0.5))  # the continuous margin less half a sample, checked next
    below, t_below = _timed(lambda: sampled_stability(a, b, k, H, delay_samples=d_exact))
    above, t_above = _timed(lambda: sampled_stability(a, b, k, H, delay_samples=d_exact + 1))
    print(
        f"\nBinding axis 3 (J = 80): exact lifted check (dense eigenvalues) d = {d_exact}: "
        f"{'stable' if below.stable else 'UNSTABLE'} (rho = {below.spectral_radius:.9f}, {t_below:.1f} s); "
        f"d = {d_exact + 1}: {'stable' if above.stable else 'UNSTABLE'} (rho = {above.spectral_radius:.9f}, "
        f"{t_above:.1f} s)\n"
    )
    print(
        "| criterion | at d = 500 plain | at d = 500 with retries | largest certified d (axis 3) | ratio to exact d | "
        "tests | time (s) |"
    )
    print("|---|---|---|---|---|---|---|")
    for order in (0, 1, 2, 3):
        plain = certify_sampled(a, b, k, H, delay_samples=D, order=order, precondition=False)
        retried = certify_sampled(a, b, k, H, delay_samples=D, order=order)
        (d_cert, _, solves), seconds = _timed(
            functools.partial(max_certified_delay_samples, a, b, k, H, order=order, d_max=d_exact + 1)
        )
        print(
            f"| {criterion_name(order)} + RCC | {plain.status.name} | {retried.status.name} | {d_cert} | "
            f"{d_cert / d_exact:.4f} | {solves} | {seconds:.1f} |"
        )
    print("\nLooped functional (d = 0 only; periodic sampling): largest certified period per axis\n")
    print("| axis | certified h (s) | exact h (s) | ratio | certifies h = 1 ms |")
    print("|---|---|---|---|---|")
    for index, (a, b, k) in enumerate(axes):
        exact_h = max_stable_period(a, b, k)
        looped = max_looped_period(a, b, k, rtol=1e-3)
        at_1ms = certify_looped(a, b, k, H)
        print(
            f"| {index + 1} | {looped.period:.5g} | {exact_h:.5g} | {looped.period / exact_h:.4f} | "
            f"{at_1ms.status.name} |"
        )
    print()


BENCH_A = np.array([[-2.0, 0.0], [0.0, -0.9]])
BENCH_AD = np.array([[-1.0, 0.0], [-1.0, -1.0]])


def benchmark_part() -> None:
    print("## Time-varying delay benchmark (h1 = 0, rtol 1e-3): h_max (s)\n")
    print("| criterion | mu = 0 | mu = 0.1 | mu = 0.5 | mu = 0.8 | rate unknown |")
    print("|---|---|---|---|---|---|")
    for order in (0, 1, 2):
        cells = []
        for rate in (0.0, 0.1, 0.5, 0.8, None):
            result = max_certified_interval_delay(BENCH_A, BENCH_AD, rate=rate, order=order, rtol=1e-3)
            cells.append(f"{result.upper:.4f}")
        print(f"| {criterion_name(order)} + RCC | " + " | ".join(cells) + " |")
    print("\n## Sampled-data benchmark A = [[0, 1], [0, -0.1]], B = [0; 0.1], K = [-3.75, -11.5] (d = 0)\n")
    a = np.array([[0.0, 1.0], [0.0, -0.1]])
    b = np.array([[0.0], [0.1]])
    k = np.array([[-3.75, -11.5]])
    exact = max_stable_period(a, b, k)
    print("| method | h_max (s) |")
    print("|---|---|")
    print(f"| exact (lifted) | {exact:.5f} |")
    for order in (0, 1):
        sampled = max_certified_period(a, b, k, order=order, rtol=1e-3)
        print(f"| input delay, {criterion_name(order)} + RCC | {sampled.period:.5f} |")
    looped = max_looped_period(a, b, k, rtol=1e-3)
    print(f"| looped functional + Wirtinger | {looped.period:.5f} |")
    print("\n## Myshkis-Yorke: x' = -x(t - tau(t)), tau(t) in [0, h] arbitrary: stable exactly for h < 3/2\n")
    for order in (0, 1, 2):
        scalar = max_certified_interval_delay([[0.0]], [[-1.0]], rate=None, order=order, rtol=1e-3)
        print(f"- {criterion_name(order)} + RCC, rate unknown: h_max = {scalar.upper:.4f} (< 1.5)")
    print()


def inertia_part() -> None:
    spacecraft = Spacecraft(paper.INERTIA)
    print(f"## Largest inertia tolerance for the paper's K at tau = {paper.TAU:g} s (diagonal box)\n")
    print("| method | tolerance | time (s) |")
    print("|---|---|---|")
    exact, seconds = _timed(lambda: max_stable_tolerance(spacecraft, paper.GAIN, paper.TAU, rtol=1e-4))
    print(f"| exact (41-point grid per axis, worst margin > tau; rtol 1e-4) | {exact:.5f} | {seconds:.1f} |")
    for order in (2, 3):
        (tol, _), seconds = _timed(
            functools.partial(max_certified_tolerance, spacecraft, paper.GAIN, paper.TAU, order=order, rtol=1e-3)
        )
        print(
            f"| certified, vertex-dependent, {criterion_name(order)} (rtol 1e-3) | {tol:.5f} "
            f"({tol / exact:.4f} x exact) | {seconds:.1f} |"
        )
    print()


def speed_part(repeats: int = 5) -> None:
    spacecraft = Spacecraft(paper.INERTIA)
    loop = linearized_loop(spacecraft, paper.GAIN)
    axes = spacecraft_axes(spacecraft, paper.GAIN)
    a3, b3, k3 = axes[2]
    (pa, pad) = loop.axes[2]
    box = inertia_polytope(spacecraft, 0.2)
    calls: list[tuple[str, Callable[[], Any]]] = []
    for order in (0, 1, 2, 3):
        calls.append(
            (
                f"constant delay, 6x6 loop (split per axis), {criterion_name(order)}",
                functools.partial(loop.certify, paper.TAU, order=order),
            )
        )
    calls.append(
        (
            "interval [0.45, 0.501] s, rate unknown, Wirtinger, axis 3",
            lambda: certify_interval(pa, pad, 0.501, tau_min=0.45, order=1),
        )
    )
    calls.append(
        ("sampled 1 kHz d = 500, Jensen, axis 3", lambda: certify_sampled(a3, b3, k3, H, delay_samples=D, order=0))
    )
    calls.append(
        (
            "sampled 1 kHz d = 500, Wirtinger (+ retries), axis 3",
            lambda: certify_sampled(a3, b3, k3, H, delay_samples=D, order=1),
        )
    )
    calls.append(("looped functional, h = 1 ms, d = 0, axis 3", lambda: certify_looped(a3, b3, k3, H)))
    calls.append(("exact lifted check, d = 500, axis 3", lambda: sampled_stability(a3, b3, k3, H, delay_samples=D)))
    calls.append(
        (
            "inertia box +-20 %, vertex-dependent, N = 2 (3 axes x 2 vertices)",
            lambda: certify_polytope(box, paper.GAIN, paper.TAU, order=2),
        )
    )
    print(f"## Speed of one certificate (median of {repeats} warm calls, this process)\n")
    print("| call | median (s) | min (s) | result |")
    print("|---|---|---|---|")
    for name, call in calls:
        result = call()  # warm-up (imports, compiles)
        times = [_timed(call)[1] for _ in range(repeats)]
        verdict = getattr(result, "status", None)
        verdict_text = verdict.name if verdict is not None else ("stable" if result.stable else "UNSTABLE")
        print(f"| {name} | {statistics.median(times):.3f} | {min(times):.3f} | {verdict_text} |")
    print()


PARTS = {"sampled": sampled_part, "benchmark": benchmark_part, "inertia": inertia_part, "speed": speed_part}

if __name__ == "__main__":
    chosen = sys.argv[1:] or list(PARTS)
    for part in chosen:
        if part not in PARTS:
            raise SystemExit(f"unknown part {part!r}; choose among {sorted(PARTS)}")
    for part in chosen:
        start = time.perf_counter()
        PARTS[part]()
        print(f"({part}: {time.perf_counter() - start:.0f} s)\n", flush=True)
