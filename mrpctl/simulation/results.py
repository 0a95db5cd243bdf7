"""Results of closed-loop runs: [`SimulationResult`][mrpctl.SimulationResult], [`BatchResult`][mrpctl.BatchResult], and
their assembly."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from mrpctl._validation import readonly, sealed
from mrpctl.conventions import RATE_SCALE, PDGains, gain_parts, state_parts
from mrpctl.engines.common import RunOutput
from mrpctl.engines.stats import DIVERGENCE_BOUND, SETTLING_ATTITUDE_DEG, SETTLING_OMEGA, Metrics
from mrpctl.errors import SpecificationError
from mrpctl.flight import FLIGHT_MEMORY_SIZE
from mrpctl.flight.tracking import pointing_metrics
from mrpctl.loop import PREDICTOR_MEMORY_SIZE
from mrpctl.rules import RULE_NAMES
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import SwitchingRule

if TYPE_CHECKING:
    # deferred: pandas (about 0.3 s to import), only for a DataFrame
    import pandas as pd  # type: ignore[import-untyped]

    # deferred: xarray (about 0.5 s to import), only for labelled data
    import xarray as xr

__all__ = [
    "AXES",
    "FLIGHT_RECORDS",
    "STATE",
    "WHEEL_VARIABLES",
    "BatchResult",
    "SimulationResult",
    "WheelRecord",
    "rule_fields",
    "to_pandas",
    "to_xarray",
]

logger = logging.getLogger("mrpctl.simulation")


class _Conversions:
    """``to_xarray()`` and ``to_pandas()`` of a result, through [`mrpctl.data`][mrpctl.data]."""

    def to_xarray(self) -> Any:
        """The result as a labelled ``xarray.Dataset`` (`mrpctl.data.to_xarray`)."""
        return to_xarray(self)  # type: ignore[arg-type]

    def to_pandas(self) -> Any:
        """The result as a ``pandas.DataFrame`` (`mrpctl.data.to_pandas`)."""
        return to_pandas(self)  # type: ignore[arg-type]


@dataclass(frozen=True, eq=False)
class WheelRecord:
    """The wheels of one run on a [`WheelCluster`][mrpctl.wheels.WheelCluster].

    Attributes
    ----------
    cluster : WheelCluster
        The wheels flown.
    speeds : numpy.ndarray
        (m, N) wheel speeds Ω_i at the kept samples (rad/s, relative to the body).
    motor_torque : numpy.ndarray
        (m, N) motor torques u_s,i held over [t_k, t_{k+1}) (N m, after the torque clip and the speed cut).
    final_speeds : numpy.ndarray
        (N,) Ω_i at the end of the run (after its last sample's period).
    peak_speed : numpy.ndarray
        (N,) max_k |Ω_i(t_k)| over every sample (rad/s).
    torque_limited_time, speed_limited_time : numpy.ndarray
        (N,) time each wheel's motor torque was clipped to its u_max,i, or cut by its speed limit
        (s: samples × period, over every sample).
    peak_momentum : float
        max_k |Gs diag(Js) Ω(t_k)| (N m s), the largest momentum the wheels stored in the body frame.
    worst_wheel : int
        The wheel with the largest peak |Ω_i|/Ω_max,i (index from 0).
    """

    cluster: Any = field(repr=False)
    speeds: np.ndarray = field(repr=False)
    motor_torque: np.ndarray = field(repr=False)
    final_speeds: np.ndarray
    peak_speed: np.ndarray
    torque_limited_time: np.ndarray
    speed_limited_time: np.ndarray
    peak_momentum: float
    worst_wheel: int


@dataclass(frozen=True, eq=False)
class SimulationResult(_Conversions):
    """One closed-loop run, sampled at the measurement instants t_k = k h.

    ``sigma``, ``omega`` are the state at t_k *after* the switching rule (the recorded
    measurement m_k), ``u`` the torque held over [t_k, t_{k+1}). With ``keep_every = k``
    only every k-th sample is kept (t_0, t_k, t_2k, …); with ``keep_every = None`` none
    (the arrays are empty) — the metrics and the switch instants are those of every sample.

    Attributes
    ----------
    t : numpy.ndarray
        (m,) times of the kept samples (s); with every sample kept, m = n =
        floor(t_final · rate) + 1, fewer if the run diverged.
    sigma : numpy.ndarray
        (m, 3) MRPs σ (dimensionless).
    omega : numpy.ndarray
        (m, 3) body rates ω (rad/s).
    u : numpy.ndarray
        (m, 3) control torque (N m).
    switch_indices : numpy.ndarray
        Sample indices k at which σ was replaced by its shadow (all of them; when
        ``keep_every != 1``, at most the first 2**20, see ``switch_count``).
    switch_times : numpy.ndarray
        The same as times (s).
    switch_count : int
        Number of shadow-set switches of the rule (exact, even when ``switch_indices`` was cut). What switches
        depends on the rule: for the plant-side rules (``OnCurrent``, ``OnDelayed``, ``BoundaryLayer``,
        ``DelayAware``) the changes of the plant's MRP set, which the control law sees τ later; for the flight
        loop (``Hysteretic``) the controller's logic switches, the flips of h, each a change of the set of the
        σ_c the control law uses (the plant's own bookkeeping changes, when the attitude passes 180°, are not
        counted: they have no effect); for the predictor (``OnPredicted``) the switches of σ̂. The plant-side
        switch at sample k and the flight loop's logic switch on the same crossing are d samples apart
        (``Hysteretic(0)`` against ``OnCurrent``).
    plant_set_changes : int
        Number of samples at which the plant's MRP σ was replaced by its shadow (exact): for the plant-side
        rules their switches (= ``switch_count``); for the flight loop and the predictor the bookkeeping that
        keeps σ short, each time the true attitude passes 180° (≠ ``switch_count`` in general: noise makes
        the controller switch without a crossing, hysteresis keeps it from switching on one).
    first_switch_time, last_switch_time : float or None
        Times of the first and last switch (s), None if there was none.
    sign_flips : numpy.ndarray
        (3,) number of sign changes u_i(t_k) u_i(t_{k−1}) < 0 per torque axis.
    max_sigma : float
        max_k |σ(t_k)| over every sample.
    peak_torque : float
        max_k |u_k|_∞ over every sample (N m).
    settling_time : float or None
        First t_k from which the run stays settled to the end: |σ| < tan(Φ_s/4) and |ω| < ω_s, the
        tolerances ``settling_attitude`` Φ_s and ``settling_rate`` ω_s (default |σ| < 1e-2, |ω| < 1e-3 rad/s);
        None if the run does not settle (or diverged).
    diverged : bool
        True when |σ| or |ω| exceeded 1e6 or stopped being finite; the run stopped there
        and the arrays end at the last good sample.
    samples : int
        Samples simulated (n, or up to the diverging one).
    saturated_fraction : float or None
        Flight loop (``rule=Hysteretic(...)``, compiled engine): the fraction of the samples at
        which a torque limit acted; None otherwise.
    peak_command : numpy.ndarray or None
        Flight loop: (4,) max over the run of the *commanded* |u_c,i| per axis and of |u_c|
        (N m), before the actuator limits; None otherwise.
    logic : numpy.ndarray or None
        Flight loop (``rule=Hysteretic(...)``, compiled engine, trajectories kept): (m,) the
        controller's logic variable h_k ∈ {−1, +1} after the rule at each kept sample (the h
        of σ_c,k); None otherwise (other rules, the predictor, ``keep_every=None``, the virtual machine).
    sigma_c : numpy.ndarray or None
        Flight loop: (m, 3) σ_c,k, the MRP the control law used at each kept sample; None otherwise.
    delay_used : numpy.ndarray or None
        Flight loop: (m,) the delay used at each kept sample, k − j*(k) (samples; constant d
        without a time-varying delay, from the newest-arrived schedule with one); None otherwise.
    command : numpy.ndarray or None
        Flight loop: (m, 3) the commanded torque u_c,k = K [σ_c,k; ω̃/4] at each kept sample, before
        the actuator limits (N m); ``u`` is the applied torque (u = u_c bit for bit where no limit
        acted); the predictor: u_c,k = K x̂_k. None otherwise.
    sigma_measured, omega_measured : numpy.ndarray or None
        Flight loop and predictor (compiled engine, trajectories kept): (m, 3) what the controller read at
        each kept sample, the delayed measurement m_{k−d} after the sensor's noise and bias: its attitude
        (the flight loop: in the short set, before the set selection; the predictor: as measured) and its
        rate ω̃ (rad/s). ``sigma``, ``omega`` stay the true state. None otherwise.
    sigma_predicted, omega_predicted : numpy.ndarray or None
        Predictor only: (m, 3) the prediction x̂_k the control law used (σ̂ after its rule, ω̂ in rad/s).
        None otherwise.
    predictor : mrpctl.Predictor or None
        The predictor controller of the run (the flight-loop fields above are then reported too);
        None for the plain delayed law.
    wheels : WheelRecord or None
        A run on a reaction-wheel cluster (``simulate(..., wheels=...)``): the wheel speeds, motor
        torques and wheel metrics; ``u`` is then the body torque of the motors −Gs u_s and
        ``saturated_fraction`` the fraction of samples with a wheel at its torque limit. None otherwise.
    error_time, feedforward : ErrorTime or None, bool or None
        A tracking run's (``reference=``) error convention and feedforward; None for regulation.
    pointing_error : numpy.ndarray or None
        Tracking, trajectories kept: (m,) the true pointing error Φ_B/R = 4 atan|σ_B/R(t_k)| (deg) at each
        kept sample; None otherwise.
    pointing_max, pointing_rms : float or None
        Tracking: the max and the RMS of Φ_B/R (deg) over the kept samples from ``settling_time`` on (the
        settling of the true error σ_B/R, ω_B/R); None when the run did not settle or nothing was kept.
    slew_time : float or None
        Tracking: the first kept t_k from which Φ_B/R < ``pointing_tolerance`` to the end; None if never.
    pointing_tolerance : float or None
        Tracking: the slew time's tolerance (deg).
    settling_attitude : float
        The attitude tolerance of ``settling_time``: a principal angle (deg), default 4 atan(1e-2) = 2.2918°.
    settling_rate : float
        The rate tolerance of ``settling_time`` (rad/s), default 1e-3.
    spacecraft, K, tau, rate, delay_samples, rule, history, substeps, x0, t_final, keep_every
        The inputs of the run.
    """

    t: np.ndarray = field(repr=False)
    sigma: np.ndarray = field(repr=False)
    omega: np.ndarray = field(repr=False)
    u: np.ndarray = field(repr=False)
    switch_indices: np.ndarray = field(repr=False)
    switch_times: np.ndarray = field(repr=False)
    switch_count: int
    first_switch_time: float | None
    last_switch_time: float | None
    sign_flips: np.ndarray = field(repr=False)
    max_sigma: float
    peak_torque: float
    settling_time: float | None
    diverged: bool
    samples: int
    spacecraft: Spacecraft
    K: np.ndarray = field(repr=False)
    tau: float
    rate: float
    delay_samples: int
    rule: SwitchingRule
    history: Any = field(repr=False)
    substeps: int
    x0: np.ndarray = field(repr=False)
    t_final: float
    keep_every: int | None = 1
    saturated_fraction: float | None = None
    peak_command: np.ndarray | None = field(default=None, repr=False)
    predictor: Any = None
    logic: np.ndarray | None = field(default=None, repr=False)
    sigma_c: np.ndarray | None = field(default=None, repr=False)
    delay_used: np.ndarray | None = field(default=None, repr=False)
    command: np.ndarray | None = field(default=None, repr=False)
    wheels: WheelRecord | None = field(default=None, repr=False)
    error_time: Any = None
    feedforward: bool | None = None
    pointing_error: np.ndarray | None = field(default=None, repr=False)
    pointing_max: float | None = None
    pointing_rms: float | None = None
    slew_time: float | None = None
    pointing_tolerance: float | None = None
    plant_set_changes: int = 0
    sigma_measured: np.ndarray | None = field(default=None, repr=False)
    omega_measured: np.ndarray | None = field(default=None, repr=False)
    sigma_predicted: np.ndarray | None = field(default=None, repr=False)
    omega_predicted: np.ndarray | None = field(default=None, repr=False)
    settling_attitude: float = SETTLING_ATTITUDE_DEG
    settling_rate: float = SETTLING_OMEGA

    @property
    def converged(self) -> bool:
        """True when the run settled (within ``settling_attitude`` and ``settling_rate``) and stayed so to the end."""
        return self.settling_time is not None

    @property
    def period(self) -> float:
        """Measurement period h (s)."""
        return 1.0 / self.rate

    @property
    def x(self) -> np.ndarray:
        """(m, 6) states x = [σ; ω/4] of the kept samples."""
        return np.hstack((self.sigma, self.omega / RATE_SCALE))

    @property
    def sigma0(self) -> np.ndarray:
        """(3,) initial MRPs σ₀ (the x0 of the run, physically)."""
        return readonly(state_parts(self.x0)[0])

    @property
    def omega0(self) -> np.ndarray:
        """(3,) initial body rates ω₀ (rad/s)."""
        return readonly(state_parts(self.x0)[1])

    @property
    def gains(self) -> PDGains:
        """The run's K as physical gains: u = −P_σ σ − P_ω ω, P_σ = −K[:, :3] (N m), P_ω = −K[:, 3:] / 4 (N m s)."""
        return PDGains.from_gain(self.K)

    def plot(self, **kwargs: Any) -> Any:
        """Plot the run: [`mrpctl.plots.plot_response`][mrpctl.plots.plot_response] (``kwargs`` passed on)."""
        # deferred: matplotlib (through mrpctl.plots), only when a figure is asked for
        from mrpctl.plots import plot_response

        return plot_response(self, **kwargs)

    def __str__(self) -> str:
        history = self.history if isinstance(self.history, str) else f"array {self.history.shape}"
        if self.diverged:
            status = f"DIVERGED at t = {(self.samples - 1) / self.rate:.3f} s"
        elif self.converged:
            status = f"converged, settling time {self.settling_time:.3f} s"
        else:
            status = "not settled"
        last = "" if self.last_switch_time is None else f", last at {self.last_switch_time:.3f} s"
        first = "" if self.first_switch_time is None else f", first at {self.first_switch_time:.3f} s"
        kept = {1: "every sample", None: "metrics only"}.get(self.keep_every, f"every {self.keep_every}th sample")
        tracking = self.error_time is not None
        return "\n".join(
            (
                f"Simulation {self.t_final:g} s, tau = {self.tau:g} s ({self.delay_samples} samples at "
                f"{self.rate:g} Hz), history {history}, RK4 x{self.substeps}, {kept} kept",
                f"  rule         {self.rule}",
            )
            + (() if self.predictor is None else (f"  predictor    {self.predictor}",))
            + (
                f"  switches     {self.switch_count}{first}{last}",
                f"  sign flips   u1 {self.sign_flips[0]}, u2 {self.sign_flips[1]}, u3 {self.sign_flips[2]}",
                f"  max |sigma|  {self.max_sigma:.6f}" + (" (the tracking error sigma_B/R)" if tracking else ""),
                f"  peak torque  {self.peak_torque:.6g} N m",
            )
            + (
                ()
                if self.saturated_fraction is None or self.peak_command is None
                else (
                    f"  actuator     saturated {100 * self.saturated_fraction:.3g} % of the samples, peak command "
                    f"|u_c| {self.peak_command[3]:.6g} N m",
                )
            )
            + (f"  status       {status}",)
            + (self._tracking_lines() if tracking else ())
        )

    def _tracking_lines(self) -> tuple[str, ...]:
        """The tracking run's convention and pointing figures, in words."""
        time = {"measurement": "measurement's time", "current": "current time"}.get(
            str(getattr(self.error_time, "value", self.error_time)), str(self.error_time)
        )
        lines = [
            f"  tracking     error against the reference at the {time}, feedforward "
            f"{'on' if self.feedforward else 'off'}"
        ]
        if self.pointing_max is not None and self.pointing_rms is not None:
            lines.append(
                f"  pointing     after settling max {self.pointing_max:.4g} deg, RMS {self.pointing_rms:.4g} deg"
            )
        if self.pointing_tolerance is not None:
            slew = "never" if self.slew_time is None else f"{self.slew_time:.3f} s"
            lines.append(f"  slew time    {slew} (pointing error within {self.pointing_tolerance:g} deg from then on)")
        return tuple(lines)


def assemble_run(
    output: RunOutput,
    *,
    n: int,
    keep_every: int | None,
    common: dict[str, Any],
    pointing_tolerance: float | None = None,
) -> SimulationResult:
    """The one place a [`SimulationResult`][mrpctl.SimulationResult] is built from what an engine returned
    (``pointing_tolerance``: a tracking run's, whose records end with the true σ_B/R)."""
    rate = common["rate"]
    metrics = Metrics.from_stats(output.stats)
    valid = metrics.valid_samples(n)
    if keep_every is None or output.measurements is None or output.u is None:
        measurements = np.zeros((0, 6))
        u = np.zeros((0, 3))
        t = np.zeros(0)
    else:
        kept = (valid - 1) // keep_every + 1
        measurements = output.measurements[:kept]
        u = output.u[:kept]
        t = np.arange(0, valid, keep_every) / rate
    indices = output.switch_indices if output.switch_indices is not None else np.zeros(0, np.int64)
    if metrics.diverged:
        settling = None
        logger.info("run diverged at t = %.4f s (|sigma| or |omega| > %g)", (valid - 1) / rate, DIVERGENCE_BOUND)
    else:
        settle_index = metrics.unsettled_index + 1
        settling = settle_index / rate if settle_index < n else None
    first, last = metrics.first_switch_index, metrics.last_switch_index
    flight: dict[str, Any] = {}
    if output.memory is not None and output.memory.size in (FLIGHT_MEMORY_SIZE, PREDICTOR_MEMORY_SIZE):
        flight = dict(saturated_fraction=float(output.memory[5]) / valid, peak_command=readonly(output.memory[6:10]))
    if output.records is not None and output.delay_used is not None and keep_every is not None:
        rows = (valid - 1) // keep_every + 1
        records = output.records[:rows]
        if common.get("predictor") is None:  # the flight sample: (h, σ_c, u_c, σ̃, ω̃)
            flight["logic"] = readonly(records[:, 0])
            flight["sigma_c"] = readonly(records[:, 1:4])
            flight["command"] = readonly(records[:, 4:7])
            flight["sigma_measured"] = readonly(records[:, 7:10])
            flight["omega_measured"] = readonly(records[:, 10:13])
        else:  # the predictor sample: (σ_y, ω_y, σ̂, ω̂, u_c, σ_c)
            flight["sigma_measured"] = readonly(records[:, 0:3])
            flight["omega_measured"] = readonly(records[:, 3:6])
            flight["sigma_predicted"] = readonly(records[:, 6:9])
            flight["omega_predicted"] = readonly(records[:, 9:12])
            flight["command"] = readonly(records[:, 12:15])
            flight["sigma_c"] = readonly(records[:, 15:18])
        flight["delay_used"] = readonly(output.delay_used[:rows], np.int64)
        if pointing_tolerance is not None:
            # the true error σ_B/R at t_k closes a tracking run's record (flight sample and predictor alike)
            pointing = pointing_metrics(output.records[:rows, -3:], t, settling, pointing_tolerance)
            pointing["pointing_error"] = readonly(pointing["pointing_error"])
            flight.update(pointing)
    return SimulationResult(
        t=sealed(t),
        sigma=sealed(measurements[:, 0:3]),
        omega=sealed(RATE_SCALE * measurements[:, 3:6]),
        u=sealed(u),
        switch_indices=readonly(indices, np.int64),
        switch_times=readonly(indices / rate),
        switch_count=metrics.switch_count,
        plant_set_changes=metrics.set_changes,
        first_switch_time=first / rate if first >= 0 else None,
        last_switch_time=last / rate if last >= 0 else None,
        sign_flips=readonly(metrics.sign_flips, np.int64),
        max_sigma=metrics.max_sigma,
        peak_torque=metrics.peak_torque,
        settling_time=settling,
        diverged=metrics.diverged,
        samples=valid,
        keep_every=keep_every,
        **common,
        **flight,
    )


def _same_history(a: Any, b: Any) -> bool:
    if isinstance(a, str) or isinstance(b, str):
        return bool(a == b)
    return bool(np.array_equal(a, b))


#: The per-run arrays of a BatchResult (concatenated along the run axis).
_BATCH_ARRAYS = (
    "x0",
    "K",
    "tau",
    "switch_count",
    "plant_set_changes",
    "first_switch_time",
    "last_switch_time",
    "sign_flips",
    "settling_time",
    "converged",
    "diverged",
    "max_sigma",
    "peak_torque",
)


@dataclass(frozen=True, eq=False)
class BatchResult(_Conversions):
    """Metrics of many closed-loop runs (one entry per run, in input order).

    Attributes
    ----------
    x0 : numpy.ndarray
        (N, 6) initial states.
    K : numpy.ndarray
        (N, 3, 6) gains.
    tau : numpy.ndarray
        (N,) delays (s).
    rules : tuple of SwitchingRule
        The rule of each run.
    spacecraft : tuple of Spacecraft
        The spacecraft of each run.
    switch_count : numpy.ndarray
        (N,) number of switches: what ``switch_count`` of [`SimulationResult`][mrpctl.simulation.SimulationResult]
        counts for the run's rule.
    plant_set_changes : numpy.ndarray
        (N,) changes of the plant's MRP set per run (as in [`SimulationResult`][mrpctl.simulation.SimulationResult]).
    switch_indices : tuple of numpy.ndarray or None
        Per run, the sample indices of its switches (with ``trajectories`` or ``switches=True``; at most 2**20
        per run); None otherwise.
    first_switch_time, last_switch_time : numpy.ndarray
        (N,) times of the first and last switch (s); NaN when a run never switched.
    sign_flips : numpy.ndarray
        (N, 3) torque sign changes per axis.
    settling_time : numpy.ndarray
        (N,) settling time (s), NaN when the run did not settle (tolerances ``settling_attitude``, deg, and
        ``settling_rate``, rad/s, as in [`SimulationResult`][mrpctl.simulation.SimulationResult]).
    converged, diverged : numpy.ndarray
        (N,) booleans.
    max_sigma : numpy.ndarray
        (N,) max |σ| over the run.
    peak_torque : numpy.ndarray
        (N,) max over the run of |u|_∞ (N m).
    saturated_fraction : numpy.ndarray or None
        Flight loop (``rule=Hysteretic(...)``): (N,) fraction of each run's samples at which a
        torque limit acted (NaN for a run of another rule); None when no run is a flight run.
    peak_command : numpy.ndarray or None
        Flight loop: (N, 4) max over each run of the *commanded* |u_c,i| per axis and of |u_c|
        (N m), before the actuator limits (NaN rows for runs of another rule); None otherwise.
    runs : tuple of SimulationResult or None
        The full runs when ``trajectories=True`` was asked for.
    wheels : tuple of WheelRecord or None
        Runs on a wheel cluster (``wheels=...``): each run's `WheelRecord` (its ``speeds`` and
        ``motor_torque`` empty without ``trajectories``); None otherwise.
    rate, t_final, substeps, history
    rate, t_final, substeps, history, settling_attitude, settling_rate
        The shared inputs.
    """

    x0: np.ndarray = field(repr=False)
    K: np.ndarray = field(repr=False)
    tau: np.ndarray = field(repr=False)
    rules: tuple[SwitchingRule, ...] = field(repr=False)
    switch_count: np.ndarray = field(repr=False)
    plant_set_changes: np.ndarray = field(repr=False)
    first_switch_time: np.ndarray = field(repr=False)
    last_switch_time: np.ndarray = field(repr=False)
    sign_flips: np.ndarray = field(repr=False)
    settling_time: np.ndarray = field(repr=False)
    converged: np.ndarray = field(repr=False)
    diverged: np.ndarray = field(repr=False)
    max_sigma: np.ndarray = field(repr=False)
    peak_torque: np.ndarray = field(repr=False)
    rate: float
    t_final: float
    substeps: int
    history: Any = field(repr=False)
    spacecraft: tuple[Spacecraft, ...] = field(default=(), repr=False)
    runs: tuple[SimulationResult, ...] | None = field(default=None, repr=False)
    saturated_fraction: np.ndarray | None = field(default=None, repr=False)
    peak_command: np.ndarray | None = field(default=None, repr=False)
    wheels: tuple[WheelRecord, ...] | None = field(default=None, repr=False)
    settling_attitude: float = SETTLING_ATTITUDE_DEG
    settling_rate: float = SETTLING_OMEGA
    switch_indices: tuple[np.ndarray, ...] | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.switch_count)

    @property
    def sigma0(self) -> np.ndarray:
        """(N, 3) initial MRPs σ₀ of the runs."""
        return readonly(state_parts(self.x0)[0])

    @property
    def omega0(self) -> np.ndarray:
        """(N, 3) initial body rates ω₀ of the runs (rad/s)."""
        return readonly(state_parts(self.x0)[1])

    @property
    def attitude_gain(self) -> np.ndarray:
        """(N, 3, 3) attitude gains P_σ = −K[:, :, :3] of u = −P_σ σ − P_ω ω (N m)."""
        return readonly(gain_parts(self.K)[0])

    @property
    def rate_gain(self) -> np.ndarray:
        """(N, 3, 3) rate gains P_ω = −K[:, :, 3:] / 4 (N m s, on ω in rad/s)."""
        return readonly(gain_parts(self.K)[1])

    @classmethod
    def concatenate(cls, batches: Sequence[BatchResult]) -> BatchResult:
        """One batch of the runs of ``batches`` in order (they must share rate, horizon, substeps, history and the
        settling tolerances).

        Raises
        ------
        SpecificationError
            If ``batches`` is empty or the shared inputs differ.
        """
        if not batches:
            raise SpecificationError("batches: give at least one BatchResult")
        first = batches[0]
        for other in batches[1:]:
            shared = ("rate", "t_final", "substeps", "settling_attitude", "settling_rate")
            same = all(getattr(other, name) == getattr(first, name) for name in shared)
            if not same or not _same_history(other.history, first.history):
                raise SpecificationError(
                    "batches: every batch must share rate, t_final, substeps, history and the settling tolerances "
                    "to be concatenated"
                )
        arrays: dict[str, Any] = {
            name: readonly(np.concatenate([getattr(b, name) for b in batches]), getattr(first, name).dtype)
            for name in _BATCH_ARRAYS
        }
        if all(b.switch_indices is not None for b in batches):
            arrays["switch_indices"] = tuple(one for b in batches for one in (b.switch_indices or ()))
        runs = None
        if all(b.runs is not None for b in batches):
            runs = tuple(run for b in batches for run in (b.runs or ()))
        flight: dict[str, Any] = {}
        if any(b.saturated_fraction is not None for b in batches):  # NaN rows for batches without flight runs
            flight["saturated_fraction"] = readonly(
                np.concatenate([_or_nan(b.saturated_fraction, (len(b),)) for b in batches])
            )
            flight["peak_command"] = readonly(np.concatenate([_or_nan(b.peak_command, (len(b), 4)) for b in batches]))
        wheels = None
        if all(b.wheels is not None for b in batches):
            wheels = tuple(record for b in batches for record in (b.wheels or ()))
        return cls(
            **flight,
            **arrays,
            wheels=wheels,
            rules=tuple(rule for b in batches for rule in b.rules),
            settling_attitude=first.settling_attitude,
            settling_rate=first.settling_rate,
            rate=first.rate,
            t_final=first.t_final,
            substeps=first.substeps,
            history=first.history,
            spacecraft=tuple(sc for b in batches for sc in b.spacecraft),
            runs=runs,
        )

    def plot(self, **kwargs: Any) -> Any:
        """Plot the batch: [`mrpctl.plots.plot_batch`][mrpctl.plots.plot_batch] (``kwargs`` passed on)."""
        # deferred: matplotlib (through mrpctl.plots), only when a figure is asked for
        from mrpctl.plots import plot_batch

        return plot_batch(self, **kwargs)

    def __str__(self) -> str:
        n = len(self)
        switching = self.last_switch_time[np.isfinite(self.last_switch_time)]
        latest = f"{switching.max():.3f} s" if switching.size else "none"
        rules = sorted({str(rule) for rule in self.rules})
        return "\n".join(
            (
                f"Batch of {n} runs over {self.t_final:g} s at {self.rate:g} Hz, "
                f"tau in [{self.tau.min():g}, {self.tau.max():g}] s",
                "  rule         " + "; ".join(rules),
                f"  converged    {int(self.converged.sum())}/{n}, diverged {int(self.diverged.sum())}",
                f"  switches     median {np.median(self.switch_count):g}, max {self.switch_count.max()}, "
                f"latest switch {latest}",
                f"  max |sigma|  {self.max_sigma.max():.6f}",
                f"  peak torque  {self.peak_torque.max():.6g} N m",
            )
        )


def _or_nan(values: np.ndarray | None, shape: tuple[int, ...]) -> np.ndarray:
    return np.full(shape, np.nan) if values is None else values


def assemble_batch(
    stats: np.ndarray,
    *,
    n: int,
    rate: float,
    common: dict[str, Any],
    runs: list[SimulationResult] | None,
    flight_memory: np.ndarray | None = None,
    wheels: tuple[WheelRecord, ...] | None = None,
) -> BatchResult:
    """The [`BatchResult`][mrpctl.BatchResult] from the (N, stats) rows of the runs (and the (N, 10) flight
    memories after the runs: n_sat at 5, peak |u_c,i| at 6:9, peak |u_c| at 9; NaN rows for
    runs of other rules)."""
    metrics = [Metrics.from_stats(row) for row in stats]
    n_runs = len(metrics)
    diverged = np.array([m.diverged for m in metrics], dtype=bool)
    settle = np.array([m.unsettled_index + 1 for m in metrics], dtype=float)
    settled = ~diverged & (settle < n)
    first = np.array([m.first_switch_index for m in metrics], dtype=float)
    last = np.array([m.last_switch_index for m in metrics], dtype=float)
    flight: dict[str, Any] = {}
    if flight_memory is not None:
        valid = np.array([m.valid_samples(n) for m in metrics], dtype=float)  # as assemble_run divides
        flight["saturated_fraction"] = readonly(flight_memory[:, 5] / valid)
        flight["peak_command"] = readonly(flight_memory[:, 6:10])
    return BatchResult(
        **flight,
        switch_count=readonly([m.switch_count for m in metrics], np.int64),
        plant_set_changes=readonly([m.set_changes for m in metrics], np.int64),
        first_switch_time=readonly(np.where(first >= 0, first / rate, np.nan)),
        last_switch_time=readonly(np.where(last >= 0, last / rate, np.nan)),
        sign_flips=readonly([m.sign_flips for m in metrics], np.int64).reshape(n_runs, 3),
        settling_time=readonly(np.where(settled, settle / rate, np.nan)),
        converged=readonly(settled, bool),
        diverged=readonly(diverged, bool),
        max_sigma=readonly([m.max_sigma for m in metrics]),
        peak_torque=readonly([m.peak_torque for m in metrics]),
        rate=rate,
        runs=tuple(runs) if runs is not None else None,
        wheels=wheels,
        **common,
    )


# ====================================================================== labelled data
AXES = [1, 2, 3]
STATE = ["sigma1", "sigma2", "sigma3", "omega1/4", "omega2/4", "omega3/4"]


def rule_fields(rule: Any) -> dict[str, Any]:
    names: dict[type, str] = {cls: name for name, cls in RULE_NAMES.items()}
    if type(rule) not in names:
        raise SpecificationError(f"rule: {type(rule).__name__} has no scenario name; it cannot be saved")
    return {"rule_type": names[type(rule)], "rule_parameter": float(rule.parameters()[0]), "rule": str(rule)}


def _time_or_nan(value: float | None) -> float:
    return np.nan if value is None else float(value)


#: The flight loop's per-sample records of a run (None when absent): name, dimensions, attributes.
FLIGHT_RECORDS: tuple[tuple[str, tuple[str, ...], dict[str, str]], ...] = (
    ("logic", ("time",), {"long_name": "logic variable h after the rule (+1 or -1)"}),
    ("sigma_c", ("time", "axis"), {"units": "1", "long_name": "MRP sigma_c used by the control law"}),
    ("delay_used", ("time",), {"units": "samples", "long_name": "delay used k - j*(k)"}),
    ("command", ("time", "axis"), {"units": "N m", "long_name": "commanded torque u_c before the limits"}),
    ("sigma_measured", ("time", "axis"), {"units": "1", "long_name": "delayed measured MRP read by the controller"}),
    ("omega_measured", ("time", "axis"), {"units": "rad/s", "long_name": "delayed measured rate read by it"}),
    ("sigma_predicted", ("time", "axis"), {"units": "1", "long_name": "predicted MRP used by the control law"}),
    ("omega_predicted", ("time", "axis"), {"units": "rad/s", "long_name": "predicted rate used by the control law"}),
)


#: A run on wheels in its dataset: name -> (dimensions, the field of its `WheelRecord` or, for ``wheel_`` names
#: of the cluster, of its `WheelCluster` (``cluster.<field>``), units). ``wheel`` counts the wheels.
WHEEL_VARIABLES: dict[str, tuple[tuple[str, ...], str, str]] = {
    "wheel_speed": (("time", "wheel"), "speeds", "rad/s"),
    "wheel_motor_torque": (("time", "wheel"), "motor_torque", "N m"),
    "wheel_final_speed": (("wheel",), "final_speeds", "rad/s"),
    "wheel_peak_speed": (("wheel",), "peak_speed", "rad/s"),
    "wheel_torque_limited_time": (("wheel",), "torque_limited_time", "s"),
    "wheel_speed_limited_time": (("wheel",), "speed_limited_time", "s"),
    "wheel_peak_momentum": ((), "peak_momentum", "N m s"),
    "worst_wheel": ((), "worst_wheel", "1"),
    "wheel_spin_axes": (("axis", "wheel"), "cluster.spin_axes", "1"),
    "wheel_spin_inertia": (("wheel",), "cluster.spin_inertia", "kg m^2"),
    "wheel_torque_limit": (("wheel",), "cluster.torque_limit", "N m"),
    "wheel_speed_limit": (("wheel",), "cluster.speed_limit", "rad/s"),
    "wheel_viscous": (("wheel",), "cluster.viscous", "N m s"),
    "wheel_coulomb": (("wheel",), "cluster.coulomb", "N m"),
    "wheel_limit_cycle_speed": (("wheel",), "cluster.limit_cycle_speed", "rad/s"),
    "wheel_initial_speed": (("wheel",), "cluster.speeds", "rad/s"),
    "wheel_bias_speed": (("wheel",), "cluster.bias_speeds", "rad/s"),
    "wheel_control_axes": (("control_axis", "axis"), "cluster.control_axes", "1"),
    "wheel_null_gain": ((), "cluster.null_gain", "1/s"),
    "wheel_gyroscopic": ((), "cluster.gyroscopic", "1"),
}


def _wheel_value(record: WheelRecord, field: str) -> Any:
    owner = record.cluster if field.startswith("cluster.") else record
    value = getattr(owner, field.removeprefix("cluster."))
    return value if isinstance(value, bool | int | float) else np.asarray(value)


def _run_dataset(result: SimulationResult) -> xr.Dataset:
    # deferred: xarray (about 0.5 s to import), only for labelled data
    import xarray as xr  # deferred: xarray takes about 0.5 s to import

    n = len(result.t)
    every = result.keep_every or 1
    indices = np.asarray(result.switch_indices, dtype=np.int64)
    kept = indices[indices % every == 0] // every  # switches that fall on a kept sample
    switched = np.zeros(n, dtype=np.int8)
    switched[kept[kept < n]] = 1
    data: dict[str, Any] = {
        "sigma": (
            ("time", "axis"),
            np.asarray(result.sigma),
            {"units": "1", "long_name": "MRP sigma (after the rule)"},
        ),
        "omega": (("time", "axis"), np.asarray(result.omega), {"units": "rad/s", "long_name": "body rate omega"}),
        "u": (("time", "axis"), np.asarray(result.u), {"units": "N m", "long_name": "torque held over [t_k, t_k+1)"}),
        "switched": (("time",), switched, {"long_name": "1 where sigma was replaced by its shadow (kept samples)"}),
        "switch_index": (("switch",), indices, {"long_name": "sample index k of every recorded switch"}),
        "switch_count": ((), int(result.switch_count), {"long_name": "number of switches (exact)"}),
        "first_switch_time": ((), _time_or_nan(result.first_switch_time), {"units": "s"}),
        "last_switch_time": ((), _time_or_nan(result.last_switch_time), {"units": "s"}),
        "peak_torque": ((), float(result.peak_torque), {"units": "N m", "long_name": "max_k |u_k|_inf"}),
        "samples": ((), int(result.samples), {"long_name": "samples simulated"}),
        "sign_flips": (("axis",), np.asarray(result.sign_flips), {"long_name": "torque sign changes per axis"}),
        "max_sigma": ((), float(result.max_sigma), {"units": "1"}),
        "settling_time": ((), np.nan if result.settling_time is None else float(result.settling_time), {"units": "s"}),
        "diverged": ((), bool(result.diverged)),
        "inertia": (("row", "col"), np.asarray(result.spacecraft.inertia), {"units": "kg m^2"}),
        "K": (("input", "state"), np.asarray(result.K), {"units": "N m", "long_name": "u = K x(t - tau)"}),
        "x0": (("state",), np.asarray(result.x0), {"long_name": "initial state [sigma; omega/4]"}),
        "tau": ((), float(result.tau), {"units": "s"}),
        "rate": ((), float(result.rate), {"units": "Hz"}),
        "delay_samples": ((), int(result.delay_samples)),
        "substeps": ((), int(result.substeps)),
        "t_final": ((), float(result.t_final), {"units": "s"}),
    }
    if result.predictor is not None:
        data["predictor_inertia"] = (
            ("row", "col"),
            np.asarray(result.predictor.model.inertia),
            {
                "units": "kg m^2",
                "long_name": "the predictor's model inertia J_m",
                "predictor_form": result.predictor.form.value,
            },
        )
    if result.saturated_fraction is not None:
        data["saturated_fraction"] = ((), float(result.saturated_fraction), {"long_name": "samples at a torque limit"})
    if result.peak_command is not None:
        data["peak_command"] = (
            ("command",),
            np.asarray(result.peak_command),
            {"units": "N m", "long_name": "max commanded |u_c,i| per axis and |u_c|"},
        )
    for name, dims, attributes in FLIGHT_RECORDS:
        value = getattr(result, name)
        if value is not None:
            data[name] = (dims, np.asarray(value), attributes)
    if result.wheels is not None:  # the wheels' speeds, torques, metrics and the cluster itself
        for name, (dims, source, unit) in WHEEL_VARIABLES.items():
            data[name] = (dims, _wheel_value(result.wheels, source), {"units": unit})
    if (result.settling_attitude, result.settling_rate) != (SETTLING_ATTITUDE_DEG, SETTLING_OMEGA):
        # the tolerances of settling_time, written when they are not the defaults
        data["settling_attitude"] = ((), result.settling_attitude, {"units": "deg", "long_name": "settled below"})
        data["settling_rate"] = ((), result.settling_rate, {"units": "rad/s", "long_name": "settled below"})
    attrs: dict[str, Any] = {
        **rule_fields(result.rule),
        "history": "array",
        "keep_every": "none" if result.keep_every is None else int(result.keep_every),
    }
    if isinstance(result.history, str):
        attrs["history"] = result.history
    else:
        data["history"] = (("history_sample", "state"), np.asarray(result.history))
    coords = {"time": ("time", np.asarray(result.t), {"units": "s"}), "axis": AXES, "state": STATE}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _batch_dataset(result: BatchResult) -> xr.Dataset:
    # deferred: xarray (about 0.5 s to import), only for labelled data
    import xarray as xr  # deferred: xarray takes about 0.5 s to import

    n = len(result)
    x0 = np.asarray(result.x0)
    data: dict[str, Any] = {
        "sigma0": (("run", "axis"), x0[:, :3], {"units": "1"}),
        "omega0": (("run", "axis"), RATE_SCALE * x0[:, 3:], {"units": "rad/s"}),
        "K": (("run", "input", "state"), np.asarray(result.K), {"units": "N m"}),
        "tau": (("run",), np.asarray(result.tau), {"units": "s"}),
        "rule": (("run",), np.array([str(rule) for rule in result.rules], dtype=object)),
        "switch_count": (("run",), np.asarray(result.switch_count)),
        "first_switch_time": (("run",), np.asarray(result.first_switch_time), {"units": "s"}),
        "last_switch_time": (("run",), np.asarray(result.last_switch_time), {"units": "s"}),
        "sign_flips": (("run", "axis"), np.asarray(result.sign_flips)),
        "settling_time": (("run",), np.asarray(result.settling_time), {"units": "s"}),
        "converged": (("run",), np.asarray(result.converged)),
        "diverged": (("run",), np.asarray(result.diverged)),
        "max_sigma": (("run",), np.asarray(result.max_sigma), {"units": "1"}),
    }
    peak = getattr(result, "peak_torque", None)
    if peak is not None:
        data["peak_torque"] = (("run",), np.asarray(peak), {"units": "N m"})
    attrs: dict[str, Any] = {
        "rate": float(result.rate),
        "t_final": float(result.t_final),
        "substeps": int(result.substeps),
        "settling_attitude_deg": float(result.settling_attitude),
        "settling_rate": float(result.settling_rate),
    }
    attrs["history"] = result.history if isinstance(result.history, str) else "array"
    coords = {"run": np.arange(n), "axis": AXES, "state": STATE}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def to_xarray(result: SimulationResult | BatchResult) -> xr.Dataset:
    """The result as an `xarray.Dataset`.

    A run: ``sigma``, ``omega``, ``u`` over (``time`` in s, ``axis`` 1-3), ``switched`` over
    time, the metrics and the inputs (inertia, K, x0, τ, rate, ...) as variables, the rule
    in ``attrs``. A batch: the initial state ``sigma0``, ``omega0`` (rad/s), ``K``, ``tau``,
    the rule and every metric over ``run``.
    """
    if isinstance(result, SimulationResult):
        return _run_dataset(result)
    if isinstance(result, BatchResult):
        return _batch_dataset(result)
    raise SpecificationError(f"result must be a SimulationResult or BatchResult, got {type(result).__name__}")


def to_pandas(result: SimulationResult | BatchResult) -> pd.DataFrame:
    """The result as a `pandas.DataFrame`.

    A run: indexed by ``t`` (s), columns sigma1-3, omega1-3 (rad/s), u1-3 (N m), switched (and,
    for a flight run with records, logic, sigma_c1-3, u_c1-3 (N m, the commanded torque) and
    delay_used (samples)); the inputs in ``DataFrame.attrs``. A batch: indexed by ``run``, columns for the initial
    state, τ, the rule and every metric.
    """
    # deferred: pandas (about 0.3 s to import), only for a DataFrame
    import pandas as pd  # deferred: pandas takes about 0.3 s to import

    if isinstance(result, SimulationResult):
        run = result
        switched = np.zeros(len(run.t), dtype=np.int8)
        switched[run.switch_indices] = 1
        columns: dict[str, Any] = {}
        for name, values in (("sigma", run.sigma), ("omega", run.omega), ("u", run.u)):
            for i in range(3):
                columns[f"{name}{i + 1}"] = np.asarray(values[:, i])
        columns["switched"] = switched
        if run.logic is not None and run.sigma_c is not None and run.command is not None:  # the flight records
            columns["logic"] = np.asarray(run.logic)
            for name, values in (("sigma_c", run.sigma_c), ("u_c", run.command)):
                for i in range(3):
                    columns[f"{name}{i + 1}"] = np.asarray(values[:, i])
        if run.delay_used is not None:
            columns["delay_used"] = np.asarray(run.delay_used)
        frame = pd.DataFrame(columns, index=pd.Index(np.asarray(run.t), name="t"))
        frame.attrs.update(
            inertia=run.spacecraft.inertia.tolist(),
            K=np.asarray(run.K).tolist(),
            x0=np.asarray(run.x0).tolist(),
            tau=run.tau,
            rate=run.rate,
            t_final=run.t_final,
            rule=str(run.rule),
            diverged=run.diverged,
            settling_time=run.settling_time,
        )
        return frame
    if isinstance(result, BatchResult):
        batch = result
        x0 = np.asarray(batch.x0)
        columns = {}
        for i in range(3):
            columns[f"sigma0_{i + 1}"] = x0[:, i]
        for i in range(3):
            columns[f"omega0_{i + 1}"] = RATE_SCALE * x0[:, 3 + i]
        columns["tau"] = np.asarray(batch.tau)
        columns["rule"] = [str(rule) for rule in batch.rules]
        for name in (
            "switch_count",
            "first_switch_time",
            "last_switch_time",
            "settling_time",
            "converged",
            "diverged",
            "max_sigma",
        ):
            columns[name] = np.asarray(getattr(batch, name))
        peak = getattr(batch, "peak_torque", None)
        if peak is not None:
            columns["peak_torque"] = np.asarray(peak)
        for i in range(3):
            columns[f"sign_flips_{i + 1}"] = np.asarray(batch.sign_flips)[:, i]
        frame = pd.DataFrame(columns, index=pd.Index(np.arange(len(batch)), name="run"))
        frame.attrs.update(rate=batch.rate, t_final=batch.t_final, substeps=batch.substeps)
        return frame
    raise SpecificationError(f"result must be a SimulationResult or BatchResult, got {type(result).__name__}")
