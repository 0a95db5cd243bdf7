"""A scenario file's optional tables and per-sample files as models ([actuator], [sensor], [disturbance], [delay],
[reference]), each error naming its table and key."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._files import read_numbers, toml_value
from mrpctl._validation import (
    finite_array,
    finite_scalar,
    nonnegative_scalar,
    positive_scalar,
)
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayKind, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel
from mrpctl.flight.tracking import ErrorTime
from mrpctl.guidance import (
    CircularOrbit,
    EigenaxisSlew,
    FileReference,
    GuidanceProfile,
    InertialPointing,
    NadirPointing,
)
from mrpctl.loop import delay_samples
from mrpctl.predictor import OnPredicted
from mrpctl.rules import rule_name
from mrpctl.switching import SwitchingRule

#: Tables of the loop as flown (``[rule] type = "hysteretic"`` or ``"on-predicted"``), all optional.
FLIGHT_TABLES = {"actuator", "sensor", "disturbance", "delay"}


#: The guidance profile the loop tracks (optional; none: regulation to the inertial origin).
REFERENCE_TABLE = "reference"


#: The keys of [reference] for each of its types (``type`` itself is allowed for all).
_REFERENCE_KEYS = {
    "inertial": {"sigma"},
    "slew": {"start", "target", "axis", "angle_deg", "rate_limit", "acceleration_limit", "t_start"},
    "nadir": {"orbit_rate", "altitude", "radius", "mu", "inclination_deg", "raan_deg", "latitude_deg"},
    "file": {"file"},
}


TABLE_KEYS = {
    "spacecraft": {"inertia"},
    "gains": {"K", "k_sigma", "k_omega", "K1", "K2", "attitude", "rate"},
    "initial": {"sigma", "principal_angle_deg", "axis", "omega"},
    "rule": {"type", "eps", "alpha", "delta"},
    "actuator": {"u_max", "u_norm", "saturation"},
    "sensor": {"attitude_noise", "rate_noise", "gyro_bias", "seed"},
    "disturbance": {"torque", "torque_file"},
    "delay": {"tau_min", "tau_max", "seed", "sequence_file"},
    "predictor": {"inertia", "inertia_error", "form"},
    "uncertainty": {"inertia_tolerance", "product_bound"},
}


@dataclass(frozen=True)
class Horizon:
    """What the per-sample files of a scenario are checked against: the folder of relative paths, n samples."""

    base: Path | None
    samples: int


def sample_count(t_final: float, rate: float) -> int:
    """n = floor(t_final · rate) + 1, the measurement samples of a run (as
    [`mrpctl.simulate`][mrpctl.simulation.simulate] counts them):
    the rows a per-sample file must hold."""
    return math.floor(t_final * rate + 1e-9) + 1


def samples_file(value: Any, key: str, *, base: Path | None = None) -> np.ndarray:
    """The numbers of a per-sample file (a disturbance torque, a delay sequence) as a finite float array.

    ``value`` is the file name: ``.npy`` (NumPy, no pickles) or ``.csv`` / ``.txt`` (comma-separated,
    ``#`` comments), relative to ``base`` (the folder of the scenario or campaign TOML file; None: the
    working directory).
    A UTF-8 byte-order mark is allowed (a spreadsheet's "CSV UTF-8" export); memory is estimated before
    reading (from a ``.npy`` header, or from the CSV's size). Errors (not a name, a missing file, a folder,
    an unknown suffix, text that is not UTF-8, a cell that is not a number, a non-finite value) name ``key``,
    the file (and the file a link points to) and the row and column (from 1, as a spreadsheet shows them),
    never the file's content.
    """
    if not isinstance(value, str | Path) or not str(value):
        raise SpecificationError(f"{key} must be a file name (.csv or .npy, relative to the TOML file), got {value!r}")
    path = Path(value)
    if not path.is_absolute() and base is not None:
        path = base / path
    if not path.exists() and not path.is_symlink():
        where = "the TOML file's folder" if base is not None else "the working directory"
        raise SpecificationError(f"{key}: no file {path} (a relative name is taken from {where})")
    raw = read_numbers(path, key)
    return finite_array(f"{key} ({path})", raw)


def torque_rows(array: np.ndarray, key: str, n: int) -> np.ndarray:
    """``array`` checked as the (n, 3) per-sample torque rows of a file named by ``key``."""
    if array.shape != (n, 3):
        raise DimensionError(
            f"{key}: expected n rows of 3 torques (N m, body frame), one row per measurement sample: shape "
            f"(n, 3) = ({n}, 3) with n = floor(t_final * rate) + 1, but the file has shape {array.shape}"
        )
    return array


def delay_values(array: np.ndarray, key: str, n: int) -> np.ndarray:
    """``array`` checked as the n per-sample delays (s) of a file named by ``key`` (one column or one row)."""
    values = array.ravel() if array.ndim == 2 and 1 in array.shape else array
    if values.shape != (n,):
        raise DimensionError(
            f"{key}: expected n delays (s), one per measurement sample (one column): n = floor(t_final * rate) + 1 "
            f"= {n}, but the file has shape {array.shape}"
        )
    return values


def delay_periods(value: Any, key: str, rate: float) -> int:
    """The delay ``value`` (s) named ``key`` as a whole number of periods at ``rate`` (Hz).

    The rule is [delay_samples][mrpctl.loop.delay_samples]'s (τ · rate whole to a relative 1e-9), so a
    delay written as k · h in floating point (3 × 0.1 = 0.30000000000000004 s at 10 Hz) is k periods.
    """
    seconds = nonnegative_scalar(key, value)
    try:
        return delay_samples(seconds, rate)
    except SpecificationError as exc:
        raise SpecificationError(
            f"{key}: delays must be whole numbers of measurement periods: {seconds!r} s at rate = {rate!r} Hz is "
            f"{seconds * rate!r} periods; choose it as a multiple of 1/rate"
        ) from exc


def _delay_bounds(tau: float, rate: float, tau_min: Any) -> tuple[float, float]:
    """(tau_min, tau) of a varying delay (s), compared as whole periods: 1 <= tau_min <= tau periods.

    ``tau_min`` defaults to one period; one that equals tau in periods but not in floating point is tau.
    """
    low = 1.0 / rate if tau_min is None else nonnegative_scalar("tau_min", tau_min)
    d_low, d_high = delay_periods(low, "tau_min", rate), delay_periods(tau, "tau", rate)
    if d_low < 1:
        raise SpecificationError(f"tau_min must be >= 1/rate = {1.0 / rate:g} s, got {low!r} s")
    if d_low > d_high:
        raise SpecificationError(
            f"tau_max must be >= tau_min (compared as whole periods), got tau_min = {low!r} s ({d_low} periods), "
            f"tau_max = tau = {tau!r} s ({d_high} periods)"
        )
    return min(low, tau), tau


def _check_tau_max(tau_max: Any, tau: float, rate: float) -> None:
    """``tau_max`` must be the scenario's tau (the history depth), compared as whole periods."""
    given = nonnegative_scalar("tau_max", tau_max)
    if delay_periods(given, "tau_max", rate) != delay_samples(tau, rate):
        raise SpecificationError(
            f"tau_max must equal the scenario's tau = {tau!r} s (the history depth), got {given!r}"
        )


def delay_sequence(delays: np.ndarray, key: str, *, tau: float, rate: float, tau_min: Any = None) -> DelayModel:
    """The per-sample delay sequence of a file named by ``key``: each delay in [tau_min, tau], whole periods.

    ``tau_min`` defaults to one period 1/rate (the smallest delay the engine takes). Delays and bounds are
    compared as whole periods (the rule of [delay_periods][mrpctl.scenario.delay_periods]), so k · h written
    in floating point is accepted; the model holds each delay as d_k / rate (s), the first delay that is not
    whole or lies outside the bounds is refused with its row (from 1).
    """
    low, high = _delay_bounds(tau, rate, tau_min)
    d_low, d_high = delay_periods(low, "tau_min", rate), delay_periods(high, "tau", rate)
    values = finite_array(key, delays)
    if values.ndim != 1 or values.size == 0:
        raise DimensionError(f"{key}: expected shape (n,) (one delay per sample) but found {values.shape}")
    negative = np.flatnonzero(values < 0.0)
    if negative.size:
        row = int(negative[0])
        raise SpecificationError(
            f"delays must lie in [tau_min, tau_max]: delay {row + 1} of {key} (counted from 1) is "
            f"{float(values[row])!r} s"
        )
    try:  # the engine's rule, vectorised (a constant bound pair that holds every value)
        periods = DelayModel.sequence(values, tau_min=float(values.min()), tau_max=float(values.max())).samples(
            rate, 0, len(values)
        )
    except SpecificationError as exc:
        for row, value in enumerate(values.tolist()):  # the first delay that is not whole, named by its row
            try:
                delay_samples(value, rate)
            except SpecificationError:
                raise SpecificationError(
                    f"{key}: delays must be whole numbers of measurement periods: delay {row + 1} (counted from 1) "
                    f"is {value!r} s, "
                    f"{value * rate!r} periods at rate = {rate!r} Hz; choose delays as multiples of 1/rate"
                ) from exc
        raise SpecificationError(f"{key}: {exc}") from exc
    outside = np.flatnonzero((periods < d_low) | (periods > d_high))
    if outside.size:
        row = int(outside[0])
        raise SpecificationError(
            f"delays must lie in [tau_min, tau_max] = [{low:g}, {high:g}] s = [{d_low}, {d_high}] periods: "
            f"delay {row + 1} of {key} (counted from 1) is {float(values[row])!r} s = {int(periods[row])} periods"
        )
    seconds = np.clip(periods / rate, low, high)  # d_k / rate: the same whole periods, within the bounds
    model = DelayModel.sequence(seconds, tau_min=low, tau_max=high)
    try:
        model.samples(rate, 0, len(values))  # each a whole number of periods (as the engine will read them)
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"{key}: {exc}") from exc
    return model


def flight_tables(
    data: dict[str, Any], rule: SwitchingRule, tau: float, rate: float, horizon: Horizon
) -> dict[str, Any]:
    """The optional [actuator], [sensor], [disturbance] and [delay] tables as flight models.

    Each table is refused with a paper rule, and every error names the table and its key.
    """
    models: dict[str, Any] = {}
    for name in sorted(FLIGHT_TABLES):
        if name not in data:
            continue
        table = data[name]
        if not isinstance(table, dict):
            raise SpecificationError(f"[{name}] must be a table of the scenario, got {table!r}")
        check_keys(name, table, TABLE_KEYS[name])
        if not isinstance(rule, Hysteretic | OnPredicted):
            raise SpecificationError(
                f"[{name}] applies only to the loop as flown: set [rule] type = 'hysteretic' "
                f"(the controller-side rule) or 'on-predicted' (the predictor), got {rule_name(rule)!r}"
            )
        if name == "delay" and isinstance(rule, OnPredicted):
            raise SpecificationError(
                "[delay] does not apply with [rule] type = 'on-predicted': the predictor runs with the constant "
                "delay tau only (its correction needs the age of each measurement)"
            )
        try:
            models[name] = _FLIGHT_BUILDERS[name](table, tau, rate, horizon)
        except (SpecificationError, DimensionError) as exc:
            raise type(exc)(f"[{name}] {exc}") from exc
    return models


def _actuator(table: dict[str, Any], tau: float, rate: float, horizon: Horizon) -> ActuatorModel:
    if "u_max" not in table:
        raise SpecificationError("needs u_max (per-axis torque limit, N m; a scalar or 3 values)")
    modes = {mode.value: mode for mode in Saturation}
    mode = table.get("saturation", Saturation.SCALE.value)
    if not isinstance(mode, str) or mode not in modes:  # a TOML list or table is not hashable
        raise SpecificationError(f"saturation must be one of {sorted(modes)}, got {mode!r}")
    norm = table.get("u_norm")
    return ActuatorModel(
        u_max=table["u_max"], norm_max=None if norm is None else positive_scalar("u_norm", norm), mode=modes[mode]
    )


def _sensor(table: dict[str, Any], tau: float, rate: float, horizon: Horizon) -> SensorModel:
    return SensorModel(
        attitude_noise=table.get("attitude_noise", 0.0),
        rate_noise=table.get("rate_noise", 0.0),
        gyro_bias=table.get("gyro_bias", (0.0, 0.0, 0.0)),
        seed=table.get("seed", 0),
    )


def _disturbance(table: dict[str, Any], tau: float, rate: float, horizon: Horizon) -> Disturbance:
    if ("torque" in table) == ("torque_file" in table):
        raise SpecificationError(
            "needs torque (constant body-frame torque, 3 values, N m) or torque_file (a .csv or .npy file of n rows "
            "of 3 torques, one per measurement sample, relative to the scenario file), one of them"
        )
    if "torque_file" in table:
        rows = samples_file(table["torque_file"], "torque_file", base=horizon.base)
        return Disturbance(torque_rows(rows, "torque_file", horizon.samples))
    return Disturbance(finite_array("torque", table["torque"], (3,)))


def _delay(table: dict[str, Any], tau: float, rate: float, horizon: Horizon) -> DelayModel:
    if "sequence_file" in table:
        if "seed" in table:
            raise SpecificationError("seed applies to the jitter (tau_min, seed), not to a sequence_file")
        _check_tau_max(table.get("tau_max", tau), tau, rate)
        values = delay_values(
            samples_file(table["sequence_file"], "sequence_file", base=horizon.base), "sequence_file", horizon.samples
        )
        return delay_sequence(values, "sequence_file", tau=tau, rate=rate, tau_min=table.get("tau_min"))
    if "tau_min" not in table:
        raise SpecificationError(
            "needs tau_min (s): the delay jitters uniformly over the whole periods in [tau_min, tau]; or "
            "sequence_file (a .csv or .npy file of n delays in s, one per measurement sample)"
        )
    _check_tau_max(table.get("tau_max", tau), tau, rate)
    low, high = _delay_bounds(tau, rate, table["tau_min"])  # whole periods, 1 <= tau_min <= tau
    return DelayModel.jitter(low, high, seed=table.get("seed", 0))


_FLIGHT_BUILDERS = {"actuator": _actuator, "sensor": _sensor, "disturbance": _disturbance, "delay": _delay}


def check_keys(table: str, data: dict[str, Any], allowed: set[str]) -> None:
    unknown = sorted(set(data) - allowed)
    if unknown:
        where = "top level" if table == "" else f"[{table}]"
        raise SpecificationError(f"unknown key {unknown[0]!r} in {where} of the scenario; allowed: {sorted(allowed)}")


#: The keys of [reference] every type takes: how the controller forms and follows the error, and the slew time's
#: tolerance (keywords of simulate: error_time, feedforward, pointing_tolerance).
TRACKING_KEYS = {"error_time", "feedforward", "pointing_tolerance_deg", "gravity_gradient"}


def tracking_keys(data: dict[str, Any]) -> dict[str, Any]:
    """The tracking keywords of the [reference] table (``error_time``: "measurement" or "current";
    ``feedforward``: true or false; ``pointing_tolerance_deg`` > 0; ``gravity_gradient``: true or false, nadir
    pointing only: the plant flies the gravity-gradient torque of the reference's orbit) as keywords of the
    scenario; {} without them."""
    table = data.get(REFERENCE_TABLE)
    if not isinstance(table, dict):
        return {}
    options: dict[str, Any] = {}
    if "error_time" in table:
        names = {time.value: time for time in ErrorTime}
        if table["error_time"] not in names:
            raise SpecificationError(
                f"[reference] error_time must be one of {sorted(names)}, got {table['error_time']!r}"
            )
        options["error_time"] = names[table["error_time"]]
    if "feedforward" in table:
        if not isinstance(table["feedforward"], bool):
            raise SpecificationError(f"[reference] feedforward must be true or false, got {table['feedforward']!r}")
        options["feedforward"] = table["feedforward"]
    if "pointing_tolerance_deg" in table:
        tolerance = positive_scalar("[reference] pointing_tolerance_deg", table["pointing_tolerance_deg"])
        if tolerance > 180.0:
            raise SpecificationError(f"[reference] pointing_tolerance_deg must be at most 180, got {tolerance:g}")
        options["pointing_tolerance"] = tolerance
    if "gravity_gradient" in table:
        if not isinstance(table["gravity_gradient"], bool):
            raise SpecificationError(
                f"[reference] gravity_gradient must be true or false, got {table['gravity_gradient']!r}"
            )
        if table["gravity_gradient"] and table.get("type") != "nadir":
            raise SpecificationError(
                "[reference] gravity_gradient = true needs an orbit: it applies to type = 'nadir' only, got type = "
                f"{table.get('type')!r}"
            )
        options["gravity_gradient"] = table["gravity_gradient"]
    return options


def reference_table(data: dict[str, Any], rate: float, horizon: Horizon) -> GuidanceProfile | None:
    """The [reference] table (optional) as a guidance profile; every error names [reference] and the key.

    ``type = "inertial"``: ``sigma`` (σ_R/N, short set). ``type = "slew"``: ``start`` (σ, default the
    origin), ``target`` (σ) or ``axis`` (unit) and ``angle_deg``, ``rate_limit`` (rad/s),
    ``acceleration_limit`` (rad/s²), ``t_start`` (s, default 0). ``type = "nadir"``: one of
    ``orbit_rate`` (rad/s), ``altitude`` (m above the Earth's equatorial radius) or ``radius`` (m), with
    ``mu`` (m³/s², default the Earth's) for the last two, and ``inclination_deg``, ``raan_deg``,
    ``latitude_deg`` (the argument of latitude at t = 0), each default 0. ``type = "file"``: ``file``, a
    .csv or .npy file of n rows of 9 numbers (σ_R/N, ω_R/N, ω̇_R/N, N components), n = floor(t_final ·
    rate) + 1, relative to the scenario file. Every type also takes the keys of
    [`tracking_keys`][mrpctl._scenario_tables.tracking_keys].
    """
    if REFERENCE_TABLE not in data:
        return None
    table = data[REFERENCE_TABLE]
    if not isinstance(table, dict):
        raise SpecificationError(f"[reference] must be a table of the scenario, got {table!r}")
    kind = table.get("type")
    if not isinstance(kind, str) or kind not in _REFERENCE_KEYS:
        raise SpecificationError(f"[reference] needs type, one of {sorted(_REFERENCE_KEYS)}, got {kind!r}")
    check_keys(REFERENCE_TABLE, table, _REFERENCE_KEYS[kind] | {"type"} | TRACKING_KEYS)
    try:
        return _REFERENCE_BUILDERS[kind](table, rate, horizon)
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[reference] {exc}") from exc


def _needs(table: dict[str, Any], kind: str, *keys: str) -> None:
    missing = [key for key in keys if key not in table]
    if missing:
        raise SpecificationError(f"type = {kind!r} needs {' and '.join(missing)}")


def _inertial_reference(table: dict[str, Any], rate: float, horizon: Horizon) -> InertialPointing:
    _needs(table, "inertial", "sigma")
    return InertialPointing(table["sigma"])


def _slew_reference(table: dict[str, Any], rate: float, horizon: Horizon) -> EigenaxisSlew:
    _needs(table, "slew", "rate_limit", "acceleration_limit")
    if ("target" in table) == ("axis" in table or "angle_deg" in table):
        raise SpecificationError("type = 'slew' needs target (an MRP), or axis and angle_deg, one of them")
    options: dict[str, Any] = {
        "start": table.get("start", (0.0, 0.0, 0.0)),
        "rate_limit": table["rate_limit"],
        "acceleration_limit": table["acceleration_limit"],
        "t_start": table.get("t_start", 0.0),
    }
    if "target" in table:
        options["target"] = table["target"]
    else:
        _needs(table, "slew", "axis", "angle_deg")
        options["axis"] = table["axis"]
        options["angle"] = math.radians(finite_scalar("angle_deg", table["angle_deg"]))
    return EigenaxisSlew(**options)


def _nadir_reference(table: dict[str, Any], rate: float, horizon: Horizon) -> NadirPointing:
    given = [key for key in ("orbit_rate", "altitude", "radius") if key in table]
    if len(given) != 1:
        raise SpecificationError(
            "type = 'nadir' needs one of orbit_rate (rad/s), altitude (m) or radius (m), got "
            + (", ".join(given) if given else "none")
        )
    if "mu" in table and given[0] == "orbit_rate":
        raise SpecificationError("mu applies with altitude or radius, not with orbit_rate")
    angles = {
        name: math.radians(finite_scalar(f"{name}_deg", table.get(f"{name}_deg", 0.0)))
        for name in ("inclination", "raan", "latitude")
    }
    mu = {"mu": table["mu"]} if "mu" in table else {}
    if given[0] == "orbit_rate":
        orbit = CircularOrbit(table["orbit_rate"], **angles)
    elif given[0] == "altitude":
        orbit = CircularOrbit.from_altitude(table["altitude"], **mu, **angles)
    else:
        orbit = CircularOrbit.from_radius(table["radius"], **mu, **angles)
    return NadirPointing(orbit)


def _file_reference(table: dict[str, Any], rate: float, horizon: Horizon) -> FileReference:
    _needs(table, "file", "file")
    rows = samples_file(table["file"], "file", base=horizon.base)
    if rows.ndim != 2 or rows.shape != (horizon.samples, 9):
        raise DimensionError(
            f"file: expected n rows of 9 numbers (sigma_RN, omega_RN_N in rad/s, domega_RN_N in rad/s^2, N "
            f"components), one per measurement sample: shape (n, 9) = ({horizon.samples}, 9) with n = "
            f"floor(t_final * rate) + 1, but the file has shape {rows.shape}"
        )
    path = Path(str(table["file"]))
    source = str(path if path.is_absolute() or horizon.base is None else horizon.base / path)
    return FileReference(rows=rows, rate=rate, source=source)


_REFERENCE_BUILDERS: dict[str, Callable[[dict[str, Any], float, Horizon], GuidanceProfile]] = {
    "inertial": _inertial_reference,
    "slew": _slew_reference,
    "nadir": _nadir_reference,
    "file": _file_reference,
}


def reference_toml(reference: GuidanceProfile | None) -> list[str]:
    """The [reference] table of a scenario's guidance profile (none when the scenario regulates)."""
    if reference is None:
        return []
    lines = ["", "[reference]"]
    if isinstance(reference, InertialPointing):
        lines += ['type = "inertial"', f"sigma = {toml_value(reference.sigma)}  # sigma_RN"]
    elif isinstance(reference, EigenaxisSlew):
        lines += ['type = "slew"', f"start = {toml_value(reference.start)}  # sigma_RN at t_start"]
        if reference.target is not None:
            lines.append(f"target = {toml_value(reference.target)}  # the short way")
        else:
            lines += [
                f"axis = {toml_value(reference.axis)}  # unit eigenaxis, start-frame components",
                f"angle_deg = {toml_value(math.degrees(float(reference.angle or 0.0)))}",
            ]
        lines += [
            f"rate_limit = {toml_value(reference.rate_limit)}  # rad/s",
            f"acceleration_limit = {toml_value(reference.acceleration_limit)}  # rad/s^2",
            f"t_start = {toml_value(reference.t_start)}  # s",
        ]
    elif isinstance(reference, NadirPointing):
        orbit = reference.orbit
        lines += [
            'type = "nadir"  # the Hill frame: x radial out, y along-track, z orbit normal',
            f"orbit_rate = {toml_value(orbit.orbit_rate)}  # rad/s",
            f"inclination_deg = {toml_value(math.degrees(orbit.inclination))}",
            f"raan_deg = {toml_value(math.degrees(orbit.raan))}",
            f"latitude_deg = {toml_value(math.degrees(orbit.latitude))}  # argument of latitude at t = 0",
        ]
    elif isinstance(reference, FileReference) and reference.source:
        lines += ['type = "file"', f"file = {toml_value(reference.source)}  # n rows of 9, one per sample"]
    else:
        raise SpecificationError(
            f"reference: a {type(reference).__name__} is not written into a scenario file; save its rows "
            "(mrpctl.guidance.reference_samples) as a .npy or .csv file and name it in [reference] file"
        )
    return lines


def flight_toml(
    actuator: ActuatorModel | None,
    sensor: SensorModel | None,
    disturbance: Disturbance | None,
    delay: DelayModel | None,
) -> list[str]:
    """The [actuator], [sensor], [disturbance] and [delay] tables of a scenario (those that are set)."""
    lines: list[str] = []
    if actuator is not None:
        lines += ["", "[actuator]", f"u_max = {toml_value(actuator.u_max)}  # N m per axis"]
        if actuator.norm_max is not None:
            lines.append(f"u_norm = {toml_value(actuator.norm_max)}  # N m")
        lines.append(f"saturation = {toml_value(actuator.mode.value)}")
    if sensor is not None:
        lines += [
            "",
            "[sensor]",
            f"attitude_noise = {toml_value(sensor.attitude_noise)}  # rad, 1 sigma per axis",
            f"rate_noise = {toml_value(sensor.rate_noise)}  # rad/s, 1 sigma per axis",
            f"gyro_bias = {toml_value(sensor.gyro_bias)}  # rad/s",
            f"seed = {sensor.seed}",
        ]
    if disturbance is not None:
        if not disturbance.constant:
            raise SpecificationError(
                "disturbance: a per-sample torque is not written into a scenario file; save its rows as a .npy or "
                ".csv file and name it in [disturbance] torque_file"
            )
        lines += ["", "[disturbance]", f"torque = {toml_value(disturbance.torque)}  # N m, body frame"]
    if delay is not None:
        if delay.kind is not DelayKind.JITTER:
            raise SpecificationError(
                f"delay: only seeded jitter is written into a scenario file, got {delay.kind.value}; save a "
                "delay sequence as a .npy or .csv file and name it in [delay] sequence_file"
            )
        lines += [
            "",
            "[delay]",
            f"tau_min = {toml_value(delay.tau_min)}  # s; jitter uniform over the whole periods in [tau_min, tau]",
            f"tau_max = {toml_value(delay.tau_max)}",
            f"seed = {delay.seed}",
        ]
    return lines
