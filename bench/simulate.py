"""Benchmark of the closed-loop simulator (mrpctl.simulation); prints one table.

For the paper's case (60 s at 1 kHz, tau = 0.5 s) and each switching rule: compile time
(cold cache), cached re-run time (engine loaded from the on-disk cache, nothing
compiled) and run time; a hand-written C reference of the same RK4 loop compiled here
(the floor) and the ratio to it; scipy ``solve_ivp`` by the method of steps and JiTCDDE
(if installed) as the tools a user would otherwise pick, NoSwitching only; batch
throughput for 1000 initial states on all cores; CasADi's virtual machine (the fallback
without a C compiler) against the floor.

Run: ``.venv/bin/python bench/simulate.py`` (about a minute). Timings are the minimum of
several repetitions, in CPU time (process time; the floor's clock too) except the
thread-pool batch (wall time); on a shared machine they still move from run to run.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

from mrpctl import _compile, paper
from mrpctl.engines.scalar import clear_engines, engine
from mrpctl.model import state
from mrpctl.simulation import simulate, simulate_batch
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed

T_FINAL = 60.0
TAU = paper.TAU
RATE = paper.MEASUREMENT_RATE
RULES = [NoSwitching(), OnCurrent(), OnDelayed(), BoundaryLayer(paper.BOUNDARY_LAYER_EPS), DelayAware()]
REPEATS = 7

FLOOR_C = r"""
#include <stdio.h>
#include <string.h>
#include <time.h>
/* The same loop as mrpctl.simulate with NoSwitching: sample, hold u = K m_{k-d}, RK4. */
#define N %(n)d
#define D %(d)d
static const double H = %(h).17g;
static const double JD[3] = {%(j0).17g, %(j1).17g, %(j2).17g};
static const double JI[3] = {%(i0).17g, %(i1).17g, %(i2).17g};
static const double K[3][6] = {%(K)s};
static double meas[N][6], torque[N][3];
static void f(const double *x, const double *u, double *xd) {
  const double s0 = x[0], s1 = x[1], s2 = x[2];
  const double w0 = 4.0 * x[3], w1 = 4.0 * x[4], w2 = 4.0 * x[5];
  const double ss = s0 * s0 + s1 * s1 + s2 * s2, sw = s0 * w0 + s1 * w1 + s2 * w2, a = 1.0 - ss;
  xd[0] = 0.25 * (a * w0 + 2.0 * (s1 * w2 - s2 * w1) + 2.0 * s0 * sw);
  xd[1] = 0.25 * (a * w1 + 2.0 * (s2 * w0 - s0 * w2) + 2.0 * s1 * sw);
  xd[2] = 0.25 * (a * w2 + 2.0 * (s0 * w1 - s1 * w0) + 2.0 * s2 * sw);
  const double h0 = JD[0] * w0, h1 = JD[1] * w1, h2 = JD[2] * w2;
  xd[3] = 0.25 * JI[0] * (u[0] - (w1 * h2 - w2 * h1));
  xd[4] = 0.25 * JI[1] * (u[1] - (w2 * h0 - w0 * h2));
  xd[5] = 0.25 * JI[2] * (u[2] - (w0 * h1 - w1 * h0));
}
static void run(const double *x0, double *x) {
  memcpy(x, x0, 6 * sizeof(double));
  for (int k = 0; k < N; ++k) {
    double u[3], k1[6], k2[6], k3[6], k4[6], z[6];
    memcpy(meas[k], x, sizeof meas[k]);
    const double *m = k >= D ? meas[k - D] : x0;
    for (int i = 0; i < 3; ++i) {
      u[i] = 0.0;
      for (int j = 0; j < 6; ++j) u[i] += K[i][j] * m[j];
      torque[k][i] = u[i];
    }
    f(x, u, k1); for (int i = 0; i < 6; ++i) z[i] = x[i] + 0.5 * H * k1[i];
    f(z, u, k2); for (int i = 0; i < 6; ++i) z[i] = x[i] + 0.5 * H * k2[i];
    f(z, u, k3); for (int i = 0; i < 6; ++i) z[i] = x[i] + H * k3[i];
    f(z, u, k4); for (int i = 0; i < 6; ++i) x[i] += H / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
  }
}
int main(void) {
  const double x0[6] = {%(x0)s};
  double x[6], best = 1e30;
  for (int rep = 0; rep < %(repeats)d; ++rep) {
    struct timespec a, b;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &a);
    run(x0, x);
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &b);
    double ms = (b.tv_sec - a.tv_sec) * 1e3 + (b.tv_nsec - a.tv_nsec) * 1e-6;
    if (ms < best) best = ms;
  }
  printf("%%.6f %%.17g %%.17g\n", best, meas[N - 1][0], meas[N - 1][3]);
  return 0;
}
"""


def best_of(function, repeats: int = REPEATS, clock=time.process_time) -> float:
    """Minimum over ``repeats`` calls; CPU time by default (the machine is shared: wall time
    measures the other jobs), wall time for the thread-pool batch."""
    times = []
    for _ in range(repeats):
        start = clock()
        function()
        times.append(clock() - start)
    return min(times)


def run_case(rule):
    return simulate(paper.SPACECRAFT, paper.GAIN, paper.INITIAL_STATE, tau=TAU, rule=rule, t_final=T_FINAL)


def build_floor(n: int, d: int, folder: Path) -> Path:
    """Write and compile the hand-written C loop; returns the executable."""
    j = np.diag(paper.SPACECRAFT.inertia)
    source = FLOOR_C % dict(
        n=n,
        d=d,
        h=1.0 / RATE,
        j0=j[0],
        j1=j[1],
        j2=j[2],
        i0=1.0 / j[0],
        i1=1.0 / j[1],
        i2=1.0 / j[2],
        K=", ".join("{" + ", ".join(f"{v:.17g}" for v in row) + "}" for row in paper.GAIN),
        x0=", ".join(f"{v:.17g}" for v in paper.INITIAL_STATE),
        repeats=REPEATS,
    )
    (folder / "floor.c").write_text(source)
    compiler = _compile.find_compiler() or "gcc"
    flags = [
        flag for flag in _compile.SIMULATION_FLAGS if flag not in ("-shared", "-fPIC", "-fno-semantic-interposition")
    ]
    subprocess.run([compiler, *flags, "floor.c", "-o", "floor", "-lm"], cwd=folder, check=True)
    return folder / "floor"


def floor_time(executable: Path) -> tuple[float, float, float]:
    """Run the C loop; (best ms, sigma_1 and omega_1/4 at the last sample)."""
    out = subprocess.run([str(executable)], capture_output=True, text=True, check=True).stdout.split()
    return float(out[0]), float(out[1]), float(out[2])


def solve_ivp_time() -> float:
    """Continuous DDE by the method of steps with solve_ivp (RK45, rtol 1e-8, atol 1e-10)."""
    inertia = paper.SPACECRAFT.inertia
    inverse = paper.SPACECRAFT.inertia_inverse
    gain = np.asarray(paper.GAIN)
    x0 = np.asarray(paper.INITIAL_STATE)

    def rhs(solution_of_previous):
        def f(t, x):
            past = x0 if solution_of_previous is None else solution_of_previous(t - TAU)
            u = gain @ past
            s, w = x[:3], 4.0 * x[3:]
            sd = 0.25 * ((1 - s @ s) * w + 2 * np.cross(s, w) + 2 * s * (s @ w))
            wd = inverse @ (u - np.cross(w, inertia @ w))
            return np.concatenate((sd, wd / 4.0))

        return f

    def solve():
        start, y, previous = 0.0, x0, None
        while start < T_FINAL - 1e-12:
            end = min(start + TAU, T_FINAL)
            sol = solve_ivp(rhs(previous), (start, end), y, rtol=1e-8, atol=1e-10, dense_output=True)
            start, y, previous = end, sol.y[:, -1], sol.sol

    return best_of(solve, 2)


def jitcdde_times() -> tuple[float, float] | None:
    """(compile s, run s) of JiTCDDE on the continuous DDE, or None if it is not installed."""
    try:
        import symengine
        from jitcdde import jitcdde, t, y
    except ImportError:
        return None
    inertia = np.diag(paper.SPACECRAFT.inertia)
    gain = np.asarray(paper.GAIN)
    s = [y(i) for i in range(3)]
    w = [4 * y(3 + i) for i in range(3)]
    past = [y(i, t - TAU) for i in range(6)]
    u = [sum(gain[i, j] * past[j] for j in range(6)) for i in range(3)]
    ss = sum(v * v for v in s)
    sw = sum(a * b for a, b in zip(s, w, strict=True))
    cross = [s[1] * w[2] - s[2] * w[1], s[2] * w[0] - s[0] * w[2], s[0] * w[1] - s[1] * w[0]]
    h = [inertia[i] * w[i] for i in range(3)]
    gyro = [w[1] * h[2] - w[2] * h[1], w[2] * h[0] - w[0] * h[2], w[0] * h[1] - w[1] * h[0]]
    f = [symengine.Rational(1, 4) * ((1 - ss) * w[i] + 2 * cross[i] + 2 * s[i] * sw) for i in range(3)]
    f += [(u[i] - gyro[i]) / (4 * inertia[i]) for i in range(3)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        start = time.perf_counter()
        dde = jitcdde(f, max_delay=TAU, verbose=False)
        dde.compile_C(simplify=False, verbose=False)
        compile_seconds = time.perf_counter() - start

        def solve():
            dde.purge_past()
            dde.constant_past(np.asarray(paper.INITIAL_STATE), time=0.0)
            dde.set_integration_parameters(rtol=1e-8, atol=1e-10)
            dde.adjust_diff()
            for time_point in np.arange(0.01, T_FINAL + 1e-9, 0.01):
                dde.integrate(time_point)

        return compile_seconds, best_of(solve, 2)


def batch_rate(count: int = 1000) -> tuple[float, int]:
    rng = np.random.default_rng(7)
    axes = rng.normal(size=(count, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    angles = np.radians(rng.uniform(150.0, 179.0, count))
    x0 = state(np.tan(angles / 4.0)[:, None] * axes, rng.uniform(0.2, 1.0, count)[:, None] * axes)
    threads = len(os.sched_getaffinity(0))
    simulate_batch(paper.SPACECRAFT, paper.GAIN, x0[:threads], tau=TAU, rule=DelayAware(), t_final=T_FINAL)
    seconds = best_of(
        lambda: simulate_batch(paper.SPACECRAFT, paper.GAIN, x0, tau=TAU, rule=DelayAware(), t_final=T_FINAL),
        2,
        time.perf_counter,
    )
    return count / seconds, threads


def vm_time() -> float:
    clear_engines()
    original = _compile.find_compiler
    _compile.find_compiler = lambda: None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", _compile.CompilerWarning)
            run_case(NoSwitching())
            return best_of(lambda: run_case(NoSwitching()), 3)
    finally:
        _compile.find_compiler = original
        clear_engines()


def main() -> int:
    cold = Path(tempfile.mkdtemp(prefix="mrpctl-bench-cache-"))
    os.environ["MRPCTL_CACHE_DIR"] = str(cold)
    print(f"mrpctl.simulation benchmark: paper case, {T_FINAL:g} s at {RATE:g} Hz, tau = {TAU:g} s")
    print(f"{'rule':<16} {'compile+run s':>13} {'cached s':>9} {'run ms':>8} {'switches':>9}")
    run_ms = {}
    try:
        for rule in RULES:
            clear_engines()
            start = time.perf_counter()
            run_case(rule)
            first = time.perf_counter() - start
            clear_engines()
            start = time.perf_counter()
            result = run_case(rule)
            cached = time.perf_counter() - start
            run_ms[rule.label] = 1e3 * best_of(lambda rule=rule: run_case(rule))
            print(f"{rule.label:<16} {first:13.2f} {cached:9.3f} {run_ms[rule.label]:8.2f} {result.switch_count:9d}")
        n = int(T_FINAL * RATE) + 1
        compiled = engine(paper.SPACECRAFT, NoSwitching(), round(TAU * RATE), 1.0 / RATE, 1)
        x0 = np.asarray(paper.INITIAL_STATE)
        space = compiled.workspace(n, switches=True)

        def engine_only():
            compiled.run(
                x0,
                0.0,
                x0[None, :],
                np.asarray(paper.GAIN),
                np.zeros(1),
                n,
                spacecraft=paper.SPACECRAFT,
                keep_every=1,
                workspace=space,
                switch_limit=n,
            )

        floor_ms, engine_ms, simulate_ms = np.inf, np.inf, np.inf
        with tempfile.TemporaryDirectory() as folder:
            executable = build_floor(n, round(TAU * RATE), Path(folder))
            for _ in range(4):  # interleaved, so that all three see the same machine load
                floor_ms = min(floor_ms, floor_time(executable)[0])
                engine_ms = min(engine_ms, 1e3 * best_of(engine_only))
                simulate_ms = min(simulate_ms, 1e3 * best_of(lambda: run_case(NoSwitching())))
            _, floor_sigma, floor_x4 = floor_time(executable)
        ours = run_case(NoSwitching())
        agree = max(abs(ours.sigma[-1, 0] - floor_sigma), abs(ours.omega[-1, 0] / 4.0 - floor_x4))
        print()
        print(f"C floor (hand-written RK4 loop, same flags) {floor_ms:8.2f} ms  (final state differs by {agree:.1e})")
        ratio = engine_ms / floor_ms
        print(f"compiled engine, NoSwitching / floor       {engine_ms:8.2f} ms = {ratio:.2f} x (goal <= 1.1)")
        print(f"simulate() incl. result object / floor     {simulate_ms:8.2f} ms = {simulate_ms / floor_ms:.2f} x")
        ivp = solve_ivp_time()
        print(f"scipy solve_ivp, method of steps (RK45)    {1e3 * ivp:8.1f} ms = {1e3 * ivp / floor_ms:.0f} x floor")
        try:
            jit = jitcdde_times()
        except Exception as exc:  # a third-party tool: report, do not fail the benchmark
            jit = None
            print(f"JiTCDDE                                    failed: {type(exc).__name__}: {exc}")
        if jit is None:
            print("JiTCDDE                                    not installed")
        else:
            ratio = 1e3 * jit[1] / floor_ms
            print(
                f"JiTCDDE (rtol 1e-8)                        {1e3 * jit[1]:8.1f} ms = {ratio:.0f} x floor"
                f"  (+ {jit[0]:.1f} s compile)"
            )
        rate, threads = batch_rate()
        print(f"batch, 1000 tumbling states, DelayAware    {rate:8.1f} runs/s on {threads} threads (goal >= 400)")
        vm = vm_time()
        ratio = 1e3 * vm / floor_ms
        print(f"CasADi virtual machine (no compiler)       {1e3 * vm:8.1f} ms = {ratio:.1f} x floor (goal <= 10)")
    finally:
        shutil.rmtree(cold, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
