"""The closed loop on a late star tracker and a fast gyro, as one CasADi sample (pure SX) and its compiled run.

One controller sample k (period h, ``design/estimation.md``):

1. plant bookkeeping: the true σ_k in the short set (``OnCurrent``, no physical effect);
2. the sensors: the star tracker takes m_k = σ_k ⊕ σ(θ_k) when it measures (every n-th sample, less the
   dropouts) and its ring delivers the measurement taken at k − ℓ; the rate-integrating gyro delivers
   ω̃_k = (I + diag(s)) ω̄_k + e_k, ω̄_k = φ_k/h the mean rate of the body's rotation φ_k from t_{k−1} to
   t_k (kept from the previous sample; ω₀ before the start). The noises θ_k, e_k and the flag come from
   [`sensor_streams`][mrpctl.estimation.sensor_streams];
3. the controller's attitude and rate, by ``mode``:

   * ``"estimator"``: the estimator's sample ([`estimator_functions`][mrpctl.estimation.estimator_functions]):
     the delayed update and the replay give σ̂_k, ω̂_k = ω̃_k − β̂;
   * ``"pd"``: the last star-tracker measurement to arrive (held between arrivals) and the raw gyro rate ω̃_k;
   * ``"predictor"``: mrpctl's model predictor ([`prediction_expr`][mrpctl.loop.functions.prediction_expr]) from
     the last arrived measurement y = (m_j, ω̃_j) and the model copy z_j of its time t_j, carried over the
     age t_k − t_j with the model copy z_k (propagated with the nominal inertia J_m);

4. the controller-side rule [`Hysteretic`][mrpctl.flight.Hysteretic] (its selection on the short set) and
   u = K [σ_c; ω_c/4], held over the period while the plant (true inertia J) is integrated by RK4.

No actuator limit and no disturbance in this loop.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import casadi as ca

from mrpctl.errors import SpecificationError
from mrpctl.estimation import COVARIANCE_SIZE, EstimatorFunctions, relative_rotation_expr
from mrpctl.flight import compose_mrp_expr, rotation_vector_to_mrp_expr, selection_function, short_expr
from mrpctl.loop.functions import InertiaInput, prediction_expr, step_function
from mrpctl.model import INPUT_SIZE, STATE_SIZE
from mrpctl.spacecraft import Spacecraft
from mrpctl.switching import OnCurrent

__all__ = ["ESTIMATED_MODES", "ESTIMATED_RECORD", "EstimatedLayout", "estimated_run_function", "estimated_sample"]

#: The controllers this loop flies.
ESTIMATED_MODES = ("estimator", "pd", "predictor")
#: The per-sample record, in order, with sizes.
ESTIMATED_RECORD = (
    ("x", 6),
    ("measurement", 3),
    ("taken", 1),
    ("gyro", 3),
    ("sigma_hat", 3),
    ("omega_hat", 3),
    ("bias_hat", 3),
    ("covariance", COVARIANCE_SIZE),
    ("innovation", 3),
    ("u", 3),
    ("switched", 1),
)
_NOISE = 7


class EstimatedLayout:
    """Where each part of the loop's memory sits (offsets into one vector)."""

    def __init__(self, functions: EstimatorFunctions, mode: str) -> None:
        self.mode = mode
        latency = functions.clock.latency
        sizes = [("tracker_ring", 4 * latency), ("controller", 5), ("mean_rate", 3)]
        if mode == "estimator":
            sizes += [("filter", functions.state_size), ("gyro_ring", 3 * latency)]
        elif mode == "pd":
            sizes += [("held", 3)]
        else:
            sizes += [("held", 13), ("gyro_ring", 3 * latency), ("model", 6), ("model_ring", 6 * latency)]
        self.slices: dict[str, slice] = {}
        start = 0
        for name, size in sizes:
            self.slices[name] = slice(start, start + size)
            start += size
        self.size = start


def _part(vector: Any, layout: EstimatedLayout, name: str, rows: int | None = None) -> Any:
    piece = vector[layout.slices[name]]
    return piece if rows is None else ca.reshape(piece, rows, piece.shape[0] // rows)


def estimated_sample(
    spacecraft: Spacecraft, functions: EstimatorFunctions, substeps: int, mode: str
) -> tuple[ca.Function, EstimatedLayout]:
    """``sample(x, memory, noise, K, delta, J, J_inv, scale, J_m, J_m_inv) -> (x_next, memory_next, record)``.

    ``noise`` = (e_k (3), θ_k (3), taken (1)); ``scale`` the gyro's scale factor errors s (3); J, J⁻¹ of the
    plant and J_m, J_m⁻¹ of the predictor's model as diagonals; ``record`` as `ESTIMATED_RECORD`.
    """
    if mode not in ESTIMATED_MODES:
        raise SpecificationError(f"mode: one of {', '.join(ESTIMATED_MODES)}, got {mode!r}")
    layout = EstimatedLayout(functions, mode)
    clock = functions.clock
    latency, h = clock.latency, clock.period
    step = step_function(spacecraft, h, substeps, inertia=InertiaInput.DIAGONAL)
    x = ca.SX.sym("x", STATE_SIZE)
    memory = ca.SX.sym("memory", layout.size)
    noise = ca.SX.sym("noise", _NOISE)
    gain = ca.SX.sym("K", INPUT_SIZE, STATE_SIZE)
    delta = ca.SX.sym("delta")
    j, j_inv = ca.SX.sym("J", 3), ca.SX.sym("J_inv", 3)
    scale = ca.SX.sym("scale", 3)
    j_m, j_m_inv = ca.SX.sym("J_m", 3), ca.SX.sym("J_m_inv", 3)

    x_meas = OnCurrent().expressions(x, x, ca.SX.zeros(1), delay_samples=0)[0]
    sigma = x_meas[0:3]
    measured = compose_mrp_expr(sigma, rotation_vector_to_mrp_expr(noise[3:6]))
    taken = noise[6]
    gyro = (1 + scale) * _part(memory, layout, "mean_rate") + noise[0:3]
    entry = ca.vertcat(measured, taken)
    if latency:
        tracker = _part(memory, layout, "tracker_ring", 4)
        arriving = tracker[:, 0]
        tracker_next = ca.horzcat(tracker[:, 1:], entry)
    else:
        arriving, tracker_next = entry, ca.SX(4, 0)
    arrived = arriving[3] > 0.5
    zero3 = ca.SX.zeros(3)
    covariance, innovation, bias = ca.SX.zeros(COVARIANCE_SIZE), zero3, zero3
    parts: dict[str, Any] = {"tracker_ring": ca.reshape(tracker_next, -1, 1)}
    if mode == "estimator":
        ring_in = [_part(memory, layout, "gyro_ring", 3)] if latency else []
        out = functions.sample(_part(memory, layout, "filter"), *ring_in, gyro, arriving[0:3], arriving[3])
        parts["filter"] = out[0]
        if latency:
            parts["gyro_ring"] = ca.reshape(out[1], -1, 1)
            out = out[1:]
        sigma_c_in, omega_c, bias, covariance, innovation = out[1], out[2], out[3], out[4], out[5]
    elif mode == "pd":
        held = ca.if_else(arrived, arriving[0:3], _part(memory, layout, "held"))
        parts["held"] = held
        sigma_c_in, omega_c = held, gyro
    else:
        held = _part(memory, layout, "held")
        z = _part(memory, layout, "model")
        if latency:
            gyro_ring = _part(memory, layout, "gyro_ring", 3)
            model_ring = _part(memory, layout, "model_ring", 6)
            gyro_then, z_then = gyro_ring[:, 0], model_ring[:, 0]
            parts["gyro_ring"] = ca.reshape(ca.horzcat(gyro_ring[:, 1:], gyro), -1, 1)
            parts["model_ring"] = ca.reshape(ca.horzcat(model_ring[:, 1:], z), -1, 1)
        else:
            gyro_then, z_then = gyro, z
        # the held measurement y = (m_j; ω̃_j/4), the model copy z_j of its time, and its age (periods)
        y = ca.if_else(arrived, ca.vertcat(arriving[0:3], gyro_then / 4), held[0:6])
        z_old = ca.if_else(arrived, z_then, held[6:12])
        age = ca.if_else(arrived, latency, held[12] + 1)
        x_hat, _ = prediction_expr(y, z_old, z, zero3, ca.inf, age * h)
        sigma_c_in, omega_c = x_hat[0:3], 4 * x_hat[3:6]
        parts["held"] = ca.vertcat(y, z_old, age)
    controller = _part(memory, layout, "controller")
    sigma_seen = short_expr(sigma_c_in)
    h_next, c_next, sigma_c, switched = selection_function()(
        controller[0], controller[1], sigma_seen, controller[2:5], delta
    )
    parts["controller"] = ca.vertcat(h_next, c_next, sigma_seen)
    u = gain @ ca.vertcat(sigma_c, omega_c / 4)
    if mode == "predictor":
        model_step = step_function(spacecraft, h, 1, inertia=InertiaInput.DIAGONAL)
        z_next = model_step(z, u, j_m, j_m_inv)
        parts["model"] = ca.vertcat(short_expr(z_next[0:3]), z_next[3:6])
    x_next = step(x_meas, u, j, j_inv)
    parts["mean_rate"] = relative_rotation_expr(sigma, x_next[0:3]) / h
    # the rings of a loop without latency are empty
    memory_next = ca.vertcat(*[parts.get(name, ca.SX(0, 1)) for name in layout.slices])
    record = ca.vertcat(x_meas, measured, taken, gyro, sigma_seen, omega_c, bias, covariance, innovation, u, switched)
    sample = ca.Function(
        "estimated_sample",
        [x, memory, noise, gain, delta, j, j_inv, scale, j_m, j_m_inv],
        [x_next, memory_next, record],
        ["x", "memory", "noise", "K", "delta", "J", "J_inv", "scale", "J_m", "J_m_inv"],
        ["x_next", "memory_next", "record"],
    )
    return sample, layout


@lru_cache(maxsize=8)
def estimated_run_function(
    spacecraft: Spacecraft, functions: EstimatorFunctions, substeps: int, mode: str, samples: int
) -> tuple[ca.Function, EstimatedLayout]:
    """The whole run: ``run(x0, memory0, noise (7 × N), K, delta, J, J_inv, scale, J_m, J_m_inv) -> (x_end,
    memory_end, records (record size × N))``, a ``mapaccum`` of `estimated_sample` (a C loop once compiled)."""
    sample, layout = estimated_sample(spacecraft, functions, substeps, mode)
    accumulated = sample.mapaccum("estimated_samples", samples, 2)
    symbols = [
        ca.MX.sym("x", STATE_SIZE),
        ca.MX.sym("memory", layout.size),
        ca.MX.sym("noise", _NOISE, samples),
        ca.MX.sym("K", INPUT_SIZE, STATE_SIZE),
        ca.MX.sym("delta"),
        *(ca.MX.sym(name, 3) for name in ("J", "J_inv", "scale", "J_m", "J_m_inv")),
    ]
    broadcast = [symbols[0], symbols[1], symbols[2]] + [ca.repmat(s, 1, samples) for s in symbols[3:]]
    xs, memories, records = accumulated(*broadcast)
    run = ca.Function(
        f"estimated_run_{mode}",
        symbols,
        [xs[:, samples - 1], memories[:, samples - 1], records],
        ["x", "memory", "noise", "K", "delta", "J", "J_inv", "scale", "J_m", "J_m_inv"],
        ["x_end", "memory_end", "records"],
    )
    return run, layout
