"""Paper-style figures of simulations and sweeps: the only module that imports matplotlib."""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")  # no screen is assumed; figures are written to files

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

if TYPE_CHECKING:
    from mrpctl.simulation import SimulationResult

__all__ = ["plot_attitude", "plot_response", "plot_sweep", "save_figure"]

_AXIS_LABELS = ("1", "2", "3")


def _mark_switches(ax: Any, switch_times: np.ndarray, *, label: bool = False) -> None:
    """A tick at the top of the axes at every switch instant (readable even for thousands)."""
    if len(switch_times) == 0:
        return
    ax.plot(
        switch_times,
        np.full(len(switch_times), 0.97),
        "|",
        color="crimson",
        markersize=7,
        markeredgewidth=0.8,
        transform=ax.get_xaxis_transform(),
        label="switch" if label else None,
    )


def _title(result: SimulationResult) -> str:
    n = int(result.switch_count)
    switches = f"{n} shadow-set switch{'es' if n != 1 else ''}"
    return textwrap.fill(f"{result.rule}, τ = {result.tau:g} s: {switches}", width=90)


def plot_response(result: SimulationResult, *, title: str | None = None) -> Figure:
    """σ, ω and u against t, with the switch instants marked (paper Figs. 2-7).

    Parameters
    ----------
    result : SimulationResult
        A run of :func:`mrpctl.simulate.simulate`.
    title : str, optional
        Figure title; by default the rule and the delay τ.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, axes = plt.subplots(3, 1, figsize=(7.0, 7.5), sharex=True, constrained_layout=True)
    t = np.asarray(result.t)
    series = (
        (np.asarray(result.sigma), r"$\sigma_{i}$", "MRP σ (-)", "default"),
        (np.asarray(result.omega), r"$\omega_{i}$", "angular rate ω (rad/s)", "default"),
        (np.asarray(result.u), r"$u_{i}$", "torque u (N m)", "steps-post"),  # zero-order hold
    )
    for ax, (values, label, ylabel, drawstyle) in zip(axes, series, strict=True):
        times = t[: len(values)]
        for i in range(3):
            ax.plot(
                times,
                values[:, i],
                label=label.replace("{i}", "{" + _AXIS_LABELS[i] + "}"),
                linewidth=1.0,
                drawstyle=drawstyle,
            )
        _mark_switches(ax, np.asarray(result.switch_times), label=ax is axes[0])
        ax.set_ylabel(ylabel)
        ax.grid(True, linewidth=0.3)
        ax.legend(loc="upper right", fontsize=8, ncol=3)
    norm = np.linalg.norm(np.asarray(result.sigma), axis=1)
    axes[0].plot(t[: len(norm)], norm, color="k", linestyle="--", linewidth=0.8, label="|σ|")
    axes[0].axhline(1.0, color="k", linewidth=0.4)
    axes[0].legend(loc="upper right", fontsize=8, ncol=4)
    axes[-1].set_xlabel("time t (s)")
    axes[0].set_title(title or _title(result), fontsize=9)
    return fig


def plot_attitude(
    result: SimulationResult, *, window: tuple[float, float] | None = None, title: str | None = None
) -> Figure:
    """σ against t over a time window, switch instants marked (the zoom of paper Fig. 5).

    Parameters
    ----------
    result : SimulationResult
        A run of :func:`mrpctl.simulate.simulate`.
    window : (float, float), optional
        Time window in s; the whole run by default.
    title : str, optional
        Figure title.
    """
    t = np.asarray(result.t)
    sigma = np.asarray(result.sigma)
    start, stop = window if window is not None else (float(t[0]), float(t[-1]))
    keep = (t >= start) & (t <= stop)
    fig, ax = plt.subplots(figsize=(7.0, 3.2), constrained_layout=True)
    for i in range(3):
        ax.plot(t[keep], sigma[keep, i], label=rf"$\sigma_{_AXIS_LABELS[i]}$", linewidth=1.0)
    switches = np.asarray(result.switch_times)
    _mark_switches(ax, switches[(switches >= start) & (switches <= stop)], label=True)
    ax.set_xlim(start, stop)
    ax.set_xlabel("time t (s)")
    ax.set_ylabel("MRP σ (-)")
    ax.grid(True, linewidth=0.3)
    ax.legend(loc="upper right", fontsize=8)
    ax.set_title(title or _title(result), fontsize=9)
    return fig


def plot_sweep(
    parameter: Sequence[float] | np.ndarray,
    *,
    switch_count: Sequence[float] | np.ndarray,
    settling_time: Sequence[float] | np.ndarray,
    converged: Sequence[bool] | np.ndarray,
    parameter_label: str,
    title: str | None = None,
) -> Figure:
    """Switch count, settling time and convergence against a swept parameter.

    Parameters
    ----------
    parameter : array_like
        The swept values (ε, τ in s, or the run index of a Monte-Carlo).
    switch_count, settling_time, converged : array_like
        One entry per run; settling time in s (NaN where the run did not settle).
    parameter_label : str
        Axis label with units.
    """
    x = np.asarray(parameter, dtype=float)
    count = np.asarray(switch_count, dtype=float)
    settle = np.asarray(settling_time, dtype=float)
    ok = np.asarray(converged, dtype=bool)
    order = np.argsort(x, kind="stable")
    fig, axes = plt.subplots(3, 1, figsize=(6.5, 6.5), sharex=True, constrained_layout=True)
    axes[0].plot(x[order], count[order], "o-", markersize=3)
    axes[0].set_ylabel("switch count (-)")
    axes[1].plot(x[order], settle[order], "o-", markersize=3)
    axes[1].set_ylabel("settling time (s)")
    axes[2].plot(x[order], ok[order].astype(float), "o", markersize=3)
    axes[2].set_yticks([0, 1], ["no", "yes"])
    axes[2].set_ylabel("converged")
    axes[2].set_xlabel(parameter_label)
    for ax in axes:
        ax.grid(True, linewidth=0.3)
    if np.all(x > 0) and x.size > 1 and x.max() / x.min() > 50:
        axes[2].set_xscale("log")
    axes[0].set_title(title or f"sweep over {parameter_label}", fontsize=10)
    return fig


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 110) -> Path:
    """Write ``fig`` to ``path`` (PNG by suffix) and close it; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
