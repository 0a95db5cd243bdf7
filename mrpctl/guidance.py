"""Guidance profiles: the reference motion (σ_R/N, ω_R/N, ω̇_R/N) a tracking loop follows.

A reference is an (n, 9) float array, one row per controller sample t_k = k / rate, in the
convention of Basilisk's ``AttRefMsgPayload``:

=========  ============================  ==========================================
columns    quantity                      units, frame
=========  ============================  ==========================================
0-2        σ_R/N (``sigma_RN``)          MRP, short set |σ| <= 1
3-5        ω_R/N (``omega_RN_N``)        rad/s, components in the inertial frame N
6-8        ω̇_R/N (``domega_RN_N``)       rad/s², components in N (N-frame derivative)
=========  ============================  ==========================================

Each profile is a small frozen value object, checked when it is made, with
``samples(t) -> (len(t), 9)``:

* [`InertialPointing`][mrpctl.guidance.InertialPointing]: a fixed attitude;
* [`EigenaxisSlew`][mrpctl.guidance.EigenaxisSlew]: a rest-to-rest rotation about a fixed
  eigenaxis with a trapezoidal rate (bounded rate and acceleration);
* [`NadirPointing`][mrpctl.guidance.NadirPointing]: the Hill frame of a
  [`CircularOrbit`][mrpctl.guidance.CircularOrbit] (Basilisk's ``hillPoint``);
* [`FileReference`][mrpctl.guidance.FileReference]: rows read from a ``.csv`` or ``.npy`` file.

Attitudes are composed as direction cosine matrices with [`mrpctl.mrp`][mrpctl.mrp]
([BN] passive, ``design/conventions.md``) and returned as short-set MRPs.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import numpy as np

from mrpctl._files import read_numbers
from mrpctl._validation import finite_array, finite_scalar, nonnegative_scalar, positive_scalar, readonly
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.mrp import from_dcm, from_principal_rotation, short, subtract, to_dcm, to_principal_rotation

__all__ = [
    "EARTH_MU",
    "EARTH_RADIUS",
    "REFERENCE_COLUMNS",
    "CircularOrbit",
    "EigenaxisSlew",
    "FileReference",
    "GuidanceProfile",
    "InertialPointing",
    "NadirPointing",
    "check_reference",
    "reference_samples",
]

#: The Earth's gravitational parameter μ (m³/s²): 398600.4415 km³/s², the JGM-3 value. Basilisk 2.12 uses
#: 398600.436 km³/s² (``orbitalMotion.MU_EARTH`` and ``gravBodyFactory().createEarth().mu``): pass ``mu=`` to fly
#: a Basilisk run's orbit (at one altitude the two rates differ by 6.9e-9 relative).
EARTH_MU = 3.986004415e14
#: The Earth's equatorial radius (m, Basilisk's ``REQ_EARTH`` = 6378.1366 km).
EARTH_RADIUS = 6378136.6
#: The 9 columns of a reference row.
REFERENCE_COLUMNS = (
    "sigma_RN_1",
    "sigma_RN_2",
    "sigma_RN_3",
    "omega_RN_N_1",
    "omega_RN_N_2",
    "omega_RN_N_3",
    "domega_RN_N_1",
    "domega_RN_N_2",
    "domega_RN_N_3",
)
#: |σ| may exceed 1 by this much in a given attitude (rounding of a set at exactly |σ| = 1).
_SHORT_TOLERANCE = 1e-9
#: | |axis| − 1 | allowed for a unit axis.
_UNIT_TOLERANCE = 1e-9


@runtime_checkable
class GuidanceProfile(Protocol):
    """What every guidance profile provides: ``samples(t)``, the (len(t), 9) reference rows at times t (s)."""

    def samples(self, t: Any) -> np.ndarray: ...


def _times(t: Any) -> np.ndarray:
    times = finite_array("t", t)
    if times.ndim == 0:
        times = times.reshape(1)
    if times.ndim != 1:
        raise DimensionError(f"t: expected a 1-D array of times (s) but found shape {times.shape}")
    return times


def _attitude(name: str, value: Any) -> np.ndarray:
    """A short-set MRP attitude (3,): finite, |σ| <= 1 (to 1e-9)."""
    sigma = finite_array(name, value, (3,))
    norm = float(np.linalg.norm(sigma))
    if norm > 1.0 + _SHORT_TOLERANCE:
        raise SpecificationError(
            f"{name} must be a short-set MRP (|sigma| <= 1), got |sigma| = {norm:.6g}; give its shadow set "
            "-sigma/|sigma|^2 (mrpctl.mrp.short), the same attitude"
        )
    return readonly(sigma)


def _unit(name: str, value: Any) -> np.ndarray:
    vector = finite_array(name, value, (3,))
    norm = float(np.linalg.norm(vector))
    if abs(norm - 1.0) > _UNIT_TOLERANCE:
        raise SpecificationError(f"{name} must be a unit vector (|{name}| = 1 to 1e-9), got |{name}| = {norm:.9g}")
    return readonly(vector / norm)


def _vector_text(values: np.ndarray) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"


# ------------------------------------------------------------------------------------------ inertial
@dataclass(frozen=True, eq=False)
class InertialPointing:
    """Hold a fixed attitude: σ_R/N constant, ω_R/N = ω̇_R/N = 0 (Basilisk's ``inertial3D``).

    Attributes
    ----------
    sigma : numpy.ndarray
        σ_R/N (3), a short-set MRP (|σ| <= 1).
    """

    sigma: np.ndarray = field(default_factory=lambda: np.zeros(3))

    def __post_init__(self) -> None:
        object.__setattr__(self, "sigma", _attitude("sigma", self.sigma))

    def samples(self, t: Any) -> np.ndarray:
        """The reference rows (len(t), 9) at times ``t`` (s)."""
        times = _times(t)
        out = np.zeros((len(times), 9))
        out[:, 0:3] = self.sigma
        return out

    def __str__(self) -> str:
        angle = math.degrees(float(to_principal_rotation(self.sigma)[1]))
        return f"inertial pointing: sigma_RN = {_vector_text(self.sigma)} ({angle:.6g} deg from N)"


# ---------------------------------------------------------------------------------------------- slew
@dataclass(frozen=True, eq=False, kw_only=True)
class EigenaxisSlew:
    """A rest-to-rest rotation about a fixed eigenaxis with a trapezoidal rate profile.

    The reference frame starts at rest at σ_start, turns by ``angle`` about the unit eigenaxis ê
    (components in the start frame, the same in every frame of the slew) and ends at rest at the
    target. The rotation angle θ(t) has a trapezoidal rate: θ̈ = +a up to the rate limit w, θ̇ = w
    (coast), θ̈ = −a to rest; when the angle is too short to reach w, a triangle of peak √(Φ a).
    So |θ̇| <= w and |θ̈| <= a at every time, θ and θ̇ are continuous, θ̈ is piecewise constant.

        [R(t)N] = [R(t)R₀] [R₀N],  [R(t)R₀] the rotation by θ(t) about ê,
        ω_R/N = θ̇ [R₀N]ᵀ ê,  ω̇_R/N = θ̈ [R₀N]ᵀ ê   (N components; the axis is fixed in N).

    Give either ``target`` (the short way, angle <= 180°) or ``axis`` and ``angle`` (any angle > 0,
    for instance a 270° slew).

    Attributes
    ----------
    start : numpy.ndarray
        σ_R₀/N (3), short set.
    rate_limit : float
        w > 0 (rad/s).
    acceleration_limit : float
        a > 0 (rad/s²).
    target : numpy.ndarray or None
        σ of the final attitude (short set), or None when ``axis`` and ``angle`` are given.
    axis : numpy.ndarray
        Unit eigenaxis ê (start-frame components); computed from ``target`` when not given.
    angle : float
        Φ > 0 (rad); computed from ``target`` when not given.
    t_start : float
        Time (s) the slew begins (at rest at σ_start before), >= 0. Default 0.
    """

    start: np.ndarray
    rate_limit: float
    acceleration_limit: float
    target: np.ndarray | None = None
    axis: np.ndarray | None = None
    angle: float | None = None
    t_start: float = 0.0

    def __post_init__(self) -> None:
        start = _attitude("start", self.start)
        object.__setattr__(self, "start", start)
        object.__setattr__(self, "rate_limit", positive_scalar("rate_limit", self.rate_limit))
        object.__setattr__(self, "acceleration_limit", positive_scalar("acceleration_limit", self.acceleration_limit))
        object.__setattr__(self, "t_start", nonnegative_scalar("t_start", self.t_start))
        if self.target is not None:
            if self.axis is not None or self.angle is not None:
                raise SpecificationError("give target, or axis and angle, not both")
            target = _attitude("target", self.target)
            relative = subtract(target, start)  # σ(target/start), short set: the short way
            axis, angle = to_principal_rotation(relative)
            if float(angle) <= 0.0:
                raise SpecificationError("target equals start: no slew (use InertialPointing for a fixed attitude)")
            object.__setattr__(self, "target", target)
            object.__setattr__(self, "axis", readonly(axis))
            object.__setattr__(self, "angle", float(angle))
            return
        if self.axis is None or self.angle is None:
            raise SpecificationError("give target (an MRP attitude), or axis (unit vector) and angle (rad > 0)")
        object.__setattr__(self, "axis", _unit("axis", self.axis))
        object.__setattr__(self, "angle", positive_scalar("angle", self.angle))

    # ---------------------------------------------------------------- profile
    @property
    def acceleration_time(self) -> float:
        """Duration (s) of the acceleration (and of the deceleration) phase."""
        w, a = self.rate_limit, self.acceleration_limit
        phi = float(self.angle)  # type: ignore[arg-type]
        return w / a if phi >= w * w / a else math.sqrt(phi / a)

    @property
    def peak_rate(self) -> float:
        """The largest |θ̇| (rad/s): the rate limit, or √(Φ a) for a short (triangular) slew."""
        return min(self.rate_limit, self.acceleration_limit * self.acceleration_time)

    @property
    def coast_time(self) -> float:
        """Duration (s) at the rate limit (0 for a triangular profile)."""
        phi = float(self.angle)  # type: ignore[arg-type]
        peak = self.peak_rate
        return max(0.0, (phi - peak * peak / self.acceleration_limit) / peak)

    @property
    def duration(self) -> float:
        """Slew duration (s), from ``t_start`` to rest at the target."""
        return 2.0 * self.acceleration_time + self.coast_time

    @property
    def t_end(self) -> float:
        """Time (s) the reference comes to rest at the target."""
        return self.t_start + self.duration

    @property
    def final(self) -> np.ndarray:
        """σ of the attitude at the end of the slew (short set)."""
        return self.samples(np.array([self.t_end]))[0, 0:3]

    def angle_profile(self, t: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(θ, θ̇, θ̈) at times ``t`` (s): rad, rad/s, rad/s²."""
        times = _times(t)
        a, peak = self.acceleration_limit, self.peak_rate
        t1, tc = self.acceleration_time, self.coast_time
        total, phi = self.duration, float(self.angle)  # type: ignore[arg-type]
        s = np.clip(times - self.t_start, 0.0, total)
        remaining = total - s
        accelerating = s < t1
        decelerating = s >= t1 + tc
        theta = np.where(
            accelerating,
            0.5 * a * s**2,
            np.where(decelerating, phi - 0.5 * a * remaining**2, 0.5 * a * t1**2 + peak * (s - t1)),
        )
        rate = np.where(accelerating, a * s, np.where(decelerating, a * remaining, peak))
        moving = (times >= self.t_start) & (times < self.t_start + total)
        accel = np.where(moving, np.where(accelerating, a, np.where(decelerating, -a, 0.0)), 0.0)
        rate = np.where(moving, np.minimum(rate, peak), 0.0)
        theta = np.where(times >= self.t_start + total, phi, theta)
        return theta, rate, accel

    def samples(self, t: Any) -> np.ndarray:
        """The reference rows (len(t), 9) at times ``t`` (s)."""
        theta, rate, accel = self.angle_profile(t)
        axis = np.asarray(self.axis)
        turned = from_principal_rotation(np.broadcast_to(axis, (len(theta), 3)), theta)  # σ(R(t)/R₀)
        dcm = to_dcm(turned) @ to_dcm(self.start)  # [R(t)N] = [R(t)R₀][R₀N]
        axis_n = to_dcm(self.start).T @ axis
        out = np.empty((len(theta), 9))
        out[:, 0:3] = from_dcm(dcm)
        out[:, 3:6] = rate[:, None] * axis_n
        out[:, 6:9] = accel[:, None] * axis_n
        return out

    def __str__(self) -> str:
        phi = float(self.angle)  # type: ignore[arg-type]
        shape = "trapezoidal" if self.coast_time > 0.0 else "triangular"
        return (
            f"eigenaxis slew: {math.degrees(phi):.6g} deg about {_vector_text(np.asarray(self.axis))} from "
            f"sigma = {_vector_text(self.start)}, rate <= {self.rate_limit:g} rad/s, acceleration <= "
            f"{self.acceleration_limit:g} rad/s^2 ({shape}, peak {self.peak_rate:.6g} rad/s), "
            f"t = {self.t_start:g} to {self.t_end:.6g} s"
        )


# --------------------------------------------------------------------------------------------- orbit
@dataclass(frozen=True, eq=False, init=False)
class CircularOrbit:
    """A circular Keplerian orbit: rate n, inclination i, right ascension of the ascending node Ω and
    argument of latitude u₀ at t = 0.

    The position unit vector in the inertial frame N (x̂ to the vernal equinox, ẑ the equator's
    normal) is r̂_N(t) = R₃(Ω)ᵀ R₁(i)ᵀ [cos u, sin u, 0], u = u₀ + n t, and the orbit normal
    ĥ = R₃(Ω)ᵀ R₁(i)ᵀ ẑ = [sin Ω sin i, −cos Ω sin i, cos i].

    Attributes
    ----------
    orbit_rate : float
        n > 0 (rad/s), n = √(μ / r³). ``rate`` is its deprecated name (``rate`` is a sample rate in Hz
        elsewhere in mrpctl).
    inclination : float
        i (rad), 0 <= i <= π. Default 0.
    raan : float
        Ω (rad). Default 0.
    latitude : float
        u₀ (rad), the argument of latitude at t = 0. Default 0.
    """

    orbit_rate: float
    inclination: float = 0.0
    raan: float = 0.0
    latitude: float = 0.0

    def __init__(
        self,
        orbit_rate: float | None = None,
        inclination: float = 0.0,
        raan: float = 0.0,
        latitude: float = 0.0,
        *,
        rate: float | None = None,
    ) -> None:
        if rate is not None:
            warnings.warn(
                "CircularOrbit(rate=...) is deprecated: use orbit_rate= (rate is a sample rate in Hz elsewhere in "
                "mrpctl)",
                DeprecationWarning,
                stacklevel=2,
            )
            if orbit_rate is not None:
                raise SpecificationError("give orbit_rate (rate is its deprecated name), not both")
            orbit_rate = rate
        if orbit_rate is None:
            raise SpecificationError("orbit_rate (n, rad/s) is required")
        n = finite_scalar("orbit_rate", orbit_rate)
        if n <= 0.0:
            raise SpecificationError(f"orbit_rate must be > 0 (rad/s), got {n!r}")
        object.__setattr__(self, "orbit_rate", n)
        object.__setattr__(self, "inclination", inclination)
        object.__setattr__(self, "raan", raan)
        object.__setattr__(self, "latitude", latitude)
        self._check_angles()

    @property
    def rate(self) -> float:
        """Deprecated name of ``orbit_rate`` (``rate`` is a sample rate in Hz elsewhere in mrpctl)."""
        warnings.warn(
            "CircularOrbit.rate is deprecated: use .orbit_rate (rate is a sample rate in Hz elsewhere in mrpctl)",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.orbit_rate

    def _check_angles(self) -> None:
        inclination = finite_scalar("inclination", self.inclination)
        if not 0.0 <= inclination <= math.pi:
            raise SpecificationError(f"inclination must lie in [0, pi] rad (0 to 180 deg), got {inclination!r}")
        object.__setattr__(self, "inclination", inclination)
        object.__setattr__(self, "raan", finite_scalar("raan", self.raan))
        object.__setattr__(self, "latitude", finite_scalar("latitude", self.latitude))

    @classmethod
    def from_radius(cls, radius: float, *, mu: float = EARTH_MU, **angles: float) -> CircularOrbit:
        """The orbit of ``radius`` (m, from the body's centre) about a body of parameter ``mu`` (m³/s²)."""
        r = positive_scalar("radius", radius)
        gm = positive_scalar("mu", mu)
        return cls(orbit_rate=math.sqrt(gm / r**3), **angles)

    @classmethod
    def from_altitude(
        cls, altitude: float, *, mu: float = EARTH_MU, body_radius: float = EARTH_RADIUS, **angles: float
    ) -> CircularOrbit:
        """The orbit at ``altitude`` (m) above a body of radius ``body_radius`` (m; the Earth's by default)."""
        h = positive_scalar("altitude", altitude)
        return cls.from_radius(positive_scalar("body_radius", body_radius) + h, mu=mu, **angles)

    @property
    def period(self) -> float:
        """2π / n (s)."""
        return 2.0 * math.pi / self.orbit_rate

    def _frame(self) -> np.ndarray:
        """[N O]: columns are the node line, the in-plane normal to it and ĥ (N components)."""
        ci, si = math.cos(self.inclination), math.sin(self.inclination)
        co, so = math.cos(self.raan), math.sin(self.raan)
        return np.array([[co, -so * ci, so * si], [so, co * ci, -co * si], [0.0, si, ci]])

    @property
    def normal(self) -> np.ndarray:
        """ĥ (3), the unit orbit normal in N components."""
        return self._frame()[:, 2].copy()

    @property
    def in_plane_axes(self) -> np.ndarray:
        """(3, 2): the columns ê₁ (to the ascending node) and ê₂ = ĥ × ê₁ (N components), so that
        r̂_N(t) = cos(u₀ + n t) ê₁ + sin(u₀ + n t) ê₂."""
        return self._frame()[:, 0:2].copy()

    def r_hat(self, t: Any) -> np.ndarray:
        """r̂_N(t) (len(t), 3): the unit vector from the body's centre to the spacecraft, N components."""
        u = self.latitude + self.orbit_rate * _times(t)
        frame = self._frame()
        return np.cos(u)[:, None] * frame[:, 0] + np.sin(u)[:, None] * frame[:, 1]

    def hill_dcm(self, t: Any) -> np.ndarray:
        """[HN](t) (len(t), 3, 3): rows r̂, θ̂ = ĥ × r̂ (along-track) and ĥ in N components."""
        r = self.r_hat(t)
        h = np.broadcast_to(self.normal, r.shape)
        return np.stack((r, np.cross(h, r), h), axis=-2)

    def __str__(self) -> str:
        return (
            f"circular orbit: n = {self.orbit_rate:.6g} rad/s (period {self.period:.6g} s), i = "
            f"{math.degrees(self.inclination):.6g} deg, RAAN = {math.degrees(self.raan):.6g} deg, "
            f"u0 = {math.degrees(self.latitude):.6g} deg"
        )


@dataclass(frozen=True, eq=False)
class NadirPointing:
    """Follow the Hill (orbit) frame of a circular orbit, as Basilisk's ``hillPoint``.

    The reference frame R = H has the axes (Basilisk's Hill frame)

    * x̂_R = r̂: radially out, from the Earth's centre to the spacecraft (the zenith), so the
      body's −x axis points at the nadir;
    * ŷ_R = θ̂ = ĥ × r̂: along-track (the velocity direction on a circular orbit);
    * ẑ_R = ĥ: the orbit normal (the orbital angular momentum's direction).

    Then ω_R/N = n ĥ (N components, constant) and ω̇_R/N = 0; σ_R/N closes after one orbit.

    Attributes
    ----------
    orbit : CircularOrbit
    """

    orbit: CircularOrbit

    def __post_init__(self) -> None:
        if not isinstance(self.orbit, CircularOrbit):
            raise SpecificationError(f"orbit must be a CircularOrbit, got {type(self.orbit).__name__}")

    @property
    def orbit_rate(self) -> float:
        """The reference rate n (rad/s) about the orbit normal."""
        return self.orbit.orbit_rate

    @property
    def rate(self) -> float:
        """Deprecated name of ``orbit_rate`` (``rate`` is a sample rate in Hz elsewhere in mrpctl)."""
        warnings.warn(
            "NadirPointing.rate is deprecated: use .orbit_rate (rate is a sample rate in Hz elsewhere in mrpctl)",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.orbit.orbit_rate

    def r_hat(self, t: Any) -> np.ndarray:
        """r̂_N(t) (len(t), 3), the unit position vector (N components) the gravity gradient needs."""
        return self.orbit.r_hat(t)

    def samples(self, t: Any) -> np.ndarray:
        """The reference rows (len(t), 9) at times ``t`` (s)."""
        dcm = self.orbit.hill_dcm(t)
        out = np.zeros((len(dcm), 9))
        out[:, 0:3] = from_dcm(dcm)
        out[:, 3:6] = self.orbit.orbit_rate * self.orbit.normal
        return out

    def __str__(self) -> str:
        return f"nadir pointing (Hill frame: x radial out, y along-track, z orbit normal) on a {self.orbit}"


# ---------------------------------------------------------------------------------------------- file
@dataclass(frozen=True, eq=False, kw_only=True)
class FileReference:
    """Reference rows given per controller sample (read from a file by [`read`][mrpctl.guidance.FileReference.read]).

    Row k holds the reference at t_k = k / rate (the 9 columns of
    ``REFERENCE_COLUMNS``); ``samples(t)`` accepts only those
    sample times.

    Attributes
    ----------
    rows : numpy.ndarray
        (n, 9), finite, each σ a short set (|σ| <= 1).
    rate : float
        The controller rate (Hz) the rows are sampled at.
    source : str
        Where the rows come from (a file name), for messages. Default "".
    """

    rows: np.ndarray = field(repr=False)
    rate: float
    source: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate", positive_scalar("rate", self.rate))
        name = f"reference rows ({self.source})" if self.source else "reference rows"
        object.__setattr__(self, "rows", check_reference(self.rows, name=name))

    @classmethod
    def read(cls, path: str | Path, *, rate: float, samples: int | None = None, key: str = "file") -> FileReference:
        """Read the rows of a ``.csv`` (comma-separated, ``#`` comments) or ``.npy`` file.

        Parameters
        ----------
        path : str or Path
            The file: n rows of 9 numbers (σ_R/N, ω_R/N in rad/s and ω̇_R/N in rad/s², N components).
        rate : float
            The controller rate (Hz): row k is the reference at k / rate.
        samples : int, optional
            The number of rows the run needs (n = floor(t_final · rate) + 1); a file with another
            number of rows is refused naming both. None: any number of rows.
        key : str, optional
            The name errors give the file (default "file").
        """
        where = Path(path)
        array = read_numbers(where, key)
        if array.ndim == 1:
            array = array.reshape(1, -1) if array.size == 9 else array.reshape(-1, 1)
        if array.shape[1] != 9:
            raise DimensionError(
                f"{key}: {where} has {array.shape[1]} columns; a reference file has 9 per row "
                "(sigma_RN, omega_RN_N in rad/s, domega_RN_N in rad/s^2, N components)"
            )
        if samples is not None and array.shape[0] != samples:
            raise DimensionError(
                f"{key}: {where} has {array.shape[0]} rows but the run needs {samples}, one per controller sample "
                "(n = floor(t_final * rate) + 1)"
            )
        return cls(rows=array, rate=rate, source=str(where))

    @property
    def t_final(self) -> float:
        """Time (s) of the last row, (n − 1) / rate."""
        return (len(self.rows) - 1) / self.rate

    def samples(self, t: Any) -> np.ndarray:
        """The rows at times ``t`` (s), each a sample time k / rate with 0 <= k < n."""
        times = _times(t)
        k = np.rint(times * self.rate)
        bad = np.flatnonzero(
            (np.abs(times * self.rate - k) > 1e-9 * np.maximum(1.0, np.abs(k))) | (k < 0) | (k >= len(self.rows))
        )
        if bad.size:
            raise SpecificationError(
                f"t: a file reference is given at the sample times k / rate = k / {self.rate:g} Hz, "
                f"k = 0 ... {len(self.rows) - 1}; t = {float(times[bad[0]])!r} s is not one of them"
            )
        return self.rows[k.astype(int)].copy()

    def __str__(self) -> str:
        where = f" from {self.source}" if self.source else ""
        return f"file reference{where}: {len(self.rows)} rows at {self.rate:g} Hz (t = 0 to {self.t_final:.6g} s)"


# ------------------------------------------------------------------------------------------ helpers
def check_reference(value: Any, samples: int | None = None, *, name: str = "reference") -> np.ndarray:
    """``value`` checked as reference rows: a finite (n, 9) float array, each σ a short set (read-only copy).

    Parameters
    ----------
    value : array_like
        (n, 9) rows [σ_R/N, ω_R/N, ω̇_R/N].
    samples : int, optional
        The required number of rows n.
    name : str, optional
        The parameter's name in messages.
    """
    rows = finite_array(name, value)
    if rows.ndim != 2 or rows.shape[1] != 9 or rows.shape[0] == 0:
        raise DimensionError(
            f"{name}: expected shape (n, 9) (sigma_RN, omega_RN_N, domega_RN_N per sample) but found {rows.shape}"
        )
    if samples is not None and rows.shape[0] != samples:
        raise DimensionError(
            f"{name}: expected {samples} rows, one per controller sample (n = floor(t_final * rate) + 1), but found "
            f"{rows.shape[0]}"
        )
    norms = np.linalg.norm(rows[:, 0:3], axis=1)
    long_rows = np.flatnonzero(norms > 1.0 + _SHORT_TOLERANCE)
    if long_rows.size:
        row = int(long_rows[0])
        raise SpecificationError(
            f"{name}: row {row + 1} (counted from 1) has |sigma_RN| = {norms[row]:.6g} > 1; every sigma_RN must be a "
            "short-set MRP (give the shadow set -sigma/|sigma|^2, the same attitude)"
        )
    return readonly(rows)


def reference_samples(profile: GuidanceProfile, samples: int, rate: float) -> np.ndarray:
    """The (samples, 9) reference rows of ``profile`` at the controller samples t_k = k / rate, k < samples.

    The array a tracking run takes; it is checked with [`check_reference`][mrpctl.guidance.check_reference].
    """
    if not isinstance(profile, GuidanceProfile):
        raise SpecificationError(f"profile must be a guidance profile (with samples(t)), got {type(profile).__name__}")
    if isinstance(samples, bool) or not isinstance(samples, int | np.integer) or samples < 1:
        raise SpecificationError(f"samples must be an integer >= 1, got {samples!r}")
    h = positive_scalar("rate", rate)
    rows = profile.samples(np.arange(int(samples)) / h)
    # the profiles return short sets already; short() here only guards a custom profile's rounding
    rows[:, 0:3] = short(rows[:, 0:3])
    return check_reference(rows, int(samples))
