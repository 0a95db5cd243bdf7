"""Export an estimator's sample (with its gyro buffer) as a CasADi Function, C source and a manifest.

[`export_estimator`][mrpctl.estimation.export.export_estimator] writes into one folder:

* ``estimator_sample.casadi``: the sample ``(state, ring, gyro, measurement, available) -> (state_next,
  ring_next, sigma, omega, bias, covariance, innovation)`` (``casadi.Function.load``);
* ``estimator_sample.c``: its C source (CasADi's generated code, no header; IEEE arithmetic in the order
  CasADi wrote it);
* ``initial_state.txt``: the state of the initial estimate given;
* ``manifest.json``: the ports (names, shapes, meaning, units, time stamps), the clock (period, n, ℓ) and
  the tuning.

The folder is written beside its destination and swapped in whole: a reader sees the old folder or the new
one, never half of one.
"""

from __future__ import annotations

import json
import os
import secrets
import shutil
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._compile import generate_code
from mrpctl.errors import SpecificationError
from mrpctl.estimation.filters import EstimatorFunctions, EstimatorKind

__all__ = ["MANIFEST_NAME", "export_estimator"]

#: The manifest's file name.
MANIFEST_NAME = "manifest.json"


def _ports(functions: EstimatorFunctions) -> dict[str, list[dict[str, Any]]]:
    latency = functions.clock.latency
    attitude = "unit quaternion q (scalar first) of [BN]" if functions.kind is EstimatorKind.MEKF else "MRP sigma"
    state = f"{attitude}, bias (rad/s), P (6 x 6, column-major)"
    inputs = [
        {"name": "state", "shape": [functions.state_size, 1], "time": "t_{k-l-1}", "meaning": f"posterior: {state}"},
        {"name": "ring", "shape": [3, latency], "time": "t_{k-l} ... t_{k-1}", "meaning": "gyro readings (rad/s)"},
        {"name": "gyro", "shape": [3, 1], "time": "t_k", "meaning": "gyro reading: mean rate over [t_{k-1}, t_k]"},
        {"name": "measurement", "shape": [3, 1], "time": "t_{k-l}", "meaning": "star tracker MRP arriving now"},
        {"name": "available", "shape": [1, 1], "time": "t_k", "meaning": "1 when a measurement arrives, else 0"},
    ]
    if latency == 0:
        inputs = [port for port in inputs if port["name"] != "ring"]
    outputs = [
        {"name": "state_next", "shape": [functions.state_size, 1], "time": "t_{k-l}", "meaning": f"posterior: {state}"},
        {"name": "ring_next", "shape": [3, latency], "time": "t_{k-l+1} ... t_k", "meaning": "gyro readings"},
        {"name": "sigma", "shape": [3, 1], "time": "t_k", "meaning": "estimated attitude, short-set MRP"},
        {"name": "omega", "shape": [3, 1], "time": "t_k", "meaning": "gyro reading less the bias (rad/s)"},
        {"name": "bias", "shape": [3, 1], "time": "t_k", "meaning": "estimated gyro bias (rad/s)"},
        {"name": "covariance", "shape": [36, 1], "time": "t_k", "meaning": "error covariance, column-major"},
        {"name": "innovation", "shape": [3, 1], "time": "t_{k-l}", "meaning": "residual of the arriving measurement"},
    ]
    if latency == 0:
        outputs = [port for port in outputs if port["name"] != "ring_next"]
    return {"inputs": inputs, "outputs": outputs}


def export_estimator(
    functions: EstimatorFunctions, folder: str | os.PathLike[str], *, initial_state: Any = None
) -> Path:
    """Write the estimator's sample, its C source and its manifest into ``folder`` (replaced whole).

    Parameters
    ----------
    functions : EstimatorFunctions
    folder : path-like
        The destination folder (created; an existing folder is replaced by the new one).
    initial_state : array_like, optional, keyword-only
        A filter state to ship with it (default the tuning's P₀ at the identity and a zero bias).

    Returns
    -------
    pathlib.Path
        The folder.
    """
    if not isinstance(functions, EstimatorFunctions):
        raise SpecificationError(f"functions must be EstimatorFunctions, got {type(functions).__name__}")
    target = Path(folder)
    if initial_state is None:
        initial_state = functions.initial_state(np.zeros(3), np.zeros(3))
    state = np.asarray(initial_state, dtype=float)
    if state.shape != (functions.state_size,) or not np.all(np.isfinite(state)):
        raise SpecificationError(f"initial_state must be {functions.state_size} finite numbers")
    sample = functions.sample
    clock = functions.clock
    manifest = {
        "function": sample.name(),
        "kind": functions.kind.value,
        "clock": {"period_s": clock.period, "tracker_every_samples": clock.every, "latency_samples": clock.latency},
        "tuning": {
            "rate_noise_rad_per_sqrt_s": functions.tuning.rate_noise,
            "bias_walk_rad_per_s_three_halves": functions.tuning.bias_walk,
            "measurement_covariance_rad2": np.asarray(functions.tuning.measurement_covariance).tolist(),
            "initial_covariance": np.asarray(functions.tuning.initial_covariance).tolist(),
        },
        **_ports(functions),
        "files": ["estimator_sample.casadi", "estimator_sample.c", "initial_state.txt", MANIFEST_NAME],
    }
    target.parent.mkdir(parents=True, exist_ok=True)
    tag = f"{os.getpid()}-{secrets.token_hex(4)}"
    staging = target.parent / f".{target.name}.staging-{tag}"
    staging.mkdir()
    try:
        sample.save(str(staging / "estimator_sample.casadi"))
        (staging / "estimator_sample.c").write_text(generate_code(sample), encoding="utf-8")
        np.savetxt(staging / "initial_state.txt", state, fmt="%.17g")
        (staging / MANIFEST_NAME).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
        old = target.parent / f".{target.name}.old-{tag}"
        if target.exists():
            target.rename(old)
        staging.rename(target)
        if old.exists():
            shutil.rmtree(old)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return target
