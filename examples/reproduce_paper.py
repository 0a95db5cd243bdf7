"""Reproduce the paper through the API: every scenario, the claims table and the figures.

Run with ``python examples/reproduce_paper.py [OUT_DIR]`` (default ``results``). The
same as ``mrpctl reproduce``, spelled out: scenarios -> simulate -> plots -> claims.
"""

from __future__ import annotations

import sys
from pathlib import Path

from mrpctl import plots
from mrpctl.reproduction import paper_scenarios, reproduce


def main(out_dir: Path) -> None:
    # One scenario by hand: the chattering case of paper Figs. 4-5.
    scenario = paper_scenarios()["paper_fig4_on_delayed"]
    print(scenario)
    result = scenario.simulate()
    print(result)
    plots.save_figure(plots.plot_attitude(result, window=(59.9, 60.0)), out_dir / "on_delayed_zoom.png")

    # All of them, with the claims table (claims.md) and summary.json.
    reproduction = reproduce(out_dir)
    print(reproduction)


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("results"))
