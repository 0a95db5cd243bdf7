"""Benchmark of the flight loop's options on the paper case (issue 10's bench goal); prints one table.

The 60 s paper case (the paper's spacecraft, gain and initial state, tau = 0.5 s, 1 kHz,
60 001 samples, ``keep_every=None``) through :func:`mrpctl.simulate`:

* ``plain``: the paper's loop with ``OnCurrent`` (the reference of the ratios),
* ``Hysteretic(0)``: the flight sample with no option,
* each option alone with the rule ``Hysteretic.from_alpha(1.2)``: torque limits, a constant
  disturbance, sensor noise (0.01 rad, 1e-4 rad/s, a gyro bias), a 0.4–0.5 s jitter,
* ``all``: every option at once;

plus, for the noise, the cost of generating it alone (``SensorModel.noise(0, n)``) and, for the
jitter, of the newest-arrived schedule (``newest_arrived_slice``), so that the table says where
the time goes. All in this process, the variants interleaved round by round, each timed by the
process's CPU time (``time.process_time``: the least disturbed by other jobs on a shared
machine); each entry is the minimum and the median over the rounds, and the ratio is to the
plain run's minimum of the same process.

Run: ``.venv/bin/python bench/flight.py [rounds]`` (default 9 rounds; about half a minute).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections.abc import Callable

from mrpctl import OnCurrent, paper, simulate
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, SensorModel, newest_arrived_slice

T_FINAL = 60.0
TAU = 0.5
RATE = 1000.0
N = 60_001
SENSOR = SensorModel(attitude_noise=0.01, rate_noise=1e-4, gyro_bias=[1e-4, -2e-4, 5e-5], seed=1)
ACTUATOR = ActuatorModel([60.0, 60.0, 60.0], norm_max=80.0)
DISTURBANCE = Disturbance([1e-3, -2e-3, 5e-4])
JITTER = DelayModel.jitter(0.4, 0.5, seed=2)
RULE = Hysteretic.from_alpha(1.2)


def _run(rule: object = RULE, **options: object) -> Callable[[], object]:
    def call() -> object:
        return simulate(
            paper.SPACECRAFT,
            paper.GAIN,
            paper.INITIAL_STATE,
            tau=TAU,
            rule=rule,  # type: ignore[arg-type]
            t_final=T_FINAL,
            rate=RATE,
            keep_every=None,
            **options,  # type: ignore[arg-type]
        )

    return call


def variants() -> dict[str, Callable[[], object]]:
    """The measured calls, in table order."""
    return {
        "plain (OnCurrent)": _run(OnCurrent()),
        "Hysteretic(0), no option": _run(Hysteretic(0.0)),
        "alpha 1.2, no option": _run(),
        "alpha 1.2 + actuator limits": _run(actuator=ACTUATOR),
        "alpha 1.2 + disturbance": _run(disturbance=DISTURBANCE),
        "alpha 1.2 + sensor noise": _run(sensor=SENSOR),
        "alpha 1.2 + jitter 0.4-0.5 s": _run(delay=JITTER),
        "all options": _run(actuator=ACTUATOR, disturbance=DISTURBANCE, sensor=SENSOR, delay=JITTER),
        "  (noise generation alone)": lambda: SENSOR.noise(0, N),
        "  (jitter schedule alone)": lambda: newest_arrived_slice(JITTER, RATE, 500, 0, N, -501),
    }


def main() -> None:
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 9
    measures = variants()
    for call in measures.values():  # compile (or load) every engine first
        call()
    times: dict[str, list[float]] = {label: [] for label in measures}
    for _ in range(rounds):
        for label, call in measures.items():
            start = time.process_time()
            call()
            times[label].append(time.process_time() - start)
    plain = min(times["plain (OnCurrent)"])
    print(
        f"paper case, {T_FINAL:g} s at {RATE:g} Hz ({N} samples), keep_every=None; process CPU time, "
        f"{rounds} interleaved rounds; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    print(f"{'variant':34s} {'min ms':>8s} {'median ms':>10s} {'x plain':>8s}")
    for label, values in times.items():
        best = min(values)
        print(f"{label:34s} {1e3 * best:8.2f} {1e3 * statistics.median(values):10.2f} {best / plain:8.2f}")


if __name__ == "__main__":
    main()
