"""simulate_batch's per-run inputs: each of the disturbance, the flight models, the reference and the gains given
once (shared by the runs) or once per run, checked and broadcast to one item per run."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from mrpctl._validation import finite_array
from mrpctl.conventions import PDGains, feedback_gain
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, Disturbance, Saturation
from mrpctl.flight.tracking import ReferenceStream
from mrpctl.simulation._tracking import tracking_options
from mrpctl.switching import SwitchingRule

__all__ = [
    "SHARED_HINT",
    "batch_gains",
    "broadcast",
    "each_run_models",
    "each_run_reference",
    "one_disturbance",
    "per_run_disturbances",
    "shared_saturation",
]


#: Appended to a shared torque series' row-count error in simulate_batch (a list of lists is one (n, 3) series).
SHARED_HINT = (
    "; a list of lists is one torque series shared by the runs: for one constant torque per run give a list of "
    "(3,) arrays or Disturbance objects (or a (runs, n, 3) array for per-run series)"
)


def per_run_disturbances(disturbance: Any, n_runs: int, n: int) -> list[Disturbance | None] | None:
    """simulate_batch's per-run disturbances, or None when one disturbance is shared by the runs.

    Per run: a list or tuple of 1 or N items of which at least one is None, a [`Disturbance`][mrpctl.flight.Disturbance]
    or a NumPy array (each item as [`simulate`][mrpctl.simulation.simulate] takes it), or a (N, n, 3) array (each run's
    rows a read-only view, not a copy). Anything else is shared (a (3,) torque, (n, 3) rows, a
    [`Disturbance`][mrpctl.flight.Disturbance]).
    """
    if disturbance is None or isinstance(disturbance, Disturbance):
        return None
    if isinstance(disturbance, list | tuple) and any(
        item is None or isinstance(item, Disturbance | np.ndarray) for item in disturbance
    ):
        broadcast("disturbance", len(disturbance), n_runs)
        items = list(disturbance) * (n_runs if len(disturbance) == 1 else 1)
        return [one_disturbance(item, f"disturbance[{i}]") for i, item in enumerate(items)]
    if isinstance(disturbance, np.ndarray) and disturbance.ndim == 3:
        if disturbance.shape[0] not in (1, n_runs) or disturbance.shape[1:] != (n, 3):
            raise DimensionError(
                f"disturbance: a per-run per-sample torque has shape (runs, n, 3) = ({n_runs}, {n}, 3) "
                f"(or (1, {n}, 3)) but found {disturbance.shape}"
            )
        return [
            Disturbance.rows_view(disturbance[i if len(disturbance) > 1 else 0], f"disturbance[{i}]")
            for i in range(n_runs)
        ]
    return None


def one_disturbance(item: Any, name: str) -> Disturbance | None:
    """One run's disturbance as a Disturbance (float64 (n, 3) rows viewed, not copied), or None."""
    if item is None or isinstance(item, Disturbance):
        return item
    if isinstance(item, np.ndarray) and item.ndim == 2:
        return Disturbance.rows_view(item, name)
    try:
        return Disturbance(item)
    except ValueError as error:
        raise type(error)(f"{name}: {error}") from error


def each_run_models(name: str, value: Any, kind: type, n_runs: int) -> tuple[list[Any], bool]:
    """simulate_batch's ``actuator``, ``sensor`` or ``delay``: one model per run, and whether a list or tuple
    gave them per run (1 or N entries, each a ``kind`` or None); anything else is shared (checked later)."""
    if not isinstance(value, list | tuple):
        return [value] * n_runs, False
    broadcast(name, len(value), n_runs)
    for i, item in enumerate(value):
        if item is not None and not isinstance(item, kind):
            raise SpecificationError(f"{name}[{i}] must be a mrpctl.flight.{kind.__name__} or None, got {item!r}")
    return list(value) * (n_runs if len(value) == 1 else 1), True


def shared_saturation(actuators: Sequence[ActuatorModel | None]) -> Saturation | None:
    """The saturation mode of the runs' actuators (None: no actuator); per-run actuators of different modes are
    refused (the mode is a structure of the compiled sample)."""
    modes = {one.mode for one in actuators if one is not None}
    if len(modes) > 1:
        raise SpecificationError(
            f"actuator: the runs of one call share the saturation mode (a structure of the compiled engine), got "
            f"{sorted(mode.value for mode in modes)}; give the runs of each mode in a call of their own"
        )
    return next(iter(modes), None)


def each_run_reference(
    reference: Any,
    error_time: Any,
    feedforward: Any,
    pointing_tolerance: Any,
    rules: Sequence[SwitchingRule],
    checked: Any,
    n: int,
    rate: float,
    samples_by_run: Sequence[int],
) -> list[ReferenceStream | None]:
    """simulate_batch's reference of each run (None: regulation), checked once per (reference, delay)."""
    runs = len(rules)
    per_run = isinstance(reference, list | tuple)
    if per_run:
        broadcast("reference", len(reference), runs)
    items = (list(reference) * (runs if len(reference) == 1 else 1)) if per_run else [reference] * runs
    made: dict[tuple[int, int], ReferenceStream | None] = {}
    out: list[ReferenceStream | None] = []
    for i in range(runs):
        key = (id(items[i]), samples_by_run[i])
        if key not in made:
            made[key] = tracking_options(
                items[i], error_time, feedforward, pointing_tolerance, rule=rules[i], predictor=checked, n=n,
                rate=rate, d=samples_by_run[i], name=f"reference[{i}]" if per_run else "reference",
            )[0]  # fmt: skip
        out.append(made[key])
    return out


def broadcast(name: str, count: int, n: int) -> None:
    if count not in (1, n):
        expected = "1 entry" if n == 1 else f"1 or {n} entries (one per run)"
        raise DimensionError(f"{name}: expected {expected} but found {count}")


def batch_gains(K: Any) -> np.ndarray:
    """simulate_batch's gains as an array: K itself ((3, 6) or (N, 3, 6), checked by the caller), or one
    [`PDGains`][mrpctl.conventions.PDGains] or a sequence of them (each converted to its K)."""
    if isinstance(K, PDGains):
        return feedback_gain(K)
    if isinstance(K, list | tuple) and any(isinstance(item, PDGains) for item in K):
        return np.stack([feedback_gain(item) for item in K]) if K else finite_array("K", K)
    return finite_array("K", K)
