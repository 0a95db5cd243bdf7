"""The estimator's sensors as frozen values: a late star tracker and a fast gyro with a drifting bias.

Star tracker
    At its own rate f_st (Hz) it measures the attitude of time t_m as [B̃N] = [B̃B](θ) [BN], θ a small
    rotation about the body axes with covariance R (rad²), and delivers it ``latency`` seconds later.
    R is diagonal from a per-axis 1σ, or, with a ``boresight`` b (unit, body frame),
    R = σ_⊥² (I − b bᵀ) + σ_roll² b bᵀ: the noise about the boresight (roll) differs from the noise
    across it. A measurement is lost with probability ``dropout``.
Gyro
    ω̃ = (I + diag(s)) ω + β + η_v, β̇ = η_u, with white noises of densities σ_v (angle random walk,
    rad/√s) and σ_u (bias random walk, rad/s^{3/2}), an initial bias β₀ (rad/s) and optional scale
    factor errors s (dimensionless); it is sampled at the controller rate.

The clock rules (one each, checked by [`StarTracker.clock`][mrpctl.estimation.StarTracker.clock]): the
controller rate divided by the star tracker's rate is a whole number n (the tracker measures every n-th
controller sample), and the latency times the controller rate is a whole number ℓ of controller periods,
at most the estimator's buffer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import finite_array, finite_scalar, integer, nonnegative_scalar, positive_scalar, readonly
from mrpctl.errors import SpecificationError

__all__ = ["ARCSEC", "Gyro", "SensorClock", "Sensors", "StarTracker"]

#: One arcsecond in radians.
ARCSEC = math.pi / (180.0 * 3600.0)
_WHOLE = 1e-9


def _whole(name: str, value: float, rule: str) -> int:
    count = round(value)
    if count < 0 or abs(value - count) > _WHOLE * max(1.0, abs(value)):
        raise SpecificationError(f"{name}: {rule}, got {value!r}")
    return int(count)


@dataclass(frozen=True)
class SensorClock:
    """The star tracker on the controller's clock.

    Attributes
    ----------
    every : int
        n = controller rate / star tracker rate: the tracker measures at controller samples 0, n, 2n, …
    latency : int
        ℓ = latency · controller rate: a measurement of sample k arrives at sample k + ℓ.
    period : float
        The controller period h = 1 / rate (s).
    """

    every: int
    latency: int
    period: float


@dataclass(frozen=True)
class StarTracker:
    """A star tracker: attitude noise about the body axes, its own rate, a latency, dropouts.

    Parameters
    ----------
    noise : float or array_like
        1σ of the attitude error rotation (rad): one value for every axis, or three (per body axis).
        With ``boresight``, one value: the noise across the boresight.
    rate : float
        Measurement rate f_st (Hz), > 0.
    latency : float
        Time from the measurement to its arrival at the controller (s), >= 0.
    dropout : float
        Probability in [0, 1) that a measurement is lost. Default 0.
    boresight : array_like or None
        Unit boresight axis in the body frame (normalised here); None: no boresight-dependent noise.
    roll_noise : float or None
        1σ about the boresight (rad), > 0; only with ``boresight`` (default: ``noise``).
    """

    noise: Any
    rate: float
    latency: float
    dropout: float = 0.0
    boresight: Any = None
    roll_noise: float | None = None
    covariance: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        noise = finite_array("noise", self.noise)
        if noise.shape not in ((), (3,)):
            raise SpecificationError(f"noise: one value or three (per body axis), got shape {noise.shape}")
        if np.any(noise <= 0.0):
            raise SpecificationError(f"noise must be > 0 rad (1 sigma), got {noise}")
        if np.any(noise > math.pi):
            raise SpecificationError(f"noise must be <= pi rad (1 sigma per axis), got {noise}")
        rate = positive_scalar("rate", self.rate)
        latency = nonnegative_scalar("latency", self.latency)
        dropout = finite_scalar("dropout", self.dropout)
        if not 0.0 <= dropout < 1.0:
            raise SpecificationError(f"dropout (probability a measurement is lost) must be in [0, 1), got {dropout}")
        if self.boresight is None:
            if self.roll_noise is not None:
                raise SpecificationError("roll_noise: give a boresight with it (the noise about the boresight)")
            covariance = np.diag(np.broadcast_to(noise, (3,)) ** 2)
            boresight = None
        else:
            if noise.shape != ():
                raise SpecificationError("noise: with a boresight, one value (the noise across the boresight)")
            axis = finite_array("boresight", self.boresight, (3,))
            norm = float(np.linalg.norm(axis))
            if norm <= 1e-12:
                raise SpecificationError("boresight must be a non-zero 3-vector (the boresight axis in body)")
            boresight = readonly(axis / norm)
            roll = float(noise) if self.roll_noise is None else positive_scalar("roll_noise", self.roll_noise)
            if roll > math.pi:
                raise SpecificationError(f"roll_noise must be <= pi rad (1 sigma), got {roll}")
            outer = np.outer(boresight, boresight)
            covariance = float(noise) ** 2 * (np.eye(3) - outer) + roll**2 * outer
            object.__setattr__(self, "roll_noise", roll)
        object.__setattr__(self, "noise", float(noise) if noise.shape == () else readonly(noise))
        object.__setattr__(self, "rate", rate)
        object.__setattr__(self, "latency", latency)
        object.__setattr__(self, "dropout", dropout)
        object.__setattr__(self, "boresight", boresight)
        object.__setattr__(self, "covariance", readonly(0.5 * (covariance + covariance.T)))

    @classmethod
    def from_arcsec(cls, noise: Any, rate: float, latency: float, **options: Any) -> StarTracker:
        """The tracker with ``noise`` (and ``roll_noise`` if given) in arcseconds."""
        noise = finite_array("noise", noise) * ARCSEC
        if options.get("roll_noise") is not None:
            options["roll_noise"] = finite_scalar("roll_noise", options["roll_noise"]) * ARCSEC
        return cls(noise if noise.shape else float(noise), rate, latency, **options)

    def clock(self, controller_rate: float, *, buffer: int | None = None) -> SensorClock:
        """The tracker on the controller's clock (see the module's clock rules).

        Raises
        ------
        SpecificationError
            If the controller rate is not a whole multiple of ``rate``, the latency not a whole number
            of controller periods, or longer than ``buffer`` periods.
        """
        controller_rate = positive_scalar("controller_rate", controller_rate)
        every = _whole(
            "rate",
            controller_rate / self.rate,
            f"the star tracker's rate must divide the controller rate {controller_rate:g} Hz "
            f"(controller rate / rate a whole number >= 1; rate = {self.rate:g} Hz)",
        )
        if every < 1:
            raise SpecificationError(
                f"rate: the star tracker's rate {self.rate:g} Hz must not exceed the controller rate "
                f"{controller_rate:g} Hz"
            )
        latency = _whole(
            "latency",
            self.latency * controller_rate,
            f"latency * controller rate must be a whole number of controller periods (latency = {self.latency:g} s,"
            f" controller rate = {controller_rate:g} Hz)",
        )
        if buffer is not None:
            buffer = integer("buffer", buffer, minimum=0)
            if latency > buffer:
                raise SpecificationError(
                    f"latency: {self.latency:g} s is {latency} controller periods, longer than the estimator's "
                    f"buffer of {buffer} gyro samples"
                )
        return SensorClock(every=every, latency=latency, period=1.0 / controller_rate)


@dataclass(frozen=True)
class Gyro:
    """A rate gyro: white rate noise, a bias random walk, an initial bias, optional scale factor errors.

    Parameters
    ----------
    rate_noise : float
        σ_v, the density of the white rate noise (angle random walk), rad/√s, > 0.
    bias_walk : float
        σ_u, the density of the bias random walk, rad/s^{3/2}, > 0.
    initial_bias : array_like
        β₀ (3,), rad/s. Default zero.
    scale_factor : array_like
        s (3,), the dimensionless scale factor errors (ω̃ = (I + diag(s)) ω + …), each in (−1, 1). Default zero.
    """

    rate_noise: float
    bias_walk: float
    initial_bias: Any = (0.0, 0.0, 0.0)
    scale_factor: Any = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate_noise", positive_scalar("rate_noise", self.rate_noise))
        object.__setattr__(self, "bias_walk", positive_scalar("bias_walk", self.bias_walk))
        object.__setattr__(self, "initial_bias", readonly(finite_array("initial_bias", self.initial_bias, (3,))))
        scale = finite_array("scale_factor", self.scale_factor, (3,))
        if np.any(np.abs(scale) >= 1.0):
            raise SpecificationError(f"scale_factor: each error must be in (-1, 1), got {scale}")
        object.__setattr__(self, "scale_factor", readonly(scale))

    def sample_noise(self, period: float) -> tuple[float, float]:
        """(1σ of the discrete rate noise, 1σ of the bias step) for samples ``period`` s apart.

        The discrete model of a sampled gyro (Crassidis & Junkins): over one period h,
        β_{k+1} = β_k + σ_u √h N_u and ω̃_k = ω_k + (β_{k+1} + β_k)/2 + √(σ_v²/h + σ_u² h/12) N_v.
        """
        h = positive_scalar("period", period)
        return math.sqrt(self.rate_noise**2 / h + self.bias_walk**2 * h / 12.0), self.bias_walk * math.sqrt(h)


@dataclass(frozen=True)
class Sensors:
    """The sensors of an estimated loop: a star tracker, a gyro, and the seed of their noise.

    Parameters
    ----------
    star_tracker : StarTracker
    gyro : Gyro
    seed : int
        Seed (>= 0) of the run's sensor noise (NumPy's PCG64). Default 0.
    """

    star_tracker: StarTracker
    gyro: Gyro
    seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.star_tracker, StarTracker):
            raise SpecificationError(f"star_tracker must be a StarTracker, got {type(self.star_tracker).__name__}")
        if not isinstance(self.gyro, Gyro):
            raise SpecificationError(f"gyro must be a Gyro, got {type(self.gyro).__name__}")
        object.__setattr__(self, "seed", integer("seed", self.seed, minimum=0))
