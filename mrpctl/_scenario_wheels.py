"""A scenario file's ``[wheels]`` table: the reaction-wheel cluster the body torque is flown on.

The table (every error names ``[wheels]`` and its key)::

    [wheels]
    layout = "orthogonal"        # three wheels along x, y, z; or "pyramid" (four wheels about z, with
                                 # elevation_deg, default 35.26 deg); or give spin_axes instead of layout
    # spin_axes = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]  # one unit axis per wheel (body frame)
    spin_inertia = 3.183e-5      # Js, kg m^2
    torque_limit = 5e-3          # u_max, N m (each wheel clipped on its own)
    speed_limit_rpm = 6000.0     # Omega_max (or speed_limit_rad_s)
    viscous = 0.0                # N m s per rad/s (optional)
    coulomb = 0.0                # N m (optional)
    limit_cycle_speed_rad_s = 1e-4  # the friction's linear band (optional)
    initial_speed_rpm = 0.0      # Omega(0) (or initial_speed_rad_s; optional)
    control_axes = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]  # the allocation's axes (optional)
    null_gain = 0.0              # 1/s, null-space momentum management, more than 3 wheels only (optional)
    bias_speed_rpm = 0.0         # the speeds it drives the wheels toward (or bias_speed_rad_s; optional)
    gyroscopic = false           # the law adds w x (J w + Gs h_s), as Basilisk's mrpFeedback (optional)

Each per-wheel value is one number for every wheel or a list of one per wheel. The wheels fly with the
rule ``"hysteretic"`` only, without ``[actuator]`` (the limits are the wheels'), ``[predictor]`` or
``[reference]``: each is refused when the file is read, with what to use instead.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mrpctl._files import toml_value
from mrpctl._validation import finite_array, finite_scalar
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.model import wheel_hub_inertia
from mrpctl.rules import rule_name
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule
from mrpctl.wheels import WheelCluster

__all__ = ["RPM", "WHEELS_TABLE", "check_wheel_scenario", "rpm", "wheels_table", "wheels_text", "wheels_toml"]

WHEELS_TABLE = "wheels"
#: rad/s per rpm: a speed in rpm times RPM is in rad/s.
RPM = math.pi / 30.0

_LAYOUTS = ("orthogonal", "pyramid")
#: The speeds that may be given in rpm or in rad/s: (WheelCluster field, key stem).
_SPEEDS = (("speed_limit", "speed_limit"), ("speeds", "initial_speed"), ("bias_speeds", "bias_speed"))
#: The other per-wheel values: (WheelCluster field, key).
_PER_WHEEL = (
    ("spin_inertia", "spin_inertia"),
    ("torque_limit", "torque_limit"),
    ("viscous", "viscous"),
    ("coulomb", "coulomb"),
    ("limit_cycle_speed", "limit_cycle_speed_rad_s"),
)
_KEYS = {
    "layout",
    "elevation_deg",
    "spin_axes",
    "control_axes",
    "null_gain",
    "gyroscopic",
    *(key for _, key in _PER_WHEEL),
    *(f"{stem}_{unit}" for _, stem in _SPEEDS for unit in ("rpm", "rad_s")),
}
_REQUIRED = ("spin_inertia", "torque_limit")
#: Values that must be > 0 (the others of _PER_WHEEL >= 0; the initial and bias speeds any sign).
_POSITIVE = {"spin_inertia", "torque_limit", "speed_limit", "limit_cycle_speed"}
_DEFAULTS = {"viscous": 0.0, "coulomb": 0.0, "limit_cycle_speed": 1e-4, "speeds": 0.0, "bias_speeds": 0.0}


def _per_wheel(key: str, value: Any, count: int, *, positive: bool | None) -> np.ndarray:
    """One number per wheel from a scalar or a list of ``count``; ``positive``: > 0, False: >= 0, None: any."""
    array = finite_array(key, value)
    if array.ndim == 0:
        array = np.full(count, float(array))
    if array.shape != (count,):
        raise DimensionError(
            f"{key}: expected one number for every wheel or a list of one per wheel ({count} wheels), got shape "
            f"{array.shape}"
        )
    if positive is True and np.any(array <= 0.0):
        raise SpecificationError(f"{key} must be > 0 for every wheel, got {array.tolist()}")
    if positive is False and np.any(array < 0.0):
        raise SpecificationError(f"{key} must be >= 0 for every wheel, got {array.tolist()}")
    return array


def _axes(table: dict[str, Any]) -> tuple[np.ndarray | None, float | None]:
    """(Gs (3, N), None) of ``spin_axes``, or (None, elevation in rad or None) of a named layout."""
    if ("layout" in table) == ("spin_axes" in table):
        raise SpecificationError(
            f"needs layout (one of {list(_LAYOUTS)}) or spin_axes (one unit axis per wheel), one of them"
        )
    if "spin_axes" in table:
        if "elevation_deg" in table:
            raise SpecificationError("elevation_deg applies to layout = 'pyramid', not to spin_axes")
        rows = finite_array("spin_axes", table["spin_axes"])
        if rows.ndim == 1 and rows.shape == (3,):
            rows = rows[None, :]
        if rows.ndim != 2 or rows.shape[1] != 3 or rows.shape[0] < 1:
            raise DimensionError(
                f"spin_axes: expected one row of 3 numbers per wheel (a unit axis, body frame; the transpose of Gs), "
                f"got shape {rows.shape}"
            )
        norms = np.linalg.norm(rows, axis=1)
        if np.any(np.abs(norms - 1.0) > 1e-12):
            raise SpecificationError(f"spin_axes: every row must be a unit vector, got norms {norms.tolist()}")
        return rows.T, None
    layout = table["layout"]
    if not isinstance(layout, str) or layout not in _LAYOUTS:
        raise SpecificationError(f"layout must be one of {list(_LAYOUTS)}, got {layout!r}")
    if "elevation_deg" not in table:
        return None, None
    if layout != "pyramid":
        raise SpecificationError(f"elevation_deg applies to layout = 'pyramid', not to {layout!r}")
    return None, math.radians(finite_scalar("elevation_deg", table["elevation_deg"]))


def _speed(table: dict[str, Any], stem: str, count: int, *, positive: bool | None) -> np.ndarray | None:
    """``<stem>_rpm`` or ``<stem>_rad_s`` in rad/s (one of them; None when neither is given)."""
    given = [key for key in (f"{stem}_rpm", f"{stem}_rad_s") if key in table]
    if len(given) > 1:
        raise SpecificationError(f"give {stem}_rpm or {stem}_rad_s, not both")
    if not given:
        return None
    values = _per_wheel(given[0], table[given[0]], count, positive=positive)
    return values * RPM if given[0].endswith("_rpm") else values


def _cluster(table: dict[str, Any]) -> WheelCluster:
    axes, elevation = _axes(table)
    count = 4 if axes is None and table["layout"] == "pyramid" else (3 if axes is None else axes.shape[1])
    for key in _REQUIRED:
        if key not in table:
            raise SpecificationError(f"needs {key} (one number for every wheel or one per wheel)")
    if "speed_limit_rpm" not in table and "speed_limit_rad_s" not in table:
        raise SpecificationError("needs speed_limit_rpm (or speed_limit_rad_s): each wheel's speed limit")
    values: dict[str, Any] = {}
    for name, key in _PER_WHEEL:
        if key in table:
            values[name] = _per_wheel(key, table[key], count, positive=name in _POSITIVE)
    for name, stem in _SPEEDS:
        speed = _speed(table, stem, count, positive=True if name in _POSITIVE else None)
        if speed is not None:
            values[name] = speed
    if "control_axes" in table:
        values["control_axes"] = finite_array("control_axes", table["control_axes"])
    if "null_gain" in table:
        values["null_gain"] = finite_scalar("null_gain", table["null_gain"])
    if "gyroscopic" in table:
        if not isinstance(table["gyroscopic"], bool):
            raise SpecificationError(f"gyroscopic must be true or false, got {table['gyroscopic']!r}")
        values["gyroscopic"] = table["gyroscopic"]
    limits = (values.pop("spin_inertia"), values.pop("torque_limit"), values.pop("speed_limit"))
    if axes is not None:
        return WheelCluster(axes, *limits, **values)
    if table["layout"] == "orthogonal":
        return WheelCluster.orthogonal(*limits, **values)
    if elevation is not None:
        values["elevation"] = elevation
    return WheelCluster.pyramid(*limits, **values)


def wheels_table(data: dict[str, Any], spacecraft: Spacecraft) -> WheelCluster | None:
    """The ``[wheels]`` table of a parsed scenario file as a [`WheelCluster`][mrpctl.wheels.WheelCluster] (None
    without it); every error names ``[wheels]`` and its key. The combinations the wheels refuse are
    checked by [`check_wheel_scenario`][mrpctl._scenario_wheels.check_wheel_scenario]."""
    if WHEELS_TABLE not in data:
        return None
    table = data[WHEELS_TABLE]
    if not isinstance(table, dict):
        raise SpecificationError(f"[wheels] must be a table of the scenario, got {table!r}")
    unknown = sorted(set(table) - _KEYS)
    if unknown:
        raise SpecificationError(f"unknown key {unknown[0]!r} in [wheels] of the scenario; allowed: {sorted(_KEYS)}")
    try:
        cluster = _cluster(table)
        wheel_hub_inertia(spacecraft, cluster)  # J − Gs diag(Js) Gsᵀ positive definite
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[wheels] {_key_names(str(exc))}") from exc
    return cluster


def _key_names(message: str) -> str:
    """A WheelCluster message with its parameter names as the table's keys (speeds in rad/s)."""
    for name, key in (
        ("speed_limit", "speed_limit (rad/s)"),
        ("bias_speeds", "bias_speed (rad/s)"),
        ("speeds", "initial_speed (rad/s)"),
        ("limit_cycle_speed", "limit_cycle_speed_rad_s"),
    ):
        if message.startswith(name + " ") or message.startswith(name + ":"):
            return key + message[len(name) :]
    return message


def check_wheel_scenario(
    wheels: WheelCluster | None,
    rule: SwitchingRule,
    *,
    actuator: Any = None,
    predictor: Any = None,
    reference: Any = None,
) -> None:
    """Refuse, naming what to use instead, a scenario whose wheels would fly with what they do not take:
    a rule other than ``"hysteretic"``, an ``[actuator]``, the predictor, a ``[reference]`` (the steering law
    ``[steering]`` flies on the wheels: `mrpctl._scenario_steering`)."""
    if wheels is None:
        return
    if predictor is not None:
        raise SpecificationError(
            "[wheels]: the predictor is not modelled on a wheel cluster; fly the wheels with [rule] type = "
            "'hysteretic' (command line: --hysteresis DELTA) and no [predictor]"
        )
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            f"[wheels]: the wheels fly with the controller-side rule only, got the rule {rule_name(rule)!r}; set "
            "[rule] type = 'hysteretic' with delta (command line: --hysteresis DELTA; delta = 0 switches as "
            "'on-current')"
        )
    if actuator is not None:
        raise SpecificationError(
            "[wheels] and [actuator] (or --torque-limit): with wheels the torque limits are the wheels' own "
            "([wheels] torque_limit and speed_limit_rpm); remove [actuator]"
        )
    if reference is not None:
        raise SpecificationError(
            "[wheels] and [reference]: tracking a reference on a wheel cluster is not modelled yet; regulate on "
            "the wheels (remove [reference]) or track with an ideal body torque (remove [wheels])"
        )


def _exact_rpm(values: np.ndarray) -> np.ndarray | None:
    """Speeds (rad/s) as rpm values that read back to them bit for bit (``rpm * RPM``), the shortest written
    of those within 8 ulp of value / RPM; None when one has none."""
    found = []
    for value in values.tolist():
        guess = value / RPM
        candidates = [guess]
        for direction in (math.inf, -math.inf):
            step = guess
            for _ in range(8):
                step = math.nextafter(step, direction)
                candidates.append(step)
        exact = [c for c in candidates if c * RPM == value]
        if not exact:
            return None
        found.append(min(exact, key=lambda c: (len(repr(c)), abs(c - guess))))
    return np.array(found)


def rpm(values: np.ndarray) -> np.ndarray:
    """Speeds (rad/s) in rpm, written shortest where a value reads back exactly (6000.0, not 6000.000000000001)."""
    exact = _exact_rpm(np.asarray(values, dtype=float).ravel())
    return np.asarray(values, dtype=float) / RPM if exact is None else exact.reshape(np.shape(values))


def _value(values: np.ndarray) -> Any:
    """One number when every wheel has it, else the list (floats to full precision: ``repr``)."""
    array = np.asarray(values, dtype=float)
    if array.size and np.all(array == array[0]) and np.all(np.signbit(array) == np.signbit(array[0])):
        return float(array[0])
    return array.tolist()


def wheels_toml(wheels: WheelCluster | None) -> list[str]:
    """The ``[wheels]`` lines of a cluster (none without it), read back by
    [`wheels_table`][mrpctl._scenario_wheels.wheels_table] to the same cluster bit for bit: the spin axes
    written out, speeds in rpm when they read back exactly, else in rad/s."""
    if wheels is None:
        return []
    lines = [
        "",
        "[wheels]",
        f"spin_axes = {toml_value(wheels.spin_axes.T.tolist())}  # one unit axis per wheel (body frame)",
        f"spin_inertia = {toml_value(_value(wheels.spin_inertia))}  # Js, kg m^2",
        f"torque_limit = {toml_value(_value(wheels.torque_limit))}  # u_max, N m",
    ]
    for name, stem in _SPEEDS:
        values = np.asarray(getattr(wheels, name))
        if name != "speed_limit" and not np.any(values):
            continue
        rpm = _exact_rpm(values)
        if rpm is not None:
            lines.append(f"{stem}_rpm = {toml_value(_value(rpm))}")
        else:
            lines.append(f"{stem}_rad_s = {toml_value(_value(values))}")
    for name, key in _PER_WHEEL[2:]:
        values = np.asarray(getattr(wheels, name))
        if not np.array_equal(values, np.full(wheels.count, _DEFAULTS[name])):
            lines.append(f"{key} = {toml_value(_value(values))}")
    if not np.array_equal(wheels.control_axes, np.eye(3)):
        lines.append(f"control_axes = {toml_value(wheels.control_axes.tolist())}  # unit rows")
    if wheels.null_gain:
        lines.append(f"null_gain = {toml_value(wheels.null_gain)}  # 1/s")
    if wheels.gyroscopic:
        lines.append("gyroscopic = true")
    return lines


def wheels_text(wheels: WheelCluster) -> str:
    """One line describing a cluster (for a scenario's text)."""
    capacity = wheels.momentum_capacity

    def shown(values: np.ndarray, scale: float = 1.0) -> str:
        v = _value(np.asarray(values) * scale)
        return f"{v:.4g}" if isinstance(v, float) else "[" + ", ".join(f"{x:.4g}" for x in v) + "]"

    return (
        f"wheels: {wheels.count}, Js = {shown(wheels.spin_inertia)} kg m^2, u_max = {shown(wheels.torque_limit)} N m, "
        f"speed limit {shown(rpm(wheels.speed_limit))} rpm, momentum {shown(capacity)} N m s per wheel"
    )
