"""Results as labelled data: xarray and pandas conversions, save/load of a run, a decimating CSV writer.

* [`to_xarray`][mrpctl.data.to_xarray] / [`to_pandas`][mrpctl.data.to_pandas]: a
[`SimulationResult`][mrpctl.SimulationResult]
  over ``time`` (and ``axis``), a [`BatchResult`][mrpctl.BatchResult] over ``run`` with
  each run's initial state and inputs.
* [`save`][mrpctl.data.save] / [`load`][mrpctl.data.load]: one run with its inputs (a predictor run's model inertia and
  the flight loop's saturation metrics included), the package versions and a seed, as a
  NetCDF-3 file (xarray's scipy engine, no netCDF4 library needed), written
  atomically (temporary file, then rename).
* [`write_csv`][mrpctl.data.write_csv]: every n-th sample of a run, with the switches in between counted.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mrpctl._files import memory_limit, regular_file, size_text
from mrpctl._validation import finite_array, integer, nonnegative_scalar, positive_scalar, readonly, sealed
from mrpctl.errors import DimensionError, MrpctlError, SpecificationError
from mrpctl.loop import check_substeps, delay_samples
from mrpctl.predictor import Predictor, PredictorForm
from mrpctl.provenance import versions
from mrpctl.rules import RULE_NAMES, rule_from_name
from mrpctl.scenario import sample_count
from mrpctl.simulation.results import (
    AXES,
    FLIGHT_RECORDS,
    STATE,
    WHEEL_VARIABLES,
    SimulationResult,
    WheelRecord,
    to_pandas,
    to_xarray,
)
from mrpctl.spacecraft import Spacecraft
from mrpctl.wheels import WheelCluster

if TYPE_CHECKING:
    # deferred: xarray (about 0.5 s to import), only for labelled data
    import xarray as xr

#: Rows formatted at once by `write_csv` (bounds its memory to a few tens of MB).
_CSV_BLOCK = 65536

__all__ = ["FORMAT", "load", "metadata", "save", "to_pandas", "to_xarray", "write_csv"]

#: Format tag written into saved files; load refuses files without it.
FORMAT = "mrpctl-run-1"


def _rule(fields: dict[str, Any]) -> Any:
    name = str(fields["rule_type"])
    value = float(fields["rule_parameter"])
    if name == "boundary-layer":
        return rule_from_name(name, eps=value)
    if name == "delay-aware":
        return rule_from_name(name, alpha=value)
    if name == "hysteretic":
        return rule_from_name(name, delta=value)
    if name == "on-predicted":
        return rule_from_name(name, alpha=value)  # alpha = inf: never switch (OnPredicted(None))
    return rule_from_name(name)


def _nan_or_time(value: Any) -> float | None:
    number = float(value)
    return None if np.isnan(number) else number


def _atomic_target(path: Path) -> tuple[int, Path]:
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    return handle, Path(name)


def save(result: SimulationResult, path: str | Path, *, seed: int | None = None) -> Path:
    """Save one run with its inputs, the package versions and (optionally) the seed it came from.

    The file is NetCDF-3 (64-bit offset) written by xarray's scipy engine into a temporary
    file beside ``path`` and renamed over it, so an interrupted save leaves any old file intact. A run on
    wheels also holds its wheel speeds and motor torques over (``time``, ``wheel``), its wheel metrics and its
    cluster (`mrpctl.simulation.results.WHEEL_VARIABLES`); [`load`][mrpctl.data.load] rebuilds them.

    Parameters
    ----------
    result : SimulationResult
        The run.
    path : path
        Target file (conventionally ``.nc``).
    seed : int, optional
        The seed that produced the run's inputs (a campaign's, for instance).

    Returns
    -------
    pathlib.Path
    """
    if not isinstance(result, SimulationResult):
        raise SpecificationError(f"result must be a SimulationResult, got {type(result).__name__}")
    dataset = to_xarray(result)
    dataset.attrs.update(format=FORMAT, versions=json.dumps(versions(), sort_keys=True))
    if seed is not None:
        dataset.attrs["seed"] = str(integer("seed", seed, minimum=0))
    path = Path(path)
    handle, temporary = _atomic_target(path)
    os.close(handle)
    try:
        dataset.to_netcdf(temporary, engine="scipy", format="NETCDF3_64BIT")
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()
    return path


#: Variables of a saved run: dimensions and dtype kinds ("f" float, "i" integer, "b" flag: bool or 0/1).
_SCHEMA: dict[str, tuple[tuple[str, ...], str]] = {
    "sigma": (("time", "axis"), "f"),
    "omega": (("time", "axis"), "f"),
    "u": (("time", "axis"), "f"),
    "switched": (("time",), "b"),
    "switch_index": (("switch",), "i"),
    "switch_count": ((), "i"),
    "first_switch_time": ((), "f"),
    "last_switch_time": ((), "f"),
    "peak_torque": ((), "f"),
    "samples": ((), "i"),
    "sign_flips": (("axis",), "i"),
    "max_sigma": ((), "f"),
    "settling_time": ((), "f"),
    "diverged": ((), "b"),
    "inertia": (("row", "col"), "f"),
    "K": (("input", "state"), "f"),
    "x0": (("state",), "f"),
    "tau": ((), "f"),
    "rate": ((), "f"),
    "delay_samples": ((), "i"),
    "substeps": ((), "i"),
    "t_final": ((), "f"),
    "time": (("time",), "f"),
    "axis": (("axis",), "i"),
    "state": (("state",), "s"),
}
#: Variables a run may have (the predictor's model, the flight loop's metrics and records, a history array).
_OPTIONAL: dict[str, tuple[tuple[str, ...], str]] = {
    "predictor_inertia": (("row", "col"), "f"),
    "settling_attitude": ((), "f"),
    "settling_rate": ((), "f"),
    "saturated_fraction": ((), "f"),
    "peak_command": (("command",), "f"),
    "logic": (("time",), "f"),
    "sigma_c": (("time", "axis"), "f"),
    "delay_used": (("time",), "i"),
    "command": (("time", "axis"), "f"),
    "sigma_measured": (("time", "axis"), "f"),
    "omega_measured": (("time", "axis"), "f"),
    "sigma_predicted": (("time", "axis"), "f"),
    "omega_predicted": (("time", "axis"), "f"),
    "history": (("history_sample", "state"), "f"),
    # a run on wheels: all of WHEEL_VARIABLES or none
    **{
        name: (dims, "i" if name == "worst_wheel" else "b" if name == "wheel_gyroscopic" else "f")
        for name, (dims, _, _) in WHEEL_VARIABLES.items()
    },
}
_KIND_NAMES = {"f": "floats", "i": "integers", "b": "flags", "s": "names"}
_SIZES = {"axis": 3, "state": 6, "row": 3, "col": 3, "input": 3, "command": 4}
_ATTRS = {"rule_type", "rule_parameter", "rule", "history", "keep_every", "format", "versions", "seed"}


def _damaged(path: Path, problem: str) -> SpecificationError:
    return SpecificationError(f"path: {path} is not a run as mrpctl.data.save writes it: {problem}")


def _kind(values: np.ndarray) -> str:
    kind = values.dtype.kind
    if kind in "OUS":
        return "s"
    return {"u": "i", "b": "b"}.get(kind, kind)


def _check_variables(dataset: xr.Dataset, path: Path) -> None:
    """Variables, dtypes and shapes against [_SCHEMA][mrpctl.data._SCHEMA], consistent with each other."""
    names = {str(name) for name in dataset.variables}
    missing = sorted(set(_SCHEMA) - names)
    if missing:
        raise _damaged(path, f"the variable {missing[0]!r} is missing")
    unknown = sorted(names - set(_SCHEMA) - set(_OPTIONAL))
    if unknown:
        raise _damaged(path, f"the variable {unknown[0]!r} is not part of the format")
    foreign = sorted({str(name) for name in dataset.attrs} - _ATTRS)
    if foreign:
        raise _damaged(path, f"the attribute {foreign[0]!r} is not part of the format")
    for name in sorted(names):
        dims, kind = _SCHEMA.get(name) or _OPTIONAL[name]
        variable = dataset.variables[name]
        if tuple(variable.dims) != dims:
            raise _damaged(path, f"{name} has the dimensions {tuple(variable.dims)}, expected {dims}")
        found = _kind(variable.values)
        if found != kind and not (kind == "b" and found == "i") and not (kind == "f" and found == "i"):
            raise _damaged(
                path,
                f"{name} holds {variable.dtype} values, expected {_KIND_NAMES[kind]}",
            )
        if kind == "b" and found == "i" and not np.isin(variable.values, (0, 1)).all():
            raise _damaged(path, f"{name} must hold 0 or 1")
    for dim, size in _SIZES.items():
        if dim in dataset.sizes and dataset.sizes[dim] != size:
            raise _damaged(path, f"the dimension {dim!r} has {dataset.sizes[dim]} entries, expected {size}")
    if dataset["axis"].values.tolist() != AXES or [str(v) for v in dataset["state"].values.tolist()] != STATE:
        raise _damaged(path, "the axis or state labels differ from the format's")


def _number(dataset: xr.Dataset, name: str) -> float:
    return float(dataset[name].values)


def _check_values(dataset: xr.Dataset, path: Path) -> dict[str, Any]:
    """The inputs checked as simulate checks them, the metrics against their ranges; the checked attributes."""
    rate = positive_scalar("rate", _number(dataset, "rate"))
    tau = nonnegative_scalar("tau", _number(dataset, "tau"))
    d = delay_samples(tau, rate)
    if int(dataset["delay_samples"]) != d:
        raise SpecificationError(f"delay_samples = {int(dataset['delay_samples'])} but tau * rate = {d}")
    check_substeps(int(dataset["substeps"]))
    t_final = positive_scalar("t_final", _number(dataset, "t_final"))
    n = sample_count(t_final, rate)
    samples = int(dataset["samples"])
    diverged = bool(dataset["diverged"])
    if not 1 <= samples <= n or (samples < n and not diverged):
        raise SpecificationError(f"samples = {samples}, but t_final * rate gives {n} (fewer only if diverged)")
    finite_array("K", dataset["K"].values)
    finite_array("x0", dataset["x0"].values)
    finite_array("inertia", dataset["inertia"].values)
    attrs = dataset.attrs
    keep = attrs.get("keep_every")
    if isinstance(keep, str):
        if keep != "none":
            raise SpecificationError(f"the attribute keep_every must be 'none' or an integer >= 1, got {keep!r}")
        every = None
    else:
        every = integer("the attribute keep_every", np.asarray(keep).item() if keep is not None else None, minimum=1)
    kept = 0 if every is None else (samples - 1) // every + 1
    times = np.asarray(dataset["time"].values, dtype=float)
    if times.shape != (kept,):
        raise SpecificationError(f"{times.size} kept samples, but {samples} samples kept every {every} give {kept}")
    expected = np.arange(0, samples, every or 1)[:kept] / rate
    if not np.all(np.abs(times - expected) <= 1e-9 * np.maximum(1.0, np.abs(expected))):
        raise SpecificationError("time is not t_k = k / rate at the kept samples")
    indices = np.asarray(dataset["switch_index"].values)
    count = int(dataset["switch_count"])
    if indices.size and (indices.min() < 0 or indices.max() >= samples or np.any(np.diff(indices) <= 0)):
        raise SpecificationError("switch_index must be increasing sample indices below samples")
    if count < indices.size or (every == 1 and count != indices.size):
        raise SpecificationError(f"switch_count = {count} but {indices.size} switches are recorded")
    for name in ("first_switch_time", "last_switch_time", "settling_time"):
        value = _number(dataset, name)
        if not (math.isnan(value) or 0.0 <= value <= t_final * (1 + 1e-9)):
            raise SpecificationError(f"{name} = {value!r} s lies outside [0, t_final]")
    if np.isnan(_number(dataset, "first_switch_time")) != (count == 0):
        raise SpecificationError("first_switch_time must be NaN exactly when there is no switch")
    for name in ("max_sigma", "peak_torque", "sign_flips", "saturated_fraction", "peak_command", "delay_used"):
        if name in dataset and np.any(np.asarray(dataset[name].values) < 0):
            raise SpecificationError(f"{name} must be >= 0")
    if "saturated_fraction" in dataset and not _number(dataset, "saturated_fraction") <= 1.0:
        raise SpecificationError("saturated_fraction must lie in [0, 1]")
    history = attrs.get("history")
    if history not in ("array", "constant", "zero-input"):
        raise SpecificationError(f"the attribute history must be 'array', 'constant' or 'zero-input', got {history!r}")
    if (history == "array") != ("history" in dataset):
        raise SpecificationError("the history variable must be present exactly when the attribute history is 'array'")
    if history == "array" and dataset["history"].shape != (d, 6):
        raise SpecificationError(f"history has shape {dataset['history'].shape}, expected (d, 6) = ({d}, 6)")
    if attrs.get("rule_type") not in RULE_NAMES:
        raise SpecificationError(f"the attribute rule_type must be one of {sorted(RULE_NAMES)}")
    parameter = np.asarray(attrs.get("rule_parameter"))
    if parameter.shape != () or parameter.dtype.kind not in "fi" or np.isnan(parameter):
        raise SpecificationError("the attribute rule_parameter must be a number")
    wheels = [name in dataset for name in WHEEL_VARIABLES]
    if any(wheels) and not all(wheels):
        missing = next(name for name in WHEEL_VARIABLES if name not in dataset)
        raise SpecificationError(f"a run on wheels has all the wheel variables, but {missing} is missing")
    if ("predictor_inertia" in dataset) != (attrs["rule_type"] == "on-predicted"):
        raise SpecificationError("predictor_inertia must be present exactly with the rule 'on-predicted'")
    versions = attrs.get("versions")
    try:
        parsed = json.loads(versions) if isinstance(versions, str) else None
    except ValueError:
        parsed = None
    if not isinstance(parsed, dict):
        raise SpecificationError("the attribute versions must be a JSON object of package versions")
    if "seed" in attrs:
        seed = attrs["seed"]
        if not (isinstance(seed, str) and seed.isdigit()):
            raise SpecificationError(f"the attribute seed must be an integer >= 0, got {seed!r}")
    return {"keep_every": every, "history": history}


def _open(path: str | Path) -> xr.Dataset:
    """The saved run at ``path``, read after its header was checked (a NetCDF-3 file whose data fit in memory)."""
    # deferred: xarray (about 0.5 s to import), only for labelled data
    import xarray as xr

    path = Path(path)
    if not path.exists() and not path.is_symlink():
        raise SpecificationError(f"path: no saved run at {path}")
    status = regular_file(path, "path")
    try:
        with path.open("rb") as handle:
            magic = handle.read(4)
    except OSError as exc:
        raise SpecificationError(f"path: cannot read {path}: {exc.strerror or type(exc).__name__}") from exc
    if magic not in (b"CDF\x01", b"CDF\x02"):
        raise SpecificationError(
            f"path: {path} is not a run saved by mrpctl.data.save (format {FORMAT}): not a NetCDF-3 file"
        )
    try:
        with xr.open_dataset(path, engine="scipy") as stored:
            need = sum(variable.nbytes for variable in stored.variables.values())
            limit = memory_limit()
            if need > limit:
                raise SpecificationError(
                    f"path: {path} declares {size_text(need)} of data, more than the {size_text(limit)} allowed "
                    "(half of the memory available)"
                )
            if need > 8 * status.st_size + 2**20:
                declared = f"{size_text(need)} of data, the file has {size_text(status.st_size)}"
                raise _damaged(path, f"its header declares {declared}")
            dataset = stored.load()
    except SpecificationError:
        raise
    except Exception as exc:
        raise _damaged(path, f"it cannot be read ({type(exc).__name__}; truncated or damaged)") from exc
    if dataset.attrs.get("format") != FORMAT:
        raise SpecificationError(f"path: {path} is not a run saved by mrpctl.data.save (format {FORMAT})")
    return dataset


def _checked(path: str | Path) -> tuple[xr.Dataset, dict[str, Any]]:
    """The saved run at ``path`` validated against the format [`save`][mrpctl.data.save] writes, and its
    checked attributes."""
    dataset = _open(path)
    _check_variables(dataset, Path(path))
    try:
        attributes = _check_values(dataset, Path(path))
    except (SpecificationError, DimensionError, TypeError, ValueError) as exc:
        raise _damaged(Path(path), str(exc)) from exc
    return dataset, attributes


def metadata(path: str | Path) -> dict[str, Any]:
    """The versions, the seed (None when not saved) and the rule of a saved run."""
    attrs = _open(path).attrs
    return {
        "format": attrs["format"],
        "versions": json.loads(attrs["versions"]),
        "seed": int(attrs["seed"]) if "seed" in attrs else None,
        "rule": attrs["rule"],
    }


def load(path: str | Path) -> SimulationResult:
    """Load a run written by [`save`][mrpctl.data.save] (arrays read-only, as returned by the simulator).

    The file is validated against the format [save][mrpctl.data.save] writes before the run is built:
    the variables and their dtypes and shapes (consistent with each other), the inputs as
    [simulate][mrpctl.simulate] checks them (rate > 0, tau >= 0 and tau * rate whole, substeps, the
    rule, the inertia), the metrics' ranges and the attributes. A missing, truncated, damaged or foreign
    file is refused with one [SpecificationError][mrpctl.errors.SpecificationError] naming the file and
    what is wrong (the reader's error chained as its cause).
    """

    dataset, checked = _checked(path)
    try:
        return _result(dataset, checked)
    except (MrpctlError, TypeError, ValueError, KeyError, IndexError) as exc:  # a rule or inertia the checks let by
        raise _damaged(Path(path), str(exc)) from exc


def _result(dataset: xr.Dataset, checked: dict[str, Any]) -> SimulationResult:
    """The run of a checked dataset."""

    rate = float(dataset["rate"])
    indices = np.asarray(dataset["switch_index"].values, dtype=np.int64)
    times = indices / rate
    keep_every = checked["keep_every"]
    settling = float(dataset["settling_time"])
    history: Any = dataset.attrs["history"]
    if history == "array":
        history = readonly(dataset["history"].values)
    predictor = None
    if "predictor_inertia" in dataset:
        form = dataset["predictor_inertia"].attrs.get("predictor_form", PredictorForm.NONLINEAR.value)
        predictor = Predictor(model=Spacecraft(dataset["predictor_inertia"].values), form=PredictorForm.parse(form))
    flown: dict[str, Any] = {}
    if "saturated_fraction" in dataset:
        flown["saturated_fraction"] = float(dataset["saturated_fraction"])
    if "peak_command" in dataset:
        flown["peak_command"] = readonly(dataset["peak_command"].values)
    for name, _, _ in FLIGHT_RECORDS:
        if name in dataset:
            values = dataset[name].values
            flown[name] = readonly(values, np.int64 if name == "delay_used" else float)
    for name in ("settling_attitude", "settling_rate"):  # written when not the defaults
        if name in dataset:
            flown[name] = float(dataset[name])
    if "wheel_spin_axes" in dataset:
        flown["wheels"] = _wheel_record(dataset)
    return SimulationResult(
        t=readonly(dataset["time"].values),
        sigma=readonly(dataset["sigma"].values),
        omega=readonly(dataset["omega"].values),
        u=readonly(dataset["u"].values),
        switch_indices=readonly(indices, np.int64),
        switch_times=readonly(times),
        switch_count=int(dataset["switch_count"]),
        first_switch_time=_nan_or_time(dataset["first_switch_time"]),
        last_switch_time=_nan_or_time(dataset["last_switch_time"]),
        sign_flips=readonly(dataset["sign_flips"].values, np.int64),
        max_sigma=float(dataset["max_sigma"]),
        peak_torque=float(dataset["peak_torque"]),
        samples=int(dataset["samples"]),
        settling_time=None if np.isnan(settling) else settling,
        diverged=bool(dataset["diverged"]),
        spacecraft=Spacecraft(dataset["inertia"].values),
        K=readonly(dataset["K"].values),
        tau=float(dataset["tau"]),
        rate=rate,
        delay_samples=int(dataset["delay_samples"]),
        rule=_rule(dataset.attrs),
        history=history,
        substeps=int(dataset["substeps"]),
        x0=readonly(dataset["x0"].values),
        t_final=float(dataset["t_final"]),
        keep_every=keep_every,
        predictor=predictor,
        **flown,
    )


def _wheel_record(dataset: xr.Dataset) -> WheelRecord:
    """The `WheelRecord` of a saved run on wheels, its cluster rebuilt (and checked) from the saved values."""

    def value(name: str) -> Any:
        return dataset[name].values

    cluster = WheelCluster(
        value("wheel_spin_axes"),
        value("wheel_spin_inertia"),
        value("wheel_torque_limit"),
        value("wheel_speed_limit"),
        viscous=value("wheel_viscous"),
        coulomb=value("wheel_coulomb"),
        limit_cycle_speed=value("wheel_limit_cycle_speed"),
        speeds=value("wheel_initial_speed"),
        control_axes=value("wheel_control_axes"),
        null_gain=float(value("wheel_null_gain")),
        bias_speeds=value("wheel_bias_speed"),
        gyroscopic=bool(value("wheel_gyroscopic")),
    )
    return WheelRecord(
        cluster=cluster,
        speeds=sealed(np.array(value("wheel_speed"), dtype=float)),
        motor_torque=sealed(np.array(value("wheel_motor_torque"), dtype=float)),
        final_speeds=readonly(value("wheel_final_speed")),
        peak_speed=readonly(value("wheel_peak_speed")),
        torque_limited_time=readonly(value("wheel_torque_limited_time")),
        speed_limited_time=readonly(value("wheel_speed_limited_time")),
        peak_momentum=float(value("wheel_peak_momentum")),
        worst_wheel=int(value("worst_wheel")),
    )


def write_csv(result: SimulationResult, path: str | Path, *, every: int = 1) -> Path:
    """Write every ``every``-th sample of a run as CSV (atomically).

    Columns: t (s), sigma1-3, omega1-3 (rad/s), u1-3 (N m), and ``switches``: the number
    of shadow-set switches at the samples since the previous written row (so decimation
    never hides a switch). Values are written with the shortest repr that round-trips, in
    blocks of 65 536 rows (memory bounded whatever the run length).

    Parameters
    ----------
    result : SimulationResult
        The run.
    path : path
        Target file.
    every : int, keyword-only
        Decimation factor >= 1: rows k = 0, every, 2 every, ..., and always the last sample
        (default 1, every sample).

    Returns
    -------
    pathlib.Path
    """
    if not isinstance(result, SimulationResult):
        raise SpecificationError(f"result must be a SimulationResult, got {type(result).__name__}")
    every = integer("every", every, minimum=1)
    n = len(result.t)
    rows = np.arange(0, n, every)
    if rows[-1] != n - 1:
        rows = np.append(rows, n - 1)  # the final state, and the switches after the last regular row
    switched = np.zeros(n, dtype=np.int64)
    switched[result.switch_indices] = 1
    # switches in (previous row, this row]: the first row counts sample 0 only
    cumulative = np.cumsum(switched)[rows]
    switches = np.diff(cumulative, prepend=0)
    values = np.column_stack(
        [np.asarray(result.t)[rows]] + [np.asarray(array)[rows] for array in (result.sigma, result.omega, result.u)]
    )
    header = "t,sigma1,sigma2,sigma3,omega1,omega2,omega3,u1,u2,u3,switches\n"
    path = Path(path)
    handle, temporary = _atomic_target(path)
    try:
        with os.fdopen(handle, "w", newline="", encoding="utf-8") as stream:
            stream.write(header)
            for start in range(0, len(rows), _CSV_BLOCK):
                block = slice(start, start + _CSV_BLOCK)
                # NumPy's float -> str: the shortest repr that round-trips (measured: as fast as pandas.to_csv)
                text = np.column_stack((values[block].astype(str), switches[block].astype(str)))
                stream.write("\n".join(map(",".join, text.tolist())))
                stream.write("\n")
        os.replace(temporary, path)
    finally:
        if temporary.exists():
            temporary.unlink()
    return path
