"""The distributions of a campaign's scalar dispersions: uniform, normal and truncated normal.

Each is drawn by its quantile function (inverse CDF) from one uniform variate of the run's stream, so a
run's value depends only on (seed, run) and the distribution, whichever distribution is chosen, and a
uniform draw is the same number it always was: ``low + (high − low) q``.

In a campaign file a dispersion is a pair (uniform) or a table::

    magnitude = [0.0, 0.05]                                              # uniform on [low, high]
    magnitude = {distribution = "uniform", low = 0.0, high = 0.05}       # the same
    scale = {distribution = "normal", mean = 1.0, std = 0.05}            # N(mean, std²)
    magnitude = {distribution = "truncnorm", mean = 0.02, std = 0.01, low = 0.0, high = 0.05}

A quantity with a bound (a magnitude ≥ 0, a torque limit > 0, δ < 1) refuses a distribution whose
support crosses it: a normal there is an error that names the truncated normal to use instead. The
normal and truncated-normal quantiles are scipy.stats' (``norm.ppf``, ``truncnorm.ppf``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from mrpctl._validation import finite_scalar
from mrpctl.errors import SpecificationError

__all__ = ["Distribution", "Normal", "TruncatedNormal", "Uniform", "parse_distribution"]


@dataclass(frozen=True)
class Uniform:
    """Uniform on [low, high] (low <= high; low == high is a fixed value)."""

    low: float
    high: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.low) and math.isfinite(self.high) and self.low <= self.high):
            raise SpecificationError(f"uniform: needs finite low <= high, got [{self.low:g}, {self.high:g}]")

    @property
    def support(self) -> tuple[float, float]:
        """The smallest and largest value a draw can take."""
        return self.low, self.high

    def quantile(self, q: np.ndarray) -> np.ndarray:
        """The values at the uniform variates ``q`` in [0, 1): low + (high − low) q."""
        return self.low + (self.high - self.low) * np.asarray(q, dtype=float)

    def __str__(self) -> str:
        return f"uniform [{self.low:g}, {self.high:g}]"


@dataclass(frozen=True)
class Normal:
    """Normal N(mean, std²), std > 0."""

    mean: float
    std: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mean) and math.isfinite(self.std) and self.std > 0.0):
            raise SpecificationError(
                f"normal: needs a finite mean and std > 0, got mean {self.mean:g}, std {self.std:g}"
            )

    @property
    def support(self) -> tuple[float, float]:
        """The smallest and largest value a draw can take (unbounded)."""
        return -math.inf, math.inf

    def quantile(self, q: np.ndarray) -> np.ndarray:
        """``scipy.stats.norm.ppf(q, mean, std)``; a variate of exactly 0 maps to the 2^-53 quantile (finite)."""
        q = np.clip(np.asarray(q, dtype=float), 2.0**-53, None)
        return np.asarray(stats.norm.ppf(q, loc=self.mean, scale=self.std), dtype=float)

    def __str__(self) -> str:
        return f"normal (mean {self.mean:g}, std {self.std:g})"


@dataclass(frozen=True)
class TruncatedNormal:
    """N(mean, std²) restricted to [low, high] (low < high; either may be infinite, not both on one side)."""

    mean: float
    std: float
    low: float
    high: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.mean) and math.isfinite(self.std) and self.std > 0.0):
            raise SpecificationError(
                f"truncnorm: needs a finite mean and std > 0, got mean {self.mean:g}, std {self.std:g}"
            )
        if math.isnan(self.low) or math.isnan(self.high) or not self.low < self.high:
            raise SpecificationError(f"truncnorm: needs low < high, got [{self.low:g}, {self.high:g}]")
        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        if not stats.norm.cdf(b) - stats.norm.cdf(a) > 0.0 and not stats.norm.sf(a) - stats.norm.sf(b) > 0.0:
            raise SpecificationError(
                f"truncnorm: [{self.low:g}, {self.high:g}] holds no probability of N({self.mean:g}, {self.std:g}^2) "
                "in double precision; move the mean into the interval or widen it"
            )

    @property
    def support(self) -> tuple[float, float]:
        """The smallest and largest value a draw can take."""
        return self.low, self.high

    def quantile(self, q: np.ndarray) -> np.ndarray:
        """``scipy.stats.truncnorm.ppf`` at the variates, clipped into [low, high] against round-off."""
        a, b = (self.low - self.mean) / self.std, (self.high - self.mean) / self.std
        values = stats.truncnorm.ppf(np.asarray(q, dtype=float), a, b, loc=self.mean, scale=self.std)
        return np.clip(np.asarray(values, dtype=float), self.low, self.high)

    def __str__(self) -> str:
        return f"truncated normal (mean {self.mean:g}, std {self.std:g}) on [{self.low:g}, {self.high:g}]"


#: A scalar dispersion's distribution.
Distribution = Uniform | Normal | TruncatedNormal

_KEYS = {
    "uniform": {"distribution", "low", "high"},
    "normal": {"distribution", "mean", "std"},
    "truncnorm": {"distribution", "mean", "std", "low", "high"},
}


def _bound_text(low: float, high: float, low_open: bool, high_open: bool) -> str:
    left = "(" if low_open or low == -math.inf else "["
    right = ")" if high_open or high == math.inf else "]"
    return f"{left}{low:g}, {high:g}{right}"


def parse_distribution(
    name: str,
    value: Any,
    *,
    low: float = -math.inf,
    high: float = math.inf,
    low_open: bool = False,
    high_open: bool = False,
) -> Distribution:
    """The distribution of a campaign file's dispersion ``name``: a pair [low, high] or a table (module docstring).

    ``low``, ``high`` (open when ``low_open`` / ``high_open``) bound the quantity: every draw must lie within
    them, so a distribution whose support leaves them is refused, naming ``name`` and the rule.
    """
    bounds = _bound_text(low, high, low_open, high_open)
    if isinstance(value, list | tuple):
        if len(value) != 2:
            raise SpecificationError(f"{name} must be a pair [low, high] or a distribution table, got {value!r}")
        a, b = (finite_scalar(name, v) for v in value)
        if not a <= b:
            raise SpecificationError(f"{name} must satisfy low <= high, got [{a:g}, {b:g}]")
        result: Distribution = Uniform(a, b)
    elif isinstance(value, dict):
        kind = value.get("distribution")
        if kind not in _KEYS:
            raise SpecificationError(
                f"{name}.distribution must be one of {sorted(_KEYS)}, got {kind!r} (or give a pair [low, high])"
            )
        unknown = set(value) - _KEYS[kind]
        missing = _KEYS[kind] - set(value)
        if unknown or missing:
            raise SpecificationError(
                f"{name}: a {kind} distribution takes exactly {sorted(_KEYS[kind] - {'distribution'})}"
                + (f"; unknown {sorted(unknown)}" if unknown else "")
                + (f"; missing {sorted(missing)}" if missing else "")
            )
        try:
            if kind == "uniform":
                result = Uniform(
                    finite_scalar(f"{name}.low", value["low"]), finite_scalar(f"{name}.high", value["high"])
                )
            elif kind == "normal":
                result = Normal(
                    finite_scalar(f"{name}.mean", value["mean"]), finite_scalar(f"{name}.std", value["std"])
                )
            else:
                result = TruncatedNormal(
                    finite_scalar(f"{name}.mean", value["mean"]),
                    finite_scalar(f"{name}.std", value["std"]),
                    _bound(f"{name}.low", value["low"]),
                    _bound(f"{name}.high", value["high"]),
                )
        except SpecificationError as error:
            raise SpecificationError(f"{name}: {error}") from None
    else:
        raise SpecificationError(f"{name} must be a pair [low, high] or a distribution table, got {value!r}")
    s_low, s_high = result.support
    rules = []
    if s_low < low or (low_open and s_low <= low):
        rules.append((f"{'>' if low_open else '>='} {low:g}", s_low))
    if s_high > high or (high_open and s_high >= high):
        rules.append((f"{'<' if high_open else '<='} {high:g}", s_high))
    if rules:
        hint = (
            f'; use {{distribution = "truncnorm", mean = ..., std = ..., low = ..., high = ...}} within {bounds}'
            if isinstance(result, Normal)
            else ""
        )
        broken = " and ".join(f"must be {rule}" for rule, _ in rules)
        edges = " and ".join(f"{e:g}" for _, e in rules)
        raise SpecificationError(
            f"{name}: every draw must lie in {bounds} ({broken}), but the {result} reaches {edges}{hint}"
        )
    return result


def _bound(name: str, value: Any) -> float:
    if isinstance(value, str) and value.strip().lower() in {"inf", "+inf", "-inf"}:
        return -math.inf if value.strip().startswith("-") else math.inf
    number = float(value) if isinstance(value, int | float) and not isinstance(value, bool) else math.nan
    if math.isnan(number):
        raise SpecificationError(f'{name} must be a number (or "inf" / "-inf"), got {value!r}')
    return number
