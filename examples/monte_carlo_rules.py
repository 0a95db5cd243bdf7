"""Monte-Carlo of tumbling initial states: how each switching rule copes with the delay.

Run with ``python examples/monte_carlo_rules.py [COUNT]`` (default 200). The paper's
spacecraft, gains and tau = 0.5 s; random axes, angles of 160-179 deg and rates of
0.5-1.2 rad/s towards 180 deg; 60 s each, run in parallel with ``simulate_batch``.
"""

from __future__ import annotations

import sys

import numpy as np

from mrpctl import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, paper, simulate_batch
from mrpctl.scenario import tumbling_states

T_FINAL = 60.0
LATE = 10.0  # s: a switch in the last LATE seconds counts as "still switching"


def main(count: int) -> None:
    x0 = tumbling_states(count, seed=1)
    rules = (NoSwitching(), OnCurrent(), OnDelayed(), BoundaryLayer(eps=0.005), DelayAware(), DelayAware(alpha=1.1))
    print(f"{count} tumbling states, tau = {paper.TAU} s, {T_FINAL:g} s each")
    print(f"{'rule':<60} {'switched':>9} {'still switching':>16} {'converged':>10} {'median switches':>16}")
    for rule in rules:
        batch = simulate_batch(paper.SPACECRAFT, paper.GAIN, x0, tau=paper.TAU, rule=rule, t_final=T_FINAL)
        late = np.nan_to_num(batch.last_switch_time, nan=-np.inf) > T_FINAL - LATE
        print(
            f"{rule!s:<60.60} {np.mean(batch.switch_count > 0):>9.0%} {np.mean(late):>16.0%} "
            f"{np.mean(batch.converged):>10.0%} {np.median(batch.switch_count):>16g}"
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
