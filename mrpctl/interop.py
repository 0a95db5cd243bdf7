"""python-control and Basilisk interop: the linearised loop, runs and gains in their terms.

* [`delayed_loop`][mrpctl.interop.delayed_loop] gives the linearised attitude loop ẋ = A x + B u, u = K x(t − τ)
  as a ``control.StateSpace`` plant, the static gain K and the delay τ, with
  [`DelayedLoop.pade`][mrpctl.interop.DelayedLoop.pade] closing it through a Padé approximation of e^{−sτ}.
* [`loop_margins`][mrpctl.interop.loop_margins] gives the per-axis phase margin and gain crossover of the loop
  broken at the delay, L_i(s) = −(K₂ᵢ s + K₁ᵢ)/s², and the delay margin PM/ω_c they imply
  (equal to [`mrpctl.design.LinearizedLoop.delay_margin`][mrpctl.design.LinearizedLoop.delay_margin] for a decoupled
  loop).
* [`to_time_response`][mrpctl.interop.to_time_response] / [`from_time_response`][mrpctl.interop.from_time_response]
convert a
  [`SimulationResult`][mrpctl.SimulationResult] to ``control.TimeResponseData`` and back.
* [`basilisk_mrp_feedback`][mrpctl.interop.basilisk_mrp_feedback] maps K to the scalar gains of Basilisk's
``mrpFeedback``.

Conventions: x = [σ; ω/4] (σ dimensionless, ω in rad/s), u in N m, τ in s; with ``physical=True``,
[`delayed_loop`][mrpctl.interop.delayed_loop] and [`to_time_response`][mrpctl.interop.to_time_response] use the
physical state [σ; ω] (ω in rad/s), labelled `PHYSICAL_LABELS` (``sigma1``-``sigma3``, ``omega1``-``omega3``).
The conversions are those of [`mrpctl.conventions`][mrpctl.conventions].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import control
import numpy as np

from mrpctl._validation import finite_array, finite_scalar, integer, nonnegative_scalar, readonly
from mrpctl.conventions import RATE_SCALE, gain_from_parts, state, state_parts
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.model import gain_matrix, pd_from_gain, plant_model
from mrpctl.spacecraft import Spacecraft, check_spacecraft

if TYPE_CHECKING:
    from mrpctl.simulation import SimulationResult

__all__ = [
    "PHYSICAL_LABELS",
    "STATE_LABELS",
    "AxisMargin",
    "BasiliskGains",
    "DelayedLoop",
    "LoopMargins",
    "basilisk_mrp_feedback",
    "basilisk_state",
    "delayed_loop",
    "from_time_response",
    "gain_from_basilisk",
    "loop_margins",
    "state_from_basilisk",
    "to_time_response",
]

#: State names of x = [σ; ω/4] used on every python-control system and response.
STATE_LABELS = ("sigma1", "sigma2", "sigma3", "omega1/4", "omega2/4", "omega3/4")
#: State names of the physical state [σ; ω] (ω in rad/s), with ``physical=True``.
PHYSICAL_LABELS = ("sigma1", "sigma2", "sigma3", "omega1", "omega2", "omega3")
INPUT_LABELS = ("u1", "u2", "u3")


# ------------------------------------------------------------------------------ the delayed loop
@dataclass(frozen=True, eq=False)
class DelayedLoop:
    """The linearised loop ẋ = A x + B u, u = K x(t − τ), in python-control terms.

    Attributes
    ----------
    plant : control.StateSpace
        ẋ = A x + B u, y = x: A = [[0, I₃], [0, 0]], B = [0; ¼ J⁻¹]; inputs u (N m), outputs
        and states x = [σ; ω/4].
    K : numpy.ndarray
        (3, 6) static gain (N m), applied as u = K y(t − τ) (positive feedback sign).
    tau : float
        The measurement delay τ (s).
    """

    plant: control.StateSpace
    K: np.ndarray = field(repr=False)
    tau: float

    @property
    def A(self) -> np.ndarray:
        """(6, 6) A."""
        return readonly(self.plant.A)

    @property
    def B(self) -> np.ndarray:
        """(6, 3) B."""
        return readonly(self.plant.B)

    @property
    def A_d(self) -> np.ndarray:
        """(6, 6) A_d = B K of ẋ = A x + A_d x(t − τ)."""
        return readonly(self.B @ self.K)

    def delay(self, order: int) -> control.StateSpace:
        """e^{−sτ} on each of the 3 torque channels by a Padé approximation of ``order`` (3 in, 3 out)."""
        n = integer("order", order, minimum=1, maximum=20)
        if self.tau == 0.0:
            return control.ss([], [], [], np.eye(3), inputs=list(INPUT_LABELS), outputs=list(INPUT_LABELS))
        num, den = control.pade(self.tau, n)
        single = control.ss(control.tf(num, den))
        a = np.kron(np.eye(3), single.A)
        b = np.kron(np.eye(3), single.B)
        c = np.kron(np.eye(3), single.C)
        d = np.kron(np.eye(3), single.D)
        return control.ss(a, b, c, d, inputs=[f"{u}_cmd" for u in INPUT_LABELS], outputs=list(INPUT_LABELS))

    def pade(self, order: int) -> control.StateSpace:
        """The closed loop with e^{−sτ} replaced by its Padé approximation of ``order``.

        The loop u = P_n(s) K x, closed by ``control.feedback`` with positive sign; its
        poles approach the rightmost characteristic roots of det(sI − A − A_d e^{−sτ}) as
        ``order`` grows. States: x, then the 3 × ``order`` Padé states.

        Parameters
        ----------
        order : int
            Padé order n (1-20) of each of the three delay channels.

        Returns
        -------
        control.StateSpace
            Input: a torque disturbance added to u (N m); output: x.
        """
        controller = self.delay(order) * control.ss([], [], [], self.K)
        return control.feedback(self.plant, controller, sign=1)

    def __str__(self) -> str:
        return f"delayed loop xdot = A x + B K x(t - tau), tau = {self.tau:g} s (6 states, 3 inputs)"


def delayed_loop(spacecraft: Spacecraft, K: Any, tau: Any = 0.0, *, physical: bool = False) -> DelayedLoop:
    """The loop linearised at x = 0 as a ``control.StateSpace`` plant, its gain and its delay.

    Parameters
    ----------
    spacecraft : Spacecraft
    K : array_like or PDGains
        (3, 6) gain on x = [σ; ω/4] (N m), convention K = [4 J K₁, 4 J K₂], or the physical
        [`PDGains`][mrpctl.conventions.PDGains].
    tau : float
        Measurement delay τ >= 0 (s).
    physical : bool, keyword-only
        The plant in the physical state [σ; ω] (ω in rad/s, labels `PHYSICAL_LABELS`):
        A = [[0, ¼ I₃], [0, 0]], B = [0; J⁻¹], and the gain on it [−P_σ, −P_ω] = [K_σ, K_ω/4]
        (u = −P_σ σ − P_ω ω); the same loop (the same poles and margins). Default False.

    Returns
    -------
    DelayedLoop
        ``plant.A`` and ``plant.B`` are exactly [`mrpctl.model.plant_model`][mrpctl.model.plant_model]'s A and B,
        so ``B @ K`` is [`mrpctl.design.linearized_loop`][mrpctl.design.linearized_loop]'s A_d (without
        ``physical``; with it, the same matrices in the state [σ; ω]).
    """
    sc = check_spacecraft(spacecraft)
    k = gain_matrix(K)
    delay = nonnegative_scalar("tau", tau)
    if not isinstance(physical, bool):
        raise SpecificationError(f"physical must be True or False, got {physical!r}")
    model = plant_model(sc)
    a, b, labels = np.array(model.A), np.array(model.B), STATE_LABELS
    if physical:  # z = S x with S = diag(I, 4 I): A -> S A S^-1, B -> S B, K -> K S^-1
        scale = np.diag([1.0, 1.0, 1.0, RATE_SCALE, RATE_SCALE, RATE_SCALE])
        a, b, labels = scale @ a / scale.diagonal(), scale @ b, PHYSICAL_LABELS
        k = k / scale.diagonal()
    plant = control.ss(
        a,
        b,
        np.eye(6),
        np.zeros((6, 3)),
        inputs=list(INPUT_LABELS),
        outputs=list(labels),
        states=list(labels),
        name="mrpctl_plant",
    )
    return DelayedLoop(plant=plant, K=readonly(k), tau=delay)


# ------------------------------------------------------------------------------ margins
@dataclass(frozen=True)
class AxisMargin:
    """Phase margin and crossover of one axis, L(s) = −(K₂ s + K₁)/s² broken at the delay.

    Attributes
    ----------
    axis : int
        0, 1 or 2.
    phase_margin : float
        Phase margin (rad); ``math.inf`` when |L(iω)| never crosses 1.
    crossover : float
        Gain crossover frequency ω_c (rad/s), |L(iω_c)| = 1.
    delay_margin : float
        PM / ω_c (s): the largest delay the axis tolerates.
    gain_margin : float
        Gain margin of the delay-free loop as python-control computes it (``math.inf`` when the
        phase never crosses −180°, as for every PD axis without delay); the delayed loop's margins
        are in [`mrpctl.design.performance`][mrpctl.design.performance].
    phase_crossover : float
        Frequency (rad/s) of that gain margin (nan when it is infinite).
    """

    axis: int
    phase_margin: float
    crossover: float
    delay_margin: float
    gain_margin: float = math.inf
    phase_crossover: float = math.nan

    def __str__(self) -> str:
        return (
            f"axis {self.axis + 1}: phase margin {math.degrees(self.phase_margin):.4g} deg at crossover "
            f"{self.crossover:.6g} rad/s -> delay margin {self.delay_margin:.6g} s"
        )


@dataclass(frozen=True)
class LoopMargins:
    """Per-axis phase margins of the delayed loop (python-control ``margin``).

    Attributes
    ----------
    axes : tuple of AxisMargin
        One per body axis.
    """

    axes: tuple[AxisMargin, ...]

    @property
    def delay_margin(self) -> float:
        """The smallest per-axis PM/ω_c (s): the delay margin of the whole loop."""
        return min(a.delay_margin for a in self.axes)

    @property
    def critical(self) -> AxisMargin:
        """The axis that sets the delay margin."""
        return min(self.axes, key=lambda a: a.delay_margin)

    def __str__(self) -> str:
        lines = [f"delay margin {self.delay_margin:.6g} s from phase margins (axis {self.critical.axis + 1} sets it)"]
        lines += [f"  {a}" for a in self.axes]
        return "\n".join(lines)


def loop_margins(spacecraft: Spacecraft, K: Any) -> LoopMargins:
    """Phase margin, crossover and implied delay margin of each axis of the loop.

    Breaking the loop at the delay, axis i has L_i(s) = −(K₂ᵢ s + K₁ᵢ)/s² (σ̈ = K₁σ + K₂σ̇
    per axis with K₁ = J⁻¹K_σ/4, K₂ = J⁻¹K_ω/4); a delay τ adds phase −ωτ, so the axis
    loses stability at τ = PM/ω_c. Computed with ``control.margin``.

    Parameters
    ----------
    spacecraft : Spacecraft
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).

    Returns
    -------
    LoopMargins

    Raises
    ------
    SpecificationError
        When K₁ or K₂ is not diagonal (coupled axes have no per-axis phase margin; use
        [`mrpctl.design.LinearizedLoop.delay_margin`][mrpctl.design.LinearizedLoop.delay_margin]).
    """
    sc = check_spacecraft(spacecraft)
    k1, k2 = pd_from_gain(sc, gain_matrix(K))
    off = max(float(np.abs(k1 - np.diag(np.diag(k1))).max()), float(np.abs(k2 - np.diag(np.diag(k2))).max()))
    scale = max(float(np.abs(k1).max()), float(np.abs(k2).max()), np.finfo(float).tiny)
    if off > 1e-12 * scale:
        raise SpecificationError(
            "K must give diagonal K1 = J^-1 K_sigma / 4 and K2 = J^-1 K_omega / 4 for per-axis phase margins; "
            "the axes of this loop are coupled: use linearized_loop(spacecraft, K).delay_margin()"
        )
    axes = []
    for i in range(3):
        loop = control.tf([-k2[i, i], -k1[i, i]], [1.0, 0.0, 0.0])
        gm, pm_deg, wpc, wc = control.margin(loop)
        pm = math.radians(float(pm_deg)) if np.isfinite(pm_deg) else math.inf
        wc = float(wc) if np.isfinite(wc) else math.nan
        tau = pm / wc if np.isfinite(pm) and np.isfinite(wc) and wc > 0 else math.inf
        axes.append(
            AxisMargin(
                axis=i,
                phase_margin=pm,
                crossover=wc,
                delay_margin=max(tau, 0.0),
                gain_margin=float(gm) if np.isfinite(gm) else math.inf,
                phase_crossover=float(wpc) if np.isfinite(wpc) else math.nan,
            )
        )
    return LoopMargins(axes=tuple(axes))


# ------------------------------------------------------------------------------ runs
def to_time_response(result: SimulationResult, *, physical: bool = False) -> control.TimeResponseData:
    """A run as ``control.TimeResponseData``: time t (s), states and outputs x = [σ; ω/4], inputs u (N m).

    The torque u is held over [t_k, t_{k+1}) (zero-order hold); python-control draws it
    by linear interpolation. The title names the rule and τ. With ``physical=True`` the states
    and outputs are [σ; ω] (ω in rad/s), labelled `PHYSICAL_LABELS` (``sigma1``-``sigma3``,
    ``omega1``-``omega3``): the result's own ``sigma`` and ``omega``.
    """
    if not isinstance(physical, bool):
        raise SpecificationError(f"physical must be True or False, got {physical!r}")
    t = np.asarray(result.t, dtype=float)
    x = np.hstack((result.sigma, result.omega)) if physical else np.asarray(result.x, dtype=float)
    u = np.asarray(result.u, dtype=float)
    labels = PHYSICAL_LABELS if physical else STATE_LABELS
    return control.TimeResponseData(
        t.copy(),
        x.T.copy(),
        x.T.copy(),
        u.T.copy(),
        output_labels=list(labels),
        state_labels=list(labels),
        input_labels=list(INPUT_LABELS),
        title=f"{result.rule}, tau = {result.tau:g} s",
        sysname="mrpctl",
    )


def from_time_response(response: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, x, u) arrays from a ``control.TimeResponseData`` with the labels of
    [`to_time_response`][mrpctl.interop.to_time_response] (either form: physical outputs [σ; ω] are
    converted to x).

    Returns
    -------
    t : numpy.ndarray
        (n,) times (s).
    x : numpy.ndarray
        (n, 6) states [σ; ω/4].
    u : numpy.ndarray
        (n, 3) torques (N m).
    """
    if not isinstance(response, control.TimeResponseData):
        raise SpecificationError(f"response must be a control.TimeResponseData, got {type(response).__name__}")
    outputs = tuple(response.output_labels)
    if outputs not in (STATE_LABELS, PHYSICAL_LABELS) or tuple(response.input_labels) != INPUT_LABELS:
        raise SpecificationError(
            f"response must have outputs {list(STATE_LABELS)} (or {list(PHYSICAL_LABELS)}) and inputs "
            f"{list(INPUT_LABELS)}, got {list(response.output_labels)} and {list(response.input_labels)}"
        )
    t = finite_array("response.time", response.time, (None,))
    x = np.asarray(response.outputs, dtype=float).T
    u = np.asarray(response.inputs, dtype=float).T
    if x.shape != (len(t), 6) or u.shape != (len(t), 3):
        raise DimensionError(f"response must hold (6, {len(t)}) outputs and (3, {len(t)}) inputs")
    if outputs == PHYSICAL_LABELS:
        x = state(x[:, 0:3], x[:, 3:6])
    return readonly(t), readonly(x), readonly(u)


# ------------------------------------------------------------------------------ Basilisk
@dataclass(frozen=True)
class BasiliskGains:
    """Settings of Basilisk's ``mrpFeedback`` that apply mrpctl's gain (undelayed regulation to N).

    Basilisk's documented law with ω_r = 0, no integral term (Ki < 0), no wheels, no known
    torque and ``controlLawType = 0`` is L_r = −K σ_BR − P ω_BR (the module negates its
    accumulated sum before writing ``torqueRequestBody``). mrpctl's law is u = K x with
    x = [σ; ω/4] and K = [k_σ I₃, k_ω I₃], i.e. u = k_σ σ + (k_ω/4) ω, so K = −k_σ and
    P = −k_ω/4, with σ_BR = σ_BN (reference frame R = N) and ω_BR_B = ω_BN_B.

    Attributes
    ----------
    K : float
        Basilisk ``K`` (N m), = −k_σ.
    P : float
        Basilisk ``P`` (N m s), = −k_ω/4.
    Ki : float
        −1: integral feedback off.
    controlLawType : int
        0: no ω × (Iω) term (mrpctl's PD has none).
    unmapped : numpy.ndarray
        (3, 6) part of mrpctl's K that Basilisk does not apply (K − [k_σ I₃, k_ω I₃]); zero
        unless [`basilisk_mrp_feedback`][mrpctl.interop.basilisk_mrp_feedback] was asked for the ``nearest`` scalar
        gains.
    names : dict
        Basilisk message field -> mrpctl quantity.
    """

    K: float
    P: float
    Ki: float = -1.0
    controlLawType: int = 0
    unmapped: np.ndarray = field(default_factory=lambda: readonly(np.zeros((3, 6))), compare=False)
    names: dict[str, str] = field(
        default_factory=lambda: {
            "sigma_BR (= sigma_BN, R = N)": "x[0:3] = sigma",
            "omega_BR_B (= omega_BN_B)": "4 * x[3:6] = omega (rad/s)",
            "torqueRequestBody": "u (N m)",
            "ISCPntB_B": "spacecraft.inertia (kg m^2), row-major",
        }
    )

    def __str__(self) -> str:
        text = (
            f"Basilisk mrpFeedback: K = {self.K:.6g}, P = {self.P:.6g}, Ki = {self.Ki:g}, "
            f"controlLawType = {self.controlLawType} (undelayed; Basilisk has no measurement delay here)"
        )
        if np.any(self.unmapped):
            text += f"; NOT the same controller: gain entries up to {np.max(np.abs(self.unmapped)):.3g} N m unmapped"
        return text


def _scalar_block_defect(name: str, block: np.ndarray) -> str | None:
    """Why a 3×3 gain block is not a scalar times I₃ (what mrpFeedback cannot take), or None."""
    s = float(np.trace(block)) / 3.0
    tolerance = 1e-12 * max(float(np.max(np.abs(block))), 1.0)
    off = block - np.diag(np.diag(block))
    if np.max(np.abs(off)) > tolerance:
        i, j = np.unravel_index(int(np.argmax(np.abs(off))), off.shape)
        return (
            f"{name} couples the axes (entry [{i}, {j}] = {block[i, j]:.6g}): mrpFeedback applies its gain to each "
            "axis of sigma_BR / omega_BR_B alone, so no off-diagonal gain can be expressed"
        )
    diagonal = np.diag(block)
    if np.max(np.abs(diagonal - s)) > tolerance:
        return (
            f"{name} differs per axis (diagonal {np.round(diagonal, 6).tolist()}): mrpFeedback has one scalar "
            "for all three axes"
        )
    return None


def basilisk_mrp_feedback(K: Any, *, nearest: bool = False) -> BasiliskGains:
    """Basilisk ``mrpFeedback`` gains equal to mrpctl's K = [k_σ I₃, k_ω I₃].

    Basilisk's ``mrpFeedback`` (src/fswAlgorithms/attControl/mrpFeedback) takes two scalars,
    ``K`` on σ_BR and ``P`` on ω_BR_B, the same on the three axes; it has no gain matrix. A
    gain whose 3×3 blocks are scalar multiples of I₃ maps exactly; a per-axis (diagonal with
    different entries) or coupled (off-diagonal) block cannot be expressed and is refused,
    unless ``nearest=True`` asks for the nearest scalar gains, with what Basilisk then does
    not apply reported in `BasiliskGains.unmapped`.

    Parameters
    ----------
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    nearest : bool, keyword-only
        Map per-axis or coupled blocks to their nearest scalar times I₃ (in the Frobenius norm:
        the mean of the diagonal) instead of refusing them. The mapped loop is then another
        controller than K: check its stability and margins before flying it.

    Returns
    -------
    BasiliskGains
        K_bsk = −k_σ and P_bsk = −k_ω/4; ``unmapped`` = K − [k_σ I₃, k_ω I₃] (zero when exact).

    Raises
    ------
    SpecificationError
        When a 3×3 block of K is not a multiple of I₃ and ``nearest`` is False: the message
        names the block and what in it ``mrpFeedback`` cannot take (per-axis or coupled gains).
    """
    k = gain_matrix(K)
    blocks = {"K[:, :3] (k_sigma)": k[:, :3], "K[:, 3:] (k_omega)": k[:, 3:]}
    defects = [d for d in (_scalar_block_defect(name, block) for name, block in blocks.items()) if d]
    if defects and not nearest:
        raise SpecificationError(
            "K must have each 3x3 block a scalar times I3 for Basilisk's mrpFeedback (scalar K and P): "
            + "; ".join(defects)
            + "; pass nearest=True for the nearest scalar gains (another controller: check it)"
        )
    k_sigma, k_omega = (float(np.trace(block)) / 3.0 for block in blocks.values())
    mapped = np.hstack((k_sigma * np.eye(3), k_omega * np.eye(3)))
    return BasiliskGains(K=-k_sigma, P=-k_omega / 4.0, unmapped=readonly(k - mapped))


def gain_from_basilisk(K_bsk: Any, P_bsk: Any) -> np.ndarray:
    """mrpctl's (3, 6) K = [−K_bsk I₃, −4 P_bsk I₃] from Basilisk's scalar ``K`` and ``P``."""
    k = finite_scalar("K_bsk", K_bsk)
    p = finite_scalar("P_bsk", P_bsk)
    return readonly(gain_from_parts(k * np.eye(3), p * np.eye(3)))


def basilisk_state(x: Any) -> tuple[np.ndarray, np.ndarray]:
    """(sigma_BN, omega_BN_B) in Basilisk's names from x = [σ; ω/4] (ω in rad/s)."""
    sigma, omega = state_parts(finite_array("x", x, (6,)))
    return readonly(sigma), readonly(omega)


def state_from_basilisk(sigma_BN: Any, omega_BN_B: Any) -> np.ndarray:
    """x = [σ; ω/4] from Basilisk's sigma_BN and omega_BN_B (rad/s)."""
    sigma = finite_array("sigma_BN", sigma_BN, (3,))
    omega = finite_array("omega_BN_B", omega_BN_B, (3,))
    return readonly(state(sigma, omega))
