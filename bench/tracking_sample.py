"""The tracking sample's cost against the regulation sample, in the same process.

The paper case (the paper's spacecraft, gain and initial state, τ = 0.5 s, 1 kHz, 60 s: 60 001 samples,
``keep_every=None``, ``rule=Hysteretic(0.0)``, compiled scalar engine) run through
[`mrpctl.simulate`][mrpctl.simulation.simulate] as

* ``regulation``: no reference (the flight sample of before: the reference of the ratios);
* ``tracking``: a nadir-like reference (0.0011 rad/s about the orbit normal), no feedforward;
* ``tracking + feedforward``: the same with the feedforward terms (the goal: <= 1.3 x regulation);
* ``tracking, current time``: the same with ``ErrorTime.CURRENT`` (the same sample; only the rows differ);

the variants interleaved round by round, each timed by the process's CPU time (``time.process_time``), min and
median over the rounds; the ratio is to the regulation run's minimum. The reference rows are built once, before
the timing (a (60 001, 9) array read through views, sliced per C call).

Run: ``PYTHONPATH=. .venv/bin/python bench/tracking_sample.py [rounds]`` (default 9).
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time

import numpy as np

from mrpctl import paper, simulate
from mrpctl.engines import isa
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


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


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
    for _ in range(rounds):
        for name, options in variants.items():
            start = time.process_time()
            simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, **common, **options)
            times[name].append(time.process_time() - start)
    flags = isa.host_isa_flags()
    vector = [f for f in flags if f.startswith(("-march", "-mavx", "-msse", "-mfma")) and "-mno-" not in f]
    print(f"CPU: {_cpu_name()}; vector ISA of the compile cache: {' '.join(vector) or 'none'}")
    print(
        f"paper case, {T_FINAL:g} s at {RATE:g} Hz ({N} samples), keep_every=None, Hysteretic(0.0); process CPU "
        f"time, {rounds} interleaved rounds; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    base = min(times["regulation"])
    print(f"{'variant':26s} {'min (ms)':>9s} {'median (ms)':>12s} {'x regulation':>13s} {'ns/sample':>10s}")
    ratios = {}
    for name, values in times.items():
        ratios[name] = min(values) / base
        print(
            f"{name:26s} {1e3 * min(values):9.2f} {1e3 * statistics.median(values):12.2f} {ratios[name]:13.3f} "
            f"{1e9 * min(values) / N:10.1f}"
        )
    verdict = "met" if ratios["tracking + feedforward"] <= 1.3 else "NOT met"
    print(f"goal: tracking + feedforward <= 1.3 x regulation: {verdict} ({ratios['tracking + feedforward']:.3f})")
    return ratios


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 9)
