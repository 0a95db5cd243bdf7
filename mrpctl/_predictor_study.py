"""The predictor study of ``mrpctl reproduce``: settling against inertia error, with and without prediction.

The paper case at τ = 0.5 s (the paper's spacecraft, x0 = [0.93, 0, 0, 0.46/4, 0, 0], 1 kHz, 60 s,
compiled engine): the best certified PD without prediction
([`mrpctl.design.synthesize_pd`][mrpctl.design.synthesize_pd],
the decay-rate-optimal certified gain, rule ``OnCurrent``) against the predictor controller with
faster gains (ζ = 1, ωₙ = `FAST_OMEGA_N`, rule ``OnPredicted(1)``), the plant's inertia scaled
by (1 + e) while both controllers keep the nominal model. `predictor_study` returns the
table rows, the sweep, the exact inertia margins of both loops, and builds the figure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl import paper
from mrpctl._validation import finite_array, positive_scalar, readonly
from mrpctl.claims import Claim, Verdict
from mrpctl.design import linearized_loop, pd_gains, synthesize_pd
from mrpctl.errors import SpecificationError
from mrpctl.predictor import (
    MarginInterval,
    OnPredicted,
    Predictor,
    inertia_mismatch_margin,
    margin_side_bracket,
    perturbed_spacecraft,
)
from mrpctl.simulation import SimulationResult, simulate
from mrpctl.switching import OnCurrent

__all__ = ["FAST_OMEGA_N", "PredictorStudy", "StudyRow", "predictor_study"]

#: ωₙ (rad/s) of the predictor's fast gains: the fastest ζ = 1 PD whose continuous predictor loop keeps
#: a ±20 % inertia margin at τ = 0.5 s (``synthesize_predictor_pd(paper.SPACECRAFT, 0.5, mismatch=0.2,
#: rate=None)``, design/predictor.md); ten times the certified PD's ωₙ.
FAST_OMEGA_N = 12.85
#: The inertia errors of the figure: e from −20 % to +30 % in steps of 2.5 %.
DEFAULT_ERRORS = tuple(round(-0.2 + 0.025 * i, 10) for i in range(21))
#: The errors of the table rows.
TABLE_ERRORS = (0.0, 0.05, 0.1)
TAU = 0.5
RATE = 1000.0
X0 = (0.93, 0.0, 0.0, 0.46 / 4, 0.0, 0.0)


@dataclass(frozen=True)
class StudyRow:
    """One run of the study: a controller at one inertia error e (J_plant = (1 + e) J_model).

    Attributes
    ----------
    controller : str
    omega_n : float or None
        ωₙ (rad/s) of the ζ = 1 gains; None for the paper's K (one K on every axis, so ωₙ differs per axis).
    e : float
        Relative inertia error of the plant.
    settling_time : float or None
        Settling time (s; |σ| < 1e-2, |ω| < 1e-3 rad/s to the end), None if not settled in the horizon.
    switch_count : int
    peak_torque : float
        max_k |u_k|_∞ (N m).
    """

    controller: str
    omega_n: float | None
    e: float
    settling_time: float | None
    switch_count: int
    peak_torque: float

    def __str__(self) -> str:
        settled = "not settled" if self.settling_time is None else f"settles in {self.settling_time:.3f} s"
        gains = "paper K" if self.omega_n is None else f"omega_n = {self.omega_n:.6g} rad/s"
        return (
            f"{self.controller} ({gains}), e = {self.e:+.0%}: {settled}, "
            f"{self.switch_count} switch(es), peak torque {self.peak_torque:.4g} N m"
        )


@dataclass(frozen=True, eq=False)
class PredictorStudy:
    """Result of `predictor_study`.

    Attributes
    ----------
    rows : tuple of StudyRow
        Both controllers at e = 0, 5 %, 10 %, then the paper's own K with the predictor (exact model)
        and without it.
    errors : numpy.ndarray
        The e of the sweep.
    pd_settling, predictor_settling : numpy.ndarray
        Settling time (s) at each e of the sweep; NaN where the run did not settle in ``t_final``.
    pd_omega_n, predictor_omega_n : float
        ωₙ (rad/s) of the two gains.
    pd_margin, predictor_margin : MarginInterval or None
        The inertia errors each loop tolerates (exact, linearised): the PD's from the delay margin of
        the perturbed delayed loop (> τ), the predictor's from
        [`mrpctl.predictor.inertia_mismatch_margin`][mrpctl.predictor.inertia_mismatch_margin]
        (sampled at 1 kHz); None when not computed.
    t_final : float
        Horizon of every run (s).
    """

    rows: tuple[StudyRow, ...]
    errors: np.ndarray = field(repr=False)
    pd_settling: np.ndarray = field(repr=False)
    predictor_settling: np.ndarray = field(repr=False)
    pd_omega_n: float
    predictor_omega_n: float
    pd_margin: MarginInterval | None
    predictor_margin: MarginInterval | None
    t_final: float

    def table(self) -> str:
        """The rows as a Markdown table."""
        lines = [
            "| controller | omega_n (rad/s) | e | settling time (s) | switches | peak torque (N m) |",
            "|---|---|---|---|---|---|",
        ]
        for row in self.rows:
            settled = f"not settled in {self.t_final:g} s" if row.settling_time is None else f"{row.settling_time:.3f}"
            gains = "paper K" if row.omega_n is None else f"{row.omega_n:.6g}"
            lines.append(
                f"| {row.controller} | {gains} | {row.e:+.0%} | {settled} | {row.switch_count} | "
                f"{row.peak_torque:.4g} |"
            )
        return "\n".join(lines)

    def claims(self) -> list[Any]:
        """The rows as [`mrpctl.reproduction.Claim`][mrpctl.reproduction.Claim] values (verdict: mrpctl only), for
        ``claims.md``."""
        claims = []
        for row in self.rows:
            settled = "not settled" if row.settling_time is None else f"settling {row.settling_time:.3f} s"
            claims.append(
                Claim(
                    source="predictor study",
                    claim=f"{row.controller}, "
                    + ("paper K" if row.omega_n is None else f"omega_n = {row.omega_n:.4g} rad/s")
                    + f", inertia error {row.e:+.0%}",
                    measurement=f"{settled}, {row.switch_count} switch(es), peak torque {row.peak_torque:.4g} N m",
                    verdict=Verdict.EXTENDS,
                )
            )
        for name, margin in (("certified PD", self.pd_margin), ("predictor", self.predictor_margin)):
            if margin is not None:
                claims.append(
                    Claim(
                        source="predictor study",
                        claim=f"largest inertia error the {name} tolerates (exact, linearised)",
                        measurement=str(margin),
                        verdict=Verdict.EXTENDS,
                    )
                )
        return claims

    def summary(self) -> dict[str, Any]:
        """A JSON-ready dictionary (for ``summary.json``)."""

        def margin(m: MarginInterval | None) -> Any:
            return None if m is None else {"lower": m.lower, "upper": m.upper, "upper_capped": m.upper_capped}

        return {
            "rows": [row.__dict__ for row in self.rows],
            "errors": self.errors.tolist(),
            "pd_settling": [None if math.isnan(v) else v for v in self.pd_settling.tolist()],
            "predictor_settling": [None if math.isnan(v) else v for v in self.predictor_settling.tolist()],
            "pd_margin": margin(self.pd_margin),
            "predictor_margin": margin(self.predictor_margin),
        }

    def figure(self) -> Any:
        """Settling time against inertia error for both controllers (a ``matplotlib.figure.Figure``).

        Runs that do not settle within ``t_final`` are drawn as crosses at t_final; the exact margins,
        when computed, as shaded bands of tolerated e.
        """
        # deferred: matplotlib, only when a figure is made
        from matplotlib.figure import Figure

        fig = Figure(figsize=(7.0, 4.2), layout="constrained")
        ax = fig.add_subplot()
        percent = 100.0 * self.errors
        curves = (
            (self.pd_settling, f"certified PD, no prediction (omega_n = {self.pd_omega_n:.3g} rad/s)", "C0"),
            (self.predictor_settling, f"predictor, fast gains (omega_n = {self.predictor_omega_n:.4g} rad/s)", "C3"),
        )
        for values, label, color in curves:
            ax.plot(percent, values, "o-", color=color, label=label)
            missing = np.isnan(values)
            if np.any(missing):
                ax.plot(percent[missing], np.full(int(missing.sum()), self.t_final), "x", color=color, markersize=9)
        ax.axhline(self.t_final, color="0.6", linewidth=0.8, linestyle=":")
        ax.annotate(
            "x: not settled in the horizon",
            (percent[0], self.t_final),
            textcoords="offset points",
            xytext=(2, -12),
            fontsize=8,
            color="0.3",
        )
        if self.predictor_margin is not None:
            lo = max(100.0 * self.predictor_margin.lower, percent[0])
            hi = min(100.0 * self.predictor_margin.upper, percent[-1])
            ax.axvspan(lo, hi, color="C3", alpha=0.07, label="predictor: stable (exact, linearised)")
        ax.set_yscale("log")
        ax.set_xlabel("inertia error of the plant e (%), J = (1 + e) J_model")
        ax.set_ylabel("settling time (s)")
        ax.set_title(f"Paper case at tau = {TAU:g} s: settling against inertia error ({RATE:g} Hz)")
        ax.legend(fontsize=8, loc="lower left")
        ax.grid(True, which="both", alpha=0.3)
        return fig

    def __str__(self) -> str:
        lines = [f"Predictor study, paper case at tau = {TAU:g} s, {self.t_final:g} s runs at {RATE:g} Hz"]
        lines += [f"  {row}" for row in self.rows]
        if self.pd_margin is not None:
            lines.append(f"  certified PD tolerates {self.pd_margin}")
        if self.predictor_margin is not None:
            lines.append(f"  predictor tolerates {self.predictor_margin}")
        return "\n".join(lines)


def _row(controller: str, omega_n: float | None, e: float, result: SimulationResult) -> StudyRow:
    return StudyRow(controller, omega_n, e, result.settling_time, result.switch_count, result.peak_torque)


def _pd_margin(gain: np.ndarray, rtol: float) -> MarginInterval:
    """The inertia errors e for which the delayed PD loop's exact delay margin still exceeds τ."""

    def stable(e: float) -> bool:
        return bool(linearized_loop(perturbed_spacecraft(paper.SPACECRAFT, e), gain).delay_margin().margin > TAU)

    upper, upper_out, upper_capped = margin_side_bracket(stable, 1.0, 10.0, rtol)
    lower, lower_out, lower_capped = margin_side_bracket(stable, -1.0, 1.0 - 1e-3, rtol)
    return MarginInterval(lower, upper, lower_capped, upper_capped, (lower, lower_out), (upper, upper_out))


def predictor_study(
    *, t_final: float = 60.0, errors: Any = DEFAULT_ERRORS, margins: bool = True, rtol: float = 1e-3
) -> PredictorStudy:
    """Run the study (compiled engine; about 50 runs of ``t_final`` at 1 kHz, plus the margins).

    Parameters
    ----------
    t_final : float, keyword-only
        Horizon of every run (s), default 60.
    errors : array_like, keyword-only
        The inertia errors e of the sweep (each > −1), default −20 % … +30 % by 2.5 %.
    margins : bool, keyword-only
        Also compute the exact inertia margins (about half a minute on a busy machine; the
        predictor's sampled test at d = 500 dominates).
    rtol : float, keyword-only
        Relative width of the margin brackets.

    Returns
    -------
    PredictorStudy
    """

    t_final = positive_scalar("t_final", t_final)
    sweep = finite_array("errors", errors).ravel()
    if sweep.size == 0 or np.any(sweep <= -1.0):
        raise SpecificationError(f"errors: relative inertia errors must be > -1 (and at least one), got {sweep}")
    if not isinstance(margins, bool):
        raise SpecificationError(f"margins must be True or False, got {margins!r}")
    x0 = np.array(X0)
    design = synthesize_pd(paper.SPACECRAFT, TAU)
    if design.gains is None:  # pragma: no cover - the paper case is certified
        raise SpecificationError("no certified PD for the paper case at tau = 0.5 s")
    pd_gain = design.gains.K
    pd_omega_n = float(np.max(design.gains.omega_n))
    fast = pd_gains(paper.SPACECRAFT, zeta=1.0, omega_n=FAST_OMEGA_N).K
    predictor = Predictor(model=paper.SPACECRAFT)

    def pd_run(e: float, gain: np.ndarray = pd_gain) -> SimulationResult:
        plant = perturbed_spacecraft(paper.SPACECRAFT, e)
        return simulate(plant, gain, x0, tau=TAU, rule=OnCurrent(), t_final=t_final, rate=RATE, keep_every=None)

    def predictor_run(e: float, gain: np.ndarray = fast) -> SimulationResult:
        plant = perturbed_spacecraft(paper.SPACECRAFT, e)
        return simulate(
            plant,
            gain,
            x0,
            tau=TAU,
            rule=OnPredicted(1.0),
            t_final=t_final,
            rate=RATE,
            keep_every=None,
            predictor=predictor,
        )

    def settling(result: SimulationResult) -> float:
        return math.nan if result.settling_time is None else float(result.settling_time)

    pd_sweep = np.array([settling(pd_run(float(e))) for e in sweep])
    predictor_sweep = np.array([settling(predictor_run(float(e))) for e in sweep])
    rows = [_row("certified PD, no prediction", pd_omega_n, e, pd_run(e)) for e in TABLE_ERRORS]
    rows += [_row("predictor, fast gains", FAST_OMEGA_N, e, predictor_run(e)) for e in TABLE_ERRORS]
    rows.append(_row("paper K with the predictor (exact model)", None, 0.0, predictor_run(0.0, paper.GAIN)))
    rows.append(_row("paper K without prediction (OnCurrent)", None, 0.0, pd_run(0.0, paper.GAIN)))
    pd_margin = predictor_margin = None
    if margins:
        pd_margin = _pd_margin(pd_gain, rtol)
        predictor_margin = inertia_mismatch_margin(
            paper.SPACECRAFT, fast, TAU, rate=RATE, per_axis=False, rtol=rtol
        ).uniform
    return PredictorStudy(
        rows=tuple(rows),
        errors=readonly(sweep),
        pd_settling=readonly(pd_sweep),
        predictor_settling=readonly(predictor_sweep),
        pd_omega_n=pd_omega_n,
        predictor_omega_n=FAST_OMEGA_N,
        pd_margin=pd_margin,
        predictor_margin=predictor_margin,
        t_final=t_final,
    )
