"""Scenario files (TOML): spacecraft, gains, initial state, delay, rule and horizon in one value."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from mrpctl._files import read_toml, toml_value
from mrpctl._scenario_estimator import ESTIMATOR_TABLE, estimator_table, estimator_toml
from mrpctl._scenario_steering import STEERING_TABLE, check_steering_scenario, steering_table, steering_toml
from mrpctl._scenario_tables import (
    FLIGHT_TABLES,
    REFERENCE_TABLE,
    TABLE_KEYS,
    Horizon,
    check_keys,
    delay_periods,
    delay_sequence,
    delay_values,
    flight_tables,
    flight_toml,
    reference_table,
    reference_toml,
    sample_count,
    samples_file,
    torque_rows,
    tracking_keys,
)
from mrpctl._scenario_wheels import WHEELS_TABLE, check_wheel_scenario, wheels_table, wheels_text, wheels_toml
from mrpctl._validation import (
    finite_array,
    finite_scalar,
    integer,
    nonnegative_scalar,
    positive_scalar,
    readonly,
)
from mrpctl.conventions import PDGains, gain_from_pd, pd_from_gain, state, state_parts
from mrpctl.errors import DimensionError, SpecificationError
from mrpctl.estimation import EstimatedLoop
from mrpctl.flight import ActuatorModel, DelayModel, Disturbance, Hysteretic, SensorModel
from mrpctl.flight.steering import SteeringLaw
from mrpctl.flight.tracking import DEFAULT_POINTING_TOLERANCE, ErrorTime
from mrpctl.guidance import (
    GuidanceProfile,
)
from mrpctl.loop import delay_samples
from mrpctl.model import gain_matrix
from mrpctl.predictor import OnPredicted, Predictor, PredictorForm
from mrpctl.rules import RULE_NAMES, rule_from_name, rule_name
from mrpctl.simulation import SETTLING_ATTITUDE_DEG, SETTLING_OMEGA, SimulationResult, settling_tolerances, simulate
from mrpctl.simulation.estimated import EstimatedResult
from mrpctl.spacecraft import Spacecraft, check_spacecraft
from mrpctl.switching import BoundaryLayer, DelayAware, SwitchingRule
from mrpctl.wheels import WheelCluster

__all__ = [
    "RULE_NAMES",
    "STARTER_SCENARIO",
    "InertiaUncertainty",
    "Scenario",
    "delay_periods",
    "delay_sequence",
    "delay_values",
    "load_scenario",
    "parse_scenario",
    "predictor_model",
    "resolve_scenario",
    "rule_from_name",
    "rule_name",
    "sample_count",
    "samples_file",
    "scenario_toml",
    "shipped_scenarios",
    "torque_rows",
    "tumbling_states",
]

#: The names a scenario file or the command line may give a switching rule.
_TOP_KEYS = {
    "name",
    "description",
    "t_final",
    "tau",
    "rate",
    "history",
    "substeps",
    "settling_attitude_deg",
    "settling_rate",
}
_TABLES = {"spacecraft", "gains", "initial", "rule", ESTIMATOR_TABLE}
#: The predictor controller's table (``[rule] type = "on-predicted"`` only, and then required).
_PREDICTOR_TABLE = "predictor"
#: The inertia uncertainty that ``mrpctl verify`` certifies (any rule; the simulation flies the nominal J).
_UNCERTAINTY_TABLE = "uncertainty"


@dataclass(frozen=True)
class InertiaUncertainty:
    """The inertias a scenario's gain must be certified for (``[uncertainty]``; ``mrpctl verify``).

    Every J with |J_ii − J0_ii| <= ``tolerance`` · J0_ii and symmetric products of inertia
    |J_ij| <= ``product_bound`` (kg m²) around the scenario's diagonal J0
    ([`mrpctl.design.inertia_polytope`][mrpctl.design.inertia_polytope]). Only the certificates use it: the simulation
    flies J0.

    Attributes
    ----------
    tolerance : float
        Relative per-axis tolerance, 0 < tolerance < 1.
    product_bound : float
        Bound on the products of inertia (kg m²), >= 0 (default 0).
    """

    tolerance: float
    product_bound: float = 0.0

    def __post_init__(self) -> None:
        tolerance = positive_scalar("inertia_tolerance", self.tolerance)
        if tolerance >= 1.0:
            raise SpecificationError(f"inertia_tolerance must be < 1 (relative), got {tolerance!r}")
        object.__setattr__(self, "tolerance", tolerance)
        object.__setattr__(self, "product_bound", nonnegative_scalar("product_bound", self.product_bound))

    def __str__(self) -> str:
        products = f", |J_ij| <= {self.product_bound:g} kg m^2" if self.product_bound else ""
        return f"inertia uncertainty: J_ii within +-{100 * self.tolerance:g} %{products}"


@dataclass(frozen=True, eq=False)
class Scenario:
    """One simulation set-up: everything [`mrpctl.simulate`][mrpctl.simulation.simulate] needs.

    Attributes
    ----------
    name : str
        Short identifier (used for file names).
    spacecraft : Spacecraft
        The plant.
    K : numpy.ndarray
        (3, 6) feedback gain on x = [σ; ω/4], u = K x(t − τ) (the paper's form; the physical
        gains are [`gains`][mrpctl.Scenario.gains]).
    x0 : numpy.ndarray
        Initial state [σ₀; ω₀/4]; also the constant initial function φ(θ) = x0 (the physical
        σ₀, ω₀ are [`sigma0`][mrpctl.Scenario.sigma0], [`omega0`][mrpctl.Scenario.omega0]).
    tau : float
        Measurement delay τ (s).
    rule : SwitchingRule
        The shadow-set switching rule.
    t_final : float
        Horizon (s).
    rate : float
        Measurement rate (Hz).
    history : str
        ``"constant"`` or ``"zero-input"``.
    substeps : int
        RK4 substeps per measurement period.
    description : str
        Free text (the paper figure it reproduces, for instance).
    actuator, sensor, disturbance, delay : optional
        The loop as flown (``rule`` a [`Hysteretic`][mrpctl.flight.Hysteretic], or an
        [`OnPredicted`][mrpctl.predictor.OnPredicted] without ``delay``):
        [`ActuatorModel`][mrpctl.flight.ActuatorModel], [`SensorModel`][mrpctl.flight.SensorModel],
        [`Disturbance`][mrpctl.flight.Disturbance] (constant or per sample), [`DelayModel`][mrpctl.flight.DelayModel]
        (seeded jitter with ``tau_max`` = ``tau``). None: not modelled.
    predictor : Predictor or None
        The predictor controller (``rule`` an [`OnPredicted`][mrpctl.predictor.OnPredicted], and then
        required): u = K x̂ with x̂ predicted by the controller's model ``predictor.model``
        (``design/predictor.md``). None: the plain delayed law u = K x(t − τ).
    uncertainty : InertiaUncertainty or None
        The inertia box ``mrpctl verify`` certifies the gain over (``[uncertainty]``, any rule); not
        used by the simulation. None: the nominal inertia only.
    settling_attitude : float
        Attitude tolerance of the settling time (principal angle, deg; file key ``settling_attitude_deg``),
        default 4 atan(1e-2) = 2.2918° (|σ| < 1e-2).
    settling_rate : float
        Rate tolerance of the settling time (rad/s; file key ``settling_rate``), default 1e-3.
    reference : GuidanceProfile or None
        The reference motion the loop tracks (``[reference]``): an
        [`InertialPointing`][mrpctl.guidance.InertialPointing],
        [`EigenaxisSlew`][mrpctl.guidance.EigenaxisSlew],
        [`NadirPointing`][mrpctl.guidance.NadirPointing] or
        [`FileReference`][mrpctl.guidance.FileReference]. None: regulation to the inertial origin.
        [`simulate`][mrpctl.Scenario.simulate] flies the tracking loop on it
        (``simulate(..., reference=...)``: the controller-side rule or the predictor).
    error_time, feedforward, pointing_tolerance : ErrorTime or None, bool, float
        How a tracking scenario's controller forms its error (``[reference] error_time``: "measurement" or
        "current"; None: simulate's default), whether it adds the feedforward terms (``feedforward``), and
        the slew time's tolerance on the pointing error in degrees (``pointing_tolerance_deg``, default 0.1).
    gravity_gradient : bool
        Nadir pointing only (``[reference] gravity_gradient = true``): the plant flies the gravity-gradient torque
        3n² r̂ × (J r̂) of the reference's orbit (``simulate(..., gravity_gradient=reference)``). Default False.
    wheels : WheelCluster or None
        The reaction wheels the body torque is flown on (``[wheels]``, `mrpctl._scenario_wheels`;
        ``simulate(..., wheels=...)``, ``design/wheels.md``). None: the torque as commanded (or ``actuator``).
    estimated_loop : EstimatedLoop or None
        The loop on an estimator of a late star tracker and a gyro (``[estimator]``; ``design/estimation.md``),
        flown by [`simulate_estimated`][mrpctl.Scenario.simulate_estimated]. None: the loop above.
    law : SteeringLaw or None
        The rate-limited steering law flown instead of the PD law (``[steering]``, `mrpctl._scenario_steering`;
        ``simulate(..., law=...)``, ``design/wheels.md``); K is the law near the target. None: the PD law.
    """

    name: str
    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    x0: np.ndarray = field(repr=False)
    tau: float
    rule: SwitchingRule
    t_final: float
    rate: float = 1000.0
    history: str = "constant"
    substeps: int = 1
    description: str = ""
    actuator: ActuatorModel | None = None
    sensor: SensorModel | None = None
    disturbance: Disturbance | None = None
    delay: DelayModel | None = None
    predictor: Predictor | None = None
    uncertainty: InertiaUncertainty | None = None
    settling_attitude: float = SETTLING_ATTITUDE_DEG
    settling_rate: float = SETTLING_OMEGA
    reference: GuidanceProfile | None = None
    error_time: ErrorTime | None = None
    feedforward: bool = False
    pointing_tolerance: float = DEFAULT_POINTING_TOLERANCE
    gravity_gradient: bool = False
    wheels: WheelCluster | None = None
    estimated_loop: EstimatedLoop | None = None
    law: SteeringLaw | None = None

    @property
    def gains(self) -> PDGains:
        """K as physical gains: u = −P_σ σ − P_ω ω, P_σ = −K[:, :3] (N m), P_ω = −K[:, 3:] / 4 (N m s)."""
        return PDGains.from_gain(self.K)

    @property
    def sigma0(self) -> np.ndarray:
        """(3,) initial MRPs σ₀."""
        return readonly(state_parts(self.x0)[0])

    @property
    def omega0(self) -> np.ndarray:
        """(3,) initial body rates ω₀ (rad/s)."""
        return readonly(state_parts(self.x0)[1])

    @property
    def flight_options(self) -> dict[str, Any]:
        """The flight models that are set, as keywords of [`mrpctl.simulate`][mrpctl.simulation.simulate] and
        [`mrpctl.export`][mrpctl._export.export]."""
        options: dict[str, Any] = {"actuator": self.actuator, "sensor": self.sensor, "disturbance": self.disturbance}
        options["delay"] = self.delay
        return {key: value for key, value in options.items() if value is not None}

    @property
    def run_options(self) -> dict[str, Any]:
        """[`flight_options`][mrpctl.Scenario.flight_options] and, when set, ``predictor``: the optional keywords of
        [`mrpctl.simulate`][mrpctl.simulation.simulate] and [`mrpctl.export`][mrpctl._export.export] for this
        scenario."""
        options = self.flight_options
        if self.predictor is not None:
            options["predictor"] = self.predictor
        return options

    def with_rule(self, rule: SwitchingRule) -> Scenario:
        """The same scenario with another switching rule."""
        return replace(self, rule=rule)

    def simulate(self) -> SimulationResult:
        """Run the scenario with [`mrpctl.simulate`][mrpctl.simulation.simulate]."""
        if self.estimated_loop is not None:
            raise SpecificationError("scenario: its [estimator] loop runs with Scenario.simulate_estimated()")
        return simulate(
            self.spacecraft,
            self.K,
            self.x0,
            tau=self.tau,
            rule=self.rule,
            t_final=self.t_final,
            rate=self.rate,
            history=self.history,
            substeps=self.substeps,
            settling_attitude=self.settling_attitude,
            settling_rate=self.settling_rate,
            reference=self.reference,
            **self.tracking_options,
            **self.run_options,
            wheels=self.wheels,
            law=self.law,
        )

    @property
    def tracking_options(self) -> dict[str, Any]:
        """A tracking scenario's ``error_time``, ``feedforward``, ``pointing_tolerance`` (and, with
        ``gravity_gradient``, the orbit) as keywords of [`mrpctl.simulate`][mrpctl.simulation.simulate]; {} when
        the scenario regulates."""
        if self.reference is None:
            return {}
        return {
            "error_time": self.error_time,
            "feedforward": self.feedforward,
            "pointing_tolerance": self.pointing_tolerance,
            **({"gravity_gradient": self.reference} if self.gravity_gradient else {}),
        }

    def simulate_estimated(self) -> EstimatedResult:
        """Run the scenario's [estimator] loop: ``simulate(..., sensors=..., estimator=...)``."""
        if self.estimated_loop is None:
            raise SpecificationError("scenario: no [estimator] table; run it with Scenario.simulate()")
        loop = self.estimated_loop
        return simulate(
            self.spacecraft, self.K, self.x0, tau=self.tau, rule=self.rule, t_final=self.t_final, rate=self.rate,
            history=self.history, substeps=self.substeps, reference=self.reference, sensors=loop.sensors,
            estimator=loop.estimator, wheels=self.wheels, **self.run_options,
        )  # fmt: skip

    def __str__(self) -> str:
        sigma0, omega0 = self.sigma0, self.omega0
        return "\n".join(
            (
                f"scenario {self.name}: {self.description}".rstrip(": "),
                f"  {self.spacecraft}",
                f"  sigma0 = {np.round(sigma0, 6).tolist()}, omega0 = {np.round(omega0, 6).tolist()} rad/s",
                f"  tau = {self.tau:g} s at {self.rate:g} Hz, rule {self.rule}, history {self.history}",
                f"  t_final = {self.t_final:g} s, {self.substeps} RK4 substep(s) per sample",
                *(f"  {value}" for value in self.run_options.values()),
                *([f"  {self.uncertainty}"] if self.uncertainty is not None else []),
                *([f"  reference: {self.reference}"] if self.reference is not None else []),
                *([f"  {wheels_text(self.wheels)}"] if self.wheels is not None else []),
                *([f"  {self.estimated_loop}"] if self.estimated_loop is not None else []),
                *([f"  steering: {self.law}"] if self.law is not None else []),
            )
        )


def _predictor_table(
    data: dict[str, Any], rule: SwitchingRule, spacecraft: Spacecraft, history: str
) -> Predictor | None:
    """The [predictor] table as a [`Predictor`][mrpctl.predictor.Predictor] (required exactly with 'on-predicted')."""
    if _PREDICTOR_TABLE not in data:
        if isinstance(rule, OnPredicted):
            raise SpecificationError(
                "[rule] type = 'on-predicted' needs a [predictor] table (the controller's model): empty for the "
                "exact model (the plant's inertia), inertia = [J1, J2, J3] (or 3x3, kg m^2), or inertia_error = e "
                "(model inertia (1 + e) J)"
            )
        return None
    table = data[_PREDICTOR_TABLE]
    if not isinstance(table, dict):
        raise SpecificationError(f"[predictor] must be a table of the scenario, got {table!r}")
    check_keys(_PREDICTOR_TABLE, table, TABLE_KEYS[_PREDICTOR_TABLE])
    if not isinstance(rule, OnPredicted):
        raise SpecificationError(
            f"[predictor] applies only with [rule] type = 'on-predicted' (switching on the predicted attitude), "
            f"got {rule_name(rule)!r}"
        )
    if history != "constant":
        raise SpecificationError(
            f"[predictor] needs history = 'constant' (the model copy starts at x0), got {history!r}"
        )
    try:
        model = predictor_model(spacecraft, table.get("inertia"), table.get("inertia_error"))
        return Predictor(model=model, form=PredictorForm.parse(table.get("form", PredictorForm.NONLINEAR.value)))
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[predictor] {exc}") from exc


def predictor_model(spacecraft: Spacecraft, inertia: Any = None, inertia_error: Any = None) -> Spacecraft:
    """The controller's model of a predictor: the plant, an explicit inertia, or the plant with a relative error.

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant (the scenario's spacecraft).
    inertia : array_like, optional
        The model's inertia J_m (3 principal values or a 3x3 matrix, kg m²).
    inertia_error : float or array_like, optional
        Relative inertia error e of the plant against the model, the one convention of mrpctl
        ([`perturbed_spacecraft`][mrpctl.predictor.perturbed_spacecraft],
        [`inertia_mismatch_margin`][mrpctl.predictor.inertia_mismatch_margin]): J = (1 + e) J_m, so
        J_m = J / (1 + e) for a scalar; for 3 values e_i, J = S J_m S with S = diag(√(1 + e_i)), so
        J_m = S⁻¹ J S⁻¹ (for a diagonal J, J_m,ii = J_ii / (1 + e_i)). e > 0: the plant is heavier than
        the model. Each e > −1 (dimensionless). Not together with ``inertia``.
    """
    plant = check_spacecraft(spacecraft, "spacecraft")
    if inertia is not None and inertia_error is not None:
        raise SpecificationError(
            "give inertia (the model's J) or inertia_error (the plant's error against the model), not both"
        )
    if inertia is not None:
        return Spacecraft(inertia)
    if inertia_error is None:
        return plant
    errors = finite_array("inertia_error", inertia_error)
    if errors.ndim == 0:
        errors = np.full(3, float(errors))
    elif errors.shape != (3,):
        raise DimensionError(f"inertia_error: expected a scalar or 3 per-axis values but found shape {errors.shape}")
    if np.any(errors <= -1.0):
        raise SpecificationError(f"inertia_error: each relative error must be > -1, got {errors.tolist()}")
    inverse = np.diag(1.0 / np.sqrt(1.0 + errors))  # S⁻¹: J = S J_m S
    return Spacecraft(inverse @ plant.inertia @ inverse)


def _table(data: dict[str, Any], name: str) -> dict[str, Any]:
    value = data.get(name)
    if not isinstance(value, dict):
        raise SpecificationError(f"scenario needs a [{name}] table")
    check_keys(name, value, TABLE_KEYS[name])
    return value


def _gain(spacecraft: Spacecraft, gains: dict[str, Any]) -> np.ndarray:
    forms = [
        k
        for k in (("K",), ("k_sigma", "k_omega"), ("K1", "K2"), ("attitude", "rate"))
        if any(key in gains for key in k)
    ]
    if len(forms) != 1 or not all(key in gains for key in forms[0]):
        raise SpecificationError(
            "[gains] must give exactly one of: attitude and rate (the physical PD gains of u = -P_sigma sigma - "
            "P_omega omega: P_sigma in N m, P_omega in N m s, each > 0 as a scalar or 3 per-axis values, or a 3x3 "
            "matrix); K (3x6, on x = [sigma; omega/4]); k_sigma and k_omega (K = [k_sigma I3, k_omega I3]); K1 and "
            "K2 (loop gains)"
        )
    if forms[0] == ("attitude", "rate"):
        return np.array(PDGains(attitude=gains["attitude"], rate=gains["rate"]).gain())
    if forms[0] == ("K",):
        return gain_matrix(gains["K"])
    if forms[0] == ("k_sigma", "k_omega"):
        k_sigma = _per_axis("k_sigma", gains["k_sigma"], matrix=False)
        k_omega = _per_axis("k_omega", gains["k_omega"], matrix=False)
        return np.hstack((k_sigma, k_omega))
    return gain_from_pd(spacecraft, _per_axis("K1", gains["K1"]), _per_axis("K2", gains["K2"]))


def _per_axis(name: str, value: Any, *, matrix: bool = True) -> np.ndarray:
    """A 3×3 block from a scalar (times I₃), 3 per-axis values (diagonal) or, if ``matrix``, a 3×3 matrix."""
    array = finite_array(name, value)
    if array.ndim == 0:
        return float(array) * np.eye(3)
    if array.shape == (3,):
        return np.diag(array)
    if matrix and array.shape == (3, 3):
        return array
    expected = "a scalar, 3 per-axis values or a 3x3 matrix" if matrix else "a scalar or 3 per-axis values"
    raise DimensionError(f"{name}: expected {expected} but found shape {array.shape}")


def _initial_state(initial: dict[str, Any]) -> np.ndarray:
    has_sigma = "sigma" in initial
    has_angle = "principal_angle_deg" in initial or "axis" in initial
    if has_sigma == has_angle:
        raise SpecificationError(
            "[initial] must give either sigma or (principal_angle_deg and axis), not both or neither"
        )
    if has_sigma:
        sigma = finite_array("sigma", initial["sigma"], (3,))
    else:
        if "principal_angle_deg" not in initial or "axis" not in initial:
            raise SpecificationError("[initial] needs both principal_angle_deg and axis")
        angle = math.radians(finite_scalar("principal_angle_deg", initial["principal_angle_deg"]))
        axis = finite_array("axis", initial["axis"], (3,))
        if np.linalg.norm(axis) == 0.0:
            raise SpecificationError("axis must be a non-zero 3-vector")
        # sigma = tan(Phi/4) e as given (paper Eq. 1): the set is not shortened here.
        sigma = math.tan(angle / 4.0) * axis / np.linalg.norm(axis)
    if "omega" not in initial:
        raise SpecificationError("[initial] needs omega (rad/s, body frame)")
    return state(sigma, finite_array("omega", initial["omega"], (3,)))


def parse_scenario(data: dict[str, Any], *, name: str = "scenario", base: str | Path | None = None) -> Scenario:
    """Build a [`Scenario`][mrpctl.Scenario] from the parsed contents of a scenario file.

    Unknown keys raise a [`SpecificationError`][mrpctl.SpecificationError] naming the key. ``base``: the
    folder relative file names (``[disturbance] torque_file``, ``[delay] sequence_file``) are taken
    from ([`load_scenario`][mrpctl.load_scenario]: the scenario file's folder; None: the working directory).

    The optional ``[reference]`` table sets [`Scenario.reference`][mrpctl.Scenario], the guidance
    profile the loop tracks (``design/tracking.md``), by its ``type``:

    * ``"inertial"``: ``sigma`` (σ_R/N, a short-set MRP);
    * ``"slew"``: ``start`` (σ, default the origin), ``target`` (σ, the short way) or ``axis`` (unit,
      start-frame components) and ``angle_deg``, ``rate_limit`` (rad/s), ``acceleration_limit``
      (rad/s²), ``t_start`` (s, default 0);
    * ``"nadir"``: the Hill frame (x radial out, y along-track, z orbit normal) of a circular orbit given
      by one of ``orbit_rate`` (rad/s), ``altitude`` (m above the Earth's equatorial radius) or ``radius``
      (m), ``mu`` (m³/s², default the Earth's) with the last two, and ``inclination_deg``, ``raan_deg``,
      ``latitude_deg`` (argument of latitude at t = 0), each default 0;
    * ``"file"``: ``file``, a .csv or .npy file of n = floor(t_final · rate) + 1 rows of 9 numbers
      (σ_R/N, ω_R/N in rad/s, ω̇_R/N in rad/s², N components), relative to ``base``.

    The optional ``[wheels]`` table sets [`Scenario.wheels`][mrpctl.Scenario], the reaction wheels the torque is
    flown on (keys and refusals: `mrpctl._scenario_wheels`); ``[steering]`` sets [`Scenario.law`][mrpctl.Scenario],
    the steering law (`mrpctl._scenario_steering`).
    The optional ``[estimator]`` table (with ``[estimator.star_tracker]``, ``[estimator.gyro]`` and optionally
    ``[estimator.tuning]``) sets [`Scenario.estimated_loop`][mrpctl.Scenario]: the loop on an estimator of a late
    star tracker and a gyro (its keys: ``design/estimation.md``; an example: ``docs/how-to/estimation.md``).
    """
    check_keys(
        "",
        data,
        _TOP_KEYS
        | _TABLES
        | FLIGHT_TABLES
        | {_PREDICTOR_TABLE, _UNCERTAINTY_TABLE, REFERENCE_TABLE, WHEELS_TABLE, STEERING_TABLE},
    )
    spacecraft_table = _table(data, "spacecraft")
    if "inertia" not in spacecraft_table:
        raise SpecificationError("[spacecraft] needs inertia (3 principal values or a 3x3 matrix, kg m^2)")
    spacecraft = Spacecraft(spacecraft_table["inertia"])
    rule_table = _table(data, "rule")
    if "type" not in rule_table:
        raise SpecificationError(f"[rule] needs type, one of {sorted(RULE_NAMES)}")
    try:
        rule = rule_from_name(
            str(rule_table["type"]),
            eps=rule_table.get("eps"),
            alpha=rule_table.get("alpha"),
            delta=rule_table.get("delta"),
        )
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[rule] {exc}") from exc
    for key in ("t_final", "tau"):
        if key not in data:
            raise SpecificationError(f"scenario needs {key} (s)")
    tau = nonnegative_scalar("tau", data["tau"])
    rate = positive_scalar("rate", data.get("rate", 1000.0))
    check_delay(tau, rate)
    history = data.get("history", "constant")
    if history not in ("constant", "zero-input"):
        raise SpecificationError(f"history must be 'constant' or 'zero-input', got {history!r}")
    substeps = integer("substeps", data.get("substeps", 1), minimum=1)
    t_final = positive_scalar("t_final", data["t_final"])
    samples = sample_count(t_final, rate)
    flight = flight_tables(data, rule, tau, rate, Horizon(None if base is None else Path(base), samples))
    predictor = _predictor_table(data, rule, spacecraft, history)
    try:
        settle_attitude, settle_rate, _ = settling_tolerances(
            data.get("settling_attitude_deg", SETTLING_ATTITUDE_DEG), data.get("settling_rate", SETTLING_OMEGA)
        )
    except SpecificationError as exc:
        raise SpecificationError(f"{exc} (scenario keys settling_attitude_deg, settling_rate)") from exc
    reference = reference_table(data, rate, Horizon(None if base is None else Path(base), samples))
    wheels = wheels_table(data, spacecraft)
    check_wheel_scenario(wheels, rule, actuator=flight.get("actuator"), predictor=predictor, reference=reference)
    K = readonly(_gain(spacecraft, _table(data, "gains")))
    law = steering_table(data, spacecraft)
    check_steering_scenario(law, rule, K, predictor=predictor, reference=reference)
    return Scenario(
        name=str(data.get("name", name)),
        spacecraft=spacecraft,
        K=K,
        x0=readonly(_initial_state(_table(data, "initial"))),
        tau=tau,
        rule=rule,
        t_final=t_final,
        rate=rate,
        history=history,
        substeps=substeps,
        description=str(data.get("description", "")),
        predictor=predictor,
        uncertainty=_uncertainty_table(data, spacecraft),
        settling_attitude=settle_attitude,
        settling_rate=settle_rate,
        reference=reference,
        **tracking_keys(data),
        estimated_loop=estimator_table(data, spacecraft=spacecraft, rule=rule, tau=tau, rate=rate, history=history),
        **flight,
        wheels=wheels,
        law=law,
    )


def _uncertainty_table(data: dict[str, Any], spacecraft: Spacecraft) -> InertiaUncertainty | None:
    """The [uncertainty] table (optional, any rule): the inertia box ``mrpctl verify`` certifies."""
    if _UNCERTAINTY_TABLE not in data:
        return None
    table = data[_UNCERTAINTY_TABLE]
    if not isinstance(table, dict):
        raise SpecificationError(f"[uncertainty] must be a table of the scenario, got {table!r}")
    check_keys(_UNCERTAINTY_TABLE, table, TABLE_KEYS[_UNCERTAINTY_TABLE])
    if "inertia_tolerance" not in table:
        raise SpecificationError(
            "[uncertainty] needs inertia_tolerance (relative per-axis tolerance on J_ii, 0 < tol < 1); "
            "product_bound (|J_ij| bound, kg m^2) is optional"
        )
    try:
        uncertainty = InertiaUncertainty(table["inertia_tolerance"], table.get("product_bound", 0.0))
    except (SpecificationError, DimensionError) as exc:
        raise type(exc)(f"[uncertainty] {exc}") from exc
    if not spacecraft.is_diagonal:
        raise SpecificationError(
            "[uncertainty] needs a diagonal nominal [spacecraft] inertia (the box is built around principal "
            "axes); give the 3 principal values"
        )
    return uncertainty


def check_delay(tau: float, rate: float) -> None:
    """τ · rate must be a whole number of measurement periods (as [`simulate`][mrpctl.simulation.simulate] requires).

    The rule is [delay_samples][mrpctl.loop.delay_samples]'s, the one the engine applies (relative
    tolerance 1e-9: τ = k · h written in floating point is k periods). A delay beyond 2^53 periods is left
    to the memory checks, which name the option that fixes it.
    """
    if math.isfinite(tau * rate) and tau * rate > 2.0**53:
        return
    delay_samples(tau, rate)


def shipped_scenarios() -> dict[str, Path]:
    """The scenario files shipped with mrpctl (package data ``mrpctl/scenarios/*.toml``), by name.

    ``examples/scenarios`` in the source tree is a link to the same folder. The command line
    accepts these names wherever it takes a scenario file (``mrpctl simulate paper_fig4_on_delayed``).
    """
    folder = Path(str(resources.files("mrpctl").joinpath("scenarios")))
    return {path.stem: path for path in sorted(folder.glob("*.toml"))}


def resolve_scenario(name_or_path: str | Path) -> Path:
    """The file of a scenario given as a path or as the name of a shipped scenario (see
    [`shipped_scenarios`][mrpctl.scenario.shipped_scenarios]).

    An existing file wins over a shipped name; a name that is neither raises a
    [`SpecificationError`][mrpctl.SpecificationError] listing the shipped names.
    """
    path = Path(name_or_path)
    if path.exists():
        return path
    shipped = shipped_scenarios()
    key = path.name.removesuffix(".toml")
    if path.parent == Path(".") and key in shipped:
        return shipped[key]
    raise SpecificationError(f"scenario file not found: {path} (shipped scenario names: {', '.join(shipped)})")


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario TOML file (UTF-8, a byte-order mark allowed), or a shipped scenario by name (see
    [`resolve_scenario`][mrpctl.scenario.resolve_scenario]).

    A missing file, a folder, a file that is not UTF-8 (its line and column named) or not valid TOML is
    refused with one [SpecificationError][mrpctl.errors.SpecificationError] naming the file.
    """
    path = resolve_scenario(path)
    data = read_toml(path, "scenario file")
    return parse_scenario(data, name=path.stem, base=path.parent)


def scenario_toml(scenario: Scenario, *, comment: str = "", physical: bool = False) -> str:
    """The scenario as a TOML file that [`load_scenario`][mrpctl.load_scenario] reads back to the same scenario.

    Floats are written with ``repr`` (shortest round-trip form), so K, J and x0 come back
    bit for bit. The gain is written as the full 3×6 K, its physical gains P_σ, P_ω and (when
    diagonal) the per-axis loop gains K₁, K₂ as comments; with ``physical=True`` it is written in
    its physical form, ``attitude`` = P_σ and ``rate`` = P_ω (per axis when diagonal and positive,
    else 3×3), when that form reads back to the same K bit for bit (always, but for a rate entry
    that underflows), with K as a comment.
    """
    if not isinstance(physical, bool):
        raise SpecificationError(f"physical must be True or False, got {physical!r}")
    if isinstance(scenario.rule, OnPredicted) and scenario.predictor is None:
        raise SpecificationError(
            "rule: 'on-predicted' needs the scenario's predictor (the controller's model) to be written as a "
            "[predictor] table; set Scenario.predictor = mrpctl.Predictor(model=...)"
        )
    k1, k2 = pd_from_gain(scenario.spacecraft, scenario.K)
    inertia = scenario.spacecraft.inertia
    inertia_value = np.diag(inertia) if scenario.spacecraft.is_diagonal else inertia
    sigma0, omega0 = scenario.sigma0, scenario.omega0
    lines = [f"# {line}" if line else "#" for line in comment.splitlines()]
    lines += [
        f"name = {toml_value(scenario.name)}",
        f"description = {toml_value(scenario.description)}",
        f"tau = {toml_value(scenario.tau)}          # measurement delay (s)",
        f"rate = {toml_value(scenario.rate)}        # measurement rate (Hz)",
        f"t_final = {toml_value(scenario.t_final)}     # horizon (s)",
        f"history = {toml_value(scenario.history)}",
        f"substeps = {scenario.substeps}",
        *(
            [f"settling_attitude_deg = {toml_value(scenario.settling_attitude)}  # settled: principal angle below"]
            if scenario.settling_attitude != SETTLING_ATTITUDE_DEG
            else []
        ),
        *(
            [f"settling_rate = {toml_value(scenario.settling_rate)}  # settled: |omega| below (rad/s)"]
            if scenario.settling_rate != SETTLING_OMEGA
            else []
        ),
        "",
        "[spacecraft]",
        f"inertia = {toml_value(inertia_value)}  # kg m^2",
        "",
        "[gains]",
    ]
    if np.array_equal(k1, np.diag(np.diag(k1))) and np.array_equal(k2, np.diag(np.diag(k2))):
        lines.append(f"# per axis: K1 = {toml_value(np.diag(k1))} (1/s^2), K2 = {toml_value(np.diag(k2))} (1/s)")
    lines += _gain_toml(scenario.K, physical)
    lines += [
        "",
        "[initial]",
        f"sigma = {toml_value(sigma0)}",
        f"omega = {toml_value(omega0)}  # rad/s, body frame",
        "",
        "[rule]",
        f"type = {toml_value(rule_name(scenario.rule))}",
    ]
    if isinstance(scenario.rule, BoundaryLayer):
        lines.append(f"eps = {toml_value(scenario.rule.eps)}")
    if isinstance(scenario.rule, DelayAware):
        lines.append(f"alpha = {toml_value(scenario.rule.alpha)}")
    if isinstance(scenario.rule, Hysteretic):
        lines.append(
            f"delta = {toml_value(scenario.rule.delta)}  # hysteresis on q0; alpha = {scenario.rule.alpha:.6g}"
        )
    if isinstance(scenario.rule, OnPredicted):
        alpha = math.inf if scenario.rule.alpha is None else scenario.rule.alpha
        lines.append(f"alpha = {toml_value(alpha)}  # switch when |sigma_hat| >= alpha; inf: never switch")
    if scenario.predictor is not None:
        model = scenario.predictor.model
        model_inertia = np.diag(model.inertia) if model.is_diagonal else model.inertia
        lines += ["", "[predictor]", f"inertia = {toml_value(model_inertia)}  # the controller's model J_m, kg m^2"]
        if scenario.predictor.form is not PredictorForm.NONLINEAR:
            lines.append(f'form = "{scenario.predictor.form.value}"  # the linearised model copy, FSA on the group')
    lines += flight_toml(scenario.actuator, scenario.sensor, scenario.disturbance, scenario.delay)
    lines += reference_toml(scenario.reference)
    if scenario.reference is not None:
        if scenario.error_time is not None:
            lines.append(f'error_time = "{scenario.error_time.value}"  # the reference at the measurement time or now')
        if scenario.feedforward:
            lines.append("feedforward = true  # omega x J omega and J (domega_R - omega x omega_R)")
        if scenario.pointing_tolerance != DEFAULT_POINTING_TOLERANCE:
            tolerance = toml_value(scenario.pointing_tolerance)
            lines.append(f"pointing_tolerance_deg = {tolerance}  # the slew time's tolerance")
        if scenario.gravity_gradient:
            lines.append("gravity_gradient = true  # the plant flies 3 n^2 r x (J r) of the orbit")
    lines += wheels_toml(scenario.wheels)
    lines += estimator_toml(scenario.estimated_loop)
    lines += steering_toml(scenario.law, scenario.spacecraft)
    if scenario.uncertainty is not None:
        lines += [
            "",
            "[uncertainty]",
            f"inertia_tolerance = {toml_value(scenario.uncertainty.tolerance)}  # relative, per axis (verify only)",
            f"product_bound = {toml_value(scenario.uncertainty.product_bound)}  # |J_ij|, kg m^2",
        ]
    return "\n".join(lines) + "\n"


def _gain_toml(K: np.ndarray, physical: bool) -> list[str]:
    """The [gains] lines of K: with ``physical`` the attitude and rate gains (per axis, else 3x3) when they read
    back to K bit for bit (the sign of every zero included), else K itself with the physical gains as comments."""
    gains = PDGains.from_gain(K)
    paper_rows = ["    " + toml_value(row) + "," for row in K]
    if not physical:
        shown = (np.diag(gains.attitude), np.diag(gains.rate)) if gains.is_diagonal else (gains.attitude, gains.rate)
        return [
            "# u = K x(t - tau) on x = [sigma; omega/4], K = [4 J K1, 4 J K2] (N m), row by row",
            "# physically u = -P_sigma sigma - P_omega omega, K = [-P_sigma, -4 P_omega]:",
            f"#   attitude = {toml_value(shown[0])}  # P_sigma, N m",
            f"#   rate = {toml_value(shown[1])}  # P_omega, N m s",
            "K = [",
            *paper_rows,
            "]",
        ]
    forms = [(gains.attitude, gains.rate)]
    if gains.is_diagonal and bool(np.all(np.diag(gains.attitude) > 0) and np.all(np.diag(gains.rate) > 0)):
        forms.insert(0, (np.diag(gains.attitude), np.diag(gains.rate)))
    for attitude, rate in forms:
        back = PDGains(attitude=attitude, rate=rate).gain()
        if np.array_equal(np.signbit(back), np.signbit(K)) and np.array_equal(back, K):
            return [
                "# u = -P_sigma sigma - P_omega omega: attitude = P_sigma (N m), rate = P_omega (N m s)",
                f"attitude = {toml_value(attitude)}",
                f"rate = {toml_value(rate)}",
                "# the paper's form u = K x(t - tau) on x = [sigma; omega/4], K = [-P_sigma, -4 P_omega]:",
                "# K = [",
                *("#" + row for row in paper_rows),
                "# ]",
            ]
    return [
        "# u = K x(t - tau) on x = [sigma; omega/4], K = [4 J K1, 4 J K2] (N m), row by row",
        "K = [",
        *paper_rows,
        "]",
    ]


#: The commented starter scenario written by ``mrpctl init``.
STARTER_SCENARIO = """\
# mrpctl scenario: one closed-loop run. Run it with `mrpctl simulate THIS.toml`,
# certify its gains with `mrpctl verify THIS.toml`. Units: SI, radians (angles in degrees
# only where the key says _deg). Unknown keys are an error naming the key.
name = "my_spacecraft"
description = "starter scenario written by mrpctl init"
tau = 0.2          # measurement delay tau (s); a whole number of periods 1/rate
rate = 1000.0      # measurement rate (Hz)
t_final = 60.0     # horizon (s)
history = "constant"  # measurements before t = 0: "constant" (= x0) or "zero-input"
substeps = 1       # RK4 substeps per measurement period
# settling_attitude_deg = 2.2918  # "settled": principal angle below this (deg; default 4 atan(0.01), |sigma| < 0.01)
# settling_rate = 1e-3            # ... and |omega| below this (rad/s), from then to the end

[spacecraft]
# Principal inertias J = diag(J1, J2, J3), or a full symmetric 3x3 matrix (kg m^2).
inertia = [12.0, 15.0, 9.0]

[gains]
# Give exactly one of:
#   attitude, rate                            the PD gains of u = -P_sigma sigma - P_omega omega (Basilisk's
#                                             mrpFeedback K and P): attitude = P_sigma (N m), rate = P_omega
#                                             (N m s, on omega in rad/s); scalars or 3 per-axis values (> 0),
#                                             or 3x3 matrices
#   K1, K2                                    loop gains of sigma'' = K1 sigma + K2 sigma' (K = [4 J K1, 4 J K2]);
#                                             scalars, 3 per-axis values or 3x3 matrices
#   K = [[...6 values...], [...], [...]]      the paper's full 3x6 gain of u = K x on x = [sigma; omega/4] (N m),
#                                             K = [-P_sigma, -4 P_omega]
#   k_sigma, k_omega                          K = [k_sigma I3, k_omega I3]; scalars or 3 per-axis values
# `mrpctl design --inertia 12 15 9 --tau 0.2 --toml s.toml` writes certified gains.
# These are critically damped (zeta = 1) at omega_n = 0.8 rad/s (K1 = -0.64, K2 = -1.6 per axis):
# P_sigma = 4 J omega_n^2 and P_omega = 2 zeta omega_n J for J = [12, 15, 9].
attitude = [30.72, 38.4, 23.04]
rate = [19.2, 24.0, 14.4]

[initial]
# Either sigma = [s1, s2, s3] (MRPs), or principal_angle_deg and axis.
principal_angle_deg = 170.0
axis = [1.0, 0.0, 0.0]
omega = [0.3, 0.0, 0.0]  # body rates (rad/s)

[rule]
# Shadow-set switching: "none", "on-current" (|sigma(t)| >= 1), "on-delayed" (|sigma(t - tau)| >= 1),
# "boundary-layer" (needs eps > 0), "delay-aware" (optional alpha >= 1, default 1; not sound in general:
# it fails to settle on fast tumbles, design/flight.md), the controller-side set selection of the loop as
# flown, "hysteretic" (delta in [0, 1) or alpha >= 1), or "on-predicted" (the predictor controller;
# alpha >= 1, inf: never switch; needs a [predictor] table: empty for the exact model, inertia = [...] or
# inertia_error = e; see predictor-paper). The default here is the command line's: hysteresis delta = 0.1
# (|sigma_c| <= alpha = 1.106), in the band delta 0.05-0.18 recommended for attitude noise up to 0.01 rad.
type = "hysteretic"
delta = 0.1

# The loop as flown (only with type = "hysteretic"; see `mrpctl simulate flight-paper`), all optional:
# [actuator]     u_max = 20.0 (N m, scalar or 3 values), u_norm = 30.0 (N m), saturation = "scale" or "clip"
# [sensor]       attitude_noise = 0.01 (rad, 1 sigma per axis), rate_noise = 1e-4 (rad/s), gyro_bias, seed = 1
# [disturbance]  torque = [1e-3, 0.0, 0.0] (N m, body frame)
# [delay]        tau_min = 0.15 (s; the delay jitters over the whole periods in [tau_min, tau]), seed = 2
# [wheels]       reaction wheels instead of [actuator]: layout = "orthogonal", spin_inertia = 0.05 (kg m^2),
#                torque_limit = 0.2 (N m), speed_limit_rpm = 6000.0 (see `mrpctl simulate cubesat_wheels`)
# [steering]     the rate-limited steering law instead of the PD law: rate_limit = 0.19 (rad/s), acceleration =
#                0.012 (rad/s^2), lag = 0.42 (s), momentum_limit (N m s, optional); `mrpctl design --torque-limit`
#
# What `mrpctl verify` certifies besides the idealised constant delay (any rule): the sampled loop at
# `rate` (exact lifted check + certificate), the [delay] jitter (interval certificate), and
# [uncertainty]  inertia_tolerance = 0.05 (every J_ii within +-5 %), product_bound = 0.0 (|J_ij|, kg m^2)
"""


def tumbling_states(
    count: int,
    *,
    seed: int = 0,
    angle_deg: tuple[float, float] = (160.0, 179.0),
    body_rate: tuple[float, float] = (0.5, 1.2),
    cross_rate: float = 0.05,
    rate: Any = None,
) -> np.ndarray:
    """Random initial states x0 = [σ; ω/4] of a body tumbling towards Φ = 180°.

    Each state has a uniformly random principal axis ê, a principal angle Φ uniform in
    ``angle_deg`` (so |σ| = tan(Φ/4) is just below 1) and a body rate
    ω = w ê + v with w uniform in ``body_rate`` (rad/s, carrying Φ through 180°) and v a
    random vector orthogonal to ê with |v| uniform in [0, ``cross_rate``]. (``rate`` is the deprecated
    name of ``body_rate``: in mrpctl ``rate`` is a measurement rate in Hz.) With the
    defaults and the paper's spacecraft and gains at τ = 0.5 s, about 87 % of the
    states carry |σ| through 1 (measured on 200 states, seed 1).

    Returns
    -------
    numpy.ndarray
        (count, 6) states, reproducible for a given ``seed``.
    """
    count = integer("count", count, minimum=1)
    seed = integer("seed", seed, minimum=0)
    cross_rate = nonnegative_scalar("cross_rate", cross_rate)
    low, high = (finite_scalar("angle_deg", a) for a in angle_deg)
    if not 0.0 <= low <= high < 360.0:
        raise SpecificationError(f"angle_deg must satisfy 0 <= low <= high < 360, got {angle_deg}")
    if rate is not None:
        warnings.warn(
            "tumbling_states(rate=) is deprecated: use body_rate= (rate is a measurement rate in Hz elsewhere)",
            DeprecationWarning,
            stacklevel=2,
        )
        body_rate = rate
    w_low, w_high = (finite_scalar("body_rate", w) for w in body_rate)
    if not 0.0 <= w_low <= w_high:
        raise SpecificationError(f"body_rate must satisfy 0 <= low <= high (rad/s), got {body_rate}")
    generator = np.random.default_rng(seed)
    axis = generator.normal(size=(count, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.radians(generator.uniform(low, high, count))
    cross = generator.normal(size=(count, 3))
    cross -= np.sum(cross * axis, axis=1, keepdims=True) * axis
    cross *= generator.uniform(0.0, cross_rate, (count, 1)) / np.linalg.norm(cross, axis=1, keepdims=True)
    omega = generator.uniform(w_low, w_high, (count, 1)) * axis + cross
    sigma = np.tan(angle / 4.0)[:, None] * axis
    return state(sigma, omega)
