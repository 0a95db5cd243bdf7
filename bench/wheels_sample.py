"""Benchmark of the wheel sample against the ideal-torque sample on the scalar engine; prints one table.

The 12U cubesat (J = diag(0.2, 0.25, 0.15) kg m², tau = 0.2 s, 100 Hz, 600 s: 60 001 samples,
``keep_every=None``, ``Hysteretic(0.1)``, a PD gain whose loop saturates the wheels for the first
tens of seconds) through :func:`mrpctl.simulate`:

* ``ideal torque``: the flight sample with no limit (the reference of the ratios' second column),
* ``ideal torque, 5 mN m``: the flight sample with a per-axis limit ``ActuatorModel(5e-3, mode=CLIP)``
  (the reference of the ratios: the loop the wheels replace),
* ``3 wheels``: three orthogonal wheels of 5 mN m and 20 mN m s at 6 000 rpm,
* ``4-wheel pyramid``: the same wheels in a pyramid,
* ``pyramid, friction + null + gyro``: with viscous and Coulomb friction, null-space momentum
  management and the gyroscopic term in the law.

All in this process, interleaved round by round, each timed by the process's CPU time; each entry
is the minimum and the median over the rounds (ns per sample), the ratio to the 5 mN m ideal-torque
sample's minimum, and the minimum, median and maximum over the rounds of the ratio to that sample's
time in the same round (the two were timed next to each other, so a round's ratio sees the same load).
The engines are compiled (or loaded from the cache) before the rounds. A second table: the same samples
on the lane engine (``simulate_batch`` of 32 runs, metrics only, one thread: W = 8 runs per C call), ns
per sample and run.

Run: ``.venv/bin/python bench/wheels_sample.py [rounds] [lane rounds]`` (default 9 and rounds // 3).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections.abc import Callable

import numpy as np
from _host import cpu_model, vector_isa

from mrpctl import simulate, simulate_batch
from mrpctl.engines.isa import host_isa_flags, native_isa_flags
from mrpctl.flight import ActuatorModel, Hysteretic, Saturation
from mrpctl.model import gain_from_pd, state
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

SPACECRAFT = Spacecraft(np.diag([0.2, 0.25, 0.15]))
TAU = 0.2
RATE = 100.0
T_FINAL = 600.0
N = 60_001
SPEED_LIMIT = 6000.0 * 2.0 * np.pi / 60.0  # rad/s
SPIN_INERTIA = 0.020 / SPEED_LIMIT  # 20 mN m s at 6 000 rpm
TORQUE_LIMIT = 5e-3
K = gain_from_pd(SPACECRAFT, -0.01 * np.ones(3), -0.2 * np.ones(3))
X0 = state([0.4, -0.3, 0.2], [0.03, -0.02, 0.01])
RULE = Hysteretic(0.1)

WHEELS = {
    "3 wheels": WheelCluster.orthogonal(SPIN_INERTIA, TORQUE_LIMIT, SPEED_LIMIT),
    "4-wheel pyramid": WheelCluster.pyramid(SPIN_INERTIA, TORQUE_LIMIT, SPEED_LIMIT),
    "pyramid, friction + null + gyro": WheelCluster.pyramid(
        SPIN_INERTIA,
        TORQUE_LIMIT,
        SPEED_LIMIT,
        viscous=1e-8,
        coulomb=1e-6,
        null_gain=0.01,
        bias_speeds=[100.0, -100.0, 100.0, -100.0],
        gyroscopic=True,
    ),
}


_SPREAD = "round ratios x 5 mN m: min / median / max"


def _spread(values: list[float], reference: list[float]) -> str:
    """The minimum, median and maximum over the rounds of each round's time over the reference's in that round."""
    ratios = [value / base for value, base in zip(values, reference, strict=True)]
    return f"{min(ratios):.2f} / {statistics.median(ratios):.2f} / {max(ratios):.2f}"


def _load() -> str:
    return ", ".join(f"{value:.1f}" for value in os.getloadavg())


def _case(**options: object) -> Callable[[], object]:
    def call() -> object:
        return simulate(SPACECRAFT, K, X0, tau=TAU, rule=RULE, t_final=T_FINAL, rate=RATE, keep_every=None, **options)  # type: ignore[arg-type]

    return call


def _batch(**options: object) -> Callable[[], object]:
    rng = np.random.default_rng(5)
    x0 = state(rng.uniform(-0.4, 0.4, (LANE_RUNS, 3)), rng.uniform(-0.03, 0.03, (LANE_RUNS, 3)))

    def call() -> object:
        return simulate_batch(SPACECRAFT, K, x0, tau=TAU, rule=RULE, t_final=T_FINAL, rate=RATE, threads=1, **options)  # type: ignore[arg-type]

    return call


LANE_RUNS = 32


def main() -> int:
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 9
    cases: dict[str, Callable[[], object]] = {
        "ideal torque": _case(),
        "ideal torque, 5 mN m": _case(actuator=ActuatorModel(TORQUE_LIMIT, mode=Saturation.CLIP)),
    }
    for label, wheels in WHEELS.items():
        cases[label] = _case(wheels=wheels)
    for call in cases.values():  # compile or load every engine first
        call()
    times: dict[str, list[float]] = {label: [] for label in cases}
    for _ in range(rounds):
        for label, call in cases.items():
            start = time.process_time()
            call()
            times[label].append(time.process_time() - start)
    base = min(times["ideal torque, 5 mN m"])
    free = min(times["ideal torque"])
    print(f"CPU: {cpu_model()}; {os.cpu_count()} CPUs, load average (1, 5, 15 min) {_load()}")
    print(vector_isa())
    host = [flag for flag in host_isa_flags() if flag.startswith(("-march", "-mtune", "-mavx2", "-mfma"))]
    native = [flag for flag in native_isa_flags() if flag.startswith(("-march", "-mtune"))]
    print(f"ISA flags of the compile: host {' '.join(host) or '(none)'}; native {' '.join(native) or '(none)'}")
    print(f"cubesat, tau = {TAU} s, {RATE:g} Hz, {N} samples, Hysteretic(0.1), best of {rounds} interleaved rounds")
    print(f"{'sample':34s} {'min ns':>8s} {'median ns':>10s} {'x 5 mN m':>9s} {'x ideal':>8s}  {_SPREAD}")
    for label, values in times.items():
        low = min(values)
        print(
            f"{label:34s} {low / N * 1e9:8.1f} {statistics.median(values) / N * 1e9:10.1f} "
            f"{low / base:9.2f} {low / free:8.2f}  {_spread(values, times['ideal torque, 5 mN m'])}"
        )
    batches: dict[str, Callable[[], object]] = {
        "ideal torque": _batch(),
        "ideal torque, 5 mN m": _batch(actuator=ActuatorModel(TORQUE_LIMIT, mode=Saturation.CLIP)),
    }
    for label, wheels in WHEELS.items():
        batches[label] = _batch(wheels=wheels)
    for call in batches.values():
        call()
    lane_times: dict[str, list[float]] = {label: [] for label in batches}
    lane_rounds = max(1, rounds // 3) if len(sys.argv) <= 2 else int(sys.argv[2])
    for _ in range(lane_rounds):
        for label, call in batches.items():
            start = time.process_time()
            call()
            lane_times[label].append(time.process_time() - start)
    base = min(lane_times["ideal torque, 5 mN m"])
    free = min(lane_times["ideal torque"])
    print(f"lane engine: simulate_batch of {LANE_RUNS} runs, metrics only, one thread, best of {lane_rounds}")
    print(f"{'sample':34s} {'ns/run-sample':>13s} {'x 5 mN m':>9s} {'x ideal':>8s}  {_SPREAD}")
    for label, values in lane_times.items():
        low = min(values)
        print(
            f"{label:34s} {low / (N * LANE_RUNS) * 1e9:13.1f} {low / base:9.2f} {low / free:8.2f}  "
            f"{_spread(values, lane_times['ideal torque, 5 mN m'])}"
        )
    print(f"load average after the rounds: {_load()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
