"""An independent plain-NumPy reference of the tracking flight loop (no CasADi, nothing from mrpctl's code).

Written again from the equations of ``design/tracking.md``, one run, in quaternions where mrpctl uses MRPs:

* plant: J ω̇ = −ω × J ω + u + w, σ̇ = ¼ ((1 − σ²) ω + 2 σ × ω + 2 σ (σ·ω)), RK4 (fixed substeps), ZOH torque;
  σ kept in the short set (−σ/|σ|² when |σ|² >= 1; no physical effect);
* sensor: β̃ = β(θ_k) ⊗ β(σ_k) (scalar first, [B̃N] = [B̃B][BN]), ω̃ = ω + b + η;
* delay: constant d samples, the history before t = 0 is x0 (noise-free);
* reference row r_k = (σ_R, ω_R^N, ω̇_R^N); the controller's row is r_{max(k−d, 0)} (error at the
  measurement's time) or r_k (current time);
* error: β_BR = β̃_BN ⊗ β_RN* (quaternion product, [BR] = [BN][NR]), sign by continuity with the previous
  sample's, then the Mayhew-Sanfelice-Teel rule h ← −h when h β₀ < −δ, σ_c = h β_v/(1 + h β₀);
  ω_BR = ω̃ − C(β̃) ω_R^N with C the DCM of the quaternion;
* law: u_c = K [σ_c; ω_BR/4] (+ ω̃ × Jω̃ + J(C ω̇_R − ω̃ × C ω_R) with feedforward);
* actuator (optional): direction-preserving scaling to u_max per axis.

The true error at t_k (from the true σ_k and r_k) gives the settling time and Φ_B/R = 2 atan2(|β_v|, |β₀|).
Only the noise samples (``SensorModel.noise``) are taken from mrpctl, as data.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class TrackingRun:
    sigma: np.ndarray  # (n, 3) plant σ_B/N (short)
    omega: np.ndarray  # (n, 3) rad/s
    u: np.ndarray  # (n, 3) applied torque
    command: np.ndarray  # (n, 3)
    sigma_c: np.ndarray  # (n, 3)
    h: np.ndarray  # (n,)
    switches: np.ndarray  # sample indices where h flipped
    pointing_deg: np.ndarray  # (n,) true Φ_B/R
    settling_time: float | None


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _quaternion(sigma: np.ndarray) -> np.ndarray:
    s2 = float(sigma @ sigma)
    return np.concatenate(([(1.0 - s2) / (1.0 + s2)], 2.0 * sigma / (1.0 + s2)))


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """β of [C(a)][C(b)] (Schaub & Junkins Eq. 3.101)."""
    a0, a1, a2, a3 = a
    b0, b1, b2, b3 = b
    return np.array(
        [
            a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
            a1 * b0 + a0 * b1 + a3 * b2 - a2 * b3,
            a2 * b0 - a3 * b1 + a0 * b2 + a1 * b3,
            a3 * b0 + a2 * b1 - a1 * b2 + a0 * b3,
        ]
    )


def _conjugate(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def _dcm(q: np.ndarray) -> np.ndarray:
    """[BN] of β (Schaub & Junkins Eq. 3.96)."""
    b0, b1, b2, b3 = q
    return np.array(
        [
            [b0 * b0 + b1 * b1 - b2 * b2 - b3 * b3, 2 * (b1 * b2 + b0 * b3), 2 * (b1 * b3 - b0 * b2)],
            [2 * (b1 * b2 - b0 * b3), b0 * b0 - b1 * b1 + b2 * b2 - b3 * b3, 2 * (b2 * b3 + b0 * b1)],
            [2 * (b1 * b3 + b0 * b2), 2 * (b2 * b3 - b0 * b1), b0 * b0 - b1 * b1 - b2 * b2 + b3 * b3],
        ]
    )


def _noise_quaternion(theta: np.ndarray) -> np.ndarray:
    angle = float(np.linalg.norm(theta))
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate(([math.cos(angle / 2)], math.sin(angle / 2) / angle * theta))


def _derivative(sigma, omega, inertia, inverse, torque):
    s2 = float(sigma @ sigma)
    sigma_dot = 0.25 * ((1.0 - s2) * omega + 2.0 * _cross(sigma, omega) + 2.0 * sigma * float(sigma @ omega))
    return sigma_dot, inverse @ (torque - _cross(omega, inertia @ omega))


def _rk4(sigma, omega, torque, dt, substeps, inertia, inverse):
    for _ in range(substeps):
        a1, b1 = _derivative(sigma, omega, inertia, inverse, torque)
        a2, b2 = _derivative(sigma + 0.5 * dt * a1, omega + 0.5 * dt * b1, inertia, inverse, torque)
        a3, b3 = _derivative(sigma + 0.5 * dt * a2, omega + 0.5 * dt * b2, inertia, inverse, torque)
        a4, b4 = _derivative(sigma + dt * a3, omega + dt * b3, inertia, inverse, torque)
        sigma = sigma + (dt / 6.0) * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        omega = omega + (dt / 6.0) * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
    return sigma, omega


def tracking_loop(
    inertia: Any,
    K: Any,
    x0: Any,
    reference: np.ndarray,
    *,
    rate: float,
    t_final: float,
    d: int,
    delta: float = 0.0,
    measurement_time: bool = True,
    feedforward: bool = False,
    sensor: Any = None,
    u_max: Any = None,
    substeps: int = 1,
    settling_sigma: float = 1e-2,
    settling_omega: float = 1e-3,
) -> TrackingRun:
    """One tracking run (see the module docstring); x0 = [σ; ω/4], ``reference`` (>= n, 9) rows."""
    inertia = np.asarray(inertia, dtype=float)
    inertia = np.diag(inertia) if inertia.shape == (3,) else inertia
    inverse = np.linalg.inv(inertia)
    gain = np.asarray(K, dtype=float)
    n = math.floor(t_final * rate + 1e-9) + 1
    dt = 1.0 / rate / substeps
    x0 = np.asarray(x0, dtype=float)
    sigma, omega = x0[0:3].copy(), 4.0 * x0[3:6]
    bias = np.zeros(3) if sensor is None else np.asarray(sensor.gyro_bias, dtype=float)
    theta = eta = None
    if sensor is not None:
        theta, eta = sensor.noise(0, n)
    ring_q: list[np.ndarray] = []
    ring_w: list[np.ndarray] = []
    history_q, history_w = _quaternion(x0[0:3]), 4.0 * x0[3:6]
    h = 1.0
    previous: np.ndarray | None = None
    out = {name: np.zeros((n, 3)) for name in ("sigma", "omega", "u", "command", "sigma_c")}
    hs, angle = np.zeros(n), np.zeros(n)
    switches: list[int] = []
    unsettled = -1
    for k in range(n):
        s2 = float(sigma @ sigma)
        if s2 >= 1.0:
            sigma = -sigma / s2
        q_true = _quaternion(sigma)
        if sensor is not None:
            assert theta is not None and eta is not None
            q_meas, w_meas = _product(_noise_quaternion(theta[k]), q_true), omega + bias + eta[k]
        else:
            q_meas, w_meas = q_true, omega.copy()
        ring_q.append(q_meas)
        ring_w.append(w_meas)
        q_used, w_used = (history_q, history_w) if k < d else (ring_q[k - d], ring_w[k - d])
        row = reference[max(k - d, 0)] if measurement_time else reference[k]
        q_error = _product(q_used, _conjugate(_quaternion(row[0:3])))
        # the sign by continuity with the previous sample's (at k = 0: the scalar part >= 0)
        flip = q_error[0] < 0.0 if previous is None else float(q_error @ previous) < 0.0
        if flip:
            q_error = -q_error
        previous = q_error
        if h * q_error[0] < -delta:
            h = -h
            switches.append(k)
        sigma_c = h * q_error[1:4] / (1.0 + h * q_error[0])
        dcm = _dcm(q_used)
        omega_r = dcm @ row[3:6]
        command = gain @ np.concatenate((sigma_c, (w_used - omega_r) / 4.0))
        if feedforward:
            command = command + _cross(w_used, inertia @ w_used)
            command = command + inertia @ (dcm @ row[6:9] - _cross(w_used, omega_r))
        applied = command
        if u_max is not None:
            limits = np.broadcast_to(np.asarray(u_max, dtype=float), (3,))
            ratio = float(np.max(np.abs(command) / limits))
            applied = np.clip(command / ratio if ratio > 1.0 else command, -limits, limits)
        # the true error at t_k
        now = reference[k]
        q_true_error = _product(q_true, _conjugate(_quaternion(now[0:3])))
        # Φ = 2 atan2(|β_v|, |β₀|), written as 4 atan(|β_v|/(1 + |β₀|)): accurate near 0 (acos is not)
        angle[k] = math.degrees(4.0 * math.atan(np.linalg.norm(q_true_error[1:4]) / (1.0 + abs(q_true_error[0]))))
        true_rate = omega - _dcm(q_true) @ now[3:6]
        sigma_error = q_true_error[1:4] / (1.0 + abs(q_true_error[0]))
        if sigma_error @ sigma_error >= settling_sigma**2 or true_rate @ true_rate >= settling_omega**2:
            unsettled = k
        out["sigma"][k], out["omega"][k], out["u"][k] = sigma, omega, applied
        out["command"][k], out["sigma_c"][k], hs[k] = command, sigma_c, h
        sigma, omega = _rk4(sigma, omega, applied, dt, substeps, inertia, inverse)
    settle = unsettled + 1
    return TrackingRun(
        switches=np.array(switches, dtype=np.int64),
        h=hs,
        pointing_deg=angle,
        settling_time=settle / rate if settle < n else None,
        **out,
    )


def _short_mrp(q: np.ndarray) -> np.ndarray:
    q = q if q[0] >= 0.0 else -q
    return q[1:4] / (1.0 + q[0])


def _mrp_shadow(sigma: np.ndarray) -> np.ndarray:
    return -sigma / float(sigma @ sigma)


def predictor_tracking_loop(
    inertia: Any,
    K: Any,
    x0: Any,
    reference: np.ndarray,
    *,
    rate: float,
    t_final: float,
    d: int,
    alpha: float = 1.0,
    feedforward: bool = False,
    model_inertia: Any = None,
    form: str = "model-copy",
) -> TrackingRun:
    """The predictor on the tracking error of the prediction against the reference of t_k, in quaternions.

    ``form="model-copy"`` (form (b): the model copy, error composed on the rotation group and carried over τ):
    q_E = q_z(k−d)* ⊗ q_y, δω = ω_y − ω_z(k−d), q̂ = q(τ δω) ⊗ q_z(k) ⊗ q_E, ω̂ = ω_z(k) + δω; the copy z
    (J_m, one RK4 step) kept short.

    ``form="linear"``: the copy z is the linear ZOH model of [σ; w] (w = ω/4, J_m), never shortened:
    z_σ += h z_w + (h²/8) J_m⁻¹ u, z_w += (h/4) J_m⁻¹ u; S_σ = z_σ(k) − z_σ(k−d) − τ z_w(k−d),
    S_w = z_w(k) − z_w(k−d); v = τ w_y + S_σ, p = v (15 − x²)/(15 − 6x²) with x² = min(v·v, 1.5625) (the [3/2]
    Padé form of tan |v| along v), q̂ = q(p) ⊗ q_y, ω̂ = 4 (w_y + S_w).

    Then, for either form: σ_B/R the short MRP of q̂ ⊗ q_R*, ω_B/R = ω̂ − C(q̂) ω_R; the set nearest the
    previous σ_B/R (|σ|² > 1e-8), then its shadow when |σ| >= α (a switch); u = K [σ_B/R; ω_B/R/4] (+ the
    feedforward of ω̂, C(q̂) and J_m); the plant and the copy z driven by u, the plant kept short.
    """
    assert form in ("model-copy", "linear"), form
    inertia = np.asarray(inertia, dtype=float)
    inertia = np.diag(inertia) if inertia.shape == (3,) else inertia
    model = inertia if model_inertia is None else np.asarray(model_inertia, dtype=float)
    model = np.diag(model) if model.shape == (3,) else model
    inverse, model_inverse = np.linalg.inv(inertia), np.linalg.inv(model)
    gain = np.asarray(K, dtype=float)
    n = math.floor(t_final * rate + 1e-9) + 1
    h = 1.0 / rate
    tau = d * h
    x = np.asarray(x0, dtype=float).copy()
    if x[0:3] @ x[0:3] > 1.0:
        x[0:3] = _mrp_shadow(x[0:3])
    z = x.copy()
    xs, zs = [], []
    out = {name: np.zeros((n, 3)) for name in ("sigma", "omega", "u", "command", "sigma_c")}
    angle = np.zeros(n)
    switches: list[int] = []
    previous = _short_mrp(_product(_quaternion(z[0:3]), _conjugate(_quaternion(reference[0][0:3]))))
    unsettled = -1
    for k in range(n):
        xs.append(x.copy())
        zs.append(z.copy())
        y = xs[k - d] if k >= d else xs[0]
        z_old = zs[k - d] if k >= d else zs[0]
        if form == "linear":
            forced_sigma = z[0:3] - z_old[0:3] - tau * z_old[3:6]
            forced_w = z[3:6] - z_old[3:6]
            v = tau * y[3:6] + forced_sigma
            x2 = min(float(v @ v), 1.5625)
            q_hat = _product(_quaternion(v * (15.0 - x2) / (15.0 - 6.0 * x2)), _quaternion(y[0:3]))
            omega_hat = 4.0 * (y[3:6] + forced_w)
        else:
            q_error = _product(_conjugate(_quaternion(z_old[0:3])), _quaternion(y[0:3]))
            d_omega = 4.0 * (y[3:6] - z_old[3:6])
            q_hat = _product(_noise_quaternion(tau * d_omega), _product(_quaternion(z[0:3]), q_error))
            omega_hat = 4.0 * z[3:6] + d_omega
        row = reference[k]
        sigma = _short_mrp(_product(q_hat, _conjugate(_quaternion(row[0:3]))))
        dcm = _dcm(q_hat if q_hat[0] >= 0.0 else -q_hat)
        omega_r = dcm @ row[3:6]
        if sigma @ sigma > 1e-8 and np.linalg.norm(_mrp_shadow(sigma) - previous) < np.linalg.norm(sigma - previous):
            sigma = _mrp_shadow(sigma)
        if sigma @ sigma >= alpha**2:
            sigma = _mrp_shadow(sigma)
            switches.append(k)
        previous = sigma
        command = gain @ np.concatenate((sigma, (omega_hat - omega_r) / 4.0))
        if feedforward:
            command = command + _cross(omega_hat, model @ omega_hat)
            command = command + model @ (dcm @ row[6:9] - _cross(omega_hat, omega_r))
        true_error = _product(_quaternion(x[0:3]), _conjugate(_quaternion(row[0:3])))
        angle[k] = math.degrees(4.0 * math.atan(np.linalg.norm(true_error[1:4]) / (1.0 + abs(true_error[0]))))
        true_rate = 4.0 * x[3:6] - _dcm(_quaternion(x[0:3])) @ row[3:6]
        sigma_error = true_error[1:4] / (1.0 + abs(true_error[0]))
        if sigma_error @ sigma_error >= 1e-4 or true_rate @ true_rate >= 1e-6:
            unsettled = k
        out["sigma"][k], out["omega"][k], out["u"][k] = x[0:3], 4.0 * x[3:6], command
        out["command"][k], out["sigma_c"][k] = command, sigma
        sigma_next, omega_next = _rk4(x[0:3], 4.0 * x[3:6], command, h, 1, inertia, inverse)
        x = np.concatenate((sigma_next, omega_next / 4.0))
        if x[0:3] @ x[0:3] > 1.0:
            x[0:3] = _mrp_shadow(x[0:3])
        if form == "linear":
            acceleration = model_inverse @ command
            z = np.concatenate((z[0:3] + h * z[3:6] + (h * h / 8.0) * acceleration, z[3:6] + (h / 4.0) * acceleration))
        else:
            sigma_m, omega_m = _rk4(z[0:3], 4.0 * z[3:6], command, h, 1, model, model_inverse)
            z = np.concatenate((sigma_m, omega_m / 4.0))
            if z[0:3] @ z[0:3] > 1.0:
                z[0:3] = _mrp_shadow(z[0:3])
    settle = unsettled + 1
    return TrackingRun(
        switches=np.array(switches, dtype=np.int64),
        h=np.ones(n),
        pointing_deg=angle,
        settling_time=settle / rate if settle < n else None,
        **out,
    )
