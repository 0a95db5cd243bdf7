"""CPU time of the 60 s paper case with the predictor controller against the plain delayed PD (issue 13).

The paper's spacecraft and gain, x0 = [0.93, 0, 0, 0.46/4, 0, 0], τ = 0.5 s, 1 kHz (60 001 samples),
one RK4 substep, compiled engine (warm: each engine is built and run once before timing). The
configurations are timed interleaved (A B C A B C ...), ``repeats`` times each, in one process, with
``time.process_time`` (CPU time of this process, one thread); the table gives the median and the ratio
to the plain PD with ``OnDelayed`` (the paper's loop). Two ways of keeping the result are timed:
every sample (what ``simulate`` does by default) and metrics only (``keep_every=None``: the engine
alone). The issue asks for the predictor within 3x of the plain PD.

``python bench/predictor.py [repeats]``
"""

from __future__ import annotations

import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mrpctl import OnPredicted, Predictor, paper, simulate
from mrpctl.flight import Hysteretic
from mrpctl.switching import OnCurrent, OnDelayed

SC = paper.SPACECRAFT
X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])
COMMON: dict[str, Any] = dict(tau=0.5, t_final=60.0, rate=1000.0)


def configurations(keep_every: int | None) -> dict[str, Callable[[], object]]:
    predictor = Predictor(model=SC)
    return {
        "plain PD, OnDelayed": lambda: simulate(SC, paper.GAIN, X0, rule=OnDelayed(), keep_every=keep_every, **COMMON),
        "plain PD, OnCurrent": lambda: simulate(SC, paper.GAIN, X0, rule=OnCurrent(), keep_every=keep_every, **COMMON),
        "flight loop, Hysteretic(0)": lambda: simulate(
            SC, paper.GAIN, X0, rule=Hysteretic(0.0), keep_every=keep_every, **COMMON
        ),
        "predictor, OnPredicted(1)": lambda: simulate(
            SC, paper.GAIN, X0, rule=OnPredicted(), predictor=predictor, keep_every=keep_every, **COMMON
        ),
    }


def main(repeats: int = 7) -> None:
    print(f"60 s paper case at 1 kHz, tau = 0.5 s: CPU time per run (median of {repeats}, interleaved)")
    print()
    print("| keep | configuration | CPU time (ms) | ratio to plain PD (OnDelayed) |")
    print("|---|---|---|---|")
    for keep_every, label in ((1, "every sample"), (None, "metrics only")):
        runs = configurations(keep_every)
        for run in runs.values():  # build (or load) every engine first
            run()
        times: dict[str, list[float]] = {name: [] for name in runs}
        for _ in range(repeats):
            for name, run in runs.items():
                start = time.process_time()
                run()
                times[name].append(time.process_time() - start)
        base = statistics.median(times["plain PD, OnDelayed"])
        for name, values in times.items():
            median = statistics.median(values)
            print(f"| {label} | {name} | {1e3 * median:.1f} | {median / base:.2f} |")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 7)
