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
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mrpctl import BatchResult, SimulationResult
from mrpctl._validation import integer, readonly
from mrpctl.errors import SpecificationError

if TYPE_CHECKING:
    import pandas as pd  # type: ignore[import-untyped]
    import xarray as xr

#: Rows formatted at once by `write_csv` (bounds its memory to a few tens of MB).
_CSV_BLOCK = 65536

__all__ = ["FORMAT", "load", "metadata", "save", "to_pandas", "to_xarray", "write_csv"]

#: Format tag written into saved files; load refuses files without it.
FORMAT = "mrpctl-run-1"

_AXES = [1, 2, 3]
_STATE = ["sigma1", "sigma2", "sigma3", "omega1/4", "omega2/4", "omega3/4"]


def _rule_fields(rule: Any) -> dict[str, Any]:
    from mrpctl.scenario import RULE_NAMES

    names: dict[type, str] = {cls: name for name, cls in RULE_NAMES.items()}
    if type(rule) not in names:
        raise SpecificationError(f"rule: {type(rule).__name__} has no scenario name; it cannot be saved")
    return {"rule_type": names[type(rule)], "rule_parameter": float(rule.parameters()[0]), "rule": str(rule)}


def _rule(fields: dict[str, Any]) -> Any:
    from mrpctl.scenario import rule_from_name

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


def _versions() -> dict[str, str]:
    from mrpctl.campaign.store import versions

    return versions()


def _time_or_nan(value: float | None) -> float:
    return np.nan if value is None else float(value)


def _nan_or_time(value: Any) -> float | None:
    number = float(value)
    return None if np.isnan(number) else number


#: The flight loop's per-sample records of a run (None when absent): name, dimensions, attributes.
_FLIGHT_RECORDS: tuple[tuple[str, tuple[str, ...], dict[str, str]], ...] = (
    ("logic", ("time",), {"long_name": "logic variable h after the rule (+1 or -1)"}),
    ("sigma_c", ("time", "axis"), {"units": "1", "long_name": "MRP sigma_c used by the control law"}),
    ("delay_used", ("time",), {"units": "samples", "long_name": "delay used k - j*(k)"}),
    ("command", ("time", "axis"), {"units": "N m", "long_name": "commanded torque u_c before the limits"}),
)


def _run_dataset(result: SimulationResult) -> xr.Dataset:
    import xarray as xr

    n = len(result.t)
    every = result.keep_every or 1
    indices = np.asarray(result.switch_indices, dtype=np.int64)
    kept = indices[indices % every == 0] // every  # switches that fall on a kept sample
    switched = np.zeros(n, dtype=np.int8)
    switched[kept[kept < n]] = 1
    data: dict[str, Any] = {
        "sigma": (
            ("time", "axis"),
            np.asarray(result.sigma),
            {"units": "1", "long_name": "MRP sigma (after the rule)"},
        ),
        "omega": (("time", "axis"), np.asarray(result.omega), {"units": "rad/s", "long_name": "body rate omega"}),
        "u": (("time", "axis"), np.asarray(result.u), {"units": "N m", "long_name": "torque held over [t_k, t_k+1)"}),
        "switched": (("time",), switched, {"long_name": "1 where sigma was replaced by its shadow (kept samples)"}),
        "switch_index": (("switch",), indices, {"long_name": "sample index k of every recorded switch"}),
        "switch_count": ((), int(result.switch_count), {"long_name": "number of switches (exact)"}),
        "first_switch_time": ((), _time_or_nan(result.first_switch_time), {"units": "s"}),
        "last_switch_time": ((), _time_or_nan(result.last_switch_time), {"units": "s"}),
        "peak_torque": ((), float(result.peak_torque), {"units": "N m", "long_name": "max_k |u_k|_inf"}),
        "samples": ((), int(result.samples), {"long_name": "samples simulated"}),
        "sign_flips": (("axis",), np.asarray(result.sign_flips), {"long_name": "torque sign changes per axis"}),
        "max_sigma": ((), float(result.max_sigma), {"units": "1"}),
        "settling_time": ((), np.nan if result.settling_time is None else float(result.settling_time), {"units": "s"}),
        "diverged": ((), bool(result.diverged)),
        "inertia": (("row", "col"), np.asarray(result.spacecraft.inertia), {"units": "kg m^2"}),
        "K": (("input", "state"), np.asarray(result.K), {"units": "N m", "long_name": "u = K x(t - tau)"}),
        "x0": (("state",), np.asarray(result.x0), {"long_name": "initial state [sigma; omega/4]"}),
        "tau": ((), float(result.tau), {"units": "s"}),
        "rate": ((), float(result.rate), {"units": "Hz"}),
        "delay_samples": ((), int(result.delay_samples)),
        "substeps": ((), int(result.substeps)),
        "t_final": ((), float(result.t_final), {"units": "s"}),
    }
    if result.predictor is not None:
        data["predictor_inertia"] = (
            ("row", "col"),
            np.asarray(result.predictor.model.inertia),
            {"units": "kg m^2", "long_name": "the predictor's model inertia J_m"},
        )
    if result.saturated_fraction is not None:
        data["saturated_fraction"] = ((), float(result.saturated_fraction), {"long_name": "samples at a torque limit"})
    if result.peak_command is not None:
        data["peak_command"] = (
            ("command",),
            np.asarray(result.peak_command),
            {"units": "N m", "long_name": "max commanded |u_c,i| per axis and |u_c|"},
        )
    for name, dims, attributes in _FLIGHT_RECORDS:
        value = getattr(result, name)
        if value is not None:
            data[name] = (dims, np.asarray(value), attributes)
    attrs: dict[str, Any] = {
        **_rule_fields(result.rule),
        "history": "array",
        "keep_every": "none" if result.keep_every is None else int(result.keep_every),
    }
    if isinstance(result.history, str):
        attrs["history"] = result.history
    else:
        data["history"] = (("history_sample", "state"), np.asarray(result.history))
    coords = {"time": ("time", np.asarray(result.t), {"units": "s"}), "axis": _AXES, "state": _STATE}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _batch_dataset(result: BatchResult) -> xr.Dataset:
    import xarray as xr

    n = len(result)
    x0 = np.asarray(result.x0)
    data: dict[str, Any] = {
        "sigma0": (("run", "axis"), x0[:, :3], {"units": "1"}),
        "omega0": (("run", "axis"), 4.0 * x0[:, 3:], {"units": "rad/s"}),
        "K": (("run", "input", "state"), np.asarray(result.K), {"units": "N m"}),
        "tau": (("run",), np.asarray(result.tau), {"units": "s"}),
        "rule": (("run",), np.array([str(rule) for rule in result.rules], dtype=object)),
        "switch_count": (("run",), np.asarray(result.switch_count)),
        "first_switch_time": (("run",), np.asarray(result.first_switch_time), {"units": "s"}),
        "last_switch_time": (("run",), np.asarray(result.last_switch_time), {"units": "s"}),
        "sign_flips": (("run", "axis"), np.asarray(result.sign_flips)),
        "settling_time": (("run",), np.asarray(result.settling_time), {"units": "s"}),
        "converged": (("run",), np.asarray(result.converged)),
        "diverged": (("run",), np.asarray(result.diverged)),
        "max_sigma": (("run",), np.asarray(result.max_sigma), {"units": "1"}),
    }
    peak = getattr(result, "peak_torque", None)
    if peak is not None:
        data["peak_torque"] = (("run",), np.asarray(peak), {"units": "N m"})
    attrs: dict[str, Any] = {
        "rate": float(result.rate),
        "t_final": float(result.t_final),
        "substeps": int(result.substeps),
    }
    attrs["history"] = result.history if isinstance(result.history, str) else "array"
    coords = {"run": np.arange(n), "axis": _AXES, "state": _STATE}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def to_xarray(result: SimulationResult | BatchResult) -> xr.Dataset:
    """The result as an `xarray.Dataset`.

    A run: ``sigma``, ``omega``, ``u`` over (``time`` in s, ``axis`` 1-3), ``switched`` over
    time, the metrics and the inputs (inertia, K, x0, τ, rate, ...) as variables, the rule
    in ``attrs``. A batch: the initial state ``sigma0``, ``omega0`` (rad/s), ``K``, ``tau``,
    the rule and every metric over ``run``.
    """
    if isinstance(result, SimulationResult):
        return _run_dataset(result)
    if isinstance(result, BatchResult):
        return _batch_dataset(result)
    raise SpecificationError(f"result must be a SimulationResult or BatchResult, got {type(result).__name__}")


def to_pandas(result: SimulationResult | BatchResult) -> pd.DataFrame:
    """The result as a `pandas.DataFrame`.

    A run: indexed by ``t`` (s), columns sigma1-3, omega1-3 (rad/s), u1-3 (N m), switched (and,
    for a flight run with records, logic, sigma_c1-3, u_c1-3 (N m, the commanded torque) and
    delay_used (samples)); the inputs in ``DataFrame.attrs``. A batch: indexed by ``run``, columns for the initial
    state, τ, the rule and every metric.
    """
    import pandas as pd

    if isinstance(result, SimulationResult):
        run = result
        switched = np.zeros(len(run.t), dtype=np.int8)
        switched[run.switch_indices] = 1
        columns: dict[str, Any] = {}
        for name, values in (("sigma", run.sigma), ("omega", run.omega), ("u", run.u)):
            for i in range(3):
                columns[f"{name}{i + 1}"] = np.asarray(values[:, i])
        columns["switched"] = switched
        if run.logic is not None and run.sigma_c is not None and run.command is not None:  # the flight records
            columns["logic"] = np.asarray(run.logic)
            for name, values in (("sigma_c", run.sigma_c), ("u_c", run.command)):
                for i in range(3):
                    columns[f"{name}{i + 1}"] = np.asarray(values[:, i])
        if run.delay_used is not None:
            columns["delay_used"] = np.asarray(run.delay_used)
        frame = pd.DataFrame(columns, index=pd.Index(np.asarray(run.t), name="t"))
        frame.attrs.update(
            inertia=run.spacecraft.inertia.tolist(),
            K=np.asarray(run.K).tolist(),
            x0=np.asarray(run.x0).tolist(),
            tau=run.tau,
            rate=run.rate,
            t_final=run.t_final,
            rule=str(run.rule),
            diverged=run.diverged,
            settling_time=run.settling_time,
        )
        return frame
    if isinstance(result, BatchResult):
        batch = result
        x0 = np.asarray(batch.x0)
        columns = {}
        for i in range(3):
            columns[f"sigma0_{i + 1}"] = x0[:, i]
        for i in range(3):
            columns[f"omega0_{i + 1}"] = 4.0 * x0[:, 3 + i]
        columns["tau"] = np.asarray(batch.tau)
        columns["rule"] = [str(rule) for rule in batch.rules]
        for name in (
            "switch_count",
            "first_switch_time",
            "last_switch_time",
            "settling_time",
            "converged",
            "diverged",
            "max_sigma",
        ):
            columns[name] = np.asarray(getattr(batch, name))
        peak = getattr(batch, "peak_torque", None)
        if peak is not None:
            columns["peak_torque"] = np.asarray(peak)
        for i in range(3):
            columns[f"sign_flips_{i + 1}"] = np.asarray(batch.sign_flips)[:, i]
        frame = pd.DataFrame(columns, index=pd.Index(np.arange(len(batch)), name="run"))
        frame.attrs.update(rate=batch.rate, t_final=batch.t_final, substeps=batch.substeps)
        return frame
    raise SpecificationError(f"result must be a SimulationResult or BatchResult, got {type(result).__name__}")


def _atomic_target(path: Path) -> tuple[int, Path]:
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    return handle, Path(name)


def save(result: SimulationResult, path: str | Path, *, seed: int | None = None) -> Path:
    """Save one run with its inputs, the package versions and (optionally) the seed it came from.

    The file is NetCDF-3 (64-bit offset) written by xarray's scipy engine into a temporary
    file beside ``path`` and renamed over it, so an interrupted save leaves any old file intact.

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
    dataset = _run_dataset(result)
    dataset.attrs.update(format=FORMAT, versions=json.dumps(_versions(), sort_keys=True))
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


def _open(path: str | Path) -> xr.Dataset:
    import xarray as xr

    path = Path(path)
    if not path.exists():
        raise SpecificationError(f"path: no saved run at {path}")
    with xr.open_dataset(path, engine="scipy") as stored:
        dataset = stored.load()
    if dataset.attrs.get("format") != FORMAT:
        raise SpecificationError(f"path: {path} is not a run saved by mrpctl.data.save (format {FORMAT})")
    return dataset


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
    """Load a run written by [`save`][mrpctl.data.save] (arrays read-only, as returned by the simulator)."""
    from mrpctl.spacecraft import Spacecraft

    dataset = _open(path)
    rate = float(dataset["rate"])
    indices = np.asarray(dataset["switch_index"].values, dtype=np.int64)
    times = indices / rate
    keep_every = dataset.attrs.get("keep_every", 1)
    settling = float(dataset["settling_time"])
    history: Any = dataset.attrs["history"]
    if history == "array":
        history = readonly(dataset["history"].values)
    predictor = None
    if "predictor_inertia" in dataset:
        from mrpctl.predictor import Predictor

        predictor = Predictor(model=Spacecraft(dataset["predictor_inertia"].values))
    flown: dict[str, Any] = {}
    if "saturated_fraction" in dataset:
        flown["saturated_fraction"] = float(dataset["saturated_fraction"])
    if "peak_command" in dataset:
        flown["peak_command"] = readonly(dataset["peak_command"].values)
    for name, _, _ in _FLIGHT_RECORDS:
        if name in dataset:
            values = dataset[name].values
            flown[name] = readonly(values, np.int64 if name == "delay_used" else float)
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
        keep_every=None if keep_every == "none" else int(keep_every),
        predictor=predictor,
        **flown,
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
