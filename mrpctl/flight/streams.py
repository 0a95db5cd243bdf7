"""Seeded random streams of the loop as flown: counter-based SplitMix64 values and a 53-bit ziggurat.

One generator: the C code of ``mrpctl/engines/noise.c`` (read its header for the algorithm), compiled
alone once (cached on disk like every compiled engine) and called here through ctypes; the compiled
engines include the same file. Every number depends only on (seed, stream, sample index): never on
slicing, lanes or threads. The tests check it bit for bit against an independent NumPy reimplementation.
"""

from __future__ import annotations

import ctypes
import threading
from importlib import resources
from typing import Any

import numpy as np

from mrpctl._compile import SIMULATION_FLAGS, compile_source, find_compiler
from mrpctl._validation import integer
from mrpctl.errors import MrpctlError, SpecificationError

__all__ = [
    "noise_library",
    "sample_slice",
    "stream_integers",
    "stream_key",
    "stream_normal_rows",
    "stream_normals",
    "stream_seed",
]

_MASK64 = (1 << 64) - 1
_LIBRARY: list[Any] = []
_LOCK = threading.Lock()


def noise_library() -> Any:
    """``noise.c`` compiled alone (once per process; the library is cached on disk), as a ``ctypes.CDLL``.

    Its ``mrpctl_stream_fill(key, n0, count, scale, integers, lo, hi, out, row_stride)`` writes value
    i < count (normal or jitter number n0 + i) to ``out[(i / 3) row_stride + i % 3]``, and
    ``mrpctl_stream_key(seed, stream)`` is a stream's key.

    Raises
    ------
    MrpctlError
        Without a C compiler (the streams, like the engines, are compiled C).
    """
    with _LOCK:
        if not _LIBRARY:
            if find_compiler() is None:
                raise MrpctlError(
                    "the sensor noise and delay jitter streams are compiled C (mrpctl/engines/noise.c): "
                    "install gcc or cc, or set CC"
                )
            code = resources.files("mrpctl").joinpath("engines", "noise.c").read_text(encoding="utf-8")
            library = ctypes.CDLL(str(compile_source(code, "mrpctl_noise", flags=SIMULATION_FLAGS)))
            library.mrpctl_stream_fill.restype = None
            library.mrpctl_stream_fill.argtypes = [
                ctypes.c_ulonglong,
                ctypes.c_longlong,
                ctypes.c_longlong,
                ctypes.c_double,
                ctypes.c_int,
                ctypes.c_longlong,
                ctypes.c_longlong,
                ctypes.c_void_p,
                ctypes.c_longlong,
            ]
            library.mrpctl_stream_key.restype = ctypes.c_ulonglong
            library.mrpctl_stream_key.argtypes = [ctypes.c_ulonglong, ctypes.c_ulonglong]
            _LIBRARY.append(library)
        return _LIBRARY[0]


def stream_key(seed: int, stream: int) -> int:
    """The 64-bit key of one stream (0 attitude, 1 rate, 2 jitter) of ``seed`` (< 2^64), from noise.c."""
    seed = integer("seed", seed, minimum=0, maximum=_MASK64)
    stream = integer("stream", stream, minimum=0, maximum=_MASK64 - 1)
    return int(noise_library().mrpctl_stream_key(seed, stream))


def stream_normals(key: int, n0: int, n1: int) -> np.ndarray:
    """Standard normal numbers n0 … n1 − 1 of the stream with ``key`` (float64), drawn by noise.c."""
    key = integer("key", key, minimum=0, maximum=_MASK64)
    n0 = integer("n0", n0, minimum=0)
    n1 = integer("n1", n1, minimum=n0)
    out = np.empty(n1 - n0)
    if n1 > n0:
        noise_library().mrpctl_stream_fill(key, n0, n1 - n0, 1.0, 0, 0, 0, out.ctypes.data, 3)
    return out


def stream_normal_rows(
    seed: int, stream: int, k0: int, k1: int, *, scale: float = 1.0, out: np.ndarray | None = None
) -> np.ndarray:
    """(k1 − k0, 3) standard normals of samples k0 … k1 − 1 of one stream, times ``scale``.

    Component c of sample k is normal number 3k + c of the stream's key
    ([`stream_normals`][mrpctl.flight.stream_normals]), written into ``out`` (any (k1 − k0, 3) float64
    view, e.g. three columns of a wider array); ``scale * value`` is the C driver's product (scale 0:
    exact zeros).
    """
    rows = k1 - k0
    target = out if out is not None else np.empty((rows, 3))
    direct = (
        target.dtype == np.float64
        and target.shape == (rows, 3)
        and target.strides[1] == 8
        and target.strides[0] % 8 == 0
        and target.strides[0] >= 24
        and target.flags.writeable
    )
    work = target if direct else np.empty((rows, 3))
    if rows > 0:
        noise_library().mrpctl_stream_fill(
            stream_key(seed, stream), 3 * k0, 3 * rows, float(scale), 0, 0, 0, work.ctypes.data, work.strides[0] // 8
        )
    if not direct:
        target[...] = work
    return target


def stream_integers(seed: int, stream: int, k0: int, k1: int, low: int, high: int) -> np.ndarray:
    """(k1 − k0,) integers uniform in [low, high] of samples k0 … k1 − 1 of one stream (noise.c's map)."""
    count = high - low + 1
    if not 0 < count <= 2**32:
        raise SpecificationError(f"the jitter range [{low}, {high}] must hold 1 to 2^32 whole periods")
    out = np.empty(k1 - k0)
    if k1 > k0:
        noise_library().mrpctl_stream_fill(stream_key(seed, stream), k0, k1 - k0, 0.0, 1, low, high, out.ctypes.data, 3)
    return out.astype(np.int64)


def sample_slice(k0: Any, k1: Any) -> tuple[int, int]:
    """(k0, k1) checked: whole numbers with 0 <= k0 <= k1."""
    start = integer("k0", k0, minimum=0)
    stop = integer("k1", k1, minimum=start)
    return start, stop


def stream_seed(seed: Any) -> int:
    """``seed`` checked: a whole number in [0, 2^64)."""
    return integer("seed", seed, minimum=0, maximum=_MASK64)
