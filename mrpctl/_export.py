"""Export the closed loop's CasADi Functions: ``.casadi`` files, C source and header, shared library.

[`export`][mrpctl._export.export] writes one folder for a given spacecraft, gain K, delay τ, measurement
rate and switching rule::

    out_dir/
        dynamics.casadi  controller.casadi  rule.casadi  step.casadi  sample.casadi  chunk.casadi
        mrpctl_model.c   mrpctl_model.h     one C translation unit holding every Function
        libmrpctl_model.so                  gcc -O2 -shared -fPIC (only when a compiler is found)
        manifest.json                       versions, parameters, ports, SHA-256 content hash

The Functions are those of [`mrpctl.loop.closed_loop_functions`][mrpctl.loop.closed_loop_functions], with the
same named ports (x = [σ; ω/4], u in N m; K, J and the rule's parameters are constants
inside them). The ``.casadi`` files keep the plain names (``step``, ``rule``, ...); in the
C code and the shared library every symbol carries the prefix ``mrpctl_``
(``mrpctl_step``, ``mrpctl_step_work``, ``mrpctl_step_SZ_W``, ...; CasADi's own helpers
become ``mrpctl__...``), so the generated code links next to other CasADi code. See
``design/export.md`` for calling the export from C, Python and MATLAB.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os
import shutil
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import casadi as ca

from mrpctl._compile import DEFAULT_FLAGS, CompilerWarning, build_library, compiler_version, find_compiler
from mrpctl._files import file_sha256
from mrpctl._publish import (
    check_folder,
    clean_leftovers,
    folder_path,
    in_place_only,
    publish,
    publish_in_place,
    staging_folder,
    write_file,
)
from mrpctl.clock import delay_samples
from mrpctl.conventions import PDGains, physical_function
from mrpctl.errors import SpecificationError
from mrpctl.flight import ActuatorModel, DelayModel, Hysteretic, SensorModel
from mrpctl.flight.steering import SteeringLaw, check_law
from mrpctl.flight.tracking import ErrorTime
from mrpctl.loop import (
    FLIGHT_MEMORY_LAYOUT,
    PREDICTOR_MEMORY_LAYOUT,
    ClosedLoopFunctions,
    FlightOptions,
    closed_loop_functions,
)
from mrpctl.loop.wheels import wheel_controller_function, wheel_step_function
from mrpctl.model import gain_matrix, wheel_dynamics_expr, wheel_hub_inertia
from mrpctl.predictor import PredictorForm
from mrpctl.provenance import mrpctl_version
from mrpctl.spacecraft import Spacecraft, check_spacecraft
from mrpctl.switching import SwitchingRule
from mrpctl.wheels import WheelCluster

__all__ = [
    "C_PREFIX",
    "EXPORTED_FUNCTIONS",
    "FLIGHT_EXPORTED_FUNCTIONS",
    "HEADER_NAME",
    "LIBRARY_NAME",
    "MANIFEST_NAME",
    "PREDICTOR_EXPORTED_FUNCTIONS",
    "SOURCE_NAME",
    "TRACKING_EXPORTED_FUNCTIONS",
    "WHEEL_EXPORTED_FUNCTIONS",
    "ExportResult",
    "content_hash",
    "export",
    "export_wheel_controller",
]

logger = logging.getLogger(__name__)

#: Prefix of every symbol in the generated C code and the shared library.
C_PREFIX = "mrpctl_"
#: The generated C source and header (one translation unit for all Functions).
SOURCE_NAME = "mrpctl_model.c"
HEADER_NAME = "mrpctl_model.h"
#: The shared library built from `SOURCE_NAME`.
LIBRARY_NAME = "libmrpctl_model.so"
#: The manifest (not covered by the content hash it holds).
MANIFEST_NAME = "manifest.json"
#: Exported Functions, in the order they appear in the C code and the manifest.
EXPORTED_FUNCTIONS = ("dynamics", "controller", "rule", "step", "sample", "chunk")
#: Exported Functions of the loop as flown (rule ``Hysteretic``), in the same sense.
FLIGHT_EXPORTED_FUNCTIONS = ("dynamics", "flight_controller", "sensor", "step", "sample", "chunk")
#: Exported Functions of the tracking loop (``tracking=True``, rule ``Hysteretic``), in the same sense.
TRACKING_EXPORTED_FUNCTIONS = ("dynamics", "tracking_controller", "sensor", "step", "sample", "chunk")
#: Exported Functions of the predictor loop (``predictor=Predictor(...)``, rule ``OnPredicted``).
PREDICTOR_EXPORTED_FUNCTIONS = (
    "dynamics",
    "predictor_controller",
    "prediction",
    "model_step",
    "sensor",
    "step",
    "sample",
    "chunk",
)
#: Exported Functions of the wheel controller ([`export_wheel_controller`][mrpctl._export.export_wheel_controller]).
WHEEL_EXPORTED_FUNCTIONS = ("wheel_controller", "wheel_dynamics", "wheel_step")
#: Version of the manifest layout.
MANIFEST_FORMAT_VERSION = 1

# Code-generation options: the same number types as mrpctl._compile, plus a header and the prefix.
_CODEGEN_OPTIONS: dict[str, Any] = {
    "with_header": True,
    "prefix": C_PREFIX,
    "casadi_real": "double",
    "casadi_int": "long long int",
}

_DESCRIPTIONS = {
    "dynamics": "xdot = A x + B u + f(x): the plant, x = [sigma; omega/4], u in N m",
    "controller": "u = K x_meas (N m)",
    "rule": "shadow-set switching rule at one sample: x_next is x with sigma possibly replaced "
    "by its shadow; x_meas is the delayed measurement m_{k-d} (x itself when d = 0)",
    "step": "x_next = x after one measurement period h = 1/rate, RK4 with `substeps` substeps, u held",
    "sample": "one measurement period: rule, record x_meas = m_k, u = K m_{k-d}, step; "
    "x_delayed is m_{k-d} (unused when d = 0)",
    "chunk": "max(d, 1) samples (mapaccum of sample); history holds the previous chunk's "
    "measurements m_{k-d}, ..., m_{k-1} (oldest first)",
}
# The Functions of the loop as flown (rule Hysteretic): the controller is what flight software runs.
_FLIGHT_DESCRIPTIONS = {
    "dynamics": _DESCRIPTIONS["dynamics"],
    "flight_controller": "the flight software: from the delayed measurement x_meas = [sigma~; omega~/4] and the "
    "controller memory (h, c, sigma~_prev), MRP set selection with hysteresis delta (h flips when h q0 < -delta), "
    "u_command = K [sigma_c; omega~/4] and u = the actuator-limited torque (N m)",
    "sensor": "x_true = x with sigma kept in the short set (bookkeeping, no physical effect); measurement = "
    "[sigma~; omega~/4] of x_true with the attitude error rotation theta = noise[0:3] (rad), rate noise "
    "eta = noise[3:6] (rad/s) and the gyro bias",
    "step": _DESCRIPTIONS["step"],
    "sample": "one measurement period of the flown loop: sensor, flight_controller on x_delayed = the delayed "
    "measurement (m_{k-d}; the sample's own measurement when d = 0), step with u + w; x_meas is the true "
    "(bookkept) state, u the applied torque, switched = 1 when h flipped, measurement the ring entry "
    "[sigma (+) sigma(theta); omega~/4] (the attitude in either set: the controller takes the short set of "
    "x_delayed); memory as in flight.memory_layout",
    "chunk": "max(d, 1) samples (mapaccum of sample); history holds the previous chunk's measurements "
    "m_{k-d}, ..., m_{k-1} (oldest first), noise one column (theta_k; eta_k) per sample",
}
# With a per-sample disturbance the flown sample and chunk take w_k as a last input `torque`.
_TORQUE_DESCRIPTIONS = {
    "sample": _FLIGHT_DESCRIPTIONS["sample"] + "; torque = w_k, the per-sample disturbance (N m, body frame)",
    "chunk": _FLIGHT_DESCRIPTIONS["chunk"] + ", torque one column w_k (N m) per sample",
}

# The tracking loop (tracking=True): the reference rows are inputs, the controller acts on the tracking error.
_TRACKING_DESCRIPTIONS = {
    "tracking_controller": "the flight software of the tracking loop: from the delayed measurement x_meas = "
    "[sigma~_BN; omega~/4] and the reference row of the error time (sigma_RN, omega_RN_N in rad/s, domega_RN_N "
    "in rad/s^2), the tracking error sigma_BR = short(sigma~_BN (+) -sigma_RN), omega_BR = omega~ - [B~N] "
    "omega_RN_N; MRP set selection with hysteresis delta on sigma_BR (memory (h, c, sigma_BR_prev)); "
    "u_command = K [sigma_c; omega_BR/4] (+ omega~ x J omega~ + J([B~N] domega_RN_N - omega~ x [B~N] omega_RN_N) "
    "with feedforward) and u = the actuator-limited torque (N m)",
    "sample": _FLIGHT_DESCRIPTIONS["sample"].replace("flight_controller", "tracking_controller")
    + "; reference = the reference row (9) of t_k (the true error tracking_error = [sigma_BR; omega_BR/4] of "
    "x_meas), reference_error = the row of the controller's error time (tracking.error_time)",
    "chunk": _FLIGHT_DESCRIPTIONS["chunk"] + ", reference and reference_error one column (9) per sample, "
    "tracking_error one column (6) per sample",
}

# The Functions of the predictor loop (predictor=Predictor(...), rule OnPredicted).
_PREDICTOR_DESCRIPTIONS = {
    "dynamics": _DESCRIPTIONS["dynamics"],
    "predictor_controller": "the flight software, once per sample: from the delayed measurement y = [sigma~; "
    "omega~/4] (m_{k-d}), the model copy at the same time z_delayed = z_{k-d}, the copy now z = z_k and the "
    "previous sigma_hat: prediction, u_command = K x_hat, u = the actuator-limited torque (N m), and "
    "z_next = model_step(z, u); the caller keeps z_k and m_k over the last d samples",
    "prediction": "x_hat = the prediction: C_hat = C(tau dw) C(z) C(z_delayed)^T C(y), dw = omega_y - omega_z_delayed, "
    "omega_hat = omega_z + dw (quaternion products), sigma_hat its short MRP, the shadow when nearer sigma_prev "
    "(|sigma_hat|^2 > 1e-8), then the shadow when |sigma_hat| >= alpha (switched = 1)",
    "model_step": "the controller's model copy: one RK4 step of the model inertia J_m over h with the applied "
    "torque u (no disturbance), sigma kept in the short set",
    "sensor": _FLIGHT_DESCRIPTIONS["sensor"],
    "step": _DESCRIPTIONS["step"],
    "sample": "one measurement period of the predictor loop: sensor, predictor_controller on x_delayed = "
    "(m_{k-d}; z_{k-d}) (12; unused when d = 0), step with u + w; x_meas is the true (bookkept) state, u the "
    "applied torque, ring = (m_k; z_k) the next delay-line entry; memory as in predictor.memory_layout",
    "chunk": "max(d, 1) samples (mapaccum of sample); history holds the previous chunk's ring entries "
    "(m_{k-d}; z_{k-d}), ..., oldest first (12 x d), noise one column (theta_k; eta_k) per sample",
}
# With a per-sample disturbance the predictor's sample and chunk take w_k as a last input `torque` (plant only).
_PREDICTOR_TORQUE_DESCRIPTIONS = {
    "sample": _PREDICTOR_DESCRIPTIONS["sample"] + "; torque = w_k, the per-sample disturbance (N m, body frame), "
    "added to u on the plant only (the model copy is driven by u alone)",
    "chunk": _PREDICTOR_DESCRIPTIONS["chunk"] + ", torque one column w_k (N m) per sample",
}


# The manifest's state and ports of export(..., physical=True).
_PHYSICAL_STATE = (
    "sigma (3): MRPs sigma_BN (dimensionless) and omega (3): body rate omega_BN in body components (rad/s), "
    "as separate ports; inside the Functions x = [sigma; omega/4] (the descriptions below use x)"
)
_PHYSICAL_PORTS = {
    "form": "physical",
    "rule": "every port holding states x = [sigma; omega/4] is split into sigma and omega (rad/s) per 6-row "
    "block: x -> sigma, omega; x_<s> -> sigma_<s>, omega_<s>; xdot -> sigma_dot, omega_dot (rad/s^2); "
    "other names -> <name>_sigma, <name>_omega; a second block (the predictor's model copy z in the 12-row "
    "delay-line entries) -> z_sigma..., z_omega... (mrpctl.conventions.physical_port_names)",
    "conversion": "x = [sigma; omega/4] and omega = 4 x[3:6], exact in floating point",
    "unchanged": "the memory vectors (the controller's own layout; the predictor's holds its model copy z = "
    "[sigma; omega/4]), u, noise (theta rad; eta rad/s), torque",
}


# =============================================================================== result
@dataclass(frozen=True)
class ExportResult:
    """What [`export`][mrpctl._export.export] wrote.

    Attributes
    ----------
    folder : pathlib.Path
        The export folder.
    files : tuple of pathlib.Path
        Every file written, the manifest last.
    library : pathlib.Path or None
        The shared library, or None when it was not built.
    skipped_reason : str or None
        Why the shared library was not built (None when it was).
    manifest : dict
        The content of ``manifest.json`` (a copy; the file is the reference).
    """

    folder: Path
    files: tuple[Path, ...] = field(repr=False)
    library: Path | None
    skipped_reason: str | None
    manifest: dict[str, Any] = field(repr=False, compare=False)

    @property
    def compiled(self) -> bool:
        """True when the shared library was built."""
        return self.library is not None

    @property
    def content_hash(self) -> str:
        """SHA-256 over the written files except the manifest (see
        [`content_hash`][mrpctl._export.ExportResult.content_hash])."""
        return self.manifest["content_hash"]["value"]

    def __str__(self) -> str:
        parameters = self.manifest["parameters"]
        names = ", ".join(self.manifest["functions"])
        library = LIBRARY_NAME if self.library is not None else f"not built: {self.skipped_reason}"
        flight = self.manifest.get("flight")
        models = []
        if flight is not None:
            models = [key for key in ("actuator", "disturbance", "sensor", "delay") if flight[key] is not None]
        flown = [] if flight is None else [f"  flight     the loop as flown; models: {', '.join(models) or 'none'}"]
        return "\n".join(
            (
                f"CasADi export in {self.folder}",
                f"  loop       tau = {parameters['tau']:g} s = {parameters['delay_samples']} samples at "
                f"{parameters['rate']:g} Hz, rule {parameters['rule']['str']}",
                *flown,
                f"  Functions  {names} (.casadi; C symbols {C_PREFIX}<name>)",
                f"  C code     {SOURCE_NAME}, {HEADER_NAME}",
                f"  library    {library}",
                f"  manifest   {MANIFEST_NAME}, content sha256 {self.content_hash[:16]}...",
            )
        )


# =============================================================================== export
def export(
    spacecraft: Spacecraft,
    K: Any,
    out_dir: str | os.PathLike[str],
    *,
    tau: float,
    rule: SwitchingRule,
    rate: float = 1000.0,
    substeps: int = 1,
    actuator: ActuatorModel | None = None,
    disturbance: Any = None,
    sensor: SensorModel | None = None,
    delay: DelayModel | None = None,
    predictor: Any = None,
    overwrite: bool = False,
    compile: bool = True,
    tracking: bool = False,
    error_time: ErrorTime = ErrorTime.MEASUREMENT,
    feedforward: bool = False,
    physical: bool = False,
) -> ExportResult:
    """Write the closed loop's CasADi Functions to ``out_dir`` as ``.casadi`` files, C code and a library.

    Everything is written into a temporary sibling folder first, which then replaces
    ``out_dir`` in one rename (the old folder is renamed aside first and removed last): an
    error or Ctrl-C at any point leaves ``out_dir`` as it was, and never half an export.

    Parameters
    ----------
    spacecraft : Spacecraft
        The plant (inertia J in kg m²).
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m): u = K x(t − τ).
    out_dir : path-like
        The export folder; created (with its parents) if missing. It must be empty or
        missing unless ``overwrite`` is true.
    tau : float, keyword-only
        Delay τ (s), a whole number d of measurement periods 1/rate.
    rule : SwitchingRule, keyword-only
        The shadow-set switching rule, e.g. ``OnDelayed()``, or the controller-side
        [`Hysteretic`][mrpctl.flight.Hysteretic]: then the loop as flown is exported
        (`FLIGHT_EXPORTED_FUNCTIONS`, with ``flight_controller`` for flight software).
    rate : float, keyword-only
        Measurement rate (Hz), default 1000; ``step`` integrates over h = 1/rate.
    substeps : int, keyword-only
        RK4 substeps per measurement period in ``step``, default 1.
    actuator, disturbance, sensor, delay : keyword-only
        The flight loop's models (``rule=Hysteretic(...)`` only), as in [`mrpctl.simulate`][mrpctl.simulation.simulate]:
        torque limits and saturation mode, a disturbance torque (N m; constant: bound into the
        Functions; per sample, (n, 3) rows or ``Disturbance(function=w)``: the ``torque`` input
        w_k of ``sample`` (3) and ``chunk`` (3 × max(d, 1)), named in the manifest), the sensor's
        gyro bias (a constant of the Functions; its noise is the ``noise`` input of ``sample``
        and ``chunk``) and a time-varying delay (recorded in the manifest). Each is listed in
        the manifest's ``flight`` section.
    predictor : mrpctl.Predictor, keyword-only
        Export the predictor loop (with ``rule=OnPredicted(alpha)``; actuator, disturbance and sensor
        allowed): `PREDICTOR_EXPORTED_FUNCTIONS`, with ``predictor_controller`` (and its pieces
        ``prediction`` and ``model_step``) for flight software, and a ``predictor`` section in the
        manifest (model inertia, τ, α, the memory and delay-line layouts). A per-sample disturbance
        is the ``torque`` input of ``sample`` and ``chunk`` here too (plant only; named in
        ``predictor.disturbance``).
    tracking, error_time, feedforward : keyword-only
        Export the tracking loop (``rule=Hysteretic(...)``; ``design/tracking.md``):
        `TRACKING_EXPORTED_FUNCTIONS`, with ``tracking_controller`` for flight software, the reference ports
        ``reference`` / ``reference_error`` of ``sample`` and ``chunk``, and a ``tracking`` section in the
        manifest naming the ports, the row layout and the error convention ``error_time`` (which row the caller
        feeds as ``reference_error``); ``feedforward`` adds the feedforward terms.
    overwrite : bool, keyword-only
        Allow a non-empty ``out_dir``: the previous export in it (the names listed in the
        module docstring) is replaced as a whole, a library that is not rebuilt disappears,
        and other files and folders in it are carried over into the new folder unchanged.
        Default False.
    compile : bool, keyword-only
        Build the shared library when a C compiler is found (default True).
    physical : bool, keyword-only
        Give every Function state ports in physical units: each port that carries x = [σ; ω/4]
        (``x``, ``x_meas``, ``x_next``, ``history``, ...) becomes two, σ (3 rows) and ω (3 rows,
        rad/s), named by [`mrpctl.conventions.physical_port_names`][mrpctl.conventions.physical_port_names]
        (``sigma``, ``omega``, ``sigma_meas``, ``omega_meas``, ``history_sigma``, ...); the other ports and
        the Function names stay ([`mrpctl.conventions.physical_function`][mrpctl.conventions.physical_function]:
        bit for bit the default export on the converted values). The manifest's ``ports`` says which form.
        Default False: the paper's x = [σ; ω/4].

    Returns
    -------
    ExportResult
        The folder, the files, the library (or None and the reason) and the manifest.

    Raises
    ------
    SpecificationError, DimensionError
        On invalid loop parameters, or when ``out_dir`` is a non-empty folder and
        ``overwrite`` is false, or is an existing file.
    CodegenError
        When ``out_dir`` cannot be created or written, ``$CC`` names no compiler, or the
        compiler fails or times out.

    Warns
    -----
    CompilerWarning
        When ``compile`` is true but no C compiler is found: every other file is
        written and the library is skipped.
    """
    overwrite = _flag("overwrite", overwrite)
    compile = _flag("compile", compile)
    physical = _flag("physical", physical)
    closed = closed_loop_functions(
        spacecraft,
        K,
        tau=tau,
        rule=rule,
        rate=rate,
        substeps=substeps,
        actuator=actuator,
        disturbance=disturbance,
        sensor=sensor,
        delay=delay,
        predictor=predictor,
        tracking=tracking,
        error_time=error_time,
        feedforward=feedforward,
    )

    def functions() -> dict[str, ca.Function]:
        made = closed.functions()
        if physical:
            return {name: physical_function(function) for name, function in made.items()}
        return made

    def manifest(staging: Path, made: dict[str, ca.Function], names: list[str], compiler: str | None,
                 reason: str | None) -> dict[str, Any]:  # fmt: skip
        return _manifest(closed, made, staging, names, compiler, reason)

    result = _write_export(out_dir, overwrite, compile, functions, manifest)
    logger.info("exported %d Functions to %s", sum(path.suffix == ".casadi" for path in result.files), result.folder)
    return result


_WHEEL_DESCRIPTIONS = {
    "wheel_controller": "the flight software of the wheel loop: from the delayed measurement x_meas = [sigma~; "
    "omega~/4], the controller memory (h, c, sigma~_prev) and the wheel speeds Omega_k (rad/s): MRP set selection "
    "with hysteresis delta, u_command = K [sigma_c; omega~/4] (+ the gyroscopic term when set), motor = the wheel "
    "motor torques u_s (N m): minimum-norm allocation over the control axes (+ null-space term), each clipped to "
    "its u_max and 0 when |Omega_i| >= Omega_max,i and Omega_i u_i >= 0; body = -Gs u_s (N m)",
    "wheel_dynamics": "xdot (6) and speeds_dot (N) of the spacecraft and its wheels: x = [sigma; omega/4], speeds "
    "Omega (rad/s), motor u_s (N m), w the external torque (N m)",
    "wheel_step": "x_next, speeds_next after one measurement period h = 1/rate, RK4 with `substeps` substeps, "
    "motor torques and w held",
}


def _steering_manifest(law: SteeringLaw) -> dict[str, Any]:
    """The steering law's numbers in the wheel controller's manifest (the ``[steering]`` keys)."""
    return {
        "rate_limit": law.rate_limit,
        "acceleration": law.acceleration,
        "lag": law.lag,
        "momentum_limit": law.momentum_limit,
        "momentum_inertia": None if law.spacecraft is None else law.spacecraft.inertia.tolist(),
        "command": "u_c = K_omega omega/4 + s K_sigma sigma_c, s = min(1, L(phi)/|omega_lin|, h/|J omega_lin|)",
    }


def export_wheel_controller(
    spacecraft: Spacecraft,
    K: Any,
    wheels: WheelCluster,
    out_dir: str | os.PathLike[str],
    *,
    tau: float,
    rule: Hysteretic | None = None,
    rate: float = 1000.0,
    substeps: int = 1,
    overwrite: bool = False,
    compile: bool = True,
    law: SteeringLaw | None = None,
) -> ExportResult:
    """Write the wheel loop's controller with its allocation (wheel torques out), its dynamics and its step.

    `WHEEL_EXPORTED_FUNCTIONS` as ``.casadi`` files, one C translation unit (symbols ``mrpctl_<name>``),
    the shared library (when a compiler is found) and ``manifest.json`` (with a ``wheels`` section), written
    as [`export`][mrpctl._export.export] writes (a staging folder, then one rename). K, J, δ and the wheel
    cluster are constants of the Functions: ``wheel_controller(x_meas, memory, speeds) -> (motor, body,
    memory_next, command, torque_limited, speed_limited)`` is what flight software runs once per sample
    (``design/wheels.md``).

    Parameters
    ----------
    spacecraft : Spacecraft
        The whole spacecraft's inertia J (kg m², wheels included).
    K : array_like
        (3, 6) gain on x = [σ; ω/4] (N m).
    wheels : WheelCluster
        The wheels, the allocation's control axes and options.
    out_dir : path-like
        The export folder (empty or missing unless ``overwrite``).
    tau : float, keyword-only
        Delay τ (s), a whole number of periods (recorded in the manifest).
    rule : Hysteretic, keyword-only
        The controller-side rule (default ``Hysteretic(0)``).
    rate, substeps, overwrite, compile : keyword-only
        As in [`export`][mrpctl._export.export].
    law : SteeringLaw, keyword-only
        The steering law the controller computes its body torque request with (its numbers compiled in, recorded
        in the manifest's ``parameters.steering``; ``command`` is its u_c), as the simulated wheel loop with
        ``simulate(..., wheels=..., law=...)``. None (default): the PD law.
    """
    overwrite = _flag("overwrite", overwrite)
    compile = _flag("compile", compile)
    spacecraft = check_spacecraft(spacecraft)
    gain = gain_matrix(K)
    if not isinstance(wheels, WheelCluster):
        raise SpecificationError(f"wheels must be a mrpctl.wheels.WheelCluster, got {type(wheels).__name__}")
    rule = Hysteretic(0.0) if rule is None else rule
    if not isinstance(rule, Hysteretic):
        raise SpecificationError(f"rule: the wheel controller takes Hysteretic(delta), got {type(rule).__name__}")
    wheel_hub_inertia(spacecraft, wheels)
    law = check_law(law, (rule,), gain)
    d = delay_samples(tau, rate)
    period = 1.0 / float(rate)
    controller = wheel_controller_function(spacecraft, wheels, law=law)
    x_meas, memory = ca.SX.sym("x_meas", 6), ca.SX.sym("memory", 5)
    speeds = ca.SX.sym("speeds", wheels.count)
    outputs = controller(x_meas, memory, speeds, ca.DM(gain), ca.DM(list(rule.parameters())))
    bound = ca.Function(
        "wheel_controller", [x_meas, memory, speeds], list(outputs), ["x_meas", "memory", "speeds"],
        controller.name_out(),
    )  # fmt: skip
    x, motor, w = ca.SX.sym("x", 6), ca.SX.sym("motor", wheels.count), ca.SX.sym("w", 3)
    xdot, speeds_dot = wheel_dynamics_expr(spacecraft, wheels, x, speeds, motor, w)
    functions = {
        "wheel_controller": bound,
        "wheel_dynamics": ca.Function(
            "wheel_dynamics", [x, speeds, motor, w], [xdot, speeds_dot], ["x", "speeds", "motor", "w"],
            ["xdot", "speeds_dot"],
        ),
        "wheel_step": wheel_step_function(spacecraft, wheels, period, substeps),
    }  # fmt: skip

    def manifest(staging: Path, made: dict[str, ca.Function], names: list[str], compiler: str | None,
                 reason: str | None) -> dict[str, Any]:  # fmt: skip
        return {
            "format": "mrpctl-export",
            "format_version": MANIFEST_FORMAT_VERSION,
            "mrpctl_version": mrpctl_version(),
            "casadi_version": vars(ca)["__version__"],
            "state": "x = [sigma; omega/4] (6) and the wheel speeds Omega (N, rad/s, relative to the body)",
            "input": "motor (N): wheel motor torques (N m); the body receives -Gs motor",
            "parameters": {
                "tau": float(tau),
                "rate": float(rate),
                "period": period,
                "delay_samples": d,
                "substeps": substeps,
                "K": gain.tolist(),
                "J": spacecraft.inertia.tolist(),
                "rule": {"class": "Hysteretic", "str": str(rule), "parameters": list(rule.parameters())},
                "initial_memory": [1.0, 1.0, "short(sigma) of the first measurement the controller sees"],
                **({} if law is None else {"steering": _steering_manifest(law)}),
            },
            "wheels": {
                "count": wheels.count,
                "spin_axes": wheels.spin_axes.tolist(),
                "spin_inertia": wheels.spin_inertia.tolist(),
                "torque_limit": wheels.torque_limit.tolist(),
                "speed_limit": wheels.speed_limit.tolist(),
                "viscous": wheels.viscous.tolist(),
                "coulomb": wheels.coulomb.tolist(),
                "limit_cycle_speed": wheels.limit_cycle_speed.tolist(),
                "control_axes": wheels.control_axes.tolist(),
                "null_gain": wheels.null_gain,
                "bias_speeds": wheels.bias_speeds.tolist(),
                "gyroscopic": wheels.gyroscopic,
            },
            "functions": {
                name: {
                    "file": f"{name}.casadi",
                    "c_symbol": C_PREFIX + name,
                    "description": _WHEEL_DESCRIPTIONS[name],
                    "inputs": _ports(function, True),
                    "outputs": _ports(function, False),
                }
                for name, function in functions.items()
            },
            "c": {
                "source": SOURCE_NAME,
                "header": HEADER_NAME,
                "symbol_prefix": C_PREFIX,
                "library": LIBRARY_NAME if compiler is not None else None,
                "library_skipped_reason": reason,
                "compiler": _compiler_description(compiler) if compiler is not None else None,
                "flags": [*DEFAULT_FLAGS, "-lm"],
            },
            "files": {name: file_sha256(staging / name) for name in sorted(names)},
            "content_hash": {
                "algorithm": "sha256",
                "covers": "every file listed in 'files' (all written files except manifest.json)",
                "value": content_hash(staging, names),
            },
        }

    return _write_export(out_dir, overwrite, compile, lambda: functions, manifest)


def _write_export(
    out_dir: Any,
    overwrite: bool,
    compile: bool,
    functions: Callable[[], dict[str, ca.Function]],
    manifest: Callable[[Path, dict[str, ca.Function], list[str], str | None, str | None], dict[str, Any]],
) -> ExportResult:
    """Write ``functions()`` (.casadi files, their C code, the library when ``compile``) and the ``manifest`` into a
    private staging folder beside ``out_dir`` and publish it whole (`mrpctl._publish`); the folder is checked (and
    a killed export's leftovers cleaned) before ``functions`` is called."""
    folder = folder_path(out_dir)
    target = Path(os.path.realpath(folder))  # a symbolic link stays, its target is replaced
    clean_leftovers(target)  # first: it may put back a folder that a killed export had moved aside
    check_folder(folder, overwrite)
    made = functions()
    ours = frozenset(_export_names())
    in_place = in_place_only(target)
    staging = staging_folder(target, in_place)
    try:
        names: list[str] = []
        for name, function in made.items():
            path = staging / f"{name}.casadi"
            write_file(path, lambda path=path, function=function: function.save(str(path)))
            names.append(path.name)
        names += _write_c_code(staging, made)
        compiler, reason = _build_library(staging, compile)
        if compiler is not None:
            names.append(LIBRARY_NAME)
        written = manifest(staging, made, names, compiler, reason)
        manifest_path = staging / MANIFEST_NAME
        write_file(manifest_path, lambda: manifest_path.write_text(json.dumps(written, indent=2) + "\n"))
        names.append(MANIFEST_NAME)
        if in_place:
            publish_in_place(staging, target, names, ours, MANIFEST_NAME)
        else:
            publish(staging, target, ours)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return ExportResult(
        folder=folder,
        files=tuple(folder / name for name in names),
        library=folder / LIBRARY_NAME if compiler is not None else None,
        skipped_reason=reason,
        manifest=written,
    )


def content_hash(folder: str | os.PathLike[str], names: Any) -> str:
    """SHA-256 of the files ``names`` in ``folder``, as the manifest's ``content_hash``.

    The hash of the text ``sha256sum`` prints for the files in byte-wise sorted name
    order (one line ``<hex digest>  <name>`` per file), so that in a shell
    ``cd folder && sha256sum $(LC_ALL=C ls | grep -vx manifest.json) | sha256sum``
    gives the same value.
    """
    folder = Path(folder)
    lines = [f"{file_sha256(folder / name)}  {name}\n" for name in sorted(names)]
    return hashlib.sha256("".join(lines).encode()).hexdigest()


# ============================================================================== helpers
def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise SpecificationError(f"{name} must be True or False, got {value!r}")
    return value


def _export_names() -> tuple[str, ...]:
    every = (
        EXPORTED_FUNCTIONS
        + FLIGHT_EXPORTED_FUNCTIONS
        + PREDICTOR_EXPORTED_FUNCTIONS
        + WHEEL_EXPORTED_FUNCTIONS
        + TRACKING_EXPORTED_FUNCTIONS
    )
    names = [f"{name}.casadi" for name in dict.fromkeys(every)]
    return (*names, SOURCE_NAME, HEADER_NAME, LIBRARY_NAME, MANIFEST_NAME)


def _write_c_code(folder: Path, functions: Mapping[str, ca.Function]) -> list[str]:
    """One .c/.h pair; each Function is wrapped under the name ``mrpctl_<name>`` (same arithmetic)."""
    generator = ca.CodeGenerator(SOURCE_NAME, _CODEGEN_OPTIONS)
    for name, function in functions.items():
        symbols = function.mx_in()
        generator.add(
            ca.Function(C_PREFIX + name, symbols, function.call(symbols), function.name_in(), function.name_out())
        )
    write_file(folder / SOURCE_NAME, lambda: generator.generate(str(folder) + os.sep))
    return [SOURCE_NAME, HEADER_NAME]


def _build_library(folder: Path, compile: bool) -> tuple[str | None, str | None]:
    """Compile the C source into the shared library: (compiler, None), or (None, reason) when skipped."""
    if not compile:
        return None, "compile=False was given"
    compiler = find_compiler()
    if compiler is None:
        reason = (
            f"no C compiler found ($CC, gcc, cc): {LIBRARY_NAME} was not built; the .casadi files and "
            f"the C source {SOURCE_NAME}/{HEADER_NAME} were written (compile them with "
            f"gcc {' '.join(DEFAULT_FLAGS)} {SOURCE_NAME} -o {LIBRARY_NAME} -lm)"
        )
        warnings.warn(reason, CompilerWarning, stacklevel=3)
        return None, reason
    build_library(folder / SOURCE_NAME, folder / LIBRARY_NAME, compiler=compiler, flags=DEFAULT_FLAGS)
    return compiler, None


def _compiler_description(compiler: str) -> dict[str, Any]:
    return {"path": compiler, "version": compiler_version(compiler)}


def _ports(function: ca.Function, inputs: bool) -> list[dict[str, Any]]:
    count = function.n_in() if inputs else function.n_out()
    ports = []
    for i in range(count):
        name = function.name_in(i) if inputs else function.name_out(i)
        rows, columns = function.size_in(i) if inputs else function.size_out(i)
        ports.append({"name": name, "shape": [int(rows), int(columns)]})
    return ports


def _manifest(
    closed: ClosedLoopFunctions,
    functions: Mapping[str, ca.Function],
    folder: Path,
    names: list[str],
    compiler: str | None,
    reason: str | None,
) -> dict[str, Any]:
    rule = closed.rule
    descriptions = _DESCRIPTIONS if closed.flight is None else _FLIGHT_DESCRIPTIONS
    if closed.predictor is not None:
        descriptions = _PREDICTOR_DESCRIPTIONS
        if "torque" in functions["sample"].name_in():
            descriptions = {**_PREDICTOR_DESCRIPTIONS, **_PREDICTOR_TORQUE_DESCRIPTIONS}
    elif "torque" in functions["sample"].name_in():
        descriptions = {**_FLIGHT_DESCRIPTIONS, **_TORQUE_DESCRIPTIONS}
    if closed.tracking is not None:
        descriptions = {**descriptions, **_TRACKING_DESCRIPTIONS}
        if "torque" in functions["sample"].name_in():
            descriptions["sample"] += "; torque = w_k, the per-sample disturbance (N m, body frame)"
            descriptions["chunk"] += ", torque one column w_k (N m) per sample"
    manifest: dict[str, Any] = {
        "format": "mrpctl-export",
        "format_version": MANIFEST_FORMAT_VERSION,
        "mrpctl_version": mrpctl_version(),
        "casadi_version": vars(ca)["__version__"],
        "state": "x = [sigma; omega/4] (6): MRPs sigma (dimensionless), body rate omega (rad/s)",
        "input": "u (3): control torque (N m), u = K x_meas",
        "parameters": {
            "tau": closed.tau,
            "rate": closed.rate,
            "period": closed.period,
            "delay_samples": closed.delay_samples,
            "substeps": closed.substeps,
            "K": closed.K.tolist(),
            "J": closed.spacecraft.inertia.tolist(),
            "rule": {
                "class": type(rule).__name__,
                "label": rule.label,
                "str": str(rule),
                "parameters": list(rule.parameters()),
            },
            "initial_memory": closed.initial_memory if closed.flight is None else None,
        },
        "functions": {
            name: {
                "file": f"{name}.casadi",
                "c_symbol": C_PREFIX + name,
                "description": descriptions[name],
                "inputs": _ports(function, True),
                "outputs": _ports(function, False),
            }
            for name, function in functions.items()
        },
        "c": {
            "source": SOURCE_NAME,
            "header": HEADER_NAME,
            "symbol_prefix": C_PREFIX,
            "casadi_real": _CODEGEN_OPTIONS["casadi_real"],
            "casadi_int": _CODEGEN_OPTIONS["casadi_int"],
            "library": LIBRARY_NAME if compiler is not None else None,
            "library_skipped_reason": reason,
            "compiler": _compiler_description(compiler) if compiler is not None else None,
            "flags": [*DEFAULT_FLAGS, "-lm"],
        },
        "files": {name: file_sha256(folder / name) for name in sorted(names)},
        "content_hash": {
            "algorithm": "sha256",
            "covers": "every file listed in 'files' (all written files except manifest.json)",
            "value": content_hash(folder, names),
        },
    }
    if closed.predictor is not None:
        manifest["predictor"] = _predictor_manifest(closed)
    elif closed.flight is not None:
        manifest["flight"] = _flight_manifest(closed, closed.flight)
    if closed.tracking is not None:
        manifest["tracking"] = _tracking_manifest(closed.tracking)
    if "sigma" in functions["step"].name_in():  # export(..., physical=True)
        manifest["state"] = _PHYSICAL_STATE
        manifest["ports"] = _PHYSICAL_PORTS
        gains = PDGains.from_gain(closed.K)
        manifest["parameters"]["attitude_gain"] = gains.attitude.tolist()  # N m
        manifest["parameters"]["rate_gain"] = gains.rate.tolist()  # N m s
        manifest["parameters"]["gain_law"] = (
            "u = -attitude_gain sigma - rate_gain omega = K x (K = [-P_sigma, -4 P_omega])"
        )
    return manifest


def _tracking_manifest(tracking: dict[str, Any]) -> dict[str, Any]:
    """The manifest's ``tracking`` section: the reference ports, the row layout and the error convention."""
    error_time = tracking["error_time"]
    return {
        "reference_ports": {
            "sample": ["reference", "reference_error"],
            "chunk": ["reference", "reference_error"],
            "tracking_controller": ["reference"],
        },
        "reference_row": "sigma_RN (3, MRP, short set), omega_RN_N (3, rad/s, inertial components), "
        "domega_RN_N (3, rad/s^2, inertial components): Basilisk's AttRefMsgPayload",
        "error_time": error_time.value,
        "error_time_meaning": (
            "reference_error (and the tracking_controller's reference) is the row of the measurement's time "
            "t_(k-d) (row 0 before t = 0)"
            if error_time is ErrorTime.MEASUREMENT
            else "reference_error (and the tracking_controller's reference) is the row of the current time t_k"
        ),
        "feedforward": tracking["feedforward"],
        "outputs": "tracking_error = [sigma_BR; omega_BR/4] of the true state against the row of t_k; "
        "tracking_controller's sigma_br = the controller's tracking error (short set)",
        "memory": "flight.memory_layout with sigma_prev = the previous sigma_BR",
    }


def _predictor_manifest(closed: ClosedLoopFunctions) -> dict[str, Any]:
    """The manifest's ``predictor`` section: the model, τ, α, the flight models and the layouts."""
    predictor = closed.predictor
    flight = closed.flight
    assert flight is not None
    actuator, disturbance, sensor = flight.actuator, flight.disturbance, flight.sensor
    constants = [float(value) for value in flight.constants]
    alpha = float(closed.rule.parameters()[0])
    return {
        "form": (
            "linear: the linearised model's exact ZOH copy (never shortened) and the FSA increment composed on the "
            "rotation group by its Pade MRP (design/predictor.md, the linear form)"
            if predictor.form is PredictorForm.LINEAR
            else "model copy with the error composed on the rotation group (design/predictor.md, form (b))"
        ),
        "form_name": predictor.form.value,
        "model_inertia": predictor.model.inertia.tolist(),
        "tau": closed.tau,
        "alpha": None if math.isinf(alpha) else alpha,
        "rule": "sigma_hat in the set nearest the previous sigma_hat, then its shadow when |sigma_hat| >= alpha "
        "(null: never)",
        "actuator": _actuator_manifest(actuator),
        "disturbance": _disturbance_manifest(disturbance),
        "sensor": _sensor_manifest(sensor),
        "constants": {
            "u_max": [_limit(value) for value in constants[0:3]],
            "u_norm": _limit(constants[3]),
            "disturbance": constants[4:7],
            "gyro_bias": constants[7:10],
            "note": "bound into the Functions (null: no limit)",
        },
        "memory_layout": {"sample": list(PREDICTOR_MEMORY_LAYOUT)},
        "delay_line": "entries (m_k; z_k) of 12: the sensor's measurement and the model copy at sample k; "
        "x_delayed of sample k is entry k - d",
        "initial_memory": "unused = 1, sigma_hat_prev = z_0 = x0 with sigma in the short set, accumulators 0 "
        "(mrpctl.loop.options.predictor_memory)",
        "history": "entries for k < d: (x0; x0) (the constant history, the only one with a predictor): x_hat = z_k",
    }


def _limit(value: float) -> float | None:
    """A limit for JSON: None for no limit (inf), which JSON cannot hold."""
    return None if math.isinf(value) else float(value)


def _actuator_manifest(actuator: ActuatorModel | None) -> dict[str, Any] | None:
    """The manifest's description of the torque limits (None: no actuator model)."""
    if actuator is None:
        return None
    return {
        "u_max": [float(value) for value in actuator.u_max],
        "norm_max": actuator.norm_max,
        "saturation": actuator.mode.value,
    }


def _sensor_manifest(sensor: SensorModel | None, noise: str | None = None) -> dict[str, Any] | None:
    """The manifest's description of the sensor (None: ideal), with the meaning of the noise input if any."""
    if sensor is None:
        return None
    out: dict[str, Any] = {
        "attitude_noise": sensor.attitude_noise,
        "rate_noise": sensor.rate_noise,
        "gyro_bias": [float(b) for b in sensor.gyro_bias],
        "seed": sensor.seed,
    }
    if noise is not None:
        out["noise"] = noise
    return out


def _flight_manifest(closed: ClosedLoopFunctions, flight: FlightOptions) -> dict[str, Any]:
    """The manifest's ``flight`` section: the models, the bound constants and the memory layouts."""
    rule = closed.rule
    actuator, disturbance, sensor, delay = flight.actuator, flight.disturbance, flight.sensor, flight.delay
    constants = [float(value) for value in flight.constants]
    return {
        "rule": {
            "delta": float(rule.parameters()[0]),
            "alpha": float(getattr(rule, "alpha", 1.0)),
            "law": "h <- -h when h q0 < -delta on the delayed measured quaternion (sign kept continuous by c); "
            "sigma_c = sigma~ when h c = +1, else its shadow; |sigma_c| <= alpha",
        },
        "actuator": _actuator_manifest(actuator),
        "saturation": flight.saturation.value,
        "disturbance": _disturbance_manifest(disturbance),
        "sensor": _sensor_manifest(
            sensor,
            noise="the noise input of sample/chunk: (theta_k; eta_k) = mrpctl.flight.SensorModel(...).noise(k0, k1) "
            "(counter-based: SplitMix64 values of (seed, stream, 3k + component) and a 256-layer ziggurat, "
            "mrpctl/engines/noise.c)",
        ),
        "delay": None
        if delay is None
        else {
            "kind": delay.kind.value,
            "tau_min": delay.tau_min,
            "tau_max": delay.tau_max,
            "samples": list(delay.bounds(closed.rate)),
            "seed": delay.seed,
            "sequence_length": None if delay.delays is None else len(delay.delays),
            "schedule": "x_delayed of sample k is the newest measurement that has arrived, m_j* with "
            "j*(k) = max{j : j + d_j <= k} (mrpctl.flight.newest_arrived)",
        },
        "constants": {
            "u_max": [_limit(value) for value in constants[0:3]],
            "u_norm": _limit(constants[3]),
            "disturbance": constants[4:7],
            "gyro_bias": constants[7:10],
            "note": "bound into the Functions (null: no limit)",
        },
        "memory_layout": {
            "sample": list(FLIGHT_MEMORY_LAYOUT),
            "flight_controller": list(FLIGHT_MEMORY_LAYOUT[0:5]),
        },
        "initial_memory": "h = c = 1; sigma_prev = short set of the sigma the controller sees at k = 0 (the first "
        "history row, m_{-d} = x0 for the constant history; for d = 0 the short set of sigma0); the accumulators "
        "0 (mrpctl.loop.FlightOptions.initial_memory)",
        "history": "m_{-d}, ..., m_{-1}: noise-free states (the constant history x0 by default)",
    }


def _disturbance_manifest(disturbance: Any) -> dict[str, Any] | None:
    """The flight manifest's ``disturbance``: the constant torque bound in, or the per-sample ``torque`` input."""
    if disturbance is None:
        return None
    if disturbance.constant:
        return {"torque": [float(w) for w in disturbance.torque]}
    shape = disturbance.shape
    return {
        "torque": None,
        "per_sample": True,
        "input": "torque",
        "samples": None if shape is None else int(shape[0]),
        "function": None if disturbance.function is None else getattr(disturbance.function, "__name__", "callable"),
        "note": "w_k (N m, body frame) is the input `torque` of sample (3) and chunk (3 x max(d, 1), one column "
        "per sample), added to the applied torque and held over the period; it is not bound into the Functions",
    }
