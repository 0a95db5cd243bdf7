"""The switching rules of a campaign file: a rule from its string (``"name"``, ``"name:parameter"``) or table,
and the string of a rule (stored with the campaign, so a store names its rules as the file did)."""

from __future__ import annotations

from typing import Any

from mrpctl._validation import finite_scalar
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.predictor import OnPredicted
from mrpctl.scenario import RULE_NAMES, rule_from_name, rule_name
from mrpctl.switching import BoundaryLayer, DelayAware, SwitchingRule

__all__ = ["parse_rule", "rule_label"]

#: The parameter a rule's string form takes after the colon.
_RULE_PARAMETER = {"boundary-layer": "eps", "delay-aware": "alpha", "hysteretic": "delta", "on-predicted": "alpha"}


def rule_label(rule: SwitchingRule) -> str:
    """The campaign-file string of ``rule``: ``"name"`` or ``"name:parameter"`` (the inverse of
    [`parse_rule`][mrpctl.campaign.rules.parse_rule])."""
    if isinstance(rule, Hysteretic):
        return f"hysteretic:{rule.delta!r}"
    if isinstance(rule, OnPredicted):
        if rule.alpha is None:
            return "on-predicted:inf"
        return "on-predicted" if float(rule.alpha) == 1.0 else f"on-predicted:{float(rule.alpha)!r}"
    name = rule_name(rule)
    if isinstance(rule, BoundaryLayer):
        return f"{name}:{float(rule.eps)!r}"
    if isinstance(rule, DelayAware) and float(rule.alpha) != 1.0:
        return f"{name}:{float(rule.alpha)!r}"
    return name


def parse_rule(where: str, value: Any) -> SwitchingRule:
    """A rule from ``"name"``, ``"name:parameter"`` or a table ``{type = ..., eps/alpha/delta = ...}``.

    The names are those of `mrpctl.rules.RULE_NAMES` and ``"hysteretic"``
    ([`mrpctl.flight.Hysteretic`][mrpctl.flight.Hysteretic], parameter delta, default 0).
    """
    names = sorted([*RULE_NAMES, "hysteretic"])
    if isinstance(value, str):
        name, colon, parameter = value.partition(":")
        table: dict[str, Any] = {"type": name.strip()}
        if colon:
            key = _RULE_PARAMETER.get(name.strip())
            if key is None:
                raise SpecificationError(f"{where}: rule {name!r} takes no parameter, got {value!r}")
            try:
                table[key] = float(parameter)
            except ValueError:
                raise SpecificationError(f"{where}: the parameter of {value!r} is not a number") from None
    elif isinstance(value, dict):
        unknown = sorted(set(value) - {"type", "eps", "alpha", "delta"})
        if unknown:
            raise SpecificationError(
                f"unknown key {unknown[0]!r} in {where} of the campaign; allowed: ['alpha', 'delta', 'eps', 'type']"
            )
        table = value
    else:
        raise SpecificationError(f"{where}: a rule is a string such as 'delay-aware' or a table, got {value!r}")
    if "type" not in table:
        raise SpecificationError(f"{where} needs type, one of {names}")
    name = str(table["type"])
    if name == "hysteretic":
        if "eps" in table or "alpha" in table:
            raise SpecificationError(f"{where}: 'hysteretic' takes delta only")
        return Hysteretic(finite_scalar(f"{where}.delta", table.get("delta", 0.0)))
    if "delta" in table:
        raise SpecificationError(f"{where}: delta applies only to 'hysteretic', not to {name!r}")
    if name not in RULE_NAMES:
        raise SpecificationError(f"{where}: rule type must be one of {names}, got {name!r}")
    return rule_from_name(name, eps=table.get("eps"), alpha=table.get("alpha"))
