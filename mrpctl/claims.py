"""Rows of a claims table: what a paper says, what mrpctl measures, and how the two compare.

Shared by the reproduction of the seed paper and by the flight and predictor studies that add rows of
their own; re-exported by `mrpctl.reproduction`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["Claim", "Verdict"]


class Verdict(enum.Enum):
    """How a measurement compares with a paper claim."""

    AGREES = "agrees"
    DIFFERS = "differs"
    EXTENDS = "mrpctl only"


@dataclass(frozen=True)
class Claim:
    """One row of the claims table: what the paper says and what mrpctl measures."""

    source: str
    claim: str
    measurement: str
    verdict: Verdict

    def __str__(self) -> str:
        return f"[{self.verdict.value}] {self.source}: {self.claim} -> {self.measurement}"
