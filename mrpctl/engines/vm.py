"""The engine without a C compiler: blocks of samples chained in CasADi's virtual machine.

A block is a whole number of chunks of max(d, 1) samples (about 500 samples; a
``mapaccum`` of chunks, the method of steps), expanded to one SX Function; a run is the
chain of blocks covering the horizon, evaluated by CasADi. It gives what the compiled
engine gives (to rounding: the VM's evaluation order may differ in the last bits) but
keeps the whole run in memory and is not interrupted between slices.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

from mrpctl.engines.common import RunOutput, Workspace
from mrpctl.engines.stats import S_DIVERGED, STATS_SIZE, initial_stats
from mrpctl.errors import CodegenError
from mrpctl.loop import InertiaInput, inertia_values
from mrpctl.loop.options import NO_FLIGHT_OPTIONS, flight_memory
from mrpctl.model import STATE_SIZE
from mrpctl.spacecraft import Spacecraft

__all__ = [
    "VirtualMachineEngine",
]

_BLOCK_TARGET = 500  # samples per block (a whole number of chunks)


def _block_function(sample: ca.Function, d: int, name: str) -> tuple[ca.Function, int]:
    """A whole number of chunks of max(d, 1) samples (about 500 samples), as one MX Function.

    ``block(x, memory, stats, history, K, parameters[, J, J_inv][, flight][, noise]) ->
    (x_end, memory_end, stats_end, history_end, measurements, u, switched)``: the inputs after
    ``history`` are the sample's constant inputs (the same at every sample), but for the flight
    sample's per-sample ``noise`` (6, samples): column k of the block is the noise (θ_k, η_k) of its
    sample k. With a sensor the history is the sensor's measurements m_k (the sample's ``measurement``
    output, the compiled driver's ring) and ``measurements`` the true states x_meas.
    """
    length = max(d, 1)
    chunks = max(1, round(_BLOCK_TARGET / length))
    samples = chunks * length
    x = ca.MX.sym("x", STATE_SIZE)
    memory = ca.MX.sym("memory", sample.size1_in(1))
    stats = ca.MX.sym("stats", STATS_SIZE)
    history = ca.MX.sym("history", STATE_SIZE, length)
    constants = _constant_symbols(sample)
    names = ["x", "memory", "stats", "history"] + [sample.name_in(i) for i in range(4, sample.n_in())]
    sensor = "noise" in sample.name_in()  # the flight sample with its sensor ports
    noise_chunk = ca.MX.sym("noise", STATE_SIZE, length)
    noise_block = ca.MX.sym("noise", STATE_SIZE, samples)

    def per_sample(values: list[Any], columns: int, noise: Any) -> list[Any]:
        """The constants repeated over ``columns`` samples, the noise (last input) as given."""
        repeated = [ca.repmat(value, 1, columns) for value in values]
        return [*repeated[:-1], noise] if sensor else repeated

    # One chunk: the method of steps over d samples (accumulators x, memory, stats).
    chunk_samples = sample.mapaccum("chunk_samples", length, 3)
    outs = chunk_samples(x, memory, stats, history, *per_sample(constants, length, noise_chunk))
    xs, memories, statss, measurements, u, switched = outs[0:6]
    ring = outs[6] if sensor else measurements  # what the next chunk reads as m_{k-d}
    chunk_inputs = (
        [x, memory, stats, history, *constants[:-1], noise_chunk] if sensor else [x, memory, stats, history, *constants]
    )
    chunk = ca.Function(
        "chunk",
        chunk_inputs,
        [xs[:, -1], memories[:, -1], statss[:, -1], ring, measurements, u, switched],
        names,
        ["x_end", "memory_end", "stats_end", "ring", "measurements", "u", "switched"],
    )
    # A block: chunks chained, each one's ring (measurements) being the next one's history.
    chained = chunk.mapaccum("block_chunks", chunks, 4)
    xs, memories, statss, rings, measurements, u, switched = chained(
        x, memory, stats, history, *per_sample(constants, chunks, noise_block)
    )
    block_inputs = (
        [x, memory, stats, history, *constants[:-1], noise_block] if sensor else [x, memory, stats, history, *constants]
    )
    block = ca.Function(
        name,
        block_inputs,
        [
            xs[:, -1],
            memories[:, -1],
            statss[:, -1],
            rings[:, samples - length :],
            measurements,
            u,
            switched,
        ],
        names,
        ["x_end", "memory_end", "stats_end", "history_end", "measurements", "u", "switched"],
    )
    return block, samples


def _constant_symbols(sample: ca.Function) -> list[ca.MX]:
    """MX symbols for the sample's inputs after x, memory, stats, x_delayed (K, parameters, ...)."""
    return [ca.MX.sym(sample.name_in(i), sample.sparsity_in(i)) for i in range(4, sample.n_in())]


class VirtualMachineEngine:
    """The engine of one structure in CasADi's virtual machine (see the module docstring)."""

    compiled_code = False

    def __init__(self, sample: ca.Function, d: int, inertia: InertiaInput, *, flight: bool = False) -> None:
        self.d = d
        self.flight = flight
        self.inertia = inertia
        self.sample = sample
        self.sensor = "noise" in sample.name_in()
        self.history_columns = max(d, 1)
        block, self.block_samples = _block_function(sample, d, sample.name().replace("sample", "block"))
        self.block = block.expand()  # one SX Function: no MX layers per sample in the VM
        self._horizons: dict[tuple[int, bool], ca.Function] = {}
        self._lock = threading.Lock()

    def blocks(self, n: int) -> int:
        """Blocks of the chain covering n samples."""
        return -(-n // self.block_samples)

    def workspace(self, n: int, switches: bool) -> Workspace:
        return Workspace(state=np.empty(0), ring=np.empty((0, STATE_SIZE)), switched=np.empty(0) if switches else None)

    def history_block(self, history: np.ndarray) -> np.ndarray:
        """(6, max(d, 1)) history block from (columns, 6) measurements (one column: constant)."""
        if history.shape[0] == self.history_columns:
            return np.ascontiguousarray(history.T)
        return np.tile(history[0][:, None], (1, self.history_columns))

    def run(
        self,
        x0: np.ndarray,
        memory0: float,
        history: np.ndarray,
        gain: np.ndarray,
        parameters: np.ndarray,
        n: int,
        *,
        spacecraft: Spacecraft,
        keep_every: int | None,
        workspace: Workspace,
        switch_limit: int = 0,
        stop: Callable[[int], bool] | None = None,
        flight_options: np.ndarray | None = None,
        sensor: Any = None,
        delay: Any = None,
        rate: float = 1.0,
        settling: tuple[float, float] | None = None,
    ) -> RunOutput:
        """As `mrpctl.engines.scalar.Engine.run`, the whole horizon at once."""
        trajectories = keep_every is not None or workspace.switched is not None
        inertia = inertia_values(spacecraft, self.inertia)
        constants = list(inertia)
        if delay is not None:
            raise CodegenError(
                "delay: a time-varying delay needs the compiled engine (install a C compiler: gcc or cc, or set CC); "
                "the virtual machine runs the constant delay only"
            )
        if self.flight and sensor is not None and not sensor.ideal and not self.sensor:
            raise ValueError("a sensor with noise or a bias needs the flight sample with its sensor ports")
        if self.flight:
            memory0 = flight_memory(x0, np.ascontiguousarray(history, dtype=float), self.d)  # type: ignore[assignment]
            constants.append(NO_FLIGHT_OPTIONS if flight_options is None else flight_options)
        if self.sensor:  # the noise of every sample of the chain: noise.c's numbers, as the compiled driver's
            padded = self.blocks(n) * self.block_samples
            noise = np.zeros((padded, STATE_SIZE)) if sensor is None else sensor.noise_rows(0, padded)
            constants.append(np.ascontiguousarray(noise.T))
        out = self.horizon(self.blocks(n), trajectories)(
            x0, memory0, initial_stats(n, settling), self.history_block(history), gain, parameters, *constants
        )
        if not trajectories:
            return self.output(np.asarray(out).ravel(), n, None, None, None, keep_every, workspace, switch_limit)
        stats, measurements, u, switched = (np.asarray(value) for value in out)
        return self.output(stats.ravel(), n, measurements.T, u.T, switched.ravel(), keep_every, workspace, switch_limit)

    @staticmethod
    def output(
        stats: np.ndarray,
        n: int,
        measurements: np.ndarray | None,
        u: np.ndarray | None,
        switched: np.ndarray | None,
        keep_every: int | None,
        workspace: Workspace,
        switch_limit: int,
    ) -> RunOutput:
        """What the compiled engine returns, from whole-horizon arrays."""
        valid = int(stats[S_DIVERGED]) + 1 if stats[S_DIVERGED] >= 0 else n
        indices = None
        if workspace.switched is not None and switched is not None:
            indices = np.flatnonzero(switched[:valid] > 0.5)[:switch_limit]
        kept_m = kept_u = None
        if keep_every is not None and measurements is not None and u is not None:
            kept_m = np.ascontiguousarray(measurements[:n:keep_every])
            kept_u = np.ascontiguousarray(u[:n:keep_every])
        return RunOutput(stats=stats, samples=valid, measurements=kept_m, u=kept_u, switch_indices=indices)

    def horizon(self, blocks: int, trajectories: bool) -> ca.Function:
        """The chain of ``blocks`` blocks as a CasADi Function (for the virtual machine).

        ``horizon(x, memory, stats, history, K, parameters[, J, J_inv]) -> (stats_end[, measurements, u, switched])``.
        """
        key = (blocks, trajectories)
        with self._lock:
            if key not in self._horizons:
                self._horizons[key] = self._build_horizon(blocks, trajectories)
            return self._horizons[key]

    def _build_horizon(self, blocks: int, trajectories: bool) -> ca.Function:
        x = ca.MX.sym("x", STATE_SIZE)
        memory = ca.MX.sym("memory", self.sample.size1_in(1))
        stats = ca.MX.sym("stats", STATS_SIZE)
        history = ca.MX.sym("history", STATE_SIZE, self.history_columns)
        constants = _constant_symbols(self.sample)
        if self.sensor:  # the per-sample noise of the whole horizon, (6, blocks * block_samples)
            constants[-1] = ca.MX.sym("noise", STATE_SIZE, blocks * self.block_samples)
        carry: tuple[Any, ...] = (x, memory, stats, history)
        pieces: list[tuple[Any, ...]] = []
        for b in range(blocks):
            if self.sensor:
                noise = constants[-1][:, b * self.block_samples : (b + 1) * self.block_samples]
                out = self.block(*carry, *constants[:-1], noise)
            else:
                out = self.block(*carry, *constants)
            carry = tuple(out[0:4])
            pieces.append(tuple(out[4:7]))
        outputs = [carry[2]]
        names = ["stats_end"]
        if trajectories:
            outputs += [ca.horzcat(*[piece[i] for piece in pieces]) for i in range(3)]
            names += ["measurements", "u", "switched"]
        return ca.Function(
            "horizon",
            [x, memory, stats, history, *constants],
            outputs,
            ["x", "memory", "stats", "history"] + [self.sample.name_in(i) for i in range(4, self.sample.n_in())],
            names,
        )
