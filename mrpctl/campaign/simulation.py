"""The campaign's one call into the simulator: dispersed runs in, per-run metrics out.

Until ``simulate_batch`` accepts one spacecraft per run, runs are grouped by inertia
(one compiled engine per distinct inertia and delay; correct but slow when the inertia is
dispersed). After the merge, :func:`simulate_runs` is switched with one line (marked).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrpctl import BatchResult, simulate_batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule

__all__ = ["METRICS", "TRAJECTORY_GROUP", "simulate_runs"]

#: Per-run metrics, in the order they are stored, with their dtype and "missing" value.
METRICS: dict[str, tuple[Any, Any]] = {
    "switch_count": (np.int64, -1),
    "first_switch_time": (np.float64, np.nan),
    "last_switch_time": (np.float64, np.nan),
    "settling_time": (np.float64, np.nan),
    "converged": (np.bool_, False),
    "diverged": (np.bool_, False),
    "max_sigma": (np.float64, np.nan),
    "peak_torque": (np.float64, np.nan),
}

#: Runs simulated at once when the trajectories are needed for the peak torque (memory:
#: about 80 bytes per sample and run, so 8 runs of 60 s at 1 kHz take 38 MB).
TRAJECTORY_GROUP = 8

#: True once the simulator reports the peak torque itself (then no trajectories are needed).
_SIMULATOR_HAS_PEAK_TORQUE = "peak_torque" in getattr(BatchResult, "__dataclass_fields__", {})


def _metrics(batch: Any, peak: np.ndarray | None) -> dict[str, np.ndarray]:
    out = {name: np.asarray(getattr(batch, name)) for name in METRICS if name != "peak_torque"}
    reported = getattr(batch, "peak_torque", None)  # the simulator's own metric, once "sim" has merged
    if reported is not None:
        out["peak_torque"] = np.asarray(reported, dtype=float)
    elif peak is not None:
        out["peak_torque"] = peak
    else:
        out["peak_torque"] = np.full(len(batch), np.nan)
    return out


def _batch(
    spacecraft: Spacecraft,
    K: np.ndarray,
    x0: np.ndarray,
    tau: np.ndarray,
    rule: SwitchingRule,
    options: dict[str, Any],
    peak_torque: bool,
) -> dict[str, np.ndarray]:
    """Runs of one spacecraft; the peak torque from trajectories when the simulator lacks it."""
    if not peak_torque or _SIMULATOR_HAS_PEAK_TORQUE:
        return _metrics(simulate_batch(spacecraft, K, x0, tau=tau, rule=rule, **options), None)
    parts: list[dict[str, np.ndarray]] = []
    for start in range(0, len(x0), TRAJECTORY_GROUP):
        part = slice(start, start + TRAJECTORY_GROUP)
        batch = simulate_batch(spacecraft, K[part], x0[part], tau=tau[part], rule=rule, trajectories=True, **options)
        assert batch.runs is not None  # trajectories=True always returns them
        peak = np.array([float(np.max(np.linalg.norm(run.u, axis=1))) if len(run.u) else np.nan for run in batch.runs])
        parts.append(_metrics(batch, peak))
    return {name: np.concatenate([p[name] for p in parts]) for name in METRICS}


def simulate_runs(
    inertia: np.ndarray,
    K: np.ndarray,
    x0: np.ndarray,
    tau: np.ndarray,
    rule: SwitchingRule,
    *,
    t_final: float,
    rate: float,
    history: str,
    substeps: int,
    threads: int | None = None,
    peak_torque: bool = True,
) -> dict[str, np.ndarray]:
    """Simulate N runs, each with its own inertia, gain, initial state and delay.

    Parameters
    ----------
    inertia : numpy.ndarray
        (N, 3, 3) inertia matrices (kg m²).
    K : numpy.ndarray
        (N, 3, 6) gains on x = [σ; ω/4].
    x0 : numpy.ndarray
        (N, 6) initial states.
    tau : numpy.ndarray
        (N,) delays (s).
    rule : SwitchingRule
        The rule of every run.
    t_final, rate, history, substeps, threads
        As in :func:`mrpctl.simulate_batch`.
    peak_torque : bool
        Also return max_k ‖u_k‖ (N m) per run (NaN when False).

    Returns
    -------
    dict of numpy.ndarray
        One (N,) array per name in :data:`METRICS`, in input order.
    """
    n = len(x0)
    options: dict[str, Any] = dict(t_final=t_final, rate=rate, history=history, substeps=substeps, threads=threads)
    # After "sim" merges (simulate_batch(spacecraft=[...]) with one engine for all), replace the
    # grouping below by one call: _batch([Spacecraft(J) for J in inertia], K, x0, tau, rule, options, peak_torque)
    groups: dict[bytes, list[int]] = {}
    for i in range(n):
        groups.setdefault(np.ascontiguousarray(inertia[i]).tobytes(), []).append(i)
    out = {name: np.full(n, missing, dtype=dtype) for name, (dtype, missing) in METRICS.items()}
    for members in groups.values():
        index = np.array(members)
        part = _batch(Spacecraft(inertia[index[0]]), K[index], x0[index], tau[index], rule, options, peak_torque)
        for name in METRICS:
            out[name][index] = part[name]
    return out
