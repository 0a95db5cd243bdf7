"""A reaction-wheel cluster: the frozen value [`WheelCluster`][mrpctl.wheels.WheelCluster] and its allocation.

N >= 1 balanced wheels with unit spin axes g_i (the columns of Gs, 3 × N, body frame), spin inertia
Js,i (kg m²), a motor torque limit u_max,i (N m), a speed limit Ω_max,i (rad/s, relative to the body),
optional viscous (c_i, N m s) and Coulomb (f_c,i, N m) friction and initial speeds Ω_i(0). The
dynamics they enter are written in [`mrpctl.model`][mrpctl.model] (`wheel_dynamics_expr`); the
equations, the semantics against Basilisk's ``reactionWheelStateEffector`` and the allocation are in
``design/wheels.md``.

The allocation follows Basilisk's ``rwMotorTorque``: a body torque request u_c (the torque the
spacecraft should receive) over the control axes C (M × 3, rows unit vectors, M <= 3) gives the motor
torques u_s = −(C Gs)ᵀ ((C Gs)(C Gs)ᵀ)⁻¹ C u_c (the body receives −Gs u_s, the reaction of the motor
torques on the wheels). For N > 3 a null-space term u_n = −k_n P diag(Js) (Ω − Ω_bias), with P =
I − Gs⁺ Gs the projector on the null space of Gs, drives the wheel speeds toward a bias without a
body torque (Gs P = 0).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import linprog

from mrpctl._validation import finite_array, finite_scalar, readonly
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.mrp import to_dcm

__all__ = [
    "WHEEL_MEMORY_FIELDS",
    "WheelCluster",
    "allocation_matrix",
    "null_space_projector",
    "rest_momentum_load",
    "wheel_memory_size",
]

#: The wheel part of the wheel sample's memory, in order, each one entry per wheel except the last:
#: the wheel speeds Ω (rad/s), the peak |Ω_i| over the samples, the samples with u_s,i clipped to
#: u_max,i, the samples with u_s,i cut by the speed limit, and the peak |Gs diag(Js) Ω| (N m s).
WHEEL_MEMORY_FIELDS = ("speeds", "peak_speed", "torque_limited", "speed_limited", "peak_momentum")


def wheel_memory_size(count: int) -> int:
    """Entries of the wheel part of the wheel sample's memory for ``count`` wheels (4 N + 1)."""
    return 4 * count + 1


def _per_wheel(name: str, value: Any, count: int) -> np.ndarray:
    array = finite_array(name, value)
    if array.ndim == 0:
        array = np.full(count, float(array))
    if array.shape != (count,):
        raise DimensionError(f"{name} must be a scalar or one value per wheel ({count}), got shape {array.shape}")
    return array


def _positive(name: str, array: np.ndarray) -> None:
    if np.any(array <= 0.0):
        raise SpecificationError(f"{name} must be > 0 for every wheel, got {array.tolist()}")


def _nonnegative(name: str, array: np.ndarray) -> None:
    if np.any(array < 0.0):
        raise SpecificationError(f"{name} must be >= 0 for every wheel, got {array.tolist()}")


@dataclass(frozen=True, eq=False)
class WheelCluster:
    """N balanced reaction wheels (see the module's docstring and ``design/wheels.md``).

    Parameters
    ----------
    spin_axes : array_like
        Gs (3, N): unit spin axes in the body frame (normalised columns are required, not made).
    spin_inertia : float or array_like
        Js,i > 0 (kg m²), a scalar for all wheels or one per wheel.
    torque_limit : float or array_like
        u_max,i > 0 (N m): each wheel's motor torque is clipped on its own.
    speed_limit : float or array_like
        Ω_max,i > 0 (rad/s): a wheel with |Ω_i| >= Ω_max,i at a sample gets no torque that would spin it
        faster (Ω_i u_s,i >= 0 → u_s,i = 0), Basilisk's rule.
    viscous, coulomb : float or array_like
        Friction c_i >= 0 (N m s) and f_c,i >= 0 (N m): the wheel's friction torque is
        −(f_c,i sign(Ω_i) + c_i Ω_i), linear through zero below ``limit_cycle_speed`` (Basilisk's
        model without its Stribeck term). Default 0.
    limit_cycle_speed : float or array_like
        ω_lc,i > 0 (rad/s), Basilisk's ``omegaLimitCycle`` (default 1e-4).
    speeds : float or array_like
        Ω_i(0) (rad/s), default 0.
    control_axes : array_like
        C (M, 3), M in 1..3 unit rows: the axes the allocation controls (default I₃); C Gs must have
        rank M.
    null_gain : float
        k_n >= 0 (1/s) of the null-space momentum management (N > 3 only; default 0: off).
    bias_speeds : float or array_like
        Ω_bias (rad/s), the speeds the null-space term drives the wheels toward (default 0).
    gyroscopic : bool
        The control law adds ω × (J ω + Gs h_s), h_s,i = Js,i (g_iᵀ ω + Ω_i), from the measured rate
        and the wheel speeds, as Basilisk's ``mrpFeedback`` does (default False).
    """

    spin_axes: np.ndarray = field(repr=False)
    spin_inertia: Any
    torque_limit: Any
    speed_limit: Any
    viscous: Any = 0.0
    coulomb: Any = 0.0
    limit_cycle_speed: Any = 1e-4
    speeds: Any = 0.0
    control_axes: Any = field(default=None, repr=False)
    null_gain: float = 0.0
    bias_speeds: Any = 0.0
    gyroscopic: bool = False

    def __post_init__(self) -> None:
        axes = finite_array("spin_axes", self.spin_axes)
        if axes.ndim != 2 or axes.shape[0] != 3 or axes.shape[1] < 1:
            raise DimensionError(f"spin_axes must be (3, N) with N >= 1 wheels, got shape {axes.shape}")
        count = axes.shape[1]
        norms = np.linalg.norm(axes, axis=0)
        if np.any(np.abs(norms - 1.0) > 1e-12):
            raise SpecificationError(f"spin_axes: every column must be a unit vector, got norms {norms.tolist()}")
        values: dict[str, np.ndarray] = {}
        for name in ("spin_inertia", "torque_limit", "speed_limit", "limit_cycle_speed"):
            values[name] = _per_wheel(name, getattr(self, name), count)
            _positive(name, values[name])
        for name in ("viscous", "coulomb"):
            values[name] = _per_wheel(name, getattr(self, name), count)
            _nonnegative(name, values[name])
        for name in ("speeds", "bias_speeds"):
            values[name] = _per_wheel(name, getattr(self, name), count)
        control = np.eye(3) if self.control_axes is None else finite_array("control_axes", self.control_axes)
        if control.ndim == 1:
            control = control[None, :]
        if control.ndim != 2 or control.shape[1] != 3 or not 1 <= control.shape[0] <= 3:
            raise DimensionError(f"control_axes must be (M, 3) with M in 1..3, got shape {control.shape}")
        rows = np.linalg.norm(control, axis=1)
        if np.any(np.abs(rows - 1.0) > 1e-12):
            raise SpecificationError(f"control_axes: every row must be a unit vector, got norms {rows.tolist()}")
        projected = control @ axes
        rank = int(np.linalg.matrix_rank(projected))
        if rank < control.shape[0]:
            raise SpecificationError(
                f"spin_axes: C Gs has rank {rank} < {control.shape[0]} control axes: the wheels cannot make "
                "a torque about every control axis (add wheels or choose fewer control axes)"
            )
        gain = finite_scalar("null_gain", self.null_gain)
        if gain < 0.0:
            raise SpecificationError(f"null_gain must be >= 0 (1/s), got {gain}")
        if gain > 0.0 and int(np.linalg.matrix_rank(axes)) >= count:
            raise SpecificationError(
                f"null_gain: the {count} wheels have no null space (Gs has full column rank); set null_gain=0"
            )
        if not isinstance(self.gyroscopic, bool):
            raise SpecificationError(f"gyroscopic must be True or False, got {self.gyroscopic!r}")
        object.__setattr__(self, "spin_axes", readonly(axes))
        object.__setattr__(self, "control_axes", readonly(control))
        object.__setattr__(self, "null_gain", gain)
        for name, array in values.items():
            object.__setattr__(self, name, readonly(array))

    # ------------------------------------------------------------------ constructors
    @classmethod
    def orthogonal(cls, spin_inertia: Any, torque_limit: Any, speed_limit: Any, **options: Any) -> WheelCluster:
        """Three wheels along the body axes x, y, z (Gs = I₃)."""
        return cls(np.eye(3), spin_inertia, torque_limit, speed_limit, **options)

    @classmethod
    def pyramid(
        cls,
        spin_inertia: Any,
        torque_limit: Any,
        speed_limit: Any,
        *,
        elevation: float = np.arctan(1 / np.sqrt(2)),
        **options: Any,
    ) -> WheelCluster:
        """Four wheels in a pyramid about the body z axis: g_i = (cos β cos φ_i, cos β sin φ_i, sin β),
        φ_i = 45°, 135°, 225°, 315°; β the elevation (rad, default atan(1/√2) ≈ 35.26°, equal capacity
        on every axis)."""
        beta = finite_scalar("elevation", elevation)
        if not 0.0 < beta < np.pi / 2:
            raise SpecificationError(f"elevation must be in (0, pi/2) rad, got {beta}")
        phi = np.deg2rad([45.0, 135.0, 225.0, 315.0])
        axes = np.vstack((np.cos(beta) * np.cos(phi), np.cos(beta) * np.sin(phi), np.full(4, np.sin(beta))))
        axes /= np.linalg.norm(axes, axis=0)
        return cls(axes, spin_inertia, torque_limit, speed_limit, **options)

    # ------------------------------------------------------------------ derived values
    @property
    def count(self) -> int:
        """N, the number of wheels."""
        return int(self.spin_axes.shape[1])

    @property
    def momentum_capacity(self) -> np.ndarray:
        """Js,i Ω_max,i (N m s) per wheel."""
        return readonly(self.spin_inertia * self.speed_limit)

    def momentum(self, speeds: Any) -> np.ndarray:
        """Gs diag(Js) Ω (N m s, body frame) of wheel speeds (..., N)."""
        omega = finite_array("speeds", speeds, (None, self.count))
        return (omega * self.spin_inertia) @ self.spin_axes.T

    def momentum_load(self, momentum: Any) -> np.ndarray | float:
        """How full the wheels must be to hold ``momentum`` (N m s, body components, (..., 3)) with the body at rest.

        The smallest max_i |Ω_i| / Ω_max,i over the wheel speeds Ω with Gs diag(Js) Ω = ``momentum``;
        ``inf`` where no wheel speeds give it (a direction the spin axes do not span). Without an
        external torque the total angular momentum is conserved, so a loop that starts with a total
        momentum H_N can come to rest at the attitude R only if the load of [RN] H_N is at most 1:
        above 1 it cannot settle on the wheels, whatever the law.

        It is the gauge of the zonotope Z = {Gs diag(Js) Ω : |Ω_i| <= Ω_max,i} spanned by the columns
        c_i = Js,i Ω_max,i g_i: where they span R³, Z is the intersection of the slabs |n·h| <= Σ_k |n·c_k|
        over the facet normals n = c_i × c_j, so the load is max_n |n·h| / Σ_k |n·c_k|. Where they do
        not, a linear program (scipy's HiGHS) per momentum.
        """
        h = finite_array("momentum", momentum, (None, 3))
        columns = self.spin_axes * (self.spin_inertia * self.speed_limit)  # c_i as columns, 3 × N
        if np.linalg.matrix_rank(columns) == 3:
            i, j = np.triu_indices(self.count, k=1)
            normals = np.cross(columns[:, i].T, columns[:, j].T)  # (pairs, 3)
            keep = np.linalg.norm(normals, axis=1) > 1e-12 * np.max(np.linalg.norm(columns, axis=0)) ** 2
            normals = normals[keep]
            support = np.sum(np.abs(normals @ columns), axis=1)  # Σ_k |n·c_k|
            loads = np.max(np.abs(h @ normals.T) / support, axis=-1)
        else:
            loads = np.array([self._load_by_program(row) for row in h.reshape(-1, 3)]).reshape(h.shape[:-1])
        return float(loads) if loads.ndim == 0 else readonly(loads)

    def _load_by_program(self, h: np.ndarray) -> float:
        """[`momentum_load`][mrpctl.wheels.WheelCluster.momentum_load] of one momentum by a linear program."""
        count = self.count
        # variables (Ω_1 … Ω_N, t): minimise t subject to Gs diag(Js) Ω = h and |Ω_i| <= t Ω_max,i
        cost = np.zeros(count + 1)
        cost[-1] = 1.0
        eye = np.eye(count)
        limits = self.speed_limit.reshape(count, 1)
        upper = np.vstack((np.hstack((eye, -limits)), np.hstack((-eye, -limits))))
        equality = np.hstack((self.spin_axes * self.spin_inertia, np.zeros((3, 1))))

        bounds = [(None, None)] * count + [(0.0, None)]
        solution = linprog(cost, A_ub=upper, b_ub=np.zeros(2 * count), A_eq=equality, b_eq=h, bounds=bounds)
        if solution.status == 2:  # infeasible: h is not in the span of the spin axes
            return float("inf")
        if solution.status != 0:
            raise RuntimeError(
                f"momentum_load: the linear program ended with status {solution.status}: {solution.message}"
            )
        return float(solution.x[-1])

    def key(self) -> tuple[Any, ...]:
        """What distinguishes the compiled samples of two clusters (their values, bit for bit)."""
        arrays = (
            self.spin_axes,
            self.spin_inertia,
            self.torque_limit,
            self.speed_limit,
            self.viscous,
            self.coulomb,
            self.limit_cycle_speed,
            self.control_axes,
            self.bias_speeds,
        )
        return (*(a.tobytes() for a in arrays), self.count, self.null_gain, self.gyroscopic)


def allocation_matrix(wheels: WheelCluster) -> np.ndarray:
    """A (N, 3) with u_s = A u_c: −(C Gs)ᵀ ((C Gs)(C Gs)ᵀ)⁻¹ C, Basilisk's ``rwMotorTorque``.

    u_c is the body torque request (the torque the spacecraft should receive, Basilisk's
    ``torqueRequestBody``); the body then receives −Gs u_s, which equals u_c on the control axes.
    """
    control = wheels.control_axes
    projected = control @ wheels.spin_axes
    return readonly(-projected.T @ np.linalg.solve(projected @ projected.T, control))


def null_space_projector(wheels: WheelCluster) -> np.ndarray:
    """P = I − Gs⁺ Gs (N, N): the wheel torques in the null space of Gs (Gs P = 0: no body torque)."""
    axes = wheels.spin_axes
    return readonly(np.eye(wheels.count) - np.linalg.pinv(axes) @ axes)


def rest_momentum_load(wheels: WheelCluster, inertia: Any, sigma: Any, omega: Any) -> np.ndarray:
    """The wheels' [`momentum_load`][mrpctl.wheels.WheelCluster.momentum_load] at rest at the origin, per run.

    ``sigma`` (..., 3) and ``omega`` (..., 3, rad/s) are initial states of the body, ``inertia`` the
    whole spacecraft's J ((..., 3, 3), one per run or shared; wheels included) and the wheels start at
    ``wheels.speeds``. The total momentum H_B = J ω + Gs diag(Js) Ω is conserved in N without an
    external torque, so the body can come to rest at σ = 0 (B = N) only where the returned load of
    H_N = [BN]ᵀ H_B is at most 1.
    """
    J = finite_array("inertia", inertia, (None, 3, 3))
    sigma = finite_array("sigma", sigma, (None, 3))
    omega = finite_array("omega", omega, (None, 3))
    body = np.einsum("...ij,...j->...i", J, omega) + wheels.momentum(wheels.speeds)
    inertial = np.einsum("...ji,...j->...i", to_dcm(sigma), body)  # [BN]ᵀ H_B
    return np.asarray(wheels.momentum_load(inertial), dtype=float)
