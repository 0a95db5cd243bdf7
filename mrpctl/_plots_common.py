"""The figures' shared plumbing (axes, legends, the notation of rules and Greek names), for
[`mrpctl.plots`][mrpctl.plots] and its private figure modules; imports matplotlib."""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from mrpctl.errors import DimensionError, SpecificationError

__all__ = ["legend_outside", "new_axes", "rule_words", "typeset"]

_WORDS = {"eps": "ε", "tau": "τ", "sigma": "σ", "omega": "ω", "alpha": "α", "delta": "δ", "Phi": "Φ"}
_WORD_RE = re.compile(r"\b(" + "|".join(_WORDS) + r")\b")


def typeset(text: str) -> str:
    """σ, τ, ε, ω typeset the same everywhere: ASCII names from callers and rules become Greek."""
    return _WORD_RE.sub(lambda m: _WORDS[m.group(1)], text)


def new_axes(n: int, ax: Any, *, figsize: tuple[float, float], sharex: bool = True) -> tuple[Figure, list[Axes]]:
    """The figure and ``n`` axes: the caller's ``ax`` (one Axes or a sequence) or a new Figure (no pyplot)."""
    if ax is None:
        fig = Figure(figsize=figsize, layout="constrained")
        made = fig.subplots(n, 1, sharex=sharex, squeeze=False)[:, 0]
        return fig, list(made)
    axes = [ax] if isinstance(ax, Axes) else list(np.ravel(np.asarray(ax, dtype=object)))
    if len(axes) != n or not all(isinstance(a, Axes) for a in axes):
        raise DimensionError(f"ax must be {'one matplotlib Axes' if n == 1 else f'{n} matplotlib Axes'}, got {ax!r}")
    owner: Any = axes[0].figure
    while not isinstance(owner, Figure) and getattr(owner, "figure", None) is not None:  # a SubFigure
        owner = owner.figure
    if not isinstance(owner, Figure):  # pragma: no cover - an Axes always belongs to a Figure
        raise SpecificationError("ax must belong to a matplotlib Figure")
    return owner, axes


def legend_outside(ax: Axes, **kwargs: Any) -> None:
    """Legend to the right of the axes, never over the data."""
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8, **kwargs)


def rule_words(rule: Any) -> str:
    """What a switching rule does, in words and the figures' notation (never its class name or repr)."""
    name = type(rule).__name__
    if name == "NoSwitching":
        return "no shadow-set switching"
    if name == "OnCurrent":
        return "switching when the current |σ(t)| ≥ 1"
    if name == "OnDelayed":
        return "switching when the delayed |σ(t − τ)| ≥ 1"
    if name == "BoundaryLayer":
        return f"switching when 1 ≤ |σ(t − τ)| ≤ 1 + ε (ε = {rule.eps:g})"
    if name == "DelayAware":
        return f"delay-aware switching when |σ(t − τ)| ≥ α (α = {rule.alpha:g})"
    if name == "Hysteretic":
        return f"controller-side set selection with hysteresis δ = {rule.delta:g}"
    if name == "OnPredicted":
        alpha = getattr(rule, "alpha", None)
        return "predictor, no switching" if alpha is None else f"predictor, switching when |σ̂| ≥ α (α = {alpha:g})"
    words = re.sub(r"(?<=[a-z])(?=[A-Z])", " ", name).lower()  # a rule of the user's: its class name in words
    return typeset(words)
