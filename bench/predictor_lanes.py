"""Predictor batches on the lanes against the plain law on the lanes, in one process.

The cases of ``examples/campaigns/predictor.toml``: the fast gains (ζ = 1, ωₙ = 12.85 rad/s) of the nominal
spacecraft, each run's plant J_ii ± 15 % with products ± 2 kg m² (a full inertia), attitudes up to 180°,
|ω| ≤ 0.3 rad/s, τ = 0.5 s, 1 kHz, 20 s; OnPredicted(1) and OnPredicted(1.2) alternating, the controller's model the
nominal spacecraft. Measured: metrics-only ``simulate_batch`` calls of the predictor on the lanes (the default),
the same calls on the scalar engine (the lanes switched off, what a predictor campaign did before), and the plain
``OnDelayed`` law on the lanes with the same plants and states and the paper's gain (with the fast gains every
plain run diverges within a second, and a lane batch whose runs all diverged stops early: no measure of the
lanes). Both predictor forms are measured: the default nonlinear model copy (form (b)) and
``PredictorForm.LINEAR`` (the linearised copy, the FSA increment on the group; ``design/predictor.md``). Each
predictor variant is checked bit for bit against the scalar engine. Rounds interleaved; the best rate of the
rounds, and the min/median/max over the rounds of each round's ratio to the plain lanes of that round; CPU time on
one thread, wall clock on every core. Read the ratios, measured in this process, rather than the absolute numbers.

Run: ``.venv/bin/python bench/predictor_lanes.py [runs] [rounds]`` (defaults 48 runs, 3 rounds).
"""

from __future__ import annotations

import os
import platform
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from mrpctl import mrp, paper, simulate_batch
from mrpctl.design import pd_gains
from mrpctl.engines import isa as host_isa
from mrpctl.engines import lanes as lane_engines
from mrpctl.predictor import OnPredicted, Predictor, PredictorForm
from mrpctl.simulation import _batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnDelayed

NOMINAL = Spacecraft(np.diag([140.0, 100.0, 80.0]))
GAINS = pd_gains(NOMINAL, zeta=1.0, omega_n=12.85).K
TAU, RATE, T_FINAL = 0.5, 1000.0, 20.0


def cases(runs: int) -> dict[str, Any]:
    """The seeded dispersed plants and initial states of ``runs`` runs."""
    rng = np.random.default_rng(13)
    crafts = []
    for _ in range(runs):
        inertia = np.diag(np.diag(NOMINAL.inertia) * (1.0 + rng.uniform(-0.15, 0.15, 3)))
        products = rng.uniform(-2.0, 2.0, 3)
        inertia[0, 1] = inertia[1, 0] = products[0]
        inertia[0, 2] = inertia[2, 0] = products[1]
        inertia[1, 2] = inertia[2, 1] = products[2]
        crafts.append(Spacecraft(inertia))
    axis = rng.normal(size=(runs, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.radians(rng.uniform(0.0, 180.0, (runs, 1)))
    sigma = mrp.short(axis * np.tan(angle / 4))
    omega = rng.normal(size=(runs, 3))
    omega *= rng.uniform(0.0, 0.3, (runs, 1)) / np.linalg.norm(omega, axis=1, keepdims=True)
    return dict(spacecraft=crafts, K=GAINS, x0=np.hstack((sigma, omega / 4)), tau=TAU, rate=RATE, t_final=T_FINAL)


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def vector_flags() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            flags = next((line.split(":", 1)[1].split() for line in handle if line.startswith("flags")), [])
    except OSError:
        flags = []
    wanted = ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512dq", "avx512vl")
    return " ".join(flag for flag in wanted if flag in flags) or "unknown"


def round_rates(
    table: dict[str, Callable[[], Any]], runs: int, rounds: int, clock: Callable[[], float]
) -> dict[str, list[float]]:
    """Runs/s of each entry in each of ``rounds`` interleaved rounds."""
    rates: dict[str, list[float]] = {label: [] for label in table}
    for _ in range(rounds):
        for label, call in table.items():
            start = clock()
            call()
            rates[label].append(runs / (clock() - start))
    return rates


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 48
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    case = cases(runs)
    predicted = dict(case, rule=[OnPredicted(1.0 if i % 2 == 0 else 1.2) for i in range(runs)])
    forms = {"": Predictor(model=NOMINAL), " (linear form)": Predictor(model=NOMINAL, form=PredictorForm.LINEAR)}
    threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)

    def predictor_on(lanes: bool, count: int, predictor: Predictor) -> Any:
        _batch._LANES = lanes
        try:
            return simulate_batch(**predicted, predictor=predictor, threads=count)
        finally:
            _batch._LANES = True

    def plain(count: int) -> Any:  # the paper's gain: the fast gains diverge on the plain law (a batch stops early)
        return simulate_batch(**dict(case, K=paper.GAIN), rule=OnDelayed(), threads=count)

    fields = ("switch_count", "settling_time", "max_sigma", "diverged", "peak_torque", "peak_command")
    same, diverged, settled = True, {"plain": int(plain(1).diverged.sum())}, {}
    for name, predictor in forms.items():
        lanes, scalar = predictor_on(True, 1, predictor), predictor_on(False, 1, predictor)  # warm, check the bits
        same = same and all(
            np.asarray(getattr(lanes, f)).tobytes() == np.asarray(getattr(scalar, f)).tobytes() for f in fields
        )
        diverged["predictor" + name] = int(lanes.diverged.sum())
        settled["predictor" + name] = int(np.isfinite(lanes.settling_time).sum())

    def table(count: int) -> dict[str, Callable[[], Any]]:
        entries: dict[str, Callable[[], Any]] = {}
        for name, predictor in forms.items():
            entries[f"predictor{name}, lanes"] = lambda p=predictor: predictor_on(True, count, p)
            entries[f"predictor{name}, scalar engine"] = lambda p=predictor: predictor_on(False, count, p)
        entries["plain OnDelayed, lanes"] = lambda: plain(count)
        return entries

    serial = round_rates(table(1), runs, rounds, time.process_time)
    wall = round_rates(table(threads), runs, rounds, time.perf_counter)
    isa = host_isa.host_isa_flags()
    wanted = ("-mavx2", "-mavx512f", "-mfma")
    shown = [flag for flag in isa if flag.startswith(("-march", "-mprefer")) or flag in wanted]
    print(f"CPU: {cpu_model()}; vector flags: {vector_flags()}; lane ISA flags: {' '.join(shown)} ({len(isa)} in all)")
    print(
        f"lane width W = {lane_engines.DEFAULT_WIDTH}; {runs} runs of the predictor campaign's cases "
        f"({T_FINAL:g} s at {RATE:g} Hz, tau = {TAU} s), best of {rounds} interleaved rounds; load average "
        f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
    )
    print(
        f"predictor lanes equal to the scalar engine bit for bit (both forms): {'yes' if same else 'NO'}; diverged "
        "runs (a lane batch stops early when all its runs diverged): "
        + ", ".join(f"{label} {count}" for label, count in diverged.items())
        + f" of {runs}; settled in {T_FINAL:g} s: "
        + ", ".join(f"{label} {count}" for label, count in settled.items())
    )
    for title, rates in (("CPU-time runs/s, one thread", serial), (f"wall-clock runs/s, {threads} threads", wall)):
        plain_rates = np.asarray(rates["plain OnDelayed, lanes"])
        print(f"{title:44s} {'best runs/s':>11s} {'x plain lanes: min':>19s} {'median':>7s} {'max':>6s}")
        for label, values in rates.items():
            ratio = np.asarray(values) / plain_rates
            print(f"{label:44s} {max(values):11.1f} {ratio.min():19.2f} {np.median(ratio):7.2f} {ratio.max():6.2f}")
    if not same:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
