"""Campaigns with the steering law: the ``[steering]`` table of a campaign file, the law every run flies.

A campaign file takes the scenario's ``[steering]`` table (`mrpctl._scenario_steering`): every run flies that one
law (``simulate_batch(..., law=...)``; on ``[wheels]`` the wheel lanes for the metrics, on an ideal torque the
scalar engine's thread pool), with its own K (the dispersed gain) as the law near the target. Refused with it, each
with what to use instead: a rule other than ``hysteretic`` (in ``[rule]`` or ``[dispersions.rule]``), the
predictor, ``[reference]`` and gains whose rate block K[:, 3:6] is singular.
"""

from __future__ import annotations

from typing import Any

from mrpctl._scenario_steering import STEERING_TABLE, check_steering_scenario, steering_table
from mrpctl.errors import SpecificationError
from mrpctl.flight import Hysteretic
from mrpctl.flight.steering import SteeringLaw
from mrpctl.spacecraft import Spacecraft

__all__ = ["campaign_law", "check_campaign_law"]


def campaign_law(table: Any, spacecraft: Spacecraft) -> SteeringLaw | None:
    """The campaign's ``[steering]`` table (None: not given) as the law every run flies; a momentum limit is
    measured with the nominal ``[spacecraft]`` inertia (the controller's, also where the inertia is dispersed)."""
    return None if table is None else steering_table({STEERING_TABLE: table}, spacecraft)


def check_campaign_law(spec: Any) -> None:
    """Refuse what a campaign with the steering law does not run, saying what to use instead."""
    law = spec.base.law
    if law is None:
        return
    if spec.predictor is not None:
        raise SpecificationError(
            "[steering] and the predictor: the steering law runs in the flight loop, not with the predictor; use "
            "the rule 'hysteretic', or remove [steering]"
        )
    other = [
        label for label, rule in zip(spec.rule_labels, spec.rule_list, strict=True) if not isinstance(rule, Hysteretic)
    ]
    if other:
        raise SpecificationError(
            f"[steering]: the steering law flies with the controller-side rule only, got {other[0]!r}; use "
            "'hysteretic' with delta ('hysteretic:0' switches as 'on-current'), in [rule] and in [dispersions.rule]"
        )
    check_steering_scenario(law, spec.rule_list[0], spec.base.K, reference=spec.base.reference)
