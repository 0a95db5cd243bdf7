"""Campaign specifications: a base scenario, a count, a seed and the dispersions, as TOML or a frozen value.

A campaign file is a scenario file (``[spacecraft]``, ``[gains]``, ``[rule]``, ``tau``,
``rate``, ``t_final``, ``history``, ``substeps``; ``[initial]`` optional, default at rest at
the origin) read by [`mrpctl.scenario.parse_scenario`][mrpctl.scenario.parse_scenario], plus ``count``, ``seed`` and a
``[dispersions]`` table::

    count = 1000
    seed = 2026
    [dispersions.attitude]
    angle_deg = [0.0, 180.0]        # principal angle range; [0, 180] = uniform on SO(3)
    [dispersions.omega]
    magnitude = [0.0, 0.1]          # rad/s, direction uniform on the sphere, added to [initial] omega
                                    # ([dispersions.rate] is its deprecated name: rate is the sample rate in Hz)
    [dispersions.inertia]
    axis_tolerance = 0.05           # relative, each diagonal entry J_ii (1 + U(-tol, tol))
    product_tolerance = 1.0         # kg m^2, each product of inertia J_ij + U(-tol, tol)
    [dispersions.tau]
    range = [0.3, 0.6]              # s
    step = 0.1                      # s, a multiple of 1/rate (each distinct delay is one engine)
    [dispersions.gains]
    scale = [0.9, 1.1]              # K = s K_base
    [dispersions.rule]
    rules = ["on-delayed", "delay-aware", "hysteretic:0.1"]   # crossed with the cases (see below)

The rule of ``[rule]`` (or of each entry of ``dispersions.rule.rules``) is a name of
`mrpctl.rules.RULE_NAMES` or ``"hysteretic"`` (the controller-side rule
[`mrpctl.flight.Hysteretic`][mrpctl.flight.Hysteretic]), as a table ``{type = "boundary-layer", eps = 0.05}`` or a
string ``"name"`` / ``"name:parameter"`` (eps of boundary-layer, alpha of delay-aware, delta of
hysteretic). A rule list is a factor **crossed** with the cases: with R rules, run i is case
⌊i / R⌋ (its dispersed inputs drawn from (seed, ⌊i / R⌋)) under rule i mod R, so every case is
run under every rule and the rules are compared on the same cases.

The flight loop's options (``[flight]``; every rule must then be hysteretic)::

    [flight]
    u_max = 2.0                     # N m, per-axis torque limit (scalar or 3 values)
    norm_max = 3.0                  # N m, limit on |u| (optional)
    saturation = "scale"            # or "clip"
    disturbance = [0.01, 0.0, 0.0]  # N m, constant body torque
    attitude_noise = 1e-4           # rad, 1 sigma per axis of the star-tracker error rotation
    rate_noise = 1e-5               # rad/s, 1 sigma per axis of the gyro noise
    gyro_bias = [0.0, 0.0, 0.0]     # rad/s
    jitter = [0.4, 0.5]             # s, delay uniform over the periods in [tau_min, tau_max = tau]
    disturbance_file = "w.csv"      # N m, n rows of 3 (one per sample), added to every run's constant torque
    delay_file = "d.csv"            # s, n delays (one per sample) in [1/rate, tau], whole periods (not with jitter)

(n = floor(t_final · rate) + 1; ``.csv``/``.txt`` comma-separated with ``#`` comments, or ``.npy``;
a relative name is taken from the campaign file's folder, as in a scenario file). Each run's torque
is w_k = W_k + w with W_k the file's row k, shared by the runs, and w its constant torque
(``disturbance`` plus its ``[dispersions.disturbance]`` draw); the delay sequence is shared by the
runs (``[dispersions.tau]``, ``jitter`` and the predictor are refused with it; the predictor takes
``disturbance_file``: the torque acts on the plant, not on its model copy). The file's numbers are
kept with the campaign ([`SampleFile`][mrpctl.campaign.spec.SampleFile]): the store holds them, so a replay never reads
the
file again (see [`mrpctl.campaign.store`][mrpctl.campaign.store]).

and their dispersions::

    [dispersions.hysteresis]
    delta = [0.0, 0.2]              # delta of the hysteretic rule, uniform
    [dispersions.actuator]
    u_max = [1.0, 3.0]              # N m, the per-axis limit (the same on the 3 axes), uniform
    [dispersions.disturbance]
    magnitude = [0.0, 0.05]         # N m, direction uniform on the sphere, added to [flight] disturbance
    [dispersions.sensor]
    attitude_noise = [0.0, 1e-3]    # rad, uniform
    rate_noise = [0.0, 1e-4]        # rad/s, uniform
    gyro_bias = [0.0, 1e-3]         # rad/s, magnitude uniform, direction uniform, added to [flight] gyro_bias

A pair [low, high] is a uniform draw; every scalar dispersion above except the attitude's angle and τ's
grid may instead be a normal or truncated normal, e.g. ``scale = {distribution = "normal", mean = 1.0,
std = 0.05}`` or ``magnitude = {distribution = "truncnorm", mean = 0.02, std = 0.01, low = 0.0, high = 0.05}``
([`mrpctl.campaign.distributions`][mrpctl.campaign.distributions]); a quantity with a bound (a magnitude or a
noise >= 0, a torque limit > 0, δ < 1) refuses a normal, whose draws could cross it.

Each run's noise and jitter streams are seeded from (seed, case)
([`mrpctl.campaign.sampling`][mrpctl.campaign.sampling]).

The predictor controller ([`mrpctl.Predictor`][mrpctl.predictor.Predictor]; every rule ``on-predicted``, ``alpha`` >= 1
may differ: ``"on-predicted:1.2"``, ``"on-predicted:inf"`` never switches)::

    [rule]
    type = "on-predicted"
    [predictor]
    inertia_error = 0.05            # the model from the NOMINAL [spacecraft]: J = S J_m S, S = diag(sqrt(1 + e))
                                    # (or inertia = [...]; empty: the nominal spacecraft itself)

The model is the same for every run; the plant is each run's dispersed spacecraft. ``flight.jitter``
and a ``history`` other than ``"constant"`` are refused with it.

A scenario ``[reference]`` table (``type = "inertial" | "slew" | "nadir" | "file"``) makes the runs fly the
tracking loop on it (every rule ``hysteretic`` or ``on-predicted``), dispersed per run by
``[dispersions.reference]`` (``slew_angle_deg``, ``slew_axis = "sphere"``, ``orbit_rate``;
[`mrpctl.campaign.reference`][mrpctl.campaign.reference]); each run then also stores its pointing.

Unknown keys anywhere are errors naming the key.
"""

from __future__ import annotations

import copy
import hashlib
import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._files import read_toml
from mrpctl._validation import finite_array, finite_scalar, integer, nonnegative_scalar, positive_scalar, readonly
from mrpctl.campaign.distributions import Distribution, parse_distribution
from mrpctl.campaign.reference import REFERENCE_KEYS, ReferenceDispersion, parse_reference_dispersion
from mrpctl.campaign.rules import parse_rule, rule_label
from mrpctl.campaign.steering import campaign_law, check_campaign_law
from mrpctl.campaign.wheels import campaign_wheels, check_campaign_wheels
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, Saturation
from mrpctl.guidance import FileReference
from mrpctl.loop import delay_samples
from mrpctl.predictor import OnPredicted, Predictor, PredictorForm
from mrpctl.scenario import (
    RULE_NAMES,
    Scenario,
    delay_periods,
    delay_sequence,
    delay_values,
    parse_scenario,
    predictor_model,
    sample_count,
    samples_file,
    torque_rows,
)
from mrpctl.switching import SwitchingRule

__all__ = [
    "AttitudeDispersion",
    "CampaignSpec",
    "FlightDispersion",
    "FlightOptions",
    "GainDispersion",
    "InertiaDispersion",
    "RateDispersion",
    "RuleDispersion",
    "SampleFile",
    "TauDispersion",
    "load_campaign",
    "parse_campaign",
]

_CAMPAIGN_KEYS = {"count", "seed", "dispersions", "peak_torque", "flight", "rule", "predictor"}
_PREDICTOR_KEYS = {"inertia", "inertia_error", "form"}
_DISPERSION_KEYS = {
    "attitude",
    "omega",
    "rate",
    "inertia",
    "tau",
    "gains",
    "rule",
    "hysteresis",
    "actuator",
    "disturbance",
    "sensor",
    "reference",
}
_KEYS = {
    "attitude": {"angle_deg"},
    "omega": {"magnitude"},
    "rate": {"magnitude"},
    "inertia": {"axis_tolerance", "product_tolerance"},
    "tau": {"range", "step"},
    "gains": {"scale"},
    "rule": {"rules"},
    "hysteresis": {"delta"},
    "actuator": {"u_max"},
    "disturbance": {"magnitude"},
    "sensor": {"attitude_noise", "rate_noise", "gyro_bias"},
    "reference": REFERENCE_KEYS,
}
_FLIGHT_KEYS = {
    "u_max",
    "norm_max",
    "saturation",
    "disturbance",
    "attitude_noise",
    "rate_noise",
    "gyro_bias",
    "jitter",
    "disturbance_file",
    "delay_file",
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
    """Body rate added to the base ω: direction uniform on the unit sphere, magnitude drawn from ``magnitude``
    (rad/s; uniform, or a truncated normal on [0, ∞) or within it)."""

    magnitude: Distribution


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
    """Gain scale s drawn from ``scale`` (uniform, normal or truncated normal): K = s K_base."""

    scale: Distribution


@dataclass(frozen=True, eq=False)
class RuleDispersion:
    """Several rules, crossed with the cases: run i is case ⌊i / R⌋ under rule i mod R.

    Attributes
    ----------
    rules : tuple of SwitchingRule
        The R >= 1 rules, in the order of the file.
    """

    rules: tuple[SwitchingRule, ...]

    @property
    def labels(self) -> tuple[str, ...]:
        """The rules' campaign-file strings ([`rule_label`][mrpctl.campaign.rules.rule_label]), stored with the
        results."""
        return tuple(rule_label(rule) for rule in self.rules)

    def __str__(self) -> str:
        return f"crossed with the cases: {', '.join(self.labels)}"


def _sha256(values: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(values, dtype=np.float64).tobytes()).hexdigest()


@dataclass(frozen=True, eq=False)
class SampleFile:
    """The numbers of a per-sample file named in ``[flight]``, as read when the campaign was parsed.

    The campaign keeps the numbers, not only the name: they are written into the store
    ([`mrpctl.campaign.store`][mrpctl.campaign.store]) and shipped to the Dask workers with each chunk, so the runs, a
    resume and a replay never depend on the file still being there. A resume re-reads the file and
    refuses it if its numbers changed (the message names the file and both SHA-256 hashes).

    Attributes
    ----------
    key : str
        ``"disturbance_file"`` or ``"delay_file"``.
    path : str
        The file as named and resolved (relative names from the campaign file's folder); for a
        campaign rebuilt from a store, the name the store recorded.
    values : numpy.ndarray
        Read-only: (n, 3) torques (N m) or (n,) delays (s), n = floor(t_final · rate) + 1.
    sha256 : str
        SHA-256 (hex) of ``values`` as C-ordered float64 bytes (the numbers, not the file's text).
    """

    key: str
    path: str
    values: np.ndarray = field(repr=False)
    sha256: str = field(init=False, default="")

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", readonly(self.values))
        object.__setattr__(self, "sha256", _sha256(self.values))

    def __str__(self) -> str:
        return f"{self.key} {self.path} ({' x '.join(str(d) for d in self.values.shape)}, sha256 {self.sha256[:12]})"


@dataclass(frozen=True, eq=False)
class FlightOptions:
    """The flight loop's options shared by the runs (base values of the flight dispersions).

    Attributes
    ----------
    actuator : ActuatorModel or None
        Torque limits (N m).
    disturbance : numpy.ndarray
        (3,) constant body torque w (N m).
    attitude_noise, rate_noise : float
        1σ of the attitude error rotation (rad) and of the rate noise (rad/s).
    gyro_bias : numpy.ndarray
        (3,) gyro bias (rad/s).
    jitter : tuple of float or None
        (tau_min, tau_max) of a jittered delay (s), tau_max = the scenario's tau.
    disturbance_file : SampleFile or None
        (n, 3) torque rows W_k (N m) shared by the runs, added to each run's constant torque.
    delay_file : SampleFile or None
        (n,) per-sample delays (s) shared by the runs (`delay_sequence`); exclusive with ``jitter``.
    delay_sequence : DelayModel or None
        The delay sequence of ``delay_file`` (tau_min = 1/rate, tau_max = tau), one object for every run.
    """

    actuator: ActuatorModel | None = None
    disturbance: np.ndarray = field(default_factory=lambda: np.zeros(3))
    attitude_noise: float = 0.0
    rate_noise: float = 0.0
    gyro_bias: np.ndarray = field(default_factory=lambda: np.zeros(3))
    jitter: tuple[float, float] | None = None
    disturbance_file: SampleFile | None = None
    delay_file: SampleFile | None = None
    delay_sequence: DelayModel | None = None

    @property
    def files(self) -> dict[str, SampleFile]:
        """The per-sample files given, by key (``disturbance_file``, ``delay_file``)."""
        found = {"disturbance_file": self.disturbance_file, "delay_file": self.delay_file}
        return {key: value for key, value in found.items() if value is not None}

    def __str__(self) -> str:
        parts = [str(self.actuator) if self.actuator is not None else "no torque limit"]
        parts.append("w = [" + ", ".join(f"{w:g}" for w in self.disturbance) + "] N m")
        parts.append(f"noise {self.attitude_noise:g} rad, {self.rate_noise:g} rad/s")
        parts.append("bias [" + ", ".join(f"{b:g}" for b in self.gyro_bias) + "] rad/s")
        if self.jitter is not None:
            parts.append(f"jitter [{self.jitter[0]:g}, {self.jitter[1]:g}] s")
        parts.extend(str(each) for each in self.files.values())
        return "; ".join(parts)


@dataclass(frozen=True)
class FlightDispersion:
    """Dispersions of the flight options; None keeps the base value.

    Attributes
    ----------
    delta : Distribution or None
        δ of the hysteretic rule, drawn within [0, 1).
    u_max : Distribution or None
        Per-axis torque limit (the same on the three axes), drawn within (0, ∞) (N m).
    disturbance : Distribution or None
        Magnitude of a torque added to the base w, drawn within [0, ∞) (N m); direction uniform on the sphere.
    attitude_noise, rate_noise : Distribution or None
        1σ of the sensor noises, drawn within [0, ∞) (rad; rad/s).
    gyro_bias : Distribution or None
        Magnitude of a bias added to the base bias, drawn within [0, ∞) (rad/s); direction uniform on the sphere.

    Each is uniform (a pair [low, high] in the file), normal or truncated normal
    ([`mrpctl.campaign.distributions`][mrpctl.campaign.distributions]).
    """

    delta: Distribution | None = None
    u_max: Distribution | None = None
    disturbance: Distribution | None = None
    attitude_noise: Distribution | None = None
    rate_noise: Distribution | None = None
    gyro_bias: Distribution | None = None

    @property
    def any(self) -> bool:
        """True when some flight option is dispersed."""
        return any(getattr(self, name) is not None for name in self.__dataclass_fields__)

    @property
    def models(self) -> bool:
        """True when a model of the flight loop (actuator, disturbance, sensor) is dispersed (δ is the rule's)."""
        return any(getattr(self, name) is not None for name in self.__dataclass_fields__ if name != "delta")


@dataclass(frozen=True, eq=False)
class CampaignSpec:
    """A Monte Carlo campaign: ``count`` runs of ``base`` dispersed by ``seed``.

    Run i's inputs depend on (seed, i) alone (see [`mrpctl.campaign.sampling`][mrpctl.campaign.sampling]).

    Attributes
    ----------
    base : Scenario
        The nominal scenario (spacecraft, gains, initial state, τ, rule, horizon).
    count : int
        Number of runs (>= 1).
    seed : int
        Root seed (>= 0).
    attitude, omega, inertia, tau, gains : dispersion or None
        The dispersions; None keeps the base value.
    peak_torque : bool
        Compute the peak torque max_k ‖u_k‖ (N m) of each run (needs the trajectories when
        the simulator does not report it; about 1.5× the run time). Default True.
    source : dict
        The parsed TOML the specification was built from (written to the results).
    reference : ReferenceDispersion or None
        ``[dispersions.reference]`` of a tracking campaign (the base reference is ``base.reference``, the
        scenario's ``[reference]``; see [`mrpctl.campaign.reference`][mrpctl.campaign.reference]).
    reference_file : SampleFile or None
        The rows of ``[reference] type = "file"`` as read (kept with the campaign, as the ``[flight]`` files).
    """

    base: Scenario
    count: int
    seed: int
    attitude: AttitudeDispersion | None = None
    omega: RateDispersion | None = None
    inertia: InertiaDispersion | None = None
    tau: TauDispersion | None = None
    gains: GainDispersion | None = None
    peak_torque: bool = True
    source: dict[str, Any] = field(default_factory=dict, repr=False)
    rules: RuleDispersion | None = None
    flight: FlightOptions | None = None
    flight_dispersion: FlightDispersion = field(default_factory=FlightDispersion)
    predictor: Predictor | None = None
    reference: ReferenceDispersion | None = None
    reference_file: SampleFile | None = None

    @property
    def tracking(self) -> bool:
        """True when the runs fly the tracking loop (the scenario has a ``[reference]``)."""
        return self.base.reference is not None

    @property
    def rule_list(self) -> tuple[SwitchingRule, ...]:
        """The rules crossed with the cases (the base rule alone when the rule is not dispersed)."""
        return (self.base.rule,) if self.rules is None else self.rules.rules

    @property
    def files(self) -> dict[str, SampleFile]:
        """The per-sample files of ``[flight]`` and the rows of ``[reference] file`` (key ``reference_file``) by key,
        with their numbers (empty without them)."""
        found = {} if self.flight is None else self.flight.files
        if self.reference_file is not None:
            found["reference_file"] = self.reference_file
        return found

    @property
    def rule_labels(self) -> tuple[str, ...]:
        """[`rule_label`][mrpctl.campaign.rules.rule_label] of each rule of
        [`rule_list`][mrpctl.campaign.CampaignSpec.rule_list] (what the results store per rule index)."""
        return tuple(rule_label(rule) for rule in self.rule_list)

    @property
    def cases(self) -> int:
        """Distinct dispersed cases: ⌈count / R⌉ with R rules crossed."""
        return -(-self.count // len(self.rule_list))

    @property
    def attitude_noisy(self) -> bool:
        """True when a run has sensor attitude noise (its numbers depend on `NOISE_REVISION`)."""
        dispersed = self.flight_dispersion.attitude_noise
        return (self.flight is not None and self.flight.attitude_noise > 0) or (
            dispersed is not None and dispersed.support[1] > 0
        )

    @property
    def rate(self) -> RateDispersion | None:
        """Deprecated name of ``omega``, the body-rate dispersion (``rate`` is the sample rate in Hz)."""
        warnings.warn(
            "CampaignSpec.rate is deprecated: use .omega (the body-rate dispersion; rate is the sample rate in Hz)",
            DeprecationWarning,
            stacklevel=2,
        )
        return self.omega

    @property
    def uses_flight(self) -> bool:
        """True when the runs go through the flight loop's models (sensor, actuator, disturbance, jitter)."""
        return self.flight is not None or self.flight_dispersion.models

    def __str__(self) -> str:
        parts = [f"campaign {self.base.name}: {self.count} runs, seed {self.seed}, rule {self.base.rule}"]
        parts.append(f"  t_final = {self.base.t_final:g} s at {self.base.rate:g} Hz, base tau = {self.base.tau:g} s")
        for name in ("attitude", "omega", "inertia", "tau", "gains", "rules"):
            value = getattr(self, name)
            parts.append(f"  {name:<9} {'base value' if value is None else value}")
        if self.predictor is not None:
            parts.append(f"  predictor {self.predictor} (the plant is the dispersed spacecraft)")
        if self.base.reference is not None:
            parts.append(f"  reference {self.base.reference}; dispersed: {self.reference or 'none'}")
        if self.uses_flight:
            parts.append(f"  flight    {self.flight if self.flight is not None else 'base models'}")
            parts.append(f"  flight dispersions {self.flight_dispersion}")
        return "\n".join(parts)


def parse_campaign(
    data: dict[str, Any],
    *,
    name: str = "campaign",
    base: str | Path | None = None,
    files: Mapping[str, SampleFile] | None = None,
) -> CampaignSpec:
    """Build a [`CampaignSpec`][mrpctl.campaign.CampaignSpec] from the parsed contents of a campaign TOML file.

    Parameters
    ----------
    data : dict
        The parsed TOML.
    name : str
        The campaign's name when ``data`` has none.
    base : path or None
        The folder relative names of ``flight.disturbance_file`` / ``flight.delay_file`` are taken
        from ([`load_campaign`][mrpctl.campaign.load_campaign]: the campaign file's folder; None: the working
        directory).
    files : mapping of str to SampleFile, optional
        The numbers of those files as read before ([`CampaignSpec.files`][mrpctl.campaign.CampaignSpec.files], from a
        store or shipped
        to a Dask worker): used instead of reading the files, and checked as if read.

    Raises
    ------
    SpecificationError
        On an unknown key (named), a missing count or seed, or a value out of range.
    """
    if not isinstance(data, dict):
        raise SpecificationError(f"campaign must be a table, got {type(data).__name__}")
    folder = None if base is None else Path(base)
    source = copy.deepcopy(data)
    scenario_part = {k: v for k, v in data.items() if k not in _CAMPAIGN_KEYS}
    scenario_part.setdefault("initial", {"sigma": [0.0, 0.0, 0.0], "omega": [0.0, 0.0, 0.0]})
    if "rule" not in data:
        raise SpecificationError(f"[rule] needs type, one of {sorted([*RULE_NAMES, 'hysteretic'])}")
    if "estimator" in scenario_part:
        raise SpecificationError(
            "[estimator]: campaigns of the estimated loop are not run (its compiled engine flies one run per call, "
            "not lanes of runs); run mrpctl simulate per case (--noise-seed N), or "
            "mrpctl.simulation.estimated.simulate_estimated per seed from Python"
        )
    table = scenario_part.get("reference")
    given_rows = (
        (files or {}).get("reference_file") if isinstance(table, dict) and table.get("type") == "file" else None
    )
    if given_rows is not None:  # the rows of [reference] file as read before (a store, a Dask task): not re-read
        scenario_part["reference"] = {k: v for k, v in scenario_part["reference"].items() if k != "file"}
        scenario_part["reference"]["type"] = "inertial"
        scenario_part["reference"]["sigma"] = [0.0, 0.0, 0.0]
    flight_tables = sorted(set(scenario_part) & {"actuator", "sensor", "disturbance", "delay"})
    if flight_tables:  # scenario-style flight tables would be dropped by the runner: refuse, never drop them
        raise SpecificationError(
            f"[{flight_tables[0]}]: a campaign gives the loop-as-flown models in its [flight] table "
            "(see design/campaigns.md), not as scenario tables"
        )
    scenario_part["rule"] = {"type": "none"}  # the campaign reads the rule itself (it knows 'hysteretic')
    wheels = scenario_part.pop("wheels", None)  # read below, with the campaign's rules (check_campaign_wheels)
    steering = scenario_part.pop("steering", None)  # read below, with the campaign's rules (check_campaign_law)
    nominal = parse_scenario(scenario_part, name=name, base=folder)
    nominal = replace(
        nominal.with_rule(parse_rule("[rule]", data["rule"])),
        wheels=campaign_wheels(wheels, nominal.spacecraft),
        law=campaign_law(steering, nominal.spacecraft),
    )
    nominal, reference_file = _reference_rows(nominal, given_rows)
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
    if "rate" in tables:
        if "omega" in tables:
            raise SpecificationError("give [dispersions.omega] ([dispersions.rate] is its deprecated name), not both")
        warnings.warn(
            "[dispersions.rate] is deprecated: name the body-rate dispersion [dispersions.omega] (rate is the sample "
            "rate in Hz elsewhere in mrpctl)",
            DeprecationWarning,
            stacklevel=2,
        )
        tables["omega"] = tables.pop("rate")
    omega = None
    if "omega" in tables:
        if "magnitude" not in tables["omega"]:
            raise SpecificationError("[dispersions.omega] needs magnitude = [low, high] (rad/s)")
        omega = RateDispersion(parse_distribution("omega.magnitude", tables["omega"]["magnitude"], low=0.0))
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
        period = 1.0 / nominal.rate
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
        gains = GainDispersion(parse_distribution("gains.scale", tables["gains"]["scale"]))
    rules = None
    if "rule" in tables:
        listed = tables["rule"].get("rules")
        if not isinstance(listed, list) or not listed:
            raise SpecificationError("[dispersions.rule] needs rules = a non-empty list of rules")
        rules = RuleDispersion(tuple(parse_rule(f"dispersions.rule.rules[{i}]", v) for i, v in enumerate(listed)))
        labels = rules.labels
        repeated = sorted({label for label in labels if labels.count(label) > 1})
        if repeated:
            raise SpecificationError(f"dispersions.rule.rules: {repeated[0]!r} is listed twice")
    flight = _flight_options(data["flight"], nominal, folder, files or {}) if "flight" in data else None
    flight_dispersion = _flight_dispersion(tables)
    reference = None
    if "reference" in tables:
        reference = parse_reference_dispersion(tables["reference"], nominal.reference)
    if getattr(nominal, "gravity_gradient", False) and reference is not None and reference.orbit_rate is not None:
        raise SpecificationError(
            "dispersions.reference.orbit_rate with [reference] gravity_gradient = true: the runs of a batch share "
            "one orbit's gravity gradient; remove one of the two"
        )
    spec = CampaignSpec(
        base=nominal,
        count=count,
        seed=seed,
        attitude=attitude,
        omega=omega,
        inertia=inertia,
        tau=tau,
        gains=gains,
        peak_torque=peak,
        source=source,
        rules=rules,
        flight=flight,
        flight_dispersion=flight_dispersion,
        predictor=_predictor(data, nominal, rules.rules if rules is not None else (nominal.rule,)),
        reference=reference,
        reference_file=reference_file,
    )
    _check_tracking(spec)
    _check_flight(spec)
    _check_predictor(spec)
    check_campaign_wheels(spec)
    check_campaign_law(spec)
    return spec


def _reference_rows(nominal: Scenario, given: SampleFile | None) -> tuple[Scenario, SampleFile | None]:
    """The scenario with the rows of ``[reference] file`` as given (``given``: read before), and those rows as a
    [`SampleFile`][mrpctl.campaign.spec.SampleFile] (kept with the campaign, as the ``[flight]`` files are)."""
    if given is not None:
        n = sample_count(nominal.t_final, nominal.rate)
        if given.values.shape != (n, 9):
            raise DimensionError(
                f"[reference] file ({given.path}): expected n rows of 9 numbers, shape ({n}, 9) with n = "
                f"floor(t_final * rate) + 1, but the stored rows have shape {given.values.shape}"
            )
        rows = FileReference(rows=np.array(given.values), rate=nominal.rate, source=given.path)
        return replace(nominal, reference=rows), given
    if isinstance(nominal.reference, FileReference):
        return nominal, SampleFile("reference_file", nominal.reference.source, nominal.reference.rows)
    return nominal, None


def _check_tracking(spec: CampaignSpec) -> None:
    """A reference is tracked by the controller-side rule or the predictor only (design/tracking.md)."""
    if spec.base.reference is None:
        return
    other = [
        label
        for label, rule in zip(spec.rule_labels, spec.rule_list, strict=True)
        if not isinstance(rule, Hysteretic | OnPredicted)
    ]
    if other:
        raise SpecificationError(
            f"[reference]: the tracking loop chooses the set of sigma_BR itself: every rule must be 'hysteretic' "
            f"(hysteretic:0 is on-current's rule on sigma_BR) or 'on-predicted' (the predictor), got {other[0]!r}"
        )


def _predictor(data: dict[str, Any], base: Scenario, rules: tuple[SwitchingRule, ...]) -> Predictor | None:
    """The [predictor] table: the controller's model is the campaign's nominal spacecraft (``base``),
    optionally with a relative error (``inertia_error``) or an explicit ``inertia``; the plant is dispersed."""
    predicted = [isinstance(rule, OnPredicted) for rule in rules]
    if any(predicted) and not all(predicted):
        mixed = next(rule_label(rule) for rule in rules if not isinstance(rule, OnPredicted))
        raise SpecificationError(
            "rules: a campaign runs either the predictor or the plain delayed law: with 'on-predicted', every "
            f"rule must be 'on-predicted' (alpha may differ), got {mixed!r} (run two campaigns to compare them)"
        )
    if "predictor" not in data:
        if any(predicted):
            raise SpecificationError(
                "[rule] type = 'on-predicted' needs a [predictor] table (the controller's model): empty for the "
                "nominal spacecraft of the campaign, inertia_error = e (the nominal J = (1 + e) J_m, or 3 per-axis "
                "values) or "
                "inertia = [J1, J2, J3] (or 3x3, kg m^2)"
            )
        return None
    table = _check_keys("[predictor]", data["predictor"], _PREDICTOR_KEYS)
    if not any(predicted):
        raise SpecificationError(
            f"[predictor] applies only with rule 'on-predicted' (the predictor's rule), got {rule_label(rules[0])!r}"
        )
    if base.history != "constant":
        raise SpecificationError(
            f"[predictor] needs history = 'constant' (the model copy starts at x0), got {base.history!r}"
        )
    try:
        model = predictor_model(base.spacecraft, table.get("inertia"), table.get("inertia_error"))
        return Predictor(model, form=PredictorForm.parse(table.get("form", PredictorForm.NONLINEAR.value)))
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[predictor] {exc}") from exc


def _check_predictor(spec: CampaignSpec) -> None:
    """The predictor runs with the constant delay tau: a jittered delay is refused."""
    if spec.predictor is not None and spec.flight is not None and spec.flight.jitter is not None:
        raise SpecificationError(
            "flight.jitter does not apply with the predictor: it runs with the constant delay tau only "
            "(its correction needs the age of each measurement); remove flight.jitter"
        )
    if spec.predictor is not None and spec.flight is not None and spec.flight.delay_file is not None:
        raise SpecificationError(
            "flight.delay_file does not apply with the predictor: it runs with the constant delay tau only "
            "(its correction needs the age of each measurement); remove flight.delay_file"
        )


def _sample_file(
    table: dict[str, Any], key: str, folder: Path | None, files: Mapping[str, SampleFile]
) -> tuple[str, np.ndarray]:
    """The name and numbers of the per-sample file ``flight.<key>``: as given in ``files``, or read
    (relative to ``folder``) by the scenario files' reader
    [`mrpctl.scenario.samples_file`][mrpctl.scenario.samples_file]."""
    where = f"flight.{key}"
    given = files.get(key)
    if given is not None:
        return given.path, finite_array(f"{where} ({given.path})", given.values)
    value = table[key]
    path = value if not isinstance(value, str) or folder is None or Path(value).is_absolute() else folder / value
    return str(path), samples_file(value, where, base=folder)


def _flight_files(
    table: dict[str, Any], base: Scenario, folder: Path | None, files: Mapping[str, SampleFile]
) -> tuple[SampleFile | None, SampleFile | None, DelayModel | None]:
    """``flight.disturbance_file`` (n x 3, N m) and ``flight.delay_file`` (n delays, s), checked as a
    scenario's ``[disturbance] torque_file`` and ``[delay] sequence_file`` are (same readers, same rules)."""
    n = sample_count(base.t_final, base.rate)
    torque = delays = model = None
    if "disturbance_file" in table:
        path, values = _sample_file(table, "disturbance_file", folder, files)
        torque = SampleFile("disturbance_file", path, torque_rows(values, "flight.disturbance_file", n))
    if "delay_file" in table:
        if "jitter" in table:
            raise SpecificationError(
                "flight.jitter and flight.delay_file: the delay is either seeded jitter or the given per-sample "
                "sequence, not both; remove one of them"
            )
        path, values = _sample_file(table, "delay_file", folder, files)
        values = delay_values(values, "flight.delay_file", n)
        try:
            model = delay_sequence(values, "flight.delay_file", tau=base.tau, rate=base.rate)
        except (SpecificationError, DimensionError) as exc:
            message = str(exc)
            prefix = "" if message.startswith("flight.delay_file") else f"flight.delay_file ({path}): "
            raise type(exc)(prefix + message) from exc
        delays = SampleFile("delay_file", path, values)
    return torque, delays, model


def _flight_options(
    table: Any, base: Scenario, folder: Path | None = None, files: Mapping[str, SampleFile] | None = None
) -> FlightOptions:
    table = _check_keys("[flight]", table, _FLIGHT_KEYS)
    disturbance_file, delay_file, sequence = _flight_files(table, base, folder, files or {})
    actuator = None
    if "u_max" in table:
        mode_name = table.get("saturation", "scale")
        modes = {mode.value: mode for mode in Saturation}
        if not isinstance(mode_name, str) or mode_name not in modes:  # a TOML list or table is not hashable
            raise SpecificationError(f"flight.saturation must be one of {sorted(modes)}, got {mode_name!r}")
        norm = table.get("norm_max")
        actuator = ActuatorModel(
            table["u_max"], None if norm is None else positive_scalar("flight.norm_max", norm), modes[mode_name]
        )
    elif "norm_max" in table or "saturation" in table:
        raise SpecificationError("flight.norm_max and flight.saturation need flight.u_max (the per-axis limit, N m)")
    jitter = None
    if "jitter" in table:
        low, high = _interval("flight.jitter", table["jitter"], low=0.0)
        # compared as whole periods (the engine's rule): k h written in floating point is k periods
        if delay_periods(high, "flight.jitter tau_max", base.rate) != delay_samples(base.tau, base.rate):
            raise SpecificationError(
                f"flight.jitter: tau_max must equal tau = {base.tau:g} s (the history depth), got {high:g} s"
            )
        if delay_periods(low, "flight.jitter tau_min", base.rate) < 1:
            raise SpecificationError(f"flight.jitter: tau_min must be >= 1/rate = {1.0 / base.rate:g} s, got {low:g} s")
        low = min(low, base.tau)  # tau_min = tau in periods but a rounding above it
        DelayModel.jitter(low, base.tau).bounds(base.rate)  # as the runs will build it
        jitter = (low, base.tau)
    return FlightOptions(
        actuator=actuator,
        disturbance=readonly(finite_array("flight.disturbance", table.get("disturbance", [0.0, 0.0, 0.0]), (3,))),
        attitude_noise=nonnegative_scalar("flight.attitude_noise", table.get("attitude_noise", 0.0)),
        rate_noise=nonnegative_scalar("flight.rate_noise", table.get("rate_noise", 0.0)),
        gyro_bias=readonly(finite_array("flight.gyro_bias", table.get("gyro_bias", [0.0, 0.0, 0.0]), (3,))),
        jitter=jitter,
        disturbance_file=disturbance_file,
        delay_file=delay_file,
        delay_sequence=sequence,
    )


def _flight_dispersion(tables: dict[str, dict[str, Any]]) -> FlightDispersion:
    values: dict[str, Distribution] = {}
    if "hysteresis" in tables:
        if "delta" not in tables["hysteresis"]:
            raise SpecificationError("[dispersions.hysteresis] needs delta = [low, high] or a distribution table")
        values["delta"] = parse_distribution(
            "hysteresis.delta", tables["hysteresis"]["delta"], low=0.0, high=1.0, high_open=True
        )
    if "actuator" in tables:
        if "u_max" not in tables["actuator"]:
            raise SpecificationError("[dispersions.actuator] needs u_max = [low, high] (N m) or a distribution table")
        values["u_max"] = parse_distribution("actuator.u_max", tables["actuator"]["u_max"], low=0.0, low_open=True)
    if "disturbance" in tables:
        if "magnitude" not in tables["disturbance"]:
            raise SpecificationError(
                "[dispersions.disturbance] needs magnitude = [low, high] (N m) or a distribution table"
            )
        values["disturbance"] = parse_distribution("disturbance.magnitude", tables["disturbance"]["magnitude"], low=0.0)
    for key in ("attitude_noise", "rate_noise", "gyro_bias"):
        if key in tables.get("sensor", {}):
            values[key] = parse_distribution(f"sensor.{key}", tables["sensor"][key], low=0.0)
    return FlightDispersion(**values)


def _check_flight(spec: CampaignSpec) -> None:
    """The flight models run in the flight loop only: every rule must be hysteretic, and jitter fixes tau."""
    labels = dict(zip(spec.rule_labels, spec.rule_list, strict=True))
    if spec.flight_dispersion.delta is not None and not any(isinstance(r, Hysteretic) for r in labels.values()):
        raise SpecificationError("dispersions.hysteresis.delta: no rule of the campaign is 'hysteretic'")
    if spec.uses_flight:
        other = [label for label, rule in labels.items() if not isinstance(rule, Hysteretic | OnPredicted)]
        if other:
            raise SpecificationError(
                f"[flight] and the flight dispersions run in the flight loop only: every rule must be 'hysteretic' "
                f"(hysteretic:0 is on-current's control) or 'on-predicted' (the predictor), got {other[0]!r}"
            )
    if spec.flight is not None and spec.flight.jitter is not None and spec.tau is not None:
        raise SpecificationError("flight.jitter fixes tau (= tau_max); remove [dispersions.tau]")
    if spec.flight is not None and spec.flight.delay_file is not None and spec.tau is not None:
        raise SpecificationError(
            "flight.delay_file fixes tau (= the largest delay the sequence may hold, the history depth); "
            "remove [dispersions.tau]"
        )


def load_campaign(path: str | Path) -> CampaignSpec:
    """Read a campaign TOML file (see ``examples/campaigns/*.toml``); relative names of per-sample files
    (``flight.disturbance_file``, ``flight.delay_file``) are taken from its folder.

    The file is UTF-8 (a byte-order mark allowed); a missing file, a folder, a file that is not UTF-8 (its
    line and column named) or not valid TOML is refused with one
    [SpecificationError][mrpctl.errors.SpecificationError] naming the file.
    """
    path = Path(path)
    data = read_toml(path, "campaign file")
    return parse_campaign(data, name=path.stem, base=path.parent)
