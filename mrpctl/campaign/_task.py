"""The work of one chunk, in its own light module: what a Dask worker imports to run a task.

Importing this module (and the package ``mrpctl.campaign``, whose names are bound lazily) does
not import xarray, zarr or matplotlib: a worker imports what it computes with and nothing else.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrpctl.campaign.sampling import run_inputs
from mrpctl.campaign.simulation import simulate_runs
from mrpctl.campaign.spec import CampaignSpec, parse_campaign

__all__ = ["chunk_on_worker", "simulate_chunk"]


def simulate_chunk(spec: CampaignSpec, start: int, stop: int, *, threads: int | None = None) -> dict[str, np.ndarray]:
    """Inputs and metrics of runs [start, stop) of ``spec`` (what one chunk stores).

    Returns
    -------
    dict of numpy.ndarray
        The arrays of :data:`mrpctl.campaign.store.INPUTS` and
        :data:`mrpctl.campaign.simulation.METRICS`, one row per run.
    """
    inputs = run_inputs(spec, start, stop)
    base = spec.base
    K = inputs.gain_scale[:, None, None] * base.K[None]
    metrics = simulate_runs(
        inputs.inertia,
        K,
        inputs.x0,
        inputs.tau,
        base.rule,
        t_final=base.t_final,
        rate=base.rate,
        history=base.history,
        substeps=base.substeps,
        threads=threads,
        peak_torque=spec.peak_torque,
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
        **metrics,
    }


def chunk_on_worker(source: dict[str, Any], name: str, start: int, stop: int) -> dict[str, np.ndarray]:
    """The Dask task: rebuild the spec from plain data (cheap to ship) and run the chunk on one thread."""
    return simulate_chunk(parse_campaign(source, name=name), start, stop, threads=1)
