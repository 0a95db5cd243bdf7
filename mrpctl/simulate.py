"""The closed loop with sampled delayed feedback and shadow-set switching, compiled to C.

The model (paper Eq. nonc, sampled; see ``design/switching.md``)::

    ẋ(t) = A x + B u(t) + f(x),   x = [σ; ω/4]
    u(t) = u_k = K m_{k−d}          for t in [t_k, t_{k+1}),  t_k = k h,  h = 1/rate
    m_k  = rule(x(t_k), m_{k−d})    the state after the switching rule at t_k

with τ = d h (d an integer >= 0). At each sample k: (1) the rule may replace σ_k by its
shadow; (2) the result is recorded as the measurement m_k; (3) u_k = K m_{k−d} is held
over one period (zero-order hold; for d = 0, u_k = K m_k); (4) the plant of
:func:`mrpctl.model.dynamics_expr` is integrated over one period by RK4 with a fixed
number of substeps. For k − d < 0 the measurements come from the history: ``"constant"``
(m = x0, the paper's initial function φ(θ) = x0), ``"zero-input"`` (m = 0, hence u = 0
until the first measurement arrives and no rule fires on it) or a (d, 6) array
m_{−d}, …, m_{−1} given by the user.

Engine: one sample is a pure SX Function (with the divergence guard and the metric
accumulators: switch count, torque sign flips, settling, max |σ|, divergence); CasADi
generates its C code, to which a fixed loop over the whole horizon is appended, compiled
by :mod:`mrpctl._compile` and cached on disk: a run is one C call. Without a compiler a
block of about 500 samples (a ``mapaccum`` of chunks of d samples, method of steps),
expanded to SX, is chained in CasADi's virtual machine.
"""

from __future__ import annotations

import ctypes
import logging
import math
import os
import threading
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._compile import SIMULATION_FLAGS, CompiledFunction, address, compile_function
from mrpctl._validation import finite_array, nonnegative_scalar, positive_scalar, readonly
from mrpctl.errors import CodegenError, DimensionError, SpecificationError
from mrpctl.model import INPUT_SIZE, STATE_SIZE, gain_matrix, plant_model
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import MEMORY_SIZE, PARAMETER_SIZE, SwitchingRule

__all__ = [
    "DIVERGENCE_BOUND",
    "HISTORY_KINDS",
    "SETTLING_OMEGA",
    "SETTLING_SIGMA",
    "BatchResult",
    "ClosedLoopFunctions",
    "SimulationResult",
    "closed_loop_functions",
    "delay_samples",
    "simulate",
    "simulate_batch",
]

logger = logging.getLogger(__name__)

#: Settling: |σ| below this (dimensionless) ...
SETTLING_SIGMA = 1e-2
#: ... and |ω| below this (rad/s), from the settling time to the end of the run.
SETTLING_OMEGA = 1e-3
#: A run is stopped and flagged diverged when |σ| or |ω| (rad/s) exceeds this or is not finite.
DIVERGENCE_BOUND = 1e6
#: The history names accepted by :func:`simulate` (or give a (d, 6) array).
HISTORY_KINDS = ("constant", "zero-input")

_BLOCK_TARGET = 500  # samples per compiled block (a whole number of chunks)
_DELAY_TOLERANCE = 1e-9

# Layout of the statistics vector accumulated in the generated code.
_S_K, _S_N, _S_COUNT, _S_FIRST, _S_LAST = 0, 1, 2, 3, 4
_S_FLIPS = slice(5, 8)
_S_UPREV = slice(8, 11)
_S_UNSETTLED, _S_MAX_SIGMA, _S_DIVERGED = 11, 12, 13
_STATS_SIZE = 14


# =============================================================================== inputs
def delay_samples(tau: Any, rate: Any) -> int:
    """d = τ · rate as an integer (τ in s, rate in Hz).

    Raises
    ------
    SpecificationError
        If τ < 0, rate <= 0, or τ · rate is not an integer to 1e-9.
    """
    tau = nonnegative_scalar("tau", tau)
    rate = positive_scalar("rate", rate)
    samples = tau * rate
    d = round(samples)
    if abs(samples - d) > _DELAY_TOLERANCE:
        raise SpecificationError(
            f"tau * rate must be a whole number of measurement periods: tau = {tau!r} s and "
            f"rate = {rate!r} Hz give tau * rate = {samples!r}; choose tau as a multiple of 1/rate"
        )
    return int(d)


def _rule(rule: Any) -> SwitchingRule:
    if not isinstance(rule, SwitchingRule):
        raise SpecificationError(
            f"rule must be a switching rule such as mrpctl.switching.OnDelayed(), got {type(rule).__name__}: {rule!r}"
        )
    return rule


def _spacecraft(spacecraft: Any) -> Spacecraft:
    if not isinstance(spacecraft, Spacecraft):
        raise SpecificationError(f"spacecraft must be a mrpctl.Spacecraft, got {type(spacecraft).__name__}")
    return spacecraft


def _substeps(substeps: Any) -> int:
    if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer) or substeps < 1:
        raise SpecificationError(f"substeps must be an integer >= 1, got {substeps!r}")
    return int(substeps)


def _history(history: Any, x0: np.ndarray, d: int) -> tuple[np.ndarray, Any]:
    """(6, max(d, 1)) initial history block, and the value to store in the result."""
    columns = max(d, 1)
    if isinstance(history, str):
        if history == "constant":
            return np.tile(x0[:, None], (1, columns)), history
        if history == "zero-input":
            return np.zeros((STATE_SIZE, columns)), history
        raise SpecificationError(f"history must be one of {HISTORY_KINDS} or an array of shape (d, 6), got {history!r}")
    array = finite_array("history", history)
    if array.shape != (d, STATE_SIZE):
        raise DimensionError(
            f"history: expected shape (d, 6) = ({d}, 6) (d = tau * rate delayed states, oldest first) "
            f"but found {array.shape}"
        )
    if d == 0:
        return np.zeros((STATE_SIZE, 1)), readonly(array)
    return np.ascontiguousarray(array.T), readonly(array)


def _samples(t_final: Any, rate: float) -> tuple[float, int]:
    t_final = positive_scalar("t_final", t_final)
    n = math.floor(t_final * rate + 1e-9) + 1
    return t_final, n


# ================================================================ symbolic building blocks
def _step_function(spacecraft: Spacecraft, period: float, substeps: int) -> ca.Function:
    """``step(x, u) -> x_next``: RK4 over one period h with ``substeps`` equal substeps."""
    dynamics = plant_model(spacecraft).dynamics
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", INPUT_SIZE)
    dt = period / substeps
    z = x
    for _ in range(substeps):
        k1 = dynamics(z, u)
        k2 = dynamics(z + (dt / 2) * k1, u)
        k3 = dynamics(z + (dt / 2) * k2, u)
        k4 = dynamics(z + dt * k3, u)
        z = z + (dt / 6) * (k1 + 2 * k2 + 2 * k3 + k4)
    return ca.Function("step", [x, u], [z], ["x", "u"], ["x_next"])


def _core_function(spacecraft: Spacecraft, rule: SwitchingRule, d: int, period: float, substeps: int) -> ca.Function:
    """One sample with K and the rule parameters as inputs (pure SX).

    ``core(x, memory, x_delayed, K, parameters) -> (x_next, memory_next, x_meas, u, switched)``.
    """
    step = _step_function(spacecraft, period, substeps)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    seen_by_rule = x_delayed if d > 0 else x
    x_meas, memory_next, switched = rule.expressions(x, seen_by_rule, memory, delay_samples=d, parameters=parameters)
    u = gain @ (x_delayed if d > 0 else x_meas)
    x_next = step(x_meas, u)
    return ca.Function(
        "core",
        [x, memory, x_delayed, gain, parameters],
        [x_next, memory_next, x_meas, u, switched],
        ["x", "memory", "x_delayed", "K", "parameters"],
        ["x_next", "memory_next", "x_meas", "u", "switched"],
    )


def _chunk_function(sample: ca.Function, d: int) -> ca.Function:
    """``chunk(x, memory, history) -> (x_end, memory_end, measurements, u, switched)``.

    One chunk is max(d, 1) samples, a ``mapaccum`` of ``sample``.
    """
    length = max(d, 1)
    accumulated = sample.mapaccum("chunk_samples", length, 2)
    x = ca.MX.sym("x", STATE_SIZE)
    memory = ca.MX.sym("memory", MEMORY_SIZE)
    history = ca.MX.sym("history", STATE_SIZE, length)
    xs, memories, measurements, u, switched = accumulated(x, memory, history)
    return ca.Function(
        "chunk",
        [x, memory, history],
        [xs[:, length - 1], memories[:, length - 1], measurements, u, switched],
        ["x", "memory", "history"],
        ["x_end", "memory_end", "measurements", "u", "switched"],
    )


@dataclass(frozen=True, eq=False)
class ClosedLoopFunctions:
    """The closed loop as named CasADi Functions (the building blocks of the simulator).

    All ports carry x = [σ; ω/4] (6), u in N m (3); K and the rule's parameters are
    constants in the expressions. ``dynamics``, ``controller``, ``switching``, ``step``
    and ``sample`` are pure SX Functions; ``chunk`` is an MX ``mapaccum`` of ``sample``
    (a loop, not an unrolled expression), also code-generatable and serialisable.

    Attributes
    ----------
    dynamics : casadi.Function
        ``dynamics(x, u) -> xdot`` from :mod:`mrpctl.model`.
    controller : casadi.Function
        ``controller(x_meas) -> u``: u = K x_meas.
    switching : casadi.Function
        ``rule(x, x_meas, memory) -> (x_next, memory_next, switched)``.
    step : casadi.Function
        ``step(x, u) -> x_next``: RK4 over one measurement period h with ``substeps``.
    sample : casadi.Function
        ``sample(x, memory, x_delayed) -> (x_next, memory_next, x_meas, u, switched)``:
        one measurement period (rule, record, hold, integrate); ``x_delayed`` is m_{k−d}
        and is not used when d = 0.
    chunk : casadi.Function
        ``chunk(x, memory, history) -> (x_end, memory_end, measurements, u, switched)``:
        max(d, 1) samples; ``history`` (6 × d) is the previous chunk's ``measurements``.
    initial_memory : float
        The rule memory at k = 0.
    """

    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    rule: SwitchingRule
    tau: float
    rate: float
    delay_samples: int
    substeps: int
    initial_memory: float
    dynamics: ca.Function = field(repr=False)
    controller: ca.Function = field(repr=False)
    switching: ca.Function = field(repr=False)
    step: ca.Function = field(repr=False)
    sample: ca.Function = field(repr=False)
    chunk: ca.Function = field(repr=False)

    @property
    def period(self) -> float:
        """Measurement period h = 1/rate (s)."""
        return 1.0 / self.rate

    def functions(self) -> dict[str, ca.Function]:
        """The Functions by name, for export."""
        return {
            "dynamics": self.dynamics,
            "controller": self.controller,
            "rule": self.switching,
            "step": self.step,
            "sample": self.sample,
            "chunk": self.chunk,
        }

    def __str__(self) -> str:
        lines = [
            f"Closed loop: {self.spacecraft}, tau = {self.tau:g} s = {self.delay_samples} samples "
            f"at {self.rate:g} Hz, RK4 with {self.substeps} substep(s), rule {self.rule}"
        ]
        lines += [f"  {function}" for function in self.functions().values()]
        return "\n".join(lines)


def closed_loop_functions(
    spacecraft: Spacecraft,
    K: Any,
    *,
    tau: float,
    rule: SwitchingRule,
    rate: float = 1000.0,
    substeps: int = 1,
) -> ClosedLoopFunctions:
    """Build the closed loop's named CasADi Functions (see :class:`ClosedLoopFunctions`).

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant.
    K : array_like
        (3, 6) gain acting on x = [σ; ω/4]: u = K x(t − τ).
    tau : float, keyword-only
        Delay τ (s), a whole number d of periods 1/rate.
    rule : SwitchingRule, keyword-only
        The shadow-set switching rule.
    rate : float, keyword-only
        Measurement rate (Hz), default 1000.
    substeps : int, keyword-only
        RK4 substeps per measurement period, default 1.
    """
    spacecraft = _spacecraft(spacecraft)
    gain = gain_matrix(K)
    rule = _rule(rule)
    d = delay_samples(tau, rate)
    rate = float(rate)
    substeps = _substeps(substeps)
    period = 1.0 / rate
    core = _core_function(spacecraft, rule, d, period, substeps)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", MEMORY_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    bound = core(x, memory, x_delayed, ca.DM(gain), ca.DM(rule.parameters()))
    sample = ca.Function(
        "sample",
        [x, memory, x_delayed],
        bound,
        ["x", "memory", "x_delayed"],
        ["x_next", "memory_next", "x_meas", "u", "switched"],
    )
    x_meas = ca.SX.sym("x_meas", STATE_SIZE)
    controller = ca.Function("controller", [x_meas], [ca.DM(gain) @ x_meas], ["x_meas"], ["u"])
    return ClosedLoopFunctions(
        spacecraft=spacecraft,
        K=readonly(gain),
        rule=rule,
        tau=float(tau),
        rate=rate,
        delay_samples=d,
        substeps=substeps,
        initial_memory=rule.initial_memory(delay_samples=d),
        dynamics=plant_model(spacecraft).dynamics,
        controller=controller,
        switching=rule.function(delay_samples=d),
        step=_step_function(spacecraft, period, substeps),
        sample=sample,
        chunk=_chunk_function(sample, d),
    )


# ======================================================================= the engine
def _engine_sample(core: ca.Function, d: int, name: str = "engine_sample") -> ca.Function:
    """The core sample plus the divergence guard and the metric accumulators (pure SX)."""
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", MEMORY_SIZE)
    stats = ca.SX.sym("stats", _STATS_SIZE)
    x_delayed = ca.SX.sym("x_delayed", STATE_SIZE)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.SX.sym("parameters", PARAMETER_SIZE)
    x_raw, memory_rule, x_meas, u, switched = core(x, memory, x_delayed, gain, parameters)

    k = stats[_S_K]
    counted = ca.logic_and(k < stats[_S_N], stats[_S_DIVERGED] < 0)
    sigma_raw, omega_raw = x_raw[0:3], 4 * x_raw[3:6]
    bound = DIVERGENCE_BOUND**2
    # NaN compares false, so a NaN or inf state is "not ok".
    ok = ca.logic_and(ca.dot(sigma_raw, sigma_raw) <= bound, ca.dot(omega_raw, omega_raw) <= bound)
    x_next = ca.if_else(ca.logic_and(counted, ok), x_raw, x_meas)
    memory_next = ca.if_else(counted, memory_rule, memory)
    switch_counted = ca.logic_and(counted, switched > 0)

    sigma, omega = x_meas[0:3], 4 * x_meas[3:6]
    sigma_squared = ca.dot(sigma, sigma)
    unsettled = ca.logic_or(sigma_squared >= SETTLING_SIGMA**2, ca.dot(omega, omega) >= SETTLING_OMEGA**2)
    u_prev = stats[_S_UPREV]
    flips = stats[_S_FLIPS] + ca.if_else(ca.logic_and(counted, u * u_prev < 0), 1.0, 0.0)
    stats_next = ca.vertcat(
        k + 1,
        stats[_S_N],
        stats[_S_COUNT] + ca.if_else(switch_counted, 1.0, 0.0),
        ca.if_else(ca.logic_and(switch_counted, stats[_S_FIRST] < 0), k, stats[_S_FIRST]),
        ca.if_else(switch_counted, k, stats[_S_LAST]),
        flips,
        ca.if_else(counted, u, u_prev),
        ca.if_else(ca.logic_and(counted, unsettled), k, stats[_S_UNSETTLED]),
        ca.if_else(counted, ca.fmax(stats[_S_MAX_SIGMA], sigma_squared), stats[_S_MAX_SIGMA]),  # max |σ|²
        ca.if_else(ca.logic_and(counted, ca.logic_not(ok)), k, stats[_S_DIVERGED]),
    )
    return ca.Function(
        name,
        [x, memory, stats, x_delayed, gain, parameters],
        [x_next, memory_next, stats_next, x_meas, u, switched],
        ["x", "memory", "stats", "x_delayed", "K", "parameters"],
        ["x_next", "memory_next", "stats_next", "x_meas", "u", "switched"],
    )


def _block_function(sample: ca.Function, d: int, name: str) -> tuple[ca.Function, int]:
    """A whole number of chunks of max(d, 1) samples (about 500 samples), as one MX Function.

    ``block(x, memory, stats, history, K, parameters) ->
    (x_end, memory_end, stats_end, history_end, measurements, u, switched)``.
    """
    length = max(d, 1)
    chunks = max(1, round(_BLOCK_TARGET / length))
    samples = chunks * length
    x = ca.MX.sym("x", STATE_SIZE)
    memory = ca.MX.sym("memory", MEMORY_SIZE)
    stats = ca.MX.sym("stats", _STATS_SIZE)
    history = ca.MX.sym("history", STATE_SIZE, length)
    gain = ca.MX.sym("K", INPUT_SIZE, STATE_SIZE)
    parameters = ca.MX.sym("parameters", PARAMETER_SIZE)

    # One chunk: the method of steps over d samples (accumulators x, memory, stats).
    chunk_samples = sample.mapaccum("chunk_samples", length, 3)
    xs, memories, statss, measurements, u, switched = chunk_samples(
        x, memory, stats, history, ca.repmat(gain, 1, length), ca.repmat(parameters, 1, length)
    )
    chunk = ca.Function(
        "chunk",
        [x, memory, stats, history, gain, parameters],
        [xs[:, -1], memories[:, -1], statss[:, -1], measurements, u, switched],
        ["x", "memory", "stats", "history", "K", "parameters"],
        ["x_end", "memory_end", "stats_end", "measurements", "u", "switched"],
    )
    # A block: chunks chained, each one's measurements being the next one's history.
    chained = chunk.mapaccum("block_chunks", chunks, 4)
    xs, memories, statss, measurements, u, switched = chained(
        x, memory, stats, history, ca.repmat(gain, 1, chunks), ca.repmat(parameters, 1, chunks)
    )
    block = ca.Function(
        name,
        [x, memory, stats, history, gain, parameters],
        [
            xs[:, -1],
            memories[:, -1],
            statss[:, -1],
            measurements[:, samples - length :],
            measurements,
            u,
            switched,
        ],
        ["x", "memory", "stats", "history", "K", "parameters"],
        ["x_end", "memory_end", "stats_end", "history_end", "measurements", "u", "switched"],
    )
    return block, samples


# The horizon loop around the generated sample (appended to CasADi's C code of the sample).
# It only moves pointers: x, memory and stats alternate between two buffers; the sample writes
# m_k, u_k and the switch flag straight into the result arrays, and reads m_{k-d} from them (or
# from the history for k < d). Without trajectories, m_k goes to a ring of d + 1 columns and
# u_k, the flag are not written. The arithmetic is the sample's, unchanged.
_DRIVER_C = r"""
/* mrpctl: the whole horizon of n samples in one call. */
CASADI_SYMBOL_EXPORT int %(name)s_run(const casadi_real* state0, const casadi_real* history,
    const casadi_real* gain, const casadi_real* parameters, long long n, long long d,
    casadi_real* measurements, casadi_real* u, casadi_real* switched, casadi_real* ring,
    casadi_real* state_end) {
  const casadi_real* arg[%(sz_arg)d];
  casadi_real* res[%(sz_res)d];
  casadi_int iw[%(sz_iw)d];
  casadi_real w[%(sz_w)d];
  casadi_real buffers[2][%(state)d];
  long long k, slot = 0, delayed_slot = 0;
  int i;
  for (i = 0; i < %(state)d; ++i) buffers[0][i] = state0[i];
  arg[4] = gain;
  arg[5] = parameters;
  for (k = 0; k < n; ++k) {
    casadi_real* now = buffers[k & 1];
    casadi_real* next = buffers[(k + 1) & 1];
    arg[0] = now;
    arg[1] = now + %(x)d;
    arg[2] = now + %(x_memory)d;
    res[0] = next;
    res[1] = next + %(x)d;
    res[2] = next + %(x_memory)d;
    if (measurements) {
      arg[3] = k < d ? history + 6 * k : measurements + 6 * (k - d);
      res[3] = measurements + 6 * k;
      res[4] = u + 3 * k;
      res[5] = switched + k;
    } else {
      arg[3] = k < d ? history + 6 * k : ring + 6 * delayed_slot;
      res[3] = ring + 6 * slot;
      res[4] = 0;
      res[5] = 0;
      if (++slot > d) slot = 0;
      if (k >= d && ++delayed_slot > d) delayed_slot = 0;
    }
    if (d == 0) arg[3] = history;
    if (%(name)s(arg, res, iw, w, 0)) return 1;
  }
  for (i = 0; i < %(state)d; ++i) state_end[i] = buffers[n & 1][i];
  return 0;
}
"""


class _Engine:
    """The engine for one structure (spacecraft, d, h, rule class, substeps).

    Compiled: the sample plus :data:`_DRIVER_C`, one C call per run. Without a compiler: a
    block of about 500 samples (an MX ``mapaccum`` of chunks) chained by CasADi's virtual machine.
    """

    def __init__(self, spacecraft: Spacecraft, rule: SwitchingRule, d: int, period: float, substeps: int) -> None:
        self.d = d
        self.history_columns = max(d, 1)
        core = _core_function(spacecraft, rule, d, period, substeps)
        label = f"{type(rule).__name__.lower()}_d{d}_s{substeps}"
        sample = _engine_sample(core, d, f"mrpctl_sample_{label}")
        driver = _DRIVER_C % dict(
            name=sample.name(),
            sz_arg=max(sample.sz_arg(), 6),
            sz_res=max(sample.sz_res(), 6),
            sz_iw=max(sample.sz_iw(), 1),
            sz_w=max(sample.sz_w(), 1),
            state=STATE_SIZE + MEMORY_SIZE + _STATS_SIZE,
            x=STATE_SIZE,
            x_memory=STATE_SIZE + MEMORY_SIZE,
        )
        self.compiled: CompiledFunction = compile_function(sample, flags=SIMULATION_FLAGS, appendix=driver)
        self._run_c = None
        self.block = None
        self.block_samples = 0
        if self.compiled.compiled:
            self._library = ctypes.CDLL(str(self.compiled.library))
            self._run_c = getattr(self._library, sample.name() + "_run")
            self._run_c.restype = ctypes.c_int
            self._run_c.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_longlong] * 2 + [ctypes.c_void_p] * 5
        else:
            block, self.block_samples = _block_function(sample, d, f"mrpctl_block_{label}")
            self.block = block.expand()  # one SX Function: no MX layers per sample in the VM
        self._horizons: dict[tuple[int, bool], ca.Function] = {}
        self._lock = threading.Lock()

    @property
    def compiled_code(self) -> bool:
        """True when runs call the compiled library (one C call per run)."""
        return self._run_c is not None

    def blocks(self, n: int) -> int:
        """Blocks of the virtual machine's chain covering n samples (0 for compiled code)."""
        return -(-n // self.block_samples) if self.block_samples else 0

    def run(
        self,
        x0: np.ndarray,
        memory0: float,
        stats0: np.ndarray,
        history0: np.ndarray,
        gain: np.ndarray,
        parameters: np.ndarray,
        n: int,
        trajectories: bool = True,
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None, np.ndarray | None]:
        """One run of n samples: (stats, measurements (>= n, 6), u (>= n, 3), switched (>= n,)).

        Compiled engines make one C call (ctypes, no copies, GIL released); without a
        compiler the CasADi horizon runs in the virtual machine (the arrays are then padded
        to whole blocks). With ``trajectories=False`` only the statistics are returned.
        """
        if self._run_c is None:
            out = self.horizon(self.blocks(n), trajectories)(x0, memory0, stats0, history0, gain, parameters)
            if not trajectories:
                return np.asarray(out).ravel(), None, None, None
            stats, measurements, u, switched = (np.asarray(value) for value in out)
            return stats.ravel(), measurements.T, u.T, switched.ravel()
        state = np.empty(STATE_SIZE + MEMORY_SIZE + _STATS_SIZE)
        state[:STATE_SIZE] = x0
        state[STATE_SIZE] = memory0
        state[STATE_SIZE + MEMORY_SIZE :] = stats0
        history0 = np.ascontiguousarray(history0.T)  # (columns, 6): column-major 6 x columns
        gain_cm = np.ascontiguousarray(gain.T)  # column-major 3 x 6
        parameters = np.ascontiguousarray(parameters, dtype=float)
        end = np.empty_like(state)
        if trajectories:
            measurements = np.empty((n, STATE_SIZE))
            u = np.empty((n, INPUT_SIZE))
            switched = np.empty(n)
            pointers = (address(measurements), address(u), address(switched), None)
        else:
            measurements = u = switched = None
            ring = np.empty((self.d + 1, STATE_SIZE))
            pointers = (None, None, None, address(ring))
        status = self._run_c(
            address(state),
            address(history0),
            address(gain_cm),
            address(parameters),
            n,
            self.d,
            *pointers,
            address(end),
        )
        if status != 0:
            raise CodegenError(f"evaluation of the compiled engine {self.compiled.library} failed")
        return end[STATE_SIZE + MEMORY_SIZE :], measurements, u, switched

    def horizon(self, blocks: int, trajectories: bool) -> ca.Function:
        """The chain of ``blocks`` blocks as a CasADi Function (for the virtual machine and ``map``).

        ``horizon(x, memory, stats, history, K, parameters) -> (stats_end[, measurements, u, switched])``.
        """
        key = (blocks, trajectories)
        with self._lock:
            if key not in self._horizons:
                self._horizons[key] = self._build_horizon(blocks, trajectories)
            return self._horizons[key]

    def _build_horizon(self, blocks: int, trajectories: bool) -> ca.Function:
        x = ca.MX.sym("x", STATE_SIZE)
        memory = ca.MX.sym("memory", MEMORY_SIZE)
        stats = ca.MX.sym("stats", _STATS_SIZE)
        history = ca.MX.sym("history", STATE_SIZE, self.history_columns)
        gain = ca.MX.sym("K", INPUT_SIZE, STATE_SIZE)
        parameters = ca.MX.sym("parameters", PARAMETER_SIZE)
        carry = (x, memory, stats, history)
        pieces: list[tuple[Any, Any, Any]] = []
        for _ in range(blocks):
            out = self.block(*carry, gain, parameters)
            carry = tuple(out[0:4])
            pieces.append(tuple(out[4:7]))
        outputs = [carry[2]]
        names = ["stats_end"]
        if trajectories:
            outputs += [ca.horzcat(*[piece[i] for piece in pieces]) for i in range(3)]
            names += ["measurements", "u", "switched"]
        return ca.Function(
            "horizon",
            [x, memory, stats, history, gain, parameters],
            outputs,
            ["x", "memory", "stats", "history", "K", "parameters"],
            names,
        )


_ENGINES: dict[tuple[Any, ...], _Engine] = {}
_ENGINES_LOCK = threading.Lock()


def _engine(spacecraft: Spacecraft, rule: SwitchingRule, d: int, period: float, substeps: int) -> _Engine:
    key = (spacecraft, type(rule), d, period, substeps)
    with _ENGINES_LOCK:
        engine = _ENGINES.get(key)
        if engine is None:
            engine = _Engine(spacecraft, rule, d, period, substeps)
            _ENGINES[key] = engine
        return engine


def _clear_engines() -> None:
    """Forget the loaded engines (the on-disk cache stays); for benchmarks."""
    with _ENGINES_LOCK:
        _ENGINES.clear()


def _initial_stats(n: int) -> np.ndarray:
    stats = np.zeros(_STATS_SIZE)
    stats[_S_N] = n
    stats[[_S_FIRST, _S_LAST, _S_UNSETTLED, _S_DIVERGED]] = -1.0
    return stats


# ======================================================================= results
def _sealed(array: np.ndarray) -> np.ndarray:
    """Make an array (or a view of a buffer) that this module allocated read-only, without a copy."""
    array.setflags(write=False)
    return array


def _frozen(values: Any, dtype: Any) -> np.ndarray:
    array = np.array(values, dtype=dtype, copy=True)
    array.setflags(write=False)
    return array


@dataclass(frozen=True)
class _Metrics:
    switch_count: int
    first_switch_index: int
    last_switch_index: int
    sign_flips: np.ndarray
    unsettled_index: int
    max_sigma: float
    diverged_index: int

    @classmethod
    def from_stats(cls, stats: np.ndarray) -> _Metrics:
        return cls(
            switch_count=round(stats[_S_COUNT]),
            first_switch_index=round(stats[_S_FIRST]),
            last_switch_index=round(stats[_S_LAST]),
            sign_flips=np.rint(stats[_S_FLIPS]).astype(np.int64),
            unsettled_index=round(stats[_S_UNSETTLED]),
            max_sigma=math.sqrt(stats[_S_MAX_SIGMA]),
            diverged_index=round(stats[_S_DIVERGED]),
        )


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """One closed-loop run, sampled at the measurement instants t_k = k h.

    ``sigma``, ``omega`` are the state at t_k *after* the switching rule (the recorded
    measurement m_k), ``u`` the torque held over [t_k, t_{k+1}).

    Attributes
    ----------
    t : numpy.ndarray
        (n,) sample times (s); n = floor(t_final · rate) + 1, fewer if the run diverged.
    sigma : numpy.ndarray
        (n, 3) MRPs σ (dimensionless).
    omega : numpy.ndarray
        (n, 3) body rates ω (rad/s).
    u : numpy.ndarray
        (n, 3) control torque (N m).
    switch_indices : numpy.ndarray
        Sample indices k at which σ was replaced by its shadow.
    switch_times : numpy.ndarray
        The same as times (s).
    sign_flips : numpy.ndarray
        (3,) number of sign changes u_i(t_k) u_i(t_{k−1}) < 0 per torque axis.
    max_sigma : float
        max_k |σ(t_k)|.
    settling_time : float or None
        First t_k from which |σ| < 1e-2 and |ω| < 1e-3 rad/s to the end; None if the run
        does not settle (or diverged).
    diverged : bool
        True when |σ| or |ω| exceeded 1e6 or stopped being finite; the arrays then end at
        the last good sample.
    spacecraft, K, tau, rate, delay_samples, rule, history, substeps, x0, t_final
        The inputs of the run.
    """

    t: np.ndarray = field(repr=False)
    sigma: np.ndarray = field(repr=False)
    omega: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    switch_indices: np.ndarray = field(repr=False)
    switch_times: np.ndarray = field(repr=False)
    sign_flips: np.ndarray = field(repr=False)
    max_sigma: float
    settling_time: float | None
    diverged: bool
    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    tau: float
    rate: float
    delay_samples: int
    rule: SwitchingRule
    history: Any = field(repr=False)
    substeps: int
    x0: np.ndarray = field(repr=False)
    t_final: float

    @property
    def switch_count(self) -> int:
        """Number of shadow-set switches."""
        return len(self.switch_indices)

    @property
    def first_switch_time(self) -> float | None:
        """Time of the first switch (s), None if there was none."""
        return float(self.switch_times[0]) if len(self.switch_times) else None

    @property
    def last_switch_time(self) -> float | None:
        """Time of the last switch (s), None if there was none."""
        return float(self.switch_times[-1]) if len(self.switch_times) else None

    @property
    def converged(self) -> bool:
        """True when the run settled (|σ| < 1e-2, |ω| < 1e-3 rad/s) and stayed so to the end."""
        return self.settling_time is not None

    @property
    def period(self) -> float:
        """Measurement period h (s)."""
        return 1.0 / self.rate

    @property
    def x(self) -> np.ndarray:
        """(n, 6) states x = [σ; ω/4]."""
        return np.hstack((self.sigma, self.omega / 4.0))

    def __str__(self) -> str:
        history = self.history if isinstance(self.history, str) else f"array {self.history.shape}"
        if self.diverged:
            status = f"DIVERGED at t = {self.t[-1]:.3f} s"
        elif self.converged:
            status = f"converged, settling time {self.settling_time:.3f} s"
        else:
            status = "not settled"
        last = "" if self.last_switch_time is None else f", last at {self.last_switch_time:.3f} s"
        first = "" if self.first_switch_time is None else f", first at {self.first_switch_time:.3f} s"
        return "\n".join(
            (
                f"Simulation {self.t_final:g} s, tau = {self.tau:g} s ({self.delay_samples} samples at "
                f"{self.rate:g} Hz), history {history}, RK4 x{self.substeps}",
                f"  rule         {self.rule}",
                f"  switches     {self.switch_count}{first}{last}",
                f"  sign flips   u1 {self.sign_flips[0]}, u2 {self.sign_flips[1]}, u3 {self.sign_flips[2]}",
                f"  max |sigma|  {self.max_sigma:.6f}",
                f"  status       {status}",
            )
        )


def _result(
    *,
    metrics: _Metrics,
    measurements: np.ndarray,
    u: np.ndarray,
    switched: np.ndarray,
    n: int,
    common: dict[str, Any],
    x0: np.ndarray,
) -> SimulationResult:
    rate = common["rate"]
    diverged = metrics.diverged_index >= 0
    valid = metrics.diverged_index + 1 if diverged else n
    measurements = measurements[:valid]
    t = np.arange(valid) / rate
    indices = np.flatnonzero(switched[:valid] > 0.5)
    if diverged:
        settling = None
        logger.info("run diverged at t = %.4f s (|sigma| or |omega| > %g)", t[-1], DIVERGENCE_BOUND)
    else:
        settle_index = metrics.unsettled_index + 1
        settling = settle_index / rate if settle_index < n else None
    return SimulationResult(
        t=_sealed(t),
        sigma=_sealed(measurements[:, 0:3]),
        omega=_sealed(4.0 * measurements[:, 3:6]),
        u=_sealed(u[:valid]),
        switch_indices=_frozen(indices, np.int64),
        switch_times=readonly(indices / rate),
        sign_flips=_frozen(metrics.sign_flips, np.int64),
        max_sigma=metrics.max_sigma,
        settling_time=settling,
        diverged=diverged,
        x0=readonly(x0),
        **common,
    )


# ======================================================================= simulate
def simulate(
    spacecraft: Spacecraft,
    K: Any,
    x0: Any,
    *,
    tau: float,
    rule: SwitchingRule,
    t_final: float,
    rate: float = 1000.0,
    history: Any = "constant",
    substeps: int = 1,
) -> SimulationResult:
    """Simulate the closed loop u(t) = K x(t − τ) with sampled measurements and switching.

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant (inertia J in kg m²).
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    x0 : array_like
        (6,) initial state x = [σ; ω/4] (ω in rad/s; see :func:`mrpctl.model.state`).
    tau : float, keyword-only
        Measurement delay τ >= 0 (s), a whole number of periods 1/rate.
    rule : SwitchingRule, keyword-only
        Shadow-set switching rule, e.g. ``OnDelayed()``.
    t_final : float, keyword-only
        Horizon (s), > 0.
    rate : float, keyword-only
        Measurement rate (Hz), default 1000.
    history : {"constant", "zero-input"} or array_like, keyword-only
        Measurements before t = 0: x0 (the paper's φ(θ) = x0; default), zero (u = 0
        until the first measurement arrives), or a (d, 6) array m_{−d}, …, m_{−1}.
    substeps : int, keyword-only
        RK4 substeps per measurement period, default 1.

    Returns
    -------
    SimulationResult

    Raises
    ------
    SpecificationError, DimensionError
        On invalid inputs (NaN, negative τ, rate <= 0, t_final <= 0, τ · rate not an
        integer, wrong shapes, unknown history).
    """
    spacecraft = _spacecraft(spacecraft)
    gain = gain_matrix(K)
    x0 = finite_array("x0", x0, (STATE_SIZE,))
    rule = _rule(rule)
    d = delay_samples(tau, rate)
    rate = float(rate)
    t_final, n = _samples(t_final, rate)
    substeps = _substeps(substeps)
    history_block, history_value = _history(history, x0, d)

    engine = _engine(spacecraft, rule, d, 1.0 / rate, substeps)
    stats, measurements, u, switched = engine.run(
        x0,
        rule.initial_memory(delay_samples=d),
        _initial_stats(n),
        history_block,
        gain,
        np.array(rule.parameters()),
        n,
    )
    common = dict(
        spacecraft=spacecraft,
        K=readonly(gain),
        tau=float(tau),
        rate=rate,
        delay_samples=d,
        rule=rule,
        history=history_value,
        substeps=substeps,
        t_final=t_final,
    )
    return _result(
        metrics=_Metrics.from_stats(stats),
        measurements=measurements,
        u=u,
        switched=switched,
        n=n,
        common=common,
        x0=x0,
    )


# ======================================================================= batches
@dataclass(frozen=True, eq=False)
class BatchResult:
    """Metrics of many closed-loop runs (one entry per run, in input order).

    Attributes
    ----------
    x0 : numpy.ndarray
        (N, 6) initial states.
    K : numpy.ndarray
        (N, 3, 6) gains.
    tau : numpy.ndarray
        (N,) delays (s).
    rules : tuple of SwitchingRule
        The rule of each run.
    switch_count : numpy.ndarray
        (N,) number of switches.
    first_switch_time, last_switch_time : numpy.ndarray
        (N,) times of the first and last switch (s); NaN when a run never switched.
    sign_flips : numpy.ndarray
        (N, 3) torque sign changes per axis.
    settling_time : numpy.ndarray
        (N,) settling time (s), NaN when the run did not settle.
    converged, diverged : numpy.ndarray
        (N,) booleans.
    max_sigma : numpy.ndarray
        (N,) max |σ| over the run.
    runs : tuple of SimulationResult or None
        The full runs when ``trajectories=True`` was asked for.
    rate, t_final, substeps, history
        The shared inputs.
    """

    x0: np.ndarray = field(repr=False)
    K: np.ndarray = field(repr=False)
    tau: np.ndarray = field(repr=False)
    rules: tuple[SwitchingRule, ...] = field(repr=False)
    switch_count: np.ndarray = field(repr=False)
    first_switch_time: np.ndarray = field(repr=False)
    last_switch_time: np.ndarray = field(repr=False)
    sign_flips: np.ndarray = field(repr=False)
    settling_time: np.ndarray = field(repr=False)
    converged: np.ndarray = field(repr=False)
    diverged: np.ndarray = field(repr=False)
    max_sigma: np.ndarray = field(repr=False)
    rate: float
    t_final: float
    substeps: int
    history: Any = field(repr=False)
    runs: tuple[SimulationResult, ...] | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.switch_count)

    def __str__(self) -> str:
        n = len(self)
        switching = self.last_switch_time[np.isfinite(self.last_switch_time)]
        latest = f"{switching.max():.3f} s" if switching.size else "none"
        rules = sorted({str(rule) for rule in self.rules})
        return "\n".join(
            (
                f"Batch of {n} runs over {self.t_final:g} s at {self.rate:g} Hz, "
                f"tau in [{self.tau.min():g}, {self.tau.max():g}] s",
                "  rule         " + "; ".join(rules),
                f"  converged    {int(self.converged.sum())}/{n}, diverged {int(self.diverged.sum())}",
                f"  switches     median {np.median(self.switch_count):g}, max {self.switch_count.max()}, "
                f"latest switch {latest}",
                f"  max |sigma|  {self.max_sigma.max():.6f}",
            )
        )


def _run_group(
    engine: _Engine,
    n: int,
    states: np.ndarray,
    gains: np.ndarray,
    rules: Sequence[SwitchingRule],
    members: list[int],
    histories: list[tuple[np.ndarray, Any]],
    memories: list[float],
    trajectories: bool,
    threads: int,
) -> list[tuple[np.ndarray, Any, Any, Any]]:
    """Runs of one delay: a thread pool over the compiled library, or CasADi ``map`` in the VM.

    CasADi's ``map(N, "thread")`` evaluates a ``casadi.external`` serially in the CasADi
    build we use (measured: CPU time equal to wall time), while ctypes releases the GIL,
    so compiled runs go through a thread pool; the virtual machine uses CasADi's map.
    """
    if engine.compiled_code:

        def one(j: int) -> tuple[np.ndarray, Any, Any, Any]:
            i = members[j]
            return engine.run(
                states[i],
                memories[j],
                _initial_stats(n),
                histories[j][0],
                gains[i],
                np.array(rules[i].parameters()),
                n,
                trajectories,
            )

        if threads == 1 or len(members) == 1:
            return [one(j) for j in range(len(members))]
        with ThreadPoolExecutor(max_workers=threads) as pool:
            return list(pool.map(one, range(len(members))))
    blocks = engine.blocks(n)
    mapped = engine.horizon(blocks, trajectories).map(len(members), "thread", threads)
    out = mapped(
        states[members].T,
        np.array([memories]),
        np.tile(_initial_stats(n)[:, None], (1, len(members))),
        np.hstack([block for block, _ in histories]),
        np.hstack([gains[i] for i in members]),
        np.array([rules[i].parameters() for i in members]).T,
    )
    out = out if isinstance(out, (list, tuple)) else [out]
    stats = np.asarray(out[0]).T
    if not trajectories:
        return [(row, None, None, None) for row in stats]
    total = blocks * engine.block_samples
    measurements, u, switched = (np.asarray(value) for value in out[1:4])
    return [
        (
            stats[j],
            measurements[:, j * total : (j + 1) * total].T,
            u[:, j * total : (j + 1) * total].T,
            switched[0, j * total : (j + 1) * total],
        )
        for j in range(len(members))
    ]


def _broadcast(name: str, count: int, n: int) -> None:
    if count not in (1, n):
        raise DimensionError(f"{name}: expected 1 or {n} entries (one per run) but found {count}")


def simulate_batch(
    spacecraft: Spacecraft,
    K: Any,
    x0: Any,
    *,
    tau: Any,
    rule: SwitchingRule | Sequence[SwitchingRule],
    t_final: float,
    rate: float = 1000.0,
    history: Any = "constant",
    substeps: int = 1,
    trajectories: bool = False,
    threads: int | None = None,
) -> BatchResult:
    """Simulate many runs at once on several threads.

    Compiled runs are spread over a thread pool that calls the generated library
    directly; in CasADi's virtual machine (no C compiler) CasADi ``map(N, "thread",
    threads)`` is used.

    Any of ``x0``, ``K``, ``tau`` and ``rule`` may be given once (shared) or once per run.

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant.
    K : array_like
        (3, 6) or (N, 3, 6) gains on x = [σ; ω/4].
    x0 : array_like
        (6,) or (N, 6) initial states x = [σ; ω/4].
    tau : float or array_like, keyword-only
        Delay(s) (s), each a whole number of periods 1/rate; runs with equal delays share
        one compiled engine.
    rule : SwitchingRule or sequence of SwitchingRule, keyword-only
        One rule, or one per run, all of the same class (their parameters, such as ε,
        may differ).
    t_final, rate, history, substeps
        As in :func:`simulate`; ``history`` is shared by all runs (an array is allowed
        only when all runs have the same delay).
    trajectories : bool, keyword-only
        Also return every run as a :class:`SimulationResult` (memory: about 80 bytes per
        sample and run).
    threads : int, keyword-only
        Worker threads; default: the CPUs available to this process.

    Returns
    -------
    BatchResult
    """
    spacecraft = _spacecraft(spacecraft)
    states = finite_array("x0", x0, (None, STATE_SIZE)).reshape(-1, STATE_SIZE)
    gains = finite_array("K", K)
    if gains.shape == (INPUT_SIZE, STATE_SIZE):
        gains = gains[None]
    if gains.ndim != 3 or gains.shape[1:] != (INPUT_SIZE, STATE_SIZE):
        raise DimensionError(f"K: expected shape (3, 6) or (N, 3, 6) but found {np.shape(K)}")
    delays = np.atleast_1d(np.asarray(tau, dtype=float))
    if delays.ndim != 1:
        raise DimensionError(f"tau: expected a scalar or shape (N,) but found {delays.shape}")
    rules = (rule,) if isinstance(rule, SwitchingRule) else tuple(rule)
    if not rules:
        raise SpecificationError("rule: give a switching rule or a non-empty sequence of rules")
    for each in rules:
        _rule(each)
    if len({type(each) for each in rules}) != 1:
        raise SpecificationError(
            "rule: all rules of a batch must be of the same class (their parameters may differ), got "
            + ", ".join(sorted({type(each).__name__ for each in rules}))
        )
    n_runs = max(len(states), len(gains), len(delays), len(rules))
    for name, count in (("x0", len(states)), ("K", len(gains)), ("tau", len(delays)), ("rule", len(rules))):
        _broadcast(name, count, n_runs)
    states = np.broadcast_to(states, (n_runs, STATE_SIZE))
    gains = np.broadcast_to(gains, (n_runs, INPUT_SIZE, STATE_SIZE))
    delays = np.broadcast_to(delays, (n_runs,))
    rules = rules * n_runs if len(rules) == 1 else rules
    rate = positive_scalar("rate", rate)
    samples_by_run = [delay_samples(value, rate) for value in delays]
    t_final, n = _samples(t_final, rate)
    substeps = _substeps(substeps)
    if threads is None:
        threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise SpecificationError(f"threads must be an integer >= 1, got {threads!r}")
    if not isinstance(history, str) and len(set(samples_by_run)) > 1:
        raise SpecificationError("history: an array history needs all runs to have the same tau")

    stats = np.empty((n_runs, _STATS_SIZE))
    runs: list[SimulationResult | None] = [None] * n_runs
    for d in sorted(set(samples_by_run)):
        members = [i for i, value in enumerate(samples_by_run) if value == d]
        engine = _engine(spacecraft, rules[members[0]], d, 1.0 / rate, substeps)
        blocks_history = [_history(history, states[i], d) for i in members]
        memories = [rules[i].initial_memory(delay_samples=d) for i in members]
        outs = _run_group(engine, n, states, gains, rules, members, blocks_history, memories, trajectories, threads)
        group_stats = np.array([out[0] for out in outs])
        stats[members] = group_stats
        if trajectories:
            for j, i in enumerate(members):
                runs[i] = _result(
                    metrics=_Metrics.from_stats(group_stats[j]),
                    measurements=outs[j][1],
                    u=outs[j][2],
                    switched=outs[j][3],
                    n=n,
                    common=dict(
                        spacecraft=spacecraft,
                        K=readonly(gains[i]),
                        tau=float(delays[i]),
                        rate=rate,
                        delay_samples=d,
                        rule=rules[i],
                        history=blocks_history[j][1],
                        substeps=substeps,
                        t_final=t_final,
                    ),
                    x0=states[i],
                )
    metrics = [_Metrics.from_stats(row) for row in stats]
    diverged = np.array([m.diverged_index >= 0 for m in metrics])
    settle = np.array([m.unsettled_index + 1 for m in metrics], dtype=float)
    settled = ~diverged & (settle < n)
    first = np.array([m.first_switch_index for m in metrics], dtype=float)
    last = np.array([m.last_switch_index for m in metrics], dtype=float)
    return BatchResult(
        x0=readonly(states),
        K=readonly(gains),
        tau=readonly(delays),
        rules=tuple(rules),
        switch_count=_frozen([m.switch_count for m in metrics], np.int64),
        first_switch_time=readonly(np.where(first >= 0, first / rate, np.nan)),
        last_switch_time=readonly(np.where(last >= 0, last / rate, np.nan)),
        sign_flips=_frozen([m.sign_flips for m in metrics], np.int64).reshape(n_runs, 3),
        settling_time=readonly(np.where(settled, settle / rate, np.nan)),
        converged=_frozen(settled, bool),
        diverged=_frozen(diverged, bool),
        max_sigma=readonly([m.max_sigma for m in metrics]),
        rate=rate,
        t_final=t_final,
        substeps=substeps,
        history=history if isinstance(history, str) else readonly(history),
        runs=tuple(runs) if trajectories else None,
    )
