"""The synthesis comparison of design/performance.md: the paper spacecraft at tau = 0.5 s and the cubesat
(J = diag(0.2, 0.25, 0.15) kg m^2) at tau = 0.2 s, under the LMI-decay designs (synthesize_pd, synthesize_lmi) and
the performance designs (H-infinity / H2 / decay-optimal PD and PID, full-matrix refinement), plus the sampled loop
of the paper spacecraft.

Run with ``OPENBLAS_NUM_THREADS=1 python bench/synthesis_comparison.py`` (several minutes; ``--sampled``: only the
sampled loop's table). Prints Markdown.
"""

# ruff: noqa: E501  (Markdown table rows are one line each)

from __future__ import annotations

import math
import time

import numpy as np

from mrpctl import paper
from mrpctl.design import synthesize_lmi, synthesize_pd
from mrpctl.design.fixed_order import pid_loop, refine_full_gain, synthesize_fixed_order
from mrpctl.design.performance import hinf_bound, hinf_norm, loop_margins_delayed
from mrpctl.design.pointing import h2_norm, pointing_budget, torque_to_attitude
from mrpctl.design.sampled_performance import sampled_h2_norm, sampled_hinf_norm, sampled_l2_gain
from mrpctl.design.spectra import spectral_abscissa
from mrpctl.model import gain_matrix
from mrpctl.spacecraft import Spacecraft

CUBESAT = Spacecraft(np.diag([0.2, 0.25, 0.15]))
#: Budgets: torque PSD (N^2 m^2/Hz), attitude ASD (rad/sqrt Hz), rate ASD (rad/s/sqrt Hz).
BUDGETS = {"paper": (1e-6, 1e-5, 1e-6), "cubesat": (1e-12, 1e-5, 1e-6)}


def _timed(fn, *args, **kwargs):
    start = time.perf_counter()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - start


def row(case: str, sc: Spacecraft, tau: float, name: str, k: np.ndarray, k_i=None, seconds: float = math.nan) -> str:
    if k_i is None:
        a, a_d, b, c = torque_to_attitude(sc, k)
        gain, bu = gain_matrix(k), b
    else:
        a, bu, b, c, gain = pid_loop(sc, k, k_i)
        a_d = bu @ gain
    abscissa = spectral_abscissa(a, a_d, tau)
    margins = loop_margins_delayed(a, bu, gain, tau)
    exact = hinf_norm(a, a_d, tau, b, c)
    bound = hinf_bound(a, a_d, tau, b, c, order=2)
    ratio = exact.value / bound.value if bound.certified else math.nan
    h2 = h2_norm(a, a_d, tau, b, c)
    if k_i is None:
        g, at, rt = BUDGETS[case]
        budget = pointing_budget(sc, k, tau, torque_psd=g, attitude_noise=at, rate_noise=rt)
        pointing = f"{budget.total_three_sigma:.4g}"
    else:
        pointing = "n/a"
    return (
        f"| {case} | {name} | {abscissa:.5g} | {margins.gain_margin:.4g} | {math.degrees(margins.phase_margin):.4g} | "
        f"{margins.delay_margin:.4g} | {exact.value:.6g} | {bound.value:.6g} ({ratio:.5f}) | {h2.value:.6g} | {pointing} | "
        f"{seconds:.1f} |"
    )


def comparison(case: str, sc: Spacecraft, tau: float) -> list[str]:
    out = []
    if case == "paper":
        out.append(row(case, sc, tau, "paper K", np.array(paper.GAIN), seconds=0.0))
    pd1, t = _timed(synthesize_pd, sc, tau, zeta=1.0)
    out.append(
        row(case, sc, tau, f"LMI-decay PD, zeta = 1 (alpha = {pd1.decay_rate:.4g} certified)", pd1.gains.K, seconds=t)
    )
    pdf, t = _timed(synthesize_pd, sc, tau, zeta=None, allow_underdamped=True)
    out.append(
        row(case, sc, tau, f"LMI-decay PD, zeta free (alpha = {pdf.decay_rate:.4g} certified)", pdf.gains.K, seconds=t)
    )
    alpha = 0.5 * pd1.decay_rate
    lmi, t = _timed(synthesize_lmi, sc, tau, decay_rate=alpha)
    if lmi.K is not None:
        out.append(row(case, sc, tau, f"LMI state feedback, alpha = {alpha:.4g}", np.array(lmi.K), seconds=t))
    for structure, objective in (("pd", "hinf"), ("pd", "h2"), ("pid", "abscissa")):
        syn, t = _timed(synthesize_fixed_order, sc, tau, structure=structure, objective=objective, order=None)
        norm = ", ".join(f"{v:.5g}" for v in syn.normalised)
        out.append(row(case, sc, tau, f"{structure.upper()}-{objective} ({norm})", syn.K, syn.K_i, seconds=t))
        if (structure, objective) == ("pd", "hinf"):
            hinf_pd = syn
    a, _, b, c = torque_to_attitude(sc, pd1.gains.K)
    full, t = _timed(refine_full_gain, a, b, pd1.gains.K, tau, b, c)
    out.append(row(case, sc, tau, f"full matrix, BFGS from LMI-decay PD ({full.iterations} it.)", full.K, seconds=t))
    full2, t = _timed(refine_full_gain, a, b, hinf_pd.K, tau, b, c)
    out.append(row(case, sc, tau, f"full matrix, BFGS from PD-hinf ({full2.iterations} it.)", full2.K, seconds=t))
    return out


def sampled_rows() -> list[str]:
    a, _, b, c = torque_to_attitude(paper.SPACECRAFT, paper.GAIN)
    k = gain_matrix(paper.GAIN)
    out = []
    for rate in (10, 20, 100, 200):
        h = 1.0 / rate
        d = round(paper.TAU / h)
        h2, t2 = _timed(sampled_h2_norm, a, b, k, h, delay_samples=d, C=c)
        hi, ti = _timed(sampled_hinf_norm, a, b, k, h, delay_samples=d, C=c)
        l2, tl = _timed(sampled_l2_gain, a, b, k, h, delay_samples=d, C=c)
        samples = math.sqrt(float(np.trace(h2.sample_covariance)))
        out.append(
            f"| {rate} Hz, d = {d} | {h2.value:.8g} ({1e3 * t2:.0f} ms) | {samples:.8g} | {hi.value:.8g} at {hi.frequency:.4g} rad/s ({1e3 * ti:.0f} ms) "
            f"| {l2.value:.8g} at {l2.frequency:.4g} rad/s, {'certified' if l2.bracket_certified else 'NOT certified'} ({1e3 * tl:.0f} ms) |"
        )
    return out


def main() -> None:
    import sys

    if sys.argv[1:] == ["--sampled"]:
        print(
            "| sampled paper loop | H2 period-averaged | H2 at the samples | H-inf, held torque | L2 gain, continuous torque and attitude |"
        )
        print("|---|---|---|---|---|")
        for line in sampled_rows():
            print(line, flush=True)
        return
    print(
        "| case | gains | abscissa (1/s) | GM | PM (deg) | DM (s) | H-inf exact | certified N = 2 (ratio) | H2 | 3-sigma total (arcsec) | synthesis (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for line in comparison("paper", paper.SPACECRAFT, paper.TAU):
        print(line, flush=True)
    for line in comparison("cubesat", CUBESAT, 0.2):
        print(line, flush=True)
    print()
    print(
        "| sampled paper loop | H2 period-averaged | H2 at the samples | H-inf, held torque | L2 gain, continuous torque and attitude |"
    )
    print("|---|---|---|---|---|")
    for line in sampled_rows():
        print(line, flush=True)


if __name__ == "__main__":
    main()
