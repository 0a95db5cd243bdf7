"""An independent NumPy reimplementation of the flight loop's random streams (mrpctl/engines/noise.c).

The package has one generator, the C code of noise.c (mrpctl.flight.streams calls it); this file is the
tests' reference: the SplitMix64 values, the 256-layer ziggurat and the jitter map written again in NumPy
and Python ints from noise.c's header, compared bit for bit with the C code on >= 10^6 values.
"""

from __future__ import annotations

import math
from functools import lru_cache
from importlib import resources

import numpy as np

# The NumPy mirror of mrpctl/engines/noise.c (read that file's header: SplitMix64 values of
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


def value(key: int, idx: int) -> int:
    """Value number idx of the stream with ``key`` (Python ints)."""
    return _value(key, idx)


def values(key: int, idx: np.ndarray) -> np.ndarray:
    """Values of a uint64 array of indices."""
    return _values(key, idx)


def _value(key: int, idx: int) -> int:
    """Value number idx of the stream with ``key`` (scalar, Python ints)."""
    return _mix64((key + (idx + 1) * _GAMMA) & _MASK64)


def _values(key: int, idx: np.ndarray) -> np.ndarray:
    """`_value` of a uint64 array of indices (uint64 arithmetic wraps mod 2^64)."""
    z = (idx + np.uint64(1)) * np.uint64(_GAMMA) + np.uint64(key)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def _ziggurat_tables() -> tuple[list[float], list[float]]:
    """X (257) and F = exp(−X²/2) of the 256-layer ziggurat, computed in float64 as documented in noise.c."""
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
    """The tables as written in mrpctl/engines/noise.c (hex-float literals): the bits both sides use."""

    text = resources.files("mrpctl").joinpath("engines", "noise.c").read_text(encoding="utf-8")
    tables = []
    for name in ("mrpctl_zig_x", "mrpctl_zig_f"):
        body = text.split(f"{name}[{_ZIG_LAYERS + 1}] = {{", 1)[1].split("}", 1)[0]
        values = [float.fromhex(item) for item in body.replace("\n", " ").split(",") if item.strip()]
        if len(values) != _ZIG_LAYERS + 1:
            raise RuntimeError(f"noise.c: {name} has {len(values)} entries, expected {_ZIG_LAYERS + 1}")
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
    runs the C loop value by value (`_normal_slow`, ``math.log``).
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


def stream_normal_rows(
    seed: int, stream: int, k0: int, k1: int, *, scale: float = 1.0, out: np.ndarray | None = None
) -> np.ndarray:
    """(k1 − k0, 3) standard normals of samples k0 … k1 − 1 of one stream, times ``scale``.

    Component c of sample k is normal number 3k + c of the stream's key
    (`stream_normals`),
    written into ``out`` (any (k1 − k0, 3) float64 view, e.g. three columns of a wider array);
    ``scale * value`` is the C driver's product.
    """
    out = np.empty((k1 - k0, 3)) if out is None else out
    values = stream_normals(stream_key(seed, stream), 3 * k0, 3 * k1).reshape(k1 - k0, 3)
    np.multiply(values, scale, out=out)
    return out


def stream_integers(seed: int, stream: int, k0: int, k1: int, low: int, high: int) -> np.ndarray:
    """(k1 − k0,) integers uniform in [low, high] of samples k0 … k1 − 1 of one stream (noise.c's map)."""
    count = high - low + 1
    if not 0 < count <= 2**32:
        raise ValueError(f"the jitter range [{low}, {high}] must hold 1 to 2^32 whole periods")
    h = _values(stream_key(seed, stream), np.arange(k0, k1, dtype=np.uint64) << np.uint64(12))
    return low + (((h >> np.uint64(32)) * np.uint64(count)) >> np.uint64(32)).astype(np.int64)
