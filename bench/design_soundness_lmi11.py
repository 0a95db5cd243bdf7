"""Soundness of every interval and sampled-data criterion on 200 seeded random systems (issue 11).

Run: python bench/design_soundness_lmi11.py [count [part parts [order ...]]]. With part/parts, only the systems
whose index is part mod parts are checked (run the parts in parallel and add the tables); the orders default to
0 1 2 (the looped criterion, which has no order, runs when 0 is among them). For each random 2x2
system it tries each criterion where a sound one must fail, and counts a violation whenever it certifies
there:

- interval (orders 0, 1, 2; rate 0, |rate| <= 0.3 or unknown, cycling): tau(t) in [0, 1.01 x the exact
  constant-delay margin] (every constant delay in the interval must be stable);
- sampled input-delay (orders 0, 1, 2; d = 0 and d = 1) and looped (d = 0): the sampling period 1.02 x
  the first exactly unstable one (lifted spectral radius > 1, checked at that period).

It also counts, on every 4th system, how often each certifies well inside the exact bound (0.3 x margin,
0.5 x / 0.9 x the period), so that "no violation" is not vacuous. Prints a markdown table.
"""

from __future__ import annotations

import sys
import time
from collections import defaultdict

import numpy as np

from mrpctl.design import delay_margin
from mrpctl.design.interval import certify_interval
from mrpctl.design.looped import certify_looped
from mrpctl.design.sampled import certify_sampled, max_stable_period, sampled_stability


def _table(tested: dict[str, int], violations: dict[str, int], power: dict[str, int], tried: dict[str, int]) -> str:
    lines = [
        "| criterion | tested where it must fail | violations | certified well inside (fraction) |",
        "|---|---|---|---|",
    ]
    for name in sorted(tested):
        inside = "0.3 x margin" if name.startswith("interval") else ("0.9 x h" if "looped" in name else "0.5 x h")
        lines.append(f"| {name} | {tested[name]} | {violations[name]} | {power[name]}/{tried[name]} at {inside} |")
    return "\n".join(lines)


def main(count: int = 200, part: int = 0, parts: int = 1, *orders: int) -> None:
    orders = orders or (0, 1, 2)
    rng = np.random.default_rng(20261201)
    tested: dict[str, int] = defaultdict(int)
    violations: dict[str, int] = defaultdict(int)
    power: dict[str, int] = defaultdict(int)
    power_tried: dict[str, int] = defaultdict(int)
    start = time.perf_counter()
    checked = 0
    while checked < count:
        a = rng.normal(size=(2, 2))
        a_d = rng.normal(size=(2, 2))
        b = rng.normal(size=(2, 1))
        k = rng.normal(size=(1, 2))
        exact = delay_margin(a, a_d)
        ex0 = max_stable_period(a, b, k, period_limit=20.0, grid=200)
        ex1 = max_stable_period(a, b, k, delay_samples=1, period_limit=20.0, grid=200)
        if not (exact.stable_without_delay and np.isfinite(exact.margin) and 0 < ex0 < 20.0 and 0 < ex1 < 20.0):
            continue
        index = checked
        checked += 1
        if index % parts != part:
            continue
        rate = (0.0, 0.3, None)[index % 3]
        rate_name = ("rate 0", "rate in [-0.3, 0.3]", "rate unknown")[index % 3]
        for order in orders:
            name = f"interval N={order}, {rate_name}"
            tested[name] += 1
            violations[name] += certify_interval(a, a_d, 1.01 * exact.margin, rate=rate, order=order).certified
            if index % 4 == 0:
                power_tried[name] += 1
                power[name] += certify_interval(a, a_d, 0.3 * exact.margin, rate=rate, order=order).certified
        for d, ex in ((0, ex0), (1, ex1)):
            h_bad = 1.02 * ex
            if sampled_stability(a, b, k, h_bad, delay_samples=d).stable:
                continue  # a stable window past the first unstable period: not a test point
            for order in orders:
                name = f"sampled input-delay N={order}, d={d}"
                tested[name] += 1
                violations[name] += certify_sampled(a, b, k, h_bad, delay_samples=d, order=order).certified
                if index % 4 == 0:
                    power_tried[name] += 1
                    power[name] += certify_sampled(a, b, k, 0.5 * ex, delay_samples=d, order=order).certified
            if d == 0 and 0 in orders:
                name = "looped + Wirtinger, d=0"
                tested[name] += 1
                violations[name] += certify_looped(a, b, k, h_bad).certified
                if index % 4 == 0:
                    power_tried[name] += 1
                    power[name] += certify_looped(a, b, k, 0.9 * ex).certified
        done = index // parts + 1
        if done % 10 == 0:
            elapsed = time.perf_counter() - start
            print(f"after {done} systems of part {part}/{parts} ({elapsed:.0f} s):", file=sys.stderr, flush=True)
            print(_table(tested, violations, power, power_tried), file=sys.stderr, flush=True)
    print(f"{checked} random systems (seed 20261201, part {part} of {parts}), {time.perf_counter() - start:.0f} s\n")
    print(_table(tested, violations, power, power_tried))


if __name__ == "__main__":
    args = [int(v) for v in sys.argv[1:]]
    main(*args) if args else main()
