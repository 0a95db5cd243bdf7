"""The lane engine's rate against its build choices: lane width W and vector ISA (the 2 000 runs/s goal).

The 60 s DelayAware tumbling batch of ``bench/vector.py`` (the paper's spacecraft and gain,
tau = 0.5 s, 1 kHz, attitudes uniform on SO(3), |omega| <= 5 rad/s). For W in (4, 8, 16) and the
ISA flags ``-mavx2`` (explicit) or ``-march=native`` resolved by the compiler
(:func:`mrpctl.engines.isa.native_isa_flags`: the flags that key the compile cache), the lane
engine alone (``simulate_lanes``), each variant checked bit for bit against the scalar engine on
16 runs; the hand-written structure-of-arrays loop of ``bench/vector.py`` (W = 8, the same
flags but loop splitting: ``vector.hand_flags``) as the yardstick. Table 1: CPU time on one thread
(the least disturbed by other jobs); table 2: wall clock on every core for the default and the hand
loop. Rounds interleaved, best of the rounds and the min / median / max over the rounds of the ratio
to the hand loop in the same round; read the ratios, measured in this process, rather than the
absolute numbers.

Run: ``.venv/bin/python bench/lanes_rate.py [runs] [rounds]`` (defaults 64 runs, 3 rounds).
"""

from __future__ import annotations

import functools
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import vector
from _host import cpu_model, vector_isa

from mrpctl import paper
from mrpctl.engines import isa as host_isa
from mrpctl.engines import lanes as _vectorize
from mrpctl.engines import scalar as _engine
from mrpctl.loop import core_function, delay_samples, inertia_input
from mrpctl.simulation import _budget
from mrpctl.switching import DelayAware


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    rule = DelayAware()
    d = delay_samples(vector.TAU, vector.RATE)
    n = _budget.sample_horizon(vector.T_FINAL, vector.RATE)[1]
    x0 = vector.tumbling_batch(runs)
    gains = np.broadcast_to(paper.GAIN, (runs, 3, 6))
    memory0 = np.full(runs, rule.initial_memory(delay_samples=d))
    history = x0[:, :, None]
    parameters = np.tile(rule.parameters(), (runs, 1))
    sample = _engine.engine_sample(
        core_function(paper.SPACECRAFT, rule, d, 1.0 / vector.RATE, 1, inertia=inertia_input(paper.SPACECRAFT)), d
    )
    checked = min(runs, 16)
    scalar = _engine.engine(paper.SPACECRAFT, rule, d, 1.0 / vector.RATE, 1)
    reference = np.array(
        [
            scalar.run(
                x0[i], memory0[i], x0[i][None], gains[i], parameters[i], n,
                spacecraft=paper.SPACECRAFT, keep_every=None, workspace=scalar.workspace(n, switches=False),
            ).stats
            for i in range(checked)
        ]
    )  # fmt: skip
    native = host_isa.native_isa_flags()
    isas = {"-mavx2": ("-mavx2",), "native": native} if native else {"-mavx2": ("-mavx2",)}
    default_isa = _vectorize.host_isa_flags()
    engines: dict[str, _vectorize.LaneEngine] = {}
    bits: dict[str, bool] = {}
    for isa_label, isa in isas.items():
        for width in (4, 8, 16):
            label = f"lanes W={width:<2d} {isa_label}"
            if isa == default_isa and width == _vectorize.DEFAULT_WIDTH:
                label += " (default)"
            lane = _vectorize.LaneEngine(sample, d, width=width, isa=isa)
            got = _vectorize.simulate_lanes(
                lane, x0[:checked], memory0[:checked], history[:checked], gains[:checked], parameters[:checked], n,
                spacecraft=paper.SPACECRAFT, threads=1,
            )  # fmt: skip
            engines[label] = lane
            bits[label] = np.array_equal(got.view(np.int64), reference.view(np.int64))
            print(f"built {label}: bit-identical to the scalar engine: {bits[label]}", flush=True)
    default = next(label for label in engines if label.endswith("(default)"))
    with tempfile.TemporaryDirectory(prefix="mrpctl-bench-") as folder:
        hand = vector.HandLoop(8, (*vector.hand_flags(), *default_isa), Path(folder))

        def measures(threads: int) -> dict[str, Callable[[], object]]:
            vector.THREADS = threads
            table: dict[str, Callable[[], object]] = {
                label: functools.partial(
                    _vectorize.simulate_lanes, lane, x0, memory0, history, gains, parameters, n,
                    spacecraft=paper.SPACECRAFT, threads=threads,
                )
                for label, lane in engines.items()
            }  # fmt: skip
            table["hand-written SoA C, W=8"] = functools.partial(hand.run, x0, gains, np.ones(runs), n, d)
            return table

        counts = dict.fromkeys(measures(1), runs)
        serial_rounds = vector.round_rates(measures(1), counts, rounds, time.process_time)
        serial = {label: max(rates) for label, rates in serial_rounds.items()}
        every = measures(vector.THREAD_COUNT)
        fastest = max(engines, key=lambda label: serial[label])
        pooled = {label: every[label] for label in dict.fromkeys((default, fastest, "hand-written SoA C, W=8"))}
        wall_rounds = vector.round_rates(pooled, counts, rounds, time.perf_counter)
        wall = {label: max(rates) for label, rates in wall_rounds.items()}
    hand = "hand-written SoA C, W=8"
    hand_rate = serial[hand]
    print()
    print(f"{cpu_model()}; {vector_isa()}")
    print(
        f"60 s DelayAware tumbling batch, {runs} runs, best of {rounds} interleaved rounds (and the spread of the "
        f"ratio to the hand loop in the same round); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    print(
        f"{'CPU-time runs/s, one thread':34s} {'runs/s':>8s} {'x default':>10s} {'x hand':>7s}  "
        "x hand per round: min median max  bits"
    )
    for label, rate in serial.items():
        mark = bits.get(label)
        flag = "" if mark is None else ("identical" if mark else "DIFFERENT")
        low, middle, high = vector.ratio_spread(serial_rounds, label, hand)
        print(
            f"{label:34s} {rate:8.1f} {rate / serial[default]:10.2f} {rate / hand_rate:7.2f}  "
            f"{low:17.2f} {middle:6.2f} {high:4.2f}  {flag}"
        )
    print(f"{'wall-clock runs/s, ' + str(vector.THREAD_COUNT) + ' threads':34s}")
    for label, rate in wall.items():
        low, middle, high = vector.ratio_spread(wall_rounds, label, hand)
        print(
            f"{label:34s} {rate:8.1f} {rate / wall[default]:10.2f} {rate / wall[hand]:7.2f}  "
            f"{low:17.2f} {middle:6.2f} {high:4.2f}"
        )


if __name__ == "__main__":
    main()
