"""The dispersed inputs of each run, from (seed, run index) alone.

Run i draws from its own generator ``default_rng(SeedSequence(seed, spawn_key=(i,)))``
(NumPy's PCG64 seeded by a SeedSequence whose spawn key is the run index), always in the
same order and always the same variates, whether or not a dispersion is enabled:

1. 4 standard normals: the attitude quaternion (uniform on SO(3) once normalised);
2. 3 standard normals and 1 uniform: the axis and the angle quantile of a
   principal-angle-restricted attitude;
3. 3 standard normals and 1 uniform: the rate direction and magnitude quantile;
4. 1 uniform: the delay grid index; 5. 1 uniform: the gain scale;
6. last, the inertia: 6 uniforms per attempt until the sample is physically valid.

So run i can be replayed on its own, and enabling one dispersion never changes the
values of another.

With R rules crossed (``[dispersions.rule]``), run i is case c = ⌊i / R⌋ under rule i mod R,
and the draws above are those of case c (spawn key (c,)): every rule sees the same cases.
The flight options draw from a second generator of the case, spawn key (c, 1), only when
the campaign uses the flight loop, always in this order: 1 uniform (δ), 1 uniform (u_max),
3 normals and 1 uniform (disturbance direction and magnitude), 1 uniform (attitude noise),
1 uniform (rate noise), 3 normals and 1 uniform (gyro bias direction and magnitude), then two
integers in [0, 2⁶³): the seeds of the run's sensor-noise and delay-jitter streams.
A tracking campaign (a ``[reference]``) draws the reference from a third generator of the case,
spawn key (c, 2): 1 uniform (slew angle), 3 normals (slew axis), 1 uniform (orbit rate)
([`mrpctl.campaign.reference`][mrpctl.campaign.reference]).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import integer, sealed
from mrpctl.campaign.distributions import Distribution
from mrpctl.campaign.reference import reference_draws, reference_values
from mrpctl.campaign.spec import AttitudeDispersion, CampaignSpec, FlightOptions
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.model import state

__all__ = [
    "RunInputs",
    "haar_angle_cdf",
    "quaternion_to_mrp",
    "run_inputs",
    "uniform_quaternions",
]

#: Attempts at a physically valid inertia before the tolerances are declared too wide.
MAX_INERTIA_ATTEMPTS = 1000


@dataclass(frozen=True, eq=False)
class RunInputs:
    """The dispersed inputs of runs ``index`` (one row each).

    Attributes
    ----------
    index : numpy.ndarray
        (N,) run indices.
    sigma0 : numpy.ndarray
        (N, 3) initial MRPs σ₀ (short set, |σ₀| <= 1 when the attitude is dispersed).
    omega0 : numpy.ndarray
        (N, 3) initial body rates ω₀ (rad/s).
    inertia : numpy.ndarray
        (N, 3, 3) inertia matrices J (kg m²).
    tau : numpy.ndarray
        (N,) delays τ (s), whole multiples of 1/rate.
    gain_scale : numpy.ndarray
        (N,) scale s of the base gain, K = s K_base.
    inertia_attempts : numpy.ndarray
        (N,) draws the inertia rejection sampler needed (1 when it is not dispersed).
    rule, case : numpy.ndarray
        (N,) index of the run's rule in ``spec.rule_list`` (i mod R) and its case ⌊i / R⌋.
    delta : numpy.ndarray
        (N,) δ of a hysteretic rule (NaN for the other rules).
    u_max : numpy.ndarray
        (N, 3) per-axis torque limits (N m; inf: none).
    disturbance : numpy.ndarray
        (N, 3) constant disturbance torques (N m).
    attitude_noise, rate_noise : numpy.ndarray
        (N,) 1σ of the attitude error rotation (rad) and of the rate noise (rad/s).
    gyro_bias : numpy.ndarray
        (N, 3) gyro biases (rad/s).
    noise_seed, jitter_seed : numpy.ndarray
        (N,) seeds of the run's sensor-noise and delay-jitter streams (0 without the flight loop).
    slew_angle, slew_axis, orbit_rate : numpy.ndarray
        A tracking campaign's reference per run: (N,) slew angle (deg), (N, 3) unit eigenaxis, (N,) orbit
        rate (rad/s); NaN where the reference has none. Empty (0 rows) without a ``[reference]``.
    """

    index: np.ndarray
    sigma0: np.ndarray
    omega0: np.ndarray
    inertia: np.ndarray
    tau: np.ndarray
    gain_scale: np.ndarray
    inertia_attempts: np.ndarray = field(repr=False)
    rule: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    case: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    delta: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    u_max: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    disturbance: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    attitude_noise: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    rate_noise: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    noise_seed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    jitter_seed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64), repr=False)
    slew_angle: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    slew_axis: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)), repr=False)
    orbit_rate: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)

    @property
    def x0(self) -> np.ndarray:
        """(N, 6) initial states x = [σ; ω/4]."""
        return state(self.sigma0, self.omega0)

    def __len__(self) -> int:
        return len(self.index)


def uniform_quaternions(normals: np.ndarray) -> np.ndarray:
    """Unit quaternions (scalar first, q₀ >= 0) from (..., 4) standard normal draws.

    A standard normal 4-vector is isotropic, so its direction is uniform on S³, and the
    unit quaternions uniform on S³ are the Haar (uniform) measure on SO(3) (Shoemake 1992;
    the double cover q ~ −q is removed by q₀ >= 0).
    """
    q = np.asarray(normals, dtype=float)
    norm = np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(norm > 0.0, q / np.where(norm > 0.0, norm, 1.0), np.array([1.0, 0.0, 0.0, 0.0]))
    return np.where(q[..., :1] < 0.0, -q, q)


def quaternion_to_mrp(q: np.ndarray) -> np.ndarray:
    """σ = q_v / (1 + q₀) of unit quaternions (scalar first, q₀ >= 0, so |σ| <= 1)."""
    return q[..., 1:] / (1.0 + q[..., :1])


def haar_angle_cdf(theta: np.ndarray | float) -> np.ndarray:
    """P(Φ <= θ) = (θ − sin θ)/π of the principal angle of a uniform rotation (θ in rad, [0, π])."""
    theta = np.asarray(theta, dtype=float)
    return (theta - np.sin(theta)) / math.pi


def _haar_angle_quantile(p: np.ndarray) -> np.ndarray:
    """Inverse of [`haar_angle_cdf`][mrpctl.campaign.sampling.haar_angle_cdf] by bisection: 64 halvings of [0, π],
    always terminates."""
    low = np.zeros_like(p)
    high = np.full_like(p, math.pi)
    for _ in range(64):
        mid = 0.5 * (low + high)
        below = haar_angle_cdf(mid) < p
        low = np.where(below, mid, low)
        high = np.where(below, high, mid)
    return 0.5 * (low + high)


def _unit(vectors: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vectors, axis=-1, keepdims=True)
    fallback = np.zeros(vectors.shape[-1])
    fallback[0] = 1.0
    return np.where(norm > 0.0, vectors / np.where(norm > 0.0, norm, 1.0), fallback)


def _attitude(
    dispersion: AttitudeDispersion, quaternion_normals: np.ndarray, axis_normals: np.ndarray, angle_quantile: np.ndarray
) -> np.ndarray:
    if dispersion.full:
        return quaternion_to_mrp(uniform_quaternions(quaternion_normals))
    low, high = (math.radians(a) for a in dispersion.angle_deg)
    p = haar_angle_cdf(low) + angle_quantile * (haar_angle_cdf(high) - haar_angle_cdf(low))
    angle = np.clip(_haar_angle_quantile(p), low, high)
    return np.tan(angle / 4.0)[:, None] * _unit(axis_normals)


def _valid_inertia(matrix: np.ndarray) -> bool:
    """Symmetric positive definite and every principal inertia <= the sum of the other two."""
    eigenvalues = np.linalg.eigvalsh(matrix)
    return bool(eigenvalues[0] > 0.0 and eigenvalues[2] <= eigenvalues[0] + eigenvalues[1])


def _inertia(spec: CampaignSpec, generator: np.random.Generator, index: int) -> tuple[np.ndarray, int]:
    base = spec.base.spacecraft.inertia
    dispersion = spec.inertia
    if dispersion is None:
        return np.array(base), 1
    upper = np.triu_indices(3, 1)
    for attempt in range(1, MAX_INERTIA_ATTEMPTS + 1):
        axes = generator.uniform(-1.0, 1.0, 3)
        products = generator.uniform(-1.0, 1.0, 3)
        matrix = np.array(base)
        matrix[np.diag_indices(3)] *= 1.0 + dispersion.axis_tolerance * axes
        offsets = np.zeros((3, 3))
        offsets[upper] = dispersion.product_tolerance * products
        matrix += offsets + offsets.T
        if _valid_inertia(matrix):
            return matrix, attempt
    raise SpecificationError(
        f"inertia: no physically valid inertia (SPD, triangle inequality) in {MAX_INERTIA_ATTEMPTS} draws for "
        f"run {index}; reduce axis_tolerance ({dispersion.axis_tolerance:g}) or product_tolerance "
        f"({dispersion.product_tolerance:g} kg m^2)"
    )


def _tau_grid(spec: CampaignSpec) -> np.ndarray:
    rate = spec.base.rate
    if spec.tau is None:
        return np.array([spec.base.tau])
    low = round(spec.tau.low * rate)
    step = round(spec.tau.step * rate)
    count = round((spec.tau.high - spec.tau.low) / spec.tau.step) + 1
    return (low + step * np.arange(count)) / rate


def run_inputs(spec: CampaignSpec, start: int, stop: int | None = None) -> RunInputs:
    """The dispersed inputs of runs start, ..., stop − 1 (stop defaults to start + 1).

    Each run's values depend only on (spec.seed, run index) and the dispersion settings.

    Raises
    ------
    SpecificationError
        If the range is outside [0, count), or the inertia tolerances admit no valid inertia.
    """
    start = integer("start", start, minimum=0, maximum=spec.count - 1)
    stop = start + 1 if stop is None else integer("stop", stop, minimum=start + 1, maximum=spec.count)
    n = stop - start
    quaternion_normals = np.empty((n, 4))
    axis_normals = np.empty((n, 3))
    angle_quantile = np.empty(n)
    rate_normals = np.empty((n, 3))
    rate_quantile = np.empty(n)
    tau_quantile = np.empty(n)
    gain_quantile = np.empty(n)
    inertia = np.empty((n, 3, 3))
    attempts = np.empty(n, dtype=np.int64)
    rules = len(spec.rule_list)
    index_all = np.arange(start, stop, dtype=np.int64)
    case_all = index_all // rules
    flight = _flight_draws(spec, case_all)
    for j, index in enumerate(case_all.tolist()):
        generator = np.random.default_rng(np.random.SeedSequence(spec.seed, spawn_key=(index,)))
        quaternion_normals[j] = generator.standard_normal(4)
        axis_normals[j] = generator.standard_normal(3)
        angle_quantile[j] = generator.random()
        rate_normals[j] = generator.standard_normal(3)
        rate_quantile[j] = generator.random()
        tau_quantile[j] = generator.random()
        gain_quantile[j] = generator.random()
        inertia[j], attempts[j] = _inertia(spec, generator, index)

    base_sigma, base_omega = spec.base.sigma0, spec.base.omega0
    if spec.attitude is None:
        sigma0 = np.tile(base_sigma, (n, 1))
    else:
        sigma0 = _attitude(spec.attitude, quaternion_normals, axis_normals, angle_quantile)
    omega0 = np.tile(base_omega, (n, 1))
    if spec.omega is not None:
        omega0 = omega0 + spec.omega.magnitude.quantile(rate_quantile)[:, None] * _unit(rate_normals)
    grid = _tau_grid(spec)
    tau = grid[np.minimum((tau_quantile * len(grid)).astype(np.int64), len(grid) - 1)]
    gain_scale = np.ones(n) if spec.gains is None else spec.gains.scale.quantile(gain_quantile)
    rule_all = index_all % rules
    tracked = {}
    if spec.tracking:
        drawn = reference_values(spec.base.reference, spec.reference, reference_draws(spec.seed, case_all))
        tracked = {name: sealed(values) for name, values in drawn.items()}
    return RunInputs(
        index=sealed(index_all),
        sigma0=sealed(sigma0),
        omega0=sealed(omega0),
        inertia=sealed(inertia),
        tau=sealed(np.array(tau)),
        gain_scale=sealed(gain_scale),
        inertia_attempts=sealed(attempts),
        rule=sealed(rule_all),
        case=sealed(case_all),
        **_flight_values(spec, rule_all, flight),
        **tracked,
    )


def _flight_draws(spec: CampaignSpec, cases: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 12) variates of the flight stream (spawn key (case, 1)) and (N, 2) stream seeds; zeros without it."""
    n = len(cases)
    draws = np.zeros((n, 12))
    seeds = np.zeros((n, 2), dtype=np.int64)
    if not spec.uses_flight and spec.flight_dispersion.delta is None:
        return draws, seeds
    for j, case in enumerate(cases.tolist()):
        generator = np.random.default_rng(np.random.SeedSequence(spec.seed, spawn_key=(case, 1)))
        draws[j, 0] = generator.random()  # delta
        draws[j, 1] = generator.random()  # u_max
        draws[j, 2:5] = generator.standard_normal(3)  # disturbance direction
        draws[j, 5] = generator.random()  # disturbance magnitude
        draws[j, 6] = generator.random()  # attitude noise
        draws[j, 7] = generator.random()  # rate noise
        draws[j, 8:11] = generator.standard_normal(3)  # gyro bias direction
        draws[j, 11] = generator.random()  # gyro bias magnitude
        seeds[j] = generator.integers(0, 2**63 - 1, size=2, dtype=np.int64, endpoint=True)
    return draws, seeds


def _uniform(distribution: Distribution | None, quantile: np.ndarray, base: float) -> np.ndarray:
    """The draws of ``distribution`` at the variates (its quantile function), or ``base`` without one."""
    if distribution is None:
        return np.full(len(quantile), base)
    return distribution.quantile(quantile)


def _flight_values(spec: CampaignSpec, rule: np.ndarray, flight: tuple[np.ndarray, np.ndarray]) -> dict[str, Any]:
    """The per-run flight options from the flight stream's variates (see the module docstring)."""
    draws, seeds = flight
    n = len(rule)
    options = spec.flight if spec.flight is not None else FlightOptions()
    dispersion = spec.flight_dispersion
    delta = np.array([r.delta if isinstance(r, Hysteretic) else np.nan for r in spec.rule_list])[rule]
    if dispersion.delta is not None:
        delta = np.where(np.isnan(delta), np.nan, _uniform(dispersion.delta, draws[:, 0], 0.0))
    if dispersion.u_max is not None:
        u_max = np.repeat(_uniform(dispersion.u_max, draws[:, 1], 0.0)[:, None], 3, axis=1)
    elif options.actuator is not None:
        u_max = np.tile(options.actuator.u_max, (n, 1))
    else:
        u_max = np.full((n, 3), np.inf)
    disturbance = np.tile(options.disturbance, (n, 1))
    if dispersion.disturbance is not None:
        disturbance = disturbance + _uniform(dispersion.disturbance, draws[:, 5], 0.0)[:, None] * _unit(draws[:, 2:5])
    gyro_bias = np.tile(options.gyro_bias, (n, 1))
    if dispersion.gyro_bias is not None:
        gyro_bias = gyro_bias + _uniform(dispersion.gyro_bias, draws[:, 11], 0.0)[:, None] * _unit(draws[:, 8:11])
    return {
        "delta": sealed(delta),
        "u_max": sealed(u_max),
        "disturbance": sealed(disturbance),
        "attitude_noise": sealed(_uniform(dispersion.attitude_noise, draws[:, 6], options.attitude_noise)),
        "rate_noise": sealed(_uniform(dispersion.rate_noise, draws[:, 7], options.rate_noise)),
        "gyro_bias": sealed(gyro_bias),
        "noise_seed": sealed(np.array(seeds[:, 0])),
        "jitter_seed": sealed(np.array(seeds[:, 1])),
    }
