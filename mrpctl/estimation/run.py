"""The sensors' random streams and the estimator compiled over a whole run (a C loop).

[`sensor_streams`][mrpctl.estimation.run.sensor_streams] draws, from one seed, everything random about
a run of N controller samples: the gyro's bias path β_k and the error e_k = (β_{k−1} + β_k)/2 + σ_N n_k of
the reading delivered at sample k (the mean rate over [t_{k−1}, t_k]; Crassidis & Junkins' discrete gyro,
σ_N² = σ_v²/h + σ_u² h/12), the star tracker's error rotations θ_k
(N(0, R)) and which measurements arrive (every n-th sample, less the dropouts). The measured values
are formed from the true motion: ω̃_k = (I + diag(s)) ω_k + e_k, and [B̃N] = [B̃B](θ_k) [BN].

[`filter_run`][mrpctl.estimation.run.filter_run] runs the estimator's sample over given measurements: a
``mapaccum`` of the sample over `CHUNK` samples, generated as C and compiled through the project's compile path
(``mrpctl._compile.compile_function``, cached), called chunk after chunk: each call is one C loop.
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from mrpctl._compile import compile_function
from mrpctl._validation import finite_array, integer, readonly
from mrpctl.errors import SpecificationError
from mrpctl.estimation.filters import EstimatorFunctions
from mrpctl.estimation.sensors import Gyro, SensorClock, StarTracker

__all__ = [
    "CHUNK",
    "FilterRun",
    "NativeFunction",
    "SensorStreams",
    "filter_run",
    "filter_run_function",
    "sensor_streams",
]


#: Samples of one compiled call: a run is a sequence of calls of one compiled chunk (compiled once per estimator,
#: whatever the run's length).
CHUNK = 4096


@dataclass(frozen=True)
class SensorStreams:
    """The random part of the sensors over N controller samples (read-only arrays).

    Attributes
    ----------
    bias : numpy.ndarray
        (N + 1, 3) the true gyro bias (rad/s), row i at t_{i−1} (row k + 1 at sample k).
    gyro_error : numpy.ndarray
        (N, 3) e_k: ω̃_k = (I + diag(s)) ω̄_k + e_k, ω̄_k the mean rate over [t_{k−1}, t_k] (rad/s).
    rotation : numpy.ndarray
        (N, 3) the star tracker's error rotation θ_k of a measurement taken at sample k (rad).
    taken : numpy.ndarray
        (N,) 1.0 where the tracker measures at sample k and the measurement is not lost.
    """

    bias: np.ndarray
    gyro_error: np.ndarray
    rotation: np.ndarray
    taken: np.ndarray


def sensor_streams(star_tracker: StarTracker, gyro: Gyro, clock: SensorClock, samples: int, seed: int) -> SensorStreams:
    """Draw the streams of a run of ``samples`` controller periods from ``seed`` (NumPy's PCG64)."""
    n = integer("samples", samples, minimum=1)
    seed = integer("seed", seed, minimum=0)
    rng = np.random.default_rng(seed)
    h = clock.period
    rate_sigma, step_sigma = gyro.sample_noise(h)
    steps = rng.standard_normal((n, 3)) * step_sigma
    bias = np.vstack((gyro.initial_bias, gyro.initial_bias + np.cumsum(steps, axis=0)))
    gyro_error = 0.5 * (bias[:-1] + bias[1:]) + rate_sigma * rng.standard_normal((n, 3))
    rotation = rng.multivariate_normal(np.zeros(3), star_tracker.covariance, size=n, method="cholesky")
    kept = rng.random(n) >= star_tracker.dropout
    taken = ((np.arange(n) % clock.every) == 0) & kept
    return SensorStreams(readonly(bias), readonly(gyro_error), readonly(rotation), readonly(taken.astype(float)))


@dataclass(frozen=True)
class FilterRun:
    """The estimator's outputs over a run, one row per controller sample k (read-only arrays).

    Attributes
    ----------
    sigma, omega, bias : numpy.ndarray
        (N, 3) the estimate now: short-set MRP σ̂_k, rate ω̂_k = ω̃_k − β̂ (rad/s), bias β̂ (rad/s).
    covariance : numpy.ndarray
        (N, 6, 6) the covariance of the estimate now: on (δθ, Δβ) for the MEKF, (δσ, Δβ) for the MRP-EKF.
    innovation : numpy.ndarray
        (N, 3) the innovation of the measurement that arrived at k (zero when none).
    state : numpy.ndarray
        (N, state size) the filter's memory after sample k (its posterior at t_{k−ℓ}).
    """

    sigma: np.ndarray
    omega: np.ndarray
    bias: np.ndarray
    covariance: np.ndarray
    innovation: np.ndarray
    state: np.ndarray


@lru_cache(maxsize=8)
def _run_function(functions: EstimatorFunctions, samples: int) -> ca.Function:
    sample = functions.sample
    latency = functions.clock.latency
    accumulated = sample.mapaccum("estimator_samples", samples, [0, 1] if latency else [0], [0, 1] if latency else [0])
    state = ca.MX.sym("state", functions.state_size)
    ring = ca.MX.sym("ring", 3, latency)
    gyro = ca.MX.sym("gyro", 3, samples)
    measurement = ca.MX.sym("measurement", 3, samples)
    available = ca.MX.sym("available", 1, samples)
    inputs = [state] + ([ring] if latency else []) + [gyro, measurement, available]
    outputs = accumulated(*inputs)
    if latency:
        states, _, sigma, omega, bias, covariance, innovation = outputs
    else:
        states, sigma, omega, bias, covariance, innovation = outputs
    names = ["state"] + (["ring"] if latency else []) + ["gyro", "measurement", "available"]
    return ca.Function(
        f"estimator_run_{functions.kind.value}",
        inputs,
        [states, sigma, omega, bias, covariance, innovation],
        names,
        ["states", "sigma", "omega", "bias", "covariance", "innovation"],
    )


def filter_run_function(functions: EstimatorFunctions, samples: int) -> ca.Function:
    """The compiled run of ``samples`` estimator samples (cached per estimator and length).

    ``run(state, [ring,] gyro (3 × N), measurement (3 × N), available (1 × N)) -> (states, sigma, omega,
    bias, covariance, innovation)``, one column per sample.
    """
    samples = integer("samples", samples, minimum=1)
    return _compiled(functions, samples)


@lru_cache(maxsize=8)
def _compiled(functions: EstimatorFunctions, samples: int) -> ca.Function:
    return compile_function(_run_function(functions, samples)).function


def filter_run(
    functions: EstimatorFunctions,
    initial_state: Any,
    gyro: Any,
    measurement: Any,
    available: Any,
    *,
    ring: Any = None,
) -> FilterRun:
    """Run the estimator over N samples of gyro readings and arrived star-tracker measurements (compiled).

    Parameters
    ----------
    functions : EstimatorFunctions
    initial_state : array_like
        The filter's posterior at t_{−ℓ−1}
        ([`initial_state`][mrpctl.estimation.EstimatorFunctions.initial_state]).
    gyro : array_like
        (N, 3) ω̃_k (rad/s), the mean rate over [t_{k−1}, t_k] delivered at sample k.
    measurement : array_like
        (N, 3) the star tracker's MRP arriving at sample k (measured at k − ℓ); any finite value where none.
    available : array_like
        (N,) 1 where a measurement arrives at k, else 0.
    ring : array_like, optional, keyword-only
        (ℓ, 3) the gyro readings before the start (ω̃_{−ℓ} … ω̃_{−1}); default the initial bias estimate
        (the attitude held until t = 0).
    """
    state = finite_array("initial_state", initial_state, (functions.state_size,))
    gyro = finite_array("gyro", gyro, (None, 3))
    n = gyro.shape[0]
    measurement = finite_array("measurement", measurement, (n, 3))
    available = finite_array("available", available, (n,))
    if np.any((available != 0.0) & (available != 1.0)):
        raise SpecificationError("available must hold 0 or 1 (a measurement arrives at the sample or not)")
    latency = functions.clock.latency
    if ring is None:
        bias = state[functions.attitude_size : functions.attitude_size + 3]
        ring = np.tile(bias, (latency, 1))
    ring = finite_array("ring", ring, (latency, 3))
    readings = np.vstack((ring, gyro))  # readings[i] = ω̃_{i−ℓ}: the ring at sample s is readings[s : s + ℓ]
    run = filter_run_function(functions, CHUNK)
    columns: list[list[np.ndarray]] = [[] for _ in range(6)]
    for start in range(0, n, CHUNK):
        stop = min(start + CHUNK, n)
        pad = CHUNK - (stop - start)  # the last chunk runs on zeros past the end; those samples are dropped

        def block(values: np.ndarray, width: int, start: int = start, stop: int = stop, pad: int = pad) -> np.ndarray:
            return np.vstack((values[start:stop], np.zeros((pad, width)))).T

        args = [state] + ([readings[start : start + latency].T] if latency else [])
        args += [block(gyro, 3), block(measurement, 3), block(available[:, None], 1)]
        out = [np.asarray(value) for value in run(*args)]
        for column, value in zip(columns, out, strict=True):
            column.append(value[:, : stop - start])
        state = out[0][:, stop - start - 1]
    states, sigma, omega, bias, covariance, innovation = (np.hstack(column) for column in columns)
    return FilterRun(
        sigma=readonly(sigma.T),
        omega=readonly(omega.T),
        bias=readonly(bias.T),
        covariance=readonly(covariance.T.reshape(n, 6, 6).transpose(0, 2, 1)),
        innovation=readonly(innovation.T),
        state=readonly(states.T),
    )


class NativeFunction:
    """A compiled CasADi Function called through ctypes on NumPy buffers (no DM conversion).

    The generated C entry point ``name(arg, res, iw, w, mem)`` of a Function with dense inputs and
    outputs: inputs are passed as contiguous float64 arrays in CasADi's column-major order (a (rows, N) port
    as an (N, rows) C-ordered array), outputs are written into arrays this class allocates.
    """

    def __init__(self, function: ca.Function, library: Any) -> None:
        for index in range(function.n_in()):
            if not function.sparsity_in(index).is_dense():
                raise SpecificationError(f"{function.name()}: input {index} is not dense")
        for index in range(function.n_out()):
            if not function.sparsity_out(index).is_dense():
                raise SpecificationError(f"{function.name()}: output {index} is not dense")
        self.name = function.name()
        self._dll = ctypes.CDLL(str(library))
        self._call = getattr(self._dll, self.name)
        self._call.restype = ctypes.c_int
        self._call.argtypes = [ctypes.c_void_p] * 4 + [ctypes.c_int]
        work = getattr(self._dll, f"{self.name}_work")
        work.restype = ctypes.c_int
        sizes = [ctypes.c_longlong() for _ in range(4)]
        work(*[ctypes.byref(size) for size in sizes])
        self._sizes = [int(size.value) for size in sizes]
        self.in_shapes = [function.size_in(i) for i in range(function.n_in())]
        self.out_shapes = [function.size_out(i) for i in range(function.n_out())]

    def __call__(self, *inputs: Any) -> list[np.ndarray]:
        """The outputs as (columns, rows) C-ordered arrays (the transpose of CasADi's (rows, columns))."""
        arrays = []
        for (rows, columns), value in zip(self.in_shapes, inputs, strict=True):
            array = np.ascontiguousarray(np.asarray(value, dtype=float).reshape(-1, order="F"))
            if array.size != rows * columns:
                raise SpecificationError(f"{self.name}: an input of {array.size} values, expected {rows} x {columns}")
            arrays.append(array)
        outputs = [np.empty((columns, rows)) for rows, columns in self.out_shapes]
        n_arg, n_res, n_iw, n_w = self._sizes
        arg = (ctypes.c_void_p * max(n_arg, 1))(*[a.ctypes.data for a in arrays])
        res = (ctypes.c_void_p * max(n_res, 1))(*[o.ctypes.data for o in outputs])
        iw = np.zeros(max(n_iw, 1), dtype=np.int64)
        w = np.zeros(max(n_w, 1))
        status = self._call(arg, res, iw.ctypes.data, w.ctypes.data, 0)
        if status != 0:
            raise SpecificationError(f"{self.name}: the compiled function returned {status}")
        return outputs
