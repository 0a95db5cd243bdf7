"""Cost of a tracking campaign's chunk: the pointing metrics (kept samples, scalar engine) against the same runs
metrics-only (the lane engine, no pointing metrics), process CPU time, min of ROUNDS interleaved rounds.

    PYTHONPATH=. python bench/campaign_tracking.py [RUNS] [ROUNDS]

Runs the first RUNS runs of examples/campaigns/tracking/slew.toml on one thread; checks that both paths give
the same METRICS bit for bit.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from mrpctl.campaign._task import run_models, run_tracking, simulate_chunk
from mrpctl.campaign.sampling import run_inputs
from mrpctl.campaign.simulation import METRICS, flight_keywords
from mrpctl.campaign.spec import load_campaign
from mrpctl.simulation import simulate_batch
from mrpctl.spacecraft import Spacecraft


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    spec = load_campaign(Path(__file__).resolve().parent.parent / "examples" / "campaigns" / "tracking" / "slew.toml")
    inputs = run_inputs(spec, 0, runs)
    base = spec.base
    models = [run_models(spec, inputs, j) for j in range(runs)]

    def lanes() -> dict[str, np.ndarray]:
        batch = simulate_batch(
            [Spacecraft(J) for J in inputs.inertia],
            inputs.gain_scale[:, None, None] * base.K[None],
            inputs.x0,
            tau=inputs.tau,
            rule=[rule for rule, _ in models],
            t_final=base.t_final,
            rate=base.rate,
            threads=1,
            reference=[run_tracking(spec, inputs, j) for j in range(runs)],
            **flight_keywords(models[0][1] or {}),
        )
        return {name: np.asarray(getattr(batch, name)) for name in METRICS}

    best = {"chunk (pointing metrics)": float("inf"), "lanes (metrics only)": float("inf")}
    results = {}
    for _ in range(rounds):
        for name, job in (
            ("chunk (pointing metrics)", lambda: simulate_chunk(spec, 0, runs, threads=1)),
            ("lanes (metrics only)", lanes),
        ):
            start = time.process_time()
            results[name] = job()
            best[name] = min(best[name], time.process_time() - start)
    chunk, lane = results["chunk (pointing metrics)"], results["lanes (metrics only)"]
    same = all(chunk[name].tobytes() == lane[name].tobytes() for name in METRICS)
    n = int(base.t_final * base.rate) + 1
    for name, seconds in best.items():
        print(f"{name:<26} {runs / seconds:8.1f} runs/s  ({seconds:.3f} s CPU for {runs} runs of {n} samples)")
    print(f"ratio {best['chunk (pointing metrics)'] / best['lanes (metrics only)']:.2f}x; METRICS identical: {same}")


if __name__ == "__main__":
    main()
