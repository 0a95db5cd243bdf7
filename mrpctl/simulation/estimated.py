"""The estimated loop: the control law on an estimator's attitude and rate, from a late star tracker and a gyro.

[`simulate_estimated`][mrpctl.simulation.estimated.simulate_estimated] runs one case of the loop of
[`mrpctl.loop.estimated`][mrpctl.loop.estimated] compiled over the whole run (one C loop), and returns the true,
measured and estimated states, the covariance and the innovations. ``simulate(..., sensors=..., estimator=...)``
calls it. The same loop flies two baselines (``mode``): ``"pd"``, the PD law on the last star-tracker
measurement to arrive and the raw gyro rate, and ``"predictor"``, mrpctl's model predictor on them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from mrpctl import mrp
from mrpctl._compile import SIMULATION_FLAGS, compile_function
from mrpctl._validation import available_memory, finite_array, finite_scalar, positive_scalar, readonly
from mrpctl.errors import SpecificationError
from mrpctl.estimation import CHUNK, Estimator, EstimatorFunctions, NativeFunction, Sensors, sensor_streams
from mrpctl.flight import Hysteretic
from mrpctl.loop import check_substeps
from mrpctl.loop.estimated import ESTIMATED_MODES, ESTIMATED_RECORD, EstimatedLayout, estimated_run_function
from mrpctl.model import STATE_SIZE, gain_matrix
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = ["EstimatedResult", "simulate_estimated", "simulate_estimated_as_simulate"]

#: Longest run (samples) of one compiled call; the run's arrays are about 0.6 kB per sample.
_MAX_SAMPLES = 2_000_000


@dataclass(frozen=True)
class EstimatedResult:
    """One run of the estimated loop, one row per controller sample (read-only arrays).

    Attributes
    ----------
    t : numpy.ndarray
        (N,) sample times (s).
    sigma, omega : numpy.ndarray
        (N, 3) the true attitude (short set) and rate (rad/s).
    measurement : numpy.ndarray
        (N, 3) the star tracker's MRP taken at the sample (whether or not it is kept); ``taken`` (N,) 1 where
        it is (its arrival is ``latency`` later).
    gyro : numpy.ndarray
        (N, 3) the gyro's reading delivered at the sample: the mean rate over the period before it (rad/s).
    bias : numpy.ndarray
        (N, 3) the true gyro bias (rad/s).
    sigma_hat, omega_hat : numpy.ndarray
        (N, 3) the attitude (short set) and rate the control law used: the estimate (``mode="estimator"``),
        the held measurement and the raw gyro (``"pd"``), or the prediction (``"predictor"``).
    bias_hat : numpy.ndarray
        (N, 3) the estimated bias (zero without an estimator).
    covariance : numpy.ndarray
        (N, 6, 6) the estimate's covariance (zero without an estimator), on (δθ, Δβ) for the MEKF and on
        (δσ, Δβ) for the MRP-EKF.
    innovation : numpy.ndarray
        (N, 3) the innovation of the measurement arriving at the sample (zero when none).
    u : numpy.ndarray
        (N, 3) the torque (N m).
    switches : int
        Flips of the controller's logic variable h.
    mode : str
    rate : float
        The controller rate (Hz).
    """

    t: np.ndarray
    sigma: np.ndarray
    omega: np.ndarray
    measurement: np.ndarray
    taken: np.ndarray
    gyro: np.ndarray
    bias: np.ndarray
    sigma_hat: np.ndarray
    omega_hat: np.ndarray
    bias_hat: np.ndarray
    covariance: np.ndarray
    innovation: np.ndarray
    u: np.ndarray
    switches: int
    mode: str
    rate: float

    @property
    def pointing_error(self) -> np.ndarray:
        """(N,) the true attitude's principal angle Φ = 4 arctan|σ| (rad): the error from the target."""
        return 4.0 * np.arctan(np.linalg.norm(self.sigma, axis=1))

    def pointing_rms(self, start: float = 0.0) -> float:
        """RMS of `pointing_error` (rad) over the samples at t >= ``start`` (s)."""
        start = finite_scalar("start", start)
        kept = self.pointing_error[self.t >= start]
        if not len(kept):
            raise SpecificationError(f"start: {start:g} s is after the run's last sample ({self.t[-1]:g} s)")
        return float(np.sqrt(np.mean(kept**2)))

    def settling_time(self, attitude: float = 0.01, rate: float | None = None) -> float:
        """The first time (s) from which the pointing error stays at or below ``attitude`` (rad) and, when given,
        |ω| at or below ``rate`` (rad/s) to the run's end; 0 if settled from the start, NaN if never."""
        attitude = positive_scalar("attitude", attitude)
        outside = self.pointing_error > attitude
        if rate is not None:
            outside |= np.linalg.norm(self.omega, axis=1) > positive_scalar("rate", rate)
        if outside[-1]:
            return math.nan
        above = np.nonzero(outside)[0]
        return float(self.t[above[-1] + 1]) if len(above) else 0.0

    @property
    def estimation_error(self) -> np.ndarray:
        """(N, 3) the attitude estimation error δθ (rad), the rotation from the estimate to the truth."""
        q_true = _quaternion(self.sigma)
        q_hat = _quaternion(self.sigma_hat)
        scalar = np.sum(q_true * q_hat, axis=1)
        # q_true ⊗ q̂⁻¹ (scalar first): the vector part q̂₀ q_v − q₀ q̂_v + q_v × q̂_v
        vector = q_hat[:, :1] * q_true[:, 1:] - q_true[:, :1] * q_hat[:, 1:] + np.cross(q_true[:, 1:], q_hat[:, 1:])
        sign = np.where(scalar < 0, -1.0, 1.0)[:, None]
        scalar, vector = np.abs(scalar), vector * sign
        norm = np.linalg.norm(vector, axis=1)
        factor = np.where(norm > 0, 2 * np.arctan2(norm, scalar) / np.where(norm > 0, norm, 1.0), 2.0)
        return factor[:, None] * vector


@lru_cache(maxsize=8)
def _compiled(run: ca.Function) -> Callable[..., Any]:
    """The run compiled with the simulator's flags (generated, hashed and loaded once per run Function),
    called through ctypes on NumPy buffers (CasADi's virtual machine when there is no compiler)."""
    compiled = compile_function(run, flags=SIMULATION_FLAGS)
    if compiled.library is None:
        function = compiled.function
        return lambda *args: [np.asarray(value).T for value in function(*args)]
    return NativeFunction(run, compiled.library)


def _quaternion(sigma: np.ndarray) -> np.ndarray:
    squared = np.sum(sigma**2, axis=1, keepdims=True)
    return np.concatenate(((1 - squared) / (1 + squared), 2 * sigma / (1 + squared)), axis=1)


def _initial_memory(
    layout: EstimatedLayout, functions: EstimatorFunctions, estimator: Estimator, x0: np.ndarray
) -> np.ndarray:
    memory = np.zeros(layout.size)
    latency = functions.clock.latency
    sigma0 = np.array(x0[0:3])
    if sigma0 @ sigma0 > 1:
        sigma0 = -sigma0 / (sigma0 @ sigma0)
    sl = layout.slices
    memory[sl["controller"]] = np.concatenate(((1.0, 1.0), sigma0))
    memory[sl["mean_rate"]] = 4 * x0[3:6]  # the reading delivered at t = 0: the initial rate
    guess = sigma0 if estimator.initial_sigma is None else np.array(estimator.initial_sigma)
    if layout.mode == "estimator":
        # before t = 0 the body turned at its initial rate: the filter starts at t_{−ℓ−1} on the guess turned
        # back by ω₀ (ℓ + 1) h, with the readings ω₀ + β̂₀ of the periods up to t_{−1}
        rate0 = 4 * x0[3:6]
        back = mrp.from_rotation_vector(-rate0 * (latency + 1) * functions.clock.period)
        memory[sl["filter"]] = functions.initial_state(mrp.add(guess, back), estimator.initial_bias)
        memory[sl["gyro_ring"]] = np.tile(rate0 + np.array(estimator.initial_bias), latency)
    elif layout.mode == "pd":
        memory[sl["held"]] = guess
    else:
        start = np.concatenate((guess, x0[3:6]))
        memory[sl["held"]] = np.concatenate((start, start, (float(latency),)))
        memory[sl["model"]] = start
        memory[sl["model_ring"]] = np.tile(start, latency)
        memory[sl["gyro_ring"]] = np.tile(4 * x0[3:6], latency)
    return memory


def simulate_estimated(
    spacecraft: Spacecraft,
    K: Any,
    x0: Any,
    *,
    sensors: Sensors,
    t_final: float,
    rate: float,
    estimator: Estimator | None = None,
    rule: Hysteretic | None = None,
    substeps: int = 1,
    mode: str = "estimator",
    model_spacecraft: Spacecraft | None = None,
) -> EstimatedResult:
    """Simulate the loop on the estimate of a late star tracker and a gyro (compiled over the run).

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant (its true inertia).
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    x0 : array_like
        (6,) initial true state [σ; ω/4].
    sensors : Sensors, keyword-only
        The star tracker (its latency is the loop's delay), the gyro and the noise seed.
    t_final : float, keyword-only
        Horizon (s).
    rate : float, keyword-only
        The controller's and the gyro's rate (Hz), a whole multiple of the star tracker's.
    estimator : Estimator, keyword-only
        Default ``Estimator()`` (the MEKF, the attitude known at the start, Farrenkopf's P₀).
    rule : Hysteretic, keyword-only
        The controller-side rule on the estimate; default ``Hysteretic(0)`` (the short set).
    substeps : int, keyword-only
        RK4 substeps of the plant per period.
    mode : str, keyword-only
        ``"estimator"`` (default), or the baselines ``"pd"`` and ``"predictor"`` (see the module).
    model_spacecraft : Spacecraft, keyword-only
        The predictor's model (default ``spacecraft``): its inertia J_m.
    """
    spacecraft = check_spacecraft(spacecraft)
    model_spacecraft = spacecraft if model_spacecraft is None else check_spacecraft(model_spacecraft)
    gain = gain_matrix(K)
    x0 = finite_array("x0", x0, (STATE_SIZE,))
    if not isinstance(sensors, Sensors):
        raise SpecificationError(f"sensors must be a Sensors value, got {type(sensors).__name__}")
    estimator = Estimator() if estimator is None else estimator
    if not isinstance(estimator, Estimator):
        raise SpecificationError(f"estimator must be an Estimator, got {type(estimator).__name__}")
    rule = Hysteretic() if rule is None else rule
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(f"rule: the estimated loop flies the controller-side Hysteretic rule, got {rule}")
    if mode not in ESTIMATED_MODES:
        raise SpecificationError(f"mode: one of {', '.join(ESTIMATED_MODES)}, got {mode!r}")
    if not all(np.all(np.diag(np.diag(m)) == m) for m in (spacecraft.inertia, model_spacecraft.inertia)):
        raise SpecificationError("spacecraft: the estimated loop takes a diagonal inertia (principal axes)")
    rate = positive_scalar("rate", rate)
    t_final = positive_scalar("t_final", t_final)
    substeps = check_substeps(substeps)
    n = math.floor(t_final * rate + 1e-9) + 1
    if n > _MAX_SAMPLES:
        raise SpecificationError(f"t_final: {n} samples are more than one run takes ({_MAX_SAMPLES})")
    # the records, their views and copies in the result, the noise: about 3 copies of the records' doubles
    needed = 8 * n * (3 * sum(size for _, size in ESTIMATED_RECORD) + 20)
    available = available_memory()
    if available is not None and needed > 0.5 * available:
        raise SpecificationError(
            f"t_final: a run of {n} samples needs about {needed / 2**20:.0f} MiB, more than half of the "
            f"{available / 2**20:.0f} MiB available; shorten the run or lower the rate"
        )
    functions = estimator.functions(sensors.star_tracker, sensors.gyro, rate)
    streams = sensor_streams(sensors.star_tracker, sensors.gyro, functions.clock, n, sensors.seed)
    noise = np.vstack((streams.gyro_error.T, streams.rotation.T, streams.taken[None, :]))
    run, layout = estimated_run_function(spacecraft, functions, substeps, mode, CHUNK)
    compiled = _compiled(run)
    j, j_m = np.diag(spacecraft.inertia).copy(), np.diag(model_spacecraft.inertia).copy()
    constants = (
        gain,
        rule.delta,
        j,
        np.diag(spacecraft.inertia_inverse).copy(),
        np.array(sensors.gyro.scale_factor),
        j_m,
        np.diag(model_spacecraft.inertia_inverse).copy(),
    )
    x, memory = x0, _initial_memory(layout, functions, estimator, x0)
    blocks = []
    for start in range(0, n, CHUNK):
        stop = min(start + CHUNK, n)
        # one compiled chunk of CHUNK samples, called chunk after chunk; the last one runs on zero noise past
        # the end, and those samples are dropped
        chunk = np.hstack((noise[:, start:stop], np.zeros((noise.shape[0], CHUNK - (stop - start)))))
        x_end, memory_end, block = compiled(x, memory, chunk, *constants)
        blocks.append(block[: stop - start])
        x, memory = x_end.ravel(), memory_end.ravel()
    records = np.vstack(blocks)
    parts: dict[str, np.ndarray] = {}
    start = 0
    for name, size in ESTIMATED_RECORD:
        parts[name] = records[:, start : start + size]
        start += size
    x = parts["x"]
    covariance = parts["covariance"].reshape(n, 6, 6).transpose(0, 2, 1)
    return EstimatedResult(
        t=readonly(np.arange(n) / rate),
        sigma=readonly(x[:, 0:3]),
        omega=readonly(4 * x[:, 3:6]),
        measurement=readonly(parts["measurement"]),
        taken=readonly(parts["taken"][:, 0]),
        gyro=readonly(parts["gyro"]),
        bias=readonly(streams.bias[1 : n + 1]),
        sigma_hat=readonly(parts["sigma_hat"]),
        omega_hat=readonly(parts["omega_hat"]),
        bias_hat=readonly(parts["bias_hat"]),
        covariance=readonly(covariance),
        innovation=readonly(parts["innovation"]),
        u=readonly(parts["u"]),
        switches=int(np.sum(parts["switched"])),
        mode=mode,
        rate=rate,
    )


def simulate_estimated_as_simulate(
    spacecraft: Spacecraft,
    K: Any,
    x0: Any,
    *,
    tau: float,
    rule: Any,
    t_final: float,
    rate: float,
    substeps: int,
    sensors: Sensors,
    estimator: Estimator | None,
) -> EstimatedResult:
    """``simulate(..., sensors=..., estimator=...)``: τ must be the star tracker's latency, the rule `Hysteretic`."""
    if not isinstance(sensors, Sensors):
        raise SpecificationError(f"sensors must be a Sensors value, got {type(sensors).__name__}")
    tau = float(tau)
    if not math.isclose(tau, sensors.star_tracker.latency, rel_tol=1e-9, abs_tol=1e-12):
        raise SpecificationError(
            f"tau: the estimated loop's delay is the star tracker's latency {sensors.star_tracker.latency:g} s, "
            f"got {tau:g}"
        )
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(f"rule: the estimated loop flies the controller-side Hysteretic rule, got {rule}")
    return simulate_estimated(
        spacecraft, K, x0, sensors=sensors, t_final=t_final, rate=rate, estimator=estimator, rule=rule,
        substeps=substeps,
    )  # fmt: skip
