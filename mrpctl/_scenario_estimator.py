"""A scenario file's ``[estimator]`` table: the loop on an estimator of a late star tracker and a fast gyro.

The table and its sub-tables take the keywords of the Python API
([`StarTracker`][mrpctl.estimation.StarTracker], [`Gyro`][mrpctl.estimation.Gyro],
[`Estimator`][mrpctl.estimation.Estimator], [`EstimatorTuning`][mrpctl.estimation.EstimatorTuning]); each
error names its table and key::

    [estimator]
    kind = "mekf"                  # or "mrp_ekf"
    seed = 1                       # the sensors' noise (NumPy's PCG64), >= 0; default 0
    attitude_error = 1e-3          # rad, 1 sigma of the initial estimate's error (omit: Farrenkopf's P0)
    bias_error = 2e-3              # rad/s, the same for the bias
    initial_bias = [0.0, 0.0, 0.0] # the initial bias estimate (rad/s)
    # initial_sigma = [...]        # the initial attitude estimate (default: the true initial attitude)
    covariance_now = true          # record the covariance now (false: at the measurement time, cheaper)

    [estimator.star_tracker]
    noise_arcsec = 10.0            # 1 sigma per axis (one value or three); or noise (rad)
    rate = 2.0                     # Hz; divides the scenario's rate
    latency = 0.5                  # s; the scenario's tau (default tau)
    dropout = 0.05                 # probability a measurement is lost, in [0, 1)
    # boresight = [0.0, 0.0, 1.0]  # with roll_noise_arcsec (or roll_noise, rad): the noise about it

    [estimator.gyro]
    rate_noise = 1e-5              # angle random walk, rad/sqrt(s)
    bias_walk = 1e-7               # bias random walk, rad/s^1.5
    initial_bias = [5e-4, -3e-4, 2e-4]  # the true initial bias (rad/s)
    scale_factor = [0.0, 0.0, 0.0]

    # [estimator.tuning]           # the filter's own noise model (default: the sensors'); any of
    # rate_noise, bias_walk, measurement_covariance (3x3, rad^2), initial_covariance (6x6)

The scenario's ``rate`` is the controller's and the gyro's, ``tau`` the tracker's latency, ``[rule]`` the
controller-side ``"hysteretic"`` rule on the estimate; the loop has no ``[actuator]``, ``[sensor]``,
``[disturbance]``, ``[delay]``, ``[predictor]`` or ``[reference]`` (``design/estimation.md``).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mrpctl._validation import finite_array
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.estimation import (
    ARCSEC,
    Estimator,
    EstimatorKind,
    EstimatorTuning,
    Gyro,
    Sensors,
    StarTracker,
)
from mrpctl.estimation.setup import EstimatedLoop
from mrpctl.flight import Hysteretic
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule

__all__ = ["ESTIMATOR_TABLE", "estimator_table", "estimator_toml"]

#: The estimated loop's table (optional).
ESTIMATOR_TABLE = "estimator"
_KEYS = {
    "kind",
    "seed",
    "attitude_error",
    "bias_error",
    "initial_bias",
    "initial_sigma",
    "covariance_now",
    "star_tracker",
    "gyro",
    "tuning",
}
_TRACKER_KEYS = {"noise", "noise_arcsec", "rate", "latency", "dropout", "boresight", "roll_noise", "roll_noise_arcsec"}
_GYRO_KEYS = {"rate_noise", "bias_walk", "initial_bias", "scale_factor"}
_TUNING_KEYS = {"rate_noise", "bias_walk", "measurement_covariance", "initial_covariance"}
#: The tables of other loops: the estimated loop flies none of them.
_OTHER_LOOPS = ("actuator", "sensor", "disturbance", "delay", "predictor", "reference", "wheels", "steering")


def _keys(where: str, table: Any, allowed: set[str]) -> dict[str, Any]:
    if not isinstance(table, dict):
        raise SpecificationError(f"[{where}] must be a table of the scenario, got {table!r}")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SpecificationError(f"unknown key {unknown[0]!r} in [{where}] of the scenario; allowed: {sorted(allowed)}")
    return table


def _sub_table(table: dict[str, Any], name: str, allowed: set[str], *, required: bool) -> dict[str, Any] | None:
    if name not in table:
        if required:
            raise SpecificationError(f"[{ESTIMATOR_TABLE}] needs a [{ESTIMATOR_TABLE}.{name}] table")
        return None
    return _keys(f"{ESTIMATOR_TABLE}.{name}", table[name], allowed)


def _one_of(table: dict[str, Any], key: str, *, required: bool) -> Any:
    """The value of ``key`` (rad) or of ``key_arcsec`` (converted), not both."""
    arcsec = f"{key}_arcsec"
    if key in table and arcsec in table:
        raise SpecificationError(f"give {key} (rad) or {arcsec}, not both")
    if arcsec in table:
        value = finite_array(arcsec, table[arcsec])
        if np.any(value <= 0.0):
            raise SpecificationError(f"{arcsec} must be > 0 arcsec (1 sigma), got {value.tolist()}")
        value = value * ARCSEC
        return float(value) if value.ndim == 0 else value
    if key in table:
        return table[key]
    if required:
        raise SpecificationError(f"needs {arcsec} (1 sigma, arcsec) or {key} (rad)")
    return None


def _star_tracker(table: dict[str, Any], tau: float, rate: float) -> StarTracker:
    if "rate" not in table:
        raise SpecificationError("needs rate (the star tracker's measurement rate, Hz)")
    latency = table.get("latency", tau)
    tracker = StarTracker(
        _one_of(table, "noise", required=True),
        table["rate"],
        latency,
        dropout=table.get("dropout", 0.0),
        boresight=table.get("boresight"),
        roll_noise=_one_of(table, "roll_noise", required=False),
    )
    if not math.isclose(tracker.latency, tau, rel_tol=1e-9, abs_tol=1e-12):
        raise SpecificationError(
            f"latency: the estimated loop's delay is the star tracker's latency, so it must equal the scenario's "
            f"tau = {tau:g} s, got {tracker.latency:g} s"
        )
    tracker.clock(rate)  # the controller rate a whole multiple of the tracker's, the latency whole periods
    return tracker


def _gyro(table: dict[str, Any]) -> Gyro:
    for key in ("rate_noise", "bias_walk"):
        if key not in table:
            raise SpecificationError(
                f"needs {key} ({'angle random walk, rad/sqrt(s)' if key == 'rate_noise' else 'rad/s^1.5'})"
            )
    return Gyro(
        table["rate_noise"],
        table["bias_walk"],
        initial_bias=table.get("initial_bias", (0.0, 0.0, 0.0)),
        scale_factor=table.get("scale_factor", (0.0, 0.0, 0.0)),
    )


def _section(where: str, build: Any, *args: Any) -> Any:
    """``build(*args)`` with its error prefixed by the table it came from."""
    try:
        return build(*args)
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[{where}] {exc}") from exc


def _estimator(
    table: dict[str, Any], tracker: StarTracker, gyro: Gyro, tuning_table: dict[str, Any] | None
) -> Estimator:
    covariance_now = table.get("covariance_now", True)
    if not isinstance(covariance_now, bool):
        raise SpecificationError(f"covariance_now must be true or false, got {covariance_now!r}")
    options = {key: table[key] for key in ("kind", "attitude_error", "bias_error", "initial_sigma") if key in table}
    estimator = Estimator(
        initial_bias=table.get("initial_bias", (0.0, 0.0, 0.0)), covariance_now=covariance_now, **options
    )
    if tuning_table is None:
        return estimator
    default = EstimatorTuning.from_sensors(
        tracker, gyro, attitude_error=estimator.attitude_error, bias_error=estimator.bias_error
    )
    tuning = _section(
        f"{ESTIMATOR_TABLE}.tuning",
        lambda: EstimatorTuning(
            tuning_table.get("rate_noise", default.rate_noise),
            tuning_table.get("bias_walk", default.bias_walk),
            tuning_table.get("measurement_covariance", default.measurement_covariance),
            tuning_table.get("initial_covariance", default.initial_covariance),
        ),
    )
    return Estimator(
        kind=estimator.kind,
        tuning=tuning,
        initial_sigma=estimator.initial_sigma,
        initial_bias=estimator.initial_bias,
        attitude_error=estimator.attitude_error,
        bias_error=estimator.bias_error,
        covariance_now=estimator.covariance_now,
    )


def estimator_table(
    data: dict[str, Any], *, spacecraft: Spacecraft, rule: SwitchingRule, tau: float, rate: float, history: str
) -> EstimatedLoop | None:
    """The ``[estimator]`` table of a scenario's data as an [`EstimatedLoop`][mrpctl.estimation.EstimatedLoop]
    (None without the table); a [`SpecificationError`][mrpctl.SpecificationError] names the table and key."""
    if ESTIMATOR_TABLE not in data:
        return None
    table = _keys(ESTIMATOR_TABLE, data[ESTIMATOR_TABLE], _KEYS)
    others = [f"[{name}]" for name in _OTHER_LOOPS if name in data]
    if others:
        raise SpecificationError(
            f"[{ESTIMATOR_TABLE}]: the estimated loop flies the PD law on the estimate without {', '.join(others)}; "
            "drop them, or drop [estimator] to fly the loop they model"
        )
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(
            f"[{ESTIMATOR_TABLE}] needs [rule] type = 'hysteretic' (the controller-side rule acts on the estimate), "
            f"got {rule}"
        )
    if history != "constant":
        raise SpecificationError(f"[{ESTIMATOR_TABLE}] needs history = 'constant', got {history!r}")
    if not spacecraft.is_diagonal:
        raise SpecificationError(
            f"[{ESTIMATOR_TABLE}] needs a diagonal [spacecraft] inertia (principal axes): give 3 principal values"
        )
    tracker_table = _sub_table(table, "star_tracker", _TRACKER_KEYS, required=True)
    gyro_table = _sub_table(table, "gyro", _GYRO_KEYS, required=True)
    tuning_table = _sub_table(table, "tuning", _TUNING_KEYS, required=False)
    tracker = _section(f"{ESTIMATOR_TABLE}.star_tracker", _star_tracker, tracker_table, tau, rate)
    gyro = _section(f"{ESTIMATOR_TABLE}.gyro", _gyro, gyro_table)
    estimator = _section(ESTIMATOR_TABLE, _estimator, table, tracker, gyro, tuning_table)
    sensors = _section(ESTIMATOR_TABLE, lambda: Sensors(tracker, gyro, seed=table.get("seed", 0)))
    return EstimatedLoop(sensors, estimator)


def _value(value: Any) -> str:
    """A bool, an int, a string, a float or a (nested) list of floats as TOML (floats by repr: bit for bit)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, int):
        return str(value)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    return repr(float(value))


def _angle(key: str, value: Any) -> str:
    """``key_arcsec = …`` when it reads back to the same radians bit for bit, else ``key = …`` (rad)."""
    radians = np.asarray(value, dtype=float)
    arcsec = radians / ARCSEC
    if np.array_equal(arcsec * ARCSEC, radians):
        return f"{key}_arcsec = {_value(arcsec)}  # 1 sigma"
    return f"{key} = {_value(radians)}  # rad, 1 sigma ({_value(np.round(arcsec, 6))} arcsec)"


def estimator_toml(loop: EstimatedLoop | None) -> list[str]:
    """The ``[estimator]`` table's lines (none without an estimated loop), read back to the same values."""
    if loop is None:
        return []
    estimator, tracker, gyro = loop.estimator, loop.sensors.star_tracker, loop.sensors.gyro
    kind = EstimatorKind(estimator.kind).value
    lines = ["", f"[{ESTIMATOR_TABLE}]", f"kind = {_value(kind)}", f"seed = {loop.sensors.seed}  # the sensors' noise"]
    for key, unit in (("attitude_error", "rad"), ("bias_error", "rad/s")):
        value = getattr(estimator, key)
        if value is not None:
            lines.append(f"{key} = {_value(value)}  # {unit}, 1 sigma of the initial estimate's error")
    lines.append(f"initial_bias = {_value(estimator.initial_bias)}  # the initial bias estimate (rad/s)")
    if estimator.initial_sigma is not None:
        lines.append(f"initial_sigma = {_value(estimator.initial_sigma)}  # the initial attitude estimate")
    lines.append(f"covariance_now = {_value(estimator.covariance_now)}")
    lines += ["", f"[{ESTIMATOR_TABLE}.star_tracker]", _angle("noise", tracker.noise)]
    lines += [
        f"rate = {_value(tracker.rate)}  # Hz",
        f"latency = {_value(tracker.latency)}  # s, the scenario's tau",
        f"dropout = {_value(tracker.dropout)}",
    ]
    if tracker.boresight is not None:
        lines += [f"boresight = {_value(tracker.boresight)}  # body frame", _angle("roll_noise", tracker.roll_noise)]
    lines += [
        "",
        f"[{ESTIMATOR_TABLE}.gyro]",
        f"rate_noise = {_value(gyro.rate_noise)}  # rad/sqrt(s)",
        f"bias_walk = {_value(gyro.bias_walk)}  # rad/s^1.5",
        f"initial_bias = {_value(gyro.initial_bias)}  # rad/s, the true initial bias",
        f"scale_factor = {_value(gyro.scale_factor)}",
    ]
    tuning = estimator.tuning
    if tuning is not None:
        lines += [
            "",
            f"[{ESTIMATOR_TABLE}.tuning]",
            f"rate_noise = {_value(tuning.rate_noise)}  # rad/sqrt(s)",
            f"bias_walk = {_value(tuning.bias_walk)}  # rad/s^1.5",
            f"measurement_covariance = {_value(tuning.measurement_covariance)}  # rad^2",
            f"initial_covariance = {_value(tuning.initial_covariance)}  # on (attitude error, bias error)",
        ]
    return lines
