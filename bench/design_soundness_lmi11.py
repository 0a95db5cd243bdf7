"""Soundness of the interval and sampled-data criteria on 200 seeded random systems (issue 11).

Run: python bench/design_soundness_lmi11.py. Prints the count checked and any violation (none expected):
a certificate for tau(t) in [0, h] above the exact constant-delay margin, or a certified sampling period
that the exact lifted system calls unstable.
"""

from __future__ import annotations

import numpy as np

from mrpctl.design import delay_margin
from mrpctl.design.interval import certify_interval
from mrpctl.design.sampled import certify_sampled, sampled_stability


def main(count: int = 200) -> None:
    rng = np.random.default_rng(20261201)
    checked = certified = violations = 0
    while checked < count:
        a = rng.normal(size=(2, 2))
        a_d = rng.normal(size=(2, 2))
        exact = delay_margin(a, a_d)
        if not exact.stable_without_delay or not np.isfinite(exact.margin):
            continue
        rate = (0.0, 0.3, None)[checked % 3]
        if certify_interval(a, a_d, 1.01 * exact.margin, rate=rate, order=checked % 3).certified:
            violations += 1
        certified += certify_interval(a, a_d, 0.3 * exact.margin, rate=rate, order=1).certified
        b = rng.normal(size=(2, 1))
        k = rng.normal(size=(1, 2))
        for h in (0.05, 0.2, 0.8):
            cert = certify_sampled(a, b, k, h, order=1)
            if cert.certified and not sampled_stability(a, b, k, h).stable:
                violations += 1
        checked += 1
    print(f"{checked} systems, {certified} certified at 0.3 x margin, {violations} violations")


if __name__ == "__main__":
    main()
