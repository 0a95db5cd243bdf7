"""The option values of the loop as flown, frozen and validated: sensor, actuator, delay, disturbance and
the controller-side rule `Hysteretic`; the newest-arrived schedule of a time-varying delay."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from mrpctl._validation import finite_array, finite_scalar, integer, nonnegative_scalar, positive_scalar, readonly
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight.expressions import Saturation
from mrpctl.flight.streams import sample_slice, stream_integers, stream_normal_rows, stream_seed
from mrpctl.switching import SwitchingRule

__all__ = [
    "FLIGHT_CONSTANTS_SIZE",
    "FLIGHT_MEMORY_SIZE",
    "NOISE_REVISION",
    "NOISE_SIZE",
    "STREAM_ATTITUDE",
    "STREAM_JITTER",
    "STREAM_RATE",
    "ActuatorModel",
    "DelayKind",
    "DelayModel",
    "Disturbance",
    "Hysteretic",
    "SensorModel",
    "newest_arrived",
    "newest_arrived_slice",
]

#: The memory a controller-side rule carries in the compiled engine: (h, c, σ̃_prev) and the
#: actuator accumulators (saturated samples, peak commanded |u_c,i| per axis, peak |u_c|).
FLIGHT_MEMORY_SIZE = 10
#: The flight sample's run-time constant input ``flight``: (u_max (3), u_norm, w (3), gyro bias b (3)).
FLIGHT_CONSTANTS_SIZE = 10
#: The flight sample's per-sample input ``noise``: (θ_k (3), η_k (3)).
NOISE_SIZE = 6
#: Revision of the numbers of the sensor's attitude noise (σ(θ) of the noise rotation): runs with attitude noise
#: of two revisions differ in their last bits. 1: libm's tan (until 2026-12-01); 2: Cephes' rational tan for
#: |θ| <= π (design/flight.md, phase 8a). A campaign store records it (``attrs["noise_revision"]``; a store
#: without it is revision 1) and is not resumed across revisions.
NOISE_REVISION = 2
#: The stream numbers of the attitude noise, the rate noise and the delay jitter (`stream_key`).
STREAM_ATTITUDE, STREAM_RATE, STREAM_JITTER = 0, 1, 2
_DELAY_TOLERANCE = 1e-9
#: Largest attitude 1σ (rad): π per axis. The error rotation's angle wraps at π, so beyond a 1σ of π the
#: error is already spread over (nearly) every attitude and a larger number means nothing more.
_MAX_ATTITUDE_NOISE = math.pi
#: Largest rate 1σ and gyro bias (rad/s): the divergence bound of the true rate (mrpctl.engines.stats).
_MAX_RATE_ERROR = 1e6


@dataclass(frozen=True, eq=False)
class SensorModel:
    """Star tracker and gyro: attitude noise as a small random rotation, white rate noise, gyro bias.

    The measured attitude is the true one followed by a small rotation θ_k (rad) about the body
    axes: [B̃N] = [B̃B](θ_k) [BN], with the components of the rotation vector θ_k i.i.d.
    N(0, σ_θ²). The error angle |θ_k| is then σ_θ·χ₃ (χ with 3 degrees of freedom): RMS angle
    √3 σ_θ, mean 2√(2/π) σ_θ ≈ 1.596 σ_θ. The measured rate is ω̃_k = ω_k + b + η_k with η_k
    i.i.d. N(0, σ_ω² I₃) and b constant. Sample k's noise depends only on (seed, k).

    Parameters
    ----------
    attitude_noise : float
        σ_θ in [0, π], 1σ per body axis of the attitude error rotation vector (rad). Default 0.
    rate_noise : float
        σ_ω >= 0, 1σ per axis of the white rate noise (rad/s), at most 10⁶ (the divergence bound of
        the rate). Default 0.
    gyro_bias : array_like
        Constant gyro bias b (3,) (rad/s), each |b_i| at most 10⁶. Default zero.
    seed : int
        Seed (>= 0) of the noise streams. Default 0.
    """

    attitude_noise: float = 0.0
    rate_noise: float = 0.0
    gyro_bias: Any = field(default=(0.0, 0.0, 0.0))
    seed: int = 0

    def __post_init__(self) -> None:
        attitude_noise = nonnegative_scalar("attitude_noise", self.attitude_noise)
        if attitude_noise > _MAX_ATTITUDE_NOISE:
            raise SpecificationError(
                f"attitude_noise must be <= pi rad (1 sigma per axis), got {attitude_noise:g}: the error rotation's "
                "angle wraps at pi, so a 1 sigma beyond pi is physically meaningless (the error is already spread "
                "over every attitude)"
            )
        object.__setattr__(self, "attitude_noise", attitude_noise)
        rate_noise = nonnegative_scalar("rate_noise", self.rate_noise)
        bias = finite_array("gyro_bias", self.gyro_bias, (3,))
        for name, size in (("rate_noise", rate_noise), ("gyro_bias", float(np.max(np.abs(bias))))):
            if size > _MAX_RATE_ERROR:
                raise SpecificationError(
                    f"{name} must be <= {_MAX_RATE_ERROR:g} rad/s (per axis), got {size:g}: a run stops as diverged "
                    f"when |omega| exceeds {_MAX_RATE_ERROR:g} rad/s, and beyond it the commanded torque can overflow "
                    "the actuator's norm limit (|u_c|^2 above 1e308)"
                )
        object.__setattr__(self, "rate_noise", rate_noise)
        object.__setattr__(self, "gyro_bias", readonly(bias))
        object.__setattr__(self, "seed", stream_seed(self.seed))

    @property
    def ideal(self) -> bool:
        """True when the sensor adds nothing (no noise, zero bias)."""
        return self.attitude_noise == 0.0 and self.rate_noise == 0.0 and not np.any(self.gyro_bias)

    def noise(self, k0: int, k1: int) -> tuple[np.ndarray, np.ndarray]:
        """The noise of measurement samples k0 … k1 − 1.

        Returns
        -------
        rotation, rate : numpy.ndarray
            (k1 − k0, 3) attitude error rotation vectors θ_k (rad) and rate noise η_k (rad/s).
            Exactly zero when the corresponding 1σ is zero. Identical for any slicing of the
            horizon (counter-based: component c of sample k is normal number 3k + c of the
            stream keyed by (seed, stream), [`stream_normals`][mrpctl.flight.stream_normals]).
        """
        rows = self.noise_rows(k0, k1)
        return rows[:, 0:3], rows[:, 3:6]

    def noise_rows(self, k0: int, k1: int, *, out: np.ndarray | None = None) -> np.ndarray:
        """The noise of samples k0 … k1 − 1 as one (k1 − k0, 6) array of rows (θ_k, η_k).

        The flight sample's per-sample ``noise`` input, the numbers of [`noise`][mrpctl.flight.SensorModel.noise] bit
        for bit,
        generated in place: into ``out`` when given (a C-contiguous float64 array of at least
        k1 − k0 rows and 6 columns, e.g. a buffer reused slice after slice; its first k1 − k0 rows
        are written and returned), else into a new array.
        """
        start, stop = sample_slice(k0, k1)
        count = stop - start
        if out is None:
            rows = np.empty((count, NOISE_SIZE))
        else:
            if out.dtype != np.float64 or out.ndim != 2 or out.shape[1] != NOISE_SIZE or len(out) < count:
                raise DimensionError(
                    f"out: expected a float64 array of shape (>= {count}, {NOISE_SIZE}) "
                    f"but found {out.dtype} {out.shape}"
                )
            if not out.flags.c_contiguous:
                raise SpecificationError("out must be C-contiguous (the engine reads its rows as one block)")
            rows = out[:count]
        for column, sigma, stream in ((0, self.attitude_noise, STREAM_ATTITUDE), (3, self.rate_noise, STREAM_RATE)):
            target = rows[:, column : column + 3]
            if sigma > 0.0:
                stream_normal_rows(self.seed, stream, start, stop, scale=sigma, out=target)
            else:
                target[...] = 0.0
        return rows

    def __str__(self) -> str:
        if self.ideal:
            return "SensorModel (ideal)"
        bias = ", ".join(f"{b:g}" for b in self.gyro_bias)
        return (
            f"SensorModel (attitude 1sigma {self.attitude_noise:g} rad per axis, rate 1sigma "
            f"{self.rate_noise:g} rad/s, gyro bias [{bias}] rad/s, seed {self.seed})"
        )


@dataclass(frozen=True, eq=False)
class ActuatorModel:
    """Torque limits: per axis |u_i| <= u_max,i and optionally |u| <= u_norm (N m).

    Parameters
    ----------
    u_max : float or array_like
        Per-axis limit u_max > 0 (N m), scalar or (3,).
    norm_max : float or None
        Limit on the Euclidean norm |u| (N m), > 0; None (default) for none.
    mode : Saturation
        `Saturation.SCALE` (default; direction-preserving) or `Saturation.CLIP`.
    """

    u_max: Any
    norm_max: float | None = None
    mode: Saturation = Saturation.SCALE

    def __post_init__(self) -> None:
        limits = finite_array("u_max", self.u_max)
        if limits.shape == ():
            limits = np.full(3, float(limits))
        if limits.shape != (3,):
            raise DimensionError(f"u_max: expected a scalar or shape (3,) but found {limits.shape}")
        if np.any(limits <= 0.0):
            raise SpecificationError(f"u_max (per-axis torque limit, N m) must be > 0 on every axis, got {limits}")
        object.__setattr__(self, "u_max", readonly(limits))
        if self.norm_max is not None:
            object.__setattr__(self, "norm_max", positive_scalar("norm_max", self.norm_max))
        if not isinstance(self.mode, Saturation):
            raise SpecificationError(f"mode must be a mrpctl.flight.Saturation, got {self.mode!r}")

    @property
    def norm_limit(self) -> float:
        """The norm limit (N m), ``inf`` when there is none (the value fed to the sample Function)."""
        return math.inf if self.norm_max is None else float(self.norm_max)

    def __str__(self) -> str:
        limits = ", ".join(f"{u:g}" for u in self.u_max)
        norm = "" if self.norm_max is None else f", |u| <= {self.norm_max:g}"
        return f"ActuatorModel (|u_i| <= [{limits}] N m{norm}, {self.mode.value})"


class DelayKind(enum.Enum):
    """Kinds of measurement delay."""

    CONSTANT = "constant"
    SEQUENCE = "sequence"
    JITTER = "jitter"


def _to_samples(name: str, seconds: np.ndarray, rate: float) -> np.ndarray:
    samples = seconds * rate
    rounded = np.rint(samples)
    bad = np.abs(samples - rounded) > _DELAY_TOLERANCE * np.maximum(1.0, np.abs(samples))  # relative, as delay_samples
    if np.any(bad):
        first = float(np.asarray(seconds).ravel()[np.flatnonzero(bad.ravel())[0]])
        raise SpecificationError(
            f"{name} must be whole numbers of measurement periods: {first!r} s at rate = {rate!r} Hz "
            f"gives {first * rate!r} periods; choose delays as multiples of 1/rate"
        )
    return rounded.astype(np.int64)


@dataclass(frozen=True, eq=False)
class DelayModel:
    """Measurement delay: constant, a given per-sample sequence, or seeded random jitter.

    Measurement k (taken at t_k) reaches the controller at sample k + d_k. At sample k the
    controller uses the newest measurement that has arrived, j*(k) = max{j : j + d_j <= k};
    a measurement overtaken by a newer one is never used ([`newest_arrived`][mrpctl.flight.newest_arrived]). Build with
    [`constant`][mrpctl.flight.DelayModel.constant], [`sequence`][mrpctl.flight.DelayModel.sequence] or
    [`jitter`][mrpctl.flight.DelayModel.jitter].

    Attributes
    ----------
    kind : DelayKind
    tau_min, tau_max : float
        Bounds of the delay (s); equal for a constant delay.
    delays : numpy.ndarray or None
        The per-sample delays (s) of a sequence.
    seed : int
        Seed of the jitter stream.
    """

    kind: DelayKind
    tau_min: float
    tau_max: float
    delays: np.ndarray | None = field(default=None, repr=False)
    seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.kind, DelayKind):
            raise SpecificationError(f"kind must be a mrpctl.flight.DelayKind, got {self.kind!r}")
        tau_min = nonnegative_scalar("tau_min", self.tau_min)
        tau_max = nonnegative_scalar("tau_max", self.tau_max)
        if tau_max < tau_min:
            raise SpecificationError(f"tau_max must be >= tau_min, got tau_min = {tau_min} s, tau_max = {tau_max} s")
        if self.kind is DelayKind.CONSTANT and tau_min != tau_max:
            raise SpecificationError("a constant delay needs tau_min == tau_max")
        object.__setattr__(self, "tau_min", tau_min)
        object.__setattr__(self, "tau_max", tau_max)
        object.__setattr__(self, "seed", stream_seed(self.seed))
        if self.kind is DelayKind.SEQUENCE:
            if self.delays is None:
                raise SpecificationError("delays: a delay sequence needs an array of per-sample delays (s)")
            delays = finite_array("delays", self.delays)
            if delays.ndim != 1 or delays.size == 0:
                raise DimensionError(f"delays: expected shape (n,) (one delay per sample) but found {delays.shape}")
            outside = (delays < tau_min) | (delays > tau_max)
            if np.any(outside):
                k = int(np.flatnonzero(outside)[0])
                raise SpecificationError(
                    f"delays must lie in [tau_min, tau_max] = [{tau_min:g}, {tau_max:g}] s; "
                    f"delays[{k}] = {delays[k]!r} s"
                )
            object.__setattr__(self, "delays", readonly(delays))
        elif self.delays is not None:
            raise SpecificationError(f"delays: only a {DelayKind.SEQUENCE.value!r} delay takes an array")

    # --------------------------------------------------------------- constructors
    @classmethod
    def constant(cls, tau: float) -> DelayModel:
        """A constant delay τ >= 0 (s)."""
        tau = nonnegative_scalar("tau", tau)
        return cls(DelayKind.CONSTANT, tau, tau)

    @classmethod
    def sequence(cls, delays: Any, *, tau_min: float, tau_max: float) -> DelayModel:
        """Per-sample delays d_k (s), one per measurement sample, each in [tau_min, tau_max]."""
        return cls(DelayKind.SEQUENCE, tau_min, tau_max, delays=delays)

    @classmethod
    def jitter(cls, tau_min: float, tau_max: float, *, seed: int = 0) -> DelayModel:
        """Seeded random delays, uniform over the whole periods in [tau_min, tau_max] (s)."""
        return cls(DelayKind.JITTER, tau_min, tau_max, seed=seed)

    # --------------------------------------------------------------------- use
    def bounds(self, rate: float) -> tuple[int, int]:
        """(d_min, d_max) in samples at ``rate`` (Hz); each bound a whole number of periods."""
        rate = positive_scalar("rate", rate)
        low, high = _to_samples("tau_min, tau_max", np.array([self.tau_min, self.tau_max]), rate)
        return int(low), int(high)

    def check_horizon(self, n: int) -> None:
        """Raise [`DimensionError`][mrpctl.DimensionError] if a sequence does not hold exactly n delays."""
        n = integer("n", n, minimum=1)
        if self.delays is not None and self.delays.shape != (n,):
            raise DimensionError(
                f"delays: expected shape (n,) = ({n},) (one delay per measurement sample) but found {self.delays.shape}"
            )

    def samples(self, rate: float, k0: int, k1: int) -> np.ndarray:
        """Delays d_k in samples of measurement samples k0 … k1 − 1 (int64), at ``rate`` (Hz).

        Jitter is uniform over the integers in [d_min, d_max], keyed by (seed, k) (a multiply-shift
        map of a 32-bit value: the relative error of each integer's probability is below (d_max − d_min + 1)/2³²).
        """
        start, stop = sample_slice(k0, k1)
        low, high = self.bounds(rate)
        if self.kind is DelayKind.CONSTANT:
            return np.full(stop - start, low, dtype=np.int64)
        if self.kind is DelayKind.JITTER:
            if low == high:
                return np.full(stop - start, low, dtype=np.int64)
            return stream_integers(self.seed, STREAM_JITTER, start, stop, low, high)
        assert self.delays is not None  # a SEQUENCE always has delays (checked in __post_init__)
        if stop > len(self.delays):
            raise DimensionError(
                f"delays: samples up to {stop - 1} were asked for but the sequence has {len(self.delays)} entries"
            )
        return _to_samples("delays", self.delays[start:stop], float(rate))

    def __str__(self) -> str:
        if self.kind is DelayKind.CONSTANT:
            return f"DelayModel (constant tau = {self.tau_min:g} s)"
        if self.kind is DelayKind.SEQUENCE:
            assert self.delays is not None
            return f"DelayModel ({len(self.delays)} given delays in [{self.tau_min:g}, {self.tau_max:g}] s)"
        return f"DelayModel (jitter in [{self.tau_min:g}, {self.tau_max:g}] s, seed {self.seed})"


def newest_arrived(delays: Any, *, history: int) -> tuple[np.ndarray, np.ndarray]:
    """The measurement each sample uses under a time-varying delay, and the delay that implies.

    Measurement j (j >= 0) arrives at sample j + d_j. The history m_{−D}, …, m_{−1}
    (D = ``history``, normally d_max) arrives at j + D, as a constant delay D would have it;
    so for a constant delay d = D, j*(k) = k − d exactly. At sample k the controller uses
    j*(k) = max{j >= −D : arrival(j) <= k}: the newest measurement that has arrived.
    j* never decreases, so a measurement overtaken by a newer one is never used.

    Parameters
    ----------
    delays : array_like of int
        (n,) d_k >= 0 in samples, with d_k <= D.
    history : int
        D >= 0, keyword-only.

    Returns
    -------
    used, delay_used : numpy.ndarray
        (n,) j*(k) (negative: a history sample) and k − j*(k) (samples), int64, read-only.
    """
    d = np.asarray(delays)
    if d.ndim != 1 or d.size == 0:
        raise DimensionError(f"delays: expected shape (n,) but found {d.shape}")
    if not np.issubdtype(d.dtype, np.integer):
        raise SpecificationError(f"delays must be integers (samples), got dtype {d.dtype}")
    depth = integer("history", history, minimum=0)
    if np.any(d < 0) or np.any(d > depth):
        raise SpecificationError(f"delays must lie in [0, history] = [0, {depth}] samples")
    n = d.size
    j = np.arange(n, dtype=np.int64)
    arrival = j + d.astype(np.int64)
    best = np.full(n, -1 - depth, dtype=np.int64)
    on_time = arrival < n
    np.maximum.at(best, arrival[on_time], j[on_time])
    k = np.arange(n, dtype=np.int64)
    history_best = np.minimum(k - depth, -1)  # newest history sample arrived by k
    used = np.maximum(np.maximum.accumulate(best), history_best)
    return readonly(used, np.int64), readonly(k - used, np.int64)


def newest_arrived_slice(
    model: DelayModel, rate: float, depth: int, k0: int, k1: int, newest_before: int
) -> np.ndarray:
    """j*(k) of [`newest_arrived`][mrpctl.flight.newest_arrived] for the samples k0 … k1 − 1 only, in bounded memory.

    ``newest_before`` is j*(k0 − 1) (−1 − ``depth`` for k0 = 0). Only the measurements
    j ∈ [k0 − depth, k1) can arrive in the slice, so the delays of those are generated
    ([`DelayModel.samples`][mrpctl.flight.DelayModel.samples], slice independent). Concatenating the slices of any
    slicing
    gives [`newest_arrived`][mrpctl.flight.newest_arrived] of the whole horizon (int64).
    """
    start, stop = sample_slice(k0, k1)
    depth = integer("depth", depth, minimum=0)
    low = max(0, start - depth)
    j = np.arange(low, stop, dtype=np.int64)
    arrival = j + model.samples(rate, low, stop)
    inside = (arrival >= start) & (arrival < stop)
    best = np.full(stop - start, int(newest_before), dtype=np.int64)
    np.maximum.at(best, arrival[inside] - start, j[inside])
    k = np.arange(start, stop, dtype=np.int64)
    return np.maximum(np.maximum.accumulate(best), np.minimum(k - depth, -1))


@dataclass(frozen=True, eq=False)
class Disturbance:
    """External torque w in body axes (N m) added to the torque the plant sees: constant or per sample.

    Parameters
    ----------
    torque : array_like
        (3,) constant, or (n, 3) one row per measurement sample (held over the period).
    function : callable, optional
        Instead of ``torque``: w(t) of a (m,) array of sample times t_k = k h (s) returning an
        (m, 3) array (N m), evaluated by the engine on each slice's times (so memory stays bounded
        by the slice; the function should be elementwise in t, e.g. NumPy ufuncs, so that the run
        does not depend on how it is sliced). The flight and predictor loops
        ([`mrpctl.simulate`][mrpctl.simulation.simulate],
        [`mrpctl.simulate_batch`][mrpctl.simulate_batch], [`mrpctl.export`][mrpctl._export.export]: there w_k is an
        input).
    """

    torque: Any = None
    function: Any = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.function is not None:
            if self.torque is not None:
                raise SpecificationError("torque, function: give a torque array or a function of time, not both")
            if not callable(self.function):
                raise SpecificationError(f"function must be callable (w(t) -> (m, 3) N m), got {self.function!r}")
            return
        if self.torque is None:
            raise SpecificationError("torque: a (3,) or (n, 3) torque (N m), or function=w(t), is required")
        torque = finite_array("torque", self.torque)
        if torque.shape != (3,) and (torque.ndim != 2 or torque.shape[1] != 3 or torque.shape[0] == 0):
            raise DimensionError(f"torque: expected shape (3,) or (n, 3) but found {torque.shape}")
        object.__setattr__(self, "torque", readonly(torque))

    @classmethod
    def rows_view(cls, rows: np.ndarray, name: str = "torque") -> Disturbance:
        """A per-sample disturbance on the (n, 3) float64 ``rows`` without copying them (a read-only view).

        For the per-run slices of a (runs, n, 3) array given to [`mrpctl.simulate_batch`][mrpctl.simulate_batch]: the
        rows are checked (finite, shape) but not copied, so the batch holds no second copy of the
        array; the caller must not modify it while the view is in use.
        """
        array = np.asarray(rows)
        if array.dtype != np.float64:
            return cls(finite_array(name, array))
        if array.ndim != 2 or array.shape[1] != 3 or array.shape[0] == 0:
            raise DimensionError(f"{name}: expected shape (n, 3) but found {array.shape}")
        if not np.all(np.isfinite(array)):
            raise SpecificationError(f"{name} must be finite (no NaN or inf)")
        view = array.view()
        view.setflags(write=False)
        made = object.__new__(cls)
        object.__setattr__(made, "torque", view)
        object.__setattr__(made, "function", None)
        return made

    @property
    def constant(self) -> bool:
        """True for a constant torque."""
        return self.function is None and bool(self.torque.ndim == 1)

    @property
    def shape(self) -> tuple[int, ...] | None:
        """The torque array's shape (None for a function of time)."""
        return None if self.function is not None else tuple(self.torque.shape)

    def check_horizon(self, n: int, name: str = "torque") -> None:
        """Raise [`DimensionError`][mrpctl.DimensionError] (naming ``name``) if a per-sample torque does not have n
        rows."""
        n = integer("n", n, minimum=1)
        if self.function is None and not self.constant and self.torque.shape != (n, 3):
            raise DimensionError(
                f"{name}: expected shape (n, 3) = ({n}, 3) (one row per measurement sample) but found "
                f"{self.torque.shape}"
            )

    def samples(self, k0: int, k1: int, rate: float | None = None) -> np.ndarray:
        """(k1 − k0, 3) torque over samples k0 … k1 − 1 (N m); ``rate`` (Hz) for a function of time."""
        start, stop = sample_slice(k0, k1)
        if self.function is not None:
            if rate is None:
                raise SpecificationError("rate: a disturbance given as a function of time needs the sample rate")
            times = np.arange(start, stop) / positive_scalar("rate", rate)
            return finite_array(
                f"function (the disturbance w(t) at t = {times[0] if len(times) else 0.0:g} s ...)",
                self.function(times),
                (stop - start, 3),
            )
        if self.constant:
            return np.tile(self.torque, (stop - start, 1))
        if stop > len(self.torque):
            raise DimensionError(f"torque: samples up to {stop - 1} were asked for but it has {len(self.torque)} rows")
        return np.array(self.torque[start:stop])

    def __str__(self) -> str:
        if self.function is not None:
            return f"Disturbance (a function of time, {getattr(self.function, '__name__', 'callable')})"
        if self.constant:
            return "Disturbance (constant [" + ", ".join(f"{w:g}" for w in self.torque) + "] N m)"
        return f"Disturbance ({len(self.torque)} samples, max |w| {np.linalg.norm(self.torque, axis=1).max():g} N m)"


@dataclass(frozen=True)
class Hysteretic(SwitchingRule):
    """Controller-side MRP set selection with hysteresis (Mayhew, Sanfelice and Teel 2011).

    The controller keeps a logic variable h ∈ {−1, +1}. On the delayed, noisy measured
    quaternion q (made continuous in time, see [`selection_function`][mrpctl.flight.selection_function]) it sets
    h ← −h when h q₀ < −δ, and feeds σ_c = h q_v / (1 + h q₀) to its control law.
    After the rule h q₀ >= −δ, so |σ_c| <= α = √((1 + δ)/(1 − δ)). δ = 0 picks the short set
    of the measurement at every sample. Between two switches q₀ must move by more than 2δ,
    and |q̇₀| <= |ω|/2, so switches are at least 4δ/max|ω| apart; attitude noise that moves
    q₀ by less than δ never causes a switch.

    As a rule of [`mrpctl.simulate`][mrpctl.simulation.simulate] (``rule=Hysteretic(delta)``) it runs in the compiled
    flight sample ([`mrpctl.loop.flight_core_function`][mrpctl.loop.flight_core_function]): the plant's MRP is kept in
    the
    short set for bookkeeping only (no physical effect), the controller's h, c and previous
    measurement are the rule memory, u = K [σ_c; ω(t − τ)/4], and the run's switches are the
    logic switches of h. Its [`expressions`][mrpctl.switching.SwitchingRule.expressions] as a plain
    [`SwitchingRule`][mrpctl.switching.SwitchingRule] are that
    bookkeeping only (the ``OnCurrent`` test); the selection is in the flight sample.

    Parameters
    ----------
    delta : float
        Hysteresis half-width δ ∈ [0, 1) (dimensionless, on q₀). Default 0.
    """

    label: ClassVar[str] = "hysteretic"

    delta: float = 0.0

    def __post_init__(self) -> None:
        delta = finite_scalar("delta", self.delta)
        if not 0.0 <= delta < 1.0:
            raise SpecificationError(f"delta (hysteresis on the quaternion scalar q0) must be in [0, 1), got {delta}")
        object.__setattr__(self, "delta", delta + 0.0)  # -0.0 -> +0.0 (the same rule; its text shows "0")

    @classmethod
    def from_alpha(cls, alpha: float) -> Hysteretic:
        """The rule whose bound on |σ_c| is α >= 1: δ = (α² − 1)/(α² + 1)."""
        alpha = finite_scalar("alpha", alpha)
        if alpha < 1.0:
            raise SpecificationError(f"alpha (bound on |sigma_c|) must be >= 1, got {alpha}")
        square = alpha * alpha  # inf (not OverflowError, as alpha**2 raises) above ~1.3e154
        delta = (square - 1.0) / (square + 1.0) if math.isfinite(square) else 1.0
        if not delta < 1.0:
            raise SpecificationError(
                f"alpha (bound on |sigma_c|) = {alpha:g} is too large: delta = (alpha^2 - 1)/(alpha^2 + 1) rounds "
                "to 1 in floating point (alpha must stay below about 9.7e7; any alpha above the largest |sigma| of "
                "the run never switches)"
            )
        return cls(delta)

    @property
    def alpha(self) -> float:
        """α = √((1 + δ)/(1 − δ)), the bound on |σ_c| (the MRP threshold at which h flips)."""
        return math.sqrt((1.0 + self.delta) / (1.0 - self.delta))

    def parameters(self) -> tuple[float]:
        """(δ,): the run-time parameter of the flight sample."""
        return (self.delta,)

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        # The plant bookkeeping (no physical effect): the OnCurrent test.
        return ca.dot(sigma, sigma) >= 1

    def min_dwell_time(self, omega_max: float) -> float:
        """4δ/ω_max (s): the shortest time between two switches when |ω| <= ω_max (rad/s)."""
        return 4.0 * self.delta / positive_scalar("omega_max", omega_max)

    def __str__(self) -> str:
        return f"Hysteretic (h flips when h q0 < -{self.delta:g}; |sigma_c| <= alpha = {self.alpha:.6g})"
