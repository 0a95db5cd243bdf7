"""Exception and warning classes raised by mrpctl."""

from __future__ import annotations

__all__ = [
    "CacheWarning",
    "CodegenError",
    "CompilerWarning",
    "DimensionError",
    "InertiaWarning",
    "MrpctlError",
    "SpecificationError",
    "StepWarning",
]


class MrpctlError(Exception):
    """Base class of every error raised by mrpctl."""


class DimensionError(MrpctlError, ValueError):
    """An array argument has the wrong shape ("expected (n, m) but found (p, q)")."""


class SpecificationError(MrpctlError, ValueError):
    """An argument has the right shape but breaks a rule (NaN, sign, range, definiteness)."""


class CodegenError(MrpctlError, RuntimeError):
    """Generating, compiling or loading CasADi code failed."""


class InertiaWarning(UserWarning):
    """An inertia is valid (symmetric positive definite) but not physically realisable."""


class CompilerWarning(UserWarning):
    """No C compiler was found: sources are written or CasADi's (slower) virtual machine is used."""


class CacheWarning(UserWarning):
    """A cached compiled library was truncated, corrupt or unchecked: it is deleted and rebuilt."""


class StepWarning(UserWarning):
    """The integration step cannot resolve the motion: the rotation per RK4 step is above 0.1 rad."""
