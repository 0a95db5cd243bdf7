"""A vectorised batch engine generated from the same CasADi sample Function as the scalar one.

`emit_lanes` walks the instruction list of a pure SX Function (``casadi.Function.
instructions``) and writes C in which every value is W-wide, one lane per run, so that gcc
vectorises across runs: W runs advance in lockstep through the sample. Each operation is
written as CasADi's own generated C writes it for one scalar (``casadi_sq(x)`` is ``x*x``,
``if_else_zero(c, x)`` is ``c ? x : 0``, comparisons and logic give 1.0 or +0.0), so the
arithmetic of each lane is bit-identical to the scalar engine's: the same IEEE operations in
the same order, ``-ffp-contract=off``, no fast-math; across lanes nothing is reassociated (no
reductions). Selections are bit masks rather than ``?:`` (gcc would sink one arm's arithmetic
into a branch and give up vectorising); comparison results keep their mask for the consumers
in the same loop. ``fmin``/``fmax`` follow the libm's rule for NaNs and for a (+0, -0) tie
(probed at import; C99 leaves the tie to the library, and gcc may swap the arguments of
CasADi's calls, so on a tie the lanes follow the libm with CasADi's argument order; the closed
loop never meets one: its arguments are sums of squares and counters). Operations without a
vector form (``sin``, ``exp``, ``pow``, ...) call the same libm function lane by lane.

Two layouts (``fuse``):

* ``fuse=False``: every work variable of CasADi's register allocation is a ``double w[W]``
  array and every instruction a loop ``for (l = 0; l < W; ++l) w7[l] = (w3[l]*w5[l]);``.
* ``fuse=True`` (default, measured 4x faster): maximal runs of vectorisable instructions are one
  loop over lanes whose body holds the instructions as scalar locals, so the values stay in
  vector registers (the shape of a hand-written structure-of-arrays loop); only values used
  across a libm call go through W-wide arrays.

`LaneEngine` compiles the emitted sample with the horizon driver ``lanes_driver.c``
and runs N runs in batches of W on a thread pool (ctypes releases the GIL); the ports are read
from the Function: an input ``p`` with an output ``p_next`` is carried from sample to sample,
the input ``x_delayed`` is fed m_{k-d} from a ring of the output ``x_meas``, every other input
is a per-lane constant (K, rule parameters, ...), every other output is not computed.

The closed loop comes from `mrpctl.engines.scalar` (``engine_sample`` of
``mrpctl.loop.core_function`` with the run-time inertia: J and J⁻¹ are per-lane constants, so
one library serves every spacecraft of an inertia layout); `simulate_lanes` gives the
statistics rows of `mrpctl.engines.stats`, bit for bit those of the scalar ``Engine.run``,
and ``simulate_batch`` uses it for metrics-only batches. The flight loop
(``mrpctl.loop.flight_core_function``) runs the same way, specialised by structure as the scalar
engine is (`lane_engine` with ``sensor``, ``limited``, ``disturbed``: the union over a
batch's runs of `mrpctl.loop.options.flight_structure`): with a sensor its delayed
input is fed from its ``measurement`` output and its per-sample ``noise`` is a stream shared by
the lanes (one [`noise_rows`][mrpctl.flight.SensorModel.noise_rows] per slice and batch), without one
from ``x_meas`` with no stream; a time-varying delay's newest-arrived schedule is shared per
slice (`closed_loop_batches`).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import hashlib
import importlib.resources
import os
import threading
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from mrpctl import _compile
from mrpctl._validation import available_memory as _available_memory  # patched by tests as lanes._available_memory
from mrpctl._validation import integer
from mrpctl.engines.isa import host_isa_flags
from mrpctl.engines.lane_batches import LaneBatches
from mrpctl.engines.lane_code import LaneProgram, emit_lanes
from mrpctl.engines.lane_streams import (
    OwnStreams,
    lane_newest_arrived,
    lane_reference_rows,
    lane_torque_rows,
    noise_and_torque_rows,
    own_streams,
    tracking_rows,
)
from mrpctl.engines.scalar import delay_label, engine_sample, noise_rows, rule_key
from mrpctl.engines.stats import S_DIVERGED, S_K, initial_stats
from mrpctl.errors import CodegenError, DimensionError, SpecificationError
from mrpctl.flight import NOISE_SIZE, DelayModel, Disturbance, Hysteretic, Saturation, SensorModel, newest_arrived_slice
from mrpctl.flight.steering import SteeringLaw
from mrpctl.flight.tracking import ReferenceStream
from mrpctl.loop import (
    InertiaInput,
    core_function,
    flight_core_function,
    inertia_input,
    inertia_values,
    predictor_core_function,
)
from mrpctl.loop.options import NO_FLIGHT_OPTIONS, flight_structure
from mrpctl.loop.wheels import wheel_core_function
from mrpctl.predictor.controller import PredictorForm
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule
from mrpctl.wheels import WheelCluster

__all__ = [
    "DEFAULT_WIDTH",
    "LaneBatches",
    "LaneEngine",
    "LaneProgram",
    "closed_loop_batches",
    "emit_lanes",
    "host_isa_flags",
    "lane_engine",
    "lane_memory",
    "lane_stats",
    "predictor_lane_engine",
    "simulate_lanes",
    "wheel_lane_engine",
]


#: Lanes per batch: measured on the 60 s DelayAware tumbling batch (bench/vector.py, AVX2 host,
#: CPU time of one core, 256 runs, best of 5): W = 4, 8, 16, 32 gave 777, 731, 751, 745 runs/s
#: (an earlier run with 64 runs: 738, 709, 731, 730), within the noise of a shared machine;
#: 8 lanes are two 4-wide vectors per operation. On the AVX-512 host (one 8-wide vector) W = 8 is the fastest
#: too, with the sample inlined into the horizon loop: W = 4, 8, 16 gave 0.68, 0.90, 0.83x the hand-written
#: loop (bench/lanes_rate.py, median round).
DEFAULT_WIDTH = 8

#: Samples per C call of a lane batch (the scalar engine's slice; a slice of W = 8 lanes of
#: the paper's loop is about 10 ms of one core): Ctrl-C and a stop flag are seen between slices.
SLICE_SAMPLES = 2**16


_DRIVER_FILE = "lanes_driver.c"
_ROLE_CARRIED, _ROLE_DELAYED, _ROLE_CONSTANT, _ROLE_STREAMED, _ROLE_NOISE = 0, 1, 2, 3, 4
_ROLE_MEASUREMENT, _ROLE_DROPPED = 1, 2
#: The keywords of the flight sample's structure (`mrpctl.loop.options.flight_structure`).
_STRUCTURE = ("sensor", "limited", "disturbed")

#: IEEE-exact flags of the lane engine: the simulator's, plus -fno-math-errno (sqrt then
#: vectorises: sqrtpd is correctly rounded like sqrtsd; only errno is not set), pressure-aware
#: scheduling before register allocation (fewer spills of the long lane loop: measured 1.1x;
#: it reorders instructions, never changes one) and no loop splitting: the driver's horizon loop,
#: with the sample inlined, is not copied once for the samples before d and once for those after
#: (one copy: the same speed, half the compile time).
LANE_FLAGS: tuple[str, ...] = (
    *_compile.SIMULATION_FLAGS,
    "-fno-math-errno",
    "-fschedule-insns",
    "-fsched-pressure",
    "-fno-split-loops",
)


def _build_library(code: str, name: str, flags: tuple[str, ...]) -> Path:
    """Compile ``code`` to a cached shared library (`mrpctl._compile.compile_source`)."""
    return _compile.compile_source(code, name, flags=flags)


def _driver_source(name: str = _DRIVER_FILE) -> str:
    return importlib.resources.files("mrpctl.engines").joinpath(name).read_text(encoding="utf-8")


# ------------------------------------------------------------------ the lane engine
class LaneEngine:
    """Runs of one sample Function, W at a time in lockstep (compiled C, a thread pool).

    Parameters
    ----------
    sample : casadi.Function
        The per-sample SX Function. An input ``p`` with an output ``p_next`` is carried from
        sample to sample; ``delayed[0]`` (default ``x_delayed``) is fed the output
        ``delayed[1]`` (default ``x_meas``) of d samples earlier; other inputs are constants
        of each run; other outputs are not computed.
    delay_samples : int
        d >= 0.
    width : int, keyword-only
        W, lanes per batch (default `DEFAULT_WIDTH`).
    fuse, ivdep : bool, keyword-only
        Emitter options (see `emit_lanes`).
    isa : tuple of str, keyword-only
        Vector-ISA flags (default `host_isa_flags`).
    flags : tuple of str, keyword-only
        The other compiler flags (default `LANE_FLAGS`); they must keep IEEE arithmetic.
    delayed : (str, str), keyword-only
        The delayed input and the output that feeds it.
    streamed : sequence of str, keyword-only
        Inputs given per sample and shared by the W lanes (e.g. the flight sample's ``noise``):
        their values of sample k are row k − k0 of the ``stream`` of `LaneBatches.run`
        (the inputs side by side, `stream_size` values a row).
    lane_streamed : sequence of str, keyword-only
        Inputs given per sample and per lane (e.g. each run's own disturbance ``torque``): in the
        same row after the shared ones, nnz × W values each (nonzero j of lane l at j W + l); the
        ``stream`` is then called as ``stream(k0, k1, runs)`` with the W runs of the batch.
    structure : mapping of str to bool, keyword-only
        When ``sample`` is the flight sample: its structure, the keywords ``sensor``, ``limited``,
        ``disturbed`` of [`mrpctl.loop.flight_core_function`][mrpctl.loop.flight_core_function] (kept as `structure`,
        the
        explicit mark of a flight engine); None (default) for any other sample.
    own_streams : bool, keyword-only
        The flight sample with each lane's own sensor noise (its ``noise`` input, when it has one) and seeded
        jitter, drawn and scheduled by the driver (``noise.c`` compiled in; `LaneBatches` with an
        `mrpctl.engines.lane_streams.OwnStreams`).
    """

    def __init__(
        self,
        sample: ca.Function,
        delay_samples: int,
        *,
        width: int = DEFAULT_WIDTH,
        fuse: bool = True,
        ivdep: bool = False,
        isa: tuple[str, ...] | None = None,
        flags: tuple[str, ...] = LANE_FLAGS,
        delayed: tuple[str, str] = ("x_delayed", "x_meas"),
        streamed: Sequence[str] = (),
        lane_streamed: Sequence[str] = (),
        structure: Mapping[str, bool] | None = None,
        own_streams: bool = False,
    ) -> None:
        self.d = integer("delay_samples", delay_samples, minimum=0)
        if structure is not None and set(structure) != set(_STRUCTURE):
            raise SpecificationError(f"structure: expected the keys {list(_STRUCTURE)} but found {sorted(structure)}")
        #: The flight sample's structure (sensor, limited, disturbed), or None for another sample.
        self.structure: dict[str, bool] | None = (
            None if structure is None else {name: bool(structure[name]) for name in _STRUCTURE}
        )
        self.width = integer("width", width, minimum=1)
        self.own_streams = bool(own_streams)
        names_in = [sample.name_in(i) for i in range(sample.n_in())]
        #: The input fed each lane's own noise rows by the driver (own streams), or None.
        self.own_noise = "noise" if self.own_streams and "noise" in names_in else None
        names_out = [sample.name_out(i) for i in range(sample.n_out())]
        delayed_in, measured_out = delayed
        if delayed_in not in names_in or measured_out not in names_out:
            raise SpecificationError(
                f"delayed: {sample.name()} needs an input {delayed_in!r} and an output {measured_out!r}, "
                f"has inputs {names_in} and outputs {names_out}"
            )
        self.measured = sample.nnz_out(names_out.index(measured_out))
        if sample.nnz_in(names_in.index(delayed_in)) != self.measured:
            raise DimensionError(f"{delayed_in} and {measured_out} of {sample.name()} differ in size")
        carried = [name for name in names_in if name + "_next" in names_out]
        every_stream = [*streamed, *lane_streamed]
        unknown = sorted(set(every_stream) - set(names_in))
        if (
            unknown
            or delayed_in in every_stream
            or set(every_stream) & set(carried)
            or set(streamed) & set(lane_streamed)
        ):
            raise SpecificationError(
                f"streamed, lane_streamed: {list(streamed)}, {list(lane_streamed)} must name distinct inputs of "
                f"{sample.name()} that are constants"
            )
        self.carried: dict[str, slice] = {}
        self.constants: dict[str, slice] = {}
        self.streamed: dict[str, slice] = {}
        self.lane_streamed: dict[str, slice] = {}  # offsets in the row; nnz x W values each
        in_role, in_offset, offset_carried, offset_constant, offset_stream = [], [], 0, 0, 0
        shared_size = sum(sample.nnz_in(i) for i, name in enumerate(names_in) if name in streamed)
        offset_lanes = shared_size
        for i, name in enumerate(names_in):
            size = sample.nnz_in(i)
            if name in lane_streamed:
                in_role.append(_ROLE_STREAMED)
                in_offset.append(offset_lanes)
                self.lane_streamed[name] = slice(offset_lanes, offset_lanes + size * self.width)
                offset_lanes += size * self.width
            elif name in streamed:
                in_role.append(_ROLE_STREAMED)
                in_offset.append(offset_stream)
                self.streamed[name] = slice(offset_stream, offset_stream + size)
                offset_stream += size
            elif name in carried:
                if sample.nnz_out(names_out.index(name + "_next")) != size:
                    raise DimensionError(f"{name} and {name}_next of {sample.name()} differ in size")
                in_role.append(_ROLE_CARRIED)
                in_offset.append(offset_carried)
                self.carried[name] = slice(offset_carried, offset_carried + size)
                offset_carried += size
            elif name == delayed_in:
                in_role.append(_ROLE_DELAYED)
                in_offset.append(0)
            elif name == self.own_noise:
                in_role.append(_ROLE_NOISE)
                in_offset.append(0)
            else:
                in_role.append(_ROLE_CONSTANT)
                in_offset.append(offset_constant)
                self.constants[name] = slice(offset_constant, offset_constant + size)
                offset_constant += size
        out_role, out_offset, drop = [], [], []
        for name in names_out:
            if name.endswith("_next") and name[: -len("_next")] in carried:
                out_role.append(_ROLE_CARRIED)
                out_offset.append(self.carried[name[: -len("_next")]].start)
            elif name == measured_out:
                out_role.append(_ROLE_MEASUREMENT)
                out_offset.append(0)
            else:
                out_role.append(_ROLE_DROPPED)
                out_offset.append(0)
                drop.append(name)
        self.carried_size, self.constant_size, self.stream_size = offset_carried, offset_constant, offset_lanes
        program = emit_lanes(
            sample,
            self.width,
            name="mrpctl_lanes_sample_body",
            fuse=fuse,
            drop=drop,
            ivdep=ivdep,
            shared=tuple(streamed),
        )
        header = (
            f"#define MRPCTL_W {self.width}\n#define MRPCTL_N_IN {len(names_in)}\n"
            f"#define MRPCTL_N_OUT {len(names_out)}\n#define MRPCTL_CARRIED {max(offset_carried, 1)}\n"
            f"#define MRPCTL_MEASURED {self.measured}\n"
            f"#define MRPCTL_ROLE_CARRIED {_ROLE_CARRIED}\n#define MRPCTL_ROLE_DELAYED {_ROLE_DELAYED}\n"
            f"#define MRPCTL_ROLE_CONSTANT {_ROLE_CONSTANT}\n#define MRPCTL_ROLE_MEASUREMENT {_ROLE_MEASUREMENT}\n"
            f"#define MRPCTL_ROLE_DROPPED {_ROLE_DROPPED}\n#define MRPCTL_ROLE_STREAMED {_ROLE_STREAMED}\n"
            + (f"#define MRPCTL_ROLE_NOISE {_ROLE_NOISE}\n" if own_streams else "")
            + f"static const int mrpctl_in_role[] = {{{', '.join(map(str, in_role))}}};\n"
            f"static const long long mrpctl_in_offset[] = {{{', '.join(map(str, in_offset))}}};\n"
            f"static const int mrpctl_out_role[] = {{{', '.join(map(str, out_role))}}};\n"
            f"static const long long mrpctl_out_offset[] = {{{', '.join(map(str, out_offset))}}};\n"
        )
        self.program = program
        self.flags = (*flags, *(host_isa_flags() if isa is None else isa))
        code = (
            header
            + (_driver_source("noise.c") if own_streams else "")  # the one generator, for the driver's own streams
            + program.code
            + "#define mrpctl_lanes_sample(arg, res) mrpctl_lanes_sample_body_call(arg, res)\n"
            + _driver_source()
            + (_driver_source("lanes_own.c") if own_streams else "")
        )
        self.library = _build_library(code, f"{sample.name()}_w{self.width}", self.flags)
        self._dll = ctypes.CDLL(str(self.library))
        if self._dll.mrpctl_lanes_width() != self.width:
            raise CodegenError(f"{self.library} was built for {self._dll.mrpctl_lanes_width()} lanes, not {self.width}")
        self._run = self._dll.mrpctl_lanes_run
        self._run.restype = ctypes.c_int
        self._run.argtypes = (
            [ctypes.c_void_p] * 3
            + [ctypes.c_longlong] * 3
            + [ctypes.c_void_p] * 2
            + [ctypes.c_longlong, ctypes.c_void_p]
        )
        if self.own_streams:  # and each lane's noise keys, scales and jitter state
            self._run_own = self._dll.mrpctl_lanes_run_own
            self._run_own.restype = ctypes.c_int
            self._run_own.argtypes = [*self._run.argtypes, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]

    @property
    def history_columns(self) -> int:
        """Columns of the initial history: max(d, 1)."""
        return max(self.d, 1)

    def batch_bytes(self) -> int:
        """Bytes of one batch's work buffers (carried block, constants, history, delay ring)."""
        per_lane = 2 * self.carried_size + self.constant_size + self.measured * (self.d + 1 + self.history_columns)
        return 8 * self.width * per_lane

    def batches(
        self,
        carried: Mapping[str, Any],
        constants: Mapping[str, Any],
        history: Any,
        n: int,
        *,
        threads: int = 1,
        slice_samples: int = SLICE_SAMPLES,
        finished: str | None = None,
        stream: Callable[..., np.ndarray] | np.ndarray | None = None,
        schedule: Callable[..., np.ndarray] | None = None,
        lane_schedule: bool = False,
        own: OwnStreams | None = None,
    ) -> LaneBatches:
        """The N runs packed into batches of W lanes, checked and ready to run (see `run`).

        ``finished`` names a carried nonzero (``"stats[13]"``-style: port and index) that a
        lane sets >= 0 when nothing more of it changes but the sample counter; a batch whose
        lanes all have it stops early (the caller completes the counter).

        ``stream`` gives the streamed inputs (shared by every run): ``stream(k0, k1)`` the
        (k1 − k0, `stream_size`) rows of a slice, or one (`stream_size`,) row for
        every sample; with per-lane streamed inputs ``stream(k0, k1, runs)``, ``runs`` the W run
        indices of the batch (padding lanes repeat its first run). ``schedule(k0, k1,
        newest_before)`` gives the newest arrived measurement j*(k) (int64, in [k − d, k − 1])
        of the samples of a slice under a time-varying delay
        (``newest_before`` is j*(k0 − 1), −1 − d at k0 = 0), shared by every run; None: the
        constant delay d. With ``lane_schedule`` (an engine with ``own_streams``) each lane has
        its own: ``schedule(k0, k1, newest_before, runs)`` gives (k1 − k0, W) values, ``newest_before`` and ``runs``
        (W,) per lane. ``own``: each run's noise and jitter, drawn and scheduled by the driver (an engine with
        ``own_streams``).
        """
        if (own is not None) != self.own_streams or (lane_schedule and own is None):
            raise SpecificationError(
                "own, lane_schedule: an engine with own_streams takes each run's OwnStreams (and only it does)"
            )
        if (self.streamed or self.lane_streamed) and stream is None:
            names = sorted([*self.streamed, *self.lane_streamed])
            raise SpecificationError(f"stream: the inputs {names} are streamed; give their values")
        if self.lane_streamed and not callable(stream):
            raise SpecificationError("stream: per-lane streamed inputs need a function stream(k0, k1, runs)")
        n = integer("n", n, minimum=0)
        slice_samples = integer("slice_samples", slice_samples, minimum=1)
        missing = sorted((set(self.carried) - set(carried)) | (set(self.constants) - set(constants)))
        extra = sorted(set(carried) - set(self.carried)) + sorted(set(constants) - set(self.constants))
        if missing or extra:
            raise SpecificationError(f"lane engine inputs: missing {missing}, unexpected {extra}")
        history_array = np.asarray(history, dtype=float)
        runs = history_array.shape[0] if history_array.ndim == 3 else -1
        shapes = {(runs, self.history_columns, self.measured), (runs, 1, self.measured)}
        if history_array.shape not in shapes or runs < 1:
            raise DimensionError(
                f"history: expected shape (N, {self.history_columns}, {self.measured}) or (N, 1, {self.measured}) "
                f"but found {history_array.shape}"
            )
        per_batch = self.batch_bytes()
        needed = 8 * runs * (2 * self.carried_size + self.constant_size) + min(threads, runs) * per_batch
        available = _available_memory()
        if available is not None and needed > available:
            raise SpecificationError(
                f"the lane engine would need about {needed / 2**30:.1f} GiB ({runs} runs; per thread and batch of "
                f"{self.width} lanes {per_batch / 2**20:.1f} MiB for the delay ring of d + 1 = {self.d + 1} "
                f"samples) but about {available / 2**30:.1f} GiB are available; run fewer runs per call, "
                "fewer threads or fewer lanes"
            )
        full_carried = np.empty((runs, max(self.carried_size, 1)))
        full_constants = np.empty((runs, max(self.constant_size, 1)))
        for target, layout, values in (
            (full_carried, self.carried, carried),
            (full_constants, self.constants, constants),
        ):
            for name, where in layout.items():
                array = np.asarray(values[name], dtype=float)
                if array.shape != (runs, where.stop - where.start):
                    raise DimensionError(
                        f"{name}: expected shape ({runs}, {where.stop - where.start}) but found {array.shape}"
                    )
                target[:, where] = array
        row = None
        if finished is not None:
            port, _, index = finished.partition("[")
            row = self.carried[port].start + int(index.rstrip("]"))
        return LaneBatches(
            self, full_carried, full_constants, history_array, n, slice_samples, row, stream=stream, schedule=schedule,
            lane_schedule=lane_schedule, own=own,
        )  # fmt: skip

    def run(
        self,
        carried: Mapping[str, Any],
        constants: Mapping[str, Any],
        history: Any,
        n: int,
        *,
        threads: int | None = None,
    ) -> dict[str, np.ndarray]:
        """N runs of n samples; the carried values after the last sample, in input order.

        Parameters
        ----------
        carried : mapping of str to array_like
            For each carried input, the (N, nnz) initial values (CasADi's column-major
            nonzero order).
        constants : mapping of str to array_like
            For each constant input, the (N, nnz) values of each run.
        history : array_like
            (N, max(d, 1), nnz of the delayed input): m_{-d}, ..., m_{-1} of each run, or
            (N, 1, nnz) for a history constant in time (not repeated in memory).
        n : int
            Samples.
        threads : int, keyword-only
            Worker threads (default: the CPUs available to this process).

        Returns
        -------
        dict of str to numpy.ndarray
            The (N, nnz) carried values after n samples.
        """
        workers = _threads(threads)
        packed = self.batches(carried, constants, history, n, threads=workers)
        _pool_map(packed.run, packed.count, workers)
        return {name: packed.out[:, where] for name, where in self.carried.items()}


def _threads(threads: int | None) -> int:
    if threads is None:
        return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return integer("threads", threads, minimum=1)


def _pool_map(task: Callable[[int], Any], count: int, threads: int) -> None:
    if threads == 1 or count == 1:
        for b in range(count):
            task(b)
        return
    with ThreadPoolExecutor(max_workers=min(threads, count)) as pool:
        for done in pool.map(task, range(count)):
            del done


# ------------------------------------------------------------------ the closed loop
_ENGINES: dict[tuple[Any, ...], LaneEngine] = {}
_ENGINES_LOCK = threading.Lock()


def lane_engine(
    spacecraft: Spacecraft,
    rule: SwitchingRule,
    d: int,
    period: float,
    substeps: int,
    *,
    width: int = DEFAULT_WIDTH,
    saturation: Saturation = Saturation.SCALE,
    sensor: bool = True,
    limited: bool = True,
    disturbed: bool = True,
    torque_input: bool = False,
    torque_per_lane: bool = False,
    reference_input: bool = False,
    feedforward: bool = False,
    reference_per_lane: bool = False,
    gravity_gradient: bool = False,
    own_streams: bool = False,
    **options: Any,
) -> LaneEngine:
    """The (cached) lane engine of the scalar engine's sample for one structure.

    The structure is the scalar engine's (`mrpctl.engines.scalar.engine`): the
    inertia layout of ``spacecraft`` (J and J⁻¹ are run-time inputs, one per lane), the
    rule's expressions, d, h, substeps (and, for the flight rule
    [`Hysteretic`][mrpctl.flight.Hysteretic], the actuator's ``saturation`` mode and the sample's
    specialisation ``sensor``, ``limited``, ``disturbed`` of
    [`mrpctl.loop.flight_core_function`][mrpctl.loop.flight_core_function]: for a batch, the union over its runs of
    `flight_structure`; default the full sample, which serves
    every run); plus W and the emitter options. The flight sample with a ``sensor`` feeds its
    delayed input from its ``measurement`` output (the sensor's, as the scalar driver's ring
    does) and takes its ``noise`` as a stream shared by the lanes; without one (an ideal sensor)
    it has neither and the delayed input is fed from ``x_meas``. With ``torque_input`` it takes its
    per-sample disturbance ``torque`` (a stream shared by the lanes too; with ``torque_per_lane`` a
    stream of each lane's own torque; ``disturbed`` is then implied). With ``reference_input`` the flight
    sample tracks a reference shared by the lanes (its rows ``reference``, ``reference_error`` streamed
    beside the noise and the torque; ``feedforward``: with the feedforward terms; with ``reference_per_lane``
    each lane's own reference, a per-lane stream). With ``gravity_gradient`` the flight sample's plant flies the
    gravity-gradient torque of the orbit whose constants follow the flight constants (shared or per lane, like
    them; the sample's time from the lane's sample counter). With ``own_streams`` each lane has its own sensor
    noise and seeded jitter, drawn and scheduled by the driver (`LaneEngine`'s ``own_streams``). The keywords are
    ignored for the other rules. The engine's `LaneEngine.structure` is the flight sample's structure.

    Raises
    ------
    CodegenError
        If the sample has an operation without a bit-identical lane form, or the compiler fails.
    """
    layout = inertia_input(spacecraft)
    flight = isinstance(rule, Hysteretic)
    if not flight:
        saturation = Saturation.SCALE
    structure = (
        {"sensor": bool(sensor), "limited": bool(limited), "disturbed": bool(disturbed or torque_input)}
        if flight
        else None
    )
    key: tuple[Any, ...] = (
        layout,
        type(rule),
        rule_key(rule, d),
        d,
        period,
        substeps,
        width,
        saturation,
        None if structure is None else tuple(structure.values()),
        torque_input and flight,
        torque_per_lane and torque_input and flight,
        tuple(sorted(options.items())),
    )
    tracking = flight and reference_input
    key += (("tracking", feedforward) + (("lanes",) if reference_per_lane else ()),) if tracking else ()
    gravity = flight and gravity_gradient
    key += ("gravity",) if gravity else ()  # without it the key of before
    own = bool(flight and own_streams)
    key += ("own streams",) if own else ()
    with _ENGINES_LOCK:
        found = _ENGINES.get(key)
        if found is None:
            label = f"{type(rule).__name__.lower()}_{delay_label(d)}_s{substeps}_{layout.value}"
            if structure is not None:
                core = flight_core_function(
                    spacecraft,
                    d,
                    period,
                    substeps,
                    inertia=layout,
                    saturation=saturation,
                    torque_input=torque_input,
                    sensor=structure["sensor"],
                    limited=structure["limited"],
                    disturbed=structure["disturbed"],
                    reference_input=tracking,
                    feedforward=tracking and feedforward,
                    settling_output=tracking,  # the scalar engine's statistics of the true error (its bits)
                    gravity_gradient=gravity,
                )
                label += f"_{saturation.value}" + ("" if structure["sensor"] else "_ideal")
                label += ("" if structure["limited"] else "_unlimited") + ("" if structure["disturbed"] else "_free")
                label += ("_torque" if torque_input else "") + ("_lanes" if torque_input and torque_per_lane else "")
                label += ("_tracking" + ("_ff" if feedforward else "")) if tracking else ""
                label += "_lanes" if tracking and reference_per_lane else ""
                label += "_gravity" if gravity else ""
                label += "_own" if own else ""
                noise = ("noise",) if structure["sensor"] and not own else ()
                rows = ("reference", "reference_error") if tracking else ()
                shared_rows, lane_rows = ((), rows) if reference_per_lane else (rows, ())
                options = {
                    "delayed": ("x_delayed", "measurement" if structure["sensor"] else "x_meas"),
                    "streamed": ((*noise, "torque") if torque_input and not torque_per_lane else noise) + shared_rows,
                    "lane_streamed": (("torque",) if torque_input and torque_per_lane else ()) + lane_rows,
                    "own_streams": own,
                    "structure": structure,
                    **options,
                }
            else:
                core = core_function(spacecraft, rule, d, period, substeps, inertia=layout)
            sample = engine_sample(core, d, f"mrpctl_lanes_{label}")
            found = LaneEngine(sample, d, width=width, **options)
            _ENGINES[key] = found
        return found


def wheel_lane_engine(
    spacecraft: Spacecraft,
    d: int,
    period: float,
    substeps: int,
    *,
    wheels: WheelCluster,
    width: int = DEFAULT_WIDTH,
    sensor: bool = True,
    disturbed: bool = True,
    torque_input: bool = False,
    torque_per_lane: bool = False,
    law: SteeringLaw | None = None,
    own_streams: bool = False,
) -> LaneEngine:
    """The (cached) lane engine of the flight sample on a wheel cluster
    ([`wheel_core_function`][mrpctl.loop.wheels.wheel_core_function]; J and the cluster are constants of the
    library), the ports as the flight sample's in `lane_engine` (structure ``limited=False``: the limits are the
    wheels'). Its runs' memories start with `mrpctl.loop.wheels.wheel_memory`. ``law``: the steering law's body
    torque request, as `mrpctl.engines.scalar.wheel_engine`'s (one library per law); None: the PD law. With
    ``own_streams`` each lane has its own sensor noise and seeded jitter, drawn and scheduled by the driver, as
    `lane_engine`'s (`LaneEngine`'s ``own_streams``; one more library per structure).

    Raises
    ------
    CodegenError
        If the sample has an operation without a bit-identical lane form, or the compiler fails.
    """
    disturbed = bool(disturbed or torque_input)
    structure = {"sensor": bool(sensor), "limited": False, "disturbed": disturbed}
    key: tuple[Any, ...] = (
        "wheels",
        wheels.key(),
        spacecraft.inertia.tobytes(),
        d,
        period,
        substeps,
        width,
        tuple(structure.values()),
        torque_input,
        torque_per_lane and torque_input,
    )
    key += () if law is None else (law,)  # without a law the key of before
    own = bool(own_streams)
    key += ("own streams",) if own else ()  # without own streams the key of before
    with _ENGINES_LOCK:
        found = _ENGINES.get(key)
        if found is None:
            core = wheel_core_function(
                spacecraft, wheels, d, period, substeps, sensor=structure["sensor"], disturbed=disturbed,
                torque_input=torque_input, law=law,
            )  # fmt: skip
            digest = hashlib.sha256(repr(key[1:3]).encode()).hexdigest()[:12]
            label = f"hysteretic_wheels{wheels.count}_{digest}_{delay_label(d)}_s{substeps}"
            label += ("" if structure["sensor"] else "_ideal") + ("" if disturbed else "_free")
            label += ("_torque" if torque_input else "") + ("_lanes" if torque_input and torque_per_lane else "")
            label += "" if law is None else "_" + law.label()
            label += "_own" if own else ""
            noise = ("noise",) if structure["sensor"] and not own else ()
            found = LaneEngine(
                engine_sample(core, d, f"mrpctl_lanes_{label}"),
                d,
                width=width,
                delayed=("x_delayed", "measurement" if structure["sensor"] else "x_meas"),
                streamed=(*noise, "torque") if torque_input and not torque_per_lane else noise,
                lane_streamed=("torque",) if torque_input and torque_per_lane else (),
                structure=structure,
                own_streams=own,
            )
            _ENGINES[key] = found
        return found


def predictor_lane_engine(
    spacecraft: Spacecraft,
    model: InertiaInput,
    d: int,
    period: float,
    substeps: int,
    *,
    width: int = DEFAULT_WIDTH,
    saturation: Saturation = Saturation.SCALE,
    sensor: bool = False,
    limited: bool = True,
    torque_input: bool = False,
    torque_per_lane: bool = False,
    own_streams: bool = False,
    form: PredictorForm = PredictorForm.NONLINEAR,
) -> LaneEngine:
    """The (cached) lane engine of the predictor sample (`mrpctl.loop.predictor_core_function`) of the scalar
    engine's structure: the plant's inertia layout (J, J⁻¹ per lane), the model's layout ``model`` (τ, J_m, J_m⁻¹
    per lane, in each run's ``flight`` constants: `mrpctl.loop.options.predictor_constants`), d, h, substeps,
    ``saturation``, ``sensor`` (a sensor given: a ``noise`` stream shared by the lanes, or each lane's own with
    ``own_streams``), ``limited`` (an actuator given) and ``torque_input`` (a per-sample torque, shared or with
    ``torque_per_lane`` each lane's own); ``form``: the predictor's. Its delayed input is fed from the ``ring``
    output, (m_k, z_k): the history of the measurements and of the model copy's states; its
    `LaneEngine.structure` is (``sensor``, ``limited``, disturbed), the constant w being always in the sample.

    Raises
    ------
    CodegenError
        If the sample has an operation without a bit-identical lane form, or the compiler fails.
    """
    layout = inertia_input(spacecraft)
    own = bool(own_streams and sensor)
    per_lane = bool(torque_per_lane and torque_input)
    key: tuple[Any, ...] = ("predictor", layout, model, d, period, substeps, width, saturation)
    key += (bool(sensor), bool(limited), bool(torque_input), per_lane, own)
    key += ("linear",) if form is PredictorForm.LINEAR else ()
    with _ENGINES_LOCK:
        found = _ENGINES.get(key)
        if found is None:
            core = predictor_core_function(
                spacecraft, d, period, substeps, inertia=layout, model_inertia=model, saturation=saturation,
                sensor=bool(sensor), limited=bool(limited), torque_input=bool(torque_input), form=form,
            )  # fmt: skip
            label = f"onpredicted_{delay_label(d)}_s{substeps}_{layout.value}_{saturation.value}_model_{model.value}"
            label += ("_sensor" if sensor else "") + ("" if limited else "_unlimited")
            label += ("_torque" if torque_input else "") + ("_lanes" if per_lane else "") + ("_own" if own else "")
            label += "_linear" if form is PredictorForm.LINEAR else ""
            noise = ("noise",) if sensor and not own else ()
            found = LaneEngine(
                engine_sample(core, d, f"mrpctl_lanes_{label}"),
                d,
                width=width,
                delayed=("x_delayed", "ring"),
                streamed=(*noise, "torque") if torque_input and not per_lane else noise,
                lane_streamed=("torque",) if per_lane else (),
                structure={"sensor": bool(sensor), "limited": bool(limited), "disturbed": True},
                own_streams=own,
            )
            _ENGINES[key] = found
        return found


def closed_loop_batches(
    engine: LaneEngine,
    x0: np.ndarray,
    memory0: np.ndarray,
    history: np.ndarray,
    gains: np.ndarray,
    parameters: np.ndarray,
    n: int,
    *,
    spacecraft: Spacecraft | Sequence[Spacecraft],
    threads: int = 1,
    slice_samples: int = SLICE_SAMPLES,
    flight_options: np.ndarray | None = None,
    sensor: SensorModel | Sequence[SensorModel | None] | None = None,
    delay: DelayModel | Sequence[DelayModel | None] | None = None,
    rate: float = 1.0,
    disturbance: Disturbance | Sequence[Disturbance] | None = None,
    reference: ReferenceStream | Sequence[ReferenceStream] | None = None,
    settling: tuple[float, float] | None = None,
) -> LaneBatches:
    """The closed-loop runs packed for `LaneBatches.run` (arguments as `simulate_lanes`);
    read the statistics with `lane_stats` once every batch has run.

    For the flight sample (an engine of `lane_engine` with a `structure`):
    ``memory0`` is (N, FLIGHT_MEMORY_SIZE) (`mrpctl.loop.options.flight_memory`
    of each run), ``flight_options`` the shared run-time constants (u_max (3), u_norm, w (3),
    gyro bias (3); default none), ``sensor`` the shared noise
    ([`SensorModel.noise_rows`][mrpctl.flight.SensorModel.noise_rows]
    of each slice, the numbers the scalar engine gets) and ``delay`` a shared time-varying
    delay at ``rate`` (Hz), whose newest-arrived schedule is computed per slice
    ([`newest_arrived_slice`][mrpctl.flight.newest_arrived_slice]), as in ``Engine.run``. ``flight_options`` may
    also be (N, 10), one row per run. ``disturbance``: a per-sample torque shared by the runs (an
    engine with a ``torque`` stream), its rows of each slice ([`samples`][mrpctl.flight.Disturbance.samples])
    streamed beside the noise; or one per-sample torque per run (an engine with a per-lane ``torque``
    stream: `lane_engine` with ``torque_per_lane``), each batch's lanes streamed their own rows.
    The engine's structure must serve every run (`flight_structure`
    of ``flight_options`` and ``sensor``, the union over the rows): a run with a limit, a torque w,
    a noisy sensor or a gyro bias on an engine specialised without it is refused
    (SpecificationError), as its numbers would not be the scalar engine's. ``reference``: a reference
    shared by the runs (an engine of `lane_engine` with ``reference_input``), its two blocks of rows of each
    slice ([`ReferenceStream.rows`][mrpctl.flight.tracking.ReferenceStream.rows]) streamed after the noise and
    the torque, or one per run (an engine with per-lane reference streams: ``reference_per_lane``); ``memory0``
    then holds each run's σ_B/R at k = 0 (`mrpctl.engines.scalar.tracking_memory`). An engine with ``own_streams`` takes
    ``sensor`` one per run and ``delay`` one per run or shared (None: the constant delay d), each lane's noise and
    jitter drawn and scheduled by the driver (a given sequence: each lane's schedule from `lane_newest_arrived`);
    another engine may take ``delay`` one per run too (each lane its own schedule, computed per slice).
    """
    runs = len(x0)
    crafts = (spacecraft,) * runs if isinstance(spacecraft, Spacecraft) else tuple(spacecraft)
    if len(crafts) != runs:
        raise DimensionError(f"spacecraft: expected 1 or {runs} entries (one per run) but found {len(crafts)}")
    constants = {
        "K": np.asarray(gains).transpose(0, 2, 1).reshape(runs, -1),  # column-major 3 x 6, as Engine.run
        "parameters": np.reshape(parameters, (runs, -1)),
    }
    if "J" in engine.constants:
        where = engine.constants["J"]
        layout = InertiaInput.DIAGONAL if where.stop - where.start == 3 else InertiaInput.FULL
        inertia = np.empty((runs, 2, where.stop - where.start))
        cache: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for i, craft in enumerate(crafts):
            values = cache.get(id(craft))
            if values is None:
                if inertia_input(craft) is not layout:  # the scalar engine of craft has the other layout
                    raise SpecificationError(
                        f"spacecraft[{i}]: this lane engine takes a {layout.value} inertia, got {craft}"
                    )
                values = cache[id(craft)] = inertia_values(craft, layout)
            inertia[i, 0], inertia[i, 1] = values[0].ravel(), values[1].ravel()  # column-major, as Engine.run
        constants["J"], constants["J_inv"] = inertia[:, 0], inertia[:, 1]
    stream: Callable[..., np.ndarray] | np.ndarray | None = None
    schedule: Callable[..., np.ndarray] | None = None
    own: OwnStreams | None = None
    structure = engine.structure
    if structure is not None:
        options = NO_FLIGHT_OPTIONS if flight_options is None else np.asarray(flight_options, dtype=float)
        constants["flight"] = np.broadcast_to(options, (runs, options.shape[-1]))
        sensors = tuple(sensor) if isinstance(sensor, Sequence) else None
        if engine.own_streams != (sensors is not None) or len(sensors or [None] * runs) != runs:
            raise SpecificationError(f"sensor: a lane engine with own_streams takes one sensor per run ({runs})")
        if sensors is not None:  # the structure's sensor: any noisy one (the biases are in the options rows)
            sensor = next((one for one in sensors if one is not None and not one.ideal), None)
            delays = tuple(delay) if isinstance(delay, Sequence) else (delay,) * runs
            own = own_streams(sensors, delays, rate, engine.d, noise=engine.own_noise is not None)
            delay = None if own.jitter_keys is not None or all(one is None for one in delays) else list(delays)
        assert sensor is None or isinstance(sensor, SensorModel)
        needed = flight_structure(options, sensor)  # the union over the rows
        missing = [name for name, used in needed.items() if used and not structure[name]]
        if missing:
            raise SpecificationError(
                f"flight_options, sensor: the runs need a lane engine with {', '.join(f'{m}=True' for m in missing)} "
                f"(lane_engine's structure: the union of flight_structure over the runs), this one has {structure}"
            )
        # the zero row at every sample (no noise, as Engine.run); none without a sensor and a shared torque
        stream = np.zeros(engine.stream_size) if engine.stream_size else None
        noisy = sensors is None and sensor is not None and (sensor.attitude_noise > 0.0 or sensor.rate_noise > 0.0)
        noise_columns = NOISE_SIZE if structure["sensor"] and sensors is None else 0  # own noise: not streamed
        per_lane = "torque" in engine.lane_streamed
        if ("torque" in engine.streamed or per_lane) != (disturbance is not None):
            raise SpecificationError("disturbance: a per-sample torque needs a lane engine with a torque stream")
        own_reference = "reference" in engine.lane_streamed
        if ("reference" in engine.streamed or own_reference) != (reference is not None):
            raise SpecificationError("reference: a tracked reference needs a lane engine with a reference stream")
        if own_reference:
            references = tuple(reference) if isinstance(reference, Sequence) else ()
            torques = tuple(disturbance) if per_lane and isinstance(disturbance, Sequence) else None
            if len(references) != runs or (per_lane and (torques is None or len(torques) != runs)):
                raise DimensionError(f"reference: this lane engine takes one reference per run ({runs})")
            shared_torque = disturbance if isinstance(disturbance, Disturbance) else None
            stream = functools.partial(
                lane_reference_rows,
                sensor if noisy else None,
                noise_columns,
                shared_torque,
                torques,
                references,
                rate,
                engine.width,
            )
        elif isinstance(reference, ReferenceStream):
            if per_lane:
                raise SpecificationError("reference: a shared reference with per-run torques is not supported")
            torque = disturbance if isinstance(disturbance, Disturbance) else None
            stream = functools.partial(tracking_rows, sensor if noisy else None, noise_columns, torque, reference, rate)
        elif reference is not None:
            raise SpecificationError("reference: this lane engine takes one shared reference")
        elif per_lane:
            torques = tuple(disturbance) if isinstance(disturbance, Sequence) else ()
            if len(torques) != runs or not all(isinstance(w, Disturbance) for w in torques):
                raise DimensionError(f"disturbance: this lane engine takes one Disturbance per run ({runs})")
            stream = functools.partial(
                lane_torque_rows, sensor if noisy else None, noise_columns, torques, rate, engine.width
            )
        elif isinstance(disturbance, Disturbance):
            stream = functools.partial(
                noise_and_torque_rows, sensor if noisy else None, noise_columns, disturbance, rate
            )
        elif sensor is not None and noisy:
            stream = functools.partial(noise_rows, sensor)
        if isinstance(delay, Sequence):
            if len(delay) != runs or own is None:
                raise DimensionError(f"delay: one delay model per run ({runs}) needs a lane engine with own_streams")
            schedule = functools.partial(lane_newest_arrived, tuple(delay), rate, engine.d)
        elif delay is not None:
            schedule = functools.partial(newest_arrived_slice, delay, rate, engine.d)
    elif flight_options is not None or sensor is not None or delay is not None:
        raise SpecificationError("flight_options, sensor, delay: this lane engine does not run the flight sample")
    return engine.batches(
        {"x": x0, "memory": np.reshape(memory0, (runs, -1)), "stats": np.tile(initial_stats(n, settling), (runs, 1))},
        constants,
        np.asarray(history).transpose(0, 2, 1),
        n,
        threads=threads,
        slice_samples=slice_samples,
        finished=f"stats[{S_DIVERGED}]",
        stream=stream,
        schedule=schedule,
        lane_schedule=isinstance(delay, Sequence),
        own=own,
    )


def lane_stats(batches: LaneBatches) -> np.ndarray:
    """The (N, STATS_SIZE) statistics after every batch ran, as the scalar ``Engine.run`` gives them.

    The scalar driver stops a run after its diverging sample; a lane goes on to the horizon
    (or its batch stops early) with every statistic frozen but the sample counter, which is
    set to the scalar driver's count: the diverging sample's index + 1.
    """
    stats = batches.out[:, batches.engine.carried["stats"]].copy()
    diverged = stats[:, S_DIVERGED] >= 0
    stats[diverged, S_K] = stats[diverged, S_DIVERGED] + 1.0
    return stats


def lane_memory(batches: LaneBatches) -> np.ndarray:
    """The (N, memory size) rule memories after every batch ran, as the scalar ``Engine.run``'s
    ``RunOutput.memory`` (frozen from the diverging sample on, as the scalar driver stops there)."""
    return batches.out[:, batches.engine.carried["memory"]].copy()


def simulate_lanes(
    engine: LaneEngine,
    x0: np.ndarray,
    memory0: np.ndarray,
    history: np.ndarray,
    gains: np.ndarray,
    parameters: np.ndarray,
    n: int,
    *,
    spacecraft: Spacecraft | Sequence[Spacecraft],
    threads: int | None = None,
) -> np.ndarray:
    """The stats (N, STATS_SIZE) of N runs of the closed loop, bit for bit the scalar ``Engine.run``'s.

    Parameters
    ----------
    engine : LaneEngine
        From `lane_engine`.
    x0 : numpy.ndarray
        (N, 6) initial states x = [σ; ω/4] (ω in rad/s).
    memory0 : numpy.ndarray
        (N,) initial rule memories.
    history : numpy.ndarray
        (N, 6, max(d, 1)) initial history blocks m_{-d}, ..., m_{-1} as columns, or (N, 6, 1)
        for a history constant in time.
    gains : numpy.ndarray
        (N, 3, 6) gains K (N m).
    parameters : numpy.ndarray
        (N, P) rule parameters.
    n : int
        Samples.
    spacecraft : Spacecraft or sequence of Spacecraft, keyword-only
        The plant, or one per run (of the engine's inertia layout; J, J⁻¹ in kg m² are
        per-lane inputs).
    threads : int, keyword-only
        Worker threads.
    """
    workers = _threads(threads)
    packed = closed_loop_batches(
        engine, x0, memory0, history, gains, parameters, n, spacecraft=spacecraft, threads=workers
    )
    _pool_map(packed.run, packed.count, workers)
    return lane_stats(packed)
