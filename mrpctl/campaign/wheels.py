"""Campaigns on reaction wheels: the ``[wheels]`` table of a campaign file, the per-run wheel metrics it stores
and their summary in the report.

A campaign file takes the scenario's ``[wheels]`` table (`mrpctl._scenario_wheels`): every run flies on that
one cluster (``simulate_batch(..., wheels=...)``, the lane engine for the metrics). Refused with it, each with
what to use instead: a rule other than ``hysteretic``, the predictor, ``flight.u_max`` and
``[dispersions.actuator]`` (the limits are the wheels'), and ``[dispersions.inertia]`` (the wheel engine
compiles J in: one library per dispersed inertia). Stored per run (over ``run`` and ``wheel``): `WHEEL_METRICS`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from mrpctl._scenario_wheels import RPM, WHEELS_TABLE, wheels_table
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

__all__ = [
    "WHEEL_METRICS",
    "campaign_wheels",
    "check_campaign_wheels",
    "wheel_metrics",
    "wheel_summary",
    "wheel_summary_lines",
]

#: Per-run wheel metrics: name -> (dims after run, dtype, missing value, unit), from each run's
#: [`WheelRecord`][mrpctl.simulation.results.WheelRecord].
WHEEL_METRICS: dict[str, tuple[tuple[str, ...], Any, Any, str]] = {
    "wheel_peak_speed": (("wheel",), np.float64, np.nan, "rad/s"),
    "wheel_final_speed": (("wheel",), np.float64, np.nan, "rad/s"),
    "wheel_torque_limited_time": (("wheel",), np.float64, np.nan, "s"),
    "wheel_speed_limited_time": (("wheel",), np.float64, np.nan, "s"),
    "wheel_peak_momentum": ((), np.float64, np.nan, "N m s"),
    "worst_wheel": ((), np.int64, -1, "1"),
}
_FIELDS = {
    "wheel_peak_speed": "peak_speed",
    "wheel_final_speed": "final_speeds",
    "wheel_torque_limited_time": "torque_limited_time",
    "wheel_speed_limited_time": "speed_limited_time",
    "wheel_peak_momentum": "peak_momentum",
    "worst_wheel": "worst_wheel",
}


def campaign_wheels(table: Any, spacecraft: Spacecraft) -> WheelCluster | None:
    """The campaign's ``[wheels]`` table (None: not given) as the cluster every run flies on."""
    return None if table is None else wheels_table({WHEELS_TABLE: table}, spacecraft)


def check_campaign_wheels(spec: Any) -> None:
    """Refuse what a campaign on wheels does not run, saying what to use instead."""
    if spec.base.wheels is None:
        return
    other = [
        label for label, rule in zip(spec.rule_labels, spec.rule_list, strict=True) if not isinstance(rule, Hysteretic)
    ]
    if spec.predictor is not None:
        raise SpecificationError(
            "[wheels]: the predictor is not modelled on a wheel cluster; fly the wheels with the rule 'hysteretic'"
        )
    if other:
        raise SpecificationError(
            f"[wheels]: the wheels fly with the controller-side rule only, got {other[0]!r}; use 'hysteretic' with "
            "delta ('hysteretic:0' switches as 'on-current'), in [rule] and in [dispersions.rule]"
        )
    if (spec.flight is not None and spec.flight.actuator is not None) or spec.flight_dispersion.u_max is not None:
        raise SpecificationError(
            "[wheels] and flight.u_max or [dispersions.actuator]: with wheels the torque limits are the wheels' own "
            "([wheels] torque_limit, speed_limit_rpm); remove flight.u_max, flight.norm_max, flight.saturation and "
            "[dispersions.actuator]"
        )
    if spec.inertia is not None:
        raise SpecificationError(
            "[wheels] and [dispersions.inertia]: the wheel engine compiles the spacecraft's inertia in (one library "
            "per inertia, so one compilation per run); run the campaign on wheels at the nominal inertia, or "
            "several campaigns, one per inertia"
        )
    if spec.base.reference is not None:
        raise SpecificationError(
            "[wheels] and [reference]: tracking a reference on a wheel cluster is not modelled yet; remove one"
        )


def wheel_metrics(records: Sequence[Any] | None, count: int, wheels: int) -> dict[str, np.ndarray]:
    """The `WHEEL_METRICS` arrays of ``count`` runs from their wheel records (missing values without them)."""
    out = {
        name: np.full((count, *([wheels] if dims else [])), missing, dtype=dtype)
        for name, (dims, dtype, missing, _) in WHEEL_METRICS.items()
    }
    for i, record in enumerate(records or ()):
        for name, field in _FIELDS.items():
            out[name][i] = getattr(record, field)
    return out


def _quantiles(values: np.ndarray) -> dict[str, float | None]:
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return {"median": None, "p95": None, "max": None}
    return {
        "median": float(np.median(finite)),
        "p95": float(np.quantile(finite, 0.95)),
        "max": float(np.max(finite)),
    }


def wheel_summary(
    dataset: Any, speed_limit: np.ndarray | None, capacity: np.ndarray | None, *, loads: np.ndarray | None = None
) -> dict[str, Any] | None:
    """The wheel metrics of a campaign's runs per wheel (None without wheels): the peak speed (rpm), the runs
    that reached the speed limit or the torque limit, the time at each limit, the peak stored momentum and how
    often each wheel was the worst one; with ``loads`` (each run's
    [`rest_momentum_load`][mrpctl.wheels.rest_momentum_load]) the runs that start with more angular momentum than
    the wheels hold at rest."""
    if "wheel_peak_speed" not in dataset:
        return None
    peak = np.asarray(dataset["wheel_peak_speed"], dtype=float)
    torque = np.asarray(dataset["wheel_torque_limited_time"], dtype=float)
    speed = np.asarray(dataset["wheel_speed_limited_time"], dtype=float)
    worst = np.asarray(dataset["worst_wheel"], dtype=np.int64)
    count = peak.shape[1]
    per_wheel = []
    for i in range(count):
        per_wheel.append(
            {
                "wheel": i + 1,
                "peak_speed_rpm": _quantiles(peak[:, i] / RPM),
                "speed_limit_rpm": None if speed_limit is None else float(speed_limit[i] / RPM),
                "runs_at_speed_limit": int(np.sum(speed[:, i] > 0.0)),
                "runs_at_torque_limit": int(np.sum(torque[:, i] > 0.0)),
                "speed_limited_time_s": _quantiles(speed[:, i]),
                "torque_limited_time_s": _quantiles(torque[:, i]),
                "worst_in_runs": int(np.sum(worst == i)),
            }
        )
    return {
        "count": count,
        "runs": int(peak.shape[0]),
        "peak_momentum_Nms": _quantiles(np.asarray(dataset["wheel_peak_momentum"], dtype=float)),
        "momentum_capacity_Nms": None if capacity is None else [float(c) for c in capacity],
        **(
            {}
            if loads is None
            else {"runs_beyond_capacity": int(np.sum(loads > 1.0)), "initial_momentum_load": _quantiles(loads)}
        ),
        "wheels": per_wheel,
    }


def wheel_summary_lines(summary: dict[str, Any] | None) -> list[str]:
    """The report's text lines of [`wheel_summary`][mrpctl.campaign.wheels.wheel_summary] (none without wheels)."""
    if summary is None:
        return []

    def g(value: float | None) -> str:
        return "nan" if value is None or not math.isfinite(value) else f"{value:.4g}"

    momentum = summary["peak_momentum_Nms"]
    capacity = summary["momentum_capacity_Nms"]
    lines = [
        f"  wheels        {summary['count']}; peak stored momentum median {g(momentum['median'])}, max "
        f"{g(momentum['max'])} N m s" + ("" if capacity is None else f" (capacity {g(max(capacity))} N m s per wheel)"),
        f"    {'wheel':>5} {'peak_rpm_med':>12} {'peak_rpm_max':>12} {'limit_rpm':>9} {'runs_at_speed_lim':>17} "
        f"{'runs_at_torque_lim':>18} {'speed_lim_s_max':>15} {'torque_lim_s_max':>16} {'worst_in':>8}",
    ]
    if summary.get("runs_beyond_capacity"):
        lines.insert(
            1,
            f"    {summary['runs_beyond_capacity']} of {summary['runs']} runs start with more angular momentum than "
            f"the wheels hold at rest (load up to {g(summary['initial_momentum_load']['max'])}): without an external "
            "torque they cannot settle",
        )
    for w in summary["wheels"]:
        lines.append(
            f"    {w['wheel']:>5} {g(w['peak_speed_rpm']['median']):>12} {g(w['peak_speed_rpm']['max']):>12} "
            f"{g(w['speed_limit_rpm']):>9} {w['runs_at_speed_limit']:>17} {w['runs_at_torque_limit']:>18} "
            f"{g(w['speed_limited_time_s']['max']):>15} {g(w['torque_limited_time_s']['max']):>16} "
            f"{w['worst_in_runs']:>8}"
        )
    return lines
