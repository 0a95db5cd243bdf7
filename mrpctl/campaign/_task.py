"""The work of one chunk, in its own light module: what a Dask worker imports to run a task.

Importing this module (and the package ``mrpctl.campaign``, whose names are bound lazily) does
not import xarray, zarr or matplotlib: a worker imports what it computes with and nothing else.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from mrpctl.campaign.reference import REFERENCE_INPUTS, run_reference
from mrpctl.campaign.sampling import RunInputs, run_inputs
from mrpctl.campaign.simulation import simulate_runs
from mrpctl.campaign.spec import CampaignSpec, FlightOptions, SampleFile, parse_campaign
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, Saturation, SensorModel
from mrpctl.guidance import GuidanceProfile
from mrpctl.switching import SwitchingRule

__all__ = [
    "FLIGHT_INPUTS",
    "WARM_UP_RUNS",
    "ShippedFiles",
    "chunk_on_worker",
    "received_files",
    "run_models",
    "run_tracking",
    "shipped_files",
    "simulate_chunk",
    "tracking_keywords",
    "warm_up_worker",
]


#: A campaign's per-sample files as a task carries them: key -> (path, values), plain data that the Dask scheduler
#: unpickles without importing mrpctl (see `shipped_files`).
ShippedFiles = dict[str, tuple[str, np.ndarray]]

#: Runs simulated (and discarded) by `warm_up_worker`: enough for the engine of a chunk, too few to cost time.
WARM_UP_RUNS = 8

#: The per-run inputs of the flight loop stored with each run (besides the rule index and case).
FLIGHT_INPUTS = (
    "delta",
    "u_max",
    "disturbance",
    "attitude_noise",
    "rate_noise",
    "gyro_bias",
    "noise_seed",
    "jitter_seed",
)


def run_models(spec: CampaignSpec, inputs: RunInputs, j: int) -> tuple[SwitchingRule, dict[str, Any] | None]:
    """Row j's rule object and flight models (None without the flight loop), rebuilt from its stored inputs.

    The models are ``actuator``, ``disturbance`` (the run's constant torque, (3,)), ``sensor``, ``delay``
    and ``disturbance_rows`` (the (n, 3) rows of ``flight.disturbance_file`` shared by the runs, or None);
    [`mrpctl.campaign.simulation.flight_keywords`][mrpctl.campaign.simulation.flight_keywords] makes them keywords of
    [`mrpctl.simulate_batch`][mrpctl.simulate_batch].
    """
    rule = spec.rule_list[int(inputs.rule[j])]
    if isinstance(rule, Hysteretic) and spec.flight_dispersion.delta is not None:
        rule = Hysteretic(float(inputs.delta[j]))
    if not spec.uses_flight:
        return rule, None
    options = spec.flight if spec.flight is not None else FlightOptions()
    u_max = inputs.u_max[j]
    actuator = None
    if np.all(np.isfinite(u_max)):
        norm = options.actuator.norm_max if options.actuator is not None else None
        mode = options.actuator.mode if options.actuator is not None else Saturation.SCALE
        actuator = ActuatorModel(np.array(u_max), norm, mode)
    sensor = SensorModel(
        float(inputs.attitude_noise[j]),
        float(inputs.rate_noise[j]),
        np.array(inputs.gyro_bias[j]),
        seed=int(inputs.noise_seed[j]),
    )
    delay = options.delay_sequence  # the shared sequence of flight.delay_file (one object), or None
    if options.jitter is not None:
        delay = DelayModel.jitter(options.jitter[0], options.jitter[1], seed=int(inputs.jitter_seed[j]))
    models = {
        "actuator": actuator,
        "disturbance": np.array(inputs.disturbance[j]),
        "sensor": sensor,
        "delay": delay,
        "disturbance_rows": None if options.disturbance_file is None else options.disturbance_file.values,
    }
    return rule, models


def run_tracking(spec: CampaignSpec, inputs: RunInputs, j: int) -> GuidanceProfile | None:
    """Row j's reference (None when the campaign regulates), rebuilt from its stored inputs: the base
    ``[reference]`` itself where it is not dispersed (one object shared by the runs)."""
    if not spec.tracking:
        return None
    return run_reference(
        spec.base.reference,
        spec.reference,
        float(inputs.slew_angle[j]),
        np.array(inputs.slew_axis[j]),
        float(inputs.orbit_rate[j]),
    )


def tracking_keywords(spec: CampaignSpec) -> dict[str, Any]:
    """The tracking options shared by a tracking campaign's runs (``error_time``, ``feedforward``,
    ``pointing_tolerance`` of [`mrpctl.simulate`][mrpctl.simulation.simulate]) where the scenario reader
    gives them (`Scenario.tracking_options`); {} otherwise (simulate's defaults)."""
    if not spec.tracking:
        return {}
    options = getattr(spec.base, "tracking_options", {})
    return dict(options) if isinstance(options, dict) else {}


def simulate_chunk(spec: CampaignSpec, start: int, stop: int, *, threads: int | None = None) -> dict[str, np.ndarray]:
    """Inputs and metrics of runs [start, stop) of ``spec`` (what one chunk stores).

    Returns
    -------
    dict of numpy.ndarray
        The arrays of `mrpctl.campaign.store.INPUTS` and
        `mrpctl.campaign.simulation.METRICS`, one row per run; a tracking campaign's also those of
        `mrpctl.campaign.reference.REFERENCE_INPUTS` and `mrpctl.campaign.simulation.POINTING_METRICS`.
    """
    inputs = run_inputs(spec, start, stop)
    base = spec.base
    K = inputs.gain_scale[:, None, None] * base.K[None]
    per_run = [run_models(spec, inputs, j) for j in range(len(inputs))]
    tracked = [run_tracking(spec, inputs, j) for j in range(len(inputs))] if spec.tracking else None
    metrics = simulate_runs(
        inputs.inertia,
        K,
        inputs.x0,
        inputs.tau,
        [rule for rule, _ in per_run],
        t_final=base.t_final,
        rate=base.rate,
        history=base.history,
        substeps=base.substeps,
        threads=threads,
        peak_torque=spec.peak_torque,
        flight=[models for _, models in per_run],
        predictor=spec.predictor,
        settling_attitude=base.settling_attitude,
        settling_rate=base.settling_rate,
        reference=tracked,
        tracking=tracking_keywords(spec),
        wheels=base.wheels,
        law=base.law,
    )
    sigma_norm = np.linalg.norm(inputs.sigma0, axis=1)
    return {
        "sigma0": np.array(inputs.sigma0),
        "omega0": np.array(inputs.omega0),
        "inertia": np.array(inputs.inertia),
        "tau": np.array(inputs.tau),
        "gain_scale": np.array(inputs.gain_scale),
        "initial_angle": 4.0 * np.arctan(sigma_norm),
        "initial_rate": np.linalg.norm(inputs.omega0, axis=1),
        "rule": np.array(inputs.rule),
        "case": np.array(inputs.case),
        **{name: np.array(getattr(inputs, name)) for name in FLIGHT_INPUTS},
        **({name: np.array(getattr(inputs, name)) for name in REFERENCE_INPUTS} if spec.tracking else {}),
        **metrics,
    }


def chunk_on_worker(
    source: dict[str, Any], name: str, start: int, stop: int, files: dict[str, SampleFile] | None = None
) -> dict[str, np.ndarray]:
    """The Dask task: rebuild the spec from plain data (cheap to ship) and run the chunk on one thread.

    ``files``: the numbers of the campaign's per-sample files
    ([`CampaignSpec.files`][mrpctl.campaign.CampaignSpec.files]), shipped with
    the task, so a worker never reads them (it may not see the campaign file's folder).
    """
    return simulate_chunk(parse_campaign(source, name=name, files=files), start, stop, threads=1)


def warm_up_worker(source: dict[str, Any], name: str, files: dict[str, SampleFile] | None = None) -> int:
    """The Dask task a campaign sends to each worker before its chunks: what a worker's first chunk pays once.

    Receiving it imports this module on the worker; running it rebuilds the spec and simulates the first
    `WARM_UP_RUNS` runs on one thread, which compiles (or loads from the compile cache) the engine of the
    campaign and loads it in the worker process. The results are discarded: the chunks simulate those
    runs again, with the same bits. Returns the number of runs simulated.
    """
    spec = parse_campaign(source, name=name, files=files)
    stop = min(spec.count, WARM_UP_RUNS)
    simulate_chunk(spec, 0, stop, threads=1)
    return stop


def shipped_files(files: Mapping[str, SampleFile]) -> ShippedFiles:
    """The numbers of the per-sample files as plain data for a Dask task (undone by `received_files`).

    The scheduler unpickles every task it is given; a [`SampleFile`][mrpctl.campaign.spec.SampleFile] would make it
    import mrpctl to do so, a (path, values) pair only NumPy."""
    return {key: (each.path, each.values) for key, each in files.items()}


def received_files(files: ShippedFiles | None) -> dict[str, SampleFile] | None:
    """The `SampleFile` objects of `shipped_files`'s data (the same numbers, the same SHA-256)."""
    if files is None:
        return None
    return {key: SampleFile(key, path, values) for key, (path, values) in files.items()}
