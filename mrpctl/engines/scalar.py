"""The compiled engine: one sample as generated C, and a horizon driver run slice by slice.

One sample (`engine_sample`) is the loop's core sample ([`mrpctl.loop.core_function`][mrpctl.loop.core_function])
plus the divergence guard and the metric accumulators, a pure SX Function with K, the rule
parameters (and, for a run-time inertia, J and J⁻¹) as inputs. CasADi generates its C
code; ``scalar_driver.c`` (package data) is appended and the whole is compiled by
`mrpctl._compile`, cached on disk. A run is a few C calls, one per slice of
`SLICE_SAMPLES` samples, so that Ctrl-C is seen between slices; the driver stops at
the first divergence.

Engines are cached in-process by the *structure* they compile: the inertia layout
(diagonal or full; J and J⁻¹ are run-time inputs), d, h, substeps and the rule's
expressions with symbolic parameters (so every instance of a built-in rule shares one
engine whatever its ε, while a user's rule whose attributes enter its expressions as
constants gets its own).
"""

from __future__ import annotations

import ctypes
import functools
import hashlib
import threading
from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._compile import (
    SIMULATION_FLAGS,
    CompiledFunction,
    address,
    compile_function,
)
from mrpctl.engines.common import RunOutput, Workspace
from mrpctl.engines.libm import inline_min_max
from mrpctl.engines.scalar_source import driver_source, settling_tail_function
from mrpctl.engines.stats import (
    DIVERGENCE_BOUND,
    S_COUNT,
    S_DIVERGED,
    S_FIRST,
    S_FLIPS,
    S_K,
    S_LAST,
    S_MAX_SIGMA,
    S_N,
    S_PEAK_TORQUE,
    S_SET_CHANGES,
    S_SETTLE_OMEGA,
    S_SETTLE_SIGMA,
    S_UNSETTLED,
    S_UPREV,
    STATS_SIZE,
    initial_stats,
)
from mrpctl.engines.vm import VirtualMachineEngine
from mrpctl.errors import CodegenError, SpecificationError
from mrpctl.flight import (
    FLIGHT_MEMORY_SIZE,
    NOISE_SIZE,
    STREAM_ATTITUDE,
    STREAM_JITTER,
    STREAM_RATE,
    DelayKind,
    DelayModel,
    Disturbance,
    Hysteretic,
    NoiseForm,
    Saturation,
    SensorModel,
    newest_arrived_slice,
    rotation_mrp_function,
    short_expr,
    stream_key,
)
from mrpctl.flight.steering import SteeringLaw
from mrpctl.flight.tracking import (
    ErrorTime,
    ReferenceStream,
    tracking_error_expr,
)
from mrpctl.loop import (
    InertiaInput,
    core_function,
    flight_core_function,
    inertia_input,
    inertia_values,
    predictor_core_function,
)
from mrpctl.loop.functions import true_error_function
from mrpctl.loop.options import NO_FLIGHT_OPTIONS, flight_memory, predictor_memory
from mrpctl.loop.wheels import wheel_core_function, wheel_memory, wheel_memory_roots
from mrpctl.model import INPUT_SIZE, ORBIT_SIZE, STATE_SIZE
from mrpctl.predictor.controller import PredictorForm
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import (
    MEMORY_SIZE,
    PARAMETER_SIZE,
    BoundaryLayer,
    DelayAware,
    NoSwitching,
    OnCurrent,
    OnDelayed,
    SwitchingRule,
)
from mrpctl.wheels import WheelCluster

__all__ = [
    "SLICE_SAMPLES",
    "STATE_BLOCK",
    "Engine",
    "clear_engines",
    "delay_label",
    "engine",
    "engine_sample",
    "noise_rows",
    "rule_key",
    "short_history",
    "slice_samples",
    "tracking_memory",
    "wheel_engine",
]

#: Samples per C call: Ctrl-C and the batch's stop flag are seen between slices (about
#: 10 ms of the paper's loop per slice at one substep; divided by the substeps).
SLICE_SAMPLES = 2**16
STATE_BLOCK = STATE_SIZE + MEMORY_SIZE + STATS_SIZE  # x, memory, stats: the driver's carried state


@functools.lru_cache(maxsize=1)
def _short_function() -> ca.Function:
    sigma = ca.SX.sym("sigma", 3)
    return ca.Function("short", [sigma], [short_expr(sigma)])


@functools.lru_cache(maxsize=1)
def _error_function() -> ca.Function:
    sigma = ca.SX.sym("sigma", 3)
    sigma_r = ca.SX.sym("sigma_r", 3)
    error = tracking_error_expr(sigma, ca.DM.zeros(3), sigma_r, ca.DM.zeros(3))[0]
    return ca.Function("error", [sigma, sigma_r], [error])


def tracking_memory(sigma_seen: np.ndarray, reference: ReferenceStream) -> np.ndarray:
    """σ̃_prev of the tracking sample at k = 0: σ_B/R of the σ̃ the controller sees at k = 0 (the regulation
    memory's, [`flight_memory`][mrpctl.loop.options.flight_memory]) against the reference row it uses at k = 0
    (through the sample's own SX: its bits)."""
    return np.asarray(_error_function()(np.asarray(sigma_seen, float), reference.first()[0:3])).ravel()


def short_history(history: np.ndarray) -> np.ndarray:
    """The history rows (columns, 6) with σ in the short set, through the flight sample's own SX (same bits).

    The compiled flight sample without a sensor reads its delayed measurement as it is (``short_measurements``
    of [`flight_core_function`][mrpctl.loop.flight_core_function]); this is the short set its controller took of a
    history
    row before: [`short_expr`][mrpctl.flight.short_expr] evaluated by CasADi's SX machine, operation by
    operation the IEEE operations of the generated C (-0 becomes +0 there too).
    """
    rows = np.array(history, dtype=float)
    rows[:, 0:3] = np.asarray(_short_function().map(rows.shape[0])(rows[:, 0:3].T)).T
    return rows


_NO_NOISE = np.zeros(NOISE_SIZE)
#: The scalar flight engine with a sensor computes the attitude noise's MRP in the driver (NoiseForm.MRP); False:
#: in the sample (the A/B of bench/flight.py)
_ROTATION_IN_DRIVER = True


def noise_rows(sensor: SensorModel, k0: int, k1: int) -> np.ndarray:
    """[`SensorModel.noise_rows`][mrpctl.flight.SensorModel.noise_rows] (k1 − k0, 6): the rows the engines read,
    drawn by the C code of ``noise.c`` (the one generator: [`mrpctl.flight.streams`][mrpctl.flight.streams])."""
    return sensor.noise_rows(k0, k1)


def slice_samples(substeps: int) -> int:
    """Samples per slice for ``substeps`` RK4 substeps (the work per slice stays about the same)."""
    return max(1, SLICE_SAMPLES // substeps)


def delay_label(d: int) -> str:
    """The delay's part of a compiled sample's name: ``d0`` for d = 0, ``dn`` for every d > 0.

    The drivers take d at run time (ring size and indices), and the samples' SX depends on d through
    d > 0 only (m_{k−d} read, or m_k itself), so one library serves every d > 0; where a sample's
    expressions hold d itself (``DelayAware``'s count, the lagged statistics, a user's rule) its code, and so
    its library's hash, differ by d.
    """
    return "d0" if d == 0 else "dn"


def engine_sample(
    core: ca.Function, d: int, name: str = "engine_sample", *, frozen_memory: bool = True, stats_first: bool = False
) -> ca.Function:
    """The core sample plus the divergence guard and the metric accumulators (pure SX).

    ``sample(x, memory, stats, x_delayed, K, parameters[, J, J_inv]) ->
    (x_next, memory_next, stats_next, x_meas, u, switched)``; J, J⁻¹ when ``core`` has them.
    ``frozen_memory``: the memory stays as it was once a sample is not counted (past the horizon, after
    the divergence), as the lanes and the virtual machine's padded chunks need; the scalar driver never
    runs such a sample, so its flight samples (ten memory entries) leave the guard out: the same memory
    on every sample it runs. A core with an input ``counted`` (the wheel sample) freezes its memory itself: it is
    fed 1.0 when the sample counts, else 0.0 (with ``frozen_memory``; 1.0 without, a constant that CasADi folds
    away), and its ``memory_next`` is taken as it is.
    ``stats_first``: the outputs start with stats_next (then x_next, memory_next, ...),
    which orders the generated code (CasADi sorts it depth first from the outputs in turn): the controller
    (the switch count and the torque), then the statistics' true error, then RK4 (the divergence test), so
    that the work off the plant's serial path comes before the integration that waits for the torque; the same
    operations, the same bits (the scalar driver's tracking samples: ``MRPCTL_STATS_FIRST``).
    A core whose statistics lag (its output ``tracking_settling_lagged``: those of sample k − d) gives the sample a
    last input ``delay``, d, which the scalar driver feeds from its own d: one library for every d >= 1.
    """
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", core.size1_in(1))  # MEMORY_SIZE; FLIGHT_MEMORY_SIZE for the flight sample
    stats = ca.SX.sym("stats", STATS_SIZE)
    x_delayed = ca.SX.sym("x_delayed", core.size1_in(2))  # STATE_SIZE; PREDICTOR_RING_WIDTH for the predictor
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    # the core's inputs after the parameters are the sample's, but for the sample index (a gravity-gradient
    # sample's time t_k = k h), which is the statistics' sample counter k, and the wheel sample's ``counted``
    ports = [i for i in range(5, core.n_in()) if core.name_in(i) not in ("sample_index", "counted")]
    extra = [ca.SX.sym(core.name_in(i), core.sparsity_in(i)) for i in ports]
    fed: dict[int, Any] = dict(zip(ports, extra, strict=True))
    self_frozen = "counted" in core.name_in()
    if self_frozen:
        counting = ca.logic_and(stats[S_K] < stats[S_N], stats[S_DIVERGED] < 0) if frozen_memory else ca.DM(1.0)
        fed[core.name_in().index("counted")] = counting
    outs = core(x, memory, x_delayed, gain, parameters, *(fed.get(i, stats[S_K]) for i in range(5, core.n_in())))
    x_raw, memory_rule, x_meas, u, switched = outs[0:5]
    more, more_names = list(outs[5:]), [core.name_out(i) for i in range(5, core.n_out())]  # the flight measurement
    settling_state = x_meas  # tracking: the true error [σ_B/R; ω_B/R/4] at t_k, for the settling statistics
    settling = None  # or what the statistics take of it: (|σ_B/R|², ω_B/R in rad/s)
    if "tracking_error" in more_names:
        settling_state = more.pop(more_names.index("tracking_error"))
        more_names.remove("tracking_error")
    lagged = False  # the statistics are those of sample k − d (the controller's error is its true error)
    for output in ("tracking_settling", "tracking_settling_lagged"):
        if output in more_names:
            settling = more.pop(more_names.index(output))
            more_names.remove(output)
            lagged = output == "tracking_settling_lagged"

    k = stats[S_K]
    counted = counting if self_frozen and frozen_memory else ca.logic_and(k < stats[S_N], stats[S_DIVERGED] < 0)
    # the sample whose true error the statistics take: k, or k − d (from k = d on; the last d at the run's end),
    # d a last input ``delay`` that the driver feeds (one library for every d >= 1: the same IEEE k − d)
    delay = ca.SX.sym("delay") if lagged else None
    settled_index, settled_counted = (k - delay, ca.logic_and(counted, k >= delay)) if lagged else (k, counted)
    sigma_raw, omega_raw = x_raw[0:3], 4 * x_raw[3:6]
    bound = DIVERGENCE_BOUND**2
    # NaN compares false, so a NaN or inf state is "not ok".
    ok = ca.logic_and(ca.dot(sigma_raw, sigma_raw) <= bound, ca.dot(omega_raw, omega_raw) <= bound)
    x_next = ca.if_else(ca.logic_and(counted, ok), x_raw, x_meas)
    memory_next = ca.if_else(counted, memory_rule, memory) if frozen_memory and not self_frozen else memory_rule
    switch_counted = ca.logic_and(counted, switched > 0)

    if settling is None:
        sigma, omega = settling_state[0:3], 4 * settling_state[3:6]
        sigma_squared = ca.dot(sigma, sigma)
    else:
        sigma_squared, omega = settling[0], settling[1:4]
    # the tolerances are run-time constants carried in the statistics (default SETTLING_SIGMA², SETTLING_OMEGA²)
    unsettled = ca.logic_or(sigma_squared >= stats[S_SETTLE_SIGMA], ca.dot(omega, omega) >= stats[S_SETTLE_OMEGA])
    # the plant's σ replaced by its shadow at this sample (by the rule, or by the flight loop's bookkeeping)
    set_changed = ca.logic_or(ca.logic_or(x_meas[0] != x[0], x_meas[1] != x[1]), x_meas[2] != x[2])
    u_prev = stats[S_UPREV]
    flips = stats[S_FLIPS] + ca.if_else(ca.logic_and(counted, u * u_prev < 0), 1.0, 0.0)
    # max |u_i| by comparisons: casadi_fmax is a libm call per use (no -ffinite-math-only)
    size = [ca.fabs(u[i]) for i in range(INPUT_SIZE)]
    torque = ca.if_else(size[0] >= size[1], size[0], size[1])
    torque = ca.if_else(torque >= size[2], torque, size[2])
    peak = stats[S_PEAK_TORQUE]
    stats_next = ca.vertcat(
        k + 1,
        stats[S_N],
        stats[S_COUNT] + ca.if_else(switch_counted, 1.0, 0.0),
        ca.if_else(ca.logic_and(switch_counted, stats[S_FIRST] < 0), k, stats[S_FIRST]),
        ca.if_else(switch_counted, k, stats[S_LAST]),
        flips,
        ca.if_else(counted, u, u_prev),
        ca.if_else(ca.logic_and(settled_counted, unsettled), settled_index, stats[S_UNSETTLED]),
        ca.if_else(settled_counted, ca.fmax(stats[S_MAX_SIGMA], sigma_squared), stats[S_MAX_SIGMA]),  # max |σ|²
        ca.if_else(ca.logic_and(counted, ca.logic_not(ok)), k, stats[S_DIVERGED]),
        ca.if_else(ca.logic_and(counted, torque > peak), torque, peak),  # max |u|_inf
        stats[S_SETTLE_SIGMA],
        stats[S_SETTLE_OMEGA],
        stats[S_SET_CHANGES] + ca.if_else(ca.logic_and(counted, set_changed), 1.0, 0.0),
    )
    first = [stats_next, x_next, memory_next] if stats_first else [x_next, memory_next, stats_next]
    first_names = ["stats_next", "x_next", "memory_next"] if stats_first else ["x_next", "memory_next", "stats_next"]
    return ca.Function(
        name,
        [x, memory, stats, x_delayed, gain, parameters, *extra, *([] if delay is None else [delay])],
        [*first, x_meas, u, switched, *more],
        ["x", "memory", "stats", "x_delayed", "K", "parameters"]
        + [core.name_in(i) for i in ports]
        + ([] if delay is None else ["delay"]),
        [*first_names, "x_meas", "u", "switched", *more_names],
    )


class Engine:
    """The compiled engine of one structure (inertia layout, d, h, rule expressions, substeps).

    J and J⁻¹ are run-time inputs, so one library serves every spacecraft of the same
    [`InertiaInput`][mrpctl.loop.InertiaInput] layout (diagonal, or full).
    """

    def __init__(
        self,
        spacecraft: Spacecraft,
        rule: SwitchingRule,
        d: int,
        period: float,
        substeps: int,
        saturation: Saturation = Saturation.SCALE,
        predictor: InertiaInput | None = None,
        sensor: bool = False,
        limited: bool = True,
        disturbed: bool = True,
        torque_input: bool = False,
        reference_input: bool = False,
        feedforward: bool = False,
        *,
        wheels: WheelCluster | None = None,
        law: SteeringLaw | None = None,
        gravity_gradient: bool = False,
        lagged_settling: bool = False,
        predictor_form: PredictorForm = PredictorForm.NONLINEAR,
    ) -> None:
        self.d = d
        self.lagged_settling = lagged_settling
        self.wheels = wheels
        self.reference_input = reference_input
        self.substeps = substeps
        self.inertia = inertia_input(spacecraft)
        self.predictor = predictor is not None
        self.flight = isinstance(rule, Hysteretic) or self.predictor
        self._structure = (spacecraft, d, period, substeps, saturation, limited, disturbed)
        self.torque_input = torque_input and self.flight
        self._squared_peak = self.flight and not self.predictor and limited  # squared_peak of the flight sample
        self._sensor = sensor
        self._law = law
        self.gravity_gradient = gravity_gradient
        if gravity_gradient and (wheels is not None or predictor is not None or not self.flight):
            raise SpecificationError(
                "gravity_gradient: the gravity-gradient torque is flown by the flight sample only "
                "(rule=Hysteretic(...), no predictor, no wheel cluster)"
            )
        if wheels is not None:
            if not isinstance(rule, Hysteretic) or predictor is not None:
                raise SpecificationError("wheels: the wheel cluster flies with rule=Hysteretic(...) only")
            self._squared_peak = False
            core = wheel_core_function(
                spacecraft,
                wheels,
                d,
                period,
                substeps,
                sensor=sensor,
                disturbed=disturbed,
                records=True,
                torque_input=torque_input,
                noise_form=NoiseForm.MRP if sensor and _ROTATION_IN_DRIVER else NoiseForm.ROTATION_VECTOR,
                short_measurements=not sensor,
                law=law,
            )
        elif predictor is not None:
            core = predictor_core_function(
                spacecraft,
                d,
                period,
                substeps,
                inertia=self.inertia,
                model_inertia=predictor,
                saturation=saturation,
                sensor=sensor,
                limited=limited,
                torque_input=self.torque_input,
                records=True,
                form=predictor_form,
                **({"reference_input": True, "feedforward": feedforward} if reference_input else {}),
            )
        elif self.flight:
            core = flight_core_function(
                spacecraft,
                d,
                period,
                substeps,
                inertia=self.inertia,
                saturation=saturation,
                sensor=sensor,
                limited=limited,
                disturbed=disturbed,
                records=True,
                torque_input=torque_input,
                # with a sensor the driver turns each block of theta rows into their MRPs (the same SX, compiled
                # into this library), so that tan's latency is not on the sample's path
                noise_form=NoiseForm.MRP if sensor and _ROTATION_IN_DRIVER else NoiseForm.ROTATION_VECTOR,
                short_measurements=not sensor,  # run() hands the driver a short history (short_history)
                # run() takes the square root of the peak |u_c|² at the end; with limits only, where the
                # actuator's |u_c| is a root too (measured: 15 instructions fewer with limits, 5-10 more without)
                squared_peak=limited,
                **(
                    {
                        "reference_input": True,
                        "feedforward": feedforward,
                        "settling_output": True,
                        "lagged_settling": lagged_settling,
                    }
                    if reference_input
                    else {}
                ),
                law=law,
                gravity_gradient=gravity_gradient,
            )
        else:
            core = core_function(spacecraft, rule, d, period, substeps, inertia=self.inertia)
        self.memory_size = core.size1_in(1)
        self.ring_width = core.size1_in(2)
        label = f"{type(rule).__name__.lower()}_{delay_label(d)}_s{substeps}_{self.inertia.value}"
        if self.flight:
            label += f"_{saturation.value}"
        if wheels is not None:
            digest = hashlib.sha256(repr((wheels.key(), spacecraft.inertia.tobytes())).encode()).hexdigest()[:12]
            label += f"_wheels{wheels.count}_{digest}" + ("" if sensor else "_ideal") + ("" if disturbed else "_free")
            label += "_torque" if torque_input else ""
            label += "" if law is None else "_" + law.label()
        elif predictor is not None:
            label += f"_model_{predictor.value}" + ("_sensor" if sensor else "") + ("" if limited else "_unlimited")
            label += "_torque" if self.torque_input else ""
            label += ("_tracking" + ("_ff" if feedforward else "")) if reference_input else ""
            label += "_linear" if predictor_form is PredictorForm.LINEAR else ""
        elif self.flight:
            label += ("" if sensor else "_ideal") + ("" if limited else "_unlimited") + ("" if disturbed else "_free")
            label += "_torque" if torque_input else ""
            label += ("_tracking" + ("_ff" if feedforward else "")) if reference_input else ""
            label += "" if law is None else "_" + law.label()
            label += "_gravity" if gravity_gradient else ""
            label += "_lagged" if lagged_settling else ""
        # the scalar driver runs counted samples only: the flight samples drop the memory guard
        # the flight tracking sample: the statistics take (|σ_B/R|², ω_B/R) of the true error, the driver forms the
        # true σ_B/R of the kept records only, and the code is ordered controller, statistics, RK4 (stats_first)
        tracked = reference_input and self.flight and not self.predictor and wheels is None
        self.sample = engine_sample(
            core, d, f"mrpctl_sample_{label}", frozen_memory=not self.flight, stats_first=tracked
        )
        min_max_flags, min_max_source = inline_min_max()  # fmax/fmin inlined, the libm's results
        rotation = None
        if self.flight and not self.predictor and sensor and _ROTATION_IN_DRIVER:
            theta = ca.SX.sym("rotation_noise", 3)
            rotation = ca.Function(self.sample.name() + "_rotation", [theta], [rotation_mrp_function()(theta)])
        true_error = None
        if tracked:
            true_error = true_error_function(self.sample.name() + "_true_error")
        tail = settling_tail_function(self.sample.name() + "_tail") if lagged_settling else None
        self.record_width = (
            (self.sample.size1_out("record") + (0 if true_error is None else true_error.size1_out(0)))
            if "record" in self.sample.name_out()
            else 0
        )
        self.compiled: CompiledFunction = compile_function(
            self.sample,
            flags=(*SIMULATION_FLAGS, *min_max_flags),
            appendix=driver_source(self.sample, rotation, true_error, tail) + min_max_source,
            others=tuple(f for f in (rotation, true_error, tail) if f is not None),
        )
        self._run_c: Any = None
        self._true_error_c: Any = None
        if self.compiled.compiled:
            self._library = ctypes.CDLL(str(self.compiled.library))
            self._run_c = getattr(self._library, self.sample.name() + "_run")
            self._run_c.restype = ctypes.c_longlong
            self._run_c.argtypes = (
                [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_longlong]
                + [ctypes.c_void_p] * 8
                + [ctypes.c_longlong, ctypes.c_void_p, ctypes.c_void_p]
                + [ctypes.c_void_p] * 4
                + [ctypes.c_longlong] * 3
                + [ctypes.c_void_p, ctypes.c_longlong, ctypes.c_longlong]
                + [ctypes.c_void_p] * 4
            )
            if true_error is not None:  # the controller's memory at k = 0 (tracking_memory, compiled)
                self._true_error_c = getattr(self._library, true_error.name() + "_one")
                self._true_error_c.restype = ctypes.c_int
                self._true_error_c.argtypes = [ctypes.c_void_p] * 3
            if tail is not None:
                self._tail_c: Any = getattr(self._library, tail.name() + "_run")
                self._tail_c.restype = ctypes.c_longlong
                self._tail_c.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_longlong, ctypes.c_void_p]
                self._tail_c.argtypes += [ctypes.c_longlong] * 2

    def virtual_machine_sample(self) -> ca.Function:
        """The sample for the virtual machine: the flight sample with the sensor ports of this structure,
        without the records and the torque input."""
        if not self.flight:
            return self.sample
        if self.wheels is not None:
            raise CodegenError("the wheel loop needs the compiled engine (a C compiler); see mrpctl._compile")
        if self.predictor:
            raise CodegenError("the predictor loop needs the compiled engine (a C compiler); see mrpctl._compile")
        spacecraft, d, period, substeps, saturation, limited, disturbed = self._structure
        core = flight_core_function(
            spacecraft,
            d,
            period,
            substeps,
            inertia=self.inertia,
            saturation=saturation,
            sensor=self._sensor,
            limited=limited,
            disturbed=disturbed,
            law=self._law,
            gravity_gradient=self.gravity_gradient,
        )
        return engine_sample(core, d, self.sample.name() + "_vm")

    @property
    def compiled_code(self) -> bool:
        """True when runs call the compiled library."""
        return self._run_c is not None

    def _tracking_memory(self, sigma_seen: np.ndarray, reference: ReferenceStream) -> np.ndarray:
        """[`tracking_memory`][mrpctl.engines.scalar.tracking_memory] by this library's true error (the same SX
        compiled: its bits, without a call into CasADi's virtual machine); the predictor's through CasADi."""
        if self._true_error_c is None:
            return tracking_memory(sigma_seen, reference)
        x_meas = np.zeros(STATE_SIZE)
        x_meas[0:3] = sigma_seen
        row = reference.first()
        out = np.empty(3)
        if self._true_error_c(address(x_meas), address(row), address(out)):
            raise CodegenError(f"evaluation of the compiled engine {self.compiled.library} failed")
        return out

    def ring_size(self, n: int) -> int:
        """Columns of the measurement ring: m_{k−d} is read back for k >= d only."""
        return min(self.d, n) + 1

    def workspace(self, n: int, switches: bool) -> Workspace:
        """Buffers for runs of n samples (``switches``: collect switch instants)."""
        return Workspace(
            state=np.empty(STATE_SIZE + self.memory_size + STATS_SIZE),
            ring=np.empty((self.ring_size(n), self.ring_width)),
            switched=np.empty(min(slice_samples(self.substeps), n)) if switches else None,
        )

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
        sensor: SensorModel | None = None,
        delay: DelayModel | None = None,
        rate: float = 1.0,
        disturbance: Disturbance | None = None,
        reference: ReferenceStream | None = None,
        settling: tuple[float, float] | None = None,
    ) -> RunOutput:
        """One run of n samples, slice by slice.

        Parameters
        ----------
        spacecraft : Spacecraft
            The run's spacecraft (of this engine's inertia layout; its J, J⁻¹ are inputs).
        history : numpy.ndarray
            (columns, 6) measurements m_{−d}, …: one column (a constant history) or d.
        keep_every : int or None
            Keep m_k and u_k for k = 0, k, 2k, …; None keeps nothing.
        workspace : Workspace
            From `workspace` (its ``switched`` buffer set when switch instants are wanted).
        switch_limit : int
            Keep at most this many switch indices (the count in the statistics stays exact).
        stop : callable, optional
            Called after each slice with the samples done; True stops the run (it then
            returns what it has). KeyboardInterrupt raised by it propagates.
        flight_options : numpy.ndarray, optional
            The flight sample's constants (u_max (3), u_norm, w (3)); default
            `NO_FLIGHT_OPTIONS`. Ignored by the other engines.
        sensor : SensorModel, optional
            The flight sample's noise: the driver draws θ_k, η_k of every sample itself
            (``noise.c``, from the seed's stream keys and the two 1σ; the bits of
            [`SensorModel.noise`][mrpctl.flight.SensorModel.noise]); its gyro bias is in ``flight_options``. None: no
            noise.
        delay, rate : DelayModel, float, optional
            A time-varying delay (d_max = this engine's d, d_min >= 1) at ``rate`` (Hz): seeded
            jitter is drawn and scheduled by the driver (O(1) a sample); for a given sequence the
            newest-arrived index j*(k) of each slice is computed in NumPy
            ([`newest_arrived_slice`][mrpctl.flight.newest_arrived_slice]) and handed to the driver.
        disturbance : Disturbance, optional
            A per-sample torque (engine built with ``torque_input``): the rows of each slice
            ([`samples`][mrpctl.flight.Disturbance.samples]) are handed to the driver.
        reference : ReferenceStream, optional
            A tracked reference (engine built with ``reference_input``): the rows of each slice
            ([`ReferenceStream.rows`][mrpctl.flight.tracking.ReferenceStream.rows]) are handed to the driver.
        """
        if self.reference_input != (reference is not None):
            raise ValueError("a reference needs an engine with a reference input, and only it")
        # (the engine's structure is an ideal sensor's: m_k = x_meas whatever sensor model the run names)
        if self.lagged_settling and (
            delay is not None or reference is None or reference.error_time is not ErrorTime.MEASUREMENT
        ):
            raise ValueError(
                "this engine folds the controller's error as the true error of t_{k-d}: a fixed delay and the "
                "measurement-time error only"
            )
        if self.torque_input != (disturbance is not None and not disturbance.constant):
            raise ValueError("a per-sample disturbance needs an engine with a torque input, and only it")
        state = workspace.state
        history = np.ascontiguousarray(history, dtype=float)
        memory_end = STATE_SIZE + self.memory_size
        state[:STATE_SIZE] = x0
        if self.predictor:
            state[STATE_SIZE:memory_end] = predictor_memory(x0)
            if reference is not None:  # the previous σ̂ is the error σ_B/R of the prediction z_0 at k = 0
                state[STATE_SIZE + 2 : STATE_SIZE + 5] = tracking_memory(
                    state[STATE_SIZE + 2 : STATE_SIZE + 5], reference
                )
            history = np.ascontiguousarray(np.hstack((history, history)))  # (m, z) with z = m before t = 0
        else:
            if self.wheels is not None:
                state[STATE_SIZE:memory_end] = wheel_memory(flight_memory(x0, history, self.d), self.wheels)
            else:
                state[STATE_SIZE:memory_end] = flight_memory(x0, history, self.d) if self.flight else memory0
            if reference is not None:  # the controller's previous MRP is the error σ_B/R it sees at k = 0
                state[STATE_SIZE + 2 : STATE_SIZE + 5] = self._tracking_memory(
                    state[STATE_SIZE + 2 : STATE_SIZE + 5], reference
                )
            if self.flight and not self._sensor:  # the sample reads m_{k-d} as it is: a history row must be short
                history = np.ascontiguousarray(short_history(history))
        state[memory_end:] = initial_stats(n, settling)
        history_stride = self.ring_width if history.shape[0] > 1 else 0
        gain_cm = np.ascontiguousarray(gain.T)  # column-major 3 x 6
        parameters = np.ascontiguousarray(parameters, dtype=float)
        if inertia_input(spacecraft) is not self.inertia:
            raise ValueError(f"this engine takes a {self.inertia.value} inertia, got {spacecraft}")
        inertia, inertia_inverse = inertia_values(spacecraft, self.inertia)
        options = np.ascontiguousarray(NO_FLIGHT_OPTIONS if flight_options is None else flight_options, dtype=float)
        if self.flight and "flight" in self.sample.name_in() and options.size != self.sample.nnz_in("flight"):
            raise ValueError(
                f"flight_options: this engine takes {self.sample.nnz_in('flight')} flight constants (with the orbit's "
                f"{ORBIT_SIZE} when it flies the gravity gradient), got {options.size}"
            )
        if keep_every is None:
            measurements = u = None
            keep = 0
        else:
            kept = (n - 1) // keep_every + 1
            measurements = np.empty((kept, STATE_SIZE))
            u = np.empty((kept, INPUT_SIZE))
            keep = keep_every
        records = delay_used = None
        if "record" in self.sample.name_out() and keep:
            records = np.empty((kept, self.record_width))
            delay_used = np.full(kept, self.d, dtype=np.int64)
        switched = workspace.switched
        indices: list[np.ndarray] = []
        stored = 0
        ring = workspace.ring
        noise, noise_key = _NO_NOISE[0:2], np.zeros(2, dtype=np.uint64)  # the driver draws the noise itself
        if "noise" in self.sample.name_in() and sensor is not None:
            noise = np.array([sensor.attitude_noise, sensor.rate_noise])
            keys = [stream_key(sensor.seed, STREAM_ATTITUDE), stream_key(sensor.seed, STREAM_RATE)]
            noise_key = np.array(keys, dtype=np.uint64)
        jitter: np.ndarray | None = None  # seeded jitter: the driver draws the delays and schedules
        if delay is not None and delay.kind is DelayKind.JITTER:
            low, high = delay.bounds(rate)
            if high != self.d or low < 1:
                raise ValueError(f"jitter in [{low}, {high}] periods: the engine needs d_min >= 1, d_max = {self.d}")
            jitter = np.empty(3 + self.d + 1, dtype=np.int64)
            jitter[0:3] = (np.uint64(stream_key(delay.seed, STREAM_JITTER)).view(np.int64), low, -1 - self.d)
        if self.predictor and flight_options is None:
            raise ValueError("the predictor engine needs its constants (predictor_constants)")
        if keep == 1 and measurements is not None and self.ring_width == STATE_SIZE and not self.flight:
            ring = measurements  # every sample kept: m_{k-d} is read back from the result (no copy)
        step = slice_samples(self.substeps)
        newest = -1 - self.d
        schedule: np.ndarray | None = None
        k = 0
        reference_rows: tuple[np.ndarray, np.ndarray, int] | None = None
        # (held, the run's n when the driver folds the last d samples' statistics (lagged), set to 1 when it did,
        # 1 when the driver checks the rows of an unchecked array as it reads them, the first bad row or -1)
        unchecked = reference is not None and reference.unchecked
        control = np.array([0, n if self.lagged_settling else -1, 0, int(unchecked), -1], dtype=np.int64)
        diverged = memory_end + S_DIVERGED
        while k < n:
            k1 = min(k + step, n)
            torque, torque_stride = _NO_NOISE, 0
            if self.torque_input:
                assert disturbance is not None
                torque, torque_stride = np.ascontiguousarray(disturbance.samples(k, k1, rate)), INPUT_SIZE
            # the error-time rows in place: the driver holds row 0 for the samples whose error time is before t = 0
            reference_rows = None if reference is None else reference.held_rows(k, k1)
            if reference_rows is not None:
                control[0] = reference_rows[2]
            if delay is not None and jitter is None:  # a given sequence: j*(k) of the slice from NumPy
                schedule = newest_arrived_slice(delay, rate, self.d, k, k1, newest)
                newest = int(schedule[-1])
            done = self._run_c(
                address(state),
                address(history),
                history_stride,
                address(gain_cm),
                address(parameters),
                address(inertia),
                address(inertia_inverse),
                address(options) if self.flight else None,
                address(noise),
                noise_key.ctypes.data,
                address(torque),
                torque_stride,
                None if reference_rows is None else address(reference_rows[0]),
                None if reference_rows is None else address(reference_rows[1]),
                None if reference_rows is None else control.ctypes.data,
                None if schedule is None else schedule.ctypes.data,
                None if jitter is None else jitter.ctypes.data,
                None if delay_used is None else delay_used.ctypes.data,
                k,
                k1,
                self.d,
                address(ring),
                len(ring),
                keep,
                None if measurements is None else address(measurements),
                None if u is None else address(u),
                None if switched is None else address(switched),
                None if records is None else address(records),
            )
            if done < 0:
                raise CodegenError(f"evaluation of the compiled engine {self.compiled.library} failed")
            if control[4] >= 0:  # a bad row: the reference's error (the first bad row of the whole array)
                assert reference is not None
                reference.check_rows()
                raise SpecificationError(f"{reference.name}: row {int(control[4])} is not finite or not short")
            if switched is not None and stored < switch_limit:
                found = np.flatnonzero(switched[:done] > 0.5)[: switch_limit - stored] + k
                if found.size:
                    indices.append(found)
                    stored += found.size
            k += done
            if stop is not None and stop(k):
                break
            if state[diverged] >= 0:
                break  # the driver stopped after the diverging sample
        if unchecked:  # the rows from the last sample run on (the driver checked those before)
            assert reference is not None
            reference.check_rows(k)
        if self.lagged_settling and reference is not None and not control[2]:  # the last d samples' statistics
            # (the driver folded them when the run ended in its last call with their rows in its slice)
            low = max(k - self.d, 0)
            rows = np.ascontiguousarray(reference.rows(low, k)[0]) if k > low else np.zeros((1, 9))
            stats = state[memory_end:]
            if self._tail_c(address(stats), address(ring), len(ring), address(rows), low, k) < 0:
                raise CodegenError(f"evaluation of the compiled engine {self.compiled.library} failed")
        switch_indices = np.concatenate(indices) if indices else np.zeros(0, np.int64)
        memory = state[STATE_SIZE:memory_end].copy()
        if self._squared_peak:  # the sample kept the peak |u_c|²
            memory[FLIGHT_MEMORY_SIZE - 1] = np.sqrt(memory[FLIGHT_MEMORY_SIZE - 1])
        elif self.wheels is not None:  # the wheel sample kept the peaks |u_c|² and |Gs diag(Js) Ω|²
            memory = wheel_memory_roots(memory)
        return RunOutput(
            stats=state[memory_end:].copy(),
            samples=k,
            measurements=measurements,
            u=u,
            switch_indices=switch_indices if switched is not None else None,
            memory=memory,
            records=records,
            delay_used=delay_used,
        )


#: The rules of `mrpctl.switching`: their expressions depend on their values only
#: through `parameters` (a run-time input), so
#: all instances of one of these classes share an engine.
_BUILT_IN_RULES = (NoSwitching, OnCurrent, OnDelayed, BoundaryLayer, DelayAware)


def rule_key(rule: SwitchingRule, d: int) -> Any:
    """What distinguishes the engines of rules: the class for a built-in rule, else a
    digest of the rule's expressions with symbolic parameters (about 5 ms; memoised per
    rule value when the rule is hashable)."""
    if type(rule) in _BUILT_IN_RULES or type(rule) is Hysteretic:
        return type(rule)
    try:
        hash(rule)
    except TypeError:
        return _expressions_digest(rule, d)
    return _memoised_digest(rule, d)


@functools.lru_cache(maxsize=1024)
def _memoised_digest(rule: SwitchingRule, d: int) -> str:
    return _expressions_digest(rule, d)


def _expressions_digest(rule: SwitchingRule, d: int) -> str:
    x = ca.SX.sym("x", STATE_SIZE)
    x_meas = ca.SX.sym("x_meas", STATE_SIZE)
    memory = ca.SX.sym("memory", MEMORY_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    out = rule.expressions(x, x_meas, memory, delay_samples=d, parameters=parameters)
    function = ca.Function("rule", [x, x_meas, memory, parameters], list(out))
    return hashlib.sha256(function.serialize().encode()).hexdigest()


_ENGINES: dict[tuple[Any, ...], Any] = {}
_ENGINES_LOCK = threading.Lock()


def engine(
    spacecraft: Spacecraft,
    rule: SwitchingRule,
    d: int,
    period: float,
    substeps: int,
    saturation: Saturation = Saturation.SCALE,
    *,
    predictor: Spacecraft | None = None,
    sensor: bool = False,
    limited: bool = True,
    disturbed: bool = True,
    torque_input: bool = False,
    reference_input: bool = False,
    feedforward: bool = False,
    law: SteeringLaw | None = None,
    gravity_gradient: bool = False,
    lagged_settling: bool = False,
    predictor_form: PredictorForm = PredictorForm.NONLINEAR,
) -> Any:
    """The engine of this structure (compiled, or the virtual machine's without a compiler), cached.

    ``saturation`` (the actuator's mode) is part of the structure of the flight and predictor
    samples only. ``predictor``: the controller's model (its inertia layout is part of the
    structure, its values are run-time inputs) for the predictor sample, with a sensor port when
    ``sensor``, the actuator when ``limited`` and a per-sample ``torque`` input when ``torque_input``; the
    predictor needs a C compiler. The flight
    sample (``rule`` a [`Hysteretic`][mrpctl.flight.Hysteretic]) is specialised the same way, with a
    sensor port when ``sensor``, the actuator when ``limited`` and the disturbance add when
    ``disturbed`` (`flight_structure` of a run's constants; one library per structure). ``law``: the flight
    sample's steering law ([`SteeringLaw`][mrpctl.flight.steering.SteeringLaw]; its numbers are compiled in,
    one library per law); None: the PD law. ``gravity_gradient``: the flight sample's plant flies the
    gravity-gradient torque of an orbit whose constants follow the flight constants
    ([`flight_core_function`][mrpctl.loop.flight_core_function]); without it the library of before.
    ``lagged_settling``: a tracking flight sample with an ideal sensor, d >= 1, the measurement-time error and a
    fixed delay takes the statistics of sample k − d from the controller's own error (no true error formed at
    t_k; the last d samples' at the end of the run); its runs refuse anything else. ``predictor_form``: the
    predictor sample's form ([`PredictorForm`][mrpctl.predictor.PredictorForm]; one library per form).
    """
    model = None if predictor is None else inertia_input(predictor)
    flight = isinstance(rule, Hysteretic)
    if not flight and model is None:
        saturation = Saturation.SCALE
    if model is None:
        if not flight:
            sensor, limited, disturbed, torque_input = False, True, True, False
        key: tuple[Any, ...] = (
            inertia_input(spacecraft),
            type(rule),
            rule_key(rule, d),
            d,
            period,
            substeps,
            saturation,
        ) + ((sensor, limited, disturbed, torque_input) if flight else ())
        key += (("tracking", feedforward),) if flight and reference_input else ()  # else the key of before
        key += () if law is None or not flight else (law,)  # without a law the key of before
        key += ("gravity",) if gravity_gradient and flight else ()  # without it the key of before
        lagged_settling = bool(lagged_settling and flight and reference_input and not sensor and d >= 1)
        key += ("lagged",) if lagged_settling else ()
    else:
        key = (inertia_input(spacecraft), "predictor", model, sensor, limited, d, period, substeps, saturation)
        key += ("torque",) if torque_input else ()  # without it the key (and the library) of before
        key += (("tracking", feedforward),) if reference_input else ()
        key += ("linear",) if predictor_form is PredictorForm.LINEAR else ()  # the default: the key of before
    with _ENGINES_LOCK:
        found = _ENGINES.get(key)
        if found is None:
            found = Engine(
                spacecraft,
                rule,
                d,
                period,
                substeps,
                saturation,
                predictor=model,
                sensor=sensor,
                limited=limited,
                disturbed=disturbed,
                torque_input=torque_input,
                reference_input=bool(reference_input and (flight or model is not None)),
                feedforward=bool(feedforward and reference_input and (flight or model is not None)),
                law=law if flight else None,
                gravity_gradient=bool(gravity_gradient),
                lagged_settling=lagged_settling and model is None,
                predictor_form=predictor_form,
            )
            if not found.compiled_code:  # no C compiler: the same sample in CasADi's virtual machine
                found = VirtualMachineEngine(found.virtual_machine_sample(), d, found.inertia, flight=found.flight)
            _ENGINES[key] = found
        return found


def wheel_engine(
    spacecraft: Spacecraft,
    rule: SwitchingRule,
    d: int,
    period: float,
    substeps: int,
    *,
    wheels: WheelCluster,
    sensor: bool = False,
    disturbed: bool = True,
    torque_input: bool = False,
    law: SteeringLaw | None = None,
) -> Engine:
    """The compiled engine of the flight sample on a wheel cluster, cached
    ([`wheel_core_function`][mrpctl.loop.wheels.wheel_core_function]; J and the cluster are constants of the
    library, so one library per spacecraft inertia and cluster). ``law``: the steering law's body torque request
    (its numbers compiled in, one library per law); None: the PD law. Needs a C compiler (CodegenError without)."""
    key: tuple[Any, ...] = (
        "wheels",
        wheels.key(),
        spacecraft.inertia.tobytes(),
        d,
        period,
        substeps,
        sensor,
        disturbed,
        torque_input,
    )
    key += () if law is None else (law,)  # without a law the key of before
    with _ENGINES_LOCK:
        found = _ENGINES.get(key)
        if found is None:
            found = Engine(
                spacecraft,
                rule,
                d,
                period,
                substeps,
                sensor=sensor,
                limited=False,
                disturbed=disturbed,
                torque_input=torque_input,
                wheels=wheels,
                law=law,
            )
            if not found.compiled_code:
                raise CodegenError(
                    "wheels: the wheel cluster needs the compiled engine (a C compiler: gcc or cc, or CC)"
                )
            _ENGINES[key] = found
        return found


def clear_engines() -> None:
    """Forget the loaded engines (the on-disk cache stays); for benchmarks and tests."""
    with _ENGINES_LOCK:
        _ENGINES.clear()
