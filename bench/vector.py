"""Benchmark of the vectorised lane engine (mrpctl.engines.lanes); prints one table.

The 60 s DelayAware tumbling batch: the paper's spacecraft and gain, tau = 0.5 s, 1 kHz,
attitudes uniform on SO(3) (scipy ``Rotation.random``), body rates uniform in a ball of
5 rad/s. Runs/s, all in this process and back to back, of

* ``simulate_batch`` without trajectories, which runs the lane engine (W = the default),
* the lane engine alone (``simulate_lanes``) for several W, with and without fusion, and ISA flags,
* the scalar engine (``simulate_batch`` with ``_batch._LANES = False``: the thread pool
  over one C call per run and slice),
* a hand-written structure-of-arrays C loop of the same closed loop (DelayAware rule,
  u = K m_{k-d}, RK4, the same statistics but the peak torque), W = 8 and 16 lanes, on the same
  thread pool; its J is a compile-time constant, where the engines take J and J⁻¹ as run-time
  inputs (the paper's diagonal J: two 3-vectors per lane).

Every lane-engine variant is checked bit for bit against the scalar engine on the batch
(column "bits"). The first table runs everything on one thread and times it by the process's CPU
time (``time.process_time``: simulate_batch runs its one worker on a pool thread), which a
machine shared with other jobs disturbs least; the second the wall clock on all cores for
the default engine, the hand-written loop and the scalar engine. The rounds are interleaved and
each entry is the best of the rounds; read the ratios rather than the absolute numbers.

Run: ``.venv/bin/python bench/vector.py [runs] [rounds]`` (defaults 64 runs, 3 rounds; a few minutes).
"""

from __future__ import annotations

import ctypes
import functools
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
from _host import cpu_model, vector_isa
from scipy.spatial.transform import Rotation

from mrpctl import _compile, paper
from mrpctl.engines import lanes as _vectorize
from mrpctl.engines import scalar as _engine
from mrpctl.loop import core_function, delay_samples, inertia_input
from mrpctl.model import state
from mrpctl.simulation import BatchResult, _batch, _budget, simulate_batch
from mrpctl.switching import DelayAware

T_FINAL = 60.0
TAU = 0.5
RATE = 1000.0
MAX_RATE = 5.0  # rad/s
THREAD_COUNT = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
THREADS = THREAD_COUNT  # threads of the hand-written loop's pool (set per table)

# The same closed loop written by hand over W lanes (structure of arrays, one loop over lanes
# per sample, the lane's values in locals): the shape a user would write to vectorise it.
HAND_C = r"""
#include <math.h>
#include <string.h>
#define W %(width)d
/* c ? a : b as bit masks (c in {0, 1}): no branch for gcc to sink arithmetic into, so the lane
 * loop if-converts and vectorises under IEEE-exact flags, as mrpctl's emitter does. */
static inline double SEL(long long c, double a, double b) {
  unsigned long long ua, ub, m = -(unsigned long long) c;
  memcpy(&ua, &a, 8); memcpy(&ub, &b, 8); ua = (ua & m) | (ub & ~m); memcpy(&a, &ua, 8); return a;
}
static const double H = %(h).17g;
static const double J0 = %(j0).17g, J1 = %(j1).17g, J2 = %(j2).17g;
static const double I0 = %(i0).17g, I1 = %(i1).17g, I2 = %(i2).17g;
#define F(s0, s1, s2, q0, q1, q2, d0, d1, d2, d3, d4, d5) do { \
    const double w0 = 4.0 * (q0), w1 = 4.0 * (q1), w2 = 4.0 * (q2); \
    const double ss = (s0) * (s0) + (s1) * (s1) + (s2) * (s2), sw = (s0) * w0 + (s1) * w1 + (s2) * w2; \
    const double a = 1.0 - ss; \
    d0 = 0.25 * (a * w0 + 2.0 * ((s1) * w2 - (s2) * w1) + 2.0 * (s0) * sw); \
    d1 = 0.25 * (a * w1 + 2.0 * ((s2) * w0 - (s0) * w2) + 2.0 * (s1) * sw); \
    d2 = 0.25 * (a * w2 + 2.0 * ((s0) * w1 - (s1) * w0) + 2.0 * (s2) * sw); \
    const double h0 = J0 * w0, h1 = J1 * w1, h2 = J2 * w2; \
    d3 = 0.25 * I0 * (u0 - (w1 * h2 - w2 * h1)); \
    d4 = 0.25 * I1 * (u1 - (w2 * h0 - w0 * h2)); \
    d5 = 0.25 * I2 * (u2 - (w0 * h1 - w1 * h0)); \
  } while (0)
/* x0: (6, W); gain: (18, W) row-major K[i][j] at (6 i + j); alpha: (W); stats: (8, W) out:
 * count, first, last, unsettled, max |sigma|^2, diverged, flips (sum). ring: (d + 1, 6, W). */
int hand_run(const double* restrict x0, const double* restrict gain, const double* restrict alpha,
             long long n, long long d, double* restrict ring, double* restrict stats) {
  double x[6][W], memory[W], uprev[3][W], count[W], first[W], last[W], unsettled[W], maxs[W], diverged[W], flips[W];
  const double dmax = d > 1 ? (double) d : 1.0;
  long long k, slot = 0, delayed_slot = 0;
  int l, i;
  for (i = 0; i < 6; ++i) for (l = 0; l < W; ++l) x[i][l] = x0[i * W + l];
  for (l = 0; l < W; ++l) {
    memory[l] = dmax; count[l] = 0; first[l] = -1; last[l] = -1; unsettled[l] = -1; maxs[l] = 0;
    diverged[l] = -1; flips[l] = 0; uprev[0][l] = uprev[1][l] = uprev[2][l] = 0;
  }
  for (k = 0; k < n; ++k) {
    const double* restrict m = k < d ? x0 : ring + 6 * W * delayed_slot;
    double* restrict now = ring + 6 * W * slot;
    const double kk = (double) k;
    for (l = 0; l < W; ++l) {
      const int counted = diverged[l] < 0;
      double s0 = x[0][l], s1 = x[1][l], s2 = x[2][l];
      const double q0 = x[3][l], q1 = x[4][l], q2 = x[5][l];
      const double m0 = m[l], m1 = m[W + l], m2 = m[2 * W + l], m3 = m[3 * W + l], m4 = m[4 * W + l], m5 = m[5 * W + l];
      const double ms = m0 * m0 + m1 * m1 + m2 * m2;
      const int sw = (ms >= alpha[l] * alpha[l]) & (memory[l] >= (double) d);
      const double ss = s0 * s0 + s1 * s1 + s2 * s2;
      s0 = SEL(sw, -s0 / ss, s0); s1 = SEL(sw, -s1 / ss, s1); s2 = SEL(sw, -s2 / ss, s2);
      double mem = SEL(sw, 0.0, memory[l]) + 1.0;
      mem = SEL(mem < dmax, mem, dmax);
      now[l] = s0; now[W + l] = s1; now[2 * W + l] = s2; now[3 * W + l] = q0; now[4 * W + l] = q1; now[5 * W + l] = q2;
      const double* g = gain + l;
#define ROW(r) (g[(6 * r) * W] * m0 + g[(6 * r + 1) * W] * m1 + g[(6 * r + 2) * W] * m2 \
                + g[(6 * r + 3) * W] * m3 + g[(6 * r + 4) * W] * m4 + g[(6 * r + 5) * W] * m5)
      const double u0 = ROW(0), u1 = ROW(1), u2 = ROW(2);
      double a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5, c0, c1, c2, c3, c4, c5, e0, e1, e2, e3, e4, e5;
      F(s0, s1, s2, q0, q1, q2, a0, a1, a2, a3, a4, a5);
      F(s0 + 0.5 * H * a0, s1 + 0.5 * H * a1, s2 + 0.5 * H * a2,
        q0 + 0.5 * H * a3, q1 + 0.5 * H * a4, q2 + 0.5 * H * a5, b0, b1, b2, b3, b4, b5);
      F(s0 + 0.5 * H * b0, s1 + 0.5 * H * b1, s2 + 0.5 * H * b2,
        q0 + 0.5 * H * b3, q1 + 0.5 * H * b4, q2 + 0.5 * H * b5, c0, c1, c2, c3, c4, c5);
      F(s0 + H * c0, s1 + H * c1, s2 + H * c2, q0 + H * c3, q1 + H * c4, q2 + H * c5, e0, e1, e2, e3, e4, e5);
#define STEP(z, p, q, r, t) ((z) + H / 6.0 * ((p) + 2.0 * (q) + 2.0 * (r) + (t)))
      const double n0 = STEP(s0, a0, b0, c0, e0), n1 = STEP(s1, a1, b1, c1, e1), n2 = STEP(s2, a2, b2, c2, e2);
      const double n3 = STEP(q0, a3, b3, c3, e3), n4 = STEP(q1, a4, b4, c4, e4), n5 = STEP(q2, a5, b5, c5, e5);
      const double ns = n0 * n0 + n1 * n1 + n2 * n2, nw = 16.0 * (n3 * n3 + n4 * n4 + n5 * n5);
      const int ok = (ns <= 1e12) & (nw <= 1e12);
      const int keep = counted & ok;
      x[0][l] = SEL(keep, n0, s0); x[1][l] = SEL(keep, n1, s1); x[2][l] = SEL(keep, n2, s2);
      x[3][l] = SEL(keep, n3, q0); x[4][l] = SEL(keep, n4, q1); x[5][l] = SEL(keep, n5, q2);
      memory[l] = SEL(counted, mem, memory[l]);
      const int switch_counted = counted & sw;
      count[l] += SEL(switch_counted, 1.0, 0.0);
      first[l] = SEL(switch_counted & (first[l] < 0), kk, first[l]);
      last[l] = SEL(switch_counted, kk, last[l]);
      flips[l] += SEL(counted & (u0 * uprev[0][l] < 0), 1.0, 0.0) + SEL(counted & (u1 * uprev[1][l] < 0), 1.0, 0.0)
                  + SEL(counted & (u2 * uprev[2][l] < 0), 1.0, 0.0);
      uprev[0][l] = SEL(counted, u0, uprev[0][l]); uprev[1][l] = SEL(counted, u1, uprev[1][l]);
      uprev[2][l] = SEL(counted, u2, uprev[2][l]);
      const double sq = s0 * s0 + s1 * s1 + s2 * s2, wq = 16.0 * (q0 * q0 + q1 * q1 + q2 * q2);
      unsettled[l] = SEL(counted & ((sq >= 1e-4) | (wq >= 1e-6)), kk, unsettled[l]);
      maxs[l] = SEL(counted & (sq > maxs[l]), sq, maxs[l]);
      diverged[l] = SEL(counted & !ok, kk, diverged[l]);
    }
    if (++slot > d) slot = 0;
    if (k >= d && ++delayed_slot > d) delayed_slot = 0;
  }
  for (l = 0; l < W; ++l) {
    stats[l] = count[l]; stats[W + l] = first[l]; stats[2 * W + l] = last[l]; stats[3 * W + l] = unsettled[l];
    stats[4 * W + l] = maxs[l]; stats[5 * W + l] = diverged[l]; stats[6 * W + l] = flips[l];
  }
  return 0;
}
"""


def hand_flags() -> tuple[str, ...]:
    """The lane engine's IEEE flags for the hand-written loop, but with loop splitting, which it is ~3 % faster with
    (its horizon loop split at k = d; the engine turns splitting off to compile its inlined sample once)."""
    return tuple(flag for flag in _vectorize.LANE_FLAGS if flag != "-fno-split-loops")


def tumbling_batch(count: int, seed: int = 2026) -> np.ndarray:
    """(count, 6) states: attitude uniform on SO(3) (short MRP set), rates uniform in |ω| <= 5 rad/s."""
    rng = np.random.default_rng(seed)
    sigma = Rotation.random(count, random_state=rng).as_mrp()
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    omega = direction * MAX_RATE * rng.uniform(size=(count, 1)) ** (1.0 / 3.0)
    return state(sigma, omega)


class HandLoop:
    """The hand-written W-lane loop, compiled with the lane engine's flags (`hand_flags`), on the thread pool."""

    def __init__(self, width: int, flags: tuple[str, ...], folder: Path) -> None:
        self.width = width
        j = np.diag(paper.SPACECRAFT.inertia)
        source = HAND_C % dict(
            width=width, h=1.0 / RATE, j0=j[0], j1=j[1], j2=j[2], i0=1 / j[0], i1=1 / j[1], i2=1 / j[2]
        )
        path = folder / f"hand_w{width}.c"
        path.write_text(source)
        library = folder / f"hand_w{width}.so"
        compiler = _compile.find_compiler() or "gcc"
        subprocess.run([compiler, *flags, str(path), "-o", str(library), "-lm"], check=True)
        self._run = ctypes.CDLL(str(library)).hand_run
        self._run.restype = ctypes.c_int
        self._run.argtypes = [ctypes.c_void_p] * 3 + [ctypes.c_longlong] * 2 + [ctypes.c_void_p] * 2

    def run(self, x0: np.ndarray, gains: np.ndarray, alpha: np.ndarray, n: int, d: int) -> np.ndarray:
        width, runs = self.width, len(x0)
        out = np.empty((runs, 7))

        def one(b: int) -> None:
            lanes = np.arange(b * width, (b + 1) * width) % runs
            block = np.ascontiguousarray(x0[lanes].T)
            gain = np.ascontiguousarray(gains[lanes].reshape(-1, 18).T)
            alphas = np.ascontiguousarray(alpha[lanes])
            ring = np.empty((d + 1, 6, width))
            stats = np.empty((7, width))
            addresses = [_compile.address(a) for a in (block, gain, alphas)]
            self._run(*addresses, n, d, _compile.address(ring), _compile.address(stats))
            stop = min((b + 1) * width, runs)
            out[b * width : stop] = stats.T[: stop - b * width]

        batches = range(-(-runs // width))
        if THREADS == 1:
            for b in batches:
                one(b)
        else:
            with ThreadPoolExecutor(THREADS) as pool:
                list(pool.map(one, batches))
        return out


def round_rates(
    measures: dict[str, Callable[[], object]], counts: dict[str, int], rounds: int, clock
) -> dict[str, list[float]]:
    """Runs/s of each measure in each of ``rounds`` interleaved rounds, timed by ``clock``."""
    rates: dict[str, list[float]] = {label: [] for label in measures}
    for _ in range(rounds):
        for label, call in measures.items():
            start = clock()
            call()
            rates[label].append(counts[label] / (clock() - start))
    return rates


def best_rates(
    measures: dict[str, Callable[[], object]], counts: dict[str, int], rounds: int, clock
) -> dict[str, float]:
    """Best runs/s of each measure over interleaved rounds, timed by ``clock``."""
    return {label: max(rates) for label, rates in round_rates(measures, counts, rounds, clock).items()}


def ratio_spread(rates: dict[str, list[float]], label: str, reference: str) -> tuple[float, float, float]:
    """min, median, max over the rounds of ``label``'s rate over ``reference``'s in the same round."""
    ratios = np.array(rates[label]) / np.array(rates[reference])
    return float(ratios.min()), float(np.median(ratios)), float(ratios.max())


def main() -> None:
    runs = int(sys.argv[1]) if len(sys.argv) > 1 else 64
    rounds = int(sys.argv[2]) if len(sys.argv) > 2 else 3
    rule = DelayAware()
    d = delay_samples(TAU, RATE)
    n = _budget.sample_horizon(T_FINAL, RATE)[1]
    x0 = tumbling_batch(runs)
    gains = np.broadcast_to(paper.GAIN, (runs, 3, 6))
    scalar_runs = max(8, runs // 4)
    memory0 = np.full(runs, rule.initial_memory(delay_samples=d))
    history = x0[:, :, None]  # the "constant" history: one column
    parameters = np.tile(rule.parameters(), (runs, 1))
    layout = inertia_input(paper.SPACECRAFT)
    sample = _engine.engine_sample(core_function(paper.SPACECRAFT, rule, d, 1.0 / RATE, 1, inertia=layout), d)
    checked = min(runs, 16)
    scalar = _engine.engine(paper.SPACECRAFT, rule, d, 1.0 / RATE, 1)
    reference = np.array(
        [
            scalar.run(
                x0[i], memory0[i], x0[i][None], gains[i], parameters[i], n,
                spacecraft=paper.SPACECRAFT, keep_every=None, workspace=scalar.workspace(n, switches=False),
            ).stats
            for i in range(checked)
        ]
    )  # fmt: skip

    isa = _vectorize.host_isa_flags()
    isa_label = "native" if any(flag.startswith("-march=") for flag in isa) else (" ".join(isa) or "sse2")
    plain = (*_compile.SIMULATION_FLAGS, "-fno-math-errno")
    variants: list[tuple[str, dict[str, Any]]] = [
        (f"lanes W={w} fused {isa_label}", dict(width=w)) for w in (4, 8, 16, 32)
    ] + [
        ("lanes W=8 per-instruction loops", dict(width=8, fuse=False)),
        ("lanes W=8 fused, #pragma GCC ivdep", dict(width=8, ivdep=True)),
        ("lanes W=8 fused, no -fsched-pressure", dict(width=8, flags=plain)),
        ("lanes W=8 fused, sse2 (no ISA flag)", dict(width=8, isa=())),
        ("lanes W=8 fused, -march=native", dict(width=8, isa=("-march=native",))),
    ]
    engines = {}
    bits = {}
    for label, options in variants:
        start = time.perf_counter()
        lane = _vectorize.LaneEngine(sample, d, **options)
        engines[label] = lane
        got = _vectorize.simulate_lanes(
            lane, x0[:checked], memory0[:checked], history[:checked], gains[:checked], parameters[:checked], n,
            spacecraft=paper.SPACECRAFT,
        )  # fmt: skip
        bits[label] = np.array_equal(got.view(np.int64), reference.view(np.int64))
        print(f"built {label} ({time.perf_counter() - start:.1f} s), bit-identical: {bits[label]}", flush=True)

    flags = (*hand_flags(), *isa)
    default = f"lanes W={_vectorize.DEFAULT_WIDTH} fused {isa_label}"
    scalar_label = "scalar engine (simulate_batch)"
    batch_label = f"simulate_batch (lanes, W={_vectorize.DEFAULT_WIDTH})"

    def batch(states: np.ndarray, threads: int, lanes: bool) -> BatchResult:
        _batch._LANES = lanes
        try:
            return simulate_batch(
                paper.SPACECRAFT, paper.GAIN, states, tau=TAU, rule=rule, t_final=T_FINAL, rate=RATE, threads=threads
            )
        finally:
            _batch._LANES = True

    batched = batch(x0[:checked], 1, True)
    assert np.array_equal(batched.switch_count, [round(row[2]) for row in reference])
    scalar_got = batch(x0[:checked], 1, False)
    for name in ("switch_count", "max_sigma", "peak_torque", "settling_time", "first_switch_time"):
        bits[batch_label] = bits.get(batch_label, True) and np.array_equal(
            np.asarray(getattr(batched, name)).view(np.uint8), np.asarray(getattr(scalar_got, name)).view(np.uint8)
        )
    with tempfile.TemporaryDirectory(prefix="mrpctl-bench-") as folder:
        hands = {w: HandLoop(w, flags, Path(folder)) for w in (8, 16)}

        def table(threads: int) -> dict[str, Callable[[], object]]:
            global THREADS
            THREADS = threads
            measures: dict[str, Callable[[], object]] = {}
            measures[batch_label] = functools.partial(batch, x0, threads, True)
            for label, lane in engines.items():
                measures[label] = functools.partial(
                    _vectorize.simulate_lanes, lane, x0, memory0, history, gains, parameters, n,
                    spacecraft=paper.SPACECRAFT, threads=threads,
                )  # fmt: skip
            for w, hand in hands.items():
                measures[f"hand-written SoA C, W={w}"] = functools.partial(hand.run, x0, gains, np.ones(runs), n, d)
            measures[scalar_label] = functools.partial(batch, x0[:scalar_runs], threads, False)
            return measures

        serial = table(1)
        counts = {label: (scalar_runs if label == scalar_label else runs) for label in serial}
        per_core_rounds = round_rates(serial, counts, rounds, time.process_time)
        per_core = {label: max(rates) for label, rates in per_core_rounds.items()}
        print("serial rounds (CPU time) done", flush=True)
        pooled = table(THREAD_COUNT)
        pooled = {
            label: pooled[label]
            for label in (batch_label, default, "hand-written SoA C, W=8", "hand-written SoA C, W=16", scalar_label)
        }
        wall_rounds = round_rates(pooled, counts, rounds, time.perf_counter)
        wall = {label: max(rates) for label, rates in wall_rounds.items()}
        hand_check = hands[8].run(x0[:checked], gains[:checked], np.ones(checked), n, d)
        agree = np.mean(hand_check[:, 0] == reference[:, 2])

    hand_best = max(per_core[f"hand-written SoA C, W={w}"] for w in (8, 16))
    print()
    print(
        f"60 s DelayAware tumbling batch (tau = {TAU} s, {RATE:g} Hz, |omega| <= {MAX_RATE} rad/s, "
        f"attitude uniform on SO(3)), {runs} runs, best of {rounds} interleaved rounds"
    )
    print(f"{cpu_model()}; {vector_isa()}")
    print(f"CPU-time runs/s on one thread (per core); load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    hand8 = "hand-written SoA C, W=8"
    print(
        f"{'variant':40s} {'runs/s':>8s} {'x scalar':>9s} {'x best hand':>12s}  x hand W=8 per round: min median max"
        "  bits vs scalar engine"
    )
    for label, rate in per_core.items():
        mark = bits.get(label)
        low, middle, high = ratio_spread(per_core_rounds, label, hand8)
        print(
            f"{label:40s} {rate:8.1f} {rate / per_core[scalar_label]:9.2f} {rate / hand_best:12.2f}  "
            f"{low:21.2f} {middle:6.2f} {high:4.2f}  "
            + ("" if mark is None else ("identical" if mark else "DIFFERENT"))
            + ("  <- default W" if label == default else "")
        )
    print()
    print(f"wall-clock runs/s on {THREAD_COUNT} threads (shared machine: absolute numbers are low)")
    wall_hand = max(rate for label, rate in wall.items() if label.startswith("hand"))
    for label, rate in wall.items():
        low, middle, high = ratio_spread(wall_rounds, label, hand8)
        print(
            f"{label:40s} {rate:8.1f} {rate / wall[scalar_label]:9.2f} {rate / wall_hand:12.2f}  "
            f"{low:21.2f} {middle:6.2f} {high:4.2f}"
        )
    print(
        f"hand-written loop: switch counts equal to the engine's on {agree:.0%} of {checked} runs (not bit-identical)"
    )


if __name__ == "__main__":
    main()
