"""The Zarr store of a campaign: every run's inputs and metrics, and which chunks are complete.

Layout of ``<out>/campaign.zarr`` (a Zarr group written by xarray):

* coordinate ``run`` (count,) and, over ``run``, the inputs ``sigma0`` (run, axis),
  ``omega0`` (run, axis), ``inertia`` (run, row, col), ``tau``, ``gain_scale``,
  ``initial_angle``, ``initial_rate`` and the metrics of `METRICS`; every array is
  chunked along ``run`` by the campaign chunk, so a chunk's write touches only its own files;
* per run also ``rule`` (index into the JSON list ``attrs["rules"]``, the rules crossed with the
  cases), ``case``, and the flight loop's ``delta``, ``u_max`` (run, axis; inf: none),
  ``disturbance`` (run, axis), ``attitude_noise``, ``rate_noise``, ``gyro_bias`` (run, axis),
  ``noise_seed``, ``jitter_seed``;
* with per-sample files in ``[flight]``, their numbers, shared by the runs: ``flight_disturbance_rows``
  (sample, axis) of ``disturbance_file`` (N m) and ``flight_delays`` (sample,) of ``delay_file`` (s),
  with ``attrs["flight_files"]`` (JSON: per key the file name as read and the SHA-256 of its numbers);
  the rows of ``[reference] file`` likewise, ``reference_rows`` (sample, column: σ_R/N, ω_R/N in rad/s,
  ω̇_R/N in rad/s²; key ``reference_file``);
* a tracking campaign's (a ``[reference]``) only: the reference inputs ``slew_angle`` (deg), ``slew_axis``
  (run, axis), ``orbit_rate`` (rad/s) and the pointing metrics ``pointing_max``, ``pointing_rms`` (deg,
  after the settling time) and ``slew_time`` (s); a regulation campaign's store is as before;
* ``chunk_complete`` (chunk,), one Zarr chunk per campaign chunk, set to True only after
  all of that chunk's arrays are written. A chunk whose flag is False (never started, or
  half-written when the campaign was interrupted) is simulated again on resume.

The store is created complete (filled with the "missing" values) in a temporary folder
and renamed into place, so a store that exists always has all its arrays.

**Per-sample files are stored, not referenced.** ``attrs["campaign"]`` holds the TOML as written,
so ``flight.disturbance_file`` / ``flight.delay_file`` there are file names only. Their numbers are
stored too (n x 3 float64 at most, n = floor(t_final · rate) + 1: 1.4 MB for a minute at 1 kHz, as
much as the file itself; counted in the size check), and [`spec_of`][mrpctl.campaign.store.spec_of] rebuilds the
campaign
from them: a replay reproduces a run bit for bit even when the file was moved, edited or deleted
(storing only a SHA-256 would make every replay depend on the file and refuse to work without it).
The hash is kept as well, to refuse a **resume** whose file now holds other numbers (the message
names the file and both hashes): the runs already stored would then disagree with the new ones.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
import zarr

from mrpctl.campaign import integrity
from mrpctl.campaign.reference import REFERENCE_INPUTS
from mrpctl.campaign.simulation import METRICS, POINTING_METRICS
from mrpctl.campaign.spec import CampaignSpec, SampleFile, parse_campaign
from mrpctl.campaign.wheels import WHEEL_METRICS
from mrpctl.errors import SpecificationError
from mrpctl.flight import NOISE_REVISION
from mrpctl.provenance import versions

__all__ = ["INPUTS", "STORE_NAME", "CampaignStore", "open_campaign", "stored_names", "tracking_store"]

STORE_NAME = "campaign.zarr"

#: The dispersed inputs stored per run: (dims after run, dtype).
INPUTS: dict[str, tuple[tuple[str, ...], Any]] = {
    "sigma0": (("axis",), np.float64),
    "omega0": (("axis",), np.float64),
    "inertia": (("row", "col"), np.float64),
    "tau": ((), np.float64),
    "gain_scale": ((), np.float64),
    "initial_angle": ((), np.float64),
    "initial_rate": ((), np.float64),
    "rule": ((), np.int64),
    "case": ((), np.int64),
    "delta": ((), np.float64),
    "u_max": (("axis",), np.float64),
    "disturbance": (("axis",), np.float64),
    "attitude_noise": ((), np.float64),
    "rate_noise": ((), np.float64),
    "gyro_bias": (("axis",), np.float64),
    "noise_seed": ((), np.int64),
    "jitter_seed": ((), np.int64),
}
_SIZES = {"axis": 3, "row": 3, "col": 3}
_UNITS = {
    "sigma0": "1",
    "omega0": "rad/s",
    "inertia": "kg m^2",
    "tau": "s",
    "gain_scale": "1",
    "initial_angle": "rad",
    "initial_rate": "rad/s",
    "u_max": "N m",
    "disturbance": "N m",
    "attitude_noise": "rad",
    "rate_noise": "rad/s",
    "gyro_bias": "rad/s",
    "first_switch_time": "s",
    "last_switch_time": "s",
    "settling_time": "s",
    "max_sigma": "1",
    "peak_torque": "N m",
}
_TRACKING_UNITS = {
    **{name: unit for name, (_, unit) in REFERENCE_INPUTS.items()},
    "pointing_max": "deg",
    "pointing_rms": "deg",
    "slew_time": "s",
}


#: The store's array of each per-sample file of ``[flight]``: (name, dims).
FILE_ARRAYS = {
    "disturbance_file": ("flight_disturbance_rows", ("sample", "axis")),
    "delay_file": ("flight_delays", ("sample",)),
    "reference_file": ("reference_rows", ("sample", "column")),
}
_FILE_UNITS = {"disturbance_file": "N m", "delay_file": "s", "reference_file": "1, rad/s, rad/s^2"}
#: The campaign file's key of each per-sample file (what messages name).
FILE_KEYS = {
    "disturbance_file": "flight.disturbance_file",
    "delay_file": "flight.delay_file",
    "reference_file": "[reference] file",
}


def tracking_store(attrs: Any) -> bool:
    """True when a store (its attrs) is a tracking campaign's: its campaign has a ``[reference]``."""
    return "reference" in json.loads(str(attrs.get("campaign", "{}")))


def _inputs(tracking: bool) -> dict[str, tuple[tuple[str, ...], Any]]:
    extra = {name: (dims, np.float64) for name, (dims, _) in REFERENCE_INPUTS.items()} if tracking else {}
    return {**INPUTS, **extra}


def _metrics(tracking: bool) -> dict[str, tuple[Any, Any]]:
    return {**METRICS, **(POINTING_METRICS if tracking else {})}


def stored_names(tracking: bool) -> list[str]:
    """The per-run inputs and metrics a store holds (a tracking campaign's with its reference and pointing)."""
    return [*_inputs(tracking), *_metrics(tracking)]


def _file_attrs(spec: CampaignSpec) -> dict[str, Any]:
    files = {key: {"path": each.path, "sha256": each.sha256} for key, each in spec.files.items()}
    return {"flight_files": json.dumps(files, sort_keys=True)} if files else {}


def _attrs(spec: CampaignSpec) -> dict[str, Any]:
    return {
        **_file_attrs(spec),
        "campaign": json.dumps(spec.source, sort_keys=True),
        "name": spec.base.name,
        "count": spec.count,
        "seed": spec.seed,
        "rule": str(spec.base.rule),
        "rules": json.dumps(list(spec.rule_labels)),
        # the predictor's model inertia (kg m^2, 3x3 as JSON; "null" without the predictor)
        "predictor_model_inertia": json.dumps(
            None if spec.predictor is None else np.asarray(spec.predictor.model.inertia, dtype=float).tolist()
        ),
        # the predictor's form ("nonlinear" or "linear"; "null" without the predictor)
        "predictor_form": json.dumps(None if spec.predictor is None else spec.predictor.form.value),
        "versions": json.dumps(versions(), sort_keys=True),
        "noise_revision": NOISE_REVISION,
    }


def _template(spec: CampaignSpec, chunk: int) -> xr.Dataset:
    """The store's arrays filled with the missing values, as lazy Dask arrays (memory: one chunk at a time)."""
    # deferred: Dask, only for a Dask campaign or a store read lazily
    import dask.array as da

    n = spec.count
    data: dict[str, Any] = {}
    for name, (dims, dtype) in _inputs(spec.tracking).items():
        shape = (n, *(_SIZES[d] for d in dims))
        missing = np.nan if np.dtype(dtype).kind == "f" else -1
        data[name] = (("run", *dims), da.full(shape, missing, dtype=dtype, chunks=(chunk, *shape[1:])))
    for name, (dtype, missing) in _metrics(spec.tracking).items():
        data[name] = (("run",), da.full((n,), missing, dtype=dtype, chunks=(chunk,)))
    wheels = spec.base.wheels
    if wheels is not None:
        for name, (dims, dtype, missing, unit) in WHEEL_METRICS.items():
            shape = (n, *([wheels.count] if dims else []))
            chunks = (chunk, *shape[1:])
            data[name] = (("run", *dims), da.full(shape, missing, dtype=dtype, chunks=chunks), {"units": unit})
    for key, each in spec.files.items():
        name, dims = FILE_ARRAYS[key]
        data[name] = (dims, np.array(each.values), {"units": _FILE_UNITS[key]})
    dataset = xr.Dataset(data, coords={"run": np.arange(n, dtype=np.int64)}, attrs=_attrs(spec))
    for name, unit in {**_UNITS, **(_TRACKING_UNITS if spec.tracking else {})}.items():
        dataset[name].attrs["units"] = unit
    return dataset


def run_arrays(tracking: bool = False, wheels: bool = False) -> dict[str, int]:
    """The per-run arrays (chunked by the campaign chunk) and their number of dimensions (``tracking``: a
    tracking campaign's, with its reference inputs and pointing metrics; ``wheels``: a campaign on wheels, with
    the wheel metrics)."""
    return {
        **{name: 1 + len(dims) for name, (dims, _) in _inputs(tracking).items()},
        **{name: 1 for name in _metrics(tracking)},
        **({name: 1 + len(dims) for name, (dims, *_) in WHEEL_METRICS.items()} if wheels else {}),
    }


def bytes_per_run(tracking: bool = False, wheels: int = 0) -> int:
    """Uncompressed bytes one run takes in the store (inputs, metrics and its coordinate; with ``wheels``
    wheels, their metrics)."""
    inputs = sum(8 * int(np.prod([_SIZES[d] for d in dims])) for dims, _ in _inputs(tracking).values())
    metrics = sum(np.dtype(dtype).itemsize for dtype, _ in _metrics(tracking).values())
    wheel = sum(8 * (wheels if dims else 1) for dims, *_ in WHEEL_METRICS.values()) if wheels else 0
    return inputs + metrics + wheel + 8


class CampaignStore:
    """A campaign's results folder: create or reopen it, write chunks, read what is complete.

    Parameters
    ----------
    out : path
        The results folder (created if needed); the store is ``out/campaign.zarr``.
    spec : CampaignSpec
        The campaign. Reopening a store of another campaign is an error.
    chunk : int or None
        Runs per chunk. None: the store's (when it exists) or 1000.

    Notes
    -----
    Opening or creating the store holds the one-writer lock
    ([writer_lock][mrpctl.campaign.integrity.writer_lock]); a caller that writes chunks holds it
    for as long as it writes (``run_campaign`` does).
    """

    def __init__(self, out: str | Path, spec: CampaignSpec, chunk: int | None = None) -> None:
        self.out = Path(out)
        self.path = self.out / STORE_NAME
        self.spec = spec
        with integrity.writer_lock(self.out):
            self._open(chunk)
        self.chunks = -(-spec.count // self.chunk)

    @property
    def _arrays(self) -> dict[str, int]:
        return run_arrays(self.spec.tracking, self.spec.base.wheels is not None)

    def _open(self, chunk: int | None) -> None:
        spec = self.spec
        if self.path.exists():
            stored = zarr.open_group(str(self.path), mode="r")
            attrs = dict(stored.attrs)
            if json.loads(str(attrs.get("campaign", "null"))) != spec.source:
                raise SpecificationError(
                    f"out: {self.path} holds another campaign ({attrs.get('name')!r}); choose a new --out folder"
                )
            _check_files(self.path, stored, spec)
            revision = stored_noise_revision(attrs)
            if spec.attitude_noisy and revision != NOISE_REVISION:
                raise SpecificationError(
                    f"out: the store at {self.path} was written with noise revision {revision}, this mrpctl computes "
                    f"revision {NOISE_REVISION} (mrpctl.flight.NOISE_REVISION): runs with attitude noise differ in "
                    "their last bits, and resuming would mix the two; choose a new --out folder"
                )
            stored_chunk = int(str(stored["chunk_complete"].attrs["runs_per_chunk"]))
            if chunk is not None and chunk != stored_chunk:
                raise SpecificationError(
                    f"chunk: the store at {self.path} was started with {stored_chunk} runs per chunk, got {chunk}; "
                    "resume with the same chunk (or leave it out)"
                )
            self.chunk = stored_chunk
        else:
            self.chunk = 1000 if chunk is None else chunk
            if self.chunk < 1:
                raise SpecificationError(f"chunk must be >= 1, got {self.chunk}")
            self._create()

    def _create(self) -> None:
        self.out.mkdir(parents=True, exist_ok=True)
        temporary = self.out / (STORE_NAME + ".tmp")
        if temporary.exists():
            shutil.rmtree(temporary)
        wheels = self.spec.base.wheels
        estimate = self.spec.count * bytes_per_run(self.spec.tracking, 0 if wheels is None else wheels.count) + sum(
            each.values.nbytes for each in self.spec.files.values()
        )
        free = shutil.disk_usage(self.out).free
        if estimate > free // 2:
            raise SpecificationError(
                f"count: the store of {self.spec.count} runs needs about {estimate / 1e9:.3g} GB (uncompressed) but "
                f"{self.out} has {free / 1e9:.3g} GB free; use a smaller count (split the campaign by seed) or "
                "another --out"
            )
        dataset = _template(self.spec, self.chunk)
        chunks = -(-self.spec.count // self.chunk)
        dataset["chunk_complete"] = (("chunk",), np.zeros(chunks, dtype=bool), {"runs_per_chunk": self.chunk})
        encoding = {name: {"chunks": (self.chunk, *dataset[name].shape[1:])} for name in dataset.data_vars}
        for name, _ in FILE_ARRAYS.values():
            if name in dataset:  # shared by the runs: one Zarr chunk
                encoding[name] = {"chunks": dataset[name].shape}
        encoding["chunk_complete"] = {"chunks": (1,)}
        # deferred: Dask, only for a Dask campaign or a store read lazily
        import dask

        # The template's lazy arrays are filled here, in this process: never on a Dask Client that happens
        # to be the default (the campaign's own, or a user's), which would ship every chunk as a task.
        with dask.config.set(scheduler="synchronous"):
            dataset.to_zarr(str(temporary), mode="w", encoding=encoding, consolidated=False)
        # the per-sample files' arrays are checked by their own SHA-256 (attrs["flight_files"], stored_files)
        skip = {*self._arrays, "chunk_complete", *(name for name, _ in FILE_ARRAYS.values())}
        integrity.record_static(temporary, skip=skip)
        os.replace(temporary, self.path)

    def check(self) -> integrity.StoreCheck:
        """Every complete chunk checked against its SHA-256 record."""
        return integrity.check_store(self.path, self._arrays, self.chunk, self.spec.count)

    def complete(self) -> np.ndarray:
        """(chunks,) True for every chunk whose runs are all written and intact (damaged chunks are not).

        Raises
        ------
        StoreDamagedError
            If a file written at the store's creation (metadata, coordinates) is damaged.
        """
        check = self.check()
        if check.static:
            raise check.error(repair="")
        self.damaged = check.damaged
        self.verified = check.verified
        return np.asarray(check.intact, dtype=bool)

    def bounds(self, index: int) -> tuple[int, int]:
        """The runs [start, stop) of chunk ``index``."""
        return index * self.chunk, min((index + 1) * self.chunk, self.spec.count)

    def write(self, index: int, values: dict[str, np.ndarray]) -> None:
        """Write chunk ``index``'s arrays, their SHA-256 record, then mark it complete (in that order).

        A chunk written before (damaged, or half-written) is first unflagged and its record and files removed.
        """
        start, stop = self.bounds(index)
        verified = (self.path / integrity.RECORDS).is_dir()
        tracking = self.spec.tracking
        flags = zarr.open_array(str(self.path / "chunk_complete"), mode="r+")
        if verified:
            flags[index] = False
            integrity.forget_chunk(self.path, self._arrays, index)
        data = {}
        for name, (dims, _) in _inputs(tracking).items():
            data[name] = (("run", *dims), values[name])
        for name in _metrics(tracking):
            data[name] = (("run",), values[name])
        for name, (dims, *_) in WHEEL_METRICS.items() if self.spec.base.wheels is not None else ():
            data[name] = (("run", *dims), values[name])
        xr.Dataset(data).to_zarr(str(self.path), region={"run": slice(start, stop)}, mode="r+", consolidated=False)
        if verified:
            integrity.record_chunk(self.path, self._arrays, index)
        flags[index] = True


def open_campaign(out: str | Path, *, complete_only: bool = True, intact_only: bool = False) -> xr.Dataset:
    """The results of a campaign (running, interrupted or finished) as an in-memory Dataset.

    Every complete chunk is first checked against its SHA-256 record
    ([check_store][mrpctl.campaign.integrity.check_store]).

    Parameters
    ----------
    out : path
        The results folder given to ``run_campaign`` / ``mrpctl campaign run --out``.
    complete_only : bool
        Keep only the runs of complete chunks (default); False returns every run, with
        the missing values (NaN, −1, False) where a run has not finished.
    intact_only : bool
        With a damaged chunk, return the runs of the intact complete chunks (and record the damaged
        ones in ``attrs["integrity"]``) rather than refusing.

    Returns
    -------
    xarray.Dataset
        Over ``run``; ``attrs`` holds the campaign (JSON), seed, count and versions, and ``integrity``
        (JSON: ``verified``, and the ``damaged`` chunks with their runs, array, file and problem).

    Raises
    ------
    StoreDamagedError
        If a chunk (or a file written at the store's creation) does not match its record; the message
        names the store, the array, the chunk's runs, what is wrong and the command that repairs it.
    """
    path = Path(out) / STORE_NAME
    if not path.exists():
        raise SpecificationError(f"out: no campaign store at {path}")
    with xr.open_zarr(str(path), consolidated=False) as stored:
        tracking = tracking_store(stored.attrs)
        wheels = "wheel_peak_speed" in stored  # a campaign on wheels
        estimate = stored.sizes["run"] * bytes_per_run(tracking, stored.sizes.get("wheel", 0) if wheels else 0)
        available = _available_memory()
        if available is not None and estimate > available // 2:
            raise SpecificationError(
                f"out: the campaign needs about {estimate / 1e9:.3g} GB in memory but {available / 1e9:.3g} GB are "
                f"available; read it lazily with xarray.open_zarr({str(path)!r}) instead"
            )
        runs_per_chunk = int(str(stored["chunk_complete"].attrs["runs_per_chunk"]))
        count = stored.sizes["run"]
        check = integrity.check_store(path, run_arrays(tracking, wheels), runs_per_chunk, count)
        repair = f"mrpctl campaign run CAMPAIGN.toml --out {out} (CAMPAIGN.toml: the file this store was run from)"
        if check.static or (check.damaged and not (intact_only and complete_only)):
            raise check.error(repair=repair)
        selected = stored.drop_vars("chunk_complete")
        if complete_only:
            done = np.repeat(np.asarray(check.intact, dtype=bool), runs_per_chunk)[:count]
            selected = selected.isel(run=np.flatnonzero(done))
        try:
            # this process's threads, whatever Dask scheduler the caller has set as its default (a closed
            # distributed Client left as the default would otherwise fail the read)
            dataset = selected.load(scheduler="threads")
        except Exception as exc:
            why = (
                "every chunk matches its checksum record, so the files are as written and the reading failed"
                if check.verified
                else "it was written without checksum records, so the damaged chunk cannot be named; run the "
                "campaign again into a new --out"
            )
            raise integrity.StoreDamagedError(
                f"out: the campaign store {path} cannot be read ({type(exc).__name__}: {exc}); {why}"
            ) from None
    note = {
        "verified": check.verified,
        "damaged": [
            {"chunk": d.index, "runs": [d.start, d.stop - 1], "array": d.array, "file": d.file, "problem": d.problem}
            for d in check.damaged
        ],
    }
    if not check.verified:
        note["note"] = "written without checksum records (an older mrpctl): the chunks cannot be verified"
    dataset.attrs["integrity"] = json.dumps(note, sort_keys=True)
    return dataset


def _available_memory() -> int | None:
    """MemAvailable from /proc/meminfo (bytes), None where it cannot be read."""
    try:
        with open("/proc/meminfo", encoding="ascii") as handle:
            for line in handle:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def stored_noise_revision(attrs: Any) -> int:
    """The `NOISE_REVISION` a store was written with (1 for a store without the attribute)."""
    return int(str(attrs.get("noise_revision", 1)))


def _check_files(path: Path, stored: Any, spec: CampaignSpec) -> None:
    """Refuse to resume a store whose per-sample files held other numbers than the files read now."""
    recorded = json.loads(str(stored.attrs.get("flight_files", "{}")))
    for key, each in spec.files.items():
        old = recorded.get(key, {}).get("sha256")
        if old != each.sha256:
            raise SpecificationError(
                f"{FILE_KEYS[key]}: {each.path} is not the file this campaign was started with: its numbers have "
                f"SHA-256 {each.sha256}, the store at {path} holds {old}; restore the file or choose a new --out folder"
            )


def stored_files(dataset: xr.Dataset) -> dict[str, SampleFile]:
    """The per-sample files' numbers a results dataset holds (by ``[flight]`` key; empty without them)."""
    recorded = json.loads(str(dataset.attrs.get("flight_files", "{}")))
    found = {}
    for key, (name, _dims) in FILE_ARRAYS.items():
        if name in dataset:
            each = SampleFile(key, str(recorded.get(key, {}).get("path", key)), np.asarray(dataset[name].values))
            expected = recorded.get(key, {}).get("sha256")
            if each.sha256 != expected:
                raise SpecificationError(
                    f"{FILE_KEYS[key]}: the store's {name} has SHA-256 {each.sha256}, but attrs['flight_files'] "
                    f"records {expected}: the store was modified"
                )
            found[key] = each
    return found


def spec_of(dataset: xr.Dataset) -> CampaignSpec:
    """The campaign specification stored in a results dataset (per-sample files from the store, never re-read)."""
    return parse_campaign(
        json.loads(dataset.attrs["campaign"]),
        name=str(dataset.attrs.get("name", "campaign")),
        files=stored_files(dataset),
    )
