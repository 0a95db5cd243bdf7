"""The campaign's one call into the simulator: dispersed runs in, per-run metrics out.

``simulate_batch`` takes one spacecraft per run (J and J⁻¹ are run-time inputs of the compiled
engine), so a campaign with dispersed inertia compiles one engine per delay, not one per run.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mrpctl import simulate_batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule

__all__ = ["METRICS", "simulate_runs"]

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


def _batch(
    spacecraft: list[Spacecraft],
    K: np.ndarray,
    x0: np.ndarray,
    tau: np.ndarray,
    rule: SwitchingRule,
    options: dict[str, Any],
) -> dict[str, np.ndarray]:
    """The runs' metrics from one metrics-only batch (the peak torque is accumulated by the engine)."""
    batch = simulate_batch(spacecraft, K, x0, tau=tau, rule=rule, **options)
    return {name: np.asarray(getattr(batch, name)) for name in METRICS}


def _spacecraft(inertia: np.ndarray) -> list[Spacecraft]:
    """One Spacecraft per run, built once per distinct inertia (the same values give the same object,
    so an undispersed inertia costs one eigen-decomposition per chunk, not one per run)."""
    built: dict[bytes, Spacecraft] = {}
    crafts = []
    for J in np.asarray(inertia, dtype=float):
        key = J.tobytes()
        craft = built.get(key)
        if craft is None:
            craft = built[key] = Spacecraft(J)
        crafts.append(craft)
    return crafts


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
        Also return the peak torque max_k |u_k|_∞ (N m) per run (NaN when False).

    Returns
    -------
    dict of numpy.ndarray
        One (N,) array per name in :data:`METRICS`, in input order.
    """
    n = len(x0)
    options: dict[str, Any] = dict(t_final=t_final, rate=rate, history=history, substeps=substeps, threads=threads)
    if n == 0:
        return {name: np.full(0, missing, dtype=dtype) for name, (dtype, missing) in METRICS.items()}
    # One call: simulate_batch takes a spacecraft per run and compiles one engine per inertia layout.
    out = _batch(_spacecraft(inertia), K, x0, tau, rule, options)
    if not peak_torque:
        out["peak_torque"] = np.full(n, np.nan)
    return out
