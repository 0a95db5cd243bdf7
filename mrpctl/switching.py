"""MRP shadow-set switching rules, as frozen values that emit CasADi expressions.

At every measurement sample t_k = k h the simulator hands the rule

* the current state x_k = [σ_k; ω_k/4] (before any switch at t_k),
* the delayed measurement m_{k−d} = [σ; ω/4] recorded d = τ/h samples earlier
  (for d = 0 it is the current state x_k itself, since no older value is needed),
* the rule's memory (one number, carried from sample to sample),

and the rule returns the state after the rule (σ_k possibly replaced by its shadow
σˢ = −σ/|σ|²; ω is never touched), the memory for the next sample and a 0/1 flag
``switched``. The rules are written with CasADi ``if_else`` so that they compile into
the generated integrator; nothing here runs per sample in Python.

Rules (paper sections IV-V, and one of ours):

========================  =====================================================
``NoSwitching()``          never switch
``OnCurrent()``            |σ_k| >= 1                       (section IV, first strategy)
``OnDelayed()``            |σ(m_{k−d})| >= 1               (section IV, second strategy)
``BoundaryLayer(eps)``     1 <= |σ(m_{k−d})| <= 1 + ε      (section V, taken literally)
``DelayAware(alpha)``      |σ(m_{k−d})| >= α and m_{k−d} was taken at or after the
                           most recent switch (k − d >= k_last)
========================  =====================================================

See ``design/switching.md`` for the discussion of each rule.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, ClassVar

import casadi as ca

from mrpctl._validation import finite_scalar
from mrpctl.errors import SpecificationError
from mrpctl.mrp import shadow_expr

__all__ = [
    "BoundaryLayer",
    "DelayAware",
    "NoSwitching",
    "OnCurrent",
    "OnDelayed",
    "SwitchingRule",
]

#: Size of the rule memory vector carried between samples (the same for every rule).
MEMORY_SIZE = 1
#: Size of the rule parameter vector (ε or α; unused entries are 0).
PARAMETER_SIZE = 1


class SwitchingRule(abc.ABC):
    """Base class of the shadow-set switching rules.

    A rule is a frozen value; [`expressions`][mrpctl.switching.SwitchingRule.expressions] writes it as CasADi
    expressions and
    [`function`][mrpctl.switching.SwitchingRule.function] as a named CasADi Function
    ``rule(x, x_meas, memory) -> (x_next, memory_next, switched)``.

    Subclasses define `_condition` (when to switch) and, when they carry memory,
    `_next_memory` and [`initial_memory`][mrpctl.switching.SwitchingRule.initial_memory].
    """

    #: Short label used in summaries and file names.
    label: ClassVar[str] = "rule"

    # ------------------------------------------------------------------ interface
    def parameters(self) -> tuple[float]:
        """The rule's numeric parameter vector (length 1; 0 when the rule has none)."""
        return (0.0,)

    def initial_memory(self, *, delay_samples: int) -> float:
        """The memory value at the first sample (k = 0) for a delay of d samples."""
        _delay(delay_samples)
        return 0.0

    def expressions(
        self,
        x: Any,
        x_meas: Any,
        memory: Any,
        *,
        delay_samples: int,
        parameters: Any = None,
    ) -> tuple[Any, Any, Any]:
        """The rule as CasADi expressions.

        Parameters
        ----------
        x : casadi.SX
            Current state x_k = [σ_k; ω_k/4] (6), before the rule.
        x_meas : casadi.SX
            The measurement the rule may look at: m_{k−d} (6); x_k when d = 0.
        memory : casadi.SX
            The rule memory (1).
        delay_samples : int
            d = τ/h, keyword-only.
        parameters : casadi.SX or None
            The parameter vector (1); ``None`` uses [`parameters`][mrpctl.switching.SwitchingRule.parameters] as
            constants.

        Returns
        -------
        x_next, memory_next, switched : casadi.SX
            The state after the rule, the memory for sample k + 1, and 1.0 when σ_k
            was replaced by its shadow (0.0 otherwise).
        """
        d = _delay(delay_samples)
        if parameters is None:
            parameters = ca.DM(self.parameters())
        sigma = x[0:3]
        switched = self._condition(sigma, x_meas[0:3], memory, parameters, d)
        switched = ca.if_else(switched, 1.0, 0.0)
        sigma_next = ca.if_else(switched, shadow_expr(sigma), sigma)
        x_next = ca.vertcat(sigma_next, x[3:6])
        return x_next, self._next_memory(memory, switched, d), switched

    def function(self, *, delay_samples: int) -> ca.Function:
        """The rule as a pure-SX CasADi Function.

        ``rule(x, x_meas, memory) -> (x_next, memory_next, switched)``.
        """
        x = ca.SX.sym("x", 6)
        x_meas = ca.SX.sym("x_meas", 6)
        memory = ca.SX.sym("memory", MEMORY_SIZE)
        out = self.expressions(x, x_meas, memory, delay_samples=delay_samples)
        return ca.Function(
            "rule",
            [x, x_meas, memory],
            list(out),
            ["x", "x_meas", "memory"],
            ["x_next", "memory_next", "switched"],
        )

    # ------------------------------------------------------------- for subclasses
    @abc.abstractmethod
    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        """Boolean CasADi expression: switch σ_k to its shadow at this sample."""

    def _next_memory(self, memory: Any, switched: Any, d: int) -> Any:
        return memory


def _delay(delay_samples: Any) -> int:
    if isinstance(delay_samples, bool) or not isinstance(delay_samples, int) or delay_samples < 0:
        raise SpecificationError(f"delay_samples must be an integer >= 0, got {delay_samples!r}")
    return delay_samples


def _norm_squared(v: Any) -> Any:
    return ca.dot(v, v)


@dataclass(frozen=True)
class NoSwitching(SwitchingRule):
    """Never switch: σ is integrated as it is, through |σ| = 1 (paper Fig. 6)."""

    label: ClassVar[str] = "no-switching"

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        return ca.DM(0)

    def __str__(self) -> str:
        return "NoSwitching (never switch)"


@dataclass(frozen=True)
class OnCurrent(SwitchingRule):
    """Switch when the plant's attitude leaves the unit sphere: |σ_k| >= 1.

    Paper section IV, first strategy. It is implementable with delayed data: it keeps the
    plant's MRP in the short set, so every recorded measurement is a short-set MRP and
    u = K [short(σ(t − τ)); ω(t − τ)/4] is exactly what a controller computes from the
    delayed measurement alone (no knowledge of the current σ is needed). The chatter of the
    paper's Figs. 4-5 needs the state-side model of [`OnDelayed`][mrpctl.OnDelayed].
    """

    label: ClassVar[str] = "on-current"

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        return _norm_squared(sigma) >= 1

    def __str__(self) -> str:
        return "OnCurrent (switch when |sigma(t)| >= 1)"


@dataclass(frozen=True)
class OnDelayed(SwitchingRule):
    """Switch σ_k when the delayed measurement is outside the unit sphere: |σ(m_{k−d})| >= 1.

    Paper section IV, second strategy: the latest available information decides.
    """

    label: ClassVar[str] = "on-delayed"

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        return _norm_squared(sigma_meas) >= 1

    def __str__(self) -> str:
        return "OnDelayed (switch when |sigma(t - tau)| >= 1)"


@dataclass(frozen=True)
class BoundaryLayer(SwitchingRule):
    """Switch σ_k when the delayed measurement is in the layer 1 <= |σ(m_{k−d})| <= 1 + ε.

    Paper section V, taken literally. It still toggles on the paper's case: see
    ``design/switching.md``.

    Parameters
    ----------
    eps : float
        Layer thickness ε > 0 (dimensionless, in units of |σ|).
    """

    eps: float
    label: ClassVar[str] = "boundary-layer"

    def __post_init__(self) -> None:
        eps = finite_scalar("eps", self.eps)
        if eps <= 0.0:
            raise SpecificationError(f"eps (boundary layer thickness) must be > 0, got {eps}")
        object.__setattr__(self, "eps", eps)

    def parameters(self) -> tuple[float]:
        return (self.eps,)

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        norm_squared = _norm_squared(sigma_meas)
        upper = (1 + parameters[0]) ** 2
        return ca.logic_and(norm_squared >= 1, norm_squared <= upper)

    def __str__(self) -> str:
        return f"BoundaryLayer (switch when 1 <= |sigma(t - tau)| <= 1 + {self.eps:g})"


@dataclass(frozen=True)
class DelayAware(SwitchingRule):
    """Switch σ_k when |σ(m_{k−d})| >= α and m_{k−d} postdates the last switch.

    The chatter of [`OnDelayed`][mrpctl.OnDelayed] comes from acting again and again on stale
    measurements taken before the last switch, which still show the old set. This rule
    ignores them: its memory is the number of samples since the last switch
    (saturated at max(d, 1)), and a switch is allowed only when it is >= d, that is when
    k − d >= k_last. With α > 1 it adds a hysteresis of the Mayhew-Sanfelice-Teel kind:
    switching at |σ| > α corresponds to their δ = (α² − 1)/(α² + 1).

    Not sound in general: it is the fix of the paper's state-side model and works with the
    paper's K, but after a crossing the plant stays in the long set for τ and the torque acts on
    |σ_long| = tan((180° + |ω|τ)/4), unbounded as |ω|τ → π. With 0.7× the fastest certified
    critically damped gains and 200 tumbles at |ω| = 5 rad/s it fails to settle in 60 s on 6/200
    runs at τ = 0.5 s and 42/200 at τ = 1.0 s, where [`NoSwitching`][mrpctl.NoSwitching],
    [`OnCurrent`][mrpctl.OnCurrent]
    and the controller-side hysteretic selection ([`mrpctl.flight.Hysteretic`][mrpctl.flight.Hysteretic]) converge on
    all 200 (``design/flight.md``). Prefer the controller-side rule for flight designs.

    Parameters
    ----------
    alpha : float
        Switching threshold α >= 1 on |σ| of the delayed measurement (default 1).
    """

    alpha: float = 1.0
    label: ClassVar[str] = "delay-aware"

    def __post_init__(self) -> None:
        alpha = finite_scalar("alpha", self.alpha)
        if alpha < 1.0:
            raise SpecificationError(f"alpha (switching threshold on |sigma|) must be >= 1, got {alpha}")
        object.__setattr__(self, "alpha", alpha)

    @property
    def hysteresis_delta(self) -> float:
        """δ = (α² − 1)/(α² + 1) of Mayhew, Sanfelice and Teel's hysteretic switching."""
        return (self.alpha**2 - 1.0) / (self.alpha**2 + 1.0)

    def parameters(self) -> tuple[float]:
        return (self.alpha,)

    def initial_memory(self, *, delay_samples: int) -> float:
        return float(max(_delay(delay_samples), 1))

    def _condition(self, sigma: Any, sigma_meas: Any, memory: Any, parameters: Any, d: int) -> Any:
        fresh = memory[0] >= d
        return ca.logic_and(_norm_squared(sigma_meas) >= parameters[0] ** 2, fresh)

    def _next_memory(self, memory: Any, switched: Any, d: int) -> Any:
        return ca.fmin(ca.if_else(switched, 0.0, memory) + 1.0, float(max(d, 1)))

    def __str__(self) -> str:
        text = f"DelayAware (switch when |sigma(t - tau)| >= {self.alpha:g} measured after the last switch"
        if self.alpha > 1.0:
            text += f"; hysteresis delta = {self.hysteresis_delta:.4g}"
        return text + ")"
