"""PD gains for the linearised per-axis loop σ̈ = K₁ σ + K₂ σ̇, and their damping analysis."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import finite_array, readonly
from mrpctl.design._common import is_diagonal
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import gain_from_pd, gain_matrix, pd_from_gain, plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = ["AxisDamping", "GainAnalysis", "PDGains", "analyze_gains", "pd_gains"]


#: Relative tolerance on ζ = 1 (critical damping) and on a vanishing discriminant.
_ZETA_TOL = 1e-9


@dataclass(frozen=True, eq=False)
class PDGains:
    """PD gains of the linearised loop σ̈ = K₁ σ + K₂ σ̇ (paper Eq. pd_design) and the gain K.

    Attributes
    ----------
    spacecraft : Spacecraft
    zeta : numpy.ndarray
        (3,) damping ratios ζ (dimensionless).
    omega_n : numpy.ndarray
        (3,) natural frequencies ωₙ (rad/s).
    K1 : numpy.ndarray
        (3, 3) K₁ = −diag(ωₙ²) (1/s²).
    K2 : numpy.ndarray
        (3, 3) K₂ = −diag(2ζωₙ) (1/s).
    K : numpy.ndarray
        (3, 6) gain on x = [σ; ω/4]: K = [4 J K₁, 4 J K₂] (``design/conventions.md``; N m).
    poles : numpy.ndarray
        (3, 2) complex closed-loop poles per axis without delay, s = −ζωₙ ± ωₙ√(ζ² − 1) (1/s).
    """

    spacecraft: Spacecraft
    zeta: np.ndarray
    omega_n: np.ndarray
    K1: np.ndarray = field(repr=False)
    K2: np.ndarray = field(repr=False)
    K: np.ndarray = field(repr=False)
    poles: np.ndarray = field(repr=False)

    @property
    def overdamped(self) -> bool:
        """True when ζ >= 1 on every axis (real poles, no overshoot)."""
        return bool(np.all(self.zeta >= 1.0))

    def __str__(self) -> str:
        lines = [f"PD gains for {self.spacecraft} (sigma_ddot = K1 sigma + K2 sigma_dot)"]
        for i in range(3):
            poles = ", ".join(_pole_text(p) for p in self.poles[i])
            lines.append(
                f"  axis {i + 1}: omega_n = {self.omega_n[i]:.6g} rad/s, zeta = {self.zeta[i]:.4g} "
                f"({damping_kind(float(self.zeta[i]))}), "
                f"K1 = {self.K1[i, i]:.6g}, K2 = {self.K2[i, i]:.6g}, poles {poles}"
            )
        lines.append(f"  K = [4 J K1, 4 J K2] = {np.array2string(self.K, precision=5, max_line_width=200)}")
        return "\n".join(lines)


def pd_gains(
    spacecraft: Spacecraft,
    *,
    zeta: Any = 1.0,
    omega_n: Any,
    allow_underdamped: bool = False,
) -> PDGains:
    """PD gains placing the poles of σ̈ = K₁ σ + K₂ σ̇ at ζ, ωₙ on each axis (paper Eq. pd_design).

    The characteristic polynomial of each axis is s² − K₂ s − K₁ = s² + 2ζωₙ s + ωₙ², so
    K₁ = −ωₙ² and K₂ = −2ζωₙ; the gain on x = [σ; ω/4] is K = [4 J K₁, 4 J K₂].

    Parameters
    ----------
    spacecraft : Spacecraft
    zeta : float or array_like, optional
        Damping ratio ζ > 0, scalar or one per axis (3,). Default 1 (critically damped, the
        boundary of "overdamped"). Values below 1 need ``allow_underdamped=True``.
    omega_n : float or array_like
        Natural frequency ωₙ > 0 (rad/s), scalar or (3,). Keyword-only and required.
    allow_underdamped : bool, optional
        Accept ζ < 1 (default False: the paper asks for an overdamped response, ζ >= 1).

    Returns
    -------
    PDGains

    Raises
    ------
    SpecificationError
        If ζ <= 0, ζ < 1 without ``allow_underdamped``, or ωₙ <= 0; NaN or inf anywhere.
    DimensionError
        If ζ or ωₙ is neither a scalar nor a 3-vector.

    Examples
    --------
    >>> from mrpctl import Spacecraft
    >>> g = pd_gains(Spacecraft([140, 100, 80]), zeta=1.0, omega_n=0.5)
    >>> float(g.K1[0, 0]), float(g.K2[0, 0]), float(g.K[0, 0])
    (-0.25, -1.0, -140.0)
    """
    spacecraft = check_spacecraft(spacecraft)
    z = _per_axis("zeta", zeta)
    w = _per_axis("omega_n", omega_n)
    if np.any(w <= 0.0):
        raise SpecificationError(f"omega_n must be > 0 rad/s on every axis, got {w}")
    if np.any(z <= 0.0):
        raise SpecificationError(f"zeta must be > 0 on every axis, got {z}")
    if np.any(z < 1.0) and not allow_underdamped:
        raise SpecificationError(
            f"zeta must be >= 1 for an overdamped loop, got {z}; pass allow_underdamped=True to accept zeta < 1"
        )
    k1 = -np.diag(w**2)
    k2 = -np.diag(2.0 * z * w)
    return PDGains(
        spacecraft=spacecraft,
        zeta=readonly(z),
        omega_n=readonly(w),
        K1=readonly(k1),
        K2=readonly(k2),
        K=readonly(gain_from_pd(spacecraft, k1, k2)),
        poles=readonly([_axis_poles(-k1[i, i], -k2[i, i]) for i in range(3)], dtype=complex),
    )


@dataclass(frozen=True, eq=False)
class AxisDamping:
    """Damping of one axis of σ̈ = K₁ σ + K₂ σ̇ with diagonal K₁, K₂.

    Attributes
    ----------
    axis : int
        1, 2 or 3 (body axis).
    K1, K2 : float
        The diagonal loop gains (1/s², 1/s).
    omega_n : float
        ωₙ = √(−K₁) (rad/s); nan when K₁ >= 0 (no restoring term).
    zeta : float
        ζ = −K₂ / (2ωₙ); nan when ωₙ is nan.
    poles : numpy.ndarray
        (2,) complex roots of s² − K₂ s − K₁ (1/s).
    """

    axis: int
    K1: float
    K2: float
    omega_n: float
    zeta: float
    poles: np.ndarray = field(repr=False)

    @property
    def stable(self) -> bool:
        """True when both poles lie in the open left half-plane."""
        return bool(np.all(self.poles.real < 0.0))

    @property
    def overdamped(self) -> bool:
        """True when stable with ζ >= 1 (real poles; ζ = 1, critical damping, counts).

        ζ is compared with a relative tolerance of 1e-9 so that gains designed for ζ = 1
        stay critically damped after the round trip K -> (K₁, K₂).
        """
        return self.stable and bool(self.zeta >= 1.0 - _ZETA_TOL)

    def __str__(self) -> str:
        kind = damping_kind(self.zeta) if self.stable else "unstable"
        poles = ", ".join(_pole_text(p) for p in self.poles)
        return (
            f"axis {self.axis}: K1 = {self.K1:.6g}, K2 = {self.K2:.6g}, omega_n = {self.omega_n:.6g} rad/s, "
            f"zeta = {self.zeta:.4g} ({kind}), poles {poles}"
        )


@dataclass(frozen=True, eq=False)
class GainAnalysis:
    """Result of [`analyze_gains`][mrpctl.design.analyze_gains]: damping of the delay-free linearised loop under a gain
    K.

    Attributes
    ----------
    spacecraft : Spacecraft
    K : numpy.ndarray
        (3, 6) gain on x = [σ; ω/4].
    K1, K2 : numpy.ndarray
        (3, 3) loop gains (K₁, K₂) = J⁻¹ K / 4 split into blocks.
    axes : tuple of AxisDamping
        One entry per axis when K₁ and K₂ are diagonal (decoupled axes); empty otherwise.
    poles : numpy.ndarray
        (6,) complex eigenvalues of [[0, I], [K₁, K₂]] (1/s), the delay-free loop.
    """

    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    K1: np.ndarray = field(repr=False)
    K2: np.ndarray = field(repr=False)
    axes: tuple[AxisDamping, ...]
    poles: np.ndarray = field(repr=False)

    @property
    def decoupled(self) -> bool:
        """True when K₁ and K₂ are diagonal, so each axis is its own second-order loop."""
        return bool(self.axes)

    @property
    def stable(self) -> bool:
        """True when the delay-free loop is asymptotically stable."""
        return bool(np.all(self.poles.real < 0.0))

    @property
    def overdamped(self) -> bool:
        """True when every pole is real and negative (ζ >= 1 on every axis)."""
        if self.axes:
            return all(a.overdamped for a in self.axes)
        scale = max(1.0, float(np.max(np.abs(self.poles))))
        return self.stable and bool(np.all(np.abs(self.poles.imag) <= 1e-9 * scale))

    def __str__(self) -> str:
        if not self.stable:
            kind = "unstable"
        elif self.axes:
            kinds = {damping_kind(a.zeta) for a in self.axes}
            kind = kinds.pop() if len(kinds) == 1 else "axes " + ", ".join(damping_kind(a.zeta) for a in self.axes)
        else:
            kind = "overdamped or critically damped" if self.overdamped else "stable, not overdamped"
        lines = [f"gain analysis for {self.spacecraft}: {kind} without delay"]
        if self.axes:
            lines.extend(f"  {a}" for a in self.axes)
        else:
            lines.append("  axes coupled (K1, K2 not diagonal); poles " + ", ".join(_pole_text(p) for p in self.poles))
        return "\n".join(lines)


def analyze_gains(spacecraft: Spacecraft, K: Any) -> GainAnalysis:
    """Per-axis ωₙ, ζ and poles of σ̈ = K₁ σ + K₂ σ̇ for a given gain K (delay-free loop).

    (K₁, K₂) = J⁻¹ K / 4 (convention of ``design/conventions.md``). When K₁ and K₂ are diagonal,
    each axis has s² − K₂ᵢᵢ s − K₁ᵢᵢ = s² + 2ζωₙ s + ωₙ², so ωₙ = √(−K₁ᵢᵢ) and
    ζ = −K₂ᵢᵢ / (2ωₙ); "overdamped" means ζ >= 1. Otherwise only the six poles are reported.

    Parameters
    ----------
    spacecraft : Spacecraft
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).

    Returns
    -------
    GainAnalysis

    Examples
    --------
    >>> from mrpctl import paper
    >>> [round(a.zeta, 2) for a in analyze_gains(paper.SPACECRAFT, paper.GAIN).axes]
    [0.41, 0.49, 0.54]
    """
    spacecraft = check_spacecraft(spacecraft)
    k = gain_matrix(K)
    k1, k2 = pd_from_gain(spacecraft, k)
    pm = plant_model(spacecraft)
    a, a_d = pm.closed_loop_matrices(k)
    poles = np.sort_complex(np.linalg.eigvals(a + a_d))
    axes: tuple[AxisDamping, ...] = ()
    if is_diagonal(k1) and is_diagonal(k2):
        axes = tuple(_axis_damping(i, float(k1[i, i]), float(k2[i, i])) for i in range(3))
    return GainAnalysis(
        spacecraft=spacecraft,
        K=readonly(k),
        K1=readonly(k1),
        K2=readonly(k2),
        axes=axes,
        poles=readonly(poles, dtype=complex),
    )


def damping_kind(zeta: float) -> str:
    """ "critically damped" for ζ = 1 (to a relative 1e-9), "overdamped" above, "underdamped" below."""
    if math.isnan(zeta):
        return "no restoring gain"
    if abs(zeta - 1.0) <= _ZETA_TOL:
        return "critically damped"
    return "overdamped" if zeta > 1.0 else "underdamped"


def _axis_damping(i: int, k1: float, k2: float) -> AxisDamping:
    if k1 < 0.0:
        omega_n = math.sqrt(-k1)
        zeta = -k2 / (2.0 * omega_n)
    else:
        omega_n = zeta = math.nan
    return AxisDamping(
        axis=i + 1,
        K1=k1,
        K2=k2,
        omega_n=omega_n,
        zeta=zeta,
        poles=readonly(_axis_poles(-k1, -k2), dtype=complex),
    )


def _axis_poles(a: float, b: float) -> np.ndarray:
    """Roots of s² + b s + a, ordered by real part (a double root where b² − 4a is rounding)."""
    discriminant = b * b - 4.0 * a
    if abs(discriminant) <= 4.0 * _ZETA_TOL * max(b * b, abs(a)):
        discriminant = 0.0
    root = np.sqrt(complex(discriminant))
    return np.sort_complex(np.array([(-b - root) / 2.0, (-b + root) / 2.0], dtype=complex))


def _per_axis(name: str, value: Any) -> np.ndarray:
    array = finite_array(name, value)
    if array.ndim == 0:
        return np.full(3, float(array))
    if array.shape != (3,):
        raise DimensionError(f"{name}: expected a scalar or shape (3,) but found {array.shape}")
    return array


def _pole_text(p: complex) -> str:
    if abs(p.imag) <= 1e-12 * max(1.0, abs(p)):
        return f"{p.real:.5g}"
    return f"{p.real:.5g}{'+' if p.imag >= 0 else '-'}{abs(p.imag):.5g}j"
