"""A separately written plain-NumPy reference of the flight loop on a reaction-wheel cluster (nothing from mrpctl).

Written again from the equations of ``design/wheels.md`` (Basilisk's balanced wheels), one run, sample by
sample, with explicit per-wheel loops where the engine uses matrices:

* state: σ (MRP), ω (rad/s), Ω (wheel speeds relative to the body, rad/s);
* hub: (J − Σ Js,i g_i g_iᵀ) ω̇ = −ω × (J ω + Σ Js,i Ω_i g_i) − Σ g_i (u_i + τ_f,i) + w;
  wheels: Ω̇_i = (u_i + τ_f,i)/Js,i − g_i·ω̇; friction τ_f,i = −(f_c sgn Ω_i + c Ω_i), linear through zero
  below ω_lc; σ̇ = ¼ ((1 − σ²) ω + 2 σ × ω + 2 σ (σ·ω)); RK4 with the torques held (ZOH);
* plant bookkeeping: σ_k → −σ_k/|σ_k|² when |σ_k|² >= 1;
* sensor (optional): β̃ = β(θ_k) ⊗ β(σ_k) (Hamilton product, scalar first), made canonical, ω̃ = ω + b + η_k,
  with the noise samples θ_k, η_k given as data;
* delay: a ring of the last d + 1 measurements, the history before t = 0 the initial state (noise-free);
* controller: quaternion sign continuity, the hysteresis h ← −h when h q̂₀ < −δ, σ_c = h q̂_v/(1 + h q̂₀),
  u_c = K [σ_c; ω_used/4] (+ ω × (J ω + Σ g_i Js,i (g_i·ω + Ω_i)) with the gyroscopic term); the wheel
  speeds read are those of the sample instant;
* steering law (optional, (ω_max, a, T, h, J), h and J None without a momentum limit): with K = [K_σ, K_ω], the
  remaining angle φ = 2 atan2(|q_v|, h q₀) of the set used, the rate command ω_lin = −4 K_ω⁻¹ K_σ σ_c
  (numpy.linalg.solve), L = min(ω_max, √((aT)² + 2aφ) − aT), s = min(1, L/|ω_lin|, h/|J ω_lin|),
  u_c = K_ω ω_used/4 + s K_σ σ_c;
* allocation: u = −pinv(C Gs) C u_c (numpy.linalg.pinv) − k_n (I − pinv(Gs) Gs) Js (Ω − Ω_bias); each u_i
  clipped to ±u_max,i, then 0 when |Ω_i| >= Ω_max,i and Ω_i u_i >= 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Wheels:
    axes: np.ndarray  # (3, N)
    js: np.ndarray
    u_max: np.ndarray
    omega_max: np.ndarray
    viscous: np.ndarray
    coulomb: np.ndarray
    cycle: np.ndarray
    speeds: np.ndarray
    control: np.ndarray = field(default_factory=lambda: np.eye(3))
    null_gain: float = 0.0
    bias: np.ndarray | None = None
    gyroscopic: bool = False


def _friction(wheels: Wheels, speeds: np.ndarray) -> np.ndarray:
    out = np.empty_like(speeds)
    for i, s in enumerate(speeds):
        c, f, lc = wheels.viscous[i], wheels.coulomb[i], wheels.cycle[i]
        sign = 1.0 if s > 0 else (-1.0 if s < 0 else 0.0)
        out[i] = -((f + c * lc) / lc * s if abs(s) < lc else f * sign + c * s)
    return out


def derivative(state: np.ndarray, u: np.ndarray, w: np.ndarray, inertia: np.ndarray, wheels: Wheels) -> np.ndarray:
    """d/dt of [σ, ω, Ω] (3 + 3 + N)."""
    sigma, omega, speeds = state[0:3], state[3:6], state[6:]
    count = wheels.axes.shape[1]
    tau = u + _friction(wheels, speeds)
    hub = inertia.copy()
    momentum = inertia @ omega
    moment = w.copy()
    for i in range(count):
        g = wheels.axes[:, i]
        hub -= wheels.js[i] * np.outer(g, g)
        momentum += wheels.js[i] * speeds[i] * g
        moment -= g * tau[i]
    moment -= np.cross(omega, momentum)
    omega_dot = np.linalg.solve(hub, moment)
    speeds_dot = np.array([tau[i] / wheels.js[i] - wheels.axes[:, i] @ omega_dot for i in range(count)])
    s2 = sigma @ sigma
    sigma_dot = 0.25 * ((1.0 - s2) * omega + 2.0 * np.cross(sigma, omega) + 2.0 * sigma * (sigma @ omega))
    return np.concatenate((sigma_dot, omega_dot, speeds_dot))


def rk4(state: np.ndarray, u: np.ndarray, w: np.ndarray, dt: float, substeps: int, inertia, wheels) -> np.ndarray:
    for _ in range(substeps):
        a = derivative(state, u, w, inertia, wheels)
        b = derivative(state + 0.5 * dt * a, u, w, inertia, wheels)
        c = derivative(state + 0.5 * dt * b, u, w, inertia, wheels)
        e = derivative(state + dt * c, u, w, inertia, wheels)
        state = state + (dt / 6.0) * (a + 2.0 * b + 2.0 * c + e)
    return state


def allocate(wheels: Wheels, command: np.ndarray, omega: np.ndarray, speeds: np.ndarray, inertia: np.ndarray):
    """(motor torques, torque-limited flags, speed-limited flags)."""
    request = command.copy()
    if wheels.gyroscopic:
        spin = wheels.js * (wheels.axes.T @ omega + speeds)
        request = request + np.cross(omega, inertia @ omega + wheels.axes @ spin)
    projected = wheels.control @ wheels.axes
    u = -np.linalg.pinv(projected) @ (wheels.control @ request)
    if wheels.null_gain > 0.0:
        count = wheels.axes.shape[1]
        null = np.eye(count) - np.linalg.pinv(wheels.axes) @ wheels.axes
        bias = np.zeros(count) if wheels.bias is None else wheels.bias
        u = u - wheels.null_gain * null @ (wheels.js * (speeds - bias))
    torque_limited = np.abs(u) > wheels.u_max
    u = np.clip(u, -wheels.u_max, wheels.u_max)
    speed_limited = (np.abs(speeds) >= wheels.omega_max) & (speeds * u >= 0.0)
    u = np.where(speed_limited, 0.0, u)
    return u, torque_limited, speed_limited


def _rotation(theta: np.ndarray) -> np.ndarray:
    angle = float(np.sqrt(theta @ theta))
    if angle == 0.0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    return np.concatenate(((np.cos(angle / 2.0),), np.sin(angle / 2.0) / angle * theta))


def _compose(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The quaternion of [FN] = [FB(a)][BN(b)] (scalar first)."""
    scalar = a[0] * b[0] - a[1:] @ b[1:]
    vector = a[0] * b[1:] + b[0] * a[1:] - np.cross(a[1:], b[1:])
    return np.concatenate(((scalar,), vector))


def _quaternion(sigma: np.ndarray) -> np.ndarray:
    s2 = sigma @ sigma
    q = np.concatenate((((1.0 - s2) / (1.0 + s2),), 2.0 * sigma / (1.0 + s2)))
    return -q if q[0] < 0 else q


def _steering(K: np.ndarray, law, sigma_c: np.ndarray, q: np.ndarray, w_used: np.ndarray) -> np.ndarray:
    """The steering law's body torque request from the set used (σ_c and its quaternion q, q₀ >= −δ)."""
    rate_limit, a, lag, momentum_limit, inertia = law
    k_sigma, k_omega = K[:, 0:3], K[:, 3:6]
    angle = 2.0 * math.atan2(math.sqrt(q[1] ** 2 + q[2] ** 2 + q[3] ** 2), q[0])
    omega_linear = -4.0 * np.linalg.solve(k_omega, k_sigma @ sigma_c)
    linear = np.linalg.norm(omega_linear)
    limit = min(rate_limit, math.sqrt((a * lag) ** 2 + 2.0 * a * angle) - a * lag)
    scale = limit / linear if linear > limit else 1.0
    if momentum_limit is not None:
        momentum = np.linalg.norm(inertia @ omega_linear)
        if scale * momentum > momentum_limit:
            scale = momentum_limit / momentum
    return k_omega @ (w_used / 4.0) + scale * (k_sigma @ sigma_c)


@dataclass
class WheelRun:
    sigma: np.ndarray  # (n, 3) after bookkeeping
    omega: np.ndarray  # (n, 3)
    speeds: np.ndarray  # (n, N) at the sample instants
    motor: np.ndarray  # (n, N)
    body: np.ndarray  # (n, 3) −Gs u
    command: np.ndarray  # (n, 3)
    torque_limited: np.ndarray  # (n, N)
    speed_limited: np.ndarray  # (n, N)
    final_speeds: np.ndarray


def wheel_loop(
    inertia,
    K,
    x0,
    wheels: Wheels,
    *,
    rate: float,
    t_final: float,
    d: int,
    delta: float = 0.0,
    substeps: int = 1,
    disturbance=None,
    noise=None,
    bias=None,
    steering=None,
) -> WheelRun:
    """One run (module docstring); x0 = [σ; ω/4]; ``noise`` = (θ (n, 3), η (n, 3)) and ``bias`` (3,) of a sensor;
    ``disturbance`` (3,) or one row per sample (n, 3); ``steering`` = (ω_max, a, T) of the steering law."""
    inertia = np.asarray(inertia, dtype=float)
    x0 = np.asarray(x0, dtype=float)
    n = math.floor(t_final * rate + 1e-9) + 1
    dt = 1.0 / rate / substeps
    w_all = np.zeros(3) if disturbance is None else np.asarray(disturbance, dtype=float)
    gyro = np.zeros(3) if bias is None else np.asarray(bias, dtype=float)
    count = wheels.axes.shape[1]
    state = np.concatenate((x0[0:3], 4.0 * x0[3:6], wheels.speeds))
    ring = [(_quaternion(x0[0:3]), 4.0 * x0[3:6])] * (d + 1)
    h = 1.0
    q_prev = None
    out = {key: [] for key in ("sigma", "omega", "speeds", "motor", "body", "command", "tl", "sl")}
    for k in range(n):
        w = w_all if w_all.ndim == 1 else w_all[k]
        sigma = state[0:3]
        s2 = sigma @ sigma
        if s2 >= 1.0:
            state = state.copy()
            state[0:3] = -sigma / s2
        sigma, omega, speeds = state[0:3], state[3:6], state[6:]
        q_meas, w_meas = _quaternion(sigma), omega.copy()
        if noise is not None:
            q_meas = _compose(_rotation(noise[0][k]), q_meas)
            q_meas = -q_meas if q_meas[0] < 0 else q_meas
            w_meas = omega + gyro + noise[1][k]
        ring = [*ring[1:], (q_meas, w_meas)]
        q_used, w_used = ring[0]
        if q_prev is None:
            q_prev = q_used
        q_hat = -q_used if q_used @ q_prev < 0.0 else q_used
        q_prev = q_hat
        if h * q_hat[0] < -delta:
            h = -h
        sigma_c = h * q_hat[1:4] / (1.0 + h * q_hat[0])
        if steering is None:
            command = np.asarray(K) @ np.concatenate((sigma_c, w_used / 4.0))
        else:
            command = _steering(np.asarray(K), steering, sigma_c, h * q_hat, w_used)
        motor, tl, sl = allocate(wheels, command, w_used, speeds, inertia)
        for key, value in (
            ("sigma", sigma),
            ("omega", omega),
            ("speeds", speeds),
            ("motor", motor),
            ("body", -(wheels.axes @ motor)),
            ("command", command),
            ("tl", tl),
            ("sl", sl),
        ):
            out[key].append(np.array(value, dtype=float))
        state = rk4(state, motor, w, dt, substeps, inertia, wheels)
    arrays = {key: np.array(value) for key, value in out.items()}
    return WheelRun(
        sigma=arrays["sigma"],
        omega=arrays["omega"],
        speeds=arrays["speeds"].reshape(n, count),
        motor=arrays["motor"].reshape(n, count),
        body=arrays["body"],
        command=arrays["command"],
        torque_limited=arrays["tl"].reshape(n, count),
        speed_limited=arrays["sl"].reshape(n, count),
        final_speeds=state[6:],
    )
