"""The predictor controller's options: `Predictor` (the model the flight software integrates) and the rule
`OnPredicted` (the MRP set chosen on the predicted attitude)."""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca

from mrpctl._validation import finite_scalar
from mrpctl.errors import SpecificationError
from mrpctl.spacecraft import Spacecraft, check_spacecraft
from mrpctl.switching import SwitchingRule

__all__ = ["OnPredicted", "Predictor", "PredictorForm"]


class PredictorForm(enum.Enum):
    """How the predictor's model copy is advanced and corrected (``design/predictor.md``).

    Both forms linearise to the same finite-spectrum-assignment prediction, so the exact stability tests of
    [`predictor_stability`][mrpctl.predictor.predictor_stability] hold for either; they differ away from the
    origin and in cost.

    * ``NONLINEAR`` (the default, form (b)): the copy is the nonlinear rigid body J_m, one RK4 step per sample,
      corrected on the rotation group by the copy's own motion over the last τ (Ĉ = C(τ δω) C(z_k) C(z_{k−d})ᵀ
      C(y)). With J_m = J the prediction is the present state up to one RK4 step's error.
    * ``LINEAR``: the copy is the linearised model's exact zero-order-hold transition (no RK4, no libm call),
      and the prediction is the FSA increment v = τ w_y + S_σ (S: the copy's forced response over the last τ)
      composed on the rotation group with the measured attitude, Ĉ = C(p(v)) C(y), p the [3/2] Padé MRP of the
      rotation 4v. No gyroscopic torque and no non-commutativity over τ: exact for a rotation about a fixed
      axis (up to the Padé error, below 1e-3 of the angle for rotations up to π over τ), slower to settle on
      fast skew-axis motion. About 1.8x the lanes' throughput of ``NONLINEAR``.
    """

    NONLINEAR = "nonlinear"
    LINEAR = "linear"

    @classmethod
    def parse(cls, value: object, name: str = "form") -> PredictorForm:
        """The form of ``value`` (a `PredictorForm` or its value, e.g. ``"linear"``)."""
        if isinstance(value, cls):
            return value
        for form in cls:
            if value == form.value:
                return form
        choices = ", ".join(repr(form.value) for form in cls)
        raise SpecificationError(f"{name} (the predictor form) must be one of {choices}, got {value!r}")


@dataclass(frozen=True, eq=False)
class Predictor:
    """The predictor controller of [`mrpctl.simulate`][mrpctl.simulation.simulate] and
    [`mrpctl.simulate_batch`][mrpctl.simulate_batch] (form (b)).

    The controller keeps a copy z of its model (inertia J_m of ``model``), advanced by one RK4
    step per sample with the torque it actually applied (after the actuator's limits; without the
    disturbance, which it does not know), starting at z_0 = x0. It remembers z over the last d
    samples and corrects the copy with the delayed measurement y_k = x(t_k − τ) on the rotation
    group: with C_E = C(z_{k−d})ᵀ C(y_k) and δω = ω_y − ω_z(k−d),

        Ĉ_k = C(τ δω) C(z_k) C_E,   ω̂_k = ω_z(k) + δω,   u_k = K [σ̂_k; ω̂_k/4]

    (``design/predictor.md``). With J_m = J the prediction is the present state up to the
    integration error of one RK4 step per sample, and the loop is the undelayed one. The
    controller's MRP set is chosen on σ̂ by the rule [`OnPredicted`][mrpctl.predictor.OnPredicted], the one rule a
    predictor run takes.

    With ``form=PredictorForm.LINEAR`` the copy is the linearised model instead, and the correction the FSA
    increment composed on the group (`PredictorForm`): cheaper, exact only about a fixed axis.

    Parameters
    ----------
    model : Spacecraft
        The controller's model (inertia J_m, kg m²); it may differ from the simulated plant.
    form : PredictorForm
        How the copy is advanced and corrected; default `PredictorForm.NONLINEAR` (form (b)).
    """

    model: Spacecraft
    form: PredictorForm = PredictorForm.NONLINEAR

    def __post_init__(self) -> None:
        object.__setattr__(self, "model", check_spacecraft(self.model, "model"))
        object.__setattr__(self, "form", PredictorForm.parse(self.form))

    def __str__(self) -> str:
        if self.form is PredictorForm.LINEAR:
            return f"Predictor (linear model copy, FSA increment on the group; model {self.model})"
        return f"Predictor (model copy with group correction; model {self.model})"


@dataclass(frozen=True)
class OnPredicted(SwitchingRule):
    """Switch the controller's MRP set on the predicted attitude σ̂ (with a [`Predictor`][mrpctl.predictor.Predictor]
    only).

    At each sample σ̂ is first taken in the set nearest σ̂_{k−1} (continuity), then replaced by its
    shadow when |σ̂| >= α; that replacement is the run's switch. α = 1 keeps σ̂ in the short set
    (the paper's undelayed rule, applied to the prediction); α > 1 adds hysteresis (σ̂ may go up to
    α before it switches); ``alpha=None`` never switches (σ̂ follows continuity only). The plant's
    own MRP is kept in the short set as bookkeeping (no physical effect): its
    [`expressions`][mrpctl.switching.SwitchingRule.expressions] as a plain rule are the ``OnCurrent`` test.

    Parameters
    ----------
    alpha : float or None
        Switching threshold α >= 1 on |σ̂| (dimensionless), default 1; None: never switch.
    """

    label: ClassVar[str] = "on-predicted"

    alpha: float | None = 1.0

    def __post_init__(self) -> None:
        if self.alpha is not None:
            alpha = finite_scalar("alpha", self.alpha)
            if alpha < 1.0:
                raise SpecificationError(
                    f"alpha (switching threshold on |sigma_hat|) must be >= 1 or None, got {alpha}"
                )
            object.__setattr__(self, "alpha", alpha)

    def parameters(self) -> tuple[float]:
        """(α,): the run-time parameter of the predictor sample (inf when ``alpha`` is None)."""
        return (math.inf if self.alpha is None else float(self.alpha),)

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        # The plant bookkeeping (no physical effect): the OnCurrent test.
        return ca.dot(sigma, sigma) >= 1

    def __str__(self) -> str:
        if self.alpha is None:
            return "OnPredicted (never switch; sigma_hat by continuity)"
        return f"OnPredicted (switch sigma_hat when |sigma_hat| >= {self.alpha:g})"
