"""The tracking sample's cost against the regulation sample, in the same process.

The paper case (the paper's spacecraft, gain and initial state, τ = 0.5 s, 1 kHz, 60 s: 60 001 samples,
``keep_every=None``, ``rule=Hysteretic(0.0)``, compiled scalar engine) run through
[`mrpctl.simulate`][mrpctl.simulation.simulate] as

* ``regulation``: no reference (the flight sample of before: the reference of the ratios);
* ``tracking``: a nadir-like reference (0.0011 rad/s about the orbit normal), no feedforward;
* ``tracking + feedforward``: the same with the feedforward terms (the goal: <= 1.3 x regulation);
* ``tracking, current time``: the same with ``ErrorTime.CURRENT`` (the same sample; only the rows differ);

the variants interleaved round by round, each timed by the process's CPU time (``time.process_time``), min and
median over the rounds; the ratio is to the regulation run's minimum, and the per-round ratios (each variant's
time over the regulation run's of the same round) are given as min / median / max, with the load average before
and after the rounds (the host is shared: the per-round ratios show how much of a spread is the host's). The
reference rows are built once, before the timing (a (60 001, 9) array read through views, sliced per C call).

Run: ``PYTHONPATH=. .venv/bin/python bench/tracking_sample.py [rounds]`` (default 9).
"""

from __future__ import annotations

import os
import statistics
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _host

from mrpctl import paper, simulate
from mrpctl.flight import ErrorTime, Hysteretic

T_FINAL = 60.0
TAU = 0.5
RATE = 1000.0
N = 60_001
ORBIT_RATE = 0.0011  # rad/s, a 500 km circular orbit


def nadir_rows(n: int, rate: float, orbit_rate: float) -> np.ndarray:
    """A frame turning at the orbit rate about the orbit normal (here the inertial z axis)."""
    angle = orbit_rate * np.arange(n) / rate
    rows = np.zeros((n, 9))
    rows[:, 2] = np.tan(angle / 4.0)
    rows[:, 5] = orbit_rate
    return rows


def main(rounds: int = 9) -> dict[str, float]:
    rows = nadir_rows(N, RATE, ORBIT_RATE)
    common = dict(tau=TAU, rule=Hysteretic(0.0), t_final=T_FINAL, rate=RATE, keep_every=None)
    variants = {
        "regulation": {},
        "tracking": {"reference": rows},
        "tracking + feedforward": {"reference": rows, "feedforward": True},
        "tracking, current time": {"reference": rows, "error_time": ErrorTime.CURRENT},
    }
    for options in variants.values():  # compile and load every engine before the timing
        simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common, **options)
    times: dict[str, list[float]] = {name: [] for name in variants}
    load_before = os.getloadavg()[0]
    for _ in range(rounds):
        for name, options in variants.items():
            start = time.process_time()
            simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common, **options)
            times[name].append(time.process_time() - start)
    load_after = os.getloadavg()[0]
    print(f"CPU: {_host.cpu_model()}; {_host.vector_isa()}")
    print(
        f"paper case, {T_FINAL:g} s at {RATE:g} Hz ({N} samples), keep_every=None, Hysteretic(0.0); process CPU "
        f"time, {rounds} interleaved rounds; load average {load_before:.1f} before, {load_after:.1f} after, on "
        f"{os.cpu_count()} CPUs"
    )
    base = min(times["regulation"])
    print(
        f"{'variant':26s} {'min (ms)':>9s} {'median (ms)':>12s} {'ns/sample':>10s} {'x regulation':>13s} "
        f"{'per round min / median / max':>29s}"
    )
    ratios = {}
    for name, values in times.items():
        ratios[name] = min(values) / base
        per_round = [value / reference for value, reference in zip(values, times["regulation"], strict=True)]
        spread = f"{min(per_round):.3f} / {statistics.median(per_round):.3f} / {max(per_round):.3f}"
        print(
            f"{name:26s} {1e3 * min(values):9.2f} {1e3 * statistics.median(values):12.2f} "
            f"{1e9 * min(values) / N:10.1f} {ratios[name]:13.3f} {spread:>29s}"
        )
    verdict = "met" if ratios["tracking + feedforward"] <= 1.3 else "NOT met"
    print(f"goal: tracking + feedforward <= 1.3 x regulation: {verdict} ({ratios['tracking + feedforward']:.3f})")
    return ratios


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 9)
