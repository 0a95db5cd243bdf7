"""The numeric tables of design/predictor.md ("The paper case at τ = 0.5 s"), computed from the code.

Every number of the three generated blocks comes from mrpctl as it is: the inertia margins from
``inertia_mismatch_margin`` (and the PD's from ``mrpctl._predictor_study``) with brackets of relative
width ``RTOL`` = 1e-5, printed to 0.01 % only where both ends of the bracket round alike (otherwise
this script stops: print more digits); the settling times, switch counts and peak torques from the
compiled engine (``simulate``). The page's blocks sit between ``<!-- predictor_tables: NAME -->`` and
``<!-- /predictor_tables -->``; ``tests/test_predictor_tables.py`` checks that the page holds exactly
what this script writes.

``python bench/predictor_tables.py``          print the blocks
``python bench/predictor_tables.py --write``  rewrite them in design/predictor.md (about 20 s)
"""

from __future__ import annotations

import math
import re
import sys
from pathlib import Path

import numpy as np

from mrpctl import OnPredicted, Predictor, paper, simulate
from mrpctl._predictor_study import predictor_study
from mrpctl.design import pd_gains
from mrpctl.predictor import MarginInterval, inertia_mismatch_margin, perturbed_spacecraft
from mrpctl.simulation import SimulationResult

PAGE = Path(__file__).resolve().parents[1] / "design" / "predictor.md"
RTOL = 1e-5
TAU = 0.5
X0 = np.array([0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0])
#: ωₙ (rad/s) of the predictor table's rows and what each is
GAINS = (
    (3.0, ""),
    (12.85, " (fastest for ±20 %, continuous design)"),
    (31.925, " (fastest for ±10 %, continuous design)"),
)
#: the e of the predictor table's settling columns, in the page's order
PREDICTOR_ERRORS = (0.0, 0.05, 0.1, -0.05, -0.1)
#: the e of the certified PD's sweep
PD_ERRORS = (-0.2, -0.1, -0.05, 0.0, 0.05, 0.1, 0.2, 0.3)
BLOCK = re.compile(r"(<!-- predictor_tables: (\S+) -->\n)(.*?)(<!-- /predictor_tables -->)", re.S)


def percent(value: float) -> str:
    """e as the page prints it: 0.01 % with a true minus sign."""
    return f"{100.0 * value:+.2f} %".replace("-", "−")


def end(value: float, capped: bool, bracket: tuple[float, float] | None) -> str:
    """One end of a margin: the limit (``> +1000 %``), or the boundary to 0.01 % (both bracket ends round alike)."""
    if capped:
        return f"> {100.0 * value:+.0f} %"
    assert bracket is not None
    printed = {percent(b) for b in bracket}
    if len(printed) != 1:
        raise SystemExit(f"the bracket {bracket} does not fix 0.01 %: print more digits or lower RTOL")
    return printed.pop()


def interval(m: MarginInterval) -> str:
    """A margin as the page prints it: (lower, upper)."""
    lo = end(m.lower, m.lower_capped, m.lower_bracket)
    hi = end(m.upper, m.upper_capped, m.upper_bracket)
    return f"({lo}, {hi})"


def _settling(run: SimulationResult) -> str:
    t = run.settling_time
    if t is not None:
        return f"{t:.2f} s"
    switches = int(run.switch_count)
    return "not settled in 20 s" + (f" ({switches} switches)" if switches else "")


def predictor_block() -> str:
    """The predictor at 100 Hz, 20 s, ``OnPredicted(1)``, exact model: margins at 1 kHz and 100 Hz, settling."""
    lines = [
        "| gains | margin (sampled, 1 kHz) | margin (100 Hz, the rate simulated) | settling e = 0 | e = +5 % "
        "| e = +10 % | e = −5 % | e = −10 % | max \\|u\\| (N m) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    model = Predictor(model=paper.SPACECRAFT)
    for omega_n, note in GAINS:
        k = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=omega_n).K
        fast, slow = (
            inertia_mismatch_margin(paper.SPACECRAFT, k, TAU, rate=rate, per_axis=False, rtol=RTOL).uniform
            for rate in (1000.0, 100.0)
        )
        cells, peak = [], 0.0
        for e in PREDICTOR_ERRORS:
            run = simulate(
                perturbed_spacecraft(paper.SPACECRAFT, e), k, X0, tau=TAU, rate=100.0, t_final=20.0,
                rule=OnPredicted(1.0), predictor=model, keep_every=None,
            )  # fmt: skip
            cell = _settling(run)
            if run.settling_time is None and not slow.lower < e < slow.upper:
                cell += ", outside the 100 Hz margin"
            cells.append(cell)
            peak = max(peak, float(run.peak_torque))
        exponent = math.floor(math.log10(peak))
        lines.append(
            f"| ωₙ = {omega_n:g} rad/s{note} | {interval(fast)} | {interval(slow)} | "
            + " | ".join(cells)
            + f" | {peak / 10**exponent:.1f}e{exponent} |"
        )
    return "\n".join(lines)


def _study_settling(t: float | None) -> str:
    return "not settled in 60 s" if t is None else f"{t:.3f} s"


def study_blocks() -> tuple[str, str]:
    """The certified PD's sweep (with its tolerated e) and the study's table (compiled engine, 1 kHz, 60 s)."""
    study = predictor_study(errors=PD_ERRORS, margins=True, rtol=RTOL)
    assert study.pd_margin is not None and study.predictor_margin is not None
    pd_cells = " | ".join("not settled" if math.isnan(t) else f"{t:.3f}" for t in study.pd_settling)
    heads = " | ".join("0" if e == 0 else percent(e).replace(".00", "") for e in PD_ERRORS)
    rows = {(r.controller, r.e): r for r in study.rows}
    pd_rows = [rows["certified PD, no prediction", e] for e in (0.0, 0.05, 0.1)]
    pd_switches = sorted({r.switch_count for r in pd_rows})
    sweep = "\n".join(
        [
            f"| e | {heads} |",
            "|---|" + "---|" * len(PD_ERRORS),
            f"| settling (s) | {pd_cells} |",
            "",
            f"Switches at e = 0, +5 %, +10 %: {', '.join(map(str, pd_switches))}; peak torque "
            f"{max(r.peak_torque for r in pd_rows):.0f} N m. It tolerates e ∈ {interval(study.pd_margin)}: "
            "the exact delay margin of the perturbed delayed loop stays above τ (`_predictor_study._pd_margin`).",
        ]
    )

    def row(controller: str, shown: str, omega_n: str, margin: str) -> str:
        cells = [
            _study_settling(rows[controller, e].settling_time)
            + (f", {rows[controller, e].switch_count} switch" if rows[controller, e].switch_count else "")
            for e in (0.0, 0.05, 0.1)
        ]
        return f"| {shown} | {omega_n} | {' | '.join(cells)} | {margin} |"

    table = "\n".join(
        [
            "| controller | ωₙ (rad/s) | e = 0 | e = +5 % | e = +10 % | tolerated e (exact, linearised) |",
            "|---|---|---|---|---|---|",
            row(
                "certified PD, no prediction",
                "certified PD, no prediction (`OnCurrent`)",
                f"{study.pd_omega_n:.4f}",
                interval(study.pd_margin),
            ),
            row(
                "predictor, fast gains",
                "predictor, fast gains (`OnPredicted(1)`)",
                f"{study.predictor_omega_n:g}",
                f"{interval(study.predictor_margin)} (1 kHz)",
            ),
        ]
        + [
            f"| {shown} | paper K | {_study_settling(r.settling_time)}, "
            f"{r.switch_count} switch{'es' * (r.switch_count != 1)} | | | |"
            for shown, r in (
                ("paper K with the predictor (exact model)", rows["paper K with the predictor (exact model)", 0.0]),
                ("paper K without prediction (`OnCurrent`)", rows["paper K without prediction (OnCurrent)", 0.0]),
            )
        ]
    )
    return sweep, table


def blocks() -> dict[str, str]:
    """Every generated block of the page, by name."""
    sweep, study = study_blocks()
    return {"pd-sweep": sweep, "predictor": predictor_block(), "study": study}


def page_blocks(text: str) -> dict[str, str]:
    """The generated blocks as the page holds them, by name."""
    return {m.group(2): m.group(3).rstrip("\n") for m in BLOCK.finditer(text)}


def rewrite(text: str, new: dict[str, str]) -> str:
    """The page with every block replaced by ``new[name]``."""
    return BLOCK.sub(lambda m: m.group(1) + new[m.group(2)] + "\n" + m.group(4), text)


def main(argv: list[str]) -> None:
    new = blocks()
    if "--write" in argv:
        text = PAGE.read_text(encoding="utf-8")
        if set(page_blocks(text)) != set(new):
            raise SystemExit(f"{PAGE} holds blocks {sorted(page_blocks(text))}, expected {sorted(new)}")
        PAGE.write_text(rewrite(text, new), encoding="utf-8")
        print(f"wrote {len(new)} blocks into {PAGE}")
    else:
        for name, block in new.items():
            print(f"<!-- predictor_tables: {name} -->\n{block}\n<!-- /predictor_tables -->\n")


if __name__ == "__main__":
    main(sys.argv[1:])
