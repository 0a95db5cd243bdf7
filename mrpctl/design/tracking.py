"""The tracking loop linearised about a constant reference motion, for the design machinery.

State x = [σ_B/R; ω_B/R/4] (body components, the convention of ``design/conventions.md``) and
u = K x(t − τ) + u_ff, the error formed against the reference at the measurement's time and the
feedforward u_ff = ω × Jω + J([BN] ω̇_R/N − ω × [BN] ω_R/N) evaluated on the same (delayed)
measurement. About a reference that turns at a constant rate ω_r (R components) with r̂ fixed in R:

    ẋ = A x + A_d x(t − τ),   A = [[0, I₃], [¼ J⁻¹ M_σ, J⁻¹ M_ω]],   A_d = B (K + F),
    B = [0; ¼ J⁻¹],
    G = [(J ω_r)×] − [ω_r×] J,   M_ω = G − J [ω_r×],   M_σ = 4 G [ω_r×] + 12 n² ([r̂×] J − [(J r̂)×]) [r̂×],
    F = −[4 G [ω_r×], 4 M_ω]  with feedforward,  F = 0 without.

M_ω holds the gyroscopic (roll-yaw) coupling, the first term of M_σ the gyroscopic stiffness and the
second the gravity-gradient stiffness. Inertial pointing (ω_r = 0, no gravity gradient) is today's
plant A = [[0, I₃], [0, 0]], A_d = B K, with and without feedforward. Nadir pointing (the Hill frame,
ω_r = n ẑ_R, r̂ = x̂_R) gives the classic coupled roll-yaw pair and the decoupled pitch axis. The
matrices are written here by hand; ``tests/test_design_tracking.py`` checks them against a
finite-difference Jacobian of the CasADi tracking-error dynamics composed from the body dynamics
([`mrpctl.model.tracking_error_dynamics_expr`][mrpctl.model.tracking_error_dynamics_expr]).

What is not covered: time-varying references (an eigenaxis slew, a file), which make the loop
linear time-varying; the error formed against the reference at the *current* time (its linear part
differs by the rotation of R over τ, n τ = 5.5e-4 rad at 500 km and τ = 0.5 s, and it holds an
offset of about n τ / 4 in σ); inertial pointing with the gravity gradient (periodic in the orbit).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from mrpctl._validation import finite_scalar, positive_scalar, readonly
from mrpctl.design.lmi import Certificate, DelayCertification, certify, max_certified_delay
from mrpctl.design.margin import DelayMargin, delay_margin
from mrpctl.design.polytope import PolytopeCertificate, certify_vertices
from mrpctl.design.sampled import SampledStability, max_stable_delay_samples, sampled_stability
from mrpctl.errors import SpecificationError
from mrpctl.guidance import InertialPointing, NadirPointing
from mrpctl.model import gain_matrix
from mrpctl.mrp import skew
from mrpctl.spacecraft import Spacecraft, check_spacecraft

__all__ = [
    "TrackingLinearization",
    "certify_orbit_rates",
    "orbit_rate_vertices",
    "tracking_linearization",
]

_X_HAT = np.array([1.0, 0.0, 0.0])
_Z_HAT = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, eq=False)
class TrackingLinearization:
    """ẋ = A x + A_d x(t − τ): the tracking-error loop linearised about a constant reference motion.

    Attributes
    ----------
    spacecraft : Spacecraft
    K : numpy.ndarray
        (3, 6) feedback gain on x = [σ_B/R; ω_B/R/4] (N m).
    reference : str
        "inertial pointing" or "nadir pointing".
    orbit_rate : float
        n (rad/s); 0 for inertial pointing.
    feedforward : bool
        Whether u carries the feedforward ω × Jω + J(ω̇_R − ω × ω_R) on the delayed measurement.
    gravity_gradient : bool
        Whether the gravity-gradient torque 3 n² r̂ × J r̂ is in the plant.
    A : numpy.ndarray
        (6, 6) the undelayed part (plant about the reference motion).
    A_d : numpy.ndarray
        (6, 6) the delayed part B (K + F).
    B : numpy.ndarray
        (6, 3) [0; ¼ J⁻¹].
    loop_gain : numpy.ndarray
        (3, 6) K + F, the gain the sampled-data loop holds (u(t) = (K + F) x(t_{k−d}) on [t_k, t_{k+1})).
    unbalanced_torque : numpy.ndarray
        (3,) the torque (N m) the reference motion needs that the law does not supply at x = 0
        (ω_r × Jω_r without feedforward, and the gravity gradient 3 n² r̂ × J r̂): zero when J is diagonal
        in the reference frame; otherwise the loop holds an offset and x = 0 is not its equilibrium.
    """

    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    reference: str
    orbit_rate: float
    feedforward: bool
    gravity_gradient: bool
    A: np.ndarray = field(repr=False)
    A_d: np.ndarray = field(repr=False)
    B: np.ndarray = field(repr=False)
    loop_gain: np.ndarray = field(repr=False)
    unbalanced_torque: np.ndarray = field(repr=False)

    def delay_margin(self, **options: Any) -> DelayMargin:
        """The exact delay margin of (A, A_d) ([`delay_margin`][mrpctl.design.delay_margin])."""
        return delay_margin(self.A, self.A_d, **options)

    def certify(self, tau: float, **options: Any) -> Certificate:
        """The Bessel-Legendre LMI certificate at the delay τ (s) ([`certify`][mrpctl.design.certify])."""
        return certify(self.A, self.A_d, tau, **options)

    def max_certified_delay(self, **options: Any) -> DelayCertification:
        """The largest certified constant delay ([`max_certified_delay`][mrpctl.design.max_certified_delay])."""
        return max_certified_delay(self.A, self.A_d, **options)

    @property
    def blocks(self) -> tuple[tuple[int, ...], ...]:
        """The state indices of the decoupled sub-loops (connected through A, B or K + F), lowest first.

        For a diagonal J: inertial pointing splits into the three axes (σᵢ, ωᵢ/4), nadir pointing
        into the pitch axis (z, the orbit normal) and the coupled roll-yaw pair (x, y).
        """
        return _components(np.asarray(self.A), np.asarray(self.B), np.asarray(self.loop_gain))

    def sampled_stability(self, period: float, *, delay_samples: int = 0) -> SampledStability:
        """Exact stability of the sampled loop at period h with d samples of delay
        ([`sampled_stability`][mrpctl.design.sampled_stability]), block by block
        ([`blocks`][mrpctl.design.tracking.TrackingLinearization.blocks]); the block of largest
        spectral radius is returned (its ``size`` is that block's companion size)."""
        results = [sampled_stability(a, b, k, period, delay_samples=delay_samples) for a, b, k in self._sub_loops()]
        return max(results, key=lambda result: result.spectral_radius)

    def max_stable_delay_samples(self, period: float, *, d_limit: int = 2000) -> int:
        """The largest d such that the sampled loop is stable for 0 ... d samples of delay
        ([`max_stable_delay_samples`][mrpctl.design.max_stable_delay_samples]), the smallest over
        the [`blocks`][mrpctl.design.tracking.TrackingLinearization.blocks].

        Block by block because the argument-principle test evaluates det(zI − Φ − z^{−d}ΓK), which is
        of the order of (h ω)ⁿ near z = 1: for the whole 6 × 6 loop at 1 kHz (about 1e-18) it is lost
        in rounding and the test misreads a stable loop (d = 0 reported unstable), while the 2 × 2 and
        4 × 4 blocks keep it well above rounding.
        """
        return min(max_stable_delay_samples(a, b, k, period, d_limit=d_limit) for a, b, k in self._sub_loops())

    def _sub_loops(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        a, b, k = np.asarray(self.A), np.asarray(self.B), np.asarray(self.loop_gain)
        loops = []
        for states in self.blocks:
            ix = np.array(states)
            inputs = np.flatnonzero(np.any(b[ix] != 0.0, axis=0) | np.any(k[:, ix] != 0.0, axis=1))
            loops.append((a[np.ix_(ix, ix)], b[np.ix_(ix, inputs)], k[np.ix_(inputs, ix)]))
        return loops

    def __str__(self) -> str:
        parts = [self.reference]
        if self.orbit_rate > 0.0:
            parts.append(f"n = {self.orbit_rate:.6g} rad/s")
            parts.append("gravity gradient" if self.gravity_gradient else "no gravity gradient")
        parts.append("with feedforward" if self.feedforward else "without feedforward")
        text = "tracking loop linearised: " + ", ".join(parts)
        unbalanced = float(np.linalg.norm(self.unbalanced_torque))
        if unbalanced > 0.0:
            text += f" (the law leaves {unbalanced:.3g} N m of the reference's torque unsupplied: an offset)"
        return text


def _components(a: np.ndarray, b: np.ndarray, k: np.ndarray) -> tuple[tuple[int, ...], ...]:
    """Connected components of the states of ẋ = A x + B u, u = K x (states and inputs linked by a nonzero entry)."""
    n, m = b.shape
    parent = list(range(n + m))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    def join(i: int, j: int) -> None:
        parent[root(i)] = root(j)

    for i, j in zip(*np.nonzero(a), strict=True):
        join(int(i), int(j))
    for i, j in zip(*np.nonzero(b), strict=True):
        join(int(i), n + int(j))
    for j, i in zip(*np.nonzero(k), strict=True):
        join(int(i), n + int(j))
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(root(i), []).append(i)
    return tuple(sorted(tuple(group) for group in groups.values()))


def _check_flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise SpecificationError(f"{name} must be True or False, got {value!r}")
    return value


def _matrices(
    inertia: np.ndarray, omega_r: np.ndarray, n_gg: float, r_hat: np.ndarray, feedforward: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(M_σ, M_ω, F) for reference rate ω_r (R components), gravity-gradient rate n_gg and r̂ (R components)."""
    w = skew(omega_r)
    g = skew(inertia @ omega_r) - w @ inertia
    m_omega = g - inertia @ w
    m_gyro = 4.0 * g @ w
    r = skew(r_hat)
    m_gg = 12.0 * n_gg**2 * (r @ inertia - skew(inertia @ r_hat)) @ r
    f = -np.hstack((m_gyro, 4.0 * m_omega)) if feedforward else np.zeros((3, 6))
    return m_gyro + m_gg, m_omega, f


def _assemble(
    sc: Spacecraft, k: np.ndarray, m_sigma: np.ndarray, m_omega: np.ndarray, f: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    j_inv = sc.inertia_inverse
    a = np.block([[np.zeros((3, 3)), np.eye(3)], [0.25 * j_inv @ m_sigma, j_inv @ m_omega]])
    b = np.vstack((np.zeros((3, 3)), 0.25 * j_inv))
    loop = k + f
    return a, b @ loop, b, loop


def tracking_linearization(
    spacecraft: Spacecraft,
    K: Any,
    reference: InertialPointing | NadirPointing | None = None,
    *,
    feedforward: bool = True,
    gravity_gradient: bool = True,
) -> TrackingLinearization:
    """Linearise the delayed tracking loop about a constant reference motion.

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant; its inertia J in the body frame, which coincides with the reference frame at x = 0.
    K : array_like
        (3, 6) gain on x = [σ_B/R; ω_B/R/4] (N m), u = K x(t − τ) + u_ff.
    reference : InertialPointing, NadirPointing or None
        The reference motion: None or an [`InertialPointing`][mrpctl.guidance.InertialPointing]
        (ω_r = 0; the attitude held does not enter), or a
        [`NadirPointing`][mrpctl.guidance.NadirPointing] (ω_r = n about the orbit normal ẑ_R,
        r̂ = x̂_R). Other profiles (an eigenaxis slew, a file) are time-varying and refused.
    feedforward : bool, optional
        With the feedforward ω × Jω + J(ω̇_R − ω × ω_R) on the delayed measurement (default True).
    gravity_gradient : bool, optional
        With the gravity-gradient torque in the plant (nadir pointing only; default True).

    Returns
    -------
    TrackingLinearization

    Raises
    ------
    SpecificationError
        For another reference type or a flag that is not a bool.
    """
    sc = check_spacecraft(spacecraft)
    k = gain_matrix(K)
    feedforward = _check_flag("feedforward", feedforward)
    gravity_gradient = _check_flag("gravity_gradient", gravity_gradient)
    if reference is None or isinstance(reference, InertialPointing):
        name, n, gg = "inertial pointing", 0.0, False
    elif isinstance(reference, NadirPointing):
        name, n, gg = "nadir pointing", reference.orbit_rate, gravity_gradient
    else:
        raise SpecificationError(
            "reference: the linearisation covers constant reference motions (InertialPointing, NadirPointing); "
            f"a {type(reference).__name__} makes the loop time-varying"
        )
    return _linearization(sc, k, name, n, feedforward, gg)


def _linearization(
    sc: Spacecraft, k: np.ndarray, name: str, n: float, feedforward: bool, gg: bool
) -> TrackingLinearization:
    j = sc.inertia
    omega_r = n * _Z_HAT
    m_sigma, m_omega, f = _matrices(j, omega_r, n if gg else 0.0, _X_HAT, feedforward)
    a, a_d, b, loop = _assemble(sc, k, m_sigma, m_omega, f)
    unbalanced = (0.0 if feedforward else 1.0) * np.cross(omega_r, j @ omega_r)
    if gg:
        unbalanced = unbalanced - 3.0 * n**2 * np.cross(_X_HAT, j @ _X_HAT)
    return TrackingLinearization(
        spacecraft=sc,
        K=readonly(k),
        reference=name,
        orbit_rate=n,
        feedforward=feedforward,
        gravity_gradient=gg,
        A=readonly(a),
        A_d=readonly(a_d),
        B=readonly(b),
        loop_gain=readonly(loop),
        unbalanced_torque=readonly(unbalanced),
    )


def orbit_rate_vertices(
    spacecraft: Spacecraft,
    K: Any,
    rates: tuple[float, float],
    *,
    feedforward: bool = True,
    gravity_gradient: bool = True,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Three (A, A_d) whose convex hull holds the nadir-pointing loop of every orbit rate n in [n_lo, n_hi].

    A and A_d are affine in (n, n²) (the coupling M_ω and the feedforward's rate part in n, the
    stiffnesses in n²), and the arc n ↦ (n, n²) over [n_lo, n_hi] lies in the triangle of its two
    ends and the meeting point ((n_lo + n_hi)/2, n_lo n_hi) of their tangents (the parabola is convex).
    The vertices are the matrices at those three (n, m) points, with m in place of n².

    Parameters
    ----------
    rates : (float, float)
        0 <= n_lo < n_hi (rad/s).
    """
    sc = check_spacecraft(spacecraft)
    k = gain_matrix(K)
    feedforward = _check_flag("feedforward", feedforward)
    gravity_gradient = _check_flag("gravity_gradient", gravity_gradient)
    try:
        lo, hi = (finite_scalar("rates", value) for value in rates)
    except TypeError:
        raise SpecificationError(f"rates must be a pair (n_lo, n_hi) in rad/s, got {rates!r}") from None
    if not 0.0 <= lo < hi:
        raise SpecificationError(f"rates must satisfy 0 <= n_lo < n_hi (rad/s), got ({lo!r}, {hi!r})")
    j = sc.inertia
    # at unit rate: the gyroscopic stiffness 4 G [ω×] (scales with n²), the coupling M_ω (with n) and
    # the gravity-gradient stiffness (with n²)
    unit_gyro, unit_omega, _ = _matrices(j, _Z_HAT, 0.0, _X_HAT, False)
    unit_gg = _matrices(j, np.zeros(3), 1.0, _X_HAT, False)[0] if gravity_gradient else np.zeros((3, 3))
    vertices = []
    for n, m in ((lo, lo * lo), (hi, hi * hi), (0.5 * (lo + hi), lo * hi)):
        f = -np.hstack((m * unit_gyro, 4.0 * n * unit_omega)) if feedforward else np.zeros((3, 6))
        a, a_d, _, _ = _assemble(sc, k, m * (unit_gyro + unit_gg), n * unit_omega, f)
        vertices.append((a, a_d))
    return vertices


def certify_orbit_rates(
    spacecraft: Spacecraft,
    K: Any,
    tau: float,
    rates: tuple[float, float],
    *,
    feedforward: bool = True,
    gravity_gradient: bool = True,
    order: int = 2,
) -> PolytopeCertificate:
    """Certify the nadir-pointing loop at the delay τ for every circular-orbit rate n in ``rates``.

    The vertices of [`orbit_rate_vertices`][mrpctl.design.tracking.orbit_rate_vertices] through
    [`certify_vertices`][mrpctl.design.certify_vertices] (a vertex-dependent Lyapunov-Krasovskii
    functional): a certificate holds for every (A, A_d) of the triangle, hence for every n in the range.
    It covers the nominal inertia only.
    """
    tau = positive_scalar("tau", tau)
    vertices = orbit_rate_vertices(spacecraft, K, rates, feedforward=feedforward, gravity_gradient=gravity_gradient)
    return certify_vertices(vertices, tau, order=order)
