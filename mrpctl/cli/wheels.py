"""The wheels of ``mrpctl simulate``: the ``--wheels-plot`` option, the wheel metrics as text and JSON, and the
refusals of the options a wheel scenario does not take."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._scenario_wheels import RPM, check_wheel_scenario, rpm
from mrpctl.cli.common import check_plot_path
from mrpctl.errors import SpecificationError
from mrpctl.scenario import Scenario
from mrpctl.simulation import SimulationResult

__all__ = [
    "WHEELS_NOT_CERTIFIED",
    "add_wheel_options",
    "check_wheel_options",
    "wheel_lines",
    "wheel_summary",
    "wheels_json",
]


#: Why ``verify`` and ``analyze`` refuse a scenario with wheels.
WHEELS_NOT_CERTIFIED = (
    "[wheels]: {command} analyses the loop on an ideal body torque (J dw/dt = u); on the wheels the small-signal "
    "plant is M dw/dt = u with M = J - Gs diag(Js) Gs^T, and the wheels' torque and speed limits are not in the "
    "analysis: remove [wheels] from a copy of the scenario to {command} its gains for an ideal torque"
)


def add_wheel_options(parser: argparse.ArgumentParser) -> None:
    """``--wheels-plot FILE``: the wheel speeds and motor torques of a scenario with a ``[wheels]`` table."""
    parser.add_argument(
        "--wheels-plot",
        type=Path,
        metavar="FILE",
        help="write the wheel speeds (rpm) and motor torques against t, with their limits, to this image "
        "(a scenario with a [wheels] table)",
    )


def check_wheel_options(scenario: Scenario, args: argparse.Namespace) -> None:
    """Refuse, before the run, ``--wheels-plot`` without wheels and the options the wheels do not take."""
    plot = getattr(args, "wheels_plot", None)
    if plot is not None and scenario.wheels is None:
        raise SpecificationError("--wheels-plot needs a scenario with a [wheels] table (the reaction wheels)")
    try:
        check_plot_path(plot)
    except SpecificationError as exc:
        raise SpecificationError(str(exc).replace("--plot", "--wheels-plot", 1)) from exc
    check_wheel_scenario(
        scenario.wheels,
        scenario.rule,
        actuator=scenario.actuator,
        predictor=scenario.predictor,
        reference=scenario.reference,
    )


def wheel_summary(result: SimulationResult) -> dict[str, Any] | None:
    """The wheel metrics of a run as JSON values (None without wheels); per-wheel lists in the cluster's order."""
    record = result.wheels
    if record is None:
        return None
    cluster = record.cluster
    return {
        "count": cluster.count,
        "peak_speed_rpm": np.asarray(record.peak_speed) / RPM,
        "speed_limit_rpm": rpm(cluster.speed_limit),
        "peak_speed_fraction": np.asarray(record.peak_speed) / np.asarray(cluster.speed_limit),
        "final_speed_rpm": np.asarray(record.final_speeds) / RPM,
        "torque_limited_time_s": np.asarray(record.torque_limited_time),
        "speed_limited_time_s": np.asarray(record.speed_limited_time),
        "peak_momentum_Nms": record.peak_momentum,
        "momentum_capacity_Nms": np.asarray(cluster.momentum_capacity),
        "worst_wheel_index": record.worst_wheel,
    }


def wheels_json(scenario: Scenario) -> dict[str, Any] | None:
    """A scenario's wheel cluster as JSON values (None without wheels)."""
    wheels = scenario.wheels
    if wheels is None:
        return None
    return {
        "spin_axes": wheels.spin_axes.T,
        "spin_inertia": wheels.spin_inertia,
        "torque_limit": wheels.torque_limit,
        "speed_limit_rpm": rpm(wheels.speed_limit),
        "viscous": wheels.viscous,
        "coulomb": wheels.coulomb,
        "null_gain": wheels.null_gain,
        "gyroscopic": wheels.gyroscopic,
    }


def wheel_lines(result: SimulationResult) -> list[str]:
    """The wheel metrics of a run as text lines, one row per wheel (none without wheels)."""
    record = result.wheels
    if record is None:
        return []
    cluster = record.cluster
    lines = [
        f"wheels ({cluster.count}): peak stored momentum {record.peak_momentum:.4g} N m s "
        f"(capacity {np.max(cluster.momentum_capacity):.4g} N m s per wheel), worst wheel {record.worst_wheel + 1}",
        f"  {'wheel':>5} {'peak_rpm':>10} {'limit_rpm':>10} {'final_rpm':>10} {'at_torque_limit_s':>18} "
        f"{'at_speed_limit_s':>17}",
    ]
    for i in range(cluster.count):
        lines.append(
            f"  {i + 1:>5} {record.peak_speed[i] / RPM:>10.1f} {cluster.speed_limit[i] / RPM:>10.1f} "
            f"{record.final_speeds[i] / RPM:>10.1f} {record.torque_limited_time[i]:>18.4g} "
            f"{record.speed_limited_time[i]:>17.4g}"
        )
    return lines
