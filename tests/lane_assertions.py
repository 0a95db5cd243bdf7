"""Bit-for-bit comparisons of the lane-engine tests: a batch against another batch (the same call in series, on the
scalar engine, or a run's own one-run batch) and a batch's row against ``simulate`` of that run alone."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from mrpctl import simulate_batch
from mrpctl.simulation import BatchResult, _batch

#: The metrics a BatchResult keeps per run.
BATCH_FIELDS = (
    "switch_count",
    "plant_set_changes",
    "first_switch_time",
    "last_switch_time",
    "sign_flips",
    "settling_time",
    "converged",
    "diverged",
    "max_sigma",
    "peak_torque",
    "saturated_fraction",
    "peak_command",
)
#: The SimulationResult attributes that are the batch metrics of one run.
RUN_FIELDS = ("switch_count", "settling_time", "converged", "diverged", "peak_torque")


def one_run(case: dict[str, Any], i: int) -> dict[str, Any]:
    """Run i's arguments: its item of every per-run list (a shared value as it is)."""
    return {name: value[i] if isinstance(value, list | np.ndarray) else value for name, value in case.items()}


def scalar_batch(*args: Any, **kwargs: Any) -> BatchResult:
    """``simulate_batch`` with the lane engine switched off: every run on the scalar engine."""
    _batch._LANES = False
    try:
        return simulate_batch(*args, **kwargs)
    finally:
        _batch._LANES = True


def assert_same_bits(
    got: BatchResult,
    want: BatchResult,
    rows: slice | list[int] = slice(None),
    fields: Iterable[str] = BATCH_FIELDS,
) -> None:
    """``got``'s ``rows`` of every field hold the same bytes as ``want``'s (same shape too)."""
    for name in fields:
        a, b = np.asarray(getattr(got, name))[rows], np.asarray(getattr(want, name))
        assert a.shape == b.shape, name
        assert np.array_equal(a.view(np.uint8), b.view(np.uint8)), name


def assert_row_is_the_run(batch: BatchResult, i: int, run: object, fields: Iterable[str] = RUN_FIELDS) -> None:
    """Row i of the batch holds the bytes of ``run``'s attributes (a run's None as the batch's NaN)."""
    for name in fields:
        mine, value = np.asarray(getattr(batch, name))[i], getattr(run, name)
        assert mine.tobytes() == np.asarray(np.nan if value is None else value, mine.dtype).tobytes(), (i, name)
