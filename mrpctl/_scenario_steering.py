"""A scenario file's ``[steering]`` table: the rate-limited MRP steering law the loop flies instead of the PD law.

The table (every error names ``[steering]`` and its key; the fields of
[`SteeringLaw`][mrpctl.flight.steering.SteeringLaw])::

    [steering]
    rate_limit = 0.1942        # omega_max, rad/s: the largest commanded rate
    acceleration = 0.012       # a, rad/s^2: the deceleration the stopping distance counts on
    lag = 0.4248               # T, s: the reaction time in the stopping distance (optional, default 0)
    momentum_limit = 0.02      # h, N m s: the largest body momentum |J w| of the commanded rate, J the
                               # [spacecraft] inertia (optional; a wheel cluster's guaranteed momentum)

``mrpctl design --torque-limit U --toml FILE`` (or ``--wheels SCENARIO``) writes it with the designed numbers. The
law is K near the target ([gains]) and needs K's rate block K[:, 3:6] invertible; it flies with the rule
``"hysteretic"`` on an ideal torque (with or without ``[actuator]``) or on ``[wheels]``, and is refused with the
predictor and with ``[reference]`` (each with what to use instead) when the file is read.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.flight.steering import SteeringLaw, check_law
from mrpctl.rules import rule_name
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule

__all__ = [
    "STEERING_NOT_CERTIFIED",
    "STEERING_TABLE",
    "check_steering_scenario",
    "steering_json",
    "steering_table",
    "steering_toml",
]

STEERING_TABLE = "steering"
_KEYS = ("rate_limit", "acceleration", "lag", "momentum_limit")
_REQUIRED = ("rate_limit", "acceleration")


def steering_table(data: dict[str, Any], spacecraft: Spacecraft) -> SteeringLaw | None:
    """The ``[steering]`` table of a parsed scenario file as a [`SteeringLaw`][mrpctl.flight.steering.SteeringLaw]
    (None without it); ``momentum_limit`` is measured with ``spacecraft``'s inertia. Every error names
    ``[steering]`` and its key; the combinations the law refuses are checked by
    [`check_steering_scenario`][mrpctl._scenario_steering.check_steering_scenario]."""
    if STEERING_TABLE not in data:
        return None
    table = data[STEERING_TABLE]
    if not isinstance(table, dict):
        raise SpecificationError(f"[steering] must be a table of the scenario, got {table!r}")
    unknown = sorted(set(table) - set(_KEYS))
    if unknown:
        raise SpecificationError(f"unknown key {unknown[0]!r} in [steering] of the scenario; allowed: {list(_KEYS)}")
    for key in _REQUIRED:
        if key not in table:
            raise SpecificationError(
                f"[steering] needs {key} ({'rad/s' if key == 'rate_limit' else 'rad/s^2'}); `mrpctl design "
                "--torque-limit U --toml FILE` writes the designed table"
            )
    for key, value in table.items():
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SpecificationError(f"[steering] {key} must be a number, got {value!r}")
    momentum = table.get("momentum_limit")
    try:
        return SteeringLaw(
            rate_limit=table["rate_limit"],
            acceleration=table["acceleration"],
            lag=table.get("lag", 0.0),
            momentum_limit=momentum,
            spacecraft=None if momentum is None else spacecraft,
        )
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[steering] {exc}") from exc


def check_steering_scenario(
    law: SteeringLaw | None,
    rule: SwitchingRule,
    K: Any,
    *,
    predictor: Any = None,
    reference: Any = None,
) -> None:
    """Refuse, naming what to use instead, a scenario whose steering law would fly with what it does not take: a
    rule other than ``"hysteretic"``, the predictor, a ``[reference]``, gains with a singular rate block."""
    if law is None:
        return
    if predictor is not None:
        raise SpecificationError(
            "[steering] and [predictor]: the steering law runs in the flight loop, not with the predictor; fly it "
            "with [rule] type = 'hysteretic' and no [predictor], or remove [steering]"
        )
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            f"[steering]: the steering law flies with the controller-side rule only, got the rule {rule_name(rule)!r}; "
            "set [rule] type = 'hysteretic' with delta (command line: --hysteresis DELTA; delta = 0 switches as "
            "'on-current')"
        )
    if reference is not None:
        raise SpecificationError(
            "[steering] and [reference]: tracking a reference with the steering law is not supported (its stopping "
            "distance counts on a target at rest); regulate with the law (remove [reference]) or track with the PD "
            "law (remove [steering])"
        )
    try:
        check_law(law, (rule,), K)
    except SpecificationError as exc:
        raise SpecificationError(f"[steering] with [gains]: {exc}") from exc


def steering_toml(law: SteeringLaw | None, spacecraft: Spacecraft) -> list[str]:
    """The ``[steering]`` lines of a law (none without it), read back by
    [`steering_table`][mrpctl._scenario_steering.steering_table] to the same law bit for bit (floats by ``repr``).
    A momentum limit is written only when the law measures it with ``spacecraft``'s inertia (the scenario's)."""
    if law is None:
        return []
    if law.spacecraft is not None and not np.array_equal(law.spacecraft.inertia, spacecraft.inertia):
        raise SpecificationError(
            "law: a [steering] table measures the momentum limit with the scenario's [spacecraft] inertia; give the "
            "SteeringLaw spacecraft=scenario.spacecraft (or no momentum_limit)"
        )
    lines = [
        "",
        "[steering]",
        f"rate_limit = {law.rate_limit!r}  # omega_max, rad/s",
        f"acceleration = {law.acceleration!r}  # a, rad/s^2",
        f"lag = {law.lag!r}  # T, s",
    ]
    if law.momentum_limit is not None:
        lines.append(f"momentum_limit = {law.momentum_limit!r}  # h, N m s: |J omega| of the commanded rate")
    return lines


#: Why ``verify`` and ``analyze`` refuse a scenario with a steering law.
STEERING_NOT_CERTIFIED = (
    "[steering]: {command} analyses the linear law u = K x(t - tau) ([gains]); the steering law is K only near the "
    "target and its rate limit is not in the analysis: remove [steering] from a copy of the scenario to {command} "
    "its gains"
)


def steering_json(law: SteeringLaw) -> dict[str, float | None]:
    """The law's numbers as JSON values (the ``[steering]`` keys)."""
    return {
        "rate_limit": law.rate_limit,
        "acceleration": law.acceleration,
        "lag": law.lag,
        "momentum_limit": law.momentum_limit,
    }
