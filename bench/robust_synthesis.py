"""Robust synthesis table of design/lmi.md section 7.8 (paper spacecraft, tau = 0.5 s).

For every delay / inertia set: the largest decay rate alpha for which ``synthesize_lmi`` returns
SYNTHESIZED (bisection on alpha to 2 % relative width; every probe is a full synthesis with its
re-verification), the synthesized per-axis loop gains at that alpha, the time of one synthesis,
and the ``synthesize_pd`` robust design (omega_n) for the same set.

Run: ``python bench/robust_synthesis.py [row ...]`` (rows: see ROWS);
prints one Markdown row per set.
"""

from __future__ import annotations

import sys
import time
from typing import Any

from mrpctl import paper
from mrpctl.design import synthesize_lmi, synthesize_pd
from mrpctl.design.synthesis import SynthesisStatus
from mrpctl.model import pd_from_gain

TAU = 0.5
ROWS: dict[str, tuple[str, dict[str, Any], int]] = {
    "nominal": ("nominal", {}, 1),
    "nominal0": ("nominal", {}, 0),
    "pb": ("+-5 % and |J_ij| <= 0.5 kg m^2 (6x6, 64 vertices)", {"tolerance": 0.05, "product_bound": 0.5}, 0),
    "tol5": ("+-5 % inertia", {"tolerance": 0.05}, 1),
    "tol10": ("+-10 % inertia", {"tolerance": 0.10}, 1),
    "tol20": ("+-20 % inertia", {"tolerance": 0.20}, 1),
    "s1k": ("sampled 1 kHz (d = 500)", {"period": 1e-3}, 0),
    "s1k1": ("sampled 1 kHz (d = 500)", {"period": 1e-3}, 1),
    "s10": ("sampled 10 Hz (d = 5)", {"period": 0.1}, 1),
    "jit": ("jitter [0.4, 0.5] s, rate unknown", {"tau_min": 0.4}, 1),
}


def largest_alpha(kwargs: dict, order: int) -> tuple[float, object, float, int]:
    good, good_res, bad = 0.0, None, 1.2 / TAU  # alpha tau = 0.6 > 2 - sqrt(2): no PD loop decays that fast
    times = []
    res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=0.0, order=order, **kwargs)
    if res.status is not SynthesisStatus.SYNTHESIZED:
        return float("nan"), res, 0.0, 1
    good_res = res
    probes = 1
    lo_alpha = 0.0
    while bad - lo_alpha > 0.02 * max(lo_alpha, 0.05):
        mid = 0.5 * (lo_alpha + bad)
        start = time.perf_counter()
        res = synthesize_lmi(paper.SPACECRAFT, TAU, decay_rate=mid, order=order, **kwargs)
        times.append(time.perf_counter() - start)
        probes += 1
        if res.status is SynthesisStatus.SYNTHESIZED:
            lo_alpha, good_res = mid, res
        else:
            bad = mid
    good = lo_alpha
    return good, good_res, sum(times) / max(len(times), 1), probes


def main(names: list[str]) -> None:
    for name in names:
        label, kwargs, order = ROWS[name]
        alpha, res, seconds, probes = largest_alpha(kwargs, order)
        gains = "-"
        if getattr(res, "K", None) is not None:
            k1, k2 = pd_from_gain(paper.SPACECRAFT, res.K)  # type: ignore[attr-defined]
            gains = f"{k1[0, 0]:.4f}, {k2[0, 0]:.4f}"
        start = time.perf_counter()
        pd = (
            synthesize_pd(paper.SPACECRAFT, TAU, order=order, **kwargs)
            if kwargs
            else synthesize_pd(paper.SPACECRAFT, TAU, order=order)
        )
        pd_time = time.perf_counter() - start
        print(
            f"| {label} | N = {order} | {alpha:.4g} | {gains} | {res.epsilon:.3g} | "  # type: ignore[attr-defined]
            f"{seconds:.1f} ({probes} syntheses) | {pd.omega_n:.6g} ({pd.status.name}) | {pd_time:.1f} |",
            flush=True,
        )
        print(f"    {res}".replace("\n", "\n    "), flush=True)
        print(f"    {pd}".replace("\n", "\n    "), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:] or list(ROWS))
