"""`LaneBatches`: the runs of one `mrpctl.engines.lanes.LaneEngine` packed in batches of W lanes, run slice by slice."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from mrpctl import _compile
from mrpctl.engines.lane_streams import OwnStreams
from mrpctl.errors import CodegenError, DimensionError, SpecificationError

__all__ = ["LaneBatches"]


class LaneBatches:
    """N runs of one `mrpctl.engines.lanes.LaneEngine` packed into ``count`` batches of W lanes.

    `run` advances one batch to the horizon slice by slice and writes its lanes'
    carried values into `out` (N, carried nonzeros); batches are independent (a thread
    pool may run them in any order: each lane's bits do not depend on it).
    """

    def __init__(
        self,
        engine: Any,  # a mrpctl.engines.lanes.LaneEngine (not imported: lanes imports this module)
        carried: np.ndarray,
        constants: np.ndarray,
        history: np.ndarray,
        n: int,
        slice_samples: int,
        finished_row: int | None,
        *,
        stream: Callable[..., np.ndarray] | np.ndarray | None = None,
        schedule: Callable[..., np.ndarray] | None = None,
        lane_schedule: bool = False,
        own: OwnStreams | None = None,
    ) -> None:
        self.engine = engine
        self._stream = stream
        self._schedule = schedule
        self._lane_schedule = lane_schedule and schedule is not None
        self._own = own
        self.runs = len(carried)
        self.count = -(-self.runs // engine.width)
        self.n = n
        self._carried, self._constants, self._history = carried, constants, history
        self._slice = slice_samples
        self._finished_row = finished_row
        self.out = np.empty_like(carried)

    def lanes(self, b: int) -> int:
        """Runs (not padding) in batch b."""
        return min((b + 1) * self.engine.width, self.runs) - b * self.engine.width

    def run(self, b: int, stop: Callable[[int], bool] | None = None) -> bool:
        """Run batch b; ``stop(samples)`` after each slice (samples: run-samples done in this
        batch) returning True abandons it. Returns True when the batch reached the horizon."""
        engine, width = self.engine, self.engine.width
        lanes = np.arange(b * width, (b + 1) * width)
        lanes[lanes >= self.runs] = b * width  # padding lanes repeat the batch's first run
        block = np.ascontiguousarray(self._carried[lanes].T)
        values = np.ascontiguousarray(self._constants[lanes].T)
        columns = np.empty((engine.history_columns, engine.measured, width))  # m_{-d}.., (measured, W) each
        columns[...] = self._history[lanes].transpose(1, 2, 0)  # broadcasts a constant (1-column) history
        ring = np.empty((engine.d + 1, engine.measured, width))
        pointers = (_compile.address(block), _compile.address(values), _compile.address(columns))
        real = self.lanes(b)
        constant_row = None
        if self._stream is not None and not callable(self._stream):
            constant_row = np.ascontiguousarray(self._stream, dtype=float)
            if constant_row.shape != (engine.stream_size,):
                raise DimensionError(f"stream: expected shape ({engine.stream_size},) but found {constant_row.shape}")
        newest: Any = np.full(width, -1 - engine.d, dtype=np.int64) if self._lane_schedule else -1 - engine.d
        run_slice = engine._run
        own: tuple[Any, ...] = ()
        if self._own is not None:  # each lane's noise keys and scales, and its jitter state (kept across slices)
            state = self._own.batch(lanes, engine.d)
            own = tuple(None if part is None else _compile.address(part) for part in state)
            run_slice = engine._run_own
        k = 0
        while k < self.n:
            k1 = min(k + self._slice, self.n)
            rows, stride = constant_row, 0
            if callable(self._stream):
                given = self._stream(k, k1, lanes) if engine.lane_streamed else self._stream(k, k1)
                rows, stride = np.ascontiguousarray(given, dtype=float), engine.stream_size
                if rows.shape != (k1 - k, engine.stream_size):
                    raise DimensionError(
                        f"stream: expected shape ({k1 - k}, {engine.stream_size}) but found {rows.shape}"
                    )
            used = None
            if self._schedule is not None:
                given = self._schedule(k, k1, newest, lanes) if self._lane_schedule else self._schedule(k, k1, newest)
                used = np.ascontiguousarray(given, dtype=np.int64)
                samples = np.arange(k, k1)[:, None] if self._lane_schedule else np.arange(k, k1)
                if (
                    used.shape != ((k1 - k, width) if self._lane_schedule else (k1 - k,))
                    or np.any(used >= samples)
                    or np.any(used < samples - engine.d)
                ):
                    raise SpecificationError(f"schedule: j*(k) must lie in [k - d, k - 1] with d = {engine.d}")
                newest = used[-1].copy() if self._lane_schedule else int(used[-1])
            status = run_slice(
                *pointers,
                k,
                k1,
                engine.d,
                _compile.address(ring),
                None if rows is None else _compile.address(rows),
                stride,
                None if used is None else _compile.address(used),
                *own,
            )
            if status != 0:
                raise CodegenError(f"the lane engine {engine.library} failed")
            k = k1
            if stop is not None and stop(k * real):
                return False
            if self._finished_row is not None and k < self.n and np.all(block[self._finished_row] >= 0):
                break  # every lane is done: only their sample counters would still move
        self.out[b * width : b * width + real] = block.T[:real]
        return True
