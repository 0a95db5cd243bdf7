"""Timings of the design module: max_certified_delay per criterion on the paper's loop, and the lmi.md table.

Run with ``python bench/design.py`` (``--skip-full-rebuild`` leaves out the slowest column: the
6x6 loop rebuilt at every delay). Prints, for Jensen (N=0), Wirtinger (N=1) and Bessel-Legendre
N=2, 3:

- per axis: the limiting J = 80 kg m^2 axis as a 2x2 problem;
- the loop split into its three axes (``LinearizedLoop.max_certified_delay``);
- the full 6x6 problem;

each with the DPP-compiled problem (warm: compiled once, reused; cold: compile included) and
rebuilt from constants at every delay ("no DPP"). Then the measured table of certified delay vs
exact margin for the classic benchmark, the scalar pure delay and the paper's loop.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from mrpctl import paper
from mrpctl.design import (
    Positivity,
    criterion_name,
    delay_margin,
    linearized_loop,
    max_certified_delay,
)
from mrpctl.design import lmi as lmi_module

ORDERS = (0, 1, 2, 3)


def _timed(fn, *args, **kwargs):
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


def timings(skip_full_rebuild: bool) -> None:
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    a_axis, a_d_axis = loop.axes[2]  # J = 80 kg m^2: the limiting axis
    print("max_certified_delay on the paper's loop (J = diag(140, 100, 80), K as printed), rtol = 1e-4")
    print("times in s; warm = compiled problem reused, cold = compile included, no DPP = rebuilt per delay\n")
    header = (
        f"{'criterion':<22}{'axis warm':>10}{'axis cold':>10}{'axis noDPP':>11}"
        f"{'3 axes warm':>12}{'6x6 warm':>10}{'6x6 cold':>10}{'6x6 noDPP':>10}{'solves':>8}{'tau (s)':>10}"
    )
    print(header)
    print("-" * len(header))
    for order in ORDERS:
        lmi_module._compiled.cache_clear()
        _, axis_cold = _timed(max_certified_delay, a_axis, a_d_axis, order=order)
        axis_r, axis_warm = _timed(max_certified_delay, a_axis, a_d_axis, order=order)
        _, axis_rebuild = _timed(max_certified_delay, a_axis, a_d_axis, order=order, parametric=False)
        _, split_warm = _timed(loop.max_certified_delay, order=order)
        _, full_cold = _timed(max_certified_delay, loop.A, loop.A_d, order=order)
        full_r, full_warm = _timed(max_certified_delay, loop.A, loop.A_d, order=order)
        if skip_full_rebuild:
            full_rebuild_text = f"{'skipped':>10}"
        else:
            _, full_rebuild = _timed(max_certified_delay, loop.A, loop.A_d, order=order, parametric=False)
            full_rebuild_text = f"{full_rebuild:>10.3f}"
        assert abs(full_r.upper - axis_r.upper) <= 2e-4 * axis_r.upper
        print(
            f"{criterion_name(order):<22}{axis_warm:>10.3f}{axis_cold:>10.3f}{axis_rebuild:>11.3f}"
            f"{split_warm:>12.3f}{full_warm:>10.3f}{full_cold:>10.3f}{full_rebuild_text}"
            f"{axis_r.solves:>8d}{axis_r.upper:>10.5f}"
        )
    print()


def table() -> None:
    systems = {
        "classic benchmark": (np.array([[-2.0, 0.0], [0.0, -0.9]]), np.array([[-1.0, 0.0], [-1.0, -1.0]])),
        "xdot = -x(t - tau)": (np.array([[0.0]]), np.array([[-1.0]])),
    }
    loop = linearized_loop(paper.SPACECRAFT, paper.GAIN)
    print("| system | criterion | positivity | certified tau (s) | exact tau (s) | ratio | time (s) |")
    print("|---|---|---|---|---|---|---|")
    for name, (a, a_d) in systems.items():
        exact = delay_margin(a, a_d).margin
        for order in ORDERS:
            for positivity in (Positivity.STRICT, Positivity.RELAXED):
                if order == 0 and positivity is Positivity.RELAXED:
                    continue  # identical to STRICT at N = 0
                max_certified_delay(a, a_d, order=order, positivity=positivity)  # compile
                result, seconds = _timed(max_certified_delay, a, a_d, order=order, positivity=positivity)
                print(
                    f"| {name} | {criterion_name(order)} | {positivity.name.lower()} | {result.upper:.5f} "
                    f"| {exact:.5f} | {result.upper / exact:.5f} | {seconds:.3f} |"
                )
    exact = loop.delay_margin().margin
    for order in ORDERS:
        loop.max_certified_delay(order=order)
        result, seconds = _timed(loop.max_certified_delay, order=order)
        print(
            f"| paper loop (3 axes) | {criterion_name(order)} | relaxed | {result.upper:.5f} | {exact:.5f} "
            f"| {result.upper / exact:.5f} | {seconds:.3f} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--skip-full-rebuild", action="store_true", help="skip the 6x6 no-DPP column")
    args = parser.parse_args()
    timings(args.skip_full_rebuild)
    table()


if __name__ == "__main__":
    main()
