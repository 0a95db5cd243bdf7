"""Campaign specifications: a base scenario, a count, a seed and the dispersions, as TOML or a frozen value.

A campaign file is a scenario file (``[spacecraft]``, ``[gains]``, ``[rule]``, ``tau``,
``rate``, ``t_final``, ``history``, ``substeps``; ``[initial]`` optional, default at rest at
the origin) read by :func:`mrpctl.scenario.parse_scenario`, plus ``count``, ``seed`` and a
``[dispersions]`` table::

    count = 1000
    seed = 2026
    [dispersions.attitude]
    angle_deg = [0.0, 180.0]        # principal angle range; [0, 180] = uniform on SO(3)
    [dispersions.rate]
    magnitude = [0.0, 0.1]          # rad/s, direction uniform on the sphere, added to [initial] omega
    [dispersions.inertia]
    axis_tolerance = 0.05           # relative, each diagonal entry J_ii (1 + U(-tol, tol))
    product_tolerance = 1.0         # kg m^2, each product of inertia J_ij + U(-tol, tol)
    [dispersions.tau]
    range = [0.3, 0.6]              # s
    step = 0.1                      # s, a multiple of 1/rate (each distinct delay is one engine)
    [dispersions.gains]
    scale = [0.9, 1.1]              # K = s K_base

Unknown keys anywhere are errors naming the key.
"""

from __future__ import annotations

import copy
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mrpctl._validation import finite_scalar, integer, nonnegative_scalar
from mrpctl.errors import SpecificationError
from mrpctl.scenario import Scenario, parse_scenario

__all__ = [
    "AttitudeDispersion",
    "CampaignSpec",
    "GainDispersion",
    "InertiaDispersion",
    "RateDispersion",
    "TauDispersion",
    "load_campaign",
    "parse_campaign",
]

_CAMPAIGN_KEYS = {"count", "seed", "dispersions", "peak_torque"}
_DISPERSION_KEYS = {"attitude", "rate", "inertia", "tau", "gains"}
_KEYS = {
    "attitude": {"angle_deg"},
    "rate": {"magnitude"},
    "inertia": {"axis_tolerance", "product_tolerance"},
    "tau": {"range", "step"},
    "gains": {"scale"},
}
#: Largest count a specification accepts (the run index is a 64-bit spawn key; this is a sanity bound).
MAX_COUNT = 10**9


def _check_keys(where: str, data: Any, allowed: set[str]) -> dict[str, Any]:
    if not isinstance(data, dict):
        raise SpecificationError(f"{where} must be a table, got {type(data).__name__}")
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise SpecificationError(f"unknown key {unknown[0]!r} in {where} of the campaign; allowed: {sorted(allowed)}")
    return data


def _interval(name: str, value: Any, *, low: float = -math.inf, high: float = math.inf) -> tuple[float, float]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise SpecificationError(f"{name} must be a pair [low, high], got {value!r}")
    a, b = (finite_scalar(name, v) for v in value)
    if not low <= a <= b <= high:
        raise SpecificationError(f"{name} must satisfy {low:g} <= low <= high <= {high:g}, got [{a:g}, {b:g}]")
    return a, b


@dataclass(frozen=True)
class AttitudeDispersion:
    """Initial attitude uniform on SO(3), restricted to a principal-angle range.

    Attributes
    ----------
    angle_deg : tuple of float
        (low, high) principal angle Φ in degrees, 0 <= low <= high <= 180. Within the range
        the rotations keep the SO(3)-uniform (Haar) density (1 − cos Φ)/π; (0, 180) is the
        uniform distribution over all rotations.
    """

    angle_deg: tuple[float, float] = (0.0, 180.0)

    @property
    def full(self) -> bool:
        """True when the whole of SO(3) is sampled."""
        return self.angle_deg == (0.0, 180.0)


@dataclass(frozen=True)
class RateDispersion:
    """Body rate added to the base ω: direction uniform on the unit sphere, magnitude uniform (rad/s)."""

    magnitude: tuple[float, float]


@dataclass(frozen=True)
class InertiaDispersion:
    """Inertia tolerances; samples that are not physically valid are drawn again (rejection).

    Attributes
    ----------
    axis_tolerance : float
        Relative tolerance t on each diagonal entry: J_ii (1 + U(−t, t)), 0 <= t < 1.
    product_tolerance : float
        Absolute tolerance p (kg m²) on each product of inertia: J_ij + U(−p, p).
    """

    axis_tolerance: float = 0.0
    product_tolerance: float = 0.0


@dataclass(frozen=True)
class TauDispersion:
    """Delay τ uniform over the grid low, low + step, ..., high (s); step is a multiple of 1/rate."""

    low: float
    high: float
    step: float

    @property
    def values(self) -> tuple[float, ...]:
        """The grid of delays (s)."""
        count = round((self.high - self.low) / self.step)
        return tuple(self.low + k * self.step for k in range(count + 1))


@dataclass(frozen=True)
class GainDispersion:
    """Gain scale s uniform in [low, high]: K = s K_base."""

    scale: tuple[float, float]


@dataclass(frozen=True, eq=False)
class CampaignSpec:
    """A Monte Carlo campaign: ``count`` runs of ``base`` dispersed by ``seed``.

    Run i's inputs depend on (seed, i) alone (see :mod:`mrpctl.campaign.sampling`).

    Attributes
    ----------
    base : Scenario
        The nominal scenario (spacecraft, gains, initial state, τ, rule, horizon).
    count : int
        Number of runs (>= 1).
    seed : int
        Root seed (>= 0).
    attitude, rate, inertia, tau, gains : dispersion or None
        The dispersions; None keeps the base value.
    peak_torque : bool
        Compute the peak torque max_k ‖u_k‖ (N m) of each run (needs the trajectories when
        the simulator does not report it; about 1.5× the run time). Default True.
    source : dict
        The parsed TOML the specification was built from (written to the results).
    """

    base: Scenario
    count: int
    seed: int
    attitude: AttitudeDispersion | None = None
    rate: RateDispersion | None = None
    inertia: InertiaDispersion | None = None
    tau: TauDispersion | None = None
    gains: GainDispersion | None = None
    peak_torque: bool = True
    source: dict[str, Any] = field(default_factory=dict, repr=False)

    def __str__(self) -> str:
        parts = [f"campaign {self.base.name}: {self.count} runs, seed {self.seed}, rule {self.base.rule}"]
        parts.append(f"  t_final = {self.base.t_final:g} s at {self.base.rate:g} Hz, base tau = {self.base.tau:g} s")
        for name in ("attitude", "rate", "inertia", "tau", "gains"):
            value = getattr(self, name)
            parts.append(f"  {name:<9} {'base value' if value is None else value}")
        return "\n".join(parts)


def parse_campaign(data: dict[str, Any], *, name: str = "campaign") -> CampaignSpec:
    """Build a :class:`CampaignSpec` from the parsed contents of a campaign TOML file.

    Raises
    ------
    SpecificationError
        On an unknown key (named), a missing count or seed, or a value out of range.
    """
    if not isinstance(data, dict):
        raise SpecificationError(f"campaign must be a table, got {type(data).__name__}")
    source = copy.deepcopy(data)
    scenario_part = {k: v for k, v in data.items() if k not in _CAMPAIGN_KEYS}
    scenario_part.setdefault("initial", {"sigma": [0.0, 0.0, 0.0], "omega": [0.0, 0.0, 0.0]})
    base = parse_scenario(scenario_part, name=name)
    if base.flight_options:  # the campaign runner does not pass the flight models on: refuse, never drop them
        raise SpecificationError(
            f"[{sorted(base.flight_options)[0]}]: the loop-as-flown models are not supported in campaigns yet"
        )
    for key in ("count", "seed"):
        if key not in data:
            raise SpecificationError(f"campaign needs {key} (an integer)")
    count = integer("count", data["count"], minimum=1, maximum=MAX_COUNT)
    seed = integer("seed", data["seed"], minimum=0)
    peak = data.get("peak_torque", True)
    if not isinstance(peak, bool):
        raise SpecificationError(f"peak_torque must be true or false, got {peak!r}")
    dispersions = _check_keys("[dispersions]", data.get("dispersions", {}), _DISPERSION_KEYS)
    tables = {k: _check_keys(f"[dispersions.{k}]", v, _KEYS[k]) for k, v in dispersions.items()}

    attitude = None
    if "attitude" in tables:
        attitude = AttitudeDispersion(
            _interval("attitude.angle_deg", tables["attitude"].get("angle_deg", [0.0, 180.0]), low=0.0, high=180.0)
        )
    rate = None
    if "rate" in tables:
        if "magnitude" not in tables["rate"]:
            raise SpecificationError("[dispersions.rate] needs magnitude = [low, high] (rad/s)")
        rate = RateDispersion(_interval("rate.magnitude", tables["rate"]["magnitude"], low=0.0))
    inertia = None
    if "inertia" in tables:
        table = tables["inertia"]
        axis = nonnegative_scalar("inertia.axis_tolerance", table.get("axis_tolerance", 0.0))
        if axis >= 1.0:
            raise SpecificationError(f"inertia.axis_tolerance must be < 1 (relative), got {axis}")
        product = nonnegative_scalar("inertia.product_tolerance", table.get("product_tolerance", 0.0))
        inertia = InertiaDispersion(axis, product)
    tau = None
    if "tau" in tables:
        table = tables["tau"]
        if "range" not in table:
            raise SpecificationError("[dispersions.tau] needs range = [low, high] (s)")
        low, high = _interval("tau.range", table["range"], low=0.0)
        period = 1.0 / base.rate
        step = finite_scalar("tau.step", table.get("step", period))
        multiple = step / period
        if step <= 0.0 or abs(multiple - round(multiple)) > 1e-9 * max(1.0, multiple):
            raise SpecificationError(f"tau.step must be a positive multiple of 1/rate = {period:g} s, got {step:g}")
        for value, label in ((low, "low"), (high - low, "high - low")):
            ratio = value / step if label != "low" else value / period
            if abs(ratio - round(ratio)) > 1e-9 * max(1.0, ratio):
                raise SpecificationError(f"tau.range: {label} = {value:g} s is not a whole number of steps")
        tau = TauDispersion(low, high, step)
    gains = None
    if "gains" in tables:
        if "scale" not in tables["gains"]:
            raise SpecificationError("[dispersions.gains] needs scale = [low, high]")
        gains = GainDispersion(_interval("gains.scale", tables["gains"]["scale"]))
    return CampaignSpec(
        base=base,
        count=count,
        seed=seed,
        attitude=attitude,
        rate=rate,
        inertia=inertia,
        tau=tau,
        gains=gains,
        peak_torque=peak,
        source=source,
    )


def load_campaign(path: str | Path) -> CampaignSpec:
    """Read a campaign TOML file (see ``examples/campaigns/*.toml``)."""
    path = Path(path)
    try:
        with path.open("rb") as handle:
            data = tomllib.load(handle)
    except FileNotFoundError as exc:
        raise SpecificationError(f"campaign file not found: {path}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise SpecificationError(f"campaign file {path} is not valid TOML: {exc}") from exc
    return parse_campaign(data, name=path.stem)
