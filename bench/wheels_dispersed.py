"""A dispersed campaign on reaction wheels: the lane engine with own streams against the scalar engine; one table.

The chunk is ``examples/campaigns/wheels/cubesat.toml`` (the 12U cubesat on three orthogonal wheels, 50 Hz) flown
with a sensor and a jittered delay over its 120 s: every run has its own noise seed, jitter seed, gyro bias, constant
disturbance, δ, attitude and rate. Measured in this process, interleaved over ``rounds`` rounds (the machine is
shared: read the ratios of each round), CPU time on one thread:

* ``lanes, own streams``: ``simulate_chunk`` of the campaign (one ``simulate_batch`` call; each lane draws its own
  run's noise and schedules its own jitter in the lane driver);
* ``scalar engine``: the same call with the lane engine switched off (``_batch._LANES = False``): where a
  ``simulate_batch`` of such wheel runs went before they took the lanes;
* ``one call per run``: each run a ``simulate_batch`` call of its own (how a campaign chunk on wheels ran them
  before: one call per set of models, each on the lanes with the other W - 1 lanes padding), on fewer runs;
* ``shared models``: the same chunk with run 0's sensor and delay model for every run (one noise stream and one
  schedule per batch of W): the throughput to reach.

The chunk is checked bit for bit against the scalar engine and the one-call-per-run results (the replay contract).

Run: ``.venv/bin/python bench/wheels_dispersed.py [runs] [rounds]`` (defaults 64 runs, 5 rounds).
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
from mrpctl.campaign.wheels import WHEEL_METRICS
from mrpctl.simulation import _batch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _host import cpu_model, vector_isa

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "campaigns" / "wheels" / "cubesat.toml"
T_FINAL = 120.0  # the example's horizon
NAMES = (*METRICS, *WHEEL_METRICS)


def spec_source(runs: int) -> dict[str, Any]:
    source = tomllib.loads(EXAMPLE.read_text(encoding="utf-8"))
    source.update(count=runs, t_final=T_FINAL)
    source["flight"] = {"attitude_noise": 1e-4, "rate_noise": 1e-5, "jitter": [0.1, 0.2]}
    source["dispersions"].update(
        hysteresis={"delta": [0.0, 0.2]},
        disturbance={"magnitude": [0.0, 1e-5]},
        sensor={"gyro_bias": [0.0, 1e-4]},
    )
    return source


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    spec = parse_campaign(spec_source(runs), name="wheels_dispersed")
    base = spec.base
    inputs = run_inputs(spec, 0, runs)
    per_run = [_task.run_models(spec, inputs, j) for j in range(runs)]
    K = inputs.gain_scale[:, None, None] * base.K[None]
    options = dict(
        t_final=base.t_final, rate=base.rate, history=base.history, substeps=base.substeps, wheels=base.wheels
    )

    def chunk(workers: int = 1) -> dict[str, np.ndarray]:
        return _task.simulate_chunk(spec, 0, runs, threads=workers)

    def scalar(workers: int = 1) -> dict[str, np.ndarray]:
        _batch._LANES = False
        try:
            return chunk(workers)
        finally:
            _batch._LANES = True

    def shared(workers: int = 1) -> dict[str, np.ndarray]:
        first = per_run[0][1]
        assert first is not None
        models = [dict(one or {}, sensor=first["sensor"], delay=first["delay"]) for _, one in per_run]
        return simulate_runs(
            inputs.inertia, K, inputs.x0, inputs.tau, [rule for rule, _ in per_run], flight=models, threads=workers,
            peak_torque=spec.peak_torque, **options,
        )  # fmt: skip

    few = max(8, runs // 8)

    def alone(workers: int = 1) -> dict[str, np.ndarray]:
        found = [
            simulate_runs(
                inputs.inertia[j : j + 1],
                K[j : j + 1],
                inputs.x0[j : j + 1],
                inputs.tau[j : j + 1],
                [per_run[j][0]],
                flight=[per_run[j][1]],
                threads=workers,
                peak_torque=spec.peak_torque,
                **options,
            )
            for j in range(few)
        ]
        return {name: np.concatenate([one[name] for one in found]) for name in NAMES}

    dispersed = chunk()  # compiles the engines
    shared()
    on_scalar, before = scalar(), alone()
    same_scalar = all(dispersed[name].tobytes() == on_scalar[name].tobytes() for name in NAMES)
    same_alone = all(dispersed[name][:few].tobytes() == before[name].tobytes() for name in NAMES)
    print(f"{cpu_model()}; {vector_isa()}")
    print(f"chunk bit for bit the scalar engine's: {same_scalar}; one call per run's ({few} runs): {same_alone}")

    cases: dict[str, tuple[int, Callable[[], Any]]] = {
        "lanes, own streams": (runs, chunk),
        "scalar engine": (runs, scalar),
        "one call per run": (few, alone),
        "shared models": (runs, shared),
    }
    rates: dict[str, list[float]] = {label: [] for label in cases}
    loads = []
    for _ in range(rounds):
        loads.append(os.getloadavg()[0])
        for label, (count, task) in cases.items():
            start = time.process_time()
            task()
            rates[label].append(count / (time.process_time() - start))
    print()
    print(
        f"wheel campaign chunk, {runs} runs of {T_FINAL:g} s at {base.rate:g} Hz on {base.wheels.count} wheels, "
        f"{rounds} interleaved rounds, CPU time on one thread; load average {min(loads):.1f}-{max(loads):.1f} on "
        f"{os.cpu_count()} CPUs"
    )
    print(f"{'':22s} {'runs/s best':>11s} {'median':>8s}   lanes / this per round: min  median  max")
    lanes = rates["lanes, own streams"]
    for label in cases:
        found = rates[label]
        line = f"  {label:20s} {max(found):11.1f} {statistics.median(found):8.1f}"
        if label != "lanes, own streams":
            ratio = [a / b for a, b in zip(lanes, found, strict=True)]
            line += f"   {min(ratio):29.2f} {statistics.median(ratio):6.2f} {max(ratio):5.2f}"
        print(line)


if __name__ == "__main__":
    main()
