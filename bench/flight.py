"""Benchmark of the flight loop's options on the paper case (issue 10's bench goal); prints one table.

The 60 s paper case (the paper's spacecraft, gain and initial state, tau = 0.5 s, 1 kHz,
60 001 samples, ``keep_every=None``) through :func:`mrpctl.simulate`:

* ``plain``: the paper's loop with ``OnCurrent`` (the reference of the ratios),
* ``Hysteretic(0)``: the flight sample with no option,
* each option alone with the rule ``Hysteretic.from_alpha(1.2)``: torque limits, a constant
  disturbance, sensor noise (0.01 rad, 1e-4 rad/s, a gyro bias), a 0.4–0.5 s jitter,
* ``all``: every option at once;

the sensor in parts (``SENSOR_PARTS``: the gyro bias alone, the rate noise alone, the attitude noise alone),
plus the NumPy side of the streams alone: the noise (``SensorModel.noise(0, n)``, the NumPy
mirror of ``_noise.c`` that the virtual machine and the reference loop use; the scalar engine
draws the noise in C, the lane engine gets C-drawn rows) and the newest-arrived schedule of a
delay sequence (``newest_arrived_slice``; the scalar engine schedules seeded jitter in C), so
that the table says where the time goes. All in this process, the variants interleaved round by
round, each timed by the process's CPU time (``time.process_time``: the least disturbed by other jobs on a shared
machine); each entry is the minimum and the median over the rounds, and the ratio is to the
plain run's minimum of the same process.

A second table: ``simulate_batch`` of 32 perturbations of the paper case, metrics only, with every
option and with no option (an ideal sensor, no limits, no disturbance: the flight sample's
cheapest structure), on the lane engine (the default: W runs per C call, the noise and the
jitter schedule generated once per slice for the W lanes) and on the scalar engine
(``_batch._LANES = False``: one run per C call, the noise per run), runs/s in CPU time on one
thread, min over the rounds (``bench/flight.py batch [rounds]``: this table alone, default 3).
Measured (design/flight.md, phase 7; three pairs of ``batch 3``, before = the commit before the
lane engine's specialisation by structure, run alternately on the same shared 2-core machine):

| batch | before: lanes, scalar (runs/s) | after: lanes, scalar (runs/s) |
|---|---|---|
| every option | 176-214, 48-57 | 193-227, 49-64 |
| no option | 224-257, 91-113 | 394-417, 82-102 |

(every option runs the full sample before and after: its change is the machine's noise; with no
option the lanes run the ideal / unlimited / free sample: 1.7 x the runs/s, 4-5 x the scalar engine.)

Run: ``.venv/bin/python bench/flight.py [rounds]`` (default 9 rounds; about a minute);
``bench/flight.py hash [-v]`` prints the SHA-256 of 75 flight runs (:func:`flight_hash`).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mrpctl import OnCurrent, paper, simulate, simulate_batch
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, SensorModel, newest_arrived_slice
from mrpctl.simulation import _batch, _simulate

T_FINAL = 60.0
TAU = 0.5
RATE = 1000.0
N = 60_001
SENSOR = SensorModel(attitude_noise=0.01, rate_noise=1e-4, gyro_bias=[1e-4, -2e-4, 5e-5], seed=1)
ACTUATOR = ActuatorModel([60.0, 60.0, 60.0], norm_max=80.0)
DISTURBANCE = Disturbance([1e-3, -2e-3, 5e-4])
JITTER = DelayModel.jitter(0.4, 0.5, seed=2)
RULE = Hysteretic.from_alpha(1.2)


_SPECIALISED = _simulate.flight_structure


def _full_structure(options: object, sensor: object) -> dict[str, bool]:
    """The unspecialised flight sample (every port and expression), as before the specialisation."""
    return {"sensor": True, "limited": True, "disturbed": True}


def _run(rule: object = RULE, full: bool = False, **options: Any) -> Callable[[], object]:
    def call() -> object:
        _simulate.flight_structure = _full_structure if full else _SPECIALISED
        try:
            return _simulate_once(rule, options)
        finally:
            _simulate.flight_structure = _SPECIALISED

    return call


def _simulate_once(rule: object, options: dict[str, object]) -> object:
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


FLIGHT: dict[str, tuple[object, dict[str, Any]]] = {
    "Hysteretic(0), no option": (Hysteretic(0.0), {}),
    "alpha 1.2, no option": (RULE, {}),
    "alpha 1.2 + actuator limits": (RULE, {"actuator": ACTUATOR}),
    "alpha 1.2 + disturbance": (RULE, {"disturbance": DISTURBANCE}),
    "alpha 1.2 + sensor noise": (RULE, {"sensor": SENSOR}),
    "alpha 1.2 + jitter 0.4-0.5 s": (RULE, {"delay": JITTER}),
    "all options": (RULE, {"actuator": ACTUATOR, "disturbance": DISTURBANCE, "sensor": SENSOR, "delay": JITTER}),
}

#: The sensor of SENSOR in parts (each with the rule RULE, no other option): the gyro bias alone (the sensor's
#: structure, the composition with σ(0) = 0, no random numbers), the rate noise alone (three normals a sample),
#: the attitude noise alone (three normals and σ(θ) a sample).
SENSOR_PARTS: dict[str, SensorModel] = {
    "  sensor part: gyro bias only": SensorModel(gyro_bias=[1e-4, -2e-4, 5e-5], seed=1),
    "  sensor part: rate noise only": SensorModel(rate_noise=1e-4, seed=1),
    "  sensor part: attitude noise only": SensorModel(attitude_noise=0.01, seed=1),
}


def variants() -> dict[str, Callable[[], object]]:
    """The measured calls, in table order; each flight variant also with the full sample ("[full]", A/B)."""
    calls: dict[str, Callable[[], object]] = {"plain (OnCurrent)": _run(OnCurrent())}
    for label, (rule, options) in FLIGHT.items():
        calls[label] = _run(rule, **options)
        calls[label + " [full]"] = _run(rule, full=True, **options)
    for label, sensor in SENSOR_PARTS.items():  # where the sensor's time goes (design/flight.md, phase 9)
        calls[label] = _run(RULE, sensor=sensor)
    calls["  (noise alone, NumPy mirror)"] = lambda: SENSOR.noise(0, N)
    calls["  (jitter schedule alone, NumPy)"] = lambda: newest_arrived_slice(JITTER, RATE, 500, 0, N, -501)
    return calls


def flight_hash(verbose: bool = False) -> str:
    """SHA-256 over the result arrays of 75 flight runs of every structure (``bench/flight.py hash [-v]``).

    Every actuator (none, SCALE, CLIP) x disturbance (none, constant, zero) x sensor (none, noisy,
    bias only, ideal) for two rules, two jitter runs, a full inertia and three ``simulate_batch``
    calls; the bytes (sign of zero included) of t, σ, ω, u, the switch times and the flight summaries.
    It must not move when the flight sample is reorganised (``2257a7a2…2457f9`` from phase 2 to 4, with
    NumPy's Philox noise; ``eed1013f…d675dd900f`` from phase 5, the noise of ``_noise.c``, to 7). It is
    ``7fb55ddd…a843baca57`` since phase 8a (design/flight.md): the sensor's rotation without tan changed the
    last bits of the runs with attitude noise (1, 5, …, 69 and 72 of ``hash -v``, and the noisy batch) only.
    """
    import hashlib

    from mrpctl.flight import Saturation
    from mrpctl.spacecraft import Spacecraft

    general = Spacecraft(np.array([[140.0, 4.0, -2.0], [4.0, 100.0, 3.0], [-2.0, 3.0, 80.0]]))
    x0 = np.array(paper.INITIAL_STATE, dtype=float)
    scale = ActuatorModel([20.0, 25.0, 30.0], norm_max=35.0)
    clip = ActuatorModel([20.0, 25.0, 30.0], norm_max=35.0, mode=Saturation.CLIP)
    torque = Disturbance([1e-2, -2e-2, 5e-3])
    noisy = SensorModel(attitude_noise=0.01, rate_noise=1e-4, seed=3)
    jitter = DelayModel.jitter(0.4, 0.5, seed=2)
    cases: list[dict[str, object]] = []
    for rule in (Hysteretic(0.0), Hysteretic.from_alpha(1.2)):
        for actuator in (None, scale, clip):
            for disturbance in (None, torque, Disturbance([0.0, 0.0, 0.0])):
                for sensor in (None, noisy, SensorModel(gyro_bias=[1e-4, -2e-4, 5e-5]), SensorModel()):
                    cases.append(dict(rule=rule, actuator=actuator, disturbance=disturbance, sensor=sensor))
    cases.append(dict(rule=Hysteretic(0.05), actuator=scale, sensor=noisy, delay=jitter))
    cases.append(dict(rule=Hysteretic(0.05), delay=jitter))
    digest = hashlib.sha256()
    for i, case in enumerate(cases):
        run: Any = simulate(paper.SPACECRAFT, paper.GAIN, x0, tau=0.5, rate=200.0, t_final=6.0, **case)  # type: ignore[arg-type]
        part = hashlib.sha256()
        for array in (
            run.t,
            run.sigma,
            run.omega,
            run.u,
            np.asarray(run.switch_times, float),
            np.asarray(run.peak_command, float),
            np.array([run.saturated_fraction], float),
        ):
            part.update(np.ascontiguousarray(array).tobytes())
        digest.update(part.digest())
        if verbose:
            print(i, part.hexdigest()[:16])
    run = simulate(
        general, paper.GAIN, x0, tau=0.02, rate=200.0, t_final=4.0, keep_every=3, rule=Hysteretic(0.1), actuator=scale
    )
    digest.update(np.ascontiguousarray(run.sigma).tobytes())
    digest.update(np.ascontiguousarray(run.u).tobytes())
    states = x0 + 0.01 * np.random.default_rng(5).standard_normal((12, 6))
    for options in ({}, {"actuator": scale, "disturbance": torque}, {"sensor": noisy}):
        batch: Any = simulate_batch(
            paper.SPACECRAFT,
            paper.GAIN,
            states,
            tau=0.5,
            rate=200.0,
            t_final=6.0,
            rule=Hysteretic(0.05),
            **options,
        )
        for name in ("settling_time", "switch_count", "max_sigma", "peak_torque"):
            digest.update(np.ascontiguousarray(np.asarray(getattr(batch, name), float)).tobytes())
    return digest.hexdigest()


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "hash":
        print(flight_hash("-v" in sys.argv))
        return
    if len(sys.argv) > 1 and sys.argv[1] == "batch":
        batch_table(int(sys.argv[2]) if len(sys.argv) > 2 else 3)
        return
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
    print("[full]: the same run with the unspecialised flight sample (every port and expression), A/B")
    print(f"{'variant':41s} {'min ms':>8s} {'median ms':>10s} {'x plain':>8s}")
    for label, values in times.items():
        best = min(values)
        print(f"{label:41s} {1e3 * best:8.2f} {1e3 * statistics.median(values):10.2f} {best / plain:8.2f}")
    batch_table(max(3, rounds // 3))


BATCH_OPTIONS: dict[str, dict[str, Any]] = {
    "every option": {"actuator": ACTUATOR, "disturbance": DISTURBANCE, "sensor": SENSOR, "delay": JITTER},
    "no option": {},
}


def batch_table(rounds: int, runs: int = 32) -> None:
    """simulate_batch with every option and with none: the lane engine against the scalar engine, CPU time,
    one thread, min over ``rounds`` (the four calls interleaved round by round)."""
    rng = np.random.default_rng(3)
    x0 = np.array(paper.INITIAL_STATE) + np.hstack((rng.normal(0, 0.01, (runs, 3)), rng.normal(0, 0.005, (runs, 3))))

    def batch(lanes: bool, options: dict[str, Any]) -> object:
        _batch._LANES = lanes
        try:
            return simulate_batch(
                paper.SPACECRAFT,
                paper.GAIN,
                x0,
                tau=TAU,
                rule=RULE,
                t_final=T_FINAL,
                rate=RATE,
                threads=1,
                **options,
            )
        finally:
            _batch._LANES = True

    engines = (("lane engine", True), ("scalar engine", False))
    cases = [(case, label, lanes) for case in BATCH_OPTIONS for label, lanes in engines]
    best = {(case, label): np.inf for case, label, _ in cases}
    results = {}
    for case, _, lanes in cases:  # compile (or load) every engine first
        batch(lanes, BATCH_OPTIONS[case])
    for _ in range(rounds):
        for case, label, lanes in cases:
            start = time.process_time()
            results[case, label] = batch(lanes, BATCH_OPTIONS[case])
            best[case, label] = min(best[case, label], time.process_time() - start)
    print()
    print(f"simulate_batch, {runs} paper-case perturbations, metrics only, 1 thread, CPU time, min of {rounds}")
    for case in BATCH_OPTIONS:
        same = all(
            np.array_equal(
                np.asarray(getattr(results[case, "lane engine"], name)),
                np.asarray(getattr(results[case, "scalar engine"], name)),
                equal_nan=True,
            )
            for name in ("switch_count", "max_sigma", "peak_torque", "saturated_fraction", "peak_command")
        )
        lane_time = best[case, "lane engine"]
        for label, _ in engines:
            seconds = best[case, label]
            ratio = seconds / lane_time
            print(f"{case:13s} {label:14s} {runs / seconds:8.1f} runs/s {ratio:8.2f} x the lane engine's time")
        print(f"{case:13s} lane engine = scalar engine on every metric: {same}")


if __name__ == "__main__":
    main()
