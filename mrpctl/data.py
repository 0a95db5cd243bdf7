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

from mrpctl._validation import integer, readonly
from mrpctl.errors import SpecificationError
from mrpctl.predictor import Predictor
from mrpctl.provenance import versions
from mrpctl.rules import rule_from_name
from mrpctl.simulation.results import FLIGHT_RECORDS, SimulationResult, to_pandas, to_xarray
from mrpctl.spacecraft import Spacecraft

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


def _open(path: str | Path) -> xr.Dataset:
    # deferred: xarray (about 0.5 s to import), only for labelled data
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
        predictor = Predictor(model=Spacecraft(dataset["predictor_inertia"].values))
    flown: dict[str, Any] = {}
    if "saturated_fraction" in dataset:
        flown["saturated_fraction"] = float(dataset["saturated_fraction"])
    if "peak_command" in dataset:
        flown["peak_command"] = readonly(dataset["peak_command"].values)
    for name, _, _ in FLIGHT_RECORDS:
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
