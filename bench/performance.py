"""The tables of design/performance.md: the paper spacecraft at tau = 0.5 s, with the paper's gains and with the
H-infinity-optimal PD gains (spectral abscissa, margins, H-infinity torque -> attitude exact and certified, H2,
a pointing budget), each with the time it took.

Run with ``OPENBLAS_NUM_THREADS=1 python bench/performance.py`` (one BLAS thread: on a shared two-core machine
the threaded eigenvalue solver was ten times slower). Prints Markdown.
"""

# ruff: noqa: E501  (Markdown table rows are one line each)

from __future__ import annotations

import math
import time

from mrpctl import paper
from mrpctl.design import delay_margin, linearized_loop
from mrpctl.design.performance import (
    hinf_bound,
    hinf_norm,
    spacecraft_margins,
)
from mrpctl.design.pointing import (
    h2_norm,
    pointing_budget,
    synthesize_hinf_pd,
    torque_to_attitude,
)
from mrpctl.design.spectra import characteristic_roots

TAU = paper.TAU
#: The stated budget: torque disturbance PSD (N^2 m^2/Hz), attitude sensor ASD (rad/sqrt Hz), rate ASD.
TORQUE_PSD = 1e-6
ATTITUDE_ASD = 1e-5
RATE_ASD = 1e-6


def _timed(fn, *args, **kwargs):
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


def rows(name: str, gain) -> list[str]:
    loop = linearized_loop(paper.SPACECRAFT, gain)
    a, a_d, b, c = torque_to_attitude(paper.SPACECRAFT, gain)
    spectrum, t_sp = _timed(characteristic_roots, loop.A, loop.A_d, TAU, count=6)
    margins, t_m = _timed(spacecraft_margins, paper.SPACECRAFT, gain, TAU)
    exact_margin, t_dm = _timed(delay_margin, loop.A, loop.A_d)
    hinf, t_h = _timed(hinf_norm, a, a_d, TAU, b, c)
    out = [
        f"| {name} | spectral abscissa (1/s) | {spectrum.abscissa:.8g} ({'certified' if spectrum.certified else 'NOT certified'}, N = {spectrum.nodes}) | {1e3 * t_sp:.0f} |",
        f"| {name} | gain margin, coupled loop | {margins.coupled.gain_margin:.6g} ({margins.coupled.gain_margin_db:.4g} dB) at {margins.coupled.phase_crossover:.5g} rad/s | {1e3 * t_m:.0f} (all margins) |",
        f"| {name} | phase margin, coupled loop | {math.degrees(margins.coupled.phase_margin):.5g} deg at {margins.coupled.gain_crossover:.5g} rad/s | |",
        f"| {name} | delay margin beyond tau | {margins.coupled.delay_margin:.6g} s (tau + it = {TAU + margins.coupled.delay_margin:.6g} s; exact crossing method {exact_margin.margin:.6g} s) | {1e3 * t_dm:.0f} (crossing method) |",
    ]
    for i, axis in enumerate(margins.axes):
        out.append(
            f"| {name} | axis {i + 1} (J = {paper.INERTIA[i]:g}) | GM {axis.gain_margin:.5g} at {axis.phase_crossover:.4g} rad/s, "
            f"PM {math.degrees(axis.phase_margin):.4g} deg at {axis.gain_crossover:.4g} rad/s, DM +{axis.delay_margin:.5g} s | |"
        )
    out.append(
        f"| {name} | H-infinity torque -> 4 sigma, exact (rad/(N m)) | {hinf.value:.10g} at {hinf.frequency:.5g} rad/s | {1e3 * t_h:.0f} |"
    )
    for order in (1, 2, 3):
        bound, t_b = _timed(hinf_bound, a, a_d, TAU, b, c, order=order)
        ratio = hinf.value / bound.value if bound.certified else math.nan
        out.append(
            f"| {name} | H-infinity certified, Bessel-Legendre N = {order} | {bound.value:.10g} "
            f"({'certified' if bound.certified else 'not certified'}; exact/certified = {ratio:.6f}) | {1e3 * t_b:.0f} |"
        )
    h2, t_h2 = _timed(h2_norm, a, a_d, TAU, b, c)
    out.append(
        f"| {name} | H2 torque -> 4 sigma (rad/(N m) s^-1/2) | {h2.value:.10g} (residual {h2.residual:.1e}) | {1e3 * t_h2:.0f} |"
    )
    budget, t_pb = _timed(
        pointing_budget,
        paper.SPACECRAFT,
        gain,
        TAU,
        torque_psd=TORQUE_PSD,
        attitude_noise=ATTITUDE_ASD,
        rate_noise=RATE_ASD,
    )
    axes = ", ".join(f"{v:.4g}" for v in budget.three_sigma)
    out.append(
        f"| {name} | pointing 3-sigma per axis / total (arcsec) | {axes} / {budget.total_three_sigma:.4g} | {1e3 * t_pb:.0f} |"
    )
    return out


def main() -> None:
    print("| gains | quantity | value | time (ms) |")
    print("|---|---|---|---|")
    for line in rows("paper K", paper.GAIN):
        print(line)
    synthesis, t_syn = _timed(synthesize_hinf_pd, paper.SPACECRAFT, TAU)
    for line in rows("H-inf PD", synthesis.K):
        print(line)
    print()
    print(
        f"H-infinity PD synthesis: omega_n = {synthesis.omega_n:.6g} rad/s, zeta = {synthesis.zeta:.5g} "
        f"({synthesis.evaluations} exact H-infinity evaluations, {t_syn:.1f} s, certified N = 2: "
        f"{synthesis.certified.value:.8g} vs exact {synthesis.exact.value:.8g})"
    )


if __name__ == "__main__":
    main()
