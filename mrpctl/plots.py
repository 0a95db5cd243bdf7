"""Figures of simulations, sweeps and Monte Carlo batches: with its private figure modules (`_plots_common`,
`_plots_pointing`, re-exported here) the only place that imports matplotlib.

The functions build `matplotlib.figure.Figure` objects and never select a backend,
so they work headless (``save_figure`` renders through Agg) and in notebooks (the figure
is displayed by the notebook's own backend). Every function takes ``ax=``: one
``Axes`` for single-panel figures, a sequence of ``Axes`` for multi-panel ones (e.g. from
``plt.subplots(3, 1)``), so figures can be composed with pyplot when the user asks for it.

Conventions on every figure: legends sit outside the data (right of the axes),
identically zero traces are not drawn but named in the legend ("σ₂, σ₃ ≡ 0"), sampled
signals in zooms are drawn as steps with a marker per sample, runs that did not settle
or diverged are drawn as failures, counts use logarithmic axes when they span a decade
or more, and the settling tolerance is written in the caption.
"""

from __future__ import annotations

import math
import os
import tempfile
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from matplotlib.axes import Axes
from matplotlib.colors import Normalize
from matplotlib.figure import Figure
from scipy.stats import chi2

from mrpctl._plots_common import legend_outside as _legend_outside
from mrpctl._plots_common import new_axes as _new_axes
from mrpctl._plots_common import rule_words as _rule_words
from mrpctl._plots_common import typeset as _typeset
from mrpctl._plots_pointing import plot_pointing
from mrpctl.conventions import state_parts
from mrpctl.errors import DimensionError, SpecificationError


class RunView(Protocol):
    """What the figures read of a run (`mrpctl.simulation.SimulationResult` provides it).

    A structural type, so that this module needs nothing of the simulator: the results call the
    figures (``run.plot()``), never the other way round.
    """

    @property
    def t(self) -> np.ndarray: ...
    @property
    def sigma(self) -> np.ndarray: ...
    @property
    def omega(self) -> np.ndarray: ...
    @property
    def u(self) -> np.ndarray: ...
    @property
    def switch_times(self) -> np.ndarray: ...
    @property
    def switch_count(self) -> int: ...
    @property
    def settling_time(self) -> float | None: ...
    @property
    def diverged(self) -> bool: ...
    @property
    def rate(self) -> float: ...
    @property
    def tau(self) -> float: ...
    @property
    def t_final(self) -> float: ...
    @property
    def rule(self) -> Any: ...


class BatchView(Protocol):
    """What the figures read of a batch (`mrpctl.simulation.BatchResult` provides it)."""

    @property
    def x0(self) -> np.ndarray: ...
    @property
    def tau(self) -> np.ndarray: ...
    @property
    def rules(self) -> tuple[Any, ...]: ...
    @property
    def switch_count(self) -> np.ndarray: ...
    @property
    def settling_time(self) -> np.ndarray: ...
    @property
    def converged(self) -> np.ndarray: ...
    @property
    def diverged(self) -> np.ndarray: ...
    @property
    def max_sigma(self) -> np.ndarray: ...
    @property
    def t_final(self) -> float: ...


__all__ = [
    "SETTLING_CAPTION",
    "plot_attitude",
    "plot_batch",
    "plot_distributions",
    "plot_estimation_error",
    "plot_monte_carlo",
    "plot_nees",
    "plot_noise_study",
    "plot_pointing",
    "plot_response",
    "plot_sweep",
    "plot_wheels",
    "render_rgba",
    "save_figure",
]

_SUB = ("₁", "₂", "₃")
_SWITCH_COLOR = "crimson"
_FAIL_COLOR = "crimson"
#: The settling tolerance of `SimulationResult` (|σ| < 1e-2, |ω| < 1e-3 rad/s).
SETTLING_CAPTION = "settled: |σ| < 10⁻² and |ω| < 10⁻³ rad/s to the end"
#: A cluster of at least this many switches in at most this fraction of the run gets a zoom inset.
_INSET_MIN_SWITCHES = 10
_INSET_MAX_FRACTION = 0.1


# ------------------------------------------------------------------------------ axes plumbing
def _components(
    ax: Axes, t: np.ndarray, values: np.ndarray, symbol: str, *, drawstyle: str = "default", marker: str | None = None
) -> None:
    """The three components of a vector signal; identically zero ones are named, not drawn."""
    zero = [i for i in range(values.shape[1]) if not np.any(values[:, i])]
    colors = ("C0", "C1", "C2")
    for i in range(values.shape[1]):
        if i in zero:
            continue
        ax.plot(
            t,
            values[:, i],
            label=f"{symbol}{_SUB[i]}",
            color=colors[i],
            linewidth=1.0,
            drawstyle=drawstyle,
            marker=marker,
            markersize=3.5,
        )
    if zero and len(zero) < values.shape[1]:
        names = ", ".join(f"{symbol}{_SUB[i]}" for i in zero)
        ax.plot([], [], " ", label=f"{names} ≡ 0")
    elif zero:
        ax.plot(t, np.zeros(len(t)), color="0.4", linewidth=1.0, label=f"{symbol}₁ = {symbol}₂ = {symbol}₃ ≡ 0")


def _mark_switches(ax: Axes, switch_times: np.ndarray, *, label: bool = False) -> None:
    """A tick at the top of the axes at every switch instant (readable even for thousands)."""
    if len(switch_times) == 0:
        return
    ax.plot(
        switch_times,
        np.full(len(switch_times), 0.97),
        "|",
        color=_SWITCH_COLOR,
        markersize=7,
        markeredgewidth=0.8,
        transform=ax.get_xaxis_transform(),
        label="switch" if label else None,
    )


def _status(result: RunView) -> str:
    if result.diverged:
        return f"DIVERGED at t = {float(result.t[-1]):.3f} s"
    if result.settling_time is not None:
        return f"settled at {result.settling_time:.1f} s ({SETTLING_CAPTION.split(': ', 1)[1]})"
    return f"did not settle in {result.t_final:g} s ({SETTLING_CAPTION.split(': ', 1)[1]})"


def _title(result: RunView) -> str:
    n = int(result.switch_count)
    switches = f"{n} shadow-set switch{'es' if n != 1 else ''}"
    what = f"{_rule_words(result.rule)}, delay τ = {result.tau:g} s at {result.rate:g} Hz"
    return textwrap.fill(f"{what[0].upper()}{what[1:]}: {switches}; {_status(result)}", width=95)


def _unit_lines(ax: Axes, values: np.ndarray, norm: np.ndarray) -> None:
    """The |σ| = 1 line (and −1 for the components) only when within or near the data; the axis fits the data."""
    lo = float(min(np.min(values), 0.0)) if values.size else 0.0
    hi = float(max(np.max(values), np.max(norm))) if values.size else 1.0
    span = max(hi - lo, 1e-12)
    near = 0.25 * span  # a line this close to the data is drawn (the axis then extends to it)
    if hi >= 1.0 - near:
        ax.axhline(1.0, color="k", linewidth=0.4, label="|σ| = 1")
    if lo <= -1.0 + near:
        ax.axhline(-1.0, color="k", linewidth=0.4, linestyle=(0, (4, 3)), label="σᵢ = −1")


def _limit_lines(ax: Axes, u_max: Any, u: np.ndarray) -> None:
    """±u_max on the torque panel (dotted, the colour of its component; for the drawn components only)."""
    try:
        limits = np.broadcast_to(np.asarray(u_max, dtype=float), (3,))
    except (TypeError, ValueError):
        raise SpecificationError(f"u_max must be one or three torque limits in N m, got {u_max!r}") from None
    if not np.all((limits > 0) | np.isinf(limits)):
        raise SpecificationError(f"u_max must be positive torque limits in N m (one or three), got {u_max!r}")
    drawn = [i for i in range(3) if np.any(u[:, i])] or [0, 1, 2]
    finite = [i for i in drawn if np.isfinite(limits[i])]
    if finite and np.ptp(limits) == 0.0:  # one limit for every axis: one pair of lines
        for sign in (1.0, -1.0):
            ax.axhline(sign * limits[finite[0]], color="0.3", linewidth=0.8, linestyle=":")
        ax.plot([], [], color="0.3", linewidth=0.8, linestyle=":", label=f"±u_max = {limits[finite[0]]:g} N m")
        return
    for i in finite:
        for sign in (1.0, -1.0):
            ax.axhline(sign * limits[i], color=f"C{i}", linewidth=0.8, linestyle=":")
        ax.plot([], [], color=f"C{i}", linewidth=0.8, linestyle=":", label=f"±u_max,{i + 1} = {limits[i]:g} N m")


def _switch_cluster(result: RunView) -> tuple[float, float] | None:
    """The window of a dense switch cluster worth a zoom inset, or None."""
    times = np.asarray(result.switch_times)
    if len(times) < _INSET_MIN_SWITCHES:
        return None
    span = float(times[-1] - times[0])
    duration = float(result.t[-1] - result.t[0]) if len(result.t) > 1 else 0.0
    if duration <= 0.0 or span > _INSET_MAX_FRACTION * duration:
        return None
    pad = max(0.15 * span, 5.0 / result.rate)
    return float(times[0]) - pad, float(times[-1]) + pad


# ------------------------------------------------------------------------------ single runs
def plot_response(
    result: RunView,
    *,
    title: str | None = None,
    ax: Any = None,
    inset: bool | None = None,
    u_max: Any = None,
) -> Figure:
    """σ, ω and u against t, with the switch instants marked (paper Figs. 2-7).

    The σ axis fits the data: the |σ| = 1 line (and σᵢ = −1) is drawn only when it lies
    within or near the data range (a quarter of the range away at most).

    Parameters
    ----------
    result : SimulationResult
        A run of [`mrpctl.simulate`][mrpctl.simulation.simulate].
    title : str, optional
        Figure title; by default the rule, the delay τ, the switch count and whether the run
        settled (with the settling tolerance).
    ax : sequence of 3 matplotlib.axes.Axes, optional
        Axes for σ, ω and u; a new figure by default.
    inset : bool, optional
        Zoom inset on the σ panel around the switches. By default drawn when at least 10
        switches fall in at most a tenth of the run (Fig. 7: 114 switches in 0.944-1.606 s).
    u_max : float, array_like (3,) or mrpctl.flight.ActuatorModel, optional
        The actuator's torque limits (N m): ±u_max drawn on the torque panel. By default the
        limit of the run's actuator when the result carries one, none otherwise.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, axes = _new_axes(3, ax, figsize=(8.0, 7.5))
    t = np.asarray(result.t)
    sigma = np.asarray(result.sigma)
    series = (
        (sigma, "σ", "MRP σ (-)", "default"),
        (np.asarray(result.omega), "ω", "angular rate ω (rad/s)", "default"),
        (np.asarray(result.u), "u", "torque u (N m)", "steps-post"),  # zero-order hold
    )
    switches = np.asarray(result.switch_times)
    for panel, (values, symbol, ylabel, drawstyle) in zip(axes, series, strict=True):
        _components(panel, t[: len(values)], values, symbol, drawstyle=drawstyle)
        _mark_switches(panel, switches, label=panel is axes[0])
        panel.set_ylabel(ylabel)
        panel.grid(True, linewidth=0.3)
    norm = np.linalg.norm(sigma, axis=1)
    axes[0].plot(t[: len(norm)], norm, color="k", linestyle="--", linewidth=0.8, label="|σ|")
    _unit_lines(axes[0], sigma, norm)
    if u_max is None:
        u_max = getattr(getattr(result, "actuator", None), "u_max", None)
    elif hasattr(u_max, "u_max"):  # an ActuatorModel
        u_max = u_max.u_max
    if u_max is not None:
        _limit_lines(axes[2], u_max, np.asarray(result.u))
    if result.diverged:
        for panel in axes:
            panel.axvline(float(t[-1]), color=_FAIL_COLOR, linewidth=1.2, linestyle=":", label="diverged")
    elif result.settling_time is not None:
        axes[0].axvline(result.settling_time, color="0.3", linewidth=0.8, linestyle="-.", label="settled")
    for panel in axes:
        _legend_outside(panel)
    axes[-1].set_xlabel("time t (s)")
    axes[0].set_title(_typeset(title) if title else _title(result), fontsize=9)
    window = _switch_cluster(result) if inset is None else (_switch_cluster(result) if inset else None)
    if inset and window is None and len(switches):
        window = (float(switches[0]) - 0.05, float(switches[-1]) + 0.05)
    if window is not None:
        _zoom_inset(axes[0], result, window)
    return fig


def plot_wheels(result: Any, *, title: str | None = None, ax: Any = None) -> Figure:
    """The wheel speeds (rpm) and motor torques (N m) of a run on a wheel cluster against t, with ±Ω_max and
    ±u_max of each wheel drawn (dotted, the wheel's colour).

    Parameters
    ----------
    result : SimulationResult
        A run of [`mrpctl.simulate`][mrpctl.simulation.simulate] with ``wheels=...`` and kept samples.
    title : str, optional
        Figure title; by default the wheel count, the peak speed and the time at the limits.
    ax : sequence of 2 matplotlib.axes.Axes, optional
        Axes for the speeds and the torques; a new figure by default.

    Returns
    -------
    matplotlib.figure.Figure
    """
    record = getattr(result, "wheels", None)
    if record is None:
        raise SpecificationError("result: plot_wheels needs a run on a wheel cluster (simulate(..., wheels=...))")
    t = np.asarray(result.t)
    speeds, torques = np.asarray(record.speeds), np.asarray(record.motor_torque)
    if t.size == 0 or speeds.shape[0] != t.size:
        raise SpecificationError("result: plot_wheels needs the kept samples (keep_every not None)")
    cluster = record.cluster
    fig, axes = _new_axes(2, ax, figsize=(7.5, 5.0))
    rpm = 60.0 / (2.0 * math.pi)
    for i in range(speeds.shape[1]):
        color = f"C{i % 10}"
        axes[0].plot(t, speeds[:, i] * rpm, color=color, linewidth=1.0, label=f"Ω{i + 1}")
        axes[1].plot(t, torques[:, i], color=color, linewidth=1.0, label=f"u_s,{i + 1}")
        for sign in (1.0, -1.0):
            axes[0].axhline(sign * cluster.speed_limit[i] * rpm, color=color, linewidth=0.8, linestyle=":")
            axes[1].axhline(sign * cluster.torque_limit[i], color=color, linewidth=0.8, linestyle=":")
    axes[0].plot([], [], color="0.3", linewidth=0.8, linestyle=":", label="±Ω_max, ±u_max")
    axes[0].set_ylabel("wheel speed (rpm)")
    axes[1].set_ylabel("motor torque (N m)")
    axes[1].set_xlabel("time t (s)")
    for panel in axes:
        _legend_outside(panel)
    if title is None:
        limited = np.asarray(record.torque_limited_time).max(), np.asarray(record.speed_limited_time).max()
        title = (
            f"{speeds.shape[1]} wheels: peak {np.max(record.peak_speed) * rpm:.0f} rpm "
            f"(wheel {record.worst_wheel + 1}), at the torque limit up to {limited[0]:g} s, "
            f"at the speed limit up to {limited[1]:g} s"
        )
    axes[0].set_title(_typeset(title), fontsize=9)
    return fig


def _zoom_inset(ax: Axes, result: RunView, window: tuple[float, float]) -> Axes:
    """An inset on ``ax`` showing the sampled σ around the switch cluster, as steps."""
    t = np.asarray(result.t)
    sigma = np.asarray(result.sigma)
    keep = (t >= window[0]) & (t <= window[1])
    inset = ax.inset_axes((0.45, 0.5, 0.53, 0.38))  # above the settled tail of σ
    inset.set_label("switch cluster zoom")
    for i in range(3):
        if np.any(sigma[:, i]):
            inset.plot(t[keep], sigma[keep, i], color=f"C{i}", linewidth=0.8, drawstyle="steps-post")
    times = np.asarray(result.switch_times)
    _mark_switches(inset, times[(times >= window[0]) & (times <= window[1])])
    inset.set_xlim(*window)
    inset.tick_params(labelsize=7)
    inset.set_title(f"zoom: {len(times)} switches in {times[0]:.3f}-{times[-1]:.3f} s", fontsize=7)
    inset.grid(True, linewidth=0.3)
    ax.indicate_inset_zoom(inset, edgecolor="0.3")
    return inset


def plot_attitude(
    result: RunView,
    *,
    window: tuple[float, float] | None = None,
    title: str | None = None,
    ax: Any = None,
    markers: bool | None = None,
) -> Figure:
    """σ against t over a time window, switch instants marked (the zoom of paper Fig. 5).

    σ is a sampled signal (one value per measurement t_k = k h), so it is drawn as steps
    that never join samples across a switch, with a marker per sample when the window
    holds at most 2 000 samples (the 0.1 s zoom at 1 kHz holds 100).

    Parameters
    ----------
    result : SimulationResult
        A run of [`mrpctl.simulate`][mrpctl.simulation.simulate].
    window : (float, float), optional
        Time window in s; the whole run by default.
    title : str, optional
        Figure title.
    ax : matplotlib.axes.Axes, optional
        Axes to draw in; a new figure by default.
    markers : bool, optional
        One marker per sample; by default when the window holds at most 2 000 samples.

    Returns
    -------
    matplotlib.figure.Figure
    """
    t = np.asarray(result.t)
    sigma = np.asarray(result.sigma)
    start, stop = window if window is not None else (float(t[0]), float(t[-1]))
    if not (math.isfinite(start) and math.isfinite(stop) and start < stop):
        raise SpecificationError(f"window must be (start, stop) with start < stop in s, got {window!r}")
    keep = (t >= start) & (t <= stop)
    fig, (axis,) = _new_axes(1, ax, figsize=(8.0, 3.4))
    with_markers = int(keep.sum()) <= 2000 if markers is None else markers
    _components(axis, t[keep], sigma[keep], "σ", drawstyle="steps-post", marker="." if with_markers else None)
    axis.plot(t[keep], np.linalg.norm(sigma[keep], axis=1), color="k", linestyle="--", linewidth=0.7, label="|σ|")
    _unit_lines(axis, sigma[keep], np.linalg.norm(sigma[keep], axis=1))
    switches = np.asarray(result.switch_times)
    shown = switches[(switches >= start) & (switches <= stop)]
    _mark_switches(axis, shown, label=True)
    axis.set_xlim(start, stop)
    axis.set_xlabel("time t (s)")
    axis.set_ylabel("MRP σ (-)")
    axis.grid(True, linewidth=0.3)
    _legend_outside(axis)
    caption = f"{len(shown)} switches in [{start:g}, {stop:g}] s, one step per sample (h = {1e3 / result.rate:g} ms)"
    axis.set_title(_typeset(title) + "\n" + caption if title else _title(result) + "\n" + caption, fontsize=9)
    return fig


# ------------------------------------------------------------------------------ sweeps and batches
def _count_scale(ax: Axes, counts: np.ndarray) -> None:
    """Log axis when the counts span a decade (symlog when zeros occur), linear otherwise."""
    finite = counts[np.isfinite(counts)]
    if finite.size == 0:
        return
    positive = finite[finite > 0]
    if positive.size == 0:
        return
    if np.any(finite == 0) and positive.max() >= 10:
        ax.set_yscale("symlog", linthresh=1.0)
    elif positive.max() >= 10 * max(positive.min(), 1.0):
        ax.set_yscale("log")


def plot_sweep(
    parameter: Sequence[float] | np.ndarray,
    *,
    switch_count: Sequence[float] | np.ndarray,
    settling_time: Sequence[float] | np.ndarray,
    converged: Sequence[bool] | np.ndarray,
    parameter_label: str,
    title: str | None = None,
    max_sigma: Sequence[float] | np.ndarray | None = None,
    diverged: Sequence[bool] | np.ndarray | None = None,
    margin: float | None = None,
    ax: Any = None,
) -> Figure:
    """Switch count, settling time and convergence (or max |σ|) against a swept parameter.

    Runs that did not settle are drawn as failures (a red × at the top of the settling
    panel, labelled), never dropped; counts get a log axis when they span a decade.

    Parameters
    ----------
    parameter : array_like
        The swept values (ε, or τ in s).
    switch_count, settling_time, converged : array_like
        One entry per run; settling time in s (NaN where the run did not settle).
    parameter_label : str
        Axis label with units.
    title : str, optional
        Figure title.
    max_sigma : array_like, optional
        max |σ| per run; replaces the converged yes/no panel when given.
    diverged : array_like of bool, optional
        Runs flagged diverged, marked apart from "did not settle".
    margin : float, optional
        The exact delay margin τ* (s), drawn as a vertical line on every panel (τ sweeps).
    ax : sequence of 3 matplotlib.axes.Axes, optional
        Axes for the three panels; a new figure by default.

    Returns
    -------
    matplotlib.figure.Figure
    """
    x = np.asarray(parameter, dtype=float)
    count = np.asarray(switch_count, dtype=float)
    settle = np.asarray(settling_time, dtype=float)
    ok = np.asarray(converged, dtype=bool)
    n = x.shape[0] if x.ndim == 1 else -1
    for name, values in (("switch_count", count), ("settling_time", settle), ("converged", ok)):
        if values.shape != (n,):
            raise DimensionError(f"{name} must have the shape of parameter ({n},), got {values.shape}")
    bad = np.asarray(diverged, dtype=bool) if diverged is not None else np.zeros(n, dtype=bool)
    if bad.shape != (n,):
        raise DimensionError(f"diverged must have the shape of parameter ({n},), got {bad.shape}")
    order = np.argsort(x, kind="stable")
    x, count, settle, ok, bad = x[order], count[order], settle[order], ok[order], bad[order]
    label = _typeset(parameter_label)
    fig, axes = _new_axes(3, ax, figsize=(7.5, 6.5))
    axes[0].plot(x, count, "o-", markersize=3, linewidth=0.8, label="switches")
    axes[0].set_ylabel("switch count (-)")
    _count_scale(axes[0], count)
    good = ok & np.isfinite(settle)
    axes[1].plot(x[good], settle[good], "o-", markersize=3, linewidth=0.8, label="settling time")
    failed = ~good & ~bad
    if failed.any():
        axes[1].plot(
            x[failed],
            np.full(int(failed.sum()), 0.93),
            "x",
            color=_FAIL_COLOR,
            markersize=8,
            markeredgewidth=1.5,
            transform=axes[1].get_xaxis_transform(),
            label="did not settle",
        )
    if bad.any():
        axes[1].plot(
            x[bad],
            np.full(int(bad.sum()), 0.93),
            "X",
            color="k",
            markersize=8,
            transform=axes[1].get_xaxis_transform(),
            label="diverged",
        )
    axes[1].set_ylabel("settling time (s)")
    if max_sigma is not None:
        peak = np.asarray(max_sigma, dtype=float)
        if peak.shape != (n,):
            raise DimensionError(f"max_sigma must have the shape of parameter ({n},), got {peak.shape}")
        peak = peak[order]
        axes[2].plot(x, peak, "o-", markersize=3, linewidth=0.8, label="max |σ|")
        axes[2].plot(x[~ok], peak[~ok], "x", color=_FAIL_COLOR, markersize=8, markeredgewidth=1.5)
        axes[2].axhline(1.0, color="k", linewidth=0.4, label="|σ| = 1")
        axes[2].set_ylabel("max |σ| (-)")
        if np.nanmax(peak) >= 10 * max(np.nanmin(peak), 1e-12):
            axes[2].set_yscale("log")
    else:
        axes[2].plot(x[ok], np.ones(int(ok.sum())), "o", markersize=4, label="settled")
        axes[2].plot(x[~ok], np.zeros(int((~ok).sum())), "x", color=_FAIL_COLOR, markersize=8, label="did not")
        axes[2].set_yticks([0, 1], ["no", "yes"])
        axes[2].set_ylim(-0.3, 1.3)
        axes[2].set_ylabel("settled")
    axes[2].set_xlabel(label)
    if margin is not None:
        if not (isinstance(margin, int | float) and margin > 0):
            raise SpecificationError(f"margin must be a positive delay margin in s, got {margin!r}")
        for panel in axes:
            panel.axvline(
                float(margin), color="k", linestyle="--", linewidth=1.0, label=f"exact margin τ* = {margin:.5g} s"
            )
    for panel in axes:
        panel.grid(True, linewidth=0.3)
        _legend_outside(panel)
    if np.all(x > 0) and x.size > 1 and x.max() / x.min() > 50:
        axes[2].set_xscale("log")
    axes[0].set_title((_typeset(title) if title else f"sweep over {label}") + f"\n{SETTLING_CAPTION}", fontsize=9)
    return fig


def _initial_angle_and_rate(x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal angle Φ = 4 arctan|σ₀| (deg) and |ω₀| (rad/s) of (N, 6) initial states x = [σ; ω/4]."""
    sigma0, omega0 = state_parts(x0)
    return np.degrees(4.0 * np.arctan(np.linalg.norm(sigma0, axis=1))), np.linalg.norm(omega0, axis=1)


def plot_monte_carlo(batch: BatchView, *, title: str | None = None, ax: Any = None) -> Figure:
    """A Monte Carlo batch as distributions: independent runs are not a line over run index.

    Panels: a histogram of switch counts (log bins when they span a decade), the empirical
    CDF of the settling time (runs that did not settle counted as failures: the CDF ends
    below 1 and the shortfall is labelled), and the switch count against the initial
    principal angle Φ₀ = 4 arctan|σ₀| and rate |ω₀| (colour), failures drawn as ×.

    Parameters
    ----------
    batch : BatchResult
        A batch of [`mrpctl.simulate_batch`][mrpctl.simulate_batch].
    title : str, optional
        Figure title.
    ax : sequence of 3 matplotlib.axes.Axes, optional
        Axes for the histogram, the CDF and the scatter; a new figure by default.

    Returns
    -------
    matplotlib.figure.Figure
    """
    count = np.asarray(batch.switch_count, dtype=float)
    settle = np.asarray(batch.settling_time, dtype=float)
    ok = np.asarray(batch.converged, dtype=bool)
    n = len(count)
    if n == 0:
        raise SpecificationError("batch must hold at least one run")
    angle, rate = _initial_angle_and_rate(np.asarray(batch.x0, dtype=float))
    fig, axes = _new_axes(3, ax, figsize=(7.5, 8.5), sharex=False)
    top = max(float(count.max()), 1.0)
    if top >= 10:
        bins = np.unique(np.concatenate(([0.0], np.geomspace(1.0, top + 1.0, 25))))
        axes[0].set_xscale("symlog", linthresh=1.0)
    else:
        bins = np.arange(-0.5, top + 1.5)
    axes[0].hist(count, bins=bins.tolist(), color="C0", edgecolor="white", label=f"{n} runs")
    axes[0].set_xlabel("switch count (-)")
    axes[0].set_ylabel("runs (-)")
    times = np.sort(settle[ok & np.isfinite(settle)])
    fraction = np.arange(1, times.size + 1) / n
    if times.size:
        axes[1].step(np.concatenate(([0.0], times)), np.concatenate(([0.0], fraction)), where="post", label="settled")
    failed = n - times.size
    axes[1].axhline(times.size / n, color=_FAIL_COLOR, linestyle=":", linewidth=1.0, label=f"{failed} did not settle")
    axes[1].set_ylim(0.0, 1.02)
    axes[1].set_xlim(0.0, float(batch.t_final))
    if not times.size:
        axes[1].text(0.5, 0.5, f"no run settled in {batch.t_final:g} s", transform=axes[1].transAxes, ha="center")
    axes[1].set_xlabel("settling time (s)")
    axes[1].set_ylabel("fraction of runs settled (-)")
    norm = Normalize(vmin=float(rate.min()), vmax=float(max(rate.max(), rate.min() + 1e-12)))
    style = {"c": None, "cmap": "viridis", "norm": norm}
    scatter = None
    if ok.any():
        scatter = axes[2].scatter(angle[ok], count[ok], s=14, label="settled", **{**style, "c": rate[ok]})
    if (~ok).any():
        failures = axes[2].scatter(
            angle[~ok], count[~ok], marker="x", s=30, label="did not settle", **{**style, "c": rate[~ok]}
        )
        scatter = scatter or failures
    if scatter is not None and rate.max() > rate.min():
        fig.colorbar(scatter, ax=axes[2], label="initial rate |ω₀| (rad/s)", location="bottom", shrink=0.6)
    axes[2].set_xlabel("initial principal angle Φ₀ (deg)")
    axes[2].set_ylabel("switch count (-)")
    _count_scale(axes[2], count)
    for panel in axes:
        panel.grid(True, linewidth=0.3)
        _legend_outside(panel)
    rules = "; ".join(sorted({_rule_words(r) for r in batch.rules}))
    head = _typeset(title) if title else textwrap.fill(f"{n} runs from dispersed initial states, {rules}", width=95)
    axes[0].set_title(f"{head}\n{SETTLING_CAPTION}", fontsize=9)
    return fig


def plot_batch(
    batch: BatchView,
    *,
    over: str | None = None,
    margin: float | None = None,
    title: str | None = None,
    ax: Any = None,
) -> Figure:
    """A batch as the figure its inputs call for: a τ sweep, an ε sweep or a Monte Carlo.

    Parameters
    ----------
    batch : BatchResult
        A batch of [`mrpctl.simulate_batch`][mrpctl.simulate_batch].
    over : {"tau", "eps", "initial"}, optional
        What varies across the runs; detected by default (τ when the delays differ, ε when
        every rule is a BoundaryLayer and their ε differ, the initial state otherwise).
    margin : float, optional
        Exact delay margin τ* (s) to mark on τ sweeps, e.g.
        ``linearized_loop(spacecraft, K).delay_margin().margin``.
    title : str, optional
        Figure title.
    ax : sequence of 3 matplotlib.axes.Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    tau = np.asarray(batch.tau, dtype=float)
    eps = [getattr(r, "eps", None) for r in batch.rules]
    if over is None:
        if np.unique(tau).size > 1:
            over = "tau"
        elif all(e is not None for e in eps) and len(set(eps)) > 1:
            over = "eps"
        else:
            over = "initial"
    if over == "initial":
        return plot_monte_carlo(batch, title=title, ax=ax)
    if over == "tau":
        values: Any = tau
        label = "delay tau (s)"
    elif over == "eps":
        if any(e is None for e in eps):
            raise SpecificationError("over='eps' needs every rule to be a BoundaryLayer(eps)")
        values = np.asarray(eps, dtype=float)
        label = "boundary layer thickness eps (-)"
    else:
        raise SpecificationError(f"over must be 'tau', 'eps' or 'initial', got {over!r}")
    return plot_sweep(
        values,
        switch_count=batch.switch_count,
        settling_time=batch.settling_time,
        converged=batch.converged,
        diverged=batch.diverged,
        max_sigma=batch.max_sigma,
        parameter_label=label,
        margin=margin,
        title=title,
        ax=ax,
    )


# ------------------------------------------------------------------------------ output
def _grid(name: str, values: Any, shape: tuple[int, int]) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != shape:
        raise DimensionError(f"{name}: expected shape {shape} but found {array.shape}")
    return array


def plot_noise_study(
    noise: Sequence[float] | np.ndarray,
    alpha: Sequence[float] | np.ndarray,
    *,
    switch_count: Any,
    settling_time: Any,
    title: str | None = None,
) -> Figure:
    """Heat maps of the controller-side rule over attitude noise × hysteresis: switches and settling.

    Parameters
    ----------
    noise : array_like
        (m,) attitude noise levels (rad, standard deviation per axis): the rows.
    alpha : array_like
        (p,) bounds α on |σ_c| (δ = (α² − 1)/(α² + 1)): the columns.
    switch_count, settling_time : array_like
        (m, p) logic switches and settling times (s; NaN: did not settle, drawn as "x").
    title : str, optional
    """
    rows, columns = np.asarray(noise, dtype=float), np.asarray(alpha, dtype=float)
    shape = (rows.size, columns.size)
    counts = _grid("switch_count", switch_count, shape)
    settling = _grid("settling_time", settling_time, shape)
    fig = Figure(figsize=(9.0, 3.6), layout="constrained")
    axes = fig.subplots(1, 2)
    panels = (
        (axes[0], np.log10(1.0 + counts), counts, "logic switches", "{:.0f}"),
        (axes[1], settling, settling, "settling time (s)", "{:.1f}"),
    )
    for ax, shade, shown, label, fmt in panels:
        finite = shade[np.isfinite(shade)]
        norm = Normalize(
            vmin=float(finite.min()) if finite.size else 0.0, vmax=float(finite.max()) if finite.size else 1.0
        )
        ax.imshow(np.where(np.isfinite(shade), shade, np.nan), cmap="viridis", norm=norm, aspect="auto", origin="lower")
        for i in range(shape[0]):
            for j in range(shape[1]):
                value = shown[i, j]
                text = "x" if not np.isfinite(value) else fmt.format(value)
                light = np.isfinite(shade[i, j]) and norm(shade[i, j]) < 0.5
                ax.text(j, i, text, ha="center", va="center", fontsize=9, color="white" if light else "black")
        ax.set_xticks(range(shape[1]), [f"{a:g}\n(δ = {(a * a - 1) / (a * a + 1):.3f})" for a in columns], fontsize=8)
        ax.set_yticks(range(shape[0]), [f"{n:g}" for n in rows])
        ax.set_xlabel("hysteresis bound α on |σ_c|")
        ax.set_ylabel("attitude noise (rad, std per axis)")
        ax.set_title(label, fontsize=10)
    if title:
        fig.suptitle(_typeset(title), fontsize=10)
    return fig


def plot_distributions(
    rates: Sequence[float] | np.ndarray,
    labels: Sequence[str],
    *,
    settled_fraction: Any,
    switching_fraction: Any,
    title: str | None = None,
) -> Figure:
    """Grouped bars: the fraction of perturbed runs that settle, and that still switch at the end, per rule and rate.

    Parameters
    ----------
    rates : array_like
        (r,) sample rates (Hz).
    labels : sequence of str
        (q,) rule labels.
    settled_fraction, switching_fraction : array_like
        (q, r) fractions in [0, 1].
    title : str, optional
    """
    rate_values = np.asarray(rates, dtype=float)
    shape = (len(labels), rate_values.size)
    settled = _grid("settled_fraction", settled_fraction, shape)
    switching = _grid("switching_fraction", switching_fraction, shape)
    fig = Figure(figsize=(9.0, 3.6), layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    width = 0.8 / max(rate_values.size, 1)
    positions = np.arange(len(labels))
    for ax, values, name in (
        (axes[0], settled, "settled by the end"),
        (axes[1], switching, "switching in the last 10 s"),
    ):
        for j, rate in enumerate(rate_values):
            ax.bar(positions + (j - (rate_values.size - 1) / 2) * width, values[:, j], width, label=f"{rate:g} Hz")
        ax.set_xticks(positions, [_typeset(label) for label in labels], fontsize=8, rotation=15)
        ax.set_ylim(0.0, 1.05)
        ax.set_title(name, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("fraction of runs")
    _legend_outside(axes[1])
    if title:
        fig.suptitle(_typeset(title), fontsize=10)
    return fig


def render_rgba(fig: Figure, *, dpi: int = 80) -> np.ndarray:
    """The figure rendered by Agg as an (h, w, 4) uint8 array (for image regression tests)."""
    # deferred: matplotlib, only when a figure is made
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    previous, previous_dpi = fig.canvas, fig.get_dpi()
    canvas = FigureCanvasAgg(fig)
    fig.set_dpi(dpi)
    try:
        canvas.draw()
        image = np.asarray(canvas.buffer_rgba()).copy()
    finally:
        fig.set_dpi(previous_dpi)
        fig.set_canvas(previous)
    return image


def save_figure(fig: Figure, path: str | Path, *, dpi: int = 110) -> Path:
    """Write ``fig`` to ``path`` atomically (format by suffix, e.g. PNG) and release it.

    The image is rendered into a temporary file next to ``path`` and moved over it, so an
    interrupted run never leaves a half-written image or destroys an older one. Figures
    made by pyplot are closed; figures made by this module need no closing.

    Returns
    -------
    pathlib.Path
        ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fmt = path.suffix.lstrip(".").lower() or "png"
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            fig.savefig(handle, dpi=dpi, format=fmt)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    if getattr(fig.canvas, "manager", None) is not None:  # made by pyplot: release it there
        # deferred: matplotlib, only when a figure is made
        import matplotlib.pyplot as plt

        plt.close(fig)
    return path


# ------------------------------------------------------------------------------ estimation
_ARCSEC = math.pi / (180.0 * 3600.0)


def plot_estimation_error(t: Any, error: Any, sigma: Any, *, title: str | None = None, ax: Any = None) -> Figure:
    """The attitude estimation error about each body axis with the filter's ±3σ envelope, in arcsec.

    Parameters
    ----------
    t : array_like
        (N,) times (s).
    error : array_like
        (N, 3) the estimation error δθ (rad), e.g. ``EstimatedResult.estimation_error``.
    sigma : array_like
        (N, 3) the filter's 1σ of δθ about each axis (rad): the square roots of the covariance's diagonal.
    title : str, optional, keyword-only
    ax : sequence of 3 Axes, optional, keyword-only
    """
    t = np.asarray(t, dtype=float)
    error = np.asarray(error, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    if t.ndim != 1 or error.shape != (t.size, 3) or sigma.shape != (t.size, 3):
        raise DimensionError(
            f"t (N,), error and sigma (N, 3): got t {t.shape}, error {error.shape}, sigma {sigma.shape}"
        )
    fig, axes = _new_axes(3, ax, figsize=(8.0, 6.0))
    for axis, a in enumerate(axes):
        envelope = 3 * sigma[:, axis] / _ARCSEC
        a.fill_between(t, -envelope, envelope, color="0.85", label="±3σ of the filter")
        a.plot(t, error[:, axis] / _ARCSEC, lw=0.8, label=f"δθ{_SUB[axis]}")
        a.set_ylabel(f"δθ{_SUB[axis]} (arcsec)")
        # the scale of the converged filter: the start's wide envelope is clipped, not allowed to flatten the rest
        scale = 1.5 * max(
            float(np.quantile(envelope, 0.95)), float(np.quantile(np.abs(error[:, axis]), 0.95)) / _ARCSEC
        )
        if scale > 0 and np.isfinite(scale):
            a.set_ylim(-scale, scale)
        inside = float(np.mean(np.abs(error[:, axis]) <= 3 * sigma[:, axis]))
        a.set_title(f"within ±3σ on {inside:.1%} of the samples", fontsize=8, loc="right")
        _legend_outside(a)
    axes[-1].set_xlabel("t (s)")
    if title:
        fig.suptitle(_typeset(title))
    return fig


def plot_nees(
    t: Any, nees: Any, *, dimension: int, title: str | None = None, ax: Any = None, level: float = 0.95
) -> Figure:
    """The NEES averaged over Monte Carlo runs against time, with its two-sided χ² band.

    With R runs of a consistent filter of ``dimension`` states, R times the average is χ² with R · dimension
    degrees of freedom: the band is its ``level`` interval divided by R.

    Parameters
    ----------
    t : array_like
        (N,) times (s).
    nees : array_like
        (R, N) the normalised estimation error squared of each run at each time.
    dimension : int, keyword-only
        The state dimension (6 for attitude and bias).
    """
    t = np.asarray(t, dtype=float)
    nees = np.asarray(nees, dtype=float)
    if t.ndim != 1 or nees.ndim != 2 or nees.shape[1] != t.size:
        raise DimensionError(f"t (N,) and nees (R, N): got t {t.shape}, nees {nees.shape}")
    if not (isinstance(dimension, int) and dimension >= 1):
        raise SpecificationError(f"dimension must be a positive integer, got {dimension!r}")
    if not 0.0 < level < 1.0:
        raise SpecificationError(f"level must be in (0, 1), got {level!r}")
    runs = nees.shape[0]
    low, high = chi2.ppf([(1 - level) / 2, (1 + level) / 2], runs * dimension) / runs
    average = nees.mean(axis=0)
    fig, (a,) = _new_axes(1, ax, figsize=(8.0, 3.5))
    a.axhspan(low, high, color="0.85", label=f"{level:.0%} χ² band ({runs} runs)")
    a.axhline(dimension, color="0.4", lw=0.8, ls="--", label=f"state dimension {dimension}")
    a.plot(t, average, lw=0.8, label="NEES, average over runs")
    inside = float(np.mean((average >= low) & (average <= high)))
    a.set_title(f"inside the band on {inside:.1%} of the samples; mean {average.mean():.3f}", fontsize=8, loc="right")
    a.set_xlabel("t (s)")
    a.set_ylabel("NEES")
    _legend_outside(a)
    if title:
        fig.suptitle(_typeset(title))
    return fig
