"""The loop as flown: sensor, actuator, delay and disturbance models, and controller-side set selection.

The paper's loop (``mrpctl.switching``) switches the *plant's* MRP and the controller reads back
whatever set the plant was in τ ago. Flight software works differently: a star tracker reports an
attitude, the plant's MRP set is a simulation detail, and the controller alone chooses which MRP set
to feed its control law, from the delayed (noisy) measurement, keeping that choice in its own memory.
This module holds the pieces of that loop (see ``design/flight.md`` for the equations):

* option values, frozen and validated: :class:`SensorModel`, :class:`ActuatorModel`,
  :class:`DelayModel`, :class:`Disturbance`, and the controller-side rule :class:`Hysteretic`
  (Mayhew, Sanfelice and Teel 2011);
* seeded noise and jitter streams that depend only on (seed, sample index), never on how the
  horizon is sliced (:meth:`SensorModel.noise`, :meth:`DelayModel.samples`);
* the newest-arrived measurement schedule of a time-varying delay (:func:`newest_arrived`);
* the CasADi expression builders of one flight sample, each also a small pure-SX
  ``casadi.Function`` with named ports: :func:`measurement_function`,
  :func:`hysteresis_function`, :func:`selection_function`, :func:`actuator_function`.

Conventions are those of :mod:`mrpctl.mrp`: σ = tan(Φ/4) ê, quaternions scalar first,
[BN] passive, x = [σ; ω/4].
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from mrpctl._validation import finite_array, finite_scalar, integer, nonnegative_scalar, positive_scalar, readonly
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.mrp import skew_expr
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
    "NoiseForm",
    "Saturation",
    "SensorModel",
    "actuator_function",
    "compose_mrp_expr",
    "hysteresis_function",
    "measurement_function",
    "newest_arrived",
    "newest_arrived_slice",
    "quaternion_from_mrp_expr",
    "raw_measurement_function",
    "rotation_mrp_function",
    "rotation_vector_to_mrp_expr",
    "selection_function",
    "short_expr",
    "stream_key",
    "stream_normals",
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
#: The stream numbers of the attitude noise, the rate noise and the delay jitter (:func:`stream_key`).
STREAM_ATTITUDE, STREAM_RATE, STREAM_JITTER = 0, 1, 2
_DELAY_TOLERANCE = 1e-9
#: Largest attitude 1σ (rad): π per axis. The error rotation's angle wraps at π, so beyond a 1σ of π the
#: error is already spread over (nearly) every attitude and a larger number means nothing more.
_MAX_ATTITUDE_NOISE = math.pi
#: Largest rate 1σ and gyro bias (rad/s): the divergence bound of the true rate (mrpctl.simulation._stats).
_MAX_RATE_ERROR = 1e6


# ================================================================== random streams
# The NumPy mirror of mrpctl/simulation/_noise.c (read that file's header: SplitMix64 values of
# (key, idx), a 256-layer ziggurat on them); the C driver generates the same bits per sample.
_MASK64 = (1 << 64) - 1
_GAMMA = 0x9E3779B97F4A7C15
_ZIG_LAYERS = 256
_ZIG_R = 3.6541528853610088
_ATTEMPTS, _TAIL_TRIES = 64, 31  # the C loops' caps: attempt 63, tail try 30 accept their candidate
_TWO_M53 = 2.0**-53


def _mix64(z: int) -> int:
    """Stafford's Mix13, the SplitMix64 finaliser, on a Python int (mod 2^64)."""
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK64
    return z ^ (z >> 31)


def stream_key(seed: int, stream: int) -> int:
    """The 64-bit key of one stream (0 attitude, 1 rate, 2 jitter) of ``seed`` (< 2^64)."""
    return _mix64((_mix64((seed + _GAMMA) & _MASK64) + (stream + 1) * 0xD1B54A32D192ED03) & _MASK64)


def _value(key: int, idx: int) -> int:
    """Value number idx of the stream with ``key`` (scalar, Python ints)."""
    return _mix64((key + (idx + 1) * _GAMMA) & _MASK64)


def _values(key: int, idx: np.ndarray) -> np.ndarray:
    """:func:`_value` of a uint64 array of indices (uint64 arithmetic wraps mod 2^64)."""
    z = (idx + np.uint64(1)) * np.uint64(_GAMMA) + np.uint64(key)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def _ziggurat_tables() -> tuple[list[float], list[float]]:
    """X (257) and F = exp(−X²/2) of the 256-layer ziggurat, computed in float64 as documented in _noise.c."""
    r = _ZIG_R
    v = r * math.exp(-0.5 * r * r) + math.sqrt(math.pi / 2.0) * math.erfc(r / math.sqrt(2.0))
    x = [0.0] * (_ZIG_LAYERS + 1)
    x[0], x[1] = v / math.exp(-0.5 * r * r), r
    for i in range(1, _ZIG_LAYERS - 1):
        x[i + 1] = math.sqrt(-2.0 * math.log(v / x[i] + math.exp(-0.5 * x[i] * x[i])))
    f = [math.exp(-0.5 * value * value) for value in x]
    f[_ZIG_LAYERS] = 1.0
    return x, f


@lru_cache(maxsize=1)
def _c_tables() -> tuple[np.ndarray, np.ndarray]:
    """The tables as written in mrpctl/simulation/_noise.c (hex-float literals): the bits both sides use."""
    from importlib import resources

    text = resources.files("mrpctl").joinpath("simulation", "_noise.c").read_text(encoding="utf-8")
    tables = []
    for name in ("mrpctl_zig_x", "mrpctl_zig_f"):
        body = text.split(f"{name}[{_ZIG_LAYERS + 1}] = {{", 1)[1].split("}", 1)[0]
        values = [float.fromhex(item) for item in body.replace("\n", " ").split(",") if item.strip()]
        if len(values) != _ZIG_LAYERS + 1:
            raise RuntimeError(f"_noise.c: {name} has {len(values)} entries, expected {_ZIG_LAYERS + 1}")
        tables.append(np.array(values))
    return tables[0], tables[1]


def _normal_slow(key: int, n: int, table_x: np.ndarray, table_f: np.ndarray) -> float:
    """Normal number n by the C code's loop, in Python floats (math.exp / math.log: the same libm)."""
    r = float(table_x[1])
    for attempt in range(_ATTEMPTS):
        base = (n << 12) | (attempt << 6)
        h = _value(key, base)
        i, negative = h & 255, (h >> 8) & 1
        x = float(h >> 11) * _TWO_M53 * float(table_x[i])
        if x < table_x[i + 1]:
            return -x if negative else x
        if i == 0:
            for t in range(_TAIL_TRIES):
                u1 = float((_value(key, base | (2 * t + 1)) >> 11) + 1) * _TWO_M53
                u2 = float((_value(key, base | (2 * t + 2)) >> 11) + 1) * _TWO_M53
                xt = -math.log(u1) / r
                y = -math.log(u2)
                if y + y > xt * xt or t == _TAIL_TRIES - 1:
                    x = r + xt
                    return -x if negative else x
        else:
            u2 = float(_value(key, base | 1) >> 11) * _TWO_M53
            f_i, f_next = float(table_f[i]), float(table_f[i + 1])
            if f_i + u2 * (f_next - f_i) < math.exp(-0.5 * x * x) or attempt == _ATTEMPTS - 1:
                return -x if negative else x
    raise AssertionError("unreachable: the last attempt accepts")  # pragma: no cover


def stream_normals(key: int, n0: int, n1: int) -> np.ndarray:
    """Standard normal numbers n0 … n1 − 1 of the stream with ``key``, as the C code draws them (float64).

    Vectorised over the values attempt by attempt (the C loop of each value, in the same
    arithmetic); the exponentials of the wedge tests are Python's ``math.exp`` (the libm's, as in
    the C code: NumPy's own exp may differ in the last bit) and the tail, about 4 values in 10⁴,
    runs the C loop value by value (:func:`_normal_slow`, ``math.log``).
    """
    table_x, table_f = _c_tables()
    out = np.empty(n1 - n0)
    pending = np.arange(n1 - n0, dtype=np.int64)
    counters = np.arange(n0, n1, dtype=np.uint64) << np.uint64(12)
    for attempt in range(_ATTEMPTS - 1):  # the last attempt (never reached in practice) is _normal_slow's
        if pending.size == 0:
            break
        base = counters[pending] | np.uint64(attempt << 6)
        h = _values(key, base)
        layer = (h & np.uint64(255)).astype(np.intp)
        x = (h >> np.uint64(11)).astype(np.float64) * _TWO_M53 * table_x[layer]
        signed = np.where((h & np.uint64(256)) != 0, -x, x)
        accept = x < table_x[layer + 1]
        wedge = np.flatnonzero(~accept & (layer != 0))
        if wedge.size:
            wx, wi = x[wedge], layer[wedge]
            u2 = (_values(key, base[wedge] | np.uint64(1)) >> np.uint64(11)).astype(np.float64) * _TWO_M53
            height = table_f[wi] + u2 * (table_f[wi + 1] - table_f[wi])
            density = np.array([math.exp(value) for value in (-0.5 * wx * wx).tolist()])
            accept[wedge] = height < density
        out[pending[accept]] = signed[accept]
        for position in pending[~accept & (layer == 0)].tolist():  # the tail: its own loop, value by value
            out[position] = _normal_slow(key, n0 + position, table_x, table_f)
        pending = pending[~accept & (layer != 0)]
    for position in pending.tolist():
        out[position] = _normal_slow(key, n0 + position, table_x, table_f)
    return out


def _stream_normals(
    seed: int, stream: int, k0: int, k1: int, *, scale: float = 1.0, out: np.ndarray | None = None
) -> np.ndarray:
    """(k1 − k0, 3) standard normals of samples k0 … k1 − 1 of one stream, times ``scale``.

    Component c of sample k is normal number 3k + c of the stream's key (:func:`stream_normals`),
    written into ``out`` (any (k1 − k0, 3) float64 view, e.g. three columns of a wider array);
    ``scale * value`` is the C driver's product.
    """
    out = np.empty((k1 - k0, 3)) if out is None else out
    values = stream_normals(stream_key(seed, stream), 3 * k0, 3 * k1).reshape(k1 - k0, 3)
    np.multiply(values, scale, out=out)
    return out


def _stream_integers(seed: int, stream: int, k0: int, k1: int, low: int, high: int) -> np.ndarray:
    """(k1 − k0,) integers uniform in [low, high] of samples k0 … k1 − 1 of one stream (_noise.c's map)."""
    count = high - low + 1
    if not 0 < count <= 2**32:
        raise SpecificationError(f"the jitter range [{low}, {high}] must hold 1 to 2^32 whole periods")
    h = _values(stream_key(seed, stream), np.arange(k0, k1, dtype=np.uint64) << np.uint64(12))
    return low + (((h >> np.uint64(32)) * np.uint64(count)) >> np.uint64(32)).astype(np.int64)


def _slice(k0: Any, k1: Any) -> tuple[int, int]:
    start = integer("k0", k0, minimum=0)
    stop = integer("k1", k1, minimum=start)
    return start, stop


def _seed(seed: Any) -> int:
    return integer("seed", seed, minimum=0, maximum=_MASK64)


# ================================================================== option values
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
        object.__setattr__(self, "seed", _seed(self.seed))

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
            stream keyed by (seed, stream), :func:`stream_normals`).
        """
        rows = self.noise_rows(k0, k1)
        return rows[:, 0:3], rows[:, 3:6]

    def noise_rows(self, k0: int, k1: int, *, out: np.ndarray | None = None) -> np.ndarray:
        """The noise of samples k0 … k1 − 1 as one (k1 − k0, 6) array of rows (θ_k, η_k).

        The flight sample's per-sample ``noise`` input, the numbers of :meth:`noise` bit for bit,
        generated in place: into ``out`` when given (a C-contiguous float64 array of at least
        k1 − k0 rows and 6 columns, e.g. a buffer reused slice after slice; its first k1 − k0 rows
        are written and returned), else into a new array.
        """
        start, stop = _slice(k0, k1)
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
                _stream_normals(self.seed, stream, start, stop, scale=sigma, out=target)
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


class Saturation(enum.Enum):
    """How a torque limit acts on a commanded torque u."""

    #: One factor s ∈ (0, 1] on the whole vector: direction preserved, every limit met.
    SCALE = "scale"
    #: Each axis clipped on its own (independent actuators), then the norm limit by scaling.
    CLIP = "clip"


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
        :attr:`Saturation.SCALE` (default; direction-preserving) or :attr:`Saturation.CLIP`.
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
    a measurement overtaken by a newer one is never used (:func:`newest_arrived`). Build with
    :meth:`constant`, :meth:`sequence` or :meth:`jitter`.

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
        object.__setattr__(self, "seed", _seed(self.seed))
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
        """Raise :class:`DimensionError` if a sequence does not hold exactly n delays."""
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
        start, stop = _slice(k0, k1)
        low, high = self.bounds(rate)
        if self.kind is DelayKind.CONSTANT:
            return np.full(stop - start, low, dtype=np.int64)
        if self.kind is DelayKind.JITTER:
            if low == high:
                return np.full(stop - start, low, dtype=np.int64)
            return _stream_integers(self.seed, STREAM_JITTER, start, stop, low, high)
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
    """j*(k) of :func:`newest_arrived` for the samples k0 … k1 − 1 only, in bounded memory.

    ``newest_before`` is j*(k0 − 1) (−1 − ``depth`` for k0 = 0). Only the measurements
    j ∈ [k0 − depth, k1) can arrive in the slice, so the delays of those are generated
    (:meth:`DelayModel.samples`, slice independent). Concatenating the slices of any slicing
    gives :func:`newest_arrived` of the whole horizon (int64).
    """
    start, stop = _slice(k0, k1)
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
        does not depend on how it is sliced). The flight and predictor loops (:func:`mrpctl.simulate`,
        :func:`mrpctl.simulate_batch`, :func:`mrpctl.export`: there w_k is an input).
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

        For the per-run slices of a (runs, n, 3) array given to :func:`mrpctl.simulate_batch`: the
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
        """Raise :class:`DimensionError` (naming ``name``) if a per-sample torque does not have n rows."""
        n = integer("n", n, minimum=1)
        if self.function is None and not self.constant and self.torque.shape != (n, 3):
            raise DimensionError(
                f"{name}: expected shape (n, 3) = ({n}, 3) (one row per measurement sample) but found "
                f"{self.torque.shape}"
            )

    def samples(self, k0: int, k1: int, rate: float | None = None) -> np.ndarray:
        """(k1 − k0, 3) torque over samples k0 … k1 − 1 (N m); ``rate`` (Hz) for a function of time."""
        start, stop = _slice(k0, k1)
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
    quaternion q (made continuous in time, see :func:`selection_function`) it sets
    h ← −h when h q₀ < −δ, and feeds σ_c = h q_v / (1 + h q₀) to its control law.
    After the rule h q₀ >= −δ, so |σ_c| <= α = √((1 + δ)/(1 − δ)). δ = 0 picks the short set
    of the measurement at every sample. Between two switches q₀ must move by more than 2δ,
    and |q̇₀| <= |ω|/2, so switches are at least 4δ/max|ω| apart; attitude noise that moves
    q₀ by less than δ never causes a switch.

    As a rule of :func:`mrpctl.simulate` (``rule=Hysteretic(delta)``) it runs in the compiled
    flight sample (:func:`mrpctl.loop.flight_core_function`): the plant's MRP is kept in the
    short set for bookkeeping only (no physical effect), the controller's h, c and previous
    measurement are the rule memory, u = K [σ_c; ω(t − τ)/4], and the run's switches are the
    logic switches of h. Its :meth:`expressions` as a plain :class:`SwitchingRule` are that
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


# ================================================================== CasADi expressions
def rotation_vector_to_mrp_expr(theta: Any) -> Any:
    """σ = tan(|θ|/4) θ/|θ| of a rotation vector θ (rad, any angle), exactly 0 at θ = 0 (SX).

    σ = k(Φ²) θ with Φ = |θ|. For Φ <= π (|σ| <= 1), k is Cephes' rational tan (Moshier, Cephes
    2.8, ``double/tan.c``: tan x = x + x³ P(x²)/Q(x²) for |x| <= π/4, x = Φ/4), written in
    y = Φ²/16 = x² as k = 1/4 + y P(y) / (4 Q(y)): no sqrt, no tan, one division, within 1 ulp of
    tan(Φ/4)/Φ (``tests/test_sensor_rotation.py``). For Φ > π, k = tan(Φ/4)/Φ by libm (its exact
    argument reduction keeps every angle, the largest accepted noise included, the NumPy
    reference's rotation); σ may then be the long set. CasADi's if_else computes both branches
    (the virtual machine and the lanes run tan(0) on the main path); in CasADi's generated C gcc
    makes the libm call a branch, so that the main path runs neither sqrt nor tan. Both share the
    one division.
    """
    angle_squared = ca.dot(theta, theta)
    return _tan_quarter_ratio_expr(angle_squared) * theta


#: Cephes tan.c (release 2.8, June 2000, S. L. Moshier), the IEEE coefficients of P and Q (Q monic,
#: its leading 1 left out) of tan x = x + x³ P(x²)/Q(x²), |x| <= π/4; highest power first.
_TAN_P = (-1.30936939181383777646e4, 1.15351664838587416140e6, -1.79565251976484877988e7)
_TAN_Q = (1.36812963470692954678e4, -1.32089234440210967447e6, 2.50083801823357915839e7, -5.38695755929454629881e7)
#: Φ² beyond which Cephes' interval |Φ/4| <= π/4 is left (π² in float64, within an ulp of π²).
_PI_SQUARED = math.pi * math.pi


def _tan_quarter_ratio_expr(angle_squared: Any) -> Any:
    """k = tan(Φ/4)/Φ from Φ² = ``angle_squared`` (SX): 1/4 at 0; see :func:`rotation_vector_to_mrp_expr`."""
    y = 0.0625 * angle_squared  # x² = Φ²/16 exactly (a power of two)
    p = (_TAN_P[0] * y + _TAN_P[1]) * y + _TAN_P[2]
    q = (((y + _TAN_Q[0]) * y + _TAN_Q[1]) * y + _TAN_Q[2]) * y + _TAN_Q[3]
    wide = angle_squared > _PI_SQUARED
    # Φ > π: tan(Φ/4)/Φ as before (sqrt(0) and tan(0) where both branches are computed)
    angle = ca.sqrt(ca.if_else(wide, angle_squared, 0.0))
    numerator = ca.if_else(wide, ca.tan(0.25 * angle), y * p)
    denominator = ca.if_else(wide, angle, 4.0 * q)  # 4 Q exactly: k = 1/4 + yP/(4Q) = (1 + yP/Q)/4
    return ca.if_else(wide, 0.0, 0.25) + numerator / denominator


def compose_mrp_expr(sigma_first: Any, sigma_second: Any) -> Any:
    """σ(F/N) of [FN] = [FB][BN] from σ_first = σ(B/N) and σ_second = σ(F/B) (SX).

    σ = ((1 − |σ₁|²) σ₂ + (1 − |σ₂|²) σ₁ − 2 σ₂ × σ₁) / (1 + |σ₁|² |σ₂|² − 2 σ₁·σ₂)
    (Schaub & Junkins Eq. 3.152), the quaternion product written in MRPs. The result may be
    the long set. With σ₂ = 0 it returns σ₁ exactly (bit for bit).
    """
    s1 = ca.dot(sigma_first, sigma_first)
    s2 = ca.dot(sigma_second, sigma_second)
    numerator = (1 - s1) * sigma_second + (1 - s2) * sigma_first - 2 * (skew_expr(sigma_second) @ sigma_first)
    return numerator * (1 / (1 + s1 * s2 - 2 * ca.dot(sigma_first, sigma_second)))  # one division, not three


def short_expr(sigma: Any) -> Any:
    """The short set (|σ| <= 1) of σ (SX): σ unchanged when |σ|² <= 1, else −σ/|σ|²."""
    squared = ca.dot(sigma, sigma)
    return ca.if_else(squared > 1, _safe_shadow_expr(sigma, squared), sigma)


def _safe_shadow_expr(sigma: Any, squared: Any) -> Any:
    # −σ/|σ|² from |σ|² = ``squared`` (computed once by the caller: SX does not merge two dot products).
    # Both if_else branches are evaluated: keep the unused shadow of σ = 0 finite.
    return sigma * (-1 / ca.if_else(squared > 0, squared, 1.0))  # one division, not three


def quaternion_from_mrp_expr(sigma: Any) -> Any:
    """β = ((1 − |σ|²)/(1 + |σ|²), 2σ/(1 + |σ|²)) (scalar first) of σ (SX); β₀ >= 0 for a short σ."""
    squared = ca.dot(sigma, sigma)
    return ca.vertcat((1 - squared) / (1 + squared), 2 * sigma / (1 + squared))


class NoiseForm(enum.Enum):
    """How a sample receives the sensor's attitude noise.

    ``ROTATION_VECTOR``: θ (rad), and the sample computes its MRP σ(θ) (:func:`rotation_vector_to_mrp_expr`):
    the exported samples, the virtual machine and the lane engine. ``MRP``: σ(θ) itself, computed before the
    sample by :func:`rotation_mrp_function` (the same expressions, so the same bits): the compiled scalar
    engine, which turns a block of θ rows into their MRPs at once, so that tan's latency is not on the
    sample's path.
    """

    ROTATION_VECTOR = "rotation_vector"
    MRP = "mrp"


@lru_cache(maxsize=1)
def rotation_mrp_function() -> ca.Function:
    """``rotation_mrp(rotation_noise) -> rotation_noise_mrp``: σ(θ) of :func:`rotation_vector_to_mrp_expr` (pure SX)."""
    theta = ca.SX.sym("rotation_noise", 3)
    return ca.Function(
        "rotation_mrp", [theta], [rotation_vector_to_mrp_expr(theta)], ["rotation_noise"], ["rotation_noise_mrp"]
    )


def _sensor_expressions(form: NoiseForm) -> tuple[list[Any], list[str], Any, Any]:
    """The sensor's inputs (x, rotation noise, rate noise, bias), their names, σ ⊕ σ(θ) (either set) and ω̃."""
    if not isinstance(form, NoiseForm):
        raise SpecificationError(f"form must be a mrpctl.flight.NoiseForm, got {form!r}")
    x = ca.SX.sym("x", 6)
    noise_name = "rotation_noise" if form is NoiseForm.ROTATION_VECTOR else "rotation_noise_mrp"
    noise = ca.SX.sym(noise_name, 3)
    eta = ca.SX.sym("rate_noise", 3)
    bias = ca.SX.sym("bias", 3)
    rotation = rotation_vector_to_mrp_expr(noise) if form is NoiseForm.ROTATION_VECTOR else noise
    omega_meas = 4 * x[3:6] + bias + eta
    names = ["x", noise_name, "rate_noise", "bias"]
    return [x, noise, eta, bias], names, compose_mrp_expr(x[0:3], rotation), omega_meas


@lru_cache(maxsize=2)
def measurement_function(form: NoiseForm = NoiseForm.ROTATION_VECTOR) -> ca.Function:
    """``measurement(x, rotation_noise, rate_noise, bias) -> (x_meas, q_meas)`` (pure SX).

    x = [σ; ω/4] is the true state (σ in either set). The sensor reports the short set of
    the measured attitude, σ̃ = short(σ ⊕ σ(θ)) with [B̃N] = [B̃B](θ)[BN], the rate
    ω̃ = ω + b + η, and x_meas = [σ̃; ω̃/4]; q_meas is σ̃'s quaternion (β₀ >= 0). With zero
    noise and bias and a short σ, x_meas is x bit for bit. With ``form`` = :attr:`NoiseForm.MRP` the
    second input is σ(θ) (``rotation_noise_mrp``, from :func:`rotation_mrp_function`) instead of θ:
    the same numbers, bit for bit. :func:`raw_measurement_function` is the same before the short set.
    """
    inputs, names, composed, omega_meas = _sensor_expressions(form)
    sigma_meas = short_expr(composed)
    x_meas = ca.vertcat(sigma_meas, 0.25 * omega_meas)  # = omega_meas / 4 exactly (a power of two)
    return ca.Function(
        "measurement", inputs, [x_meas, quaternion_from_mrp_expr(sigma_meas)], names, ["x_meas", "q_meas"]
    )


@lru_cache(maxsize=2)
def raw_measurement_function(form: NoiseForm = NoiseForm.ROTATION_VECTOR) -> ca.Function:
    """``raw_measurement(x, rotation_noise, rate_noise, bias) -> x_raw`` (pure SX): [σ ⊕ σ(θ); ω̃/4].

    :func:`measurement_function` before its short set: the attitude in either set, so that
    x_meas = [short(x_raw[0:3]); x_raw[3:6]] bit for bit. The flight sample puts x_raw in its ring
    and takes the short set of the delayed entry, which it needs for the history anyway: one short
    set a sample, not two.
    """
    inputs, names, composed, omega_meas = _sensor_expressions(form)
    return ca.Function("raw_measurement", inputs, [ca.vertcat(composed, 0.25 * omega_meas)], names, ["x_raw"])


@lru_cache(maxsize=1)
def hysteresis_function() -> ca.Function:
    """``hysteresis(h, q, delta) -> (h_next, sigma_c, switched)`` (pure SX): the Mayhew-Sanfelice-Teel rule.

    q (4, scalar first, unit) is the measured quaternion, continuous in time (its sign
    chosen by continuity, not by β₀ >= 0). h_next = −h when h q₀ < −δ, else h;
    σ_c = h_next q_v / (1 + h_next q₀); switched = 1.0 when h flipped.
    """
    h = ca.SX.sym("h")
    q = ca.SX.sym("q", 4)
    delta = ca.SX.sym("delta")
    switched = ca.if_else(h * q[0] < -delta, 1.0, 0.0)
    h_next = ca.if_else(switched, -h, h)
    sigma_c = h_next * q[1:4] / (1 + h_next * q[0])
    return ca.Function(
        "hysteresis", [h, q, delta], [h_next, sigma_c, switched], ["h", "q", "delta"], ["h_next", "sigma_c", "switched"]
    )


@lru_cache(maxsize=1)
def selection_function() -> ca.Function:
    """``selection(h, c, sigma_meas, sigma_prev, delta) -> (h_next, c_next, sigma_c, switched)`` (pure SX).

    The controller-side rule on the sensor's short-set MRP σ̃ (β̃₀ >= 0), in the form the
    flight sample uses. The controller's continuous quaternion is q̂ = c β̃: c ∈ {−1, +1}
    flips when β̃ and the previous measurement's β̃' point to opposite hemispheres,
    β̃·β̃' < 0 ⇔ (1 − |σ̃|²)(1 − |σ̃'|²) + 4 σ̃·σ̃' < 0 (the attitude passed Φ = 180°).
    Then the rule of :func:`hysteresis_function` on q̂: with e = h c, h flips when
    e β̃₀ < −δ ⇔ e < 0 and (1 + δ)|σ̃|² < 1 − δ. σ_c = σ̃ when h_next c_next = +1 (bit for
    bit) and its shadow −σ̃/|σ̃|² otherwise. Identical to :func:`hysteresis_function` on q̂ up
    to rounding; with δ = 0 σ_c is σ̃ at every sample. h and c are ±1 (flips are products by ±1).
    """
    h = ca.SX.sym("h")
    c = ca.SX.sym("c")
    sigma = ca.SX.sym("sigma_meas", 3)
    previous = ca.SX.sym("sigma_prev", 3)
    delta = ca.SX.sym("delta")
    s_now = ca.dot(sigma, sigma)
    s_prev = ca.dot(previous, previous)
    flipped = (1 - s_now) * (1 - s_prev) + 4 * ca.dot(sigma, previous) < 0
    # h, c = ±1: a flip is a product by ±1 (exact), not an if_else (two selects and an add)
    c_next = c * (1 - 2 * flipped)
    effective = h * c_next
    switched = ca.if_else(ca.logic_and(effective < 0, (1 + delta) * s_now < 1 - delta), 1.0, 0.0)
    h_next = h * (1 - 2 * switched)
    # σ_c = σ (e = h_next c_next = +1) or its shadow −σ/|σ|²: σ times one selected factor, not three
    # selected components. if_else(e > 0, σ, shadow) was (e > 0 ? σ : 0) + (e <= 0 ? shadow : 0), which
    # turns a −0 into +0: so does the + (e² − 1) = +0 here (an exact zero that CasADi does not fold away).
    e = h_next * c_next
    factor = ca.if_else(e > 0, 1.0, -1 / ca.if_else(s_now > 0, s_now, 1.0))
    sigma_c = sigma * factor + (e * e - 1)
    return ca.Function(
        "selection",
        [h, c, sigma, previous, delta],
        [h_next, c_next, sigma_c, switched],
        ["h", "c", "sigma_meas", "sigma_prev", "delta"],
        ["h_next", "c_next", "sigma_c", "switched"],
    )


@lru_cache(maxsize=2)
def actuator_function(mode: Saturation = Saturation.SCALE) -> ca.Function:
    """``actuator(u, u_max, norm_max, w) -> (u_applied, u_plant, saturated)`` (pure SX).

    ``SCALE``: u_applied = u / r with r = max(maxᵢ |uᵢ|/u_max,ᵢ, |u|/u_norm) when r > 1
    (direction preserved), then clipped per axis so that rounding never exceeds u_max.
    ``CLIP``: uᵢ clipped to [−u_max,ᵢ, u_max,ᵢ], then scaled by u_norm/|u| if |u| > u_norm.
    A limit that is not reached leaves u bit for bit; ``norm_max`` = inf means no norm limit.
    u_plant = u_applied + w (the disturbance torque). saturated = 1.0 when a limit acted.
    """
    if not isinstance(mode, Saturation):
        raise SpecificationError(f"mode must be a mrpctl.flight.Saturation, got {mode!r}")
    u = ca.SX.sym("u", 3)
    u_max = ca.SX.sym("u_max", 3)
    norm_max = ca.SX.sym("norm_max")
    w = ca.SX.sym("w", 3)
    if mode is Saturation.SCALE:
        ratio = ca.fmax(ca.mmax(ca.fabs(u) / u_max), ca.norm_2(u) / norm_max)
        saturated = ratio > 1
        # u / r when r > 1, else u: one divisor selected, not three quotients (u / 1 is u exactly); the
        # if_else added +0 to the chosen branch (−0 → +0), and so does saturated² − saturated (= +0)
        scaled = u / ca.if_else(saturated, ratio, 1.0) + (saturated * saturated - saturated)
        applied = ca.fmin(ca.fmax(scaled, -u_max), u_max)
    else:
        clipped = ca.fmin(ca.fmax(u, -u_max), u_max)
        ratio = ca.norm_2(clipped) / norm_max
        scaled = ratio > 1
        applied = clipped / ca.if_else(scaled, ratio, 1.0) + (scaled * scaled - scaled)  # as in SCALE
        saturated = ca.logic_or(ca.mmax(ca.fabs(u) - u_max) > 0, ratio > 1)
    return ca.Function(
        "actuator",
        [u, u_max, norm_max, w],
        [applied, applied + w, saturated],  # a comparison: 1.0 or 0.0
        ["u", "u_max", "norm_max", "w"],
        ["u_applied", "u_plant", "saturated"],
    )
