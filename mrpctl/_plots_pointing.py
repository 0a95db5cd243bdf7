"""The pointing error of a tracking run (`plot_pointing`, re-exported by [`mrpctl.plots`][mrpctl.plots])."""

from __future__ import annotations

import textwrap
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from mrpctl._plots_common import legend_outside, new_axes, rule_words, typeset
from mrpctl.errors import SpecificationError

__all__ = ["plot_pointing"]


def plot_pointing(result: Any, *, title: str | None = None, ax: Any = None) -> Figure:
    """The pointing error Φ_B/R (deg, log scale) of a tracking run against t, with the tolerance band.

    Φ_B/R = 4 atan|σ_B/R| is the true error between the body and the reference (not the error the
    controller formed from its delayed measurement). The band below the slew-time tolerance is shaded,
    the slew time (Φ within the tolerance from then on) and the settling time are marked.

    Parameters
    ----------
    result : SimulationResult
        A tracking run of [`mrpctl.simulate`][mrpctl.simulation.simulate] (``reference=``) with its
        trajectory kept.
    title : str, optional
        Figure title; by default the rule, the delay and the pointing figures after settling.
    ax : matplotlib.axes.Axes, optional
        The axes to draw in; a new figure by default.

    Returns
    -------
    matplotlib.figure.Figure
    """
    error = getattr(result, "pointing_error", None)
    if error is None:
        raise SpecificationError(
            "result: plot_pointing needs a tracking run (simulate(..., reference=...)) with its trajectory kept "
            "(keep_every is not None)"
        )
    fig, (axis,) = new_axes(1, ax, figsize=(8.0, 3.6))
    t = np.asarray(result.t)[: len(error)]
    phi = np.asarray(error, dtype=float)
    floor = max(float(np.max(phi)) * 1e-12, 1e-12) if np.any(phi > 0) else 1e-12
    axis.semilogy(t, np.maximum(phi, floor), color="C0", linewidth=1.0, label="pointing error Φ_B/R")
    tolerance = getattr(result, "pointing_tolerance", None)
    if tolerance is not None:
        axis.axhspan(floor, tolerance, color="C2", alpha=0.12, linewidth=0, label=f"within {tolerance:g}°")
        axis.axhline(tolerance, color="C2", linewidth=0.9, linestyle="--")
    slew = getattr(result, "slew_time", None)
    if slew is not None:
        axis.axvline(slew, color="C2", linewidth=0.9, linestyle=":", label=f"slew time {slew:.1f} s")
    if result.settling_time is not None:
        axis.axvline(result.settling_time, color="0.3", linewidth=0.8, linestyle="-.", label="settled")
    axis.set_ylabel("pointing error Φ (deg)")
    axis.set_xlabel("time t (s)")
    axis.grid(True, which="both", linewidth=0.3)
    legend_outside(axis)
    if title is None:
        figures = []
        if getattr(result, "pointing_max", None) is not None:
            figures.append(f"after settling max {result.pointing_max:.3g}°, RMS {result.pointing_rms:.3g}°")
        title = f"Pointing: {rule_words(result.rule)}, delay τ = {result.tau:g} s" + (
            f"; {figures[0]}" if figures else ""
        )
    axis.set_ylim(bottom=floor)
    axis.set_title(textwrap.fill(typeset(title), width=80), fontsize=9)
    return fig
