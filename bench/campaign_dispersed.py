"""A fully dispersed flown campaign against the same campaign with shared models; prints one table.

The chunk is ``examples/campaigns/flight.toml`` (controller-side hysteresis, torque limit, a constant disturbance,
star-tracker and gyro noise, gyro bias, a jittered delay, all dispersed) with the inertia dispersed too and a
10 s horizon at 1 kHz: every run has its own noise seed, jitter seed, inertia, disturbance, u_max and δ. Measured
in this process, interleaved over ``rounds`` rounds (the machine is shared: read the ratios of each round):

* ``dispersed``: ``simulate_chunk`` of the campaign (one ``simulate_batch`` call: each lane streamed its own run's
  noise rows and newest-arrived schedule);
* ``shared``: the same chunk, sampled and its models built the same way, with run 0's sensor and delay model shared
  by every run (inertia, disturbance, u_max, δ still per run; one noise stream and one schedule per batch of W
  runs): the throughput to reach;
* ``one call per run``: each run a ``simulate_batch`` call of its own (how a campaign ran such runs before), on
  fewer runs.

The dispersed chunk is checked bit for bit against the one-call-per-run results (the replay contract). CPU time on
one thread (the least disturbed by other jobs) and wall clock on every core.

Run: ``.venv/bin/python bench/campaign_dispersed.py [runs] [rounds]`` (defaults 64 runs, 5 rounds).
"""

from __future__ import annotations

import os
import statistics
import sys
import time
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl.campaign import _task, parse_campaign, run_inputs
from mrpctl.campaign.simulation import METRICS, simulate_runs

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _host import cpu_model, vector_isa

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "campaigns" / "flight.toml"
T_FINAL = 10.0


def spec_source(runs: int) -> dict[str, Any]:
    source = tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))
    source.update(count=runs, t_final=T_FINAL)
    source["dispersions"]["inertia"] = {"axis_tolerance": 0.05}
    return source


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    spec = parse_campaign(spec_source(runs), name="dispersed")
    base = spec.base
    inputs = run_inputs(spec, 0, runs)
    per_run = [_task.run_models(spec, inputs, j) for j in range(runs)]
    K = inputs.gain_scale[:, None, None] * base.K[None]
    options = dict(t_final=base.t_final, rate=base.rate, history=base.history, substeps=base.substeps)

    def shared(count: int, workers: int) -> dict[str, np.ndarray]:
        """The chunk as a campaign whose runs share run 0's sensor and delay model: sampled and its models built
        as `simulate_chunk` does, then one sensor and one delay model for every run."""
        drawn = run_inputs(spec, 0, count)
        built = [_task.run_models(spec, drawn, j) for j in range(count)]
        first = built[0][1]
        assert first is not None
        models = [dict(one or {}, sensor=first["sensor"], delay=first["delay"]) for _, one in built]
        return simulate_runs(
            drawn.inertia, drawn.gain_scale[:, None, None] * base.K[None], drawn.x0, drawn.tau,
            [rule for rule, _ in built], flight=models, threads=workers, peak_torque=spec.peak_torque, **options,
        )  # fmt: skip

    def alone(count: int) -> dict[str, np.ndarray]:
        found = [
            simulate_runs(
                inputs.inertia[j : j + 1],
                K[j : j + 1],
                inputs.x0[j : j + 1],
                inputs.tau[j : j + 1],
                [per_run[j][0]],
                flight=[per_run[j][1]],
                threads=1,
                **options,
            )
            for j in range(count)
        ]
        return {name: np.concatenate([one[name] for one in found]) for name in METRICS}

    few = max(8, runs // 8)
    dispersed = _task.simulate_chunk(spec, 0, runs, threads=1)  # compiles the engines
    shared(runs, 1)
    before = alone(few)
    identical = all(dispersed[name][:few].tobytes() == before[name].tobytes() for name in METRICS)
    print(f"{cpu_model()}; {vector_isa()}")
    print(f"dispersed chunk bit for bit the one-call-per-run results on its first {few} runs: {identical}", flush=True)

    def timed(task: Callable[[], Any], clock: Callable[[], float]) -> float:
        start = clock()
        task()
        return clock() - start

    cases: dict[str, tuple[int, Callable[[int], Any]]] = {
        "dispersed": (runs, lambda workers: _task.simulate_chunk(spec, 0, runs, threads=workers)),
        "shared": (runs, lambda workers: shared(runs, workers)),
        "one call per run": (few, lambda workers: alone(few)),
    }
    rates: dict[tuple[str, str], list[float]] = {}
    for _ in range(rounds):
        for clock_name, clock, workers in (("cpu", time.process_time, 1), ("wall", time.perf_counter, threads)):
            for label, (count, task) in cases.items():
                if label == "one call per run" and clock_name == "wall":
                    continue
                seconds = timed(lambda task=task, workers=workers: task(workers), clock)
                rates.setdefault((clock_name, label), []).append(count / seconds)
    print()
    print(
        f"flown campaign chunk, {runs} runs of {T_FINAL:g} s at {base.rate:g} Hz, {rounds} interleaved rounds; "
        f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    print(f"{'':36s} {'runs/s best':>11s} {'median':>8s}   dispersed / shared per round: min  median  max")
    for clock_name, title in (("cpu", "CPU time, one thread"), ("wall", f"wall clock, {threads} threads")):
        print(title)
        for label in cases:
            found = rates.get((clock_name, label))
            if found is None:
                continue
            line = f"  {label:34s} {max(found):11.1f} {statistics.median(found):8.1f}"
            if label == "dispersed":
                ratio = [a / b for a, b in zip(found, rates[(clock_name, "shared")], strict=True)]
                line += f"   {min(ratio):39.2f} {statistics.median(ratio):6.2f} {max(ratio):5.2f}"
            print(line)


if __name__ == "__main__":
    main()
