"""Study: cheaper predictor samples built on a linear model copy (a bench, not a feature; the package is unchanged).

Form (b) of ``design/predictor.md`` (the engine's predictor) advances its model copy z by one RK4 step of the
nonlinear model J_m each sample (``mrpctl.loop.functions.predictor_core_function``: ``model_step =
step_function(spacecraft, period, 1, inertia=model_inertia)``, then ``short``). The variants (`VARIANTS`) replace
that step by the exact zero-order-hold transition of the model linearised about the origin, x = [σ; ω/4]:

    ẋ = A x + B_m u,  A = [0 I; 0 0],  B_m = [0; ¼ J_m⁻¹]
    z_{k+1} = Φ z_k + Γ_m u_k,  Φ = [I hI; 0 I],  Γ_m = [h²/8 J_m⁻¹; h/4 J_m⁻¹]

(per axis for a diagonal J_m: σ_z += h w_z + (h²/8) u/J_i, w_z += (h/4) u/J_i):

* "linear": then the same ``short``, the rest of form (b) unchanged (the group correction C(τ δω) C(z_k)
  C(z_{k−d})ᵀ C(y), ω̂ = ω_z(k) + δω, the rule). Its linearisation is still the FSA prediction, but away from the
  origin the copy's relative rotation C(z_k) C(z_{k−d})ᵀ is no longer the model's.
* "rotation": z is a linear state (no ``short``); S = z_k − Φ^d z_{k−d} is the forced response over the window
  (S_σ = z_σ(k) − z_σ(k−d) − τ z_w(k−d), S_w = z_w(k) − z_w(k−d)), and Ĉ = exp(−[θ×]) C(y), θ = 4 (τ w_y + S_σ),
  ŵ = w_y + S_w (`rotation_prediction_expr`): the FSA prediction with its σ increment applied as a rotation.
* "increment": the same with the increment applied as an MRP, Ĉ = C(τ w_y + S_σ) C(y) (`increment_prediction_expr`):
  no sin/cos, so no libm call in the sample and one lane segment; its rotation angle is 4 atan(|v|), not 4 |v|.
* "pade": the MRP of the rotation 4 v by a Padé form of tan (`pade_prediction_expr`): the angle of "rotation"
  to 1e-3 up to π, still no libm call.

Four parts, each printed:

1. ``count``: the lane program of the sample as the lane engine emits it (`emit_lanes` of `engine_sample`, the
   outputs the engine does not read dropped, W = 8, d = 500, 1 kHz): lane values (``const double v`` lines),
   divisions (OP_DIV/OP_INV instructions; the slashes of the C text, as counted before in ``design/lanes.md``, are
   8 more: the comments), libm calls (sin, cos, ...) and segments, for the plain ``OnDelayed`` sample, form (b)
   and the variants.
2. ``accuracy``: the paper case (J = diag(140, 100, 80), x0 = paper.INITIAL_STATE, τ = 0.5 s, 20 s; and a skew-axis
   x0, `STATES`) at 100 Hz and
   1 kHz, ζ = 1 gains ωₙ = 3 and 12.85 rad/s, OnPredicted(1), plant J = (1 + e) J_m for e = 0, +10 %, −10 %: a
   NumPy loop written here (DCMs, not the engine's quaternions) of form (b) and of each variant, giving the
   prediction error (the angle between Ĉ_k and the true C(σ_k) for t > τ, max and RMS; the rate error max |ω̂ − ω|),
   final |σ|, settling time (|σ| < 1e-2 and |ω| < 1e-3 rad/s from then on) and switches; each case checked against
   the compiled engine (form (b): `mrpctl.simulate`; a variant: the same engine with its sample, see
   `variant_engines`): the settling times must agree to 1e-9 s and the switch counts exactly (or the engine
   reports the run diverged).
3. ``lanes``: runs/s of ``bench/predictor_lanes.py``'s 48 cases (full-inertia plants ± 15 %, fast gains, 1 kHz, 20 s)
   on the lanes, one thread, CPU time: plain ``OnDelayed`` (paper gain), form (b) and the variants, interleaved
   rounds in one process; min/median/max of the per-round ratios to plain.

4. ``campaign``: the 48 cases run by run on the scalar engine of each sample: settled, final |σ|, fast turning.

Run: ``.venv/bin/python bench/predictor_linear_study.py [count|accuracy|accuracy100|campaign|lanes ...] [--rounds N]``
(default: count, accuracy, campaign, lanes; 7 rounds).
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import casadi as ca
import numpy as np

from mrpctl import paper, simulate, simulate_batch
from mrpctl.design import pd_gains
from mrpctl.engines import lanes as lane_engines
from mrpctl.engines import scalar as scalar_engines
from mrpctl.engines.lane_code import emit_lanes
from mrpctl.engines.scalar import engine_sample
from mrpctl.loop import functions as loop_functions
from mrpctl.loop.functions import InertiaInput, core_function, predictor_core_function
from mrpctl.model import INPUT_SIZE, STATE_SIZE
from mrpctl.predictor import OnPredicted, Predictor
from mrpctl.simulation import _batch
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnDelayed

TAU = 0.5
T_FINAL = 20.0
SETTLE_SIGMA, SETTLE_OMEGA = 1e-2, 1e-3


# ---------------------------------------------------------------- the variant's sample


def linear_model_step(period: float, kind: InertiaInput) -> ca.Function:
    """``step(x, u, J, J_inv) -> x_next``: the exact ZOH transition of the model linearised about the origin."""
    x = ca.SX.sym("x", STATE_SIZE)
    u = ca.SX.sym("u", INPUT_SIZE)
    j_in, j_inv_in, _, j_inv = loop_functions._inertia_symbols(kind)
    acceleration = j_inv @ u  # J_m⁻¹ u (a product per axis for a diagonal model)
    h = period
    sigma = x[0:3] + h * x[3:6] + (h * h / 8.0) * acceleration
    rate = x[3:6] + (h / 4.0) * acceleration
    return ca.Function("step", [x, u, j_in, j_inv_in], [ca.vertcat(sigma, rate)], ["x", "u", "J", "J_inv"], ["x_next"])


def rotation_prediction_expr(y: Any, z_old: Any, z: Any, previous: Any, alpha: Any, tau: Any) -> tuple[Any, Any]:
    """`prediction_expr` with the group correction replaced by the linear FSA prediction on the group (variant
    "rotation"): with a linear copy, S = z_k − Φ^d z_{k−d} is the forced response over the window (S_σ = z_σ(k) −
    z_σ(k−d) − τ z_w(k−d), S_w = z_w(k) − z_w(k−d)), and Ĉ = exp(−[θ×]) C(y) with θ = τ ω_y + 4 S_σ, ω̂ = ω_y + 4 S_w
    (x units: ŵ = w_y + S_w); the rule as in `prediction_expr`."""
    forced = z[0:3] - z_old[0:3] - tau * z_old[3:6]
    theta = 4 * (tau * y[3:6] + forced)
    q_hat = loop_functions._quaternion_product(
        loop_functions._rotation_quaternion(theta), loop_functions.quaternion_from_mrp_expr(y[0:3])
    )
    return _rule(q_hat, y, z_old, z, previous, alpha)


def increment_prediction_expr(y: Any, z_old: Any, z: Any, previous: Any, alpha: Any, tau: Any) -> tuple[Any, Any]:
    """As `rotation_prediction_expr` with the rotation exp(−[θ×]) replaced by the rotation of the MRP θ/4 = τ w_y + S_σ
    (variant "increment": the FSA's σ increment composed on the group, Ĉ = C(τ w_y + S_σ) C(y); tan(φ/4) against φ/4,
    a third-order difference in the angle φ over τ; no sin/cos, no libm call in the sample)."""
    increment = tau * y[3:6] + (z[0:3] - z_old[0:3] - tau * z_old[3:6])
    q_hat = loop_functions._quaternion_product(
        loop_functions.quaternion_from_mrp_expr(increment), loop_functions.quaternion_from_mrp_expr(y[0:3])
    )
    return _rule(q_hat, y, z_old, z, previous, alpha)


def pade_prediction_expr(y: Any, z_old: Any, z: Any, previous: Any, alpha: Any, tau: Any) -> tuple[Any, Any]:
    """As `increment_prediction_expr` with the MRP of the rotation θ = 4 v (v = τ w_y + S_σ) by the [3/2] Padé form of
    tan: tan(φ/4) θ/φ ≈ v (15 − x²)/(15 − 6 x²), x² = |v|² (x = φ/4; relative error below 1e-3 up to φ = π, a pole
    at φ ≈ 6.3 rad, a rotation by 2π over τ); variant "pade": one more division than "increment", no libm call."""
    increment = tau * y[3:6] + (z[0:3] - z_old[0:3] - tau * z_old[3:6])
    squared = ca.dot(increment, increment)
    increment = increment * ((15 - squared) / (15 - 6 * squared))
    q_hat = loop_functions._quaternion_product(
        loop_functions.quaternion_from_mrp_expr(increment), loop_functions.quaternion_from_mrp_expr(y[0:3])
    )
    return _rule(q_hat, y, z_old, z, previous, alpha)


def _rule(q_hat: Any, y: Any, z_old: Any, z: Any, previous: Any, alpha: Any) -> tuple[Any, Any]:
    """The short MRP of q̂, continuity and the switch as in `prediction_expr`; ŵ = w_y + S_w."""
    sigma_hat = loop_functions._short_mrp_from_quaternion(q_hat)
    shadow = loop_functions._safe_shadow(sigma_hat)
    nearer = ca.logic_and(
        ca.dot(sigma_hat, sigma_hat) > loop_functions._CONTINUITY_FLOOR,
        ca.norm_2(shadow - previous) < ca.norm_2(sigma_hat - previous),
    )
    sigma_hat = ca.if_else(nearer, shadow, sigma_hat)
    switched = ca.if_else(ca.dot(sigma_hat, sigma_hat) >= alpha * alpha, 1.0, 0.0)
    sigma_hat = ca.if_else(switched, loop_functions._safe_shadow(sigma_hat), sigma_hat)
    return ca.vertcat(sigma_hat, y[3:6] + (z[3:6] - z_old[3:6])), switched


#: The samples compared: the engine's form (b); "linear": the copy by the linear ZOH transition, then ``short``,
#: the rest of form (b) unchanged (the brief's variant); "rotation": the linear copy without ``short`` (a linear
#: state) and `rotation_prediction_expr` instead of the group correction; "increment": the same with
#: `increment_prediction_expr`; "pade": the same with `pade_prediction_expr`.
VARIANTS = ("b", "linear", "rotation", "increment", "pade")


def variant_core_function(variant: str, *args: Any, **kwargs: Any) -> ca.Function:
    """`predictor_core_function` of ``variant`` (`VARIANTS`). For the others the model copy's RK4 step
    is replaced by `linear_model_step` (predictor_core_function builds the plant's step first and the model's
    second, ``step_function(spacecraft, period, 1, inertia=model_inertia)``); for "rotation" and "increment" also
    the ``short`` of z (its only use in that function) and the correction."""
    if variant == "b":
        return predictor_core_function(*args, **kwargs)
    original = (loop_functions.step_function, loop_functions.short_expr, loop_functions.prediction_expr)
    calls: list[int] = []

    def patched(spacecraft: Spacecraft, period: float, substeps: int, **options: Any) -> ca.Function:
        calls.append(substeps)
        if len(calls) == 2:
            if substeps != 1:
                raise AssertionError("the model copy's step is built second, with one substep")
            return linear_model_step(period, options["inertia"])
        return original[0](spacecraft, period, substeps, **options)

    loop_functions.step_function = patched  # type: ignore[assignment]
    if variant in ("rotation", "increment", "pade"):
        loop_functions.short_expr = lambda sigma: sigma
        loop_functions.prediction_expr = {
            "rotation": rotation_prediction_expr,
            "increment": increment_prediction_expr,
        }.get(variant, pade_prediction_expr)
    try:
        core = predictor_core_function(*args, **kwargs)
    finally:
        loop_functions.step_function, loop_functions.short_expr, loop_functions.prediction_expr = original
    if len(calls) != 2:
        raise AssertionError(f"predictor_core_function built {len(calls)} steps, expected the plant's and the model's")
    return core


LABELS = {
    "b": "predictor, form (b)",
    "linear": "linear copy, group corr.",
    "rotation": "linear copy, rotation",
    "increment": "linear copy, MRP increment",
    "pade": "linear copy, Pade increment",
}
_VARIANT_CACHES: dict[str, dict[str, dict[Any, Any]]] = {v: {"lanes": {}, "scalar": {}} for v in VARIANTS[1:]}


@contextlib.contextmanager
def variant_engines(variant: str) -> Iterator[None]:
    """The engines (lanes and scalar) built inside use the sample of ``variant``; their in-process caches are the
    variant's own (the compile cache on disk is keyed by the code: no stale library)."""
    if variant == "b":
        yield
        return
    saved = (lane_engines._ENGINES, scalar_engines._ENGINES)
    saved_cores = (lane_engines.predictor_core_function, scalar_engines.predictor_core_function)
    lane_engines._ENGINES = _VARIANT_CACHES[variant]["lanes"]
    scalar_engines._ENGINES = _VARIANT_CACHES[variant]["scalar"]

    def core(*args: Any, **kwargs: Any) -> ca.Function:
        return variant_core_function(variant, *args, **kwargs)

    lane_engines.predictor_core_function = core  # type: ignore[assignment]
    scalar_engines.predictor_core_function = core  # type: ignore[assignment]
    try:
        yield
    finally:
        lane_engines._ENGINES, scalar_engines._ENGINES = saved
        lane_engines.predictor_core_function, scalar_engines.predictor_core_function = saved_cores


# ---------------------------------------------------------------- 1. counting the emitted lane program


def lane_counts(core: ca.Function, d: int, delayed_output: str) -> dict[str, int]:
    """Lane values, divisions, libm calls, segments of the lane program of ``core`` as `LaneEngine` emits it."""
    sample = engine_sample(core, d, "count")
    names_in = [sample.name_in(i) for i in range(sample.n_in())]
    names_out = [sample.name_out(i) for i in range(sample.n_out())]
    drop = [n for n in names_out if not (n.endswith("_next") and n[:-5] in names_in) and n != delayed_output]
    program = emit_lanes(sample, lane_engines.DEFAULT_WIDTH, drop=drop)
    ops = [sample.instruction_id(k) for k in range(sample.n_instructions())]
    libm = (ca.OP_SIN, ca.OP_COS, ca.OP_TAN, ca.OP_ATAN, ca.OP_ATAN2, ca.OP_EXP, ca.OP_LOG)  # fmax: a lane form
    return {
        "values": program.code.count("const double v"),
        "divisions": ops.count(ca.OP_DIV) + ops.count(ca.OP_INV),
        "slashes": program.code.count("/"),
        "libm": sum(ops.count(op) for op in libm),
        "segments": program.segments,
    }


def count() -> None:
    d, period = 500, 1e-3
    plant = Spacecraft(np.array([[140.0, 1.0, 1.0], [1.0, 100.0, 1.0], [1.0, 1.0, 80.0]]))  # a full-inertia plant
    for layout in (InertiaInput.FULL, InertiaInput.DIAGONAL):
        craft = plant if layout is InertiaInput.FULL else paper.SPACECRAFT
        rows = {
            "plain OnDelayed": lane_counts(
                core_function(craft, OnDelayed(), d, period, 1, inertia=layout), d, "x_meas"
            ),
        }
        for variant in VARIANTS:
            core = variant_core_function(variant, craft, d, period, 1, inertia=layout, limited=False)
            rows[LABELS[variant]] = lane_counts(core, d, "ring")
        plain = rows["plain OnDelayed"]
        print(
            f"lane program, d = {d}, W = {lane_engines.DEFAULT_WIDTH}, plant {layout.value}, diagonal model, "
            "no actuator"
        )
        print(
            f"{'sample':24s} {'values':>7s} {'x plain':>8s} {'div':>4s} {'slashes':>8s} {'libm':>5s} {'segments':>9s}"
        )
        for label, row in rows.items():
            print(
                f"{label:24s} {row['values']:7d} {row['values'] / plain['values']:8.2f} {row['divisions']:4d} "
                f"{row['slashes']:8d} {row['libm']:5d} {row['segments']:9d}"
            )


# ---------------------------------------------------------------- 2. accuracy: a NumPy loop written here


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def dcm(sigma: np.ndarray) -> np.ndarray:
    """[BN] of an MRP (Schaub): I + (8 [σ×]² − 4 (1 − σ²) [σ×]) / (1 + σ²)²."""
    s2 = float(sigma @ sigma)
    s = skew(sigma)
    return np.eye(3) + (8.0 * s @ s - 4.0 * (1.0 - s2) * s) / (1.0 + s2) ** 2


def rotation(theta: np.ndarray) -> np.ndarray:
    """exp(−[θ×]) by Rodrigues' formula."""
    angle = float(np.linalg.norm(theta))
    if angle < 1e-12:
        return np.eye(3) - skew(theta)
    k = skew(theta / angle)
    return np.eye(3) - np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def short_mrp(c: np.ndarray) -> np.ndarray:
    """The short MRP of a DCM (Shepperd's quaternion, then q_v/(1 + q₀) with q₀ >= 0)."""
    trace = np.trace(c)
    candidates = np.array([trace, c[0, 0], c[1, 1], c[2, 2]])
    i = int(np.argmax(candidates))
    if i == 0:
        q0 = 0.5 * np.sqrt(1.0 + trace)
        q = np.array(
            [q0, (c[1, 2] - c[2, 1]) / (4 * q0), (c[2, 0] - c[0, 2]) / (4 * q0), (c[0, 1] - c[1, 0]) / (4 * q0)]
        )
    else:
        a, b = [(1, 2), (2, 0), (0, 1)][i - 1]
        qi = 0.5 * np.sqrt(1.0 + 2 * c[i - 1, i - 1] - trace)
        q = np.zeros(4)
        q[i] = qi
        q[0] = (c[a, b] - c[b, a]) / (4 * qi)
        q[a + 1] = (c[i - 1, a] + c[a, i - 1]) / (4 * qi)
        q[b + 1] = (c[i - 1, b] + c[b, i - 1]) / (4 * qi)
    if q[0] < 0:
        q = -q
    return q[1:4] / (1.0 + q[0])


def shorten(sigma: np.ndarray) -> np.ndarray:
    s2 = float(sigma @ sigma)
    return -sigma / s2 if s2 > 1.0 else sigma


def derivative(x: np.ndarray, u: np.ndarray, inertia: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    sigma, omega = x[0:3], 4.0 * x[3:6]
    s2 = float(sigma @ sigma)
    b = (1.0 - s2) * np.eye(3) + 2.0 * skew(sigma) + 2.0 * np.outer(sigma, sigma)
    omega_dot = inverse @ (-np.cross(omega, inertia @ omega) + u)
    return np.concatenate((b @ omega / 4.0, omega_dot / 4.0))


def rk4(x: np.ndarray, u: np.ndarray, h: float, inertia: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    k1 = derivative(x, u, inertia, inverse)
    k2 = derivative(x + h / 2 * k1, u, inertia, inverse)
    k3 = derivative(x + h / 2 * k2, u, inertia, inverse)
    k4 = derivative(x + h * k3, u, inertia, inverse)
    return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def principal_angle(c: np.ndarray) -> float:
    """The rotation angle of a DCM, atan2(sin, cos) (no arccos floor near 0)."""
    axial = 0.5 * np.array([c[2, 1] - c[1, 2], c[0, 2] - c[2, 0], c[1, 0] - c[0, 1]])
    return float(np.arctan2(np.linalg.norm(axial), (np.trace(c) - 1.0) / 2.0))


def reference_loop(
    plant: np.ndarray, model: np.ndarray, gain: np.ndarray, x0: np.ndarray, rate: float, variant: str
) -> dict[str, float]:
    """The predictor loop (OnPredicted(1)) of ``variant`` (`VARIANTS`), written again with DCMs."""
    h = 1.0 / rate
    d = round(TAU * rate)
    n = round(T_FINAL * rate)
    plant_inverse, model_inverse = np.linalg.inv(plant), np.linalg.inv(model)
    x = np.array(x0, dtype=float)
    z = np.concatenate((shorten(x[0:3]), x[3:6]))
    ring = [np.concatenate((x0, x0))] * d  # (m, z) at t_{k−d}, the constant history
    previous = z[0:3].copy()
    errors, rate_errors, sigmas, omegas = [], [], [], []
    switches = 0
    for k in range(n):
        if float(x[0:3] @ x[0:3]) > 1.0:  # OnCurrent bookkeeping of the plant's set
            x = np.concatenate((-x[0:3] / float(x[0:3] @ x[0:3]), x[3:6]))
        sigmas.append(float(np.linalg.norm(x[0:3])))
        omegas.append(float(np.linalg.norm(4.0 * x[3:6])))
        if d > 0:
            ring.append(np.concatenate((x, z)))
            entry = ring.pop(0)
            y, z_old = entry[0:6], entry[6:12]
        else:
            y, z_old = x, z
        if variant in ("rotation", "increment", "pade"):
            forced = z[0:3] - z_old[0:3] - TAU * z_old[3:6]  # S_σ, the forced response over the window
            v = TAU * y[3:6] + forced
            if variant == "rotation":
                c_hat = rotation(4.0 * v) @ dcm(y[0:3])
            elif variant == "increment":
                c_hat = dcm(v) @ dcm(y[0:3])
            else:
                x2 = float(v @ v)
                c_hat = dcm(v * (15.0 - x2) / (15.0 - 6.0 * x2)) @ dcm(y[0:3])
        else:
            delta = 4.0 * (y[3:6] - z_old[3:6])
            c_hat = rotation(TAU * delta) @ dcm(z[0:3]) @ dcm(z_old[0:3]).T @ dcm(y[0:3])
        sigma_hat = short_mrp(c_hat)
        s2 = float(sigma_hat @ sigma_hat)
        if s2 > 1e-8:
            shadow = -sigma_hat / s2
            if np.linalg.norm(shadow - previous) < np.linalg.norm(sigma_hat - previous):
                sigma_hat = shadow
        if float(sigma_hat @ sigma_hat) >= 1.0:
            switches += 1
            sigma_hat = -sigma_hat / float(sigma_hat @ sigma_hat)
        previous = sigma_hat
        x_hat = np.concatenate((sigma_hat, y[3:6] + (z[3:6] - z_old[3:6])))
        if k * h > TAU + 1e-12:
            errors.append(principal_angle(c_hat @ dcm(x[0:3]).T))
            rate_errors.append(float(np.linalg.norm(4.0 * (x_hat[3:6] - x[3:6]))))
        u = gain @ x_hat
        if variant == "b":
            z_next = rk4(z, u, h, model, model_inverse)
        else:
            a = model_inverse @ u
            z_next = np.concatenate((z[0:3] + h * z[3:6] + h * h / 8.0 * a, z[3:6] + h / 4.0 * a))
        z = (
            z_next
            if variant in ("rotation", "increment", "pade")
            else np.concatenate((shorten(z_next[0:3]), z_next[3:6]))
        )
        x = rk4(x, u, h, plant, plant_inverse)
    settled = [s < SETTLE_SIGMA and w < SETTLE_OMEGA for s, w in zip(sigmas, omegas, strict=True)]
    settling = float("nan")
    if settled[-1]:
        last = max((i for i, ok in enumerate(settled) if not ok), default=-1)
        settling = (last + 1) * h
    final = x[0:3] if float(x[0:3] @ x[0:3]) <= 1.0 else -x[0:3] / float(x[0:3] @ x[0:3])
    return {
        "error_max": max(errors),
        "error_rms": float(np.sqrt(np.mean(np.square(errors)))),
        "error_end": float(np.max(errors[-round(rate) :])),  # over the last second
        "rate_error_max": max(rate_errors),
        "final_sigma": float(np.linalg.norm(final)),
        "settling": settling,
        "switches": switches,
    }


def engine_run(
    plant: Spacecraft, model: Spacecraft, gain: np.ndarray, x0: np.ndarray, rate: float, variant: str
) -> Any:
    call = dict(tau=TAU, rule=OnPredicted(1.0), t_final=T_FINAL, rate=rate, predictor=Predictor(model=model))
    with variant_engines(variant):
        return simulate(plant, gain, x0, **call)


#: The initial states: the paper's (a rotation about the x axis alone: every rotation of the loop commutes) and
#: one about a skew axis (150° about (1, 2, 3)/√14, ω0 = (0.3, −0.2, 0.25) rad/s: the rotations do not commute).
_SKEW_AXIS = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
STATES = {
    "paper": np.asarray(paper.INITIAL_STATE, dtype=float),
    "skew": np.concatenate((_SKEW_AXIS * np.tan(np.radians(150.0) / 4), np.array([0.3, -0.2, 0.25]) / 4)),
}


def accuracy(rates: tuple[float, ...] = (100.0, 1000.0)) -> None:
    model = paper.SPACECRAFT
    print(
        "tau = 0.5 s, 20 s, OnPredicted(1), zeta = 1, model J_m = paper J, plant (1 + e) J_m; prediction error = "
        "angle(C_hat, C_true) for t > tau (max, RMS, max over the last second); rate error = max |omega_hat - omega| "
        "(rad/s); settling: |sigma| < 1e-2, |omega| < 1e-3 rad/s from then on; 'engine': the compiled engine with the "
        "same sample gives the same settling time (1e-9 s) and switches"
    )
    header = (
        f"{'x0':>5s} {'rate':>5s} {'wn':>6s} {'e':>5s} {'variant':>8s} {'err max':>9s} {'err rms':>9s} {'err end':>9s} "
        f"{'rate err':>9s} {'final |s|':>10s} {'settling':>9s} {'sw':>3s} {'engine':>7s}"
    )
    print(header)
    np.seterr(all="ignore")  # a diverging run overflows
    for name, x0 in STATES.items():
        for rate in rates:
            for omega_n in (3.0, 12.85):
                gain = pd_gains(model, zeta=1.0, omega_n=omega_n).K
                for e in (0.0, 0.1, -0.1):
                    plant = Spacecraft(model.inertia * (1.0 + e))
                    for variant in VARIANTS:
                        row = reference_loop(plant.inertia, model.inertia, gain, x0, rate, variant)
                        run = engine_run(plant, model, gain, x0, rate, variant)
                        engine_settling = float("nan") if run.settling_time is None else run.settling_time
                        agrees = run.switch_count == row["switches"] and (
                            (np.isnan(engine_settling) and np.isnan(row["settling"]))
                            or abs(engine_settling - row["settling"]) < 1e-9
                        )
                        verdict = "diverged" if run.diverged else ("agrees" if agrees else "DIFFERS")
                        settling = "-" if np.isnan(row["settling"]) else f"{row['settling']:.3f}"
                        print(
                            f"{name:>5s} {rate:5.0f} {omega_n:6.2f} {e:+5.0%} {variant:>8s} {row['error_max']:9.2e} "
                            f"{row['error_rms']:9.2e} {row['error_end']:9.2e} {row['rate_error_max']:9.2e} "
                            f"{row['final_sigma']:10.2e} {settling:>9s} {row['switches']:3d} "
                            f"{verdict:>8s}",
                            flush=True,
                        )


# ---------------------------------------------------------------- 3. the lanes, in one process


def lanes(rounds: int) -> None:
    sys.path.insert(0, os.path.dirname(__file__))
    import predictor_lanes  # the cases of bench/predictor_lanes.py

    runs = 48
    case = predictor_lanes.cases(runs)
    predicted = dict(case, rule=[OnPredicted(1.0 if i % 2 == 0 else 1.2) for i in range(runs)])
    predictor = Predictor(model=predictor_lanes.NOMINAL)

    def predictor_call(variant: str) -> Callable[[], Any]:
        def call() -> Any:
            with variant_engines(variant):
                return simulate_batch(**predicted, predictor=predictor, threads=1)

        return call

    def plain() -> Any:
        return simulate_batch(**dict(case, K=paper.GAIN), rule=OnDelayed(), threads=1)

    if not _batch._LANES:
        raise SystemExit("the lanes are off")
    table: dict[str, Callable[[], Any]] = {"plain OnDelayed": plain}
    table.update({LABELS[variant]: predictor_call(variant) for variant in VARIANTS})
    checks = {label: call() for label, call in table.items()}  # builds (or loads) every library first
    seconds: dict[str, list[float]] = {label: [] for label in table}
    for _ in range(rounds):
        for label, call in table.items():
            start = time.process_time()
            call()
            seconds[label].append(time.process_time() - start)
    print(
        f"lanes, one thread, CPU time, {runs} runs of bench/predictor_lanes.py's cases, {rounds} interleaved rounds, "
        f"load average {' '.join(f'{v:.2f}' for v in os.getloadavg())}"
    )
    print(f"diverged runs: { {label: int(np.asarray(r.diverged).sum()) for label, r in checks.items()} }")
    reference = np.asarray(checks[LABELS["b"]].settling_time, dtype=float)
    for variant in VARIANTS[1:]:
        other = np.asarray(checks[LABELS[variant]].settling_time, dtype=float)
        both = np.isfinite(reference) & np.isfinite(other)
        print(
            f"settling (s), form (b) vs {LABELS[variant]}, {int(both.sum())} runs settled in both: median "
            f"{np.median(reference[both]):.3f} vs {np.median(other[both]):.3f}, max |difference| "
            f"{np.max(np.abs(reference[both] - other[both])):.3f}; settled in (b) only "
            f"{int((np.isfinite(reference) & ~np.isfinite(other)).sum())}, in the variant only "
            f"{int((~np.isfinite(reference) & np.isfinite(other)).sum())}"
        )
    print(f"{'':26s} {'best runs/s':>12s} {'ratio to plain: min':>20s} {'median':>7s} {'max':>6s}")
    for label, values in seconds.items():
        ratios = np.array(seconds["plain OnDelayed"]) / np.array(values)
        print(
            f"{label:26s} {runs / min(values):12.1f} {ratios.min():20.3f} {np.median(ratios):7.3f} {ratios.max():6.3f}"
        )


def campaign() -> None:
    """Each variant on the 48 cases of ``bench/predictor_lanes.py`` run by run (`mrpctl.simulate`, the scalar engine
    of the variant's sample): settled in 20 s, the final |σ| of the others, and the runs still turning fast at the end
    (|ω| > 1 rad/s at 20 s)."""
    sys.path.insert(0, os.path.dirname(__file__))
    import predictor_lanes

    runs = 48
    case = predictor_lanes.cases(runs)
    predictor = Predictor(model=predictor_lanes.NOMINAL)
    print(
        f"{runs} runs of bench/predictor_lanes.py's cases (plant J_ii ± 15 %, products ± 2 kg m², diagonal nominal "
        "model, fast gains, tau = 0.5 s, 1 kHz, 20 s), run by run"
    )
    print(
        f"{'variant':28s} {'settled':>8s} {'final |s| of the others: median':>32s} {'max':>9s} {'|w| > 1 rad/s':>14s}"
    )
    for variant in VARIANTS:
        settled, others, fast = 0, [], 0
        with variant_engines(variant):
            for i in range(runs):
                result = simulate(
                    case["spacecraft"][i], case["K"], case["x0"][i], tau=TAU, t_final=T_FINAL, rate=case["rate"],
                    rule=OnPredicted(1.0 if i % 2 == 0 else 1.2), predictor=predictor,
                )  # fmt: skip
                sigma = np.linalg.norm(result.sigma[-1])
                settled += result.settling_time is not None
                if result.settling_time is None:
                    others.append(float(sigma))
                fast += bool(np.linalg.norm(result.omega[-1]) > 1.0)
        shown = f"{np.median(others):32.2e} {max(others):9.2e}" if others else f"{'-':>32s} {'-':>9s}"
        print(f"{LABELS[variant]:28s} {settled:8d} {shown} {fast:14d}")


def main() -> None:
    args = sys.argv[1:]
    rounds = 7
    if "--rounds" in args:
        at = args.index("--rounds")
        rounds = int(args[at + 1])
        del args[at : at + 2]
    parts = args or ["count", "accuracy", "campaign", "lanes"]
    for part in parts:
        if part == "count":
            count()
        elif part == "accuracy":
            accuracy()
        elif part == "accuracy100":  # 100 Hz only
            accuracy((100.0,))
        elif part == "campaign":
            campaign()
        elif part == "lanes":
            lanes(rounds)
        else:
            raise SystemExit(f"unknown part {part!r}: count, accuracy or lanes")


if __name__ == "__main__":
    main()
