"""The switching rules by name: the names that scenario and campaign files, saved results and the command
line give the rules, and the rule each name makes."""

from __future__ import annotations

import math
from typing import Any

from mrpctl._validation import finite_scalar
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.predictor import OnPredicted
from mrpctl.switching import BoundaryLayer, DelayAware, NoSwitching, OnCurrent, OnDelayed, SwitchingRule

__all__ = ["DEFAULT_DELTA", "DEFAULT_RULE", "RULE_NAMES", "rule_from_name", "rule_name"]

#: The hysteresis δ of the default rule: inside the band α ≈ 1.05–1.2 (δ ≈ 0.05–0.18) that design/flight.md
#: recommends for attitude noise up to 0.01 rad per axis (α = √((1 + δ)/(1 − δ)) = 1.106).
DEFAULT_DELTA = 0.1
#: The rule of the command line without a scenario file (``simulate``, ``sweep``), of ``design --toml`` and of
#: the ``init`` starter: the controller-side set selection with hysteresis, ``Hysteretic(DEFAULT_DELTA)``, which
#: converges wherever ``NoSwitching`` and ``OnCurrent`` do in the tumble studies of design/flight.md (the
#: plant-side ``DelayAware`` does not; it stays available by name).
DEFAULT_RULE: SwitchingRule = Hysteretic(DEFAULT_DELTA)

#: The rule classes by their file and command-line names.
RULE_NAMES = {
    "none": NoSwitching,
    "on-current": OnCurrent,
    "on-delayed": OnDelayed,
    "boundary-layer": BoundaryLayer,
    "delay-aware": DelayAware,
    "hysteretic": Hysteretic,
    "on-predicted": OnPredicted,
}


def rule_from_name(
    name: str, *, eps: float | None = None, alpha: float | None = None, delta: float | None = None
) -> SwitchingRule:
    """The switching rule called ``name`` (one of `RULE_NAMES`).

    ``eps`` is required by (and only allowed for) ``boundary-layer``; ``alpha`` is
    optional for ``delay-aware`` (default 1), ``hysteretic`` and ``on-predicted`` (default 1;
    ``inf`` or None: never switch); ``delta`` (the hysteresis δ ∈ [0, 1) on q₀) only for
    ``hysteretic``, which takes δ or α = √((1 + δ)/(1 − δ)), not both (default δ = 0).
    """
    if name not in RULE_NAMES:
        raise SpecificationError(f"rule type must be one of {sorted(RULE_NAMES)}, got {name!r}")
    if eps is not None and name != "boundary-layer":
        raise SpecificationError(f"rule: eps applies only to 'boundary-layer', not to {name!r}")
    if alpha is not None and name not in ("delay-aware", "hysteretic", "on-predicted"):
        raise SpecificationError(
            f"rule: alpha applies only to 'delay-aware', 'hysteretic' and 'on-predicted', not to {name!r}"
        )
    if delta is not None and name != "hysteretic":
        raise SpecificationError(f"rule: delta applies only to 'hysteretic', not to {name!r}")
    if name == "hysteretic":
        if delta is not None and alpha is not None:
            raise SpecificationError(
                "rule: 'hysteretic' takes delta or alpha (alpha = sqrt((1 + delta)/(1 - delta))), not both"
            )
        if alpha is not None:
            return Hysteretic.from_alpha(alpha)
        return Hysteretic(0.0 if delta is None else delta)
    if name == "boundary-layer":
        if eps is None:
            raise SpecificationError("rule: 'boundary-layer' needs eps (the layer thickness, > 0)")
        return BoundaryLayer(eps=finite_scalar("eps", eps))
    if name == "delay-aware":
        return DelayAware() if alpha is None else DelayAware(alpha=finite_scalar("alpha", alpha))
    if name == "on-predicted":
        return _on_predicted(alpha)
    return RULE_NAMES[name]()


def _on_predicted(alpha: Any) -> OnPredicted:
    """``OnPredicted(alpha)``: α >= 1 (default 1); α = +inf stands for None (never switch), as in a file."""
    if alpha is None:
        return OnPredicted()
    if isinstance(alpha, int | float) and not isinstance(alpha, bool) and alpha == math.inf:
        return OnPredicted(alpha=None)
    return OnPredicted(alpha=alpha)


def rule_name(rule: SwitchingRule) -> str:
    """The scenario-file name of ``rule`` (the inverse of [`rule_from_name`][mrpctl.scenario.rule_from_name])."""
    for name, cls in RULE_NAMES.items():
        if type(rule) is cls:
            return name
    raise SpecificationError(f"rule {rule!r} has no scenario-file name; use one of {sorted(RULE_NAMES)}")
